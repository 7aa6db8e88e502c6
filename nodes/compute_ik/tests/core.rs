//! The IK node's logic without ROS.
#![allow(clippy::unwrap_used)]
use compute_ik::core::*;
use compute_ik::eezybot::*;
use compute_ik::pipeline::Step as Output;
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

/// The test's clock: the targets' stamp, so they are not old.
fn now() -> Time {
    Time::from_nanos(1_700_000_000_123_456_789)
}

fn target(x: f64, y: f64, z: f64, frame: &str) -> PointStamped {
    PointStamped {
        header: Header {
            stamp: now(),
            frame_id: frame.into(),
        },
        point: Point { x, y, z },
    }
}

/// Aim `c` at (x, y, z) in `frame`, stamped now.
fn aim(c: &mut IkCore, x: f64, y: f64, z: f64, frame: &str) -> Result<Output, Rejection> {
    c.handle_xyz_target(&target(x, y, z, frame), now())
}

/// Step the planned motion until the arm rests; the outputs of every step.
fn settle(c: &mut IkCore) -> Vec<Output> {
    let mut out = vec![];
    while let Some(o) = c.step(now()) {
        out.push(o);
        assert!(out.len() < 10_000, "never settles");
    }
    out
}

#[test]
fn reachable_target_gives_both_outputs_with_the_cause_stamp() {
    let mut c = core();
    let out = aim(&mut c, 0.2, 0.05, 0.15, "base_link").unwrap();
    assert_eq!(
        out.joint_states.header.stamp,
        Time::from_nanos(1_700_000_000_123_456_789)
    );
    assert_eq!(
        out.servo_angles.as_ref().unwrap().header.stamp,
        out.joint_states.header.stamp
    );
    assert_eq!(
        out.servo_angles.as_ref().unwrap().name,
        [
            "base_servo",
            "shoulder_servo",
            "elbow_servo",
            "gripper_servo"
        ]
    );
    assert_eq!(out.joint_states.name.len(), 11);
    // the first step leaves at once; the rest follow at the motion rate
    let out = settle(&mut c).pop().unwrap();
    let arm = Arm::default();
    let p = arm.forward(&c.state().joints);
    assert!((p - Vector3::new(0.2, 0.05, 0.15)).norm() < 1e-12);
    // servo mapping of ROBOT.md
    let q = c.state().joints;
    let deg: Vec<f64> = out
        .servo_angles
        .as_ref()
        .unwrap()
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
    assert!(aim(&mut core(), 0.2, 0.0, 0.15, "").is_ok());
}

#[test]
fn a_1mb_name_is_cut_in_the_rejection_and_diagnostics() {
    let huge = "x".repeat(1 << 20);
    let mut c = core();
    let joints = |names: Vec<String>| JointState {
        position: vec![0.0; names.len()],
        name: names,
        ..JointState::default()
    };
    let rejections = [
        aim(&mut c, 0.2, 0.0, 0.15, &huge),
        c.handle_joint_target(&joints(vec![huge.clone()]), now()),
        c.handle_joint_target(&joints(vec![huge.clone(), huge.clone()]), now()),
    ];
    for result in rejections {
        let text = result.unwrap_err().to_string();
        assert!(
            text.len() < 1024 && text.contains("xxxxxxxx… (1048576 bytes)"),
            "{}",
            &text[..text.len().min(300)]
        );
        let d = c.diagnostic_status("compute_ik");
        let longest = d.values.iter().map(|kv| kv.value.len()).max().unwrap_or(0);
        assert!(d.message.len() < 1024 && longest < 1024);
    }
    c.set_base_frame(&huge);
    let text = aim(&mut c, 0.2, 0.0, 0.15, "map").unwrap_err().to_string();
    assert!(text.len() < 1024, "{}", &text[..text.len().min(300)]);
}

#[test]
fn every_bad_input_is_refused_and_keeps_the_state() {
    let mut c = core();
    aim(&mut c, 0.2, 0.0, 0.15, "base_link").unwrap();
    settle(&mut c);
    let good = *c.state();
    let bad_joint = |names: &[&str], pos: &[f64]| JointState {
        name: names.iter().map(|s| s.to_string()).collect(),
        position: pos.to_vec(),
        ..JointState::default()
    };
    let cases: Vec<(Result<Output, Rejection>, &str)> = vec![
        (aim(&mut c, 1.0, 0.0, 0.15, "base_link"), "too_far"),
        (
            aim(&mut c, f64::NAN, 0.0, 0.15, "base_link"),
            "non_finite_target",
        ),
        (
            aim(&mut c, 0.2, f64::INFINITY, 0.15, "base_link"),
            "non_finite_target",
        ),
        (aim(&mut c, 0.2, 0.0, 0.15, "map"), "wrong_frame"),
        (
            aim(&mut c, -0.2, 0.0, 0.15, "base_link"),
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
            c.handle_joint_target(&bad_joint(&["wrist_joint"], &[0.0]), now()),
            "unknown_joint",
        ),
        (
            c.handle_joint_target(&bad_joint(&["base_joint"], &[]), now()),
            "length_mismatch",
        ),
        (
            c.handle_joint_target(&bad_joint(&[], &[]), now()),
            "no_joints",
        ),
        (
            c.handle_joint_target(
                &bad_joint(&["base_joint", "base_joint"], &[0.0, 0.1]),
                now(),
            ),
            "duplicate_joint",
        ),
        (
            c.handle_joint_target(&bad_joint(&["shoulder_joint"], &[f64::NAN]), now()),
            "non_finite_joint:shoulder_joint",
        ),
        (
            c.handle_joint_target(&bad_joint(&["shoulder_joint"], &[2.5]), now()),
            "out_of_limits:shoulder_joint",
        ),
        (
            c.handle_joint_target(&bad_joint(&["gripper_joint"], &[2.0]), now()),
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
            rejected: 14,
            stale: 0,
            superseded: 0,
            steps: c.counters().steps,
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
    c.handle_joint_target(&msg, now()).unwrap();
    let out = settle(&mut c).pop().unwrap();
    assert_eq!(c.state().joints.base_rad, 0.3);
    assert_eq!(c.state().joints.shoulder_rad, ArmJoints::HOME.shoulder_rad);
    assert!((c.state().gripper_opening - 0.5).abs() < 1e-12);
    assert!((out.servo_angles.as_ref().unwrap().position[3].to_degrees() - 120.0).abs() < 1e-9);
}

#[test]
fn estop_refuses_everything_until_released() {
    let mut c = core();
    c.set_estop(true);
    let r = aim(&mut c, 0.2, 0.0, 0.15, "").unwrap_err();
    assert_eq!(r.reason, Reason::EmergencyStop);
    assert_eq!(c.diagnostic_status("x").level, DiagnosticStatus::WARN);
    c.set_estop(false);
    assert!(aim(&mut c, 0.2, 0.0, 0.15, "").is_ok());
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

/// Servo angles (deg) of every output of a move: the first, then each step.
fn servo_trace(first: Output, rest: Vec<Output>) -> Vec<Vec<f64>> {
    std::iter::once(first)
        .chain(rest)
        .map(|o| {
            o.servo_angles
                .as_ref()
                .unwrap()
                .position
                .iter()
                .map(|r| r.to_degrees())
                .collect()
        })
        .collect()
}

/// Every servo's speed and acceleration along a trace stepped every `dt`, from rest at
/// `start`, within the shipped limits (300 deg/s, 1200 deg/s^2; the claw 500, 2000).
fn assert_within_servo_limits(start: &[f64], trace: &[Vec<f64>], dt: f64) {
    let limits = [
        (300.0, 1200.0),
        (300.0, 1200.0),
        (300.0, 1200.0),
        (500.0, 2000.0),
    ];
    let mut prev = start.to_vec();
    let mut prev_v = [0.0; 4];
    for (k, q) in trace.iter().enumerate() {
        for i in 0..4 {
            let v = (q[i] - prev[i]) / dt;
            let a = (v - prev_v[i]) / dt;
            assert!(
                v.abs() <= limits[i].0 * (1.0 + 1e-9) + 1e-9,
                "step {k} servo {i}: {v} deg/s"
            );
            assert!(
                a.abs() <= limits[i].1 * (1.0 + 1e-6) + 1e-6,
                "step {k} servo {i}: {a} deg/s^2"
            );
            prev_v[i] = v;
        }
        prev = q.clone();
    }
}

fn home_servos() -> Vec<f64> {
    vec![90.0, 90.0, 90.0, 60.0]
}

#[test]
fn a_jump_is_planned_as_a_motion_within_the_servo_limits() {
    // the measurement: a 30 deg base move was one servo_angles message
    let mut c = core();
    let msg = JointState {
        name: vec!["base_joint".into()],
        position: vec![30f64.to_radians()],
        ..JointState::default()
    };
    let first = c.handle_joint_target(&msg, now()).unwrap();
    assert!(c.is_moving());
    let rest = settle(&mut c);
    let trace = servo_trace(first, rest);
    // 60 deg of the base servo at 300 deg/s, ramped in 0.25 s: ~0.45 s, ~23 steps of 20 ms
    assert!(trace.len() > 15 && trace.len() < 40, "{}", trace.len());
    assert_within_servo_limits(&home_servos(), &trace, 0.02);
    assert!((trace.last().unwrap()[0] - 30.0).abs() < 1e-9);
    // the first step leaves at once, and small: one acceleration step
    assert!((trace[0][0] - 90.0).abs() < 1200.0 * 0.02 * 0.02 + 1e-9 && trace[0][0] < 90.0);
}

#[test]
fn a_new_target_mid_move_replans_from_the_current_state_within_the_limits() {
    let mut c = core();
    let first = aim(&mut c, 0.2, 0.08, 0.15, "").unwrap();
    let mut outs = vec![];
    for _ in 0..8 {
        outs.push(c.step(now()).unwrap());
    }
    outs.push(aim(&mut c, 0.16, -0.08, 0.22, "").unwrap());
    outs.extend(settle(&mut c));
    let trace = servo_trace(first, outs);
    assert_within_servo_limits(&home_servos(), &trace, 0.02);
    let p = Arm::default().forward(&c.state().joints);
    assert!((p - Vector3::new(0.16, -0.08, 0.22)).norm() < 1e-12);
}

#[test]
fn estop_stops_the_motion_where_it_is() {
    let mut c = core();
    aim(&mut c, 0.2, 0.08, 0.15, "").unwrap();
    for _ in 0..5 {
        c.step(now()).unwrap();
    }
    let here = *c.state();
    c.set_estop(true);
    assert!(c.step(now()).is_none());
    assert_eq!(*c.state(), here);
    c.set_estop(false);
    assert!(
        c.step(now()).is_none(),
        "moved after the release without a target"
    );
}

#[test]
fn old_targets_are_refused_and_a_zero_stamp_means_now() {
    let mut c = core();
    let mut old = target(0.2, 0.0, 0.15, "");
    old.header.stamp = Time::from_nanos(now().to_nanos() - 700_000_000);
    let r = c.handle_xyz_target(&old, now()).unwrap_err();
    assert_eq!(r.reason.code(), "stale");
    assert!(r.to_string().contains("0.700 s ago"), "{r}");
    assert_eq!(c.counters().stale, 1);
    assert!(!c.is_moving());
    let mut zero = target(0.2, 0.0, 0.15, "");
    zero.header.stamp = Time::ZERO;
    let out = c.handle_xyz_target(&zero, now()).unwrap();
    assert_eq!(out.joint_states.header.stamp, now());
    // 0 turns the check off
    c.set_motion(MotionSettings {
        max_target_age_s: 0.0,
        ..c.motion()
    });
    assert!(c.handle_xyz_target(&old, now()).is_ok());
}

#[test]
fn a_straight_line_is_followed_or_refused_before_the_move() {
    let mut c = core();
    c.set_motion(MotionSettings {
        mode: MotionMode::Line,
        ..c.motion()
    });
    aim(&mut c, 0.2, -0.1, 0.15, "").unwrap();
    settle(&mut c);
    // from (0.2, -0.1, 0.15) to (0.2, 0.1, 0.15): the tool stays on the segment
    let first = aim(&mut c, 0.2, 0.1, 0.15, "").unwrap();
    let arm = Arm::default();
    let mut outs = vec![first];
    outs.extend(settle(&mut c));
    let on_line = |o: &Output| {
        let q: Vec<f64> = o.joint_states.position.clone();
        let p = arm.forward(&ArmJoints {
            base_rad: q[0],
            shoulder_rad: q[1],
            elbow_rad: q[2],
        });
        (p.x - 0.2).abs().max((p.z - 0.15).abs())
    };
    let worst = outs.iter().map(on_line).fold(0.0, f64::max);
    assert!(worst < 2e-4, "the tool left the line by {worst} m");
    assert!(outs.len() > 10);
    // a line that crosses the unreachable region around the base's axis (r < 0.102 m
    // at this height): refused, nothing moves
    aim(&mut c, 0.08, 0.075, 0.15, "").unwrap();
    settle(&mut c);
    let before = *c.state();
    let r = aim(&mut c, 0.08, -0.075, 0.15, "");
    let err = r.unwrap_err();
    assert_eq!(err.reason.code(), "line_leaves_workspace", "{err}");
    assert!(err.to_string().contains("% along the line"), "{err}");
    assert!(!c.is_moving());
    assert_eq!(*c.state(), before);
}

/// `xyz_line_target` moves along a straight line whatever `motion` (here `joint`, the
/// default, under which `xyz_target` leaves the line); its refusal names its topic.
#[test]
fn xyz_line_target_follows_a_line_under_joint_motion() {
    use compute_ik::pipeline::Input;
    let arm = Arm::default();
    let off_line = |outs: &[Output]| {
        outs.iter()
            .map(|o| {
                let q = &o.joint_states.position;
                let p = arm.forward(&ArmJoints {
                    base_rad: q[0],
                    shoulder_rad: q[1],
                    elbow_rad: q[2],
                });
                (p.x - 0.2).abs().max((p.z - 0.15).abs())
            })
            .fold(0.0, f64::max)
    };
    let mut moves = vec![];
    for line in [false, true] {
        let mut c = core();
        assert_eq!(c.motion().mode, MotionMode::Joint);
        aim(&mut c, 0.2, -0.1, 0.15, "").unwrap();
        settle(&mut c);
        let msg = target(0.2, 0.1, 0.15, "");
        let input = if line {
            Input::XyzLineTarget(msg)
        } else {
            Input::XyzTarget(msg)
        };
        let mut outs = vec![c.handle(&input, now()).unwrap().unwrap()];
        outs.extend(settle(&mut c));
        moves.push(off_line(&outs));
    }
    let (joint, line) = (moves[0], moves[1]);
    assert!(line < 2e-4, "the tool left the line by {line} m");
    assert!(
        joint > 1e-2,
        "xyz_target moved in joint space, {joint} m off the line"
    );

    // a line across the unreachable region around the base's axis: refused, named
    let mut c = core();
    aim(&mut c, 0.08, 0.075, 0.15, "").unwrap();
    settle(&mut c);
    let err = c
        .handle(&Input::XyzLineTarget(target(0.08, -0.075, 0.15, "")), now())
        .unwrap()
        .unwrap_err();
    assert_eq!(err.reason.code(), "line_leaves_workspace", "{err}");
    assert_eq!(err.source, Source::XyzLineTarget);
    assert!(!c.is_moving());
}

#[test]
fn a_refusal_reads_back_through_ros_plumbing_feedback_with_its_code_and_stamp() {
    use eezybot_msgs::diagnostic_msgs::DiagnosticArray;
    use ros_plumbing::feedback::{self, Health, ReasonCode};
    let mut c = core();
    let read = |c: &IkCore| {
        let array = DiagnosticArray {
            status: vec![c.diagnostic_status("ik2: inverse kinematics")],
            ..Default::default()
        };
        feedback::decode(&array).remove(0)
    };
    let ok = read(&c);
    assert_eq!((ok.node.as_deref(), ok.health), (Some("ik2"), Health::Ok));
    assert!(ok.refusal.is_none(), "nothing refused yet");
    let cases = [
        (target(1.0, 0.0, 0.1, ""), ReasonCode::Unreachable),
        (target(0.2, 0.0, 0.15, "map"), ReasonCode::WrongFrame),
        (target(f64::NAN, 0.0, 0.15, ""), ReasonCode::NotFinite),
        (target(-0.2, 0.0, 0.15, ""), ReasonCode::OutOfLimits),
    ];
    for (i, (mut msg, code)) in cases.into_iter().enumerate() {
        msg.header.stamp = Time::from_nanos(now().to_nanos() - i as i64);
        let rejection = c.handle_xyz_target(&msg, now()).unwrap_err();
        let heard = read(&c);
        assert_eq!(heard.health, Health::Warn);
        let r = heard.refusal.unwrap();
        assert!(r.is_for(msg.header.stamp), "{r:?}");
        assert_eq!(r.code, code, "{rejection}");
        assert_eq!(r.reason, rejection.reason.to_string());
        assert_eq!(r.topic, "xyz_target");
    }
    c.set_estop(true);
    let mut msg = target(0.2, 0.0, 0.15, "");
    msg.header.stamp = Time::from_nanos(now().to_nanos() - 100);
    c.handle_xyz_target(&msg, now()).unwrap_err();
    assert_eq!(read(&c).refusal.unwrap().code, ReasonCode::Estop);
    c.set_estop(false);
    c.set_motion(MotionSettings {
        max_target_age_s: 0.5,
        ..c.motion()
    });
    let mut old = target(0.2, 0.0, 0.15, "");
    old.header.stamp = Time::from_nanos(now().to_nanos() - 2_000_000_000);
    c.handle_xyz_target(&old, now()).unwrap_err();
    let r = read(&c).refusal.unwrap();
    assert!(r.is_for(old.header.stamp));
    assert_eq!(r.code, ReasonCode::Stale);
}
