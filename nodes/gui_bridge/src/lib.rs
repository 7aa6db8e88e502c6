#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod access;
pub mod bounded;
pub mod calibrate;
pub mod calibrate_cli;
pub mod calibration_ros;
pub mod cli;
pub mod delivery;
pub mod desk;
pub mod foxglove;
pub mod linger;
pub mod message;
pub mod panel;
pub mod program;
pub mod record;
pub mod recorder_ros;
pub mod recording;
pub mod ros_outputs;
pub mod scene;
pub mod serve;
pub mod teleop;
pub mod tls;
pub mod web;

use crate::desk::FileDone;
use crate::message::Snapshot;
use crate::panel::{Clock, Effect, Panel};
use crate::teleop::Command;
use crate::web::{LogLine, Requests, WebEvent, WebStats};
use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use futures::future::{BoxFuture, LocalBoxFuture};
use futures::{Stream, StreamExt};
use ros_plumbing::peers::{Peer, PeerWatch};
use ros_plumbing::{ParamRange, ParamSpec, ParameterValue, Params};
use std::future::Future;
use std::ops::ControlFlow;
use std::time::{Duration, Instant};
use tokio::sync::{broadcast, mpsc, watch};

pub use crate::panel::{EXPECTED_NODES, MAX_TRACKED_NODES, REFUSAL_WARN_FOR};

/// The default `camera_view`: the physics twin's camera (docs/twin.md).
pub const CAMERA_VIEW: &str = "twin/camera/image_raw/compressed";

/// The default `foxglove_origins`: Foxglove's web app.
pub const FOXGLOVE_ORIGINS: &str = "https://app.foxglove.dev";

/// The node's description and parameters.
pub fn spec() -> ros_plumbing::NodeSpec {
    ros_plumbing::NodeSpec {
        name: "gui_bridge",
        description: "operator input (web page, keyboard, gamepad, command line) -> xyz_target / xyz_line_target / gripper_target / joint_target / estop",
        usage: "[serve | once X Y Z [--gripper G] [--line] [--timeout S] | play WAYPOINTS.csv|RUN.mcap [--line] [--timeout S] | record OUT.csv|OUT.mcap | calibrate [--leader]]",
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
            ParamSpec::new(
                "calibration_file",
                ParameterValue::String(String::new()),
                "where the calibration wizard saves (atomically, the previous file kept as FILE.bak), then sets arm_config to it on the nodes ik_node and servo_nodes name, those running; empty = arm_config if set, else $XDG_CONFIG_HOME/eezybot/arm.yaml (~/.config/eezybot/arm.yaml), made from the shipped config",
            )
            .read_only(),
            ParamSpec::new(
                "ik_node",
                ParameterValue::String(NodeNames::IK.into()),
                "the node running the inverse kinematics, by name (as `-r __node:=` named it): the panel lists it first, and a saved calibration sets its arm_config",
            )
            .read_only()
            .validator(|v| match v {
                ParameterValue::String(n) => check_node_names(std::slice::from_ref(n)),
                _ => Ok(()),
            }),
            ParamSpec::new(
                "servo_nodes",
                ParameterValue::StringArray(NodeNames::SERVOS.iter().map(|s| s.to_string()).collect()),
                "the serial_nodes, follower and leader, by name: the panel lists the first, and a saved calibration sets arm_config on each one running",
            )
            .read_only()
            .validator(|v| match v {
                ParameterValue::StringArray(n) => check_node_names(n),
                _ => Ok(()),
            }),
            ParamSpec::new(
                "recorder_node",
                ParameterValue::String(NodeNames::RECORDER.into()),
                "the recorder node, by name (as `-r __node:=` named it): the panel's recording card shows its diagnostics, sets its task parameter and calls its episode services (recorder/start_episode, save_episode, discard_episode, in its namespace)",
            )
            .read_only()
            .validator(|v| match v {
                ParameterValue::String(n) => check_node_names(std::slice::from_ref(n)),
                _ => Ok(()),
            }),
            ParamSpec::new("base_frame", ParameterValue::String("base_link".into()), "frame_id of the targets sent; the 3D view shows the twin's cube (tf frame `cube`) only as a child of this frame (as set at start)"),
            ParamSpec::new(
                "camera_view",
                ParameterValue::String(CAMERA_VIEW.into()),
                "the image topic (sensor_msgs/CompressedImage, JPEG or PNG, sensor-data QoS) the panel's small camera view shows, subscribed at start; empty = no camera view",
            )
            .read_only(),
            ParamSpec::new(
                "camera_view_fps",
                ParameterValue::Double(scene::CAMERA_VIEW_FPS),
                "most camera images a second passed on to the browsers (only while one is connected; the others are dropped, never queued)",
            )
            .read_only()
            .range(ParamRange::Double { min: 0.5, max: 30.0 }),
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
                "let Foxglove clients publish xyz_target, xyz_line_target, pose_target, gripper_target, joint_target (each client passes the panel's rules first: Origin, Host, and the token, which a foxglove_bind beyond loopback requires)",
            )
            .read_only(),
            ParamSpec::new(
                "tls_cert",
                ParameterValue::String(String::new()),
                "the web panel's TLS certificate (PEM, the server's certificate first, then any CA certificates of its chain; valid for the names and addresses browsers use, e.g. from launch_scripts/panel_certs.sh): with tls_key, the panel is served as https:// and wss://, the Foxglove server as wss://; empty = plain HTTP, which a bind or foxglove_bind beyond loopback refuses unless insecure_http",
            )
            .read_only(),
            ParamSpec::new(
                "tls_key",
                ParameterValue::String(String::new()),
                "the private key of tls_cert (PEM: PKCS#8, EC or RSA; readable by this user only)",
            )
            .read_only(),
            ParamSpec::new(
                "insecure_http",
                ParameterValue::Boolean(false),
                "serve plain HTTP and WS on a bind or foxglove_bind beyond loopback, without tls_cert: the access token then travels in the clear (anyone on that network can read it and move the arm); a warning at start and in every diagnostics report. Without this or tls_cert such a bind does not start (exit 2)",
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

/// The graph's nodes the panel and the calibration wizard work with, found by their
/// names (parameters `ik_node` and `servo_nodes`), never by what their `diagnostics`
/// say they do: a node renamed with `-r __node:=` is named here too.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeNames {
    /// The node running the inverse kinematics (and the arbiter).
    pub ik: String,
    /// The serial_nodes, follower and leader.
    pub servos: Vec<String>,
    /// The recorder, whose episodes the panel's recording card starts and ends.
    pub recorder: String,
}

impl NodeNames {
    /// `ik_node`'s default: the contract's name.
    pub const IK: &'static str = "compute_ik";
    /// `servo_nodes`' default: the follower's contract name and the leader's documented
    /// one (docs/nodes.md).
    pub const SERVOS: [&'static str; 2] = ["serial_node", "leader_arm"];
    /// `recorder_node`'s default: the contract's name.
    pub const RECORDER: &'static str = "recorder";

    /// The names the node's parameters give.
    pub fn from_params(params: &Params) -> NodeNames {
        let mut names = NodeNames::default();
        if let Some(ik) = params.string("ik_node") {
            names.ik = ik;
        }
        if let Some(servos) = params.get_as::<Vec<String>>("servo_nodes") {
            names.servos = servos;
        }
        if let Some(recorder) = params.string("recorder_node") {
            names.recorder = recorder;
        }
        names
    }

    /// The nodes a saved calibration sets `arm_config` on: the IK node and every
    /// serial_node.
    pub fn calibrated(&self) -> impl Iterator<Item = &str> {
        std::iter::once(self.ik.as_str()).chain(self.servos.iter().map(String::as_str))
    }
}

impl Default for NodeNames {
    fn default() -> NodeNames {
        NodeNames {
            ik: NodeNames::IK.into(),
            servos: NodeNames::SERVOS.iter().map(|s| s.to_string()).collect(),
            recorder: NodeNames::RECORDER.into(),
        }
    }
}

fn check_node_names(names: &[String]) -> Result<(), String> {
    names
        .iter()
        .try_for_each(|n| ros_plumbing::names::check_node_name(n).map_err(|e| e.to_string()))
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
    /// `leader/joint_states`: a leader arm's joints, shown beside the follower
    LeaderJoints(JointState),
    /// `leader/deadman`
    LeaderDeadman(bool),
    /// `tf`, as the panel reads it: the twin's cube, if the message has it
    Tf(scene::CubeTf),
    /// an image of the camera view's topic (`camera_view`)
    CameraImage(scene::CameraImage),
    /// A sample on `topic` over the panel's limits ([`bounded`]): not copied, logged
    /// (throttled), counted in `diagnostics` and shown on the page; the panel keeps what
    /// it had.
    Refused {
        /// the topic, as subscribed (`robot_description`, `leader/joint_states`, …)
        topic: &'static str,
        /// why, e.g. `16000 joints > 256`
        reason: String,
    },
    /// A sample on `topic` that could not be deserialized (malformed CDR): logged,
    /// counted in `diagnostics`, otherwise ignored (an unreadable `estop` changes nothing).
    Unreadable {
        /// the topic, as subscribed (`joint_states`, `estop`, …)
        topic: &'static str,
        /// why it could not be read
        error: String,
    },
}

/// Where the bridge's targets go.
pub trait Outputs {
    /// Publish on `xyz_target`, or with `line` on `xyz_line_target`
    /// ([`teleop::xyz_topic`]), with this stamp.
    fn xyz_target(&self, xyz: [f64; 3], line: bool, stamp: Time);
    /// Publish on `gripper_target`.
    fn gripper_target(&self, opening: f64);
    /// Publish on `joint_target` with this stamp.
    fn joint_target(&self, positions: &[(String, f64)], stamp: Time);
    /// Publish on `estop`.
    fn estop(&self, engaged: bool);
    /// Publish a `diagnostics` report with this status.
    fn diagnostics(&self, status: DiagnosticStatus);
}

/// How often the page gets a leader arm's joints, at most.
pub const LEADER_VIEW_RATE_HZ: f64 = 20.0;

/// A calibration to write and apply ([`crate::calibrate::Effect::Save`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SaveJob {
    /// the servos' calibration
    pub servos: eezybot_kinematics::ServoCalibrations,
    /// the leader section
    pub leader: Option<eezybot_kinematics::LeaderCalibration>,
    /// give the arm back to compute_ik (`calibration` deactivated) once `arm_config` is applied
    pub end_calibrating: bool,
    /// the nodes to set `arm_config` on (compute_ik and the serial_nodes heard)
    pub nodes: Vec<String>,
}

/// The calibration wizard's ROS side: taking the arm from compute_ik (its `calibration`
/// controller) and giving it back, and saving and
/// applying a calibration (`arm_config` on the other nodes).
pub trait CalibrationControl {
    /// Take the arm from compute_ik (`calibration` activated, its lease renewed) or give
    /// it back.
    fn set_calibrating(&self, on: bool) -> LocalBoxFuture<'_, Result<(), String>>;
    /// Write the calibration, set `arm_config` on the job's nodes, then end calibrating
    /// if asked.
    fn save(&self, job: SaveJob) -> LocalBoxFuture<'_, calibrate::SaveOutcome>;
    /// Publish on `servo_angles` (horn angles in deg), while calibrating.
    fn servo_angles(&self, deg: [f64; 4], stamp: Time);
    /// These nodes were heard: make their parameter clients now, so that the services
    /// are matched long before a calibration is saved.
    fn prepare(&self, nodes: &[String]);
}

/// The recording card's ROS side: the calls on the recorder node, each bounded in time
/// (a call that gets no answer ends as a failure saying so).
pub trait RecorderControl {
    /// Do `work`: `Ok` with the recorder's message, or why not.
    fn call(&self, work: recording::RecordWork) -> LocalBoxFuture<'_, Result<String, String>>;
}

/// No recorder side (tests of the loop): every call fails, saying so.
pub struct NoRecorder;

impl RecorderControl for NoRecorder {
    fn call(&self, _work: recording::RecordWork) -> LocalBoxFuture<'_, Result<String, String>> {
        Box::pin(async { Err("no recorder client in this bridge".to_string()) })
    }
}

/// No ROS side (tests of the loop without calibration): every job fails with the reason.
pub struct NoCalibration;

impl CalibrationControl for NoCalibration {
    fn set_calibrating(&self, _on: bool) -> LocalBoxFuture<'_, Result<(), String>> {
        Box::pin(async { Err("no compute_ik parameters to set".to_string()) })
    }
    fn save(&self, _job: SaveJob) -> LocalBoxFuture<'_, calibrate::SaveOutcome> {
        Box::pin(async {
            calibrate::SaveOutcome {
                written: Err("no calibration file".into()),
                applied: vec![],
                failed: vec![],
            }
        })
    }
    fn servo_angles(&self, _deg: [f64; 4], _stamp: Time) {}
    fn prepare(&self, _nodes: &[String]) {}
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
    /// What the panel's listeners speak: `insecure_http` warns in every report.
    pub transport: tls::Transport,
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

/// The bridge loop's ends: where its inputs come from and where its effects go.
pub struct Handles<'a, I, O, F: Fn() -> Vec<usize>, S> {
    /// The ROS inputs.
    pub inputs: I,
    /// The browsers' requests, and what happened to their connections.
    pub requests: Requests,
    /// The web side's counters (clients, refusals, limits hit): the loop owns them and
    /// counts the [`web::WebEvent`]s of `requests`.
    pub web: WebStats,
    /// Messages to every browser.
    pub to_browsers: broadcast::Sender<String>,
    /// What a browser that connects gets first (and `/robot.urdf`).
    pub snapshot: watch::Sender<Snapshot>,
    /// The publishers.
    pub outputs: &'a O,
    /// The node's parameters (`rate` may change).
    pub params: Params,
    /// How the panel reports itself on `diagnostics`.
    pub reporting: Reporting<F>,
    /// The calibration wizard's ROS side.
    pub calibration: &'a dyn CalibrationControl,
    /// The recording card's ROS side.
    pub recorder: &'a dyn RecorderControl,
    /// The camera view's latest image, for the browsers (each takes the latest when it
    /// can: a slow one skips images, none queue).
    pub camera: watch::Sender<Option<axum::body::Bytes>>,
    /// The loop ends when this resolves.
    pub shutdown: S,
}

/// The loop between browsers and ROS, around `panel`; runs until `shutdown` resolves.
///
/// Its work in order of priority: shutdown, e-stop requests, targets due, the jobs
/// beside it finishing (a program file's, the calibration wizard's, the recording
/// card's call on the recorder), the periodic
/// reports, a change of `rate`, ROS inputs, what happened to the web side's connections
/// (counted in the loop's own [`WebStats`]: the server's tasks share no lock), then
/// other browser requests; so a browser flooding requests delays neither an e-stop nor
/// the targets nor the live view. Each wakeup is an `Event`, handled by
/// `Bridge::on_event`.
pub async fn run<I, O, F, S>(panel: Panel, io: Handles<'_, I, O, F, S>)
where
    I: Stream<Item = Input>,
    O: Outputs,
    F: Fn() -> Vec<usize>,
    S: Future<Output = ()>,
{
    let (mut bridge, inputs, shutdown) = Bridge::new(panel, io);
    tokio::pin!(inputs);
    tokio::pin!(shutdown);
    loop {
        let clock = Clock::read();
        if bridge.panel.publish_due(clock.now) {
            // Due now: publish before anything else. (A sleep until a past instant ends
            // only when the timer next runs, which a loop kept busy by requests would put
            // off for as long as they keep coming.)
            bridge
                .sink
                .apply(bridge.panel.on_tick(clock), None, &mut bridge.jobs);
            continue;
        }
        let wake = bridge.panel.next_wakeup(clock.now);
        let event = tokio::select! {
            biased;
            _ = &mut shutdown => Event::Shutdown,
            Some(from) = bridge.requests.estops.recv() => Event::Estop(from),
            _ = async { if let Some(w) = wake { tokio::time::sleep_until(w.into()).await } }, if wake.is_some() => Event::Due,
            done = finished(&mut bridge.jobs.file), if bridge.jobs.file.is_some() => Event::FileDone(done),
            done = finished(&mut bridge.jobs.calibration), if bridge.jobs.calibration.is_some() => Event::CalibrationDone(done),
            done = finished(&mut bridge.jobs.record), if bridge.jobs.record.is_some() => Event::RecordDone(done),
            _ = bridge.status_tick.tick() => Event::StatusTick,
            _ = bridge.diag_tick.tick() => Event::Report,
            _ = bridge.peer_poll.tick() => Event::PeerPoll,
            Ok(()) = bridge.param_changes.changed() => Event::Rate,
            input = inputs.next() => match input {
                Some(input) => Event::Input(input),
                None => break,
            },
            Some(event) = bridge.requests.events.recv() => Event::Web(event),
            Some(from) = bridge.requests.others.recv() => Event::Request(from),
        };
        if bridge.on_event(event).await.is_break() {
            break;
        }
    }
}

/// What woke [`run`]'s loop, in its order of priority.
enum Event {
    /// `shutdown` resolved
    Shutdown,
    /// an e-stop request of a browser's
    Estop(web::FromClient),
    /// the panel's next wakeup (a target due)
    Due,
    /// the program file's job is done
    FileDone(FileDone),
    /// the calibration wizard's job is done
    CalibrationDone(panel::CalibrationDone),
    /// the recording card's call is done
    RecordDone(recording::RecordDone),
    /// the calibration's status (every 500 ms)
    StatusTick,
    /// the panel's `diagnostics` (every second)
    Report,
    /// the watched topics' peers (every 250 ms)
    PeerPoll,
    /// a parameter was set (`rate` may have changed)
    Rate,
    /// a ROS input
    Input(Input),
    /// what happened to a connection of the web side
    Web(WebEvent),
    /// any other request of a browser's
    Request(web::FromClient),
}

/// What [`run`] holds besides its ROS inputs and shutdown: the panel, where its effects
/// go and the jobs they start, the browsers' requests, the timers, the parameters and
/// the watch on their changes, how the panel reports itself.
struct Bridge<'a, O, F: Fn() -> Vec<usize>> {
    panel: Panel,
    sink: Sink<'a, 'a, O>,
    jobs: Jobs<'a>,
    requests: Requests,
    /// the `diagnostics` report, every second
    diag_tick: tokio::time::Interval,
    /// the watched topics' peers, polled every 250 ms
    peer_poll: tokio::time::Interval,
    /// the calibration's status (and the parameter clients of the nodes heard), every 500 ms
    status_tick: tokio::time::Interval,
    params: Params,
    param_changes: watch::Receiver<u64>,
    reporting: Reporting<F>,
    /// the camera view (`camera_view`): which images go to the browsers
    camera: scene::CameraView,
}

impl<'a, O: Outputs, F: Fn() -> Vec<usize>> Bridge<'a, O, F> {
    /// The loop's state from its ends, and the ROS inputs and shutdown; the first
    /// snapshot is sent.
    fn new<I, S>(panel: Panel, io: Handles<'a, I, O, F, S>) -> (Self, I, S) {
        let Handles {
            inputs,
            requests,
            web,
            to_browsers,
            snapshot,
            outputs,
            params,
            reporting,
            calibration,
            recorder,
            camera,
            shutdown,
        } = io;
        snapshot.send_replace(panel.snapshot());
        let bridge = Bridge {
            panel,
            sink: Sink {
                outputs,
                to_browsers,
                snapshot,
                web,
                calibration,
                recorder,
                camera,
            },
            jobs: Jobs {
                file: None,
                calibration: None,
                record: None,
            },
            requests,
            diag_tick: tokio::time::interval(Duration::from_secs(1)),
            peer_poll: tokio::time::interval(Duration::from_millis(250)),
            status_tick: tokio::time::interval(Duration::from_millis(500)),
            param_changes: params.subscribe(),
            camera: scene::CameraView::new(
                params
                    .f64("camera_view_fps")
                    .unwrap_or(scene::CAMERA_VIEW_FPS),
            ),
            params,
            reporting,
        };
        (bridge, inputs, shutdown)
    }

    /// Handle `event`; `Break` once the loop is to end (shutdown).
    async fn on_event(&mut self, event: Event) -> ControlFlow<()> {
        let (panel, sink, jobs) = (&mut self.panel, &mut self.sink, &mut self.jobs);
        match event {
            Event::Shutdown => {
                self.stop().await;
                return ControlFlow::Break(());
            }
            Event::Estop(from) => sink.apply(
                panel.on_request(from.request, Clock::read()),
                Some(&from.reply),
                jobs,
            ),
            Event::Due => sink.apply(panel.on_tick(Clock::read()), None, jobs),
            Event::FileDone(done) => {
                jobs.file = None;
                sink.apply(panel.on_file_done(done), None, jobs);
            }
            Event::CalibrationDone(done) => {
                jobs.calibration = None;
                sink.apply(panel.on_calibration_done(done, Clock::read()), None, jobs);
            }
            Event::RecordDone(done) => {
                jobs.record = None;
                sink.apply(panel.on_record_done(done, Clock::read()), None, jobs);
            }
            Event::StatusTick => {
                sink.calibration.prepare(&panel.calibration_nodes());
                sink.apply(panel.on_status_tick(Clock::read()), None, jobs)
            }
            Event::Report => sink.report(panel, &self.camera, &self.reporting),
            Event::PeerPoll => self.poll_peers(),
            Event::Rate => panel.set_rate(self.params.f64("rate").unwrap_or(50.0)),
            Event::Input(Input::CameraImage(image)) => {
                let (outcome, line) =
                    self.camera
                        .on_image(image, sink.web.clients(), Instant::now());
                log(line);
                if let scene::CameraOutcome::Forward(bytes) = outcome {
                    sink.camera.send_replace(Some(bytes));
                }
            }
            Event::Input(input) => sink.apply(panel.on_input(input, Clock::read()), None, jobs),
            Event::Web(event) => {
                let ended = matches!(event, WebEvent::Ended { .. });
                sink.web_event(event);
                if ended && sink.web.clients() == 0 {
                    // nobody is left to finish a calibration: the arm goes back
                    sink.apply(panel.on_every_client_gone(Clock::read()), None, jobs);
                }
            }
            Event::Request(from) => {
                sink.apply(
                    panel.on_request(from.request, Clock::read()),
                    Some(&from.reply),
                    jobs,
                );
                // one request at a time, then let the other tasks run (on this node's
                // one thread: another client's handler with an e-stop in hand)
                tokio::task::yield_now().await;
            }
        }
        ControlFlow::Continue(())
    }

    /// Poll the watched topics' peers: log what changed, and report it at once.
    fn poll_peers(&mut self) {
        let reporting = &mut self.reporting;
        let changes = reporting
            .peers
            .update(&(reporting.counts)(), Instant::now());
        changes.iter().for_each(|c| c.log());
        if !changes.is_empty() {
            self.sink.report(&self.panel, &self.camera, &self.reporting);
        }
    }

    /// Before the loop ends: give the arm back to compute_ik if the wizard holds it.
    async fn stop(&self) {
        if self.panel.calibrating() {
            log::warn!("stopping while calibrating: giving the arm back to compute_ik");
            let give_back = self.sink.calibration.set_calibrating(false);
            if let Err(e) = tokio::time::timeout(Duration::from_secs(3), give_back)
                .await
                .unwrap_or_else(|_| Err("no answer".into()))
            {
                log::error!("the arm is still held for calibration ({e}): `ros2 control switch_controllers --deactivate calibration`, or compute_ik gives it back after its calibration_lease");
            }
        }
    }
}

/// Work of the loop's beside it, at most one of each kind: a program file's load or
/// save (off the event loop: a FIFO, a hung mount; the loop goes on, the job times
/// out), the calibration wizard's ROS work, and the recording card's call on the
/// recorder (bounded in time by [`RecorderControl::call`]).
struct Jobs<'m> {
    file: Option<BoxFuture<'static, FileDone>>,
    /// the arm taken from compute_ik or given back, or a calibration saved and applied
    calibration: Option<LocalBoxFuture<'m, panel::CalibrationDone>>,
    /// a call on the recorder (the card takes one at a time)
    record: Option<LocalBoxFuture<'m, recording::RecordDone>>,
}

/// The job's output once it is done (never, without one).
async fn finished<J: Future + Unpin>(job: &mut Option<J>) -> J::Output {
    match job.as_mut() {
        Some(job) => job.await,
        None => std::future::pending().await,
    }
}

/// Where the panel's effects go; the web side's counters.
struct Sink<'a, 'm, O> {
    outputs: &'a O,
    to_browsers: broadcast::Sender<String>,
    snapshot: watch::Sender<Snapshot>,
    web: WebStats,
    calibration: &'m dyn CalibrationControl,
    recorder: &'m dyn RecorderControl,
    camera: watch::Sender<Option<axum::body::Bytes>>,
}

impl<'m, O: Outputs> Sink<'_, 'm, O> {
    /// Apply `effects`; `reply` answers the request they come from (a full reply queue
    /// drops the answer: the loop never waits for a client).
    fn apply(
        &mut self,
        effects: Vec<Effect>,
        reply: Option<&mpsc::Sender<String>>,
        jobs: &mut Jobs<'m>,
    ) {
        for effect in effects {
            match effect {
                Effect::Publish { command, stamp } => match command {
                    Command::Target { xyz, line } => self.outputs.xyz_target(xyz, line, stamp),
                    Command::Gripper(g) => self.outputs.gripper_target(g),
                    Command::Joints(q) => self.outputs.joint_target(&q, stamp),
                    Command::Estop(on) => self.outputs.estop(on),
                },
                Effect::Broadcast(message) => {
                    let text = message.to_text();
                    if text.len() > web::MAX_BROADCAST_BYTES {
                        // bounded at their sources (bounded.rs); this is the last wall
                        log(self.web.dropped_broadcast(&text, Instant::now()));
                    } else {
                        let _ = self.to_browsers.send(text);
                    }
                }
                Effect::Answer(message) => {
                    let full = reply.map(|r| r.try_send(message.to_text()));
                    if let Some(Err(mpsc::error::TrySendError::Full(_))) = full {
                        self.web.dropped_reply();
                    }
                }
                Effect::Rejected { kind, reason } => {
                    log(self.web.rejected_request(kind, &reason, Instant::now()));
                }
                Effect::File { job, dir } => {
                    jobs.file = Some(Box::pin(async move {
                        let fallback = job.clone();
                        let blocking = tokio::task::spawn_blocking(move || job.run(&dir));
                        match tokio::time::timeout(desk::FILE_TIMEOUT, blocking).await {
                            Ok(Ok(done)) => done,
                            _ => fallback.timed_out(desk::FILE_TIMEOUT),
                        }
                    }));
                }
                Effect::Snapshot(s) => {
                    self.snapshot.send_replace(s);
                }
                Effect::Log(level, text) => log(Some((level, text))),
                Effect::Calibration(work) => {
                    let c = self.calibration;
                    match work {
                        panel::CalibrationWork::ServoAngles(deg) => {
                            c.servo_angles(deg, Time::now())
                        }
                        panel::CalibrationWork::SetCalibrating(on) => {
                            jobs.calibration = Some(Box::pin(async move {
                                panel::CalibrationDone::Calibrating(on, c.set_calibrating(on).await)
                            }));
                        }
                        panel::CalibrationWork::Save(job) => {
                            jobs.calibration = Some(Box::pin(async move {
                                panel::CalibrationDone::Saved(c.save(*job).await)
                            }));
                        }
                    }
                }
                Effect::Record(work) => {
                    let r = self.recorder;
                    let op = work.op();
                    jobs.record = Some(Box::pin(async move {
                        recording::RecordDone {
                            op,
                            result: r.call(work).await,
                        }
                    }));
                }
            }
        }
    }

    /// Count what happened to a connection of the web side.
    fn web_event(&mut self, event: WebEvent) {
        log(self.web.on_event(event, Instant::now()));
    }

    /// The panel's `diagnostics`, with the watched topics' peers.
    fn report<F: Fn() -> Vec<usize>>(
        &self,
        panel: &Panel,
        camera: &scene::CameraView,
        reporting: &Reporting<F>,
    ) {
        let now = Instant::now();
        let mut status = panel.report(&reporting.name, &reporting.url, &self.web, now);
        status
            .values
            .extend(camera.values().into_iter().map(|(key, value)| KeyValue {
                key: key.into(),
                value,
            }));
        match &reporting.transport {
            tls::Transport::Plain => {}
            tls::Transport::Tls { .. } => status.values.push(KeyValue {
                key: "tls".into(),
                value: "on".into(),
            }),
            insecure @ tls::Transport::Insecure { .. } => {
                status.values.push(KeyValue {
                    key: "tls".into(),
                    value: "off (insecure_http)".into(),
                });
                status.level = status.level.max(DiagnosticStatus::WARN);
                if let Some(warning) = insecure.warning() {
                    status.message = format!("{}; {warning}", status.message);
                }
            }
        }
        reporting.peers.annotate(&mut status, now);
        self.outputs.diagnostics(status);
    }
}

/// Write a line of the panel's or the web side's, if there is one.
fn log(line: Option<LogLine>) {
    if let Some((level, text)) = line {
        log::log!(level, "{text}");
    }
}
