//! The arm configuration file (`config/arm.yaml`): geometry, limits, servo calibration.

use crate::{Arm, JointLimits, MotionLimits, ServoCalibrations, ServoId};
use serde::{Deserialize, Serialize};
use std::io::Read;
use std::path::{Path, PathBuf};

/// The configuration shipped in `config/arm.yaml`, compiled in as the default.
pub const SHIPPED_ARM_YAML: &str = include_str!("../../../config/arm.yaml");

/// The largest configuration file read (bytes); the shipped one is 2.5 KB.
pub const MAX_CONFIG_BYTES: usize = 64 * 1024;

/// The most flow collections (`[` or `{`) a configuration may open; the shipped one
/// opens 12. The YAML parser's time grows with the product of their nesting and the
/// file's length (thousands nested take seconds to minutes), and every `[`/`{` anywhere
/// in the text (even in a comment or a string) counts, so this bounds the nesting without
/// having to understand YAML.
pub const MAX_FLOW_COLLECTIONS: usize = 256;

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
    /// The file is larger than [`MAX_CONFIG_BYTES`].
    #[error("{origin}: {bytes} bytes, more than the {limit} an arm configuration may have")]
    TooLarge {
        /// the file, or `<inline>`
        origin: String,
        /// its size (or as much of it as was read)
        bytes: u64,
        /// [`MAX_CONFIG_BYTES`]
        limit: usize,
    },
    /// The text opens more `[`/`{` than [`MAX_FLOW_COLLECTIONS`]: refused before parsing.
    #[error("{origin}: {count} `[` or `{{` (flow collections), more than the {limit} an arm configuration may have")]
    TooManyFlowCollections {
        /// the file, or `<inline>`
        origin: String,
        /// how many `[` and `{` the text has
        count: usize,
        /// [`MAX_FLOW_COLLECTIONS`]
        limit: usize,
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
    /// The leader arm's potentiometer calibration (optional section `leader:`, written by
    /// the calibration wizard; files without it load unchanged).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub leader: Option<LeaderCalibration>,
}

impl ArmConfig {
    /// The configuration shipped with the project (`config/arm.yaml`).
    pub fn shipped() -> Result<ArmConfig, ConfigError> {
        Self::from_yaml(SHIPPED_ARM_YAML, "config/arm.yaml (built in)")
    }

    /// Parse and validate YAML text; `origin` names it in errors. Text over
    /// [`MAX_CONFIG_BYTES`] or with more than [`MAX_FLOW_COLLECTIONS`] `[`/`{` is refused
    /// before it is parsed.
    pub fn from_yaml(text: &str, origin: &str) -> Result<ArmConfig, ConfigError> {
        if text.len() > MAX_CONFIG_BYTES {
            return Err(ConfigError::TooLarge {
                origin: origin.to_string(),
                bytes: text.len() as u64,
                limit: MAX_CONFIG_BYTES,
            });
        }
        let count = text.bytes().filter(|&b| b == b'[' || b == b'{').count();
        if count > MAX_FLOW_COLLECTIONS {
            return Err(ConfigError::TooManyFlowCollections {
                origin: origin.to_string(),
                count,
                limit: MAX_FLOW_COLLECTIONS,
            });
        }
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

    /// Read, parse and validate a file. No more than [`MAX_CONFIG_BYTES`] + 1 bytes are
    /// read, so a huge or endless file (`/dev/zero`) is refused as too large.
    pub fn load(path: &Path) -> Result<ArmConfig, ConfigError> {
        let read_error = |source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        };
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .and_then(|f| f.take(MAX_CONFIG_BYTES as u64 + 1).read_to_end(&mut bytes))
            .map_err(read_error)?;
        let origin = path.display().to_string();
        if bytes.len() > MAX_CONFIG_BYTES {
            let size = std::fs::metadata(path).map_or(0, |m| m.len());
            return Err(ConfigError::TooLarge {
                origin,
                bytes: size.max(bytes.len() as u64),
                limit: MAX_CONFIG_BYTES,
            });
        }
        let text = String::from_utf8(bytes)
            .map_err(|e| read_error(std::io::Error::new(std::io::ErrorKind::InvalidData, e)))?;
        Self::from_yaml(&text, &origin)
    }

    /// Check that every value is usable: positive lengths, ordered finite limits,
    /// servo ranges inside 0–180° and plausible pulse widths.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let invalid = invalid_in(origin);
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
        if let Some(leader) = &self.leader {
            leader.validate(origin)?;
        }
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

// ------------------------------------------------ leader arm (calibration wizard)

/// The default full-scale reading of a leader arm's ADC: the Arduino's 10 bits.
pub const DEFAULT_ADC_MAX: u16 = 1023;

/// One leader-arm potentiometer: the two readings the wizard took at two references. The
/// map is the line through them: `input = input_a + (counts − counts_a) · (input_b −
/// input_a) / (counts_b − counts_a)`, the input in the servo's terms (base_joint,
/// shoulder_joint, forearm elevation φ, claw opening 0 … 1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LeaderChannel {
    /// ADC reading at reference A (counts; an average may be fractional).
    pub counts_a: f64,
    /// The input at reference A.
    pub input_a: f64,
    /// ADC reading at reference B.
    pub counts_b: f64,
    /// The input at reference B.
    pub input_b: f64,
}

impl LeaderChannel {
    /// Input units per count.
    pub fn slope(&self) -> f64 {
        (self.input_b - self.input_a) / (self.counts_b - self.counts_a)
    }

    /// The input for a reading.
    pub fn input(&self, counts: f64) -> f64 {
        self.input_a + (counts - self.counts_a) * self.slope()
    }

    /// The reading at an input.
    pub fn counts(&self, input: f64) -> f64 {
        self.counts_a + (input - self.input_a) / self.slope()
    }
}

fn default_adc_max() -> u16 {
    DEFAULT_ADC_MAX
}

/// The leader arm's potentiometers: the optional `leader:` section of the arm
/// configuration. A channel that is absent is not calibrated.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LeaderCalibration {
    /// The ADC's full-scale reading (1023 for the Arduino's 10 bits).
    #[serde(default = "default_adc_max")]
    pub adc_max: u16,
    /// Base potentiometer (input: base_joint, deg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base: Option<LeaderChannel>,
    /// Main-arm potentiometer (input: shoulder_joint, deg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shoulder: Option<LeaderChannel>,
    /// Forearm potentiometer (input: forearm elevation φ, deg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub elbow: Option<LeaderChannel>,
    /// Claw potentiometer or trigger (input: opening 0 … 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gripper: Option<LeaderChannel>,
}

impl Default for LeaderCalibration {
    fn default() -> Self {
        LeaderCalibration {
            adc_max: DEFAULT_ADC_MAX,
            base: None,
            shoulder: None,
            elbow: None,
            gripper: None,
        }
    }
}

impl LeaderCalibration {
    /// One channel.
    pub fn get(&self, servo: ServoId) -> Option<&LeaderChannel> {
        servo
            .of([&self.base, &self.shoulder, &self.elbow, &self.gripper])
            .as_ref()
    }

    /// Set one channel.
    pub fn set(&mut self, servo: ServoId, channel: LeaderChannel) {
        *servo.of([
            &mut self.base,
            &mut self.shoulder,
            &mut self.elbow,
            &mut self.gripper,
        ]) = Some(channel);
    }

    /// The loader's check (the plausibility is `calibration::derive_leader`'s): a positive full
    /// scale, finite values, readings within it, distinct readings and inputs.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let invalid = invalid_in(origin);
        if self.adc_max == 0 {
            return Err(invalid("leader.adc_max", "0".into(), "must be positive"));
        }
        for servo in ServoId::ALL {
            let Some(c) = self.get(servo) else { continue };
            let field = servo.of([
                "leader.base",
                "leader.shoulder",
                "leader.elbow",
                "leader.gripper",
            ]);
            let value = format!("{c:?}");
            let full = f64::from(self.adc_max);
            if ![c.counts_a, c.input_a, c.counts_b, c.input_b]
                .iter()
                .all(|v| v.is_finite())
            {
                return Err(invalid(field, value, "every value must be finite"));
            }
            if !(0.0..=full).contains(&c.counts_a) || !(0.0..=full).contains(&c.counts_b) {
                return Err(invalid(
                    field,
                    value,
                    "readings must lie within 0 … adc_max",
                ));
            }
            if c.counts_a == c.counts_b || c.input_a == c.input_b {
                return Err(invalid(
                    field,
                    value,
                    "the two readings and the two inputs must differ",
                ));
            }
        }
        Ok(())
    }
}

/// A maker of [`ConfigError::Invalid`] for the file `origin`.
fn invalid_in(origin: &str) -> impl Fn(&'static str, String, &'static str) -> ConfigError + '_ {
    move |field, value, why| ConfigError::Invalid {
        origin: origin.to_string(),
        field,
        value,
        why,
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
    fn a_broken_leader_section_is_refused_naming_it() {
        assert_eq!(ArmConfig::shipped().unwrap().leader, None);
        let err = ArmConfig::from_yaml(
            "leader: { base: { counts_a: 5, input_a: 0, counts_b: 5, input_b: 45 } }",
            "t",
        )
        .unwrap_err();
        assert!(err.to_string().contains("leader.base"), "{err}");
        let err = ArmConfig::from_yaml("leader: { bsae: {} }", "t").unwrap_err();
        assert!(err.to_string().contains("bsae"), "{err}");
    }

    #[test]
    fn reversed_limits_are_rejected() {
        let err = ArmConfig::from_yaml("limits_deg: { base: [45, -45] }", "t").unwrap_err();
        assert!(err.to_string().contains("limits_deg.base"), "{err}");
    }

    #[test]
    fn deeply_nested_flow_collections_are_refused_before_parsing() {
        for depth in [10_000, 100_000] {
            // refused by the count before the YAML parser sees it: the error says so
            // (how long that takes: `cargo bench -p eezybot_kinematics --bench kinematics`)
            let text = format!("geometry: {}{}\n", "[".repeat(depth), "]".repeat(depth));
            let err = ArmConfig::from_yaml(&text, "deep.yaml").unwrap_err();
            let text = err.to_string();
            assert!(text.contains("deep.yaml"), "{text}");
            match (depth, err) {
                (10_000, ConfigError::TooManyFlowCollections { count, limit, .. }) => {
                    assert_eq!((count, limit), (10_000, MAX_FLOW_COLLECTIONS), "{text}");
                }
                (100_000, ConfigError::TooLarge { bytes, .. }) => assert_eq!(bytes, 200_011),
                (_, err) => panic!("{err}"),
            }
        }
        let many = format!("geometry: {}{}\n", "{".repeat(300), "}".repeat(300));
        let err = ArmConfig::from_yaml(&many, "t").unwrap_err();
        assert!(err.to_string().contains("300 `[` or `{`"), "{err}");
    }

    #[test]
    fn a_huge_or_endless_file_is_refused_without_reading_it_all() {
        let err = ArmConfig::load(Path::new("/dev/zero")).unwrap_err();
        assert!(
            matches!(
                err,
                ConfigError::TooLarge {
                    limit: MAX_CONFIG_BYTES,
                    ..
                }
            ),
            "{err}"
        );
        let path = std::env::temp_dir().join(format!("arm_config_big_{}.yaml", std::process::id()));
        std::fs::write(&path, format!("# {}\n", "x".repeat(MAX_CONFIG_BYTES))).unwrap();
        let err = ArmConfig::load(&path).unwrap_err();
        std::fs::remove_file(&path).unwrap();
        assert!(
            matches!(err, ConfigError::TooLarge { bytes, .. } if bytes == MAX_CONFIG_BYTES as u64 + 3),
            "{err}"
        );
    }

    #[test]
    fn shipped_config_is_well_inside_the_limits() {
        assert!(SHIPPED_ARM_YAML.len() < MAX_CONFIG_BYTES / 8);
        let flows = SHIPPED_ARM_YAML.matches(['[', '{']).count();
        assert!(flows < MAX_FLOW_COLLECTIONS / 8, "{flows}");
    }

    #[test]
    fn missing_file_names_the_path() {
        let err = ArmConfig::load(Path::new("/nonexistent/arm.yaml")).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/arm.yaml"));
    }
}
