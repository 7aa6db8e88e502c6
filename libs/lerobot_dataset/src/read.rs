//! Reads one episode of a LeRobot v3.0 dataset back: a float vector feature's rows (the
//! `action` for a replay) and their `timestamp`s, found as lerobot's loader finds them:
//! `meta/info.json` (`codebase_version` v3.0, `fps`, `features`, `data_path`),
//! the episode's row in `meta/episodes/*/*.parquet` (`data/chunk_index`,
//! `data/file_index`, `length`), then its rows (`episode_index` = the episode, in
//! `frame_index` order) in that data file. Only the columns needed are decoded.
//!
//! Vectors are read as the writer writes them (`fixed_size_list<float32>`) and as
//! other writers may (`list`/`large_list` of float32 or float64).

use std::fs::{self, File};
use std::path::{Path, PathBuf};

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, Int64Type};
use arrow_array::{Array, ArrayRef, RecordBatch};
use arrow_schema::DataType;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ProjectionMask;
use serde_json::Value;

use crate::CODEBASE_VERSION;

/// Why an episode could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// The folder is not a LeRobot v3.0 dataset.
    #[error("{path} is not a LeRobot v3.0 dataset: {reason}")]
    NotADataset {
        /// The folder.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// No episode of that index.
    #[error("{path} has no episode {episode}: it has {total} (0 … {last})", last = match .total { 0 => "none".to_string(), n => (n - 1).to_string() })]
    NoSuchEpisode {
        /// The folder.
        path: PathBuf,
        /// The index asked for.
        episode: u64,
        /// The episodes it has (`total_episodes`).
        total: u64,
    },
    /// The dataset has no such feature, or it is not a float vector.
    #[error("{path}: {reason}")]
    Feature {
        /// The folder.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A file could not be read, or does not hold what info.json says.
    #[error("{path}: {reason}")]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// One feature of one episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeRows {
    /// The episode's index.
    pub episode_index: u64,
    /// The dataset's frames per second.
    pub fps: u32,
    /// The dataset's `total_episodes`.
    pub total_episodes: u64,
    /// The feature read.
    pub feature: String,
    /// Its `names`, one per value of a row.
    pub names: Vec<String>,
    /// Its rows, in `frame_index` order, each `names.len()` long.
    pub rows: Vec<Vec<f32>>,
    /// Each row's `timestamp` (s from the episode's start).
    pub timestamps: Vec<f32>,
}

impl EpisodeRows {
    /// The episode's duration (s): its last timestamp.
    pub fn duration_s(&self) -> f64 {
        self.timestamps.last().map_or(0.0, |&t| f64::from(t))
    }
}

/// The `action` rows of episode `episode` in the dataset at `root`.
pub fn read_actions(root: &Path, episode: u64) -> Result<EpisodeRows, ReadError> {
    read_episode(root, episode, "action")
}

/// The rows of float vector `feature` of episode `episode` in the dataset at `root`.
pub fn read_episode(root: &Path, episode: u64, feature: &str) -> Result<EpisodeRows, ReadError> {
    let not_a_dataset = |reason: String| ReadError::NotADataset {
        path: root.to_path_buf(),
        reason,
    };
    let info_path = root.join("meta/info.json");
    let body = fs::read(&info_path).map_err(|e| {
        not_a_dataset(if e.kind() == std::io::ErrorKind::NotFound {
            "it has no meta/info.json".to_string()
        } else {
            format!("meta/info.json: {e}")
        })
    })?;
    let info: Value = serde_json::from_slice(&body)
        .map_err(|e| not_a_dataset(format!("meta/info.json is not JSON: {e}")))?;
    let version = info.get("codebase_version").and_then(Value::as_str);
    if version != Some(CODEBASE_VERSION) {
        return Err(not_a_dataset(format!(
            "meta/info.json's codebase_version is {}, not {CODEBASE_VERSION}",
            version.map_or("missing".to_string(), |v| format!("{v:?}"))
        )));
    }
    let fps = info
        .get("fps")
        .and_then(Value::as_u64)
        .and_then(|f| u32::try_from(f).ok())
        .filter(|&f| f > 0)
        .ok_or_else(|| not_a_dataset("meta/info.json has no positive fps".into()))?;
    let total = info
        .get("total_episodes")
        .and_then(Value::as_u64)
        .ok_or_else(|| not_a_dataset("meta/info.json has no total_episodes".into()))?;
    let names = feature_names(&info, feature).map_err(|reason| ReadError::Feature {
        path: root.to_path_buf(),
        reason,
    })?;
    if episode >= total {
        return Err(ReadError::NoSuchEpisode {
            path: root.to_path_buf(),
            episode,
            total,
        });
    }
    let data_path = info
        .get("data_path")
        .and_then(Value::as_str)
        .unwrap_or(crate::DATA_PATH);

    let (chunk, file, length) = find_episode(root, episode)?;
    let rel = data_path
        .replace("{chunk_index:03d}", &format!("{chunk:03}"))
        .replace("{file_index:03d}", &format!("{file:03}"));
    let path = root.join(rel);
    let (rows, timestamps) = read_rows(&path, episode, feature, names.len())?;
    if rows.len() as u64 != length {
        return Err(ReadError::File {
            path,
            reason: format!(
                "episode {episode} has {} rows here but length {length} in the episodes table",
                rows.len()
            ),
        });
    }
    Ok(EpisodeRows {
        episode_index: episode,
        fps,
        total_episodes: total,
        feature: feature.to_string(),
        names,
        rows,
        timestamps,
    })
}

/// The names of float vector `feature` in info.json, or why it has none.
fn feature_names(info: &Value, feature: &str) -> Result<Vec<String>, String> {
    let features = info
        .get("features")
        .and_then(Value::as_object)
        .ok_or("meta/info.json has no features")?;
    let f = features.get(feature).ok_or_else(|| {
        format!(
            "the dataset has no `{feature}` feature (it has {})",
            features.keys().cloned().collect::<Vec<_>>().join(", ")
        )
    })?;
    let dtype = f.get("dtype").and_then(Value::as_str).unwrap_or("");
    if !matches!(dtype, "float32" | "float64") {
        return Err(format!(
            "`{feature}` is of dtype {dtype:?}, not a float vector"
        ));
    }
    let width = f
        .get("shape")
        .and_then(Value::as_array)
        .filter(|s| s.len() == 1)
        .and_then(|s| s[0].as_u64())
        .ok_or_else(|| format!("`{feature}`'s shape is not [n]"))? as usize;
    // names: a list, or lerobot's older {"motors": [...]}
    let list = match f.get("names") {
        Some(Value::Array(a)) => Some(a.clone()),
        Some(Value::Object(o)) if o.len() == 1 => {
            o.values().next().and_then(Value::as_array).cloned()
        }
        _ => None,
    };
    let names: Vec<String> = match list {
        Some(a) => a
            .iter()
            .map(|v| v.as_str().map(str::to_string))
            .collect::<Option<_>>()
            .ok_or_else(|| format!("`{feature}`'s names are not strings"))?,
        None => return Err(format!("`{feature}` has no names")),
    };
    if names.len() != width {
        return Err(format!(
            "`{feature}` has {} names for its shape [{width}]",
            names.len()
        ));
    }
    Ok(names)
}

/// Every `*.parquet` of `dir/*/`, sorted (`chunk-000/file-000.parquet` …).
fn parquet_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(chunks) = fs::read_dir(dir) else {
        return out;
    };
    for c in chunks.flatten() {
        if let Ok(files) = fs::read_dir(c.path()) {
            for f in files.flatten() {
                let p = f.path();
                if p.extension().is_some_and(|e| e == "parquet") {
                    out.push(p);
                }
            }
        }
    }
    out.sort();
    out
}

fn file_error(path: &Path) -> impl Fn(String) -> ReadError + '_ {
    move |reason| ReadError::File {
        path: path.to_path_buf(),
        reason,
    }
}

/// The batches of `path`, only the top-level `columns` decoded (each must be there).
fn read_columns(path: &Path, columns: &[&str]) -> Result<Vec<RecordBatch>, ReadError> {
    let err = file_error(path);
    let file = File::open(path).map_err(|e| err(e.to_string()))?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| err(e.to_string()))?;
    let schema = builder.schema().clone();
    let mut roots = Vec::new();
    for c in columns {
        let i = schema
            .fields()
            .iter()
            .position(|f| f.name() == c)
            .ok_or_else(|| err(format!("no column `{c}`")))?;
        roots.push(i);
    }
    let mask = ProjectionMask::roots(builder.parquet_schema(), roots);
    let reader = builder
        .with_projection(mask)
        .build()
        .map_err(|e| err(e.to_string()))?;
    reader.map(|b| b.map_err(|e| err(e.to_string()))).collect()
}

fn column<'a>(batch: &'a RecordBatch, name: &str, path: &Path) -> Result<&'a ArrayRef, ReadError> {
    batch
        .column_by_name(name)
        .ok_or_else(|| file_error(path)(format!("no column `{name}`")))
}

/// An integer column's values (int64, or a narrower integer).
fn ints(batch: &RecordBatch, name: &str, path: &Path) -> Result<Vec<i64>, ReadError> {
    let c = column(batch, name, path)?;
    let c = arrow_cast_i64(c).ok_or_else(|| {
        file_error(path)(format!(
            "column `{name}` is {}, not an integer",
            c.data_type()
        ))
    })?;
    Ok(c)
}

fn arrow_cast_i64(c: &ArrayRef) -> Option<Vec<i64>> {
    use arrow_array::types::{Int32Type, UInt32Type, UInt64Type};
    let out = match c.data_type() {
        DataType::Int64 => c
            .as_primitive::<Int64Type>()
            .iter()
            .map(|v| v.unwrap_or(-1))
            .collect(),
        DataType::Int32 => c
            .as_primitive::<Int32Type>()
            .iter()
            .map(|v| v.map_or(-1, i64::from))
            .collect(),
        DataType::UInt32 => c
            .as_primitive::<UInt32Type>()
            .iter()
            .map(|v| v.map_or(-1, i64::from))
            .collect(),
        DataType::UInt64 => c
            .as_primitive::<UInt64Type>()
            .iter()
            .map(|v| v.and_then(|v| i64::try_from(v).ok()).unwrap_or(-1))
            .collect(),
        _ => return None,
    };
    Some(out)
}

/// Where episode `episode`'s rows are: its data chunk and file, and its length.
fn find_episode(root: &Path, episode: u64) -> Result<(i64, i64, u64), ReadError> {
    let files = parquet_files(&root.join("meta/episodes"));
    if files.is_empty() {
        return Err(ReadError::NotADataset {
            path: root.to_path_buf(),
            reason: "it has no meta/episodes/*/*.parquet".into(),
        });
    }
    let wanted = [
        "episode_index",
        "data/chunk_index",
        "data/file_index",
        "length",
    ];
    for path in &files {
        for batch in read_columns(path, &wanted)? {
            let eps = ints(&batch, "episode_index", path)?;
            if let Some(i) = eps.iter().position(|&e| e == episode as i64) {
                let chunk = ints(&batch, "data/chunk_index", path)?[i];
                let file = ints(&batch, "data/file_index", path)?[i];
                let length = ints(&batch, "length", path)?[i];
                let length = u64::try_from(length).map_err(|_| {
                    file_error(path)(format!("episode {episode}'s length is {length}"))
                })?;
                return Ok((chunk, file, length));
            }
        }
    }
    Err(ReadError::NotADataset {
        path: root.to_path_buf(),
        reason: format!(
            "episode {episode} is counted in meta/info.json but in none of meta/episodes/*/*.parquet"
        ),
    })
}

/// The float values of row `i` of a vector column, or `None` if it is not one.
fn vector_rows(c: &ArrayRef, width: usize) -> Option<Vec<Vec<f32>>> {
    let (values, offsets): (ArrayRef, Vec<(usize, usize)>) = match c.data_type() {
        DataType::FixedSizeList(_, n) => {
            let l = c.as_fixed_size_list();
            let n = *n as usize;
            (
                l.values().clone(),
                (0..l.len()).map(|i| (l.value_offset_at(i), n)).collect(),
            )
        }
        DataType::List(_) => {
            let l = c.as_list::<i32>();
            let o = l.value_offsets();
            (
                l.values().clone(),
                (0..l.len())
                    .map(|i| (o[i] as usize, (o[i + 1] - o[i]) as usize))
                    .collect(),
            )
        }
        DataType::LargeList(_) => {
            let l = c.as_list::<i64>();
            let o = l.value_offsets();
            (
                l.values().clone(),
                (0..l.len())
                    .map(|i| (o[i] as usize, (o[i + 1] - o[i]) as usize))
                    .collect(),
            )
        }
        _ => return None,
    };
    let flat: Vec<f32> = match values.data_type() {
        DataType::Float32 => values
            .as_primitive::<Float32Type>()
            .iter()
            .map(|v| v.unwrap_or(f32::NAN))
            .collect(),
        DataType::Float64 => values
            .as_primitive::<Float64Type>()
            .iter()
            .map(|v| v.map_or(f32::NAN, |v| v as f32))
            .collect(),
        _ => return None,
    };
    offsets
        .into_iter()
        .map(|(start, len)| {
            (len == width)
                .then(|| flat.get(start..start + len).map(<[f32]>::to_vec))
                .flatten()
        })
        .collect()
}

fn floats(c: &ArrayRef) -> Option<Vec<f32>> {
    match c.data_type() {
        DataType::Float32 => Some(
            c.as_primitive::<Float32Type>()
                .iter()
                .map(|v| v.unwrap_or(f32::NAN))
                .collect(),
        ),
        DataType::Float64 => Some(
            c.as_primitive::<Float64Type>()
                .iter()
                .map(|v| v.map_or(f32::NAN, |v| v as f32))
                .collect(),
        ),
        _ => None,
    }
}

/// Episode `episode`'s rows of `feature` in data file `path`, and their timestamps,
/// in frame_index order.
type Rows = (Vec<Vec<f32>>, Vec<f32>);
fn read_rows(path: &Path, episode: u64, feature: &str, width: usize) -> Result<Rows, ReadError> {
    let err = file_error(path);
    let mut found: Vec<(i64, Vec<f32>, f32)> = Vec::new();
    for batch in read_columns(
        path,
        &[feature, "timestamp", "frame_index", "episode_index"],
    )? {
        let eps = ints(&batch, "episode_index", path)?;
        let frames = ints(&batch, "frame_index", path)?;
        let values = vector_rows(column(&batch, feature, path)?, width).ok_or_else(|| {
            err(format!(
                "column `{feature}` is not a list of {width} floats per row"
            ))
        })?;
        let stamps = floats(column(&batch, "timestamp", path)?)
            .ok_or_else(|| err("column `timestamp` is not float".into()))?;
        for (i, v) in values.into_iter().enumerate() {
            if eps[i] == episode as i64 {
                found.push((frames[i], v, stamps[i]));
            }
        }
    }
    found.sort_by_key(|f| f.0);
    if let Some(w) = found.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(err(format!(
            "episode {episode} has frame_index {} twice",
            w[0].0
        )));
    }
    if let Some((k, _, _)) = found.iter().find(|f| f.1.iter().any(|x| !x.is_finite())) {
        return Err(err(format!(
            "episode {episode}'s frame {k} has a `{feature}` value that is not a number"
        )));
    }
    Ok(found.into_iter().map(|(_, v, t)| (v, t)).unzip())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{DatasetSpec, DatasetWriter, Frame};

    const J: [&str; 4] = [
        "base_joint",
        "shoulder_joint",
        "elbow_joint",
        "gripper_joint",
    ];

    /// Action row k of episode e: distinct, and irregular enough not to compress
    /// (so that files roll at their size).
    fn row(e: usize, k: usize) -> [f32; 4] {
        let x = (e * 100_003 + k * 7_919) as f32;
        [
            e as f32 + k as f32 * 0.01,
            (x * 0.37).sin(),
            (x * 1.13).cos(),
            0.1 * e as f32,
        ]
    }

    /// A dataset of episodes of `lengths` frames: action row k of episode e is
    /// `row(e, k)`, the state its negation.
    fn dataset(dir: &Path, lengths: &[usize], spec: DatasetSpec) {
        let mut w = DatasetWriter::create(dir, spec).unwrap();
        for (e, &n) in lengths.iter().enumerate() {
            w.start_episode(&format!("task {e}")).unwrap();
            for k in 0..n {
                let a = row(e, k);
                let s = a.map(|x| -x);
                w.add_frame(Frame {
                    state: &s,
                    action: &a,
                    images: &[],
                })
                .unwrap();
            }
            w.save_episode().unwrap();
        }
    }

    #[test]
    fn episodes_read_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let lengths = [5, 12, 1, 7];
        dataset(
            dir.path(),
            &lengths,
            DatasetSpec::new(30, "eezybot_mk2", &J, &J),
        );
        for (e, &n) in lengths.iter().enumerate() {
            let ep = read_actions(dir.path(), e as u64).unwrap();
            assert_eq!(ep.episode_index, e as u64);
            assert_eq!(ep.fps, 30);
            assert_eq!(ep.total_episodes, 4);
            assert_eq!(ep.names, J);
            assert_eq!(
                ep.rows,
                (0..n).map(|k| row(e, k).to_vec()).collect::<Vec<_>>()
            );
            assert_eq!(
                ep.timestamps,
                (0..n).map(|k| (k as f64 / 30.0) as f32).collect::<Vec<_>>()
            );
        }
        let state = read_episode(dir.path(), 1, "observation.state").unwrap();
        assert_eq!(state.rows[3], row(1, 3).map(|x| -x).to_vec());
    }

    #[test]
    fn episodes_across_data_files_are_found() {
        let dir = tempfile::tempdir().unwrap();
        let mut spec = DatasetSpec::new(10, "eezybot_mk2", &J, &J);
        // 1 MB files: two episodes of 10 000 irregular frames (about 0.6 MB each) roll it
        spec.data_files_size_in_mb = 1;
        dataset(dir.path(), &[10_000, 10_000, 20], spec);
        let files = parquet_files(&dir.path().join("data"));
        assert!(files.len() >= 2, "the data file did not roll: {files:?}");
        let ep = read_actions(dir.path(), 2).unwrap();
        assert_eq!(ep.rows.len(), 20);
        assert_eq!(ep.rows[19], row(2, 19).to_vec());
        assert!((ep.duration_s() - 1.9).abs() < 1e-6);
        let ep = read_actions(dir.path(), 0).unwrap();
        assert_eq!(ep.rows[9_999], row(0, 9_999).to_vec());
    }

    #[test]
    fn refusals_say_why() {
        let dir = tempfile::tempdir().unwrap();
        let e = read_actions(dir.path(), 0).unwrap_err();
        assert!(matches!(e, ReadError::NotADataset { .. }), "{e}");
        assert!(e.to_string().contains("no meta/info.json"), "{e}");

        dataset(
            dir.path(),
            &[3, 4],
            DatasetSpec::new(30, "eezybot_mk2", &J, &J),
        );
        let e = read_actions(dir.path(), 2).unwrap_err();
        assert!(
            matches!(e, ReadError::NoSuchEpisode { total: 2, .. }),
            "{e}"
        );
        assert!(
            e.to_string().contains("has no episode 2: it has 2 (0 … 1)"),
            "{e}"
        );

        let e = read_episode(dir.path(), 0, "observation.images.camera").unwrap_err();
        assert!(
            e.to_string()
                .contains("no `observation.images.camera` feature"),
            "{e}"
        );
        let e = read_episode(dir.path(), 0, "frame_index").unwrap_err();
        assert!(e.to_string().contains("not a float vector"), "{e}");

        // not v3.0
        let info = dir.path().join("meta/info.json");
        let body = fs::read_to_string(&info).unwrap();
        fs::write(&info, body.replace("\"v3.0\"", "\"v2.1\"")).unwrap();
        let e = read_actions(dir.path(), 0).unwrap_err();
        assert!(
            e.to_string()
                .contains("codebase_version is \"v2.1\", not v3.0"),
            "{e}"
        );
        fs::write(&info, &body).unwrap();

        // a data file that is not parquet
        let data = dir.path().join("data/chunk-000/file-000.parquet");
        fs::write(&data, b"not parquet").unwrap();
        let e = read_actions(dir.path(), 1).unwrap_err();
        assert!(matches!(e, ReadError::File { .. }), "{e}");
    }
}
