//! Who moves the arm. Five commanders share it, named and switched as ros2_control's
//! controllers are:
//!
//! | controller | claims (`<joint>/position`) | commands |
//! |---|---|---|
//! | `teleop` | the arm's joints | `xyz_target`, `pose_target`, `joint_target` |
//! | `arm_controller` | the arm's joints | `arm_controller/follow_joint_trajectory`, `arm_controller/joint_trajectory` |
//! | `gripper_controller` | the claw | `gripper_controller/gripper_cmd`, `gripper_target` |
//! | `leader_follower` | the arm's joints and the claw | `leader/joint_states` while `leader/deadman` is held |
//! | `calibration` | the arm's joints and the claw | the calibration wizard's servo jogs |
//!
//! An active controller holds the interfaces it claims; no two active controllers claim
//! one interface, so at most one commander's output reaches a joint in any period. The
//! e-stop is a lock above them all: while it is engaged nothing passes, whoever is active.
//!
//! [`Arbiter::handle`] is the one transition function: a switch request, a commander's
//! command (a target, a goal, a leader sample), a goal's end, the deadman, the e-stop, an
//! owner heard, and time passing (the leader's sample timeout, the calibration owner's
//! lease) all come through it, and it says what it decided and what changed. It keeps no
//! clock of its own: every event comes with the time it happened at.
//!
//! `teleop` and `gripper_controller` are active at start: an operator's targets move the
//! arm and the claw. As `arm_controller` takes trajectories both from its action and its
//! topic, `gripper_controller` takes the claw's commands from its action and from
//! `gripper_target`; a `joint_target` that names the claw's joint is teleop's and
//! gripper_controller's at once.
//!
//! Beside explicit switches (`switch_controller`), the rules users know take the arm on
//! demand: a command for an inactive `teleop`, `arm_controller`, `gripper_controller` or
//! `leader_follower` activates it, deactivating whoever held its interfaces, if they may
//! be preempted ([`Arbiter::preemptible`]): anyone but `calibration` and a
//! `leader_follower` that follows (its deadman held). README.md has the table.

use std::fmt;
use std::time::{Duration, Instant};

/// One of the five commanders.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Controller {
    /// the operator's targets for the arm: `xyz_target`, `pose_target`, `joint_target`
    Teleop,
    /// trajectories: FollowJointTrajectory goals and `arm_controller/joint_trajectory`
    ArmController,
    /// the claw: GripperCommand goals and `gripper_target`
    GripperController,
    /// a leader arm's joints, while its deadman is held
    LeaderFollower,
    /// the calibration wizard's servo jogs
    Calibration,
}

impl Controller {
    /// All five, in the order `list_controllers` gives them.
    pub const ALL: [Controller; 5] = [
        Controller::Teleop,
        Controller::ArmController,
        Controller::GripperController,
        Controller::LeaderFollower,
        Controller::Calibration,
    ];

    /// The controller's name (ros2_control's `name`).
    pub fn name(self) -> &'static str {
        match self {
            Controller::Teleop => "teleop",
            Controller::ArmController => "arm_controller",
            Controller::GripperController => "gripper_controller",
            Controller::LeaderFollower => "leader_follower",
            Controller::Calibration => "calibration",
        }
    }

    /// The controller of that name.
    pub fn from_name(name: &str) -> Option<Controller> {
        Controller::ALL.into_iter().find(|c| c.name() == name)
    }

    /// Its type, as `list_controllers` shows it (ros2_controllers' types where ours
    /// behave as theirs do).
    pub fn type_name(self) -> &'static str {
        match self {
            Controller::Teleop => "eezybot/TeleopController",
            Controller::ArmController => "joint_trajectory_controller/JointTrajectoryController",
            Controller::GripperController => "position_controllers/GripperActionController",
            Controller::LeaderFollower => "eezybot/LeaderFollowerController",
            Controller::Calibration => "eezybot/CalibrationController",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

impl fmt::Display for Controller {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The arm's joints: the arm's own (claimed by `teleop` and `arm_controller`) and the
/// claw's, if it has one (claimed by `gripper_controller`). `leader_follower` and
/// `calibration` claim them all.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// the arm's joints, e.g. `base_joint`, `shoulder_joint`, `elbow_joint`
    pub arm: Vec<String>,
    /// the claw's joint, e.g. `claw_joint`
    pub gripper: Option<String>,
}

impl Layout {
    /// Every joint: the arm's, then the claw's.
    pub fn joints(&self) -> impl Iterator<Item = &str> {
        self.arm.iter().chain(&self.gripper).map(String::as_str)
    }
}

/// ros2_control's `strictness` of a switch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strictness {
    /// (1) do what can be done; skip the rest, saying why
    BestEffort,
    /// (2) all or nothing: any part that cannot be done refuses the whole switch
    Strict,
}

/// Who asked for a switch (the calibration's owner must keep being heard).
pub type Owner = String;

/// A `switch_controller` request.
#[derive(Clone, Debug, PartialEq)]
pub struct Switch {
    /// names to activate
    pub activate: Vec<String>,
    /// names to deactivate
    pub deactivate: Vec<String>,
    /// all or nothing, or as much as can be
    pub strictness: Strictness,
    /// who asked (the owner of a calibration it activates)
    pub owner: Owner,
    /// a calibration it activates is given back when its owner is not heard from
    /// within the lease ([`Arbiter::set_owner_lease`]); else it stays until switched off
    pub lease: bool,
}

/// A commander's command: it moves the arm if the arbiter lets it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// `xyz_target`, `pose_target`, or a `joint_target` of the arm's joints only
    ArmTarget,
    /// a `joint_target` that names the claw's joint (and maybe the arm's)
    ArmAndClawTarget,
    /// `gripper_target`
    ClawTarget,
    /// a FollowJointTrajectory goal or an `arm_controller/joint_trajectory` message
    Trajectory,
    /// a GripperCommand goal
    GripperGoal,
    /// a `leader/joint_states` sample
    LeaderSample,
}

/// What happened.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// `switch_controller`
    Switch(Switch),
    /// a commander wants to move the arm
    Command(Command),
    /// the running trajectory (`ArmController`) or gripper goal (`GripperController`)
    /// ended on its own: done, failed or canceled by its client
    Finished(Controller),
    /// `leader/deadman`: held (true) or released
    Deadman(bool),
    /// `estop`: engaged (true) or released
    Estop(bool),
    /// the owner of a calibration was heard from (it renews its lease)
    OwnerAlive(Owner),
    /// time passed (the leader's timeout, the calibration owner's lease)
    Tick,
}

/// Why a request was refused. Each has one code ([`Refusal::code`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Refusal {
    /// the e-stop is engaged: nothing moves
    #[error("emergency stop engaged: nothing moves until it is released")]
    Estop,
    /// calibration has the arm
    #[error("calibrating: the calibration wizard has the arm until `calibration` is deactivated")]
    Calibrating,
    /// the leader arm follows (its deadman held) and is not preempted by a command
    #[error("{joint} is held by leader_follower (the leader's deadman is held)")]
    Following {
        /// the first joint asked for that it holds
        joint: String,
    },
    /// a leader sample with the deadman released: not followed
    #[error("the leader's deadman is released: the follower holds")]
    DeadmanReleased,
    /// no controller of that name
    #[error("no controller named `{0}` (teleop, arm_controller, gripper_controller, leader_follower, calibration)")]
    UnknownController(String),
    /// to activate, but active already
    #[error("{0} is active already")]
    AlreadyActive(Controller),
    /// to deactivate, but not active
    #[error("{0} is not active")]
    NotActive(Controller),
    /// the switch would leave an interface claimed by two active controllers
    #[error("{joint}/position would be claimed by both {first} and {second}: deactivate one in the same switch")]
    DoubleClaim {
        /// the joint
        joint: String,
        /// one claimant
        first: Controller,
        /// the other
        second: Controller,
    },
    /// the controller claims nothing on this arm (a claw's, on an arm without one)
    #[error("{0} has no interfaces on this arm (it has no claw)")]
    NoInterfaces(Controller),
}

impl Refusal {
    /// The refusal's code, for `diagnostics` (one code for one reason).
    pub fn code(&self) -> &'static str {
        match self {
            Refusal::Estop => "estop",
            Refusal::Calibrating => "calibrating",
            Refusal::Following { .. } => "leader_following",
            Refusal::DeadmanReleased => "deadman_released",
            Refusal::UnknownController(_) => "unknown_controller",
            Refusal::AlreadyActive(_) => "already_active",
            Refusal::NotActive(_) => "not_active",
            Refusal::DoubleClaim { .. } => "double_claim",
            Refusal::NoInterfaces(_) => "no_interfaces",
        }
    }
}

/// Why what a controller ran ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Why {
    /// another commander took its interfaces
    PreemptedBy(Controller),
    /// a newer command of its own (a `gripper_target` or a `joint_target` naming the
    /// claw, during a gripper goal)
    Superseded,
    /// `switch_controller` deactivated it
    Switched,
    /// the e-stop was engaged
    Estop,
    /// the leader's deadman was released
    DeadmanReleased,
    /// no leader sample within the leader's timeout
    LeaderTimeout,
    /// the calibration's owner was not heard from within the lease
    OwnerGone,
}

impl fmt::Display for Why {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Why::PreemptedBy(c) => write!(f, "preempted by {c}"),
            Why::Superseded => f.write_str("preempted by a newer command"),
            Why::Switched => f.write_str("deactivated by switch_controller"),
            Why::Estop => f.write_str("emergency stop engaged"),
            Why::DeadmanReleased => f.write_str("deadman released"),
            Why::LeaderTimeout => f.write_str("no leader sample within the leader's timeout"),
            Why::OwnerGone => {
                f.write_str("its owner was not heard from within the lease: the arm is given back")
            }
        }
    }
}

/// What changed; the node acts on each (ends goals, holds, takes the arm back).
#[derive(Clone, Debug, PartialEq)]
pub enum Change {
    /// now active
    Activated(Controller),
    /// now inactive: what it ran ends, the joints it claimed hold where they are
    Deactivated(Controller, Why),
    /// still active, but what it ran ends (a goal aborted, the leader no longer
    /// followed) and its joints hold
    Stopped(Controller, Why),
    /// a part of a best-effort switch that was not done
    Skipped(String, Refusal),
}

/// The arbiter's answer to an event.
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    /// a command: `Ok(controller that carries it)`; a switch: `Ok(None)` when done (a
    /// best-effort one maybe in part: see the changes); otherwise `Ok(None)`
    pub result: Result<Option<Controller>, Refusal>,
    /// what changed, in order
    pub changes: Vec<Change>,
}

/// An active controller's state.
#[derive(Clone, Debug, PartialEq)]
pub enum Mode {
    /// `teleop`: moves to the operator's latest target
    Teleop,
    /// `arm_controller`: executing a trajectory, or idle (holding)
    Trajectory {
        /// a trajectory is executing
        running: bool,
    },
    /// `gripper_controller`: a goal running, or idle
    Gripper {
        /// a goal is running
        running: bool,
    },
    /// `leader_follower`: following (deadman held, samples fresh) or holding
    Leader {
        /// when it holds if no further sample comes (following), or None (holding)
        until: Option<Instant>,
    },
    /// `calibration`: its owner and when it was last heard from
    Calibration {
        /// who activated it
        owner: Owner,
        /// when it was last heard from (None: no lease, it stays until switched off)
        heard: Option<Instant>,
    },
}

/// A controller as `list_controllers` shows it.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerInfo {
    /// which
    pub controller: Controller,
    /// `active` or `inactive`
    pub active: bool,
    /// its interfaces, `<joint>/position` (claimed while active)
    pub interfaces: Vec<String>,
    /// what it does now, for `diagnostics`
    pub detail: String,
}

/// Joint `i`'s bit in a claim; the arbiter tracks the first 128 joints of an arm (a
/// serial arm has far fewer; any beyond are claimed by nobody).
fn bit(i: usize) -> u128 {
    if i < 128 {
        1 << i
    } else {
        0
    }
}

/// Without a leader sample for this long, the follower holds (5 samples at 100 Hz).
pub const DEFAULT_LEADER_TIMEOUT: Duration = Duration::from_millis(50);

/// A calibration whose owner is not heard from for this long gives the arm back.
pub const DEFAULT_OWNER_LEASE: Duration = Duration::from_secs(10);

/// The arbiter: which controllers are active and in what state, and the e-stop.
#[derive(Clone, Debug)]
pub struct Arbiter {
    layout: Layout,
    /// each controller's claims, a bit per joint (of [`Layout::joints`])
    claims: [u128; 5],
    active: [Option<Mode>; 5],
    estop: bool,
    deadman: bool,
    leader_timeout: Duration,
    owner_lease: Duration,
}

impl Arbiter {
    /// For this arm, with `teleop` and `gripper_controller` (if it has a claw) active
    /// (the operator's targets move the arm and the claw as they always did), the
    /// e-stop released and the deadman not held.
    pub fn new(layout: Layout) -> Arbiter {
        let arm: u128 = (0..layout.arm.len()).map(bit).fold(0, |a, b| a | b);
        let claw: u128 = layout.gripper.as_ref().map_or(0, |_| bit(layout.arm.len()));
        let mut active: [Option<Mode>; 5] = Default::default();
        active[Controller::Teleop.index()] = Some(Mode::Teleop);
        if claw != 0 {
            active[Controller::GripperController.index()] = Some(Mode::Gripper { running: false });
        }
        Arbiter {
            claims: [arm, arm, claw, arm | claw, arm | claw],
            layout,
            active,
            estop: false,
            deadman: false,
            leader_timeout: DEFAULT_LEADER_TIMEOUT,
            owner_lease: DEFAULT_OWNER_LEASE,
        }
    }

    /// How long without a leader sample before the follower holds.
    pub fn set_leader_timeout(&mut self, timeout: Duration) {
        self.leader_timeout = timeout;
    }

    /// How long a calibration's owner may stay silent before the arm is given back.
    pub fn set_owner_lease(&mut self, lease: Duration) {
        self.owner_lease = lease;
    }

    /// The arm's joints.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// The e-stop is engaged.
    pub fn estop(&self) -> bool {
        self.estop
    }

    /// `c`'s state, if active.
    pub fn mode(&self, c: Controller) -> Option<&Mode> {
        self.active[c.index()].as_ref()
    }

    /// `c` is active.
    pub fn is_active(&self, c: Controller) -> bool {
        self.active[c.index()].is_some()
    }

    /// `c`'s output reaches the servos now: active, the e-stop released, and for the
    /// leader, following.
    pub fn passes(&self, c: Controller) -> bool {
        !self.estop
            && match self.mode(c) {
                None => false,
                Some(Mode::Leader { until }) => until.is_some(),
                Some(_) => true,
            }
    }

    /// Who commands joint `i` (of [`Layout::joints`]) now: none under the e-stop, when
    /// nobody active claims it, or when its holder holds.
    pub fn commander_of(&self, i: usize) -> Option<Controller> {
        Controller::ALL
            .into_iter()
            .find(|&c| self.passes(c) && self.claims[c.index()] & bit(i) != 0)
    }

    /// Whether an active `c` may be preempted by a command of another: anyone but
    /// `calibration` and a following `leader_follower`.
    pub fn preemptible(&self, c: Controller) -> bool {
        match self.mode(c) {
            None => true,
            Some(Mode::Calibration { .. }) => false,
            Some(Mode::Leader { until }) => until.is_none(),
            Some(_) => true,
        }
    }

    /// When [`Event::Tick`] is next due: the leader's timeout, the owner's lease.
    pub fn deadline(&self) -> Option<Instant> {
        self.active
            .iter()
            .flatten()
            .filter_map(|m| match m {
                Mode::Leader { until } => *until,
                Mode::Calibration { heard, .. } => heard.map(|t| t + self.owner_lease),
                _ => None,
            })
            .min()
    }

    /// The controllers, as `list_controllers` shows them.
    pub fn controllers(&self) -> Vec<ControllerInfo> {
        Controller::ALL
            .into_iter()
            .map(|c| ControllerInfo {
                controller: c,
                active: self.is_active(c),
                interfaces: self.interfaces(c),
                detail: self.detail(c),
            })
            .collect()
    }

    /// `c`'s interfaces, `<joint>/position`.
    pub fn interfaces(&self, c: Controller) -> Vec<String> {
        self.layout
            .joints()
            .enumerate()
            .filter(|(i, _)| self.claims[c.index()] & bit(*i) != 0)
            .map(|(_, j)| format!("{j}/position"))
            .collect()
    }

    fn detail(&self, c: Controller) -> String {
        let state = match self.mode(c) {
            None => return "inactive".into(),
            Some(Mode::Teleop) => "active".to_string(),
            Some(Mode::Trajectory { running: true }) => "executing a trajectory".into(),
            Some(Mode::Gripper { running: true }) => "executing a goal".into(),
            Some(Mode::Trajectory { .. } | Mode::Gripper { .. }) => "active, idle".into(),
            Some(Mode::Leader { until: Some(_) }) => "following".into(),
            Some(Mode::Leader { until: None }) => "holding (deadman released)".into(),
            Some(Mode::Calibration { owner, .. }) => format!("calibrating for {owner}"),
        };
        if self.estop {
            format!("{state}; emergency stop engaged: holding")
        } else {
            state
        }
    }

    /// The one transition function: `event` at `now`.
    pub fn handle(&mut self, event: Event, now: Instant) -> Outcome {
        let mut changes = vec![];
        let result = match event {
            Event::Switch(s) => self.switch(s, now, &mut changes).map(|()| None),
            Event::Command(c) => self.command(c, now, &mut changes).map(Some),
            Event::Finished(c) => {
                self.finished(c);
                Ok(None)
            }
            Event::Deadman(held) => {
                self.deadman = held;
                if !held {
                    self.hold_leader(Why::DeadmanReleased, &mut changes);
                }
                Ok(None)
            }
            Event::Estop(engaged) => {
                if engaged && !self.estop {
                    self.stop_all(&mut changes);
                }
                self.estop = engaged;
                Ok(None)
            }
            Event::OwnerAlive(who) => {
                if let Some(Mode::Calibration { owner, heard }) =
                    &mut self.active[Controller::Calibration.index()]
                {
                    if *owner == who && heard.is_some() {
                        *heard = Some(now);
                    }
                }
                Ok(None)
            }
            Event::Tick => {
                self.expire(now, &mut changes);
                Ok(None)
            }
        };
        Outcome { result, changes }
    }

    /// [`Event::Finished`]: `c`'s trajectory or goal ended on its own (it needs no
    /// time, and changes nothing else).
    pub fn finished(&mut self, c: Controller) {
        if let Some(Mode::Trajectory { running } | Mode::Gripper { running }) =
            &mut self.active[c.index()]
        {
            *running = false;
        }
    }

    /// The e-stop engaged: every running thing stops (the controllers stay active).
    fn stop_all(&mut self, changes: &mut Vec<Change>) {
        for c in Controller::ALL {
            let stopped = match &mut self.active[c.index()] {
                Some(Mode::Trajectory { running } | Mode::Gripper { running }) => {
                    std::mem::replace(running, false)
                }
                Some(Mode::Leader { until }) => until.take().is_some(),
                Some(Mode::Teleop) => true, // its motion stops
                _ => false,
            };
            if stopped {
                changes.push(Change::Stopped(c, Why::Estop));
            }
        }
    }

    fn hold_leader(&mut self, why: Why, changes: &mut Vec<Change>) {
        if let Some(Mode::Leader { until }) = &mut self.active[Controller::LeaderFollower.index()] {
            if until.take().is_some() {
                changes.push(Change::Stopped(Controller::LeaderFollower, why));
            }
        }
    }

    /// Timeouts due at `now`.
    fn expire(&mut self, now: Instant, changes: &mut Vec<Change>) {
        if let Some(Mode::Leader { until: Some(t) }) =
            &self.active[Controller::LeaderFollower.index()]
        {
            if *t <= now {
                self.hold_leader(Why::LeaderTimeout, changes);
            }
        }
        if let Some(Mode::Calibration {
            heard: Some(heard), ..
        }) = &self.active[Controller::Calibration.index()]
        {
            if *heard + self.owner_lease <= now {
                self.deactivate(Controller::Calibration, Why::OwnerGone, changes);
            }
        }
    }

    fn deactivate(&mut self, c: Controller, why: Why, changes: &mut Vec<Change>) {
        if self.active[c.index()].take().is_some() {
            changes.push(Change::Deactivated(c, why));
        }
    }

    fn activate(
        &mut self,
        c: Controller,
        (owner, lease): (&str, bool),
        now: Instant,
        changes: &mut Vec<Change>,
    ) {
        self.active[c.index()] = Some(match c {
            Controller::Teleop => Mode::Teleop,
            Controller::ArmController => Mode::Trajectory { running: false },
            Controller::GripperController => Mode::Gripper { running: false },
            Controller::LeaderFollower => Mode::Leader { until: None },
            Controller::Calibration => Mode::Calibration {
                owner: owner.to_string(),
                heard: lease.then_some(now),
            },
        });
        changes.push(Change::Activated(c));
    }

    /// The active controllers other than `c` whose claims overlap `c`'s.
    fn holders(&self, c: Controller) -> Vec<Controller> {
        Controller::ALL
            .into_iter()
            .filter(|&d| {
                d != c && self.is_active(d) && self.claims[d.index()] & self.claims[c.index()] != 0
            })
            .collect()
    }

    fn first_joint(&self, mask: u128) -> String {
        self.layout
            .joints()
            .enumerate()
            .find(|(i, _)| mask & bit(*i) != 0)
            .map_or_else(String::new, |(_, j)| j.to_string())
    }

    /// Make `c` active on demand, taking its interfaces from preemptible holders.
    fn take(
        &mut self,
        c: Controller,
        now: Instant,
        changes: &mut Vec<Change>,
    ) -> Result<(), Refusal> {
        if self.is_active(c) {
            return Ok(());
        }
        if self.claims[c.index()] == 0 {
            return Err(Refusal::NoInterfaces(c));
        }
        let holders = self.holders(c);
        if let Some(&d) = holders.iter().find(|&&d| !self.preemptible(d)) {
            return Err(match d {
                Controller::Calibration => Refusal::Calibrating,
                _ => Refusal::Following {
                    joint: self.first_joint(self.claims[d.index()] & self.claims[c.index()]),
                },
            });
        }
        for d in holders {
            self.deactivate(d, Why::PreemptedBy(c), changes);
        }
        self.activate(c, ("", false), now, changes);
        Ok(())
    }

    /// A command: all of it is carried, or none (a refusal changes nothing).
    fn command(
        &mut self,
        cmd: Command,
        now: Instant,
        changes: &mut Vec<Change>,
    ) -> Result<Controller, Refusal> {
        if self.estop {
            return Err(Refusal::Estop);
        }
        if self.is_active(Controller::Calibration) {
            return Err(Refusal::Calibrating);
        }
        let mut next = self.clone();
        let mut made = vec![];
        let carrier = next.carry(cmd, now, &mut made)?;
        *self = next;
        changes.extend(made);
        Ok(carrier)
    }

    fn carry(
        &mut self,
        cmd: Command,
        now: Instant,
        changes: &mut Vec<Change>,
    ) -> Result<Controller, Refusal> {
        match cmd {
            Command::ArmTarget => {
                self.take(Controller::Teleop, now, changes)?;
                Ok(Controller::Teleop)
            }
            Command::ArmAndClawTarget => {
                self.take(Controller::Teleop, now, changes)?;
                self.claw_command(now, changes)?;
                Ok(Controller::Teleop)
            }
            Command::ClawTarget => {
                self.claw_command(now, changes)?;
                Ok(Controller::GripperController)
            }
            Command::Trajectory => {
                self.take(Controller::ArmController, now, changes)?;
                self.active[Controller::ArmController.index()] =
                    Some(Mode::Trajectory { running: true });
                Ok(Controller::ArmController)
            }
            Command::GripperGoal => {
                self.take(Controller::GripperController, now, changes)?;
                self.active[Controller::GripperController.index()] =
                    Some(Mode::Gripper { running: true });
                Ok(Controller::GripperController)
            }
            Command::LeaderSample => {
                if !self.deadman {
                    return Err(Refusal::DeadmanReleased);
                }
                self.take(Controller::LeaderFollower, now, changes)?;
                self.active[Controller::LeaderFollower.index()] = Some(Mode::Leader {
                    until: Some(now + self.leader_timeout),
                });
                Ok(Controller::LeaderFollower)
            }
        }
    }

    /// A target for the claw (not a goal): gripper_controller's; a running goal of it
    /// is superseded.
    fn claw_command(&mut self, now: Instant, changes: &mut Vec<Change>) -> Result<(), Refusal> {
        self.take(Controller::GripperController, now, changes)?;
        if let Some(Mode::Gripper { running }) =
            &mut self.active[Controller::GripperController.index()]
        {
            if std::mem::replace(running, false) {
                changes.push(Change::Stopped(
                    Controller::GripperController,
                    Why::Superseded,
                ));
            }
        }
        Ok(())
    }

    /// `switch_controller`, as ros2_control does it: the names must be known, a
    /// controller activated must be inactive (unless deactivated in the same switch),
    /// one deactivated must be active, the result must claim no interface twice, and
    /// nothing is activated under the e-stop. Strict: any of these refuses the whole
    /// switch; best effort: that part is skipped.
    fn switch(
        &mut self,
        s: Switch,
        now: Instant,
        changes: &mut Vec<Change>,
    ) -> Result<(), Refusal> {
        let strict = s.strictness == Strictness::Strict;
        let mut skipped = vec![];
        let mut fail = |name: &str, r: Refusal| -> Result<(), Refusal> {
            if strict {
                Err(r)
            } else {
                skipped.push(Change::Skipped(name.to_string(), r));
                Ok(())
            }
        };
        let mut deactivate = vec![];
        for name in &s.deactivate {
            match Controller::from_name(name) {
                None => fail(name, Refusal::UnknownController(name.clone()))?,
                Some(c) if !self.is_active(c) => fail(name, Refusal::NotActive(c))?,
                Some(c) if !deactivate.contains(&c) => deactivate.push(c),
                Some(_) => {}
            }
        }
        let mut activate = vec![];
        for name in &s.activate {
            match Controller::from_name(name) {
                None => fail(name, Refusal::UnknownController(name.clone()))?,
                Some(_) if self.estop => fail(name, Refusal::Estop)?,
                Some(c) if self.is_active(c) && !deactivate.contains(&c) => {
                    fail(name, Refusal::AlreadyActive(c))?
                }
                Some(c) if self.claims[c.index()] == 0 => fail(name, Refusal::NoInterfaces(c))?,
                Some(c) if !activate.contains(&c) => activate.push(c),
                Some(_) => {}
            }
        }
        // the result: who stays, then each activated in turn, none claiming twice
        let mut held: Vec<Controller> = Controller::ALL
            .into_iter()
            .filter(|&c| self.is_active(c) && !deactivate.contains(&c))
            .collect();
        let mut admitted = vec![];
        for c in activate {
            let clash = held
                .iter()
                .find(|&&d| self.claims[d.index()] & self.claims[c.index()] != 0);
            if let Some(&d) = clash {
                fail(
                    c.name(),
                    Refusal::DoubleClaim {
                        joint: self.first_joint(self.claims[d.index()] & self.claims[c.index()]),
                        first: d,
                        second: c,
                    },
                )?;
            } else {
                held.push(c);
                admitted.push(c);
            }
        }
        for c in deactivate {
            self.deactivate(c, Why::Switched, changes);
        }
        for c in admitted {
            self.activate(c, (&s.owner, s.lease), now, changes);
        }
        changes.extend(skipped);
        Ok(())
    }
}
