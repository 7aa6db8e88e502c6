//! Several axes moving together within their limits, re-planned from their current
//! state whenever a new goal arrives.

use crate::{track, AxisLimits, AxisState, MotionError};

/// Velocities below this count as standing still.
const AT_REST: f64 = 1e-12;
/// How far a path may start from where the planner is (or will stop).
const PATH_START_TOLERANCE: f64 = 1e-6;

/// A path in joint space: waypoints evenly spaced along a path parameter (e.g. a
/// Cartesian line sampled every millimetre), followed by linear interpolation.
#[derive(Clone, Debug, PartialEq)]
pub struct JointPath {
    points: Vec<Vec<f64>>,
}

impl JointPath {
    /// A path through `points` (at least two, all with the same number of axes, finite).
    pub fn new(points: Vec<Vec<f64>>) -> Result<JointPath, MotionError> {
        if points.len() < 2 {
            return Err(MotionError::EmptyPath);
        }
        let axes = points[0].len();
        for p in &points {
            if p.len() != axes {
                return Err(MotionError::WrongAxisCount {
                    expected: axes,
                    got: p.len(),
                });
            }
            check_finite(p)?;
        }
        Ok(JointPath { points })
    }

    /// The first point.
    pub fn start(&self) -> &[f64] {
        &self.points[0]
    }

    /// The last point.
    pub fn end(&self) -> &[f64] {
        &self.points[self.points.len() - 1]
    }

    /// Number of waypoints.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Never true: a path has at least two points.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The waypoints.
    pub fn points(&self) -> &[Vec<f64>] {
        &self.points
    }

    /// The point at path parameter `u` (0 … len−1), interpolated.
    pub fn at(&self, u: f64) -> Vec<f64> {
        let last = (self.points.len() - 1) as f64;
        let u = u.clamp(0.0, last);
        let k = (u.floor() as usize).min(self.points.len() - 2);
        let f = u - k as f64;
        self.points[k]
            .iter()
            .zip(&self.points[k + 1])
            .map(|(a, b)| a + (b - a) * f)
            .collect()
    }

    /// Limits of the path parameter such that every axis stays within its own: half
    /// of each axis' acceleration for the parameter's acceleration along the path, half
    /// for the path's curvature at full speed.
    fn parameter_limits(&self, axes: &[AxisLimits]) -> AxisLimits {
        let mut v = f64::INFINITY;
        let mut a = f64::INFINITY;
        for (i, l) in axes.iter().enumerate() {
            for w in self.points.windows(2) {
                let slope = (w[1][i] - w[0][i]).abs();
                if slope > 0.0 {
                    v = v.min(l.max_velocity / slope);
                    a = a.min(0.5 * l.max_acceleration / slope);
                }
            }
            for w in self.points.windows(3) {
                let curvature = (w[2][i] - 2.0 * w[1][i] + w[0][i]).abs();
                if curvature > 0.0 {
                    v = v.min((0.5 * l.max_acceleration / curvature).sqrt());
                }
            }
        }
        // a path that does not move any axis: any finite limit will do
        let finite = |x: f64| if x.is_finite() { x } else { 1e9 };
        AxisLimits {
            max_velocity: finite(v),
            max_acceleration: finite(a),
        }
    }
}

fn check_finite(q: &[f64]) -> Result<(), MotionError> {
    match q.iter().position(|x| !x.is_finite()) {
        Some(axis) => Err(MotionError::NonFinite {
            axis,
            value: q[axis],
        }),
        None => Ok(()),
    }
}

#[derive(Clone, Debug)]
enum Goal {
    /// At rest; nothing to do.
    Rest,
    /// Every axis toward `target`, each within `limits`.
    Move {
        target: Vec<f64>,
        limits: Vec<AxisLimits>,
    },
    /// Braking to a standstill, then following the path.
    StopThen(JointPath),
    /// Following a path: `u` is the path parameter and its speed.
    Path {
        path: JointPath,
        u: AxisState,
        limits: AxisLimits,
    },
}

/// Axes moving toward a goal within their limits, one fixed period per [`step`].
///
/// [`step`]: Planner::step
#[derive(Clone, Debug)]
pub struct Planner {
    limits: Vec<AxisLimits>,
    axes: Vec<AxisState>,
    period: f64,
    goal: Goal,
}

impl Planner {
    /// A planner for axes with these limits, at rest at `start`, stepped every
    /// `period` seconds.
    pub fn new(
        limits: Vec<AxisLimits>,
        start: &[f64],
        period: f64,
    ) -> Result<Planner, MotionError> {
        if !(period.is_finite() && period > 0.0) {
            return Err(MotionError::BadLimit {
                what: "period",
                value: period,
            });
        }
        let mut p = Planner {
            axes: vec![AxisState::default(); limits.len()],
            limits,
            period,
            goal: Goal::Rest,
        };
        p.reset(start)?;
        Ok(p)
    }

    fn check(&self, q: &[f64]) -> Result<(), MotionError> {
        if q.len() != self.axes.len() {
            return Err(MotionError::WrongAxisCount {
                expected: self.axes.len(),
                got: q.len(),
            });
        }
        check_finite(q)
    }

    /// The step period (s).
    pub fn period(&self) -> f64 {
        self.period
    }

    /// The axes' limits.
    pub fn limits(&self) -> &[AxisLimits] {
        &self.limits
    }

    /// Change the limits; the current motion continues within the new ones (a faster
    /// axis is braked at its new acceleration).
    pub fn set_limits(&mut self, limits: Vec<AxisLimits>) -> Result<(), MotionError> {
        if limits.len() != self.axes.len() {
            return Err(MotionError::WrongAxisCount {
                expected: self.axes.len(),
                got: limits.len(),
            });
        }
        self.limits = limits;
        if let Goal::Move { target, .. } = &self.goal {
            self.goal = Goal::Move {
                target: target.clone(),
                limits: self.limits.clone(),
            };
        }
        Ok(())
    }

    /// Start over at rest at `position` (e.g. the pose a device reports).
    pub fn reset(&mut self, position: &[f64]) -> Result<(), MotionError> {
        self.check(position)?;
        for (a, &p) in self.axes.iter_mut().zip(position) {
            *a = AxisState {
                position: p,
                velocity: 0.0,
            };
        }
        self.goal = Goal::Rest;
        Ok(())
    }

    /// Stop where the axes are now, at once (an emergency stop: the commanded motion
    /// ends here; the next goal starts from rest at this position).
    pub fn stop(&mut self) {
        for a in &mut self.axes {
            a.velocity = 0.0;
        }
        self.goal = Goal::Rest;
    }

    /// Current positions.
    pub fn position(&self) -> Vec<f64> {
        self.axes.iter().map(|a| a.position).collect()
    }

    /// Current velocities (per second).
    pub fn velocity(&self) -> Vec<f64> {
        self.axes.iter().map(|a| a.velocity).collect()
    }

    /// Whether a goal is still being pursued.
    pub fn is_moving(&self) -> bool {
        !matches!(self.goal, Goal::Rest)
    }

    fn at_rest(&self) -> bool {
        self.axes.iter().all(|a| a.velocity.abs() < AT_REST)
    }

    /// Where the current goal ends.
    pub fn destination(&self) -> Vec<f64> {
        match &self.goal {
            Goal::Rest => self.position(),
            Goal::Move { target, .. } => target.clone(),
            Goal::StopThen(path) | Goal::Path { path, .. } => path.end().to_vec(),
        }
    }

    /// Where the axes would come to a standstill if they braked now as hard as their
    /// limits allow: where a path must start if one is to follow the current motion.
    pub fn stopping_position(&self) -> Vec<f64> {
        let mut axes = self.axes.clone();
        while axes.iter().any(|a| a.velocity.abs() >= AT_REST) {
            for (a, l) in axes.iter_mut().zip(&self.limits) {
                *a = brake(*a, *l, self.period);
            }
        }
        axes.iter().map(|a| a.position).collect()
    }

    /// Move every axis to `target`, from the current state. Axes starting at rest
    /// arrive together (each slowed in proportion to its share of the move: a straight
    /// line in joint space); a motion under way is re-planned with each axis'
    /// full limits, its velocity carried over.
    pub fn move_to(&mut self, target: &[f64]) -> Result<(), MotionError> {
        self.check(target)?;
        let limits = if self.at_rest() {
            let d: Vec<f64> = target
                .iter()
                .zip(&self.axes)
                .map(|(t, a)| (t - a.position).abs())
                .collect();
            if d.iter().all(|&x| x == 0.0) {
                self.goal = Goal::Rest;
                return Ok(());
            }
            // the fastest common profile every axis can follow: axis i covers d_i·s(t)
            let (mut vs, mut as_) = (f64::INFINITY, f64::INFINITY);
            for (di, l) in d.iter().zip(&self.limits) {
                if *di > 0.0 {
                    vs = vs.min(l.max_velocity / di);
                    as_ = as_.min(l.max_acceleration / di);
                }
            }
            d.iter()
                .zip(&self.limits)
                .map(|(di, l)| {
                    if *di > 0.0 {
                        AxisLimits {
                            max_velocity: di * vs,
                            max_acceleration: di * as_,
                        }
                    } else {
                        *l
                    }
                })
                .collect()
        } else {
            self.limits.clone()
        };
        self.goal = Goal::Move {
            target: target.to_vec(),
            limits,
        };
        Ok(())
    }

    /// Follow `path`: at once if the axes are at rest where it starts, else after
    /// braking to a standstill, which must be where it starts
    /// ([`Planner::stopping_position`]).
    pub fn follow(&mut self, path: JointPath) -> Result<(), MotionError> {
        self.check(path.start())?;
        let moving = !self.at_rest();
        let start = if moving {
            self.stopping_position()
        } else {
            self.position()
        };
        if let Some((axis, distance)) = path
            .start()
            .iter()
            .zip(&start)
            .map(|(a, b)| (a - b).abs())
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .filter(|(_, d)| *d > PATH_START_TOLERANCE)
        {
            return Err(MotionError::PathStartMismatch { axis, distance });
        }
        self.goal = if moving {
            Goal::StopThen(path)
        } else {
            self.path_goal(path)
        };
        Ok(())
    }

    fn path_goal(&self, path: JointPath) -> Goal {
        let limits = path.parameter_limits(&self.limits);
        Goal::Path {
            path,
            u: AxisState::default(),
            limits,
        }
    }

    /// Advance one period. Returns the new positions while a goal is pursued (the
    /// step that reaches it included), `None` once at rest.
    pub fn step(&mut self) -> Option<Vec<f64>> {
        let dt = self.period;
        let goal = std::mem::replace(&mut self.goal, Goal::Rest);
        self.goal = match goal {
            Goal::Rest => return None,
            Goal::Move { target, limits } => {
                for ((a, t), l) in self.axes.iter_mut().zip(&target).zip(&limits) {
                    *a = track(*a, *t, *l, dt);
                }
                let arrived = self
                    .axes
                    .iter()
                    .zip(&target)
                    .all(|(a, t)| a.position == *t && a.velocity == 0.0);
                if arrived {
                    Goal::Rest
                } else {
                    Goal::Move { target, limits }
                }
            }
            Goal::StopThen(path) => {
                for (a, l) in self.axes.iter_mut().zip(&self.limits) {
                    *a = brake(*a, *l, dt);
                }
                if self.at_rest() {
                    // land exactly on the path's start (equal within the tolerance)
                    for (a, p) in self.axes.iter_mut().zip(path.start()) {
                        a.position = *p;
                    }
                    self.path_goal(path)
                } else {
                    Goal::StopThen(path)
                }
            }
            Goal::Path { path, u, limits } => {
                let end = (path.len() - 1) as f64;
                let u = track(u, end, limits, dt);
                let q = path.at(u.position);
                for (a, p) in self.axes.iter_mut().zip(&q) {
                    a.velocity = (p - a.position) / dt;
                    a.position = *p;
                }
                if u.position == end && u.velocity == 0.0 {
                    for a in &mut self.axes {
                        a.velocity = 0.0;
                    }
                    Goal::Rest
                } else {
                    Goal::Path { path, u, limits }
                }
            }
        };
        Some(self.position())
    }
}

/// One period of braking as hard as allowed.
fn brake(a: AxisState, l: AxisLimits, dt: f64) -> AxisState {
    let dv = l.max_acceleration * dt;
    let velocity = if a.velocity.abs() <= dv {
        0.0
    } else {
        a.velocity - dv * a.velocity.signum()
    };
    AxisState {
        position: a.position + velocity * dt,
        velocity,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT: f64 = 0.02;

    fn limits() -> Vec<AxisLimits> {
        vec![
            AxisLimits::new(2.6, 10.0).unwrap(),
            AxisLimits::new(5.2, 21.0).unwrap(),
            AxisLimits::new(5.2, 21.0).unwrap(),
        ]
    }

    /// Every position the planner passes through until it rests, the start included.
    fn trace(p: &mut Planner) -> Vec<Vec<f64>> {
        let mut out = vec![p.position()];
        while let Some(q) = p.step() {
            out.push(q);
            assert!(out.len() < 100_000, "never settles");
        }
        out
    }

    /// Velocities and accelerations of a trace are within the limits (with the
    /// velocity at rest before it).
    fn check_limits(tr: &[Vec<f64>], l: &[AxisLimits], v0: &[f64]) -> Result<(), String> {
        let mut prev_v = v0.to_vec();
        for w in tr.windows(2) {
            for i in 0..l.len() {
                let v = (w[1][i] - w[0][i]) / DT;
                let a = (v - prev_v[i]) / DT;
                if v.abs() > l[i].max_velocity * (1.0 + 1e-9) + 1e-12 {
                    return Err(format!("axis {i} velocity {v} > {}", l[i].max_velocity));
                }
                if a.abs() > l[i].max_acceleration * (1.0 + 1e-6) + 1e-9 {
                    return Err(format!(
                        "axis {i} acceleration {a} > {}",
                        l[i].max_acceleration
                    ));
                }
                prev_v[i] = v;
            }
        }
        Ok(())
    }

    proptest! {
        // A move from rest: within every axis' limits, on a straight line in joint
        // space, and every axis arrives in the same step.
        #[test]
        fn a_move_from_rest_is_synchronised_and_within_limits(
            start in proptest::collection::vec(-1.0..1.0f64, 3),
            target in proptest::collection::vec(-1.0..1.0f64, 3),
        ) {
            let mut p = Planner::new(limits(), &start, DT).unwrap();
            p.move_to(&target).unwrap();
            let tr = trace(&mut p);
            prop_assert_eq!(tr.last().unwrap(), &target);
            check_limits(&tr, &limits(), &[0.0; 3]).map_err(TestCaseError::fail)?;
            let d: Vec<f64> = (0..3).map(|i| target[i] - start[i]).collect();
            let lead = (0..3).max_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs())).unwrap();
            prop_assume!(d[lead] != 0.0);
            for q in &tr {
                let s = (q[lead] - start[lead]) / d[lead];
                for i in 0..3 {
                    prop_assert!((q[i] - (start[i] + s * d[i])).abs() < 1e-9, "off the line: {q:?}");
                }
            }
        }

        // A new goal in the middle of a move: re-planned from the current position and
        // velocity, never beyond the limits, and it gets there.
        #[test]
        fn replanning_mid_move_keeps_the_limits(
            target1 in proptest::collection::vec(-1.0..1.0f64, 3),
            target2 in proptest::collection::vec(-1.0..1.0f64, 3),
            after in 1usize..40,
        ) {
            let mut p = Planner::new(limits(), &[0.0; 3], DT).unwrap();
            p.move_to(&target1).unwrap();
            let mut tr = vec![p.position()];
            for _ in 0..after {
                if let Some(q) = p.step() { tr.push(q) }
            }
            p.move_to(&target2).unwrap();
            tr.extend(trace(&mut p).into_iter().skip(1));
            check_limits(&tr, &limits(), &[0.0; 3]).map_err(TestCaseError::fail)?;
            prop_assert_eq!(tr.last().unwrap(), &target2);
        }
    }

    #[test]
    fn a_path_is_followed_within_the_limits_from_rest_and_after_braking() {
        // a curved path: a quarter circle in the first two axes
        let pts: Vec<Vec<f64>> = (0..=200)
            .map(|k| {
                let t = f64::from(k) / 200.0 * std::f64::consts::FRAC_PI_2;
                vec![t.cos() - 1.0, t.sin(), 0.3 * t]
            })
            .collect();
        let path = JointPath::new(pts).unwrap();
        let mut p = Planner::new(limits(), &[0.0; 3], DT).unwrap();
        p.follow(path.clone()).unwrap();
        let tr = trace(&mut p);
        check_limits(&tr, &limits(), &[0.0; 3]).unwrap();
        assert_eq!(tr.last().unwrap(), path.end());

        // moving when the path is given: it must start where the axes stop
        let mut p = Planner::new(limits(), &[0.0; 3], DT).unwrap();
        p.move_to(&[1.0, 1.0, 1.0]).unwrap();
        let mut tr = vec![p.position()];
        for _ in 0..10 {
            tr.push(p.step().unwrap());
        }
        assert!(matches!(
            p.follow(path.clone()),
            Err(MotionError::PathStartMismatch { .. })
        ));
        let stop = p.stopping_position();
        let shifted: Vec<Vec<f64>> = path
            .points()
            .iter()
            .map(|q| q.iter().zip(&stop).map(|(a, b)| a + b).collect())
            .collect();
        p.follow(JointPath::new(shifted.clone()).unwrap()).unwrap();
        tr.extend(trace(&mut p).into_iter().skip(1));
        check_limits(&tr, &limits(), &[0.0; 3]).unwrap();
        assert_eq!(tr.last().unwrap(), shifted.last().unwrap());
    }

    #[test]
    fn stop_freezes_and_the_next_move_starts_from_rest_there() {
        let mut p = Planner::new(limits(), &[0.0; 3], DT).unwrap();
        p.move_to(&[1.0, 1.0, 1.0]).unwrap();
        for _ in 0..10 {
            p.step();
        }
        let here = p.position();
        p.stop();
        assert_eq!(p.step(), None);
        assert_eq!(p.position(), here);
        assert_eq!(p.velocity(), vec![0.0; 3]);
        p.move_to(&[0.0; 3]).unwrap();
        let first = p.step().unwrap();
        for i in 0..3 {
            assert!((first[i] - here[i]).abs() <= limits()[i].max_acceleration * DT * DT + 1e-12);
        }
    }

    #[test]
    fn bad_goals_are_refused_and_change_nothing() {
        let mut p = Planner::new(limits(), &[0.0; 3], DT).unwrap();
        assert!(matches!(
            p.move_to(&[0.0, f64::NAN, 0.0]),
            Err(MotionError::NonFinite { axis: 1, .. })
        ));
        assert!(matches!(
            p.move_to(&[0.0; 2]),
            Err(MotionError::WrongAxisCount {
                expected: 3,
                got: 2
            })
        ));
        assert!(!p.is_moving());
        assert!(Planner::new(limits(), &[0.0; 3], 0.0).is_err());
    }
}
