//! The synthetic scanner as a camera: it renders what the camera sees with the C-arm where
//! `/tf` says it is at the exposure, the laser on between a scan's START and END.

use super::{rotate_180, Context, Frame, FrameSource};
use crate::camera_driver::SourceSpec;
use xsurf_core::rig::Rig;
use xsurf_core::synth::{LaserModel, ScanSettings, Scanner};

/// The synthetic source; its scanner is set up at the first frame.
#[derive(Default)]
pub(in crate::camera_driver) struct Synthetic {
    /// The scanner and the camera's index in its rig.
    scanner: Option<(Scanner, usize)>,
}

impl Synthetic {
    fn scanner(&mut self, ctx: &Context) -> Result<&(Scanner, usize), String> {
        if self.scanner.is_none() {
            let cfg = ctx.cfg;
            let rig = cfg.rig.clone().unwrap_or_else(|| Rig::study(cfg.width, cfg.height));
            let settings = ScanSettings { encoding: cfg.encoding, seed: cfg.seed, ..ScanSettings::default() };
            let s = Scanner::new(cfg.scene.clone(), rig, LaserModel::default(), settings).map_err(|e| e.to_string())?;
            let i = s.camera_index(ctx.camera).ok_or_else(|| format!("camera {:?} is not in the rig", ctx.camera))?;
            self.scanner = Some((s, i));
        }
        self.scanner.as_ref().ok_or_else(|| "no scanner".to_string())
    }
}

impl FrameSource for Synthetic {
    /// The frame exposed at `now_ns` (its stamp), once a pose has arrived.
    fn frames(&mut self, now_ns: i64, _slot_ns: i64, ctx: &Context) -> Vec<Frame> {
        let Some(pose) = ctx.pose else { return Vec::new() };
        let frame = match self.scanner(ctx) {
            Ok((s, i)) => s.rig.cameras[*i].model().map(|m| {
                let mut image = s.render_at(*i, &pose, ctx.laser_on, ctx.frames);
                if ctx.cfg.rotate_180 {
                    rotate_180(&mut image);
                }
                Frame { stamp_ns: now_ns, image, model: ctx.cfg.camera_info.unwrap_or(m) }
            }),
            Err(e) => {
                log::error!("camera_driver: {e}");
                return Vec::new();
            }
        };
        match frame {
            Ok(f) => vec![f],
            Err(e) => {
                log::error!("camera_driver: {e}");
                Vec::new()
            }
        }
    }
    /// The scanner is set up again from the new parameters (scene, size, seed).
    fn reconfigured(&mut self, spec: &SourceSpec) -> bool {
        self.scanner = None;
        matches!(spec, SourceSpec::Synthetic)
    }
}
