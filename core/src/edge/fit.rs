//! Sub-pixel centres of one located peak: centre of gravity, log-parabola (Caruana),
//! and the pixel-integrated Gaussian that narrow lines need.

use super::lanes::Sample;
use super::EdgeConfig;
use crate::geom::solve3;

/// Centre of gravity of the contiguous run around `m` above `threshold`, weights
/// `sample - threshold` (every sample of the run is above it, the peak included).
pub(super) fn center_of_gravity<S: Sample>(p: &[S], m: usize, threshold: f32, max_hw: usize) -> Option<f32> {
    let cut = S::cut(threshold);
    let (lo, hi) = S::run(p, m, max_hw, cut);
    let (sv, sxv) = S::weighted(&p[lo..=hi]);
    let k = (hi - lo + 1) as f64;
    let t = f64::from(threshold);
    let sw = sv - k * t;
    let swx = sxv - t * k * (k - 1.0) / 2.0;
    (sw > 0.0).then(|| lo as f32 + (swx / sw) as f32)
}

/// Gaussian fit: weighted least-squares parabola through ln(sample - background) around `m`,
/// weights (sample - background)^2 (Caruana's method), over samples above `peak_fraction`.
pub(super) fn gaussian_fit<S: Sample>(p: &[S], m: usize, bg: f32, strength: f32, cfg: &EdgeConfig) -> Option<f32> {
    let floor = cfg.peak_fraction.max(0.05) * strength;
    let max_hw = cfg.max_half_width_px as usize;
    let mut lo = m;
    while lo > 0 && m - lo < max_hw && p[lo - 1].f() - bg > floor {
        lo -= 1;
    }
    let mut hi = m;
    while hi + 1 < p.len() && hi - m < max_hw && p[hi + 1].f() - bg > floor {
        hi += 1;
    }
    if hi - lo < 2 {
        // Fewer than three samples: a three-point log-parabola needs its neighbours.
        lo = m.checked_sub(1)?;
        hi = (m + 1).min(p.len() - 1);
        if hi - lo < 2 {
            return None;
        }
    }
    // Normal equations of sum w (a + b x + c x^2 - ln y)^2, x relative to m.
    let mut s = [0.0f64; 5];
    let mut t = [0.0f64; 3];
    for i in lo..=hi {
        let y = f64::from((p[i].f() - bg).max(1e-3));
        let w = y * y;
        let x = i as f64 - m as f64;
        let ly = y.ln();
        let mut xp = 1.0;
        for sk in s.iter_mut() {
            *sk += w * xp;
            xp *= x;
        }
        t[0] += w * ly;
        t[1] += w * ly * x;
        t[2] += w * ly * x * x;
    }
    let a = [[s[0], s[1], s[2]], [s[1], s[2], s[3]], [s[2], s[3], s[4]]];
    let sol = solve3(a, t)?;
    let (b, c) = (sol[1], sol[2]);
    if c >= 0.0 {
        return None;
    }
    let off = (-b / (2.0 * c)).clamp(-(max_hw as f64), max_hw as f64);
    Some((m as f64 + off) as f32)
}

/// The standard normal quantile (probit), Acklam's rational approximation (relative error
/// under 1.2e-9 over (0, 1)), in `f64`: in `f32` the central polynomials cancel to 1e-4.
pub(super) fn probit(q: f32) -> f32 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.38357751867269e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] =
        [-5.447609879822406e1, 1.615858368580409e2, -1.556989798598866e2, 6.680131188771972e1, -1.328068155288572e1];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [7.784695709041462e-3, 3.224671290700398e-1, 2.445134137142996, 3.754408661907416];
    const LOW: f64 = 0.02425;
    let q = f64::from(q);
    let tail = |q: f64| {
        let t = (-2.0 * q.ln()).sqrt();
        (((((C[0] * t + C[1]) * t + C[2]) * t + C[3]) * t + C[4]) * t + C[5])
            / ((((D[0] * t + D[1]) * t + D[2]) * t + D[3]) * t + 1.0)
    };
    let z = if q < LOW {
        tail(q)
    } else if q > 1.0 - LOW {
        -tail(1.0 - q)
    } else {
        let r = q - 0.5;
        let s = r * r;
        (((((A[0] * s + A[1]) * s + A[2]) * s + A[3]) * s + A[4]) * s + A[5]) * r
            / (((((B[0] * s + B[1]) * s + B[2]) * s + B[3]) * s + B[4]) * s + 1.0)
    };
    z as f32
}

/// Cumulative fractions outside this range carry too little signal to place an edge.
const EDGE_FRACTION_MIN: f32 = 0.005;

/// Centre of a line that box pixels sample: sample `i` holds `A (Phi((i + 1/2 - c) / s) -
/// Phi((i - 1/2 - c) / s))` above the background, the Gaussian integrated over the pixel.
///
/// The fraction of the line's light left of a pixel edge `e` is `Phi((e - c) / s)`, so its
/// probit `z(e) = (e - c) / s` is a straight line in `e` whose zero is the centre. The two edges
/// of the peak sample `m`, one pixel apart, give it in closed form: `s = 1 / (z(m + 1/2) -
/// z(m - 1/2))` and `c = m - 1/2 - s z(m - 1/2)`, with the fractions summed over the run
/// `lo..=hi`. Unlike a centre of gravity over a threshold, or any three-point interpolation, it
/// does not lock to pixel centres when the line is narrower than a pixel or two. The background
/// is a straight line between the two flanks' means (`bg_left` at `x_left`, `bg_right` at
/// `x_right`).
///
/// A line much narrower than a pixel may leave light on one neighbour only: one edge, whose
/// probit `z` fixes `e - c = z s` but not `c` and `s` apart. That case is returned as
/// [`Fit::OneEdge`], for the caller to resolve with the width of the line's other samples.
pub(super) fn integrated_gaussian<S: Sample>(
    p: &[S],
    (lo, m, hi): (usize, usize, usize),
    (x_left, bg_left): (f32, f32),
    (x_right, bg_right): (f32, f32),
) -> Option<Fit> {
    if !(lo < m && m < hi && hi < p.len()) {
        return None;
    }
    let slope = if x_right > x_left { (bg_right - bg_left) / (x_right - x_left) } else { 0.0 };
    let y = |i: usize| (p[i].f() - (bg_left + slope * (i as f32 - x_left))).max(0.0);
    let left: f32 = (lo..m).map(y).sum();
    let right: f32 = (m + 1..=hi).map(y).sum();
    let total = left + y(m) + right;
    if !(total > 0.0) {
        return None;
    }
    let usable = |f: f32| (EDGE_FRACTION_MIN..=1.0 - EDGE_FRACTION_MIN).contains(&f);
    let (f1, f2) = (left / total, 1.0 - right / total);
    let (e1, e2) = (m as f32 - 0.5, m as f32 + 0.5);
    match (usable(f1), usable(f2)) {
        (true, true) => {
            let (z1, z2) = (probit(f1), probit(f2));
            let b = z2 - z1;
            (b > 0.0).then(|| Fit::Centre { centre: e1 - z1 / b, sigma: 1.0 / b })
        }
        (true, false) => Some(Fit::OneEdge { edge: e1, z: probit(f1) }),
        (false, true) => Some(Fit::OneEdge { edge: e2, z: probit(f2) }),
        (false, false) => None,
    }
}

/// The outcome of [`integrated_gaussian`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Fit {
    /// Centre and standard deviation of the line, pixels.
    Centre { centre: f32, sigma: f32 },
    /// One usable edge at `edge`: the centre is `edge - z * sigma` for the line's sigma.
    OneEdge { edge: f32, z: f32 },
}

/// Gauss-Newton iterations of [`least_squares_gaussian`].
const LS_ITERATIONS: usize = 8;

/// Least-squares fit of `b + a exp(-(x - c)^2 / (2 s^2))` to `p[lo..=hi]` (Gauss-Newton from
/// `init = [b, a, c, s]`), the model a reference fit would use. Saturated samples (at or above
/// `saturation`) are censored: they only say the line reaches the top of the range, so they are
/// left out of the residuals and a clipped top cannot bias the centre. Returns the centre, or
/// `None` when the fit fails or leaves `lo..=hi`.
pub(super) fn least_squares_gaussian<S: Sample>(
    p: &[S],
    lo: usize,
    hi: usize,
    init: [f64; 4],
    saturation: f32,
) -> Option<f32> {
    let mut q = init;
    let free = (lo..=hi).filter(|&i| p[i].f() < saturation).count();
    if hi >= p.len() || free < 5 || !(q[3] > 0.0) {
        return None;
    }
    for _ in 0..LS_ITERATIONS {
        let [b, a, c, s] = q;
        let mut n = [[0.0f64; 4]; 4];
        let mut g = [0.0f64; 4];
        for i in lo..=hi {
            let y = f64::from(p[i].f());
            if y >= f64::from(saturation) {
                continue;
            }
            let x = i as f64;
            let d = (x - c) / s;
            let e = (-0.5 * d * d).exp();
            let r = y - (b + a * e);
            let j = [1.0, e, a * e * d / s, a * e * d * d / s];
            for (k, jk) in j.iter().enumerate() {
                g[k] += jk * r;
                for (l, jl) in j.iter().enumerate() {
                    n[k][l] += jk * jl;
                }
            }
        }
        let step = solve(n, g)?;
        for (qk, dk) in q.iter_mut().zip(step) {
            *qk += dk;
        }
        if !(q[3] > 0.05 && q[1] > 0.0) {
            return None;
        }
        if step[2].abs() < 1e-4 {
            break;
        }
    }
    let c = q[2];
    (c >= lo as f64 && c <= hi as f64).then_some(c as f32)
}

/// Solves the system `a x = b` by Gaussian elimination with partial pivoting.
fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let piv = (col..N).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if !(a[piv][col].abs() > 1e-12) {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for row in col + 1..N {
            let f = a[row][col] / a[col][col];
            for k in col..N {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let s: f64 = (row + 1..N).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::probit;

    #[test]
    fn probit_matches_the_normal_quantiles() {
        for (q, z) in [(0.5, 0.0), (0.975, 1.959_964), (0.8, 0.841_621_2), (0.01, -2.326_348), (0.001, -3.090_232)] {
            assert!((probit(q) - z).abs() < 2e-5, "probit({q}) = {} (expected {z})", probit(q));
        }
    }
}
