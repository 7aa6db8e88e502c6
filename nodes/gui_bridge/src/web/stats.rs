//! The web side's counters and log lines, kept by one owner.
//!
//! The web server's tasks (each HTTP request, each WebSocket client) share none of
//! this: each sends what happened as a [`WebEvent`] on a bounded channel
//! ([`RequestSenders::report`](super::RequestSenders::report)), and the bridge loop,
//! which owns the one [`WebStats`], applies it with `&mut self` and reads it for
//! `diagnostics`. No lock is shared between tasks. The accept path needs one thing at
//! once, room for another client, and has it from a semaphore
//! ([`WebState::slots`](super::WebState::slots)), not from these counters.
//!
//! Everything here is pure: the time is passed in, and a log line is returned
//! ([`LogLine`]) for the caller to write, so the once-per-address and throttled lines
//! are tested with fixed times.

use super::{ClientEnd, REASON_MAX};
use crate::access::Refusal;
use ros_plumbing::logging::{shorten, Throttle};
use std::collections::HashSet;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::time::Instant;

/// A line for the log: its level and text.
pub type LogLine = (log::Level, String);

/// What happened on the web side, as a connection task reports it to the stats' owner.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum WebEvent {
    /// A request refused by the access policy.
    Refused {
        /// the client's address, when known
        who: Option<SocketAddr>,
        /// the request (`GET /ws`)
        what: String,
        /// why
        refusal: Refusal,
    },
    /// A WebSocket upgrade refused because `max_clients` clients were connected.
    Busy {
        /// the client's address, when known
        who: Option<SocketAddr>,
        /// the limit
        max_clients: usize,
    },
    /// A client's WebSocket is open.
    Connected,
    /// A message from `from` that is no request (`reason`: why not).
    BadRequest {
        /// the client's address
        from: String,
        /// why it is no request
        reason: String,
    },
    /// A client's connection ended (after [`WebEvent::Connected`]).
    Ended {
        /// the client's address
        from: String,
        /// how
        end: ClientEnd,
        /// the messages from it that were no request
        bad_requests: u64,
    },
    /// A WebSocket upgrade failed after the HTTP request was taken.
    UpgradeFailed {
        /// the client's address
        from: String,
        /// the error
        error: String,
    },
}

/// Refused clients whose refusal is logged; past this many, refusals are only counted.
const MAX_LOGGED_REFUSALS: usize = 1024;

/// Counters of the web side, for `diagnostics`: a plain value, owned by the bridge loop.
#[derive(Debug, Default)]
pub struct WebStats {
    clients: u64,
    refused_origin: u64,
    refused_host: u64,
    refused_token: u64,
    refused_busy: u64,
    oversized: u64,
    bad_requests: u64,
    rejected: u64,
    clients_closed: u64,
    clients_dropped: u64,
    dropped_replies: u64,
    dropped_broadcasts: u64,
    stalled: u64,
    evicted: u64,
    last_refusal: Option<(Instant, String)>,
    logged: HashSet<(IpAddr, &'static str)>,
    last_rejection: Option<String>,
    last_drop: Option<String>,
    complaints: Throttle,
    /// the Foxglove server's front, when it runs (its refusals are reported with ours;
    /// its counters are its own, read here)
    foxglove: Option<Arc<foxglove_bridge::FrontStats>>,
}

impl WebStats {
    /// The same, reporting the Foxglove server's front counters with the panel's.
    pub fn with_foxglove(mut self, front: Option<Arc<foxglove_bridge::FrontStats>>) -> WebStats {
        self.foxglove = front;
        self
    }

    /// How many panel clients (WebSockets) are connected.
    pub fn clients(&self) -> u64 {
        self.clients
    }

    /// Apply what a connection task reported at `now`; the line to log, if any.
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::web::{WebEvent, WebStats};
    /// let (mut stats, t0) = (WebStats::default(), std::time::Instant::now());
    /// assert_eq!(stats.on_event(WebEvent::Connected, t0), None);
    /// assert!(stats.values().contains(&("clients", "1".to_string())));
    /// ```
    pub fn on_event(&mut self, event: WebEvent, now: Instant) -> Option<LogLine> {
        match event {
            WebEvent::Refused { who, what, refusal } => {
                *match refusal.kind() {
                    "origin" => &mut self.refused_origin,
                    "host" => &mut self.refused_host,
                    _ => &mut self.refused_token,
                } += 1;
                self.note(who, refusal.kind(), format!("{what}: {refusal}"), now)
            }
            WebEvent::Busy { who, max_clients } => {
                self.refused_busy += 1;
                let reason = format!("WebSocket: {max_clients} clients are connected already");
                self.note(who, "busy", reason, now)
            }
            WebEvent::Connected => {
                self.clients += 1;
                None
            }
            WebEvent::BadRequest { from, reason } => {
                self.bad_requests += 1;
                self.rejected += 1;
                let reason = shorten(&reason, REASON_MAX);
                self.last_rejection = Some(format!("bad request: {reason}"));
                let quiet = self.complaints.allow("request/bad_request", now)?;
                let text = format!(
                    "bad request from {from} refused: {reason}{}",
                    Throttle::suffix(quiet)
                );
                Some((log::Level::Warn, text))
            }
            WebEvent::Ended {
                from,
                end,
                bad_requests,
            } => {
                self.clients = self.clients.saturating_sub(1);
                self.client_ended(&from, &end, bad_requests, now)
            }
            WebEvent::UpgradeFailed { from, error } => {
                let reason = format!("WebSocket upgrade failed: {}", shorten(&error, REASON_MAX));
                self.dropped(
                    &from,
                    "client/upgrade_failed",
                    log::Level::Warn,
                    reason,
                    "",
                    now,
                )
            }
        }
    }

    /// Log a refusal the first time this address is refused for this kind of reason (a
    /// page retrying every second logs one line, not one a second); remember it as the
    /// latest.
    fn note(
        &mut self,
        who: Option<SocketAddr>,
        kind: &'static str,
        reason: String,
        now: Instant,
    ) -> Option<LogLine> {
        let ip = who.map_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED), |a| a.ip());
        let from = who.map_or_else(|| "unknown address".to_string(), |a| a.ip().to_string());
        let first = self.logged.len() < MAX_LOGGED_REFUSALS && self.logged.insert((ip, kind));
        let line = first.then(|| {
            let text = format!("web panel refused {from}: {reason} (further refusals of {from} for this reason are counted in diagnostics, not logged)");
            (log::Level::Warn, text)
        });
        self.last_refusal = Some((now, format!("{from}: {reason}")));
        line
    }

    /// Count the end of `from`'s connection, after `bad_requests` bad requests from it;
    /// a drop is logged at most once per kind per [`Throttle::PERIOD`].
    fn client_ended(
        &mut self,
        from: &str,
        end: &ClientEnd,
        bad_requests: u64,
        now: Instant,
    ) -> Option<LogLine> {
        let after = if bad_requests > 0 {
            format!(" after {bad_requests} bad requests")
        } else {
            String::new()
        };
        if !end.is_drop() {
            if matches!(end, ClientEnd::Closed) {
                self.clients_closed += 1;
            }
            return Some((end.level(), format!("web client {from} left: {end}{after}")));
        }
        match end {
            ClientEnd::Oversized { .. } => self.oversized += 1,
            ClientEnd::Stalled { .. } => self.stalled += 1,
            ClientEnd::Evicted { .. } => self.evicted += 1,
            _ => {}
        }
        self.dropped(from, end.kind(), end.level(), end.to_string(), &after, now)
    }

    /// Count a dropped client, name it as the latest drop, and log it (throttled by
    /// `kind`).
    fn dropped(
        &mut self,
        from: &str,
        kind: &str,
        level: log::Level,
        reason: String,
        after: &str,
        now: Instant,
    ) -> Option<LogLine> {
        self.clients_dropped += 1;
        let line = format!("web client {from} dropped: {reason}{after}");
        self.last_drop = Some(format!("{from}: {reason}"));
        let quiet = self.complaints.allow(kind, now)?;
        Some((level, format!("{line}{}", Throttle::suffix(quiet))))
    }

    /// Count a request refused after parsing (`kind`:
    /// [`Refusal::kind`](crate::teleop::Refusal::kind)) at `now`; the line to log, once
    /// per kind per [`Throttle::PERIOD`] (an unreachable target at info: the operator is
    /// exploring the reach; the others at warn).
    pub fn rejected_request(&mut self, kind: &str, reason: &str, now: Instant) -> Option<LogLine> {
        self.rejected += 1;
        let reason = shorten(reason, REASON_MAX);
        self.last_rejection = Some(reason.to_string());
        let quiet = self.complaints.allow(&format!("request/{kind}"), now)?;
        let level = if kind == "unreachable" {
            log::Level::Info
        } else {
            log::Level::Warn
        };
        let text = format!(
            "web request refused ({kind}): {reason}{}",
            Throttle::suffix(quiet)
        );
        Some((level, text))
    }

    /// Count a reply dropped because a client's queue was full.
    pub fn dropped_reply(&mut self) {
        self.dropped_replies += 1;
    }

    /// Count a message to the browsers over [`super::MAX_BROADCAST_BYTES`], dropped; the
    /// line to log (once per [`Throttle::PERIOD`]), naming its kind and size.
    pub fn dropped_broadcast(&mut self, text: &str, now: Instant) -> Option<LogLine> {
        self.dropped_broadcasts += 1;
        let kind: String = text.chars().take(24).collect();
        let quiet = self.complaints.allow("broadcast/oversized", now)?;
        let line = format!(
            "a message of {} bytes to the browsers dropped (more than {}): {kind}…{}",
            text.len(),
            super::MAX_BROADCAST_BYTES,
            Throttle::suffix(quiet)
        );
        Some((log::Level::Warn, line))
    }

    /// The reason of the latest refused request.
    pub fn last_rejection(&self) -> Option<&str> {
        self.last_rejection.as_deref()
    }

    /// The latest refusal and when.
    pub fn last_refusal(&self) -> Option<&(Instant, String)> {
        self.last_refusal.as_ref()
    }

    /// All refusals so far.
    pub fn refused_total(&self) -> u64 {
        self.refused_origin + self.refused_host + self.refused_token + self.refused_busy
    }

    /// The counters as `diagnostics` key/values.
    pub fn values(&self) -> Vec<(&'static str, String)> {
        let text = |t: &Option<String>| t.clone().unwrap_or_default();
        let mut values = vec![
            ("clients", self.clients.to_string()),
            ("refused_origin", self.refused_origin.to_string()),
            ("refused_host", self.refused_host.to_string()),
            ("refused_token", self.refused_token.to_string()),
            ("refused_busy", self.refused_busy.to_string()),
            ("clients_closed", self.clients_closed.to_string()),
            ("clients_dropped", self.clients_dropped.to_string()),
            ("last_client_drop", text(&self.last_drop)),
            ("closed_oversized", self.oversized.to_string()),
            ("closed_stalled", self.stalled.to_string()),
            ("closed_waiting", self.evicted.to_string()),
            ("rejected", self.rejected.to_string()),
            ("bad_requests", self.bad_requests.to_string()),
            ("last_rejection", text(&self.last_rejection)),
            ("dropped_replies", self.dropped_replies.to_string()),
            ("dropped_broadcasts", self.dropped_broadcasts.to_string()),
        ];
        if let Some(f) = &self.foxglove {
            let get = |c: &std::sync::atomic::AtomicU64| {
                c.load(std::sync::atomic::Ordering::Relaxed).to_string()
            };
            values.extend([
                ("foxglove_refused", get(&f.refused)),
                ("foxglove_refused_busy", get(&f.refused_busy)),
                ("foxglove_closed_oversized", get(&f.closed_oversized)),
                ("foxglove_header_timeouts", get(&f.header_timeouts)),
                ("foxglove_oversized_samples", get(&f.oversized_samples)),
            ]);
        }
        values
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn value(stats: &WebStats, key: &str) -> String {
        let values = stats.values();
        let found = values.iter().find(|(k, _)| *k == key);
        found.map(|(_, v)| v.clone()).unwrap_or_default()
    }

    fn at(t0: Instant, s: u64) -> Instant {
        t0 + Duration::from_secs(s)
    }

    fn refused(port: u16, what: &str, refusal: Refusal) -> WebEvent {
        WebEvent::Refused {
            who: Some(SocketAddr::from(([127, 0, 0, 1], port))),
            what: what.into(),
            refusal,
        }
    }

    #[test]
    fn a_refusal_is_logged_once_per_address_and_kind_and_every_one_counted() {
        let (mut stats, t0) = (WebStats::default(), Instant::now());
        let token = || refused(5000, "GET /ws", Refusal::NoToken);
        let (level, line) = stats.on_event(token(), t0).unwrap();
        assert_eq!(level, log::Level::Warn);
        assert!(
            line.starts_with("web panel refused 127.0.0.1: GET /ws: "),
            "{line}"
        );
        // another port of the same address, later: counted, not logged
        assert_eq!(
            stats.on_event(refused(5001, "GET /", Refusal::WrongToken), at(t0, 60)),
            None
        );
        let host = refused(5002, "GET /ws", Refusal::NoHost);
        assert!(stats.on_event(host, at(t0, 61)).is_some(), "another kind");
        let busy = WebEvent::Busy {
            who: None,
            max_clients: 32,
        };
        let (_, line) = stats.on_event(busy.clone(), at(t0, 62)).unwrap();
        assert!(line.starts_with("web panel refused unknown address: WebSocket: 32 clients"));
        assert_eq!(stats.on_event(busy, at(t0, 63)), None);
        assert_eq!(
            (
                value(&stats, "refused_token"),
                value(&stats, "refused_host")
            ),
            ("2".into(), "1".into())
        );
        assert_eq!(
            (value(&stats, "refused_busy"), stats.refused_total()),
            ("2".into(), 5)
        );
        let (when, last) = stats.last_refusal().unwrap();
        assert_eq!(*when, at(t0, 63));
        assert!(
            last.starts_with("unknown address: WebSocket: 32 clients"),
            "{last}"
        );
    }

    #[test]
    fn complaints_are_throttled_by_kind_with_the_number_not_logged() {
        let (mut stats, t0) = (WebStats::default(), Instant::now());
        let bad = || WebEvent::BadRequest {
            from: "127.0.0.1:5000".into(),
            reason: "expected value".into(),
        };
        let (_, line) = stats.on_event(bad(), t0).unwrap();
        assert_eq!(
            line,
            "bad request from 127.0.0.1:5000 refused: expected value"
        );
        assert_eq!(stats.on_event(bad(), at(t0, 1)), None);
        assert_eq!(stats.on_event(bad(), at(t0, 2)), None);
        // a kind of its own
        let (level, _) = stats
            .rejected_request("unreachable", "out of reach", at(t0, 2))
            .unwrap();
        assert_eq!(level, log::Level::Info);
        assert_eq!(
            stats.rejected_request("unreachable", "out of reach", at(t0, 3)),
            None
        );
        let (_, line) = stats.on_event(bad(), at(t0, 5)).unwrap();
        assert!(
            line.ends_with(" (2 more like it in the last 5 s, not logged)"),
            "{line}"
        );
        assert_eq!(
            (value(&stats, "bad_requests"), value(&stats, "rejected")),
            ("4".into(), "6".into())
        );
        assert_eq!(stats.last_rejection(), Some("bad request: expected value"));
    }

    #[test]
    fn clients_are_counted_while_connected_and_their_ends_by_kind() {
        let (mut stats, t0) = (WebStats::default(), Instant::now());
        let ended = |port: u16, end: ClientEnd, bad_requests: u64| WebEvent::Ended {
            from: format!("127.0.0.1:{port}"),
            end,
            bad_requests,
        };
        for _ in 0..3 {
            stats.on_event(WebEvent::Connected, t0);
        }
        let (level, line) = stats
            .on_event(ended(5000, ClientEnd::Closed, 2), t0)
            .unwrap();
        assert_eq!(level, log::Level::Debug);
        assert_eq!(
            line,
            "web client 127.0.0.1:5000 left: closed by the client after 2 bad requests"
        );
        let stalled = ClientEnd::Stalled {
            timeout: Duration::from_secs(10),
        };
        let (level, line) = stats.on_event(ended(5001, stalled.clone(), 0), t0).unwrap();
        assert_eq!(level, log::Level::Warn);
        assert_eq!(
            line,
            "web client 127.0.0.1:5001 dropped: took no message within 10.0 s"
        );
        assert_eq!(stats.on_event(ended(5002, stalled, 0), at(t0, 1)), None);
        assert_eq!(value(&stats, "clients"), "0");
        let failed = WebEvent::UpgradeFailed {
            from: "127.0.0.1:5003".into(),
            error: "no upgrade header".into(),
        };
        let (_, line) = stats.on_event(failed, at(t0, 1)).unwrap();
        assert_eq!(
            line,
            "web client 127.0.0.1:5003 dropped: WebSocket upgrade failed: no upgrade header"
        );
        let counted = [
            "clients_closed",
            "clients_dropped",
            "closed_stalled",
            "closed_oversized",
        ];
        let counted: Vec<String> = counted.iter().map(|k| value(&stats, k)).collect();
        assert_eq!(counted, ["1", "3", "2", "0"]);
        assert_eq!(
            value(&stats, "last_client_drop"),
            "127.0.0.1:5003: WebSocket upgrade failed: no upgrade header"
        );
    }

    #[test]
    fn dropped_replies_are_counted_and_foxglove_reported_only_when_it_runs() {
        let mut stats = WebStats::default();
        stats.dropped_reply();
        assert_eq!(value(&stats, "dropped_replies"), "1");
        assert!(stats
            .values()
            .iter()
            .all(|(k, _)| !k.starts_with("foxglove_")));
        let front = Arc::new(foxglove_bridge::FrontStats::default());
        front
            .refused
            .fetch_add(3, std::sync::atomic::Ordering::Relaxed);
        let stats = stats.with_foxglove(Some(front));
        assert_eq!(value(&stats, "foxglove_refused"), "3");
        assert_eq!(value(&stats, "foxglove_header_timeouts"), "0");
    }
}
