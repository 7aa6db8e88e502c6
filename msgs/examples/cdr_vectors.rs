//! Test vectors for the rclpy byte-for-byte check (`tests/test_msgs_interop.py`).
//!
//! `cdr_vectors encode` prints `name type hex` for every case, serialized by our structs.
//! `cdr_vectors decode` reads `name hex` lines (rclpy's bytes), decodes each with our
//! struct, and prints `name OK` if it equals our own value for that case (bit for bit:
//! NaN, -0.0 and every string byte), else `name MISMATCH …`.
//!
//! The values are written again, independently, in `tests/interop/cases.py`.

use eezybot_msgs::builtin_interfaces::Duration;
use eezybot_msgs::cdr::{hex, unhex};
use eezybot_msgs::control_msgs::{
    FollowJointTrajectoryFeedback, FollowJointTrajectoryGoal, FollowJointTrajectoryResult,
    GripperCommand, GripperCommandGoal, GripperCommandResult, JointComponentTolerance,
    JointTolerance, JointTrajectoryControllerState,
};
use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use eezybot_msgs::geometry_msgs::Twist;
use eezybot_msgs::geometry_msgs::{
    Point, PointStamped, Pose, PoseStamped, Quaternion, Transform, TransformStamped, Vector3,
};
use eezybot_msgs::sensor_msgs::{CameraInfo, CompressedImage, JointState, RegionOfInterest};
use eezybot_msgs::std_msgs::{Bool, Float64, Header, String as StringMsg};
use eezybot_msgs::tf2_msgs::TFMessage;
use eezybot_msgs::trajectory_msgs::{
    JointTrajectory, JointTrajectoryPoint, MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint,
};
use eezybot_msgs::{cdr, RosMessage, Time};
use std::io::BufRead;

type Check = Box<dyn Fn(&[u8]) -> Result<(), String>>;

struct Case {
    name: &'static str,
    ros_type: String,
    bytes: Vec<u8>,
    check: Check,
}

fn case<M: RosMessage + std::fmt::Debug>(name: &'static str, value: M) -> Case {
    case_of(name, M::ros_type_string(), value)
}

/// A case of a type that is no topic's (an action's goal, result or feedback).
fn case_of<M>(name: &'static str, ros_type: String, value: M) -> Case
where
    M: serde::Serialize + serde::de::DeserializeOwned + std::fmt::Debug + 'static,
{
    let bytes = cdr::encode(&value).unwrap_or_else(|e| panic!("{name}: {e}"));
    let want = format!("{value:?}");
    let ours = bytes.clone();
    Case {
        name,
        ros_type,
        bytes,
        check: Box::new(move |theirs| {
            let got: M = cdr::decode(theirs).map_err(|e| e.to_string())?;
            // Debug shows NaN, -0.0 and every character; re-encoding compares every bit.
            if format!("{got:?}") != want {
                return Err(format!("decoded {got:?}, expected {want}"));
            }
            let again = cdr::encode(&got).map_err(|e| e.to_string())?;
            if again != ours {
                return Err("decoded value re-encodes differently".into());
            }
            Ok(())
        }),
    }
}

fn t(sec: i32, nanosec: u32) -> Time {
    Time::from_nanos(i64::from(sec) * 1_000_000_000 + i64::from(nanosec))
}

fn header(sec: i32, nanosec: u32, frame: &str) -> Header {
    Header {
        stamp: t(sec, nanosec),
        frame_id: frame.into(),
    }
}

fn ts(h: Header, child: &str, tr: [f64; 3], rot: [f64; 4]) -> TransformStamped {
    TransformStamped {
        header: h,
        child_frame_id: child.into(),
        transform: Transform {
            translation: Vector3 {
                x: tr[0],
                y: tr[1],
                z: tr[2],
            },
            rotation: Quaternion {
                x: rot[0],
                y: rot[1],
                z: rot[2],
                w: rot[3],
            },
        },
    }
}

const UNICODE: &str = "bäse_link→ü🤖";

fn cases() -> Vec<Case> {
    let nan = f64::NAN;
    let inf = f64::INFINITY;
    vec![
        case("header_empty", header(0, 0, "")),
        case("header_max", header(i32::MAX, 999_999_999, UNICODE)),
        case("header_min", header(i32::MIN, 0, "base_link")),
        case(
            "string_empty",
            StringMsg {
                data: String::new(),
            },
        ),
        case(
            "string_unicode",
            StringMsg {
                data: format!("{UNICODE} \"quoted\"\n\ttab"),
            },
        ),
        case("float64_neg_zero", Float64 { data: -0.0 }),
        case("float64_nan", Float64 { data: nan }),
        case("float64_inf", Float64 { data: inf }),
        case("float64_neg_inf", Float64 { data: -inf }),
        case("float64_min_subnormal", Float64 { data: 5e-324 }),
        case("float64_max", Float64 { data: f64::MAX }),
        case("bool_true", Bool { data: true }),
        case("bool_false", Bool { data: false }),
        case(
            "point",
            Point {
                x: -0.0,
                y: inf,
                z: nan,
            },
        ),
        case(
            "point_stamped",
            PointStamped {
                header: header(1_700_000_000, 123_456_789, "base_link"),
                point: Point {
                    x: 0.2,
                    y: -0.05,
                    z: 0.15,
                },
            },
        ),
        case(
            "point_stamped_odd_frame",
            PointStamped {
                header: header(-1, 1, "x"),
                point: Point {
                    x: f64::MIN,
                    y: 1e300,
                    z: -5e-324,
                },
            },
        ),
        case(
            "pose_stamped",
            PoseStamped {
                header: header(1_700_000_000, 987_654_321, "base_link"),
                pose: Pose {
                    position: Point {
                        x: 0.3,
                        y: -0.25,
                        z: 0.5,
                    },
                    orientation: Quaternion {
                        x: 0.0,
                        y: std::f64::consts::FRAC_1_SQRT_2,
                        z: 0.0,
                        w: std::f64::consts::FRAC_1_SQRT_2,
                    },
                },
            },
        ),
        case(
            "pose_stamped_odd",
            PoseStamped {
                header: header(-1, 1, UNICODE),
                pose: Pose {
                    position: Point {
                        x: nan,
                        y: -0.0,
                        z: f64::MAX,
                    },
                    orientation: Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: 0.0,
                        w: 0.0,
                    },
                },
            },
        ),
        case(
            "vector3",
            Vector3 {
                x: f64::MIN,
                y: 5e-324,
                z: -inf,
            },
        ),
        case(
            "quaternion_identity",
            Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            },
        ),
        case(
            "quaternion_odd",
            Quaternion {
                x: nan,
                y: -0.0,
                z: inf,
                w: -1.0,
            },
        ),
        case(
            "transform",
            Transform {
                translation: Vector3 {
                    x: 1.0,
                    y: 2.0,
                    z: 3.0,
                },
                rotation: Quaternion {
                    x: 0.5,
                    y: -0.5,
                    z: 0.5,
                    w: -0.5,
                },
            },
        ),
        case(
            "transform_stamped",
            ts(
                header(5, 6, "base_link"),
                "tool0",
                [0.1, -0.0, nan],
                [0.0, 0.0, 0.0, 1.0],
            ),
        ),
        case(
            "transform_stamped_empty_frames",
            ts(
                header(i32::MIN, 999_999_999, ""),
                "",
                [inf, -inf, 0.0],
                [1.0, 0.0, 0.0, 0.0],
            ),
        ),
        case("joint_state_empty", JointState::default()),
        case(
            "joint_state_full",
            JointState {
                header: header(1_700_000_000, 5, ""),
                name: vec!["base_joint".into(), UNICODE.into(), String::new()],
                position: vec![nan, -0.0, inf],
                velocity: vec![],
                effort: vec![f64::MAX],
            },
        ),
        case("compressed_image_empty", CompressedImage::default()),
        case(
            "compressed_image",
            CompressedImage {
                header: header(1_700_000_000, 33_333_333, "camera"),
                format: "jpeg".into(),
                data: vec![0xff, 0xd8, 0xff, 0x00, 0x7f, 0xff, 0xd9],
            },
        ),
        case("camera_info_empty", CameraInfo::default()),
        case(
            "camera_info",
            CameraInfo {
                header: header(7, 999_999_999, "wrist"),
                height: 480,
                width: 640,
                distortion_model: "plumb_bob".into(),
                d: vec![-0.25, 0.125, nan, -0.0, 1e-300],
                k: [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0],
                r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                p: [
                    500.0, 0.0, 320.0, 0.0, 0.0, 500.0, 240.0, 0.0, 0.0, 0.0, 1.0, inf,
                ],
                binning_x: 1,
                binning_y: u32::MAX,
                roi: RegionOfInterest {
                    x_offset: 1,
                    y_offset: 2,
                    height: 3,
                    width: 4,
                    do_rectify: true,
                },
            },
        ),
        case("tf_message_empty", TFMessage { transforms: vec![] }),
        case(
            "tf_message_two",
            TFMessage {
                transforms: vec![
                    ts(
                        header(10, 20, "base_link"),
                        "turntable",
                        [0.0, 0.0, 0.094],
                        [0.0, 0.0, 0.38268343236508984, 0.9238795325112867],
                    ),
                    ts(
                        header(10, 20, UNICODE),
                        "a",
                        [-0.0, nan, 1e-300],
                        [nan, 0.0, 0.0, 1.0],
                    ),
                ],
            },
        ),
        case(
            "key_value",
            KeyValue {
                key: String::new(),
                value: UNICODE.into(),
            },
        ),
        case(
            "diagnostic_status",
            DiagnosticStatus {
                level: 255,
                name: "compute_ik: inverse kinematics".into(),
                message: String::new(),
                hardware_id: "x".into(),
                values: vec![],
            },
        ),
        case(
            "duration",
            Duration {
                sec: -3,
                nanosec: 999_999_999,
            },
        ),
        case("joint_trajectory_empty", JointTrajectory::default()),
        case("joint_trajectory", joint_trajectory()),
        case("controller_state", controller_state()),
        case_of(
            "follow_joint_trajectory_goal",
            "control_msgs/action/FollowJointTrajectory_Goal".into(),
            fjt_goal(),
        ),
        case_of(
            "follow_joint_trajectory_result",
            "control_msgs/action/FollowJointTrajectory_Result".into(),
            FollowJointTrajectoryResult {
                error_code: FollowJointTrajectoryResult::PATH_TOLERANCE_VIOLATED,
                error_string: UNICODE.into(),
            },
        ),
        case_of(
            "follow_joint_trajectory_feedback",
            "control_msgs/action/FollowJointTrajectory_Feedback".into(),
            FollowJointTrajectoryFeedback {
                header: header(7, 8, ""),
                joint_names: vec!["base_joint".into()],
                desired: tpoint(&[0.5], &[-0.25], &[1.0], &[], 1, 2),
                actual: tpoint(&[0.25], &[], &[], &[], 0, 0),
                error: tpoint(&[0.25], &[], &[], &[], 0, 0),
                index: 2,
                multi_dof_index: -1,
                ..Default::default()
            },
        ),
        case_of(
            "gripper_command_goal",
            "control_msgs/action/GripperCommand_Goal".into(),
            GripperCommandGoal {
                command: GripperCommand {
                    position: 0.5,
                    max_effort: -0.0,
                },
            },
        ),
        case_of(
            "gripper_command_result",
            "control_msgs/action/GripperCommand_Result".into(),
            GripperCommandResult {
                position: f64::NAN,
                effort: 0.0,
                stalled: true,
                reached_goal: false,
            },
        ),
        case("diagnostic_array_empty", DiagnosticArray::default()),
        case(
            "diagnostic_array",
            DiagnosticArray {
                header: header(i32::MAX, 0, "odd"),
                status: vec![
                    DiagnosticStatus {
                        level: DiagnosticStatus::WARN,
                        name: UNICODE.into(),
                        message: "out of reach".into(),
                        hardware_id: String::new(),
                        values: vec![
                            KeyValue {
                                key: "k".into(),
                                value: String::new(),
                            },
                            KeyValue {
                                key: "ü".into(),
                                value: "v".into(),
                            },
                        ],
                    },
                    DiagnosticStatus {
                        level: 0,
                        ..DiagnosticStatus::default()
                    },
                ],
            },
        ),
    ]
}

fn tpoint(
    p: &[f64],
    v: &[f64],
    a: &[f64],
    e: &[f64],
    sec: i32,
    nanosec: u32,
) -> JointTrajectoryPoint {
    JointTrajectoryPoint {
        positions: p.to_vec(),
        velocities: v.to_vec(),
        accelerations: a.to_vec(),
        effort: e.to_vec(),
        time_from_start: Duration { sec, nanosec },
    }
}

fn joint_trajectory() -> JointTrajectory {
    JointTrajectory {
        header: header(1_700_000_000, 5, "base_link"),
        joint_names: vec!["base_joint".into(), UNICODE.into(), String::new()],
        points: vec![
            tpoint(&[0.0, 1.5, -1.5], &[], &[], &[], 0, 0),
            tpoint(
                &[0.1, f64::NAN, -0.0],
                &[0.2, 0.0, f64::INFINITY],
                &[1.0, 2.0, 3.0],
                &[f64::MAX],
                1,
                500_000_000,
            ),
        ],
    }
}

fn controller_state() -> JointTrajectoryControllerState {
    JointTrajectoryControllerState {
        header: header(2, 3, ""),
        joint_names: vec!["base_joint".into(), "elbow_joint".into()],
        reference: tpoint(&[0.5, -1.0], &[0.1, 0.2], &[], &[], 1, 0),
        feedback: tpoint(&[0.49, -1.01], &[], &[], &[], 0, 0),
        error: tpoint(&[0.01, 0.01], &[], &[], &[], 0, 0),
        output: tpoint(&[0.5, -1.0], &[], &[], &[], 0, 0),
        multi_dof_joint_names: vec!["planar".into()],
        multi_dof_reference: MultiDOFJointTrajectoryPoint {
            transforms: vec![Transform::default()],
            velocities: vec![Twist {
                linear: Vector3 {
                    x: 1.0,
                    y: 2.0,
                    z: 3.0,
                },
                angular: Vector3 {
                    x: -1.0,
                    y: -0.0,
                    z: f64::NAN,
                },
            }],
            accelerations: vec![],
            time_from_start: Duration { sec: 4, nanosec: 1 },
        },
        speed_scaling_factor: 0.5,
        ..Default::default()
    }
}

fn fjt_goal() -> FollowJointTrajectoryGoal {
    FollowJointTrajectoryGoal {
        trajectory: joint_trajectory(),
        multi_dof_trajectory: MultiDOFJointTrajectory {
            header: header(1, 2, "odom"),
            joint_names: vec!["planar".into()],
            points: vec![MultiDOFJointTrajectoryPoint {
                transforms: vec![Transform::default(), Transform::default()],
                ..Default::default()
            }],
        },
        path_tolerance: vec![JointTolerance {
            name: "elbow_joint".into(),
            position: 0.05,
            velocity: -1.0,
            acceleration: 0.0,
        }],
        component_path_tolerance: vec![JointComponentTolerance {
            joint_name: "planar".into(),
            component: 5,
            position: 0.1,
            velocity: 0.2,
            acceleration: 0.3,
        }],
        goal_tolerance: vec![JointTolerance::default()],
        component_goal_tolerance: vec![],
        goal_time_tolerance: Duration {
            sec: 0,
            nanosec: 500_000_000,
        },
    }
}

fn main() {
    let mode = std::env::args().nth(1).unwrap_or_default();
    let cases = cases();
    match mode.as_str() {
        "encode" => {
            for c in &cases {
                println!("{} {} {}", c.name, c.ros_type, hex(&c.bytes));
            }
        }
        "decode" => {
            for line in std::io::stdin().lock().lines() {
                let line = line.unwrap_or_default();
                let mut parts = line.split_whitespace();
                let (Some(name), Some(h)) = (parts.next(), parts.next()) else {
                    continue;
                };
                let verdict = match (cases.iter().find(|c| c.name == name), unhex(h)) {
                    (None, _) => "MISMATCH no such case".to_string(),
                    (_, None) => "MISMATCH bad hex".to_string(),
                    (Some(c), Some(bytes)) => match (c.check)(&bytes) {
                        Ok(()) => "OK".into(),
                        Err(e) => format!("MISMATCH {e}"),
                    },
                };
                println!("{name} {verdict}");
            }
        }
        _ => {
            eprintln!("usage: cdr_vectors encode|decode");
            std::process::exit(2);
        }
    }
}
