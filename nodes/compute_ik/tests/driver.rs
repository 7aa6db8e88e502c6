//! The node's loop policy ([`Driver`]) on a fixed clock: every event is handed its
//! time, as `servo_protocol::host`'s tests do, so nothing here waits or reads a clock.
#![allow(clippy::unwrap_used, clippy::expect_used)]
mod common;
use common::*;
use compute_ik::core::Source;
use compute_ik::driver::{Driver, Effect, MIN_IMMEDIATE_DIAG_GAP};
use compute_ik::eezybot::EezyBot;
use compute_ik::urdf_arm::{UrdfArm, UrdfCore};
use compute_ik::Input;
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::ArmConfig;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use std::time::Duration;

fn reports(effects: &[Effect]) -> usize {
    effects.iter().filter(|e| **e == Effect::Report).count()
}

/// Run the driver's deadlines until nothing is due; the effects with their times.
fn run_until_idle(d: &mut Driver<EezyBot>, clock: &Clock) -> Vec<(Duration, Effect)> {
    let mut out = vec![];
    while let Some(t) = d.deadline() {
        let since = t - clock.t0;
        let effects = d.on_time(t, clock.wall(since));
        out.extend(effects.into_iter().map(|e| (since, e)));
        assert!(out.len() < 10_000, "never settles");
    }
    out
}

#[test]
fn a_target_goes_at_once_then_steps_every_period_after_one_and_a_half_and_reports_at_rest() {
    let clock = Clock::new();
    let mut d = driver();
    let (now, wall) = clock.at(ms(1000));
    let first = d.on_inputs(vec![xyz(0.2, 0.1, 0.15, wall)], now, wall);
    assert_eq!(published(&first).len(), 1, "{first:?}");
    assert_eq!(
        published(&first)[0].header.stamp,
        wall,
        "the first step carries the target's stamp"
    );
    assert_eq!(reports(&first), 0);
    assert_eq!(d.deadline(), Some(now + ms(30)), "1.5 periods of 20 ms");
    let rest = run_until_idle(&mut d, &clock);
    let steps: Vec<Duration> = rest
        .iter()
        .filter_map(|(t, e)| matches!(e, Effect::Publish(_)).then_some(*t))
        .collect();
    assert!(steps.len() > 5, "{} steps", steps.len());
    assert_eq!(steps[0], ms(1030));
    for w in steps.windows(2) {
        assert_eq!(w[1] - w[0], ms(20), "one step a period");
    }
    // each step stamped when it is planned; the end of the motion is reported once
    let (last_t, last) = rest.last().unwrap();
    assert_eq!((*last_t, last), (*steps.last().unwrap(), &Effect::Report));
    assert_eq!(rest.iter().filter(|(_, e)| *e == Effect::Report).count(), 1);
    assert!(!d.core().is_moving());
    assert_eq!(d.deadline(), None);
}

#[test]
fn of_targets_that_arrive_together_the_newest_wins_and_the_rest_are_counted() {
    let clock = Clock::new();
    let mut d = driver();
    let (now, wall) = clock.at(ms(10));
    let burst = vec![
        xyz(0.2, 0.1, 0.15, wall),
        xyz(0.2, 0.0, 0.15, wall),
        xyz(0.2, -0.1, 0.15, wall),
    ];
    let effects = d.on_inputs(burst, now, wall);
    assert_eq!(published(&effects).len(), 1);
    assert_eq!(d.core().counters().superseded, 2);
    assert_eq!(d.core().counters().accepted, 1);
    let goal = d.core().goal().joints;
    assert!(
        goal.base_rad < 0.0,
        "the last one (y < 0) is the goal: {goal:?}"
    );
}

#[test]
fn a_late_target_is_held_for_a_newer_one_and_the_newest_applied_at_the_deadline() {
    let clock = Clock::new();
    let mut d = driver();
    // live targets, received 2 ms after their stamps: the usual delay
    for i in 0..5u64 {
        let (now, wall) = clock.at(ms(20 * i));
        let stamp = clock.wall(ms(20 * i).saturating_sub(ms(2)));
        let e = d.on_inputs(vec![xyz(0.2, 0.0, 0.15, stamp)], now, wall);
        assert_eq!(published(&e).len(), 1);
    }
    run_until_idle(&mut d, &clock);
    // after an outage: two targets stamped 0.4 s before they arrive, one after the other
    let (now, wall) = clock.at(ms(5000));
    let old = |y: f64, back: u64| xyz(0.2, y, 0.15, clock.wall(ms(5000 - back)));
    let held = d.on_inputs(vec![old(0.1, 400)], now, wall);
    assert!(held.is_empty(), "held back: {held:?}");
    let deadline = d.deadline().unwrap();
    let (now2, wall2) = clock.at(ms(5010));
    assert!(d.on_inputs(vec![old(-0.1, 390)], now2, wall2).is_empty());
    assert_eq!(
        d.deadline(),
        Some(deadline),
        "a newer late target does not extend the wait"
    );
    assert_eq!(d.core().counters().superseded, 1);
    assert!(d.on_time(deadline - ms(1), clock.wall(ms(5029))).is_empty());
    let applied = d.on_time(deadline, clock.wall(deadline - clock.t0));
    assert_eq!(published(&applied).len(), 1);
    assert!(
        d.core().goal().joints.base_rad < 0.0,
        "the newest of the two"
    );
}

#[test]
fn refusals_are_reported_at_once_at_most_every_100_ms() {
    let clock = Clock::new();
    let mut d = driver();
    let mut at = |t: u64| {
        let (now, wall) = clock.at(ms(t));
        reports(&d.on_inputs(vec![xyz(2.0, 0.0, 0.15, wall)], now, wall))
    };
    assert_eq!(at(0), 1);
    assert_eq!(at(50), 0, "within {MIN_IMMEDIATE_DIAG_GAP:?} of the last");
    assert_eq!(at(100), 1);
    assert_eq!(d.core().counters().rejected, 3);
    let r = d.core().last_rejection().unwrap();
    assert_eq!(
        (r.source, r.reason.code().as_str()),
        (Source::XyzTarget, "too_far")
    );
}

#[test]
fn the_estop_stops_the_motion_at_once_and_refuses_targets_until_released() {
    let clock = Clock::new();
    let mut d = driver();
    let (now, wall) = clock.at(ms(0));
    d.on_inputs(vec![xyz(0.2, 0.1, 0.15, wall)], now, wall);
    assert!(d.core().is_moving());
    let (now, wall) = clock.at(ms(10));
    let e = d.on_inputs(vec![Input::Estop(true)], now, wall);
    assert_eq!(e, vec![Effect::Report]);
    assert!(
        !d.core().is_moving() && d.deadline().is_none(),
        "no step after the e-stop"
    );
    let (now, wall) = clock.at(ms(20));
    assert!(
        d.on_inputs(vec![Input::Estop(true)], now, wall).is_empty(),
        "no change, no report"
    );
    let (now, wall) = clock.at(ms(500));
    let refused = d.on_inputs(vec![xyz(0.2, 0.0, 0.15, wall)], now, wall);
    assert_eq!((published(&refused).len(), reports(&refused)), (0, 1));
    assert_eq!(d.core().last_rejection().unwrap().reason.code(), "estop");
    let (now, wall) = clock.at(ms(600));
    assert_eq!(
        d.on_inputs(vec![Input::Estop(false)], now, wall),
        vec![Effect::Report]
    );
    let (now, wall) = clock.at(ms(700));
    assert_eq!(
        published(&d.on_inputs(vec![xyz(0.2, 0.0, 0.15, wall)], now, wall)).len(),
        1
    );
}

#[test]
fn a_new_joint_states_subscriber_gets_the_pose_over_four_polls() {
    let clock = Clock::new();
    let mut d = driver();
    let wall = clock.wall(ms(0));
    // (controller_state comes at every poll too, without a servo_state)
    let greet = |e: Vec<Effect>| match e.as_slice() {
        [Effect::ControllerState(_), Effect::JointStates(js)] => js.header.stamp == wall,
        [Effect::ControllerState(_)] => false,
        other => panic!("{other:?}"),
    };
    let (a, b, c) = ([1; 16], [2; 16], [3; 16]);
    assert!(greet(d.on_poll(&[a], wall)));
    for _ in 0..3 {
        assert!(greet(d.on_poll(&[a], wall)));
    }
    assert!(!greet(d.on_poll(&[a], wall)), "four polls, then quiet");
    assert!(!greet(d.on_poll(&[], wall)), "one leaving is not greeted");
    assert!(greet(d.on_poll(&[b], wall)), "one more is");
    for _ in 0..3 {
        d.on_poll(&[b], wall);
    }
    assert!(!greet(d.on_poll(&[b], wall)));
    // one left and another came between two polls: still one, and a new one
    assert!(greet(d.on_poll(&[c], wall)), "a replacement is greeted");
}

#[test]
fn a_urdf_arm_runs_the_same_pipeline_and_publishes_no_servo_angles() {
    let clock = Clock::new();
    let model = RobotModel::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../urdf/jaco.urdf"
    )))
    .unwrap();
    let core = UrdfCore::new(UrdfArm::new(model, "", "").unwrap(), "base_link").unwrap();
    let mut d = Driver::new(core);
    let (now, wall) = clock.at(ms(0));
    let e = d.on_inputs(vec![Input::GripperTarget(0.5, wall)], now, wall);
    assert_eq!(reports(&e), 1);
    assert_eq!(
        d.core().last_rejection().unwrap().reason.code(),
        "no_gripper"
    );
    let js = JointState {
        name: vec!["jaco_joint_1".into()],
        position: vec![0.3],
        ..Default::default()
    };
    let (now, wall) = clock.at(ms(200));
    let e = d.on_inputs(vec![Input::JointTarget(js)], now, wall);
    match e.as_slice() {
        [Effect::Publish(step)] => assert!(step.servo_angles.is_none()),
        other => panic!("{other:?}"),
    }
}

// ---- arm_controller (trajectories) ----

use eezybot_msgs::builtin_interfaces::Duration as RosDuration;
use eezybot_msgs::trajectory_msgs::{JointTrajectory, JointTrajectoryPoint};

fn arm_joints(js: &JointState) -> [f64; 3] {
    ARM.map(|n| position(js, n))
}

fn trajectory(points: &[([f64; 3], f64)]) -> Input {
    Input::Trajectory(JointTrajectory {
        joint_names: ARM.map(String::from).to_vec(),
        points: points
            .iter()
            .map(|(p, t)| JointTrajectoryPoint {
                positions: p.to_vec(),
                time_from_start: RosDuration::from_secs_f64(*t),
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    })
}

/// The home pose's arm joints.
fn home(d: &Driver<EezyBot>) -> [f64; 3] {
    arm_joints(&d.core().joint_states(Time::ZERO))
}

fn last_published(effects: &[(Duration, Effect)]) -> &JointState {
    effects
        .iter()
        .rev()
        .find_map(|(_, e)| match e {
            Effect::Publish(s) => Some(&s.joint_states),
            _ => None,
        })
        .expect("something published")
}

#[test]
fn a_trajectory_on_the_topic_runs_in_time_and_ends_exactly_at_its_last_point() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let end = [h[0] + 0.3, h[1] + 0.1, h[2] - 0.1];
    let (t0, w0) = clock.at(ms(0));
    let first = d.on_inputs(vec![trajectory(&[(end, 1.0)])], t0, w0);
    // the first step at once (still at the start: t = 0)
    let step = published(&first);
    assert_eq!(step.len(), 1);
    let out = run_until_idle(&mut d, &clock);
    let steps: Vec<(Duration, [f64; 3])> = out
        .iter()
        .filter_map(|(t, e)| match e {
            Effect::Publish(s) => Some((*t, arm_joints(&s.joint_states))),
            _ => None,
        })
        .collect();
    // linear between the start and the point: halfway at 0.5 s
    let (_, half) = steps.iter().find(|(t, _)| *t >= ms(500)).unwrap();
    assert!((half[0] - (h[0] + 0.15)).abs() < 0.01, "{half:?}");
    assert_eq!(
        arm_joints(last_published(&out)).map(|v| (v * 1e9).round()),
        end.map(|v| (v * 1e9).round())
    );
    let done = steps
        .iter()
        .position(|(_, q)| (q[0] - end[0]).abs() < 1e-12)
        .unwrap();
    assert!(
        steps[done].0 >= ms(1000) && steps[done].0 <= ms(1020),
        "{:?}",
        steps[done].0
    );
}

#[test]
fn a_refused_trajectory_moves_nothing_and_says_why() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let (t0, w0) = clock.at(ms(0));
    let too_fast = trajectory(&[([h[0] + 0.5, h[1], h[2]], 0.05)]);
    let effects = d.on_inputs(vec![too_fast], t0, w0);
    assert!(published(&effects).is_empty());
    assert_eq!(reports(&effects), 1);
    assert!(d.deadline().is_none());
    let why = controller_value(&d, "last_trajectory");
    assert!(
        why.contains("INVALID_GOAL")
            && why.contains("base servo")
            && why.contains("velocity limit"),
        "{why}"
    );
}

#[test]
fn a_target_during_a_trajectory_takes_the_arm_and_is_reached() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let (t0, w0) = clock.at(ms(0));
    d.on_inputs(vec![trajectory(&[([h[0] + 0.4, h[1], h[2]], 2.0)])], t0, w0);
    // 300 ms into the trajectory
    while let Some(t) = d.deadline().filter(|t| *t <= clock.t0 + ms(300)) {
        d.on_time(t, clock.wall(t - clock.t0));
    }
    let (t1, w1) = clock.at(ms(300));
    let effects = d.on_inputs(vec![xyz(0.15, -0.05, 0.12, w1)], t1, w1);
    assert_eq!(published(&effects).len(), 1, "the target's first step");
    let out = run_until_idle(&mut d, &clock);
    // the same target alone, from rest at home, ends at the same joints
    let mut alone = driver();
    alone.on_inputs(vec![xyz(0.15, -0.05, 0.12, w0)], t0, w0);
    let alone_out = run_until_idle(&mut alone, &clock);
    let (a, b) = (
        arm_joints(last_published(&out)),
        arm_joints(last_published(&alone_out)),
    );
    assert!(
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9),
        "{a:?} vs {b:?}"
    );
    assert!(d.controller_values()[0].1 == "idle");
}

#[test]
fn a_gripper_target_during_a_trajectory_moves_the_claw_and_the_trajectory_goes_on() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let end = [h[0] - 0.2, h[1], h[2]];
    let (t0, w0) = clock.at(ms(0));
    d.on_inputs(vec![trajectory(&[(end, 1.0)])], t0, w0);
    let (t1, w1) = clock.at(ms(200));
    while let Some(t) = d.deadline().filter(|t| *t <= t1) {
        d.on_time(t, clock.wall(t - clock.t0));
    }
    d.on_inputs(vec![Input::GripperTarget(1.0, w1)], t1, w1);
    let out = run_until_idle(&mut d, &clock);
    let last = last_published(&out);
    assert!(
        arm_joints(last)
            .iter()
            .zip(end)
            .all(|(a, b)| (a - b).abs() < 1e-9),
        "{last:?}"
    );
    assert!(
        (position(last, "gripper_joint") - ArmConfig::default().geometry.gripper_open_rad).abs()
            < 1e-9
    );
}

#[test]
fn servo_state_reports_in_a_burst_are_not_counted_as_superseded_targets() {
    let clock = Clock::new();
    let mut d = driver();
    let (t0, w0) = clock.at(ms(0));
    let report = |deg: f64| {
        Input::ServoState(JointState {
            name: [
                "base_servo",
                "shoulder_servo",
                "elbow_servo",
                "gripper_servo",
            ]
            .map(String::from)
            .to_vec(),
            position: vec![deg.to_radians(), 1.5, 1.5, 1.0],
            ..Default::default()
        })
    };
    let burst = vec![
        report(90.0),
        xyz(0.2, 0.0, 0.15, w0),
        report(91.0),
        xyz(0.2, 0.01, 0.15, w0),
        report(92.0),
    ];
    d.on_inputs(burst, t0, w0);
    let c = d.core().counters();
    assert_eq!((c.received, c.superseded), (1, 1), "{c:?}");
}

// ---- following a leader arm ----

fn leader(q: [f64; 3]) -> Input {
    Input::LeaderJoints(JointState {
        name: ARM.map(String::from).to_vec(),
        position: q.to_vec(),
        ..Default::default()
    })
}

/// Steps published until `until` (run by the driver's own deadlines).
fn steps_until(
    d: &mut Driver<EezyBot>,
    clock: &Clock,
    until: Duration,
) -> Vec<(Duration, [f64; 3])> {
    let mut out = vec![];
    while let Some(t) = d.deadline().filter(|t| *t <= clock.t0 + until) {
        let since = t - clock.t0;
        for e in d.on_time(t, clock.wall(since)) {
            if let Effect::Publish(s) = e {
                out.push((since, arm_joints(&s.joint_states)));
            }
        }
    }
    out
}

#[test]
fn the_follower_follows_the_leader_only_while_the_deadman_is_held() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let far = [h[0] + 0.4, h[1], h[2]];
    let (t0, w0) = clock.at(ms(0));
    // deadman released: samples are not followed
    assert!(published(&d.on_inputs(vec![leader(far)], t0, w0)).is_empty());
    assert!(
        leader_value(&d).starts_with("holding"),
        "{}",
        leader_value(&d)
    );
    let (t1, w1) = clock.at(ms(10));
    let e = d.on_inputs(vec![Input::LeaderDeadman(true), leader(far)], t1, w1);
    assert_eq!(published(&e).len(), 1, "held: followed at once");
    assert_eq!(leader_value(&d), "following");
    // samples every 10 ms, as the leader firmware sends them, for 200 ms
    for k in 2..22 {
        let (t, w) = clock.at(ms(10 * k));
        steps_until(&mut d, &clock, ms(10 * k));
        d.on_inputs(vec![Input::LeaderDeadman(true), leader(far)], t, w);
    }
    let moving = arm_joints(&d.core().joint_states(Time::ZERO));
    assert!(
        moving[0] > h[0] + 0.05 && moving[0] < far[0],
        "{moving:?}: on its way, within the motion limits"
    );
    // released: the arm holds where it is at once, no further step
    let (t, w) = clock.at(ms(215));
    let e = d.on_inputs(vec![Input::LeaderDeadman(false)], t, w);
    assert!(published(&e).is_empty());
    let held = arm_joints(&d.core().joint_states(Time::ZERO));
    assert!(
        steps_until(&mut d, &clock, ms(2000)).is_empty(),
        "a step after the release"
    );
    assert_eq!(arm_joints(&d.core().joint_states(Time::ZERO)), held);
    assert!(leader_value(&d).contains("deadman released"));
}

#[test]
fn without_leader_samples_the_follower_holds_after_the_timeout() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let far = [h[0] - 0.4, h[1], h[2]];
    let (t0, w0) = clock.at(ms(0));
    d.on_inputs(vec![Input::LeaderDeadman(true), leader(far)], t0, w0);
    // the cable is pulled after the first sample: steps go on until the timeout, not after
    let steps = steps_until(&mut d, &clock, ms(2000));
    let last = steps.last().unwrap().0;
    assert!(
        last < ms(50) + ms(1),
        "a step at {last:?}, after the 50 ms timeout"
    );
    assert!(
        leader_value(&d).contains("no leader sample for 50 ms"),
        "{}",
        leader_value(&d)
    );
    let q = arm_joints(&d.core().joint_states(Time::ZERO));
    assert!(q[0] > far[0] && q[0] < h[0], "{q:?}: held on its way");
}

// ---- who moves the arm: the arbiter, and the controller manager's services ----

#[test]
fn while_the_leader_is_followed_a_target_is_refused_as_held_and_moves_nothing() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let far = [h[0] + 0.4, h[1], h[2]];
    let (t0, w0) = clock.at(ms(0));
    d.on_inputs(vec![Input::LeaderDeadman(true), leader(far)], t0, w0);
    assert_eq!(leader_value(&d), "following");
    let (t1, w1) = clock.at(ms(10));
    let e = d.on_inputs(vec![xyz(0.2, -0.1, 0.15, w1), leader(far)], t1, w1);
    let r = d.core().last_rejection().expect("refused");
    assert_eq!(r.reason.code(), "held");
    assert!(
        r.reason.to_string().contains("leader_follower"),
        "{}",
        r.reason
    );
    assert!(reports(&e) >= 1);
    // the leader's motion goes on toward its pose, untouched by the target
    let steps = steps_until(&mut d, &clock, ms(40));
    assert!(steps.iter().all(|(_, q)| q[0] > h[0] - 1e-9), "{steps:?}");
    assert_eq!(active(&mut d, t1, w1), ["leader_follower"]);
    // released: the next target takes the arm
    let (t2, w2) = clock.at(ms(50));
    d.on_inputs(vec![Input::LeaderDeadman(false)], t2, w2);
    let (t3, w3) = clock.at(ms(60));
    let e = d.on_inputs(vec![xyz(0.2, -0.1, 0.15, w3)], t3, w3);
    assert_eq!(published(&e).len(), 1, "taken: {e:?}");
    assert_eq!(active(&mut d, t3, w3), ["teleop"]);
}

#[test]
fn a_switch_that_deactivates_arm_controller_stops_its_trajectory_where_it_is() {
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let (t0, w0) = clock.at(ms(0));
    d.on_inputs(vec![trajectory(&[([h[0] + 0.5, h[1], h[2]], 2.0)])], t0, w0);
    assert_eq!(
        active(&mut d, t0, w0),
        ["arm_controller", "gripper_controller"]
    );
    steps_until(&mut d, &clock, ms(300));
    let (t1, w1) = clock.at(ms(305));
    // a strict switch that would claim the arm twice: refused, the trajectory goes on
    let e = d.on_inputs(vec![switch(1, &["teleop"], &[])], t1, w1);
    let (ok, message) = switched(&e).expect("answered");
    assert!(!ok && message.contains("double_claim"), "{message}");
    assert!(
        !steps_until(&mut d, &clock, ms(400)).is_empty(),
        "still running"
    );
    let (t2, w2) = clock.at(ms(405));
    let e = d.on_inputs(vec![switch(2, &["teleop"], &["arm_controller"])], t2, w2);
    assert_eq!(switched(&e), Some((true, String::new())));
    let held = arm_joints(&d.core().joint_states(Time::ZERO));
    assert!(
        steps_until(&mut d, &clock, ms(3000)).is_empty(),
        "no step after the switch"
    );
    assert_eq!(arm_joints(&d.core().joint_states(Time::ZERO)), held);
    assert_eq!(active(&mut d, t2, w2), ["teleop", "gripper_controller"]);
    assert!(controller_value(&d, "last_switch_controller") == "done");
}

/// The claw's servo angle (deg) of a published step.
fn claw_deg(effect: &Effect) -> Option<f64> {
    match effect {
        Effect::Publish(s) => s.servo_angles.as_ref().map(|m| {
            let i = m.name.iter().position(|n| n == "gripper_servo").unwrap();
            m.position[i].to_degrees()
        }),
        _ => None,
    }
}

/// A trajectory that starts while a gripper goal moves the claw (the core's planner
/// moving it, the arm idle) takes the claw on from where it is: no step of the claw's
/// servo is longer than its speed allows in a period (found by tests/soak/switching.py:
/// the claw jumped back 85° to where the gripper goal had started).
#[test]
fn a_trajectory_started_during_a_gripper_goal_takes_the_claw_on_from_where_it_is() {
    use compute_ik::pipeline::GoalRequest;
    use eezybot_msgs::control_msgs::{GripperCommand, GripperCommandGoal};
    let clock = Clock::new();
    let mut d = driver();
    let h = home(&d);
    let (t0, w0) = clock.at(ms(0));
    let open = ArmConfig::default().geometry.gripper_open_rad;
    let goal = Input::GripperGoal(GoalRequest {
        ticket: ros_plumbing::action::Ticket(1),
        id: ros_plumbing::action::GoalId::ZERO,
        goal: Box::new(GripperCommandGoal {
            command: GripperCommand {
                position: open,
                max_effort: 0.0,
            },
        }),
    });
    let mut steps: Vec<f64> = d
        .on_inputs(vec![goal], t0, w0)
        .iter()
        .filter_map(claw_deg)
        .collect();
    let (t1, w1) = clock.at(ms(200));
    while let Some(t) = d.deadline().filter(|t| *t <= t1) {
        let e = d.on_time(t, clock.wall(t - clock.t0));
        steps.extend(e.iter().filter_map(claw_deg));
    }
    let moved = steps.last().unwrap() - steps.first().unwrap();
    assert!(moved.abs() > 20.0, "the claw is under way: {steps:?}");
    let end = [h[0] - 0.2, h[1], h[2]];
    let e = d.on_inputs(vec![trajectory(&[(end, 1.0)])], t1, w1);
    steps.extend(e.iter().filter_map(claw_deg));
    steps.extend(
        run_until_idle(&mut d, &clock)
            .iter()
            .filter_map(|(_, e)| claw_deg(e)),
    );
    let max_step = ArmConfig::default().motion.gripper.max_velocity_deg_s * 0.02;
    for (a, b) in steps.iter().zip(&steps[1..]) {
        assert!(
            (b - a).abs() <= max_step + 1e-6,
            "the claw stepped {a} -> {b} deg: {steps:?}"
        );
    }
    let last = steps.last().unwrap();
    assert!(
        (last - 180.0).abs() < 1e-6,
        "the gripper goal got there: {last}"
    );
}
