//! A mutation fuzzer of every decoder that takes bytes from outside (issue 24, item 5), on
//! stable Rust, in the test suite.
//!
//! Each target starts from its seed corpus (`tests/fuzz/corpus/<target>/`, committed; written by
//! the ignored test `write_seed_corpus` from our own writers) and runs a fixed count of mutated
//! inputs from a fixed seed: bit flips, interesting bytes and integers (lengths of 0, -1, 2^31),
//! deletions, duplications, insertions of the target's tokens, truncations and splices of two
//! seeds. Each input must come back as a value or a typed error with a message (no panic), and
//! raise the resident memory by at most `MAX_RESIDENT_BYTES`. A failing input is
//! written to `target/fuzz-failures/<target>/` and the test names it; the fixed ones become
//! fixtures in `tests/fuzz/crashes/<target>/`, replayed by the regression tests at the end,
//! each named after its fixture.
//!
//! `XSURF_FUZZ_ITERS=N` runs N inputs per target (default `DEFAULT_ITERS`) and
//! `XSURF_FUZZ_SEED=S` another sequence; `XSURF_FUZZ_TARGET=name` runs one target.
// A scenario reads top to bottom: its steps stay in one test function.
#![allow(clippy::too_many_lines)]
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};
use xsurf_core::synth::SplitMix;
use xsurf_runtime::component::{AnyComponent, Msg, Outbox};
use xsurf_runtime::params::Params;

// ---------------------------------------------------------------------------------------------
// Memory. Each input's resident memory is measured: the kernel's peak (VmHWM) is reset before it
// (`/proc/self/clear_refs`) and read after, and may not rise more than `MAX_RESIDENT_BYTES` above
// what was resident before. The allocator also refuses any allocation that would take the
// process past its target's `max_allocated`, address space reserved whether touched or not (the
// run then aborts with "memory allocation of N bytes failed"; the input is the file this run
// printed for its target): 1 GiB, and 6 GiB for MCAP, because the mcap crate (through binrw)
// reserves address space for a string field as long as its u32 length says, up to 4 GiB, before
// it finds the record too short; those pages are never touched.

#[global_allocator]
static ALLOC: cap::Cap<std::alloc::System> = cap::Cap::new(std::alloc::System, usize::MAX);

/// The most one input may add to the resident memory at its peak.
const MAX_RESIDENT_BYTES: u64 = 256 << 20;
/// The most the process may have allocated (address space reserved, touched or not) at once.
const MAX_ALLOCATED_BYTES: usize = 1 << 30;
/// The same for MCAP: binrw's reservations of up to 4 GiB (see above).
const MCAP_MAX_ALLOCATED_BYTES: usize = 6 << 30;

/// A `/proc/self/status` field in bytes.
fn status_bytes(field: &str) -> u64 {
    xsurf_nodes::offline::proc_status_bytes(field).unwrap()
}

/// Inputs per target in the test suite.
const DEFAULT_ITERS: usize = 4000;

// ---------------------------------------------------------------------------------------------
// Targets.

/// What one decoder made of one input.
enum Outcome {
    /// Decoded.
    Ok,
    /// Refused, with this message.
    Refused(String),
}

fn outcome<T, E: std::fmt::Display>(r: Result<T, E>) -> Outcome {
    match r {
        Ok(_) => Outcome::Ok,
        Err(e) => Outcome::Refused(e.to_string()),
    }
}

/// A fuzz target: its name (the corpus folder), the file extension its inputs are written with
/// when the decoder reads a file, tokens worth inserting, and the decoder.
struct Target {
    name: &'static str,
    ext: &'static str,
    tokens: &'static [&'static [u8]],
    /// True if a refusal must name the file it read.
    names_file: bool,
    /// The most the process may have allocated at once while this target runs (address space
    /// reserved, touched or not): `MAX_ALLOCATED_BYTES`, or more where a dependency is known to
    /// reserve more than it touches.
    max_allocated: usize,
    run: fn(&[u8], &Path, &mut Nodes) -> Outcome,
}

const YAML_TOKENS: &[&[u8]] = &[
    b": ",
    b"\n- ",
    b"[",
    b"]",
    b"{",
    b"}",
    b"ros__parameters",
    b"/**",
    b"!!binary ",
    b"&a ",
    b"*a",
    b"~",
    b"1e999",
    b"-9223372036854775809",
    b"\"\\u0000\"",
    b".nan",
    b"\t",
    b"---\n",
    b"? ",
    b"|\n",
    b"<<: *a",
];
const BIN_TOKENS: &[&[u8]] = &[b"\x00\x00\x00\x00", b"\xff\xff\xff\xff", b"\x00\x00\x00\x80", b"\xff\xff\xff\x7f"];
const ARG_TOKENS: &[&[u8]] = &[
    b"--ros-args",
    b"-p",
    b"-r",
    b"--params-file",
    b"--log-level",
    b"--",
    b":=",
    b"__ns",
    b"__node",
    b"-e",
    b"--remap",
    b"--param",
    b"/",
    b"~",
];
const PLY_TOKENS: &[&[u8]] = &[
    b"element vertex ",
    b"element face ",
    b"property float x\n",
    b"property list uchar int vertex_indices\n",
    b"format binary_little_endian 1.0\n",
    b"format ascii 1.0\n",
    b"end_header\n",
    b"4294967295",
    b"-1",
];
const DICOM_TOKENS: &[&[u8]] = &[
    b"DICM",
    b"\x02\x00\x10\x00UI",
    b"\xe0\x7f\x10\x00OW\x00\x00\xff\xff\xff\xff",
    b"\x28\x00\x10\x00US\x02\x00",
    b"\x28\x00\x11\x00US\x02\x00",
    b"1.2.840.10008.1.2.4.50\x00",
    b"\xfe\xff\x00\xe0\xff\xff\xff\xff",
];
const MCAP_TOKENS: &[&[u8]] = &[b"\x89MCAP0\r\n", b"\x06", b"\x07", b"\x05", b"zstd", b"ros2msg", b"cdr"];

/// The graph's seven components, built from default parameters, that CDR inputs are handed to.
struct Nodes {
    nodes: Vec<Box<dyn AnyComponent>>,
    out: Outbox,
}

impl Nodes {
    fn new() -> Nodes {
        let mut nodes = Vec::new();
        for name in ["camera_driver", "c_arm_pose", "edge_detector", "triangulator", "mesher", "merger", "xray_aligner"]
        {
            let decls = xsurf_nodes::registry::declarations(name).unwrap();
            let params = Params::resolve(&decls, &BTreeMap::new()).unwrap();
            let mut n = xsurf_nodes::registry::build(name, &params).unwrap();
            n.set_identity(name, "/cam1");
            nodes.push(n);
        }
        // A second edge detector, for image_transport's compressed images.
        let decls = xsurf_nodes::registry::declarations("edge_detector").unwrap();
        let compressed = BTreeMap::from([(
            "image_transport".to_string(),
            xsurf_runtime::params::ParamValue::String("compressed".into()),
        )]);
        let params = Params::resolve(&decls, &compressed).unwrap();
        nodes.push(xsurf_nodes::registry::build("edge_detector", &params).unwrap());
        Nodes { nodes, out: Outbox::default() }
    }

    /// Hands `msg` to every input of every node that takes its type.
    fn feed(&mut self, msg: &Msg) {
        for n in &mut self.nodes {
            for (i, p) in n.inputs().iter().enumerate() {
                if p.type_name == msg.type_name() {
                    // A refusal is the node's typed answer; only a panic fails the input.
                    let _ = n.handle(i, msg, &mut self.out);
                }
            }
        }
        // What the nodes publish is not looked at; it must not pile up either.
        self.out.items.clear();
        self.out.refused.clear();
    }
}

fn cdr_target(type_name: &'static str) -> fn(&[u8], &Path, &mut Nodes) -> Outcome {
    macro_rules! by_type {
        ($($t:literal),*) => {
            match type_name {
                $($t => |b: &[u8], _: &Path, nodes: &mut Nodes| match Msg::decode($t, b) {
                    Ok(m) => {
                        nodes.feed(&m);
                        Outcome::Ok
                    }
                    Err(e) => Outcome::Refused(e.to_string()),
                },)*
                other => panic!("no CDR target for {other}"),
            }
        };
    }
    by_type!(
        "sensor_msgs/msg/Image",
        "sensor_msgs/msg/CompressedImage",
        "sensor_msgs/msg/CameraInfo",
        "tf2_msgs/msg/TFMessage",
        "xsurf_msgs/msg/LaserLine",
        "sensor_msgs/msg/PointCloud2",
        "visualization_msgs/msg/Marker",
        "xsurf_msgs/msg/ScanEvent",
        "sensor_msgs/msg/JointState",
        "rosgraph_msgs/msg/Clock",
        "std_msgs/msg/String"
    )
}

/// The corpus folder of a CDR target.
fn cdr_name(type_name: &str) -> &'static str {
    match type_name {
        "sensor_msgs/msg/Image" => "cdr_image",
        "sensor_msgs/msg/CompressedImage" => "cdr_compressed_image",
        "sensor_msgs/msg/CameraInfo" => "cdr_camera_info",
        "tf2_msgs/msg/TFMessage" => "cdr_tf",
        "xsurf_msgs/msg/LaserLine" => "cdr_laser_line",
        "sensor_msgs/msg/PointCloud2" => "cdr_point_cloud",
        "visualization_msgs/msg/Marker" => "cdr_marker",
        "xsurf_msgs/msg/ScanEvent" => "cdr_scan_event",
        "sensor_msgs/msg/JointState" => "cdr_joint_state",
        "rosgraph_msgs/msg/Clock" => "cdr_clock",
        "std_msgs/msg/String" => "cdr_scan_report",
        other => panic!("no CDR target for {other}"),
    }
}

/// Reads every message of the bag in `path`'s folder and decodes those of types we take in.
fn read_bag(dir: &Path) -> Outcome {
    let bag = match xsurf_formats::bag::Bag::open(dir) {
        Ok(b) => b,
        Err(e) => return Outcome::Refused(e.to_string()),
    };
    let _ = bag.info();
    for m in bag.messages() {
        match m {
            Ok(m) => {
                let _ = Msg::decode(&m.type_name, &m.data);
            }
            // The reader stops at the first bad record: what came before is kept.
            Err(e) => return Outcome::Refused(e.to_string()),
        }
    }
    Outcome::Ok
}

fn targets() -> Vec<Target> {
    let mut v: Vec<Target> = Msg::TYPE_NAMES
        .iter()
        .map(|t| Target {
            name: cdr_name(t),
            ext: "cdr",
            tokens: BIN_TOKENS,
            names_file: false,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: cdr_target(t),
        })
        .collect();
    v.extend([
        Target {
            name: "mcap",
            ext: "mcap",
            tokens: MCAP_TOKENS,
            names_file: false,
            max_allocated: MCAP_MAX_ALLOCATED_BYTES,
            // The input is the bag's storage file beside a good metadata.yaml.
            run: |b, path, _| {
                let dir = path.with_extension("bag");
                let _ = std::fs::remove_dir_all(&dir);
                std::fs::create_dir_all(&dir).unwrap();
                let seed = corpus_dir().join("mcap").join("metadata.yaml.txt");
                std::fs::copy(seed, dir.join("metadata.yaml")).unwrap();
                std::fs::write(dir.join("b_0.mcap"), b).unwrap();
                let with_metadata = read_bag(&dir);
                // And without it: the folder is indexed from its storage file.
                std::fs::remove_file(dir.join("metadata.yaml")).unwrap();
                let _ = read_bag(&dir);
                with_metadata
            },
        },
        Target {
            name: "bag_metadata",
            ext: "yaml",
            tokens: YAML_TOKENS,
            names_file: true,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |b, path, _| outcome(xsurf_formats::bag::BagMetadata::parse(&String::from_utf8_lossy(b), path)),
        },
        Target {
            name: "params_yaml",
            ext: "yaml",
            tokens: YAML_TOKENS,
            names_file: false,
            max_allocated: MAX_ALLOCATED_BYTES,
            // A params file as `--params-file` gives it to each node, then each node's validation.
            run: |b, _, _| {
                let text = String::from_utf8_lossy(b);
                let mut last = Outcome::Ok;
                for node in ["edge_detector", "triangulator", "mesher", "merger", "c_arm_pose"] {
                    let fq = format!("/cam1/{node}");
                    match xsurf_runtime::rosargs::params_from_yaml(&text, &fq) {
                        Ok(map) => {
                            let decls = xsurf_nodes::registry::declarations(node).unwrap();
                            if let Ok(p) = Params::resolve(&decls, &map) {
                                let _ = xsurf_nodes::registry::build(node, &p).map(|_| ());
                            }
                        }
                        Err(e) => last = Outcome::Refused(e),
                    }
                }
                last
            },
        },
        Target {
            name: "launch_yaml",
            ext: "yaml",
            tokens: YAML_TOKENS,
            names_file: true,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |_, path, _| outcome(xsurf_nodes::launch::load(path, &BTreeMap::new()).map_err(|e| format!("{e:#}"))),
        },
        Target {
            name: "rig_yaml",
            ext: "yaml",
            tokens: YAML_TOKENS,
            names_file: true,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |_, path, _| outcome(xsurf_formats::rig::read(path)),
        },
        Target {
            name: "camera_calibration_yaml",
            ext: "yaml",
            tokens: YAML_TOKENS,
            names_file: true,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |_, path, _| match xsurf_formats::calibration::read(path) {
                Ok(c) => outcome(c.model()),
                Err(e) => Outcome::Refused(e.to_string()),
            },
        },
        Target {
            name: "dicom",
            ext: "dcm",
            tokens: DICOM_TOKENS,
            names_file: true,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |_, path, _| outcome(xsurf_formats::dicom::read_file(path)),
        },
        Target {
            name: "dicom_study",
            ext: "dcm",
            tokens: DICOM_TOKENS,
            names_file: true,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |_, path, _| outcome(xsurf_formats::dicom_surface::read_study(path)),
        },
        Target {
            name: "dimse_response",
            ext: "bin",
            tokens: BIN_TOKENS,
            names_file: false,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |b, _, _| outcome(xsurf_nodes::pacs::command_status(b)),
        },
        Target {
            name: "ply",
            ext: "ply",
            tokens: PLY_TOKENS,
            names_file: false,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |b, _, _| outcome(xsurf_formats::ply::read(&mut std::io::Cursor::new(b))),
        },
        Target {
            name: "bmp",
            ext: "bmp",
            tokens: BIN_TOKENS,
            names_file: true,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |_, path, _| outcome(xsurf_formats::frames::read_frame(path)),
        },
        Target {
            name: "png",
            ext: "png",
            tokens: BIN_TOKENS,
            names_file: true,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |b, path, _| {
                // As a frame file, and as a CompressedImage's payload.
                let _ = xsurf_formats::compressed::decode("png", b);
                outcome(xsurf_formats::frames::read_frame(path))
            },
        },
        Target {
            name: "pgm",
            ext: "pgm",
            tokens: BIN_TOKENS,
            names_file: true,
            max_allocated: MAX_ALLOCATED_BYTES,
            run: |_, path, _| outcome(xsurf_formats::frames::read_frame(path)),
        },
        Target {
            name: "ros_args",
            ext: "args",
            tokens: ARG_TOKENS,
            names_file: false,
            max_allocated: MAX_ALLOCATED_BYTES,
            // One argument per line, as a node's `argv` after the program name.
            run: |b, _, _| {
                let text = String::from_utf8_lossy(b);
                let args: Vec<&str> = text.split('\n').collect();
                match xsurf_runtime::rosargs::RosArgs::parse(&args) {
                    Ok(a) => {
                        let (name, ns) = a.node_identity("edge_detector", "/");
                        let fq = xsurf_runtime::rosargs::fq_name(&ns, &name);
                        outcome(a.param_overrides(&fq))
                    }
                    Err(e) => Outcome::Refused(e.to_string()),
                }
            },
        },
    ]);
    v
}

// ---------------------------------------------------------------------------------------------
// The mutator.

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fuzz/corpus")
}

fn crashes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fuzz/crashes")
}

/// The crash fixtures of a target: `(file name, bytes)`.
fn fixtures(target: &str) -> Vec<(String, Vec<u8>)> {
    let Ok(rd) = std::fs::read_dir(crashes_dir().join(target)) else { return Vec::new() };
    let mut v: Vec<(String, Vec<u8>)> = rd
        .map(|e| e.unwrap().path())
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap()))
        .collect();
    v.sort();
    v
}

fn seeds(target: &str) -> Vec<Vec<u8>> {
    let dir = corpus_dir().join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e} (run the ignored test write_seed_corpus)", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| !p.to_string_lossy().ends_with(".txt"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "{}: no seeds", dir.display());
    files.iter().map(|p| std::fs::read(p).unwrap()).collect()
}

struct Mutator {
    rng: SplitMix,
}

impl Mutator {
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.rng.next_u64() % n as u64) as usize
        }
    }

    /// One to eight mutations of `seed` (with `other`, a second seed, for splices).
    fn mutate(&mut self, seed: &[u8], other: &[u8], tokens: &[&[u8]]) -> Vec<u8> {
        let mut b = seed.to_vec();
        for _ in 0..1 + self.below(8) {
            let len = b.len();
            match self.below(10) {
                0 if len > 0 => {
                    let i = self.below(len);
                    b[i] ^= 1 << self.below(8);
                }
                1 if len > 0 => {
                    let i = self.below(len);
                    b[i] = [0u8, 0xff, 0x7f, 0x80, 0x01, b'0', b'\n', b' '][self.below(8)];
                }
                2 if len >= 4 => {
                    // A length or count field made absurd.
                    let i = self.below(len - 3);
                    let v: u32 = [0, u32::MAX, 0x8000_0000, 0x7fff_ffff, 0x0001_0000, 0xffff][self.below(6)];
                    b[i..i + 4].copy_from_slice(&v.to_le_bytes());
                }
                3 if len > 0 => {
                    let i = self.below(len);
                    let n = (1 + self.below(32)).min(len - i);
                    b.drain(i..i + n);
                }
                4 if len > 0 => {
                    let i = self.below(len);
                    let n = (1 + self.below(64)).min(len - i);
                    let chunk = b[i..i + n].to_vec();
                    let at = self.below(len + 1);
                    b.splice(at..at, chunk);
                }
                5 if !tokens.is_empty() => {
                    let t = tokens[self.below(tokens.len())];
                    let at = self.below(len + 1);
                    b.splice(at..at, t.iter().copied());
                }
                6 if !tokens.is_empty() && len > 0 => {
                    let t = tokens[self.below(tokens.len())];
                    let at = self.below(len);
                    let end = (at + t.len()).min(len);
                    b.splice(at..end, t.iter().copied());
                }
                7 if len > 0 => b.truncate(self.below(len)),
                8 if !other.is_empty() => {
                    let cut = self.below(b.len() + 1);
                    let from = self.below(other.len());
                    b.truncate(cut);
                    b.extend_from_slice(&other[from..]);
                }
                _ if len > 0 => {
                    let i = self.below(len);
                    b[i] = self.rng.next_u64() as u8;
                }
                _ => b.push(self.rng.next_u64() as u8),
            }
        }
        b
    }
}

/// Why one input failed.
/// On success, how long the input took and the decoder's refusal, if it refused it.
fn check_one(t: &Target, input: &[u8], path: &Path, nodes: &mut Nodes) -> Result<(Duration, Option<String>), String> {
    std::fs::write(path, input).unwrap();
    // 5: reset the peak resident set size to the current one.
    std::fs::write("/proc/self/clear_refs", "5").unwrap();
    let before = status_bytes("VmRSS:");
    let t0 = Instant::now();
    let r = catch_unwind(AssertUnwindSafe(|| (t.run)(input, path, nodes)));
    let took = t0.elapsed();
    let rose = status_bytes("VmHWM:").saturating_sub(before);
    match r {
        Err(p) => {
            let why = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            Err(format!("panicked: {why}"))
        }
        Ok(_) if rose > MAX_RESIDENT_BYTES => Err(format!("resident memory rose {} MiB", rose >> 20)),
        Ok(Outcome::Refused(msg)) if msg.trim().is_empty() => Err("refused with an empty message".into()),
        Ok(Outcome::Refused(msg)) if t.names_file && !msg.contains(&*path.file_name().unwrap().to_string_lossy()) => {
            Err(format!("refused without naming the file: {msg}"))
        }
        Ok(Outcome::Refused(msg)) => Ok((took, Some(msg))),
        Ok(Outcome::Ok) => Ok((took, None)),
    }
}

/// The fuzz folder holds the files a launch file names beside it (launch-config's).
fn prepare(work: &Path) {
    let here = Path::new(env!("CARGO_MANIFEST_DIR")).join("../launch-config");
    for f in ["params.yaml", "rig_study.yaml", "xsurf.rviz"] {
        std::fs::copy(here.join(f), work.join(f)).unwrap();
    }
}

/// Progress on stderr, past the test harness's capture (an abort must leave the target named).
fn say(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{line}");
}

fn env_num(name: &str, default: u64) -> u64 {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The tests of this binary run one at a time: memory is measured for the whole process.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Runs every target (or `XSURF_FUZZ_TARGET`'s) for the configured count.
#[test]
fn decoders_survive_mutated_input() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let iters = env_num("XSURF_FUZZ_ITERS", DEFAULT_ITERS as u64) as usize;
    let seed = env_num("XSURF_FUZZ_SEED", 0x5eed_f022);
    let only = std::env::var("XSURF_FUZZ_TARGET").ok();
    let work = std::env::temp_dir().join(format!("xsurf-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&work).unwrap();
    let failures_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/fuzz-failures");
    prepare(&work);
    let mut nodes = Nodes::new();
    let mut failures = Vec::new();
    let t_all = Instant::now();
    for t in targets() {
        if only.as_deref().is_some_and(|o| o != t.name) {
            continue;
        }
        ALLOC.set_limit(t.max_allocated).unwrap();
        let mut corpus = seeds(t.name);
        let n_seeds = corpus.len();
        // The crash fixtures join the seeds: mutations of them go where bugs were.
        corpus.extend(fixtures(t.name).into_iter().map(|(_, b)| b));
        let mut m =
            Mutator { rng: SplitMix::new(seed ^ t.name.bytes().fold(0u64, |h, b| h.rotate_left(5) ^ u64::from(b))) };
        let path = work.join(format!("input-{}.{}", t.name, t.ext));
        let (mut slowest, mut decoded) = (Duration::ZERO, 0usize);
        let before = ALLOC.allocated();
        say(&format!("fuzz {}: each input is written to {} before it runs", t.name, path.display()));
        let t0 = Instant::now();
        for k in 0..iters + corpus.len() {
            // The seeds themselves first: they must decode.
            let input = if k < corpus.len() {
                corpus[k].clone()
            } else {
                let a = &corpus[m.below(corpus.len())];
                let b = &corpus[m.below(corpus.len())];
                m.mutate(a, b, t.tokens)
            };
            match check_one(&t, &input, &path, &mut nodes) {
                Ok((took, refused)) => {
                    slowest = slowest.max(took);
                    decoded += usize::from(refused.is_none());
                    // A seed that is refused fuzzes nothing beyond the first refusal.
                    if let Some(msg) = refused.filter(|_| k < n_seeds) {
                        failures.push(format!("{}: seed {k} is refused: {msg}", t.name));
                    }
                }
                Err(why) => {
                    let dir = failures_dir.join(t.name);
                    std::fs::create_dir_all(&dir).unwrap();
                    let file = dir.join(format!("input-{k}.{}", t.ext));
                    std::fs::write(&file, &input).unwrap();
                    failures.push(format!("{}: input {k} ({}): {why}", t.name, file.display()));
                    if failures.len() > 20 {
                        break;
                    }
                }
            }
        }
        say(&format!(
            "fuzz {:<26} {:>6} inputs ({:>3.0} % taken) in {:>6.2} s; slowest {:>7.2} ms; {:+.1} MiB held after",
            t.name,
            iters + corpus.len(),
            100.0 * decoded as f64 / (iters + corpus.len()) as f64,
            t0.elapsed().as_secs_f64(),
            slowest.as_secs_f64() * 1e3,
            (ALLOC.allocated() as f64 - before as f64) / (1 << 20) as f64
        ));
    }
    say(&format!("fuzz: all targets in {:.1} s", t_all.elapsed().as_secs_f64()));
    let _ = std::fs::remove_dir_all(&work);
    assert!(failures.is_empty(), "{} failing input(s):\n{}", failures.len(), failures.join("\n"));
}

// ---------------------------------------------------------------------------------------------
// Regression tests: each crash the fuzzer found, replayed from its fixture.

/// Replays `tests/fuzz/crashes/<target>/<fixture>` within the memory bound; the decoder's
/// refusal, if it refused it.
fn replay(target: &str, fixture: &str) -> Option<String> {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let t = targets().into_iter().find(|t| t.name == target).unwrap();
    ALLOC.set_limit(t.max_allocated).unwrap();
    let input = std::fs::read(crashes_dir().join(target).join(fixture)).unwrap();
    let work = std::env::temp_dir().join(format!("xsurf-fuzz-replay-{}-{fixture}", std::process::id()));
    std::fs::create_dir_all(&work).unwrap();
    let path = work.join(format!("input.{}", t.ext));
    prepare(&work);
    let mut nodes = Nodes::new();
    let (_, refused) = check_one(&t, &input, &path, &mut nodes).unwrap_or_else(|e| panic!("{target}/{fixture}: {e}"));
    std::fs::remove_dir_all(&work).unwrap();
    refused
}

/// An MCAP record whose u64 length is far beyond the file: the mcap crate allocated that
/// length (8e18 bytes) before reading. Now refused by the reader's record length limit.
#[test]
fn crash_mcap_record_length_beyond_the_file() {
    let msg = replay("mcap", "record_length_beyond_the_file.mcap").expect("refused");
    assert!(msg.contains("b_0.mcap") && msg.contains("byte"), "{msg}");
}

/// A Channel record whose topic string says 1.7 GB inside a short record: binrw reserves that
/// much before it finds the record too short. Refused; the reservation is never touched.
#[test]
fn crash_mcap_string_length_beyond_the_record() {
    let msg = replay("mcap", "string_length_beyond_the_record.mcap").expect("refused");
    assert!(msg.contains("b_0.mcap"), "{msg}");
}

/// A DICOM element whose length says 4 GB in a 1 KB file: dicom-rs allocated and zero-filled
/// the length before reading (4 GB resident). Now refused by the length walk, by name and byte
/// offset.
#[test]
fn crash_dicom_element_length_beyond_the_file() {
    let msg = replay("dicom", "element_length_beyond_the_file.dcm").expect("refused");
    assert!(msg.contains("at byte offset") && msg.contains("the file has"), "{msg}");
}

/// A VR code that no VR has ("0I"): dicom-rs reads it as UN, with a 4-byte length taken from
/// the value (700 MB resident). The walk reads it the same way and refuses the length.
#[test]
fn crash_dicom_unknown_vr_read_with_a_long_length() {
    let msg = replay("dicom", "unknown_vr_read_with_a_long_length.dcm").expect("refused");
    assert!(msg.contains("SOPClassUID (0008,0016) at byte offset 374"), "{msg}");
}

/// A CompressedImage whose JPEG frame header says 65535x65535: jpeg-decoder reserved 4 GiB for
/// a 600-byte image (found at 30 000 inputs, seed 77). Now refused by size before decoding.
#[test]
fn crash_cdr_compressed_image_jpeg_frame_65535_a_side() {
    // The message itself is well formed CDR; the edge detector refuses its image.
    assert_eq!(replay("cdr_compressed_image", "jpeg_frame_65535_a_side.cdr"), None);
    let input = std::fs::read(crashes_dir().join("cdr_compressed_image/jpeg_frame_65535_a_side.cdr")).unwrap();
    let Msg::CompressedImage(c) = Msg::decode("sensor_msgs/msg/CompressedImage", &input).unwrap() else { panic!() };
    let e = xsurf_formats::compressed::decode(&c.format, &c.data).unwrap_err();
    assert!(e.contains("65535x65535 is larger than 8192 pixels a side"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// The seed corpus, from our own writers.

/// Writes `tests/fuzz/corpus/` afresh (run by hand: `cargo test --release -p xsurf-nodes --test
/// fuzz -- --ignored write_seed_corpus`).
#[test]
#[ignore]
fn write_seed_corpus() {
    use xsurf_msgs::sensor_msgs::{CameraInfo, CompressedImage, Image, JointState};
    use xsurf_msgs::xsurf_msgs::ScanEvent;
    let root = corpus_dir();
    let _ = std::fs::remove_dir_all(&root);
    let put = |target: &str, name: &str, bytes: &[u8]| {
        let d = root.join(target);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join(name), bytes).unwrap();
    };
    let rig = xsurf_core::rig::Rig::study(64, 48);
    let model = rig.cameras[0].model().unwrap();
    let hdr = |sec: i32, frame: &str| {
        let mut h = xsurf_nodes::convert::header(0, frame);
        h.stamp.sec = sec;
        h
    };
    // Images: a bright vertical line on a dark 64x48 frame.
    let mut mono = xsurf_core::image::Image::new(64, 48, xsurf_core::image::Encoding::Mono8);
    for r in 0..48 {
        for (c, v) in [(30usize, 120u8), (31, 230), (32, 120)] {
            mono.data[r * 64 + c] = v;
        }
    }
    let image_msg = |img: &xsurf_core::image::Image| Image {
        header: hdr(1, "cam1_optical_frame"),
        height: img.height,
        width: img.width,
        encoding: img.encoding.ros_name().into(),
        is_bigendian: 0,
        step: img.step(),
        data: img.data.clone(),
    };
    let mut rgb = xsurf_core::image::Image::new(64, 48, xsurf_core::image::Encoding::Rgb8);
    for (i, px) in rgb.data.chunks_mut(3).enumerate() {
        px[0] = mono.data[i];
        px[1] = mono.data[i] / 4;
    }
    let enc = |m: &Msg| m.encode().unwrap();
    put("cdr_image", "mono8.cdr", &enc(&Msg::Image(Arc::new(image_msg(&mono)))));
    put("cdr_image", "rgb8.cdr", &enc(&Msg::Image(Arc::new(image_msg(&rgb)))));
    let png = xsurf_formats::image::encode_png(64, 48, xsurf_formats::image::PngKind::Grey8, &mono.data).unwrap();
    let jpeg = xsurf_formats::frames::encode_jpeg(&mono, 90).unwrap();
    for (name, format, data) in [("png.cdr", "png", &png), ("jpeg.cdr", "jpeg", &jpeg)] {
        let c = CompressedImage { header: hdr(1, "cam1_optical_frame"), format: format.into(), data: data.clone() };
        put("cdr_compressed_image", name, &enc(&Msg::CompressedImage(Arc::new(c))));
    }
    let info: CameraInfo = xsurf_nodes::convert::camera_info(&model, hdr(1, "cam1_optical_frame"));
    put("cdr_camera_info", "plumb_bob.cdr", &enc(&Msg::CameraInfo(Arc::new(info))));
    let tf = xsurf_msgs::tf2_msgs::TFMessage {
        transforms: vec![
            xsurf_nodes::convert::transform_stamped(
                1_000_000_000,
                "table",
                "carm",
                &rig.cameras[0].carm_from_optical(),
            ),
            xsurf_nodes::convert::transform_stamped(
                1_000_000_000,
                "carm",
                "cam1_optical_frame",
                &rig.cameras[0].carm_from_optical(),
            ),
        ],
    };
    put("cdr_tf", "two.cdr", &enc(&Msg::Tf(Arc::new(tf))));
    let mut line = xsurf_core::edge::LaserLine::default();
    let mut det = xsurf_core::edge::EdgeDetector::new(Default::default()).unwrap();
    det.detect(&mono.view().unwrap(), &mut line).unwrap();
    let line_msg = xsurf_nodes::convert::lines_msg(&[line], &[], hdr(1, "cam1_optical_frame"));
    put("cdr_laser_line", "mono8.cdr", &enc(&Msg::LaserLine(Arc::new(line_msg))));
    let profile = xsurf_core::triangulate::Profile {
        points: (0..12).map(|i| [0.01 * i as f32, 0.2, 0.3]).collect(),
        intensity: vec![80.0; 12],
        rgb: Some(vec![0x00ff8040; 12]),
        range: vec![0.5; 12],
        outside_volume: 0,
    };
    let cloud = xsurf_nodes::convert::profile_cloud(&profile, hdr(1, "table"));
    put("cdr_point_cloud", "profile.cdr", &enc(&Msg::Cloud(Arc::new(cloud))));
    let mut grid = xsurf_core::mesh::Grid::new(12);
    for f in 0..4 {
        let mut p = profile.clone();
        for q in &mut p.points {
            q[1] += 0.004 * f as f32;
        }
        grid.push(f, &p).unwrap();
    }
    put(
        "cdr_point_cloud",
        "grid.cdr",
        &enc(&Msg::Cloud(Arc::new(xsurf_nodes::convert::grid_cloud(&grid, hdr(2, "table"))))),
    );
    let mesh = xsurf_core::mesh::mesh_grid(&grid, &Default::default());
    let marker = xsurf_nodes::convert::mesh_marker(&mesh, hdr(2, "table"), "cam1", 3, 1.0);
    put("cdr_marker", "mesh.cdr", &enc(&Msg::Marker(Arc::new(marker))));
    for (name, event) in [("start.cdr", ScanEvent::START), ("end.cdr", ScanEvent::END)] {
        let e = ScanEvent { header: hdr(1, "table"), scan_id: 3, event };
        put("cdr_scan_event", name, &enc(&Msg::ScanEvent(Arc::new(e))));
    }
    let js = JointState {
        header: hdr(1, ""),
        name: vec!["carm_travel".into(), "carm_angle".into()],
        position: vec![0.25, 0.0],
        velocity: vec![0.07, 0.0],
        effort: vec![],
    };
    put("cdr_joint_state", "carm.cdr", &enc(&Msg::JointState(Arc::new(js))));
    let clock = xsurf_msgs::rosgraph_msgs::Clock { clock: xsurf_msgs::builtin_interfaces::Time { sec: 5, nanosec: 7 } };
    put("cdr_clock", "clock.cdr", &enc(&Msg::Clock(Arc::new(clock))));
    // A mesher's scan report (JSON in a std_msgs/String), as the merger takes it.
    let report = r#"{"scan_id":0,"camera":"cam1","aborted":false,"frames_expected":80,"frames_received":71,"frames_lost":9,"frames_without_line":4,"profiles_refused":0,"gaps":[{"after":"1700000000.634578400","before":"1700000000.833038799","frames":5}]}"#;
    let text = xsurf_msgs::std_msgs::StringMsg { data: report.into() };
    put("cdr_scan_report", "mesher.cdr", &enc(&Msg::Text(Arc::new(text))));

    // A small bag (one camera: camera_info, two images, tf, events), plain and zstd.
    for (name, zstd) in [("plain.mcap", false), ("zstd.mcap", true)] {
        let dir = std::env::temp_dir().join(format!("xsurf-fuzz-seed-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut w = xsurf_formats::bag::BagWriter::create_with_stem(&dir, "b", xsurf_formats::bag::BagOptions { zstd })
            .unwrap();
        let qos = xsurf_formats::bag::Qos::RELIABLE;
        let msgs: Vec<(&str, Msg)> = vec![
            ("/scan/events", Msg::ScanEvent(Arc::new(ScanEvent { header: hdr(1, "table"), scan_id: 1, event: 0 }))),
            (
                "/tf_static",
                Msg::decode("tf2_msgs/msg/TFMessage", &std::fs::read(root.join("cdr_tf/two.cdr")).unwrap()).unwrap(),
            ),
            (
                "/cam1/camera_info",
                Msg::CameraInfo(Arc::new(xsurf_nodes::convert::camera_info(&model, hdr(1, "cam1_optical_frame")))),
            ),
            ("/cam1/image_raw", Msg::Image(Arc::new(image_msg(&mono)))),
            ("/cam1/image_raw", Msg::Image(Arc::new(image_msg(&mono)))),
            ("/scan/events", Msg::ScanEvent(Arc::new(ScanEvent { header: hdr(2, "table"), scan_id: 1, event: 1 }))),
        ];
        for (topic, m) in &msgs {
            w.add_topic(topic, m.type_name(), &Msg::definition(m.type_name()).unwrap(), &qos).unwrap();
        }
        for (k, (topic, m)) in msgs.iter().enumerate() {
            let t = 1_000_000_000 + k as u64 * 1000;
            w.write(topic, t, t, &m.encode().unwrap()).unwrap();
        }
        w.finish().unwrap();
        put("mcap", name, &std::fs::read(dir.join("b_0.mcap")).unwrap());
        if !zstd {
            let meta = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
            put("bag_metadata", "metadata.yaml", meta.as_bytes());
            // The good metadata.yaml the mcap target puts beside its inputs (not a seed).
            put("mcap", "metadata.yaml.txt", meta.as_bytes());
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    let here = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    put("params_yaml", "launch-config.yaml", &std::fs::read(here.join("launch-config/params.yaml")).unwrap());
    put(
        "params_yaml",
        "nested.yaml",
        b"/**:\n  ros__parameters:\n    laser_plane: [0.0, 1.0, 0.0, 0.0]\n/cam1/edge_detector:\n  ros__parameters:\n    method: gaussian\n    roi:\n      x_offset: 4\n      width: 40\n",
    );
    put("launch_yaml", "xsurf.launch.yaml", &std::fs::read(here.join("launch-config/xsurf.launch.yaml")).unwrap());
    put("rig_yaml", "rig_study.yaml", &std::fs::read(here.join("launch-config/rig_study.yaml")).unwrap());
    let cal = xsurf_formats::calibration::CameraCalibration::from_model("cam1", &model);
    put("camera_calibration_yaml", "cam1.yaml", cal.to_yaml().as_bytes());

    let tmp = std::env::temp_dir().join(format!("xsurf-fuzz-seed-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let px: Vec<u16> = (0..16 * 8).map(|i| (i * 97 % 4000) as u16).collect();
    let radiograph = xsurf_core::xray::Radiograph::new(16, 8, px, 12).unwrap();
    let xinfo = xsurf_formats::dicom::XrayInfo {
        source_detector_m: Some(1.3),
        pixel_spacing_m: Some([0.001, 0.001]),
        acquisition_start_ns: Some(1_700_000_000_000_000_000),
        exposure_ms: Some(12.0),
    };
    let dcm = tmp.join("x.dcm");
    xsurf_formats::dicom::write_file(&dcm, &radiograph, &xinfo, "fuzz").unwrap();
    put("dicom", "radiograph.dcm", &std::fs::read(&dcm).unwrap());
    put("dicom_study", "radiograph.dcm", &std::fs::read(&dcm).unwrap());
    // A C-STORE-RSP command set as a PACS sends it (Implicit VR Little Endian).
    let el =
        |e: u16, v: &[u8]| [&0u16.to_le_bytes()[..], &e.to_le_bytes(), &(v.len() as u32).to_le_bytes(), v].concat();
    let class = b"1.2.840.10008.5.1.4.1.1.68.1\0";
    let body = [
        el(0x0002, class),
        el(0x0100, &0x8001u16.to_le_bytes()),
        el(0x0120, &1u16.to_le_bytes()),
        el(0x0800, &0x0101u16.to_le_bytes()),
        el(0x0900, &0u16.to_le_bytes()),
    ]
    .concat();
    put("dimse_response", "c_store_rsp.bin", &[el(0x0000, &(body.len() as u32).to_le_bytes()), body].concat());
    let ply = tmp.join("m.ply");
    xsurf_formats::ply::write_file(&ply, &mesh).unwrap();
    put("ply", "mesh.ply", &std::fs::read(&ply).unwrap());
    let small = {
        let mut s = xsurf_core::image::Image::new(16, 12, xsurf_core::image::Encoding::Mono8);
        for (i, v) in s.data.iter_mut().enumerate() {
            *v = (i * 7) as u8;
        }
        s
    };
    let bmp = tmp.join("f.bmp");
    xsurf_formats::frames::write_bmp_mono8(&bmp, &small).unwrap();
    put("bmp", "mono8.bmp", &std::fs::read(&bmp).unwrap());
    let pgm = tmp.join("f.pgm");
    xsurf_formats::frames::write_pgm(&pgm, &small).unwrap();
    put("pgm", "mono8.pgm", &std::fs::read(&pgm).unwrap());
    let png_small =
        xsurf_formats::image::encode_png(16, 12, xsurf_formats::image::PngKind::Grey8, &small.data).unwrap();
    put("png", "mono8.png", &png_small);
    let rgb_small: Vec<u8> = small.data.iter().flat_map(|&v| [v, v / 2, 255 - v]).collect();
    put(
        "png",
        "rgb8.png",
        &xsurf_formats::image::encode_png(16, 12, xsurf_formats::image::PngKind::Rgb8, &rgb_small).unwrap(),
    );
    put(
        "ros_args",
        "full.args",
        b"--ros-args\n-r\n__ns:=/cam1\n-r\n__node:=ed\n-r\nimage_raw:=/camera/image\n-p\nmethod:=gaussian\n-p\nroi.width:=40\n-p\nlaser_plane:=[0.0, 1.0, 0.0, 0.0]\n--log-level\ndebug\n--\nuser",
    );
    put(
        "ros_args",
        "params_file.args",
        b"--ros-args\n--params-file\n../launch-config/params.yaml\n-p\nmin_strength:=8.5",
    );
    std::fs::remove_dir_all(&tmp).unwrap();
}
