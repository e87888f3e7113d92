//! Several components in one process, connected in memory: a published message is handed to
//! every subscriber before the publish call returns (nothing can be dropped), and to an optional
//! tap that forwards every output to outside observers (DDS, a bag) as soon as its node returns.
//!
//! Delivery is breadth first, through one FIFO queue: messages are handled in the order they were
//! published, so every topic keeps its order and a cause is handled before its effects. A tick
//! lets every node publish first (two cameras' frames leave together) and only then handles what
//! they published, so one camera's frame does not wait behind the other's whole chain.

use crate::component::{AnyComponent, Msg, NodeError, Outbox, Port};
use crate::params::Params;
use crate::rosargs::{fq_name, resolve_topic, Remap};
use std::collections::HashMap;

/// A component placed in the graph.
pub struct Placed {
    /// The component.
    pub component: Box<dyn AnyComponent>,
    /// Its node name.
    pub name: String,
    /// Its namespace.
    pub namespace: String,
    /// Resolved input topics.
    pub inputs: Vec<(Port, String)>,
    /// Resolved output topics.
    pub outputs: Vec<(Port, String)>,
    /// Messages it failed to handle.
    pub errors: u64,
    /// The same, by kind ([`NodeError::kind`]).
    pub errors_by_kind: std::collections::BTreeMap<&'static str, u64>,
    /// Messages it handled.
    pub handled: u64,
    /// Time spent in its handlers, ns.
    pub busy_ns: u64,
    /// The last message it refused, and why.
    pub last_error: Option<String>,
    /// Refusals logged (each different from the one before).
    logged: u64,
    /// Its outputs that nothing takes (see [`Router::quiet_unheard`]).
    unheard: Vec<usize>,
}

impl Placed {
    /// The fully qualified node name.
    pub fn fq_name(&self) -> String {
        fq_name(&self.namespace, &self.name)
    }
    /// Hands the component a message on input `input`: counted, timed, and a refusal logged
    /// (the first few; all are counted and the last is kept for reports). Returns what it
    /// published.
    pub fn handle(&mut self, input: usize, msg: &Msg) -> Outbox {
        let mut out = Outbox::unheard(self.unheard.clone());
        self.handled += 1;
        let t0 = std::time::Instant::now();
        let r = self.component.handle(input, msg, &mut out);
        self.busy_ns += t0.elapsed().as_nanos() as u64;
        if let Err(e) = r {
            self.refuse(input, &e);
        }
        self.take_refusals(&mut out);
        out
    }
    /// Counts a refused message of input `input`, logs the first few different reasons (a
    /// reason repeated, such as a region of interest outside every frame, is logged once), keeps
    /// the last.
    fn refuse(&mut self, input: usize, e: &NodeError) {
        self.errors += 1;
        *self.errors_by_kind.entry(e.kind()).or_default() += 1;
        let topic = self.inputs.get(input).map_or("?", |(_, t)| t.as_str()).to_string();
        let text = format!("{topic}: {e}");
        if self.last_error.as_deref() != Some(text.as_str()) {
            self.logged += 1;
            if self.logged <= 5 {
                log::warn!("{}: message on {topic} refused: {e}", self.fq_name());
            } else if self.logged == 6 {
                log::warn!("{}: more messages refused; counting them quietly", self.fq_name());
            }
        }
        self.last_error = Some(text);
    }
    /// Counts the earlier messages the component refused while handling this one.
    fn take_refusals(&mut self, out: &mut Outbox) {
        for (input, e) in std::mem::take(&mut out.refused) {
            self.refuse(input, &e);
        }
    }
    /// Ticks the component (timed); returns what it published.
    pub fn tick(&mut self, now_ns: i64) -> Outbox {
        let mut out = Outbox::unheard(self.unheard.clone());
        let t0 = std::time::Instant::now();
        self.component.tick(now_ns, &mut out);
        self.busy_ns += t0.elapsed().as_nanos() as u64;
        self.take_refusals(&mut out);
        out
    }
    /// Tells the component no more input is coming (timed); returns what it published.
    pub fn finish(&mut self) -> Outbox {
        let mut out = Outbox::unheard(self.unheard.clone());
        let t0 = std::time::Instant::now();
        self.component.finish(&mut out);
        self.busy_ns += t0.elapsed().as_nanos() as u64;
        self.take_refusals(&mut out);
        out
    }
    /// Waits for the component's work on threads of its own, after every node's finish (see
    /// [`Component::settle`](crate::component::Component::settle)); returns what it published.
    pub fn settle(&mut self) -> Outbox {
        let mut out = Outbox::unheard(self.unheard.clone());
        self.component.settle(&mut out);
        self.take_refusals(&mut out);
        out
    }
}

/// True for a topic that ROS lets many nodes publish: `/tf`, `/tf_static` and the scan events
/// (`xsurf_msgs/msg/ScanEvent`, "every node follows them whoever publishes").
pub fn is_shared(topic: &str, type_name: &str) -> bool {
    topic == "/tf" || topic == "/tf_static" || type_name == "xsurf_msgs/msg/ScanEvent"
}

/// Callback for every message published in the graph: `(topic, message)`.
pub type Tap = Box<dyn FnMut(&str, &Msg)>;

/// The in-memory graph.
#[derive(Default)]
pub struct Router {
    nodes: Vec<Placed>,
    subs: HashMap<String, Vec<(usize, usize)>>,
    tap: Option<Tap>,
    /// Published, not yet handled: `(topic, message)`.
    queue: std::collections::VecDeque<(String, Msg)>,
}

impl Router {
    /// An empty graph.
    pub fn new() -> Self {
        Self::default()
    }
    /// Sets the tap.
    pub fn set_tap(&mut self, tap: Tap) {
        self.tap = Some(tap);
    }
    /// Adds a component as node `namespace/name` with remaps; returns its index.
    pub fn add(
        &mut self,
        mut component: Box<dyn AnyComponent>,
        name: &str,
        namespace: &str,
        remaps: &[Remap],
    ) -> usize {
        component.set_identity(name, namespace);
        let resolve = |p: Port| {
            let t = resolve_topic(&p.topic, namespace, name, remaps);
            (p, t)
        };
        let inputs: Vec<_> = component.inputs().into_iter().map(resolve).collect();
        let outputs: Vec<_> = component.outputs().into_iter().map(resolve).collect();
        let idx = self.nodes.len();
        for (i, (_, t)) in inputs.iter().enumerate() {
            self.subs.entry(t.clone()).or_default().push((idx, i));
        }
        self.nodes.push(Placed {
            component,
            name: name.to_string(),
            namespace: namespace.to_string(),
            inputs,
            outputs,
            errors: 0,
            errors_by_kind: Default::default(),
            handled: 0,
            busy_ns: 0,
            last_error: None,
            logged: 0,
            unheard: Vec::new(),
        });
        idx
    }
    /// Who takes each topic: `(node, input)` pairs in the order the nodes were added (the
    /// one subscription table; the thread executor takes it over).
    pub fn subscriptions(&self) -> &HashMap<String, Vec<(usize, usize)>> {
        &self.subs
    }
    /// The nodes.
    pub fn nodes(&self) -> &[Placed] {
        &self.nodes
    }
    /// The nodes, taken out of the graph (to run them on threads of their own).
    pub fn into_nodes(self) -> Vec<Placed> {
        self.nodes
    }
    /// A node, mutably (to reconfigure it).
    pub fn node_mut(&mut self, idx: usize) -> Option<&mut Placed> {
        self.nodes.get_mut(idx)
    }
    /// Tells every node which of its outputs no node of the graph subscribes to
    /// ([`Outbox::heard`](crate::component::Outbox::heard)), so that it may leave them out: for a
    /// graph that has no tap and no outside subscriber (offline).
    pub fn quiet_unheard(&mut self) {
        for n in &mut self.nodes {
            n.unheard = (0..n.outputs.len()).filter(|&k| !self.subs.contains_key(&n.outputs[k].1)).collect();
        }
    }
    /// True if any node subscribes to `topic`.
    pub fn has_subscriber(&self, topic: &str) -> bool {
        self.subs.contains_key(topic)
    }
    /// Delivers a message that came from outside the graph (a bag, DDS) to its subscribers, and
    /// everything they publish in turn, before it returns; the tap does not see it (it is not
    /// the graph's own output).
    pub fn publish(&mut self, topic: &str, msg: &Msg) {
        self.queue.push_back((topic.to_string(), msg.clone()));
        self.drain();
    }
    /// Handles queued messages until none is left.
    fn drain(&mut self) {
        while let Some((topic, msg)) = self.queue.pop_front() {
            let Some(subs) = self.subs.get(&topic).cloned() else { continue };
            for (node, input) in subs {
                let out = self.nodes[node].handle(input, &msg);
                self.deliver(node, out);
            }
        }
    }
    /// Taps and queues what node `node` published.
    fn deliver(&mut self, node: usize, out: Outbox) {
        for (port, msg) in out.items {
            let Some((_, topic)) = self.nodes[node].outputs.get(port).cloned() else {
                log::error!("{}: published on undeclared output {port}", self.nodes[node].fq_name());
                continue;
            };
            if let Some(tap) = self.tap.as_mut() {
                tap(&topic, &msg);
            }
            self.queue.push_back((topic, msg));
        }
    }
    /// Topics some node of the graph publishes.
    pub fn output_topics(&self) -> Vec<(String, crate::component::Port)> {
        self.nodes.iter().flat_map(|n| n.outputs.iter().map(|(p, t)| (t.clone(), p.clone()))).collect()
    }
    /// Topics some node subscribes to that no node of the graph publishes (they come from outside).
    pub fn external_inputs(&self) -> Vec<(String, crate::component::Port)> {
        self.inputs_where(|published, _, _| !published)
    }
    /// Topics that some node subscribes to and some node of the graph publishes, but that ROS
    /// lets any node publish ([`is_shared`]: `/tf`, `/tf_static`, scan events): publishers
    /// outside the graph count as well, so a host subscribes to them too (and leaves out its own
    /// publications).
    pub fn shared_inputs(&self) -> Vec<(String, crate::component::Port)> {
        self.inputs_where(|published, topic, port| published && is_shared(topic, port.type_name))
    }
    /// Each subscribed topic once, with the first port on it, where `keep(published in the
    /// graph, topic, port)`.
    fn inputs_where(
        &self,
        keep: impl Fn(bool, &str, &crate::component::Port) -> bool,
    ) -> Vec<(String, crate::component::Port)> {
        let outs: std::collections::HashSet<String> = self.output_topics().into_iter().map(|(t, _)| t).collect();
        let mut v: Vec<(String, crate::component::Port)> = Vec::new();
        for n in &self.nodes {
            for (p, t) in &n.inputs {
                if keep(outs.contains(t), t, p) && !v.iter().any(|(x, _)| x == t) {
                    v.push((t.clone(), p.clone()));
                }
            }
        }
        v
    }
    /// Ticks every node with the graph's clock. The sources (nodes without inputs) first, all
    /// their messages leaving before anything is made from them (no camera waits behind
    /// another's chain); then the others in the order they were added, each one's output
    /// handled before the next one ticks (what a mesher's timer closes reaches the merger
    /// before the merger's own timer runs, as time orders them live).
    pub fn tick(&mut self, now_ns: i64) {
        let source = |n: &Placed| n.inputs.is_empty();
        for i in 0..self.nodes.len() {
            if source(&self.nodes[i]) {
                let out = self.nodes[i].tick(now_ns);
                self.deliver(i, out);
            }
        }
        self.drain();
        for i in 0..self.nodes.len() {
            if !source(&self.nodes[i]) {
                let out = self.nodes[i].tick(now_ns);
                self.deliver(i, out);
                self.drain();
            }
        }
    }
    /// Tells every node, in the order they were added, that no more input is coming; then,
    /// in the same order, waits for each node's work on threads of its own
    /// ([`Component::settle`](crate::component::Component::settle)).
    pub fn finish(&mut self) {
        for i in 0..self.nodes.len() {
            let out = self.nodes[i].finish();
            self.deliver(i, out);
            self.drain();
        }
        for i in 0..self.nodes.len() {
            let out = self.nodes[i].settle();
            self.deliver(i, out);
            self.drain();
        }
    }
    /// Applies parameters to node `idx` (validated by the component).
    pub fn reconfigure(&mut self, idx: usize, params: &Params) -> Result<(), crate::params::ParamError> {
        match self.nodes.get_mut(idx) {
            Some(n) => n.component.reconfigure(params),
            None => Err(crate::params::ParamError::Undeclared(format!("node {idx}"))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::component::{Component, NodeError, QosClass};
    use crate::params::ParamError;
    use std::sync::{Arc, Mutex};
    use xsurf_msgs::sensor_msgs::Image;
    use xsurf_msgs::RosMessage;

    /// A source (publishes one image per tick on `out`) or a relay (`input` -> `out`).
    struct Node {
        input: Option<&'static str>,
        out: &'static str,
        seen: Arc<Mutex<Vec<String>>>,
    }
    fn image(tag: u32) -> Msg {
        Msg::Image(Arc::new(Image { width: tag, ..Default::default() }))
    }
    fn tag(m: &Msg) -> u32 {
        match m {
            Msg::Image(i) => i.width,
            _ => u32::MAX,
        }
    }
    impl Component for Node {
        type Input = usize;
        type Output = usize;
        fn node_name(&self) -> &'static str {
            "n"
        }
        fn inputs(&self) -> Vec<(usize, Port)> {
            self.input.iter().map(|t| (0, Port::new(t, Image::TYPE_NAME, QosClass::Reliable))).collect()
        }
        fn outputs(&self) -> Vec<(usize, Port)> {
            vec![(0, Port::new(self.out, Image::TYPE_NAME, QosClass::Reliable))]
        }
        fn reconfigure(&mut self, _: &Params) -> Result<(), ParamError> {
            Ok(())
        }
        fn handle(&mut self, _: usize, msg: &Msg, out: &mut Outbox) -> Result<(), NodeError> {
            self.seen.lock().unwrap().push(format!("{} {}", self.out, tag(msg)));
            // Two outputs per input: their order must hold downstream.
            out.publish(0, image(tag(msg) * 10));
            out.publish(0, image(tag(msg) * 10 + 1));
            Ok(())
        }
        fn tick(&mut self, _: i64, out: &mut Outbox) {
            if self.input.is_none() {
                out.publish(0, image(if self.out == "/a" { 1 } else { 2 }));
            }
        }
    }

    /// Records at each tick whether its output is heard.
    struct Listener {
        out: &'static str,
        heard: Arc<Mutex<Vec<bool>>>,
    }
    impl Component for Listener {
        type Input = usize;
        type Output = usize;
        fn node_name(&self) -> &'static str {
            "l"
        }
        fn inputs(&self) -> Vec<(usize, Port)> {
            Vec::new()
        }
        fn outputs(&self) -> Vec<(usize, Port)> {
            vec![(0, Port::new(self.out, Image::TYPE_NAME, QosClass::Reliable))]
        }
        fn reconfigure(&mut self, _: &Params) -> Result<(), ParamError> {
            Ok(())
        }
        fn handle(&mut self, _: usize, _: &Msg, _: &mut Outbox) -> Result<(), NodeError> {
            Ok(())
        }
        fn tick(&mut self, _: i64, out: &mut Outbox) {
            self.heard.lock().unwrap().push(out.heard(0));
        }
    }

    #[test]
    fn outputs_no_node_takes_are_unheard_once_the_graph_says_so() {
        let heard = Arc::new(Mutex::new(Vec::new()));
        let seen = Arc::new(Mutex::new(Vec::new()));
        let mut r = Router::new();
        let listener = |out| crate::component::boxed(Listener { out, heard: heard.clone() });
        r.add(listener("/taken"), "a", "/", &[]);
        r.add(listener("/nobody"), "b", "/", &[]);
        r.add(crate::component::boxed(Node { input: Some("/taken"), out: "/c", seen }), "c", "/", &[]);
        // Until the graph is told it has no outside subscriber, every output is heard.
        r.tick(0);
        assert_eq!(*heard.lock().unwrap(), [true, true]);
        heard.lock().unwrap().clear();
        r.quiet_unheard();
        r.tick(1);
        assert_eq!(*heard.lock().unwrap(), [true, false]);
    }

    #[test]
    fn a_tick_publishes_every_source_first_and_keeps_order() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let tapped = Arc::new(Mutex::new(Vec::new()));
        let mut r = Router::new();
        let node = |input, out| crate::component::boxed(Node { input, out, seen: seen.clone() });
        r.add(node(None, "/a"), "a", "/", &[]);
        r.add(node(None, "/b"), "b", "/", &[]);
        r.add(node(Some("/a"), "/a2"), "a2", "/", &[]);
        r.add(node(Some("/b"), "/b2"), "b2", "/", &[]);
        r.add(node(Some("/a2"), "/a3"), "a3", "/", &[]);
        let t = tapped.clone();
        r.set_tap(Box::new(move |topic, m| t.lock().unwrap().push(format!("{topic} {}", tag(m)))));
        r.tick(0);
        let tapped = tapped.lock().unwrap().clone();
        // Both sources' frames leave before anything is made from either.
        assert_eq!(&tapped[..2], ["/a 1", "/b 2"]);
        // b's first product is not held back behind a's second stage.
        let pos = |s: &str| tapped.iter().position(|x| x == s).unwrap();
        assert!(pos("/b2 20") < pos("/a3 100"), "{tapped:?}");
        // Each topic keeps its order, and every message is handled exactly once.
        assert_eq!(*seen.lock().unwrap(), ["/a2 1", "/b2 2", "/a3 10", "/a3 11"]);
        assert_eq!(tapped.len(), 2 + 4 + 4);
        // A message from outside is handled, with all it causes, before publish returns.
        r.publish("/a2", &image(7));
        assert_eq!(seen.lock().unwrap().last().unwrap(), "/a3 7");
    }

    /// A node that, on a tick, publishes what it was given (a mesher closing a scan on its
    /// timer) and notes when its own tick runs against what it was handled.
    struct Timer {
        input: &'static str,
        out: &'static str,
        held: Vec<u32>,
        seen: Arc<Mutex<Vec<String>>>,
    }
    impl Component for Timer {
        type Input = usize;
        type Output = usize;
        fn node_name(&self) -> &'static str {
            "t"
        }
        fn inputs(&self) -> Vec<(usize, Port)> {
            vec![(0, Port::new(self.input, Image::TYPE_NAME, QosClass::Reliable))]
        }
        fn outputs(&self) -> Vec<(usize, Port)> {
            vec![(0, Port::new(self.out, Image::TYPE_NAME, QosClass::Reliable))]
        }
        fn reconfigure(&mut self, _: &Params) -> Result<(), ParamError> {
            Ok(())
        }
        fn handle(&mut self, _: usize, msg: &Msg, _: &mut Outbox) -> Result<(), NodeError> {
            self.seen.lock().unwrap().push(format!("{} got {}", self.out, tag(msg)));
            self.held.push(tag(msg));
            Ok(())
        }
        fn tick(&mut self, _: i64, out: &mut Outbox) {
            self.seen.lock().unwrap().push(format!("{} tick", self.out));
            for t in self.held.drain(..) {
                out.publish(0, image(t));
            }
        }
    }

    #[test]
    fn what_a_timer_publishes_reaches_later_nodes_before_their_timers() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let mut r = Router::new();
        let timer = |input, out| crate::component::boxed(Timer { input, out, held: Vec::new(), seen: seen.clone() });
        r.add(timer("/in", "/mid"), "mesher", "/", &[]);
        r.add(timer("/mid", "/end"), "merger", "/", &[]);
        r.publish("/in", &image(5));
        r.tick(1);
        assert_eq!(*seen.lock().unwrap(), ["/mid got 5", "/mid tick", "/end got 5", "/end tick"]);
    }
}
