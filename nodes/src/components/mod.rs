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
use xsurf_runtime::params::{NodeParams, ParamDecl, ParamError, ParamValue, Params};
use xsurf_runtime::rosargs::RosArgs;

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
        "camera_driver" => camera_driver::CameraDriverParams::declarations(),
        "c_arm_pose" => c_arm_pose::CArmPoseParams::declarations(),
        "edge_detector" => edge_detector::EdgeParams::declarations(),
        "triangulator" => triangulator::TriangulatorParams::declarations(),
        "mesher" => mesher::MesherParams::declarations(),
        "merger" => merger::MergerParams::declarations(),
        "xray_aligner" => xray_aligner::XrayAlignerParams::declarations(),
        _ => return None,
    })
}

/// The parameters of the node `node` placed as `fq`, as every host resolves them (the node
/// executables, `xsurf compose`, `xsurf reconstruct`): the node's and the host's declarations,
/// overridden by the params files and `-p` rules of `ros` that match `fq`, then by `extra` (what
/// the host itself sets). A rule naming a parameter the node does not declare is logged.
pub fn resolve(
    node: &str,
    fq: &str,
    ros: &RosArgs,
    extra: &[(&str, ParamValue)],
) -> Result<(Vec<ParamDecl>, Params), String> {
    let mut decls = declarations(node).ok_or_else(|| format!("{fq}: node type {node} has no component"))?;
    decls.extend(xsurf_runtime::dds::host_declarations());
    let mut overrides = ros.param_overrides(fq).map_err(|e| format!("{fq}: {e}"))?;
    for n in ros.explicit_param_names(fq).map_err(|e| format!("{fq}: {e}"))? {
        if !decls.iter().any(|d| d.name == n) {
            log::warn!("{fq}: parameter {n} is not a parameter of {node} (`{node} --help` lists them); ignored");
        }
    }
    overrides.extend(extra.iter().map(|(k, v)| (k.to_string(), v.clone())));
    let params = Params::resolve(&decls, &overrides).map_err(|e| format!("{fq}: {e}"))?;
    Ok((decls, params))
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The declared defaults, resolved and read back, are the struct's defaults.
    fn defaults_round_trip<P: NodeParams + Default + PartialEq + std::fmt::Debug>() {
        let p = Params::resolve(&P::declarations(), &Default::default()).unwrap();
        assert_eq!(P::from_params(&p).unwrap(), P::default());
    }

    #[test]
    fn every_node_reads_its_declared_defaults_back() {
        defaults_round_trip::<camera_driver::CameraDriverParams>();
        defaults_round_trip::<c_arm_pose::CArmPoseParams>();
        defaults_round_trip::<edge_detector::EdgeParams>();
        defaults_round_trip::<triangulator::TriangulatorParams>();
        defaults_round_trip::<mesher::MesherParams>();
        defaults_round_trip::<merger::MergerParams>();
        defaults_round_trip::<xray_aligner::XrayAlignerParams>();
        defaults_round_trip::<xsurf_runtime::dds::HostParams>();
        for node in NODE_NAMES {
            let p = Params::resolve(&declarations(node).unwrap(), &Default::default()).unwrap();
            assert!(build(node, &p).is_ok(), "{node} does not start on its defaults");
        }
    }
}
