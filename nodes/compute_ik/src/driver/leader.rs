//! Following a leader arm (`leader/joint_states` while `leader/deadman` is held):
//! whether the follower follows is the arbiter's (`leader_follower` passing); this
//! is what the driver does with a sample, the deadman and a hold.

use super::{Driver, Effect};
use crate::pipeline::ArmModel;
use arbiter::{Change, Command, Controller, Refusal};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use ros_plumbing::logging::Throttle;
use std::time::{Duration, Instant};

/// Without a leader sample for this long, the follower holds (5 samples at 100 Hz).
pub const DEFAULT_LEADER_TIMEOUT: Duration = Duration::from_millis(50);

/// Why the follower holds once the deadman is let go.
const DEADMAN_RELEASED: &str = "deadman released";

/// Following a leader arm (`leader/joint_states`, `leader/deadman`); whether it
/// follows is the arbiter's (`leader_follower` passing).
#[derive(Debug, Default)]
pub(super) struct Leader {
    /// the deadman is held (its latest sample)
    pub(super) deadman: bool,
    /// how long without a sample before holding (for messages; the arbiter times it)
    pub(super) timeout: Duration,
    /// what the follower does, for `diagnostics`
    pub(super) state: LeaderStatus,
}

/// What the follower does with the leader arm (shown in `diagnostics` as `leader`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(super) enum LeaderStatus {
    /// no leader heard yet
    #[default]
    NoLeader,
    /// the deadman held, no sample followed yet
    Waiting,
    /// following the samples; the last one refused and why, if it was
    Following {
        /// why the latest sample was not taken (outside the follower's limits)
        refused: Option<String>,
    },
    /// holding where it is, and why
    Holding(String),
}

impl LeaderStatus {
    /// Following (the latest sample taken or not).
    pub(super) fn is_following(&self) -> bool {
        matches!(self, LeaderStatus::Following { .. })
    }
}

impl std::fmt::Display for LeaderStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LeaderStatus::NoLeader => write!(f, "no leader"),
            LeaderStatus::Waiting => write!(f, "deadman held, waiting for a leader sample"),
            LeaderStatus::Following { refused: None } => write!(f, "following"),
            LeaderStatus::Following {
                refused: Some(reason),
            } => write!(f, "following, this pose refused: {reason}"),
            LeaderStatus::Holding(why) => write!(f, "holding: {why}"),
        }
    }
}

impl<M: ArmModel> Driver<M> {
    /// The follower holds where it is (the arbiter stopped `leader_follower`).
    pub(super) fn hold_leader(&mut self, why: String, effects: &mut Vec<Effect>) {
        if self.leader.state.is_following() {
            self.core.stop_motion();
            log::info!("leader: {why}: the follower holds");
            effects.push(Effect::Report);
        }
        self.leader.state = LeaderStatus::Holding(why);
    }

    /// A `leader/deadman` sample: the arbiter told (releasing it holds the follower).
    pub(super) fn on_deadman(
        &mut self,
        held: bool,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        self.leader.deadman = held;
        let out = self.arbiter.handle(arbiter::Event::Deadman(held), now);
        self.apply_changes(out.changes, "", wall, effects);
        if !held {
            self.leader.state = LeaderStatus::Holding(DEADMAN_RELEASED.into());
        } else if !self.arbiter.passes(Controller::LeaderFollower) {
            self.leader.state = LeaderStatus::Waiting;
        }
    }

    /// A leader sample: followed (a joint target for its joints, within the motion
    /// limits) while the deadman is held and the arbiter lets `leader_follower` have
    /// the arm.
    pub(super) fn on_leader_joints(
        &mut self,
        msg: JointState,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let out = self
            .arbiter
            .handle(arbiter::Event::Command(Command::LeaderSample), now);
        if let Err(why) = out.result {
            self.leader_not_followed(why, effects);
            return;
        }
        let starts = out
            .changes
            .contains(&Change::Activated(Controller::LeaderFollower))
            || !self.leader.state.is_following();
        self.apply_changes(out.changes, "the leader arm", wall, effects);
        if starts {
            log::info!("leader: deadman held: the follower follows");
            effects.push(Effect::Report);
        }
        self.follow_leader(msg, now, wall, effects);
    }

    /// The arbiter refused a leader sample (`why`): the follower's state says why.
    fn leader_not_followed(&mut self, why: Refusal, effects: &mut Vec<Effect>) {
        let why = match why {
            Refusal::DeadmanReleased => {
                if self.leader.state == LeaderStatus::NoLeader {
                    self.leader.state = LeaderStatus::Holding(DEADMAN_RELEASED.into());
                }
                return;
            }
            Refusal::Calibrating => "calibrating".to_string(),
            Refusal::Estop => "emergency stop engaged".to_string(),
            why => why.to_string(),
        };
        let holding = LeaderStatus::Holding(why);
        if self.leader.state != holding {
            log::info!("leader sample not followed: {}", holding);
            effects.push(Effect::Report);
        }
        self.leader.state = holding;
    }

    /// The follower retargeted to a leader sample it may follow (its joints, within
    /// the motion limits), the first step of a new motion at once.
    fn follow_leader(
        &mut self,
        msg: JointState,
        now: Instant,
        wall: Time,
        effects: &mut Vec<Effect>,
    ) {
        let target = JointState {
            header: Header {
                stamp: Time::ZERO,
                frame_id: String::new(),
            },
            ..msg
        };
        match self.core.retarget_joints(&target, wall) {
            Ok(()) => {
                self.leader.state = LeaderStatus::Following { refused: None };
                // stepped at the motion rate, whatever the leader's rate; the first
                // step of a new motion at once
                if self.next_step.is_none() {
                    if let Some(step) = self.core.step(wall) {
                        effects.push(Effect::Publish(step));
                    }
                    self.next_step = Some(now + self.step_period());
                }
            }
            Err(reason) => {
                // outside the follower's limits (or malformed): not followed, the
                // follower goes on to the last pose it could take
                self.leader.state = LeaderStatus::Following {
                    refused: Some(reason.to_string()),
                };
                if let Some(quiet) = self.complaints.allow("leader/refused", now) {
                    log::warn!(
                        "leader sample not followed: {reason}{}",
                        Throttle::suffix(quiet)
                    );
                }
            }
        }
    }
}
