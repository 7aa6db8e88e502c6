//! Why a pose, a target or a servo command was refused.

use std::fmt;

/// A constrained quantity of the arm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Joint {
    /// `base_joint`
    Base,
    /// `shoulder_joint`
    Shoulder,
    /// `elbow_joint`
    Elbow,
    /// φ = shoulder + elbow, the forearm's absolute elevation (derived)
    ForearmElevation,
    /// `gripper_joint`
    Gripper,
}

impl Joint {
    /// The name used on `joint_states` (or a descriptive name for derived quantities).
    pub fn name(self) -> &'static str {
        match self {
            Joint::Base => "base_joint",
            Joint::Shoulder => "shoulder_joint",
            Joint::Elbow => "elbow_joint",
            Joint::ForearmElevation => "forearm_elevation",
            Joint::Gripper => "gripper_joint",
        }
    }
}

impl fmt::Display for Joint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Why the kinematics refused a target or a pose. The state of the caller is
/// never changed by a refused request.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum KinematicsError {
    /// A target coordinate is NaN or infinite.
    #[error("target {axis} is {value}, not a finite number")]
    NonFiniteTarget {
        /// `x`, `y` or `z`
        axis: &'static str,
        /// the offending value
        value: f64,
    },
    /// A joint value is NaN or infinite.
    #[error("{joint} is {value}, not a finite number")]
    NonFiniteJoint {
        /// which joint
        joint: Joint,
        /// the offending value
        value: f64,
    },
    /// The wrist would have to be farther from the shoulder than the links reach.
    #[error(
        "out of reach: wrist {distance_m:.4} m from the shoulder, links reach at most {max_m:.4} m"
    )]
    TooFar {
        /// shoulder → wrist distance needed (m)
        distance_m: f64,
        /// L2 + L3 (m)
        max_m: f64,
    },
    /// The wrist would have to be closer to the shoulder than the links fold.
    #[error("out of reach: wrist {distance_m:.4} m from the shoulder, links fold to at least {min_m:.4} m")]
    TooClose {
        /// shoulder → wrist distance needed (m)
        distance_m: f64,
        /// |L2 − L3| (m)
        min_m: f64,
    },
    /// A joint (or the forearm elevation) would leave its limits.
    #[error("{joint} would be {:.2}°, outside its limits {:.2}° … {:.2}°",
            value_rad.to_degrees(), min_rad.to_degrees(), max_rad.to_degrees())]
    OutOfLimits {
        /// which joint
        joint: Joint,
        /// the value it would need (rad)
        value_rad: f64,
        /// lower limit (rad)
        min_rad: f64,
        /// upper limit (rad)
        max_rad: f64,
    },
    /// The claw opening is outside 0 … 1.
    #[error("gripper opening {value} outside 0.0 (closed) … 1.0 (open)")]
    GripperOutOfRange {
        /// the offending value
        value: f64,
    },
    /// The calibration maps a joint value outside the servo's allowed range.
    #[error("{servo} servo would be at {angle_deg:.2}°, outside its calibrated range {min_deg:.2}° … {max_deg:.2}°")]
    ServoOutOfRange {
        /// which servo
        servo: &'static str,
        /// the angle it would need (deg)
        angle_deg: f64,
        /// lower bound (deg)
        min_deg: f64,
        /// upper bound (deg)
        max_deg: f64,
    },
    /// A link named for a chain is not in the robot model.
    #[error("link `{link}` is not in the robot model")]
    UnknownLink {
        /// the missing link
        link: String,
    },
    /// The tip link of a chain does not hang below its base link.
    #[error("link `{tip}` is not below `{base}`: no serial chain between them")]
    NotAChain {
        /// the chain's base link
        base: String,
        /// the chain's tip link
        tip: String,
    },
    /// A joint named for a chain is not usable as asked.
    #[error("joint `{joint}`: {why}")]
    BadChainJoint {
        /// the joint
        joint: String,
        /// what is wrong with it
        why: &'static str,
    },
    /// Lower above upper, or NaN, in limits or a constraint.
    #[error("`{name}` has limits {lower} … {upper}: lower must not exceed upper, and neither may be NaN")]
    InvalidLimits {
        /// the joint or constraint
        name: String,
        /// lower bound
        lower: f64,
        /// upper bound
        upper: f64,
    },
    /// A vector has the wrong number of entries.
    #[error("{what} has {got} entries, the chain needs {expected}")]
    DimensionMismatch {
        /// which input
        what: &'static str,
        /// entries needed
        expected: usize,
        /// entries given
        got: usize,
    },
    /// An entry of a joint vector or of a target is NaN or infinite.
    #[error("{what}[{index}] is {value}, not a finite number")]
    NonFiniteValue {
        /// which input
        what: &'static str,
        /// position in it
        index: usize,
        /// the offending value
        value: f64,
    },
    /// A numerical IK solver did not reach the target within its tolerances and budget.
    #[error("IK did not converge: best residual {position_error_m:.3e} m, {orientation_error_rad:.3e} rad after {iterations} iterations in {attempts} attempt(s)")]
    IkNotConverged {
        /// position residual of the best attempt (m)
        position_error_m: f64,
        /// orientation residual of the best attempt (rad)
        orientation_error_rad: f64,
        /// iterations over all attempts
        iterations: usize,
        /// attempts (the seed plus random restarts)
        attempts: usize,
    },
}

impl KinematicsError {
    /// A short machine-readable reason, e.g. `out_of_limits:shoulder_joint`, for
    /// diagnostics key/values and tests.
    pub fn code(&self) -> String {
        match self {
            KinematicsError::NonFiniteTarget { .. } => "non_finite_target".into(),
            KinematicsError::NonFiniteJoint { joint, .. } => format!("non_finite_joint:{joint}"),
            KinematicsError::TooFar { .. } => "too_far".into(),
            KinematicsError::TooClose { .. } => "too_close".into(),
            KinematicsError::OutOfLimits { joint, .. } => format!("out_of_limits:{joint}"),
            KinematicsError::GripperOutOfRange { .. } => "gripper_out_of_range".into(),
            KinematicsError::ServoOutOfRange { servo, .. } => format!("servo_out_of_range:{servo}"),
            KinematicsError::UnknownLink { .. } => "unknown_link".into(),
            KinematicsError::NotAChain { .. } => "not_a_chain".into(),
            KinematicsError::BadChainJoint { joint, .. } => format!("bad_chain_joint:{joint}"),
            KinematicsError::InvalidLimits { name, .. } => format!("invalid_limits:{name}"),
            KinematicsError::DimensionMismatch { what, .. } => format!("dimension_mismatch:{what}"),
            KinematicsError::NonFiniteValue { what, .. } => format!("non_finite:{what}"),
            KinematicsError::IkNotConverged { .. } => "ik_not_converged".into(),
        }
    }
}
