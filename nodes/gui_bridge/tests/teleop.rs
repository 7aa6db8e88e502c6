//! The operator state machine and the waypoint files.
#![allow(clippy::unwrap_used)]

use eezybot_kinematics::Arm;
use gui_bridge::teleop::*;
use std::time::{Duration, Instant};

fn teleop() -> Teleop {
    Teleop::new(Arm::default(), 50.0)
}

/// Joint mode's event for these (name, position).
fn joints(q: &[(&str, f64)]) -> Event {
    let positions = q.iter().map(|(n, v)| (n.to_string(), *v)).collect();
    Event::Joints { positions }
}

/// The Kinova Jaco's model (a URDF arm that is not the EezyBot).
fn jaco() -> eezybot_kinematics::urdf::RobotModel {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../urdf/jaco.urdf");
    eezybot_kinematics::urdf::RobotModel::load(std::path::Path::new(path)).unwrap()
}

/// A teleop that took the target `xyz`.
fn teleop_at(xyz: [f64; 3]) -> Teleop {
    let mut t = teleop();
    t.handle_event(Event::SetTarget { xyz, line: false })
        .unwrap();
    t
}

#[test]
fn unreachable_targets_send_nothing_and_keep_the_target() {
    let mut t = teleop();
    let before = t.target();
    let e = t
        .handle_event(Event::SetTarget {
            xyz: [1.0, 0.0, 0.1],
            line: true,
        })
        .unwrap_err();
    assert!(e.to_string().contains("out of reach"));
    assert_eq!(t.target(), before);
    assert!(t.take_due(Instant::now()).is_empty());
}

#[test]
fn jog_moves_by_the_step_from_the_current_target() {
    let mut t = teleop_at([0.2, 0.0, 0.15]);
    t.handle_event(Event::Jog {
        dxyz: [0.0, 0.01, 0.0],
    })
    .unwrap();
    let now = Instant::now();
    assert_eq!(
        t.take_due(now),
        vec![Command::Target {
            xyz: [0.2, 0.01, 0.15],
            line: false
        }]
    );
}

#[test]
fn latest_wins_within_the_rate_limit() {
    let mut t = teleop_at([0.2, 0.0, 0.15]);
    let t0 = Instant::now();
    assert_eq!(t.take_due(t0).len(), 1);
    // the latest with its kind: a line move of a program's
    for (y, line) in [(0.01, false), (0.02, false), (0.03, true)] {
        t.handle_event(Event::SetTarget {
            xyz: [0.2, y, 0.15],
            line,
        })
        .unwrap();
    }
    assert!(
        t.take_due(t0 + Duration::from_millis(5)).is_empty(),
        "within 20 ms of the last"
    );
    assert_eq!(
        t.next_due(t0 + Duration::from_millis(5)),
        Some(t0 + Duration::from_millis(20))
    );
    assert_eq!(
        t.take_due(t0 + Duration::from_millis(20)),
        vec![Command::Target {
            xyz: [0.2, 0.03, 0.15],
            line: true
        }]
    );
}

#[test]
fn estop_goes_out_at_once() {
    let mut t = teleop_at([0.2, 0.0, 0.15]);
    let t0 = Instant::now();
    t.take_due(t0);
    t.handle_event(Event::Estop { engaged: true }).unwrap();
    assert_eq!(t.take_due(t0), vec![Command::Estop(true)]);
}

#[test]
fn joint_mode_checks_limits() {
    let mut t = teleop();
    assert!(t.handle_event(joints(&[("shoulder_joint", 2.5)])).is_err());
    assert!(t.handle_event(joints(&[("wrist_joint", 0.0)])).is_err());
    let f = t.handle_event(joints(&[("base_joint", 0.2)])).unwrap();
    assert!((f.joints.base_rad - 0.2).abs() < 1e-15);
}

#[test]
fn a_urdf_arm_gets_its_own_joints_and_no_eezybot_check() {
    let jaco = jaco();
    let mut t = teleop();
    assert!(t.is_eezybot() && t.joint_sliders().len() == 3);
    let view = t.set_robot(&jaco).clone();
    assert!(!view.eezybot && view.tool_link.as_deref() == Some("jaco_end_effector"));
    assert!(!t.is_eezybot());
    let names: Vec<String> = t.joint_sliders().into_iter().map(|j| j.name).collect();
    assert_eq!(
        names,
        (1..=6)
            .map(|i| format!("jaco_joint_{i}"))
            .collect::<Vec<_>>()
    );
    // the EezyBot's joints are not this arm's
    let e = t.handle_event(joints(&[("base_joint", 0.1)])).unwrap_err();
    assert!(e.to_string().contains("this arm's: jaco_joint_1"), "{e}");
    // its URDF limits apply
    assert!(t.handle_event(joints(&[("jaco_joint_2", 4.0)])).is_err());
    t.handle_event(joints(&[("jaco_joint_2", 1.0)])).unwrap();
    assert_eq!(
        t.take_due(Instant::now()),
        vec![Command::Joints(vec![("jaco_joint_2".into(), 1.0)])]
    );
    // a Cartesian target out of the EezyBot's reach is sent: compute_ik judges it
    t.handle_event(Event::SetTarget {
        xyz: [0.5, 0.2, 0.4],
        line: false,
    })
    .unwrap();
    assert_eq!(
        t.take_due(Instant::now() + Duration::from_secs(1)),
        vec![Command::Target {
            xyz: [0.5, 0.2, 0.4],
            line: false
        }]
    );
}

#[test]
fn joint_targets_it_cannot_check_are_refused_and_change_nothing() {
    let mut t = teleop();
    t.handle_event(joints(&[("base_joint", 0.2), ("gripper_joint", 0.3)]))
        .unwrap();
    t.take_due(Instant::now());
    let (target, none) = (t.target(), t.handle_event(joints(&[])));
    assert!(matches!(none, Err(Refusal::NoJoints { .. })), "{none:?}");
    for (positions, says) in [
        (
            vec![("gripper_joint".to_string(), 1e300)],
            "gripper_joint = 1e300 is outside its limits 0.0 … 0.6",
        ),
        (vec![("gripper_joint".into(), -0.1)], "gripper_joint = -0.1"),
        (vec![("base_joint".into(), f64::NAN)], "base_joint = NaN"),
        (
            vec![("shoulder_joint".into(), f64::INFINITY)],
            "shoulder_joint = inf",
        ),
        (
            vec![("base_joint".into(), 0.1), ("wrist_joint".into(), 0.0)],
            "unknown joint `wrist_joint` (this arm's: base_joint, shoulder_joint, elbow_joint, gripper_joint)",
        ),
        (
            vec![("base_joint".into(), 0.1), ("base_joint".into(), 0.2)],
            "joint `base_joint` given twice",
        ),
        (
            vec![("gripper_mimic_joint".into(), 0.1)],
            "unknown joint `gripper_mimic_joint`",
        ),
    ] {
        let e = t
            .handle_event(Event::Joints {
                positions: positions.clone(),
            })
            .unwrap_err();
        assert!(e.to_string().contains(says), "{positions:?}: {e}");
        assert_eq!(e.kind(), "bad_joint_target");
        assert_eq!(t.target(), target, "{positions:?} moved the target");
        assert!(t.take_due(Instant::now() + Duration::from_secs(1)).is_empty());
    }
    // a 1 MB name comes back cut to a readable length
    let e = t
        .handle_event(Event::Joints {
            positions: vec![("j".repeat(1 << 20), 0.0)],
        })
        .unwrap_err();
    assert!(e.to_string().len() < 300, "{} bytes", e.to_string().len());
    // the claw within its range is taken
    t.handle_event(joints(&[("gripper_joint", 0.6)])).unwrap();
    assert_eq!(
        t.take_due(Instant::now() + Duration::from_secs(1)),
        vec![Command::Joints(vec![("gripper_joint".into(), 0.6)])]
    );
}

#[test]
fn check_joint_positions_takes_the_limits_inclusive() {
    let limits = [JointSlider {
        name: "j".into(),
        lower: -1.0,
        upper: 1.0,
    }];
    for ok in [-1.0, 0.0, 1.0] {
        check_joint_positions(&[("j".into(), ok)], &limits).unwrap();
    }
    for bad in [
        -1.0 - 1e-12,
        1.0 + 1e-12,
        f64::NAN,
        f64::NEG_INFINITY,
        1e300,
    ] {
        assert!(
            matches!(
                check_joint_positions(&[("j".into(), bad)], &limits),
                Err(Refusal::JointOutOfLimits { .. })
            ),
            "{bad}"
        );
    }
    assert!(matches!(
        check_joint_positions(&[], &limits),
        Err(Refusal::NoJoints { .. })
    ));
}

#[test]
fn a_urdf_arm_refuses_a_joint_target_naming_no_joint() {
    let jaco = jaco();
    let mut t = teleop();
    t.set_robot(&jaco);
    let e = t.handle_event(joints(&[])).unwrap_err();
    assert!(
        e.to_string()
            .contains("names no joint (this arm's: jaco_joint_1"),
        "{e}"
    );
    // the claw of the EezyBot is not this arm's
    assert!(t.handle_event(joints(&[("gripper_joint", 0.1)])).is_err());
    assert!(t.take_due(Instant::now()).is_empty());
}
