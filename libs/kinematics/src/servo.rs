//! Servo calibration: joint values → servo horn angles and pulse widths.

use crate::{ArmState, ConfigError, KinematicsError};
use serde::{Deserialize, Serialize};

/// The four servos, in the order of `servo_angles`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ServoId {
    /// Pin 8, MG995, turns the base through a 2:1 reversing gear pair.
    Base,
    /// Pin 9, MG995, main arm.
    Shoulder,
    /// Pin 10, MG995, forearm (through the parallelogram: sets φ directly).
    Elbow,
    /// Pin 11, SG90, claw.
    Gripper,
}

impl ServoId {
    /// All servos in `servo_angles` order.
    pub const ALL: [ServoId; 4] = [
        ServoId::Base,
        ServoId::Shoulder,
        ServoId::Elbow,
        ServoId::Gripper,
    ];

    /// Name on `servo_angles` / `servo_state`.
    pub fn name(self) -> &'static str {
        self.of([
            "base_servo",
            "shoulder_servo",
            "elbow_servo",
            "gripper_servo",
        ])
    }

    /// This servo's one of four things given in `ServoId::ALL` order (the base's,
    /// the shoulder's, the elbow's, the gripper's).
    pub fn of<T>(self, [base, shoulder, elbow, gripper]: [T; 4]) -> T {
        match self {
            ServoId::Base => base,
            ServoId::Shoulder => shoulder,
            ServoId::Elbow => elbow,
            ServoId::Gripper => gripper,
        }
    }
}

/// One servo: `angle_deg = offset_deg + gain · input`, where the input is the
/// joint value in degrees (base, shoulder), the forearm elevation φ in degrees
/// (elbow servo), or the claw opening 0…1 (gripper).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServoCalibration {
    /// Servo angle at input 0 (deg).
    pub offset_deg: f64,
    /// Servo degrees per input unit; the sign is the mounting direction, the
    /// magnitude includes any gear ratio (2 for the base's 25→50 tooth pair).
    pub gain: f64,
    /// Lowest angle the servo may be sent to (deg).
    pub min_deg: f64,
    /// Highest angle the servo may be sent to (deg).
    pub max_deg: f64,
    /// Pulse width at 0° (µs); the Servo library's default is 544.
    pub pulse_min_us: u16,
    /// Pulse width at 180° (µs); the Servo library's default is 2400.
    pub pulse_max_us: u16,
}

impl ServoCalibration {
    const fn new(offset_deg: f64, gain: f64, min_deg: f64, max_deg: f64) -> Self {
        ServoCalibration {
            offset_deg,
            gain,
            min_deg,
            max_deg,
            pulse_min_us: 544,
            pulse_max_us: 2400,
        }
    }

    /// Servo angle (deg) for an input, checked against `min_deg … max_deg`.
    pub fn angle_deg(&self, servo: ServoId, input: f64) -> Result<f64, KinematicsError> {
        let angle_deg = self.offset_deg + self.gain * input;
        // A hair of tolerance so that limits that coincide exactly (45° base → 0°)
        // are not refused for rounding.
        const EPS_DEG: f64 = 1e-9;
        if !(angle_deg >= self.min_deg - EPS_DEG && angle_deg <= self.max_deg + EPS_DEG) {
            return Err(KinematicsError::ServoOutOfRange {
                servo: servo.name(),
                angle_deg,
                min_deg: self.min_deg,
                max_deg: self.max_deg,
            });
        }
        Ok(angle_deg.clamp(self.min_deg, self.max_deg))
    }

    /// Pulse width (µs) for a servo angle, as the Servo library maps it.
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::ServoCalibrations;
    /// let c = ServoCalibrations::default().base;
    /// assert_eq!(c.pulse_us(0.0), 544.0);
    /// assert_eq!(c.pulse_us(90.0), 1472.0);
    /// assert_eq!(c.pulse_us(180.0), 2400.0);
    /// ```
    pub fn pulse_us(&self, angle_deg: f64) -> f64 {
        let (lo, hi) = (f64::from(self.pulse_min_us), f64::from(self.pulse_max_us));
        lo + (hi - lo) * angle_deg / 180.0
    }
}

/// The calibration of all four servos.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServoCalibrations {
    /// Base servo (input: `base_joint`, deg).
    pub base: ServoCalibration,
    /// Main-arm servo (input: `shoulder_joint`, deg).
    pub shoulder: ServoCalibration,
    /// Forearm servo (input: forearm elevation φ, deg).
    pub elbow: ServoCalibration,
    /// Claw servo (input: opening 0…1).
    pub gripper: ServoCalibration,
}

impl Default for ServoCalibrations {
    /// ROBOT.md: base = 90 − 2·θ1, main = 180 − α, forearm = 90 + φ, gripper 60 closed … 180 open.
    fn default() -> Self {
        ServoCalibrations {
            base: ServoCalibration::new(90.0, -2.0, 0.0, 180.0),
            shoulder: ServoCalibration::new(180.0, -1.0, 0.0, 180.0),
            elbow: ServoCalibration::new(90.0, 1.0, 0.0, 180.0),
            gripper: ServoCalibration::new(60.0, 120.0, 60.0, 180.0),
        }
    }
}

/// Servo horn angles in radians (0 … π = the Servo library's 0 … 180°), in
/// `servo_angles` order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServoAngles {
    /// `base_servo`, `shoulder_servo`, `elbow_servo`, `gripper_servo`.
    pub rad: [f64; 4],
}

impl ServoCalibrations {
    /// The calibration of one servo.
    pub fn get(&self, servo: ServoId) -> &ServoCalibration {
        servo.of([&self.base, &self.shoulder, &self.elbow, &self.gripper])
    }

    /// Servo angles for an arm state, or the first servo that would leave its range.
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{ArmState, ServoCalibrations};
    /// let a = ServoCalibrations::default().servo_angles(&ArmState::default()).unwrap();
    /// let deg: Vec<f64> = a.rad.iter().map(|r| r.to_degrees().round()).collect();
    /// assert_eq!(deg, [90.0, 90.0, 90.0, 60.0]); // home pose, claw closed
    /// ```
    pub fn servo_angles(&self, state: &ArmState) -> Result<ServoAngles, KinematicsError> {
        if !(0.0..=1.0).contains(&state.gripper_opening) {
            return Err(KinematicsError::GripperOutOfRange {
                value: state.gripper_opening,
            });
        }
        let q = &state.joints;
        let inputs = [
            q.base_rad.to_degrees(),
            q.shoulder_rad.to_degrees(),
            q.forearm_elevation_rad().to_degrees(),
            state.gripper_opening,
        ];
        let mut rad = [0.0; 4];
        for (i, servo) in ServoId::ALL.into_iter().enumerate() {
            rad[i] = self.get(servo).angle_deg(servo, inputs[i])?.to_radians();
        }
        Ok(ServoAngles { rad })
    }

    /// The arm state that servo angles (rad, `servo_angles` order) put the arm in: the
    /// inverse of [`Self::servo_angles`], unchecked (a reported angle is what it is).
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{ArmState, ServoCalibrations};
    /// let c = ServoCalibrations::default();
    /// let mut s = ArmState::default();
    /// s.joints.base_rad = 0.3;
    /// s.gripper_opening = 0.5;
    /// let back = c.state_of_angles(c.servo_angles(&s).unwrap().rad);
    /// assert!((back.joints.base_rad - 0.3).abs() < 1e-12);
    /// assert!((back.joints.elbow_rad - s.joints.elbow_rad).abs() < 1e-12);
    /// assert!((back.gripper_opening - 0.5).abs() < 1e-12);
    /// ```
    pub fn state_of_angles(&self, rad: [f64; 4]) -> ArmState {
        let input = |servo: ServoId, r: f64| {
            let c = self.get(servo);
            (r.to_degrees() - c.offset_deg) / c.gain
        };
        let base = input(ServoId::Base, rad[0]).to_radians();
        let shoulder = input(ServoId::Shoulder, rad[1]).to_radians();
        let forearm = input(ServoId::Elbow, rad[2]).to_radians();
        let mut state = ArmState::default();
        state.joints.base_rad = base;
        state.joints.shoulder_rad = shoulder;
        state.joints.elbow_rad = forearm - shoulder;
        state.gripper_opening = input(ServoId::Gripper, rad[3]);
        state
    }

    /// Servo angles (rad) for an arm state, each clamped into its servo's range (for
    /// a state that may lie a hair outside them; [`Self::servo_angles`] refuses).
    pub fn clamped_servo_angles(&self, state: &ArmState) -> [f64; 4] {
        let q = &state.joints;
        let inputs = [
            q.base_rad.to_degrees(),
            q.shoulder_rad.to_degrees(),
            q.forearm_elevation_rad().to_degrees(),
            state.gripper_opening.clamp(0.0, 1.0),
        ];
        let mut rad = [0.0; 4];
        for (i, servo) in ServoId::ALL.into_iter().enumerate() {
            let c = self.get(servo);
            rad[i] = (c.offset_deg + c.gain * inputs[i])
                .clamp(c.min_deg, c.max_deg)
                .to_radians();
        }
        rad
    }

    /// Check the ranges: inside 0–180°, ordered, non-zero gain, pulses 400–2600 µs.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        for servo in ServoId::ALL {
            let c = self.get(servo);
            let field = servo.of([
                "servos.base",
                "servos.shoulder",
                "servos.elbow",
                "servos.gripper",
            ]);
            let invalid = |why: &'static str| ConfigError::Invalid {
                origin: origin.to_string(),
                field,
                value: format!("{c:?}"),
                why,
            };
            if !(c.offset_deg.is_finite() && c.gain.is_finite() && c.gain != 0.0) {
                return Err(invalid(
                    "offset must be finite and gain finite and non-zero",
                ));
            }
            if !(0.0 <= c.min_deg && c.min_deg <= c.max_deg && c.max_deg <= 180.0) {
                return Err(invalid("need 0 <= min_deg <= max_deg <= 180"));
            }
            if !(400 <= c.pulse_min_us && c.pulse_min_us < c.pulse_max_us && c.pulse_max_us <= 2600)
            {
                return Err(invalid("need 400 <= pulse_min_us < pulse_max_us <= 2600"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ArmJoints;

    #[test]
    fn robot_md_mapping() {
        let cal = ServoCalibrations::default();
        let state = ArmState {
            joints: ArmJoints {
                base_rad: 20f64.to_radians(),
                shoulder_rad: 100f64.to_radians(),
                elbow_rad: -110f64.to_radians(),
            },
            gripper_opening: 0.5,
        };
        let deg = cal.servo_angles(&state).unwrap().rad.map(f64::to_degrees);
        let want = [90.0 - 40.0, 180.0 - 100.0, 90.0 - 10.0, 120.0];
        for (g, w) in deg.iter().zip(want) {
            assert!((g - w).abs() < 1e-9, "{deg:?} vs {want:?}");
        }
    }

    #[test]
    fn gripper_outside_unit_range_is_refused() {
        let cal = ServoCalibrations::default();
        let state = ArmState {
            gripper_opening: 1.5,
            ..ArmState::default()
        };
        assert!(matches!(
            cal.servo_angles(&state),
            Err(KinematicsError::GripperOutOfRange { .. })
        ));
    }

    #[test]
    fn servo_range_is_enforced() {
        let mut cal = ServoCalibrations::default();
        cal.base.max_deg = 100.0;
        let state = ArmState {
            joints: ArmJoints {
                base_rad: (-10f64).to_radians(),
                ..ArmJoints::HOME
            },
            gripper_opening: 0.0,
        };
        assert!(matches!(
            cal.servo_angles(&state),
            Err(KinematicsError::ServoOutOfRange {
                servo: "base_servo",
                ..
            })
        ));
    }
}
