//! `edge_detector`: `image_raw` -> `laser_line`, one sample per image row (or column).

mod params;
pub use params::*;

/// The node type, as the registry lists it.
pub const NODE: crate::registry::NodeType =
    crate::registry::NodeType::of::<EdgeParams>("edge_detector", crate::registry::Role::PerCamera, 50, |p| Ok(boxed(EdgeDetectorNode::new(p)?)));

use crate::convert;
use std::sync::Arc;
use xsurf_core::edge::{Channel, LaserDetectors, LaserLine};
use xsurf_core::limits;
use xsurf_msgs::sensor_msgs::CameraInfo;
use xsurf_msgs::std_msgs::StringMsg;
use xsurf_msgs::xsurf_msgs::LaserLine as LineMsg;
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_msgs::RosMessage;
use xsurf_runtime::component::{boxed, Component, Msg, NodeError, Outbox, Port, QosClass};
use xsurf_runtime::params::{NodeParams, ParamError, Params};

/// The edge detector component.
pub struct EdgeDetectorNode {
    transport: Transport,
    /// One detector per laser (one without `lasers`).
    detector: LaserDetectors,
    /// The lasers' names, as each line message carries them (empty without `lasers`).
    lasers: Vec<String>,
    lines: Vec<LaserLine>,
    frames: u64,
    samples_found: u64,
    frames_with_line: u64,
    bad_images: u64,
    /// The image size camera_info gives, once one has arrived.
    camera_size: Option<(u32, u32)>,
    /// The camera (the node's namespace), for the scan reports.
    camera: String,
    /// The images of the current scan refused, for its report.
    tally: crate::tally::ScanTally,
}

/// The edge detector's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// `image_raw` (or `image_raw/compressed`, by `image_transport`).
    Image,
    /// `camera_info`: the image size every image must have.
    CameraInfo,
    /// `/scan/events`: the scans, for the reports.
    Events,
}

/// The edge detector's outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// `laser_line`: one per image.
    Line,
    /// `/scan/report`: this camera's account of each scan.
    Report,
}

type Out = Outbox<Input, Output>;

impl EdgeDetectorNode {
    /// Frames in which a line was found, so far.
    pub fn frames_with_line(&self) -> u64 {
        self.frames_with_line
    }
    /// Builds the node from its parameters.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        let (typed, detector, lasers) = Self::detectors(p)?;
        Ok(Self {
            transport: typed.image_transport,
            detector,
            lasers,
            lines: Vec::new(),
            frames: 0,
            samples_found: 0,
            frames_with_line: 0,
            bad_images: 0,
            camera_size: None,
            camera: String::new(),
            tally: Default::default(),
        })
    }

    /// The parameters, a detector per laser (each in its own colour against the others) and
    /// the lasers' names.
    fn detectors(p: &Params) -> Result<(EdgeParams, LaserDetectors, Vec<String>), ParamError> {
        let typed = EdgeParams::from_params(p)?;
        let config = typed.config()?;
        let lasers = crate::lasers::from_params(p, &typed.lasers, [0.0; 3])?;
        let configs = match &lasers {
            None => vec![config],
            Some(l) => {
                l.iter().map(|l| xsurf_core::edge::EdgeConfig { channel: Channel::against_others(l.channel), ..config.clone() }).collect()
            }
        };
        let detector = LaserDetectors::new(configs)
            .map_err(|e| Params::invalid("edge_detector", e.to_string()))?
            .with_second_surfaces(typed.second_surfaces);
        let names = lasers.map(|l| l.into_iter().map(|l| l.name).collect()).unwrap_or_default();
        Ok((typed, detector, names))
    }

    /// Finds the line in one image.
    fn image(&mut self, msg: &Msg, out: &mut Out) -> Result<(), NodeError> {
        let at = |h: &xsurf_msgs::std_msgs::Header| format!("{}.{:09}", h.stamp.sec, h.stamp.nanosec);
        // A compressed image is decoded once, here where it enters the pipeline.
        let decoded;
        let (view, header) = match msg {
            Msg::Image(img) => {
                let view = convert::image_view(img).map_err(|e| {
                    self.bad_images += 1;
                    NodeError::malformed(format!("image at {}: {e}", at(&img.header)))
                })?;
                (view, &img.header)
            }
            Msg::CompressedImage(c) => {
                decoded = xsurf_formats::compressed::decode(&c.format, &c.data).map_err(|e| {
                    self.bad_images += 1;
                    NodeError::malformed(format!("compressed image at {}: {e}", at(&c.header)))
                })?;
                (decoded.view().map_err(NodeError::malformed)?, &c.header)
            }
            other => {
                return Err(NodeError::unexpected(Input::Image, other))
            }
        };
        // An image that contradicts its camera is refused where it enters.
        if let Some((w, h)) = self.camera_size.filter(|&s| s != (view.width(), view.height())) {
            self.bad_images += 1;
            return Err(NodeError::contradicts(format!(
                "image at {} is {}x{}, camera_info says {w}x{h}",
                at(header),
                view.width(),
                view.height()
            )));
        }
        let stats = self.detector.detect(&view, &mut self.lines).map_err(|e| match e {
            xsurf_core::edge::EdgeError::GreyWithLasers { .. } => {
                self.bad_images += 1;
                NodeError::contradicts(format!("image at {}: {e}; parameter lasers names {:?}", at(header), self.lasers))
            }
            e => NodeError::malformed(e),
        })?;
        let found: u32 = stats.iter().map(|s| s.found + s.second).sum();
        self.frames += 1;
        self.samples_found += u64::from(found);
        self.frames_with_line += u64::from(found > 0);
        let line = convert::lines_msg(&self.lines, &self.lasers, header.clone());
        out.publish(Output::Line, Msg::LaserLine(Arc::new(line)));
        Ok(())
    }
}

impl Component for EdgeDetectorNode {
    type Input = Input;
    type Output = Output;
    fn node_name(&self) -> &'static str {
        "edge_detector"
    }
    fn set_identity(&mut self, _name: &str, namespace: &str) {
        self.camera = namespace.trim_matches('/').rsplit('/').next().unwrap_or("").to_string();
    }
    fn inputs(&self) -> Vec<(Input, Port)> {
        let image = match self.transport {
            Transport::Raw => Port::new("image_raw", xsurf_msgs::sensor_msgs::Image::TYPE_NAME, QosClass::Sensor),
            Transport::Compressed => {
                Port::new("image_raw/compressed", xsurf_msgs::sensor_msgs::CompressedImage::TYPE_NAME, QosClass::Sensor)
            }
        };
        vec![
            (Input::Image, image),
            (Input::CameraInfo, Port::new("camera_info", CameraInfo::TYPE_NAME, QosClass::Sensor)),
            (Input::Events, Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn outputs(&self) -> Vec<(Output, Port)> {
        vec![
            (Output::Line, Port::new("laser_line", LineMsg::TYPE_NAME, QosClass::Reliable)),
            (Output::Report, Port::new("/scan/report", StringMsg::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn reconfigure(&mut self, p: &Params) -> Result<(), ParamError> {
        let (typed, detector, lasers) = Self::detectors(p)?;
        if typed.image_transport != self.transport {
            return Err(Params::invalid("image_transport", "fixed at start (it chooses the subscription)"));
        }
        self.detector = detector;
        self.lasers = lasers;
        Ok(())
    }
    fn handle(&mut self, input: Input, msg: &Msg, out: &mut Out) -> Result<(), NodeError> {
        match (input, msg) {
            (Input::CameraInfo, Msg::CameraInfo(i)) => {
                if !limits::image_side_ok(i.width) || !limits::image_side_ok(i.height) {
                    return Err(NodeError::malformed(format!(
                        "camera_info size {}x{} is outside {} pixels a side",
                        i.width,
                        i.height,
                        limits::image_side_text()
                    )));
                }
                self.camera_size = Some((i.width, i.height));
                Ok(())
            }
            (Input::Events, Msg::ScanEvent(e)) => {
                if let Some(report) = self.tally.event(e, crate::tally::Stage::EdgeDetector, &self.camera) {
                    out.publish(Output::Report, report);
                }
                Ok(())
            }
            (Input::Image, _) => {
                let r = self.image(msg, out);
                if let Some(stamp) = msg.stamp_ns() {
                    match &r {
                        Ok(()) => self.tally.count(stamp),
                        Err(e) => self.tally.refuse(stamp, "image", &e.to_string()),
                    }
                }
                r
            }
            (i, m) => Err(NodeError::unexpected(i, m)),
        }
    }
    fn tick(&mut self, now_ns: i64, out: &mut Out) {
        if let Some(report) = self.tally.due(now_ns) {
            out.publish(Output::Report, report);
        }
    }
    fn finish(&mut self, out: &mut Out) {
        if let Some(report) = self.tally.report() {
            out.publish(Output::Report, report);
        }
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("frames", self.frames),
            ("frames_with_line", self.frames_with_line),
            ("samples_found", self.samples_found),
            ("bad_images", self.bad_images),
        ]
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use xsurf_msgs::sensor_msgs::Image;

    /// A mono8 frame with a bright vertical line at column `col`.
    fn frame(width: u32, height: u32, col: u32, sec: i32) -> Msg {
        let mut data = vec![10u8; (width * height) as usize];
        for r in 0..height {
            for (dc, v) in [(-1i32, 120u8), (0, 220), (1, 120)] {
                data[(r * width) as usize + (col as i32 + dc) as usize] = v;
            }
        }
        let mut img = Image { width, height, encoding: "mono8".into(), step: width, data, ..Default::default() };
        img.header.stamp.sec = sec;
        Msg::Image(Arc::new(img))
    }

    /// An image whose size contradicts camera_info is refused where it enters and counted;
    /// the camera's own images go on (issue 24: one bad message costs only itself).
    #[test]
    fn images_that_contradict_camera_info_are_refused() {
        let params = Params::resolve(&EdgeParams::declarations(), &Default::default()).unwrap();
        let mut n = EdgeDetectorNode::new(&params).unwrap();
        let mut out = Out::default();
        // Before any camera_info, an image is taken as it is.
        n.handle(Input::Image, &frame(80, 60, 40, 1), &mut out).unwrap();
        let info = CameraInfo { width: 64, height: 40, ..Default::default() };
        n.handle(Input::CameraInfo, &Msg::CameraInfo(Arc::new(info)), &mut out).unwrap();
        let e = n.handle(Input::Image, &frame(16, 12, 5, 2), &mut out).unwrap_err();
        assert!(e.to_string().contains("image at 2.000000000 is 16x12, camera_info says 64x40"), "{e}");
        for sec in 3..6 {
            n.handle(Input::Image, &frame(64, 40, 30, sec), &mut out).unwrap();
        }
        assert_eq!((n.frames, n.bad_images, n.frames_with_line), (4, 1, 4));
        assert_eq!(out.items.len(), 4, "one laser_line per image taken");
        let Msg::LaserLine(l) = &out.items[3].1 else { panic!("expected a line") };
        assert_eq!((l.image_width, l.image_height), (64, 40));
        assert!((l.u[20] - 30.0).abs() < 0.05, "{}", l.u[20]);
        // A camera_info that no camera has is refused by name and changes nothing.
        let bad = CameraInfo { width: 0, height: 40, ..Default::default() };
        let e = n.handle(Input::CameraInfo, &Msg::CameraInfo(Arc::new(bad)), &mut out).unwrap_err();
        assert!(e.to_string().contains("camera_info size 0x40"), "{e}");
        n.handle(Input::Image, &frame(64, 40, 30, 7), &mut out).unwrap();
    }
}
