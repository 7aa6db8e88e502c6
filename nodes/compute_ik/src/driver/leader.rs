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

/// Following a leader arm (`leader/joint_states`, `leader/deadman`); whether it
/// follows is the arbiter's (`leader_follower` passing).
#[derive(Debug, Default)]
pub(super) struct Leader {
    /// the deadman is held (its latest sample)
    pub(super) deadman: bool,
    /// how long without a sample before holding (for messages; the arbiter times it)
    pub(super) timeout: Duration,
    /// why the follower holds, for `diagnostics`
    pub(super) state: String,
}

impl<M: ArmModel> Driver<M> {
    /// The follower holds where it is (the arbiter stopped `leader_follower`).
    pub(super) fn hold_leader(&mut self, why: String, effects: &mut Vec<Effect>) {
        if self.leader.state == "following" || self.leader.state.starts_with("following,") {
            self.core.stop_motion();
            log::info!("leader: {why}: the follower holds");
            effects.push(Effect::Report);
        }
        self.leader.state = format!("holding: {why}");
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
            self.leader.state = "holding: deadman released".into();
        } else if !self.arbiter.passes(Controller::LeaderFollower) {
            self.leader.state = "deadman held, waiting for a leader sample".into();
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
            || !self.leader.state.starts_with("following");
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
                if self.leader.state == "no leader" {
                    self.leader.state = "holding: deadman released".into();
                }
                return;
            }
            Refusal::Calibrating => "calibrating".to_string(),
            Refusal::Estop => "emergency stop engaged".to_string(),
            why => why.to_string(),
        };
        if !self.leader.state.ends_with(&why) {
            log::info!("leader sample not followed: {why}");
            effects.push(Effect::Report);
        }
        self.leader.state = format!("holding: {why}");
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
                self.leader.state = "following".into();
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
                self.leader.state = format!("following, this pose refused: {reason}");
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
