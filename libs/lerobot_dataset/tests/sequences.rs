//! Any sequence of episodes saved, discarded and interrupted by a crash (the writer
//! dropped mid-episode, then `open_resume`) leaves a dataset whose files agree: info's
//! totals are the saved episodes', the frames' indices run 0..total without a gap in
//! episode order, each episode's row in the episodes table points at its frames, and
//! every interrupted episode is reported with its frames.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::fs::File;
use std::path::Path;

use arrow_array::{Array, Int64Array, RecordBatch};
use lerobot_dataset::{DatasetSpec, DatasetWriter, Frame};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use proptest::prelude::*;

#[derive(Debug, Clone)]
enum Op {
    Save { frames: usize, task: u8 },
    Discard { frames: usize },
    Crash { frames: usize },
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        3 => (1usize..40, 0u8..3).prop_map(|(frames, task)| Op::Save { frames, task }),
        1 => (0usize..10).prop_map(|frames| Op::Discard { frames }),
        1 => (0usize..10).prop_map(|frames| Op::Crash { frames }),
    ]
}

fn spec() -> DatasetSpec {
    DatasetSpec::new(30, "eezybot_mk2", &["a", "b"], &["a", "b"])
}

fn frames(w: &mut DatasetWriter, n: usize) {
    for i in 0..n {
        let v = [i as f32, -(i as f32)];
        w.add_frame(Frame {
            state: &v,
            action: &v,
            images: &[],
        })
        .unwrap();
    }
}

fn column(batches: &[RecordBatch], name: &str) -> Vec<i64> {
    batches
        .iter()
        .flat_map(|b| {
            let a = b.column_by_name(name).unwrap();
            a.as_any()
                .downcast_ref::<Int64Array>()
                .unwrap()
                .values()
                .to_vec()
        })
        .collect()
}

fn read_all(dir: &Path) -> Vec<RecordBatch> {
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .flat_map(|c| std::fs::read_dir(c.unwrap().path()).unwrap())
        .map(|f| f.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "parquet"))
        .collect();
    paths.sort();
    paths
        .iter()
        .flat_map(|p| {
            ParquetRecordBatchReaderBuilder::try_new(File::open(p).unwrap())
                .unwrap()
                .build()
                .unwrap()
                .map(|b| b.unwrap())
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn files_agree_after_any_sequence(ops in proptest::collection::vec(op(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("ds");
        let mut w = DatasetWriter::create(&root, spec()).unwrap();
        let mut saved: Vec<usize> = Vec::new();
        for op in &ops {
            match *op {
                Op::Save { frames: n, task } => {
                    w.start_episode(&format!("task {task}")).unwrap();
                    frames(&mut w, n);
                    let s = w.save_episode().unwrap();
                    prop_assert_eq!(s.episode_index as usize, saved.len());
                    saved.push(n);
                }
                Op::Discard { frames: n } => {
                    w.start_episode("discarded").unwrap();
                    frames(&mut w, n);
                    prop_assert_eq!(w.discard_episode().unwrap(), n);
                }
                Op::Crash { frames: n } => {
                    w.start_episode("crashed").unwrap();
                    frames(&mut w, n);
                    drop(w);
                    let (again, rec) = DatasetWriter::open_resume(&root, spec()).unwrap();
                    let i = rec.interrupted.unwrap();
                    prop_assert_eq!((i.episode_index as usize, i.frames), (saved.len(), n));
                    prop_assert!(rec.rolled_forward.is_empty());
                    w = again;
                }
            }
        }
        drop(w);
        let (_, rec) = DatasetWriter::open_resume(&root, spec()).unwrap();
        prop_assert!(rec.is_clean());
        let info: serde_json::Value =
            serde_json::from_slice(&std::fs::read(root.join("meta/info.json")).unwrap()).unwrap();
        let total: usize = saved.iter().sum();
        prop_assert_eq!(info["total_episodes"].as_u64(), Some(saved.len() as u64));
        prop_assert_eq!(info["total_frames"].as_u64(), Some(total as u64));
        if saved.is_empty() {
            prop_assert!(!root.join("data").exists());
            return Ok(());
        }
        let data = read_all(&root.join("data"));
        prop_assert_eq!(column(&data, "index"), (0..total as i64).collect::<Vec<_>>());
        let episodes = read_all(&root.join("meta/episodes"));
        prop_assert_eq!(column(&episodes, "episode_index"), (0..saved.len() as i64).collect::<Vec<_>>());
        prop_assert_eq!(column(&episodes, "length"), saved.iter().map(|&n| n as i64).collect::<Vec<_>>());
        let ep_of_frame = column(&data, "episode_index");
        let from = column(&episodes, "dataset_from_index");
        let to = column(&episodes, "dataset_to_index");
        for (e, (f, t)) in from.iter().zip(&to).enumerate() {
            prop_assert!(ep_of_frame[*f as usize..*t as usize].iter().all(|&x| x == e as i64));
        }
        let stats: serde_json::Value =
            serde_json::from_slice(&std::fs::read(root.join("meta/stats.json")).unwrap()).unwrap();
        prop_assert_eq!(stats["index"]["count"][0].as_u64(), Some(total as u64));
        prop_assert_eq!(stats["index"]["max"][0].as_f64(), Some((total - 1) as f64));
    }
}
