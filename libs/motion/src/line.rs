//! Straight Cartesian lines, checked along their whole length before a move starts.

use crate::{JointPath, MotionError};
use std::fmt;

/// Why a straight line cannot be moved along.
#[derive(Clone, Debug, PartialEq)]
pub enum LineError<E> {
    /// A point of the line is not reachable: `reason` is the IK's.
    Unreachable {
        /// where along the line, 0 (start) … 1 (end)
        fraction: f64,
        /// the point (m)
        point: [f64; 3],
        /// why not
        reason: E,
    },
    /// Between two neighbouring points a joint would have to jump (the line passes a
    /// singularity or changes IK branch).
    Jump {
        /// where along the line, 0 … 1
        fraction: f64,
        /// the point (m)
        point: [f64; 3],
        /// the joint
        axis: usize,
        /// its change between the two points
        change: f64,
    },
    /// The joint path could not be built.
    Path(MotionError),
}

impl<E: fmt::Display> fmt::Display for LineError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let at = |f: &mut fmt::Formatter<'_>, fraction: f64, p: &[f64; 3]| {
            write!(
                f,
                "{:.0} % along the line, at ({:.4}, {:.4}, {:.4}) m",
                fraction * 100.0,
                p[0],
                p[1],
                p[2]
            )
        };
        match self {
            LineError::Unreachable {
                fraction,
                point,
                reason,
            } => {
                write!(f, "the straight line leaves the workspace ")?;
                at(f, *fraction, point)?;
                write!(f, ": {reason}")
            }
            LineError::Jump {
                fraction,
                point,
                axis,
                change,
            } => {
                write!(
                    f,
                    "the straight line needs joint {axis} to jump by {change:.3} "
                )?;
                at(f, *fraction, point)
            }
            LineError::Path(e) => write!(f, "{e}"),
        }
    }
}

/// The joint path of a straight line from `from` to `to` (m): the line sampled at
/// most `step_m` apart, `ik` solved at every sample. Refused, with where and why, if
/// any sample is unreachable or a joint changes by more than `max_joint_step` between
/// neighbouring samples.
///
/// # Examples
/// ```
/// use eezybot_motion::{straight_line, LineError};
/// // a planar two-link arm of unit links: reachable within radius 2
/// let ik = |p: [f64; 3]| -> Result<Vec<f64>, String> {
///     let r2 = p[0] * p[0] + p[1] * p[1];
///     let c = (r2 - 2.0) / 2.0;
///     if !(-1.0..=1.0).contains(&c) { return Err(format!("{:.3} m away", r2.sqrt())) }
///     let e = -c.acos();
///     Ok(vec![p[1].atan2(p[0]) - e.sin().atan2(1.0 + e.cos()), e])
/// };
/// let path = straight_line([1.5, 0.0, 0.0], [0.0, 1.5, 0.0], 0.01, 0.2, ik).unwrap();
/// assert!(path.len() > 200);
/// // out past the reach of 2: refused where the line leaves it (or where the elbow
/// // would have to snap straight just before)
/// match straight_line([1.5, 0.0, 0.0], [3.0, 0.0, 0.0], 0.01, 0.2, ik).unwrap_err() {
///     LineError::Unreachable { fraction, .. } | LineError::Jump { fraction, .. } => {
///         assert!(fraction > 0.3 && fraction <= 0.34, "{fraction}")
///     }
///     other => panic!("{other}"),
/// }
/// ```
pub fn straight_line<E, F>(
    from: [f64; 3],
    to: [f64; 3],
    step_m: f64,
    max_joint_step: f64,
    mut ik: F,
) -> Result<JointPath, LineError<E>>
where
    F: FnMut([f64; 3]) -> Result<Vec<f64>, E>,
{
    let length = (0..3)
        .map(|i| (to[i] - from[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    let segments = if length.is_finite() && step_m > 0.0 {
        ((length / step_m).ceil() as usize).clamp(1, 1_000_000)
    } else {
        1
    };
    let mut points: Vec<Vec<f64>> = Vec::with_capacity(segments + 1);
    for k in 0..=segments {
        let fraction = k as f64 / segments as f64;
        let point: [f64; 3] = std::array::from_fn(|i| from[i] + (to[i] - from[i]) * fraction);
        let q = ik(point).map_err(|reason| LineError::Unreachable {
            fraction,
            point,
            reason,
        })?;
        if let Some(prev) = points.last() {
            if let Some((axis, change)) = q
                .iter()
                .zip(prev)
                .map(|(a, b)| (a - b).abs())
                .enumerate()
                .find(|(_, d)| *d > max_joint_step)
            {
                return Err(LineError::Jump {
                    fraction,
                    point,
                    axis,
                    change,
                });
            }
        }
        points.push(q);
    }
    JointPath::new(points).map_err(LineError::Path)
}
