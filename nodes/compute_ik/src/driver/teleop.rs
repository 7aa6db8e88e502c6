//! Teleop targets (`xyz_target`, `pose_target`, `joint_target`, `gripper_target`):
//! the arbiter's decision on a copy, then the pipeline's; a target taken takes its
//! joints from whoever held them, a refused one is logged and reported.

use super::{Driver, Effect, MIN_IMMEDIATE_DIAG_GAP};
use crate::core::Rejection;
use crate::pipeline::{ArmModel, Input, Step};
use arbiter::{Arbiter, Change, Command, Refusal};
use eezybot_motion::AxisState;
use eezybot_msgs::Time;
use ros_plumbing::logging::Throttle;
use std::time::Instant;

impl<M: ArmModel> Driver<M> {
    /// The arbiter's decision on a teleop target, on a copy: `Ok` with the arbiter as
    /// it would be and what would change, for when the target is taken; `Err` with why
    /// not, when another commander holds its joints (the e-stop and calibrating are
    /// the core's to refuse, with their own codes).
    fn teleop_decision(
        &self,
        input: &Input,
        now: Instant,
    ) -> Option<Result<(Arbiter, Vec<Change>), Refusal>> {
        let command = match input {
            Input::XyzTarget(_) | Input::XyzLineTarget(_) | Input::PoseTarget(_) => {
                Command::ArmTarget
            }
            Input::JointTarget(m) => {
                let claw = self.arbiter.layout().gripper.as_ref();
                if claw.is_some_and(|g| m.name.contains(g)) {
                    Command::ArmAndClawTarget
                } else {
                    Command::ArmTarget
                }
            }
            Input::GripperTarget(..) => Command::ClawTarget,
            _ => return None,
        };
        let mut next = self.arbiter.clone();
        let out = next.handle(arbiter::Event::Command(command), now);
        Some(match out.result {
            Ok(_) => Ok((next, out.changes)),
            Err(Refusal::Estop | Refusal::Calibrating | Refusal::NoInterfaces(_)) => {
                Ok((self.arbiter.clone(), vec![]))
            }
            Err(why) => Err(why),
        })
    }

    /// A teleop target (`xyz_target`, `pose_target`, `joint_target`,
    /// `gripper_target`), or a sample that could not be read: the arbiter's decision
    /// (a target refused when another commander holds its joints), then the
    /// pipeline's (its first step published, or the refusal reported). This is
    /// `xyz_target`'s handler: `run` → [`Driver::on_inputs`] → here.
    pub(super) fn on_target(
        &mut self,
        input: Input,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let (next, changes) = match self.teleop_decision(&input, now) {
            Some(Err(why)) => {
                let why = why.to_string();
                if let Some(rejection) = self.core.reject_held(&input, why, wall) {
                    self.report_rejection(rejection, now, effects);
                }
                return;
            }
            Some(Ok((next, changes))) => (Some(next), changes),
            None => (None, vec![]),
        };
        let Some(result) = self.core.handle(&input, wall) else {
            return;
        };
        for notice in self.core.take_notices() {
            if let Some(quiet) = self.complaints.allow(&notice.kind, now) {
                log::info!("{}{}", notice.text, Throttle::suffix(quiet));
            }
        }
        match result {
            Ok(step) => self.target_taken(&input, step, (next, changes), now, wall, effects),
            Err(rejection) => self.report_rejection(rejection, now, effects),
        }
    }

    /// The pipeline took a target (its first `step`): the target takes its joints
    /// (from a running goal, or a holding leader: the arbiter as `decision` left it,
    /// and its changes, with the topic for the messages), the step is published and
    /// the next one timed.
    fn target_taken(
        &mut self,
        input: &Input,
        step: Step,
        decision: (Option<Arbiter>, Vec<Change>),
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let (next, changes) = decision;
        if let Some(next) = next {
            self.arbiter = next;
        }
        self.apply_changes(changes, input_topic(input), wall, effects);
        if matches!(input, Input::GripperTarget(..)) {
            self.claw_beside_trajectory();
        }
        effects.push(Effect::Publish(step));
        // The next step one and a half periods after this first one: a
        // target stream at the motion rate (a 50 Hz teleop) steps the
        // motion itself, and a fill-in step comes only when targets pause.
        // With one period, a target a little late behind the timer made two
        // steps back to back: 52 steps a second for a 50 Hz stream, more than
        // serial_node's 50 frames a second, so every command waited for a
        // frame slot (xyz_target -> first byte p50 7.5 ms). Each step is one
        // planner period of motion whenever it is published, so a later
        // fill-in never makes a step larger.
        self.next_step = self
            .core
            .is_moving()
            .then(|| now + self.step_period().mul_f64(1.5));
    }

    /// A `gripper_target` taken while a trajectory runs: the trajectory keeps the arm;
    /// the claw moves on its own, from where it is to the target's opening.
    fn claw_beside_trajectory(&mut self) {
        if let (Some(_), Some(gm)) = (
            &self.arm,
            self.map.as_ref().and_then(|m| m.gripper.as_ref()),
        ) {
            let here = self.core.axes()[gm.axis];
            let target = self.core.model().axes(self.core.goal())[gm.axis];
            self.claw = Some((
                target,
                AxisState {
                    position: here,
                    velocity: 0.0,
                },
            ));
        }
    }

    /// A refused target: logged (throttled per topic and reason) and reported at once
    /// (at most every [`MIN_IMMEDIATE_DIAG_GAP`]).
    pub(super) fn report_rejection(
        &mut self,
        rejection: Rejection,
        now: Instant,
        effects: &mut Vec<Effect>,
    ) {
        let kind = format!("{}/{}", rejection.source.topic(), rejection.reason.code());
        if let Some(quiet) = self.complaints.allow(&kind, now) {
            log::warn!("{rejection}{}", Throttle::suffix(quiet));
        }
        if self
            .last_immediate
            .is_none_or(|t| now.duration_since(t) >= MIN_IMMEDIATE_DIAG_GAP)
        {
            self.last_immediate = Some(now);
            effects.push(Effect::Report);
        }
    }
}

/// The topic an input came on, for messages.
fn input_topic(input: &Input) -> &'static str {
    match input {
        Input::XyzTarget(_) => "xyz_target",
        Input::XyzLineTarget(_) => "xyz_line_target",
        Input::PoseTarget(_) => "pose_target",
        Input::GripperTarget(..) => "gripper_target",
        Input::JointTarget(_) => "joint_target",
        _ => "another command",
    }
}
