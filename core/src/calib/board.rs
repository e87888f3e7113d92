//! Checkerboard detection: X-junction candidates (negative Hessian determinant on a smoothed
//! image, confirmed by four alternating sectors on a ring around them), a lattice grown from a
//! seed by local prediction, labelled in a fixed order (see [`BoardSpec`]), and refined to
//! sub-pixel precision by the gradient-orthogonality condition (every gradient near a corner is
//! perpendicular to the vector from the corner).

use crate::geom::Vec3;
use crate::image::{Encoding, ImageView};
use std::collections::HashMap;

/// A checkerboard: `cols x rows` inner corners (OpenCV's pattern size), `square_m` apart.
///
/// Corner `k = j * cols + i` lies at `(i * square_m, j * square_m, 0)` in the board frame. The
/// board frame's x runs along the `cols` corners, y along the `rows`, and z = x × y points
/// into the board (away from a camera that sees the printed side). Corner 0 is the corner whose
/// diagonal outer square is black; when `cols + rows` is odd that choice is unique (the far
/// corner's outer square is white), otherwise a 180-degree turn of the board is ambiguous.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardSpec {
    /// Inner corners along x.
    pub cols: usize,
    /// Inner corners along y.
    pub rows: usize,
    /// Square size, metres.
    pub square_m: f64,
}

impl BoardSpec {
    /// A board from `COLSxROWS` (inner corners, for example `9x6`) and the square size.
    pub fn parse(size: &str, square_m: f64) -> Result<BoardSpec, String> {
        let (c, r) = size.split_once(['x', 'X']).ok_or_else(|| format!("board size {size:?} is not COLSxROWS"))?;
        let n = |s: &str| s.trim().parse::<usize>().map_err(|_| format!("board size {size:?} is not COLSxROWS"));
        let spec = BoardSpec { cols: n(c)?, rows: n(r)?, square_m };
        if spec.cols < 3 || spec.rows < 3 || spec.cols > 64 || spec.rows > 64 {
            return Err(format!("board size {size}: need 3..=64 inner corners each way"));
        }
        if !(square_m > 0.0 && square_m < 1.0) {
            return Err(format!("square size {square_m} m is not in (0, 1)"));
        }
        Ok(spec)
    }
    /// Number of inner corners.
    pub fn len(&self) -> usize {
        self.cols * self.rows
    }
    /// Always false (a board has corners); for symmetry with [`BoardSpec::len`].
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Corner `k` in the board frame, metres.
    pub fn point(&self, k: usize) -> Vec3 {
        Vec3::new((k % self.cols) as f64 * self.square_m, (k / self.cols) as f64 * self.square_m, 0.0)
    }
    /// Whether corner 0 is unique (see the type's documentation).
    pub fn origin_unique(&self) -> bool {
        self.cols != self.rows && (self.cols + self.rows) % 2 == 1
    }
    /// Whether square `(a, b)` (its corner nearest the origin at inner corner `(a, b)`, with
    /// `a` in `-1..cols` and `b` in `-1..rows`) is black.
    pub fn square_is_black(a: i64, b: i64) -> bool {
        (a + b).rem_euclid(2) == 0
    }
}

/// The corners found in one image, in board order, pixels (ROS convention: the top-left
/// pixel's centre is (0, 0)).
#[derive(Debug, Clone, PartialEq)]
pub struct Corners {
    /// Corner positions, `cols * rows`, row-major.
    pub points: Vec<[f64; 2]>,
    /// Median distance between neighbouring corners, pixels.
    pub spacing_px: f64,
}

/// Why no board was found, in terms a technician can act on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BoardError {
    /// The image is too small to hold a board.
    #[error("board not found: the image is only {width}x{height} pixels")]
    TooSmall {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
    /// Hardly any light.
    #[error("board not found: image too dark (99th percentile grey level {p99:.0} of 255): more light or exposure")]
    TooDark {
        /// 99th percentile grey level (8-bit scale).
        p99: f64,
    },
    /// No pattern with usable contrast.
    #[error("board not found: too little contrast (grey levels {lo:.0} to {hi:.0}): board missing or over-exposed")]
    LowContrast {
        /// 1st percentile.
        lo: f64,
        /// 99th percentile.
        hi: f64,
    },
    /// Edges spread over many pixels.
    #[error("board not found: image blurred (edges spread over about {sigma_px:.1} px): focus, or hold still")]
    Blurred {
        /// Estimated blur (Gaussian sigma), pixels.
        sigma_px: f64,
    },
    /// A partial lattice reaches the image border.
    #[error(
        "board cut off by the frame: {found_cols}x{found_rows} of {cols}x{rows} inner corners found, reaching the image edge"
    )]
    CutOff {
        /// Corners found along one axis.
        found_cols: usize,
        /// Corners found along the other.
        found_rows: usize,
        /// Expected.
        cols: usize,
        /// Expected.
        rows: usize,
    },
    /// The lattice found is not the board's.
    #[error("board not found: the best corner grid is {found_cols}x{found_rows} ({found} corners), expected {cols}x{rows} inner corners ({candidates} corner candidates){hint}")]
    WrongGrid {
        /// Corners in that grid (fewer than its extent where some are missing).
        found: usize,
        /// Corners found along one axis.
        found_cols: usize,
        /// Corners found along the other.
        found_rows: usize,
        /// Expected.
        cols: usize,
        /// Expected.
        rows: usize,
        /// X-junction candidates seen.
        candidates: usize,
        /// A hint (wrong `--board` size, partly hidden).
        hint: String,
    },
}

/// A grey image as f32 (8-bit scale).
struct Grey {
    w: usize,
    h: usize,
    data: Vec<f32>,
}

impl Grey {
    fn from_view(view: &ImageView<'_>) -> Grey {
        let (w, h) = (view.width() as usize, view.height() as usize);
        let mut data = Vec::with_capacity(w * h);
        if view.encoding() == Encoding::Mono8 {
            for y in 0..h as u32 {
                data.extend(view.row(y)[..w].iter().map(|&b| f32::from(b)));
            }
        } else {
            for y in 0..h as u32 {
                for x in 0..w as u32 {
                    let [r, g, b] = view.rgb_at(x, y);
                    data.push(crate::image::luma(f32::from(r), f32::from(g), f32::from(b)));
                }
            }
        }
        Grey { w, h, data }
    }
    fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.w + x]
    }
    /// Bilinear sample, clamped to the image.
    fn sample(&self, x: f64, y: f64) -> f32 {
        let x = x.clamp(0.0, (self.w - 1) as f64);
        let y = y.clamp(0.0, (self.h - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.w - 1), (y0 + 1).min(self.h - 1));
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let top = self.at(x0, y0) * (1.0 - fx) + self.at(x1, y0) * fx;
        let bottom = self.at(x0, y1) * (1.0 - fx) + self.at(x1, y1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
    fn blurred(&self, sigma: f64) -> Grey {
        Grey { w: self.w, h: self.h, data: crate::image::gaussian_blur(&self.data, self.w, self.h, sigma) }
    }
    fn percentile(&self, q: f64) -> f64 {
        percentile(self.data.iter().map(|&v| f64::from(v)).collect(), q)
    }
}

fn percentile(mut v: Vec<f64>, q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    let (_, x, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    *x
}

/// Ring radius of the X-junction test, pixels.
const RING_PX: f64 = 3.5;
const RING_SAMPLES: usize = 24;

/// Whether the ring around `(x, y)` shows four alternating sectors with at least `min_contrast`:
/// on the ring's own values split where they separate best (Otsu's), or on the ring made
/// symmetric (each sample plus the one opposite), which cancels a shadow's or a gradient's
/// one-sided change: across a shadow's edge one bright square may be darker than the other's
/// half-way level, yet both stay brighter than the dark pair.
/// Candidates take the first test only; the second is for a corner the lattice predicts
/// (`predicted`), where a line or stripe that passes it is rejected by the squares' colours.
fn is_x_junction(g: &Grey, x: f64, y: f64, radius: f64, min_contrast: f32, predicted: bool) -> bool {
    let mut s = [0.0f32; RING_SAMPLES];
    for (k, v) in s.iter_mut().enumerate() {
        let a = std::f64::consts::TAU * k as f64 / RING_SAMPLES as f64;
        *v = g.sample(x + radius * a.cos(), y + radius * a.sin());
    }
    let (lo, hi) = s.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    if hi - lo < min_contrast {
        return false;
    }
    if four_sectors(&s, otsu_split(&s)) {
        return true;
    }
    if !predicted {
        return false;
    }
    let mut sym = [0.0f32; RING_SAMPLES];
    for (k, v) in sym.iter_mut().enumerate() {
        *v = 0.5 * (s[k] + s[(k + RING_SAMPLES / 2) % RING_SAMPLES]);
    }
    let (lo, hi) = sym.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    hi - lo >= 0.5 * min_contrast && four_sectors(&sym, 0.5 * (lo + hi))
}

/// The threshold that splits the values into the two groups of largest between-class variance
/// (Otsu's), half-way between the two values it falls between.
fn otsu_split(values: &[f32]) -> f32 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f32::total_cmp);
    let n = sorted.len();
    let Some((&first, &last)) = sorted.first().zip(sorted.last()) else { return 0.0 };
    let total: f32 = sorted.iter().sum();
    let (mut best, mut mid, mut below) = (f32::MIN, 0.5 * (first + last), 0.0f32);
    for k in 1..n {
        below += sorted[k - 1];
        let (n0, n1) = (k as f32, (n - k) as f32);
        let (m0, m1) = (below / n0, (total - below) / n1);
        let between = n0 * n1 * (m1 - m0) * (m1 - m0);
        if between > best {
            best = between;
            mid = 0.5 * (sorted[k - 1] + sorted[k]);
        }
    }
    mid
}

/// Whether the ring's samples above and below `mid` form four runs of at least two samples.
fn four_sectors(s: &[f32; RING_SAMPLES], mid: f32) -> bool {
    let bits: Vec<bool> = s.iter().map(|&v| v > mid).collect();
    let Some(start) = (0..RING_SAMPLES).find(|&k| bits[k] != bits[(k + RING_SAMPLES - 1) % RING_SAMPLES]) else {
        return false;
    };
    // Run lengths starting at a transition.
    let mut runs = Vec::new();
    let mut len = 0;
    for k in 0..RING_SAMPLES {
        let i = (start + k) % RING_SAMPLES;
        if k > 0 && bits[i] != bits[(i + RING_SAMPLES - 1) % RING_SAMPLES] {
            runs.push(len);
            len = 0;
        }
        len += 1;
    }
    runs.push(len);
    runs.len() == 4 && runs.iter().all(|&r| r >= 2)
}

/// The corner response of a smoothed image: the negative Hessian determinant where it is
/// positive (saddles), zero elsewhere; and its maximum.
fn saddle_response(g: &Grey) -> (Vec<f32>, f32) {
    let (w, h) = (g.w, g.h);
    let mut resp = vec![0.0f32; w * h];
    let mut max = 0.0f32;
    for y in 2..h.saturating_sub(2) {
        for x in 2..w.saturating_sub(2) {
            let c = g.at(x, y);
            let ixx = g.at(x + 1, y) - 2.0 * c + g.at(x - 1, y);
            let iyy = g.at(x, y + 1) - 2.0 * c + g.at(x, y - 1);
            let ixy = 0.25 * (g.at(x + 1, y + 1) - g.at(x + 1, y - 1) - g.at(x - 1, y + 1) + g.at(x - 1, y - 1));
            let r = ixy * ixy - ixx * iyy;
            if r > 0.0 {
                resp[y * w + x] = r;
                max = max.max(r);
            }
        }
    }
    (resp, max)
}

/// X-junction candidates (integer positions) of a smoothed image with its response.
fn candidates(g: &Grey, resp: &[f32], max: f32, min_contrast: f32) -> Vec<[f64; 2]> {
    let (w, h) = (g.w, g.h);
    let thr = 0.02 * max;
    let mut out = Vec::new();
    const NMS: usize = 3;
    for y in NMS..h.saturating_sub(NMS) {
        'px: for x in NMS..w.saturating_sub(NMS) {
            let r = resp[y * w + x];
            if r <= thr {
                continue;
            }
            for yy in y - NMS..=y + NMS {
                for xx in x - NMS..=x + NMS {
                    let o = resp[yy * w + xx];
                    if o > r || (o == r && (yy, xx) < (y, x)) {
                        continue 'px;
                    }
                }
            }
            if is_x_junction(g, x as f64, y as f64, RING_PX, min_contrast, false) {
                out.push([x as f64, y as f64]);
            }
        }
    }
    out
}

type Cell = (i32, i32);

fn d2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

/// What the lattice search works on: the images, the corner response and the candidates.
struct Search<'a> {
    /// Lightly smoothed image: square colours.
    fine: &'a Grey,
    /// Smoothed images with their corner responses, finest first: X-junction tests at the
    /// lattice's scale (a coarser one closes the gaps of boards whose squares do not quite touch).
    levels: &'a [Level],
    /// Ring contrast an X-junction needs.
    min_contrast: f32,
}

/// One scale of the corner search.
struct Level {
    sigma: f64,
    grey: Grey,
    resp: Vec<f32>,
}

impl Level {
    fn new(raw: &Grey, sigma: f64) -> Level {
        let grey = raw.blurred(sigma);
        let (resp, _) = saddle_response(&grey);
        Level { sigma, grey, resp }
    }
}

/// Smoothing of the corner search's levels, pixels.
const LEVEL_SIGMAS: [f64; 3] = [1.5, 3.0, 6.0];

/// A lattice being grown: cell -> point, the points (candidates plus corners found by local
/// search), and which square colour cell (0, 0) has.
struct Lattice {
    grid: HashMap<Cell, usize>,
    pts: Vec<[f64; 2]>,
    /// +1 when square (0, 0) (between corners (0, 0) and (1, 1)) is the brighter colour.
    phase: f64,
    /// Sign of the image-space cross product of the lattice's i and j steps.
    handed: f64,
}

/// The smallest corner spacing taken for a board, pixels: finer lattices (a speaker grille, a
/// keyboard, a fabric) are texture, and the corner tests cannot resolve them.
const MIN_STEP_PX: f64 = 2.0 * RING_PX + 1.0;

/// Step to the next corner, as a fraction of the lattice step, within which a candidate is
/// taken for the predicted corner.
const CAPTURE: f64 = 0.35;

impl Search<'_> {
    /// Mean grey level of a square around `centre`, spanned by half-steps `u` and `v`.
    fn square_value(&self, centre: [f64; 2], u: [f64; 2], v: [f64; 2]) -> f64 {
        let mut s = 0.0;
        for (a, b) in [(0.0, 0.0), (0.4, 0.0), (-0.4, 0.0), (0.0, 0.4), (0.0, -0.4)] {
            s += f64::from(self.fine.sample(centre[0] + a * u[0] + b * v[0], centre[1] + a * u[1] + b * v[1]));
        }
        s / 5.0
    }

    /// Whether an edge from `c` to `t` (lattice cells, neighbours; `t` at `pt`) has the
    /// checkerboard's colours, with enough contrast, in the two squares beside it and in the two
    /// beyond `t`. The second pair keeps a lattice from stepping off the board onto a false
    /// corner (a narrow white border against a darker background looks like an X-junction).
    fn edge_ok(&self, lat: &Lattice, c: Cell, t: Cell, pt: [f64; 2]) -> bool {
        let pc = lat.pts[lat.grid[&c]];
        let d = (t.0 - c.0, t.1 - c.1);
        let e = (d.1.abs(), d.0.abs()); // the other axis, positive direction
        let p = |cell: Cell| lat.grid.get(&cell).map(|&k| lat.pts[k]);
        let step = [pt[0] - pc[0], pt[1] - pc[1]];
        // The lattice step along +e near the edge.
        let perp = match (p((c.0 + e.0, c.1 + e.1)), p((c.0 - e.0, c.1 - e.1))) {
            (Some(q), _) => [q[0] - pc[0], q[1] - pc[1]],
            (None, Some(q)) => [pc[0] - q[0], pc[1] - q[1]],
            (None, None) => {
                // A quarter turn of the step, to the side the lattice's handedness puts +e.
                let factor = if d.0 != 0 { lat.handed * f64::from(d.0) } else { -lat.handed * f64::from(d.1) };
                [-step[1] * factor, step[0] * factor]
            }
        };
        let half_step = [0.5 * step[0], 0.5 * step[1]];
        let half_perp = [0.5 * perp[0], 0.5 * perp[1]];
        let thr = f64::from(0.4 * self.min_contrast);
        // Segment from `a` (cell) at `pa` one step along d: its +e square has its lower corner
        // at min(a, a + d).
        let segment_ok = |a: Cell, pa: [f64; 2]| {
            let mid = [pa[0] + half_step[0], pa[1] + half_step[1]];
            let plus = self.square_value([mid[0] + half_perp[0], mid[1] + half_perp[1]], half_step, half_perp);
            let minus = self.square_value([mid[0] - half_perp[0], mid[1] - half_perp[1]], half_step, half_perp);
            let sq = (a.0.min(a.0 + d.0), a.1.min(a.1 + d.1));
            let sign = if (sq.0 + sq.1).rem_euclid(2) == 0 { lat.phase } else { -lat.phase };
            (plus - minus) * sign > thr
        };
        if !(segment_ok(c, pc) && segment_ok(t, pt)) {
            return false;
        }
        // Close around `t`, its four squares in the lattice's orientation: a corner of another
        // pattern (a second board, clutter) taken for `t` is turned or scaled differently.
        let (mut bright, mut dark) = (f64::INFINITY, f64::NEG_INFINITY);
        for sd in [-1, 1] {
            for se in [-1, 1] {
                let q = [
                    pt[0] + 0.3 * (f64::from(sd) * step[0] + f64::from(se) * perp[0]),
                    pt[1] + 0.3 * (f64::from(sd) * step[1] + f64::from(se) * perp[1]),
                ];
                let v = f64::from(self.fine.sample(q[0], q[1]));
                let sq = (t.0.min(t.0 + sd * d.0 + se * e.0), t.1.min(t.1 + sd * d.1 + se * e.1));
                if ((sq.0 + sq.1).rem_euclid(2) == 0) == (lat.phase > 0.0) {
                    bright = bright.min(v);
                } else {
                    dark = dark.max(v);
                }
            }
        }
        bright - dark > thr
    }

    /// The strongest X-junction within `radius` of `pred` that no candidate marks, tested at
    /// the level whose smoothing suits the lattice `step` (pixels).
    fn local_corner(&self, pred: [f64; 2], radius: f64, step: f64) -> Option<[f64; 2]> {
        let level = self.levels.iter().rev().find(|l| l.sigma <= step / 8.0).or(self.levels.first())?;
        let (w, h) = (level.grey.w as i64, level.grey.h as i64);
        let r = radius.ceil() as i64;
        let (cx, cy) = (pred[0].round() as i64, pred[1].round() as i64);
        let mut best: Option<(f32, [f64; 2])> = None;
        for y in (cy - r).max(2)..=(cy + r).min(h - 3) {
            for x in (cx - r).max(2)..=(cx + r).min(w - 3) {
                let q = [x as f64, y as f64];
                let v = level.resp[y as usize * w as usize + x as usize];
                if v > 0.0 && d2(q, pred) <= radius * radius && best.is_none_or(|(b, _)| v > b) {
                    best = Some((v, q));
                }
            }
        }
        let (_, q) = best?;
        let ring = RING_PX.max(2.5 * level.sigma).min(0.3 * step);
        is_x_junction(&level.grey, q[0], q[1], ring, 0.5 * self.min_contrast, true).then_some(q)
    }

    /// Starts a lattice at candidate `seed`: two neighbours at about a right angle whose four
    /// squares around the seed alternate in colour.
    fn start(&self, pts: &[[f64; 2]], seed: usize) -> Option<Lattice> {
        let ps = pts[seed];
        let mut near: Vec<usize> = (0..pts.len()).filter(|&k| k != seed).collect();
        near.sort_by(|&a, &b| d2(pts[a], ps).total_cmp(&d2(pts[b], ps)));
        near.truncate(8);
        for (n, &a) in near.iter().enumerate() {
            let va = [pts[a][0] - ps[0], pts[a][1] - ps[1]];
            let la = va[0].hypot(va[1]);
            for &b in near.iter().skip(n + 1) {
                let vb = [pts[b][0] - ps[0], pts[b][1] - ps[1]];
                let lb = vb[0].hypot(vb[1]);
                let square = (va[0] * vb[0] + va[1] * vb[1]).abs() / (la * lb) < 0.6 && lb < 2.0 * la && la < 2.0 * lb;
                if !square || la.min(lb) < MIN_STEP_PX {
                    continue;
                }
                let (hu, hv) = ([0.5 * va[0], 0.5 * va[1]], [0.5 * vb[0], 0.5 * vb[1]]);
                let at = |su: f64, sv: f64| {
                    self.square_value([ps[0] + su * hu[0] + sv * hv[0], ps[1] + su * hu[1] + sv * hv[1]], hu, hv)
                };
                let (s00, s11, s10, s01) = (at(1.0, 1.0), at(-1.0, -1.0), at(-1.0, 1.0), at(1.0, -1.0));
                let thr = f64::from(0.4 * self.min_contrast);
                let phase = (s00 - s10).signum();
                let alternate = [s00 - s10, s00 - s01, s11 - s10, s11 - s01].iter().all(|&x| x * phase > thr);
                if !alternate {
                    continue;
                }
                let mut grid = HashMap::new();
                grid.insert((0, 0), seed);
                grid.insert((1, 0), a);
                grid.insert((0, 1), b);
                let handed = (va[0] * vb[1] - va[1] * vb[0]).signum();
                return Some(Lattice { grid, pts: pts.to_vec(), phase, handed });
            }
        }
        None
    }

    /// Grows a lattice from candidate `seed` by predicting each neighbour and taking the
    /// candidate there (or an X-junction found by a local search) if the squares along the new
    /// edge have the checkerboard's colours.
    fn grow(&self, pts: &[[f64; 2]], seed: usize) -> Option<Lattice> {
        let mut lat = self.start(pts, seed)?;
        let mut used = vec![false; lat.pts.len()];
        for &k in lat.grid.values() {
            used[k] = true;
        }
        let dirs: [Cell; 4] = [(1, 0), (-1, 0), (0, 1), (0, -1)];
        loop {
            let mut added = false;
            let mut cells: Vec<Cell> = lat.grid.keys().copied().collect();
            cells.sort_unstable();
            for c in cells {
                for d in dirs {
                    let t = (c.0 + d.0, c.1 + d.1);
                    if lat.grid.contains_key(&t) {
                        continue;
                    }
                    let Some(mut pred) = predict(&lat, c, d) else { continue };
                    let pc = lat.pts[lat.grid[&c]];
                    let step2 = d2(pred, pc);
                    let mut radius = CAPTURE * step2.sqrt();
                    // Where the lattice around is dense enough, its local homography predicts
                    // far better, and a corner of another pattern near the board's edge is
                    // off that prediction.
                    if let Some(h) = local_homography(&lat, t) {
                        pred = h;
                        radius = (HOMOGRAPHY_CAPTURE * step2.sqrt()).max(1.5);
                    }
                    let best = (0..lat.pts.len())
                        .filter(|&k| !used[k])
                        .min_by(|&x, &y| d2(lat.pts[x], pred).total_cmp(&d2(lat.pts[y], pred)))
                        .filter(|&k| d2(lat.pts[k], pred) < radius * radius);
                    let k = match best {
                        Some(k) => k,
                        None => match self.local_corner(pred, radius, step2.sqrt()) {
                            Some(q) => {
                                lat.pts.push(q);
                                used.push(false);
                                lat.pts.len() - 1
                            }
                            None => continue,
                        },
                    };
                    if self.edge_ok(&lat, c, t, lat.pts[k]) {
                        lat.grid.insert(t, k);
                        used[k] = true;
                        added = true;
                    }
                }
            }
            if !added {
                return Some(lat);
            }
        }
    }
}

/// Where the neighbour of `c` in direction `d` should be: the lattice continued along `d`
/// (with perspective's steady change of step) and the parallelograms with the neighbours
/// beside it, averaged.
fn predict(lat: &Lattice, c: Cell, d: Cell) -> Option<[f64; 2]> {
    let p = |cell: Cell| lat.grid.get(&cell).map(|&k| lat.pts[k]);
    let pc = p(c)?;
    let t = (c.0 + d.0, c.1 + d.1);
    let mut preds = Vec::new();
    if let Some(pb) = p((c.0 - d.0, c.1 - d.1)) {
        let ratio = match p((c.0 - 2 * d.0, c.1 - 2 * d.1)) {
            Some(pa) => (d2(pc, pb) / d2(pb, pa).max(1e-12)).sqrt().clamp(0.5, 2.0),
            None => 1.0,
        };
        preds.push([pc[0] + (pc[0] - pb[0]) * ratio, pc[1] + (pc[1] - pb[1]) * ratio]);
    }
    for e in [(d.1, d.0), (-d.1, -d.0)] {
        if let (Some(ce), Some(te)) = (p((c.0 + e.0, c.1 + e.1)), p((t.0 + e.0, t.1 + e.1))) {
            preds.push([pc[0] + te[0] - ce[0], pc[1] + te[1] - ce[1]]);
        }
    }
    if preds.is_empty() {
        return None;
    }
    let n = preds.len() as f64;
    Some([preds.iter().map(|q| q[0]).sum::<f64>() / n, preds.iter().map(|q| q[1]).sum::<f64>() / n])
}

/// The fraction of the lattice step within which a corner must lie of the local homography's
/// prediction.
const HOMOGRAPHY_CAPTURE: f64 = 0.15;

/// Where the homography fitted to the lattice's corners within two cells of `t` puts `t`;
/// None with fewer than six such corners, or all in one row or column.
fn local_homography(lat: &Lattice, t: Cell) -> Option<[f64; 2]> {
    let (mut plane, mut image) = (Vec::new(), Vec::new());
    for i in t.0 - 2..=t.0 + 2 {
        for j in t.1 - 2..=t.1 + 2 {
            if let Some(&k) = lat.grid.get(&(i, j)) {
                plane.push([f64::from(i - t.0), f64::from(j - t.1)]);
                image.push(lat.pts[k]);
            }
        }
    }
    let spans = |axis: usize| plane.iter().any(|p| p[axis] != plane[0][axis]);
    if plane.len() < 6 || !spans(0) || !spans(1) {
        return None;
    }
    let h = super::homography(&plane, &image)?;
    let w = h[8];
    (w.abs() > 1e-12).then(|| [h[2] / w, h[5] / w])
}

/// A lattice grown with a diagonal as one of its axes (strong foreshortening makes a diagonal
/// the shorter step) is a sheared rectangle: undo the shear that makes it full.
fn unshear(grid: HashMap<Cell, usize>) -> HashMap<Cell, usize> {
    if extent(&grid).4 {
        return grid;
    }
    for k in [-1, 1, -2, 2] {
        for along_i in [true, false] {
            let sheared: HashMap<Cell, usize> = grid
                .iter()
                .map(|(&(i, j), &v)| if along_i { ((i + k * j, j), v) } else { ((i, j + k * i), v) })
                .collect();
            if extent(&sheared).4 {
                return sheared;
            }
        }
    }
    grid
}

/// Extent (columns, rows) of a lattice and whether it is a full rectangle.
fn extent(grid: &HashMap<Cell, usize>) -> (i32, i32, i32, i32, bool) {
    let (mut i0, mut i1, mut j0, mut j1) = (i32::MAX, i32::MIN, i32::MAX, i32::MIN);
    for &(i, j) in grid.keys() {
        i0 = i0.min(i);
        i1 = i1.max(i);
        j0 = j0.min(j);
        j1 = j1.max(j);
    }
    let full = grid.len() as i64 == i64::from(i1 - i0 + 1) * i64::from(j1 - j0 + 1);
    (i0, j0, i1 - i0 + 1, j1 - j0 + 1, full)
}

/// The board's window in a lattice: the one full `cols x rows` (or `rows x cols`) rectangle of
/// cells. None when there is none, or more than one (a larger checkerboard than asked for).
fn board_window(grid: &HashMap<Cell, usize>, spec: &BoardSpec) -> Option<HashMap<Cell, usize>> {
    if grid.is_empty() {
        return None;
    }
    let (i0, j0, ci, cj, _) = extent(grid);
    let mut found = Vec::new();
    let mut sizes = vec![(spec.cols as i32, spec.rows as i32)];
    if spec.cols != spec.rows {
        sizes.push((spec.rows as i32, spec.cols as i32));
    }
    for (wc, wr) in sizes {
        for a in i0..=i0 + ci - wc {
            for b in j0..=j0 + cj - wr {
                if (a..a + wc).all(|i| (b..b + wr).all(|j| grid.contains_key(&(i, j)))) {
                    found.push((a, b, wc, wr));
                }
            }
        }
    }
    let [(a, b, wc, wr)] = found[..] else { return None };
    Some(
        grid.iter()
            .filter(|(&(i, j), _)| i >= a && i < a + wc && j >= b && j < b + wr)
            .map(|(&c, &k)| (c, k))
            .collect(),
    )
}

/// The window around `q0` (`r` pixels each way, clamped to the image) with the light flattened:
/// divided by a plane fitted to the window's bright pixels (those above its Otsu split), so
/// that a shadow's edge or a gradient across the corner leaves its four squares as even as on a
/// flat-lit board. Returns the patch and its origin in the image; the window as it is where
/// the fit fails.
fn flattened(g: &Grey, q0: [f64; 2], r: usize) -> (Grey, usize, usize) {
    let (cx, cy) = (q0[0].round().max(0.0) as usize, q0[1].round().max(0.0) as usize);
    let (x0, y0) = (cx.saturating_sub(r), cy.saturating_sub(r));
    let (x1, y1) = ((cx + r).min(g.w - 1), (cy + r).min(g.h - 1));
    let (w, h) = (x1 + 1 - x0, y1 + 1 - y0);
    let mut data = Vec::with_capacity(w * h);
    for y in y0..=y1 {
        data.extend_from_slice(&g.data[y * g.w + x0..=y * g.w + x1]);
    }
    let patch = Grey { w, h, data };
    let split = f64::from(otsu_split(&patch.data));
    // Least-squares plane a + b x + c y over the bright pixels.
    let (mut m, mut v) = ([0.0f64; 9], [0.0f64; 3]);
    let mut bright = 0usize;
    for y in 0..h {
        for x in 0..w {
            let val = f64::from(patch.data[y * w + x]);
            if val <= split {
                continue;
            }
            bright += 1;
            let f = [1.0, x as f64 - w as f64 / 2.0, y as f64 - h as f64 / 2.0];
            for i in 0..3 {
                v[i] += f[i] * val;
                for j in 0..3 {
                    m[i * 3 + j] += f[i] * f[j];
                }
            }
        }
    }
    if bright < 12 {
        return (patch, x0, y0);
    }
    let Some(l) = crate::calib::linalg::cholesky(&m, 3) else { return (patch, x0, y0) };
    let [a, bx, by] = <[f64; 3]>::try_from(crate::calib::linalg::cholesky_solve(&l, 3, &v)).unwrap_or([0.0; 3]);
    let light = |x: usize, y: usize| a + bx * (x as f64 - w as f64 / 2.0) + by * (y as f64 - h as f64 / 2.0);
    let corners = [light(0, 0), light(w - 1, 0), light(0, h - 1), light(w - 1, h - 1)];
    if corners.iter().any(|&c| !(c > 0.2 * a)) || !(a > 0.0) {
        return (patch, x0, y0);
    }
    let mut flat = patch;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            flat.data[i] = (f64::from(flat.data[i]) * a / light(x, y)) as f32;
        }
    }
    (flat, x0, y0)
}

/// Refines a corner: minimises `sum w (g . (p - q))^2` over the window (gradient `g` at `p`),
/// on the window with its light flattened ([`flattened`]).
fn refine(image: &Grey, q0: [f64; 2], half: usize) -> [f64; 2] {
    let (g, ox, oy) = flattened(image, q0, 2 * half + 2);
    let (ox, oy) = (ox as f64, oy as f64);
    let start = [q0[0] - ox, q0[1] - oy];
    let mut q = start;
    let sigma = half as f64 * 0.6;
    let grad = |x: usize, y: usize| {
        (f64::from(g.at(x + 1, y) - g.at(x - 1, y)) * 0.5, f64::from(g.at(x, y + 1) - g.at(x, y - 1)) * 0.5)
    };
    for _ in 0..20 {
        let (cx, cy) = (q[0].round() as isize, q[1].round() as isize);
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let h = half as isize;
        for y in cy - h..=cy + h {
            for x in cx - h..=cx + h {
                if x < 1 || y < 1 || x as usize >= g.w - 1 || y as usize >= g.h - 1 {
                    continue;
                }
                let (gx, gy) = grad(x as usize, y as usize);
                let (dx, dy) = (x as f64 - q[0], y as f64 - q[1]);
                let w = (-(dx * dx + dy * dy) / (2.0 * sigma * sigma)).exp();
                let (xx, yy, xy) = (w * gx * gx, w * gy * gy, w * gx * gy);
                a11 += xx;
                a12 += xy;
                a22 += yy;
                b1 += xx * x as f64 + xy * y as f64;
                b2 += xy * x as f64 + yy * y as f64;
            }
        }
        let det = a11 * a22 - a12 * a12;
        if !(det.abs() > 1e-9) {
            break;
        }
        let n = [(a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det];
        let moved = ((n[0] - q[0]).powi(2) + (n[1] - q[1]).powi(2)).sqrt();
        if ((n[0] - start[0]).powi(2) + (n[1] - start[1]).powi(2)).sqrt() > half as f64 {
            return q0; // ran away: keep the candidate
        }
        q = n;
        if moved < 0.002 {
            break;
        }
    }
    [q[0] + ox, q[1] + oy]
}

/// An image made ready for the lattice search: grey, smoothed, its levels and candidates.
struct Prepared {
    raw: Grey,
    fine: Grey,
    levels: Vec<Level>,
    min_contrast: f32,
    pts: Vec<[f64; 2]>,
    /// 1st and 99th percentile grey levels.
    lo: f64,
    hi: f64,
}

impl Prepared {
    fn new(view: &ImageView<'_>) -> Prepared {
        let raw = Grey::from_view(view);
        let (lo, hi) = (raw.percentile(0.01), raw.percentile(0.99));
        let fine = raw.blurred(0.8);
        let min_contrast = (0.15 * (hi - lo) as f32).max(6.0);
        let levels: Vec<Level> = LEVEL_SIGMAS.iter().map(|&s| Level::new(&raw, s)).collect();
        let max = levels[0].resp.iter().fold(0.0f32, |m, &v| m.max(v));
        let pts = candidates(&levels[0].grey, &levels[0].resp, max, min_contrast);
        Prepared { raw, fine, levels, min_contrast, pts, lo, hi }
    }
    fn search(&self) -> Search<'_> {
        Search { fine: &self.fine, levels: &self.levels, min_contrast: self.min_contrast }
    }
}

/// Finds the board in an image.
pub fn detect(view: &ImageView<'_>, spec: &BoardSpec) -> Result<Corners, BoardError> {
    if view.width() < 16 || view.height() < 16 {
        return Err(BoardError::TooSmall { width: view.width(), height: view.height() });
    }
    let prep = Prepared::new(view);
    let (raw, fine, pts, lo, hi) = (&prep.raw, &prep.fine, &prep.pts, prep.lo, prep.hi);
    let search = prep.search();

    // Seeds: candidates nearest the centroid first; a seed already in a grown lattice would
    // grow the same one again.
    let n = pts.len().max(1) as f64;
    let centroid = [pts.iter().map(|p| p[0]).sum::<f64>() / n, pts.iter().map(|p| p[1]).sum::<f64>() / n];
    let mut order: Vec<usize> = (0..pts.len()).collect();
    order.sort_by(|&a, &b| d2(pts[a], centroid).total_cmp(&d2(pts[b], centroid)));
    let mut seen = vec![false; pts.len()];
    let mut best = Lattice { grid: HashMap::new(), pts: Vec::new(), phase: 1.0, handed: 1.0 };
    let mut tried = 0;
    for &seed in &order {
        if seen[seed] {
            continue;
        }
        if tried == MAX_SEEDS {
            break;
        }
        tried += 1;
        let Some(mut lat) = search.grow(pts, seed) else { continue };
        for &k in lat.grid.values() {
            if let Some(s) = seen.get_mut(k) {
                *s = true;
            }
        }
        lat.grid = unshear(std::mem::take(&mut lat.grid));
        if let Some(window) = board_window(&lat.grid, spec) {
            return Ok(label(&window, &lat.pts, spec, fine));
        }
        if lat.grid.len() > best.grid.len() {
            best = lat;
        }
    }
    Err(explain(raw, &best.grid, &best.pts, spec, lo, hi, pts.len()))
}

/// Lattices grown (from different seeds) before the search gives up.
const MAX_SEEDS: usize = 40;

/// Orders a full lattice as the board's corners and refines them.
fn label(grid: &HashMap<Cell, usize>, pts: &[[f64; 2]], spec: &BoardSpec, g: &Grey) -> Corners {
    let (i0, j0, ci, cj, _) = extent(grid);
    let at = |i: i32, j: i32| pts[grid[&(i0 + i, j0 + j)]];
    // (i, j) -> board (col, row), starting with the lattice as found.
    let mut idx: Vec<Vec<[f64; 2]>> = (0..cj).map(|j| (0..ci).map(|i| at(i, j)).collect()).collect();
    if ci as usize != spec.cols {
        // Transpose so that rows of `idx` hold `cols` corners.
        idx = (0..ci as usize).map(|i| (0..cj as usize).map(|j| idx[j][i]).collect()).collect();
    }
    let cross = |m: &Vec<Vec<[f64; 2]>>| {
        let (o, u, v) = (m[0][0], m[0][1], m[1][0]);
        (u[0] - o[0]) * (v[1] - o[1]) - (u[1] - o[1]) * (v[0] - o[0])
    };
    if cross(&idx) < 0.0 {
        idx.reverse(); // mirror the rows: board z away from the camera
    }
    // Corner 0 is next to a black outer square.
    let (r, c) = (spec.rows - 1, spec.cols - 1);
    let outer = |p: [f64; 2], diag: [f64; 2]| g.sample(p[0] + 0.5 * (p[0] - diag[0]), p[1] + 0.5 * (p[1] - diag[1]));
    let first = outer(idx[0][0], idx[1][1]);
    let last = outer(idx[r][c], idx[r - 1][c - 1]);
    if first > last {
        idx.reverse();
        for row in &mut idx {
            row.reverse();
        }
    }
    let mut points: Vec<[f64; 2]> = idx.into_iter().flatten().collect();
    // Spacing: median distance to the next corner along x.
    let mut d: Vec<f64> = (0..points.len())
        .filter(|k| k % spec.cols + 1 < spec.cols)
        .map(|k| ((points[k + 1][0] - points[k][0]).powi(2) + (points[k + 1][1] - points[k][1]).powi(2)).sqrt())
        .collect();
    d.sort_by(f64::total_cmp);
    let spacing_px = d.get(d.len() / 2).copied().unwrap_or(0.0);
    let half = ((0.3 * spacing_px).round() as usize).clamp(2, 10);
    for p in &mut points {
        *p = refine(g, *p, half);
    }
    Corners { points, spacing_px }
}

/// Why the best lattice is not the board.
fn explain(
    raw: &Grey,
    best: &HashMap<Cell, usize>,
    pts: &[[f64; 2]],
    spec: &BoardSpec,
    lo: f64,
    hi: f64,
    candidates: usize,
) -> BoardError {
    if hi < 40.0 {
        return BoardError::TooDark { p99: hi };
    }
    if hi - lo < 25.0 {
        return BoardError::LowContrast { lo, hi };
    }
    let (_, _, ci, cj, _) = if best.is_empty() { (0, 0, 0, 0, true) } else { extent(best) };
    let (found_cols, found_rows) = (ci.max(0) as usize, cj.max(0) as usize);
    if best.len() >= 4 {
        let mut d: Vec<f64> = Vec::new();
        for (&(i, j), &k) in best {
            if let Some(&n) = best.get(&(i + 1, j)) {
                d.push(((pts[n][0] - pts[k][0]).powi(2) + (pts[n][1] - pts[k][1]).powi(2)).sqrt());
            }
        }
        d.sort_by(f64::total_cmp);
        let spacing = d.get(d.len() / 2).copied().unwrap_or(0.0);
        let margin = 1.3 * spacing;
        let touches = best.values().any(|&k| {
            let p = pts[k];
            p[0] < margin || p[1] < margin || p[0] > raw.w as f64 - 1.0 - margin || p[1] > raw.h as f64 - 1.0 - margin
        });
        let larger = best.len() > spec.len();
        if touches && !larger {
            return BoardError::CutOff { found_cols, found_rows, cols: spec.cols, rows: spec.rows };
        }
    }
    // Edge blur: a blurred step of contrast C has a peak gradient C / (sigma sqrt(2 pi)).
    let mut grads = Vec::with_capacity(raw.data.len());
    for y in 1..raw.h - 1 {
        for x in 1..raw.w - 1 {
            let gx = f64::from(raw.at(x + 1, y) - raw.at(x - 1, y)) * 0.5;
            let gy = f64::from(raw.at(x, y + 1) - raw.at(x, y - 1)) * 0.5;
            grads.push((gx * gx + gy * gy).sqrt());
        }
    }
    let g_hi = percentile(grads, 0.998).max(1e-9);
    let sigma_px = (hi - lo) / (g_hi * (std::f64::consts::TAU).sqrt());
    if sigma_px > 2.0 {
        return BoardError::Blurred { sigma_px };
    }
    let same_size =
        (found_cols, found_rows) == (spec.cols, spec.rows) || (found_cols, found_rows) == (spec.rows, spec.cols);
    let hint = if best.len() > spec.len() {
        ": is the --board size right?".to_string()
    } else if same_size {
        format!(
            ": {} of its corners not found (part of the board hidden, in glare or in deep shadow)",
            spec.len().saturating_sub(best.len())
        )
    } else if best.is_empty() {
        ": no checkerboard in view".to_string()
    } else {
        ": board partly hidden, glare, or the wrong --board size".to_string()
    };
    BoardError::WrongGrid {
        found: best.len(),
        found_cols,
        found_rows,
        cols: spec.cols,
        rows: spec.rows,
        candidates,
        hint,
    }
}

/// A lattice corner for diagnosis: its cell and position.
#[doc(hidden)]
pub type DebugCorner = ((i32, i32), [f64; 2]);

/// For diagnosis (`examples/board_debug.rs`): the X-junction candidates and the largest
/// lattice grown (cell, position).
#[doc(hidden)]
pub fn lattice_debug(view: &ImageView<'_>, _spec: &BoardSpec) -> (Vec<[f64; 2]>, Vec<DebugCorner>) {
    let prep = Prepared::new(view);
    let pts = &prep.pts;
    let search = prep.search();
    let mut best: Vec<DebugCorner> = Vec::new();
    let only: Option<[f64; 2]> = std::env::var("XSURF_BOARD_SEED").ok().and_then(|s| {
        let (x, y) = s.split_once(',')?;
        Some([x.parse().ok()?, y.parse().ok()?])
    });
    for seed in 0..pts.len() {
        if let Some(q) = only {
            if (0..pts.len()).any(|k| d2(pts[k], q) < d2(pts[seed], q)) {
                continue;
            }
        }
        if let Some(lat) = search.grow(pts, seed) {
            if lat.grid.len() > best.len() {
                best = lat.grid.iter().map(|(&c, &k)| (c, lat.pts[k])).collect();
            }
        }
    }
    (pts.clone(), best)
}
