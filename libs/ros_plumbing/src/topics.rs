//! The contract of the graph, each topic, action and service declared once: name, type,
//! QoS (topics) and which of our nodes publish and subscribe (topics) or serve and call
//! (actions, services). Every endpoint of every node is created from these constants
//! ([`RosNode::publish_on`](crate::RosNode::publish_on),
//! [`RosNode::subscribe_to`](crate::RosNode::subscribe_to), [`Callable::name`]); the
//! Python tests read the same tables from `tests/data/topics.json` ([`json`]) and
//! docs/topics.md's tables are [`markdown_table`] and [`callables_table`], both checked
//! against [`all`] and [`CALLABLES`] by `tests/contract.rs` and `tests/docs.rs`;
//! regenerate them with `cargo run -p ros_plumbing --example topics -- --json` and
//! `EEZYBOT_BLESS=1 cargo test -p ros_plumbing --test docs`. The SROS2 permissions
//! ([`crate::sros2`]) are generated from them, and wan/'s `CROSSING` is checked against
//! them (`tests/crossing.rs`). Foxglove's channels and MCAP recordings are derived from
//! it too (`foxglove_bridge::TOPICS`, the topics with [`Topic::foxglove`]): a
//! transient-local topic is "latched", and the roles [`Topic::target`] and
//! [`Topic::recorded`] are declared here.
//!
//! # Examples
//! ```
//! use ros_plumbing::topics;
//! assert_eq!(topics::ESTOP.name, "estop");
//! assert_eq!(topics::ESTOP.type_name(), "std_msgs/msg/Bool");
//! assert_eq!(topics::qos_text(&topics::ESTOP.qos), "reliable, transient-local, keep last 1");
//! ```

use crate::qos;
use eezybot_msgs::control_msgs::JointTrajectoryControllerState;
use eezybot_msgs::diagnostic_msgs::DiagnosticArray;
use eezybot_msgs::geometry_msgs::{PointStamped, PoseStamped};
use eezybot_msgs::sensor_msgs::{CameraInfo, CompressedImage, JointState};
use eezybot_msgs::std_msgs::{Bool, Float64, String as StringMsg};
use eezybot_msgs::tf2_msgs::TFMessage;
use eezybot_msgs::trajectory_msgs::JointTrajectory;
use eezybot_msgs::RosMessage;
use ros2_client::qos::{Durability, History, Reliability};
use ros2_client::QosProfile;
use std::fmt::Write as _;
use std::marker::PhantomData;

/// One topic of the contract, typed by its message `M`.
#[derive(Debug)]
pub struct Topic<M> {
    /// The name, relative to the node's namespace (`xyz_target`).
    pub name: &'static str,
    /// Its QoS, the same at every endpoint.
    pub qos: QosProfile,
    /// The nodes of ours that publish it (empty: only outside tools do).
    pub publishers: &'static [&'static str],
    /// The nodes of ours that subscribe it (empty: only outside tools do).
    pub subscribers: &'static [&'static str],
    /// An operator target: a Foxglove panel may publish it, and a recording replays it
    /// ([`Topic::as_target`]).
    pub target: bool,
    /// A channel of gui_bridge's Foxglove server, and so a topic MCAP recordings and
    /// `gui_bridge play` know ([`Topic::off_foxglove`]).
    pub foxglove: bool,
    message: PhantomData<fn() -> M>,
}

impl<M: RosMessage> Topic<M> {
    /// Declare a topic.
    pub const fn new(
        name: &'static str,
        qos: QosProfile,
        publishers: &'static [&'static str],
        subscribers: &'static [&'static str],
    ) -> Self {
        Topic {
            name,
            qos,
            publishers,
            subscribers,
            target: false,
            foxglove: true,
            message: PhantomData,
        }
    }

    /// The topic without a Foxglove channel ([`Topic::foxglove`]): the controllers' and
    /// the leader arm's topics, which Foxglove does not show nor a recording keep.
    pub const fn off_foxglove(self) -> Self {
        Topic {
            foxglove: false,
            ..self
        }
    }

    /// The topic as an operator target ([`Topic::target`]).
    pub const fn as_target(self) -> Self {
        Topic {
            target: true,
            ..self
        }
    }

    /// Declare an operator target ([`Topic::as_target`]), published by `publishers`:
    /// every target has the commands' QoS and is subscribed by compute_ik, recorded by
    /// `gui_bridge record` and offered to Foxglove.
    pub const fn new_target(name: &'static str, publishers: &'static [&'static str]) -> Self {
        Topic::new(name, qos::COMMANDS, publishers, &[IK, RECORD, FOXGLOVE]).as_target()
    }

    /// Latched: published transient-local, so a late subscriber gets the last sample.
    pub fn latched(&self) -> bool {
        is_latched(&self.qos)
    }

    /// Written into a recording: `gui_bridge record` subscribes it
    /// (the targets, and what it takes to view the session again).
    pub fn recorded(&self) -> bool {
        self.subscribers.contains(&RECORD)
    }

    /// The message type as `ros2 topic` prints it (`std_msgs/msg/Bool`).
    pub fn type_name(&self) -> String {
        M::ros_type_string()
    }

    /// This topic as a row of the untyped table.
    pub fn entry(&self) -> TopicEntry {
        TopicEntry {
            name: self.name,
            type_name: self.type_name(),
            qos: self.qos.clone(),
            publishers: self.publishers,
            subscribers: self.subscribers,
            target: self.target,
            foxglove: self.foxglove,
        }
    }
}

/// One topic of [`all`], its message type as text.
#[derive(Clone, Debug, PartialEq)]
pub struct TopicEntry {
    /// [`Topic::name`]
    pub name: &'static str,
    /// [`Topic::type_name`]
    pub type_name: String,
    /// [`Topic::qos`]
    pub qos: QosProfile,
    /// [`Topic::publishers`]
    pub publishers: &'static [&'static str],
    /// [`Topic::subscribers`]
    pub subscribers: &'static [&'static str],
    /// [`Topic::target`]
    pub target: bool,
    /// [`Topic::foxglove`]
    pub foxglove: bool,
}

impl TopicEntry {
    /// [`Topic::latched`]
    pub fn latched(&self) -> bool {
        is_latched(&self.qos)
    }

    /// [`Topic::recorded`]
    pub fn recorded(&self) -> bool {
        self.subscribers.contains(&RECORD)
    }
}

fn is_latched(qos: &QosProfile) -> bool {
    matches!(qos.durability, Durability::TransientLocal)
}

/// `gui_bridge` (one line, to keep the table below readable).
const GUI: &str = "gui_bridge";
const IK: &str = "compute_ik";
const SERIAL: &str = "serial_node";
const STATE: &str = "state_publisher";
const CAMERA: &str = "camera_node";
/// The `recorder` node (LeRobot datasets from the running graph).
const RECORDER: &str = "recorder";
/// The physics twin (`twin`, docs/twin.md): the arm in MuJoCo behind the servo link.
const TWIN: &str = "twin";
/// `recorder replay`, the recorder's command line playing an episode back (a trajectory
/// goal, the claw's openings).
const REPLAY: &str = "recorder (replay)";
/// `gui_bridge record` subscribes what it saves (the targets; with an MCAP file also
/// what replays and views the session).
const RECORD: &str = "gui_bridge (record)";
/// gui_bridge's Foxglove server (`foxglove_bind`) subscribes a topic of the graph while
/// a Foxglove client watches it, to forward it to Foxglove (`robot_description` and
/// `tf_static` as long as it runs).
const FOXGLOVE: &str = "gui_bridge (Foxglove)";
/// gui_bridge's calibration wizard (it drives the servos while compute_ik's `calibration`
/// controller is active, and shows a leader arm beside the follower).
const CALIBRATION: &str = "gui_bridge (calibration)";
/// serial_node in the leader role (`-p role:=leader`, README "A leader arm"): it reads a
/// leader arm on the PC or on the Pi, wherever the leader's cable goes.
pub const LEADER_READER: &str = "serial_node (leader)";

/// Desired position of `tool0`, metres, in `header.frame_id`.
pub const XYZ_TARGET: Topic<PointStamped> = Topic::new_target("xyz_target", &[GUI]);
/// Desired position of the tool, reached along a straight line (refused if any point
/// of the line is out of reach), whatever compute_ik's `motion`.
pub const XYZ_LINE_TARGET: Topic<PointStamped> = Topic::new_target("xyz_line_target", &[GUI]);
/// Desired pose of the tip link (arms with orientation, `ros2 topic pub`).
pub const POSE_TARGET: Topic<PoseStamped> = Topic::new_target("pose_target", &[]);
/// Claw opening, 0.0 closed … 1.0 open.
pub const GRIPPER_TARGET: Topic<Float64> = Topic::new_target("gripper_target", &[GUI, REPLAY]);
/// Joint mode: positions of named actuated joints, rad.
pub const JOINT_TARGET: Topic<JointState> = Topic::new_target("joint_target", &[GUI]);
/// Emergency stop, latched: `true` = no servo moves until `false`.
pub const ESTOP: Topic<Bool> = Topic::new("estop", qos::ESTOP, &[GUI], &[IK, SERIAL, GUI]);
/// Every non-fixed URDF joint, rad.
pub const JOINT_STATES: Topic<JointState> = Topic::new(
    "joint_states",
    qos::COMMANDS,
    &[IK],
    &[STATE, GUI, RECORD, RECORDER],
);
/// Servo horn angles after calibration, rad.
pub const SERVO_ANGLES: Topic<JointState> = Topic::new(
    "servo_angles",
    qos::COMMANDS,
    &[IK, CALIBRATION],
    &[SERIAL, FOXGLOVE],
);
/// What the Arduino reports it applied, rad.
pub const SERVO_STATE: Topic<JointState> = Topic::new(
    "servo_state",
    qos::COMMANDS,
    &[SERIAL],
    &[GUI, IK, RECORD, RECORDER],
);
/// The URDF text, latched.
pub const ROBOT_DESCRIPTION: Topic<StringMsg> = Topic::new(
    "robot_description",
    qos::ROBOT_DESCRIPTION,
    &[STATE],
    &[GUI, RECORD],
);
/// Transforms of the movable joints, and the twin's frame `cube` (the panel's 3D view shows it).
pub const TF: Topic<TFMessage> =
    Topic::new("tf", qos::TF, &[STATE, TWIN], &[GUI, RECORD, FOXGLOVE]);
/// Transforms of the fixed joints, latched.
pub const TF_STATIC: Topic<TFMessage> =
    Topic::new("tf_static", qos::TF_STATIC, &[STATE], &[RECORD, FOXGLOVE]);
/// Each node's health.
pub const DIAGNOSTICS: Topic<DiagnosticArray> = Topic::new(
    "diagnostics",
    qos::DIAGNOSTICS,
    &[GUI, IK, SERIAL, STATE, CAMERA, RECORDER],
    &[GUI],
);

/// arm_controller's trajectory topic (ros2_controllers' joint_trajectory_controller
/// name): a trajectory to execute now, replacing any running one. compute_ik has it when
/// its arm has controllers.
pub const JOINT_TRAJECTORY: Topic<JointTrajectory> =
    Topic::new("arm_controller/joint_trajectory", qos::COMMANDS, &[], &[IK]).off_foxglove();
/// arm_controller's state: reference, feedback (servo_state), error and output.
pub const CONTROLLER_STATE: Topic<JointTrajectoryControllerState> =
    Topic::new("arm_controller/controller_state", qos::COMMANDS, &[IK], &[]).off_foxglove();
/// A leader arm's joints ([`LEADER_READER`]), in the follower's joint convention;
/// compute_ik follows them while [`LEADER_DEADMAN`] is held, gui_bridge shows them.
pub const LEADER_JOINT_STATES: Topic<JointState> = Topic::new(
    "leader/joint_states",
    qos::COMMANDS,
    &[LEADER_READER],
    &[IK, GUI, RECORDER],
)
.off_foxglove();
/// The leader arm's deadman button: `true` while held, with every leader sample.
pub const LEADER_DEADMAN: Topic<Bool> = Topic::new(
    "leader/deadman",
    qos::COMMANDS,
    &[LEADER_READER],
    &[IK, GUI, RECORDER],
)
.off_foxglove();

/// A camera's images, JPEG (`format` `jpeg`), stamped when the frame was taken, with
/// `frame_id` the camera's frame; several cameras by node namespace
/// (`-r __ns:=/wrist`: `/wrist/camera/image_raw/compressed`). Sensor-data QoS
/// ([`qos::SENSOR_DATA`]). No Foxglove channel; the panel's camera view shows it with
/// gui_bridge's `-p camera_view:=camera/image_raw/compressed`.
pub const CAMERA_IMAGE: Topic<CompressedImage> = Topic::new(
    "camera/image_raw/compressed",
    qos::SENSOR_DATA,
    &[CAMERA],
    &[RECORDER],
)
.off_foxglove();
/// The camera's [`CameraInfo`] for each image, with the image's header (size; an
/// uncalibrated camera's zero matrices).
pub const CAMERA_INFO: Topic<CameraInfo> =
    Topic::new("camera/camera_info", qos::SENSOR_DATA, &[CAMERA], &[]).off_foxglove();

/// The physics twin's joints as its physics has them: every movable URDF joint, passive
/// ones included (rad, rad/s), what the arm in MuJoCo really does where `joint_states`
/// is what compute_ik commands. The twin's tf frame `cube` (on `tf`) is its cube.
pub const TWIN_JOINT_STATES: Topic<JointState> =
    Topic::new("twin/joint_states", qos::COMMANDS, &[TWIN], &[]).off_foxglove();
/// The twin's camera (the scene camera of its model), JPEG, the message `camera_node`
/// sends: the recorder and the panel take it as a real camera (gui_bridge's small
/// camera view, its `camera_view` by default).
pub const TWIN_CAMERA_IMAGE: Topic<CompressedImage> = Topic::new(
    "twin/camera/image_raw/compressed",
    qos::SENSOR_DATA,
    &[TWIN],
    &[RECORDER, GUI],
)
.off_foxglove();
/// The twin camera's [`CameraInfo`], with each image's header (its pinhole model from
/// the camera's field of view).
pub const TWIN_CAMERA_INFO: Topic<CameraInfo> =
    Topic::new("twin/camera/camera_info", qos::SENSOR_DATA, &[TWIN], &[]).off_foxglove();

/// One action or service of the contract: its name, its type, the nodes of ours that
/// serve it and those that call it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Callable {
    /// An action (`<name>/_action/send_goal`, …) or a service.
    pub kind: CallableKind,
    /// The name, relative to the node's namespace (`controller_manager/list_controllers`).
    pub name: &'static str,
    /// The type's package (`control_msgs`).
    pub package: &'static str,
    /// The type's name in its package (`FollowJointTrajectory`).
    pub type_name: &'static str,
    /// The nodes of ours that serve it.
    pub servers: &'static [&'static str],
    /// The nodes of ours that call it (empty: only outside tools do).
    pub clients: &'static [&'static str],
}

/// Whether a [`Callable`] is an action or a service.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CallableKind {
    /// A ROS 2 action: three services and two topics under `<name>/_action/`.
    Action,
    /// A ROS 2 service.
    Service,
}

impl Callable {
    /// The type as `ros2 action list -t` / `ros2 service list -t` print it
    /// (`control_msgs/action/FollowJointTrajectory`).
    pub fn type_text(&self) -> String {
        let kind = match self.kind {
            CallableKind::Action => "action",
            CallableKind::Service => "srv",
        };
        format!("{}/{kind}/{}", self.package, self.type_name)
    }
}

/// arm_controller's FollowJointTrajectory action (MoveIt's, `ros2 action send_goal`'s).
pub const FOLLOW_JOINT_TRAJECTORY: Callable = Callable {
    kind: CallableKind::Action,
    name: "arm_controller/follow_joint_trajectory",
    package: "control_msgs",
    type_name: "FollowJointTrajectory",
    servers: &[IK],
    clients: &[REPLAY],
};
/// gripper_controller's GripperCommand action.
pub const GRIPPER_CMD: Callable = Callable {
    kind: CallableKind::Action,
    name: "gripper_controller/gripper_cmd",
    package: "control_msgs",
    type_name: "GripperCommand",
    servers: &[IK],
    clients: &[],
};
/// ros2_control's controller manager: which controllers there are, active or not, and
/// what they claim.
pub const LIST_CONTROLLERS: Callable = Callable {
    kind: CallableKind::Service,
    name: "controller_manager/list_controllers",
    package: "controller_manager_msgs",
    type_name: "ListControllers",
    servers: &[IK],
    clients: &[CALIBRATION],
};
/// ros2_control's controller manager: activate and deactivate controllers.
pub const SWITCH_CONTROLLER: Callable = Callable {
    kind: CallableKind::Service,
    name: "controller_manager/switch_controller",
    package: "controller_manager_msgs",
    type_name: "SwitchController",
    servers: &[IK],
    clients: &[CALIBRATION],
};

/// The recorder's episode services (std_srvs/srv/Trigger): start an episode of the
/// `task` parameter's task.
pub const START_EPISODE: Callable = Callable {
    kind: CallableKind::Service,
    name: "recorder/start_episode",
    package: "std_srvs",
    type_name: "Trigger",
    servers: &[RECORDER],
    clients: &[GUI],
};
/// End the episode and keep it (written to the dataset).
pub const SAVE_EPISODE: Callable = Callable {
    kind: CallableKind::Service,
    name: "recorder/save_episode",
    package: "std_srvs",
    type_name: "Trigger",
    servers: &[RECORDER],
    clients: &[GUI],
};
/// End the episode and throw it away.
pub const DISCARD_EPISODE: Callable = Callable {
    kind: CallableKind::Service,
    name: "recorder/discard_episode",
    package: "std_srvs",
    type_name: "Trigger",
    servers: &[RECORDER],
    clients: &[GUI],
};

/// Every action and service of the contract (besides the parameter services every node
/// has), in the order of the docs' table.
pub const CALLABLES: &[Callable] = &[
    FOLLOW_JOINT_TRAJECTORY,
    GRIPPER_CMD,
    LIST_CONTROLLERS,
    SWITCH_CONTROLLER,
    START_EPISODE,
    SAVE_EPISODE,
    DISCARD_EPISODE,
];

/// Something done with each typed topic of the contract ([`visit_all`]): for code that
/// needs the message type, e.g. to subscribe a topic chosen by name.
pub trait TopicVisitor {
    /// Called once for each topic.
    fn visit<M: RosMessage>(&mut self, topic: &Topic<M>);
}

/// Every topic of the contract, typed, in the order of the docs' topic table.
pub fn visit_all(v: &mut impl TopicVisitor) {
    macro_rules! each {
        ($($topic:ident),*) => {$(v.visit(&$topic);)*};
    }
    each!(
        XYZ_TARGET,
        XYZ_LINE_TARGET,
        POSE_TARGET,
        GRIPPER_TARGET,
        JOINT_TARGET,
        ESTOP,
        JOINT_STATES,
        SERVO_ANGLES,
        SERVO_STATE,
        ROBOT_DESCRIPTION,
        TF,
        TF_STATIC,
        DIAGNOSTICS,
        JOINT_TRAJECTORY,
        CONTROLLER_STATE,
        LEADER_JOINT_STATES,
        LEADER_DEADMAN,
        CAMERA_IMAGE,
        CAMERA_INFO,
        TWIN_JOINT_STATES,
        TWIN_CAMERA_IMAGE,
        TWIN_CAMERA_INFO
    );
}

/// Every topic of the contract ([`visit_all`]'s order).
pub fn all() -> Vec<TopicEntry> {
    struct Entries(Vec<TopicEntry>);
    impl TopicVisitor for Entries {
        fn visit<M: RosMessage>(&mut self, topic: &Topic<M>) {
            self.0.push(topic.entry());
        }
    }
    let mut entries = Entries(Vec::new());
    visit_all(&mut entries);
    entries.0
}

fn reliability_text(qos: &QosProfile) -> &'static str {
    match qos.reliability {
        Reliability::Reliable { .. } => "reliable",
        Reliability::BestEffort => "best effort",
    }
}

fn durability_text(qos: &QosProfile) -> &'static str {
    match qos.durability {
        Durability::Volatile => "volatile",
        Durability::TransientLocal => "transient-local",
    }
}

fn depth(qos: &QosProfile) -> Option<usize> {
    match qos.history {
        History::KeepLast { depth } => Some(depth),
        History::KeepAll => None,
    }
}

/// A QoS as the topic table writes it:
/// `reliable, transient-local, keep last 1`.
pub fn qos_text(qos: &QosProfile) -> String {
    let history = depth(qos).map_or_else(|| "keep all".to_string(), |d| format!("keep last {d}"));
    format!(
        "{}, {}, {history}",
        reliability_text(qos),
        durability_text(qos)
    )
}

fn json_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn json_list(items: &[&str]) -> String {
    let items: Vec<String> = items.iter().map(|s| json_string(s)).collect();
    format!("[{}]", items.join(", "))
}

/// The tables as JSON, one topic, action or service per line, as `tests/data/topics.json`
/// holds them: `{"topics": [{"name", "type", "reliability", "durability", "depth", "qos",
/// "publishers", "subscribers", "latched", "target", "recorded", "foxglove"}, …],
/// "actions": [{"name", "type", "servers", "clients"}, …], "services": […]}` (`depth`
/// null for keep all).
pub fn json(entries: &[TopicEntry], callables: &[Callable]) -> String {
    let rows: Vec<String> = entries
        .iter()
        .map(|e| {
            format!(
                "    {{\"name\": {}, \"type\": {}, \"reliability\": {}, \"durability\": {}, \"depth\": {}, \"qos\": {}, \"publishers\": {}, \"subscribers\": {}, \"latched\": {}, \"target\": {}, \"recorded\": {}, \"foxglove\": {}}}",
                json_string(e.name),
                json_string(&e.type_name),
                json_string(reliability_text(&e.qos)),
                json_string(durability_text(&e.qos)),
                depth(&e.qos).map_or_else(|| "null".to_string(), |d| d.to_string()),
                json_string(&qos_text(&e.qos)),
                json_list(e.publishers),
                json_list(e.subscribers),
                e.latched(),
                e.target,
                e.recorded(),
                e.foxglove,
            )
        })
        .collect();
    let callables_of = |kind: CallableKind| -> String {
        callables
            .iter()
            .filter(|c| c.kind == kind)
            .map(|c| {
                format!(
                    "    {{\"name\": {}, \"type\": {}, \"servers\": {}, \"clients\": {}}}",
                    json_string(c.name),
                    json_string(&c.type_text()),
                    json_list(c.servers),
                    json_list(c.clients),
                )
            })
            .collect::<Vec<_>>()
            .join(",\n")
    };
    format!(
        "{{\"topics\": [\n{}\n],\n\"actions\": [\n{}\n],\n\"services\": [\n{}\n]}}\n",
        rows.join(",\n"),
        callables_of(CallableKind::Action),
        callables_of(CallableKind::Service),
    )
}

fn nodes_text(nodes: &[&str]) -> String {
    if nodes.is_empty() {
        "(outside tools)".to_string()
    } else {
        nodes
            .iter()
            .map(|n| match n.split_once(' ') {
                Some((node, how)) => format!("`{node}` {how}"),
                None => format!("`{n}`"),
            })
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The topic table as docs/topics.md shows it:
/// `| topic | type | QoS | publishers | subscribers |`.
pub fn markdown_table(entries: &[TopicEntry]) -> String {
    let mut s =
        String::from("| topic | type | QoS | publishers | subscribers |\n|---|---|---|---|---|\n");
    for e in entries {
        let _ = writeln!(
            s,
            "| `{}` | `{}` | {} | {} | {} |",
            e.name,
            e.type_name,
            qos_text(&e.qos),
            nodes_text(e.publishers),
            nodes_text(e.subscribers)
        );
    }
    s
}

/// The actions and services as docs/topics.md shows them:
/// `| action or service | type | served by | called by |`.
pub fn callables_table(callables: &[Callable]) -> String {
    let mut s =
        String::from("| action or service | type | served by | called by |\n|---|---|---|---|\n");
    for c in callables {
        let _ = writeln!(
            s,
            "| `{}` | `{}` | {} | {} |",
            c.name,
            c.type_text(),
            nodes_text(c.servers),
            nodes_text(c.clients)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_every_node_is_ours() {
        let all = all();
        let mut names: Vec<_> = all.iter().map(|e| e.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), all.len());
        for e in &all {
            for n in e.publishers.iter().chain(e.subscribers) {
                let node = n.split(' ').next().unwrap_or_default();
                assert!(
                    [GUI, IK, SERIAL, STATE, CAMERA, RECORDER, TWIN].contains(&node),
                    "{}: {n}",
                    e.name
                );
            }
        }
        let mut callables: Vec<_> = CALLABLES.iter().map(|c| c.name).collect();
        callables.sort_unstable();
        callables.dedup();
        assert_eq!(callables.len(), CALLABLES.len());
        for c in CALLABLES {
            assert!(
                !c.servers.is_empty(),
                "{}: served by a node of ours",
                c.name
            );
            assert!(!names.contains(&c.name), "{} is a topic too", c.name);
            for n in c.servers.iter().chain(c.clients) {
                let node = n.split(' ').next().unwrap_or_default();
                assert!(
                    [GUI, IK, SERIAL, STATE, CAMERA, RECORDER, TWIN].contains(&node),
                    "{}: {n}",
                    c.name
                );
            }
        }
    }

    #[test]
    fn callables_have_their_ros_type_text() {
        assert_eq!(
            FOLLOW_JOINT_TRAJECTORY.type_text(),
            "control_msgs/action/FollowJointTrajectory"
        );
        assert_eq!(
            SWITCH_CONTROLLER.type_text(),
            "controller_manager_msgs/srv/SwitchController"
        );
        let table = callables_table(CALLABLES);
        assert!(table.contains(
            "| `controller_manager/list_controllers` | `controller_manager_msgs/srv/ListControllers` | `compute_ik` | `gui_bridge` (calibration) |"
        ), "{table}");
        let json = json(&[], CALLABLES);
        assert!(
            json.contains(
                "\"actions\": [\n    {\"name\": \"arm_controller/follow_joint_trajectory\""
            ),
            "{json}"
        );
    }

    #[test]
    fn json_escapes() {
        assert_eq!(json_string("a\"b\\c\n"), "\"a\\\"b\\\\c\\u000a\"");
    }
}
