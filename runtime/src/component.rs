//! The transport-agnostic node: messages in, messages out, typed config from parameters.
//! The same component runs alone over DDS, composed in one process, or driven from a bag.

use crate::params::{ParamError, Params};
use std::sync::Arc;
use xsurf_msgs::{
    cdr, rosgraph_msgs::Clock, sensor_msgs::CameraInfo, sensor_msgs::CompressedImage, sensor_msgs::Image,
    sensor_msgs::JointState, sensor_msgs::PointCloud2, std_msgs::StringMsg, tf2_msgs::TFMessage,
    visualization_msgs::Marker, xsurf_msgs::LaserLine, xsurf_msgs::ScanEvent, RosMessage,
};

/// A message on a topic; shared so that fan-out copies nothing.
#[derive(Debug, Clone)]
pub enum Msg {
    /// `sensor_msgs/msg/Image`.
    Image(Arc<Image>),
    /// `sensor_msgs/msg/CompressedImage` (image_transport's `compressed` plugin).
    CompressedImage(Arc<CompressedImage>),
    /// `sensor_msgs/msg/CameraInfo`.
    CameraInfo(Arc<CameraInfo>),
    /// `tf2_msgs/msg/TFMessage` (on `/tf` or `/tf_static`).
    Tf(Arc<TFMessage>),
    /// `xsurf_msgs/msg/LaserLine`.
    LaserLine(Arc<LaserLine>),
    /// `sensor_msgs/msg/PointCloud2`.
    Cloud(Arc<PointCloud2>),
    /// `visualization_msgs/msg/Marker`.
    Marker(Arc<Marker>),
    /// `xsurf_msgs/msg/ScanEvent`.
    ScanEvent(Arc<ScanEvent>),
    /// `sensor_msgs/msg/JointState`.
    JointState(Arc<JointState>),
    /// `rosgraph_msgs/msg/Clock`.
    Clock(Arc<Clock>),
    /// `std_msgs/msg/String` (the scan reports on `/scan/report`, JSON).
    Text(Arc<StringMsg>),
}

/// Why bytes could not become a [`Msg`].
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// A type this graph does not carry.
    #[error("unknown message type {0}")]
    UnknownType(String),
    /// Bad CDR.
    #[error("{type_name}: {source}")]
    Cdr {
        /// The type.
        type_name: String,
        /// The cause.
        source: cdr::CdrError,
    },
}

macro_rules! msg_types {
    ($($variant:ident => $t:ty),* $(,)?) => {
        impl Msg {
            /// The ROS 2 type name.
            pub fn type_name(&self) -> &'static str {
                match self { $(Msg::$variant(_) => <$t>::TYPE_NAME,)* }
            }
            /// CDR bytes with the encapsulation header.
            pub fn encode(&self) -> Result<Vec<u8>, cdr::CdrError> {
                match self { $(Msg::$variant(m) => cdr::encode(m.as_ref()),)* }
            }
            /// Decodes CDR bytes of the named type.
            pub fn decode(type_name: &str, bytes: &[u8]) -> Result<Msg, DecodeError> {
                $(if type_name == <$t>::TYPE_NAME {
                    return cdr::decode::<$t>(bytes)
                        .map(|m| Msg::$variant(Arc::new(m)))
                        .map_err(|source| DecodeError::Cdr { type_name: type_name.into(), source });
                })*
                Err(DecodeError::UnknownType(type_name.to_string()))
            }
            /// The `.msg` definition with dependencies, for bags.
            pub fn definition(type_name: &str) -> Option<String> {
                $(if type_name == <$t>::TYPE_NAME { return Some(<$t>::definition()); })*
                None
            }
            /// The message's stamp (ns since the epoch): its header's, a tf message's first
            /// transform's; `None` for a clock or an empty tf message.
            pub fn stamp_ns(&self) -> Option<i64> {
                match self {
                    Msg::Tf(m) => m.transforms.first().map(|t| t.header.stamp.nanos()),
                    Msg::Clock(_) | Msg::Text(_) => None,
                    Msg::Image(m) => Some(m.header.stamp.nanos()),
                    Msg::CompressedImage(m) => Some(m.header.stamp.nanos()),
                    Msg::CameraInfo(m) => Some(m.header.stamp.nanos()),
                    Msg::LaserLine(m) => Some(m.header.stamp.nanos()),
                    Msg::Cloud(m) => Some(m.header.stamp.nanos()),
                    Msg::Marker(m) => Some(m.header.stamp.nanos()),
                    Msg::ScanEvent(m) => Some(m.header.stamp.nanos()),
                    Msg::JointState(m) => Some(m.header.stamp.nanos()),
                }
            }
            /// Every type name a [`Msg`] can carry.
            pub const TYPE_NAMES: &'static [&'static str] = &[$(<$t>::TYPE_NAME),*];
        }
    };
}

msg_types! {
    Image => Image,
    CompressedImage => CompressedImage,
    CameraInfo => CameraInfo,
    Tf => TFMessage,
    LaserLine => LaserLine,
    Cloud => PointCloud2,
    Marker => Marker,
    ScanEvent => ScanEvent,
    JointState => JointState,
    Clock => Clock,
    Text => StringMsg,
}

/// Quality of service by topic class (each overridable by the `qos.<class>.*` parameters of
/// the DDS host).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QosClass {
    /// Camera streams: best effort, depth 5.
    Sensor,
    /// Lines, profiles, events, reports, `/tf`: reliable, depth 10.
    Reliable,
    /// The latest state of a surface, each message superseding the one before (a camera's grid
    /// so far and its mesh, the merged surface, the radiograph's overlay): reliable, depth 1.
    /// These are the largest messages (tens of MB at 1920x1200); a deeper history would hold
    /// that many copies in every writer.
    State,
    /// `/tf_static`: reliable, transient local, depth 1.
    Static,
}

/// One input or output of a component.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Port {
    /// Default topic name (relative names are placed in the node's namespace).
    pub topic: String,
    /// ROS 2 type name.
    pub type_name: &'static str,
    /// QoS class.
    pub qos: QosClass,
}

impl Port {
    /// A port.
    pub fn new(topic: &str, type_name: &'static str, qos: QosClass) -> Port {
        Port { topic: topic.to_string(), type_name, qos }
    }
}

/// Messages a component publishes while handling one input: `(output index, message)`; and
/// earlier messages it refuses only now (a line kept until its pose arrived, say).
#[derive(Debug, Default)]
pub struct Outbox {
    /// Queued messages.
    pub items: Vec<(usize, Msg)>,
    /// Earlier messages refused now: `(input index, why)`. The host counts and logs each under
    /// its own input's topic, not the topic of the message being handled.
    pub refused: Vec<(usize, NodeError)>,
}

impl Outbox {
    /// Publishes `msg` on output `port`.
    pub fn publish(&mut self, port: usize, msg: Msg) {
        self.items.push((port, msg));
    }
    /// Refuses an earlier message of input `input`, now.
    pub fn refuse(&mut self, input: usize, e: NodeError) {
        self.refused.push((input, e));
    }
}

/// A failure handling one message: logged and counted by the host; the node goes on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct NodeError(pub String);

impl NodeError {
    /// An error from anything displayable.
    pub fn new(e: impl std::fmt::Display) -> Self {
        NodeError(e.to_string())
    }
}

/// A node's logic, independent of the transport.
pub trait Component: Send {
    /// The node's default name (`edge_detector`, ...).
    fn node_name(&self) -> &'static str;
    /// Inputs, in the order `handle` numbers them.
    fn inputs(&self) -> Vec<Port>;
    /// Outputs, in the order `Outbox::publish` numbers them.
    fn outputs(&self) -> Vec<Port>;
    /// Tells the component where it was placed (node name and namespace), before any message.
    fn set_identity(&mut self, _name: &str, _namespace: &str) {}
    /// Applies a new set of parameter values; a set that fails validation is refused and the
    /// old configuration stays.
    fn reconfigure(&mut self, params: &Params) -> Result<(), ParamError>;
    /// Handles one message from input `input`.
    fn handle(&mut self, input: usize, msg: &Msg, out: &mut Outbox) -> Result<(), NodeError>;
    /// Called periodically with the node's clock (ns since the epoch).
    fn tick(&mut self, _now_ns: i64, _out: &mut Outbox) {}
    /// When the node next needs a tick (ns on its clock), if it keeps a schedule of its own (a
    /// camera's frame times): the host ticks it then rather than at its next periodic tick.
    fn next_tick_ns(&self) -> Option<i64> {
        None
    }
    /// No more input is coming (end of a bag, or shutdown): flush what is pending.
    fn finish(&mut self, _out: &mut Outbox) {}
    /// True for a node whose work is bulk (meshing, merging, overlays) rather than on the path
    /// from a frame to its profile: the live host runs it, and the publishers of its outputs,
    /// at a lower CPU priority, so that on a loaded machine the cameras' chain goes first.
    fn bulk(&self) -> bool {
        false
    }
    /// Counters for reports and logs, as `(name, value)`.
    fn counters(&self) -> Vec<(&'static str, u64)> {
        Vec::new()
    }
    /// Failures that are not about one message (a file it could not write, and why), the most
    /// recent last, for reports.
    fn problems(&self) -> Vec<String> {
        Vec::new()
    }
}
