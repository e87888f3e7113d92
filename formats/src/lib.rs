//! # xsurf-formats
//!
//! File formats, each on `Read`/`Write` or byte slices with thin filesystem wrappers:
//! [`ply`] (binary PLY, writer and reader), [`vrml`] (VRML 2.0 scenes), [`gltf`] (binary glTF
//! scenes), [`image`] (PNG), [`bag`] (rosbag2 directories with MCAP storage). Every file is
//! written atomically: to a temporary name beside the target, synced, then renamed, so no
//! half-written file ever stands under the final name.
#![deny(missing_docs)]

pub mod bag;
pub mod calibration;
pub mod compressed;
pub mod dicom;
pub mod dicom_surface;
pub mod frames;
pub mod gltf;
pub mod image;
pub mod plot;
pub mod ply;
pub mod preview;
pub mod rig;
pub mod scene;
pub mod vrml;

use std::io::Write;
use std::path::{Path, PathBuf};

/// An I/O error with the path it concerns. The message carries the cause, so the cause is not
/// also given as the error's source (a chain printed with `{:#}` would say it twice).
#[derive(Debug, thiserror::Error)]
#[error("{path}: {cause}")]
pub struct FileError {
    /// The file.
    pub path: PathBuf,
    /// The cause.
    pub cause: std::io::Error,
}

impl FileError {
    /// Wraps an I/O error with its path.
    pub fn new(path: &Path, cause: std::io::Error) -> Self {
        Self { path: path.to_path_buf(), cause }
    }
}

/// Why `path` cannot be read as a file ("does not exist", "is a folder, not a file", or the
/// system's reason), or `None` if it is a file.
pub fn file_problem(path: &Path) -> Option<String> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => None,
        Ok(m) if m.is_dir() => Some("is a folder, not a file".into()),
        Ok(_) => Some("is not a regular file".into()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Some("does not exist".into()),
        Err(e) => Some(e.to_string()),
    }
}

/// Writes a file atomically: `write` fills a temporary file beside `path`, which is synced and
/// renamed over `path` only if `write` succeeds.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), FileError> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| {
        let file = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::new(file);
        write(&mut w)?;
        w.flush()?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(|e| FileError::new(path, e))
}

/// Writes bytes to a file atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    write_atomic(path, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A write under a file (not a folder) names the path and the cause once, also when the
    /// error is printed with its chain of sources (it was "...: Not a directory (os error 20):
    /// Not a directory (os error 20)").
    #[test]
    fn a_file_error_says_its_cause_once() {
        let dir = std::env::temp_dir().join(format!("xsurf-fileerror-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("plain"), b"x").unwrap();
        let e = write_bytes_atomic(&dir.join("plain/out.bin"), b"y").unwrap_err();
        let mut text = e.to_string();
        let mut src = std::error::Error::source(&e);
        while let Some(s) = src {
            text.push_str(&format!(": {s}"));
            src = s.source();
        }
        assert!(text.contains("plain/out.bin"), "{text}");
        let cause = e.cause.to_string();
        assert_eq!(text.matches(cause.as_str()).count(), 1, "{text}");
        assert_eq!(file_problem(&dir.join("plain")), None);
        assert_eq!(file_problem(&dir).as_deref(), Some("is a folder, not a file"));
        assert_eq!(file_problem(&dir.join("none")).as_deref(), Some("does not exist"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn failed_write_leaves_no_file() {
        let dir = std::env::temp_dir().join(format!("xsurf-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("out.bin");
        let r = write_atomic(&target, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk full"))
        });
        assert!(r.is_err());
        assert!(!target.exists());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "temporary removed");
        write_bytes_atomic(&target, b"whole").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"whole");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
