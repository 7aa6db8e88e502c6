//! The dataset writer on a thread of its own: saving an episode (parquet files, fsyncs,
//! the video remux) takes from milliseconds to a second, and the node's loop must go
//! on sampling its inputs and answering requests meanwhile.

use crate::compose::Row;
use crate::inputs::Picture;
use lerobot_dataset::{DatasetSpec, DatasetWriter, Error, Image, Recovery, SavedEpisode};
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Rows waiting for the writer; a row that finds the queue full is dropped and counted
/// (the writer fell 4 s behind at 30 fps: a disk that stalls).
pub const QUEUE: usize = 120;

/// What the writer is asked.
#[derive(Debug)]
pub enum Job {
    /// Open the dataset at `root` (create it if absent or empty; with `resume`, append
    /// to one that is there; without, refuse it).
    Open {
        /// The dataset folder.
        root: PathBuf,
        /// Its features and fps.
        spec: DatasetSpec,
        /// Append to an existing dataset.
        resume: bool,
    },
    /// Begin an episode of `task`.
    Begin(String),
    /// A row of the episode.
    Row(Box<Row>),
    /// Save the episode.
    Save,
    /// Throw the episode away.
    Discard,
}

/// The dataset as opened.
#[derive(Clone, Debug, PartialEq)]
pub struct Opened {
    /// Episodes it has.
    pub episodes: u64,
    /// Frames it has.
    pub frames: u64,
    /// Whether it was created now.
    pub created: bool,
    /// What was repaired after a crash, in words (`None`: nothing).
    pub recovered: Option<String>,
}

/// What the writer did.
#[derive(Debug)]
pub enum Done {
    /// The dataset opened, or why not.
    Opened(Result<Opened, String>),
    /// The episode began (its index), or why not.
    Began(Result<u64, String>),
    /// A row was not written (an image the encoder could not take now, or one that does
    /// not fit the camera): counted as dropped, the episode goes on.
    RowDropped(u64, String),
    /// A row could not be written (a full disk, the encoder gone): the episode cannot go on.
    RowFailed(String),
    /// The episode was saved (and how long it took), or why not.
    Saved(Result<(SavedEpisode, Duration), String>),
    /// The episode was thrown away (its frames), or why not.
    Discarded(Result<usize, String>),
}

/// What a recovery did, in words.
pub fn recovery_text(r: &Recovery) -> Option<String> {
    if r.is_clean() {
        return None;
    }
    let mut parts = vec![];
    if let Some(i) = &r.interrupted {
        parts.push(format!(
            "episode {} ({:?}, {} frames) was interrupted and is discarded",
            i.episode_index, i.task, i.frames
        ));
    }
    if !r.rolled_forward.is_empty() {
        parts.push(format!(
            "a save interrupted after its journal was completed ({} files)",
            r.rolled_forward.len()
        ));
    }
    if !r.removed_episode_files.is_empty() {
        parts.push(format!(
            "its video files were removed ({})",
            r.removed_episode_files.len()
        ));
    }
    if !r.removed_temporaries.is_empty() {
        parts.push(format!(
            "a save interrupted before its journal was undone ({} temporaries removed)",
            r.removed_temporaries.len()
        ));
    }
    Some(parts.join("; "))
}

fn open(root: PathBuf, spec: DatasetSpec, resume: bool) -> Result<(DatasetWriter, Opened), String> {
    let has_info = root.join("meta/info.json").exists();
    let empty = match std::fs::read_dir(&root) {
        Ok(mut d) => d.next().is_none(),
        Err(_) => !root.exists(),
    };
    if has_info || !empty {
        if !resume {
            return Err(format!(
                "{} is not empty and resume is false: give a new root, or resume:=true to append",
                root.display()
            ));
        }
        let (w, r) = DatasetWriter::open_resume(&root, spec).map_err(|e| e.to_string())?;
        let opened = Opened {
            episodes: w.total_episodes(),
            frames: w.total_frames(),
            created: false,
            recovered: recovery_text(&r),
        };
        Ok((w, opened))
    } else {
        let w = DatasetWriter::create(&root, spec).map_err(|e| e.to_string())?;
        Ok((
            w,
            Opened {
                episodes: 0,
                frames: 0,
                created: true,
                recovered: None,
            },
        ))
    }
}

/// A picture as the writer takes it (the encoding was checked when it came).
pub fn image(p: &Picture) -> Image<'_> {
    match p {
        Picture::Jpeg(data) => Image::Jpeg(data),
        Picture::Raw {
            width,
            height,
            encoding,
            step,
            data,
        } => Image::Raw {
            encoding: *encoding,
            width: *width,
            height: *height,
            step: *step,
            data,
        },
    }
}

/// The writer thread: takes jobs until the sender goes, answering through `done`. A
/// job needing the dataset before it opened is answered with why not.
pub fn run(jobs: mpsc::Receiver<Job>, done: impl Fn(Done)) {
    let mut writer: Option<DatasetWriter> = None;
    let mut row_failed = false;
    let not_open = || "the dataset is not open".to_string();
    while let Ok(job) = jobs.recv() {
        match job {
            Job::Open { root, spec, resume } => {
                let r = open(root, spec, resume).map(|(w, o)| {
                    writer = Some(w);
                    o
                });
                done(Done::Opened(r));
            }
            Job::Begin(task) => {
                row_failed = false;
                let r = match writer.as_mut() {
                    Some(w) => w
                        .start_episode(&task)
                        .map(|()| w.total_episodes())
                        .map_err(|e| e.to_string()),
                    None => Err(not_open()),
                };
                done(Done::Began(r));
            }
            Job::Row(row) => {
                // after a failed row the episode is over: the rest are not written
                if row_failed {
                    continue;
                }
                let Some(w) = writer.as_mut() else { continue };
                let images: Vec<Image<'_>> = row.images.iter().map(|p| image(p)).collect();
                let frame = lerobot_dataset::Frame {
                    state: &row.state,
                    action: &row.action,
                    images: &images,
                };
                match w.add_frame(frame) {
                    Ok(()) => {}
                    Err(e @ (Error::EncoderBehind { .. } | Error::BadFrame(_))) => {
                        done(Done::RowDropped(row.grid_index, e.to_string()))
                    }
                    Err(e) => {
                        row_failed = true;
                        done(Done::RowFailed(e.to_string()));
                    }
                }
            }
            Job::Save => {
                let t = Instant::now();
                let r = match writer.as_mut() {
                    Some(w) => w
                        .save_episode()
                        .map(|s| (s, t.elapsed()))
                        .map_err(|e| e.to_string()),
                    None => Err(not_open()),
                };
                done(Done::Saved(r));
            }
            Job::Discard => {
                let r = match writer.as_mut() {
                    Some(w) => w.discard_episode().map_err(|e| e.to_string()),
                    None => Err(not_open()),
                };
                done(Done::Discarded(r));
            }
        }
    }
}
