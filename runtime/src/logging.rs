//! A small `log` backend: `[LEVEL] [logger]: message` on stderr, with a global level and
//! per-logger levels (the ROS 2 `--log-level` forms). RustDDS' per-datagram warnings and
//! ros2-client's informational chatter are quiet unless asked for by logger name, and a
//! library's record repeated from one source line is printed at most [`REPEAT_BURST`] times in
//! [`REPEAT_WINDOW`] (RustDDS logs an error for every NACK_FRAG of a large sample under repair:
//! about a million lines in 30 s for two 1920x1200 clouds).

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

/// Where log records also go (the node's `/rosout` publisher), set once a node exists.
pub type RosoutSink = Box<dyn Fn(log::Level, &str, &str) + Send + Sync>;
static ROSOUT: Mutex<Option<RosoutSink>> = Mutex::new(None);

/// Forwards xsurf's own log records (info and above) to `sink` from now on.
pub fn set_rosout(sink: RosoutSink) {
    if let Ok(mut g) = ROSOUT.lock() {
        *g = Some(sink);
    }
}

struct Logger {
    level: log::LevelFilter,
    per: Vec<(String, log::LevelFilter)>,
    repeats: Mutex<Repeats>,
}

/// Records a library may print from one source line in [`REPEAT_WINDOW`].
pub const REPEAT_BURST: u32 = 5;
/// The window over which a library's repeated records are counted.
pub const REPEAT_WINDOW: Duration = Duration::from_secs(10);

/// Where a record comes from: its module and line.
type Source = (Option<&'static str>, Option<u32>);

/// Counts each source line's records in its current window.
#[derive(Default)]
struct Repeats {
    /// Per source: the window's start, records seen in it, and records held back before it.
    seen: HashMap<Source, (Instant, u32, u32)>,
}

impl Repeats {
    /// Whether a record from `source` at `now` is printed, and if so how many from the same
    /// source were held back since the last one printed.
    fn admit(&mut self, source: Source, now: Instant) -> Option<u32> {
        let (start, count, held) = self.seen.entry(source).or_insert((now, 0, 0));
        if now.duration_since(*start) >= REPEAT_WINDOW {
            *start = now;
            *count = 0;
        }
        *count += 1;
        if *count > REPEAT_BURST {
            *held += 1;
            return None;
        }
        Some(std::mem::take(held))
    }
}

static LOGGER: OnceLock<Logger> = OnceLock::new();

impl log::Log for Logger {
    fn enabled(&self, m: &log::Metadata<'_>) -> bool {
        let target = m.target();
        let level = self
            .per
            .iter()
            .filter(|(name, _)| target.starts_with(name.as_str()))
            .max_by_key(|(name, _)| name.len())
            .map(|(_, l)| *l)
            .unwrap_or(if target.starts_with("rustdds") || target.starts_with("ros2_client::distributions") {
                // RustDDS is verbose at warn; ros2-client warns at every start that ROS_DISTRO is
                // not set, which it need not be here (no ROS install).
                log::LevelFilter::Error
            } else if target.starts_with("ros2_client") {
                self.level.min(log::LevelFilter::Warn)
            } else {
                self.level
            });
        m.level() <= level
    }
    fn log(&self, r: &log::Record<'_>) {
        if self.enabled(r.metadata()) {
            // A record held back is dropped before it is formatted.
            let held = if r.target().starts_with("xsurf") {
                0
            } else {
                let Ok(mut repeats) = self.repeats.lock() else { return };
                let Some(held) = repeats.admit((r.module_path_static(), r.line()), Instant::now()) else { return };
                held
            };
            let mut msg = r.args().to_string();
            if held > 0 {
                msg.push_str(&format!(" ({held} more from the same place not shown)"));
            }
            eprintln!("[{}] [{}]: {msg}", r.level(), r.target());
            if r.level() <= log::Level::Info && r.target().starts_with("xsurf") {
                if let Ok(g) = ROSOUT.try_lock() {
                    if let Some(sink) = g.as_ref() {
                        sink(r.level(), r.target(), &msg);
                    }
                }
            }
        }
    }
    fn flush(&self) {}
}

/// Installs the logger (once; later calls are ignored).
pub fn init(level: log::LevelFilter, per_logger: Vec<(String, log::LevelFilter)>) {
    let max = per_logger.iter().map(|p| p.1).chain([level]).max().unwrap_or(level);
    let l = LOGGER.get_or_init(|| Logger { level, per: per_logger, repeats: Mutex::default() });
    if log::set_logger(l).is_ok() {
        log::set_max_level(max);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_repeated_library_record_is_held_back_and_counted() {
        let mut r = Repeats::default();
        let (a, b): (Source, Source) = ((Some("rustdds::x"), Some(7)), (Some("rustdds::x"), Some(8)));
        let t0 = Instant::now();
        for k in 0..REPEAT_BURST {
            assert_eq!(r.admit(a, t0 + Duration::from_millis(u64::from(k))), Some(0));
        }
        for k in 0..100 {
            assert_eq!(r.admit(a, t0 + Duration::from_millis(100 + k)), None);
        }
        // Another line is counted apart.
        assert_eq!(r.admit(b, t0 + Duration::from_secs(1)), Some(0));
        // The next window prints again, with the count of what was held back.
        assert_eq!(r.admit(a, t0 + REPEAT_WINDOW + Duration::from_millis(1)), Some(100));
        assert_eq!(r.admit(a, t0 + REPEAT_WINDOW + Duration::from_millis(2)), Some(0));
    }
}
