//! Time-parameterised joint trajectories, executed as ros2_controllers'
//! joint_trajectory_controller executes them: from the joints' current positions at
//! time 0 through each waypoint at its `time_from_start`, cubic (Hermite) between two
//! points that both give velocities, linear otherwise, holding the last point at the
//! end. A trajectory that would break a joint's velocity or acceleration limit is
//! refused whole, before anything moves, naming the joint, the limit and the segment:
//! it is never slowed down.

use crate::AxisLimits;

/// One waypoint of a trajectory (trajectory_msgs/msg/JointTrajectoryPoint).
#[derive(Clone, Debug, PartialEq)]
pub struct Waypoint {
    /// Seconds after the trajectory's start, after the previous point's.
    pub time_from_start: f64,
    /// One position per joint.
    pub positions: Vec<f64>,
    /// One velocity per joint, or none (the segments at this point are then linear).
    pub velocities: Option<Vec<f64>>,
}

/// Why a trajectory was refused. Joints and points are indices (points from 0, the
/// start, the joints' positions when it is given, being "the start").
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TrajectoryError {
    /// No waypoint.
    #[error("the trajectory has no points")]
    Empty,
    /// A list of the wrong length.
    #[error("point {point}: {field} has {got} values for {expected} joints")]
    WrongSize {
        /// the point
        point: usize,
        /// `positions`, `velocities` or `start`
        field: &'static str,
        /// joints of the trajectory
        expected: usize,
        /// values given
        got: usize,
    },
    /// A NaN or infinite value.
    #[error("point {point}: {field}[{joint}] is {value}")]
    NonFinite {
        /// the point
        point: usize,
        /// `positions`, `velocities`, `time_from_start` or `start`
        field: &'static str,
        /// the joint (0 for a time)
        joint: usize,
        /// the value
        value: f64,
    },
    /// A point not after the one before it (the first: not after the start, 0 s).
    #[error("point {point}: time_from_start {time} s is not after {previous} s")]
    TimeNotIncreasing {
        /// the point
        point: usize,
        /// its time_from_start
        time: f64,
        /// the previous point's (0 for the first)
        previous: f64,
    },
    /// A segment that needs more than a joint's limit.
    #[error("joint {joint}: the {limit} limit {max:.4} would be exceeded ({needed:.4}) between {from} and point {to}")]
    OverLimit {
        /// the joint
        joint: usize,
        /// `velocity` or `acceleration`
        limit: &'static str,
        /// what the segment needs at its worst
        needed: f64,
        /// the joint's limit
        max: f64,
        /// `the start` or `point N`
        from: String,
        /// the segment's end point
        to: usize,
    },
}

/// Positions, velocities and accelerations of every joint at one instant.
#[derive(Clone, Debug, PartialEq)]
pub struct TrajectorySample {
    /// Positions.
    pub positions: Vec<f64>,
    /// Velocities (per second).
    pub velocities: Vec<f64>,
    /// Accelerations (per second²).
    pub accelerations: Vec<f64>,
    /// At or past the last point's time: the positions are the last point's, exactly.
    pub finished: bool,
}

/// A trajectory checked against the joints' limits, ready to be sampled.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// Knot times, 0 (the start) first.
    times: Vec<f64>,
    /// Positions at each knot.
    positions: Vec<Vec<f64>>,
    /// Velocities at each knot, where known (the start's: 0).
    velocities: Vec<Option<Vec<f64>>>,
}

/// Slack for rounding in the limit checks (relative).
const SLACK: f64 = 1e-9;

impl Trajectory {
    /// The trajectory from `start` (the joints' positions now, at rest) through `points`,
    /// checked whole: sizes, finite values, increasing times, and every segment within
    /// `limits` (one per joint) for velocity and, where cubic, acceleration. A linear
    /// segment's velocity is constant; where two of them meet it steps, as in
    /// joint_trajectory_controller (the servos' own velocity guard bounds it).
    pub fn new(
        start: &[f64],
        points: Vec<Waypoint>,
        limits: &[AxisLimits],
    ) -> Result<Trajectory, TrajectoryError> {
        let n = limits.len();
        if points.is_empty() {
            return Err(TrajectoryError::Empty);
        }
        check_values(0, "start", start, n)?;
        let mut times = vec![0.0];
        let mut positions = vec![start.to_vec()];
        let mut velocities = vec![Some(vec![0.0; n])];
        for (i, p) in points.into_iter().enumerate() {
            let point = i + 1;
            if !p.time_from_start.is_finite() {
                return Err(TrajectoryError::NonFinite {
                    point,
                    field: "time_from_start",
                    joint: 0,
                    value: p.time_from_start,
                });
            }
            let previous = times[times.len() - 1];
            if p.time_from_start <= previous {
                return Err(TrajectoryError::TimeNotIncreasing {
                    point,
                    time: p.time_from_start,
                    previous,
                });
            }
            check_values(point, "positions", &p.positions, n)?;
            if let Some(v) = &p.velocities {
                check_values(point, "velocities", v, n)?;
            }
            times.push(p.time_from_start);
            positions.push(p.positions);
            velocities.push(p.velocities);
        }
        let t = Trajectory {
            times,
            positions,
            velocities,
        };
        t.check_limits(limits)?;
        Ok(t)
    }

    /// Joints.
    pub fn joints(&self) -> usize {
        self.positions[0].len()
    }

    /// The last point's time_from_start.
    pub fn duration(&self) -> f64 {
        self.times[self.times.len() - 1]
    }

    /// The waypoints' times (without the start).
    pub fn point_times(&self) -> &[f64] {
        &self.times[1..]
    }

    /// The waypoints' positions (without the start).
    pub fn point_positions(&self) -> &[Vec<f64>] {
        &self.positions[1..]
    }

    /// The state `t` seconds after the start: before 0 the start, from the end on
    /// the last point, exactly, at rest (`finished`; so too for a NaN `t`).
    pub fn sample(&self, t: f64) -> TrajectorySample {
        let n = self.joints();
        if t.is_nan() || t >= self.duration() {
            return TrajectorySample {
                positions: self.positions[self.positions.len() - 1].clone(),
                velocities: vec![0.0; n],
                accelerations: vec![0.0; n],
                finished: true,
            };
        }
        let t = t.max(0.0);
        // the segment [times[k], times[k + 1]) holding t
        let k = self.times.partition_point(|&x| x <= t).saturating_sub(1);
        let k = k.min(self.times.len() - 2);
        let mut s = TrajectorySample {
            positions: Vec::with_capacity(n),
            velocities: Vec::with_capacity(n),
            accelerations: Vec::with_capacity(n),
            finished: false,
        };
        for j in 0..n {
            let seg = self.segment(k, j);
            let (p, v, a) = seg.at(t - self.times[k]);
            s.positions.push(p);
            s.velocities.push(v);
            s.accelerations.push(a);
        }
        s
    }

    /// Joint `j`'s piece of segment `k` (from knot k to knot k + 1).
    fn segment(&self, k: usize, j: usize) -> Segment {
        let dt = self.times[k + 1] - self.times[k];
        let (p0, p1) = (self.positions[k][j], self.positions[k + 1][j]);
        match (&self.velocities[k], &self.velocities[k + 1]) {
            (Some(v0), Some(v1)) => Segment::cubic(p0, v0[j], p1, v1[j], dt),
            _ => Segment::linear(p0, p1, dt),
        }
    }

    fn check_limits(&self, limits: &[AxisLimits]) -> Result<(), TrajectoryError> {
        for k in 0..self.times.len() - 1 {
            for (j, l) in limits.iter().enumerate() {
                let seg = self.segment(k, j);
                let from = if k == 0 {
                    "the start".to_string()
                } else {
                    format!("point {k}")
                };
                for (limit, needed, max) in [
                    ("velocity", seg.max_speed(), l.max_velocity),
                    ("acceleration", seg.max_acceleration(), l.max_acceleration),
                ] {
                    if needed > max * (1.0 + SLACK) + SLACK {
                        return Err(TrajectoryError::OverLimit {
                            joint: j,
                            limit,
                            needed,
                            max,
                            from,
                            to: k + 1,
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

fn check_values(
    point: usize,
    field: &'static str,
    values: &[f64],
    n: usize,
) -> Result<(), TrajectoryError> {
    if values.len() != n {
        return Err(TrajectoryError::WrongSize {
            point,
            field,
            expected: n,
            got: values.len(),
        });
    }
    if let Some((joint, &value)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(TrajectoryError::NonFinite {
            point,
            field,
            joint,
            value,
        });
    }
    Ok(())
}

/// One joint over one segment: p(τ) = c0 + c1·τ + c2·τ² + c3·τ³ for τ in [0, dt].
#[derive(Clone, Copy, Debug)]
struct Segment {
    c: [f64; 4],
    dt: f64,
    linear: bool,
}

impl Segment {
    fn linear(p0: f64, p1: f64, dt: f64) -> Segment {
        Segment {
            c: [p0, (p1 - p0) / dt, 0.0, 0.0],
            dt,
            linear: true,
        }
    }

    /// The cubic Hermite polynomial with these end positions and velocities.
    fn cubic(p0: f64, v0: f64, p1: f64, v1: f64, dt: f64) -> Segment {
        let d = p1 - p0;
        Segment {
            c: [
                p0,
                v0,
                (3.0 * d - (2.0 * v0 + v1) * dt) / (dt * dt),
                (-2.0 * d + (v0 + v1) * dt) / (dt * dt * dt),
            ],
            dt,
            linear: false,
        }
    }

    /// Position, velocity and acceleration τ into the segment.
    fn at(&self, tau: f64) -> (f64, f64, f64) {
        let [c0, c1, c2, c3] = self.c;
        (
            c0 + tau * (c1 + tau * (c2 + tau * c3)),
            c1 + tau * (2.0 * c2 + tau * 3.0 * c3),
            if self.linear {
                0.0
            } else {
                2.0 * c2 + 6.0 * c3 * tau
            },
        )
    }

    /// The largest |velocity| over the segment: at an end, or where the (quadratic)
    /// velocity turns.
    fn max_speed(&self) -> f64 {
        let [_, c1, c2, c3] = self.c;
        let mut taus = vec![0.0, self.dt];
        if c3 != 0.0 {
            let turn = -c2 / (3.0 * c3);
            if turn > 0.0 && turn < self.dt {
                taus.push(turn);
            }
        }
        taus.into_iter()
            .map(|tau| (c1 + tau * (2.0 * c2 + tau * 3.0 * c3)).abs())
            .fold(0.0, f64::max)
    }

    /// The largest |acceleration| over the segment (linear in τ: at an end).
    fn max_acceleration(&self) -> f64 {
        if self.linear {
            return 0.0;
        }
        let [_, _, c2, c3] = self.c;
        (2.0 * c2).abs().max((2.0 * c2 + 6.0 * c3 * self.dt).abs())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Whatever is accepted stays within the limits everywhere (sampled densely),
        /// passes through every point at its time and ends exactly on the last.
        #[test]
        fn accepted_trajectories_keep_the_limits_and_hit_every_point(
            raw in prop::collection::vec(
                (0.05f64..1.0, -0.9f64..0.9, prop::option::of(-0.6f64..0.6)), 1..6)
        ) {
            let (vmax, amax) = (1.5, 8.0);
            let l = vec![AxisLimits::new(vmax, amax).unwrap()];
            let (mut t, mut p) = (0.0, 0.0);
            // steps within the velocity limit; given velocities may still ask too much
            // acceleration or overshoot, and such trajectories are refused (prop_assume:
            // proptest fails if it has to refuse too many, so the property is not vacuous)
            let points: Vec<Waypoint> = raw
                .iter()
                .map(|&(dt, step, v)| {
                    t += dt;
                    p += step * vmax * dt;
                    Waypoint { time_from_start: t, positions: vec![p], velocities: v.map(|v| vec![v * vmax]) }
                })
                .collect();
            let traj = Trajectory::new(&[0.0], points.clone(), &l);
            prop_assume!(traj.is_ok());
            let traj = traj.unwrap();
            for w in &points {
                let s = traj.sample(w.time_from_start - 1e-12);
                prop_assert!((s.positions[0] - w.positions[0]).abs() < 1e-6);
            }
            let end = traj.duration();
            for i in 0..=2000 {
                let s = traj.sample(end * f64::from(i) / 2000.0);
                prop_assert!(s.velocities[0].abs() <= vmax * (1.0 + 1e-6), "{s:?}");
                prop_assert!(s.accelerations[0].abs() <= amax * (1.0 + 1e-6), "{s:?}");
            }
            prop_assert_eq!(traj.sample(end).positions[0], points[points.len() - 1].positions[0]);
        }
    }

    fn limits(v: f64, a: f64) -> Vec<AxisLimits> {
        vec![AxisLimits::new(v, a).unwrap(); 2]
    }

    fn point(t: f64, p: [f64; 2], v: Option<[f64; 2]>) -> Waypoint {
        Waypoint {
            time_from_start: t,
            positions: p.to_vec(),
            velocities: v.map(|v| v.to_vec()),
        }
    }

    #[test]
    fn linear_segments_pass_through_every_point_and_end_exactly() {
        let t = Trajectory::new(
            &[0.0, 1.0],
            vec![point(1.0, [0.5, 1.0], None), point(3.0, [0.1, 0.2], None)],
            &limits(1.0, 10.0),
        )
        .unwrap();
        assert_eq!(t.duration(), 3.0);
        let mid = t.sample(0.5);
        assert_eq!(mid.positions, vec![0.25, 1.0]);
        assert_eq!(mid.velocities, vec![0.5, 0.0]);
        assert!((t.sample(1.0).positions[0] - 0.5).abs() < 1e-15);
        let end = t.sample(3.0);
        assert_eq!(end.positions, vec![0.1, 0.2]);
        assert!(end.finished);
        assert_eq!(end.velocities, vec![0.0, 0.0]);
        assert_eq!(t.sample(99.0).positions, vec![0.1, 0.2]);
        assert_eq!(t.sample(-1.0).positions, vec![0.0, 1.0]);
    }

    #[test]
    fn cubic_segments_meet_the_given_velocities() {
        let t = Trajectory::new(
            &[0.0, 0.0],
            vec![
                point(1.0, [0.5, -0.5], Some([0.6, -0.6])),
                point(2.0, [1.0, -1.0], Some([0.0, 0.0])),
            ],
            &limits(2.0, 10.0),
        )
        .unwrap();
        let at_start = t.sample(0.0);
        assert_eq!(at_start.velocities, vec![0.0, 0.0]);
        let s = t.sample(1.0);
        assert!((s.positions[0] - 0.5).abs() < 1e-12);
        assert!((s.velocities[0] - 0.6).abs() < 1e-12);
        let just_before = t.sample(1.0 - 1e-9);
        assert!((just_before.velocities[1] + 0.6).abs() < 1e-6);
        assert_eq!(t.sample(2.0).positions, vec![1.0, -1.0]);
    }

    #[test]
    fn a_jump_or_a_too_fast_segment_is_refused_naming_the_joint_and_the_limit() {
        // the first point 2 rad away after 1 s needs 2 rad/s
        let e = Trajectory::new(
            &[0.0, 0.0],
            vec![point(1.0, [0.0, 2.0], None)],
            &limits(1.0, 10.0),
        )
        .unwrap_err();
        assert!(
            matches!(
                &e,
                TrajectoryError::OverLimit {
                    joint: 1,
                    limit: "velocity",
                    to: 1,
                    ..
                }
            ),
            "{e}"
        );
        assert!(
            e.to_string().contains("between the start and point 1"),
            "{e}"
        );
        // cubic, within velocity but accelerating too hard
        let e = Trajectory::new(
            &[0.0, 0.0],
            vec![
                point(0.2, [0.0, 0.1], Some([0.0, 0.9])),
                point(0.4, [0.0, 0.2], Some([0.0, 0.0])),
            ],
            &limits(1.0, 5.0),
        )
        .unwrap_err();
        assert!(
            matches!(
                &e,
                TrajectoryError::OverLimit {
                    joint: 1,
                    limit: "acceleration",
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn malformed_trajectories_are_refused() {
        let l = limits(1.0, 1.0);
        assert_eq!(
            Trajectory::new(&[0.0, 0.0], vec![], &l).unwrap_err(),
            TrajectoryError::Empty
        );
        assert!(matches!(
            Trajectory::new(&[0.0, 0.0], vec![point(0.0, [0.0, 0.0], None)], &l).unwrap_err(),
            TrajectoryError::TimeNotIncreasing { point: 1, .. }
        ));
        assert!(matches!(
            Trajectory::new(
                &[0.0, 0.0],
                vec![point(1.0, [0.0, 0.0], None), point(1.0, [0.0, 0.0], None)],
                &l
            )
            .unwrap_err(),
            TrajectoryError::TimeNotIncreasing { point: 2, .. }
        ));
        assert!(matches!(
            Trajectory::new(&[0.0, 0.0], vec![point(1.0, [f64::NAN, 0.0], None)], &l).unwrap_err(),
            TrajectoryError::NonFinite {
                point: 1,
                field: "positions",
                joint: 0,
                ..
            }
        ));
        let mut short = point(1.0, [0.0, 0.0], None);
        short.positions.pop();
        assert!(matches!(
            Trajectory::new(&[0.0, 0.0], vec![short], &l).unwrap_err(),
            TrajectoryError::WrongSize {
                point: 1,
                field: "positions",
                expected: 2,
                got: 1
            }
        ));
        assert!(matches!(
            Trajectory::new(&[0.0], vec![point(1.0, [0.0, 0.0], None)], &l).unwrap_err(),
            TrajectoryError::WrongSize {
                point: 0,
                field: "start",
                ..
            }
        ));
    }
}
