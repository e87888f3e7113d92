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

mod fit;
mod lanes;
mod plane;
mod track;

use crate::image::{Encoding, ImageError, ImageView};
use fit::{center_of_gravity, gaussian_fit, integrated_gaussian, least_squares_gaussian, Fit};
pub use lanes::argmax_u8;
use lanes::Sample;
use serde::{Deserialize, Serialize};

/// How the line centre is located within a row.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The study's method: first five-pixel rise above `gradient_threshold`, integer pixels.
    Gradient,
    /// Centre of gravity of the background-subtracted samples above a fraction of the peak.
    #[default]
    CenterOfGravity,
    /// Least-squares fit of a Gaussian over a constant background, started from the weighted
    /// parabola through the logarithm of the peak (Caruana); saturated samples are censored.
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
    /// `vertical` / `horizontal`.
    pub fn name(self) -> &'static str {
        match self {
            Orientation::Vertical => "vertical",
            Orientation::Horizontal => "horizontal",
        }
    }
}

/// Which signal of a colour image carries the laser.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Channel {
    /// The red channel.
    Red,
    /// Luma (0.299 R + 0.587 G + 0.114 B).
    Luma,
    /// Red minus the mean of green and blue, clamped at 0: the laser's colour against the
    /// others, so white surfaces, room light and highlights drop out. The default.
    #[default]
    RedMinusOthers,
    /// The green channel.
    Green,
    /// The blue channel.
    Blue,
    /// Green minus the mean of red and blue, clamped at 0 (a green laser).
    GreenMinusOthers,
    /// Blue minus the mean of red and green, clamped at 0 (a blue laser).
    BlueMinusOthers,
}

/// Every channel, in the order of [`Channel::name`]'s list.
const CHANNELS: [Channel; 7] = [
    Channel::RedMinusOthers,
    Channel::GreenMinusOthers,
    Channel::BlueMinusOthers,
    Channel::Red,
    Channel::Green,
    Channel::Blue,
    Channel::Luma,
];

impl Channel {
    /// Parses `red_minus_others`, `green_minus_others`, `blue_minus_others`, `red`, `green`,
    /// `blue`, `luma`.
    pub fn parse(s: &str) -> Option<Channel> {
        CHANNELS.into_iter().find(|c| c.name() == s)
    }
    /// The parameter value naming this channel.
    pub fn name(self) -> &'static str {
        match self {
            Channel::Red => "red",
            Channel::Luma => "luma",
            Channel::RedMinusOthers => "red_minus_others",
            Channel::Green => "green",
            Channel::Blue => "blue",
            Channel::GreenMinusOthers => "green_minus_others",
            Channel::BlueMinusOthers => "blue_minus_others",
        }
    }
    /// A laser of colour `c` seen against the other colours: what the detector reads for each
    /// laser of a scanner with several.
    pub fn against_others(c: LaserColor) -> Channel {
        match c {
            LaserColor::Red => Channel::RedMinusOthers,
            LaserColor::Green => Channel::GreenMinusOthers,
            LaserColor::Blue => Channel::BlueMinusOthers,
        }
    }
    /// The signal of this channel from one pixel's red, green and blue.
    pub fn of(self, r: f32, g: f32, b: f32) -> f32 {
        match self {
            Channel::Red => r,
            Channel::Green => g,
            Channel::Blue => b,
            Channel::Luma => crate::image::luma(r, g, b),
            Channel::RedMinusOthers => (r - 0.5 * (g + b)).max(0.0),
            Channel::GreenMinusOthers => (g - 0.5 * (r + b)).max(0.0),
            Channel::BlueMinusOthers => (b - 0.5 * (r + g)).max(0.0),
        }
    }
}

/// The colour of a laser (parameter `laser.<name>.channel`): on colour cameras each laser's
/// line is found in its own colour against the others.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LaserColor {
    /// A red laser.
    Red,
    /// A green laser.
    Green,
    /// A blue laser.
    Blue,
}

impl LaserColor {
    /// Parses `red`, `green`, `blue`.
    pub fn parse(s: &str) -> Option<LaserColor> {
        [LaserColor::Red, LaserColor::Green, LaserColor::Blue].into_iter().find(|c| c.name() == s)
    }
    /// The parameter value naming this colour.
    pub fn name(self) -> &'static str {
        match self {
            LaserColor::Red => "red",
            LaserColor::Green => "green",
            LaserColor::Blue => "blue",
        }
    }
}

/// `Display` as the parameter value and `FromStr` from it, with an error that names the value.
macro_rules! named {
    ($t:ty, $what:literal) => {
        impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }
        impl std::str::FromStr for $t {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                Self::parse(s).ok_or_else(|| format!($what, s))
            }
        }
    };
}
named!(Method, "unknown method {:?} (center_of_gravity, gaussian, parabolic or gradient)");
named!(Orientation, "{:?} is not vertical or horizontal");
named!(
    Channel,
    "unknown channel {:?} (red_minus_others, green_minus_others, blue_minus_others, red, green, blue or luma)"
);
named!(LaserColor, "unknown laser colour {:?} (red, green or blue)");

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

impl std::fmt::Display for Roi {
    /// As the parameters read: `roi.x_offset 700, roi.y_offset 0, roi.width 40, roi.height 0`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "roi.x_offset {}, roi.y_offset {}, roi.width {}, roi.height {}",
            self.x_offset, self.y_offset, self.width, self.height
        )
    }
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
    /// Peaks narrower than this (FWHM, pixels) are rejected: a camera whose laser line is wide
    /// sets it to tell the line from sharpening overshoot at edges and from fine texture.
    pub min_width_px: f32,
    /// For `gradient`: the five-pixel rise that marks the line, grey levels.
    pub gradient_threshold: f32,
    /// Colour is sampled this far beside the line centre (the study's t +/- d), pixels.
    pub color_offset_px: f32,
    /// A line stands above the background on both sides: the lower side's rise must be at
    /// least this fraction of the higher side's. A step (bright on one side) is not a line.
    pub min_side_ratio: f32,
    /// Lines narrower than this (FWHM, pixels) are located by a pixel-integrated Gaussian fit,
    /// whatever the method: every thresholded or three-point estimate locks to pixel centres
    /// there.
    pub narrow_width_px: f32,
    /// Peaks tried per row until one passes every test: the brightest, the one of highest
    /// contrast, then the next brightest (each outside the peaks already refused).
    pub max_candidates: u32,
    /// Samples of a line run along at least this many consecutive rows (columns); shorter runs
    /// (noise, texture, a highlight) are dropped, and a frame without laser light gives none.
    pub min_run: u32,
    /// Largest step of the line centre between neighbouring rows (columns) of one run, pixels.
    pub max_jump_px: f32,
}

impl EdgeConfig {
    /// The defaults (the node's parameter defaults), usable in constant expressions.
    pub const DEFAULT: EdgeConfig = EdgeConfig {
        method: Method::CenterOfGravity,
        line_orientation: Orientation::Vertical,
        channel: Channel::RedMinusOthers,
        roi: Roi { x_offset: 0, y_offset: 0, width: 0, height: 0 },
        min_strength: 8.0,
        noise_factor: 4.0,
        peak_fraction: 0.15,
        max_half_width_px: 12,
        flank_px: 10,
        max_width_px: 14.0,
        min_width_px: 0.0,
        gradient_threshold: 40.0,
        color_offset_px: 8.0,
        min_side_ratio: 0.3,
        narrow_width_px: 3.2,
        max_candidates: 3,
        min_run: 5,
        max_jump_px: 3.0,
    };
}

impl Default for EdgeConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why a configuration or an image was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EdgeError {
    /// The image itself is malformed.
    #[error(transparent)]
    Image(#[from] ImageError),
    /// The region of interest lies outside the image.
    #[error("the region of interest ({roi}) lies outside the {width}x{height} image")]
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
    /// Several lasers in a grey image: only colour tells their lines apart.
    #[error("a {encoding} image cannot tell {lasers} lasers apart (their lines are told apart by colour)")]
    GreyWithLasers {
        /// The image's encoding.
        encoding: &'static str,
        /// Lasers configured.
        lasers: usize,
    },
}

impl EdgeConfig {
    /// The columns and rows of `image` that the region of interest searches.
    pub fn region(&self, image: &ImageView<'_>) -> Result<(std::ops::Range<u32>, std::ops::Range<u32>), EdgeError> {
        let (w, h) = (image.width(), image.height());
        let roi = self.roi;
        if roi.x_offset >= w || roi.y_offset >= h {
            return Err(EdgeError::RoiOutside { roi, width: w, height: h });
        }
        let x1 = if roi.width == 0 { w } else { (roi.x_offset + roi.width).min(w) };
        let y1 = if roi.height == 0 { h } else { (roi.y_offset + roi.height).min(h) };
        Ok((roi.x_offset..x1, roi.y_offset..y1))
    }

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
        if !(self.min_width_px >= 0.0 && self.min_width_px < self.max_width_px) {
            return bad("min_width_px", "must be >= 0 and below max_width_px");
        }
        if !(self.gradient_threshold > 0.0) {
            return bad("gradient_threshold", "must be > 0");
        }
        if !(self.color_offset_px.is_finite() && self.color_offset_px >= 0.0) {
            return bad("color_offset_px", "must be a finite value >= 0");
        }
        if !(0.0..=1.0).contains(&self.min_side_ratio) {
            return bad("min_side_ratio", "must be in [0, 1]");
        }
        if !(self.narrow_width_px.is_finite() && self.narrow_width_px >= 0.0) {
            return bad("narrow_width_px", "must be a finite value >= 0");
        }
        if self.max_candidates == 0 || self.max_candidates > 16 {
            return bad("max_candidates", "must be in 1..=16");
        }
        if self.min_run == 0 || self.min_run > 1000 {
            return bad("min_run", "must be in 1..=1000");
        }
        if !(self.max_jump_px.is_finite() && self.max_jump_px > 0.0) {
            return bad("max_jump_px", "must be a finite value > 0");
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
    /// Clears sample `i` (no line there).
    fn clear(&mut self, i: usize) {
        self.u[i] = f32::NAN;
        self.v[i] = f32::NAN;
        self.strength[i] = 0.0;
        self.width[i] = 0.0;
    }
    /// The position across the line of sample `i` (the column of a vertical line), NaN where
    /// none.
    pub fn across(&self, i: usize) -> f32 {
        match self.orientation {
            Orientation::Vertical => self.u[i],
            Orientation::Horizontal => self.v[i],
        }
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

/// One located peak in a profile.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Peak {
    pos: f32,
    strength: f32,
    width: f32,
    saturated: bool,
    /// A narrow line's fitted form: its sigma (pixels), or the one edge that awaits the
    /// frame's sigma (`pos` holds the centre of gravity until then).
    fit: Option<Fit>,
    /// Found only with flanks cut short at the dark samples beside a line in a dark stripe
    /// between brighter surfaces: taken where no other candidate of the row is a line. The
    /// samples the next candidate's search leaves out (as for a refused peak).
    fallback: Option<(usize, usize)>,
}

/// The background beside a peak: each flank's mean and centre, and the noise.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Flanks {
    /// Mean and centre (sample position) of the left flank.
    left: (f32, f32),
    /// Mean and centre of the right flank.
    right: (f32, f32),
    /// Pooled mean of both flanks.
    mean: f32,
    /// Standard deviation of each flank about its own mean, pooled (so a shading slope between
    /// the two flanks is not counted as noise).
    noise: f32,
}

/// The flanks outside `m +/- gap`, each `flank` samples long. `None` unless both lie inside the
/// profile with at least half their length: a peak at the edge of the row or of the region
/// searched may be the cut-off halo of a line outside it, and is not a line.
#[inline]
fn background<S: Sample>(p: &[S], m: usize, gap: usize, flank: usize) -> Option<Flanks> {
    let need = flank.div_ceil(2).max(1);
    let end = m.checked_sub(gap)?;
    let start = end.saturating_sub(flank);
    let rstart = m + gap + 1;
    let rend = (rstart + flank).min(p.len());
    if end - start < need || rend < rstart + need {
        return None;
    }
    Some(Flanks::of(side(p, start, end), side(p, rstart, rend)))
}

impl Flanks {
    /// The background of the two flanks `l` and `r`.
    fn of(l: Side, r: Side) -> Flanks {
        let n = (l.count + r.count) as f32;
        Flanks {
            left: (l.mean, l.centre),
            right: (r.mean, r.centre),
            mean: (l.mean * l.count as f32 + r.mean * r.count as f32) / n,
            noise: ((l.ss + r.ss).max(0.0) / n).sqrt(),
        }
    }
}

/// One flank's level: its mean, where it was taken, and the sum of squares about it.
struct Side {
    mean: f32,
    centre: f32,
    ss: f32,
    count: usize,
}

impl Side {
    /// The level of the `count` samples from `start` whose sum is `sum` and sum of squares
    /// `squares`.
    fn of(sum: f32, squares: f32, count: usize, start: usize) -> Side {
        Side {
            mean: sum / count as f32,
            centre: 0.5 * (2 * start + count) as f32 - 0.5,
            ss: squares - sum * sum / count as f32,
            count,
        }
    }
}

/// The level of `p[start..end]`: its mean, or, where its two halves disagree by more than the
/// quieter half's noise allows (another line, a highlight or an edge reaching into the flank),
/// the darker half's.
#[inline]
fn side<S: Sample>(p: &[S], start: usize, end: usize) -> Side {
    let k = end - start;
    let h = k / 2;
    let (a, b) = S::moments(p, start, start + h);
    let (c, d) = S::moments(p, start + h, end);
    let whole = Side::of;
    if h < 2 || k - h < 2 {
        return whole(a + c, b + d, k, start);
    }
    let (first, second) = (whole(a, b, h, start), whole(c, d, k - h, start + h));
    // |difference| <= HALF_AGREEMENT * (the quieter half's sd) + 1, in squares (no roots).
    let var = |s: &Side| s.ss.max(0.0) / s.count as f32;
    let excess = ((first.mean - second.mean).abs() - 1.0).max(0.0);
    if excess * excess <= HALF_AGREEMENT * HALF_AGREEMENT * var(&first).min(var(&second)) {
        Side { ss: first.ss + second.ss, ..whole(a + c, b + d, k, start) }
    } else if first.mean < second.mean {
        first
    } else {
        second
    }
}

/// The halves of a flank agree when their means differ by at most this many noise standard
/// deviations (plus one grey level of quantisation).
const HALF_AGREEMENT: f32 = 3.0;

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

/// Locates a line whose brightest sample is `m`, or refuses it: too weak for the local noise,
/// a step rather than a peak, cut off by the edge of the profile, or too wide.
fn find_peak<S: Sample>(
    p: &[S],
    m: usize,
    cfg: &EdgeConfig,
    scale: f32,
    saturation: f32,
) -> Result<Peak, (usize, usize)> {
    let n = p.len();
    let peak = p[m].f();
    let max_hw = cfg.max_half_width_px as usize;
    let flank = cfg.flank_px as usize;
    // First pass: the run above half of the peak over the background nearby gives the gap
    // that keeps the background flanks off the line.
    // Wide enough that the flanks clear most lines on the first try.
    let gap0 = max_hw.min(6);
    let Some(f0) = background(p, m, gap0, flank) else {
        return Err((m.saturating_sub(gap0), m + gap0));
    };
    let half0 = S::cut(f0.mean + 0.5 * (peak - f0.mean));
    // One sample further than a line may reach, so that a line too wide shows as such.
    let (lo, hi) = S::run(p, m, max_hw + 1, half0);
    let run = (lo.saturating_sub(1), hi + 1);
    // The flanks just clear the line: twice its half-width and two more samples out.
    let hw = (m - lo).max(hi - m);
    let gap = (2 * hw + 2).max(gap0).min(max_hw);
    let f = match if gap == gap0 { Some(f0) } else { background(p, m, gap, flank) } {
        Some(f) => f,
        None => return Err(run),
    };
    // With the first flanks, the first pass's run is the half-maximum run.
    let known = (gap == gap0).then_some((lo, hi));
    let first = judge::<S, true>(p, m, &f, known, cfg, (scale, saturation), run);
    // A line a pixel or two wide, clearly above its near samples, that fails with flanks `gap0`
    // out may lie in a narrow dark stripe between brighter surfaces: its background is right
    // beside it, GAP_PER_WIDTH times its width out.
    if first.is_ok() || hw > 1 {
        return first;
    }
    // Where those flanks read a surface brighter than the line, the half-maximum run over them
    // is the top sample alone; the samples that stand for the line's near background are then
    // two beyond the run above half the peak over the lower sample two away (for a line two
    // pixels wide, its other half would be taken for its background).
    let base = p[m.saturating_sub(2)].f().min(p[(m + 2).min(n - 1)].f());
    let (llo, lhi) = S::run(p, m, 2, S::cut(base + 0.5 * (peak - base)));
    // The level beside the run `(a, b)`: the higher of the samples two beyond it on each side,
    // or (`close`) of the lower of the two samples beyond it on each side. A line a single dark
    // sample from a brighter surface (the print's edge right beside it) stands over that dark
    // sample, not over the surface two beyond: it is tried as a line in a stripe with that
    // side's flank one sample long.
    let beside = |(a, b): (usize, usize), close: bool| {
        let (l, r) = (p[a - 2].f(), p[b + 2].f());
        if close {
            l.min(p[a - 1].f()).max(r.min(p[b + 1].f()))
        } else {
            l.max(r)
        }
    };
    let clear_by = |(a, b): (usize, usize), by: f32, close: bool| {
        a >= 2 && b + 2 < n && peak - beside((a, b), close) >= by * cfg.min_strength * scale
    };
    let clear = |r| clear_by(r, NARROW_RETRY, false);
    let runs = [(lo.min(llo), hi.max(lhi)), (lo, hi)];
    let Some(((glo, ghi), close)) = [false, true]
        .into_iter()
        .find_map(|close| runs.into_iter().find(|&r| clear_by(r, STRIPE_RETRY, close)).map(|r| (r, close)))
    else {
        return first;
    };
    let level = f0.mean + 0.5 * (peak - f0.mean);
    let w0 = crossing(p, hi + 1, hi, level) - crossing(p, lo - 1, lo, level);
    let near = ((GAP_PER_WIDTH * w0).ceil() as usize).clamp(1, max_hw);
    let near_flanks = background(p, m, near, flank)
        .filter(|_| near < gap && clear((lo, hi)))
        .map_or(Err(run), |f| judge::<S, true>(p, m, &f, None, cfg, (scale, saturation), run));
    // On a dark surface a few pixels from a brighter one (dark print beside bare skin under
    // room light), even the flanks `near` out reach the bright surface: the background is then
    // the dark samples between the line and it, up to the first sample above the half maximum.
    // Where the line is dimmer than the surfaces on both sides (a stripe of dark print between
    // two of them: the hard pyramid's print at 320x240), that half maximum, over flanks that
    // read the bright surfaces, lies near the line's top and lets their ramps into the flanks;
    // there the flanks end where the samples rise past half the line over the dark samples
    // right beside it. Such a line must be narrow and enclosed by surfaces brighter than its
    // peak, and even then it is a fallback that a line found otherwise in the row displaces: a
    // narrow mark on a textured floor passes the same tests (the robot's real frames lost a few
    // hundred columns when such marks were taken first).
    let beside_dark = beside((glo, ghi), close);
    let dark_level = level.min(beside_dark + 0.5 * (peak - beside_dark));
    near_flanks
        .or_else(|_| {
            let f = dark_background(p, (lo, hi), flank, level).filter(|_| clear((lo, hi))).ok_or(run)?;
            judge::<S, true>(p, m, &f, None, cfg, (scale, saturation), run)
        })
        .or_else(|e| {
            dark_flanks(p, (glo, ghi), flank, dark_level)
                .filter(|&e| enclosed(p, e, peak))
                .and_then(|e| Some((e, dark_flanks_background(p, e, flank, SHORT_DARK_FLANK)?)))
                .and_then(|([start, end, rstart, rend], f)| {
                    let shoulders = (end - start).min(rend - rstart) >= DARK_FLANK;
                    let judge = if shoulders { judge::<S, true> } else { judge::<S, false> };
                    judge(p, m, &f, None, cfg, (scale, saturation), run).ok()
                })
                .filter(|pk| pk.width <= cfg.narrow_width_px)
                .map(|pk| Peak { fallback: Some(run), ..pk })
                .ok_or(e)
        })
}

/// A narrow peak on a run's course (`track::extend`'s search): the line continued from the
/// rows beside it, where the full tests refuse it because a brighter surface lies a sample or
/// two off (a line on dark print right beside the print's edge: the hard pyramid at 320x240,
/// `face 45 | 24 | line 45 | 18 | print 8 8 8`). Its base is the higher of the lowest sample
/// within two on each side; its darker side's flank, the samples under the base from three
/// out (at least `DARK_FLANK`, at most `flank_px`). It must stand `COURSE_STRENGTH` times
/// `min_strength`, and `noise_factor` times that flank's noise, above its base; the base must
/// lie under half the peak over the flank (a line falls away on both sides; the top of a
/// brighter surface's edge does not); and it must be at most `narrow_width_px` wide at half
/// its height over the base. Its centre is the centre of gravity of the three samples about
/// the peak over the flank's level.
fn course_peak<S: Sample>(p: &[S], m: usize, cfg: &EdgeConfig, scale: f32) -> Option<Peak> {
    let n = p.len();
    if m < 3 || m + 3 >= n {
        return None;
    }
    let peak = p[m].f();
    let (lo_l, lo_r) = (p[m - 2].f().min(p[m - 1].f()), p[m + 1].f().min(p[m + 2].f()));
    let base = lo_l.max(lo_r);
    let strength = peak - base;
    // The darker side's flank: from three samples out, the samples below the base.
    let flank = cfg.flank_px as usize;
    let (mut sum, mut squares, mut count) = (0.0f32, 0.0f32, 0usize);
    let mut take = |v: f32| {
        (sum, squares, count) = (sum + v, squares + v * v, count + 1);
    };
    if lo_l <= lo_r {
        for i in (m.saturating_sub(2 + flank)..m - 2).rev() {
            if p[i].f() >= base {
                break;
            }
            take(p[i].f());
        }
    } else {
        for i in m + 3..(m + 3 + flank).min(n) {
            if p[i].f() >= base {
                break;
            }
            take(p[i].f());
        }
    }
    if count < DARK_FLANK {
        return None;
    }
    let dark = sum / count as f32;
    let noise = ((squares - sum * dark) / count as f32).max(0.0).sqrt();
    // Both sides fall below half the peak over the dark flank within two samples: a line, not
    // the top of a bright surface's edge it merges into.
    if strength < (COURSE_STRENGTH * cfg.min_strength * scale).max(cfg.noise_factor * noise)
        || base > dark + 0.5 * (peak - dark)
    {
        return None;
    }
    let half = base + 0.5 * strength;
    let (l, r) = S::run(p, m, 2, S::cut(half));
    let width = crossing(p, r + 1, r, half) - crossing(p, l - 1, l, half);
    if width > cfg.narrow_width_px {
        return None;
    }
    let w = |i: usize| (p[i].f() - dark).max(0.0);
    let (a, b, c) = (w(m - 1), w(m), w(m + 1));
    let pos = m as f32 + (c - a) / (a + b + c);
    Some(Peak { pos, strength, width, saturated: false, fit: None, fallback: None })
}

/// A narrow peak on a run's course stands this many times `min_strength` above its base
/// (`course_peak`).
const COURSE_STRENGTH: f32 = 1.0;

/// A narrow peak on a run's course (`course_peak`) lies at most this far from where the course
/// is expected, pixels (the search's radius grows with the rows missed, this does not).
const COURSE_REACH_PX: f32 = 1.5;

/// The extents `(start..end, rstart..rend)` of the dark flanks beside the half-maximum run
/// `(lo, hi)`: from two samples beyond it outwards, each the samples below `level` (at most
/// `flank`) up to the first sample that is not (a brighter surface beside the line). A side
/// that holds fewer than `DARK_FLANK` samples so also takes the sample right beside the run
/// where that is below `level`.
fn dark_flanks<S: Sample>(p: &[S], (lo, hi): (usize, usize), flank: usize, level: f32) -> Option<[usize; 4]> {
    let mut end = lo.checked_sub(1)?;
    let mut start = end;
    while start > 0 && end - start < flank && p[start - 1].f() < level {
        start -= 1;
    }
    // At the profile's end the right flank is empty (never `rend < rstart`).
    let mut rstart = (hi + 2).min(p.len());
    let mut rend = rstart;
    while rend < p.len() && rend - rstart < flank && p[rend].f() < level {
        rend += 1;
    }
    // A side cut short by a brighter surface three samples from the run also takes the sample
    // right beside the run, where that is already dark (the line's tail has ended).
    if end - start < DARK_FLANK && p[end].f() < level {
        end += 1;
    }
    if rend < rstart + DARK_FLANK && hi + 1 < p.len() && p[hi + 1].f() < level {
        rstart = hi + 1;
    }
    Some([start, end, rstart, rend])
}

/// The background of the dark flanks (`dark_flanks`). `None` unless each side has at least
/// `DARK_FLANK` samples and ends at a brighter sample or at its full length, never at the
/// profile's end.
fn dark_background<S: Sample>(p: &[S], run: (usize, usize), flank: usize, level: f32) -> Option<Flanks> {
    dark_flanks(p, run, flank, level).and_then(|e| dark_flanks_background(p, e, flank, DARK_FLANK))
}

/// The background of the dark flanks with extents `[start, end, rstart, rend]`, as
/// `dark_background`, but for the shorter side, which needs only `short` samples.
fn dark_flanks_background<S: Sample>(
    p: &[S],
    [start, end, rstart, rend]: [usize; 4],
    flank: usize,
    short: usize,
) -> Option<Flanks> {
    let (left, right) = (end - start, rend - rstart);
    let (least_l, least_r) = if left >= right { (DARK_FLANK, short) } else { (short, DARK_FLANK) };
    let closed = |k: usize, least: usize, edge: bool| k >= least && (k == flank || !edge);
    if !closed(left, least_l, start == 0) || !closed(right, least_r, rend == p.len()) {
        return None;
    }
    // The whole of each flank: its halves are not compared, the brighter surface is outside it.
    let whole = |a: usize, b: usize| {
        let (sum, squares) = S::moments(p, a, b);
        Side::of(sum, squares, b - a, a)
    };
    Some(Flanks::of(whole(start, end), whole(rstart, rend)))
}

/// Whether the dark flanks with extents `[start, _, _, rend]` (`dark_flanks`) both end at a
/// surface brighter than the line's `peak` (within `ENCLOSED_REACH` samples beyond them): a
/// dark stripe between two brighter surfaces, not a narrow mark on a textured floor.
fn enclosed<S: Sample>(p: &[S], [start, _, _, rend]: [usize; 4], peak: f32) -> bool {
    let left = (start.saturating_sub(ENCLOSED_REACH)..start).any(|i| p[i].f() >= peak);
    let right = (rend..(rend + ENCLOSED_REACH).min(p.len())).any(|i| p[i].f() >= peak);
    left && right
}

/// How far beyond a dark flank the brighter surface that encloses it is looked for, samples.
const ENCLOSED_REACH: usize = 3;

/// The fewest samples of a flank between a narrow line and a brighter surface beside it.
const DARK_FLANK: usize = 2;

/// The fewest samples of the shorter flank of a narrow line in a dark stripe enclosed by
/// brighter surfaces (the other flank holds `DARK_FLANK`).
const SHORT_DARK_FLANK: usize = 1;

/// The tests of a peak at `m` against its flanks `f`, and its centre: too weak for the local
/// noise, a step rather than a peak, cut off by the edge of the profile, or too wide or narrow
/// is refused (with `run`, where the next candidate is not looked for). `known` is the
/// half-maximum run when it is already known. `SHOULDERS`: whether a brighter surface two or
/// three samples beyond the half-maximum run raises the level of the centre's samples (not
/// where the flanks end at that surface, a dark sample parting it from the line).
fn judge<S: Sample, const SHOULDERS: bool>(
    p: &[S],
    m: usize,
    f: &Flanks,
    known: Option<(usize, usize)>,
    cfg: &EdgeConfig,
    (scale, saturation): (f32, f32),
    run: (usize, usize),
) -> Result<Peak, (usize, usize)> {
    let n = p.len();
    let peak = p[m].f();
    let max_hw = cfg.max_half_width_px as usize;
    let bg = f.mean;
    let strength = peak - bg;
    let floor = (cfg.min_strength * scale).max(cfg.noise_factor * f.noise);
    if strength < floor || strength <= 0.0 {
        return Err(run);
    }
    // A peak, not a step: it rises above the background on both sides.
    let (rise_l, rise_r) = (peak - f.left.0, peak - f.right.0);
    if rise_l.min(rise_r) < floor.max(cfg.min_side_ratio * rise_l.max(rise_r)) {
        return Err(run);
    }
    // Full width at half maximum.
    let half = bg + 0.5 * strength;
    let (l, r) = known.unwrap_or_else(|| S::run(p, m, max_hw + 1, S::cut(half)));
    if l == 0 || r + 1 >= n {
        return Err(run); // the line runs into the edge of the profile
    }
    let left = crossing(p, l - 1, l, half);
    let right = crossing(p, r + 1, r, half);
    let width = right - left;
    if width > cfg.max_width_px || width < cfg.min_width_px || m - l > max_hw || r - m > max_hw {
        return Err(run);
    }
    let saturated = peak >= saturation;
    // The centre's samples: above `peak_fraction` of the peak over the higher flank, so that on
    // a step (a bright face on one side) the run does not spill into the face; at most half the
    // peak over the background, so that the run is never empty.
    let high = f.left.0.max(f.right.0);
    let mut level =
        (bg + cfg.peak_fraction * strength).max(high + cfg.peak_fraction * (peak - high)).min(bg + 0.5 * strength);
    // A bright face may also end before the flank does (a highlight beside the line, whose
    // flank then reads the darker surface beyond it), and the run spill onto it: the lower of
    // the two samples two and three beyond the half-maximum run stands for the face on each
    // side (a line's own tail is still falling there) when it stands clearly above the flanks,
    // and the centre's samples are those above it.
    let at = |i: usize| p[i.min(n - 1)].f();
    let (ll, rr) = (l.saturating_sub(2), r + 2);
    let mut stepped = false;
    if SHOULDERS && (at(ll) > level || at(rr) > level) {
        let shoulder = at(ll).min(at(ll.saturating_sub(1))).max(at(rr).min(at(rr + 1)));
        stepped = shoulder - high > floor;
        if stepped {
            level = level.max(shoulder + cfg.peak_fraction * (peak - shoulder));
        }
    }
    let cog = |p: &[S]| center_of_gravity(p, m, level, max_hw);
    let mut fit = None;
    let pos = if !saturated && width < cfg.narrow_width_px {
        // The fit's run: above the centre-of-gravity level, and one sample more on each side.
        let (a, b) = S::run(p, m, max_hw, S::cut(level));
        let (a, b) = (a.saturating_sub(1), (b + 1).min(n - 1));
        fit = integrated_gaussian(p, (a, m, b), (f.left.1, f.left.0), (f.right.1, f.right.0));
        match fit {
            Some(Fit::Centre { centre, .. }) => centre,
            _ => cog(p).ok_or(run)?,
        }
    } else {
        // A line's light falls away on both sides: above `peak_fraction` of its height, the
        // logarithm of a line that is neither clipped nor on a shoulder is concave (the
        // log-parabola of `gaussian_fit`, which also starts the Gaussian method's fit). A halo
        // on the edge of crushed black stands over both flanks but stays up on its bright side:
        // the Ciclop's laser-off photographs of its pattern gave 22-25 rows by the centre of
        // gravity before every method asked this.
        let log_parabola =
            if saturated || stepped { None } else { Some(gaussian_fit(p, m, bg, strength, cfg).ok_or(run)?) };
        match cfg.method {
            Method::Parabolic if !saturated => {
                let (a, b, c) = (p[m - 1].f(), peak, p[m + 1].f());
                let den = a - 2.0 * b + c;
                Some(if den < 0.0 { m as f32 + (0.5 * (a - c) / den).clamp(-0.5, 0.5) } else { m as f32 })
            }
            Method::Gaussian => {
                // The log-parabola (or, on a clipped top or a shoulder, the centre of gravity)
                // starts a least-squares fit of the Gaussian itself, saturated samples censored.
                let start = log_parabola.or_else(|| cog(p));
                let reach = ((0.8 * width).ceil() as usize).max(4).min(2 * max_hw);
                let (a, b) = (m.saturating_sub(reach), (m + reach).min(n - 1));
                start.and_then(|c| {
                    let init = [f64::from(bg), f64::from(strength), f64::from(c), f64::from(width / 2.3548)];
                    least_squares_gaussian(p, a, b, init, saturation)
                        .filter(|x| (x - c).abs() < if stepped { STEPPED_FIT_REACH_PX } else { 0.5 * width })
                        .or(Some(c))
                })
            }
            _ => cog(p),
        }
        .ok_or(run)?
    };
    Ok(Peak { pos, strength, width, saturated, fit, fallback: None })
}

/// How far the Gaussian's least-squares fit may move a line on a shoulder from its centre of
/// gravity, pixels: the fit's one background does not hold there.
const STEPPED_FIT_REACH_PX: f32 = 0.3;

/// The study's method: first rise over five samples above the threshold; integer position.
fn gradient_edge<S: Sample>(p: &[S], threshold: f32) -> Option<Peak> {
    (0..p.len().saturating_sub(4)).map(|i| (i, p[i + 4].f() - p[i].f())).find(|&(_, g)| g > threshold).map(|(i, g)| {
        Peak { pos: (i + 2) as f32, strength: g, width: 0.0, saturated: false, fit: None, fallback: None }
    })
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
    /// Peaks that passed every test of their own row but belonged to a run shorter than
    /// `min_run` (noise, texture, a highlight, a frame without laser light), dropped.
    pub short_runs: u32,
    /// Samples of the second line (a second surface in the same row), where asked for.
    pub second: u32,
}

/// A reusable detector: owns its scratch buffers so that the hot path does not allocate.
#[derive(Debug, Default, Clone)]
pub struct EdgeDetector {
    config: EdgeConfig,
    scratch: Scratch,
    /// Per sample: saturated, and a narrow line's fit.
    state: Vec<(bool, Option<Fit>)>,
    /// The narrow line's sigma (pixels) as last measured, for the samples of a frame that
    /// measures none.
    sigma_px: Option<f32>,
    /// The line's typical width (median FWHM, pixels) in the last frame that had a line.
    width_px: Option<f32>,
    /// Scratch for the medians of widths and strengths (the frame's, each run's), as order keys.
    widths: Vec<u32>,
    /// The frame's signal as bytes, where it is not read in place.
    plane: Plane,
    /// Per sample of the second line: saturated, and a narrow line's fit.
    second_state: Vec<(bool, Option<Fit>)>,
    /// The last frame's line: per sample its centre across (NaN where none), and the image's
    /// size and orientation it belongs to.
    previous: Previous,
}

/// The last frame's line, for the next frame's choice among a row's peaks.
#[derive(Debug, Default, Clone)]
struct Previous {
    /// Per sample, the centre across (a vertical line's column), NaN where none.
    across: Vec<f32>,
    /// Per sample, the line's strength.
    strength: Vec<f32>,
    /// The image's size and the line's orientation.
    shape: (u32, u32, bool),
}

impl Previous {
    /// This frame's line `out` (of an image `w x h`, `vertical` or not), in the buffers of the
    /// last's.
    fn remember(mut self, out: &LaserLine, (w, h, vertical): (u32, u32, bool)) -> Previous {
        self.across.clear();
        self.across.extend_from_slice(if vertical { &out.u } else { &out.v });
        self.strength.clear();
        self.strength.extend_from_slice(&out.strength);
        self.shape = (w, h, vertical);
        self
    }
}

/// Where a detection reads its signal.
#[derive(Debug, Clone, Copy)]
enum Signal<'a> {
    /// The image itself: mono8 rows in place, or the float profiles of mono16 and colour.
    Image,
    /// Bytes, one row of the region's width per sample (a colour image's channel, for a
    /// vertical line).
    Plane(&'a [u8]),
    /// Row-major bytes of a horizontal line's region, read by column (see [`Columns`]).
    Rows(plane::Rows<'a>),
}

/// A horizontal line's signal in row-major bytes, read by column. Every column's first
/// candidate, its brightest sample, is found in one pass over the rows in order
/// ([`plane::column_argmax`]) and judged on the window its tests read ([`window_reach`]),
/// gathered from the rows. Only the columns whose first candidate fails, and the searches near
/// a run's course, read a whole column, transposed 16 columns at a time when first needed. The
/// samples are those of the transposed image, bit for bit.
type Columns<'a> = plane::Rows<'a>;

/// How far from its peak a line's tests read, samples: the window of [`Columns`]. The flanks
/// end `max_half_width_px + flank_px` out, the half-maximum run's crossings and the narrow
/// line's retry `max_half_width_px + 3`, the least-squares Gaussian `2 * max_half_width_px`;
/// one more for margin. `a_peaks_tests_read_only_its_window` holds it to that.
fn window_reach(cfg: &EdgeConfig) -> usize {
    let hw = cfg.max_half_width_px as usize;
    let tests = hw + (cfg.flank_px as usize).max(3);
    let fit = if cfg.method == Method::Gaussian { 2 * hw } else { 0 };
    tests.max(fit) + 1
}

/// Where one detection searches: the image, its region and its signal.
struct Search<'a, 'b> {
    image: &'a ImageView<'b>,
    cfg: &'a EdgeConfig,
    /// The signal as bytes, one row of `inner.len()` per sample of `outer`: a colour image's
    /// channel for a vertical line (`None`: mono8 rows read in place, the float profiles of
    /// mono16, or a horizontal line's `columns`).
    plane: Option<&'a [u8]>,
    /// A horizontal line's row-major bytes (instead of `plane`).
    columns: Option<Columns<'a>>,
    /// Samples along the line (rows of a vertical line).
    outer: std::ops::Range<u32>,
    /// Positions across the line searched (columns of a vertical line).
    inner: std::ops::Range<u32>,
    vertical: bool,
    scale: f32,
    saturation: f32,
    /// The line's typical width in the last frames (pixels), once known: a row's candidate
    /// far wider is tried last (see [`WIDE_PEAK_TOLERANCE`]).
    typical_width: Option<f32>,
}

/// A row's candidate more than this many times the line's typical width (of the last frames)
/// is a glossy highlight or a bright blur sooner than the line: it is kept as a fallback, and
/// the row's other candidates are tried first. The hard body's highlights at 320x240 are 7-14
/// px wide against a line of about 2, brighter than the dim line on the hair beside them,
/// which was never tried. Well above what a line's own rows reach: on the body's curves at
/// 320x240 a run's rows are 1.4-4 px wide where the frame's typical width is under 2, and the
/// robot's real line, smeared by the camera's motion, 1.9 times its typical width. (2, 3 and 4
/// give the same hard report.)
const WIDE_PEAK_TOLERANCE: f32 = 4.0;

impl Search<'_, '_> {
    /// The line in sample `s`: the strongest peak that passes every test (up to
    /// `max_candidates` tried), or with `near = (centre, radius)` the strongest within `radius`
    /// of `centre` (absolute position across). Position is absolute.
    ///
    /// With `course` (a search on a run's course, `near` given), a narrow peak that fails the
    /// full tests may still pass [`course_peak`]'s.
    fn sample(&self, s: u32, near: Option<(f32, f32)>, course: bool, buf: &mut Scratch) -> Option<Peak> {
        let enc = self.image.encoding();
        let (x0, x1) = (self.inner.start as usize, self.inner.end as usize);
        let peak = if let Some(c) = &self.columns {
            self.column(c, (s - self.outer.start) as usize, near, course, buf)
        } else if let Some(plane) = self.plane {
            let (n, k) = (x1 - x0, (s - self.outer.start) as usize);
            self.locate(&plane[k * n..(k + 1) * n], near, course, &mut buf.contrast_u8)
        } else if self.vertical && enc == Encoding::Mono8 {
            self.locate(&self.image.row(s)[x0..x1], near, course, &mut buf.contrast_u8)
        } else {
            fill_profile(self.image, s, self.inner.clone(), self.vertical, self.cfg.channel, &mut buf.profile);
            self.locate(&buf.profile[..], near, course, &mut buf.contrast_f32)
        }?;
        let shift = |f| match f {
            Fit::Centre { centre, sigma } => Fit::Centre { centre: centre + x0 as f32, sigma },
            Fit::OneEdge { edge, z } => Fit::OneEdge { edge: edge + x0 as f32, z },
        };
        Some(Peak { pos: peak.pos + x0 as f32, fit: peak.fit.map(shift), ..peak })
    }

    /// The line in column `k` of `c` (position in the region), as [`Search::locate`] finds it
    /// in the whole column.
    fn column(
        &self,
        c: &Columns<'_>,
        k: usize,
        near: Option<(f32, f32)>,
        course: bool,
        buf: &mut Scratch,
    ) -> Option<Peak> {
        let n = c.rows;
        if near.is_none() && self.cfg.method != Method::Gradient {
            // The first candidate on its window: the column's other bytes are never read.
            let m = buf.column_at[k] as usize;
            let reach = window_reach(self.cfg);
            let (a, b) = (m.saturating_sub(reach), (m + reach + 1).min(n));
            let column = c.data[c.start + a * c.stride + k..].iter().step_by(c.stride);
            for (w, &v) in buf.window[a..b].iter_mut().zip(column) {
                *w = v;
            }
            if let Ok(peak) = find_peak(&buf.window[..n], m, self.cfg, self.scale, self.saturation) {
                return Some(peak);
            }
        }
        let strip = k / 16;
        if !buf.ready[strip] {
            let (k0, k1) = (16 * strip, (16 * strip + 16).min(c.cols));
            let rows = *c;
            plane::transpose_into(n, k1 - k0, |j| &rows.row(j)[k0..], &mut buf.strips[k0 * n..k1 * n]);
            buf.ready[strip] = true;
        }
        self.locate(&buf.strips[k * n..(k + 1) * n], near, course, &mut buf.contrast_u8)
    }

    /// For a candidate far wider than the line's typical width (`WIDE_PEAK_TOLERANCE`): the
    /// samples it spans, which the row's next search leaves out.
    fn too_wide(&self, peak: &Peak, n: usize) -> Option<(usize, usize)> {
        let t = self.typical_width?;
        (peak.width > WIDE_PEAK_TOLERANCE * t).then(|| {
            let reach = 0.5 * peak.width + 1.0;
            ((peak.pos - reach).max(0.0) as usize, ((peak.pos + reach) as usize).min(n.saturating_sub(1)))
        })
    }

    fn locate<S: Sample>(
        &self,
        p: &[S],
        near: Option<(f32, f32)>,
        course: bool,
        contrast: &mut Vec<S>,
    ) -> Option<Peak> {
        let cfg = self.cfg;
        if cfg.method == Method::Gradient {
            return gradient_edge(p, cfg.gradient_threshold * self.scale);
        }
        let off = self.inner.start as f32;
        if let Some((c, r)) = near {
            let (a, b) = ((c - off - r).max(0.0) as usize, ((c - off + r).max(0.0) as usize + 1).min(p.len()));
            let m = a + S::argmax(p.get(a..b)?)?;
            let peak = match (find_peak(p, m, cfg, self.scale, self.saturation), course) {
                (Ok(peak), _) => peak,
                (Err(_), false) => return None,
                (Err(_), true) => {
                    // The window's sample of highest peak contrast over the lowest samples within
                    // two (its brightest may be a brighter surface's edge beside the line).
                    let (a, b) = (a.max(3), b.min(p.len().saturating_sub(3)));
                    S::contrast(p.get(a - 2..b + 2)?, 2, contrast);
                    let m = a + S::argmax(contrast.get(2..(b + 2).checked_sub(a)?)?)?;
                    course_peak(p, m, cfg, self.scale).filter(|pk| (pk.pos + off - c).abs() <= COURSE_REACH_PX)?
                }
            };
            return ((peak.pos + off - c).abs() <= r).then_some(peak);
        }
        // Brightest first, then the sample of the highest peak contrast (a dim line in a dark
        // region beside brighter surfaces is not the row's brightest), then the brightest
        // again; a refused peak's run is left out of the next search. (A third try by contrast
        // found a textured ridge 32 rows long in a real laser-off photograph.)
        let mut refused: [(usize, usize); 16] = [(0, 0); 16];
        let mut fallback = None;
        for k in 0..cfg.max_candidates as usize {
            let m = if k == 1 {
                S::contrast(p, CONTRAST_OFFSET, contrast);
                argmax_outside(contrast, &refused[..k]).filter(|&m| contrast[m].f() > 0.0)
            } else {
                argmax_outside(p, &refused[..k])
            };
            let Some(m) = m else { continue };
            match find_peak(p, m, cfg, self.scale, self.saturation) {
                Ok(peak) => {
                    let wide = self.too_wide(&peak, p.len());
                    match peak.fallback.or(wide) {
                        None => return Some(peak),
                        Some(run) => {
                            // Kept for when no other candidate is a line; the next search goes
                            // on as after a refused peak. A candidate far wider than the line
                            // yields to a later fallback that is not.
                            refused[k] = run;
                            refused[..=k].sort_unstable();
                            if fallback.as_ref().is_none_or(|(_, w)| *w && wide.is_none()) {
                                fallback = Some((peak, wide.is_some()));
                            }
                        }
                    }
                }
                Err(run) => {
                    refused[k] = run;
                    refused[..=k].sort_unstable();
                }
            }
        }
        fallback.map(|(peak, _)| peak)
    }
}

/// A line near the last frame's continues it when at least this fraction of its strength.
const PREVIOUS_STRENGTH: f32 = 0.5;

/// A narrow peak is tried again with flanks right beside it when it stands this many times
/// `min_strength` above the samples two beyond its half-maximum run.
const NARROW_RETRY: f32 = 2.0;

/// A narrow line in a dark stripe between brighter surfaces is tried again when it stands this
/// many times `min_strength` above the samples two beyond its half-maximum run.
const STRIPE_RETRY: f32 = 1.5;

/// The flanks of a narrow line tried again start this many line widths (FWHM) from the peak.
const GAP_PER_WIDTH: f32 = 1.2;

/// A frame's line sets the typical width when it has at least this many samples.
const TYPICAL_WIDTH_SAMPLES: usize = 20;

/// How far either side of a sample its peak contrast looks, pixels.
const CONTRAST_OFFSET: usize = 3;

/// The detector's per-row scratch buffers.
#[derive(Debug, Default, Clone)]
struct Scratch {
    /// A row or column of the signal, as floats.
    profile: Vec<f32>,
    /// Peak contrast of a byte row.
    contrast_u8: Vec<u8>,
    /// Peak contrast of a float profile.
    contrast_f32: Vec<f32>,
    /// A column's bytes near its first candidate (the rest stale), as long as the column.
    window: Vec<u8>,
    /// Whole columns, transposed 16 at a time where needed (see [`Columns`]).
    strips: Vec<u8>,
    /// Which strips of 16 columns `strips` holds for this frame.
    ready: Vec<bool>,
    /// The columns' running maxima (see [`Columns`]).
    column_max: plane::ColumnMax,
    /// Each column's first maximum (row in the region).
    column_at: Vec<u32>,
    /// The laser's own channel around a found sample (see [`recentre_on_laser`]).
    raw: Vec<u8>,
}

impl Scratch {
    /// The buffers for reading `rows` by columns, and each column's first maximum.
    fn prepare_columns(&mut self, rows: &plane::Rows<'_>) {
        self.window.resize(rows.rows, 0);
        self.strips.resize(rows.rows * rows.cols, 0);
        self.ready.clear();
        self.ready.resize(rows.cols.div_ceil(16), false);
        self.column_at.resize(rows.cols, 0);
        plane::column_argmax(rows, &mut self.column_max, &mut self.column_at);
    }
}

/// The first maximum of `p` outside the sorted, possibly overlapping closed ranges `skip`.
fn argmax_outside<S: Sample>(p: &[S], skip: &[(usize, usize)]) -> Option<usize> {
    if skip.is_empty() {
        return S::argmax(p);
    }
    let mut best: Option<usize> = None;
    let mut start = 0;
    for &(a, b) in skip.iter().chain(std::iter::once(&(p.len(), p.len()))) {
        if a > start {
            if let Some(m) = S::argmax(&p[start..a.min(p.len())]) {
                let m = start + m;
                if best.is_none_or(|b| p[m] > p[b]) {
                    best = Some(m);
                }
            }
        }
        start = start.max(b + 1);
    }
    best
}

impl EdgeDetector {
    /// A detector with a validated configuration.
    pub fn new(config: EdgeConfig) -> Result<Self, EdgeError> {
        config.validate()?;
        Ok(Self { config, ..Default::default() })
    }

    /// The configuration in use.
    pub fn config(&self) -> &EdgeConfig {
        &self.config
    }

    /// Finds the line in `image`, writing one sample per row (or column) into `out`.
    ///
    /// Each row's strongest peak that passes the tests is taken; then runs of samples that
    /// follow each other (within `max_jump_px`) are extended into their neighbouring rows by a
    /// search near the run's own course (so a brighter highlight or a texture peak beside the
    /// line yields to the line), and runs shorter than `min_run` are dropped.
    pub fn detect(&mut self, image: &ImageView<'_>, out: &mut LaserLine) -> Result<DetectStats, EdgeError> {
        self.detect_with(image, out, None)
    }

    /// [`EdgeDetector::detect`], and where two surfaces put the line into one row, the other
    /// surface's line into `second` (the same shape as `out`, NaN elsewhere).
    ///
    /// Where an object hides part of the table, the object's line and the table's overlap by a
    /// few rows, and the first line holds one of them. Each run of the first line (at least
    /// `min_run` samples) is followed on beyond its ends into the rows another run holds, by a
    /// search near its own course (as the first line's runs are extended into free rows); what
    /// it finds there, at least twice the line's width from the first line's sample, is the
    /// second line. So a second sample is always the continuation of a line found in rows of
    /// its own, never a lone peak: a highlight or texture beside the line is not taken for a
    /// second surface. A frame without a first line has no second.
    pub fn detect_surfaces(
        &mut self,
        image: &ImageView<'_>,
        out: &mut LaserLine,
        second: &mut LaserLine,
    ) -> Result<DetectStats, EdgeError> {
        self.detect_with(image, out, Some(second))
    }

    fn detect_with(
        &mut self,
        image: &ImageView<'_>,
        out: &mut LaserLine,
        second: Option<&mut LaserLine>,
    ) -> Result<DetectStats, EdgeError> {
        let region = self.config.region(image)?;
        let vertical = self.config.line_orientation == Orientation::Vertical;
        let mut plane = std::mem::take(&mut self.plane);
        let signal = fill_plane(image, self.config.channel, vertical, region.clone(), &mut plane);
        let r = self.detect_in(image, region, signal, out, second);
        self.plane = plane;
        Ok(r)
    }

    /// The detection over `region` (columns, rows) of `image`, reading the signal from
    /// `signal`.
    fn detect_in(
        &mut self,
        image: &ImageView<'_>,
        (xs, ys): (std::ops::Range<u32>, std::ops::Range<u32>),
        signal: Signal<'_>,
        out: &mut LaserLine,
        second: Option<&mut LaserLine>,
    ) -> DetectStats {
        let cfg = &self.config;
        let (w, h) = (image.width(), image.height());
        let enc = image.encoding();
        let vertical = cfg.line_orientation == Orientation::Vertical;
        let samples = if vertical { h } else { w };
        out.reset(cfg.line_orientation, w, h, samples as usize, enc.is_color());
        let (outer, inner) = if vertical { (ys, xs) } else { (xs, ys) };
        let (plane, columns) = match signal {
            Signal::Image => (None, None),
            Signal::Plane(p) => (Some(p), None),
            Signal::Rows(rows) => {
                self.scratch.prepare_columns(&rows);
                (None, Some(rows))
            }
        };
        let (scale, saturation, typical_width) = (level_scale(enc), enc.max_value(), self.width_px);
        let search = Search { image, cfg, plane, columns, outer, inner, vertical, scale, saturation, typical_width };
        let mut stats = DetectStats::default();
        self.state.clear();
        self.state.resize(samples as usize, (false, None));
        let put = |out: &mut LaserLine, state: &mut [(bool, Option<Fit>)], s: u32, peak: Option<Peak>| {
            put_peak(out, state, s, peak, vertical, search.scale)
        };
        // The last frame's line, where it is of an image like this one.
        let previous = std::mem::take(&mut self.previous);
        let before = (previous.shape == (w, h, vertical) && cfg.method != Method::Gradient).then_some(&previous);
        for s in search.outer.clone() {
            stats.searched += 1;
            let mut peak = search.sample(s, None, false, &mut self.scratch);
            // Where a row holds several peaks, continuity with the last frame chooses: the
            // strongest candidate stands only if no line continues the last frame's there (as
            // near as `max_jump_px`, at least half as strong: a highlight or a texture peak does
            // not displace the line, nor a texture peak where the line was the line that moved
            // on; a line that moved further is found as before).
            if let Some(b) = before {
                let q = b.across[s as usize];
                if q.is_finite() && peak.as_ref().is_none_or(|p| (p.pos - q).abs() > cfg.max_jump_px) {
                    peak = continue_last(&search, s, (q, b.strength[s as usize]), peak, &mut self.scratch);
                }
            }
            put(out, &mut self.state, s, peak);
        }
        if cfg.method != Method::Gradient {
            let profile = &mut self.scratch;
            let state = &mut self.state;
            track::extend(out, cfg, search.outer.clone(), |out, s, near, held| {
                // A search that finds nothing near this run's course leaves the sample as it was.
                // A narrow peak that only the course's tests pass fills an empty sample or one of
                // a run too short to stand (never a real line's shorter run beside this one).
                let course = held < cfg.min_run;
                let peak = search.sample(s, Some(near), course, profile);
                let found = peak.is_some();
                if found {
                    put(out, state, s, peak);
                }
                found
            });
            stats.short_runs = track::drop_short_runs(out, cfg, search.outer.clone(), self.width_px, &mut self.widths);
            if let Some(w) = track::typical_width(out, TYPICAL_WIDTH_SAMPLES, &mut self.widths) {
                self.width_px = Some(w);
            }
        }
        resolve_one_edge_fits(&self.state, &mut self.sigma_px, out);
        let lane = laser_lane(cfg.channel, enc);
        let span = (search.inner.clone(), search.outer.clone());
        if let Some(lane) = lane {
            recentre_on_laser(image, cfg, span.clone(), lane, &mut self.scratch.raw, out);
        }
        (stats.found, stats.saturated) = finish(image, cfg, &self.state, search.outer.clone(), out);
        self.previous = previous.remember(out, (w, h, vertical));
        let Some(second) = second else { return stats };
        second.reset(cfg.line_orientation, w, h, samples as usize, enc.is_color());
        if cfg.method == Method::Gradient {
            return stats;
        }
        let mut state = std::mem::take(&mut self.second_state);
        state.clear();
        state.resize(samples as usize, (false, None));
        second_line(&search, &mut self.scratch, out, second, &mut state);
        resolve_one_edge_fits(&state, &mut self.sigma_px, second);
        if let Some(lane) = lane {
            recentre_on_laser(image, cfg, span, lane, &mut self.scratch.raw, second);
        }
        stats.second = finish(image, cfg, &state, search.outer.clone(), second).0;
        self.second_state = state;
        stats
    }
}

/// Sample `s`'s line where the last frame's (centre `q` across, `strength` in 8-bit grey
/// levels) is not `peak`'s: the line found within `max_jump_px` of `q`, if it is at least
/// `PREVIOUS_STRENGTH` as strong and not a fallback; else `peak`. Out of the per-row loop: it
/// runs only where the line moved or a row's peaks disagree.
#[cold]
#[inline(never)]
fn continue_last(
    search: &Search<'_, '_>,
    s: u32,
    (q, strength): (f32, f32),
    peak: Option<Peak>,
    scratch: &mut Scratch,
) -> Option<Peak> {
    let continues = |p: &Peak| p.fallback.is_none() && p.strength >= PREVIOUS_STRENGTH * strength * search.scale;
    search.sample(s, Some((q, search.cfg.max_jump_px)), false, scratch).filter(continues).or(peak)
}

/// The second surfaces' samples beside `first` (see [`EdgeDetector::detect_surfaces`]),
/// written into `second`, their saturation and fits into `state`.
fn second_line(
    search: &Search<'_, '_>,
    scratch: &mut Scratch,
    first: &LaserLine,
    second: &mut LaserLine,
    state: &mut [(bool, Option<Fit>)],
) {
    let vertical = search.vertical;
    track::second_surfaces(first, search.cfg, search.outer.clone(), |s, near, held| {
        if second.u[s as usize].is_finite() {
            return track::Probe::Taken;
        }
        let Some(peak) = search.sample(s, Some(near), false, scratch) else { return track::Probe::Missed };
        // Two lines closer than twice their widths are one line, or a line and its halo.
        let apart = 2.0 * peak.width.max(first.width[s as usize]).max(1.0);
        if (peak.pos - held).abs() < apart {
            return track::Probe::Missed;
        }
        let pos = peak.pos;
        put_peak(second, state, s, Some(peak), vertical, search.scale);
        track::Probe::Found(pos)
    });
}

/// The lines of several lasers in one image, each in its own channel (the laser's colour
/// against the others): one detector per laser, with the same orientation and region, and the
/// channels of a colour frame extracted in one pass over its 3-byte pixels.
#[derive(Debug, Default, Clone)]
pub struct LaserDetectors {
    detectors: Vec<EdgeDetector>,
    /// Every laser's signal, one plane after the other (`w * h` bytes each), row-major.
    colour: Vec<u8>,
    /// Each laser's second surfaces' line too ([`EdgeDetector::detect_surfaces`]).
    second_surfaces: bool,
}

impl LaserDetectors {
    /// One detector per configuration; they must agree on everything but the channel.
    pub fn new(configs: Vec<EdgeConfig>) -> Result<Self, EdgeError> {
        let mut detectors = Vec::with_capacity(configs.len());
        for c in configs {
            if let Some(first) = detectors.first().map(|d: &EdgeDetector| d.config()) {
                if (EdgeConfig { channel: first.channel, ..c }) != *first {
                    return Err(EdgeError::InvalidConfig {
                        name: "channel",
                        reason: "the lasers' detectors differ in more than their channel".into(),
                    });
                }
            }
            detectors.push(EdgeDetector::new(c)?);
        }
        Ok(Self { detectors, ..Default::default() })
    }

    /// The same detectors, keeping each laser's second surfaces' line as well (`true`,
    /// [`EdgeDetector::detect_surfaces`]) or not.
    pub fn with_second_surfaces(self, second_surfaces: bool) -> Self {
        Self { second_surfaces, ..self }
    }

    /// Lines per laser that [`LaserDetectors::detect`] writes: 2 with the second surfaces, else 1.
    pub fn layers(&self) -> usize {
        1 + usize::from(self.second_surfaces)
    }

    /// Finds each laser's line in `image`, laser `k`'s into `outs[k]` (`outs` is resized to
    /// the lasers, times [`LaserDetectors::layers`]). With the second surfaces, laser `k`'s
    /// second line goes into `outs[n + k]` (`n` lasers): layer-major, as a `LaserLine` message
    /// carries them. One laser is found as [`EdgeDetector::detect`] (or `detect_surfaces`)
    /// finds it, in any encoding; several need a colour image.
    pub fn detect(&mut self, image: &ImageView<'_>, outs: &mut Vec<LaserLine>) -> Result<Vec<DetectStats>, EdgeError> {
        let n = self.detectors.len();
        outs.resize_with(n * self.layers(), LaserLine::default);
        let (firsts, seconds) = outs.split_at_mut(n);
        self.detect_layers(image, firsts, seconds)
    }

    /// [`LaserDetectors::detect`] into the first lines `outs` and, where `seconds` holds one
    /// per laser, the second lines.
    fn detect_layers(
        &mut self,
        image: &ImageView<'_>,
        outs: &mut [LaserLine],
        seconds: &mut [LaserLine],
    ) -> Result<Vec<DetectStats>, EdgeError> {
        let n = self.detectors.len();
        if n == 1 {
            let d = &mut self.detectors[0];
            return Ok(vec![match seconds.first_mut() {
                Some(second) => d.detect_surfaces(image, &mut outs[0], second)?,
                None => d.detect(image, &mut outs[0])?,
            }]);
        }
        let enc = image.encoding();
        if !enc.is_color() {
            return Err(EdgeError::GreyWithLasers { encoding: enc.ros_name(), lasers: n });
        }
        let Some(cfg) = self.detectors.first().map(|d| d.config().clone()) else { return Ok(Vec::new()) };
        let (xs, ys) = cfg.region(image)?;
        let (x0, w, y0, h) = (xs.start as usize, xs.len(), ys.start as usize, ys.len());
        let channels: Vec<Channel> = self.detectors.iter().map(|d| d.config().channel).collect();
        let plane = w * h;
        // Every byte is written below: the buffer is only sized, not cleared.
        self.colour.resize(n * plane, 0);
        let rgb = enc == Encoding::Rgb8;
        for j in 0..h {
            let row = &image.row((y0 + j) as u32)[3 * x0..];
            plane::channel_rows(row, w, rgb, &channels, &mut self.colour[j * w..], plane);
        }
        let vertical = cfg.line_orientation == Orientation::Vertical;
        let mut stats = Vec::with_capacity(n);
        for (k, (d, out)) in self.detectors.iter_mut().zip(outs.iter_mut()).enumerate() {
            let bytes = &self.colour[k * plane..(k + 1) * plane];
            let signal = if vertical {
                Signal::Plane(bytes)
            } else {
                Signal::Rows(plane::Rows { data: bytes, start: 0, stride: w, rows: h, cols: w })
            };
            stats.push(d.detect_in(image, (xs.clone(), ys.clone()), signal, out, seconds.get_mut(k)));
        }
        Ok(stats)
    }
}

/// Where the detector reads `image`'s signal, with the bytes it needs in `plane`: a colour
/// image's channel extracted, row-major (read by rows for a vertical line, by columns for a
/// horizontal one). A mono8 image is read in place, by rows or by columns; mono16 as floats.
fn fill_plane<'a>(
    image: &ImageView<'a>,
    channel: Channel,
    vertical: bool,
    (xs, ys): (std::ops::Range<u32>, std::ops::Range<u32>),
    plane: &'a mut Plane,
) -> Signal<'a> {
    let (x0, w) = (xs.start as usize, xs.len());
    let (y0, h) = (ys.start as usize, ys.len());
    match image.encoding() {
        Encoding::Mono8 if vertical => Signal::Image,
        Encoding::Mono8 => {
            let step = image.step();
            Signal::Rows(plane::Rows { data: image.data(), start: y0 * step + x0, stride: step, rows: h, cols: w })
        }
        enc @ (Encoding::Rgb8 | Encoding::Bgr8) => {
            let rgb = enc == Encoding::Rgb8;
            // Every byte is written below: the buffer is only sized, not cleared.
            plane.bytes.resize(w * h, 0);
            for (j, out) in plane.bytes.chunks_exact_mut(w.max(1)).enumerate().take(h) {
                plane::channel_row(&image.row((y0 + j) as u32)[3 * x0..], rgb, channel, out);
            }
            let bytes = &plane.bytes[..];
            if vertical {
                Signal::Plane(bytes)
            } else {
                Signal::Rows(plane::Rows { data: bytes, start: 0, stride: w, rows: h, cols: w })
            }
        }
        Encoding::Mono16 => Signal::Image,
    }
}

/// The byte of a colour pixel that holds the laser's own colour, where the detector reads the
/// laser's colour against the others (`None` otherwise).
fn laser_lane(channel: Channel, encoding: Encoding) -> Option<usize> {
    let rgb = match encoding {
        Encoding::Rgb8 => true,
        Encoding::Bgr8 => false,
        _ => return None,
    };
    match channel {
        Channel::RedMinusOthers => Some(if rgb { 0 } else { 2 }),
        Channel::GreenMinusOthers => Some(1),
        Channel::BlueMinusOthers => Some(if rgb { 2 } else { 0 }),
        _ => None,
    }
}

/// A sample placed on the laser's own channel agrees with its place on the colour against the
/// others within this many pixels, or keeps the latter (a looser agreement, half the line's
/// width, let highlights beside the line move it: on the hard pyramid at 320x240 in colour,
/// cam1's points beyond 5 mm went from 0.003 to 0.11 %).
const RECENTRE_AGREEMENT_PX: f32 = 0.5;

/// A saturated line narrower than this (FWHM on the laser's own channel, pixels) keeps its
/// place on the colour against the others: its clipped top is a pixel or two, whose centre of
/// gravity locks to the pixels.
const RECENTRE_MIN_WIDTH_PX: f32 = 2.0;

/// Places again, on the laser's own channel (byte `lane` of each pixel), every sample found
/// where that channel is saturated.
///
/// The laser's colour against the others (red minus the mean of green and blue) is what tells
/// the line from white light, highlights and room light, and the line is found and judged on
/// it. But it hides saturation: where the laser's channel clips at the top of its range, the
/// difference is a flat top below it that no test takes for saturated, and the narrow line's
/// fit, which assumes a Gaussian's top, is pulled by the clipped samples and by the other
/// channels' noise on them. On the laser's own channel the clipping is seen, and the centre is
/// found as for any saturated line. So a sample whose laser channel reaches the top of the
/// range at its peak is found again by the same tests on that channel, in the window around it
/// that the tests read, and placed there where it passes them as a saturated line at least
/// [`RECENTRE_MIN_WIDTH_PX`] wide and agrees with the first place within
/// [`RECENTRE_AGREEMENT_PX`]; otherwise it stays where the colour against the others put it.
fn recentre_on_laser(
    image: &ImageView<'_>,
    cfg: &EdgeConfig,
    (inner, outer): (std::ops::Range<u32>, std::ops::Range<u32>),
    lane: usize,
    buf: &mut Vec<u8>,
    out: &mut LaserLine,
) {
    let vertical = cfg.line_orientation == Orientation::Vertical;
    let reach = window_reach(cfg);
    let (lo, hi) = (inner.start as usize, inner.end as usize);
    let top = image.encoding().max_value();
    let saturation = top as u8;
    for s in outer {
        let i = s as usize;
        let across = if vertical { out.u[i] } else { out.v[i] };
        if !across.is_finite() || across < 0.0 {
            continue;
        }
        let m0 = across.round() as usize;
        let (a, b) = (m0.saturating_sub(reach).max(lo), (m0 + reach + 1).min(hi));
        if !(a..b).contains(&m0) {
            continue;
        }
        // A vertical line's sample is a row; a horizontal line's a column, read across the rows.
        let row = if vertical { image.row(s) } else { &[] };
        let at = |k: usize| if vertical { row[3 * k + lane] } else { image.row(k as u32)[3 * i + lane] };
        let near = m0.saturating_sub(1).max(a)..(m0 + 2).min(b);
        if !near.clone().any(|k| at(k) >= saturation) {
            continue;
        }
        buf.clear();
        buf.extend((a..b).map(at));
        let Some(m) = u8::argmax(&buf[near.start - a..near.end - a]).map(|k| near.start - a + k) else { continue };
        let Ok(peak) = find_peak(buf, m, cfg, 1.0, top) else { continue };
        let pos = a as f32 + peak.pos;
        if peak.saturated && peak.width >= RECENTRE_MIN_WIDTH_PX && (pos - across).abs() <= RECENTRE_AGREEMENT_PX {
            if vertical {
                out.u[i] = pos;
            } else {
                out.v[i] = pos;
            }
        }
    }
}

/// The detector's byte signal of a frame (see [`fill_plane`]).
#[derive(Debug, Default, Clone)]
struct Plane {
    /// A colour image's channel over the region, row-major.
    bytes: Vec<u8>,
}

/// Writes `peak` (or no line) into sample `s` of `out`, and its saturation and fit into
/// `state`.
fn put_peak(
    out: &mut LaserLine,
    state: &mut [(bool, Option<Fit>)],
    s: u32,
    peak: Option<Peak>,
    vertical: bool,
    scale: f32,
) {
    let i = s as usize;
    let Some(peak) = peak else {
        out.clear(i);
        return;
    };
    let (u, v) = if vertical { (peak.pos, s as f32) } else { (s as f32, peak.pos) };
    out.u[i] = u;
    out.v[i] = v;
    out.strength[i] = peak.strength / scale;
    out.width[i] = peak.width;
    state[i] = (peak.saturated, peak.fit);
}

/// The found samples' colour beside the line (colour images); returns how many samples were
/// found, and how many of them saturated.
fn finish(
    image: &ImageView<'_>,
    cfg: &EdgeConfig,
    state: &[(bool, Option<Fit>)],
    outer: std::ops::Range<u32>,
    out: &mut LaserLine,
) -> (u32, u32) {
    let vertical = cfg.line_orientation == Orientation::Vertical;
    let (mut found, mut saturated) = (0, 0);
    for s in outer {
        let i = s as usize;
        if !out.u[i].is_finite() {
            continue;
        }
        found += 1;
        saturated += u32::from(state[i].0);
        if image.encoding().is_color() {
            let c = side_colour(image, out.u[i], out.v[i], vertical, cfg.color_offset_px);
            out.rgb[3 * i..3 * i + 3].copy_from_slice(&c);
        }
    }
    (found, saturated)
}

/// Places the narrow-line samples that had one usable edge, with the mean sigma of this frame's
/// other narrow-line fits (or of the last frame that had any, `sigma_px`).
fn resolve_one_edge_fits(state: &[(bool, Option<Fit>)], sigma_px: &mut Option<f32>, out: &mut LaserLine) {
    let (mut sum, mut n, mut pending) = (0.0f32, 0u32, false);
    for (i, (_, fit)) in state.iter().enumerate() {
        match fit {
            Some(Fit::Centre { sigma, .. }) if out.u[i].is_finite() => {
                sum += sigma;
                n += 1;
            }
            Some(Fit::OneEdge { .. }) => pending = true,
            _ => {}
        }
    }
    if n > 0 {
        *sigma_px = Some(sum / n as f32);
    }
    let Some(sigma) = sigma_px.filter(|_| pending) else { return };
    for (i, (_, fit)) in state.iter().enumerate() {
        let Some(Fit::OneEdge { edge, z }) = *fit else { continue };
        let centre = edge - z * sigma;
        let slot = if out.orientation == Orientation::Vertical { &mut out.u[i] } else { &mut out.v[i] };
        // Within the pixel that the centre of gravity found, or the fit does not apply.
        if slot.is_finite() && (centre - *slot).abs() <= 0.5 {
            *slot = centre;
        }
    }
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
                channel.of(f32::from(r), f32::from(g), f32::from(b))
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

/// A mono8 image transposed: its rows become columns (a vertical line becomes horizontal).
#[cfg(test)]
fn transposed(img: &crate::image::Image) -> crate::image::Image {
    let (w, h) = (img.width as usize, img.height as usize);
    let mut t = crate::image::Image::new(img.height, img.width, Encoding::Mono8);
    for y in 0..h {
        for x in 0..w {
            t.data[x * h + y] = img.data[y * w + x];
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::lanes::{walk_left, walk_right};
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
            let a = u8::argmax(&row).and_then(|m| find_peak(&row, m, &cfg, 1.0, 255.0).ok());
            let b = f32::argmax(&float).and_then(|m| find_peak(&float, m, &cfg, 1.0, 255.0).ok());
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

    proptest::proptest! {
        /// A peak's tests read nothing beyond `window_reach` of it: the window alone, its
        /// outside dark or bright, gives the whole profile's answer, bit for bit, for lines
        /// narrow and wide, beside steps, in any method and with any reach of the tests.
        #[test]
        fn a_peaks_tests_read_only_its_window(
            n in 8usize..160,
            c in 0.0f64..1.0,
            sigma in 0.3f64..8.0,
            amp in 0.0f64..260.0,
            bg in 0.0f64..80.0,
            step in (0usize..160, -60.0f64..60.0),
            noise in proptest::collection::vec(-12i32..12, 160),
            method in 0usize..3,
            max_hw in 1u32..30,
            flank in 1u32..30,
        ) {
            let c = c * n as f64;
            let p: Vec<u8> = (0..n)
                .map(|i| {
                    let d = (i as f64 - c) / sigma;
                    let s = if i >= step.0 { step.1 } else { 0.0 };
                    (bg + s + amp * (-0.5 * d * d).exp() + f64::from(noise[i])).round().clamp(0.0, 255.0) as u8
                })
                .collect();
            let method = [Method::CenterOfGravity, Method::Gaussian, Method::Parabolic][method];
            let cfg = EdgeConfig { method, max_half_width_px: max_hw, flank_px: flank, ..Default::default() };
            let m = u8::argmax(&p).unwrap();
            let reach = window_reach(&cfg);
            let whole = find_peak(&p, m, &cfg, 1.0, 255.0);
            for poison in [0u8, 255] {
                let mut w = vec![poison; n];
                let (a, b) = (m.saturating_sub(reach), (m + reach + 1).min(n));
                w[a..b].copy_from_slice(&p[a..b]);
                let part = find_peak(&w, m, &cfg, 1.0, 255.0);
                let bits = |r: &Result<Peak, (usize, usize)>| {
                    r.as_ref().map(|k| (k.pos.to_bits(), k.width.to_bits(), k.strength.to_bits())).map_err(|_| ())
                };
                proptest::prop_assert_eq!(bits(&part), bits(&whole), "{:?} m {} poison {}", p, m, poison);
            }
        }
    }

    /// Every encoding and orientation reaches the same byte path: a frame's columns (the frame
    /// transposed, its line horizontal) and its colour versions (the frame in the red channel,
    /// red first or blue first) give the mono8 rows' samples bit for bit, with and without a
    /// region of interest.
    #[test]
    fn columns_and_colour_give_the_rows_samples_exactly() {
        use crate::rig::Rig;
        use crate::synth::{LaserModel, ScanSettings, Scanner, Scene};
        let settings = ScanSettings { encoding: Encoding::Mono8, ..Default::default() };
        let s = Scanner::new(Scene::by_name("phantom").unwrap(), Rig::study(320, 240), LaserModel::default(), settings)
            .unwrap();
        let img = s.render(0, s.frame_count() / 2);
        let t = transposed(&img);
        let colour = |enc: Encoding, src: &Image| {
            let mut c = Image::new(src.width, src.height, enc);
            let r = if enc == Encoding::Rgb8 { 0 } else { 2 };
            for (i, &v) in src.data.iter().enumerate() {
                c.data[3 * i + r] = v;
            }
            c
        };
        let roi = Roi { x_offset: 37, y_offset: 21, width: 201, height: 150 };
        let swapped = Roi { x_offset: roi.y_offset, y_offset: roi.x_offset, width: roi.height, height: roi.width };
        for (rows_roi, cols_roi) in [(Roi::default(), Roi::default()), (roi, swapped)] {
            let rows = detect(&img, EdgeConfig { roi: rows_roi, ..Default::default() });
            assert!(rows.found() > 100, "{}", rows.found());
            let horizontal =
                EdgeConfig { line_orientation: Orientation::Horizontal, roi: cols_roi, ..Default::default() };
            let cols = detect(&t, horizontal.clone());
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let same = |a: &LaserLine, b: &LaserLine, swap: bool| {
                let (u, v) = if swap { (&b.v, &b.u) } else { (&b.u, &b.v) };
                (bits(&a.u), bits(&a.v), bits(&a.strength), bits(&a.width))
                    == (bits(u), bits(v), bits(&b.strength), bits(&b.width))
            };
            assert!(same(&cols, &rows, true), "columns: u and v swap");
            for enc in [Encoding::Rgb8, Encoding::Bgr8] {
                for channel in [Channel::Red, Channel::RedMinusOthers] {
                    let c = detect(&colour(enc, &img), EdgeConfig { roi: rows_roi, channel, ..Default::default() });
                    assert!(same(&c, &rows, false), "{enc:?} {channel:?}");
                    let c = detect(&colour(enc, &t), EdgeConfig { channel, ..horizontal.clone() });
                    assert!(same(&c, &rows, true), "{enc:?} {channel:?} columns");
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

    /// For each of the first `rows` rows of `out` with a line, its centre minus `centre(row)`.
    fn row_errors(out: &LaserLine, rows: u32, centre: impl Fn(u32) -> f64) -> Vec<f64> {
        (0..rows).filter_map(|y| Some(f64::from(out.u[y as usize]) - centre(y)).filter(|e| e.is_finite())).collect()
    }

    /// The root mean square of `errs`.
    fn rms(errs: &[f64]) -> f64 {
        (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt()
    }

    /// The line of `img` found by a detector that saw `before` first (the line's width in the
    /// last frames, and the last frame's line).
    fn detect_after(before: &Image, img: &Image, cfg: EdgeConfig) -> LaserLine {
        let mut d = EdgeDetector::new(cfg).unwrap();
        let mut out = LaserLine::default();
        d.detect(&before.view().unwrap(), &mut out).unwrap();
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
                let img = line_image(64, 16, c, 1.6, 200.0, 20.0);
                let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
                let err = (f64::from(out.u[0]) - c).abs();
                assert!(err < 0.05, "{m:?} at {c}: found {} (err {err})", out.u[0]);
                let fwhm = 2.3548 * 1.6;
                assert!((f64::from(out.width[0]) - fwhm).abs() < 0.3, "{m:?} width {}", out.width[0]);
                assert!((out.strength[0] - 200.0).abs() < 15.0, "strength {}", out.strength[0]);
            }
        }
    }

    /// The narrowest reach a configuration allows, with the least-squares Gaussian: the fit's
    /// window was clamped to at least 4 samples and at most `2 * max_half_width_px` (2 here),
    /// which panicked.
    #[test]
    fn gaussian_with_the_least_half_width_does_not_panic() {
        // Saturated, so that it is not a narrow line's pixel-integrated fit.
        let img = line_image(64, 16, 30.3, 0.5, 400.0, 40.0);
        let cfg = EdgeConfig { method: Method::Gaussian, max_half_width_px: 1, ..Default::default() };
        let out = detect(&img, cfg);
        assert!(out.found() > 0 && (out.u[0] - 30.3).abs() < 0.3, "{:?}", &out.u[..4]);
    }

    #[test]
    fn gradient_method_is_integer_and_on_the_rising_edge() {
        let img = line_image(64, 8, 30.37, 1.6, 200.0, 20.0);
        let out = detect(&img, EdgeConfig { method: Method::Gradient, ..Default::default() });
        let u = out.u[0];
        assert_eq!(u, u.round());
        assert!((25.0..30.37).contains(&u), "{u}");
    }

    #[test]
    fn saturated_line_is_centred() {
        let img = line_image(64, 16, 40.3, 2.0, 600.0, 10.0);
        assert!(img.data.iter().filter(|&&v| v == 255).count() > 2);
        for m in [Method::CenterOfGravity, Method::Gaussian, Method::Parabolic] {
            let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
            assert!((out.u[0] - 40.3).abs() < 0.05, "{m:?}: {}", out.u[0]);
        }
    }

    #[test]
    fn strongest_of_two_peaks_is_chosen() {
        let a = line_image(100, 8, 25.2, 1.5, 90.0, 10.0);
        let b = line_image(100, 8, 70.6, 1.5, 180.0, 0.0);
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
        let mut img = line_image(200, 8, 120.4, 1.5, 25.0, 40.0);
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
        let img = line_image(32, 40, 17.25, 1.5, 200.0, 0.0);
        // Transpose into a horizontal line at row 17.25.
        let mut t = Image::new(40, 32, Encoding::Mono8);
        for y in 0..40u32 {
            for x in 0..32u32 {
                t.data[(x * 40 + y) as usize] = img.data[(y * 32 + x) as usize];
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
        assert!((out.v[7] - 17.25).abs() < 0.05 && out.u[7] == 7.0);
    }

    #[test]
    fn colour_channels_and_side_colour() {
        let grey = line_image(80, 8, 40.0, 1.5, 150.0, 0.0);
        let mut img = Image::new(80, 8, Encoding::Bgr8);
        for (i, &g) in grey.data.iter().enumerate() {
            // A white-ish surface (B=G=R=90) with a red laser on top.
            img.data[3 * i] = 90;
            img.data[3 * i + 1] = 90;
            img.data[3 * i + 2] = 90u8.saturating_add(g);
        }
        for ch in [Channel::Red, Channel::Luma, Channel::RedMinusOthers] {
            let out = detect(&img, EdgeConfig { channel: ch, ..Default::default() });
            assert!((out.u[0] - 40.0).abs() < 0.05, "{ch:?} {}", out.u[0]);
            assert_eq!(&out.rgb[..3], &[90, 90, 90]);
        }
    }

    #[test]
    fn saturated_line_in_colour_is_placed_on_the_lasers_channel() {
        // A red laser that clips the red channel at 255 on a grey surface under room light
        // (70 in each channel; a tenth of the laser's light in green and blue, as a camera's
        // filters pass it), 2.5 px wide, with noise in each channel: red minus the others sees
        // a flat top below 255 and no saturation.
        let top = box_line(-0.5, 0.5, 0.0, 2.5);
        let centre = |along: u32| 60.0 + 0.0513 * f64::from(along);
        let (n, across) = (60u32, 120u32);
        // A vertical line (one sample per row) and the same line lying horizontally (one sample
        // per column, read by columns from the rows).
        for (rgb, vertical) in [(true, true), (false, true), (true, false), (false, false)] {
            let (w, h) = if vertical { (across, n) } else { (n, across) };
            let mut img = Image::new(w, h, if rgb { Encoding::Rgb8 } else { Encoding::Bgr8 });
            let mut rng = crate::synth::SplitMix::new(41);
            for y in 0..h {
                for x in 0..w {
                    let (s, a) = if vertical { (y, x) } else { (x, y) };
                    let laser = 400.0 * box_line(f64::from(a) - 0.5, f64::from(a) + 0.5, centre(s), 2.5) / top;
                    let px = 3 * (y * w + x) as usize;
                    let mut put = |k: usize, v: f64| {
                        img.data[px + k] = (v + 2.0 * rng.normal()).round().clamp(0.0, 255.0) as u8;
                    };
                    let (r, g, b) = (70.0 + laser, 70.0 + 0.1 * laser, 70.0 + 0.1 * laser);
                    put(0, if rgb { r } else { b });
                    put(1, g);
                    put(2, if rgb { b } else { r });
                }
            }
            assert!(img.data.iter().filter(|&&v| v == 255).count() > 2 * n as usize, "the red channel clips");
            let line_orientation = if vertical { Orientation::Vertical } else { Orientation::Horizontal };
            // The parabolic method is left out: on the flat top of red minus the others it is
            // 0.8 px off, further than the laser's channel is let move a sample.
            for m in [Method::CenterOfGravity, Method::Gaussian] {
                let out = detect(&img, EdgeConfig { method: m, line_orientation, ..Default::default() });
                let errs: Vec<f64> = (0..n)
                    .map(|s| f64::from(if vertical { out.u[s as usize] } else { out.v[s as usize] }) - centre(s))
                    .filter(|e| e.is_finite())
                    .collect();
                let what = format!("{m:?}, {}, {}", if rgb { "rgb8" } else { "bgr8" }, line_orientation.name());
                assert_eq!(errs.len(), n as usize, "{what}: every sample found");
                let rms = rms(&errs);
                let bias = errs.iter().sum::<f64>() / errs.len() as f64;
                // The vertical line placed on red minus the others: rms 0.031-0.035 px (centre
                // of gravity) and 0.049-0.053 px (Gaussian); on the red channel 0.027-0.030 and
                // 0.024-0.026.
                assert!(rms < 0.03 && bias.abs() < 0.01, "{what}: rms {rms:.4} px, bias {bias:+.4} px");
            }
        }
    }

    #[test]
    fn mono16_scaled_thresholds() {
        let g = line_image(64, 8, 20.6, 1.5, 200.0, 10.0);
        let mut img = Image::new(64, 8, Encoding::Mono16);
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

    /// A mono8 row image (`h` rows) from a function of the column's left and right pixel edges.
    fn image_from(w: u32, h: u32, f: impl Fn(u32, f64, f64) -> f64) -> Image {
        let mut img = Image::new(w, h, Encoding::Mono8);
        for y in 0..h {
            for x in 0..w {
                let v = f(y, x as f64 - 0.5, x as f64 + 0.5);
                img.data[(y * w + x) as usize] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
        img
    }

    /// The share of a Gaussian line's light (centre `c`, FWHM `fwhm`) that falls on the pixel
    /// [a, b]: the box-integrated Gaussian, by Simpson's rule on 400 intervals.
    fn box_line(a: f64, b: f64, c: f64, fwhm: f64) -> f64 {
        let s = fwhm / 2.354_820_045;
        let n = 400;
        let h = (b - a) / n as f64;
        let g = |x: f64| (-0.5 * ((x - c) / s).powi(2)).exp() / (s * (2.0 * std::f64::consts::PI).sqrt());
        let mut acc = 0.0;
        for i in 0..=n {
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            acc += w * g(a + i as f64 * h);
        }
        acc * h / 3.0
    }

    /// Largest error of each method over 20 sub-pixel phases of an 8-bit line (amplitude 200
    /// over a background of 20, no noise), for FWHM `fwhm` px (before the pixels integrate it).
    fn phase_bias(method: Method, fwhm: f64) -> f64 {
        let mut worst = 0.0f64;
        // Row k holds phase k / 20: the line crosses the rows at a slant, as a real one does.
        let centre = |k: u32| 40.0 + f64::from(k) / 20.0;
        // 200 grey levels on the pixel that a centred line would light most.
        let top = box_line(-0.5, 0.5, 0.0, fwhm);
        let img = image_from(80, 20, |y, a, b| 20.0 + 200.0 * box_line(a, b, centre(y), fwhm) / top);
        let out = detect(&img, EdgeConfig { method, ..Default::default() });
        for k in 0..20 {
            let u = f64::from(out.u[k as usize]);
            worst = worst.max(if u.is_finite() { (u - centre(k)).abs() } else { f64::INFINITY });
        }
        worst
    }

    #[test]
    fn no_pixel_locking_for_lines_half_a_pixel_to_three_wide() {
        let mut failed = Vec::new();
        for fwhm in [0.5, 1.0, 1.5, 2.0, 3.0, 4.0] {
            let mut line = format!("FWHM {fwhm} px, largest error over 20 phases:");
            for m in [Method::CenterOfGravity, Method::Gaussian, Method::Parabolic, Method::Gradient] {
                let b = phase_bias(m, fwhm);
                line += &format!(" {} {b:.4}", m.name());
                if m != Method::Gradient && b > 0.03 {
                    failed.push(format!("{m:?} at FWHM {fwhm} px: error up to {b:.4} px"));
                }
            }
            eprintln!("{line}");
        }
        assert!(failed.is_empty(), "{failed:#?}");
    }

    /// Adds zero-mean pseudo-random noise of standard deviation `sd` to every pixel.
    fn add_noise(img: &mut Image, sd: f64, seed: u64) {
        let mut rng = crate::synth::SplitMix::new(seed);
        for d in img.data.iter_mut() {
            *d = (f64::from(*d) + sd * rng.normal()).round().clamp(0.0, 255.0) as u8;
        }
    }

    const SUBPIXEL_METHODS: [Method; 3] = [Method::CenterOfGravity, Method::Gaussian, Method::Parabolic];

    #[test]
    fn step_edge_is_not_a_line() {
        // A bright object's edge against a darker background, blurred, with and without the
        // overshoot that sharpening or JPEG leaves; and a bright band wider than any line.
        let smooth = |x: f64| 1.0 / (1.0 + (-x / 0.8).exp());
        let step = image_from(120, 30, |_, a, _| 40.0 + 160.0 * smooth(a + 0.5 - 60.3));
        let ringing = image_from(120, 30, |_, a, _| {
            let x = a + 0.5 - 60.3;
            40.0 + 160.0 * smooth(x) + 18.0 * (-(x - 1.5).powi(2) / 2.0).exp()
        });
        let band = image_from(120, 30, |_, a, _| if (40.0..80.0).contains(&(a + 0.5)) { 190.0 } else { 40.0 });
        for (name, mut img) in [("step", step), ("ringing step", ringing), ("wide band", band)] {
            add_noise(&mut img, 1.5, 3);
            for m in SUBPIXEL_METHODS {
                let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
                assert_eq!(out.found(), 0, "{name}, {m:?}: {:?}", &out.u[..5]);
            }
        }
    }

    #[test]
    fn a_halo_on_the_edge_of_crushed_black_is_not_a_line() {
        // The Ciclop's laser-off photographs of its pattern at high contrast: the black squares
        // crushed to 0, and on their edges against the grey (50) a sharpening halo 30-34 levels
        // over the grey, 4-8 px wide at half its height over the mean of the two sides. It
        // stands over both flanks (a third as much over the grey as over the black), so the
        // step test passes it; its light does not fall away on the grey side as a line's does
        // (no concave log-profile: `gaussian_fit`). Without that test the centre of gravity and
        // the parabola took it for a line in 36-40 of the 40 rows.
        let smooth = |x: f64| 1.0 / (1.0 + (-x / 0.5).exp());
        for (rim, sigma) in [(30.0, 1.4), (34.0, 1.4), (30.0, 1.6), (34.0, 1.8), (30.0, 2.2)] {
            let mut img = image_from(120, 40, |_, a, _| {
                let x = a + 0.5 - 60.3;
                50.0 * smooth(x) + rim * (-(x - 1.0).powi(2) / (2.0 * sigma * sigma)).exp() * smooth(x)
            });
            add_noise(&mut img, 1.5, 5);
            for m in SUBPIXEL_METHODS {
                let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
                assert_eq!(out.found(), 0, "halo {rim} levels, sigma {sigma} px, {m:?}: {:?}", &out.u[..3]);
            }
        }
    }

    #[test]
    fn laser_off_frame_gives_no_samples() {
        // Room light on a textured scene: smooth shading, a specular highlight, short bright
        // marks and sensor noise, and no laser.
        let mut rng = crate::synth::SplitMix::new(11);
        let marks: Vec<(f64, f64)> = (0..40).map(|_| (rng.uniform() * 200.0, rng.uniform() * 120.0)).collect();
        let mut img = image_from(200, 120, |y, a, _| {
            let (x, y) = (a + 0.5, f64::from(y));
            let mut v = 60.0 + 30.0 * (x / 37.0).sin() * (y / 23.0).cos();
            v += 150.0 * (-((x - 140.0).powi(2) + (y - 60.0).powi(2)) / (2.0 * 9.0)).exp();
            for &(mx, my) in &marks {
                if (y - my).abs() < 1.5 {
                    v += 70.0 * (-(x - mx).powi(2) / 1.2).exp();
                }
            }
            v
        });
        add_noise(&mut img, 2.0, 5);
        for m in SUBPIXEL_METHODS {
            let mut d = EdgeDetector::new(EdgeConfig { method: m, ..Default::default() }).unwrap();
            let mut out = LaserLine::default();
            let stats = d.detect(&img.view().unwrap(), &mut out).unwrap();
            assert_eq!(out.found(), 0, "{m:?}: {stats:?}");
        }
    }

    #[test]
    fn elongated_highlight_in_the_first_frame_gives_no_samples() {
        // A glossy highlight about 11 px wide (FWHM) and 32 rows long, like the one the hard
        // preset renders on the body, in a laser-off frame that opens a scan: no earlier frame
        // has told the line's width. (The real Ciclop line, 10-13 px wide, has runs of 23 rows
        // that must stay: `tests/realdata.rs`.)
        let mut img = image_from(160, 120, |y, a, _| {
            let (x, y) = (a + 0.5 - 80.0, f64::from(y) - 60.0);
            40.0 + 110.0 * (-(x * x) / (2.0 * 5.2 * 5.2) - (y * y) / (2.0 * 6.5 * 6.5)).exp()
        });
        add_noise(&mut img, 2.0, 17);
        for m in SUBPIXEL_METHODS {
            let mut d = EdgeDetector::new(EdgeConfig { method: m, ..Default::default() }).unwrap();
            let mut out = LaserLine::default();
            let stats = d.detect(&img.view().unwrap(), &mut out).unwrap();
            assert_eq!(out.found(), 0, "{m:?}: {stats:?}");
        }
    }

    #[test]
    fn highlight_beside_the_line_does_not_take_its_place() {
        // A line down column 40.3 and, beside it, a highlight brighter than the line.
        let mut img = image_from(120, 60, |y, a, b| {
            let h = 250.0 * (-((a + 0.5 - 56.0).powi(2) + (f64::from(y) - 30.0).powi(2)) / (2.0 * 4.0)).exp();
            30.0 + 120.0 * box_line(a, b, 40.3, 2.5) / box_line(-0.5, 0.5, 0.0, 2.5) + h
        });
        add_noise(&mut img, 1.5, 9);
        for m in SUBPIXEL_METHODS {
            let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
            for (y, &u) in out.u.iter().enumerate() {
                assert!((u - 40.3).abs() < 0.15, "{m:?} row {y}: {u}: {:?}", &img.data[y * 120 + 20..y * 120 + 76]);
            }
        }
    }

    #[test]
    fn a_wide_highlight_brighter_than_the_line_yields_to_it_once_the_line_is_known() {
        // The hard body's hair at 320x240: a dim line (35 grey levels over the hair, 2 px)
        // and, in the same rows 25 px on, a glossy highlight on the skin 13 px wide and three
        // times as bright (here in every row, so that no run of the line's own anchors it). The
        // highlight passes a row's tests as a peak, so the line was never tried.
        let top = box_line(-0.5, 0.5, 0.0, 2.0);
        let line = |y: u32, a: f64, b: f64, c: f64| 35.0 * box_line(a, b, c + 0.05 * f64::from(y), 2.0) / top;
        let glint = |a: f64| 100.0 * (-(a + 0.5 - 85.0).powi(2) / (2.0 * 5.5f64.powi(2))).exp();
        // The frame before shows the line's width elsewhere (so the last frame's line does not
        // choose here).
        let mut plain = image_from(140, 100, |y, a, b| 8.0 + line(y, a, b, 25.0));
        let mut both = image_from(140, 100, |y, a, b| 8.0 + line(y, a, b, 60.0) + glint(a));
        add_noise(&mut plain, 1.5, 41);
        add_noise(&mut both, 1.5, 42);
        let rows = |out: &LaserLine| (0..100).filter(|&y| (out.u[y] - (60.0 + 0.05 * y as f32)).abs() < 0.5).count();
        for m in SUBPIXEL_METHODS {
            let cfg = EdgeConfig { method: m, ..Default::default() };
            // A detector that saw the line's width in the frame before finds it in every row.
            let out = detect_after(&plain, &both, cfg.clone());
            assert_eq!((rows(&out), out.found()), (100, 100), "{m:?}: {:?}", &out.u[..]);
            // A fresh one does not know the line's width: the highlight takes the rows.
            assert_eq!(rows(&detect(&both, cfg)), 0, "{m:?}");
        }
    }

    #[test]
    fn a_highlight_far_wider_than_the_line_yields_to_a_line_found_as_a_fallback() {
        // The hard body at 320x240: a glossy highlight 10 px wide, the row's brightest, and the
        // dim line (20 grey levels) in a dark stripe (12) between two surfaces (40), dimmer than
        // they are. Both are fallbacks: the highlight as far wider than the line, the line as
        // found only with the stripe's own dark flanks. The first fallback used to take the row.
        let top = box_line(-0.5, 0.5, 0.0, 1.6);
        let glint = |a: f64| 100.0 * (-((a + 0.5 - 100.0) / 6.0).powi(2)).exp();
        let line = |a: f64, b: f64, c: f64| 20.0 * box_line(a, b, c, 1.6) / top;
        let smooth = |x: f64| 1.0 / (1.0 + (-x / 0.4).exp());
        let stripe = |a: f64| 1.0 - smooth(a + 0.5 - 143.0) * smooth(157.0 - a - 0.5);
        // The frame before shows the line's width elsewhere (so the last frame's line does not
        // choose here).
        let mut plain = image_from(200, 60, |_, a, b| 40.0 + line(a, b, 175.0));
        let mut both =
            image_from(200, 60, |y, a, b| 12.0 + 28.0 * stripe(a) + glint(a) + line(a, b, 150.0 + 0.05 * f64::from(y)));
        add_noise(&mut plain, 1.0, 51);
        add_noise(&mut both, 1.0, 53);
        let rows = |out: &LaserLine| (0..60).filter(|&y| (out.u[y] - (150.0 + 0.05 * y as f32)).abs() < 0.5).count();
        for m in SUBPIXEL_METHODS {
            let out = detect_after(&plain, &both, EdgeConfig { method: m, ..Default::default() });
            assert_eq!((rows(&out), out.found()), (60, 60), "{m:?}: {:?}", &out.u[..]);
        }
    }

    #[test]
    fn bright_face_ending_beside_the_line_does_not_pull_it() {
        // A saturated line at the edge of a bright face (a glossy face under room light, 80
        // grey levels over the table) that ends 6 px on, before the right flank: the flank then
        // reads the darker table beyond the face, and the face used to count as the line's own
        // light (the hard pyramid at 320x240: the line bulged 4 px onto the face, 5-22 mm off,
        // in 17 frames). Before the face was looked for beside the run: 1.66-1.83 px off with
        // the centre of gravity and the parabola, 1.25-1.47 px with the Gaussian.
        let cover = |a: f64, b: f64, lo: f64, hi: f64| (b.min(hi) - a.max(lo)).max(0.0);
        for amp in [250.0, 400.0] {
            let img = image_from(80, 20, |y, a, b| {
                let c = 40.0 + 0.05 * f64::from(y);
                let base = 75.0 * cover(a, b, f64::NEG_INFINITY, c + 1.2)
                    + 155.0 * cover(a, b, c + 1.2, c + 7.0)
                    + 45.0 * cover(a, b, c + 7.0, f64::INFINITY);
                base + amp * box_line(a, b, c, 2.0) / box_line(-0.5, 0.5, 0.0, 2.0)
            });
            assert!(img.data.contains(&255));
            for m in SUBPIXEL_METHODS {
                let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
                assert_eq!(out.found(), 20, "amp {amp} {m:?}");
                for (y, &u) in out.u.iter().enumerate() {
                    let c = 40.0 + 0.05 * y as f32;
                    assert!((u - c).abs() < 0.5, "amp {amp} {m:?} row {y}: {u} for {c}");
                }
            }
        }
    }

    /// The signal-to-noise ratio (line amplitude over the noise's standard deviation) down to
    /// which a dim line on a dark surface is found.
    const STATED_SNR: f64 = 8.0;

    #[test]
    fn dim_line_on_a_dark_surface_is_found_at_the_stated_snr() {
        let noise = 2.0;
        let amp = STATED_SNR * noise;
        let top = box_line(-0.5, 0.5, 0.0, 3.0);
        let centre = |y: u32| 60.0 + 0.13 * f64::from(y);
        let mut img = image_from(140, 200, |y, a, b| 8.0 + amp * box_line(a, b, centre(y), 3.0) / top);
        add_noise(&mut img, noise, 21);
        for m in SUBPIXEL_METHODS {
            let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
            let errs: Vec<f64> = (0..200u32)
                .filter_map(|y| Some(f64::from(out.u[y as usize]) - centre(y)).filter(|e| e.is_finite()))
                .collect();
            assert!(errs.len() >= 190, "{m:?}: found in {} of 200 rows", errs.len());
            let rms = rms(&errs);
            assert!(rms < 0.3, "{m:?}: rms {rms} px");
        }
        // Noise alone at the same level gives nothing.
        let mut flat = image_from(140, 200, |_, _, _| 8.0);
        add_noise(&mut flat, noise, 22);
        assert_eq!(detect(&flat, EdgeConfig::default()).found(), 0);
    }

    #[test]
    fn dim_line_on_dark_print_beside_a_bright_surface_is_found() {
        // The hard preset's dark print in grey: the line (43 grey levels over a print at 9) a
        // few pixels from the edge of bare surface under room light (46), brighter than the
        // line's own flank a step away. Each side of the edge, at 3.5 to 6 px.
        let top = box_line(-0.5, 0.5, 0.0, 1.8);
        let smooth = |x: f64| 1.0 / (1.0 + (-x / 0.4).exp());
        for gap in [3.5, 4.0, 5.0, 6.0] {
            for mirror in [false, true] {
                let centre = |y: u32| 60.0 + 0.05 * f64::from(y);
                let mut img = image_from(120, 60, |y, a, b| {
                    let c = centre(y);
                    let x = a + 0.5 - c;
                    let bright = if mirror { smooth(x - gap) } else { smooth(-x - gap) };
                    9.0 + 37.0 * bright + 43.0 * box_line(a, b, c, 1.8) / top
                });
                add_noise(&mut img, 2.0, 29);
                let side = if mirror { "right" } else { "left" };
                assert_found_in_rows(&img, centre, 57, 0.25, &format!("edge {gap} px to the {side}"));
            }
        }
    }

    #[test]
    fn dim_line_in_a_dark_stripe_between_brighter_surfaces_is_found() {
        // The hard pyramid's dark print at 320x240 in grey: the line crosses a stripe of print
        // (9) 14 px wide between two surfaces under room light (45), and on the print it is
        // dimmer than they are (25 grey levels over the print). Anywhere at least 4.5 px from
        // either edge (nearer: `dim_line_three_pixels_from_a_dark_stripes_edge_is_found`).
        for offset in [-2.5, -1.0, 0.0, 1.5, 2.5] {
            for (m, errs) in print_stripe_errors(offset, 31) {
                let what = format!("{m:?}, {offset} px from the stripe's middle");
                assert!(errs.len() >= 57, "{what}: found in {} of 60 rows", errs.len());
                let rms = rms(&errs);
                assert!(rms < 0.25, "{what}: rms {rms:.3} px");
            }
        }
        // The stripe alone, without the line, gives nothing.
        let img = print_stripe(None, 37);
        for m in SUBPIXEL_METHODS {
            assert_eq!(detect(&img, EdgeConfig { method: m, ..Default::default() }).found(), 0, "{m:?}");
        }
    }

    /// The middle of `print_stripe`'s stripe in row `y`.
    fn print_stripe_middle(y: u32) -> f64 {
        60.0 + 0.05 * f64::from(y)
    }

    /// The hard pyramid's dark print at 320x240 in grey, 60 rows: a stripe of print (9) 14 px
    /// wide between two surfaces under room light (45), and with `offset` a line 25 grey levels
    /// over the print, 1.8 px wide, that many pixels from the stripe's middle; noise of 2
    /// levels (`seed`).
    fn print_stripe(offset: Option<f64>, seed: u64) -> Image {
        let top = box_line(-0.5, 0.5, 0.0, 1.8);
        let smooth = |x: f64| 1.0 / (1.0 + (-x / 0.4).exp());
        let mut img = image_from(120, 60, |y, a, b| {
            let x = a + 0.5 - print_stripe_middle(y);
            let line = offset.map_or(0.0, |o| 25.0 * box_line(a, b, print_stripe_middle(y) + o, 1.8) / top);
            9.0 + 36.0 * (smooth(x - 7.0) + smooth(-x - 7.0)) + line
        });
        add_noise(&mut img, 2.0, seed);
        img
    }

    /// Each method's row errors on `print_stripe` with its line `offset` px from the middle.
    fn print_stripe_errors(offset: f64, seed: u64) -> Vec<(Method, Vec<f64>)> {
        let img = print_stripe(Some(offset), seed);
        let centre = |y: u32| print_stripe_middle(y) + offset;
        SUBPIXEL_METHODS
            .iter()
            .map(|&m| (m, row_errors(&detect(&img, EdgeConfig { method: m, ..Default::default() }), 60, centre)))
            .collect()
    }

    #[test]
    fn dim_line_three_pixels_from_a_dark_stripes_edge_is_found() {
        // The hard pyramid's print at 320x240 in grey, in the frames where the sheet nears the
        // print's edge: the line (25 grey levels over the print, 1.8 px wide) lies 3-4 px from
        // the brighter surface, so that one dark sample may separate the line's tail from the
        // surface's ramp. That sample and the line's own last sample, already dark, are then
        // its flank (`dark_flanks`). At 4 px the surface's ramp reaches the line in about half
        // the rows.
        for offset in [-4.0, -3.5, 3.5, 4.0] {
            for (m, errs) in print_stripe_errors(offset, 47) {
                let what = format!("{m:?}, {offset} px from the stripe's middle");
                // Without the line's own dark sample in the flank: 0-23 rows.
                let least = if offset.abs() < 3.8 { 50 } else { 30 };
                assert!(errs.len() >= least, "{what}: found in {} of 60 rows", errs.len());
                let rms = rms(&errs);
                assert!(rms < 0.2, "{what}: rms {rms:.3} px");
            }
        }
    }

    /// Where the sheet enters the hard phantom's print at 320x240 in grey: a bright face (55) up
    /// to `face_edge(y)`, then the print (11), and a brighter surface (50) 16 px on.
    fn face_edge(y: u32) -> f64 {
        50.0 + 0.05 * f64::from(y)
    }

    /// The level of `face_edge`'s surfaces at `a` in row `y`.
    fn face_and_print(y: u32, a: f64) -> f64 {
        let smooth = |x: f64| 1.0 / (1.0 + (-x / 0.4).exp());
        11.0 + 44.0 * smooth(face_edge(y) - (a + 0.5)) + 39.0 * smooth(a + 0.5 - face_edge(y) - 16.0)
    }

    /// `face_and_print` with a line on the print, 40 levels over it and 1.4 px wide, centred at
    /// `centre(y)` in the rows where `lit(y)`, under noise of 1.5 levels (`seed`).
    fn line_on_print(centre: impl Fn(u32) -> f64, lit: impl Fn(u32) -> bool, seed: u64) -> Image {
        let top = box_line(-0.5, 0.5, 0.0, 1.4);
        let mut img = image_from(120, 60, |y, a, b| {
            face_and_print(y, a) + if lit(y) { 40.0 * box_line(a, b, centre(y), 1.4) / top } else { 0.0 }
        });
        add_noise(&mut img, 1.5, seed);
        img
    }

    #[test]
    fn narrow_line_two_dark_samples_from_a_brighter_face_is_found() {
        // The hard phantom's print at 320x240 in grey where the sheet enters it (`line_on_print`):
        // the line on the print 2.2-2.8 px from the face's edge, about as bright as the face. The
        // line stands over the one or two dark samples between it and the face, not over the
        // face three samples off: while the peak contrast compared it with the samples three
        // away, it was a candidate only where the face's edge had fallen by then (found in 0 /
        // 30 / 54 of the 60 rows at 2.2 / 2.5 / 2.8 px; then 28 / 45 / 56). Nearer the face,
        // its ramp meets the line's tail and the dark flank is too short; the rows found are
        // followed along their course there (`course_peak`: 60 / 47 / 60 rows).
        for (gap, least) in [(2.2, 50), (2.5, 40), (2.8, 54)] {
            let centre = |y: u32| face_edge(y) + gap;
            let img = line_on_print(centre, |_| true, 53);
            assert_found_in_rows(&img, centre, least, 0.15, &format!("{gap} px from the face"));
        }
        // The face and the print alone: steps, no line.
        assert_no_line(face_and_print, 59);
    }

    #[test]
    fn a_line_nearing_a_brighter_faces_edge_is_followed_along_its_course() {
        // The hard pyramid's print at 320x240 in grey where the sheet nears the print's edge
        // (`line_on_print`): the line's distance from the face's edge falls from 3.5 px in the
        // first row to 1.8 or 1.5 px in the last. Where a single dark sample separates the two,
        // the line's full tests read the face for its background and refuse it (found in 35 and
        // 37 of the 60 rows so); the run found farther from the edge is followed on
        // (`course_peak`): 54 and 52 rows, RMS 0.10 px.
        for gap in [1.8, 1.5] {
            let centre = |y: u32| face_edge(y) + 3.5 - (3.5 - gap) * f64::from(y) / 59.0;
            let img = line_on_print(centre, |_| true, 61);
            assert_found_in_rows(&img, centre, 50, 0.2, &format!("nearing the face to {gap} px"));
        }
        // Where the line ends (hidden from row 30 on), its course is not followed onto the
        // face's edge or the print beside it.
        let img = line_on_print(|y| face_edge(y) + 3.5 - 1.5 * f64::from(y) / 59.0, |y| y < 30, 67);
        for m in SUBPIXEL_METHODS {
            let out = detect(&img, EdgeConfig { method: m, ..Default::default() });
            let beyond = (30..60).filter(|&y| out.u[y].is_finite()).count();
            assert_eq!(beyond, 0, "{m:?}: {beyond} samples past the line's end");
        }
    }

    #[test]
    fn a_line_one_dark_sample_from_the_prints_far_edge_is_found() {
        // The hard phantom's print at 320x240 in grey, frame 58 of cam2: the line lies on the
        // print (18) 1.8-2.2 px from its far edge, where a surface brighter than the line begins
        // (60), with no run elsewhere in the frame to follow. One dark sample parts the line from
        // that surface's ramp: that sample is the flank on its side (`SHORT_DARK_FLANK`), found
        // where the line stands `STRIPE_RETRY` times `min_strength` over the lower of the two
        // samples beyond it. Before, with two dark samples needed a side: 0, 0, 0 and 27 rows.
        let smooth = |x: f64| 1.0 / (1.0 + (-x / 0.4).exp());
        let edge = |y: u32| 60.0 + 0.05 * f64::from(y);
        let surfaces =
            |y: u32, a: f64| 18.0 + 42.0 * smooth(a + 0.5 - edge(y)) + 40.0 * smooth(edge(y) - 12.0 - (a + 0.5));
        for (amp, width, gap, least) in
            [(40.0, 1.6, 1.8, 20), (40.0, 1.6, 2.0, 45), (40.0, 1.6, 2.2, 55), (30.0, 1.8, 2.2, 40)]
        {
            let centre = |y: u32| edge(y) - gap;
            let top = box_line(-0.5, 0.5, 0.0, width);
            let mut img = image_from(120, 60, |y, a, b| surfaces(y, a) + amp * box_line(a, b, centre(y), width) / top);
            add_noise(&mut img, 1.5, 71);
            let what = format!("a line {amp} levels over the print, {width} px wide, {gap} px from its edge");
            assert_found_in_rows(&img, centre, least, 0.15, &what);
        }
        // The print between its two brighter surfaces, without the line: nothing.
        assert_no_line(surfaces, 73);
    }

    #[test]
    fn dim_line_at_the_stated_snr_in_a_dark_stripe_is_found() {
        // The body's hair and the pyramid's print at 320x240 in grey: a line 18 grey levels over
        // a dark stripe (9) 12 px wide between brighter surfaces (45 and 70), under noise of 1.5
        // levels. Its brightest pixel stands 12.6-18 levels over the stripe, by its phase: a
        // signal-to-noise ratio of 8.4-12, above the stated 8, and often under twice
        // `min_strength` over the samples beside it (with that bound, as before
        // `STRIPE_RETRY`, it was found in 24-31 of the 60 rows).
        let top = box_line(-0.5, 0.5, 0.0, 1.4);
        let smooth = |x: f64| 1.0 / (1.0 + (-x / 0.4).exp());
        let stripe = |y: u32| 60.0 + 0.05 * f64::from(y);
        let surfaces = |y: u32, a: f64| {
            let x = a + 0.5 - stripe(y);
            9.0 + 36.0 * smooth(-x - 6.0) + 61.0 * smooth(x - 6.0)
        };
        for offset in [-1.0, 0.0, 1.0] {
            let centre = |y: u32| stripe(y) + offset;
            let mut img = image_from(120, 60, |y, a, b| surfaces(y, a) + 18.0 * box_line(a, b, centre(y), 1.4) / top);
            add_noise(&mut img, 1.5, 41);
            assert_found_in_rows(&img, centre, 54, 0.3, &format!("{offset} px from the stripe's middle"));
        }
        // The stripe alone, without the line, gives nothing.
        assert_no_line(surfaces, 43);
    }

    /// Each sub-pixel method finds the line of `img` (60 rows, centre `centre(y)`) in at least
    /// `least` rows, within `rms_px` RMS; `what` names the case.
    fn assert_found_in_rows(img: &Image, centre: impl Fn(u32) -> f64, least: usize, rms_px: f64, what: &str) {
        for m in SUBPIXEL_METHODS {
            let errs = row_errors(&detect(img, EdgeConfig { method: m, ..Default::default() }), 60, &centre);
            assert!(errs.len() >= least, "{m:?}, {what}: found in {} of 60 rows", errs.len());
            let rms = rms(&errs);
            assert!(rms < rms_px, "{m:?}, {what}: rms {rms:.3} px");
        }
    }

    /// No sub-pixel method finds a line in the 120 x 60 image of `surfaces` under noise of 1.5
    /// grey levels (seed `seed`).
    fn assert_no_line(surfaces: impl Fn(u32, f64) -> f64, seed: u64) {
        let mut img = image_from(120, 60, |y, a, _| surfaces(y, a));
        add_noise(&mut img, 1.5, seed);
        for m in SUBPIXEL_METHODS {
            assert_eq!(detect(&img, EdgeConfig { method: m, ..Default::default() }).found(), 0, "{m:?}");
        }
    }

    #[test]
    fn two_surfaces_in_one_row_are_both_kept() {
        // An object's line (rows 0-34, bright) and the table's beside it (rows 25-59, dimmer):
        // rows 25-34 cross both surfaces, where the object hides the table's line no further.
        // A highlight beside the table's line (rows 45-48) is no second surface.
        let object = |y: u32| 70.0 + 0.1 * f64::from(y);
        let table = |y: u32| 30.0 + 0.05 * f64::from(y);
        let mut img = image_from(100, 60, |y, a, b| {
            let mut v = 20.0;
            if y <= 34 {
                v += 120.0 * box_line(a, b, object(y), 2.5) / box_line(-0.5, 0.5, 0.0, 2.5);
            }
            if y >= 25 {
                v += 80.0 * box_line(a, b, table(y), 2.5) / box_line(-0.5, 0.5, 0.0, 2.5);
            }
            if (45..=48).contains(&y) && (84.5..=87.5).contains(&a) {
                v += 150.0;
            }
            v
        });
        add_noise(&mut img, 2.0, 41);
        for m in SUBPIXEL_METHODS {
            let cfg = EdgeConfig { method: m, ..Default::default() };
            let mut d = EdgeDetector::new(cfg.clone()).unwrap();
            let (mut first, mut second) = (LaserLine::default(), LaserLine::default());
            let stats = d.detect_surfaces(&img.view().unwrap(), &mut first, &mut second).unwrap();
            // The first line is what `detect` finds.
            assert_eq!(format!("{first:?}"), format!("{:?}", detect(&img, cfg)), "{m:?}");
            assert_eq!(stats.second as usize, second.found(), "{m:?}");
            let mut both = 0;
            for y in 25..=34u32 {
                let (a, b) = (f64::from(first.u[y as usize]), f64::from(second.u[y as usize]));
                let (near, far) = if (a - object(y)).abs() < 1.0 { (a, b) } else { (b, a) };
                if (near - object(y)).abs() < 0.2 && (far - table(y)).abs() < 0.2 {
                    both += 1;
                }
            }
            assert!(both >= 9, "{m:?}: both lines in {both} of the 10 rows that cross two surfaces");
            // Nowhere else a second line: not beside the highlight, not in rows of one surface.
            let elsewhere: Vec<u32> =
                (0..60u32).filter(|&y| !(25..=34).contains(&y) && second.u[y as usize].is_finite()).collect();
            assert!(elsewhere.is_empty(), "{m:?}: second samples in rows {elsewhere:?}");
            assert_eq!(second.len(), 60);
        }
        // Without laser light, no line, first or second.
        let mut dark = image_from(100, 60, |_, _, _| 20.0);
        add_noise(&mut dark, 2.0, 43);
        let mut d = EdgeDetector::new(EdgeConfig::default()).unwrap();
        let (mut first, mut second) = (LaserLine::default(), LaserLine::default());
        let stats = d.detect_surfaces(&dark.view().unwrap(), &mut first, &mut second).unwrap();
        assert_eq!((first.found(), second.found(), stats.second), (0, 0, 0));
    }

    #[test]
    fn several_lasers_keep_each_ones_second_surfaces() {
        // A red laser crossing two surfaces (rows 25-34 hold both lines) and a green one on one
        // surface, in one rgb8 image with room light and noise in each channel.
        let object = |y: u32| 70.0 + 0.1 * f64::from(y);
        let table = |y: u32| 30.0 + 0.05 * f64::from(y);
        let green = |y: u32| 110.0 - 0.08 * f64::from(y);
        let top = box_line(-0.5, 0.5, 0.0, 2.5);
        let (w, h) = (140u32, 60u32);
        let mut img = Image::new(w, h, Encoding::Rgb8);
        let mut rng = crate::synth::SplitMix::new(47);
        for y in 0..h {
            for x in 0..w {
                let (a, b) = (f64::from(x) - 0.5, f64::from(x) + 0.5);
                let mut red = 0.0;
                if y <= 34 {
                    red += 120.0 * box_line(a, b, object(y), 2.5) / top;
                }
                if y >= 25 {
                    red += 80.0 * box_line(a, b, table(y), 2.5) / top;
                }
                let g = 100.0 * box_line(a, b, green(y), 2.5) / top;
                let px = 3 * (y * w + x) as usize;
                for (k, v) in
                    [30.0 + red + 0.1 * g, 30.0 + g + 0.1 * red, 30.0 + 0.1 * (red + g)].into_iter().enumerate()
                {
                    img.data[px + k] = (v + 2.0 * rng.normal()).round().clamp(0.0, 255.0) as u8;
                }
            }
        }
        let configs = || {
            [Channel::RedMinusOthers, Channel::GreenMinusOthers]
                .map(|channel| EdgeConfig { channel, ..Default::default() })
                .to_vec()
        };
        let view = img.view().unwrap();
        let (mut one, mut two) = (Vec::new(), Vec::new());
        let mut plain = LaserDetectors::new(configs()).unwrap();
        assert_eq!(plain.layers(), 1);
        plain.detect(&view, &mut one).unwrap();
        let mut both = LaserDetectors::new(configs()).unwrap().with_second_surfaces(true);
        assert_eq!(both.layers(), 2);
        // Twice, so that buffers kept from the first frame are used again.
        for _ in 0..2 {
            let stats = both.detect(&view, &mut two).unwrap();
            // Layer-major: both first lines as without the second surfaces, then each laser's
            // second.
            assert_eq!(two.len(), 4);
            assert_eq!(format!("{:?}", &two[..2]), format!("{one:?}"));
            assert_eq!((stats[0].second as usize, stats[1].second), (two[2].found(), 0));
            assert_eq!(two[3].found(), 0, "the green laser crosses one surface");
            let crossing = (25..=34u32)
                .filter(|&y| {
                    let (a, b) = (f64::from(two[0].u[y as usize]), f64::from(two[2].u[y as usize]));
                    let (near, far) = if (a - object(y)).abs() < 1.0 { (a, b) } else { (b, a) };
                    (near - object(y)).abs() < 0.25 && (far - table(y)).abs() < 0.25
                })
                .count();
            assert!(crossing >= 9, "both red lines in {crossing} of the 10 rows that cross two surfaces");
            let elsewhere = (0..h).filter(|&y| !(25..=34).contains(&y) && two[2].u[y as usize].is_finite()).count();
            assert_eq!(elsewhere, 0);
        }
        // Back to one line per laser: two lines again.
        let mut again = both.with_second_surfaces(false);
        again.detect(&view, &mut two).unwrap();
        assert_eq!(format!("{two:?}"), format!("{one:?}"));
        // One laser keeps its second surfaces as `detect_surfaces` does, in any encoding.
        let grey = EdgeConfig::default();
        let mut single = LaserDetectors::new(vec![grey.clone()]).unwrap().with_second_surfaces(true);
        single.detect(&view, &mut two).unwrap();
        let (mut first, mut second) = (LaserLine::default(), LaserLine::default());
        EdgeDetector::new(grey).unwrap().detect_surfaces(&view, &mut first, &mut second).unwrap();
        assert_eq!(format!("{two:?}"), format!("{:?}", [first, second]));
    }

    #[test]
    fn the_last_frames_line_chooses_among_a_rows_peaks() {
        // A glint brighter than the laser line that looks like one (as wide, along every row)
        // appears beside it: a detector that saw the line in the last frame keeps the line; a
        // fresh detector takes the brightest. A line that moved further than `max_jump_px` is
        // found as without the last frame, and a frame without laser light forgets it.
        let top = box_line(-0.5, 0.5, 0.0, 2.5);
        let frame = |line: Option<f64>, glint: bool, seed: u64| {
            let mut img = image_from(160, 60, |y, a, b| {
                let mut v = 20.0;
                if let Some(c) = line {
                    v += 80.0 * box_line(a, b, c + 0.02 * f64::from(y), 2.5) / top;
                }
                if glint {
                    v += 150.0 * box_line(a, b, 110.0 - 0.03 * f64::from(y), 2.5) / top;
                }
                v
            });
            add_noise(&mut img, 2.0, seed);
            img
        };
        let near = |out: &LaserLine, c: f64| {
            (0..60u32).filter(|&y| (f64::from(out.u[y as usize]) - c - 0.02 * f64::from(y)).abs() < 0.3).count()
        };
        for m in SUBPIXEL_METHODS {
            let cfg = EdgeConfig { method: m, ..Default::default() };
            let both = frame(Some(60.4), true, 51);
            // Fresh: the glint, the brightest.
            let fresh = detect(&both, cfg.clone());
            assert_eq!((near(&fresh, 60.4), fresh.found()), (0, 60), "{m:?}");
            // After a frame with the line alone: the line.
            let mut d = EdgeDetector::new(cfg.clone()).unwrap();
            let mut out = LaserLine::default();
            d.detect(&frame(Some(59.6), false, 52).view().unwrap(), &mut out).unwrap();
            d.detect(&both.view().unwrap(), &mut out).unwrap();
            assert_eq!((near(&out, 60.4), out.found()), (60, 60), "{m:?}");
            // The line moved 8 px with the glint beside it: the brightest again.
            d.detect(&frame(Some(68.4), true, 53).view().unwrap(), &mut out).unwrap();
            assert_eq!(near(&out, 68.4), 0, "{m:?}");
            // A frame without laser light, then both: the brightest.
            let mut d = EdgeDetector::new(cfg.clone()).unwrap();
            d.detect(&frame(Some(59.6), false, 54).view().unwrap(), &mut out).unwrap();
            d.detect(&frame(None, false, 55).view().unwrap(), &mut out).unwrap();
            assert_eq!(out.found(), 0, "{m:?}");
            d.detect(&both.view().unwrap(), &mut out).unwrap();
            assert_eq!(near(&out, 60.4), 0, "{m:?}");
        }
    }

    #[test]
    fn a_weak_peak_where_the_line_was_does_not_hold_it_back() {
        // The line moves 15 px between two frames (the camera shook); where it was, a texture
        // ridge a fifth as strong passes the tests. The moved line is found, not the ridge.
        let top = box_line(-0.5, 0.5, 0.0, 2.5);
        let frame = |line: f64, ridge: bool, seed: u64| {
            let mut img = image_from(160, 60, |y, a, b| {
                let mut v = 20.0 + 80.0 * box_line(a, b, line + 0.02 * f64::from(y), 2.5) / top;
                if ridge {
                    v += 16.0 * box_line(a, b, 60.0 + 0.02 * f64::from(y), 2.5) / top;
                }
                v
            });
            add_noise(&mut img, 1.0, seed);
            img
        };
        for m in SUBPIXEL_METHODS {
            let cfg = EdgeConfig { method: m, ..Default::default() };
            // The ridge alone is a line to the detector.
            let ridge = detect(
                &frame(130.0, true, 61),
                EdgeConfig { roi: Roi { width: 100, ..Default::default() }, ..cfg.clone() },
            );
            assert_eq!(ridge.found(), 60, "{m:?}: the ridge passes the tests");
            let mut d = EdgeDetector::new(cfg).unwrap();
            let mut out = LaserLine::default();
            d.detect(&frame(60.0, false, 62).view().unwrap(), &mut out).unwrap();
            d.detect(&frame(75.0, true, 63).view().unwrap(), &mut out).unwrap();
            let on_line =
                (0..60u32).filter(|&y| (f64::from(out.u[y as usize]) - 75.0 - 0.02 * f64::from(y)).abs() < 0.3).count();
            assert_eq!((on_line, out.found()), (60, 60), "{m:?}");
        }
    }

    #[test]
    fn region_boundary_never_makes_a_line() {
        // A line at column 18: its falling halo enters a region that starts at column 22, and
        // the image's own edge cuts a line at column 1.
        let img =
            image_from(120, 30, |_, a, b| 20.0 + 200.0 * box_line(a, b, 18.0, 3.0) / box_line(-0.5, 0.5, 0.0, 3.0));
        let roi = Roi { x_offset: 22, width: 80, ..Default::default() };
        for m in SUBPIXEL_METHODS {
            assert_eq!(detect(&img, EdgeConfig { method: m, roi, ..Default::default() }).found(), 0, "{m:?}");
        }
        let edge =
            image_from(120, 30, |_, a, b| 20.0 + 200.0 * box_line(a, b, 0.6, 3.0) / box_line(-0.5, 0.5, 0.0, 3.0));
        for m in SUBPIXEL_METHODS {
            assert_eq!(detect(&edge, EdgeConfig { method: m, ..Default::default() }).found(), 0, "{m:?}");
        }
    }

    /// Debug aid (run with --ignored --nocapture): the spread of each estimate under sensor
    /// noise, by width.
    #[test]
    #[ignore]
    fn noise_spread_by_width() {
        for fwhm in [1.0, 2.0, 3.0, 3.5, 4.0] {
            for narrow in [0.0f32, 10.0] {
                let mut errs = Vec::new();
                let mut rng = crate::synth::SplitMix::new(7);
                let top = box_line(-0.5, 0.5, 0.0, fwhm);
                let centre = |k: u32| 40.0 + f64::from(k % 20) / 20.0;
                let mut img = image_from(80, 200, |y, a, b| 30.0 + 120.0 * box_line(a, b, centre(y), fwhm) / top);
                for (i, d) in img.data.iter_mut().enumerate() {
                    let y = (i / 80) as u32;
                    let x = (i % 80) as f64;
                    let v = 30.0 + 120.0 * box_line(x - 0.5, x + 0.5, centre(y), fwhm) / top + 1.5 * rng.normal();
                    *d = v.round().clamp(0.0, 255.0) as u8;
                }
                let out = detect(&img, EdgeConfig { narrow_width_px: narrow, min_run: 1, ..Default::default() });
                for k in 0..200u32 {
                    let u = f64::from(out.u[k as usize]);
                    if u.is_finite() {
                        errs.push(u - centre(k));
                    }
                }
                let n = errs.len() as f64;
                let mean = errs.iter().sum::<f64>() / n;
                let sd = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
                eprintln!("fwhm {fwhm} narrow {narrow}: n {n} mean {mean:.4} sd {sd:.4}");
            }
        }
    }
}

#[cfg(test)]
mod speed {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A horizontal line read by columns against the same frame's vertical line read by rows,
    /// with the frame in cache (the same call repeated) and out of every cache (64 MiB written
    /// between calls), and the columns' first pass alone. The pyramid's middle frame at
    /// 1920x1200, mono8.
    /// `cargo test --release -p xsurf-core --lib edge::speed -- --ignored --nocapture`
    #[test]
    #[ignore = "a timing probe"]
    fn columns_against_rows_in_and_out_of_cache() {
        use crate::rig::Rig;
        use crate::synth::{LaserModel, ScanSettings, Scanner, Scene};
        let settings = ScanSettings { encoding: Encoding::Mono8, ..Default::default() };
        let scene = Scene::by_name("pyramid").unwrap();
        let s = Scanner::new(scene, Rig::study(1920, 1200), LaserModel::default(), settings).unwrap();
        let img = s.render(0, s.frame_count() / 2);
        let (w, h) = (img.width, img.height);
        let t = transposed(&img);
        let horizontal = EdgeConfig { line_orientation: Orientation::Horizontal, ..Default::default() };
        let (mut by_columns, mut by_rows) =
            (EdgeDetector::new(horizontal).unwrap(), EdgeDetector::new(EdgeConfig::default()).unwrap());
        let mut out = LaserLine::default();
        let (tv, v) = (t.view().unwrap(), img.view().unwrap());
        let rows = plane::Rows { data: &t.data, start: 0, stride: h as usize, rows: w as usize, cols: h as usize };
        let (mut max, mut at) = (plane::ColumnMax::default(), vec![0; h as usize]);
        let mut junk = vec![1u8; 64 << 20];
        for cold in [false, true] {
            let mut timed = |f: &mut dyn FnMut()| {
                let mut total = 0.0;
                for _ in 0..200 {
                    if cold {
                        junk.iter_mut().step_by(64).for_each(|x| *x = x.wrapping_add(1));
                        std::hint::black_box(&junk);
                    }
                    let start = std::time::Instant::now();
                    f();
                    total += start.elapsed().as_secs_f64();
                }
                total / 200.0 * 1e6
            };
            let c = timed(&mut || {
                by_columns.detect(&tv, &mut out).unwrap();
            });
            let r = timed(&mut || {
                by_rows.detect(&v, &mut out).unwrap();
            });
            let pass = timed(&mut || plane::column_argmax(&rows, &mut max, &mut at));
            let strips = by_columns.scratch.ready.iter().filter(|&&x| x).count();
            println!(
                "{}: columns {c:.0} us, rows {r:.0} us ({:.0} %), first pass {pass:.0} us, {strips} of {} strips transposed",
                if cold { "out of cache" } else { "in cache" },
                100.0 * r / c,
                by_columns.scratch.ready.len()
            );
        }
    }
}
