//! Property tests of the numerical IK: FK∘IK round trips on random reachable Jaco poses
//! for every solver, agreement with the EezyBot's closed form wherever it succeeds (and
//! failure wherever the target is out of reach), limits and the α/φ coupling kept,
//! nearest reachable points against brute force, undesirable-configuration directions.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
use common::load;
use eezybot_kinematics::assess::{assess, nearest_reachable, AssessOptions, Concern, ToolAxisAway};
use eezybot_kinematics::chain::{ChainBuilder, SerialChain};
use eezybot_kinematics::ik::{IkAlgorithm, IkSolver, Stopwatch, Target};
use eezybot_kinematics::rng::SplitMix64;
use eezybot_kinematics::{Arm, ArmJoints, KinematicsError};
use nalgebra::{Isometry3, Vector3};
use proptest::prelude::*;
use std::f64::consts::PI;
use std::sync::LazyLock;
use std::time::Duration;

/// `n` cases, or fewer when PROPTEST_CASES asks for fewer (tests/run_all.sh runs these
/// under qemu-aarch64, where an unreachable target's full restart budget is slow).
fn cases(n: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .map_or(n, |cap: u32| cap.min(n))
}

static JACO: LazyLock<SerialChain> = LazyLock::new(|| {
    SerialChain::from_model(&load("jaco.urdf"), "base_link", "jaco_end_effector").unwrap()
});
static EEZY: LazyLock<SerialChain> =
    LazyLock::new(|| Arm::default().serial_chain(&load("eezybot.urdf")).unwrap());

const ALGORITHMS: [IkAlgorithm; 3] = [
    IkAlgorithm::DampedLeastSquares,
    IkAlgorithm::NewtonRaphson,
    IkAlgorithm::PseudoInverse,
];
const HOME: [f64; 3] = [
    0.0,
    std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
];

fn solver(algorithm: IkAlgorithm, attempts: usize) -> IkSolver {
    let mut s = IkSolver::new(algorithm);
    s.options.max_attempts = attempts;
    s
}

fn pose_error(chain: &SerialChain, x: &[f64], goal: &Isometry3<f64>) -> (f64, f64) {
    let tip = chain.forward(x).unwrap();
    (
        (tip.translation.vector - goal.translation.vector).norm(),
        (tip.rotation.inverse() * goal.rotation)
            .scaled_axis()
            .norm(),
    )
}

fn smallest_singular_value(x: &[f64]) -> f64 {
    let (_, j) = JACO.jacobian(x).unwrap();
    j.svd(false, false).singular_values.min()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(100), max_global_rejects: 1_000_000, ..ProptestConfig::default() })]

    #[test]
    fn jaco_fk_of_ik_is_the_pose_for_every_solver(seed in any::<u64>()) {
        let mut rng = SplitMix64::new(seed);
        let goal = JACO.forward(&JACO.random_configuration(&mut rng)).unwrap();
        let start = JACO.random_configuration(&mut rng);
        for algorithm in ALGORITHMS {
            let s = solver(algorithm, 200);
            let sol = s.solve(&JACO, &Target::pose(goal), &start)
                .map_err(|e| TestCaseError::fail(format!("{algorithm:?}: {e}")))?;
            let (dp, dr) = pose_error(&JACO, &sol.joints, &goal);
            prop_assert!(dp <= 1e-5 && dr <= 1e-4, "{algorithm:?}: {dp} m, {dr} rad");
            prop_assert!((dp - sol.report.position_error_m).abs() < 1e-12);
            prop_assert!(JACO.within_limits(&sol.joints, 0.0), "{algorithm:?} left the limits");
            prop_assert!(sol.report.manipulability > 0.0);
        }
    }

    /// Away from singularities (the solvers' own `near_singular`: smallest singular
    /// value of the Jacobian under 0.01), where Newton-Raphson may need a restart: seed
    /// 6765700043639165130, smallest singular value 1.5e-4, stalled at 5e-5 m.
    #[test]
    fn jaco_warm_start_takes_few_iterations(seed in any::<u64>()) {
        let mut rng = SplitMix64::new(seed);
        let q = JACO.random_configuration(&mut rng);
        let mut near = q.clone();
        near.iter_mut().for_each(|v| *v += rng.uniform(-0.02, 0.02));
        JACO.project(&mut near);
        prop_assume!(smallest_singular_value(&q) > 0.01 && smallest_singular_value(&near) > 0.01);
        let goal = JACO.forward(&near).unwrap();
        for algorithm in ALGORITHMS {
            let sol = solver(algorithm, 1).solve(&JACO, &Target::pose(goal), &q).unwrap();
            prop_assert!(sol.report.iterations <= 10 && sol.report.attempts == 1,
                         "{algorithm:?}: {} iterations", sol.report.iterations);
        }
    }

    #[test]
    fn jaco_position_only_ignores_the_orientation(seed in any::<u64>()) {
        let mut rng = SplitMix64::new(seed);
        let p = JACO.forward(&JACO.random_configuration(&mut rng)).unwrap().translation.vector;
        let start = JACO.random_configuration(&mut rng);
        let sol = solver(IkAlgorithm::DampedLeastSquares, 50).solve(&JACO, &Target::position(p), &start).unwrap();
        let reached = JACO.forward(&sol.joints).unwrap().translation.vector;
        prop_assert!((reached - p).norm() <= 1e-5);
        prop_assert_eq!(sol.report.orientation_error_rad, 0.0);
    }
}

/// Targets in a box around the EezyBot's workspace: most are unreachable (ROBOT.md).
fn eezybot_target() -> impl Strategy<Value = Vector3<f64>> {
    (0.0f64..0.32, -0.25f64..0.25, 0.0f64..0.32).prop_map(|(x, y, z)| Vector3::new(x, y, z))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(200), ..ProptestConfig::default() })]

    #[test]
    fn eezybot_numerical_solvers_agree_with_the_closed_form(target in eezybot_target()) {
        let arm = Arm::default();
        let closed = arm.solve_position(&target, 0.0);
        for algorithm in ALGORITHMS {
            let mut s = solver(algorithm, 4);
            s.options.position_tolerance_m = 1e-12;
            let numeric = s.solve(&EEZY, &Target::position(target), &HOME);
            match (&closed, numeric) {
                (Ok(q), Ok(sol)) => {
                    let x = &sol.joints;
                    let p_closed = arm.forward(q);
                    let p_numeric = EEZY.forward(x).unwrap().translation.vector;
                    prop_assert!((p_numeric - p_closed).norm() <= 1e-9, "{algorithm:?}: {p_numeric:?} vs {p_closed:?}");
                    let d = [x[0] - q.base_rad, x[1] - q.shoulder_rad, x[2] - q.elbow_rad];
                    prop_assert!(d.iter().all(|v| v.abs() < 1e-7), "{algorithm:?}: joints differ by {d:?}");
                    prop_assert!(EEZY.within_limits(x, 0.0));
                }
                (Ok(q), Err(e)) => prop_assert!(false, "{algorithm:?} failed where the closed form gives {q:?}: {e}"),
                (Err(_), Ok(sol)) => {
                    // only on the boundary of the workspace, within the tolerance
                    let x = &sol.joints;
                    let q = ArmJoints { base_rad: x[0], shoulder_rad: x[1], elbow_rad: x[2] };
                    prop_assert!(arm.limits.check(&q).is_ok() && (arm.forward(&q) - target).norm() <= 1e-12);
                }
                (Err(_), Err(e)) => {
                    prop_assert!(matches!(e, KinematicsError::IkNotConverged { attempts: 4, .. }), "{e}");
                }
            }
        }
    }
}

#[test]
fn eezybot_solutions_keep_the_coupling_at_its_edges() {
    // Targets reached with φ exactly at its limits and the shoulder at its limits.
    let arm = Arm::default();
    let l = arm.limits;
    for (a, phi) in [
        (l.shoulder_rad.1, (-10f64).to_radians()),
        (1.6, l.forearm_elevation_rad.1 - 1e-12),
        (1.2, l.forearm_elevation_rad.0 + 1e-12),
    ] {
        let q = ArmJoints {
            base_rad: 0.2,
            shoulder_rad: a,
            elbow_rad: phi - a,
        };
        assert!(arm.limits.check(&q).is_ok(), "{q:?}");
        let target = arm.forward(&q);
        let mut s = solver(IkAlgorithm::DampedLeastSquares, 10);
        s.options.position_tolerance_m = 1e-12;
        let sol = s.solve(&EEZY, &Target::position(target), &HOME).unwrap();
        assert!(EEZY.within_limits(&sol.joints, 0.0));
        assert!(
            !sol.report.near_limits.is_empty(),
            "a limit is active: {:?}",
            sol.report
        );
        let closed = arm.solve_position(&target, 0.0).unwrap();
        assert!((sol.joints[1] - closed.shoulder_rad).abs() < 1e-7);
    }
}

#[test]
fn nearest_reachable_is_no_farther_than_brute_force() {
    let arm = Arm::default();
    let l = arm.limits;
    // every in-limit configuration on a grid (closed-form FK)
    let n = 48;
    let mut grid = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            for k in 0..=n {
                let t = |lim: (f64, f64), s: usize| lim.0 + (lim.1 - lim.0) * s as f64 / n as f64;
                let q = ArmJoints {
                    base_rad: t(l.base_rad, i),
                    shoulder_rad: t(l.shoulder_rad, j),
                    elbow_rad: t(l.elbow_rad, k),
                };
                if l.check(&q).is_ok() {
                    grid.push(arm.forward(&q));
                }
            }
        }
    }
    let mut rng = SplitMix64::new(11);
    let mut s = IkSolver::default();
    s.options.max_attempts = 8;
    let mut checked = 0;
    while checked < 30 {
        let target = Vector3::new(
            rng.uniform(-0.2, 0.5),
            rng.uniform(-0.4, 0.4),
            rng.uniform(-0.1, 0.45),
        );
        if arm.solve_position(&target, 0.0).is_ok() {
            continue;
        }
        checked += 1;
        let brute = grid
            .iter()
            .map(|p| (p - target).norm())
            .fold(f64::INFINITY, f64::min);
        let near = nearest_reachable(
            &EEZY,
            &target,
            &HOME,
            &s,
            &mut rng,
            &mut std::time::Instant::now(),
        )
        .unwrap();
        assert!(!near.reachable && EEZY.within_limits(&near.joints, 1e-12));
        assert!(
            (EEZY.forward(&near.joints).unwrap().translation.vector - near.position).norm() < 1e-15
        );
        assert!(
            near.distance_m <= brute + 1e-9,
            "{target:?}: nearest {} m, grid {} m",
            near.distance_m,
            brute
        );
    }
    // a reachable target is its own nearest point
    let p = arm.forward(&ArmJoints {
        base_rad: 0.1,
        shoulder_rad: 1.5,
        elbow_rad: -1.7,
    });
    let near = nearest_reachable(
        &EEZY,
        &p,
        &HOME,
        &s,
        &mut rng,
        &mut std::time::Instant::now(),
    )
    .unwrap();
    assert!(near.reachable && near.distance_m <= 1e-5);
}

#[test]
fn jaco_singularity_is_found_with_a_way_out() {
    // upright: shoulder and elbow aligned, the report's V-REP start pose
    let x = [PI, PI / 2.0, -PI / 2.0, 0.0, -PI, PI];
    let found = assess(&JACO, &x, &AssessOptions::pose(), &[]).unwrap();
    let Some(u) = found
        .iter()
        .find(|u| matches!(u.concern, Concern::NearSingular { .. }))
    else {
        panic!("upright is singular: {found:?}")
    };
    let m = |x: &[f64]| {
        let (_, j) = JACO.jacobian(x).unwrap();
        (j.clone() * j.transpose()).determinant().abs().sqrt()
    };
    let moved: Vec<f64> = x
        .iter()
        .zip(&u.direction)
        .map(|(a, d)| a + 0.05 * d)
        .collect();
    assert!(m(&moved) > m(&x) + 1e-6, "{} -> {}", m(&x), m(&moved));
    assert!((u.direction.iter().map(|d| d * d).sum::<f64>() - 1.0).abs() < 1e-9);
    // a solve that ends there says so
    let goal = JACO.forward(&x).unwrap();
    let sol = IkSolver::default()
        .solve(&JACO, &Target::pose(goal), &x)
        .unwrap();
    assert!(sol.report.near_singular && sol.report.min_singular_value < 1e-2);
}

#[test]
fn user_check_gripper_up_suggests_a_way_down() {
    let check = ToolAxisAway {
        name: "gripper_up".into(),
        axis: Vector3::z_axis(),
        forbidden: Vector3::z_axis(),
        min_angle_rad: 60f64.to_radians(),
    };
    let mut rng = SplitMix64::new(5);
    let mut found = 0;
    for _ in 0..2000 {
        let x = JACO.random_configuration(&mut rng);
        let tip = JACO.forward(&x).unwrap();
        let cost = eezybot_kinematics::assess::ConfigurationCheck::cost(&check, &tip, &x);
        let out = assess(&JACO, &x, &AssessOptions::pose(), &[&check]).unwrap();
        let hit = out
            .iter()
            .find(|u| matches!(u.concern, Concern::Check { .. }));
        assert_eq!(hit.is_some(), cost > 0.0);
        if let Some(u) = hit {
            found += 1;
            let moved: Vec<f64> = x
                .iter()
                .zip(&u.direction)
                .map(|(a, d)| a + 1e-3 * d)
                .collect();
            let after = eezybot_kinematics::assess::ConfigurationCheck::cost(
                &check,
                &JACO.forward(&moved).unwrap(),
                &moved,
            );
            assert!(after < cost, "{cost} -> {after}");
        }
    }
    assert!(found > 100, "only {found} configurations point up");
}

#[test]
fn preferred_orientation_keeps_the_position_exact() {
    // The Jaco with joint 6 locked: a 5-DOF arm that cannot reach every orientation.
    let model = load("jaco.urdf");
    let five = ChainBuilder::new(&model, "base_link", "jaco_end_effector")
        .limits("jaco_joint_6", 0.0, 0.0)
        .build()
        .unwrap();
    let mut rng = SplitMix64::new(9);
    for _ in 0..20 {
        let mut q = JACO.random_configuration(&mut rng);
        q[5] = rng.uniform(0.5, 1.0); // an orientation the locked arm cannot have
        let goal = JACO.forward(&q).unwrap();
        let start = five.random_configuration(&mut rng);
        let s = solver(IkAlgorithm::DampedLeastSquares, 20);
        assert!(s.solve(&five, &Target::pose(goal), &start).is_err());
        let plain = s
            .solve(&five, &Target::position(goal.translation.vector), &start)
            .unwrap();
        let preferred = s
            .solve(&five, &Target::pose_preferred(goal, 0.3), &start)
            .unwrap();
        let (dp, dr) = pose_error(&five, &preferred.joints, &goal);
        let (_, dr_plain) = pose_error(&five, &plain.joints, &goal);
        assert!(dp <= 1e-5, "position missed by {dp}");
        assert!(
            dr <= dr_plain + 1e-9,
            "orientation {dr} rad, position-only {dr_plain} rad"
        );
        assert!((preferred.report.orientation_error_rad - dr).abs() < 1e-3);
    }
}

struct FakeClock(Duration);

impl Stopwatch for FakeClock {
    fn elapsed(&mut self) -> Duration {
        self.0 += Duration::from_millis(1);
        self.0
    }
}

#[test]
fn failure_reports_the_residual_and_the_budget_stops_restarts() {
    let far = Target::position(Vector3::new(2.0, 0.0, 0.5));
    let mut s = IkSolver::default();
    s.options.max_attempts = 1000;
    s.options.time_budget = Some(Duration::from_millis(3));
    let err = s
        .solve_with_budget(
            &JACO,
            &far,
            &[0.0; 6],
            &mut SplitMix64::new(1),
            &mut FakeClock(Duration::ZERO),
        )
        .unwrap_err();
    match err {
        KinematicsError::IkNotConverged {
            position_error_m,
            attempts,
            ..
        } => {
            assert_eq!(attempts, 3);
            // the Jaco reaches about 0.98 m from its shoulder, 0.2755 m up
            assert!(
                position_error_m > 0.9 && position_error_m < 1.2,
                "{position_error_m}"
            );
        }
        other => panic!("{other}"),
    }
    let e = s.solve(&JACO, &far, &[0.0; 5]).unwrap_err();
    assert!(matches!(e, KinematicsError::DimensionMismatch { .. }));
    let e = s
        .solve(
            &JACO,
            &Target::position(Vector3::new(f64::NAN, 0.0, 0.0)),
            &[0.0; 6],
        )
        .unwrap_err();
    assert!(
        matches!(e, KinematicsError::NonFiniteValue { index: 0, .. }),
        "{e}"
    );
}

#[test]
fn same_inputs_same_answer() {
    let mut rng = SplitMix64::new(4);
    let goal = JACO.forward(&JACO.random_configuration(&mut rng)).unwrap();
    let s = solver(IkAlgorithm::DampedLeastSquares, 50);
    let a = s.solve(&JACO, &Target::pose(goal), &[0.0; 6]).unwrap();
    let b = s.solve(&JACO, &Target::pose(goal), &[0.0; 6]).unwrap();
    assert_eq!(a, b);
}
