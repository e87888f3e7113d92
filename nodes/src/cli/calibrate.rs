//! `xsurf calibrate`: the technician's calibration commands (offline; no DDS participant).
//!
//! ```text
//! xsurf calibrate synth DIR [--size WxH] [--board COLSxROWS] [--square M] [--views N] [--noise S] [--seed N] [--preset ideal|hard]
//! xsurf calibrate intrinsics IMAGE... --board COLSxROWS --square M -o CAMERA.yaml [--name NAME]
//!       [--model plumb_bob|rational_polynomial] [--report DIR]
//! xsurf calibrate placement [--rig RIG.yaml] -o RIG.yaml --board COLSxROWS --square M --board-origin X,Y[,Z]
//!       [--board-yaw DEG] (--camera NAME --intrinsics CAMERA.yaml --travels T[,T...] IMAGE...)... [--report DIR]
//! xsurf calibrate laser --rig RIG.yaml [-o RIG.yaml] (--camera NAME --heights H[,H...] IMAGE...)... [--report DIR]
//! xsurf calibrate scan BAG --rig RIG.yaml [-o RIG.yaml] [--params-file FILE] [--max-translation M]
//!       [--max-rotation DEG] [--report DIR]
//! ```
//! Each command prints its numbers, writes a report (`report.json` and PNG plots; by default in
//! `<output>_<command>_report/`) and explains every image it could not use.

use super::args::{list, usage, Args, Syntax};
use anyhow::{anyhow, bail, Context};
use serde_json::json;
use std::path::{Path, PathBuf};
use xsurf_core::calib::board::{detect, BoardSpec, Corners};
use xsurf_core::calib::intrinsics::{self, DistortionModel, IntrinsicsConfig};
use xsurf_core::calib::laser::{self, LaserView};
use xsurf_core::calib::placement::{self, table_from_board, PlacementView};
use xsurf_core::camera::CameraModel;
use xsurf_core::edge::{Channel, EdgeConfig, EdgeDetector, LaserLine};
use xsurf_core::geom::Vec3;
use xsurf_core::merge::refine::{Record, RefinementFile, Status};
use xsurf_core::pose::table_from_carm;
use xsurf_core::rig::{Rig, RigCamera};
use xsurf_core::synth::calib::{board_views, render_board, BoardLook, Exposure, RayTable};
use xsurf_core::synth::{Preset, ScanSettings, Scanner, Scene};
use xsurf_formats::calibration::{self, CameraCalibration};
use xsurf_formats::plot::{palette, Plot, BLUE, GREY, RED};
use xsurf_formats::write_bytes_atomic;

/// Travels at which the synthetic set images the board on the tabletop, metres.
pub const SYNTH_TRAVELS: [f64; 3] = [-0.03, 0.0, 0.03];
/// Tabletop heights of the synthetic laser set, metres.
pub const SYNTH_HEIGHTS: [f64; 3] = [0.0, 0.12, 0.24];
/// JPEG quality of the hard synthetic set's board views.
const SYNTH_JPEG_QUALITY: u8 = 75;

/// Images that share a camera and its per-image values.
#[derive(Debug, Default)]
struct Group {
    camera: String,
    intrinsics: Option<PathBuf>,
    values: Vec<f64>,
    images: Vec<PathBuf>,
}

/// A calibrate command's options (the shared parser), with the groups opened by `--camera`
/// read into [`Group`]s.
#[derive(Debug)]
struct Opts {
    args: Args,
    positional: Vec<PathBuf>,
    groups: Vec<Group>,
}

impl Opts {
    /// `valued` options; in a `--camera` group, `--intrinsics` and `values_flag` (a list).
    fn parse(args: &[String], valued: &[&str], values_flag: Option<&str>) -> anyhow::Result<Opts> {
        let inner: Vec<&str> = std::iter::once("--intrinsics").chain(values_flag).collect();
        let a = Args::parse(args, &Syntax { flags: &[], valued, group: Some(("--camera", &inner)) })?;
        let mut groups = Vec::new();
        for g in &a.groups {
            groups.push(Group {
                camera: g.name.clone(),
                intrinsics: g.get("--intrinsics").map(PathBuf::from),
                values: match values_flag.and_then(|f| g.get(f).map(|v| (f, v))) {
                    Some((f, v)) => list(f, v)?,
                    None => Vec::new(),
                },
                images: g.positional.iter().map(PathBuf::from).collect(),
            });
        }
        Ok(Opts { positional: a.positional.iter().map(PathBuf::from).collect(), groups, args: a })
    }
    fn get(&self, name: &str) -> Option<&str> {
        self.args.get(name)
    }
    fn need(&self, name: &str) -> anyhow::Result<&str> {
        self.args.need(name)
    }
    fn num(&self, name: &str, default: f64) -> anyhow::Result<f64> {
        self.args.num(name, default)
    }
    fn whole(&self, name: &str, default: u64) -> anyhow::Result<u64> {
        self.args.num(name, default)
    }
    fn board(&self) -> anyhow::Result<BoardSpec> {
        let square = self.need("--square")?;
        let square: f64 = square
            .parse()
            .ok()
            .filter(|s: &f64| s.is_finite())
            .ok_or_else(|| usage(format!("--square: {square:?} is not a number (metres)")))?;
        BoardSpec::parse(self.need("--board")?, square).map_err(|e| usage(format!("--board/--square: {e}")))
    }
}

/// The output file of a calibrate command, checked before any work: not empty, not a folder,
/// in a folder that exists.
fn output_file(p: &str) -> anyhow::Result<PathBuf> {
    let path = PathBuf::from(p);
    if p.is_empty() {
        return Err(usage("-o: an empty path"));
    }
    if path.is_dir() {
        return Err(usage(format!("-o {p}: is a folder; name the file to write (for example {p}/cam1.yaml)")));
    }
    if let Some(parent) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !parent.is_dir() {
            return Err(usage(format!("-o {p}: the folder {} does not exist", parent.display())));
        }
    }
    Ok(path)
}

/// Runs `xsurf calibrate ARGS`.
pub fn run(args: &[String]) -> anyhow::Result<()> {
    let rest = args.get(1..).unwrap_or(&[]);
    match args.first().map(String::as_str) {
        Some("synth") => synth(rest),
        Some("intrinsics") => cmd_intrinsics(rest),
        Some("placement") => cmd_placement(rest),
        Some("laser") => cmd_laser(rest),
        Some("scan") => cmd_scan(rest),
        Some(other) => {
            Err(usage(format!("unknown calibrate command {other:?} (synth, intrinsics, placement, laser, scan)")))
        }
        None => Err(usage("calibrate needs a command (synth, intrinsics, placement, laser, scan)")),
    }
}

fn report_dir(o: &Opts, out: &Path, kind: &str) -> PathBuf {
    match o.get("--report") {
        Some(d) => PathBuf::from(d),
        None => {
            let stem =
                out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "calibration".into());
            out.with_file_name(format!("{stem}_{kind}_report"))
        }
    }
}

fn write_json(path: &Path, v: &serde_json::Value) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(v)?;
    write_bytes_atomic(path, text.as_bytes())?;
    Ok(())
}

fn find_board(path: &Path, spec: &BoardSpec) -> Result<(Corners, (u32, u32)), String> {
    // The caller names the file: its reason alone (the reader's error names it too).
    let img = xsurf_formats::frames::read_frame(path).map_err(|e| {
        let e = e.to_string();
        e.strip_prefix(&format!("{}: ", path.display())).map_or(e.clone(), str::to_owned)
    })?;
    let view = img.view().map_err(|e| e.to_string())?;
    let c = detect(&view, spec).map_err(|e| e.to_string())?;
    Ok((c, (img.width, img.height)))
}

/// Each image's board: its corners (the images with a board of the first image's size),
/// each image's index among those or why it is not used, and that size.
type BoardSearch = (Vec<Vec<[f64; 2]>>, Vec<(PathBuf, Option<usize>, Option<String>)>, Option<(u32, u32)>);

fn find_boards(paths: &[PathBuf], spec: &BoardSpec) -> BoardSearch {
    let mut found = Vec::new();
    let mut status: Vec<(PathBuf, Option<usize>, Option<String>)> = Vec::new();
    let mut size = None;
    for path in paths {
        match find_board(path, spec) {
            Ok((c, s)) if size.is_none_or(|z| z == s) => {
                size = Some(s);
                status.push((path.clone(), Some(found.len()), None));
                found.push(c.points);
            }
            Ok((_, s)) => {
                let want = size.unwrap_or(s);
                status.push((
                    path.clone(),
                    None,
                    Some(format!("image is {}x{}, the others {}x{}", s.0, s.1, want.0, want.1)),
                ))
            }
            Err(e) => status.push((path.clone(), None, Some(e))),
        }
    }
    (found, status, size)
}

/// The plots of an intrinsic calibration's report: RMS per image, residual vectors, and where
/// the corners fell on the sensor.
fn intrinsics_plots(
    dir: &Path,
    r: &intrinsics::IntrinsicsResult,
    status: &[(PathBuf, Option<usize>, Option<String>)],
    found: &[Vec<[f64; 2]>],
    (w, h): (u32, u32),
) -> anyhow::Result<()> {
    // Per image RMS.
    let n = status.len();
    let top = r.views.iter().map(|v| v.rms_px).fold(0.1f64, f64::max) * 1.1;
    let mut bars = Plot::new("REPROJECTION RMS PER IMAGE", "IMAGE", "PX", (-0.5, n as f64 - 0.5), (0.0, top));
    for (k, (_, idx, _)) in status.iter().enumerate() {
        match idx {
            Some(i) => {
                let v = &r.views[*i];
                bars.bar(k as f64, 0.8, v.rms_px, if v.rejected.is_some() { RED } else { BLUE });
            }
            None => bars.bar(k as f64, 0.8, top, GREY),
        }
    }
    bars.legend(0, "USED", BLUE);
    bars.legend(1, "REJECTED", RED);
    bars.legend(2, "NO BOARD", GREY);
    bars.write_png(&dir.join("rms_per_image.png"))?;
    // Residual vectors.
    let lim = r
        .views
        .iter()
        .filter(|v| v.rejected.is_none())
        .flat_map(|v| v.residuals.iter().map(|d| d[0].abs().max(d[1].abs())))
        .fold(0.2f64, f64::max)
        * 1.1;
    let mut sc = Plot::new("RESIDUALS (CIRCLE 0.2 PX)", "DU PX", "DV PX", (-lim, lim), (-lim, lim));
    sc.circle(0.0, 0.0, 0.2, GREY);
    for (i, v) in r.views.iter().enumerate().filter(|(_, v)| v.rejected.is_none()) {
        for d in &v.residuals {
            sc.dot(d[0], d[1], 1, palette(i));
        }
    }
    sc.write_png(&dir.join("residuals.png"))?;
    // Where the corners fell on the sensor: gaps mean distortion is not pinned there.
    let mut cov = Plot::new("CORNERS ON THE SENSOR", "U PX", "V PX (DOWN)", (0.0, f64::from(w)), (-f64::from(h), 0.0));
    for (i, pts) in found.iter().enumerate() {
        for p in pts {
            cov.dot(p[0], -p[1], 1, palette(i));
        }
    }
    cov.write_png(&dir.join("coverage.png"))?;
    Ok(())
}

fn cmd_intrinsics(args: &[String]) -> anyhow::Result<()> {
    let o = Opts::parse(args, &["--board", "--square", "-o", "--out", "--name", "--model", "--report"], None)?;
    let spec = o.board()?;
    let out = output_file(o.get("-o").or(o.get("--out")).ok_or_else(|| usage("-o CAMERA.yaml is required"))?)?;
    let m = o.get("--model").unwrap_or("plumb_bob");
    let model = DistortionModel::parse(m)
        .ok_or_else(|| usage(format!("--model {m}: expected plumb_bob or rational_polynomial")))?;
    let name = o.get("--name").map(str::to_string).unwrap_or_else(|| {
        out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "camera".into())
    });
    if o.positional.is_empty() {
        return Err(usage("name the board images"));
    }
    let (found, status, size) = find_boards(&o.positional, &spec);
    for (p, _, why) in &status {
        if let Some(why) = why {
            println!("{}: not used: {why}", p.display());
        }
    }
    let reasons: String =
        status.iter().filter_map(|(p, _, w)| w.as_ref().map(|w| format!("\n  {}: {w}", p.display()))).collect();
    let Some((w, h)) = size else {
        bail!("intrinsics: no image shows the {}x{} board{reasons}", spec.cols, spec.rows);
    };
    let cfg = IntrinsicsConfig { model, ..IntrinsicsConfig::default() };
    let r = intrinsics::calibrate(&spec, &found, w, h, &cfg).map_err(|e| {
        // The error may name what it calibrated already ("intrinsics: 2 usable, 3 needed").
        let e = e.to_string();
        if e.starts_with("intrinsics") {
            anyhow!("{e}{reasons}")
        } else {
            anyhow!("intrinsics: {e}{reasons}")
        }
    })?;
    let m = &r.model;
    println!(
        "{name}: {w}x{h}, fx {:.2} fy {:.2} cx {:.2} cy {:.2} (1-sigma {:.2} {:.2} {:.2} {:.2} px), {} d {:?}",
        m.fx,
        m.fy,
        m.cx,
        m.cy,
        r.std_devs.first().copied().unwrap_or(f64::NAN),
        r.std_devs.get(1).copied().unwrap_or(f64::NAN),
        r.std_devs.get(2).copied().unwrap_or(f64::NAN),
        r.std_devs.get(3).copied().unwrap_or(f64::NAN),
        m.distortion.to_ros().0,
        m.distortion.to_ros().1
    );
    let mut images = Vec::new();
    for (p, idx, why) in &status {
        let entry = match idx {
            Some(i) => {
                let v = &r.views[*i];
                println!(
                    "  {}: reprojection RMS {:.3} px{}",
                    p.display(),
                    v.rms_px,
                    v.rejected.as_ref().map(|s| format!(", rejected: {s}")).unwrap_or_default()
                );
                json!({"file": p, "status": if v.rejected.is_some() {"rejected"} else {"used"},
                       "reason": v.rejected, "rms_px": v.rms_px, "residuals_px": v.residuals,
                       "corners_px": found[*i]})
            }
            None => json!({"file": p, "status": "board not found", "reason": why}),
        };
        images.push(entry);
    }
    let used = r.views.iter().filter(|v| v.rejected.is_none()).count();
    println!("reprojection RMS {:.3} px over {used} images; written {}", r.rms_px, out.display());
    calibration::write(&out, &CameraCalibration::from_model(&name, m))?;

    let dir = report_dir(&o, &out, "intrinsics");
    std::fs::create_dir_all(&dir).with_context(|| format!("report folder {}", dir.display()))?;
    write_json(
        &dir.join("report.json"),
        &json!({"kind": "intrinsics", "camera_name": name, "board": {"cols": spec.cols, "rows": spec.rows, "square_m": spec.square_m},
                "width": w, "height": h, "fx": m.fx, "fy": m.fy, "cx": m.cx, "cy": m.cy,
                "distortion_model": m.distortion.to_ros().0, "d": m.distortion.to_ros().1,
                "std_devs": r.std_devs, "rms_px": r.rms_px, "iterations": r.report.iterations, "images": images}),
    )?;
    intrinsics_plots(&dir, &r, &status, &found, (w, h))?;
    println!("report: {}", dir.display());
    Ok(())
}

fn per_image_values(g: &Group, flag: &str) -> anyhow::Result<Vec<f64>> {
    match g.values.len() {
        0 => Err(usage(format!("--camera {}: {flag} is required", g.camera))),
        1 => Ok(vec![g.values[0]; g.images.len()]),
        n if n == g.images.len() => Ok(g.values.clone()),
        n => Err(usage(format!("--camera {}: {flag} has {n} values for {} images", g.camera, g.images.len()))),
    }
}

/// One camera's placement from its board images at their travels: put in `rig`, its residuals
/// plotted into `dir`; returns its entry of the report.
fn place_camera(
    g: &Group,
    gi: usize,
    spec: &BoardSpec,
    board: &xsurf_core::geom::Iso3,
    rig: &mut Rig,
    dir: &Path,
) -> anyhow::Result<serde_json::Value> {
    let ipath =
        g.intrinsics.as_ref().ok_or_else(|| usage(format!("--camera {}: --intrinsics is required", g.camera)))?;
    let model: CameraModel = calibration::read(ipath)?.model().map_err(|e| anyhow!("{}: {e}", ipath.display()))?;
    let travels = per_image_values(g, "--travels")?;
    let mut views = Vec::new();
    let mut files = Vec::new();
    let mut reasons = String::new();
    for (p, &t) in g.images.iter().zip(&travels) {
        match find_board(p, spec) {
            Ok((c, s)) if s == (model.width, model.height) => {
                views.push(PlacementView { corners: c.points, table_from_carm: table_from_carm(t, 0.0, 0.0) });
                files.push((p.clone(), t));
            }
            Ok((_, s)) => reasons.push_str(&format!(
                "\n  {}: image is {}x{}, the intrinsics {}x{}",
                p.display(),
                s.0,
                s.1,
                model.width,
                model.height
            )),
            Err(e) => reasons.push_str(&format!("\n  {}: {e}", p.display())),
        }
    }
    if !reasons.is_empty() {
        println!("{}: images not used:{reasons}", g.camera);
    }
    let r = placement::calibrate(spec, &model, board, &views)
        .map_err(|e| anyhow!("placement of {}: {e}{reasons}", g.camera))?;
    let t = r.carm_from_optical.translation;
    let q = r.carm_from_optical.quaternion();
    println!(
        "{}: carm -> {}_optical_frame translation [{:.4}, {:.4}, {:.4}] m, rotation [{:.5}, {:.5}, {:.5}, {:.5}]; reprojection RMS {:.3} px over {} images",
        g.camera, g.camera, t.x, t.y, t.z, q.x, q.y, q.z, q.w, r.rms_px, views.len()
    );
    let cam = RigCamera::from_parts(&g.camera, &model, &r.carm_from_optical);
    match rig.cameras.iter_mut().find(|c| c.name == g.camera) {
        Some(c) => *c = cam,
        None => rig.cameras.push(cam),
    }
    let images: Vec<_> = files
        .iter()
        .zip(r.view_rms_px.iter().zip(&r.residuals))
        .map(|((p, t), (rms, res))| json!({"file": p, "travel_m": t, "rms_px": rms, "residuals_px": res}))
        .collect();
    let entry = json!({"camera": g.camera, "intrinsics": ipath, "translation_m": [t.x, t.y, t.z],
                       "rotation_xyzw": [q.x, q.y, q.z, q.w], "rms_px": r.rms_px, "images": images});
    let lim = r.residuals.iter().flatten().map(|d| d[0].abs().max(d[1].abs())).fold(0.2f64, f64::max) * 1.1;
    let mut sc = Plot::new(&format!("{} PLACEMENT RESIDUALS", g.camera), "DU PX", "DV PX", (-lim, lim), (-lim, lim));
    sc.circle(0.0, 0.0, 0.2, GREY);
    for (i, res) in r.residuals.iter().enumerate() {
        for d in res {
            sc.dot(d[0], d[1], 1, palette(i + gi));
        }
    }
    sc.write_png(&dir.join(format!("{}_residuals.png", g.camera)))?;
    Ok(entry)
}

fn cmd_placement(args: &[String]) -> anyhow::Result<()> {
    let o = Opts::parse(
        args,
        &["--board", "--square", "-o", "--out", "--rig", "--board-origin", "--board-yaw", "--report"],
        Some("--travels"),
    )?;
    let spec = o.board()?;
    let origin = list("--board-origin", o.need("--board-origin")?)?;
    let origin = match origin[..] {
        [x, y] => Vec3::new(x, y, 0.0),
        [x, y, z] => Vec3::new(x, y, z),
        _ => return Err(usage("--board-origin: expected X,Y or X,Y,Z (metres, table frame)")),
    };
    let board = table_from_board(origin, o.num("--board-yaw", 0.0)?.to_radians());
    if !spec.origin_unique() {
        return Err(usage(format!(
            "--board {}x{}: the board's corner 0 is ambiguous (a 180-degree turn looks the same); use a board with one odd and one even count of inner corners, such as 9x6",
            spec.cols, spec.rows
        )));
    }
    let mut rig = match o.get("--rig") {
        Some(p) => xsurf_formats::rig::read(Path::new(p))?,
        None => {
            let r = Rig::study(640, 480);
            println!(
                "no --rig: starting a new rig (laser_plane {:?}, laser_source {:?} until calibrated)",
                r.laser_plane, r.laser_source
            );
            Rig { cameras: Vec::new(), ..r }
        }
    };
    let out = output_file(
        o.get("-o").or(o.get("--out")).or(o.get("--rig")).ok_or_else(|| usage("-o RIG.yaml is required"))?,
    )?;
    if o.groups.is_empty() {
        return Err(usage("give at least one --camera NAME --intrinsics FILE --travels T IMAGE..."));
    }
    let dir = report_dir(&o, &out, "placement");
    std::fs::create_dir_all(&dir).with_context(|| format!("report folder {}", dir.display()))?;
    let mut report = Vec::new();
    for (gi, g) in o.groups.iter().enumerate() {
        report.push(place_camera(g, gi, &spec, &board, &mut rig, &dir)?);
    }
    xsurf_formats::rig::write(
        &out,
        &rig,
        "xsurf rig file (see launch-config/rig_study.yaml); placement by `xsurf calibrate placement`",
    )?;
    write_json(
        &dir.join("report.json"),
        &json!({"kind": "placement", "board_origin_m": [origin.x, origin.y, origin.z], "cameras": report}),
    )?;
    println!("written {}; report: {}", out.display(), dir.display());
    Ok(())
}

/// The laser line's centre pixels in an image (the edge detector's defaults).
/// Pixel positions and the image size.
type Pixels = (Vec<[f64; 2]>, (u32, u32));

fn line_pixels(path: &Path, channel: Option<Channel>) -> Result<Pixels, String> {
    // The caller names the file: its reason alone (the reader's error names it too).
    let img = xsurf_formats::frames::read_frame(path).map_err(|e| {
        let e = e.to_string();
        e.strip_prefix(&format!("{}: ", path.display())).map_or(e.clone(), str::to_owned)
    })?;
    let view = img.view().map_err(|e| e.to_string())?;
    let d = EdgeConfig::default();
    let mut det =
        EdgeDetector::new(EdgeConfig { channel: channel.unwrap_or(d.channel), ..d }).map_err(|e| e.to_string())?;
    let mut line = LaserLine::default();
    det.detect(&view, &mut line).map_err(|e| e.to_string())?;
    let px: Vec<[f64; 2]> = line
        .u
        .iter()
        .zip(&line.v)
        .filter(|(u, v)| u.is_finite() && v.is_finite())
        .map(|(&u, &v)| [f64::from(u), f64::from(v)])
        .collect();
    Ok((px, (img.width, img.height)))
}

/// An image of the laser calibration: its file, camera and tabletop height.
type LaserFile = (PathBuf, String, f64);

/// The laser line's pixels of each image (in `channel`: a laser's colour against the others;
/// `None`, the edge detector's default), with its camera's geometry from the rig and the
/// tabletop height; and each image's file, camera and height.
fn laser_views(
    groups: &[Group],
    rig: &Rig,
    rig_path: &Path,
    channel: Option<Channel>,
) -> anyhow::Result<(Vec<LaserView>, Vec<LaserFile>)> {
    let mut views = Vec::new();
    let mut files = Vec::new();
    for g in groups {
        let cam = rig.camera(&g.camera).ok_or_else(|| {
            anyhow!("rig file {}: no camera {:?}; run `xsurf calibrate placement` first", rig_path.display(), g.camera)
        })?;
        let geometry =
            cam.geometry().map_err(|e| anyhow!("rig file {}: camera {}: {e}", rig_path.display(), g.camera))?;
        let heights = per_image_values(g, "--heights")?;
        for (p, &h) in g.images.iter().zip(&heights) {
            let (pixels, size) = line_pixels(p, channel).map_err(|e| anyhow!("{}: {e}", p.display()))?;
            if size != (cam.width, cam.height) {
                bail!(
                    "{}: image is {}x{}, camera {} is {}x{}",
                    p.display(),
                    size.0,
                    size.1,
                    g.camera,
                    cam.width,
                    cam.height
                );
            }
            views.push(LaserView { camera: geometry.clone(), height_m: h, pixels });
            files.push((p.clone(), g.camera.clone(), h));
        }
    }
    Ok((views, files))
}

fn cmd_laser(args: &[String]) -> anyhow::Result<()> {
    let o = Opts::parse(args, &["-o", "--out", "--rig", "--report"], Some("--heights"))?;
    let rig_path = PathBuf::from(o.need("--rig")?);
    let mut rig = xsurf_formats::rig::read(&rig_path)?;
    let out = output_file(o.get("-o").or(o.get("--out")).unwrap_or(o.need("--rig")?))?;
    if o.groups.is_empty() {
        return Err(usage("give at least one --camera NAME --heights H[,H...] IMAGE..."));
    }
    let dir = report_dir(&o, &out, "laser");
    std::fs::create_dir_all(&dir).with_context(|| format!("report folder {}", dir.display()))?;
    // A scanner with several lasers: each plane from its own colour in the same images.
    let lasers: Vec<(Option<usize>, Option<Channel>, [f64; 4])> = if rig.lasers.is_empty() {
        vec![(None, None, rig.laser_plane)]
    } else {
        rig.lasers
            .iter()
            .enumerate()
            .map(|(k, l)| (Some(k), Some(Channel::against_others(l.channel)), l.plane))
            .collect()
    };
    let mut reports = Vec::new();
    for (k, channel, old) in lasers {
        let name = k.map_or_else(|| "laser_plane".to_string(), |k| format!("laser.{}.plane", rig.lasers[k].name));
        let (views, files) = laser_views(&o.groups, &rig, &rig_path, channel)?;
        let r = laser::calibrate(&views, Vec3::new(old[0], old[1], old[2])).map_err(|e| {
            // Name the files behind "view N".
            let mut msg = format!("{name}: {e}");
            for (i, (p, c, h)) in files.iter().enumerate() {
                msg = msg.replace(&format!("view {i}:"), &format!("{} ({c}, height {h} m):", p.display()));
            }
            anyhow!(msg)
        })?;
        let p = r.plane.to_params();
        match k {
            None => rig.laser_plane = p,
            Some(k) => rig.lasers[k].plane = p,
        }
        println!(
            "{name} [{:.6}, {:.6}, {:.6}, {:.6}] (was {old:?}); RMS {:.3} mm, max {:.3} mm over {} points ({} dropped)",
            p[0],
            p[1],
            p[2],
            p[3],
            r.rms_m * 1e3,
            r.max_m * 1e3,
            r.used,
            r.dropped
        );
        let file =
            if k.is_some() { format!("residuals_{}.png", name.replace('.', "_")) } else { "residuals.png".into() };
        let images = laser_report(&views, &files, &r, &dir.join(file))?;
        reports.push(json!({"parameter": name, "plane": p, "rms_m": r.rms_m, "max_m": r.max_m,
                            "used": r.used, "dropped": r.dropped, "images": images}));
    }
    if let Some(first) = rig.lasers.first() {
        // The collimator's plane (the X-ray fan beam's) is the first laser's.
        rig.laser_plane = first.plane;
    }
    xsurf_formats::rig::write(
        &out,
        &rig,
        "xsurf rig file (see launch-config/rig_study.yaml); laser planes by `xsurf calibrate laser`",
    )?;
    let p = rig.laser_plane;
    let mut params = format!(
        "# Written by `xsurf calibrate laser`: the laser planes for every node (--params-file).\n/**:\n  ros__parameters:\n    laser_plane: [{}, {}, {}, {}]\n",
        p[0], p[1], p[2], p[3]
    );
    if !rig.lasers.is_empty() {
        params.push_str(&crate::lasers::params_yaml(&rig.lasers));
    }
    write_bytes_atomic(&dir.join("params.yaml"), params.as_bytes())?;
    let single = reports.len() == 1 && rig.lasers.is_empty();
    let report = if single {
        let mut r = reports.remove(0);
        r["kind"] = json!("laser");
        r["laser_plane"] = json!(rig.laser_plane);
        r
    } else {
        json!({"kind": "laser", "laser_plane": rig.laser_plane, "lasers": reports})
    };
    write_json(&dir.join("report.json"), &report)?;
    println!("written {}; report and params.yaml: {}", out.display(), dir.display());
    Ok(())
}

/// One laser's residuals per image: printed, plotted into `png`, and returned for the report.
fn laser_report(
    views: &[LaserView],
    files: &[LaserFile],
    r: &laser::LaserResult,
    png: &Path,
) -> anyhow::Result<Vec<serde_json::Value>> {
    let mut images = Vec::new();
    let lim = r.max_m.max(1e-4) * 1.2e3;
    let rows = views.iter().flat_map(|v| v.pixels.iter().map(|p| p[1])).fold(1.0f64, f64::max);
    let mut plot = Plot::new("LASER PLANE RESIDUALS", "IMAGE ROW PX", "MM", (0.0, rows), (-lim, lim));
    plot.hline(0.0, GREY);
    for (i, ((f, c, h), (v, res))) in files.iter().zip(views.iter().zip(&r.residuals)).enumerate() {
        let ok: Vec<f64> = res.iter().copied().filter(|d| d.is_finite()).collect();
        let rms = (ok.iter().map(|d| d * d).sum::<f64>() / ok.len().max(1) as f64).sqrt();
        println!("  {} ({c}, height {h} m): {} points, RMS {:.3} mm", f.display(), ok.len(), rms * 1e3);
        images.push(json!({"file": f, "camera": c, "height_m": h, "points": ok.len(), "rms_m": rms,
                           "pixels": v.pixels, "residuals_m": res}));
        for (px, d) in v.pixels.iter().zip(res) {
            plot.dot(px[1], d * 1e3, 1, palette(i));
        }
        if i < 12 {
            plot.legend(i, &format!("{c} H {h:.3}"), palette(i));
        }
    }
    plot.write_png(png)?;
    Ok(images)
}

/// `xsurf calibrate scan BAG --rig RIG`: the placement of each further camera refined against
/// the first camera's surface in a scan of any rigid object both cameras see, with no hand
/// input. The bag is reconstructed offline with the merger's refinement (triangulated with the
/// rig's laser plane and the bag's `/tf_static`); the refined placements go into the rig. Exits
/// with an error, the rig untouched, if any camera's refinement was refused.
/// The refined placements of `cameras` put into `rig` (each printed); returns the cameras
/// refused, with why.
fn apply_refinements(cameras: &[Record], rig: &mut Rig, rig_path: &Path) -> anyhow::Result<Vec<String>> {
    let mut refused = Vec::new();
    for c in cameras {
        let name = c.camera.as_str();
        let (Status::Refined, Some(refined)) = (c.status, c.refined) else {
            refused.push(format!("{name}: {}", c.reason));
            continue;
        };
        let cam = rig
            .cameras
            .iter_mut()
            .find(|rc| rc.name == name)
            .ok_or_else(|| anyhow!("rig file {}: no camera {name:?} (the bag has it)", rig_path.display()))?;
        cam.set_carm_from_optical(&refined.iso());
        let [dx, dy, dz] = c.correction_m.unwrap_or_default();
        let num = |v: Option<f64>| v.unwrap_or(f64::NAN);
        println!(
            "{name}: refined against {}: moved {:.2} mm / {:.3} deg; residual RMS {:.3} -> {:.3} mm over {} points, \
             overlap {:.0} %, {} iterations",
            c.reference,
            (dx.powi(2) + dy.powi(2) + dz.powi(2)).sqrt() * 1e3,
            num(c.correction_deg),
            num(c.rms_before_m) * 1e3,
            num(c.rms_after_m) * 1e3,
            c.points.unwrap_or(0),
            num(c.overlap_fraction) * 100.0,
            c.iterations.unwrap_or(0)
        );
    }
    Ok(refused)
}

fn cmd_scan(args: &[String]) -> anyhow::Result<()> {
    let o = Opts::parse(
        args,
        &["-o", "--out", "--rig", "--report", "--params-file", "--max-translation", "--max-rotation"],
        None,
    )?;
    let [bag] = o.positional.as_slice() else { return Err(usage("calibrate scan needs one BAG")) };
    let rig_path = PathBuf::from(o.need("--rig")?);
    let mut rig = xsurf_formats::rig::read(&rig_path)?;
    let out = output_file(o.get("-o").or(o.get("--out")).unwrap_or(o.need("--rig")?))?;
    let p = rig.laser_plane;
    let mut params = vec![format!("laser_plane:=[{}, {}, {}, {}]", p[0], p[1], p[2], p[3]), "refine:=true".into()];
    for (flag, name) in
        [("--max-translation", "refine_max_translation_m"), ("--max-rotation", "refine_max_rotation_deg")]
    {
        if o.get(flag).is_some() {
            let v = o.num(flag, 0.0)?;
            if !(v > 0.0 && v.is_finite()) {
                return Err(usage(format!("{flag}: {v} must be positive")));
            }
            params.push(format!("{name}:={v}"));
        }
    }
    let dir = report_dir(&o, &out, "scan");
    println!("reconstructing {} into {} with the merger's refinement", bag.display(), dir.display());
    let report = crate::offline::reconstruct(&crate::offline::Options {
        bag: bag.clone(),
        params_file: o.get("--params-file").map(PathBuf::from),
        out: dir.clone(),
        params,
        ..Default::default()
    })?;
    // One scan's files are in DIR itself, several scans' in DIR/scan_<id>/: the last scan counts.
    let Some(&scan) = report.scans.last() else {
        bail!("{}: no scan was reconstructed (no START/END on /scan/events, or no frames)", bag.display());
    };
    let refinement = if report.scans.len() == 1 {
        dir.join("refinement.json")
    } else {
        dir.join(format!("scan_{scan}/refinement.json"))
    };
    let text = std::fs::read_to_string(&refinement).map_err(|e| {
        anyhow!("{}: {e}: the merger refined nothing (one camera only, or no refinement ran)", refinement.display())
    })?;
    let outcome: RefinementFile = serde_json::from_str(&text).with_context(|| format!("{}", refinement.display()))?;
    let cameras = outcome.cameras;
    let refused = apply_refinements(&cameras, &mut rig, &rig_path)?;
    write_json(
        &dir.join("report.json"),
        &json!({"kind": "scan", "bag": bag, "scan_id": scan, "rig": out, "cameras": cameras,
                "reconstruction": serde_json::to_value(&report)?}),
    )?;
    if !refused.is_empty() || cameras.is_empty() {
        bail!(
            "the rig {} is left as it was: {}",
            rig_path.display(),
            if refused.is_empty() { "no camera was refined".to_string() } else { refused.join("; ") }
        );
    }
    let names: Vec<&str> = cameras.iter().map(|c| c.camera.as_str()).collect();
    xsurf_formats::rig::write(
        &out,
        &rig,
        &format!(
            "xsurf rig file (see launch-config/rig_study.yaml); the placement of {} refined by `xsurf calibrate scan` \
             from scan {scan} of {}",
            names.join(", "),
            bag.display()
        ),
    )?;
    println!("written {}; report: {}", out.display(), dir.display());
    Ok(())
}

/// What `xsurf calibrate synth` renders, from its options.
struct SynthSet {
    dir: std::path::PathBuf,
    spec: BoardSpec,
    square: f64,
    size: (u32, u32),
    /// Board views per camera.
    count: usize,
    noise: f64,
    seed: u64,
    preset: Preset,
    exposure: Exposure,
    /// The board's look in the intrinsics views and on the table.
    looks: (BoardLook, BoardLook),
    /// The board views' file type: the hard set's are JPEG at quality 75, as most calibration
    /// sets are.
    ext: &'static str,
    /// The three-laser scanner ([`Rig::three_lasers`]): its laser views in colour.
    three: bool,
}

impl SynthSet {
    fn parse(args: &[String]) -> anyhow::Result<SynthSet> {
        let o = Opts::parse(
            args,
            &["--size", "--board", "--square", "--views", "--noise", "--seed", "--preset", "--lasers"],
            None,
        )?;
        let three = match o.get("--lasers").unwrap_or("1") {
            "1" => false,
            "3" => true,
            n => {
                return Err(usage(format!(
                    "--lasers {n}: 1 (the collimator) or 3 (Rig::three_lasers, rgb8 laser views)"
                )))
            }
        };
        let [dir] = &o.positional[..] else { return Err(usage("calibrate synth needs one output folder")) };
        let name = o.get("--preset").unwrap_or("ideal");
        let preset = Preset::parse(name).ok_or_else(|| usage(format!("--preset {name:?}: ideal or hard")))?;
        let hard = preset == Preset::Hard;
        let (w, h) = match o.get("--size").unwrap_or("640x480").split_once('x') {
            Some((a, b)) => (
                a.parse::<u32>().map_err(|_| usage("--size: bad width"))?,
                b.parse::<u32>().map_err(|_| usage("--size: bad height"))?,
            ),
            None => return Err(usage("--size: expected WxH")),
        };
        if !xsurf_core::limits::image_side_ok(w) || !xsurf_core::limits::image_side_ok(h) {
            return Err(usage(format!("--size: width and height in {}", xsurf_core::limits::image_side_text())));
        }
        let board = o.get("--board").unwrap_or("9x6");
        let square = o.num("--square", 0.02765)?;
        let spec = BoardSpec::parse(board, square).map_err(|e| usage(format!("--board/--square: {e}")))?;
        let count = o.whole("--views", 20)?;
        if !(3..=500).contains(&count) {
            return Err(usage(format!("--views {count}: from 3 to 500 board views (intrinsics need 3 or more)")));
        }
        let noise = o.num("--noise", 2.0)?;
        let look = if hard { BoardLook::hard() } else { BoardLook::default() };
        Ok(SynthSet {
            dir: dir.into(),
            spec,
            square,
            size: (w, h),
            count: count as usize,
            noise,
            seed: o.whole("--seed", 1)?,
            preset,
            exposure: if hard { Exposure::hard() } else { Exposure { noise_sigma: noise, ..Exposure::default() } },
            looks: (look.clone(), BoardLook { background: 0.85, ..look }),
            ext: if hard { "jpg" } else { "png" },
            three,
        })
    }

    /// Writes `img` as a JPEG or PNG, by `path`'s extension.
    fn write_image(path: &Path, img: &xsurf_core::image::Image) -> anyhow::Result<()> {
        if path.extension().is_some_and(|e| e == "jpg") {
            xsurf_formats::frames::write_jpeg(path, img, SYNTH_JPEG_QUALITY)?;
        } else {
            let kind = match img.encoding {
                xsurf_core::image::Encoding::Rgb8 => xsurf_formats::image::PngKind::Rgb8,
                _ => xsurf_formats::image::PngKind::Grey8,
            };
            xsurf_formats::image::write_png(path, img.width, img.height, kind, &img.data)?;
        }
        Ok(())
    }

    /// The head of calibrate.sh. The script calls the binary that wrote it (xsurf need not be
    /// on PATH after a plain build); XSURF overrides it.
    fn script_head(&self) -> String {
        let exe = std::env::current_exe().ok().and_then(|p| p.to_str().map(str::to_owned)).map_or_else(
            || "xsurf".to_string(),
            // Escaped for its place inside double quotes in the script.
            |p| p.chars().flat_map(|c| if "\"$`\\".contains(c) { vec!['\\', c] } else { vec![c] }).collect(),
        );
        format!(
            "#!/usr/bin/env bash\n# Calibrates the rig from this set (written by `xsurf calibrate synth`); compare rig.yaml with truth_rig.yaml.\n# XSURF=/path/to/xsurf runs another xsurf than the one that wrote it.\nset -euo pipefail\ncd \"$(dirname \"$0\")\"\nXSURF=\"${{XSURF:-{exe}}}\"\nB=\"--board {}x{} --square {}\"\n",
            self.spec.cols, self.spec.rows, self.square
        )
    }

    /// Camera `ci`'s images: board views for its intrinsics, the board on the table at
    /// [`SYNTH_TRAVELS`] for its placement, the laser on the tabletop at [`SYNTH_HEIGHTS`].
    /// Returns its intrinsics command and its arguments to the placement and laser commands.
    fn camera(
        &self,
        truth: &Rig,
        ci: usize,
        board_pose: &xsurf_core::geom::Iso3,
    ) -> anyhow::Result<(String, String, String)> {
        let (dir, spec, ext, count, seed) = (&self.dir, &self.spec, self.ext, self.count, self.seed);
        let cam = &truth.cameras[ci];
        let model = cam.model()?;
        let rays = RayTable::new(&model);
        let poses = board_views(&model, spec, count, seed + 1000 * ci as u64);
        if poses.len() < count {
            return Err(usage(format!(
                "--size {}x{}: the {}x{} board fits in view only {} of {count} times (a larger image, or fewer --views)",
                self.size.0,
                self.size.1,
                spec.cols,
                spec.rows,
                poses.len()
            )));
        }
        for (i, pose) in poses.iter().enumerate() {
            let img = render_board(&rays, pose, spec, &self.looks.0, &self.exposure, seed ^ ((ci * 100 + i) as u64));
            Self::write_image(&dir.join(format!("intrinsics/{}_{i:02}.{ext}", cam.name)), &img)?;
        }
        let intrinsics = format!("\"$XSURF\" calibrate intrinsics $B -o {0}.yaml intrinsics/{0}_*.{ext}\n", cam.name);
        let mut names = Vec::new();
        for (i, &t) in SYNTH_TRAVELS.iter().enumerate() {
            let pose = table_from_carm(t, 0.0, 0.0).compose(&cam.carm_from_optical()).inverse().compose(board_pose);
            let img =
                render_board(&rays, &pose, spec, &self.looks.1, &self.exposure, seed ^ ((ci * 100 + 50 + i) as u64));
            let name = format!("placement/{}_{i}.{ext}", cam.name);
            Self::write_image(&dir.join(&name), &img)?;
            names.push(name);
        }
        let travels: Vec<String> = SYNTH_TRAVELS.iter().map(|t| t.to_string()).collect();
        let placement = format!(
            " \\\n  --camera {0} --intrinsics {0}.yaml --travels {1} {2}",
            cam.name,
            travels.join(","),
            names.join(" ")
        );
        let encoding = if self.three { xsurf_core::image::Encoding::Rgb8 } else { xsurf_core::image::Encoding::Mono8 };
        let mut settings =
            ScanSettings { noise_sigma: self.noise, seed: seed + 77, encoding, ..ScanSettings::default() };
        self.preset.apply(&mut settings);
        let scanner = Scanner::new(Scene::tabletop(), truth.clone(), self.preset.laser(), settings)?;
        let mut names = Vec::new();
        for (i, &hgt) in SYNTH_HEIGHTS.iter().enumerate() {
            let img = scanner.render_at(ci, &table_from_carm(0.0, hgt, 0.0), true, (ci * 10 + i) as u64);
            let name = format!("laser/{}_{i}.png", cam.name);
            Self::write_image(&dir.join(&name), &img)?;
            names.push(name);
        }
        let heights: Vec<String> = SYNTH_HEIGHTS.iter().map(|t| t.to_string()).collect();
        let laser = format!(" \\\n  --camera {} --heights {} {}", cam.name, heights.join(","), names.join(" "));
        println!(
            "{}: {} board views, {} on the tabletop, {} laser lines",
            cam.name,
            poses.len(),
            SYNTH_TRAVELS.len(),
            SYNTH_HEIGHTS.len()
        );
        Ok((intrinsics, placement, laser))
    }
}

/// [`Rig::three_lasers`] as mounted: each laser off its design by a fraction of a degree about
/// its source and a millimetre or two along the travel (what the laser calibration is for).
fn mounted_three_lasers(size: (u32, u32)) -> Rig {
    let mut rig = Rig::three_lasers(size.0, size.1);
    for (l, (deg, shift_m)) in rig.lasers.iter_mut().zip([(0.15, 0.0005), (0.6, 0.0015), (-0.5, -0.0012)]) {
        let (sn, cs) = f64::to_radians(deg).sin_cos();
        let [nx, ny, nz, _] = l.plane;
        // Turned about the X axis through the source, then moved along Y with it.
        let n = [nx, cs * ny - sn * nz, sn * ny + cs * nz];
        l.source[1] += shift_m;
        let d = n[0] * l.source[0] + n[1] * l.source[1] + n[2] * l.source[2];
        l.plane = [n[0], n[1], n[2], d];
    }
    rig.laser_plane = rig.lasers[0].plane;
    rig
}

/// `xsurf calibrate synth DIR`: a calibration set rendered from the study's rig, with the
/// true rig and the commands that calibrate from it.
fn synth(args: &[String]) -> anyhow::Result<()> {
    let set = SynthSet::parse(args)?;
    let dir = &set.dir;
    let truth = if set.three { mounted_three_lasers(set.size) } else { Rig::study(set.size.0, set.size.1) };
    for sub in ["intrinsics", "placement", "laser"] {
        std::fs::create_dir_all(dir.join(sub)).with_context(|| format!("{}", dir.join(sub).display()))?;
    }
    xsurf_formats::rig::write(
        &dir.join("truth_rig.yaml"),
        &truth,
        "the true rig the calibration set was rendered with",
    )?;
    // The placement board: centred under the C-arm at travel 0.
    let (spec, square) = (&set.spec, set.square);
    let origin = Vec3::new(-(spec.cols as f64 - 1.0) * 0.5 * square, (spec.rows as f64 - 1.0) * 0.5 * square, 0.0);
    let board_pose = table_from_board(origin, 0.0);
    let mut script = set.script_head();
    let mut placement_args =
        format!("\"$XSURF\" calibrate placement $B --board-origin {},{},0 -o rig.yaml", origin.x, origin.y);
    if set.three {
        // The scanner as designed (cameras and lasers: names, colours, nominal planes): what
        // the placement starts from and the laser calibration corrects.
        let nominal = Rig::three_lasers(set.size.0, set.size.1);
        xsurf_formats::rig::write(&dir.join("nominal_rig.yaml"), &nominal, "the scanner as designed")?;
        placement_args.push_str(" --rig nominal_rig.yaml");
    }
    let mut laser_args = String::from("\"$XSURF\" calibrate laser --rig rig.yaml");
    for ci in 0..truth.cameras.len() {
        let (intrinsics, placement, laser) = set.camera(&truth, ci, &board_pose)?;
        script.push_str(&intrinsics);
        placement_args.push_str(&placement);
        laser_args.push_str(&laser);
    }
    script.push_str(&placement_args);
    script.push('\n');
    script.push_str(&laser_args);
    script.push('\n');
    write_bytes_atomic(&dir.join("calibrate.sh"), script.as_bytes())?;
    println!("calibration set written to {} (truth_rig.yaml; run calibrate.sh to calibrate from it)", dir.display());
    Ok(())
}
