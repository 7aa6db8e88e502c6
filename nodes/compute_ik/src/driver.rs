//! The node's loop policy around a [`Pipeline`], on a clock it is given (as
//! `servo_protocol::host` is): which inputs of a burst are applied, a late target held
//! back for a newer one (the [`CommandGate`] serial_node shares), when the planned
//! motion steps, when a refusal is reported at
//! once, and the pose sent to a new `joint_states` subscriber. Events in, [`Effect`]s
//! out; [`crate::run`] does the I/O.

use crate::pipeline::{ArmModel, Input, Pipeline, Step};
use command_gate::{CommandGate, Stamp, Verdict};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use ros_plumbing::burst;
use ros_plumbing::logging::Throttle;
use ros_plumbing::Params;
use std::time::{Duration, Instant};

/// Most frequent diagnostics sent at once on a rejection; the periodic report covers the rest.
pub const MIN_IMMEDIATE_DIAG_GAP: Duration = Duration::from_millis(100);

/// Polls of the peers over which a new `joint_states` subscriber is sent the pose (the
/// new reader may match our writer a little after we match it: over a second, not once).
const GREET_POLLS: u8 = 4;

/// What to do.
#[derive(Clone, Debug, PartialEq)]
pub enum Effect {
    /// Publish a step (`joint_states`, and `servo_angles` if any).
    Publish(Step),
    /// Publish on `joint_states` only (the pose, for a new viewer).
    JointStates(JointState),
    /// Publish a `diagnostics` report.
    Report,
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
    subscribers: usize,
    greet_polls: u8,
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
            subscribers: 0,
            greet_polls: 0,
        }
    }

    /// The pipeline.
    pub fn core(&self) -> &Pipeline<M> {
        &self.core
    }

    /// When [`Driver::on_time`] is next due: the next motion step or the held target.
    pub fn deadline(&self) -> Option<Instant> {
        match (self.next_step, self.gate.deadline()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    fn step_period(&self) -> Duration {
        Duration::from_secs_f64(self.core.motion().period_s)
    }

    /// Time passed to `now` (`wall`: the clock the stamps are on): the motion's next
    /// step, and the held late target when its time has come.
    pub fn on_time(&mut self, now: Instant, wall: Time) -> Vec<Effect> {
        let mut effects = vec![];
        if let Some(t) = self.next_step.filter(|t| *t <= now) {
            if let Some(step) = self.core.step(wall) {
                effects.push(Effect::Publish(step));
            }
            self.next_step = Some(t + self.step_period()).filter(|_| self.core.is_moving());
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

    /// The peers were looked at: `subscribers` read `joint_states`. A new one is sent
    /// the pose, stamped `wall`, over the next polls.
    pub fn on_poll(&mut self, subscribers: usize, wall: Time) -> Vec<Effect> {
        if subscribers > self.subscribers {
            self.greet_polls = GREET_POLLS;
        }
        self.subscribers = subscribers;
        if self.greet_polls == 0 {
            return vec![];
        }
        self.greet_polls -= 1;
        vec![Effect::JointStates(self.core.joint_states(wall))]
    }

    /// The parameters changed: applied (a new solver logged and reported).
    pub fn on_params(&mut self, params: &Params) -> Vec<Effect> {
        let solver = self.core.solver();
        self.core.apply_params(params);
        if self.core.solver() == solver {
            return vec![];
        }
        log::info!("solver: {}", params.string("solver").unwrap_or_default());
        vec![Effect::Report]
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
                    self.next_step = None;
                    effects.push(Effect::Report);
                }
                continue;
            }
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
                Err(rejection) => {
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
        }
    }
}

/// Of the inputs that arrived together, the ones to act on, in order: an
/// `xyz_target` followed by a newer one is superseded, and so are a `pose_target` and a
/// `gripper_target` (latest wins); `joint_target`s (which may name only some joints),
/// e-stops and unreadable samples are all kept. Returns them and how many were
/// superseded.
pub fn coalesce(batch: Vec<Input>) -> (Vec<Input>, usize) {
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
