#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

mod line;
mod planner;
mod trajectory;

pub use line::{straight_line, LineError};
pub use planner::{JointPath, Planner};
pub use trajectory::{Trajectory, TrajectoryError, TrajectorySample, Waypoint};

/// Why a limit, goal or path was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MotionError {
    /// A limit that is not a positive finite number.
    #[error("{what} must be a positive finite number, not {value}")]
    BadLimit {
        /// which limit
        what: &'static str,
        /// the value given
        value: f64,
    },
    /// A goal or position with the wrong number of axes.
    #[error("{got} axes given, the planner has {expected}")]
    WrongAxisCount {
        /// axes of the planner
        expected: usize,
        /// axes given
        got: usize,
    },
    /// A goal or position that is NaN or infinite.
    #[error("axis {axis} is {value}")]
    NonFinite {
        /// the axis
        axis: usize,
        /// the value
        value: f64,
    },
    /// A path that does not start where the planner will be when it starts it.
    #[error("the path starts {distance:.3e} away from the axes' position (axis {axis})")]
    PathStartMismatch {
        /// the axis furthest off
        axis: usize,
        /// how far off
        distance: f64,
    },
    /// A path with fewer than two points.
    #[error("a path needs at least two points")]
    EmptyPath,
}

/// Velocity and acceleration limits of one axis (units per second, per second²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisLimits {
    /// Highest speed, > 0.
    pub max_velocity: f64,
    /// Highest acceleration (and deceleration), > 0.
    pub max_acceleration: f64,
}

impl AxisLimits {
    /// Limits, checked: both positive and finite.
    pub fn new(max_velocity: f64, max_acceleration: f64) -> Result<AxisLimits, MotionError> {
        for (what, value) in [
            ("max_velocity", max_velocity),
            ("max_acceleration", max_acceleration),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(MotionError::BadLimit { what, value });
            }
        }
        Ok(AxisLimits {
            max_velocity,
            max_acceleration,
        })
    }

    /// Both limits multiplied by `k` (0 < k ≤ 1 slows the axis down).
    pub fn scaled(self, k: f64) -> AxisLimits {
        AxisLimits {
            max_velocity: self.max_velocity * k,
            max_acceleration: self.max_acceleration * k,
        }
    }
}

/// Position and velocity of one axis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AxisState {
    /// Position.
    pub position: f64,
    /// Velocity (per second).
    pub velocity: f64,
}

/// One time step `dt` of an axis moving toward `target` within `limits`.
///
/// The position advances by the new velocity times `dt`; the velocity changes by at
/// most `max_acceleration · dt` and stays within `±max_velocity`. The axis aims at
/// the fastest velocity from which braking by `max_acceleration · dt` per step ends
/// exactly on the target, so from rest it never overshoots and it stops on the target
/// (velocity 0) without a jump. If it moves too fast for a new, closer target, it
/// brakes as hard as allowed and comes back. A velocity above `max_velocity` (limits
/// lowered while moving) is brought down at `max_acceleration`.
///
/// # Examples
/// ```
/// use eezybot_motion::{track, AxisLimits, AxisState};
/// let l = AxisLimits::new(2.0, 10.0).unwrap();
/// let mut s = AxisState::default();
/// let mut peak: f64 = 0.0;
/// for _ in 0..200 {
///     let next = track(s, 1.0, l, 0.01);
///     assert!((next.velocity - s.velocity).abs() <= 10.0 * 0.01 + 1e-12);
///     peak = peak.max(next.velocity);
///     s = next;
/// }
/// assert_eq!(s, AxisState { position: 1.0, velocity: 0.0 });
/// assert!((peak - 2.0).abs() < 1e-12);
/// ```
pub fn track(state: AxisState, target: f64, limits: AxisLimits, dt: f64) -> AxisState {
    let AxisState { position, velocity } = state;
    let dv_max = limits.max_acceleration * dt;
    let error = target - position;
    if error.abs() <= ARRIVED * target.abs().max(1.0) && velocity.abs() <= dv_max {
        return AxisState {
            position: target,
            velocity: 0.0,
        };
    }
    // The fastest velocity from which braking by dv_max per step ends exactly on the
    // target: velocities (n+f)·dv, (n−1+f)·dv, …, f·dv, 0 cover
    // dv·dt·((n+1)·f + n(n+1)/2) = |error|, with n whole and 0 ≤ f < 1.
    let x = error.abs() / (dv_max * dt);
    let n = ((((1.0 + 8.0 * x).sqrt() - 1.0) / 2.0).floor()).max(0.0);
    let f = ((x - n * (n + 1.0) / 2.0) / (n + 1.0)).clamp(0.0, 1.0);
    let wanted = error.signum() * ((n + f) * dv_max).min(limits.max_velocity);
    let velocity = velocity + (wanted - velocity).clamp(-dv_max, dv_max);
    let next = position + velocity * dt;
    AxisState {
        // on the target but for rounding: on the target
        position: if (target - next).abs() <= ARRIVED * target.abs().max(1.0) {
            target
        } else {
            next
        },
        velocity,
    }
}

/// Closer than this (relative to the target's magnitude, at least 1) is there.
const ARRIVED: f64 = 1e-12;

/// Time for an axis at rest to cover `distance` within `limits` (continuous time:
/// a triangle or a trapezoid).
pub fn move_time(distance: f64, limits: AxisLimits) -> f64 {
    let d = distance.abs();
    let (v, a) = (limits.max_velocity, limits.max_acceleration);
    if d <= v * v / a {
        2.0 * (d / a).sqrt()
    } else {
        d / v + v / a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn run(mut s: AxisState, target: f64, l: AxisLimits, dt: f64, steps: usize) -> Vec<AxisState> {
        let mut out = vec![s];
        for _ in 0..steps {
            s = track(s, target, l, dt);
            out.push(s);
        }
        out
    }

    proptest! {
        // From any state, for any target: acceleration and velocity within limits at
        // every step (after a too-fast start has been braked), and the axis ends on the
        // target at rest.
        #[test]
        fn limits_hold_and_the_target_is_reached(
            p0 in -3.0..3.0f64, v0 in -2.0..2.0f64, target in -3.0..3.0f64,
            vmax in 0.1..3.0f64, amax in 0.5..30.0f64, dt in 0.002..0.05f64,
        ) {
            let l = AxisLimits::new(vmax, amax).unwrap();
            let v0 = v0.clamp(-vmax, vmax);
            let traj = run(AxisState { position: p0, velocity: v0 }, target, l, dt, 20_000);
            for w in traj.windows(2) {
                prop_assert!((w[1].velocity - w[0].velocity).abs() <= amax * dt * (1.0 + 1e-9) + 1e-12,
                    "accel {} > {}", (w[1].velocity - w[0].velocity) / dt, amax);
                prop_assert!(w[1].velocity.abs() <= vmax * (1.0 + 1e-9));
            }
            prop_assert_eq!(traj.last().copied(), Some(AxisState { position: target, velocity: 0.0 }));
        }

        // From rest the axis never passes the target, and takes about the continuous
        // time-optimal time.
        #[test]
        fn from_rest_no_overshoot_and_near_optimal_time(
            d in 1e-4..3.0f64, vmax in 0.1..3.0f64, amax in 0.5..30.0f64, dt in 0.002..0.02f64,
        ) {
            let l = AxisLimits::new(vmax, amax).unwrap();
            let traj = run(AxisState::default(), d, l, dt, 20_000);
            prop_assert!(traj.iter().all(|s| s.position <= d && s.position >= 0.0));
            let steps = traj.iter().position(|s| s.position == d && s.velocity == 0.0).unwrap();
            let t = steps as f64 * dt;
            let best = move_time(d, l);
            // semi-implicit steps may gain a few periods on the continuous optimum
            prop_assert!(t >= best - 4.0 * dt && t <= best + 3.0 * dt + 0.1 * best, "{t} vs {best}");
        }
    }

    #[test]
    fn too_fast_for_a_close_target_brakes_and_comes_back() {
        let l = AxisLimits::new(1.0, 5.0).unwrap();
        let traj = run(
            AxisState {
                position: 0.0,
                velocity: 1.0,
            },
            0.01,
            l,
            0.01,
            1000,
        );
        let furthest = traj.iter().map(|s| s.position).fold(0.0, f64::max);
        // braking from 1 m/s at 5 m/s² takes 0.1 m
        assert!(furthest > 0.09 && furthest < 0.12, "{furthest}");
        assert_eq!(traj.last().unwrap().position, 0.01);
    }

    #[test]
    fn bad_limits_are_refused_with_the_value() {
        assert_eq!(
            AxisLimits::new(f64::NAN, 1.0).unwrap_err().to_string(),
            "max_velocity must be a positive finite number, not NaN"
        );
        assert!(AxisLimits::new(1.0, 0.0).is_err());
        assert!(AxisLimits::new(-1.0, 1.0).is_err());
    }
}
