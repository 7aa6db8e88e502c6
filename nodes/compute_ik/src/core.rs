//! The IK node's logic, free of ROS I/O: targets in, joint states and servo angles
//! out, or a rejection with its reason. A rejected input never changes the state.

use crate::numeric::{describe_pose, NumericIk, Solver};
use eezybot_kinematics::ik::Target;
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::{
    Arm, ArmConfig, ArmJoints, ArmState, Joint, KinematicsError, MotionLimits, ServoCalibrations,
    ServoId, ACTUATED_JOINTS,
};
use eezybot_motion::{straight_line, AxisLimits, LineError, Planner};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{PointStamped, Pose, PoseStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use ros_plumbing::diagnostics::{stamp_text, LAST_REJECTION_KEY, REJECTED_STAMP_KEY};
use ros_plumbing::logging::{shorten, NAME_MAX};
use ros_plumbing::topics;
use std::fmt;

/// The EezyBot's URDF (`urdf/eezybot.urdf`), whose chain the numerical solvers drive.
pub const EEZYBOT_URDF: &str = include_str!("../../../urdf/eezybot.urdf");

/// Which input topic a request came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// `xyz_target`
    XyzTarget,
    /// `gripper_target`
    GripperTarget,
    /// `joint_target`
    JointTarget,
    /// `pose_target`
    PoseTarget,
}

impl Source {
    /// The topic name.
    pub fn topic(self) -> &'static str {
        match self {
            Source::XyzTarget => topics::XYZ_TARGET.name,
            Source::GripperTarget => topics::GRIPPER_TARGET.name,
            Source::JointTarget => topics::JOINT_TARGET.name,
            Source::PoseTarget => topics::POSE_TARGET.name,
        }
    }
}

/// Why an input was refused.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Reason {
    /// The kinematics refused it (reach, limits, non-finite values, servo range).
    Kinematics(KinematicsError),
    /// `header.frame_id` is neither empty nor the base frame.
    WrongFrame {
        /// the frame given
        frame_id: String,
        /// the frame expected
        expected: String,
    },
    /// `joint_target` names a joint that is not actuated (or does not exist).
    UnknownJoint {
        /// the name given
        name: String,
    },
    /// `joint_target` names a joint that a URDF arm does not have (or does not move).
    UnknownArmJoint {
        /// the name given
        name: String,
        /// the joints it accepts
        known: Vec<String>,
    },
    /// `joint_target` names a joint twice.
    DuplicateJoint {
        /// the name given twice
        name: String,
    },
    /// `joint_target` has a different number of names and positions.
    LengthMismatch {
        /// names
        names: usize,
        /// positions
        positions: usize,
    },
    /// `joint_target` names no joint.
    NoJoints,
    /// The emergency stop is engaged.
    EmergencyStop,
    /// The target's stamp is older than `max_target_age`.
    TooOld {
        /// how old (s)
        age_s: f64,
        /// the limit (s)
        max_s: f64,
    },
    /// A straight-line move would leave the workspace (or jump at a singularity).
    Line {
        /// why, and where along the line
        why: String,
    },
    /// The sample could not be deserialized.
    Unreadable {
        /// what the middleware said
        error: String,
    },
    /// A `pose_target`'s orientation is not a rotation (a quaternion far from unit
    /// length, or not finite).
    BadOrientation {
        /// the quaternion given (x, y, z, w)
        quaternion: [f64; 4],
    },
    /// A numerical solver did not reach the target (or another error of the chain).
    Numeric {
        /// the solver
        solver: Solver,
        /// what it said
        error: KinematicsError,
        /// whether the target's orientation was required (its residual matters)
        orientation: bool,
    },
    /// `gripper_target` for an arm without the EezyBot's claw.
    NoGripper,
    /// A joint of a URDF arm would leave its limits (or a linear constraint of them).
    JointLimit {
        /// the joint, or the constraint's name
        name: String,
        /// the value it would have (rad or m)
        value: f64,
        /// lower limit
        lower: f64,
        /// upper limit
        upper: f64,
        /// rad (else m)
        revolute: bool,
    },
}

impl Reason {
    /// A short machine-readable code, e.g. `too_far`, `wrong_frame`.
    pub fn code(&self) -> String {
        match self {
            Reason::Kinematics(e) => e.code(),
            Reason::WrongFrame { .. } => "wrong_frame".into(),
            Reason::UnknownJoint { .. } | Reason::UnknownArmJoint { .. } => "unknown_joint".into(),
            Reason::DuplicateJoint { .. } => "duplicate_joint".into(),
            Reason::LengthMismatch { .. } => "length_mismatch".into(),
            Reason::NoJoints => "no_joints".into(),
            Reason::EmergencyStop => "estop".into(),
            Reason::TooOld { .. } => "too_old".into(),
            Reason::Line { .. } => "line_leaves_workspace".into(),
            Reason::Unreadable { .. } => "unreadable".into(),
            Reason::BadOrientation { .. } => "bad_orientation".into(),
            Reason::Numeric { error, .. } => error.code(),
            Reason::NoGripper => "no_gripper".into(),
            Reason::JointLimit { name, .. } => {
                format!("out_of_limits:{}", shorten(name, NAME_MAX))
            }
        }
    }

    /// Whether the target is out of the arm's reach or limits (what the nearest
    /// reachable point may replace), rather than malformed.
    pub fn is_out_of_workspace(&self) -> bool {
        matches!(
            self,
            Reason::Kinematics(
                KinematicsError::TooFar { .. }
                    | KinematicsError::TooClose { .. }
                    | KinematicsError::OutOfLimits { .. }
            ) | Reason::Numeric {
                error: KinematicsError::IkNotConverged { .. },
                ..
            }
        )
    }
}

impl fmt::Display for Reason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Reason::Kinematics(e) => write!(f, "{e}"),
            Reason::WrongFrame { frame_id, expected } => write!(
                f,
                "frame_id `{}` is not `{}` (targets must be given in the arm's base frame)",
                shorten(frame_id, NAME_MAX),
                shorten(expected, NAME_MAX)
            ),
            Reason::UnknownJoint { name } => {
                write!(
                    f,
                    "unknown joint `{}` (actuated joints: {})",
                    shorten(name, NAME_MAX),
                    ACTUATED_JOINTS.join(", ")
                )
            }
            Reason::UnknownArmJoint { name, known } => write!(
                f,
                "unknown joint `{}` (this arm's joints: {})",
                shorten(name, NAME_MAX),
                known.join(", ")
            ),
            Reason::DuplicateJoint { name } => {
                write!(f, "joint `{}` named twice", shorten(name, NAME_MAX))
            }
            Reason::LengthMismatch { names, positions } => {
                write!(f, "{names} names but {positions} positions")
            }
            Reason::NoJoints => write!(f, "no joint named"),
            Reason::EmergencyStop => write!(
                f,
                "emergency stop engaged: no motion until `estop` is false"
            ),
            Reason::TooOld { age_s, max_s } => write!(
                f,
                "target stamped {age_s:.3} s ago, older than max_target_age {max_s:.3} s (delayed, or the publisher's clock differs)"
            ),
            Reason::Line { why } => write!(f, "{why}"),
            Reason::Unreadable { error } => write!(f, "unreadable sample: {error}"),
            Reason::BadOrientation { quaternion: [x, y, z, w] } => write!(
                f,
                "orientation ({x}, {y}, {z}, {w}) is not a rotation: a unit quaternion x y z w is expected (no rotation is 0 0 0 1)"
            ),
            Reason::Numeric {
                solver,
                error:
                    KinematicsError::IkNotConverged {
                        position_error_m,
                        orientation_error_rad,
                        iterations,
                        attempts,
                    },
                orientation,
            } => {
                write!(
                    f,
                    "not reached: the closest the {} solver got within the joint limits is {position_error_m:.4} m",
                    solver.name()
                )?;
                if *orientation {
                    write!(f, " and {:.2}°", orientation_error_rad.to_degrees())?;
                }
                write!(
                    f,
                    " away ({iterations} iterations, {attempts} attempt{}): {}",
                    if *attempts == 1 { "" } else { "s" },
                    if *orientation {
                        "out of reach, past a joint limit, or an orientation this arm cannot take there"
                    } else {
                        "out of reach or past a joint limit"
                    }
                )
            }
            Reason::Numeric { solver, error, .. } => {
                write!(f, "{} solver: {error}", solver.name())
            }
            Reason::NoGripper => write!(
                f,
                "this arm has no gripper_target claw (that is the EezyBot's): move its joints with joint_target"
            ),
            Reason::JointLimit {
                name,
                value,
                lower,
                upper,
                revolute,
            } => {
                let name = shorten(name, NAME_MAX);
                if *revolute {
                    write!(
                        f,
                        "{name} would be {:.2}°, outside its limits {:.2}° … {:.2}°",
                        value.to_degrees(),
                        lower.to_degrees(),
                        upper.to_degrees()
                    )
                } else {
                    write!(
                        f,
                        "{name} would be {value:.4} m, outside its limits {lower:.4} m … {upper:.4} m"
                    )
                }
            }
        }
    }
}

impl From<KinematicsError> for Reason {
    fn from(e: KinematicsError) -> Self {
        Reason::Kinematics(e)
    }
}

/// A refused input.
#[derive(Clone, Debug, PartialEq)]
pub struct Rejection {
    /// Where it came from.
    pub source: Source,
    /// Why.
    pub reason: Reason,
    /// The stamp of the refused input.
    pub stamp: Time,
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} rejected: {}", self.source.topic(), self.reason)
    }
}

/// One step of the arm's motion: what an accepted input produces first (stamped with
/// the input's stamp), then every planner step (stamped when it is planned).
#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// Every non-fixed URDF joint.
    pub joint_states: JointState,
    /// The four servo horn angles (rad).
    pub servo_angles: JointState,
}

/// Counters for diagnostics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Inputs received on any target topic.
    pub received: u64,
    /// Inputs that produced output.
    pub accepted: u64,
    /// Inputs refused.
    pub rejected: u64,
    /// Of those, refused for being older than `max_target_age`.
    pub too_old: u64,
    /// Targets dropped unused because a newer one of the same kind arrived with them
    /// (latest wins).
    pub superseded: u64,
    /// Planner steps published after the first of a move.
    pub steps: u64,
}

/// How xyz targets are moved to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotionMode {
    /// Every actuator within its limits, together: a straight line in joint space.
    Joint,
    /// The tool on a straight line; refused before the move if any point of the line
    /// is out of the workspace.
    Line,
}

impl MotionMode {
    /// The parameter's value.
    pub fn name(self) -> &'static str {
        match self {
            MotionMode::Joint => "joint",
            MotionMode::Line => "line",
        }
    }

    /// From the parameter's value.
    pub fn parse(s: &str) -> Option<MotionMode> {
        match s {
            "joint" => Some(MotionMode::Joint),
            "line" => Some(MotionMode::Line),
            _ => None,
        }
    }
}

/// How the core moves the arm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionSettings {
    /// Time between two planned steps (s).
    pub period_s: f64,
    /// How xyz targets are moved to.
    pub mode: MotionMode,
    /// Targets stamped longer ago are refused (s); 0 = no limit.
    pub max_target_age_s: f64,
    /// Spacing of the points at which a straight line is checked (m).
    pub line_step_m: f64,
}

impl Default for MotionSettings {
    fn default() -> Self {
        MotionSettings {
            period_s: 0.02,
            mode: MotionMode::Joint,
            max_target_age_s: 0.5,
            line_step_m: 0.002,
        }
    }
}

/// Largest change of any joint between two points of a straight line checked every
/// `line_step_m`: more means the line passes a singularity.
const LINE_MAX_JOINT_STEP_RAD: f64 = 0.1;

/// The IK node's state.
#[derive(Clone, Debug)]
pub struct IkCore {
    arm: Arm,
    calibration: ServoCalibrations,
    limits: MotionLimits,
    gripper_open_rad: f64,
    base_frame: String,
    /// the commanded state: where the planner is
    state: ArmState,
    /// where the current motion ends
    goal: ArmState,
    planner: Planner,
    motion: MotionSettings,
    estop: bool,
    counters: Counters,
    last_rejection: Option<Rejection>,
    last_event_rejected: bool,
    /// the URDF whose chain the numerical solvers drive
    model: Option<RobotModel>,
    /// that chain with this arm's limits (None: the URDF is not the EezyBot's)
    numeric: Option<NumericIk>,
    numeric_error: Option<KinematicsError>,
    solver: Solver,
    /// replace targets this close outside the workspace by the nearest reachable point
    substitute_max_m: Option<f64>,
    substitutions: u64,
    last_substitution: Option<String>,
    last_pose: Option<String>,
    notices: Vec<Notice>,
}

/// Something the node should log that is not a rejection (a substituted target, an
/// orientation the arm cannot take): a throttle kind and the line.
#[derive(Clone, Debug, PartialEq)]
pub struct Notice {
    /// What kind, for [`ros_plumbing::logging::Throttle`], e.g. `xyz_target/substituted`.
    pub kind: String,
    /// The line to log.
    pub text: String,
}

/// Largest joint difference (rad) by which a numerical solution outside the limits (by
/// rounding in the projection onto them) is moved back inside.
const LIMIT_ROUNDING_RAD: f64 = 1e-9;

/// Above this difference (deg) between a `pose_target`'s orientation and the one the
/// arm takes, a notice is logged.
const ORIENTATION_NOTICE_DEG: f64 = 1.0;

impl IkCore {
    /// A core for this configuration, at rest in the home pose with the claw closed,
    /// with the default [`MotionSettings`] and the closed-form solver; the numerical
    /// solvers drive the shipped `urdf/eezybot.urdf`.
    pub fn new(config: &ArmConfig, base_frame: &str) -> IkCore {
        let model = RobotModel::from_urdf_str(EEZYBOT_URDF, "urdf/eezybot.urdf").ok();
        Self::build(config, base_frame, model)
    }

    /// As [`IkCore::new`], the numerical solvers driving this EezyBot URDF (its chain
    /// `base_link` → `tool0` with the passive linkage joints, [`Arm::serial_chain`]).
    pub fn with_model(
        config: &ArmConfig,
        base_frame: &str,
        model: RobotModel,
    ) -> Result<IkCore, KinematicsError> {
        let core = Self::build(config, base_frame, Some(model));
        match &core.numeric_error {
            Some(e) => Err(e.clone()),
            None => Ok(core),
        }
    }

    fn build(config: &ArmConfig, base_frame: &str, model: Option<RobotModel>) -> IkCore {
        let motion = MotionSettings::default();
        let state = ArmState::default();
        let planner = Planner::new(
            axis_limits(&config.motion, &config.servos),
            &actuators(&state),
            motion.period_s,
        )
        .unwrap_or_else(|_| unreachable!("validated limits and a finite home pose"));
        let mut core = IkCore {
            arm: config.arm(),
            calibration: config.servos,
            limits: config.motion,
            gripper_open_rad: config.geometry.gripper_open_rad,
            base_frame: base_frame.to_string(),
            state,
            goal: state,
            planner,
            motion,
            estop: false,
            counters: Counters::default(),
            last_rejection: None,
            last_event_rejected: false,
            model,
            numeric: None,
            numeric_error: None,
            solver: Solver::Analytic,
            substitute_max_m: None,
            substitutions: 0,
            last_substitution: None,
            last_pose: None,
            notices: Vec::new(),
        };
        core.rebuild_chain();
        core
    }

    /// The chain of the URDF with this arm's limits (again after a configuration change).
    fn rebuild_chain(&mut self) {
        let built = match &self.model {
            Some(m) => self.arm.serial_chain(m),
            None => Err(KinematicsError::UnknownLink {
                link: "base_link".into(),
            }),
        };
        match built {
            Ok(chain) => {
                self.numeric = Some(NumericIk::new(chain, false));
                self.numeric_error = None;
            }
            Err(e) => {
                self.numeric = None;
                self.numeric_error = Some(e);
            }
        }
    }

    /// Swap in a new configuration (kept state is re-checked on the next input; the
    /// motion under way continues within the new limits).
    pub fn set_config(&mut self, config: &ArmConfig) {
        let changed = config.arm() != self.arm;
        self.arm = config.arm();
        self.calibration = config.servos;
        self.limits = config.motion;
        self.gripper_open_rad = config.geometry.gripper_open_rad;
        let _ = self
            .planner
            .set_limits(axis_limits(&config.motion, &config.servos));
        if changed {
            self.rebuild_chain();
        }
    }

    /// Choose the IK solver for Cartesian targets (`analytic`: the closed form).
    pub fn set_solver(&mut self, solver: Solver) {
        self.solver = solver;
    }

    /// The solver in use.
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

    /// The numerical chain, if the URDF is the EezyBot's.
    pub fn numeric(&self) -> Option<&NumericIk> {
        self.numeric.as_ref()
    }

    /// Change how the arm is moved. A new step period applies from the next target.
    pub fn set_motion(&mut self, motion: MotionSettings) {
        if motion.period_s != self.motion.period_s {
            if let Ok(p) = Planner::new(
                axis_limits(&self.limits, &self.calibration),
                &actuators(&self.state),
                motion.period_s,
            ) {
                self.planner = p;
                self.goal = self.state;
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

    /// Where the current motion ends (the last accepted target).
    pub fn goal(&self) -> &ArmState {
        &self.goal
    }

    /// Change the frame targets must be given in.
    pub fn set_base_frame(&mut self, base_frame: &str) {
        self.base_frame = base_frame.to_string();
    }

    /// The commanded state: where the arm is on its way to the goal.
    pub fn state(&self) -> &ArmState {
        &self.state
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
            self.goal = self.state;
        }
        self.estop = engaged;
    }

    /// Is the emergency stop engaged?
    pub fn estop(&self) -> bool {
        self.estop
    }

    /// Handle an `xyz_target` arriving at `now`: the first step of the move toward it.
    pub fn handle_xyz_target(
        &mut self,
        msg: &PointStamped,
        now: Time,
    ) -> Result<Output, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            self.check_estop()?;
            self.check_age(stamp, now)?;
            check_frame(&msg.header.frame_id, &self.base_frame)?;
            let target = Vector3::new(msg.point.x, msg.point.y, msg.point.z);
            self.move_to_point(Source::XyzTarget, target, None)
        })();
        self.finish(Source::XyzTarget, stamp, now, result)
    }

    /// Handle a `pose_target` arriving at `now`. The EezyBot has three joints: its claw
    /// stays level and faces along the base angle, so its orientation follows from the
    /// position. The pose is solved position first (the numerical solvers pursue the
    /// orientation in what freedom the position leaves, which for this arm is none);
    /// the angle between the orientation asked and the one taken is reported in
    /// `diagnostics` (`last_pose_target`) and logged when over 1°.
    pub fn handle_pose_target(
        &mut self,
        msg: &PoseStamped,
        now: Time,
    ) -> Result<Output, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            self.check_estop()?;
            self.check_age(stamp, now)?;
            check_frame(&msg.header.frame_id, &self.base_frame)?;
            let (position, rotation) = pose_parts(&msg.pose)?;
            let goal = self.move_to_point(Source::PoseTarget, position, Some(rotation))?;
            let taken = self.tool_pose(&goal.joints);
            let off_deg = taken.rotation.angle_to(&rotation).to_degrees();
            let text = format!(
                "position first: the orientation taken is {off_deg:.2}° from the one asked (this arm's claw stays level, facing along the base angle); tool0 at {}",
                describe_pose(&taken)
            );
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

    /// `tool0` in `base_link` for these joints (from the URDF chain when there is one).
    fn tool_pose(&self, q: &ArmJoints) -> Isometry3<f64> {
        match self
            .numeric
            .as_ref()
            .map(|n| n.chain().forward(&q.to_chain()))
        {
            Some(Ok(p)) => p,
            _ => Isometry3::from_parts(
                Translation3::from(self.arm.forward(q)),
                UnitQuaternion::from_euler_angles(0.0, 0.0, q.base_rad),
            ),
        }
    }

    /// The goal for a Cartesian target (position, and for a pose its orientation):
    /// solved, checked against the servo ranges, and planned as a line in line mode. A
    /// target just outside the workspace may be replaced by the nearest reachable point
    /// ([`IkCore::set_substitution`]).
    fn move_to_point(
        &mut self,
        source: Source,
        target: Vector3<f64>,
        orientation: Option<UnitQuaternion<f64>>,
    ) -> Result<ArmState, Reason> {
        let (joints, point, substituted) = self.solve_point(source, target, orientation)?;
        let goal = ArmState {
            joints,
            ..self.goal
        };
        self.calibration.servo_angles(&goal)?;
        if self.motion.mode == MotionMode::Line {
            let record = self.numeric.as_ref().and_then(|n| n.last_solve().cloned());
            let planned = self.plan_line(point, goal);
            if let Some(n) = self.numeric.as_mut() {
                n.restore_last_solve(record); // the target's solve, not the line's last sample
            }
            planned?;
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

    /// Joints for a point with the current solver, or those of the nearest reachable
    /// point when substitution is on and the point is just outside the workspace; with
    /// the point they reach and, if substituted, the line that says so.
    fn solve_point(
        &mut self,
        source: Source,
        target: Vector3<f64>,
        orientation: Option<UnitQuaternion<f64>>,
    ) -> Result<(ArmJoints, Vector3<f64>, Option<String>), Reason> {
        let reason = match self.solve_exact(&target, orientation) {
            Ok(q) => return Ok((q, target, None)),
            Err(reason) => reason,
        };
        let Some(max_m) = self.substitute_max_m else {
            return Err(reason);
        };
        if !reason.is_out_of_workspace() {
            return Err(reason);
        }
        let seed = self.goal.joints.to_chain();
        let Some(numeric) = self.numeric.as_mut() else {
            return Err(reason);
        };
        let Ok(near) = numeric.nearest(&target, &seed) else {
            return Err(reason);
        };
        if near.distance_m > max_m {
            return Err(reason);
        }
        let Some(q) = ArmJoints::from_chain(&near.joints) else {
            return Err(reason);
        };
        let q = self.inside_limits(q)?;
        let p = self.arm.forward(&q);
        let text = format!(
            "{} ({:.4}, {:.4}, {:.4}) m is out of reach ({reason}): moved to the nearest reachable point ({:.4}, {:.4}, {:.4}) m, {:.4} m away",
            source.topic(),
            target.x,
            target.y,
            target.z,
            p.x,
            p.y,
            p.z,
            (p - target).norm()
        );
        Ok((q, p, Some(text)))
    }

    /// Joints that put `tool0` at `target` with the current solver (the closed form or a
    /// numerical one on the URDF chain, warm-started from the goal).
    fn solve_exact(
        &mut self,
        target: &Vector3<f64>,
        orientation: Option<UnitQuaternion<f64>>,
    ) -> Result<ArmJoints, Reason> {
        let solver = self.solver;
        if solver.algorithm().is_none() {
            return Ok(self.arm.solve_position(target, self.goal.joints.base_rad)?);
        }
        for (axis, value) in [("x", target.x), ("y", target.y), ("z", target.z)] {
            if !value.is_finite() {
                return Err(KinematicsError::NonFiniteTarget { axis, value }.into());
            }
        }
        let seed = self.goal.joints.to_chain();
        let Some(numeric) = self.numeric.as_mut() else {
            return Err(Reason::Numeric {
                solver,
                orientation: false,
                error: self
                    .numeric_error
                    .clone()
                    .unwrap_or(KinematicsError::UnknownLink {
                        link: "tool0".into(),
                    }),
            });
        };
        let goal = match orientation {
            None => Target::position(*target),
            Some(r) => {
                Target::pose_preferred(Isometry3::from_parts(Translation3::from(*target), r), 1.0)
            }
        };
        let sol = numeric
            .solve(solver, &goal, &seed)
            .map_err(|error| Reason::Numeric {
                solver,
                error,
                orientation: false,
            })?;
        let q = ArmJoints::from_chain(&sol.joints).ok_or(Reason::Numeric {
            solver,
            orientation: false,
            error: KinematicsError::DimensionMismatch {
                what: "solution",
                expected: 3,
                got: sol.joints.len(),
            },
        })?;
        self.inside_limits(q)
    }

    /// `q`, or `q` moved back inside the limits when a numerical solution is outside them
    /// by rounding only.
    fn inside_limits(&self, q: ArmJoints) -> Result<ArmJoints, Reason> {
        let Err(e) = self.arm.limits.check(&q) else {
            return Ok(q);
        };
        let c = self.arm.limits.clamp(&q);
        let moved = (c.base_rad - q.base_rad)
            .abs()
            .max((c.shoulder_rad - q.shoulder_rad).abs())
            .max((c.elbow_rad - q.elbow_rad).abs());
        if moved <= LIMIT_ROUNDING_RAD && self.arm.limits.check(&c).is_ok() {
            Ok(c)
        } else {
            Err(e.into())
        }
    }

    /// The straight line from where the arm stops to `target`, checked along its
    /// whole length, as the planner's path (the claw moves along with it).
    fn plan_line(&mut self, target: Vector3<f64>, goal: ArmState) -> Result<(), Reason> {
        let stop = self.planner.stopping_position();
        let from_state = state_of(&stop);
        let from = self.arm.forward(&from_state.joints);
        let arm = self.arm;
        let solver = self.solver;
        let numeric = &mut self.numeric;
        let mut seed = from_state.joints;
        let path = straight_line(
            [from.x, from.y, from.z],
            [target.x, target.y, target.z],
            self.motion.line_step_m,
            LINE_MAX_JOINT_STEP_RAD,
            |p| {
                let point = Vector3::new(p[0], p[1], p[2]);
                let q = if (point - target).norm() <= 1e-12 {
                    goal.joints // the end: the goal itself (a substituted point lies on the boundary)
                } else {
                    match (solver.algorithm(), numeric.as_mut()) {
                        (Some(_), Some(n)) => {
                            let sol = n
                                .solve_unrecorded(
                                    solver,
                                    &Target::position(point),
                                    &seed.to_chain(),
                                )
                                .map_err(|error| Reason::Numeric {
                                    solver,
                                    error,
                                    orientation: false,
                                })?;
                            ArmJoints::from_chain(&sol.joints).unwrap_or(seed)
                        }
                        _ => arm.solve_position(&point, seed.base_rad)?,
                    }
                };
                seed = q;
                Ok::<_, Reason>(vec![q.base_rad, q.shoulder_rad, q.elbow_rad])
            },
        )
        .map_err(|e| match &e {
            LineError::Unreachable { .. } | LineError::Jump { .. } | LineError::Path(_) => {
                Reason::Line { why: e.to_string() }
            }
        })?;
        let n = path.len().saturating_sub(1).max(1) as f64;
        let (g0, g1) = (stop[3], goal.gripper_opening);
        let points: Vec<Vec<f64>> = path
            .points()
            .iter()
            .enumerate()
            .map(|(k, q)| {
                let joints = ArmJoints {
                    base_rad: q[0],
                    shoulder_rad: q[1],
                    elbow_rad: q[2],
                };
                actuators(&ArmState {
                    joints,
                    gripper_opening: g0 + (g1 - g0) * k as f64 / n,
                })
                .to_vec()
            })
            .collect();
        // the first point is where the arm stops, to the last bit
        let mut points = points;
        if let Some(first) = points.first_mut() {
            first.copy_from_slice(&stop);
        }
        let path = eezybot_motion::JointPath::new(points)
            .map_err(|e| Reason::Line { why: e.to_string() })?;
        self.planner
            .follow(path)
            .map_err(|e| Reason::Line { why: e.to_string() })
    }

    /// Handle a `gripper_target` (0 closed … 1 open); `stamp` is when it arrived,
    /// since std_msgs/Float64 has no header.
    pub fn handle_gripper_target(
        &mut self,
        opening: f64,
        stamp: Time,
    ) -> Result<Output, Rejection> {
        let result = (|| {
            self.check_estop()?;
            if !(0.0..=1.0).contains(&opening) {
                return Err(KinematicsError::GripperOutOfRange { value: opening }.into());
            }
            Ok(ArmState {
                gripper_opening: opening,
                ..self.goal
            })
        })();
        self.finish(Source::GripperTarget, stamp, stamp, result)
    }

    /// Handle a `joint_target` arriving at `now`: positions (rad) for some or all
    /// actuated joints; the others keep the values of the current goal.
    pub fn handle_joint_target(
        &mut self,
        msg: &JointState,
        now: Time,
    ) -> Result<Output, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            self.check_estop()?;
            self.check_age(stamp, now)?;
            if msg.name.len() != msg.position.len() {
                return Err(Reason::LengthMismatch {
                    names: msg.name.len(),
                    positions: msg.position.len(),
                });
            }
            if msg.name.is_empty() {
                return Err(Reason::NoJoints);
            }
            let mut joints = self.goal.joints;
            let mut gripper_rad = self.goal.gripper_opening * self.gripper_open_rad;
            let mut seen: Vec<&str> = Vec::with_capacity(4);
            for (name, &value) in msg.name.iter().zip(&msg.position) {
                if seen.contains(&name.as_str()) {
                    return Err(Reason::DuplicateJoint { name: name.clone() });
                }
                seen.push(name);
                let joint = match name.as_str() {
                    "base_joint" => Joint::Base,
                    "shoulder_joint" => Joint::Shoulder,
                    "elbow_joint" => Joint::Elbow,
                    "gripper_joint" => Joint::Gripper,
                    _ => return Err(Reason::UnknownJoint { name: name.clone() }),
                };
                if !value.is_finite() {
                    return Err(KinematicsError::NonFiniteJoint { joint, value }.into());
                }
                match joint {
                    Joint::Base => joints.base_rad = value,
                    Joint::Shoulder => joints.shoulder_rad = value,
                    Joint::Elbow => joints.elbow_rad = value,
                    _ => gripper_rad = value,
                }
            }
            self.arm.limits.check(&joints)?;
            if !(0.0..=self.gripper_open_rad).contains(&gripper_rad) {
                return Err(KinematicsError::OutOfLimits {
                    joint: Joint::Gripper,
                    value_rad: gripper_rad,
                    min_rad: 0.0,
                    max_rad: self.gripper_open_rad,
                }
                .into());
            }
            Ok(ArmState {
                joints,
                gripper_opening: gripper_rad / self.gripper_open_rad,
            })
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
        self.last_event_rejected = true;
        let rejection = Rejection {
            source,
            reason,
            stamp,
        };
        self.last_rejection = Some(rejection.clone());
        rejection
    }

    fn check_estop(&self) -> Result<(), Reason> {
        if self.estop {
            Err(Reason::EmergencyStop)
        } else {
            Ok(())
        }
    }

    /// A target stamped longer than `max_target_age` before `now` is refused; a zero
    /// stamp means "now", and a stamp ahead of our clock is not old.
    fn check_age(&self, stamp: Time, now: Time) -> Result<(), Reason> {
        check_age(stamp, now, self.motion.max_target_age_s)
    }

    /// Make a validated goal the planner's (unless the line planner already took it)
    /// and return the first step at once, stamped with the input's stamp (`now` for a
    /// zero stamp); or record the rejection.
    fn finish(
        &mut self,
        source: Source,
        stamp: Time,
        now: Time,
        candidate: Result<ArmState, Reason>,
    ) -> Result<Output, Rejection> {
        self.counters.received += 1;
        let stamp = if stamp == Time::ZERO { now } else { stamp };
        let accepted = candidate.and_then(|goal| {
            self.calibration.servo_angles(&goal)?;
            let line = source == Source::XyzTarget && self.motion.mode == MotionMode::Line;
            if !line {
                self.planner
                    .move_to(&actuators(&goal))
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
            Err(reason) => {
                if reason.code() == "too_old" {
                    self.counters.too_old += 1;
                }
                Err(self.reject(source, stamp, reason))
            }
        }
    }

    /// The next planned step, stamped `now`, while the arm is moving.
    pub fn step(&mut self, now: Time) -> Option<Output> {
        if !self.planner.is_moving() {
            return None;
        }
        self.advance();
        self.counters.steps += 1;
        Some(self.output(now))
    }

    /// One planner step into `state`; a step that would leave the joint limits (a
    /// re-planned motion braking past a corner of the coupled limits) is clamped.
    fn advance(&mut self) {
        if let Some(a) = self.planner.step() {
            let mut next = state_of(&a);
            if self.arm.limits.check(&next.joints).is_err() {
                next.joints = self.arm.limits.clamp(&next.joints);
                log::debug!("a planned step clamped into the joint limits");
            }
            self.state = next;
        }
    }

    fn output(&self, stamp: Time) -> Output {
        // the planner stays within the goal's servo ranges; a clamp keeps it so
        let servos = self
            .calibration
            .servo_angles(&self.state)
            .map(|s| s.rad)
            .unwrap_or_else(|_| self.calibration.clamped_servo_angles(&self.state));
        Output {
            joint_states: self.joint_states(stamp),
            servo_angles: JointState {
                header: Header {
                    stamp,
                    frame_id: String::new(),
                },
                name: ServoId::ALL.iter().map(|s| s.name().to_string()).collect(),
                position: servos.to_vec(),
                velocity: vec![],
                effort: vec![],
            },
        }
    }

    /// `joint_states` for the last good state (every non-fixed URDF joint), with this stamp.
    pub fn joint_states(&self, stamp: Time) -> JointState {
        let joints = self.state.joint_positions(&self.arm.geometry);
        JointState {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            name: joints.iter().map(|(n, _)| (*n).to_string()).collect(),
            position: joints.iter().map(|(_, v)| *v).collect(),
            velocity: vec![],
            effort: vec![],
        }
    }

    /// The node's diagnostics entry: OK, or WARN while the latest input was refused or
    /// the emergency stop is engaged, with the last rejection reason and counters.
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
        let q: &ArmJoints = &self.state.joints;
        let p = self.arm.forward(q);
        let mut values = vec![
            ("received", self.counters.received.to_string()),
            ("accepted", self.counters.accepted.to_string()),
            ("rejected", self.counters.rejected.to_string()),
            ("too_old", self.counters.too_old.to_string()),
            ("superseded", self.counters.superseded.to_string()),
            ("estop", self.estop.to_string()),
            (
                "motion",
                if self.planner.is_moving() {
                    format!("moving ({})", self.motion.mode.name())
                } else {
                    "at rest".to_string()
                },
            ),
            ("motion_mode", self.motion.mode.name().to_string()),
            (
                "max_target_age_s",
                format!("{}", self.motion.max_target_age_s),
            ),
            ("tool0_xyz_m", format!("{:.4} {:.4} {:.4}", p.x, p.y, p.z)),
            (
                "joints_deg",
                format!(
                    "base {:.2} shoulder {:.2} elbow {:.2} gripper_opening {:.3}",
                    q.base_rad.to_degrees(),
                    q.shoulder_rad.to_degrees(),
                    q.elbow_rad.to_degrees(),
                    self.state.gripper_opening
                ),
            ),
        ];
        if let Some(r) = &self.last_rejection {
            values.push((LAST_REJECTION_KEY, r.reason.to_string()));
            values.push(("last_rejection_code", r.reason.code()));
            values.push(("last_rejection_topic", r.source.topic().to_string()));
            // the refusal signal `gui_bridge once/play` wait for
            values.push((REJECTED_STAMP_KEY, stamp_text(r.stamp)));
        }
        let mut more: Vec<(String, String)> = vec![(
            "solver".into(),
            match (&self.numeric, self.solver.algorithm()) {
                (None, Some(_)) => format!(
                    "{} (unusable: {})",
                    self.solver.name(),
                    self.numeric_error
                        .as_ref()
                        .map(|e| e.to_string())
                        .unwrap_or_default()
                ),
                _ => self.solver.name().to_string(),
            },
        )];
        if let Some(n) = &self.numeric {
            if let Some(r) = n.last_solve() {
                more.push(("last_solve".into(), r.describe()));
            }
            // undesirable configurations of the commanded state, each with a way out
            more.extend(n.assess_values(&q.to_chain()));
        }
        more.push((
            "substitute_nearest".into(),
            match self.substitute_max_m {
                Some(m) => format!("on, within {m} m"),
                None => "off".into(),
            },
        ));
        more.push(("substitutions".into(), self.substitutions.to_string()));
        if let Some(t) = &self.last_substitution {
            more.push(("last_substitution".into(), t.clone()));
        }
        if let Some(t) = &self.last_pose {
            more.push(("last_pose_target".into(), t.clone()));
        }
        values.extend(more.iter().map(|(k, v)| (k.as_str(), v.clone())));
        ros_plumbing::diagnostics::status(level, name, "eezybot_arm", &message, &values)
    }
}

/// A target stamped longer than `max_s` before `now` is refused; a zero stamp means
/// "now", a stamp ahead of our clock is not old, and `max_s` ≤ 0 means no limit.
pub fn check_age(stamp: Time, now: Time, max_s: f64) -> Result<(), Reason> {
    if max_s <= 0.0 || stamp == Time::ZERO {
        return Ok(());
    }
    let age_s = (now.to_nanos() - stamp.to_nanos()) as f64 * 1e-9;
    if age_s > max_s {
        return Err(Reason::TooOld { age_s, max_s });
    }
    Ok(())
}

/// A target's `frame_id` must be empty or the base frame.
pub fn check_frame(frame_id: &str, base_frame: &str) -> Result<(), Reason> {
    if frame_id.is_empty() || frame_id == base_frame {
        Ok(())
    } else {
        Err(Reason::WrongFrame {
            frame_id: frame_id.to_string(),
            expected: base_frame.to_string(),
        })
    }
}

/// Relative error of a quaternion's length accepted (and normalized away), so that
/// hand-typed values such as `0.707 0 0 0.707` pass.
pub const QUATERNION_NORM_TOLERANCE: f64 = 0.01;

/// Position and rotation of a pose: the quaternion must be finite and of unit length
/// within [`QUATERNION_NORM_TOLERANCE`] (it is normalized); the position is checked by
/// the solvers.
///
/// # Examples
/// ```
/// use compute_ik::core::pose_parts;
/// use eezybot_msgs::geometry_msgs::{Point, Pose, Quaternion};
/// let pose = Pose { position: Point { x: 0.2, y: 0.0, z: 0.1 },
///                   orientation: Quaternion { x: 0.0, y: 0.0, z: 0.707, w: 0.707 } };
/// let (p, r) = pose_parts(&pose).unwrap();
/// assert!((r.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-12 && p.x == 0.2);
/// let zero = Pose { orientation: Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 0.0 }, ..pose };
/// assert_eq!(pose_parts(&zero).unwrap_err().code(), "bad_orientation");
/// ```
pub fn pose_parts(pose: &Pose) -> Result<(Vector3<f64>, UnitQuaternion<f64>), Reason> {
    let o = pose.orientation;
    let q = Quaternion::new(o.w, o.x, o.y, o.z);
    let norm = q.norm();
    if !(norm.is_finite() && (norm - 1.0).abs() <= QUATERNION_NORM_TOLERANCE) {
        return Err(Reason::BadOrientation {
            quaternion: [o.x, o.y, o.z, o.w],
        });
    }
    let p = pose.position;
    Ok((
        Vector3::new(p.x, p.y, p.z),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// The actuators a state sets, the planner's axes: base θ1, shoulder α, forearm
/// elevation φ (rad) and claw opening.
pub fn actuators(s: &ArmState) -> [f64; 4] {
    [
        s.joints.base_rad,
        s.joints.shoulder_rad,
        s.joints.forearm_elevation_rad(),
        s.gripper_opening,
    ]
}

/// The state whose actuators are `a` (see [`actuators`]).
pub fn state_of(a: &[f64]) -> ArmState {
    ArmState {
        joints: ArmJoints {
            base_rad: a[0],
            shoulder_rad: a[1],
            elbow_rad: a[2] - a[1],
        },
        gripper_opening: a[3],
    }
}

/// The planner's axis limits from the servos' (`config/arm.yaml` `motion`).
pub fn axis_limits(motion: &MotionLimits, cal: &ServoCalibrations) -> Vec<AxisLimits> {
    motion
        .input_limits(cal)
        .iter()
        .map(|&(v, a)| AxisLimits {
            max_velocity: v,
            max_acceleration: a,
        })
        .collect()
}
