//! Issue 10's IK benchmark: random reachable poses of the 6-DOF Jaco (urdf/jaco.urdf),
//! for each solver, warm-started (a random joint-space walk with small steps, each pose
//! solved from the previous solution) and cold-started (independent poses, each from a
//! random seed, random restarts within the time budget); the `k` crate's
//! `JacobianIkSolver` on the same poses. Success = position within 1e-5 m, orientation
//! within 1e-4 rad (checked by an independent FK) and every limit respected.
//!
//! `cargo run --release --manifest-path libs/kinematics/ik_bench/Cargo.toml -- [--poses N]
//! [--budget-ms B] [--step-rad S] [--seed N]`
#![allow(clippy::unwrap_used, clippy::expect_used)]

use eezybot_kinematics::chain::SerialChain;
use eezybot_kinematics::ik::{IkAlgorithm, IkSolver, Target};
use eezybot_kinematics::rng::SplitMix64;
use eezybot_kinematics::urdf::RobotModel;
use k::InverseKinematicsSolver;
use nalgebra::Isometry3;
use std::path::Path;
use std::time::{Duration, Instant};

const POSITION_TOL: f64 = 1e-5;
const ORIENTATION_TOL: f64 = 1e-4;

struct Args {
    poses: usize,
    budget: Duration,
    step_rad: f64,
    seed: u64,
}

fn args() -> Args {
    let mut a = Args {
        poses: 10_000,
        budget: Duration::from_millis(5),
        step_rad: 0.02,
        seed: 2024,
    };
    let v: Vec<String> = std::env::args().skip(1).collect();
    for pair in v.chunks(2) {
        let value = pair.get(1).map(String::as_str).unwrap_or("");
        match pair[0].as_str() {
            "--poses" => a.poses = value.parse().expect("--poses N"),
            "--budget-ms" => {
                a.budget =
                    Duration::from_secs_f64(value.parse::<f64>().expect("--budget-ms B") / 1e3)
            }
            "--step-rad" => a.step_rad = value.parse().expect("--step-rad S"),
            "--seed" => a.seed = value.parse().expect("--seed N"),
            "--bench" => {} // cargo bench passes this
            other => panic!("unknown argument {other}"),
        }
    }
    a
}

/// Whether `x` reaches `goal` within the tolerances and the limits.
fn reached(chain: &SerialChain, x: &[f64], goal: &Isometry3<f64>) -> bool {
    let Ok(tip) = chain.forward(x) else {
        return false;
    };
    let dp = (tip.translation.vector - goal.translation.vector).norm();
    let dr = (tip.rotation.inverse() * goal.rotation)
        .scaled_axis()
        .norm();
    dp <= POSITION_TOL && dr <= ORIENTATION_TOL && chain.within_limits(x, 1e-9)
}

#[derive(Default)]
struct Stats {
    ok: usize,
    times: Vec<Duration>,
    iterations: usize,
    attempts: usize,
}

impl Stats {
    fn line(&mut self, name: &str) -> String {
        let n = self.times.len().max(1);
        self.times.sort_unstable();
        let pct = |p: f64| self.times[((n as f64 - 1.0) * p).round() as usize].as_secs_f64() * 1e6;
        let mean = self.times.iter().map(Duration::as_secs_f64).sum::<f64>() / n as f64 * 1e6;
        format!(
            "| {name:<34} | {:>8.3} % | {:>9.1} | {:>9.1} | {:>9.1} | {:>6.1} | {:>5.2} |",
            100.0 * self.ok as f64 / n as f64,
            pct(0.5),
            pct(0.99),
            mean,
            self.iterations as f64 / n as f64,
            self.attempts as f64 / n as f64,
        )
    }
}

/// A random walk through joint space (steps uniform in ±step per joint, kept inside the
/// limits): consecutive poses are close.
fn trajectory(
    chain: &SerialChain,
    n: usize,
    step: f64,
    rng: &mut SplitMix64,
) -> Vec<(Vec<f64>, Isometry3<f64>)> {
    let mut x = chain.random_configuration(rng);
    (0..n)
        .map(|_| {
            for xi in x.iter_mut() {
                *xi += rng.uniform(-step, step);
            }
            chain.project(&mut x);
            (x.clone(), chain.forward(&x).unwrap())
        })
        .collect()
}

fn solver(algorithm: IkAlgorithm, budget: Duration) -> IkSolver {
    let mut s = IkSolver::new(algorithm);
    s.options.max_attempts = usize::MAX;
    s.options.time_budget = Some(budget);
    // IK_BENCH_TUNE="stall,max_iterations,max_step" overrides, for tuning experiments
    if let Ok(t) = std::env::var("IK_BENCH_TUNE") {
        let v: Vec<f64> = t
            .split(',')
            .map(|x| x.parse().expect("IK_BENCH_TUNE numbers"))
            .collect();
        s.options.stall_iterations = v[0] as usize;
        s.options.max_iterations = v[1] as usize;
        s.options.max_step = v[2];
    }
    s
}

#[allow(clippy::too_many_arguments)]
fn run_ours(
    chain: &SerialChain,
    s: &IkSolver,
    goals: &[Isometry3<f64>],
    seeds: Option<&[Vec<f64>]>,
    first: &[f64],
    rng: &mut SplitMix64,
    truth: &[Vec<f64>],
) -> Stats {
    let mut st = Stats::default();
    let mut previous = first.to_vec();
    let diagnose = std::env::var_os("IK_BENCH_DIAGNOSE").is_some();
    for (i, goal) in goals.iter().enumerate() {
        let seed = seeds.map_or(&previous, |s| &s[i]);
        let target = Target::pose(*goal);
        let t0 = Instant::now();
        let r = s.solve_with_budget(chain, &target, seed, rng, &mut Instant::now());
        st.times.push(t0.elapsed());
        match r {
            Ok(sol) => {
                st.iterations += sol.report.iterations;
                st.attempts += sol.report.attempts;
                if reached(chain, &sol.joints, goal) {
                    st.ok += 1;
                }
                previous = sol.joints;
            }
            Err(
                e @ eezybot_kinematics::KinematicsError::IkNotConverged {
                    iterations,
                    attempts,
                    ..
                },
            ) => {
                st.iterations += iterations;
                st.attempts += attempts;
                if diagnose {
                    // how the generating joints look: singular? at a limit?
                    let r = s.solve(chain, &target, &truth[i]).map(|s| s.report);
                    eprintln!("pose {i}: {e}\n  truth {:?}\n  {r:?}", truth[i]);
                }
            }
            Err(e) => panic!("{e}"),
        }
    }
    st
}

fn k_pose(p: &Isometry3<f64>) -> k::Isometry3<f64> {
    let t = p.translation.vector;
    let q = p.rotation.coords;
    k::Isometry3::from_parts(
        k::Translation3::new(t.x, t.y, t.z),
        k::UnitQuaternion::from_quaternion(k::nalgebra::Quaternion::new(q.w, q.x, q.y, q.z)),
    )
}

#[allow(clippy::too_many_arguments)]
fn run_k(
    chain: &SerialChain,
    arm: &k::SerialChain<f64>,
    ks: &k::JacobianIkSolver<f64>,
    goals: &[Isometry3<f64>],
    seeds: Option<&[Vec<f64>]>,
    first: &[f64],
    budget: Duration,
    rng: &mut SplitMix64,
) -> Stats {
    let mut st = Stats::default();
    let mut previous = first.to_vec();
    for (i, goal) in goals.iter().enumerate() {
        let target = k_pose(goal);
        let t0 = Instant::now();
        let mut seed = seeds.map_or(previous.clone(), |s| s[i].clone());
        let mut ok = false;
        loop {
            st.attempts += 1;
            arm.set_joint_positions_clamped(&seed);
            if ks.solve(arm, &target).is_ok() {
                ok = true;
                break;
            }
            if t0.elapsed() >= budget {
                break;
            }
            seed = chain.random_configuration(rng);
        }
        st.times.push(t0.elapsed());
        st.iterations += 0;
        if ok {
            let x = arm.joint_positions();
            if reached(chain, &x, goal) {
                st.ok += 1;
            }
            previous = x;
        }
    }
    st
}

fn main() {
    let a = args();
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../urdf/jaco.urdf");
    let model = RobotModel::load(&urdf).unwrap();
    let chain = SerialChain::from_model(&model, "base_link", "jaco_end_effector").unwrap();
    let mut rng = SplitMix64::new(a.seed);

    let walk = trajectory(&chain, a.poses, a.step_rad, &mut rng);
    let walk_goals: Vec<Isometry3<f64>> = walk.iter().map(|(_, g)| *g).collect();
    let walk_truth: Vec<Vec<f64>> = walk.iter().map(|(x, _)| x.clone()).collect();
    let walk_start = walk[0].0.clone();
    let cold_truth: Vec<Vec<f64>> = (0..a.poses)
        .map(|_| chain.random_configuration(&mut rng))
        .collect();
    let cold_goals: Vec<Isometry3<f64>> = cold_truth
        .iter()
        .map(|x| chain.forward(x).unwrap())
        .collect();
    let cold_seeds: Vec<Vec<f64>> = (0..a.poses)
        .map(|_| chain.random_configuration(&mut rng))
        .collect();

    println!(
        "Jaco 2 (6 DOF, urdf/jaco.urdf), {} poses; success = {POSITION_TOL:e} m and {ORIENTATION_TOL:e} rad, limits kept;",
        a.poses
    );
    println!(
        "warm: joint-space walk, steps uniform in ±{} rad per joint, each pose from the previous solution;",
        a.step_rad
    );
    println!(
        "cold: independent poses, each from a random seed, random restarts within {:?}. Times per solve in µs.",
        a.budget
    );
    println!();
    println!("| solver                             | success    |   p50 µs  |   p99 µs  |  mean µs  | iters | tries |");
    println!("|------------------------------------|------------|-----------|-----------|-----------|-------|-------|");
    for (name, alg) in [
        ("DLS (adaptive damping)", IkAlgorithm::DampedLeastSquares),
        ("Newton-Raphson (line search)", IkAlgorithm::NewtonRaphson),
        ("pseudo-inverse (capped step)", IkAlgorithm::PseudoInverse),
    ] {
        let s = solver(alg, a.budget);
        let mut warm = run_ours(
            &chain,
            &s,
            &walk_goals,
            None,
            &walk_start,
            &mut rng,
            &walk_truth,
        );
        println!("{}", warm.line(&format!("{name}, warm")));
        let mut cold = run_ours(
            &chain,
            &s,
            &cold_goals,
            Some(&cold_seeds),
            &walk_start,
            &mut rng,
            &cold_truth,
        );
        println!("{}", cold.line(&format!("{name}, cold")));
    }
    let kchain = k::Chain::<f64>::from_urdf_file(&urdf).unwrap();
    let end = kchain.find("jaco_end_effector_joint").unwrap();
    let arm = k::SerialChain::from_end(end);
    for multiplier in [0.5, 1.0] {
        let ks = k::JacobianIkSolver::new(POSITION_TOL, ORIENTATION_TOL, multiplier, 100);
        let mut warm = run_k(
            &chain,
            &arm,
            &ks,
            &walk_goals,
            None,
            &walk_start,
            a.budget,
            &mut rng,
        );
        println!(
            "{}",
            warm.line(&format!("k JacobianIkSolver ×{multiplier}, warm"))
        );
        let mut cold = run_k(
            &chain,
            &arm,
            &ks,
            &cold_goals,
            Some(&cold_seeds),
            &walk_start,
            a.budget,
            &mut rng,
        );
        println!(
            "{}",
            cold.line(&format!("k JacobianIkSolver ×{multiplier}, cold"))
        );
    }
    println!();
    println!("(k counts no iterations; its 'tries' are our restarts around it, same budget.)");
    println!("Published (UR5, Beeson & Ames 2015): TRAC-IK 99.55 % in 0.42 ms; KDL 35.88 % in 3.30 ms (mean).");
}
