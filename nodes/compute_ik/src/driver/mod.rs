//! The node's loop policy around a [`Pipeline`], on a clock it is given (as
//! `servo_protocol::host` is): which inputs of a burst are applied, a late target held
//! back for a newer one (the [`CommandGate`] serial_node shares), when the planned
//! motion steps, when a refusal is reported at
//! once, and the pose sent to a new `joint_states` subscriber. Events in, [`Effect`]s
//! out; [`crate::run`] does the I/O.
//!
//! Who moves the arm is the arbiter's (`libs/arbiter`); the driver wires it. Here the
//! driver's state, its entry points ([`Driver::on_inputs`] routes each input to its
//! handler, [`Driver::on_time`], [`Driver::on_poll`], [`Driver::on_params`]) and
//! `diagnostics`; by commander: `teleop` (the targets), `trajectory`
//! (arm_controller), `gripper` (gripper_controller), `leader` (leader_follower),
//! and `arbitration` (the arbiter's changes acted on, the e-stop, calibration,
//! `list_controllers` and `switch_controller`).

use crate::controller::{Actual, ControllerMap, ControllerSettings};
use crate::pipeline::{ArmModel, Input, Pipeline, Step};
use arbiter::{Arbiter, Controller, Layout};
use command_gate::{CommandGate, Stamp, Verdict};
use eezybot_motion::AxisState;
use eezybot_msgs::control_msgs::{
    FollowJointTrajectoryFeedback, FollowJointTrajectoryResult as Fjt, GripperCommandResult,
    JointTrajectoryControllerState,
};
use eezybot_msgs::controller_manager_msgs::{ListControllersResponse, SwitchControllerResponse};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use ros_plumbing::action::{self, GoalEnd, GoalId};
use ros_plumbing::burst;
use ros_plumbing::feedback;
use ros_plumbing::logging::Throttle;
use ros_plumbing::service::Ticket;
use ros_plumbing::Params;
use std::time::{Duration, Instant};

mod arbitration;
mod gripper;
mod leader;
mod teleop;
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
        ticket: action::Ticket,
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
                state: Default::default(),
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
            ("leader".to_string(), self.leader.state.to_string()),
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

    /// One motion step's period.
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
            // the gate holds Cartesian targets only (xyz_target, pose_target)
            self.on_target(m, now, wall, &mut effects);
        }
        effects
    }

    /// Inputs that arrived together at `now`: of a kind where the latest wins, the
    /// newest only; a late Cartesian target held back for a newer one. Each input
    /// goes to its handler from here (an `xyz_target` to `Driver::on_target`:
    /// two calls from [`crate::run`]).
    pub fn on_inputs(&mut self, arrived: Vec<Input>, now: Instant, wall: Time) -> Vec<Effect> {
        let mut effects = vec![];
        let fx = &mut effects;
        for input in self.admit(arrived, now, wall) {
            match input {
                Input::Estop(engaged) => self.on_estop(engaged, now, wall, fx),
                Input::Trajectory(msg) => self.on_trajectory(msg, wall, now, fx),
                Input::TrajectoryGoal(goal) => self.on_trajectory_goal(goal, wall, now, fx),
                Input::GripperGoal(goal) => self.on_gripper_goal(goal, wall, now, fx),
                Input::Cancel(ids) => self.on_cancel(&ids, wall, fx),
                Input::ServoState(msg) => self.on_servo_state(&msg, wall, fx),
                Input::LeaderDeadman(held) => self.on_deadman(held, now, wall, fx),
                Input::LeaderJoints(msg) => self.on_leader_joints(msg, now, wall, fx),
                Input::ListControllers(ticket, caller) => {
                    self.on_list_controllers(ticket, caller, now, fx)
                }
                Input::SwitchController(ticket, caller, req) => {
                    self.on_switch_controller(ticket, caller, req, now, wall, fx)
                }
                target @ (Input::XyzTarget(_)
                | Input::XyzLineTarget(_)
                | Input::PoseTarget(_)
                | Input::JointTarget(_)
                | Input::GripperTarget(..)
                | Input::Unreadable(..)) => self.on_target(target, now, wall, fx),
            }
        }
        effects
    }

    /// Of inputs that arrived together, the ones to apply now, in order: of a kind
    /// where the latest wins, the newest only ([`coalesce`]); a late Cartesian target
    /// held back by the gate for a newer one (its due time is [`Driver::deadline`]'s).
    fn admit(&mut self, arrived: Vec<Input>, now: Instant, wall: Time) -> Vec<Input> {
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
        batch
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

    /// Whether the motion steps on: the pipeline moving, a trajectory or a gripper
    /// goal running.
    fn busy(&self) -> bool {
        self.core.is_moving() || self.arm.is_some() || self.gripper.is_some()
    }

    /// A trajectory or a gripper goal refused (`what`, with a FollowJointTrajectory
    /// `code`): logged, kept for `diagnostics` (`last_trajectory`), reported.
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
        // the newest xyz target wins, either kind
        Input::XyzTarget(_) | Input::XyzLineTarget(_) => Some(0),
        Input::GripperTarget(..) => Some(1),
        Input::PoseTarget(_) => Some(2),
        _ => None,
    })
}

/// A stamp in seconds.
fn seconds(t: Time) -> f64 {
    t.to_nanos() as f64 * 1e-9
}

/// A Cartesian target's stamp (s), for the lateness check.
fn cartesian_stamp(input: &Input) -> Option<f64> {
    match input {
        Input::XyzTarget(m) | Input::XyzLineTarget(m) => Some(seconds(m.header.stamp)),
        Input::PoseTarget(m) => Some(seconds(m.header.stamp)),
        _ => None,
    }
}
