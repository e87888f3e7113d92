//! Calibration: the camera intrinsics from checkerboard views (Zhang's method refined by
//! Levenberg-Marquardt over the ROS distortion models), each camera's placement on the C-arm
//! from a board lying on the tabletop, and the laser plane from the line on the tabletop at
//! several heights. Pure: images in, numbers and residuals out.

pub mod board;
pub mod intrinsics;
pub mod laser;
pub mod linalg;
pub mod lm;
pub mod placement;

use crate::geom::{Iso3, Mat3, Vec3};
use linalg::sym_eigen;

/// Why a calibration could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibError {
    /// Not enough usable views (the reasons for the others are in the message).
    #[error("{what}: {usable} usable, {needed} needed{reasons}")]
    TooFewViews {
        /// What was being calibrated.
        what: &'static str,
        /// Usable views.
        usable: usize,
        /// Views needed.
        needed: usize,
        /// Why the others were not used, one line each.
        reasons: String,
    },
    /// The data cannot determine the result.
    #[error("degenerate: {0}")]
    Degenerate(String),
}

/// The homography `H` (row-major) mapping plane points `(X, Y, 1)` to image points `(x, y, 1)`,
/// by the normalised direct linear transform. `None` for fewer than 4 points or a degenerate set.
pub fn homography(plane: &[[f64; 2]], image: &[[f64; 2]]) -> Option<[f64; 9]> {
    if plane.len() < 4 || plane.len() != image.len() {
        return None;
    }
    let norm = |pts: &[[f64; 2]]| {
        let n = pts.len() as f64;
        let (mx, my) = (pts.iter().map(|p| p[0]).sum::<f64>() / n, pts.iter().map(|p| p[1]).sum::<f64>() / n);
        let d = pts.iter().map(|p| ((p[0] - mx).powi(2) + (p[1] - my).powi(2)).sqrt()).sum::<f64>() / n;
        let s = if d > 1e-300 { std::f64::consts::SQRT_2 / d } else { 1.0 };
        [s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0]
    };
    let (ta, tb) = (norm(plane), norm(image));
    let apply = |t: &[f64; 9], p: [f64; 2]| [t[0] * p[0] + t[2], t[4] * p[1] + t[5]];
    let mut ata = [0.0; 81];
    for (p, q) in plane.iter().zip(image) {
        let (a, b) = (apply(&ta, *p), apply(&tb, *q));
        let rows = [
            [a[0], a[1], 1.0, 0.0, 0.0, 0.0, -b[0] * a[0], -b[0] * a[1], -b[0]],
            [0.0, 0.0, 0.0, a[0], a[1], 1.0, -b[1] * a[0], -b[1] * a[1], -b[1]],
        ];
        for r in &rows {
            for i in 0..9 {
                for j in 0..9 {
                    ata[i * 9 + j] += r[i] * r[j];
                }
            }
        }
    }
    let (vals, vecs) = sym_eigen(&ata, 9);
    if vals.len() < 2 || !(vals[1] > 1e-12 * vals[8].max(1e-300)) {
        return None;
    }
    let hn = &vecs[0];
    // H = Tb^-1 Hn Ta.
    let tb_inv = [1.0 / tb[0], 0.0, -tb[2] / tb[0], 0.0, 1.0 / tb[4], -tb[5] / tb[4], 0.0, 0.0, 1.0];
    let mul = |a: &[f64], b: &[f64]| {
        let mut r = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                r[i * 3 + j] = (0..3).map(|k| a[i * 3 + k] * b[k * 3 + j]).sum();
            }
        }
        r
    };
    let h = mul(&mul(&tb_inv, hn), &ta);
    let s = h[8];
    if s.abs() < 1e-300 {
        return None;
    }
    Some(h.map(|v| v / s))
}

/// The pose of a plane (`camera <- plane`) from its homography onto normalised image
/// coordinates (`K^-1` applied), in front of the camera.
pub fn pose_from_homography(h: &[f64; 9]) -> Option<Iso3> {
    let col = |c: usize| Vec3::new(h[c], h[3 + c], h[6 + c]);
    let (h1, h2, h3) = (col(0), col(1), col(2));
    let scale = 2.0 / (h1.norm() + h2.norm());
    if !scale.is_finite() {
        return None;
    }
    let sign = if h3.z * scale < 0.0 { -1.0 } else { 1.0 };
    let s = scale * sign;
    let r1 = (h1 * s).try_normalize()?;
    let r2 = h2 * s;
    let r2 = (r2 - r1 * r2.dot(r1)).try_normalize()?;
    let r3 = r1.cross(r2);
    Some(Iso3 { rotation: Mat3::from_columns(r1, r2, r3), translation: h3 * s })
}

/// A pose perturbed by a rotation vector (applied on the left) and a translation step: the
/// retraction the solvers use.
pub(crate) fn retract_pose(p: &Iso3, d: &[f64]) -> Iso3 {
    let r = Mat3::from_rotation_vector(Vec3::new(d[0], d[1], d[2]));
    Iso3 { rotation: r.mul_mat(&p.rotation), translation: p.translation + Vec3::new(d[3], d[4], d[5]) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homography_and_pose_of_a_known_plane() {
        let truth = Iso3 {
            rotation: Mat3::rot_x(0.3).mul_mat(&Mat3::rot_y(-0.2)).mul_mat(&Mat3::rot_z(0.4)),
            translation: Vec3::new(0.05, -0.02, 0.7),
        };
        let plane: Vec<[f64; 2]> = (0..20).map(|k| [(k % 5) as f64 * 0.03, (k / 5) as f64 * 0.03]).collect();
        let image: Vec<[f64; 2]> = plane
            .iter()
            .map(|p| {
                let q = truth.transform_point(Vec3::new(p[0], p[1], 0.0));
                [q.x / q.z, q.y / q.z]
            })
            .collect();
        let h = homography(&plane, &image).unwrap();
        let pose = pose_from_homography(&h).unwrap();
        assert!((pose.translation - truth.translation).norm() < 1e-9, "{pose:?}");
        assert!(pose.rotation.angle_to(&truth.rotation) < 1e-9);
        assert!(homography(&plane[..3], &image[..3]).is_none());
        let collinear: Vec<[f64; 2]> = (0..6).map(|k| [k as f64, 2.0 * k as f64]).collect();
        assert!(homography(&collinear, &collinear).is_none());
    }
}
