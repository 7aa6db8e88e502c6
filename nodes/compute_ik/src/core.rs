//! The IK node's logic, free of ROS I/O: targets in, joint states and servo angles
//! out, or a rejection with its reason. A rejected input never changes the state.

use eezybot_kinematics::{
    Arm, ArmConfig, ArmJoints, ArmState, Joint, KinematicsError, ServoCalibrations, ServoId,
    ACTUATED_JOINTS,
};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::PointStamped;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use nalgebra::Vector3;
use std::fmt;

/// Which input topic a request came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// `xyz_target`
    XyzTarget,
    /// `gripper_target`
    GripperTarget,
    /// `joint_target`
    JointTarget,
}

impl Source {
    /// The topic name.
    pub fn topic(self) -> &'static str {
        match self {
            Source::XyzTarget => "xyz_target",
            Source::GripperTarget => "gripper_target",
            Source::JointTarget => "joint_target",
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
    /// The sample could not be deserialized.
    Unreadable {
        /// what the middleware said
        error: String,
    },
}

impl Reason {
    /// A short machine-readable code, e.g. `too_far`, `wrong_frame`.
    pub fn code(&self) -> String {
        match self {
            Reason::Kinematics(e) => e.code(),
            Reason::WrongFrame { .. } => "wrong_frame".into(),
            Reason::UnknownJoint { .. } => "unknown_joint".into(),
            Reason::DuplicateJoint { .. } => "duplicate_joint".into(),
            Reason::LengthMismatch { .. } => "length_mismatch".into(),
            Reason::NoJoints => "no_joints".into(),
            Reason::EmergencyStop => "estop".into(),
            Reason::Unreadable { .. } => "unreadable".into(),
        }
    }
}

impl fmt::Display for Reason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Reason::Kinematics(e) => write!(f, "{e}"),
            Reason::WrongFrame { frame_id, expected } => {
                write!(f, "frame_id `{frame_id}` is not `{expected}` (targets must be given in the arm's base frame)")
            }
            Reason::UnknownJoint { name } => {
                write!(
                    f,
                    "unknown joint `{name}` (actuated joints: {})",
                    ACTUATED_JOINTS.join(", ")
                )
            }
            Reason::DuplicateJoint { name } => write!(f, "joint `{name}` named twice"),
            Reason::LengthMismatch { names, positions } => {
                write!(f, "{names} names but {positions} positions")
            }
            Reason::NoJoints => write!(f, "no joint named"),
            Reason::EmergencyStop => write!(
                f,
                "emergency stop engaged: no motion until `estop` is false"
            ),
            Reason::Unreadable { error } => write!(f, "unreadable sample: {error}"),
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

/// What an accepted input produces.
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
}

/// The IK node's state.
#[derive(Clone, Debug)]
pub struct IkCore {
    arm: Arm,
    calibration: ServoCalibrations,
    gripper_open_rad: f64,
    base_frame: String,
    state: ArmState,
    estop: bool,
    counters: Counters,
    last_rejection: Option<Rejection>,
    last_event_rejected: bool,
}

impl IkCore {
    /// A core for this configuration, starting at the home pose with the claw closed.
    pub fn new(config: &ArmConfig, base_frame: &str) -> IkCore {
        IkCore {
            arm: config.arm(),
            calibration: config.servos,
            gripper_open_rad: config.geometry.gripper_open_rad,
            base_frame: base_frame.to_string(),
            state: ArmState::default(),
            estop: false,
            counters: Counters::default(),
            last_rejection: None,
            last_event_rejected: false,
        }
    }

    /// Swap in a new configuration (kept state is re-checked on the next input).
    pub fn set_config(&mut self, config: &ArmConfig) {
        self.arm = config.arm();
        self.calibration = config.servos;
        self.gripper_open_rad = config.geometry.gripper_open_rad;
    }

    /// Change the frame targets must be given in.
    pub fn set_base_frame(&mut self, base_frame: &str) {
        self.base_frame = base_frame.to_string();
    }

    /// The last good state.
    pub fn state(&self) -> &ArmState {
        &self.state
    }

    /// Counters so far.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// The most recent rejection, if any.
    pub fn last_rejection(&self) -> Option<&Rejection> {
        self.last_rejection.as_ref()
    }

    /// Engage or release the emergency stop. While engaged every target is refused.
    pub fn set_estop(&mut self, engaged: bool) {
        self.estop = engaged;
    }

    /// Is the emergency stop engaged?
    pub fn estop(&self) -> bool {
        self.estop
    }

    /// Handle an `xyz_target`.
    pub fn handle_xyz_target(&mut self, msg: &PointStamped) -> Result<Output, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            self.check_estop()?;
            let frame = msg.header.frame_id.as_str();
            if !(frame.is_empty() || frame == self.base_frame) {
                return Err(Reason::WrongFrame {
                    frame_id: frame.to_string(),
                    expected: self.base_frame.clone(),
                });
            }
            let target = Vector3::new(msg.point.x, msg.point.y, msg.point.z);
            let joints = self
                .arm
                .solve_position(&target, self.state.joints.base_rad)?;
            Ok(ArmState {
                joints,
                ..self.state
            })
        })();
        self.finish(Source::XyzTarget, stamp, result)
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
                ..self.state
            })
        })();
        self.finish(Source::GripperTarget, stamp, result)
    }

    /// Handle a `joint_target`: positions (rad) for some or all actuated joints; the
    /// others keep their values.
    pub fn handle_joint_target(&mut self, msg: &JointState) -> Result<Output, Rejection> {
        let stamp = msg.header.stamp;
        let result = (|| {
            self.check_estop()?;
            if msg.name.len() != msg.position.len() {
                return Err(Reason::LengthMismatch {
                    names: msg.name.len(),
                    positions: msg.position.len(),
                });
            }
            if msg.name.is_empty() {
                return Err(Reason::NoJoints);
            }
            let mut joints = self.state.joints;
            let mut gripper_rad = self.state.gripper_opening * self.gripper_open_rad;
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
        self.finish(Source::JointTarget, stamp, result)
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

    /// Turn a candidate state into output (servo ranges checked), or record the rejection.
    fn finish(
        &mut self,
        source: Source,
        stamp: Time,
        candidate: Result<ArmState, Reason>,
    ) -> Result<Output, Rejection> {
        self.counters.received += 1;
        let produced = candidate.and_then(|state| {
            let servos = self.calibration.servo_angles(&state)?;
            Ok((state, servos))
        });
        match produced {
            Ok((state, servos)) => {
                self.state = state;
                self.counters.accepted += 1;
                self.last_event_rejected = false;
                Ok(Output {
                    joint_states: self.joint_states(stamp),
                    servo_angles: JointState {
                        header: Header {
                            stamp,
                            frame_id: String::new(),
                        },
                        name: ServoId::ALL.iter().map(|s| s.name().to_string()).collect(),
                        position: servos.rad.to_vec(),
                        velocity: vec![],
                        effort: vec![],
                    },
                })
            }
            Err(reason) => Err(self.reject(source, stamp, reason)),
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
            ("estop", self.estop.to_string()),
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
            values.push(("last_rejection", r.reason.to_string()));
            values.push(("last_rejection_code", r.reason.code()));
            values.push(("last_rejection_topic", r.source.topic().to_string()));
        }
        ros_plumbing::diagnostics::status(level, name, "eezybot_arm", &message, &values)
    }
}
