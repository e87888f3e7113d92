//! The `main` of every node executable, and `xsurf compose`: parse the ROS 2 command line,
//! resolve the parameters for each node's fully qualified name, build the components, host
//! them over DDS (alone, or several in one process connected in memory).
//!
//! Exit codes: 0 after a clean shutdown (SIGINT/SIGTERM), 1 when DDS fails, 2 for a malformed
//! command line, params file, parameter value or environment variable.

use crate::registry as components;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;
use xsurf_runtime::component::AnyComponent;
use xsurf_runtime::dds::{self, DdsEnv, HostConfig, QosTable};
use xsurf_runtime::params::Params;
use xsurf_runtime::rosargs::{fq_name, RosArgs};

/// Builds the component `node` (a node type of [`components::NODE_NAMES`]) placed as
/// `namespace/name`, with its parameters resolved from `ros`.
pub fn node_config(
    node: &'static str,
    name: &str,
    namespace: &str,
    ros: &RosArgs,
) -> Result<(HostConfig, Box<dyn AnyComponent>), String> {
    let fq = fq_name(namespace, name);
    let (decls, params) = components::resolve(node, &fq, ros, &[])?;
    QosTable::from_params(&params).map_err(|e| format!("{fq}: {e}"))?;
    let component = components::build(node, &params).map_err(|e| format!("{fq}: {e}"))?;
    for d in &decls {
        if let Some(v) = params.get(d.name).filter(|v| **v != d.default) {
            log::info!("{fq}: parameter {} = {v}", d.name);
        }
    }
    let cfg = HostConfig {
        name: name.to_string(),
        namespace: namespace.to_string(),
        remaps: ros.remaps.clone(),
        decls,
        params,
        validate: Arc::new(move |p: &Params| components::build(node, p).map(|_| ()).map_err(|e| e.to_string())),
        rosout: ros.rosout_logs.unwrap_or(true),
        tick_period: Duration::from_millis(components::node_type(node).map_or(50, |t| t.tick_period_ms)),
    };
    Ok((cfg, component))
}

fn parse(who: &str, args: &[String]) -> Result<RosArgs, ExitCode> {
    match RosArgs::parse(args) {
        Ok(r) => {
            xsurf_runtime::logging::init(r.log_level.unwrap_or(log::LevelFilter::Info), r.logger_levels.clone());
            Ok(r)
        }
        Err(e) => {
            eprintln!("{who}: {e}");
            Err(ExitCode::from(2))
        }
    }
}

/// A usage error unless `name` and every part of the namespace `ns` are ROS name tokens.
fn check_identity(name: &str, ns: &str) -> Result<(), String> {
    // ROS 2's rule (rcl): letters, digits and underscores, not starting with a digit.
    let rule = "letters, digits or _, not starting with a digit";
    let ok = |t: &str| {
        let mut c = t.chars();
        c.next().is_some_and(|f| f.is_ascii_alphabetic() || f == '_')
            && c.all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
    };
    if !ok(name) {
        return Err(format!("node name {name:?} is not a valid ROS name ({rule})"));
    }
    if let Some(bad) = ns.split('/').filter(|p| !p.is_empty()).find(|p| !ok(p)) {
        return Err(format!("namespace {ns:?}: {bad:?} is not a valid ROS name ({rule})"));
    }
    Ok(())
}

fn host(who: &str, nodes: Vec<(HostConfig, Box<dyn AnyComponent>)>) -> ExitCode {
    let env = match DdsEnv::from_env(|k| std::env::var(k).ok()) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("{who}: {e}");
            return ExitCode::from(2);
        }
    };
    match dds::run_graph(&env, nodes) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{who}: {e}");
            ExitCode::from(1)
        }
    }
}

/// The `--help` of a node executable: usage, topics (as a node with default parameters has
/// them; relative names are placed in the node's namespace), parameters from the same
/// declarations the node uses, and services.
pub fn node_help(node: &str) -> String {
    use std::fmt::Write;
    let mut s = format!(
        "{node} {} (xsurf; documented in nodes/README.md)\n\nusage: {node} [--ros-args [-r __ns:=/NS] [-r __node:=NAME] [-r FROM:=TO] [-p NAME:=VALUE] [--params-file FILE] [--log-level LEVEL]]\n",
        env!("CARGO_PKG_VERSION")
    );
    let decls = components::declarations(node).unwrap_or_default();
    if let Ok(c) = Params::resolve(&decls, &Default::default()).and_then(|p| components::build(node, &p)) {
        let ports = |title: &str, ports: Vec<xsurf_runtime::component::Port>, s: &mut String| {
            let _ = writeln!(s, "\n{title}:");
            for p in ports {
                let _ = writeln!(s, "  {:28} {} ({:?})", p.topic, p.type_name, p.qos);
            }
        };
        ports("subscribes (with default parameters)", c.inputs(), &mut s);
        ports("publishes", c.outputs(), &mut s);
    }
    let _ = writeln!(s, "\nparameters (name, type, default, unit: meaning):");
    for d in &decls {
        let _ = writeln!(s, "  {}", d.help_line());
    }
    let _ = writeln!(s, "\nparameters of every node (the host's):");
    for d in dds::host_declarations() {
        let _ = writeln!(s, "  {}", d.help_line());
    }
    let _ = writeln!(
        s,
        "\nservices: ~/list_parameters, ~/get_parameters, ~/set_parameters, ~/set_parameters_atomically,\n  ~/describe_parameters, ~/get_parameter_types (rcl_interfaces, as `ros2 param` uses them)"
    );
    s
}

/// Runs the node `node` with this process's arguments.
pub fn main(node: &'static str) -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().is_some_and(|a| a == "--help" || a == "-h") {
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        let _ = out.write_all(node_help(node).as_bytes()).and_then(|()| out.flush());
        return ExitCode::SUCCESS;
    }
    if args.first().is_some_and(|a| a == "--version") {
        println!("{node} {}", env!("CARGO_PKG_VERSION"));
        return ExitCode::SUCCESS;
    }
    let ros = match parse(node, &args) {
        Ok(r) => r,
        Err(code) => return code,
    };
    if !ros.user_args.is_empty() {
        eprintln!("{node}: unexpected arguments {:?} (ROS arguments go after --ros-args)", ros.user_args);
        return ExitCode::from(2);
    }
    let (name, ns) = ros.node_identity(node, "/");
    if let Err(e) = check_identity(&name, &ns) {
        eprintln!("{node}: {e}");
        return ExitCode::from(2);
    }
    match node_config(node, &name, &ns, &ros) {
        Ok(n) => host(node, vec![n]),
        Err(e) => {
            eprintln!("{e}");
            ExitCode::from(2)
        }
    }
}

/// `xsurf compose /ns/node_type... [--ros-args ...]`: several nodes in one process, connected
/// in memory; each node is named by its type and placed in its namespace; parameters come
/// from the params files and `-p` rules as for separate nodes.
pub fn compose(args: &[String]) -> ExitCode {
    let ros = match parse("xsurf compose", args) {
        Ok(r) => r,
        Err(code) => return code,
    };
    if ros.user_args.is_empty() {
        eprintln!(
            "xsurf compose: name the nodes, e.g. xsurf compose /cam1/edge_detector /cam1/triangulator [--ros-args ...]"
        );
        return ExitCode::from(2);
    }
    let mut nodes = Vec::new();
    for spec in &ros.user_args {
        // `/ns/name=type`, or `/ns/type` for a node named as its type.
        let (path, ty_given) = match spec.split_once('=') {
            Some((p, t)) => (p, Some(t)),
            None => (spec.as_str(), None),
        };
        let (ns, name) = path.rsplit_once('/').unwrap_or(("", path));
        let ty = ty_given.unwrap_or(name);
        let Some(&node) = components::NODE_NAMES.iter().find(|n| **n == ty) else {
            eprintln!("xsurf compose: {spec}: unknown node type {ty:?} (known: {})", components::NODE_NAMES.join(", "));
            return ExitCode::from(2);
        };
        let ns = xsurf_runtime::rosargs::normalize_ns(ns);
        if let Err(e) = check_identity(name, &ns) {
            eprintln!("xsurf compose: {spec}: {e}");
            return ExitCode::from(2);
        }
        match node_config(node, name, &ns, &ros) {
            Ok(n) => nodes.push(n),
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(2);
            }
        }
    }
    host("xsurf compose", nodes)
}
