//! The writer against the files it leaves: episodes saved and discarded, a crash
//! mid-episode, resume refusals, file rolling, a write error, a journalled save.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::collections::BTreeMap;
use std::fs::{self, File};
use std::path::{Path, PathBuf};

use arrow_array::{Array, FixedSizeListArray, Float32Array, Int64Array, RecordBatch};
use lerobot_dataset::{DatasetSpec, DatasetWriter, Error, Frame};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use serde_json::Value;

const J: [&str; 4] = [
    "base_joint",
    "shoulder_joint",
    "elbow_joint",
    "gripper_joint",
];

fn spec() -> DatasetSpec {
    DatasetSpec::new(30, "eezybot_mk2", &J, &J)
}

/// A pseudo-random but reproducible value stream (a 64-bit LCG).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
}

fn add_frames(w: &mut DatasetWriter, n: usize, rng: &mut Lcg) -> Vec<[f32; 8]> {
    let mut out = Vec::new();
    for _ in 0..n {
        let v: [f32; 8] = std::array::from_fn(|_| rng.next());
        w.add_frame(Frame {
            state: &v[..4],
            action: &v[4..],
            images: &[],
        })
        .unwrap();
        out.push(v);
    }
    out
}

fn read(path: &Path) -> RecordBatch {
    let f = File::open(path).unwrap();
    let r = ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .with_batch_size(1 << 20)
        .build()
        .unwrap();
    let batches: Vec<RecordBatch> = r.map(|b| b.unwrap()).collect();
    arrow_select_concat(&batches)
}

fn arrow_select_concat(b: &[RecordBatch]) -> RecordBatch {
    assert_eq!(b.len(), 1, "one batch per small file");
    b[0].clone()
}

fn ints(b: &RecordBatch, col: &str) -> Vec<i64> {
    let a = b
        .column_by_name(col)
        .unwrap()
        .as_any()
        .downcast_ref::<Int64Array>()
        .unwrap();
    a.values().to_vec()
}

fn json(path: &Path) -> Value {
    serde_json::from_slice(&fs::read(path).unwrap()).unwrap()
}

fn files(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    fn walk(d: &Path, root: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, root, out);
            } else {
                out.insert(p.strip_prefix(root).unwrap().into(), fs::read(&p).unwrap());
            }
        }
    }
    walk(root, root, &mut out);
    out
}

#[test]
fn two_episodes_one_discarded() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut rng = Lcg(1);
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    w.start_episode("pick up the cube").unwrap();
    let ep0 = add_frames(&mut w, 50, &mut rng);
    assert_eq!(w.save_episode().unwrap().frames, 50);
    w.start_episode("a false start").unwrap();
    add_frames(&mut w, 7, &mut rng);
    assert_eq!(w.discard_episode().unwrap(), 7);
    w.start_episode("wave").unwrap();
    let ep1 = add_frames(&mut w, 31, &mut rng);
    let saved = w.save_episode().unwrap();
    assert_eq!((saved.episode_index, saved.task_index), (1, 1));
    drop(w);

    let info = json(&root.join("meta/info.json"));
    assert_eq!(info["total_episodes"], 2);
    assert_eq!(info["total_frames"], 81);
    assert_eq!(info["total_tasks"], 2);
    assert_eq!(info["splits"]["train"], "0:2");
    assert_eq!(info["features"]["action"]["names"][3], "gripper_joint");

    let d = read(&root.join("data/chunk-000/file-000.parquet"));
    assert_eq!(d.num_rows(), 81);
    assert_eq!(ints(&d, "index"), (0..81).collect::<Vec<_>>());
    let ep_idx = ints(&d, "episode_index");
    assert_eq!(ep_idx.iter().filter(|&&e| e == 0).count(), 50);
    assert_eq!(ep_idx.iter().filter(|&&e| e == 1).count(), 31);
    assert_eq!(ints(&d, "frame_index")[50], 0);
    assert_eq!(ints(&d, "task_index")[80], 1);
    let ts = d
        .column_by_name("timestamp")
        .unwrap()
        .as_any()
        .downcast_ref::<Float32Array>()
        .unwrap();
    assert_eq!(ts.value(49), (49.0f64 / 30.0) as f32);
    assert_eq!(ts.value(50), 0.0);
    let state = d
        .column_by_name("observation.state")
        .unwrap()
        .as_any()
        .downcast_ref::<FixedSizeListArray>()
        .unwrap();
    let s = state.value(60);
    let s = s.as_any().downcast_ref::<Float32Array>().unwrap();
    assert_eq!(s.values().to_vec(), ep1[10][..4].to_vec());

    let e = read(&root.join("meta/episodes/chunk-000/file-000.parquet"));
    assert_eq!(e.num_rows(), 2);
    assert_eq!(ints(&e, "length"), vec![50, 31]);
    assert_eq!(ints(&e, "dataset_from_index"), vec![0, 50]);
    assert_eq!(ints(&e, "dataset_to_index"), vec![50, 81]);
    assert!(e.column_by_name("stats/action/q99").is_some());
    assert!(e.column_by_name("stats/task_index/count").is_some());

    let tasks = lerobot_dataset::tables::read_tasks(&root.join("meta/tasks.parquet")).unwrap();
    assert_eq!(tasks, vec!["pick up the cube", "wave"]);

    // stats.json: min/max/mean over both episodes, counted in frames
    let st = json(&root.join("meta/stats.json"));
    let all: Vec<[f32; 8]> = ep0.iter().chain(&ep1).copied().collect();
    let col: Vec<f64> = all.iter().map(|v| f64::from(v[5])).collect();
    let mean = col.iter().sum::<f64>() / col.len() as f64;
    let min = col.iter().copied().fold(f64::INFINITY, f64::min);
    assert!((st["action"]["mean"][1].as_f64().unwrap() - mean).abs() < 1e-9);
    assert!((st["action"]["min"][1].as_f64().unwrap() - min).abs() < 1e-12);
    assert_eq!(st["action"]["count"], serde_json::json!([81]));
    assert_eq!(st["index"]["max"], serde_json::json!([80.0]));
    // nothing left of the episodes in progress
    assert!(!root.join(".recording/episode.jsonl").exists());
}

#[test]
fn crash_mid_episode_keeps_finished_episodes() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut rng = Lcg(2);
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    w.start_episode("pick up the cube").unwrap();
    add_frames(&mut w, 40, &mut rng);
    w.save_episode().unwrap();
    w.start_episode("stack").unwrap();
    add_frames(&mut w, 12, &mut rng);
    let before = files(&root);
    drop(w); // a crash: no save, no discard

    let (mut w, rec) = DatasetWriter::open_resume(&root, spec()).unwrap();
    let i = rec
        .interrupted
        .expect("the interrupted episode is reported");
    assert_eq!(
        (i.episode_index, i.task.as_str(), i.frames),
        (1, "stack", 12)
    );
    assert!(rec.rolled_forward.is_empty() && rec.removed_temporaries.is_empty());
    assert_eq!((w.total_episodes(), w.total_frames()), (1, 40));
    // the finished episode's files are as they were
    let after = files(&root);
    for (p, b) in &before {
        if !p.starts_with(".recording") {
            assert_eq!(after.get(p), Some(b), "{}", p.display());
        }
    }
    // resume appends, in new files as lerobot does
    w.start_episode("stack").unwrap();
    add_frames(&mut w, 9, &mut rng);
    let s = w.save_episode().unwrap();
    assert_eq!((s.episode_index, s.task_index), (1, 1));
    let d = read(&root.join("data/chunk-000/file-001.parquet"));
    assert_eq!(ints(&d, "index"), (40..49).collect::<Vec<_>>());
    let e = read(&root.join("meta/episodes/chunk-000/file-001.parquet"));
    assert_eq!(ints(&e, "data/file_index"), vec![1]);
    assert_eq!(ints(&e, "meta/episodes/file_index"), vec![1]);
    let info = json(&root.join("meta/info.json"));
    assert_eq!(info["total_frames"], 49);
    // a second open finds nothing to repair
    drop(w);
    let (_, rec) = DatasetWriter::open_resume(&root, spec()).unwrap();
    assert!(rec.is_clean(), "{rec:?}");
}

#[test]
fn resume_refuses_other_fps_or_features_touching_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    w.start_episode("wave").unwrap();
    add_frames(&mut w, 5, &mut Lcg(3));
    w.save_episode().unwrap();
    w.start_episode("left running").unwrap();
    add_frames(&mut w, 2, &mut Lcg(4));
    drop(w);
    let before = files(&root);

    let mut other = spec();
    other.fps = 15;
    other.action_names[0] = "yaw".into();
    match DatasetWriter::open_resume(&root, other) {
        Err(Error::Mismatch { differences, .. }) => {
            assert_eq!(differences.len(), 2, "{differences:?}");
            assert!(differences[0].contains("fps is 30 in the dataset, 15 here"));
            assert!(differences[1].contains("action: names"), "{differences:?}");
        }
        other => panic!("expected a mismatch, got {:?}", other.err()),
    }
    let five = DatasetSpec::new(30, "eezybot_mk2", &["a", "b", "c", "d", "e"], &J);
    let err = DatasetWriter::open_resume(&root, five).err().unwrap();
    assert!(
        err.to_string().contains("observation.state: shape"),
        "{err}"
    );
    // nothing touched, not even the interrupted episode
    assert_eq!(files(&root), before);
}

#[test]
fn refuses_what_is_not_a_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("photos");
    fs::create_dir_all(&plain).unwrap();
    fs::write(plain.join("cat.jpg"), b"not a dataset").unwrap();
    let err = DatasetWriter::open_resume(&plain, spec()).err().unwrap();
    assert!(matches!(err, Error::NotADataset { .. }), "{err}");
    let err = DatasetWriter::create(&plain, spec()).err().unwrap();
    assert!(matches!(err, Error::NotEmpty(_)), "{err}");
    // a v2.1 dataset
    fs::create_dir_all(plain.join("meta")).unwrap();
    fs::write(
        plain.join("meta/info.json"),
        br#"{"codebase_version": "v2.1", "fps": 30}"#,
    )
    .unwrap();
    let err = DatasetWriter::open_resume(&plain, spec()).err().unwrap();
    assert!(err.to_string().contains("v2.1"), "{err}");
    assert_eq!(fs::read_dir(&plain).unwrap().count(), 2);
}

#[test]
fn files_roll_at_the_size_and_chunks_at_chunks_size() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut s = spec();
    s.data_files_size_in_mb = 1;
    s.chunks_size = 2;
    let mut w = DatasetWriter::create(&root, s).unwrap();
    let mut rng = Lcg(5);
    // random values do not compress: ~60 bytes a frame, 10000 frames ≈ 0.6 MB
    for _ in 0..3 {
        w.start_episode("wave").unwrap();
        add_frames(&mut w, 10_000, &mut rng);
        w.save_episode().unwrap();
    }
    let p0 = root.join("data/chunk-000/file-000.parquet");
    let size = fs::metadata(&p0).unwrap().len();
    assert!(size > 512 * 1024 && size < 1024 * 1024, "{size}");
    assert_eq!(ints(&read(&p0), "episode_index")[0], 0);
    let p1 = root.join("data/chunk-000/file-001.parquet");
    assert_eq!(ints(&read(&p1), "index")[0], 10_000);
    let p2 = root.join("data/chunk-001/file-000.parquet");
    assert_eq!(ints(&read(&p2), "index")[0], 20_000);
    // the episodes table rolls by lerobot's own estimate, its file's bytes per
    // episode_index times the new episode's frames: not after episode 0 (index 0 gives
    // no estimate), after episode 1
    let e = read(&root.join("meta/episodes/chunk-000/file-000.parquet"));
    assert_eq!(ints(&e, "episode_index"), vec![0, 1]);
    assert_eq!(ints(&e, "data/chunk_index"), vec![0, 0]);
    assert_eq!(ints(&e, "data/file_index"), vec![0, 1]);
    assert_eq!(ints(&e, "meta/episodes/file_index"), vec![0, 0]);
    let e = read(&root.join("meta/episodes/chunk-000/file-001.parquet"));
    assert_eq!(ints(&e, "episode_index"), vec![2]);
    assert_eq!(ints(&e, "data/chunk_index"), vec![1]);
    assert_eq!(ints(&e, "data/file_index"), vec![0]);
    assert_eq!(ints(&e, "meta/episodes/file_index"), vec![1]);
}

#[test]
fn a_write_error_changes_nothing_and_keeps_the_episode() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    w.start_episode("wave").unwrap();
    add_frames(&mut w, 10, &mut Lcg(6));
    w.save_episode().unwrap();
    let before = files(&root);
    w.start_episode("wave").unwrap();
    add_frames(&mut w, 10, &mut Lcg(7));
    // the stats file's temporary cannot be created (a directory is in its place): the
    // save fails after the data and episodes temporaries were written
    let blocker = root.join("meta/stats.json.tmp-commit");
    fs::create_dir(&blocker).unwrap();
    let err = w.save_episode().err().unwrap();
    assert!(matches!(err, Error::Io { .. }), "{err}");
    fs::remove_dir(&blocker).unwrap();
    let mut now = files(&root);
    now.remove(Path::new(".recording/episode.jsonl"));
    let mut was = before.clone();
    was.remove(Path::new(".recording/episode.jsonl"));
    assert_eq!(
        now, was,
        "the temporaries are removed, nothing else changed"
    );
    assert_eq!(w.episode_frames(), Some(10));
    // room again: the same episode saves
    let s = w.save_episode().unwrap();
    assert_eq!((s.episode_index, s.frames), (1, 10));
    assert_eq!(json(&root.join("meta/info.json"))["total_frames"], 20);
}

#[test]
fn a_journalled_save_is_rolled_forward_and_stray_temporaries_removed() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    w.start_episode("wave").unwrap();
    add_frames(&mut w, 3, &mut Lcg(8));
    w.save_episode().unwrap();
    drop(w);
    // what a crash between the journal and the renames leaves: a temporary (here a
    // changed info.json) and the journal naming it; plus a temporary of a save that
    // never reached its journal
    let mut info = json(&root.join("meta/info.json"));
    info["robot_type"] = "journalled".into();
    fs::write(
        root.join("meta/info.json.tmp-commit"),
        serde_json::to_vec(&info).unwrap(),
    )
    .unwrap();
    fs::write(
        root.join(".recording/commit.json"),
        br#"["meta/info.json"]"#,
    )
    .unwrap();
    fs::write(
        root.join("data/chunk-000/file-001.parquet.tmp-commit"),
        b"half",
    )
    .unwrap();
    let rec = lerobot_dataset::recover(&root).unwrap();
    assert_eq!(rec.rolled_forward, vec![PathBuf::from("meta/info.json")]);
    assert_eq!(
        rec.removed_temporaries,
        vec![PathBuf::from("data/chunk-000/file-001.parquet.tmp-commit")]
    );
    assert_eq!(
        json(&root.join("meta/info.json"))["robot_type"],
        "journalled"
    );
    assert!(!root.join(".recording/commit.json").exists());
}

#[test]
fn bad_frames_and_order_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut w = DatasetWriter::create(dir.path().join("ds"), spec()).unwrap();
    let v = [0.0f32; 4];
    let err = w
        .add_frame(Frame {
            state: &v,
            action: &v,
            images: &[],
        })
        .err()
        .unwrap();
    assert!(matches!(err, Error::State(_)));
    w.start_episode("wave").unwrap();
    assert!(matches!(w.start_episode("x"), Err(Error::State(_))));
    assert!(matches!(w.save_episode(), Err(Error::State(_))));
    let short = [0.0f32; 3];
    assert!(matches!(
        w.add_frame(Frame {
            state: &short,
            action: &v,
            images: &[],
        }),
        Err(Error::BadFrame(_))
    ));
    let nan = [0.0, f32::NAN, 0.0, 0.0];
    assert!(matches!(
        w.add_frame(Frame {
            state: &v,
            action: &nan,
            images: &[],
        }),
        Err(Error::BadFrame(_))
    ));
    assert_eq!(w.episode_frames(), Some(0));
}

#[test]
fn the_log_of_an_episode_saved_just_before_a_crash_is_not_an_interruption() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut rng = Lcg(9);
    let mut w = DatasetWriter::create(&root, spec()).unwrap();
    w.start_episode("pick up the cube").unwrap();
    add_frames(&mut w, 5, &mut rng);
    w.save_episode().unwrap();
    drop(w);
    // the crash came between the save's commit and the removal of the episode's log
    fs::write(
        root.join(".recording/episode.jsonl"),
        "{\"episode_index\":0,\"task\":\"pick up the cube\"}\n",
    )
    .unwrap();
    let (w, rec) = DatasetWriter::open_resume(&root, spec()).unwrap();
    assert_eq!(rec.interrupted, None);
    assert!(!root.join(".recording/episode.jsonl").exists());
    assert_eq!(w.total_episodes(), 1);
}
