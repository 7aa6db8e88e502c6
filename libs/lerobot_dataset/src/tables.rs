//! The three parquet tables, with the Arrow schemas lerobot 0.6.1 writes:
//! - data (`_save_episode_data`: the HF `datasets` features of info.json): vectors as
//!   `fixed_size_list<item: float32>[n]`, `timestamp` float32, the indices int64;
//! - episodes (`_flush_metadata_buffer`: `pa.Table.from_pydict` of the episode dicts):
//!   int64 scalars, `tasks` as `list<item: string>`, each stat as `list<item: double>`
//!   (`count` as `list<item: int64>`), an image's as `list<list<list<double>>>` (its
//!   shape (3, 1, 1)); each camera's `videos/<key>/chunk_index`, `file_index` (int64),
//!   `from_timestamp`, `to_timestamp` (double);
//! - tasks (`DataFrame.to_parquet` of a frame indexed by the task string): `task_index`
//!   int64 then `task` string, with pandas' schema metadata naming `task` the index
//!   (without it pandas reads a RangeIndex and every task becomes 0).
//!
//! All snappy-compressed with dictionary encoding, as lerobot's `ParquetWriter`s.

use std::fs::File;
use std::path::Path;
use std::sync::Arc;

use arrow_array::builder::{Float64Builder, Int64Builder, ListBuilder, StringBuilder};
use arrow_array::{
    Array, ArrayRef, FixedSizeListArray, Float32Array, Float64Array, Int64Array, RecordBatch,
    StringArray,
};
use arrow_schema::{DataType, Field, Metadata, Schema};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::WriterProperties;

use crate::stats::{FeatureStats, StatValue};

/// Why a table could not be built, written or read.
pub type TableError = String;

fn props() -> WriterProperties {
    WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .set_dictionary_enabled(true)
        .build()
}

fn to_parquet(batch: &RecordBatch) -> Result<Vec<u8>, TableError> {
    let mut out = Vec::new();
    let mut w = ArrowWriter::try_new(&mut out, batch.schema(), Some(props()))
        .map_err(|e| format!("parquet writer: {e}"))?;
    w.write(batch).map_err(|e| format!("parquet write: {e}"))?;
    w.close().map_err(|e| format!("parquet close: {e}"))?;
    Ok(out)
}

/// The frames of one data file, column by column.
#[derive(Debug, Clone, Default)]
pub struct DataRows {
    /// `observation.state`, row-major, `state_dim` per frame.
    pub state: Vec<f32>,
    /// `action`, row-major, `action_dim` per frame.
    pub action: Vec<f32>,
    /// Seconds from the episode's start: `frame_index / fps`.
    pub timestamp: Vec<f32>,
    /// Frame number within its episode.
    pub frame_index: Vec<i64>,
    /// The episode's number.
    pub episode_index: Vec<i64>,
    /// Frame number within the dataset.
    pub index: Vec<i64>,
    /// Row of tasks.parquet.
    pub task_index: Vec<i64>,
}

impl DataRows {
    /// Number of frames.
    pub fn len(&self) -> usize {
        self.timestamp.len()
    }

    /// No frames.
    pub fn is_empty(&self) -> bool {
        self.timestamp.is_empty()
    }

    /// Appends `other`'s frames.
    pub fn extend(&mut self, other: &DataRows) {
        self.state.extend_from_slice(&other.state);
        self.action.extend_from_slice(&other.action);
        self.timestamp.extend_from_slice(&other.timestamp);
        self.frame_index.extend_from_slice(&other.frame_index);
        self.episode_index.extend_from_slice(&other.episode_index);
        self.index.extend_from_slice(&other.index);
        self.task_index.extend_from_slice(&other.task_index);
    }
}

fn fixed_list(values: &[f32], dim: usize) -> Result<ArrayRef, TableError> {
    let item = Arc::new(Field::new("item", DataType::Float32, true));
    let arr = FixedSizeListArray::try_new(
        item,
        dim as i32,
        Arc::new(Float32Array::from(values.to_vec())),
        None,
    )
    .map_err(|e| format!("fixed_size_list: {e}"))?;
    Ok(Arc::new(arr))
}

fn fixed_list_type(dim: usize) -> DataType {
    DataType::FixedSizeList(
        Arc::new(Field::new("item", DataType::Float32, true)),
        dim as i32,
    )
}

/// The data file's bytes.
pub fn data_parquet(
    rows: &DataRows,
    state_dim: usize,
    action_dim: usize,
) -> Result<Vec<u8>, TableError> {
    let schema = Schema::new(vec![
        Field::new("observation.state", fixed_list_type(state_dim), true),
        Field::new("action", fixed_list_type(action_dim), true),
        Field::new("timestamp", DataType::Float32, true),
        Field::new("frame_index", DataType::Int64, true),
        Field::new("episode_index", DataType::Int64, true),
        Field::new("index", DataType::Int64, true),
        Field::new("task_index", DataType::Int64, true),
    ]);
    let cols: Vec<ArrayRef> = vec![
        fixed_list(&rows.state, state_dim)?,
        fixed_list(&rows.action, action_dim)?,
        Arc::new(Float32Array::from(rows.timestamp.clone())),
        Arc::new(Int64Array::from(rows.frame_index.clone())),
        Arc::new(Int64Array::from(rows.episode_index.clone())),
        Arc::new(Int64Array::from(rows.index.clone())),
        Arc::new(Int64Array::from(rows.task_index.clone())),
    ];
    let batch =
        RecordBatch::try_new(Arc::new(schema), cols).map_err(|e| format!("data batch: {e}"))?;
    to_parquet(&batch)
}

/// One row of the episodes table.
#[derive(Debug, Clone)]
pub struct EpisodeRow {
    /// The episode's number.
    pub episode_index: i64,
    /// Its tasks (lerobot: the distinct tasks of its frames).
    pub tasks: Vec<String>,
    /// Frames.
    pub length: i64,
    /// Where its frames are: `data/chunk-{chunk}/file-{file}.parquet`.
    pub data_chunk_index: i64,
    /// See `data_chunk_index`.
    pub data_file_index: i64,
    /// Its first frame's `index`.
    pub dataset_from_index: i64,
    /// One past its last frame's `index`.
    pub dataset_to_index: i64,
    /// Where each camera's frames are, in the spec's camera order.
    pub videos: Vec<VideoLocation>,
    /// Its statistics, feature by feature in the order of info.json's features (an
    /// image feature's, `observation.images.*`, nested as shape (3, 1, 1)).
    pub stats: Vec<(String, FeatureStats)>,
    /// Where this row is: `meta/episodes/chunk-{chunk}/file-{file}.parquet`.
    pub meta_chunk_index: i64,
    /// See `meta_chunk_index`.
    pub meta_file_index: i64,
}

/// Where one camera's frames of an episode are: `videos/<key>/chunk-{chunk}/file-{file}.mp4`
/// from `from_timestamp` to `to_timestamp` seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoLocation {
    /// The feature, `observation.images.<name>`.
    pub key: String,
    /// The chunk of its file.
    pub chunk_index: i64,
    /// Its file in the chunk.
    pub file_index: i64,
    /// The file's duration before this episode.
    pub from_timestamp: f64,
    /// `from_timestamp` plus the episode's duration.
    pub to_timestamp: f64,
}

/// The episodes file's bytes: columns in lerobot's order (episode_index, tasks, length,
/// data/…, dataset_from/to_index, `videos/<key>/…` per camera, `stats/<feature>/<stat>`…,
/// meta/episodes/…).
pub fn episodes_parquet(rows: &[EpisodeRow]) -> Result<Vec<u8>, TableError> {
    let first = rows.first().ok_or("no episode rows")?;
    let mut fields = Vec::new();
    let mut cols: Vec<ArrayRef> = Vec::new();
    let int_col = |name: &str, f: &dyn Fn(&EpisodeRow) -> i64| -> (Field, ArrayRef) {
        (
            Field::new(name, DataType::Int64, true),
            Arc::new(Int64Array::from(rows.iter().map(f).collect::<Vec<_>>())),
        )
    };
    let mut push = |(f, c): (Field, ArrayRef)| {
        fields.push(f);
        cols.push(c);
    };
    push(int_col("episode_index", &|r| r.episode_index));
    let mut tasks = ListBuilder::new(StringBuilder::new());
    for r in rows {
        for t in &r.tasks {
            tasks.values().append_value(t);
        }
        tasks.append(true);
    }
    let tasks = tasks.finish();
    push((
        Field::new("tasks", tasks.data_type().clone(), true),
        Arc::new(tasks),
    ));
    push(int_col("length", &|r| r.length));
    push(int_col("data/chunk_index", &|r| r.data_chunk_index));
    push(int_col("data/file_index", &|r| r.data_file_index));
    push(int_col("dataset_from_index", &|r| r.dataset_from_index));
    push(int_col("dataset_to_index", &|r| r.dataset_to_index));
    for (vi, v) in first.videos.iter().enumerate() {
        let key = &v.key;
        let at = |r: &EpisodeRow| r.videos.get(vi).cloned();
        push(int_col(&format!("videos/{key}/chunk_index"), &|r| {
            at(r).map_or(0, |v| v.chunk_index)
        }));
        push(int_col(&format!("videos/{key}/file_index"), &|r| {
            at(r).map_or(0, |v| v.file_index)
        }));
        for (name, f) in [
            (
                "from_timestamp",
                (|v: &VideoLocation| v.from_timestamp) as fn(&VideoLocation) -> f64,
            ),
            ("to_timestamp", |v: &VideoLocation| v.to_timestamp),
        ] {
            let col: Vec<f64> = rows.iter().map(|r| at(r).map_or(0.0, |v| f(&v))).collect();
            push((
                Field::new(format!("videos/{key}/{name}"), DataType::Float64, true),
                Arc::new(Float64Array::from(col)),
            ));
        }
    }
    for (fi, (feature, fstats)) in first.stats.iter().enumerate() {
        for (si, (stat, _)) in fstats.entries().iter().enumerate() {
            let name = format!("stats/{feature}/{stat}");
            let col: ArrayRef = if *stat == "count" {
                let mut b = ListBuilder::new(Int64Builder::new());
                for r in rows {
                    b.values().append_value(r.stats[fi].1.count as i64);
                    b.append(true);
                }
                Arc::new(b.finish())
            } else if feature.starts_with(crate::IMAGE_FEATURE_PREFIX) {
                // lerobot: the (3, 1, 1) array's tolist(): list<list<list<double>>>
                let mut b =
                    ListBuilder::new(ListBuilder::new(ListBuilder::new(Float64Builder::new())));
                for r in rows {
                    if let StatValue::Floats(v) = r.stats[fi].1.entries()[si].1 {
                        for &x in v {
                            b.values().values().values().append_value(x);
                            b.values().values().append(true);
                            b.values().append(true);
                        }
                    }
                    b.append(true);
                }
                Arc::new(b.finish())
            } else {
                let mut b = ListBuilder::new(Float64Builder::new());
                for r in rows {
                    if let StatValue::Floats(v) = r.stats[fi].1.entries()[si].1 {
                        b.values().append_slice(v);
                    }
                    b.append(true);
                }
                Arc::new(b.finish())
            };
            push((Field::new(name, col.data_type().clone(), true), col));
        }
    }
    push(int_col("meta/episodes/chunk_index", &|r| {
        r.meta_chunk_index
    }));
    push(int_col("meta/episodes/file_index", &|r| r.meta_file_index));
    let batch = RecordBatch::try_new(Arc::new(Schema::new(fields)), cols)
        .map_err(|e| format!("episodes batch: {e}"))?;
    to_parquet(&batch)
}

/// The pandas metadata `DataFrame.to_parquet` writes (pandas 2.x, which lerobot 0.6.1
/// pins) for a frame of one int64 column `task_index` indexed by the string `task`.
pub const TASKS_PANDAS_METADATA: &str = r#"{"index_columns": ["task"], "column_indexes": [{"name": null, "field_name": null, "pandas_type": "unicode", "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}], "columns": [{"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": null}, {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object", "metadata": null}], "creator": {"library": "pyarrow", "version": "21.0.0"}, "pandas_version": "2.3.3"}"#;

/// tasks.parquet's bytes: task `i` of `tasks` has task_index `i`.
pub fn tasks_parquet(tasks: &[String]) -> Result<Vec<u8>, TableError> {
    let schema = Schema::new(vec![
        Field::new("task_index", DataType::Int64, true),
        Field::new("task", DataType::Utf8, true),
    ])
    .with_metadata(Metadata::new().with("pandas", TASKS_PANDAS_METADATA));
    let batch = RecordBatch::try_new(
        Arc::new(schema),
        vec![
            Arc::new(Int64Array::from(
                (0..tasks.len() as i64).collect::<Vec<_>>(),
            )),
            Arc::new(StringArray::from(tasks.to_vec())),
        ],
    )
    .map_err(|e| format!("tasks batch: {e}"))?;
    to_parquet(&batch)
}

/// Reads tasks.parquet back: the tasks ordered by their task_index, which must be
/// 0..n without gaps.
pub fn read_tasks(path: &Path) -> Result<Vec<String>, TableError> {
    let file = File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .and_then(|b| b.build())
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let mut pairs: Vec<(i64, String)> = Vec::new();
    for batch in reader {
        let batch = batch.map_err(|e| format!("{}: {e}", path.display()))?;
        let idx = batch
            .column_by_name("task_index")
            .and_then(|c| c.as_any().downcast_ref::<Int64Array>())
            .ok_or_else(|| format!("{}: no int64 column task_index", path.display()))?;
        let task = batch
            .column_by_name("task")
            .ok_or_else(|| format!("{}: no column task", path.display()))?;
        let task = arrow_array::cast::AsArray::as_string_opt::<i32>(task.as_ref())
            .map(|a| {
                (0..a.len())
                    .map(|i| a.value(i).to_string())
                    .collect::<Vec<_>>()
            })
            .or_else(|| {
                arrow_array::cast::AsArray::as_string_opt::<i64>(task.as_ref())
                    .map(|a| (0..a.len()).map(|i| a.value(i).to_string()).collect())
            })
            .ok_or_else(|| format!("{}: column task is not a string", path.display()))?;
        for (i, t) in task.into_iter().enumerate() {
            pairs.push((idx.value(i), t));
        }
    }
    pairs.sort_by_key(|p| p.0);
    for (i, (ti, t)) in pairs.iter().enumerate() {
        if *ti != i as i64 {
            return Err(format!(
                "{}: task_index {ti} of {t:?} where {i} was expected",
                path.display()
            ));
        }
    }
    Ok(pairs.into_iter().map(|p| p.1).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tasks_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("tasks.parquet");
        let tasks = vec!["pick the cube".to_string(), "wave".to_string()];
        std::fs::write(&p, tasks_parquet(&tasks).unwrap()).unwrap();
        assert_eq!(read_tasks(&p).unwrap(), tasks);
        let f = File::open(&p).unwrap();
        let b = ParquetRecordBatchReaderBuilder::try_new(f).unwrap();
        let md = b.schema().metadata();
        assert_eq!(
            md.get("pandas").map(String::as_str),
            Some(TASKS_PANDAS_METADATA)
        );
    }
}
