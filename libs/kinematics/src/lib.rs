#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod assess;
pub mod calibration;
pub mod chain;
mod config;
pub mod envelope;
mod error;
pub mod ik;
mod motion;
pub mod rng;
mod servo;
pub mod urdf;

pub use config::{
    ArmConfig, ArmGeometry, ConfigError, JointLimitsDeg, LeaderCalibration, LeaderChannel,
    LimitDeg, DEFAULT_ADC_MAX, MAX_CONFIG_BYTES, MAX_FLOW_COLLECTIONS, SHIPPED_ARM_YAML,
};
pub use error::{Joint, KinematicsError};
pub use motion::{MotionLimits, ServoMotionLimits};
pub use servo::{ServoAngles, ServoCalibration, ServoCalibrations, ServoId};

use nalgebra::Vector3;
use std::f64::consts::FRAC_PI_2;

/// Below this horizontal distance (m) from the yaw axis the base angle is undefined
/// and the previous one is kept.
pub const YAW_AXIS_EPS_M: f64 = 1e-9;

/// The three actuated arm joints, as published on `joint_states` (radians).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmJoints {
    /// `base_joint`: θ1, base yaw; 0 = +x, positive counter-clockwise seen from +z.
    pub base_rad: f64,
    /// `shoulder_joint`: α, main-arm elevation above horizontal.
    pub shoulder_rad: f64,
    /// `elbow_joint`: φ − α, forearm angle relative to the main arm (≤ 0).
    pub elbow_rad: f64,
}

impl ArmJoints {
    /// Home pose: base 0, main arm vertical, forearm horizontal.
    pub const HOME: ArmJoints = ArmJoints {
        base_rad: 0.0,
        shoulder_rad: FRAC_PI_2,
        elbow_rad: -FRAC_PI_2,
    };

    /// φ = α + elbow: the forearm's absolute elevation, which the forearm servo sets.
    pub fn forearm_elevation_rad(&self) -> f64 {
        self.shoulder_rad + self.elbow_rad
    }

    /// The variables of [`Arm::serial_chain`]: `[base, shoulder, elbow]`.
    pub fn to_chain(&self) -> [f64; 3] {
        [self.base_rad, self.shoulder_rad, self.elbow_rad]
    }

    /// From the variables of [`Arm::serial_chain`] (`None` unless exactly three).
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::ArmJoints;
    /// let q = ArmJoints::HOME;
    /// assert_eq!(ArmJoints::from_chain(&q.to_chain()), Some(q));
    /// ```
    pub fn from_chain(x: &[f64]) -> Option<ArmJoints> {
        match x {
            [base_rad, shoulder_rad, elbow_rad] => Some(ArmJoints {
                base_rad: *base_rad,
                shoulder_rad: *shoulder_rad,
                elbow_rad: *elbow_rad,
            }),
            _ => None,
        }
    }

    /// The value of an actuated arm joint.
    pub fn get(&self, joint: Joint) -> Option<f64> {
        match joint {
            Joint::Base => Some(self.base_rad),
            Joint::Shoulder => Some(self.shoulder_rad),
            Joint::Elbow => Some(self.elbow_rad),
            Joint::ForearmElevation => Some(self.forearm_elevation_rad()),
            Joint::Gripper => None,
        }
    }
}

impl Default for ArmJoints {
    fn default() -> Self {
        Self::HOME
    }
}

/// Joint limits in radians, inclusive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimits {
    /// `base_joint` (min, max).
    pub base_rad: (f64, f64),
    /// `shoulder_joint` (min, max).
    pub shoulder_rad: (f64, f64),
    /// `elbow_joint` (min, max).
    pub elbow_rad: (f64, f64),
    /// φ = shoulder + elbow (min, max).
    pub forearm_elevation_rad: (f64, f64),
}

impl JointLimits {
    /// Limits of one constrained quantity.
    pub fn of(&self, joint: Joint) -> Option<(f64, f64)> {
        match joint {
            Joint::Base => Some(self.base_rad),
            Joint::Shoulder => Some(self.shoulder_rad),
            Joint::Elbow => Some(self.elbow_rad),
            Joint::ForearmElevation => Some(self.forearm_elevation_rad),
            Joint::Gripper => None,
        }
    }

    /// Every limit row at once; the first that fails is named, in the order
    /// base, shoulder, elbow, forearm elevation.
    pub fn check(&self, q: &ArmJoints) -> Result<(), KinematicsError> {
        for joint in [
            Joint::Base,
            Joint::Shoulder,
            Joint::Elbow,
            Joint::ForearmElevation,
        ] {
            let (min, max) = self.of(joint).unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
            let value = q.get(joint).unwrap_or(f64::NAN);
            if !value.is_finite() {
                return Err(KinematicsError::NonFiniteJoint { joint, value });
            }
            if value < min || value > max {
                return Err(KinematicsError::OutOfLimits {
                    joint,
                    value_rad: value,
                    min_rad: min,
                    max_rad: max,
                });
            }
        }
        Ok(())
    }

    /// The shoulder angles for which some elbow angle satisfies both elbow rows (its own
    /// limits and the forearm's elevation), within the shoulder's limits; None when no
    /// shoulder angle has one.
    pub fn feasible_shoulder_rad(&self) -> Option<(f64, f64)> {
        let lo = self
            .shoulder_rad
            .0
            .max(self.forearm_elevation_rad.0 - self.elbow_rad.1);
        let hi = self
            .shoulder_rad
            .1
            .min(self.forearm_elevation_rad.1 - self.elbow_rad.0);
        (lo <= hi).then_some((lo, hi))
    }

    /// Joints within every limit row, near `q`: base clamped into its range, the
    /// shoulder into its range where some elbow angle satisfies the forearm elevation
    /// too, the elbow into its own range intersected with what the forearm elevation
    /// allows at that shoulder angle.
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{ArmConfig, ArmJoints};
    /// let limits = ArmConfig::default().arm().limits;
    /// for q in [
    ///     ArmJoints { base_rad: 1.0, shoulder_rad: 2.0, elbow_rad: -0.5 },
    ///     ArmJoints { base_rad: -9.0, shoulder_rad: 1.2, elbow_rad: 0.4 },
    ///     ArmJoints { base_rad: 0.0, shoulder_rad: -1.0, elbow_rad: -3.0 },
    /// ] {
    ///     assert!(limits.check(&limits.clamp(&q)).is_ok());
    /// }
    /// let inside = ArmJoints { base_rad: 0.1, shoulder_rad: 1.0, elbow_rad: -1.2 };
    /// assert!(limits.check(&inside).is_ok());
    /// assert_eq!(limits.clamp(&inside), inside);
    /// ```
    pub fn clamp(&self, q: &ArmJoints) -> ArmJoints {
        let base_rad = q.base_rad.clamp(self.base_rad.0, self.base_rad.1);
        let shoulder_rad = if let Some((s_lo, s_hi)) = self.feasible_shoulder_rad() {
            q.shoulder_rad.clamp(s_lo, s_hi)
        } else {
            q.shoulder_rad
                .clamp(self.shoulder_rad.0, self.shoulder_rad.1)
        };
        // (a hair inside, so that shoulder + elbow rounds within the elevation row)
        const INSIDE: f64 = 1e-12;
        let lo = self
            .elbow_rad
            .0
            .max(self.forearm_elevation_rad.0 - shoulder_rad + INSIDE);
        let hi = self
            .elbow_rad
            .1
            .min(self.forearm_elevation_rad.1 - shoulder_rad - INSIDE);
        let elbow_rad = if lo <= hi {
            q.elbow_rad.clamp(lo, hi)
        } else {
            (lo + hi) / 2.0
        };
        ArmJoints {
            base_rad,
            shoulder_rad,
            elbow_rad,
        }
    }
}

/// The arm: geometry and limits. Cheap to copy; all methods are pure.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arm {
    /// Link lengths and offsets.
    pub geometry: ArmGeometry,
    /// Joint limits.
    pub limits: JointLimits,
}

impl Default for Arm {
    fn default() -> Self {
        ArmConfig::default().arm()
    }
}

impl Arm {
    /// Tool point `tool0` in `base_link` (m) for joint angles `q`.
    ///
    /// r = L2·cos α + L3·cos φ + tool_dx; z = H + L2·sin α + L3·sin φ;
    /// x = r·cos θ1; y = r·sin θ1.
    pub fn forward(&self, q: &ArmJoints) -> Vector3<f64> {
        let g = &self.geometry;
        let phi = q.forearm_elevation_rad();
        let r = g.main_arm_m * q.shoulder_rad.cos() + g.forearm_m * phi.cos() + g.tool_dx_m;
        let z = g.shoulder_height_m + g.main_arm_m * q.shoulder_rad.sin() + g.forearm_m * phi.sin();
        Vector3::new(r * q.base_rad.cos(), r * q.base_rad.sin(), z)
    }

    /// Joint angles that put `tool0` at `target` (m, in `base_link`).
    ///
    /// The solution is unique on the arm's only physical branch (elbow ≤ 0). On the
    /// yaw axis the base angle is undefined and `previous_base_rad` is kept. Every
    /// reach and joint limit is checked; on failure nothing is returned but the reason.
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{Arm, Joint, KinematicsError};
    /// let arm = Arm::default();
    /// let q = arm.solve_position(&[0.2, 0.05, 0.15].into(), 0.0).unwrap();
    /// assert!((arm.forward(&q) - nalgebra::Vector3::new(0.2, 0.05, 0.15)).norm() < 1e-12);
    /// // far outside the reach of the two links
    /// assert!(matches!(arm.solve_position(&[1.0, 0.0, 0.1].into(), 0.0),
    ///                  Err(KinematicsError::TooFar { .. })));
    /// // behind the base: outside the ±45° base limit
    /// assert!(matches!(arm.solve_position(&[-0.2, 0.0, 0.15].into(), 0.0),
    ///                  Err(KinematicsError::OutOfLimits { joint: Joint::Base, .. })));
    /// ```
    pub fn solve_position(
        &self,
        target: &Vector3<f64>,
        previous_base_rad: f64,
    ) -> Result<ArmJoints, KinematicsError> {
        for (axis, value) in [("x", target.x), ("y", target.y), ("z", target.z)] {
            if !value.is_finite() {
                return Err(KinematicsError::NonFiniteTarget { axis, value });
            }
        }
        let g = &self.geometry;
        let (l2, l3) = (g.main_arm_m, g.forearm_m);
        let rho = target.x.hypot(target.y);
        let base_rad = if rho < YAW_AXIS_EPS_M {
            if previous_base_rad.is_finite() {
                previous_base_rad
            } else {
                0.0
            }
        } else {
            target.y.atan2(target.x)
        };
        // Wrist pivot in the arm plane, relative to the shoulder pivot.
        let r = rho - g.tool_dx_m;
        let h = target.z - g.shoulder_height_m;
        let s2 = r * r + h * h;
        let (min_reach, max_reach) = ((l2 - l3).abs(), l2 + l3);
        if s2 > max_reach * max_reach {
            return Err(KinematicsError::TooFar {
                distance_m: s2.sqrt(),
                max_m: max_reach,
            });
        }
        if s2 < min_reach * min_reach {
            return Err(KinematicsError::TooClose {
                distance_m: s2.sqrt(),
                min_m: min_reach,
            });
        }
        let cos_e = (s2 - l2 * l2 - l3 * l3) / (2.0 * l2 * l3);
        // This product form keeps its accuracy at both reach limits.
        let prod = ((max_reach * max_reach - s2) * (s2 - min_reach * min_reach)).max(0.0);
        let sin_e = -prod.sqrt() / (2.0 * l2 * l3);
        let elbow_rad = sin_e.atan2(cos_e);
        let shoulder_rad = h.atan2(r) - (l3 * sin_e).atan2(l2 + l3 * cos_e);
        let q = ArmJoints {
            base_rad,
            shoulder_rad,
            elbow_rad,
        };
        self.limits.check(&q)?;
        Ok(q)
    }
}

impl Arm {
    /// The serial chain `base_link` → `tool0` of the EezyBot URDF for the numerical
    /// solvers: variables `base_joint`, `shoulder_joint`, `elbow_joint` with this arm's
    /// limits (not the URDF's, which are rounded to 1e-6 rad), the coupling
    /// `forearm_elevation` φ = shoulder + elbow within its limits as a linear constraint,
    /// and every passive joint of [`PassiveJoints`] declared, so
    /// [`chain::SerialChain::joint_positions`] gives them all.
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{Arm, ArmJoints, urdf::RobotModel};
    /// let model = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/eezybot.urdf"))).unwrap();
    /// let arm = Arm::default();
    /// let chain = arm.serial_chain(&model).unwrap();
    /// let q = ArmJoints { base_rad: 0.3, shoulder_rad: 1.2, elbow_rad: -1.4 };
    /// let tip = chain.forward(&[q.base_rad, q.shoulder_rad, q.elbow_rad]).unwrap();
    /// assert!((tip.translation.vector - arm.forward(&q)).norm() < 1e-12);
    /// ```
    pub fn serial_chain(
        &self,
        model: &urdf::RobotModel,
    ) -> Result<chain::SerialChain, KinematicsError> {
        let l = &self.limits;
        let (alpha, elbow) = (ACTUATED_JOINTS[1], ACTUATED_JOINTS[2]);
        let terms: [&[(&str, f64)]; 6] = [
            &[(alpha, -1.0), (elbow, -1.0)], // wrist = −φ
            &[(alpha, 1.0), (elbow, 1.0)],   // crank = φ
            &[(elbow, -1.0)],                // drive link = α − φ = −elbow
            &[(alpha, 1.0)],                 // level link = α
            &[(alpha, -1.0)],                // triangle = −α
            &[(alpha, 1.0), (elbow, 1.0)],   // upper link = φ
        ];
        let mut b = chain::ChainBuilder::new(model, "base_link", "tool0")
            .limits(ACTUATED_JOINTS[0], l.base_rad.0, l.base_rad.1)
            .limits(alpha, l.shoulder_rad.0, l.shoulder_rad.1)
            .limits(elbow, l.elbow_rad.0, l.elbow_rad.1)
            .constraint(
                Joint::ForearmElevation.name(),
                &[(alpha, 1.0), (elbow, 1.0)],
                l.forearm_elevation_rad.0,
                l.forearm_elevation_rad.1,
            )
            // the URDF's limits of the passive joints restate the coupling, rounded
            .dependent_joint_limits(false);
        for (name, t) in PassiveJoints::NAMES.iter().zip(terms) {
            b = b.passive(name, t, 0.0);
        }
        b.build()
    }
}

/// Angles (rad) of the passive joints of the URDF's open-chain model of the
/// closed linkages (the seed report's chains 1–4), each relative to its parent link.
///
/// All follow from α and φ alone: parallelograms keep link directions equal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PassiveJoints {
    /// `wrist_joint` (forearm → front plate): −φ keeps the plate and the claw level.
    pub wrist_rad: f64,
    /// `crank_joint` (turntable → forearm drive crank on the shoulder axis): φ.
    pub crank_rad: f64,
    /// `drive_link_joint` (crank → 135 mm drive link, parallel to the main arm): α − φ.
    pub drive_link_rad: f64,
    /// `level_link_joint` (turntable → 135 mm levelling link at the fixed pivot): α.
    pub level_link_rad: f64,
    /// `triangle_joint` (levelling link → triangle link at the elbow, kept level): −α.
    pub triangle_rad: f64,
    /// `upper_link_joint` (triangle link → 147 mm upper link, parallel to the forearm): φ.
    pub upper_link_rad: f64,
}

impl PassiveJoints {
    /// Joint names, in the order of [`PassiveJoints::values`].
    pub const NAMES: [&'static str; 6] = [
        "wrist_joint",
        "crank_joint",
        "drive_link_joint",
        "level_link_joint",
        "triangle_joint",
        "upper_link_joint",
    ];

    /// The passive joint angles for the arm joints `q`.
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{ArmJoints, PassiveJoints};
    /// let p = PassiveJoints::from_arm(&ArmJoints::HOME);
    /// assert_eq!(p.wrist_rad, 0.0); // forearm horizontal: plate needs no correction
    /// ```
    pub fn from_arm(q: &ArmJoints) -> PassiveJoints {
        let alpha = q.shoulder_rad;
        let phi = q.forearm_elevation_rad();
        PassiveJoints {
            wrist_rad: -phi,
            crank_rad: phi,
            drive_link_rad: alpha - phi,
            level_link_rad: alpha,
            triangle_rad: -alpha,
            upper_link_rad: phi,
        }
    }

    /// Values in the order of [`PassiveJoints::NAMES`].
    pub fn values(&self) -> [f64; 6] {
        [
            self.wrist_rad,
            self.crank_rad,
            self.drive_link_rad,
            self.level_link_rad,
            self.triangle_rad,
            self.upper_link_rad,
        ]
    }
}

/// Names of the actuated joints, as on `joint_states` and `joint_target`.
pub const ACTUATED_JOINTS: [&str; 4] = [
    "base_joint",
    "shoulder_joint",
    "elbow_joint",
    "gripper_joint",
];

/// Name of the claw's second finger, which mirrors `gripper_joint` (a URDF mimic joint).
pub const GRIPPER_MIMIC_JOINT: &str = "gripper_mimic_joint";

/// The full state of the arm: actuated joints and claw opening (0 closed … 1 open).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmState {
    /// Arm joints.
    pub joints: ArmJoints,
    /// Claw opening, 0.0 closed … 1.0 open.
    pub gripper_opening: f64,
}

impl Default for ArmState {
    fn default() -> Self {
        ArmState {
            joints: ArmJoints::HOME,
            gripper_opening: 0.0,
        }
    }
}

impl ArmState {
    /// Every non-fixed joint of the URDF with its position (rad): actuated, passive
    /// and the claw mimic, in a fixed order.
    pub fn joint_positions(&self, geometry: &ArmGeometry) -> Vec<(&'static str, f64)> {
        let gripper_rad = self.gripper_opening * geometry.gripper_open_rad;
        let mut out = vec![
            (ACTUATED_JOINTS[0], self.joints.base_rad),
            (ACTUATED_JOINTS[1], self.joints.shoulder_rad),
            (ACTUATED_JOINTS[2], self.joints.elbow_rad),
            (ACTUATED_JOINTS[3], gripper_rad),
        ];
        let passive = PassiveJoints::from_arm(&self.joints);
        out.extend(PassiveJoints::NAMES.iter().copied().zip(passive.values()));
        out.push((GRIPPER_MIMIC_JOINT, -gripper_rad));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn home_pose_matches_robot_md() {
        let arm = Arm::default();
        let p = arm.forward(&ArmJoints::HOME);
        assert!((p - Vector3::new(0.147 + 0.0393, 0.0, 0.094 + 0.135)).norm() < 1e-15);
    }

    #[test]
    fn workspace_extent_matches_robot_md() {
        // ROBOT.md: at z = 0.15, r 0.102–0.278; at z = 0.10, r 0.125–0.260 (its
        // figures come from a coarse grid: at z = 0.15 the elbow limit binds at 0.1035).
        let arm = Arm::default();
        for (z, rmin, rmax) in [(0.15, 0.102, 0.278), (0.10, 0.125, 0.260)] {
            let reach: Vec<f64> = (0..4000)
                .map(|i| i as f64 * 1e-4)
                .filter(|r| arm.solve_position(&Vector3::new(*r, 0.0, z), 0.0).is_ok())
                .collect();
            let (lo, hi) = (reach[0], reach[reach.len() - 1]);
            assert!((lo - rmin).abs() < 2.5e-3, "z={z}: min r {lo} vs {rmin}");
            assert!((hi - rmax).abs() < 1.5e-3, "z={z}: max r {hi} vs {rmax}");
        }
    }

    #[test]
    fn yaw_axis_keeps_previous_base_angle() {
        let arm = Arm {
            limits: JointLimits {
                base_rad: (-4.0, 4.0),
                ..Arm::default().limits
            },
            ..Arm::default()
        };
        // On the axis the tool would need r = -tool_dx: out of reach anyway, but the
        // base angle chosen must be the previous one, never NaN.
        match arm.solve_position(&Vector3::new(0.0, 0.0, 0.2), 0.3) {
            Ok(q) => assert_eq!(q.base_rad, 0.3),
            Err(e) => assert!(!matches!(e, KinematicsError::NonFiniteTarget { .. })),
        }
    }

    #[test]
    fn passive_joints_keep_plate_level() {
        let q = ArmJoints {
            base_rad: 0.1,
            shoulder_rad: 1.2,
            elbow_rad: -1.5,
        };
        let p = PassiveJoints::from_arm(&q);
        // absolute plate pitch = α + elbow + wrist = 0
        assert!((q.shoulder_rad + q.elbow_rad + p.wrist_rad).abs() < 1e-15);
        // triangle stays level: α + triangle = 0
        assert!((p.level_link_rad + p.triangle_rad).abs() < 1e-15);
        // drive link parallel to main arm: crank + drive_link = α
        assert!((p.crank_rad + p.drive_link_rad - q.shoulder_rad).abs() < 1e-15);
    }
}
