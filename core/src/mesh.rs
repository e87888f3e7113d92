//! The organized grid (samples x frames) and its triangulation into a surface mesh.
//!
//! Triangles are made only between grid neighbours, so the mesh grows with the scan and never
//! bridges a deliberate hole. A triangle is kept when every edge passes the length limit
//! (`max_edge_m + max_edge_per_m * range`, the depth-dependent term of PCL's OrganizedFastMesh)
//! and its smallest angle reaches `min_angle_deg` (the study's 12 degrees). On a grid whose
//! frames lie well apart compared with its samples (a fast scan: 4.7 mm between frames and a
//! millimetre between samples), the angles are judged with the frame spacing scaled to the
//! sample spacing, so that the grid's own aspect is not taken for slivers.

use crate::triangulate::Profile;
use serde::{Deserialize, Serialize};

/// The organized point grid of one camera for one scan: column `c` is frame `c`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Grid {
    samples: usize,
    points: Vec<[f32; 3]>,
    intensity: Vec<f32>,
    range: Vec<f32>,
    rgb: Vec<u32>,
    has_rgb: bool,
    stamps_ns: Vec<i64>,
}

impl Grid {
    /// An empty grid with `samples` points per frame.
    pub fn new(samples: usize) -> Self {
        Self { samples, ..Default::default() }
    }
    /// Points per frame (the cloud's `height`).
    pub fn samples(&self) -> usize {
        self.samples
    }
    /// Frames so far (the cloud's `width`).
    pub fn frames(&self) -> usize {
        self.points.len().checked_div(self.samples).unwrap_or(0)
    }
    /// True if colour has been recorded.
    pub fn has_rgb(&self) -> bool {
        self.has_rgb
    }
    /// Appends one frame. A profile of another length is an error (its sample count is returned).
    pub fn push(&mut self, stamp_ns: i64, p: &Profile) -> Result<(), usize> {
        if self.samples == 0 && self.points.is_empty() {
            self.samples = p.points.len();
        }
        if p.points.len() != self.samples || p.intensity.len() != self.samples || p.range.len() != self.samples {
            return Err(p.points.len());
        }
        self.points.extend_from_slice(&p.points);
        self.intensity.extend_from_slice(&p.intensity);
        self.range.extend_from_slice(&p.range);
        match &p.rgb {
            Some(c) if c.len() == self.samples => {
                self.has_rgb = true;
                self.rgb.extend_from_slice(c);
            }
            _ => self.rgb.extend(std::iter::repeat_n(0, self.samples)),
        }
        self.stamps_ns.push(stamp_ns);
        Ok(())
    }
    /// The frames of `frames` with every `stride`-th sample (0, stride, 2 stride, ...): a
    /// coarser grid of part of the scan, for a preview.
    pub fn part(&self, frames: std::ops::Range<usize>, stride: usize) -> Grid {
        let stride = stride.max(1);
        let take = |v: &[f32], f: usize| -> Vec<f32> {
            v[f * self.samples..(f + 1) * self.samples].iter().step_by(stride).copied().collect()
        };
        let mut g = Grid::new(self.samples.div_ceil(stride));
        for f in frames.start..frames.end.min(self.frames()) {
            let row = f * self.samples..(f + 1) * self.samples;
            let p = Profile {
                points: self.points[row.clone()].iter().step_by(stride).copied().collect(),
                intensity: take(&self.intensity, f),
                rgb: self.has_rgb.then(|| self.rgb[row].iter().step_by(stride).copied().collect()),
                range: take(&self.range, f),
                ..Default::default()
            };
            // Same lengths by construction.
            let _ = g.push(self.stamps_ns[f], &p);
        }
        g
    }
    /// The grid of samples `rows` of every frame: one laser's block of a grid that stacks
    /// several lasers' samples (`blocks`).
    pub fn rows(&self, rows: std::ops::Range<usize>) -> Grid {
        let rows = rows.start.min(self.samples)..rows.end.min(self.samples);
        let mut g = Grid::new(rows.len());
        for f in 0..self.frames() {
            let at = f * self.samples + rows.start..f * self.samples + rows.end;
            let p = Profile {
                points: self.points[at.clone()].to_vec(),
                intensity: self.intensity[at.clone()].to_vec(),
                rgb: self.has_rgb.then(|| self.rgb[at.clone()].to_vec()),
                range: self.range[at].to_vec(),
                ..Default::default()
            };
            // Same lengths by construction.
            let _ = g.push(self.stamps_ns[f], &p);
        }
        g
    }
    /// The grid split into `blocks` grids of equal samples per frame, block `k` holding samples
    /// `k * n..(k + 1) * n`: a scanner's lasers, one grid each. One block is the grid itself.
    pub fn blocks(&self, blocks: usize) -> Vec<Grid> {
        if blocks <= 1 {
            return vec![self.clone()];
        }
        let n = self.samples / blocks;
        (0..blocks).map(|k| self.rows(k * n..(k + 1) * n)).collect()
    }
    /// Grids of the same frames stacked sample by sample, the inverse of [`Grid::blocks`]; one
    /// grid is itself, moved.
    pub fn stacked(mut grids: Vec<Grid>) -> Grid {
        if grids.len() == 1 {
            return grids.swap_remove(0);
        }
        let samples = grids.iter().map(|g| g.samples).sum();
        let mut out = Grid::new(samples);
        let frames = grids.iter().map(Grid::frames).min().unwrap_or(0);
        let has_rgb = grids.iter().any(|g| g.has_rgb);
        for f in 0..frames {
            let mut p = Profile { rgb: has_rgb.then(Vec::new), ..Default::default() };
            for g in &grids {
                let at = f * g.samples..(f + 1) * g.samples;
                p.points.extend_from_slice(&g.points[at.clone()]);
                p.intensity.extend_from_slice(&g.intensity[at.clone()]);
                p.range.extend_from_slice(&g.range[at.clone()]);
                if let Some(rgb) = p.rgb.as_mut() {
                    rgb.extend_from_slice(&g.rgb[at]);
                }
            }
            // Same lengths by construction.
            let _ = out.push(grids[0].stamps_ns[f], &p);
        }
        out
    }
    /// Point at sample `s` of frame `f`.
    pub fn point(&self, s: usize, f: usize) -> [f32; 3] {
        self.points[f * self.samples + s]
    }
    /// Points, frame-major (`index = frame * samples + sample`).
    pub fn points(&self) -> &[[f32; 3]] {
        &self.points
    }
    /// The points, for in-place edits (a NaN point is a missing sample).
    pub fn points_mut(&mut self) -> &mut [[f32; 3]] {
        &mut self.points
    }
    /// Laser strength, frame-major.
    pub fn intensity(&self) -> &[f32] {
        &self.intensity
    }
    /// Colours 0x00RRGGBB, frame-major (0 when unknown).
    pub fn rgb(&self) -> &[u32] {
        &self.rgb
    }
    /// Camera distances, frame-major.
    pub fn range(&self) -> &[f32] {
        &self.range
    }
    /// Image stamps of the frames.
    pub fn stamps_ns(&self) -> &[i64] {
        &self.stamps_ns
    }
    /// Number of finite points.
    pub fn valid(&self) -> usize {
        self.points.iter().filter(|p| p[0].is_finite()).count()
    }

    /// The points after `iterations` passes of Laplacian smoothing on the grid itself, and the
    /// indices of the interior points: those whose four grid neighbours are all present and
    /// within `max_edge_m`. An interior point moves `lambda` of the way to their mean on each
    /// pass; every other point (an edge of the scan, a hole's rim, a jump) stays. The mesh-free
    /// counterpart of [`Mesh::smooth`], for when only the points are needed.
    pub fn smoothed_points(&self, iterations: u32, lambda: f32, max_edge_m: f32) -> (Vec<[f32; 3]>, Vec<usize>) {
        let (ns, nf) = (self.samples, self.frames());
        let mut cur = self.points.clone();
        if ns < 3 || nf < 3 {
            return (cur, Vec::new());
        }
        let interior: Vec<usize> = (1..nf - 1)
            .flat_map(|f| (1..ns - 1).map(move |s| f * ns + s))
            .filter(|&i| [i - 1, i + 1, i - ns, i + ns].iter().all(|&j| dist(cur[i], cur[j]) <= max_edge_m))
            .collect();
        let mut next = cur.clone();
        for _ in 0..iterations {
            for &i in &interior {
                let (p, a, b, c, d) = (cur[i], cur[i - 1], cur[i + 1], cur[i - ns], cur[i + ns]);
                next[i] = [0, 1, 2].map(|k| p[k] + lambda * ((a[k] + b[k] + c[k] + d[k]) / 4.0 - p[k]));
            }
            // Only interior points are written, and they all are on every pass.
            std::mem::swap(&mut cur, &mut next);
        }
        (cur, interior)
    }

    /// Fills isolated single missing points (along a frame or across frames) by averaging the two
    /// neighbours when they are closer than `max_gap_m`; larger holes are kept. Returns how many
    /// points were filled.
    pub fn fill_single_holes(&mut self, max_gap_m: f32) -> usize {
        let (ns, nf) = (self.samples, self.frames());
        let mut fills = Vec::new();
        for f in 0..nf {
            for s in 0..ns {
                if self.point(s, f)[0].is_finite() {
                    continue;
                }
                let pairs = [
                    (s > 0 && s + 1 < ns).then(|| ((s - 1, f), (s + 1, f))),
                    (f > 0 && f + 1 < nf).then(|| ((s, f - 1), (s, f + 1))),
                ];
                for ((s0, f0), (s1, f1)) in pairs.into_iter().flatten() {
                    let (a, b) = (self.point(s0, f0), self.point(s1, f1));
                    if a[0].is_finite() && b[0].is_finite() && dist(a, b) <= max_gap_m {
                        let i0 = f0 * ns + s0;
                        let i1 = f1 * ns + s1;
                        fills.push((f * ns + s, mid(a, b), i0, i1));
                        break;
                    }
                }
            }
        }
        for &(i, p, i0, i1) in &fills {
            self.points[i] = p;
            self.intensity[i] = 0.5 * (self.intensity[i0] + self.intensity[i1]);
            self.range[i] = 0.5 * (self.range[i0] + self.range[i1]);
            self.rgb[i] = avg_rgb(self.rgb[i0], self.rgb[i1]);
        }
        fills.len()
    }

    /// Prepares a finished grid for meshing as the mesher does: rejects the points that their
    /// neighbours contradict (`outlier_tolerance_m`, [`Grid::reject_contradicted`]) and those
    /// the laser sheet only partly reached (`partial_sheet_ratio`, [`Grid::partial_sheet`]),
    /// both judged on the grid as it was, then fills single holes if `fill_single_holes`.
    /// Returns the points rejected and filled.
    pub fn clean(&mut self, cfg: &MeshConfig) -> Cleaned {
        // Both verdicts on the grid as it was.
        let mut rejected = self.contradicted(cfg.outlier_tolerance_m, cfg.max_edge_m);
        let partial = self.partial_sheet(cfg.partial_sheet_ratio, cfg.max_edge_m);
        let partial_sheet = partial.len();
        rejected.extend(partial);
        rejected.sort_unstable();
        rejected.dedup();
        let rejected = self.remove(&rejected);
        let filled = if cfg.fill_single_holes { self.fill_single_holes(cfg.max_edge_m) } else { 0 };
        Cleaned { rejected, partial_sheet, filled }
    }

    /// The points at a surface's edge across frames that the laser sheet only partly reached
    /// (indices, frame-major), for [`Grid::clean`].
    ///
    /// The sheet has a thickness. In the frame where it first reaches a surface (the front of an
    /// object, the C-arm moving onto it), or last leaves it, only its tail may fall on the
    /// surface: the line there is weak, and its centre is the centre of the part of the sheet
    /// that the surface catches, not of the sheet, so the point is placed off the surface by up
    /// to the sheet's half-thickness seen along the ray (millimetres on the hard phantom at
    /// 320x240). Its neighbours along the frame make the same error, so they do not contradict
    /// it, and its one neighbour across frames cannot predict it. Its strength tells: such a
    /// point holds a fraction of the light of the same sample in the next frame inward, where
    /// the whole sheet lies on the surface.
    ///
    /// A point is taken when exactly one of its neighbours across frames (the same sample in
    /// the frame before and after) lies within `max_gap_m` of it (the same surface), and that
    /// neighbour's strength is at least `ratio` times its own. Points without a strength (0)
    /// are never taken. `ratio <= 1` takes nothing.
    pub fn partial_sheet(&self, ratio: f32, max_gap_m: f32) -> Vec<usize> {
        let (ns, nf) = (self.samples, self.frames());
        if !(ratio > 1.0) || ns == 0 {
            return Vec::new();
        }
        let gap2 = max_gap_m * max_gap_m;
        // A point with a strength: one the rule can judge, or judge by.
        let judged = |i: usize| self.intensity[i] > 0.0 && self.points[i][0].is_finite();
        let mut out = Vec::new();
        for i in (0..ns * nf).filter(|&i| judged(i)) {
            let p = self.points[i];
            let near = |j: usize| judged(j) && dist2(p, self.points[j]) <= gap2;
            let before = i.checked_sub(ns).filter(|&j| near(j));
            let after = Some(i + ns).filter(|&j| j < ns * nf && near(j));
            if let (Some(j), None) | (None, Some(j)) = (before, after) {
                if self.intensity[j] >= ratio * self.intensity[i] {
                    out.push(i);
                }
            }
        }
        out
    }

    /// Rejects (sets to NaN) the points that their grid neighbours contradict, and returns how
    /// many. This is where a line detector's wrong peak ends up: a highlight, an occlusion
    /// edge's mixed pixel, a bright edge taken for the line in a few rows. Such points sit off a
    /// surface that the points around them agree on.
    ///
    /// Each point is judged along its frame (the neighbouring samples) and across frames (the
    /// same sample in the neighbouring frames). In each direction its neighbours predict it by
    /// straight extrapolation from the two points before it and from the two after it, and by
    /// the midpoint of the points either side. An extrapolation is made only from points
    /// closer to each other than `max_gap_m` (the same surface), the midpoint from points within
    /// twice that. The midpoint is the prediction least moved by the points' own noise: an
    /// extrapolation doubles a neighbour's error, and on a curved surface both extrapolations
    /// overshoot where the midpoint does not, so a point on a noisy or curved surface that lies
    /// between its neighbours is not contradicted by them. A point is
    /// contradicted in a direction when that direction makes at least one prediction and every
    /// prediction misses it by more than `tolerance_m`; it is rejected when it is contradicted in
    /// either direction, unless that direction's one prediction is a lone extrapolation from one
    /// side that misses it by under `LONE_MISS` tolerances while the other direction's midpoint
    /// places it (see [`Verdict`]). A wrong run two points wide is contradicted from both sides: each
    /// side's extrapolation runs into the other wrong point or past it. A real step keeps its points: the side of the step a point lies on predicts
    /// it. A point with too few neighbours to predict it is kept. All verdicts are taken on the
    /// grid as it was, then applied, so the order does not matter. `tolerance_m <= 0` rejects
    /// nothing.
    pub fn reject_contradicted(&mut self, tolerance_m: f32, max_gap_m: f32) -> usize {
        let rejected = self.contradicted(tolerance_m, max_gap_m);
        self.remove(&rejected)
    }

    /// The points [`Grid::reject_contradicted`] rejects (indices, frame-major), the grid left
    /// as it is.
    fn contradicted(&self, tolerance_m: f32, max_gap_m: f32) -> Vec<usize> {
        let (ns, nf) = (self.samples, self.frames());
        if !(tolerance_m > 0.0) || ns == 0 {
            return Vec::new();
        }
        let pts = &self.points;
        let at = |s: isize, f: isize| -> Option<[f32; 3]> {
            if s < 0 || f < 0 || s >= ns as isize || f >= nf as isize {
                return None;
            }
            Some(pts[f as usize * ns + s as usize]).filter(|p| p[0].is_finite())
        };
        let (tol2, gap2) = (tolerance_m * tolerance_m, max_gap_m * max_gap_m);
        // The verdict in one direction: `step(k)` is the neighbour k steps away.
        let verdict = |p: [f32; 3], step: &dyn Fn(isize) -> Option<[f32; 3]>| -> Verdict {
            let (b2, b1, a1, a2) = (step(-2), step(-1), step(1), step(2));
            let extrapolate = |n: Option<[f32; 3]>, m: Option<[f32; 3]>| match (n, m) {
                (Some(n), Some(m)) if dist2(n, m) <= gap2 => Some([0, 1, 2].map(|k| 2.0 * n[k] - m[k])),
                _ => None,
            };
            let (before, after) = (extrapolate(b1, b2), extrapolate(a1, a2));
            // The midpoint, where the extrapolations made agree with it (within twice the
            // tolerance): a wrong run two points wide puts the midpoint halfway to its other
            // point, and the extrapolation through that point twice as far beyond it.
            let between = match (b1, a1) {
                (Some(b), Some(a)) if dist2(a, b) <= 4.0 * gap2 => Some(mid(a, b))
                    .filter(|m| [before, after].into_iter().flatten().all(|q| dist2(q, *m) <= 4.0 * tol2)),
                _ => None,
            };
            let misses = [before, after, between].map(|q| q.map(|q| dist2(p, q)));
            let made = misses.iter().flatten().count();
            let nearest = misses.iter().flatten().fold(f32::INFINITY, |a, &b| a.min(b));
            Verdict {
                contradicted: made > 0 && nearest > tol2,
                lone: made == 1 && misses[2].is_none() && nearest <= LONE_MISS * LONE_MISS * tol2,
                centred: misses[2].is_some_and(|d| d <= tol2),
            }
        };
        let mut rejected = Vec::new();
        for f in 0..nf as isize {
            for s in 0..ns as isize {
                let Some(p) = at(s, f) else { continue };
                let along = verdict(p, &|k| at(s + k, f));
                let across = verdict(p, &|k| at(s, f + k));
                if along.rejects_against(&across) || across.rejects_against(&along) {
                    rejected.push(f as usize * ns + s as usize);
                }
            }
        }
        rejected
    }

    /// Removes the points `indices` (frame-major, each once) and returns how many.
    fn remove(&mut self, indices: &[usize]) -> usize {
        for &i in indices {
            self.points[i] = [f32::NAN; 3];
            self.intensity[i] = 0.0;
            self.range[i] = f32::NAN;
            self.rgb[i] = 0;
        }
        indices.len()
    }
}

/// How one direction of the grid judges a point ([`Grid::reject_contradicted`]).
struct Verdict {
    /// At least one prediction, and every one misses the point by more than the tolerance.
    contradicted: bool,
    /// The one prediction made is an extrapolation from one side (the grid ends or has a gap on
    /// the other) that misses by at most `LONE_MISS` tolerances.
    lone: bool,
    /// The midpoint of the neighbours on both sides predicts the point within the tolerance.
    centred: bool,
}

impl Verdict {
    /// Whether this direction rejects the point, `other` being the other direction's verdict.
    /// A lone extrapolation from one side doubles its neighbour's error and overshoots on a
    /// curved surface; where the other direction's neighbours on both sides place the point,
    /// it is not enough to reject it. (The hard body at 320x240 in grey with its second
    /// surfaces' line: of cam2's points the rule rejected, 390 lay under 1 mm from the surface,
    /// most of them in the first or last frame on a surface or at a run's end.)
    fn rejects_against(&self, other: &Verdict) -> bool {
        self.contradicted && !(self.lone && other.centred)
    }
}

/// How far (in tolerances) a lone extrapolation may miss a point that the other direction's
/// midpoint places, and the point still be kept. Farther, the point is off its surface: with
/// 1.5 the hard phantom at 320x240 in grey, with its second surfaces' line, kept two more points
/// beyond 5 mm (cam2 0.096 -> 0.103 %, over the floor); with 1.3 none, and the hard body at
/// 320x240 in grey with its second line keeps 144 / 175 more of its points (coverage +0.15 /
/// +0.15 points).
const LONE_MISS: f32 = 1.3;

/// What [`Grid::clean`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Cleaned {
    /// Points rejected: those their neighbours contradict, and those the sheet only partly
    /// reached.
    pub rejected: usize,
    /// Of `rejected`, the points the sheet only partly reached ([`Grid::partial_sheet`]).
    pub partial_sheet: usize,
    /// Single holes filled.
    pub filled: usize,
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    dist2(a, b).sqrt()
}
/// Squared distance.
fn dist2(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}
fn mid(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [(a[0] + b[0]) * 0.5, (a[1] + b[1]) * 0.5, (a[2] + b[2]) * 0.5]
}
fn avg_rgb(a: u32, b: u32) -> u32 {
    let ch = |v: u32, sh: u32| (v >> sh) & 0xff;
    (((ch(a, 16) + ch(b, 16)) / 2) << 16) | (((ch(a, 8) + ch(b, 8)) / 2) << 8) | ((ch(a, 0) + ch(b, 0)) / 2)
}

/// Configuration of the mesher (parameters of the `mesher` node).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MeshConfig {
    /// Longest triangle edge at zero range, metres.
    pub max_edge_m: f32,
    /// Extra edge length allowed per metre of camera range (PCL's depth-dependent term).
    pub max_edge_per_m: f32,
    /// Smallest angle a triangle may have, degrees (the study used 12).
    pub min_angle_deg: f32,
    /// Fill isolated single missing points before meshing.
    pub fill_single_holes: bool,
    /// Points that their grid neighbours miss by more than this are rejected before meshing,
    /// metres (0: none); see [`Grid::reject_contradicted`].
    pub outlier_tolerance_m: f32,
    /// A point at a surface's edge across frames is rejected when its one neighbour across
    /// frames holds at least this many times its laser strength: the sheet only partly
    /// reached it (1 or less: none); see [`Grid::partial_sheet`].
    pub partial_sheet_ratio: f32,
    /// Laplacian smoothing iterations (0: none); boundary vertices stay fixed.
    pub smooth_iterations: u32,
    /// Laplacian step (0..1].
    pub smooth_lambda: f32,
}

impl Default for MeshConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl MeshConfig {
    /// The defaults (the mesher's and merger's parameter defaults), usable in constant
    /// expressions.
    pub const DEFAULT: MeshConfig = MeshConfig {
        max_edge_m: 0.012,
        max_edge_per_m: 0.0,
        min_angle_deg: 12.0,
        fill_single_holes: true,
        outlier_tolerance_m: 0.0035,
        partial_sheet_ratio: 1.8,
        smooth_iterations: 0,
        smooth_lambda: 0.5,
    };

    /// Checks every value.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.max_edge_m > 0.0 && self.max_edge_m.is_finite()) {
            return Err(format!("max_edge_m must be > 0, got {}", self.max_edge_m));
        }
        if !(self.max_edge_per_m >= 0.0 && self.max_edge_per_m.is_finite()) {
            return Err(format!("max_edge_per_m must be >= 0, got {}", self.max_edge_per_m));
        }
        if !(0.0..60.0).contains(&self.min_angle_deg) {
            return Err(format!("min_angle_deg must be in [0, 60), got {}", self.min_angle_deg));
        }
        if !(self.outlier_tolerance_m >= 0.0 && self.outlier_tolerance_m.is_finite()) {
            return Err(format!("outlier_tolerance_m must be >= 0, got {}", self.outlier_tolerance_m));
        }
        if !(self.partial_sheet_ratio >= 0.0 && self.partial_sheet_ratio.is_finite()) {
            return Err(format!("partial_sheet_ratio must be >= 0, got {}", self.partial_sheet_ratio));
        }
        if !(self.smooth_lambda > 0.0 && self.smooth_lambda <= 1.0) {
            return Err(format!("smooth_lambda must be in (0, 1], got {}", self.smooth_lambda));
        }
        Ok(())
    }
}

/// A triangle mesh with per-vertex attributes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions (metres, `table`).
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals (same length as positions once computed).
    pub normals: Vec<[f32; 3]>,
    /// Vertex colours (same length as positions).
    pub colors: Vec<[u8; 3]>,
    /// Triangles, counter-clockwise seen from the side the normals point to.
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Adds triangles over the existing vertices; the normals are recomputed if the mesh has
    /// them.
    pub fn add_triangles(&mut self, triangles: Vec<[u32; 3]>) {
        self.triangles.extend(triangles);
        if !self.normals.is_empty() {
            self.compute_normals();
        }
    }

    /// Appends another mesh (indices shifted).
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.colors.extend_from_slice(&other.colors);
        self.triangles.extend(other.triangles.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
    }

    /// Drops the vertices no triangle uses (isolated points are not surface) and renumbers the
    /// triangles. Returns how many were dropped.
    pub fn remove_unreferenced(&mut self) -> usize {
        let n = self.positions.len();
        let mut map = vec![u32::MAX; n];
        for t in &self.triangles {
            for &i in t {
                map[i as usize] = 0;
            }
        }
        let mut next = 0u32;
        for m in map.iter_mut() {
            if *m == 0 {
                *m = next;
                next += 1;
            }
        }
        let keep = |v: &mut Vec<[f32; 3]>| {
            if v.len() == n {
                let mut k = 0;
                v.retain(|_| {
                    k += 1;
                    map[k - 1] != u32::MAX
                });
            }
        };
        keep(&mut self.positions);
        keep(&mut self.normals);
        if self.colors.len() == n {
            let mut k = 0;
            self.colors.retain(|_| {
                k += 1;
                map[k - 1] != u32::MAX
            });
        }
        for t in &mut self.triangles {
            for i in t.iter_mut() {
                *i = map[*i as usize];
            }
        }
        n - next as usize
    }

    /// Area-weighted vertex normals.
    pub fn compute_normals(&mut self) {
        let mut acc = vec![[0.0f32; 3]; self.positions.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.positions[i as usize]);
            let n = cross(sub(b, a), sub(c, a));
            for &i in t {
                let s = &mut acc[i as usize];
                *s = [s[0] + n[0], s[1] + n[1], s[2] + n[2]];
            }
        }
        self.normals = acc
            .into_iter()
            .map(|n| {
                let l = dot(n, n).sqrt();
                if l > 0.0 {
                    [n[0] / l, n[1] / l, n[2] / l]
                } else {
                    [0.0, 0.0, 1.0]
                }
            })
            .collect();
    }

    /// The triangles' corners by vertex: `corners[start[v]..start[v + 1]]` holds, for each
    /// triangle `(v, b, c)` at `v` (in its own order), the pair `(b, c)`: the directed edge
    /// `v -> b` and the third vertex.
    pub(crate) fn corners(&self) -> (Vec<usize>, Vec<(u32, u32)>) {
        let n = self.positions.len();
        let mut start = vec![0usize; n + 1];
        for t in &self.triangles {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut corners = vec![(0u32, 0u32); start[n]];
        for t in &self.triangles {
            for k in 0..3 {
                let a = t[k] as usize;
                corners[fill[a]] = (t[(k + 1) % 3], t[(k + 2) % 3]);
                fill[a] += 1;
            }
        }
        (start, corners)
    }

    /// Laplacian smoothing: each interior vertex moves `lambda` of the way to the mean of its
    /// neighbours, `iterations` times; vertices on a boundary edge stay put.
    pub fn smooth(&mut self, iterations: u32, lambda: f32) {
        if iterations == 0 || self.triangles.is_empty() {
            return;
        }
        let n = self.positions.len();
        // A vertex's corner list holds a neighbour once per triangle on their shared edge, so a
        // neighbour listed once marks a boundary edge (no hash map: this runs on every merge).
        let (start, corners) = self.corners();
        let mut listed: Vec<u32> = corners.iter().flat_map(|&(b, c)| [b, c]).collect();
        let start: Vec<usize> = start.iter().map(|&i| 2 * i).collect();
        // Interior vertices with their distinct neighbours (compressed adjacency).
        let mut interior: Vec<(u32, u32, u32)> = Vec::with_capacity(n);
        let mut adj: Vec<u32> = Vec::with_capacity(start[n] / 2);
        for i in 0..n {
            let nb = &mut listed[start[i]..start[i + 1]];
            nb.sort_unstable();
            let first = adj.len();
            let mut boundary = false;
            let mut k = 0;
            while k < nb.len() {
                let run = nb[k..].iter().take_while(|&&j| j == nb[k]).count();
                boundary |= run == 1;
                adj.push(nb[k]);
                k += run;
            }
            if boundary || adj.len() == first {
                adj.truncate(first);
            } else {
                interior.push((i as u32, first as u32, adj.len() as u32));
            }
        }
        let mut next = self.positions.clone();
        for _ in 0..iterations {
            for &(i, a, b) in &interior {
                let nb = &adj[a as usize..b as usize];
                let mut m = [0.0f32; 3];
                for &j in nb {
                    let p = self.positions[j as usize];
                    for k in 0..3 {
                        m[k] += p[k];
                    }
                }
                let p = self.positions[i as usize];
                for k in 0..3 {
                    next[i as usize][k] = p[k] + lambda * (m[k] / nb.len() as f32 - p[k]);
                }
            }
            // Only interior vertices are written, and they all are on every pass.
            std::mem::swap(&mut self.positions, &mut next);
        }
    }
}

pub(crate) fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(crate) fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
pub(crate) fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn norm(a: [f32; 3]) -> f32 {
    dot(a, a).sqrt()
}

/// Checks of a mesh's shape, for the tests of the steps that add triangles.
#[cfg(test)]
pub(crate) mod checks {
    use super::{cross, norm, sub, Mesh};

    /// The total area of the triangles.
    pub fn area(m: &Mesh) -> f32 {
        m.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.positions[i as usize]);
                norm(cross(sub(b, a), sub(c, a))) / 2.0
            })
            .sum()
    }

    /// Directed edges used twice (an overlap or a flipped triangle).
    pub fn doubled_edges(m: &Mesh) -> usize {
        let mut e: Vec<(u32, u32)> =
            m.triangles.iter().flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]).collect();
        e.sort_unstable();
        e.windows(2).filter(|w| w[0] == w[1]).count()
    }
}

/// True if the triangle `[pa, pb, pc]` has every edge within `max_edge` and its smallest angle
/// at least `asin(sin_min)` (the mesher's test, also the zipper's).
#[inline]
pub(crate) fn triangle_ok([pa, pb, pc]: [[f32; 3]; 3], max_edge: f32, sin_min: f32) -> bool {
    // All in squares (no square roots): lengths, and sin = 2*area / (product of the two edges
    // beside the smallest angle, which is opposite the shortest edge).
    let (ab, bc, ca) = (dist2(pa, pb), dist2(pb, pc), dist2(pc, pa));
    let max2 = max_edge * max_edge;
    if ab > max2 || bc > max2 || ca > max2 || max_edge < 0.0 {
        return false;
    }
    let n = cross(sub(pb, pa), sub(pc, pa));
    let area2_sq = dot(n, n);
    let (e1, e2) = if ab <= bc && ab <= ca {
        (bc, ca)
    } else if bc <= ca {
        (ab, ca)
    } else {
        (ab, bc)
    };
    let den = e1 * e2;
    den > 0.0 && area2_sq >= sin_min * sin_min.abs() * den
}

/// Colour of a vertex without camera colour: grey from the laser strength.
fn grey_from_intensity(i: f32) -> [u8; 3] {
    let g = (90.0 + i.clamp(0.0, 255.0) * 0.6) as u8;
    [g, g, g]
}

/// Frames further apart than this many times the samples make a grid anisotropic: its
/// triangles' angles are judged after scaling (below it, the study's rule as it is).
const ANISOTROPY_MIN: f32 = 1.5;

/// The anisotropy of a grid whose frames lie further apart than its samples (a fast scan, or a
/// high-resolution camera): the mean direction from one frame to the next, and the factor that
/// brings the frame spacing down to the sample spacing. A triangle judged in that squeezed space
/// keeps the study's 12-degree rule for what it is meant for (slivers across depth jumps, which
/// are not along the travel), and a flat surface's own cells are no longer slivers.
#[derive(Debug, Clone, Copy)]
struct GridShape {
    frame_dir: [f32; 3],
    squeeze: f32,
}

impl GridShape {
    /// Every this many cells are sampled for the spacings.
    const STRIDE: usize = 7;

    fn of(grid: &Grid, max_edge: f32) -> Option<GridShape> {
        let (ns, nf) = (grid.samples(), grid.frames());
        let pts = grid.points();
        let lim2 = max_edge * max_edge;
        let (mut across, mut along) = (Vec::new(), Vec::new());
        let mut dir = [0.0f32; 3];
        for i in (0..ns * nf.saturating_sub(1)).step_by(Self::STRIDE) {
            let (p, q) = (pts[i], pts[i + ns]);
            if p[0].is_finite() && q[0].is_finite() && dist2(p, q) <= lim2 {
                along.push(dist2(p, q));
                let d = sub(q, p);
                dir = [dir[0] + d[0], dir[1] + d[1], dir[2] + d[2]];
            }
            if i % ns + 1 < ns {
                let r = pts[i + 1];
                if p[0].is_finite() && r[0].is_finite() && dist2(p, r) <= lim2 {
                    across.push(dist2(p, r));
                }
            }
        }
        let median = |v: &mut Vec<f32>| -> Option<f32> {
            let mid = v.len() / 2;
            (!v.is_empty()).then(|| v.select_nth_unstable_by(mid, f32::total_cmp).1.sqrt())
        };
        let ratio = median(&mut along)? / median(&mut across)?;
        let norm = dot(dir, dir).sqrt();
        (ratio > ANISOTROPY_MIN && norm > 0.0)
            .then(|| GridShape { frame_dir: dir.map(|v| v / norm), squeeze: 1.0 - 1.0 / ratio })
    }

    /// `p` with its component along the frames scaled down by the anisotropy.
    fn squeezed(self, p: [f32; 3]) -> [f32; 3] {
        let k = self.squeeze * dot(p, self.frame_dir);
        [p[0] - k * self.frame_dir[0], p[1] - k * self.frame_dir[1], p[2] - k * self.frame_dir[2]]
    }
}

/// Calls `emit([a, b, c])` (grid indices) for every triangle the mesher makes of `grid`.
fn grid_triangles(grid: &Grid, cfg: &MeshConfig, emit: impl FnMut([usize; 3])) {
    grid_triangles_in(grid, cfg, 0..grid.frames(), emit);
}

/// [`grid_triangles`] of the cells between consecutive frames of `frames` only (the cells
/// from frame `f` to `f + 1` for `f` in `frames.start..frames.end - 1`).
fn grid_triangles_in(grid: &Grid, cfg: &MeshConfig, frames: std::ops::Range<usize>, mut emit: impl FnMut([usize; 3])) {
    let (ns, nf) = (grid.samples(), frames.end.min(grid.frames()));
    let pts = grid.points();
    let valid = |i: usize| pts[i][0].is_finite();
    let sin_min = cfg.min_angle_deg.to_radians().sin();
    let limit = |i: usize| cfg.max_edge_m + cfg.max_edge_per_m * grid.range()[i].max(0.0);
    let fixed = cfg.max_edge_per_m == 0.0;
    let shape = GridShape::of(grid, cfg.max_edge_m);
    // Accept a triangle of grid indices if its edges and angles pass; on an anisotropic grid
    // the angles are judged with the frame spacing scaled to the sample spacing.
    let ok = |a: usize, b: usize, c: usize| -> bool {
        let max_edge = if fixed { cfg.max_edge_m } else { limit(a).min(limit(b)).min(limit(c)) };
        let t = [pts[a], pts[b], pts[c]];
        match shape {
            None => triangle_ok(t, max_edge, sin_min),
            Some(g) => triangle_ok(t, max_edge, 0.0) && triangle_ok(t.map(|p| g.squeezed(p)), f32::INFINITY, sin_min),
        }
    };
    for f in frames.start..nf.saturating_sub(1) {
        for s in 0..ns.saturating_sub(1) {
            let i00 = f * ns + s;
            let i10 = i00 + 1; // next sample, same frame
            let i01 = i00 + ns; // same sample, next frame
            let i11 = i01 + 1;
            let v = [i00, i10, i01, i11].map(valid);
            let mut emit = |a: usize, b: usize, c: usize| {
                if ok(a, b, c) {
                    emit([a, b, c]);
                }
            };
            match v {
                [true, true, true, true] => {
                    // Split along the shorter diagonal.
                    if dist2(pts[i00], pts[i11]) <= dist2(pts[i10], pts[i01]) {
                        emit(i00, i10, i11);
                        emit(i00, i11, i01);
                    } else {
                        emit(i00, i10, i01);
                        emit(i10, i11, i01);
                    }
                }
                [false, true, true, true] => emit(i10, i11, i01),
                [true, false, true, true] => emit(i00, i11, i01),
                [true, true, false, true] => emit(i00, i10, i11),
                [true, true, true, false] => emit(i00, i10, i01),
                _ => {}
            }
        }
    }
}

/// For each grid sample, whether some triangle of [`mesh_grid`] uses it (a sample can be valid
/// and still lie in no triangle: an isolated point, or one whose cells are all slivers, as on a
/// face seen edge-on).
pub fn meshed_samples(grid: &Grid, cfg: &MeshConfig) -> Vec<bool> {
    let mut used = vec![false; grid.points().len()];
    grid_triangles(grid, cfg, |t| t.iter().for_each(|&i| used[i] = true));
    used
}

/// Triangulates an organized grid into a mesh. Its vertices are the grid's finite points that
/// some triangle uses (isolated points are left out of the surface; the grid keeps them).
pub fn mesh_grid(grid: &Grid, cfg: &MeshConfig) -> Mesh {
    let mut mesh = raw_mesh(grid, cfg, 0..grid.frames());
    mesh.smooth(cfg.smooth_iterations, cfg.smooth_lambda);
    mesh.compute_normals();
    mesh
}

/// The part of [`mesh_grid`] between the frames of `frames` (the cells from each frame of it to
/// the next), unsmoothed: what a growing scan adds since its last part. The parts of
/// consecutive ranges that share their boundary frame (`a..b`, then `b - 1..c`) together hold
/// every triangle of the unsmoothed whole, each once.
pub fn mesh_grid_frames(grid: &Grid, cfg: &MeshConfig, frames: std::ops::Range<usize>) -> Mesh {
    let mut mesh = raw_mesh(grid, cfg, frames);
    mesh.compute_normals();
    mesh
}

/// The triangles of the cells in `frames`, on the samples they use, facing up.
fn raw_mesh(grid: &Grid, cfg: &MeshConfig, frames: std::ops::Range<usize>) -> Mesh {
    const UNUSED: u32 = u32::MAX;
    const USED: u32 = u32::MAX - 1;
    let mut index = vec![UNUSED; grid.points().len()];
    let mut corners: Vec<[u32; 3]> = Vec::with_capacity(2 * grid.samples() * frames.len());
    grid_triangles_in(grid, cfg, frames, |t| {
        corners.push(t.map(|i| i as u32));
        for i in t {
            index[i] = USED;
        }
    });
    // The used samples become vertices in grid order.
    let mut mesh = Mesh::default();
    let used = index.iter().filter(|&&v| v == USED).count();
    mesh.positions.reserve_exact(used);
    mesh.colors.reserve_exact(used);
    for (i, v) in index.iter_mut().enumerate().filter(|(_, v)| **v == USED) {
        *v = mesh.positions.len() as u32;
        mesh.positions.push(grid.points()[i]);
        mesh.colors.push(if grid.has_rgb() {
            let c = grid.rgb()[i];
            [(c >> 16) as u8, (c >> 8) as u8, c as u8]
        } else {
            grey_from_intensity(grid.intensity()[i])
        });
    }
    mesh.triangles = corners.into_iter().map(|t| t.map(|i| index[i as usize])).collect();
    // Orient the surface to face up (the scanner looks down on the table).
    let up: f32 = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            cross(sub(b, a), sub(c, a))[2]
        })
        .sum();
    if up < 0.0 {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat_grid(ns: usize, nf: usize, ds: f32, df: f32) -> Grid {
        let mut g = Grid::new(ns);
        for f in 0..nf {
            let p = Profile {
                points: (0..ns).map(|s| [s as f32 * ds, f as f32 * df, 0.0]).collect(),
                intensity: vec![100.0; ns],
                rgb: None,
                range: vec![1.0; ns],
                ..Default::default()
            };
            g.push(f as i64, &p).unwrap();
        }
        g
    }

    /// A grid of `z(x, y)` sampled `ds` apart along frames and `df` apart across them, with
    /// uniform noise of `noise` metres either way (a fixed sequence).
    fn surface(ns: usize, nf: usize, ds: f32, df: f32, noise: f32, z: impl Fn(f32, f32) -> f32) -> Grid {
        let mut g = Grid::new(ns);
        let mut seed = 12345u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
        };
        for f in 0..nf {
            let p = Profile {
                points: (0..ns)
                    .map(|s| {
                        let (x, y) = (s as f32 * ds, f as f32 * df);
                        [x, y, z(x, y) + noise * rnd()]
                    })
                    .collect(),
                intensity: vec![100.0; ns],
                rgb: None,
                range: vec![1.0; ns],
                ..Default::default()
            };
            g.push(f as i64, &p).unwrap();
        }
        g
    }

    /// A part of a grid: its frames, every stride-th sample, the rest as it was.
    #[test]
    fn a_part_of_a_grid_keeps_its_frames_and_every_nth_sample() {
        let g = flat_grid(7, 5, 0.001, 0.002);
        let whole = g.part(0..5, 1);
        assert_eq!((whole.points(), whole.stamps_ns()), (g.points(), g.stamps_ns()));
        let p = g.part(2..9, 3);
        assert_eq!((p.samples(), p.frames()), (3, 3));
        assert_eq!(p.point(2, 0), g.point(6, 2));
        assert_eq!(p.stamps_ns(), &g.stamps_ns()[2..5]);
    }

    /// A growing scan's parts, each meshed from the frame where the last one ended, hold the
    /// unsmoothed whole's triangles, each once (compared by their corners' positions).
    #[test]
    fn the_parts_of_a_growing_scan_make_the_whole() {
        let g = surface(60, 50, 0.001, 0.0023, 0.0002, |x, y| 0.05 + 0.3 * (x - 0.03) * (y - 0.05));
        let cfg = MeshConfig { smooth_iterations: 0, ..MeshConfig::default() };
        let key = |m: &Mesh| -> Vec<[[u32; 3]; 3]> {
            let mut v: Vec<[[u32; 3]; 3]> = m
                .triangles
                .iter()
                .map(|t| {
                    let mut c = t.map(|i| m.positions[i as usize].map(f32::to_bits));
                    c.sort_unstable();
                    c
                })
                .collect();
            v.sort_unstable();
            v
        };
        let whole = key(&mesh_grid(&g, &cfg));
        assert!(whole.len() > 5000);
        let mut parts = Vec::new();
        let mut from = 0;
        for to in [1, 2, 9, 10, 23, 50] {
            let m = mesh_grid_frames(&g, &cfg, from..to);
            assert!(m.positions.iter().all(|p| p[1] >= from as f32 * 0.0023 - 1e-6), "only the new frames");
            parts.extend(key(&m));
            from = to.max(1) - 1;
        }
        parts.sort_unstable();
        assert_eq!(parts, whole);
    }

    /// Smooth surfaces, ridges and steps in either direction keep every point, at the sample
    /// spacing of a slow scan and of a fast one (frames 4.7 mm apart).
    #[test]
    fn surfaces_ridges_and_steps_keep_their_points() {
        type Height = fn(f32, f32) -> f32;
        let cases: [(&str, Height); 5] = [
            ("dome", |x, y| 0.08 - ((x - 0.04).powi(2) + (y - 0.08).powi(2)) * 3.0),
            ("ridge across frames", |_, y| 0.086 - 0.82 * (y - 0.08).abs()),
            ("ridge along frames", |x, _| 0.086 - 0.82 * (x - 0.04).abs()),
            ("step across frames", |_, y| if y > 0.08 { 0.04 } else { 0.0 }),
            ("step along frames", |x, _| if x > 0.04 { 0.008 } else { 0.0 }),
        ];
        for (name, z) in &cases {
            for df in [0.0023, 0.0047] {
                let mut g = surface(80, (0.16 / df) as usize, 0.001, df, 0.0003, z);
                let before = g.valid();
                assert_eq!(g.reject_contradicted(0.003, 0.012), 0, "{name}, frames {df} m apart");
                assert_eq!(g.valid(), before);
            }
        }
    }

    /// A wrong peak in one frame, the same in two frames over a few samples, and a run along one
    /// frame are rejected, and nothing else.
    #[test]
    fn points_their_neighbours_contradict_are_rejected() {
        let mut g = surface(60, 60, 0.001, 0.0023, 0.0003, |x, y| 0.02 + 0.3 * x - 0.2 * y);
        let ns = g.samples();
        let mut wrong = vec![(10, 10)];
        wrong.extend((20..25).flat_map(|s| [(s, 30), (s, 31)]));
        wrong.extend((30..40).map(|s| (s, 50)));
        for &(s, f) in &wrong {
            g.points_mut()[f * ns + s][2] += 0.006;
        }
        let before = g.valid();
        assert_eq!(g.reject_contradicted(0.003, 0.012), wrong.len());
        assert_eq!(g.valid(), before - wrong.len());
        for &(s, f) in &wrong {
            assert!(g.point(s, f)[0].is_nan(), "sample {s} of frame {f} kept");
            assert_eq!((g.intensity()[f * ns + s], g.rgb()[f * ns + s]), (0.0, 0));
        }
        // A tolerance of zero rejects nothing.
        let mut g = flat_grid(10, 10, 0.001, 0.002);
        g.points_mut()[55][2] = 0.05;
        assert_eq!(g.reject_contradicted(0.0, 0.012), 0);
        // The mesher's preparation rejects before it fills: the hole left is filled from the
        // neighbours, not from the wrong point.
        let cleaned = g.clean(&MeshConfig::default());
        assert_eq!(cleaned, Cleaned { rejected: 1, partial_sheet: 0, filled: 1 });
        assert!(g.point(5, 5)[2].abs() < 1e-6, "{:?}", g.point(5, 5));
    }

    /// Points as noisy as the hard scanner's at 320x240 (uniform, +-1.4 mm: 0.8 mm standard
    /// deviation) on a tilted plane, samples 2.5 mm and frames 4.7 mm apart: no point with a
    /// neighbour on each side is contradicted (an extrapolation alone misses such a point by up
    /// to 5.6 mm, the midpoint by at most 2.8 mm), and wrong points 10 mm off still are.
    #[test]
    fn noisy_points_between_their_neighbours_are_kept() {
        let (ns, nf) = (60, 60);
        let mut g = surface(ns, nf, 0.0025, 0.0047, 0.0014, |x, y| 0.02 + 0.3 * x - 0.2 * y);
        let interior = |s: usize, f: usize| (1..ns - 1).contains(&s) && (1..nf - 1).contains(&f);
        let mut g2 = g.clone();
        g2.reject_contradicted(0.0035, 0.012);
        let lost: Vec<(usize, usize)> = (0..nf)
            .flat_map(|f| (0..ns).map(move |s| (s, f)))
            .filter(|&(s, f)| interior(s, f) && g2.point(s, f)[0].is_nan())
            .collect();
        assert!(lost.is_empty(), "{} interior points rejected: {lost:?}", lost.len());
        let wrong = [(10, 10), (30, 25), (45, 50)];
        for &(s, f) in &wrong {
            g.points_mut()[f * ns + s][2] += 0.010;
        }
        g.reject_contradicted(0.0035, 0.012);
        for &(s, f) in &wrong {
            assert!(g.point(s, f)[0].is_nan(), "sample {s} of frame {f} kept");
        }
        // A point beside a wrong one may lose the predictions through it and go too.
        let lost_beside = (0..nf)
            .flat_map(|f| (0..ns).map(move |s| (s, f)))
            .filter(|&(s, f)| !wrong.contains(&(s, f)) && g2.point(s, f)[0].is_finite() && g.point(s, f)[0].is_nan())
            .count();
        assert!(lost_beside <= 2, "{lost_beside} points beside the wrong ones lost");
    }

    /// The same noisy plane: its first and last frames' points have neighbours across frames on
    /// one side only, a lone extrapolation that misses them by up to 5.6 mm, while along their
    /// frame the midpoint places them. All but one are kept (the rule without the other
    /// direction's say rejected 3 of the 116); wrong points 10 mm off there still go.
    #[test]
    fn noisy_points_at_the_grids_ends_are_kept_where_the_other_direction_places_them() {
        let (ns, nf) = (60, 60);
        let mut g = surface(ns, nf, 0.0025, 0.0047, 0.0014, |x, y| 0.02 + 0.3 * x - 0.2 * y);
        let ends: Vec<(usize, usize)> =
            [0, nf - 1].into_iter().flat_map(|f| (1..ns - 1).map(move |s| (s, f))).collect();
        let mut g2 = g.clone();
        g2.reject_contradicted(0.0035, 0.012);
        let lost = ends.iter().filter(|&&(s, f)| g2.point(s, f)[0].is_nan()).count();
        assert!(lost <= 1, "{lost} of the {} points of the end frames rejected", ends.len());
        let wrong = [(20, 0), (40, nf - 1)];
        for &(s, f) in &wrong {
            g.points_mut()[f * ns + s][2] += 0.010;
        }
        g.reject_contradicted(0.0035, 0.012);
        for &(s, f) in &wrong {
            assert!(g.point(s, f)[0].is_nan(), "sample {s} of frame {f} kept");
        }
    }

    /// A surface curved across frames (z = c (y - y0)^2, flat along them), frames 4.7 mm apart:
    /// the straight extrapolation from the two frames before the last misses the last by
    /// 2 c df^2 = 4.0 mm, over the tolerance (3.5 mm) but under 1.3 of it, while along its frame
    /// the midpoint places it exactly. Kept (the rule before rejected both end frames); 1 mm
    /// off the surface the extrapolation misses by 5 mm, and the point goes.
    #[test]
    fn a_lone_extrapolation_over_a_curve_does_not_reject_what_the_other_direction_places() {
        let (ns, nf, df) = (20, 6, 0.0047);
        let y0 = 0.5 * (nf - 1) as f32 * df;
        let curved = || surface(ns, nf, 0.0025, df, 0.0, |_, y| 90.0 * (y - y0).powi(2));
        let mut g = curved();
        assert_eq!(g.reject_contradicted(0.0035, 0.012), 4, "the corners alone: no midpoint along");
        for f in [0, nf - 1] {
            assert!((1..ns - 1).all(|s| g.point(s, f)[0].is_finite()), "frame {f} lost points");
        }
        let mut g = curved();
        g.points_mut()[(nf - 1) * ns + 10][2] += 0.001;
        g.reject_contradicted(0.0035, 0.012);
        assert!(g.point(10, nf - 1)[0].is_nan(), "a point 1 mm off the curve kept");
        assert!(g.point(9, nf - 1)[0].is_finite() && g.point(11, nf - 1)[0].is_finite());
    }

    /// A box 20 mm high on the table, frames 20-39 on it. The first and last frame on it are
    /// weak (the sheet's tail) and 2.5 mm high: taken as partly reached, whatever the rejection of
    /// contradicted points makes of them; the same edges at full strength, the table's own edges
    /// and a grid without strengths keep every point.
    #[test]
    fn points_the_sheet_only_partly_reached_are_rejected() {
        let on_box = |f: usize| (20..40).contains(&f);
        let boxed =
            |weak: f32| {
                let mut g = surface(30, 60, 0.001, 0.002, 0.0002, |_, y| {
                    if on_box((y / 0.002).round() as usize) {
                        0.02
                    } else {
                        0.0
                    }
                });
                let ns = g.samples();
                for (f, strength) in [(20, weak), (39, weak * 1.2)] {
                    for s in 0..ns {
                        g.points_mut()[f * ns + s][2] += 0.0025;
                        g.intensity[f * ns + s] = strength;
                    }
                }
                g
            };
        let mut g = boxed(30.0);
        assert_eq!(g.clone().reject_contradicted(0.0035, 0.012), 0, "the rule before this one keeps them");
        let ns = g.samples();
        let cleaned = g.clean(&MeshConfig { fill_single_holes: false, ..Default::default() });
        assert_eq!(cleaned, Cleaned { rejected: 2 * ns, partial_sheet: 2 * ns, filled: 0 });
        assert!((0..ns).all(|s| g.point(s, 20)[0].is_nan() && g.point(s, 39)[0].is_nan()));
        assert_eq!(g.valid(), 58 * ns);
        // Strong enough: the sheet lay wholly on the box.
        assert!(boxed(60.0).partial_sheet(1.8, 0.012).is_empty());
        // Off, and without strengths.
        assert!(boxed(30.0).partial_sheet(0.0, 0.012).is_empty());
        let mut g = boxed(30.0);
        g.intensity.iter_mut().for_each(|i| *i = 0.0);
        assert!(g.partial_sheet(1.8, 0.012).is_empty());
    }

    proptest::proptest! {
        /// The test in squares decides as the test in lengths and angles does (away from the
        /// limits, where rounding may go either way).
        #[test]
        fn triangle_test_in_squares_matches_lengths_and_angles(
            p in proptest::array::uniform9(-0.02f32..0.02),
            max_edge in 0.0f32..0.03,
            min_angle_deg in 0.0f32..40.0,
        ) {
            let [a, b, c] = [[p[0], p[1], p[2]], [p[3], p[4], p[5]], [p[6], p[7], p[8]]];
            let sin_min = min_angle_deg.to_radians().sin();
            let (ab, bc, ca) = (dist(a, b), dist(b, c), dist(c, a));
            let area2 = {
                let n = cross(sub(b, a), sub(c, a));
                dot(n, n).sqrt()
            };
            // The sine of the smallest angle, opposite the shortest edge.
            let mut e = [ab, bc, ca];
            e.sort_by(f32::total_cmp);
            let sin = area2 / (e[1] * e[2]);
            let longest = e[2];
            let clear = (longest - max_edge).abs() > 1e-4 * max_edge && (sin - sin_min).abs() > 1e-4 && e[0] > 1e-6;
            if clear {
                proptest::prop_assert_eq!(triangle_ok([a, b, c], max_edge, sin_min), longest <= max_edge && sin >= sin_min);
            }
        }
    }

    #[test]
    fn full_grid_gives_two_triangles_per_cell_facing_up() {
        let g = flat_grid(5, 4, 0.001, 0.002);
        let m = mesh_grid(&g, &MeshConfig::default());
        assert_eq!(m.positions.len(), 20);
        assert_eq!(m.triangles.len(), 2 * 4 * 3);
        assert!(m.normals.iter().all(|n| (n[2] - 1.0).abs() < 1e-6));
    }

    #[test]
    fn isolated_points_are_not_surface_vertices() {
        let mut g = flat_grid(4, 4, 0.001, 0.001);
        // A far point in the middle of a row: its triangles fail the edge rule.
        g.points[5] = [0.5, 0.5, 0.5];
        let m = mesh_grid(&g, &MeshConfig::default());
        assert_eq!(m.positions.len(), 15);
        assert!(m.positions.iter().all(|p| p[2] == 0.0));
        assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < m.positions.len()));
        assert_eq!(m.colors.len(), 15);
    }

    #[test]
    fn long_edges_and_slivers_are_refused() {
        let g = flat_grid(3, 3, 0.001, 0.02);
        assert_eq!(mesh_grid(&g, &MeshConfig::default()).triangles.len(), 0, "20 mm edges");
        // 0.5 mm x 10 mm cells (smallest angle 2.9 degrees) are the grid's own aspect when every
        // cell is so: meshed (see the anisotropic test). A sliver inside an isotropic grid is
        // refused: one sample pulled 0.9 mm along its cell's diagonal.
        let g = flat_grid(3, 3, 0.0005, 0.010);
        assert_eq!(mesh_grid(&g, &MeshConfig::default()).triangles.len(), 8);
        let mut g = flat_grid(3, 3, 0.001, 0.001);
        g.points[4] = [0.0019, 0.0019, 0.0];
        let n = mesh_grid(&g, &MeshConfig::default()).triangles.len();
        assert!(n < 8, "{n} triangles: the slivers next to the displaced sample are refused");
        let cfg = MeshConfig { min_angle_deg: 0.5, ..Default::default() };
        assert_eq!(mesh_grid(&g, &cfg).triangles.len(), 8);
    }

    #[test]
    fn single_holes_filled_deliberate_holes_kept() {
        let mut g = flat_grid(6, 6, 0.001, 0.001);
        let ns = 6;
        g.points[2 * ns + 3] = [f32::NAN; 3];
        for s in 1..4 {
            g.points[4 * ns + s] = [f32::NAN; 3];
            g.points[5 * ns + s] = [f32::NAN; 3];
        }
        let filled = g.fill_single_holes(0.01);
        assert_eq!(filled, 1);
        assert!((g.point(3, 2)[0] - 0.003).abs() < 1e-6);
        assert!(g.point(2, 4)[0].is_nan());
    }

    #[test]
    fn smoothing_keeps_boundary_and_flattens_a_bump() {
        let mut g = flat_grid(5, 5, 0.001, 0.001);
        g.points[2 * 5 + 2][2] = 0.001;
        let mut m = mesh_grid(&g, &MeshConfig::default());
        let before: Vec<_> = m.positions.clone();
        m.smooth(5, 0.5);
        assert!(m.positions[12][2] < 0.0005);
        assert_eq!(m.positions[0], before[0]);
        assert_eq!(m.positions[4], before[4]);
    }

    #[test]
    fn grid_smoothing_flattens_a_bump_and_keeps_edges_rims_and_jumps() {
        let at = |f: usize, s: usize| f * 7 + s;
        let mut g = flat_grid(7, 7, 0.001, 0.001);
        g.points[at(3, 3)][2] = 0.001; // a bump
        g.points[at(5, 1)] = [f32::NAN; 3]; // a hole
        g.points[at(1, 5)][2] = 0.05; // a jump past the edge limit
        let (p, interior) = g.smoothed_points(5, 0.5, 0.012);
        assert!(p[at(3, 3)][2] < 0.0005 && p[at(3, 3)][2] > 0.0);
        // The scan's edge, the hole's rim and both sides of the jump stay where they were.
        for i in [0, 3, at(6, 3), at(4, 1), at(5, 2), at(1, 5), at(1, 4), at(2, 5)] {
            assert_eq!(p[i], g.points[i], "point {i}");
            assert!(!interior.contains(&i), "point {i}");
        }
        assert!(p[at(5, 1)][0].is_nan());
        assert!(interior.contains(&(at(3, 3))));
        assert_eq!(interior.len(), 25 - 6, "interior: {interior:?}"); // less the hole, jump and their neighbours
                                                                      // No passes: the points as they are.
        let bits = |v: &[[f32; 3]]| v.iter().map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(&g.smoothed_points(0, 0.5, 0.012).0), bits(&g.points));
    }

    #[test]
    fn mismatched_profile_length_is_refused() {
        let mut g = flat_grid(4, 1, 0.001, 0.001);
        let p = Profile {
            points: vec![[0.0; 3]; 3],
            intensity: vec![0.0; 3],
            rgb: None,
            range: vec![0.0; 3],
            ..Default::default()
        };
        assert_eq!(g.push(1, &p), Err(3));
    }

    #[test]
    fn anisotropic_grid_keeps_its_surface_and_still_refuses_depth_jumps() {
        // Frames 10 times further apart than samples: 0.5 mm across, 5 mm along the travel.
        let flat = flat_grid(40, 30, 0.0005, 0.005);
        let cfg = MeshConfig::default();
        let mesh = mesh_grid(&flat, &cfg);
        assert_eq!(mesh.triangles.len(), 2 * 39 * 29, "every cell of a flat anisotropic grid is meshed");
        // The study's rule alone would drop them all (smallest angle 5.7 degrees).
        assert!(GridShape::of(&flat, cfg.max_edge_m).is_some());
        // A depth jump across the samples (a 4 mm step in z between two samples) is still not
        // bridged: its triangles are slivers in any scaling.
        let mut g = Grid::new(40);
        for f in 0..30 {
            let p = Profile {
                points: (0..40)
                    .map(|s| [s as f32 * 0.0005, f as f32 * 0.005, if s < 20 { 0.0 } else { 0.004 }])
                    .collect(),
                intensity: vec![100.0; 40],
                rgb: None,
                range: vec![1.0; 40],
                ..Default::default()
            };
            g.push(f as i64, &p).unwrap();
        }
        let mesh = mesh_grid(&g, &cfg);
        assert_eq!(mesh.triangles.len(), 2 * 38 * 29, "the cells across the jump are refused, the others kept");
        // An isotropic grid keeps the study's rule exactly.
        assert!(GridShape::of(&flat_grid(20, 20, 0.001, 0.0012), cfg.max_edge_m).is_none());
    }
    /// A stacked grid split into its blocks and stacked again is itself; each block holds its
    /// own samples.
    #[test]
    fn blocks_split_and_stack_back() {
        let g = surface(30, 7, 0.001, 0.002, 0.0, |x, y| x + y);
        let b = g.blocks(3);
        assert_eq!(b.iter().map(Grid::samples).collect::<Vec<_>>(), vec![10, 10, 10]);
        assert_eq!(b[1].point(4, 5), g.point(14, 5));
        assert_eq!(b[2].stamps_ns(), g.stamps_ns());
        assert_eq!(Grid::stacked(b), g);
        assert_eq!(g.blocks(1), vec![g.clone()]);
    }
}
