//! Shared helpers of the integration suites: a synthetic bag made once per test binary, the
//! Python checkers, and running the `xsurf` binary.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The workspace root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// A fresh scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("xsurf-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The venv's Python, or `None` (then the test is skipped, unless CI requires the checkers).
pub fn python() -> Option<PathBuf> {
    let p = root().join(".venv/bin/python");
    if p.is_file() {
        return Some(p);
    }
    assert!(
        std::env::var("XSURF_REQUIRE_CHECKERS").is_err(),
        "the Python checkers are required: run `bash scripts/setup-venv.sh`"
    );
    eprintln!("skipped: no .venv (run `bash scripts/setup-venv.sh` to enable the independent checkers)");
    None
}

/// Runs a checker script under `tests/py/`, returning its stdout parsed as JSON.
pub fn checker(script: &str, args: &[&Path]) -> Option<serde_json::Value> {
    let py = python()?;
    let out = Command::new(py).arg(root().join("tests/py").join(script)).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{script} failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    Some(serde_json::from_slice(&out.stdout).unwrap())
}

/// Runs `xsurf ARGS`.
pub fn xsurf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xsurf")).args(args).output().unwrap()
}

/// Runs `xsurf reconstruct BAG --params-file PARAMS --out OUT`.
pub fn reconstruct(bag: &Path, params: &Path, out: &Path) -> Output {
    let s = |p: &Path| p.to_string_lossy().into_owned();
    xsurf(&["reconstruct", &s(bag), "--params-file", &s(params), "--out", &s(out)])
}

/// A PLY file's mesh.
pub fn read_ply(path: &Path) -> xsurf_core::mesh::Mesh {
    let f = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    xsurf_formats::ply::read(&mut std::io::BufReader::new(f)).unwrap()
}

/// Asserts that a run failed cleanly: the expected exit code, no panic, and stderr naming `what`.
pub fn assert_clean_failure(out: &Output, code: i32, what: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "exit code; stderr:\n{err}");
    assert!(!err.contains("panicked"), "panic:\n{err}");
    assert!(err.contains(what), "stderr should name {what:?}:\n{err}");
}

/// A small synthetic scan of the pyramid (320x240, 140 mm/s, zstd), made once.
pub fn pyramid_bag() -> &'static Path {
    static BAG: OnceLock<PathBuf> = OnceLock::new();
    BAG.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("xsurf-test-{}-pyramid-bag", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let out =
            xsurf(&["synth", "pyramid", "-o", dir.to_str().unwrap(), "--size", "320x240", "--speed", "0.14", "--zstd"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        dir
    })
}

/// Copies a bag directory.
pub fn copy_bag(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dst.join(e.file_name())).unwrap();
    }
}

/// The tests of one binary that run a DDS graph take their turns: two at once on a 2-core
/// machine slow discovery past the tools' timeouts (a parameter call gave up after 15 s in CI)
/// and starve the cameras (a "whole" scan lost a tenth of its frames).
static ONE_GRAPH_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Holds the machine for one graph until the guard is dropped.
pub fn one_graph_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_GRAPH_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}
