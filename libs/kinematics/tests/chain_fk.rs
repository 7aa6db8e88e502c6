//! The serial chains built from the URDFs: the Jaco's FK equals the DH FK of the seed
//! report's Table 4.1, the EezyBot's equals the closed-form FK, Jacobians equal finite
//! differences, builder errors name the problem.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
use common::load;
use eezybot_kinematics::chain::{ChainBuilder, SerialChain};
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::{Arm, ArmJoints, ArmState, KinematicsError};
use nalgebra::{Isometry3, Matrix4, Vector3};
use proptest::prelude::*;
use std::f64::consts::PI;
use std::sync::LazyLock;

static JACO: LazyLock<SerialChain> = LazyLock::new(|| {
    SerialChain::from_model(&load("jaco.urdf"), "base_link", "jaco_end_effector").unwrap()
});
static EEZY: LazyLock<SerialChain> =
    LazyLock::new(|| Arm::default().serial_chain(&load("eezybot.urdf")).unwrap());

/// Table 4.1 of the seed report (classical DH: alpha_i, a_i, d_i in m), typed in again
/// here on purpose rather than shared with the generator.
const DH: [(f64, f64, f64); 6] = [
    (PI / 2.0, 0.0, 0.2755),
    (PI, 0.410, 0.0),
    (PI / 2.0, 0.0, -0.0098),
    (PI / 3.0, 0.0, -0.25008),
    (PI / 3.0, 0.0, -0.085563),
    (PI, 0.0, -0.20278),
];

/// The classical DH product A_1 ... A_6, A_i = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i).
fn dh_fk(q: &[f64]) -> Matrix4<f64> {
    let mut t = Matrix4::identity();
    for ((alpha, a, d), th) in DH.iter().zip(q) {
        let (st, ct) = th.sin_cos();
        let (sa, ca) = alpha.sin_cos();
        #[rustfmt::skip]
        let m = Matrix4::new(
            ct, -st * ca, st * sa, a * ct,
            st, ct * ca, -ct * sa, a * st,
            0.0, sa, ca, *d,
            0.0, 0.0, 0.0, 1.0,
        );
        t *= m;
    }
    t
}

fn compare(urdf: &Isometry3<f64>, dh: &Matrix4<f64>) -> (f64, f64) {
    let u = urdf.to_homogeneous();
    let dp = (u.fixed_view::<3, 1>(0, 3) - dh.fixed_view::<3, 1>(0, 3)).norm();
    // |R1 − R2|_F = 2√2·sin(θ/2) ≈ √2·θ, accurate for small θ (acos of the trace is not)
    let dr = (u.fixed_view::<3, 3>(0, 0) - dh.fixed_view::<3, 3>(0, 0)).norm() / 2f64.sqrt();
    (dp, dr)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2_000, ..ProptestConfig::default() })]

    #[test]
    fn jaco_urdf_fk_equals_table_4_1_dh_fk(q in prop::array::uniform6(-2.0 * PI..2.0 * PI)) {
        let (dp, dr) = compare(&JACO.forward(&q).unwrap(), &dh_fk(&q));
        prop_assert!(dp < 1e-9 && dr < 1e-9, "{dp} m, {dr} rad at {q:?}");
    }

    #[test]
    fn jacobians_equal_finite_differences(q in prop::array::uniform6(-PI..PI), e in prop::array::uniform3(-1.0f64..1.0)) {
        for (chain, x) in [(&*JACO, q.to_vec()), (&*EEZY, vec![e[0] * 0.7, 1.4 + 0.5 * e[1], -1.6 + 0.4 * e[2]])] {
            let (tip, j) = chain.jacobian(&x).unwrap();
            let h = 1e-6;
            for k in 0..chain.dof() {
                let (mut up, mut down) = (x.clone(), x.clone());
                up[k] += h;
                down[k] -= h;
                let (tu, td) = (chain.forward(&up).unwrap(), chain.forward(&down).unwrap());
                let v = (tu.translation.vector - td.translation.vector) / (2.0 * h);
                let w = (tu.rotation * td.rotation.inverse()).scaled_axis() / (2.0 * h);
                let col = j.column(k);
                prop_assert!((v - col.fixed_rows::<3>(0)).norm() < 1e-7, "linear {k}: {v:?} vs {col:?} at {tip:?}");
                prop_assert!((w - col.fixed_rows::<3>(3)).norm() < 1e-7, "angular {k}: {w:?} vs {col:?}");
            }
        }
    }

    #[test]
    fn eezybot_chain_fk_equals_library_fk(b in -0.78f64..0.78, a in 0.75f64..2.18, t in 0.0f64..1.0) {
        let arm = Arm::default();
        let l = arm.limits;
        let lo = l.forearm_elevation_rad.0.max(a + l.elbow_rad.0);
        let hi = l.forearm_elevation_rad.1.min(a + l.elbow_rad.1);
        prop_assume!(lo <= hi);
        let q = ArmJoints { base_rad: b, shoulder_rad: a, elbow_rad: lo + t * (hi - lo) - a };
        let x = [q.base_rad, q.shoulder_rad, q.elbow_rad];
        let tip = EEZY.forward(&x).unwrap();
        prop_assert!((tip.translation.vector - arm.forward(&q)).norm() < 1e-9);
        prop_assert!(tip.rotation.angle_to(&nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), b)) < 1e-9,
                     "tool0 stays level, turned by the base only");
        prop_assert!(EEZY.within_limits(&x, 1e-12));
        // every dependent joint as compute_ik publishes it
        let published = ArmState { joints: q, gripper_opening: 0.0 }.joint_positions(&arm.geometry);
        let ours = EEZY.joint_positions(&x).unwrap();
        for (name, value) in &ours {
            let (_, want) = published.iter().find(|(n, _)| n == name).unwrap();
            prop_assert!((value - want).abs() < 1e-12, "{name}: {value} vs {want}");
        }
        prop_assert_eq!(ours.len(), 9); // 3 actuated + wrist + 5 passive off the chain
    }
}

#[test]
fn jaco_upright_pose_is_the_reports() {
    // The report: q = [pi, pi/2, -pi/2, 0, -pi, pi] puts the tip at (0, -64.299, 1181.145) mm
    // (after "slight tweaking of the tip"); the table itself gives (0, -64.3, 1181.142).
    let tip = JACO
        .forward(&[PI, PI / 2.0, -PI / 2.0, 0.0, -PI, PI])
        .unwrap();
    let want = Vector3::new(0.0, -0.0643, 1.181142);
    assert!((tip.translation.vector - want).norm() < 1e-6, "{tip:?}");
}

#[test]
fn jaco_limits_are_kinovas() {
    let v = JACO.variables();
    assert_eq!(v.len(), 6);
    for i in [0, 3, 4, 5] {
        assert!(
            v[i].continuous && v[i].lower == f64::NEG_INFINITY,
            "{:?}",
            v[i]
        );
    }
    // actuator 2: 47..313 deg, actuator 3: 19..341 deg in Kinova's angles (180 = upright)
    assert!((v[1].lower - (90f64 - 133.0).to_radians()).abs() < 1e-12);
    assert!((v[1].upper - (90f64 + 133.0).to_radians()).abs() < 1e-12);
    assert!((v[2].lower - (-90f64 - 161.0).to_radians()).abs() < 1e-12);
    assert!((v[2].upper - (-90f64 + 161.0).to_radians()).abs() < 1e-12);
    assert!(JACO.constraints().is_empty());
}

#[test]
fn eezybot_chain_variables_limits_and_coupling() {
    let arm = Arm::default();
    let names: Vec<&str> = EEZY.variables().iter().map(|v| v.name.as_str()).collect();
    assert_eq!(names, ["base_joint", "shoulder_joint", "elbow_joint"]);
    assert_eq!(EEZY.variables()[1].lower, arm.limits.shoulder_rad.0);
    let c = &EEZY.constraints()[0];
    assert_eq!(c.name, "forearm_elevation");
    assert_eq!(c.coefficients, [0.0, 1.0, 1.0]);
    assert_eq!((c.lower, c.upper), arm.limits.forearm_elevation_rad);
    // α = 90°, elbow = −60°: φ = 30° > 20°
    let x = [0.0, 90f64.to_radians(), -60f64.to_radians()];
    assert!(!EEZY.within_limits(&x, 1e-9));
}

#[test]
fn passive_joint_limits_become_constraints_by_default() {
    // Without the explicit coupling, the URDF's wrist_joint limits (−φ within −20°…65°,
    // rounded to 1e-6 rad) express the same coupling.
    let chain = ChainBuilder::new(&load("eezybot.urdf"), "base_link", "tool0")
        .passive(
            "wrist_joint",
            &[("shoulder_joint", -1.0), ("elbow_joint", -1.0)],
            0.0,
        )
        .build()
        .unwrap();
    assert_eq!(chain.dof(), 3);
    let c = &chain.constraints()[0];
    assert_eq!(c.name, "wrist_joint");
    assert_eq!(c.coefficients, [0.0, -1.0, -1.0]);
    assert!((c.upper - 65f64.to_radians()).abs() < 1e-6);
}

#[test]
fn mimic_joint_on_the_chain_follows_its_leader() {
    let m = RobotModel::from_urdf_str(
        r#"<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
        <joint name="j1" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/><origin xyz="1 0 0"/></joint>
        <joint name="j2" type="revolute"><parent link="b"/><child link="c"/><axis xyz="0 0 1"/><origin xyz="1 0 0"/>
          <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/><mimic joint="j1" multiplier="2" offset="0.1"/></joint>
        </robot>"#,
        "inline",
    )
    .unwrap();
    let chain = SerialChain::from_model(&m, "a", "c").unwrap();
    assert_eq!(chain.dof(), 1);
    let q = chain.joint_positions(&[0.2]).unwrap();
    assert_eq!(q[1], ("j2", 2.0 * 0.2 + 0.1));
    // its limits constrain the leader: −0.5 ≤ 2·j1 + 0.1 ≤ 0.5
    let c = &chain.constraints()[0];
    assert!((c.lower + 0.6).abs() < 1e-15 && (c.upper - 0.4).abs() < 1e-15);
    assert!(!chain.within_limits(&[0.25], 0.0));
    // the Jacobian counts the mimic joint at twice the rate; the tip (on j2's axis,
    // 1 m from j1's) moves at 1 m/rad
    let (_, j) = chain.jacobian(&[0.0]).unwrap();
    assert!(
        (j[(5, 0)] - 3.0).abs() < 1e-12 && (j[(1, 0)] - 1.0).abs() < 1e-12,
        "{j}"
    );
}

#[test]
fn builder_errors_name_the_problem() {
    let m = load("eezybot.urdf");
    let e = SerialChain::from_model(&m, "base_link", "nowhere").unwrap_err();
    assert_eq!(
        e,
        KinematicsError::UnknownLink {
            link: "nowhere".into()
        }
    );
    let e = SerialChain::from_model(&m, "tool0", "base_link").unwrap_err();
    assert!(matches!(e, KinematicsError::NotAChain { .. }), "{e}");
    let e = ChainBuilder::new(&m, "base_link", "tool0")
        .passive("no_such_joint", &[], 0.0)
        .build()
        .unwrap_err();
    assert!(e.to_string().contains("no_such_joint"), "{e}");
    let e = ChainBuilder::new(&m, "base_link", "tool0")
        .limits("shoulder_joint", 2.0, 1.0)
        .build()
        .unwrap_err();
    assert!(
        matches!(
            e,
            KinematicsError::InvalidLimits {
                lower: 2.0,
                upper: 1.0,
                ..
            }
        ),
        "{e}"
    );
    let e = EEZY.forward(&[0.0, 1.0]).unwrap_err();
    assert!(
        matches!(
            e,
            KinematicsError::DimensionMismatch {
                expected: 3,
                got: 2,
                ..
            }
        ),
        "{e}"
    );
    let e = EEZY.forward(&[0.0, f64::NAN, 1.0]).unwrap_err();
    assert!(
        matches!(e, KinematicsError::NonFiniteValue { index: 1, .. }),
        "{e}"
    );
}

#[test]
fn projection_lands_inside_the_coupled_limits() {
    let mut rng = eezybot_kinematics::rng::SplitMix64::new(3);
    for _ in 0..10_000 {
        let mut x: Vec<f64> = (0..3).map(|_| rng.uniform(-4.0, 4.0)).collect();
        let left = EEZY.project(&mut x);
        assert!(
            left < 1e-12 && EEZY.within_limits(&x, 1e-12),
            "{x:?} violates by {left}"
        );
        let r = EEZY.random_configuration(&mut rng);
        assert!(EEZY.within_limits(&r, 0.0));
    }
}
