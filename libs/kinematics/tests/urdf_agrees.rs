//! The shipped URDF agrees with the kinematics library: tool0, the closed linkages,
//! level links, joint names and limits.
#![allow(clippy::unwrap_used)]

use eezybot_kinematics::urdf::{JointKind, RobotModel};
use eezybot_kinematics::{Arm, ArmJoints, ArmState};
use nalgebra::{Isometry3, Point3};
use proptest::prelude::*;
use std::path::Path;

static MODEL: std::sync::LazyLock<RobotModel> = std::sync::LazyLock::new(|| {
    RobotModel::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../urdf/eezybot.urdf"))
        .unwrap()
});

fn model() -> &'static RobotModel {
    &MODEL
}

fn in_limits() -> impl Strategy<Value = ArmState> {
    let l = Arm::default().limits;
    (
        l.base_rad.0..=l.base_rad.1,
        l.shoulder_rad.0..=l.shoulder_rad.1,
        0.0f64..=1.0,
        0.0f64..=1.0,
    )
        .prop_filter_map(
            "no forearm elevation fits",
            move |(base_rad, shoulder_rad, t, g)| {
                let lo = l.forearm_elevation_rad.0.max(shoulder_rad + l.elbow_rad.0);
                let hi = l.forearm_elevation_rad.1.min(shoulder_rad + l.elbow_rad.1);
                (lo <= hi).then_some(ArmState {
                    joints: ArmJoints {
                        base_rad,
                        shoulder_rad,
                        elbow_rad: lo + t * (hi - lo) - shoulder_rad,
                    },
                    gripper_opening: g,
                })
            },
        )
}

/// A point given in `link`'s frame, expressed in the turntable frame (the arm plane is x-z).
fn in_turntable(
    poses: &std::collections::HashMap<String, Isometry3<f64>>,
    link: &str,
    p: [f64; 3],
) -> Point3<f64> {
    poses["turntable"].inverse() * (poses[link] * Point3::from(p))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2_000, ..ProptestConfig::default() })]

    #[test]
    fn urdf_tool0_equals_library_fk(state in in_limits()) {
        let m = model();
        let arm = Arm::default();
        let positions = state.joint_positions(&arm.geometry);
        let poses = m.link_poses(&positions);
        let tool = poses["tool0"].translation.vector;
        let fk = arm.forward(&state.joints);
        prop_assert!((tool - fk).norm() < 1e-9, "URDF {tool:?} vs FK {fk:?}");
    }

    #[test]
    fn linkages_close_and_plates_stay_level(state in in_limits()) {
        let m = model();
        let g = Arm::default().geometry;
        let poses = m.link_poses(&state.joint_positions(&g));
        let plane = |p: Point3<f64>| (p.x, p.z);
        let close = |a: Point3<f64>, b: Point3<f64>| {
            let ((ax, az), (bx, bz)) = (plane(a), plane(b));
            (ax - bx).hypot(az - bz)
        };
        // chain 2: the drive link's tip is the forearm's rear pin
        let gap = close(in_turntable(&poses, "drive_link", [g.main_arm_m, 0.0, 0.0]), in_turntable(&poses, "forearm", [-0.057, 0.0, 0.0]));
        prop_assert!(gap < 1e-9, "drive link misses the forearm by {gap}");
        // chain 3: the triangle link sits on the elbow axle
        let gap = close(in_turntable(&poses, "triangle_link", [0.038, 0.0, -0.0202]), in_turntable(&poses, "main_arm", [g.main_arm_m, 0.0, 0.0]));
        prop_assert!(gap < 1e-9, "triangle link misses the elbow by {gap}");
        // chain 4: the upper link's tip is the front plate's upper pin
        let gap = close(in_turntable(&poses, "upper_link", [g.forearm_m, 0.0, 0.0]), in_turntable(&poses, "front_plate", [0.0, 0.0, 0.03]));
        prop_assert!(gap < 1e-9, "upper link misses the plate by {gap}");
        // the front plate and the triangle stay level (no pitch relative to the turntable)
        for link in ["front_plate", "triangle_link", "tool0"] {
            let r = (poses["turntable"].inverse() * poses[link]).rotation;
            prop_assert!(r.angle() < 1e-9, "{link} tilts by {} rad", r.angle());
        }
        // the claw fingers mirror each other
        let left = (poses["front_plate"].inverse() * poses["claw_left"]).rotation;
        let right = (poses["front_plate"].inverse() * poses["claw_right"]).rotation;
        prop_assert!((left * right).angle() < 1e-12);
    }
}

#[test]
fn joint_states_names_are_the_urdf_non_fixed_joints() {
    let m = model();
    let mut urdf: Vec<&str> = m
        .joints
        .iter()
        .filter(|j| j.is_movable())
        .map(|j| j.name.as_str())
        .collect();
    let mut published: Vec<&str> = ArmState::default()
        .joint_positions(&Arm::default().geometry)
        .into_iter()
        .map(|(n, _)| n)
        .collect();
    urdf.sort_unstable();
    published.sort_unstable();
    assert_eq!(urdf, published);
}

#[test]
fn urdf_limits_are_the_configured_limits() {
    let m = model();
    let l = Arm::default().limits;
    for (name, (lo, hi)) in [
        ("base_joint", l.base_rad),
        ("shoulder_joint", l.shoulder_rad),
        ("elbow_joint", l.elbow_rad),
    ] {
        match &m.joint(name).unwrap().kind {
            JointKind::Revolute { limits, .. } => {
                assert!(
                    (limits.0 - lo).abs() < 1e-6 && (limits.1 - hi).abs() < 1e-6,
                    "{name}: {limits:?}"
                );
            }
            other => panic!("{name} is {other:?}"),
        }
    }
    assert_eq!(m.root, "base_link");
}
