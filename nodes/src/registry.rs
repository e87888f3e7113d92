//! The node types. Each lives in its own folder, `nodes/src/<node>/`: `mod.rs` holds the
//! component (its ports, messages and counters) and the `NODE` that registers it here,
//! `params.rs` its parameters, declared once; its parts sit beside them. Hosts (the node
//! executables, `xsurf compose`, `xsurf launch`, `xsurf reconstruct`) find a node type, its
//! parameters and its constructor here by name; the docs (`--help`, nodes/README.md) follow
//! from the same entries.

use xsurf_runtime::component::AnyComponent;
use xsurf_runtime::params::{NodeParams, ParamDecl, ParamError, ParamValue, Params};
use xsurf_runtime::rosargs::RosArgs;

/// A node type as the registry lists it.
#[derive(Clone, Copy)]
pub struct NodeType {
    /// The node's name in the spec (and the executable's).
    pub name: &'static str,
    /// Its parameter declarations (its `params.rs`).
    pub declarations: fn() -> Vec<ParamDecl>,
    /// Its component from resolved parameters.
    pub build: fn(&Params) -> Result<Box<dyn AnyComponent>, ParamError>,
    /// Where it sits in the graph.
    pub role: Role,
    /// How often a live host ticks it when it asks for nothing sooner, ms (sources keep time on
    /// their own clocks; the processing nodes need only slow ticks).
    pub tick_period_ms: u64,
}

impl NodeType {
    /// The node type `name` whose parameters are `P`, built by `build`.
    pub const fn of<P: NodeParams>(
        name: &'static str,
        role: Role,
        tick_period_ms: u64,
        build: fn(&Params) -> Result<Box<dyn AnyComponent>, ParamError>,
    ) -> NodeType {
        NodeType { name, declarations: P::declarations, build, role, tick_period_ms }
    }
}

/// Where a node type sits in the graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A source of the scanner's data (a camera, the C-arm): a bag replaces it offline.
    Source,
    /// One per camera, in the camera's namespace: the chain from images to a camera's surface.
    PerCamera,
    /// One for the scanner, taking every camera's results.
    Scanner,
}

/// Every node type, in pipeline order (the list in `lib.rs`, one name per node).
pub const NODES: [NodeType; crate::NODE_TYPES.len()] = crate::NODE_TYPES;

/// The node type names, in pipeline order.
pub const NODE_NAMES: [&str; NODES.len()] = {
    let mut names = [""; NODES.len()];
    let mut i = 0;
    while i < NODES.len() {
        names[i] = NODES[i].name;
        i += 1;
    }
    names
};

/// The node type named `name`.
pub fn node_type(name: &str) -> Option<&'static NodeType> {
    NODES.iter().find(|t| t.name == name)
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

/// The declarations of a node type by name (for docs and `ros2 param` services).
pub fn declarations(node: &str) -> Option<Vec<ParamDecl>> {
    node_type(node).map(|t| (t.declarations)())
}

/// Builds a component by node type name from its resolved parameters.
pub fn build(node: &str, params: &Params) -> Result<Box<dyn AnyComponent>, ParamError> {
    match node_type(node) {
        Some(t) => (t.build)(params),
        None => Err(ParamError::Invalid { name: "node".into(), reason: format!("no component named {node}") }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use xsurf_runtime::params::NodeParams;

    /// The declared defaults, resolved and read back, are the struct's defaults.
    fn defaults_round_trip<P: NodeParams + Default + PartialEq + std::fmt::Debug>() {
        let p = Params::resolve(&P::declarations(), &Default::default()).unwrap();
        assert_eq!(P::from_params(&p).unwrap(), P::default());
    }

    #[test]
    fn every_node_reads_its_declared_defaults_back() {
        defaults_round_trip::<crate::camera_driver::CameraDriverParams>();
        defaults_round_trip::<crate::c_arm_pose::CArmPoseParams>();
        defaults_round_trip::<crate::edge_detector::EdgeParams>();
        defaults_round_trip::<crate::triangulator::TriangulatorParams>();
        defaults_round_trip::<crate::mesher::MesherParams>();
        defaults_round_trip::<crate::merger::MergerParams>();
        defaults_round_trip::<crate::xray_aligner::XrayAlignerParams>();
        defaults_round_trip::<xsurf_runtime::dds::HostParams>();
        for node in NODE_NAMES {
            let p = Params::resolve(&declarations(node).unwrap(), &Default::default()).unwrap();
            assert!(build(node, &p).is_ok(), "{node} does not start on its defaults");
        }
    }
}
