//! The camera_calibration YAML that ROS 2's camera_info_manager reads and writes
//! (`image_width`, `image_height`, `camera_name`, `camera_matrix`, `distortion_model`,
//! `distortion_coefficients`, `rectification_matrix`, `projection_matrix`), and
//! `camera_info_url`s (`file:///path`, or a plain path).

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use xsurf_core::camera::CameraModel;

/// A matrix as the format stores it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Matrix {
    /// Rows.
    pub rows: u32,
    /// Columns.
    pub cols: u32,
    /// Row-major values.
    pub data: Vec<f64>,
}

/// One camera's calibration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraCalibration {
    /// Image width, pixels.
    pub image_width: u32,
    /// Image height, pixels.
    pub image_height: u32,
    /// Camera name.
    pub camera_name: String,
    /// K (3x3).
    pub camera_matrix: Matrix,
    /// `plumb_bob` or `rational_polynomial`.
    pub distortion_model: String,
    /// D (1xN).
    pub distortion_coefficients: Matrix,
    /// R (3x3).
    pub rectification_matrix: Matrix,
    /// P (3x4).
    pub projection_matrix: Matrix,
}

/// A calibration file that cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("{}: {what}", file.display())]
pub struct CalibrationError {
    /// The file (or URL).
    pub file: PathBuf,
    /// What is wrong.
    pub what: String,
}

impl CameraCalibration {
    /// The calibration of a camera model (R identity, P = [K | 0]).
    pub fn from_model(name: &str, m: &CameraModel) -> Self {
        let (model, d) = m.distortion.to_ros();
        let mat = |rows, cols, data| Matrix { rows, cols, data };
        Self {
            image_width: m.width,
            image_height: m.height,
            camera_name: name.to_string(),
            camera_matrix: mat(3, 3, m.k().to_vec()),
            distortion_model: model.to_string(),
            distortion_coefficients: mat(1, d.len() as u32, d),
            rectification_matrix: mat(3, 3, vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
            projection_matrix: mat(3, 4, vec![m.fx, 0.0, m.cx, 0.0, 0.0, m.fy, m.cy, 0.0, 0.0, 0.0, 1.0, 0.0]),
        }
    }

    /// The camera model it describes.
    pub fn model(&self) -> Result<CameraModel, String> {
        let k = &self.camera_matrix;
        if (k.rows, k.cols, k.data.len()) != (3, 3, 9) {
            return Err(format!("camera_matrix is {}x{} with {} values, expected 3x3", k.rows, k.cols, k.data.len()));
        }
        let d = &self.distortion_coefficients;
        if d.data.len() != (d.rows * d.cols) as usize {
            return Err(format!("distortion_coefficients has {} values for {}x{}", d.data.len(), d.rows, d.cols));
        }
        CameraModel::from_ros(self.image_width, self.image_height, &k.data, &self.distortion_model, &d.data)
            .map_err(|e| e.to_string())
    }
}

/// The file of a `camera_info_url`: `file:///abs/path` or a plain path (`package://` needs a ROS
/// installation and is refused).
pub fn url_path(url: &str) -> Result<PathBuf, String> {
    if let Some(p) = url.strip_prefix("file://") {
        return Ok(PathBuf::from(p));
    }
    if url.contains("://") {
        return Err(format!("camera_info_url {url:?}: only file:// URLs and paths are supported"));
    }
    Ok(PathBuf::from(url))
}

/// Reads a calibration file.
pub fn read(path: &Path) -> Result<CameraCalibration, CalibrationError> {
    let err = |what: String| CalibrationError { file: path.to_path_buf(), what };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    let c: CameraCalibration = serde_yaml::from_str(&text).map_err(|e| err(e.to_string()))?;
    c.model().map_err(err)?;
    Ok(c)
}

impl CameraCalibration {
    /// The file's text, laid out as ROS 2's camera_calibration_parsers writes it (keys in its
    /// order, matrices as `rows`, `cols` and a flow sequence `data`); every number keeps its full
    /// precision and is written as a float.
    pub fn to_yaml(&self) -> String {
        let num = |v: f64| format!("{v:?}");
        let matrix = |name: &str, m: &Matrix| {
            let data: Vec<String> = m.data.iter().map(|&v| num(v)).collect();
            format!("{name}:\n  rows: {}\n  cols: {}\n  data: [{}]\n", m.rows, m.cols, data.join(", "))
        };
        // The camera name is quoted only when YAML would read it as something else.
        let name = if self.camera_name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            && self.camera_name.starts_with(|c: char| c.is_ascii_alphabetic())
        {
            self.camera_name.clone()
        } else {
            format!("{:?}", self.camera_name)
        };
        format!(
            "image_width: {}\nimage_height: {}\ncamera_name: {name}\n{}distortion_model: {}\n{}{}{}",
            self.image_width,
            self.image_height,
            matrix("camera_matrix", &self.camera_matrix),
            self.distortion_model,
            matrix("distortion_coefficients", &self.distortion_coefficients),
            matrix("rectification_matrix", &self.rectification_matrix),
            matrix("projection_matrix", &self.projection_matrix),
        )
    }
}

/// Writes a calibration file atomically (see [`CameraCalibration::to_yaml`]).
pub fn write(path: &Path, c: &CameraCalibration) -> Result<(), crate::FileError> {
    crate::write_bytes_atomic(path, c.to_yaml().as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_camera_calibration_format_and_round_trips() {
        // As camera_calibration's cameracalibrator writes it.
        let text = "image_width: 640\nimage_height: 480\ncamera_name: narrow_stereo\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [700.1, 0, 322.4, 0, 701.2, 237.6, 0, 0, 1]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [-0.12, 0.05, 0.0005, -0.0003, 0]\nrectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nprojection_matrix:\n  rows: 3\n  cols: 4\n  data: [700.1, 0, 322.4, 0, 0, 701.2, 237.6, 0, 0, 0, 1, 0]\n";
        let dir = std::env::temp_dir().join(format!("xsurf-calib-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("c.yaml"), text).unwrap();
        let c = read(&dir.join("c.yaml")).unwrap();
        let m = c.model().unwrap();
        assert_eq!((m.fx, m.fy, m.cx, m.cy), (700.1, 701.2, 322.4, 237.6));
        assert_eq!(CameraCalibration::from_model("narrow_stereo", &m), c);
        write(&dir.join("d.yaml"), &c).unwrap();
        assert_eq!(read(&dir.join("d.yaml")).unwrap(), c);
        let written = std::fs::read_to_string(dir.join("d.yaml")).unwrap();
        assert!(written.starts_with("image_width: 640\nimage_height: 480\ncamera_name: narrow_stereo\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [700.1, 0.0, 322.4,"), "{written}");
        let odd = CameraCalibration { camera_name: "cam 1: left".into(), ..c.clone() };
        write(&dir.join("e.yaml"), &odd).unwrap();
        assert_eq!(read(&dir.join("e.yaml")).unwrap(), odd);
        assert_eq!(url_path("file:///tmp/x.yaml").unwrap(), PathBuf::from("/tmp/x.yaml"));
        assert!(url_path("package://cam/x.yaml").is_err());
        std::fs::write(
            dir.join("bad.yaml"),
            text.replace("rows: 3\n  cols: 3\n  data: [700.1", "rows: 2\n  cols: 3\n  data: [700.1"),
        )
        .unwrap();
        let e = read(&dir.join("bad.yaml")).unwrap_err().to_string();
        assert!(e.contains("bad.yaml") && e.contains("camera_matrix"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
