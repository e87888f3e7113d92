//! Camera intrinsics from checkerboard views: homographies, a closed-form start (principal point
//! at the image centre, focal lengths from the orthogonality of each view's rotation, as
//! OpenCV's initialisation), then Levenberg-Marquardt over fx, fy, cx, cy, the distortion
//! coefficients and every view's pose, minimising the reprojection error. Views whose error
//! stands out are rejected with the reason, and the solve is repeated without them.

use super::board::BoardSpec;
use super::lm::{self, Problem};
use super::{homography, pose_from_homography, retract_pose, CalibError};
use crate::camera::{CameraModel, Distortion};
use crate::geom::Iso3;

/// Which distortion model to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DistortionModel {
    /// `plumb_bob`: k1 k2 p1 p2 k3.
    PlumbBob,
    /// `rational_polynomial`: k1 k2 p1 p2 k3 k4 k5 k6.
    RationalPolynomial,
}

impl DistortionModel {
    /// From the ROS name.
    pub fn parse(s: &str) -> Option<DistortionModel> {
        match s {
            "plumb_bob" => Some(DistortionModel::PlumbBob),
            "rational_polynomial" => Some(DistortionModel::RationalPolynomial),
            _ => None,
        }
    }
    fn coefficients(self) -> usize {
        match self {
            DistortionModel::PlumbBob => 5,
            DistortionModel::RationalPolynomial => 8,
        }
    }
    fn build(self, d: &[f64]) -> Distortion {
        match self {
            DistortionModel::PlumbBob => Distortion::PlumbBob { k1: d[0], k2: d[1], p1: d[2], p2: d[3], k3: d[4] },
            DistortionModel::RationalPolynomial => {
                let mut a = [0.0; 8];
                a.copy_from_slice(&d[..8]);
                Distortion::RationalPolynomial { d: a }
            }
        }
    }
}

/// Settings of the intrinsics solve.
#[derive(Debug, Clone, PartialEq)]
pub struct IntrinsicsConfig {
    /// Distortion model.
    pub model: DistortionModel,
    /// A view is rejected when its RMS error exceeds this many times the median...
    pub outlier_factor: f64,
    /// ...and this many pixels.
    pub outlier_floor_px: f64,
    /// Levenberg-Marquardt iterations.
    pub max_iterations: usize,
}

impl Default for IntrinsicsConfig {
    fn default() -> Self {
        Self { model: DistortionModel::PlumbBob, outlier_factor: 3.0, outlier_floor_px: 0.3, max_iterations: 60 }
    }
}

/// One view's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewResult {
    /// `optical <- board`.
    pub pose: Iso3,
    /// RMS reprojection error, pixels.
    pub rms_px: f64,
    /// Reprojection error per corner (projected minus detected), pixels.
    pub residuals: Vec<[f64; 2]>,
    /// Why the view was left out of the final solve, if it was.
    pub rejected: Option<String>,
}

/// The calibrated camera.
#[derive(Debug, Clone, PartialEq)]
pub struct IntrinsicsResult {
    /// The camera model (image size from the input).
    pub model: CameraModel,
    /// Standard deviations of fx, fy, cx, cy and the distortion coefficients.
    pub std_devs: Vec<f64>,
    /// Per input view, in order.
    pub views: Vec<ViewResult>,
    /// RMS reprojection error over the views used, pixels.
    pub rms_px: f64,
    /// The final solve.
    pub report: lm::Report,
}

#[derive(Clone)]
struct State {
    k: [f64; 4],
    d: Vec<f64>,
    poses: Vec<Iso3>,
}

struct Intrinsics<'a> {
    spec: &'a BoardSpec,
    views: Vec<&'a [[f64; 2]]>,
    model: DistortionModel,
}

impl Intrinsics<'_> {
    fn project(&self, s: &State, pose: &Iso3, k: usize) -> Option<[f64; 2]> {
        let p = pose.transform_point(self.spec.point(k));
        if p.z <= 1e-6 {
            return None;
        }
        let (xd, yd) = self.model.build(&s.d).distort(p.x / p.z, p.y / p.z);
        Some([s.k[0] * xd + s.k[2], s.k[1] * yd + s.k[3]])
    }
}

impl Problem for Intrinsics<'_> {
    type State = State;
    fn dim(&self) -> usize {
        4 + self.model.coefficients() + 6 * self.views.len()
    }
    fn residuals(&self, s: &State, out: &mut Vec<f64>) {
        for (pose, obs) in s.poses.iter().zip(&self.views) {
            for (k, o) in obs.iter().enumerate() {
                match self.project(s, pose, k) {
                    Some(p) => out.extend([p[0] - o[0], p[1] - o[1]]),
                    None => out.extend([1e3, 1e3]),
                }
            }
        }
    }
    fn retract(&self, s: &State, d: &[f64]) -> State {
        let nd = self.model.coefficients();
        let mut n = s.clone();
        for i in 0..4 {
            n.k[i] += d[i];
        }
        for i in 0..nd {
            n.d[i] += d[4 + i];
        }
        for (v, pose) in n.poses.iter_mut().enumerate() {
            *pose = retract_pose(pose, &d[4 + nd + 6 * v..4 + nd + 6 * v + 6]);
        }
        n
    }
    fn step(&self, k: usize) -> f64 {
        if k < 4 {
            1e-3
        } else {
            1e-7
        }
    }
}

fn rms(res: &[[f64; 2]]) -> f64 {
    (res.iter().map(|r| r[0] * r[0] + r[1] * r[1]).sum::<f64>() / res.len().max(1) as f64).sqrt()
}

/// Focal lengths from the homographies, with the principal point at `c` (OpenCV's start).
fn initial_focal(hs: &[[f64; 9]], c: [f64; 2]) -> Option<[f64; 2]> {
    // Normal equations of  a*x + b*y = r  in (1/fx^2, 1/fy^2).
    let (mut s11, mut s12, mut s22, mut t1, mut t2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for h in hs {
        // Shift the image origin to the principal point: H' = T H.
        let mut g = *h;
        for j in 0..3 {
            g[j] -= c[0] * h[6 + j];
            g[3 + j] -= c[1] * h[6 + j];
        }
        let (h11, h21, h31, h12, h22, h32) = (g[0], g[3], g[6], g[1], g[4], g[7]);
        for (a, b, r) in [
            (h11 * h12, h21 * h22, -h31 * h32),
            (h11 * h11 - h12 * h12, h21 * h21 - h22 * h22, -(h31 * h31 - h32 * h32)),
        ] {
            // Scale each equation to unit size so that every view weighs alike.
            let n = (a * a + b * b).sqrt();
            if n < 1e-300 {
                continue;
            }
            let (a, b, r) = (a / n, b / n, r / n);
            s11 += a * a;
            s12 += a * b;
            s22 += b * b;
            t1 += a * r;
            t2 += b * r;
        }
    }
    let det = s11 * s22 - s12 * s12;
    if !(det.abs() > 1e-300) {
        return None;
    }
    let x = (s22 * t1 - s12 * t2) / det;
    let y = (s11 * t2 - s12 * t1) / det;
    (x > 0.0 && y > 0.0).then(|| [1.0 / x.sqrt(), 1.0 / y.sqrt()])
}

fn solve_views(
    spec: &BoardSpec,
    views: &[&[[f64; 2]]],
    size: (u32, u32),
    cfg: &IntrinsicsConfig,
    start: Option<(&State, &[Iso3])>,
) -> Result<lm::Solution<State>, CalibError> {
    let plane: Vec<[f64; 2]> = (0..spec.len()).map(|k| [spec.point(k).x, spec.point(k).y]).collect();
    let state = match start {
        Some((s, poses)) => State { k: s.k, d: s.d.clone(), poses: poses.to_vec() },
        None => {
            let hs: Vec<[f64; 9]> = views
                .iter()
                .map(|v| homography(&plane, v))
                .collect::<Option<_>>()
                .ok_or_else(|| CalibError::Degenerate("a view's corners are collinear".into()))?;
            let c = [(f64::from(size.0) - 1.0) * 0.5, (f64::from(size.1) - 1.0) * 0.5];
            let [fx, fy] = initial_focal(&hs, c).ok_or_else(|| {
                CalibError::Degenerate(
                    "the focal length cannot be found: every view is square-on; tilt the board in some views".into(),
                )
            })?;
            let mut poses = Vec::new();
            for v in views {
                let norm: Vec<[f64; 2]> = v.iter().map(|p| [(p[0] - c[0]) / fx, (p[1] - c[1]) / fy]).collect();
                let h = homography(&plane, &norm)
                    .ok_or_else(|| CalibError::Degenerate("a view's corners are collinear".into()))?;
                poses.push(
                    pose_from_homography(&h)
                        .ok_or_else(|| CalibError::Degenerate("a view's pose is undefined".into()))?,
                );
            }
            State { k: [fx, fy, c[0], c[1]], d: vec![0.0; cfg.model.coefficients()], poses }
        }
    };
    let problem = Intrinsics { spec, views: views.to_vec(), model: cfg.model };
    Ok(lm::solve(&problem, state, cfg.max_iterations))
}

/// The solution after outlier rejection, the views used (indices) and each view's reason for
/// rejection.
type Kept = (lm::Solution<State>, Vec<usize>, Vec<Option<String>>);

/// Views fewer than this leave the focal length and centre undetermined.
const NEEDED_VIEWS: usize = 3;

/// The views kept after rejecting outliers one at a time, worst first, re-solving after each:
/// a view whose reprojection RMS is beyond `outlier_factor` times the median (and the floor)
/// goes while more than [`NEEDED_VIEWS`] remain. Returns the last solution, the views used
/// (indices into `views`) and each view's reason for rejection.
fn reject_outliers(
    spec: &BoardSpec,
    views: &[Vec<[f64; 2]>],
    size: (u32, u32),
    cfg: &IntrinsicsConfig,
    mut sol: lm::Solution<State>,
) -> Result<Kept, CalibError> {
    let all: Vec<&[[f64; 2]]> = views.iter().map(|v| v.as_slice()).collect();
    let problem = Intrinsics { spec, views: all, model: cfg.model };
    let per_view = |s: &State, used: &[usize]| -> Vec<f64> {
        used.iter()
            .enumerate()
            .map(|(i, &v)| {
                let res: Vec<[f64; 2]> = (0..spec.len())
                    .map(|k| {
                        problem
                            .project(s, &s.poses[i], k)
                            .map_or([1e3, 1e3], |p| [p[0] - views[v][k][0], p[1] - views[v][k][1]])
                    })
                    .collect();
                rms(&res)
            })
            .collect()
    };
    let mut used: Vec<usize> = (0..views.len()).collect();
    let mut rejected: Vec<Option<String>> = vec![None; views.len()];
    loop {
        let errs = per_view(&sol.state, &used);
        let mut sorted = errs.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        let limit = (cfg.outlier_factor * median).max(cfg.outlier_floor_px);
        let Some((worst, &e)) = errs.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) else { break };
        if e <= limit || used.len() <= NEEDED_VIEWS {
            break;
        }
        rejected[used[worst]] = Some(format!(
            "reprojection RMS {e:.2} px is {:.1}x the median {median:.2} px (limit {limit:.2} px): board moved, bent, or corners misread",
            e / median.max(1e-12)
        ));
        used.remove(worst);
        let mut poses = sol.state.poses.clone();
        poses.remove(worst);
        let sub: Vec<&[[f64; 2]]> = used.iter().map(|&v| views[v].as_slice()).collect();
        let start = sol.state.clone();
        sol = solve_views(spec, &sub, size, cfg, Some((&start, &poses)))?;
    }
    Ok((sol, used, rejected))
}

/// Calibrates a camera of `width x height` pixels from the board's corners in each view
/// (`views[i]` in board order, see [`BoardSpec`]).
pub fn calibrate(
    spec: &BoardSpec,
    views: &[Vec<[f64; 2]>],
    width: u32,
    height: u32,
    cfg: &IntrinsicsConfig,
) -> Result<IntrinsicsResult, CalibError> {
    if let Some(v) = views.iter().position(|v| v.len() != spec.len()) {
        return Err(CalibError::Degenerate(format!(
            "view {v} has {} corners, the board {}",
            views[v].len(),
            spec.len()
        )));
    }
    if views.len() < NEEDED_VIEWS {
        return Err(CalibError::TooFewViews {
            what: "intrinsics",
            usable: views.len(),
            needed: NEEDED_VIEWS,
            reasons: String::new(),
        });
    }
    let all: Vec<&[[f64; 2]]> = views.iter().map(|v| v.as_slice()).collect();
    let sol = solve_views(spec, &all, (width, height), cfg, None)?;
    let (sol, used, rejected) = reject_outliers(spec, views, (width, height), cfg, sol)?;
    let problem = Intrinsics { spec, views: all, model: cfg.model };
    let s = &sol.state;
    let model = CameraModel {
        width,
        height,
        fx: s.k[0],
        fy: s.k[1],
        cx: s.k[2],
        cy: s.k[3],
        distortion: cfg.model.build(&s.d),
    };
    model.validate().map_err(|e| CalibError::Degenerate(e.to_string()))?;
    // Every view's residuals under the final model; rejected views get their own pose fitted.
    let mut out = Vec::new();
    for (v, obs) in views.iter().enumerate() {
        let pose = match used.iter().position(|&u| u == v) {
            Some(i) => s.poses[i],
            None => super::placement::solve_pnp(spec, &model, obs).map(|r| r.0).unwrap_or(Iso3::IDENTITY),
        };
        let residuals: Vec<[f64; 2]> = (0..spec.len())
            .map(|k| problem.project(s, &pose, k).map_or([f64::NAN; 2], |p| [p[0] - obs[k][0], p[1] - obs[k][1]]))
            .collect();
        out.push(ViewResult { pose, rms_px: rms(&residuals), residuals, rejected: rejected[v].clone() });
    }
    let used_res: Vec<[f64; 2]> =
        out.iter().filter(|v| v.rejected.is_none()).flat_map(|v| v.residuals.iter().copied()).collect();
    let std_devs = sol.std_devs(4 + cfg.model.coefficients()).unwrap_or_default();
    Ok(IntrinsicsResult { model, std_devs, views: out, rms_px: rms(&used_res), report: sol.report })
}
