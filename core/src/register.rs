//! Camera-to-camera refinement: the second camera's placement (`carm -> optical`) corrected
//! against the first camera's surface.
//!
//! A wrong camera placement does not move the camera's cloud rigidly: each point is where the
//! camera's ray meets the laser plane, so a small camera error bends the cloud within the plane.
//! The refinement therefore keeps what was observed (each point's ray in the camera frame and the
//! C-arm pose of its frame) and re-triangulates through a corrected placement, minimising the
//! point-to-plane distances to the reference surface (Gauss-Newton on the 6 parameters, nearest
//! neighbours from a k-d tree, trimmed and Huber-weighted correspondences re-found every
//! iteration). It refuses, with the reason, when the overlap is too small, when the fit stays
//! poor, or when the result moves the camera further than a bound: then the calibrated placement
//! stands.

use crate::geom::{Iso3, Mat3, Plane, Quat, Vec3};
use crate::mesh::{Grid, Mesh, MeshConfig};
use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// One observed point of the camera being refined.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Unit ray in the camera's optical frame.
    pub ray: Vec3,
    /// `table -> carm` of the point's frame.
    pub table_from_carm: Iso3,
}

impl Observation {
    /// The observation behind a point `p` (in `table`) that was triangulated with the placement
    /// `carm_from_optical` at the pose `table_from_carm`: its ray from the optical centre.
    pub fn from_point(p: Vec3, table_from_carm: &Iso3, carm_from_optical: &Iso3) -> Option<Self> {
        let q = carm_from_optical.inverse().transform_point(table_from_carm.inverse().transform_point(p));
        Some(Self { ray: q.try_normalize()?, table_from_carm: *table_from_carm })
    }

    /// The ray in `carm` through the placement `carm_from_optical`, the plane's normal along it
    /// and the distance to the laser plane along it; `None` for a ray parallel to the plane.
    fn ray_to_plane(&self, carm_from_optical: &Iso3, plane: &Plane) -> Option<(Vec3, f64, f64)> {
        let d = carm_from_optical.transform_vector(self.ray);
        let den = plane.normal.dot(d);
        (den.abs() >= 1e-12).then(|| (d, den, (plane.d - plane.normal.dot(carm_from_optical.translation)) / den))
    }

    /// The point in `table` through the placement `carm_from_optical` and the laser plane (in
    /// `carm`); `None` for a ray parallel to the plane or meeting it behind the camera.
    pub fn triangulate(&self, carm_from_optical: &Iso3, plane: &Plane) -> Option<Vec3> {
        let (d, _, t) = self.ray_to_plane(carm_from_optical, plane)?;
        (t > 0.0).then(|| self.table_from_carm.transform_point(carm_from_optical.translation + d * t))
    }

    /// The derivatives of `normal . p` (`normal` in `table`, `p` the triangulated point) with
    /// respect to the correction `(rotation vector, translation)` of [`corrected`] at zero:
    /// the ray turns by `w x d` and the centre moves by `t`, and the point slides along the ray
    /// to stay on the laser plane.
    fn jacobian(&self, carm_from_optical: &Iso3, plane: &Plane, normal: Vec3) -> Option<[f64; 6]> {
        let (d, den, s) = self.ray_to_plane(carm_from_optical, plane)?;
        let g = self.table_from_carm.rotation.transpose().mul_vec(normal);
        let g = g - plane.normal * (g.dot(d) / den);
        let w = d.cross(g) * s;
        Some([w.x, w.y, w.z, g.x, g.y, g.z])
    }
}

/// The C-arm's motion during a scan as the merger sees it: travel along `table` Y at a fixed
/// angle and tabletop height (`table -> carm` = rotation about Y by the angle, translation
/// `(x, travel, z)`), so each frame's pose follows from the travel alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanMotion {
    /// `table -> carm` of any frame of the scan (its travel is not used).
    pub table_from_carm: Iso3,
}

impl ScanMotion {
    /// The pose at `travel_m`.
    pub fn at(&self, travel_m: f64) -> Iso3 {
        let mut t = self.table_from_carm;
        t.translation.y = travel_m;
        t
    }

    /// The travel at which the laser `plane` (in `carm`) passes through `p` (in `table`):
    /// every triangulated point lies on the plane of its own frame. `None` when the plane is
    /// parallel to the travel.
    pub fn travel_of(&self, p: Vec3, plane: &Plane) -> Option<f64> {
        let m = self.table_from_carm.rotation.mul_vec(plane.normal);
        let t = self.table_from_carm.translation;
        (m.y.abs() > 1e-6).then(|| (m.dot(p) - m.x * t.x - m.z * t.z - plane.d) / m.y)
    }
}

/// The observations behind a camera's grid of points (frame-major, `samples` per frame, NaN
/// where none): each point's frame pose recovered from its travel, and its ray through
/// `carm_from_optical`. Returns `(grid index, observation)` pairs. Points of one frame must give
/// one travel: a spread beyond `max_spread_m` means the C-arm turned or the tabletop moved
/// during the scan, and is refused (naming the frame).
pub fn grid_observations(
    points: &[[f32; 3]],
    samples: usize,
    carm_from_optical: &Iso3,
    plane: &Plane,
    motion: &ScanMotion,
    max_spread_m: f64,
) -> Result<Vec<(usize, Observation)>, RefineError> {
    let mut out = Vec::with_capacity(points.len());
    let mut travels: Vec<(usize, Vec3, f64)> = Vec::with_capacity(samples);
    let optical_from_carm = carm_from_optical.inverse();
    for (f, col) in points.chunks(samples.max(1)).enumerate() {
        travels.clear();
        travels.extend(col.iter().enumerate().filter_map(|(s, p)| {
            let v = Vec3::new(p[0].into(), p[1].into(), p[2].into());
            v.is_finite().then(|| motion.travel_of(v, plane).map(|t| (s, v, t)))?
        }));
        if travels.is_empty() {
            continue;
        }
        let (lo, hi) = travels.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x.2), b.max(x.2)));
        if hi - lo > max_spread_m {
            return Err(RefineError::NotOneTravel { frame: f, spread_m: hi - lo, max_spread_m });
        }
        let pose = motion.at((lo + hi) / 2.0);
        let optical_from_table = optical_from_carm.compose(&pose.inverse());
        out.extend(travels.iter().filter_map(|&(s, v, _)| {
            let ray = optical_from_table.transform_point(v).try_normalize()?;
            Some((f * samples + s, Observation { ray, table_from_carm: pose }))
        }));
    }
    Ok(out)
}

/// Settings of the refinement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineConfig {
    /// Gauss-Newton iterations at most.
    pub max_iterations: u32,
    /// Correspondences farther than this are not used, metres.
    pub max_distance_m: f64,
    /// Fraction of the correspondences kept (the closest), 0..1.
    pub trim_fraction: f64,
    /// Huber threshold on the point-to-plane residual, metres.
    pub huber_m: f64,
    /// Observations used at most (evenly subsampled).
    pub max_points: usize,
    /// Smallest number of overlapping points.
    pub min_overlap_points: usize,
    /// Smallest fraction of the observations that overlap the reference.
    pub min_overlap_fraction: f64,
    /// Largest correction of the camera's position, metres.
    pub max_translation_m: f64,
    /// Largest correction of the camera's orientation, degrees.
    pub max_rotation_deg: f64,
    /// Largest RMS point-to-plane residual accepted after the fit, metres.
    pub max_rms_m: f64,
    /// Laplacian smoothing passes (on the grid, four neighbours) over both surfaces before the
    /// fit (the refined placement is then applied to the points as measured): averages the line
    /// detector's noise out of the correspondences.
    pub smooth_iterations: u32,
    /// Points of one frame must lie on laser planes no further apart in travel than this,
    /// metres (see [`grid_observations`]).
    pub max_travel_spread_m: f64,
    /// A correction is applied only where the data constrain it: it must be at least this many
    /// of its standard deviations (from the normal equations, along the correction), so that
    /// the uncertainty is well below the correction.
    pub min_significance: f64,
    /// ... and the RMS residual must fall by at least this fraction of what it was. A correct
    /// calibration's residual is the surfaces' own noise, which no placement lowers much.
    pub min_rms_reduction: f64,
    /// Correspondences per independent measurement in the covariance: the grids' smoothing
    /// and the line detector spread one measurement's error over neighbouring samples, so the
    /// normal equations' own count overstates what is known.
    pub points_per_measurement: f64,
    /// Grid neighbours further apart than this, metres, are neither smoothed together nor
    /// used for a normal (the meshes' `max_edge_m`: frames far apart still have neighbours).
    pub max_edge_m: f32,
    /// A direction of the placement that the data hold no better than this (one standard
    /// deviation along an eigen-direction of the normal equations, rotations taken at
    /// [`LEVER_M`]), metres, is left as calibrated: the fit would slide along it on the
    /// smallest bias between the cameras' surfaces, barely changing either.
    pub max_sigma_m: f64,
}

/// The distance at which a rotation of the camera is compared with its shifts: a radian at a
/// metre (about where the scene is) as a metre.
pub const LEVER_M: f64 = 1.0;

impl RefineConfig {
    /// The defaults (the merger's parameter defaults), usable in constant expressions.
    pub const DEFAULT: RefineConfig = RefineConfig {
        max_iterations: 40,
        max_distance_m: 0.01,
        trim_fraction: 0.9,
        huber_m: 0.001,
        max_points: 8_000,
        min_overlap_points: 200,
        min_overlap_fraction: 0.05,
        max_translation_m: 0.02,
        max_rotation_deg: 2.0,
        max_rms_m: 0.001,
        smooth_iterations: 6,
        max_travel_spread_m: 0.001,
        min_significance: 5.0,
        min_rms_reduction: 0.25,
        points_per_measurement: 50.0,
        max_edge_m: MeshConfig::DEFAULT.max_edge_m,
        max_sigma_m: 0.003,
    };
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What the refinement did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineReport {
    /// The refined placement `carm -> optical`.
    pub carm_from_optical: Iso3,
    /// Correction of the camera's position (refined minus calibrated, in `carm`), metres.
    pub translation_m: Vec3,
    /// Angle of the orientation correction, degrees.
    pub rotation_deg: f64,
    /// Iterations run.
    pub iterations: u32,
    /// RMS point-to-plane residual of the correspondences before, metres.
    pub rms_before_m: f64,
    /// The same after.
    pub rms_after_m: f64,
    /// Fraction of the observations with a reference point within `max_distance_m`, after.
    pub overlap_fraction: f64,
    /// Observations used.
    pub points: usize,
    /// Standard deviations of the whole correction (its Mahalanobis norm).
    pub significance: f64,
    /// One standard deviation of the position correction alone (normal equations), metres.
    pub sigma_translation_m: f64,
    /// One standard deviation of the orientation correction, degrees.
    pub sigma_rotation_deg: f64,
    /// Of the six directions of the placement, those the data held in the last step (see
    /// [`RefineConfig::max_sigma_m`]); along the others the camera stayed as calibrated.
    pub held_directions: u32,
}

/// Why the calibrated placement stands.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RefineError {
    /// Too few points of the camera lie near the reference surface.
    #[error("too little overlap: {points} of {total} points within {max_distance_m} m of the reference (need {min_points} and {min_fraction})")]
    TooLittleOverlap {
        /// Overlapping points.
        points: usize,
        /// Points tried.
        total: usize,
        /// The distance used.
        max_distance_m: f64,
        /// The minimum count.
        min_points: usize,
        /// The minimum fraction.
        min_fraction: f64,
    },
    /// The correction is beyond the bounds.
    #[error("the refined placement moves the camera {translation_m:.4} m and {rotation_deg:.3} deg, beyond the bounds {max_translation_m} m / {max_rotation_deg} deg")]
    MovedTooFar {
        /// Translation found.
        translation_m: f64,
        /// Rotation found.
        rotation_deg: f64,
        /// Bound.
        max_translation_m: f64,
        /// Bound.
        max_rotation_deg: f64,
    },
    /// The fit stays poor.
    #[error("no good fit: RMS residual {rms_m:.5} m after {iterations} iterations (limit {max_rms_m} m)")]
    PoorFit {
        /// RMS after.
        rms_m: f64,
        /// Iterations run.
        iterations: u32,
        /// Limit.
        max_rms_m: f64,
    },
    /// The geometry does not constrain the placement (a flat or featureless overlap).
    #[error("the overlap does not constrain the camera's placement (singular normal equations)")]
    Degenerate,
    /// The correction is within what the data can tell, or it hardly improves the fit: the
    /// calibration stands.
    #[error(
        "correction not supported by the data: {translation_m:.5} m / {rotation_deg:.4} deg is {significance:.1} \
         standard deviations (need {min_significance}; 1-sigma {sigma_translation_m:.5} m / {sigma_rotation_deg:.4} \
         deg alone), RMS residual {rms_before_m:.5} -> {rms_after_m:.5} m (need a {min_rms_reduction} reduction)"
    )]
    NotSignificant {
        /// Size of the position correction, metres.
        translation_m: f64,
        /// Angle of the orientation correction, degrees.
        rotation_deg: f64,
        /// Standard deviations of the whole correction (Mahalanobis norm).
        significance: f64,
        /// Its 1-sigma uncertainty alone, metres.
        sigma_translation_m: f64,
        /// Its 1-sigma uncertainty alone, degrees.
        sigma_rotation_deg: f64,
        /// RMS residual before, metres.
        rms_before_m: f64,
        /// RMS residual after, metres.
        rms_after_m: f64,
        /// Significance needed.
        min_significance: f64,
        /// Fraction of reduction needed.
        min_rms_reduction: f64,
    },
    /// The points of one frame lie on laser planes of different travels.
    #[error("frame {frame}: its points lie on laser planes {spread_m:.5} m of travel apart (limit {max_spread_m} m): the C-arm turned or the tabletop moved during the scan")]
    NotOneTravel {
        /// The frame (grid column).
        frame: usize,
        /// Spread of the travels.
        spread_m: f64,
        /// Limit.
        max_spread_m: f64,
    },
    /// The reference surface is (nearly) empty or its normals do not match its points.
    #[error("the reference surface has {points} usable points and {normals} normals")]
    BadReference {
        /// Points.
        points: usize,
        /// Normals.
        normals: usize,
    },
}

/// The reference surface: points with unit normals, indexed for nearest-neighbour queries.
pub struct Reference {
    points: Vec<Vec3>,
    normals: Vec<Vec3>,
    tree: ImmutableKdTree<f64, 3>,
}

impl Reference {
    /// Indexes `points` (in `table`) with their `normals`; non-finite entries and zero normals
    /// are left out.
    pub fn new(points: &[Vec3], normals: &[Vec3]) -> Result<Self, RefineError> {
        if points.len() != normals.len() {
            return Err(RefineError::BadReference { points: points.len(), normals: normals.len() });
        }
        let (p, n): (Vec<Vec3>, Vec<Vec3>) = points
            .iter()
            .zip(normals)
            .filter(|(p, n)| p.is_finite() && n.is_finite() && n.norm() > 0.5)
            .map(|(p, n)| (*p, *n))
            .unzip();
        if p.len() < 3 {
            return Err(RefineError::BadReference { points: p.len(), normals: n.len() });
        }
        let entries: Vec<[f64; 3]> = p.iter().map(|v| v.to_array()).collect();
        let tree = ImmutableKdTree::new_from_slice(&entries)
            .map_err(|_| RefineError::BadReference { points: p.len(), normals: n.len() })?;
        Ok(Self { points: p, normals: n, tree })
    }

    /// The surface of a mesh (its vertices and vertex normals).
    pub fn from_mesh(mesh: &Mesh) -> Result<Self, RefineError> {
        let v = |a: &[f32; 3]| Vec3::new(a[0].into(), a[1].into(), a[2].into());
        let p: Vec<Vec3> = mesh.positions.iter().map(v).collect();
        let n: Vec<Vec3> = mesh.normals.iter().map(v).collect();
        Self::new(&p, &n)
    }

    /// Points indexed.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True if no point is indexed (never, once built).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The nearest reference point to `q` within `max_d`: its index.
    fn nearest(&self, q: Vec3, max_d: f64) -> Option<usize> {
        let r = self.tree.query(&q.to_array()).nearest_one::<SquaredEuclidean<f64>>().execute();
        (r.distance <= max_d * max_d).then_some(r.item as usize)
    }
}

/// A placement corrected by `x = (rotation vector, translation)` applied in `carm` about the
/// camera's centre.
fn corrected(base: &Iso3, x: &[f64; 6]) -> Iso3 {
    let w = Vec3::new(x[0], x[1], x[2]);
    let angle = w.norm();
    let r = if angle > 0.0 { Quat::from_axis_angle(w / angle, angle).to_mat3() } else { Mat3::IDENTITY };
    Iso3 { rotation: r.mul_mat(&base.rotation), translation: base.translation + Vec3::new(x[3], x[4], x[5]) }
}

/// Angle between two rotations, degrees.
fn rotation_angle_deg(a: &Mat3, b: &Mat3) -> f64 {
    let m = a.transpose().mul_mat(b);
    let tr = m.column(0).x + m.column(1).y + m.column(2).z;
    ((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Solves the symmetric 6x6 system `a x = b` by Gaussian elimination with partial pivoting.
fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    let scale = (0..6).map(|i| a[i][i].abs()).fold(0.0, f64::max).max(1e-300);
    for c in 0..6 {
        let p = (c..6).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-12 * scale {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..6 {
            let f = a[r][c] / a[c][c];
            for k in c..6 {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; 6];
    for c in (0..6).rev() {
        let s: f64 = (c + 1..6).map(|k| a[c][k] * x[k]).sum();
        x[c] = (b[c] - s) / a[c][c];
    }
    Some(x)
}

/// A correspondence: (observation index, reference index, signed residual along the
/// reference's normal).
type Match = (usize, usize, f64);

/// One camera's point-to-plane ICP against the reference surface.
struct Icp<'a> {
    reference: &'a Reference,
    /// The observations used (every `step`-th, at most `max_points`).
    obs: Vec<&'a Observation>,
    plane: &'a Plane,
    cfg: &'a RefineConfig,
}

impl Icp<'_> {
    /// The correspondences of placement `e`.
    /// The observations are split over the cores (each match is its observation's alone).
    fn matches(&self, e: &Iso3) -> Vec<Match> {
        crate::par::filter_map(&self.obs, 1024, |i, o| {
            let p = o.triangulate(e, self.plane)?;
            let j = self.reference.nearest(p, self.cfg.max_distance_m)?;
            Some((i, j, self.reference.normals[j].dot(p - self.reference.points[j])))
        })
    }
    /// The `trim_fraction` of the matches with the smallest residuals.
    fn trimmed(&self, mut m: Vec<Match>) -> Vec<Match> {
        m.sort_by(|a, b| a.2.abs().total_cmp(&b.2.abs()));
        m.truncate(((m.len() as f64) * self.cfg.trim_fraction).ceil() as usize);
        m
    }
    fn rms(m: &[Match]) -> f64 {
        (m.iter().map(|x| x.2 * x.2).sum::<f64>() / m.len().max(1) as f64).sqrt()
    }
    /// Gauss-Newton's normal equations at placement `e`, Huber-weighted.
    fn normal_equations(&self, m: &[Match], e: &Iso3) -> ([[f64; 6]; 6], [f64; 6]) {
        let (mut ata, mut atb) = ([[0.0; 6]; 6], [0.0; 6]);
        for &(i, j, r) in m {
            let Some(jac) = self.obs[i].jacobian(e, self.plane, self.reference.normals[j]) else { continue };
            let w = if r.abs() <= self.cfg.huber_m { 1.0 } else { self.cfg.huber_m / r.abs() };
            for a in 0..6 {
                for b in 0..6 {
                    ata[a][b] += w * jac[a] * jac[b];
                }
                atb[a] -= w * jac[a] * r;
            }
        }
        (ata, atb)
    }
    /// Gauss-Newton from `start` until a step moves no ray by more than a micrometre at a
    /// metre, or `max_iterations`; the placement and the iterations taken.
    /// Also the directions held in the last step.
    fn solve(&self, start: &Iso3) -> Result<(Iso3, u32, u32), RefineError> {
        let mut e = *start;
        let (mut iterations, mut held) = (0, 0);
        for it in 0..self.cfg.max_iterations {
            iterations = it + 1;
            let m = self.matches(&e);
            if m.len() < self.cfg.min_overlap_points {
                break;
            }
            let m = self.trimmed(m);
            let (ata, atb) = self.normal_equations(&m, &e);
            let s2 = Icp::rms(&m).powi(2) * self.cfg.points_per_measurement;
            let x;
            (x, held) = held_step(&ata, &atb, s2, self.cfg.max_sigma_m).ok_or(RefineError::Degenerate)?;
            e = corrected(&e, &x);
            if Vec3::new(x[0], x[1], x[2]).norm() < 1e-6 && Vec3::new(x[3], x[4], x[5]).norm() < 1e-6 {
                break;
            }
        }
        Ok((e, iterations, held))
    }
}

/// The Gauss-Newton step `ata x = atb` in the directions the data hold: along each
/// eigen-direction of the normal equations (rotations scaled by [`LEVER_M`]) whose standard
/// deviation, `sqrt(s2 / eigenvalue)`, is at most `max_sigma_m`; nothing along the others.
/// Also how many directions are held; `None` where none is.
fn held_step(ata: &[[f64; 6]; 6], atb: &[f64; 6], s2: f64, max_sigma_m: f64) -> Option<([f64; 6], u32)> {
    let scale = |k: usize| if k < 3 { 1.0 / LEVER_M } else { 1.0 };
    let a: Vec<f64> = (0..36).map(|i| ata[i / 6][i % 6] * scale(i / 6) * scale(i % 6)).collect();
    let b: Vec<f64> = (0..6).map(|k| atb[k] * scale(k)).collect();
    let (values, vectors) = crate::calib::linalg::sym_eigen(&a, 6);
    let mut x = [0.0; 6];
    let mut held = 0;
    for (l, v) in values.iter().zip(&vectors) {
        if !(*l > 0.0 && s2 / l <= max_sigma_m * max_sigma_m) {
            continue;
        }
        held += 1;
        let along = (0..6).map(|k| v[k] * b[k]).sum::<f64>() / l;
        for k in 0..6 {
            x[k] += along * v[k] * scale(k);
        }
    }
    (held > 0).then_some((x, held))
}

/// The variances of the six correction parameters: the diagonal of `s2 (ata)^-1`.
fn variances(ata: [[f64; 6]; 6], s2: f64) -> Result<Vec<f64>, RefineError> {
    let column = |k: usize| {
        let mut unit = [0.0; 6];
        unit[k] = 1.0;
        solve6(ata, unit).map(|c| c[k] * s2)
    };
    (0..6).map(column).collect::<Option<_>>().ok_or(RefineError::Degenerate)
}

/// How many standard deviations the correction from `before` to `after` is, along its own
/// direction in the six parameters (the Mahalanobis norm under `ata / s2`): a shift and a turn
/// that the data only constrain together are judged together.
fn significance(before: &Iso3, after: &Iso3, ata: &[[f64; 6]; 6], s2: f64) -> f64 {
    let t = after.translation - before.translation;
    let q = after.rotation.mul_mat(&before.rotation.transpose()).to_quat();
    let q = if q.w < 0.0 { Quat { x: -q.x, y: -q.y, z: -q.z, w: -q.w } } else { q };
    let v = Vec3::new(q.x, q.y, q.z);
    let angle = 2.0 * v.norm().atan2(q.w);
    let w = v.try_normalize().map_or(Vec3::ZERO, |a| a * angle);
    let x = [w.x, w.y, w.z, t.x, t.y, t.z];
    let d2: f64 = (0..6).map(|a| (0..6).map(|b| x[a] * ata[a][b] * x[b]).sum::<f64>()).sum::<f64>() / s2.max(1e-30);
    d2.max(0.0).sqrt()
}

/// Refines `carm_from_optical` of the camera whose `observations` are given against the
/// `reference` surface, with the laser `plane` in `carm`.
pub fn refine_camera(
    reference: &Reference,
    observations: &[Observation],
    carm_from_optical: &Iso3,
    plane: &Plane,
    cfg: &RefineConfig,
) -> Result<RefineReport, RefineError> {
    let step = observations.len().div_ceil(cfg.max_points.max(1)).max(1);
    let icp = Icp { reference, obs: observations.iter().step_by(step).collect(), plane, cfg };
    let points = icp.obs.len();
    let first = icp.matches(carm_from_optical);
    let fraction = first.len() as f64 / points.max(1) as f64;
    if first.len() < cfg.min_overlap_points || fraction < cfg.min_overlap_fraction {
        return Err(RefineError::TooLittleOverlap {
            points: first.len(),
            total: points,
            max_distance_m: cfg.max_distance_m,
            min_points: cfg.min_overlap_points,
            min_fraction: cfg.min_overlap_fraction,
        });
    }
    let rms_before = Icp::rms(&icp.trimmed(first));
    let (e, iterations, held_directions) = icp.solve(carm_from_optical)?;
    let all = icp.matches(&e);
    let overlap_fraction = all.len() as f64 / points.max(1) as f64;
    let overlap = all.len();
    let last = icp.trimmed(all);
    let rms_after = Icp::rms(&last);
    // The correction's uncertainty: sigma^2 (J^T W J)^-1 at the result, the residual variance
    // counted per independent measurement.
    let (ata, _) = icp.normal_equations(&last, &e);
    let s2 = rms_after * rms_after * cfg.points_per_measurement;
    let var = variances(ata, s2)?;
    let sigma_rotation_deg = (var[0] + var[1] + var[2]).max(0.0).sqrt().to_degrees();
    let sigma_translation_m = (var[3] + var[4] + var[5]).max(0.0).sqrt();
    let translation_m = e.translation - carm_from_optical.translation;
    let rotation_deg = rotation_angle_deg(&carm_from_optical.rotation, &e.rotation);
    if translation_m.norm() > cfg.max_translation_m || rotation_deg > cfg.max_rotation_deg {
        return Err(RefineError::MovedTooFar {
            translation_m: translation_m.norm(),
            rotation_deg,
            max_translation_m: cfg.max_translation_m,
            max_rotation_deg: cfg.max_rotation_deg,
        });
    }
    if !(rms_after <= cfg.max_rms_m) || overlap < cfg.min_overlap_points {
        return Err(RefineError::PoorFit { rms_m: rms_after, iterations, max_rms_m: cfg.max_rms_m });
    }
    let significance = significance(carm_from_optical, &e, &ata, s2);
    let significant = significance >= cfg.min_significance;
    let reduced = rms_after <= (1.0 - cfg.min_rms_reduction) * rms_before;
    if !(significant && reduced) {
        return Err(RefineError::NotSignificant {
            translation_m: translation_m.norm(),
            rotation_deg,
            significance,
            sigma_translation_m,
            sigma_rotation_deg,
            rms_before_m: rms_before,
            rms_after_m: rms_after,
            min_significance: cfg.min_significance,
            min_rms_reduction: cfg.min_rms_reduction,
        });
    }
    Ok(RefineReport {
        carm_from_optical: e,
        translation_m,
        rotation_deg,
        iterations,
        rms_before_m: rms_before,
        rms_after_m: rms_after,
        overlap_fraction,
        points,
        significance,
        sigma_translation_m,
        sigma_rotation_deg,
        held_directions,
    })
}

/// Points (as `Vec3`) and unit normals of a frame-major grid of `samples` per frame, the normal
/// from the differences to the grid neighbours (across the frame and along the scan) within
/// `max_edge_m`; a zero normal where a direction has no such neighbour.
fn grid_normals(points: &[[f32; 3]], samples: usize, max_edge_m: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    let v = |a: [f32; 3]| Vec3::new(a[0].into(), a[1].into(), a[2].into());
    let n = points.len();
    let lim2 = f64::from(max_edge_m).powi(2);
    // The neighbour at index j if it exists and is close, else the point itself.
    let near = |i: usize, j: Option<usize>| -> Vec3 {
        let p = v(points[i]);
        match j.filter(|&j| j < n).map(|j| v(points[j])) {
            Some(q) if (q - p).norm_squared() <= lim2 => q,
            _ => p,
        }
    };
    let normals = (0..n)
        .map(|i| {
            let s = i % samples.max(1);
            let across = near(i, (s + 1 < samples).then_some(i + 1)) - near(i, (s > 0).then(|| i - 1));
            let along = near(i, Some(i + samples)) - near(i, i.checked_sub(samples));
            across.cross(along).try_normalize().unwrap_or(Vec3::ZERO)
        })
        .collect();
    (points.iter().map(|&p| v(p)).collect(), normals)
}

/// Refines the placement of the camera whose `grid` (triangulated through `carm_from_optical`)
/// is given against the `reference` grid of another camera, and on success re-triangulates the
/// grid's points through the refined placement, in place. Both surfaces are smoothed for the fit
/// (`smooth_iterations`); the points moved are the ones measured. On refusal the grid is
/// untouched and the calibrated placement stands.
pub fn refine_grid(
    reference: &Grid,
    grid: &mut Grid,
    carm_from_optical: &Iso3,
    plane: &Plane,
    motion: &ScanMotion,
    cfg: &RefineConfig,
) -> Result<RefineReport, RefineError> {
    // The reference's surface and the grid's observations side by side.
    let lambda = MeshConfig::DEFAULT.smooth_lambda;
    let smooth = |g: &Grid| g.smoothed_points(cfg.smooth_iterations, lambda, cfg.max_edge_m);
    let (surface, observed) = crate::par::join(
        || reference_surface(reference, &smooth, cfg.max_edge_m),
        || {
            let measured = grid_observations(
                grid.points(),
                grid.samples(),
                carm_from_optical,
                plane,
                motion,
                cfg.max_travel_spread_m,
            )?;
            // The fit uses at most `max_points` observations, from the interior of the smoothed
            // grid (where every point was smoothed); each point's own travel puts it on a laser
            // plane.
            let (smoothed, interior) = smooth(grid);
            let step = interior.len().div_ceil(cfg.max_points.max(1)).max(1);
            let obs: Vec<Observation> = interior
                .iter()
                .step_by(step)
                .filter_map(|&i| {
                    let p = smoothed[i];
                    let v = Vec3::new(p[0].into(), p[1].into(), p[2].into());
                    Observation::from_point(v, &motion.at(motion.travel_of(v, plane)?), carm_from_optical)
                })
                .collect();
            Ok::<_, RefineError>((measured, obs))
        },
    );
    // The errors in the order of one thread's steps: the measured points', then the reference's.
    let (measured, obs) = observed?;
    let surface = surface?;
    let report = refine_camera(&surface, &obs, carm_from_optical, plane, cfg)?;
    let points = grid.points_mut();
    for (i, o) in measured {
        points[i] = o
            .triangulate(&report.carm_from_optical, plane)
            .map_or([f32::NAN; 3], |p| [p.x as f32, p.y as f32, p.z as f32]);
    }
    Ok(report)
}

/// The reference grid's surface for the fit: smoothed on its grid, with normals from it, every
/// other sample along each frame (the planes through them fit as well, and the tree builds in
/// half the time).
fn reference_surface(
    reference: &Grid,
    smooth: &(impl Fn(&Grid) -> (Vec<[f32; 3]>, Vec<usize>) + Sync),
    max_edge_m: f32,
) -> Result<Reference, RefineError> {
    let (ref_points, _) = smooth(reference);
    let (points, normals) = grid_normals(&ref_points, reference.samples(), max_edge_m);
    let ns = reference.samples().max(1);
    let (points, normals): (Vec<Vec3>, Vec<Vec3>) = points
        .into_iter()
        .zip(normals)
        .enumerate()
        .filter(|(i, _)| (i % ns).is_multiple_of(2))
        .map(|(_, pn)| pn)
        .unzip();
    Reference::new(&points, &normals)
}

/// Moves a grid of a camera from one placement (`from`, the one it was triangulated through)
/// to another (`to`, a refined one): each point's ray is recovered through `from` and
/// intersected again with its laser's `plane` through `to`, as [`refine_grid`] does for the grid
/// it refines. The further lasers' grids of a refined camera follow it this way.
pub fn retriangulate_grid(
    grid: &mut Grid,
    from: &Iso3,
    to: &Iso3,
    plane: &Plane,
    motion: &ScanMotion,
    max_spread_m: f64,
) -> Result<(), RefineError> {
    let measured = grid_observations(grid.points(), grid.samples(), from, plane, motion, max_spread_m)?;
    let points = grid.points_mut();
    for (i, o) in measured {
        points[i] = o.triangulate(to, plane).map_or([f32::NAN; 3], |p| [p.x as f32, p.y as f32, p.z as f32]);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn observation_round_trip_and_six_by_six_solve() {
        let e = Iso3::look_at(Vec3::new(0.25, 0.4, 0.8), Vec3::new(0.0, 0.0, 0.05), -Vec3::X).unwrap();
        let plane = Plane::from_params([0.0, 1.0, 0.0, 0.0]).unwrap();
        let pose = Iso3 { rotation: Mat3::IDENTITY, translation: Vec3::new(0.0, 0.1, 0.0) };
        let p = Vec3::new(0.03, 0.1, 0.02);
        let o = Observation::from_point(p, &pose, &e).unwrap();
        assert!((o.triangulate(&e, &plane).unwrap() - p).norm() < 1e-12);
        let a = [
            [4.0, 1.0, 0.0, 0.0, 0.0, 0.5],
            [1.0, 3.0, 0.2, 0.0, 0.0, 0.0],
            [0.0, 0.2, 5.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 2.0, 0.3, 0.0],
            [0.0, 0.0, 0.0, 0.3, 6.0, 1.0],
            [0.5, 0.0, 0.0, 0.0, 1.0, 3.0],
        ];
        let x = [1.0, -2.0, 0.5, 3.0, -1.0, 0.25];
        let b: Vec<f64> = a.iter().map(|r| r.iter().zip(&x).map(|(p, q)| p * q).sum()).collect();
        let got = solve6(a, b.try_into().unwrap()).unwrap();
        assert!(got.iter().zip(&x).all(|(g, w)| (g - w).abs() < 1e-12), "{got:?}");
        assert!(solve6([[0.0; 6]; 6], [1.0; 6]).is_none());
        let r = corrected(&e, &[0.0, 0.0, 0.01, 0.001, 0.0, 0.0]);
        assert!((rotation_angle_deg(&e.rotation, &r.rotation) - 0.01f64.to_degrees()).abs() < 1e-9);
    }

    #[test]
    fn jacobian_matches_central_differences() {
        let e = Iso3::look_at(Vec3::new(0.25, 0.4, 0.8), Vec3::new(0.0, 0.0, 0.05), -Vec3::X).unwrap();
        let plane = Plane::from_params([0.0, 0.96, 0.28, 0.01]).unwrap();
        let pose = Iso3 { rotation: Mat3::rot_y(0.2), translation: Vec3::new(0.0, 0.1, -0.02) };
        let n = Vec3::new(0.3, -0.2, 0.93).try_normalize().unwrap();
        let ray = Vec3::new(0.05, -0.1, 1.0).try_normalize().unwrap();
        let o = Observation { ray, table_from_carm: pose };
        let jac = o.jacobian(&e, &plane, n).unwrap();
        for k in 0..6 {
            let h = 1e-6;
            let (mut xp, mut xm) = ([0.0; 6], [0.0; 6]);
            xp[k] = h;
            xm[k] = -h;
            let pp = o.triangulate(&corrected(&e, &xp), &plane).unwrap();
            let pm = o.triangulate(&corrected(&e, &xm), &plane).unwrap();
            let fd = n.dot(pp - pm) / (2.0 * h);
            assert!((fd - jac[k]).abs() < 1e-6 * (1.0 + fd.abs()), "parameter {k}: {fd} vs {}", jac[k]);
        }
    }

    #[test]
    fn grid_observations_recover_each_frame_and_refuse_a_mixed_one() {
        let e = Iso3::look_at(Vec3::new(0.25, 0.4, 0.8), Vec3::new(0.0, 0.0, 0.05), -Vec3::X).unwrap();
        let plane = Plane::from_params([0.0, 0.96, 0.28, 0.01]).unwrap();
        let motion = ScanMotion { table_from_carm: crate::pose::table_from_carm(0.0, 0.02, 0.1) };
        // Two frames of three points each, on the laser plane at their travels.
        let mut pts = Vec::new();
        for travel in [0.1, 0.13] {
            let pose = motion.at(travel);
            for x in [-0.05, 0.0, 0.04] {
                // A point of the plane in carm: n . q = d, with q.x = x and q.z = 0.02.
                let q = Vec3::new(x, (0.01 - 0.28 * 0.02) / 0.96, 0.02);
                let p = pose.transform_point(q);
                assert!((motion.travel_of(p, &plane).unwrap() - travel).abs() < 1e-12);
                pts.push([p.x as f32, p.y as f32, p.z as f32]);
            }
        }
        pts.push([f32::NAN; 3]);
        pts.push([f32::NAN; 3]);
        pts.push([f32::NAN; 3]);
        // Moved to another placement and back, each point returns where it was.
        let mut g = Grid::new(3);
        for col in pts.chunks(3).take(2) {
            let p = crate::triangulate::Profile {
                points: col.to_vec(),
                intensity: vec![0.0; 3],
                range: vec![0.0; 3],
                ..Default::default()
            };
            g.push(0, &p).unwrap();
        }
        let moved = corrected(&e, &[0.002, -0.001, 0.003, 0.001, 0.0, -0.002]);
        let before = g.clone();
        retriangulate_grid(&mut g, &e, &moved, &plane, &motion, 1e-4).unwrap();
        assert!(g.points().iter().zip(before.points()).any(|(a, b)| (a[2] - b[2]).abs() > 1e-4), "moved");
        retriangulate_grid(&mut g, &moved, &e, &plane, &motion, 1e-4).unwrap();
        for (a, b) in g.points().iter().zip(before.points()) {
            assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-5), "{a:?} vs {b:?}");
        }
        let obs = grid_observations(&pts, 3, &e, &plane, &motion, 1e-4).unwrap();
        assert_eq!(obs.iter().map(|o| o.0).collect::<Vec<_>>(), [0, 1, 2, 3, 4, 5]);
        for (i, o) in &obs {
            let p = o.triangulate(&e, &plane).unwrap();
            let want = Vec3::new(pts[*i][0].into(), pts[*i][1].into(), pts[*i][2].into());
            assert!((p - want).norm() < 1e-6, "{i}: {p:?} vs {want:?}");
        }
        // A frame whose points lie on two travels' planes.
        pts.swap(2, 3);
        let e = grid_observations(&pts, 3, &e, &plane, &motion, 1e-4).unwrap_err();
        assert!(matches!(e, RefineError::NotOneTravel { frame: 0, .. }), "{e}");
    }
}
