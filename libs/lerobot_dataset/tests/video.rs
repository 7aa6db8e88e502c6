//! Cameras (needs Debian's ffmpeg, installed by launch_scripts/setup_env.sh): episodes
//! with a JPEG and a raw camera encoded, appended to one file per camera, their frames
//! decoded back by ffmpeg and compared with what was given; bad images refused; a
//! crash, a discard and a dying or missing ffmpeg.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::fs::{self, File};
use std::path::{Path, PathBuf};
use std::process::Command;

use arrow_array::{Array, Float64Array, Int64Array, ListArray, RecordBatch};
use lerobot_dataset::{DatasetSpec, DatasetWriter, Error, Frame, Image, RawEncoding};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use serde_json::Value;

const J: [&str; 4] = [
    "base_joint",
    "shoulder_joint",
    "elbow_joint",
    "gripper_joint",
];
const FRONT: (u32, u32) = (160, 120);
const WRIST: (u32, u32) = (64, 64);

fn spec() -> DatasetSpec {
    DatasetSpec::new(30, "eezybot_mk2", &J, &J)
        .with_camera("front", FRONT.0, FRONT.1)
        .with_camera("wrist", WRIST.0, WRIST.1)
}

/// Frame `i`'s colour: far apart from one frame to the next.
fn colour(i: usize, camera: usize) -> [u8; 3] {
    let i = i + 7 * camera;
    [
        (40 + i * 67 % 180) as u8,
        (30 + i * 101 % 190) as u8,
        (20 + i * 151 % 200) as u8,
    ]
}

fn jpeg(i: usize) -> Vec<u8> {
    let c = colour(i, 0);
    let rgb: Vec<u8> = (0..FRONT.0 * FRONT.1).flat_map(|_| c).collect();
    let mut out = Vec::new();
    jpeg_encoder::Encoder::new(&mut out, 90)
        .encode(
            &rgb,
            FRONT.0 as u16,
            FRONT.1 as u16,
            jpeg_encoder::ColorType::Rgb,
        )
        .unwrap();
    out
}

/// bgr8 rows of `WRIST.0 * 3 + 4` bytes (padding as some drivers have).
fn bgr(i: usize) -> Vec<u8> {
    let [r, g, b] = colour(i, 1);
    let step = WRIST.0 as usize * 3 + 4;
    let mut data = vec![0xEE; step * WRIST.1 as usize];
    for row in data.chunks_mut(step) {
        for p in row[..WRIST.0 as usize * 3].chunks_mut(3) {
            p.copy_from_slice(&[b, g, r]);
        }
    }
    data
}

fn add(w: &mut DatasetWriter, i: usize) -> Result<(), Error> {
    add_with(w, i, true)
}

/// Adds frame `i` of both cameras; `wait`: while ffmpeg is a second behind.
fn add_with(w: &mut DatasetWriter, i: usize, wait: bool) -> Result<(), Error> {
    let v = [i as f32 * 0.01; 4];
    let j = jpeg(i);
    let b = bgr(i);
    let images = [
        Image::Jpeg(&j),
        Image::Raw {
            encoding: RawEncoding::Bgr8,
            width: WRIST.0,
            height: WRIST.1,
            step: WRIST.0 * 3 + 4,
            data: &b,
        },
    ];
    let frame = Frame {
        state: &v,
        action: &v,
        images: &images,
    };
    if wait {
        add_waiting(w, frame)
    } else {
        w.add_frame(frame)
    }
}

/// add_frame, waiting while ffmpeg is a second behind (these tests add frames faster
/// than real time)
fn add_waiting(w: &mut DatasetWriter, frame: Frame<'_>) -> Result<(), Error> {
    let start = std::time::Instant::now();
    loop {
        match w.add_frame(frame) {
            Err(Error::EncoderBehind { .. })
                if start.elapsed() < std::time::Duration::from_secs(5) =>
            {
                std::thread::sleep(std::time::Duration::from_millis(5))
            }
            r => return r,
        }
    }
}

fn read(path: &Path) -> RecordBatch {
    let f = File::open(path).unwrap();
    let r = ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap();
    let b: Vec<RecordBatch> = r.map(|b| b.unwrap()).collect();
    assert_eq!(b.len(), 1);
    b[0].clone()
}

fn json(path: &Path) -> Value {
    serde_json::from_slice(&fs::read(path).unwrap()).unwrap()
}

/// Every frame of an mp4 decoded by ffmpeg to RGB.
fn decode(mp4: &Path, w: u32, h: u32) -> Vec<Vec<u8>> {
    let out = Command::new("ffmpeg")
        .args(["-v", "error", "-i"])
        .arg(mp4)
        .args(["-f", "rawvideo", "-pix_fmt", "rgb24", "-"])
        .output()
        .unwrap();
    assert!(out.status.success());
    out.stdout
        .chunks((w * h * 3) as usize)
        .map(<[u8]>::to_vec)
        .collect()
}

/// The ffmpeg processes whose command line names `root`.
fn ffmpeg_children(root: &Path) -> usize {
    let me = std::process::id().to_string();
    let root = root.to_string_lossy().to_string();
    fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| {
            let p = e.path();
            let stat = fs::read_to_string(p.join("stat")).unwrap_or_default();
            let ppid = stat
                .rsplit(')')
                .next()
                .and_then(|s| s.split_whitespace().nth(1))
                .unwrap_or("");
            let cmd = fs::read(p.join("cmdline")).unwrap_or_default();
            ppid == me && String::from_utf8_lossy(&cmd).contains(&root)
        })
        .count()
}

fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = fs::read_dir(dir)
        .map(|r| r.filter_map(|e| e.ok()).map(|e| e.path()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn two_cameras_two_episodes_one_discarded() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    let info = json(&root.join("meta/info.json"));
    assert_eq!(
        info["video_path"],
        "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    );
    assert_eq!(
        info["features"]["observation.images.front"],
        serde_json::json!({"dtype": "video", "shape": [120, 160, 3],
            "names": ["height", "width", "channels"], "info": {"is_depth_map": false}})
    );

    w.start_episode("pick up the cube").unwrap();
    for i in 0..20 {
        add(&mut w, i).unwrap();
    }
    assert_eq!(ffmpeg_children(&root), 2, "one ffmpeg per camera");
    w.save_episode().unwrap();
    assert_eq!(ffmpeg_children(&root), 0);

    w.start_episode("a false start").unwrap();
    for i in 0..5 {
        add(&mut w, 100 + i).unwrap();
    }
    assert_eq!(w.discard_episode().unwrap(), 5);
    assert_eq!(ffmpeg_children(&root), 0, "discard kills ffmpeg");
    assert_eq!(files_under(&root.join(".recording")), Vec::<PathBuf>::new());

    w.start_episode("wave").unwrap();
    for i in 20..33 {
        add(&mut w, i).unwrap();
    }
    w.save_episode().unwrap();
    drop(w);

    // info.json: the probed video info after the first episode, in lerobot's key order
    let text = fs::read_to_string(root.join("meta/info.json")).unwrap();
    let info: Value = serde_json::from_str(&text).unwrap();
    let front = &info["features"]["observation.images.front"]["info"];
    assert_eq!(
        front,
        &serde_json::json!({"is_depth_map": false, "video.height": 120, "video.width": 160,
            "video.codec": "av1", "video.pix_fmt": "yuv420p", "video.fps": 30,
            "video.channels": 3, "has_audio": false, "video.g": 2, "video.crf": 30,
            "video.preset": 12, "video.fast_decode": 0, "video.video_backend": "pyav",
            "video.extra_options": {}})
    );
    let at = |k: &str| text.find(&format!("\"{k}\"")).unwrap();
    assert!(at("is_depth_map") < at("video.height") && at("has_audio") < at("video.g"));
    assert!(at("observation.images.wrist") < at("timestamp"));
    assert_eq!(info["total_frames"], 33);

    // the episodes table: both episodes in file 0 of each camera, end to end
    let e = read(&root.join("meta/episodes/chunk-000/file-000.parquet"));
    let names: Vec<String> = e
        .schema()
        .fields()
        .iter()
        .map(|f| f.name().clone())
        .collect();
    let pos = |n: &str| names.iter().position(|x| x == n).unwrap();
    assert_eq!(
        pos("videos/observation.images.front/chunk_index"),
        pos("dataset_to_index") + 1
    );
    assert!(
        pos("videos/observation.images.wrist/to_timestamp") < pos("stats/observation.state/min")
    );
    for cam in ["front", "wrist"] {
        let col = |s: &str| format!("videos/observation.images.{cam}/{s}");
        let ints = |s: &str| {
            e.column_by_name(&col(s))
                .unwrap()
                .as_any()
                .downcast_ref::<Int64Array>()
                .unwrap()
                .values()
                .to_vec()
        };
        let floats = |s: &str| {
            e.column_by_name(&col(s))
                .unwrap()
                .as_any()
                .downcast_ref::<Float64Array>()
                .unwrap()
                .values()
                .to_vec()
        };
        assert_eq!(ints("chunk_index"), vec![0, 0]);
        assert_eq!(ints("file_index"), vec![0, 0]);
        assert_eq!(floats("from_timestamp"), vec![0.0, 20.0 / 30.0]);
        assert_eq!(floats("to_timestamp"), vec![20.0 / 30.0, 33.0 / 30.0]);
    }
    // image stats nested (3, 1, 1)
    let min = e
        .column_by_name("stats/observation.images.front/min")
        .unwrap();
    let min = min.as_any().downcast_ref::<ListArray>().unwrap();
    let channels = min.value(0);
    assert_eq!(channels.len(), 3);
    let rows = channels
        .as_any()
        .downcast_ref::<ListArray>()
        .unwrap()
        .value(0);
    let cols = rows.as_any().downcast_ref::<ListArray>().unwrap().value(0);
    assert_eq!(
        cols.as_any().downcast_ref::<Float64Array>().unwrap().len(),
        1
    );

    // the videos: every frame, in order, of the colour given (JPEG and AV1 tolerance)
    for (cam, (w, h)) in [(0, FRONT), (1, WRIST)] {
        let name = ["front", "wrist"][cam];
        let mp4 = root.join(format!(
            "videos/observation.images.{name}/chunk-000/file-000.mp4"
        ));
        let frames = decode(&mp4, w, h);
        assert_eq!(frames.len(), 33, "{name}");
        for (k, f) in frames.iter().enumerate() {
            let centre = ((h / 2 * w + w / 2) * 3) as usize;
            let want = colour(k, cam);
            for c in 0..3 {
                let d = (i32::from(f[centre + c]) - i32::from(want[c])).abs();
                assert!(
                    d <= 8,
                    "{name} frame {k} channel {c}: {} vs {}",
                    f[centre + c],
                    want[c]
                );
            }
        }
    }

    // stats.json: the frames are solid colours, so each channel's mean over the
    // sampled frames is the mean of their colours (all 33 are sampled)
    let st = json(&root.join("meta/stats.json"));
    let s = &st["observation.images.wrist"];
    assert_eq!(s["count"], serde_json::json!([33]));
    assert_eq!(s["mean"].as_array().unwrap().len(), 3);
    for c in 0..3 {
        let mean = (0..33).map(|k| f64::from(colour(k, 1)[c])).sum::<f64>() / 33.0 / 255.0;
        let got = s["mean"][c][0][0].as_f64().unwrap();
        assert!((got - mean).abs() < 2.0 / 255.0, "{c}: {got} vs {mean}");
    }
    assert!(s["q50"][0][0][0].is_number());
}

#[test]
fn bad_images_are_refused_and_the_episode_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    w.start_episode("t").unwrap();
    add(&mut w, 0).unwrap();
    let v = [0.0f32; 4];
    let j = jpeg(1);
    let b = bgr(1);
    let raw = |width, height, step, data| Image::Raw {
        encoding: RawEncoding::Bgr8,
        width,
        height,
        step,
        data,
    };
    let bad: Vec<(Vec<Image<'_>>, &str)> = vec![
        (
            vec![Image::Jpeg(&j)],
            "1 images, expected one per camera (2)",
        ),
        (
            vec![Image::Jpeg(&j), Image::Jpeg(&j)],
            "a 160x120 JPEG, expected 64x64",
        ),
        (vec![Image::Jpeg(&b), raw(64, 64, 196, &b)], "not a JPEG"),
        (
            vec![Image::Jpeg(&j), raw(64, 32, 196, &b)],
            "a 64x32 image, expected 64x64",
        ),
        (
            vec![Image::Jpeg(&j), raw(64, 64, 100, &b)],
            "step 100 is less than a row",
        ),
        (
            vec![raw(160, 120, 480, &[0; 57600]), raw(64, 64, 196, &b)],
            "a raw frame in an episode whose frames are JPEG",
        ),
    ];
    for (images, why) in bad {
        let e = w
            .add_frame(Frame {
                state: &v,
                action: &v,
                images: &images,
            })
            .unwrap_err();
        assert!(matches!(e, Error::BadFrame(_)), "{e}");
        assert!(e.to_string().contains(why), "{e} / {why}");
    }
    add(&mut w, 1).unwrap();
    let saved = w.save_episode().unwrap();
    assert_eq!(saved.frames, 2);
    let frames = decode(
        &root.join("videos/observation.images.front/chunk-000/file-000.mp4"),
        FRONT.0,
        FRONT.1,
    );
    assert_eq!(frames.len(), 2);
}

#[test]
fn a_crash_mid_episode_leaves_whole_episodes_and_resume_starts_new_files() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    w.start_episode("pick").unwrap();
    for i in 0..10 {
        add(&mut w, i).unwrap();
    }
    w.save_episode().unwrap();
    let info_before = fs::read(root.join("meta/info.json")).unwrap();
    w.start_episode("interrupted").unwrap();
    for i in 0..7 {
        add(&mut w, i).unwrap();
    }
    assert_eq!(ffmpeg_children(&root), 2);
    drop(w); // a crash: the writer's ffmpeg go with it
    assert_eq!(ffmpeg_children(&root), 0, "no ffmpeg outlives the writer");
    // what the episode's cameras left (ffmpeg may not have opened its mp4 yet)
    assert!(root
        .join(".recording/observation.images.front.counts")
        .exists());

    // a resume with other cameras is refused, touching nothing
    let other = DatasetSpec::new(30, "eezybot_mk2", &J, &J).with_camera("front", 320, 240);
    let e = DatasetWriter::open_resume(&root, other).err().unwrap();
    let text = e.to_string();
    assert!(text.contains("feature observation.images.front: shape is [120,160,3] in the dataset, [240,320,3] here"), "{text}");
    assert!(
        text.contains("the dataset has feature observation.images.wrist"),
        "{text}"
    );
    assert!(root.join(".recording/episode.jsonl").exists());

    let (mut w, rec) = DatasetWriter::open_resume(&root, spec()).unwrap();
    let i = rec.interrupted.unwrap();
    assert_eq!((i.episode_index, i.frames), (1, 7));
    let removed: Vec<String> = rec
        .removed_episode_files
        .iter()
        .map(|p| p.to_string_lossy().to_string())
        .collect();
    assert!(
        removed.contains(&".recording/observation.images.front.ffmpeg.log".to_string())
            && removed.contains(&".recording/observation.images.wrist.counts".to_string()),
        "{removed:?}"
    );
    assert_eq!(files_under(&root.join(".recording")), Vec::<PathBuf>::new());
    // the video info of the first episode is kept as it was
    assert_eq!(fs::read(root.join("meta/info.json")).unwrap(), info_before);

    // resumed: the next episode starts the next video file, as lerobot's resume does
    w.start_episode("after").unwrap();
    for i in 0..4 {
        add(&mut w, i).unwrap();
    }
    w.save_episode().unwrap();
    let front = root.join("videos/observation.images.front/chunk-000");
    assert_eq!(
        files_under(&front),
        vec![front.join("file-000.mp4"), front.join("file-001.mp4")]
    );
    assert_eq!(
        decode(&front.join("file-000.mp4"), FRONT.0, FRONT.1).len(),
        10
    );
    assert_eq!(
        decode(&front.join("file-001.mp4"), FRONT.0, FRONT.1).len(),
        4
    );
    let info = json(&root.join("meta/info.json"));
    assert_eq!(
        info["features"]["observation.images.front"]["info"]["video.codec"],
        "av1"
    );
    let e = read(&root.join("meta/episodes/chunk-000/file-001.parquet"));
    let file = e
        .column_by_name("videos/observation.images.front/file_index")
        .unwrap()
        .as_any()
        .downcast_ref::<Int64Array>()
        .unwrap()
        .value(0);
    assert_eq!(file, 1);
}

#[test]
fn a_missing_or_dying_ffmpeg_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut missing = spec();
    missing.ffmpeg = dir.path().join("no-ffmpeg-here");
    let e = DatasetWriter::create(dir.path().join("a"), missing)
        .err()
        .unwrap();
    assert!(matches!(e, Error::Video { .. }), "{e}");
    assert!(e.to_string().contains("cannot run"), "{e}");

    // an ffmpeg that has the encoder but dies when asked to encode
    let fake = dir.path().join("ffmpeg");
    fs::write(
        &fake,
        "#!/bin/sh\ncase \"$*\" in *-encoders*) echo ' V..... libsvtav1 SVT-AV1';; \
         *) echo 'encoder exploded' >&2; exit 3;; esac\n",
    )
    .unwrap();
    Command::new("chmod").arg("+x").arg(&fake).status().unwrap();
    let mut dying = spec();
    dying.ffmpeg = fake;
    let root = dir.path().join("b");
    let mut w = DatasetWriter::create(&root, dying).unwrap();
    w.start_episode("t").unwrap();
    // the first frames may be queued before ffmpeg is seen gone; the save sees it
    let mut err = None;
    for i in 0..30 {
        if let Err(e) = add(&mut w, i) {
            err = Some(e);
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let e = match err {
        Some(e) => e,
        None => w.save_episode().unwrap_err(),
    };
    assert!(matches!(e, Error::Video { .. }), "{e}");
    assert!(e.to_string().contains("encoder exploded"), "{e}");
    // nothing saved, the episode can be discarded
    assert!(w.save_episode().is_err());
    w.discard_episode().unwrap();
    assert_eq!(w.total_episodes(), 0);
    assert_eq!(files_under(&root.join(".recording")), Vec::<PathBuf>::new());
}

#[test]
fn video_files_roll_at_their_size() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut spec = DatasetSpec::new(30, "eezybot_mk2", &J, &J).with_camera("noise", 256, 256);
    spec.video_files_size_in_mb = 1;
    let mut w = DatasetWriter::create(&root, spec).unwrap();
    // noise compresses badly: each episode is a good part of a megabyte
    let mut seed = 7u64;
    let mut sizes = Vec::new();
    for e in 0..4 {
        w.start_episode("noise").unwrap();
        for _ in 0..12 {
            let px: Vec<u8> = (0..256 * 256 * 3)
                .map(|_| {
                    seed = seed
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (seed >> 56) as u8
                })
                .collect();
            let v = [0.0f32; 4];
            let img = Image::Raw {
                encoding: RawEncoding::Rgb8,
                width: 256,
                height: 256,
                step: 768,
                data: &px,
            };
            add_waiting(
                &mut w,
                Frame {
                    state: &v,
                    action: &v,
                    images: &[img],
                },
            )
            .unwrap();
        }
        w.save_episode().unwrap();
        let dir = root.join("videos/observation.images.noise/chunk-000");
        sizes.push(
            files_under(&dir)
                .iter()
                .map(|p| fs::metadata(p).unwrap().len())
                .collect::<Vec<_>>(),
        );
        assert!(sizes[e].len() <= e + 1);
    }
    let e = read(&root.join("meta/episodes/chunk-000/file-000.parquet"));
    let col = |s: &str| {
        e.column_by_name(&format!("videos/observation.images.noise/{s}"))
            .unwrap()
            .clone()
    };
    let files = col("file_index");
    let files = files
        .as_any()
        .downcast_ref::<Int64Array>()
        .unwrap()
        .values()
        .to_vec();
    let from = col("from_timestamp");
    let from = from
        .as_any()
        .downcast_ref::<Float64Array>()
        .unwrap()
        .values()
        .to_vec();
    // both cases happened (here: [0, 0, 1, 1] for episodes of about 0.45 MB)
    assert!(
        files.windows(2).any(|p| p[0] == p[1]) && files.windows(2).any(|p| p[0] != p[1]),
        "{files:?} {sizes:?}"
    );
    let mb = 1024.0 * 1024.0;
    let last = sizes.last().unwrap();
    assert!(last.len() >= 2, "the file rolled: {sizes:?}");
    for k in 1..4 {
        if files[k] == files[k - 1] {
            // appended: it fitted under 1 MB, and starts where the file ended
            assert!((from[k] - from[k - 1] - 12.0 / 30.0).abs() < 1e-9);
        } else {
            // a new file: the next index, from 0, because the old file plus this episode
            // reached 1 MB
            assert_eq!(files[k], files[k - 1] + 1);
            assert_eq!(from[k], 0.0);
            let old = sizes[k - 1][files[k - 1] as usize] as f64;
            let this = sizes[k][files[k] as usize] as f64;
            assert!(old + this >= mb, "{sizes:?}");
        }
    }
    // every file holds the frames of its episodes
    for (i, f) in files_under(&root.join("videos/observation.images.noise/chunk-000"))
        .iter()
        .enumerate()
    {
        let eps = files.iter().filter(|&&x| x == i as i64).count();
        assert_eq!(decode(f, 256, 256).len(), 12 * eps, "{sizes:?}");
    }
}

#[test]
fn a_frame_is_refused_whole_when_ffmpeg_is_a_second_behind() {
    let dir = tempfile::tempdir().unwrap();
    // an "ffmpeg" that has the encoder but never reads its input
    let fake = dir.path().join("ffmpeg");
    fs::write(
        &fake,
        "#!/bin/sh\ncase \"$*\" in *-encoders*) echo ' V..... libsvtav1 SVT-AV1';; \
         *) exec sleep 60;; esac\n",
    )
    .unwrap();
    Command::new("chmod").arg("+x").arg(&fake).status().unwrap();
    let mut spec = spec();
    spec.ffmpeg = fake;
    let mut w = DatasetWriter::create(dir.path().join("ds"), spec).unwrap();
    w.start_episode("t").unwrap();
    // the pipe takes some frames, the queue one second (30) more: then add_frame refuses
    // instead of waiting
    let mut refused = None;
    for i in 0..2000 {
        match add_with(&mut w, i, false) {
            Ok(()) => {}
            Err(e) => {
                refused = Some((i, e));
                break;
            }
        }
    }
    let (i, e) = refused.expect("refused once the queue is full");
    assert!(matches!(e, Error::EncoderBehind { frames: 30, .. }), "{e}");
    assert!(e.to_string().contains("the frame was not recorded"), "{e}");
    // the refused frame is in no camera and not in the table
    assert_eq!(w.episode_frames(), Some(i));
    assert!(matches!(
        add_with(&mut w, i, false),
        Err(Error::EncoderBehind { .. })
    ));
    // discard kills the stuck encoder at once
    let t = std::time::Instant::now();
    assert_eq!(w.discard_episode().unwrap(), i);
    assert!(t.elapsed() < std::time::Duration::from_secs(30));
}

/// The pts of every frame of an MP4 (ffprobe), seconds.
fn pts(mp4: &Path) -> Vec<f64> {
    let out = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-select_streams",
            "v",
            "-show_entries",
            "frame=pts_time",
            "-of",
            "csv=p=0",
        ])
        .arg(mp4)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| l.trim().trim_end_matches(',').parse().unwrap())
        .collect()
}

/// An episode appended to a camera's file starts at its `from_timestamp` exactly, also
/// when the file before it lasts no whole number of milliseconds (23 frames at 30 fps:
/// 0.7667 s): lerobot finds each frame at `from_timestamp + timestamp` within 1e-4 s.
#[test]
fn an_appended_episode_starts_at_its_from_timestamp() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    for (e, n) in [(0, 23), (1, 23), (2, 10)] {
        w.start_episode(&format!("episode {e}")).unwrap();
        for i in 0..n {
            add(&mut w, e * 100 + i).unwrap();
        }
        w.save_episode().unwrap();
    }
    drop(w);
    let episodes = read(&root.join("meta/episodes/chunk-000/file-000.parquet"));
    let from = episodes
        .column_by_name("videos/observation.images.front/from_timestamp")
        .unwrap()
        .as_any()
        .downcast_ref::<Float64Array>()
        .unwrap()
        .clone();
    let t = pts(&root.join("videos/observation.images.front/chunk-000/file-000.mp4"));
    assert_eq!(t.len(), 56);
    for (e, first) in [(0usize, 0usize), (1, 23), (2, 46)] {
        assert!(
            (t[first] - from.value(e)).abs() < 1e-5
                && (from.value(e) - first as f64 / 30.0).abs() < 1e-9,
            "episode {e}: its first frame at {} s, from_timestamp {}",
            t[first],
            from.value(e)
        );
    }
    for (k, p) in t.iter().enumerate() {
        assert!((p - k as f64 / 30.0).abs() < 1e-4, "frame {k} at {p} s");
    }
}
