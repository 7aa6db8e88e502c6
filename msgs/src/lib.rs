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

/// A part of an action (goal, result, feedback): no topic of its own.
macro_rules! ros2_client_message {
    ($ty:ty) => {
        impl ros2_client::Message for $ty {}
    };
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

/// `builtin_interfaces`' Duration (Time is ros2-client's): <https://github.com/ros2/rcl_interfaces/tree/rolling/builtin_interfaces/msg>
pub mod builtin_interfaces {
    use serde::{Deserialize, Serialize};

    /// [builtin_interfaces/msg/Duration](https://github.com/ros2/rcl_interfaces/blob/rolling/builtin_interfaces/msg/Duration.msg):
    /// a signed time span, `sec + nanosec·10⁻⁹` (`nanosec` < 10⁹).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
    pub struct Duration {
        /// Whole seconds (may be negative).
        pub sec: i32,
        /// Nanoseconds added to `sec`, 0 … 999 999 999.
        pub nanosec: u32,
    }

    impl Duration {
        /// The span in seconds.
        pub fn as_secs_f64(self) -> f64 {
            f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
        }

        /// The span of `s` seconds, rounded to the nanosecond (saturating at the `i32`
        /// range of `sec`; NaN gives zero).
        pub fn from_secs_f64(s: f64) -> Duration {
            let nanos = (s * 1e9).round();
            let nanos = if nanos.is_nan() {
                0
            } else {
                nanos.clamp(i64::MIN as f64, i64::MAX as f64) as i64
            };
            let sec = nanos.div_euclid(1_000_000_000);
            let nanosec = nanos.rem_euclid(1_000_000_000) as u32;
            match i32::try_from(sec) {
                Ok(sec) => Duration { sec, nanosec },
                Err(_) if sec < 0 => Duration {
                    sec: i32::MIN,
                    nanosec: 0,
                },
                Err(_) => Duration {
                    sec: i32::MAX,
                    nanosec: 999_999_999,
                },
            }
        }
    }

    ros_message!(Duration, "builtin_interfaces", "Duration");
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

    /// [geometry_msgs/msg/Twist](https://github.com/ros2/common_interfaces/blob/rolling/geometry_msgs/msg/Twist.msg)
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Twist {
        /// Linear velocity (m/s).
        pub linear: Vector3,
        /// Angular velocity (rad/s).
        pub angular: Vector3,
    }

    ros_message!(Twist, "geometry_msgs", "Twist");
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

    /// [sensor_msgs/msg/CompressedImage](https://github.com/ros2/common_interfaces/blob/rolling/sensor_msgs/msg/CompressedImage.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct CompressedImage {
        /// Acquisition time of the image; `frame_id` is the camera's optical frame.
        pub header: Header,
        /// The encoding: `jpeg` or `png` (image_transport's compressed plugin also
        /// writes e.g. `rgb8; jpeg compressed bgr8`).
        pub format: String,
        /// The compressed image, a whole JPEG or PNG file.
        pub data: Vec<u8>,
    }

    ros_message!(CompressedImage, "sensor_msgs", "CompressedImage");

    /// [sensor_msgs/msg/Image](https://github.com/ros2/common_interfaces/blob/rolling/sensor_msgs/msg/Image.msg):
    /// an uncompressed image.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Image {
        /// Acquisition time of the image; `frame_id` is the camera's optical frame.
        pub header: Header,
        /// Rows, px.
        pub height: u32,
        /// Columns, px.
        pub width: u32,
        /// Pixel encoding (`rgb8`, `bgr8`, `mono8`, … as in sensor_msgs/image_encodings.hpp).
        pub encoding: String,
        /// Whether multi-byte values are big-endian.
        pub is_bigendian: u8,
        /// Bytes of one row (with any padding).
        pub step: u32,
        /// The pixels, `step * height` bytes.
        pub data: Vec<u8>,
    }

    ros_message!(Image, "sensor_msgs", "Image");

    /// [sensor_msgs/msg/RegionOfInterest](https://github.com/ros2/common_interfaces/blob/rolling/sensor_msgs/msg/RegionOfInterest.msg):
    /// a window of an image, px; all zero = the full image.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct RegionOfInterest {
        /// Leftmost pixel of the window.
        pub x_offset: u32,
        /// Topmost pixel of the window.
        pub y_offset: u32,
        /// Height of the window.
        pub height: u32,
        /// Width of the window.
        pub width: u32,
        /// Whether a rectified image is wanted of this window.
        pub do_rectify: bool,
    }

    ros_message!(RegionOfInterest, "sensor_msgs", "RegionOfInterest");

    /// [sensor_msgs/msg/CameraInfo](https://github.com/ros2/common_interfaces/blob/rolling/sensor_msgs/msg/CameraInfo.msg):
    /// a camera's calibration, published beside each of its images with the same header.
    /// All zero `k`, `r`, `p` = uncalibrated.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct CameraInfo {
        /// The stamp and frame of the image this describes.
        pub header: Header,
        /// Image height the camera was calibrated at, px.
        pub height: u32,
        /// Image width the camera was calibrated at, px.
        pub width: u32,
        /// `plumb_bob`, `rational_polynomial`, … (empty: uncalibrated).
        pub distortion_model: String,
        /// Distortion parameters of `distortion_model`.
        pub d: Vec<f64>,
        /// Intrinsic matrix, 3×3 row-major.
        pub k: [f64; 9],
        /// Rectification matrix, 3×3 row-major.
        pub r: [f64; 9],
        /// Projection matrix, 3×4 row-major.
        pub p: [f64; 12],
        /// Horizontal binning (0 or 1: none).
        pub binning_x: u32,
        /// Vertical binning (0 or 1: none).
        pub binning_y: u32,
        /// The window of the image published.
        pub roi: RegionOfInterest,
    }

    ros_message!(CameraInfo, "sensor_msgs", "CameraInfo");
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

/// `trajectory_msgs`: <https://github.com/ros2/common_interfaces/tree/rolling/trajectory_msgs/msg>
pub mod trajectory_msgs {
    use super::builtin_interfaces::Duration;
    use super::geometry_msgs::{Transform, Twist};
    use super::std_msgs::Header;
    use serde::{Deserialize, Serialize};

    /// [trajectory_msgs/msg/JointTrajectoryPoint](https://github.com/ros2/common_interfaces/blob/rolling/trajectory_msgs/msg/JointTrajectoryPoint.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct JointTrajectoryPoint {
        /// Positions (rad or m), parallel to the trajectory's `joint_names`.
        pub positions: Vec<f64>,
        /// Velocities; empty, or one per joint.
        pub velocities: Vec<f64>,
        /// Accelerations; empty, or one per joint.
        pub accelerations: Vec<f64>,
        /// Efforts; empty, or one per joint.
        pub effort: Vec<f64>,
        /// When the point is to be reached, from the trajectory's `header.stamp`.
        pub time_from_start: Duration,
    }

    /// [trajectory_msgs/msg/JointTrajectory](https://github.com/ros2/common_interfaces/blob/rolling/trajectory_msgs/msg/JointTrajectory.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct JointTrajectory {
        /// `stamp`: when the trajectory starts (zero: now).
        pub header: Header,
        /// The joints the points give.
        pub joint_names: Vec<String>,
        /// The points, in time order.
        pub points: Vec<JointTrajectoryPoint>,
    }

    /// [trajectory_msgs/msg/MultiDOFJointTrajectoryPoint](https://github.com/ros2/common_interfaces/blob/rolling/trajectory_msgs/msg/MultiDOFJointTrajectoryPoint.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct MultiDOFJointTrajectoryPoint {
        /// One transform per joint.
        pub transforms: Vec<Transform>,
        /// Velocities; empty, or one per joint.
        pub velocities: Vec<Twist>,
        /// Accelerations; empty, or one per joint.
        pub accelerations: Vec<Twist>,
        /// When the point is to be reached.
        pub time_from_start: Duration,
    }

    /// [trajectory_msgs/msg/MultiDOFJointTrajectory](https://github.com/ros2/common_interfaces/blob/rolling/trajectory_msgs/msg/MultiDOFJointTrajectory.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct MultiDOFJointTrajectory {
        /// Start time and frame.
        pub header: Header,
        /// The joints.
        pub joint_names: Vec<String>,
        /// The points.
        pub points: Vec<MultiDOFJointTrajectoryPoint>,
    }

    ros_message!(
        JointTrajectoryPoint,
        "trajectory_msgs",
        "JointTrajectoryPoint"
    );
    ros_message!(JointTrajectory, "trajectory_msgs", "JointTrajectory");
    ros_message!(
        MultiDOFJointTrajectoryPoint,
        "trajectory_msgs",
        "MultiDOFJointTrajectoryPoint"
    );
    ros_message!(
        MultiDOFJointTrajectory,
        "trajectory_msgs",
        "MultiDOFJointTrajectory"
    );
}

/// `control_msgs` (ros-controls/control_msgs 6.x, the Kilted release; where Jazzy's 5.x
/// differs, said at the type): <https://github.com/ros-controls/control_msgs>
pub mod control_msgs {
    use super::builtin_interfaces::Duration;
    use super::std_msgs::Header;
    use super::trajectory_msgs::{
        JointTrajectory, JointTrajectoryPoint, MultiDOFJointTrajectory,
        MultiDOFJointTrajectoryPoint,
    };
    use serde::{Deserialize, Serialize};

    /// [control_msgs/msg/JointTolerance](https://github.com/ros-controls/control_msgs/blob/master/control_msgs/msg/JointTolerance.msg):
    /// 0 = the controller's default, negative = no limit.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct JointTolerance {
        /// The joint.
        pub name: String,
        /// rad or m
        pub position: f64,
        /// rad/s or m/s
        pub velocity: f64,
        /// rad/s² or m/s²
        pub acceleration: f64,
    }

    /// [control_msgs/msg/JointComponentTolerance](https://github.com/ros-controls/control_msgs/blob/master/control_msgs/msg/JointComponentTolerance.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct JointComponentTolerance {
        /// The joint.
        pub joint_name: String,
        /// X_AXIS = 1 … ROTATION = 5.
        pub component: u16,
        /// position
        pub position: f64,
        /// velocity
        pub velocity: f64,
        /// acceleration
        pub acceleration: f64,
    }

    /// [control_msgs/msg/JointTrajectoryControllerState](https://github.com/ros-controls/control_msgs/blob/master/control_msgs/msg/JointTrajectoryControllerState.msg)
    /// (the same in Jazzy's 5.x)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct JointTrajectoryControllerState {
        /// Stamp of the state.
        pub header: Header,
        /// The controller's joints.
        pub joint_names: Vec<String>,
        /// Where the trajectory (or the hold) wants the joints now.
        pub reference: JointTrajectoryPoint,
        /// What the joints report.
        pub feedback: JointTrajectoryPoint,
        /// reference − feedback
        pub error: JointTrajectoryPoint,
        /// What the controller commands.
        pub output: JointTrajectoryPoint,
        /// Multi-DOF joints (none here).
        pub multi_dof_joint_names: Vec<String>,
        /// unused
        pub multi_dof_reference: MultiDOFJointTrajectoryPoint,
        /// unused
        pub multi_dof_feedback: MultiDOFJointTrajectoryPoint,
        /// unused
        pub multi_dof_error: MultiDOFJointTrajectoryPoint,
        /// unused
        pub multi_dof_output: MultiDOFJointTrajectoryPoint,
        /// The speed scaling applied (1 = as planned).
        pub speed_scaling_factor: f64,
    }

    /// [control_msgs/action/FollowJointTrajectory](https://github.com/ros-controls/control_msgs/blob/master/control_msgs/action/FollowJointTrajectory.action): the goal.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct FollowJointTrajectoryGoal {
        /// The trajectory.
        pub trajectory: JointTrajectory,
        /// Planar or floating joints (none here).
        pub multi_dof_trajectory: MultiDOFJointTrajectory,
        /// How far each joint may be off while moving.
        pub path_tolerance: Vec<JointTolerance>,
        /// Per component, multi-DOF joints.
        pub component_path_tolerance: Vec<JointComponentTolerance>,
        /// How far each joint may be off at the end.
        pub goal_tolerance: Vec<JointTolerance>,
        /// Per component, multi-DOF joints.
        pub component_goal_tolerance: Vec<JointComponentTolerance>,
        /// How long after the last point's time the goal tolerance may still be met.
        pub goal_time_tolerance: Duration,
    }

    /// FollowJointTrajectory's result.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct FollowJointTrajectoryResult {
        /// One of the constants on [`FollowJointTrajectoryResult`].
        pub error_code: i32,
        /// Why, in words.
        pub error_string: String,
    }

    impl FollowJointTrajectoryResult {
        /// Done.
        pub const SUCCESSFUL: i32 = 0;
        /// The goal cannot be executed (limits, times, points).
        pub const INVALID_GOAL: i32 = -1;
        /// The goal's joints are not the controller's.
        pub const INVALID_JOINTS: i32 = -2;
        /// The trajectory ends before now.
        pub const OLD_HEADER_TIMESTAMP: i32 = -3;
        /// A joint left its path tolerance.
        pub const PATH_TOLERANCE_VIOLATED: i32 = -4;
        /// A joint missed its goal tolerance in time.
        pub const GOAL_TOLERANCE_VIOLATED: i32 = -5;
    }

    /// FollowJointTrajectory's feedback as control_msgs 6.3 and later have it (Kilted):
    /// with `index` and `multi_dof_index`. Jazzy's 5.x has neither
    /// ([`FollowJointTrajectoryFeedbackJazzy`]).
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct FollowJointTrajectoryFeedback {
        /// Stamp.
        pub header: Header,
        /// The controller's joints.
        pub joint_names: Vec<String>,
        /// Where the trajectory wants the joints now.
        pub desired: JointTrajectoryPoint,
        /// What the joints report.
        pub actual: JointTrajectoryPoint,
        /// desired − actual
        pub error: JointTrajectoryPoint,
        /// The index of the point being moved to.
        pub index: i32,
        /// Multi-DOF joints (none here).
        pub multi_dof_joint_names: Vec<String>,
        /// unused
        pub multi_dof_desired: MultiDOFJointTrajectoryPoint,
        /// unused
        pub multi_dof_actual: MultiDOFJointTrajectoryPoint,
        /// unused
        pub multi_dof_error: MultiDOFJointTrajectoryPoint,
        /// unused
        pub multi_dof_index: i32,
    }

    /// FollowJointTrajectory's feedback as Jazzy's control_msgs 5.x has it.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct FollowJointTrajectoryFeedbackJazzy {
        /// Stamp.
        pub header: Header,
        /// The controller's joints.
        pub joint_names: Vec<String>,
        /// Where the trajectory wants the joints now.
        pub desired: JointTrajectoryPoint,
        /// What the joints report.
        pub actual: JointTrajectoryPoint,
        /// desired − actual
        pub error: JointTrajectoryPoint,
        /// Multi-DOF joints (none here).
        pub multi_dof_joint_names: Vec<String>,
        /// unused
        pub multi_dof_desired: MultiDOFJointTrajectoryPoint,
        /// unused
        pub multi_dof_actual: MultiDOFJointTrajectoryPoint,
        /// unused
        pub multi_dof_error: MultiDOFJointTrajectoryPoint,
    }

    impl From<FollowJointTrajectoryFeedback> for FollowJointTrajectoryFeedbackJazzy {
        fn from(f: FollowJointTrajectoryFeedback) -> Self {
            FollowJointTrajectoryFeedbackJazzy {
                header: f.header,
                joint_names: f.joint_names,
                desired: f.desired,
                actual: f.actual,
                error: f.error,
                multi_dof_joint_names: f.multi_dof_joint_names,
                multi_dof_desired: f.multi_dof_desired,
                multi_dof_actual: f.multi_dof_actual,
                multi_dof_error: f.multi_dof_error,
            }
        }
    }

    /// [control_msgs/msg/GripperCommand](https://github.com/ros-controls/control_msgs/blob/master/control_msgs/msg/GripperCommand.msg)
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct GripperCommand {
        /// The gripper joint's position (rad here, as gripper_action_controller).
        pub position: f64,
        /// Most effort; ≤ 0 = no limit (our hobby servo has no effort control).
        pub max_effort: f64,
    }

    /// [control_msgs/action/GripperCommand](https://github.com/ros-controls/control_msgs/blob/master/control_msgs/action/GripperCommand.action): the goal.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct GripperCommandGoal {
        /// Where the gripper goes.
        pub command: GripperCommand,
    }

    /// GripperCommand's result, and (the same fields) its feedback.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct GripperCommandResult {
        /// The gripper joint's position (rad).
        pub position: f64,
        /// The effort (unknown here: 0).
        pub effort: f64,
        /// It stopped short of the goal.
        pub stalled: bool,
        /// It reached the goal.
        pub reached_goal: bool,
    }

    ros_message!(JointTolerance, "control_msgs", "JointTolerance");
    ros_message!(
        JointComponentTolerance,
        "control_msgs",
        "JointComponentTolerance"
    );
    ros_message!(
        JointTrajectoryControllerState,
        "control_msgs",
        "JointTrajectoryControllerState"
    );
    ros_message!(GripperCommand, "control_msgs", "GripperCommand");
    ros2_client_message!(FollowJointTrajectoryGoal);
    ros2_client_message!(FollowJointTrajectoryResult);
    ros2_client_message!(FollowJointTrajectoryFeedback);
    ros2_client_message!(FollowJointTrajectoryFeedbackJazzy);
    ros2_client_message!(GripperCommandGoal);
    ros2_client_message!(GripperCommandResult);
}

/// `controller_manager_msgs`, the part ros2_control's controller manager interface needs:
/// <https://github.com/ros-controls/ros2_control/tree/master/controller_manager_msgs>
/// (the same in Jazzy's 4.x and Kilted's 5.x).
pub mod controller_manager_msgs {
    use super::builtin_interfaces::Duration;
    use serde::{Deserialize, Serialize};

    /// [controller_manager_msgs/msg/ChainConnection](https://github.com/ros-controls/ros2_control/blob/master/controller_manager_msgs/msg/ChainConnection.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct ChainConnection {
        /// The controller exporting the references.
        pub name: String,
        /// Its references.
        pub reference_interfaces: Vec<String>,
    }

    /// [controller_manager_msgs/msg/ControllerState](https://github.com/ros-controls/ros2_control/blob/master/controller_manager_msgs/msg/ControllerState.msg)
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct ControllerState {
        /// The controller's name.
        pub name: String,
        /// `unconfigured`, `inactive`, `active` or `finalized`.
        pub state: String,
        /// Its class, e.g. `joint_trajectory_controller/JointTrajectoryController`.
        pub r#type: String,
        /// Runs asynchronously.
        pub is_async: bool,
        /// Hz.
        pub update_rate: u16,
        /// The command interfaces it holds now (active only).
        pub claimed_interfaces: Vec<String>,
        /// The command interfaces it needs.
        pub required_command_interfaces: Vec<String>,
        /// The state interfaces it needs.
        pub required_state_interfaces: Vec<String>,
        /// Exports references for a chain.
        pub is_chainable: bool,
        /// Its references are claimed by another controller.
        pub is_chained: bool,
        /// State interfaces it exports.
        pub exported_state_interfaces: Vec<String>,
        /// References it exports.
        pub reference_interfaces: Vec<String>,
        /// The controllers it is chained to.
        pub chain_connections: Vec<ChainConnection>,
    }

    /// [ListControllers](https://github.com/ros-controls/ros2_control/blob/master/controller_manager_msgs/srv/ListControllers.srv)'
    /// request: empty (the one-byte placeholder every empty ROS 2 structure has).
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct ListControllersRequest {
        /// Always 0.
        pub structure_needs_at_least_one_member: u8,
    }

    /// ListControllers' response.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct ListControllersResponse {
        /// Every controller.
        pub controller: Vec<ControllerState>,
    }

    /// [SwitchController](https://github.com/ros-controls/ros2_control/blob/master/controller_manager_msgs/srv/SwitchController.srv)'
    /// request.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct SwitchControllerRequest {
        /// Names to activate.
        pub activate_controllers: Vec<String>,
        /// Names to deactivate.
        pub deactivate_controllers: Vec<String>,
        /// [`Self::BEST_EFFORT`], [`Self::STRICT`], [`Self::AUTO`] or [`Self::FORCE_AUTO`].
        pub strictness: i32,
        /// Activate as soon as possible (every switch of ours is at once).
        pub activate_asap: bool,
        /// How long the switch may take (ours are at once).
        pub timeout: Duration,
    }

    impl SwitchControllerRequest {
        /// Do what can be done.
        pub const BEST_EFFORT: i32 = 1;
        /// All or nothing.
        pub const STRICT: i32 = 2;
        /// ros2_control: activate or deactivate the controllers a chain needs too.
        pub const AUTO: i32 = 3;
        /// ros2_control: as AUTO, deactivating what stands in the way.
        pub const FORCE_AUTO: i32 = 4;
    }

    /// SwitchController's response.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct SwitchControllerResponse {
        /// Done (in part, with BEST_EFFORT).
        pub ok: bool,
        /// Why not, or what was skipped.
        pub message: String,
    }

    ros_message!(
        ChainConnection,
        "controller_manager_msgs",
        "ChainConnection"
    );
    ros_message!(
        ControllerState,
        "controller_manager_msgs",
        "ControllerState"
    );
    ros2_client_message!(ListControllersRequest);
    ros2_client_message!(ListControllersResponse);
    ros2_client_message!(SwitchControllerRequest);
    ros2_client_message!(SwitchControllerResponse);
}

/// `std_srvs`: <https://github.com/ros2/common_interfaces/tree/rolling/std_srvs/srv>
pub mod std_srvs {
    use serde::{Deserialize, Serialize};

    /// [std_srvs/srv/Trigger](https://github.com/ros2/common_interfaces/blob/rolling/std_srvs/srv/Trigger.srv)'s
    /// request: empty (the one-byte placeholder every empty ROS 2 structure has).
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct TriggerRequest {
        /// Always 0.
        pub structure_needs_at_least_one_member: u8,
    }

    /// Trigger's response.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct TriggerResponse {
        /// Whether it was done.
        pub success: bool,
        /// What was done, or why not.
        pub message: String,
    }

    ros2_client_message!(TriggerRequest);
    ros2_client_message!(TriggerResponse);
}
