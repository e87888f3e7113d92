//! Sub-pixel laser-line detection, one sample per image row (or column).
//!
//! Every method first finds the strongest peak of the row profile (the brightest sample, which
//! also picks the strongest of several lines), estimates the local background and noise from
//! two flanks beside it, and accepts the peak only if it stands above the background by more than
//! `max(min_strength, noise_factor * noise)`: the study's "floating threshold". The centre is then
//! refined by the chosen method. A saturated peak (a plateau at the encoding's maximum) is
//! always located by its centre of gravity, because a fit to a clipped top is biased.
//!
//! [`Method::Gradient`] is the reference study's method (a five-pixel gradient above a fixed
//! threshold, integer pixels), kept so that the improvement can be measured.

use crate::geom::solve3;
use crate::image::{Encoding, ImageError, ImageView};
use serde::{Deserialize, Serialize};
use wide::u8x16;

/// How the line centre is located within a row.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The study's method: first five-pixel rise above `gradient_threshold`, integer pixels.
    Gradient,
    /// Centre of gravity of the background-subtracted samples above a fraction of the peak.
    #[default]
    CenterOfGravity,
    /// Weighted least-squares parabola through the logarithm of the peak (a Gaussian fit).
    Gaussian,
    /// Parabola through the peak sample and its two neighbours.
    Parabolic,
}

impl Method {
    /// Parses the parameter value (`gradient`, `center_of_gravity`/`cog`, `gaussian`, `parabolic`).
    pub fn parse(s: &str) -> Option<Method> {
        match s {
            "gradient" => Some(Method::Gradient),
            "center_of_gravity" | "cog" | "centre_of_gravity" => Some(Method::CenterOfGravity),
            "gaussian" => Some(Method::Gaussian),
            "parabolic" => Some(Method::Parabolic),
            _ => None,
        }
    }
    /// The parameter value naming this method.
    pub fn name(self) -> &'static str {
        match self {
            Method::Gradient => "gradient",
            Method::CenterOfGravity => "center_of_gravity",
            Method::Gaussian => "gaussian",
            Method::Parabolic => "parabolic",
        }
    }
}

/// Which way the line runs in the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Orientation {
    /// The line runs top to bottom: one sample per image row (`LaserLine.ORIENTATION_VERTICAL`).
    #[default]
    Vertical,
    /// The line runs left to right: one sample per image column.
    Horizontal,
}

impl Orientation {
    /// Parses `vertical` / `horizontal`.
    pub fn parse(s: &str) -> Option<Orientation> {
        match s {
            "vertical" => Some(Orientation::Vertical),
            "horizontal" => Some(Orientation::Horizontal),
            _ => None,
        }
    }
}

/// Which signal of a colour image carries the laser.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Channel {
    /// The red channel.
    #[default]
    Red,
    /// Luma (0.299 R + 0.587 G + 0.114 B).
    Luma,
    /// Red minus the mean of green and blue, clamped at 0: suppresses white surfaces.
    RedMinusOthers,
}

impl Channel {
    /// Parses `red`, `luma`, `red_minus_others`.
    pub fn parse(s: &str) -> Option<Channel> {
        match s {
            "red" => Some(Channel::Red),
            "luma" => Some(Channel::Luma),
            "red_minus_others" => Some(Channel::RedMinusOthers),
            _ => None,
        }
    }
}

/// A rectangle of the image to search (pixels); zero width or height means "to the edge".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Roi {
    /// First column.
    pub x_offset: u32,
    /// First row.
    pub y_offset: u32,
    /// Columns (0: to the right edge).
    pub width: u32,
    /// Rows (0: to the bottom edge).
    pub height: u32,
}

/// Configuration of the detector. Every field is an `edge_detector` parameter of the same name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct EdgeConfig {
    /// Centre-finding method.
    pub method: Method,
    /// Line orientation in the image.
    pub line_orientation: Orientation,
    /// Signal used for colour images.
    pub channel: Channel,
    /// Region searched.
    pub roi: Roi,
    /// Smallest accepted peak height above the local background, grey levels (8-bit scale;
    /// scaled by 257 for mono16).
    pub min_strength: f32,
    /// The peak must also exceed this many times the local noise (standard deviation).
    pub noise_factor: f32,
    /// Samples above `background + peak_fraction * strength` take part in the centre estimate.
    pub peak_fraction: f32,
    /// Largest half-width searched around the peak, pixels.
    pub max_half_width_px: u32,
    /// Length of each background flank, pixels.
    pub flank_px: u32,
    /// Peaks wider than this (full width at half maximum, pixels) are rejected as smeared
    /// (grazing incidence or a depth edge).
    pub max_width_px: f32,
    /// For `gradient`: the five-pixel rise that marks the line, grey levels.
    pub gradient_threshold: f32,
    /// Colour is sampled this far beside the line centre (the study's t +/- d), pixels.
    pub color_offset_px: f32,
}

impl Default for EdgeConfig {
    fn default() -> Self {
        Self {
            method: Method::CenterOfGravity,
            line_orientation: Orientation::Vertical,
            channel: Channel::Red,
            roi: Roi::default(),
            min_strength: 20.0,
            noise_factor: 6.0,
            peak_fraction: 0.15,
            max_half_width_px: 12,
            flank_px: 10,
            max_width_px: 14.0,
            gradient_threshold: 40.0,
            color_offset_px: 8.0,
        }
    }
}

/// Why a configuration or an image was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EdgeError {
    /// The image itself is malformed.
    #[error(transparent)]
    Image(#[from] ImageError),
    /// The region of interest lies outside the image.
    #[error("roi {roi:?} lies outside the {width}x{height} image")]
    RoiOutside {
        /// The region.
        roi: Roi,
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
    },
    /// A configuration value is out of range.
    #[error("invalid edge_detector parameter {name}: {reason}")]
    InvalidConfig {
        /// Parameter name.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
}

impl EdgeConfig {
    /// Checks every value; the same check refuses a bad run-time parameter set.
    pub fn validate(&self) -> Result<(), EdgeError> {
        let bad = |name, reason: &str| Err(EdgeError::InvalidConfig { name, reason: reason.to_string() });
        if !(self.min_strength.is_finite() && self.min_strength >= 0.0) {
            return bad("min_strength", "must be a finite value >= 0");
        }
        if !(self.noise_factor.is_finite() && self.noise_factor >= 0.0) {
            return bad("noise_factor", "must be a finite value >= 0");
        }
        if !(self.peak_fraction >= 0.0 && self.peak_fraction < 1.0) {
            return bad("peak_fraction", "must be in [0, 1)");
        }
        if self.max_half_width_px == 0 || self.max_half_width_px > 256 {
            return bad("max_half_width_px", "must be in 1..=256");
        }
        if self.flank_px == 0 || self.flank_px > 256 {
            return bad("flank_px", "must be in 1..=256");
        }
        if !(self.max_width_px > 0.0) {
            return bad("max_width_px", "must be > 0");
        }
        if !(self.gradient_threshold > 0.0) {
            return bad("gradient_threshold", "must be > 0");
        }
        if !(self.color_offset_px.is_finite() && self.color_offset_px >= 0.0) {
            return bad("color_offset_px", "must be a finite value >= 0");
        }
        Ok(())
    }
}

/// The laser line found in one image: the algorithm side of `xsurf_msgs/LaserLine`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LaserLine {
    /// Orientation the samples follow.
    pub orientation: Orientation,
    /// Source image width.
    pub image_width: u32,
    /// Source image height.
    pub image_height: u32,
    /// Sub-pixel column of the line centre per sample, NaN where none.
    pub u: Vec<f32>,
    /// Sub-pixel row of the line centre per sample, NaN where none.
    pub v: Vec<f32>,
    /// Peak height above the local background (grey levels), 0 where none.
    pub strength: Vec<f32>,
    /// Full width at half maximum (pixels), 0 where none.
    pub width: Vec<f32>,
    /// Surface colour beside the line, 3 bytes a sample; empty for grey images.
    pub rgb: Vec<u8>,
}

impl LaserLine {
    /// Number of samples (rows for vertical lines, columns for horizontal).
    pub fn len(&self) -> usize {
        self.u.len()
    }
    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }
    /// Number of samples where a line was found.
    pub fn found(&self) -> usize {
        self.u.iter().filter(|u| u.is_finite()).count()
    }
    fn reset(&mut self, orientation: Orientation, w: u32, h: u32, n: usize, color: bool) {
        self.orientation = orientation;
        self.image_width = w;
        self.image_height = h;
        for buf in [&mut self.u, &mut self.v] {
            buf.clear();
            buf.resize(n, f32::NAN);
        }
        for buf in [&mut self.strength, &mut self.width] {
            buf.clear();
            buf.resize(n, 0.0);
        }
        self.rgb.clear();
        if color {
            self.rgb.resize(3 * n, 0);
        }
    }
}

/// A sample type of a row profile.
trait Sample: Copy + PartialOrd {
    /// A level in the sample's own terms, so that walks compare without converting.
    type Cut: Copy;
    fn f(self) -> f32;
    /// The cut that [`Sample::above`] compares with: `s.above(cut(l))` iff `s.f() > l`.
    fn cut(level: f32) -> Self::Cut;
    fn above(self, cut: Self::Cut) -> bool;
    /// Sum and sum of squares of `p[start..end]`.
    fn moments(p: &[Self], start: usize, end: usize) -> (f32, f32);
    /// Sum of a run and its first moment about the run's start: (sum v, sum i v).
    fn weighted(s: &[Self]) -> (f64, f64);
    /// Index of the first maximum of `p` (`None` if empty).
    fn argmax(p: &[Self]) -> Option<usize>;
    /// The run of samples above `cut` on either side of `m`, at most `reach` samples each way
    /// and inside `p`: `(first, last)`. `p[m]` itself is not compared.
    #[inline(always)]
    fn run(p: &[Self], m: usize, reach: usize, cut: Self::Cut) -> (usize, usize) {
        (walk_left(p, m, m.saturating_sub(reach), cut), walk_right(p, m, m + reach, cut))
    }
}

/// Lane masks for a flank loaded as 16 bytes: `FIRST[16 - k..][..16]` keeps the first `k` lanes,
/// `LAST[k..][..16]` keeps the last `k`.
const FIRST: [u8; 32] = {
    let mut m = [0u8; 32];
    let mut i = 0;
    while i < 16 {
        m[i] = 0xFF;
        i += 1;
    }
    m
};
const LAST: [u8; 32] = {
    let mut m = [0u8; 32];
    let mut i = 16;
    while i < 32 {
        m[i] = 0xFF;
        i += 1;
    }
    m
};

/// Sum and sum of squares of 16 bytes under a mask: vectorises (widen, multiply-add).
#[inline(always)]
fn masked_moments16(w: &[u8], mask: &[u8]) -> Option<(f32, f32)> {
    let (w, mask): (&[u8; 16], &[u8; 16]) = (w.try_into().ok()?, mask.try_into().ok()?);
    let a: u16 = w.iter().zip(mask).map(|(&v, &k)| u16::from(v & k)).sum();
    let b: i32 = w.iter().zip(mask).map(|(&v, &k)| i32::from(i16::from(v & k)) * i32::from(i16::from(v & k))).sum();
    Some((f32::from(a), b as f32))
}

impl Sample for u8 {
    type Cut = i32;
    #[inline(always)]
    fn f(self) -> f32 {
        f32::from(self)
    }
    /// For an integer sample, `s > l` iff `s > floor(l)`. The shift by one makes the
    /// truncating cast a floor; the clamp keeps it in range (NaN gives -1: every sample above).
    #[inline(always)]
    fn cut(level: f32) -> i32 {
        (level + 1.0).clamp(0.0, 256.0) as i32 - 1
    }
    #[inline(always)]
    fn above(self, cut: i32) -> bool {
        i32::from(self) > cut
    }
    /// Exact integer sums (a flank of at most 256 samples cannot overflow u32). A flank of up
    /// to 16 samples is read as one 16-byte block with the other lanes masked off.
    #[inline(always)]
    fn moments(p: &[u8], start: usize, end: usize) -> (f32, f32) {
        let k = end - start;
        if k <= 16 {
            let fast = if start + 16 <= p.len() {
                masked_moments16(&p[start..start + 16], &FIRST[16 - k..32 - k])
            } else if end >= 16 {
                masked_moments16(&p[end - 16..end], &LAST[k..k + 16])
            } else {
                None
            };
            if let Some(m) = fast {
                return m;
            }
        }
        let (mut a, mut b) = (0u32, 0u32);
        for &v in &p[start..end] {
            let x = u32::from(v);
            a += x;
            b += x * x;
        }
        (a as f32, b as f32)
    }
    #[inline(always)]
    fn weighted(s: &[u8]) -> (f64, f64) {
        let (mut a, mut b) = (0u32, 0u32);
        for (i, &v) in s.iter().enumerate() {
            a += u32::from(v);
            b += i as u32 * u32::from(v);
        }
        (f64::from(a), f64::from(b))
    }
    /// The maximum 16 lanes at a time, then the first 32 bytes that hold it (compare, move mask).
    #[inline]
    fn argmax(p: &[u8]) -> Option<usize> {
        let mut blocks = p.chunks_exact(16);
        let lanes = (&mut blocks).filter_map(block).fold(u8x16::ZERO, |m, b| m.max(u8x16::new(b)));
        let max = lanes.to_array().into_iter().chain(blocks.remainder().iter().copied()).fold(0, u8::max);
        let key = u8x16::splat(max);
        let hits = |b: &[u8]| block(b).map_or(0, |b| u8x16::new(b).simd_eq(key).to_bitmask());
        let mut pairs = p.chunks_exact(32);
        for (k, b) in (&mut pairs).enumerate() {
            let (lo, hi) = b.split_at(16);
            let found = hits(lo) | hits(hi) << 16;
            if found != 0 {
                return Some(32 * k + found.trailing_zeros() as usize);
            }
        }
        // Under 32 bytes left.
        let tail = pairs.remainder();
        tail.iter().position(|&v| v == max).map(|i| p.len() - tail.len() + i)
    }
    /// Inside the row, one 32-byte window around `m`: a lane mask of the samples above the
    /// cut, whose ones next to `m` on each side are the run.
    #[inline(always)]
    fn run(p: &[u8], m: usize, reach: usize, cut: i32) -> (usize, usize) {
        let window = m.checked_sub(16).and_then(|a| p.get(a..m + 16)).filter(|_| reach < 16);
        let halves = window.and_then(|w| Some((block(&w[..16])?, block(&w[16..])?)));
        let (Some((a, b)), Some(floor)) = (halves, above_floor(cut)) else {
            return (walk_left(p, m, m.saturating_sub(reach), cut), walk_right(p, m, m + reach, cut));
        };
        // Bit i: p[m - 16 + i] is above the cut; bit 16 is p[m].
        let mask = above16(a, floor) | above16(b, floor) << 16;
        let left = ((mask as u16).leading_ones() as usize).min(reach);
        let right = ((!(mask >> 17)).trailing_zeros() as usize).min(reach);
        (m - left, m + right)
    }
}

/// Index of the first maximum of a row of bytes (`None` if empty): where every sub-pixel method
/// starts, the strongest line's peak. Vectorised (16 lanes: SSE2, NEON or scalar).
pub fn argmax_u8(row: &[u8]) -> Option<usize> {
    u8::argmax(row)
}

/// A 16-byte block of a slice of exactly 16.
#[inline(always)]
fn block(b: &[u8]) -> Option<[u8; 16]> {
    b.try_into().ok()
}

/// The lane value that a byte above the integer cut reaches: `cut + 1`, or `None` when the cut
/// is below every byte (`cut < 0`) or above every byte (`cut >= 255`).
#[inline(always)]
fn above_floor(cut: i32) -> Option<u8x16> {
    u8::try_from(cut + 1).ok().filter(|&f| f > 0).map(u8x16::splat)
}

/// Bit `i` is set iff `w[i] >= floor` (bits 16 and up are clear).
#[inline(always)]
fn above16(w: [u8; 16], floor: u8x16) -> u32 {
    let v = u8x16::new(w);
    v.max(floor).simd_eq(v).to_bitmask()
}
impl Sample for f32 {
    type Cut = f32;
    #[inline(always)]
    fn f(self) -> f32 {
        self
    }
    #[inline(always)]
    fn cut(level: f32) -> f32 {
        level
    }
    #[inline(always)]
    fn above(self, cut: f32) -> bool {
        self > cut
    }
    #[inline(always)]
    fn moments(p: &[f32], start: usize, end: usize) -> (f32, f32) {
        let (mut a, mut b) = (0.0f32, 0.0f32);
        for &x in &p[start..end] {
            a += x;
            b += x * x;
        }
        (a, b)
    }
    #[inline(always)]
    fn weighted(s: &[f32]) -> (f64, f64) {
        let (mut a, mut b) = (0.0f64, 0.0f64);
        for (i, &v) in s.iter().enumerate() {
            a += f64::from(v);
            b += i as f64 * f64::from(v);
        }
        (a, b)
    }
    fn argmax(p: &[f32]) -> Option<usize> {
        let mut best: Option<(usize, f32)> = None;
        for (i, &v) in p.iter().enumerate() {
            if best.is_none_or(|(_, b)| v > b) {
                best = Some((i, v));
            }
        }
        best.map(|(i, _)| i)
    }
}

/// The first of [`Sample::run`], one sample at a time: the lowest `l` in `min..=from` with
/// every sample of `p[l..from]` above `cut`.
#[inline(always)]
fn walk_left<S: Sample>(p: &[S], from: usize, min: usize, cut: S::Cut) -> usize {
    from - p[min..from].iter().rev().take_while(|v| v.above(cut)).count()
}

/// The last of [`Sample::run`], one sample at a time: the highest `r` in `from..=max` (and
/// inside `p`) with every sample of `p[from + 1..=r]` above `cut`.
#[inline(always)]
fn walk_right<S: Sample>(p: &[S], from: usize, max: usize, cut: S::Cut) -> usize {
    let end = (max + 1).min(p.len());
    from + p[from + 1..end].iter().take_while(|v| v.above(cut)).count()
}

/// One located peak in a profile.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Peak {
    pos: f32,
    strength: f32,
    width: f32,
    saturated: bool,
}

/// Background level and noise around a peak at `m`, from flanks outside `±gap`: the pooled mean,
/// and the standard deviation of each flank about its own mean (so a shading slope between the
/// two flanks is not counted as noise).
#[inline]
fn background<S: Sample>(p: &[S], m: usize, gap: usize, flank: usize) -> (f32, f32) {
    let (mut sum, mut n, mut ss) = (0.0f32, 0usize, 0.0f32);
    if m > gap {
        let end = m - gap;
        let start = end.saturating_sub(flank);
        let (a, b) = S::moments(p, start, end);
        let k = end - start;
        if k > 0 {
            sum += a;
            n += k;
            ss += b - a * a / k as f32;
        }
    }
    let start = m + gap + 1;
    if start < p.len() {
        let end = (start + flank).min(p.len());
        let (a, b) = S::moments(p, start, end);
        let k = end - start;
        sum += a;
        n += k;
        ss += b - a * a / k as f32;
    }
    if n == 0 {
        return (0.0, 0.0);
    }
    (sum / n as f32, (ss.max(0.0) / n as f32).sqrt())
}

/// Linear-interpolated position where the profile crosses `level` between `i` (below) and `j`.
fn crossing<S: Sample>(p: &[S], i: usize, j: usize, level: f32) -> f32 {
    let (a, b) = (p[i].f(), p[j].f());
    let t = if (b - a).abs() > f32::EPSILON { (level - a) / (b - a) } else { 0.5 };
    i as f32 + (j as f32 - i as f32) * t.clamp(0.0, 1.0)
}

/// The samples' scale relative to 8-bit grey levels.
fn level_scale(encoding: Encoding) -> f32 {
    if encoding == Encoding::Mono16 {
        257.0
    } else {
        1.0
    }
}

/// Locates the strongest line in one profile with a sub-pixel method.
fn find_peak<S: Sample>(p: &[S], m: usize, cfg: &EdgeConfig, scale: f32, saturation: f32) -> Option<Peak> {
    let n = p.len();
    let peak = p[m].f();
    let max_hw = cfg.max_half_width_px as usize;
    // First pass: the run above half of the peak over the row minimum nearby gives the gap
    // that keeps the background flanks off the line.
    // Wide enough that the flanks clear most lines on the first try.
    let gap0 = max_hw.min(6);
    let (bg0, noise0) = background(p, m, gap0, cfg.flank_px as usize);
    let half0 = S::cut(bg0 + 0.5 * (peak - bg0));
    // One sample further than a line may reach, so that a line too wide shows as such.
    let (lo, hi) = S::run(p, m, max_hw + 1, half0);
    let gap = (2 * (m - lo).max(hi - m) + 2).min(max_hw);
    // A narrower line keeps the first flanks (they are clear of it, only a little further out).
    let gap = gap.max(gap0);
    let (bg, noise) = if gap == gap0 { (bg0, noise0) } else { background(p, m, gap, cfg.flank_px as usize) };
    let strength = peak - bg;
    if strength < (cfg.min_strength * scale).max(cfg.noise_factor * noise) || strength <= 0.0 {
        return None;
    }
    // Full width at half maximum.
    let half = bg + 0.5 * strength;
    // With the first flanks, `half` is the first pass's level and its run is already known.
    let (l, r) = if gap == gap0 { (lo, hi) } else { S::run(p, m, max_hw + 1, S::cut(half)) };
    let left = if l > 0 { crossing(p, l - 1, l, half) } else { l as f32 - 0.5 };
    let right = if r + 1 < n { crossing(p, r + 1, r, half) } else { r as f32 + 0.5 };
    let width = right - left;
    if width > cfg.max_width_px || m - l > max_hw || r - m > max_hw {
        return None;
    }
    let saturated = peak >= saturation;
    let pos = match cfg.method {
        Method::Parabolic if !saturated && m > 0 && m + 1 < n => {
            let (a, b, c) = (p[m - 1].f(), peak, p[m + 1].f());
            let den = a - 2.0 * b + c;
            if den < 0.0 {
                m as f32 + (0.5 * (a - c) / den).clamp(-0.5, 0.5)
            } else {
                m as f32
            }
        }
        Method::Gaussian if !saturated => gaussian_fit(p, m, bg, strength, cfg)?,
        _ => center_of_gravity(p, m, bg + cfg.peak_fraction * strength, max_hw)?,
    };
    Some(Peak { pos, strength, width, saturated })
}

/// Centre of gravity of the contiguous run around `m` above `threshold`, weights
/// `sample - threshold` (every sample of the run is above it, the peak included).
fn center_of_gravity<S: Sample>(p: &[S], m: usize, threshold: f32, max_hw: usize) -> Option<f32> {
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
fn gaussian_fit<S: Sample>(p: &[S], m: usize, bg: f32, strength: f32, cfg: &EdgeConfig) -> Option<f32> {
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

/// The study's method: first rise over five samples above the threshold; integer position.
fn gradient_edge<S: Sample>(p: &[S], threshold: f32) -> Option<Peak> {
    (0..p.len().saturating_sub(4))
        .map(|i| (i, p[i + 4].f() - p[i].f()))
        .find(|&(_, g)| g > threshold)
        .map(|(i, g)| Peak { pos: (i + 2) as f32, strength: g, width: 0.0, saturated: false })
}

/// Counters of one detection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DetectStats {
    /// Samples searched.
    pub searched: u32,
    /// Samples with a line.
    pub found: u32,
    /// Samples whose peak was saturated.
    pub saturated: u32,
}

/// A reusable detector: owns its scratch buffers so that the hot path does not allocate.
#[derive(Debug, Default, Clone)]
pub struct EdgeDetector {
    config: EdgeConfig,
    profile: Vec<f32>,
}

impl EdgeDetector {
    /// A detector with a validated configuration.
    pub fn new(config: EdgeConfig) -> Result<Self, EdgeError> {
        config.validate()?;
        Ok(Self { config, profile: Vec::new() })
    }

    /// The configuration in use.
    pub fn config(&self) -> &EdgeConfig {
        &self.config
    }

    /// Finds the line in `image`, writing one sample per row (or column) into `out`.
    pub fn detect(&mut self, image: &ImageView<'_>, out: &mut LaserLine) -> Result<DetectStats, EdgeError> {
        let cfg = &self.config;
        let (w, h) = (image.width(), image.height());
        let roi = cfg.roi;
        if roi.x_offset >= w || roi.y_offset >= h {
            return Err(EdgeError::RoiOutside { roi, width: w, height: h });
        }
        let x1 = if roi.width == 0 { w } else { (roi.x_offset + roi.width).min(w) };
        let y1 = if roi.height == 0 { h } else { (roi.y_offset + roi.height).min(h) };
        let (x0, y0) = (roi.x_offset, roi.y_offset);
        let enc = image.encoding();
        let vertical = cfg.line_orientation == Orientation::Vertical;
        let samples = if vertical { h } else { w };
        out.reset(cfg.line_orientation, w, h, samples as usize, enc.is_color());
        let scale = level_scale(enc);
        let saturation = enc.max_value();
        let mut stats = DetectStats::default();
        let (outer, inner) = if vertical { (y0..y1, x0..x1) } else { (x0..x1, y0..y1) };
        for s in outer {
            stats.searched += 1;
            let peak = if vertical && enc == Encoding::Mono8 {
                let row = &image.row(s)[inner.start as usize..inner.end as usize];
                locate(row, u8::argmax(row), cfg, scale, saturation)
            } else {
                fill_profile(image, s, inner.clone(), vertical, cfg.channel, &mut self.profile);
                let p = &self.profile[..];
                locate(p, f32::argmax(p), cfg, scale, saturation)
            };
            let Some(peak) = peak else { continue };
            let pos = inner.start as f32 + peak.pos;
            let (u, v) = if vertical { (pos, s as f32) } else { (s as f32, pos) };
            let i = s as usize;
            out.u[i] = u;
            out.v[i] = v;
            out.strength[i] = peak.strength / scale;
            out.width[i] = peak.width;
            stats.found += 1;
            stats.saturated += u32::from(peak.saturated);
            if enc.is_color() {
                let c = side_colour(image, u, v, vertical, cfg.color_offset_px);
                out.rgb[3 * i..3 * i + 3].copy_from_slice(&c);
            }
        }
        Ok(stats)
    }
}

fn locate<S: Sample>(p: &[S], m: Option<usize>, cfg: &EdgeConfig, scale: f32, saturation: f32) -> Option<Peak> {
    if cfg.method == Method::Gradient {
        return gradient_edge(p, cfg.gradient_threshold * scale);
    }
    find_peak(p, m?, cfg, scale, saturation)
}

/// Copies one row or column of the chosen signal into `buf` as f32.
fn fill_profile(
    image: &ImageView<'_>,
    s: u32,
    inner: std::ops::Range<u32>,
    vertical: bool,
    channel: Channel,
    buf: &mut Vec<f32>,
) {
    buf.clear();
    let enc = image.encoding();
    let big_endian = image.is_big_endian();
    let pixel = |row: &[u8], x: usize| -> f32 {
        match enc {
            Encoding::Mono8 => f32::from(row[x]),
            Encoding::Mono16 => {
                let b = [row[2 * x], row[2 * x + 1]];
                f32::from(if big_endian { u16::from_be_bytes(b) } else { u16::from_le_bytes(b) })
            }
            Encoding::Rgb8 | Encoding::Bgr8 => {
                let px = &row[3 * x..3 * x + 3];
                let (r, g, b) = if enc == Encoding::Rgb8 { (px[0], px[1], px[2]) } else { (px[2], px[1], px[0]) };
                let (r, g, b) = (f32::from(r), f32::from(g), f32::from(b));
                match channel {
                    Channel::Red => r,
                    Channel::Luma => crate::image::luma(r, g, b),
                    Channel::RedMinusOthers => (r - 0.5 * (g + b)).max(0.0),
                }
            }
        }
    };
    if vertical {
        let row = image.row(s);
        let (x0, x1) = (inner.start as usize, inner.end as usize);
        match (enc, channel) {
            // Colour rows, the common cases: one pass over 3-byte pixels, no per-pixel dispatch.
            (Encoding::Rgb8 | Encoding::Bgr8, Channel::Red) => {
                let r = if enc == Encoding::Rgb8 { 0 } else { 2 };
                buf.extend(row[3 * x0..3 * x1].chunks_exact(3).map(|p| f32::from(p[r])));
            }
            (Encoding::Rgb8 | Encoding::Bgr8, Channel::RedMinusOthers) => {
                let (r, b) = if enc == Encoding::Rgb8 { (0, 2) } else { (2, 0) };
                buf.extend(
                    row[3 * x0..3 * x1]
                        .chunks_exact(3)
                        .map(|p| (f32::from(p[r]) - 0.5 * (f32::from(p[1]) + f32::from(p[b]))).max(0.0)),
                );
            }
            _ => buf.extend(inner.map(|x| pixel(row, x as usize))),
        }
    } else {
        buf.extend(inner.map(|y| pixel(image.row(y), s as usize)));
    }
}

/// Mean colour at `offset` pixels either side of the line centre, across the line.
fn side_colour(image: &ImageView<'_>, u: f32, v: f32, vertical: bool, offset: f32) -> [u8; 3] {
    let mut acc = [0u32; 3];
    let mut n = 0;
    for sign in [-1.0f32, 1.0] {
        let (x, y) = if vertical { (u + sign * offset, v) } else { (u, v + sign * offset) };
        let (x, y) = (x.round(), y.round());
        if x < 0.0 || y < 0.0 || x >= image.width() as f32 || y >= image.height() as f32 {
            continue;
        }
        let c = image.rgb_at(x as u32, y as u32);
        for k in 0..3 {
            acc[k] += u32::from(c[k]);
        }
        n += 1;
    }
    if n == 0 {
        return [0; 3];
    }
    [(acc[0] / n) as u8, (acc[1] / n) as u8, (acc[2] / n) as u8]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    proptest::proptest! {
        /// The byte path (masked 16-byte flanks, integer walks, integer sums) takes the same
        /// decisions as the float path on the same samples, and finds the same centre.
        #[test]
        fn byte_and_float_profiles_agree(
            n in 8usize..120,
            c in 0.0f64..1.0,
            sigma in 0.4f64..4.0,
            amp in 0.0f64..260.0,
            bg in 0.0f64..80.0,
            noise in proptest::collection::vec(-12i32..12, 120),
            method in 0usize..3,
        ) {
            let c = c * n as f64;
            let row: Vec<u8> = (0..n)
                .map(|i| {
                    let d = (i as f64 - c) / sigma;
                    (bg + amp * (-0.5 * d * d).exp() + f64::from(noise[i])).round().clamp(0.0, 255.0) as u8
                })
                .collect();
            let float: Vec<f32> = row.iter().map(|&v| f32::from(v)).collect();
            let method = [Method::CenterOfGravity, Method::Gaussian, Method::Parabolic][method];
            let cfg = EdgeConfig { method, ..Default::default() };
            let a = locate(&row, u8::argmax(&row), &cfg, 1.0, 255.0);
            let b = locate(&float, f32::argmax(&float), &cfg, 1.0, 255.0);
            proptest::prop_assert_eq!(a.is_some(), b.is_some(), "{:?} {:?} {:?}", row, a, b);
            if let (Some(a), Some(b)) = (a, b) {
                proptest::prop_assert!((a.pos - b.pos).abs() < 1e-3, "{:?} {:?}", a, b);
                proptest::prop_assert!((a.width - b.width).abs() < 1e-4);
                proptest::prop_assert_eq!(a.strength, b.strength);
            }
        }
    }

    proptest::proptest! {
        /// The vectorised byte primitives against one-sample-at-a-time walks and search.
        #[test]
        fn byte_runs_and_argmax_match_scalar(
            row in proptest::collection::vec(0u8..=255, 0..80),
            m in 0usize..80,
            reach in 0usize..20,
            cut in -3i32..260,
            small in proptest::collection::vec(0u8..4, 0..80),
        ) {
            // Random bytes against any cut, and runs of few levels against cuts among them.
            for (p, cut) in [(&row[..], cut), (&small[..], cut.rem_euclid(5) - 1)] {
                let expected = p.iter().enumerate().fold(None, |b: Option<(usize, u8)>, (i, &v)| match b {
                    Some((_, bv)) if bv >= v => b,
                    _ => Some((i, v)),
                });
                proptest::prop_assert_eq!(argmax_u8(p), expected.map(|(i, _)| i));
                if m < p.len() {
                    let scalar = (walk_left(p, m, m.saturating_sub(reach), cut), walk_right(p, m, m + reach, cut));
                    proptest::prop_assert_eq!(u8::run(p, m, reach, cut), scalar, "{:?} m {} reach {} cut {}", p, m, reach, cut);
                }
            }
        }
    }

    /// A mono8 image with a vertical Gaussian line at column `c` (box-integrated over each pixel).
    fn line_image(w: u32, h: u32, c: f64, sigma: f64, amp: f64, bg: f64) -> Image {
        let mut img = Image::new(w, h, Encoding::Mono8);
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0;
                for k in 0..16 {
                    let xs = x as f64 - 0.5 + (k as f64 + 0.5) / 16.0;
                    acc += (-(xs - c).powi(2) / (2.0 * sigma * sigma)).exp();
                }
                let val = bg + amp * acc / 16.0;
                img.data[(y * w + x) as usize] = val.round().clamp(0.0, 255.0) as u8;
            }
        }
        img
    }

    fn detect(img: &Image, cfg: EdgeConfig) -> LaserLine {
        let mut d = EdgeDetector::new(cfg).unwrap();
        let mut out = LaserLine::default();
        d.detect(&img.view().unwrap(), &mut out).unwrap();
        out
    }

    #[test]
    fn constant_image_has_no_line() {
        let mut img = Image::new(64, 8, Encoding::Mono8);
        img.data.fill(120);
        for m in [Method::CenterOfGravity, Method::Gaussian, Method::Parabolic, Method::Gradient] {
            let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
            assert_eq!(out.found(), 0, "{m:?}");
            assert_eq!(out.len(), 8);
            assert!(out.u.iter().all(|u| u.is_nan()));
        }
    }

    #[test]
    fn gaussian_line_found_within_005_px() {
        for m in [Method::CenterOfGravity, Method::Gaussian, Method::Parabolic] {
            for k in 0..10 {
                let c = 30.0 + k as f64 * 0.1 + 0.013;
                let img = line_image(64, 2, c, 1.6, 200.0, 20.0);
                let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
                let err = (f64::from(out.u[0]) - c).abs();
                assert!(err < 0.05, "{m:?} at {c}: found {} (err {err})", out.u[0]);
                let fwhm = 2.3548 * 1.6;
                assert!((f64::from(out.width[0]) - fwhm).abs() < 0.3, "{m:?} width {}", out.width[0]);
                assert!((out.strength[0] - 200.0).abs() < 15.0, "strength {}", out.strength[0]);
            }
        }
    }

    #[test]
    fn gradient_method_is_integer_and_on_the_rising_edge() {
        let img = line_image(64, 1, 30.37, 1.6, 200.0, 20.0);
        let out = detect(&img, EdgeConfig { method: Method::Gradient, ..Default::default() });
        let u = out.u[0];
        assert_eq!(u, u.round());
        assert!((25.0..30.37).contains(&u), "{u}");
    }

    #[test]
    fn saturated_line_is_centred() {
        let img = line_image(64, 1, 40.3, 2.0, 600.0, 10.0);
        assert!(img.data.iter().filter(|&&v| v == 255).count() > 2);
        for m in [Method::CenterOfGravity, Method::Gaussian, Method::Parabolic] {
            let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
            assert!((out.u[0] - 40.3).abs() < 0.05, "{m:?}: {}", out.u[0]);
        }
    }

    #[test]
    fn strongest_of_two_peaks_is_chosen() {
        let a = line_image(100, 1, 25.2, 1.5, 90.0, 10.0);
        let b = line_image(100, 1, 70.6, 1.5, 180.0, 0.0);
        let mut img = a.clone();
        for (d, s) in img.data.iter_mut().zip(&b.data) {
            *d = d.saturating_add(*s);
        }
        let out = detect(&img, EdgeConfig::default());
        assert!((out.u[0] - 70.6).abs() < 0.05, "{}", out.u[0]);
    }

    #[test]
    fn dim_line_over_noise_found_and_noise_alone_not() {
        // Deterministic pseudo-noise of +-3 grey levels, a line of 25 levels.
        let mut img = line_image(200, 1, 120.4, 1.5, 25.0, 40.0);
        let mut s = 12345u32;
        let mut noisy = img.clone();
        for d in noisy.data.iter_mut() {
            s = s.wrapping_mul(1664525).wrapping_add(1013904223);
            *d = (i32::from(*d) + (s >> 29) as i32 - 3).clamp(0, 255) as u8;
        }
        let out = detect(&noisy, EdgeConfig::default());
        assert!((out.u[0] - 120.4).abs() < 0.3, "{}", out.u[0]);
        img.data = noisy.data.iter().zip(&img.data).map(|(n, c)| n.wrapping_sub(*c).wrapping_add(40)).collect();
        let out = detect(&img, EdgeConfig::default());
        assert_eq!(out.found(), 0);
    }

    #[test]
    fn horizontal_orientation_and_roi() {
        let img = line_image(16, 40, 7.25, 1.5, 200.0, 0.0);
        // Transpose into a horizontal line at row 7.25.
        let mut t = Image::new(40, 16, Encoding::Mono8);
        for y in 0..40u32 {
            for x in 0..16u32 {
                t.data[(x * 40 + y) as usize] = img.data[(y * 16 + x) as usize];
            }
        }
        let cfg = EdgeConfig {
            line_orientation: Orientation::Horizontal,
            roi: Roi { x_offset: 5, y_offset: 0, width: 10, height: 0 },
            ..Default::default()
        };
        let out = detect(&t, cfg);
        assert_eq!(out.len(), 40);
        assert_eq!(out.found(), 10);
        assert!(out.u[4].is_nan() && out.u[15].is_nan());
        assert!((out.v[7] - 7.25).abs() < 0.05 && out.u[7] == 7.0);
    }

    #[test]
    fn colour_channels_and_side_colour() {
        let grey = line_image(80, 1, 40.0, 1.5, 150.0, 0.0);
        let mut img = Image::new(80, 1, Encoding::Bgr8);
        for (i, &g) in grey.data.iter().enumerate() {
            // A white-ish surface (B=G=R=90) with a red laser on top.
            img.data[3 * i] = 90;
            img.data[3 * i + 1] = 90;
            img.data[3 * i + 2] = 90u8.saturating_add(g);
        }
        for ch in [Channel::Red, Channel::Luma, Channel::RedMinusOthers] {
            let out = detect(&img, EdgeConfig { channel: ch, ..Default::default() });
            assert!((out.u[0] - 40.0).abs() < 0.05, "{ch:?} {}", out.u[0]);
            assert_eq!(&out.rgb[..], &[90, 90, 90]);
        }
    }

    #[test]
    fn mono16_scaled_thresholds() {
        let g = line_image(64, 1, 20.6, 1.5, 200.0, 10.0);
        let mut img = Image::new(64, 1, Encoding::Mono16);
        for (i, &v) in g.data.iter().enumerate() {
            img.data[2 * i..2 * i + 2].copy_from_slice(&(u16::from(v) * 257).to_le_bytes());
        }
        let out = detect(&img, EdgeConfig::default());
        assert!((out.u[0] - 20.6).abs() < 0.05);
        assert!((out.strength[0] - 190.0).abs() < 15.0, "{}", out.strength[0]);
    }

    #[test]
    fn bad_config_and_roi_are_typed_errors() {
        assert!(EdgeDetector::new(EdgeConfig { peak_fraction: 1.5, ..Default::default() }).is_err());
        assert!(EdgeDetector::new(EdgeConfig { min_strength: f32::NAN, ..Default::default() }).is_err());
        let img = Image::new(10, 10, Encoding::Mono8);
        let mut d =
            EdgeDetector::new(EdgeConfig { roi: Roi { x_offset: 20, ..Default::default() }, ..Default::default() })
                .unwrap();
        let mut out = LaserLine::default();
        assert!(matches!(d.detect(&img.view().unwrap(), &mut out), Err(EdgeError::RoiOutside { .. })));
    }
}
