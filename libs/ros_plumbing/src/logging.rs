//! The `log` crate's records on stderr (rcutils' format) and on `/rosout`.
//!
//! Records from this project's crates go to both; records from libraries (RustDDS…)
//! go to stderr only, and only from `warn` up unless the level is `debug`, so that a
//! library logging from inside a DDS callback can never loop through `/rosout`.

use ros2_client::log::LogLevel;
use ros2_client::{NodeLoggingHandle, RosoutRaw};
use std::io::Write;
use std::sync::OnceLock;

/// Crate-name prefixes of this project: their records are the node's own.
const OWN_TARGETS: &[&str] = &[
    "compute_ik",
    "serial_node",
    "state_publisher",
    "camera_node",
    "recorder",
    "lerobot_dataset",
    "gui_bridge",
    "ros_plumbing",
    "eezybot_",
];

struct NodeLogger {
    level: log::LevelFilter,
    stderr: bool,
    /// The node's logger name (`arm2.compute_ik`), set once the node exists.
    name: OnceLock<String>,
    rosout: OnceLock<NodeLoggingHandle>,
}

static LOGGER: OnceLock<NodeLogger> = OnceLock::new();

fn is_own(target: &str) -> bool {
    OWN_TARGETS.iter().any(|p| target.starts_with(p))
}

impl log::Log for NodeLogger {
    fn enabled(&self, meta: &log::Metadata<'_>) -> bool {
        // `tracing`'s span enter/exit records (target `tracing::span`, at the span's
        // level: ERROR for ros2-client's `rosout_raw`) reach `log` once any crate in the
        // build enables tracing's `log` feature (the foxglove SDK does): not messages
        if meta.target().starts_with("tracing::span") {
            return false;
        }
        let ceiling = if is_own(meta.target()) {
            self.level
        } else if meta.target() == "ros2_client::distributions" {
            // "ROS_DISTRO is not set": expected, these nodes need no ROS install.
            if self.level >= log::LevelFilter::Debug {
                log::LevelFilter::Warn
            } else {
                log::LevelFilter::Error
            }
        } else if self.level >= log::LevelFilter::Trace {
            // `--log-level trace`: the libraries' (RustDDS, ros2-client) debug output too
            log::LevelFilter::Debug
        } else if self.level >= log::LevelFilter::Debug {
            log::LevelFilter::Info
        } else {
            self.level.min(log::LevelFilter::Warn)
        };
        meta.level() <= ceiling
    }

    fn log(&self, record: &log::Record<'_>) {
        if !self.enabled(record.metadata()) {
            return;
        }
        // ros2-client's tracing echo of every /rosout message we publish ("[rosout]
        // (node) …"), which we have printed already; its own problems still show
        if record.target() == "ros2_client::rosout"
            && record.args().as_str().map_or_else(
                || record.args().to_string().starts_with("[rosout] ("),
                |m| m.starts_with("[rosout] ("),
            )
        {
            return;
        }
        let name = self.name.get().map(String::as_str).unwrap_or("-");
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        if self.stderr {
            let level = match record.level() {
                log::Level::Error => "ERROR",
                log::Level::Warn => "WARN",
                log::Level::Info => "INFO",
                log::Level::Debug | log::Level::Trace => "DEBUG",
            };
            let who = if is_own(record.target()) {
                name.to_string()
            } else {
                format!("{name}:{}", record.target())
            };
            // one write per line, so lines of several nodes on one terminal do not interleave
            let line = format!(
                "[{level}] [{}.{:09}] [{who}]: {}\n",
                now.as_secs(),
                now.subsec_nanos(),
                record.args()
            );
            let _ = std::io::stderr().lock().write_all(line.as_bytes());
        }
        if is_own(record.target()) {
            if let Some(handle) = self.rosout.get() {
                let level = match record.level() {
                    log::Level::Error => LogLevel::Error,
                    log::Level::Warn => LogLevel::Warn,
                    log::Level::Info => LogLevel::Info,
                    log::Level::Debug | log::Level::Trace => LogLevel::Debug,
                };
                handle.rosout_raw(
                    ros2_client::builtin_interfaces::Time::now(),
                    level,
                    name,
                    &record.args().to_string(),
                    record.file().unwrap_or(""),
                    record.module_path().unwrap_or(""),
                    record.line().unwrap_or(0),
                );
            }
        }
    }

    fn flush(&self) {
        let _ = std::io::stderr().flush();
    }
}

/// Install the logger (first call wins). Until [`attach_node`] runs, records go to
/// stderr only.
pub fn init(level: log::LevelFilter, stderr: bool) {
    let logger = LOGGER.get_or_init(|| NodeLogger {
        level,
        stderr,
        name: OnceLock::new(),
        rosout: OnceLock::new(),
    });
    if log::set_logger(logger).is_ok() {
        log::set_max_level(level);
    }
}

/// Name the node in log lines and, if `rosout` is given, publish records on `/rosout`.
pub fn attach_node(logger_name: String, rosout: Option<NodeLoggingHandle>) {
    if let Some(l) = LOGGER.get() {
        let _ = l.name.set(logger_name);
        if let Some(h) = rosout {
            let _ = l.rosout.set(h);
        }
    }
}

/// How often a repeated complaint about the same kind of bad input is logged: the
/// first one at once, then at most one line per [`Throttle::PERIOD`] saying how many
/// were not logged. A publisher sending a wrong message at 50 Hz gets a clear line,
/// not 50 a second on stderr and `/rosout` (every one is still counted in
/// `diagnostics`).
#[derive(Debug, Default)]
pub struct Throttle {
    kinds: std::collections::HashMap<String, (std::time::Instant, u64)>,
}

impl Throttle {
    /// Least time between two lines about one kind of input.
    pub const PERIOD: std::time::Duration = std::time::Duration::from_secs(5);

    /// Whether to log a complaint of `kind` now: `Some(n)` with the number of the same
    /// kind not logged since the last line, or `None` (counted, not logged).
    ///
    /// # Examples
    /// ```
    /// use ros_plumbing::logging::Throttle;
    /// use std::time::{Duration, Instant};
    /// let (mut t, t0) = (Throttle::default(), Instant::now());
    /// assert_eq!(t.allow("nan", t0), Some(0));
    /// assert_eq!(t.allow("nan", t0 + Duration::from_secs(1)), None);
    /// assert_eq!(t.allow("range", t0 + Duration::from_secs(1)), Some(0));
    /// assert_eq!(t.allow("nan", t0 + Duration::from_secs(2)), None);
    /// assert_eq!(t.allow("nan", t0 + Duration::from_secs(6)), Some(2));
    /// ```
    pub fn allow(&mut self, kind: &str, now: std::time::Instant) -> Option<u64> {
        match self.kinds.get_mut(kind) {
            Some((last, quiet)) if now.saturating_duration_since(*last) < Self::PERIOD => {
                *quiet += 1;
                None
            }
            Some((last, quiet)) => {
                let n = *quiet;
                *last = now;
                *quiet = 0;
                Some(n)
            }
            None => {
                if self.kinds.len() >= 256 {
                    self.kinds.clear(); // kinds are a handful; never grow without bound
                }
                self.kinds.insert(kind.to_string(), (now, 0));
                Some(0)
            }
        }
    }

    /// ` (N more like it not logged)` for a line [`Throttle::allow`] let through, or "".
    pub fn suffix(quiet: u64) -> String {
        if quiet == 0 {
            String::new()
        } else {
            format!(
                " ({quiet} more like it in the last {} s, not logged)",
                Self::PERIOD.as_secs()
            )
        }
    }
}

/// `text` cut to `max` characters for a log line or a diagnostics value, saying how
/// long it was: a 1 MB name in a bad message must not become a 1 MB log line.
///
/// # Examples
/// ```
/// use ros_plumbing::logging::shorten;
/// assert_eq!(shorten("base_servo", 64), "base_servo");
/// assert_eq!(shorten(&"x".repeat(100), 8), "xxxxxxxx… (100 bytes)");
/// ```
pub fn shorten(text: &str, max: usize) -> std::borrow::Cow<'_, str> {
    match text.char_indices().nth(max) {
        Some((i, _)) => format!("{}… ({} bytes)", &text[..i], text.len()).into(),
        None => text.into(),
    }
}

/// Someone else's text (a header value, a file name) for a message or log line: control
/// characters replaced with `?`, at most `max` characters, `…` after a cut.
/// ```
/// use ros_plumbing::logging::printable;
/// assert_eq!(printable("evil\r\nHost", 64), "evil??Host");
/// assert_eq!(printable(&"x".repeat(100), 8), "xxxxxxxx…");
/// ```
pub fn printable(text: &str, max: usize) -> String {
    let mut out: String = text
        .chars()
        .take(max)
        .map(|c| if c.is_control() { '?' } else { c })
        .collect();
    if text.chars().nth(max).is_some() {
        out.push('…');
    }
    out
}

/// The length names are cut to in log lines and diagnostics ([`shorten`]).
pub const NAME_MAX: usize = 64;
