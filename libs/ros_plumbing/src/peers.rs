//! Who is at the other end of a node's topics.
//!
//! A node watches some of its endpoints: for a subscription, how many remote
//! publishers it has matched; for a publisher, how many remote subscriptions. When a
//! topic that had peers loses them all (the other node stopped, or the network went
//! down for longer than the DDS lease), that is a *lost* peer; when they come back, a
//! *regained* one. [`PeerWatch`] is the pure state machine: the node feeds it the
//! current counts, logs the events it returns and adds [`PeerWatch::annotate`] to its
//! `diagnostics` entry.

use eezybot_msgs::diagnostic_msgs::{DiagnosticStatus, KeyValue};
use std::time::{Duration, Instant};

/// What is at the other end of a watched endpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Peer {
    /// Remote publishers of one of our subscriptions.
    Publisher,
    /// Remote subscriptions of one of our publishers.
    Subscriber,
}

impl Peer {
    fn noun(self) -> &'static str {
        match self {
            Peer::Publisher => "publisher",
            Peer::Subscriber => "subscriber",
        }
    }
}

/// A change of a watched topic's peers.
#[derive(Clone, Debug, PartialEq)]
pub enum PeerEvent {
    /// The first peer matched (at start, or a node that started later).
    Found {
        /// The topic (as resolved, e.g. `/servo_angles`).
        topic: String,
        /// What was found.
        peer: Peer,
    },
    /// Every peer is gone.
    Lost {
        /// The topic.
        topic: String,
        /// What was lost.
        peer: Peer,
    },
    /// Peers are back after a loss.
    Regained {
        /// The topic.
        topic: String,
        /// What came back.
        peer: Peer,
        /// How long there was none.
        after: Duration,
    },
}

impl PeerEvent {
    /// Log the event: a loss is a warning, the rest information.
    pub fn log(&self) {
        match self {
            PeerEvent::Found { topic, peer } => log::info!("{topic}: {} found", peer.noun()),
            PeerEvent::Lost { topic, peer } => log::warn!(
                "{topic}: {} lost (a node stopped, or the network is down)",
                peer.noun()
            ),
            PeerEvent::Regained { topic, peer, after } => log::info!(
                "{topic}: {} regained after {:.1} s",
                peer.noun(),
                after.as_secs_f64()
            ),
        }
    }
}

#[derive(Debug)]
struct Watched {
    topic: String,
    peer: Peer,
    count: usize,
    matched_once: bool,
    lost: u64,
    regained: u64,
    lost_at: Option<Instant>,
}

/// The watched topics of one node and what happened to their peers.
///
/// # Examples
/// ```
/// use ros_plumbing::peers::{Peer, PeerEvent, PeerWatch};
/// use std::time::{Duration, Instant};
/// let mut w = PeerWatch::new(&[("/servo_angles".into(), Peer::Publisher)]);
/// let t0 = Instant::now();
/// assert!(matches!(w.update(&[1], t0)[0], PeerEvent::Found { .. }));
/// assert!(matches!(w.update(&[0], t0)[0], PeerEvent::Lost { .. }));
/// let back = w.update(&[1], t0 + Duration::from_secs(3));
/// assert!(matches!(back[0], PeerEvent::Regained { after, .. } if after == Duration::from_secs(3)));
/// ```
#[derive(Debug, Default)]
pub struct PeerWatch {
    watched: Vec<Watched>,
}

impl PeerWatch {
    /// Watch these topics (resolved names), in the order [`PeerWatch::update`]'s counts come.
    pub fn new(topics: &[(String, Peer)]) -> PeerWatch {
        PeerWatch {
            watched: topics
                .iter()
                .map(|(topic, peer)| Watched {
                    topic: topic.clone(),
                    peer: *peer,
                    count: 0,
                    matched_once: false,
                    lost: 0,
                    regained: 0,
                    lost_at: None,
                })
                .collect(),
        }
    }

    /// The current peer counts, one per watched topic; returns what changed.
    pub fn update(&mut self, counts: &[usize], now: Instant) -> Vec<PeerEvent> {
        let mut events = Vec::new();
        for (w, &count) in self.watched.iter_mut().zip(counts) {
            let (topic, peer) = (w.topic.clone(), w.peer);
            match (w.count, count) {
                (0, n) if n > 0 && !w.matched_once => {
                    w.matched_once = true;
                    events.push(PeerEvent::Found { topic, peer });
                }
                (0, n) if n > 0 => {
                    w.regained += 1;
                    let after = w.lost_at.take().map(|t| now - t).unwrap_or_default();
                    events.push(PeerEvent::Regained { topic, peer, after });
                }
                (n, 0) if n > 0 => {
                    w.lost += 1;
                    w.lost_at = Some(now);
                    events.push(PeerEvent::Lost { topic, peer });
                }
                _ => {}
            }
            w.count = count;
        }
        events
    }

    /// Topics whose peers are lost now, with how long ago.
    pub fn lost_now(&self, now: Instant) -> Vec<(String, Peer, Duration)> {
        self.watched
            .iter()
            .filter_map(|w| w.lost_at.map(|t| (w.topic.clone(), w.peer, now - t)))
            .collect()
    }

    /// Add the peers to a node's diagnostics entry: per topic the number of peers now
    /// and how often they were lost and regained. While a peer is lost, an OK entry
    /// becomes WARN and its message says which.
    pub fn annotate(&self, status: &mut DiagnosticStatus, now: Instant) {
        for w in &self.watched {
            let what = format!("{} {}s", w.topic, w.peer.noun());
            status.values.push(KeyValue {
                key: what.clone(),
                value: w.count.to_string(),
            });
            status.values.push(KeyValue {
                key: format!("{what} lost"),
                value: w.lost.to_string(),
            });
            status.values.push(KeyValue {
                key: format!("{what} regained"),
                value: w.regained.to_string(),
            });
        }
        let lost = self.lost_now(now);
        if !lost.is_empty() {
            let text = lost
                .iter()
                .map(|(topic, peer, ago)| {
                    format!(
                        "{topic}: {} lost {:.0} s ago",
                        peer.noun(),
                        ago.as_secs_f64()
                    )
                })
                .collect::<Vec<_>>()
                .join(", ");
            if status.level == DiagnosticStatus::OK {
                status.level = DiagnosticStatus::WARN;
                status.message = text;
            } else {
                status.message = format!("{}; {text}", status.message);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn watch() -> PeerWatch {
        PeerWatch::new(&[
            ("/servo_angles".into(), Peer::Publisher),
            ("/servo_state".into(), Peer::Subscriber),
        ])
    }

    fn ok() -> DiagnosticStatus {
        DiagnosticStatus {
            level: DiagnosticStatus::OK,
            name: "serial_node: servo link".into(),
            message: "connected".into(),
            hardware_id: String::new(),
            values: vec![],
        }
    }

    #[test]
    fn no_peer_yet_is_not_a_loss() {
        let mut w = watch();
        let t = Instant::now();
        assert!(w.update(&[0, 0], t).is_empty());
        let mut s = ok();
        w.annotate(&mut s, t);
        assert_eq!(s.level, DiagnosticStatus::OK);
    }

    #[test]
    fn loss_and_return_are_counted_and_shown() {
        let mut w = watch();
        let t0 = Instant::now();
        assert_eq!(w.update(&[1, 2], t0).len(), 2);
        assert_eq!(
            w.update(&[0, 2], t0 + Duration::from_secs(1)),
            vec![PeerEvent::Lost {
                topic: "/servo_angles".into(),
                peer: Peer::Publisher
            }]
        );
        let mut s = ok();
        w.annotate(&mut s, t0 + Duration::from_secs(4));
        assert_eq!(s.level, DiagnosticStatus::WARN);
        assert_eq!(s.message, "/servo_angles: publisher lost 3 s ago");
        let events = w.update(&[2, 2], t0 + Duration::from_secs(5));
        assert_eq!(
            events,
            vec![PeerEvent::Regained {
                topic: "/servo_angles".into(),
                peer: Peer::Publisher,
                after: Duration::from_secs(4)
            }]
        );
        let mut s = ok();
        w.annotate(&mut s, t0 + Duration::from_secs(5));
        assert_eq!(s.level, DiagnosticStatus::OK);
        let v = |k: &str| {
            s.values
                .iter()
                .find(|kv| kv.key == k)
                .map(|kv| kv.value.clone())
        };
        assert_eq!(v("/servo_angles publishers").as_deref(), Some("2"));
        assert_eq!(v("/servo_angles publishers lost").as_deref(), Some("1"));
        assert_eq!(v("/servo_angles publishers regained").as_deref(), Some("1"));
        assert_eq!(v("/servo_state subscribers lost").as_deref(), Some("0"));
    }

    #[test]
    fn a_worse_status_keeps_its_level_and_names_the_loss_too() {
        let mut w = watch();
        let t0 = Instant::now();
        w.update(&[1, 1], t0);
        w.update(&[1, 0], t0);
        let mut s = ok();
        s.level = DiagnosticStatus::ERROR;
        s.message = "not connected".into();
        w.annotate(&mut s, t0);
        assert_eq!(s.level, DiagnosticStatus::ERROR);
        assert_eq!(
            s.message,
            "not connected; /servo_state: subscriber lost 0 s ago"
        );
    }

    #[test]
    fn fewer_peers_but_not_none_is_no_loss() {
        let mut w = watch();
        let t0 = Instant::now();
        w.update(&[3, 1], t0);
        assert!(w.update(&[1, 1], t0).is_empty());
    }
}
