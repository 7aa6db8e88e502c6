//! Writes a small LeRobot v3.0 dataset for the independent readers
//! (tests/test_lerobot_dataset.py, tests/lerobot_load.py).
//!
//! - `write_demo DIR`: a new dataset: episode 0 "pick up the cube" (90 frames), one
//!   episode discarded, episode 1 "wave" (45 frames).
//! - `write_demo DIR --stop-mid-episode`: resumes DIR, starts an episode, adds 20 frames,
//!   prints `IN_EPISODE` and waits (to be killed with SIGKILL).
//! - `write_demo DIR --resume`: resumes DIR, prints what the recovery found as one JSON
//!   line (`RECOVERY {...}`), and adds an episode "pick up the cube" (60 frames).
//!
//! The joints move on smooth curves (a deterministic function of the frame number), the
//! action leading the state by a few frames, as a follower lags its leader.

use std::io::Write;

use lerobot_dataset::{DatasetSpec, DatasetWriter, Frame};

const JOINTS: [&str; 4] = [
    "base_joint",
    "shoulder_joint",
    "elbow_joint",
    "gripper_joint",
];

fn joints(t: f64, phase: f64) -> [f32; 4] {
    [
        (0.6 * (0.9 * t + phase).sin()) as f32,
        (0.3 + 0.25 * (0.5 * t).cos()) as f32,
        (-0.4 + 0.2 * (1.3 * t + phase).sin()) as f32,
        (0.5 + 0.5 * (2.0 * t).sin().signum() * (2.0 * t).sin().abs().sqrt()) as f32,
    ]
}

fn episode(w: &mut DatasetWriter, task: &str, frames: usize, phase: f64) -> Result<(), String> {
    w.start_episode(task).map_err(|e| e.to_string())?;
    for i in 0..frames {
        let t = i as f64 / 30.0;
        let state = joints(t, phase);
        let action = joints(t + 0.1, phase);
        w.add_frame(Frame {
            state: &state,
            action: &action,
            images: &[],
        })
        .map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn spec() -> DatasetSpec {
    DatasetSpec::new(30, "eezybot_mk2", &JOINTS, &JOINTS)
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = args
        .first()
        .ok_or("usage: write_demo DIR [--resume|--stop-mid-episode]")?;
    match args.get(1).map(String::as_str) {
        None => {
            let mut w = DatasetWriter::create(dir, spec()).map_err(|e| e.to_string())?;
            episode(&mut w, "pick up the cube", 90, 0.0)?;
            w.save_episode().map_err(|e| e.to_string())?;
            episode(&mut w, "a false start", 17, 1.0)?;
            w.discard_episode().map_err(|e| e.to_string())?;
            episode(&mut w, "wave", 45, 2.0)?;
            w.save_episode().map_err(|e| e.to_string())?;
            println!(
                "WROTE {} episodes, {} frames",
                w.total_episodes(),
                w.total_frames()
            );
        }
        Some("--stop-mid-episode") => {
            let (mut w, _) = DatasetWriter::open_resume(dir, spec()).map_err(|e| e.to_string())?;
            episode(&mut w, "interrupted", 20, 3.0)?;
            println!("IN_EPISODE");
            std::io::stdout().flush().map_err(|e| e.to_string())?;
            loop {
                std::thread::sleep(std::time::Duration::from_secs(1));
            }
        }
        Some("--resume") => {
            let (mut w, r) = DatasetWriter::open_resume(dir, spec()).map_err(|e| e.to_string())?;
            let interrupted = r.interrupted.as_ref().map(|i| {
                serde_json::json!({"episode_index": i.episode_index, "task": i.task, "frames": i.frames})
            });
            println!(
                "RECOVERY {}",
                serde_json::json!({
                    "interrupted": interrupted,
                    "rolled_forward": r.rolled_forward.len(),
                    "removed_temporaries": r.removed_temporaries.len(),
                })
            );
            episode(&mut w, "pick up the cube", 60, 4.0)?;
            w.save_episode().map_err(|e| e.to_string())?;
            println!(
                "WROTE {} episodes, {} frames",
                w.total_episodes(),
                w.total_frames()
            );
        }
        Some(other) => return Err(format!("unknown option {other}")),
    }
    Ok(())
}

fn main() {
    if let Err(e) = run() {
        eprintln!("write_demo: {e}");
        std::process::exit(1);
    }
}
