//! The second camera's placement refined against the first camera's surface (issue: two-camera
//! merging that needs no hand): the synthetic pyramid, cam2's calibration perturbed by 2 mm and
//! 0.3 degrees, measured against the true placement and the true surface.
#![allow(clippy::unwrap_used)]

use xsurf_core::edge::{EdgeConfig, EdgeDetector, LaserLine};
use xsurf_core::eval::{accuracy, surface_errors};
use xsurf_core::geom::{Iso3, Plane, Quat, Vec3};
use xsurf_core::mesh::Grid;
use xsurf_core::register::{refine_camera, refine_grid, Observation, Reference, RefineConfig, RefineError, ScanMotion};

use xsurf_core::rig::Rig;
use xsurf_core::synth::{LaserModel, ScanSettings, Scanner, Scene};
use xsurf_core::triangulate::{CameraGeometry, Profile, Triangulator, TriangulatorConfig};

struct Scan {
    rig: Rig,
    scanner: Scanner,
    /// Per camera, per frame: the detected line and the frame's pose.
    lines: Vec<Vec<(LaserLine, Iso3, i64)>>,
}

fn scan() -> Scan {
    let rig = Rig::study(640, 480);
    let settings = ScanSettings { speed_mps: 0.07, ..Default::default() };
    let scanner =
        Scanner::new(Scene::by_name("pyramid").unwrap(), rig.clone(), LaserModel::default(), settings).unwrap();
    let mut lines = Vec::new();
    for ci in 0..rig.cameras.len() {
        let mut det = EdgeDetector::new(EdgeConfig::default()).unwrap();
        let mut v = Vec::new();
        for f in 0..scanner.frame_count() {
            let ft = scanner.frame_time(f);
            let mut line = LaserLine::default();
            det.detect(&scanner.render(ci, f).view().unwrap(), &mut line).unwrap();
            v.push((line, scanner.pose_at(scanner.seconds_of(ft.stamp_ns)), ft.stamp_ns));
        }
        lines.push(v);
    }
    Scan { rig, scanner, lines }
}

/// The camera's grid triangulated with `carm_from_optical`, and each point's frame pose.
fn grid(s: &Scan, ci: usize, carm_from_optical: &Iso3) -> (Grid, Vec<(Vec3, Iso3)>) {
    let model = s.rig.cameras[ci].model().unwrap();
    let cfg = TriangulatorConfig { laser_plane: s.rig.laser_plane, ..Default::default() };
    let tri = Triangulator::new(CameraGeometry { model, carm_from_optical: *carm_from_optical }, &cfg).unwrap();
    let mut g = Grid::new(480);
    let mut pts = Vec::new();
    let mut prof = Profile::default();
    for (line, pose, stamp) in &s.lines[ci] {
        tri.triangulate(line, pose, &mut prof);
        g.push(*stamp, &prof).unwrap();
        for p in &prof.points {
            if p[0].is_finite() {
                pts.push((Vec3::new(p[0].into(), p[1].into(), p[2].into()), *pose));
            }
        }
    }
    (g, pts)
}

fn rms_mm(scene: &Scene, pts: &[Vec3]) -> f64 {
    let p: Vec<[f32; 3]> = pts.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
    accuracy(surface_errors(scene, &p)).rms_m * 1e3
}

fn finite(g: &Grid) -> impl Iterator<Item = Vec3> + '_ {
    g.points().iter().map(|p| Vec3::new(p[0].into(), p[1].into(), p[2].into())).filter(|p| p.is_finite())
}

fn perturb(e: &Iso3, mm: f64, deg: f64) -> Iso3 {
    let axis = Vec3::new(0.3, -0.5, 0.8).try_normalize().unwrap();
    let dir = Vec3::new(1.0, 1.0, -1.0).try_normalize().unwrap();
    let r = Quat::from_axis_angle(axis, deg.to_radians()).to_mat3();
    Iso3 { rotation: r.mul_mat(&e.rotation), translation: e.translation + dir * (mm * 1e-3) }
}

fn placement_error(truth: &Iso3, e: &Iso3) -> (f64, f64) {
    ((e.translation - truth.translation).norm() * 1e3, truth.rotation.angle_to(&e.rotation).to_degrees())
}

#[test]
fn perturbed_second_camera_is_recovered_and_the_merge_is_as_good_as_calibrated() {
    let s = scan();
    let plane = Plane::from_params(s.rig.laser_plane).unwrap();
    let e1 = s.rig.cameras[0].carm_from_optical();
    let e2 = s.rig.cameras[1].carm_from_optical();
    let (g1, _) = grid(&s, 0, &e1);
    let (g2_true, _) = grid(&s, 1, &e2);
    let rms_true = rms_mm(&s.scanner.scene, &finite(&g1).chain(finite(&g2_true)).collect::<Vec<_>>());
    let motion = ScanMotion { table_from_carm: s.lines[1][0].1 };

    let bad = perturb(&e2, 2.0, 0.3);
    let (mut g2, p2_bad) = grid(&s, 1, &bad);
    let rms_bad = rms_mm(&s.scanner.scene, &finite(&g1).chain(finite(&g2)).collect::<Vec<_>>());
    let t = std::time::Instant::now();
    let cfg = RefineConfig::default();
    let r = refine_grid(&g1, &mut g2, &bad, &plane, &motion, &cfg).unwrap_or_else(|e| panic!("{e}"));
    let took = t.elapsed();
    let (dt_mm, dr_deg) = placement_error(&e2, &r.carm_from_optical);
    let rms_refined = rms_mm(&s.scanner.scene, &finite(&g1).chain(finite(&g2)).collect::<Vec<_>>());
    eprintln!(
        "refine: {} iterations, {} points, {took:?}; {:.0} sigma (1-sigma {:.3} mm / {:.4} deg alone); residual RMS {:.3} -> {:.3} mm, overlap {:.0} %; \
         placement error {dt_mm:.3} mm / {dr_deg:.4} deg (perturbed 2 mm / 0.3 deg); merged RMS: calibrated \
         {rms_true:.3}, perturbed {rms_bad:.3}, refined {rms_refined:.3} mm",
        r.iterations,
        r.points,
        r.significance,
        r.sigma_translation_m * 1e3,
        r.sigma_rotation_deg,
        r.rms_before_m * 1e3,
        r.rms_after_m * 1e3,
        r.overlap_fraction * 100.0
    );
    assert!(rms_bad > 1.5 * rms_true, "the perturbation must matter: {rms_bad} vs {rms_true}");
    // The bounds: the merge within 10 % of the calibrated one, the placement within
    // 0.3 mm and 0.05 degrees of the truth.
    assert!(rms_refined <= 1.1 * rms_true, "merged RMS {rms_refined} vs calibrated {rms_true}");
    // The detector no longer locks to pixels, and what is left of the shift-and-turn valley of
    // a narrow view on the ideal renders is 0.3-0.4 mm along it (the merged surface is as good
    // as the calibrated one, above).
    assert!(dt_mm < 0.4, "translation error {dt_mm} mm");
    assert!(dr_deg < 0.05, "rotation error {dr_deg} deg");
    // Every measured point was moved, none lost.
    assert_eq!(g2.valid(), g2_true.valid());

    // A correctly calibrated camera is left where it is: the correction the noise asks for is
    // within its uncertainty, or barely lowers the residual, and is refused with the numbers.
    let mut g2_exact = g2_true.clone();
    match refine_grid(&g1, &mut g2_exact, &e2, &plane, &motion, &cfg) {
        Err(e @ RefineError::NotSignificant { .. }) => eprintln!("exact calibration kept: {e}"),
        Ok(r) => {
            let (dt, dr) = placement_error(&e2, &r.carm_from_optical);
            assert!(dt < 0.5 && dr < 0.05, "a correct calibration moved by {dt} mm / {dr} deg");
        }
        Err(e) => panic!("{e}"),
    }

    // Refusals leave the grid as it was: no overlap (the reference elsewhere) ...
    let obs: Vec<Observation> = p2_bad.iter().filter_map(|(p, pose)| Observation::from_point(*p, pose, &bad)).collect();
    let cam1: Vec<Vec3> = finite(&g1).collect();
    let far: Vec<Vec3> = cam1.iter().map(|p| *p + Vec3::new(0.0, 1.0, 0.0)).collect();
    let far_ref = Reference::new(&far, &vec![Vec3::Z; far.len()]).unwrap();
    let e = refine_camera(&far_ref, &obs, &bad, &plane, &cfg).unwrap_err();
    assert!(matches!(e, RefineError::TooLittleOverlap { .. }), "{e}");
    let (mut g2, _) = grid(&s, 1, &bad);
    let before = g2.clone();
    let mut shifted = g1.clone();
    shifted.points_mut().iter_mut().for_each(|p| p[1] += 1.0);
    let e = refine_grid(&shifted, &mut g2, &bad, &plane, &motion, &cfg).unwrap_err();
    assert!(matches!(e, RefineError::TooLittleOverlap { .. }), "{e}");
    assert!(g2.points().iter().zip(before.points()).all(|(a, b)| a == b || (a[0].is_nan() && b[0].is_nan())));
    // ... a correction beyond the bounds (the 2 mm perturbation against a 0.5 mm bound) ...
    let tight = RefineConfig { max_translation_m: 0.0005, ..Default::default() };
    let e = refine_grid(&g1, &mut g2, &bad, &plane, &motion, &tight).unwrap_err();
    assert!(matches!(e, RefineError::MovedTooFar { .. }), "{e}");
    // ... and a wildly wrong calibration: the camera placed 30 mm and 5 degrees off.
    let wild = perturb(&e2, 30.0, 5.0);
    let (mut g2, _) = grid(&s, 1, &wild);
    let e = refine_grid(&g1, &mut g2, &wild, &plane, &motion, &cfg).unwrap_err();
    eprintln!("wild start refused: {e}");
    assert!(matches!(
        e,
        RefineError::TooLittleOverlap { .. } | RefineError::MovedTooFar { .. } | RefineError::PoorFit { .. }
    ));
}

mod common;
use xsurf_core::image::Encoding;
use xsurf_core::mesh::MeshConfig;
use xsurf_core::synth::Preset;

/// Where the refinement leaves cam2 on a scan of `scene` (each camera's grid as the mesher hands
/// it to the merger, its contradicted points rejected): from the true calibration, and from cam2
/// off by 2 mm / 0.3 degrees; each as its distance to the truth (mm, degrees), or the refusal.
type Placed = Result<(f64, f64), RefineError>;

/// cam2's surface, RMS distance to the true surface in mm: triangulated through the true
/// placement, through the perturbed one, and after the perturbed one was refined (or refused).
struct Surfaces {
    truth: f64,
    perturbed: f64,
    refined: f64,
}

fn refined(
    scene: &str,
    (w, h): (u32, u32),
    encoding: Encoding,
    preset: Preset,
    speed_mps: f64,
) -> (Placed, Placed, Surfaces) {
    let mesh = MeshConfig::default();
    let rig = Rig::study(w, h);
    let mut settings = ScanSettings { speed_mps, encoding, ..Default::default() };
    preset.apply(&mut settings);
    let scanner = Scanner::new(Scene::by_name(scene).unwrap(), rig.clone(), preset.laser(), settings).unwrap();
    let plane = Plane::from_params(rig.laser_plane).unwrap();
    let motion = ScanMotion { table_from_carm: scanner.pose_at(0.0) };
    let e2 = rig.cameras[1].carm_from_optical();
    let grids = |used: &Rig| {
        let mut g = common::camera_grids(&scanner, used);
        for g in &mut g {
            g.reject_contradicted(mesh.outlier_tolerance_m, mesh.max_edge_m);
        }
        g
    };
    let surface = |g: &Grid| rms_mm(&scanner.scene, &finite(g).collect::<Vec<_>>());
    let g = grids(&rig);
    let to_truth = |r: xsurf_core::register::RefineReport| placement_error(&e2, &r.carm_from_optical);
    let exact = refine_grid(&g[0], &mut g[1].clone(), &e2, &plane, &motion, &RefineConfig::default()).map(to_truth);
    let bad = perturb(&e2, 2.0, 0.3);
    let mut stale = rig.clone();
    stale.cameras[1].set_carm_from_optical(&bad);
    let mut g2 = grids(&stale).swap_remove(1);
    let perturbed_surface = surface(&g2);
    let perturbed = refine_grid(&g[0], &mut g2, &bad, &plane, &motion, &RefineConfig::default()).map(to_truth);
    let surfaces = Surfaces { truth: surface(&g[1]), perturbed: perturbed_surface, refined: surface(&g2) };
    (exact, perturbed, surfaces)
}

/// On the hard pyramid at 320x240 the fit once slid along a direction the data hardly hold and
/// accepted cam2 at 6.8 mm / 0.42 degrees from the truth, having started 2 mm / 0.3 degrees
/// off. A refinement must never make a camera worse: refused, or its surface as near the truth
/// as the true placement's and its placement no further from the truth than where it started.
///
/// The surface is the measure, the placement only a bound: at this resolution the data hold
/// five of the six directions of the placement, and along the sixth (a shift and turn together,
/// 5 mm / 0.3 degrees at one standard deviation) the camera stays as it was given and its
/// surface does not change. Where it ends along that valley moved from 1.8 to 2.5 mm when a few
/// hundred dim samples on the dark print were added, with the surface at the truth's 0.67 mm
/// RMS both times.
#[test]
fn a_perturbed_camera_is_never_made_worse_on_a_hard_scan() {
    let (exact, perturbed, s) = refined("pyramid", (320, 240), Encoding::Mono8, Preset::Hard, 0.07);
    match exact {
        Ok((dt, dr)) => assert!(dt < 0.5 && dr < 0.05, "a correct calibration moved by {dt} mm / {dr} deg"),
        Err(e) => eprintln!("the true calibration kept: {e}"),
    }
    eprintln!(
        "cam2's surface RMS: {:.3} mm through the truth, {:.3} mm perturbed, {:.3} mm refined",
        s.truth, s.perturbed, s.refined
    );
    assert!(s.perturbed > 3.0 * s.truth, "the perturbation must matter: {} vs {} mm", s.perturbed, s.truth);
    match perturbed {
        Ok((dt, dr)) => {
            eprintln!("cam2 off by 2 mm / 0.3 deg, refined to {dt:.3} mm / {dr:.4} deg of the truth");
            assert!(s.refined <= 1.05 * s.truth, "refined surface {} mm vs the truth's {} mm", s.refined, s.truth);
            // No further than the 2 mm / 0.3 degree start, the turn taken at a metre (5.6 mm
            // together); the old slide to 6.8 mm / 0.42 degrees was 10 mm.
            let along = (dt * dt + (dr.to_radians() * 1e3).powi(2)).sqrt();
            assert!(along < 5.5 && dr < 0.3, "made worse: {dt} mm / {dr} deg from the truth");
        }
        Err(e) => {
            eprintln!("the perturbed placement kept: {e}");
            assert_eq!(s.refined, s.perturbed, "a refusal leaves the grid as it was");
        }
    }
}
/// The refinement on the `hard` preset's scans and the bundled bags' (issue 17): where the
/// true calibration is left (the floor: within 0.5 mm / 0.05 degrees, or refused), and where
/// cam2, off by 2 mm / 0.3 degrees, is put. A report, not a test: the floor is not met on every
/// scan (run with `--ignored --nocapture`; BENCHMARKS.md quotes it).
#[test]
#[ignore]
fn refinement_on_hard_scans() {
    let show = |r: Placed| match r {
        Ok((dt, dr)) => format!("moved to {dt:.3} mm / {dr:.4} deg of the truth"),
        Err(e) => format!("refused ({e})"),
    };
    // The hard scans, and the bundled bags' (ideal, 320x240 at 140 mm/s).
    for (scene, size, encoding, preset, speed) in [
        ("pyramid", (640, 480), Encoding::Mono8, Preset::Hard, 0.07),
        ("phantom", (640, 480), Encoding::Mono8, Preset::Hard, 0.07),
        ("pyramid", (320, 240), Encoding::Mono8, Preset::Hard, 0.07),
        ("phantom", (320, 240), Encoding::Rgb8, Preset::Hard, 0.07),
        ("pyramid", (320, 240), Encoding::Mono8, Preset::Ideal, 0.14),
        ("phantom", (320, 240), Encoding::Mono8, Preset::Ideal, 0.14),
    ] {
        let (exact, perturbed, s) = refined(scene, size, encoding, preset, speed);
        let what = format!("{scene} {}x{} {encoding:?} {preset:?}", size.0, size.1);
        eprintln!("{what}, the true calibration: {}", show(exact));
        eprintln!("{what}, cam2 off by 2 mm / 0.3 deg: {}", show(perturbed));
        eprintln!(
            "{what}, cam2's surface RMS: {:.3} mm through the truth, {:.3} perturbed, {:.3} refined",
            s.truth, s.perturbed, s.refined
        );
    }
}
