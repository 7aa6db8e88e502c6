//! The router's refusals, in its log at a normal level: Zenoh's access control says
//! what it refused only at trace level, one line per message, among as many lines for
//! what it allowed and for the permissions it caches when a client first uses a key
//! (`zenoh::net::routing::interceptor::access_control`, zenoh 1.10.2). [`Refusals`] is a
//! `tracing` layer that reads that target's events and prints
//!
//! ```text
//! eezybot_wan_router: refused: pi may not publish servo_angles (client 1a2b…; Put ingress)
//! ```
//!
//! once per client, kind and key, then how many more every [`REPEAT_EVERY`] at most
//! (on the next refusal after it). A client whose certificate matches no role is named
//! once (everything it sends is refused). Memory is bounded: at most [`MAX_TRACKED`]
//! (client, kind, key) entries; past that, further kinds are counted together.
//!
//! Which lines are decisions on real messages: `Using cached result: Z is unauthorized
//! to K on KEY`, and `Z on SUBJECT is unauthorized to K on KEY` unless it is one of the
//! nine that follow `ACL (FLOW): caching permissions for `KEY` ...` on the same thread
//! (the cache of every message kind for that key, computed when the key is first used:
//! not a message). The role comes from SUBJECT (Zenoh's
//! `Interface(…)+CertCommonName(…)+Transport(…)+zid`). Not said: a client declaring
//! its own admin space ([`own_admin_space`]).

use std::cell::RefCell;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use tracing::field::{Field, Visit};
use tracing::{Event, Subscriber};
use tracing_subscriber::layer::{Context, Layer};

use crate::acl::ROLES;

/// The target of Zenoh's access-control events.
pub const ACL_TARGET: &str = "zenoh::net::routing::interceptor::access_control";

/// A refusal repeated is counted, and said again at most this often.
pub const REPEAT_EVERY: Duration = Duration::from_secs(10);

/// Distinct (client, kind, key) refusals remembered.
pub const MAX_TRACKED: usize = 256;

/// The message kinds in the order `compute_keyexpr_cache` decides them.
const CACHE_ORDER: [&str; 9] = [
    "Query",
    "Reply",
    "Put",
    "Delete",
    "Declare/Undeclare Subscriber",
    "Declare/Undeclare Queryable",
    "Declare/Undeclare Liveliness Token",
    "Liveliness Query",
    "Declare Liveliness Subscriber",
];

/// One decision line of Zenoh's access control, parsed.
#[derive(Debug, PartialEq, Eq)]
pub enum Line<'a> {
    /// `ACL (FLOW): caching permissions for `KEY` ...`
    Caching { flow: &'a str, key: &'a str },
    /// A decision: `cached` if from the cache (then no subject is named).
    Decision {
        zid: &'a str,
        subject: Option<&'a str>,
        allowed: bool,
        kind: &'a str,
        flow: &'a str,
        key: &'a str,
        cached: bool,
    },
    /// `Z did not match any configured ACL subject. …`
    NoSubject { zid: &'a str },
}

/// Parse one message of [`ACL_TARGET`]; `None` for anything else.
pub fn parse(msg: &str) -> Option<Line<'_>> {
    if let Some(rest) = msg.strip_prefix("ACL (") {
        let (flow, rest) = rest.split_once("): caching permissions for `")?;
        let (key, _) = rest.split_once('`')?;
        return Some(Line::Caching { flow, key });
    }
    if let Some((zid, _)) = msg.split_once(" did not match any configured ACL subject") {
        return Some(Line::NoSubject { zid });
    }
    let (cached, rest) = match msg.strip_prefix("Using cached result: ") {
        Some(rest) => (true, rest),
        None => (false, msg),
    };
    let (who, allowed, rest) = if let Some((who, rest)) = rest.split_once(" is unauthorized to ") {
        (who, false, rest)
    } else {
        let (who, rest) = rest.split_once(" is authorized to ")?;
        (who, true, rest)
    };
    let (what, key) = rest.rsplit_once(" on ")?;
    let (kind, flow) = what.strip_suffix(')')?.rsplit_once(" (")?;
    let (zid, subject) = match who.split_once(" on ") {
        Some((zid, subject)) => (zid, Some(subject)),
        None => (who, None),
    };
    Some(Line::Decision {
        zid,
        subject,
        allowed,
        kind,
        flow,
        key,
        cached,
    })
}

/// The role named in a subject
/// (`Interface(w-pi)+CertCommonName(pi)+Transport(Tls)+zid`), if one of [`ROLES`].
fn role_in(subject: &str) -> Option<&'static str> {
    let cn = subject
        .split('+')
        .find_map(|p| p.strip_prefix("CertCommonName(")?.strip_suffix(')'))?;
    ROLES.iter().map(|r| r.name()).find(|r| *r == cn)
}

/// A client declaring its own admin space (`@/ZID/…`: every Zenoh session does, as it
/// opens): refused, as every `@/…` key is (nobody reaches a bridge's admin space
/// through the router), but expected, so not said.
fn own_admin_space(zid: &str, kind: &str, flow: &str, key: &str) -> bool {
    flow == "ingress"
        && matches!(kind, "Declare Subscriber" | "Declare Queryable")
        && key
            .strip_prefix("@/")
            .and_then(|k| k.strip_prefix(zid))
            .is_some_and(|k| k.starts_with('/'))
}

/// What a refused kind of message means, as "may not …".
pub fn verb(kind: &str, flow: &str) -> String {
    if flow == "egress" {
        return format!("be sent a {kind} on");
    }
    match kind {
        "Put" => "publish",
        "Delete" => "delete",
        "Query" => "query",
        "Reply" => "reply on",
        "Declare Subscriber" => "subscribe to",
        "Declare Queryable" => "serve queries on",
        "Liveliness Token" => "declare a liveliness token on",
        "Liveliness Query" => "query liveliness on",
        "Declare Liveliness Subscriber" => "subscribe to liveliness on",
        other => return format!("send a {other} on"),
    }
    .to_string()
}

#[derive(Default)]
struct Seen {
    last_said: Option<Instant>,
    unsaid: u64,
}

#[derive(Default)]
struct State {
    roles: HashMap<String, &'static str>,
    seen: HashMap<(String, String, String), Seen>,
    overflow: Seen,
}

thread_local! {
    /// (flow, key, index in CACHE_ORDER) while a cache computation's lines come.
    static CACHING: RefCell<Option<(String, String, usize)>> = const { RefCell::new(None) };
}

/// The layer (see the module's documentation). `say` prints one line.
pub struct Refusals {
    program: &'static str,
    state: Mutex<State>,
    say: Box<dyn Fn(&str) + Send + Sync>,
}

impl Refusals {
    /// Lines go to stderr, each prefixed `PROGRAM: `.
    pub fn new(program: &'static str) -> Self {
        Self::with_output(program, |line| eprintln!("{line}"))
    }

    /// Lines go to `say` (tests).
    pub fn with_output(program: &'static str, say: impl Fn(&str) + Send + Sync + 'static) -> Self {
        Refusals {
            program,
            state: Mutex::new(State::default()),
            say: Box::new(say),
        }
    }

    /// Take one message of [`ACL_TARGET`] (on the thread that logged it).
    pub fn take(&self, msg: &str) {
        let Some(line) = parse(msg) else { return };
        match line {
            Line::Caching { flow, key } => {
                CACHING.with(|c| *c.borrow_mut() = Some((flow.into(), key.into(), 0)));
            }
            Line::NoSubject { zid } => (self.say)(&format!(
                "{}: refused: client {zid} has no role: its certificate's common name is neither pc nor pi (a certificate made before roles: make it again with wan_certs.sh), so everything it sends is refused",
                self.program
            )),
            Line::Decision {
                zid,
                subject,
                allowed,
                kind,
                flow,
                key,
                cached,
            } => {
                if cached && allowed {
                    // the common case, every message let through: nothing to learn or say
                    CACHING.with(|c| *c.borrow_mut() = None);
                    return;
                }
                let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
                if let Some(role) = subject.and_then(role_in) {
                    if state.roles.len() < MAX_TRACKED || state.roles.contains_key(zid) {
                        state.roles.insert(zid.to_string(), role);
                    }
                }
                let of_cache = !cached
                    && CACHING.with(|c| {
                        let mut c = c.borrow_mut();
                        match c.as_mut() {
                            Some((f, k, i))
                                if f == flow && k == key && CACHE_ORDER.get(*i) == Some(&kind) =>
                            {
                                *i += 1;
                                if *i == CACHE_ORDER.len() {
                                    *c = None;
                                }
                                true
                            }
                            _ => {
                                *c = None;
                                false
                            }
                        }
                    });
                if cached {
                    CACHING.with(|c| *c.borrow_mut() = None);
                }
                // undeclarations follow their declaration's fate
                if allowed
                    || of_cache
                    || kind.starts_with("Undeclare")
                    || kind.contains('/')
                    || own_admin_space(zid, kind, flow, key)
                {
                    return;
                }
                self.refused(&mut state, zid, kind, flow, key);
            }
        }
    }

    fn refused(&self, state: &mut State, zid: &str, kind: &str, flow: &str, key: &str) {
        let who = match state.roles.get(zid) {
            Some(role) => format!("{role} (client {zid})"),
            None => format!("client {zid}"),
        };
        let mut line = format!(
            "{}: refused: {} may not {} {key}",
            self.program,
            who,
            verb(kind, flow)
        );
        let now = Instant::now();
        let id = (zid.to_string(), format!("{kind} {flow}"), key.to_string());
        let full = state.seen.len() >= MAX_TRACKED && !state.seen.contains_key(&id);
        let seen = if full {
            line = format!(
                "{}: refused: more kinds of message than tracked, the last: {} may not {} {key}",
                self.program,
                who,
                verb(kind, flow)
            );
            &mut state.overflow
        } else {
            state.seen.entry(id).or_default()
        };
        match seen.last_said {
            Some(t) if now.duration_since(t) < REPEAT_EVERY => seen.unsaid += 1,
            _ => {
                if seen.unsaid > 0 {
                    let _ = write!(
                        line,
                        " ({} more times since the last such line)",
                        seen.unsaid
                    );
                } else if seen.last_said.is_none() {
                    let _ = write!(
                        line,
                        " ({kind} {flow}; repeats counted, said again every {} s at most)",
                        REPEAT_EVERY.as_secs()
                    );
                }
                seen.last_said = Some(now);
                seen.unsaid = 0;
                (self.say)(&line);
            }
        }
    }
}

/// The `message` field of an event, formatted.
struct Message(String);

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.0, "{value:?}");
        }
    }
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.0.push_str(value);
        }
    }
}

impl<S: Subscriber> Layer<S> for Refusals {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        if event.metadata().target() != ACL_TARGET {
            return;
        }
        let mut m = Message(String::new());
        event.record(&mut m);
        self.take(&m.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    fn layer() -> (Refusals, Arc<Mutex<Vec<String>>>) {
        let lines = Arc::new(Mutex::new(Vec::new()));
        let l = lines.clone();
        (
            Refusals::with_output("r", move |s| l.lock().unwrap().push(s.to_string())),
            lines,
        )
    }

    const Z: &str = "3f2a";

    fn cache_lines(subject: &str, flow: &str, key: &str, allowed: &[&str]) -> Vec<String> {
        let mut v = vec![format!("ACL ({flow}): caching permissions for `{key}` ...")];
        for kind in CACHE_ORDER {
            let verdict = if allowed.contains(&kind) {
                "authorized"
            } else {
                "unauthorized"
            };
            v.push(format!(
                "{Z} on {subject} is {verdict} to {kind} ({flow}) on {key}"
            ));
        }
        v
    }

    #[test]
    fn parses_zenohs_lines() {
        assert_eq!(
            parse("ACL (ingress): caching permissions for `servo_angles` ..."),
            Some(Line::Caching {
                flow: "ingress",
                key: "servo_angles"
            })
        );
        assert_eq!(
            parse("Using cached result: 3f2a is unauthorized to Put (ingress) on servo_angles"),
            Some(Line::Decision {
                zid: "3f2a",
                subject: None,
                allowed: false,
                kind: "Put",
                flow: "ingress",
                key: "servo_angles",
                cached: true
            })
        );
        assert_eq!(
            parse("3f2a on Interface(w-pi)+CertCommonName(pi)+Transport(Tls)+3f2a is authorized to Declare Liveliness Subscriber (egress) on @/*/@ros2_lv/**"),
            Some(Line::Decision {
                zid: "3f2a",
                subject: Some("Interface(w-pi)+CertCommonName(pi)+Transport(Tls)+3f2a"),
                allowed: true,
                kind: "Declare Liveliness Subscriber",
                flow: "egress",
                key: "@/*/@ros2_lv/**",
                cached: false
            })
        );
        assert_eq!(parse("Access control is enabled"), None);
    }

    #[test]
    fn a_refused_put_is_said_once_then_counted_and_cache_lines_are_not_refusals() {
        let (r, lines) = layer();
        // the Pi's bridge subscribing to servo_angles: the cache says put is not
        // allowed, but no put was refused
        for l in cache_lines(
            "Interface(w-pi)+CertCommonName(pi)+Transport(Tls)+3f2a",
            "ingress",
            "servo_angles",
            &["Declare/Undeclare Subscriber"],
        ) {
            r.take(&l);
        }
        r.take(&format!("Using cached result: {Z} is authorized to Declare Subscriber (ingress) on servo_angles"));
        assert!(
            lines.lock().unwrap().is_empty(),
            "{:?}",
            lines.lock().unwrap()
        );
        // then it publishes there: refused, said once, then counted
        for _ in 0..3 {
            r.take(&format!(
                "Using cached result: {Z} is unauthorized to Put (ingress) on servo_angles"
            ));
        }
        let got = lines.lock().unwrap().clone();
        assert_eq!(got.len(), 1, "{got:?}");
        assert!(
            got[0].starts_with(
                "r: refused: pi (client 3f2a) may not publish servo_angles (Put ingress;"
            ),
            "{got:?}"
        );
    }

    #[test]
    fn an_uncached_refusal_and_a_client_without_a_role_are_said() {
        let (r, lines) = layer();
        r.take(&format!("{Z} on Interface(w-pc)+CertCommonName(pi)+Transport(Tls)+{Z} is unauthorized to Put (ingress) on servo_angles"));
        r.take("77aa did not match any configured ACL subject. Default permission `Deny` will be applied on all messages");
        r.take(&format!("{Z} on Interface(w-pc)+CertCommonName(pi)+Transport(Tls)+{Z} is unauthorized to Declare Subscriber (ingress) on robot_description"));
        // its own admin space: refused, not said; another's is
        r.take(&format!("{Z} on Interface(w-pc)+CertCommonName(pi)+Transport(Tls)+{Z} is unauthorized to Declare Queryable (ingress) on @/{Z}/ros2/**"));
        r.take(&format!("{Z} on Interface(w-pc)+CertCommonName(pi)+Transport(Tls)+{Z} is unauthorized to Declare Queryable (ingress) on @/{Z}0/ros2/**"));
        let got = lines.lock().unwrap().clone();
        assert_eq!(got.len(), 4, "{got:?}");
        assert!(
            got[0].contains("pi (client 3f2a) may not publish servo_angles"),
            "{got:?}"
        );
        assert!(got[1].contains("client 77aa has no role"), "{got:?}");
        assert!(
            got[2].contains("may not subscribe to robot_description"),
            "{got:?}"
        );
        assert!(
            got[3].contains("may not serve queries on @/3f2a0/ros2/**"),
            "{got:?}"
        );
    }

    #[test]
    fn memory_is_bounded() {
        let (r, lines) = layer();
        for i in 0..(MAX_TRACKED + 50) {
            r.take(&format!(
                "Using cached result: {Z} is unauthorized to Put (ingress) on k{i}"
            ));
        }
        let state = r.state.lock().unwrap();
        assert_eq!(state.seen.len(), MAX_TRACKED);
        assert_eq!(state.overflow.unsaid, 49);
        assert_eq!(lines.lock().unwrap().len(), MAX_TRACKED + 1);
    }
}
