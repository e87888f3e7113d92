//! The laser plane in `carm` from the laser line on the flat tabletop at two or more tabletop
//! heights: each line pixel's ray (through a calibrated camera) meets the tabletop, whose plane
//! in `carm` is `z = height` (see the `carm` frame: `table -> carm` = (0, travel, -h)); a
//! plane is fitted to all those points (total least squares, then once more without points
//! beyond three standard deviations).

use super::linalg::sym_eigen;
use super::CalibError;
use crate::geom::{Plane, Vec3};
use crate::triangulate::CameraGeometry;

/// The laser line seen by one camera with the tabletop at one height.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserView {
    /// The camera (intrinsics and placement on the C-arm).
    pub camera: CameraGeometry,
    /// Tabletop height change since calibration (the `h` of `table -> carm`), metres.
    pub height_m: f64,
    /// Line centre pixels `(u, v)`.
    pub pixels: Vec<[f64; 2]>,
}

/// The plane found.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserResult {
    /// The laser plane in `carm`, oriented to agree with the reference normal given.
    pub plane: Plane,
    /// RMS distance of the points used from the plane, metres.
    pub rms_m: f64,
    /// Largest distance of a point used, metres.
    pub max_m: f64,
    /// Per view: the signed distance of each of its points from the plane, metres (NaN for a
    /// pixel whose ray misses the tabletop).
    pub residuals: Vec<Vec<f64>>,
    /// Per view: the points in `carm`.
    pub points: Vec<Vec<Vec3>>,
    /// Points used in the final fit.
    pub used: usize,
    /// Points dropped as outliers.
    pub dropped: usize,
}

/// The tabletop points of one view, in `carm`.
pub fn tabletop_points(view: &LaserView) -> Vec<Vec3> {
    let c = &view.camera;
    let eye = c.carm_from_optical.translation;
    view.pixels
        .iter()
        .map(|p| {
            let Some(ray) = c.model.ray(p[0], p[1]) else { return Vec3::new(f64::NAN, f64::NAN, f64::NAN) };
            let d = c.carm_from_optical.transform_vector(ray);
            let t = (view.height_m - eye.z) / d.z;
            if d.z.abs() < 1e-12 || t <= 0.0 {
                Vec3::new(f64::NAN, f64::NAN, f64::NAN)
            } else {
                eye + d * t
            }
        })
        .collect()
}

fn fit(points: &[Vec3]) -> Option<(Plane, [f64; 3])> {
    let n = points.len() as f64;
    if points.len() < 3 {
        return None;
    }
    let c = points.iter().fold(Vec3::ZERO, |a, &p| a + p) / n;
    let mut cov = [0.0; 9];
    for p in points {
        let d = *p - c;
        let v = [d.x, d.y, d.z];
        for i in 0..3 {
            for j in 0..3 {
                cov[i * 3 + j] += v[i] * v[j] / n;
            }
        }
    }
    let (vals, vecs) = sym_eigen(&cov, 3);
    let normal = Vec3::new(vecs[0][0], vecs[0][1], vecs[0][2]).try_normalize()?;
    Some((Plane { normal, d: normal.dot(c) }, [vals[0], vals[1], vals[2]]))
}

/// Fits the laser plane; `reference_normal` orients the result (the rig's current normal).
pub fn calibrate(views: &[LaserView], reference_normal: Vec3) -> Result<LaserResult, CalibError> {
    let points: Vec<Vec<Vec3>> = views.iter().map(tabletop_points).collect();
    let mut reasons = String::new();
    for (v, pts) in points.iter().enumerate() {
        let ok = pts.iter().filter(|p| p.is_finite()).count();
        if ok < 10 {
            reasons.push_str(&format!("\n  view {v}: laser line not found ({ok} points on the tabletop)"));
        }
    }
    let usable: Vec<usize> =
        (0..views.len()).filter(|&v| points[v].iter().filter(|p| p.is_finite()).count() >= 10).collect();
    if usable.is_empty() {
        return Err(CalibError::TooFewViews { what: "laser plane", usable: 0, needed: 2, reasons });
    }
    let mut heights: Vec<f64> = usable.iter().map(|&v| views[v].height_m).collect();
    heights.sort_by(f64::total_cmp);
    let spread = heights.last().copied().unwrap_or(0.0) - heights.first().copied().unwrap_or(0.0);
    if spread < 0.02 {
        return Err(CalibError::Degenerate(format!(
            "the laser points lie on one line: every usable view has the tabletop at {:.3} m{}; a plane needs two or more tabletop heights at least 20 mm apart (the trolley rises 0-340 mm){reasons}",
            heights.first().copied().unwrap_or(0.0),
            if usable.len() == 1 { " (one view)" } else { "" }
        )));
    }
    let all: Vec<Vec3> = usable.iter().flat_map(|&v| points[v].iter().copied().filter(|p| p.is_finite())).collect();
    let (plane, vals) = fit(&all).ok_or_else(|| CalibError::Degenerate("too few laser points".into()))?;
    if vals[1].sqrt() < 0.005 {
        return Err(CalibError::Degenerate(format!(
            "the laser points span only {:.1} mm across the line: the line was not seen at more than one height",
            vals[1].sqrt() * 1e3
        )));
    }
    let sigma = vals[0].sqrt();
    let kept: Vec<Vec3> =
        all.iter().copied().filter(|p| plane.signed_distance(*p).abs() <= 3.0 * sigma.max(1e-6)).collect();
    let (mut plane, _) = fit(&kept).ok_or_else(|| CalibError::Degenerate("too few laser points".into()))?;
    if plane.normal.dot(reference_normal) < 0.0 {
        plane = Plane { normal: -plane.normal, d: -plane.d };
    }
    let residuals: Vec<Vec<f64>> =
        points.iter().map(|pts| pts.iter().map(|p| plane.signed_distance(*p)).collect()).collect();
    let d: Vec<f64> = kept.iter().map(|p| plane.signed_distance(*p)).collect();
    let rms_m = (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt();
    let max_m = d.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    Ok(LaserResult { plane, rms_m, max_m, residuals, points, used: kept.len(), dropped: all.len() - kept.len() })
}
