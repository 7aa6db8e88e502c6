//! Feature statistics as lerobot 0.6.1 computes them (`lerobot/datasets/compute_stats.py`).
//!
//! - Per episode, per feature (`get_feature_stats` with `axis=0`): min, max, mean, std
//!   (population: `sqrt(max(0, E[x²] - E[x]²))`), count (the number of frames), and the
//!   quantiles q01, q10, q50, q90, q99 from `RunningQuantileStats`: a histogram of 5000
//!   bins per dimension between `min - 1e-10` and `max + 1e-10` (numpy `linspace`
//!   edges; numpy `histogram` bins, half-open but the last closed), the quantile
//!   interpolated linearly inside the bin where the cumulative count reaches
//!   `q * count`. An episode of one frame gets the quantiles set to the mean (lerobot's
//!   `_compute_basic_stats`).
//! - Across episodes (`aggregate_feature_stats`): min of mins, max of maxes, the mean
//!   weighted by counts, the variance by the parallel algorithm
//!   (`Σ count·(std² + (mean - total_mean)²) / Σ count`), and each quantile the
//!   count-weighted mean of the episodes' quantiles (not a quantile of the whole data).
//!
//! - Images (`compute_episode_stats` for image/video features, [`image_stats`]): the
//!   frames at lerobot's `sample_indices`, downsampled, per channel, divided by 255.
//!
//! Precision: lerobot computes float32 features (and uint8 images) in float32 (numpy's
//! promotion). The histogram is computed as it does, with float32 bin edges
//! ([`Precision`]), so the quantiles are lerobot's own (tests/lerobot_load.py: equal to
//! lerobot's `get_feature_stats`). The moments are computed in f64: lerobot's float32
//! `E[x²] - E[x]²` loses digits to cancellation, so its std differs from ours by up to
//! about 1e-6 (2e-6 seen for a joint with std 0.02), its mean by about 1e-7.

use serde_json::Value;

use crate::json::Ordered;

/// The quantiles lerobot stores (`DEFAULT_QUANTILES`) and their keys.
pub const QUANTILES: [(f64, &str); 5] = [
    (0.01, "q01"),
    (0.10, "q10"),
    (0.50, "q50"),
    (0.90, "q90"),
    (0.99, "q99"),
];

/// lerobot's `RunningQuantileStats` default `num_quantile_bins`.
pub const QUANTILE_BINS: usize = 5000;

/// The statistics of one feature: one value per dimension, `count` frames.
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureStats {
    /// Per-dimension minimum.
    pub min: Vec<f64>,
    /// Per-dimension maximum.
    pub max: Vec<f64>,
    /// Per-dimension mean.
    pub mean: Vec<f64>,
    /// Per-dimension population standard deviation.
    pub std: Vec<f64>,
    /// Number of frames.
    pub count: u64,
    /// Per-dimension quantiles, in the order of [`QUANTILES`].
    pub quantiles: [Vec<f64>; 5],
}

/// numpy's `linspace(start, stop, num)`: `start + i * step`, the last exactly `stop`.
fn linspace(start: f64, stop: f64, num: usize) -> Vec<f64> {
    let div = (num - 1) as f64;
    let step = (stop - start) / div;
    let mut v: Vec<f64> = (0..num).map(|i| start + i as f64 * step).collect();
    if let Some(last) = v.last_mut() {
        *last = stop;
    }
    v
}

/// numpy's `histogram(values, bins=edges)`: bin i holds `edges[i] <= x < edges[i+1]`,
/// the last bin also `x == edges[-1]`; values outside are not counted.
fn histogram(values: &[f64], edges: &[f64]) -> Vec<f64> {
    let bins = edges.len() - 1;
    let mut hist = vec![0.0; bins];
    let (first, last) = (edges[0], edges[bins]);
    for &x in values {
        if !(x >= first && x <= last) {
            continue;
        }
        // the number of edges <= x, minus one
        let i = edges.partition_point(|&e| e <= x);
        let bin = if i > bins { bins - 1 } else { i - 1 };
        hist[bin.min(bins - 1)] += 1.0;
    }
    hist
}

/// [`histogram`] of distinct `values` each seen `weights[i]` times.
fn histogram_weighted(values: &[f64], weights: &[f64], edges: &[f64]) -> Vec<f64> {
    let bins = edges.len() - 1;
    let mut hist = vec![0.0; bins];
    let (first, last) = (edges[0], edges[bins]);
    for (&x, &w) in values.iter().zip(weights) {
        if !(x >= first && x <= last) {
            continue;
        }
        let i = edges.partition_point(|&e| e <= x);
        let bin = if i > bins { bins - 1 } else { i - 1 };
        hist[bin.min(bins - 1)] += w;
    }
    hist
}

/// The floating point type numpy computes a feature's histogram in: lerobot's
/// `RunningQuantileStats` promotes with `np.result_type(dtype, np.float32)`, so float32
/// features (and uint8 images) get float32 bin edges, int64 features float64 ones. The
/// quantiles depend on it: a value near an edge falls in one bin or the next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    /// float32 features and images.
    F32,
    /// int64 (and float64) features.
    F64,
}

/// lerobot's bin edges, `np.linspace(min - 1e-10, max + 1e-10, bins + 1)`, computed in
/// `p` as numpy does (NumPy 2 keeps a float32 minus a Python float in float32):
/// `arange(num) * step + start` with `step = (stop - start) / bins`, the last edge
/// exactly `stop`; with a zero step, `arange(num) / bins * delta + start`.
fn quantile_edges(min: f64, max: f64, p: Precision) -> Vec<f64> {
    match p {
        Precision::F64 => linspace(min - 1e-10, max + 1e-10, QUANTILE_BINS + 1),
        Precision::F32 => {
            let start = min as f32 - 1e-10f32;
            let stop = max as f32 + 1e-10f32;
            let div = QUANTILE_BINS as f32;
            let delta = stop - start;
            let step = delta / div;
            let mut v: Vec<f64> = (0..=QUANTILE_BINS)
                .map(|i| {
                    let y = i as f32;
                    f64::from(if step == 0.0 {
                        y / div * delta + start
                    } else {
                        y * step + start
                    })
                })
                .collect();
            if let Some(last) = v.last_mut() {
                *last = f64::from(stop);
            }
            v
        }
    }
}

/// lerobot's `_compute_single_quantile` (its bin width `edges[idx + 1] - edges[idx]` is
/// taken in the edges' precision, the rest in float64).
fn single_quantile(hist: &[f64], edges: &[f64], target: f64, p: Precision) -> f64 {
    let mut cumsum = Vec::with_capacity(hist.len());
    let mut acc = 0.0;
    for &h in hist {
        acc += h;
        cumsum.push(acc);
    }
    // numpy searchsorted(side="left"): the first index with cumsum[idx] >= target
    let idx = cumsum.partition_point(|&c| c < target);
    if idx == 0 {
        return edges[0];
    }
    if idx >= cumsum.len() {
        return edges[edges.len() - 1];
    }
    let before = cumsum[idx - 1];
    let in_bin = cumsum[idx] - before;
    if in_bin == 0.0 {
        return edges[idx];
    }
    let fraction = (target - before) / in_bin;
    let width = match p {
        Precision::F32 => f64::from(edges[idx + 1] as f32 - edges[idx] as f32),
        Precision::F64 => edges[idx + 1] - edges[idx],
    };
    edges[idx] + fraction * width
}

impl FeatureStats {
    /// The statistics of `rows` (frames × dimensions), as lerobot's
    /// `get_feature_stats(array, axis=0, …)` computes them. `None` without rows or with
    /// rows of different lengths. `p`: the feature's [`Precision`].
    pub fn compute(rows: &[Vec<f64>], p: Precision) -> Option<Self> {
        let n = rows.len();
        let dims = rows.first()?.len();
        if rows.iter().any(|r| r.len() != dims) {
            return None;
        }
        let column = |d: usize| rows.iter().map(move |r| r[d]);
        let mut s = FeatureStats {
            min: Vec::with_capacity(dims),
            max: Vec::with_capacity(dims),
            mean: Vec::with_capacity(dims),
            std: Vec::with_capacity(dims),
            count: n as u64,
            quantiles: Default::default(),
        };
        for d in 0..dims {
            let min = column(d).fold(f64::INFINITY, f64::min);
            let max = column(d).fold(f64::NEG_INFINITY, f64::max);
            let mean = column(d).sum::<f64>() / n as f64;
            let std = if n < 2 {
                // np.std
                (column(d).map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64).sqrt()
            } else {
                let mean_sq = column(d).map(|x| x * x).sum::<f64>() / n as f64;
                (mean_sq - mean * mean).max(0.0).sqrt()
            };
            s.min.push(min);
            s.max.push(max);
            s.mean.push(mean);
            s.std.push(std);
            if n < 2 {
                for q in s.quantiles.iter_mut() {
                    q.push(mean);
                }
            } else {
                let edges = quantile_edges(min, max, p);
                let values: Vec<f64> = column(d).collect();
                let hist = histogram(&values, &edges);
                for (qi, (q, _)) in QUANTILES.iter().enumerate() {
                    s.quantiles[qi].push(single_quantile(&hist, &edges, q * n as f64, p));
                }
            }
        }
        Some(s)
    }

    /// lerobot's `aggregate_feature_stats` over `parts` (all of the same dimension).
    pub fn aggregate(parts: &[&FeatureStats]) -> Option<Self> {
        let first = parts.first()?;
        let dims = first.mean.len();
        if parts.iter().any(|p| p.mean.len() != dims) {
            return None;
        }
        let total: u64 = parts.iter().map(|p| p.count).sum();
        let tc = total as f64;
        let per_dim = |f: &dyn Fn(&FeatureStats, usize) -> f64| -> Vec<f64> {
            (0..dims)
                .map(|d| parts.iter().map(|p| f(p, d) * p.count as f64).sum::<f64>() / tc)
                .collect()
        };
        let mean = per_dim(&|p, d| p.mean[d]);
        let variance = per_dim(&|p, d| {
            let delta = p.mean[d] - mean[d];
            p.std[d] * p.std[d] + delta * delta
        });
        let mut quantiles: [Vec<f64>; 5] = Default::default();
        for (qi, q) in quantiles.iter_mut().enumerate() {
            *q = per_dim(&|p, d| p.quantiles[qi][d]);
        }
        Some(FeatureStats {
            min: (0..dims)
                .map(|d| parts.iter().map(|p| p.min[d]).fold(f64::INFINITY, f64::min))
                .collect(),
            max: (0..dims)
                .map(|d| {
                    parts
                        .iter()
                        .map(|p| p.max[d])
                        .fold(f64::NEG_INFINITY, f64::max)
                })
                .collect(),
            mean,
            std: variance.iter().map(|v| v.sqrt()).collect(),
            count: total,
            quantiles,
        })
    }

    /// The stat names in lerobot's order with their values (`count` as one integer).
    pub fn entries(&self) -> Vec<(&'static str, StatValue<'_>)> {
        let mut v = vec![
            ("min", StatValue::Floats(&self.min)),
            ("max", StatValue::Floats(&self.max)),
            ("mean", StatValue::Floats(&self.mean)),
            ("std", StatValue::Floats(&self.std)),
            ("count", StatValue::Count(self.count)),
        ];
        for (qi, (_, key)) in QUANTILES.iter().enumerate() {
            v.push((key, StatValue::Floats(&self.quantiles[qi])));
        }
        v
    }

    /// As stats.json holds it: `{"min": [...], ..., "count": [n], "q01": [...], ...}`.
    pub fn to_json(&self) -> Ordered {
        Ordered::obj(self.entries().into_iter().map(|(k, v)| {
            let val = match v {
                StatValue::Floats(f) => Ordered::val(f.to_vec()),
                StatValue::Count(c) => Ordered::val(vec![c]),
            };
            (k, val)
        }))
    }

    /// As stats.json holds an image feature's stats: each value nested as shape
    /// (channels, 1, 1), `count` as `[n]`.
    pub fn to_json_image(&self) -> Ordered {
        Ordered::obj(self.entries().into_iter().map(|(k, v)| {
            let val = match v {
                StatValue::Floats(f) => {
                    Ordered::val(f.iter().map(|&x| vec![vec![x]]).collect::<Vec<_>>())
                }
                StatValue::Count(c) => Ordered::val(vec![c]),
            };
            (k, val)
        }))
    }

    /// Reads what [`FeatureStats::to_json`] and [`FeatureStats::to_json_image`] write
    /// (and lerobot's stats.json).
    pub fn from_json(v: &Value) -> Option<Self> {
        // image stats nest each value as (channels, 1, 1): flattened
        fn flat(v: &Value, out: &mut Vec<f64>) -> Option<()> {
            match v {
                Value::Array(items) => items.iter().try_for_each(|x| flat(x, out)),
                x => {
                    out.push(x.as_f64()?);
                    Some(())
                }
            }
        }
        let floats = |k: &str| -> Option<Vec<f64>> {
            let mut out = Vec::new();
            flat(v.get(k)?, &mut out)?;
            Some(out)
        };
        let count = v.get("count")?.as_array()?.first()?.as_u64()?;
        let mut quantiles: [Vec<f64>; 5] = Default::default();
        for (qi, (_, key)) in QUANTILES.iter().enumerate() {
            quantiles[qi] = floats(key)?;
        }
        Some(FeatureStats {
            min: floats("min")?,
            max: floats("max")?,
            mean: floats("mean")?,
            std: floats("std")?,
            count,
            quantiles,
        })
    }
}

/// lerobot's `estimate_num_samples` (defaults: 100 to 10 000 samples, power 0.75): how
/// many frames of an episode its image statistics sample.
pub fn estimate_num_samples(len: usize) -> usize {
    let min = 100.min(len);
    let pow = (len as f64).powf(0.75) as usize;
    min.max(pow.min(10_000))
}

/// lerobot's `sample_indices`: `round(linspace(0, len - 1, n))`, numpy's rounding (half
/// to even), `n` from [`estimate_num_samples`].
pub fn sample_indices(len: usize) -> Vec<usize> {
    let n = estimate_num_samples(len);
    if n == 0 {
        return Vec::new();
    }
    if n == 1 {
        return vec![0];
    }
    linspace(0.0, (len - 1) as f64, n)
        .into_iter()
        .map(|x| x.round_ties_even() as usize)
        .collect()
}

/// lerobot's `auto_downsample_height_width` step for an image of `height` × `width`:
/// 1 below 300 pixels on the long side, else `int(long side / 150)`.
pub fn downsample_step(height: usize, width: usize) -> usize {
    if width.max(height) < 300 {
        1
    } else if width > height {
        (width / 150).max(1)
    } else {
        (height / 150).max(1)
    }
}

/// One channel's (or a frame's) pixels counted per value: lerobot's image statistics
/// need only these. A frame adds its pixels after lerobot's downsampling
/// ([`downsample_step`]); summing the counts of the sampled frames gives their
/// statistics ([`PixelCounts::stats`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PixelCounts(pub [[u64; 256]; 3]);

impl Default for PixelCounts {
    fn default() -> Self {
        PixelCounts([[0; 256]; 3])
    }
}

impl PixelCounts {
    /// Bytes of one frame's counts on disk ([`PixelCounts::to_record`]).
    pub const RECORD_BYTES: usize = 3 * 256 * 4;

    /// Adds an RGB frame (`height × width × 3` bytes, row-major), downsampled as lerobot
    /// does (every [`downsample_step`]-th row and column). `false` if the frame has
    /// another size (nothing added).
    pub fn add_frame(&mut self, rgb: &[u8], height: usize, width: usize) -> bool {
        if rgb.len() != height * width * 3 {
            return false;
        }
        let step = downsample_step(height, width);
        for y in (0..height).step_by(step) {
            for x in (0..width).step_by(step) {
                let p = (y * width + x) * 3;
                for (c, count) in self.0.iter_mut().enumerate() {
                    count[usize::from(rgb[p + c])] += 1;
                }
            }
        }
        true
    }

    /// Adds another's counts.
    pub fn add(&mut self, other: &PixelCounts) {
        for (a, b) in self.0.iter_mut().zip(&other.0) {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
        }
    }

    /// One frame's counts as little-endian u32 (a downsampled frame has fewer than
    /// 300 × 300 pixels), [`PixelCounts::RECORD_BYTES`] bytes.
    pub fn to_record(&self) -> Vec<u8> {
        self.0
            .iter()
            .flatten()
            .flat_map(|&c| (c.min(u64::from(u32::MAX)) as u32).to_le_bytes())
            .collect()
    }

    /// Reads what [`PixelCounts::to_record`] wrote.
    pub fn from_record(record: &[u8]) -> Option<Self> {
        if record.len() != Self::RECORD_BYTES {
            return None;
        }
        let mut out = PixelCounts::default();
        for (i, b) in record.chunks_exact(4).enumerate() {
            out.0[i / 256][i % 256] = u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        }
        Some(out)
    }

    /// lerobot's per-channel statistics of these pixels (`get_feature_stats` over
    /// axes (0, 2, 3), divided by 255), for `frames` sampled frames (the `count`).
    /// `None` without pixels.
    pub fn stats(&self, frames: u64) -> Option<FeatureStats> {
        let pixels: u64 = self.0[0].iter().sum();
        if pixels == 0 {
            return None;
        }
        let n = pixels as f64;
        let mut s = FeatureStats {
            min: Vec::new(),
            max: Vec::new(),
            mean: Vec::new(),
            std: Vec::new(),
            count: frames,
            quantiles: Default::default(),
        };
        for count in &self.0 {
            let values: Vec<f64> = (0..256)
                .filter(|&v| count[v] > 0)
                .map(|v| v as f64)
                .collect();
            let weights: Vec<f64> = (0..256)
                .filter(|&v| count[v] > 0)
                .map(|v| count[v] as f64)
                .collect();
            let min = values[0];
            let max = values[values.len() - 1];
            let mean = values.iter().zip(&weights).map(|(v, w)| v * w).sum::<f64>() / n;
            let std = if pixels < 2 {
                0.0
            } else {
                let mean_sq = values
                    .iter()
                    .zip(&weights)
                    .map(|(v, w)| v * v * w)
                    .sum::<f64>()
                    / n;
                (mean_sq - mean * mean).max(0.0).sqrt()
            };
            s.min.push(min / 255.0);
            s.max.push(max / 255.0);
            s.mean.push(mean / 255.0);
            s.std.push(std / 255.0);
            if pixels < 2 {
                for q in s.quantiles.iter_mut() {
                    q.push(mean / 255.0);
                }
            } else {
                // uint8 pixels are promoted to float32
                let edges = quantile_edges(min, max, Precision::F32);
                let hist = histogram_weighted(&values, &weights, &edges);
                for (qi, (q, _)) in QUANTILES.iter().enumerate() {
                    let v = single_quantile(&hist, &edges, q * n, Precision::F32);
                    s.quantiles[qi].push(v / 255.0);
                }
            }
        }
        Some(s)
    }
}

/// The statistics of a camera's frames in one episode, as lerobot's
/// `compute_episode_stats` computes them for an image or video feature: the frames at
/// [`sample_indices`], each downsampled by [`downsample_step`] (every step-th row and
/// column), per channel over all their pixels, divided by 255; `count` is the number of
/// frames sampled. `frame(i)` gives frame `i` of the `len` as RGB bytes, row-major
/// (`height × width × 3`); `None` if a frame is missing or of another size.
///
/// The pixels are counted per value ([`PixelCounts`]), which gives numpy's histogram
/// exactly and takes no memory per pixel. In stats.json each value is nested as lerobot's
/// shape (3, 1, 1): see [`FeatureStats::to_json_image`].
pub fn image_stats(
    len: usize,
    height: usize,
    width: usize,
    mut frame: impl FnMut(usize) -> Option<Vec<u8>>,
) -> Option<FeatureStats> {
    let idx = sample_indices(len);
    let mut counts = PixelCounts::default();
    for &i in &idx {
        if !counts.add_frame(&frame(i)?, height, width) {
            return None;
        }
    }
    counts.stats(idx.len() as u64)
}

/// One stat's value: per-dimension floats, or the frame count.
#[derive(Debug, Clone, Copy)]
pub enum StatValue<'a> {
    /// min, max, mean, std and the quantiles.
    Floats(&'a [f64]),
    /// count.
    Count(u64),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(v: &[f64]) -> Vec<Vec<f64>> {
        v.iter().map(|&x| vec![x]).collect()
    }

    #[test]
    fn basic_stats_by_hand() {
        // 1, 2, 3, 4: mean 2.5, E[x²] = 7.5, var = 1.25
        let s = FeatureStats::compute(&rows(&[1.0, 2.0, 3.0, 4.0]), Precision::F64).unwrap();
        assert_eq!(s.min, vec![1.0]);
        assert_eq!(s.max, vec![4.0]);
        assert_eq!(s.mean, vec![2.5]);
        assert!((s.std[0] - 1.25f64.sqrt()).abs() < 1e-12);
        assert_eq!(s.count, 4);
    }

    #[test]
    fn quantiles_by_histogram_interpolation() {
        // 0..=99 over 5000 bins of width (99 + 2e-10) / 5000: value k sits in bin
        // floor(k / w). q50: target 50 frames; the cumulative count reaches 50 at the
        // bin of value 49, so q50 = left edge of that bin + (50 - 49) / 1 · width.
        let values: Vec<f64> = (0..100).map(f64::from).collect();
        let s = FeatureStats::compute(&rows(&values), Precision::F64).unwrap();
        let lo: f64 = -1e-10;
        let w = (99.0 + 2e-10) / 5000.0;
        let bin49 = ((49.0 - lo) / w).floor();
        let expect = lo + bin49 * w + w;
        assert!(
            (s.quantiles[2][0] - expect).abs() < 1e-9,
            "{}",
            s.quantiles[2][0]
        );
        // q01: target 1 frame; the first bin (value 0) already holds it → edges[0]
        assert!((s.quantiles[0][0] - lo).abs() < 1e-12);
        // q99: target 99: the bin of value 98 ends it
        let bin98 = ((98.0 - lo) / w).floor();
        assert!((s.quantiles[4][0] - (lo + (bin98 + 1.0) * w)).abs() < 1e-9);
    }

    #[test]
    fn one_frame_quantiles_are_the_mean() {
        let s = FeatureStats::compute(&[vec![3.0, -1.0]], Precision::F32).unwrap();
        assert_eq!(s.std, vec![0.0, 0.0]);
        for q in &s.quantiles {
            assert_eq!(q, &vec![3.0, -1.0]);
        }
    }

    #[test]
    fn constant_feature() {
        let s = FeatureStats::compute(&rows(&[7.0; 10]), Precision::F32).unwrap();
        assert_eq!(s.std, vec![0.0]);
        for q in &s.quantiles {
            assert!((q[0] - 7.0).abs() < 1e-9, "{q:?}");
        }
    }

    #[test]
    fn aggregate_equals_whole_for_moments() {
        let a: Vec<f64> = vec![1.0, 5.0, 2.0];
        let b: Vec<f64> = vec![10.0, -3.0, 4.0, 8.0, 0.5];
        let sa = FeatureStats::compute(&rows(&a), Precision::F64).unwrap();
        let sb = FeatureStats::compute(&rows(&b), Precision::F64).unwrap();
        let all: Vec<f64> = a.iter().chain(&b).copied().collect();
        let sall = FeatureStats::compute(&rows(&all), Precision::F64).unwrap();
        let agg = FeatureStats::aggregate(&[&sa, &sb]).unwrap();
        assert_eq!(agg.count, 8);
        assert_eq!(agg.min, sall.min);
        assert_eq!(agg.max, sall.max);
        assert!((agg.mean[0] - sall.mean[0]).abs() < 1e-12);
        assert!((agg.std[0] - sall.std[0]).abs() < 1e-12);
        // quantiles: count-weighted means of the parts' quantiles
        let q = (sa.quantiles[2][0] * 3.0 + sb.quantiles[2][0] * 5.0) / 8.0;
        assert!((agg.quantiles[2][0] - q).abs() < 1e-12);
    }

    #[test]
    fn sampling_as_lerobot() {
        // the docstring of lerobot's estimate_num_samples
        assert_eq!(estimate_num_samples(1), 1);
        assert_eq!(estimate_num_samples(500), 105);
        assert_eq!(estimate_num_samples(1000), 177);
        assert_eq!(estimate_num_samples(2000), 299);
        assert_eq!(estimate_num_samples(5000), 594);
        assert_eq!(estimate_num_samples(10_000), 1000);
        assert_eq!(estimate_num_samples(20_000), 1681);
        assert_eq!(sample_indices(50), (0..50).collect::<Vec<_>>());
        // np.round(np.linspace(0, 150, 100)): 150/99 steps, halves to even
        let idx = sample_indices(151);
        assert_eq!(idx.len(), 100);
        assert_eq!(&idx[..6], &[0, 2, 3, 5, 6, 8]);
        assert_eq!(idx[99], 150);
        assert_eq!(downsample_step(480, 640), 4);
        assert_eq!(downsample_step(120, 160), 1);
        assert_eq!(downsample_step(720, 405), 4);
    }

    #[test]
    fn image_stats_by_hand() {
        // 4 frames of 2 × 2 (no downsampling, every frame sampled): red 0 and 255 in
        // equal numbers, green all 51, blue 0..=15 over the 16 pixels
        let frames: Vec<Vec<u8>> = (0..4u8)
            .map(|f| {
                (0..4u8)
                    .flat_map(|p| [if (f + p) % 2 == 0 { 0 } else { 255 }, 51, f * 4 + p])
                    .collect()
            })
            .collect();
        let s = image_stats(4, 2, 2, |i| frames.get(i).cloned()).unwrap();
        assert_eq!(s.count, 4);
        assert_eq!(s.min, vec![0.0, 0.2, 0.0]);
        assert_eq!(s.max, vec![1.0, 0.2, 15.0 / 255.0]);
        assert!((s.mean[0] - 0.5).abs() < 1e-12 && (s.std[0] - 0.5).abs() < 1e-12);
        assert!((s.mean[2] - 7.5 / 255.0).abs() < 1e-12);
        let var_blue = (0..16).map(|v| (f64::from(v) - 7.5).powi(2)).sum::<f64>() / 16.0;
        assert!((s.std[2] - var_blue.sqrt() / 255.0).abs() < 1e-12);
        // green: one value → every quantile within 1e-10 of it
        for q in &s.quantiles {
            assert!((q[1] - 0.2).abs() < 1e-9);
        }
        // lerobot 0.6.1's get_feature_stats(frames, axis=(0, 2, 3), keepdims=True) / 255
        // on the same frames (the same float32 bin edges: the same quantiles)
        let lerobot = [
            [-3.921568679809537e-13, 0.2, -3.921568679809537e-13],
            [-3.921568679809537e-13, 0.2, 0.003924705841962029],
            [-3.921568679809537e-13, 0.2, 0.027458822960947073],
            [0.999959992053462, 0.2, 0.054898824504777496],
            [0.9999959992053462, 0.2, 0.05882164689606312],
        ];
        for (qi, want) in lerobot.iter().enumerate() {
            for (c, w) in want.iter().enumerate() {
                assert!((s.quantiles[qi][c] - w).abs() < 1e-9, "{qi} {c}: {s:?}");
            }
        }
        assert!((s.std[2] - 0.018077537417411804).abs() < 1e-7);
        // the weighted histogram equals the per-pixel one
        let blue: Vec<Vec<f64>> = (0..16).map(|v| vec![f64::from(v)]).collect();
        let per_pixel = FeatureStats::compute(&blue, Precision::F32).unwrap();
        for qi in 0..5 {
            assert!((s.quantiles[qi][2] - per_pixel.quantiles[qi][0] / 255.0).abs() < 1e-12);
        }
        let j = String::from_utf8(s.to_json_image().to_pretty()).unwrap();
        let v: Value = serde_json::from_str(&j).unwrap();
        assert_eq!(v["max"][0], serde_json::json!([[1.0]]));
        assert_eq!(v["count"], serde_json::json!([4]));
        assert_eq!(FeatureStats::from_json(&v).unwrap(), s);
        // per-frame records summed give the same
        let mut sum = PixelCounts::default();
        for f in &frames {
            let mut c = PixelCounts::default();
            assert!(c.add_frame(f, 2, 2));
            let rec = c.to_record();
            assert_eq!(rec.len(), PixelCounts::RECORD_BYTES);
            sum.add(&PixelCounts::from_record(&rec).unwrap());
        }
        assert_eq!(sum.stats(4).unwrap(), s);
        // a frame of the wrong size is refused
        assert!(image_stats(4, 2, 3, |i| frames.get(i).cloned()).is_none());
    }

    #[test]
    fn json_round_trip() {
        let s = FeatureStats::compute(&[vec![1.0, 2.0], vec![3.0, 5.0]], Precision::F64).unwrap();
        let text = String::from_utf8(s.to_json().to_pretty()).unwrap();
        let keys: Vec<usize> = ["min", "max", "mean", "std", "count", "q01", "q99"]
            .iter()
            .map(|k| text.find(&format!("\"{k}\"")).unwrap())
            .collect();
        assert!(keys.windows(2).all(|w| w[0] < w[1]), "{text}");
        let j: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(j["count"], serde_json::json!([2]));
        assert_eq!(FeatureStats::from_json(&j).unwrap(), s);
    }
}
