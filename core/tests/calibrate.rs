//! Calibration against the synthetic scanner's truth (issue: calibration): intrinsics,
//! placement and laser plane from noisy 640x480 sets, the failure paths a technician meets, and
//! a scan reconstructed with the calibrated rig against the same scan with the true rig.
#![allow(clippy::unwrap_used)]

mod common;

use xsurf_core::calib::board::{detect, BoardError, BoardSpec};
use xsurf_core::calib::intrinsics::{calibrate as calibrate_intrinsics, IntrinsicsConfig};
use xsurf_core::calib::laser::{calibrate as calibrate_laser, LaserView};
use xsurf_core::calib::placement::{calibrate as calibrate_placement, table_from_board, PlacementView};
use xsurf_core::calib::CalibError;
use xsurf_core::camera::CameraModel;
use xsurf_core::edge::{EdgeConfig, EdgeDetector, LaserLine};
use xsurf_core::eval::{accuracy, surface_errors};
use xsurf_core::geom::{Iso3, Plane, Vec3};
use xsurf_core::pose::table_from_carm;
use xsurf_core::rig::{Rig, RigCamera};
use xsurf_core::synth::calib::{board_views, render_board, BoardLook, Exposure, RayTable};
use xsurf_core::synth::{LaserModel, ScanSettings, Scanner, Scene};

fn spec() -> BoardSpec {
    // The study's board had 27.65 mm squares.
    BoardSpec::parse("9x6", 0.02765).unwrap()
}

/// Where the placement board lies on the tabletop, and the travels at which it is imaged.
fn placement_board() -> Iso3 {
    table_from_board(Vec3::new(-0.11, 0.07, 0.0), 0.0)
}
const PLACEMENT_TRAVELS: [f64; 3] = [-0.03, 0.0, 0.03];
const LASER_HEIGHTS: [f64; 3] = [0.0, 0.12, 0.24];

struct Calibrated {
    rig: Rig,
    intrinsics_rms: Vec<f64>,
}

fn intrinsics_views(model: &CameraModel, count: usize, seed: u64) -> Vec<Vec<[f64; 2]>> {
    let rays = RayTable::new(model);
    board_views(model, &spec(), count, seed)
        .iter()
        .enumerate()
        .map(|(i, pose)| {
            let img = render_board(&rays, pose, &spec(), &BoardLook::default(), &Exposure::default(), seed + i as u64);
            detect(&img.view().unwrap(), &spec()).unwrap_or_else(|e| panic!("view {i}: {e}")).points
        })
        .collect()
}

fn placement_views(truth: &RigCamera, seed: u64) -> Vec<PlacementView> {
    let model = truth.model().unwrap();
    let rays = RayTable::new(&model);
    let look = BoardLook { background: 0.85, ..BoardLook::default() };
    PLACEMENT_TRAVELS
        .iter()
        .enumerate()
        .map(|(i, &t)| {
            let table_from_carm = table_from_carm(t, 0.0, 0.0);
            let optical_from_board =
                table_from_carm.compose(&truth.carm_from_optical()).inverse().compose(&placement_board());
            let img = render_board(&rays, &optical_from_board, &spec(), &look, &Exposure::default(), seed + i as u64);
            let corners = detect(&img.view().unwrap(), &spec())
                .unwrap_or_else(|e| panic!("{} travel {t}: {e}", truth.name))
                .points;
            PlacementView { corners, table_from_carm }
        })
        .collect()
}

fn laser_pixels(truth: &Rig, cam: usize, height: f64, seed: u64) -> Vec<[f64; 2]> {
    let settings = ScanSettings { noise_sigma: 2.0, seed, ..Default::default() };
    let scanner = Scanner::new(Scene::tabletop(), truth.clone(), LaserModel::default(), settings).unwrap();
    let img = scanner.render_at(cam, &table_from_carm(0.0, height, 0.0), true, seed);
    let mut det = EdgeDetector::new(EdgeConfig::default()).unwrap();
    let mut line = LaserLine::default();
    det.detect(&img.view().unwrap(), &mut line).unwrap();
    line.u.iter().zip(&line.v).filter(|(u, _)| u.is_finite()).map(|(&u, &v)| [f64::from(u), f64::from(v)]).collect()
}

fn calibrate_all(truth: &Rig) -> Calibrated {
    let mut rig = truth.clone();
    let mut intrinsics_rms = Vec::new();
    for (ci, cam) in truth.cameras.iter().enumerate() {
        let model = cam.model().unwrap();
        let views = intrinsics_views(&model, 20, 100 * ci as u64 + 7);
        let r = calibrate_intrinsics(&spec(), &views, model.width, model.height, &IntrinsicsConfig::default()).unwrap();
        intrinsics_rms.push(r.rms_px);
        let p =
            calibrate_placement(&spec(), &r.model, &placement_board(), &placement_views(cam, 50 + ci as u64)).unwrap();
        rig.cameras[ci] = RigCamera::from_parts(&cam.name, &r.model, &p.carm_from_optical);
    }
    let mut views = Vec::new();
    for ci in 0..truth.cameras.len() {
        for (k, &h) in LASER_HEIGHTS.iter().enumerate() {
            let camera = rig.cameras[ci].geometry().unwrap();
            views.push(LaserView { camera, height_m: h, pixels: laser_pixels(truth, ci, h, 900 + k as u64) });
        }
    }
    let laser = calibrate_laser(&views, Vec3::Y).unwrap();
    eprintln!(
        "laser: rms {:.3} mm, max {:.3} mm, {} used, {} dropped",
        laser.rms_m * 1e3,
        laser.max_m * 1e3,
        laser.used,
        laser.dropped
    );
    rig.laser_plane = laser.plane.to_params();
    Calibrated { rig, intrinsics_rms }
}

fn rotation_deg(a: &Iso3, b: &Iso3) -> f64 {
    a.rotation.angle_to(&b.rotation).to_degrees()
}

/// Largest distance of the calibrated plane from the true one over the working region (the
/// fan on the tabletop, x within +-0.3 m, up to 0.34 m above it), metres.
fn plane_offset(truth: &Plane, cal: &Plane) -> f64 {
    let mut worst = 0.0f64;
    for x in [-0.3, 0.0, 0.3] {
        for z in [0.0, 0.17, 0.34] {
            // A point of the true plane at (x, ?, z).
            let p = Vec3::new(x, 0.0, z);
            let p = p - truth.normal * truth.signed_distance(p);
            worst = worst.max(cal.signed_distance(p).abs());
        }
    }
    worst
}

fn scan_rms(truth: &Rig, used: &Rig) -> f64 {
    let settings = ScanSettings { speed_mps: 0.07, ..Default::default() };
    let scanner =
        Scanner::new(Scene::by_name("pyramid").unwrap(), truth.clone(), LaserModel::default(), settings).unwrap();
    let points: Vec<[f32; 3]> = common::camera_grids(&scanner, used).iter().flat_map(|g| g.points().to_vec()).collect();
    accuracy(surface_errors(&scanner.scene, &points)).rms_m
}

#[test]
fn calibrated_rig_meets_the_bounds_and_reconstructs_as_well_as_the_true_rig() {
    let truth = Rig::study(640, 480);
    let cal = calibrate_all(&truth);
    for (t, c) in truth.cameras.iter().zip(&cal.rig.cameras) {
        let (tm, cm) = (t.model().unwrap(), c.model().unwrap());
        let (dfx, dfy) = ((cm.fx / tm.fx - 1.0).abs(), (cm.fy / tm.fy - 1.0).abs());
        let (dcx, dcy) = ((cm.cx - tm.cx).abs(), (cm.cy - tm.cy).abs());
        let dt = (c.carm_from_optical().translation - t.carm_from_optical().translation).norm();
        let dr = rotation_deg(&c.carm_from_optical(), &t.carm_from_optical());
        eprintln!(
            "{}: fx {:.3} % fy {:.3} % cx {dcx:.3} px cy {dcy:.3} px; placement {:.3} mm {dr:.4} deg; d {:?}",
            t.name,
            dfx * 100.0,
            dfy * 100.0,
            dt * 1e3,
            c.d
        );
        assert!(dfx < 0.003 && dfy < 0.003, "focal lengths {dfx} {dfy}");
        assert!(dcx < 0.5 && dcy < 0.5, "principal point {dcx} {dcy}");
        assert!(dt < 0.001 && dr < 0.1, "placement {dt} m {dr} deg");
    }
    eprintln!("reprojection rms {:?} px", cal.intrinsics_rms);
    for rms in &cal.intrinsics_rms {
        assert!(*rms < 0.2, "reprojection rms {rms} px");
    }
    let (tp, cp) = (Plane::from_params(truth.laser_plane).unwrap(), Plane::from_params(cal.rig.laser_plane).unwrap());
    let angle = tp.normal.dot(cp.normal).clamp(-1.0, 1.0).acos().to_degrees();
    let offset = plane_offset(&tp, &cp);
    eprintln!("laser plane: {angle:.4} deg, {:.3} mm; {:?}", offset * 1e3, cal.rig.laser_plane);
    assert!(angle < 0.1 && offset < 0.0005, "laser plane {angle} deg {offset} m");

    let (true_rms, cal_rms) = (scan_rms(&truth, &truth), scan_rms(&truth, &cal.rig));
    eprintln!("pyramid rms: true rig {:.4} mm, calibrated rig {:.4} mm", true_rms * 1e3, cal_rms * 1e3);
    assert!(cal_rms <= 1.1 * true_rms, "calibrated {cal_rms} vs true {true_rms}");
}

fn study_model() -> CameraModel {
    Rig::study(640, 480).cameras[0].model().unwrap()
}

fn detect_at(pose: &Iso3, look: &BoardLook, exposure: &Exposure) -> Result<Vec<[f64; 2]>, BoardError> {
    let model = study_model();
    let img = render_board(&RayTable::new(&model), pose, &spec(), look, exposure, 1);
    detect(&img.view().unwrap(), &spec()).map(|c| c.points)
}

fn square_on(x: f64, y: f64, z: f64) -> Iso3 {
    Iso3 { rotation: xsurf_core::geom::Mat3::IDENTITY, translation: Vec3::new(x, y, z) }
}

#[test]
fn each_board_failure_is_explained() {
    let look = BoardLook::default();
    let ok = Exposure::default();
    // Square on and centred: found.
    let centred = square_on(-0.11, -0.07, 0.6);
    assert_eq!(detect_at(&centred, &look, &ok).unwrap().len(), 54);
    // No board in view (it is far off to the side): nothing but the background.
    let e = detect_at(&square_on(3.0, 0.0, 0.6), &look, &ok).unwrap_err();
    assert!(matches!(e, BoardError::LowContrast { .. }), "{e}");
    assert!(e.to_string().contains("board missing"), "{e}");
    // Shifted so that its right part leaves the frame.
    let e = detect_at(&square_on(0.12, -0.07, 0.6), &look, &ok).unwrap_err();
    assert!(matches!(e, BoardError::CutOff { .. }), "{e}");
    assert!(e.to_string().contains("cut off by the frame"), "{e}");
    // Dim is fine (white at about 10 grey levels is still found); too dark is explained.
    let dim = Exposure { level: 12.0, ..Exposure::default() };
    assert_eq!(detect_at(&centred, &look, &dim).unwrap().len(), 54);
    let dark = Exposure { level: 5.0, ..Exposure::default() };
    let e = detect_at(&centred, &look, &dark).unwrap_err();
    assert!(matches!(e, BoardError::TooDark { .. }), "{e}");
    // Soft focus (4 px blur on 32 px squares) is still found, at the sharp image's corners;
    // out of focus is explained.
    let sharp = detect_at(&centred, &look, &ok).unwrap();
    let soft = detect_at(&centred, &look, &Exposure { blur_px: 4.0, ..Exposure::default() }).unwrap();
    let worst = sharp.iter().zip(&soft).map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1])).fold(0.0, f64::max);
    assert!(worst < 0.3, "soft focus moves a corner by {worst:.3} px");
    let blurred = Exposure { blur_px: 12.0, ..Exposure::default() };
    let e = detect_at(&centred, &look, &blurred).unwrap_err();
    assert!(matches!(e, BoardError::Blurred { .. }), "{e}");
    // The wrong board size given: a larger lattice than asked for.
    let model = study_model();
    let img = render_board(&RayTable::new(&model), &centred, &spec(), &look, &ok, 1);
    let small = BoardSpec::parse("7x5", spec().square_m).unwrap();
    let e = detect(&img.view().unwrap(), &small).unwrap_err();
    assert!(e.to_string().contains("--board size"), "{e}");
    // An image too small to hold anything.
    let tiny = xsurf_core::image::Image::new(4, 3, xsurf_core::image::Encoding::Mono8);
    let e = detect(&tiny.view().unwrap(), &spec()).unwrap_err();
    assert!(matches!(e, BoardError::TooSmall { width: 4, height: 3 }), "{e}");
}

#[test]
fn a_moved_view_is_rejected_with_its_reason() {
    let model = study_model();
    let mut views = intrinsics_views(&model, 8, 31);
    // View 3: the board slipped during the exposure; half of its corners are off by 2 px.
    for p in views[3].iter_mut().skip(27) {
        p[0] += 2.0;
    }
    let r = calibrate_intrinsics(&spec(), &views, 640, 480, &IntrinsicsConfig::default()).unwrap();
    let reasons: Vec<_> = r.views.iter().enumerate().filter_map(|(i, v)| v.rejected.as_ref().map(|s| (i, s))).collect();
    eprintln!("{reasons:?}, rms {:.3} px", r.rms_px);
    assert_eq!(reasons.len(), 1, "{reasons:?}");
    assert_eq!(reasons[0].0, 3);
    assert!(reasons[0].1.contains("x the median"), "{}", reasons[0].1);
    assert!(r.rms_px < 0.2 && (r.model.fx / model.fx - 1.0).abs() < 0.003);
    // Too few views.
    let e = calibrate_intrinsics(&spec(), &views[..2], 640, 480, &IntrinsicsConfig::default()).unwrap_err();
    assert!(matches!(e, CalibError::TooFewViews { .. }), "{e}");
}

#[test]
fn a_single_tabletop_height_is_refused() {
    let truth = Rig::study(640, 480);
    let camera = truth.cameras[0].geometry().unwrap();
    let views: Vec<LaserView> = (0..3)
        .map(|k| LaserView { camera: camera.clone(), height_m: 0.1, pixels: laser_pixels(&truth, 0, 0.1, k) })
        .collect();
    let e = calibrate_laser(&views, Vec3::Y).unwrap_err();
    assert!(e.to_string().contains("two or more tabletop heights"), "{e}");
    // A view without the line (laser off) is named; the rest still decide.
    let mut views = views;
    views.push(LaserView { camera: camera.clone(), height_m: 0.2, pixels: Vec::new() });
    let e = calibrate_laser(&views, Vec3::Y).unwrap_err();
    assert!(e.to_string().contains("view 3: laser line not found"), "{e}");
}

#[test]
fn a_wide_lens_calibrates_with_the_rational_polynomial_model() {
    use xsurf_core::calib::intrinsics::DistortionModel;
    use xsurf_core::camera::Distortion;
    // A wide lens with strong barrel distortion, as OpenCV's rational model describes it.
    let truth = CameraModel {
        width: 640,
        height: 480,
        fx: 420.0,
        fy: 421.0,
        cx: 318.0,
        cy: 243.0,
        distortion: Distortion::RationalPolynomial { d: [0.4, -0.05, 0.0004, -0.0002, 0.0, 0.75, 0.0, 0.0] },
    };
    let views = intrinsics_views(&truth, 20, 77);
    let cfg = IntrinsicsConfig { model: DistortionModel::RationalPolynomial, ..IntrinsicsConfig::default() };
    let r = calibrate_intrinsics(&spec(), &views, 640, 480, &cfg).unwrap();
    let m = r.model;
    eprintln!("rational: fx {} fy {} cx {} cy {} d {:?} rms {}", m.fx, m.fy, m.cx, m.cy, m.distortion, r.rms_px);
    assert!(r.rms_px < 0.2, "rms {}", r.rms_px);
    assert!((m.fx / truth.fx - 1.0).abs() < 0.003 && (m.fy / truth.fy - 1.0).abs() < 0.003);
    assert!((m.cx - truth.cx).abs() < 0.5 && (m.cy - truth.cy).abs() < 0.5);
    // The fitted model maps the image like the true one wherever the board was seen
    // (coefficients of a rational model trade off against each other, and it is not meant to
    // extrapolate beyond the calibrated field; the mapping is what matters).
    let (mut worst, mut sum2, mut n) = (0.0f64, 0.0, 0.0);
    for p in views.iter().flatten() {
        let (a, b) = (truth.ray(p[0], p[1]).unwrap(), m.ray(p[0], p[1]).unwrap());
        let e = ((a.x - b.x).powi(2) + (a.y - b.y).powi(2)).sqrt() * truth.fx;
        worst = worst.max(e);
        sum2 += e * e;
        n += 1.0;
    }
    let rms = (sum2 / n).sqrt();
    eprintln!("mapping difference over the observed corners: rms {rms:.3} px, max {worst:.3} px");
    assert!(rms < 0.3, "mapping differs by {rms} px rms");
    assert!(worst < 1.0, "mapping differs by up to {worst} px");
}

/// The board turned a quarter, half and three quarters, in the hard look (clutter with a
/// second checkerboard behind it, uneven light), and with no border at all: found, and named in board order (corner `k`
/// where the board's point `k` projects), rows and columns by the board's size, not the image's
/// axes.
#[test]
fn a_turned_board_in_clutter_is_found_in_board_order() {
    let model = study_model();
    let rays = RayTable::new(&model);
    let spec = spec();
    let centre = Vec3::new(4.0 * spec.square_m, 2.5 * spec.square_m, 0.0);
    // The last two: no white border at all, against the clutter.
    let borderless = BoardLook { margin_squares: 0.0, ..BoardLook::hard() };
    for (k, (deg, look)) in [
        (0.0f64, BoardLook::hard()),
        (90.0, BoardLook::hard()),
        (180.0, BoardLook::hard()),
        (270.0, BoardLook::hard()),
        (33.0, BoardLook::hard()),
        (0.0, borderless.clone()),
        (-20.0, borderless),
    ]
    .into_iter()
    .enumerate()
    {
        let rotation = xsurf_core::geom::Mat3::rot_x(0.35).mul_mat(&xsurf_core::geom::Mat3::rot_z(deg.to_radians()));
        let pose = Iso3 { rotation, translation: Vec3::new(-0.02, 0.0, 0.55) - rotation.mul_vec(centre) };
        let img = render_board(&rays, &pose, &spec, &look, &Exposure::hard(), 40 + k as u64);
        let c = detect(&img.view().unwrap(), &spec).unwrap_or_else(|e| panic!("{deg} degrees: {e}"));
        let worst = c
            .points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let (u, v) = model.project(pose.transform_point(spec.point(i))).unwrap();
                (p[0] - u).hypot(p[1] - v)
            })
            .fold(0.0, f64::max);
        eprintln!("{deg} degrees: worst corner {worst:.3} px");
        assert!(worst < 0.5, "{deg} degrees: a corner {worst:.2} px from where it projects");
    }
}

/// Diagnosis: mean corner error against the projection, with and without the hard set's uneven
/// light (`cargo test --release -p xsurf-core --test calibrate shadow_bias_probe -- --ignored --nocapture`).
#[test]
#[ignore]
fn shadow_bias_probe() {
    let model = study_model();
    let rays = RayTable::new(&model);
    let spec = spec();
    for uneven in [0.0, 1.0] {
        let (mut sx, mut sy, mut n, mut sx_near, mut n_near) = (0.0, 0.0, 0, 0.0, 0);
        for (i, pose) in board_views(&model, &spec, 20, 5).iter().enumerate() {
            let img = render_board(
                &rays,
                pose,
                &spec,
                &BoardLook::hard(),
                &Exposure { uneven, ..Exposure::hard() },
                i as u64,
            );
            let Ok(c) = detect(&img.view().unwrap(), &spec) else { continue };
            for (k, p) in c.points.iter().enumerate() {
                let (u, v) = model.project(pose.transform_point(spec.point(k))).unwrap();
                sx += p[0] - u;
                sy += p[1] - v;
                n += 1;
                // Distance to the shadow's edge line (0.35 w, h) -> (w, 0.45 h).
                let (ax, ay, bx, by) = (0.35 * 640.0, 480.0, 640.0, 0.45 * 480.0);
                let side = ((bx - ax) * (v - ay) - (by - ay) * (u - ax)) / f64::hypot(bx - ax, by - ay);
                if side.abs() < 12.0 {
                    sx_near += p[0] - u;
                    n_near += 1;
                }
            }
        }
        eprintln!(
            "uneven {uneven}: {n} corners, mean error ({:+.4}, {:+.4}) px; {n_near} near the shadow's edge: mean dx {:+.4}",
            sx / n as f64,
            sy / n as f64,
            sx_near / n_near.max(1) as f64
        );
    }
}
