//! The IK node's logic without ROS.
#![allow(clippy::unwrap_used)]
use compute_ik::core::*;
use eezybot_kinematics::{Arm, ArmConfig, ArmJoints};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::Point;
use eezybot_msgs::geometry_msgs::PointStamped;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use nalgebra::Vector3;

fn core() -> IkCore {
    IkCore::new(&ArmConfig::default(), "base_link")
}

fn target(x: f64, y: f64, z: f64, frame: &str) -> PointStamped {
    PointStamped {
        header: Header {
            stamp: Time::from_nanos(1_700_000_000_123_456_789),
            frame_id: frame.into(),
        },
        point: Point { x, y, z },
    }
}

#[test]
fn reachable_target_gives_both_outputs_with_the_cause_stamp() {
    let mut c = core();
    let out = c
        .handle_xyz_target(&target(0.2, 0.05, 0.15, "base_link"))
        .unwrap();
    assert_eq!(
        out.joint_states.header.stamp,
        Time::from_nanos(1_700_000_000_123_456_789)
    );
    assert_eq!(out.servo_angles.header.stamp, out.joint_states.header.stamp);
    assert_eq!(
        out.servo_angles.name,
        [
            "base_servo",
            "shoulder_servo",
            "elbow_servo",
            "gripper_servo"
        ]
    );
    assert_eq!(out.joint_states.name.len(), 11);
    let arm = Arm::default();
    let p = arm.forward(&c.state().joints);
    assert!((p - Vector3::new(0.2, 0.05, 0.15)).norm() < 1e-12);
    // servo mapping of ROBOT.md
    let q = c.state().joints;
    let deg: Vec<f64> = out
        .servo_angles
        .position
        .iter()
        .map(|r| r.to_degrees())
        .collect();
    assert!((deg[0] - (90.0 - 2.0 * q.base_rad.to_degrees())).abs() < 1e-9);
    assert!((deg[1] - (180.0 - q.shoulder_rad.to_degrees())).abs() < 1e-9);
    assert!((deg[2] - (90.0 + q.forearm_elevation_rad().to_degrees())).abs() < 1e-9);
    assert!((deg[3] - 60.0).abs() < 1e-9);
}

#[test]
fn empty_frame_means_base_link() {
    assert!(core()
        .handle_xyz_target(&target(0.2, 0.0, 0.15, ""))
        .is_ok());
}

#[test]
fn every_bad_input_is_refused_and_keeps_the_state() {
    let mut c = core();
    c.handle_xyz_target(&target(0.2, 0.0, 0.15, "base_link"))
        .unwrap();
    let good = *c.state();
    let bad_joint = |names: &[&str], pos: &[f64]| JointState {
        name: names.iter().map(|s| s.to_string()).collect(),
        position: pos.to_vec(),
        ..JointState::default()
    };
    let cases: Vec<(Result<Output, Rejection>, &str)> = vec![
        (
            c.handle_xyz_target(&target(1.0, 0.0, 0.15, "base_link")),
            "too_far",
        ),
        (
            c.handle_xyz_target(&target(f64::NAN, 0.0, 0.15, "base_link")),
            "non_finite_target",
        ),
        (
            c.handle_xyz_target(&target(0.2, f64::INFINITY, 0.15, "base_link")),
            "non_finite_target",
        ),
        (
            c.handle_xyz_target(&target(0.2, 0.0, 0.15, "map")),
            "wrong_frame",
        ),
        (
            c.handle_xyz_target(&target(-0.2, 0.0, 0.15, "base_link")),
            "out_of_limits:base_joint",
        ),
        (
            c.handle_gripper_target(1.5, Time::ZERO),
            "gripper_out_of_range",
        ),
        (
            c.handle_gripper_target(f64::NAN, Time::ZERO),
            "gripper_out_of_range",
        ),
        (
            c.handle_joint_target(&bad_joint(&["wrist_joint"], &[0.0])),
            "unknown_joint",
        ),
        (
            c.handle_joint_target(&bad_joint(&["base_joint"], &[])),
            "length_mismatch",
        ),
        (c.handle_joint_target(&bad_joint(&[], &[])), "no_joints"),
        (
            c.handle_joint_target(&bad_joint(&["base_joint", "base_joint"], &[0.0, 0.1])),
            "duplicate_joint",
        ),
        (
            c.handle_joint_target(&bad_joint(&["shoulder_joint"], &[f64::NAN])),
            "non_finite_joint:shoulder_joint",
        ),
        (
            c.handle_joint_target(&bad_joint(&["shoulder_joint"], &[2.5])),
            "out_of_limits:shoulder_joint",
        ),
        (
            c.handle_joint_target(&bad_joint(&["gripper_joint"], &[2.0])),
            "out_of_limits:gripper_joint",
        ),
    ];
    for (result, code) in cases {
        let rejection = result.unwrap_err();
        assert_eq!(rejection.reason.code(), code, "{rejection}");
        assert_eq!(*c.state(), good);
    }
    let d = c.diagnostic_status("compute_ik");
    assert_eq!(d.level, DiagnosticStatus::WARN);
    c.handle_gripper_target(0.5, Time::ZERO).unwrap();
    assert_eq!(
        c.diagnostic_status("compute_ik").level,
        DiagnosticStatus::OK
    );
    assert_eq!(
        c.counters(),
        Counters {
            received: 16,
            accepted: 2,
            rejected: 14
        }
    );
}

#[test]
fn joint_mode_keeps_unnamed_joints() {
    let mut c = core();
    let msg = JointState {
        name: vec!["base_joint".into(), "gripper_joint".into()],
        position: vec![0.3, 0.3],
        ..JointState::default()
    };
    let out = c.handle_joint_target(&msg).unwrap();
    assert_eq!(c.state().joints.base_rad, 0.3);
    assert_eq!(c.state().joints.shoulder_rad, ArmJoints::HOME.shoulder_rad);
    assert!((c.state().gripper_opening - 0.5).abs() < 1e-12);
    assert!((out.servo_angles.position[3].to_degrees() - 120.0).abs() < 1e-9);
}

#[test]
fn estop_refuses_everything_until_released() {
    let mut c = core();
    c.set_estop(true);
    let r = c
        .handle_xyz_target(&target(0.2, 0.0, 0.15, ""))
        .unwrap_err();
    assert_eq!(r.reason, Reason::EmergencyStop);
    assert_eq!(c.diagnostic_status("x").level, DiagnosticStatus::WARN);
    c.set_estop(false);
    assert!(c.handle_xyz_target(&target(0.2, 0.0, 0.15, "")).is_ok());
}

#[test]
fn unreadable_samples_are_counted_and_reported() {
    let mut c = core();
    let r = c.reject_unreadable(Source::JointTarget, "bad CDR".into());
    assert_eq!(r.reason.code(), "unreadable");
    let d = c.diagnostic_status("compute_ik");
    assert_eq!(d.level, DiagnosticStatus::WARN);
    assert!(d.message.contains("bad CDR"), "{}", d.message);
    assert_eq!(c.counters().rejected, 1);
    assert_eq!(*c.state(), eezybot_kinematics::ArmState::default());
}
