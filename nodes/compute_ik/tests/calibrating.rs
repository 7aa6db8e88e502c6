//! Calibrating on the node's loop policy ([`Driver`]), on a fixed clock as in
//! `tests/driver.rs`: the calibration wizard takes the arm by activating `calibration`
//! through `controller_manager/switch_controller` (deactivating whoever held it), as
//! gui_bridge does; meanwhile nothing is published and every target is refused;
//! deactivated, the arm is taken where `servo_state` says it is.
#![allow(clippy::unwrap_used, clippy::expect_used)]
mod common;
use arm_config_file::calibration_text;
use common::*;
use compute_ik::core::Source;
use compute_ik::driver::{Driver, Effect};
use compute_ik::eezybot::EezyBot;
use compute_ik::pipeline::GoalRequest;
use compute_ik::Input;
use eezybot_kinematics::ServoCalibrations;
use eezybot_msgs::builtin_interfaces::Duration as RosDuration;
use eezybot_msgs::control_msgs::FollowJointTrajectoryGoal;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::trajectory_msgs::{JointTrajectory, JointTrajectoryPoint};
use eezybot_msgs::Time;
use ros_plumbing::action::{GoalEnd, GoalId, Ticket};
use ros_plumbing::{ParameterValue, Params};
use std::collections::BTreeMap;
use std::time::Duration;

/// The node's parameters at their defaults, with `arm_config`.
fn params(arm_config: &str) -> Params {
    let mut values: BTreeMap<String, ParameterValue> = compute_ik::spec()
        .params
        .iter()
        .map(|s| (s.name.to_string(), s.default.clone()))
        .collect();
    values.insert(
        "arm_config".into(),
        ParameterValue::String(arm_config.to_string()),
    );
    Params::new(values)
}

/// Nothing is due but the end of the calibration's lease, taken at `taken_ms` (no step
/// planned: the wizard's caller renews the lease, this test does not).
fn only_the_lease_is_due(d: &Driver<EezyBot>, clock: &Clock, taken_ms: u64) {
    let (taken, _) = clock.at(ms(taken_ms));
    assert_eq!(d.deadline(), Some(taken + arbiter::DEFAULT_OWNER_LEASE));
}

/// The calibration wizard takes the arm (`calibration` activated, whoever is active
/// deactivated, in one strict switch) or gives it back, as gui_bridge does; with
/// `arm_config`, the new calibration is set first (the wizard's save).
fn calibrate(
    d: &mut Driver<EezyBot>,
    on: bool,
    arm_config: Option<&str>,
    now: std::time::Instant,
    wall: Time,
) -> Vec<Effect> {
    let mut e = vec![];
    if let Some(config) = arm_config {
        e.extend(d.on_params(&params(config), now, wall));
    }
    let input = if on {
        let holders = active(d, now, wall);
        let others: Vec<&str> = holders
            .iter()
            .map(String::as_str)
            .filter(|n| *n != "calibration")
            .collect();
        switch(1, &["calibration"], &others)
    } else {
        switch(2, &[], &["calibration"])
    };
    e.extend(d.on_inputs(vec![input], now, wall));
    e
}

fn joint_target(stamp: Time, joints: &[(&str, f64)]) -> Input {
    Input::JointTarget(JointState {
        header: Header {
            stamp,
            frame_id: String::new(),
        },
        name: joints.iter().map(|(n, _)| n.to_string()).collect(),
        position: joints.iter().map(|(_, v)| *v).collect(),
        ..Default::default()
    })
}

const SERVOS: [&str; 4] = [
    "base_servo",
    "shoulder_servo",
    "elbow_servo",
    "gripper_servo",
];

/// A `servo_state` at these horn angles (deg).
fn servo_state(deg: [f64; 4]) -> Input {
    Input::ServoState(JointState {
        name: SERVOS.map(String::from).to_vec(),
        position: deg.map(f64::to_radians).to_vec(),
        ..Default::default()
    })
}

fn diag_value(d: &Driver<EezyBot>, key: &str) -> String {
    d.core()
        .diagnostic_status("compute_ik")
        .values
        .into_iter()
        .find(|kv| kv.key == key)
        .unwrap_or_else(|| panic!("no {key} in diagnostics"))
        .value
}

/// Every effect of the driver's deadlines until `until`.
fn run_until(d: &mut Driver<EezyBot>, clock: &Clock, until: Duration) -> Vec<Effect> {
    let mut out = vec![];
    while let Some(t) = d.deadline().filter(|t| *t <= clock.t0 + until) {
        out.extend(d.on_time(t, clock.wall(t - clock.t0)));
        assert!(out.len() < 10_000, "never settles");
    }
    out
}

fn trajectory(to: [f64; 3], secs: f64) -> JointTrajectory {
    JointTrajectory {
        joint_names: ARM.map(String::from).to_vec(),
        points: vec![JointTrajectoryPoint {
            positions: to.to_vec(),
            time_from_start: RosDuration::from_secs_f64(secs),
            ..Default::default()
        }],
        ..Default::default()
    }
}

fn goal(n: u64, to: [f64; 3], secs: f64) -> Input {
    Input::TrajectoryGoal(GoalRequest {
        ticket: Ticket(n),
        id: GoalId::ZERO,
        goal: Box::new(FollowJointTrajectoryGoal {
            trajectory: trajectory(to, secs),
            ..Default::default()
        }),
    })
}

fn home(d: &Driver<EezyBot>) -> [f64; 3] {
    let js = d.core().joint_states(Time::ZERO);
    ARM.map(|n| position(&js, n))
}

#[test]
fn calibrating_stops_a_running_motion_and_publishes_nothing_more() {
    let clock = Clock::new();
    let mut d = driver();
    let (now, wall) = clock.at(ms(0));
    assert_eq!(
        published(&d.on_inputs(vec![xyz(0.2, 0.1, 0.15, wall)], now, wall)).len(),
        1
    );
    // a few steps on its way
    let before = run_until(&mut d, &clock, ms(100));
    assert!(!published(&before).is_empty());
    assert!(d.core().is_moving());
    let pose = d.core().joint_states(Time::ZERO);
    let (now, wall) = clock.at(ms(105));
    let e = calibrate(&mut d, true, None, now, wall);
    assert!(published(&e).is_empty(), "{e:?}");
    assert!(e.contains(&Effect::Report), "{e:?}");
    assert!(d.core().calibrating());
    assert!(!d.core().is_moving());
    only_the_lease_is_due(&d, &clock, 105);
    let after = run_until(&mut d, &clock, ms(5000));
    assert!(published(&after).is_empty(), "{after:?}");
    assert_eq!(
        d.core().joint_states(Time::ZERO).position,
        pose.position,
        "held where it was"
    );
    // asked again: refused (active already), nothing published
    let (now, wall) = clock.at(ms(200));
    let e = calibrate(&mut d, true, None, now, wall);
    assert!(published(&e).is_empty(), "{e:?}");
    assert_eq!(switched(&e).map(|(ok, _)| ok), Some(false), "{e:?}");
}

#[test]
fn while_calibrating_targets_are_refused_with_reason_calibrating() {
    let clock = Clock::new();
    let mut d = driver();
    let (now, wall) = clock.at(ms(0));
    calibrate(&mut d, true, None, now, wall);
    let cases: Vec<(Input, Source)> = vec![
        (xyz(0.2, 0.0, 0.15, wall), Source::XyzTarget),
        (
            joint_target(wall, &[("base_joint", 0.3)]),
            Source::JointTarget,
        ),
        (Input::GripperTarget(0.5, wall), Source::GripperTarget),
    ];
    for (i, (input, source)) in cases.into_iter().enumerate() {
        let (now, wall) = clock.at(ms(200 * (i as u64 + 1)));
        let rejected = d.core().counters().rejected;
        let e = d.on_inputs(vec![input], now, wall);
        assert!(published(&e).is_empty(), "{source:?}: {e:?}");
        assert!(e.contains(&Effect::Report), "{source:?}: {e:?}");
        assert_eq!(d.core().counters().rejected, rejected + 1);
        let r = d.core().last_rejection().unwrap();
        assert_eq!(
            (r.source, r.reason.code().as_str()),
            (source, "calibrating")
        );
        assert!(r.reason.to_string().contains("calibrat"), "{}", r.reason);
    }
    only_the_lease_is_due(&d, &clock, 0);
    // the e-stop's reason comes first when both hold
    let (now, wall) = clock.at(ms(1000));
    d.on_inputs(vec![Input::Estop(true)], now, wall);
    let (now, wall) = clock.at(ms(1200));
    d.on_inputs(vec![xyz(0.2, 0.0, 0.15, wall)], now, wall);
    assert_eq!(d.core().last_rejection().unwrap().reason.code(), "estop");
}

#[test]
fn while_calibrating_trajectories_are_rejected_and_a_running_goal_is_aborted() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let (now, wall) = clock.at(ms(0));
    // a goal running when calibrating starts is aborted
    let e = d.on_inputs(vec![goal(1, [h[0] + 0.3, h[1], h[2]], 2.0)], now, wall);
    assert!(
        e.iter()
            .any(|e| matches!(e, Effect::AnswerGoal { accepted: true, .. })),
        "{e:?}"
    );
    run_until(&mut d, &clock, ms(200));
    let (now, wall) = clock.at(ms(205));
    let e = calibrate(&mut d, true, None, now, wall);
    assert!(
        e.iter()
            .any(|e| matches!(e, Effect::TrajectoryResult(id, GoalEnd::Aborted, _) if *id == GoalId::ZERO)),
        "{e:?}"
    );
    assert!(published(&e).is_empty());
    assert_eq!(d.controller_values()[0].1, "idle");
    assert!(run_until(&mut d, &clock, ms(5000)).is_empty());
    // a new goal is rejected, saying why
    let (now, wall) = clock.at(ms(6000));
    let e = d.on_inputs(vec![goal(2, [h[0] - 0.2, h[1], h[2]], 2.0)], now, wall);
    assert!(
        e.iter().any(|e| matches!(
            e,
            Effect::AnswerGoal {
                accepted: false,
                gripper: false,
                ..
            }
        )),
        "{e:?}"
    );
    assert!(!e
        .iter()
        .any(|e| matches!(e, Effect::AnswerGoal { accepted: true, .. })));
    assert!(published(&e).is_empty());
    let why = controller_value(&d, "last_trajectory");
    assert!(
        why.contains("INVALID_GOAL") && why.contains("calibrat"),
        "{why}"
    );
    // and one on the topic
    let (now, wall) = clock.at(ms(6100));
    let e = d.on_inputs(
        vec![Input::Trajectory(trajectory([h[0] - 0.2, h[1], h[2]], 2.0))],
        now,
        wall,
    );
    assert!(published(&e).is_empty());
    only_the_lease_is_due(&d, &clock, 205);
}

#[test]
fn while_calibrating_a_leader_arm_is_not_followed() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let leader = |q: [f64; 3]| {
        Input::LeaderJoints(JointState {
            name: ARM.map(String::from).to_vec(),
            position: q.to_vec(),
            ..Default::default()
        })
    };
    let (now, wall) = clock.at(ms(0));
    calibrate(&mut d, true, None, now, wall);
    for k in 1..10 {
        let (now, wall) = clock.at(ms(10 * k));
        let e = d.on_inputs(
            vec![Input::LeaderDeadman(true), leader([h[0] + 0.3, h[1], h[2]])],
            now,
            wall,
        );
        assert!(published(&e).is_empty(), "{e:?}");
        assert!(published(&run_until(&mut d, &clock, ms(10 * k + 5))).is_empty());
    }
    assert!(
        leader_value(&d).contains("calibrating"),
        "{}",
        leader_value(&d)
    );
}

#[test]
fn diagnostics_report_calibrating() {
    let clock = Clock::new();
    let mut d = driver();
    assert_eq!(diag_value(&d, "calibrating"), "false");
    let (now, wall) = clock.at(ms(0));
    calibrate(&mut d, true, None, now, wall);
    assert_eq!(diag_value(&d, "calibrating"), "true");
    let status = d.core().diagnostic_status("compute_ik");
    assert!(status.message.contains("calibrating"), "{}", status.message);
    assert_eq!(
        status.level,
        eezybot_msgs::diagnostic_msgs::DiagnosticStatus::WARN
    );
    let (now, wall) = clock.at(ms(100));
    calibrate(&mut d, false, None, now, wall);
    assert_eq!(diag_value(&d, "calibrating"), "false");
    assert!(!d.core().calibrating());
}

/// A copy of the shipped configuration whose base horn sits 7° further (offset 97°).
struct TempConfig(std::path::PathBuf);

impl TempConfig {
    fn new(tag: &str, servos: &ServoCalibrations) -> TempConfig {
        let dir = std::env::temp_dir().join(format!(
            "compute_ik_calibrating_{tag}_{}",
            std::process::id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let shipped = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../config/arm.yaml"
        ))
        .unwrap();
        let text = calibration_text(&shipped, servos, None).unwrap();
        let path = dir.join("arm.yaml");
        std::fs::write(&path, text).unwrap();
        TempConfig(dir)
    }
    fn path(&self) -> String {
        self.0.join("arm.yaml").display().to_string()
    }
}

impl Drop for TempConfig {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn ending_calibrating_takes_the_arm_where_servo_state_says_through_the_new_calibration() {
    let clock = Clock::new();
    let mut d = driver();
    let (now, wall) = clock.at(ms(0));
    calibrate(&mut d, true, None, now, wall);
    // the wizard leaves the arm at base 10°, main arm 80°, forearm φ −20°, claw half
    // open, as the new calibration (the base's horn 7° off) reads it
    let mut servos = ServoCalibrations::default();
    servos.base.offset_deg = 97.0;
    let config = TempConfig::new("new", &servos);
    let deg = [
        97.0 - 2.0 * 10.0,
        180.0 - 80.0,
        90.0 - 20.0,
        60.0 + 120.0 * 0.5,
    ];
    let (now, wall) = clock.at(ms(100));
    let e = d.on_inputs(vec![servo_state(deg)], now, wall);
    assert!(published(&e).is_empty(), "nothing while calibrating: {e:?}");
    // arm_config set, then calibration given back (the wizard's save)
    let (now, wall) = clock.at(ms(200));
    let e = calibrate(&mut d, false, Some(&config.path()), now, wall);
    let steps: Vec<_> = e
        .iter()
        .filter_map(|e| match e {
            Effect::Publish(s) => Some(s),
            _ => None,
        })
        .collect();
    assert_eq!(steps.len(), 1, "one step: {e:?}");
    assert!(e.contains(&Effect::Report));
    let js = &steps[0].joint_states;
    assert_eq!(js.header.stamp, wall);
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
    assert!(
        close(position(js, "base_joint"), 10f64.to_radians()),
        "base {} rad: read through the shipped calibration it would be 6.5°",
        position(js, "base_joint")
    );
    assert!(close(position(js, "shoulder_joint"), 80f64.to_radians()));
    assert!(close(
        position(js, "elbow_joint"),
        (-20f64 - 80.0).to_radians()
    ));
    assert!(close(position(js, "gripper_joint"), 0.5 * 0.6));
    // the servos stay where they are
    let angles = steps[0].servo_angles.as_ref().unwrap();
    for (name, want) in SERVOS.iter().zip(deg) {
        let got = position(angles, name).to_degrees();
        assert!((got - want).abs() < 1e-6, "{name}: {got} vs {want}");
    }
    assert!(!d.core().calibrating());
    assert!(!d.core().is_moving());
    assert_eq!(diag_value(&d, "calibrating"), "false");
    // targets are taken again, from there
    let (now, wall) = clock.at(ms(300));
    let e = d.on_inputs(vec![joint_target(wall, &[("base_joint", 0.0)])], now, wall);
    assert_eq!(published(&e).len(), 1, "{e:?}");
    let out = run_until(&mut d, &clock, ms(10_000));
    let last = published(&out).last().copied().unwrap().clone();
    assert!(close(position(&last, "base_joint"), 0.0));
    assert!(close(position(&last, "shoulder_joint"), 80f64.to_radians()));
    let (now, wall) = clock.at(ms(10_100));
    let e = d.on_inputs(vec![xyz(0.2, 0.0, 0.15, wall)], now, wall);
    assert_eq!(published(&e).len(), 1, "{e:?}");
    assert!(d.core().is_moving());
}

#[test]
fn ending_calibrating_clamps_a_reported_pose_outside_the_limits() {
    let clock = Clock::new();
    let mut d = driver();
    let (now, wall) = clock.at(ms(0));
    calibrate(&mut d, true, None, now, wall);
    // the main arm at 130° (servo 50°), past its 125° limit; the forearm horizontal
    let deg = [90.0, 180.0 - 130.0, 90.0 + 0.0, 60.0];
    let (now, wall) = clock.at(ms(100));
    d.on_inputs(vec![servo_state(deg)], now, wall);
    let (now, wall) = clock.at(ms(200));
    let e = calibrate(&mut d, false, None, now, wall);
    let js = published(&e);
    assert_eq!(js.len(), 1, "{e:?}");
    let shoulder = position(js[0], "shoulder_joint").to_degrees();
    assert!(shoulder <= 125.0 + 1e-9, "{shoulder}: inside its limit");
}

#[test]
fn ending_calibrating_without_servo_state_publishes_nothing_and_takes_targets_again() {
    let clock = Clock::new();
    let mut d = driver();
    let (now, wall) = clock.at(ms(0));
    calibrate(&mut d, true, None, now, wall);
    // a servo_state without every servo is not a pose
    let (now, wall) = clock.at(ms(50));
    d.on_inputs(
        vec![Input::ServoState(JointState {
            name: vec!["base_servo".into()],
            position: vec![1.0],
            ..Default::default()
        })],
        now,
        wall,
    );
    let (now, wall) = clock.at(ms(100));
    let e = calibrate(&mut d, false, None, now, wall);
    assert!(published(&e).is_empty(), "{e:?}");
    assert_eq!(switched(&e), Some((true, String::new())), "{e:?}");
    assert!(!d.core().calibrating());
    let (now, wall) = clock.at(ms(200));
    let e = d.on_inputs(vec![xyz(0.2, 0.0, 0.15, wall)], now, wall);
    assert_eq!(published(&e).len(), 1, "{e:?}");
}

#[test]
fn a_calibration_whose_caller_went_silent_is_given_back_after_the_lease_and_diagnostics_say_so() {
    let clock = Clock::new();
    let mut d = driver();
    let (now, wall) = clock.at(ms(0));
    calibrate(&mut d, true, None, now, wall);
    // the wizard lists the controllers every 2 s: it keeps the arm past the lease
    for t in (2000..=14_000).step_by(2000) {
        run_until(&mut d, &clock, ms(t));
        let (now, wall) = clock.at(ms(t));
        active(&mut d, now, wall);
    }
    assert!(d.core().calibrating());
    // then nothing from it (gui_bridge killed): the arm is given back at the lease's end
    run_until(
        &mut d,
        &clock,
        ms(14_000) + arbiter::DEFAULT_OWNER_LEASE - ms(1),
    );
    assert!(d.core().calibrating());
    run_until(&mut d, &clock, ms(14_000) + arbiter::DEFAULT_OWNER_LEASE);
    assert!(!d.core().calibrating());
    let why = controller_value(&d, "last_switch_controller");
    assert!(
        why.contains("calibration deactivated") && why.contains("within the lease"),
        "{why}"
    );
    // and compute_ik takes targets again
    let (now, wall) = clock.at(ms(30_000));
    let e = d.on_inputs(vec![xyz(0.2, 0.0, 0.15, wall)], now, wall);
    assert_eq!(published(&e).len(), 1, "{e:?}");
}
