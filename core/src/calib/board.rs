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
    #[error("board not found: the best corner grid is {found_cols}x{found_rows}, expected {cols}x{rows} inner corners ({candidates} corner candidates){hint}")]
    WrongGrid {
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

/// Whether the ring around `(x, y)` shows four alternating sectors with at least `min_contrast`.
fn is_x_junction(g: &Grey, x: f64, y: f64, min_contrast: f32) -> bool {
    let mut s = [0.0f32; RING_SAMPLES];
    for (k, v) in s.iter_mut().enumerate() {
        let a = std::f64::consts::TAU * k as f64 / RING_SAMPLES as f64;
        *v = g.sample(x + RING_PX * a.cos(), y + RING_PX * a.sin());
    }
    let (lo, hi) = s.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    if hi - lo < min_contrast {
        return false;
    }
    let mid = 0.5 * (lo + hi);
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

/// X-junction candidates (integer positions).
fn candidates(g: &Grey, min_contrast: f32) -> Vec<[f64; 2]> {
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
            if is_x_junction(g, x as f64, y as f64, min_contrast) {
                out.push([x as f64, y as f64]);
            }
        }
    }
    out
}

type Cell = (i32, i32);

/// Grows a lattice from candidate `seed`; returns cell -> candidate index.
fn grow(pts: &[[f64; 2]], seed: usize) -> HashMap<Cell, usize> {
    let d2 = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    let mut grid = HashMap::new();
    let mut near: Vec<usize> = (0..pts.len()).filter(|&k| k != seed).collect();
    near.sort_by(|&a, &b| d2(pts[a], pts[seed]).total_cmp(&d2(pts[b], pts[seed])));
    let Some(&a) = near.first() else { return grid };
    let va = [pts[a][0] - pts[seed][0], pts[a][1] - pts[seed][1]];
    let la = d2(pts[a], pts[seed]).sqrt();
    let b = near.iter().skip(1).take(8).copied().find(|&k| {
        let vb = [pts[k][0] - pts[seed][0], pts[k][1] - pts[seed][1]];
        let lb = d2(pts[k], pts[seed]).sqrt();
        (va[0] * vb[0] + va[1] * vb[1]).abs() / (la * lb) < 0.6 && lb < 2.0 * la
    });
    let Some(b) = b else { return grid };
    let mut used = vec![false; pts.len()];
    for (cell, k) in [((0, 0), seed), ((1, 0), a), ((0, 1), b)] {
        grid.insert(cell, k);
        used[k] = true;
    }
    let dirs: [Cell; 4] = [(1, 0), (-1, 0), (0, 1), (0, -1)];
    loop {
        let mut added = false;
        let cells: Vec<Cell> = grid.keys().copied().collect();
        for c in cells {
            for d in dirs {
                let t = (c.0 + d.0, c.1 + d.1);
                if grid.contains_key(&t) {
                    continue;
                }
                let p = |cell: Cell| grid.get(&cell).map(|&k| pts[k]);
                let Some(pc) = p(c) else { continue };
                let mut preds = Vec::new();
                if let Some(pb) = p((c.0 - d.0, c.1 - d.1)) {
                    // Perspective shortens (or stretches) successive steps by about the same ratio.
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
                    continue;
                }
                let n = preds.len() as f64;
                let pred = [preds.iter().map(|q| q[0]).sum::<f64>() / n, preds.iter().map(|q| q[1]).sum::<f64>() / n];
                let step2 = d2(pred, pc);
                let best =
                    (0..pts.len()).filter(|&k| !used[k]).min_by(|&x, &y| d2(pts[x], pred).total_cmp(&d2(pts[y], pred)));
                if let Some(k) = best {
                    if d2(pts[k], pred) < 0.35f64.powi(2) * step2 {
                        grid.insert(t, k);
                        used[k] = true;
                        added = true;
                    }
                }
            }
        }
        if !added {
            return grid;
        }
    }
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

/// Refines a corner: minimises `sum w (g . (p - q))^2` over the window (gradient `g` at `p`).
fn refine(g: &Grey, q0: [f64; 2], half: usize) -> [f64; 2] {
    let mut q = q0;
    let sigma = half as f64 * 0.6;
    for _ in 0..20 {
        let (cx, cy) = (q[0].round() as isize, q[1].round() as isize);
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let h = half as isize;
        for y in cy - h..=cy + h {
            for x in cx - h..=cx + h {
                if x < 1 || y < 1 || x as usize >= g.w - 1 || y as usize >= g.h - 1 {
                    continue;
                }
                let (xu, yu) = (x as usize, y as usize);
                let gx = f64::from(g.at(xu + 1, yu) - g.at(xu - 1, yu)) * 0.5;
                let gy = f64::from(g.at(xu, yu + 1) - g.at(xu, yu - 1)) * 0.5;
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
            return q;
        }
        let n = [(a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det];
        let moved = ((n[0] - q[0]).powi(2) + (n[1] - q[1]).powi(2)).sqrt();
        if ((n[0] - q0[0]).powi(2) + (n[1] - q0[1]).powi(2)).sqrt() > half as f64 {
            return q0; // ran away: keep the candidate
        }
        q = n;
        if moved < 0.002 {
            break;
        }
    }
    q
}

/// Finds the board in an image.
pub fn detect(view: &ImageView<'_>, spec: &BoardSpec) -> Result<Corners, BoardError> {
    if view.width() < 16 || view.height() < 16 {
        return Err(BoardError::TooSmall { width: view.width(), height: view.height() });
    }
    let raw = Grey::from_view(view);
    let (lo, hi) = (raw.percentile(0.01), raw.percentile(0.99));
    let fine = raw.blurred(0.8);
    let coarse = raw.blurred(1.5);
    let min_contrast = (0.25 * (hi - lo) as f32).max(6.0);
    let pts = candidates(&coarse, min_contrast);

    // Seeds: candidates nearest the centroid first.
    let n = pts.len().max(1) as f64;
    let centroid = [pts.iter().map(|p| p[0]).sum::<f64>() / n, pts.iter().map(|p| p[1]).sum::<f64>() / n];
    let mut order: Vec<usize> = (0..pts.len()).collect();
    order.sort_by(|&a, &b| {
        let da = (pts[a][0] - centroid[0]).powi(2) + (pts[a][1] - centroid[1]).powi(2);
        let db = (pts[b][0] - centroid[0]).powi(2) + (pts[b][1] - centroid[1]).powi(2);
        da.total_cmp(&db)
    });
    let mut best: HashMap<Cell, usize> = HashMap::new();
    for &seed in order.iter().take(12) {
        let grid = unshear(grow(&pts, seed));
        let (_, _, ci, cj, full) = extent(&grid);
        let fits = full
            && ((ci as usize, cj as usize) == (spec.cols, spec.rows)
                || (ci as usize, cj as usize) == (spec.rows, spec.cols));
        if fits {
            return Ok(label(&grid, &pts, spec, &fine));
        }
        if grid.len() > best.len() {
            best = grid;
        }
    }
    Err(explain(&raw, &best, &pts, spec, lo, hi))
}

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
        let larger = found_cols * found_rows > spec.len();
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
    let hint = if found_cols * found_rows > spec.len() {
        ": is the --board size right?".to_string()
    } else if best.is_empty() {
        ": no checkerboard in view".to_string()
    } else {
        ": board partly hidden, glare, or the wrong --board size".to_string()
    };
    BoardError::WrongGrid { found_cols, found_rows, cols: spec.cols, rows: spec.rows, candidates: pts.len(), hint }
}
