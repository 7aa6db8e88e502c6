//! state_publisher's logic on the shipped URDF and on a different robot.
#![allow(clippy::unwrap_used)]

use eezybot_kinematics::urdf::RobotModel;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use state_publisher::core::{JointProblem, TfCore};
use std::path::Path;

fn test_robot() -> RobotModel {
    RobotModel::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/test_robot.urdf"),
    )
    .unwrap()
}

fn js(names: &[&str], pos: &[f64]) -> JointState {
    JointState {
        header: Header {
            stamp: Time::from_nanos(42),
            frame_id: String::new(),
        },
        name: names.iter().map(|s| s.to_string()).collect(),
        position: pos.to_vec(),
        ..JointState::default()
    }
}

#[test]
fn fixed_joints_go_to_tf_static_with_the_prefix() {
    let core = TfCore::new(test_robot(), "r1/");
    let s = core.static_transforms(Time::ZERO);
    assert_eq!(s.transforms.len(), 1);
    let t = &s.transforms[0];
    assert_eq!(
        (t.header.frame_id.as_str(), t.child_frame_id.as_str()),
        ("r1/base", "r1/mount")
    );
    assert!((t.transform.translation.z - 0.1).abs() < 1e-15);
    // yaw of pi/2: quaternion (0, 0, sin(pi/4), cos(pi/4))
    assert!((t.transform.rotation.z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-15);
}

#[test]
fn continuous_prismatic_revolute_and_mimic() {
    let mut core = TfCore::new(test_robot(), "");
    let (tf, problems) = core.handle_joint_states(&js(
        &["wheel_joint", "slider_joint", "finger_a_joint"],
        &[7.0, 0.3, 0.4],
    ));
    assert!(problems.is_empty());
    let by_child = |c: &str| {
        tf.transforms
            .iter()
            .find(|t| t.child_frame_id == c)
            .unwrap()
            .clone()
    };
    assert!(tf
        .transforms
        .iter()
        .all(|t| t.header.stamp == Time::from_nanos(42)));
    // continuous about x by 7 rad (no limits): quaternion x = sin(3.5), w = cos(3.5)
    let w = by_child("wheel");
    assert!(
        (w.transform.rotation.x - 3.5f64.sin()).abs() < 1e-12
            && (w.transform.rotation.w - 3.5f64.cos()).abs() < 1e-12
    );
    assert!((w.transform.translation.x - 0.2).abs() < 1e-15);
    // prismatic along z by 0.3 from its origin (0, 0.1, 0)
    let c = by_child("carriage");
    assert!(
        (c.transform.translation.y - 0.1).abs() < 1e-15
            && (c.transform.translation.z - 0.3).abs() < 1e-15
    );
    // mimic: finger_b = -2 * 0.4 + 0.1 = -0.7 about z
    let b = by_child("finger_b");
    assert!((b.transform.rotation.z - (-0.35f64).sin()).abs() < 1e-12);
    assert_eq!(tf.transforms.len(), 4);
    assert!(core.missing_joints().is_empty());
}

#[test]
fn bad_joints_are_skipped_and_named() {
    let mut core = TfCore::new(test_robot(), "");
    let (tf, problems) = core.handle_joint_states(&js(
        &[
            "nope",
            "slider_joint",
            "wheel_joint",
            "mount_joint",
            "finger_a_joint",
        ],
        &[1.0, f64::NAN, 1.0, 0.0],
    ));
    assert_eq!(tf.transforms.len(), 1, "only the wheel is good");
    let text: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
    assert_eq!(
        text,
        [
            "unknown joint `nope` (not in the URDF)",
            "joint `slider_joint` position is NaN",
            "joint `mount_joint` is fixed and takes no position",
            "joint `finger_a_joint` has no position (fewer positions than names)",
        ]
    );
    assert!(matches!(problems[0], JointProblem::Unknown { .. }));
    assert_eq!(core.missing_joints(), ["slider_joint", "finger_a_joint"]);
    let d = core.diagnostic_status("state_publisher: robot state", &[]);
    assert_eq!(d.level, 1);
    assert!(
        d.message.contains("slider_joint") && d.message.contains("finger_a_joint"),
        "{}",
        d.message
    );
}

#[test]
fn shipped_urdf_publishes_every_movable_joint_from_compute_ik_output() {
    let model = state_publisher::load_urdf("").unwrap().model;
    let fixed = model.joints.iter().filter(|j| !j.is_movable()).count();
    let mut core = TfCore::new(model, "");
    let state = eezybot_kinematics::ArmState::default();
    let positions = state.joint_positions(&eezybot_kinematics::Arm::default().geometry);
    let names: Vec<&str> = positions.iter().map(|(n, _)| *n).collect();
    let values: Vec<f64> = positions.iter().map(|(_, v)| *v).collect();
    let (tf, problems) = core.handle_joint_states(&js(&names, &values));
    assert!(problems.is_empty(), "{problems:?}");
    assert_eq!(tf.transforms.len() + fixed, core.model().joints.len());
    assert_eq!(core.diagnostic_status("x", &[]).level, 0);
}

#[test]
fn built_in_urdf_is_the_shipped_file() {
    let file = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../urdf/eezybot.urdf"),
    )
    .unwrap();
    assert_eq!(state_publisher::SHIPPED_URDF, file);
    assert_eq!(state_publisher::load_urdf("").unwrap().text, file);
}

/// Regression: the default was a path into the build tree, absent on a Raspberry Pi
/// that got the binary alone.
#[test]
fn urdf_default_needs_no_file_of_the_build_tree() {
    let spec = state_publisher::spec();
    let urdf = spec.params.iter().find(|p| p.name == "urdf").unwrap();
    assert!(
        matches!(&urdf.default, ros_plumbing::ParameterValue::String(s) if s.is_empty()),
        "{:?}",
        urdf.default
    );
    let help = spec.help();
    assert!(!help.contains(env!("CARGO_MANIFEST_DIR")), "{help}");
    assert!(help.contains("built into this binary"), "{help}");
}

#[test]
fn a_joint_named_twice_and_positions_without_names_are_named() {
    let mut core = TfCore::new(test_robot(), "");
    let (tf, problems) =
        core.handle_joint_states(&js(&["wheel_joint", "wheel_joint"], &[0.5, 1.5, 2.5]));
    assert_eq!(
        tf.transforms.len(),
        1,
        "the first position of the wheel is used"
    );
    let text: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
    assert_eq!(
        text,
        [
            "3 positions for 2 names: the last 1 belong to no joint",
            "joint `wheel_joint` is named twice (its first position is used)",
        ]
    );
}
