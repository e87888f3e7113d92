//! Pinhole camera with the ROS distortion models (`plumb_bob`, `rational_polynomial`).
//!
//! Pixel coordinates follow ROS `CameraInfo`: the centre of the top-left pixel is (0, 0).

use crate::geom::Vec3;
use serde::{Deserialize, Serialize};

/// Lens distortion, as named in `sensor_msgs/CameraInfo.distortion_model`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum Distortion {
    /// No distortion (an empty `D`).
    None,
    /// Brown-Conrady: `D = [k1, k2, p1, p2, k3]`.
    PlumbBob {
        /// Radial, r^2.
        k1: f64,
        /// Radial, r^4.
        k2: f64,
        /// Tangential 1.
        p1: f64,
        /// Tangential 2.
        p2: f64,
        /// Radial, r^6.
        k3: f64,
    },
    /// OpenCV rational model: `D = [k1, k2, p1, p2, k3, k4, k5, k6]`.
    RationalPolynomial {
        /// `[k1, k2, p1, p2, k3, k4, k5, k6]`.
        d: [f64; 8],
    },
}

/// Why a camera description was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// The distortion model name is not one we handle.
    #[error("unsupported distortion model {0:?} (expected plumb_bob, rational_polynomial or empty)")]
    UnsupportedModel(String),
    /// `D` has the wrong number of coefficients for the model.
    #[error("distortion model {model} needs {expected} coefficients in D, got {got}")]
    WrongCoefficientCount {
        /// The model.
        model: String,
        /// How many it needs.
        expected: usize,
        /// How many there were.
        got: usize,
    },
    /// Focal lengths must be positive and finite, the image non-empty.
    #[error("invalid intrinsics: {0}")]
    InvalidIntrinsics(String),
}

impl Distortion {
    /// From a ROS `distortion_model` string and its `D` vector.
    pub fn from_ros(model: &str, d: &[f64]) -> Result<Distortion, CameraError> {
        let need = |n: usize| {
            if d.len() == n {
                Ok(())
            } else {
                Err(CameraError::WrongCoefficientCount { model: model.to_string(), expected: n, got: d.len() })
            }
        };
        match model {
            "" | "none" => Ok(Distortion::None),
            "plumb_bob" if d.is_empty() || d.iter().all(|v| *v == 0.0) => Ok(Distortion::None),
            "plumb_bob" => {
                need(5)?;
                Ok(Distortion::PlumbBob { k1: d[0], k2: d[1], p1: d[2], p2: d[3], k3: d[4] })
            }
            "rational_polynomial" => {
                need(8)?;
                let mut a = [0.0; 8];
                a.copy_from_slice(d);
                Ok(Distortion::RationalPolynomial { d: a })
            }
            other => Err(CameraError::UnsupportedModel(other.to_string())),
        }
    }

    /// The ROS `distortion_model` name and `D` vector.
    pub fn to_ros(&self) -> (&'static str, Vec<f64>) {
        match *self {
            Distortion::None => ("plumb_bob", vec![0.0; 5]),
            Distortion::PlumbBob { k1, k2, p1, p2, k3 } => ("plumb_bob", vec![k1, k2, p1, p2, k3]),
            Distortion::RationalPolynomial { d } => ("rational_polynomial", d.to_vec()),
        }
    }

    /// Applies the distortion to normalised image coordinates.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let (k1, k2, p1, p2, k3, k4, k5, k6) = match *self {
            Distortion::None => return (x, y),
            Distortion::PlumbBob { k1, k2, p1, p2, k3 } => (k1, k2, p1, p2, k3, 0.0, 0.0, 0.0),
            Distortion::RationalPolynomial { d } => (d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]),
        };
        let r2 = x * x + y * y;
        let r4 = r2 * r2;
        let r6 = r4 * r2;
        let radial = (1.0 + k1 * r2 + k2 * r4 + k3 * r6) / (1.0 + k4 * r2 + k5 * r4 + k6 * r6);
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Inverts [`Distortion::distort`] by Newton's method. `None` if it does not converge
    /// (far outside the region where the model is invertible).
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        if matches!(self, Distortion::None) {
            return Some((xd, yd));
        }
        const H: f64 = 1e-7;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..30 {
            let (fx, fy) = self.distort(x, y);
            let (ex, ey) = (fx - xd, fy - yd);
            if ex.abs() < 1e-14 && ey.abs() < 1e-14 {
                return Some((x, y));
            }
            let (ax, ay) = self.distort(x + H, y);
            let (bx, by) = self.distort(x, y + H);
            let (j11, j21, j12, j22) = ((ax - fx) / H, (ay - fy) / H, (bx - fx) / H, (by - fy) / H);
            let det = j11 * j22 - j12 * j21;
            if !det.is_finite() || det.abs() < 1e-12 {
                return None;
            }
            x -= (j22 * ex - j12 * ey) / det;
            y -= (-j21 * ex + j11 * ey) / det;
        }
        let (fx, fy) = self.distort(x, y);
        ((fx - xd).abs() < 1e-9 && (fy - yd).abs() < 1e-9).then_some((x, y))
    }
}

/// Intrinsics of one camera, as in `sensor_msgs/CameraInfo` (no binning, full ROI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraModel {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length in x, pixels.
    pub fx: f64,
    /// Focal length in y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Lens distortion.
    pub distortion: Distortion,
}

impl CameraModel {
    /// From the ROS layout (`camera_info`, camera_calibration files): row-major `K` (at least 9
    /// values), the distortion model's name and `D`; validated.
    pub fn from_ros(
        width: u32,
        height: u32,
        k: &[f64],
        distortion_model: &str,
        d: &[f64],
    ) -> Result<CameraModel, CameraError> {
        if k.len() < 9 {
            return Err(CameraError::InvalidIntrinsics(format!("K has {} values, needs 9", k.len())));
        }
        let m = CameraModel {
            width,
            height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion: Distortion::from_ros(distortion_model, d)?,
        };
        m.validate()?;
        Ok(m)
    }

    /// Checks that the intrinsics can be used.
    pub fn validate(&self) -> Result<(), CameraError> {
        let ok = |v: f64| v.is_finite();
        if self.width == 0 || self.height == 0 {
            return Err(CameraError::InvalidIntrinsics(format!("image size {}x{}", self.width, self.height)));
        }
        if !(self.fx > 0.0 && self.fy > 0.0 && ok(self.fx) && ok(self.fy) && ok(self.cx) && ok(self.cy)) {
            return Err(CameraError::InvalidIntrinsics(format!(
                "fx {} fy {} cx {} cy {}",
                self.fx, self.fy, self.cx, self.cy
            )));
        }
        Ok(())
    }

    /// Projects a point in the optical frame to pixel coordinates (`None` behind the camera).
    pub fn project(&self, p: Vec3) -> Option<(f64, f64)> {
        if p.z <= 1e-9 {
            return None;
        }
        let (xd, yd) = self.distortion.distort(p.x / p.z, p.y / p.z);
        Some((self.fx * xd + self.cx, self.fy * yd + self.cy))
    }

    /// The viewing ray through pixel `(u, v)` in the optical frame, with z = 1.
    pub fn ray(&self, u: f64, v: f64) -> Option<Vec3> {
        let (x, y) = self.distortion.undistort((u - self.cx) / self.fx, (v - self.cy) / self.fy)?;
        Some(Vec3::new(x, y, 1.0))
    }

    /// This camera at another resolution (intrinsics scaled; distortion unchanged).
    pub fn scaled(&self, width: u32, height: u32) -> CameraModel {
        let sx = f64::from(width) / f64::from(self.width);
        let sy = f64::from(height) / f64::from(self.height);
        CameraModel {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
            distortion: self.distortion,
        }
    }

    /// The 3x3 camera matrix `K`, row-major.
    pub fn k(&self) -> [f64; 9] {
        [self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(distortion: Distortion) -> CameraModel {
        CameraModel { width: 640, height: 480, fx: 700.0, fy: 702.0, cx: 321.3, cy: 238.1, distortion }
    }

    #[test]
    fn project_then_ray_returns_the_direction() {
        for d in [
            Distortion::None,
            Distortion::PlumbBob { k1: -0.12, k2: 0.05, p1: 0.0005, p2: -0.0003, k3: 0.0 },
            Distortion::RationalPolynomial { d: [0.3, -0.1, 0.001, 0.0005, 0.01, 0.4, -0.05, 0.02] },
        ] {
            let c = cam(d);
            let p = Vec3::new(0.2, -0.15, 0.9);
            let (u, v) = c.project(p).unwrap();
            let r = c.ray(u, v).unwrap();
            assert!((r * p.z - p).norm() < 1e-10, "{d:?}: {r:?}");
        }
    }

    #[test]
    fn ros_names_round_trip() {
        let d = Distortion::PlumbBob { k1: 0.1, k2: 0.2, p1: 0.3, p2: 0.4, k3: 0.5 };
        let (name, v) = d.to_ros();
        assert_eq!(Distortion::from_ros(name, &v).unwrap(), d);
        assert!(matches!(Distortion::from_ros("equidistant", &[0.0; 4]), Err(CameraError::UnsupportedModel(_))));
        assert!(matches!(
            Distortion::from_ros("rational_polynomial", &[0.0; 5]),
            Err(CameraError::WrongCoefficientCount { expected: 8, got: 5, .. })
        ));
    }

    #[test]
    fn invalid_intrinsics_are_refused() {
        let mut c = cam(Distortion::None);
        c.fx = 0.0;
        assert!(c.validate().is_err());
        c.fx = f64::NAN;
        assert!(c.validate().is_err());
    }
}
