//! The ROS 2 command line (`--ros-args ... --`), params files and name remapping, following
//! rcl's rules (design article "ROS command line arguments"):
//!
//! - `-p/--param name:=value` (YAML value), `--params-file FILE`, `-r/--remap [node:]from:=to`
//!   (including `__node` and `__ns`), `--log-level [logger:=]LEVEL`, `-e/--enclave NAME`,
//!   `--enable-/--disable-rosout-logs`, `--enable-/--disable-stdout-logs`,
//!   `--enable-/--disable-external-lib-logs`, `--log-config-file FILE`, `--log-file-name NAME`;
//! - several `--ros-args` sections; `--` ends one; everything else is the program's own;
//! - params files: `/**`, fully qualified and wildcard node names, `ros__parameters`, nested
//!   maps flattened into dotted names; later values win, and a node's exact name wins over a
//!   wildcard entry.

use crate::params::ParamValue;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// A malformed command line or params file. The program exits with code 2.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ArgsError {
    /// An argument we do not know inside `--ros-args`.
    #[error("unknown ROS argument {0:?}")]
    Unknown(String),
    /// A flag lacks its value.
    #[error("ROS argument {0} needs a value")]
    MissingValue(String),
    /// A `-p` or `-r` rule is not `name:=value`.
    #[error("malformed {flag} rule {rule:?}: {reason}")]
    BadRule {
        /// The flag.
        flag: &'static str,
        /// The rule text.
        rule: String,
        /// What is wrong.
        reason: String,
    },
    /// A params file cannot be read or parsed.
    #[error("params file {path}: {reason}")]
    ParamsFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A log level name we do not know.
    #[error("unknown log level {0:?} (debug, info, warn, error, fatal)")]
    LogLevel(String),
}

/// One remapping rule.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Remap {
    /// Only for the node of this name, if given.
    pub node: Option<String>,
    /// Name matched (may be relative).
    pub from: String,
    /// Replacement.
    pub to: String,
}

/// A parameter source in command-line order.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamSource {
    /// `-p name:=value`.
    Value(String, ParamValue),
    /// `--params-file FILE`.
    File(PathBuf),
}

/// Everything the ROS part of a command line says.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RosArgs {
    /// Parameter sources, in order.
    pub params: Vec<ParamSource>,
    /// Remapping rules, in order.
    pub remaps: Vec<Remap>,
    /// Global log level, if set.
    pub log_level: Option<log::LevelFilter>,
    /// Per-logger levels.
    pub logger_levels: Vec<(String, log::LevelFilter)>,
    /// Security enclave.
    pub enclave: Option<String>,
    /// Log to `/rosout` (default true).
    pub rosout_logs: Option<bool>,
    /// Log to stdout/stderr (default true).
    pub stdout_logs: Option<bool>,
    /// Arguments outside `--ros-args` sections (the program's own).
    pub user_args: Vec<String>,
}

fn level(s: &str) -> Result<log::LevelFilter, ArgsError> {
    Ok(match s.to_ascii_lowercase().as_str() {
        "debug" => log::LevelFilter::Debug,
        "info" => log::LevelFilter::Info,
        "warn" | "warning" => log::LevelFilter::Warn,
        "error" | "fatal" => log::LevelFilter::Error,
        "unset" => log::LevelFilter::Trace,
        _ => return Err(ArgsError::LogLevel(s.to_string())),
    })
}

fn split_rule(flag: &'static str, rule: &str) -> Result<(String, String), ArgsError> {
    let (a, b) = rule.split_once(":=").ok_or_else(|| ArgsError::BadRule {
        flag,
        rule: rule.to_string(),
        reason: "expected name:=value".into(),
    })?;
    if a.is_empty() {
        return Err(ArgsError::BadRule { flag, rule: rule.to_string(), reason: "empty name".into() });
    }
    Ok((a.to_string(), b.to_string()))
}

impl RosArgs {
    /// Parses a command line (without the program name).
    pub fn parse<S: AsRef<str>>(args: &[S]) -> Result<RosArgs, ArgsError> {
        let mut out = RosArgs::default();
        let mut i = 0;
        let mut in_ros = false;
        let next = |i: &mut usize, flag: &str| -> Result<String, ArgsError> {
            *i += 1;
            args.get(*i).map(|s| s.as_ref().to_string()).ok_or_else(|| ArgsError::MissingValue(flag.to_string()))
        };
        while i < args.len() {
            let a = args[i].as_ref();
            if !in_ros {
                if a == "--ros-args" {
                    in_ros = true;
                } else {
                    out.user_args.push(a.to_string());
                }
                i += 1;
                continue;
            }
            match a {
                "--ros-args" => {}
                "--" => in_ros = false,
                "-p" | "--param" => {
                    let rule = next(&mut i, a)?;
                    let (name, value) = split_rule("-p", &rule)?;
                    let v =
                        ParamValue::parse(&value).map_err(|reason| ArgsError::BadRule { flag: "-p", rule, reason })?;
                    out.params.push(ParamSource::Value(name, v));
                }
                "--params-file" => out.params.push(ParamSource::File(PathBuf::from(next(&mut i, a)?))),
                "-r" | "--remap" => {
                    let rule = next(&mut i, a)?;
                    let (lhs, to) = split_rule("-r", &rule)?;
                    // `node:from` (the node prefix has no slash and is not a special name).
                    let (node, from) = match lhs.split_once(':') {
                        Some((n, f)) if !n.contains('/') && !n.is_empty() => (Some(n.to_string()), f.to_string()),
                        _ => (None, lhs),
                    };
                    if to.is_empty() || from.is_empty() {
                        return Err(ArgsError::BadRule { flag: "-r", rule, reason: "empty name".into() });
                    }
                    out.remaps.push(Remap { node, from, to });
                }
                "--log-level" => {
                    let v = next(&mut i, a)?;
                    match v.split_once(":=") {
                        Some((logger, l)) => out.logger_levels.push((logger.to_string(), level(l)?)),
                        None => out.log_level = Some(level(&v)?),
                    }
                }
                "-e" | "--enclave" => out.enclave = Some(next(&mut i, a)?),
                "--enable-rosout-logs" => out.rosout_logs = Some(true),
                "--disable-rosout-logs" => out.rosout_logs = Some(false),
                "--enable-stdout-logs" => out.stdout_logs = Some(true),
                "--disable-stdout-logs" => out.stdout_logs = Some(false),
                "--enable-external-lib-logs" | "--disable-external-lib-logs" => {}
                "--log-config-file" | "--log-file-name" => {
                    next(&mut i, a)?;
                }
                other => return Err(ArgsError::Unknown(other.to_string())),
            }
            i += 1;
        }
        Ok(out)
    }

    /// The node's name and namespace after `__node` / `__ns` remaps (node-prefixed rules
    /// apply when their prefix is the default name).
    pub fn node_identity(&self, default_name: &str, default_ns: &str) -> (String, String) {
        let mut name = default_name.to_string();
        let mut ns = normalize_ns(default_ns);
        for r in &self.remaps {
            if r.node.as_deref().is_some_and(|n| n != default_name) {
                continue;
            }
            match r.from.as_str() {
                "__node" | "__name" => name = r.to.clone(),
                "__ns" => ns = normalize_ns(&r.to),
                _ => {}
            }
        }
        (name, ns)
    }

    /// The parameter overrides for the node `/<ns>/<name>`, from files and `-p` in order,
    /// each file's exact-name entries applied after its wildcard entries.
    pub fn param_overrides(&self, fq_node: &str) -> Result<BTreeMap<String, ParamValue>, ArgsError> {
        let mut out = BTreeMap::new();
        for src in &self.params {
            match src {
                ParamSource::Value(n, v) => {
                    out.insert(n.clone(), v.clone());
                }
                ParamSource::File(path) => {
                    let text = std::fs::read_to_string(path)
                        .map_err(|e| ArgsError::ParamsFile { path: path.clone(), reason: io_reason(&e) })?;
                    out.extend(
                        params_from_yaml(&text, fq_node)
                            .map_err(|reason| ArgsError::ParamsFile { path: path.clone(), reason })?,
                    );
                }
            }
        }
        Ok(out)
    }
}

/// An I/O error's reason, in words for the two a user makes most.
fn io_reason(e: &std::io::Error) -> String {
    match e.kind() {
        std::io::ErrorKind::NotFound => "does not exist".into(),
        std::io::ErrorKind::IsADirectory => "is a folder, not a file".into(),
        _ => e.to_string(),
    }
}

impl RosArgs {
    /// The parameter names given for `fq_node` itself: by `-p`, and in params-file entries that
    /// name the node (not wildcards, which address every node). A name among these that the
    /// node does not declare is a mistake worth a warning.
    pub fn explicit_param_names(&self, fq_node: &str) -> Result<Vec<String>, ArgsError> {
        let mut out = Vec::new();
        for src in &self.params {
            match src {
                ParamSource::Value(n, _) => out.push(n.clone()),
                ParamSource::File(path) => {
                    let text = std::fs::read_to_string(path)
                        .map_err(|e| ArgsError::ParamsFile { path: path.clone(), reason: io_reason(&e) })?;
                    let (_, exact) = params_from_yaml_split(&text, fq_node)
                        .map_err(|reason| ArgsError::ParamsFile { path: path.clone(), reason })?;
                    out.extend(exact.into_keys());
                }
            }
        }
        out.sort();
        out.dedup();
        Ok(out)
    }
}

/// `/ns` with a leading slash and no trailing one (`/` for the root).
pub fn normalize_ns(ns: &str) -> String {
    let t = ns.trim_matches('/');
    if t.is_empty() {
        "/".into()
    } else {
        format!("/{t}")
    }
}

/// The fully qualified node name.
pub fn fq_name(ns: &str, name: &str) -> String {
    if ns == "/" {
        format!("/{name}")
    } else {
        format!("{ns}/{name}")
    }
}

/// Glob match of a params-file node key against a fully qualified node name: `*` matches one
/// name segment (or part of one), `**` any number of segments. A key without a leading slash is
/// taken as `/key`.
pub fn node_key_matches(key: &str, fq_node: &str) -> bool {
    let key = if key.starts_with('/') { key.to_string() } else { format!("/{key}") };
    let k: Vec<&str> = key.trim_start_matches('/').split('/').collect();
    let n: Vec<&str> = fq_node.trim_start_matches('/').split('/').collect();
    fn seg(p: &str, s: &str) -> bool {
        match p.split_once('*') {
            None => p == s,
            Some((a, b)) => {
                s.len() >= a.len() + b.len() && s.starts_with(a) && s.ends_with(b) || (a.is_empty() && b.is_empty())
            }
        }
    }
    fn rec(k: &[&str], n: &[&str]) -> bool {
        match (k.first(), n.first()) {
            (None, None) => true,
            (Some(&"**"), _) => rec(&k[1..], n) || (!n.is_empty() && rec(k, &n[1..])),
            (Some(p), Some(s)) => seg(p, s) && rec(&k[1..], &n[1..]),
            _ => false,
        }
    }
    rec(&k, &n)
}

fn flatten(prefix: &str, v: &serde_yaml::Value, out: &mut BTreeMap<String, ParamValue>) -> Result<(), String> {
    match v {
        serde_yaml::Value::Mapping(m) => {
            for (k, v) in m {
                let k = k.as_str().map(str::to_string).or_else(|| k.as_i64().map(|i| i.to_string()));
                let k = k.ok_or_else(|| format!("non-string key under {prefix:?}"))?;
                let name = if prefix.is_empty() { k } else { format!("{prefix}.{k}") };
                flatten(&name, v, out)?;
            }
            Ok(())
        }
        other => {
            let pv = ParamValue::from_yaml(other).map_err(|e| format!("parameter {prefix}: {e}"))?;
            out.insert(prefix.to_string(), pv);
            Ok(())
        }
    }
}

/// The parameters a params file (text) gives the node `fq_node`.
pub fn params_from_yaml(text: &str, fq_node: &str) -> Result<BTreeMap<String, ParamValue>, String> {
    let (mut wildcard, exact) = params_from_yaml_split(text, fq_node)?;
    wildcard.extend(exact);
    Ok(wildcard)
}

/// Parameter values by name.
pub type ParamMap = BTreeMap<String, ParamValue>;

/// A params file's values for `fq_node`, split into those of wildcard entries (`/**`) and those
/// of entries that name the node itself.
pub fn params_from_yaml_split(text: &str, fq_node: &str) -> Result<(ParamMap, ParamMap), String> {
    let doc: serde_yaml::Value = serde_yaml::from_str(text).map_err(|e| format!("not YAML: {e}"))?;
    let top = doc.as_mapping().ok_or("top level must map node names to ros__parameters")?;
    let mut wildcard = BTreeMap::new();
    let mut exact = BTreeMap::new();
    for (k, v) in top {
        let key = k.as_str().ok_or("node names must be strings")?;
        // Namespaces may nest: `/ns: {node: {ros__parameters: ...}}`.
        collect(key, v, fq_node, &mut wildcard, &mut exact)?;
    }
    Ok((wildcard, exact))
}

fn collect(
    key: &str,
    v: &serde_yaml::Value,
    fq_node: &str,
    wildcard: &mut BTreeMap<String, ParamValue>,
    exact: &mut BTreeMap<String, ParamValue>,
) -> Result<(), String> {
    let m = v.as_mapping().ok_or_else(|| format!("entry {key:?} must be a mapping"))?;
    for (k, vv) in m {
        let kk = k.as_str().ok_or_else(|| format!("non-string key under {key:?}"))?;
        if kk == "ros__parameters" {
            if node_key_matches(key, fq_node) {
                let target = if key.contains('*') { &mut *wildcard } else { &mut *exact };
                flatten("", vv, target)?;
            }
        } else {
            let sub = format!("{}/{}", key.trim_end_matches('/'), kk.trim_start_matches('/'));
            collect(&sub, vv, fq_node, wildcard, exact)?;
        }
    }
    Ok(())
}

/// Resolves a topic name for a node: relative names are placed in the node's namespace, `~`
/// names under the node, then the first matching remap rule applies.
pub fn resolve_topic(name: &str, ns: &str, node: &str, remaps: &[Remap]) -> String {
    let expand = |n: &str| -> String {
        if let Some(rest) = n.strip_prefix("~/") {
            format!("{}/{}", fq_name(ns, node), rest)
        } else if n == "~" {
            fq_name(ns, node)
        } else if n.starts_with('/') {
            n.to_string()
        } else {
            fq_name(ns, n)
        }
    };
    let full = expand(name);
    for r in remaps {
        if r.node.as_deref().is_some_and(|n| n != node) || r.from.starts_with("__") {
            continue;
        }
        if expand(&r.from) == full {
            return expand(&r.to);
        }
    }
    full
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(args: &[&str]) -> Result<RosArgs, ArgsError> {
        RosArgs::parse(args)
    }

    #[test]
    #[allow(clippy::approx_constant)] // the docs example's literal values
    fn ros2_docs_examples() {
        // From the ROS 2 "Passing ROS arguments to nodes via the command-line" page.
        let a = p(&["--ros-args", "--remap", "__node:=my_node", "--remap", "__ns:=/demo"]).unwrap();
        assert_eq!(a.node_identity("talker", "/"), ("my_node".into(), "/demo".into()));
        let a = p(&["--ros-args", "-r", "chatter:=my_topic"]).unwrap();
        assert_eq!(resolve_topic("chatter", "/", "talker", &a.remaps), "/my_topic");
        let a = p(&[
            "--ros-args",
            "-p",
            "some_int:=42",
            "-p",
            "a_string:=Hello world",
            "-p",
            "some_lists.some_integers:=[1, 2, 3, 4]",
            "-p",
            "some_lists.some_doubles:=[3.14, 2.718]",
        ])
        .unwrap();
        let o = a.param_overrides("/n").unwrap();
        assert_eq!(o["some_int"], ParamValue::Integer(42));
        assert_eq!(o["a_string"], ParamValue::String("Hello world".into()));
        assert_eq!(o["some_lists.some_integers"], ParamValue::IntegerArray(vec![1, 2, 3, 4]));
        assert_eq!(o["some_lists.some_doubles"], ParamValue::DoubleArray(vec![3.14, 2.718]));
        let a = p(&["--ros-args", "--log-level", "debug"]).unwrap();
        assert_eq!(a.log_level, Some(log::LevelFilter::Debug));
        let a = p(&["--ros-args", "--log-level", "talker1:=debug", "--enable-rosout-logs", "-e", "/enc"]).unwrap();
        assert_eq!(a.logger_levels, vec![("talker1".to_string(), log::LevelFilter::Debug)]);
        assert_eq!(a.rosout_logs, Some(true));
        assert_eq!(a.enclave.as_deref(), Some("/enc"));
    }

    #[test]
    fn sections_user_args_and_node_prefixed_rules() {
        let a = p(&["mine", "--ros-args", "-r", "talker:chatter:=x", "--", "also", "--ros-args", "-r", "__ns:=/cam1"])
            .unwrap();
        assert_eq!(a.user_args, vec!["mine", "also"]);
        assert_eq!(resolve_topic("chatter", "/", "talker", &a.remaps), "/x");
        assert_eq!(resolve_topic("chatter", "/", "listener", &a.remaps), "/chatter");
        assert_eq!(a.node_identity("edge_detector", "/").1, "/cam1");
        assert_eq!(resolve_topic("image_raw", "/cam1", "edge_detector", &[]), "/cam1/image_raw");
        assert_eq!(resolve_topic("~/status", "/cam1", "edge_detector", &[]), "/cam1/edge_detector/status");
    }

    #[test]
    fn malformed_input_is_a_clear_error() {
        assert_eq!(p(&["--ros-args", "--bogus"]), Err(ArgsError::Unknown("--bogus".into())));
        assert_eq!(p(&["--ros-args", "-p"]), Err(ArgsError::MissingValue("-p".into())));
        assert!(matches!(p(&["--ros-args", "-p", "novalue"]), Err(ArgsError::BadRule { flag: "-p", .. })));
        assert!(matches!(p(&["--ros-args", "-r", ":=x"]), Err(ArgsError::BadRule { flag: "-r", .. })));
        assert!(matches!(p(&["--ros-args", "-p", "a:=[1, x]"]), Err(ArgsError::BadRule { .. })));
        assert_eq!(p(&["--ros-args", "--log-level", "loud"]), Err(ArgsError::LogLevel("loud".into())));
        let a = p(&["--ros-args", "--params-file", "/nonexistent.yaml"]).unwrap();
        assert!(matches!(a.param_overrides("/n"), Err(ArgsError::ParamsFile { .. })));
    }

    #[test]
    fn params_file_wildcards_nesting_and_precedence() {
        // The layout of the ROS 2 docs' "Parameters" concept page, plus our own nodes.
        let y = r#"
/**:
  ros__parameters:
    use_sim_time: true
    laser_plane: [0.0, 1.0, 0.0, 0.0]
    min_strength: 10.0
/cam1/edge_detector:
  ros__parameters:
    min_strength: 25.0
    roi:
      x_offset: 8
/**/edge_detector:
  ros__parameters:
    method: gaussian
    min_strength: 5.0
cam2:
  edge_detector:
    ros__parameters:
      method: parabolic
"#;
        let a = params_from_yaml(y, "/cam1/edge_detector").unwrap();
        assert_eq!(a["use_sim_time"], ParamValue::Bool(true));
        assert_eq!(a["min_strength"], ParamValue::Double(25.0), "exact name wins over wildcards");
        assert_eq!(a["roi.x_offset"], ParamValue::Integer(8));
        assert_eq!(a["method"], ParamValue::String("gaussian".into()));
        let b = params_from_yaml(y, "/cam2/edge_detector").unwrap();
        assert_eq!(b["method"], ParamValue::String("parabolic".into()));
        assert_eq!(b["min_strength"], ParamValue::Double(5.0));
        let c = params_from_yaml(y, "/merger").unwrap();
        assert!(!c.contains_key("method"));
        assert!(params_from_yaml("- a\n- b\n", "/n").is_err());
        assert!(params_from_yaml("/n:\n  ros__parameters:\n    x: {a: [1, b]}\n", "/n").is_err());
    }

    #[test]
    fn later_sources_win() {
        let dir = std::env::temp_dir().join(format!("xsurf-params-{}.yaml", std::process::id()));
        std::fs::write(&dir, "/**:\n  ros__parameters:\n    speed: 0.035\n").unwrap();
        let path = dir.to_string_lossy().to_string();
        let a = p(&["--ros-args", "-p", "speed:=0.14", "--params-file", &path]).unwrap();
        assert_eq!(a.param_overrides("/c_arm_pose").unwrap()["speed"], ParamValue::Double(0.035));
        let a = p(&["--ros-args", "--params-file", &path, "-p", "speed:=0.14"]).unwrap();
        assert_eq!(a.param_overrides("/c_arm_pose").unwrap()["speed"], ParamValue::Double(0.14));
        std::fs::remove_file(&dir).unwrap();
    }

    #[test]
    fn node_key_globs() {
        assert!(node_key_matches("/**", "/a/b"));
        assert!(node_key_matches("/cam*/edge_detector", "/cam1/edge_detector"));
        assert!(!node_key_matches("/cam*/edge_detector", "/x/edge_detector"));
        assert!(node_key_matches("merger", "/merger"));
        assert!(!node_key_matches("merger", "/ns/merger"));
        assert!(node_key_matches("/**/merger", "/merger"));
    }
}
