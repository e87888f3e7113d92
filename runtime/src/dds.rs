//! Hosting one component as a ROS 2 node over DDS (ros2-client / RustDDS).
//!
//! What the host adds to ros2-client, which has none of it: `ROS_DOMAIN_ID`,
//! `ROS_LOCALHOST_ONLY=1` / `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (loopback only, through
//! `with_only_networks`), the node's parameters declared with their defaults so the standard
//! parameter services answer `ros2 param list/get/set` (a set that fails the component's
//! validation is refused with the reason), `use_sim_time` with `/clock` subscribed as
//! `rosgraph_msgs/msg/Clock`, log records forwarded to `/rosout`, QoS by topic class, and a clean
//! shutdown on SIGINT/SIGTERM (pending output flushed, the participant announces it leaves).
//!
//! Each subscription is read on its own thread into one bounded queue (depth
//! [`QUEUE_DEPTH`]). When the queue is full, a camera-stream (best-effort) message is dropped and
//! counted; other messages wait (their publishers are reliable).

use crate::component::{AnyComponent, Msg, Port, QosClass};
use crate::params::{NodeParams, ParamDecl, ParamValue, Params};
use crate::rosargs::Remap;
use futures::StreamExt;
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History, QosProfile, Reliability, WhenFull};
use ros2_client::{Context, MessageTypeName, Name, Node, NodeName, NodeOptions, ParameterValue as RosValue};
use std::net::Ipv4Addr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use xsurf_msgs::{
    rosgraph_msgs::Clock, sensor_msgs::CameraInfo, sensor_msgs::CompressedImage, sensor_msgs::Image,
    sensor_msgs::JointState, sensor_msgs::PointCloud2, std_msgs::StringMsg, tf2_msgs::TFMessage,
    visualization_msgs::Marker, xsurf_msgs::LaserLine, xsurf_msgs::ScanEvent,
};

/// Messages waiting for the component, at most.
pub const QUEUE_DEPTH: usize = 64;

/// Why the node could not start.
#[derive(Debug, thiserror::Error)]
pub enum HostError {
    /// An environment variable is malformed.
    #[error("environment variable {name}={value:?}: {reason}")]
    Env {
        /// Variable.
        name: &'static str,
        /// Value.
        value: String,
        /// What is wrong.
        reason: &'static str,
    },
    /// DDS refused something.
    #[error("DDS: {0}")]
    Dds(String),
    /// A node's thread ended before shutdown (it panicked); the others were shut down.
    #[error("{0} stopped unexpectedly")]
    NodeDied(String),
}

/// The DDS domain and network settings from the ROS 2 environment variables.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DdsEnv {
    /// `ROS_DOMAIN_ID` (0 when unset).
    pub domain_id: u16,
    /// `ROS_LOCALHOST_ONLY=1` or `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`.
    pub localhost_only: bool,
    /// `XSURF_LATENCY_LOG`: a file that gets one line per message the host publishes,
    /// `topic stamp_ns published_ns` (wall clock; `published` is when the DDS write returned).
    /// Appended to, so that several processes can share it. For benchmarks.
    pub latency_log: Option<std::path::PathBuf>,
}

impl DdsEnv {
    /// Reads the environment (through `get`, so tests need not touch the process environment).
    pub fn from_env(get: impl Fn(&str) -> Option<String>) -> Result<DdsEnv, HostError> {
        let domain_id = match get("ROS_DOMAIN_ID").filter(|v| !v.trim().is_empty()) {
            None => 0,
            Some(v) => match v.trim().parse::<u16>() {
                Ok(d) if d <= 232 => d,
                _ => {
                    return Err(HostError::Env {
                        name: "ROS_DOMAIN_ID",
                        value: v,
                        reason: "must be an integer in 0..=232",
                    })
                }
            },
        };
        let localhost_only = get("ROS_LOCALHOST_ONLY").is_some_and(|v| v.trim() == "1")
            || get("ROS_AUTOMATIC_DISCOVERY_RANGE").is_some_and(|v| v.trim().eq_ignore_ascii_case("LOCALHOST"));
        let latency_log = get("XSURF_LATENCY_LOG").filter(|v| !v.trim().is_empty()).map(std::path::PathBuf::from);
        Ok(DdsEnv { domain_id, localhost_only, latency_log })
    }

    /// A ros2-client context for these settings.
    pub fn context(&self) -> Result<Context, HostError> {
        let mut b = DomainParticipantBuilder::new(self.domain_id);
        if self.localhost_only {
            b = b.with_only_networks([Ipv4Addr::LOCALHOST]);
        }
        let dp = b.build().map_err(|e| HostError::Dds(format!("participant for domain {}: {e:?}", self.domain_id)))?;
        Context::from_domain_participant(dp).map_err(|e| HostError::Dds(format!("context: {e:?}")))
    }
}

/// The QoS of a topic class.
pub fn qos(class: QosClass) -> QosProfile {
    let reliable = Reliability::Reliable { when_full: WhenFull::Wait(Duration::from_millis(100)) };
    let base = QosProfile::publisher_default();
    match class {
        QosClass::Sensor => base
            .reliability(Reliability::BestEffort)
            .history(History::KeepLast { depth: 5 })
            .durability(Durability::Volatile),
        QosClass::Reliable => {
            base.reliability(reliable).history(History::KeepLast { depth: 10 }).durability(Durability::Volatile)
        }
        QosClass::State => {
            base.reliability(reliable).history(History::KeepLast { depth: 1 }).durability(Durability::Volatile)
        }
        QosClass::Static => {
            base.reliability(reliable).history(History::KeepLast { depth: 1 }).durability(Durability::TransientLocal)
        }
    }
}

/// Converts our parameter value to ros2-client's.
pub fn to_ros(v: &ParamValue) -> RosValue {
    match v {
        ParamValue::Bool(b) => RosValue::Boolean(*b),
        ParamValue::Integer(i) => RosValue::Integer(*i),
        ParamValue::Double(d) => RosValue::Double(*d),
        ParamValue::String(s) => RosValue::String(s.clone()),
        ParamValue::BoolArray(a) => RosValue::BooleanArray(a.clone()),
        ParamValue::IntegerArray(a) => RosValue::IntegerArray(a.clone()),
        ParamValue::DoubleArray(a) => RosValue::DoubleArray(a.clone()),
        ParamValue::StringArray(a) => RosValue::StringArray(a.clone()),
    }
}

/// Converts ros2-client's parameter value to ours (`None` for unset and byte arrays).
pub fn from_ros(v: &RosValue) -> Option<ParamValue> {
    Some(match v {
        RosValue::Boolean(b) => ParamValue::Bool(*b),
        RosValue::Integer(i) => ParamValue::Integer(*i),
        RosValue::Double(d) => ParamValue::Double(*d),
        RosValue::String(s) => ParamValue::String(s.clone()),
        RosValue::BooleanArray(a) => ParamValue::BoolArray(a.clone()),
        RosValue::IntegerArray(a) => ParamValue::IntegerArray(a.clone()),
        RosValue::DoubleArray(a) => ParamValue::DoubleArray(a.clone()),
        RosValue::StringArray(a) => ParamValue::StringArray(a.clone()),
        RosValue::NotSet | RosValue::ByteArray(_) => return None,
    })
}

fn type_name(full: &str) -> Result<MessageTypeName, HostError> {
    let mut it = full.split('/');
    match (it.next(), it.next(), it.next()) {
        (Some(pkg), Some("msg"), Some(t)) => Ok(MessageTypeName::new(pkg, t)),
        _ => Err(HostError::Dds(format!("bad type name {full}"))),
    }
}

fn topic_name(full: &str) -> Result<Name, HostError> {
    Name::parse(full).map_err(|e| HostError::Dds(format!("topic name {full}: {e}")))
}

/// A typed publisher for one output.
enum Pub {
    Image(ros2_client::Publisher<Shared<Image>>),
    CompressedImage(ros2_client::Publisher<Shared<CompressedImage>>),
    CameraInfo(ros2_client::Publisher<Shared<CameraInfo>>),
    Tf(ros2_client::Publisher<Shared<TFMessage>>),
    LaserLine(ros2_client::Publisher<Shared<LaserLine>>),
    Cloud(ros2_client::Publisher<Shared<PointCloud2>>),
    Marker(ros2_client::Publisher<Shared<Marker>>),
    ScanEvent(ros2_client::Publisher<Shared<ScanEvent>>),
    JointState(ros2_client::Publisher<Shared<JointState>>),
    Clock(ros2_client::Publisher<Clock>),
    Text(ros2_client::Publisher<Shared<StringMsg>>),
}

/// A message as its node made it, shared (`Arc`) and serialized in place: publishing copies
/// none of it (a full body's mesh Marker is 44 MB, 20 ms to copy; a 1920x1200 image 2.3 MB
/// sixty times a second).
struct Shared<T>(Arc<T>);

/// Names the message's type only: a failed write's error (which carries the message) is logged,
/// and a whole image or mesh has no place in a log line.
impl<T> std::fmt::Debug for Shared<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "a {}", std::any::type_name::<T>())
    }
}

impl<T: serde::Serialize> serde::Serialize for Shared<T> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.0.serialize(s)
    }
}

impl Pub {
    /// The writer's id, as subscribers see it.
    fn gid(&self) -> ros2_client::Gid {
        match self {
            Pub::Image(p) => p.gid(),
            Pub::CompressedImage(p) => p.gid(),
            Pub::CameraInfo(p) => p.gid(),
            Pub::Tf(p) => p.gid(),
            Pub::LaserLine(p) => p.gid(),
            Pub::Cloud(p) => p.gid(),
            Pub::Marker(p) => p.gid(),
            Pub::ScanEvent(p) => p.gid(),
            Pub::JointState(p) => p.gid(),
            Pub::Clock(p) => p.gid(),
            Pub::Text(p) => p.gid(),
        }
    }
    fn publish(&self, m: &Msg) -> Result<(), String> {
        match (self, m) {
            (Pub::Image(p), Msg::Image(m)) => p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}")),
            (Pub::CompressedImage(p), Msg::CompressedImage(m)) => {
                p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}"))
            }
            (Pub::CameraInfo(p), Msg::CameraInfo(m)) => p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}")),
            (Pub::Tf(p), Msg::Tf(m)) => p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}")),
            (Pub::LaserLine(p), Msg::LaserLine(m)) => p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}")),
            (Pub::Cloud(p), Msg::Cloud(m)) => p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}")),
            (Pub::Marker(p), Msg::Marker(m)) => p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}")),
            (Pub::ScanEvent(p), Msg::ScanEvent(m)) => p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}")),
            (Pub::JointState(p), Msg::JointState(m)) => p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}")),
            (Pub::Clock(p), Msg::Clock(m)) => p.publish(**m).map_err(|e| format!("{e:?}")),
            (Pub::Text(p), Msg::Text(m)) => p.publish(Shared(m.clone())).map_err(|e| format!("{e:?}")),
            (_, m) => Err(format!("a {} does not fit this publisher", m.type_name())),
        }
    }
}

/// What the reader threads send to the node's loop.
enum Event {
    Message(usize, Msg),
    Clock(i64),
    Reconfigure(usize, String, ParamValue),
}

/// The node's DDS side: publishers by topic name (so other hosts, like bag play, can use it).
pub struct DdsNode {
    node: Node,
    pubs: Publishers,
}

impl DdsNode {
    /// Creates a publisher on `topic` for `type_name` with the class's QoS.
    pub fn add_publisher(&mut self, topic: &str, type_name_full: &str, class: QosClass) -> Result<(), HostError> {
        let p = self.make_publisher(topic, type_name_full, qos(class))?;
        self.pubs.0.push((topic.to_string(), p));
        Ok(())
    }

    fn make_publisher(&mut self, topic: &str, type_name_full: &str, profile: QosProfile) -> Result<Pub, HostError> {
        let t = self
            .node
            .create_topic(&topic_name(topic)?, type_name(type_name_full)?, &profile)
            .map_err(|e| HostError::Dds(format!("topic {topic}: {e:?}")))?;
        let q = Some(profile);
        let err = |e: ros2_client::CreateError| HostError::Dds(format!("publisher {topic}: {e:?}"));
        let p = match type_name_full {
            "sensor_msgs/msg/Image" => Pub::Image(self.node.create_publisher(&t, q).map_err(err)?),
            "sensor_msgs/msg/CompressedImage" => Pub::CompressedImage(self.node.create_publisher(&t, q).map_err(err)?),
            "sensor_msgs/msg/CameraInfo" => Pub::CameraInfo(self.node.create_publisher(&t, q).map_err(err)?),
            "tf2_msgs/msg/TFMessage" => Pub::Tf(self.node.create_publisher(&t, q).map_err(err)?),
            "xsurf_msgs/msg/LaserLine" => Pub::LaserLine(self.node.create_publisher(&t, q).map_err(err)?),
            "sensor_msgs/msg/PointCloud2" => Pub::Cloud(self.node.create_publisher(&t, q).map_err(err)?),
            "visualization_msgs/msg/Marker" => Pub::Marker(self.node.create_publisher(&t, q).map_err(err)?),
            "xsurf_msgs/msg/ScanEvent" => Pub::ScanEvent(self.node.create_publisher(&t, q).map_err(err)?),
            "sensor_msgs/msg/JointState" => Pub::JointState(self.node.create_publisher(&t, q).map_err(err)?),
            "rosgraph_msgs/msg/Clock" => Pub::Clock(self.node.create_publisher(&t, q).map_err(err)?),
            "std_msgs/msg/String" => Pub::Text(self.node.create_publisher(&t, q).map_err(err)?),
            other => return Err(HostError::Dds(format!("no publisher for type {other}"))),
        };
        Ok(p)
    }

    /// Publishes on a topic added with [`DdsNode::add_publisher`].
    pub fn publish(&self, topic: &str, m: &Msg) -> Result<(), String> {
        self.pubs.publish(topic, m)
    }

    /// The ros2-client node.
    pub fn node(&mut self) -> &mut Node {
        &mut self.node
    }
}

/// Starts a subscription whose messages go to `tx` as input `index`.
#[allow(clippy::too_many_arguments)]
fn subscribe(
    node: &mut Node,
    topic: &str,
    type_full: &str,
    profile: QosProfile,
    droppable: bool,
    index: usize,
    feed: Feed,
    ignore: Arc<Vec<ros2_client::Gid>>,
) -> Result<(), HostError> {
    let Feed { tx, dropped, stop } = feed;
    let t = node
        .create_topic(&topic_name(topic)?, type_name(type_full)?, &profile)
        .map_err(|e| HostError::Dds(format!("topic {topic}: {e:?}")))?;
    let q = Some(profile);
    let topic_s = topic.to_string();
    macro_rules! spawn_reader {
        ($ty:ty, $wrap:expr) => {{
            let sub = node
                .create_subscription::<$ty>(&t, q)
                .map_err(|e| HostError::Dds(format!("subscription {topic}: {e:?}")))?;
            std::thread::Builder::new()
                .name(format!("sub {topic_s}"))
                .spawn(move || {
                    futures::executor::block_on(async {
                        let mut s = std::pin::pin!(sub.async_stream());
                        while let Some(r) = s.next().await {
                            if stop.load(Ordering::Relaxed) {
                                break;
                            }
                            match r {
                                // This process's own publications are delivered in memory.
                                Ok((_, info)) if ignore.contains(&info.publisher_gid()) => {}
                                Ok((m, _info)) => {
                                    let ev = $wrap(m);
                                    if droppable {
                                        match tx.try_send(ev) {
                                            Ok(()) => {}
                                            Err(TrySendError::Full(_)) => {
                                                let n = dropped.fetch_add(1, Ordering::Relaxed) + 1;
                                                if n.is_power_of_two() {
                                                    log::warn!("{topic_s}: node busy, {n} message(s) dropped so far");
                                                }
                                            }
                                            Err(TrySendError::Disconnected(_)) => break,
                                        }
                                    } else if tx.send(ev).is_err() {
                                        break;
                                    }
                                }
                                Err(e) => log::warn!("{topic_s}: read error {e:?}"),
                            }
                        }
                    })
                })
                .map_err(|e| HostError::Dds(format!("thread: {e}")))?;
        }};
    }
    match type_full {
        "sensor_msgs/msg/Image" => spawn_reader!(Image, |m| Event::Message(index, Msg::Image(Arc::new(m)))),
        "sensor_msgs/msg/CompressedImage" => {
            spawn_reader!(CompressedImage, |m| Event::Message(index, Msg::CompressedImage(Arc::new(m))))
        }
        "sensor_msgs/msg/CameraInfo" => {
            spawn_reader!(CameraInfo, |m| Event::Message(index, Msg::CameraInfo(Arc::new(m))))
        }
        "tf2_msgs/msg/TFMessage" => spawn_reader!(TFMessage, |m| Event::Message(index, Msg::Tf(Arc::new(m)))),
        "xsurf_msgs/msg/LaserLine" => spawn_reader!(LaserLine, |m| Event::Message(index, Msg::LaserLine(Arc::new(m)))),
        "sensor_msgs/msg/PointCloud2" => spawn_reader!(PointCloud2, |m| Event::Message(index, Msg::Cloud(Arc::new(m)))),
        "visualization_msgs/msg/Marker" => spawn_reader!(Marker, |m| Event::Message(index, Msg::Marker(Arc::new(m)))),
        "xsurf_msgs/msg/ScanEvent" => spawn_reader!(ScanEvent, |m| Event::Message(index, Msg::ScanEvent(Arc::new(m)))),
        "sensor_msgs/msg/JointState" => {
            spawn_reader!(JointState, |m| Event::Message(index, Msg::JointState(Arc::new(m))))
        }
        "rosgraph_msgs/msg/Clock" => spawn_reader!(Clock, |m: Clock| Event::Clock(m.clock.nanos())),
        "std_msgs/msg/String" => spawn_reader!(StringMsg, |m| Event::Message(index, Msg::Text(Arc::new(m)))),
        other => return Err(HostError::Dds(format!("no subscription for type {other}"))),
    }
    Ok(())
}

/// Subscribes `topic` on `node`, handing every message to `tx` as `(index, message)`. Camera
/// streams (`class` Sensor) are dropped and counted when `tx` is full; others wait.
pub fn subscribe_forward(
    node: &mut DdsNode,
    topic: &str,
    type_name_full: &str,
    class: QosClass,
    index: usize,
    tx: SyncSender<(usize, Msg)>,
    stop: Arc<AtomicBool>,
) -> Result<Arc<AtomicU64>, HostError> {
    let (etx, erx) = sync_channel::<Event>(QUEUE_DEPTH);
    let dropped = Arc::new(AtomicU64::new(0));
    let feed = Feed { tx: etx, dropped: dropped.clone(), stop };
    subscribe(node.node(), topic, type_name_full, qos(class), class == QosClass::Sensor, index, feed, Arc::default())?;
    std::thread::Builder::new()
        .name(format!("sub {topic}"))
        .spawn(move || {
            while let Ok(ev) = erx.recv() {
                if let Event::Message(i, m) = ev {
                    if tx.send((i, m)).is_err() {
                        break;
                    }
                }
            }
        })
        .map_err(|e| HostError::Dds(format!("thread: {e}")))?;
    Ok(dropped)
}

/// The topics the participant has discovered, as (`/name`, `pkg/msg/Type`).
pub fn discovered_topics(ctx: &Context) -> Vec<(String, String)> {
    ctx.discovered_topics()
        .into_iter()
        .filter_map(|t| {
            let mut it = t.type_name.split("::");
            let (pkg, msg, dds, ty) = (it.next()?, it.next()?, it.next()?, it.next()?);
            // ROS topics are DDS topics `rt/...`; services (`rq/`, `rr/`) and others are skipped.
            let name = match t.name.strip_prefix("rt/") {
                Some(rest) => format!("/{rest}"),
                None if t.name.starts_with('/') => t.name.clone(),
                None => return None,
            };
            (msg == "msg" && dds == "dds_").then(|| (name, format!("{pkg}/msg/{}", ty.trim_end_matches('_'))))
        })
        .collect()
}

/// Checks a full set of parameter values (the component's own config conversion).
pub type Validator = Arc<dyn Fn(&Params) -> Result<(), String> + Send + Sync>;

/// Where a subscription's reader thread delivers.
#[derive(Clone)]
struct Feed {
    tx: SyncSender<Event>,
    dropped: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
}

/// Everything needed to host a component.
pub struct HostConfig {
    /// Node name.
    pub name: String,
    /// Namespace.
    pub namespace: String,
    /// Remapping rules.
    pub remaps: Vec<Remap>,
    /// Declarations (for the parameter services).
    pub decls: Vec<ParamDecl>,
    /// Resolved parameter values.
    pub params: Params,
    /// Validates a full set of values (the component's own config conversion).
    pub validate: Validator,
    /// Publish log records on `/rosout`.
    pub rosout: bool,
    /// How often `tick` runs.
    pub tick_period: Duration,
}

/// A node with no parameters of its own, for tools (`bag play`, `bag record`).
pub fn tool_node(ctx: &Context, name: &str) -> Result<DdsNode, HostError> {
    let cfg = HostConfig {
        name: name.to_string(),
        namespace: "/".into(),
        remaps: vec![],
        decls: vec![],
        params: Params::default(),
        validate: Arc::new(|_| Ok(())),
        rosout: false,
        tick_period: Duration::from_millis(50),
    };
    create_node(ctx, &cfg, None)
}

/// Creates the node (parameters declared, services on, `/rosout`) in `ctx`.
pub fn create_node(
    ctx: &Context,
    cfg: &HostConfig,
    tx: Option<SyncSender<(String, ParamValue)>>,
) -> Result<DdsNode, HostError> {
    let mut opts =
        NodeOptions::new().enable_rosout(cfg.rosout).start_parameter_services(true).allow_undeclared_parameters(false);
    let mut declared: Vec<String> = Vec::new();
    for d in &cfg.decls {
        let v = cfg.params.get(d.name).unwrap_or(&d.default);
        opts = opts.declare_parameter(d.name, to_ros(v));
        declared.push(d.name.to_string());
    }
    let use_sim = cfg.params.get("use_sim_time").cloned().unwrap_or(ParamValue::Bool(false));
    if !declared.iter().any(|d| d == "use_sim_time") {
        opts = opts.declare_parameter("use_sim_time", to_ros(&use_sim));
    }
    let shared = Arc::new(Mutex::new(cfg.params.clone()));
    let decls = cfg.decls.clone();
    let validate = cfg.validate.clone();
    let v_shared = shared.clone();
    let set_decls = cfg.decls.clone();
    opts = opts.parameter_validator(Box::new(move |name, value| {
        let v = from_ros(value).ok_or_else(|| format!("parameter {name}: unsupported value {value:?}"))?;
        let mut p = v_shared.lock().map_err(|_| "parameter store poisoned".to_string())?.clone();
        // ros2-client also validates the declared values at start-up: those are the current ones.
        if (name == "use_sim_time" || name.starts_with("qos.")) && p.get(name).is_some_and(|cur| *cur != v) {
            return Err(format!("{name} is read at start-up; restart the node to change it"));
        }
        p.set(&decls, name, v).map_err(|e| e.to_string())?;
        validate(&p)
    }));
    opts = opts.parameter_set_action(Box::new(move |name, value| {
        if let (Some(v), Some(tx)) = (from_ros(value), tx.as_ref()) {
            let changed = match shared.lock() {
                Ok(mut p) => {
                    // ros2-client sets every declared parameter once at start-up, to the value
                    // it already has: that is no reconfiguration (a node rebuilt per parameter).
                    let current = |p: &Params| {
                        p.get(name)
                            .cloned()
                            .or_else(|| set_decls.iter().find(|d| d.name == name).map(|d| d.default.clone()))
                    };
                    let before = current(&p);
                    // Validated just before by the validator; keep the store in step for the next one.
                    let _ = p.set(&set_decls, name, v.clone());
                    before != current(&p)
                }
                Err(_) => true,
            };
            if changed {
                let _ = tx.try_send((name.to_string(), v));
            }
        }
        Ok(())
    }));
    let node_name = NodeName::new(&cfg.namespace, &cfg.name)
        .map_err(|e| HostError::Dds(format!("node name {}/{}: {e:?}", cfg.namespace, cfg.name)))?;
    let node = ctx.new_node(node_name, opts).map_err(|e| HostError::Dds(format!("node: {e:?}")))?;
    Ok(DdsNode { node, pubs: Publishers::default() })
}

crate::choice! {
    /// A topic class's reliability (the `qos.*.reliability` parameters).
    pub enum ReliabilityParam {
        /// Lost samples are resent.
        Reliable = "reliable",
        /// Lost samples stay lost.
        BestEffort = "best_effort",
    }
}

crate::parameters! {
    /// The host's own parameters, declared on every node: QoS by topic class, read at start-up.
    pub struct HostParams {
        /// take time from `/clock` (`rosgraph_msgs/msg/Clock`), read at start-up
        use_sim_time: bool = false;
        /// camera streams: best_effort or reliable (read at start-up)
        qos_sensor_reliability ["qos.sensor.reliability"]: ReliabilityParam = ReliabilityParam::BestEffort, via Choice;
        /// camera streams: history depth (read at start-up)
        qos_sensor_depth ["qos.sensor.depth"]: usize = 5, unit "messages", range 1..=1000;
        /// lines, profiles, events, reports, /tf: reliable or best_effort (read at start-up)
        qos_reliable_reliability ["qos.reliable.reliability"]: ReliabilityParam = ReliabilityParam::Reliable, via Choice;
        /// lines, profiles, events, reports, /tf: history depth (read at start-up)
        qos_reliable_depth ["qos.reliable.depth"]: usize = 10, unit "messages", range 1..=1000;
        /// clouds, meshes, overlay (each supersedes the last): reliable or best_effort (read at start-up)
        qos_state_reliability ["qos.state.reliability"]: ReliabilityParam = ReliabilityParam::Reliable, via Choice;
        /// clouds, meshes, overlay: history depth (read at start-up)
        qos_state_depth ["qos.state.depth"]: usize = 1, unit "messages", range 1..=1000;
    }
}

/// The host's own parameters, declared on every node.
pub fn host_declarations() -> Vec<ParamDecl> {
    HostParams::declarations()
}

/// QoS per class after the `qos.*` parameters.
#[derive(Debug, Clone)]
pub struct QosTable {
    sensor: QosProfile,
    reliable: QosProfile,
    state: QosProfile,
}

impl QosTable {
    /// From a node's parameters (missing values keep the defaults).
    pub fn from_params(p: &Params) -> Result<QosTable, String> {
        let decls = HostParams::declarations();
        let given = p.iter().filter(|(n, _)| decls.iter().any(|d| d.name == n.as_str()));
        let p = Params::resolve(&decls, &given.map(|(n, v)| (n.clone(), v.clone())).collect())
            .and_then(|p| HostParams::from_params(&p))
            .map_err(|e| e.to_string())?;
        let class = |base: QosProfile, r: ReliabilityParam, depth: usize| {
            base.reliability(match r {
                ReliabilityParam::Reliable => {
                    Reliability::Reliable { when_full: WhenFull::Wait(Duration::from_millis(100)) }
                }
                ReliabilityParam::BestEffort => Reliability::BestEffort,
            })
            .history(History::KeepLast { depth })
        };
        Ok(QosTable {
            sensor: class(qos(QosClass::Sensor), p.qos_sensor_reliability, p.qos_sensor_depth),
            reliable: class(qos(QosClass::Reliable), p.qos_reliable_reliability, p.qos_reliable_depth),
            state: class(qos(QosClass::State), p.qos_state_reliability, p.qos_state_depth),
        })
    }
    /// The profile of a class.
    pub fn get(&self, c: QosClass) -> QosProfile {
        match c {
            QosClass::Sensor => self.sensor.clone(),
            QosClass::Reliable => self.reliable.clone(),
            QosClass::State => self.state.clone(),
            QosClass::Static => qos(QosClass::Static),
        }
    }
}

/// Runs one component as a node until SIGINT/SIGTERM. Returns the number of refused messages.
pub fn run(env: &DdsEnv, cfg: HostConfig, component: Box<dyn AnyComponent>) -> Result<u64, HostError> {
    run_graph(env, vec![(cfg, component)])
}

/// Runs several components in one process until SIGINT/SIGTERM: each on a thread of its own,
/// connected in memory ([`Threads`](crate::threads::Threads)), each with its own ROS 2 node
/// (name, parameters, services), every output also published on DDS for outside observers, and
/// DDS subscriptions for the topics no component of the process publishes (and for the shared
/// ones: tf, scan events). Returns the number of refused messages.
pub fn run_graph(env: &DdsEnv, nodes: Vec<(HostConfig, Box<dyn AnyComponent>)>) -> Result<u64, HostError> {
    let ctx = env.context()?;
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = sync_channel::<Event>(QUEUE_DEPTH);
    let dropped = Arc::new(AtomicU64::new(0));
    let feed = Feed { tx: tx.clone(), dropped: dropped.clone(), stop: stop.clone() };
    let Placement { router, mut dds_nodes, mut configs, qos, sim_time } = place_nodes(&ctx, nodes, &tx)?;
    let (pubs, sensor_topics) = make_publishers(&router, &mut dds_nodes, &qos)?;
    let externals = subscribe_externals(&router, &mut dds_nodes, &qos, &pubs, &feed)?;
    let _clock = if sim_time { Some(clock_subscription(env, &feed)?) } else { None };
    drop(tx);
    drop(feed);
    let pub_errors = Arc::new(AtomicU64::new(0));
    let latency_log = match &env.latency_log {
        Some(path) => Some(Arc::new(
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(path)
                .map_err(|e| HostError::Dds(format!("XSURF_LATENCY_LOG {}: {e}", path.display())))?,
        )),
        None => None,
    };
    // The outputs of bulk nodes (clouds, meshes) are serialized at their nodes' lower priority.
    let bulk_topics: Vec<String> = router
        .nodes()
        .iter()
        .filter(|n| n.component.bulk())
        .flat_map(|n| n.outputs.iter().map(|(_, t)| t.clone()))
        .collect();
    let publishers = PublishThreads::start(pubs, &sensor_topics, &bulk_topics, pub_errors.clone(), latency_log)?;
    let tap = publish_tap(&publishers, &pub_errors);
    start_spinners(&mut dds_nodes)?;
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .map_err(|e| HostError::Dds(format!("signal handler: {e}")))?;
    }
    let node_count = router.nodes().len();
    let ticks: Vec<Duration> = configs.iter().map(|c| c.0.tick_period).collect();
    let started = std::time::Instant::now();
    let graph = crate::threads::Threads::start(router, tap, &ticks, sim_time)
        .map_err(|e| HostError::Dds(format!("thread: {e}")))?;
    log::info!(
        "{} node(s) running, a thread each (domain {}, {})",
        node_count,
        env.domain_id,
        if env.localhost_only { "localhost only" } else { "all interfaces" }
    );
    let died = serve(&graph, &rx, &externals, &mut configs, &stop);
    log::info!("shutting down");
    stop.store(true, Ordering::SeqCst);
    let d = dropped.load(Ordering::Relaxed) + graph.dropped();
    let overflowed = graph.overflowed();
    let nodes = graph.finish();
    if d > 0 {
        log::warn!("{d} camera message(s) dropped while a node was busy");
    }
    if overflowed > 0 {
        log::error!("{overflowed} message(s) dropped because a node's inbox stayed full");
    }
    // The last outputs leave through the publisher threads before the count.
    publishers.join();
    let errors = pub_errors.load(Ordering::Relaxed) + log_node_figures(&nodes, started.elapsed().as_secs_f64());
    // Give reliable writers a moment to deliver the last output, then leave the graph.
    std::thread::sleep(Duration::from_millis(200));
    // Dropping a node stops its spinner (ros2-client's Drop signals it; signalling it first
    // by hand as well filled the one-slot channel, and the Drop then logged an error).
    drop(nodes);
    drop(dds_nodes);
    drop(ctx);
    if let Some(name) = died {
        return Err(HostError::NodeDied(name));
    }
    Ok(errors)
}

/// The components placed in a router, each with its DDS node (parameters, services, rosout)
/// and its resolved parameters.
struct Placement {
    router: crate::router::Router,
    dds_nodes: Vec<DdsNode>,
    configs: Vec<(HostConfig, Params)>,
    /// Each node's QoS by topic class (its `qos.*` parameters).
    qos: Vec<QosTable>,
    /// Some node takes its time from `/clock`.
    sim_time: bool,
}

/// Creates each component's DDS node; the first node's log also goes to `/rosout`; run-time
/// parameter sets are forwarded into the host's loop as [`Event::Reconfigure`].
fn place_nodes(
    ctx: &Context,
    nodes: Vec<(HostConfig, Box<dyn AnyComponent>)>,
    tx: &SyncSender<Event>,
) -> Result<Placement, HostError> {
    let mut p = Placement {
        router: crate::router::Router::new(),
        dds_nodes: Vec::new(),
        configs: Vec::new(),
        qos: Vec::new(),
        sim_time: false,
    };
    for (i, (cfg, component)) in nodes.into_iter().enumerate() {
        let (ptx, prx) = sync_channel::<(String, ParamValue)>(16);
        let dn = create_node(ctx, &cfg, Some(ptx))?;
        if cfg.rosout && i == 0 {
            let h = dn.node.logging_handle();
            let name = crate::rosargs::fq_name(&cfg.namespace, &cfg.name).trim_start_matches('/').replace('/', ".");
            crate::logging::set_rosout(Box::new(move |level, _target, msg| {
                use ros2_client::rosout::RosoutRaw;
                let lvl = match level {
                    log::Level::Error => ros2_client::log::LogLevel::Error,
                    log::Level::Warn => ros2_client::log::LogLevel::Warn,
                    log::Level::Info => ros2_client::log::LogLevel::Info,
                    _ => ros2_client::log::LogLevel::Debug,
                };
                h.rosout_raw(ros2_client::builtin_interfaces::Time::now(), lvl, &name, msg, "", "", 0);
            }));
        }
        // Parameter set actions of node i, forwarded into the loop.
        let tx2 = tx.clone();
        std::thread::Builder::new()
            .name(format!("params {}", cfg.name))
            .spawn(move || {
                while let Ok((n, v)) = prx.recv() {
                    if tx2.send(Event::Reconfigure(i, n, v)).is_err() {
                        break;
                    }
                }
            })
            .map_err(|e| HostError::Dds(format!("thread: {e}")))?;
        p.sim_time |= matches!(cfg.params.get("use_sim_time"), Some(ParamValue::Bool(true)));
        p.qos.push(QosTable::from_params(&cfg.params).map_err(HostError::Dds)?);
        p.router.add(component, &cfg.name, &cfg.namespace, &cfg.remaps);
        let params = cfg.params.clone();
        p.configs.push((cfg, params));
        p.dds_nodes.push(dn);
    }
    if p.dds_nodes.is_empty() {
        return Err(HostError::Dds("no node to run".into()));
    }
    Ok(p)
}

/// A publisher for every output, on the node that produces it; and the camera streams among
/// them.
fn make_publishers(
    router: &crate::router::Router,
    dds_nodes: &mut [DdsNode],
    qos: &[QosTable],
) -> Result<(Publishers, Vec<String>), HostError> {
    let mut pubs = Publishers::default();
    let mut sensor_topics = Vec::new();
    for (ni, n) in router.nodes().iter().enumerate() {
        let table = &qos[ni];
        for (p, topic) in &n.outputs {
            if !pubs.has(topic) {
                let pb = dds_nodes[ni].make_publisher(topic, p.type_name, table.get(p.qos))?;
                pubs.0.push((topic.clone(), pb));
                if p.qos == QosClass::Sensor {
                    sensor_topics.push(topic.clone());
                }
                log::info!("{}: publishes {topic} ({})", n.name, p.type_name);
            }
        }
    }
    Ok((pubs, sensor_topics))
}

/// A topic subscribed over DDS: its name, its port, and the process's own writers on it (whose
/// samples were delivered in memory already).
type External = (String, Port, Arc<Vec<ros2_client::Gid>>);

/// DDS subscriptions for what comes from outside the process: topics no node here publishes,
/// and the shared ones (tf, scan events) that others may publish too. Each is made on the
/// first node that takes it; its samples reach the loop as [`Event::Message`] with its index.
fn subscribe_externals(
    router: &crate::router::Router,
    dds_nodes: &mut [DdsNode],
    qos: &[QosTable],
    pubs: &Publishers,
    feed: &Feed,
) -> Result<Vec<External>, HostError> {
    let mut externals: Vec<External> =
        router.external_inputs().into_iter().map(|(t, p)| (t, p, Arc::default())).collect();
    for (topic, p) in router.shared_inputs() {
        let own: Vec<ros2_client::Gid> = pubs.0.iter().filter(|(t, _)| *t == topic).map(|(_, pb)| pb.gid()).collect();
        externals.push((topic, p, Arc::new(own)));
    }
    for (k, (topic, p, ignore)) in externals.iter().enumerate() {
        let ni = router.nodes().iter().position(|n| n.inputs.iter().any(|(_, t)| t == topic)).unwrap_or(0);
        let table = &qos[ni];
        subscribe(
            dds_nodes[ni].node(),
            topic,
            p.type_name,
            table.get(p.qos),
            p.qos == QosClass::Sensor,
            k,
            feed.clone(),
            ignore.clone(),
        )?;
        log::info!("{}: subscribed {topic} ({})", router.nodes()[ni].name, p.type_name);
    }
    Ok(externals)
}

/// `/clock` through a participant of its own, whose node never spins: ros2-client's spinner
/// subscribes `/clock` itself, typed builtin_interfaces/Time (not rosgraph_msgs/Clock as ROS 2
/// has it); two types on one topic in one participant make RustDDS drop the topic.
fn clock_subscription(env: &DdsEnv, feed: &Feed) -> Result<(Context, Node), HostError> {
    let cctx = env.context()?;
    let name = NodeName::new("/", "_xsurf_clock").map_err(|e| HostError::Dds(format!("clock node: {e:?}")))?;
    let mut cnode = cctx
        .new_node(name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| HostError::Dds(format!("clock node: {e:?}")))?;
    // Best effort, as rclcpp's ClockQoS: it matches reliable and best-effort publishers.
    subscribe(
        &mut cnode,
        "/clock",
        "rosgraph_msgs/msg/Clock",
        qos(QosClass::Sensor),
        false,
        usize::MAX,
        feed.clone(),
        Arc::default(),
    )?;
    Ok((cctx, cnode))
}

/// What the executor calls for every message a node publishes: hand it to the topic's publisher
/// thread (a camera stream whose thread is behind drops it; others wait); failures are counted
/// and logged (the first five, then at powers of two).
fn publish_tap(publishers: &PublishThreads, pub_errors: &Arc<AtomicU64>) -> crate::threads::SharedTap {
    let pub_errors = pub_errors.clone();
    let senders = publishers.senders.clone();
    Arc::new(move |topic: &str, m: &Msg| {
        let Some((_, tx, droppable)) = senders.iter().find(|(t, _, _)| t == topic) else {
            log::error!("no publisher on {topic}");
            return;
        };
        let sent = if *droppable {
            match tx.try_send(m.clone()) {
                Err(TrySendError::Full(_)) => Err("its publisher is behind: dropped".to_string()),
                r => r.map_err(|e| e.to_string()),
            }
        } else {
            tx.send(m.clone()).map_err(|e| e.to_string())
        };
        if let Err(e) = sent {
            let n = pub_errors.fetch_add(1, Ordering::Relaxed) + 1;
            if n <= 5 || n.is_power_of_two() {
                log::warn!("publish on {topic} failed ({n} so far): {e}");
            }
        }
    })
}

/// One spinner thread per node: its parameter services.
fn start_spinners(dds_nodes: &mut [DdsNode]) -> Result<(), HostError> {
    for dn in dds_nodes {
        let spinner = dn.node.spinner().map_err(|e| HostError::Dds(format!("spinner: {e:?}")))?;
        std::thread::Builder::new()
            .name("spinner".into())
            .spawn(move || {
                if let Err(e) = futures::executor::block_on(spinner.spin()) {
                    log::error!("parameter services stopped: {e:?}");
                }
            })
            .map_err(|e| HostError::Dds(format!("thread: {e}")))?;
    }
    Ok(())
}

/// The host's loop until a stop (SIGINT/SIGTERM) or a node dies (named in the result): DDS
/// samples into the graph, `/clock`, run-time parameter sets.
fn serve(
    graph: &crate::threads::Threads,
    rx: &Receiver<Event>,
    externals: &[External],
    configs: &mut [(HostConfig, Params)],
    stop: &AtomicBool,
) -> Option<String> {
    while !stop.load(Ordering::SeqCst) {
        if let Some(name) = graph.dead_node() {
            log::error!("{name} stopped unexpectedly; shutting the process down");
            return Some(name);
        }
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(Event::Message(k, m)) => {
                if let Some((topic, _, _)) = externals.get(k) {
                    graph.publish(topic, &m);
                }
            }
            Ok(Event::Clock(t)) => graph.clock(t),
            Ok(Event::Reconfigure(ni, name, v)) => {
                let Some((cfg, params)) = configs.get_mut(ni) else { continue };
                if params.set(&cfg.decls, &name, v).is_ok() {
                    graph.reconfigure(ni, params, &name);
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    None
}

/// Logs each node's figures at shutdown (messages, busy share, counters, refusals); returns the
/// messages refused in all.
fn log_node_figures(nodes: &[crate::router::Placed], ran_s: f64) -> u64 {
    let ran = ran_s.max(1e-9);
    let mut errors = 0;
    for n in nodes {
        errors += n.errors;
        // Time in the component's own code (not DDS, not serialization): per-node CPU when
        // several share a process.
        log::info!(
            "{}: handled {} message(s), busy {:.1} % of a core over {ran:.1} s",
            n.fq_name(),
            n.handled,
            100.0 * n.busy_ns as f64 * 1e-9 / ran
        );
        for (k, v) in n.component.counters() {
            log::info!("{}: {k} = {v}", n.fq_name());
        }
        if n.errors > 0 {
            log::warn!(
                "{}: {} message(s) refused, last: {}",
                n.fq_name(),
                n.errors,
                n.last_error.as_deref().unwrap_or("")
            );
        }
    }
    errors
}

/// Publishers by topic.
#[derive(Default)]
struct Publishers(Vec<(String, Pub)>);

/// One thread per published topic, so that serializing and sending a large message (a growing
/// cloud, a mesh, an image) never holds up the graph's loop nor another topic; each topic keeps
/// its order. A camera stream (sensor QoS) whose thread falls behind drops the message (counted
/// as a publish error, as best effort would); any other topic waits for its thread.
struct PublishThreads {
    /// `(topic, sender, droppable)`.
    senders: Arc<Vec<(String, SyncSender<Msg>, bool)>>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

/// Messages queued per topic before a camera stream drops or another topic waits.
const PUBLISH_QUEUE: usize = 8;

impl PublishThreads {
    fn start(
        pubs: Publishers,
        sensor_topics: &[String],
        bulk_topics: &[String],
        errors: Arc<AtomicU64>,
        latency_log: Option<Arc<std::fs::File>>,
    ) -> Result<Self, HostError> {
        let mut senders = Vec::new();
        let mut threads = Vec::new();
        for (topic, pb) in pubs.0 {
            let (tx, rx) = sync_channel::<Msg>(PUBLISH_QUEUE);
            let errors = errors.clone();
            let name = topic.clone();
            let latency_log = latency_log.clone();
            let bulk = bulk_topics.contains(&topic);
            threads.push(
                std::thread::Builder::new()
                    .name(format!("pub {topic}"))
                    .spawn(move || {
                        if bulk {
                            crate::threads::lower_this_thread();
                        }
                        while let Ok(m) = rx.recv() {
                            if let Err(e) = pb.publish(&m) {
                                let n = errors.fetch_add(1, Ordering::Relaxed) + 1;
                                if n <= 5 || n.is_power_of_two() {
                                    log::warn!("publish on {name} failed ({n} so far): {e}");
                                }
                            } else if let (Some(file), Some(stamp)) = (&latency_log, m.stamp_ns()) {
                                log_latency(file, &name, stamp);
                            }
                        }
                    })
                    .map_err(|e| HostError::Dds(format!("thread: {e}")))?,
            );
            let droppable = sensor_topics.contains(&topic);
            senders.push((topic, tx, droppable));
        }
        Ok(Self { senders: Arc::new(senders), threads })
    }

    /// Waits for every queued message to be published (the senders must be gone: the tap
    /// replaced).
    fn join(self) {
        drop(self.senders);
        for t in self.threads {
            let _ = t.join();
        }
    }
}

/// Appends `topic stamp_ns now_ns` to the latency log in one write (appends of one short line
/// from several threads or processes do not interleave). A failed write is ignored: the log is
/// a measurement, not the node's output.
fn log_latency(mut file: &std::fs::File, topic: &str, stamp_ns: i64) {
    use std::io::Write;
    let _ = file.write_all(format!("{topic} {stamp_ns} {}\n", crate::wall_clock_ns()).as_bytes());
}

impl Publishers {
    fn has(&self, topic: &str) -> bool {
        self.0.iter().any(|(t, _)| t == topic)
    }
    fn publish(&self, topic: &str, m: &Msg) -> Result<(), String> {
        let p = self.0.iter().find(|(t, _)| t == topic).ok_or_else(|| format!("no publisher on {topic}"))?;
        p.1.publish(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros_environment() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |k: &str| pairs.iter().find(|p| p.0 == k).map(|p| p.1.to_string())
        };
        assert_eq!(
            DdsEnv::from_env(env(&[])).unwrap(),
            DdsEnv { domain_id: 0, localhost_only: false, latency_log: None }
        );
        assert_eq!(
            DdsEnv::from_env(env(&[("ROS_DOMAIN_ID", "42"), ("ROS_LOCALHOST_ONLY", "1")])).unwrap(),
            DdsEnv { domain_id: 42, localhost_only: true, latency_log: None }
        );
        assert!(DdsEnv::from_env(env(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")])).unwrap().localhost_only);
        assert!(DdsEnv::from_env(env(&[("ROS_DOMAIN_ID", "300")])).is_err());
        assert!(DdsEnv::from_env(env(&[("ROS_DOMAIN_ID", "x")])).unwrap_err().to_string().contains("ROS_DOMAIN_ID"));
    }

    #[test]
    fn parameter_values_convert_both_ways() {
        for v in [
            ParamValue::Bool(true),
            ParamValue::Integer(3),
            ParamValue::Double(0.5),
            ParamValue::String("a".into()),
            ParamValue::DoubleArray(vec![1.0]),
            ParamValue::StringArray(vec!["x".into()]),
        ] {
            assert_eq!(from_ros(&to_ros(&v)), Some(v));
        }
    }
}
