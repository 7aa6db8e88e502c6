//! `arm_controller` and `gripper_controller`, as ros2_controllers'
//! joint_trajectory_controller and gripper_action_controller offer them, free of ROS
//! I/O: a trajectory is checked whole before anything moves ([`plan`]: the joints, the
//! points, the times, and every segment against the motion limits of the servos), then
//! sampled at the node's motion rate ([`Execution::tick`]); "actual" is what the
//! Arduino reported it applied (`servo_state`), compared for the path tolerance with
//! what was commanded for the same instant (the reply carries the command's stamp), and
//! for the goal tolerance with the last point.

use eezybot_motion::{AxisLimits, Trajectory, TrajectoryError, Waypoint};
use eezybot_msgs::builtin_interfaces::Duration;
use eezybot_msgs::control_msgs::{FollowJointTrajectoryResult as Fjt, JointTolerance};
use eezybot_msgs::trajectory_msgs::{JointTrajectory, JointTrajectoryPoint};
use nalgebra::{DMatrix, DVector};

/// How the controller's joints drive the planner's axes.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerMap {
    /// arm_controller's joints, in its order.
    pub joints: Vec<String>,
    /// The planner axes they drive, in the same order.
    pub axes: Vec<usize>,
    /// What each of those axes is, for messages ("the elbow servo (forearm elevation,
    /// shoulder_joint + elbow_joint)").
    pub axis_names: Vec<String>,
    /// axes = `to_axes` · joints (a linear map, invertible).
    pub to_axes: DMatrix<f64>,
    /// gripper_controller's joint, if any.
    pub gripper: Option<GripperMap>,
}

/// How gripper_controller's joint drives its planner axis.
#[derive(Clone, Debug, PartialEq)]
pub struct GripperMap {
    /// The joint (`gripper_joint`).
    pub joint: String,
    /// Its planner axis.
    pub axis: usize,
    /// The joint's angle (rad) per unit of the axis (the opening 0 … 1).
    pub rad_per_unit: f64,
}

impl ControllerMap {
    /// Joint values (controller order) of the arm axes' values (the same order).
    pub fn joints_of(&self, axes: &[f64]) -> Vec<f64> {
        let inv = self
            .to_axes
            .clone()
            .try_inverse()
            .unwrap_or_else(|| DMatrix::identity(axes.len(), axes.len()));
        (inv * DVector::from_column_slice(axes))
            .iter()
            .copied()
            .collect()
    }

    /// The arm axes' values of joint values (controller order).
    pub fn axes_of(&self, joints: &[f64]) -> Vec<f64> {
        (&self.to_axes * DVector::from_column_slice(joints))
            .iter()
            .copied()
            .collect()
    }
}

/// The defaults a goal's zero tolerances stand for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerSettings {
    /// Largest error (rad) while moving; 0 = not checked.
    pub path_tolerance: f64,
    /// Largest error (rad) at the end; 0 = not checked.
    pub goal_tolerance: f64,
    /// How long after the last point the goal tolerance may be met (s).
    pub goal_time: f64,
}

impl Default for ControllerSettings {
    fn default() -> Self {
        ControllerSettings {
            path_tolerance: 0.0,
            goal_tolerance: 0.05,
            goal_time: 1.0,
        }
    }
}

/// How close (rad) a first point at 0 s must be to where the arm is.
pub const START_MATCH_RAD: f64 = 0.01;

/// A trajectory of only its start point holds it this long (s).
const HOLD_S: f64 = 0.001;

/// A goal refused before anything moved: the FollowJointTrajectory error code and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Refusal {
    /// [`Fjt`]'s `INVALID_GOAL`, `INVALID_JOINTS` or `OLD_HEADER_TIMESTAMP`.
    pub code: i32,
    /// Why, naming the joint, point and limit.
    pub text: String,
}

impl Refusal {
    fn new(code: i32, text: impl Into<String>) -> Refusal {
        Refusal {
            code,
            text: text.into(),
        }
    }
}

/// A checked trajectory, ready to run.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The arm axes' trajectory, from where they were at rest.
    pub trajectory: Trajectory,
    /// Per controller joint: the path tolerance (rad), `None` = not checked.
    pub path_tolerance: Vec<Option<f64>>,
    /// Per controller joint: the goal tolerance (rad), `None` = not checked.
    pub goal_tolerance: Vec<Option<f64>>,
    /// How long after the last point the goal tolerance may be met (s).
    pub goal_time: f64,
    /// When it starts (s, on the stamps' clock).
    pub start_s: f64,
    /// How late the stamp was (s): the trajectory starts now instead, in full.
    pub late_s: f64,
}

/// Check a trajectory for the controller: every controller joint named once and no
/// other, at least one point, the sizes, the times, each point's positions (`check`:
/// the arm's joint limits and servo ranges, given joint values in controller order)
/// and every segment against the arm axes' `limits`, starting at rest from
/// `start_axes`. `now_s`: now, on the stamps' clock.
#[allow(clippy::too_many_arguments)]
pub fn plan(
    map: &ControllerMap,
    limits: &[AxisLimits],
    start_axes: &[f64],
    msg: &JointTrajectory,
    path_tolerance: &[JointTolerance],
    goal_tolerance: &[JointTolerance],
    goal_time: Duration,
    settings: &ControllerSettings,
    now_s: f64,
    check: impl Fn(&[f64]) -> Result<(), String>,
) -> Result<Plan, Refusal> {
    let n = map.joints.len();
    // where each controller joint is in the message
    let mut order = vec![usize::MAX; n];
    for (k, name) in msg.joint_names.iter().enumerate() {
        let Some(j) = map.joints.iter().position(|c| c == name) else {
            return Err(Refusal::new(
                Fjt::INVALID_JOINTS,
                format!(
                    "joint `{}` is not one of arm_controller's joints ({})",
                    shorten(name),
                    map.joints.join(", ")
                ),
            ));
        };
        if order[j] != usize::MAX {
            return Err(Refusal::new(
                Fjt::INVALID_JOINTS,
                format!("joint `{name}` is named twice"),
            ));
        }
        order[j] = k;
    }
    if let Some(j) = order.iter().position(|k| *k == usize::MAX) {
        return Err(Refusal::new(
            Fjt::INVALID_JOINTS,
            format!(
                "joint `{}` is missing: a trajectory gives every joint of arm_controller ({})",
                map.joints[j],
                map.joints.join(", ")
            ),
        ));
    }
    if msg.points.is_empty() {
        return Err(Refusal::new(
            Fjt::INVALID_GOAL,
            "the trajectory has no points",
        ));
    }
    let mut waypoints = Vec::with_capacity(msg.points.len());
    let mut previous = 0.0;
    for (i, p) in msg.points.iter().enumerate() {
        let point = i + 1;
        let sized = |field: &str, v: &[f64], may_be_empty: bool| {
            if v.len() == n || (may_be_empty && v.is_empty()) {
                Ok(())
            } else {
                Err(Refusal::new(
                    Fjt::INVALID_GOAL,
                    format!(
                        "point {point}: {field} has {} values for {n} joints",
                        v.len()
                    ),
                ))
            }
        };
        sized("positions", &p.positions, false)?;
        sized("velocities", &p.velocities, true)?;
        sized("accelerations", &p.accelerations, true)?;
        let time = p.time_from_start.as_secs_f64();
        let positions: Vec<f64> = order.iter().map(|&k| p.positions[k]).collect();
        if i == 0 && time == 0.0 {
            // MoveIt's first point is the start state, at 0 s: skipped when the arm is
            // there, refused when it is not (reaching it would take no time)
            let here = map.joints_of(start_axes);
            if let Some(j) = (0..n).find(|&j| (positions[j] - here[j]).abs() > START_MATCH_RAD) {
                return Err(Refusal::new(
                    Fjt::INVALID_GOAL,
                    format!(
                        "point 1 is at 0 s but {} is {:.3} rad from it (the start must be where the arm is, within {START_MATCH_RAD} rad)",
                        map.joints[j],
                        (positions[j] - here[j]).abs()
                    ),
                ));
            }
            continue;
        }
        if p.time_from_start.nanosec >= 1_000_000_000 || time <= previous {
            return Err(Refusal::new(
                Fjt::INVALID_GOAL,
                format!(
                    "point {point}: time_from_start {time:.3} s is not after the previous point's {previous:.3} s"
                ),
            ));
        }
        previous = time;
        if let Some(j) = positions.iter().position(|v| !v.is_finite()) {
            return Err(Refusal::new(
                Fjt::INVALID_GOAL,
                format!(
                    "point {point}: {} position is {}",
                    map.joints[j], positions[j]
                ),
            ));
        }
        check(&positions)
            .map_err(|why| Refusal::new(Fjt::INVALID_GOAL, format!("point {point}: {why}")))?;
        let velocities = (!p.velocities.is_empty()).then(|| {
            let v: Vec<f64> = order.iter().map(|&k| p.velocities[k]).collect();
            map.axes_of(&v)
        });
        waypoints.push(Waypoint {
            time_from_start: time,
            positions: map.axes_of(&positions),
            velocities,
        });
    }
    if waypoints.is_empty() {
        // only the start: hold it
        waypoints.push(Waypoint {
            time_from_start: HOLD_S,
            positions: start_axes.to_vec(),
            velocities: None,
        });
    }
    let trajectory = Trajectory::new(start_axes, waypoints, limits).map_err(|e| match e {
        TrajectoryError::OverLimit {
            joint,
            limit,
            needed,
            max,
            from,
            to,
        } => Refusal::new(
            Fjt::INVALID_GOAL,
            format!(
                "{} would need {needed:.3} {unit} between {from} and point {to}, over its {limit} limit of {max:.3} {unit} (config/arm.yaml motion): the trajectory is refused, not slowed down",
                map.axis_names.get(joint).map_or("an axis", String::as_str),
                unit = if limit == "velocity" { "rad/s" } else { "rad/s²" },
            ),
        ),
        e => Refusal::new(Fjt::INVALID_GOAL, e.to_string()),
    })?;
    let tolerances = |given: &[JointTolerance], default: f64, what: &str| {
        let mut out = vec![(default > 0.0).then_some(default); n];
        for t in given {
            let Some(j) = map.joints.iter().position(|c| *c == t.name) else {
                return Err(Refusal::new(
                    Fjt::INVALID_JOINTS,
                    format!(
                        "{what} names joint `{}`, not one of arm_controller's",
                        shorten(&t.name)
                    ),
                ));
            };
            if t.position.is_nan() {
                return Err(Refusal::new(
                    Fjt::INVALID_GOAL,
                    format!("{what} of {} is NaN", t.name),
                ));
            }
            out[j] = match t.position {
                p if p > 0.0 => Some(p),
                p if p < 0.0 => None,
                _ => out[j],
            };
        }
        Ok(out)
    };
    let path_tolerance = tolerances(path_tolerance, settings.path_tolerance, "path_tolerance")?;
    let goal_tolerance = tolerances(goal_tolerance, settings.goal_tolerance, "goal_tolerance")?;
    let goal_time = match goal_time.as_secs_f64() {
        t if t > 0.0 => t,
        _ => settings.goal_time,
    };
    let stamp_s = msg.header.stamp.to_nanos() as f64 * 1e-9;
    let start = if msg.header.stamp.to_nanos() == 0 {
        now_s
    } else {
        stamp_s
    };
    if start + trajectory.duration() < now_s {
        return Err(Refusal::new(
            Fjt::OLD_HEADER_TIMESTAMP,
            format!(
                "the trajectory ended {:.3} s ago (header.stamp {stamp_s:.3} + {:.3} s)",
                now_s - start - trajectory.duration(),
                trajectory.duration()
            ),
        ));
    }
    Ok(Plan {
        trajectory,
        path_tolerance,
        goal_tolerance,
        goal_time,
        start_s: start.max(now_s),
        late_s: (now_s - start).max(0.0),
    })
}

fn shorten(s: &str) -> String {
    ros_plumbing::logging::shorten(s, ros_plumbing::logging::NAME_MAX).to_string()
}

/// How a trajectory ended.
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    /// It reached the last point within the goal tolerance.
    pub succeeded: bool,
    /// The FollowJointTrajectory error code.
    pub code: i32,
    /// Why, in words (empty on success).
    pub text: String,
}

/// What the joints reported: positions in controller order, and the stamp of the
/// command they answer (s).
#[derive(Clone, Debug, PartialEq)]
pub struct Actual {
    /// Positions (rad), controller order.
    pub positions: Vec<f64>,
    /// The stamp the reply carried (s).
    pub stamp_s: f64,
}

/// One step of a running trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Tick {
    /// The arm axes to command now.
    pub axes: Vec<f64>,
    /// Where the trajectory wants the joints now (controller order).
    pub desired: JointTrajectoryPoint,
    /// The point being moved to (0-based index into the message's points).
    pub index: i32,
    /// The end, if it came.
    pub outcome: Option<Outcome>,
}

/// A trajectory running.
#[derive(Clone, Debug)]
pub struct Execution {
    plan: Plan,
    map: ControllerMap,
}

impl Execution {
    /// Run `plan` for the joints of `map`.
    pub fn new(plan: Plan, map: ControllerMap) -> Execution {
        Execution { plan, map }
    }

    /// The plan.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The desired joint point at time `t` (s) from the start.
    pub fn desired_at(&self, t: f64) -> (Vec<f64>, JointTrajectoryPoint) {
        let s = self.plan.trajectory.sample(t);
        let point = JointTrajectoryPoint {
            positions: self.map.joints_of(&s.positions),
            velocities: self.map.joints_of(&s.velocities),
            accelerations: self.map.joints_of(&s.accelerations),
            effort: vec![],
            time_from_start: Duration::from_secs_f64(t.clamp(0.0, self.plan.trajectory.duration())),
        };
        (s.positions, point)
    }

    /// The step at `now_s`, judged against the latest report `actual`.
    pub fn tick(&self, now_s: f64, actual: Option<&Actual>) -> Tick {
        let t = now_s - self.plan.start_s;
        let (axes, desired) = self.desired_at(t);
        let times = self.plan.trajectory.point_times();
        let index = times.partition_point(|&x| x <= t).min(times.len() - 1) as i32;
        let outcome = self.judge(t, actual);
        Tick {
            axes,
            desired,
            index,
            outcome,
        }
    }

    fn judge(&self, t: f64, actual: Option<&Actual>) -> Option<Outcome> {
        let duration = self.plan.trajectory.duration();
        if let Some(a) = actual {
            // the path: the reply against what was commanded for its own instant
            let ta = a.stamp_s - self.plan.start_s;
            if (0.0..duration).contains(&ta) {
                let (_, at) = self.desired_at(ta);
                for (j, tol) in self.plan.path_tolerance.iter().enumerate() {
                    let Some(tol) = tol else { continue };
                    let off = (at.positions[j] - a.positions[j]).abs();
                    if off > *tol {
                        return Some(Outcome {
                            succeeded: false,
                            code: Fjt::PATH_TOLERANCE_VIOLATED,
                            text: format!(
                                "{} was {off:.3} rad from the trajectory at {ta:.3} s (path tolerance {tol:.3} rad): the servo is blocked or lagging",
                                self.map.joints[j]
                            ),
                        });
                    }
                }
            }
        }
        if t < duration {
            return None;
        }
        let last = self
            .map
            .joints_of(&self.plan.trajectory.sample(duration).positions);
        let miss = |a: &Actual| {
            self.plan
                .goal_tolerance
                .iter()
                .enumerate()
                .filter_map(|(j, tol)| tol.map(|tol| (j, tol, (last[j] - a.positions[j]).abs())))
                .find(|(_, tol, off)| off > tol)
        };
        let checked = self.plan.goal_tolerance.iter().any(Option::is_some);
        match actual {
            _ if !checked => Some(Outcome {
                succeeded: true,
                code: Fjt::SUCCESSFUL,
                text: String::new(),
            }),
            Some(a) if miss(a).is_none() => Some(Outcome {
                succeeded: true,
                code: Fjt::SUCCESSFUL,
                text: String::new(),
            }),
            _ if t < duration + self.plan.goal_time => None,
            None => Some(Outcome {
                succeeded: false,
                code: Fjt::GOAL_TOLERANCE_VIOLATED,
                text: format!(
                    "no servo_state came within goal_time_tolerance {:.3} s of the end: is serial_node running?",
                    self.plan.goal_time
                ),
            }),
            Some(a) => {
                let (j, tol, off) = miss(a).unwrap_or((0, 0.0, 0.0));
                Some(Outcome {
                    succeeded: false,
                    code: Fjt::GOAL_TOLERANCE_VIOLATED,
                    text: format!(
                        "{} is {off:.3} rad from the last point {:.3} s after the end (goal tolerance {tol:.3} rad)",
                        self.map.joints[j], self.plan.goal_time
                    ),
                })
            }
        }
    }
}

/// The FollowJointTrajectory result of an outcome.
pub fn result_of(outcome: &Outcome) -> Fjt {
    Fjt {
        error_code: outcome.code,
        error_string: outcome.text.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_msgs::Time;

    /// The EezyBot's map: the elbow servo sets shoulder + elbow.
    fn map() -> ControllerMap {
        ControllerMap {
            joints: vec![
                "base_joint".into(),
                "shoulder_joint".into(),
                "elbow_joint".into(),
            ],
            axes: vec![0, 1, 2],
            axis_names: vec!["base".into(), "shoulder".into(), "elbow servo".into()],
            to_axes: DMatrix::from_row_slice(3, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0]),
            gripper: None,
        }
    }

    fn limits() -> Vec<AxisLimits> {
        vec![AxisLimits::new(2.0, 10.0).unwrap(); 3]
    }

    fn point(p: [f64; 3], t: f64) -> JointTrajectoryPoint {
        JointTrajectoryPoint {
            positions: p.to_vec(),
            time_from_start: Duration::from_secs_f64(t),
            ..Default::default()
        }
    }

    fn traj(names: &[&str], points: Vec<JointTrajectoryPoint>) -> JointTrajectory {
        JointTrajectory {
            joint_names: names.iter().map(|s| s.to_string()).collect(),
            points,
            ..Default::default()
        }
    }

    const NAMES: [&str; 3] = ["base_joint", "shoulder_joint", "elbow_joint"];

    fn plan_of(msg: &JointTrajectory) -> Result<Plan, Refusal> {
        plan(
            &map(),
            &limits(),
            &[0.0, 1.0, 0.5],
            msg,
            &[],
            &[],
            Duration::default(),
            &ControllerSettings::default(),
            100.0,
            |_| Ok(()),
        )
    }

    #[test]
    fn joints_are_reordered_and_mapped_to_the_axes() {
        let msg = traj(
            &["elbow_joint", "base_joint", "shoulder_joint"],
            vec![point([-0.4, 0.1, 1.1], 1.0)],
        );
        let p = plan_of(&msg).unwrap();
        let end = p.trajectory.sample(1.0).positions;
        let want = [0.1, 1.1, 0.7];
        assert!(
            end.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12),
            "{end:?}"
        );
        let e = Execution::new(p, map());
        let (_, d) = e.desired_at(1.0);
        assert!((d.positions[2] + 0.4).abs() < 1e-12);
    }

    #[test]
    fn a_first_point_at_zero_seconds_where_the_arm_is_is_the_start() {
        let msg = traj(
            &NAMES,
            vec![point([0.0, 1.0, -0.5], 0.0), point([0.2, 1.0, -0.5], 1.0)],
        );
        let p = plan_of(&msg).unwrap();
        assert_eq!(p.trajectory.point_times(), &[1.0]);
        let only = traj(&NAMES, vec![point([0.0, 1.0, -0.5], 0.0)]);
        assert!(plan_of(&only).unwrap().trajectory.duration() < 0.01);
    }

    #[test]
    fn wrong_joint_sets_are_refused_as_invalid_joints() {
        for names in [
            &["base_joint", "shoulder_joint"][..],
            &["base_joint", "shoulder_joint", "wrist_joint"],
            &["base_joint", "base_joint", "elbow_joint"],
        ] {
            let msg = traj(names, vec![point([0.0, 1.0, -0.5], 1.0)]);
            assert_eq!(
                plan_of(&msg).unwrap_err().code,
                Fjt::INVALID_JOINTS,
                "{names:?}"
            );
        }
    }

    #[test]
    fn a_too_fast_segment_is_refused_naming_the_axis_and_limit() {
        let msg = traj(
            &NAMES,
            vec![point([0.0, 1.0, -0.5], 0.5), point([0.0, 1.0, 0.5], 0.6)],
        );
        let r = plan_of(&msg).unwrap_err();
        assert_eq!(r.code, Fjt::INVALID_GOAL);
        assert!(
            r.text.contains("elbow servo") && r.text.contains("limit"),
            "{}",
            r.text
        );
    }

    #[test]
    fn bad_points_and_times_are_refused() {
        let mut short = point([0.0, 1.0, -0.5], 1.0);
        short.positions.pop();
        let mut nan = point([0.0, 1.0, -0.5], 1.0);
        nan.positions[1] = f64::NAN;
        let away = point([0.3, 1.0, -0.5], 0.0);
        for pts in [
            vec![],
            vec![short],
            vec![nan],
            vec![point([0.0, 1.0, -0.5], 1.0), point([0.0, 1.0, -0.5], 1.0)],
            vec![away],
        ] {
            assert_eq!(
                plan_of(&traj(&NAMES, pts)).unwrap_err().code,
                Fjt::INVALID_GOAL
            );
        }
        let mut old = traj(&NAMES, vec![point([0.0, 1.0, -0.5], 1.0)]);
        old.header.stamp = Time::from_nanos(50_000_000_000);
        assert_eq!(plan_of(&old).unwrap_err().code, Fjt::OLD_HEADER_TIMESTAMP);
        let limit = plan(
            &map(),
            &limits(),
            &[0.0, 1.0, 0.5],
            &traj(&NAMES, vec![point([0.0, 1.0, -0.5], 1.0)]),
            &[],
            &[],
            Duration::default(),
            &ControllerSettings::default(),
            100.0,
            |_| Err("elbow_joint out of its limits".into()),
        );
        assert!(limit.unwrap_err().text.contains("point 1: elbow_joint"));
    }

    fn actual(p: Vec<f64>, s: f64) -> Actual {
        Actual {
            positions: p,
            stamp_s: s,
        }
    }

    #[test]
    fn a_blocked_joint_violates_the_path_tolerance_judged_at_the_replys_stamp() {
        let msg = traj(&NAMES, vec![point([0.0, 1.0, 0.5], 2.0)]);
        let path = [JointTolerance {
            name: "elbow_joint".into(),
            position: 0.1,
            ..Default::default()
        }];
        let p = plan(
            &map(),
            &limits(),
            &[0.0, 1.0, 0.5],
            &msg,
            &path,
            &[],
            Duration::default(),
            &ControllerSettings::default(),
            100.0,
            |_| Ok(()),
        )
        .unwrap();
        let e = Execution::new(p, map());
        // a late reply that matches what was commanded for its own stamp is fine
        let (_, at) = e.desired_at(0.5);
        assert!(e
            .tick(101.0, Some(&actual(at.positions.clone(), 100.5)))
            .outcome
            .is_none());
        // the elbow stuck at its start while the command moved on
        let out = e
            .tick(101.0, Some(&actual(vec![0.0, 1.0, -0.5], 100.9)))
            .outcome
            .unwrap();
        assert_eq!(out.code, Fjt::PATH_TOLERANCE_VIOLATED);
        assert!(out.text.contains("elbow_joint"), "{}", out.text);
    }

    #[test]
    fn the_end_succeeds_within_the_goal_tolerance_and_aborts_after_the_goal_time() {
        let msg = traj(&NAMES, vec![point([0.0, 1.0, 0.0], 1.0)]);
        let e = Execution::new(plan_of(&msg).unwrap(), map());
        let end = vec![0.0, 1.0, 0.0];
        assert!(e
            .tick(100.5, Some(&actual(end.clone(), 100.5)))
            .outcome
            .is_none());
        let done = e.tick(101.0, Some(&actual(end, 101.0))).outcome.unwrap();
        assert!(done.succeeded);
        let off = vec![0.0, 1.0, -0.2];
        assert!(e
            .tick(101.5, Some(&actual(off.clone(), 101.5)))
            .outcome
            .is_none());
        let late = e.tick(102.1, Some(&actual(off, 102.0))).outcome.unwrap();
        assert_eq!(late.code, Fjt::GOAL_TOLERANCE_VIOLATED);
        assert_eq!(
            e.tick(102.1, None).outcome.unwrap().code,
            Fjt::GOAL_TOLERANCE_VIOLATED
        );
    }

    #[test]
    fn the_trajectory_ends_exactly_at_the_last_point() {
        let msg = traj(
            &NAMES,
            vec![point([0.2, 1.1, -0.3], 0.8), point([0.3, 1.2, -0.2], 1.6)],
        );
        let e = Execution::new(plan_of(&msg).unwrap(), map());
        let t = e.tick(150.0, None);
        let want = [0.3, 1.2, -0.2];
        assert!(t
            .desired
            .positions
            .iter()
            .zip(want)
            .all(|(a, b)| (a - b).abs() < 1e-12));
        assert!(t.outcome.is_some());
        assert_eq!(t.index, 1);
    }
}
