//! # xsurf-runtime
//!
//! Hosting for xsurf's nodes: the ROS 2 command line and params files ([`rosargs`]),
//! parameter values and declarations ([`params`]), the transport-agnostic component API
//! ([`component`]), the in-memory composition of several components ([`router`], single-threaded
//! and deterministic, for bags), and the live executor with a thread per node ([`threads`]).
#![deny(missing_docs)]

pub mod component;
pub mod dds;
pub mod harness;
pub mod logging;
pub mod params;
pub mod rosargs;
pub mod router;
pub mod threads;

/// The wall clock: ns since the Unix epoch (0 for a clock set before it).
pub fn wall_clock_ns() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as i64)
}
