//! The workspace envelopes: the EezyBot's lathe profile holds every configuration within
//! the limits, the closed-form IK refuses what lies clearly outside it, its extent is
//! ROBOT.md's, it is a counter-clockwise ring of at most 200 points; a URDF chain's
//! point cloud is deterministic and made of FK of configurations within the limits.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
use common::load;
use eezybot_kinematics::chain::SerialChain;
use eezybot_kinematics::envelope::{
    chain_envelope, eezybot_envelope, Envelope, MAX_PROFILE_POINTS, MIN_CELL_M,
};
use eezybot_kinematics::rng::SplitMix64;
use eezybot_kinematics::{Arm, ArmJoints, JointLimitsDeg};
use nalgebra::Vector3;
use std::time::Instant;

const CELL_M: f64 = 0.004;

fn profile(arm: &Arm, cell_m: f64) -> Vec<[f64; 2]> {
    match eezybot_envelope(arm, cell_m) {
        Envelope::Lathe { profile, yaw } => {
            assert_eq!(yaw, [arm.limits.base_rad.0, arm.limits.base_rad.1]);
            profile
        }
        other => panic!("expected a lathe, got {other:?}"),
    }
}

/// A second arm: narrower shoulder and coupling rows, another shoulder height, so that
/// nothing here holds for the default limits only.
fn other_arm() -> Arm {
    let mut config = eezybot_kinematics::ArmConfig::default();
    config.geometry.shoulder_height_m = 0.085;
    config.limits_deg = JointLimitsDeg {
        base: [-30.0, 60.0],
        shoulder: [50.0, 110.0],
        elbow: [-130.0, -70.0],
        forearm_elevation: [-40.0, 10.0],
    };
    config.arm()
}

fn segments(poly: &[[f64; 2]]) -> impl Iterator<Item = ([f64; 2], [f64; 2])> + '_ {
    (0..poly.len()).map(move |k| (poly[k], poly[(k + 1) % poly.len()]))
}

/// Even-odd rule.
fn inside(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut odd = false;
    for (a, b) in segments(poly) {
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let r = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < r {
                odd = !odd;
            }
        }
    }
    odd
}

fn boundary_distance(poly: &[[f64; 2]], p: [f64; 2]) -> f64 {
    segments(poly)
        .map(|(a, b)| {
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let t =
                (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
            (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
        })
        .fold(f64::INFINITY, f64::min)
}

fn twice_signed_area(poly: &[[f64; 2]]) -> f64 {
    segments(poly).map(|(a, b)| a[0] * b[1] - b[0] * a[1]).sum()
}

/// Configurations within every limit row: a grid at `step_deg` over the shoulder and
/// elbow boxes (kept when the arm's check passes) plus the boundary of the feasible
/// set (each limit row walked at its bound, clamped inside as the arm does).
fn configurations_within_limits(arm: &Arm, step_deg: f64) -> Vec<ArmJoints> {
    let l = &arm.limits;
    let steps = |(lo, hi): (f64, f64)| {
        let n = ((hi - lo) / step_deg.to_radians()).ceil() as usize;
        (0..=n).map(move |k| lo + (hi - lo) * k as f64 / n as f64)
    };
    let mut out = Vec::new();
    for shoulder_rad in steps(l.shoulder_rad) {
        for elbow_rad in steps(l.elbow_rad) {
            let q = ArmJoints {
                base_rad: 0.0,
                shoulder_rad,
                elbow_rad,
            };
            if l.check(&q).is_ok() {
                out.push(q);
            }
            // and the nearest configuration within the limits (on the boundary)
            let c = l.clamp(&q);
            if l.check(&c).is_ok() {
                out.push(c);
            }
        }
    }
    out
}

/// (r, z) of the tool at yaw 0.
fn plane(arm: &Arm, q: &ArmJoints) -> [f64; 2] {
    let p = arm.forward(&ArmJoints {
        base_rad: 0.0,
        ..*q
    });
    [p.x, p.z]
}

#[test]
fn every_configuration_within_limits_lies_inside_the_profile() {
    for (name, arm) in [("default", Arm::default()), ("other", other_arm())] {
        let poly = profile(&arm, CELL_M);
        let configs = configurations_within_limits(&arm, 0.2);
        assert!(
            configs.len() > 50_000,
            "{name}: {} configurations",
            configs.len()
        );
        let mut worst: f64 = 0.0;
        for q in &configs {
            let p = plane(&arm, q);
            if !inside(&poly, p) {
                let d = boundary_distance(&poly, p);
                worst = worst.max(d);
                assert!(d <= CELL_M, "{name}: {q:?} at {p:?} is {d} m outside");
            }
        }
        println!("{name}: worst configuration outside the profile by {worst:.5} m");
    }
}

#[test]
fn targets_clearly_outside_the_profile_are_refused_by_ik() {
    for (name, arm) in [("default", Arm::default()), ("other", other_arm())] {
        let poly = profile(&arm, CELL_M);
        let (mut refused, mut solved) = (0, 0);
        let step = CELL_M / 3.0;
        for i in 0..=(0.40 / step) as usize {
            for j in 0..=(0.40 / step) as usize {
                let p = [-0.05 + i as f64 * step, -0.05 + j as f64 * step];
                let ik = arm.solve_position(&Vector3::new(p[0], 0.0, p[1]), 0.0);
                let d = boundary_distance(&poly, p);
                if d <= 2.0 * CELL_M {
                    continue;
                }
                if inside(&poly, p) {
                    // the profile is not loose either: deep inside means reachable
                    assert!(ik.is_ok(), "{name}: {p:?} {d} m inside: {ik:?}");
                    solved += 1;
                } else {
                    assert!(
                        ik.is_err(),
                        "{name}: {p:?} is {d} m outside but IK gives {ik:?}"
                    );
                    refused += 1;
                }
            }
        }
        assert!(
            refused > 1000 && solved > 1000,
            "{name}: {refused} / {solved}"
        );
    }
}

#[test]
fn profile_bounding_box_matches_robot_md() {
    // ROBOT.md: tool radius 0.100–0.279 m, height 0.052–0.279 m with the default limits
    let arm = Arm::default();
    let poly = profile(&arm, CELL_M);
    let min = |k: usize| poly.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
    let max = |k: usize| poly.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
    let bbox = [min(0), max(0), min(1), max(1)];
    println!(
        "profile: {} points, r {:.4}…{:.4} m, z {:.4}…{:.4} m",
        poly.len(),
        bbox[0],
        bbox[1],
        bbox[2],
        bbox[3]
    );
    for (got, want) in bbox.iter().zip([0.100, 0.279, 0.052, 0.279]) {
        assert!(
            (got - want).abs() <= 2.0 * CELL_M,
            "bounding box {bbox:?} vs ROBOT.md"
        );
    }
    // and against the extent of the configurations themselves, within a cell
    let pts: Vec<[f64; 2]> = configurations_within_limits(&arm, 0.1)
        .iter()
        .map(|q| plane(&arm, q))
        .collect();
    let emin = |k: usize| pts.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
    let emax = |k: usize| pts.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
    for (got, want) in bbox.iter().zip([emin(0), emax(0), emin(1), emax(1)]) {
        assert!((got - want).abs() <= CELL_M, "{bbox:?}: {got} vs {want}");
    }
}

/// Do segments `a`–`b` and `c`–`d` cross or touch?
fn segments_meet(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let orient = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        ((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])).signum()
    };
    let (o1, o2, o3, o4) = (
        orient(a, b, c),
        orient(a, b, d),
        orient(c, d, a),
        orient(c, d, b),
    );
    o1 * o2 <= 0.0 && o3 * o4 <= 0.0
}

#[test]
fn profile_is_a_simple_counter_clockwise_ring_of_at_most_200_points() {
    for arm in [Arm::default(), other_arm()] {
        for cell in [MIN_CELL_M, 0.002, CELL_M, 0.008, 0.02] {
            let poly = profile(&arm, cell);
            let n = poly.len();
            assert!(
                (3..=MAX_PROFILE_POINTS).contains(&n),
                "cell {cell}: {n} points"
            );
            assert_ne!(
                poly[0],
                poly[n - 1],
                "cell {cell}: last point repeats the first"
            );
            assert!(twice_signed_area(&poly) > 0.0, "cell {cell}: clockwise");
            for i in 0..n {
                for j in i + 2..n {
                    if i == 0 && j == n - 1 {
                        continue; // adjacent through the closing edge
                    }
                    let (a, b) = (poly[i], poly[(i + 1) % n]);
                    let (c, d) = (poly[j], poly[(j + 1) % n]);
                    assert!(
                        !segments_meet(a, b, c, d),
                        "cell {cell}: edges {i} and {j} meet"
                    );
                }
            }
        }
    }
}

#[test]
fn profile_build_time_is_printed() {
    let arm = Arm::default();
    let start = Instant::now();
    let env = eezybot_envelope(&arm, CELL_M);
    let elapsed = start.elapsed();
    let Envelope::Lathe { profile, .. } = &env else {
        panic!("a lathe")
    };
    println!(
        "eezybot_envelope(cell {CELL_M} m): {} points in {:.2} ms",
        profile.len(),
        elapsed.as_secs_f64() * 1e3
    );
}

#[test]
fn odd_cells_and_empty_limits_give_a_profile_or_nothing_without_panicking() {
    let arm = Arm::default();
    for cell in [f64::NAN, 0.0, -1.0, 1e-9, f64::INFINITY, 5.0] {
        let poly = profile(&arm, cell);
        assert!(poly.len() <= MAX_PROFILE_POINTS, "cell {cell}");
        assert!(poly.iter().flatten().all(|v| v.is_finite()), "cell {cell}");
    }
    // no shoulder angle satisfies the coupling: nothing is reachable
    let mut config = eezybot_kinematics::ArmConfig::default();
    config.limits_deg.forearm_elevation = [60.0, 70.0];
    config.limits_deg.shoulder = [42.5, 80.0];
    assert!(profile(&config.arm(), CELL_M).is_empty());
}

#[test]
fn envelopes_serialise_with_a_kind_tag() {
    let lathe = Envelope::Lathe {
        profile: vec![[0.1, 0.05], [0.2, 0.05], [0.15, 0.2]],
        yaw: [-0.5, 0.5],
    };
    let points = Envelope::Points {
        points: vec![[0.1, 0.2, 0.3]],
    };
    // serde_json is not a dependency of this crate; the YAML data model is the same
    let v: serde_norway::Value =
        serde_norway::from_str(&serde_norway::to_string(&lathe).unwrap()).unwrap();
    let want: serde_norway::Value = serde_norway::from_str(
        r#"{"kind":"lathe","profile":[[0.1,0.05],[0.2,0.05],[0.15,0.2]],"yaw":[-0.5,0.5]}"#,
    )
    .unwrap();
    assert_eq!(v, want);
    let v: serde_norway::Value =
        serde_norway::from_str(&serde_norway::to_string(&points).unwrap()).unwrap();
    let want: serde_norway::Value =
        serde_norway::from_str(r#"{"kind":"points","points":[[0.1,0.2,0.3]]}"#).unwrap();
    assert_eq!(v, want);
}

#[test]
fn chain_envelope_is_deterministic_and_made_of_fk_within_limits() {
    let chains = [
        (
            "eezybot",
            Arm::default().serial_chain(&load("eezybot.urdf")).unwrap(),
        ),
        (
            "jaco",
            SerialChain::from_model(&load("jaco.urdf"), "base_link", "jaco_end_effector").unwrap(),
        ),
    ];
    for (name, chain) in &chains {
        let env = chain_envelope(chain, 2000, 42);
        assert_eq!(env, chain_envelope(chain, 2000, 42), "{name}");
        assert_ne!(env, chain_envelope(chain, 2000, 43), "{name}");
        let Envelope::Points { points } = env else {
            panic!("{name}: a point cloud")
        };
        assert_eq!(points.len(), 2000);
        // re-run: the same configurations, each within the limits, FK equal to the point
        let mut rng = SplitMix64::new(42);
        for p in &points {
            let x = chain.random_configuration(&mut rng);
            assert!(chain.within_limits(&x, 1e-9), "{name}: {x:?}");
            let t = chain.forward(&x).unwrap().translation.vector;
            assert_eq!(*p, [t.x, t.y, t.z], "{name}: {x:?}");
        }
        // a prefix of a longer run
        let Envelope::Points { points: more } = chain_envelope(chain, 2500, 42) else {
            panic!()
        };
        assert_eq!(points[..], more[..2000]);
    }
    assert_eq!(
        chain_envelope(&chains[0].1, 0, 1),
        Envelope::Points { points: vec![] }
    );
}

#[test]
fn eezybot_chain_cloud_lies_within_its_lathe() {
    let arm = Arm::default();
    let chain = arm.serial_chain(&load("eezybot.urdf")).unwrap();
    let poly = profile(&arm, CELL_M);
    let Envelope::Points { points } = chain_envelope(&chain, 5000, 3) else {
        panic!()
    };
    for p in points {
        let (r, yaw) = (p[0].hypot(p[1]), p[1].atan2(p[0]));
        assert!(arm.limits.base_rad.0 - 1e-9 <= yaw && yaw <= arm.limits.base_rad.1 + 1e-9);
        let rz = [r, p[2]];
        assert!(
            inside(&poly, rz) || boundary_distance(&poly, rz) <= CELL_M,
            "{p:?}"
        );
    }
}
