//! Foxglove and MCAP for gui_bridge: the graph's samples as CDR (for the Foxglove
//! WebSocket server of `foxglove_bind`, and for `record FILE.mcap`), targets from
//! Foxglove panels onto ROS, and `play FILE.mcap`. The protocol and file work is
//! [`foxglove_bridge`]'s; this module is the ROS side.
//!
//! ros2-client hands a subscription deserialized messages, not the wire's bytes, so each
//! sample is serialized again with the serializer the messages are published with
//! (`eezybot_msgs::cdr`): the same bytes as any little-endian ROS 2 writer's for these
//! types (Fast DDS' too; a big-endian writer's samples come out little-endian).

use crate::access::{self, AccessPolicy, RequestFacts};
use anyhow::{anyhow, Context as _};
use eezybot_msgs::geometry_msgs::{PointStamped, PoseStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Float64;
use eezybot_msgs::{RosMessage, Time};
use foxglove_bridge::{
    now_ns, Admitted, ClientPublish, ClientSample, FoxgloveBridge, FrontLimits, Gate, McapRecorder,
    McapTargets, RecordedTarget, Refused, TopicNames, UpgradeRequest,
};
use futures::future::{FutureExt, LocalBoxFuture};
use futures::stream::{LocalBoxStream, StreamExt};
use ros_plumbing::{topics, RosNode, TopicPublisher};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::cell::RefCell;
use std::collections::{BTreeSet, HashMap};
use std::future::Future;
use std::path::Path;
use std::rc::Rc;
use std::sync::Arc;
use std::time::Duration;

/// One sample: the topic (relative name) and its CDR bytes.
pub type RawSample = (&'static str, Vec<u8>);

/// Is `path` an MCAP file (by its extension, `.mcap`, any case)?
pub fn is_mcap(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}

/// The topic names as this node has them (namespace and remaps).
pub fn topic_names(node: &RosNode) -> TopicNames {
    TopicNames::default().resolved_by(|t| node.resolver().resolve(t).ok())
}

/// Gives a tap's subscription back to the node when the tap is no longer wanted (after
/// its stream was dropped).
type Untap = Box<dyn FnOnce(&mut RosNode)>;

fn tap<M>(
    node: &mut RosNode,
    topic: &topics::Topic<M>,
) -> anyhow::Result<(LocalBoxStream<'static, RawSample>, Untap)>
where
    M: RosMessage + Serialize + DeserializeOwned + 'static,
{
    let sub = Rc::new(node.subscribe_to(topic)?);
    let name = topic.name;
    let stream = futures::stream::unfold(sub.clone(), |sub| async move {
        let r = sub.async_take().await;
        Some((r, sub))
    })
    .filter_map(move |r| async move {
        match r {
            Ok((m, _)) => match eezybot_msgs::cdr::encode(&m) {
                Ok(bytes) => Some((name, bytes)),
                Err(e) => {
                    log::warn!("{name}: cannot serialize a sample again: {e}");
                    None
                }
            },
            Err(e) => {
                log::debug!("{name}: unreadable sample: {e:?}");
                None
            }
        }
    })
    .boxed_local();
    let untap: Untap = Box::new(move |node: &mut RosNode| {
        // the stream holds the other reference until it is dropped
        if let Ok(sub) = Rc::try_unwrap(sub) {
            node.unsubscribe(sub);
        }
    });
    Ok((stream, untap))
}

/// Taps on the topics of the contract ([`topics::visit_all`]) that `wanted(relative
/// name)` chooses: every topic of the graph the Foxglove server and MCAP recordings know.
struct Tapper<'a, F> {
    node: &'a mut RosNode,
    wanted: F,
    taps: Vec<(&'static str, LocalBoxStream<'static, RawSample>, Untap)>,
    error: Option<anyhow::Error>,
}

impl<F: Fn(&str) -> bool> topics::TopicVisitor for Tapper<'_, F> {
    fn visit<M: RosMessage>(&mut self, topic: &topics::Topic<M>) {
        if self.error.is_some() || !(self.wanted)(topic.name) {
            return;
        }
        match tap(self.node, topic) {
            Ok((samples, untap)) => self.taps.push((topic.name, samples, untap)),
            Err(e) => self.error = Some(e),
        }
    }
}

/// Taps on the topics of the graph that `wanted(relative name)` chooses.
fn tap_wanted(
    node: &mut RosNode,
    wanted: impl Fn(&str) -> bool,
) -> anyhow::Result<Vec<(&'static str, LocalBoxStream<'static, RawSample>, Untap)>> {
    let mut tapper = Tapper {
        node,
        wanted,
        taps: Vec::new(),
        error: None,
    };
    topics::visit_all(&mut tapper);
    match tapper.error {
        Some(e) => Err(e),
        None => Ok(tapper.taps),
    }
}

/// The samples of every topic of the graph for which `wanted(relative name)` holds, as
/// they arrive.
pub fn taps(
    node: &mut RosNode,
    wanted: impl Fn(&str) -> bool,
) -> anyhow::Result<LocalBoxStream<'static, RawSample>> {
    let streams = tap_wanted(node, wanted)?.into_iter().map(|(_, s, _)| s);
    Ok(futures::stream::select_all(streams).boxed_local())
}

/// One topic's samples, with its name, among the Foxglove server's taps.
struct Keyed {
    topic: &'static str,
    samples: LocalBoxStream<'static, RawSample>,
}

impl futures::Stream for Keyed {
    type Item = RawSample;
    fn poll_next(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<Option<RawSample>> {
        self.samples.poll_next_unpin(cx)
    }
}

/// The Foxglove server's subscriptions: a ROS topic is subscribed only while a Foxglove
/// client subscribes its channel (so that, say, compute_ik sees serial_node's
/// `servo_angles` subscription go when the link to the Pi goes, not a Foxglove tap's
/// stay), except the latched topics, kept for clients that come later.
struct Taps {
    streams: futures::stream::SelectAll<Keyed>,
    untaps: HashMap<&'static str, Untap>,
}

impl Taps {
    fn new() -> Taps {
        Taps {
            streams: futures::stream::SelectAll::new(),
            untaps: HashMap::new(),
        }
    }

    /// Subscribe what `wanted` has and is not subscribed yet; unsubscribe what it no
    /// longer has.
    fn follow(&mut self, node: &RefCell<&mut RosNode>, wanted: &BTreeSet<&'static str>) {
        for &topic in wanted {
            if self.untaps.contains_key(topic) {
                continue;
            }
            match tap_wanted(&mut node.borrow_mut(), |t| t == topic) {
                Ok(taps) => {
                    for (topic, samples, untap) in taps {
                        log::debug!("Foxglove: subscribed {topic}");
                        self.streams.push(Keyed { topic, samples });
                        self.untaps.insert(topic, untap);
                    }
                }
                Err(e) => log::warn!("Foxglove: cannot subscribe {topic}: {e:#}"),
            }
        }
        let gone: Vec<&'static str> = self
            .untaps
            .keys()
            .copied()
            .filter(|t| !wanted.contains(t)) // `wanted` always has the always-tapped
            .collect();
        if gone.is_empty() {
            return;
        }
        let kept: Vec<Keyed> = std::mem::take(&mut self.streams)
            .into_iter()
            .filter(|k| !gone.contains(&k.topic))
            .collect();
        self.streams = kept.into_iter().collect();
        for topic in gone {
            if let Some(untap) = self.untaps.remove(topic) {
                untap(&mut node.borrow_mut());
                log::debug!("Foxglove: unsubscribed {topic}");
            }
        }
    }
}

/// Topics subscribed as long as the Foxglove server runs: the latched ones it takes to
/// view the graph (the robot model and its fixed transforms: latched and recorded in
/// the topic contract), whose last sample every client gets when it subscribes.
fn always_tapped_topics() -> BTreeSet<&'static str> {
    topics::all()
        .iter()
        .filter(|t| t.latched() && t.recorded())
        .map(|t| t.name)
        .collect()
}

/// Publishers of the five target topics, publishing samples given as CDR.
pub struct TargetPublishers {
    xyz: TopicPublisher<PointStamped>,
    xyz_line: TopicPublisher<PointStamped>,
    pose: TopicPublisher<PoseStamped>,
    gripper: TopicPublisher<Float64>,
    joints: TopicPublisher<JointState>,
}

impl TargetPublishers {
    /// Create them.
    pub fn new(node: &mut RosNode) -> anyhow::Result<TargetPublishers> {
        Ok(TargetPublishers {
            xyz: node.publish_on(&topics::XYZ_TARGET)?,
            xyz_line: node.publish_on(&topics::XYZ_LINE_TARGET)?,
            pose: node.publish_on(&topics::POSE_TARGET)?,
            gripper: node.publish_on(&topics::GRIPPER_TARGET)?,
            joints: node.publish_on(&topics::JOINT_TARGET)?,
        })
    }

    /// Wait until the subscribers of the five topics have acknowledged every target
    /// published, at most `max_wait` (false on timeout).
    pub async fn delivered(&self, max_wait: Duration) -> bool {
        let (xyz, xyz_line, pose, gripper, joints) = tokio::join!(
            self.xyz.delivered(max_wait),
            self.xyz_line.delivered(max_wait),
            self.pose.delivered(max_wait),
            self.gripper.delivered(max_wait),
            self.joints.delivered(max_wait)
        );
        xyz && xyz_line && pose && gripper && joints
    }

    /// Publish the CDR sample `cdr` of the target topic `topic`; with `restamp`, its
    /// `header.stamp` becomes now (a replayed target is a new request, not an old one
    /// that compute_ik's `max_target_age` would refuse).
    pub fn publish(&self, topic: &str, cdr: &[u8], restamp: bool) -> anyhow::Result<()> {
        let stamp = |t: &mut Time| {
            if restamp {
                *t = Time::now();
            }
        };
        let bad = |e| anyhow!("{topic}: unreadable sample: {e}");
        match topic {
            "xyz_target" | "xyz_line_target" => {
                let mut m: PointStamped = eezybot_msgs::cdr::decode(cdr).map_err(bad)?;
                stamp(&mut m.header.stamp);
                let line = topic == topics::XYZ_LINE_TARGET.name;
                if line { &self.xyz_line } else { &self.xyz }.publish(m);
            }
            "pose_target" => {
                let mut m: PoseStamped = eezybot_msgs::cdr::decode(cdr).map_err(bad)?;
                stamp(&mut m.header.stamp);
                self.pose.publish(m);
            }
            "gripper_target" => {
                self.gripper
                    .publish(eezybot_msgs::cdr::decode(cdr).map_err(bad)?);
            }
            "joint_target" => {
                let mut m: JointState = eezybot_msgs::cdr::decode(cdr).map_err(bad)?;
                stamp(&mut m.header.stamp);
                self.joints.publish(m);
            }
            other => return Err(anyhow!("{other} is not a target topic")),
        }
        Ok(())
    }
}

/// Is the `foxglove_bind` parameter's address loopback (or the server off)? A Foxglove
/// server on any other address makes the panel's token required (generated if not set),
/// for the panel and for every Foxglove client alike.
pub fn bind_is_loopback(foxglove_bind: &str) -> bool {
    let bind = foxglove_bind.trim();
    bind.is_empty()
        || bind
            .parse::<std::net::SocketAddr>()
            .is_ok_and(|a| a.ip().is_loopback())
}

/// The `foxglove_origins` parameter as a list (comma-separated, blanks dropped).
pub fn origins(parameter: &str) -> Vec<String> {
    parameter
        .split(',')
        .map(str::trim)
        .filter(|o| !o.is_empty())
        .map(str::to_string)
        .collect()
}

/// Who may use the Foxglove server: the web panel's rules ([`AccessPolicy`]), with the
/// `Origin`s of `foxglove_origins` instead of the panel's own, the token from the URL
/// (`ws://HOST:8765/?token=…`) or an `Authorization` header. Every client it admits may publish when `foxglove_publish` is on: the panel's
/// token is required whenever `foxglove_bind` is not loopback, so a client that may
/// publish either presented it or is a program on this machine (or a page of a listed
/// origin).
pub fn gate(access: AccessPolicy, origins: Vec<String>) -> Gate {
    Arc::new(move |req: &UpgradeRequest| {
        let facts = RequestFacts {
            host: req.header("host"),
            origin: req.header("origin"),
            forwarded_proto: None,
            query_token: access::query_token(req.query()),
            header_token: req
                .header("authorization")
                .and_then(access::authorization_token),
            protocol_token: None,
        };
        access
            .check_listed_origins(&facts, &origins)
            .map(|_| Admitted { may_publish: true })
            .map_err(|r| Refused {
                status: r.status(),
                reason: r.to_string(),
            })
    })
}

/// The Foxglove server at work.
pub struct Serving<'a> {
    /// Forwards every topic a client subscribes until it is dropped (it never ends by
    /// itself).
    pub forwarding: LocalBoxFuture<'a, ()>,
    /// Its front's counters (refusals, limits hit), reported with the web panel's.
    pub front: Arc<foxglove_bridge::FrontStats>,
}

/// The Foxglove WebSocket server of the `foxglove_bind` parameter (`None` when empty,
/// or when it cannot listen).
///
/// Every connection passes [`gate`] first (the panel's `access` policy); Foxglove panels
/// may publish targets only with `foxglove_publish:=true`.
pub async fn serve<'a>(
    node: &'a RefCell<&mut RosNode>,
    access: AccessPolicy,
    tls: Option<Arc<rustls::ServerConfig>>,
) -> anyhow::Result<Option<Serving<'a>>> {
    let params = node.borrow().params().clone();
    let bind = params.string("foxglove_bind").unwrap_or_default();
    if bind.trim().is_empty() {
        log::info!("Foxglove WebSocket server off (foxglove_bind is empty)");
        return Ok(None);
    }
    let publish = if params.bool("foxglove_publish").unwrap_or(false) {
        ClientPublish::Targets { queue: 64 }
    } else {
        ClientPublish::Off
    };
    let token_required = access.token_required();
    let gate = gate(
        access,
        origins(&params.string("foxglove_origins").unwrap_or_default()),
    );
    let names = topic_names(&node.borrow());
    let server_name = node.borrow().resolver().node_name().to_string();
    let scheme = if tls.is_some() { "wss" } else { "ws" };
    let started = FoxgloveBridge::start_secure(
        &bind,
        &names,
        publish,
        &server_name,
        gate,
        FrontLimits::default(),
        tls,
    )
    .await;
    let mut bridge = match started {
        Ok(bridge) => bridge,
        Err(e) => {
            // the web panel goes on: a second gui_bridge on this host, or a Foxglove
            // bridge of another kind, may hold the default port
            log::warn!("Foxglove WebSocket server not started: {e}");
            return Ok(None);
        }
    };
    let targets = match publish {
        ClientPublish::Off => None,
        ClientPublish::Targets { .. } => Some(TargetPublishers::new(&mut node.borrow_mut())?),
    };
    log::info!(
        "Foxglove WebSocket server on {scheme}://{} ({}{})",
        bridge.local_addr(),
        if targets.is_some() {
            "clients may publish targets"
        } else {
            "watch only"
        },
        if token_required {
            ", token required: ws(s)://ADDRESS/?token=… as the panel's URL"
        } else {
            ", loopback only, no token"
        }
    );
    let front = bridge.front_stats();
    let from_clients = bridge.take_client_samples();
    Ok(Some(Serving {
        forwarding: forward(bridge, node, from_clients, targets).boxed_local(),
        front,
    }))
}

async fn forward(
    bridge: FoxgloveBridge,
    node: &RefCell<&mut RosNode>,
    from_clients: Option<tokio::sync::mpsc::Receiver<ClientSample>>,
    targets: Option<TargetPublishers>,
) {
    let from_panels = async {
        if let (Some(mut rx), Some(targets)) = (from_clients, targets.as_ref()) {
            while let Some(s) = rx.recv().await {
                if let Err(e) = targets.publish(s.topic, &s.cdr, false) {
                    log::warn!("from a Foxglove client: {e:#}");
                }
            }
        }
        futures::future::pending::<()>().await
    };
    let to_clients = async {
        let mut watched = bridge.watched();
        let mut taps = Taps::new();
        let always = always_tapped_topics();
        let mut wanted: BTreeSet<&'static str> = always.clone();
        taps.follow(node, &wanted);
        // a peer flooding samples over the limit gets a line every few seconds (each one
        // is counted in diagnostics: foxglove_oversized_samples)
        let mut complaints = ros_plumbing::logging::Throttle::default();
        loop {
            tokio::select! {
                changed = watched.changed() => {
                    if changed.is_err() {
                        break; // the server is gone
                    }
                    wanted = watched.borrow_and_update().iter().copied().chain(always.iter().copied()).collect();
                    taps.follow(node, &wanted);
                }
                Some((topic, cdr)) = taps.streams.next() => {
                    if let Err(e) = bridge.log(topic, &cdr, now_ns()) {
                        if let Some(quiet) = complaints.allow(topic, std::time::Instant::now()) {
                            log::warn!("Foxglove: {e}{}", ros_plumbing::logging::Throttle::suffix(quiet));
                        }
                    }
                }
            }
        }
    };
    futures::future::join(from_panels, to_clients).await;
}

/// `record FILE.mcap`: the targets and what it takes to view the session again
/// (`joint_states`, `tf`, `tf_static`, `robot_description`, `servo_state`) into an MCAP
/// file, until `shutdown`. It says what it records as it goes: each topic's first
/// sample (info), each target (debug: a user checking that the operator's targets were
/// taken, a test waiting for its last one), and each topic's count when it stops.
pub async fn record_mcap(
    node: &mut RosNode,
    path: &Path,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let shown = path.display().to_string();
    let names = topic_names(node);
    let mut recorder = McapRecorder::create(path, &names)
        .with_context(|| format!("cannot record into {shown}"))?;
    let samples = taps(node, |t| recorder.records(t))?;
    println!("recording the targets, joint_states, tf, tf_static, robot_description and servo_state into {shown}; Ctrl-C to stop");
    let counts = record_until(&mut recorder, &names, samples, shutdown, now_ns)
        .await
        .with_context(|| format!("writing {shown}"))?;
    let n = recorder
        .finish()
        .with_context(|| format!("finishing {shown}"))?;
    let per_topic: Vec<String> = topics::all()
        .iter()
        .filter(|t| t.recorded())
        .map(|t| {
            let count = counts.get(t.name).copied().unwrap_or(0);
            format!("{} {count}", names.shown(t.name))
        })
        .collect();
    println!(
        "recorded {n} messages into {shown}: {}",
        per_topic.join(", ")
    );
    Ok(())
}

/// How many samples of each topic (relative name) a recording took.
type Counts = HashMap<&'static str, u64>;

/// Write `samples` into `recorder`, each at `now()`, until `shutdown`; then what the
/// readers had already received (a target sent just before Ctrl-C is in the file).
async fn record_until<W: std::io::Write + std::io::Seek>(
    recorder: &mut McapRecorder<W>,
    names: &TopicNames,
    samples: impl futures::Stream<Item = RawSample>,
    shutdown: impl Future<Output = ()>,
    now: impl Fn() -> u64,
) -> anyhow::Result<Counts> {
    let targets: BTreeSet<&'static str> = topics::all()
        .iter()
        .filter(|t| t.target)
        .map(|t| t.name)
        .collect();
    let mut counts = Counts::new();
    let mut take = |(topic, cdr): RawSample| -> anyhow::Result<()> {
        if !recorder.write(topic, &cdr, now())? {
            return Ok(());
        }
        // reported once written: the file has it once the recording is finished
        let n = counts.entry(topic).or_insert(0);
        *n += 1;
        if *n == 1 {
            log::info!("{}: first sample recorded", names.shown(topic));
        }
        if targets.contains(topic) {
            log::debug!("{}: sample {n} recorded", names.shown(topic));
        }
        Ok(())
    };
    tokio::pin!(samples, shutdown);
    loop {
        tokio::select! {
            biased;
            _ = &mut shutdown => break,
            Some(sample) = samples.next() => take(sample)?,
        }
    }
    // what arrived before the stop, not what comes while the file is being closed
    while let Some(Some(sample)) = samples.next().now_or_never() {
        take(sample)?;
    }
    Ok(counts)
}

/// `play FILE.mcap`: publish the recording's targets at their recorded times relative to
/// the first (compute_ik applies its motion limits as to live targets), each stamped
/// now; waits up to `timeout` for compute_ik to subscribe `xyz_target`.
pub async fn play_mcap(
    node: &mut RosNode,
    path: &Path,
    timeout: Duration,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let shown = path.display().to_string();
    let recording = McapTargets::open(path).with_context(|| format!("cannot play {shown}"))?;
    if recording.is_empty() {
        return Err(anyhow!("{shown} has no targets to play"));
    }
    let publishers = TargetPublishers::new(node)?;
    let node = &*node;
    let work = async {
        let deadline = tokio::time::Instant::now() + timeout;
        while publishers.xyz.get_subscription_count(node.node()) == 0 {
            if tokio::time::Instant::now() > deadline {
                return Err(anyhow!(
                    "nobody subscribes {} (is compute_ik running in this ROS domain?)",
                    node.resolve(&topics::XYZ_TARGET)?
                ));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        // the subscriber's reader may match ours a moment later
        tokio::time::sleep(Duration::from_millis(300)).await;
        let start = tokio::time::Instant::now();
        let n = recording.len();
        play_at_recorded_times(
            recording.targets(),
            |offset| tokio::time::sleep_until(start + offset),
            |t| publishers.publish(t.topic, &t.cdr, true),
        )
        .await?;
        // the last samples reach their subscribers before the node shuts down
        if !publishers.delivered(crate::delivery::DELIVERED_WAIT).await {
            log::warn!(
                "a subscriber did not acknowledge the last targets within {:?}: it may have missed them",
                crate::delivery::DELIVERED_WAIT
            );
        }
        println!("played {n} targets from {shown}");
        anyhow::Ok(())
    };
    crate::delivery::until_shutdown(work, shutdown).await
}

/// `play`'s schedule: each target once `wait_until` (given its recorded time after the
/// first target's) returns, then `publish`ed, in the recording's order.
async fn play_at_recorded_times<W, F>(
    targets: &[RecordedTarget],
    mut wait_until: W,
    mut publish: impl FnMut(&RecordedTarget) -> anyhow::Result<()>,
) -> anyhow::Result<()>
where
    W: FnMut(Duration) -> F,
    F: Future<Output = ()>,
{
    let Some(first) = targets.first().map(|t| t.log_time_ns) else {
        return Ok(());
    };
    for t in targets {
        wait_until(Duration::from_nanos(t.log_time_ns.saturating_sub(first))).await;
        publish(t)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::{Cell, RefCell};
    use std::io::Cursor;

    /// A recording of xyz targets at these log times (ns), written and read back as
    /// `play` reads a file.
    fn recording(log_times_ns: &[u64]) -> McapTargets {
        let mut out = Cursor::new(Vec::new());
        let mut rec = McapRecorder::new(&mut out, &TopicNames::default()).unwrap();
        for (i, &t) in log_times_ns.iter().enumerate() {
            let target = PointStamped {
                point: eezybot_msgs::geometry_msgs::Point {
                    x: i as f64,
                    ..Default::default()
                },
                ..Default::default()
            };
            let cdr = eezybot_msgs::cdr::encode(&target).unwrap();
            assert!(
                rec.write("xyz_target", &cdr, t).unwrap(),
                "xyz_target is recorded"
            );
        }
        rec.finish().unwrap();
        McapTargets::from_bytes(out.get_ref()).unwrap()
    }

    /// The simulated time (since the first target) at which each target was published,
    /// and which target (its x): the clock moves only when the player waits.
    fn played(targets: &McapTargets) -> Vec<(Duration, f64)> {
        let now = Cell::new(Duration::ZERO);
        let log = RefCell::new(Vec::new());
        let wait_until = |at: Duration| {
            now.set(now.get().max(at));
            std::future::ready(())
        };
        let publish = |t: &RecordedTarget| {
            let m: PointStamped = eezybot_msgs::cdr::decode(&t.cdr)?;
            log.borrow_mut().push((now.get(), m.point.x));
            Ok(())
        };
        futures::executor::block_on(play_at_recorded_times(
            targets.targets(),
            wait_until,
            publish,
        ))
        .unwrap();
        log.into_inner()
    }

    #[test]
    fn record_takes_the_samples_received_before_the_stop() {
        // three targets already received when Ctrl-C comes, and a reader that goes on
        // (nothing more arrives)
        let targets: Vec<RawSample> = (0..3)
            .map(|i| {
                let target = PointStamped {
                    point: eezybot_msgs::geometry_msgs::Point {
                        x: f64::from(i),
                        ..Default::default()
                    },
                    ..Default::default()
                };
                ("xyz_target", eezybot_msgs::cdr::encode(&target).unwrap())
            })
            .collect();
        let samples = futures::stream::iter(targets).chain(futures::stream::pending());
        let names = TopicNames::default();
        let mut out = Cursor::new(Vec::new());
        let mut rec = McapRecorder::new(&mut out, &names).unwrap();
        let counts = futures::executor::block_on(record_until(
            &mut rec,
            &names,
            samples,
            std::future::ready(()),
            || 1_795_000_000_000_000_000,
        ))
        .unwrap();
        rec.finish().unwrap();
        assert_eq!(counts.get("xyz_target"), Some(&3));
        let xs: Vec<f64> = McapTargets::from_bytes(out.get_ref())
            .unwrap()
            .targets()
            .iter()
            .map(|t| {
                eezybot_msgs::cdr::decode::<PointStamped>(&t.cdr)
                    .unwrap()
                    .point
                    .x
            })
            .collect();
        assert_eq!(xs, vec![0.0, 1.0, 2.0]);
    }

    #[test]
    fn play_publishes_each_target_at_its_recorded_time_after_the_first() {
        let t0 = 1_795_000_000_000_000_000;
        let ms = |n: u64| Duration::from_millis(n);
        let got = played(&recording(&[t0, t0 + 600_000_000, t0 + 1_500_000_000]));
        assert_eq!(got, vec![(ms(0), 0.0), (ms(600), 1.0), (ms(1500), 2.0)]);
    }

    #[test]
    fn play_follows_the_log_times_not_the_order_of_writing() {
        let t0 = 1_795_000_000_000_000_000;
        let ms = |n: u64| Duration::from_millis(n);
        // written late: the second sample was received before the first
        let got = played(&recording(&[t0 + 200_000_000, t0, t0 + 900_000_000]));
        assert_eq!(got, vec![(ms(0), 1.0), (ms(200), 0.0), (ms(900), 2.0)]);
    }
}
