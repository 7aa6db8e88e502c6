//! The twin's physics against the kinematics and the servos' datasheets, on simulated
//! time only (no clock is read: the host's load cannot change a result).
#![cfg(feature = "mujoco")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use eezybot_kinematics::rng::SplitMix64;
use eezybot_kinematics::{ArmConfig, ArmJoints, ArmState};
use nalgebra::Vector3;
use twin::sim::Sim;
use twin_model::Scene;

const URDF: &str = include_str!("../../../urdf/eezybot.urdf");

fn sim() -> (Sim, ArmConfig) {
    let config = ArmConfig::shipped().unwrap();
    (Sim::new(URDF, &config, &Scene::default()).unwrap(), config)
}

/// The horn angles (rad) the shipped calibration gives an arm state.
fn horns(config: &ArmConfig, q: ArmJoints, opening: f64) -> [f64; 4] {
    config
        .servos
        .servo_angles(&ArmState {
            joints: q,
            gripper_opening: opening,
        })
        .unwrap()
        .rad
}

#[test]
fn fk_agrees_with_the_kinematics_and_the_loops_stay_closed_at_20_held_out_poses() {
    let (mut sim, config) = sim();
    let arm = config.arm();
    let limits = config.limits_deg.to_radians();
    let mut rng = SplitMix64::new(35);
    let mut checked = 0;
    let mut worst = (0.0f64, 0.0f64);
    while checked < 20 {
        let q = ArmJoints {
            base_rad: rng.uniform(limits.base_rad.0, limits.base_rad.1),
            shoulder_rad: rng.uniform(limits.shoulder_rad.0, limits.shoulder_rad.1),
            elbow_rad: rng.uniform(limits.elbow_rad.0, limits.elbow_rad.1),
        };
        if limits.check(&q).is_err() {
            continue; // outside the coupled forearm limits: not a pose of the arm
        }
        sim.pose(&q, 0.0);
        sim.set_horn_targets(horns(&config, q, 0.0).map(Some));
        sim.run(0.3).unwrap();
        // the twin's tool point against the kinematics' FK of the twin's own joint
        // angles (where gravity and the servos' stiffness left them)
        let fk = arm.forward(&sim.arm_joints());
        let err = (sim.tool0() - fk).norm();
        let loops = sim.loop_errors().into_iter().fold(0.0, f64::max);
        assert!(
            err <= 1e-3,
            "pose {q:?}: tool0 {} mm from the FK",
            err * 1e3
        );
        assert!(
            loops <= 1e-3,
            "pose {q:?}: a loop open by {} mm",
            loops * 1e3
        );
        worst = (worst.0.max(err), worst.1.max(loops));
        checked += 1;
    }
    eprintln!(
        "FK error at most {:.3} mm, loop closure error at most {:.3} mm",
        worst.0 * 1e3,
        worst.1 * 1e3
    );
}

/// Simulated seconds from a step of `servo`'s horn target by `step_deg` to its horn's
/// first coming within 1° of the target.
fn step_time(sim: &mut Sim, servo: usize, step_deg: f64) -> f64 {
    let mut targets = sim.horns().map(Some);
    let target = sim.horns()[servo] + step_deg.to_radians();
    targets[servo] = Some(target);
    sim.set_horn_targets(targets);
    let start = sim.time();
    while (sim.horns()[servo] - target).abs() > 1f64.to_radians() {
        sim.step().unwrap();
        assert!(sim.time() - start < 2.0, "the servo never got there");
    }
    sim.time() - start
}

#[test]
fn a_60_degree_step_of_the_base_servo_takes_0_2_s() {
    let (mut sim, _) = sim();
    sim.run(0.2).unwrap();
    // the MG995's 0.2 s/60°, at its horn: through the 2:1 gear, 30° of base_joint
    let before = sim.joint("base_joint").unwrap();
    let t = step_time(&mut sim, 0, -60.0);
    let turned = (sim.joint("base_joint").unwrap() - before).to_degrees();
    eprintln!("60° base servo step: {t:.3} s (base_joint turned {turned:.1}°)");
    assert!((0.18..=0.22).contains(&t), "{t} s");
    assert!((turned - 30.0).abs() < 1.0, "{turned}°");
}

/// A ramp of the shoulder servo's horn target at `deg_per_s` over 60°, then 0.3 s
/// more: the largest lag of the horn behind its target during the ramp (deg), and the
/// lag at its end.
fn ramp_lag(deg_per_s: f64) -> (f64, f64) {
    let (mut sim, config) = sim();
    // from α = 110° down to 50°, the forearm held at φ = −20°: inside every limit
    let q = ArmJoints {
        base_rad: 0.0,
        shoulder_rad: 110f64.to_radians(),
        elbow_rad: -130f64.to_radians(),
    };
    sim.pose(&q, 0.0);
    let start_horns = horns(&config, q, 0.0);
    sim.set_horn_targets(start_horns.map(Some));
    sim.run(0.2).unwrap();
    let t0 = sim.time();
    let duration = 60.0 / deg_per_s;
    let mut worst: f64 = 0.0;
    let mut lag_at_end = 0.0;
    while sim.time() - t0 < duration {
        let s = (sim.time() - t0).min(duration) * deg_per_s;
        let mut targets = start_horns.map(Some);
        // the main-arm servo's horn: 180° − α, so it lowers the arm as it grows
        let target = start_horns[1] + s.to_radians();
        targets[1] = Some(target);
        sim.set_horn_targets(targets);
        sim.step().unwrap();
        lag_at_end = (target - sim.horns()[1]).to_degrees();
        worst = worst.max(lag_at_end.abs());
    }
    (worst, lag_at_end)
}

#[test]
fn a_trajectory_within_the_servo_speed_tracks_and_a_faster_one_lags() {
    // half the MG995's rated speed: the servo keeps up
    let (slow, _) = ramp_lag(150.0);
    // twice it: the servo cannot
    let (fast, fast_end) = ramp_lag(600.0);
    eprintln!("lag behind a 60° ramp: at 150°/s at most {slow:.2}°, at 600°/s {fast:.1}° (end {fast_end:.1}°)");
    assert!(slow < 4.0, "{slow}°");
    // at 300°/s at most, the horn is about 30° behind a 0.1 s ramp at 600°/s
    assert!(fast > 20.0, "{fast}°");
}

/// How far the tool hangs below where the kinematics puts it for the servos' targets
/// (m), at full reach, with the main-arm servo's stall torque scaled by `scale`.
fn sag_at_full_reach(scale: f64) -> f64 {
    let (mut sim, config) = sim();
    // full reach (0.279 m): the main arm at its lowest limit, the forearm as high as the
    // elbow's limit lets it
    let q = ArmJoints {
        base_rad: 0.0,
        shoulder_rad: 45f64.to_radians(),
        elbow_rad: -60f64.to_radians(),
    };
    sim.set_torque_scale(1, scale);
    sim.pose(&q, 0.0);
    sim.set_horn_targets(horns(&config, q, 0.0).map(Some));
    sim.run(1.0).unwrap();
    config.arm().forward(&q).z - sim.tool0().z
}

#[test]
fn with_half_the_shoulder_torque_the_arm_sags_at_full_reach() {
    let full = sag_at_full_reach(1.0);
    let half = sag_at_full_reach(0.5);
    eprintln!(
        "sag at full reach: {:.2} mm with the MG995's torque, {:.2} mm with half",
        full * 1e3,
        half * 1e3
    );
    // (seen: 1.5 mm and 2.2 mm; the arm is light, 0.8 N·m of stall torque holds it)
    assert!(
        full >= 0.0 && half > full + 0.3e-3,
        "full {full} m, half {half} m"
    );
}

/// A scripted pick of the cube at `cube_xy` (the scene's stand moved with it): open,
/// move over it, lower, close, lift 5 cm. The cube's rise (m).
fn pick(cube_xy: [f64; 2]) -> f64 {
    let config = ArmConfig::shipped().unwrap();
    let scene = Scene {
        cube_xy,
        ..Scene::default()
    };
    let mut sim = Sim::new(URDF, &config, &scene).unwrap();
    let arm = config.arm();
    let (cube0, _) = sim.cube_pose();
    // the claw's fingers hang 6 mm below tool0: grip the cube at its middle
    let grip = Vector3::new(cube0.x, cube0.y, cube0.z + 0.006);
    let above = grip + Vector3::new(0.0, 0.0, 0.05);
    let go = |sim: &mut Sim, from: ArmState, to: ArmState, seconds: f64| {
        // a straight line in joint space, as compute_ik's planner would send it
        let (a, b) = (
            horns(&config, from.joints, from.gripper_opening),
            horns(&config, to.joints, to.gripper_opening),
        );
        let t0 = sim.time();
        while sim.time() - t0 < seconds {
            let s = ((sim.time() - t0) / (seconds * 0.8)).min(1.0);
            sim.set_horn_targets(std::array::from_fn(|i| Some(a[i] + (b[i] - a[i]) * s)));
            sim.step().unwrap();
        }
        to
    };
    let at = |p: Vector3<f64>, opening: f64| ArmState {
        joints: arm.solve_position(&p, 0.0).unwrap(),
        gripper_opening: opening,
    };
    let home = ArmState::default();
    let now = go(
        &mut sim,
        home,
        ArmState {
            gripper_opening: 1.0,
            ..home
        },
        0.5,
    );
    let now = go(&mut sim, now, at(above, 1.0), 1.0);
    let now = go(&mut sim, now, at(grip, 1.0), 0.8);
    let now = go(&mut sim, now, at(grip, 0.0), 0.6);
    go(
        &mut sim,
        now,
        at(grip + Vector3::new(0.0, 0.0, 0.05), 0.0),
        1.0,
    );
    sim.run(0.5).unwrap();
    sim.cube_pose().0.z - cube0.z
}

#[test]
fn a_scripted_pick_lifts_the_cube_5_cm_in_19_of_20_seeded_trials() {
    let mut rng = SplitMix64::new(2035);
    let mut lifted = 0;
    let mut rises = Vec::new();
    for _ in 0..20 {
        let xy = [0.2 + rng.uniform(-0.01, 0.01), rng.uniform(-0.03, 0.03)];
        let rise = pick(xy);
        rises.push(rise);
        if rise >= 0.045 {
            lifted += 1;
        }
    }
    eprintln!(
        "pick: {lifted}/20 lifted ≥ 45 mm; rises (mm): {:?}",
        rises.iter().map(|r| (r * 1e3).round()).collect::<Vec<_>>()
    );
    assert!(lifted >= 19, "{lifted}/20");
}

#[test]
fn an_unstable_simulation_stops_with_the_reason_and_stays_stopped() {
    let (mut sim, _) = sim();
    sim.run(0.05).unwrap();
    // far beyond anything physical: MuJoCo resets its state and warns; the twin stops
    sim.set_joint_velocity("shoulder_joint", 1e12);
    let e = sim.step().unwrap_err().to_string();
    assert!(e.contains("unstable") && e.contains("velocity"), "{e}");
    assert!(
        sim.step().is_err(),
        "it stays stopped: no made-up angles after a reset"
    );
}

#[test]
fn limp_servos_let_the_arm_droop_against_their_gear_friction_only() {
    let (mut sim, _) = sim();
    sim.run(0.2).unwrap();
    let held = sim.tool0();
    sim.set_horn_targets([None; 4]);
    sim.run(1.0).unwrap();
    let limp = sim.tool0();
    eprintln!(
        "without pulses the tool moved {:.1} mm",
        (limp - held).norm() * 1e3
    );
    // unpowered, the arm is not held in place as a powered one is
    assert!((limp - held).norm() > 1e-3);
}
