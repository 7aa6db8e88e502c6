//! arm_controller: a trajectory (a FollowJointTrajectory goal, or a sample on
//! `arm_controller/joint_trajectory`) checked against the arm and against who holds
//! it, run a step a period, judged against `servo_state`, and ended; its feedback
//! and `arm_controller/controller_state`.

use super::{code_name, seconds, Driver, Effect};
use crate::controller::{self, Actual, ControllerMap, Execution, Outcome};
use crate::pipeline::{ArmModel, GoalRequest};
use arbiter::{Command, Controller};
use eezybot_motion::track;
use eezybot_motion::AxisState;
use eezybot_msgs::control_msgs::{
    FollowJointTrajectoryFeedback, FollowJointTrajectoryGoal, FollowJointTrajectoryResult as Fjt,
    JointTrajectoryControllerState,
};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::trajectory_msgs::{JointTrajectory, JointTrajectoryPoint};
use eezybot_msgs::Time;
use ros_plumbing::action::{GoalEnd, GoalId};
use std::time::Instant;

/// Who sent the running trajectory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Owner {
    /// a FollowJointTrajectory goal
    Action(GoalId),
    /// `arm_controller/joint_trajectory`
    Topic,
}

/// The running trajectory.
#[derive(Debug)]
pub(super) struct ArmRun {
    exec: Execution,
    owner: Owner,
    /// its last step, for controller_state
    last: Option<controller::Tick>,
}

/// How far ahead of its time (in motion periods) each trajectory step is sampled.
pub const TRAJECTORY_LEAD_PERIODS: f64 = 0.5;

/// Without a `servo_state` for this long (s), controller_state comes at the peer polls.
pub const CONTROLLER_STATE_QUIET_S: f64 = 0.5;

impl<M: ArmModel> Driver<M> {
    /// What `diagnostics` says of `arm_controller`: idle, or the trajectory it runs.
    pub(super) fn arm_controller_summary(&self) -> String {
        match &self.arm {
            None => "idle".to_string(),
            Some(r) => format!(
                "executing a trajectory of {:.3} s from {}",
                r.exec.plan().trajectory.duration(),
                match r.owner {
                    Owner::Action(_) => "follow_joint_trajectory",
                    Owner::Topic => "joint_trajectory",
                }
            ),
        }
    }

    /// Check a trajectory against the arm as it is now, and against who holds it.
    fn plan(
        &self,
        msg: &JointTrajectory,
        goal: Option<&FollowJointTrajectoryGoal>,
        wall: Time,
        now: Instant,
    ) -> Result<controller::Plan, controller::Refusal> {
        let map = self.may_plan(goal, now)?;
        let axes = self.core.axes();
        let limits = self.core.axis_limits();
        let start: Vec<f64> = map.axes.iter().map(|&a| axes[a]).collect();
        let arm_limits: Vec<_> = map.axes.iter().map(|&a| limits[a]).collect();
        let (path, goal_tol, goal_time) = match goal {
            Some(g) => (
                &g.path_tolerance[..],
                &g.goal_tolerance[..],
                g.goal_time_tolerance,
            ),
            None => (&[][..], &[][..], Default::default()),
        };
        controller::plan(
            map,
            &arm_limits,
            &start,
            msg,
            path,
            goal_tol,
            goal_time,
            &self.settings,
            seconds(wall),
            |q| {
                self.core
                    .check_joints(&map.joints, q)
                    .map_err(|r| r.to_string())
            },
        )
    }

    /// Whether a trajectory may be planned now, before its points are looked at: the
    /// arm has a trajectory controller (its map, returned), nothing halts the core,
    /// the arbiter would let `arm_controller` have the arm, and a goal names no
    /// multi-DOF joints.
    fn may_plan(
        &self,
        goal: Option<&FollowJointTrajectoryGoal>,
        now: Instant,
    ) -> Result<&ControllerMap, controller::Refusal> {
        let Some(map) = &self.map else {
            return Err(controller::Refusal {
                code: Fjt::INVALID_JOINTS,
                text: "this arm has no trajectory controller (the EezyBot only)".into(),
            });
        };
        if let Some(why) = self.core.halted() {
            return Err(controller::Refusal {
                code: Fjt::INVALID_GOAL,
                text: why.to_string(),
            });
        }
        if let Err(why) = self.may(Command::Trajectory, now) {
            return Err(controller::Refusal {
                code: Fjt::INVALID_GOAL,
                text: why.to_string(),
            });
        }
        if let Some(g) = goal {
            if !g.multi_dof_trajectory.points.is_empty()
                || !g.multi_dof_trajectory.joint_names.is_empty()
            {
                return Err(controller::Refusal {
                    code: Fjt::INVALID_JOINTS,
                    text: "multi_dof_trajectory: this arm has no multi-DOF joints".into(),
                });
            }
        }
        Ok(map)
    }

    /// A checked trajectory runs (a running one preempted, the arm taken from whoever
    /// held it): its first step at once, then one a period.
    pub(super) fn start_arm(
        &mut self,
        mut plan: controller::Plan,
        owner: Owner,
        wall: Time,
        now: Instant,
        effects: &mut Vec<Effect>,
    ) {
        let Some(map) = self.map.clone() else { return };
        // Steps come once a period: each is sampled half a period ahead of its time, so
        // the steps straddle every instant of the trajectory (within half a period's
        // motion of it, early or late, rather than up to a whole period late), and the
        // first step, at once, already moves.
        plan.start_s -= TRAJECTORY_LEAD_PERIODS * self.step_period().as_secs_f64();
        if plan.late_s > 0.0 {
            log::info!(
                "trajectory: header.stamp {:.3} s in the past, started now in full",
                plan.late_s
            );
        }
        self.end_arm(
            GoalEnd::Canceled,
            Fjt::INVALID_GOAL,
            "preempted by a newer trajectory".into(),
            effects,
        );
        self.take(Command::Trajectory, "arm_controller", now, wall, effects);
        self.core.stop_motion();
        // a gripper goal under way goes on from where the core's planner moved the claw
        // (tracked from here on beside the trajectory), not from where it started
        if let (Some(g), Some(gm)) = (
            &mut self.gripper,
            self.map.as_ref().and_then(|m| m.gripper.as_ref()),
        ) {
            g.motion = AxisState {
                position: self.core.axes()[gm.axis],
                velocity: 0.0,
            };
        }
        self.last_trajectory = Some(format!(
            "executing: {} points over {:.3} s",
            plan.trajectory.point_times().len(),
            plan.trajectory.duration()
        ));
        self.arm = Some(ArmRun {
            exec: Execution::new(plan, map),
            owner,
            last: None,
        });
        // the first step at once, then one per period
        self.tick_arm(wall, effects);
        self.next_step = Some(now + self.step_period());
    }

    /// An `arm_controller/joint_trajectory` sample: an empty one stops the arm where it
    /// is; any other runs if it is accepted, else it is refused.
    pub(super) fn on_trajectory(
        &mut self,
        msg: JointTrajectory,
        wall: Time,
        now: Instant,
        effects: &mut Vec<Effect>,
    ) {
        if msg.points.is_empty() {
            // ros2_controllers: an empty trajectory stops the arm where it is
            if self.arm.is_some() {
                self.end_arm(
                    GoalEnd::Aborted,
                    Fjt::INVALID_GOAL,
                    "stopped by an empty trajectory on arm_controller/joint_trajectory".into(),
                    effects,
                );
                self.core.stop_motion();
            }
            return;
        }
        match self.plan(&msg, None, wall, now) {
            Ok(plan) => self.start_arm(plan, Owner::Topic, wall, now, effects),
            Err(r) => self.refuse("arm_controller/joint_trajectory", r.code, &r.text, effects),
        }
    }

    /// A FollowJointTrajectory goal: answered, and run if it is accepted.
    pub(super) fn on_trajectory_goal(
        &mut self,
        g: GoalRequest<FollowJointTrajectoryGoal>,
        wall: Time,
        now: Instant,
        effects: &mut Vec<Effect>,
    ) {
        match self.plan(&g.goal.trajectory, Some(&g.goal), wall, now) {
            Ok(plan) => {
                effects.push(Effect::AnswerGoal {
                    ticket: g.ticket,
                    accepted: true,
                    gripper: false,
                });
                self.start_arm(plan, Owner::Action(g.id), wall, now, effects);
            }
            Err(r) => {
                effects.push(Effect::AnswerGoal {
                    ticket: g.ticket,
                    accepted: false,
                    gripper: false,
                });
                self.refuse("follow_joint_trajectory goal", r.code, &r.text, effects);
            }
        }
    }

    /// End the running trajectory, if any: its result to its client.
    pub(super) fn end_arm(
        &mut self,
        end: GoalEnd,
        code: i32,
        text: String,
        effects: &mut Vec<Effect>,
    ) {
        self.end_arm_then(end, code, text, true, effects);
    }

    /// [`Self::end_arm`]; `stop`: the arm stops where it is (and a claw on its way goes
    /// on), else a target that took the arm has planned its motion already.
    pub(super) fn end_arm_then(
        &mut self,
        end: GoalEnd,
        code: i32,
        text: String,
        stop: bool,
        effects: &mut Vec<Effect>,
    ) {
        let Some(run) = self.arm.take() else { return };
        self.arbiter.finished(Controller::ArmController);
        let claw = self.claw.take();
        if stop {
            self.core.stop_motion();
            // a claw on its way goes on, at its own limits
            let target = self
                .gripper
                .as_ref()
                .map(|g| g.target)
                .or(claw.map(|(t, _)| t));
            self.claw_goes_on(target);
        }
        let note = end_note(end, code, &text);
        if end != GoalEnd::Succeeded {
            log::warn!("trajectory {note}");
        } else {
            log::info!("trajectory succeeded");
        }
        self.last_trajectory = Some(note);
        effects.push(Effect::Report);
        if let Owner::Action(id) = run.owner {
            effects.push(Effect::TrajectoryResult(
                id,
                end,
                Fjt {
                    error_code: code,
                    error_string: text,
                },
            ));
        }
    }

    /// The stopped arm's claw goes on to `target` (a gripper goal's, or a
    /// `gripper_target`'s), if it is not there.
    fn claw_goes_on(&mut self, target: Option<f64>) {
        let gripper = self.map.as_ref().and_then(|m| m.gripper.as_ref());
        if let (Some(t), Some(gm)) = (target, gripper) {
            let mut axes = self.core.axes();
            if axes[gm.axis] != t {
                axes[gm.axis] = t;
                self.core.move_to_axes(&axes);
            }
        }
    }

    /// A step of the running trajectory: its sampled point (the claw on its own way),
    /// published, with feedback to a goal's client; ended when the tick says so.
    pub(super) fn tick_arm(&mut self, wall: Time, effects: &mut Vec<Effect>) {
        let (Some(run), Some(map)) = (&mut self.arm, &self.map) else {
            return;
        };
        let actual = self.actual.as_ref().map(|(a, _)| a);
        let tick = run.exec.tick(seconds(wall), actual);
        let owner = run.owner;
        let mut axes = self.core.axes();
        for (k, &a) in map.axes.iter().enumerate() {
            axes[a] = tick.axes[k];
        }
        self.track_claw(&mut axes);
        let outcome = tick.outcome.clone();
        let step = self.core.command_axes(&axes, wall);
        effects.push(Effect::Publish(step));
        if let Owner::Action(id) = owner {
            effects.push(Effect::TrajectoryFeedback(
                id,
                Box::new(self.feedback(&tick, wall)),
            ));
        }
        if let Some(run) = &mut self.arm {
            run.last = Some(tick);
        }
        if let Some(Outcome {
            succeeded,
            code,
            text,
        }) = outcome
        {
            let end = if succeeded {
                GoalEnd::Succeeded
            } else {
                GoalEnd::Aborted
            };
            self.end_arm(end, code, text, effects);
        }
    }

    /// While a trajectory runs the arm, the claw moves on its own at its limits, to a
    /// gripper goal's opening or a `gripper_target`'s: its step into `axes`.
    fn track_claw(&mut self, axes: &mut [f64]) {
        let Some(gm) = self.map.as_ref().and_then(|m| m.gripper.as_ref()) else {
            return;
        };
        let limits = self.core.axis_limits()[gm.axis];
        let dt = self.core.motion().period_s;
        let claw = match (&mut self.gripper, &mut self.claw) {
            (Some(g), _) => Some((g.target, &mut g.motion)),
            (None, Some((target, motion))) => Some((*target, motion)),
            (None, None) => None,
        };
        if let Some((target, motion)) = claw {
            *motion = track(*motion, target, limits, dt);
            axes[gm.axis] = motion.position;
        }
    }

    /// FollowJointTrajectory feedback on a step: desired, actual (servo_state), error.
    fn feedback(&self, tick: &controller::Tick, wall: Time) -> FollowJointTrajectoryFeedback {
        let map = self.map.as_ref();
        let actual = self
            .actual
            .as_ref()
            .map(|(a, _)| a.positions.clone())
            .unwrap_or_default();
        let error = if actual.is_empty() {
            JointTrajectoryPoint::default()
        } else {
            positions_point(difference(&tick.desired.positions, &actual))
        };
        FollowJointTrajectoryFeedback {
            header: Header {
                stamp: wall,
                frame_id: String::new(),
            },
            joint_names: map.map(|m| m.joints.clone()).unwrap_or_default(),
            desired: tick.desired.clone(),
            actual: positions_point(actual),
            error,
            index: tick.index,
            ..Default::default()
        }
    }

    /// `arm_controller/controller_state` now: the reference (the running trajectory's
    /// desired point, else the command), the feedback (servo_state), the error, the
    /// output (the command).
    pub(super) fn controller_state(&self, wall: Time) -> Option<JointTrajectoryControllerState> {
        let map = self.map.as_ref()?;
        let axes = self.core.axes();
        let command: Vec<f64> =
            map.joints_of(&map.axes.iter().map(|&a| axes[a]).collect::<Vec<_>>());
        let reference = match self.arm.as_ref().and_then(|r| r.last.as_ref()) {
            Some(t) => t.desired.clone(),
            None => positions_point(command.clone()),
        };
        let actual = self.actual.as_ref().map(|(a, _)| a.positions.clone());
        let error = actual
            .as_ref()
            .map(|a| positions_point(difference(&reference.positions, a)))
            .unwrap_or_default();
        Some(JointTrajectoryControllerState {
            header: Header {
                stamp: wall,
                frame_id: String::new(),
            },
            joint_names: map.joints.clone(),
            reference,
            feedback: positions_point(actual.unwrap_or_default()),
            error,
            output: positions_point(command),
            speed_scaling_factor: 1.0,
            ..Default::default()
        })
    }

    /// A `servo_state` report: with every servo, the actual state that trajectories and
    /// gripper goals are judged against (and controller_state goes out with it).
    pub(super) fn on_servo_state(
        &mut self,
        msg: &JointState,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let Some(map) = &self.map else { return };
        let Some(axes) = self.core.model().reported_axes(msg) else {
            log::debug!("servo_state without every servo: not used as the actual state");
            return;
        };
        let positions = map.joints_of(&map.axes.iter().map(|&a| axes[a]).collect::<Vec<_>>());
        let claw = map.gripper.as_ref().map(|g| axes[g.axis] * g.rad_per_unit);
        let stamp = if msg.header.stamp == Time::ZERO {
            wall
        } else {
            msg.header.stamp
        };
        self.servo_state_at = Some(seconds(wall));
        self.last_servo_state = Some(msg.clone());
        self.actual = Some((
            Actual {
                positions,
                stamp_s: seconds(stamp),
            },
            claw,
        ));
        if let Some(state) = self.controller_state(wall) {
            effects.push(Effect::ControllerState(Box::new(state)));
        }
        self.gripper_progress(wall, false, effects);
    }

    /// Cancels accepted for these goals: the trajectory or gripper goal of that id
    /// ends as canceled.
    pub(super) fn on_cancel(&mut self, ids: &[GoalId], _wall: Time, effects: &mut Vec<Effect>) {
        for id in ids {
            if matches!(self.arm.as_ref().map(|r| r.owner), Some(Owner::Action(a)) if a == *id) {
                self.end_arm(
                    GoalEnd::Canceled,
                    Fjt::SUCCESSFUL,
                    "canceled by the client".into(),
                    effects,
                );
            }
            if self.gripper.as_ref().is_some_and(|g| g.id == *id) {
                self.end_gripper(
                    GoalEnd::Canceled,
                    false,
                    "canceled by the client",
                    true,
                    effects,
                );
            }
        }
    }
}

/// A point of controller joint positions only.
fn positions_point(positions: Vec<f64>) -> JointTrajectoryPoint {
    JointTrajectoryPoint {
        positions,
        ..Default::default()
    }
}

/// a − b, element by element.
fn difference(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}

/// What `diagnostics`' `last_trajectory` says of a trajectory that ended.
fn end_note(end: GoalEnd, code: i32, text: &str) -> String {
    match end {
        GoalEnd::Succeeded => "succeeded".to_string(),
        _ => format!(
            "{} ({}): {text}",
            if end == GoalEnd::Canceled {
                "canceled"
            } else {
                "aborted"
            },
            code_name(code)
        ),
    }
}
