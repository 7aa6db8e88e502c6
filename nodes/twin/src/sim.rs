//! The twin in MuJoCo: the model of [`twin_model`], stepped with the servos' torques.
//!
//! Time is the simulation's own ([`Sim::time`]): nothing here reads a clock, so a test
//! steps it as fast as it can and judges it by simulated seconds.

use std::sync::Arc;

use eezybot_kinematics::{ArmConfig, ArmJoints, PassiveJoints};
use mujoco_rs::prelude::*;
use nalgebra::{Point3, UnitQuaternion, Vector3};
use twin_model::{Scene, Servo, TwinModel};

/// Why the twin stopped or could not start.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The model could not be made.
    #[error("{0}")]
    Model(#[from] twin_model::TwinModelError),
    /// MuJoCo refused the generated model.
    #[error("MuJoCo could not load the twin's model: {0}")]
    Load(String),
    /// The generated model lacks something the twin reads.
    #[error("the twin's model has no {0}")]
    Missing(String),
    /// The simulation blew up: it is stopped rather than report made-up angles.
    #[error("the simulation went unstable at t = {time:.3} s: {reason}")]
    Unstable {
        /// Simulated time (s).
        time: f64,
        /// What was seen.
        reason: String,
    },
}

/// A joint's addresses in MuJoCo's arrays.
#[derive(Clone, Copy, Debug)]
struct JointAddr {
    qpos: usize,
    dof: usize,
}

/// The twin: MuJoCo's model and data, the servos' states and their targets.
pub struct Sim {
    model: TwinModel,
    mj: Arc<MjModel>,
    data: MjData<Arc<MjModel>>,
    servos: [Servo; 4],
    /// Horn targets (rad), servo_angles order; `None`: no pulse (the servo goes limp).
    targets: [Option<f64>; 4],
    drives: [JointAddr; 4],
    joints: Vec<(String, JointAddr)>,
    tool0: usize,
    cube: usize,
    closures: Vec<(usize, usize)>,
}

/// Routes MuJoCo's own messages (its warnings of an unstable simulation among them) to
/// the `log` crate, once per process: without it MuJoCo writes them to MUJOCO_LOG.TXT in
/// the working directory. [`Sim::new`] calls it before it touches MuJoCo.
pub fn route_mujoco_logs() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // SAFETY: the hook must not be installed while another thread uses MuJoCo. Every
        // use of MuJoCo in this crate starts with a Sim::new, which comes here first, and
        // `call_once` holds every other caller until this call has returned.
        #[allow(unsafe_code)]
        unsafe {
            mujoco_rs::logging::install_logging_hook();
        }
    });
}

impl Sim {
    /// The twin of the arm assembled to `config`, from URDF text, in `scene`, at rest in
    /// the home pose with the claw closed and the servos holding it there.
    pub fn new(urdf_text: &str, config: &ArmConfig, scene: &Scene) -> Result<Sim, SimError> {
        route_mujoco_logs();
        let model = twin_model::build(urdf_text, "urdf", config, scene)?;
        let mj = Arc::new(
            MjModel::from_xml_string(&model.mjcf).map_err(|e| SimError::Load(e.to_string()))?,
        );
        let addr = |name: &str| -> Result<JointAddr, SimError> {
            let id = mj
                .name_to_id(MjtObjBase::mjOBJ_JOINT, name)
                .ok_or_else(|| SimError::Missing(format!("joint `{name}`")))?;
            let qpos = usize::try_from(mj.jnt_qposadr()[id])
                .map_err(|_| SimError::Missing(name.into()))?;
            let dof =
                usize::try_from(mj.jnt_dofadr()[id]).map_err(|_| SimError::Missing(name.into()))?;
            Ok(JointAddr { qpos, dof })
        };
        let drives = [
            addr(model.drives[0].joint)?,
            addr(model.drives[1].joint)?,
            addr(model.drives[2].joint)?,
            addr(model.drives[3].joint)?,
        ];
        let joints = model
            .joints
            .iter()
            .map(|j| Ok((j.clone(), addr(j)?)))
            .collect::<Result<Vec<_>, SimError>>()?;
        let id = |kind, name: &str| {
            mj.name_to_id(kind, name)
                .ok_or_else(|| SimError::Missing(name.to_string()))
        };
        let tool0 = id(MjtObjBase::mjOBJ_SITE, "tool0")?;
        let cube = id(MjtObjBase::mjOBJ_BODY, "cube")?;
        let closures = model
            .closures
            .iter()
            .map(|c| {
                Ok((
                    id(MjtObjBase::mjOBJ_BODY, c.body1)?,
                    id(MjtObjBase::mjOBJ_BODY, c.body2)?,
                ))
            })
            .collect::<Result<Vec<_>, SimError>>()?;
        let data = MjData::new(mj.clone());
        let servos = model.drives.map(|d| Servo::new(d.spec, 0.0));
        let mut sim = Sim {
            model,
            mj,
            data,
            servos,
            targets: [None; 4],
            drives,
            joints,
            tool0,
            cube,
            closures,
        };
        sim.pose(&ArmJoints::HOME, 0.0);
        let horns = sim.horns();
        sim.targets = horns.map(Some);
        Ok(sim)
    }

    /// Puts the arm at rest in a pose (every passive joint where the linkage has it),
    /// the servos meshed there.
    pub fn pose(&mut self, q: &ArmJoints, gripper_rad: f64) {
        let p = PassiveJoints::from_arm(q);
        let values = [
            ("base_joint", q.base_rad),
            ("shoulder_joint", q.shoulder_rad),
            ("elbow_joint", q.elbow_rad),
            ("gripper_joint", gripper_rad),
            ("gripper_mimic_joint", -gripper_rad),
        ];
        let passive = PassiveJoints::NAMES.iter().copied().zip(p.values());
        for (name, v) in values.into_iter().chain(passive) {
            if let Some((_, a)) = self.joints.iter().find(|(n, _)| n == name) {
                self.data.qpos_mut()[a.qpos] = v;
                self.data.qvel_mut()[a.dof] = 0.0;
            }
        }
        self.data.forward();
        let horns = self.horns();
        for (servo, horn) in self.servos.iter_mut().zip(horns) {
            *servo = Servo::new(*servo.spec(), horn);
        }
    }

    /// The generated model.
    pub fn model(&self) -> &TwinModel {
        &self.model
    }

    /// MuJoCo's model (for a renderer).
    pub fn mj_model(&self) -> Arc<MjModel> {
        self.mj.clone()
    }

    /// MuJoCo's data (for a camera's snapshot).
    pub fn data(&self) -> &MjData<Arc<MjModel>> {
        &self.data
    }

    /// Sets a joint's velocity (rad/s): a kick, for experiments and for the tests of an
    /// unstable simulation.
    pub fn set_joint_velocity(&mut self, name: &str, vel: f64) {
        if let Some((_, a)) = self.joints.iter().find(|(n, _)| n == name) {
            self.data.qvel_mut()[a.dof] = vel;
        }
    }

    /// The horn targets (rad) the servos steer to; `None`: no pulse.
    pub fn horn_targets(&self) -> [Option<f64>; 4] {
        self.targets
    }

    /// Scales a servo's stall torque from now on (servo_angles order).
    pub fn set_torque_scale(&mut self, servo: usize, scale: f64) {
        let horn = self.horns().get(servo).copied().unwrap_or(0.0);
        if let (Some(s), Some(d)) = (self.servos.get_mut(servo), self.model.drives.get(servo)) {
            *s = Servo::new(d.spec.with_torque_scale(scale), horn);
        }
    }

    /// Steers the servos to horn angles (rad); `None`: no pulse, the servo limp.
    pub fn set_horn_targets(&mut self, targets: [Option<f64>; 4]) {
        self.targets = targets.map(|t| t.map(|r| r.clamp(0.0, std::f64::consts::PI)));
    }

    /// Steers the servos by pulse widths (µs, 0 = no pulse), as the pins carry them:
    /// each becomes a horn angle by the twin's calibration.
    pub fn set_pulses_us(&mut self, pulses: [f64; 4]) {
        let mut targets = [None; 4];
        for (i, p) in pulses.iter().enumerate() {
            if *p > 0.0 {
                targets[i] = Some(self.model.drives[i].horn_of_pulse_rad(*p));
            }
        }
        self.targets = targets;
    }

    /// The horn angles (rad) now, servo_angles order.
    pub fn horns(&self) -> [f64; 4] {
        std::array::from_fn(|i| {
            self.model.drives[i].horn_rad(self.data.qpos()[self.drives[i].qpos])
        })
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.data.time()
    }

    /// The physics step (s).
    pub fn timestep(&self) -> f64 {
        self.data.model().opt().timestep
    }

    /// One physics step; an unstable simulation is an error, and stays stopped.
    pub fn step(&mut self) -> Result<(), SimError> {
        let dt = self.timestep();
        for i in 0..4 {
            let d = self.model.drives[i];
            let a = self.drives[i];
            let pos = d.horn_rad(self.data.qpos()[a.qpos]);
            let vel = d.ratio * self.data.qvel()[a.dof];
            // without a pulse the servo is limp: only its gear train's friction (the
            // joint's frictionloss) holds it
            let torque = match self.targets[i] {
                Some(target) => self.servos[i].torque(target, pos, vel, dt),
                None => 0.0,
            };
            self.data.ctrl_mut()[i] = d.ratio * torque;
        }
        self.data.step();
        self.check()
    }

    /// Steps until the simulated time has passed `seconds` more.
    pub fn run(&mut self, seconds: f64) -> Result<(), SimError> {
        let steps = (seconds / self.timestep()).round() as u64;
        for _ in 0..steps {
            self.step()?;
        }
        Ok(())
    }

    /// MuJoCo resets its data when a state goes bad (a NaN, a huge acceleration) and
    /// counts a warning: seen here, the twin stops.
    fn check(&self) -> Result<(), SimError> {
        let warnings = self.data.warning();
        for (kind, what) in [
            (MjtWarning::mjWARN_BADQPOS, "a position became NaN or huge"),
            (MjtWarning::mjWARN_BADQVEL, "a velocity became NaN or huge"),
            (
                MjtWarning::mjWARN_BADQACC,
                "an acceleration became NaN or huge (a constraint blew up)",
            ),
        ] {
            if warnings[kind as usize].number > 0 {
                return Err(SimError::Unstable {
                    time: self.time(),
                    reason: what.into(),
                });
            }
        }
        if let Some(i) = self.data.qpos().iter().position(|v| !v.is_finite()) {
            return Err(SimError::Unstable {
                time: self.time(),
                reason: format!("qpos[{i}] is not finite"),
            });
        }
        Ok(())
    }

    /// Every movable joint's angle (rad), in the URDF's order: what `twin/joint_states`
    /// carries.
    pub fn joint_positions(&self) -> Vec<(&str, f64)> {
        self.joints
            .iter()
            .map(|(n, a)| (n.as_str(), self.data.qpos()[a.qpos]))
            .collect()
    }

    /// The velocities (rad/s) in the same order.
    pub fn joint_velocities(&self) -> Vec<f64> {
        self.joints
            .iter()
            .map(|(_, a)| self.data.qvel()[a.dof])
            .collect()
    }

    /// One joint's angle (rad).
    pub fn joint(&self, name: &str) -> Option<f64> {
        self.joints
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, a)| self.data.qpos()[a.qpos])
    }

    /// The actuated joints as the kinematics names them.
    pub fn arm_joints(&self) -> ArmJoints {
        let j = |n| self.joint(n).unwrap_or(0.0);
        ArmJoints {
            base_rad: j("base_joint"),
            shoulder_rad: j("shoulder_joint"),
            elbow_rad: j("elbow_joint"),
        }
    }

    /// `tool0` in `base_link` (m).
    pub fn tool0(&self) -> Vector3<f64> {
        Vector3::from(self.data.site_xpos()[self.tool0])
    }

    /// The cube's pose in `base_link`: position (m) and orientation.
    pub fn cube_pose(&self) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let p = self.data.xpos()[self.cube];
        let [w, i, j, k] = self.data.xquat()[self.cube];
        (
            Vector3::from(p),
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, i, j, k)),
        )
    }

    /// Each loop's closure error (m): how far apart its pin's two halves are.
    pub fn loop_errors(&self) -> Vec<f64> {
        self.model
            .closures
            .iter()
            .zip(&self.closures)
            .map(|(c, &(b1, b2))| {
                let world = |body: usize, p: [f64; 3]| {
                    let [x, y, z] = self.data.xpos()[body];
                    let [w, i, j, k] = self.data.xquat()[body];
                    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, i, j, k));
                    Vector3::new(x, y, z) + q * Point3::from(p).coords
                };
                (world(b1, c.anchor1) - world(b2, c.anchor2)).norm()
            })
            .collect()
    }
}
