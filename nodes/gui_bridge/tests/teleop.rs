//! The operator state machine and the waypoint files.
#![allow(clippy::unwrap_used)]

use eezybot_kinematics::Arm;
use gui_bridge::teleop::*;
use std::time::{Duration, Instant};

fn teleop() -> Teleop {
    Teleop::new(Arm::default(), 50.0)
}

#[test]
fn unreachable_targets_send_nothing_and_keep_the_target() {
    let mut t = teleop();
    let before = t.target();
    let e = t
        .handle_event(Event::SetTarget {
            xyz: [1.0, 0.0, 0.1],
        })
        .unwrap_err();
    assert!(e.to_string().contains("out of reach"));
    assert_eq!(t.target(), before);
    assert!(t.take_due(Instant::now()).is_empty());
}

#[test]
fn jog_moves_by_the_step_from_the_current_target() {
    let mut t = teleop();
    t.handle_event(Event::SetTarget {
        xyz: [0.2, 0.0, 0.15],
    })
    .unwrap();
    t.handle_event(Event::Jog {
        dxyz: [0.0, 0.01, 0.0],
    })
    .unwrap();
    let now = Instant::now();
    assert_eq!(t.take_due(now), vec![Command::Target([0.2, 0.01, 0.15])]);
}

#[test]
fn latest_wins_within_the_rate_limit() {
    let mut t = teleop();
    let t0 = Instant::now();
    t.handle_event(Event::SetTarget {
        xyz: [0.2, 0.0, 0.15],
    })
    .unwrap();
    assert_eq!(t.take_due(t0).len(), 1);
    for y in [0.01, 0.02, 0.03] {
        t.handle_event(Event::SetTarget {
            xyz: [0.2, y, 0.15],
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
        vec![Command::Target([0.2, 0.03, 0.15])]
    );
}

#[test]
fn estop_goes_out_at_once() {
    let mut t = teleop();
    t.handle_event(Event::SetTarget {
        xyz: [0.2, 0.0, 0.15],
    })
    .unwrap();
    let t0 = Instant::now();
    t.take_due(t0);
    t.handle_event(Event::Estop { engaged: true }).unwrap();
    assert_eq!(t.take_due(t0), vec![Command::Estop(true)]);
}

#[test]
fn joint_mode_checks_limits() {
    let mut t = teleop();
    assert!(t
        .handle_event(Event::Joints {
            positions: vec![("shoulder_joint".into(), 2.5)]
        })
        .is_err());
    assert!(t
        .handle_event(Event::Joints {
            positions: vec![("wrist_joint".into(), 0.0)]
        })
        .is_err());
    let f = t
        .handle_event(Event::Joints {
            positions: vec![("base_joint".into(), 0.2)],
        })
        .unwrap();
    assert!((f.joints.base_rad - 0.2).abs() < 1e-15);
}

#[test]
fn waypoints_roundtrip_and_name_bad_lines() {
    let w = vec![
        Waypoint {
            xyz: [0.2, 0.0, 0.15],
            gripper: Some(0.5),
            dwell_s: 1.0,
        },
        Waypoint {
            xyz: [0.18, 0.05, 0.12],
            gripper: None,
            dwell_s: 0.0,
        },
    ];
    let text = format!(
        "{WAYPOINT_HEADER}\n{}\n{}\n",
        format_waypoint(&w[0]),
        format_waypoint(&w[1])
    );
    assert_eq!(parse_waypoints(&text).unwrap(), w);
    assert!(parse_waypoints("0.2,0,0.15,2,0")
        .unwrap_err()
        .contains("line 1"));
    assert!(parse_waypoints("x,y,z,gripper,dwell\n0.2,zero,0.15,,0")
        .unwrap_err()
        .contains("line 2"));
}
