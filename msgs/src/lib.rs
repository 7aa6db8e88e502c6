#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub use ros2_client::builtin_interfaces::Time;
use ros2_client::MessageTypeName;
use serde::{de::DeserializeOwned, Serialize};

pub mod cdr;

/// A message type with its ROS 2 name, so a topic can be created for it.
pub trait RosMessage: Serialize + DeserializeOwned + Clone + Send + Sync + 'static {
    /// ROS package, e.g. `geometry_msgs`.
    const PACKAGE: &'static str;
    /// Type name inside the package, e.g. `PointStamped`.
    const NAME: &'static str;

    /// The type name as ros2-client wants it for a topic.
    fn type_name() -> MessageTypeName {
        MessageTypeName::new(Self::PACKAGE, Self::NAME)
    }

    /// The name `ros2 topic` prints, e.g. `geometry_msgs/msg/PointStamped`.
    fn ros_type_string() -> String {
        format!("{}/msg/{}", Self::PACKAGE, Self::NAME)
    }
}

macro_rules! ros_message {
    ($ty:ty, $pkg:literal, $name:literal) => {
        impl $crate::RosMessage for $ty {
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $name;
        }
        impl ros2_client::Message for $ty {}
    };
}

/// `std_msgs`: <https://github.com/ros2/common_interfaces/tree/rolling/std_msgs/msg>
pub mod std_msgs {
    use super::Time;
    use serde::{Deserialize, Serialize};

    /// [std_msgs/msg/Header](https://github.com/ros2/common_interfaces/blob/rolling/std_msgs/msg/Header.msg)
    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    pub struct Header {
        /// Time of the data or of the request that caused it.
        pub stamp: Time,
        /// Coordinate frame the data is expressed in.
        pub frame_id: std::string::String,
    }

    impl Default for Header {
        fn default() -> Self {
            Header {
                stamp: Time::ZERO,
                frame_id: std::string::String::new(),
            }
        }
    }

    /// [std_msgs/msg/String](https://github.com/ros2/common_interfaces/blob/rolling/std_msgs/msg/String.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct String {
        /// The text.
        pub data: std::string::String,
    }

    /// [std_msgs/msg/Float64](https://github.com/ros2/common_interfaces/blob/rolling/std_msgs/msg/Float64.msg)
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Float64 {
        /// The value.
        pub data: f64,
    }

    /// [std_msgs/msg/Bool](https://github.com/ros2/common_interfaces/blob/rolling/std_msgs/msg/Bool.msg)
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Bool {
        /// The value.
        pub data: bool,
    }

    ros_message!(Header, "std_msgs", "Header");
    ros_message!(String, "std_msgs", "String");
    ros_message!(Float64, "std_msgs", "Float64");
    ros_message!(Bool, "std_msgs", "Bool");
}

/// `geometry_msgs`: <https://github.com/ros2/common_interfaces/tree/rolling/geometry_msgs/msg>
pub mod geometry_msgs {
    use super::std_msgs::Header;
    use serde::{Deserialize, Serialize};

    /// [geometry_msgs/msg/Point](https://github.com/ros2/common_interfaces/blob/rolling/geometry_msgs/msg/Point.msg)
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Point {
        /// x (m)
        pub x: f64,
        /// y (m)
        pub y: f64,
        /// z (m)
        pub z: f64,
    }

    /// [geometry_msgs/msg/PointStamped](https://github.com/ros2/common_interfaces/blob/rolling/geometry_msgs/msg/PointStamped.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct PointStamped {
        /// Stamp and frame of the point.
        pub header: Header,
        /// The point.
        pub point: Point,
    }

    /// [geometry_msgs/msg/Vector3](https://github.com/ros2/common_interfaces/blob/rolling/geometry_msgs/msg/Vector3.msg)
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Vector3 {
        /// x
        pub x: f64,
        /// y
        pub y: f64,
        /// z
        pub z: f64,
    }

    /// [geometry_msgs/msg/Quaternion](https://github.com/ros2/common_interfaces/blob/rolling/geometry_msgs/msg/Quaternion.msg)
    #[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
    pub struct Quaternion {
        /// x
        pub x: f64,
        /// y
        pub y: f64,
        /// z
        pub z: f64,
        /// w
        pub w: f64,
    }

    impl Default for Quaternion {
        /// The identity rotation, as in the `.msg` defaults.
        fn default() -> Self {
            Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }
        }
    }

    /// [geometry_msgs/msg/Transform](https://github.com/ros2/common_interfaces/blob/rolling/geometry_msgs/msg/Transform.msg)
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Transform {
        /// Translation (m).
        pub translation: Vector3,
        /// Rotation.
        pub rotation: Quaternion,
    }

    /// [geometry_msgs/msg/TransformStamped](https://github.com/ros2/common_interfaces/blob/rolling/geometry_msgs/msg/TransformStamped.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct TransformStamped {
        /// Stamp and parent frame.
        pub header: Header,
        /// Child frame.
        pub child_frame_id: String,
        /// Pose of the child frame in the parent frame.
        pub transform: Transform,
    }

    /// [geometry_msgs/msg/Pose](https://github.com/ros2/common_interfaces/blob/rolling/geometry_msgs/msg/Pose.msg)
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Pose {
        /// Position (m).
        pub position: Point,
        /// Orientation.
        pub orientation: Quaternion,
    }

    /// [geometry_msgs/msg/PoseStamped](https://github.com/ros2/common_interfaces/blob/rolling/geometry_msgs/msg/PoseStamped.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct PoseStamped {
        /// Stamp and frame of the pose.
        pub header: Header,
        /// The pose.
        pub pose: Pose,
    }

    ros_message!(Point, "geometry_msgs", "Point");
    ros_message!(Pose, "geometry_msgs", "Pose");
    ros_message!(PoseStamped, "geometry_msgs", "PoseStamped");
    ros_message!(PointStamped, "geometry_msgs", "PointStamped");
    ros_message!(Vector3, "geometry_msgs", "Vector3");
    ros_message!(Quaternion, "geometry_msgs", "Quaternion");
    ros_message!(Transform, "geometry_msgs", "Transform");
    ros_message!(TransformStamped, "geometry_msgs", "TransformStamped");
}

/// `sensor_msgs`: <https://github.com/ros2/common_interfaces/tree/rolling/sensor_msgs/msg>
pub mod sensor_msgs {
    use super::std_msgs::Header;
    use serde::{Deserialize, Serialize};

    /// [sensor_msgs/msg/JointState](https://github.com/ros2/common_interfaces/blob/rolling/sensor_msgs/msg/JointState.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct JointState {
        /// Stamp of the state.
        pub header: Header,
        /// Joint names.
        pub name: Vec<String>,
        /// Positions (rad or m), parallel to `name`; may be empty.
        pub position: Vec<f64>,
        /// Velocities, parallel to `name`; may be empty.
        pub velocity: Vec<f64>,
        /// Efforts, parallel to `name`; may be empty.
        pub effort: Vec<f64>,
    }

    ros_message!(JointState, "sensor_msgs", "JointState");
}

/// `tf2_msgs`: <https://github.com/ros2/geometry2/tree/rolling/tf2_msgs/msg>
pub mod tf2_msgs {
    use super::geometry_msgs::TransformStamped;
    use serde::{Deserialize, Serialize};

    /// [tf2_msgs/msg/TFMessage](https://github.com/ros2/geometry2/blob/rolling/tf2_msgs/msg/TFMessage.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct TFMessage {
        /// The transforms.
        pub transforms: Vec<TransformStamped>,
    }

    ros_message!(TFMessage, "tf2_msgs", "TFMessage");
}

/// `diagnostic_msgs`: <https://github.com/ros2/common_interfaces/tree/rolling/diagnostic_msgs/msg>
pub mod diagnostic_msgs {
    use super::std_msgs::Header;
    use serde::{Deserialize, Serialize};

    /// [diagnostic_msgs/msg/KeyValue](https://github.com/ros2/common_interfaces/blob/rolling/diagnostic_msgs/msg/KeyValue.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct KeyValue {
        /// What the value is.
        pub key: String,
        /// The value, as text.
        pub value: String,
    }

    /// [diagnostic_msgs/msg/DiagnosticStatus](https://github.com/ros2/common_interfaces/blob/rolling/diagnostic_msgs/msg/DiagnosticStatus.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct DiagnosticStatus {
        /// One of [`DiagnosticStatus::OK`] … [`DiagnosticStatus::STALE`] (`byte` in the `.msg`).
        pub level: u8,
        /// What is being reported on, e.g. `compute_ik: inverse kinematics`.
        pub name: String,
        /// A human-readable summary.
        pub message: String,
        /// Which piece of hardware this is about.
        pub hardware_id: String,
        /// Details.
        pub values: Vec<KeyValue>,
    }

    impl DiagnosticStatus {
        /// Everything is fine.
        pub const OK: u8 = 0;
        /// Something is off, the node keeps working.
        pub const WARN: u8 = 1;
        /// Something is wrong.
        pub const ERROR: u8 = 2;
        /// No recent report.
        pub const STALE: u8 = 3;
    }

    /// [diagnostic_msgs/msg/DiagnosticArray](https://github.com/ros2/common_interfaces/blob/rolling/diagnostic_msgs/msg/DiagnosticArray.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct DiagnosticArray {
        /// Stamp of the report.
        pub header: Header,
        /// One entry per reported item.
        pub status: Vec<DiagnosticStatus>,
    }

    ros_message!(KeyValue, "diagnostic_msgs", "KeyValue");
    ros_message!(DiagnosticStatus, "diagnostic_msgs", "DiagnosticStatus");
    ros_message!(DiagnosticArray, "diagnostic_msgs", "DiagnosticArray");
}
