//! Angle <-> pulse conversion and the checks on servo_angles.
#![allow(clippy::unwrap_used)]

use eezybot_kinematics::ServoCalibrations;
use eezybot_msgs::sensor_msgs::JointState;
use serial_node::core::*;

fn msg(names: &[&str], pos: &[f64]) -> JointState {
    JointState {
        name: names.iter().map(|s| s.to_string()).collect(),
        position: pos.to_vec(),
        ..JointState::default()
    }
}

const ALL: [&str; 4] = [
    "base_servo",
    "shoulder_servo",
    "elbow_servo",
    "gripper_servo",
];

#[test]
fn robot_md_pulses() {
    let cal = ServoCalibrations::default();
    let deg = [0.0f64, 90.0, 180.0, 120.0];
    let t = angles_to_ticks(&cal, &msg(&ALL, &deg.map(f64::to_radians))).unwrap();
    // 544 + 1856 * deg / 180 µs, in half microseconds
    assert_eq!(t, [1088, 2944, 4800, 3563]);
    let back = ticks_to_angles(&cal, &t);
    for (b, d) in back.iter().zip(deg) {
        assert!((b.to_degrees() - d).abs() < 0.05);
    }
}

#[test]
fn any_order_of_names() {
    let cal = ServoCalibrations::default();
    let a = angles_to_ticks(
        &cal,
        &msg(
            &[
                "gripper_servo",
                "elbow_servo",
                "shoulder_servo",
                "base_servo",
            ],
            &[1.2, 1.0, 1.5, 1.6],
        ),
    );
    let b = angles_to_ticks(&cal, &msg(&ALL, &[1.6, 1.5, 1.0, 1.2]));
    assert_eq!(a, b);
}

#[test]
fn bad_messages_are_named() {
    let cal = ServoCalibrations::default();
    let cases = [
        (msg(&ALL, &[1.0, 1.0, 1.0]), "length_mismatch"),
        (
            msg(
                &["base_servo", "x", "elbow_servo", "gripper_servo"],
                &[1.0; 4],
            ),
            "unknown_servo",
        ),
        (msg(&ALL[..3], &[1.0; 3]), "missing_servo"),
        (
            msg(
                &[
                    "base_servo",
                    "shoulder_servo",
                    "elbow_servo",
                    "gripper_servo",
                    "base_servo",
                ],
                &[1.0, 1.0, 1.0, 1.2, 2.0],
            ),
            "duplicate_servo",
        ),
        (msg(&ALL, &[1.0, f64::NAN, 1.0, 1.2]), "non_finite"),
        (msg(&ALL, &[1.0, 1.0, 1.0, 0.5]), "out_of_range"), // gripper below 60°
        (msg(&ALL, &[-0.1, 1.0, 1.0, 1.2]), "out_of_range"),
    ];
    for (m, code) in cases {
        assert_eq!(angles_to_ticks(&cal, &m).unwrap_err().code(), code, "{m:?}");
    }
}

#[test]
fn a_huge_name_is_cut_in_the_reason() {
    let cal = ServoCalibrations::default();
    let huge = "x".repeat(1 << 20);
    let names = ["base_servo", "shoulder_servo", "elbow_servo", huge.as_str()];
    let reason = angles_to_ticks(&cal, &msg(&names, &[1.0; 4]))
        .unwrap_err()
        .to_string();
    assert!(
        reason.len() < 300 && reason.contains("(1048576 bytes)"),
        "{}",
        reason.len()
    );
}
