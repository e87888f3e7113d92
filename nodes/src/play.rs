//! `xsurf bag play`: publishes a bag's messages over DDS with their original timing.

use anyhow::{bail, Context};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use xsurf_formats::bag::Bag;
use xsurf_runtime::component::{Msg, QosClass};
use xsurf_runtime::dds::{self, DdsEnv};

/// Options of `bag play`.
#[derive(Debug, Clone)]
pub struct PlayOptions {
    /// Playback rate (1 = real time).
    pub rate: f64,
    /// Play again from the start until interrupted.
    pub repeat: bool,
    /// Publish `/clock` (`rosgraph_msgs/msg/Clock`) with each message's time.
    pub clock: bool,
    /// Only these topics (all when empty).
    pub topics: Vec<String>,
    /// Skip this many seconds from the start.
    pub start_offset_s: f64,
    /// Wait this long after creating the publishers, for subscribers to match.
    pub delay_s: f64,
}

/// A publisher for each topic of the bag that is played (`--topics`, or all that xsurf knows),
/// with the bag's QoS: a transient-local topic as static, a best-effort one as a camera stream.
fn publishers(bag: &Bag, node: &mut dds::DdsNode, opts: &PlayOptions) -> anyhow::Result<BTreeMap<String, QosClass>> {
    let mut topics = BTreeMap::new();
    for t in &bag.metadata.topics {
        if !opts.topics.is_empty() && !opts.topics.contains(&t.name) {
            continue;
        }
        if !Msg::TYPE_NAMES.contains(&t.type_name.as_str()) {
            log::warn!("{}: type {} is not played (unknown to xsurf)", t.name, t.type_name);
            continue;
        }
        let class = match t.qos {
            Some(q) if q.transient_local => QosClass::Static,
            Some(q) if !q.reliable => QosClass::Sensor,
            _ => QosClass::Reliable,
        };
        node.add_publisher(&t.name, &t.type_name, class).with_context(|| format!("topic {}", t.name))?;
        topics.insert(t.name.clone(), class);
    }
    for t in &opts.topics {
        if !topics.contains_key(t) {
            bail!("topic {t} is not in the bag (or not playable)");
        }
    }
    Ok(topics)
}

/// Plays the bag; returns the number of messages published.
pub fn play(dir: &Path, opts: &PlayOptions) -> anyhow::Result<u64> {
    if !(opts.rate > 0.0 && opts.rate.is_finite()) {
        bail!("--rate {} must be > 0", opts.rate);
    }
    let bag = Bag::open(dir)?;
    let length_s = bag.metadata.duration_ns as f64 * 1e-9;
    if !(opts.start_offset_s >= 0.0 && opts.start_offset_s.is_finite()) {
        bail!("--start-offset {}: seconds from the bag's start, 0 or more", opts.start_offset_s);
    }
    if opts.start_offset_s > 0.0 && opts.start_offset_s >= length_s {
        bail!(
            "--start-offset {} s is past the end of {} ({length_s:.3} s long): nothing would be played",
            opts.start_offset_s,
            dir.display()
        );
    }
    let env = DdsEnv::from_env(|k| std::env::var(k).ok())?;
    let ctx = env.context()?;
    let mut node = dds::tool_node(&ctx, "xsurf_bag_player")?;
    let topics = publishers(&bag, &mut node, opts)?;
    if opts.clock {
        node.add_publisher("/clock", "rosgraph_msgs/msg/Clock", QosClass::Reliable)?;
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))?;
    }
    std::thread::sleep(Duration::from_secs_f64(opts.delay_s.max(0.0)));
    let start = bag.metadata.start_ns + (opts.start_offset_s.max(0.0) * 1e9) as u64;
    let mut published = 0u64;
    loop {
        let t0 = Instant::now();
        for m in bag.messages() {
            if stop.load(Ordering::SeqCst) {
                return Ok(published);
            }
            let m = m?;
            let Some(_) = topics.get(&m.topic) else { continue };
            if m.log_time_ns < start {
                continue;
            }
            let due = Duration::from_secs_f64((m.log_time_ns - start) as f64 * 1e-9 / opts.rate);
            if let Some(wait) = due.checked_sub(t0.elapsed()) {
                std::thread::sleep(wait);
            }
            let msg = match Msg::decode(&m.type_name, &m.data) {
                Ok(x) => x,
                Err(e) => {
                    log::warn!("{}: {e}", m.topic);
                    continue;
                }
            };
            if opts.clock {
                let c = xsurf_msgs::rosgraph_msgs::Clock {
                    clock: xsurf_msgs::builtin_interfaces::Time::from_nanos(m.log_time_ns as i64),
                };
                let _ = node.publish("/clock", &Msg::Clock(Arc::new(c)));
            }
            if let Err(e) = node.publish(&m.topic, &msg) {
                log::warn!("{}: publish failed: {e}", m.topic);
                continue;
            }
            published += 1;
        }
        if !opts.repeat {
            break;
        }
    }
    // Let reliable writers deliver the tail before the participant leaves.
    std::thread::sleep(Duration::from_millis(500));
    Ok(published)
}
