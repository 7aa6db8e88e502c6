//! compute_ik's numerical solvers, undesirable configurations, nearest-point
//! substitution, pose targets and a URDF arm (the Jaco), without ROS.
#![allow(clippy::unwrap_used)]
use compute_ik::core::*;
use compute_ik::eezybot::*;
use compute_ik::numeric::Solver;
use compute_ik::urdf_arm::{UrdfArm, UrdfCore};
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::{Arm, ArmConfig};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{Point, PointStamped, Pose, PoseStamped, Quaternion};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use std::collections::HashMap;

fn now() -> Time {
    Time::from_nanos(1_700_000_000_123_456_789)
}

fn header() -> Header {
    Header {
        stamp: now(),
        frame_id: "base_link".into(),
    }
}

fn xyz(x: f64, y: f64, z: f64) -> PointStamped {
    PointStamped {
        header: header(),
        point: Point { x, y, z },
    }
}

fn pose_msg(p: &Isometry3<f64>) -> PoseStamped {
    let t = p.translation.vector;
    let q = p.rotation.quaternion();
    PoseStamped {
        header: header(),
        pose: Pose {
            position: Point {
                x: t.x,
                y: t.y,
                z: t.z,
            },
            orientation: Quaternion {
                x: q.i,
                y: q.j,
                z: q.k,
                w: q.w,
            },
        },
    }
}

fn values(s: &DiagnosticStatus) -> HashMap<String, String> {
    s.values
        .iter()
        .map(|kv| (kv.key.clone(), kv.value.clone()))
        .collect()
}

fn settle_eezy(c: &mut IkCore) {
    let mut n = 0;
    while c.step(now()).is_some() {
        n += 1;
        assert!(n < 10_000, "never settles");
    }
}

fn settle_urdf(c: &mut UrdfCore) {
    let mut n = 0;
    while c.step(now()).is_some() {
        n += 1;
        assert!(n < 100_000, "never settles");
    }
}

const NUMERIC: [Solver; 3] = [Solver::Jacobian, Solver::Dls, Solver::Newton];

#[test]
fn every_numerical_solver_agrees_with_the_closed_form_through_the_core() {
    let arm = Arm::default();
    // a grid over the workspace's bounding box: most points are out of reach
    let mut reached = 0;
    for x in [0.06, 0.12, 0.18, 0.24, 0.28] {
        for y in [-0.15, -0.05, 0.0, 0.1] {
            for z in [0.06, 0.12, 0.2, 0.26] {
                let mut closed = IkCore::new(&ArmConfig::default(), "base_link");
                let want = closed.handle_xyz_target(&xyz(x, y, z), now());
                settle_eezy(&mut closed);
                for solver in NUMERIC {
                    let mut c = IkCore::new(&ArmConfig::default(), "base_link");
                    c.set_solver(solver);
                    let got = c.handle_xyz_target(&xyz(x, y, z), now());
                    settle_eezy(&mut c);
                    match (&want, &got) {
                        (Ok(_), Ok(_)) => {
                            let (a, b) = (closed.state().joints, c.state().joints);
                            let dp = (arm.forward(&a) - arm.forward(&b)).norm();
                            assert!(dp <= 1e-9, "{solver:?} at ({x}, {y}, {z}): {dp} m apart");
                            for (u, v) in a.to_chain().iter().zip(b.to_chain()) {
                                assert!((u - v).abs() < 1e-7, "{solver:?}: {a:?} vs {b:?}");
                            }
                        }
                        (Ok(_), Err(e)) => panic!("{solver:?} refused ({x}, {y}, {z}): {e}"),
                        (Err(_), Ok(_)) => {
                            // only on the boundary, within the numerical tolerance
                            let p = arm.forward(&c.state().joints);
                            assert!((p - Vector3::new(x, y, z)).norm() <= 1e-12);
                        }
                        (Err(_), Err(e)) => {
                            assert_eq!(e.reason.code(), "ik_not_converged", "{e}");
                            assert!(e.to_string().contains("not reached"), "{e}");
                        }
                    }
                }
                reached += usize::from(want.is_ok());
            }
        }
    }
    assert!(reached >= 10, "only {reached} grid points reachable");
}

#[test]
fn a_straight_line_with_a_numerical_solver_is_the_closed_forms_line() {
    for solver in [Solver::Analytic, Solver::Dls] {
        let mut c = IkCore::new(&ArmConfig::default(), "base_link");
        c.set_solver(solver);
        c.set_motion(MotionSettings {
            mode: MotionMode::Line,
            ..MotionSettings::default()
        });
        c.handle_xyz_target(&xyz(0.2, -0.05, 0.15), now()).unwrap();
        let arm = Arm::default();
        let mut n = 0;
        while c.step(now()).is_some() {
            n += 1;
            let p = arm.forward(&c.state().joints);
            // on the line from home (0.1863, 0, 0.229) to the target
            let (a, b) = (
                Vector3::new(0.147 + 0.0393, 0.0, 0.094 + 0.135),
                Vector3::new(0.2, -0.05, 0.15),
            );
            let d = (p - a).cross(&(b - a)).norm() / (b - a).norm();
            assert!(d < 1e-4, "{solver:?}: {d} m off the line");
        }
        assert!(n > 5);
        assert!((arm.forward(&c.state().joints) - Vector3::new(0.2, -0.05, 0.15)).norm() < 1e-9);
    }
}

#[test]
fn a_target_just_outside_is_replaced_by_the_nearest_point_only_when_asked() {
    let outside = xyz(0.29, 0.0, 0.15); // ROBOT.md: at z = 0.15 the reach ends at r 0.278
    let mut c = IkCore::new(&ArmConfig::default(), "base_link");
    assert!(c.handle_xyz_target(&outside, now()).is_err());
    c.set_substitution(Some(0.02));
    c.handle_xyz_target(&outside, now()).unwrap();
    settle_eezy(&mut c);
    let p = Arm::default().forward(&c.state().joints);
    let d = (p - Vector3::new(0.29, 0.0, 0.15)).norm();
    assert!(d > 0.005 && d < 0.02, "{d}");
    assert!(p.y.abs() < 1e-6, "{p:?}");
    let notices = c.take_notices();
    assert_eq!(notices.len(), 1);
    assert!(
        notices[0].text.contains("nearest reachable point"),
        "{notices:?}"
    );
    let v = values(&c.diagnostic_status("ik"));
    assert_eq!(v["substitutions"], "1");
    assert!(
        v["last_substitution"].contains("xyz_target (0.2900, 0.0000, 0.1500) m is out of reach")
    );
    // far out: still refused, with the reason
    let far = c.handle_xyz_target(&xyz(1.0, 0.0, 0.1), now()).unwrap_err();
    assert_eq!(far.reason.code(), "too_far");
    // malformed: never substituted
    let nan = c
        .handle_xyz_target(&xyz(f64::NAN, 0.0, 0.1), now())
        .unwrap_err();
    assert_eq!(nan.reason.code(), "non_finite_target");
}

#[test]
fn the_eezybot_takes_a_pose_position_first_and_reports_the_orientation_left() {
    let mut c = IkCore::new(&ArmConfig::default(), "base_link");
    let mut reference = IkCore::new(&ArmConfig::default(), "base_link");
    reference
        .handle_xyz_target(&xyz(0.2, 0.05, 0.15), now())
        .unwrap();
    settle_eezy(&mut reference);
    // pointing the claw down: the EezyBot cannot
    let down = Isometry3::from_parts(
        Vector3::new(0.2, 0.05, 0.15).into(),
        UnitQuaternion::from_euler_angles(0.0, std::f64::consts::FRAC_PI_2, 0.0),
    );
    for solver in [Solver::Analytic, Solver::Dls] {
        c.set_solver(solver);
        c.handle_pose_target(&pose_msg(&down), now()).unwrap();
        settle_eezy(&mut c);
        let (a, b) = (reference.state().joints, c.state().joints);
        assert!((Arm::default().forward(&a) - Arm::default().forward(&b)).norm() < 1e-9);
        let v = values(&c.diagnostic_status("ik"));
        let off: f64 = v["last_pose_target"]
            .strip_prefix("position first: the orientation taken is ")
            .and_then(|t| t.split('°').next())
            .unwrap()
            .parse()
            .unwrap();
        assert!((89.0..=92.0).contains(&off), "{v:?}"); // pitch 90°, yaw 14°
        assert!(c
            .take_notices()
            .iter()
            .any(|n| n.kind == "pose_target/orientation"));
    }
    // a quaternion of zeros is no rotation
    let mut zero = pose_msg(&down);
    zero.pose.orientation = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 0.0,
    };
    let e = c.handle_pose_target(&zero, now()).unwrap_err();
    assert_eq!(e.reason.code(), "bad_orientation");
    assert!(
        e.to_string()
            .starts_with("pose_target rejected: orientation (0, 0, 0, 0) is not a rotation"),
        "{e}"
    );
}

#[test]
fn an_eezybot_at_its_shoulder_limit_is_reported_with_the_way_out() {
    let mut c = IkCore::new(&ArmConfig::default(), "base_link");
    let v = values(&c.diagnostic_status("ik"));
    assert_eq!(v["undesirable"], "none");
    let msg = JointState {
        header: header(),
        name: vec!["shoulder_joint".into(), "elbow_joint".into()],
        position: vec![125f64.to_radians(), -110f64.to_radians()],
        ..JointState::default()
    };
    c.handle_joint_target(&msg, now()).unwrap();
    settle_eezy(&mut c);
    let s = c.diagnostic_status("ik");
    assert_eq!(s.level, DiagnosticStatus::OK);
    let v = values(&s);
    assert!(
        v["undesirable"].contains("at_limit:shoulder_joint:upper"),
        "{v:?}"
    );
    let detail = &v["undesirable:at_limit:shoulder_joint:upper"];
    assert!(detail.contains("away: shoulder_joint -1.00"), "{detail}");
    assert!(detail.contains("tool toward ("), "{detail}");
}

fn jaco() -> UrdfCore {
    let model = RobotModel::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../urdf/jaco.urdf"
    )))
    .unwrap();
    UrdfCore::new(
        UrdfArm::new(model, "", "jaco_end_effector").unwrap(),
        "base_link",
    )
    .unwrap()
}

fn jaco_tip(c: &UrdfCore) -> Isometry3<f64> {
    c.arm().chain().forward(c.state()).unwrap()
}

#[test]
fn the_jaco_reaches_poses_and_keeps_its_orientation_for_positions() {
    let mut c = jaco();
    let chain = c.arm().chain().clone();
    let js = c.joint_states(now());
    assert_eq!(js.name.len(), 6);
    let q = [-0.5, 2.5, -2.0, 1.0, 2.5, 0.5];
    let goal = chain.forward(&q).unwrap();
    let out = c.handle_pose_target(&pose_msg(&goal), now()).unwrap();
    assert_eq!(out.joint_states.header.stamp, now());
    settle_urdf(&mut c);
    let tip = jaco_tip(&c);
    assert!((tip.translation.vector - goal.translation.vector).norm() < 1e-9);
    assert!(tip.rotation.angle_to(&goal.rotation) < 1e-8);
    // a position: reached, the orientation kept
    let p = tip.translation.vector + Vector3::new(0.03, -0.02, 0.05);
    c.handle_xyz_target(&xyz(p.x, p.y, p.z), now()).unwrap();
    settle_urdf(&mut c);
    let after = jaco_tip(&c);
    assert!((after.translation.vector - p).norm() < 1e-9);
    assert!(
        after.rotation.angle_to(&tip.rotation) < 1e-6,
        "{}",
        after.rotation.angle_to(&tip.rotation)
    );
    let v = values(&c.diagnostic_status("ik"));
    assert!(v["last_solve"].starts_with("dls: converged"), "{v:?}");
    assert_eq!(
        v["solver"],
        "dls (analytic asked: this arm has no closed form)"
    );
    // the same with every solver, in a straight line
    c.set_motion(MotionSettings {
        mode: MotionMode::Line,
        ..MotionSettings::default()
    });
    let nearby = chain.forward(&[-0.4, 2.4, -2.1, 1.1, 2.4, 0.6]).unwrap();
    for (solver, back) in NUMERIC.into_iter().zip([goal, nearby, goal]) {
        c.set_solver(solver);
        c.handle_pose_target(&pose_msg(&back), now()).unwrap();
        settle_urdf(&mut c);
        let t = jaco_tip(&c);
        assert!(
            (t.translation.vector - back.translation.vector).norm() < 1e-9,
            "{solver:?}"
        );
        assert!(t.rotation.angle_to(&back.rotation) < 1e-8, "{solver:?}");
        let v = values(&c.diagnostic_status("ik"));
        assert!(
            v["last_solve"].starts_with(&format!("{}: converged", solver.name())),
            "{v:?}"
        );
    }
}

#[test]
fn the_jaco_refuses_what_it_cannot_do_with_a_reason() {
    let mut c = jaco();
    let far = c.handle_xyz_target(&xyz(3.0, 0.0, 0.5), now()).unwrap_err();
    assert_eq!(far.reason.code(), "ik_not_converged");
    assert!(
        far.to_string()
            .contains("not reached: the closest the dls solver got"),
        "{far}"
    );
    let claw = c.handle_gripper_target(0.5, now()).unwrap_err();
    assert_eq!(claw.reason.code(), "no_gripper");
    let unknown = JointState {
        header: header(),
        name: vec!["base_joint".into()],
        position: vec![0.1],
        ..JointState::default()
    };
    let e = c.handle_joint_target(&unknown, now()).unwrap_err();
    assert!(
        e.to_string()
            .contains("this arm's joints: jaco_joint_1, jaco_joint_2"),
        "{e}"
    );
    let beyond = JointState {
        name: vec!["jaco_joint_2".into()],
        position: vec![4.0],
        ..unknown
    };
    let e = c.handle_joint_target(&beyond, now()).unwrap_err();
    assert_eq!(e.reason.code(), "out_of_limits:jaco_joint_2");
    // and substitutes a point just out of reach when asked
    c.set_substitution(Some(0.05));
    // 2 cm above the report's upright tip, (0, -0.0643, 1.1811) m
    let edge = c.handle_xyz_target(&xyz(0.0, -0.0643, 1.2011), now());
    assert!(edge.is_ok(), "{edge:?}");
    settle_urdf(&mut c);
    let d = (jaco_tip(&c).translation.vector - Vector3::new(0.0, -0.0643, 1.2011)).norm();
    assert!(d > 0.001 && d <= 0.02 + 1e-6, "{d}");
}

#[test]
fn the_upright_jaco_is_near_singular_and_pointing_up_with_ways_out() {
    let mut c = jaco();
    c.set_gripper_up(Some(60.0));
    let pi = std::f64::consts::PI;
    let upright = JointState {
        header: header(),
        name: (1..=6).map(|i| format!("jaco_joint_{i}")).collect(),
        position: vec![pi, pi / 2.0, -pi / 2.0, 0.0, -pi, pi],
        ..JointState::default()
    };
    c.handle_joint_target(&upright, now()).unwrap();
    settle_urdf(&mut c);
    let v = values(&c.diagnostic_status("ik"));
    assert!(v["undesirable"].contains("near_singular"), "{v:?}");
    assert!(
        v["undesirable:near_singular"].contains("away: jaco_joint_"),
        "{v:?}"
    );
    // the report's upright pose points the gripper straight up
    assert!(v["undesirable"].contains("gripper_up"), "{v:?}");
    assert!(
        v["undesirable:gripper_up"].starts_with("the gripper faces upwards"),
        "{v:?}"
    );
}
