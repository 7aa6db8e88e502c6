//! The one target pipeline, for any arm: every target passes the same checks (e-stop,
//! age, frame, finiteness), is solved by the arm ([`ArmModel`]), may be replaced by the
//! nearest reachable point, is planned (a joint move or a straight line), counted, and
//! reported in `diagnostics`; a refused one is recorded and changes nothing. Free of ROS
//! I/O: time comes in as arguments.

use crate::controller::ControllerMap;
use crate::core::{
    check_age, check_finite, check_frame, pose_parts, Counters, MotionMode, MotionSettings, Notice,
    Reason, Rejection, Source,
};
use crate::numeric::{NumericIk, Solver};
use eezybot_kinematics::ik::Target;
use eezybot_motion::{straight_line, AxisLimits, JointPath, LineError, Planner};
use eezybot_msgs::control_msgs::{FollowJointTrajectoryGoal, GripperCommandGoal};
use eezybot_msgs::controller_manager_msgs::SwitchControllerRequest;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{PointStamped, PoseStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::trajectory_msgs::JointTrajectory;
use eezybot_msgs::Time;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use ros_plumbing::action::{self, GoalId};
use ros_plumbing::feedback::{self, Refusal};
use ros_plumbing::service::{Caller, Ticket};
use ros_plumbing::Params;

/// Largest change of any joint (rad or m) between two points of a straight line checked
/// every `line_step_m`: more means the line passes a singularity.
const LINE_MAX_JOINT_STEP: f64 = 0.1;

/// Above this difference (deg) between a `pose_target`'s orientation and the one the
/// arm takes, a notice is logged.
const ORIENTATION_NOTICE_DEG: f64 = 1.0;

/// One event for the node.
#[derive(Clone, Debug)]
pub enum Input {
    /// An `xyz_target` sample.
    XyzTarget(PointStamped),
    /// An `xyz_line_target` sample: the tool along a straight line.
    XyzLineTarget(PointStamped),
    /// A `pose_target` sample.
    PoseTarget(PoseStamped),
    /// A `gripper_target` sample and when it arrived.
    GripperTarget(f64, Time),
    /// A `joint_target` sample.
    JointTarget(JointState),
    /// An `estop` sample.
    Estop(bool),
    /// A sample that could not be read (malformed): where, and the error.
    Unreadable(Source, String),
    /// An `arm_controller/joint_trajectory` sample.
    Trajectory(JointTrajectory),
    /// A new `arm_controller/follow_joint_trajectory` goal.
    TrajectoryGoal(GoalRequest<FollowJointTrajectoryGoal>),
    /// A new `gripper_controller/gripper_cmd` goal.
    GripperGoal(GoalRequest<GripperCommandGoal>),
    /// Cancels accepted for these goals (of either action).
    Cancel(Vec<GoalId>),
    /// A `servo_state` sample: what the Arduino applied.
    ServoState(JointState),
    /// A `leader/joint_states` sample: the leader arm's joints.
    LeaderJoints(JointState),
    /// A `leader/deadman` sample: the leader's deadman button is held.
    LeaderDeadman(bool),
    /// A `controller_manager/list_controllers` request, to answer.
    ListControllers(Ticket, Caller),
    /// A `controller_manager/switch_controller` request, to answer.
    SwitchController(Ticket, Caller, SwitchControllerRequest),
}

/// A goal request of an action: the request to answer, the goal's id, the goal.
#[derive(Clone, Debug)]
pub struct GoalRequest<G> {
    /// The request (answered with accept or reject).
    pub ticket: action::Ticket,
    /// The goal's id.
    pub id: GoalId,
    /// The goal.
    pub goal: Box<G>,
}

/// What an accepted target or a motion step publishes.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// Every non-fixed URDF joint.
    pub joint_states: JointState,
    /// The servo horn angles (rad), for an arm with servos (the EezyBot).
    pub servo_angles: Option<JointState>,
}

/// A Cartesian target: a position, and for a `pose_target` an orientation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cartesian {
    /// Where the tool goes (m, base frame).
    pub position: Vector3<f64>,
    /// How it is turned there (`None`: an `xyz_target`).
    pub orientation: Option<UnitQuaternion<f64>>,
}

/// A solved target: the arm's state there, and the target as solved (what a straight
/// line to it pursues).
#[derive(Clone, Debug)]
pub struct Solved<S> {
    /// The goal.
    pub state: S,
    /// The target the solve reached.
    pub target: Target,
}

/// What the two arms differ in: how a target is solved, how a state maps to the
/// planner's axes, `joint_states` and servo angles, and what diagnostics say of the
/// state. Everything else is [`Pipeline`]'s.
pub trait ArmModel {
    /// The arm's state (the commanded pose).
    type State: Clone + PartialEq + std::fmt::Debug;

    /// One line on what is driven, for the start log.
    fn describe(&self) -> String;
    /// Whether this arm has servos (publishes `servo_angles`).
    fn has_servos(&self) -> bool;
    /// The state at start.
    fn start(&self) -> Self::State;
    /// The planner's axes of a state.
    fn axes(&self, s: &Self::State) -> Vec<f64>;
    /// The state of a planned step (moved into the limits if rounding left them).
    fn planned(&self, axes: &[f64]) -> Self::State;
    /// The planner's velocity and acceleration limits, one per axis.
    fn axis_limits(&self) -> Vec<AxisLimits>;
    /// Apply the arm's own parameters; whether its axis limits may have changed.
    fn apply_params(&mut self, params: &Params) -> bool;

    /// Solve a Cartesian target from the goal `goal` with `solver`.
    fn solve(
        &mut self,
        solver: Solver,
        target: &Cartesian,
        goal: &Self::State,
    ) -> Result<Solved<Self::State>, Reason>;
    /// The nearest reachable point to a target out of reach, and how far it is (m);
    /// `None` when the arm does not substitute this target.
    fn nearest(
        &mut self,
        target: &Cartesian,
        goal: &Self::State,
    ) -> Option<(Solved<Self::State>, f64)>;
    /// The goal of a `joint_target` (names unique, as many as positions, at least one).
    fn joint_goal(
        &self,
        names: &[String],
        positions: &[f64],
        goal: &Self::State,
    ) -> Result<Self::State, Reason>;
    /// The goal of a `gripper_target` (0 closed … 1 open).
    fn gripper_goal(&self, opening: f64, goal: &Self::State) -> Result<Self::State, Reason>;
    /// A goal the arm can take besides its joint limits (the servo ranges).
    fn check_goal(&self, goal: &Self::State) -> Result<(), Reason>;

    /// The tool's pose in a state.
    fn tool_pose(&self, s: &Self::State) -> Isometry3<f64>;
    /// The tool's position in a state (where a straight line starts).
    fn tool_position(&self, s: &Self::State) -> Vector3<f64> {
        self.tool_pose(s).translation.vector
    }
    /// The angle (deg) between an orientation asked and the one the goal takes, and the
    /// line `diagnostics` reports (`last_pose_target`).
    fn pose_note(&self, goal: &Self::State, asked: &UnitQuaternion<f64>) -> (f64, String);

    /// The joints a straight line tracks (checked for jumps) at a state.
    fn line_joints(&self, s: &Self::State) -> Vec<f64>;
    /// The line's joints at one of its points, solved from `seed`; `end`: the point is
    /// the target (whose goal is `goal`).
    fn line_point(
        &mut self,
        solver: Solver,
        target: &Target,
        seed: &[f64],
        end: Option<&Self::State>,
    ) -> Result<Vec<f64>, Reason>;
    /// The planner's axes at a point of the line (`fraction` of the way) to `goal` from
    /// the axes `stop`.
    fn line_axes(
        &self,
        joints: &[f64],
        goal: &Self::State,
        stop: &[f64],
        fraction: f64,
    ) -> Vec<f64>;
    /// The goal once a line is planned to `goal`, the line ending at the axes `end`.
    fn line_goal(&self, goal: Self::State, end: &[f64]) -> Self::State;

    /// `joint_states` of a state (every non-fixed URDF joint).
    fn joint_states(&self, s: &Self::State, stamp: Time) -> JointState;
    /// `servo_angles` of a state, for an arm with servos.
    fn servo_angles(&self, s: &Self::State, stamp: Time) -> Option<JointState>;
    /// The `diagnostics` hardware id.
    fn hardware_id(&self) -> String;
    /// What `diagnostics` says of a state (tool pose, joints).
    fn state_values(&self, s: &Self::State) -> Vec<(String, String)>;
    /// The `solver` value of `diagnostics`.
    fn solver_text(&self, solver: Solver) -> String;
    /// The numerical solvers' chain, if any.
    fn numeric(&self) -> Option<&NumericIk>;
    /// The same, to solve with.
    fn numeric_mut(&mut self) -> Option<&mut NumericIk>;
    /// The chain's variables of a state (for the numerical assessments).
    fn chain_variables(&self, s: &Self::State) -> Vec<f64>;

    /// How arm_controller's and gripper_controller's joints drive the planner's axes;
    /// `None`: this arm has no trajectory controller.
    fn controller_map(&self) -> Option<ControllerMap> {
        None
    }
    /// The planner's axes a `servo_state` report puts the arm at; `None` when it does
    /// not give every servo.
    fn reported_axes(&self, _servo_state: &JointState) -> Option<Vec<f64>> {
        None
    }
}

/// The node's state for an arm: what it commands, where the motion goes, and what it
/// refused.
#[derive(Clone, Debug)]
pub struct Pipeline<M: ArmModel> {
    model: M,
    solver: Solver,
    base_frame: String,
    /// the commanded state: where the planner is
    state: M::State,
    /// where the current motion ends
    goal: M::State,
    planner: Planner,
    motion: MotionSettings,
    estop: bool,
    calibrating: bool,
    counters: Counters,
    last_rejection: Option<Rejection>,
    last_event_rejected: bool,
    /// replace targets this close outside the workspace by the nearest reachable point
    substitute_max_m: Option<f64>,
    substitutions: u64,
    last_substitution: Option<String>,
    last_pose: Option<String>,
    notices: Vec<Notice>,
}

impl<M: ArmModel> Pipeline<M> {
    /// At rest in the arm's start pose, with the default [`MotionSettings`] and the
    /// `analytic` solver. Errors: why the planner refuses the arm's limits.
    pub fn for_arm(model: M, base_frame: &str) -> Result<Self, String> {
        let motion = MotionSettings::default();
        let state = model.start();
        let planner = Planner::new(model.axis_limits(), &model.axes(&state), motion.period_s)
            .map_err(|e| e.to_string())?;
        Ok(Pipeline {
            model,
            solver: Solver::Analytic,
            base_frame: base_frame.to_string(),
            goal: state.clone(),
            state,
            planner,
            motion,
            estop: false,
            calibrating: false,
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
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The arm, to change.
    pub fn model_mut(&mut self) -> &mut M {
        &mut self.model
    }

    /// Apply the run-time parameters: solver, substitution, base frame, motion settings
    /// and the arm's own ([`ArmModel::apply_params`]).
    pub fn apply_params(&mut self, params: &Params) {
        if self.model.apply_params(params) {
            let _ = self.planner.set_limits(self.model.axis_limits());
        }
        self.set_solver(
            params
                .string("solver")
                .as_deref()
                .and_then(Solver::parse)
                .unwrap_or(Solver::Analytic),
        );
        self.set_substitution(
            params
                .bool("substitute_nearest")
                .unwrap_or(false)
                .then(|| params.f64("substitute_max_distance").unwrap_or(0.01)),
        );
        if let Some(frame) = params.string("base_frame") {
            self.set_base_frame(&frame);
        }
        self.set_motion(motion_settings(params));
    }

    /// Choose the IK solver for Cartesian targets.
    pub fn set_solver(&mut self, solver: Solver) {
        self.solver = solver;
    }

    /// The solver asked for.
    pub fn solver(&self) -> Solver {
        self.solver
    }

    /// Replace a target at most `max_m` outside the workspace by the nearest reachable
    /// point, reported, instead of refusing it (`None`: refuse every unreachable one).
    pub fn set_substitution(&mut self, max_m: Option<f64>) {
        self.substitute_max_m = max_m.filter(|m| *m > 0.0);
    }

    /// What to log besides rejections since the last call (substitutions, orientations
    /// the arm cannot take).
    pub fn take_notices(&mut self) -> Vec<Notice> {
        std::mem::take(&mut self.notices)
    }

    /// Change how the arm is moved. A new step period applies from the next target.
    pub fn set_motion(&mut self, motion: MotionSettings) {
        if motion.period_s != self.motion.period_s {
            let axes = self.model.axes(&self.state);
            if let Ok(p) = Planner::new(self.model.axis_limits(), &axes, motion.period_s) {
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

    /// The commanded state: where the arm is on its way to the goal.
    pub fn state(&self) -> &M::State {
        &self.state
    }

    /// Where the current motion ends (the last accepted target).
    pub fn goal(&self) -> &M::State {
        &self.goal
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

    /// Engage or release the emergency stop. Engaging stops the motion where it is;
    /// while engaged every target is refused; after the release the arm stays until a
    /// new target.
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

    /// Start or end calibrating (the parameter `calibrating`): while calibrating the
    /// calibration wizard drives the servos, the motion stops where it is and every
    /// target is refused ([`Reason::Calibrating`]), as under the e-stop.
    pub fn set_calibrating(&mut self, on: bool) {
        if on {
            self.planner.stop();
            self.goal = self.state.clone();
        }
        self.calibrating = on;
    }

    /// Is the arm being calibrated?
    pub fn calibrating(&self) -> bool {
        self.calibrating
    }

    /// Why no motion is taken now, if none is: the e-stop, or calibrating.
    pub fn halted(&self) -> Option<Reason> {
        self.check_estop().err()
    }

    /// Take the arm where it is reported to be (`servo_state` through the current
    /// calibration, `axes`), clamped into the joint limits, at rest: after calibrating,
    /// when the wizard left the servos wherever the last reference was. Returns the
    /// step to publish (the same angles, so nothing moves unless the clamp did).
    pub fn take_reported(&mut self, axes: &[f64], now: Time) -> Step {
        self.command_axes(axes, now)
    }

    /// Handle one target input arriving at `now` (`None` for `estop`, which is
    /// [`Pipeline::set_estop`]'s).
    pub fn handle(&mut self, input: &Input, now: Time) -> Option<Result<Step, Rejection>> {
        Some(match input {
            Input::XyzTarget(m) => self.handle_xyz(Source::XyzTarget, m, now),
            Input::XyzLineTarget(m) => self.handle_xyz(Source::XyzLineTarget, m, now),
            Input::PoseTarget(m) => self.handle_pose_target(m, now),
            Input::GripperTarget(v, stamp) => self.handle_gripper_target(*v, *stamp),
            Input::JointTarget(m) => self.handle_joint_target(m, now),
            Input::Unreadable(source, e) => Err(self.reject_unreadable(*source, e.clone())),
            Input::Estop(_)
            | Input::Trajectory(_)
            | Input::TrajectoryGoal(_)
            | Input::GripperGoal(_)
            | Input::Cancel(_)
            | Input::ServoState(_)
            | Input::LeaderJoints(_)
            | Input::LeaderDeadman(_)
            | Input::ListControllers(..)
            | Input::SwitchController(..) => return None,
        })
    }

    /// Handle an `xyz_target` arriving at `now`: the first step of the move toward it.
    pub fn handle_xyz_target(&mut self, msg: &PointStamped, now: Time) -> Result<Step, Rejection> {
        self.handle_xyz(Source::XyzTarget, msg, now)
    }

    /// Handle an `xyz_target` or `xyz_line_target` (`source`) arriving at `now`.
    fn handle_xyz(
        &mut self,
        source: Source,
        msg: &PointStamped,
        now: Time,
    ) -> Result<Step, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            self.check_target(stamp, now, &msg.header.frame_id)?;
            let position = Vector3::new(msg.point.x, msg.point.y, msg.point.z);
            check_finite(&position)?;
            let target = Cartesian {
                position,
                orientation: None,
            };
            self.move_to(source, &target)
        })();
        self.finish(source, stamp, now, result)
    }

    /// How a target from `source` is moved to: `xyz_line_target`'s along a line,
    /// `xyz_target`'s and `pose_target`'s as `motion` says, the others' in joint space.
    fn mode_of(&self, source: Source) -> MotionMode {
        match source {
            Source::XyzLineTarget => MotionMode::Line,
            Source::XyzTarget | Source::PoseTarget => self.motion.mode,
            Source::GripperTarget | Source::JointTarget => MotionMode::Joint,
        }
    }

    /// Handle a `pose_target` arriving at `now`: as far as the arm can take the
    /// orientation (the arm says, [`ArmModel::solve`]); the angle left is reported in
    /// `diagnostics` (`last_pose_target`) and logged when over 1°.
    pub fn handle_pose_target(&mut self, msg: &PoseStamped, now: Time) -> Result<Step, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            self.check_target(stamp, now, &msg.header.frame_id)?;
            let (position, rotation) = pose_parts(&msg.pose)?;
            check_finite(&position)?;
            let target = Cartesian {
                position,
                orientation: Some(rotation),
            };
            let goal = self.move_to(Source::PoseTarget, &target)?;
            let (off_deg, text) = self.model.pose_note(&goal, &rotation);
            if off_deg > ORIENTATION_NOTICE_DEG {
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

    /// Handle a `gripper_target` (0 closed … 1 open); `stamp` is when it arrived,
    /// since std_msgs/Float64 has no header.
    pub fn handle_gripper_target(&mut self, opening: f64, stamp: Time) -> Result<Step, Rejection> {
        let result = self
            .check_estop()
            .and_then(|()| self.model.gripper_goal(opening, &self.goal));
        self.finish(Source::GripperTarget, stamp, stamp, result)
    }

    /// Handle a `joint_target` arriving at `now`: positions for some or all of the
    /// arm's joints; the others keep the values of the current goal.
    pub fn handle_joint_target(&mut self, msg: &JointState, now: Time) -> Result<Step, Rejection> {
        let result = self.joint_candidate(msg, now);
        self.finish(Source::JointTarget, msg.header.stamp, now, result)
    }

    fn joint_candidate(&self, msg: &JointState, now: Time) -> Result<M::State, Reason> {
        self.check_estop()?;
        check_age(msg.header.stamp, now, self.motion.max_target_age_s)?;
        if msg.name.len() != msg.position.len() {
            return Err(Reason::LengthMismatch {
                names: msg.name.len(),
                positions: msg.position.len(),
            });
        }
        if msg.name.is_empty() {
            return Err(Reason::NoJoints);
        }
        for (i, name) in msg.name.iter().enumerate() {
            if msg.name[..i].contains(name) {
                return Err(Reason::DuplicateJoint { name: name.clone() });
            }
        }
        self.model.joint_goal(&msg.name, &msg.position, &self.goal)
    }

    /// Move the goal to joint positions (as a `joint_target` would) without stepping:
    /// the motion toward it is stepped at the motion rate by the caller's timer, so a
    /// stream faster than the motion rate (a leader arm's 100 Hz) cannot step the
    /// planner faster. Not counted as a target; a refusal changes nothing.
    pub fn retarget_joints(&mut self, msg: &JointState, now: Time) -> Result<(), Reason> {
        let goal = self.joint_candidate(msg, now)?;
        self.model.check_goal(&goal)?;
        self.planner
            .move_to(&self.model.axes(&goal))
            .map_err(|e| Reason::Line { why: e.to_string() })?;
        self.goal = goal;
        Ok(())
    }

    /// Record a target refused before it was judged: another commander holds the
    /// joints it names (the arbiter's `why`). `None` for an input that is no target.
    pub fn reject_held(&mut self, input: &Input, why: String, now: Time) -> Option<Rejection> {
        let (source, stamp) = match input {
            Input::XyzTarget(m) => (Source::XyzTarget, m.header.stamp),
            Input::XyzLineTarget(m) => (Source::XyzLineTarget, m.header.stamp),
            Input::PoseTarget(m) => (Source::PoseTarget, m.header.stamp),
            Input::JointTarget(m) => (Source::JointTarget, m.header.stamp),
            Input::GripperTarget(_, stamp) => (Source::GripperTarget, *stamp),
            _ => return None,
        };
        self.counters.received += 1;
        let stamp = if stamp == Time::ZERO { now } else { stamp };
        Some(self.reject(source, stamp, Reason::Held { why }))
    }

    /// Record a sample on `source` that could not be read at all.
    pub fn reject_unreadable(&mut self, source: Source, error: String) -> Rejection {
        self.counters.received += 1;
        self.reject(source, Time::now(), Reason::Unreadable { error })
    }

    fn check_estop(&self) -> Result<(), Reason> {
        if self.estop {
            Err(Reason::EmergencyStop)
        } else if self.calibrating {
            Err(Reason::Calibrating)
        } else {
            Ok(())
        }
    }

    /// The checks of a Cartesian target: e-stop, age, frame.
    fn check_target(&self, stamp: Time, now: Time, frame_id: &str) -> Result<(), Reason> {
        self.check_estop()?;
        check_age(stamp, now, self.motion.max_target_age_s)?;
        check_frame(frame_id, &self.base_frame)
    }

    fn reject(&mut self, source: Source, stamp: Time, reason: Reason) -> Rejection {
        self.counters.rejected += 1;
        if matches!(reason, Reason::TooOld { .. }) {
            self.counters.stale += 1;
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

    /// The goal for a Cartesian target: solved, or replaced by the nearest reachable
    /// point when substitution is on and the target is just out of reach; checked
    /// against the servo ranges; planned as a line in line mode.
    fn move_to(&mut self, source: Source, target: &Cartesian) -> Result<M::State, Reason> {
        let (solved, substituted) = match self.model.solve(self.solver, target, &self.goal) {
            Ok(solved) => (solved, None),
            Err(reason) => {
                let near = match self.substitute_max_m {
                    Some(max_m) if reason.is_out_of_workspace() => self
                        .model
                        .nearest(target, &self.goal)
                        .filter(|(_, distance_m)| *distance_m <= max_m),
                    _ => None,
                };
                let Some((near, _)) = near else {
                    return Err(reason);
                };
                let (t, p) = (target.position, near.target.pose.translation.vector);
                let text = format!(
                    "{} ({:.4}, {:.4}, {:.4}) m is out of reach ({reason}): moved to the nearest reachable point ({:.4}, {:.4}, {:.4}) m, {:.4} m away",
                    source.topic(),
                    t.x,
                    t.y,
                    t.z,
                    p.x,
                    p.y,
                    p.z,
                    (p - t).norm()
                );
                (near, Some(text))
            }
        };
        self.model.check_goal(&solved.state)?;
        let mut goal = solved.state;
        if self.mode_of(source) == MotionMode::Line {
            let record = self.model.numeric().and_then(|n| n.last_solve().cloned());
            let planned = self.plan_line(&solved.target, goal);
            if let Some(n) = self.model.numeric_mut() {
                n.restore_last_solve(record); // the target's solve, not the line's last sample
            }
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

    /// The straight line from where the arm stops to `target` (the orientation turned
    /// along it, slerp), solved at every sample and checked for jumps, as the planner's
    /// path. Returns the goal: where the line ends.
    fn plan_line(&mut self, target: &Target, goal: M::State) -> Result<M::State, Reason> {
        let stop = self.planner.stopping_position();
        let from_state = self.model.planned(&stop);
        let from = self.model.tool_pose(&from_state);
        let a = self.model.tool_position(&from_state);
        let b = target.pose.translation.vector;
        let length2 = (b - a).norm_squared();
        let keep_orientation = target.orientation_weights.iter().any(|w| *w != 0.0);
        let solver = self.solver;
        let mut seed = self.model.line_joints(&from_state);
        let model = &mut self.model;
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
                let rotation = if keep_orientation {
                    from.rotation
                        .try_slerp(&target.pose.rotation, u, 1e-9)
                        .unwrap_or(target.pose.rotation)
                } else {
                    target.pose.rotation
                };
                t.pose = Isometry3::from_parts(Translation3::from(point), rotation);
                // the end: the goal itself (a substituted point lies on the boundary)
                let end = ((point - b).norm() <= 1e-12).then_some(&goal);
                let x = model.line_point(solver, &t, &seed, end)?;
                seed.clone_from(&x);
                Ok::<_, Reason>(x)
            },
        )
        .map_err(|e| match &e {
            LineError::Unreachable { .. } | LineError::Jump { .. } | LineError::Path(_) => {
                Reason::Line { why: e.to_string() }
            }
        })?;
        let n = path.len().saturating_sub(1).max(1) as f64;
        let mut points: Vec<Vec<f64>> = path
            .points()
            .iter()
            .enumerate()
            .map(|(k, x)| self.model.line_axes(x, &goal, &stop, k as f64 / n))
            .collect();
        // the first point is where the arm stops, to the last bit
        if let Some(first) = points.first_mut() {
            first.clone_from(&stop);
        }
        let end = points
            .last()
            .cloned()
            .unwrap_or_else(|| self.model.axes(&goal));
        let path = JointPath::new(points).map_err(|e| Reason::Line { why: e.to_string() })?;
        self.planner
            .follow(path)
            .map_err(|e| Reason::Line { why: e.to_string() })?;
        Ok(self.model.line_goal(goal, &end))
    }

    /// Make a validated goal the planner's (unless a line planned it already) and
    /// return the first step at once, stamped with the input's stamp (`now` for a zero
    /// stamp); or record the rejection.
    fn finish(
        &mut self,
        source: Source,
        stamp: Time,
        now: Time,
        candidate: Result<M::State, Reason>,
    ) -> Result<Step, Rejection> {
        self.counters.received += 1;
        let stamp = if stamp == Time::ZERO { now } else { stamp };
        let line = self.mode_of(source) == MotionMode::Line;
        let accepted = candidate.and_then(|goal| {
            self.model.check_goal(&goal)?;
            if !line {
                self.planner
                    .move_to(&self.model.axes(&goal))
                    .map_err(|e| Reason::Line { why: e.to_string() })?;
            }
            Ok(goal)
        });
        match accepted {
            Ok(goal) => {
                self.goal = goal;
                self.counters.accepted += 1;
                self.last_event_rejected = false;
                // the first step leaves at once: a small move gets no added latency
                self.advance();
                Ok(self.output(stamp))
            }
            Err(reason) => Err(self.reject(source, stamp, reason)),
        }
    }

    /// The next planned step, stamped `now`, while the arm is moving.
    pub fn step(&mut self, now: Time) -> Option<Step> {
        if !self.planner.is_moving() {
            return None;
        }
        self.advance();
        self.counters.steps += 1;
        Some(self.output(now))
    }

    fn advance(&mut self) {
        if let Some(axes) = self.planner.step() {
            self.state = self.model.planned(&axes);
        }
    }

    fn output(&self, stamp: Time) -> Step {
        Step {
            joint_states: self.joint_states(stamp),
            servo_angles: self.model.servo_angles(&self.state, stamp),
        }
    }

    /// The planner's axes of the commanded state.
    pub fn axes(&self) -> Vec<f64> {
        self.model.axes(&self.state)
    }

    /// The planner's velocity and acceleration limits, one per axis.
    pub fn axis_limits(&self) -> Vec<eezybot_motion::AxisLimits> {
        self.planner.limits().to_vec()
    }

    /// Whether joint values (of `names`, from the current goal) are a goal the arm can
    /// take: its joint limits and servo ranges.
    pub fn check_joints(&self, names: &[String], positions: &[f64]) -> Result<(), Reason> {
        let goal = self.model.joint_goal(names, positions, &self.state)?;
        self.model.check_goal(&goal)
    }

    /// Command the arm to the axes `axes` (a trajectory's step), stamped `now`: the
    /// planner is left at rest there, the goal is there.
    pub fn command_axes(&mut self, axes: &[f64], now: Time) -> Step {
        self.state = self.model.planned(axes);
        self.goal = self.state.clone();
        if let Err(e) = self.planner.reset(&self.model.axes(&self.state)) {
            log::warn!("trajectory step: {e}");
        }
        self.counters.steps += 1;
        self.output(now)
    }

    /// Plan a motion to the axes `axes` from where the arm is (within the limits).
    pub fn move_to_axes(&mut self, axes: &[f64]) {
        match self.planner.move_to(axes) {
            Ok(()) => self.goal = self.model.planned(axes),
            Err(e) => log::warn!("cannot move on: {e}"),
        }
    }

    /// Stop the planned motion where it is (a trajectory takes over, or ends).
    pub fn stop_motion(&mut self) {
        self.planner.stop();
        let axes = self.planner.position();
        self.state = self.model.planned(&axes);
        self.goal = self.state.clone();
        let _ = self.planner.reset(&axes);
    }

    /// `joint_states` of the commanded state (every non-fixed URDF joint), with this
    /// stamp.
    pub fn joint_states(&self, stamp: Time) -> JointState {
        self.model.joint_states(&self.state, stamp)
    }

    /// The node's diagnostics entry: OK, or WARN while the latest input was refused or
    /// the emergency stop is engaged, with the last rejection ([`feedback::encode`]),
    /// counters, the state and the solver.
    pub fn diagnostic_status(&self, name: &str) -> DiagnosticStatus {
        let (level, message) = if self.estop {
            (DiagnosticStatus::WARN, "emergency stop engaged".to_string())
        } else if self.calibrating {
            (
                DiagnosticStatus::WARN,
                "calibrating: the wizard drives the servos, no target is taken".to_string(),
            )
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
        let c = &self.counters;
        let mut values: Vec<(String, String)> = vec![
            ("received".into(), c.received.to_string()),
            ("accepted".into(), c.accepted.to_string()),
            ("rejected".into(), c.rejected.to_string()),
            ("stale".into(), c.stale.to_string()),
            ("superseded".into(), c.superseded.to_string()),
            ("estop".into(), self.estop.to_string()),
            ("calibrating".into(), self.calibrating.to_string()),
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
        ];
        values.extend(self.model.state_values(&self.state));
        values.push(("solver".into(), self.model.solver_text(self.solver)));
        if let Some(n) = self.model.numeric() {
            if let Some(r) = n.last_solve() {
                values.push(("last_solve".into(), r.describe()));
            }
            // undesirable configurations of the commanded state, each with a way out
            values.extend(n.assess_values(&self.model.chain_variables(&self.state)));
        }
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
            values.push(("last_rejection_code".into(), r.reason.code()));
            // the refusal gui_bridge's `once`/`play` wait for, read by ros_plumbing::feedback
            let refusal = Refusal::new(
                r.stamp,
                r.reason.reason_code(),
                &r.reason.to_string(),
                r.source.topic(),
            );
            values.extend(
                feedback::encode(&refusal)
                    .into_iter()
                    .map(|(k, v)| (k.to_string(), v)),
            );
        }
        let refs: Vec<(&str, String)> = values
            .iter()
            .map(|(k, v)| (k.as_str(), v.clone()))
            .collect();
        ros_plumbing::diagnostics::status(level, name, &self.model.hardware_id(), &message, &refs)
    }
}

/// The motion settings the parameters say ([`MotionSettings::default`] for any unset).
pub fn motion_settings(params: &Params) -> MotionSettings {
    let default = MotionSettings::default();
    MotionSettings {
        period_s: params
            .f64("motion_rate")
            .map_or(default.period_s, |rate| 1.0 / rate),
        mode: params
            .string("motion")
            .as_deref()
            .and_then(MotionMode::parse)
            .unwrap_or(default.mode),
        max_target_age_s: params
            .f64("max_target_age")
            .unwrap_or(default.max_target_age_s),
        ..default
    }
}

/// A `JointState` of these names and positions, with this stamp.
pub fn joint_state<'a>(
    stamp: Time,
    joints: impl IntoIterator<Item = (&'a str, f64)>,
) -> JointState {
    let (name, position): (Vec<String>, Vec<f64>) =
        joints.into_iter().map(|(n, v)| (n.to_string(), v)).unzip();
    JointState {
        header: Header {
            stamp,
            frame_id: String::new(),
        },
        name,
        position,
        velocity: vec![],
        effort: vec![],
    }
}
