//! Writes the twin's MJCF for the shipped URDF and arm config to stdout, to open in
//! MuJoCo's own viewer (`python -m mujoco.viewer --mjcf FILE`) or to read.
//!
//! `cargo run -p twin_model --example write_mjcf > eezybot_twin.xml`
use std::process::ExitCode;

fn main() -> ExitCode {
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../urdf/eezybot.urdf");
    let result = std::fs::read_to_string(&here)
        .map_err(|e| format!("{}: {e}", here.display()))
        .and_then(|urdf| {
            let config = eezybot_kinematics::ArmConfig::shipped().map_err(|e| e.to_string())?;
            twin_model::build(
                &urdf,
                "urdf/eezybot.urdf",
                &config,
                &twin_model::Scene::default(),
            )
            .map_err(|e| e.to_string())
        });
    match result {
        Ok(model) => {
            print!("{}", model.mjcf);
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("write_mjcf: {e}");
            ExitCode::FAILURE
        }
    }
}
