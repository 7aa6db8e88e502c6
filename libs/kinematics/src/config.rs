//! The arm configuration file (`config/arm.yaml`): geometry, limits, servo calibration.

use crate::{Arm, JointLimits, MotionLimits, ServoCalibrations};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The configuration shipped in `config/arm.yaml`, compiled in as the default.
pub const SHIPPED_ARM_YAML: &str = include_str!("../../../config/arm.yaml");

/// Why a configuration file could not be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// the file
        path: PathBuf,
        /// the I/O error
        source: std::io::Error,
    },
    /// The YAML is malformed or has unknown or mistyped fields.
    #[error("{origin}: {message}")]
    Parse {
        /// the file, or `<inline>`
        origin: String,
        /// what the parser said
        message: String,
    },
    /// A value is out of its sensible range.
    #[error("{origin}: {field} = {value}: {why}")]
    Invalid {
        /// the file, or `<inline>`
        origin: String,
        /// which field
        field: &'static str,
        /// the value
        value: String,
        /// what is wrong with it
        why: &'static str,
    },
}

/// Link lengths and offsets (m). Defaults from `shared/ROBOT.md`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArmGeometry {
    /// Shoulder pivot height above `base_link`.
    pub shoulder_height_m: f64,
    /// Main arm L2, shoulder → elbow pivot.
    pub main_arm_m: f64,
    /// Forearm L3, elbow → wrist pivot.
    pub forearm_m: f64,
    /// `tool0` offset from the wrist pivot, horizontal and forward in the arm plane.
    pub tool_dx_m: f64,
    /// Claw finger swing (rad) between closed and fully open (`gripper_joint` range).
    pub gripper_open_rad: f64,
}

impl Default for ArmGeometry {
    fn default() -> Self {
        ArmGeometry {
            shoulder_height_m: 0.094,
            main_arm_m: 0.135,
            forearm_m: 0.147,
            tool_dx_m: 0.0393,
            gripper_open_rad: 0.6,
        }
    }
}

/// A `[min, max]` pair in degrees.
pub type LimitDeg = [f64; 2];

/// Joint limits in degrees, as written in the configuration file.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JointLimitsDeg {
    /// `base_joint`
    pub base: LimitDeg,
    /// `shoulder_joint`
    pub shoulder: LimitDeg,
    /// `elbow_joint`
    pub elbow: LimitDeg,
    /// φ = shoulder + elbow
    pub forearm_elevation: LimitDeg,
}

impl Default for JointLimitsDeg {
    fn default() -> Self {
        JointLimitsDeg {
            base: [-45.0, 45.0],
            shoulder: [42.5, 125.0],
            elbow: [-145.0, -60.0],
            forearm_elevation: [-65.0, 20.0],
        }
    }
}

impl JointLimitsDeg {
    /// In radians.
    pub fn to_radians(&self) -> JointLimits {
        let r = |l: LimitDeg| (l[0].to_radians(), l[1].to_radians());
        JointLimits {
            base_rad: r(self.base),
            shoulder_rad: r(self.shoulder),
            elbow_rad: r(self.elbow),
            forearm_elevation_rad: r(self.forearm_elevation),
        }
    }
}

/// The whole configuration file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArmConfig {
    /// Link lengths.
    pub geometry: ArmGeometry,
    /// Joint limits.
    pub limits_deg: JointLimitsDeg,
    /// Servo calibration.
    pub servos: ServoCalibrations,
    /// Servo speed and acceleration limits.
    pub motion: MotionLimits,
}

impl ArmConfig {
    /// The configuration shipped with the project (`config/arm.yaml`).
    pub fn shipped() -> Result<ArmConfig, ConfigError> {
        Self::from_yaml(SHIPPED_ARM_YAML, "config/arm.yaml (built in)")
    }

    /// Parse and validate YAML text; `origin` names it in errors.
    pub fn from_yaml(text: &str, origin: &str) -> Result<ArmConfig, ConfigError> {
        let config: ArmConfig = serde_norway::from_str(text).map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        config.validate(origin)?;
        Ok(config)
    }

    /// The file at `path`, or the shipped configuration when `path` is empty (the
    /// nodes' `arm_config` parameter).
    pub fn load_or_shipped(path: &str) -> Result<ArmConfig, ConfigError> {
        if path.is_empty() {
            Self::shipped()
        } else {
            Self::load(Path::new(path))
        }
    }

    /// Read, parse and validate a file.
    pub fn load(path: &Path) -> Result<ArmConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_yaml(&text, &path.display().to_string())
    }

    /// Check that every value is usable: positive lengths, ordered finite limits,
    /// servo ranges inside 0–180° and plausible pulse widths.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let invalid =
            |field: &'static str, value: String, why: &'static str| ConfigError::Invalid {
                origin: origin.to_string(),
                field,
                value,
                why,
            };
        let g = &self.geometry;
        for (field, v) in [
            ("geometry.shoulder_height_m", g.shoulder_height_m),
            ("geometry.main_arm_m", g.main_arm_m),
            ("geometry.forearm_m", g.forearm_m),
            ("geometry.gripper_open_rad", g.gripper_open_rad),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(field, v.to_string(), "must be a positive number"));
            }
        }
        if !g.tool_dx_m.is_finite() {
            return Err(invalid(
                "geometry.tool_dx_m",
                g.tool_dx_m.to_string(),
                "must be finite",
            ));
        }
        let l = &self.limits_deg;
        for (field, [lo, hi]) in [
            ("limits_deg.base", l.base),
            ("limits_deg.shoulder", l.shoulder),
            ("limits_deg.elbow", l.elbow),
            ("limits_deg.forearm_elevation", l.forearm_elevation),
        ] {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(invalid(
                    field,
                    format!("[{lo}, {hi}]"),
                    "must be finite with min <= max",
                ));
            }
        }
        if !(l.elbow[1] < 0.0 && l.elbow[0] > -180.0) {
            return Err(invalid(
                "limits_deg.elbow",
                format!("[{}, {}]", l.elbow[0], l.elbow[1]),
                "must lie inside (-180, 0): the IK solves the elbow-down branch only",
            ));
        }
        self.servos.validate(origin)?;
        self.motion.validate(origin)?;
        Ok(())
    }

    /// The arm this configuration describes.
    pub fn arm(&self) -> Arm {
        Arm {
            geometry: self.geometry,
            limits: self.limits_deg.to_radians(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_config_parses_and_equals_defaults() {
        let shipped = ArmConfig::shipped().unwrap();
        assert_eq!(shipped, ArmConfig::default());
    }

    #[test]
    fn unknown_field_is_rejected_with_its_name() {
        let err =
            ArmConfig::from_yaml("geometry: { shoulder_hieght_m: 0.1 }", "test.yaml").unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("test.yaml") && text.contains("shoulder_hieght_m"),
            "{text}"
        );
    }

    #[test]
    fn partial_file_takes_defaults_for_the_rest() {
        let c = ArmConfig::from_yaml("geometry: { shoulder_height_m: 0.085 }", "t").unwrap();
        assert_eq!(c.geometry.shoulder_height_m, 0.085);
        assert_eq!(c.geometry.forearm_m, 0.147);
        assert_eq!(c.servos, ServoCalibrations::default());
    }

    #[test]
    fn reversed_limits_are_rejected() {
        let err = ArmConfig::from_yaml("limits_deg: { base: [45, -45] }", "t").unwrap_err();
        assert!(err.to_string().contains("limits_deg.base"), "{err}");
    }

    #[test]
    fn missing_file_names_the_path() {
        let err = ArmConfig::load(Path::new("/nonexistent/arm.yaml")).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/arm.yaml"));
    }
}
