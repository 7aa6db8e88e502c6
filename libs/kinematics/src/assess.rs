//! Undesirable configurations (near a singularity, at a limit, or whatever a user check
//! says, e.g. "the gripper points up") with a joint-space direction away from each, and
//! the nearest reachable point to an unreachable position target.
//!
//! # Examples
//! ```
//! use eezybot_kinematics::{Arm, assess::{assess, AssessOptions, Concern}, urdf::RobotModel};
//! let model = RobotModel::load(std::path::Path::new(concat!(
//!     env!("CARGO_MANIFEST_DIR"), "/../../urdf/eezybot.urdf"))).unwrap();
//! let chain = Arm::default().serial_chain(&model).unwrap();
//! // shoulder at its upper limit (125°)
//! let x = [0.0, 125f64.to_radians(), -100f64.to_radians()];
//! let found = assess(&chain, &x, &AssessOptions::position(), &[]).unwrap();
//! let limit = found.iter().find(|u| matches!(u.concern, Concern::AtLimit(_))).unwrap();
//! assert!(limit.direction[1] < 0.0); // away from the limit: lower the shoulder
//! ```

use crate::chain::{LimitProximity, SerialChain};
use crate::ik::{singular_values_of_rows, IkAlgorithm, IkSolver, Stopwatch, Target, Workspace};
use crate::rng::SplitMix64;
use crate::KinematicsError;
use nalgebra::{Isometry3, Matrix6xX, Unit, Vector3};

/// A user check of a configuration: a cost that is 0 when the configuration is fine and
/// grows the worse it gets. Its negative gradient (by central differences) is the
/// suggested direction.
pub trait ConfigurationCheck {
    /// A short name for reports, e.g. `gripper_up`.
    fn name(&self) -> &str;
    /// The cost of a configuration (`tip` is its FK).
    fn cost(&self, tip: &Isometry3<f64>, joints: &[f64]) -> f64;
}

/// "A tool axis points too close to a forbidden direction": cost
/// `max(0, cos(angle between them) − cos(min_angle))`. The seed report's undesirable
/// configuration, the gripper facing upwards instead of forwards, is
/// `ToolAxisAway { axis: z, forbidden: +z of the base, min_angle_rad: 60° }` for a tool
/// whose approach axis is z.
#[derive(Clone, Debug, PartialEq)]
pub struct ToolAxisAway {
    /// Name in reports.
    pub name: String,
    /// The axis in the tip frame.
    pub axis: Unit<Vector3<f64>>,
    /// The direction it should stay away from, in the base frame.
    pub forbidden: Unit<Vector3<f64>>,
    /// Smallest acceptable angle between them (rad).
    pub min_angle_rad: f64,
}

impl ConfigurationCheck for ToolAxisAway {
    fn name(&self) -> &str {
        &self.name
    }

    fn cost(&self, tip: &Isometry3<f64>, _joints: &[f64]) -> f64 {
        let cos = (tip.rotation * self.axis.into_inner()).dot(&self.forbidden);
        (cos - self.min_angle_rad.cos()).max(0.0)
    }
}

/// What is undesirable.
#[derive(Clone, Debug, PartialEq)]
pub enum Concern {
    /// Close to a singularity of the task Jacobian.
    NearSingular {
        /// Product of its singular values.
        manipulability: f64,
        /// Its smallest singular value.
        min_singular_value: f64,
    },
    /// At (or beyond, or within the margin of) a joint limit or coupling constraint.
    AtLimit(LimitProximity),
    /// A [`ConfigurationCheck`] reports a positive cost.
    Check {
        /// Its name.
        name: String,
        /// Its cost.
        cost: f64,
    },
}

/// An undesirable aspect of a configuration and a way out.
#[derive(Clone, Debug, PartialEq)]
pub struct Undesirable {
    /// What is wrong.
    pub concern: Concern,
    /// Unit direction in variable space that improves it (zeros when none is known):
    /// the gradient of manipulability, away from the limit, or down the check's cost.
    pub direction: Vec<f64>,
}

/// Thresholds of [`assess`].
#[derive(Clone, Debug, PartialEq)]
pub struct AssessOptions {
    /// Task rows for the singularity test: x, y, z position, rotation about x, y, z.
    pub rows: [bool; 6],
    /// Near singular below this smallest singular value (m/rad, rad/rad).
    pub singular_threshold: f64,
    /// At a limit within this distance (rad or m).
    pub limit_margin: f64,
    /// Step of the central differences (rad or m).
    pub step: f64,
    /// Probe step where manipulability is flat (at a singularity of rank deficiency two
    /// or more, where its gradient vanishes): the direction then combines the one-sided
    /// probes `±escape_step` along each variable that raise the small singular values.
    pub escape_step: f64,
}

impl AssessOptions {
    /// Position rows only (a 3-DOF arm such as the EezyBot): near singular below
    /// 0.01 m/rad, at a limit within 2°.
    pub fn position() -> Self {
        AssessOptions {
            rows: [true, true, true, false, false, false],
            singular_threshold: 1e-2,
            limit_margin: 2f64.to_radians(),
            step: 1e-6,
            escape_step: 0.05,
        }
    }

    /// All six rows (a 6-DOF arm).
    pub fn pose() -> Self {
        AssessOptions {
            rows: [true; 6],
            ..AssessOptions::position()
        }
    }
}

fn manipulability(
    chain: &SerialChain,
    x: &[f64],
    rows: &[bool; 6],
    jac: &mut Matrix6xX<f64>,
) -> (f64, f64) {
    chain.forward_jacobian_into(x, jac);
    singular_values_of_rows(jac, rows)
}

/// Σ min(σᵢ, threshold) over the singular values of the active rows.
fn small_singular_values(jac: &Matrix6xX<f64>, rows: &[bool; 6], threshold: f64) -> f64 {
    let active: Vec<usize> = (0..6).filter(|r| rows[*r]).collect();
    let a = nalgebra::DMatrix::from_fn(active.len(), jac.ncols(), |r, c| jac[(active[r], c)]);
    a.singular_values().iter().map(|s| s.min(threshold)).sum()
}

fn unit(mut v: Vec<f64>) -> Vec<f64> {
    let n = v.iter().map(|a| a * a).sum::<f64>().sqrt();
    if n > 0.0 && n.is_finite() {
        v.iter_mut().for_each(|a| *a /= n);
    } else {
        v.iter_mut().for_each(|a| *a = 0.0);
    }
    v
}

/// Central-difference gradient of `f` at `x`.
fn gradient(x: &[f64], h: f64, mut f: impl FnMut(&[f64]) -> f64) -> Vec<f64> {
    let mut probe = x.to_vec();
    (0..x.len())
        .map(|i| {
            probe[i] = x[i] + h;
            let up = f(&probe);
            probe[i] = x[i] - h;
            let down = f(&probe);
            probe[i] = x[i];
            (up - down) / (2.0 * h)
        })
        .collect()
}

/// Everything undesirable about configuration `x`, each with a direction away from it:
/// near a singularity (smallest singular value of the task Jacobian below the threshold;
/// direction: the gradient of manipulability), near or at a limit (direction: the limit's
/// inward normal) and every user check with a positive cost (direction: down its
/// gradient).
pub fn assess(
    chain: &SerialChain,
    x: &[f64],
    options: &AssessOptions,
    checks: &[&dyn ConfigurationCheck],
) -> Result<Vec<Undesirable>, KinematicsError> {
    chain.check(x)?;
    let mut out = Vec::new();
    let mut jac = Matrix6xX::zeros(chain.dof());
    let (m, smin) = manipulability(chain, x, &options.rows, &mut jac);
    if smin < options.singular_threshold {
        let mut g = unit(gradient(x, options.step, |p| {
            manipulability(chain, p, &options.rows, &mut jac).0
        }));
        let along: Vec<f64> = x
            .iter()
            .zip(&g)
            .map(|(a, d)| a + options.escape_step * d)
            .collect();
        if manipulability(chain, &along, &options.rows, &mut jac).0 <= m {
            // Flat (a rank deficiency of two or more): raise the small singular values
            // one variable at a time, one-sided, and combine the probes that help.
            let small = |p: &[f64], jac: &mut Matrix6xX<f64>| {
                chain.forward_jacobian_into(p, jac);
                small_singular_values(jac, &options.rows, options.singular_threshold)
            };
            let base = small(x, &mut jac);
            let mut probe = x.to_vec();
            g = (0..x.len())
                .map(|i| {
                    let mut side = |h: f64| {
                        probe[i] = x[i] + h;
                        let v = small(&probe, &mut jac) - base;
                        probe[i] = x[i];
                        v
                    };
                    let (up, down) = (side(options.escape_step), side(-options.escape_step));
                    if up >= down {
                        up.max(0.0)
                    } else {
                        -down.max(0.0)
                    }
                })
                .collect();
        }
        out.push(Undesirable {
            concern: Concern::NearSingular {
                manipulability: m,
                min_singular_value: smin,
            },
            direction: unit(g),
        });
    }
    for p in chain.near_limits(x, options.limit_margin) {
        let direction = p.away.clone();
        out.push(Undesirable {
            concern: Concern::AtLimit(p),
            direction,
        });
    }
    for check in checks {
        let cost = check.cost(&chain.forward_unchecked(x), x);
        if cost > 0.0 {
            let g = gradient(x, options.step, |p| {
                check.cost(&chain.forward_unchecked(p), p)
            });
            out.push(Undesirable {
                concern: Concern::Check {
                    name: check.name().to_string(),
                    cost,
                },
                direction: unit(g.into_iter().map(|v| -v).collect()),
            });
        }
    }
    Ok(out)
}

/// The reachable point nearest to a position target.
#[derive(Clone, Debug, PartialEq)]
pub struct NearestReachable {
    /// The point (m, base frame).
    pub position: Vector3<f64>,
    /// Variables that reach it, inside every limit.
    pub joints: Vec<f64>,
    /// Its distance from the target (m).
    pub distance_m: f64,
    /// The target itself is reachable (distance within the position tolerance).
    pub reachable: bool,
}

/// Projects a position target onto the reachable set: minimizes `|p(x) − target|` over
/// configurations inside the limits (projected damped least squares from `seed`, then
/// from random configurations, `solver.options.max_attempts` in all and within its time
/// budget), keeping the best. A local method: with enough restarts the global nearest
/// point is found with high probability, not certainty.
///
/// # Examples
/// ```
/// use eezybot_kinematics::{Arm, assess::nearest_reachable, ik::IkSolver, rng::SplitMix64,
///                          urdf::RobotModel};
/// let model = RobotModel::load(std::path::Path::new(concat!(
///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/eezybot.urdf"))).unwrap();
/// let chain = Arm::default().serial_chain(&model).unwrap();
/// let mut solver = IkSolver::default();
/// solver.options.max_attempts = 8;
/// // 1 m in front: out of reach; the nearest point is at full stretch towards it
/// let near = nearest_reachable(&chain, &[1.0, 0.0, 0.2].into(), &[0.0, 1.6, -1.6], &solver,
///                              &mut SplitMix64::new(1), &mut std::time::Instant::now()).unwrap();
/// assert!(!near.reachable);
/// assert!(near.position.x > 0.27 && near.position.y.abs() < 1e-6);
/// ```
pub fn nearest_reachable(
    chain: &SerialChain,
    target: &Vector3<f64>,
    seed: &[f64],
    solver: &IkSolver,
    rng: &mut SplitMix64,
    clock: &mut dyn Stopwatch,
) -> Result<NearestReachable, KinematicsError> {
    chain.check(seed)?;
    for (index, value) in target.iter().enumerate() {
        if !value.is_finite() {
            return Err(KinematicsError::NonFiniteValue {
                what: "target position",
                index,
                value: *value,
            });
        }
    }
    let mut s = solver.clone();
    s.options.algorithm = IkAlgorithm::DampedLeastSquares;
    // converge onto the boundary, not merely into a slow crawl along it
    s.options.stall_iterations = s.options.stall_iterations.max(30);
    s.options.max_iterations = s.options.max_iterations.max(300);
    let goal = Target::position(*target);
    let mut ws = Workspace::new(chain.dof());
    let mut x = seed.to_vec();
    let mut best: Option<(Vec<f64>, f64)> = None;
    for attempt in 0..s.options.max_attempts.max(1) {
        if attempt > 0 {
            if s.options.time_budget.is_some_and(|b| clock.elapsed() >= b) {
                break;
            }
            x = chain.random_configuration(rng);
        }
        let a = s.attempt(chain, &goal, &mut x, &mut ws);
        if best.as_ref().is_none_or(|(_, d)| a.eval.position_m < *d) {
            best = Some((x.clone(), a.eval.position_m));
        }
        if a.converged {
            break;
        }
    }
    let (joints, _) = best.unwrap_or((x, f64::INFINITY));
    let position = chain.forward_unchecked(&joints).translation.vector;
    let distance_m = (position - target).norm();
    Ok(NearestReachable {
        position,
        joints,
        distance_m,
        reachable: distance_m <= s.options.position_tolerance_m,
    })
}
