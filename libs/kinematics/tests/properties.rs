//! Property tests of the kinematics invariants (ROBOT.md).
#![allow(
    clippy::unwrap_used,
    clippy::unnecessary_lazy_evaluations,
    clippy::single_match
)]

use eezybot_kinematics::{Arm, ArmJoints, Joint, KinematicsError};
use nalgebra::Vector3;
use proptest::prelude::*;

fn arm() -> Arm {
    Arm::default()
}

/// Joint angles inside every limit, the α/φ coupling included.
fn in_limits() -> impl Strategy<Value = ArmJoints> {
    let l = arm().limits;
    (
        l.base_rad.0..=l.base_rad.1,
        l.shoulder_rad.0..=l.shoulder_rad.1,
        0.0f64..=1.0,
    )
        .prop_filter_map(
            "forearm elevation outside its limits",
            move |(base_rad, shoulder_rad, t)| {
                // pick φ inside both its own limits and the elbow limits for this α
                let lo = l.forearm_elevation_rad.0.max(shoulder_rad + l.elbow_rad.0);
                let hi = l.forearm_elevation_rad.1.min(shoulder_rad + l.elbow_rad.1);
                (lo <= hi).then(|| ArmJoints {
                    base_rad,
                    shoulder_rad,
                    elbow_rad: lo + t * (hi - lo) - shoulder_rad,
                })
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 20_000, ..ProptestConfig::default() })]

    #[test]
    fn fk_of_ik_is_the_target(q in in_limits()) {
        let arm = arm();
        let p = arm.forward(&q);
        let q2 = arm.solve_position(&p, 0.0).map_err(|e| TestCaseError::fail(format!("{p:?}: {e}")))?;
        let err = (arm.forward(&q2) - p).norm();
        prop_assert!(err <= 1e-12, "FK(IK(p)) misses p by {err} m");
    }

    #[test]
    fn ik_of_fk_is_the_joints(q in in_limits()) {
        let arm = arm();
        let q2 = arm.solve_position(&arm.forward(&q), 0.0).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert!((q2.base_rad - q.base_rad).abs() < 1e-9);
        prop_assert!((q2.shoulder_rad - q.shoulder_rad).abs() < 1e-9, "{q:?} vs {q2:?}");
        prop_assert!((q2.elbow_rad - q.elbow_rad).abs() < 1e-9, "{q:?} vs {q2:?}");
    }

}

proptest! {
    #![proptest_config(ProptestConfig { cases: 5_000, max_global_rejects: 200_000, ..ProptestConfig::default() })]

    /// One limit violated (the unique elbow-down solution is the one sampled), so the
    /// refusal must name exactly that limit.
    #[test]
    fn one_violated_limit_is_named(q in in_limits(), which in 0usize..4, excess in 0.001f64..0.5, upper in any::<bool>()) {
        let arm = arm();
        let l = arm.limits;
        let mut bad = q;
        let expected = match which {
            0 => { bad.base_rad = if upper { l.base_rad.1 + excess } else { l.base_rad.0 - excess }; Joint::Base }
            1 => {
                // move α alone beyond its limit, keeping φ: elbow follows
                let phi = q.forearm_elevation_rad();
                bad.shoulder_rad = if upper { l.shoulder_rad.1 + excess } else { l.shoulder_rad.0 - excess };
                bad.elbow_rad = phi - bad.shoulder_rad;
                Joint::Shoulder
            }
            2 => { bad.elbow_rad = if upper { l.elbow_rad.1 + excess } else { l.elbow_rad.0 - excess }; Joint::Elbow }
            _ => {
                let phi = if upper { l.forearm_elevation_rad.1 + excess } else { l.forearm_elevation_rad.0 - excess };
                bad.elbow_rad = phi - q.shoulder_rad;
                Joint::ForearmElevation
            }
        };
        // Keep only samples where exactly the intended row fails, on the physical branch.
        prop_assume!(bad.elbow_rad < -1e-3 && bad.elbow_rad > -std::f64::consts::PI + 1e-3);
        prop_assume!(bad.base_rad.abs() < std::f64::consts::PI - 1e-3);
        let fails: Vec<Joint> = [Joint::Base, Joint::Shoulder, Joint::Elbow, Joint::ForearmElevation]
            .into_iter()
            .filter(|j| {
                let (lo, hi) = l.of(*j).unwrap();
                let v = bad.get(*j).unwrap();
                v < lo || v > hi
            })
            .collect();
        prop_assume!(fails == vec![expected]);
        match arm.solve_position(&arm.forward(&bad), 0.0) {
            Err(KinematicsError::OutOfLimits { joint, .. }) => prop_assert_eq!(joint, expected),
            other => prop_assert!(false, "expected {expected:?} refused, got {other:?}"),
        }
    }

    #[test]
    fn beyond_the_links_is_too_far_or_too_close(theta in -0.7f64..0.7, elev in -1.5f64..1.5, d in 0.0f64..1.0) {
        let arm = arm();
        let g = arm.geometry;
        let (min, max) = ((g.main_arm_m - g.forearm_m).abs(), g.main_arm_m + g.forearm_m);
        // a wrist distance outside [min, max], then the matching tool point
        let s = if d < 0.5 { min * d * 1.99 } else { max * (1.0 + d) };
        let r = s * elev.cos();
        prop_assume!(r > 0.0);
        let rho = r + g.tool_dx_m;
        let p = Vector3::new(rho * theta.cos(), rho * theta.sin(), g.shoulder_height_m + s * elev.sin());
        match arm.solve_position(&p, 0.0) {
            Err(KinematicsError::TooFar { .. }) => prop_assert!(s > max),
            Err(KinematicsError::TooClose { .. }) => prop_assert!(s < min),
            other => prop_assert!(false, "s={s}: got {other:?}"),
        }
    }

    #[test]
    fn never_a_nan_out(x in any::<f64>(), y in any::<f64>(), z in any::<f64>(), prev in any::<f64>()) {
        match arm().solve_position(&Vector3::new(x, y, z), prev) {
            Ok(q) => prop_assert!(q.base_rad.is_finite() && q.shoulder_rad.is_finite() && q.elbow_rad.is_finite()),
            Err(_) => {}
        }
    }

    #[test]
    fn never_a_nan_out_near_the_workspace(x in -0.4f64..0.4, y in -0.4f64..0.4, z in -0.1f64..0.5) {
        if let Ok(q) = arm().solve_position(&Vector3::new(x, y, z), 0.0) {
            prop_assert!(q.base_rad.is_finite() && q.shoulder_rad.is_finite() && q.elbow_rad.is_finite());
            prop_assert!((arm().forward(&q) - Vector3::new(x, y, z)).norm() <= 1e-12);
        }
    }
}

#[test]
fn non_finite_targets_name_the_axis() {
    for (p, axis) in [
        (Vector3::new(f64::NAN, 0.0, 0.1), "x"),
        (Vector3::new(0.2, f64::INFINITY, 0.1), "y"),
        (Vector3::new(0.2, 0.0, f64::NEG_INFINITY), "z"),
    ] {
        match arm().solve_position(&p, 0.0) {
            Err(KinematicsError::NonFiniteTarget { axis: a, .. }) => assert_eq!(a, axis),
            other => panic!("{p:?}: {other:?}"),
        }
    }
}

#[test]
fn regression_seed_report_sign_loss_atan2_keeps_negative_y() {
    // The seed's θ1 = acos(y/c) lost the sign; a target at -y must turn the base clockwise.
    let q = arm()
        .solve_position(&Vector3::new(0.2, -0.05, 0.15), 0.0)
        .unwrap();
    assert!(q.base_rad < 0.0);
}

#[test]
fn regression_seed_report_mirrored_low_targets() {
    // The seed's θ2 = acos(c/s) mirrored targets below the shoulder upwards.
    let arm = arm();
    let low = Vector3::new(0.20, 0.0, 0.08);
    assert!(low.z < arm.geometry.shoulder_height_m);
    let q = arm.solve_position(&low, 0.0).unwrap();
    assert!((arm.forward(&q) - low).norm() < 1e-12);
}
