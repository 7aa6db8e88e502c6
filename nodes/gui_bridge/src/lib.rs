#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod access;
pub mod cli;
pub mod delivery;
pub mod desk;
pub mod foxglove;
pub mod linger;
pub mod program;
pub mod record;
pub mod ros_outputs;
pub mod serve;
pub mod teleop;
pub mod web;

use crate::teleop::{Command, Event, RobotView, Teleop};
use crate::web::{ClientRequest, FromClient, Requests, WebStats};
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::{ArmJoints, ACTUATED_JOINTS};
use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use futures::{Stream, StreamExt};
use ros_plumbing::diagnostics::{
    status_node, LatencyWindow, LAST_REJECTION_KEY, REJECTED_STAMP_KEY,
};
use ros_plumbing::logging::{shorten, Throttle};
use ros_plumbing::peers::{Peer, PeerWatch};
use ros_plumbing::topics;
use ros_plumbing::{ParamRange, ParamSpec, ParameterValue, Params};
use serde_json::json;
use std::collections::{BTreeMap, VecDeque};
use std::future::Future;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::broadcast;

/// The default `foxglove_origins`: Foxglove's web app.
pub const FOXGLOVE_ORIGINS: &str = "https://app.foxglove.dev";

/// The node's description and parameters.
pub fn spec() -> ros_plumbing::NodeSpec {
    ros_plumbing::NodeSpec {
        name: "gui_bridge",
        description: "operator input (web page, keyboard, gamepad, command line) -> xyz_target / gripper_target / joint_target / estop",
        usage: "[serve | once X Y Z [--gripper G] [--line] [--timeout S] | play WAYPOINTS.csv|RUN.mcap [--line] [--timeout S] | record OUT.csv|OUT.mcap]",
        params: vec![
            ParamSpec::new("bind", ParameterValue::String("127.0.0.1:8080".into()), "address:port of the web page").read_only(),
            ParamSpec::new(
                "token",
                ParameterValue::String(String::new()),
                "access token of the web page (16-256 of A-Z a-z 0-9 - . _ ~); empty = none on a loopback bind, generated and printed otherwise; reads (generated) or (hidden) once running",
            )
            .read_only()
            .validator(|v| match v {
                ParameterValue::String(t) => access::check_token_parameter(t),
                _ => Ok(()),
            }),
            ParamSpec::new("rate", ParameterValue::Double(50.0), "most messages a second on each target topic (latest wins)")
                .range(ParamRange::Double { min: 1.0, max: 500.0 }),
            ParamSpec::new(
                "arm_config",
                ParameterValue::String(String::new()),
                "arm geometry and limits for the reachability check; empty = the shipped config/arm.yaml",
            )
            .validator(|v| match v {
                ParameterValue::String(p) => load_arm(p).map(|_| ()),
                _ => Ok(()),
            }),
            ParamSpec::new("base_frame", ParameterValue::String("base_link".into()), "frame_id of the targets sent"),
            ParamSpec::new(
                "program_dir",
                ParameterValue::String(String::new()),
                "where the panel saves and loads waypoint programs (NAME.csv, which `gui_bridge play` runs too); empty = $ROS_HOME/eezybot_programs, else ~/.ros/eezybot_programs",
            )
            .read_only(),
            ParamSpec::new(
                "foxglove_bind",
                ParameterValue::String(foxglove_bridge::DEFAULT_BIND.into()),
                "address:port of the Foxglove WebSocket server (every topic, ros2msg schemas, CDR; a topic is subscribed only while a Foxglove client watches it); empty = off",
            )
            .read_only()
            .validator(|v| match v {
                ParameterValue::String(b) if !b.trim().is_empty() => b
                    .parse::<std::net::SocketAddr>()
                    .map(|_| ())
                    .map_err(|_| format!("{b:?} is not an address like 127.0.0.1:8765 or [::1]:8765")),
                _ => Ok(()),
            }),
            ParamSpec::new(
                "foxglove_publish",
                ParameterValue::Boolean(false),
                "let Foxglove clients publish xyz_target, pose_target, gripper_target, joint_target (each client passes the panel's rules first: Origin, Host, and the token, which a foxglove_bind beyond loopback requires)",
            )
            .read_only(),
            ParamSpec::new(
                "foxglove_origins",
                ParameterValue::String(FOXGLOVE_ORIGINS.into()),
                "web origins allowed to connect to the Foxglove server, comma-separated (a request without Origin, from a program, always may); empty = none",
            )
            .read_only(),
        ],
    }
}

/// The arm model from an `arm_config` path (empty: the shipped configuration).
pub fn load_arm(path: &str) -> Result<eezybot_kinematics::Arm, String> {
    eezybot_kinematics::ArmConfig::load_or_shipped(path)
        .map(|c| c.arm())
        .map_err(|e| e.to_string())
}

/// One ROS input of the bridge.
#[derive(Clone, Debug)]
pub enum Input {
    /// `joint_states`
    JointStates(JointState),
    /// `robot_description`
    RobotDescription(String),
    /// `diagnostics`
    Diagnostics(DiagnosticArray),
    /// `servo_state`
    ServoState(JointState),
    /// `estop`
    Estop(bool),
    /// A sample on `topic` that could not be deserialized (malformed CDR): logged,
    /// counted in `diagnostics`, otherwise ignored (an unreadable `estop` changes nothing).
    Unreadable {
        /// the topic, as subscribed (`joint_states`, `estop`, …)
        topic: &'static str,
        /// why it could not be read
        error: String,
    },
}

/// Samples that could not be read, for `diagnostics` and the (throttled) log.
#[derive(Debug, Default)]
struct UnreadableSamples {
    count: u64,
    last: Option<String>,
    complaints: Throttle,
}

impl UnreadableSamples {
    fn note(&mut self, topic: &str, error: &str) {
        self.count += 1;
        let error = shorten(error, web::REASON_MAX);
        self.last = Some(format!("{topic}: {error}"));
        if let Some(quiet) = self.complaints.allow(topic, Instant::now()) {
            log::warn!(
                "unreadable sample on {topic} ignored: {error}{}",
                Throttle::suffix(quiet)
            );
        }
    }

    fn values(&self) -> [(&'static str, String); 2] {
        [
            ("unreadable_samples", self.count.to_string()),
            (
                "last_unreadable_sample",
                self.last.clone().unwrap_or_default(),
            ),
        ]
    }
}

/// Where the bridge's targets go.
pub trait Outputs {
    /// Publish on `xyz_target` with this stamp.
    fn xyz_target(&self, xyz: [f64; 3], stamp: Time);
    /// Publish on `gripper_target`.
    fn gripper_target(&self, opening: f64);
    /// Publish on `joint_target` with this stamp.
    fn joint_target(&self, positions: &[(String, f64)], stamp: Time);
    /// Publish on `estop`.
    fn estop(&self, engaged: bool);
    /// Publish a `diagnostics` report with this status.
    fn diagnostics(&self, status: DiagnosticStatus);
}

/// The topics whose peers the web panel watches (resolved names): `xyz_target`
/// subscribers (compute_ik) and `servo_state` publishers (serial_node, usually on
/// another machine).
pub fn watched_topics(xyz_target: &str, servo_state: &str) -> Vec<(String, Peer)> {
    vec![
        (xyz_target.to_string(), Peer::Subscriber),
        (servo_state.to_string(), Peer::Publisher),
    ]
}

/// How the web panel reports itself on `diagnostics`.
pub struct Reporting<F: Fn() -> Vec<usize>> {
    /// The entry's name (`gui_bridge: operator panel`).
    pub name: String,
    /// Where the panel is served.
    pub url: String,
    /// The watched topics' peers.
    pub peers: PeerWatch,
    /// Their counts now, in [`watched_topics`]' order.
    pub counts: F,
    /// The web side's counters (clients, refusals, limits hit).
    pub web: Arc<WebStats>,
}

/// How long a refused client keeps the panel's diagnostics at WARN.
pub const REFUSAL_WARN_FOR: Duration = Duration::from_secs(60);

/// Longest node name (and task, hardware id) the panel shows.
const NODE_NAME_MAX: usize = ros_plumbing::diagnostics::NODE_NAME_MAX;
/// Most nodes the panel tracks; a new one beyond them replaces one gone silent, if any.
pub const MAX_TRACKED_NODES: usize = 16;
/// A node heard within this is up.
const UP_WITHIN: Duration = Duration::from_secs(3);
/// A node not heard for this long is forgotten (its task's placeholder shows again).
const FORGET_AFTER: Duration = Duration::from_secs(60);

/// The graph's other nodes the panel always shows: (default node name, the task their
/// `diagnostics` entry names). Until a node reporting that task is heard, the default
/// name shows as missing; any node reporting it, under whatever name, takes its place.
pub const EXPECTED_NODES: [(&str, &str); 3] = [
    ("compute_ik", "inverse kinematics"),
    ("state_publisher", "robot state"),
    ("serial_node", "servo link"),
];

struct Heard {
    task: String,
    hardware_id: String,
    level: u8,
    message: String,
    at: Instant,
}

/// Health of the other nodes, from their `diagnostics`: every node heard, by the name
/// it reports (so under any remap or namespace), besides this one.
struct NodeHealth {
    own: String,
    seen: BTreeMap<String, Heard>,
    last_rejection: Option<String>,
}

impl NodeHealth {
    fn new(own: &str) -> Self {
        NodeHealth {
            own: own.to_string(),
            seen: BTreeMap::new(),
            last_rejection: None,
        }
    }

    fn update(&mut self, msg: &DiagnosticArray) {
        let now = Instant::now();
        self.seen
            .retain(|_, h| now.duration_since(h.at) < FORGET_AFTER);
        for s in &msg.status {
            if let Some(kv) = s.values.iter().find(|kv| kv.key == REJECTED_STAMP_KEY) {
                let reason = s
                    .values
                    .iter()
                    .find(|kv| kv.key == LAST_REJECTION_KEY)
                    .map_or(kv.value.as_str(), |r| r.value.as_str());
                self.last_rejection = Some(shorten(reason, web::REASON_MAX).into_owned());
            }
            let Some((node, task)) = status_node(&s.name) else {
                continue;
            };
            if node == self.own {
                continue;
            }
            if !self.seen.contains_key(node) && self.seen.len() >= MAX_TRACKED_NODES {
                // room only by forgetting one gone silent: a flood of names never
                // pushes out a node that is up
                let silent = self
                    .seen
                    .iter()
                    .filter(|(_, h)| now.duration_since(h.at) >= UP_WITHIN)
                    .min_by_key(|(_, h)| h.at)
                    .map(|(n, _)| n.clone());
                match silent {
                    Some(n) => self.seen.remove(&n),
                    None => continue,
                };
            }
            self.seen.insert(
                node.to_string(),
                Heard {
                    task: shorten(task, NODE_NAME_MAX).into_owned(),
                    hardware_id: shorten(&s.hardware_id, NODE_NAME_MAX).into_owned(),
                    level: s.level,
                    message: shorten(&s.message, web::REASON_MAX).into_owned(),
                    at: now,
                },
            );
        }
    }

    /// `{"t": "status", "nodes": [{name, task, hardware_id, up, level, message, age_s}…],
    /// "last_rejection"}`: the expected tasks first (each node heard reporting it, or its
    /// default name as missing), then every other node heard, by name.
    fn json(&self) -> serde_json::Value {
        let entry = |name: &str, h: &Heard| {
            let age = h.at.elapsed();
            json!({"name": name, "task": h.task, "hardware_id": h.hardware_id, "up": age < UP_WITHIN,
                   "level": h.level, "message": h.message, "age_s": age.as_secs_f64()})
        };
        let mut nodes = vec![];
        let mut listed: Vec<&str> = vec![];
        for (default, task) in EXPECTED_NODES {
            let mut doing = self
                .seen
                .iter()
                .filter(|(n, h)| h.task == task || n.as_str() == default)
                .peekable();
            if doing.peek().is_none() {
                nodes.push(json!({"name": default, "task": task, "hardware_id": "", "up": false,
                                  "level": DiagnosticStatus::STALE, "message": "not seen", "age_s": null}));
            }
            for (n, h) in doing {
                if !listed.contains(&n.as_str()) {
                    listed.push(n);
                    nodes.push(entry(n, h));
                }
            }
        }
        for (n, h) in &self.seen {
            if !listed.contains(&n.as_str()) {
                nodes.push(entry(n, h));
            }
        }
        json!({"t": "status", "nodes": nodes, "last_rejection": self.last_rejection})
    }
}

/// Arrival time − stamp of `servo_state` replies to our own targets.
struct Latency {
    /// stamps of our last 200 targets, ns
    ours: VecDeque<i64>,
    /// the last 50 latencies, ms
    ms: LatencyWindow,
}

impl Default for Latency {
    fn default() -> Self {
        Latency {
            ours: VecDeque::new(),
            ms: LatencyWindow::new(50),
        }
    }
}

impl Latency {
    fn sent(&mut self, stamp: Time) {
        if self.ours.len() == 200 {
            self.ours.pop_front();
        }
        self.ours.push_back(stamp.to_nanos());
    }
    fn reply(&mut self, stamp: Time) -> Option<serde_json::Value> {
        let i = self.ours.iter().position(|s| *s == stamp.to_nanos())?;
        self.ours.remove(i);
        let ms = (Time::now().to_nanos() - stamp.to_nanos()) as f64 / 1e6;
        self.ms.push(ms);
        Some(
            json!({"t": "latency", "ms": ms, "median_ms": self.ms.percentile(0.5), "n": self.ms.len()}),
        )
    }
}

fn joints_json(q: &ArmJoints) -> serde_json::Value {
    json!({"base_joint": q.base_rad, "shoulder_joint": q.shoulder_rad, "elbow_joint": q.elbow_rad})
}

/// The panel's program directory: the `program_dir` parameter, else
/// `$ROS_HOME/eezybot_programs`, else `~/.ros/eezybot_programs` (ROS 2's own default for
/// `ROS_HOME`), else `./eezybot_programs`.
pub fn program_dir(param: &str) -> std::path::PathBuf {
    if !param.trim().is_empty() {
        return param.into();
    }
    let home = |v: &str| std::env::var_os(v).filter(|s| !s.is_empty());
    match (home("ROS_HOME"), home("HOME")) {
        (Some(ros), _) => std::path::Path::new(&ros).join("eezybot_programs"),
        (None, Some(h)) => std::path::Path::new(&h)
            .join(".ros")
            .join("eezybot_programs"),
        (None, None) => "eezybot_programs".into(),
    }
}

/// The arm as the page needs it: its name, whether it is the EezyBot, the joint
/// mode's sliders (from the URDF once `robot_description` arrived) and its reach.
pub fn robot_json(teleop: &Teleop) -> serde_json::Value {
    let sliders: Vec<serde_json::Value> = teleop
        .joint_sliders()
        .iter()
        .map(|j| json!({"name": j.name, "lower": j.lower, "upper": j.upper}))
        .collect();
    let scene = teleop.scene();
    let field = |k: &str| scene.and_then(|s| s.get(k)).cloned();
    match teleop.robot() {
        Some(RobotView {
            name,
            eezybot,
            reach_m,
            tool_link,
            ..
        }) => json!({
            "name": name, "eezybot": eezybot, "joints": sliders, "reach": reach_m,
            "tool_link": tool_link, "from_urdf": true,
            // the page fetches the text (it can be larger than a WebSocket client's buffer)
            "urdf": teleop.urdf().map(|(_, rev)| format!("robot.urdf?rev={rev}")),
            "envelope": field("envelope"),
        }),
        None => json!({
            "name": "eezybot", "eezybot": true, "joints": sliders, "reach": 0.33,
            "tool_link": "tool0", "from_urdf": false,
        }),
    }
}

/// The snapshot a browser gets when it connects.
pub fn hello_json(teleop: &Teleop, rate: f64) -> String {
    let arm = teleop.arm();
    let l = arm.limits;
    let g = arm.geometry;
    json!({
        "t": "hello",
        "target": teleop.target(),
        "pose": teleop.last_pose(),
        "rate": rate,
        "robot": robot_json(teleop),
        "program": teleop.program(),
        "limits": {
            "base_joint": [l.base_rad.0, l.base_rad.1],
            "shoulder_joint": [l.shoulder_rad.0, l.shoulder_rad.1],
            "elbow_joint": [l.elbow_rad.0, l.elbow_rad.1],
            "gripper_joint": [0.0, g.gripper_open_rad],
        },
        "workspace": {"x": [0.0, 0.30], "y": [-0.22, 0.22], "z": [0.0, 0.30]},
        "geometry": {"shoulder_height": g.shoulder_height_m, "main_arm": g.main_arm_m, "forearm": g.forearm_m, "tool_dx": g.tool_dx_m},
    })
    .to_string()
}

/// The page's 3D view of `model`: the reachable workspace, for the EezyBot the solid of
/// revolution of its closed form's limits, for any other arm a cloud of its tool's
/// positions at random configurations.
///
/// The EezyBot's envelope depends on the arm's configuration only: computed once, into
/// `eezybot`. Another arm's is computed for each new description, within the node's loop,
/// so only for a chain of at most [`ENVELOPE_MAX_JOINTS`] joints (a description of
/// thousands of links would hold the loop for seconds).
fn scene_json(
    model: &RobotModel,
    teleop: &Teleop,
    eezybot: &std::cell::OnceCell<eezybot_kinematics::envelope::Envelope>,
) -> serde_json::Value {
    use eezybot_kinematics::envelope::{chain_envelope, eezybot_envelope};
    let envelope = match teleop.robot() {
        Some(r) if !r.eezybot => r
            .tool_link
            .as_ref()
            .filter(|_| model.joints.len() <= ENVELOPE_MAX_JOINTS)
            .and_then(|tip| {
                eezybot_kinematics::chain::SerialChain::from_model(model, &model.root, tip)
                    .ok()
                    .map(|chain| chain_envelope(&chain, 2000, 1))
            }),
        _ => Some(
            eezybot
                .get_or_init(|| eezybot_envelope(teleop.arm(), 0.004))
                .clone(),
        ),
    };
    json!({ "envelope": envelope })
}

/// The most joints a URDF may have for the 3D view to get its workspace envelope.
pub const ENVELOPE_MAX_JOINTS: usize = 64;

/// Segments (parent origin → child origin, child link name) of every joint of the URDF
/// for these joint positions, for the page's side and top views.
fn segments(model: &RobotModel, js: &JointState) -> Vec<([f64; 6], String)> {
    let positions: Vec<(&str, f64)> = js
        .name
        .iter()
        .map(String::as_str)
        .zip(js.position.iter().copied())
        .collect();
    let poses = model.link_poses(&positions);
    model
        .joints
        .iter()
        .filter_map(|j| {
            let a = poses.get(&j.parent)?.translation.vector;
            let b = poses.get(&j.child)?.translation.vector;
            ((b - a).norm() > 1e-6).then(|| ([a.x, a.y, a.z, b.x, b.y, b.z], j.child.clone()))
        })
        .collect()
}

/// Apply one browser request and answer it (a full reply queue drops the answer: the
/// loop never waits for a client).
fn serve_request(teleop: &std::sync::Mutex<Teleop>, from: FromClient, stats: &WebStats) {
    let FromClient { request, reply } = from;
    let event = match request {
        ClientRequest::Check { xyz } => {
            let answer = match teleop.lock().map(|t| (t.is_eezybot(), t.check(xyz))) {
                Ok((false, _)) => {
                    json!({"t": "check", "xyz": xyz, "reachable": null, "reason": "not checked here: this arm has no closed form, compute_ik decides when it is sent"})
                }
                Ok((true, Ok(q))) => {
                    json!({"t": "check", "xyz": xyz, "reachable": true, "joints": joints_json(&q)})
                }
                Ok((true, Err(e))) => {
                    json!({"t": "check", "xyz": xyz, "reachable": false, "reason": e.to_string()})
                }
                Err(_) => return,
            };
            answer_client(&reply, answer, stats);
            return;
        }
        ClientRequest::Target { xyz } => Event::SetTarget { xyz },
        ClientRequest::Jog { d } => Event::Jog { dxyz: d },
        ClientRequest::Gripper { v } => Event::Gripper { opening: v },
        ClientRequest::Joints { q } => Event::Joints {
            positions: q.into_iter().collect(),
        },
        ClientRequest::Estop { on } => Event::Estop { engaged: on },
        // the run loop's desk takes these
        ClientRequest::Program(_) => return,
    };
    let result = teleop
        .lock()
        .map(|mut t| (t.is_eezybot(), t.handle_event(event)));
    let answer = match result {
        Ok((true, Ok(f))) => {
            json!({"t": "ack", "target": f.target, "joints": joints_json(&f.joints), "reachable": true})
        }
        Ok((false, Ok(f))) => {
            json!({"t": "ack", "target": f.target, "joints": null, "reachable": true})
        }
        Ok((_, Err(refusal))) => {
            let reason = refusal.to_string();
            stats.rejected_request(refusal.kind(), &reason);
            json!({"t": "refused", "reason": shorten(&reason, web::REASON_MAX), "reachable": false})
        }
        Err(_) => return,
    };
    answer_client(&reply, answer, stats);
}

fn answer_client(
    reply: &tokio::sync::mpsc::Sender<String>,
    answer: serde_json::Value,
    stats: &WebStats,
) {
    if let Err(tokio::sync::mpsc::error::TrySendError::Full(_)) = reply.try_send(answer.to_string())
    {
        stats.dropped_replies.fetch_add(1, Ordering::Relaxed);
    }
}

/// Publish what the operator state has due now; tell the browsers.
fn publish_due(
    teleop: &std::sync::Mutex<Teleop>,
    outputs: &impl Outputs,
    sent: &mut u64,
    latency: &mut Latency,
    to_browsers: &broadcast::Sender<String>,
) -> Option<Time> {
    let send = |v: serde_json::Value| {
        let _ = to_browsers.send(v.to_string());
    };
    let mut xyz_stamp = None;
    let commands = teleop
        .lock()
        .map(|mut t| t.take_due(Instant::now()))
        .unwrap_or_default();
    for c in commands {
        let stamp = Time::now();
        match &c {
            Command::Target(xyz) => {
                *sent += 1;
                xyz_stamp = Some(stamp);
                outputs.xyz_target(*xyz, stamp);
                latency.sent(stamp);
                send(
                    json!({"t": "sent", "topic": topics::XYZ_TARGET.name, "xyz": xyz, "stamp_ns": stamp.to_nanos()}),
                );
            }
            Command::Gripper(g) => {
                outputs.gripper_target(*g);
                send(json!({"t": "sent", "topic": topics::GRIPPER_TARGET.name, "value": g}));
            }
            Command::Joints(q) => {
                outputs.joint_target(q, stamp);
                latency.sent(stamp);
                send(
                    json!({"t": "sent", "topic": topics::JOINT_TARGET.name, "q": q, "stamp_ns": stamp.to_nanos()}),
                );
            }
            Command::Estop(on) => {
                outputs.estop(*on);
                send(json!({"t": "sent", "topic": topics::ESTOP.name, "on": on}));
            }
        }
    }
    xyz_stamp
}

/// The loop between browsers and ROS; runs until `shutdown` resolves.
///
/// Its work in order of priority: shutdown, e-stop requests, targets due, the periodic
/// reports, ROS inputs, then other browser requests; so a browser flooding requests
/// delays neither an e-stop nor the targets nor the live view.
#[allow(clippy::too_many_arguments)]
pub async fn run<F: Fn() -> Vec<usize>>(
    teleop: std::sync::Arc<std::sync::Mutex<Teleop>>,
    inputs: impl Stream<Item = Input>,
    mut requests: Requests,
    to_browsers: broadcast::Sender<String>,
    outputs: &impl Outputs,
    params: Params,
    mut reporting: Reporting<F>,
    mut desk: desk::Desk,
    motion: &dyn desk::MotionControl,
    shutdown: impl Future<Output = ()>,
) {
    let mut sent = 0u64;
    let mut diag_tick = tokio::time::interval(Duration::from_secs(1));
    let mut peer_poll = tokio::time::interval(Duration::from_millis(250));
    let report = |peers: &PeerWatch, sent: u64, unreadable: &UnreadableSamples| {
        let mut values = vec![
            ("url", reporting.url.clone()),
            ("targets_sent", sent.to_string()),
        ];
        values.extend(reporting.web.values());
        values.extend(unreadable.values());
        let recent = reporting
            .web
            .last_refusal()
            .filter(|(at, _)| at.elapsed() < REFUSAL_WARN_FOR);
        if let Some((_, last)) = reporting.web.last_refusal() {
            values.push(("last_refusal", last));
        }
        let (level, message) = match recent {
            Some((at, last)) => (
                DiagnosticStatus::WARN,
                format!(
                    "web panel on {}; refused a client {:.0} s ago ({} refusals in all): {last}",
                    reporting.url,
                    at.elapsed().as_secs_f64(),
                    reporting.web.refused_total()
                ),
            ),
            None => (
                DiagnosticStatus::OK,
                format!("web panel on {}", reporting.url),
            ),
        };
        let mut s =
            ros_plumbing::diagnostics::status(level, &reporting.name, "", &message, &values);
        peers.annotate(&mut s, Instant::now());
        outputs.diagnostics(s);
    };
    let own = status_node(&reporting.name).map_or("", |(n, _)| n);
    let mut health = NodeHealth::new(own);
    let mut unreadable = UnreadableSamples::default();
    let mut latency = Latency::default();
    let mut model: Option<RobotModel> = None;
    let eezybot_envelope = std::cell::OnceCell::new();
    let mut status_tick = tokio::time::interval(Duration::from_millis(500));
    let mut param_changes = params.subscribe();
    let send = |v: serde_json::Value| {
        let _ = to_browsers.send(v.to_string());
    };
    // a browser that connects later gets the latest pose with its hello
    let send_pose = |v: serde_json::Value| {
        let _ = to_browsers.send(v.to_string());
        if let Ok(mut t) = teleop.lock() {
            t.set_last_pose(v);
        }
    };
    tokio::pin!(inputs);
    tokio::pin!(shutdown);
    // the waypoint program: where the tool and the claw are (teach, arrival), and
    // compute_ik's `motion` being set (Some: for a point's move mode) or put back (None)
    let mut last_tool: Option<[f64; 3]> = None;
    let mut last_gripper: Option<f64> = None;
    let mut motion_job: Option<futures::future::LocalBoxFuture<'_, Option<Result<(), String>>>> =
        None;
    // a program file's load or save, off the event loop (a FIFO, a hung mount: the loop
    // goes on, the job times out)
    let mut file_job: Option<futures::future::BoxFuture<'static, desk::FileDone>> = None;
    if let Ok(mut t) = teleop.lock() {
        t.set_program(desk.json());
    }
    macro_rules! desk_outcome {
        ($out:expr) => {{
            let out: desk::DeskOutcome = $out;
            if let Some(job) = out.file.clone() {
                let dir = desk.dir().to_path_buf();
                file_job = Some(Box::pin(async move {
                    let fallback = job.clone();
                    let blocking = tokio::task::spawn_blocking(move || job.run(&dir));
                    match tokio::time::timeout(desk::FILE_TIMEOUT, blocking).await {
                        Ok(Ok(done)) => done,
                        _ => fallback.timed_out(desk::FILE_TIMEOUT),
                    }
                }));
            }
            if let Some(mode) = out.set_mode {
                motion_job = Some(Box::pin(async move { Some(motion.set(mode).await) }));
            } else if out.restore_mode {
                motion_job = Some(Box::pin(async move {
                    motion.restore().await;
                    None
                }));
            }
            if out.changed || out.set_mode.is_some() || out.restore_mode {
                let v = desk.json();
                if let Ok(mut t) = teleop.lock() {
                    t.set_program(v.clone());
                }
                send(v);
            }
        }};
    }
    macro_rules! desk_step {
        () => {{
            let out = match teleop.lock() {
                Ok(mut t) => desk.play_step(&mut t, Instant::now(), last_tool),
                Err(_) => desk::DeskOutcome::default(),
            };
            desk_outcome!(out);
        }};
    }
    loop {
        let now = Instant::now();
        let desk_wake = desk.next_wakeup();
        let due = teleop.lock().ok().and_then(|t| t.next_due(now));
        if due.is_some_and(|d| d <= now) {
            // Due now: publish before anything else. (A sleep until a past instant ends
            // only when the timer next runs, which a loop kept busy by requests would put
            // off for as long as they keep coming.)
            if let Some(stamp) =
                publish_due(&teleop, outputs, &mut sent, &mut latency, &to_browsers)
            {
                desk.published_target(stamp);
            }
            continue;
        }
        tokio::select! {
            biased;
            _ = &mut shutdown => break,
            Some(from) = requests.estops.recv() => {
                let engaged = matches!(from.request, ClientRequest::Estop { on: true });
                serve_request(&teleop, from, &reporting.web);
                if engaged && desk.playing() {
                    desk_outcome!(desk::DeskOutcome { restore_mode: desk.stop(), changed: true, ..Default::default() });
                }
            }
            _ = async { if let Some(d) = due { tokio::time::sleep_until(d.into()).await } }, if due.is_some() => {
                if let Some(stamp) = publish_due(&teleop, outputs, &mut sent, &mut latency, &to_browsers) {
                    desk.published_target(stamp);
                }
            }
            _ = async { if let Some(w) = desk_wake { tokio::time::sleep_until(w.into()).await } }, if desk_wake.is_some() => {
                desk_step!();
            }
            done = async { match file_job.as_mut() { Some(job) => job.await, None => futures::future::pending().await } }, if file_job.is_some() => {
                file_job = None;
                desk_outcome!(desk.file_done(done));
            }
            done = async { match motion_job.as_mut() { Some(job) => job.await, None => futures::future::pending().await } }, if motion_job.is_some() => {
                motion_job = None;
                if let Some(result) = done {
                    desk.mode_set(result);
                    desk_step!();
                }
            }
            _ = status_tick.tick() => send(health.json()),
            _ = diag_tick.tick() => report(&reporting.peers, sent, &unreadable),
            _ = peer_poll.tick() => {
                let changes = reporting.peers.update(&(reporting.counts)(), Instant::now());
                changes.iter().for_each(|c| c.log());
                if !changes.is_empty() {
                    report(&reporting.peers, sent, &unreadable);
                }
            }
            Ok(()) = param_changes.changed() => {
                if let Ok(mut t) = teleop.lock() {
                    t.set_rate(params.f64("rate").unwrap_or(50.0));
                }
            }
            input = inputs.next() => {
                let Some(input) = input else { break };
                let joint_states = matches!(input, Input::JointStates(_));
                match input {
                    Input::JointStates(js) if !teleop.lock().map(|t| t.is_eezybot()).unwrap_or(true) => {
                        // any other arm: every joint, the links' segments and its tool
                        if let Some(m) = model.as_ref() {
                            let finite: Vec<(String, f64)> = js.name.iter().cloned().zip(js.position.iter().copied())
                                .filter(|(_, v)| v.is_finite()).collect();
                            let refs: Vec<(&str, f64)> = finite.iter().map(|(n, v)| (n.as_str(), *v)).collect();
                            let tool_link = teleop.lock().ok().and_then(|t| t.robot().and_then(|r| r.tool_link.clone()));
                            let tool = tool_link.and_then(|l| m.link_poses(&refs).get(&l).map(|p| p.translation.vector));
                            last_tool = tool.map(|p| [p.x, p.y, p.z]);
                            let joints: serde_json::Map<String, serde_json::Value> = finite.iter()
                                .filter(|(n, _)| m.joint_index(n).is_some())
                                .map(|(n, v)| (n.clone(), json!(v))).collect();
                            send_pose(json!({
                                "t": "pose", "joints": joints, "gripper": null,
                                "tool": tool.map(|p| [p.x, p.y, p.z]),
                                "segments": segments(m, &js),
                            }));
                        }
                    }
                    Input::JointStates(js) => {
                        let get = |n: &str| js.name.iter().position(|x| x == n).and_then(|i| js.position.get(i).copied());
                        if let (Some(b), Some(s), Some(e)) = (get(ACTUATED_JOINTS[0]), get(ACTUATED_JOINTS[1]), get(ACTUATED_JOINTS[2])) {
                            if b.is_finite() && s.is_finite() && e.is_finite() {
                                let q = ArmJoints { base_rad: b, shoulder_rad: s, elbow_rad: e };
                                let tool = teleop.lock().map(|mut t| { t.observe_joints(q); t.arm().forward(&q) });
                                last_tool = tool.as_ref().ok().map(|p| [p.x, p.y, p.z]);
                                let open_rad = teleop.lock().map(|t| t.arm().geometry.gripper_open_rad).unwrap_or(0.0);
                                if let Some(g) = get(ACTUATED_JOINTS[3]).filter(|g| g.is_finite() && open_rad > 0.0) {
                                    last_gripper = Some((g / open_rad).clamp(0.0, 1.0));
                                }
                                let segs = model.as_ref().map(|m| segments(m, &js)).unwrap_or_default();
                                // every joint, passive linkage ones included, for the 3D view
                                // (the URDF's joints only: a joint_states of thousands of names
                                // must not become a message of megabytes to every browser)
                                let all: serde_json::Map<String, serde_json::Value> = js.name.iter().zip(js.position.iter())
                                    .filter(|(n, v)| v.is_finite() && model.as_ref().is_some_and(|m| m.joint_index(n).is_some()))
                                    .map(|(n, v)| (n.clone(), json!(v))).collect();
                                send_pose(json!({
                                    "t": "pose", "joints": joints_json(&q), "all": all,
                                    "gripper": get(ACTUATED_JOINTS[3]),
                                    "tool": tool.map(|p| [p.x, p.y, p.z]).ok(),
                                    "segments": segs,
                                }));
                            }
                        }
                    }
                    Input::RobotDescription(text) => match RobotModel::from_urdf_str(&text, topics::ROBOT_DESCRIPTION.name) {
                        Ok(m) => {
                            log::info!("robot_description: {} ({} links)", m.name, m.links.len());
                            // the joint mode's sliders come from the URDF, for any arm
                            if let Ok(robot) = teleop.lock().map(|mut t| {
                                t.set_robot(&m);
                                let scene = scene_json(&m, &t, &eezybot_envelope);
                                t.set_urdf(text.as_str().into());
                                t.set_scene(scene);
                                robot_json(&t)
                            }) {
                                send(json!({"t": "robot", "robot": robot}));
                            }
                            model = Some(m);
                        }
                        Err(e) => log::warn!("robot_description not usable for the live view: {e}"),
                    },
                    Input::Diagnostics(d) => {
                        health.update(&d);
                        if desk.playing() {
                            let value = |s: &DiagnosticStatus, k: &str| s.values.iter().find(|v| v.key == k).map(|v| v.value.clone());
                            for st in &d.status {
                                if let Some(stamp) = value(st, REJECTED_STAMP_KEY) {
                                    let reason = value(st, LAST_REJECTION_KEY).unwrap_or_else(|| st.message.clone());
                                    desk.refused(&stamp, &reason);
                                }
                            }
                            desk_step!();
                        }
                    }
                    Input::ServoState(s) => {
                        if let Some(v) = latency.reply(s.header.stamp) {
                            send(v);
                        }
                    }
                    Input::Estop(on) => {
                        send(json!({"t": "estop", "on": on}));
                        if on && desk.playing() {
                            desk_outcome!(desk::DeskOutcome { restore_mode: desk.stop(), changed: true, ..Default::default() });
                        }
                    }
                    Input::Unreadable { topic, error } => unreadable.note(topic, &error),
                }
                if joint_states && desk.playing() {
                    desk_step!(); // arrival is judged on where the tool is now
                }
            }
            Some(from) = requests.others.recv() => {
                match from.request {
                    ClientRequest::Program(op) => {
                        let out = match teleop.lock() {
                            Ok(t) => desk.request(op, &t, last_tool, last_gripper, Instant::now()),
                            Err(_) => desk::DeskOutcome::default(),
                        };
                        desk_outcome!(out);
                        desk_step!();
                    }
                    _ => serve_request(&teleop, from, &reporting.web),
                }
                // one request at a time, then let the other tasks run (on this node's
                // one thread: another client's handler with an e-stop in hand)
                tokio::task::yield_now().await;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_msgs::diagnostic_msgs::KeyValue;
    use eezybot_msgs::std_msgs::Header;

    /// (status name, level, key-value pairs)
    type Entry<'a> = (&'a str, u8, &'a [(&'a str, &'a str)]);

    fn array(statuses: &[Entry]) -> DiagnosticArray {
        DiagnosticArray {
            header: Header::default(),
            status: statuses
                .iter()
                .map(|(name, level, values)| DiagnosticStatus {
                    level: *level,
                    name: (*name).into(),
                    message: "m".into(),
                    hardware_id: "eezybot_arm".into(),
                    values: values
                        .iter()
                        .map(|(k, v)| KeyValue {
                            key: (*k).into(),
                            value: (*v).into(),
                        })
                        .collect(),
                })
                .collect(),
        }
    }

    fn names(h: &NodeHealth) -> Vec<(String, bool)> {
        h.json()["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| {
                (
                    n["name"].as_str().unwrap().to_string(),
                    n["up"].as_bool().unwrap(),
                )
            })
            .collect()
    }

    #[test]
    fn nodes_show_under_the_names_they_run_under() {
        let mut h = NodeHealth::new("gui_bridge");
        assert_eq!(
            names(&h),
            [
                ("compute_ik".into(), false),
                ("state_publisher".into(), false),
                ("serial_node".into(), false)
            ]
        );
        h.update(&array(&[
            ("ik2: inverse kinematics", 0, &[]),
            ("gui_bridge: operator panel", 0, &[]),
            ("serial_node: servo link", 1, &[]),
            ("camera: frames", 0, &[]),
        ]));
        assert_eq!(
            names(&h),
            [
                ("ik2".into(), true),
                ("state_publisher".into(), false),
                ("serial_node".into(), true),
                ("camera".into(), true)
            ]
        );
    }

    #[test]
    fn the_rejection_shown_is_the_one_carrying_the_refusal_key() {
        let mut h = NodeHealth::new("gui_bridge");
        h.update(&array(&[(
            "serial_node: servo link",
            1,
            &[("last_rejection", "servo")],
        )]));
        assert!(h.json()["last_rejection"].is_null());
        h.update(&array(&[(
            "ik2: inverse kinematics",
            1,
            &[
                ("last_rejection", "out of reach"),
                (REJECTED_STAMP_KEY, "1.000000002"),
            ],
        )]));
        assert_eq!(h.json()["last_rejection"], "out of reach");
    }

    #[test]
    fn a_flood_of_names_never_pushes_out_a_node_that_is_up() {
        let mut h = NodeHealth::new("gui_bridge");
        h.update(&array(&[("compute_ik: inverse kinematics", 0, &[])]));
        let many: Vec<String> = (0..2000).map(|i| format!("s{i}")).collect();
        let flood: Vec<Entry> = many.iter().map(|n| (n.as_str(), 0, &[][..])).collect();
        h.update(&array(&flood));
        h.update(&array(&[
            (":::", 0, &[]),
            ("", 0, &[]),
            ("\u{2603}: x", 0, &[]),
        ]));
        assert_eq!(h.seen.len(), MAX_TRACKED_NODES);
        assert!(h.seen.contains_key("compute_ik"));
    }
}
