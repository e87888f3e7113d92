//! Criterion benchmarks of the hot algorithms, grouped by image size.
//!
//! `byte_sum` reads the same buffer as the detectors and adds it up: the memory-read bound
//! that the detectors are compared against in the same run (see BENCHMARKS.md).
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use std::hint::black_box;
use xsurf_core::edge::{argmax_u8, EdgeConfig, EdgeDetector, LaserLine, Method};
use xsurf_core::fuse::{one_surface, FuseConfig};
use xsurf_core::image::{Encoding, Image};
use xsurf_core::mesh::{mesh_grid, Grid, MeshConfig};
use xsurf_core::pose::table_from_carm;
use xsurf_core::rig::Rig;
use xsurf_core::synth::{LaserModel, ScanSettings, Scanner, Scene};
use xsurf_core::triangulate::{Profile, Triangulator, TriangulatorConfig};

fn scanner(w: u32, h: u32, encoding: Encoding) -> Scanner {
    let settings = ScanSettings { encoding, ..Default::default() };
    Scanner::new(Scene::by_name("pyramid").unwrap(), Rig::study(w, h), LaserModel::default(), settings).unwrap()
}

/// Sum of all bytes, in blocks small enough for 16-bit lanes: vectorises to the read bound.
fn byte_sum(data: &[u8]) -> u64 {
    data.chunks(128).map(|c| u64::from(c.iter().map(|&v| u16::from(v)).sum::<u16>())).sum()
}

/// What every detector does first on each row: the row's maximum and its first position (the
/// strongest line). The floor under any detector's per-row cost on short rows.
fn row_argmax(data: &[u8], w: usize) -> usize {
    data.chunks_exact(w).map(|row| argmax_u8(row).unwrap_or(0)).sum()
}

fn edge_detection(c: &mut Criterion) {
    for (w, h) in [(320u32, 240u32), (640, 480), (1920, 1200)] {
        let mut g = c.benchmark_group(format!("edge_{w}x{h}"));
        g.throughput(Throughput::Elements(u64::from(w) * u64::from(h)));
        let s = scanner(w, h, Encoding::Mono8);
        let img = s.render(0, s.frame_count() / 2);
        g.bench_function("byte_sum", |b| b.iter(|| byte_sum(black_box(&img.data))));
        g.bench_function("row_argmax", |b| b.iter(|| row_argmax(black_box(&img.data), w as usize)));
        for m in [Method::CenterOfGravity, Method::Gaussian, Method::Parabolic, Method::Gradient] {
            let mut d = EdgeDetector::new(EdgeConfig { method: m, ..Default::default() }).unwrap();
            let mut out = LaserLine::default();
            let view = img.view().unwrap();
            g.bench_with_input(BenchmarkId::new("mono8", m.name()), &view, |b, v| {
                b.iter(|| d.detect(black_box(v), &mut out).unwrap())
            });
        }
        // The same with the second surfaces' line (`detect_surfaces`): what the walk along
        // each run's ends costs where the line crosses one surface per row.
        let mut d = EdgeDetector::new(EdgeConfig::default()).unwrap();
        let (mut out, mut second) = (LaserLine::default(), LaserLine::default());
        let view = img.view().unwrap();
        g.bench_function("mono8/center_of_gravity+second_surfaces", |b| {
            b.iter(|| d.detect_surfaces(black_box(&view), &mut out, &mut second).unwrap())
        });
        let rgb = scanner(w, h, Encoding::Rgb8).render(0, s.frame_count() / 2);
        let mut d = EdgeDetector::new(EdgeConfig::default()).unwrap();
        let mut out = LaserLine::default();
        let view = rgb.view().unwrap();
        g.bench_function("rgb8/center_of_gravity", |b| b.iter(|| d.detect(black_box(&view), &mut out).unwrap()));
        g.finish();
    }
}

/// Several lasers (issue 20): one frame of the three-laser scanner (red, green and blue planes)
/// read by one laser's detector and by three (every channel extracted in one pass), beside
/// byte_sum over the same bytes.
fn several_lasers(c: &mut Criterion) {
    use xsurf_core::edge::{Channel, LaserColor, LaserDetectors};
    let (w, h) = (640u32, 480u32);
    let mut g = c.benchmark_group(format!("lasers_{w}x{h}"));
    g.throughput(Throughput::Elements(u64::from(w) * u64::from(h)));
    let settings = ScanSettings { encoding: Encoding::Rgb8, ..Default::default() };
    let s =
        Scanner::new(Scene::by_name("box").unwrap(), Rig::three_lasers(w, h), LaserModel::default(), settings).unwrap();
    let img = s.render(0, s.frame_count() / 2);
    let view = img.view().unwrap();
    g.bench_function("byte_sum", |b| b.iter(|| byte_sum(black_box(&img.data))));
    let config = |c| EdgeConfig { channel: Channel::against_others(c), ..Default::default() };
    for (name, colours) in [
        ("rgb8/one_laser", vec![LaserColor::Red]),
        ("rgb8/three_lasers", vec![LaserColor::Red, LaserColor::Green, LaserColor::Blue]),
    ] {
        let mut d = LaserDetectors::new(colours.into_iter().map(config).collect()).unwrap();
        let mut out = Vec::new();
        g.bench_function(name, |b| b.iter(|| d.detect(black_box(&view), &mut out).unwrap()));
    }
    g.finish();
}

fn triangulation(c: &mut Criterion) {
    let mut g = c.benchmark_group("triangulate_640x480");
    let s = scanner(640, 480, Encoding::Mono8);
    let img: Image = s.render(0, s.frame_count() / 2);
    let mut line = LaserLine::default();
    EdgeDetector::new(EdgeConfig::default()).unwrap().detect(&img.view().unwrap(), &mut line).unwrap();
    let rig = Rig::study(640, 480);
    let tri = Triangulator::new(rig.cameras[0].geometry().unwrap(), &TriangulatorConfig::default()).unwrap();
    let mut prof = Profile::default();
    g.throughput(Throughput::Elements(line.found() as u64));
    let pose = table_from_carm(0.1, 0.0, 0.0);
    g.bench_function("points", |b| b.iter(|| tri.triangulate(black_box(&line), &pose, &mut prof)));
    g.finish();
}

/// A 480 x 390 grid (the study's full-body size) of a wavy surface with a few holes.
fn body_grid() -> Grid {
    camera_grid(0.0, |_| 100.0)
}

/// The wavy surface as one camera samples it: shifted by `shift` metres across, with a line
/// strength that depends on the position across (x).
fn camera_grid(shift: f32, strength: impl Fn(f32) -> f32) -> Grid {
    let (ns, nf) = (480usize, 390usize);
    let mut g = Grid::new(ns);
    for f in 0..nf {
        let y = f as f32 * 0.0047;
        let points: Vec<[f32; 3]> = (0..ns)
            .map(|s| {
                let x = s as f32 * 0.00125 - 0.3 + shift;
                if (s * 7 + f * 13) % 97 == 0 {
                    [f32::NAN; 3]
                } else {
                    [x, y, 0.1 * (x * 8.0).cos().max(0.0) + 0.01 * (y * 20.0).sin()]
                }
            })
            .collect();
        g.push(
            f as i64,
            &Profile {
                intensity: points.iter().map(|p: &[f32; 3]| strength(p[0])).collect(),
                points,
                rgb: None,
                range: vec![0.9; ns],
                outside_volume: 0,
            },
        )
        .unwrap();
    }
    g
}

fn meshing(c: &mut Criterion) {
    let mut g = c.benchmark_group("mesh_480x390");
    g.sample_size(20);
    let grid = body_grid();
    g.throughput(Throughput::Elements(grid.points().len() as u64));
    g.bench_function("mesh", |b| b.iter(|| mesh_grid(black_box(&grid), &MeshConfig::default())));
    let cfg = MeshConfig { smooth_iterations: 3, ..Default::default() };
    g.bench_function("mesh_fill_smooth3", |b| {
        b.iter(|| {
            let mut gg = grid.clone();
            gg.fill_single_holes(0.01);
            mesh_grid(&gg, &cfg)
        })
    });
    g.finish();
}

/// The merger's work for a full-body pair (issue: two-camera merging, target < 200 ms on one
/// core): fuse the overlapping grids into one layer, mesh both, combine.
fn merging(c: &mut Criterion) {
    let mut g = c.benchmark_group("merge_2x480x390");
    g.sample_size(10);
    let a = camera_grid(0.0, |x| 120.0 - 100.0 * x);
    let b = camera_grid(0.0006, |x| 120.0 + 100.0 * x);
    g.throughput(Throughput::Elements((a.points().len() + b.points().len()) as u64));
    let merge = |fuse: Option<FuseConfig>| {
        let mut grids = [a.clone(), b.clone()];
        if let Some(f) = fuse {
            one_surface(&mut grids, &f);
        }
        let mut merged = mesh_grid(&grids[0], &MeshConfig::default());
        merged.append(&mesh_grid(&grids[1], &MeshConfig::default()));
        merged
    };
    g.bench_function("fuse_mesh_combine", |bch| bch.iter(|| merge(Some(FuseConfig::default()))));
    // The second camera's placement refined against the first before fusing (the merger's
    // default): a camera above the scene, the laser plane y = travel in carm.
    let cam = Iso3::look_at(Vec3::new(0.25, 0.4, 0.8), Vec3::new(0.0, 0.0, 0.05), -Vec3::X).unwrap();
    let plane = Plane::from_params([0.0, 1.0, 0.0, 0.0]).unwrap();
    let motion = ScanMotion { table_from_carm: Iso3::IDENTITY };
    g.bench_function("refine_only", |bch| {
        bch.iter(|| {
            let mut second = b.clone();
            // The pair needs no correction, so the refinement refuses one, after the same work.
            let _ = refine_grid(&a, &mut second, &cam, &plane, &motion, &RefineConfig::default());
            second
        })
    });
    // Both grids meshed and combined, with each vertex's camera.
    let cfg = MeshConfig::default();
    let combined = |grids: &[Grid], cfg: &MeshConfig| {
        let mut merged = mesh_grid(&grids[0], cfg);
        let mut camera = vec![0u8; merged.positions.len()];
        let second = mesh_grid(&grids[1], cfg);
        camera.extend(vec![1u8; second.positions.len()]);
        merged.append(&second);
        (merged, camera)
    };
    // The merger's whole job with its defaults: refine, fuse, mesh both, combine, zipper, close
    // the small holes.
    g.bench_function("refine_fuse_mesh_combine_zipper_fill", |bch| {
        bch.iter(|| {
            let mut grids = [a.clone(), b.clone()];
            let (first, second) = grids.split_at_mut(1);
            let _ = refine_grid(&first[0], &mut second[0], &cam, &plane, &motion, &RefineConfig::default());
            one_surface(&mut grids, &FuseConfig::default());
            let (mut merged, camera) = combined(&grids, &cfg);
            zipper(&mut merged, &camera, cfg.max_edge_m, cfg.min_angle_deg);
            fill_holes(&mut merged, cfg.max_edge_m, 64);
            merged
        })
    });
    g.bench_function("mesh_combine_no_fuse", |bch| bch.iter(|| merge(None)));
    // The seam steps alone, on the fused pair.
    {
        let mut grids = [a.clone(), b.clone()];
        one_surface(&mut grids, &FuseConfig::default());
        let (mut merged, camera) = combined(&grids, &cfg);
        g.bench_function("zipper_only", |bch| {
            bch.iter(|| {
                let mut m = merged.clone();
                zipper(&mut m, &camera, cfg.max_edge_m, cfg.min_angle_deg);
                m
            })
        });
        zipper(&mut merged, &camera, cfg.max_edge_m, cfg.min_angle_deg);
        g.bench_function("fill_only", |bch| {
            bch.iter(|| {
                let mut m = merged.clone();
                fill_holes(&mut m, cfg.max_edge_m, 64)
            })
        });
    }
    g.finish();
}

use xsurf_core::geom::{Iso3, Plane, Vec3};
use xsurf_core::holes::fill_holes;
use xsurf_core::register::{refine_grid, RefineConfig, ScanMotion};
use xsurf_core::zipper::zipper;

criterion_group!(benches, edge_detection, several_lasers, triangulation, meshing, merging);
criterion_main!(benches);
