//! IK and FK timing, and how long refusing a hostile input takes (the unit tests check
//! that it is refused before parsing; the time is here, not asserted there).
//! `cargo bench -p eezybot_kinematics`.
use criterion::{criterion_group, criterion_main, Criterion};
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::{Arm, ArmConfig, ArmJoints, ArmState, ServoCalibrations};
use nalgebra::Vector3;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let arm = Arm::default();
    // 64 reachable targets spread over the workspace (FK of in-limit joints), so
    // branch prediction does not see a single input.
    let targets: Vec<Vector3<f64>> = (0..64)
        .map(|i| {
            let t = i as f64 / 64.0;
            let alpha_deg = 60.0 + 50.0 * t;
            let (lo, hi) = (
                (alpha_deg - 140.0f64).max(-60.0),
                (alpha_deg - 65.0f64).min(15.0),
            );
            let phi_deg = lo + (hi - lo) * ((t * 7.0) % 1.0);
            let shoulder_rad = alpha_deg.to_radians();
            let elbow_rad = phi_deg.to_radians() - shoulder_rad;
            arm.forward(&ArmJoints {
                base_rad: (-40.0 + 80.0 * t).to_radians(),
                shoulder_rad,
                elbow_rad,
            })
        })
        .collect();
    assert!(targets.iter().all(|p| arm.solve_position(p, 0.0).is_ok()));
    let mut i = 0;
    c.bench_function("ik_solve_position", |b| {
        b.iter(|| {
            i = (i + 1) & 63;
            black_box(arm.solve_position(black_box(&targets[i]), 0.0))
        })
    });
    let q = ArmJoints {
        base_rad: 0.2,
        shoulder_rad: 1.3,
        elbow_rad: -1.6,
    };
    c.bench_function("fk_forward", |b| {
        b.iter(|| black_box(arm.forward(black_box(&q))))
    });
    let cal = ServoCalibrations::default();
    let state = ArmState {
        joints: q,
        gripper_opening: 0.3,
    };
    c.bench_function("servo_angles", |b| {
        b.iter(|| black_box(cal.servo_angles(black_box(&state))))
    });
    // 10,000 nested elements / flow collections: refused before parsing
    let depth = 10_000;
    let urdf = format!(
        "<robot name='deep'><link name='a'>{}{}</link></robot>",
        "<visual>".repeat(depth),
        "</visual>".repeat(depth)
    );
    c.bench_function("refuse_10k_deep_urdf", |b| {
        b.iter(|| black_box(RobotModel::from_urdf_str(black_box(&urdf), "deep.urdf").is_err()))
    });
    let yaml = format!("geometry: {}{}\n", "[".repeat(depth), "]".repeat(depth));
    c.bench_function("refuse_10k_deep_arm_config", |b| {
        b.iter(|| black_box(ArmConfig::from_yaml(black_box(&yaml), "deep.yaml").is_err()))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
