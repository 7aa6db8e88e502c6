//! The EezyBotArm Mk2 as an [`ArmModel`]: the closed-form IK (or a numerical solver on
//! its URDF chain), its joint and servo limits, and the servo mapping that makes
//! `servo_angles`. [`IkCore`] is the target pipeline driving it.

use crate::controller::{ControllerMap, GripperMap};
use crate::core::Reason;
use crate::numeric::{describe_pose, NumericIk, Solver};
use crate::pipeline::{joint_state, ArmModel, Cartesian, Pipeline, Solved};
use eezybot_kinematics::ik::Target;
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::{
    Arm, ArmConfig, ArmJoints, ArmState, Joint, KinematicsError, MotionLimits, ServoCalibrations,
    ServoId,
};
use eezybot_motion::AxisLimits;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use ros_plumbing::Params;

/// The EezyBot's URDF (`urdf/eezybot.urdf`), whose chain the numerical solvers drive.
pub const EEZYBOT_URDF: &str = include_str!("../../../urdf/eezybot.urdf");

/// Largest joint difference (rad) by which a numerical solution outside the limits (by
/// rounding in the projection onto them) is moved back inside.
const LIMIT_ROUNDING_RAD: f64 = 1e-9;

/// The target pipeline driving the EezyBot.
pub type IkCore = Pipeline<EezyBot>;

/// The EezyBotArm Mk2: geometry and limits, servo calibration, and the URDF chain the
/// numerical solvers drive.
#[derive(Clone, Debug)]
pub struct EezyBot {
    arm: Arm,
    calibration: ServoCalibrations,
    limits: MotionLimits,
    gripper_open_rad: f64,
    /// the URDF whose chain the numerical solvers drive
    model: Option<RobotModel>,
    /// that chain with this arm's limits (None: the URDF is not the EezyBot's)
    numeric: Option<NumericIk>,
    numeric_error: Option<KinematicsError>,
}

impl Pipeline<EezyBot> {
    /// A core for this configuration, at rest in the home pose with the claw closed,
    /// with the default motion settings and the closed-form solver; the numerical
    /// solvers drive the shipped `urdf/eezybot.urdf`.
    pub fn new(config: &ArmConfig, base_frame: &str) -> IkCore {
        let model = RobotModel::from_urdf_str(EEZYBOT_URDF, "urdf/eezybot.urdf").ok();
        Self::with(EezyBot::new(config, model), base_frame)
    }

    /// As [`IkCore::new`], the numerical solvers driving this EezyBot URDF (its
    /// chain `base_link` → `tool0` with the passive linkage joints, [`Arm::serial_chain`]).
    pub fn with_model(
        config: &ArmConfig,
        base_frame: &str,
        model: RobotModel,
    ) -> Result<IkCore, KinematicsError> {
        let arm = EezyBot::new(config, Some(model));
        match &arm.numeric_error {
            Some(e) => Err(e.clone()),
            None => Ok(Self::with(arm, base_frame)),
        }
    }

    fn with(arm: EezyBot, base_frame: &str) -> IkCore {
        Pipeline::for_arm(arm, base_frame)
            .unwrap_or_else(|_| unreachable!("validated limits and a finite home pose"))
    }

    /// The numerical chain, if the URDF is the EezyBot's.
    pub fn numeric(&self) -> Option<&NumericIk> {
        self.model().numeric.as_ref()
    }
}

impl EezyBot {
    fn new(config: &ArmConfig, model: Option<RobotModel>) -> EezyBot {
        let mut arm = EezyBot {
            arm: config.arm(),
            calibration: config.servos,
            limits: config.motion,
            gripper_open_rad: config.geometry.gripper_open_rad,
            model,
            numeric: None,
            numeric_error: None,
        };
        arm.rebuild_chain();
        arm
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
        if changed {
            self.rebuild_chain();
        }
    }

    /// Joints that put `tool0` at `target` with `solver` (the closed form or a
    /// numerical one on the URDF chain, warm-started from `seed`).
    fn solve_exact(
        &mut self,
        solver: Solver,
        target: &Cartesian,
        seed: &ArmJoints,
    ) -> Result<ArmJoints, Reason> {
        let p = target.position;
        if solver.algorithm().is_none() {
            return Ok(self.arm.solve_position(&p, seed.base_rad)?);
        }
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
        let goal = match target.orientation {
            None => Target::position(p),
            Some(r) => Target::pose_preferred(Isometry3::from_parts(Translation3::from(p), r), 1.0),
        };
        let numeric_error = |error| Reason::Numeric {
            solver,
            error,
            orientation: false,
        };
        let sol = numeric
            .solve(solver, &goal, &seed.to_chain())
            .map_err(numeric_error)?;
        let q = ArmJoints::from_chain(&sol.joints).ok_or(numeric_error(
            KinematicsError::DimensionMismatch {
                what: "solution",
                expected: 3,
                got: sol.joints.len(),
            },
        ))?;
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

    /// A solved goal: these joints, the claw as in `goal`, and the point they reach.
    fn solved(&self, joints: ArmJoints, goal: &ArmState, point: Vector3<f64>) -> Solved<ArmState> {
        Solved {
            state: ArmState { joints, ..*goal },
            target: Target::position(point),
        }
    }
}

impl ArmModel for EezyBot {
    type State = ArmState;

    fn describe(&self) -> String {
        "the EezyBotArm Mk2 (base_link -> tool0; servo_angles for serial_node)".into()
    }

    fn has_servos(&self) -> bool {
        true
    }

    fn start(&self) -> ArmState {
        ArmState::default()
    }

    fn axes(&self, s: &ArmState) -> Vec<f64> {
        actuators(s).to_vec()
    }

    /// A step that would leave the joint limits (a re-planned motion braking past a
    /// corner of the coupled limits) is clamped.
    fn planned(&self, axes: &[f64]) -> ArmState {
        let mut next = state_of(axes);
        if self.arm.limits.check(&next.joints).is_err() {
            next.joints = self.arm.limits.clamp(&next.joints);
            log::debug!("a planned step clamped into the joint limits");
        }
        next
    }

    fn axis_limits(&self) -> Vec<AxisLimits> {
        axis_limits(&self.limits, &self.calibration)
    }

    fn apply_params(&mut self, params: &Params) -> bool {
        // loaded when it was set, off the loop ([`crate::load_arm_config`]); a store
        // without the loader (a test's) loads it here
        match params.loaded::<ArmConfig>("arm_config") {
            Some(config) => self.set_config(&config),
            None => {
                match ArmConfig::load_or_shipped(&params.string("arm_config").unwrap_or_default()) {
                    Ok(config) => self.set_config(&config),
                    Err(e) => log::error!("keeping the previous arm configuration: {e}"),
                }
            }
        }
        true
    }

    fn solve(
        &mut self,
        solver: Solver,
        target: &Cartesian,
        goal: &ArmState,
    ) -> Result<Solved<ArmState>, Reason> {
        let q = self.solve_exact(solver, target, &goal.joints)?;
        Ok(self.solved(q, goal, target.position))
    }

    fn nearest(&mut self, target: &Cartesian, goal: &ArmState) -> Option<(Solved<ArmState>, f64)> {
        let near = self
            .numeric
            .as_mut()?
            .nearest(&target.position, &goal.joints.to_chain())
            .ok()?;
        let q = self
            .inside_limits(ArmJoints::from_chain(&near.joints)?)
            .ok()?;
        let p = self.arm.forward(&q);
        Some((self.solved(q, goal, p), near.distance_m))
    }

    fn joint_goal(
        &self,
        names: &[String],
        positions: &[f64],
        goal: &ArmState,
    ) -> Result<ArmState, Reason> {
        let mut joints = goal.joints;
        let mut gripper_rad = goal.gripper_opening * self.gripper_open_rad;
        for (name, &value) in names.iter().zip(positions) {
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
    }

    fn gripper_goal(&self, opening: f64, goal: &ArmState) -> Result<ArmState, Reason> {
        if !(0.0..=1.0).contains(&opening) {
            return Err(KinematicsError::GripperOutOfRange { value: opening }.into());
        }
        Ok(ArmState {
            gripper_opening: opening,
            ..*goal
        })
    }

    fn check_goal(&self, goal: &ArmState) -> Result<(), Reason> {
        self.calibration.servo_angles(goal)?;
        Ok(())
    }

    /// `tool0` in `base_link` (from the URDF chain when there is one).
    fn tool_pose(&self, s: &ArmState) -> Isometry3<f64> {
        let q = &s.joints;
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

    fn tool_position(&self, s: &ArmState) -> Vector3<f64> {
        self.arm.forward(&s.joints)
    }

    /// The EezyBot has three joints: its claw stays level and faces along the base
    /// angle, so its orientation follows from the position (solved position first).
    fn pose_note(&self, goal: &ArmState, asked: &UnitQuaternion<f64>) -> (f64, String) {
        let taken = self.tool_pose(goal);
        let off_deg = taken.rotation.angle_to(asked).to_degrees();
        let text = format!(
            "position first: the orientation taken is {off_deg:.2}° from the one asked (this arm's claw stays level, facing along the base angle); tool0 at {}",
            describe_pose(&taken)
        );
        (off_deg, text)
    }

    fn line_joints(&self, s: &ArmState) -> Vec<f64> {
        s.joints.to_chain().to_vec()
    }

    fn line_point(
        &mut self,
        solver: Solver,
        target: &Target,
        seed: &[f64],
        end: Option<&ArmState>,
    ) -> Result<Vec<f64>, Reason> {
        let seed = ArmJoints::from_chain(seed).unwrap_or(ArmJoints::HOME);
        let q = match (end, solver.algorithm(), self.numeric.as_mut()) {
            (Some(goal), ..) => goal.joints,
            (None, Some(_), Some(n)) => {
                let point = Target::position(target.pose.translation.vector);
                let sol = n
                    .solve_unrecorded(solver, &point, &seed.to_chain())
                    .map_err(|error| Reason::Numeric {
                        solver,
                        error,
                        orientation: false,
                    })?;
                ArmJoints::from_chain(&sol.joints).unwrap_or(seed)
            }
            _ => self
                .arm
                .solve_position(&target.pose.translation.vector, seed.base_rad)?,
        };
        Ok(q.to_chain().to_vec())
    }

    /// The claw moves along with the line.
    fn line_axes(&self, joints: &[f64], goal: &ArmState, stop: &[f64], fraction: f64) -> Vec<f64> {
        let (g0, g1) = (stop[3], goal.gripper_opening);
        let joints = ArmJoints::from_chain(joints).unwrap_or(goal.joints);
        self.axes(&ArmState {
            joints,
            gripper_opening: g0 + (g1 - g0) * fraction,
        })
    }

    fn line_goal(&self, goal: ArmState, _end: &[f64]) -> ArmState {
        goal
    }

    fn joint_states(&self, s: &ArmState, stamp: Time) -> JointState {
        joint_state(stamp, s.joint_positions(&self.arm.geometry))
    }

    /// The planner stays within the goal's servo ranges; a clamp keeps it so.
    fn servo_angles(&self, s: &ArmState, stamp: Time) -> Option<JointState> {
        let servos = self
            .calibration
            .servo_angles(s)
            .map(|a| a.rad)
            .unwrap_or_else(|_| self.calibration.clamped_servo_angles(s));
        Some(joint_state(
            stamp,
            ServoId::ALL.iter().map(|id| id.name()).zip(servos),
        ))
    }

    fn hardware_id(&self) -> String {
        "eezybot_arm".into()
    }

    fn state_values(&self, s: &ArmState) -> Vec<(String, String)> {
        let q = &s.joints;
        let p = self.arm.forward(q);
        vec![
            (
                "tool0_xyz_m".into(),
                format!("{:.4} {:.4} {:.4}", p.x, p.y, p.z),
            ),
            (
                "joints_deg".into(),
                format!(
                    "base {:.2} shoulder {:.2} elbow {:.2} gripper_opening {:.3}",
                    q.base_rad.to_degrees(),
                    q.shoulder_rad.to_degrees(),
                    q.elbow_rad.to_degrees(),
                    s.gripper_opening
                ),
            ),
        ]
    }

    fn solver_text(&self, solver: Solver) -> String {
        match (&self.numeric, solver.algorithm()) {
            (None, Some(_)) => format!(
                "{} (unusable: {})",
                solver.name(),
                self.numeric_error
                    .as_ref()
                    .map(|e| e.to_string())
                    .unwrap_or_default()
            ),
            _ => solver.name().to_string(),
        }
    }

    fn numeric(&self) -> Option<&NumericIk> {
        self.numeric.as_ref()
    }

    fn numeric_mut(&mut self) -> Option<&mut NumericIk> {
        self.numeric.as_mut()
    }

    fn chain_variables(&self, s: &ArmState) -> Vec<f64> {
        s.joints.to_chain().to_vec()
    }

    /// base, shoulder and elbow on the base, shoulder and forearm-elevation axes (the
    /// elbow servo sets shoulder + elbow); the claw's joint on the opening.
    fn controller_map(&self) -> Option<ControllerMap> {
        Some(ControllerMap {
            joints: ["base_joint", "shoulder_joint", "elbow_joint"]
                .map(String::from)
                .to_vec(),
            axes: vec![0, 1, 2],
            axis_names: vec![
                "the base servo (base_joint, through the 2:1 gear)".into(),
                "the shoulder servo (shoulder_joint)".into(),
                "the elbow servo (the forearm's elevation, shoulder_joint + elbow_joint)".into(),
            ],
            to_axes: nalgebra::DMatrix::from_row_slice(
                3,
                3,
                &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0],
            ),
            gripper: Some(GripperMap {
                joint: "gripper_joint".into(),
                axis: 3,
                rad_per_unit: self.gripper_open_rad,
            }),
        })
    }

    fn reported_axes(&self, servo_state: &JointState) -> Option<Vec<f64>> {
        let mut rad = [0.0; 4];
        for (i, id) in ServoId::ALL.iter().enumerate() {
            let k = servo_state.name.iter().position(|n| n == id.name())?;
            rad[i] = *servo_state.position.get(k).filter(|v| v.is_finite())?;
        }
        Some(actuators(&self.calibration.state_of_angles(rad)).to_vec())
    }
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
