//! Per-solve timing of the numerical IK (criterion): the 6-DOF Jaco, warm-started (each
//! pose of a small-step joint-space walk from the previous pose's joints) and
//! cold-started (random seeds, random restarts within 5 ms), for each solver; and the
//! EezyBot (position-only, coupled limits) next to its closed form.
//! `cargo bench -p eezybot_kinematics --bench ik_solvers`. Success rates and p50/p99 over
//! 10,000 poses, with the `k` crate alongside: `libs/kinematics/ik_bench`.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion};
use eezybot_kinematics::chain::SerialChain;
use eezybot_kinematics::ik::{IkAlgorithm, IkSolver, Target};
use eezybot_kinematics::rng::SplitMix64;
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::{Arm, ArmJoints};
use nalgebra::Isometry3;
use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

const N: usize = 256;

fn load(file: &str) -> RobotModel {
    RobotModel::load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../urdf")
            .join(file),
    )
    .unwrap()
}

fn bench(c: &mut Criterion) {
    let jaco =
        SerialChain::from_model(&load("jaco.urdf"), "base_link", "jaco_end_effector").unwrap();
    let mut rng = SplitMix64::new(42);
    // warm: a joint-space walk, steps uniform in ±0.02 rad per joint
    let mut x = jaco.random_configuration(&mut rng);
    let walk: Vec<(Vec<f64>, Isometry3<f64>)> = (0..=N)
        .map(|_| {
            x.iter_mut().for_each(|v| *v += rng.uniform(-0.02, 0.02));
            jaco.project(&mut x);
            (x.clone(), jaco.forward(&x).unwrap())
        })
        .collect();
    let cold: Vec<(Vec<f64>, Isometry3<f64>)> = (0..N)
        .map(|_| {
            let goal = jaco.forward(&jaco.random_configuration(&mut rng)).unwrap();
            (jaco.random_configuration(&mut rng), goal)
        })
        .collect();
    for (name, algorithm) in [
        ("dls", IkAlgorithm::DampedLeastSquares),
        ("newton_raphson", IkAlgorithm::NewtonRaphson),
        ("pseudo_inverse", IkAlgorithm::PseudoInverse),
    ] {
        let mut s = IkSolver::new(algorithm);
        s.options.max_attempts = usize::MAX;
        s.options.time_budget = Some(Duration::from_millis(5));
        let mut i = 0;
        c.bench_function(&format!("jaco_{name}_warm"), |b| {
            b.iter(|| {
                i = (i + 1) % N;
                let target = Target::pose(walk[i + 1].1);
                black_box(s.solve(&jaco, black_box(&target), &walk[i].0))
            })
        });
        let mut i = 0;
        c.bench_function(&format!("jaco_{name}_cold"), |b| {
            b.iter(|| {
                i = (i + 1) % N;
                let target = Target::pose(cold[i].1);
                black_box(s.solve_with_budget(
                    &jaco,
                    black_box(&target),
                    &cold[i].0,
                    &mut rng,
                    &mut Instant::now(),
                ))
            })
        });
    }
    let arm = Arm::default();
    let eezy = arm.serial_chain(&load("eezybot.urdf")).unwrap();
    let targets: Vec<_> = (0..N)
        .map(|_| {
            let x = eezy.random_configuration(&mut rng);
            arm.forward(&ArmJoints {
                base_rad: x[0],
                shoulder_rad: x[1],
                elbow_rad: x[2],
            })
        })
        .collect();
    let home = [
        0.0,
        std::f64::consts::FRAC_PI_2,
        -std::f64::consts::FRAC_PI_2,
    ];
    let s = IkSolver::default();
    let mut i = 0;
    c.bench_function("eezybot_dls_from_home", |b| {
        b.iter(|| {
            i = (i + 1) % N;
            black_box(s.solve(&eezy, black_box(&Target::position(targets[i])), &home))
        })
    });
    let mut i = 0;
    c.bench_function("eezybot_closed_form", |b| {
        b.iter(|| {
            i = (i + 1) % N;
            black_box(arm.solve_position(black_box(&targets[i]), 0.0))
        })
    });
    let q = walk[0].0.clone();
    c.bench_function("jaco_fk_and_jacobian", |b| {
        b.iter(|| black_box(jaco.jacobian(black_box(&q))))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
