//! compute_ik for an arm known only by its URDF (`-p urdf:=… -p tip_link:=…`), e.g.
//! the 6-DOF Kinova Jaco of `urdf/jaco.urdf`: the serial chain between two links,
//! solved by the numerical solvers, moved within the URDF's velocity limits. No servo
//! mapping: such an arm publishes `joint_states` (every non-fixed joint) and no
//! `servo_angles`. [`UrdfModel`] is the [`ArmModel`]; [`UrdfCore`] the target pipeline
//! driving it.

use crate::core::Reason;
use crate::numeric::{describe_pose, NumericIk, Solver};
use crate::pipeline::{joint_state, ArmModel, Cartesian, Pipeline, Solved};
use eezybot_kinematics::chain::SerialChain;
use eezybot_kinematics::ik::Target;
use eezybot_kinematics::urdf::{JointKind, RobotModel};
use eezybot_kinematics::KinematicsError;
use eezybot_motion::AxisLimits;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use ros_plumbing::Params;
use std::f64::consts::PI;

/// Velocity limit (rad/s or m/s) of a joint whose URDF gives none (or zero).
pub const DEFAULT_VELOCITY: f64 = 1.0;

/// A joint reaches its URDF velocity limit in this time: the acceleration limit is
/// the velocity limit divided by it (the servos' default ramp, `config/arm.yaml`).
pub const ACCELERATION_TIME_S: f64 = 0.25;

/// Arms with at least this many joints follow a `pose_target`'s orientation exactly;
/// fewer pursue it as far as the position leaves freedom.
const FULL_POSE_DOF: usize = 6;

/// One joint whose position compute_ik sets (movable, not a mimic).
#[derive(Clone, Debug, PartialEq)]
pub struct ArmJoint {
    /// URDF name.
    pub name: String,
    /// Lower limit (−∞ for a continuous joint).
    pub lower: f64,
    /// Upper limit (+∞ for a continuous joint).
    pub upper: f64,
    /// Rotates without end (URDF `continuous`).
    pub continuous: bool,
    /// Revolute or continuous (else prismatic).
    pub revolute: bool,
    /// Velocity limit (URDF `<limit velocity>`, else [`DEFAULT_VELOCITY`]).
    pub velocity: f64,
    /// Its index among the chain's variables, if the chain moves it.
    pub variable: Option<usize>,
}

/// The arm: URDF, chain and the joints compute_ik sets.
#[derive(Clone, Debug)]
pub struct UrdfArm {
    model: RobotModel,
    chain: SerialChain,
    joints: Vec<ArmJoint>,
}

impl UrdfArm {
    /// The arm of `model` between link `base` (empty: the URDF's root) and link `tip`
    /// (empty: the URDF's only leaf link). Errors name the problem.
    ///
    /// # Examples
    /// ```
    /// use compute_ik::urdf_arm::UrdfArm;
    /// use eezybot_kinematics::urdf::RobotModel;
    /// let model = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/jaco.urdf"))).unwrap();
    /// let arm = UrdfArm::new(model, "", "").unwrap();
    /// assert_eq!(arm.chain().tip_link(), "jaco_end_effector");
    /// assert_eq!(arm.joints().len(), 6);
    /// ```
    pub fn new(model: RobotModel, base: &str, tip: &str) -> Result<UrdfArm, String> {
        let base = if base.is_empty() {
            model.root.clone()
        } else {
            base.to_string()
        };
        let tip = if tip.is_empty() {
            match model.leaf_links().as_slice() {
                [one] => one.to_string(),
                many => {
                    return Err(format!(
                        "the URDF has {} leaf links ({}): say which is the tool with tip_link",
                        many.len(),
                        many.join(", ")
                    ))
                }
            }
        } else {
            tip.to_string()
        };
        let chain = SerialChain::from_model(&model, &base, &tip).map_err(|e| e.to_string())?;
        if chain.dof() == 0 {
            return Err(format!("no joint moves `{tip}` relative to `{base}`"));
        }
        let joints = model
            .independent_joints()
            .map(|j| {
                let (lower, upper, continuous, revolute) = match &j.kind {
                    JointKind::Revolute { limits, .. } => (limits.0, limits.1, false, true),
                    JointKind::Prismatic { limits, .. } => (limits.0, limits.1, false, false),
                    _ => (f64::NEG_INFINITY, f64::INFINITY, true, true),
                };
                let variable = chain.variable_index(&j.name);
                let (lower, upper) = match variable {
                    Some(i) => (chain.variables()[i].lower, chain.variables()[i].upper),
                    None => (lower, upper),
                };
                ArmJoint {
                    name: j.name.clone(),
                    lower,
                    upper,
                    continuous,
                    revolute,
                    velocity: model.velocity_limit(&j.name).unwrap_or(DEFAULT_VELOCITY),
                    variable,
                }
            })
            .collect();
        Ok(UrdfArm {
            model,
            chain,
            joints,
        })
    }

    /// The chain base → tip.
    pub fn chain(&self) -> &SerialChain {
        &self.chain
    }

    /// The URDF.
    pub fn model(&self) -> &RobotModel {
        &self.model
    }

    /// The joints compute_ik sets, in URDF order (the planner's axes and the names
    /// `joint_target` accepts).
    pub fn joints(&self) -> &[ArmJoint] {
        &self.joints
    }

    /// The chain variables within a vector of [`UrdfArm::joints`] positions.
    fn variables_of(&self, q: &[f64]) -> Vec<f64> {
        let mut x = vec![0.0; self.chain.dof()];
        for (j, v) in self.joints.iter().zip(q) {
            if let Some(i) = j.variable {
                x[i] = *v;
            }
        }
        x
    }

    /// `q` with the chain variables replaced by `x`.
    fn with_variables(&self, q: &[f64], x: &[f64]) -> Vec<f64> {
        self.joints
            .iter()
            .zip(q)
            .map(|(j, v)| j.variable.map_or(*v, |i| x[i]))
            .collect()
    }

    /// A start pose: every joint at 0, or the middle of its limits when 0 is outside
    /// them, then moved into the chain's coupling constraints.
    fn start_pose(&self) -> Vec<f64> {
        let q: Vec<f64> = self
            .joints
            .iter()
            .map(|j| {
                if (j.lower..=j.upper).contains(&0.0) {
                    0.0
                } else {
                    (j.lower + j.upper) / 2.0
                }
            })
            .collect();
        let mut x = self.variables_of(&q);
        self.chain.project(&mut x);
        self.with_variables(&q, &x)
    }

    /// Every non-fixed joint of the URDF (mimic joints following their leaders).
    fn joint_positions(&self, q: &[f64]) -> Vec<(String, f64)> {
        let of = |name: &str| {
            self.joints
                .iter()
                .position(|j| j.name == name)
                .map_or(0.0, |i| q[i])
        };
        self.model
            .joints
            .iter()
            .filter(|j| j.is_movable())
            .map(|j| {
                let v = match &j.mimic {
                    Some(m) => m.multiplier * of(&self.model.joints[m.leader].name) + m.offset,
                    None => of(&j.name),
                };
                (j.name.clone(), v)
            })
            .collect()
    }

    fn axis_limits(&self) -> Vec<AxisLimits> {
        self.joints
            .iter()
            .map(|j| AxisLimits {
                max_velocity: j.velocity,
                max_acceleration: j.velocity / ACCELERATION_TIME_S,
            })
            .collect()
    }
}

/// The target pipeline driving a [`UrdfArm`].
pub type UrdfCore = Pipeline<UrdfModel>;

/// A [`UrdfArm`] and its numerical solvers, as an [`ArmModel`].
#[derive(Clone, Debug)]
pub struct UrdfModel {
    arm: UrdfArm,
    numeric: NumericIk,
}

impl Pipeline<UrdfModel> {
    /// At rest in the arm's start pose (every joint at 0, or mid-range), with the
    /// `solver` parameter's default, `analytic`, which for an arm without a closed form
    /// is DLS.
    pub fn new(arm: UrdfArm, base_frame: &str) -> Result<UrdfCore, String> {
        let pose_rows = arm.chain.dof() >= FULL_POSE_DOF;
        let numeric = NumericIk::new(arm.chain.clone(), pose_rows);
        Pipeline::for_arm(UrdfModel { arm, numeric }, base_frame)
            .map_err(|e| format!("the URDF's velocity limits: {e}"))
    }

    /// The arm.
    pub fn arm(&self) -> &UrdfArm {
        &self.model().arm
    }

    /// The seed report's "gripper facing up" check (tip z axis within this angle of
    /// +z, deg; `None` or 0: off).
    pub fn set_gripper_up(&mut self, min_angle_deg: Option<f64>) {
        self.model_mut().numeric.set_gripper_up(min_angle_deg);
    }
}

impl UrdfModel {
    /// The numerical method used for `solver`: `analytic` (there is no closed form for
    /// a URDF arm) means DLS.
    fn effective(solver: Solver) -> Solver {
        match solver {
            Solver::Analytic => Solver::Dls,
            s => s,
        }
    }

    /// The tip's pose for joint positions `q`.
    fn tip(&self, q: &[f64]) -> Isometry3<f64> {
        self.arm
            .chain
            .forward(&self.arm.variables_of(q))
            .unwrap_or_else(|_| Isometry3::identity())
    }

    /// Continuous joints turned by whole turns to the nearest of `x`'s equivalents to
    /// `near` (the shortest way round).
    fn unwrap_continuous(&self, x: &[f64], near: &[f64]) -> Vec<f64> {
        x.iter()
            .enumerate()
            .map(|(i, v)| {
                if self.arm.chain.variables()[i].continuous {
                    near[i] + (v - near[i] + PI).rem_euclid(2.0 * PI) - PI
                } else {
                    *v
                }
            })
            .collect()
    }

    /// Solve `target` from `goal`: the joints of every joint, continuous ones the
    /// shortest way round.
    fn solve_target(
        &mut self,
        solver: Solver,
        target: Target,
        goal: &[f64],
    ) -> Result<Solved<Vec<f64>>, Reason> {
        let solver = Self::effective(solver);
        let seed = self.arm.variables_of(goal);
        let sol = self
            .numeric
            .solve(solver, &target, &seed)
            .map_err(|error| Reason::Numeric {
                solver,
                error,
                orientation: target.orientation_required,
            })?;
        let x = self.unwrap_continuous(&sol.joints, &seed);
        Ok(Solved {
            state: self.arm.with_variables(goal, &x),
            target,
        })
    }
}

impl ArmModel for UrdfModel {
    type State = Vec<f64>;

    fn describe(&self) -> String {
        let chain = &self.arm.chain;
        format!(
            "URDF arm `{}`: {} -> {}, {} joints ({}); no servo_angles",
            self.arm.model.name,
            chain.base_link(),
            chain.tip_link(),
            chain.dof(),
            chain
                .variables()
                .iter()
                .map(|v| v.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )
    }

    fn has_servos(&self) -> bool {
        false
    }

    fn start(&self) -> Vec<f64> {
        self.arm.start_pose()
    }

    fn axes(&self, s: &Vec<f64>) -> Vec<f64> {
        s.clone()
    }

    fn planned(&self, axes: &[f64]) -> Vec<f64> {
        let mut x = self.arm.variables_of(axes);
        if self.arm.chain.within_limits(&x, 0.0) {
            return axes.to_vec();
        }
        self.arm.chain.project(&mut x);
        log::debug!("a planned step moved into the joint limits");
        self.arm.with_variables(axes, &x)
    }

    fn axis_limits(&self) -> Vec<AxisLimits> {
        self.arm.axis_limits()
    }

    /// The seed report's "gripper facing up" check (tip z axis within
    /// `gripper_up_angle` of +z, deg; 0: off).
    fn apply_params(&mut self, params: &Params) -> bool {
        self.numeric.set_gripper_up(params.f64("gripper_up_angle"));
        false
    }

    /// An `xyz_target`: the tip to this position. An arm of six joints or more keeps
    /// its tool's orientation when it can (solved as a pose with the current
    /// orientation); otherwise, and with four or five joints, the orientation is kept as
    /// well as the position allows (pursued in the null space of the position task). A
    /// `pose_target`: with six joints or more, position and orientation are both
    /// reached (or the target is refused with the residuals); with fewer, the position
    /// is reached and the orientation pursued as far as the position leaves freedom.
    fn solve(
        &mut self,
        solver: Solver,
        target: &Cartesian,
        goal: &Vec<f64>,
    ) -> Result<Solved<Vec<f64>>, Reason> {
        let full = self.arm.chain.dof() >= FULL_POSE_DOF;
        let Some(r) = target.orientation else {
            let keep =
                Isometry3::from_parts(Translation3::from(target.position), self.tip(goal).rotation);
            if full {
                // the orientation kept exactly where the arm can, else as well as it can
                if let Ok(exact) = self.solve_target(solver, Target::pose(keep), goal) {
                    return Ok(exact);
                }
            }
            let t = if self.arm.chain.dof() > 3 {
                Target::pose_preferred(keep, 1.0)
            } else {
                Target::position(target.position)
            };
            return self.solve_target(solver, t, goal);
        };
        let pose = Isometry3::from_parts(Translation3::from(target.position), r);
        let t = if full {
            Target::pose(pose)
        } else {
            Target::pose_preferred(pose, 1.0)
        };
        self.solve_target(solver, t, goal)
    }

    /// Position targets only (the orientation kept as in [`ArmModel::solve`]).
    fn nearest(&mut self, target: &Cartesian, goal: &Vec<f64>) -> Option<(Solved<Vec<f64>>, f64)> {
        if target.orientation.is_some() {
            return None;
        }
        let seed = self.arm.variables_of(goal);
        let near = self.numeric.nearest(&target.position, &seed).ok()?;
        let x = self.unwrap_continuous(&near.joints, &seed);
        let keep =
            Isometry3::from_parts(Translation3::from(near.position), self.tip(goal).rotation);
        let t = if self.arm.chain.dof() > 3 {
            Target::pose_preferred(keep, 1.0)
        } else {
            Target::position(near.position)
        };
        let state = self.arm.with_variables(goal, &x);
        Some((Solved { state, target: t }, near.distance_m))
    }

    /// Every named joint within its limits and the chain's constraints.
    fn joint_goal(
        &self,
        names: &[String],
        positions: &[f64],
        goal: &Vec<f64>,
    ) -> Result<Vec<f64>, Reason> {
        let mut goal = goal.clone();
        for (index, (name, &value)) in names.iter().zip(positions).enumerate() {
            let Some(i) = self.arm.joints.iter().position(|j| &j.name == name) else {
                return Err(Reason::UnknownArmJoint {
                    name: name.clone(),
                    known: self.arm.joints.iter().map(|j| j.name.clone()).collect(),
                });
            };
            let j = &self.arm.joints[i];
            if !value.is_finite() {
                return Err(KinematicsError::NonFiniteValue {
                    what: "joint_target",
                    index,
                    value,
                }
                .into());
            }
            if value < j.lower || value > j.upper {
                return Err(Reason::JointLimit {
                    name: name.clone(),
                    value,
                    lower: j.lower,
                    upper: j.upper,
                    revolute: j.revolute,
                });
            }
            goal[i] = value;
        }
        let x = self.arm.variables_of(&goal);
        for c in self.arm.chain.constraints() {
            let v = c.value(&x);
            if v < c.lower || v > c.upper {
                return Err(Reason::JointLimit {
                    name: c.name.clone(),
                    value: v,
                    lower: c.lower,
                    upper: c.upper,
                    revolute: true,
                });
            }
        }
        Ok(goal)
    }

    /// This arm has no EezyBot claw.
    fn gripper_goal(&self, _opening: f64, _goal: &Vec<f64>) -> Result<Vec<f64>, Reason> {
        Err(Reason::NoGripper)
    }

    fn check_goal(&self, _goal: &Vec<f64>) -> Result<(), Reason> {
        Ok(())
    }

    fn tool_pose(&self, s: &Vec<f64>) -> Isometry3<f64> {
        self.tip(s)
    }

    fn pose_note(&self, goal: &Vec<f64>, asked: &UnitQuaternion<f64>) -> (f64, String) {
        let taken = self.tip(goal);
        let off_deg = taken.rotation.angle_to(asked).to_degrees();
        let text = format!(
            "orientation {off_deg:.2e}° from the one asked ({}); tip at {}",
            if self.arm.chain.dof() >= FULL_POSE_DOF {
                "position and orientation required"
            } else {
                "position first, orientation as far as the position allows"
            },
            describe_pose(&taken)
        );
        (off_deg, text)
    }

    fn line_joints(&self, s: &Vec<f64>) -> Vec<f64> {
        self.arm.variables_of(s)
    }

    /// Every point solved, the end too (the line's own branch of the solutions).
    fn line_point(
        &mut self,
        solver: Solver,
        target: &Target,
        seed: &[f64],
        _end: Option<&Vec<f64>>,
    ) -> Result<Vec<f64>, Reason> {
        let solver = Self::effective(solver);
        let sol = self
            .numeric
            .solve_unrecorded(solver, target, seed)
            .map_err(|error| Reason::Numeric {
                solver,
                error,
                orientation: target.orientation_required,
            })?;
        Ok(self.unwrap_continuous(&sol.joints, seed))
    }

    fn line_axes(
        &self,
        joints: &[f64],
        goal: &Vec<f64>,
        _stop: &[f64],
        _fraction: f64,
    ) -> Vec<f64> {
        self.arm.with_variables(goal, joints)
    }

    fn line_goal(&self, _goal: Vec<f64>, end: &[f64]) -> Vec<f64> {
        end.to_vec()
    }

    fn joint_states(&self, s: &Vec<f64>, stamp: Time) -> JointState {
        let joints = self.arm.joint_positions(s);
        joint_state(stamp, joints.iter().map(|(n, v)| (n.as_str(), *v)))
    }

    fn servo_angles(&self, _s: &Vec<f64>, _stamp: Time) -> Option<JointState> {
        None
    }

    fn hardware_id(&self) -> String {
        self.arm.model.name.clone()
    }

    /// The tip's pose and every joint.
    fn state_values(&self, s: &Vec<f64>) -> Vec<(String, String)> {
        let chain = &self.arm.chain;
        vec![
            ("robot".into(), self.arm.model.name.clone()),
            (
                "chain".into(),
                format!(
                    "{} -> {}, {} joints",
                    chain.base_link(),
                    chain.tip_link(),
                    chain.dof()
                ),
            ),
            ("tip_pose".into(), describe_pose(&self.tip(s))),
            (
                "joints".into(),
                self.arm
                    .joints
                    .iter()
                    .zip(s)
                    .map(|(j, v)| {
                        if j.revolute {
                            format!("{} {:.2}°", j.name, v.to_degrees())
                        } else {
                            format!("{} {v:.4} m", j.name)
                        }
                    })
                    .collect::<Vec<_>>()
                    .join(", "),
            ),
        ]
    }

    fn solver_text(&self, solver: Solver) -> String {
        match solver {
            Solver::Analytic => "dls (analytic asked: this arm has no closed form)".into(),
            s => s.name().to_string(),
        }
    }

    fn numeric(&self) -> Option<&NumericIk> {
        Some(&self.numeric)
    }

    fn numeric_mut(&mut self) -> Option<&mut NumericIk> {
        Some(&mut self.numeric)
    }

    fn chain_variables(&self, s: &Vec<f64>) -> Vec<f64> {
        self.arm.variables_of(s)
    }
}
