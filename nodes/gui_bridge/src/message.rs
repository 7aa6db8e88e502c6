//! What the panel sends to browsers: [`ToClient`], the counterpart of
//! [`ClientRequest`](crate::web::ClientRequest). Each message is a JSON object whose
//! `t` names its kind (`web/panel.js`'s `handle()` switches on it); every field below is
//! one the page reads, and a field written as `null` stays `null` (not left out).

use crate::program::{PlayerState, Program};
use crate::teleop::{JointSlider, RobotView};
use eezybot_kinematics::envelope::Envelope;
use eezybot_kinematics::{Arm, ArmJoints};
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Arc;

/// A message to browsers.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "t", rename_all = "snake_case")]
pub enum ToClient {
    /// A target, a jog, the claw, a joint target or the e-stop was taken.
    Ack {
        /// the Cartesian target now (m)
        target: [f64; 3],
        /// the joints that reach it (the EezyBot's closed form; null for any other arm)
        joints: Option<ArmJointsMsg>,
        /// always true
        reachable: bool,
    },
    /// A request was refused.
    Refused {
        /// why (cut to [`crate::web::REASON_MAX`])
        reason: String,
        /// false for a request the loop refused; left out for a message that was no
        /// request
        #[serde(skip_serializing_if = "Option::is_none")]
        reachable: Option<bool>,
    },
    /// The answer to a `check` (nothing is sent).
    Check {
        /// the point asked about (m)
        xyz: [f64; 3],
        /// reachable, not, or null: not checked here (an arm without a closed form)
        reachable: Option<bool>,
        /// the joints that reach it (reachable only)
        #[serde(skip_serializing_if = "Option::is_none")]
        joints: Option<ArmJointsMsg>,
        /// why not (or why not checked)
        #[serde(skip_serializing_if = "Option::is_none")]
        reason: Option<String>,
    },
    /// Where the arm is, from `joint_states`.
    Pose(Pose),
    /// The arm, from `robot_description`.
    Robot {
        /// the arm as the page needs it
        robot: RobotInfo,
    },
    /// The waypoint program, its files and its player.
    Program(ProgramView),
    /// Health of the other nodes, from their `diagnostics`.
    Status {
        /// the expected nodes first, then every other node heard
        nodes: Vec<NodeEntry>,
        /// compute_ik's last refusal of a target
        last_rejection: Option<String>,
        /// who moves the arm: compute_ik's active controllers
        controllers: Option<String>,
        /// compute_ik's last switch of controllers (`done`, or why not)
        last_switch: Option<String>,
    },
    /// Arrival time − stamp of a `servo_state` reply to one of our targets.
    Latency {
        /// this one, ms
        ms: f64,
        /// the median of the last 50, ms
        median_ms: Option<f64>,
        /// how many of them
        n: usize,
    },
    /// `estop` as heard on the topic.
    Estop {
        /// engaged?
        on: bool,
    },
    /// Something was published.
    Sent(Sent),
    /// The calibration wizard ([`crate::calibrate::Wizard::view`]).
    Calibration(Box<CalibrationView>),
    /// A leader arm's joints (`leader/joint_states`) and its deadman (`leader/deadman`),
    /// at most [`crate::LEADER_VIEW_RATE_HZ`] a second.
    Leader {
        /// joint name -> rad
        joints: BTreeMap<String, f64>,
        /// the deadman is held (null: not heard yet)
        deadman: Option<bool>,
    },
    /// The recording card: the recorder's state and the last episode call (made by
    /// recording.rs's `RecordCard::view`).
    Recorder(Box<RecordView>),
    /// The inputs refused now (`robot_description` over the limits, …: bounded.rs),
    /// each with its reason; empty once each refused topic's next sample is taken.
    InputsRefused {
        /// topic and reason, e.g. `robot_description`, `16000 joints > 256`
        inputs: Vec<InputRefusal>,
    },
    /// The physics twin's cube (its `tf` frame `cube` in `base_frame`), at most
    /// [`crate::scene::CUBE_VIEW_RATE_HZ`] a second and only when it moved; `p` and `q`
    /// null once no cube frame came for [`crate::scene::CUBE_STALE_AFTER`] (hidden).
    Cube {
        /// position (m), null: no cube
        p: Option<[f64; 3]>,
        /// orientation, quaternion `[x, y, z, w]`, null: no cube
        q: Option<[f64; 4]>,
    },
}

impl ToClient {
    /// The `cube` message for this pose (None: no cube).
    pub fn cube(t: Option<&eezybot_msgs::geometry_msgs::Transform>) -> ToClient {
        ToClient::Cube {
            p: t.map(|t| [t.translation.x, t.translation.y, t.translation.z]),
            q: t.map(|t| [t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w]),
        }
    }
}

/// `{"t": "recorder", …}`: the recorder as its `diagnostics` report it (each value null
/// until heard, or when unreadable), the call in flight, the last call's outcome and
/// which buttons work now.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RecordView {
    /// the recorder's node name (`recorder_node`)
    pub node: String,
    /// heard within the last 5 s
    pub up: bool,
    /// why the buttons are off: no recorder heard, or not any more
    pub note: Option<String>,
    /// waiting, idle, recording, saving, stopped (or what a newer recorder says)
    pub state: Option<String>,
    /// its status's level: 0 OK, 1 WARN (frames dropped), 2 ERROR (stopped)
    pub level: Option<u8>,
    /// its status's message
    pub message: Option<String>,
    /// the episode's task (recording), else the `task` parameter
    pub task: Option<String>,
    /// the episode being recorded (recording, saving), else the next one
    pub episode: Option<u64>,
    /// episodes saved in the dataset
    pub episodes: Option<u64>,
    /// frames of the episode in progress
    pub frames: Option<u64>,
    /// seconds since the episode started, when reported
    pub elapsed_s: Option<f64>,
    /// seconds since that report (the page adds it and its own time since)
    pub age_s: Option<f64>,
    /// frames dropped in the episode in progress
    pub dropped: Option<u64>,
    /// frames dropped since the recorder started
    pub dropped_total: Option<u64>,
    /// frames a second
    pub fps: Option<f64>,
    /// the dataset's folder
    pub root: Option<String>,
    /// the cameras' feature names, comma-separated
    pub cameras: Option<String>,
    /// the recorder's last episode action's outcome
    pub last: Option<String>,
    /// why recording stopped, or what it waits for
    pub reason: Option<String>,
    /// the call in flight: start, save, discard
    pub busy: Option<&'static str>,
    /// Record works now
    pub can_start: bool,
    /// Save works now
    pub can_save: bool,
    /// Discard works now
    pub can_discard: bool,
    /// the last call's outcome
    pub call: Option<RecordCallView>,
}

/// The outcome of the card's last call.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RecordCallView {
    /// start, save, discard
    pub op: &'static str,
    /// the recorder did it
    pub ok: bool,
    /// its message, or why not (its refusal, a timeout)
    pub text: String,
}

/// `{"t": "calibration", …}`: the wizard as the page shows it (the step list, the
/// reference to show next with its pose for a picture, the jog range, the result).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CalibrationView {
    /// a calibration is under way
    pub active: bool,
    /// `follower` or `leader`
    pub arm: String,
    /// idle, starting, moving, jog, reading, review, saving, testing, done, failed
    pub phase: String,
    /// the active step (index into `steps`)
    pub step: usize,
    /// every servo, in calibration order
    pub steps: Vec<StepView>,
    /// the reference to mark next in the active step (0 = A, 1 = B)
    pub reference: usize,
    /// the active servo's commanded angle (deg; follower only)
    pub commanded_deg: Option<f64>,
    /// the active servo's `servo_state` (deg; follower only)
    pub state_deg: Option<f64>,
    /// where the active servo may be jogged now
    pub jog: Option<JogView>,
    /// the leader's live ADC counts, A0 … A3 (leader only)
    pub counts: Option<[f64; 4]>,
    /// what to do now
    pub instruction: String,
    /// the last refusal or failure
    pub error: Option<String>,
    /// where the calibration was saved and applied
    pub saved: Option<SavedView>,
    /// the guided test move
    pub test: Option<TestView>,
    /// the claw's swing (rad) from closed to open, for pictures of an opening
    pub gripper_open_rad: f64,
}

/// One servo's step.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StepView {
    /// base, shoulder, elbow, gripper
    pub servo: String,
    /// what the user calls it
    pub title: String,
    /// the leader's potentiometer input for this joint (A0 … A3 = 0 … 3)
    pub channel: usize,
    /// what its input measures
    pub input_name: String,
    /// `deg` or `opening`
    pub unit: String,
    /// references A and B
    pub references: [ReferenceView; 2],
    /// B's alternative, if any
    pub alternative_b: Option<ReferenceView>,
    /// the alternative is used
    pub use_alternative: bool,
    /// the joints held while this servo is calibrated
    pub holds: Vec<String>,
    /// the marks: servo deg (follower) or ADC counts (leader)
    pub marks: [Option<f64>; 2],
    /// what the marks gave
    pub derived: Option<DerivedView>,
    /// why the marks were refused
    pub error: Option<String>,
}

/// What a step's two marks gave (the JSON has no tag: the follower's fields or the
/// leader's).
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum DerivedView {
    /// A follower servo's line: servo deg = `offset_deg` + `gain` · input.
    Servo {
        /// the servo's angle at input 0
        offset_deg: f64,
        /// servo degrees per unit of input (its sign: the direction)
        gain: f64,
        /// against the shipped gain's sign
        direction: DirectionView,
        /// the gain over the shipped one
        gain_ratio: f64,
        /// the servo's range kept from the config
        min_deg: f64,
        /// the servo's range kept from the config
        max_deg: f64,
    },
    /// A leader potentiometer's two readings.
    Leader {
        /// ADC counts at reference A
        counts_a: f64,
        /// the joint's input at reference A
        input_a: f64,
        /// ADC counts at reference B
        counts_b: f64,
        /// the joint's input at reference B
        input_b: f64,
    },
}

/// Which way a servo turns its joint, against the shipped calibration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum DirectionView {
    /// the shipped gain's sign
    #[serde(rename = "as shipped")]
    AsShipped,
    /// the opposite sign: the servo is mounted mirrored
    #[serde(rename = "reversed")]
    Reversed,
}

/// A reference pose.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReferenceView {
    /// the servo's input there (deg, or the claw's opening)
    pub input: f64,
    /// what the user looks for
    pub description: String,
    /// the whole arm there, joint name -> rad, for a picture drawn from the URDF
    pub pose: BTreeMap<&'static str, f64>,
}

/// The jog range and steps.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JogView {
    /// lowest servo angle, deg
    pub min_deg: f64,
    /// highest, deg
    pub max_deg: f64,
    /// the fine step, deg
    pub fine_deg: f64,
    /// the coarse step, deg
    pub coarse_deg: f64,
}

/// Where the calibration went.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SavedView {
    /// the file written (null: not written)
    pub path: Option<String>,
    /// the previous file's copy
    pub backup: Option<String>,
    /// nodes whose `arm_config` was set
    pub applied: Vec<String>,
    /// nodes that refused it, with why
    pub failed: Vec<String>,
}

/// The guided test move.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TestView {
    /// joint name -> rad
    pub pose: BTreeMap<String, f64>,
    /// what the arm should show
    pub description: String,
    /// the arm arrived there (`joint_states`)
    pub done: bool,
}

impl ToClient {
    /// The JSON text sent over the WebSocket.
    pub fn to_text(&self) -> String {
        // serializing these types cannot fail (string keys, no custom serializers)
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// The EezyBot's three arm joints, rad.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ArmJointsMsg {
    /// base
    pub base_joint: f64,
    /// shoulder
    pub shoulder_joint: f64,
    /// elbow
    pub elbow_joint: f64,
}

impl From<&ArmJoints> for ArmJointsMsg {
    fn from(q: &ArmJoints) -> Self {
        ArmJointsMsg {
            base_joint: q.base_rad,
            shoulder_joint: q.shoulder_rad,
            elbow_joint: q.elbow_rad,
        }
    }
}

/// `{"t": "pose", …}`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Pose {
    /// The actuated joints (the EezyBot's three), or every URDF joint of another arm.
    pub joints: BTreeMap<String, f64>,
    /// The EezyBot only: every URDF joint, passive linkage ones included, for the 3D view.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub all: Option<BTreeMap<String, f64>>,
    /// The claw's joint (rad), if reported (always null for another arm).
    pub gripper: Option<f64>,
    /// Where the tool is (m).
    pub tool: Option<[f64; 3]>,
    /// (parent origin → child origin, child link) of every joint, for the side and top views.
    pub segments: Vec<([f64; 6], String)>,
}

/// The arm as the page needs it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotInfo {
    /// its name, whether it is the EezyBot, the joint mode's sliders, its reach, its tool
    #[serde(flatten)]
    pub view: RobotView,
    /// whether this came from `robot_description`
    pub from_urdf: bool,
    /// with a URDF: where to fetch it and the workspace envelope
    #[serde(flatten)]
    pub scene: Option<UrdfScene>,
}

impl RobotInfo {
    /// The EezyBot before any `robot_description`.
    pub fn eezybot(joints: Vec<JointSlider>) -> RobotInfo {
        let view = RobotView {
            name: "eezybot".into(),
            eezybot: true,
            joints,
            reach_m: 0.33,
            tool_link: Some("tool0".into()),
        };
        RobotInfo {
            view,
            from_urdf: false,
            scene: None,
        }
    }
}

/// What the 3D view draws of a URDF arm besides the pose.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct UrdfScene {
    /// `robot.urdf?rev=N`: the page fetches the text over HTTP (it can be larger than a
    /// WebSocket client's buffer)
    pub urdf: Option<String>,
    /// the reachable workspace
    pub envelope: Option<Envelope>,
}

/// `{"t": "program", …}`: the desk as every browser shows it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ProgramView {
    /// the points
    pub program: Program,
    /// the player, once a program played
    pub player: Option<PlayerState>,
    /// the program files on the node's host
    pub files: Vec<String>,
    /// the program's name (as last saved or loaded)
    pub name: String,
    /// the desk's last word
    pub message: String,
    /// where the files are
    pub dir: String,
    /// a save found this program existing: the panel asks whether to replace it
    pub confirm_overwrite: Option<String>,
}

/// One node of `{"t": "status"}`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NodeEntry {
    /// the name it runs under
    pub name: String,
    /// what its `diagnostics` entry says it does
    pub task: String,
    /// its hardware id
    pub hardware_id: String,
    /// heard recently
    pub up: bool,
    /// its level (OK, WARN, ERROR, STALE)
    pub level: u8,
    /// its message
    pub message: String,
    /// seconds since heard (null: never)
    pub age_s: Option<f64>,
}

/// `{"t": "sent", "topic": …}`: what went out on which topic.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Sent {
    /// `xyz_target`
    Xyz {
        /// the topic's name
        topic: &'static str,
        /// m
        xyz: [f64; 3],
        /// the target's stamp, ns
        stamp_ns: i64,
    },
    /// `gripper_target`
    Gripper {
        /// the topic's name
        topic: &'static str,
        /// 0 … 1
        value: f64,
    },
    /// `joint_target`
    Joints {
        /// the topic's name
        topic: &'static str,
        /// (name, position) pairs
        q: Vec<(String, f64)>,
        /// the target's stamp, ns
        stamp_ns: i64,
    },
    /// `estop`
    Estop {
        /// the topic's name
        topic: &'static str,
        /// engaged?
        on: bool,
    },
}

/// The arm's fixed facts a browser gets with its hello.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ArmFacts {
    /// joint limits (rad), by joint
    pub limits: BTreeMap<&'static str, [f64; 2]>,
    /// the sliders' ranges (m)
    pub workspace: BTreeMap<&'static str, [f64; 2]>,
    /// link lengths (m) for the side and top views
    pub geometry: BTreeMap<&'static str, f64>,
}

impl ArmFacts {
    /// Of this arm.
    pub fn of(arm: &Arm) -> ArmFacts {
        let l = arm.limits;
        let g = arm.geometry;
        ArmFacts {
            limits: BTreeMap::from([
                ("base_joint", [l.base_rad.0, l.base_rad.1]),
                ("shoulder_joint", [l.shoulder_rad.0, l.shoulder_rad.1]),
                ("elbow_joint", [l.elbow_rad.0, l.elbow_rad.1]),
                ("gripper_joint", [0.0, g.gripper_open_rad]),
            ]),
            workspace: BTreeMap::from([
                ("x", [0.0, 0.30]),
                ("y", [-0.22, 0.22]),
                ("z", [0.0, 0.30]),
            ]),
            geometry: BTreeMap::from([
                ("shoulder_height", g.shoulder_height_m),
                ("main_arm", g.main_arm_m),
                ("forearm", g.forearm_m),
                ("tool_dx", g.tool_dx_m),
            ]),
        }
    }
}

/// One input refused now ([`crate::bounded`]), as the page shows it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct InputRefusal {
    /// the topic (relative name: `robot_description`)
    pub topic: &'static str,
    /// why, e.g. `16000 joints > 256`
    pub reason: String,
}

/// What a browser that connects gets first: the panel as it is now. The bridge loop
/// keeps it current; the web server reads it for each new client (and `/robot.urdf`).
#[derive(Clone, Debug)]
pub struct Snapshot {
    /// the Cartesian target now (m)
    pub target: [f64; 3],
    /// the latest `pose` message
    pub pose: Option<Arc<ToClient>>,
    /// the arm
    pub robot: Arc<RobotInfo>,
    /// the latest `program` message
    pub program: Arc<ToClient>,
    /// the arm's fixed facts
    pub arm: Arc<ArmFacts>,
    /// the text of `robot_description`, for `/robot.urdf`
    pub urdf: Option<Arc<str>>,
    /// the latest `calibration` message (none: no wizard here)
    pub calibration: Option<Arc<ToClient>>,
    /// the latest `recorder` message (the recording card)
    pub recorder: Option<Arc<ToClient>>,
    /// the latest `cube` message
    pub cube: Arc<ToClient>,
    /// the camera view's topic (`camera_view`; None: no camera view)
    pub camera: Option<Arc<str>>,
    /// the inputs refused now
    pub inputs_refused: Vec<InputRefusal>,
}

/// `{"t": "hello", …}`.
#[derive(Serialize)]
#[serde(tag = "t", rename = "hello")]
struct Hello<'a> {
    target: [f64; 3],
    pose: Option<&'a ToClient>,
    rate: f64,
    robot: &'a RobotInfo,
    program: &'a ToClient,
    calibration: Option<&'a ToClient>,
    recorder: Option<&'a ToClient>,
    cube: &'a ToClient,
    camera: Option<&'a str>,
    inputs_refused: &'a [InputRefusal],
    #[serde(flatten)]
    arm: &'a ArmFacts,
}

impl Snapshot {
    /// The hello message, with the `rate` parameter as it is now.
    pub fn hello(&self, rate: f64) -> String {
        serde_json::to_string(&Hello {
            target: self.target,
            pose: self.pose.as_deref(),
            rate,
            robot: &self.robot,
            program: &self.program,
            calibration: self.calibration.as_deref(),
            recorder: self.recorder.as_deref(),
            cube: &self.cube,
            camera: self.camera.as_deref(),
            inputs_refused: &self.inputs_refused,
            arm: &self.arm,
        })
        .unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn value(m: &ToClient) -> serde_json::Value {
        serde_json::from_str(&m.to_text()).unwrap()
    }

    /// The fields `web/panel.js` reads, null where it may read null.
    #[test]
    fn the_wire_format_is_the_one_the_page_reads() {
        let q = ArmJointsMsg {
            base_joint: 0.1,
            shoulder_joint: 0.2,
            elbow_joint: 0.3,
        };
        let joints = json!({"base_joint": 0.1, "shoulder_joint": 0.2, "elbow_joint": 0.3});
        let cases = [
            (
                ToClient::Ack {
                    target: [0.2, 0.0, 0.1],
                    joints: Some(q),
                    reachable: true,
                },
                json!({"t": "ack", "target": [0.2, 0.0, 0.1], "joints": joints, "reachable": true}),
            ),
            (
                ToClient::Ack {
                    target: [0.2, 0.0, 0.1],
                    joints: None,
                    reachable: true,
                },
                json!({"t": "ack", "target": [0.2, 0.0, 0.1], "joints": null, "reachable": true}),
            ),
            (
                ToClient::Refused {
                    reason: "far".into(),
                    reachable: Some(false),
                },
                json!({"t": "refused", "reason": "far", "reachable": false}),
            ),
            (
                ToClient::Refused {
                    reason: "not JSON".into(),
                    reachable: None,
                },
                json!({"t": "refused", "reason": "not JSON"}),
            ),
            (
                ToClient::Check {
                    xyz: [1.0, 2.0, 3.0],
                    reachable: None,
                    joints: None,
                    reason: Some("not here".into()),
                },
                json!({"t": "check", "xyz": [1.0, 2.0, 3.0], "reachable": null, "reason": "not here"}),
            ),
            (
                ToClient::Check {
                    xyz: [1.0, 2.0, 3.0],
                    reachable: Some(true),
                    joints: Some(q),
                    reason: None,
                },
                json!({"t": "check", "xyz": [1.0, 2.0, 3.0], "reachable": true, "joints": joints}),
            ),
            (
                ToClient::Pose(Pose {
                    joints: BTreeMap::from([("j".to_string(), 1.0)]),
                    all: None,
                    gripper: None,
                    tool: Some([1.0, 2.0, 3.0]),
                    segments: vec![([0.0, 0.0, 0.0, 1.0, 1.0, 1.0], "l".into())],
                }),
                json!({"t": "pose", "joints": {"j": 1.0}, "gripper": null, "tool": [1.0, 2.0, 3.0],
                       "segments": [[[0.0, 0.0, 0.0, 1.0, 1.0, 1.0], "l"]]}),
            ),
            (
                ToClient::Pose(Pose {
                    joints: BTreeMap::new(),
                    all: Some(BTreeMap::new()),
                    gripper: Some(0.5),
                    tool: None,
                    segments: vec![],
                }),
                json!({"t": "pose", "joints": {}, "all": {}, "gripper": 0.5, "tool": null, "segments": []}),
            ),
            (
                ToClient::Robot {
                    robot: RobotInfo::eezybot(vec![]),
                },
                json!({"t": "robot", "robot": {"name": "eezybot", "eezybot": true, "joints": [], "reach": 0.33,
                                               "tool_link": "tool0", "from_urdf": false}}),
            ),
            (
                ToClient::Robot {
                    robot: RobotInfo {
                        view: RobotView {
                            name: "jaco".into(),
                            eezybot: false,
                            joints: vec![JointSlider {
                                name: "j1".into(),
                                lower: -1.0,
                                upper: 1.0,
                            }],
                            reach_m: 1.5,
                            tool_link: None,
                        },
                        from_urdf: true,
                        scene: Some(UrdfScene {
                            urdf: Some("robot.urdf?rev=1".into()),
                            envelope: None,
                        }),
                    },
                },
                json!({"t": "robot", "robot": {"name": "jaco", "eezybot": false,
                       "joints": [{"name": "j1", "lower": -1.0, "upper": 1.0}], "reach": 1.5, "tool_link": null,
                       "from_urdf": true, "urdf": "robot.urdf?rev=1", "envelope": null}}),
            ),
            (
                ToClient::Status {
                    nodes: vec![NodeEntry {
                        name: "compute_ik".into(),
                        task: "inverse kinematics".into(),
                        hardware_id: String::new(),
                        up: false,
                        level: 3,
                        message: "not seen".into(),
                        age_s: None,
                    }],
                    last_rejection: None,
                    controllers: Some("teleop, gripper_controller".into()),
                    last_switch: None,
                },
                json!({"t": "status", "nodes": [{"name": "compute_ik", "task": "inverse kinematics",
                       "hardware_id": "", "up": false, "level": 3, "message": "not seen", "age_s": null}],
                       "last_rejection": null, "controllers": "teleop, gripper_controller",
                       "last_switch": null}),
            ),
            (
                ToClient::Latency {
                    ms: 2.5,
                    median_ms: Some(2.0),
                    n: 3,
                },
                json!({"t": "latency", "ms": 2.5, "median_ms": 2.0, "n": 3}),
            ),
            (
                ToClient::Estop { on: true },
                json!({"t": "estop", "on": true}),
            ),
            (
                ToClient::Sent(Sent::Xyz {
                    topic: "xyz_target",
                    xyz: [1.0, 2.0, 3.0],
                    stamp_ns: 7,
                }),
                json!({"t": "sent", "topic": "xyz_target", "xyz": [1.0, 2.0, 3.0], "stamp_ns": 7}),
            ),
            (
                ToClient::Sent(Sent::Gripper {
                    topic: "gripper_target",
                    value: 0.5,
                }),
                json!({"t": "sent", "topic": "gripper_target", "value": 0.5}),
            ),
            (
                ToClient::Sent(Sent::Joints {
                    topic: "joint_target",
                    q: vec![("j".into(), 0.5)],
                    stamp_ns: 7,
                }),
                json!({"t": "sent", "topic": "joint_target", "q": [["j", 0.5]], "stamp_ns": 7}),
            ),
            (
                ToClient::Sent(Sent::Estop {
                    topic: "estop",
                    on: false,
                }),
                json!({"t": "sent", "topic": "estop", "on": false}),
            ),
            (
                ToClient::Cube {
                    p: Some([0.2, 0.0, 0.0675]),
                    q: Some([0.0, 0.0, 0.0, 1.0]),
                },
                json!({"t": "cube", "p": [0.2, 0.0, 0.0675], "q": [0.0, 0.0, 0.0, 1.0]}),
            ),
        ];
        for (message, wire) in cases {
            assert_eq!(value(&message), wire, "{message:?}");
        }
    }

    #[test]
    fn a_hello_carries_the_pose_and_program_messages_and_the_arm() {
        let arm = crate::load_arm("").unwrap();
        let program = ToClient::Program(ProgramView {
            program: Program::default(),
            player: None,
            files: vec!["p".into()],
            name: String::new(),
            message: String::new(),
            dir: "/tmp/p".into(),
            confirm_overwrite: None,
        });
        let snapshot = Snapshot {
            target: [0.2, 0.0, 0.1],
            pose: Some(Arc::new(ToClient::Estop { on: false })),
            robot: Arc::new(RobotInfo::eezybot(vec![])),
            program: Arc::new(program),
            arm: Arc::new(ArmFacts::of(&arm)),
            urdf: None,
            calibration: None,
            recorder: None,
            cube: Arc::new(ToClient::cube(None)),
            camera: Some("twin/camera/image_raw/compressed".into()),
            inputs_refused: vec![InputRefusal {
                topic: "robot_description",
                reason: "16000 joints > 256".into(),
            }],
        };
        let hello: serde_json::Value = serde_json::from_str(&snapshot.hello(50.0)).unwrap();
        assert!(hello["recorder"].is_null());
        assert_eq!(hello["cube"], json!({"t": "cube", "p": null, "q": null}));
        assert_eq!(hello["camera"], "twin/camera/image_raw/compressed");
        assert_eq!(
            hello["inputs_refused"],
            json!([{"topic": "robot_description", "reason": "16000 joints > 256"}])
        );
        assert_eq!(hello["t"], "hello");
        assert_eq!(hello["rate"], 50.0);
        assert_eq!(hello["target"], json!([0.2, 0.0, 0.1]));
        assert_eq!(hello["pose"]["t"], "estop");
        assert_eq!(hello["program"]["t"], "program");
        assert_eq!(hello["program"]["files"], json!(["p"]));
        assert!(
            hello["program"]["player"].is_null() && hello["program"]["confirm_overwrite"].is_null()
        );
        assert_eq!(hello["robot"]["name"], "eezybot");
        assert_eq!(
            hello["workspace"],
            json!({"x": [0.0, 0.30], "y": [-0.22, 0.22], "z": [0.0, 0.30]})
        );
        assert_eq!(
            hello["limits"]["gripper_joint"],
            json!([0.0, arm.geometry.gripper_open_rad])
        );
        assert_eq!(hello["geometry"]["main_arm"], arm.geometry.main_arm_m);
        assert_eq!(hello["geometry"].as_object().unwrap().len(), 4);
    }
}
