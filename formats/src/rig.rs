//! The rig file (YAML, `xsurf_core::rig::Rig`; documented in `launch-config/rig_study.yaml`):
//! read by `camera_driver` and `c_arm_pose`, written by `xsurf synth` and `xsurf calibrate`.

use std::path::{Path, PathBuf};
use xsurf_core::rig::Rig;

/// A rig file that cannot be read.
#[derive(Debug, thiserror::Error)]
#[error("{}: {what}", file.display())]
pub struct RigFileError {
    /// The file.
    pub file: PathBuf,
    /// What is wrong.
    pub what: String,
}

/// Reads a rig file and validates it ([`Rig::validate`]): every reader refuses the same rigs.
pub fn read(path: &Path) -> Result<Rig, RigFileError> {
    let err = |what: String| RigFileError { file: path.to_path_buf(), what };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    let rig: Rig = serde_yaml::from_str(&text)
        .map_err(|e| err(format!("not a rig file (see launch-config/rig_study.yaml): {e}")))?;
    rig.validate().map_err(err)?;
    Ok(rig)
}

/// Writes a rig file atomically; each line of `header` becomes a comment above it.
pub fn write(path: &Path, rig: &Rig, header: &str) -> Result<(), crate::FileError> {
    let body = serde_yaml::to_string(rig).map_err(|e| crate::FileError::new(path, std::io::Error::other(e)))?;
    let comments: String = header.lines().map(|l| format!("# {l}\n")).collect();
    crate::write_bytes_atomic(path, format!("{comments}{body}").as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_names_a_bad_file() {
        let dir = std::env::temp_dir().join(format!("xsurf-rig-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let rig = Rig::study(320, 240);
        write(&dir.join("r.yaml"), &rig, "a test\nrig").unwrap();
        let text = std::fs::read_to_string(dir.join("r.yaml")).unwrap();
        assert!(text.starts_with("# a test\n# rig\n"), "{text}");
        assert_eq!(read(&dir.join("r.yaml")).unwrap(), rig);
        std::fs::write(dir.join("bad.yaml"), "cameras: 3\n").unwrap();
        let e = read(&dir.join("bad.yaml")).unwrap_err().to_string();
        assert!(e.contains("bad.yaml") && e.contains("not a rig file"), "{e}");
        // Parsed but invalid: refused with the file, the camera and the field.
        let mut dup = rig.clone();
        dup.cameras[1].name = "cam1".into();
        write(&dir.join("dup.yaml"), &dup, "").unwrap();
        let e = read(&dir.join("dup.yaml")).unwrap_err().to_string();
        assert!(e.contains("dup.yaml") && e.contains("cameras[1] (\"cam1\")"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
