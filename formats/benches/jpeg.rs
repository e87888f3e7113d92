//! JPEG decode (and encode) per camera frame on one core: a rendered scan frame (the hard
//! preset: room light, speckle, the laser line) at 640x480 and 1920x1200, mono8 and rgb8,
//! encoded at quality 90 as a camera's MJPEG stream or image_transport's `compressed` plugin
//! (default 95) would be.
#![allow(clippy::unwrap_used, missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use xsurf_core::image::Encoding;
use xsurf_core::rig::Rig;
use xsurf_core::synth::{Preset, ScanSettings, Scanner, Scene};
use xsurf_formats::frames::{encode_jpeg, jpeg_frame};

fn jpeg(c: &mut Criterion) {
    for (w, h) in [(640u32, 480u32), (1920, 1200)] {
        for encoding in [Encoding::Mono8, Encoding::Rgb8] {
            let mut settings = ScanSettings { encoding, ..Default::default() };
            Preset::Hard.apply(&mut settings);
            let s = Scanner::new(Scene::by_name("phantom").unwrap(), Rig::study(w, h), Preset::Hard.laser(), settings)
                .unwrap();
            let img = s.render(0, s.frame_count() / 2);
            let bytes = encode_jpeg(&img, 90).unwrap();
            let mut g = c.benchmark_group(format!("jpeg/{w}x{h}/{}", encoding.ros_name()));
            g.throughput(Throughput::Elements(u64::from(w * h)));
            g.bench_function("decode", |b| b.iter(|| jpeg_frame(black_box(&bytes)).unwrap()));
            g.bench_function("encode_q90", |b| b.iter(|| encode_jpeg(black_box(&img), 90).unwrap()));
            g.finish();
        }
    }
}

criterion_group!(benches, jpeg);
criterion_main!(benches);
