//! What the integration tests share.
#![allow(clippy::unwrap_used, dead_code)]

use eezybot_kinematics::urdf::RobotModel;
use std::path::Path;

/// A URDF of the repository's `urdf/` directory.
pub fn load(file: &str) -> RobotModel {
    RobotModel::load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../urdf")
            .join(file),
    )
    .unwrap()
}
