//! The centre-of-gravity detector's rate as a fraction of the plain byte sum's, measured in
//! alternation: each round times a batch of byte sums over an image, then a batch of detections
//! of the same image, so that both see the same state of a shared, noisy machine. Prints the
//! median ratio over the rounds and its spread (10th-90th percentile), per image size.
//!
//! `cargo bench -p xsurf-core --bench edge_ratio [-- ROUNDS]`
#![allow(missing_docs, clippy::unwrap_used)]

use std::hint::black_box;
use std::time::Instant;
use xsurf_core::edge::{EdgeConfig, EdgeDetector, LaserLine, Method};
use xsurf_core::image::Encoding;
use xsurf_core::rig::Rig;
use xsurf_core::synth::{LaserModel, ScanSettings, Scanner, Scene};

/// The same read bound as `core.rs`'s `byte_sum`: the buffer summed in 16-bit lanes.
fn byte_sum(data: &[u8]) -> u64 {
    data.chunks(128).map(|c| u64::from(c.iter().map(|&v| u16::from(v)).sum::<u16>())).sum()
}

fn main() {
    // `cargo bench` passes `--bench`; a number among the arguments is the round count.
    let rounds: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(200);
    println!("| image | byte_sum Gpx/s | center_of_gravity Gpx/s | ratio, median | 10th-90th pct | rounds |");
    println!("|---|---|---|---|---|---|");
    for (w, h) in [(320u32, 240u32), (640, 480), (1920, 1200)] {
        let settings = ScanSettings { encoding: Encoding::Mono8, ..Default::default() };
        let s = Scanner::new(Scene::by_name("pyramid").unwrap(), Rig::study(w, h), LaserModel::default(), settings)
            .unwrap();
        let img = s.render(0, s.frame_count() / 2);
        let view = img.view().unwrap();
        let mut d = EdgeDetector::new(EdgeConfig { method: Method::CenterOfGravity, ..Default::default() }).unwrap();
        let mut out = LaserLine::default();
        // About a millisecond of each per round.
        let batch = (2_000_000 / (w * h) as usize).max(1);
        let px = (w * h) as f64 * batch as f64;
        let (mut sums, mut cogs, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
        for round in 0..rounds + 10 {
            let t = Instant::now();
            for _ in 0..batch {
                black_box(byte_sum(black_box(&img.data)));
            }
            let a = t.elapsed().as_secs_f64();
            let t = Instant::now();
            for _ in 0..batch {
                d.detect(black_box(&view), &mut out).unwrap();
            }
            let b = t.elapsed().as_secs_f64();
            if round >= 10 {
                sums.push(px / a * 1e-9);
                cogs.push(px / b * 1e-9);
                ratios.push(a / b);
            }
        }
        let pct = |v: &mut Vec<f64>, q: f64| {
            v.sort_by(f64::total_cmp);
            v[((v.len() - 1) as f64 * q).round() as usize]
        };
        println!(
            "| {w}x{h} mono8 | {:.1} | {:.2} | **{:.0} %** | {:.0}-{:.0} % | {rounds} |",
            pct(&mut sums, 0.5),
            pct(&mut cogs, 0.5),
            100.0 * pct(&mut ratios, 0.5),
            100.0 * pct(&mut ratios, 0.1),
            100.0 * pct(&mut ratios, 0.9),
        );
    }
}
