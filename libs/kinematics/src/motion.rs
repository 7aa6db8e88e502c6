//! Motion limits of the servos (`config/arm.yaml`, section `motion`): how fast each
//! servo horn may turn and accelerate, in the Servo library's degrees. compute_ik plans
//! every move within them; serial_node refuses to move a pulse faster (its last guard).

use crate::{ConfigError, ServoCalibration, ServoCalibrations, ServoId};
use serde::{Deserialize, Serialize};

/// One servo's limits at its horn.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServoMotionLimits {
    /// Highest horn speed (deg/s).
    pub max_velocity_deg_s: f64,
    /// Highest horn acceleration (deg/s²).
    pub max_acceleration_deg_s2: f64,
}

impl ServoMotionLimits {
    /// A servo rated `s_per_60deg` (its datasheet speed), reaching it in `ramp_s`.
    pub fn rated(s_per_60deg: f64, ramp_s: f64) -> ServoMotionLimits {
        let v = 60.0 / s_per_60deg;
        ServoMotionLimits {
            max_velocity_deg_s: v,
            max_acceleration_deg_s2: v / ramp_s,
        }
    }

    /// In the units of the servo's input (deg or opening per second, per second²):
    /// the horn's limits divided by the calibration's gain (for the base, the 2:1
    /// gear halves the joint's speed).
    pub fn input_limits(&self, cal: &ServoCalibration) -> (f64, f64) {
        let g = cal.gain.abs();
        (
            self.max_velocity_deg_s / g,
            self.max_acceleration_deg_s2 / g,
        )
    }

    /// The velocity limit in pulse ticks (0.5 µs) per second, with the calibration's
    /// pulse range over 180°.
    pub fn ticks_per_s(&self, cal: &ServoCalibration) -> f64 {
        let us_per_deg = (f64::from(cal.pulse_max_us) - f64::from(cal.pulse_min_us)) / 180.0;
        self.max_velocity_deg_s * us_per_deg * 2.0
    }
}

/// The four servos' limits.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionLimits {
    /// Base servo (MG995; the base joint turns at half its speed).
    pub base: ServoMotionLimits,
    /// Main-arm servo (MG995).
    pub shoulder: ServoMotionLimits,
    /// Forearm servo (MG995; sets the forearm elevation φ).
    pub elbow: ServoMotionLimits,
    /// Claw servo (SG90).
    pub gripper: ServoMotionLimits,
}

impl Default for MotionLimits {
    /// The rated speeds, MG995 0.2 s/60° (300°/s) and SG90 0.12 s/60° (500°/s), reached
    /// in 0.25 s.
    fn default() -> Self {
        let mg995 = ServoMotionLimits::rated(0.2, 0.25);
        MotionLimits {
            base: mg995,
            shoulder: mg995,
            elbow: mg995,
            gripper: ServoMotionLimits::rated(0.12, 0.25),
        }
    }
}

impl MotionLimits {
    /// One servo's limits.
    pub fn get(&self, servo: ServoId) -> &ServoMotionLimits {
        servo.of([&self.base, &self.shoulder, &self.elbow, &self.gripper])
    }

    /// Limits of what the servos drive, in `ServoId::ALL` order: base joint,
    /// shoulder joint, forearm elevation φ (rad/s, rad/s²) and claw opening (1/s, 1/s²).
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{MotionLimits, ServoCalibrations};
    /// let l = MotionLimits::default().input_limits(&ServoCalibrations::default());
    /// assert!((l[0].0.to_degrees() - 150.0).abs() < 1e-9); // the base: half its servo
    /// assert!((l[3].0 - 500.0 / 120.0).abs() < 1e-9);      // the claw: 120° of servo per unit
    /// ```
    pub fn input_limits(&self, cal: &ServoCalibrations) -> [(f64, f64); 4] {
        ServoId::ALL.map(|s| {
            let (v, a) = self.get(s).input_limits(cal.get(s));
            if s == ServoId::Gripper {
                (v, a)
            } else {
                (v.to_radians(), a.to_radians())
            }
        })
    }

    /// Each servo's velocity limit in pulse ticks per second, `ServoId::ALL` order.
    pub fn ticks_per_s(&self, cal: &ServoCalibrations) -> [f64; 4] {
        ServoId::ALL.map(|s| self.get(s).ticks_per_s(cal.get(s)))
    }

    /// Check that every limit is a positive number.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        for (field, v) in [
            (
                "motion.base.max_velocity_deg_s",
                self.base.max_velocity_deg_s,
            ),
            (
                "motion.base.max_acceleration_deg_s2",
                self.base.max_acceleration_deg_s2,
            ),
            (
                "motion.shoulder.max_velocity_deg_s",
                self.shoulder.max_velocity_deg_s,
            ),
            (
                "motion.shoulder.max_acceleration_deg_s2",
                self.shoulder.max_acceleration_deg_s2,
            ),
            (
                "motion.elbow.max_velocity_deg_s",
                self.elbow.max_velocity_deg_s,
            ),
            (
                "motion.elbow.max_acceleration_deg_s2",
                self.elbow.max_acceleration_deg_s2,
            ),
            (
                "motion.gripper.max_velocity_deg_s",
                self.gripper.max_velocity_deg_s,
            ),
            (
                "motion.gripper.max_acceleration_deg_s2",
                self.gripper.max_acceleration_deg_s2,
            ),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError::Invalid {
                    origin: origin.to_string(),
                    field,
                    value: v.to_string(),
                    why: "must be a positive number",
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ArmConfig;

    #[test]
    fn shipped_limits_are_the_rated_speeds() {
        let c = ArmConfig::shipped().unwrap();
        assert_eq!(c.motion, MotionLimits::default());
        assert!((c.motion.base.max_velocity_deg_s - 300.0).abs() < 1e-9);
        assert!((c.motion.gripper.max_velocity_deg_s - 500.0).abs() < 1e-9);
        // 300°/s with 544…2400 µs over 180°: 6186.7 ticks/s
        let t = c.motion.ticks_per_s(&c.servos);
        assert!((t[0] - 300.0 * 1856.0 / 180.0 * 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_non_positive_limit_is_refused_with_its_field() {
        let err = ArmConfig::from_yaml(
            "motion: { elbow: { max_velocity_deg_s: 0, max_acceleration_deg_s2: 100 } }",
            "t.yaml",
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("motion.elbow.max_velocity_deg_s"),
            "{err}"
        );
    }
}
