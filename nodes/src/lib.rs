//! # xsurf-nodes
//!
//! The nodes of the spec as transport-agnostic components ([`components`]), the conversions
//! between messages and the algorithms ([`convert`]), the scanner's tf view ([`tf`]), the
//! synthetic scan writer ([`synth`]), the calibration commands ([`calibrate`]), offline reconstruction from a bag ([`offline`]) and the
//! launcher of ROS 2 YAML launch files ([`launch`]).
#![deny(missing_docs)]

pub mod calibrate;
pub mod components;
pub mod convert;
pub mod host;
pub mod launch;
pub mod offline;
pub mod param_client;
pub mod play;
pub mod record;
pub mod synth;
pub mod tf;
pub mod v4l2;

/// A command-line mistake in an `xsurf` command (the binary prints its usage and exits 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);
