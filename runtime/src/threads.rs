//! The live graph's executor: every component of a process on a thread of its own, connected in
//! memory (an `Arc` per message, no copy), as a multi-threaded ROS 2 component container.
//!
//! A node's slow work (a growing cloud, a mesh at END, the merge) then holds up only that node:
//! the cameras keep their frame times and the other camera's chain runs on the other core. Each
//! node thread ticks itself: at its tick period, or earlier when the component asks
//! ([`Component::next_tick_ns`](crate::component::Component::next_tick_ns)), so a camera's frame leaves on time.
//!
//! Delivery: one FIFO inbox per node, so every topic keeps its order. Camera streams (sensor QoS)
//! are best effort here as over DDS: a node that already has [`SENSOR_BACKLOG`] of them waiting
//! drops the next one and counts it. Other messages queue (they are small and rare next to the
//! frames: lines, profiles, clouds at a few hertz, events), up to [`INBOX_CAPACITY`] a node; a
//! publisher facing a full inbox waits up to [`INBOX_WAIT`] for it to drain, then drops the
//! message, counts it and logs it, so that one stuck node can neither grow without bound nor
//! stall the graph.
//!
//! Offline (a bag, `xsurf reconstruct`) the single-threaded [`crate::router::Router`] runs the same
//! components deterministically.

use crate::component::{Msg, Outbox, QosClass};
use crate::params::Params;
use crate::router::{Placed, Router};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Camera-stream messages a node may have waiting before the next one is dropped.
pub const SENSOR_BACKLOG: usize = 4;

/// Messages of any kind a node's inbox holds (at 100 Hz of `/tf`, a node can fall 40 s behind).
pub const INBOX_CAPACITY: usize = 4096;

/// How long a publisher waits for a full inbox before the message is dropped.
pub const INBOX_WAIT: Duration = Duration::from_secs(2);

/// The nice value of the threads of bulk nodes ([`crate::component::Component::bulk`]) and of
/// their publishers.
pub const BULK_NICE: i32 = 10;

/// The nice value of work that no one waits for, beside the bulk nodes (a mesher's mesh, made
/// after its final cloud has gone to the merger, which is waited for).
pub const BACKGROUND_NICE: i32 = 19;

/// Lowers the calling thread's CPU priority to [`BULK_NICE`] (Linux keeps a nice value per
/// thread), never raising it. Lowering needs no privilege; a failure is logged and the thread
/// goes on as it was.
pub fn lower_this_thread() {
    lower_this_thread_to(BULK_NICE);
}

/// Lowers the calling thread's CPU priority to `nice`, never raising it (see
/// [`lower_this_thread`]).
pub fn lower_this_thread_to(nice: i32) {
    let tid = rustix::thread::gettid();
    let now = rustix::process::getpriority_process(Some(tid)).unwrap_or(0);
    if now >= nice {
        return;
    }
    if let Err(e) = rustix::process::setpriority_process(Some(tid), nice) {
        log::debug!("thread {tid:?}: nice {nice} not set: {e}");
    }
}

/// Forwards every message a node publishes to outside observers (DDS, a bag).
pub type SharedTap = Arc<dyn Fn(&str, &Msg) + Send + Sync>;

/// Work for a node's thread.
enum Work {
    /// A message on input `usize`; `true` for a camera stream.
    Input(usize, Msg, bool),
    /// The simulated clock (`use_sim_time`).
    Clock(i64),
    /// A parameter set (already applied to the node's parameters) and the name that changed.
    Reconfigure(Box<Params>, String),
    /// No more input: flush, then acknowledge.
    Finish(SyncSender<()>),
    /// Leave the thread.
    Stop,
}

/// A node's inbox.
struct Inbox {
    tx: SyncSender<Work>,
    /// Camera-stream messages waiting.
    sensor_waiting: AtomicUsize,
    /// Camera-stream messages dropped because the node was behind.
    dropped: AtomicU64,
    /// Other messages dropped because the inbox stayed full for [`INBOX_WAIT`].
    overflowed: AtomicU64,
}

impl Inbox {
    /// Queues `w`, waiting up to [`INBOX_WAIT`] while the inbox is full.
    fn offer(&self, mut w: Work) -> Offer {
        let deadline = Instant::now() + INBOX_WAIT;
        loop {
            match self.tx.try_send(w) {
                Ok(()) => return Offer::Queued,
                Err(TrySendError::Disconnected(_)) => return Offer::Gone,
                Err(TrySendError::Full(back)) if Instant::now() < deadline => {
                    w = back;
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(TrySendError::Full(_)) => {
                    self.overflowed.fetch_add(1, Ordering::Relaxed);
                    return Offer::Dropped;
                }
            }
        }
    }
}

/// What became of a message offered to an inbox.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Offer {
    /// Queued.
    Queued,
    /// Dropped: the inbox stayed full for [`INBOX_WAIT`] (counted).
    Dropped,
    /// The node's thread has left (after shutdown).
    Gone,
}

/// One subscription: node, its input, and whether the topic is a camera stream.
#[derive(Clone, Copy)]
struct Sub {
    node: usize,
    input: usize,
    sensor: bool,
}

/// Where messages go: the tap, and each topic's subscribers.
#[derive(Clone)]
struct Fabric {
    inboxes: Arc<Vec<Inbox>>,
    subs: Arc<HashMap<String, Vec<Sub>>>,
    tap: SharedTap,
}

impl Fabric {
    /// Hands `msg` to every subscriber of `topic` (and to the tap if it is the graph's own).
    fn emit(&self, topic: &str, msg: &Msg, own: bool) {
        if own {
            (self.tap)(topic, msg);
        }
        let Some(subs) = self.subs.get(topic) else { return };
        for &Sub { node, input, sensor } in subs {
            let inbox = &self.inboxes[node];
            if sensor && inbox.sensor_waiting.fetch_add(1, Ordering::AcqRel) >= SENSOR_BACKLOG {
                inbox.sensor_waiting.fetch_sub(1, Ordering::AcqRel);
                inbox.dropped.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            // A node whose thread has left (after shutdown) simply gets nothing more.
            let offer = inbox.offer(Work::Input(input, msg.clone(), sensor));
            if offer != Offer::Queued && sensor {
                inbox.sensor_waiting.fetch_sub(1, Ordering::AcqRel);
            }
            if offer == Offer::Dropped {
                log::error!("{topic}: a node's inbox stayed full for {INBOX_WAIT:?}; the message is dropped");
            }
        }
    }
}

/// A node's place in the executor.
struct Runner {
    placed: Placed,
    index: usize,
    tick_period: Duration,
    sim_time: bool,
    fabric: Fabric,
}

impl Runner {
    fn publish(&mut self, out: Outbox) {
        for (port, msg) in out.items {
            match self.placed.outputs.get(port) {
                Some((_, topic)) => self.fabric.emit(topic, &msg, true),
                None => log::error!("{}: published on undeclared output {port}", self.placed.fq_name()),
            }
        }
    }

    /// Does one piece of work; `false` when the thread is to leave.
    fn work(&mut self, w: Work, clock: &mut Option<i64>, finished: &mut bool) -> bool {
        match w {
            Work::Input(input, msg, sensor) => {
                if sensor {
                    self.fabric.inboxes[self.index].sensor_waiting.fetch_sub(1, Ordering::AcqRel);
                }
                let out = self.placed.handle(input, &msg);
                self.publish(out);
            }
            Work::Clock(t) => *clock = Some(t),
            Work::Reconfigure(params, name) => match self.placed.component.reconfigure(&params) {
                Ok(()) => log::info!("{}: parameter {name} set", self.placed.name),
                Err(e) => log::warn!("{}: parameter {name} refused: {e}", self.placed.name),
            },
            Work::Finish(ack) => {
                *finished = true;
                let out = self.placed.finish();
                self.publish(out);
                // Each node has a thread of its own here: nothing to overlap by waiting later.
                let out = self.placed.settle();
                self.publish(out);
                let _ = ack.send(());
            }
            Work::Stop => return false,
        }
        true
    }

    fn run(mut self, rx: Receiver<Work>) -> Placed {
        if self.placed.component.bulk() {
            lower_this_thread();
        }
        let mut clock: Option<i64> = None;
        let mut last_tick = Instant::now();
        let mut finished = false;
        loop {
            let wake = if self.sim_time || finished { None } else { self.placed.component.next_tick_ns() };
            let timeout = match wake {
                Some(w) => self.tick_period.min(Duration::from_nanos((w - crate::wall_clock_ns()).max(0) as u64)),
                None => self.tick_period,
            };
            match rx.recv_timeout(timeout) {
                Ok(w) => {
                    if !self.work(w, &mut clock, &mut finished) {
                        break;
                    }
                    // What is already waiting is handled before the next tick (up to a bound, so
                    // that a flood cannot stop the ticks): a camera whose frame takes longer than
                    // the gap between two poses renders from the newest pose, not from a backlog
                    // that grows without end (and holds its Finish back at shutdown).
                    let mut stop = false;
                    for _ in 0..MAX_WORK_PER_TICK {
                        match rx.try_recv() {
                            Ok(w) => {
                                if !self.work(w, &mut clock, &mut finished) {
                                    stop = true;
                                    break;
                                }
                            }
                            Err(_) => break,
                        }
                    }
                    if stop {
                        break;
                    }
                }
                Err(RecvTimeoutError::Disconnected) => break,
                Err(RecvTimeoutError::Timeout) => {}
            }
            if finished {
                continue;
            }
            // With simulated time, time does not start before the first /clock message.
            let now = if self.sim_time { clock } else { Some(crate::wall_clock_ns()) };
            let due = wake.is_some_and(|w| now.is_some_and(|n| n >= w));
            if let Some(now) = now.filter(|_| due || last_tick.elapsed() >= self.tick_period) {
                last_tick = Instant::now();
                let out = self.placed.tick(now);
                self.publish(out);
            }
        }
        self.placed
    }
}

/// Queued messages a node handles between two of its ticks at most.
const MAX_WORK_PER_TICK: usize = 256;

/// The running executor.
pub struct Threads {
    fabric: Fabric,
    threads: Vec<JoinHandle<Placed>>,
}

impl Threads {
    /// Starts one thread per node of `router`; node `i` ticks every `tick_periods[i]` (50 ms if
    /// missing) on the wall clock, or on `/clock` with `sim_time`.
    pub fn start(
        router: Router,
        tap: SharedTap,
        tick_periods: &[Duration],
        sim_time: bool,
    ) -> std::io::Result<Threads> {
        let subs: HashMap<String, Vec<Sub>> = router
            .subscriptions()
            .iter()
            .map(|(topic, takers)| {
                let subs = takers
                    .iter()
                    .map(|&(node, input)| {
                        let sensor = router.nodes()[node].inputs[input].0.qos == QosClass::Sensor;
                        Sub { node, input, sensor }
                    })
                    .collect();
                (topic.clone(), subs)
            })
            .collect();
        let nodes = router.into_nodes();
        let (txs, rxs): (Vec<_>, Vec<_>) = nodes.iter().map(|_| sync_channel::<Work>(INBOX_CAPACITY)).unzip();
        let inboxes = txs
            .into_iter()
            .map(|tx| Inbox {
                tx,
                sensor_waiting: AtomicUsize::new(0),
                dropped: AtomicU64::new(0),
                overflowed: AtomicU64::new(0),
            })
            .collect();
        let fabric = Fabric { inboxes: Arc::new(inboxes), subs: Arc::new(subs), tap };
        let mut threads = Vec::new();
        for (index, (placed, rx)) in nodes.into_iter().zip(rxs).enumerate() {
            let runner = Runner {
                tick_period: tick_periods.get(index).copied().unwrap_or(Duration::from_millis(50)),
                sim_time,
                fabric: fabric.clone(),
                index,
                placed,
            };
            let name = format!("node {}", runner.placed.fq_name());
            threads.push(std::thread::Builder::new().name(name).spawn(move || runner.run(rx))?);
        }
        Ok(Threads { fabric, threads })
    }

    /// Delivers a message from outside the process (DDS) to the nodes that subscribe to `topic`.
    pub fn publish(&self, topic: &str, msg: &Msg) {
        self.fabric.emit(topic, msg, false);
    }

    /// The simulated clock, to every node.
    pub fn clock(&self, now_ns: i64) {
        for inbox in self.fabric.inboxes.iter() {
            // A full inbox drops a clock message: the next one supersedes it.
            let _ = inbox.tx.try_send(Work::Clock(now_ns));
        }
    }

    /// Hands node `node` its new parameters (`name` is the one that changed, for the log).
    pub fn reconfigure(&self, node: usize, params: &Params, name: &str) {
        if let Some(inbox) = self.fabric.inboxes.get(node) {
            let _ = inbox.tx.send(Work::Reconfigure(Box::new(params.clone()), name.to_string()));
        }
    }

    /// The name of a node whose thread has ended before [`Threads::finish`] (it panicked), if any.
    pub fn dead_node(&self) -> Option<String> {
        self.threads
            .iter()
            .find(|t| t.is_finished())
            .map(|t| t.thread().name().unwrap_or("a node").trim_start_matches("node ").to_string())
    }

    /// Camera-stream messages dropped so far because a node was behind.
    pub fn dropped(&self) -> u64 {
        self.fabric.inboxes.iter().map(|i| i.dropped.load(Ordering::Relaxed)).sum()
    }

    /// Other messages dropped so far because a node's inbox stayed full for [`INBOX_WAIT`].
    pub fn overflowed(&self) -> u64 {
        self.fabric.inboxes.iter().map(|i| i.overflowed.load(Ordering::Relaxed)).sum()
    }

    /// Tells every node, in the order they were added, that no more input is coming (each
    /// flushes after what is already queued for it, and what it publishes reaches the nodes
    /// after it), then stops the threads and gives the nodes back for their counters.
    pub fn finish(self) -> Vec<Placed> {
        for inbox in self.fabric.inboxes.iter() {
            let (ack, done) = sync_channel(1);
            if inbox.tx.send(Work::Finish(ack)).is_ok() {
                let _ = done.recv();
            }
        }
        for inbox in self.fabric.inboxes.iter() {
            let _ = inbox.tx.send(Work::Stop);
        }
        let mut nodes = Vec::new();
        for t in self.threads {
            match t.join() {
                Ok(p) => nodes.push(p),
                Err(_) => log::error!("a node thread panicked"),
            }
        }
        nodes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::component::{Component, NodeError, Port};
    use crate::params::ParamError;
    use std::sync::Mutex;
    use xsurf_msgs::sensor_msgs::Image;
    use xsurf_msgs::RosMessage;

    /// A source (one frame per tick on `out`), or a relay (`input` -> `out`) that takes
    /// `work` per message; at finish it publishes a marker frame (tag 999).
    struct Node {
        input: Option<(&'static str, QosClass)>,
        out: &'static str,
        work: Duration,
        seen: Arc<Mutex<Vec<(String, u32)>>>,
        count: u32,
    }
    fn frame(tag: u32) -> Msg {
        Msg::Image(Arc::new(Image { width: tag, ..Default::default() }))
    }
    fn tag(m: &Msg) -> u32 {
        if let Msg::Image(i) = m {
            i.width
        } else {
            u32::MAX
        }
    }
    impl Component for Node {
        type Input = usize;
        type Output = usize;
        fn node_name(&self) -> &'static str {
            "n"
        }
        fn inputs(&self) -> Vec<(usize, Port)> {
            self.input.iter().map(|(t, q)| (0, Port::new(t, Image::TYPE_NAME, *q))).collect()
        }
        fn outputs(&self) -> Vec<(usize, Port)> {
            vec![(0, Port::new(self.out, Image::TYPE_NAME, QosClass::Sensor))]
        }
        fn reconfigure(&mut self, _: &Params) -> Result<(), ParamError> {
            Ok(())
        }
        fn handle(&mut self, _: usize, msg: &Msg, out: &mut Outbox) -> Result<(), NodeError> {
            std::thread::sleep(self.work);
            self.seen.lock().unwrap().push((self.out.to_string(), tag(msg)));
            out.publish(0, msg.clone());
            Ok(())
        }
        fn tick(&mut self, _: i64, out: &mut Outbox) {
            if self.input.is_none() {
                self.count += 1;
                out.publish(0, frame(self.count));
            }
        }
        fn finish(&mut self, out: &mut Outbox) {
            out.publish(0, frame(999));
        }
    }

    type Log = Arc<Mutex<Vec<(String, u32)>>>;
    /// A node of a test graph: its input (topic, QoS), its output topic, its work per message.
    type Spec = (Option<(&'static str, QosClass)>, &'static str, Duration);

    fn graph(nodes: Vec<Spec>) -> (Router, Log) {
        let seen: Log = Arc::default();
        let mut r = Router::new();
        for (i, (input, out, work)) in nodes.into_iter().enumerate() {
            let n = Node { input, out, work, seen: seen.clone(), count: 0 };
            r.add(crate::component::boxed(n), &format!("n{i}"), "/", &[]);
        }
        (r, seen)
    }

    #[test]
    fn a_slow_node_holds_up_only_itself_and_finish_flushes_in_order() {
        let reliable = QosClass::Reliable;
        // Two cameras; the first camera's second stage is slow (a mesher building a cloud).
        let (r, seen) = graph(vec![
            (None, "/a", Duration::ZERO),
            (None, "/b", Duration::ZERO),
            (Some(("/a", reliable)), "/a2", Duration::from_millis(30)),
            (Some(("/b", reliable)), "/b2", Duration::ZERO),
        ]);
        let tapped: Log = Arc::default();
        let t = tapped.clone();
        let tap: SharedTap = Arc::new(move |topic: &str, m: &Msg| t.lock().unwrap().push((topic.to_string(), tag(m))));
        let ms = Duration::from_millis(5);
        let g = Threads::start(r, tap, &[ms, ms, ms, ms], false).unwrap();
        std::thread::sleep(Duration::from_millis(300));
        let nodes = g.finish();
        assert_eq!(nodes.len(), 4);
        let seen = seen.lock().unwrap().clone();
        let count = |out: &str| seen.iter().filter(|(o, _)| o == out).count();
        // The fast chain kept up with its source, whatever the slow one did.
        let b_frames = tapped.lock().unwrap().iter().filter(|(t, v)| t == "/b" && *v != 999).count();
        assert!(b_frames >= 30, "{b_frames}");
        assert_eq!(count("/b2"), b_frames + 1, "every /b frame and the finish marker reached /b2");
        // The slow chain lost nothing (reliable) and got the finish marker last.
        let a_frames = tapped.lock().unwrap().iter().filter(|(t, v)| t == "/a" && *v != 999).count();
        let a2: Vec<u32> = seen.iter().filter(|(o, _)| o == "/a2").map(|(_, v)| *v).collect();
        assert_eq!(a2.len(), a_frames + 1);
        assert_eq!(a2.last(), Some(&999));
        assert!(a2.windows(2).all(|w| w[0] < w[1]), "in order: {a2:?}");
    }

    /// Panics on its first message.
    struct Fragile;
    impl Component for Fragile {
        type Input = usize;
        type Output = usize;
        fn node_name(&self) -> &'static str {
            "fragile"
        }
        fn inputs(&self) -> Vec<(usize, Port)> {
            vec![(0, Port::new("/a", Image::TYPE_NAME, QosClass::Reliable))]
        }
        fn outputs(&self) -> Vec<(usize, Port)> {
            Vec::new()
        }
        fn reconfigure(&mut self, _: &Params) -> Result<(), ParamError> {
            Ok(())
        }
        fn handle(&mut self, _: usize, _: &Msg, _: &mut Outbox) -> Result<(), NodeError> {
            panic!("a bug")
        }
    }

    #[test]
    fn a_node_that_dies_is_named_and_the_rest_still_shut_down() {
        let (mut r, _) = graph(vec![(None, "/a", Duration::ZERO)]);
        r.add(crate::component::boxed(Fragile), "fragile", "/x", &[]);
        let tap: SharedTap = Arc::new(|_: &str, _: &Msg| {});
        let g = Threads::start(r, tap, &[Duration::from_millis(5), Duration::from_millis(50)], false).unwrap();
        let t0 = Instant::now();
        while g.dead_node().is_none() && t0.elapsed() < Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(g.dead_node().as_deref(), Some("/x/fragile"));
        assert_eq!(g.finish().len(), 1, "the live node comes back, the dead one is reported");
    }

    #[test]
    #[allow(clippy::disallowed_methods)] // the threads of the test need no names
    fn a_bulk_thread_runs_at_the_lower_priority_and_others_do_not() {
        // Field 19 of /proc/thread-self/stat is the thread's nice value (after the `(comm)`).
        let nice = || {
            let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap();
            let after = &stat[stat.rfind(')').unwrap() + 2..];
            after.split(' ').nth(16).unwrap().parse::<i32>().unwrap()
        };
        let base = std::thread::spawn(nice).join().unwrap();
        let lowered = std::thread::spawn(move || {
            lower_this_thread();
            nice()
        })
        .join()
        .unwrap();
        assert_eq!(lowered, BULK_NICE.max(base));
        assert_eq!(std::thread::spawn(nice).join().unwrap(), base, "only the calling thread is lowered");
    }

    /// A camera: each tick (its frame) takes 20 ms; it keeps the newest pose it was given.
    struct SlowTicker {
        newest: Arc<Mutex<u32>>,
    }
    impl Component for SlowTicker {
        type Input = usize;
        type Output = usize;
        fn node_name(&self) -> &'static str {
            "camera"
        }
        fn inputs(&self) -> Vec<(usize, Port)> {
            vec![(0, Port::new("/pose", Image::TYPE_NAME, QosClass::Reliable))]
        }
        fn outputs(&self) -> Vec<(usize, Port)> {
            Vec::new()
        }
        fn reconfigure(&mut self, _: &Params) -> Result<(), ParamError> {
            Ok(())
        }
        fn handle(&mut self, _: usize, msg: &Msg, _: &mut Outbox) -> Result<(), NodeError> {
            *self.newest.lock().unwrap() = tag(msg);
            Ok(())
        }
        fn tick(&mut self, _: i64, _: &mut Outbox) {
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Poses at 1 kHz into a camera whose frame takes 20 ms: every pose waiting is taken before
    /// the next frame, so the camera renders from the newest and its backlog does not grow
    /// (which once held a camera_driver's shutdown past the launcher's 10 s).
    #[test]
    fn a_slow_ticker_takes_what_is_waiting_before_its_next_tick() {
        let (mut r, _) = graph(vec![(None, "/pose", Duration::ZERO)]);
        let newest: Arc<Mutex<u32>> = Arc::default();
        r.add(crate::component::boxed(SlowTicker { newest: newest.clone() }), "camera", "/", &[]);
        let published: Arc<Mutex<u32>> = Arc::default();
        let p = published.clone();
        let tap: SharedTap = Arc::new(move |_: &str, m: &Msg| *p.lock().unwrap() = tag(m));
        let g = Threads::start(r, tap, &[Duration::from_millis(1), Duration::from_millis(1)], false).unwrap();
        std::thread::sleep(Duration::from_millis(400));
        let (sent, taken) = (*published.lock().unwrap(), *newest.lock().unwrap());
        let t0 = Instant::now();
        g.finish();
        assert!(sent > 100, "{sent}");
        // One frame's worth of poses behind at most (20 at 1 kHz), with room for a slow machine.
        assert!(taken + 60 >= sent, "the camera has pose {taken}, {sent} were sent");
        assert!(t0.elapsed() < Duration::from_secs(1), "finish waited {:?}", t0.elapsed());
    }

    #[test]
    fn a_camera_stream_into_a_busy_node_drops_and_counts() {
        let (r, seen) = graph(vec![
            (None, "/a", Duration::ZERO),
            (Some(("/a", QosClass::Sensor)), "/a2", Duration::from_millis(20)),
        ]);
        let tap: SharedTap = Arc::new(|_: &str, _: &Msg| {});
        let g = Threads::start(r, tap, &[Duration::from_millis(1), Duration::from_millis(50)], false).unwrap();
        std::thread::sleep(Duration::from_millis(200));
        let dropped = g.dropped();
        g.finish();
        let handled = seen.lock().unwrap().iter().filter(|(o, _)| o == "/a2").count() as u64;
        assert!(dropped > 0, "a 1 ms source into a 20 ms node must drop");
        assert!(handled <= 200 / 20 + SENSOR_BACKLOG as u64 + 2, "{handled} handled: the backlog is bounded");
    }

    /// A node stuck on its first message (a merge that takes seconds).
    struct Stuck {
        handled: Arc<AtomicU64>,
    }
    impl Component for Stuck {
        type Input = usize;
        type Output = usize;
        fn node_name(&self) -> &'static str {
            "stuck"
        }
        fn inputs(&self) -> Vec<(usize, Port)> {
            vec![(0, Port::new("/x", Image::TYPE_NAME, QosClass::Reliable))]
        }
        fn outputs(&self) -> Vec<(usize, Port)> {
            Vec::new()
        }
        fn reconfigure(&mut self, _: &Params) -> Result<(), ParamError> {
            Ok(())
        }
        fn handle(&mut self, _: usize, _: &Msg, _: &mut Outbox) -> Result<(), NodeError> {
            if self.handled.fetch_add(1, Ordering::SeqCst) == 0 {
                std::thread::sleep(INBOX_WAIT + Duration::from_secs(1));
            }
            Ok(())
        }
    }

    /// A node's inbox is bounded: a publisher waits for a full one up to INBOX_WAIT, then the
    /// message is dropped and counted; everything queued is still handled.
    #[test]
    fn a_full_inbox_waits_then_drops_and_counts() {
        let mut r = Router::new();
        let handled = Arc::new(AtomicU64::new(0));
        r.add(crate::component::boxed(Stuck { handled: handled.clone() }), "stuck", "/", &[]);
        let tap: SharedTap = Arc::new(|_: &str, _: &Msg| {});
        let g = Threads::start(r, tap, &[Duration::from_millis(50)], false).unwrap();
        let msg = frame(1);
        g.publish("/x", &msg);
        while handled.load(Ordering::SeqCst) == 0 {
            std::thread::sleep(Duration::from_millis(1));
        }
        // The node is stuck on the first: the inbox takes INBOX_CAPACITY more, then one waits.
        for _ in 0..INBOX_CAPACITY {
            g.publish("/x", &msg);
        }
        assert_eq!(g.overflowed(), 0);
        let t0 = Instant::now();
        g.publish("/x", &msg);
        assert!(t0.elapsed() >= INBOX_WAIT, "the publisher waited {:?}", t0.elapsed());
        assert_eq!(g.overflowed(), 1);
        g.finish();
        assert_eq!(handled.load(Ordering::SeqCst), 1 + INBOX_CAPACITY as u64);
    }
}
