//! One surface from two cameras (issue: two-camera merging): the study's pyramid scanned by
//! both cameras, fused; measured against the synthetic truth.
#![allow(clippy::unwrap_used)]

mod common;

use xsurf_core::eval::{accuracy, coverage, mesh_coverage, surface_errors};
use xsurf_core::fuse::{min_cross_distance, one_surface, FuseConfig};
use xsurf_core::mesh::{mesh_grid, Grid, MeshConfig};
use xsurf_core::rig::Rig;
use xsurf_core::synth::{LaserModel, ScanSettings, Scanner, Scene};
use xsurf_core::triangulate::TriangulatorConfig;
use xsurf_core::zipper::zipper;

/// The pyramid at 320x240 and 140 mm/s: the scanner, each camera's grid, and the points the
/// cameras can observe (the truth).
fn pyramid_scan() -> (Scanner, Vec<Grid>, Vec<xsurf_core::geom::Vec3>) {
    let rig = Rig::study(320, 240);
    let settings = ScanSettings { speed_mps: 0.14, ..Default::default() };
    let scanner =
        Scanner::new(Scene::by_name("pyramid").unwrap(), rig.clone(), LaserModel::default(), settings).unwrap();
    let grids = common::camera_grids(&scanner, &rig);
    let min_angle = TriangulatorConfig::default().min_ray_plane_angle_deg;
    let mut truth = Vec::new();
    for ci in 0..rig.cameras.len() {
        for f in 0..scanner.frame_count() {
            truth.extend(scanner.observable_points(ci, f, min_angle));
        }
    }
    (scanner, grids, truth)
}

#[test]
fn fused_pyramid_has_one_layer_full_coverage_and_no_loss_of_accuracy() {
    let (scanner, mut grids, truth) = pyramid_scan();
    let all =
        |g: &[Grid]| g.iter().flat_map(|g| g.points().iter().copied().filter(|p| p[0].is_finite())).collect::<Vec<_>>();
    let before = all(&grids);
    let (acc0, cov0, d0) = (
        accuracy(surface_errors(&scanner.scene, &before)),
        coverage(&truth, &before, 0.003),
        min_cross_distance(&grids),
    );
    let fuse = FuseConfig::default();
    let report = one_surface(&mut grids, &fuse);
    let after = all(&grids);
    let (acc1, cov1, d1) =
        (accuracy(surface_errors(&scanner.scene, &after)), coverage(&truth, &after, 0.003), min_cross_distance(&grids));
    eprintln!(
        "before: {} points, rms {:.3} mm, coverage {:.2} %, closest cross pair {:.3} mm\nafter: {} points, rms {:.3} mm, coverage {:.2} %, closest cross pair {:.3} mm; {report:?}",
        before.len(), acc0.rms_m * 1e3, cov0 * 100.0, d0 * 1e3, after.len(), acc1.rms_m * 1e3, cov1 * 100.0, d1 * 1e3
    );
    assert!(d0 < 0.0005, "the cameras overlap before fusing");
    assert!(d1 >= fuse.min_distance_m, "closest samples of different cameras {d1} m");
    assert!(cov1 >= 0.95, "coverage of what both cameras observe {cov1}");
    assert!(acc1.rms_m <= acc0.rms_m * 1.05, "rms {} -> {}", acc0.rms_m, acc1.rms_m);
    assert!(report.dropped.iter().sum::<usize>() > before.len() / 5, "{report:?}");
    // Each camera's mesh keeps its own region: neither disappears.
    for g in &grids {
        assert!(mesh_grid(g, &MeshConfig::default()).triangles.len() > 1000);
    }
}

/// The merged mesh after fusing has a strip of no triangles wherever ownership changes between
/// the cameras; the zipper closes it. Measured as the truth covered by triangles (not only by
/// vertices), against both cameras meshed as they are before fusing (a double layer).
#[test]
fn zippered_pyramid_has_no_seam_gaps() {
    let (scanner, mut grids, truth) = pyramid_scan();
    let cfg = MeshConfig::default();
    let merged = |grids: &[Grid]| {
        let mut m = xsurf_core::mesh::Mesh::default();
        let mut camera = Vec::new();
        for (k, g) in grids.iter().enumerate() {
            let mesh = mesh_grid(g, &cfg);
            camera.extend(std::iter::repeat_n(k as u8, mesh.positions.len()));
            m.append(&mesh);
        }
        (m, camera)
    };
    let r = 0.001;
    let (unfused, _) = merged(&grids);
    let cov_unfused = mesh_coverage(&truth, &unfused, r);
    one_surface(&mut grids, &FuseConfig::default());
    let (mut fused, camera) = merged(&grids);
    let cov_fused = mesh_coverage(&truth, &fused, r);
    let report = zipper(&mut fused, &camera, cfg.max_edge_m, cfg.min_angle_deg);
    let cov_zipped = mesh_coverage(&truth, &fused, r);
    let acc = accuracy(surface_errors(&scanner.scene, &fused.positions));
    eprintln!(
        "truth within 1 mm of a triangle: both cameras unfused {:.2} %, fused {:.2} %, zippered {:.2} %; {report:?}",
        cov_unfused * 100.0,
        cov_fused * 100.0,
        cov_zipped * 100.0
    );
    // Measured: 99.90 % unfused, 99.47 % fused, 99.82 % zippered (before fusing gave orphans
    // back, 98.89 % fused and 99.23 % zippered: strips one sample wide kept by the wrong camera).
    assert!(cov_fused < cov_unfused - 0.002, "fusing opens seams: {cov_fused} vs {cov_unfused}");
    assert!(cov_zipped > cov_fused + 0.002, "zippered {cov_zipped} vs fused {cov_fused}");
    assert!(cov_zipped >= cov_unfused - 0.002, "seams left open: zippered {cov_zipped} vs unfused {cov_unfused}");
    assert!(report.bridges > 100 && report.closings > 100, "{report:?}");
    assert!(acc.rms_m < 0.001, "{acc:?}");
    // Every triangle is used once per directed edge: no overlap, no flip.
    let mut e: Vec<(u32, u32)> =
        fused.triangles.iter().flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]).collect();
    e.sort_unstable();
    assert!(e.windows(2).all(|w| w[0] != w[1]), "a directed edge is used twice");
}
