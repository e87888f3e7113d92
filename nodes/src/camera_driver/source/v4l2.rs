//! A Video4Linux2 camera (`--features v4l2`): opened when due (again after a failure, every
//! second), then every frame that arrived since the last tick, stamped at its dequeue time
//! minus the camera's delay.

use super::{model_for, rotate_180, Context, Frame, FrameSource};
use crate::camera_driver::SourceSpec;
use crate::v4l2::{Capture, Captured};
use std::path::PathBuf;
use xsurf_core::camera::CameraModel;

/// The V4L2 source.
pub(in crate::camera_driver) struct V4l2 {
    device: PathBuf,
    offset_ns: i64,
    /// The open camera.
    capture: Option<Capture>,
    /// When the next attempt to open it is due.
    reopen_at: i64,
    device_errors: u64,
    read_errors: u64,
    /// Without `camera_info_url`: the rig's intrinsics at the frames' size.
    rig_model: Option<CameraModel>,
}

impl V4l2 {
    /// The camera at `device`, whose frames are stamped `offset_ns` before they are dequeued.
    pub(in crate::camera_driver) fn new(device: PathBuf, offset_ns: i64) -> V4l2 {
        V4l2 { device, offset_ns, capture: None, reopen_at: i64::MIN, device_errors: 0, read_errors: 0, rig_model: None }
    }

    /// Opens the camera when due; false if it is not open.
    fn open(&mut self, now_ns: i64, ctx: &Context) -> bool {
        if self.capture.is_some() {
            return true;
        }
        if now_ns < self.reopen_at {
            return false;
        }
        let cfg = ctx.cfg;
        match Capture::open(&self.device, cfg.width, cfg.height, 1e9 / cfg.period_ns as f64, cfg.encoding) {
            Ok(c) => {
                log::info!("camera_driver: {} streaming {}", self.device.display(), String::from_utf8_lossy(&c.fourcc));
                self.capture = Some(c);
                true
            }
            Err(e) => {
                self.device_errors += 1;
                self.reopen_at = now_ns + 1_000_000_000;
                if self.device_errors <= 3 || self.device_errors.is_power_of_two() {
                    log::error!("camera_driver: {e} (attempt {}; retrying every second)", self.device_errors);
                }
                false
            }
        }
    }
}

impl FrameSource for V4l2 {
    fn paced(&self) -> bool {
        false
    }
    fn frames(&mut self, now_ns: i64, _slot_ns: i64, ctx: &Context) -> Vec<Frame> {
        let mut out = Vec::new();
        if !self.open(now_ns, ctx) {
            return out;
        }
        while let Some(item) = self.capture.as_ref().and_then(|c| c.try_next()) {
            match item {
                Captured::Frame(at, mut image) => {
                    if ctx.cfg.rotate_180 {
                        rotate_180(&mut image);
                    }
                    let Some(model) = model_for(ctx.cfg, ctx.camera, &mut self.rig_model, image.width, image.height)
                    else {
                        return out;
                    };
                    out.push(Frame { stamp_ns: at - self.offset_ns, image, model });
                }
                Captured::Bad(e) => {
                    self.read_errors += 1;
                    log::warn!("camera_driver: {e}");
                }
                Captured::Ended(e) => {
                    self.device_errors += 1;
                    self.capture = None;
                    self.reopen_at = now_ns + 1_000_000_000;
                    log::error!("camera_driver: {e}; reopening in a second");
                    return out;
                }
            }
        }
        out
    }
    fn read_errors(&self) -> u64 {
        self.read_errors
    }
    fn device_errors(&self) -> u64 {
        self.device_errors
    }
    /// The same device stays open; the camera model is derived again.
    fn reconfigured(&mut self, spec: &SourceSpec) -> bool {
        self.rig_model = None;
        matches!(spec, SourceSpec::V4l2 { device, offset_ns } if *device == self.device && *offset_ns == self.offset_ns)
    }
}
