//! A service server on one node's event loop, its requests named by [`Ticket`]s so that
//! the code that answers them needs no middleware types.
//!
//! As [`crate::action::ActionServer`]'s answers do, an answer waits until the service's
//! response writer has matched the response reader its request names: a client that
//! sees the service ready asks at once, and we may learn of its response reader after
//! the request; written before that match, the answer would go to nobody. Waiting
//! answers are sent from [`ServiceServer::next`] once the match comes (or after
//! `ANSWER_WAIT`), also from a `next()` already pending when the answer was given: a
//! node awaits its next request while it answers the last one.

use crate::error::PlumbingError;
use crate::names::Resolver;
use crate::qos;
use ros2_client::service::request_id::RmwRequestId;
use ros2_client::{Client, Message, Name, Node, Server, ServiceMapping, ServiceTypeName};
use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tokio::sync::Notify;

/// A client of the service `full` (an absolute name: `/arm2/recorder/start_episode`) of
/// type `package/srv/type_name`, with the services' QoS: every client of ours is made here.
pub fn client<Req: Message + Clone + 'static, Resp: Message + 'static>(
    ros: &mut crate::RosNode,
    full: &str,
    package: &str,
    type_name: &str,
) -> Result<Client<Req, Resp>, PlumbingError> {
    let name = Name::parse(full).map_err(|e| PlumbingError::Name {
        name: full.to_string(),
        why: format!("{e:?}"),
    })?;
    ros.node_mut()
        .create_client(
            ServiceMapping::Enhanced,
            &name,
            &ServiceTypeName::new(package, type_name),
            qos::SERVICES,
            qos::SERVICES,
        )
        .map_err(|e| PlumbingError::Ros(format!("{full}: {e:?}")))
}

/// The namespace of a node's full name, where its services are: `/arm2/recorder` is in
/// `/arm2`, `/recorder` in `` (the services then `/recorder/...`).
pub fn namespace_of(full_name: &str) -> &str {
    match full_name.rfind('/') {
        Some(0) | None => "",
        Some(i) => &full_name[..i],
    }
}

/// How long an answer waits for its client's response reader to match.
const ANSWER_WAIT: Duration = Duration::from_secs(10);

/// How often waiting answers are looked at again.
const ANSWER_RECHECK: Duration = Duration::from_millis(5);

/// A request to answer (with [`ServiceServer::answer`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Ticket(pub u64);

/// Who sent a request: its client's participant (the first 12 bytes of its GUID), the
/// same for every request of one client node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Caller(pub [u8; 12]);

impl std::fmt::Display for Caller {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for b in self.0 {
            write!(f, "{b:02x}")?;
        }
        Ok(())
    }
}

struct State<Resp> {
    next: u64,
    open: HashMap<Ticket, RmwRequestId>,
    waiting: Vec<(RmwRequestId, Resp, Instant)>,
}

/// The server of one service.
pub struct ServiceServer<Req: Message, Resp: Message> {
    server: Server<Req, Resp>,
    state: Mutex<State<Resp>>,
    /// An answer began to wait: a pending [`ServiceServer::next`] looks again.
    deferred: Notify,
    name: String,
}

impl<Req, Resp> ServiceServer<Req, Resp>
where
    Req: Message + Clone + 'static,
    Resp: Message + 'static,
{
    /// The server of service `name` (relative: in the node's namespace, remapped) of
    /// type `package/srv/type_name`.
    pub fn new(
        node: &mut Node,
        resolver: &Resolver,
        name: &str,
        package: &str,
        type_name: &str,
    ) -> Result<Self, PlumbingError> {
        let resolved = resolver.resolve(name)?;
        let ros_name = Name::parse(&resolved).map_err(|e| PlumbingError::Name {
            name: resolved.clone(),
            why: format!("{e:?}"),
        })?;
        let server = node
            .create_server(
                ServiceMapping::Enhanced,
                &ros_name,
                &ServiceTypeName::new(package, type_name),
                qos::SERVICES,
                qos::SERVICES,
            )
            .map_err(|e| PlumbingError::Ros(format!("cannot serve {resolved}: {e:?}")))?;
        Ok(ServiceServer {
            server,
            state: Mutex::new(State {
                next: 0,
                open: HashMap::new(),
                waiting: Vec::new(),
            }),
            deferred: Notify::new(),
            name: resolved,
        })
    }

    /// The service's resolved name (`/controller_manager/list_controllers`).
    pub fn name(&self) -> &str {
        &self.name
    }

    fn state(&self) -> std::sync::MutexGuard<'_, State<Resp>> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The next request, its ticket and its caller; answers waiting for their client's
    /// response reader are sent on the way once it matched. `Err`: a request that
    /// could not be read.
    pub async fn next(&self) -> Result<(Ticket, Caller, Req), String> {
        loop {
            let waiting = self.send_waiting();
            tokio::select! {
                _ = tokio::time::sleep(ANSWER_RECHECK), if waiting => {}
                _ = self.deferred.notified() => {}
                r = self.server.async_receive_request() => {
                    let (id, request) = r.map_err(|e| format!("{}: {e:?}", self.name))?;
                    let mut prefix = [0u8; 12];
                    prefix.copy_from_slice(&id.writer_gid.as_bytes()[..12]);
                    let mut s = self.state();
                    let ticket = Ticket(s.next);
                    s.next += 1;
                    s.open.insert(ticket, id);
                    return Ok((ticket, Caller(prefix), request));
                }
            }
        }
    }

    /// Answer the request of `ticket` (now, or once its client's response reader
    /// matched); an unknown or answered ticket is ignored.
    pub fn answer(&self, ticket: Ticket, response: Resp) {
        let Some(id) = self.state().open.remove(&ticket) else {
            return;
        };
        if self.server.response_reader_matched(id) {
            self.send(id, response);
        } else {
            log::debug!(
                "{}: an answer waits for its client's response reader to match",
                self.name
            );
            self.state().waiting.push((id, response, Instant::now()));
            // the `next()` awaiting a request may be pending with no answer to look at
            self.deferred.notify_one();
        }
    }

    /// Send the waiting answers whose client's reader has matched, and those that
    /// waited `ANSWER_WAIT` (their client has most likely gone). Whether any still wait.
    fn send_waiting(&self) -> bool {
        let due: Vec<_> = {
            let mut s = self.state();
            if s.waiting.is_empty() {
                return false;
            }
            let all = std::mem::take(&mut s.waiting);
            let (due, wait): (Vec<_>, Vec<_>) = all.into_iter().partition(|(id, _, since)| {
                self.server.response_reader_matched(*id) || since.elapsed() >= ANSWER_WAIT
            });
            s.waiting = wait;
            due
        };
        for (id, response, _) in due {
            self.send(id, response);
        }
        !self.state().waiting.is_empty()
    }

    fn send(&self, id: RmwRequestId, response: Resp) {
        if let Err(e) = self.server.send_response(id, response) {
            log::warn!("{}: cannot answer a request: {e:?}", self.name);
        }
    }
}
