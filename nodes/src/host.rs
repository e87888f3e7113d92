//! The `main` of every node executable: parse the ROS 2 command line, resolve the parameters
//! for the node's fully qualified name, build the component, host it over DDS.
//!
//! Exit codes: 0 after a clean shutdown (SIGINT/SIGTERM), 1 when DDS fails, 2 for a malformed
//! command line, params file, parameter value or environment variable.

use crate::components;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;
use xsurf_runtime::dds::{self, DdsEnv, HostConfig};
use xsurf_runtime::params::Params;
use xsurf_runtime::rosargs::{fq_name, RosArgs};

/// Runs the node `node` (one of [`components::NODE_NAMES`]) with this process's arguments.
pub fn main(node: &'static str) -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let ros = match RosArgs::parse(&args) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("{node}: {e}");
            return ExitCode::from(2);
        }
    };
    xsurf_runtime::logging::init(ros.log_level.unwrap_or(log::LevelFilter::Info), ros.logger_levels.clone());
    if !ros.user_args.is_empty() {
        eprintln!("{node}: unexpected arguments {:?} (ROS arguments go after --ros-args)", ros.user_args);
        return ExitCode::from(2);
    }
    let (name, ns) = ros.node_identity(node, "/");
    let fq = fq_name(&ns, &name);
    let Some(decls) = components::declarations(node) else {
        eprintln!("{node}: this node has no component yet");
        return ExitCode::from(2);
    };
    let params = match ros
        .param_overrides(&fq)
        .map_err(|e| e.to_string())
        .and_then(|o| Params::resolve(&decls, &o).map_err(|e| e.to_string()))
    {
        Ok(p) => p,
        Err(e) => {
            eprintln!("{fq}: {e}");
            return ExitCode::from(2);
        }
    };
    let component = match components::build(node, &params) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{fq}: {e}");
            return ExitCode::from(2);
        }
    };
    for d in &decls {
        if let Some(v) = params.get(d.name).filter(|v| **v != d.default) {
            log::info!("{fq}: parameter {} = {v}", d.name);
        }
    }
    let env = match DdsEnv::from_env(|k| std::env::var(k).ok()) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("{fq}: {e}");
            return ExitCode::from(2);
        }
    };
    let cfg = HostConfig {
        name,
        namespace: ns,
        remaps: ros.remaps.clone(),
        decls,
        params,
        validate: Arc::new(move |p: &Params| components::build(node, p).map(|_| ()).map_err(|e| e.to_string())),
        rosout: ros.rosout_logs.unwrap_or(true),
        tick_period: Duration::from_millis(50),
    };
    match dds::run(&env, cfg, component) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{fq}: {e}");
            ExitCode::from(1)
        }
    }
}
