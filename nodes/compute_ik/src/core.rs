//! The vocabulary every arm shares, free of ROS I/O: where a target came from
//! ([`Source`]), why one is refused ([`Reason`], [`Rejection`]), the counters, how the
//! arm moves ([`MotionSettings`]) and the checks every target passes ([`check_age`],
//! [`check_frame`], [`check_finite`], [`pose_parts`]). The pipeline that applies them is
//! [`crate::pipeline`]; the arms are [`crate::eezybot`] and [`crate::urdf_arm`].

use crate::numeric::Solver;
use eezybot_kinematics::{KinematicsError, ACTUATED_JOINTS};
use eezybot_msgs::geometry_msgs::Pose;
use eezybot_msgs::Time;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use ros_plumbing::feedback::ReasonCode;
use ros_plumbing::logging::{shorten, NAME_MAX};
use ros_plumbing::topics;
use std::fmt;

/// Which input topic a request came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// `xyz_target`
    XyzTarget,
    /// `xyz_line_target`
    XyzLineTarget,
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
            Source::XyzLineTarget => topics::XYZ_LINE_TARGET.name,
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
    /// compute_ik's `calibrating` is true: the calibration wizard drives the servos.
    Calibrating,
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
    /// Another commander holds the joints (the arbiter's refusal, e.g. the leader arm
    /// while its deadman is held).
    Held {
        /// the arbiter's words
        why: String,
    },
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
            Reason::Calibrating => "calibrating".into(),
            Reason::Held { .. } => "held".into(),
            Reason::TooOld { .. } => "stale".into(),
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

    /// The stable code other nodes read ([`ros_plumbing::feedback`]'s `reason_code`).
    pub fn reason_code(&self) -> ReasonCode {
        match self {
            Reason::Kinematics(e) | Reason::Numeric { error: e, .. } => kinematics_code(e),
            Reason::WrongFrame { .. } => ReasonCode::WrongFrame,
            Reason::UnknownJoint { .. }
            | Reason::UnknownArmJoint { .. }
            | Reason::DuplicateJoint { .. }
            | Reason::LengthMismatch { .. }
            | Reason::NoJoints => ReasonCode::BadJoints,
            Reason::EmergencyStop => ReasonCode::Estop,
            Reason::Calibrating => ReasonCode::Calibrating,
            Reason::Held { .. } => ReasonCode::Held,
            Reason::TooOld { .. } => ReasonCode::Stale,
            Reason::Line { .. } => ReasonCode::LineBlocked,
            Reason::Unreadable { .. } => ReasonCode::Unreadable,
            Reason::BadOrientation { .. } => ReasonCode::BadOrientation,
            Reason::NoGripper => ReasonCode::NoGripper,
            Reason::JointLimit { .. } => ReasonCode::OutOfLimits,
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
            Reason::Calibrating => write!(
                f,
                "the arm is being calibrated: no target is taken until `calibration` is deactivated (controller_manager/switch_controller)"
            ),
            Reason::TooOld { age_s, max_s } => write!(
                f,
                "target stamped {age_s:.3} s ago, older than max_target_age {max_s:.3} s (delayed, or the publisher's clock differs)"
            ),
            Reason::Line { why } => write!(f, "{why}"),
            Reason::Held { why } => write!(f, "{why}"),
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

/// The [`ReasonCode`] of a kinematics error.
fn kinematics_code(e: &KinematicsError) -> ReasonCode {
    match e {
        KinematicsError::TooFar { .. }
        | KinematicsError::TooClose { .. }
        | KinematicsError::IkNotConverged { .. } => ReasonCode::Unreachable,
        KinematicsError::OutOfLimits { .. }
        | KinematicsError::GripperOutOfRange { .. }
        | KinematicsError::ServoOutOfRange { .. } => ReasonCode::OutOfLimits,
        KinematicsError::NonFiniteTarget { .. }
        | KinematicsError::NonFiniteJoint { .. }
        | KinematicsError::NonFiniteValue { .. } => ReasonCode::NotFinite,
        _ => ReasonCode::SolverFailed,
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
    pub stale: u64,
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

/// `max_target_age`'s default (s): the parameter's, and [`MotionSettings::default`]'s.
pub const DEFAULT_MAX_TARGET_AGE_S: f64 = 0.5;

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
            max_target_age_s: DEFAULT_MAX_TARGET_AGE_S,
            line_step_m: 0.002,
        }
    }
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

/// A target position must be finite.
pub fn check_finite(p: &Vector3<f64>) -> Result<(), Reason> {
    for (axis, value) in [("x", p.x), ("y", p.y), ("z", p.z)] {
        if !value.is_finite() {
            return Err(KinematicsError::NonFiniteTarget { axis, value }.into());
        }
    }
    Ok(())
}
