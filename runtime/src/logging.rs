//! A small `log` backend: `[LEVEL] [logger]: message` on stderr, with a global level and
//! per-logger levels (the ROS 2 `--log-level` forms). RustDDS' per-datagram warnings and
//! ros2-client's informational chatter are quiet unless asked for by logger name.

use std::sync::{Mutex, OnceLock};

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
            let msg = r.args().to_string();
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
    let l = LOGGER.get_or_init(|| Logger { level, per: per_logger });
    if log::set_logger(l).is_ok() {
        log::set_max_level(max);
    }
}
