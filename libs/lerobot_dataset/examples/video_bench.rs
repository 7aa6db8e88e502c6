//! Measures a camera's cost: episodes of one 640x480 camera at 30 fps fed in real time,
//! then the time from stop to saved, ffmpeg's CPU and the video's bytes per minute.
//!
//!     video_bench DIR [--seconds 20] [--episodes 2] [--raw]
//!
//! The frames are a moving scene (a gradient, a square crossing it, a fine texture) with
//! sensor-like noise of ±4 levels, 60 distinct frames cycled, JPEG-encoded (quality 90)
//! before the clock starts; `--raw` gives them as rgb8 pixels instead. Prints one line
//! per episode. ffmpeg's CPU is the children's CPU time (`/proc/self/stat` cutime +
//! cstime, counted once ffmpeg has been waited for) over the episode's wall time.

use std::time::{Duration, Instant};

use lerobot_dataset::{DatasetSpec, DatasetWriter, Error, Frame, Image, RawEncoding};

const W: u32 = 640;
const H: u32 = 480;
const FPS: u32 = 30;

fn scene(i: u32) -> Vec<u8> {
    let mut seed = 0x9E37_79B9_7F4A_7C15u64 ^ u64::from(i);
    let mut rgb = Vec::with_capacity((W * H * 3) as usize);
    let (sx, sy) = ((i * 7) % (W - 120), 100 + (i * 3) % (H - 220));
    for y in 0..H {
        for x in 0..W {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((seed >> 61) as i32) - 4; // -4..=3
            let inside = x >= sx && x < sx + 120 && y >= sy && y < sy + 120;
            let texture = if (x / 4 + y / 4) % 2 == 0 { 12 } else { 0 };
            let base = if inside {
                [200, 60, 40]
            } else {
                [(x * 255 / W) as i32, (y * 255 / H) as i32, 128 + texture]
            };
            for c in base {
                rgb.push((c + noise).clamp(0, 255) as u8);
            }
        }
    }
    rgb
}

/// Children's CPU seconds (ffmpeg, ffprobe once waited for) and our own.
fn cpu_s() -> (f64, f64) {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let f: Vec<f64> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    // after the comm: state is [0]; utime [11], stime [12], cutime [13], cstime [14]
    let tick = 100.0;
    let get = |i: usize| f.get(i).copied().unwrap_or(0.0) / tick;
    (get(13) + get(14), get(11) + get(12))
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = args
        .first()
        .ok_or("usage: video_bench DIR [--seconds S] [--episodes N] [--raw]")?;
    let opt = |name: &str, default: u32| -> u32 {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let seconds = opt("--seconds", 20);
    let episodes = opt("--episodes", 2);
    let raw = args.iter().any(|a| a == "--raw");
    let frames: Vec<Vec<u8>> = (0..60)
        .map(|i| {
            let rgb = scene(i);
            if raw {
                return Ok(rgb);
            }
            let mut jpeg = Vec::new();
            jpeg_encoder::Encoder::new(&mut jpeg, 90)
                .encode(&rgb, W as u16, H as u16, jpeg_encoder::ColorType::Rgb)
                .map_err(|e| e.to_string())?;
            Ok(jpeg)
        })
        .collect::<Result<_, String>>()?;
    let jpeg_kb = frames.iter().map(Vec::len).sum::<usize>() as f64 / 60.0 / 1024.0;
    println!(
        "frames: {} 640x480, {:.1} KiB each",
        if raw { "rgb8" } else { "JPEG" },
        jpeg_kb
    );
    let spec = DatasetSpec::new(FPS, "eezybot_mk2", &["j"], &["j"]).with_camera("camera", W, H);
    let mut w = DatasetWriter::create(dir, spec).map_err(|e| e.to_string())?;
    let n = seconds * FPS;
    let v = [0.0f32];
    for e in 0..episodes {
        let (child0, own0) = cpu_s();
        w.start_episode("bench").map_err(|e| e.to_string())?;
        let t0 = Instant::now();
        let mut worst_add = Duration::ZERO;
        let mut dropped = 0;
        for i in 0..n {
            let due = t0 + Duration::from_secs_f64(f64::from(i) / f64::from(FPS));
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
            let f = &frames[(i % 60) as usize];
            let img = if raw {
                Image::Raw {
                    encoding: RawEncoding::Rgb8,
                    width: W,
                    height: H,
                    step: W * 3,
                    data: f,
                }
            } else {
                Image::Jpeg(f)
            };
            let a = Instant::now();
            match w.add_frame(Frame {
                state: &v,
                action: &v,
                images: &[img],
            }) {
                Ok(()) => {}
                // ffmpeg a second behind: a dropped frame, as a live recorder counts it
                Err(Error::EncoderBehind { .. }) => dropped += 1,
                Err(e) => return Err(e.to_string()),
            }
            worst_add = worst_add.max(a.elapsed());
        }
        let recorded = t0.elapsed().as_secs_f64();
        let stop = Instant::now();
        w.save_episode().map_err(|e| e.to_string())?;
        let saved = stop.elapsed().as_secs_f64();
        let (child1, own1) = cpu_s();
        let mp4 = std::path::Path::new(dir).join(format!(
            "videos/observation.images.camera/chunk-000/file-{:03}.mp4",
            0
        ));
        let size = std::fs::metadata(&mp4).map(|m| m.len()).unwrap_or(0);
        println!(
            "episode {e}: {n} frames in {recorded:.1} s ({dropped} refused: ffmpeg behind); \
             stop -> saved {saved:.3} s; \
             ffmpeg CPU {:.0} % of a core; writer CPU {:.0} %; slowest add_frame {:.1} ms; \
             video file now {:.2} MB ({:.2} MB per minute of video)",
            100.0 * (child1 - child0) / (recorded + saved),
            100.0 * (own1 - own0) / (recorded + saved),
            worst_add.as_secs_f64() * 1000.0,
            size as f64 / 1e6,
            size as f64 / 1e6 / (f64::from(seconds) * f64::from(e + 1) / 60.0)
        );
    }
    Ok(())
}

fn main() {
    if let Err(e) = run() {
        eprintln!("video_bench: {e}");
        std::process::exit(1);
    }
}
