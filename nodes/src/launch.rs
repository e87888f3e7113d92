//! `xsurf launch FILE [--composed] [NAME:=VALUE...]`: the ROS 2 YAML launch format without ROS.
//!
//! Reads the actions `arg` (overridden by `NAME:=VALUE` on the command line), `let`, `node`
//! (`exec`, `pkg` ignored, `name`, `namespace`, `param` values and `from` files, `remap`,
//! `args`, `ros_args`, `respawn`, `respawn_delay`, `env` as `name`/`value` pairs), `include` (with `arg`), `group` and `push_ros_namespace` (also spelt
//! `push-ros-namespace`), with the substitutions `$(var NAME)`, `$(env NAME [DEFAULT])` and
//! `$(dirname)`. Anything else is an error naming the file and the action.
//!
//! Separate mode starts one process per node (the executable beside `xsurf`, else on PATH, else,
//! for a node type of the registry, `xsurf compose` with that one node), prefixes their output
//! with the node's name, and supervises them: a node with `respawn: true`
//! that exits (crashed, killed) is reported and started again after `respawn_delay` seconds, as
//! `ros2 launch` does, unless it exits 2 (its command line or parameters refused, which a restart
//! cannot mend); any other node that exits is reported, the others are stopped, and the
//! launcher exits 1. SIGINT/SIGTERM stop every node (SIGTERM, then SIGKILL after 10 s; nothing is
//! respawned then) and the launcher exits 0 when they all left cleanly. `--composed` hosts every
//! node in one `xsurf compose` process, which is respawned (with the longest delay asked) if any
//! node asks for it.

use anyhow::{anyhow, bail, Context};
use serde_yaml::Value;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use xsurf_runtime::rosargs::{fq_name, normalize_ns};

/// One node to start.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSpec {
    /// Executable (a name, or a path).
    pub exec: String,
    /// Node name.
    pub name: String,
    /// Absolute namespace.
    pub namespace: String,
    /// Parameter files, in order.
    pub param_files: Vec<PathBuf>,
    /// Parameter values, in order (name, YAML value).
    pub params: Vec<(String, Value)>,
    /// Remaps `from:=to`.
    pub remaps: Vec<(String, String)>,
    /// Extra arguments before `--ros-args`.
    pub args: Vec<String>,
    /// Extra ROS arguments.
    pub ros_args: Vec<String>,
    /// Start the node again when it exits (`respawn`), after `respawn_delay` seconds.
    pub respawn: Option<Duration>,
    /// Environment variables of its process (`env`: `name`, `value`), in order.
    pub env: Vec<(String, String)>,
}

impl NodeSpec {
    /// Fully qualified node name.
    pub fn fq_name(&self) -> String {
        fq_name(&self.namespace, &self.name)
    }
}

struct Scope {
    file: PathBuf,
    vars: BTreeMap<String, String>,
    namespace: String,
}

fn substitute(text: &str, scope: &Scope) -> anyhow::Result<String> {
    let mut out = String::new();
    let mut rest = text;
    while let Some(i) = rest.find("$(") {
        out.push_str(&rest[..i]);
        let end = rest[i..].find(')').ok_or_else(|| anyhow!("unclosed substitution in {text:?}"))? + i;
        let inner: Vec<&str> = rest[i + 2..end].split_whitespace().collect();
        let value =
            match inner.as_slice() {
                ["var", name] => scope.vars.get(*name).cloned().ok_or_else(|| {
                    anyhow!("$(var {name}): no launch argument or variable {name} (give {name}:=VALUE)")
                })?,
                ["env", name] => std::env::var(name).map_err(|_| anyhow!("$(env {name}): not set"))?,
                ["env", name, default @ ..] => std::env::var(name).unwrap_or_else(|_| default.join(" ")),
                ["dirname"] => scope.file.parent().unwrap_or(Path::new(".")).to_string_lossy().into_owned(),
                other => bail!("substitution $({}) is not supported (var, env, dirname are)", other.join(" ")),
            };
        out.push_str(&value);
        rest = &rest[end + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

fn text(v: &Value, what: &str, scope: &Scope) -> anyhow::Result<String> {
    let s = match v {
        Value::String(s) => s.clone(),
        Value::Number(n) => n.to_string(),
        Value::Bool(b) => b.to_string(),
        _ => bail!("{what}: expected a string"),
    };
    substitute(&s, scope)
}

fn field<'a>(m: &'a Value, key: &str) -> Option<&'a Value> {
    m.get(key)
}

/// Substitutes inside strings of a parameter value.
fn param_value(v: &Value, scope: &Scope) -> anyhow::Result<Value> {
    Ok(match v {
        Value::String(s) => {
            let s = substitute(s, scope)?;
            // As a launch file would: a substituted value is parsed as YAML.
            serde_yaml::from_str::<Value>(&s).ok().filter(|v| !matches!(v, Value::Null)).unwrap_or(Value::String(s))
        }
        Value::Sequence(items) => {
            Value::Sequence(items.iter().map(|i| param_value(i, scope)).collect::<Result<_, _>>()?)
        }
        other => other.clone(),
    })
}

/// Reads a launch file into the nodes it starts.
pub fn load(path: &Path, cli_args: &BTreeMap<String, String>) -> anyhow::Result<Vec<NodeSpec>> {
    let mut nodes = Vec::new();
    let mut scope = Scope { file: path.to_path_buf(), vars: BTreeMap::new(), namespace: "/".into() };
    load_into(path, cli_args, &mut scope, &mut nodes, 0)?;
    Ok(nodes)
}

fn load_into(
    path: &Path,
    cli_args: &BTreeMap<String, String>,
    scope: &mut Scope,
    nodes: &mut Vec<NodeSpec>,
    depth: u32,
) -> anyhow::Result<()> {
    if depth > 16 {
        bail!("{}: includes nested more than 16 deep", path.display());
    }
    let text_in = std::fs::read_to_string(path).with_context(|| format!("launch file {}", path.display()))?;
    let doc: Value = serde_yaml::from_str(&text_in).with_context(|| format!("launch file {}", path.display()))?;
    let actions = doc
        .get("launch")
        .and_then(Value::as_sequence)
        .ok_or_else(|| anyhow!("{}: expected a top-level `launch:` list", path.display()))?;
    scope.file = path.to_path_buf();
    actions_into(actions, cli_args, scope, nodes, depth).with_context(|| format!("launch file {}", path.display()))
}

fn actions_into(
    actions: &[Value],
    cli_args: &BTreeMap<String, String>,
    scope: &mut Scope,
    nodes: &mut Vec<NodeSpec>,
    depth: u32,
) -> anyhow::Result<()> {
    for (i, action) in actions.iter().enumerate() {
        let m = action.as_mapping().filter(|m| m.len() == 1).ok_or_else(|| anyhow!("action {i}: expected one key"))?;
        let (k, body) = m.iter().next().ok_or_else(|| anyhow!("action {i}: empty"))?;
        let kind = k.as_str().unwrap_or("");
        let ctx = || format!("action {i} ({kind})");
        match kind {
            "arg" => {
                let name = text(field(body, "name").ok_or_else(|| anyhow!("{}: no name", ctx()))?, "name", scope)?;
                let value = match (cli_args.get(&name), field(body, "default")) {
                    (Some(v), _) => v.clone(),
                    (None, Some(d)) => text(d, "default", scope)?,
                    (None, None) => bail!("launch argument {name} has no default: give {name}:=VALUE"),
                };
                scope.vars.insert(name, value);
            }
            "let" => {
                let name = text(field(body, "name").ok_or_else(|| anyhow!("{}: no name", ctx()))?, "name", scope)?;
                let value = text(field(body, "value").ok_or_else(|| anyhow!("{}: no value", ctx()))?, "value", scope)?;
                scope.vars.insert(name, value);
            }
            "push_ros_namespace" | "push-ros-namespace" => {
                let ns = text(
                    field(body, "namespace").ok_or_else(|| anyhow!("{}: no namespace", ctx()))?,
                    "namespace",
                    scope,
                )?;
                scope.namespace = join_ns(&scope.namespace, &ns);
            }
            "group" => {
                let children = body
                    .as_sequence()
                    .or_else(|| field(body, "children").and_then(Value::as_sequence))
                    .ok_or_else(|| anyhow!("{}: expected a list of actions", ctx()))?;
                let saved = (scope.vars.clone(), scope.namespace.clone());
                actions_into(children, cli_args, scope, nodes, depth).with_context(ctx)?;
                (scope.vars, scope.namespace) = saved;
            }
            "include" => {
                let file = text(field(body, "file").ok_or_else(|| anyhow!("{}: no file", ctx()))?, "file", scope)?;
                let mut file = PathBuf::from(file);
                if file.is_relative() && !file.exists() {
                    file = scope.file.parent().unwrap_or(Path::new(".")).join(file);
                }
                let mut args = cli_args.clone();
                for a in field(body, "arg").and_then(Value::as_sequence).into_iter().flatten() {
                    let name =
                        text(field(a, "name").ok_or_else(|| anyhow!("{}: arg without name", ctx()))?, "name", scope)?;
                    let value = text(
                        field(a, "value").ok_or_else(|| anyhow!("{}: arg without value", ctx()))?,
                        "value",
                        scope,
                    )?;
                    args.insert(name, value);
                }
                let mut inner = Scope { file: file.clone(), vars: BTreeMap::new(), namespace: scope.namespace.clone() };
                load_into(&file, &args, &mut inner, nodes, depth + 1).with_context(ctx)?;
            }
            "node" => nodes.push(node(body, scope).with_context(ctx)?),
            other => bail!(
                "{}: action {other:?} is not supported (arg, let, node, include, group, push_ros_namespace are)",
                ctx()
            ),
        }
    }
    Ok(())
}

fn join_ns(base: &str, ns: &str) -> String {
    if ns.starts_with('/') {
        normalize_ns(ns)
    } else {
        normalize_ns(&format!("{}/{ns}", base.trim_end_matches('/')))
    }
}

fn node(body: &Value, scope: &Scope) -> anyhow::Result<NodeSpec> {
    let exec = text(field(body, "exec").ok_or_else(|| anyhow!("node without exec"))?, "exec", scope)?;
    let base = Path::new(&exec).file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or(exec.clone());
    let name = match field(body, "name") {
        Some(n) => text(n, "name", scope)?,
        None => base,
    };
    let namespace = match field(body, "namespace") {
        Some(n) => join_ns(&scope.namespace, &text(n, "namespace", scope)?),
        None => scope.namespace.clone(),
    };
    let mut spec = NodeSpec {
        exec,
        name,
        namespace,
        param_files: Vec::new(),
        params: Vec::new(),
        remaps: Vec::new(),
        args: Vec::new(),
        ros_args: Vec::new(),
        respawn: None,
        env: Vec::new(),
    };
    let respawn = match field(body, "respawn") {
        None => false,
        Some(v) => match text(v, "respawn", scope)?.as_str() {
            "true" | "True" => true,
            "false" | "False" => false,
            other => bail!("respawn: {other:?} is not true or false"),
        },
    };
    let delay = match field(body, "respawn_delay") {
        None => 0.0,
        Some(v) => {
            let t = text(v, "respawn_delay", scope)?;
            t.parse::<f64>()
                .ok()
                .filter(|d| d.is_finite() && (0.0..=3600.0).contains(d))
                .ok_or_else(|| anyhow!("respawn_delay: {t:?} is not a number of seconds in [0, 3600]"))?
        }
    };
    if respawn {
        spec.respawn = Some(Duration::from_secs_f64(delay));
    }
    for p in field(body, "param").and_then(Value::as_sequence).into_iter().flatten() {
        if let Some(f) = field(p, "from") {
            let f = PathBuf::from(text(f, "param from", scope)?);
            if let Some(why) = xsurf_formats::file_problem(&f) {
                bail!("node {}: params file {} {why}", spec.fq_name(), f.display());
            }
            spec.param_files.push(f);
        } else {
            let name =
                text(field(p, "name").ok_or_else(|| anyhow!("param without name or from"))?, "param name", scope)?;
            let value = param_value(field(p, "value").ok_or_else(|| anyhow!("param {name} without value"))?, scope)?;
            spec.params.push((name, value));
        }
    }
    for r in field(body, "remap").and_then(Value::as_sequence).into_iter().flatten() {
        let from = text(field(r, "from").ok_or_else(|| anyhow!("remap without from"))?, "remap from", scope)?;
        let to = text(field(r, "to").ok_or_else(|| anyhow!("remap without to"))?, "remap to", scope)?;
        spec.remaps.push((from, to));
    }
    if let Some(a) = field(body, "args") {
        spec.args = text(a, "args", scope)?.split_whitespace().map(str::to_string).collect();
    }
    if let Some(a) = field(body, "ros_args") {
        spec.ros_args = text(a, "ros_args", scope)?.split_whitespace().map(str::to_string).collect();
    }
    for e in field(body, "env").and_then(Value::as_sequence).into_iter().flatten() {
        let name = text(field(e, "name").ok_or_else(|| anyhow!("env without name"))?, "env name", scope)?;
        let value = text(field(e, "value").ok_or_else(|| anyhow!("env {name} without value"))?, "env value", scope)?;
        if name.is_empty() || name.contains('=') {
            bail!("node {}: env name {name:?} is not a variable name", spec.fq_name());
        }
        spec.env.push((name, value));
    }
    Ok(spec)
}

/// Writes the inline parameters of every node into one params file (keys are the fully
/// qualified node names), so both modes pass them the same way.
fn inline_params_file(nodes: &[NodeSpec], dir: &Path) -> anyhow::Result<Option<PathBuf>> {
    let mut doc = serde_yaml::Mapping::new();
    for n in nodes.iter().filter(|n| !n.params.is_empty()) {
        let mut params = serde_yaml::Mapping::new();
        for (k, v) in &n.params {
            params.insert(Value::String(k.clone()), v.clone());
        }
        let mut inner = serde_yaml::Mapping::new();
        inner.insert(Value::String("ros__parameters".into()), Value::Mapping(params));
        doc.insert(Value::String(n.fq_name()), Value::Mapping(inner));
    }
    if doc.is_empty() {
        return Ok(None);
    }
    let path = dir.join("inline_params.yaml");
    std::fs::write(&path, serde_yaml::to_string(&Value::Mapping(doc))?)?;
    Ok(Some(path))
}

/// Where node executable `exec` is: a path as given, the file beside `xsurf`, or one on PATH;
/// `None` if none is found.
fn executable(exec: &str) -> Option<PathBuf> {
    if exec.contains('/') {
        return Some(PathBuf::from(exec));
    }
    let beside = std::env::current_exe().ok().and_then(|p| p.parent().map(|d| d.join(exec)));
    let path = std::env::var_os("PATH").unwrap_or_default();
    beside.into_iter().chain(std::env::split_paths(&path).map(|d| d.join(exec))).find(|p| p.is_file())
}

/// The command that starts node `n` as its own process: its executable, or, for a node type
/// of the registry that has no executable of its own, `xsurf compose` with that one node (so
/// that a node added as a folder and a registry line runs under `xsurf launch` too).
fn node_command(n: &NodeSpec, inline: Option<&Path>) -> Command {
    let mut cmd = match executable(&n.exec) {
        Some(path) => {
            let mut cmd = Command::new(path);
            cmd.args(&n.args).arg("--ros-args");
            cmd.args(["-r".to_string(), format!("__node:={}", n.name), "-r".into(), format!("__ns:={}", n.namespace)]);
            cmd
        }
        None if crate::registry::node_type(&n.exec).is_some() => {
            let exe = std::env::current_exe().unwrap_or_else(|_| PathBuf::from("xsurf"));
            let mut cmd = Command::new(exe);
            cmd.arg("compose").arg(format!("{}={}", n.fq_name(), n.exec)).args(&n.args).arg("--ros-args");
            cmd
        }
        // Not found: spawning it names the missing executable.
        None => {
            let mut cmd = Command::new(&n.exec);
            cmd.args(&n.args).arg("--ros-args");
            cmd
        }
    };
    for f in &n.param_files {
        cmd.arg("--params-file").arg(f);
    }
    if let Some(f) = inline {
        cmd.arg("--params-file").arg(f);
    }
    for (from, to) in &n.remaps {
        cmd.args(["-r".to_string(), format!("{from}:={to}")]);
    }
    cmd.args(&n.ros_args);
    cmd.envs(n.env.iter().map(|(k, v)| (k, v)));
    cmd
}

struct Running {
    label: String,
    child: Child,
    status: Option<std::process::ExitStatus>,
    /// How to start it again, and after how long, for a node with `respawn`.
    respawn: Option<(Duration, Box<dyn Fn() -> Command>)>,
    /// When it is to be started again.
    restart_at: Option<Instant>,
    restarts: u32,
    /// SIGKILL sent (it did not stop on SIGTERM).
    killed: bool,
}

fn spawn(label: &str, mut cmd: Command) -> anyhow::Result<Running> {
    cmd.stdout(Stdio::piped()).stderr(Stdio::piped());
    let mut child = cmd.spawn().with_context(|| format!("cannot start {label}: {cmd:?}"))?;
    for pipe in [
        child.stdout.take().map(|p| Box::new(p) as Box<dyn std::io::Read + Send>),
        child.stderr.take().map(|p| Box::new(p) as Box<dyn std::io::Read + Send>),
    ]
    .into_iter()
    .flatten()
    {
        let label = label.to_string();
        std::thread::Builder::new().name(format!("output {label}")).spawn(move || {
            for line in std::io::BufReader::new(pipe).lines().map_while(Result::ok) {
                eprintln!("[{label}] {line}");
            }
        })?;
    }
    eprintln!("[launch] started {label} (pid {})", child.id());
    Ok(Running {
        label: label.to_string(),
        child,
        status: None,
        respawn: None,
        restart_at: None,
        restarts: 0,
        killed: false,
    })
}

fn terminate(r: &Running) {
    let _ = Command::new("kill").args(["-TERM", &r.child.id().to_string()]).status();
}

/// `xsurf compose` with every node of the launch file: one process, started again if any node
/// asks for respawn.
fn start_composed(nodes: &[NodeSpec], inline: Option<&Path>) -> anyhow::Result<Running> {
    let mut args: Vec<String> = vec!["compose".into()];
    let mut ros: Vec<String> = vec!["--ros-args".into()];
    for n in nodes {
        let ty = Path::new(&n.exec).file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
        if !n.args.is_empty() {
            bail!("node {}: args are not supported with --composed", n.fq_name());
        }
        args.push(if ty == n.name { n.fq_name() } else { format!("{}={ty}", n.fq_name()) });
        for f in &n.param_files {
            ros.extend(["--params-file".into(), f.to_string_lossy().into_owned()]);
        }
        if !n.remaps.is_empty() && nodes.iter().filter(|o| o.name == n.name).count() > 1 {
            bail!(
                "node {}: node-specific remaps cannot be told apart from another node named {} when composed",
                n.fq_name(),
                n.name
            );
        }
        for (from, to) in &n.remaps {
            ros.extend(["-r".into(), format!("{}:{from}:={to}", n.name)]);
        }
        ros.extend(n.ros_args.iter().cloned());
    }
    if let Some(f) = inline {
        ros.extend(["--params-file".into(), f.to_string_lossy().into_owned()]);
    }
    // One process: the nodes' environments together, and two values of one variable an error.
    let mut env: BTreeMap<String, (String, String)> = BTreeMap::new();
    for n in nodes {
        for (k, v) in &n.env {
            match env.get(k) {
                Some((other, w)) if w != v => {
                    bail!(
                        "env {k}: node {} sets {v:?} and node {other} {w:?}, which one process cannot have",
                        n.fq_name()
                    )
                }
                _ => {
                    env.insert(k.clone(), (n.fq_name(), v.clone()));
                }
            }
        }
    }
    let exe = std::env::current_exe()?;
    let command = move || {
        let mut cmd = Command::new(&exe);
        cmd.args(&args).args(&ros);
        cmd.envs(env.iter().map(|(k, (_, v))| (k, v)));
        cmd
    };
    let mut r = spawn("xsurf compose", command())?;
    // Composed, the one process hosts every node: it is started again if any node asks.
    r.respawn =
        nodes.iter().filter_map(|n| n.respawn).max().map(|d| (d, Box::new(command) as Box<dyn Fn() -> Command>));
    Ok(r)
}

/// Each node of the launch file as a process of its own; a node that cannot be started stops
/// the ones already started.
fn start_each(nodes: &[NodeSpec], inline: Option<&Path>) -> anyhow::Result<Vec<Running>> {
    let mut running = Vec::new();
    for n in nodes {
        let command = {
            let (n, inline) = (n.clone(), inline.map(Path::to_path_buf));
            move || node_command(&n, inline.as_deref())
        };
        match spawn(&n.fq_name(), command()) {
            Ok(mut r) => {
                r.respawn = n.respawn.map(|d| (d, Box::new(command) as Box<dyn Fn() -> Command>));
                running.push(r);
            }
            Err(e) => {
                running.iter().for_each(terminate);
                return Err(e);
            }
        }
    }
    Ok(running)
}

/// Watches the processes until all have ended: respawns those that ask for it (not one whose
/// command line or parameters are refused, exit 2), stops the others when one fails or a signal
/// arrives, and kills what has not stopped 10 s after SIGTERM. True if anything failed.
fn supervise(running: &mut [Running], stop: &AtomicBool) -> bool {
    let mut failed = false;
    let mut stopping_since: Option<Instant> = None;
    loop {
        for r in running.iter_mut().filter(|r| r.status.is_none()) {
            if let Ok(Some(s)) = r.child.try_wait() {
                r.status = Some(s);
                // Exit 2 is a refused command line or parameter: starting again cannot help.
                let refused = s.code() == Some(2);
                match (&r.respawn, stopping_since) {
                    (Some(_), None) if refused => {
                        eprintln!(
                            "[launch] {} exited with {s} (its command line or parameters are refused): not respawned; stopping the others",
                            r.label
                        );
                        failed = true;
                    }
                    (Some((delay, _)), None) => {
                        eprintln!(
                            "[launch] {} exited with {s}; respawning in {:.1} s (respawn {})",
                            r.label,
                            delay.as_secs_f64(),
                            r.restarts + 1
                        );
                        r.restart_at = Some(Instant::now() + *delay);
                    }
                    (None, None) => {
                        eprintln!("[launch] {} exited unexpectedly with {s}; stopping the others", r.label);
                        failed = true;
                    }
                    (_, Some(_)) if !s.success() => eprintln!("[launch] {} exited with {s}", r.label),
                    _ => {}
                }
            }
        }
        if stopping_since.is_none() {
            for r in running.iter_mut().filter(|r| r.restart_at.is_some_and(|t| Instant::now() >= t)) {
                r.restart_at = None;
                let Some((_, command)) = &r.respawn else { continue };
                match spawn(&r.label, command()) {
                    Ok(new) => {
                        r.child = new.child;
                        r.status = None;
                        r.restarts += 1;
                    }
                    Err(e) => {
                        eprintln!("[launch] {e:#}; stopping the others");
                        failed = true;
                    }
                }
            }
        } else {
            running.iter_mut().for_each(|r| r.restart_at = None);
        }
        if running.iter().all(|r| r.status.is_some() && r.restart_at.is_none()) {
            break;
        }
        if stopping_since.is_none() && (failed || stop.load(Ordering::SeqCst)) {
            stopping_since = Some(Instant::now());
            running.iter().filter(|r| r.status.is_none()).for_each(terminate);
        }
        if stopping_since.is_some_and(|t| t.elapsed() > Duration::from_secs(10)) {
            for r in running.iter_mut().filter(|r| r.status.is_none() && !r.killed) {
                eprintln!("[launch] {} did not stop in 10 s: killed", r.label);
                r.killed = true;
                let _ = r.child.kill();
                failed = true;
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    failed
}

/// Starts the nodes and supervises them until they end or a signal arrives.
pub fn run(nodes: &[NodeSpec], composed: bool) -> anyhow::Result<ExitCode> {
    if nodes.is_empty() {
        bail!("the launch file starts no node");
    }
    let dir = std::env::temp_dir().join(format!("xsurf-launch-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let inline = inline_params_file(nodes, &dir)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)).context("signal handler")?;
    }
    let mut running =
        if composed { vec![start_composed(nodes, inline.as_deref())?] } else { start_each(nodes, inline.as_deref())? };
    let failed = supervise(&mut running, &stop);
    let _ = std::fs::remove_dir_all(&dir);
    let unclean = running.iter().any(|r| r.status.is_some_and(|s| !s.success()));
    Ok(if failed || unclean { ExitCode::from(1) } else { ExitCode::SUCCESS })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_namespaces_args_includes_and_params() {
        let dir = std::env::temp_dir().join(format!("xsurf-launch-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("p.yaml"), "/**:\n  ros__parameters: {}\n").unwrap();
        std::fs::write(
            dir.join("inner.launch.yaml"),
            "launch:\n- arg: {name: who}\n- node: {exec: merger, name: $(var who)}\n",
        )
        .unwrap();
        std::fs::write(
            dir.join("main.launch.yaml"),
            r#"launch:
- arg: {name: params, default: $(dirname)/p.yaml}
- arg: {name: speed, default: "0.07"}
- let: {name: cam, value: cam1}
- node:
    exec: c_arm_pose
    param:
    - {from: $(var params)}
    - {name: speed, value: $(var speed)}
    - {name: laser_plane, value: [0.0, 1.0, 0.0, 0.0]}
- group:
  - push_ros_namespace: {namespace: $(var cam)}
  - node: {exec: edge_detector, remap: [{from: image_raw, to: image}]}
  - node: {exec: /opt/bin/triangulator, name: tri, namespace: sub}
- include: {file: inner.launch.yaml, arg: [{name: who, value: m2}]}
- node: {exec: mesher, respawn: "true", respawn_delay: 2.5, env: [{name: GLIBC_TUNABLES, value: $(var speed)}]}
- node: {exec: merger, respawn: false}
"#,
        )
        .unwrap();
        let cli = BTreeMap::from([("speed".to_string(), "0.14".to_string())]);
        let nodes = load(&dir.join("main.launch.yaml"), &cli).unwrap();
        let names: Vec<String> = nodes.iter().map(NodeSpec::fq_name).collect();
        assert_eq!(names, ["/c_arm_pose", "/cam1/edge_detector", "/cam1/sub/tri", "/m2", "/mesher", "/merger"]);
        assert_eq!(nodes[4].respawn, Some(Duration::from_millis(2500)));
        assert_eq!(nodes[4].env, [("GLIBC_TUNABLES".to_string(), "0.14".to_string())]);
        assert_eq!((nodes[0].respawn, nodes[5].respawn), (None, None));
        assert_eq!(nodes[0].param_files, [dir.join("p.yaml")]);
        assert_eq!(nodes[0].params[0], ("speed".to_string(), serde_yaml::from_str::<Value>("0.14").unwrap()));
        assert!(matches!(nodes[0].params[1].1, Value::Sequence(_)));
        assert_eq!(nodes[1].remaps, [("image_raw".to_string(), "image".to_string())]);
        assert_eq!((nodes[2].exec.as_str(), nodes[3].exec.as_str()), ("/opt/bin/triangulator", "merger"));

        // Errors name what is wrong.
        let bad = |yaml: &str, want: &str| {
            std::fs::write(dir.join("bad.launch.yaml"), yaml).unwrap();
            let e = format!("{:#}", load(&dir.join("bad.launch.yaml"), &BTreeMap::new()).unwrap_err());
            assert!(e.contains(want) && e.contains("bad.launch.yaml"), "{e}");
        };
        bad("launch:\n- executable: {cmd: ls}\n", "\"executable\" is not supported");
        bad("launch:\n- arg: {name: x}\n", "give x:=VALUE");
        bad("launch:\n- node: {exec: merger, name: $(find-pkg-share xsurf)}\n", "find-pkg-share");
        bad("nodes: []\n", "top-level `launch:`");
        bad("launch:\n- node: {exec: merger, respawn: maybe}\n", "respawn: \"maybe\" is not true or false");
        bad("launch:\n- node: {exec: merger, respawn: true, respawn_delay: -1}\n", "respawn_delay: \"-1\"");
        bad("launch:\n- node: {exec: merger, param: [{from: /no/such.yaml}]}\n", "/no/such.yaml does not exist");
        bad(
            "launch:\n- node: {exec: merger, env: [{name: A=B, value: c}]}\n",
            "env name \"A=B\" is not a variable name",
        );
        bad("launch:\n- node: {exec: merger, env: [{name: A}]}\n", "env A without value");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A node type of the registry with no executable of its own (a unit test's binary has
    /// none beside it) starts as `xsurf compose` with that one node, under its launch name;
    /// an executable that is neither found nor a node type is started by its name, whose
    /// failure names it.
    #[test]
    fn a_node_type_without_an_executable_runs_composed_alone() {
        let spec = NodeSpec {
            exec: "xray_aligner".into(),
            name: "aligner".into(),
            namespace: "/xray".into(),
            param_files: vec![PathBuf::from("p.yaml")],
            params: vec![],
            remaps: vec![("in".into(), "out".into())],
            args: vec![],
            ros_args: vec![],
            respawn: None,
            env: vec![("MALLOC_ARENA_MAX".into(), "2".into())],
        };
        assert!(
            executable("xray_aligner").is_none(),
            "precondition: no xray_aligner beside the test binary or on PATH"
        );
        let cmd = node_command(&spec, None);
        let args: Vec<String> = cmd.get_args().map(|a| a.to_string_lossy().into_owned()).collect();
        assert_eq!(cmd.get_program(), std::env::current_exe().unwrap().as_os_str());
        let env: Vec<_> = cmd.get_envs().collect();
        assert_eq!(env, [(std::ffi::OsStr::new("MALLOC_ARENA_MAX"), Some(std::ffi::OsStr::new("2")))]);
        assert_eq!(
            args,
            ["compose", "/xray/aligner=xray_aligner", "--ros-args", "--params-file", "p.yaml", "-r", "in:=out"]
        );
        let other = NodeSpec { exec: "no_such_node".into(), ..spec };
        assert_eq!(node_command(&other, None).get_program(), "no_such_node");
    }
}
