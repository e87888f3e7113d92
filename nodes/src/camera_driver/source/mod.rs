//! Where a camera's frames come from, behind one trait: the synthetic scanner
//! ([`synthetic`]), an image sequence ([`files`]) and a Video4Linux2 camera ([`v4l2`]).

pub(super) mod files;
pub(super) mod synthetic;
pub(super) mod v4l2;

use super::{Config, SourceSpec};
use xsurf_core::camera::CameraModel;
use xsurf_core::geom::Iso3;
use xsurf_core::image::Image;
use xsurf_core::rig::Rig;

/// A frame to publish, with its stamp and the camera model its camera_info gives.
pub(super) struct Frame {
    /// Exposure stamp, ns.
    pub stamp_ns: i64,
    /// The image (turned by `rotate_180` already).
    pub image: Image,
    /// The camera model at the image's size.
    pub model: CameraModel,
}

/// What a source may need of the node when it makes a frame.
pub(super) struct Context<'a> {
    /// The node's configuration.
    pub cfg: &'a Config,
    /// The camera (the rig's name).
    pub camera: &'a str,
    /// `table -> carm` at the frame's time, extrapolated from `/tf`, if any has arrived.
    pub pose: Option<Iso3>,
    /// The laser is on (between a scan's START and END).
    pub laser_on: bool,
    /// Frames published so far.
    pub frames: u64,
}

/// A source of frames.
pub(super) trait FrameSource: Send {
    /// True for a source the node paces by its frame slots (one frame a slot); false for a
    /// camera with a clock of its own, polled at every tick.
    fn paced(&self) -> bool {
        true
    }
    /// The frames due now: the one of the frame slot `slot_ns` (a paced source), or every
    /// frame that has arrived by `now_ns`.
    fn frames(&mut self, now_ns: i64, slot_ns: i64, ctx: &Context) -> Vec<Frame>;
    /// Frames that could not be read or decoded so far.
    fn read_errors(&self) -> u64 {
        0
    }
    /// Failures to open or keep the device so far.
    fn device_errors(&self) -> u64 {
        0
    }
    /// The node's parameters changed (`spec` is the new source's): keep going if it is this
    /// source, forgetting what was derived from the old parameters; `false` to be replaced.
    fn reconfigured(&mut self, spec: &SourceSpec) -> bool;
}

/// The source `spec` describes.
pub(super) fn build(spec: &SourceSpec) -> Box<dyn FrameSource> {
    match spec {
        SourceSpec::Synthetic => Box::new(synthetic::Synthetic::default()),
        SourceSpec::Files { list, stamps, repeat } => {
            Box::new(files::Files::new(list.clone(), stamps.clone(), *repeat))
        }
        SourceSpec::V4l2 { device, offset_ns } => Box::new(v4l2::V4l2::new(device.clone(), *offset_ns)),
    }
}

/// Turns an image by 180 degrees (pixel order reversed, pixels kept whole).
pub(super) fn rotate_180(img: &mut Image) {
    // Reversing the bytes reverses the pixel order and each pixel's bytes; turn those back.
    img.data.reverse();
    let n = img.encoding.bytes_per_pixel();
    if n > 1 {
        img.data.chunks_exact_mut(n).for_each(<[u8]>::reverse);
    }
}

/// The camera model for frames of `width` x `height`: `camera_info_url`'s, else the rig's
/// intrinsics scaled to the frames (kept in `cache`); `None` (logged) if the camera is in neither.
pub(super) fn model_for(
    cfg: &Config,
    camera: &str,
    cache: &mut Option<CameraModel>,
    width: u32,
    height: u32,
) -> Option<CameraModel> {
    match (&cfg.camera_info, *cache) {
        (Some(m), _) => Some(*m),
        (None, Some(m)) if (m.width, m.height) == (width, height) => Some(m),
        (None, _) => {
            let study;
            let rig = match &cfg.rig {
                Some(r) => r,
                None => {
                    study = Rig::study(width, height);
                    &study
                }
            };
            match rig.camera(camera).map(|c| c.model()) {
                Some(Ok(m)) => {
                    let m = m.scaled(width, height);
                    *cache = Some(m);
                    Some(m)
                }
                _ => {
                    log::error!("camera_driver: camera {camera:?} is not in the rig and no camera_info_url is set");
                    None
                }
            }
        }
    }
}
