//! A ROS 2 action server as rcl_action keeps one: the goals' states and their
//! `status` topic, results kept for the clients that ask late, cancel requests
//! answered with the goals that will stop. [`GoalTable`] is the bookkeeping, free of
//! I/O (tested here); [`ActionServer`] puts it on ros2-client's action services and
//! topics. What a goal means, and when it is accepted, executed and finished, is the
//! node's.
//!
//! ros2-client has an `AsyncActionServer`, but it cannot be driven from one event loop
//! beside topics: sending a result waits for the client's result request (a goal whose
//! client never asks blocks the caller), an aborted goal can no longer be given a
//! result, and a result asked for after the goal ended is never answered.

use crate::names::Resolver;
use crate::qos;
use crate::PlumbingError;
use ros2_client::action::{
    ActionServerQosPolicies, CancelGoalRequest, CancelGoalResponse, GoalInfo, GoalStatusEnum,
};
use ros2_client::action_msgs::{CancelGoalResponseEnum, GoalStatus, GoalStatusArray};
use ros2_client::builtin_interfaces::Time;
use ros2_client::service::request_id::RmwRequestId;
use ros2_client::{ActionTypeName, Message, Name, Node, ServiceMapping};
use std::collections::{BTreeMap, HashMap};
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tokio::sync::Notify;

/// ros2-client's goal id (a `unique_identifier_msgs/UUID`): the wire's, kept inside
/// this module.
type RosGoalId = ros2_client::action::GoalId;

/// How long a finished goal's result is kept for a client that asks late (rcl_action's
/// default `result_timeout`, 15 min).
pub const RESULT_KEEP: Duration = Duration::from_secs(15 * 60);

/// At most this many finished goals are kept (the oldest go first).
pub const FINISHED_KEEP: usize = 100;

/// How long an answer waits for its client's response reader to match before it is
/// sent anyway (see [`ActionServer`]).
const ANSWER_WAIT: Duration = Duration::from_secs(10);

/// How often waiting answers are looked at again.
const ANSWER_RECHECK: Duration = Duration::from_millis(5);

/// How a goal ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GoalEnd {
    /// Done as asked.
    Succeeded,
    /// Stopped by the server (a violated tolerance, an e-stop, a newer goal).
    Aborted,
    /// Stopped because the client asked.
    Canceled,
}

impl GoalEnd {
    fn status(self) -> GoalStatusEnum {
        match self {
            GoalEnd::Succeeded => GoalStatusEnum::Succeeded,
            GoalEnd::Aborted => GoalStatusEnum::Aborted,
            GoalEnd::Canceled => GoalStatusEnum::Canceled,
        }
    }
}

#[derive(Debug)]
struct Goal<R, Q> {
    accepted: Time,
    status: GoalStatusEnum,
    result: Option<R>,
    finished: Option<Instant>,
    /// result requests that came before the result
    waiting: Vec<Q>,
}

/// The goals of one action server: their states, their results, the result requests
/// waiting for them. `R`: the result type; `Q`: what identifies a request to answer.
#[derive(Debug)]
pub struct GoalTable<R, Q> {
    goals: BTreeMap<RosGoalId, Goal<R, Q>>,
}

impl<R, Q> Default for GoalTable<R, Q> {
    fn default() -> Self {
        GoalTable {
            goals: BTreeMap::new(),
        }
    }
}

/// What to answer a result request with, now or later.
#[derive(Debug, PartialEq)]
pub enum ResultAnswer<R> {
    /// The goal ended: its status and result.
    Now(GoalStatusEnum, R),
    /// The goal is still running: the answer goes out when it ends.
    Later,
    /// No such goal (never accepted, or forgotten): status Unknown and a default
    /// result, as rcl_action answers.
    Unknown,
}

impl<R: Clone, Q> GoalTable<R, Q> {
    /// A goal accepted at `stamp` (already executing: this server has no queue).
    pub fn accept(&mut self, id: RosGoalId, stamp: Time) {
        self.goals.insert(
            id,
            Goal {
                accepted: stamp,
                status: GoalStatusEnum::Executing,
                result: None,
                finished: None,
                waiting: Vec::new(),
            },
        );
    }

    /// Whether `id` is known (running or finished and kept).
    pub fn contains(&self, id: &RosGoalId) -> bool {
        self.goals.contains_key(id)
    }

    /// Whether `id` is running (executing or canceling).
    pub fn is_active(&self, id: &RosGoalId) -> bool {
        self.goals.get(id).is_some_and(|g| g.finished.is_none())
    }

    /// The goals still running.
    pub fn active(&self) -> Vec<RosGoalId> {
        self.goals
            .iter()
            .filter(|(_, g)| g.finished.is_none())
            .map(|(id, _)| *id)
            .collect()
    }

    /// A result request for `id` from `requester`: answered now, or kept until the
    /// goal ends.
    pub fn result_request(&mut self, id: RosGoalId, requester: Q) -> ResultAnswer<R> {
        match self.goals.get_mut(&id) {
            None => ResultAnswer::Unknown,
            Some(Goal {
                result: Some(r),
                status,
                ..
            }) => ResultAnswer::Now(*status, r.clone()),
            Some(g) => {
                g.waiting.push(requester);
                ResultAnswer::Later
            }
        }
    }

    /// A cancel request: the running goals it names (by id, or every goal accepted at
    /// or before `stamp`, or all when both are zero, as rcl_action reads it), now
    /// canceling, and the answer's return code.
    pub fn cancel_request(&mut self, info: &GoalInfo) -> (Vec<GoalInfo>, CancelGoalResponseEnum) {
        let zero_id = info.goal_id == RosGoalId::ZERO;
        let zero_stamp = info.stamp == Time::ZERO;
        let mut canceling = Vec::new();
        let mut terminated = false;
        for (id, g) in self.goals.iter_mut() {
            let named = *id == info.goal_id
                || (zero_id && zero_stamp)
                || (!zero_stamp && g.accepted <= info.stamp);
            if !named {
                continue;
            }
            if g.finished.is_some() {
                terminated |= *id == info.goal_id;
                continue;
            }
            g.status = GoalStatusEnum::Canceling;
            canceling.push(GoalInfo {
                goal_id: *id,
                stamp: g.accepted,
            });
        }
        let code = if !canceling.is_empty() {
            CancelGoalResponseEnum::None
        } else if !zero_id && !self.goals.contains_key(&info.goal_id) {
            CancelGoalResponseEnum::UnknownGoal
        } else if terminated {
            CancelGoalResponseEnum::GoalTerminated
        } else {
            CancelGoalResponseEnum::Rejected
        };
        (canceling, code)
    }

    /// Whether a cancel of `id` was asked for (it is canceling).
    pub fn is_canceling(&self, id: &RosGoalId) -> bool {
        self.goals
            .get(id)
            .is_some_and(|g| g.status == GoalStatusEnum::Canceling)
    }

    /// Goal `id` ended at `now` with `result`: the result requests waiting for it, to
    /// answer with the returned status. `None` if it is not running.
    pub fn finish(
        &mut self,
        id: &RosGoalId,
        end: GoalEnd,
        result: R,
        now: Instant,
    ) -> Option<(GoalStatusEnum, Vec<Q>)> {
        let g = self.goals.get_mut(id).filter(|g| g.finished.is_none())?;
        g.status = end.status();
        g.result = Some(result);
        g.finished = Some(now);
        Some((g.status, std::mem::take(&mut g.waiting)))
    }

    /// Forget the finished goals kept longer than [`RESULT_KEEP`], and the oldest
    /// beyond [`FINISHED_KEEP`]. Whether any was forgotten.
    pub fn expire(&mut self, now: Instant) -> bool {
        let before = self.goals.len();
        self.goals.retain(|_, g| {
            g.finished
                .is_none_or(|t| now.saturating_duration_since(t) < RESULT_KEEP)
        });
        let mut finished: Vec<(Instant, RosGoalId)> = self
            .goals
            .iter()
            .filter_map(|(id, g)| g.finished.map(|t| (t, *id)))
            .collect();
        if finished.len() > FINISHED_KEEP {
            finished.sort();
            for (_, id) in &finished[..finished.len() - FINISHED_KEEP] {
                self.goals.remove(id);
            }
        }
        self.goals.len() != before
    }

    /// The `status` topic's message: every goal known, in acceptance order.
    pub fn statuses(&self) -> GoalStatusArray {
        let mut list: Vec<GoalStatus> = self
            .goals
            .iter()
            .map(|(id, g)| GoalStatus {
                goal_info: GoalInfo {
                    goal_id: *id,
                    stamp: g.accepted,
                },
                status: g.status,
            })
            .collect();
        list.sort_by_key(|s| s.goal_info.stamp);
        GoalStatusArray { status_list: list }
    }
}

/// An action goal's id: the 16 bytes of its UUID (`unique_identifier_msgs/UUID`),
/// chosen by the client. Shown as the UUID (`0a1b2c3d-…`).
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct GoalId([u8; 16]);

impl GoalId {
    /// The nil UUID (all zeros).
    pub const ZERO: GoalId = GoalId([0; 16]);

    /// The goal id of these 16 bytes (in the UUID's byte order).
    pub const fn from_bytes(bytes: [u8; 16]) -> GoalId {
        GoalId(bytes)
    }

    /// Its 16 bytes.
    pub const fn as_bytes(&self) -> &[u8; 16] {
        &self.0
    }

    fn from_ros(id: RosGoalId) -> GoalId {
        GoalId(*id.uuid.as_bytes())
    }

    fn to_ros(self) -> RosGoalId {
        RosGoalId {
            uuid: uuid::Uuid::from_bytes(self.0),
        }
    }
}

impl std::fmt::Display for GoalId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Display::fmt(&uuid::Uuid::from_bytes(self.0).hyphenated(), f)
    }
}

impl std::fmt::Debug for GoalId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GoalId({self})")
    }
}

/// A goal request to answer (with [`ActionServer::accept`] or [`ActionServer::reject`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Ticket(pub u64);

/// A request an [`ActionServer`] hands to the node.
#[derive(Debug)]
pub enum ActionRequest<G> {
    /// A new goal: accept ([`ActionServer::accept`]) or reject it.
    Goal {
        /// The request, to answer.
        ticket: Ticket,
        /// The goal's id.
        id: GoalId,
        /// The goal.
        goal: G,
    },
    /// Cancel requests were accepted for these goals (now canceling): stop them and
    /// finish them as [`GoalEnd::Canceled`].
    Cancel(Vec<GoalId>),
    /// A request that could not be read (or a middleware error).
    Unreadable(String),
}

/// The QoS of rcl_action's defaults: services and feedback reliable, volatile, keep
/// last 10; `status` transient-local, keep last 1.
pub fn server_qos() -> ActionServerQosPolicies {
    ActionServerQosPolicies {
        goal_service: qos::SERVICES,
        result_service: qos::SERVICES,
        cancel_service: qos::SERVICES,
        feedback_publisher: qos::reliable(10),
        status_publisher: qos::latched(1),
    }
}

/// An answer to one of an action's three services.
enum Answer<R> {
    Goal(ros2_client::action::SendGoalResponse),
    Cancel(CancelGoalResponse),
    Result(ros2_client::action::GetResultResponse<R>),
}

/// An action server on one node's event loop. `G`, `R`, `F`: goal, result, feedback.
///
/// An answer waits until the service's response writer has matched the response
/// reader its request names (`Server::response_reader_matched`): a client that sees
/// the server ready asks at once, and we may learn of its response reader after the
/// request; written before that match, the answer would go to nobody. Such answers
/// are sent from [`ActionServer::next`] once the match comes (or after `ANSWER_WAIT`),
/// also from a `next()` already pending when the answer was given.
pub struct ActionServer<G, R, F>
where
    G: Message + Clone,
    R: Message + Clone,
    F: Message,
{
    server: ros2_client::action::ActionServer<G, R, F>,
    table: Mutex<GoalTable<R, RmwRequestId>>,
    waiting: Mutex<Vec<(RmwRequestId, Answer<R>, Instant)>>,
    /// An answer began to wait: a pending [`ActionServer::next`] looks again.
    deferred: Notify,
    goal_requests: Mutex<GoalRequests>,
    name: String,
}

/// The goal requests not answered yet, by ticket: the request and the goal's id.
#[derive(Default)]
struct GoalRequests {
    next: u64,
    open: HashMap<Ticket, (RmwRequestId, RosGoalId)>,
}

impl<G, R, F> ActionServer<G, R, F>
where
    G: Message + Clone + 'static,
    R: Message + Clone + Default + 'static,
    F: Message + 'static,
{
    /// The server of action `name` (relative: in the node's namespace, remapped) of
    /// type `package/action/type_name`.
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
            .create_action_server(
                ServiceMapping::Enhanced,
                &ros_name,
                &ActionTypeName::new(package, type_name),
                server_qos(),
            )
            .map_err(|e| PlumbingError::Ros(format!("cannot serve action {resolved}: {e:?}")))?;
        let s = ActionServer {
            server,
            table: Mutex::new(GoalTable::default()),
            waiting: Mutex::new(Vec::new()),
            deferred: Notify::new(),
            goal_requests: Mutex::new(GoalRequests::default()),
            name: resolved,
        };
        s.publish_statuses();
        Ok(s)
    }

    /// The action's resolved name (`/arm_controller/follow_joint_trajectory`).
    pub fn name(&self) -> &str {
        &self.name
    }

    fn table(&self) -> std::sync::MutexGuard<'_, GoalTable<R, RmwRequestId>> {
        self.table.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn goal_requests(&self) -> std::sync::MutexGuard<'_, GoalRequests> {
        self.goal_requests.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A goal request, given a ticket to answer it by.
    fn goal_request(
        &self,
        request: RmwRequestId,
        goal: ros2_client::action::SendGoalRequest<G>,
    ) -> ActionRequest<G> {
        let mut requests = self.goal_requests();
        let ticket = Ticket(requests.next);
        requests.next += 1;
        requests.open.insert(ticket, (request, goal.goal_id));
        ActionRequest::Goal {
            ticket,
            id: GoalId::from_ros(goal.goal_id),
            goal: goal.goal,
        }
    }

    fn publish_statuses(&self) {
        let statuses = self.table().statuses();
        if let Err(e) = self.server.send_goal_statuses(statuses) {
            log::warn!("{}: cannot publish the goal statuses: {e:?}", self.name);
        }
    }

    /// The next goal or accepted cancel; result requests are answered on the way, and
    /// answers waiting for their client's response reader are sent once it matched.
    pub async fn next(&self) -> ActionRequest<G> {
        loop {
            let waiting = self.send_waiting();
            let goal = self.server.goal_server_ref().async_receive_request();
            let cancel = self.server.cancel_server_ref().async_receive_request();
            let result = self.server.result_server_ref().async_receive_request();
            tokio::select! {
                _ = tokio::time::sleep(ANSWER_RECHECK), if waiting => {}
                _ = self.deferred.notified() => {}
                r = goal => match r {
                    Ok((request, g)) => return self.goal_request(request, g),
                    Err(e) => return ActionRequest::Unreadable(format!("send_goal: {e:?}")),
                },
                r = cancel => match r {
                    Ok((request, c)) => {
                        if let Some(ids) = self.cancel(request, &c) {
                            return ActionRequest::Cancel(ids);
                        }
                    }
                    Err(e) => return ActionRequest::Unreadable(format!("cancel_goal: {e:?}")),
                },
                r = result => match r {
                    Ok((request, q)) => self.result_request(request, q.goal_id),
                    Err(e) => return ActionRequest::Unreadable(format!("get_result: {e:?}")),
                },
            }
        }
    }

    fn cancel(&self, request: RmwRequestId, c: &CancelGoalRequest) -> Option<Vec<GoalId>> {
        let (canceling, return_code) = self.table().cancel_request(&c.goal_info);
        let ids: Vec<GoalId> = canceling
            .iter()
            .map(|g| GoalId::from_ros(g.goal_id))
            .collect();
        let response = CancelGoalResponse {
            return_code,
            goals_canceling: canceling,
        };
        self.answer(request, Answer::Cancel(response));
        if ids.is_empty() {
            return None;
        }
        self.publish_statuses();
        Some(ids)
    }

    fn result_request(&self, request: RmwRequestId, id: RosGoalId) {
        let answer = self.table().result_request(id, request);
        let (status, result) = match answer {
            ResultAnswer::Later => return,
            ResultAnswer::Now(status, result) => (status, result),
            ResultAnswer::Unknown => (GoalStatusEnum::Unknown, R::default()),
        };
        self.send_result(request, status, result);
    }

    fn send_result(&self, request: RmwRequestId, status: GoalStatusEnum, result: R) {
        let response = ros2_client::action::GetResultResponse { status, result };
        self.answer(request, Answer::Result(response));
    }

    /// Accept the goal of `ticket` (it executes at once); an unknown or answered ticket
    /// is ignored.
    pub fn accept(&self, ticket: Ticket) {
        let Some((request, id)) = self.goal_requests().open.remove(&ticket) else {
            return;
        };
        let stamp = Time::now();
        {
            let mut table = self.table();
            table.expire(Instant::now());
            table.accept(id, stamp);
        }
        self.publish_statuses();
        self.answer_goal(request, true, stamp);
    }

    /// Reject the goal of `ticket` (it is forgotten); an unknown or answered ticket is
    /// ignored.
    pub fn reject(&self, ticket: Ticket) {
        let Some((request, _)) = self.goal_requests().open.remove(&ticket) else {
            return;
        };
        self.answer_goal(request, false, Time::now());
    }

    fn answer_goal(&self, request: RmwRequestId, accepted: bool, stamp: Time) {
        let response = ros2_client::action::SendGoalResponse { accepted, stamp };
        self.answer(request, Answer::Goal(response));
    }

    /// Whether an answer to `request` written now reaches its client.
    fn reaches(&self, request: RmwRequestId, answer: &Answer<R>) -> bool {
        match answer {
            Answer::Goal(_) => self
                .server
                .goal_server_ref()
                .response_reader_matched(request),
            Answer::Cancel(_) => self
                .server
                .cancel_server_ref()
                .response_reader_matched(request),
            Answer::Result(_) => self
                .server
                .result_server_ref()
                .response_reader_matched(request),
        }
    }

    /// Send `answer` to `request` now, or once its client's response reader matched.
    fn answer(&self, request: RmwRequestId, answer: Answer<R>) {
        if self.reaches(request, &answer) {
            self.send(request, answer);
        } else {
            log::debug!(
                "{}: an answer waits for its client's response reader to match",
                self.name
            );
            self.waiting().push((request, answer, Instant::now()));
            // the `next()` awaiting a request may be pending with no answer to look at
            self.deferred.notify_one();
        }
    }

    fn waiting(&self) -> std::sync::MutexGuard<'_, Vec<(RmwRequestId, Answer<R>, Instant)>> {
        self.waiting.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Send the waiting answers whose client's reader has matched, and those that
    /// waited `ANSWER_WAIT` (their client has most likely gone; sending loses
    /// nothing). Whether any still wait.
    fn send_waiting(&self) -> bool {
        let due: Vec<_> = {
            let mut waiting = self.waiting();
            if waiting.is_empty() {
                return false;
            }
            let all = std::mem::take(&mut *waiting);
            let (due, wait): (Vec<_>, Vec<_>) =
                all.into_iter().partition(|(request, answer, since)| {
                    self.reaches(*request, answer) || since.elapsed() >= ANSWER_WAIT
                });
            *waiting = wait;
            due
        };
        for (request, answer, _) in due {
            self.send(request, answer);
        }
        !self.waiting().is_empty()
    }

    fn send(&self, request: RmwRequestId, answer: Answer<R>) {
        let sent = match answer {
            Answer::Goal(a) => self
                .server
                .send_goal_response(request, a)
                .map_err(|e| format!("a goal request: {e:?}")),
            Answer::Cancel(a) => self
                .server
                .send_cancel_response(request, a)
                .map_err(|e| format!("a cancel request: {e:?}")),
            Answer::Result(a) => self
                .server
                .send_result(request, a)
                .map_err(|e| format!("a result request: {e:?}")),
        };
        if let Err(e) = sent {
            log::warn!("{}: cannot answer {e}", self.name);
        }
    }

    /// Whether goal `id` is running.
    pub fn is_active(&self, id: &GoalId) -> bool {
        self.table().is_active(&id.to_ros())
    }

    /// Feedback on running goal `id`.
    pub fn feedback(&self, id: GoalId, feedback: F) {
        let id = id.to_ros();
        if !self.table().is_active(&id) {
            return;
        }
        if let Err(e) = self.server.send_feedback(id, feedback) {
            log::debug!("{}: cannot publish feedback: {e}", self.name);
        }
    }

    /// Goal `id` ended: its status is published and its result sent to every client
    /// that asked (and kept for those that ask later). Nothing if it is not running.
    pub fn finish(&self, id: GoalId, end: GoalEnd, result: R) {
        let id = id.to_ros();
        let done = self
            .table()
            .finish(&id, end, result.clone(), Instant::now());
        let Some((status, waiting)) = done else {
            return;
        };
        self.publish_statuses();
        for request in waiting {
            self.send_result(request, status, result.clone());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A goal id whose first byte is `n`.
    fn id(n: u8) -> RosGoalId {
        let mut bytes = [0u8; 16];
        bytes[0] = n;
        GoalId::from_bytes(bytes).to_ros()
    }

    fn t(s: i32) -> Time {
        Time::from_nanos(i64::from(s) * 1_000_000_000)
    }

    #[test]
    fn a_goal_id_is_the_uuid_of_its_wire_bytes_and_shows_as_that_uuid() {
        let bytes: [u8; 16] = std::array::from_fn(|i| (i as u8 * 17).wrapping_add(1));
        let wire = rustdds::serialization::deserialize_from_cdr_with_rep_id::<RosGoalId>(
            &bytes,
            rustdds::RepresentationIdentifier::CDR_LE,
        )
        .map(|(v, _)| v)
        .expect("a UUID is 16 bytes");
        let id = GoalId::from_bytes(bytes);
        assert_eq!(GoalId::from_ros(wire), id);
        assert_eq!(id.to_ros(), wire);
        assert_eq!(id.as_bytes(), &bytes);
        assert_eq!(id.to_string(), "01122334-4556-6778-899a-abbccddeef00");
        assert_eq!(
            format!("{id:?}"),
            "GoalId(01122334-4556-6778-899a-abbccddeef00)"
        );
        assert_eq!(
            GoalId::ZERO.to_string(),
            "00000000-0000-0000-0000-000000000000"
        );
    }

    #[test]
    fn a_result_asked_before_the_end_is_answered_at_the_end_and_kept_after() {
        let mut table = GoalTable::<u32, &str>::default();
        let now = Instant::now();
        table.accept(id(1), t(1));
        assert_eq!(table.result_request(id(1), "early"), ResultAnswer::Later);
        let (status, waiting) = table.finish(&id(1), GoalEnd::Succeeded, 7, now).unwrap();
        assert_eq!(
            (status, waiting),
            (GoalStatusEnum::Succeeded, vec!["early"])
        );
        assert_eq!(
            table.result_request(id(1), "late"),
            ResultAnswer::Now(GoalStatusEnum::Succeeded, 7)
        );
        assert_eq!(table.finish(&id(1), GoalEnd::Aborted, 8, now), None);
        assert_eq!(table.result_request(id(2), "x"), ResultAnswer::Unknown);
    }

    #[test]
    fn cancel_names_goals_by_id_by_stamp_or_all() {
        let mut table = GoalTable::<u32, ()>::default();
        for n in 1..=3 {
            table.accept(id(n), t(i32::from(n)));
        }
        let by_id = GoalInfo {
            goal_id: id(2),
            stamp: Time::ZERO,
        };
        let (c, code) = table.cancel_request(&by_id);
        assert_eq!(c.iter().map(|g| g.goal_id).collect::<Vec<_>>(), vec![id(2)]);
        assert_eq!(code, CancelGoalResponseEnum::None);
        assert!(table.is_canceling(&id(2)) && !table.is_canceling(&id(1)));
        table.finish(&id(2), GoalEnd::Canceled, 0, Instant::now());
        let (c, code) = table.cancel_request(&by_id);
        assert!(c.is_empty());
        assert_eq!(code, CancelGoalResponseEnum::GoalTerminated);
        let unknown = GoalInfo {
            goal_id: id(9),
            stamp: Time::ZERO,
        };
        assert_eq!(
            table.cancel_request(&unknown).1,
            CancelGoalResponseEnum::UnknownGoal
        );
        let before_2 = GoalInfo {
            goal_id: RosGoalId::ZERO,
            stamp: t(2),
        };
        let (c, _) = table.cancel_request(&before_2);
        assert_eq!(c.iter().map(|g| g.goal_id).collect::<Vec<_>>(), vec![id(1)]);
        let all = GoalInfo {
            goal_id: RosGoalId::ZERO,
            stamp: Time::ZERO,
        };
        let (c, _) = table.cancel_request(&all);
        assert_eq!(
            c.iter().map(|g| g.goal_id).collect::<Vec<_>>(),
            vec![id(1), id(3)]
        );
    }

    #[test]
    fn finished_goals_expire_after_the_keep_time_and_beyond_the_count() {
        let mut table = GoalTable::<u32, ()>::default();
        let t0 = Instant::now();
        table.accept(id(1), t(1));
        table.accept(id(2), t(2));
        table.finish(&id(1), GoalEnd::Aborted, 0, t0);
        assert!(!table.expire(t0 + RESULT_KEEP - Duration::from_secs(1)));
        assert!(table.expire(t0 + RESULT_KEEP));
        assert!(!table.contains(&id(1)) && table.is_active(&id(2)));
        for n in 0..(FINISHED_KEEP as u8 + 5) {
            table.accept(id(10 + n), t(10));
            table.finish(
                &id(10 + n),
                GoalEnd::Succeeded,
                0,
                t0 + Duration::from_millis(u64::from(n)),
            );
        }
        table.expire(t0);
        assert_eq!(table.statuses().status_list.len(), FINISHED_KEEP + 1);
        assert!(!table.contains(&id(10)) && table.contains(&id(10 + FINISHED_KEEP as u8 + 4)));
    }

    #[test]
    fn statuses_list_every_goal_in_acceptance_order() {
        let mut table = GoalTable::<u32, ()>::default();
        table.accept(id(5), t(2));
        table.accept(id(1), t(3));
        table.finish(&id(5), GoalEnd::Succeeded, 0, Instant::now());
        let s = table.statuses().status_list;
        assert_eq!(s.len(), 2);
        assert_eq!(s[0].goal_info.goal_id, id(5));
        assert_eq!(s[0].status, GoalStatusEnum::Succeeded);
        assert_eq!(s[1].status, GoalStatusEnum::Executing);
    }
}
