//! The nodes' logic as components (see `xsurf_runtime::component`). Each has `new(&Params)`,
//! declares its parameters with defaults, units and meanings, and is documented in
//! `nodes/README.md`.

pub mod c_arm_pose;
pub mod camera_driver;
pub mod edge_detector;
pub mod merger;
pub mod mesher;
mod tally;
pub mod triangulator;
pub mod xray_aligner;

use xsurf_runtime::component::{Component, Msg, Outbox};
use xsurf_runtime::params::{ParamDecl, ParamError, ParamValue, Params};

/// A parameter declaration.
pub(crate) fn decl(
    name: &'static str,
    default: ParamValue,
    unit: &'static str,
    description: &'static str,
) -> ParamDecl {
    ParamDecl { name, default, unit, description }
}

/// Outputs published again at a fixed period until cleared, as a latched topic would be for
/// viewers that join late or lose a large best-effort message (the mesher's and merger's
/// results between scans).
#[derive(Default)]
pub(crate) struct Republisher {
    /// Output index and message.
    msgs: Vec<(usize, Msg)>,
    /// When they were last published (set at the first tick after `set`).
    last_ns: Option<i64>,
}

impl Republisher {
    /// Remembers the messages just published.
    pub(crate) fn set(&mut self, msgs: Vec<(usize, Msg)>) {
        self.msgs = msgs;
        self.last_ns = None;
    }
    /// Forgets them (a new scan).
    pub(crate) fn clear(&mut self) {
        self.msgs.clear();
    }
    /// Publishes them again when `period_ns` has passed (`None`: never).
    pub(crate) fn tick(&mut self, period_ns: Option<i64>, now_ns: i64, out: &mut Outbox) {
        let Some(period) = period_ns else { return };
        if self.msgs.is_empty() {
            return;
        }
        match self.last_ns {
            Some(t) if now_ns - t < period => {}
            Some(_) => {
                self.last_ns = Some(now_ns);
                for (i, m) in &self.msgs {
                    out.publish(*i, m.clone());
                }
            }
            None => self.last_ns = Some(now_ns),
        }
    }
}

/// The node names of the spec, in pipeline order.
pub const NODE_NAMES: [&str; 7] =
    ["camera_driver", "c_arm_pose", "edge_detector", "triangulator", "mesher", "merger", "xray_aligner"];

/// The declarations of a node by name (for docs and `ros2 param` services).
pub fn declarations(node: &str) -> Option<Vec<ParamDecl>> {
    Some(match node {
        "camera_driver" => camera_driver::declarations(),
        "c_arm_pose" => c_arm_pose::declarations(),
        "edge_detector" => edge_detector::declarations(),
        "triangulator" => triangulator::declarations(),
        "mesher" => mesher::declarations(),
        "merger" => merger::declarations(),
        "xray_aligner" => xray_aligner::declarations(),
        _ => return None,
    })
}

/// Builds a component by node name from its resolved parameters.
pub fn build(node: &str, params: &Params) -> Result<Box<dyn Component>, ParamError> {
    Ok(match node {
        "camera_driver" => Box::new(camera_driver::CameraDriverNode::new(params)?),
        "c_arm_pose" => Box::new(c_arm_pose::CArmPoseNode::new(params)?),
        "edge_detector" => Box::new(edge_detector::EdgeDetectorNode::new(params)?),
        "triangulator" => Box::new(triangulator::TriangulatorNode::new(params)?),
        "mesher" => Box::new(mesher::MesherNode::new(params)?),
        "merger" => Box::new(merger::MergerNode::new(params)?),
        "xray_aligner" => Box::new(xray_aligner::XrayAlignerNode::new(params)?),
        other => {
            return Err(ParamError::Invalid { name: "node".into(), reason: format!("no component named {other}") })
        }
    })
}
