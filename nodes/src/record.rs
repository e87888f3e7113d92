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
        QosClass::Reliable => Qos::RELIABLE,
        QosClass::Static => Qos::STATIC,
    }
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
    let mut writer = BagWriter::create(dir, BagOptions { zstd: opts.zstd })?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))?;
    }
    let (tx, rx) = sync_channel(dds::QUEUE_DEPTH);
    let mut subscribed: Vec<String> = Vec::new();
    let mut drops = Vec::new();
    let mut wanted: BTreeMap<String, Option<String>> = opts.topics.iter().map(|t| (t.clone(), None)).collect();
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
                writer.add_topic(&topic, &ty, &def, &bag_qos(class))?;
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
                let now = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_nanos() as u64);
                let data = m.encode()?;
                writer.write(&subscribed[i], now, now, &data).with_context(|| stopped(dir, written))?;
                written += 1;
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    // Messages already received are written before the bag is closed.
    while let Ok((i, m)) = rx.try_recv() {
        let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64);
        writer.write(&subscribed[i], now, now, &m.encode()?).with_context(|| stopped(dir, written))?;
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
    writer.finish().with_context(|| stopped(dir, written))?;
    stop.store(true, Ordering::SeqCst);
    Ok(written)
}
