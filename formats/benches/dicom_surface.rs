//! The surface as DICOM (issue 21): a full-body merge's size (two cameras' grids of 480 samples
//! by 390 frames, 374 400 points, about 745 000 triangles) encoded as a Surface Scan Mesh file,
//! beside the same mesh written as binary PLY in the same run (the reference: a plain copy of
//! the same arrays), and as the VRML scene's text. Sending it to a PACS: `scripts/bench-pacs.sh`.
#![allow(clippy::unwrap_used, missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use xsurf_core::mesh::Mesh;
use xsurf_formats::dicom_surface::{surface_mesh_bytes, uid_for, Equipment, Instance, Study};

/// Two grids of `samples` x `frames` over a body-sized surface, each meshed as its grid.
fn full_body(samples: u32, frames: u32) -> Mesh {
    let mut m = Mesh::default();
    for cam in 0..2u32 {
        let base = m.positions.len() as u32;
        for f in 0..frames {
            for s in 0..samples {
                let x = -0.25 + 0.5 * f64::from(s) / f64::from(samples) + 0.01 * f64::from(cam);
                let y = 1.6 * f64::from(f) / f64::from(frames);
                let z = 0.1 + 0.05 * (x * 9.0).cos() * (y * 4.0).sin();
                m.positions.push([x as f32, y as f32, z as f32]);
                m.colors.push([200, 170, 150]);
            }
        }
        for f in 0..frames - 1 {
            for s in 0..samples - 1 {
                let a = base + f * samples + s;
                let (b, c, d) = (a + 1, a + samples, a + samples + 1);
                m.triangles.push([a, b, c]);
                m.triangles.push([b, d, c]);
            }
        }
    }
    m
}

fn surface(c: &mut Criterion) {
    let mesh = full_body(480, 390);
    let study = Study { study_instance_uid: uid_for("bench/study"), patient_id: "BENCH".into(), ..Study::default() };
    let equipment = Equipment {
        manufacturer: "xsurf".into(),
        model_name: "bench".into(),
        device_serial_number: "0".into(),
        software_versions: "0".into(),
        station_name: String::new(),
        institution_name: String::new(),
    };
    let inst = Instance {
        study: &study,
        equipment: &equipment,
        series_instance_uid: uid_for("bench/series"),
        series_number: 1001,
        series_description: "bench".into(),
        sop_instance_uid: uid_for("bench/instance"),
        frame_of_reference_uid: uid_for("bench/frame"),
        acquisition_start_ns: 1_700_000_000_000_000_000,
        acquisition_duration_s: 13.0,
        acquisition_number: 1,
        opacity: 0.7,
    };
    let bytes = surface_mesh_bytes(&mesh, &inst).unwrap().len();
    eprintln!(
        "full body: {} points, {} triangles, surface.dcm {bytes} bytes",
        mesh.positions.len(),
        mesh.triangles.len()
    );
    let mut g = c.benchmark_group("full_body_surface");
    g.sample_size(20);
    g.throughput(Throughput::Bytes(bytes as u64));
    g.bench_function("surface_dcm", |b| b.iter(|| surface_mesh_bytes(black_box(&mesh), &inst).unwrap()));
    g.bench_function("ply", |b| {
        b.iter(|| {
            let mut v = Vec::with_capacity(bytes);
            xsurf_formats::ply::write(&mut v, black_box(&mesh)).unwrap();
            v
        })
    });
    g.bench_function("scene_wrl", |b| {
        let scene = xsurf_formats::scene::Scene {
            surfaces: vec![xsurf_formats::scene::Surface { name: "merged", mesh: &mesh, transparency: 0.3 }],
            plane: None,
        };
        b.iter(|| {
            let mut v = Vec::with_capacity(4 * bytes);
            xsurf_formats::vrml::write(&mut v, black_box(&scene)).unwrap();
            v
        })
    });
    g.finish();
}

criterion_group!(benches, surface);
criterion_main!(benches);
