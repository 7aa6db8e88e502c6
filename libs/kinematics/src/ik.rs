//! Numerical inverse kinematics of any [`SerialChain`]: pseudo-inverse Jacobian, damped
//! least squares with adaptive damping, and Newton–Raphson; position-only, full-pose
//! and weighted targets; joint limits and linear joint couplings respected; random
//! restarts within an attempt count and a time budget.
//!
//! One attempt iterates `x ← P(x + Δx)` where `P` projects onto the limits
//! ([`SerialChain::project`]) and `Δx` comes from the weighted task error
//! `ê = W·[p* − p; R*ᵀ·log(R*·Rᵀ)]` and Jacobian `Ĵ = W·[J_v; R*ᵀ·J_ω]`:
//!
//! * [`IkAlgorithm::PseudoInverse`]: `Δx = Ĵ⁺ê` (SVD, singular values below
//!   [`IkOptions::singular_value_cutoff`] dropped), scaled down so no joint moves more
//!   than [`IkOptions::max_step`]; every step is taken (the classic resolved-rate loop).
//! * [`IkAlgorithm::DampedLeastSquares`]: `Δx = Ĵᵀ(ĴĴᵀ + λI)⁻¹ê` with the adaptive
//!   damping `λ = μ·E + λ₀`, `E = ½|ê|²` (Sugihara's error-dependent damping: large far
//!   from the target, vanishing near it so convergence ends quadratic), and `μ` adapted
//!   Levenberg–Marquardt style: a step that lowers `E` is taken and `μ` shrinks, one that
//!   does not is refused and `μ` grows ([`Damping`]).
//! * [`IkAlgorithm::NewtonRaphson`]: the Newton step `Δx = Ĵ⁺ê` (for a square,
//!   regular Jacobian `Ĵ⁻¹ê`) with a backtracking line search on `E` (Armijo, halving).
//!
//! An attempt ends converged, or at [`IkOptions::max_iterations`], or stalled (a local
//! minimum: no decrease of `E` by 1 % in [`IkOptions::stall_iterations`] steps). Further
//! attempts start from random configurations ([`SerialChain::random_configuration`]),
//! up to [`IkOptions::max_attempts`] and, with [`IkSolver::solve_with_budget`], within
//! [`IkOptions::time_budget`].
//!
//! # Examples
//! ```
//! use eezybot_kinematics::{Arm, ik::{IkSolver, Target}, urdf::RobotModel};
//! let model = RobotModel::load(std::path::Path::new(concat!(
//!     env!("CARGO_MANIFEST_DIR"), "/../../urdf/eezybot.urdf"))).unwrap();
//! let arm = Arm::default();
//! let chain = arm.serial_chain(&model).unwrap();
//! let target = nalgebra::Vector3::new(0.2, 0.05, 0.15);
//! let mut solver = IkSolver::default();
//! solver.options.position_tolerance_m = 1e-12; // default 1e-5
//! let sol = solver
//!     .solve(&chain, &Target::position(target), &[0.0, 1.5707963267948966, -1.5707963267948966])
//!     .unwrap();
//! // the same joints as the closed form
//! let closed = arm.solve_position(&target, 0.0).unwrap();
//! assert!((sol.joints[1] - closed.shoulder_rad).abs() < 1e-9);
//! assert!(sol.report.position_error_m <= 1e-12 && !sol.report.near_singular);
//! ```

use crate::chain::{LimitProximity, SerialChain};
use crate::rng::SplitMix64;
use crate::KinematicsError;
use nalgebra::{DMatrix, DVector, Isometry3, Matrix6, Matrix6xX, Vector3, Vector6};
use std::time::Duration;

/// What the tip should reach, and how much each component matters.
#[derive(Clone, Debug, PartialEq)]
pub struct Target {
    /// Desired tip pose in the chain's base frame (only its translation for a
    /// position-only target).
    pub pose: Isometry3<f64>,
    /// Weights of the x, y, z position errors (base frame; 0 = that axis is free).
    pub position_weights: Vector3<f64>,
    /// Weights of the orientation error about the target frame's x, y, z axes
    /// (0 = free, e.g. the roll about a tool axis a 5-DOF arm cannot control).
    pub orientation_weights: Vector3<f64>,
    /// Whether the weighted orientation must be reached for success. When `false`, the
    /// orientation is pursued only in the null space of the position task (task
    /// priority), and success is judged on the position alone: for arms that cannot
    /// reach every orientation.
    pub orientation_required: bool,
}

impl Target {
    /// A position-only target (m, base frame).
    pub fn position(p: Vector3<f64>) -> Self {
        Target {
            pose: Isometry3::translation(p.x, p.y, p.z),
            position_weights: Vector3::repeat(1.0),
            orientation_weights: Vector3::zeros(),
            orientation_required: false,
        }
    }

    /// A full-pose target: position and orientation required, unit weights (m and rad).
    pub fn pose(pose: Isometry3<f64>) -> Self {
        Target {
            pose,
            position_weights: Vector3::repeat(1.0),
            orientation_weights: Vector3::repeat(1.0),
            orientation_required: true,
        }
    }

    /// A pose whose orientation is only preferred, with weight `weight` on every axis:
    /// the position is reached exactly and the orientation as well as the arm can.
    pub fn pose_preferred(pose: Isometry3<f64>, weight: f64) -> Self {
        Target {
            orientation_weights: Vector3::repeat(weight),
            orientation_required: false,
            ..Target::pose(pose)
        }
    }

    fn has_orientation(&self) -> bool {
        self.orientation_weights.iter().any(|w| *w != 0.0)
    }

    /// Task rows that matter: x, y, z position, then orientation about x, y, z.
    pub fn active_rows(&self) -> [bool; 6] {
        let p = &self.position_weights;
        let o = &self.orientation_weights;
        [
            p.x != 0.0,
            p.y != 0.0,
            p.z != 0.0,
            o.x != 0.0,
            o.y != 0.0,
            o.z != 0.0,
        ]
    }

    fn check(&self) -> Result<(), KinematicsError> {
        let t = &self.pose.translation.vector;
        let q = self.pose.rotation.coords;
        let values = [t.x, t.y, t.z, q.x, q.y, q.z, q.w];
        let weights = self
            .position_weights
            .iter()
            .chain(self.orientation_weights.iter());
        for (index, value) in values.iter().chain(weights).enumerate() {
            if !value.is_finite() {
                return Err(KinematicsError::NonFiniteValue {
                    what: "target (x y z qx qy qz qw, then weights)",
                    index,
                    value: *value,
                });
            }
        }
        Ok(())
    }
}

/// The numerical method of one attempt (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum IkAlgorithm {
    /// Truncated-SVD pseudo-inverse, step length capped, every step taken.
    PseudoInverse,
    /// Damped least squares, damping adapted to the error and to each step's success.
    DampedLeastSquares,
    /// Newton–Raphson with a backtracking line search.
    NewtonRaphson,
}

/// The adaptive damping of [`IkAlgorithm::DampedLeastSquares`]: `λ = μ·E + bias`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Damping {
    /// Initial `μ`.
    pub initial: f64,
    /// `μ` is multiplied by this after a successful step (< 1).
    pub decrease: f64,
    /// `μ` is multiplied by this after a refused step (> 1).
    pub increase: f64,
    /// Smallest `μ`.
    pub min: f64,
    /// Largest `μ`: beyond it the attempt is at a local minimum and ends.
    pub max: f64,
    /// Constant part `λ₀` (keeps `ĴĴᵀ + λI` regular at exact singularities).
    pub bias: f64,
}

impl Default for Damping {
    fn default() -> Self {
        Damping {
            initial: 1.0,
            decrease: 0.3,
            increase: 8.0,
            min: 1e-3,
            max: 1e8,
            bias: 1e-12,
        }
    }
}

/// Solver settings. The defaults suit arms of 0.1–1 m (errors in m and rad).
#[derive(Clone, Debug, PartialEq)]
pub struct IkOptions {
    /// The method.
    pub algorithm: IkAlgorithm,
    /// Steps (taken or refused) per attempt.
    pub max_iterations: usize,
    /// Attempts: the seed, then random restarts (1 = no restart).
    pub max_attempts: usize,
    /// Wall-clock budget over all attempts ([`IkSolver::solve_with_budget`] only).
    pub time_budget: Option<Duration>,
    /// Success: position error (weighted axes, m) at most this.
    pub position_tolerance_m: f64,
    /// Success: orientation error (weighted axes, rad) at most this, when required.
    pub orientation_tolerance_rad: f64,
    /// Largest change of any variable in one pseudo-inverse step (rad or m).
    pub max_step: f64,
    /// Singular values below this are treated as zero by the pseudo-inverse.
    pub singular_value_cutoff: f64,
    /// Adaptive damping of the DLS method.
    pub damping: Damping,
    /// An attempt that has not lowered `E` by 1 % in this many steps has stalled.
    pub stall_iterations: usize,
    /// Results report `near_singular` when the smallest singular value of the task
    /// Jacobian (active rows, unweighted; m/rad and rad/rad) is below this.
    pub singular_threshold: f64,
    /// Results report limits closer than this (rad or m).
    pub limit_margin: f64,
    /// Seed of the restart generator of [`IkSolver::solve`].
    pub random_seed: u64,
}

impl Default for IkOptions {
    fn default() -> Self {
        IkOptions {
            algorithm: IkAlgorithm::DampedLeastSquares,
            max_iterations: 100,
            max_attempts: 1,
            time_budget: None,
            position_tolerance_m: 1e-5,
            orientation_tolerance_rad: 1e-4,
            max_step: 0.5,
            singular_value_cutoff: 1e-9,
            damping: Damping::default(),
            stall_iterations: 6,
            singular_threshold: 1e-2,
            limit_margin: 1e-3,
            random_seed: 0x5EED,
        }
    }
}

/// How a solve went. Also reported, in part, by [`KinematicsError::IkNotConverged`].
#[derive(Clone, Debug, PartialEq)]
pub struct IkReport {
    /// Steps over all attempts.
    pub iterations: usize,
    /// Attempts (1 = converged from the seed).
    pub attempts: usize,
    /// Position error left, weighted axes only (m).
    pub position_error_m: f64,
    /// Orientation error left, weighted axes only (rad; 0 for position-only targets).
    pub orientation_error_rad: f64,
    /// Yoshikawa's manipulability: the product of the singular values of the task
    /// Jacobian (active rows, unweighted).
    pub manipulability: f64,
    /// Its smallest singular value (0 when there are fewer variables than task rows).
    pub min_singular_value: f64,
    /// `min_singular_value` below [`IkOptions::singular_threshold`].
    pub near_singular: bool,
    /// Limits within [`IkOptions::limit_margin`].
    pub near_limits: Vec<LimitProximity>,
}

/// A converged solve.
#[derive(Clone, Debug, PartialEq)]
pub struct IkSolution {
    /// The variables (in [`SerialChain::variables`] order).
    pub joints: Vec<f64>,
    /// Iterations, residuals, manipulability, singularity and limits.
    pub report: IkReport,
}

/// A clock handed in for time budgets (the solver itself reads none).
pub trait Stopwatch {
    /// Time since the solve started.
    fn elapsed(&mut self) -> Duration;
}

impl Stopwatch for std::time::Instant {
    fn elapsed(&mut self) -> Duration {
        std::time::Instant::elapsed(self)
    }
}

/// A numerical IK solver: options plus the methods. Cheap to clone; holds no state
/// between solves.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IkSolver {
    /// Settings.
    pub options: IkOptions,
}

/// Errors and merit of one configuration.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Eval {
    pub(crate) error: Vector6<f64>,
    pub(crate) position_m: f64,
    pub(crate) orientation_rad: f64,
    /// ½|ê|² of the primary task (everything when the orientation is required).
    pub(crate) energy: f64,
    /// ½|ê|² of a preferred orientation (0 otherwise).
    pub(crate) secondary: f64,
}

/// Buffers reused over the iterations of a solve.
pub(crate) struct Workspace {
    jac: Matrix6xX<f64>,
    jac_new: Matrix6xX<f64>,
    weighted: Matrix6xX<f64>,
    x_new: Vec<f64>,
    dx: Vec<f64>,
}

impl Workspace {
    pub(crate) fn new(n: usize) -> Self {
        Workspace {
            jac: Matrix6xX::zeros(n),
            jac_new: Matrix6xX::zeros(n),
            weighted: Matrix6xX::zeros(n),
            x_new: vec![0.0; n],
            dx: vec![0.0; n],
        }
    }
}

/// How one attempt ended.
pub(crate) struct Attempt {
    pub(crate) iterations: usize,
    pub(crate) eval: Eval,
    pub(crate) converged: bool,
}

impl IkSolver {
    /// A solver with default options and this algorithm.
    pub fn new(algorithm: IkAlgorithm) -> Self {
        IkSolver {
            options: IkOptions {
                algorithm,
                ..IkOptions::default()
            },
        }
    }

    /// Solves from `seed` (projected into the limits first), then from random
    /// configurations up to [`IkOptions::max_attempts`] (restarts drawn from
    /// [`IkOptions::random_seed`]: the same call gives the same answer).
    pub fn solve(
        &self,
        chain: &SerialChain,
        target: &Target,
        seed: &[f64],
    ) -> Result<IkSolution, KinematicsError> {
        let mut rng = SplitMix64::new(self.options.random_seed);
        self.solve_inner(chain, target, seed, &mut rng, None)
    }

    /// As [`IkSolver::solve`], with restarts from `rng` and no new attempt once `clock`
    /// passes [`IkOptions::time_budget`] (an attempt under way finishes).
    ///
    /// # Examples
    /// Cold start on the 6-DOF Jaco: a random seed, restarts for up to 0.5 s.
    /// ```
    /// use eezybot_kinematics::{chain::SerialChain, ik::*, rng::SplitMix64, urdf::RobotModel};
    /// let model = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/jaco.urdf"))).unwrap();
    /// let chain = SerialChain::from_model(&model, "base_link", "jaco_end_effector").unwrap();
    /// let mut rng = SplitMix64::new(1);
    /// let goal = chain.forward(&chain.random_configuration(&mut rng)).unwrap();
    /// let mut solver = IkSolver::default();
    /// solver.options.max_attempts = 100;
    /// solver.options.time_budget = Some(std::time::Duration::from_millis(500));
    /// let seed = chain.random_configuration(&mut rng);
    /// let sol = solver
    ///     .solve_with_budget(&chain, &Target::pose(goal), &seed, &mut rng, &mut std::time::Instant::now())
    ///     .unwrap();
    /// let reached = chain.forward(&sol.joints).unwrap();
    /// assert!((reached.translation.vector - goal.translation.vector).norm() <= 1e-5);
    /// ```
    pub fn solve_with_budget(
        &self,
        chain: &SerialChain,
        target: &Target,
        seed: &[f64],
        rng: &mut SplitMix64,
        clock: &mut dyn Stopwatch,
    ) -> Result<IkSolution, KinematicsError> {
        self.solve_inner(chain, target, seed, rng, Some(clock))
    }

    fn solve_inner(
        &self,
        chain: &SerialChain,
        target: &Target,
        seed: &[f64],
        rng: &mut SplitMix64,
        mut clock: Option<&mut dyn Stopwatch>,
    ) -> Result<IkSolution, KinematicsError> {
        chain.check(seed)?;
        target.check()?;
        let o = &self.options;
        let mut ws = Workspace::new(chain.dof());
        let mut x = seed.to_vec();
        let mut best: Option<(Vec<f64>, Eval)> = None;
        let (mut iterations, mut attempts) = (0, 0);
        loop {
            attempts += 1;
            let a = self.attempt(chain, target, &mut x, &mut ws);
            iterations += a.iterations;
            if a.converged {
                let report = self.report(chain, target, &x, &a.eval, iterations, attempts);
                return Ok(IkSolution { joints: x, report });
            }
            if best.as_ref().is_none_or(|(_, b)| a.eval.energy < b.energy) {
                best = Some((x.clone(), a.eval));
            }
            let out_of_time = match (&mut clock, o.time_budget) {
                (Some(c), Some(budget)) => c.elapsed() >= budget,
                _ => false,
            };
            if attempts >= o.max_attempts || out_of_time {
                break;
            }
            chain.random_into(rng, &mut x);
        }
        let (position_error_m, orientation_error_rad) = best
            .map(|(_, e)| (e.position_m, e.orientation_rad))
            .unwrap_or((f64::INFINITY, f64::INFINITY));
        Err(KinematicsError::IkNotConverged {
            position_error_m,
            orientation_error_rad,
            iterations,
            attempts,
        })
    }

    /// Residuals, manipulability and limits at `x` (for a result or a failure report).
    fn report(
        &self,
        chain: &SerialChain,
        target: &Target,
        x: &[f64],
        eval: &Eval,
        iterations: usize,
        attempts: usize,
    ) -> IkReport {
        let (manipulability, min_singular_value) = task_singular_values(chain, target, x);
        IkReport {
            iterations,
            attempts,
            position_error_m: eval.position_m,
            orientation_error_rad: eval.orientation_rad,
            manipulability,
            min_singular_value,
            near_singular: min_singular_value < self.options.singular_threshold,
            near_limits: chain.near_limits(x, self.options.limit_margin),
        }
    }

    /// The step direction of the algorithm into `dx`, restricted to the tangent space of
    /// the limits it would push through (an active set: a variable at a bound or a
    /// constraint at its bound with the step pointing out), so that solves slide along
    /// limits instead of being clipped by the projection. False if the damped system is
    /// not positive definite (the caller raises the damping).
    #[allow(clippy::too_many_arguments)]
    fn direction(
        &self,
        chain: &SerialChain,
        x: &[f64],
        weighted: &Matrix6xX<f64>,
        error: &Vector6<f64>,
        lambda: f64,
        priority: bool,
        dx: &mut [f64],
    ) -> bool {
        let o = &self.options;
        let raw = |j: &Matrix6xX<f64>, dx: &mut [f64]| -> bool {
            if priority {
                priority_direction(j, error, lambda, o.singular_value_cutoff, dx);
                true
            } else if o.algorithm == IkAlgorithm::DampedLeastSquares {
                dls_direction(j, error, lambda, dx)
            } else {
                pinv_direction(j, error, o.singular_value_cutoff, dx);
                true
            }
        };
        if !raw(weighted, dx) {
            return false;
        }
        let mut active: Vec<Vec<f64>> = Vec::new();
        for _ in 0..chain.dof() {
            let before = active.len();
            for normal in chain.blocking_limits(x, dx, 1e-10) {
                if !active.contains(&normal) {
                    active.push(normal);
                }
            }
            if active.len() == before {
                break;
            }
            // Ĵ·P with P = I − N N⁺ projecting out the active normals
            let n = chain.dof();
            let normals = DMatrix::from_fn(n, active.len(), |r, c| active[c][r]);
            let p = DMatrix::identity(n, n) - &normals * pseudo_inverse(&normals, 0.0, 1e-12);
            let mut restricted = Matrix6xX::zeros(n);
            for r in 0..6 {
                for c in 0..n {
                    restricted[(r, c)] = (0..n).map(|k| weighted[(r, k)] * p[(k, c)]).sum();
                }
            }
            if !raw(&restricted, dx) {
                return false;
            }
            // numerical safety: keep the step in the tangent space
            let v = DVector::from_column_slice(dx);
            let v = &p * v;
            dx.copy_from_slice(v.as_slice());
        }
        true
    }

    pub(crate) fn converged(&self, target: &Target, e: &Eval) -> bool {
        e.position_m <= self.options.position_tolerance_m
            && (!target.orientation_required
                || e.orientation_rad <= self.options.orientation_tolerance_rad)
    }

    /// One attempt from `x` (projected first); `x` ends at the last accepted point.
    pub(crate) fn attempt(
        &self,
        chain: &SerialChain,
        target: &Target,
        x: &mut [f64],
        ws: &mut Workspace,
    ) -> Attempt {
        let o = &self.options;
        chain.project(x);
        let tip = chain.forward_jacobian_into(x, &mut ws.jac);
        let mut cur = evaluate(target, &tip);
        let priority = target.has_orientation() && !target.orientation_required;
        let mut mu = o.damping.initial;
        let mut reference = cur.energy; // for stall detection
        let mut since_progress = 0;
        let mut polishing = false;
        let mut it = 0;
        while it < o.max_iterations {
            if !polishing && self.converged(target, &cur) {
                if !priority {
                    return Attempt {
                        iterations: it,
                        eval: cur,
                        converged: true,
                    };
                }
                polishing = true; // position reached: improve the preferred orientation
            }
            it += 1;
            weighted_jacobian_into(target, &ws.jac, &mut ws.weighted);
            let lambda = match o.algorithm {
                IkAlgorithm::DampedLeastSquares => {
                    mu * (cur.energy + cur.secondary) + o.damping.bias
                }
                _ => 0.0,
            };
            if !self.direction(
                chain,
                x,
                &ws.weighted,
                &cur.error,
                lambda,
                priority,
                &mut ws.dx,
            ) {
                mu *= o.damping.increase;
                continue;
            }
            if o.algorithm == IkAlgorithm::PseudoInverse {
                let largest = ws.dx.iter().fold(0.0f64, |m, d| m.max(d.abs()));
                if largest > o.max_step {
                    let s = o.max_step / largest;
                    ws.dx.iter_mut().for_each(|d| *d *= s);
                }
            }
            let mut step = 1.0;
            let accepted = loop {
                for ((xn, xi), d) in ws.x_new.iter_mut().zip(x.iter()).zip(&ws.dx) {
                    *xn = xi + step * d;
                }
                chain.project(&mut ws.x_new);
                let tip = chain.forward_jacobian_into(&ws.x_new, &mut ws.jac_new);
                let new = evaluate(target, &tip);
                let better = if polishing {
                    self.converged(target, &new) && new.secondary < cur.secondary
                } else {
                    new.energy < cur.energy
                };
                match o.algorithm {
                    IkAlgorithm::PseudoInverse if !polishing => break Some(new),
                    _ if polishing && !better && step > 1.0 / 64.0 => {
                        step *= 0.5;
                        it += 1;
                        if it >= o.max_iterations {
                            break None;
                        }
                    }
                    IkAlgorithm::NewtonRaphson if !better && step > 1.0 / 64.0 && !polishing => {
                        step *= 0.5;
                        it += 1;
                        if it >= o.max_iterations {
                            break None;
                        }
                    }
                    _ => break better.then_some(new),
                }
            };
            match accepted {
                Some(new) => {
                    x.copy_from_slice(&ws.x_new);
                    std::mem::swap(&mut ws.jac, &mut ws.jac_new);
                    if polishing && new.secondary > 0.999 * cur.secondary {
                        cur = new;
                        break; // the preferred orientation no longer improves
                    }
                    cur = new;
                    mu = (mu * o.damping.decrease).max(o.damping.min);
                }
                None if polishing => break,
                None => {
                    if o.algorithm == IkAlgorithm::DampedLeastSquares {
                        mu *= o.damping.increase;
                        if mu > o.damping.max {
                            break; // a local minimum of E
                        }
                    } else {
                        break; // Newton: no descent along the line
                    }
                }
            }
            if polishing {
                continue;
            }
            if cur.energy < 0.99 * reference {
                reference = cur.energy;
                since_progress = 0;
            } else {
                since_progress += 1;
                if since_progress >= o.stall_iterations {
                    break;
                }
            }
        }
        let converged = self.converged(target, &cur);
        Attempt {
            iterations: it,
            eval: cur,
            converged,
        }
    }
}

/// Task errors of a tip pose.
pub(crate) fn evaluate(target: &Target, tip: &Isometry3<f64>) -> Eval {
    let wp = &target.position_weights;
    let wo = &target.orientation_weights;
    let dp = target.pose.translation.vector - tip.translation.vector;
    let mut error = Vector6::zeros();
    let mut position2 = 0.0;
    for i in 0..3 {
        if wp[i] != 0.0 {
            position2 += dp[i] * dp[i];
            error[i] = wp[i] * dp[i];
        }
    }
    let mut orientation2 = 0.0;
    if target.has_orientation() {
        let rt = target.pose.rotation;
        // rotation taking the tip to the target, about the target frame's axes
        let d = rt.inverse() * (rt * tip.rotation.inverse()).scaled_axis();
        for i in 0..3 {
            if wo[i] != 0.0 {
                orientation2 += d[i] * d[i];
                error[i + 3] = wo[i] * d[i];
            }
        }
    }
    let p2: f64 = error.fixed_rows::<3>(0).norm_squared();
    let o2: f64 = error.fixed_rows::<3>(3).norm_squared();
    let (energy, secondary) = if target.orientation_required {
        (0.5 * (p2 + o2), 0.0)
    } else {
        (0.5 * p2, 0.5 * o2)
    };
    Eval {
        error,
        position_m: position2.sqrt(),
        orientation_rad: orientation2.sqrt(),
        energy,
        secondary,
    }
}

/// `Ĵ = W·[J_v; R*ᵀ J_ω]`.
fn weighted_jacobian(target: &Target, jac: &Matrix6xX<f64>) -> Matrix6xX<f64> {
    let mut w = Matrix6xX::zeros(jac.ncols());
    weighted_jacobian_into(target, jac, &mut w);
    w
}

fn weighted_jacobian_into(target: &Target, jac: &Matrix6xX<f64>, w: &mut Matrix6xX<f64>) {
    w.copy_from(jac);
    let rt = target.pose.rotation.inverse().to_rotation_matrix();
    for mut col in w.column_iter_mut() {
        let ang = rt * Vector3::new(col[3], col[4], col[5]);
        for i in 0..3 {
            col[i] *= target.position_weights[i];
            col[i + 3] = ang[i] * target.orientation_weights[i];
        }
    }
}

/// `Δx = Ĵᵀ(ĴĴᵀ + λI)⁻¹ê` (a 6 × 6 Cholesky solve). False if not positive definite.
fn dls_direction(j: &Matrix6xX<f64>, e: &Vector6<f64>, lambda: f64, dx: &mut [f64]) -> bool {
    let a: Matrix6<f64> = j * j.transpose() + Matrix6::identity() * lambda;
    let Some(chol) = a.cholesky() else {
        return false;
    };
    let y = chol.solve(e);
    for (d, col) in dx.iter_mut().zip(j.column_iter()) {
        *d = col.dot(&y);
    }
    dx.iter().all(|d| d.is_finite())
}

/// Damped (λ > 0) or truncated (λ = 0) pseudo-inverse of `a` through its SVD.
fn pseudo_inverse(a: &DMatrix<f64>, lambda: f64, cutoff: f64) -> DMatrix<f64> {
    let svd = a.clone().svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return DMatrix::zeros(a.ncols(), a.nrows());
    };
    let k = svd.singular_values.len();
    let mut inv = DMatrix::zeros(a.ncols(), a.nrows());
    for i in 0..k {
        let s = svd.singular_values[i];
        let f = if lambda > 0.0 {
            s / (s * s + lambda)
        } else if s > cutoff {
            1.0 / s
        } else {
            0.0
        };
        if f != 0.0 {
            inv += v_t.row(i).transpose() * u.column(i).transpose() * f;
        }
    }
    inv
}

/// `Δx = Ĵ⁺ê` with the truncated SVD pseudo-inverse.
fn pinv_direction(j: &Matrix6xX<f64>, e: &Vector6<f64>, cutoff: f64, dx: &mut [f64]) {
    let svd = j.clone().svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        dx.iter_mut().for_each(|d| *d = 0.0);
        return;
    };
    dx.iter_mut().for_each(|d| *d = 0.0);
    for (i, s) in svd.singular_values.iter().enumerate() {
        if *s > cutoff {
            let c = u.column(i).dot(e) / s;
            for (d, v) in dx.iter_mut().zip(v_t.row(i).iter()) {
                *d += c * v;
            }
        }
    }
}

/// Two-level task priority (position first, orientation in its null space):
/// `Δx = J₁#e₁ + (J₂N₁)#(e₂ − J₂J₁#e₁)`, `N₁ = I − J₁⁺J₁`, `#` damped by λ (or truncated).
fn priority_direction(
    j: &Matrix6xX<f64>,
    e: &Vector6<f64>,
    lambda: f64,
    cutoff: f64,
    dx: &mut [f64],
) {
    let n = j.ncols();
    let j1 = DMatrix::from_fn(3, n, |r, c| j[(r, c)]);
    let j2 = DMatrix::from_fn(3, n, |r, c| j[(r + 3, c)]);
    let e1 = DVector::from_fn(3, |r, _| e[r]);
    let e2 = DVector::from_fn(3, |r, _| e[r + 3]);
    let dx1 = pseudo_inverse(&j1, lambda, cutoff) * &e1;
    let null = DMatrix::identity(n, n) - pseudo_inverse(&j1, 0.0, cutoff) * &j1;
    let j2n = &j2 * &null;
    let dx2 = &null * (pseudo_inverse(&j2n, lambda, cutoff) * (e2 - &j2 * &dx1));
    for (i, d) in dx.iter_mut().enumerate() {
        *d = dx1[i] + dx2[i];
    }
}

/// Manipulability (product of singular values) and smallest singular value of the
/// unweighted task Jacobian's active rows (orientation rows about the target axes).
pub(crate) fn task_singular_values(chain: &SerialChain, target: &Target, x: &[f64]) -> (f64, f64) {
    let mut jac = Matrix6xX::zeros(chain.dof());
    chain.forward_jacobian_into(x, &mut jac);
    let unit = Target {
        position_weights: target
            .position_weights
            .map(|w| if w != 0.0 { 1.0 } else { 0.0 }),
        orientation_weights: target
            .orientation_weights
            .map(|w| if w != 0.0 { 1.0 } else { 0.0 }),
        ..target.clone()
    };
    let rows = unit.active_rows();
    singular_values_of_rows(&weighted_jacobian(&unit, &jac), &rows)
}

pub(crate) fn singular_values_of_rows(jac: &Matrix6xX<f64>, rows: &[bool; 6]) -> (f64, f64) {
    let active: Vec<usize> = (0..6).filter(|r| rows[*r]).collect();
    let n = jac.ncols();
    if active.is_empty() || n == 0 {
        return (0.0, 0.0);
    }
    let a = DMatrix::from_fn(active.len(), n, |r, c| jac[(active[r], c)]);
    let s = a.singular_values();
    let product = s.iter().product();
    let min = if active.len() > n {
        0.0
    } else {
        s.iter().copied().fold(f64::INFINITY, f64::min)
    };
    (product, min)
}
