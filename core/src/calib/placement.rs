//! A camera's placement on the C-arm (`carm -> <cam>_optical_frame`) from the board lying flat
//! on the tabletop at a known place, seen with the C-arm at known travels: a planar PnP start
//! (homography of the undistorted corners) refined by Levenberg-Marquardt over the six pose
//! parameters against every view's reprojection error.

use super::board::BoardSpec;
use super::lm::{self, Problem};
use super::{homography, pose_from_homography, retract_pose, CalibError};
use crate::camera::CameraModel;
use crate::geom::{Iso3, Mat3, Vec3};

/// `table <- board` for a board lying printed side up on the tabletop: corner 0 at `origin`
/// (table frame, metres; z is the board's top surface), the board's x axis turned `yaw_rad`
/// from the table's X about Z. The board's z (into the board) then points down.
pub fn table_from_board(origin: Vec3, yaw_rad: f64) -> Iso3 {
    let flip = Mat3 { m: [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]] };
    Iso3 { rotation: Mat3::rot_z(yaw_rad).mul_mat(&flip), translation: origin }
}

/// One image of the board on the tabletop.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacementView {
    /// The board's corners in board order, pixels.
    pub corners: Vec<[f64; 2]>,
    /// `table <- carm` when the image was taken.
    pub table_from_carm: Iso3,
}

/// The placement found.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacementResult {
    /// `carm <- optical`.
    pub carm_from_optical: Iso3,
    /// RMS reprojection error per view, pixels.
    pub view_rms_px: Vec<f64>,
    /// Reprojection error per view and corner (projected minus detected), pixels.
    pub residuals: Vec<Vec<[f64; 2]>>,
    /// RMS over all views, pixels.
    pub rms_px: f64,
    /// The solve.
    pub report: lm::Report,
}

struct Pnp<'a> {
    spec: &'a BoardSpec,
    model: &'a CameraModel,
    /// (corners, `optical <- board` = pre * X * post).
    views: Vec<(&'a [[f64; 2]], Iso3, Iso3)>,
}

impl Pnp<'_> {
    /// Residuals of one view with `x` the unknown pose: `optical <- board = pre^-1 ... `.
    fn view_residuals(&self, x: &Iso3, v: usize, out: &mut Vec<f64>) {
        let (obs, pre, post) = &self.views[v];
        // optical <- board = (pre * x)^-1 * post, where pre * x = table <- optical.
        let optical_from_board = pre.compose(x).inverse().compose(post);
        for (k, o) in obs.iter().enumerate() {
            match self.model.project(optical_from_board.transform_point(self.spec.point(k))) {
                Some((u, w)) => out.extend([u - o[0], w - o[1]]),
                None => out.extend([1e3, 1e3]),
            }
        }
    }
}

impl Problem for Pnp<'_> {
    type State = Iso3;
    fn dim(&self) -> usize {
        6
    }
    fn residuals(&self, s: &Iso3, out: &mut Vec<f64>) {
        for v in 0..self.views.len() {
            self.view_residuals(s, v, out);
        }
    }
    fn retract(&self, s: &Iso3, d: &[f64]) -> Iso3 {
        retract_pose(s, d)
    }
    fn step(&self, _k: usize) -> f64 {
        1e-7
    }
}

fn rms(r: &[f64]) -> f64 {
    (r.iter().map(|v| v * v).sum::<f64>() / (r.len() / 2).max(1) as f64).sqrt()
}

/// The start pose `optical <- board` of one view from its undistorted corners.
fn initial_pose(spec: &BoardSpec, model: &CameraModel, corners: &[[f64; 2]]) -> Option<Iso3> {
    let plane: Vec<[f64; 2]> = (0..spec.len()).map(|k| [spec.point(k).x, spec.point(k).y]).collect();
    let norm: Vec<[f64; 2]> =
        corners.iter().map(|p| model.ray(p[0], p[1]).map(|r| [r.x, r.y])).collect::<Option<_>>()?;
    pose_from_homography(&homography(&plane, &norm)?)
}

/// `optical <- board` of one view and its RMS reprojection error (pixels).
pub fn solve_pnp(spec: &BoardSpec, model: &CameraModel, corners: &[[f64; 2]]) -> Option<(Iso3, f64)> {
    let start = initial_pose(spec, model, corners)?.inverse();
    // Unknown x = board <- optical: optical <- board = (I * x)^-1 * I.
    let p = Pnp { spec, model, views: vec![(corners, Iso3::IDENTITY, Iso3::IDENTITY)] };
    let sol = lm::solve(&p, start, 50);
    let mut r = Vec::new();
    p.view_residuals(&sol.state, 0, &mut r);
    Some((sol.state.inverse(), rms(&r)))
}

/// Finds `carm <- optical` from views of the board lying at `table_from_board`.
pub fn calibrate(
    spec: &BoardSpec,
    model: &CameraModel,
    table_from_board: &Iso3,
    views: &[PlacementView],
) -> Result<PlacementResult, CalibError> {
    if views.is_empty() {
        return Err(CalibError::TooFewViews { what: "placement", usable: 0, needed: 1, reasons: String::new() });
    }
    if let Some(v) = views.iter().position(|v| v.corners.len() != spec.len()) {
        return Err(CalibError::Degenerate(format!(
            "view {v} has {} corners, the board {}",
            views[v].corners.len(),
            spec.len()
        )));
    }
    let first = &views[0];
    let optical_from_board = initial_pose(spec, model, &first.corners)
        .ok_or_else(|| CalibError::Degenerate("view 0: the corners cannot be undistorted or are collinear".into()))?;
    // carm <- optical = (table <- carm)^-1 * (table <- board) * (board <- optical).
    let start = first.table_from_carm.inverse().compose(table_from_board).compose(&optical_from_board.inverse());
    let p = Pnp {
        spec,
        model,
        views: views.iter().map(|v| (v.corners.as_slice(), v.table_from_carm, *table_from_board)).collect(),
    };
    let sol = lm::solve(&p, start, 100);
    let mut residuals = Vec::new();
    let mut view_rms_px = Vec::new();
    let mut all = Vec::new();
    for v in 0..views.len() {
        let mut r = Vec::new();
        p.view_residuals(&sol.state, v, &mut r);
        view_rms_px.push(rms(&r));
        all.extend_from_slice(&r);
        residuals.push(r.chunks(2).map(|c| [c[0], c[1]]).collect());
    }
    Ok(PlacementResult { carm_from_optical: sol.state, view_rms_px, residuals, rms_px: rms(&all), report: sol.report })
}
