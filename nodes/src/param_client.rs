//! `xsurf param list|get|set NODE ...`: the standard ROS 2 parameter services of a node, from
//! the command line (what `ros2 param` does), over DDS.

use anyhow::{anyhow, bail, Context as _};
use ros2_client::rcl_interfaces::{
    GetParametersRequest, GetParametersResponse, ListParametersRequest, ListParametersResponse, SetParametersRequest,
    SetParametersResponse,
};
use ros2_client::service::Client;
use ros2_client::{
    Message, Name, Node, NodeName, NodeOptions, Parameter, ParameterValue, ServiceMapping, ServiceTypeName,
};
use std::time::Duration;
use xsurf_runtime::dds::{from_ros, to_ros, DdsEnv};
use xsurf_runtime::params::ParamValue;

fn usage(msg: impl Into<String>) -> anyhow::Error {
    anyhow!(crate::UsageError(msg.into()))
}

/// How long to wait for the node's services before giving up, by default.
const TIMEOUT: Duration = Duration::from_secs(15);

/// How long to wait quietly before saying what is being waited for.
const QUIET: Duration = Duration::from_secs(2);

fn client<Req: Message + Clone + 'static, Resp: Message + 'static>(
    node: &mut Node,
    target: &str,
    service: &str,
    ty: &str,
) -> anyhow::Result<Client<Req, Resp>> {
    let qos = ros2_client::QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast { depth: 1 });
    node.create_client::<Req, Resp>(
        ServiceMapping::Enhanced,
        &Name::new(target, service).map_err(|e| anyhow!("node name {target}: {e}"))?,
        &ServiceTypeName::new("rcl_interfaces", ty),
        qos.clone(),
        qos,
    )
    .map_err(|e| anyhow!("client {target}/{service}: {e:?}"))
}

fn call<Req: Message + 'static, Resp: Message + 'static>(
    node: &Node,
    c: &Client<Req, Resp>,
    req: Req,
) -> anyhow::Result<Resp> {
    futures::executor::block_on(async {
        c.wait_for_service(node).await;
        let id = c.async_send_request(req).await.map_err(|e| anyhow!("request: {e:?}"))?;
        c.async_receive_response(id).await.map_err(|e| anyhow!("response: {e:?}"))
    })
}

/// After `timeout` without an answer, says so and exits 1 (a thread of its own, so the call
/// that waits needs no timeout); after `QUIET`, says what it is waiting for.
fn give_up_after(timeout: Duration, node_name: &str, env: &DdsEnv) -> anyhow::Result<()> {
    let target = node_name.to_string();
    let (domain, scope) = (env.domain_id, if env.localhost_only { "localhost only" } else { "all interfaces" });
    std::thread::Builder::new().name("waiting note".into()).spawn(move || {
        std::thread::sleep(QUIET.min(timeout));
        if timeout > QUIET {
            eprintln!(
                "xsurf: waiting for the parameter services of {target} (ROS_DOMAIN_ID {domain}, {scope}; up to {:.0} s more)",
                (timeout - QUIET).as_secs_f64()
            );
            std::thread::sleep(timeout - QUIET);
        }
        eprintln!(
            "xsurf: error: no answer from the parameter services of {target} within {:.0} s: is the node running, \
             in ROS_DOMAIN_ID {domain}? (`--timeout S` waits longer)",
            timeout.as_secs_f64()
        );
        std::process::exit(1);
    })?;
    Ok(())
}

/// What `param` asks a node.
enum Request {
    /// `list NODE`.
    List,
    /// `get NODE NAME`.
    Get(String),
    /// `set NODE NAME VALUE`.
    Set(String, String),
}

/// `param`'s arguments: how long to wait, the node's fully qualified name and the request.
fn parse_args(args: &[String]) -> anyhow::Result<(Duration, String, Request)> {
    let mut args = args.to_vec();
    let mut timeout = TIMEOUT;
    if let Some(i) = args.iter().position(|a| a == "--timeout") {
        let v = args.get(i + 1).ok_or_else(|| usage("--timeout needs a value (seconds)"))?;
        let s: f64 = v
            .parse()
            .ok()
            .filter(|s: &f64| s.is_finite() && *s > 0.0 && *s <= 3600.0)
            .ok_or_else(|| usage(format!("--timeout: {v:?} is not a number of seconds in (0, 3600]")))?;
        timeout = Duration::from_secs_f64(s);
        args.drain(i..i + 2);
    }
    let (verb, node_name, rest) = match args.as_slice() {
        [v, n, rest @ ..] => (v.as_str(), n.as_str(), rest),
        _ => return Err(usage("param needs list, get or set and a NODE")),
    };
    if !node_name.starts_with('/') {
        return Err(usage(format!("node {node_name:?}: give the fully qualified name, e.g. /cam1/edge_detector")));
    }
    let request = match (verb, rest) {
        ("list", []) => Request::List,
        ("get", [name]) => Request::Get(name.clone()),
        ("set", [name, value]) => Request::Set(name.clone(), value.clone()),
        ("list" | "get" | "set", _) => return Err(usage(format!("param {verb}: wrong number of arguments"))),
        _ => return Err(usage(format!("param {verb:?}: expected list, get or set"))),
    };
    Ok((timeout, node_name.to_string(), request))
}

/// Runs `param` with its arguments (`--timeout S` anywhere: how long to wait for the node);
/// prints the answer on stdout.
pub fn run(args: &[String]) -> anyhow::Result<()> {
    let (timeout, node_name, request) = parse_args(args)?;
    let node_name = node_name.as_str();
    let env = DdsEnv::from_env(|k| std::env::var(k).ok())?;
    let ctx = env.context()?;
    let mut node = ctx
        .new_node(
            NodeName::new("/", &format!("xsurf_param_{}", std::process::id()))?,
            NodeOptions::new().enable_rosout(false).start_parameter_services(false),
        )
        .map_err(|e| anyhow!("node: {e:?}"))?;
    let spinner = node.spinner().map_err(|e| anyhow!("spinner: {e:?}"))?;
    std::thread::Builder::new().name("spinner".into()).spawn(move || futures::executor::block_on(spinner.spin()))?;
    give_up_after(timeout, node_name, &env)?;
    match request {
        Request::List => {
            let c = client::<ListParametersRequest, ListParametersResponse>(
                &mut node,
                node_name,
                "list_parameters",
                "ListParameters",
            )?;
            let r = call(&node, &c, ListParametersRequest { prefixes: vec![], depth: 0 })?;
            let mut names = r.result.names;
            names.sort();
            for n in names {
                println!("  {n}");
            }
        }
        Request::Get(name) => {
            let c = client::<GetParametersRequest, GetParametersResponse>(
                &mut node,
                node_name,
                "get_parameters",
                "GetParameters",
            )?;
            let r = call(&node, &c, GetParametersRequest { names: vec![name.clone()] })?;
            let v =
                r.values.into_iter().next().map(ParameterValue::from).ok_or_else(|| anyhow!("no value returned"))?;
            match from_ros(&v) {
                Some(v) => println!("{} value is: {v}", v.type_name()),
                None => bail!("parameter {name} is not set on {node_name}"),
            }
        }
        Request::Set(name, value) => set(&mut node, node_name, &name, &value)?,
    }
    Ok(())
}

/// `param set NODE NAME VALUE`, answered as `ros2 param set` answers.
fn set(node: &mut ros2_client::Node, node_name: &str, name: &str, value: &str) -> anyhow::Result<()> {
    let v = ParamValue::parse(value).map_err(|e| usage(format!("value {value:?}: {e}")))?;
    let c = client::<SetParametersRequest, SetParametersResponse>(node, node_name, "set_parameters", "SetParameters")?;
    let req = SetParametersRequest { parameter: vec![Parameter { name: name.to_string(), value: to_ros(&v) }.into()] };
    let r = call(node, &c, req)?;
    let res = r.results.into_iter().next().context("no result returned")?;
    if !res.successful {
        // As `ros2 param set` prints it; the error line then does not repeat the reason.
        println!("Setting parameter failed: {}", res.reason);
        bail!("{node_name} refused {name} = {value} (the reason above)");
    }
    println!("Set parameter successful");
    Ok(())
}
