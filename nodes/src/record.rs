//! `xsurf bag record`: subscribes to topics over DDS and writes them to a rosbag2 bag, each
//! with the QoS of its class (recorded in the bag).

use anyhow::{bail, Context as _};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};
use xsurf_formats::bag::{BagOptions, BagWriter, Qos};
use xsurf_runtime::component::{Msg, QosClass};
use xsurf_runtime::dds::{self, DdsEnv};

/// Options of `bag record`.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// Topics to record (with `all` false).
    pub topics: Vec<String>,
    /// Record every discovered topic of a type xsurf knows.
    pub all: bool,
    /// zstd chunk compression.
    pub zstd: bool,
    /// Stop after this long (else on SIGINT/SIGTERM).
    pub duration_s: Option<f64>,
    /// One bag per scan, `DIR/scan_<id>` (START to END or ABORT, from `/scan/events`), each
    /// beginning with the last `/tf_static` and `/tf` heard before it (the `/tf` only if stamped
    /// at or before the START); nothing is recorded between scans.
    pub split_by_scan: bool,
}

/// Where messages go: one bag, or one bag per scan.
struct Sink {
    dir: std::path::PathBuf,
    options: BagOptions,
    split: bool,
    /// The bag being written (always, without `split`; during a scan, with it).
    writer: Option<BagWriter>,
    /// Every topic added so far: name, type, definition, QoS (each new bag gets them all).
    topics: Vec<(String, String, String, Qos)>,
    /// With `split`, the last `/tf_static` and `/tf` heard (with the stamp), written first into
    /// each scan's bag: `/tf` only if stamped at or before the scan's START (the last one heard
    /// may be a later scan's or another play's, when this scan's earliest transforms arrive
    /// after its START event; a reader would then meet a transform from after the scan first).
    preroll: BTreeMap<String, (Option<i64>, Vec<u8>)>,
    /// With `split`, between scans: the last `GRACE_NS` of messages (arrival ns, topic, stamp,
    /// CDR), so that a frame stamped after START that arrives before the START event (another
    /// DDS reader) still goes into the scan's bag.
    recent: std::collections::VecDeque<(u64, String, Option<i64>, Vec<u8>)>,
    /// With `split`, after END: when the scan's bag is closed (frames stamped before END may
    /// arrive after the event).
    close_at: Option<u64>,
}

/// How long a scan's bag takes messages that arrive before START or after END, ns.
const GRACE_NS: u64 = 1_000_000_000;

impl Sink {
    fn new(dir: &Path, options: BagOptions, split: bool) -> anyhow::Result<Sink> {
        let writer = if split {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
            None
        } else {
            Some(BagWriter::create(dir, options)?)
        };
        Ok(Sink {
            dir: dir.to_path_buf(),
            options,
            split,
            writer,
            topics: Vec::new(),
            preroll: BTreeMap::new(),
            recent: std::collections::VecDeque::new(),
            close_at: None,
        })
    }

    fn add_topic(&mut self, topic: &str, ty: &str, def: &str, qos: Qos) -> anyhow::Result<()> {
        if let Some(w) = &mut self.writer {
            w.add_topic(topic, ty, def, &qos)?;
        }
        self.topics.push((topic.into(), ty.into(), def.into(), qos));
        Ok(())
    }

    /// Writes one message; with `split`, a scan event opens or closes the scan's bag.
    fn write(&mut self, topic: &str, now: u64, m: &Msg) -> anyhow::Result<()> {
        let data = m.encode()?;
        if !self.split {
            if let Some(w) = &mut self.writer {
                w.write(topic, now, now, &data)?;
            }
            return Ok(());
        }
        let event = match m {
            Msg::ScanEvent(e) if topic == "/scan/events" => Some((e.scan_id, e.event, e.header.stamp.nanos())),
            _ => None,
        };
        self.tick(now)?;
        if let Some((id, xsurf_msgs::xsurf_msgs::ScanEvent::START, start_ns)) = event {
            self.close()?;
            let mut dir = self.dir.join(format!("scan_{id}"));
            let mut k = 2;
            while dir.exists() {
                dir = self.dir.join(format!("scan_{id}_{k}"));
                k += 1;
            }
            let mut w = BagWriter::create(&dir, self.options)?;
            for (t, ty, def, qos) in &self.topics {
                w.add_topic(t, ty, def, qos)?;
            }
            for (t, (stamp, d)) in &self.preroll {
                if t == "/tf_static" || stamp.is_none_or(|s| s <= start_ns) {
                    w.write(t, now, now, d)?;
                }
            }
            // What arrived before the event but belongs to the scan.
            for (at, t, stamp, d) in self.recent.drain(..) {
                if stamp.is_some_and(|s| s >= start_ns) {
                    w.write(&t, at, at, &d)?;
                }
            }
            log::info!("scan {id}: recording into {}", dir.display());
            self.writer = Some(w);
        }
        if topic == "/tf_static" || topic == "/tf" {
            self.preroll.insert(topic.to_string(), (m.stamp_ns(), data.clone()));
        }
        match &mut self.writer {
            Some(w) => w.write(topic, now, now, &data)?,
            None => {
                self.recent.push_back((now, topic.to_string(), m.stamp_ns(), data));
                while self.recent.front().is_some_and(|r| r.0 + GRACE_NS < now) {
                    self.recent.pop_front();
                }
            }
        }
        if let Some((id, xsurf_msgs::xsurf_msgs::ScanEvent::END | xsurf_msgs::xsurf_msgs::ScanEvent::ABORT, _)) = event
        {
            self.close_at = Some(now + GRACE_NS);
            log::info!("scan {id}: ended; its bag closes in 1 s");
        }
        Ok(())
    }

    /// Closes a scan's bag once its grace after END has passed.
    fn tick(&mut self, now: u64) -> anyhow::Result<()> {
        if self.close_at.is_some_and(|t| now >= t) {
            self.close()?;
        }
        Ok(())
    }

    /// Finishes the bag being written.
    fn close(&mut self) -> anyhow::Result<()> {
        self.close_at = None;
        if let Some(w) = self.writer.take() {
            w.finish()?;
        }
        Ok(())
    }
}

fn class_of(topic: &str, type_name: &str) -> QosClass {
    if topic == "/tf_static" {
        QosClass::Static
    } else if matches!(
        type_name,
        "sensor_msgs/msg/Image" | "sensor_msgs/msg/CompressedImage" | "sensor_msgs/msg/CameraInfo"
    ) {
        QosClass::Sensor
    } else {
        QosClass::Reliable
    }
}

fn bag_qos(c: QosClass) -> Qos {
    match c {
        QosClass::Sensor => Qos::SENSOR,
        QosClass::Reliable | QosClass::State => Qos::RELIABLE,
        QosClass::Static => Qos::STATIC,
    }
}

/// The receive time of a message: now, ns since the epoch.
fn now_ns() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

/// What a recording that failed leaves behind.
fn stopped(dir: &Path, written: u64) -> String {
    format!(
        "recording stopped after {written} messages; {} holds them up to its last complete chunk \
         (`xsurf bag info` reads it, `xsurf bag reindex` writes its metadata.yaml)",
        dir.display()
    )
}

/// Records until stopped; returns the number of messages written.
pub fn record(dir: &Path, opts: &RecordOptions) -> anyhow::Result<u64> {
    if !opts.all && opts.topics.is_empty() {
        bail!("name the topics to record, or --all");
    }
    let env = DdsEnv::from_env(|k| std::env::var(k).ok())?;
    let ctx = env.context()?;
    let mut node = dds::tool_node(&ctx, "xsurf_bag_recorder")?;
    let mut sink = Sink::new(dir, BagOptions { zstd: opts.zstd }, opts.split_by_scan)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))?;
    }
    let (tx, rx) = sync_channel(dds::QUEUE_DEPTH);
    let mut subscribed: Vec<String> = Vec::new();
    let mut drops = Vec::new();
    let mut wanted: BTreeMap<String, Option<String>> = opts.topics.iter().map(|t| (t.clone(), None)).collect();
    if opts.split_by_scan {
        // The scans are cut by their events, and each bag needs the frames' placement.
        for t in ["/scan/events", "/tf", "/tf_static"] {
            wanted.entry(t.to_string()).or_insert(None);
        }
    }
    let t0 = Instant::now();
    let mut last_discovery = None::<Instant>;
    let mut written = 0u64;
    while !stop.load(Ordering::SeqCst) && opts.duration_s.is_none_or(|d| t0.elapsed().as_secs_f64() < d) {
        if last_discovery.is_none_or(|t| t.elapsed() > Duration::from_millis(500)) {
            last_discovery = Some(Instant::now());
            for (topic, ty) in dds::discovered_topics(&ctx) {
                if subscribed.contains(&topic) || !Msg::TYPE_NAMES.contains(&ty.as_str()) {
                    continue;
                }
                if !opts.all && !wanted.contains_key(&topic) {
                    continue;
                }
                let class = class_of(&topic, &ty);
                let def = Msg::definition(&ty).context("definition")?;
                sink.add_topic(&topic, &ty, &def, bag_qos(class))?;
                drops.push((
                    topic.clone(),
                    dds::subscribe_forward(&mut node, &topic, &ty, class, subscribed.len(), tx.clone(), stop.clone())?,
                ));
                log::info!("recording {topic} ({ty})");
                wanted.insert(topic.clone(), Some(ty));
                subscribed.push(topic);
            }
        }
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok((i, m)) => {
                sink.write(&subscribed[i], now_ns(), &m).with_context(|| stopped(dir, written))?;
                written += 1;
            }
            Err(RecvTimeoutError::Timeout) => {
                sink.tick(now_ns()).with_context(|| stopped(dir, written))?;
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    // Messages already received are written before the bag is closed.
    while let Ok((i, m)) = rx.try_recv() {
        sink.write(&subscribed[i], now_ns(), &m).with_context(|| stopped(dir, written))?;
        written += 1;
    }
    for (t, d) in &drops {
        let n = d.load(Ordering::Relaxed);
        if n > 0 {
            log::warn!("{t}: {n} message(s) dropped: the recorder could not keep up");
        }
    }
    for (t, ty) in &wanted {
        if ty.is_none() {
            log::warn!("{t}: never discovered; not recorded");
        }
    }
    sink.close().with_context(|| stopped(dir, written))?;
    stop.store(true, Ordering::SeqCst);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;
    use xsurf_msgs::builtin_interfaces::Time;
    use xsurf_msgs::geometry_msgs::TransformStamped;
    use xsurf_msgs::std_msgs::Header;
    use xsurf_msgs::tf2_msgs::TFMessage;
    use xsurf_msgs::xsurf_msgs::ScanEvent;

    fn header(stamp_ns: i64) -> Header {
        Header { stamp: Time::from_nanos(stamp_ns), frame_id: "table".into() }
    }

    fn tf(stamp_ns: i64) -> Msg {
        let t = TransformStamped { header: header(stamp_ns), child_frame_id: "carm".into(), ..Default::default() };
        Msg::Tf(Arc::new(TFMessage { transforms: vec![t] }))
    }

    fn event(stamp_ns: i64, event: u8) -> Msg {
        Msg::ScanEvent(Arc::new(ScanEvent { header: header(stamp_ns), scan_id: 1, event }))
    }

    /// The stamps of a bag's `/tf`, in the order written.
    fn tf_stamps(dir: &Path) -> Vec<i64> {
        let bag = xsurf_formats::bag::Bag::open(dir).unwrap();
        bag.messages()
            .map(Result::unwrap)
            .filter(|m| m.topic == "/tf")
            .map(|m| match Msg::decode("tf2_msgs/msg/TFMessage", &m.data).unwrap() {
                Msg::Tf(t) => t.transforms[0].header.stamp.nanos(),
                _ => unreachable!(),
            })
            .collect()
    }

    /// A bag played twice: the second scan's START arrives before its own earliest transforms
    /// (another DDS writer), so the last `/tf` heard is the first play's, stamped after the
    /// second scan's START. The second scan's bag must not begin with it.
    #[test]
    fn a_scans_bag_begins_with_no_transform_from_after_its_start() {
        let dir = std::env::temp_dir().join(format!("xsurf-record-preroll-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut sink = Sink::new(&dir, BagOptions { zstd: false }, true).unwrap();
        sink.add_topic("/tf", "tf2_msgs/msg/TFMessage", "", Qos::RELIABLE).unwrap();
        sink.add_topic("/scan/events", "xsurf_msgs/msg/ScanEvent", "", Qos::RELIABLE).unwrap();
        let s: i64 = 1_000_000_000;
        let mut now: u64 = 5_000_000_000;
        let mut put = |sink: &mut Sink, topic: &str, m: Msg, dt: u64| {
            now += dt;
            sink.write(topic, now, &m).unwrap();
        };
        // First play: a transform before START, the scan, END.
        put(&mut sink, "/tf", tf(90 * s / 100), 0);
        put(&mut sink, "/scan/events", event(95 * s / 100, ScanEvent::START), 10_000_000);
        put(&mut sink, "/tf", tf(2 * s), 10_000_000);
        put(&mut sink, "/scan/events", event(26 * s / 10, ScanEvent::END), 10_000_000);
        put(&mut sink, "/tf", tf(267 * s / 100), 10_000_000);
        // Second play, 3 s on: START first, then its earlier transforms.
        put(&mut sink, "/scan/events", event(95 * s / 100, ScanEvent::START), 3_000_000_000);
        put(&mut sink, "/tf", tf(90 * s / 100), 3_000_000);
        put(&mut sink, "/tf", tf(2 * s), 10_000_000);
        sink.close().unwrap();
        // The first bag also holds the transform heard within its grace after END.
        assert_eq!(tf_stamps(&dir.join("scan_1")), [90 * s / 100, 2 * s, 267 * s / 100]);
        assert_eq!(tf_stamps(&dir.join("scan_1_2")), [90 * s / 100, 2 * s]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
