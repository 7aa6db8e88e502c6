//! The numerical solvers as compute_ik uses them (the `solver` parameter): one serial
//! chain, solves warm-started from the arm's goal with random restarts within a time
//! budget, the nearest reachable point of an unreachable target, and the assessment of
//! a configuration (near a singularity, at a limit, the gripper pointing up) with a
//! direction away from each, worded for `diagnostics`. Pure but for the clock that
//! bounds a solve's restarts.

use eezybot_kinematics::assess::{
    assess, nearest_reachable, AssessOptions, Concern, ConfigurationCheck, NearestReachable,
    ToolAxisAway, Undesirable,
};
use eezybot_kinematics::chain::{Bound, SerialChain};
use eezybot_kinematics::ik::{IkAlgorithm, IkSolution, IkSolver, Target};
use eezybot_kinematics::rng::SplitMix64;
use eezybot_kinematics::KinematicsError;
use nalgebra::{Isometry3, Vector3};
use std::fmt::Write as _;
use std::time::{Duration, Instant};

/// The `solver` parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Solver {
    /// The EezyBot's closed form (ROBOT.md); for an arm without one, [`Solver::Dls`].
    Analytic,
    /// Pseudo-inverse Jacobian ([`IkAlgorithm::PseudoInverse`]).
    Jacobian,
    /// Damped least squares with adaptive damping ([`IkAlgorithm::DampedLeastSquares`]).
    Dls,
    /// Newton–Raphson with a line search ([`IkAlgorithm::NewtonRaphson`]).
    Newton,
}

impl Solver {
    /// Every value of the parameter, in the order of the documentation.
    pub const NAMES: [&'static str; 4] = ["analytic", "jacobian", "dls", "newton"];

    /// The parameter's value.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Analytic => "analytic",
            Solver::Jacobian => "jacobian",
            Solver::Dls => "dls",
            Solver::Newton => "newton",
        }
    }

    /// From the parameter's value.
    ///
    /// # Examples
    /// ```
    /// use compute_ik::numeric::Solver;
    /// assert_eq!(Solver::parse("dls"), Some(Solver::Dls));
    /// assert_eq!(Solver::parse("DLS"), None);
    /// ```
    pub fn parse(s: &str) -> Option<Solver> {
        match s {
            "analytic" => Some(Solver::Analytic),
            "jacobian" => Some(Solver::Jacobian),
            "dls" => Some(Solver::Dls),
            "newton" => Some(Solver::Newton),
            _ => None,
        }
    }

    /// The numerical method, `None` for the closed form.
    pub fn algorithm(self) -> Option<IkAlgorithm> {
        match self {
            Solver::Analytic => None,
            Solver::Jacobian => Some(IkAlgorithm::PseudoInverse),
            Solver::Dls => Some(IkAlgorithm::DampedLeastSquares),
            Solver::Newton => Some(IkAlgorithm::NewtonRaphson),
        }
    }

    /// The parameter's validator: an unknown value is refused with the valid ones.
    pub fn check(s: &str) -> Result<Solver, String> {
        Solver::parse(s).ok_or_else(|| {
            format!(
                "unknown solver `{s}`: use one of {}",
                Solver::NAMES.join(", ")
            )
        })
    }
}

/// How the node solves numerically. The tolerances are tight so that, on the EezyBot,
/// every numerical solver lands within 1e-9 m of the closed form.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NumericSettings {
    /// Success: position error at most this (m).
    pub position_tolerance_m: f64,
    /// Success: orientation error at most this (rad), when the orientation is required.
    pub orientation_tolerance_rad: f64,
    /// The warm start plus random restarts.
    pub max_attempts: usize,
    /// No restart once a solve has taken this long.
    pub time_budget: Duration,
    /// The nearest reachable point: attempts (DLS on the distance) and their budget.
    pub nearest_attempts: usize,
    /// Budget of the nearest-point search.
    pub nearest_budget: Duration,
}

impl Default for NumericSettings {
    fn default() -> Self {
        NumericSettings {
            position_tolerance_m: 1e-12,
            orientation_tolerance_rad: 1e-9,
            max_attempts: 16,
            time_budget: Duration::from_millis(20),
            nearest_attempts: 12,
            nearest_budget: Duration::from_millis(20),
        }
    }
}

/// What the last numerical solve did, for `diagnostics`.
#[derive(Clone, Debug, PartialEq)]
pub struct SolveRecord {
    /// The solver.
    pub solver: Solver,
    /// Converged?
    pub converged: bool,
    /// Iterations over all attempts.
    pub iterations: usize,
    /// Attempts (1 = from the warm start).
    pub attempts: usize,
    /// Position residual (m).
    pub position_error_m: f64,
    /// Orientation residual (rad).
    pub orientation_error_rad: f64,
    /// Wall time of the solve (µs).
    pub micros: f64,
}

impl SolveRecord {
    /// One line, e.g. `dls: converged in 4 iterations, 1 attempt, residual 2.1e-16 m / 0 rad, 31 µs`.
    pub fn describe(&self) -> String {
        format!(
            "{}: {} in {} iterations, {} attempt{}, residual {:.1e} m / {:.1e} rad, {:.0} µs",
            self.solver.name(),
            if self.converged {
                "converged"
            } else {
                "not converged"
            },
            self.iterations,
            self.attempts,
            if self.attempts == 1 { "" } else { "s" },
            self.position_error_m,
            self.orientation_error_rad,
            self.micros
        )
    }
}

/// A chain and everything the node needs to solve it numerically.
#[derive(Clone, Debug)]
pub struct NumericIk {
    chain: SerialChain,
    settings: NumericSettings,
    rng: SplitMix64,
    assess_options: AssessOptions,
    gripper_up: Option<ToolAxisAway>,
    last: Option<SolveRecord>,
}

/// The smallest angle (deg) the `gripper_up` check allows by default between the tip's z
/// axis (its approach axis) and straight up.
pub const GRIPPER_UP_DEFAULT_DEG: f64 = 60.0;

impl NumericIk {
    /// For this chain. `pose_rows`: whether singularities are judged on all six task
    /// rows (an arm that can orient its tool) or on the position rows only.
    pub fn new(chain: SerialChain, pose_rows: bool) -> NumericIk {
        NumericIk {
            chain,
            settings: NumericSettings::default(),
            rng: SplitMix64::new(0x1C0_FFEE),
            assess_options: if pose_rows {
                AssessOptions::pose()
            } else {
                AssessOptions::position()
            },
            gripper_up: None,
            last: None,
        }
    }

    /// The chain.
    pub fn chain(&self) -> &SerialChain {
        &self.chain
    }

    /// The settings.
    pub fn settings(&self) -> &NumericSettings {
        &self.settings
    }

    /// The seed report's undesirable configuration, the gripper facing upwards: the
    /// tip's z axis closer than `min_angle_deg` to the base's +z (`None` or 0: no check).
    pub fn set_gripper_up(&mut self, min_angle_deg: Option<f64>) {
        self.gripper_up = min_angle_deg.filter(|a| *a > 0.0).map(|a| ToolAxisAway {
            name: "gripper_up".into(),
            axis: Vector3::z_axis(),
            forbidden: Vector3::z_axis(),
            min_angle_rad: a.to_radians(),
        });
    }

    /// What the last solve did.
    pub fn last_solve(&self) -> Option<&SolveRecord> {
        self.last.as_ref()
    }

    /// Solve `target` with `solver` (a numerical one) from `seed`, then from random
    /// configurations within the settings' attempts and time budget; remembered as the
    /// last solve.
    pub fn solve(
        &mut self,
        solver: Solver,
        target: &Target,
        seed: &[f64],
    ) -> Result<IkSolution, KinematicsError> {
        let (result, record) = self.solve_timed(solver, target, seed);
        if record.is_some() {
            self.last = record;
        }
        result
    }

    /// As [`NumericIk::solve`], not remembered (the samples of a straight line).
    pub fn solve_unrecorded(
        &mut self,
        solver: Solver,
        target: &Target,
        seed: &[f64],
    ) -> Result<IkSolution, KinematicsError> {
        self.solve_timed(solver, target, seed).0
    }

    /// Put back what [`NumericIk::last_solve`] said before.
    pub fn restore_last_solve(&mut self, record: Option<SolveRecord>) {
        self.last = record;
    }

    fn solve_timed(
        &mut self,
        solver: Solver,
        target: &Target,
        seed: &[f64],
    ) -> (Result<IkSolution, KinematicsError>, Option<SolveRecord>) {
        let algorithm = solver
            .algorithm()
            .unwrap_or(IkAlgorithm::DampedLeastSquares);
        let mut s = IkSolver::new(algorithm);
        s.options.position_tolerance_m = self.settings.position_tolerance_m;
        s.options.orientation_tolerance_rad = self.settings.orientation_tolerance_rad;
        s.options.max_attempts = self.settings.max_attempts;
        s.options.time_budget = Some(self.settings.time_budget);
        let started = Instant::now();
        let mut clock = started;
        let result = s.solve_with_budget(&self.chain, target, seed, &mut self.rng, &mut clock);
        let micros = started.elapsed().as_secs_f64() * 1e6;
        let record = match &result {
            Ok(sol) => Some(SolveRecord {
                solver,
                converged: true,
                iterations: sol.report.iterations,
                attempts: sol.report.attempts,
                position_error_m: sol.report.position_error_m,
                orientation_error_rad: sol.report.orientation_error_rad,
                micros,
            }),
            Err(KinematicsError::IkNotConverged {
                position_error_m,
                orientation_error_rad,
                iterations,
                attempts,
            }) => Some(SolveRecord {
                solver,
                converged: false,
                iterations: *iterations,
                attempts: *attempts,
                position_error_m: *position_error_m,
                orientation_error_rad: *orientation_error_rad,
                micros,
            }),
            Err(_) => None,
        };
        (result, record)
    }

    /// The reachable point nearest to `target` (m), searched from `seed` and random
    /// configurations within the settings' budget.
    pub fn nearest(
        &mut self,
        target: &Vector3<f64>,
        seed: &[f64],
    ) -> Result<NearestReachable, KinematicsError> {
        let mut s = IkSolver::default();
        s.options.max_attempts = self.settings.nearest_attempts;
        s.options.time_budget = Some(self.settings.nearest_budget);
        let mut clock = Instant::now();
        nearest_reachable(&self.chain, target, seed, &s, &mut self.rng, &mut clock)
    }

    /// Everything undesirable about configuration `x`, as `diagnostics` key/values:
    /// `undesirable` (a summary, `none` when all is well) and one `undesirable:<what>`
    /// per concern, with the way out in joint space and as the tool's motion.
    pub fn assess_values(&self, x: &[f64]) -> Vec<(String, String)> {
        let checks: Vec<&dyn ConfigurationCheck> = self
            .gripper_up
            .iter()
            .map(|c| c as &dyn ConfigurationCheck)
            .collect();
        match assess(&self.chain, x, &self.assess_options, &checks) {
            Ok(found) => describe_undesirable(&self.chain, x, &found),
            Err(e) => vec![("undesirable".into(), format!("not assessed: {e}"))],
        }
    }
}

/// The key of a concern: `near_singular`, `at_limit:<joint or constraint>:<lower|upper>`
/// or the check's name (`gripper_up`).
pub fn concern_key(chain: &SerialChain, u: &Undesirable) -> String {
    match &u.concern {
        Concern::NearSingular { .. } => "near_singular".into(),
        Concern::AtLimit(p) => format!(
            "at_limit:{}:{}",
            chain.limit_name(p.limit),
            match p.bound {
                Bound::Lower => "lower",
                Bound::Upper => "upper",
            }
        ),
        Concern::Check { name, .. } => name.clone(),
    }
}

/// `diagnostics` key/values for the concerns `found` at `x` (see
/// [`NumericIk::assess_values`]).
pub fn describe_undesirable(
    chain: &SerialChain,
    x: &[f64],
    found: &[Undesirable],
) -> Vec<(String, String)> {
    if found.is_empty() {
        return vec![("undesirable".into(), "none".into())];
    }
    let keys: Vec<String> = found.iter().map(|u| concern_key(chain, u)).collect();
    let mut out = vec![("undesirable".into(), keys.join(", "))];
    let jac = chain.jacobian(x).ok();
    for (key, u) in keys.into_iter().zip(found) {
        let mut text = match &u.concern {
            Concern::NearSingular {
                manipulability,
                min_singular_value,
            } => format!(
                "near a singularity: smallest singular value {min_singular_value:.2e}, manipulability {manipulability:.2e}"
            ),
            Concern::AtLimit(p) => {
                if p.distance < 0.0 {
                    format!(
                        "{:.2e} beyond its {} limit",
                        -p.distance,
                        if p.bound == Bound::Lower { "lower" } else { "upper" }
                    )
                } else {
                    format!(
                        "{:.2e} from its {} limit",
                        p.distance,
                        if p.bound == Bound::Lower { "lower" } else { "upper" }
                    )
                }
            }
            Concern::Check { name, cost } if name == "gripper_up" => {
                format!("the gripper faces upwards (cost {cost:.3}) instead of out in front")
            }
            Concern::Check { name, cost } => format!("{name} (cost {cost:.3})"),
        };
        let _ = write!(text, "; away: {}", joint_direction(chain, &u.direction));
        if let Some((_, j)) = &jac {
            let d = nalgebra::DVector::from_column_slice(&u.direction);
            let twist = j * d;
            let v = Vector3::new(twist[0], twist[1], twist[2]);
            if v.norm() > 1e-9 {
                let v = v.normalize();
                let _ = write!(
                    text,
                    ", tool toward ({:+.2}, {:+.2}, {:+.2})",
                    v.x, v.y, v.z
                );
            }
        }
        out.push((format!("undesirable:{key}"), text));
    }
    out
}

/// `base_joint +0.71, elbow_joint -0.70` (components below 0.005 left out).
pub fn joint_direction(chain: &SerialChain, d: &[f64]) -> String {
    let parts: Vec<String> = chain
        .variables()
        .iter()
        .zip(d)
        .filter(|(_, v)| v.abs() >= 0.005)
        .map(|(var, v)| format!("{} {v:+.2}", var.name))
        .collect();
    if parts.is_empty() {
        "no direction known".into()
    } else {
        parts.join(", ")
    }
}

/// Roll, pitch, yaw (deg) of a pose's rotation, and its position: `x y z m, rpy r p y deg`.
pub fn describe_pose(p: &Isometry3<f64>) -> String {
    let t = p.translation.vector;
    let (r, pi, y) = p.rotation.euler_angles();
    format!(
        "{:.4} {:.4} {:.4} m, rpy {:.2} {:.2} {:.2} deg",
        t.x,
        t.y,
        t.z,
        r.to_degrees(),
        pi.to_degrees(),
        y.to_degrees()
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_kinematics::urdf::RobotModel;

    fn jaco() -> SerialChain {
        let model = RobotModel::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../urdf/jaco.urdf"
        )))
        .unwrap();
        SerialChain::from_model(&model, "base_link", "jaco_end_effector").unwrap()
    }

    #[test]
    fn unknown_solver_is_refused_with_the_valid_ones() {
        let e = Solver::check("lm").unwrap_err();
        assert!(
            e.contains("`lm`") && e.contains("analytic, jacobian, dls, newton"),
            "{e}"
        );
        for n in Solver::NAMES {
            assert_eq!(Solver::check(n).unwrap().name(), n);
        }
    }

    #[test]
    fn upright_jaco_is_near_singular_with_a_way_out_in_words() {
        let pi = std::f64::consts::PI;
        let n = NumericIk::new(jaco(), true);
        let v = n.assess_values(&[pi, pi / 2.0, -pi / 2.0, 0.0, -pi, pi]);
        let summary = &v[0].1;
        assert!(summary.contains("near_singular"), "{v:?}");
        let detail = &v
            .iter()
            .find(|(k, _)| k == "undesirable:near_singular")
            .unwrap()
            .1;
        assert!(detail.contains("away: jaco_joint_"), "{detail}");
    }

    #[test]
    fn a_failed_solve_is_recorded_with_its_residual() {
        let mut n = NumericIk::new(jaco(), true);
        let far = Target::position(Vector3::new(5.0, 0.0, 0.0));
        let seed = [0.0, 1.5, -1.5, 0.0, 0.0, 0.0];
        assert!(n.solve(Solver::Dls, &far, &seed).is_err());
        let r = n.last_solve().unwrap();
        assert!(!r.converged && r.position_error_m > 3.0, "{r:?}");
        assert!(r.describe().starts_with("dls: not converged"));
    }
}
