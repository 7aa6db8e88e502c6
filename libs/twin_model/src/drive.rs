//! Which joint each servo turns, and how: the twin's side of the servo calibration.
//!
//! The twin is a physical arm, assembled as the shipped `config/arm.yaml` describes (or
//! as another config given as the twin's own `arm_config`). A pulse width becomes a horn
//! angle as a servo makes it (linear between the calibration's `pulse_min_us` at 0° and
//! `pulse_max_us` at 180°), and a horn angle turns its joint through the linkage:
//! `horn = offset + gain · input`, the calibration's own equation read backwards. A graph
//! that commands with a different calibration then puts the twin where it would put a
//! real arm: a few degrees off.

use eezybot_kinematics::{ArmGeometry, ServoCalibration, ServoCalibrations, ServoId};
use std::f64::consts::PI;

use crate::servo::ServoSpec;

/// One servo and the joint it drives: `horn_rad = horn_at_zero_rad + ratio · joint_rad`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drive {
    /// Which servo.
    pub servo: ServoId,
    /// The URDF joint it turns (`crank_joint` for the forearm servo: it sets φ directly).
    pub joint: &'static str,
    /// d(horn) / d(joint): −2 for the base (the 2:1 gear pair reverses), −1 for the main
    /// arm, 1 for the forearm, about 3.5 for the claw.
    pub ratio: f64,
    /// The horn angle (rad) at joint angle 0.
    pub horn_at_zero_rad: f64,
    /// The servo's pulse width (µs) at 0° and at 180°.
    pub pulse_us: (f64, f64),
    /// The servo.
    pub spec: ServoSpec,
}

impl Drive {
    /// The four drives of an arm assembled to `servos` (in `servo_angles` order).
    pub fn all(servos: &ServoCalibrations, geometry: &ArmGeometry) -> [Drive; 4] {
        let drive = |servo: ServoId, joint, per_input_rad: f64, spec| {
            let c: &ServoCalibration = servos.get(servo);
            Drive {
                servo,
                joint,
                ratio: c.gain * per_input_rad,
                horn_at_zero_rad: c.offset_deg.to_radians(),
                pulse_us: (f64::from(c.pulse_min_us), f64::from(c.pulse_max_us)),
                spec,
            }
        };
        // the inputs of base, shoulder and forearm are in degrees (gain: horn deg per
        // joint deg, the same per rad); the claw's is its opening 0…1, which is
        // gripper_joint / gripper_open_rad
        let one = 1.0;
        let claw = PI / 180.0 / geometry.gripper_open_rad;
        [
            drive(ServoId::Base, "base_joint", one, ServoSpec::MG995),
            drive(ServoId::Shoulder, "shoulder_joint", one, ServoSpec::MG995),
            drive(ServoId::Elbow, "crank_joint", one, ServoSpec::MG995),
            drive(ServoId::Gripper, "gripper_joint", claw, ServoSpec::SG90),
        ]
    }

    /// The horn angle (rad) at a joint angle.
    pub fn horn_rad(&self, joint_rad: f64) -> f64 {
        self.horn_at_zero_rad + self.ratio * joint_rad
    }

    /// The joint angle (rad) at a horn angle.
    pub fn joint_rad(&self, horn_rad: f64) -> f64 {
        (horn_rad - self.horn_at_zero_rad) / self.ratio
    }

    /// The horn angle (rad) a pulse of `pulse_us` steers the servo to: linear between
    /// the servo's two widths, and within its travel (0 … 180°: a servo's pot and stops
    /// end there).
    pub fn horn_of_pulse_rad(&self, pulse_us: f64) -> f64 {
        let (lo, hi) = self.pulse_us;
        ((pulse_us - lo) / (hi - lo) * PI).clamp(0.0, PI)
    }

    /// The pulse width (µs) for a horn angle: the inverse of [`Self::horn_of_pulse_rad`]
    /// within the travel.
    pub fn pulse_of_horn_us(&self, horn_rad: f64) -> f64 {
        let (lo, hi) = self.pulse_us;
        lo + (hi - lo) * horn_rad.clamp(0.0, PI) / PI
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_kinematics::{ArmConfig, ArmState, PassiveJoints};

    #[test]
    fn the_drives_invert_the_calibration() {
        let cfg = ArmConfig::shipped().unwrap();
        let drives = Drive::all(&cfg.servos, &cfg.geometry);
        let mut state = ArmState::default();
        state.joints.base_rad = 0.3;
        state.joints.shoulder_rad = 1.2;
        state.joints.elbow_rad = -1.5;
        state.gripper_opening = 0.25;
        let horns = cfg.servos.servo_angles(&state).unwrap().rad;
        let passive = PassiveJoints::from_arm(&state.joints);
        let joints = [
            state.joints.base_rad,
            state.joints.shoulder_rad,
            passive.crank_rad,
            state.gripper_opening * cfg.geometry.gripper_open_rad,
        ];
        for (d, (horn, joint)) in drives.iter().zip(horns.iter().zip(joints)) {
            assert!((d.horn_rad(joint) - horn).abs() < 1e-12, "{}", d.joint);
            assert!((d.joint_rad(*horn) - joint).abs() < 1e-12, "{}", d.joint);
        }
        // the base turns at half its servo's speed, the other way
        assert_eq!(drives[0].ratio, -2.0);
    }

    #[test]
    fn pulses_map_linearly_within_the_travel() {
        let cfg = ArmConfig::shipped().unwrap();
        let d = Drive::all(&cfg.servos, &cfg.geometry)[0];
        assert_eq!(d.horn_of_pulse_rad(544.0), 0.0);
        assert!((d.horn_of_pulse_rad(1472.0) - PI / 2.0).abs() < 1e-12);
        assert_eq!(d.horn_of_pulse_rad(3000.0), PI);
        assert_eq!(d.horn_of_pulse_rad(100.0), 0.0);
        assert!((d.pulse_of_horn_us(d.horn_of_pulse_rad(2000.0)) - 2000.0).abs() < 1e-9);
    }
}
