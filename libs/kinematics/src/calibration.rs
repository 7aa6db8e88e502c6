//! Guided calibration (issue 22 item 1): the math behind the calibration wizard. No ROS,
//! no UI, no files.
//!
//! The user jogs one servo at a time until the arm shows a **reference pose** that is
//! easy to see on a real arm (the base straight ahead, the main arm vertical, …) and
//! marks the servo angle; two marks per servo give its line `servo_deg = offset_deg +
//! gain · input` ([`derive()`]). Implausible results are refused with a reason
//! ([`CalibrationError`]): a gain far from the shipped one, a reversed direction where
//! the hardware cannot reverse, a joint range the servo cannot cover, marks too close to
//! give a gain. The same two-reference derivation maps a leader arm's potentiometer
//! (ADC counts) to a joint input ([`derive_leader`], [`LeaderCalibration`], the optional
//! `leader:` section of the arm configuration).
//!
//! Saving the result into `config/arm.yaml` is the `arm_config_file` crate's
//! (`calibration_text` rewrites the `servos:` block and the `leader:` section of a
//! configuration text, keeping every other byte; `write_calibration` saves it
//! atomically, keeping the previous file as `<name>.bak`).
//!
//! The choices (references, holds, jog ranges, tolerances) are explained in
//! docs/robot.md, "Calibrating with the wizard (the math)".
//!
//! # Examples
//! ```
//! use eezybot_kinematics::{ArmConfig, ServoCalibrations, ServoId};
//! use eezybot_kinematics::calibration::{derive, CalibrationPlan, Mark, Tolerances};
//! let config = ArmConfig::shipped().unwrap();
//! let plan = CalibrationPlan::new(&config).unwrap();
//! let refs = plan.get(ServoId::Shoulder).references;
//! // this arm's main arm is vertical at 97° and leans 45° forward at 142°
//! let marks = [Mark::new(refs[0].input, 97.0), Mark::new(refs[1].input, 142.0)];
//! let d = derive(&config, ServoId::Shoulder, marks, &config.servos.shoulder,
//!                &Tolerances::default()).unwrap();
//! assert_eq!((d.calibration.offset_deg, d.calibration.gain), (187.0, -1.0));
//! ```

use crate::{ArmConfig, ServoCalibration, ServoCalibrations, ServoId};
pub use crate::{LeaderCalibration, LeaderChannel, DEFAULT_ADC_MAX};
use std::fmt;

/// The order in which the wizard calibrates the servos: the base; the forearm (elbow
/// servo) with the main arm held at its home angle, where its servo angle is the same
/// whichever way the servo is mounted; the main arm (shoulder servo) with the forearm
/// held by its new calibration; the claw.
pub const CALIBRATION_ORDER: [ServoId; 4] = [
    ServoId::Base,
    ServoId::Elbow,
    ServoId::Shoulder,
    ServoId::Gripper,
];

/// The wizard's fine jog step (servo degrees): a quarter of a degree at the base joint.
pub const FINE_STEP_DEG: f64 = 0.5;

/// The wizard's coarse jog step (servo degrees).
pub const COARSE_STEP_DEG: f64 = 5.0;

/// How far (servo degrees) a horn may sit from where the shipped calibration expects it:
/// an MG995's output spline has 25 teeth (14.4° each), so a horn put on as close as it
/// goes is within half a tooth, 7.2°, plus about 3° of print and assembly play.
pub const HORN_MARGIN_DEG: f64 = 10.0;

/// The servo-degree margin a jog range keeps beyond the pose it is meant to reach (one
/// coarse step), so the user can overshoot a reference and come back.
pub const JOG_SLACK_DEG: f64 = COARSE_STEP_DEG;

/// How much more than the shipped |gain| (a fraction) the jog range after the first mark
/// allows past the joint's limits: the unit-to-unit spread of a servo's degrees per
/// pulse width. References at the very end of a joint's range (the base's ±45°, the
/// claw's open) stay reachable on a servo that turns that much less per degree.
pub const JOG_GAIN_SPREAD: f64 = 0.10;

/// How the derivation judges plausibility. [`Tolerances::default`] holds the values
/// docs/robot.md justifies; set `max_uncovered_deg` to 0 to refuse any calibration that
/// leaves part of a joint's range out of its servo's reach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerances {
    /// Largest relative difference of |gain| from the shipped one for the base,
    /// shoulder and elbow servos (0.20: unit-to-unit servo spread ±10 % plus two marks
    /// ±1° over a 45° span pass; a 270° servo (−33 %), a 1:1 base gear (−50 %) or a 60°
    /// pose marked as 45° (+33 %) do not).
    pub joint_gain: f64,
    /// The same for the claw (0.30): its "open" reference is where the fingers stop,
    /// not an angle against a square, and SG90 clones spread more.
    pub claw_gain: f64,
    /// Smallest distance between the two marks, and between the two references mapped
    /// through the shipped gain (servo degrees).
    pub min_mark_separation_deg: f64,
    /// Largest part of a joint's range (servo degrees, both ends together) that may lie
    /// outside the servo's allowed range: those joint values are then refused at run
    /// time (`ServoOutOfRange`) instead of driven. Default 7.2°, half a spline tooth:
    /// less than that cannot be fixed by re-seating the horn.
    pub max_uncovered_deg: f64,
    /// A leader reading within this fraction of the ADC's full scale from either rail
    /// is refused (0.02: 20 counts of 1023; a wiper at its end stop, a broken wire or a
    /// shorted input reads the rail whatever the joint does).
    pub leader_rail_fraction: f64,
    /// Smallest difference of the two leader readings, as a fraction of the full scale
    /// (0.02: ten times the Arduino's ±2 counts of noise; a 270° pot turning with a
    /// joint through 45° moves 170 counts).
    pub leader_min_separation_fraction: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances {
            joint_gain: 0.20,
            claw_gain: 0.30,
            min_mark_separation_deg: 5.0,
            max_uncovered_deg: 7.2,
            leader_rail_fraction: 0.02,
            leader_min_separation_fraction: 0.02,
        }
    }
}

impl Tolerances {
    /// The relative gain tolerance of one servo.
    pub fn gain(&self, servo: ServoId) -> f64 {
        match servo {
            ServoId::Gripper => self.claw_gain,
            _ => self.joint_gain,
        }
    }
}

/// Which way a servo turns its joint, relative to the shipped calibration's sign.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// The sign of the shipped gain.
    AsShipped,
    /// The opposite sign: the servo is mounted mirrored.
    Reversed,
}

impl Direction {
    /// +1 or −1, the factor on the shipped gain.
    pub fn sign(self) -> f64 {
        match self {
            Direction::AsShipped => 1.0,
            Direction::Reversed => -1.0,
        }
    }

    /// The direction of a gain of this servo.
    pub fn of_gain(servo: ServoId, gain: f64) -> Direction {
        if gain * expected_gain(servo) >= 0.0 {
            Direction::AsShipped
        } else {
            Direction::Reversed
        }
    }

    /// The direction seen while jogging: the servo angle changed by `servo_delta_deg`
    /// and the joint's input by `input_delta` (any amounts, only their signs count).
    pub fn from_observation(servo: ServoId, servo_delta_deg: f64, input_delta: f64) -> Direction {
        Direction::of_gain(servo, servo_delta_deg * input_delta)
    }
}

/// Whether this arm's hardware lets the servo turn its joint the other way round.
///
/// The main-arm and forearm servos sit coaxially on the shoulder axis, one on each side
/// of the turntable, mirror images of each other, and each drives its part directly
/// (the main arm; the forearm's crank): a build that flips one or swaps the sides turns
/// its joint the other way, and the calibration's sign absorbs that. The base servo
/// drives the turntable through an external 25 → 50 tooth gear pair from its one pocket
/// under it: an external pair always reverses, so its gain is negative on every arm (a
/// positive one means left and right were confused). The claw's SG90 sits in a fixed
/// pocket, closing towards the low angles, which the shipped `min_deg` (60°, closed)
/// guards.
pub fn is_reversible(servo: ServoId) -> bool {
    matches!(servo, ServoId::Shoulder | ServoId::Elbow)
}

/// The shipped gain (`ServoCalibrations::default()`): its magnitude is the expected
/// one, its sign the shipped direction.
pub fn expected_gain(servo: ServoId) -> f64 {
    ServoCalibrations::default().get(servo).gain
}

/// The servo's input at the home pose (base 0°, main arm vertical 90°, forearm
/// horizontal 0°, claw closed 0), where a servo's angle does not depend on the way it
/// is mounted.
pub fn home_input(servo: ServoId) -> f64 {
    servo.of([0.0, 90.0, 0.0, 0.0])
}

/// The range of a servo's input the arm can take with every limit row of `config`
/// holding: the base's row; the shoulder's row where some elbow angle satisfies the
/// elbow and forearm-elevation rows; the forearm elevation's row where some shoulder
/// angle allows it; the claw's 0 … 1. `(lo, hi)` with lo > hi when none.
pub fn input_range(config: &ArmConfig, servo: ServoId) -> (f64, f64) {
    let l = &config.limits_deg;
    match servo {
        ServoId::Base => (l.base[0], l.base[1]),
        ServoId::Shoulder => (
            l.shoulder[0].max(l.forearm_elevation[0] - l.elbow[1]),
            l.shoulder[1].min(l.forearm_elevation[1] - l.elbow[0]),
        ),
        ServoId::Elbow => (
            l.forearm_elevation[0].max(l.shoulder[0] + l.elbow[0]),
            l.forearm_elevation[1].min(l.shoulder[1] + l.elbow[1]),
        ),
        ServoId::Gripper => (0.0, 1.0),
    }
}

/// What a servo's input measures, for messages.
pub fn input_name(servo: ServoId) -> &'static str {
    servo.of([
        "base_joint",
        "shoulder_joint",
        "forearm elevation φ",
        "claw opening",
    ])
}

/// An input value with its unit: degrees, or the claw's opening 0 … 1.
fn show(servo: ServoId, input: f64) -> String {
    match servo {
        ServoId::Gripper => format!("{input:.2}"),
        _ => format!("{input:.2}°"),
    }
}

/// A pose the user can recognise on a real arm: a servo's input there and how to see it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reference {
    /// The servo's input at this pose (deg; the claw: opening 0 … 1).
    pub input: f64,
    /// What the user looks for.
    pub description: &'static str,
}

/// A joint that must be held while another servo is calibrated, so that its references
/// lie inside every limit row (the forearm cannot point 45° down with the main arm
/// leaning far forward).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hold {
    /// The servo that holds it.
    pub servo: ServoId,
    /// Its input to command.
    pub input: f64,
    /// The inputs (lo, hi) at which both references of the servo being calibrated are
    /// within every limit row.
    pub allowed: (f64, f64),
    /// True when `servo` is calibrated earlier in [`CALIBRATION_ORDER`] (command `input`
    /// through its new calibration); false when it is not yet: then `input` is its
    /// [`home_input`], commanded as the shipped calibration's angle there, which holds it
    /// within [`HORN_MARGIN_DEG`] / |gain| of home however it is mounted.
    pub calibrated_first: bool,
    /// What the user sees.
    pub description: &'static str,
}

/// Servo angles (deg) the wizard may command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JogRange {
    /// Lowest.
    pub min_deg: f64,
    /// Highest.
    pub max_deg: f64,
}

impl JogRange {
    /// Whether `deg` is inside.
    pub fn contains(&self, deg: f64) -> bool {
        (self.min_deg..=self.max_deg).contains(&deg)
    }

    /// `deg` clamped inside.
    pub fn clamp(&self, deg: f64) -> f64 {
        deg.clamp(self.min_deg, self.max_deg)
    }

    fn hull(values: &[f64], slack: f64) -> JogRange {
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        JogRange {
            min_deg: (lo - slack).clamp(0.0, 180.0),
            max_deg: (hi + slack).clamp(0.0, 180.0),
        }
    }

    fn intersect(self, other: JogRange) -> JogRange {
        let min_deg = self.min_deg.max(other.min_deg);
        let max_deg = self.max_deg.min(other.max_deg);
        if min_deg <= max_deg {
            JogRange { min_deg, max_deg }
        } else {
            // disjoint: keep the first (never for the plans of this module)
            self
        }
    }
}

/// The wizard's plan for one servo.
#[derive(Clone, Debug, PartialEq)]
pub struct ServoPlan {
    /// The servo.
    pub servo: ServoId,
    /// Reference A (the home input: mark it first) and reference B.
    pub references: [Reference; 2],
    /// Another pose the user may mark instead of B when B is out of the servo's reach.
    pub alternative_b: Option<Reference>,
    /// Joints to pose first.
    pub holds: Vec<Hold>,
    /// The servo's input range under the configuration's limits ([`input_range`]).
    pub input_range: (f64, f64),
}

impl ServoPlan {
    /// The servo angle the wizard starts at: the shipped calibration's angle at
    /// [`home_input`] (reference A), the same whichever way the servo is mounted.
    pub fn start_deg(&self) -> f64 {
        let c = ServoCalibrations::default();
        let c = c.get(self.servo);
        c.offset_deg + c.gain * home_input(self.servo)
    }

    /// The jog range before anything is marked: [`Self::start_deg`] ± [`HORN_MARGIN_DEG`],
    /// where every plausibly assembled arm shows reference A, either direction. Jogging
    /// here also shows which way the servo turns the joint
    /// ([`Direction::from_observation`]).
    pub fn first_jog_range(&self) -> JogRange {
        JogRange::hull(&[self.start_deg()], HORN_MARGIN_DEG)
    }

    /// The jog range once reference A is marked at `mark_a_deg` and the direction is
    /// known, towards the reference whose input is `b_input` (B or the alternative):
    /// where B lies for any gain within `tolerances` in that direction, plus
    /// [`JOG_SLACK_DEG`], but no further than the joint's limits at the shipped |gain|
    /// plus [`JOG_GAIN_SPREAD`] (plus the slack); inside 0 … 180°. For a servo that cannot reverse the direction is
    /// ignored.
    pub fn second_jog_range(
        &self,
        mark_a_deg: f64,
        b_input: f64,
        direction: Direction,
        tolerances: &Tolerances,
    ) -> JogRange {
        let direction = if is_reversible(self.servo) {
            direction
        } else {
            Direction::AsShipped
        };
        let g = expected_gain(self.servo) * direction.sign();
        let x_a = self.references[0].input;
        let tol = tolerances.gain(self.servo);
        let toward_b = JogRange::hull(
            &[
                mark_a_deg,
                mark_a_deg + (1.0 - tol) * g * (b_input - x_a),
                mark_a_deg + (1.0 + tol) * g * (b_input - x_a),
            ],
            JOG_SLACK_DEG,
        );
        let (lo, hi) = self.input_range;
        let spread = 1.0 + JOG_GAIN_SPREAD;
        let limits = JogRange::hull(
            &[
                mark_a_deg + spread * g * (lo - x_a),
                mark_a_deg + spread * g * (hi - x_a),
            ],
            JOG_SLACK_DEG,
        );
        toward_b.intersect(limits)
    }
}

/// The wizard's plan: every servo's references, holds and jog ranges, checked against a
/// configuration's limits.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationPlan {
    /// One per servo, in [`CALIBRATION_ORDER`].
    pub steps: [ServoPlan; 4],
}

impl CalibrationPlan {
    /// The plan for an arm with `config`'s limits. Refused when a reference lies outside
    /// them or the holds cannot make both references of a servo reachable.
    ///
    /// With the shipped limits: base 0° and 45° left (alternative 45° right; ±45° is the
    /// base's range); forearm φ = 0° (horizontal) and −45° (45° down), both within every
    /// row for a main arm between 60° and 100°, held at its home 90°; main arm 90°
    /// (vertical) and 45° (leaning 45° forward; its range is 42.5° … 125°), both within
    /// every row for a forearm between −55° and −15°, held at −35°; claw closed (0) and
    /// fully open (1).
    pub fn new(config: &ArmConfig) -> Result<CalibrationPlan, CalibrationError> {
        let l = &config.limits_deg;
        let reference = |input, description| Reference { input, description };
        let base = [
            reference(
                0.0,
                "base straight ahead: the arm points along the base's front",
            ),
            reference(
                45.0,
                "base turned 45° left (counter-clockwise seen from above)",
            ),
        ];
        let elbow = [
            reference(0.0, "forearm horizontal"),
            reference(-45.0, "forearm 45° below horizontal (its tip down)"),
        ];
        let shoulder = [
            reference(90.0, "main arm vertical"),
            reference(45.0, "main arm leaning 45° forward (45° above horizontal)"),
        ];
        let gripper = [
            reference(0.0, "claw closed: the fingers just touch"),
            reference(1.0, "claw fully open: the fingers as far apart as they go"),
        ];
        // the main-arm angles at which both forearm references satisfy every row
        let (phi_lo, phi_hi) = (
            elbow[1].input.min(elbow[0].input),
            elbow[0].input.max(elbow[1].input),
        );
        let alpha_window = (
            l.shoulder[0].max(phi_hi - l.elbow[1]),
            l.shoulder[1].min(phi_lo - l.elbow[0]),
        );
        // the forearm elevations at which both main-arm references satisfy every row
        let (a_lo, a_hi) = (
            shoulder[1].input.min(shoulder[0].input),
            shoulder[0].input.max(shoulder[1].input),
        );
        let phi_window = (
            l.forearm_elevation[0].max(a_hi + l.elbow[0]),
            l.forearm_elevation[1].min(a_lo + l.elbow[1]),
        );
        let steps = [
            ServoPlan {
                servo: ServoId::Base,
                references: base,
                alternative_b: Some(reference(
                    -45.0,
                    "base turned 45° right (clockwise seen from above)",
                )),
                holds: vec![],
                input_range: input_range(config, ServoId::Base),
            },
            ServoPlan {
                servo: ServoId::Elbow,
                references: elbow,
                alternative_b: None,
                holds: vec![Hold {
                    servo: ServoId::Shoulder,
                    input: home_input(ServoId::Shoulder),
                    allowed: alpha_window,
                    calibrated_first: false,
                    description: "main arm vertical (its servo at the shipped home angle)",
                }],
                input_range: input_range(config, ServoId::Elbow),
            },
            ServoPlan {
                servo: ServoId::Shoulder,
                references: shoulder,
                alternative_b: None,
                holds: vec![Hold {
                    servo: ServoId::Elbow,
                    input: (phi_window.0 + phi_window.1) / 2.0,
                    allowed: phi_window,
                    calibrated_first: true,
                    description: "forearm pointing down, midway between the elevations both references allow (−35° with the shipped limits)",
                }],
                input_range: input_range(config, ServoId::Shoulder),
            },
            ServoPlan {
                servo: ServoId::Gripper,
                references: gripper,
                alternative_b: None,
                holds: vec![],
                input_range: input_range(config, ServoId::Gripper),
            },
        ];
        for step in &steps {
            let (lo, hi) = step.input_range;
            for r in step.references.iter().chain(&step.alternative_b) {
                if !(lo..=hi).contains(&r.input) {
                    return Err(CalibrationError::ReferenceUnreachable {
                        servo: step.servo,
                        why: format!(
                            "reference \"{}\" ({} = {}) is outside the range {} … {} that the limits allow",
                            r.description,
                            input_name(step.servo),
                            show(step.servo, r.input),
                            show(step.servo, lo),
                            show(step.servo, hi)
                        ),
                    });
                }
            }
            for h in &step.holds {
                let (lo, hi) = h.allowed;
                // an uncalibrated servo holds within the horn margin of its home input
                let spread = if h.calibrated_first {
                    0.0
                } else {
                    HORN_MARGIN_DEG / expected_gain(h.servo).abs()
                };
                if !(lo <= h.input - spread && h.input + spread <= hi) {
                    return Err(CalibrationError::ReferenceUnreachable {
                        servo: step.servo,
                        why: format!(
                            "both references need {} within {} … {}, which holding it at {} (± {}) does not guarantee",
                            input_name(h.servo),
                            show(h.servo, lo),
                            show(h.servo, hi),
                            show(h.servo, h.input),
                            show(h.servo, spread)
                        ),
                    });
                }
            }
        }
        Ok(CalibrationPlan { steps })
    }

    /// The plan of one servo.
    pub fn get(&self, servo: ServoId) -> &ServoPlan {
        let i = servo.of([0, 2, 1, 3]);
        &self.steps[i]
    }
}

/// One mark: the servo angle at which the arm showed a reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mark {
    /// The reference's input (deg; the claw: opening 0 … 1).
    pub input: f64,
    /// The servo angle the user marked (deg, 0 … 180).
    pub servo_deg: f64,
}

impl Mark {
    /// A mark.
    pub fn new(input: f64, servo_deg: f64) -> Mark {
        Mark { input, servo_deg }
    }
}

/// A derived calibration and what was learnt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Derived {
    /// The servo.
    pub servo: ServoId,
    /// The new calibration: offset and gain from the marks; `min_deg`/`max_deg` and the
    /// pulse widths from the previous calibration, except the claw's `min_deg`/`max_deg`,
    /// which become its closed and open angles (they mean exactly that).
    pub calibration: ServoCalibration,
    /// Which way the servo turns its joint.
    pub direction: Direction,
    /// |gain| / |shipped gain|.
    pub gain_ratio: f64,
    /// The servo angles (lo, hi) of the two ends of the input range.
    pub range_deg: (f64, f64),
    /// The part of the input range the servo reaches (the whole range unless up to
    /// `max_uncovered_deg` of it lies outside the servo's allowed angles).
    pub reachable_input: (f64, f64),
}

impl Derived {
    /// Whether part of the input range is out of the servo's reach.
    pub fn is_clipped(&self, config: &ArmConfig) -> bool {
        self.reachable_input != input_range(config, self.servo)
    }
}

/// Why a calibration, a plan or a leader channel was refused. Every message names the
/// servo and the numbers.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum CalibrationError {
    /// A mark, reading or input is NaN or infinite.
    NonFinite {
        /// the servo
        servo: ServoId,
        /// which value
        what: &'static str,
    },
    /// A reference's input lies outside the servo's input range.
    InputOutsideRange {
        /// the servo
        servo: ServoId,
        /// the input
        input: f64,
        /// the range's low end
        min: f64,
        /// the range's high end
        max: f64,
    },
    /// The two references are too close to give a gain.
    ReferencesTooClose {
        /// the servo
        servo: ServoId,
        /// reference A's input
        input_a: f64,
        /// reference B's input
        input_b: f64,
        /// the smallest separation, in servo degrees at the shipped gain
        min_deg: f64,
    },
    /// A mark outside the 0 … 180° the Servo library can command.
    MarkOutsideServo {
        /// the servo
        servo: ServoId,
        /// the mark
        servo_deg: f64,
    },
    /// The two marks are too close to give a gain.
    MarksTooClose {
        /// the servo
        servo: ServoId,
        /// mark A
        deg_a: f64,
        /// mark B
        deg_b: f64,
        /// the smallest separation
        min_deg: f64,
    },
    /// The marks turn the joint the other way round, which this servo's mounting cannot.
    Reversed {
        /// the servo
        servo: ServoId,
        /// the derived gain
        gain: f64,
        /// the shipped gain
        expected: f64,
    },
    /// |gain| too far from the shipped one.
    GainImplausible {
        /// the servo
        servo: ServoId,
        /// the derived gain
        gain: f64,
        /// the shipped gain
        expected: f64,
        /// the tolerance (fraction)
        tolerance: f64,
    },
    /// Part of the input range maps outside the servo's allowed angles.
    RangeOutsideServo {
        /// the servo
        servo: ServoId,
        /// the input range's low end and its servo angle
        lo: (f64, f64),
        /// the input range's high end and its servo angle
        hi: (f64, f64),
        /// the allowed servo angles
        allowed: (f64, f64),
        /// how many servo degrees are out of reach
        uncovered_deg: f64,
        /// the most allowed
        max_uncovered_deg: f64,
    },
    /// The plan's references or holds do not fit the configuration's limits.
    ReferenceUnreachable {
        /// the servo
        servo: ServoId,
        /// why
        why: String,
    },
    /// A leader reading outside 0 … adc_max.
    LeaderOutsideAdc {
        /// the channel
        servo: ServoId,
        /// the reading
        counts: f64,
        /// the full scale
        adc_max: u16,
    },
    /// A leader reading at (or within the margin of) a rail.
    LeaderAtRail {
        /// the channel
        servo: ServoId,
        /// the reading
        counts: f64,
        /// the margin (counts)
        margin: f64,
        /// the full scale
        adc_max: u16,
    },
    /// The two leader readings are too close to give a slope.
    LeaderReadingsTooClose {
        /// the channel
        servo: ServoId,
        /// reading A
        counts_a: f64,
        /// reading B
        counts_b: f64,
        /// the smallest difference
        min_counts: f64,
    },
    /// An end of the input range lies outside the ADC's span.
    LeaderRangeOutsideAdc {
        /// the channel
        servo: ServoId,
        /// the end of the input range
        input: f64,
        /// the reading it extrapolates to
        counts: f64,
        /// the full scale
        adc_max: u16,
    },
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use CalibrationError as E;
        match self {
            E::NonFinite { servo, what } => {
                write!(f, "{}: {what} is not a finite number", servo.name())
            }
            E::InputOutsideRange {
                servo,
                input,
                min,
                max,
            } => write!(
                f,
                "{}: a reference at {} = {} is outside the range {} … {} the joint limits allow",
                servo.name(),
                input_name(*servo),
                show(*servo, *input),
                show(*servo, *min),
                show(*servo, *max)
            ),
            E::ReferencesTooClose {
                servo,
                input_a,
                input_b,
                min_deg,
            } => write!(
                f,
                "{}: the references {} and {} are too close to give a gain (they must be at least {min_deg:.1} servo degrees apart)",
                servo.name(),
                show(*servo, *input_a),
                show(*servo, *input_b)
            ),
            E::MarkOutsideServo { servo, servo_deg } => write!(
                f,
                "{}: a mark at {servo_deg:.2}° is outside the servo's 0 … 180°",
                servo.name()
            ),
            E::MarksTooClose {
                servo,
                deg_a,
                deg_b,
                min_deg,
            } => write!(
                f,
                "{}: the marks {deg_a:.2}° and {deg_b:.2}° are less than {min_deg:.1}° apart: no usable gain (was the same pose marked twice, or did the servo not move?)",
                servo.name()
            ),
            E::Reversed {
                servo,
                gain,
                expected,
            } => write!(
                f,
                "{}: the marks give gain {gain:.3}, the opposite direction of the shipped {expected:.3}, which this servo's mounting cannot produce: were the two references swapped (left and right, open and closed)?",
                servo.name()
            ),
            E::GainImplausible {
                servo,
                gain,
                expected,
                tolerance,
            } => write!(
                f,
                "{}: the marks give gain {gain:.3} ({:.0} % of the expected {:.3}), outside ±{:.0} %: a reference marked at the wrong pose, or a different servo or gear?",
                servo.name(),
                100.0 * gain.abs() / expected.abs(),
                expected.abs(),
                100.0 * tolerance
            ),
            E::RangeOutsideServo {
                servo,
                lo,
                hi,
                allowed,
                uncovered_deg,
                max_uncovered_deg,
            } => {
                write!(
                    f,
                    "{}: {} {} would need the servo at {:.2}° and {} at {:.2}°, but it may only turn within {:.2} … {:.2}°: {uncovered_deg:.2}° of the range out of reach (at most {max_uncovered_deg:.2}° allowed)",
                    servo.name(),
                    input_name(*servo),
                    show(*servo, lo.0),
                    lo.1,
                    show(*servo, hi.0),
                    hi.1,
                    allowed.0,
                    allowed.1
                )?;
                let out = |deg: f64| deg < allowed.0 || deg > allowed.1;
                if out(lo.1) && out(hi.1) {
                    write!(f, "; the servo cannot cover this range: narrow the joint limits")
                } else {
                    write!(
                        f,
                        "; re-seat the horn one spline tooth (14.4°) towards the other end, or narrow the joint limits"
                    )
                }
            }
            E::ReferenceUnreachable { servo, why } => {
                write!(f, "{}: cannot calibrate with these limits: {why}", servo.name())
            }
            E::LeaderOutsideAdc {
                servo,
                counts,
                adc_max,
            } => write!(
                f,
                "leader {}: reading {counts:.1} is outside the ADC's 0 … {adc_max}",
                input_name(*servo)
            ),
            E::LeaderAtRail {
                servo,
                counts,
                margin,
                adc_max,
            } => write!(
                f,
                "leader {}: reading {counts:.1} is within {margin:.0} counts of a rail (0 or {adc_max}): a potentiometer at its end stop or a broken wire reads that whatever the joint does",
                input_name(*servo)
            ),
            E::LeaderReadingsTooClose {
                servo,
                counts_a,
                counts_b,
                min_counts,
            } => write!(
                f,
                "leader {}: readings {counts_a:.1} and {counts_b:.1} differ by less than {min_counts:.0} counts: is the potentiometer turning with the joint?",
                servo.name()
            ),
            E::LeaderRangeOutsideAdc {
                servo,
                input,
                counts,
                adc_max,
            } => write!(
                f,
                "leader {}: at {} the potentiometer would read {counts:.1}, outside the ADC's 0 … {adc_max}: it saturates before the joint reaches its limit (turn the potentiometer on its shaft towards the middle)",
                input_name(*servo),
                show(*servo, *input)
            ),
        }
    }
}

impl std::error::Error for CalibrationError {}

fn finite(servo: ServoId, what: &'static str, v: f64) -> Result<f64, CalibrationError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(CalibrationError::NonFinite { servo, what })
    }
}

/// The two reference inputs: finite, inside the input range, far enough apart.
fn check_references(
    config: &ArmConfig,
    servo: ServoId,
    input_a: f64,
    input_b: f64,
    tolerances: &Tolerances,
) -> Result<(), CalibrationError> {
    finite(servo, "reference A's input", input_a)?;
    finite(servo, "reference B's input", input_b)?;
    let (min, max) = input_range(config, servo);
    for input in [input_a, input_b] {
        if !(min..=max).contains(&input) {
            return Err(CalibrationError::InputOutsideRange {
                servo,
                input,
                min,
                max,
            });
        }
    }
    let min_deg = tolerances.min_mark_separation_deg;
    if (input_b - input_a).abs() * expected_gain(servo).abs() < min_deg {
        return Err(CalibrationError::ReferencesTooClose {
            servo,
            input_a,
            input_b,
            min_deg,
        });
    }
    Ok(())
}

/// Derive one servo's calibration from its two marks.
///
/// gain = Δservo / Δinput, offset = servo_A − gain · input_A, direction = the sign of
/// the gain against the shipped one. Checked in this order: finite values; reference
/// inputs inside [`input_range`] and far enough apart; marks inside 0 … 180° and at least
/// `min_mark_separation_deg` apart; the direction (only [`is_reversible`] servos may
/// reverse); |gain| within the tolerance of the shipped |gain|; the input range mapped
/// inside the allowed angles (0 … 180° and the previous `min_deg`/`max_deg`; for the
/// claw 0 … 180°) but for at most `max_uncovered_deg`.
pub fn derive(
    config: &ArmConfig,
    servo: ServoId,
    marks: [Mark; 2],
    previous: &ServoCalibration,
    tolerances: &Tolerances,
) -> Result<Derived, CalibrationError> {
    let [a, b] = marks;
    finite(servo, "mark A", a.servo_deg)?;
    finite(servo, "mark B", b.servo_deg)?;
    check_references(config, servo, a.input, b.input, tolerances)?;
    for m in [a, b] {
        if !(0.0..=180.0).contains(&m.servo_deg) {
            return Err(CalibrationError::MarkOutsideServo {
                servo,
                servo_deg: m.servo_deg,
            });
        }
    }
    let min_deg = tolerances.min_mark_separation_deg;
    if (b.servo_deg - a.servo_deg).abs() < min_deg {
        return Err(CalibrationError::MarksTooClose {
            servo,
            deg_a: a.servo_deg,
            deg_b: b.servo_deg,
            min_deg,
        });
    }
    let gain = (b.servo_deg - a.servo_deg) / (b.input - a.input);
    let offset_deg = a.servo_deg - gain * a.input;
    let expected = expected_gain(servo);
    let direction = Direction::of_gain(servo, gain);
    if direction == Direction::Reversed && !is_reversible(servo) {
        return Err(CalibrationError::Reversed {
            servo,
            gain,
            expected,
        });
    }
    let gain_ratio = gain.abs() / expected.abs();
    let tolerance = tolerances.gain(servo);
    if !((1.0 - tolerance)..=(1.0 + tolerance)).contains(&gain_ratio) {
        return Err(CalibrationError::GainImplausible {
            servo,
            gain,
            expected,
            tolerance,
        });
    }
    let (x_lo, x_hi) = input_range(config, servo);
    let at = |x: f64| offset_deg + gain * x;
    let (s_lo, s_hi) = (at(x_lo), at(x_hi));
    let mut calibration = ServoCalibration {
        offset_deg,
        gain,
        ..*previous
    };
    let allowed = if servo == ServoId::Gripper {
        // the claw's allowed range is its closed … open, as in the shipped file
        calibration.min_deg = s_lo.min(s_hi).clamp(0.0, 180.0);
        calibration.max_deg = s_lo.max(s_hi).clamp(0.0, 180.0);
        (0.0, 180.0)
    } else {
        (previous.min_deg.max(0.0), previous.max_deg.min(180.0))
    };
    let below = |s: f64| (allowed.0 - s).max(0.0);
    let above = |s: f64| (s - allowed.1).max(0.0);
    let uncovered_deg = below(s_lo.min(s_hi)) + above(s_lo.max(s_hi));
    if uncovered_deg > tolerances.max_uncovered_deg {
        return Err(CalibrationError::RangeOutsideServo {
            servo,
            lo: (x_lo, s_lo),
            hi: (x_hi, s_hi),
            allowed,
            uncovered_deg,
            max_uncovered_deg: tolerances.max_uncovered_deg,
        });
    }
    // the inputs whose servo angle is allowed
    let input_at = |s: f64| (s - offset_deg) / gain;
    let (r0, r1) = (input_at(allowed.0), input_at(allowed.1));
    let reachable_input = if uncovered_deg > 0.0 {
        (x_lo.max(r0.min(r1)), x_hi.min(r0.max(r1)))
    } else {
        (x_lo, x_hi)
    };
    Ok(Derived {
        servo,
        calibration,
        direction,
        gain_ratio,
        range_deg: (s_lo.min(s_hi), s_lo.max(s_hi)),
        reachable_input,
    })
}

/// Derive all four servos (marks in [`ServoId::ALL`] order) into a new
/// [`ServoCalibrations`]; the first refusal is returned.
pub fn derive_all(
    config: &ArmConfig,
    marks: [[Mark; 2]; 4],
    previous: &ServoCalibrations,
    tolerances: &Tolerances,
) -> Result<(ServoCalibrations, [Derived; 4]), CalibrationError> {
    let mut out = *previous;
    let mut derived = Vec::with_capacity(4);
    for (servo, m) in ServoId::ALL.into_iter().zip(marks) {
        let d = derive(config, servo, m, previous.get(servo), tolerances)?;
        *servo.of([
            &mut out.base,
            &mut out.shoulder,
            &mut out.elbow,
            &mut out.gripper,
        ]) = d.calibration;
        derived.push(d);
    }
    let derived: [Derived; 4] = match derived.try_into() {
        Ok(d) => d,
        Err(_) => unreachable!("four servos"),
    };
    Ok((out, derived))
}

// ---------------------------------------------------------------- leader potentiometers

/// One leader reading: the ADC counts at a reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeaderReading {
    /// The reference's input.
    pub input: f64,
    /// The ADC reading there (counts; an average may be fractional).
    pub counts: f64,
}

/// Derive a leader channel from two readings at two references (the same references as
/// the servos'). Refused: non-finite values; references outside the input range or too
/// close; a reading outside 0 … `adc_max` or within `leader_rail_fraction` of a rail; two
/// readings less than `leader_min_separation_fraction` of the full scale apart; an end of
/// the input range that extrapolates outside 0 … `adc_max` (the potentiometer would
/// saturate before the joint reaches its limit).
pub fn derive_leader(
    config: &ArmConfig,
    servo: ServoId,
    readings: [LeaderReading; 2],
    adc_max: u16,
    tolerances: &Tolerances,
) -> Result<LeaderChannel, CalibrationError> {
    let [a, b] = readings;
    finite(servo, "reading A", a.counts)?;
    finite(servo, "reading B", b.counts)?;
    check_references(config, servo, a.input, b.input, tolerances)?;
    let full = f64::from(adc_max);
    let margin = tolerances.leader_rail_fraction * full;
    for r in [a, b] {
        if !(0.0..=full).contains(&r.counts) {
            return Err(CalibrationError::LeaderOutsideAdc {
                servo,
                counts: r.counts,
                adc_max,
            });
        }
        if r.counts < margin || r.counts > full - margin {
            return Err(CalibrationError::LeaderAtRail {
                servo,
                counts: r.counts,
                margin,
                adc_max,
            });
        }
    }
    let min_counts = tolerances.leader_min_separation_fraction * full;
    if (b.counts - a.counts).abs() < min_counts {
        return Err(CalibrationError::LeaderReadingsTooClose {
            servo,
            counts_a: a.counts,
            counts_b: b.counts,
            min_counts,
        });
    }
    let channel = LeaderChannel {
        counts_a: a.counts,
        input_a: a.input,
        counts_b: b.counts,
        input_b: b.input,
    };
    let (lo, hi) = input_range(config, servo);
    for input in [lo, hi] {
        let counts = channel.counts(input);
        if !(0.0..=full).contains(&counts) {
            return Err(CalibrationError::LeaderRangeOutsideAdc {
                servo,
                input,
                counts,
                adc_max,
            });
        }
    }
    Ok(channel)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn shipped() -> ArmConfig {
        ArmConfig::shipped().unwrap()
    }

    /// A simulated arm's servo: where its horn really puts the joint.
    #[derive(Clone, Copy, Debug)]
    struct TrueServo {
        offset_deg: f64,
        gain: f64,
    }

    impl TrueServo {
        /// Horn seated `e` servo degrees off the shipped home angle, gain `k` times the
        /// shipped magnitude, turning `direction`, mirrored about the home pose.
        fn new(servo: ServoId, e: f64, k: f64, direction: Direction) -> TrueServo {
            let gain = expected_gain(servo) * k * direction.sign();
            let home_deg = plan().get(servo).start_deg() + e;
            TrueServo {
                offset_deg: home_deg - gain * home_input(servo),
                gain,
            }
        }
        /// The servo angle at which the horn shows `input` (the user's mark).
        fn mark(&self, input: f64) -> Mark {
            Mark::new(input, self.offset_deg + self.gain * input)
        }
        /// The input the horn shows at a servo angle.
        fn input_at(&self, deg: f64) -> f64 {
            (deg - self.offset_deg) / self.gain
        }
    }

    fn plan() -> CalibrationPlan {
        CalibrationPlan::new(&shipped()).unwrap()
    }

    fn derive_default(servo: ServoId, marks: [Mark; 2]) -> Result<Derived, CalibrationError> {
        let c = shipped();
        derive(
            &c,
            servo,
            marks,
            c.servos.get(servo),
            &Tolerances::default(),
        )
    }

    /// Every input in the reachable range, commanded through `d`, lands within `eps` of
    /// itself on the true arm.
    fn assert_exact(servo: ServoId, d: &Derived, truth: &TrueServo, eps: f64) {
        let (lo, hi) = d.reachable_input;
        assert!(lo < hi, "{d:?}");
        for i in 0..=200 {
            let x = lo + (hi - lo) * f64::from(i) / 200.0;
            let deg = d.calibration.angle_deg(servo, x).unwrap();
            let shown = truth.input_at(deg);
            assert!(
                (shown - x).abs() < eps,
                "{servo:?}: {x} shows {shown} ({d:?})"
            );
        }
    }

    #[test]
    fn references_are_inside_the_shipped_limits_and_holds_reach_them() {
        let c = shipped();
        let p = plan();
        let order: Vec<ServoId> = p.steps.iter().map(|s| s.servo).collect();
        assert_eq!(order, CALIBRATION_ORDER);
        // the forearm's references with the main arm anywhere in 80 … 100° (home ± the
        // horn margin): every limit row holds
        let e = p.get(ServoId::Elbow);
        assert_eq!(e.holds[0].allowed, (60.0, 100.0));
        let limits = c.arm().limits;
        for alpha in [80.0f64, 90.0, 100.0] {
            for phi in [0.0f64, -45.0] {
                let q = crate::ArmJoints {
                    base_rad: 0.0,
                    shoulder_rad: alpha.to_radians(),
                    elbow_rad: (phi - alpha).to_radians(),
                };
                assert!(limits.check(&q).is_ok(), "α {alpha} φ {phi}");
            }
        }
        // the main arm's references with the forearm held at −35°
        let s = p.get(ServoId::Shoulder);
        assert_eq!(s.holds[0].allowed, (-55.0, -15.0));
        assert_eq!(s.holds[0].input, -35.0);
        for alpha in [90.0f64, 45.0] {
            let q = crate::ArmJoints {
                base_rad: 0.0,
                shoulder_rad: alpha.to_radians(),
                elbow_rad: (-35.0 - alpha).to_radians(),
            };
            assert!(limits.check(&q).is_ok(), "α {alpha}");
        }
        // the horizontal main arm of the issue is out of range: a plan using it is refused
        let mut tight = c.clone();
        tight.limits_deg.shoulder = [50.0, 125.0];
        let err = CalibrationPlan::new(&tight).unwrap_err();
        assert!(err.to_string().contains("main arm leaning 45°"), "{err}");
        assert_eq!(p.get(ServoId::Shoulder).input_range, (42.5, 125.0));
        assert_eq!(p.get(ServoId::Elbow).input_range, (-65.0, 20.0));
    }

    #[test]
    fn jog_ranges_reach_every_plausible_arm_s_references() {
        let p = plan();
        let tol = Tolerances::default();
        assert_eq!(
            p.get(ServoId::Base).first_jog_range(),
            JogRange {
                min_deg: 80.0,
                max_deg: 100.0
            }
        );
        assert_eq!(
            p.get(ServoId::Gripper).first_jog_range(),
            JogRange {
                min_deg: 50.0,
                max_deg: 70.0
            }
        );
        for servo in ServoId::ALL {
            let plan = p.get(servo);
            let dirs: &[Direction] = if is_reversible(servo) {
                &[Direction::AsShipped, Direction::Reversed]
            } else {
                &[Direction::AsShipped]
            };
            for &dir in dirs {
                // (just inside the margin: the window's ends are exact, the marks rounded)
                for e in [
                    -HORN_MARGIN_DEG + 0.01,
                    -7.0,
                    0.0,
                    7.0,
                    HORN_MARGIN_DEG - 0.01,
                ] {
                    for k in [0.9, 1.0, 1.05] {
                        let t = TrueServo::new(servo, e, k, dir);
                        let a = t.mark(plan.references[0].input).servo_deg;
                        assert!(plan.first_jog_range().contains(a), "{servo:?} {e} {k}");
                        // B, or the alternative, wherever the servo can show it
                        // B, or the alternative, wherever the servo can show it (the claw
                        // opens as far as the servo goes)
                        let bs = [Some(plan.references[1]), plan.alternative_b];
                        let reachable: Vec<(f64, f64)> = bs
                            .iter()
                            .flatten()
                            .map(|r| (r.input, t.mark(r.input).servo_deg))
                            .map(|(x, deg)| {
                                if servo == ServoId::Gripper {
                                    (x, deg.min(180.0))
                                } else {
                                    (x, deg)
                                }
                            })
                            .filter(|(_, deg)| (0.0..=180.0).contains(deg))
                            .collect();
                        assert!(!reachable.is_empty() || k > 1.0, "{servo:?} {e} {k}");
                        for (x_b, b) in reachable {
                            let range = plan.second_jog_range(a, x_b, dir, &tol);
                            assert!(
                                range.contains(b),
                                "{servo:?} e {e} k {k} {dir:?}: {b} not in {range:?}"
                            );
                            // and the arm is driven no further past its limits than the
                            // gain spread and the slack allow
                            let (lo, hi) = plan.input_range;
                            let g = expected_gain(servo).abs();
                            let d = (hi - lo) * ((1.0 + JOG_GAIN_SPREAD) / k - 1.0).max(0.0)
                                + JOG_SLACK_DEG / (k * g)
                                + 1e-9;
                            for end in [range.min_deg, range.max_deg] {
                                let x = t.input_at(end);
                                assert!(
                                    (lo - d..=hi + d).contains(&x),
                                    "{servo:?} {dir:?} e {e} k {k}: {x}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn the_issue_s_arm_offset_7_and_elbow_reversed() {
        let c = shipped();
        let p = plan();
        let mut truth = Vec::new();
        let mut marks = Vec::new();
        for servo in ServoId::ALL {
            let dir = if servo == ServoId::Elbow {
                Direction::Reversed
            } else {
                Direction::AsShipped
            };
            let t = TrueServo::new(servo, 7.0, 1.0, dir);
            let refs = p.get(servo).references;
            let mut m = [t.mark(refs[0].input), t.mark(refs[1].input)];
            if servo == ServoId::Gripper {
                // open would be at 187°: the user opens it as far as the servo goes
                assert!((m[1].servo_deg - 187.0).abs() < 1e-9);
                m[1] = Mark::new(1.0, 180.0);
            }
            truth.push(t);
            marks.push(m);
        }
        let marks: [[Mark; 2]; 4] = marks.try_into().unwrap();
        let (new, derived) = derive_all(&c, marks, &c.servos, &Tolerances::default()).unwrap();
        let [b, s, e, g] = derived;
        assert_eq!((new.base.offset_deg, new.base.gain), (97.0, -2.0));
        assert_eq!((new.shoulder.offset_deg, new.shoulder.gain), (187.0, -1.0));
        assert_eq!((new.elbow.offset_deg, new.elbow.gain), (97.0, -1.0));
        assert_eq!(e.direction, Direction::Reversed);
        assert_eq!((new.gripper.offset_deg, new.gripper.gain), (67.0, 113.0));
        assert_eq!((new.gripper.min_deg, new.gripper.max_deg), (67.0, 180.0));
        // the base's −45° would need 187°: 3.5° of its range is out of reach (refused at
        // run time, never driven)
        assert!(
            (b.reachable_input.0 + 41.5).abs() < 1e-9 && b.reachable_input.1 == 45.0,
            "{b:?}"
        );
        assert!(b.is_clipped(&c) && !s.is_clipped(&c) && !e.is_clipped(&c) && !g.is_clipped(&c));
        for (servo, d) in [
            (ServoId::Base, b),
            (ServoId::Shoulder, s),
            (ServoId::Elbow, e),
        ] {
            assert_exact(servo, &d, &truth[servo.of([0, 1, 2, 3])], 1e-9);
        }
        // the whole arm: every joint command within range lands on the modelled joint
        let arm = c.arm();
        let (lo, hi) = arm.limits.feasible_shoulder_rad().unwrap();
        for i in 0..=20 {
            for j in 0..=20 {
                let alpha = lo + (hi - lo) * f64::from(i) / 20.0;
                let q = arm.limits.clamp(&crate::ArmJoints {
                    base_rad: (-41.0 + 86.0 * f64::from(j) / 20.0).to_radians(),
                    shoulder_rad: alpha,
                    elbow_rad: -1.5 + f64::from(j) / 20.0,
                });
                let state = crate::ArmState {
                    joints: q,
                    gripper_opening: 0.5,
                };
                let rad = new.servo_angles(&state).unwrap().rad;
                let shown_base = truth[0].input_at(rad[0].to_degrees());
                let shown_alpha = truth[1].input_at(rad[1].to_degrees());
                let shown_phi = truth[2].input_at(rad[2].to_degrees());
                assert!((shown_base - q.base_rad.to_degrees()).abs() < 0.5);
                assert!((shown_alpha - q.shoulder_rad.to_degrees()).abs() < 0.5);
                assert!((shown_phi - q.forearm_elevation_rad().to_degrees()).abs() < 0.5);
            }
        }
    }

    #[test]
    fn refusals_name_the_servo_and_the_numbers() {
        // a base turning the wrong way: its gear cannot
        let err = derive_default(
            ServoId::Base,
            [Mark::new(0.0, 90.0), Mark::new(45.0, 180.0)],
        )
        .unwrap_err();
        assert!(
            matches!(
                err,
                CalibrationError::Reversed {
                    servo: ServoId::Base,
                    ..
                }
            ),
            "{err}"
        );
        assert!(
            err.to_string().contains("base_servo") && err.to_string().contains("2.000"),
            "{err}"
        );
        // a claw mounted the other way
        let err = derive_default(
            ServoId::Gripper,
            [Mark::new(0.0, 170.0), Mark::new(1.0, 50.0)],
        )
        .unwrap_err();
        assert!(
            matches!(
                err,
                CalibrationError::Reversed {
                    servo: ServoId::Gripper,
                    ..
                }
            ),
            "{err}"
        );
        // the elbow may reverse
        let d = derive_default(
            ServoId::Elbow,
            [Mark::new(0.0, 90.0), Mark::new(-45.0, 135.0)],
        )
        .unwrap();
        assert_eq!(d.direction, Direction::Reversed);
        // a 1:1 base gear: gain 1 where 2 is expected
        let err = derive_default(ServoId::Base, [Mark::new(0.0, 90.0), Mark::new(45.0, 45.0)])
            .unwrap_err();
        assert!(
            matches!(err, CalibrationError::GainImplausible { .. }),
            "{err}"
        );
        assert!(
            err.to_string().contains("50 %") && err.to_string().contains("±20 %"),
            "{err}"
        );
        // a 60° pose marked as 45°: +33 %
        let err = derive_default(
            ServoId::Shoulder,
            [Mark::new(90.0, 90.0), Mark::new(45.0, 150.0)],
        )
        .unwrap_err();
        assert!(
            matches!(err, CalibrationError::GainImplausible { .. }),
            "{err}"
        );
        // the same pose marked twice
        let err = derive_default(
            ServoId::Shoulder,
            [Mark::new(90.0, 90.0), Mark::new(45.0, 93.0)],
        )
        .unwrap_err();
        assert!(
            matches!(err, CalibrationError::MarksTooClose { .. }),
            "{err}"
        );
        assert!(err.to_string().contains("93.00°"), "{err}");
        // references too close or out of range
        let err = derive_default(
            ServoId::Shoulder,
            [Mark::new(90.0, 90.0), Mark::new(88.0, 95.0)],
        )
        .unwrap_err();
        assert!(
            matches!(err, CalibrationError::ReferencesTooClose { .. }),
            "{err}"
        );
        let err = derive_default(
            ServoId::Shoulder,
            [Mark::new(90.0, 90.0), Mark::new(0.0, 180.0)],
        )
        .unwrap_err();
        assert!(
            matches!(err, CalibrationError::InputOutsideRange { .. }),
            "{err}"
        );
        assert!(err.to_string().contains("42.50°"), "{err}");
        let err = derive_default(
            ServoId::Shoulder,
            [Mark::new(90.0, 90.0), Mark::new(45.0, 181.0)],
        )
        .unwrap_err();
        assert!(
            matches!(err, CalibrationError::MarkOutsideServo { .. }),
            "{err}"
        );
        let err = derive_default(
            ServoId::Shoulder,
            [Mark::new(90.0, f64::NAN), Mark::new(45.0, 135.0)],
        )
        .unwrap_err();
        assert!(matches!(err, CalibrationError::NonFinite { .. }), "{err}");
        // a shoulder horn far off: 125° would need −9.5°
        let err = derive_default(
            ServoId::Shoulder,
            [Mark::new(90.0, 25.5), Mark::new(45.0, 70.5)],
        )
        .unwrap_err();
        let text = err.to_string();
        assert!(
            matches!(err, CalibrationError::RangeOutsideServo { .. }),
            "{text}"
        );
        assert!(
            text.contains("125.00°") && text.contains("-9.50°") && text.contains("re-seat"),
            "{text}"
        );
        // a base whose gain is 10 % high cannot cover ±45°: both ends out
        let err = derive_default(ServoId::Base, [Mark::new(0.0, 90.0), Mark::new(30.0, 24.0)])
            .unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("narrow the joint limits") && !text.contains("re-seat"),
            "{text}"
        );
        // a stricter previous range counts
        let c = shipped();
        let mut prev = c.servos.shoulder;
        prev.max_deg = 130.0;
        let err = derive(
            &c,
            ServoId::Shoulder,
            [Mark::new(90.0, 90.0), Mark::new(45.0, 135.0)],
            &prev,
            &Tolerances::default(),
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("137.50°") && err.to_string().contains("130.00°"),
            "{err}"
        );
        // and strict tolerances refuse the issue's base
        let strict = Tolerances {
            max_uncovered_deg: 0.0,
            ..Tolerances::default()
        };
        let err = derive(
            &c,
            ServoId::Base,
            [Mark::new(0.0, 97.0), Mark::new(45.0, 7.0)],
            &c.servos.base,
            &strict,
        )
        .unwrap_err();
        assert!(err.to_string().contains("187.00°"), "{err}");
    }

    #[test]
    fn derived_keeps_the_previous_range_and_pulses() {
        let c = shipped();
        let mut prev = c.servos.elbow;
        prev.pulse_min_us = 500;
        prev.pulse_max_us = 2500;
        prev.min_deg = 5.0;
        let d = derive(
            &c,
            ServoId::Elbow,
            [Mark::new(0.0, 92.0), Mark::new(-45.0, 47.0)],
            &prev,
            &Tolerances::default(),
        )
        .unwrap();
        assert_eq!(
            d.calibration,
            ServoCalibration {
                offset_deg: 92.0,
                gain: 1.0,
                ..prev
            }
        );
    }

    #[test]
    fn direction_from_observation() {
        assert_eq!(
            Direction::from_observation(ServoId::Elbow, 5.0, 5.0),
            Direction::AsShipped
        );
        assert_eq!(
            Direction::from_observation(ServoId::Elbow, 5.0, -5.0),
            Direction::Reversed
        );
        assert_eq!(
            Direction::from_observation(ServoId::Base, 5.0, -2.5),
            Direction::AsShipped
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        /// Plausible miscalibrations: the derived calibration is the true one, and it
        /// is refused only when part of the range is out of the servo's reach or a mark
        /// could not be made.
        #[test]
        fn plausible_miscalibrations_are_recovered_exactly(
            servo_i in 0usize..4,
            e in -10.0f64..10.0,
            k in 0.9f64..1.1,
            reversed in any::<bool>(),
            use_alt in any::<bool>(),
        ) {
            let servo = ServoId::ALL[servo_i];
            let c = shipped();
            let p = plan();
            let plan = p.get(servo);
            let dir = if reversed && is_reversible(servo) { Direction::Reversed } else { Direction::AsShipped };
            let t = TrueServo::new(servo, e, k, dir);
            let b = if use_alt { plan.alternative_b.unwrap_or(plan.references[1]) } else { plan.references[1] };
            let marks = [t.mark(plan.references[0].input), t.mark(b.input)];
            let got = derive(&c, servo, marks, c.servos.get(servo), &Tolerances::default());
            // what the true arm implies
            let (lo, hi) = input_range(&c, servo);
            let ends = [t.offset_deg + t.gain * lo, t.offset_deg + t.gain * hi];
            let (allowed_lo, allowed_hi) = if servo == ServoId::Gripper { (0.0, 180.0) } else {
                let s = c.servos.get(servo);
                (s.min_deg, s.max_deg)
            };
            let uncovered = (allowed_lo - ends[0].min(ends[1])).max(0.0) + (ends[0].max(ends[1]) - allowed_hi).max(0.0);
            let marks_possible = marks.iter().all(|m| (0.0..=180.0).contains(&m.servo_deg));
            match got {
                Ok(d) => {
                    prop_assert!(marks_possible && uncovered <= 7.2 + 1e-9, "{d:?}");
                    prop_assert!((d.calibration.gain - t.gain).abs() < 1e-9);
                    prop_assert!((d.calibration.offset_deg - t.offset_deg).abs() < 1e-9);
                    prop_assert_eq!(d.direction, dir);
                    assert_exact(servo, &d, &t, 0.01);
                }
                Err(CalibrationError::MarkOutsideServo { .. }) => prop_assert!(!marks_possible),
                Err(CalibrationError::RangeOutsideServo { uncovered_deg, .. }) => {
                    prop_assert!(marks_possible);
                    prop_assert!((uncovered_deg - uncovered).abs() < 1e-9 && uncovered > 7.2 - 1e-9);
                }
                Err(other) => prop_assert!(false, "{}", other),
            }
        }

        /// Implausible ones are refused: a gain beyond the tolerance, a fixed servo
        /// reversed.
        #[test]
        fn implausible_miscalibrations_are_refused(
            servo_i in 0usize..4,
            e in -5.0f64..5.0,
            k in prop_oneof![0.3f64..0.79, 1.21f64..2.0],
            reversed in any::<bool>(),
        ) {
            let servo = ServoId::ALL[servo_i];
            let c = shipped();
            let p = plan();
            let plan = p.get(servo);
            let dir = if reversed { Direction::Reversed } else { Direction::AsShipped };
            let implausible_gain = (k - 1.0).abs() > Tolerances::default().gain(servo);
            let t = TrueServo::new(servo, e, k, dir);
            // the reference B (or its alternative) the servo can show
            let Some(b) = [Some(plan.references[1]), plan.alternative_b]
                .into_iter()
                .flatten()
                .map(|r| t.mark(r.input))
                .find(|m| (0.0..=180.0).contains(&m.servo_deg))
            else {
                return Ok(());
            };
            let a = t.mark(plan.references[0].input);
            let got = derive(&c, servo, [a, b], c.servos.get(servo), &Tolerances::default());
            if dir == Direction::Reversed && !is_reversible(servo) {
                prop_assert!(matches!(got, Err(CalibrationError::Reversed { .. })), "{:?}", got);
            } else if implausible_gain {
                prop_assert!(matches!(got, Err(CalibrationError::GainImplausible { .. })), "{:?}", got);
            } else {
                // the claw within its wider tolerance
                prop_assert!(matches!(got, Ok(_) | Err(CalibrationError::RangeOutsideServo { .. })), "{:?}", got);
            }
        }

        /// Leader channels: the map goes through both readings and inverts.
        #[test]
        fn leader_channels_map_their_readings(
            servo_i in 0usize..3,
            at_a in 200.0f64..800.0,
            counts_per_deg in prop_oneof![-4.0f64..-1.0, 1.0f64..4.0],
        ) {
            let servo = ServoId::ALL[servo_i];
            let c = shipped();
            let p = plan();
            let refs = p.get(servo).references;
            let at_b = at_a + counts_per_deg * (refs[1].input - refs[0].input);
            let readings = [
                LeaderReading { input: refs[0].input, counts: at_a },
                LeaderReading { input: refs[1].input, counts: at_b },
            ];
            match derive_leader(&c, servo, readings, 1023, &Tolerances::default()) {
                Ok(ch) => {
                    prop_assert!((ch.input(at_a) - refs[0].input).abs() < 1e-9);
                    prop_assert!((ch.input(at_b) - refs[1].input).abs() < 1e-9);
                    let (lo, hi) = input_range(&c, servo);
                    for x in [lo, hi] {
                        prop_assert!((0.0..=1023.0).contains(&ch.counts(x)));
                        prop_assert!((ch.input(ch.counts(x)) - x).abs() < 1e-9);
                    }
                }
                Err(
                    CalibrationError::LeaderRangeOutsideAdc { .. }
                    | CalibrationError::LeaderAtRail { .. }
                    | CalibrationError::LeaderOutsideAdc { .. },
                ) => {}
                Err(other) => prop_assert!(false, "{}", other),
            }
        }
    }

    #[test]
    fn leader_refusals() {
        let c = shipped();
        let t = Tolerances::default();
        let r = |input, counts| LeaderReading { input, counts };
        let d = |a, b| derive_leader(&c, ServoId::Shoulder, [a, b], 1023, &t);
        assert!(matches!(
            d(r(90.0, 500.0), r(45.0, 10.0)),
            Err(CalibrationError::LeaderAtRail { .. })
        ));
        assert!(matches!(
            d(r(90.0, 500.0), r(45.0, 1023.0)),
            Err(CalibrationError::LeaderAtRail { .. })
        ));
        assert!(matches!(
            d(r(90.0, 500.0), r(45.0, 1024.0)),
            Err(CalibrationError::LeaderOutsideAdc { .. })
        ));
        assert!(matches!(
            d(r(90.0, 500.0), r(45.0, 510.0)),
            Err(CalibrationError::LeaderReadingsTooClose { .. })
        ));
        // 11.1 counts per degree: 42.5° would read 1027.8, past the ADC's end; at 8 counts
        // per degree the whole 42.5° … 125° reads 880 … 220
        let err = d(r(90.0, 500.0), r(45.0, 1000.0)).unwrap_err();
        assert!(
            matches!(err, CalibrationError::LeaderRangeOutsideAdc { .. }),
            "{err}"
        );
        assert!(err.to_string().contains("42.50°"), "{err}");
        let ok = d(r(90.0, 500.0), r(45.0, 860.0)).unwrap();
        assert_eq!(ok.input(500.0), 90.0);
        assert_eq!(ok.input(860.0), 45.0);
    }
}
