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
//! lerobot computes in float32 for float32 features (numpy's promotion); this computes
//! in f64 throughout, so the values agree to float32 precision, not bit for bit.

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

/// lerobot's `_compute_single_quantile`.
fn single_quantile(hist: &[f64], edges: &[f64], target: f64) -> f64 {
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
    edges[idx] + fraction * (edges[idx + 1] - edges[idx])
}

impl FeatureStats {
    /// The statistics of `rows` (frames × dimensions), as lerobot's
    /// `get_feature_stats(array, axis=0, …)` computes them. `None` without rows or with
    /// rows of different lengths.
    pub fn compute(rows: &[Vec<f64>]) -> Option<Self> {
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
                let edges = linspace(min - 1e-10, max + 1e-10, QUANTILE_BINS + 1);
                let values: Vec<f64> = column(d).collect();
                let hist = histogram(&values, &edges);
                for (qi, (q, _)) in QUANTILES.iter().enumerate() {
                    s.quantiles[qi].push(single_quantile(&hist, &edges, q * n as f64));
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

    /// Reads what [`FeatureStats::to_json`] writes (and lerobot's stats.json).
    pub fn from_json(v: &Value) -> Option<Self> {
        let floats = |k: &str| -> Option<Vec<f64>> {
            v.get(k)?.as_array()?.iter().map(|x| x.as_f64()).collect()
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
        let s = FeatureStats::compute(&rows(&[1.0, 2.0, 3.0, 4.0])).unwrap();
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
        let s = FeatureStats::compute(&rows(&values)).unwrap();
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
        let s = FeatureStats::compute(&[vec![3.0, -1.0]]).unwrap();
        assert_eq!(s.std, vec![0.0, 0.0]);
        for q in &s.quantiles {
            assert_eq!(q, &vec![3.0, -1.0]);
        }
    }

    #[test]
    fn constant_feature() {
        let s = FeatureStats::compute(&rows(&[7.0; 10])).unwrap();
        assert_eq!(s.std, vec![0.0]);
        for q in &s.quantiles {
            assert!((q[0] - 7.0).abs() < 1e-9, "{q:?}");
        }
    }

    #[test]
    fn aggregate_equals_whole_for_moments() {
        let a: Vec<f64> = vec![1.0, 5.0, 2.0];
        let b: Vec<f64> = vec![10.0, -3.0, 4.0, 8.0, 0.5];
        let sa = FeatureStats::compute(&rows(&a)).unwrap();
        let sb = FeatureStats::compute(&rows(&b)).unwrap();
        let all: Vec<f64> = a.iter().chain(&b).copied().collect();
        let sall = FeatureStats::compute(&rows(&all)).unwrap();
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
    fn json_round_trip() {
        let s = FeatureStats::compute(&[vec![1.0, 2.0], vec![3.0, 5.0]]).unwrap();
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
