//! Reconstruction accuracy against the synthetic scanner's ground truth (issue: reconstruction
//! core). Two cameras, the study's pyramid; the study's `gradient` method measured alongside.
#![allow(clippy::unwrap_used)]

use xsurf_core::edge::{EdgeConfig, EdgeDetector, LaserLine, Method, Orientation};
use xsurf_core::eval::{accuracy, coverage, pyramid_extents, surface_errors, Accuracy, PyramidExtents};
use xsurf_core::geom::Vec3;
use xsurf_core::mesh::{mesh_grid, Grid, MeshConfig};
use xsurf_core::pose::PoseTrack;
use xsurf_core::rig::Rig;
use xsurf_core::synth::{LaserModel, ScanSettings, Scanner, Scene};
use xsurf_core::triangulate::{Profile, Triangulator, TriangulatorConfig};

struct Outcome {
    acc: Accuracy,
    coverage: f64,
    extents: Option<PyramidExtents>,
    triangles: usize,
}

fn scan(width: u32, height: u32, speed: f64, method: Method) -> Outcome {
    scan_with(Rig::study(width, height), speed, method)
}

/// The pyramid scanned with `rig`, each camera's detector told the orientation the scanner
/// says its line has (as `xsurf synth` writes it into the bag's parameters).
fn scan_with(rig: Rig, speed: f64, method: Method) -> Outcome {
    let (width, height) = (rig.cameras[0].width, rig.cameras[0].height);
    let settings = ScanSettings { speed_mps: speed, ..Default::default() };
    let scanner =
        Scanner::new(Scene::by_name("pyramid").unwrap(), rig.clone(), LaserModel::default(), settings).unwrap();
    // The C-arm pose as c_arm_pose would publish it: 100 Hz samples of the speed model.
    let mut poses = PoseTrack::default();
    let t_end = scanner.duration_s() + 0.1;
    let mut t = -0.1;
    while t <= t_end {
        poses.push(scanner.settings.start_stamp_ns + (t * 1e9).round() as i64, &scanner.pose_at(t));
        t += 0.01;
    }
    let tri_cfg = TriangulatorConfig { laser_plane: rig.laser_plane, ..Default::default() };
    let mut all_points = Vec::new();
    let mut truth = Vec::new();
    let mut triangles = 0;
    for (ci, cam) in rig.cameras.iter().enumerate() {
        let tri = Triangulator::new(cam.geometry().unwrap(), &tri_cfg).unwrap();
        let line_orientation = scanner.line_orientation(ci);
        let mut det = EdgeDetector::new(EdgeConfig { method, line_orientation, ..Default::default() }).unwrap();
        let samples = if line_orientation == Orientation::Vertical { cam.height } else { cam.width };
        let mut grid = Grid::new(samples as usize);
        let mut line = LaserLine::default();
        let mut prof = Profile::default();
        for f in 0..scanner.frame_count() {
            let ft = scanner.frame_time(f);
            let img = scanner.render(ci, f);
            det.detect(&img.view().unwrap(), &mut line).unwrap();
            tri.triangulate(&line, &poses.at(ft.stamp_ns).unwrap(), &mut prof);
            grid.push(ft.stamp_ns, &prof).unwrap();
            truth.extend(scanner.observable_points(ci, f, tri_cfg.min_ray_plane_angle_deg));
        }
        let mesh = mesh_grid(&grid, &MeshConfig::default());
        triangles += mesh.triangles.len();
        all_points.extend_from_slice(grid.points());
    }
    let scene = &scanner.scene;
    let acc = accuracy(surface_errors(scene, &all_points));
    let cov = coverage(&truth, &all_points, 0.003);
    let extents = pyramid_extents(scene, &all_points);
    eprintln!(
        "{width}x{height} {speed} m/s {:?}: {} points, rms {:.3} mm, p99 {:.3} mm, max {:.2} mm, >2mm {:.3} %, coverage {:.2} % of {} truth, extents {:?}, {} triangles",
        method,
        acc.points,
        acc.rms_m * 1e3,
        acc.p99_m * 1e3,
        acc.max_m * 1e3,
        acc.outlier_fraction_2mm * 100.0,
        cov * 100.0,
        truth.len(),
        extents,
        triangles
    );
    let _ = Vec3::ZERO;
    Outcome { acc, coverage: cov, extents, triangles }
}

fn check_extents(e: Option<PyramidExtents>) {
    let e = e.expect("pyramid measurable");
    assert!((e.base_x_m - 0.210).abs() < 0.001, "base x {e:?}");
    assert!((e.base_y_m - 0.297).abs() < 0.001, "base y {e:?}");
    assert!((e.height_m - 0.086).abs() < 0.001, "height {e:?}");
}

#[test]
fn pyramid_640x480_70mm_s_meets_the_bounds_and_beats_the_study_method() {
    let o = scan(640, 480, 0.070, Method::CenterOfGravity);
    assert!(o.acc.outlier_fraction_2mm < 0.005, "outliers {}", o.acc.outlier_fraction_2mm);
    assert!(o.acc.rms_m <= 0.0005, "rms {}", o.acc.rms_m);
    assert!(o.coverage >= 0.95, "coverage {}", o.coverage);
    assert!(o.triangles > 0);
    check_extents(o.extents);
    let study = scan(640, 480, 0.070, Method::Gradient);
    assert!(
        study.acc.rms_m > 2.0 * o.acc.rms_m,
        "the study's method should be clearly worse: {} vs {}",
        study.acc.rms_m,
        o.acc.rms_m
    );
}

#[test]
fn pyramid_640x480_other_subpixel_methods() {
    for m in [Method::Gaussian, Method::Parabolic] {
        let o = scan(640, 480, 0.070, m);
        assert!(o.acc.rms_m <= 0.0005, "{m:?} rms {}", o.acc.rms_m);
        assert!(o.coverage >= 0.95, "{m:?} coverage {}", o.coverage);
    }
}

#[test]
fn pyramid_320x240_140mm_s_meets_the_bounds() {
    let o = scan(320, 240, 0.140, Method::CenterOfGravity);
    assert!(o.acc.outlier_fraction_2mm < 0.005, "outliers {}", o.acc.outlier_fraction_2mm);
    assert!(o.acc.rms_m <= 0.0010, "rms {}", o.acc.rms_m);
    assert!(o.coverage >= 0.95, "coverage {}", o.coverage);
    check_extents(o.extents);
}

/// A camera hung on its side (cam2 turned a quarter turn about its optical axis): its line runs
/// along the image rows, the scanner says so, and the columns' path of the detector gives the
/// same bounds as the upright rig.
#[test]
fn pyramid_640x480_with_a_camera_on_its_side_meets_the_same_bounds() {
    let mut rig = Rig::study(640, 480);
    rig.cameras[1].roll_quarter_turn();
    let scanner = Scanner::new(
        Scene::by_name("pyramid").unwrap(),
        rig.clone(),
        LaserModel::default(),
        ScanSettings { speed_mps: 0.070, ..Default::default() },
    )
    .unwrap();
    assert_eq!(scanner.line_orientation(0), Orientation::Vertical);
    assert_eq!(scanner.line_orientation(1), Orientation::Horizontal);
    let upright = Scanner::new(
        Scene::by_name("pyramid").unwrap(),
        Rig::study(640, 480),
        LaserModel::default(),
        ScanSettings::default(),
    )
    .unwrap();
    assert_eq!(upright.line_orientation(1), Orientation::Vertical);
    let o = scan_with(rig, 0.070, Method::CenterOfGravity);
    assert!(o.acc.outlier_fraction_2mm < 0.005, "outliers {}", o.acc.outlier_fraction_2mm);
    assert!(o.acc.rms_m <= 0.0005, "rms {}", o.acc.rms_m);
    assert!(o.coverage >= 0.95, "coverage {}", o.coverage);
    assert!(o.triangles > 0);
    check_extents(o.extents);
}
