//! The node's loop policy around a [`Pipeline`], on a clock it is given (as
//! `servo_protocol::host` is): which inputs of a burst are applied, a late target held
//! back for a newer one (the [`CommandGate`] serial_node shares), when the planned
//! motion steps, when a refusal is reported at
//! once, and the pose sent to a new `joint_states` subscriber. Events in, [`Effect`]s
//! out; [`crate::run`] does the I/O.

use crate::controller::{Actual, ControllerMap, ControllerSettings};
use crate::core::Rejection;
use crate::pipeline::{ArmModel, Input, Pipeline, Step};
use arbiter::{Arbiter, Change, Command, Controller, Layout, Refusal, Strictness, Switch, Why};
use command_gate::{CommandGate, Stamp, Verdict};
use eezybot_motion::AxisState;
use eezybot_msgs::control_msgs::{
    FollowJointTrajectoryFeedback, FollowJointTrajectoryResult as Fjt, GripperCommandResult,
    JointTrajectoryControllerState,
};
use eezybot_msgs::controller_manager_msgs::{
    ControllerState, ListControllersResponse, SwitchControllerRequest, SwitchControllerResponse,
};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use ros2_client::action::GoalId;
use ros2_client::service::request_id::RmwRequestId;
use ros_plumbing::action::GoalEnd;
use ros_plumbing::burst;
use ros_plumbing::feedback;
use ros_plumbing::logging::Throttle;
use ros_plumbing::service::{Caller, Ticket};
use ros_plumbing::Params;
use std::time::{Duration, Instant};

mod gripper;
mod leader;
mod trajectory;

use gripper::GripperRun;
pub use gripper::{GRIPPER_STALL_S, GRIPPER_TOLERANCE_RAD};
use leader::Leader;
pub use leader::DEFAULT_LEADER_TIMEOUT;
use trajectory::ArmRun;
pub use trajectory::{CONTROLLER_STATE_QUIET_S, TRAJECTORY_LEAD_PERIODS};

/// Most frequent diagnostics sent at once on a rejection; the periodic report covers the rest.
pub const MIN_IMMEDIATE_DIAG_GAP: Duration = Duration::from_millis(100);

/// Polls of the peers over which a new `joint_states` subscriber is sent the pose (the
/// new reader may match our writer a little after we match it: over a second, not once).
const GREET_POLLS: u8 = 4;

/// A matched subscription, by its GUID's 16 bytes.
pub type ReaderId = [u8; 16];

/// What to do.
#[derive(Clone, Debug, PartialEq)]
pub enum Effect {
    /// Publish a step (`joint_states`, and `servo_angles` if any).
    Publish(Step),
    /// Publish on `joint_states` only (the pose, for a new viewer).
    JointStates(JointState),
    /// Publish a `diagnostics` report.
    Report,
    /// Answer a goal request (of arm_controller, or of gripper_controller if
    /// `gripper`).
    AnswerGoal {
        /// the request
        request: RmwRequestId,
        /// the goal
        id: GoalId,
        /// accepted (else rejected)
        accepted: bool,
        /// gripper_controller's
        gripper: bool,
    },
    /// FollowJointTrajectory feedback on a running goal.
    TrajectoryFeedback(GoalId, Box<FollowJointTrajectoryFeedback>),
    /// A FollowJointTrajectory goal ended.
    TrajectoryResult(GoalId, GoalEnd, Fjt),
    /// GripperCommand feedback on a running goal.
    GripperFeedback(GoalId, GripperCommandResult),
    /// A GripperCommand goal ended.
    GripperResult(GoalId, GoalEnd, GripperCommandResult),
    /// Publish on `arm_controller/controller_state`.
    ControllerState(Box<JointTrajectoryControllerState>),
    /// Answer a `controller_manager/list_controllers` request.
    ListControllers(Ticket, ListControllersResponse),
    /// Answer a `controller_manager/switch_controller` request.
    SwitchController(Ticket, SwitchControllerResponse),
}

/// What ends the other commanders when `calibration` becomes active.
const CALIBRATING: &str = "calibrating: the calibration wizard drives the servos";

/// The loop's state around the pipeline.
#[derive(Debug)]
pub struct Driver<M: ArmModel> {
    core: Pipeline<M>,
    /// when the planned motion steps next (one step per period while moving)
    next_step: Option<Instant>,
    /// a Cartesian target (xyz or pose) that arrived late (held back by a network
    /// outage) is held until no newer one followed for [`command_gate::HOLD_LATE`];
    /// too old ones are the pipeline's to refuse (`max_target_age`)
    gate: CommandGate<Input>,
    complaints: Throttle,
    last_immediate: Option<Instant>,
    /// the `joint_states` subscriptions at the last poll
    readers: std::collections::BTreeSet<ReaderId>,
    greet_polls: u8,
    map: Option<ControllerMap>,
    settings: ControllerSettings,
    arm: Option<ArmRun>,
    gripper: Option<GripperRun>,
    /// a `gripper_target` that came while a trajectory runs the arm: the opening, and
    /// the claw's axis moving there
    claw: Option<(f64, AxisState)>,
    /// the latest servo_state: controller joints, and the claw's axis
    actual: Option<(Actual, Option<f64>)>,
    /// the last trajectory refused or ended, for `diagnostics`
    last_trajectory: Option<String>,
    /// when the last servo_state came (s, wall clock)
    servo_state_at: Option<f64>,
    /// the last servo_state with every servo, to take the arm where it is after
    /// calibrating (read through the calibration of that moment)
    last_servo_state: Option<JointState>,
    leader: Leader,
    /// who moves the arm: the controllers, active or not, and the e-stop's lock
    arbiter: Arbiter,
    /// the last `switch_controller`'s outcome, for `diagnostics`
    last_switch: Option<String>,
}

impl<M: ArmModel> Driver<M> {
    /// Around this pipeline, nothing planned.
    pub fn new(core: Pipeline<M>) -> Self {
        Driver {
            core,
            next_step: None,
            gate: CommandGate::new(),
            complaints: Throttle::default(),
            last_immediate: None,
            readers: Default::default(),
            greet_polls: 0,
            map: None,
            settings: ControllerSettings::default(),
            arm: None,
            gripper: None,
            claw: None,
            actual: None,
            last_trajectory: None,
            servo_state_at: None,
            last_servo_state: None,
            leader: Leader {
                timeout: DEFAULT_LEADER_TIMEOUT,
                state: "no leader".into(),
                ..Leader::default()
            },
            arbiter: Arbiter::new(Layout {
                arm: vec![],
                gripper: None,
            }),
            last_switch: None,
        }
        .with_map()
    }

    /// The controller map (the EezyBot's), and the arbiter over the arm's joints.
    fn with_map(mut self) -> Self {
        self.map = self.core.model().controller_map();
        let layout = match &self.map {
            Some(m) => Layout {
                arm: m.joints.clone(),
                gripper: m.gripper.as_ref().map(|g| g.joint.clone()),
            },
            None => Layout {
                arm: self.core.joint_states(Time::ZERO).name,
                gripper: None,
            },
        };
        self.arbiter = Arbiter::new(layout);
        self.arbiter.set_leader_timeout(DEFAULT_LEADER_TIMEOUT);
        self
    }

    /// The tolerances a goal's zeros stand for.
    pub fn set_controller_settings(&mut self, settings: ControllerSettings) {
        self.settings = settings;
    }

    /// What `diagnostics` says of the controllers.
    pub fn controller_values(&self) -> Vec<(String, String)> {
        let running = self.arm_controller_summary();
        let active: Vec<&str> = Controller::ALL
            .into_iter()
            .filter(|&c| self.arbiter.is_active(c))
            .map(Controller::name)
            .collect();
        let mut v = vec![
            ("arm_controller".to_string(), running),
            ("leader".to_string(), self.leader.state.clone()),
            (
                feedback::ACTIVE_CONTROLLERS_KEY.to_string(),
                if active.is_empty() {
                    "none (the arm holds)".into()
                } else {
                    active.join(", ")
                },
            ),
        ];
        if let Some(t) = &self.last_trajectory {
            v.push(("last_trajectory".into(), t.clone()));
        }
        if let Some(t) = &self.last_switch {
            v.push((feedback::LAST_SWITCH_KEY.into(), t.clone()));
        }
        v
    }

    /// The pipeline.
    pub fn core(&self) -> &Pipeline<M> {
        &self.core
    }

    /// When [`Driver::on_time`] is next due: the next motion step, the held target, or
    /// the arbiter's (the leader's timeout, a calibration owner's lease).
    pub fn deadline(&self) -> Option<Instant> {
        [
            self.next_step,
            self.gate.deadline(),
            self.arbiter.deadline(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// How long without a leader sample before the follower holds.
    pub fn set_leader_timeout(&mut self, timeout: Duration) {
        self.leader.timeout = timeout;
        self.arbiter.set_leader_timeout(timeout);
    }

    /// How long a calibration's caller may stay silent before the arm is given back.
    pub fn set_calibration_lease(&mut self, lease: Duration) {
        self.arbiter.set_owner_lease(lease);
    }

    /// The arbiter (who moves the arm).
    pub fn arbiter(&self) -> &Arbiter {
        &self.arbiter
    }

    fn step_period(&self) -> Duration {
        Duration::from_secs_f64(self.core.motion().period_s)
    }

    /// Time passed to `now` (`wall`: the clock the stamps are on): the motion's next
    /// step, and the held late target when its time has come.
    pub fn on_time(&mut self, now: Instant, wall: Time) -> Vec<Effect> {
        let mut effects = vec![];
        if self.arbiter.deadline().is_some_and(|t| t <= now) {
            let out = self.arbiter.handle(arbiter::Event::Tick, now);
            self.apply_changes(out.changes, "", wall, &mut effects);
        }
        if let Some(t) = self.next_step.filter(|t| *t <= now) {
            if self.arm.is_some() {
                self.tick_arm(wall, &mut effects);
            } else if let Some(step) = self.core.step(wall) {
                effects.push(Effect::Publish(step));
            }
            self.gripper_progress(wall, true, &mut effects);
            self.next_step = Some(t + self.step_period()).filter(|_| self.busy());
            if self.next_step.is_none() {
                effects.push(Effect::Report);
            }
        }
        if let Some(m) = self.gate.take_due(now) {
            log::debug!("applying the newest late target");
            self.apply(vec![m], now, wall, &mut effects);
        }
        effects
    }

    /// Inputs that arrived together at `now`: of a kind where the latest wins, the
    /// newest only; a late Cartesian target held back for a newer one.
    pub fn on_inputs(&mut self, arrived: Vec<Input>, now: Instant, wall: Time) -> Vec<Effect> {
        let (arrived, superseded) = coalesce(arrived);
        if superseded > 0 {
            log::debug!("{superseded} targets superseded by newer ones that arrived with them");
            self.core.count_superseded(superseded as u64);
        }
        let mut batch = Vec::new();
        for input in arrived {
            let Some(stamp_s) = cartesian_stamp(&input) else {
                batch.push(input);
                continue;
            };
            let received_s = seconds(wall);
            let superseded = match self.gate.offer(
                input,
                Stamp {
                    stamp_s,
                    received_s,
                },
                now,
            ) {
                Verdict::Pass { item, superseded } => {
                    batch.push(item);
                    superseded
                }
                Verdict::Held { replaced, .. } => replaced,
                Verdict::TooOld { .. } => false, // without a maximum age: never
            };
            if superseded {
                log::debug!("a late target superseded by a newer one");
                self.core.count_superseded(1);
            }
        }
        let mut effects = vec![];
        self.apply(batch, now, wall, &mut effects);
        effects
    }

    /// The peers were looked at: `readers` read `joint_states`. A new one is sent the
    /// pose, stamped `wall`, over the next polls: one not there at the last poll, even
    /// if one that was has gone meanwhile (a count would not change: `gui_bridge once`
    /// run again while the last one's reader was being removed waits for this pose).
    pub fn on_poll(&mut self, readers: &[ReaderId], wall: Time) -> Vec<Effect> {
        let mut effects = vec![];
        // controller_state comes with every servo_state; without one lately (no
        // serial_node), it comes at the polls, with no feedback
        let quiet = self
            .servo_state_at
            .is_none_or(|t| seconds(wall) - t > CONTROLLER_STATE_QUIET_S);
        if quiet {
            if let Some(state) = self.controller_state(wall) {
                effects.push(Effect::ControllerState(Box::new(state)));
            }
        }
        let readers: std::collections::BTreeSet<ReaderId> = readers.iter().copied().collect();
        if !readers.is_subset(&self.readers) {
            self.greet_polls = GREET_POLLS;
        }
        self.readers = readers;
        if self.greet_polls == 0 {
            return effects;
        }
        self.greet_polls -= 1;
        effects.push(Effect::JointStates(self.core.joint_states(wall)));
        effects
    }

    /// The parameters changed at `now` (`wall`): applied (a new solver logged and
    /// reported).
    pub fn on_params(&mut self, params: &Params, _now: Instant, _wall: Time) -> Vec<Effect> {
        let solver = self.core.solver();
        self.core.apply_params(params);
        let mut effects = vec![];
        if self.core.solver() != solver {
            log::info!("solver: {}", params.string("solver").unwrap_or_default());
            effects.push(Effect::Report);
        }
        effects
    }

    /// Act on what the arbiter changed. `by`: what took the joints (a topic, "the
    /// leader arm"), or why a switch deactivated a controller, for the messages.
    fn apply_changes(
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

    /// `switch_controller`: as ros2_control does it (strictness 0 is STRICT, its
    /// default; AUTO and FORCE_AUTO are BEST_EFFORT, as ros2_control has no chains to
    /// follow here either); a best-effort switch that did nothing of what it asked is
    /// not ok.
    fn switch_controller(
        &mut self,
        caller: Caller,
        req: SwitchControllerRequest,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) -> SwitchControllerResponse {
        let strictness = match req.strictness {
            0 | SwitchControllerRequest::STRICT => Strictness::Strict,
            SwitchControllerRequest::BEST_EFFORT
            | SwitchControllerRequest::AUTO
            | SwitchControllerRequest::FORCE_AUTO => Strictness::BestEffort,
            n => {
                return SwitchControllerResponse {
                    ok: false,
                    message: format!(
                        "unknown strictness {n} (BEST_EFFORT 1, STRICT 2, AUTO 3, FORCE_AUTO 4)"
                    ),
                }
            }
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
        let skipped: Vec<String> = out
            .changes
            .iter()
            .filter_map(|c| match c {
                Change::Skipped(name, why) => Some(format!("{name} ({}): {why}", why.code())),
                _ => None,
            })
            .collect();
        let done = out.changes.len() - skipped.len();
        let response = match &out.result {
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
        };
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
            Input::XyzTarget(_) | Input::PoseTarget(_) => Command::ArmTarget,
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

    fn apply(&mut self, batch: Vec<Input>, now: Instant, wall: Time, effects: &mut Vec<Effect>) {
        for input in batch {
            if let Input::Estop(engaged) = input {
                if engaged != self.core.estop() {
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
                continue;
            }
            match input {
                Input::Trajectory(msg) => {
                    self.on_trajectory(msg, wall, now, effects);
                    continue;
                }
                Input::TrajectoryGoal(goal) => {
                    self.on_trajectory_goal(goal, wall, now, effects);
                    continue;
                }
                Input::GripperGoal(goal) => {
                    self.on_gripper_goal(goal, wall, now, effects);
                    continue;
                }
                Input::Cancel(ids) => {
                    self.on_cancel(&ids, wall, effects);
                    continue;
                }
                Input::ServoState(msg) => {
                    self.on_servo_state(&msg, wall, effects);
                    continue;
                }
                Input::LeaderDeadman(held) => {
                    self.on_deadman(held, now, wall, effects);
                    continue;
                }
                Input::LeaderJoints(msg) => {
                    self.on_leader_joints(msg, now, wall, effects);
                    continue;
                }
                Input::ListControllers(ticket, caller) => {
                    self.arbiter
                        .handle(arbiter::Event::OwnerAlive(caller.to_string()), now);
                    effects.push(Effect::ListControllers(ticket, self.list_controllers()));
                    continue;
                }
                Input::SwitchController(ticket, caller, req) => {
                    let answer = self.switch_controller(caller, req, now, wall, effects);
                    effects.push(Effect::SwitchController(ticket, answer));
                    continue;
                }
                _ => {}
            }
            let decision = self.teleop_decision(&input, now);
            let (next, changes) = match decision {
                Some(Err(why)) => {
                    let why = why.to_string();
                    if let Some(rejection) = self.core.reject_held(&input, why, wall) {
                        self.report_rejection(rejection, now, effects);
                    }
                    continue;
                }
                Some(Ok((next, changes))) => (Some(next), changes),
                None => (None, vec![]),
            };
            let Some(result) = self.core.handle(&input, wall) else {
                continue;
            };
            for notice in self.core.take_notices() {
                if let Some(quiet) = self.complaints.allow(&notice.kind, now) {
                    log::info!("{}{}", notice.text, Throttle::suffix(quiet));
                }
            }
            match result {
                Ok(step) => {
                    // the target takes its joints (from a running goal, or a holding
                    // leader): the arbiter's changes, with the topic for the messages
                    if let Some(next) = next {
                        self.arbiter = next;
                    }
                    self.apply_changes(changes, input_topic(&input), wall, effects);
                    if let (Input::GripperTarget(..), Some(_), Some(gm)) = (
                        &input,
                        &self.arm,
                        self.map.as_ref().and_then(|m| m.gripper.as_ref()),
                    ) {
                        // the trajectory keeps the arm; the claw moves on its own
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
                Err(rejection) => self.report_rejection(rejection, now, effects),
            }
        }
    }

    /// A refused target: logged (throttled per topic and reason) and reported at once
    /// (at most every [`MIN_IMMEDIATE_DIAG_GAP`]).
    fn report_rejection(&mut self, rejection: Rejection, now: Instant, effects: &mut Vec<Effect>) {
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
        Input::PoseTarget(_) => "pose_target",
        Input::GripperTarget(..) => "gripper_target",
        Input::JointTarget(_) => "joint_target",
        _ => "another command",
    }
}

impl<M: ArmModel> Driver<M> {
    /// Whether the arbiter would let `command` have its joints now (nothing changes).
    fn may(&self, command: Command, now: Instant) -> Result<(), Refusal> {
        let mut probe = self.arbiter.clone();
        probe
            .handle(arbiter::Event::Command(command), now)
            .result
            .map(|_| ())
    }

    /// `command` takes its joints (the arbiter said it may): whoever held them ends
    /// what it ran (`by` names the taker in the messages).
    fn take(
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

    fn busy(&self) -> bool {
        self.core.is_moving() || self.arm.is_some() || self.gripper.is_some()
    }

    fn refuse(&mut self, what: &str, code: i32, text: &str, effects: &mut Vec<Effect>) {
        let line = format!("{what} refused ({}): {text}", code_name(code));
        log::warn!("{line}");
        self.last_trajectory = Some(line);
        effects.push(Effect::Report);
    }
}

/// The name of a FollowJointTrajectory error code.
pub fn code_name(code: i32) -> &'static str {
    match code {
        Fjt::SUCCESSFUL => "SUCCESSFUL",
        Fjt::INVALID_GOAL => "INVALID_GOAL",
        Fjt::INVALID_JOINTS => "INVALID_JOINTS",
        Fjt::OLD_HEADER_TIMESTAMP => "OLD_HEADER_TIMESTAMP",
        Fjt::PATH_TOLERANCE_VIOLATED => "PATH_TOLERANCE_VIOLATED",
        Fjt::GOAL_TOLERANCE_VIOLATED => "GOAL_TOLERANCE_VIOLATED",
        _ => "unknown",
    }
}

/// Of the inputs that arrived together, the ones to act on, in order: an
/// `xyz_target` followed by a newer one is superseded, and so are a `pose_target` and a
/// `gripper_target` (latest wins); `joint_target`s (which may name only some joints),
/// e-stops and unreadable samples are all kept. Returns them and how many were
/// superseded. Of `servo_state` reports and `arm_controller/joint_trajectory` samples,
/// too, only the newest is kept, uncounted: the count is of targets (`diagnostics`'
/// `superseded`, beside `received`).
pub fn coalesce(batch: Vec<Input>) -> (Vec<Input>, usize) {
    let (batch, _) = burst::latest_wins(batch, |i| match i {
        Input::ServoState(_) => Some(0),
        Input::Trajectory(_) => Some(1),
        Input::LeaderJoints(_) => Some(2),
        _ => None,
    });
    burst::latest_wins(batch, |i| match i {
        Input::XyzTarget(_) => Some(0),
        Input::GripperTarget(..) => Some(1),
        Input::PoseTarget(_) => Some(2),
        _ => None,
    })
}

fn seconds(t: Time) -> f64 {
    t.to_nanos() as f64 * 1e-9
}

/// A Cartesian target's stamp (s), for the lateness check.
fn cartesian_stamp(input: &Input) -> Option<f64> {
    match input {
        Input::XyzTarget(m) => Some(seconds(m.header.stamp)),
        Input::PoseTarget(m) => Some(seconds(m.header.stamp)),
        _ => None,
    }
}
