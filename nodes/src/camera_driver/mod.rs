//! `camera_driver`: publishes `image_raw` and `camera_info` (same stamp, frame
//! `<camera>_optical_frame`). Source `synthetic`: the synthetic scanner renders what the camera
//! sees with the C-arm where `/tf` says it is at the exposure, the laser on between a scan's
//! START and END; CI and demos use it in place of a camera. Source `files`: an image sequence
//! (the study's `frame_000.bmp`..., BMP/PNG/PGM/PPM/JPEG) at `fps`, stamped from the rate or a
//! sidecar file. camera_info comes from `camera_info_url` (the camera_calibration YAML) or the
//! rig. `rotate_180` turns every image (the study's cameras hung upside down); the calibration
//! must then describe the turned images.

mod params;
mod source;
pub use params::*;

/// The node type, as the registry lists it.
pub const NODE: crate::registry::NodeType =
    crate::registry::NodeType::of::<CameraDriverParams>("camera_driver", crate::registry::Role::Source, 2, |p| Ok(boxed(CameraDriverNode::new(p)?)));

use crate::edge_detector::Transport;
use crate::convert;
use std::sync::Arc;
use xsurf_core::geom::Iso3;
use xsurf_core::image::Encoding;
use xsurf_core::rig::Rig;
use xsurf_core::synth::{Scene, SCENE_NAMES};
use xsurf_msgs::sensor_msgs::{CameraInfo, CompressedImage, Image};
use xsurf_msgs::std_msgs::StringMsg;
use xsurf_msgs::tf2_msgs::TFMessage;
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_msgs::RosMessage;
use xsurf_runtime::component::{boxed, Component, Msg, NodeError, Outbox, Port, QosClass};
use xsurf_runtime::params::{NodeParams, ParamError, Params};

/// Where the images come from, as the parameters describe it.
#[derive(Debug, Clone, PartialEq)]
enum SourceSpec {
    Synthetic,
    Files {
        list: Vec<std::path::PathBuf>,
        stamps: Option<Vec<i64>>,
        repeat: bool,
    },
    /// A Video4Linux2 camera; stamps are the dequeue time minus `offset_ns`.
    V4l2 {
        device: std::path::PathBuf,
        offset_ns: i64,
    },
}

struct Config {
    source: SourceSpec,
    camera_info: Option<xsurf_core::camera::CameraModel>,
    rotate_180: bool,
    scene: Scene,
    camera: String,
    rig: Option<Rig>,
    width: u32,
    height: u32,
    period_ns: i64,
    encoding: Encoding,
    /// The compressed transport's codec and JPEG quality; None for raw images.
    compressed: Option<(xsurf_formats::compressed::Codec, u8)>,
    seed: u64,
    table_frame: String,
    carm_frame: String,
}

/// The source the parameters describe, its files listed and its stamps read.
fn source_spec(p: &CameraDriverParams) -> Result<SourceSpec, ParamError> {
    Ok(match p.source {
        SourceKind::Synthetic => SourceSpec::Synthetic,
        SourceKind::Files => {
            let list = source::files::frame_list(&p.files).map_err(|e| Params::invalid("files", e))?;
            let stamps = match &p.timestamps_file {
                None => None,
                Some(ts) => {
                    let s = source::files::read_stamps(ts).map_err(|e| Params::invalid("timestamps_file", e))?;
                    if s.len() < list.len() {
                        return Err(Params::invalid(
                            "timestamps_file",
                            format!("{}: {} stamps for {} frames", ts.display(), s.len(), list.len()),
                        ));
                    }
                    Some(s)
                }
            };
            SourceSpec::Files { list, stamps, repeat: p.loop_files }
        }
        SourceKind::V4l2 => {
            if !cfg!(feature = "v4l2") {
                return Err(Params::invalid(
                    "source",
                    "v4l2: this build has no V4L2 support (build xsurf-nodes with `--features v4l2`)",
                ));
            }
            if p.device.is_empty() {
                return Err(Params::invalid("device", "the v4l2 source needs a device such as /dev/video0"));
            }
            let offset = p.stamp_offset_s;
            if !(0.0..=1.0).contains(&offset) {
                return Err(Params::invalid("stamp_offset_s", format!("{offset:?} is not in [0, 1]")));
            }
            SourceSpec::V4l2 { device: (&p.device).into(), offset_ns: (offset * 1e9).round() as i64 }
        }
    })
}

fn config(raw: &Params) -> Result<Config, ParamError> {
    let p = CameraDriverParams::from_params(raw)?;
    let source = source_spec(&p)?;
    let url = p.camera_info_url;
    let camera_info = if url.is_empty() {
        None
    } else {
        let path = xsurf_formats::calibration::url_path(&url).map_err(|e| Params::invalid("camera_info_url", e))?;
        let c =
            xsurf_formats::calibration::read(&path).map_err(|e| Params::invalid("camera_info_url", e.to_string()))?;
        Some(c.model().map_err(|e| Params::invalid("camera_info_url", e))?)
    };
    let scene = Scene::by_name(&p.scene).ok_or_else(|| {
        Params::invalid("scene", format!("unknown scene {:?} (known: {})", p.scene, SCENE_NAMES.join(", ")))
    })?;
    let dim = |n: &str, v: i64| -> Result<u32, ParamError> {
        u32::try_from(v)
            .ok()
            .filter(|&v| xsurf_core::limits::image_side_ok(v))
            .ok_or_else(|| Params::invalid(n, format!("{v} is not in {}", xsurf_core::limits::image_side_text())))
    };
    let fps = p.fps;
    if !(fps > 0.0 && fps <= 1000.0) {
        return Err(Params::invalid("fps", format!("{fps:?} is not in (0, 1000]")));
    }
    let encoding = match p.encoding.as_str() {
        "mono8" => Encoding::Mono8,
        "rgb8" => Encoding::Rgb8,
        "bgr8" => Encoding::Bgr8,
        other => return Err(Params::invalid("encoding", format!("{other:?} is not mono8, rgb8 or bgr8"))),
    };
    let compressed = match p.image_transport {
        Transport::Raw => None,
        Transport::Compressed => {
            let f = &p.compressed_format;
            let codec = xsurf_formats::compressed::Codec::parse(f)
                .ok_or_else(|| Params::invalid("compressed_format", format!("{f:?}: jpeg or png")))?;
            // In 1..=100 by the declaration's range.
            Some((codec, p.jpeg_quality.clamp(1, 100) as u8))
        }
    };
    let mut rig = match &p.rig_file {
        None => None,
        Some(f) => Some(xsurf_formats::rig::read(f).map_err(|e| Params::invalid("rig_file", e.to_string()))?),
    };
    if let Some(lasers) = crate::lasers::from_params(raw, &p.lasers, [0.0, 0.0, 1.2])? {
        // A grey camera sees every laser alike: only colour tells their lines apart.
        if let (false, SourceSpec::Synthetic, Some(second)) = (encoding.is_color(), &source, lasers.get(1)) {
            return Err(Params::invalid(
                &format!("laser.{}.channel", second.name),
                format!(
                    "{} on a {} camera: a grey image cannot tell {} lasers apart (encoding rgb8 or bgr8)",
                    second.channel.name(),
                    p.encoding,
                    lasers.len()
                ),
            ));
        }
        let study = xsurf_core::rig::Rig::study(dim("width", p.width)?, dim("height", p.height)?);
        rig.get_or_insert(study).lasers = lasers;
    }
    Ok(Config {
        source,
        camera_info,
        rotate_180: p.rotate_180,
        scene,
        camera: p.camera,
        rig,
        width: dim("width", p.width)?,
        height: dim("height", p.height)?,
        period_ns: (1e9 / fps) as i64,
        compressed,
        encoding,
        seed: p.seed as u64,
        table_frame: p.table_frame,
        carm_frame: p.carm_frame,
    })
}

/// The camera driver's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// `/tf`: the C-arm's pose, for the synthetic camera.
    Tf,
    /// `/scan/events`: the laser on between START and END, and the scans for the reports.
    Events,
}

/// The camera driver's outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// `image_raw` (or `image_raw/compressed`, by `image_transport`).
    Image,
    /// `camera_info`, stamped as its image.
    CameraInfo,
    /// `/scan/report`: this camera's account of each scan.
    Report,
}

type Out = Outbox<Input, Output>;

/// The camera driver component.
pub struct CameraDriverNode {
    cfg: Config,
    camera: String,
    /// Where the frames come from.
    source: Box<dyn source::FrameSource>,
    /// The two newest `table -> carm` samples, for extrapolating to the exposure.
    poses: [Option<(i64, Iso3)>; 2],
    laser_on: bool,
    /// The frames of the current scan, for its report.
    tally: crate::tally::ScanTally,
    /// A paced source's next frame slot.
    next_ns: Option<i64>,
    frames: u64,
    skipped: u64,
    encode_errors: u64,
}

impl CameraDriverNode {
    /// Builds the node from its parameters.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        let cfg = config(p)?;
        Ok(Self {
            camera: cfg.camera.clone(),
            source: source::build(&cfg.source),
            cfg,
            poses: [None, None],
            laser_on: false,
            tally: Default::default(),
            next_ns: None,
            frames: 0,
            skipped: 0,
            encode_errors: 0,
        })
    }

    /// Publishes a frame and its camera_info, both stamped with the frame's stamp in the
    /// camera's optical frame.
    fn publish_frame(&mut self, f: source::Frame, out: &mut Out) {
        let stamp = f.stamp_ns;
        let header = convert::header(stamp, &format!("{}_optical_frame", self.camera));
        let image = match self.cfg.compressed {
            None => Msg::Image(Arc::new(convert::image_msg(header.clone(), f.image))),
            Some((codec, quality)) => match xsurf_formats::compressed::encode(&f.image, codec, quality) {
                Ok((format, data)) => {
                    Msg::CompressedImage(Arc::new(CompressedImage { header: header.clone(), format, data }))
                }
                Err(e) => {
                    self.encode_errors += 1;
                    log::error!("camera_driver: frame at {}: {e}", convert::fmt_stamp(stamp));
                    return;
                }
            },
        };
        out.publish(Output::CameraInfo, Msg::CameraInfo(Arc::new(convert::camera_info(&f.model, header))));
        out.publish(Output::Image, image);
        self.frames += 1;
        self.tally.count(stamp);
    }

    /// The frames the source has now, published.
    fn take_frames(&mut self, now_ns: i64, slot_ns: i64, out: &mut Out) {
        let ctx = source::Context {
            cfg: &self.cfg,
            camera: &self.camera,
            pose: self.pose_at(now_ns),
            laser_on: self.laser_on,
            frames: self.frames,
        };
        for f in self.source.frames(now_ns, slot_ns, &ctx) {
            self.publish_frame(f, out);
        }
    }

    /// `table -> carm` at `t`, extrapolated linearly from the two newest samples.
    fn pose_at(&self, t: i64) -> Option<Iso3> {
        match self.poses {
            [Some((t1, p1)), Some((t0, p0))] if t1 > t0 => {
                let f = (t - t0) as f64 / (t1 - t0) as f64;
                Some(Iso3 { rotation: p1.rotation, translation: p0.translation.lerp(p1.translation, f) })
            }
            [Some((_, p1)), _] => Some(p1),
            _ => None,
        }
    }
}

impl Component for CameraDriverNode {
    type Input = Input;
    type Output = Output;
    fn node_name(&self) -> &'static str {
        "camera_driver"
    }
    fn set_identity(&mut self, _name: &str, namespace: &str) {
        if self.cfg.camera.is_empty() {
            self.camera = namespace.trim_matches('/').rsplit('/').next().unwrap_or("").to_string();
        }
    }
    fn inputs(&self) -> Vec<(Input, Port)> {
        vec![
            (Input::Tf, Port::new("/tf", TFMessage::TYPE_NAME, QosClass::Reliable)),
            (Input::Events, Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn outputs(&self) -> Vec<(Output, Port)> {
        let image = match self.cfg.compressed {
            None => Port::new("image_raw", Image::TYPE_NAME, QosClass::Sensor),
            Some(_) => Port::new("image_raw/compressed", CompressedImage::TYPE_NAME, QosClass::Sensor),
        };
        vec![
            (Output::Image, image),
            (Output::CameraInfo, Port::new("camera_info", CameraInfo::TYPE_NAME, QosClass::Sensor)),
            (Output::Report, Port::new("/scan/report", StringMsg::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn reconfigure(&mut self, p: &Params) -> Result<(), ParamError> {
        self.cfg = config(p)?;
        if !self.source.reconfigured(&self.cfg.source) {
            self.source = source::build(&self.cfg.source);
        }
        Ok(())
    }
    fn handle(&mut self, input: Input, msg: &Msg, out: &mut Out) -> Result<(), NodeError> {
        match (input, msg) {
            (Input::Tf, Msg::Tf(tf)) => {
                for t in &tf.transforms {
                    if t.header.frame_id.trim_start_matches('/') == self.cfg.table_frame
                        && t.child_frame_id.trim_start_matches('/') == self.cfg.carm_frame
                    {
                        // A pose that is not rigid is refused: the camera renders from the last good.
                        let pose = convert::rigid(t).map_err(NodeError::malformed)?;
                        let s = t.header.stamp.nanos();
                        if self.poses[0].is_none_or(|(t0, _)| s > t0) {
                            self.poses[1] = self.poses[0];
                            self.poses[0] = Some((s, pose));
                        }
                    }
                }
                Ok(())
            }
            (Input::Events, Msg::ScanEvent(e)) => {
                self.laser_on = match e.event {
                    ScanEvent::START => true,
                    ScanEvent::END | ScanEvent::ABORT => false,
                    // An event no scan has does not turn the laser off in the middle of one.
                    other => return Err(NodeError::malformed(format!("unknown scan event {other}"))),
                };
                if let Some(report) = self.tally.event(e, crate::tally::Stage::CameraDriver, &self.camera) {
                    out.publish(Output::Report, report);
                }
                Ok(())
            }
            (i, m) => Err(NodeError::unexpected(i, m)),
        }
    }
    /// The next frame's time, so that a frame leaves on time rather than at the host's next tick
    /// (a V4L2 camera keeps its own time: it is polled at the tick period).
    fn next_tick_ns(&self) -> Option<i64> {
        if !self.source.paced() {
            return None;
        }
        self.next_ns
    }
    fn tick(&mut self, now_ns: i64, out: &mut Out) {
        if let Some(report) = self.tally.due(now_ns) {
            out.publish(Output::Report, report);
        }
        if !self.source.paced() {
            self.take_frames(now_ns, now_ns, out);
            return;
        }
        let next = *self.next_ns.get_or_insert(now_ns);
        if now_ns < next {
            return;
        }
        // Stay on the frame grid; frames the host could not render in time are counted.
        let behind = (now_ns - next) / self.cfg.period_ns;
        self.skipped += behind as u64;
        self.tally.skip(next, behind as u64);
        // The slot this frame fills: a late host skips slots (the counter) rather than letting
        // the stamps fall behind the clock the C-arm's pose is on.
        let slot = next + behind * self.cfg.period_ns;
        self.next_ns = Some(slot + self.cfg.period_ns);
        self.take_frames(now_ns, slot, out);
    }
    fn finish(&mut self, out: &mut Out) {
        if let Some(report) = self.tally.report() {
            out.publish(Output::Report, report);
        }
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("frames", self.frames),
            ("frames_not_rendered_in_time", self.skipped),
            ("read_errors", self.source.read_errors()),
            ("device_errors", self.source.device_errors()),
            ("encode_errors", self.encode_errors),
        ]
    }
}

#[cfg(test)]
mod tests {
    // A scenario reads top to bottom: its steps stay in one test function.
    #![allow(clippy::too_many_lines)]
    use super::*;
    use xsurf_core::synth::{LaserModel, ScanSettings, Scanner};
    use crate::registry::{build, declarations};
    use std::cell::RefCell;
    use std::rc::Rc;
    use xsurf_runtime::params::ParamValue as V;
    use xsurf_runtime::router::Router;

    #[test]
    fn v4l2_source_is_refused_without_the_feature_and_survives_a_missing_camera_with_it() {
        let mut o = std::collections::BTreeMap::new();
        o.insert("source".to_string(), V::String("v4l2".into()));
        o.insert("device".to_string(), V::String("/dev/video-xsurf-none".into()));
        let p = Params::resolve(&declarations("camera_driver").unwrap(), &o).unwrap();
        match (cfg!(feature = "v4l2"), CameraDriverNode::new(&p)) {
            (false, Err(e)) => {
                assert!(e.to_string().contains("source") && e.to_string().contains("--features v4l2"), "{e}");
            }
            (true, Ok(mut node)) => {
                let mut out = Out::default();
                for k in 0..3 {
                    node.tick(k * 600_000_000, &mut out);
                }
                assert!(out.items.is_empty());
                let errors = node.counters().into_iter().find(|c| c.0 == "device_errors").unwrap().1;
                assert_eq!(errors, 2, "opened at 0 and again a second later, not at every tick");
            }
            (built, r) => panic!("feature v4l2 built: {built}, node: {:?}", r.err()),
        }
        o.insert("stamp_offset_s".to_string(), V::Double(-0.1));
        let p = Params::resolve(&declarations("camera_driver").unwrap(), &o).unwrap();
        let e = CameraDriverNode::new(&p).err().unwrap().to_string();
        assert!(e.contains(if cfg!(feature = "v4l2") { "stamp_offset_s" } else { "source" }), "{e}");
    }

    #[test]
    fn files_source_publishes_the_sequence_with_its_calibration_stamps_and_rotation() {
        let dir = std::env::temp_dir().join(format!("xsurf-files-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        // Three frames of the synthetic scanner as the study stored them (8-bit BMP), a
        // calibration file and a sidecar of stamps.
        let rig = Rig::study(160, 120);
        let scanner = Scanner::new(
            Scene::by_name("pyramid").unwrap(),
            rig.clone(),
            LaserModel::default(),
            ScanSettings::default(),
        )
        .unwrap();
        let frames: Vec<_> = (0..3).map(|f| scanner.render(0, 20 + f)).collect();
        for (i, f) in frames.iter().enumerate() {
            xsurf_formats::frames::write_bmp_mono8(&dir.join(format!("frame_{i:03}.bmp")), f).unwrap();
        }
        let model = rig.cameras[0].model().unwrap();
        let calib = dir.join("cam1.yaml");
        xsurf_formats::calibration::write(
            &calib,
            &xsurf_formats::calibration::CameraCalibration::from_model("cam1", &model),
        )
        .unwrap();
        std::fs::write(dir.join("stamps.txt"), "# exposure times\n12.5\n12.533333\n12566666667\n").unwrap();
        let run = |extra: &[(&str, V)]| {
            let mut o: std::collections::BTreeMap<String, V> = [
                ("source", V::String("files".into())),
                ("files", V::String(dir.join("frame_%03d.bmp").to_string_lossy().into())),
                ("camera_info_url", V::String(format!("file://{}", calib.display()))),
                ("fps", V::Double(100.0)),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect();
            for (k, v) in extra {
                o.insert(k.to_string(), v.clone());
            }
            let p = Params::resolve(&declarations("camera_driver").unwrap(), &o).unwrap();
            let mut router = Router::new();
            router.add(build("camera_driver", &p).unwrap(), "camera_driver", "/cam1", &[]);
            let seen: Rc<RefCell<Vec<(String, Msg)>>> = Rc::default();
            let s = seen.clone();
            router.set_tap(Box::new(move |t, m| s.borrow_mut().push((t.to_string(), m.clone()))));
            for k in 0..10 {
                router.tick(1_000_000_000 + k * 10_000_000);
            }
            let v = seen.borrow().clone();
            v
        };
        let seen = run(&[("timestamps_file", V::String(dir.join("stamps.txt").to_string_lossy().into()))]);
        let images: Vec<&Image> = seen
            .iter()
            .filter_map(|(t, m)| match m {
                Msg::Image(i) if t == "/cam1/image_raw" => Some(i.as_ref()),
                _ => None,
            })
            .collect();
        assert_eq!(images.len(), 3, "three frames, then it stops");
        let stamps: Vec<i64> = images.iter().map(|i| i.header.stamp.nanos()).collect();
        assert_eq!(stamps, [12_500_000_000, 12_533_333_000, 12_566_666_667]);
        for (img, f) in images.iter().zip(&frames) {
            assert_eq!(img.data, f.data);
            assert_eq!(img.header.frame_id, "cam1_optical_frame");
        }
        let info = seen.iter().find_map(|(t, m)| match m {
            Msg::CameraInfo(c) if t == "/cam1/camera_info" => Some(c.clone()),
            _ => None,
        });
        assert_eq!(convert::camera_model(&info.unwrap()).unwrap(), model);
        // Stamps from the rate, and the images turned.
        let seen = run(&[("rotate_180", V::Bool(true)), ("loop_files", V::Bool(true))]);
        let images: Vec<&Image> = seen
            .iter()
            .filter_map(|(_, m)| match m {
                Msg::Image(i) => Some(i.as_ref()),
                _ => None,
            })
            .collect();
        assert_eq!(images.len(), 10, "looping");
        assert_eq!(images[1].header.stamp.nanos() - images[0].header.stamp.nanos(), 10_000_000);
        let mut turned = frames[0].data.clone();
        turned.reverse();
        assert_eq!(images[0].data, turned);
        assert_eq!(images[3].data, turned, "the loop starts again");
        // A late host: the frames keep their slots on the grid; the slots it missed are counted.
        let p = Params::resolve(
            &declarations("camera_driver").unwrap(),
            &[
                ("source".to_string(), V::String("files".into())),
                ("files".to_string(), V::String(dir.join("frame_%03d.bmp").to_string_lossy().into())),
                ("camera_info_url".to_string(), V::String(format!("file://{}", calib.display()))),
                ("fps".to_string(), V::Double(100.0)),
                ("loop_files".to_string(), V::Bool(true)),
            ]
            .into_iter()
            .collect(),
        )
        .unwrap();
        let mut node = CameraDriverNode::new(&p).unwrap();
        let mut out = Out::default();
        let t0 = 5_000_000_000i64;
        for late_ms in [0, 10, 45, 50] {
            node.tick(t0 + late_ms * 1_000_000, &mut out);
        }
        let stamps: Vec<i64> = out
            .items
            .iter()
            .filter_map(|(_, m)| match m {
                Msg::Image(i) => Some(i.header.stamp.nanos() - t0),
                _ => None,
            })
            .collect();
        assert_eq!(stamps, [0, 10_000_000, 40_000_000, 50_000_000]);
        assert_eq!(node.counters()[1], ("frames_not_rendered_in_time", 2));
        // Bad configuration is refused, naming the parameter.
        let bad = |k: &str, v: V| {
            let mut o = std::collections::BTreeMap::new();
            o.insert("source".to_string(), V::String("files".into()));
            o.insert("files".to_string(), V::String(dir.to_string_lossy().into()));
            o.insert(k.to_string(), v);
            let p = Params::resolve(&declarations("camera_driver").unwrap(), &o).unwrap();
            CameraDriverNode::new(&p).err().map(|e| e.to_string()).unwrap_or_default()
        };
        assert!(bad("files", V::String("/no/such/dir".into())).contains("files"));
        assert!(bad("camera_info_url", V::String("package://x/y.yaml".into())).contains("camera_info_url"));
        assert!(bad("timestamps_file", V::String(dir.join("cam1.yaml").to_string_lossy().into()))
            .contains("timestamps_file"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The compressed transport end to end in a composed graph: camera_driver publishes
    /// `image_raw/compressed`, edge_detector (image_transport compressed) decodes it; PNG gives
    /// the raw transport's lines exactly, JPEG nearly every sample within a tenth of a pixel.
    #[test]
    fn compressed_transport_reaches_the_edge_detector() {
        let dir = std::env::temp_dir().join(format!("xsurf-compressed-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let scanner = Scanner::new(
            Scene::by_name("pyramid").unwrap(),
            Rig::study(320, 240),
            LaserModel::default(),
            ScanSettings::default(),
        )
        .unwrap();
        let n = scanner.frame_count();
        for (i, f) in [n / 3, n / 2, 2 * n / 3].into_iter().enumerate() {
            xsurf_formats::frames::write_pgm(&dir.join(format!("frame_{i}.pgm")), &scanner.render(0, f)).unwrap();
        }
        let lines = |transport: &[(&str, V)]| {
            let mut o: std::collections::BTreeMap<String, V> = [
                ("source", V::String("files".into())),
                ("files", V::String(dir.join("frame_%d.pgm").to_string_lossy().into())),
                ("fps", V::Double(100.0)),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect();
            let mut e = std::collections::BTreeMap::new();
            for (k, v) in transport {
                o.insert(k.to_string(), v.clone());
                if *k == "image_transport" {
                    e.insert(k.to_string(), v.clone());
                }
            }
            let p = Params::resolve(&declarations("camera_driver").unwrap(), &o).unwrap();
            let pe = Params::resolve(&declarations("edge_detector").unwrap(), &e).unwrap();
            let mut router = Router::new();
            router.add(build("camera_driver", &p).unwrap(), "camera_driver", "/cam1", &[]);
            router.add(build("edge_detector", &pe).unwrap(), "edge_detector", "/cam1", &[]);
            let seen: Rc<RefCell<Vec<(String, Msg)>>> = Rc::default();
            let s = seen.clone();
            router.set_tap(Box::new(move |t, m| s.borrow_mut().push((t.to_string(), m.clone()))));
            for k in 0..6 {
                router.tick(1_000_000_000 + k * 10_000_000);
            }
            let v: Vec<(String, Msg)> = seen.borrow().clone();
            let topics: Vec<String> = v.iter().map(|(t, _)| t.clone()).collect();
            let lines: Vec<Vec<f32>> = v
                .into_iter()
                .filter_map(|(_, m)| match m {
                    Msg::LaserLine(l) => Some(l.v.clone()),
                    _ => None,
                })
                .collect();
            (topics, lines)
        };
        let found = |l: &[Vec<f32>]| l.iter().flatten().filter(|v| v.is_finite()).count();
        let (raw_topics, raw) = lines(&[]);
        assert!(raw_topics.iter().any(|t| t == "/cam1/image_raw"));
        assert_eq!(raw.len(), 3);
        assert!(found(&raw) > 300, "{} samples", found(&raw));
        let png = [("image_transport", V::String("compressed".into())), ("compressed_format", V::String("png".into()))];
        let (topics, lossless) = lines(&png);
        assert!(topics.iter().any(|t| t == "/cam1/image_raw/compressed"));
        assert!(!topics.iter().any(|t| t == "/cam1/image_raw"));
        let same = raw.iter().flatten().zip(lossless.iter().flatten()).all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same && lossless.len() == 3, "PNG: the raw transport's lines exactly");
        let jpeg = [("image_transport", V::String("compressed".into())), ("jpeg_quality", V::Integer(90))];
        let (_, lossy) = lines(&jpeg);
        assert_eq!(lossy.len(), 3);
        let (mut both, mut close) = (0, 0);
        for (x, y) in raw.iter().flatten().zip(lossy.iter().flatten()) {
            if x.is_finite() && y.is_finite() {
                both += 1;
                close += usize::from((x - y).abs() < 0.1);
            }
        }
        assert!(both * 100 >= found(&raw) * 98 && close * 100 >= both * 95, "{close} of {both} samples within 0.1 px");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
