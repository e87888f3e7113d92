//! `xray_aligner`: the radiograph, placed under the surface.
//!
//! The radiograph comes from a DICOM file (parameter `dicom_file`, loaded at start and again
//! whenever the parameter is set: `ros2 param set /xray_aligner dicom_file /path/x.dcm` is the
//! request) and is published as acquired on `/xray/image` (mono16); or, with
//! `image_source: topic`, it arrives on `/xray/image` from the scanner. It is placed in `table`
//! once its scan has ended and the C-arm's pose is known over the whole exposure: rows by the
//! travel between the exposure's start and end (the scan's START and END events, or the
//! DICOM's Acquisition DateTime and Exposure Time), columns by the fan-beam geometry at the
//! reference plane. Unexposed detector columns are cropped. The result goes out on
//! `/xray/overlay` (a TRIANGLE_LIST grid with per-vertex grey and the windowed PNG as an
//! embedded texture; the merger puts it into the scene files) and, with `output_dir`, as
//! `<output_dir>/scan_<id>/xray.png` (windowed, cropped) and `xray.json` (the placement: crop,
//! exposure, geometry and the grid of table points with their texture coordinates).

mod params;
pub use params::*;

/// The node type, as the registry lists it.
pub const NODE: crate::registry::NodeType =
    crate::registry::NodeType::of::<XrayAlignerParams>("xray_aligner", crate::registry::Role::Scanner, 50, |p| Ok(boxed(XrayAlignerNode::new(p)?)));

use crate::convert;
use crate::tf::TfBuffer;
use std::path::PathBuf;
use std::sync::Arc;
use xsurf_core::geom::{Plane, Vec3};
use xsurf_core::xray::{DetectorGeometry, FanBeam, Placement, Radiograph, Window};
use xsurf_formats::dicom::{self, XrayInfo};
use xsurf_formats::image::{encode_png, PngKind};
use xsurf_msgs::geometry_msgs::{Point, Vector3};
use xsurf_msgs::sensor_msgs::{CompressedImage, Image};
use xsurf_msgs::std_msgs::ColorRGBA;
use xsurf_msgs::tf2_msgs::TFMessage;
use xsurf_msgs::visualization_msgs::{Marker, UVCoordinate};
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_msgs::RosMessage;
use xsurf_runtime::component::{boxed, Component, Msg, NodeError, Outbox, Port, QosClass};
use xsurf_runtime::params::{NodeParams, ParamError, Params};

#[derive(Debug, Clone, PartialEq)]
struct Config {
    from_topic: bool,
    dicom_file: String,
    topic_monochrome1: bool,
    plane: Plane,
    source: Vec3,
    source_detector_m: f64,
    pitch_m: f64,
    center_column: Option<f64>,
    flip_columns: bool,
    plane_height_m: f64,
    crop_threshold: f64,
    window: Option<Window>,
    dicom_timing: bool,
    grid: (u32, u32),
    wait_ns: i64,
    output_dir: Option<PathBuf>,
    frame_id: String,
    table_frame: String,
    carm_frame: String,
}

fn config(p: &Params) -> Result<Config, ParamError> {
    let p = XrayAlignerParams::from_params(p)?;
    let plane = crate::triangulator::laser_plane("laser_plane", &p.laser_plane)?;
    let plane = Plane::from_params(plane)
        .ok_or_else(|| Params::invalid("laser_plane", format!("{plane:?}: needs 4 finite values, non-zero normal")))?;
    let src = &p.laser_source;
    let source = <[f64; 3]>::try_from(src.as_slice())
        .ok()
        .map(Vec3::from_array)
        .ok_or_else(|| Params::invalid("laser_source", format!("{src:?}: needs 3 finite values")))?;
    let crop = p.crop_threshold;
    if !(0.0..1.0).contains(&crop) {
        return Err(Params::invalid("crop_threshold", format!("{crop:?} is not in [0, 1)")));
    }
    let (wc, ww) = (p.window_center, p.window_width);
    if !(ww >= 0.0) {
        return Err(Params::invalid("window_width", format!("{ww:?} must be >= 0")));
    }
    Ok(Config {
        from_topic: p.image_source == ImageSource::Topic,
        dicom_file: p.dicom_file,
        topic_monochrome1: p.topic_monochrome1,
        plane,
        source,
        source_detector_m: p.source_detector_m,
        pitch_m: p.detector_pitch_m,
        center_column: (p.center_column >= 0.0).then_some(p.center_column),
        flip_columns: p.flip_columns,
        plane_height_m: p.plane_height_m,
        crop_threshold: crop,
        window: (ww >= 1.0).then_some(Window { center: wc, width: ww }),
        dicom_timing: p.exposure_timing == ExposureTiming::Dicom,
        grid: (p.grid_columns, p.grid_rows),
        wait_ns: (p.wait_for_pose_s * 1e9) as i64,
        output_dir: p.output_dir,
        frame_id: p.frame_id,
        table_frame: p.table_frame,
        carm_frame: p.carm_frame,
    })
}

/// The radiograph's overlay for rviz2: the placed grid as a triangle list, each vertex
/// coloured by the windowed grey level under it (`grey`, `size` = width x height) and
/// textured with the PNG.
fn overlay_marker(
    grid: &xsurf_core::xray::PlacedGrid,
    grey: &[u8],
    size: (u32, u32),
    png: &[u8],
    scan_id: u32,
    header: xsurf_msgs::std_msgs::Header,
) -> Marker {
    let (w, h) = (size.0 as usize, size.1 as usize);
    let sample = |uv: [f32; 2]| -> f32 {
        let x = ((uv[0] * w as f32) as usize).min(w - 1);
        let y = (((1.0 - uv[1]) * h as f32) as usize).min(h - 1);
        f32::from(grey[y * w + x]) / 255.0
    };
    let mut m = Marker {
        header: header.clone(),
        ns: "xray".into(),
        id: scan_id as i32,
        type_: Marker::TRIANGLE_LIST,
        action: Marker::ADD,
        scale: Vector3 { x: 1.0, y: 1.0, z: 1.0 },
        color: ColorRGBA { r: 1.0, g: 1.0, b: 1.0, a: 1.0 },
        texture_resource: "embedded://xray.png".into(),
        texture: CompressedImage { header, format: "png".into(), data: png.to_vec() },
        ..Default::default()
    };
    m.pose.orientation.w = 1.0;
    for t in &grid.triangles {
        for &i in t {
            let (p, uv) = (grid.positions[i as usize], grid.uv[i as usize]);
            m.points.push(Point { x: p.x, y: p.y, z: p.z });
            let g = sample(uv);
            m.colors.push(ColorRGBA { r: g, g, b: g, a: 1.0 });
            // rviz2 (Ogre) has v = 0 at the image's top.
            m.uv_coordinates.push(UVCoordinate { u: uv[0], v: 1.0 - uv[1] });
        }
    }
    m
}

/// A complete scan: its id and exposure window.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ScanWindow {
    id: u32,
    start_ns: i64,
    end_ns: Option<i64>,
}

/// The xray_aligner component.
pub struct XrayAlignerNode {
    cfg: Config,
    tf: TfBuffer,
    scan: Option<ScanWindow>,
    /// The radiograph waiting to be placed.
    pending: Option<(Radiograph, XrayInfo)>,
    load_requested: bool,
    end_seen_ns: Option<i64>,
    loaded: u64,
    load_errors: u64,
    placed: u64,
    place_errors: u64,
    bad_images: u64,
}

/// The X-ray aligner's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// `/tf`: the C-arm's poses during the exposure.
    Tf,
    /// `/scan/events`: the exposure's window.
    Events,
    /// `/xray/image`, with `image_source: topic`.
    Image,
}

/// The X-ray aligner's outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// `/xray/image`: the radiograph read from its DICOM file (`image_source: dicom`).
    Image,
    /// `/xray/overlay`: the radiograph placed in the table frame.
    Overlay,
}

type Out = Outbox<Input, Output>;

impl XrayAlignerNode {
    /// Radiographs placed, so far.
    pub fn placed(&self) -> u64 {
        self.placed
    }
    /// Builds the node from its parameters (a `dicom_file` is loaded at the first tick).
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        let cfg = config(p)?;
        // The whole exposure's poses are kept: up to about an hour of /tf at 100 Hz.
        let tf = TfBuffer::with_capacity(&cfg.table_frame, &cfg.carm_frame, 500_000_000, 400_000);
        Ok(Self {
            load_requested: !cfg.from_topic && !cfg.dicom_file.is_empty(),
            cfg,
            tf,
            scan: None,
            pending: None,
            end_seen_ns: None,
            loaded: 0,
            load_errors: 0,
            placed: 0,
            place_errors: 0,
            bad_images: 0,
        })
    }

    /// Index of `/xray/overlay` among the outputs (`/xray/image` comes first when loading DICOM).
    fn load(&mut self, out: &mut Out) {
        self.load_requested = false;
        let path = PathBuf::from(&self.cfg.dicom_file);
        match dicom::read_file(&path) {
            Ok(f) => {
                log::info!(
                    "xray_aligner: {}: {}x{} {}-bit {}",
                    path.display(),
                    f.image.width,
                    f.image.height,
                    f.image.bits_stored,
                    if f.image.monochrome1 { "MONOCHROME1" } else { "MONOCHROME2" }
                );
                self.loaded += 1;
                let stamp = f.info.acquisition_start_ns.or(self.scan.map(|s| s.start_ns)).unwrap_or(0);
                out.publish(Output::Image, Msg::Image(Arc::new(mono16_msg(&f.image, stamp, &self.cfg.carm_frame))));
                self.pending = Some((f.image, f.info));
            }
            Err(e) => {
                self.load_errors += 1;
                log::error!("xray_aligner: {e}");
            }
        }
    }

    /// The exposure window: from the events or the file.
    fn exposure(&self, info: &XrayInfo) -> Result<(u32, i64, i64), String> {
        if self.cfg.dicom_timing {
            let start = info.acquisition_start_ns.ok_or("the DICOM has no AcquisitionDateTime (0008,002A)")?;
            let ms = info.exposure_ms.ok_or("the DICOM has no ExposureTime (0018,1150)")?;
            return Ok((self.scan.map_or(0, |s| s.id), start, start + (ms * 1e6) as i64));
        }
        match self.scan {
            Some(ScanWindow { id, start_ns, end_ns: Some(end) }) => Ok((id, start_ns, end)),
            Some(_) => Err("the scan has not ended yet".into()),
            None => Err("no scan START/END on /scan/events (or set exposure_timing: dicom)".into()),
        }
    }

    /// Places the pending radiograph if its exposure is complete and posed (or `force`).
    fn try_place(&mut self, now_ns: i64, force: bool, out: &mut Out) {
        let Some((image, info)) = &self.pending else { return };
        let (scan_id, start, end) = match self.exposure(info) {
            Ok(w) => w,
            Err(e) => {
                if force {
                    self.place_errors += 1;
                    log::error!("xray_aligner: cannot place the radiograph: {e}");
                    self.pending = None;
                }
                return;
            }
        };
        let posed = self.tf.latest_pose_stamp().is_some_and(|l| l >= end);
        let waited = self.end_seen_ns.is_some_and(|t| now_ns >= t + self.cfg.wait_ns);
        if !(posed || waited || force) {
            return;
        }
        let result = self.place(image, info, scan_id, start, end);
        self.pending = None;
        match result {
            Ok((marker, png, json)) => {
                self.placed += 1;
                log::info!(
                    "xray_aligner: scan {scan_id}: radiograph placed, {} triangles on z = {} m",
                    marker.points.len() / 3,
                    self.cfg.plane_height_m
                );
                if let Some(dir) = &self.cfg.output_dir {
                    let dir = dir.join(format!("scan_{scan_id}"));
                    let r = std::fs::create_dir_all(&dir).map_err(|e| e.to_string()).and_then(|_| {
                        xsurf_formats::write_bytes_atomic(&dir.join("xray.png"), &png).map_err(|e| e.to_string())?;
                        xsurf_formats::write_bytes_atomic(&dir.join("xray.json"), json.as_bytes())
                            .map_err(|e| e.to_string())
                    });
                    if let Err(e) = r {
                        log::error!("xray_aligner: cannot write xray.png and xray.json in {}: {e}", dir.display());
                    }
                }
                out.publish(Output::Overlay, Msg::Marker(Arc::new(marker)));
            }
            Err(e) => {
                self.place_errors += 1;
                log::error!("xray_aligner: cannot place the radiograph of scan {scan_id}: {e}");
            }
        }
    }

    fn place(
        &self,
        image: &Radiograph,
        info: &XrayInfo,
        scan_id: u32,
        start_ns: i64,
        end_ns: i64,
    ) -> Result<(Marker, Vec<u8>, String), String> {
        let c = &self.cfg;
        let pick = |param: f64, file: Option<f64>, what: &str| -> Result<f64, String> {
            if param > 0.0 {
                return Ok(param);
            }
            file.filter(|v| *v > 0.0).ok_or_else(|| format!("{what} is 0 and the radiograph does not give it"))
        };
        let geometry = DetectorGeometry {
            source_detector_m: pick(
                c.source_detector_m,
                info.source_detector_m,
                "source_detector_m (DICOM DistanceSourceToDetector (0018,1110))",
            )?,
            pitch_m: pick(
                c.pitch_m,
                info.pixel_spacing_m.map(|p| p[1]),
                "detector_pitch_m (DICOM ImagerPixelSpacing (0018,1164))",
            )?,
            center_column: c.center_column,
            flip_columns: c.flip_columns,
            plane_height_m: c.plane_height_m,
        };
        let cols = if c.crop_threshold > 0.0 {
            image.exposed_columns(c.crop_threshold).map_err(|e| e.to_string())?
        } else {
            0..image.width
        };
        let placement = Placement {
            fan: FanBeam::new(&c.plane, c.source).map_err(|e| e.to_string())?,
            geometry,
            detector_columns: image.width,
            rows: image.height,
            start_ns,
            end_ns,
        };
        let pose_at = |t: i64| self.tf.table_from_carm(t).map_err(|e| e.to_string());
        let grid = placement.grid(cols.clone(), c.grid.0, c.grid.1, &pose_at).map_err(|e| e.to_string())?;
        let cropped = image.crop_columns(cols.clone());
        let grey = cropped.display(c.window);
        let png = encode_png(cropped.width, cropped.height, PngKind::Grey8, &grey).map_err(|e| e.to_string())?;
        let m = overlay_marker(&grid, &grey, (cropped.width, cropped.height), &png, scan_id, convert::header(start_ns, &c.frame_id));
        let json = serde_json::json!({
            "scan_id": scan_id,
            "detector_columns": image.width,
            "columns": [cols.start, cols.end],
            "rows": image.height,
            "exposure_ns": [start_ns, end_ns],
            "source_detector_m": geometry.source_detector_m,
            "detector_pitch_m": geometry.pitch_m,
            "plane_height_m": geometry.plane_height_m,
            "grid": {
                "columns": grid.columns,
                "rows": grid.rows,
                "positions": grid.positions.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>(),
                "uv": grid.uv,
            },
            "about": "xray.png is the cropped radiograph (columns [start, end) of the detector); grid vertex (j, k) lies at texture (u, v) = (j / (columns - 1), 1 - k / (rows - 1)), v = 0 at the image's last row",
        });
        Ok((m, png, serde_json::to_string_pretty(&json).map_err(|e| e.to_string())?))
    }
}

/// `/xray/image`: the stored values as mono16.
fn mono16_msg(r: &Radiograph, stamp_ns: i64, frame: &str) -> Image {
    Image {
        header: convert::header(stamp_ns, frame),
        height: r.height,
        width: r.width,
        encoding: "mono16".into(),
        is_bigendian: 0,
        step: r.width * 2,
        data: r.pixels.iter().flat_map(|v| v.to_le_bytes()).collect(),
    }
}

/// A radiograph from an `/xray/image` message (mono8 or mono16).
fn from_msg(m: &Image, monochrome1: bool) -> Result<Radiograph, String> {
    let bpp = match m.encoding.as_str() {
        "mono16" | "16UC1" => 2usize,
        "mono8" | "8UC1" => 1,
        other => return Err(format!("encoding {other}: a radiograph must be mono8 or mono16")),
    };
    let (w, h, step) = (m.width as usize, m.height as usize, m.step as usize);
    if w == 0 || h == 0 || step < w * bpp || m.data.len() < step * (h - 1) + w * bpp {
        return Err(format!("{}x{} step {} does not fit {} bytes", m.width, m.height, m.step, m.data.len()));
    }
    let mut px = Vec::with_capacity(w * h);
    for row in m.data.chunks(step).take(h) {
        if bpp == 1 {
            px.extend(row[..w].iter().map(|&b| u16::from(b)));
        } else {
            px.extend(row[..2 * w].chunks_exact(2).map(|b| {
                if m.is_bigendian != 0 {
                    u16::from_be_bytes([b[0], b[1]])
                } else {
                    u16::from_le_bytes([b[0], b[1]])
                }
            }));
        }
    }
    let mut r = Radiograph::new(m.width, m.height, px, if bpp == 1 { 8 } else { 16 }).map_err(|e| e.to_string())?;
    r.monochrome1 = monochrome1;
    Ok(r)
}

impl Component for XrayAlignerNode {
    type Input = Input;
    type Output = Output;
    fn node_name(&self) -> &'static str {
        "xray_aligner"
    }
    fn inputs(&self) -> Vec<(Input, Port)> {
        let mut v = vec![
            (Input::Tf, Port::new("/tf", TFMessage::TYPE_NAME, QosClass::Reliable)),
            (Input::Events, Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable)),
        ];
        if self.cfg.from_topic {
            v.push((Input::Image, Port::new("/xray/image", Image::TYPE_NAME, QosClass::Reliable)));
        }
        v
    }
    fn outputs(&self) -> Vec<(Output, Port)> {
        let mut v = Vec::new();
        if !self.cfg.from_topic {
            v.push((Output::Image, Port::new("/xray/image", Image::TYPE_NAME, QosClass::Reliable)));
        }
        v.push((Output::Overlay, Port::new("/xray/overlay", Marker::TYPE_NAME, QosClass::State)));
        v
    }
    fn reconfigure(&mut self, p: &Params) -> Result<(), ParamError> {
        let c = config(p)?;
        if c.from_topic != self.cfg.from_topic {
            return Err(Params::invalid("image_source", "cannot change while running (restart the node)"));
        }
        if !c.from_topic && !c.dicom_file.is_empty() && c.dicom_file != self.cfg.dicom_file {
            self.load_requested = true;
        }
        self.cfg = c;
        Ok(())
    }
    fn handle(&mut self, input: Input, msg: &Msg, out: &mut Out) -> Result<(), NodeError> {
        match (input, msg) {
            (Input::Tf, Msg::Tf(t)) => {
                let added = self.tf.add_dynamic(t);
                if self.pending.is_some() && self.end_seen_ns.is_some() {
                    let now = self.tf.latest_pose_stamp().unwrap_or(0);
                    self.try_place(now, false, out);
                }
                added.map_err(NodeError::malformed)
            }
            (Input::Events, Msg::ScanEvent(e)) => {
                let stamp = e.header.stamp.nanos();
                match e.event {
                    ScanEvent::START => {
                        // The poses of the scan before this one are kept (its radiograph may
                        // still come, timed by its DICOM); older ones are forgotten.
                        if let Some(previous) = self.scan.map(|s| s.start_ns) {
                            self.tf.forget_before(previous.min(stamp));
                        }
                        self.scan = Some(ScanWindow { id: e.scan_id, start_ns: stamp, end_ns: None });
                        self.end_seen_ns = None;
                    }
                    ScanEvent::END => match &mut self.scan {
                        Some(s) if s.id == e.scan_id => {
                            s.end_ns = Some(stamp);
                            self.end_seen_ns = Some(stamp);
                        }
                        _ => log::warn!("xray_aligner: END of scan {} without its START", e.scan_id),
                    },
                    _ => {
                        self.scan = None;
                        self.end_seen_ns = None;
                    }
                }
                Ok(())
            }
            (Input::Image, Msg::Image(m)) if self.cfg.from_topic => match from_msg(m, self.cfg.topic_monochrome1) {
                Ok(r) => {
                    self.pending = Some((r, XrayInfo::default()));
                    self.loaded += 1;
                    Ok(())
                }
                Err(e) => {
                    self.bad_images += 1;
                    Err(NodeError::malformed(format!("/xray/image: {e}")))
                }
            },
            (i, m) => Err(NodeError::unexpected(i, m)),
        }
    }
    fn tick(&mut self, now_ns: i64, out: &mut Out) {
        if self.load_requested {
            self.load(out);
        }
        if self.pending.is_some() && (self.end_seen_ns.is_some() || self.cfg.dicom_timing) {
            self.try_place(now_ns, false, out);
        }
    }
    fn finish(&mut self, out: &mut Out) {
        if self.load_requested {
            self.load(out);
        }
        self.try_place(i64::MAX, true, out);
    }
    /// Bulk work: the live host runs it behind the frame path.
    fn bulk(&self) -> bool {
        true
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("loaded", self.loaded),
            ("load_errors", self.load_errors),
            ("placed", self.placed),
            ("place_errors", self.place_errors),
            ("bad_images", self.bad_images),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registry::{build, declarations};
    use std::cell::RefCell;
    use std::rc::Rc;
    use xsurf_core::pose::table_from_carm;
    use xsurf_core::xray::Radiograph;
    use xsurf_runtime::params::ParamValue as V;
    use xsurf_runtime::router::Router;

    fn params(node: &str, set: &[(&str, V)]) -> Params {
        let overrides = set.iter().map(|(k, v)| (k.to_string(), v.clone())).collect();
        Params::resolve(&declarations(node).unwrap(), &overrides).unwrap()
    }

    #[test]
    fn a_radiograph_loaded_on_request_after_the_scan_is_placed_and_reaches_the_scene() {
        let dir = std::env::temp_dir().join(format!("xsurf-aligner-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        // A 40x10 radiograph: 5 unexposed columns at each edge.
        let px: Vec<u16> =
            (0..400).map(|i| if (5..35).contains(&(i % 40)) { 9000 + (i % 7) as u16 } else { 20 }).collect();
        let mut r = Radiograph::new(40, 10, px, 14).unwrap();
        r.monochrome1 = true;
        let info = XrayInfo { source_detector_m: Some(1.3), pixel_spacing_m: Some([0.01, 0.01]), ..Default::default() };
        let dcm = dir.join("x.dcm");
        dicom::write_file(&dcm, &r, &info, "t").unwrap();

        let mut router = Router::new();
        let aligner =
            router.add(build("xray_aligner", &params("xray_aligner", &[])).unwrap(), "xray_aligner", "/", &[]);
        let out = V::String(dir.to_string_lossy().into_owned());
        router.add(build("merger", &params("merger", &[("output_dir", out)])).unwrap(), "merger", "/", &[]);
        let seen: Rc<RefCell<Vec<(String, Msg)>>> = Rc::default();
        let s = seen.clone();
        router.set_tap(Box::new(move |t, m| s.borrow_mut().push((t.to_string(), m.clone()))));

        // A scan from t = 1 s to 2 s at 0.1 m/s, poses at 100 Hz; a cloud so the merger merges.
        let event = |t: i64, e: u8| {
            Msg::ScanEvent(Arc::new(ScanEvent { header: convert::header(t, "table"), scan_id: 7, event: e }))
        };
        router.publish("/scan/events", &event(1_000_000_000, ScanEvent::START));
        for k in 0..=250 {
            let t = k * 10_000_000;
            let pose = table_from_carm((t - 1_000_000_000) as f64 * 1e-10, 0.0, 0.0);
            let tf = TFMessage { transforms: vec![convert::transform_stamped(t, "table", "carm", &pose)] };
            router.publish("/tf", &Msg::Tf(Arc::new(tf)));
        }
        let mut grid = xsurf_core::mesh::Grid::new(3);
        for f in 0..3 {
            let points = (0..3).map(|i| [i as f32 * 0.01, f as f32 * 0.01, 0.0]).collect();
            let p = xsurf_core::triangulate::Profile {
                points,
                intensity: vec![100.0; 3],
                outside_volume: 0,
                rgb: None,
                range: vec![1.0; 3],
            };
            grid.push(i64::from(f), &p).unwrap();
        }
        // Stamped in the scan (its last frame): a cloud older than START is refused as stale.
        let h = convert::header(1_900_000_000, "table");
        router.publish("/cam1/cloud", &Msg::Cloud(Arc::new(convert::grid_cloud(&grid, h))));
        router.publish("/scan/events", &event(2_000_000_000, ScanEvent::END));
        router.tick(2_500_000_000);
        router.tick(3_100_000_000);
        let scan = dir.join("scan_7");
        assert!(scan.join("scene.wrl").is_file(), "merged");
        assert!(!scan.join("xray.png").exists(), "no radiograph yet");

        // The request: the parameter is set after the scan.
        router
            .reconfigure(aligner, &params("xray_aligner", &[("dicom_file", V::String(dcm.to_string_lossy().into()))]))
            .unwrap();
        router.tick(3_200_000_000);
        let seen = seen.borrow();
        let image = seen.iter().find(|(t, _)| t == "/xray/image").expect("published as acquired");
        let Msg::Image(img) = &image.1 else { panic!() };
        assert_eq!((img.encoding.as_str(), img.width, img.height, img.step), ("mono16", 40, 10, 80));
        let overlay = seen.iter().find(|(t, _)| t == "/xray/overlay").expect("placed");
        let Msg::Marker(m) = &overlay.1 else { panic!() };
        assert_eq!((m.id, m.type_, m.ns.as_str()), (7, Marker::TRIANGLE_LIST, "xray"));
        assert_eq!(m.points.len() % 3, 0);
        assert_eq!((m.colors.len(), m.uv_coordinates.len()), (m.points.len(), m.points.len()));
        assert_eq!(m.texture.format, "png");
        // Columns 5..35 cropped, 0.01 m pitch demagnified by 1.2 / 1.3 at the tabletop; rows
        // from travel 0 (START) to 0.1 m (END).
        let xs: Vec<f64> = m.points.iter().map(|p| p.x).collect();
        let ys: Vec<f64> = m.points.iter().map(|p| p.y).collect();
        let span = |v: &[f64]| {
            (v.iter().cloned().fold(f64::INFINITY, f64::min), v.iter().cloned().fold(f64::NEG_INFINITY, f64::max))
        };
        let (x0, x1) = span(&xs);
        assert!((x0 + 0.15 * 1.2 / 1.3).abs() < 1e-9 && (x1 - 0.15 * 1.2 / 1.3).abs() < 1e-9, "{x0} {x1}");
        let (y0, y1) = span(&ys);
        assert!(y0.abs() < 1e-9 && (y1 - 0.1).abs() < 1e-9, "{y0} {y1}");
        // The merger rewrote the scan's scene with the radiograph.
        assert!(scan.join("xray.png").is_file());
        assert!(std::fs::read_to_string(scan.join("scene.wrl")).unwrap().contains("ImageTexture"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
