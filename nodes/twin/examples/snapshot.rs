//! Renders the twin's camera (the default scene: home pose, the cube on its stand) to a
//! PNG, as the camera publishes it (docs/twin.md's picture):
//!
//!     cargo run --release -p twin --features mujoco --example snapshot -- twin_camera.png
use std::process::ExitCode;

use mujoco_rs::prelude::*;

fn main() -> ExitCode {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "twin_camera.png".into());
    match snapshot(&out) {
        Ok(()) => {
            eprintln!("snapshot: wrote {out}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("snapshot: {e}");
            ExitCode::FAILURE
        }
    }
}

fn snapshot(out: &str) -> Result<(), Box<dyn std::error::Error>> {
    let config = eezybot_kinematics::ArmConfig::shipped()?;
    let scene = twin_model::Scene::default();
    let mut sim = twin::sim::Sim::new(twin::node::URDF, &config, &scene)?;
    // the claw a little open, settled in place
    let mut horns = sim.horns().map(Some);
    horns[3] = Some(100f64.to_radians());
    sim.set_horn_targets(horns);
    sim.run(0.5)?;
    let model = sim.mj_model();
    let (w, h) = scene.image_size;
    let mut renderer = twin::camera::scene_renderer(&model, w, h)?;
    let mut data = MjData::new(model.clone());
    sim.data().copy_visual_to(&mut data)?;
    renderer.sync_data(&mut data)?;
    renderer.render()?;
    renderer.save_rgb(out)?;
    Ok(())
}
