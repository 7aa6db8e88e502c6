//! The topic contract ([`ros_plumbing::topics`]) and its copies cannot drift:
//! `tests/data/topics.json` (read by the Python tests), the topic table of the docs,
//! Foxglove's channels (`foxglove_bridge::TOPICS`: the topics with `foxglove`), and the
//! QoS as the written contract states it.

use ros_plumbing::topics;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn the_python_tests_read_the_same_topic_table() {
    let want = topics::json(&topics::all(), topics::CALLABLES);
    assert!(
        read(&repo().join("tests/data/topics.json")) == want,
        "tests/data/topics.json is stale; regenerate it:\n  \
         cargo run -q -p ros_plumbing --example topics -- --json > tests/data/topics.json"
    );
}

/// The header of the rendered topic table.
const TABLE_HEADER: &str = "| topic | type | QoS | publishers | subscribers |";

/// The repository's own docs that hold the topic table (README.md, docs/*.md).
fn docs_with_the_topic_table() -> Vec<(PathBuf, String)> {
    let mut files = vec![repo().join("README.md")];
    if let Ok(dir) = std::fs::read_dir(repo().join("docs")) {
        files.extend(
            dir.filter_map(Result::ok)
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x == "md")),
        );
    }
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let text = read(&p);
            (p, text)
        })
        .filter(|(_, text)| text.contains(TABLE_HEADER))
        .collect()
}

#[test]
fn the_docs_topic_table_is_the_contract() {
    let docs = docs_with_the_topic_table();
    assert!(
        !docs.is_empty(),
        "no topic table in README.md or docs/*.md (a line `{TABLE_HEADER}`)"
    );
    let want = topics::markdown_table(&topics::all());
    for (path, text) in docs {
        assert!(
            text.contains(&want),
            "{}'s topic table differs from ros_plumbing::topics; it should read:\n\n{want}\n\
             (cargo run -q -p ros_plumbing --example topics -- --markdown)",
            path.display()
        );
    }
}

/// The rows of the first topic table in `text`: topic name → the row's cells.
fn table_rows(text: &str) -> Vec<(String, Vec<String>)> {
    text.lines()
        .skip_while(|l| !l.starts_with(TABLE_HEADER))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let cells: Vec<String> = l
                .trim_matches('|')
                .split('|')
                .map(|c| c.trim().trim_matches('`').to_string())
                .collect();
            (cells[0].clone(), cells)
        })
        .collect()
}

#[test]
fn every_topic_of_the_contract_is_written_in_the_docs_with_its_type_and_qos() {
    for (path, text) in docs_with_the_topic_table() {
        let rows = table_rows(&text);
        let contract = topics::all();
        for t in &contract {
            let row = rows
                .iter()
                .find(|(name, _)| name == t.name)
                .map(|(_, cells)| cells)
                .unwrap_or_else(|| panic!("{}: no row for {}", path.display(), t.name));
            assert_eq!(row[1], t.type_name, "{}: {}'s type", path.display(), t.name);
            assert_eq!(
                row[2],
                topics::qos_text(&t.qos),
                "{}: {}'s QoS",
                path.display(),
                t.name
            );
        }
        for (name, _) in &rows {
            assert!(
                contract.iter().any(|t| t.name == name),
                "{}: {name} is not a topic of the contract",
                path.display()
            );
        }
    }
}

/// The topics, types and QoS as the project's written interface contract states them
/// (its topic table), transcribed here: an independent reference, so that a QoS
/// changed in topics.rs fails here even when the generated table and topics.json are
/// regenerated with it. `None`: the contract leaves it open (volatile is DDS' default
/// durability; the contract gives no depth for `tf`, `tf_static` and `diagnostics`).
/// `xyz_line_target` is this project's addition (issue 33: a line move without a
/// parameter switched first), with `xyz_target`'s type and QoS.
/// (topic, type, reliability, durability, depth)
type Written = (
    &'static str,
    &'static str,
    &'static str,
    Option<&'static str>,
    Option<usize>,
);
const WRITTEN: &[Written] = &[
    (
        "xyz_target",
        "geometry_msgs/msg/PointStamped",
        "reliable",
        Some("volatile"),
        Some(10),
    ),
    (
        "xyz_line_target",
        "geometry_msgs/msg/PointStamped",
        "reliable",
        Some("volatile"),
        Some(10),
    ),
    (
        "pose_target",
        "geometry_msgs/msg/PoseStamped",
        "reliable",
        None,
        Some(10),
    ),
    (
        "gripper_target",
        "std_msgs/msg/Float64",
        "reliable",
        None,
        Some(10),
    ),
    (
        "joint_target",
        "sensor_msgs/msg/JointState",
        "reliable",
        None,
        Some(10),
    ),
    (
        "estop",
        "std_msgs/msg/Bool",
        "reliable",
        Some("transient-local"),
        Some(1),
    ),
    (
        "joint_states",
        "sensor_msgs/msg/JointState",
        "reliable",
        None,
        Some(10),
    ),
    (
        "servo_angles",
        "sensor_msgs/msg/JointState",
        "reliable",
        None,
        Some(10),
    ),
    (
        "servo_state",
        "sensor_msgs/msg/JointState",
        "reliable",
        None,
        Some(10),
    ),
    (
        "robot_description",
        "std_msgs/msg/String",
        "reliable",
        Some("transient-local"),
        Some(1),
    ),
    (
        "tf",
        "tf2_msgs/msg/TFMessage",
        "reliable",
        Some("volatile"),
        None,
    ),
    (
        "tf_static",
        "tf2_msgs/msg/TFMessage",
        "reliable",
        Some("transient-local"),
        None,
    ),
    (
        "diagnostics",
        "diagnostic_msgs/msg/DiagnosticArray",
        "reliable",
        None,
        None,
    ),
];

/// The topics of [`topics::all`] besides [`WRITTEN`], with their types: the trajectory
/// topics (which the written contract names outside its QoS table), the leader
/// arm's (whose names it leaves to the implementation), the camera's (named with their
/// types under "Cameras"; their QoS is ROS's sensor-data profile, `qos::SENSOR_DATA`) and
/// the physics twin's (named under "Physics twin": its joints as `joint_states` are, its
/// camera as `camera_node`'s).
const WRITTEN_WITHOUT_QOS: &[(&str, &str)] = &[
    (
        "arm_controller/joint_trajectory",
        "trajectory_msgs/msg/JointTrajectory",
    ),
    (
        "arm_controller/controller_state",
        "control_msgs/msg/JointTrajectoryControllerState",
    ),
    ("leader/joint_states", "sensor_msgs/msg/JointState"),
    ("leader/deadman", "std_msgs/msg/Bool"),
    (
        "camera/image_raw/compressed",
        "sensor_msgs/msg/CompressedImage",
    ),
    ("camera/camera_info", "sensor_msgs/msg/CameraInfo"),
    ("twin/joint_states", "sensor_msgs/msg/JointState"),
    (
        "twin/camera/image_raw/compressed",
        "sensor_msgs/msg/CompressedImage",
    ),
    ("twin/camera/camera_info", "sensor_msgs/msg/CameraInfo"),
];

#[test]
fn the_qos_is_the_written_contracts() {
    let all = topics::all();
    let (contract, others): (Vec<_>, Vec<_>) = all
        .iter()
        .partition(|t| WRITTEN.iter().any(|w| w.0 == t.name));
    assert_eq!(
        contract.iter().map(|t| t.name).collect::<Vec<_>>(),
        WRITTEN.iter().map(|w| w.0).collect::<Vec<_>>(),
        "the topics of the contract"
    );
    assert_eq!(
        others
            .iter()
            .map(|t| (t.name, t.type_name.as_str()))
            .collect::<Vec<_>>(),
        WRITTEN_WITHOUT_QOS,
        "the topics beyond the written contract's table"
    );
    for (t, &(name, type_name, reliability, durability, depth)) in contract.iter().zip(WRITTEN) {
        let qos = topics::qos_text(&t.qos); // "reliable, transient-local, keep last 1"
        let parts: Vec<&str> = qos.split(", ").collect();
        assert_eq!(t.type_name, type_name, "{name}'s type");
        assert_eq!(parts[0], reliability, "{name}'s reliability");
        // a durability the contract leaves open is DDS' default, volatile
        assert_eq!(
            parts[1],
            durability.unwrap_or("volatile"),
            "{name}'s durability"
        );
        if let Some(depth) = depth {
            assert_eq!(parts[2], format!("keep last {depth}"), "{name}'s history");
        }
    }
}

#[test]
fn foxglove_channels_are_the_contract() {
    let contract: Vec<_> = topics::all().into_iter().filter(|t| t.foxglove).collect();
    assert_eq!(
        foxglove_bridge::TOPICS.len(),
        contract.len(),
        "a Foxglove channel for every topic that has one"
    );
    for spec in foxglove_bridge::TOPICS {
        let t = contract
            .iter()
            .find(|t| t.name == spec.topic)
            .unwrap_or_else(|| panic!("Foxglove channel {} is not a topic", spec.topic));
        assert_eq!(spec.type_name, t.type_name, "{}'s type", t.name);
        assert_eq!(
            spec.latched,
            topics::qos_text(&t.qos).contains("transient-local"),
            "{}: latched is transient-local",
            t.name
        );
        assert_eq!(spec.target, t.target, "{}: target", t.name);
        assert_eq!(
            spec.recorded,
            t.subscribers.contains(&"gui_bridge (record)"),
            "{}: recorded is what `gui_bridge record` subscribes",
            t.name
        );
    }
    // the roles as the docs describe them: the operator targets
    let targets: Vec<&str> = foxglove_bridge::TOPICS
        .iter()
        .filter(|s| s.target)
        .map(|s| s.topic)
        .collect();
    assert_eq!(
        targets,
        [
            "xyz_target",
            "xyz_line_target",
            "pose_target",
            "gripper_target",
            "joint_target"
        ]
    );
}
