//! Writes LeRobot v3.0 datasets as lerobot 0.6.1 writes them, from Rust and without ROS:
//! the `recorder` node drives a [`DatasetWriter`].
//!
//! # Layout (lerobot's `datasets/utils.py`, `dataset_metadata.py`, `dataset_writer.py`)
//! - `meta/info.json`: the `DatasetInfo` dataclass in field order (codebase_version
//!   `v3.0`, fps, features, totals, chunks_size 1000, data_files_size_in_mb 100,
//!   video_files_size_in_mb 200, data_path, video_path (null without cameras),
//!   robot_type, splits `{"train": "0:N"}`), indented by 4;
//! - `meta/stats.json`: per feature min, max, mean, std, count, q01 … q99
//!   ([`stats`]: lerobot's histogram quantiles and its aggregation across episodes);
//! - `meta/tasks.parquet`: `task_index` with the task as pandas index ([`tables`]);
//! - `meta/episodes/chunk-CCC/file-FFF.parquet`: one row per episode, its per-episode
//!   stats as `stats/<feature>/<stat>` columns;
//! - `data/chunk-CCC/file-FFF.parquet`: one row per frame;
//! - `videos/<key>/chunk-CCC/file-FFF.mp4`: each camera's episodes end to end.
//!
//! Features: `observation.state` and `action` (float32 vectors named by the joint
//! names), then lerobot's defaults `timestamp` (float32, `frame_index / fps`, as
//! lerobot's `add_frame` computes it: frames are on the fps grid by construction),
//! `frame_index`, `episode_index`, `index`, `task_index` (int64); each camera's
//! `observation.images.<name>` after `action` (below, "Cameras").
//!
//! Files roll as lerobot rolls them: a data or episodes file is closed when its size
//! plus the new episode's estimated size (the file's bytes per frame, or for the
//! episodes table lerobot's bytes per `episode_index`) reaches `data_files_size_in_mb`;
//! the next file is `file-FFF+1`, and after `chunks_size` files the next chunk. A
//! resumed dataset continues in new files, as lerobot's resume does.
//!
//! # Crash safety
//! - **An episode in progress** lives in memory and, frame by frame, in
//!   `<root>/.recording/episode.jsonl` (a header line with its index and task, then one
//!   line per frame, flushed to the OS each frame). Nothing under `meta/` or `data/`
//!   changes until it is saved, so a `kill -9` or a power cut mid-episode leaves every
//!   finished episode as it was. Dropping a writer mid-episode is such a crash: the
//!   episode is left for the next [`DatasetWriter::open_resume`], which discards it and
//!   reports it ([`Recovery::interrupted`]: its index, task and the frames lost).
//! - **Saving** changes five files (data, episodes, tasks, stats, info), and one video
//!   file per camera (written by ffmpeg, see "Cameras"). Each is written
//!   whole to `<file>.tmp-commit` and fsynced; then a journal
//!   `.recording/commit.json` listing the renames is written (to a temporary, fsynced,
//!   renamed: it exists whole or not at all); then each temporary is renamed over its
//!   file, the directories fsynced, and the journal removed. A crash before the journal
//!   leaves the old files (the temporaries are removed at the next open); a crash after
//!   it is rolled forward at the next open. Either way the dataset has whole episodes
//!   only. (Between the journal and the last rename, a few microseconds, lerobot itself
//!   would see new data with old meta: open it with [`DatasetWriter::open_resume`] or
//!   [`recover`] first.) The temporaries do not end in `.parquet`, so lerobot's loader,
//!   which reads every `data/*/*.parquet`, never sees them.
//! - **A write error** (a full disk) in a save removes the temporaries, returns
//!   [`Error::Io`] and changes nothing: the finished episodes are intact and the episode
//!   stays in progress (save again once there is room, or discard it).
//! - **A folder that is not a LeRobot v3.0 dataset**, or whose fps or features differ from
//!   the spec, is refused by [`DatasetWriter::open_resume`] before anything in it is
//!   touched, with every difference named ([`Error::Mismatch`]).
//!
//! # Cameras ([`DatasetSpec::with_camera`], [`Frame::images`], [`video`])
//! What lerobot 0.6.1 writes (`dataset_writer.py` `_save_episode_video`,
//! `video_utils.py`, `configs/video.py`), and how this crate does it:
//! - **The feature** `observation.images.<name>` (after `action`, before lerobot's
//!   defaults): dtype `video`, shape `[h, w, 3]`, names `["height", "width", "channels"]`,
//!   `info` `{"is_depth_map": false}` at creation; after the first episode, what
//!   `get_video_info` probes from the file (here ffprobe: `video.height`, `video.width`,
//!   `video.codec` `av1`, `video.pix_fmt` `yuv420p`, `video.fps`, `video.channels` 3,
//!   `has_audio` false) then the encoder's settings (`video.g` 2, `video.crf` 30,
//!   `video.preset` 12, `video.fast_decode` 0, `video.video_backend` `pyav`,
//!   `video.extra_options` {}), in lerobot's key order. info.json's `video_path` is
//!   [`VIDEO_PATH`] when there are cameras. A resume also compares the cameras (shape,
//!   names) and refuses videos of another codec.
//! - **The frames** ([`Image`]): a JPEG (sensor_msgs/CompressedImage, passed to ffmpeg as
//!   is, as `-f mjpeg`) or raw pixels (sensor_msgs/Image `rgb8`, `bgr8`, `rgba8`, `bgra8`,
//!   `mono8` with its `step`; converted to packed RGB here, `-f rawvideo rgb24`). A frame
//!   whose size is not the camera's (read from the JPEG's SOF header), a JPEG that is not
//!   one, too few bytes for the rows, or a frame of the other kind than the episode's
//!   first frame of that camera (one ffmpeg input per episode) is refused
//!   ([`Error::BadFrame`]) and nothing of the frame is kept.
//! - **Encoding, live**: at a camera's first frame of an episode the writer starts one
//!   `ffmpeg` for it, with lerobot's default encoder (`RGBEncoderConfig()`: libsvtav1,
//!   yuv420p, `-g 2 -crf 30 -preset 12 -svtav1-params fast-decode=0`), input frame rate
//!   = the dataset's fps, `-fps_mode passthrough`: frame `i` has pts `i / fps`, exactly the
//!   row's timestamp (lerobot decodes `from_timestamp + timestamp`, tolerance 1e-4).
//!   Debian 12's ffmpeg 5.1 has libsvtav1 (SVT-AV1 1.4.1): measured at 30 fps 640x480
//!   (examples/video_bench.rs, release, JPEG frames of a moving noisy scene) it took
//!   38–43 % of one of this machine's 2 cores (32 % with raw rgb8 frames), so AV1 is
//!   kept (no need for libx264); about 3 MB per minute of that scene.
//!   The frames go to ffmpeg through a queue of one second and a thread: `add_frame`
//!   never waits for ffmpeg; when a camera's queue is full the frame is refused whole
//!   ([`Error::EncoderBehind`]: no camera and no row takes it; count it as dropped). ffmpeg writes
//!   `.recording/<feature>.mp4` and, as a second output, every frame decoded to RGB,
//!   which a thread counts ([`stats::PixelCounts`], lerobot's downsampling) into
//!   `.recording/<feature>.counts` (3 KiB per frame). Its messages go to
//!   `.recording/<feature>.ffmpeg.log`.
//! - **Image statistics**: lerobot's `compute_episode_stats` for a video feature (the
//!   frames at `sample_indices`, downsampled, per channel, /255; shape (3, 1, 1)) summed
//!   from the sampled frames' counts at save: exact for raw frames, and for JPEG frames
//!   over ffmpeg's decoding of them (lerobot's own path decodes its camera's frames too).
//!   Counting every frame live costs a little CPU but makes the save instant and keeps
//!   neither the pictures in memory nor a second decode of the episode at save (which
//!   would take seconds, and measure the AV1 loss instead of the frames).
//! - **Saving** (stop → saved 0.16–0.30 s for 20 s episodes at 30 fps 640x480 here; the
//!   remux rewrites the camera's current file, which near its 200 MB adds about a second:
//!   0.84 s for 181 MB plus an episode):
//!   close each pipe, wait for ffmpeg, check with ffprobe that it wrote every frame, then
//!   lerobot's placement: the camera's current file with the episode appended by a remux
//!   (ffmpeg's concat demuxer, `-c copy -movflags +faststart`, as
//!   `concatenate_video_files`), or, when its size plus the episode's reaches
//!   `video_files_size_in_mb` (200), or after creation or a resume, the next file
//!   (`file-FFF+1`, the next chunk after `chunks_size`). The new file is written as that
//!   file's `.tmp-commit` (a hard link for a new file) and is one more temporary of the
//!   save's journal below: a crash leaves whole episodes only, in the videos as in the
//!   tables. The episodes table gets `videos/<key>/chunk_index`, `file_index`,
//!   `from_timestamp` (the file's duration before the episode), `to_timestamp` (plus the
//!   episode's stream duration as PyAV computes it), after `dataset_to_index`.
//! - **Discard** kills the episode's ffmpeg and removes its files. **Dropping the
//!   writer** kills every ffmpeg it started (no child outlives it); after a `kill -9` of
//!   the process, its ffmpeg see their input end and exit by themselves. Either way the
//!   next [`DatasetWriter::open_resume`] discards the episode, removes its files and
//!   lists them ([`Recovery::removed_episode_files`]).
//! - **ffmpeg missing** (checked with its encoder list at create and resume when there
//!   are cameras), **stopping or failing** is [`Error::Video`] with its last messages,
//!   never a panic; an episode whose encoder stopped cannot be saved: discard it.
//! - Decoding on this machine: lerobot's default, torchcodec, does not load (it needs
//!   FFmpeg's shared libraries, `libavutil.so.56`–`59`); lerobot falls back to PyAV
//!   (15.1.0), whose wheel has libdav1d: lerobot 0.6.1 loaded the demo's camera datasets
//!   (tests/lerobot_load.py).
//!
//! The data and episodes files are rewritten whole at each save (their finished rows are
//! kept in memory until the file rolls): a file of 100 MB is about 1.5 million frames
//! (14 hours at 30 fps), so a save writes at most that.

pub mod json;
pub mod read;
pub mod stats;
pub mod tables;
pub mod video;

use std::fs::{self, File};
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use serde_json::Value;

use json::Ordered;
use stats::{FeatureStats, PixelCounts, Precision};
use tables::{DataRows, EpisodeRow, VideoLocation};
use video::{Encoder, EpisodeFiles, InputKind};
pub use video::{Image, RawEncoding};

/// lerobot's `CODEBASE_VERSION`.
pub const CODEBASE_VERSION: &str = "v3.0";
/// lerobot's `DEFAULT_CHUNK_SIZE`: files per chunk folder.
pub const DEFAULT_CHUNK_SIZE: u64 = 1000;
/// lerobot's `DEFAULT_DATA_FILE_SIZE_IN_MB`.
pub const DEFAULT_DATA_FILE_SIZE_IN_MB: u64 = 100;
/// lerobot's `DEFAULT_VIDEO_FILE_SIZE_IN_MB`.
pub const DEFAULT_VIDEO_FILE_SIZE_IN_MB: u64 = 200;
/// lerobot's `DEFAULT_DATA_PATH`.
pub const DATA_PATH: &str = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet";
/// lerobot's `DEFAULT_VIDEO_PATH` (info.json's `video_path` when there are cameras).
pub const VIDEO_PATH: &str = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4";
/// A camera's feature is this prefix and its name.
pub const IMAGE_FEATURE_PREFIX: &str = "observation.images.";
/// The folder of an episode in progress and of the commit journal.
pub const RECORDING_DIR: &str = ".recording";
const IN_PROGRESS: &str = "episode.jsonl";
const JOURNAL: &str = "commit.json";
const TMP_SUFFIX: &str = ".tmp-commit";

/// Why the writer refused or failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The folder is not a LeRobot v3.0 dataset; nothing in it was touched.
    #[error("{path} is not a LeRobot v3.0 dataset: {reason}")]
    NotADataset {
        /// The folder.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The dataset's fps or features differ from the spec; nothing was touched.
    #[error("{path}: the dataset differs from what is recorded: {}", .differences.join("; "))]
    Mismatch {
        /// The folder.
        path: PathBuf,
        /// Each difference, in words.
        differences: Vec<String>,
    },
    /// `create` on a folder that exists and is not empty.
    #[error("{0} exists and is not empty: resume it or choose a new folder")]
    NotEmpty(PathBuf),
    /// The spec itself is unusable.
    #[error("bad dataset spec: {0}")]
    BadSpec(String),
    /// A frame that does not fit the spec.
    #[error("bad frame: {0}")]
    BadFrame(String),
    /// start/add/save/discard out of order.
    #[error("{0}")]
    State(String),
    /// Reading or writing failed (a full disk): finished episodes are intact.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// A table could not be built or read.
    #[error("{0}")]
    Table(String),
    /// A camera's ffmpeg is a second of frames behind: this frame was not recorded (for
    /// any camera nor in the table); the episode goes on (count it as dropped).
    #[error("camera {camera}: ffmpeg is {frames} frames behind: the frame was not recorded")]
    EncoderBehind {
        /// The camera's feature.
        camera: String,
        /// Frames waiting for it.
        frames: usize,
    },
    /// A camera's video could not be encoded or placed (ffmpeg missing, stopped or
    /// failed): the finished episodes are intact; the episode in progress cannot be
    /// saved if its encoder stopped (discard it).
    #[error("camera {camera}: {reason}")]
    Video {
        /// The camera's feature, `observation.images.<name>`.
        camera: String,
        /// What happened (with ffmpeg's last messages).
        reason: String,
    },
}

/// Result of this crate.
pub type Result<T> = std::result::Result<T, Error>;

fn io(context: impl Into<String>) -> impl FnOnce(std::io::Error) -> Error {
    let context = context.into();
    move |source| Error::Io { context, source }
}

/// A camera: its frames are the feature `observation.images.<name>`, a video.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Camera {
    /// `<name>` of `observation.images.<name>` (no `/`).
    pub name: String,
    /// Pixels per row of every frame.
    pub width: u32,
    /// Rows of every frame.
    pub height: u32,
}

impl Camera {
    /// Its feature name, `observation.images.<name>`.
    pub fn feature(&self) -> String {
        format!("{IMAGE_FEATURE_PREFIX}{}", self.name)
    }
}

/// What the dataset holds besides lerobot's default features.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetSpec {
    /// Frames per second (the sampling grid).
    pub fps: u32,
    /// info.json's `robot_type` (`eezybot_mk2`).
    pub robot_type: String,
    /// `observation.state`'s names (the joint names).
    pub state_names: Vec<String>,
    /// `action`'s names.
    pub action_names: Vec<String>,
    /// Files per chunk folder (lerobot's default 1000).
    pub chunks_size: u64,
    /// Size at which data and episodes files roll (lerobot's default 100 MB).
    pub data_files_size_in_mb: u64,
    /// The cameras, in the order of [`Frame::images`] (none by default).
    pub cameras: Vec<Camera>,
    /// Size at which a camera's video file rolls (lerobot's default 200 MB).
    pub video_files_size_in_mb: u64,
    /// The ffmpeg program (default `ffmpeg` on the PATH; `ffprobe` is taken beside it),
    /// needed only with cameras.
    pub ffmpeg: PathBuf,
}

impl DatasetSpec {
    /// A spec with lerobot's default chunk and file sizes.
    pub fn new(fps: u32, robot_type: &str, state_names: &[&str], action_names: &[&str]) -> Self {
        DatasetSpec {
            fps,
            robot_type: robot_type.to_string(),
            state_names: state_names.iter().map(|s| s.to_string()).collect(),
            action_names: action_names.iter().map(|s| s.to_string()).collect(),
            chunks_size: DEFAULT_CHUNK_SIZE,
            data_files_size_in_mb: DEFAULT_DATA_FILE_SIZE_IN_MB,
            cameras: Vec::new(),
            video_files_size_in_mb: DEFAULT_VIDEO_FILE_SIZE_IN_MB,
            ffmpeg: PathBuf::from("ffmpeg"),
        }
    }

    /// Adds a camera `observation.images.<name>` of `width` × `height` pixels.
    pub fn with_camera(mut self, name: &str, width: u32, height: u32) -> Self {
        self.cameras.push(Camera {
            name: name.to_string(),
            width,
            height,
        });
        self
    }

    fn check(&self) -> Result<()> {
        if self.fps == 0 {
            return Err(Error::BadSpec("fps must be positive".into()));
        }
        if self.chunks_size == 0
            || self.data_files_size_in_mb == 0
            || self.video_files_size_in_mb == 0
        {
            return Err(Error::BadSpec(
                "chunk and file sizes must be positive".into(),
            ));
        }
        for (what, names) in [
            ("observation.state", &self.state_names),
            ("action", &self.action_names),
        ] {
            if names.is_empty() {
                return Err(Error::BadSpec(format!("{what} has no names")));
            }
            let mut sorted = names.clone();
            sorted.sort();
            sorted.dedup();
            if sorted.len() != names.len() {
                return Err(Error::BadSpec(format!("{what} names repeat: {names:?}")));
            }
        }
        for (i, c) in self.cameras.iter().enumerate() {
            let bad_char = |ch: char| !(ch.is_ascii_alphanumeric() || "_-.".contains(ch));
            if c.name.is_empty() || c.name.starts_with('.') || c.name.contains(bad_char) {
                return Err(Error::BadSpec(format!(
                    "camera name {:?}: use letters, digits, _, - and . (not first)",
                    c.name
                )));
            }
            if self.cameras[..i].iter().any(|o| o.name == c.name) {
                return Err(Error::BadSpec(format!("camera {} appears twice", c.name)));
            }
            // SVT-AV1 1.4 encodes frames from 64x64, yuv420p needs even sizes
            if c.width < 64 || c.height < 64 || c.width % 2 == 1 || c.height % 2 == 1 {
                return Err(Error::BadSpec(format!(
                    "camera {}: {}x{} (the encoder needs even sizes of at least 64x64)",
                    c.name, c.width, c.height
                )));
            }
        }
        Ok(())
    }

    /// The feature names in info.json's order: `observation.state`, `action`, the
    /// cameras', then lerobot's defaults.
    pub fn feature_names(&self) -> Vec<String> {
        let mut v = vec!["observation.state".to_string(), "action".to_string()];
        v.extend(self.cameras.iter().map(Camera::feature));
        v.extend(
            [
                "timestamp",
                "frame_index",
                "episode_index",
                "index",
                "task_index",
            ]
            .map(String::from),
        );
        v
    }

    /// info.json's `features`, as lerobot writes them (`{**features, **DEFAULT_FEATURES}`),
    /// a camera's `info` as at creation (`{"is_depth_map": false}`).
    pub fn features(&self) -> Ordered {
        let created = vec![video_info_created(); self.cameras.len()];
        self.features_with(&created)
    }

    /// [`DatasetSpec::features`] with each camera's `info` given.
    fn features_with(&self, camera_info: &[Ordered]) -> Ordered {
        let vector = |names: &[String]| {
            Ordered::obj([
                ("dtype", Ordered::val("float32")),
                ("shape", Ordered::val(vec![names.len()])),
                ("names", Ordered::val(names.to_vec())),
            ])
        };
        let scalar = |dtype: &str| {
            Ordered::obj([
                ("dtype", Ordered::val(dtype)),
                ("shape", Ordered::val(vec![1])),
                ("names", Ordered::Val(Value::Null)),
            ])
        };
        let mut f = vec![
            ("observation.state".to_string(), vector(&self.state_names)),
            ("action".to_string(), vector(&self.action_names)),
        ];
        for (c, info) in self.cameras.iter().zip(camera_info) {
            f.push((
                c.feature(),
                Ordered::obj([
                    ("dtype", Ordered::val("video")),
                    ("shape", Ordered::val(vec![c.height, c.width, 3])),
                    ("names", Ordered::val(vec!["height", "width", "channels"])),
                    ("info", info.clone()),
                ]),
            ));
        }
        for (name, dtype) in [
            ("timestamp", "float32"),
            ("frame_index", "int64"),
            ("episode_index", "int64"),
            ("index", "int64"),
            ("task_index", "int64"),
        ] {
            f.push((name.to_string(), scalar(dtype)));
        }
        Ordered::Obj(f)
    }

    fn features_value(&self) -> Value {
        serde_json::from_slice(&self.features().to_pretty()).unwrap_or(Value::Null)
    }
}

/// One frame: the follower's joints, what was commanded, and each camera's image.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// `observation.state`, in the spec's order.
    pub state: &'a [f32],
    /// `action`, in the spec's order.
    pub action: &'a [f32],
    /// One image per camera, in the spec's camera order (`&[]` without cameras). A
    /// camera's first frame in an episode fixes how its frames reach ffmpeg (JPEG or raw):
    /// a frame of the other kind in the same episode is refused.
    pub images: &'a [Image<'a>],
}

/// An episode found interrupted (not saved) and discarded.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Interrupted {
    /// The index it would have had.
    pub episode_index: u64,
    /// Its task.
    pub task: String,
    /// The frames it had when interrupted (all lost).
    pub frames: usize,
}

/// What opening an existing dataset repaired.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recovery {
    /// A save interrupted after its journal, completed: the files renamed into place.
    pub rolled_forward: Vec<PathBuf>,
    /// Temporaries of a save interrupted before its journal, removed.
    pub removed_temporaries: Vec<PathBuf>,
    /// An episode in progress when the writer stopped, discarded.
    pub interrupted: Option<Interrupted>,
    /// The files of that episode's cameras (its videos being encoded, their pixel
    /// counts, ffmpeg's logs) under `.recording/`, removed.
    pub removed_episode_files: Vec<PathBuf>,
}

impl Recovery {
    /// Nothing was repaired.
    pub fn is_clean(&self) -> bool {
        *self == Recovery::default()
    }
}

/// A saved episode.
#[derive(Debug, Clone, PartialEq)]
pub struct SavedEpisode {
    /// Its index.
    pub episode_index: u64,
    /// Its frames.
    pub frames: usize,
    /// Its task's index.
    pub task_index: u64,
}

struct InProgress {
    task: String,
    state: Vec<f32>,
    action: Vec<f32>,
    frames: usize,
    log: BufWriter<File>,
    /// One per camera.
    encoders: Vec<Encoding>,
}

/// A camera's encoding in the episode in progress.
enum Encoding {
    /// No frame yet (ffmpeg starts at the first).
    NotStarted,
    Running(Encoder),
    /// ffmpeg finished the episode's file with these frames (a save that failed later
    /// can be retried).
    Finished(u64),
    /// ffmpeg stopped or failed: the episode cannot be saved.
    Failed(String),
}

/// Where a camera's next episode goes.
#[derive(Debug, Clone)]
struct CameraFiles {
    /// info.json's `info` of the feature.
    info: Ordered,
    /// The file that takes the next episode if it fits, and its duration so far; `None`
    /// after creation or resume (lerobot starts a new file).
    current: Option<((u64, u64), f64)>,
    /// The file a new file would be.
    next_new: (u64, u64),
}

/// Writes episodes into a LeRobot v3.0 dataset folder.
pub struct DatasetWriter {
    root: PathBuf,
    spec: DatasetSpec,
    total_episodes: u64,
    total_frames: u64,
    tasks: Vec<String>,
    stats: Option<Vec<(String, FeatureStats)>>,
    data_at: (u64, u64),
    data_rows: DataRows,
    episodes_at: (u64, u64),
    episode_rows: Vec<EpisodeRow>,
    cameras: Vec<CameraFiles>,
    current: Option<InProgress>,
}

fn chunk_file(pattern: &str, chunk: u64, file: u64) -> String {
    format!("{pattern}/chunk-{chunk:03}/file-{file:03}.parquet")
}

/// lerobot's `update_chunk_file_indices`.
fn next_file((chunk, file): (u64, u64), chunks_size: u64) -> (u64, u64) {
    if file == chunks_size - 1 {
        (chunk + 1, 0)
    } else {
        (chunk, file + 1)
    }
}

/// The largest `(chunk, file)` of `dir/chunk-CCC/file-FFF.<ext>`, if any.
fn last_file(dir: &Path, ext: &str) -> Result<Option<(u64, u64)>> {
    let mut best = None;
    let Ok(chunks) = fs::read_dir(dir) else {
        return Ok(None);
    };
    for c in chunks {
        let c = c.map_err(io(format!("listing {}", dir.display())))?;
        let name = c.file_name().to_string_lossy().to_string();
        let Some(ci) = name
            .strip_prefix("chunk-")
            .and_then(|s| s.parse::<u64>().ok())
        else {
            continue;
        };
        for f in fs::read_dir(c.path()).map_err(io(format!("listing {}", name)))? {
            let f = f.map_err(io(format!("listing {name}")))?;
            let fname = f.file_name().to_string_lossy().to_string();
            let Some(fi) = fname
                .strip_prefix("file-")
                .and_then(|s| s.strip_suffix(ext))
                .and_then(|s| s.strip_suffix('.'))
                .and_then(|s| s.parse::<u64>().ok())
            else {
                continue;
            };
            if best.is_none_or(|b| (ci, fi) > b) {
                best = Some((ci, fi));
            }
        }
    }
    Ok(best)
}

fn fsync_dir(dir: &Path) -> Result<()> {
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(io(format!("fsync {}", dir.display())))
}

fn write_synced(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(parent) = path.parent() {
        fs::create_dir_all(parent).map_err(io(format!("creating {}", parent.display())))?;
    }
    let mut f = File::create(path).map_err(io(format!("creating {}", path.display())))?;
    f.write_all(bytes)
        .and_then(|_| f.sync_all())
        .map_err(io(format!("writing {}", path.display())))
}

fn tmp_of(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(TMP_SUFFIX);
    PathBuf::from(s)
}

/// Writes `files` (paths relative to `root`) as one atomic change with the `staged`
/// ones, whose temporaries are already written and fsynced (the videos): temporaries,
/// journal, renames (see the crate docs). On an error before the journal, the
/// temporaries are removed and nothing changed.
fn commit(root: &Path, files: &[(String, Vec<u8>)], staged: &[String]) -> Result<()> {
    let mut written: Vec<PathBuf> = staged.iter().map(|rel| tmp_of(&root.join(rel))).collect();
    let result = (|| {
        for (rel, bytes) in files {
            let tmp = tmp_of(&root.join(rel));
            written.push(tmp.clone());
            write_synced(&tmp, bytes)?;
        }
        let rec = root.join(RECORDING_DIR);
        let journal: Vec<&str> = staged
            .iter()
            .map(String::as_str)
            .chain(files.iter().map(|(rel, _)| rel.as_str()))
            .collect();
        let body = serde_json::to_vec(&journal).unwrap_or_default();
        let jtmp = tmp_of(&rec.join(JOURNAL));
        written.push(jtmp.clone());
        write_synced(&jtmp, &body)?;
        fs::rename(&jtmp, rec.join(JOURNAL)).map_err(io("renaming the commit journal"))?;
        fsync_dir(&rec)
    })();
    if let Err(e) = result {
        for t in &written {
            let _ = fs::remove_file(t);
        }
        let _ = fs::remove_file(root.join(RECORDING_DIR).join(JOURNAL));
        return Err(e);
    }
    roll_forward(root).map(|_| ())
}

/// Completes a journalled save: renames each temporary still there, fsyncs, removes the
/// journal. Returns the files renamed.
fn roll_forward(root: &Path) -> Result<Vec<PathBuf>> {
    let jpath = root.join(RECORDING_DIR).join(JOURNAL);
    let body = match fs::read(&jpath) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io(format!("reading {}", jpath.display()))(e)),
    };
    let rels: Vec<String> = serde_json::from_slice(&body).map_err(|e| Error::NotADataset {
        path: root.to_path_buf(),
        reason: format!("{} unreadable: {e}", jpath.display()),
    })?;
    let mut renamed = Vec::new();
    let mut dirs = Vec::new();
    for rel in &rels {
        let target = root.join(rel);
        let tmp = tmp_of(&target);
        if tmp.exists() {
            fs::rename(&tmp, &target).map_err(io(format!("renaming {}", tmp.display())))?;
            renamed.push(PathBuf::from(rel));
        }
        if let Some(p) = target.parent() {
            if !dirs.contains(&p.to_path_buf()) {
                dirs.push(p.to_path_buf());
            }
        }
    }
    for d in &dirs {
        fsync_dir(d)?;
    }
    fs::remove_file(&jpath).map_err(io(format!("removing {}", jpath.display())))?;
    fsync_dir(&root.join(RECORDING_DIR))?;
    Ok(renamed)
}

/// Removes `*.tmp-commit` files under `dir` (left by a save interrupted before its
/// journal).
fn remove_temporaries(dir: &Path, root: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(());
    };
    for e in entries {
        let e = e.map_err(io(format!("listing {}", dir.display())))?;
        let p = e.path();
        if p.is_dir() {
            remove_temporaries(&p, root, out)?;
        } else if p.to_string_lossy().ends_with(TMP_SUFFIX) {
            fs::remove_file(&p).map_err(io(format!("removing {}", p.display())))?;
            out.push(p.strip_prefix(root).unwrap_or(&p).to_path_buf());
        }
    }
    Ok(())
}

/// The first line of the episode in progress's log.
#[derive(serde::Serialize, serde::Deserialize)]
struct LogHeader {
    episode_index: u64,
    task: String,
}

/// Each further line of that log: one frame.
#[derive(serde::Serialize, serde::Deserialize)]
struct LogFrame<S> {
    state: S,
    action: S,
}

fn read_interrupted(path: &Path) -> Option<Interrupted> {
    let f = File::open(path).ok()?;
    let mut lines = BufReader::new(f).lines();
    let header: LogHeader = serde_json::from_str(&lines.next()?.ok()?).ok()?;
    // only whole lines are frames (a kill may cut the last one)
    let frames = lines
        .map_while(|l| l.ok())
        .filter(|l| serde_json::from_str::<LogFrame<Vec<f32>>>(l).is_ok())
        .count();
    Some(Interrupted {
        episode_index: header.episode_index,
        task: header.task,
        frames,
    })
}

/// Repairs what a crash left in `root` (see the crate docs): completes a journalled
/// save, removes the temporaries of an unjournalled one, and discards an episode in
/// progress, saying which. Call it only on a folder [`DatasetWriter::open_resume`] would
/// accept; `open_resume` calls it itself.
pub fn recover(root: &Path) -> Result<Recovery> {
    let mut r = Recovery {
        rolled_forward: roll_forward(root)?,
        ..Default::default()
    };
    for sub in ["meta", "data", "videos", RECORDING_DIR] {
        remove_temporaries(&root.join(sub), root, &mut r.removed_temporaries)?;
    }
    // what an episode's cameras left (the journal and the episode's log aside)
    let rec = root.join(RECORDING_DIR);
    if let Ok(entries) = fs::read_dir(&rec) {
        for e in entries {
            let e = e.map_err(io(format!("listing {}", rec.display())))?;
            let name = e.file_name();
            if name == JOURNAL || name == IN_PROGRESS || !e.path().is_file() {
                continue;
            }
            fs::remove_file(e.path()).map_err(io(format!("removing {}", e.path().display())))?;
            r.removed_episode_files
                .push(Path::new(RECORDING_DIR).join(name));
        }
    }
    r.removed_episode_files.sort();
    let ip = root.join(RECORDING_DIR).join(IN_PROGRESS);
    if ip.exists() {
        r.interrupted = Some(read_interrupted(&ip).unwrap_or(Interrupted {
            episode_index: 0,
            task: String::new(),
            frames: 0,
        }));
        fs::remove_file(&ip).map_err(io(format!("removing {}", ip.display())))?;
    }
    Ok(r)
}

/// The keys of a video feature's `info` in lerobot's order (`{"is_depth_map": false}` at
/// creation, then `get_video_info`'s probed fields and the encoder's settings).
const VIDEO_INFO_ORDER: [&str; 14] = [
    "is_depth_map",
    "video.height",
    "video.width",
    "video.codec",
    "video.pix_fmt",
    "video.fps",
    "video.channels",
    "has_audio",
    "video.g",
    "video.crf",
    "video.preset",
    "video.fast_decode",
    "video.video_backend",
    "video.extra_options",
];

/// A video feature's `info` read back, in lerobot's key order (serde_json's map sorts
/// keys): the known keys first, any others after.
fn video_info_ordered(info: &Value) -> Ordered {
    let Some(map) = info.as_object() else {
        return Ordered::Val(info.clone());
    };
    let mut pairs: Vec<(String, Ordered)> = VIDEO_INFO_ORDER
        .iter()
        .filter_map(|k| {
            map.get(*k)
                .map(|v| (k.to_string(), Ordered::Val(v.clone())))
        })
        .collect();
    for (k, v) in map {
        if !VIDEO_INFO_ORDER.contains(&k.as_str()) {
            pairs.push((k.clone(), Ordered::Val(v.clone())));
        }
    }
    Ordered::Obj(pairs)
}

/// A video feature's `info` at creation, before any episode was probed.
fn video_info_created() -> Ordered {
    Ordered::obj([("is_depth_map", Ordered::val(false))])
}

/// What lerobot's `update_video_info` writes after the first episode: the probed
/// stream, then the encoder's settings ([`video`]'s constants).
fn video_info_probed(p: &video::Probe) -> Ordered {
    Ordered::obj([
        ("is_depth_map", Ordered::val(false)),
        ("video.height", Ordered::val(p.height)),
        ("video.width", Ordered::val(p.width)),
        ("video.codec", Ordered::val(p.codec.clone())),
        ("video.pix_fmt", Ordered::val(p.pix_fmt.clone())),
        ("video.fps", Ordered::val(p.fps)),
        // get_pix_fmt_channels: yuv420p has 3 components
        ("video.channels", Ordered::val(3)),
        ("has_audio", Ordered::val(false)),
        ("video.g", Ordered::val(video::GOP)),
        ("video.crf", Ordered::val(video::CRF)),
        ("video.preset", Ordered::val(video::PRESET)),
        ("video.fast_decode", Ordered::val(0)),
        ("video.video_backend", Ordered::val("pyav")),
        ("video.extra_options", Ordered::Obj(Vec::new())),
    ])
}

fn kind_name(k: InputKind) -> &'static str {
    match k {
        InputKind::Jpeg => "JPEG",
        InputKind::Rgb24 => "raw",
    }
}

fn check_ffmpeg(spec: &DatasetSpec) -> Result<()> {
    match spec.cameras.first() {
        None => Ok(()),
        Some(c) => video::check_ffmpeg(&spec.ffmpeg).map_err(|reason| Error::Video {
            camera: c.feature(),
            reason,
        }),
    }
}

fn load_json(path: &Path) -> std::result::Result<Value, String> {
    let body = fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    serde_json::from_slice(&body).map_err(|e| format!("{}: {e}", path.display()))
}

/// The differences between a dataset's info.json and `spec`, in words.
fn differences(info: &Value, spec: &DatasetSpec) -> Vec<String> {
    let mut d = Vec::new();
    let fps = info.get("fps").and_then(Value::as_u64);
    if fps != Some(u64::from(spec.fps)) {
        d.push(format!(
            "fps is {} in the dataset, {} here",
            fps.map_or("missing".to_string(), |f| f.to_string()),
            spec.fps
        ));
    }
    let want = spec.features_value();
    let empty = serde_json::Map::new();
    let have = info
        .get("features")
        .and_then(Value::as_object)
        .unwrap_or(&empty);
    let want = want.as_object().unwrap_or(&empty);
    for (k, w) in want {
        match have.get(k) {
            None => d.push(format!("feature {k} is missing from the dataset")),
            Some(h) => {
                for field in ["dtype", "shape", "names"] {
                    if h.get(field) != w.get(field) {
                        d.push(format!(
                            "feature {k}: {field} is {} in the dataset, {} here",
                            h.get(field).unwrap_or(&Value::Null),
                            w.get(field).unwrap_or(&Value::Null)
                        ));
                    }
                }
            }
        }
    }
    for k in have.keys() {
        if !want.contains_key(k) {
            d.push(format!("the dataset has feature {k}, not recorded here"));
        }
    }
    // a video file takes episodes of one codec only
    for c in &spec.cameras {
        let codec = have
            .get(&c.feature())
            .and_then(|f| f.get("info"))
            .and_then(|i| i.get("video.codec"))
            .and_then(Value::as_str);
        if let Some(codec) = codec.filter(|c| *c != "av1") {
            d.push(format!(
                "feature {}: its videos are {codec}, av1 here",
                c.feature()
            ));
        }
    }
    d
}

impl DatasetWriter {
    /// Creates a new dataset in `root` (absent or an empty folder): writes info.json.
    pub fn create(root: impl AsRef<Path>, spec: DatasetSpec) -> Result<Self> {
        spec.check()?;
        let root = root.as_ref().to_path_buf();
        if root.exists() {
            let mut entries =
                fs::read_dir(&root).map_err(io(format!("listing {}", root.display())))?;
            if entries.next().is_some() {
                return Err(Error::NotEmpty(root));
            }
        }
        check_ffmpeg(&spec)?;
        fs::create_dir_all(root.join(RECORDING_DIR))
            .map_err(io(format!("creating {}", root.display())))?;
        let cameras = spec
            .cameras
            .iter()
            .map(|_| CameraFiles {
                info: video_info_created(),
                current: None,
                next_new: (0, 0),
            })
            .collect();
        let w = DatasetWriter {
            root,
            spec,
            total_episodes: 0,
            total_frames: 0,
            tasks: Vec::new(),
            stats: None,
            data_at: (0, 0),
            data_rows: DataRows::default(),
            episodes_at: (0, 0),
            episode_rows: Vec::new(),
            cameras,
            current: None,
        };
        commit(
            &w.root,
            &[("meta/info.json".into(), w.info_json(0, 0, 0, &w.cameras))],
            &[],
        )?;
        Ok(w)
    }

    /// Opens an existing dataset to append episodes, after checking that it is a LeRobot
    /// v3.0 dataset with the spec's fps and features (refused with every difference
    /// named, nothing touched). Then repairs what a crash left ([`recover`]) and says so.
    /// New episodes go to new data and episodes files, as lerobot's resume does.
    pub fn open_resume(root: impl AsRef<Path>, spec: DatasetSpec) -> Result<(Self, Recovery)> {
        spec.check()?;
        let root = root.as_ref().to_path_buf();
        let not = |reason: String| Error::NotADataset {
            path: root.clone(),
            reason,
        };
        if !root.is_dir() {
            return Err(not("no such folder".into()));
        }
        check_ffmpeg(&spec)?;
        let info = load_json(&root.join("meta/info.json")).map_err(not)?;
        let version = info.get("codebase_version").and_then(Value::as_str);
        if version != Some(CODEBASE_VERSION) {
            return Err(not(format!(
                "codebase_version is {version:?}, not {CODEBASE_VERSION:?}"
            )));
        }
        let diff = differences(&info, &spec);
        if !diff.is_empty() {
            return Err(Error::Mismatch {
                path: root,
                differences: diff,
            });
        }
        // from here on the folder is ours to repair
        fs::create_dir_all(root.join(RECORDING_DIR))
            .map_err(io(format!("creating {}", root.display())))?;
        let mut recovery = recover(&root)?;
        let info = load_json(&root.join("meta/info.json")).map_err(not)?;
        let num = |k: &str| info.get(k).and_then(Value::as_u64);
        let total_episodes =
            num("total_episodes").ok_or_else(|| not("no total_episodes".into()))?;
        let total_frames = num("total_frames").ok_or_else(|| not("no total_frames".into()))?;
        // the log of an episode whose save committed just before the crash: it is saved
        if recovery
            .interrupted
            .as_ref()
            .is_some_and(|i| i.episode_index < total_episodes && !i.task.is_empty())
        {
            recovery.interrupted = None;
        }
        let mut spec = spec;
        spec.chunks_size = num("chunks_size").unwrap_or(DEFAULT_CHUNK_SIZE).max(1);
        spec.data_files_size_in_mb = num("data_files_size_in_mb")
            .unwrap_or(DEFAULT_DATA_FILE_SIZE_IN_MB)
            .max(1);
        spec.video_files_size_in_mb = num("video_files_size_in_mb")
            .unwrap_or(DEFAULT_VIDEO_FILE_SIZE_IN_MB)
            .max(1);
        let tasks_path = root.join("meta/tasks.parquet");
        let tasks = if tasks_path.exists() {
            tables::read_tasks(&tasks_path).map_err(Error::Table)?
        } else {
            Vec::new()
        };
        let stats = if total_episodes > 0 {
            let s = load_json(&root.join("meta/stats.json")).map_err(not)?;
            let mut v = Vec::new();
            for name in spec.feature_names() {
                let fs = s
                    .get(&name)
                    .and_then(FeatureStats::from_json)
                    .ok_or_else(|| not(format!("stats.json has no usable stats for {name}")))?;
                v.push((name, fs));
            }
            Some(v)
        } else {
            None
        };
        let cs = spec.chunks_size;
        let data_at =
            last_file(&root.join("data"), "parquet")?.map_or((0, 0), |l| next_file(l, cs));
        let episodes_at =
            last_file(&root.join("meta/episodes"), "parquet")?.map_or((0, 0), |l| next_file(l, cs));
        let mut cameras = Vec::new();
        for c in &spec.cameras {
            let key = c.feature();
            let info = info
                .get("features")
                .and_then(|f| f.get(&key))
                .and_then(|f| f.get("info"))
                .map_or_else(video_info_created, video_info_ordered);
            let next_new = last_file(&root.join("videos").join(&key), "mp4")?
                .map_or((0, 0), |l| next_file(l, cs));
            cameras.push(CameraFiles {
                info,
                current: None,
                next_new,
            });
        }
        Ok((
            DatasetWriter {
                root,
                spec,
                total_episodes,
                total_frames,
                tasks,
                stats,
                data_at,
                data_rows: DataRows::default(),
                episodes_at,
                episode_rows: Vec::new(),
                cameras,
                current: None,
            },
            recovery,
        ))
    }

    /// The dataset folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The spec (for a resumed dataset, with its chunk and file sizes).
    pub fn spec(&self) -> &DatasetSpec {
        &self.spec
    }

    /// Finished episodes.
    pub fn total_episodes(&self) -> u64 {
        self.total_episodes
    }

    /// Frames of the finished episodes.
    pub fn total_frames(&self) -> u64 {
        self.total_frames
    }

    /// The tasks, by task_index.
    pub fn tasks(&self) -> &[String] {
        &self.tasks
    }

    /// Frames of the episode in progress, if one is.
    pub fn episode_frames(&self) -> Option<usize> {
        self.current.as_ref().map(|c| c.frames)
    }

    fn info_json(
        &self,
        episodes: u64,
        frames: u64,
        tasks: usize,
        cameras: &[CameraFiles],
    ) -> Vec<u8> {
        let splits = if episodes > 0 {
            Ordered::obj([("train", Ordered::val(format!("0:{episodes}")))])
        } else {
            Ordered::Obj(Vec::new())
        };
        Ordered::obj([
            ("codebase_version", Ordered::val(CODEBASE_VERSION)),
            ("fps", Ordered::val(self.spec.fps)),
            (
                "features",
                self.spec
                    .features_with(&cameras.iter().map(|c| c.info.clone()).collect::<Vec<_>>()),
            ),
            ("total_episodes", Ordered::val(episodes)),
            ("total_frames", Ordered::val(frames)),
            ("total_tasks", Ordered::val(tasks)),
            ("chunks_size", Ordered::val(self.spec.chunks_size)),
            (
                "data_files_size_in_mb",
                Ordered::val(self.spec.data_files_size_in_mb),
            ),
            (
                "video_files_size_in_mb",
                Ordered::val(self.spec.video_files_size_in_mb),
            ),
            ("data_path", Ordered::val(DATA_PATH)),
            (
                "video_path",
                if self.spec.cameras.is_empty() {
                    Ordered::Val(Value::Null)
                } else {
                    Ordered::val(VIDEO_PATH)
                },
            ),
            ("robot_type", Ordered::val(self.spec.robot_type.clone())),
            ("splits", splits),
        ])
        .to_pretty()
    }

    /// Starts an episode of `task`.
    pub fn start_episode(&mut self, task: &str) -> Result<()> {
        if self.current.is_some() {
            return Err(Error::State(
                "an episode is already in progress: save or discard it first".into(),
            ));
        }
        if task.trim().is_empty() {
            return Err(Error::BadFrame("the task is empty".into()));
        }
        let path = self.root.join(RECORDING_DIR).join(IN_PROGRESS);
        let file = File::create(&path).map_err(io(format!("creating {}", path.display())))?;
        let mut log = BufWriter::new(file);
        let header = serde_json::to_string(&LogHeader {
            episode_index: self.total_episodes,
            task: task.to_string(),
        })
        .map_err(|e| Error::BadFrame(e.to_string()))?;
        writeln!(log, "{header}")
            .and_then(|_| log.flush())
            .map_err(io(format!("writing {}", path.display())))?;
        self.current = Some(InProgress {
            task: task.to_string(),
            state: Vec::new(),
            action: Vec::new(),
            frames: 0,
            log,
            encoders: self
                .spec
                .cameras
                .iter()
                .map(|_| Encoding::NotStarted)
                .collect(),
        });
        Ok(())
    }

    fn episode_files(&self, camera: usize) -> EpisodeFiles {
        EpisodeFiles::new(
            &self.root.join(RECORDING_DIR),
            &self.spec.cameras[camera].feature(),
        )
    }

    /// Checks a frame's images against the cameras and the episode's encoders; returns
    /// how each reaches ffmpeg.
    fn check_images(&self, cur: &InProgress, images: &[Image<'_>]) -> Result<Vec<InputKind>> {
        if images.len() != self.spec.cameras.len() {
            return Err(Error::BadFrame(format!(
                "{} images, expected one per camera ({})",
                images.len(),
                self.spec.cameras.len()
            )));
        }
        let mut kinds = Vec::new();
        for ((c, img), enc) in self.spec.cameras.iter().zip(images).zip(&cur.encoders) {
            let kind = img
                .check(c.width, c.height)
                .map_err(|e| Error::BadFrame(format!("camera {}: {e}", c.feature())))?;
            match enc {
                Encoding::Running(e) if e.kind() != kind => {
                    return Err(Error::BadFrame(format!(
                        "camera {}: a {} frame in an episode whose frames are {}",
                        c.feature(),
                        kind_name(kind),
                        kind_name(e.kind())
                    )))
                }
                Encoding::Failed(reason) => {
                    return Err(Error::Video {
                        camera: c.feature(),
                        reason: reason.clone(),
                    })
                }
                _ => {}
            }
            kinds.push(kind);
        }
        Ok(kinds)
    }

    /// Adds the next frame (on the fps grid: its timestamp is `frame_index / fps`).
    pub fn add_frame(&mut self, frame: Frame<'_>) -> Result<()> {
        let (ns, na) = (self.spec.state_names.len(), self.spec.action_names.len());
        let cur = self
            .current
            .as_ref()
            .ok_or_else(|| Error::State("no episode in progress".into()))?;
        if frame.state.len() != ns || frame.action.len() != na {
            return Err(Error::BadFrame(format!(
                "{} state and {} action values, expected {ns} and {na}",
                frame.state.len(),
                frame.action.len()
            )));
        }
        if let Some(v) = frame
            .state
            .iter()
            .chain(frame.action)
            .find(|v| !v.is_finite())
        {
            return Err(Error::BadFrame(format!("a value is not finite: {v}")));
        }
        let kinds = self.check_images(cur, frame.images)?;
        // never wait for ffmpeg: a frame no camera can take now is refused whole
        for (enc, cam) in cur.encoders.iter().zip(&self.spec.cameras) {
            if let Encoding::Running(e) = enc {
                if !e.has_room() {
                    return Err(Error::EncoderBehind {
                        camera: cam.feature(),
                        frames: e.behind(),
                    });
                }
            }
        }
        if cur
            .encoders
            .iter()
            .any(|e| matches!(e, Encoding::Finished(_)))
        {
            return Err(Error::State(
                "the episode is being saved: save or discard it first".into(),
            ));
        }
        // the log first: a write error (a full disk) leaves nothing of the frame anywhere
        let line = serde_json::to_string(&LogFrame {
            state: frame.state,
            action: frame.action,
        })
        .map_err(|e| Error::BadFrame(e.to_string()))?;
        let cur = self
            .current
            .as_mut()
            .ok_or_else(|| Error::State("no episode in progress".into()))?;
        writeln!(cur.log, "{line}")
            .and_then(|_| cur.log.flush())
            .map_err(io("writing the episode in progress"))?;
        // each camera's image to its ffmpeg (started at the episode's first frame); a
        // failure here makes the episode unsaveable (Encoding::Failed)
        for (i, (img, kind)) in frame.images.iter().zip(kinds).enumerate() {
            let cam = &self.spec.cameras[i];
            let files = EpisodeFiles::new(&self.root.join(RECORDING_DIR), &cam.feature());
            let cur = self
                .current
                .as_mut()
                .ok_or_else(|| Error::State("no episode in progress".into()))?;
            let slot = &mut cur.encoders[i];
            if matches!(slot, Encoding::NotStarted) {
                match Encoder::start(
                    &self.spec.ffmpeg,
                    &files,
                    kind,
                    cam.width,
                    cam.height,
                    self.spec.fps,
                ) {
                    Ok(e) => *slot = Encoding::Running(e),
                    Err(reason) => {
                        *slot = Encoding::Failed(reason.clone());
                        return Err(Error::Video {
                            camera: cam.feature(),
                            reason,
                        });
                    }
                }
            }
            if let Encoding::Running(e) = slot {
                if let Err(reason) = e.push(*img) {
                    *slot = Encoding::Failed(reason.clone());
                    return Err(Error::Video {
                        camera: cam.feature(),
                        reason,
                    });
                }
            }
        }
        let cur = self
            .current
            .as_mut()
            .ok_or_else(|| Error::State("no episode in progress".into()))?;
        cur.state.extend_from_slice(frame.state);
        cur.action.extend_from_slice(frame.action);
        cur.frames += 1;
        Ok(())
    }

    /// Discards the episode in progress; returns its frames.
    pub fn discard_episode(&mut self) -> Result<usize> {
        let cur = self
            .current
            .take()
            .ok_or_else(|| Error::State("no episode in progress".into()))?;
        let frames = cur.frames;
        // kills the cameras' ffmpeg, then their files go
        drop(cur);
        for i in 0..self.spec.cameras.len() {
            self.episode_files(i).remove();
        }
        let path = self.root.join(RECORDING_DIR).join(IN_PROGRESS);
        fs::remove_file(&path).map_err(io(format!("removing {}", path.display())))?;
        Ok(frames)
    }

    /// Ends each camera's encoding of the episode in progress (once: a save that fails
    /// later keeps the finished files) and checks that ffmpeg took every frame.
    fn finish_encoders(&mut self, frames: usize) -> Result<()> {
        let Some(cur) = self.current.as_mut() else {
            return Err(Error::State("no episode in progress".into()));
        };
        for (slot, cam) in cur.encoders.iter_mut().zip(&self.spec.cameras) {
            let taken = std::mem::replace(slot, Encoding::NotStarted);
            *slot = match taken {
                Encoding::Running(e) => match e.finish() {
                    Ok(n) => Encoding::Finished(n),
                    Err(reason) => Encoding::Failed(reason),
                },
                other => other,
            };
            let fail = |reason: String| Error::Video {
                camera: cam.feature(),
                reason,
            };
            match slot {
                Encoding::Finished(n) if *n == frames as u64 => {}
                Encoding::Finished(n) => {
                    return Err(fail(format!(
                        "ffmpeg decoded {n} frames of the episode's {frames}: discard it"
                    )))
                }
                Encoding::Failed(reason) => {
                    return Err(fail(format!("{reason}: discard the episode")))
                }
                _ => return Err(fail("no frame reached ffmpeg".into())),
            }
        }
        Ok(())
    }

    /// The image statistics of camera `i`'s episode of `frames` frames: the sampled
    /// frames' pixel counts, kept by its encoder.
    fn camera_stats(&self, i: usize, frames: usize) -> Result<FeatureStats> {
        let files = self.episode_files(i);
        let feature = self.spec.cameras[i].feature();
        let fail = |reason: String| Error::Video {
            camera: feature.clone(),
            reason,
        };
        let all = fs::read(&files.counts)
            .map_err(|e| fail(format!("{}: {e}", files.counts.display())))?;
        let idx = stats::sample_indices(frames);
        let mut sum = PixelCounts::default();
        for &f in &idx {
            let rec = all
                .get(f * PixelCounts::RECORD_BYTES..(f + 1) * PixelCounts::RECORD_BYTES)
                .and_then(PixelCounts::from_record)
                .ok_or_else(|| fail(format!("no pixel counts for frame {f}")))?;
            sum.add(&rec);
        }
        sum.stats(idx.len() as u64)
            .ok_or_else(|| fail("no pixels to count".into()))
    }

    /// Places camera `i`'s episode video as lerobot's `_save_episode_video` does: the
    /// camera's current file with the episode appended (a remux), or, when that would
    /// reach `video_files_size_in_mb` (or after creation or a resume), a new file. The
    /// result is written as the target's commit temporary; returns its path (relative to
    /// the root), where the episode is, and the camera's files afterwards.
    fn place_video(&self, i: usize, frames: usize) -> Result<(String, VideoLocation, CameraFiles)> {
        let cam = &self.spec.cameras[i];
        let key = cam.feature();
        let fail = |reason: String| Error::Video {
            camera: key.clone(),
            reason,
        };
        let files = self.episode_files(i);
        let probe = video::probe(&self.spec.ffmpeg, &files.video).map_err(&fail)?;
        if probe.frames != frames as u64 {
            return Err(fail(format!(
                "the episode's video has {} frames, {frames} expected",
                probe.frames
            )));
        }
        let mb = |p: &Path| fs::metadata(p).map(|m| m.len() as f64 / (1024.0 * 1024.0));
        let ep_mb = mb(&files.video).map_err(io(format!("size of {}", files.video.display())))?;
        let state = &self.cameras[i];
        let rel_of = |(c, f): (u64, u64)| format!("videos/{key}/chunk-{c:03}/file-{f:03}.mp4");
        let (target, from, append_to) = match state.current {
            None => (state.next_new, 0.0, None),
            Some((at, to)) => {
                let path = self.root.join(rel_of(at));
                let size = mb(&path).map_err(io(format!("size of {}", path.display())))?;
                if size + ep_mb >= self.spec.video_files_size_in_mb as f64 {
                    (next_file(at, self.spec.chunks_size), 0.0, None)
                } else {
                    (at, to, Some(path))
                }
            }
        };
        let rel = rel_of(target);
        let tmp = tmp_of(&self.root.join(&rel));
        if let Some(parent) = tmp.parent() {
            fs::create_dir_all(parent).map_err(io(format!("creating {}", parent.display())))?;
        }
        let _ = fs::remove_file(&tmp);
        match append_to {
            // a second name for the episode's file: a failed save keeps the original
            None => fs::hard_link(&files.video, &tmp)
                .or_else(|_| fs::copy(&files.video, &tmp).map(|_| ()))
                .map_err(io(format!("placing {}", tmp.display())))?,
            Some(current) => {
                let list = self
                    .root
                    .join(RECORDING_DIR)
                    .join(format!("{key}.ffconcat"));
                video::concatenate(&self.spec.ffmpeg, &current, from, &files.video, &tmp, &list)
                    .map_err(&fail)?
            }
        }
        File::open(&tmp)
            .and_then(|f| f.sync_all())
            .map_err(io(format!("fsync {}", tmp.display())))?;
        let to = from + probe.duration_s;
        let location = VideoLocation {
            key: key.clone(),
            chunk_index: target.0 as i64,
            file_index: target.1 as i64,
            from_timestamp: from,
            to_timestamp: to,
        };
        let after = CameraFiles {
            // lerobot probes the first episode's video for info.json
            info: if self.total_episodes == 0 {
                video_info_probed(&probe)
            } else {
                state.info.clone()
            },
            current: Some((target, to)),
            next_new: next_file(target, self.spec.chunks_size),
        };
        Ok((rel, location, after))
    }

    /// Saves the episode in progress atomically (see the crate docs). On an error,
    /// nothing changed and the episode is still in progress.
    pub fn save_episode(&mut self) -> Result<SavedEpisode> {
        let n = self
            .current
            .as_ref()
            .ok_or_else(|| Error::State("no episode in progress".into()))?
            .frames;
        if n == 0 {
            return Err(Error::State(
                "the episode has no frames: add frames or discard it".into(),
            ));
        }
        self.finish_encoders(n)?;
        let cur = self
            .current
            .as_ref()
            .ok_or_else(|| Error::State("no episode in progress".into()))?;
        let (ns, na) = (self.spec.state_names.len(), self.spec.action_names.len());
        let ep = self.total_episodes as i64;
        let mut tasks = self.tasks.clone();
        let task_index = match tasks.iter().position(|t| *t == cur.task) {
            Some(i) => i,
            None => {
                tasks.push(cur.task.clone());
                tasks.len() - 1
            }
        } as i64;
        let new_task = tasks.len() != self.tasks.len();
        let first_index = self.total_frames as i64;
        let fps = f64::from(self.spec.fps);
        let rows = DataRows {
            state: cur.state.clone(),
            action: cur.action.clone(),
            timestamp: (0..n).map(|i| (i as f64 / fps) as f32).collect(),
            frame_index: (0..n as i64).collect(),
            episode_index: vec![ep; n],
            index: (first_index..first_index + n as i64).collect(),
            task_index: vec![task_index; n],
        };

        // per-episode stats, in feature order
        let vec_rows = |flat: &[f32], dim: usize| -> Vec<Vec<f64>> {
            flat.chunks(dim)
                .map(|c| c.iter().map(|&v| f64::from(v)).collect())
                .collect()
        };
        let scalar = |v: Vec<f64>| -> Vec<Vec<f64>> { v.into_iter().map(|x| vec![x]).collect() };
        let i64s = |v: &[i64]| scalar(v.iter().map(|&x| x as f64).collect());
        // observation.state, action and timestamp are float32
        let f32s = Precision::F32;
        let columns = [
            ("observation.state", vec_rows(&rows.state, ns), f32s),
            ("action", vec_rows(&rows.action, na), f32s),
            (
                "timestamp",
                scalar(rows.timestamp.iter().map(|&t| f64::from(t)).collect()),
                f32s,
            ),
            ("frame_index", i64s(&rows.frame_index), Precision::F64),
            ("episode_index", i64s(&rows.episode_index), Precision::F64),
            ("index", i64s(&rows.index), Precision::F64),
            ("task_index", i64s(&rows.task_index), Precision::F64),
        ];
        let mut ep_stats = Vec::new();
        for name in self.spec.feature_names() {
            let s = match columns.iter().find(|c| c.0 == name) {
                Some((_, col, p)) => FeatureStats::compute(col, *p)
                    .ok_or_else(|| Error::Table(format!("stats of {name}")))?,
                None => {
                    let i = self
                        .spec
                        .cameras
                        .iter()
                        .position(|c| c.feature() == name)
                        .ok_or_else(|| Error::Table(format!("no feature {name}")))?;
                    self.camera_stats(i, n)?
                }
            };
            ep_stats.push((name, s));
        }
        let stats: Vec<(String, FeatureStats)> = match &self.stats {
            None => ep_stats.clone(),
            Some(old) => old
                .iter()
                .zip(&ep_stats)
                .map(|((name, a), (_, b))| {
                    FeatureStats::aggregate(&[a, b])
                        .map(|s| (name.clone(), s))
                        .ok_or_else(|| Error::Table(format!("aggregating the stats of {name}")))
                })
                .collect::<Result<_>>()?,
        };

        // the data file: this episode joins the current file unless it would pass the
        // size limit (lerobot's estimate), then it starts the next file
        let mb = |p: &Path| fs::metadata(p).map(|m| m.len() as f64 / (1024.0 * 1024.0));
        let limit = self.spec.data_files_size_in_mb as f64;
        let mut data_at = self.data_at;
        let mut data_rows = self.data_rows.clone();
        if !data_rows.is_empty() {
            let path = self.root.join(chunk_file("data", data_at.0, data_at.1));
            let size = mb(&path).map_err(io(format!("size of {}", path.display())))?;
            let per_frame = size / data_rows.len() as f64;
            if size + per_frame * n as f64 >= limit {
                data_at = next_file(data_at, self.spec.chunks_size);
                data_rows = DataRows::default();
            }
        }
        data_rows.extend(&rows);

        // each camera's video: its commit temporary made now (removed on any error)
        let mut staged: Vec<String> = Vec::new();
        let mut videos = Vec::new();
        let mut cameras_after = Vec::new();
        for i in 0..self.spec.cameras.len() {
            match self.place_video(i, n) {
                Ok((rel, location, after)) => {
                    staged.push(rel);
                    videos.push(location);
                    cameras_after.push(after);
                }
                Err(e) => {
                    for rel in &staged {
                        let _ = fs::remove_file(tmp_of(&self.root.join(rel)));
                    }
                    return Err(e);
                }
            }
        }

        // the episodes table, rolled by lerobot's own estimate (bytes per episode_index)
        let mut episodes_at = self.episodes_at;
        let mut episode_rows = self.episode_rows.clone();
        if let Some(last) = episode_rows.last() {
            let path = self
                .root
                .join(chunk_file("meta/episodes", episodes_at.0, episodes_at.1));
            let size = mb(&path).map_err(io(format!("size of {}", path.display())))?;
            let per = if last.episode_index > 0 {
                size / last.episode_index as f64
            } else {
                0.0
            };
            if size + per * n as f64 >= limit {
                episodes_at = next_file(episodes_at, self.spec.chunks_size);
                episode_rows.clear();
            }
        }
        episode_rows.push(EpisodeRow {
            episode_index: ep,
            tasks: vec![cur.task.clone()],
            length: n as i64,
            data_chunk_index: data_at.0 as i64,
            data_file_index: data_at.1 as i64,
            dataset_from_index: first_index,
            dataset_to_index: first_index + n as i64,
            videos,
            stats: ep_stats,
            meta_chunk_index: episodes_at.0 as i64,
            meta_file_index: episodes_at.1 as i64,
        });

        let total_episodes = self.total_episodes + 1;
        let total_frames = self.total_frames + n as u64;
        let files = (|| -> Result<Vec<(String, Vec<u8>)>> {
            let mut files = Vec::new();
            if new_task {
                files.push((
                    "meta/tasks.parquet".to_string(),
                    tables::tasks_parquet(&tasks).map_err(Error::Table)?,
                ));
            }
            files.push((
                chunk_file("data", data_at.0, data_at.1),
                tables::data_parquet(&data_rows, ns, na).map_err(Error::Table)?,
            ));
            files.push((
                chunk_file("meta/episodes", episodes_at.0, episodes_at.1),
                tables::episodes_parquet(&episode_rows).map_err(Error::Table)?,
            ));
            let stats_json = Ordered::obj(stats.iter().map(|(name, s)| {
                let json = if name.starts_with(IMAGE_FEATURE_PREFIX) {
                    s.to_json_image()
                } else {
                    s.to_json()
                };
                (name.clone(), json)
            }));
            files.push(("meta/stats.json".to_string(), stats_json.to_pretty()));
            files.push((
                "meta/info.json".to_string(),
                self.info_json(total_episodes, total_frames, tasks.len(), &cameras_after),
            ));
            Ok(files)
        })();
        let files = match files {
            Ok(f) => f,
            Err(e) => {
                for rel in &staged {
                    let _ = fs::remove_file(tmp_of(&self.root.join(rel)));
                }
                return Err(e);
            }
        };
        commit(&self.root, &files, &staged)?;

        // committed: the episode is part of the dataset
        self.total_episodes = total_episodes;
        self.total_frames = total_frames;
        self.tasks = tasks;
        self.stats = Some(stats);
        self.data_at = data_at;
        self.data_rows = data_rows;
        self.episodes_at = episodes_at;
        self.episode_rows = episode_rows;
        self.cameras = cameras_after;
        if let Some(cur) = self.current.take() {
            drop(cur.log);
        }
        let ip = self.root.join(RECORDING_DIR).join(IN_PROGRESS);
        fs::remove_file(&ip).map_err(io(format!("removing {}", ip.display())))?;
        for i in 0..self.spec.cameras.len() {
            self.episode_files(i).remove();
        }
        Ok(SavedEpisode {
            episode_index: ep as u64,
            frames: n,
            task_index: task_index as u64,
        })
    }
}
