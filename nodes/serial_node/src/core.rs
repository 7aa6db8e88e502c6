//! Pure logic of serial_node: servo angles ↔ pulse ticks with the calibration's ranges.

use eezybot_kinematics::{ServoCalibration, ServoCalibrations, ServoId};
use eezybot_msgs::sensor_msgs::JointState;
use ros_plumbing::logging::{shorten, NAME_MAX};
use servo_protocol::{SERVOS, TICKS_PER_US};
use std::fmt;

/// Why a `servo_angles` message was refused.
#[derive(Clone, Debug, PartialEq)]
pub enum Rejection {
    /// `name` and `position` differ in length.
    LengthMismatch {
        /// names
        names: usize,
        /// positions
        positions: usize,
    },
    /// A name that is not one of the four servos.
    UnknownServo {
        /// the name
        name: String,
    },
    /// A servo named twice: an ambiguous command.
    DuplicateServo {
        /// the servo
        name: &'static str,
    },
    /// A servo is missing from the message.
    MissingServo {
        /// the servo
        name: &'static str,
    },
    /// A position is NaN or infinite.
    NonFinite {
        /// the servo
        name: String,
        /// the value
        value: f64,
    },
    /// An angle outside the servo's calibrated range.
    OutOfRange {
        /// the servo
        name: &'static str,
        /// the angle (deg)
        angle_deg: f64,
        /// lowest allowed (deg)
        min_deg: f64,
        /// highest allowed (deg)
        max_deg: f64,
    },
}

impl Rejection {
    /// Short machine-readable code.
    pub fn code(&self) -> &'static str {
        match self {
            Rejection::LengthMismatch { .. } => "length_mismatch",
            Rejection::UnknownServo { .. } => "unknown_servo",
            Rejection::DuplicateServo { .. } => "duplicate_servo",
            Rejection::MissingServo { .. } => "missing_servo",
            Rejection::NonFinite { .. } => "non_finite",
            Rejection::OutOfRange { .. } => "out_of_range",
        }
    }
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Rejection::LengthMismatch { names, positions } => write!(f, "{names} names but {positions} positions"),
            Rejection::UnknownServo { name } => write!(
                f,
                "unknown servo `{}` (servos: base_servo, shoulder_servo, elbow_servo, gripper_servo)",
                shorten(name, NAME_MAX)
            ),
            Rejection::DuplicateServo { name } => {
                write!(f, "`{name}` is given twice (an ambiguous command)")
            }
            Rejection::MissingServo { name } => write!(f, "no position for `{name}`"),
            Rejection::NonFinite { name, value } => {
                write!(f, "`{}` is {value}", shorten(name, NAME_MAX))
            }
            Rejection::OutOfRange { name, angle_deg, min_deg, max_deg } => write!(
                f,
                "`{name}` at {angle_deg:.2}° is outside its range {min_deg:.2}° … {max_deg:.2}°"
            ),
        }
    }
}

/// Pulse width in 0.5 µs ticks for a servo angle, as the Servo library maps 0–180°.
///
/// # Examples
/// ```
/// use eezybot_kinematics::ServoCalibrations;
/// let c = ServoCalibrations::default().base;
/// assert_eq!(serial_node::core::angle_to_ticks(&c, 90f64.to_radians()), 2944); // 1472 µs
/// ```
pub fn angle_to_ticks(cal: &ServoCalibration, angle_rad: f64) -> u16 {
    let us = cal.pulse_us(angle_rad.to_degrees());
    (us * f64::from(TICKS_PER_US))
        .round()
        .clamp(1.0, f64::from(u16::MAX)) as u16
}

/// The servo angle (rad) a pulse width stands for; 0 ticks (no pulses) gives NaN.
pub fn ticks_to_angle(cal: &ServoCalibration, ticks: u16) -> f64 {
    if ticks == 0 {
        return f64::NAN;
    }
    let (lo, hi) = (f64::from(cal.pulse_min_us), f64::from(cal.pulse_max_us));
    let us = f64::from(ticks) / f64::from(TICKS_PER_US);
    ((us - lo) / (hi - lo) * 180.0).to_radians()
}

/// Check a `servo_angles` message and turn it into the four pulse widths.
/// Names may come in any order; all four servos must be there.
pub fn angles_to_ticks(
    cal: &ServoCalibrations,
    msg: &JointState,
) -> Result<[u16; SERVOS], Rejection> {
    if msg.name.len() != msg.position.len() {
        return Err(Rejection::LengthMismatch {
            names: msg.name.len(),
            positions: msg.position.len(),
        });
    }
    let mut angles = [None; SERVOS];
    for (name, &value) in msg.name.iter().zip(&msg.position) {
        let Some(i) = ServoId::ALL.iter().position(|s| s.name() == name) else {
            return Err(Rejection::UnknownServo { name: name.clone() });
        };
        if !value.is_finite() {
            return Err(Rejection::NonFinite {
                name: name.clone(),
                value,
            });
        }
        if angles[i].is_some() {
            return Err(Rejection::DuplicateServo {
                name: ServoId::ALL[i].name(),
            });
        }
        angles[i] = Some(value);
    }
    let mut ticks = [0u16; SERVOS];
    for (i, servo) in ServoId::ALL.into_iter().enumerate() {
        let angle = angles[i].ok_or(Rejection::MissingServo { name: servo.name() })?;
        let c = cal.get(servo);
        let deg = angle.to_degrees();
        const EPS_DEG: f64 = 1e-6;
        if deg < c.min_deg - EPS_DEG || deg > c.max_deg + EPS_DEG {
            return Err(Rejection::OutOfRange {
                name: servo.name(),
                angle_deg: deg,
                min_deg: c.min_deg,
                max_deg: c.max_deg,
            });
        }
        ticks[i] = angle_to_ticks(c, deg.clamp(c.min_deg, c.max_deg).to_radians());
    }
    Ok(ticks)
}

/// The four servo angles (rad) for reported pulse widths.
pub fn ticks_to_angles(cal: &ServoCalibrations, ticks: &[u16; SERVOS]) -> [f64; SERVOS] {
    let mut out = [0.0; SERVOS];
    for (i, servo) in ServoId::ALL.into_iter().enumerate() {
        out[i] = ticks_to_angle(cal.get(servo), ticks[i]);
    }
    out
}

/// The servos named in `mock_stalled_servos`: a comma-separated list of servo names
/// (spaces around them and empty items ignored; empty: none), as a mask in channel
/// order. An unknown name is refused, with the names there are.
///
/// # Examples
/// ```
/// use serial_node::core::parse_servo_list;
/// assert_eq!(parse_servo_list("elbow_servo"), Ok([false, false, true, false]));
/// assert_eq!(parse_servo_list(" base_servo, gripper_servo "), Ok([true, false, false, true]));
/// assert_eq!(parse_servo_list(""), Ok([false; 4]));
/// assert!(parse_servo_list("elbow").unwrap_err().contains("unknown servo `elbow`"));
/// ```
pub fn parse_servo_list(text: &str) -> Result<[bool; SERVOS], String> {
    let mut mask = [false; SERVOS];
    for name in text.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        let Some(i) = ServoId::ALL.iter().position(|s| s.name() == name) else {
            return Err(format!(
                "unknown servo `{}` (servos: {})",
                shorten(name, NAME_MAX),
                servo_list_text(&[true; SERVOS]).replace(',', ", ")
            ));
        };
        mask[i] = true;
    }
    Ok(mask)
}

/// The servos of a mask as [`parse_servo_list`] reads them: names in channel order,
/// comma-separated; empty for none.
pub fn servo_list_text(mask: &[bool; SERVOS]) -> String {
    ServoId::ALL
        .iter()
        .zip(mask)
        .filter(|(_, on)| **on)
        .map(|(s, _)| s.name())
        .collect::<Vec<_>>()
        .join(",")
}

/// A leader arm's joints from its potentiometers' readings (each a fraction of the ADC's
/// full scale, `servo_protocol::leader::LeaderState::fractions`), by the leader's
/// calibration (`leader:` of the arm config: ADC counts → the servo's input) and the
/// geometry's claw opening: `(joint name, rad)` in the follower's convention, for the
/// calibrated channels (`elbow_joint` needs the shoulder's too: the forearm's
/// potentiometer gives its elevation, shoulder + elbow).
pub fn leader_joints(
    cal: &eezybot_kinematics::LeaderCalibration,
    gripper_open_rad: f64,
    fractions: [f64; 4],
) -> Vec<(&'static str, f64)> {
    let counts = |f: f64| f * (f64::from(cal.adc_max) + 1.0);
    let input = |ch: &Option<eezybot_kinematics::LeaderChannel>, i: usize| {
        ch.as_ref().map(|c| c.input(counts(fractions[i])))
    };
    let base = input(&cal.base, 0);
    let shoulder = input(&cal.shoulder, 1);
    let forearm = input(&cal.elbow, 2);
    let opening = input(&cal.gripper, 3);
    let mut out = Vec::with_capacity(4);
    if let Some(b) = base {
        out.push(("base_joint", b.to_radians()));
    }
    if let Some(s) = shoulder {
        out.push(("shoulder_joint", s.to_radians()));
    }
    if let (Some(s), Some(f)) = (shoulder, forearm) {
        out.push(("elbow_joint", (f - s).to_radians()));
    }
    if let Some(o) = opening {
        out.push(("gripper_joint", o.clamp(0.0, 1.0) * gripper_open_rad));
    }
    out
}
