//! The detector's signal as bytes: what the byte path of the detector reads. A mono8 image is
//! read in place. A colour image's channel (the laser's colour, or its colour against the
//! others) is extracted once per frame, 32 pixels at a time. A horizontal line is read by
//! columns from row-major bytes: every column's brightest sample in one pass over the rows
//! ([`column_argmax`]), and whole columns, where a sample needs them, transposed in tiles of 8
//! rows by 16 columns ([`transpose_into`]). All run in 16-byte lanes (SSE2, NEON or scalar
//! through `wide`), so every encoding and orientation reaches the same vectorised detector as
//! mono8 rows.

use super::Channel;
use wide::u8x16;

/// 16 bytes from the front of `s` (which holds at least 16).
#[inline(always)]
fn load(s: &[u8]) -> u8x16 {
    let mut a = [0u8; 16];
    a.copy_from_slice(&s[..16]);
    u8x16::new(a)
}

/// One perfect shuffle of 8 registers: register `i` is interleaved with register `i + 4`, the
/// low halves first. Three of them turn 8 rows of 16 bytes into 16 columns of 8, two to a
/// register.
#[inline(always)]
fn shuffle8(v: &[u8x16; 8]) -> [u8x16; 8] {
    let (lo, hi) = (u8x16::unpack_low, u8x16::unpack_high);
    [
        lo(v[0], v[4]),
        hi(v[0], v[4]),
        lo(v[1], v[5]),
        hi(v[1], v[5]),
        lo(v[2], v[6]),
        hi(v[2], v[6]),
        lo(v[3], v[7]),
        hi(v[3], v[7]),
    ]
}

/// The same over 6 registers (register `i` with `i + 3`): five of them separate the three
/// channels of 32 pixels of 3 bytes.
#[inline(always)]
fn shuffle6(v: &[u8x16; 6]) -> [u8x16; 6] {
    let (lo, hi) = (u8x16::unpack_low, u8x16::unpack_high);
    [lo(v[0], v[3]), hi(v[0], v[3]), lo(v[1], v[4]), hi(v[1], v[4]), lo(v[2], v[5]), hi(v[2], v[5])]
}

/// The transpose of a `rows` x `cols` block of bytes whose row `j` is `row(j)` (at least `cols`
/// bytes from its start), into `dst` (at least `rows * cols` bytes): `dst[k * rows + j] =
/// row(j)[k]`. Tiles of 8 rows by 16 columns in
/// lanes (all in registers), the ragged edges one byte at a time.
pub(super) fn transpose_into<'a>(rows: usize, cols: usize, row: impl Fn(usize) -> &'a [u8], dst: &mut [u8]) {
    let (full_rows, full_cols) = (rows / 8 * 8, cols / 16 * 16);
    // Strips of 64 rows, 16 columns at a time: each column's 64 bytes of the strip (a cache
    // line) are written whole while they are in the first-level cache, and each row's bytes are
    // read in order.
    for j0 in (0..full_rows).step_by(64) {
        let j1 = (j0 + 64).min(full_rows);
        for k in (0..full_cols).step_by(16) {
            for j in (j0..j1).step_by(8) {
                let mut v: [u8x16; 8] = std::array::from_fn(|i| load(&row(j + i)[k..]));
                for _ in 0..3 {
                    v = shuffle8(&v);
                }
                // Register i: column k + 2i of the 8 rows, then column k + 2i + 1.
                for (i, t) in v.iter().enumerate() {
                    let t = t.as_array();
                    let at = (k + 2 * i) * rows + j;
                    dst[at..at + 8].copy_from_slice(&t[..8]);
                    dst[at + rows..at + rows + 8].copy_from_slice(&t[8..]);
                }
            }
        }
        for j in j0..j1 {
            for (k, &b) in row(j)[full_cols..cols].iter().enumerate() {
                dst[(full_cols + k) * rows + j] = b;
            }
        }
    }
    for j in full_rows..rows {
        for (k, &b) in row(j)[..cols].iter().enumerate() {
            dst[k * rows + j] = b;
        }
    }
}

/// Rows of bytes in a buffer: row `j` is `cols` bytes from `start + j * stride`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Rows<'a> {
    pub data: &'a [u8],
    pub start: usize,
    pub stride: usize,
    pub rows: usize,
    pub cols: usize,
}

impl<'a> Rows<'a> {
    /// Row `j` (`cols` bytes).
    #[inline(always)]
    pub fn row(&self, j: usize) -> &'a [u8] {
        let at = self.start + j * self.stride;
        &self.data[at..at + self.cols]
    }

    /// The byte of row `j`, column `k`.
    #[inline(always)]
    pub fn at(&self, j: usize, k: usize) -> u8 {
        self.data[self.start + j * self.stride + k]
    }
}

/// Rows per block of [`column_argmax`]'s first pass.
const BLOCK: usize = 16;

/// The running maxima of [`column_argmax`]: each column's maximum so far, and the group of
/// blocks where it was first reached.
#[derive(Debug, Default, Clone)]
pub(super) struct ColumnMax {
    best: Vec<u8>,
    group: Vec<u8>,
}

/// The first row of each column's maximum: `at[k]` is the least `j` at which `rows.at(j, k)`
/// is the greatest of column `k` (what `Sample::argmax` gives on the column). One pass over
/// the rows in order, 16 columns to a lane: each block of 16 rows' column maxima, and the first
/// group of blocks that raises a column's maximum (a byte per column: at most 256 groups); then
/// only that group's rows are read again, one byte per row, for each column.
pub(super) fn column_argmax(rows: &Rows<'_>, scratch: &mut ColumnMax, at: &mut [u32]) {
    let (h, w) = (rows.rows, rows.cols);
    let full = w / 16 * 16;
    let group_rows = BLOCK * h.div_ceil(BLOCK * 256).max(1);
    scratch.best.clear();
    scratch.best.resize(w, 0);
    scratch.group.clear();
    scratch.group.resize(w, 0);
    for j0 in (0..h).step_by(BLOCK) {
        let j1 = (j0 + BLOCK).min(h);
        let g = (j0 / group_rows) as u8;
        let tag = u8x16::splat(g);
        // The block's rows (its last repeated where the image ends inside it), read in
        // order side by side: each 16 columns' block maximum in registers, then merged into
        // the running maximum and its group.
        let r: [&[u8]; BLOCK] = std::array::from_fn(|i| rows.row((j0 + i).min(j1 - 1)));
        for k in (0..full).step_by(16) {
            let m = r[1..].iter().fold(load(&r[0][k..]), |m, row| m.max(load(&row[k..])));
            let old = load(&scratch.best[k..]);
            let kept = m.saturating_sub(old).simd_eq(u8x16::ZERO);
            scratch.best[k..k + 16].copy_from_slice(old.max(m).as_array());
            let group = kept.bitselect(load(&scratch.group[k..]), tag);
            scratch.group[k..k + 16].copy_from_slice(group.as_array());
        }
        for k in full..w {
            let m = r.iter().fold(0, |m, row| m.max(row[k]));
            if m > scratch.best[k] {
                (scratch.best[k], scratch.group[k]) = (m, g);
            }
        }
    }
    for (k, at) in at.iter_mut().enumerate().take(w) {
        let a = usize::from(scratch.group[k]) * group_rows;
        let b = (a + group_rows).min(h);
        *at = (a..b).find(|&j| rows.at(j, k) == scratch.best[k]).unwrap_or(a) as u32;
    }
}

/// The detector's byte for one pixel of channel `channel`, from its red, green and blue.
#[inline(always)]
fn combine(channel: Channel, r: u8x16, g: u8x16, b: u8x16) -> u8x16 {
    match channel {
        Channel::Red => r,
        Channel::Green => g,
        Channel::Blue => b,
        // r - (g + b) / 2 at or above zero, the half rounded down in the mean: within half a
        // level of the exact value.
        Channel::RedMinusOthers => against(r, g, b),
        Channel::GreenMinusOthers => against(g, r, b),
        Channel::BlueMinusOthers => against(b, r, g),
        Channel::Luma => {
            let (r, g, b) = (r.to_array(), g.to_array(), b.to_array());
            u8x16::new(std::array::from_fn(|i| luma(r[i], g[i], b[i])))
        }
    }
}

/// `c - (a + b) / 2` at or above zero, the half rounded down in the mean: within half a level
/// of the exact value.
#[inline(always)]
fn against(c: u8x16, a: u8x16, b: u8x16) -> u8x16 {
    c.saturating_sub((a >> 1) + (b >> 1) + (a & b & u8x16::splat(1)))
}

/// Luma (0.299 R + 0.587 G + 0.114 B) rounded to a byte, in integers.
#[inline(always)]
fn luma(r: u8, g: u8, b: u8) -> u8 {
    ((19_595 * u32::from(r) + 38_470 * u32::from(g) + 7_471 * u32::from(b) + 32_768) >> 16) as u8
}

/// The same for one pixel, one byte at a time.
#[inline(always)]
fn combine1(channel: Channel, r: u8, g: u8, b: u8) -> u8 {
    match channel {
        Channel::Red => r,
        Channel::Green => g,
        Channel::Blue => b,
        Channel::RedMinusOthers => r.saturating_sub(((u16::from(g) + u16::from(b)) / 2) as u8),
        Channel::GreenMinusOthers => g.saturating_sub(((u16::from(r) + u16::from(b)) / 2) as u8),
        Channel::BlueMinusOthers => b.saturating_sub(((u16::from(r) + u16::from(g)) / 2) as u8),
        Channel::Luma => luma(r, g, b),
    }
}

/// The red, green and blue bytes (in memory order: red first only if the pixels are rgb) of
/// the 32 3-byte pixels at the front of `src` (which holds at least 96 bytes): the first
/// channel's 32 bytes in the first two registers, then the second's, then the third's. Five
/// perfect shuffles, written out so that the six registers stay in registers.
#[inline(always)]
fn deinterleave32(src: &[u8]) -> [u8x16; 6] {
    let v = [load(src), load(&src[16..]), load(&src[32..]), load(&src[48..]), load(&src[64..]), load(&src[80..])];
    shuffle6(&shuffle6(&shuffle6(&shuffle6(&shuffle6(&v)))))
}

/// `f(red, green, blue)` of the first `n` 3-byte pixels of `px` into `out[..n]`: 32 pixels at a
/// time in lanes, the rest one at a time by `f1`. Written once per channel, so that each
/// channel's arithmetic is compiled into its own loop.
#[inline(always)]
fn each_pixel(
    px: &[u8],
    n: usize,
    rgb: bool,
    out: &mut [u8],
    f: impl Fn(u8x16, u8x16, u8x16) -> u8x16,
    f1: impl Fn(u8, u8, u8) -> u8,
) {
    let full = n / 32 * 32;
    for (src, dst) in px[..3 * full].chunks_exact(96).zip(out[..full].chunks_exact_mut(32)) {
        let v = deinterleave32(src);
        let (lo, hi) =
            if rgb { (f(v[0], v[2], v[4]), f(v[1], v[3], v[5])) } else { (f(v[4], v[2], v[0]), f(v[5], v[3], v[1])) };
        dst[..16].copy_from_slice(lo.as_array());
        dst[16..].copy_from_slice(hi.as_array());
    }
    for (p, o) in px[3 * full..3 * n].chunks_exact(3).zip(&mut out[full..n]) {
        *o = if rgb { f1(p[0], p[1], p[2]) } else { f1(p[2], p[1], p[0]) };
    }
}

/// Channel `channel` of the 3-byte pixels of `px` (red first if `rgb`, else blue first) into
/// `out`, one byte per pixel: 32 pixels at a time in lanes, the rest one at a time.
pub(super) fn channel_row(px: &[u8], rgb: bool, channel: Channel, out: &mut [u8]) {
    let n = out.len().min(px.len() / 3);
    let one = |r, g, b| combine1(channel, r, g, b);
    match channel {
        Channel::Red => each_pixel(px, n, rgb, out, |r, _, _| r, one),
        Channel::Green => each_pixel(px, n, rgb, out, |_, g, _| g, one),
        Channel::Blue => each_pixel(px, n, rgb, out, |_, _, b| b, one),
        Channel::RedMinusOthers => each_pixel(px, n, rgb, out, against, one),
        Channel::GreenMinusOthers => each_pixel(px, n, rgb, out, |r, g, b| against(g, r, b), one),
        Channel::BlueMinusOthers => each_pixel(px, n, rgb, out, |r, g, b| against(b, r, g), one),
        Channel::Luma => each_pixel(px, n, rgb, out, |r, g, b| combine(Channel::Luma, r, g, b), one),
    }
}

/// Several channels of the first `n` 3-byte pixels of `px` in one pass: channel
/// `channels[k]` into `out[k * stride..][..n]`. The pixels are separated into red, green and
/// blue once per 32, and each channel made from them in lanes. Nothing is written unless `px`
/// holds the pixels and `out` every channel's stretch.
pub(super) fn channel_rows(px: &[u8], n: usize, rgb: bool, channels: &[Channel], out: &mut [u8], stride: usize) {
    let Some(last) = channels.len().checked_sub(1) else { return };
    if px.len() < 3 * n || n > stride || out.len() < last * stride + n {
        return;
    }
    if let [channel] = channels {
        return channel_row(&px[..3 * n], rgb, *channel, &mut out[..n]);
    }
    let full = n / 32 * 32;
    for (i, src) in px[..3 * full].chunks_exact(96).enumerate() {
        let v = deinterleave32(src);
        // v[0..2]: the first channel of 32 pixels, v[2..4] the second, v[4..6] the third.
        for half in 0..2 {
            let (first, g, last) = (v[half], v[2 + half], v[4 + half]);
            let (r, b) = if rgb { (first, last) } else { (last, first) };
            for (k, &channel) in channels.iter().enumerate() {
                let at = k * stride + 32 * i + 16 * half;
                out[at..at + 16].copy_from_slice(combine(channel, r, g, b).as_array());
            }
        }
    }
    for (i, p) in px[3 * full..3 * n].chunks_exact(3).enumerate() {
        let (r, b) = if rgb { (p[0], p[2]) } else { (p[2], p[0]) };
        for (k, &channel) in channels.iter().enumerate() {
            out[k * stride + full + i] = combine1(channel, r, p[1], b);
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A reproducible byte pattern with every value.
    fn bytes(n: usize, seed: u64) -> Vec<u8> {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (s >> 33) as u8
            })
            .collect()
    }

    /// The lanes give the plain definition of a transpose, for blocks with and without ragged
    /// edges, read from rows longer than the block.
    #[test]
    fn transpose_is_the_transpose() {
        for (rows, cols) in [(16, 16), (32, 48), (17, 33), (5, 40), (40, 5), (1, 1), (0, 7), (31, 16)] {
            let stride = cols + 3;
            let src = bytes(rows * stride + 16, (rows * 100 + cols) as u64);
            let mut dst = vec![0u8; rows * cols];
            transpose_into(rows, cols, |j| &src[j * stride..], &mut dst);
            for j in 0..rows {
                for k in 0..cols {
                    assert_eq!(dst[k * rows + j], src[j * stride + k], "{rows}x{cols} at ({j}, {k})");
                }
            }
        }
    }

    /// Each column's first maximum, against a plain search down the column: random bytes,
    /// columns of few levels (many ties), and images tall enough that a group holds several
    /// blocks; read from rows longer than the block, at an offset.
    #[test]
    fn column_argmax_is_the_first_maximum() {
        let mut scratch = ColumnMax::default();
        for (rows, cols) in [(1, 1), (16, 16), (17, 33), (240, 320), (5000, 20), (9000, 3), (33, 100)] {
            for levels in [256u32, 3] {
                let stride = cols + 5;
                let data: Vec<u8> = bytes(rows * stride + 7, (rows * cols) as u64 + u64::from(levels))
                    .into_iter()
                    .map(|b| (u32::from(b) % levels) as u8)
                    .collect();
                let r = Rows { data: &data, start: 7, stride, rows, cols };
                let mut at = vec![u32::MAX; cols];
                column_argmax(&r, &mut scratch, &mut at);
                for k in 0..cols {
                    let column: Vec<u8> = (0..rows).map(|j| r.at(j, k)).collect();
                    let max = column.iter().copied().max().unwrap();
                    let first = column.iter().position(|&v| v == max).unwrap();
                    assert_eq!(at[k] as usize, first, "{rows}x{cols} levels {levels} column {k}");
                }
            }
        }
    }

    /// Every channel of every length, in lanes and one pixel at a time, against the plain
    /// arithmetic: red exact, red against the others and luma within half a level of the exact
    /// value.
    #[test]
    fn channel_rows_match_the_plain_arithmetic() {
        for n in [0, 1, 31, 32, 33, 64, 100, 640] {
            let px = bytes(3 * n, n as u64);
            for rgb in [true, false] {
                for channel in super::super::CHANNELS {
                    let mut out = vec![0u8; n];
                    channel_row(&px, rgb, channel, &mut out);
                    for (i, p) in px.chunks_exact(3).enumerate() {
                        let (r, g, b) = if rgb { (p[0], p[1], p[2]) } else { (p[2], p[1], p[0]) };
                        let exact = channel.of(f32::from(r), f32::from(g), f32::from(b));
                        let got = f32::from(out[i]);
                        assert!((got - exact).abs() <= 0.51, "{channel:?} rgb {rgb} n {n} px {i}: {got} vs {exact}");
                        if matches!(channel, Channel::Red | Channel::Green | Channel::Blue) {
                            assert_eq!(got, exact);
                        }
                    }
                }
                // Three channels in one pass: each as it is alone, in its own stretch of the
                // output (stride beyond the row: the rest left as it was).
                let three = [Channel::RedMinusOthers, Channel::GreenMinusOthers, Channel::BlueMinusOthers];
                let stride = n + 5;
                let mut all = vec![7u8; 3 * stride];
                channel_rows(&px, n, rgb, &three, &mut all, stride);
                for (k, &channel) in three.iter().enumerate() {
                    let mut one = vec![0u8; n];
                    channel_row(&px, rgb, channel, &mut one);
                    assert_eq!(&all[k * stride..k * stride + n], &one[..], "{channel:?} n {n}");
                    assert!(all[k * stride + n..(k + 1) * stride].iter().all(|&b| b == 7));
                }
            }
        }
    }
}

#[cfg(test)]
mod speed {
    #![allow(clippy::unwrap_used)]
    /// `cargo test --release -p xsurf-core --lib plane::speed -- --ignored --nocapture`
    #[test]
    #[ignore = "a timing probe"]
    fn transpose_and_channel_rates() {
        let (w, h) = (1920usize, 1200usize);
        let src: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 251) as u8).collect();
        let mut dst = vec![0u8; w * h];
        for (w, h) in [(w, h), (h, w), (640, 480), (480, 640)] {
            let t = std::time::Instant::now();
            for _ in 0..100 {
                super::transpose_into(h, w, |j| &src[j * w..], &mut dst);
            }
            let s = t.elapsed().as_secs_f64() / 100.0;
            println!("transpose {w}x{h}: {:.0} us, {:.2} GB/s", s * 1e6, (w * h) as f64 / s * 1e-9);
        }
        let mut out = vec![0u8; w];
        let t = std::time::Instant::now();
        for _ in 0..100 {
            for j in 0..h {
                super::channel_row(&src[3 * w * j..], true, super::Channel::RedMinusOthers, &mut out);
            }
        }
        let s = t.elapsed().as_secs_f64() / 100.0;
        println!("channel {w}x{h}: {:.0} us, {:.2} Gpx/s", s * 1e6, (w * h) as f64 / s * 1e-9);
    }
}
