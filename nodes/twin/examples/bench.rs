//! The twin's speed (BENCHMARKS.md, "The physics twin"): how many times faster than real
//! time it runs, headless and with its camera, and what a physics step and a camera frame
//! cost (p50, p99). Run it built with optimisations, on a quiet machine:
//!
//!     . launch_scripts/install_mujoco.sh --env
//!     cargo run --release -p twin --features mujoco --example bench [-- SECONDS [EVENTS]]
//!
//! With EVENTS (a servo_sim event file: the firmware in simavr's pin edges), the twin in
//! lock-step also replays it as fast as it can (`twin::lockstep`), and says how many
//! times faster than the board's simulated time.
//!
//! Each run simulates SECONDS (default 20) of the scripted pick's motion (the arm reaching
//! over the cube, closing, lifting, back), looping; "with camera" also renders 640 x 480
//! and encodes it to JPEG every 1/30 s of simulated time, on the same thread (the node
//! draws on a thread of its own: this is the harder case). The real-time factor is
//! simulated seconds per wall second.
use std::time::Instant;

use eezybot_kinematics::{ArmConfig, ArmJoints, ArmState};
use mujoco_rs::prelude::*;
use twin::sim::Sim;
use twin_model::Scene;

fn main() {
    let seconds: f64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(20.0);
    let events = std::env::args().nth(2);
    if let Err(e) = run(seconds).and_then(|()| events.map_or(Ok(()), |path| replay(&path))) {
        eprintln!("bench: {e}");
        std::process::exit(1);
    }
}

/// The twin in lock-step with a recorded event file, replayed as fast as the physics runs.
fn replay(path: &str) -> Result<(), Box<dyn std::error::Error>> {
    let text = std::fs::read_to_string(path)?;
    let events: Vec<_> = text
        .lines()
        .filter_map(twin_model::pulses::BoardEvent::parse)
        .collect();
    let config = ArmConfig::shipped()?;
    let mut sim = Sim::new(twin::node::URDF, &config, &Scene::default())?;
    let mut lockstep = twin::lockstep::Lockstep::new();
    let start = Instant::now();
    for e in &events {
        lockstep.apply(&mut sim, *e)?;
    }
    let wall = start.elapsed().as_secs_f64();
    println!(
        "lock-step replay of {path}: {} events, {:.2} s of the board's time in {wall:.3} s: {:.0}x real time",
        events.len(),
        sim.time(),
        sim.time() / wall
    );
    Ok(())
}

/// The horn targets of the scripted motion at simulated time `t` (a 6 s loop).
fn script(config: &ArmConfig, t: f64) -> [Option<f64>; 4] {
    let arm = config.arm();
    let phase = t % 6.0;
    let (p, opening) = match phase {
        p if p < 1.5 => (nalgebra::Vector3::new(0.2, 0.05, 0.12), 1.0),
        p if p < 3.0 => (nalgebra::Vector3::new(0.2, 0.0, 0.074), 1.0),
        p if p < 4.0 => (nalgebra::Vector3::new(0.2, 0.0, 0.074), 0.0),
        p if p < 5.0 => (nalgebra::Vector3::new(0.2, 0.0, 0.124), 0.0),
        _ => (nalgebra::Vector3::new(0.15, -0.05, 0.2), 0.0),
    };
    let joints = arm.solve_position(&p, 0.0).unwrap_or(ArmJoints::HOME);
    let state = ArmState {
        joints,
        gripper_opening: opening,
    };
    config
        .servos
        .servo_angles(&state)
        .map(|a| a.rad.map(Some))
        .unwrap_or([None; 4])
}

fn percentiles(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| {
        v.get(((v.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    (at(0.5), at(0.99))
}

fn run(seconds: f64) -> Result<(), Box<dyn std::error::Error>> {
    let config = ArmConfig::shipped()?;
    let urdf = twin::node::URDF;
    let scene = Scene::default();

    // headless
    let mut sim = Sim::new(urdf, &config, &scene)?;
    let mut steps = Vec::new();
    let start = Instant::now();
    while sim.time() < seconds {
        sim.set_horn_targets(script(&config, sim.time()));
        let t = Instant::now();
        sim.step()?;
        steps.push(t.elapsed().as_secs_f64() * 1e6);
    }
    let wall = start.elapsed().as_secs_f64();
    let (p50, p99) = percentiles(steps);
    println!(
        "headless: {seconds:.0} s simulated in {wall:.2} s: {:.0}x real time; a physics step ({} ms) p50 {p50:.1} us, p99 {p99:.1} us",
        seconds / wall,
        sim.timestep() * 1e3
    );

    // with the camera: 640 x 480 at 30 fps of simulated time, rendered and encoded here
    let mut sim = Sim::new(urdf, &config, &scene)?;
    let model = sim.mj_model();
    let (w, h) = scene.image_size;
    let mut renderer = twin::camera::scene_renderer(&model, w, h)?;
    let mut snapshot = MjData::new(model.clone());
    let (mut frames, mut jpeg_bytes) = (Vec::new(), 0usize);
    let mut next_frame = 0.0;
    let start = Instant::now();
    while sim.time() < seconds {
        sim.set_horn_targets(script(&config, sim.time()));
        sim.step()?;
        if sim.time() >= next_frame {
            next_frame += 1.0 / 30.0;
            let t = Instant::now();
            sim.data().copy_visual_to(&mut snapshot)?;
            renderer.sync_data(&mut snapshot)?;
            renderer.render()?;
            let rgb = renderer.rgb_flat().ok_or("no image")?;
            jpeg_bytes += camera_node::jpeg::encode_rgb(rgb, w as usize, h as usize, 80)?.len();
            frames.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let n = frames.len();
    let (p50, p99) = percentiles(frames);
    println!(
        "with camera ({w} x {h}, 30 fps): {seconds:.0} s simulated in {wall:.2} s: {:.2}x real time; a frame (snapshot, render, JPEG) p50 {p50:.1} ms, p99 {p99:.1} ms; {n} frames, {:.0} KB each",
        seconds / wall,
        jpeg_bytes as f64 / n.max(1) as f64 / 1024.0
    );
    Ok(())
}
