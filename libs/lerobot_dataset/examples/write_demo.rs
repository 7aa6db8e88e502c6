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
//!
//! With `--cameras` (anywhere after DIR) the dataset has two cameras: `front`, 320x240
//! JPEG frames, and `wrist`, 160x120 raw `bgr8` frames with 8 bytes of padding per row.
//! Each frame is four quadrants of solid colour, [`colour`] of the frame's dataset
//! `index`, the quadrant and the camera (tests/test_lerobot_dataset.py computes the same).

use std::io::Write;

use lerobot_dataset::{DatasetSpec, DatasetWriter, Error, Frame, Image, Interrupted, RawEncoding};

/// What `--resume` prints after `RECOVERY` (tests/test_lerobot_dataset.py reads it).
#[derive(serde::Serialize)]
struct RecoveryReport<'a> {
    interrupted: Option<&'a Interrupted>,
    rolled_forward: usize,
    removed_temporaries: usize,
    removed_episode_files: &'a [std::path::PathBuf],
}

const FRONT: (u32, u32) = (320, 240);
const WRIST: (u32, u32) = (160, 120);
const WRIST_STEP: u32 = WRIST.0 * 3 + 8;

/// Quadrant `q` (0 top left, 1 top right, 2 bottom left, 3 bottom right) of the frame
/// with dataset index `index` of camera `camera` (0 front, 1 wrist): channels in 20..236.
fn colour(index: u64, q: u64, camera: u64) -> [u8; 3] {
    let k = index * 4 + q + camera * 2;
    [
        ((37 * k + 40) % 216 + 20) as u8,
        ((91 * k + 10) % 216 + 20) as u8,
        ((53 * k + 90) % 216 + 20) as u8,
    ]
}

/// The frame as packed RGB.
fn pattern(index: u64, camera: u64, (w, h): (u32, u32)) -> Vec<u8> {
    let mut rgb = Vec::with_capacity((w * h * 3) as usize);
    for y in 0..h {
        for x in 0..w {
            let q = u64::from(y >= h / 2) * 2 + u64::from(x >= w / 2);
            rgb.extend_from_slice(&colour(index, q, camera));
        }
    }
    rgb
}

/// The images of the frame with dataset index `index`: a JPEG and padded bgr8 rows.
fn images(index: u64) -> Result<(Vec<u8>, Vec<u8>), String> {
    let mut jpeg = Vec::new();
    jpeg_encoder::Encoder::new(&mut jpeg, 90)
        .encode(
            &pattern(index, 0, FRONT),
            FRONT.0 as u16,
            FRONT.1 as u16,
            jpeg_encoder::ColorType::Rgb,
        )
        .map_err(|e| e.to_string())?;
    let rgb = pattern(index, 1, WRIST);
    let mut bgr = Vec::with_capacity((WRIST_STEP * WRIST.1) as usize);
    for row in rgb.chunks((WRIST.0 * 3) as usize) {
        for p in row.chunks(3) {
            bgr.extend_from_slice(&[p[2], p[1], p[0]]);
        }
        bgr.extend_from_slice(&[0xAB; 8]);
    }
    Ok((jpeg, bgr))
}

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
    let cameras = !w.spec().cameras.is_empty();
    w.start_episode(task).map_err(|e| e.to_string())?;
    for i in 0..frames {
        let t = i as f64 / 30.0;
        let state = joints(t, phase);
        let action = joints(t + 0.1, phase);
        // the frame's dataset index (lerobot's `index`)
        let index = w.total_frames() + i as u64;
        let (jpeg, bgr) = if cameras {
            images(index)?
        } else {
            Default::default()
        };
        let both = [
            Image::Jpeg(&jpeg),
            Image::Raw {
                encoding: RawEncoding::Bgr8,
                width: WRIST.0,
                height: WRIST.1,
                step: WRIST_STEP,
                data: &bgr,
            },
        ];
        let frame = Frame {
            state: &state,
            action: &action,
            images: if cameras { &both } else { &[] },
        };
        // offline, so wait for an ffmpeg that is a second behind (a live recorder would
        // count the frame as dropped)
        loop {
            match w.add_frame(frame) {
                Err(Error::EncoderBehind { .. }) => {
                    std::thread::sleep(std::time::Duration::from_millis(5))
                }
                r => break r.map_err(|e| e.to_string())?,
            }
        }
    }
    Ok(())
}

fn spec(cameras: bool) -> DatasetSpec {
    let s = DatasetSpec::new(30, "eezybot_mk2", &JOINTS, &JOINTS);
    if cameras {
        s.with_camera("front", FRONT.0, FRONT.1)
            .with_camera("wrist", WRIST.0, WRIST.1)
    } else {
        s
    }
}

fn run() -> Result<(), String> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let cameras = args.iter().any(|a| a == "--cameras");
    args.retain(|a| a != "--cameras");
    let spec = || spec(cameras);
    let dir = args
        .first()
        .ok_or("usage: write_demo DIR [--cameras] [--resume|--stop-mid-episode]")?;
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
            let report = RecoveryReport {
                interrupted: r.interrupted.as_ref(),
                rolled_forward: r.rolled_forward.len(),
                removed_temporaries: r.removed_temporaries.len(),
                removed_episode_files: &r.removed_episode_files,
            };
            println!(
                "RECOVERY {}",
                serde_json::to_string(&report).map_err(|e| e.to_string())?
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
