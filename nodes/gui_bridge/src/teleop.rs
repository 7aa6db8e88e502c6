//! Operator input as a state machine: UI events → [`Event`] → [`Teleop::handle_event`]
//! → the targets to publish. No I/O: the web server, the keyboard, the gamepad and the
//! command line all feed it the same events.

use eezybot_kinematics::urdf::{JointKind, RobotModel};
use eezybot_kinematics::{Arm, ArmJoints, KinematicsError, ACTUATED_JOINTS};
use eezybot_msgs::geometry_msgs::PointStamped;
use nalgebra::Vector3;
use ros_plumbing::logging::{shorten, NAME_MAX};
use ros_plumbing::topics::{self, Topic};
use std::f64::consts::PI;
use std::time::{Duration, Instant};

/// One slider of the joint mode (`{"name", "lower", "upper"}` to the page).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct JointSlider {
    /// The joint's name on `joint_target`.
    pub name: String,
    /// Lowest value (rad or m).
    pub lower: f64,
    /// Highest value (rad or m).
    pub upper: f64,
}

/// The arm the panel drives, from `robot_description` (to the page as
/// `{"name", "eezybot", "joints", "reach", "tool_link"}`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RobotView {
    /// The URDF's robot name.
    pub name: String,
    /// The EezyBot (its closed form checks Cartesian targets; its claw has a slider).
    pub eezybot: bool,
    /// The joint mode's sliders.
    pub joints: Vec<JointSlider>,
    /// A generous reach (m): the sum of the joint offsets from the root, for the
    /// Cartesian sliders' range and the live view's scale.
    #[serde(rename = "reach")]
    pub reach_m: f64,
    /// The link a Cartesian target places, when the URDF has one end (else none).
    pub tool_link: Option<String>,
}

impl RobotView {
    /// The panel's view of a URDF: for the EezyBot (its chain builds with `arm`'s
    /// passive linkage joints) the three actuated arm joints within `arm`'s limits, as
    /// without a URDF; for any other arm every movable joint that is not a mimic, within
    /// its URDF limits (a continuous joint: −π … π).
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{Arm, urdf::RobotModel};
    /// use gui_bridge::teleop::RobotView;
    /// let jaco = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/jaco.urdf"))).unwrap();
    /// let v = RobotView::of(&jaco, &Arm::default());
    /// assert!(!v.eezybot && v.joints.len() == 6 && v.joints[0].name == "jaco_joint_1");
    /// let eezybot = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/eezybot.urdf"))).unwrap();
    /// let v = RobotView::of(&eezybot, &Arm::default());
    /// assert!(v.eezybot);
    /// assert_eq!(v.joints.iter().map(|j| j.name.as_str()).collect::<Vec<_>>(),
    ///            ["base_joint", "shoulder_joint", "elbow_joint"]);
    /// ```
    pub fn of(model: &RobotModel, arm: &Arm) -> RobotView {
        let eezybot = arm.serial_chain(model).is_ok();
        let joints = if eezybot {
            eezybot_sliders(arm)
        } else {
            model
                .independent_joints()
                .map(|j| {
                    let (lower, upper) = match &j.kind {
                        JointKind::Revolute { limits, .. }
                        | JointKind::Prismatic { limits, .. } => *limits,
                        _ => (-PI, PI),
                    };
                    JointSlider {
                        name: j.name.clone(),
                        lower,
                        upper,
                    }
                })
                .collect()
        };
        let reach_m = model
            .joints
            .iter()
            .map(|j| j.origin.translation.vector.norm())
            .sum::<f64>()
            .max(0.05);
        let tool_link = match model.leaf_links().as_slice() {
            [one] => Some(one.to_string()),
            _ => None,
        };
        RobotView {
            name: model.name.clone(),
            eezybot,
            joints,
            reach_m,
            tool_link,
        }
    }
}

/// The EezyBot's joint sliders: base, shoulder, elbow within the arm's limits.
fn eezybot_sliders(arm: &Arm) -> Vec<JointSlider> {
    let l = arm.limits;
    [
        (ACTUATED_JOINTS[0], l.base_rad),
        (ACTUATED_JOINTS[1], l.shoulder_rad),
        (ACTUATED_JOINTS[2], l.elbow_rad),
    ]
    .iter()
    .map(|(name, (lower, upper))| JointSlider {
        name: (*name).to_string(),
        lower: *lower,
        upper: *upper,
    })
    .collect()
}

/// Something the operator did.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// Move `tool0` to a point (m, `base_link`).
    SetTarget {
        /// the point
        xyz: [f64; 3],
        /// on a straight line (a program's line move), else as compute_ik's `motion`
        /// says ([`Command::Target`])
        line: bool,
    },
    /// Move `tool0` by a step (m) from the current target (keyboard jog, gamepad).
    Jog {
        /// the step
        dxyz: [f64; 3],
    },
    /// Claw opening, 0 closed … 1 open.
    Gripper {
        /// opening
        opening: f64,
    },
    /// Joint mode: positions (rad) of some actuated joints.
    Joints {
        /// (name, position)
        positions: Vec<(String, f64)>,
    },
    /// Engage or release the emergency stop.
    Estop {
        /// engaged?
        engaged: bool,
    },
}

/// Something to publish.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// On `xyz_target` (moved as compute_ik's `motion` says: `joint` unless started
    /// otherwise), or with `line` on `xyz_line_target` (the tool on a straight line).
    Target {
        /// the point (m, `base_link`)
        xyz: [f64; 3],
        /// on `xyz_line_target`
        line: bool,
    },
    /// On `gripper_target`.
    Gripper(f64),
    /// On `joint_target`.
    Joints(Vec<(String, f64)>),
    /// On `estop`.
    Estop(bool),
}

/// The topic of an xyz target: `xyz_line_target` for a straight line, else `xyz_target`.
pub fn xyz_topic(line: bool) -> &'static Topic<PointStamped> {
    if line {
        &topics::XYZ_LINE_TARGET
    } else {
        &topics::XYZ_TARGET
    }
}

/// Why an event sends nothing.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Refusal {
    /// The target is not reachable (the same check compute_ik makes).
    #[error("{0}")]
    Unreachable(KinematicsError),
    /// A value is not a finite number or is out of its range.
    #[error("{0}")]
    BadValue(String),
    /// A joint target that names no joint.
    #[error("joint target names no joint (this arm's: {})", known.join(", "))]
    NoJoints {
        /// the joints a target may name
        known: Vec<String>,
    },
    /// A joint target names a joint this arm has not (or that takes no target).
    #[error("unknown joint `{name}` (this arm's: {})", known.join(", "))]
    UnknownJoint {
        /// the name given (cut to [`NAME_MAX`] characters)
        name: String,
        /// the joints a target may name
        known: Vec<String>,
    },
    /// A joint target names a joint twice.
    #[error("joint `{name}` given twice")]
    DuplicateJoint {
        /// the joint (cut to [`NAME_MAX`] characters)
        name: String,
    },
    /// A joint position is NaN, infinite or outside the joint's limits.
    #[error("{joint} = {value:?} is outside its limits {lower:?} … {upper:?}")]
    JointOutOfLimits {
        /// the joint
        joint: String,
        /// the value given (rad, or m for a prismatic joint)
        value: f64,
        /// lowest value
        lower: f64,
        /// highest value
        upper: f64,
    },
}

impl Refusal {
    /// What kind of refusal, for diagnostics and log throttling: `unreachable`,
    /// `bad_value` or `bad_joint_target`.
    pub fn kind(&self) -> &'static str {
        match self {
            Refusal::Unreachable(_) => "unreachable",
            Refusal::BadValue(_) => "bad_value",
            Refusal::NoJoints { .. }
            | Refusal::UnknownJoint { .. }
            | Refusal::DuplicateJoint { .. }
            | Refusal::JointOutOfLimits { .. } => "bad_joint_target",
        }
    }
}

/// Check a joint target against the joints it may name and their limits, before
/// anything is sent: at least one joint, each known and named once, each position a
/// finite number within its limits (inclusive). The first problem is the refusal.
///
/// # Examples
/// ```
/// use gui_bridge::teleop::{check_joint_positions, JointSlider, Refusal};
/// let limits = [JointSlider { name: "gripper_joint".into(), lower: 0.0, upper: 0.6 }];
/// assert!(check_joint_positions(&[("gripper_joint".into(), 0.3)], &limits).is_ok());
/// let e = check_joint_positions(&[("gripper_joint".into(), 1e300)], &limits).unwrap_err();
/// assert_eq!(e.to_string(), "gripper_joint = 1e300 is outside its limits 0.0 … 0.6");
/// assert!(matches!(check_joint_positions(&[], &limits), Err(Refusal::NoJoints { .. })));
/// ```
pub fn check_joint_positions(
    positions: &[(String, f64)],
    limits: &[JointSlider],
) -> Result<(), Refusal> {
    let known = || limits.iter().map(|j| j.name.clone()).collect::<Vec<_>>();
    if positions.is_empty() {
        return Err(Refusal::NoJoints { known: known() });
    }
    for (i, (name, value)) in positions.iter().enumerate() {
        let Some(j) = limits.iter().find(|j| &j.name == name) else {
            return Err(Refusal::UnknownJoint {
                name: shorten(name, NAME_MAX).into_owned(),
                known: known(),
            });
        };
        if positions[..i].iter().any(|(n, _)| n == name) {
            return Err(Refusal::DuplicateJoint {
                name: shorten(name, NAME_MAX).into_owned(),
            });
        }
        // NaN fails both comparisons: refused as well
        if !(value.is_finite() && *value >= j.lower && *value <= j.upper) {
            return Err(Refusal::JointOutOfLimits {
                joint: name.clone(),
                value: *value,
                lower: j.lower,
                upper: j.upper,
            });
        }
    }
    Ok(())
}

/// What the operator sees after an event.
#[derive(Clone, Debug, PartialEq)]
pub struct Feedback {
    /// The cartesian target now (m).
    pub target: [f64; 3],
    /// The joints that reach it.
    pub joints: ArmJoints,
}

/// Latest-wins rate limiting per output: at most one message per `min_interval`.
#[derive(Clone, Debug)]
struct Slot<T> {
    pending: Option<T>,
    last_sent: Option<Instant>,
}

impl<T> Default for Slot<T> {
    fn default() -> Self {
        Slot {
            pending: None,
            last_sent: None,
        }
    }
}

impl<T> Slot<T> {
    fn due(&self, now: Instant, min_interval: Duration) -> Option<Instant> {
        self.pending.as_ref()?;
        Some(
            self.last_sent
                .map(|t| (t + min_interval).max(now))
                .unwrap_or(now),
        )
    }
    fn take(&mut self, now: Instant, min_interval: Duration) -> Option<T> {
        if self.due(now, min_interval)? <= now {
            self.last_sent = Some(now);
            self.pending.take()
        } else {
            None
        }
    }
}

/// The teleoperation state.
#[derive(Clone, Debug)]
pub struct Teleop {
    arm: Arm,
    target: Vector3<f64>,
    joints: ArmJoints,
    min_interval: Duration,
    /// the point, and whether on a straight line
    xyz: Slot<([f64; 3], bool)>,
    gripper: Slot<f64>,
    joint_target: Slot<Vec<(String, f64)>>,
    estop: Option<bool>,
    robot: Option<RobotView>,
}

impl Teleop {
    /// A state starting at the home pose, publishing each output at most `rate_hz` times a second.
    pub fn new(arm: Arm, rate_hz: f64) -> Teleop {
        let joints = ArmJoints::HOME;
        Teleop {
            target: arm.forward(&joints),
            arm,
            joints,
            min_interval: Duration::from_secs_f64(1.0 / rate_hz.max(0.1)),
            xyz: Slot::default(),
            gripper: Slot::default(),
            joint_target: Slot::default(),
            estop: None,
            robot: None,
        }
    }

    /// The arm `robot_description` describes: joint mode and checks follow it.
    pub fn set_robot(&mut self, model: &RobotModel) -> &RobotView {
        self.robot.insert(RobotView::of(model, &self.arm))
    }

    /// The arm from `robot_description`, if one arrived.
    pub fn robot(&self) -> Option<&RobotView> {
        self.robot.as_ref()
    }

    /// Whether the arm is the EezyBot (also before any `robot_description`).
    pub fn is_eezybot(&self) -> bool {
        self.robot.as_ref().is_none_or(|r| r.eezybot)
    }

    /// The joint mode's sliders: the URDF's joints, or the EezyBot's before any URDF.
    pub fn joint_sliders(&self) -> Vec<JointSlider> {
        match &self.robot {
            Some(r) => r.joints.clone(),
            None => eezybot_sliders(&self.arm),
        }
    }

    /// The joints a `joint_target` may name, within their limits: the joint sliders,
    /// and for the EezyBot its claw too (`gripper_joint`, 0 closed … `gripper_open_rad`
    /// open, as compute_ik takes it).
    pub fn joint_target_limits(&self) -> Vec<JointSlider> {
        let mut limits = self.joint_sliders();
        if self.is_eezybot() {
            limits.push(JointSlider {
                name: ACTUATED_JOINTS[3].to_string(),
                lower: 0.0,
                upper: self.arm.geometry.gripper_open_rad,
            });
        }
        limits
    }

    /// Change the publish rate limit.
    pub fn set_rate(&mut self, rate_hz: f64) {
        self.min_interval = Duration::from_secs_f64(1.0 / rate_hz.max(0.1));
    }

    /// The current cartesian target.
    pub fn target(&self) -> [f64; 3] {
        [self.target.x, self.target.y, self.target.z]
    }

    /// The arm model used for the checks.
    pub fn arm(&self) -> &Arm {
        &self.arm
    }

    /// The arm moved (from `joint_states`): jogs continue from where it is.
    pub fn observe_joints(&mut self, joints: ArmJoints) {
        self.joints = joints;
        if self.xyz.pending.is_none() {
            self.target = self.arm.forward(&joints);
        }
    }

    /// Would `xyz` be reachable? The check compute_ik makes, without sending anything.
    pub fn check(&self, xyz: [f64; 3]) -> Result<ArmJoints, Refusal> {
        self.arm
            .solve_position(&Vector3::from(xyz), self.joints.base_rad)
            .map_err(Refusal::Unreachable)
    }

    /// Apply an operator event. A refused event changes nothing and sends nothing.
    pub fn handle_event(&mut self, event: Event) -> Result<Feedback, Refusal> {
        match event {
            Event::SetTarget { xyz, line } => self.move_to(xyz, line),
            Event::Jog { dxyz } => {
                if dxyz.iter().any(|d| !d.is_finite() || d.abs() > 0.05) {
                    return Err(Refusal::BadValue(format!(
                        "jog step {dxyz:?} is not a number within ±0.05 m"
                    )));
                }
                let t = self.target();
                self.move_to([t[0] + dxyz[0], t[1] + dxyz[1], t[2] + dxyz[2]], false)
            }
            Event::Gripper { opening } => {
                if !(0.0..=1.0).contains(&opening) {
                    return Err(Refusal::BadValue(format!(
                        "gripper opening {opening} outside 0 … 1"
                    )));
                }
                self.gripper.pending = Some(opening);
                Ok(self.feedback())
            }
            Event::Joints { positions } => {
                check_joint_positions(&positions, &self.joint_target_limits())?;
                if self.is_eezybot() {
                    // each joint within its own limits (checked above); the forearm
                    // elevation (shoulder + elbow) within its limits as well
                    let mut q = self.joints;
                    for (name, value) in &positions {
                        match name.as_str() {
                            "base_joint" => q.base_rad = *value,
                            "shoulder_joint" => q.shoulder_rad = *value,
                            "elbow_joint" => q.elbow_rad = *value,
                            _ => {} // gripper_joint: compute_ik applies it
                        }
                    }
                    self.arm.limits.check(&q).map_err(Refusal::Unreachable)?;
                    self.joints = q;
                    self.target = self.arm.forward(&q);
                }
                self.xyz.pending = None;
                self.joint_target.pending = Some(positions);
                Ok(self.feedback())
            }
            Event::Estop { engaged } => {
                self.estop = Some(engaged);
                Ok(self.feedback())
            }
        }
    }

    fn move_to(&mut self, xyz: [f64; 3], line: bool) -> Result<Feedback, Refusal> {
        let joints = if self.is_eezybot() {
            self.check(xyz)?
        } else {
            // no closed form here: compute_ik is the judge (its refusal shows on the page)
            if xyz.iter().any(|v| !v.is_finite()) {
                return Err(Refusal::BadValue(format!("target {xyz:?} is not finite")));
            }
            self.joints
        };
        self.target = Vector3::from(xyz);
        self.joints = joints;
        self.joint_target.pending = None;
        self.xyz.pending = Some((xyz, line));
        Ok(self.feedback())
    }

    fn feedback(&self) -> Feedback {
        Feedback {
            target: self.target(),
            joints: self.joints,
        }
    }

    /// When the next pending output may go out (None: nothing pending).
    pub fn next_due(&self, now: Instant) -> Option<Instant> {
        if self.estop.is_some() {
            return Some(now);
        }
        [
            self.xyz.due(now, self.min_interval),
            self.gripper.due(now, self.min_interval),
            self.joint_target.due(now, self.min_interval),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// The outputs due now (latest wins; the e-stop is never delayed).
    pub fn take_due(&mut self, now: Instant) -> Vec<Command> {
        let mut out = vec![];
        if let Some(e) = self.estop.take() {
            out.push(Command::Estop(e));
        }
        if let Some((xyz, line)) = self.xyz.take(now, self.min_interval) {
            out.push(Command::Target { xyz, line });
        }
        if let Some(g) = self.gripper.take(now, self.min_interval) {
            out.push(Command::Gripper(g));
        }
        if let Some(j) = self.joint_target.take(now, self.min_interval) {
            out.push(Command::Joints(j));
        }
        out
    }
}
