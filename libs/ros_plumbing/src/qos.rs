//! QoS presets for the topics of `shared/INTERFACES.md`.

use ros2_client::qos::{Durability, History, Reliability, WhenFull};
use ros2_client::QosProfile;
use std::time::Duration;

/// How long a reliable `publish` may wait for space in the send window before it
/// gives up. Short: a node's loop must not stall behind a slow reader.
pub const WRITE_WAIT: Duration = Duration::from_millis(20);

/// Reliable, volatile, keep last `depth`.
pub const fn reliable(depth: usize) -> QosProfile {
    QosProfile::publisher_default()
        .reliability(Reliability::Reliable {
            when_full: WhenFull::Wait(WRITE_WAIT),
        })
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth })
}

/// Reliable, transient-local (latched), keep last `depth`.
pub const fn latched(depth: usize) -> QosProfile {
    reliable(depth).durability(Durability::TransientLocal)
}

/// `xyz_target`, `gripper_target`, `joint_target`, `joint_states`, `servo_angles`,
/// `servo_state`: reliable, volatile, keep last 10.
pub const COMMANDS: QosProfile = reliable(10);
/// `diagnostics`: reliable, volatile, keep last 10.
pub const DIAGNOSTICS: QosProfile = reliable(10);
/// `tf`: reliable, volatile, keep last 100 (as tf2_ros).
pub const TF: QosProfile = reliable(100);
/// `tf_static`: reliable, transient-local, keep last 1 (as tf2_ros' static broadcaster).
pub const TF_STATIC: QosProfile = latched(1);
/// `robot_description`: reliable, transient-local, keep last 1.
pub const ROBOT_DESCRIPTION: QosProfile = latched(1);
/// `estop`: reliable, transient-local, keep last 1: a late joiner learns the stop.
pub const ESTOP: QosProfile = latched(1);
/// `camera/image_raw/compressed`, `camera/camera_info`: ROS's sensor-data profile
/// (rclcpp `SensorDataQoS`, rclpy `qos_profile_sensor_data`, what image pipelines and
/// camera drivers such as usb_cam publish with): best effort, volatile, keep last 5. A
/// lost frame is not sent again (the next one is newer), and a slow reader never holds
/// the camera back. A reliable subscriber does not match it; a best-effort one does.
pub const SENSOR_DATA: QosProfile = QosProfile::publisher_default()
    .reliability(Reliability::BestEffort)
    .durability(Durability::Volatile)
    .history(History::KeepLast { depth: 5 });
/// Service requests and replies (rmw's default for services: reliable, volatile, keep
/// last 10).
pub const SERVICES: QosProfile = reliable(10);
