//! # xsurf-nodes
//!
//! The nodes of the spec as transport-agnostic components, one folder each
//! ([`camera_driver`], [`c_arm_pose`], [`edge_detector`], [`triangulator`], [`mesher`],
//! [`merger`], [`xray_aligner`]) listed in the [`registry`], the conversions
//! between messages and the algorithms ([`convert`]), the scanner's tf view ([`tf`]), the
//! synthetic scan writer ([`synth`]), the `xsurf` command and its calibration commands ([`cli`]), offline reconstruction from a bag ([`offline`]) and the
//! launcher of ROS 2 YAML launch files ([`launch`]).
#![deny(missing_docs)]

pub mod cli;
pub mod convert;
pub mod host;
pub mod lasers;
pub mod launch;
pub mod offline;
pub mod pacs;
pub mod param_client;
pub mod play;
pub mod record;
pub mod registry;
mod republish;
pub mod scan_report;
pub mod synth;
mod tally;
pub mod tf;
pub mod v4l2;

/// The node types, in pipeline order: each is a folder `nodes/src/<node>/` whose `NODE` says
/// what the [`registry`] lists. Adding a node is one folder and its name here.
macro_rules! node_types {
    ($($node:ident),+ $(,)?) => {
        $(pub mod $node;)+
        const NODE_TYPES: [registry::NodeType; [$(stringify!($node)),+].len()] = [$($node::NODE),+];
    };
}
node_types!(camera_driver, c_arm_pose, edge_detector, triangulator, mesher, merger, xray_aligner);

/// A command-line mistake in an `xsurf` command (the binary prints its usage and exits 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);
