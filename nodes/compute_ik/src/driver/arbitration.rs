//! Who moves the arm, acted on: the arbiter decides (`libs/arbiter`); here its
//! changes end what a deactivated commander ran, calibration starts and ends, the
//! e-stop is told, and `controller_manager`'s `list_controllers` and
//! `switch_controller` are answered.

use super::{Driver, Effect};
use crate::pipeline::ArmModel;
use arbiter::{Change, Command, Controller, Outcome, Refusal, Strictness, Switch, Why};
use eezybot_msgs::control_msgs::FollowJointTrajectoryResult as Fjt;
use eezybot_msgs::controller_manager_msgs::{
    ControllerState, ListControllersResponse, SwitchControllerRequest, SwitchControllerResponse,
};
use eezybot_msgs::Time;
use ros_plumbing::action::GoalEnd;
use ros_plumbing::service::{Caller, Ticket};
use std::time::Instant;

/// What ends the other commanders when `calibration` becomes active.
pub(super) const CALIBRATING: &str = "calibrating: the calibration wizard drives the servos";

impl<M: ArmModel> Driver<M> {
    /// Act on what the arbiter changed. `by`: what took the joints (a topic, "the
    /// leader arm"), or why a switch deactivated a controller, for the messages.
    pub(super) fn apply_changes(
        &mut self,
        changes: Vec<Change>,
        by: &str,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let mut switched = false;
        for change in changes {
            match change {
                Change::Activated(c) => {
                    log::info!("{c} active");
                    if c == Controller::Calibration {
                        self.set_calibrating(true, wall, effects);
                    }
                    switched = true;
                }
                Change::Deactivated(c, why) => {
                    if why == Why::OwnerGone {
                        // nobody asked for this one: say why in diagnostics too
                        log::warn!("{c} inactive: {why}");
                        self.last_switch = Some(format!("{c} deactivated: {why}"));
                    } else {
                        log::info!("{c} inactive: {why}");
                    }
                    self.end_commander(c, why, by, wall, effects);
                    switched = true;
                }
                Change::Stopped(c, why) => self.end_commander(c, why, by, wall, effects),
                Change::Skipped(name, why) => {
                    log::warn!("switch_controller: {name} skipped: {why}")
                }
            }
        }
        if switched && !effects.contains(&Effect::Report) {
            effects.push(Effect::Report);
        }
    }

    /// What `c` ran ends (`why`): goals aborted, the leader held, the motion stopped
    /// where it is, unless a target that took the joints planned its motion already.
    fn end_commander(
        &mut self,
        c: Controller,
        why: Why,
        by: &str,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let text = match why {
            Why::PreemptedBy(_) | Why::Superseded => format!("preempted by {by}"),
            Why::Switched if !by.is_empty() => by.to_string(),
            Why::LeaderTimeout => format!(
                "no leader sample for {} ms (cable pulled, or the leader's node stopped)",
                self.leader.timeout.as_millis()
            ),
            why => why.to_string(),
        };
        let planned = matches!(
            why,
            Why::PreemptedBy(Controller::Teleop | Controller::GripperController) | Why::Superseded
        );
        match c {
            Controller::ArmController => {
                self.end_arm_then(GoalEnd::Aborted, Fjt::INVALID_GOAL, text, !planned, effects)
            }
            Controller::GripperController => {
                self.end_gripper(GoalEnd::Aborted, false, &text, !planned, effects)
            }
            Controller::LeaderFollower => {
                let text = if by == CALIBRATING {
                    "calibrating".into()
                } else {
                    text
                };
                self.hold_leader(text, effects)
            }
            Controller::Teleop => {
                // a commander that takes the arm replans from where it is at once (a
                // trajectory stops the motion itself); switched off, the arm holds
                let preempted = matches!(why, Why::PreemptedBy(_) | Why::Superseded);
                if !preempted && self.arm.is_none() && self.gripper.is_none() {
                    self.core.stop_motion();
                }
            }
            Controller::Calibration => self.set_calibrating(false, wall, effects),
        }
    }

    /// Start calibrating (the arbiter made `calibration` active, and ended the others):
    /// publish nothing until the end. End it: take the arm where `servo_state` says.
    fn set_calibrating(&mut self, on: bool, wall: Time, effects: &mut Vec<Effect>) {
        self.core.set_calibrating(on);
        self.next_step = None;
        if on {
            log::warn!("calibrating: the calibration wizard drives the servos; targets refused until `calibration` is deactivated");
        } else {
            let reported = self
                .last_servo_state
                .as_ref()
                .and_then(|msg| self.core.model().reported_axes(msg));
            match reported {
                Some(axes) => {
                    log::info!("calibrating ended: taking the arm where servo_state says it is");
                    effects.push(Effect::Publish(self.core.take_reported(&axes, wall)));
                }
                None => log::info!(
                    "calibrating ended; no servo_state heard, the arm is taken where it was commanded before"
                ),
            }
        }
    }

    /// The controllers, as `list_controllers` answers.
    fn list_controllers(&self) -> ListControllersResponse {
        let controller = self
            .arbiter
            .controllers()
            .into_iter()
            .map(|c| ControllerState {
                name: c.controller.name().into(),
                state: if c.active { "active" } else { "inactive" }.into(),
                r#type: c.controller.type_name().into(),
                is_async: false,
                update_rate: self.core.motion().period_s.recip().round() as u16,
                claimed_interfaces: if c.active {
                    c.interfaces.clone()
                } else {
                    vec![]
                },
                required_command_interfaces: c.interfaces,
                required_state_interfaces: vec![],
                ..ControllerState::default()
            })
            .collect();
        ListControllersResponse { controller }
    }

    /// An `estop` sample: if it changes the lock (`engaged`), the core and the arbiter
    /// are told (commanders that move the arm stopped) and nothing planned goes on.
    pub(super) fn on_estop(
        &mut self,
        engaged: bool,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        if engaged == self.core.estop() {
            return;
        }
        if engaged {
            log::warn!("emergency stop engaged: targets refused until estop is false")
        } else {
            log::info!("emergency stop released")
        }
        self.core.set_estop(engaged);
        let out = self.arbiter.handle(arbiter::Event::Estop(engaged), now);
        self.apply_changes(out.changes, "", wall, effects);
        self.next_step = None;
        effects.push(Effect::Report);
    }

    /// A `list_controllers` request: its caller is alive (a calibration's lease
    /// renewed), and it is answered.
    pub(super) fn on_list_controllers(
        &mut self,
        ticket: Ticket,
        caller: Caller,
        now: Instant,
        effects: &mut Vec<Effect>,
    ) {
        self.arbiter
            .handle(arbiter::Event::OwnerAlive(caller.to_string()), now);
        effects.push(Effect::ListControllers(ticket, self.list_controllers()));
    }

    /// A `switch_controller` request, switched and answered.
    pub(super) fn on_switch_controller(
        &mut self,
        ticket: Ticket,
        caller: Caller,
        req: SwitchControllerRequest,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let answer = self.switch_controller(caller, req, now, wall, effects);
        effects.push(Effect::SwitchController(ticket, answer));
    }

    /// `switch_controller`: as ros2_control does it (the strictness read by
    /// [`strictness`]); a best-effort switch that did nothing of what it asked is not
    /// ok ([`switch_response`]).
    fn switch_controller(
        &mut self,
        caller: Caller,
        req: SwitchControllerRequest,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) -> SwitchControllerResponse {
        let strictness = match strictness(req.strictness) {
            Ok(strictness) => strictness,
            Err(unknown) => return unknown,
        };
        let asked = req.activate_controllers.len() + req.deactivate_controllers.len();
        let switch = Switch {
            activate: req.activate_controllers,
            deactivate: req.deactivate_controllers,
            strictness,
            owner: caller.to_string(),
            lease: true,
        };
        let out = self.arbiter.handle(arbiter::Event::Switch(switch), now);
        let response = switch_response(&out, asked);
        self.note_switch(&response);
        // what a deactivated commander reports it ended by
        let by = if out
            .changes
            .contains(&Change::Activated(Controller::Calibration))
        {
            CALIBRATING
        } else {
            ""
        };
        self.apply_changes(out.changes, by, wall, effects);
        effects.push(Effect::Report);
        response
    }

    /// A switch's answer, logged and kept for `diagnostics`.
    fn note_switch(&mut self, response: &SwitchControllerResponse) {
        if response.ok {
            log::info!(
                "switch_controller: done{}",
                if response.message.is_empty() {
                    String::new()
                } else {
                    format!("; {}", response.message)
                }
            );
        } else {
            log::warn!("switch_controller: {}", response.message);
        }
        self.last_switch = Some(if response.ok {
            "done".into()
        } else {
            response.message.clone()
        });
    }

    /// Whether the arbiter would let `command` have its joints now (nothing changes).
    pub(super) fn may(&self, command: Command, now: Instant) -> Result<(), Refusal> {
        let mut probe = self.arbiter.clone();
        probe
            .handle(arbiter::Event::Command(command), now)
            .result
            .map(|_| ())
    }

    /// `command` takes its joints (the arbiter said it may): whoever held them ends
    /// what it ran (`by` names the taker in the messages).
    pub(super) fn take(
        &mut self,
        command: Command,
        by: &str,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let out = self.arbiter.handle(arbiter::Event::Command(command), now);
        match out.result {
            Ok(_) => self.apply_changes(out.changes, by, wall, effects),
            Err(why) => log::warn!("{by}: not given the joints after all: {why}"),
        }
    }
}

/// ros2_control's strictness: 0 is STRICT, its default; AUTO and FORCE_AUTO are
/// BEST_EFFORT (ros2_control has no chains to follow here either); an unknown one
/// is answered at once, not ok.
fn strictness(n: i32) -> Result<Strictness, SwitchControllerResponse> {
    match n {
        0 | SwitchControllerRequest::STRICT => Ok(Strictness::Strict),
        SwitchControllerRequest::BEST_EFFORT
        | SwitchControllerRequest::AUTO
        | SwitchControllerRequest::FORCE_AUTO => Ok(Strictness::BestEffort),
        n => Err(SwitchControllerResponse {
            ok: false,
            message: format!(
                "unknown strictness {n} (BEST_EFFORT 1, STRICT 2, AUTO 3, FORCE_AUTO 4)"
            ),
        }),
    }
}

/// The answer to a switch as the arbiter decided it (`asked`: how many controllers
/// the request named): refused with the reason's code; a switch that did nothing of
/// what it asked, only skipping, is not ok; what was skipped is said.
fn switch_response(out: &Outcome, asked: usize) -> SwitchControllerResponse {
    let skipped: Vec<String> = out
        .changes
        .iter()
        .filter_map(|c| match c {
            Change::Skipped(name, why) => Some(format!("{name} ({}): {why}", why.code())),
            _ => None,
        })
        .collect();
    let done = out.changes.len() - skipped.len();
    match &out.result {
        Err(why) => SwitchControllerResponse {
            ok: false,
            message: format!("refused ({}): {why}", why.code()),
        },
        Ok(_) if asked > 0 && done == 0 && !skipped.is_empty() => SwitchControllerResponse {
            ok: false,
            message: format!("nothing switched: {}", skipped.join("; ")),
        },
        Ok(_) if skipped.is_empty() => SwitchControllerResponse {
            ok: true,
            message: String::new(),
        },
        Ok(_) => SwitchControllerResponse {
            ok: true,
            message: format!("skipped: {}", skipped.join("; ")),
        },
    }
}
