//! The web panel's core: teleoperation, the program desk and the live view, as one
//! state owned by the bridge loop. Events go in with the time they happen at
//! ([`Clock`]); [`Effect`]s come out for the loop to apply (publish, answer a browser,
//! tell every browser, run a file job, log). No I/O here.

use crate::bounded::{RefusedInputs, MAX_JOINTS};
use crate::calibrate::{self as cal, Wizard};
use crate::desk::{Desk, DeskOutcome, FileDone, FileJob};
use crate::message::{
    ArmFacts, ArmJointsMsg, NodeEntry, Pose, RobotInfo, Sent, Snapshot, ToClient, UrdfScene,
};
use crate::recording::{RecordCard, RecordDone, RecordWork};
use crate::scene::CubeView;
use crate::teleop::{xyz_topic, Command, Event, Teleop};
use crate::web::{self, ClientRequest, WebStats};
use crate::{Input, NodeNames};
use eezybot_kinematics::envelope::Envelope;
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::{Arm, ArmJoints, ACTUATED_JOINTS};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use ros_plumbing::diagnostics::LatencyWindow;
use ros_plumbing::feedback::{self, Feedback};
use ros_plumbing::logging::{shorten, Throttle};
use ros_plumbing::topics;
use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// When an event happens: the monotonic clock (rate limits, timeouts) and the wall
/// clock (stamps).
#[derive(Clone, Copy, Debug)]
pub struct Clock {
    /// monotonic
    pub now: Instant,
    /// ROS time
    pub wall: Time,
}

impl Clock {
    /// The clocks now.
    pub fn read() -> Clock {
        Clock {
            now: Instant::now(),
            wall: Time::now(),
        }
    }
}

/// Something for the bridge loop to do.
#[derive(Debug)]
pub enum Effect {
    /// Publish this, stamped `stamp` (the stamp of a target).
    Publish {
        /// what, on which topic
        command: Command,
        /// its stamp
        stamp: Time,
    },
    /// Tell every browser.
    Broadcast(ToClient),
    /// Answer the browser whose request this is.
    Answer(ToClient),
    /// A request was refused: count it in the web side's diagnostics.
    Rejected {
        /// [`crate::teleop::Refusal::kind`]
        kind: &'static str,
        /// why
        reason: String,
    },
    /// Run this program file job in `dir` off the loop, then call [`Panel::on_file_done`].
    File {
        /// the job
        job: FileJob,
        /// the program directory
        dir: PathBuf,
    },
    /// What a browser that connects now gets changed.
    Snapshot(Snapshot),
    /// Log this.
    Log(log::Level, String),
    /// The calibration wizard's work on ROS: take the arm from compute_ik, publish
    /// `servo_angles`, save and apply (then call [`Panel::on_calibration_done`]).
    Calibration(CalibrationWork),
    /// A call on the recorder, off the loop (then call [`Panel::on_record_done`]).
    Record(RecordWork),
}

/// What the calibration wizard needs done on ROS ([`crate::calibrate::Effect`]s the
/// panel does not do itself).
#[derive(Clone, Debug, PartialEq)]
pub enum CalibrationWork {
    /// Take the arm from compute_ik, or give it back.
    SetCalibrating(bool),
    /// Publish `servo_angles` at these horn angles (deg).
    ServoAngles([f64; 4]),
    /// Write and apply this calibration.
    Save(Box<crate::SaveJob>),
}

/// The outcome of a [`CalibrationWork`] job.
#[derive(Clone, Debug, PartialEq)]
pub enum CalibrationDone {
    /// The arm was taken (true) or given back (false), or not.
    Calibrating(bool, Result<(), String>),
    /// The save.
    Saved(crate::calibrate::SaveOutcome),
}

/// Longest node name (and task, hardware id) the panel shows.
const NODE_NAME_MAX: usize = ros_plumbing::diagnostics::NODE_NAME_MAX;
/// Most nodes the panel tracks; a new one beyond them replaces one gone silent, if any.
pub const MAX_TRACKED_NODES: usize = 16;
/// A node heard within this is up.
const UP_WITHIN: Duration = Duration::from_secs(3);
/// A node not heard for this long is forgotten (an expected one shows as missing again).
const FORGET_AFTER: Duration = Duration::from_secs(60);
/// How long a refused client keeps the panel's diagnostics at WARN.
pub const REFUSAL_WARN_FOR: Duration = Duration::from_secs(60);
/// The most joints a URDF may have for the 3D view to get its workspace envelope.
pub const ENVELOPE_MAX_JOINTS: usize = 64;

/// The graph's other nodes the panel always shows, by default name, with what they do
/// (shown for a node not heard yet). The IK node and the serial_node go by the names
/// [`NodeNames`] gives (`ik_node`, the first of `servo_nodes`); until a node of that
/// name is heard it shows as missing.
pub const EXPECTED_NODES: [(&str, &str); 3] = [
    (NodeNames::IK, "inverse kinematics"),
    ("state_publisher", "robot state"),
    (NodeNames::SERVOS[0], "servo link"),
];

/// Samples that could not be read, for `diagnostics` and the (throttled) log.
#[derive(Debug, Default)]
struct UnreadableSamples {
    count: u64,
    last: Option<String>,
    complaints: Throttle,
}

impl UnreadableSamples {
    fn note(&mut self, topic: &str, error: &str, now: Instant) -> Option<Effect> {
        self.count += 1;
        let error = shorten(error, web::REASON_MAX);
        self.last = Some(format!("{topic}: {error}"));
        let quiet = self.complaints.allow(topic, now)?;
        Some(Effect::Log(
            log::Level::Warn,
            format!(
                "unreadable sample on {topic} ignored: {error}{}",
                Throttle::suffix(quiet)
            ),
        ))
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
    names: NodeNames,
    seen: BTreeMap<String, Heard>,
    last_rejection: Option<String>,
    /// who moves the arm (compute_ik's active controllers), and its last switch
    controllers: Option<String>,
    last_switch: Option<String>,
}

impl NodeHealth {
    fn new(own: &str) -> Self {
        NodeHealth {
            own: own.to_string(),
            names: NodeNames::default(),
            seen: BTreeMap::new(),
            last_rejection: None,
            controllers: None,
            last_switch: None,
        }
    }

    /// Those of `names` heard within [`UP_WITHIN`] of `now`.
    fn up<'a>(&self, names: impl Iterator<Item = &'a str>, now: Instant) -> Vec<String> {
        names
            .filter(|n| {
                self.seen
                    .get(*n)
                    .is_some_and(|h| now.duration_since(h.at) < UP_WITHIN)
            })
            .map(str::to_string)
            .collect()
    }

    /// The expected nodes' names, under [`NodeNames`].
    fn expected(&self) -> [(&str, &'static str); 3] {
        let [ik, state, servo] = EXPECTED_NODES;
        let first_servo = self.names.servos.first().map_or(servo.0, String::as_str);
        [
            (self.names.ik.as_str(), ik.1),
            state,
            (first_servo, servo.1),
        ]
    }

    fn update(&mut self, heard: &[Feedback], now: Instant) {
        self.seen
            .retain(|_, h| now.duration_since(h.at) < FORGET_AFTER);
        for s in heard {
            if let Some(refusal) = &s.refusal {
                self.last_rejection = Some(shorten(&refusal.reason, web::REASON_MAX).into_owned());
            }
            if let Some(c) = &s.controllers {
                self.controllers = Some(shorten(c, web::REASON_MAX).into_owned());
            }
            if let Some(w) = &s.last_switch {
                self.last_switch = Some(shorten(w, web::REASON_MAX).into_owned());
            }
            let Some(node) = s.node.as_deref() else {
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
                    task: shorten(&s.task, NODE_NAME_MAX).into_owned(),
                    hardware_id: shorten(&s.hardware_id, NODE_NAME_MAX).into_owned(),
                    level: s.health.level(),
                    message: shorten(&s.message, web::REASON_MAX).into_owned(),
                    at: now,
                },
            );
        }
    }

    /// The expected nodes first (as heard, or as missing), then every other node heard,
    /// by name.
    fn status(&self, now: Instant) -> ToClient {
        let entry = |name: &str, h: &Heard| {
            let age = now.saturating_duration_since(h.at);
            NodeEntry {
                name: name.to_string(),
                task: h.task.clone(),
                hardware_id: h.hardware_id.clone(),
                up: age < UP_WITHIN,
                level: h.level,
                message: h.message.clone(),
                age_s: Some(age.as_secs_f64()),
            }
        };
        let mut nodes = vec![];
        let mut listed: Vec<&str> = vec![];
        for (name, task) in self.expected() {
            if listed.contains(&name) {
                continue;
            }
            listed.push(name);
            nodes.push(match self.seen.get(name) {
                Some(h) => entry(name, h),
                None => NodeEntry {
                    name: name.into(),
                    task: task.into(),
                    hardware_id: String::new(),
                    up: false,
                    level: DiagnosticStatus::STALE,
                    message: "not seen".into(),
                    age_s: None,
                },
            });
        }
        for (n, h) in &self.seen {
            if !listed.contains(&n.as_str()) {
                nodes.push(entry(n, h));
            }
        }
        ToClient::Status {
            nodes,
            last_rejection: self.last_rejection.clone(),
            controllers: self.controllers.clone(),
            last_switch: self.last_switch.clone(),
        }
    }
}

/// Arrival time − stamp of `servo_state` replies to our own targets.
struct Latency {
    /// stamps of our last 200 targets, ns
    ours: VecDeque<i64>,
    /// the last 50 latencies, ms
    ms: LatencyWindow,
}

impl Latency {
    fn new() -> Latency {
        Latency {
            ours: VecDeque::new(),
            ms: LatencyWindow::new(50),
        }
    }

    fn sent(&mut self, stamp: Time) {
        if self.ours.len() == 200 {
            self.ours.pop_front();
        }
        self.ours.push_back(stamp.to_nanos());
    }

    fn reply(&mut self, stamp: Time, wall: Time) -> Option<ToClient> {
        let i = self.ours.iter().position(|s| *s == stamp.to_nanos())?;
        self.ours.remove(i);
        let ms = (wall.to_nanos() - stamp.to_nanos()) as f64 / 1e6;
        self.ms.push(ms);
        Some(ToClient::Latency {
            ms,
            median_ms: self.ms.percentile(0.5),
            n: self.ms.len(),
        })
    }
}

/// The panel: the operator state, the program desk, the live view and what the page
/// shows of the other nodes.
pub struct Panel {
    teleop: Teleop,
    desk: Desk,
    health: NodeHealth,
    latency: Latency,
    unreadable: UnreadableSamples,
    /// samples over the limits of bounded.rs, refused
    refused: RefusedInputs,
    /// `xyz_target` messages published
    sent: u64,
    /// the arm of `robot_description`, for the live view
    model: Option<RobotModel>,
    /// the EezyBot's workspace envelope (its configuration's only: computed once)
    eezybot_envelope: Option<Envelope>,
    /// where the tool and the claw are (teach, arrival)
    last_tool: Option<[f64; 3]>,
    last_gripper: Option<f64>,
    /// `robot_description`'s text and its revision
    urdf: Option<(Arc<str>, u64)>,
    /// what a browser that connects later gets
    pose: Option<Arc<ToClient>>,
    robot: Arc<RobotInfo>,
    program: Arc<ToClient>,
    arm_facts: Arc<ArmFacts>,
    /// the snapshot changed since the last [`Effect::Snapshot`]
    changed: bool,
    /// the calibration wizard (the EezyBot's only)
    wizard: Option<Wizard>,
    /// its latest view
    calibration: Option<Arc<ToClient>>,
    /// the leader arm's latest joints and deadman, and when they were last sent
    leader: LeaderView,
    /// the recording card
    recorder: RecordCard,
    /// its latest view
    recorder_view: Arc<ToClient>,
    /// the physics twin's cube, from `tf`
    cube: CubeView,
    /// its latest message
    cube_view: Arc<ToClient>,
    /// the camera view's topic (`camera_view`), if any
    camera_topic: Option<Arc<str>>,
}

/// A leader's deadman is shown only with joints heard this recently.
const LEADER_JOINTS_FRESH: Duration = Duration::from_millis(500);

/// The leader arm as the page shows it beside the follower.
#[derive(Debug, Default)]
struct LeaderView {
    joints: BTreeMap<String, f64>,
    deadman: Option<bool>,
    /// when the joints last came
    joints_at: Option<Instant>,
    sent_at: Option<Instant>,
    /// a change not sent yet (held back by the rate)
    pending: bool,
}

impl Panel {
    /// The panel of `arm`, targets at most `rate` a second each, programs on `desk`;
    /// `own` is this node's name (its own `diagnostics` are not shown as another node's).
    pub fn new(arm: Arm, rate: f64, desk: Desk, own: &str) -> Panel {
        let teleop = Teleop::new(arm, rate);
        Panel {
            robot: Arc::new(RobotInfo::eezybot(teleop.joint_sliders())),
            program: Arc::new(ToClient::Program(desk.view())),
            arm_facts: Arc::new(ArmFacts::of(teleop.arm())),
            teleop,
            desk,
            health: NodeHealth::new(own),
            latency: Latency::new(),
            unreadable: UnreadableSamples::default(),
            refused: RefusedInputs::default(),
            sent: 0,
            model: None,
            eezybot_envelope: None,
            last_tool: None,
            last_gripper: None,
            urdf: None,
            pose: None,
            changed: false,
            wizard: None,
            calibration: None,
            leader: LeaderView::default(),
            recorder: RecordCard::new(NodeNames::RECORDER),
            recorder_view: Arc::new(ToClient::Recorder(Box::new(
                RecordCard::new(NodeNames::RECORDER).view(Instant::now()),
            ))),
            cube: CubeView::new("base_link"),
            cube_view: Arc::new(ToClient::cube(None)),
            camera_topic: None,
        }
    }

    /// Show the twin's cube in `base_frame` (the 3D view's root; default `base_link`)
    /// and name the camera view's topic (None: no camera view).
    pub fn with_scene(mut self, base_frame: &str, camera_topic: Option<&str>) -> Panel {
        self.cube = CubeView::new(base_frame);
        self.camera_topic = camera_topic.map(Arc::from);
        self
    }

    /// The cube's message changed: to every browser and those that connect later.
    fn show_cube(&mut self, message: Option<ToClient>, effects: &mut Vec<Effect>) {
        if let Some(m) = message {
            let m = Arc::new(m);
            effects.push(Effect::Broadcast((*m).clone()));
            self.cube_view = m;
            self.changed = true;
        }
    }

    /// Enable the calibration wizard for an EezyBot with this configuration.
    pub fn enable_calibration(
        &mut self,
        config: eezybot_kinematics::ArmConfig,
    ) -> Result<(), String> {
        let wizard = Wizard::new(config).map_err(|e| e.to_string())?;
        self.calibration = Some(Arc::new(ToClient::Calibration(Box::new(wizard.view()))));
        self.wizard = Some(wizard);
        self.changed = true;
        Ok(())
    }

    /// Whether compute_ik was told to send nothing by the wizard (set it back when the
    /// node stops).
    pub fn calibrating(&self) -> bool {
        self.wizard.as_ref().is_some_and(|w| w.holds_compute_ik())
    }

    /// The nodes whose `arm_config` a saved calibration goes to: the IK node and the
    /// serial_nodes [`NodeNames`] names, those heard on `diagnostics` now.
    pub fn calibration_nodes(&self) -> Vec<String> {
        self.health
            .up(self.health.names.calibrated(), Instant::now())
    }

    /// Find the graph's nodes by these names (the default: the contract's).
    pub fn with_node_names(mut self, names: NodeNames) -> Panel {
        self.recorder = RecordCard::new(&names.recorder);
        self.health.names = names;
        self.recorder_view = Arc::new(ToClient::Recorder(Box::new(
            self.recorder.view(Instant::now()),
        )));
        self
    }

    /// The recording card's view changed: to every browser, and to those that connect
    /// later.
    fn show_recorder(&mut self, now: Instant, effects: &mut Vec<Effect>) {
        let view = Arc::new(ToClient::Recorder(Box::new(self.recorder.view(now))));
        effects.push(Effect::Broadcast((*view).clone()));
        self.recorder_view = view;
        self.changed = true;
    }

    /// A call on the recorder ended ([`Effect::Record`]).
    pub fn on_record_done(&mut self, done: RecordDone, clock: Clock) -> Vec<Effect> {
        let mut effects = vec![];
        let level = if done.result.is_ok() {
            log::Level::Info
        } else {
            log::Level::Warn
        };
        let text = match &done.result {
            Ok(t) => format!("record: {} done: {t}", done.op.name()),
            Err(e) => format!("record: {} failed: {e}", done.op.name()),
        };
        effects.push(Effect::Log(level, text));
        self.recorder.on_done(done);
        self.show_recorder(clock.now, &mut effects);
        self.finish(effects)
    }

    /// The last panel client left: a calibration it was running is cancelled, so the
    /// arm goes back to compute_ik (nobody is left to finish it; a calibration being
    /// saved finishes and gives the arm back itself).
    pub fn on_every_client_gone(&mut self, clock: Clock) -> Vec<Effect> {
        let mut effects = vec![];
        let running = self
            .wizard
            .as_ref()
            .is_some_and(|w| w.holds_compute_ik() && !w.saving());
        if running {
            log::warn!(
                "calibration cancelled: the last browser left; the arm goes back to compute_ik"
            );
            self.calibrate(Ok(cal::Op::Cancel), clock, &mut effects);
        }
        self.finish(effects)
    }

    /// A wizard request, or its ROS work done.
    fn calibrate(&mut self, op: Result<cal::Op, String>, clock: Clock, effects: &mut Vec<Effect>) {
        let Some(wizard) = self.wizard.as_mut() else {
            refuse(
                effects,
                "calibration",
                "calibration: only for the EezyBot (this arm has no servos to calibrate)".into(),
                None,
            );
            return;
        };
        let out = op.and_then(|op| wizard.request(op, clock.now));
        match out {
            Ok(fx) => self.calibration_effects(fx, clock, effects),
            Err(reason) => {
                let fx = wizard.refused(&reason);
                refuse(effects, "calibration", reason, None);
                self.calibration_effects(fx, clock, effects);
            }
        }
    }

    fn calibration_effects(
        &mut self,
        fx: Vec<cal::Effect>,
        clock: Clock,
        effects: &mut Vec<Effect>,
    ) {
        for e in fx {
            match e {
                cal::Effect::SetCalibrating(on) => {
                    effects.push(Effect::Calibration(CalibrationWork::SetCalibrating(on)))
                }
                cal::Effect::ServoAngles(deg) => {
                    effects.push(Effect::Calibration(CalibrationWork::ServoAngles(deg)))
                }
                cal::Effect::Save(mut job) => {
                    job.nodes = self.calibration_nodes();
                    effects.push(Effect::Calibration(CalibrationWork::Save(job)))
                }
                cal::Effect::JointTarget(q) => effects.push(Effect::Publish {
                    command: Command::Joints(q),
                    stamp: clock.wall,
                }),
                cal::Effect::View => {
                    if let Some(w) = &self.wizard {
                        let view = Arc::new(ToClient::Calibration(Box::new(w.view())));
                        effects.push(Effect::Broadcast((*view).clone()));
                        self.calibration = Some(view);
                        self.changed = true;
                    }
                }
                cal::Effect::Log(level, text) => effects.push(Effect::Log(level, text)),
            }
        }
    }

    /// A [`CalibrationWork`] job is done.
    pub fn on_calibration_done(&mut self, done: CalibrationDone, clock: Clock) -> Vec<Effect> {
        let mut effects = vec![];
        if let Some(w) = self.wizard.as_mut() {
            let fx = match done {
                CalibrationDone::Calibrating(on, result) => {
                    w.on_calibrating_set(on, result, clock.now)
                }
                CalibrationDone::Saved(outcome) => w.on_saved(outcome, clock.now),
            };
            self.calibration_effects(fx, clock, &mut effects);
        }
        self.finish(effects)
    }

    /// What a browser that connects now gets.
    pub fn snapshot(&self) -> Snapshot {
        Snapshot {
            target: self.teleop.target(),
            pose: self.pose.clone(),
            robot: self.robot.clone(),
            program: self.program.clone(),
            arm: self.arm_facts.clone(),
            urdf: self.urdf.as_ref().map(|(text, _)| text.clone()),
            calibration: self.calibration.clone(),
            recorder: Some(self.recorder_view.clone()),
            cube: self.cube_view.clone(),
            camera: self.camera_topic.clone(),
            inputs_refused: self.refused.view(),
        }
    }

    /// The program directory.
    pub fn program_dir(&self) -> &std::path::Path {
        self.desk.dir()
    }

    /// Change the publish rate limit (the `rate` parameter).
    pub fn set_rate(&mut self, rate: f64) {
        self.teleop.set_rate(rate);
    }

    /// When [`Panel::on_tick`] is due next: a target to publish or the player to run.
    pub fn next_wakeup(&self, now: Instant) -> Option<Instant> {
        [self.teleop.next_due(now), self.desk.next_wakeup()]
            .into_iter()
            .flatten()
            .min()
    }

    /// Whether a target is due for publishing now (the loop does this before anything else).
    pub fn publish_due(&self, now: Instant) -> bool {
        self.teleop.next_due(now).is_some_and(|d| d <= now)
    }

    /// Time passed: publish what is due (latest wins; the e-stop first), run the player
    /// when it is due.
    pub fn on_tick(&mut self, clock: Clock) -> Vec<Effect> {
        let mut effects = vec![];
        for command in self.teleop.take_due(clock.now) {
            let stamp = clock.wall;
            let sent = match &command {
                Command::Target { xyz, line } => {
                    self.sent += 1;
                    self.latency.sent(stamp);
                    self.desk.published_target(stamp);
                    Sent::Xyz {
                        topic: xyz_topic(*line).name,
                        xyz: *xyz,
                        stamp_ns: stamp.to_nanos(),
                    }
                }
                Command::Gripper(g) => Sent::Gripper {
                    topic: topics::GRIPPER_TARGET.name,
                    value: *g,
                },
                Command::Joints(q) => {
                    self.latency.sent(stamp);
                    Sent::Joints {
                        topic: topics::JOINT_TARGET.name,
                        q: q.clone(),
                        stamp_ns: stamp.to_nanos(),
                    }
                }
                Command::Estop(on) => Sent::Estop {
                    topic: topics::ESTOP.name,
                    on: *on,
                },
            };
            effects.push(Effect::Publish { command, stamp });
            effects.push(Effect::Broadcast(ToClient::Sent(sent)));
        }
        if self.desk.next_wakeup().is_some_and(|w| w <= clock.now) {
            self.desk_step(clock.now, &mut effects);
        }
        if self.leader.pending {
            self.send_leader(clock.now, &mut effects);
        }
        if self.cube.pending() {
            let m = self.cube.on_tick(clock.now);
            self.show_cube(m, &mut effects);
        }
        self.finish(effects)
    }

    /// Every half second: the other nodes' health to every browser; the wizard's
    /// timeouts.
    pub fn on_status_tick(&mut self, clock: Clock) -> Vec<Effect> {
        let mut effects = vec![Effect::Broadcast(self.health.status(clock.now))];
        if self.recorder.up_changed(clock.now) {
            self.show_recorder(clock.now, &mut effects);
        }
        if let Some(w) = self.wizard.as_mut() {
            let fx = w.on_tick(clock.now);
            self.calibration_effects(fx, clock, &mut effects);
        }
        if self.leader.pending {
            self.send_leader(clock.now, &mut effects);
        }
        // a held-back move of the cube, or the cube gone silent
        let m = self.cube.on_tick(clock.now);
        self.show_cube(m, &mut effects);
        self.finish(effects)
    }

    /// A browser's request; its answer is an [`Effect::Answer`].
    pub fn on_request(&mut self, request: ClientRequest, clock: Clock) -> Vec<Effect> {
        let mut effects = vec![];
        let event = match request {
            ClientRequest::Check { xyz } => {
                return vec![Effect::Answer(self.check(xyz))];
            }
            // taken by the web side (a waiting client's first message)
            ClientRequest::Hello => return vec![],
            ClientRequest::Program(op) => {
                let out = self.desk.request(
                    op,
                    &self.teleop,
                    self.last_tool,
                    self.last_gripper,
                    clock.now,
                );
                self.desk_outcome(out, &mut effects);
                self.desk_step(clock.now, &mut effects);
                return self.finish(effects);
            }
            ClientRequest::Calibrate(op) => {
                self.calibrate(op.into_op(), clock, &mut effects);
                return self.finish(effects);
            }
            ClientRequest::Record(r) => {
                // no motion: taken while calibrating too
                let (op, task) = r.op();
                match self.recorder.request(op, task, clock.now) {
                    Ok(work) => {
                        effects.push(Effect::Log(
                            log::Level::Info,
                            format!("record: {} asked of {}", op.name(), self.recorder.node()),
                        ));
                        effects.push(Effect::Record(work));
                        self.show_recorder(clock.now, &mut effects);
                    }
                    Err(reason) => refuse(&mut effects, "record", reason, None),
                }
                return self.finish(effects);
            }
            ClientRequest::Estop { on } => Event::Estop { engaged: on },
            _ if self.calibrating() => {
                refuse(
                    &mut effects,
                    "calibrating",
                    "calibrating: the wizard drives the servos (finish or cancel it first)".into(),
                    Some(false),
                );
                return self.finish(effects);
            }
            ClientRequest::Target { xyz } => Event::SetTarget { xyz, line: false },
            ClientRequest::Jog { d } => Event::Jog { dxyz: d },
            ClientRequest::Gripper { v } => Event::Gripper { opening: v },
            ClientRequest::Joints { q } => Event::Joints {
                positions: q.into_iter().collect(),
            },
        };
        let engaged = matches!(event, Event::Estop { engaged: true });
        let eezybot = self.teleop.is_eezybot();
        match self.teleop.handle_event(event) {
            Ok(f) => {
                self.changed = true;
                effects.push(Effect::Answer(ToClient::Ack {
                    target: f.target,
                    joints: eezybot.then(|| ArmJointsMsg::from(&f.joints)),
                    reachable: true,
                }));
            }
            Err(refusal) => {
                let reason = refusal.to_string();
                let answer = ToClient::Refused {
                    reason: shorten(&reason, web::REASON_MAX).into_owned(),
                    reachable: Some(false),
                };
                effects.push(Effect::Rejected {
                    kind: refusal.kind(),
                    reason,
                });
                effects.push(Effect::Answer(answer));
            }
        }
        if engaged {
            self.stop_playing(&mut effects);
        }
        self.finish(effects)
    }

    /// The answer to a `check`: the EezyBot's closed form, as compute_ik checks.
    fn check(&self, xyz: [f64; 3]) -> ToClient {
        let (reachable, joints, reason) = if !self.teleop.is_eezybot() {
            let why =
                "not checked here: this arm has no closed form, compute_ik decides when it is sent";
            (None, None, Some(why.into()))
        } else {
            match self.teleop.check(xyz) {
                Ok(q) => (Some(true), Some(ArmJointsMsg::from(&q)), None),
                Err(e) => (Some(false), None, Some(e.to_string())),
            }
        };
        ToClient::Check {
            xyz,
            reachable,
            joints,
            reason,
        }
    }

    /// A ROS input.
    pub fn on_input(&mut self, input: Input, clock: Clock) -> Vec<Effect> {
        let mut effects = vec![];
        match input {
            Input::JointStates(js) => {
                self.input_taken(topics::JOINT_STATES.name, &mut effects);
                if let Some(w) = self.wizard.as_mut() {
                    let joints = js
                        .name
                        .iter()
                        .cloned()
                        .zip(js.position.iter().copied())
                        .collect();
                    let fx = w.on_joint_states(&joints);
                    self.calibration_effects(fx, clock, &mut effects);
                }
                if let Some(pose) = self.pose_of(&js) {
                    let pose = Arc::new(ToClient::Pose(pose));
                    effects.push(Effect::Broadcast((*pose).clone()));
                    self.pose = Some(pose);
                    self.changed = true;
                }
                // arrival is judged on where the tool is now
                self.desk_step(clock.now, &mut effects);
            }
            Input::RobotDescription(text) => {
                self.input_taken(topics::ROBOT_DESCRIPTION.name, &mut effects);
                self.robot_description(text, clock.now, &mut effects);
            }
            Input::Diagnostics(d) => {
                let recorder = d
                    .status
                    .iter()
                    .filter(|s| self.recorder.on_status(s, clock.now))
                    .count();
                if recorder > 0 {
                    self.show_recorder(clock.now, &mut effects);
                }
                let heard = feedback::decode(&d);
                self.health.update(&heard, clock.now);
                if let (Some(w), Some(counts)) = (self.wizard.as_mut(), leader_counts(&d)) {
                    let fx = w.on_leader_counts(counts, clock.now);
                    self.calibration_effects(fx, clock, &mut effects);
                }
                if self.desk.playing() {
                    for refusal in heard.iter().filter_map(|f| f.refusal.as_ref()) {
                        self.desk.refused(refusal);
                    }
                    self.desk_step(clock.now, &mut effects);
                }
            }
            Input::ServoState(s) => {
                if let (Some(w), Some(deg)) = (self.wizard.as_mut(), servo_degrees(&s)) {
                    let fx = w.on_servo_state(deg, clock.now);
                    self.calibration_effects(fx, clock, &mut effects);
                }
                if let Some(latency) = self.latency.reply(s.header.stamp, clock.wall) {
                    effects.push(Effect::Broadcast(latency));
                }
            }
            Input::Estop(on) => {
                if let Some(w) = self.wizard.as_mut() {
                    let fx = w.on_estop(on, clock.now);
                    self.calibration_effects(fx, clock, &mut effects);
                }
                effects.push(Effect::Broadcast(ToClient::Estop { on }));
                if on {
                    self.stop_playing(&mut effects);
                }
            }
            Input::Tf(tf) => {
                let (m, log) = self.cube.on_tf(tf, clock.now);
                effects.extend(log.map(|(level, text)| Effect::Log(level, text)));
                self.show_cube(m, &mut effects);
            }
            // the bridge loop passes the images on itself (they are not the panel's state)
            Input::CameraImage(_) => {}
            Input::Unreadable { topic, error } => {
                effects.extend(self.unreadable.note(topic, &error, clock.now));
            }
            Input::Refused { topic, reason } => {
                self.refuse_input(topic, &reason, clock.now, &mut effects);
            }
            Input::LeaderJoints(js) => {
                self.input_taken(topics::LEADER_JOINT_STATES.name, &mut effects);
                self.leader.joints = js
                    .name
                    .iter()
                    .cloned()
                    .zip(js.position.iter().copied())
                    .collect();
                self.leader.joints_at = Some(clock.now);
                self.leader.pending = true;
                self.send_leader(clock.now, &mut effects);
            }
            Input::LeaderDeadman(held) => {
                // shown with the leader's joints: without recent ones (none heard, or the
                // joints stopped) there is no leader to show
                let recent = self
                    .leader
                    .joints_at
                    .is_some_and(|t| clock.now.duration_since(t) < LEADER_JOINTS_FRESH);
                if self.leader.deadman != Some(held) {
                    self.leader.deadman = Some(held);
                    if recent {
                        self.leader.pending = true;
                        self.send_leader(clock.now, &mut effects);
                    }
                }
            }
        }
        self.finish(effects)
    }

    /// A program file job of an [`Effect::File`] is done (or timed out).
    pub fn on_file_done(&mut self, done: FileDone) -> Vec<Effect> {
        let mut effects = vec![];
        let out = self.desk.file_done(done);
        self.desk_outcome(out, &mut effects);
        self.finish(effects)
    }

    /// The panel's own `diagnostics` status (the loop adds the watched topics' peers).
    pub fn report(&self, name: &str, url: &str, web: &WebStats, now: Instant) -> DiagnosticStatus {
        let mut values = vec![
            ("url", url.to_string()),
            ("targets_sent", self.sent.to_string()),
        ];
        values.extend(web.values());
        values.extend(self.unreadable.values());
        values.extend(self.refused.values());
        values.extend(self.cube.values());
        let last = web.last_refusal().cloned();
        let recent = last
            .clone()
            .filter(|(at, _)| now.saturating_duration_since(*at) < REFUSAL_WARN_FOR);
        if let Some((_, last)) = last {
            values.push(("last_refusal", last));
        }
        let refused_input = self
            .refused
            .last()
            .filter(|(at, _)| now.saturating_duration_since(*at) < REFUSAL_WARN_FOR);
        let (level, message) = match (recent, refused_input) {
            (Some((at, last)), _) => (
                DiagnosticStatus::WARN,
                format!(
                    "web panel on {url}; refused a client {:.0} s ago ({} refusals in all): {last}",
                    now.saturating_duration_since(at).as_secs_f64(),
                    web.refused_total()
                ),
            ),
            (None, Some((at, last))) => (
                DiagnosticStatus::WARN,
                format!(
                    "web panel on {url}; refused an input {:.0} s ago: {last}",
                    now.saturating_duration_since(*at).as_secs_f64(),
                ),
            ),
            (None, None) => (DiagnosticStatus::OK, format!("web panel on {url}")),
        };
        ros_plumbing::diagnostics::status(level, name, "", &message, &values)
    }

    /// Append the snapshot if it changed.
    /// The leader's joints to every browser, at most [`crate::LEADER_VIEW_RATE_HZ`] a
    /// second (a held-back change goes with the next tick).
    fn send_leader(&mut self, now: Instant, effects: &mut Vec<Effect>) {
        let period = Duration::from_secs_f64(1.0 / crate::LEADER_VIEW_RATE_HZ);
        if self
            .leader
            .sent_at
            .is_some_and(|t| now.duration_since(t) < period)
        {
            return;
        }
        self.leader.sent_at = Some(now);
        self.leader.pending = false;
        effects.push(Effect::Broadcast(ToClient::Leader {
            joints: self.leader.joints.clone(),
            deadman: self.leader.deadman,
        }));
    }

    fn finish(&mut self, mut effects: Vec<Effect>) -> Vec<Effect> {
        if std::mem::take(&mut self.changed) {
            effects.push(Effect::Snapshot(self.snapshot()));
        }
        effects
    }

    fn stop_playing(&mut self, effects: &mut Vec<Effect>) {
        if self.desk.playing() {
            self.desk.stop();
            let out = DeskOutcome {
                changed: true,
                ..Default::default()
            };
            self.desk_outcome(out, effects);
        }
    }

    fn desk_step(&mut self, now: Instant, effects: &mut Vec<Effect>) {
        let out = self.desk.play_step(&mut self.teleop, now, self.last_tool);
        self.desk_outcome(out, effects);
    }

    fn desk_outcome(&mut self, out: DeskOutcome, effects: &mut Vec<Effect>) {
        if let Some(job) = out.file {
            effects.push(Effect::File {
                job,
                dir: self.desk.dir().to_path_buf(),
            });
        }
        if out.changed {
            let view = Arc::new(ToClient::Program(self.desk.view()));
            effects.push(Effect::Broadcast((*view).clone()));
            self.program = view;
            self.changed = true;
        }
    }

    /// A sample of `topic` refused ([`Input::Refused`]): counted, logged (throttled), and
    /// shown on the page while it holds.
    fn refuse_input(
        &mut self,
        topic: &'static str,
        reason: &str,
        now: Instant,
        effects: &mut Vec<Effect>,
    ) {
        let (changed, line) = self.refused.refused(topic, reason, now);
        effects.extend(line.map(|(level, text)| Effect::Log(level, text)));
        if changed {
            self.show_refused(effects);
        }
    }

    /// A sample of `topic` was taken: a refusal of it shown on the page is over.
    fn input_taken(&mut self, topic: &str, effects: &mut Vec<Effect>) {
        if self.refused.taken(topic) {
            self.show_refused(effects);
        }
    }

    fn show_refused(&mut self, effects: &mut Vec<Effect>) {
        effects.push(Effect::Broadcast(ToClient::InputsRefused {
            inputs: self.refused.view(),
        }));
        self.changed = true;
    }

    fn robot_description(&mut self, text: String, now: Instant, effects: &mut Vec<Effect>) {
        let m = match RobotModel::from_urdf_str(&text, topics::ROBOT_DESCRIPTION.name) {
            Ok(m) if m.joints.len() > MAX_JOINTS => {
                // (bounded.rs counts `<joint` elements before parsing; this is the model's)
                let reason = format!("{} joints > {MAX_JOINTS}", m.joints.len());
                self.refuse_input(topics::ROBOT_DESCRIPTION.name, &reason, now, effects);
                return;
            }
            Ok(m) => m,
            Err(e) => {
                effects.push(Effect::Log(
                    log::Level::Warn,
                    format!("robot_description not usable for the live view: {e}"),
                ));
                return;
            }
        };
        effects.push(Effect::Log(
            log::Level::Info,
            format!("robot_description: {} ({} links)", m.name, m.links.len()),
        ));
        // the joint mode's sliders come from the URDF, for any arm
        let view = self.teleop.set_robot(&m).clone();
        let envelope = self.envelope(&m);
        let rev = self.urdf.as_ref().map_or(1, |(_, r)| r + 1);
        self.urdf = Some((text.into(), rev));
        let robot = RobotInfo {
            view,
            from_urdf: true,
            scene: Some(UrdfScene {
                urdf: Some(format!("robot.urdf?rev={rev}")),
                envelope,
            }),
        };
        effects.push(Effect::Broadcast(ToClient::Robot {
            robot: robot.clone(),
        }));
        self.robot = Arc::new(robot);
        self.model = Some(m);
        self.changed = true;
    }

    /// The 3D view's workspace: for the EezyBot the solid of revolution of its closed
    /// form's limits (computed once), for any other arm a cloud of its tool's positions
    /// at random configurations, only for a chain of at most [`ENVELOPE_MAX_JOINTS`]
    /// joints (a description of thousands of links would hold the loop for seconds).
    fn envelope(&mut self, model: &RobotModel) -> Option<Envelope> {
        use eezybot_kinematics::envelope::{chain_envelope, eezybot_envelope};
        match self.teleop.robot() {
            Some(r) if !r.eezybot => r
                .tool_link
                .as_ref()
                .filter(|_| model.joints.len() <= ENVELOPE_MAX_JOINTS)
                .and_then(|tip| {
                    eezybot_kinematics::chain::SerialChain::from_model(model, &model.root, tip)
                        .ok()
                        .map(|chain| chain_envelope(&chain, 2000, 1))
                }),
            _ => {
                let arm = self.teleop.arm();
                Some(
                    self.eezybot_envelope
                        .get_or_insert_with(|| eezybot_envelope(arm, 0.004))
                        .clone(),
                )
            }
        }
    }

    /// The live view of `js`; remembers where the tool and the claw are.
    fn pose_of(&mut self, js: &JointState) -> Option<Pose> {
        if !self.teleop.is_eezybot() {
            // any other arm: every joint, the links' segments and its tool
            let m = self.model.as_ref()?;
            let finite: Vec<(&str, f64)> = js
                .name
                .iter()
                .map(String::as_str)
                .zip(js.position.iter().copied())
                .filter(|(_, v)| v.is_finite())
                .collect();
            let tool_link = self.teleop.robot().and_then(|r| r.tool_link.clone());
            let tool = tool_link
                .and_then(|l| m.link_poses(&finite).get(&l).map(|p| p.translation.vector))
                .map(|p| [p.x, p.y, p.z]);
            self.last_tool = tool;
            let joints = finite
                .iter()
                .filter(|(n, _)| m.joint_index(n).is_some())
                .map(|(n, v)| (n.to_string(), *v))
                .collect();
            return Some(Pose {
                joints,
                all: None,
                gripper: None,
                tool,
                segments: segments(m, js),
            });
        }
        let get = |n: &str| {
            js.name
                .iter()
                .position(|x| x == n)
                .and_then(|i| js.position.get(i).copied())
        };
        let (b, s, e) = (
            get(ACTUATED_JOINTS[0])?,
            get(ACTUATED_JOINTS[1])?,
            get(ACTUATED_JOINTS[2])?,
        );
        if !(b.is_finite() && s.is_finite() && e.is_finite()) {
            return None;
        }
        let q = ArmJoints {
            base_rad: b,
            shoulder_rad: s,
            elbow_rad: e,
        };
        self.teleop.observe_joints(q);
        let tool = self.teleop.arm().forward(&q);
        self.last_tool = Some([tool.x, tool.y, tool.z]);
        let open_rad = self.teleop.arm().geometry.gripper_open_rad;
        if let Some(g) = get(ACTUATED_JOINTS[3]).filter(|g| g.is_finite() && open_rad > 0.0) {
            self.last_gripper = Some((g / open_rad).clamp(0.0, 1.0));
        }
        let model = self.model.as_ref();
        // every joint, passive linkage ones included, for the 3D view (the URDF's joints
        // only: a joint_states of thousands of names must not become a message of
        // megabytes to every browser)
        let all = js
            .name
            .iter()
            .zip(js.position.iter())
            .filter(|(n, v)| v.is_finite() && model.is_some_and(|m| m.joint_index(n).is_some()))
            .map(|(n, v)| (n.clone(), *v))
            .collect();
        let msg = ArmJointsMsg::from(&q);
        Some(Pose {
            joints: BTreeMap::from([
                ("base_joint".to_string(), msg.base_joint),
                ("shoulder_joint".to_string(), msg.shoulder_joint),
                ("elbow_joint".to_string(), msg.elbow_joint),
            ]),
            all: Some(all),
            gripper: get(ACTUATED_JOINTS[3]),
            tool: Some([tool.x, tool.y, tool.z]),
            segments: model.map(|m| segments(m, js)).unwrap_or_default(),
        })
    }
}

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

/// Refuse a request: count it (`kind`, the reason in full) and answer the browser (the
/// reason cut to [`web::REASON_MAX`]).
fn refuse(effects: &mut Vec<Effect>, kind: &'static str, reason: String, reachable: Option<bool>) {
    effects.push(Effect::Answer(ToClient::Refused {
        reason: shorten(&reason, web::REASON_MAX).into_owned(),
        reachable,
    }));
    effects.push(Effect::Rejected { kind, reason });
}

/// `servo_state`'s four horn angles in degrees (`servo_angles` order), if it names them
/// all with finite values.
pub(crate) fn servo_degrees(msg: &JointState) -> Option<[f64; 4]> {
    let mut deg = [0.0; 4];
    for (i, id) in eezybot_kinematics::ServoId::ALL.iter().enumerate() {
        let k = msg.name.iter().position(|n| n == id.name())?;
        deg[i] = msg.position.get(k).filter(|v| v.is_finite())?.to_degrees();
    }
    Some(deg)
}

/// A leader serial_node's live ADC counts (`leader_counts`, "A0 A1 A2 A3"), from any
/// status of a `diagnostics` array.
pub(crate) fn leader_counts(
    d: &eezybot_msgs::diagnostic_msgs::DiagnosticArray,
) -> Option<[f64; 4]> {
    let text = d
        .status
        .iter()
        .flat_map(|s| &s.values)
        .find(|kv| kv.key == "leader_counts")?;
    let v: Vec<f64> = text
        .value
        .split_whitespace()
        .map(|x| x.parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()?;
    let counts: [f64; 4] = v.try_into().ok()?;
    counts.iter().all(|c| c.is_finite()).then_some(counts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, KeyValue};
    use eezybot_msgs::std_msgs::Header;
    use ros_plumbing::diagnostics::REJECTED_STAMP_KEY;

    /// (status name, level, key-value pairs)
    type Entry<'a> = (&'a str, u8, &'a [(&'a str, &'a str)]);

    /// A `diagnostics` report of these statuses, read.
    fn array(statuses: &[Entry]) -> Vec<Feedback> {
        feedback::decode(&DiagnosticArray {
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
        })
    }

    fn json(h: &NodeHealth) -> serde_json::Value {
        serde_json::from_str(&h.status(Instant::now()).to_text()).unwrap()
    }

    fn names(h: &NodeHealth) -> Vec<(String, bool)> {
        json(h)["nodes"]
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
    fn nodes_are_found_by_name_not_by_what_their_status_says() {
        // a node calling itself "inverse kinematics" is not compute_ik, nor a
        // calibration target: only the names NodeNames gives are
        let mut h = NodeHealth::new("gui_bridge");
        h.update(
            &array(&[
                ("impostor: inverse kinematics", 0, &[]),
                ("serial_node: servo link", 0, &[]),
                ("leader_arm: servo link", 0, &[]),
            ]),
            Instant::now(),
        );
        assert_eq!(
            names(&h),
            [
                ("compute_ik".into(), false),
                ("state_publisher".into(), false),
                ("serial_node".into(), true),
                ("impostor".into(), true),
                ("leader_arm".into(), true)
            ]
        );
        assert_eq!(
            h.up(h.names.calibrated(), Instant::now()),
            ["serial_node", "leader_arm"]
        );
        // renamed with -r __node:=ik2, named by ik_node and servo_nodes
        h.names = NodeNames {
            ik: "ik2".into(),
            servos: vec!["arm_link".into()],
            ..NodeNames::default()
        };
        h.update(
            &array(&[
                ("ik2: inverse kinematics", 0, &[]),
                ("arm_link: servo link", 0, &[]),
            ]),
            Instant::now(),
        );
        assert_eq!(
            names(&h)[..3],
            [
                ("ik2".into(), true),
                ("state_publisher".into(), false),
                ("arm_link".into(), true)
            ]
        );
        assert_eq!(
            h.up(h.names.calibrated(), Instant::now()),
            ["ik2", "arm_link"]
        );
    }

    #[test]
    fn nodes_show_under_the_names_they_run_under() {
        let mut h = NodeHealth::new("gui_bridge");
        h.names.ik = "ik2".into();
        assert_eq!(
            names(&h),
            [
                ("ik2".into(), false),
                ("state_publisher".into(), false),
                ("serial_node".into(), false)
            ]
        );
        h.update(
            &array(&[
                ("ik2: inverse kinematics", 0, &[]),
                ("gui_bridge: operator panel", 0, &[]),
                ("serial_node: servo link", 1, &[]),
                ("camera: frames", 0, &[]),
            ]),
            Instant::now(),
        );
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
        h.update(
            &array(&[("serial_node: servo link", 1, &[("last_rejection", "servo")])]),
            Instant::now(),
        );
        assert!(json(&h)["last_rejection"].is_null());
        h.update(
            &array(&[(
                "ik2: inverse kinematics",
                1,
                &[
                    ("last_rejection", "out of reach"),
                    (REJECTED_STAMP_KEY, "1.000000002"),
                ],
            )]),
            Instant::now(),
        );
        assert_eq!(json(&h)["last_rejection"], "out of reach");
    }

    #[test]
    fn a_flood_of_names_never_pushes_out_a_node_that_is_up() {
        let mut h = NodeHealth::new("gui_bridge");
        h.update(
            &array(&[("compute_ik: inverse kinematics", 0, &[])]),
            Instant::now(),
        );
        let many: Vec<String> = (0..2000).map(|i| format!("s{i}")).collect();
        let flood: Vec<Entry> = many.iter().map(|n| (n.as_str(), 0, &[][..])).collect();
        h.update(&array(&flood), Instant::now());
        h.update(
            &array(&[(":::", 0, &[]), ("", 0, &[]), ("\u{2603}: x", 0, &[])]),
            Instant::now(),
        );
        assert_eq!(h.seen.len(), MAX_TRACKED_NODES);
        assert!(h.seen.contains_key("compute_ik"));
    }
}
