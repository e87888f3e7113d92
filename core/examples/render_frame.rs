//! Renders one frame of a synthetic scan to a PGM/PPM file, to look at what the scanner makes:
//! `cargo run --release -p xsurf-core --example render_frame -- SCENE WxH ideal|hard mono8|rgb8 FRAME OUT`
//! (`CAM=1`: the second camera; `SPEED`: the C-arm's speed in m/s, else the default's).
#![allow(clippy::unwrap_used, missing_docs)]

use xsurf_core::image::Encoding;
use xsurf_core::rig::Rig;
use xsurf_core::synth::{Preset, ScanSettings, Scanner, Scene};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let (w, h) = a[1].split_once('x').map(|(w, h)| (w.parse().unwrap(), h.parse().unwrap())).unwrap();
    let preset = Preset::parse(&a[2]).unwrap();
    let encoding = if a[3] == "rgb8" { Encoding::Rgb8 } else { Encoding::Mono8 };
    let mut settings = ScanSettings { encoding, ..Default::default() };
    if let Ok(v) = std::env::var("SPEED") {
        settings.speed_mps = v.parse().unwrap();
    }
    preset.apply(&mut settings);
    let s = Scanner::new(Scene::by_name(&a[0]).unwrap(), Rig::study(w, h), preset.laser(), settings).unwrap();
    let f: u32 = a[4].parse().unwrap();
    let cam: usize = std::env::var("CAM").map_or(0, |v| v.parse().unwrap());
    let img = s.render(cam, f.min(s.frame_count() - 1));
    let head = if encoding == Encoding::Rgb8 { format!("P6\n{w} {h}\n255\n") } else { format!("P5\n{w} {h}\n255\n") };
    let mut bytes = head.into_bytes();
    bytes.extend_from_slice(&img.data);
    std::fs::write(&a[5], bytes).unwrap();
}
