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

/// The name of one of a component's inputs or outputs: an enum with a variant per port (or per
/// port of a camera, `Cloud(k)`), never a bare index.
pub trait PortId: Copy + Eq + std::fmt::Debug + Send + 'static {}
impl<T: Copy + Eq + std::fmt::Debug + Send + 'static> PortId for T {}

/// Messages a component publishes while handling one input: `(output, message)`; and earlier
/// messages it refuses only now (a line kept until its pose arrived, say). A component fills an
/// `Outbox<Self::Input, Self::Output>`; a host reads the `Outbox` of port positions.
#[derive(Debug)]
pub struct Outbox<I = usize, O = usize> {
    /// Queued messages.
    pub items: Vec<(O, Msg)>,
    /// Earlier messages refused now: `(input, why)`. The host counts and logs each under its own
    /// input's topic, not the topic of the message being handled.
    pub refused: Vec<(I, NodeError)>,
    /// Outputs that nothing takes (see [`Outbox::heard`]).
    unheard: Vec<O>,
}

impl<I, O> Default for Outbox<I, O> {
    fn default() -> Self {
        Outbox { items: Vec::new(), refused: Vec::new(), unheard: Vec::new() }
    }
}

impl<I, O: PartialEq> Outbox<I, O> {
    /// An empty outbox whose host says that nothing takes the outputs `unheard` (offline, a
    /// topic no node of the graph subscribes to).
    pub fn unheard(unheard: Vec<O>) -> Self {
        Outbox { items: Vec::new(), refused: Vec::new(), unheard }
    }
    /// False where the host knows that nothing takes output `port`: a component may then leave
    /// out a message that is costly to build and that no one reads (a mesh's marker offline).
    /// Live every output is heard (a DDS peer may subscribe at any time).
    pub fn heard(&self, port: O) -> bool {
        !self.unheard.contains(&port)
    }
}

impl<I, O> Outbox<I, O> {
    /// Publishes `msg` on output `port`.
    pub fn publish(&mut self, port: O, msg: Msg) {
        self.items.push((port, msg));
    }
    /// Refuses an earlier message of input `input`, now.
    pub fn refuse(&mut self, input: I, e: NodeError) {
        self.refused.push((input, e));
    }
}

/// Why a component refused a message (or failed on it): logged and counted by the host, by
/// kind; the node goes on. The text says what was wrong in the message's own terms (its topic or
/// stamp, the field, the value).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NodeError {
    /// The message cannot be read: bad encoding, a field out of range or not finite, an unknown
    /// event.
    #[error("{0}")]
    Malformed(String),
    /// Well formed, but it contradicts what the node knows: the camera's geometry, the scan's
    /// grid, the frame it should be in.
    #[error("{0}")]
    Contradicts(String),
    /// The node cannot use it yet (no camera_info so far, no pose for its stamp).
    #[error("{0}")]
    NotReady(String),
    /// A message of another type than its port carries.
    #[error("unexpected {got} on {port}{}", carries(*.expected))]
    WrongType {
        /// The port, as the component names it (or its position).
        port: String,
        /// The type the port carries, where the one refusing knows it.
        expected: Option<&'static str>,
        /// The type that came.
        got: &'static str,
    },
    /// The message was good; the work on it failed (a file that could not be written).
    #[error("{0}")]
    Failed(String),
}

/// `, which carries <type>` when the type is known.
fn carries(expected: Option<&'static str>) -> String {
    expected.map(|t| format!(", which carries {t}")).unwrap_or_default()
}

impl NodeError {
    /// [`NodeError::Malformed`] from anything displayable.
    pub fn malformed(e: impl std::fmt::Display) -> Self {
        NodeError::Malformed(e.to_string())
    }
    /// [`NodeError::Contradicts`] from anything displayable.
    pub fn contradicts(e: impl std::fmt::Display) -> Self {
        NodeError::Contradicts(e.to_string())
    }
    /// [`NodeError::NotReady`] from anything displayable.
    pub fn not_ready(e: impl std::fmt::Display) -> Self {
        NodeError::NotReady(e.to_string())
    }
    /// [`NodeError::Failed`] from anything displayable.
    pub fn failed(e: impl std::fmt::Display) -> Self {
        NodeError::Failed(e.to_string())
    }
    /// [`NodeError::WrongType`]: `msg` came on `port`, which does not carry its type.
    pub fn unexpected(port: impl std::fmt::Debug, msg: &Msg) -> Self {
        NodeError::WrongType { port: format!("{port:?}"), expected: None, got: msg.type_name() }
    }
    /// The same error of the same kind, its text led by `context` (`line at 12.5: ...`).
    pub fn context(self, context: impl std::fmt::Display) -> Self {
        match self {
            NodeError::Malformed(t) => NodeError::Malformed(format!("{context}: {t}")),
            NodeError::Contradicts(t) => NodeError::Contradicts(format!("{context}: {t}")),
            NodeError::NotReady(t) => NodeError::NotReady(format!("{context}: {t}")),
            NodeError::Failed(t) => NodeError::Failed(format!("{context}: {t}")),
            NodeError::WrongType { port, expected, got } => {
                NodeError::WrongType { port: format!("{context}: {port}"), expected, got }
            }
        }
    }
    /// The kind, as reports count it: `malformed`, `contradicts`, `not_ready`, `wrong_type`,
    /// `failed`.
    pub fn kind(&self) -> &'static str {
        match self {
            NodeError::Malformed(_) => "malformed",
            NodeError::Contradicts(_) => "contradicts",
            NodeError::NotReady(_) => "not_ready",
            NodeError::WrongType { .. } => "wrong_type",
            NodeError::Failed(_) => "failed",
        }
    }
}

/// A node's logic, independent of the transport. Its ports are named by its own `Input` and
/// `Output` types; [`boxed`] makes it an [`AnyComponent`], which hosts number by position.
pub trait Component: Send + 'static {
    /// The names of its inputs.
    type Input: PortId;
    /// The names of its outputs.
    type Output: PortId;
    /// The node's default name (`edge_detector`, ...).
    fn node_name(&self) -> &'static str;
    /// Its inputs, each named, in the order a host subscribes to them.
    fn inputs(&self) -> Vec<(Self::Input, Port)>;
    /// Its outputs, each named, in the order a host advertises them.
    fn outputs(&self) -> Vec<(Self::Output, Port)>;
    /// Tells the component where it was placed (node name and namespace), before any message.
    fn set_identity(&mut self, _name: &str, _namespace: &str) {}
    /// Applies a new set of parameter values; a set that fails validation is refused and the
    /// old configuration stays.
    fn reconfigure(&mut self, params: &Params) -> Result<(), ParamError>;
    /// Handles one message from input `input` (of the type its port declares: the host checks).
    fn handle(
        &mut self,
        input: Self::Input,
        msg: &Msg,
        out: &mut Outbox<Self::Input, Self::Output>,
    ) -> Result<(), NodeError>;
    /// Called periodically with the node's clock (ns since the epoch).
    fn tick(&mut self, _now_ns: i64, _out: &mut Outbox<Self::Input, Self::Output>) {}
    /// When the node next needs a tick (ns on its clock), if it keeps a schedule of its own (a
    /// camera's frame times): the host ticks it then rather than at its next periodic tick.
    fn next_tick_ns(&self) -> Option<i64> {
        None
    }
    /// No more input is coming (end of a bag, or shutdown): flush what is pending.
    fn finish(&mut self, _out: &mut Outbox<Self::Input, Self::Output>) {}
    /// After every node of the graph has been told to [`finish`](Component::finish): wait for
    /// work the node still has on threads of its own (a scan's mesh being made) and publish it.
    /// So one node's finishing work runs beside the next nodes' (offline, where one thread
    /// finishes them in turn).
    fn settle(&mut self, _out: &mut Outbox<Self::Input, Self::Output>) {}
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

/// A component as hosts see it: its ports numbered by position, `handle(0, ..)` being its first
/// input. Made by [`boxed`]; the concrete component stays reachable through [`AnyComponent::as_any`]
/// (the offline report reads each node's figures from its own type).
pub trait AnyComponent: Send {
    /// See [`Component::node_name`].
    fn node_name(&self) -> &'static str;
    /// Its input ports, by position.
    fn inputs(&self) -> Vec<Port>;
    /// Its output ports, by position.
    fn outputs(&self) -> Vec<Port>;
    /// See [`Component::set_identity`].
    fn set_identity(&mut self, name: &str, namespace: &str);
    /// See [`Component::reconfigure`].
    fn reconfigure(&mut self, params: &Params) -> Result<(), ParamError>;
    /// Handles one message from the input at position `input`; a message whose type is not the
    /// port's is refused ([`NodeError::WrongType`]) before it reaches the component.
    fn handle(&mut self, input: usize, msg: &Msg, out: &mut Outbox) -> Result<(), NodeError>;
    /// See [`Component::tick`].
    fn tick(&mut self, now_ns: i64, out: &mut Outbox);
    /// See [`Component::next_tick_ns`].
    fn next_tick_ns(&self) -> Option<i64>;
    /// See [`Component::finish`].
    fn finish(&mut self, out: &mut Outbox);
    /// See [`Component::settle`].
    fn settle(&mut self, out: &mut Outbox);
    /// See [`Component::bulk`].
    fn bulk(&self) -> bool;
    /// See [`Component::counters`].
    fn counters(&self) -> Vec<(&'static str, u64)>;
    /// See [`Component::problems`].
    fn problems(&self) -> Vec<String>;
    /// The component itself, to downcast to its type.
    fn as_any(&self) -> &dyn std::any::Any;
}

/// `component` with its ports numbered, for a host.
pub fn boxed<C: Component>(component: C) -> Box<dyn AnyComponent> {
    // A component's ports are fixed once it is built: listed here, once.
    let inputs = component.inputs().into_iter().map(|(id, p)| (id, p.type_name)).collect();
    let outputs = component.outputs().into_iter().map(|(id, _)| id).collect();
    Box::new(Numbered { inner: component, inputs, outputs })
}

/// A component with its port names listed by position.
struct Numbered<C: Component> {
    inner: C,
    /// Input names and their types, by position.
    inputs: Vec<(C::Input, &'static str)>,
    /// Output names, by position.
    outputs: Vec<C::Output>,
}

impl<C: Component> Numbered<C> {
    /// The component's own outbox, with the outputs that the host's outbox says nothing takes.
    fn typed(&self, out: &Outbox) -> Outbox<C::Input, C::Output> {
        Outbox::unheard(out.unheard.iter().filter_map(|&k| self.outputs.get(k).copied()).collect())
    }
    /// The component's outbox as positions. An output the component never listed (a bug in the
    /// component) is logged and dropped; so is a refusal of an input it never listed.
    fn numbered(&self, typed: Outbox<C::Input, C::Output>, out: &mut Outbox) {
        for (id, msg) in typed.items {
            match self.outputs.iter().position(|o| *o == id) {
                Some(k) => out.publish(k, msg),
                None => log::error!("{}: published on undeclared output {id:?}", self.inner.node_name()),
            }
        }
        for (id, e) in typed.refused {
            match self.inputs.iter().position(|(i, _)| *i == id) {
                Some(k) => out.refuse(k, e),
                None => log::error!("{}: refused on undeclared input {id:?}: {e}", self.inner.node_name()),
            }
        }
    }
}

impl<C: Component> AnyComponent for Numbered<C> {
    fn node_name(&self) -> &'static str {
        self.inner.node_name()
    }
    fn inputs(&self) -> Vec<Port> {
        self.inner.inputs().into_iter().map(|(_, p)| p).collect()
    }
    fn outputs(&self) -> Vec<Port> {
        self.inner.outputs().into_iter().map(|(_, p)| p).collect()
    }
    fn set_identity(&mut self, name: &str, namespace: &str) {
        self.inner.set_identity(name, namespace);
    }
    fn reconfigure(&mut self, params: &Params) -> Result<(), ParamError> {
        self.inner.reconfigure(params)
    }
    fn handle(&mut self, input: usize, msg: &Msg, out: &mut Outbox) -> Result<(), NodeError> {
        let Some(&(id, expected)) = self.inputs.get(input) else {
            return Err(NodeError::WrongType { port: format!("input {input}"), expected: None, got: msg.type_name() });
        };
        if msg.type_name() != expected {
            return Err(NodeError::WrongType {
                port: format!("{id:?}"),
                expected: Some(expected),
                got: msg.type_name(),
            });
        }
        let mut typed = self.typed(out);
        let r = self.inner.handle(id, msg, &mut typed);
        self.numbered(typed, out);
        r
    }
    fn tick(&mut self, now_ns: i64, out: &mut Outbox) {
        let mut typed = self.typed(out);
        self.inner.tick(now_ns, &mut typed);
        self.numbered(typed, out);
    }
    fn next_tick_ns(&self) -> Option<i64> {
        self.inner.next_tick_ns()
    }
    fn finish(&mut self, out: &mut Outbox) {
        let mut typed = self.typed(out);
        self.inner.finish(&mut typed);
        self.numbered(typed, out);
    }
    fn settle(&mut self, out: &mut Outbox) {
        let mut typed = self.typed(out);
        self.inner.settle(&mut typed);
        self.numbered(typed, out);
    }
    fn bulk(&self) -> bool {
        self.inner.bulk()
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        self.inner.counters()
    }
    fn problems(&self) -> Vec<String> {
        self.inner.problems()
    }
    fn as_any(&self) -> &dyn std::any::Any {
        &self.inner
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum In {
        Lines,
        Events,
    }
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum Out {
        Never,
        Profiles,
    }

    /// Lists its ports in another order than its enums declare them, and an output it never
    /// lists; refuses the line before each event.
    struct Node;

    impl Component for Node {
        type Input = In;
        type Output = Out;
        fn node_name(&self) -> &'static str {
            "node"
        }
        fn inputs(&self) -> Vec<(In, Port)> {
            vec![
                (In::Events, Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable)),
                (In::Lines, Port::new("laser_line", LaserLine::TYPE_NAME, QosClass::Reliable)),
            ]
        }
        fn outputs(&self) -> Vec<(Out, Port)> {
            vec![(Out::Profiles, Port::new("profile", PointCloud2::TYPE_NAME, QosClass::Reliable))]
        }
        fn reconfigure(&mut self, _: &Params) -> Result<(), ParamError> {
            Ok(())
        }
        fn handle(&mut self, input: In, msg: &Msg, out: &mut Outbox<In, Out>) -> Result<(), NodeError> {
            match (input, msg) {
                (In::Lines, Msg::LaserLine(_)) => {
                    out.publish(Out::Profiles, Msg::Cloud(Arc::default()));
                    out.publish(Out::Never, Msg::Cloud(Arc::default()));
                    Ok(())
                }
                (In::Events, Msg::ScanEvent(_)) => {
                    out.refuse(In::Lines, NodeError::not_ready("no pose"));
                    Err(NodeError::malformed("unknown scan event 9"))
                }
                (i, m) => Err(NodeError::unexpected(i, m)),
            }
        }
    }

    /// A host's positions reach the component as its own port names, and what it publishes or
    /// refuses goes back as positions; a message of another type than its port's never reaches
    /// it, and an output it never listed is dropped, not sent elsewhere.
    #[test]
    fn ports_are_numbered_by_the_lists_and_typed_inside() {
        let mut c = boxed(Node);
        assert_eq!(c.inputs().iter().map(|p| p.topic.as_str()).collect::<Vec<_>>(), ["/scan/events", "laser_line"]);
        let mut out = Outbox::default();
        c.handle(1, &Msg::LaserLine(Arc::default()), &mut out).unwrap();
        assert_eq!(
            out.items.iter().map(|(k, _)| *k).collect::<Vec<_>>(),
            [0],
            "Profiles is output 0; Never is dropped"
        );
        let e = c.handle(0, &Msg::ScanEvent(Arc::default()), &mut out).unwrap_err();
        assert_eq!((e.kind(), e.to_string().as_str()), ("malformed", "unknown scan event 9"));
        assert_eq!(out.refused, [(1, NodeError::not_ready("no pose"))], "the line's refusal under input 1");
        let e = c.handle(1, &Msg::ScanEvent(Arc::default()), &mut out).unwrap_err();
        assert_eq!(e.kind(), "wrong_type");
        assert_eq!(
            e.to_string(),
            "unexpected xsurf_msgs/msg/ScanEvent on Lines, which carries xsurf_msgs/msg/LaserLine"
        );
        assert_eq!(c.handle(2, &Msg::ScanEvent(Arc::default()), &mut out).unwrap_err().kind(), "wrong_type");
        assert!(c.as_any().downcast_ref::<Node>().is_some());
        let e = NodeError::not_ready("no pose").context("line at 1.5");
        assert_eq!((e.kind(), e.to_string().as_str()), ("not_ready", "line at 1.5: no pose"));
    }
}
