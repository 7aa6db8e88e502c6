//! gripper_controller: a GripperCommand goal taken (the arbiter willing), the claw
//! moved to its opening, and the goal judged against `servo_state` (reached, or
//! stalled short of it) until it ends.

use super::{seconds, Driver, Effect};
use crate::pipeline::{ArmModel, GoalRequest};
use arbiter::{Command, Controller};
use eezybot_motion::AxisState;
use eezybot_msgs::control_msgs::{
    FollowJointTrajectoryResult as Fjt, GripperCommandGoal, GripperCommandResult,
};
use eezybot_msgs::Time;
use ros_plumbing::action::{GoalEnd, GoalId};
use std::time::Instant;

/// How close (rad) the claw's reported angle must come to a GripperCommand's position.
pub const GRIPPER_TOLERANCE_RAD: f64 = 0.02;

/// How long (s) the claw may stay short of a GripperCommand's position after its
/// command got there before the goal ends as stalled.
pub const GRIPPER_STALL_S: f64 = 1.0;

#[derive(Debug)]
pub(super) struct GripperRun {
    pub(super) id: GoalId,
    /// the opening asked for (axis units)
    pub(super) target: f64,
    /// the claw's axis, moved here while a trajectory runs the arm
    pub(super) motion: AxisState,
    /// when the command reached the target (s)
    commanded_at: Option<f64>,
}

impl<M: ArmModel> Driver<M> {
    /// A GripperCommand goal: answered; if accepted, it takes the claw (a running
    /// gripper goal preempted) and the claw moves to its opening.
    pub(super) fn on_gripper_goal(
        &mut self,
        g: GoalRequest<GripperCommandGoal>,
        wall: Time,
        now: Instant,
        effects: &mut Vec<Effect>,
    ) {
        let opening = match self.gripper_goal_opening(&g.goal, now) {
            Ok(opening) => opening,
            Err((code, why)) => {
                effects.push(Effect::AnswerGoal {
                    ticket: g.ticket,
                    accepted: false,
                    gripper: true,
                });
                self.refuse("gripper_cmd goal", code, &why, effects);
                return;
            }
        };
        effects.push(Effect::AnswerGoal {
            ticket: g.ticket,
            accepted: true,
            gripper: true,
        });
        self.end_gripper(
            GoalEnd::Canceled,
            false,
            "preempted by a newer goal",
            true,
            effects,
        );
        self.take(Command::GripperGoal, "gripper_cmd goal", now, wall, effects);
        self.start_gripper(g.id, opening, now, wall, effects);
    }

    /// The opening (0 closed … 1 open) a GripperCommand goal asks for, or why it is
    /// refused (a FollowJointTrajectory code, the reason): no gripper controller, the
    /// core halted, the arbiter unwilling, a position out of range.
    fn gripper_goal_opening(
        &self,
        goal: &GripperCommandGoal,
        now: Instant,
    ) -> Result<f64, (i32, String)> {
        let Some(gm) = self.map.as_ref().and_then(|m| m.gripper.as_ref()) else {
            return Err((
                Fjt::INVALID_JOINTS,
                "this arm has no gripper controller".into(),
            ));
        };
        let position = goal.command.position;
        let opening = position / gm.rad_per_unit;
        let refusal = if let Some(why) = self.core.halted() {
            Some(why.to_string())
        } else if let Err(why) = self.may(Command::GripperGoal, now) {
            Some(why.to_string())
        } else if !(position.is_finite() && (-1e-9..=1.0 + 1e-9).contains(&opening)) {
            Some(format!(
                "position {position} rad is outside {}'s range 0 … {:.4} rad (closed … open)",
                gm.joint, gm.rad_per_unit
            ))
        } else {
            None
        };
        match refusal {
            Some(why) => Err((Fjt::INVALID_GOAL, why)),
            None => Ok(opening.clamp(0.0, 1.0)),
        }
    }

    /// Goal `id` runs: the claw moves to `opening` (with the arm's motion, or on its
    /// own while a trajectory runs the arm), stepped from now on.
    fn start_gripper(
        &mut self,
        id: GoalId,
        opening: f64,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let Some(axis) = self
            .map
            .as_ref()
            .and_then(|m| m.gripper.as_ref())
            .map(|g| g.axis)
        else {
            return;
        };
        let axes = self.core.axes();
        self.gripper = Some(GripperRun {
            id,
            target: opening,
            motion: AxisState {
                position: axes[axis],
                velocity: 0.0,
            },
            commanded_at: None,
        });
        if self.arm.is_none() {
            match self.core.handle_gripper_target(opening, wall) {
                Ok(step) => effects.push(Effect::Publish(step)),
                Err(r) => {
                    self.end_gripper(GoalEnd::Aborted, false, &r.to_string(), true, effects);
                    return;
                }
            }
        }
        if self.next_step.is_none() {
            self.next_step = Some(now + self.step_period());
        }
    }

    /// Judge the running gripper goal (on a step, with feedback; or on a report).
    pub(super) fn gripper_progress(&mut self, wall: Time, step: bool, effects: &mut Vec<Effect>) {
        let (Some(g), Some(gm)) = (
            &mut self.gripper,
            self.map.as_ref().and_then(|m| m.gripper.as_ref()),
        ) else {
            return;
        };
        let now_s = seconds(wall);
        let commanded = self.core.axes()[gm.axis];
        if (commanded - g.target).abs() < 1e-9 && g.commanded_at.is_none() {
            g.commanded_at = Some(now_s);
        }
        let actual = self.actual.as_ref().and_then(|(_, c)| *c);
        let target_rad = g.target * gm.rad_per_unit;
        let reached = commanded_at_target(g.commanded_at)
            && actual.is_some_and(|a| (a - target_rad).abs() <= GRIPPER_TOLERANCE_RAD);
        let state = GripperCommandResult {
            position: actual.unwrap_or(commanded * gm.rad_per_unit),
            effort: 0.0,
            stalled: false,
            reached_goal: reached,
        };
        let (id, commanded_at) = (g.id, g.commanded_at);
        if reached {
            self.gripper_done(id, GoalEnd::Succeeded, state, effects);
            return;
        }
        if commanded_at.is_some_and(|t| now_s - t > GRIPPER_STALL_S) {
            let why = match actual {
                Some(a) => format!(
                    "{} stopped at {a:.3} rad, short of {target_rad:.3} rad",
                    gm.joint
                ),
                None => "no servo_state came: is serial_node running?".into(),
            };
            log::warn!("gripper_cmd goal aborted: stalled: {why}");
            self.last_trajectory = Some(format!("gripper_cmd aborted: stalled: {why}"));
            let stalled = GripperCommandResult {
                stalled: true,
                ..state
            };
            self.gripper_done(id, GoalEnd::Aborted, stalled, effects);
            return;
        }
        if step {
            effects.push(Effect::GripperFeedback(id, state));
        }
    }

    /// The running gripper goal `id` ended as judged (`end`, with `result`): the
    /// claw is the arbiter's again.
    fn gripper_done(
        &mut self,
        id: GoalId,
        end: GoalEnd,
        result: GripperCommandResult,
        effects: &mut Vec<Effect>,
    ) {
        self.gripper = None;
        self.arbiter.finished(Controller::GripperController);
        effects.push(Effect::GripperResult(id, end, result));
    }

    /// End the running gripper goal, if any; `stop`: the claw stops where it is (else a
    /// target that took it has planned its motion already).
    pub(super) fn end_gripper(
        &mut self,
        end: GoalEnd,
        reached: bool,
        why: &str,
        stop: bool,
        effects: &mut Vec<Effect>,
    ) {
        let Some(g) = self.gripper.take() else { return };
        self.arbiter.finished(Controller::GripperController);
        log::info!("gripper_cmd goal ended: {why}");
        let gm = self.map.as_ref().and_then(|m| m.gripper.as_ref());
        let position = self
            .actual
            .as_ref()
            .and_then(|(_, c)| *c)
            .or_else(|| gm.map(|gm| self.core.axes()[gm.axis] * gm.rad_per_unit))
            .unwrap_or_default();
        if stop && end != GoalEnd::Succeeded && self.arm.is_none() {
            self.core.stop_motion();
        }
        effects.push(Effect::GripperResult(
            g.id,
            end,
            GripperCommandResult {
                position,
                effort: 0.0,
                stalled: false,
                reached_goal: reached,
            },
        ));
    }
}

/// Whether the claw's command got to the goal (then the report is judged).
fn commanded_at_target(at: Option<f64>) -> bool {
    at.is_some()
}
