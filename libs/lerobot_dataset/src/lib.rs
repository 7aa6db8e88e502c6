//! Writes LeRobot v3.0 datasets as lerobot 0.6.1 writes them, from Rust and without ROS:
//! the `recorder` node drives a [`DatasetWriter`].
//!
//! # Layout (lerobot's `datasets/utils.py`, `dataset_metadata.py`, `dataset_writer.py`)
//! - `meta/info.json`: the `DatasetInfo` dataclass in field order (codebase_version
//!   `v3.0`, fps, features, totals, chunks_size 1000, data_files_size_in_mb 100,
//!   video_files_size_in_mb 200, data_path, video_path (null: no video features yet),
//!   robot_type, splits `{"train": "0:N"}`), indented by 4;
//! - `meta/stats.json`: per feature min, max, mean, std, count, q01 … q99
//!   ([`stats`]: lerobot's histogram quantiles and its aggregation across episodes);
//! - `meta/tasks.parquet`: `task_index` with the task as pandas index ([`tables`]);
//! - `meta/episodes/chunk-CCC/file-FFF.parquet`: one row per episode, its per-episode
//!   stats as `stats/<feature>/<stat>` columns;
//! - `data/chunk-CCC/file-FFF.parquet`: one row per frame.
//!
//! Features: `observation.state` and `action` (float32 vectors named by the joint
//! names), then lerobot's defaults `timestamp` (float32, `frame_index / fps`, as
//! lerobot's `add_frame` computes it: frames are on the fps grid by construction),
//! `frame_index`, `episode_index`, `index`, `task_index` (int64). Images are not handled
//! yet (video encoding is a later step).
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
//! - **Saving** changes five files (data, episodes, tasks, stats, info). Each is written
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
//! # Not yet: cameras (what lerobot 0.6.1 does, for the video step)
//! - The feature `observation.images.<name>`: dtype `video`, shape `[h, w, 3]`, names
//!   `["height", "width", "channels"]`, `info` `{"is_depth_map": false}` at creation,
//!   then after the first episode what `get_video_info` probes from the file
//!   (`video.height`, `video.width`, `video.codec` `av1`, `video.pix_fmt` `yuv420p`,
//!   `video.fps`, `video.channels` 3, `has_audio` false) plus the encoder's settings
//!   (`video.g` 2, `video.crf` 30, `video.preset` 12 for libsvtav1, `video.fast_decode`
//!   0, `video.extra_options` {}, `video.video_backend` `pyav`); info.json's `video_path`
//!   becomes `videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4`.
//! - Each episode is encoded to an mp4 of its own (libsvtav1, yuv420p, GOP 2, CRF 30),
//!   then appended to the camera's current file by a remux, or starts the next file when
//!   the current one's size plus the episode's reaches `video_files_size_in_mb` (200).
//!   The episodes table gets `videos/<key>/chunk_index`, `file_index`, `from_timestamp`
//!   (the file's duration before the episode) and `to_timestamp` after
//!   `dataset_to_index`; the per-episode stats come from [`stats::image_stats`] (shape
//!   (3, 1, 1): nested lists in the episodes table, [`stats::FeatureStats::to_json_image`]
//!   in stats.json). With this crate's commit, the remuxed file is one more temporary.
//! - Decoding on this machine: lerobot's default, torchcodec, does not load (it needs
//!   FFmpeg's shared libraries, `libavutil.so.56`–`59`, not installed); lerobot falls back
//!   to PyAV (15.1.0 in its wheel set), which has libdav1d. Debian's ffmpeg 5.1 is not
//!   installed yet; `libsvtav1enc1` 1.4.1 is.
//!
//! The data and episodes files are rewritten whole at each save (their finished rows are
//! kept in memory until the file rolls): a file of 100 MB is about 1.5 million frames
//! (14 hours at 30 fps), so a save writes at most that.

pub mod json;
pub mod stats;
pub mod tables;

use std::fs::{self, File};
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use serde_json::Value;

use json::Ordered;
use stats::{FeatureStats, Precision};
use tables::{DataRows, EpisodeRow};

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
}

/// Result of this crate.
pub type Result<T> = std::result::Result<T, Error>;

fn io(context: impl Into<String>) -> impl FnOnce(std::io::Error) -> Error {
    let context = context.into();
    move |source| Error::Io { context, source }
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
        }
    }

    fn check(&self) -> Result<()> {
        if self.fps == 0 {
            return Err(Error::BadSpec("fps must be positive".into()));
        }
        if self.chunks_size == 0 || self.data_files_size_in_mb == 0 {
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
        Ok(())
    }

    /// The feature names in info.json's order.
    pub fn feature_names(&self) -> [&'static str; 7] {
        [
            "observation.state",
            "action",
            "timestamp",
            "frame_index",
            "episode_index",
            "index",
            "task_index",
        ]
    }

    /// info.json's `features`, as lerobot writes them (`{**features, **DEFAULT_FEATURES}`).
    pub fn features(&self) -> Ordered {
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
        Ordered::obj([
            ("observation.state", vector(&self.state_names)),
            ("action", vector(&self.action_names)),
            ("timestamp", scalar("float32")),
            ("frame_index", scalar("int64")),
            ("episode_index", scalar("int64")),
            ("index", scalar("int64")),
            ("task_index", scalar("int64")),
        ])
    }

    fn features_value(&self) -> Value {
        serde_json::from_slice(&self.features().to_pretty()).unwrap_or(Value::Null)
    }
}

/// One frame: the follower's joints and what was commanded.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// `observation.state`, in the spec's order.
    pub state: &'a [f32],
    /// `action`, in the spec's order.
    pub action: &'a [f32],
}

/// An episode found interrupted (not saved) and discarded.
#[derive(Debug, Clone, PartialEq)]
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

/// The largest `(chunk, file)` of `dir/chunk-CCC/file-FFF.parquet`, if any.
fn last_file(dir: &Path) -> Result<Option<(u64, u64)>> {
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
                .and_then(|s| s.strip_suffix(".parquet"))
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

/// Writes `files` (paths relative to `root`) as one atomic change: temporaries,
/// journal, renames (see the crate docs). On an error before the journal, the
/// temporaries are removed and nothing changed.
fn commit(root: &Path, files: &[(String, Vec<u8>)]) -> Result<()> {
    let mut written = Vec::new();
    let staged = (|| {
        for (rel, bytes) in files {
            let tmp = tmp_of(&root.join(rel));
            written.push(tmp.clone());
            write_synced(&tmp, bytes)?;
        }
        let rec = root.join(RECORDING_DIR);
        let journal: Vec<&str> = files.iter().map(|(rel, _)| rel.as_str()).collect();
        let body = serde_json::to_vec(&journal).unwrap_or_default();
        let jtmp = tmp_of(&rec.join(JOURNAL));
        written.push(jtmp.clone());
        write_synced(&jtmp, &body)?;
        fs::rename(&jtmp, rec.join(JOURNAL)).map_err(io("renaming the commit journal"))?;
        fsync_dir(&rec)
    })();
    if let Err(e) = staged {
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
    for sub in ["meta", "data", RECORDING_DIR] {
        remove_temporaries(&root.join(sub), root, &mut r.removed_temporaries)?;
    }
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
        fs::create_dir_all(root.join(RECORDING_DIR))
            .map_err(io(format!("creating {}", root.display())))?;
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
            current: None,
        };
        commit(&w.root, &[("meta/info.json".into(), w.info_json(0, 0, 0))])?;
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
        let recovery = recover(&root)?;
        let info = load_json(&root.join("meta/info.json")).map_err(not)?;
        let num = |k: &str| info.get(k).and_then(Value::as_u64);
        let total_episodes =
            num("total_episodes").ok_or_else(|| not("no total_episodes".into()))?;
        let total_frames = num("total_frames").ok_or_else(|| not("no total_frames".into()))?;
        let mut spec = spec;
        spec.chunks_size = num("chunks_size").unwrap_or(DEFAULT_CHUNK_SIZE).max(1);
        spec.data_files_size_in_mb = num("data_files_size_in_mb")
            .unwrap_or(DEFAULT_DATA_FILE_SIZE_IN_MB)
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
                    .get(name)
                    .and_then(FeatureStats::from_json)
                    .ok_or_else(|| not(format!("stats.json has no usable stats for {name}")))?;
                v.push((name.to_string(), fs));
            }
            Some(v)
        } else {
            None
        };
        let cs = spec.chunks_size;
        let data_at = last_file(&root.join("data"))?.map_or((0, 0), |l| next_file(l, cs));
        let episodes_at =
            last_file(&root.join("meta/episodes"))?.map_or((0, 0), |l| next_file(l, cs));
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
                current: None,
            },
            recovery,
        ))
    }

    /// The dataset folder.
    pub fn root(&self) -> &Path {
        &self.root
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

    fn info_json(&self, episodes: u64, frames: u64, tasks: usize) -> Vec<u8> {
        let splits = if episodes > 0 {
            Ordered::obj([("train", Ordered::val(format!("0:{episodes}")))])
        } else {
            Ordered::Obj(Vec::new())
        };
        Ordered::obj([
            ("codebase_version", Ordered::val(CODEBASE_VERSION)),
            ("fps", Ordered::val(self.spec.fps)),
            ("features", self.spec.features()),
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
                Ordered::val(DEFAULT_VIDEO_FILE_SIZE_IN_MB),
            ),
            ("data_path", Ordered::val(DATA_PATH)),
            ("video_path", Ordered::Val(Value::Null)),
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
        });
        Ok(())
    }

    /// Adds the next frame (on the fps grid: its timestamp is `frame_index / fps`).
    pub fn add_frame(&mut self, frame: Frame<'_>) -> Result<()> {
        let (ns, na) = (self.spec.state_names.len(), self.spec.action_names.len());
        let cur = self
            .current
            .as_mut()
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
        let line = serde_json::to_string(&LogFrame {
            state: frame.state,
            action: frame.action,
        })
        .map_err(|e| Error::BadFrame(e.to_string()))?;
        writeln!(cur.log, "{line}")
            .and_then(|_| cur.log.flush())
            .map_err(io("writing the episode in progress"))?;
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
        drop(cur.log);
        let path = self.root.join(RECORDING_DIR).join(IN_PROGRESS);
        fs::remove_file(&path).map_err(io(format!("removing {}", path.display())))?;
        Ok(cur.frames)
    }

    /// Saves the episode in progress atomically (see the crate docs). On an error,
    /// nothing changed and the episode is still in progress.
    pub fn save_episode(&mut self) -> Result<SavedEpisode> {
        let cur = self
            .current
            .as_ref()
            .ok_or_else(|| Error::State("no episode in progress".into()))?;
        let n = cur.frames;
        if n == 0 {
            return Err(Error::State(
                "the episode has no frames: add frames or discard it".into(),
            ));
        }
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
        let columns = [
            vec_rows(&rows.state, ns),
            vec_rows(&rows.action, na),
            scalar(rows.timestamp.iter().map(|&t| f64::from(t)).collect()),
            i64s(&rows.frame_index),
            i64s(&rows.episode_index),
            i64s(&rows.index),
            i64s(&rows.task_index),
        ];
        let mut ep_stats = Vec::new();
        for (i, (name, col)) in self
            .spec
            .feature_names()
            .iter()
            .zip(columns.iter())
            .enumerate()
        {
            // observation.state, action and timestamp are float32
            let p = if i < 3 {
                Precision::F32
            } else {
                Precision::F64
            };
            let s = FeatureStats::compute(col, p)
                .ok_or_else(|| Error::Table(format!("stats of {name}")))?;
            ep_stats.push((name.to_string(), s));
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
            stats: ep_stats,
            meta_chunk_index: episodes_at.0 as i64,
            meta_file_index: episodes_at.1 as i64,
        });

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
        let stats_json = Ordered::obj(stats.iter().map(|(name, s)| (name.clone(), s.to_json())));
        files.push(("meta/stats.json".to_string(), stats_json.to_pretty()));
        let total_episodes = self.total_episodes + 1;
        let total_frames = self.total_frames + n as u64;
        files.push((
            "meta/info.json".to_string(),
            self.info_json(total_episodes, total_frames, tasks.len()),
        ));
        commit(&self.root, &files)?;

        // committed: the episode is part of the dataset
        self.total_episodes = total_episodes;
        self.total_frames = total_frames;
        self.tasks = tasks;
        self.stats = Some(stats);
        self.data_at = data_at;
        self.data_rows = data_rows;
        self.episodes_at = episodes_at;
        self.episode_rows = episode_rows;
        if let Some(cur) = self.current.take() {
            drop(cur.log);
        }
        let ip = self.root.join(RECORDING_DIR).join(IN_PROGRESS);
        fs::remove_file(&ip).map_err(io(format!("removing {}", ip.display())))?;
        Ok(SavedEpisode {
            episode_index: ep as u64,
            frames: n,
            task_index: task_index as u64,
        })
    }
}
