//! Publishing `diagnostics` (diagnostic_msgs/DiagnosticArray), and what the graph's
//! nodes read in each other's: the status naming convention ([`status_node`]), the
//! refusal keys ([`REJECTED_STAMP_KEY`], [`LAST_REJECTION_KEY`], [`stamp_text`]), the
//! report period parameter ([`diagnostics_period`]) and latency percentiles
//! ([`LatencyWindow`]).

use crate::params::{ParamRange, ParamSpec, Params};
use crate::publisher::TopicPublisher;
use crate::security::CertificateExpiry;
use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use ros2_client::ParameterValue;
use std::collections::VecDeque;
use std::time::Duration;

/// The `diagnostics` key by which a node that takes targets (compute_ik) says it refused
/// one: its value is the refused target's `header.stamp` as [`stamp_text`] writes it.
/// A sender (gui_bridge `once`/`play`) knows its target was refused when a status
/// carries it with its target's stamp.
pub const REJECTED_STAMP_KEY: &str = "last_rejection_stamp";

/// The `diagnostics` key of the reason of the last refusal (`out of reach: …`).
pub const LAST_REJECTION_KEY: &str = "last_rejection";

/// A stamp as `SEC.NANOSEC`, nine digits of nanoseconds (`1712345678.000123456`), the
/// value of [`REJECTED_STAMP_KEY`].
///
/// # Examples
/// ```
/// use eezybot_msgs::Time;
/// use ros_plumbing::diagnostics::stamp_text;
/// assert_eq!(stamp_text(Time::new(1712345678, 123456)), "1712345678.000123456");
/// ```
pub fn stamp_text(stamp: Time) -> String {
    let ns = stamp.to_nanos();
    format!(
        "{}.{:09}",
        ns.div_euclid(1_000_000_000),
        ns.rem_euclid(1_000_000_000)
    )
}

/// Longest node name [`status_node`] accepts.
pub const NODE_NAME_MAX: usize = 64;

/// The node and the task a `diagnostics` status names, by diagnostic_updater's
/// convention `NODE: TASK` (every node of the graph follows it: `compute_ik: inverse
/// kinematics`, `ik2: inverse kinematics` under `-r __node:=ik2`); a name without `: `
/// is a node's name with no task. `None` unless NODE is a valid ROS node name of at
/// most [`NODE_NAME_MAX`] characters.
///
/// # Examples
/// ```
/// use ros_plumbing::diagnostics::status_node;
/// assert_eq!(status_node("ik2: inverse kinematics"), Some(("ik2", "inverse kinematics")));
/// assert_eq!(status_node("serial_node"), Some(("serial_node", "")));
/// assert_eq!(status_node("::::"), None);
/// ```
pub fn status_node(status_name: &str) -> Option<(&str, &str)> {
    let (node, task) = status_name
        .split_once(':')
        .map_or((status_name, ""), |(n, t)| (n, t.trim()));
    let valid = !node.is_empty()
        && node.len() <= NODE_NAME_MAX
        && node.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !node.starts_with(|c: char| c.is_ascii_digit());
    valid.then_some((node, task))
}

/// The `diagnostics_period` parameter every node declares: seconds between its
/// diagnostics reports, default 1, 0.05 … 60.
pub fn diagnostics_period_param() -> ParamSpec {
    ParamSpec::new(
        "diagnostics_period",
        ParameterValue::Double(1.0),
        "seconds between diagnostics reports",
    )
    .range(ParamRange::Double {
        min: 0.05,
        max: 60.0,
    })
}

/// The current `diagnostics_period` (1 s if unset).
pub fn diagnostics_period(params: &Params) -> Duration {
    Duration::from_secs_f64(params.f64("diagnostics_period").unwrap_or(1.0))
}

/// The value at fraction `p` (0 … 1) of `samples` sorted, the nearest rank rounded
/// (`p` = 0.5 of an even count is the upper median); `None` when there are none.
///
/// # Examples
/// ```
/// use ros_plumbing::diagnostics::percentile;
/// assert_eq!(percentile([3.0, 1.0, 2.0, 4.0], 0.5), Some(3.0));
/// assert_eq!(percentile([], 0.99), None);
/// ```
pub fn percentile(samples: impl IntoIterator<Item = f64>, p: f64) -> Option<f64> {
    let mut v: Vec<f64> = samples.into_iter().collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * p.clamp(0.0, 1.0)).round() as usize;
    v.get(i).copied()
}

/// The last `capacity` latencies, for percentiles in `diagnostics`.
///
/// # Examples
/// ```
/// use ros_plumbing::diagnostics::LatencyWindow;
/// let mut w = LatencyWindow::new(2);
/// let keys = ["tf_latency_us_p50", "tf_latency_us_p99"];
/// assert!(w.p50_p99(keys).is_empty());
/// for us in [100.0, 10.0, 20.0] {
///     w.push(us);
/// }
/// assert_eq!(w.len(), 2);
/// assert_eq!(w.p50_p99(keys)[0], ("tf_latency_us_p50", "20.0".to_string()));
/// ```
#[derive(Clone, Debug)]
pub struct LatencyWindow {
    samples: VecDeque<f64>,
    capacity: usize,
}

impl LatencyWindow {
    /// An empty window keeping the last `capacity` samples (at least one).
    pub fn new(capacity: usize) -> Self {
        LatencyWindow {
            samples: VecDeque::new(),
            capacity: capacity.max(1),
        }
    }

    /// Add a sample, forgetting the oldest when full.
    pub fn push(&mut self, sample: f64) {
        if self.samples.len() == self.capacity {
            self.samples.pop_front();
        }
        self.samples.push_back(sample);
    }

    /// How many samples it holds.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// [`percentile`] of the samples held.
    pub fn percentile(&self, p: f64) -> Option<f64> {
        percentile(self.samples.iter().copied(), p)
    }

    /// [`p50_p99`] of the samples held.
    pub fn p50_p99(&self, keys: [&'static str; 2]) -> Vec<(&'static str, String)> {
        p50_p99(self.samples.iter().copied(), keys)
    }
}

/// The median and the 99th percentile of `samples` under these two keys, with one
/// decimal, for a status' values; none when there are no samples.
pub fn p50_p99(
    samples: impl IntoIterator<Item = f64>,
    keys: [&'static str; 2],
) -> Vec<(&'static str, String)> {
    let v: Vec<f64> = samples.into_iter().collect();
    match (percentile(v.iter().copied(), 0.5), percentile(v, 0.99)) {
        (Some(p50), Some(p99)) => vec![
            (keys[0], format!("{p50:.1}")),
            (keys[1], format!("{p99:.1}")),
        ],
        _ => vec![],
    }
}

/// Build one status entry.
///
/// # Examples
/// ```
/// use ros_plumbing::diagnostics::status;
/// use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
/// let s = status(DiagnosticStatus::WARN, "compute_ik: inverse kinematics", "eezybot_arm",
///                "target out of reach", &[("rejected", "3".into())]);
/// assert_eq!(s.values[0].key, "rejected");
/// ```
pub fn status(
    level: u8,
    name: &str,
    hardware_id: &str,
    message: &str,
    values: &[(&str, String)],
) -> DiagnosticStatus {
    DiagnosticStatus {
        level,
        name: name.to_string(),
        message: message.to_string(),
        hardware_id: hardware_id.to_string(),
        values: values
            .iter()
            .map(|(k, v)| KeyValue {
                key: (*k).to_string(),
                value: v.clone(),
            })
            .collect(),
    }
}

/// A certificate this close to its end makes every report of the node a warning.
pub const CERTIFICATE_WARNING_DAYS: i64 = 30;

/// Adds a secured node's certificate expiry to one of its reports:
/// `certificate_expires` (UTC date) and `certificate_days_left`; within
/// [`CERTIFICATE_WARNING_DAYS`] of it (or past it) the report is at least a warning
/// and its message says which file to renew.
pub fn annotate_certificate(
    status: &mut DiagnosticStatus,
    expiry: &CertificateExpiry,
    now_unix: i64,
) {
    let days_left = (expiry.not_after - now_unix).div_euclid(86_400);
    let date = utc_date(expiry.not_after);
    status.values.push(KeyValue {
        key: "certificate_expires".into(),
        value: date.clone(),
    });
    status.values.push(KeyValue {
        key: "certificate_days_left".into(),
        value: days_left.to_string(),
    });
    if days_left < CERTIFICATE_WARNING_DAYS {
        status.level = status.level.max(DiagnosticStatus::WARN);
        let warning = format!(
            "{} expires on {date} ({days_left} days): renew it (docs/security.md: Certificates that expire)",
            expiry.path.display()
        );
        status.message = if status.message.is_empty() {
            warning
        } else {
            format!("{}; {warning}", status.message)
        };
    }
}

/// `YYYY-MM-DD` of a Unix time (UTC).
pub fn utc_date(unix: i64) -> String {
    let (y, m, d) = crate::sros2::civil_from_days(unix.div_euclid(86_400));
    format!("{y:04}-{m:02}-{d:02}")
}

/// Publishes a node's diagnostics on `diagnostics`.
pub struct DiagnosticsPublisher {
    publisher: TopicPublisher<DiagnosticArray>,
    certificate: Option<CertificateExpiry>,
}

impl DiagnosticsPublisher {
    /// Wrap a publisher created on the `diagnostics` topic.
    pub fn new(publisher: TopicPublisher<DiagnosticArray>) -> Self {
        DiagnosticsPublisher {
            publisher,
            certificate: None,
        }
    }

    /// Every report from now on carries the certificate's expiry ([`annotate_certificate`]).
    pub fn with_certificate(mut self, expiry: Option<CertificateExpiry>) -> Self {
        self.certificate = expiry;
        self
    }

    /// Another certificate the node serves with (the web panel's TLS certificate): the
    /// reports carry whichever of its certificates runs out first, naming that file.
    pub fn also_certificate(mut self, expiry: CertificateExpiry) -> Self {
        self.certificate = CertificateExpiry::earlier(self.certificate, expiry);
        self
    }

    /// Publish these statuses stamped now (a secured node's with its certificate's
    /// expiry). A failed write is logged, never fatal.
    pub fn publish(&self, mut status: Vec<DiagnosticStatus>) {
        if let Some(expiry) = &self.certificate {
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| i64::try_from(d.as_secs()).unwrap_or(i64::MAX));
            for s in &mut status {
                annotate_certificate(s, expiry, now);
            }
        }
        let msg = DiagnosticArray {
            header: Header {
                stamp: Time::now(),
                frame_id: String::new(),
            },
            status,
        };
        self.publisher.publish(msg);
    }
}

#[cfg(test)]
mod certificate_tests {
    use super::*;
    use std::path::PathBuf;

    fn expiry(days: i64) -> CertificateExpiry {
        CertificateExpiry {
            path: PathBuf::from("/k/enclaves/eezybot/pi/cert.pem"),
            not_after: 1_800_000_000 + days * 86_400,
        }
    }

    fn ok() -> DiagnosticStatus {
        status(
            DiagnosticStatus::OK,
            "serial_node: servo link",
            "eezybot_arm",
            "connected",
            &[],
        )
    }

    #[test]
    fn a_report_carries_the_certificate_expiry_and_stays_ok_far_from_it() {
        let mut s = ok();
        annotate_certificate(&mut s, &expiry(400), 1_800_000_000);
        assert_eq!(s.level, DiagnosticStatus::OK);
        assert_eq!(s.message, "connected");
        let v: Vec<_> = s
            .values
            .iter()
            .map(|kv| (kv.key.as_str(), kv.value.as_str()))
            .collect();
        assert_eq!(
            v,
            [
                ("certificate_expires", "2028-02-19"),
                ("certificate_days_left", "400")
            ]
        );
    }

    #[test]
    fn within_30_days_it_is_a_warning_that_names_the_file() {
        let mut s = ok();
        annotate_certificate(&mut s, &expiry(29), 1_800_000_000);
        assert_eq!(s.level, DiagnosticStatus::WARN);
        assert!(
            s.message
                .starts_with("connected; /k/enclaves/eezybot/pi/cert.pem expires on "),
            "{}",
            s.message
        );
        assert!(s.message.contains("(29 days): renew it"), "{}", s.message);
        let mut s = ok();
        annotate_certificate(&mut s, &expiry(30), 1_800_000_000);
        assert_eq!(s.level, DiagnosticStatus::OK);
        // an error stays an error; past the end the days go negative
        let mut e = status(DiagnosticStatus::ERROR, "x", "y", "", &[]);
        annotate_certificate(&mut e, &expiry(-2), 1_800_000_000);
        assert_eq!(e.level, DiagnosticStatus::ERROR);
        assert!(e.message.contains("(-2 days)"), "{}", e.message);
    }

    #[test]
    fn dates_are_utc_calendar_dates() {
        assert_eq!(utc_date(0), "1970-01-01");
        assert_eq!(utc_date(951_782_400), "2000-02-29");
        assert_eq!(utc_date(1_796_000_000), "2026-11-30"); // (checked with Python's datetime)
        assert_eq!(utc_date(-86_400), "1969-12-31");
    }
}
