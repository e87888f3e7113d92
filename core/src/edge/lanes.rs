//! The per-sample primitives of a row profile: bytes in 16-byte lanes (SSE2, NEON or scalar
//! through `wide`), floats one at a time. Kept apart from the detector that uses them.

use wide::u8x16;

/// A sample type of a row profile.
pub(super) trait Sample: Copy + PartialOrd {
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
    /// The peak contrast of every sample: how far it stands above the higher of the lowest
    /// sample within `d` before it and the lowest within `d` after it (zero within `d` of
    /// either end, and never negative), into `out`. A narrow line a dark gap of one or two
    /// samples from a brighter surface stands above that gap, not above the surface.
    fn contrast(p: &[Self], d: usize, out: &mut Vec<Self>);
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
    #[inline]
    fn contrast(p: &[u8], d: usize, out: &mut Vec<u8>) {
        out.clear();
        out.resize(p.len(), 0);
        if p.len() > 2 * d {
            for (o, w) in out[d..p.len() - d].iter_mut().zip(p.windows(2 * d + 1)) {
                let low = |s: &[u8]| s.iter().copied().min().unwrap_or(0);
                *o = w[d].saturating_sub(low(&w[..d]).max(low(&w[d + 1..])));
            }
        }
    }
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
    fn contrast(p: &[f32], d: usize, out: &mut Vec<f32>) {
        out.clear();
        out.resize(p.len(), 0.0);
        if p.len() > 2 * d {
            for (o, w) in out[d..p.len() - d].iter_mut().zip(p.windows(2 * d + 1)) {
                let low = |s: &[f32]| s.iter().copied().fold(f32::INFINITY, f32::min);
                *o = (w[d] - low(&w[..d]).max(low(&w[d + 1..]))).max(0.0);
            }
        }
    }
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
pub(super) fn walk_left<S: Sample>(p: &[S], from: usize, min: usize, cut: S::Cut) -> usize {
    from - p[min..from].iter().rev().take_while(|v| v.above(cut)).count()
}

/// The last of [`Sample::run`], one sample at a time: the highest `r` in `from..=max` (and
/// inside `p`) with every sample of `p[from + 1..=r]` above `cut`.
#[inline(always)]
pub(super) fn walk_right<S: Sample>(p: &[S], from: usize, max: usize, cut: S::Cut) -> usize {
    let end = (max + 1).min(p.len());
    from + p[from + 1..end].iter().take_while(|v| v.above(cut)).count()
}
