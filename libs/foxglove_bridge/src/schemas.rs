//! The graph's topics and their `ros2msg` schemas.
//!
//! A `ros2msg` schema (the format of rosbag2's MCAP files and of the Foxglove WebSocket
//! protocol) is the message's `.msg` definition followed, for every message type it
//! uses directly or indirectly, by a line of 80 `=`, a line `MSG: pkg/Type` and that
//! type's definition. The definitions below are those of ROS 2's `std_msgs`,
//! `builtin_interfaces`, `geometry_msgs`, `sensor_msgs`, `tf2_msgs` and `diagnostic_msgs`
//! with comments and blank lines removed (field order, types, constants and default
//! values as upstream).

use ros_plumbing::topics;
use std::sync::LazyLock;

/// One message type: its name (`pkg/msg/Type`), its `.msg` text and the types it uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageDefinition {
    /// `pkg/msg/Type`, as ROS 2 and Foxglove name it.
    pub name: &'static str,
    /// The `.msg` text (no comments).
    pub text: &'static str,
    /// The message types its fields use (`pkg/msg/Type`).
    pub uses: &'static [&'static str],
}

/// The message types: each a `pub const` documented with its name (and a note in
/// parentheses), and [`DEFINITIONS`], every one of them in this order.
macro_rules! definitions {
    ($($constant:ident $(($note:literal))? = $name:literal, $text:literal, [$($uses:literal),*];)*) => {
        $(
            #[doc = concat!("`", $name, "`", $(" (", $note, ")",)? ".")]
            pub const $constant: MessageDefinition = MessageDefinition {
                name: $name,
                text: $text,
                uses: &[$($uses),*],
            };
        )*

        /// Every message type the graph's topics use, directly or in a field.
        pub const DEFINITIONS: &[MessageDefinition] = &[$($constant),*];
    };
}

definitions! {
    TIME = "builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n", [];
    HEADER = "std_msgs/msg/Header", "builtin_interfaces/Time stamp\nstring frame_id\n", ["builtin_interfaces/msg/Time"];
    STRING = "std_msgs/msg/String", "string data\n", [];
    FLOAT64 = "std_msgs/msg/Float64", "float64 data\n", [];
    BOOL = "std_msgs/msg/Bool", "bool data\n", [];
    VECTOR3 = "geometry_msgs/msg/Vector3", "float64 x\nfloat64 y\nfloat64 z\n", [];
    POINT = "geometry_msgs/msg/Point", "float64 x\nfloat64 y\nfloat64 z\n", [];
    QUATERNION ("default values as upstream: the identity") = "geometry_msgs/msg/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n", [];
    POSE = "geometry_msgs/msg/Pose", "Point position\nQuaternion orientation\n", ["geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"];
    TRANSFORM = "geometry_msgs/msg/Transform", "Vector3 translation\nQuaternion rotation\n", ["geometry_msgs/msg/Vector3", "geometry_msgs/msg/Quaternion"];
    TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped", "std_msgs/Header header\nstring child_frame_id\nTransform transform\n", ["std_msgs/msg/Header", "geometry_msgs/msg/Transform"];
    POINT_STAMPED = "geometry_msgs/msg/PointStamped", "std_msgs/Header header\nPoint point\n", ["std_msgs/msg/Header", "geometry_msgs/msg/Point"];
    POSE_STAMPED = "geometry_msgs/msg/PoseStamped", "std_msgs/Header header\nPose pose\n", ["std_msgs/msg/Header", "geometry_msgs/msg/Pose"];
    TF_MESSAGE = "tf2_msgs/msg/TFMessage", "geometry_msgs/TransformStamped[] transforms\n", ["geometry_msgs/msg/TransformStamped"];
    JOINT_STATE = "sensor_msgs/msg/JointState", "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n", ["std_msgs/msg/Header"];
    KEY_VALUE = "diagnostic_msgs/msg/KeyValue", "string key\nstring value\n", [];
    DIAGNOSTIC_STATUS = "diagnostic_msgs/msg/DiagnosticStatus", "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n", ["diagnostic_msgs/msg/KeyValue"];
    DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray", "std_msgs/Header header\nDiagnosticStatus[] status\n", ["std_msgs/msg/Header", "diagnostic_msgs/msg/DiagnosticStatus"];
}

/// The definition of `pkg/msg/Type`, if it is one of [`DEFINITIONS`].
pub fn definition(type_name: &str) -> Option<&'static MessageDefinition> {
    DEFINITIONS.iter().find(|d| d.name == type_name)
}

/// The separator line before each dependency of a `ros2msg` schema: 80 `=`.
pub const SEPARATOR: &str =
    "================================================================================";

/// The full `ros2msg` schema text of `pkg/msg/Type`: its definition, then each type it
/// uses (depth first, each once) after [`SEPARATOR`] and `MSG: pkg/Type`.
///
/// # Examples
/// ```
/// let text = foxglove_bridge::schemas::ros2msg_schema("geometry_msgs/msg/PointStamped").unwrap();
/// assert!(text.starts_with("std_msgs/Header header\nPoint point\n"));
/// assert!(text.contains("\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"));
/// ```
pub fn ros2msg_schema(type_name: &str) -> Option<String> {
    let top = definition(type_name)?;
    let mut text = top.text.to_string();
    let mut done = vec![top.name];
    let mut stack: Vec<&str> = top.uses.iter().rev().copied().collect();
    while let Some(name) = stack.pop() {
        if done.contains(&name) {
            continue;
        }
        let d = definition(name)?;
        done.push(d.name);
        text.push_str(SEPARATOR);
        text.push_str("\nMSG: ");
        text.push_str(&d.name.replacen("/msg/", "/", 1));
        text.push('\n');
        text.push_str(d.text);
        stack.extend(d.uses.iter().rev().copied());
    }
    Some(text)
}

/// What a topic of the graph carries and how the bridge treats it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicSpec {
    /// The topic's name relative to the node's namespace (`tf`, `xyz_target`, …).
    pub topic: &'static str,
    /// Its message type, `pkg/msg/Type`.
    pub type_name: &'static str,
    /// Published transient-local (the last sample is given to late subscribers).
    pub latched: bool,
    /// An operator target: something a Foxglove panel may publish and a recording replays.
    pub target: bool,
    /// Written into a recording (targets and what it takes to view the session again).
    pub recorded: bool,
}

impl TopicSpec {
    /// The spec of a topic of the contract; `None` for a message type without a
    /// definition here (`every_topic_and_every_dependency_has_a_definition` fails then).
    fn of(entry: &topics::TopicEntry) -> Option<TopicSpec> {
        Some(TopicSpec {
            topic: entry.name,
            type_name: definition(&entry.type_name)?.name,
            latched: entry.latched(),
            target: entry.target,
            recorded: entry.recorded(),
        })
    }
}

/// Every topic of the graph with a Foxglove channel: the topic contract's
/// (`ros_plumbing::topics::all()`) with `foxglove`, in its order. Iterate it (`for spec in TOPICS`) or use it as a slice (`TOPICS.iter()`,
/// `TOPICS.len()`).
pub const TOPICS: Topics = Topics;

/// The type of [`TOPICS`]: the table, built from the contract on first use.
#[derive(Debug, Clone, Copy)]
pub struct Topics;

static TABLE: LazyLock<Vec<TopicSpec>> = LazyLock::new(|| {
    topics::all()
        .iter()
        .filter(|t| t.foxglove)
        .filter_map(TopicSpec::of)
        .collect()
});

impl std::ops::Deref for Topics {
    type Target = [TopicSpec];
    fn deref(&self) -> &[TopicSpec] {
        &TABLE
    }
}

impl IntoIterator for Topics {
    type Item = &'static TopicSpec;
    type IntoIter = std::slice::Iter<'static, TopicSpec>;
    fn into_iter(self) -> Self::IntoIter {
        TABLE.iter()
    }
}

/// The spec of a topic of the graph, by its relative name.
pub fn topic_spec(topic: &str) -> Option<&'static TopicSpec> {
    TABLE.iter().find(|t| t.topic == topic)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_topic_and_every_dependency_has_a_definition() {
        let channels: Vec<_> = topics::all().into_iter().filter(|t| t.foxglove).collect();
        for t in &channels {
            assert!(ros2msg_schema(&t.type_name).is_some(), "{}", t.type_name);
        }
        assert_eq!(TOPICS.len(), channels.len());
        for d in DEFINITIONS {
            for u in d.uses {
                assert!(definition(u).is_some(), "{} uses {u}", d.name);
            }
        }
    }

    #[test]
    fn tf_message_schema_lists_each_dependency_once_in_rosbag2_format() {
        let text = ros2msg_schema("tf2_msgs/msg/TFMessage").unwrap();
        let blocks: Vec<&str> = text.split(&format!("{SEPARATOR}\n")).collect();
        assert_eq!(blocks[0], "geometry_msgs/TransformStamped[] transforms\n");
        let names: Vec<&str> = blocks[1..]
            .iter()
            .map(|b| b.lines().next().unwrap())
            .collect();
        assert_eq!(
            names,
            [
                "MSG: geometry_msgs/TransformStamped",
                "MSG: std_msgs/Header",
                "MSG: builtin_interfaces/Time",
                "MSG: geometry_msgs/Transform",
                "MSG: geometry_msgs/Vector3",
                "MSG: geometry_msgs/Quaternion",
            ]
        );
    }

    #[test]
    fn a_type_without_dependencies_is_its_definition_alone() {
        assert_eq!(
            ros2msg_schema("std_msgs/msg/String").as_deref(),
            Some("string data\n")
        );
        assert_eq!(ros2msg_schema("nope/msg/Nope"), None);
    }
}
