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

/// How long to wait for the node's services before giving up.
const TIMEOUT: Duration = Duration::from_secs(15);

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

/// Runs `param` with its arguments; prints the answer on stdout.
pub fn run(args: &[String]) -> anyhow::Result<()> {
    let (verb, node_name, rest) = match args {
        [v, n, rest @ ..] => (v.as_str(), n.as_str(), rest),
        _ => bail!("usage: xsurf param list|get|set NODE [NAME [VALUE]]"),
    };
    if !node_name.starts_with('/') {
        bail!("node {node_name:?}: give the fully qualified name, e.g. /cam1/edge_detector");
    }
    let env = DdsEnv::from_env(|k| std::env::var(k).ok())?;
    let ctx = env.context()?;
    let mut node = ctx
        .new_node(
            NodeName::new("/", &format!("xsurf_param_{}", std::process::id()))?,
            NodeOptions::new().enable_rosout(false).start_parameter_services(false),
        )
        .map_err(|e| anyhow!("node: {e:?}"))?;
    let spinner = node.spinner().map_err(|e| anyhow!("spinner: {e:?}"))?;
    std::thread::spawn(move || futures::executor::block_on(spinner.spin()));
    let target = node_name.to_string();
    std::thread::spawn(move || {
        std::thread::sleep(TIMEOUT);
        eprintln!("xsurf: error: no answer from the parameter services of {target} within {} s", TIMEOUT.as_secs());
        std::process::exit(1);
    });
    match (verb, rest) {
        ("list", []) => {
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
        ("get", [name]) => {
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
        ("set", [name, value]) => {
            let v = ParamValue::parse(value).map_err(|e| anyhow!("value {value:?}: {e}"))?;
            let c = client::<SetParametersRequest, SetParametersResponse>(
                &mut node,
                node_name,
                "set_parameters",
                "SetParameters",
            )?;
            let req =
                SetParametersRequest { parameter: vec![Parameter { name: name.clone(), value: to_ros(&v) }.into()] };
            let r = call(&node, &c, req)?;
            let res = r.results.into_iter().next().context("no result returned")?;
            if res.successful {
                println!("Set parameter successful");
            } else {
                println!("Setting parameter failed: {}", res.reason);
                bail!("{node_name} refused {name} = {value}: {}", res.reason);
            }
        }
        _ => bail!("usage: xsurf param list NODE | get NODE NAME | set NODE NAME VALUE"),
    }
    Ok(())
}
