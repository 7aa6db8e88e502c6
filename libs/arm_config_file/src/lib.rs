#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

mod edit;
mod save;

pub use edit::calibration_text;
pub use save::{backup_path, write_calibration, Saved};

use eezybot_kinematics::ConfigError;
use std::path::PathBuf;

/// Why a calibration could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriteError {
    /// The existing file could not be read or is not an arm configuration that loads.
    #[error("the existing configuration cannot be rewritten: {0}")]
    Original(ConfigError),
    /// The new values are not a valid calibration.
    #[error("the new calibration is invalid: {0}")]
    Invalid(ConfigError),
    /// The rewritten text does not load back to exactly the new values (nothing was
    /// written).
    #[error("the rewritten configuration does not load back to the new values: {0}")]
    Verify(String),
    /// A file operation failed; the configuration file is unchanged.
    #[error("{action} {path}: {source}")]
    Io {
        /// what was being done
        action: &'static str,
        /// the file
        path: PathBuf,
        /// the I/O error
        source: std::io::Error,
    },
}

/// A calibration unlike the shipped one in every way the writer must keep: digits that
/// need all 17 to read back, a sum that is not its decimal, a changed range and pulse.
#[cfg(test)]
fn odd_calibration() -> eezybot_kinematics::ServoCalibrations {
    let mut s = eezybot_kinematics::ServoCalibrations::default();
    s.base.offset_deg = 97.123_456_789_012_34;
    s.base.gain = -1.987_654_321;
    s.shoulder.offset_deg = 187.0;
    s.elbow.gain = -1.0;
    s.elbow.offset_deg = 0.1 + 0.2; // 0.30000000000000004
    s.gripper.min_deg = 67.0;
    s.gripper.pulse_max_us = 2500;
    s
}
