//! compute_ik for an arm known only by its URDF (`-p urdf:=… -p tip_link:=…`), e.g.
//! the 6-DOF Kinova Jaco of `urdf/jaco.urdf`: the serial chain between two links,
//! solved by the numerical solvers, moved within the URDF's velocity limits. No servo
//! mapping: such an arm publishes `joint_states` (every non-fixed joint) and no
//! `servo_angles`. Free of ROS I/O, like [`crate::core::IkCore`]; a rejected input never
//! changes the state.

use crate::core::{
    check_age, check_frame, pose_parts, Counters, MotionMode, MotionSettings, Notice, Reason,
    Rejection, Source,
};
use crate::numeric::{describe_pose, NumericIk, Solver};
use eezybot_kinematics::chain::SerialChain;
use eezybot_kinematics::ik::Target;
use eezybot_kinematics::urdf::{JointKind, RobotModel};
use eezybot_kinematics::KinematicsError;
use eezybot_motion::{straight_line, AxisLimits, JointPath, LineError, Planner};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{PointStamped, PoseStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use nalgebra::{Isometry3, Translation3, Vector3};
use ros_plumbing::diagnostics::{stamp_text, LAST_REJECTION_KEY, REJECTED_STAMP_KEY};
use std::f64::consts::PI;

/// Velocity limit (rad/s or m/s) of a joint whose URDF gives none (or zero).
pub const DEFAULT_VELOCITY: f64 = 1.0;

/// A joint reaches its URDF velocity limit in this time: the acceleration limit is
/// the velocity limit divided by it (the servos' default ramp, `config/arm.yaml`).
pub const ACCELERATION_TIME_S: f64 = 0.25;

/// Largest joint change (rad or m) between two samples of a straight line (2 mm apart)
/// before the line counts as passing a singularity.
const LINE_MAX_JOINT_STEP: f64 = 0.1;

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

/// The state of compute_ik driving a [`UrdfArm`].
#[derive(Clone, Debug)]
pub struct UrdfCore {
    arm: UrdfArm,
    numeric: NumericIk,
    solver: Solver,
    base_frame: String,
    /// where the planner is (positions of [`UrdfArm::joints`])
    state: Vec<f64>,
    /// where the current motion ends
    goal: Vec<f64>,
    planner: Planner,
    motion: MotionSettings,
    estop: bool,
    counters: Counters,
    last_rejection: Option<Rejection>,
    last_event_rejected: bool,
    substitute_max_m: Option<f64>,
    substitutions: u64,
    last_substitution: Option<String>,
    last_pose: Option<String>,
    notices: Vec<Notice>,
}

impl UrdfCore {
    /// At rest in the arm's start pose (every joint at 0, or mid-range), with the
    /// `solver` parameter's default, `analytic`, which for an arm without a closed form
    /// is DLS.
    pub fn new(arm: UrdfArm, base_frame: &str) -> Result<UrdfCore, String> {
        let motion = MotionSettings::default();
        let state = arm.start_pose();
        let planner = Planner::new(arm.axis_limits(), &state, motion.period_s)
            .map_err(|e| format!("the URDF's velocity limits: {e}"))?;
        let pose_rows = arm.chain.dof() >= FULL_POSE_DOF;
        Ok(UrdfCore {
            numeric: NumericIk::new(arm.chain.clone(), pose_rows),
            arm,
            solver: Solver::Analytic,
            base_frame: base_frame.to_string(),
            goal: state.clone(),
            state,
            planner,
            motion,
            estop: false,
            counters: Counters::default(),
            last_rejection: None,
            last_event_rejected: false,
            substitute_max_m: None,
            substitutions: 0,
            last_substitution: None,
            last_pose: None,
            notices: Vec::new(),
        })
    }

    /// The arm.
    pub fn arm(&self) -> &UrdfArm {
        &self.arm
    }

    /// Positions of [`UrdfArm::joints`] where the arm is now (commanded).
    pub fn state(&self) -> &[f64] {
        &self.state
    }

    /// The solver; `analytic` (there is no closed form for a URDF arm) means DLS.
    pub fn set_solver(&mut self, solver: Solver) {
        self.solver = solver;
    }

    /// The solver asked for.
    pub fn solver(&self) -> Solver {
        self.solver
    }

    /// The numerical method actually used.
    fn effective_solver(&self) -> Solver {
        match self.solver {
            Solver::Analytic => Solver::Dls,
            s => s,
        }
    }

    /// The seed report's "gripper facing up" check (tip z axis within this angle of
    /// +z, deg; `None` or 0: off).
    pub fn set_gripper_up(&mut self, min_angle_deg: Option<f64>) {
        self.numeric.set_gripper_up(min_angle_deg);
    }

    /// See [`crate::core::IkCore::set_substitution`] (position targets only).
    pub fn set_substitution(&mut self, max_m: Option<f64>) {
        self.substitute_max_m = max_m.filter(|m| *m > 0.0);
    }

    /// See [`crate::core::IkCore::take_notices`].
    pub fn take_notices(&mut self) -> Vec<Notice> {
        std::mem::take(&mut self.notices)
    }

    /// Change how the arm is moved. A new step period applies from the next target.
    pub fn set_motion(&mut self, motion: MotionSettings) {
        if motion.period_s != self.motion.period_s {
            if let Ok(p) = Planner::new(self.arm.axis_limits(), &self.state, motion.period_s) {
                self.planner = p;
                self.goal = self.state.clone();
            }
        }
        self.motion = motion;
    }

    /// How the arm is moved.
    pub fn motion(&self) -> MotionSettings {
        self.motion
    }

    /// Whether the arm is moving toward a goal.
    pub fn is_moving(&self) -> bool {
        self.planner.is_moving()
    }

    /// Change the frame targets must be given in.
    pub fn set_base_frame(&mut self, base_frame: &str) {
        self.base_frame = base_frame.to_string();
    }

    /// Counters so far.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Count targets dropped because newer ones arrived with them.
    pub fn count_superseded(&mut self, n: u64) {
        self.counters.superseded += n;
    }

    /// The most recent rejection, if any.
    pub fn last_rejection(&self) -> Option<&Rejection> {
        self.last_rejection.as_ref()
    }

    /// Engage or release the emergency stop (as [`crate::core::IkCore::set_estop`]).
    pub fn set_estop(&mut self, engaged: bool) {
        if engaged {
            self.planner.stop();
            self.goal = self.state.clone();
        }
        self.estop = engaged;
    }

    /// Is the emergency stop engaged?
    pub fn estop(&self) -> bool {
        self.estop
    }

    /// The tip's pose for joint positions `q`.
    fn tip(&self, q: &[f64]) -> Isometry3<f64> {
        self.arm
            .chain
            .forward(&self.arm.variables_of(q))
            .unwrap_or_else(|_| Isometry3::identity())
    }

    /// Handle an `xyz_target`: the tip to this position. An arm of six joints or more
    /// keeps its tool's orientation when it can (solved as a pose with the current
    /// orientation); otherwise, and with four or five joints, the orientation is kept as
    /// well as the position allows (pursued in the null space of the position task).
    pub fn handle_xyz_target(
        &mut self,
        msg: &PointStamped,
        now: Time,
    ) -> Result<JointState, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            self.check_common(stamp, now, &msg.header.frame_id)?;
            let p = Vector3::new(msg.point.x, msg.point.y, msg.point.z);
            check_finite(&p)?;
            let keep = Isometry3::from_parts(Translation3::from(p), self.tip(&self.goal).rotation);
            let dof = self.arm.chain.dof();
            if dof >= FULL_POSE_DOF {
                // the orientation kept exactly where the arm can, else as well as it can
                let exact = self.move_to(Source::XyzTarget, Target::pose(keep), false);
                if exact.is_ok() {
                    return exact;
                }
            }
            let target = if dof > 3 {
                Target::pose_preferred(keep, 1.0)
            } else {
                Target::position(p)
            };
            self.move_to(Source::XyzTarget, target, true)
        })();
        self.finish(Source::XyzTarget, stamp, now, result)
    }

    /// Handle a `pose_target`: with six joints or more, position and orientation are
    /// both reached (or the target is refused with the residuals); with fewer, the
    /// position is reached and the orientation pursued as far as the position leaves
    /// freedom, the angle left reported in `diagnostics` (`last_pose_target`).
    pub fn handle_pose_target(
        &mut self,
        msg: &PoseStamped,
        now: Time,
    ) -> Result<JointState, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            self.check_common(stamp, now, &msg.header.frame_id)?;
            let (p, r) = pose_parts(&msg.pose)?;
            check_finite(&p)?;
            let pose = Isometry3::from_parts(Translation3::from(p), r);
            let full = self.arm.chain.dof() >= FULL_POSE_DOF;
            let target = if full {
                Target::pose(pose)
            } else {
                Target::pose_preferred(pose, 1.0)
            };
            let goal = self.move_to(Source::PoseTarget, target, false)?;
            let taken = self.tip(&goal);
            let off_deg = taken.rotation.angle_to(&r).to_degrees();
            let text = format!(
                "orientation {off_deg:.2e}° from the one asked ({}); tip at {}",
                if full {
                    "position and orientation required"
                } else {
                    "position first, orientation as far as the position allows"
                },
                describe_pose(&taken)
            );
            if off_deg > 1.0 {
                self.notices.push(Notice {
                    kind: "pose_target/orientation".into(),
                    text: format!("pose_target: {text}"),
                });
            }
            self.last_pose = Some(text);
            Ok(goal)
        })();
        self.finish(Source::PoseTarget, stamp, now, result)
    }

    fn check_common(&self, stamp: Time, now: Time, frame: &str) -> Result<(), Reason> {
        if self.estop {
            return Err(Reason::EmergencyStop);
        }
        check_age(stamp, now, self.motion.max_target_age_s)?;
        check_frame(frame, &self.base_frame)
    }

    /// Solve `target` from the goal, substituting the nearest reachable point for a
    /// position just out of reach when allowed; plan a line in line mode. Returns the
    /// goal (positions of every joint).
    fn move_to(
        &mut self,
        source: Source,
        target: Target,
        may_substitute: bool,
    ) -> Result<Vec<f64>, Reason> {
        let solver = self.effective_solver();
        let seed = self.arm.variables_of(&self.goal);
        let mut substituted = None;
        let x = match self.numeric.solve(solver, &target, &seed) {
            Ok(sol) => sol.joints,
            Err(error) => {
                let reason = Reason::Numeric {
                    solver,
                    error,
                    orientation: target.orientation_required,
                };
                let p = target.pose.translation.vector;
                match self.substitute_max_m {
                    Some(max) if may_substitute && reason.is_out_of_workspace() => {
                        let near = self
                            .numeric
                            .nearest(&p, &seed)
                            .map_err(|_| reason.clone())?;
                        if near.distance_m > max {
                            return Err(reason);
                        }
                        substituted = Some(format!(
                            "{} ({:.4}, {:.4}, {:.4}) m is out of reach ({reason}): moved to the nearest reachable point ({:.4}, {:.4}, {:.4}) m, {:.4} m away",
                            source.topic(),
                            p.x,
                            p.y,
                            p.z,
                            near.position.x,
                            near.position.y,
                            near.position.z,
                            near.distance_m
                        ));
                        near.joints
                    }
                    _ => return Err(reason),
                }
            }
        };
        let x = self.unwrap_continuous(&x, &seed);
        let mut goal = self.arm.with_variables(&self.goal, &x);
        if self.motion.mode == MotionMode::Line {
            let record = self.numeric.last_solve().cloned();
            let planned = self.plan_line(&target, &goal);
            self.numeric.restore_last_solve(record);
            goal = planned?;
        }
        if let Some(text) = substituted {
            self.substitutions += 1;
            self.notices.push(Notice {
                kind: format!("{}/substituted", source.topic()),
                text: text.clone(),
            });
            self.last_substitution = Some(text);
        }
        Ok(goal)
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

    /// The straight line from where the arm stops to the target (the orientation
    /// turned along it, slerp), solved at every sample; the planner follows it. Returns
    /// the goal: where the line ends.
    fn plan_line(&mut self, target: &Target, goal: &[f64]) -> Result<Vec<f64>, Reason> {
        let stop = self.planner.stopping_position();
        let from = self.tip(&stop);
        let to = target.pose;
        let (a, b) = (from.translation.vector, to.translation.vector);
        let length2 = (b - a).norm_squared();
        let solver = self.effective_solver();
        let mut seed = self.arm.variables_of(&stop);
        let keep_orientation = target.orientation_weights.iter().any(|w| *w != 0.0);
        let numeric = &mut self.numeric;
        let chain_continuous: Vec<bool> = self
            .arm
            .chain
            .variables()
            .iter()
            .map(|v| v.continuous)
            .collect();
        let path = straight_line(
            [a.x, a.y, a.z],
            [b.x, b.y, b.z],
            self.motion.line_step_m,
            LINE_MAX_JOINT_STEP,
            |p| {
                let point = Vector3::new(p[0], p[1], p[2]);
                let u = if length2 > 0.0 {
                    ((point - a).dot(&(b - a)) / length2).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                let mut t = target.clone();
                t.pose = Isometry3::from_parts(
                    Translation3::from(point),
                    if keep_orientation {
                        from.rotation
                            .try_slerp(&to.rotation, u, 1e-9)
                            .unwrap_or(to.rotation)
                    } else {
                        to.rotation
                    },
                );
                let sol = numeric
                    .solve_unrecorded(solver, &t, &seed)
                    .map_err(|error| Reason::Numeric {
                        solver,
                        error,
                        orientation: t.orientation_required,
                    })?;
                let x: Vec<f64> = sol
                    .joints
                    .iter()
                    .enumerate()
                    .map(|(i, v)| {
                        if chain_continuous[i] {
                            seed[i] + (v - seed[i] + PI).rem_euclid(2.0 * PI) - PI
                        } else {
                            *v
                        }
                    })
                    .collect();
                seed.clone_from(&x);
                Ok::<_, Reason>(x)
            },
        )
        .map_err(|e| match &e {
            LineError::Unreachable { .. } | LineError::Jump { .. } | LineError::Path(_) => {
                Reason::Line { why: e.to_string() }
            }
        })?;
        let mut points: Vec<Vec<f64>> = path
            .points()
            .iter()
            .map(|x| self.arm.with_variables(goal, x))
            .collect();
        if let Some(first) = points.first_mut() {
            first.clone_from(&stop);
        }
        let end = points.last().cloned().unwrap_or_else(|| goal.to_vec());
        let path = JointPath::new(points).map_err(|e| Reason::Line { why: e.to_string() })?;
        self.planner
            .follow(path)
            .map_err(|e| Reason::Line { why: e.to_string() })?;
        Ok(end)
    }

    /// `gripper_target`: this arm has no EezyBot claw; refused.
    pub fn handle_gripper_target(
        &mut self,
        _opening: f64,
        stamp: Time,
    ) -> Result<JointState, Rejection> {
        let result = if self.estop {
            Err(Reason::EmergencyStop)
        } else {
            Err(Reason::NoGripper)
        };
        self.finish(Source::GripperTarget, stamp, stamp, result)
    }

    /// `joint_target`: positions of some of [`UrdfArm::joints`]; the others keep the
    /// goal's. Every named joint within its limits and the chain's constraints.
    pub fn handle_joint_target(
        &mut self,
        msg: &JointState,
        now: Time,
    ) -> Result<JointState, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            if self.estop {
                return Err(Reason::EmergencyStop);
            }
            check_age(stamp, now, self.motion.max_target_age_s)?;
            if msg.name.len() != msg.position.len() {
                return Err(Reason::LengthMismatch {
                    names: msg.name.len(),
                    positions: msg.position.len(),
                });
            }
            if msg.name.is_empty() {
                return Err(Reason::NoJoints);
            }
            let mut goal = self.goal.clone();
            let mut seen: Vec<&str> = Vec::with_capacity(msg.name.len());
            for (name, &value) in msg.name.iter().zip(&msg.position) {
                if seen.contains(&name.as_str()) {
                    return Err(Reason::DuplicateJoint { name: name.clone() });
                }
                seen.push(name);
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
                        index: seen.len() - 1,
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
        })();
        self.finish(Source::JointTarget, stamp, now, result)
    }

    /// Record a sample on `source` that could not be read at all.
    pub fn reject_unreadable(&mut self, source: Source, error: String) -> Rejection {
        self.counters.received += 1;
        self.reject(source, Time::now(), Reason::Unreadable { error })
    }

    fn reject(&mut self, source: Source, stamp: Time, reason: Reason) -> Rejection {
        self.counters.rejected += 1;
        if reason.code() == "too_old" {
            self.counters.too_old += 1;
        }
        self.last_event_rejected = true;
        let rejection = Rejection {
            source,
            reason,
            stamp,
        };
        self.last_rejection = Some(rejection.clone());
        rejection
    }

    fn finish(
        &mut self,
        source: Source,
        stamp: Time,
        now: Time,
        candidate: Result<Vec<f64>, Reason>,
    ) -> Result<JointState, Rejection> {
        self.counters.received += 1;
        let stamp = if stamp == Time::ZERO { now } else { stamp };
        let line = matches!(source, Source::XyzTarget | Source::PoseTarget)
            && self.motion.mode == MotionMode::Line;
        let accepted = candidate.and_then(|goal| {
            if !line {
                self.planner
                    .move_to(&goal)
                    .map_err(|e| Reason::Line { why: e.to_string() })?;
            }
            Ok(goal)
        });
        match accepted {
            Ok(goal) => {
                self.goal = goal;
                self.counters.accepted += 1;
                self.last_event_rejected = false;
                self.advance();
                Ok(self.joint_states(stamp))
            }
            Err(reason) => Err(self.reject(source, stamp, reason)),
        }
    }

    /// The next planned step (its `joint_states`, stamped `now`) while moving.
    pub fn step(&mut self, now: Time) -> Option<JointState> {
        if !self.planner.is_moving() {
            return None;
        }
        self.advance();
        self.counters.steps += 1;
        Some(self.joint_states(now))
    }

    fn advance(&mut self) {
        if let Some(mut q) = self.planner.step() {
            let mut x = self.arm.variables_of(&q);
            if !self.arm.chain.within_limits(&x, 0.0) {
                self.arm.chain.project(&mut x);
                q = self.arm.with_variables(&q, &x);
                log::debug!("a planned step moved into the joint limits");
            }
            self.state = q;
        }
    }

    /// `joint_states` (every non-fixed URDF joint) of the commanded state.
    pub fn joint_states(&self, stamp: Time) -> JointState {
        let joints = self.arm.joint_positions(&self.state);
        JointState {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            name: joints.iter().map(|(n, _)| n.clone()).collect(),
            position: joints.iter().map(|(_, v)| *v).collect(),
            velocity: vec![],
            effort: vec![],
        }
    }

    /// The `diagnostics` entry (as [`crate::core::IkCore::diagnostic_status`], with the
    /// tip's pose and every joint).
    pub fn diagnostic_status(&self, name: &str) -> DiagnosticStatus {
        let (level, message) = if self.estop {
            (DiagnosticStatus::WARN, "emergency stop engaged".to_string())
        } else if self.last_event_rejected {
            let r = self
                .last_rejection
                .as_ref()
                .map(|r| r.to_string())
                .unwrap_or_default();
            (DiagnosticStatus::WARN, r)
        } else {
            (DiagnosticStatus::OK, "ok".to_string())
        };
        let chain = &self.arm.chain;
        let mut values: Vec<(String, String)> = vec![
            ("received".into(), self.counters.received.to_string()),
            ("accepted".into(), self.counters.accepted.to_string()),
            ("rejected".into(), self.counters.rejected.to_string()),
            ("too_old".into(), self.counters.too_old.to_string()),
            ("superseded".into(), self.counters.superseded.to_string()),
            ("estop".into(), self.estop.to_string()),
            (
                "motion".into(),
                if self.planner.is_moving() {
                    format!("moving ({})", self.motion.mode.name())
                } else {
                    "at rest".to_string()
                },
            ),
            ("motion_mode".into(), self.motion.mode.name().to_string()),
            (
                "max_target_age_s".into(),
                format!("{}", self.motion.max_target_age_s),
            ),
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
            ("tip_pose".into(), describe_pose(&self.tip(&self.state))),
            (
                "joints".into(),
                self.arm
                    .joints
                    .iter()
                    .zip(&self.state)
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
            (
                "solver".into(),
                match self.solver {
                    Solver::Analytic => "dls (analytic asked: this arm has no closed form)".into(),
                    s => s.name().to_string(),
                },
            ),
        ];
        if let Some(r) = self.numeric.last_solve() {
            values.push(("last_solve".into(), r.describe()));
        }
        values.extend(
            self.numeric
                .assess_values(&self.arm.variables_of(&self.state)),
        );
        values.push((
            "substitute_nearest".into(),
            match self.substitute_max_m {
                Some(m) => format!("on, within {m} m"),
                None => "off".into(),
            },
        ));
        values.push(("substitutions".into(), self.substitutions.to_string()));
        if let Some(t) = &self.last_substitution {
            values.push(("last_substitution".into(), t.clone()));
        }
        if let Some(t) = &self.last_pose {
            values.push(("last_pose_target".into(), t.clone()));
        }
        if let Some(r) = &self.last_rejection {
            values.push((LAST_REJECTION_KEY.into(), r.reason.to_string()));
            values.push(("last_rejection_code".into(), r.reason.code()));
            values.push(("last_rejection_topic".into(), r.source.topic().to_string()));
            values.push((REJECTED_STAMP_KEY.into(), stamp_text(r.stamp)));
        }
        let refs: Vec<(&str, String)> = values
            .iter()
            .map(|(k, v)| (k.as_str(), v.clone()))
            .collect();
        ros_plumbing::diagnostics::status(level, name, &self.arm.model.name, &message, &refs)
    }
}

fn check_finite(p: &Vector3<f64>) -> Result<(), Reason> {
    for (axis, value) in [("x", p.x), ("y", p.y), ("z", p.z)] {
        if !value.is_finite() {
            return Err(KinematicsError::NonFiniteTarget { axis, value }.into());
        }
    }
    Ok(())
}
