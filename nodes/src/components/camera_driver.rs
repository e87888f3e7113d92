//! `camera_driver`: publishes `image_raw` and `camera_info` (same stamp, frame
//! `<camera>_optical_frame`). Source `synthetic`: the synthetic scanner renders what the camera
//! sees with the C-arm where `/tf` says it is at the exposure, the laser on between a scan's
//! START and END; CI and demos use it in place of a camera.

use super::decl;
use crate::convert;
use std::sync::Arc;
use xsurf_core::geom::Iso3;
use xsurf_core::image::Encoding;
use xsurf_core::rig::Rig;
use xsurf_core::synth::{LaserModel, ScanSettings, Scanner, Scene, SCENE_NAMES};
use xsurf_msgs::sensor_msgs::{CameraInfo, Image};
use xsurf_msgs::tf2_msgs::TFMessage;
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_msgs::RosMessage;
use xsurf_runtime::component::{Component, Msg, NodeError, Outbox, Port, QosClass};
use xsurf_runtime::params::{ParamDecl, ParamError, ParamValue as V, Params};

/// The parameters of `camera_driver`.
pub fn declarations() -> Vec<ParamDecl> {
    vec![
        decl("source", V::String("synthetic".into()), "", "image source: synthetic (files and v4l2 are not built yet)"),
        decl(
            "scene",
            V::String("pyramid".into()),
            "",
            "synthetic source: pyramid, phantom, sphere, cylinder, box or body",
        ),
        decl("camera", V::String(String::new()), "", "camera name in the rig (default: the node's namespace)"),
        decl(
            "rig_file",
            V::String(String::new()),
            "",
            "rig YAML (see launch-config/rig_study.yaml); empty: the study's rig",
        ),
        decl("width", V::Integer(640), "px", "image width (the study rig's intrinsics are scaled to it)"),
        decl("height", V::Integer(480), "px", "image height"),
        decl("fps", V::Double(30.0), "Hz", "frame rate"),
        decl("encoding", V::String("mono8".into()), "", "mono8, rgb8 or bgr8"),
        decl("seed", V::Integer(1), "", "synthetic sensor noise seed"),
        decl("table_frame", V::String("table".into()), "", "fixed frame of /tf"),
        decl("carm_frame", V::String("carm".into()), "", "C-arm frame of /tf"),
    ]
}

struct Config {
    scene: Scene,
    camera: String,
    rig: Option<Rig>,
    width: u32,
    height: u32,
    period_ns: i64,
    encoding: Encoding,
    seed: u64,
    table_frame: String,
    carm_frame: String,
}

fn config(p: &Params) -> Result<Config, ParamError> {
    let source = p.string("source")?;
    if source != "synthetic" {
        return Err(Params::invalid("source", format!("{source:?}: only the synthetic source is built so far")));
    }
    let scene_name = p.string("scene")?;
    let scene = Scene::by_name(&scene_name).ok_or_else(|| {
        Params::invalid("scene", format!("unknown scene {scene_name:?} (known: {})", SCENE_NAMES.join(", ")))
    })?;
    let dim = |n: &str| -> Result<u32, ParamError> {
        let v = p.i64(n)?;
        u32::try_from(v)
            .ok()
            .filter(|v| (16..=8192).contains(v))
            .ok_or_else(|| Params::invalid(n, format!("{v} is not in 16..=8192")))
    };
    let fps = p.f64("fps")?;
    if !(fps > 0.0 && fps <= 1000.0) {
        return Err(Params::invalid("fps", format!("{fps} is not in (0, 1000]")));
    }
    let enc = p.string("encoding")?;
    let encoding = match enc.as_str() {
        "mono8" => Encoding::Mono8,
        "rgb8" => Encoding::Rgb8,
        "bgr8" => Encoding::Bgr8,
        other => return Err(Params::invalid("encoding", format!("{other:?} is not mono8, rgb8 or bgr8"))),
    };
    let rig_file = p.string("rig_file")?;
    let rig = if rig_file.is_empty() {
        None
    } else {
        let text =
            std::fs::read_to_string(&rig_file).map_err(|e| Params::invalid("rig_file", format!("{rig_file}: {e}")))?;
        Some(serde_yaml::from_str::<Rig>(&text).map_err(|e| Params::invalid("rig_file", format!("{rig_file}: {e}")))?)
    };
    Ok(Config {
        scene,
        camera: p.string("camera")?,
        rig,
        width: dim("width")?,
        height: dim("height")?,
        period_ns: (1e9 / fps) as i64,
        encoding,
        seed: p.i64("seed")? as u64,
        table_frame: p.string("table_frame")?,
        carm_frame: p.string("carm_frame")?,
    })
}

/// The camera driver component.
pub struct CameraDriverNode {
    cfg: Config,
    camera: String,
    scanner: Option<(Scanner, usize)>,
    /// The two newest `table -> carm` samples, for extrapolating to the exposure.
    poses: [Option<(i64, Iso3)>; 2],
    laser_on: bool,
    next_ns: Option<i64>,
    frames: u64,
    skipped: u64,
}

impl CameraDriverNode {
    /// Builds the node from its parameters.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        let cfg = config(p)?;
        Ok(Self {
            camera: cfg.camera.clone(),
            cfg,
            scanner: None,
            poses: [None, None],
            laser_on: false,
            next_ns: None,
            frames: 0,
            skipped: 0,
        })
    }

    fn scanner(&mut self) -> Result<&(Scanner, usize), NodeError> {
        if self.scanner.is_none() {
            let rig = self.cfg.rig.clone().unwrap_or_else(|| Rig::study(self.cfg.width, self.cfg.height));
            let settings = ScanSettings { encoding: self.cfg.encoding, seed: self.cfg.seed, ..ScanSettings::default() };
            let s =
                Scanner::new(self.cfg.scene.clone(), rig, LaserModel::default(), settings).map_err(NodeError::new)?;
            let i = s
                .camera_index(&self.camera)
                .ok_or_else(|| NodeError::new(format!("camera {:?} is not in the rig", self.camera)))?;
            self.scanner = Some((s, i));
        }
        self.scanner.as_ref().ok_or_else(|| NodeError::new("no scanner"))
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
    fn node_name(&self) -> &'static str {
        "camera_driver"
    }
    fn set_identity(&mut self, _name: &str, namespace: &str) {
        if self.cfg.camera.is_empty() {
            self.camera = namespace.trim_matches('/').rsplit('/').next().unwrap_or("").to_string();
        }
    }
    fn inputs(&self) -> Vec<Port> {
        vec![
            Port::new("/tf", TFMessage::TYPE_NAME, QosClass::Reliable),
            Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable),
        ]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![
            Port::new("image_raw", Image::TYPE_NAME, QosClass::Sensor),
            Port::new("camera_info", CameraInfo::TYPE_NAME, QosClass::Sensor),
        ]
    }
    fn declarations(&self) -> Vec<ParamDecl> {
        declarations()
    }
    fn reconfigure(&mut self, p: &Params) -> Result<(), ParamError> {
        self.cfg = config(p)?;
        self.scanner = None;
        Ok(())
    }
    fn handle(&mut self, input: usize, msg: &Msg, _out: &mut Outbox) -> Result<(), NodeError> {
        match (input, msg) {
            (0, Msg::Tf(tf)) => {
                for t in &tf.transforms {
                    if t.header.frame_id.trim_start_matches('/') == self.cfg.table_frame
                        && t.child_frame_id.trim_start_matches('/') == self.cfg.carm_frame
                    {
                        let s = t.header.stamp.nanos();
                        if self.poses[0].is_none_or(|(t0, _)| s > t0) {
                            self.poses[1] = self.poses[0];
                            self.poses[0] = Some((s, convert::iso(&t.transform)));
                        }
                    }
                }
                Ok(())
            }
            (1, Msg::ScanEvent(e)) => {
                self.laser_on = e.event == ScanEvent::START;
                Ok(())
            }
            (i, m) => Err(NodeError::new(format!("unexpected {} on input {i}", m.type_name()))),
        }
    }
    fn tick(&mut self, now_ns: i64, out: &mut Outbox) {
        let next = *self.next_ns.get_or_insert(now_ns);
        if now_ns < next {
            return;
        }
        // Stay on the frame grid; frames the host could not render in time are counted.
        let behind = (now_ns - next) / self.cfg.period_ns;
        self.skipped += behind as u64;
        self.next_ns = Some(next + (behind + 1) * self.cfg.period_ns);
        let Some(pose) = self.pose_at(now_ns) else { return };
        let laser = self.laser_on;
        let frame = self.frames;
        let (img, model) = match self.scanner() {
            Ok((s, i)) => match s.rig.cameras[*i].model() {
                Ok(m) => (s.render_at(*i, &pose, laser, frame), m),
                Err(e) => {
                    log::error!("camera_driver: {e}");
                    return;
                }
            },
            Err(e) => {
                log::error!("camera_driver: {e}");
                return;
            }
        };
        let header = convert::header(now_ns, &format!("{}_optical_frame", self.camera));
        out.publish(1, Msg::CameraInfo(Arc::new(convert::camera_info(&model, header.clone()))));
        out.publish(0, Msg::Image(Arc::new(Image::from_image(header, img))));
        self.frames += 1;
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![("frames", self.frames), ("frames_not_rendered_in_time", self.skipped)]
    }
}
