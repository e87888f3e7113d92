//! The centre-of-gravity detector's rate as a fraction of the plain byte sum's, measured in
//! alternation: each round times a batch of byte sums over an image, then a batch of detections
//! of the same image, so that both see the same state of a shared, noisy machine. Prints the
//! median ratio over the rounds and its spread (10th-90th percentile), per image size and case:
//!
//! - `rows`: mono8, a vertical line, one sample per row (against byte_sum over the image);
//! - `columns`: the same frame transposed, a horizontal line, one sample per column (against
//!   `rows` on the untransposed frame, timed in the same round);
//! - `rgb8`, `bgr8`: the frame rendered in colour, channel `red_minus_others` (against byte_sum
//!   over the same 3-byte pixels).
//!
//! Each case's detections follow the byte sum over its own image, so every detector starts
//! from a frame that was just read, as one just received from a camera is (the rows' did, the
//! others' followed other images until 2026-12-07). `columns, frame not just read` keeps the
//! earlier order, the transposed frame timed right after the rows' detections: what reading
//! the frame from further out costs the column path's first pass.
//!
//! `cargo bench -p xsurf-core --bench edge_ratio [-- ROUNDS]`
#![allow(missing_docs, clippy::unwrap_used)]

use std::hint::black_box;
use std::time::Instant;
use xsurf_core::edge::{EdgeConfig, EdgeDetector, LaserLine, Method, Orientation};
use xsurf_core::image::{Encoding, Image, ImageView};
use xsurf_core::rig::Rig;
use xsurf_core::synth::{LaserModel, ScanSettings, Scanner, Scene};

/// The same read bound as `core.rs`'s `byte_sum`: the buffer summed in 16-bit lanes.
fn byte_sum(data: &[u8]) -> u64 {
    data.chunks(128).map(|c| u64::from(c.iter().map(|&v| u16::from(v)).sum::<u16>())).sum()
}

/// The middle frame of the pyramid scan at `w` x `h` in `encoding`.
fn frame(w: u32, h: u32, encoding: Encoding) -> Image {
    let settings = ScanSettings { encoding, ..Default::default() };
    let s =
        Scanner::new(Scene::by_name("pyramid").unwrap(), Rig::study(w, h), LaserModel::default(), settings).unwrap();
    s.render(0, s.frame_count() / 2)
}

/// `img` (one byte per pixel) transposed: its vertical line horizontal.
fn transposed(img: &Image) -> Image {
    let (w, h) = (img.width, img.height);
    let mut t = Image::new(h, w, img.encoding);
    for y in 0..h {
        for x in 0..w {
            t.data[(x * h + y) as usize] = img.data[(y * w + x) as usize];
        }
    }
    t
}

/// `img` (rgb8) as bgr8.
fn as_bgr(img: &Image) -> Image {
    let mut b = img.clone();
    b.encoding = Encoding::Bgr8;
    for p in b.data.chunks_exact_mut(3) {
        p.swap(0, 2);
    }
    b
}

/// Seconds per call of `f`, over `batch` calls.
fn timed(batch: usize, mut f: impl FnMut()) -> f64 {
    let t = Instant::now();
    for _ in 0..batch {
        f();
    }
    t.elapsed().as_secs_f64() / batch as f64
}

/// The median and the 10th and 90th percentiles.
fn spread(v: &mut [f64]) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.1), at(0.9))
}

fn detector(orientation: Orientation) -> EdgeDetector {
    EdgeDetector::new(EdgeConfig {
        method: Method::CenterOfGravity,
        line_orientation: orientation,
        ..Default::default()
    })
    .unwrap()
}

fn main() {
    // `cargo bench` passes `--bench`; a number among the arguments is the round count.
    let rounds: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(200);
    println!("| image | case | byte_sum Gpx/s | detector Gpx/s | against | ratio, median | 10th-90th pct |");
    println!("|---|---|---|---|---|---|---|");
    for (w, h) in [(640u32, 480u32), (1920, 1200)] {
        let mono = frame(w, h, Encoding::Mono8);
        let cols = transposed(&mono);
        let rgb = frame(w, h, Encoding::Rgb8);
        let bgr = as_bgr(&rgb);
        let (mono_v, cols_v, rgb_v, bgr_v) =
            (mono.view().unwrap(), cols.view().unwrap(), rgb.view().unwrap(), bgr.view().unwrap());
        let (mut rows_d, mut cols_d, mut rgb_d, mut bgr_d) = (
            detector(Orientation::Vertical),
            detector(Orientation::Horizontal),
            detector(Orientation::Vertical),
            detector(Orientation::Vertical),
        );
        let mut out = LaserLine::default();
        let mut detect = |d: &mut EdgeDetector, v: &ImageView<'_>| {
            d.detect(black_box(v), &mut out).unwrap();
        };
        // About a millisecond of each per round.
        let batch = (2_000_000 / (w * h) as usize).max(1);
        let px = f64::from(w * h);
        let mut t: [Vec<f64>; 9] = Default::default();
        let sum = |data: &[u8]| {
            black_box(byte_sum(black_box(data)));
        };
        for round in 0..rounds + 10 {
            let s1 = timed(batch, || sum(&mono.data));
            let r = timed(batch, || detect(&mut rows_d, &mono_v));
            let s2 = timed(batch, || sum(&cols.data));
            let c = timed(batch, || detect(&mut cols_d, &cols_v));
            let s3 = timed(batch, || sum(&rgb.data));
            let a = timed(batch, || detect(&mut rgb_d, &rgb_v));
            let s4 = timed(batch, || sum(&bgr.data));
            let b = timed(batch, || detect(&mut bgr_d, &bgr_v));
            // The transposed frame again after the colour cases' 20 MB (as the columns were
            // timed before 2026-12-07).
            let far = timed(batch, || detect(&mut cols_d, &cols_v));
            if round >= 10 {
                for (k, v) in [s1, r, s2, c, s3, a, s4, b, far].into_iter().enumerate() {
                    t[k].push(v);
                }
            }
        }
        let rate = |k: usize| px / spread(&mut t[k].clone()).0 * 1e-9;
        let ratio = |num: usize, den: usize| {
            let mut r: Vec<f64> = t[num].iter().zip(&t[den]).map(|(n, d)| n / d).collect();
            spread(&mut r)
        };
        let line = |case: &str, sum: usize, k: usize, against: &str, base: usize| {
            let (m, lo, hi) = ratio(base, k);
            println!(
                "| {w}x{h} | {case} | {:.1} | {:.2} | {against} | **{:.0} %** | {:.0}-{:.0} % |",
                rate(sum),
                rate(k),
                100.0 * m,
                100.0 * lo,
                100.0 * hi
            );
        };
        line("rows (mono8, vertical)", 0, 1, "byte_sum", 0);
        line("columns (mono8, horizontal)", 2, 3, "rows", 1);
        line("columns, frame not just read", 2, 8, "rows", 1);
        line("rgb8", 4, 5, "byte_sum (3 bytes a pixel)", 4);
        line("bgr8", 6, 7, "byte_sum (3 bytes a pixel)", 6);
    }
}
