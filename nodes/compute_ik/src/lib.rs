#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod controller;
pub mod core;
pub mod driver;
pub mod eezybot;
pub mod numeric;
pub mod pipeline;
pub mod urdf_arm;

use crate::controller::ControllerSettings;
use crate::core::{MotionMode, DEFAULT_MAX_TARGET_AGE_S};
use crate::driver::{Driver, Effect};
use crate::eezybot::IkCore;
use crate::numeric::{Solver, GRIPPER_UP_DEFAULT_DEG};
pub use crate::pipeline::{ArmModel, Input, Pipeline, Step};
use crate::urdf_arm::{UrdfArm, UrdfCore};
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::ArmConfig;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use futures::{Stream, StreamExt};
use ros_plumbing::burst;
use ros_plumbing::peers::{Peer, PeerWatch};
use ros_plumbing::{ParamRange, ParamSpec, ParameterValue, Params};
use std::future::Future;
use std::time::{Duration, Instant};

/// The node's description and parameters.
pub fn spec() -> ros_plumbing::NodeSpec {
    ros_plumbing::NodeSpec {
        name: "compute_ik",
        description: "inverse kinematics for the EezyBotArm Mk2: xyz_target / gripper_target / joint_target -> \
                      joint_states + servo_angles",
        usage: "",
        params: vec![
            ParamSpec::file(
                "arm_config",
                "arm geometry, limits and servo calibration YAML; empty = the shipped config/arm.yaml",
                "empty, or an arm_config YAML file that loads",
                |p| ArmConfig::load_or_shipped(p).map(|_| ()).map_err(|e| e.to_string()),
            ),
            ParamSpec::new("base_frame", ParameterValue::String("base_link".into()), "frame xyz_target must be given in")
                .constraints("not empty")
                .text_check(|s| if s.is_empty() { Err("must not be empty".into()) } else { Ok(()) }),
            ros_plumbing::diagnostics::diagnostics_period_param(),
            ParamSpec::new(
                "motion",
                ParameterValue::String("joint".into()),
                "how xyz_target's and pose_target's targets are moved to: `joint` (every servo within its limits, together) or `line` (the tool on a straight line, refused if any point of it is unreachable); set at start, read-only after (a line move at any time: xyz_line_target)",
            )
            .constraints("one of: joint, line")
            .read_only()
            .text_check(|s| MotionMode::parse(s).map(|_| ()).ok_or_else(|| "must be `joint` or `line`".into())),
            ParamSpec::new(
                "motion_rate",
                ParameterValue::Double(50.0),
                "steps a second of a planned motion on joint_states and servo_angles (the servos' 50 Hz refresh)",
            )
            .range(ParamRange::Double { min: 1.0, max: 500.0 }),
            ParamSpec::new(
                "max_target_age",
                ParameterValue::Double(DEFAULT_MAX_TARGET_AGE_S),
                "targets stamped longer ago than this (s) by compute_ik's clock are refused; a zero stamp means now; 0 = no limit",
            )
            .range(ParamRange::Double { min: 0.0, max: 3600.0 }),
            ParamSpec::new(
                "solver",
                ParameterValue::String("analytic".into()),
                "IK of xyz_target and pose_target: `analytic` (the EezyBot's closed form; dls for an arm without one), `jacobian` (pseudo-inverse), `dls` (damped least squares), `newton` (Newton-Raphson); switchable while running",
            )
            .constraints("one of: analytic, jacobian, dls, newton")
            .text_check(|s| Solver::check(s).map(|_| ())),
            ParamSpec::file(
                "urdf",
                "the arm's URDF; empty = the EezyBot (closed form, servo mapping); any other arm is solved numerically on the chain base_link -> tip_link and publishes no servo_angles",
                "empty, or a URDF file that loads",
                |p| match p {
                    "" => Ok(()),
                    p => RobotModel::load(std::path::Path::new(p)).map(|_| ()).map_err(|e| e.to_string()),
                },
            )
            .read_only(),
            ParamSpec::new(
                "tip_link",
                ParameterValue::String(String::new()),
                "the URDF link xyz_target and pose_target place; empty = tool0 for the EezyBot, else the URDF's only leaf link",
            )
            .read_only(),
            ParamSpec::new(
                "base_link",
                ParameterValue::String(String::new()),
                "the URDF link the chain starts at (targets are in its frame); empty = the URDF's root link",
            )
            .read_only(),
            ParamSpec::new(
                "substitute_nearest",
                ParameterValue::Boolean(false),
                "a position target at most substitute_max_distance out of reach is replaced by the nearest reachable point (logged, in diagnostics) instead of refused",
            ),
            ParamSpec::new(
                "substitute_max_distance",
                ParameterValue::Double(0.01),
                "how far out of reach (m) a target may be for substitute_nearest",
            )
            .range(ParamRange::Double { min: 1e-6, max: 1.0 }),
            ParamSpec::new(
                "goal_tolerance",
                ParameterValue::Double(ControllerSettings::default().goal_tolerance),
                "arm_controller: how far (rad) each joint's servo_state may be from a trajectory's last point for the goal to succeed, where the goal gives 0; 0 = not checked",
            )
            .range(ParamRange::Double { min: 0.0, max: 3.2 }),
            ParamSpec::new(
                "path_tolerance",
                ParameterValue::Double(ControllerSettings::default().path_tolerance),
                "arm_controller: how far (rad) each joint's servo_state may be from what was commanded for the same instant while a trajectory runs, where the goal gives 0; 0 = not checked",
            )
            .range(ParamRange::Double { min: 0.0, max: 3.2 }),
            ParamSpec::new(
                "goal_time_tolerance",
                ParameterValue::Double(ControllerSettings::default().goal_time),
                "arm_controller: how long (s) after a trajectory's last point the goal tolerance may still be met, where the goal gives 0",
            )
            .range(ParamRange::Double { min: 0.0, max: 60.0 }),
            ParamSpec::new(
                "leader_timeout",
                ParameterValue::Double(driver::DEFAULT_LEADER_TIMEOUT.as_secs_f64()),
                "following a leader arm (leader/joint_states while leader/deadman is true): without a leader sample for this long (s) the follower holds",
            )
            .range(ParamRange::Double { min: 0.01, max: 5.0 }),
            ParamSpec::new(
                "calibration_lease",
                ParameterValue::Double(arbiter::DEFAULT_OWNER_LEASE.as_secs_f64()),
                "a `calibration` made active by controller_manager/switch_controller is given back (deactivated, the arm taken where servo_state says) when its caller has made no list_controllers or switch_controller request for this long (s)",
            )
            .range(ParamRange::Double { min: 0.5, max: 3600.0 }),
            ParamSpec::new(
                "feedback_layout",
                ParameterValue::String("any".into()),
                "FollowJointTrajectory feedback as control_msgs lays it out: `any` (Kilted's, with index left 0, which Jazzy's clients read too), `kilted` (control_msgs 6.3 and later, index filled in) or `jazzy` (control_msgs 5)",
            )
            .constraints("one of: any, kilted, jazzy")
            .text_check(|s| FeedbackLayout::parse(s).map(|_| ()).ok_or_else(|| "must be `any`, `kilted` or `jazzy`".into()))
            .read_only(),
            ParamSpec::new(
                "gripper_up_angle",
                ParameterValue::Double(GRIPPER_UP_DEFAULT_DEG),
                "URDF arms: the configuration is reported undesirable (gripper_up) when the tip's z axis is closer than this (deg) to straight up; 0 = no check",
            )
            .range(ParamRange::Double { min: 0.0, max: 180.0 }),
        ],
    }
}

/// The arm compute_ik drives, as the parameters say: the EezyBot (closed form and servo
/// mapping) or an arm known by its URDF. Each is a [`Pipeline`]; the node runs either
/// with [`run`].
#[derive(Clone, Debug)]
pub enum Core {
    /// The EezyBotArm Mk2.
    EezyBot(Box<IkCore>),
    /// Any other serial arm of a URDF.
    Urdf(Box<UrdfCore>),
}

impl Core {
    /// The core the parameters describe: the EezyBot unless `urdf` names another arm
    /// (an EezyBot URDF with tip `tool0` is the EezyBot), with the run-time parameters
    /// applied. Errors name the problem.
    pub fn from_params(params: &Params) -> Result<Core, String> {
        let config = ArmConfig::load_or_shipped(&params.string("arm_config").unwrap_or_default())
            .map_err(|e| format!("arm_config: {e}"))?;
        let base_frame = params
            .string("base_frame")
            .unwrap_or_else(|| "base_link".into());
        let urdf = params.string("urdf").unwrap_or_default();
        let tip = params.string("tip_link").unwrap_or_default();
        let base = params.string("base_link").unwrap_or_default();
        let eezybot_ends =
            matches!(tip.as_str(), "" | "tool0") && matches!(base.as_str(), "" | "base_link");
        let mut core = if urdf.is_empty() {
            if !eezybot_ends {
                return Err(format!(
                    "tip_link `{tip}` / base_link `{base}`: the EezyBot's chain is base_link -> tool0 (set urdf to use other links)"
                ));
            }
            Core::EezyBot(Box::new(IkCore::new(&config, &base_frame)))
        } else {
            let model =
                RobotModel::load(std::path::Path::new(&urdf)).map_err(|e| format!("urdf: {e}"))?;
            if eezybot_ends && config.arm().serial_chain(&model).is_ok() {
                let core = IkCore::with_model(&config, &base_frame, model)
                    .map_err(|e| format!("urdf: {e}"))?;
                Core::EezyBot(Box::new(core))
            } else {
                let arm =
                    UrdfArm::new(model, &base, &tip).map_err(|e| format!("urdf {urdf}: {e}"))?;
                Core::Urdf(Box::new(UrdfCore::new(arm, &base_frame)?))
            }
        };
        match &mut core {
            Core::EezyBot(c) => c.apply_params(params),
            Core::Urdf(c) => c.apply_params(params),
        }
        Ok(core)
    }
}

/// The trajectory controller's defaults, from the parameters.
pub fn controller_settings(params: &Params) -> ControllerSettings {
    let d = ControllerSettings::default();
    ControllerSettings {
        path_tolerance: params.f64("path_tolerance").unwrap_or(d.path_tolerance),
        goal_tolerance: params.f64("goal_tolerance").unwrap_or(d.goal_tolerance),
        goal_time: params.f64("goal_time_tolerance").unwrap_or(d.goal_time),
    }
}

/// How long without a leader sample before the follower holds.
pub fn leader_timeout(params: &Params) -> Duration {
    let s = params
        .f64("leader_timeout")
        .unwrap_or(driver::DEFAULT_LEADER_TIMEOUT.as_secs_f64());
    Duration::from_secs_f64(s.clamp(0.01, 5.0))
}

/// How FollowJointTrajectory feedback is laid out on the wire: control_msgs changed it
/// in 6.3 (Kilted's release) by adding `index` and `multi_dof_index`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FeedbackLayout {
    /// Kilted's layout with both indices 0: Jazzy's clients read it too (the zeros
    /// read as empty sequences), Kilted's read every field.
    Any,
    /// Kilted's layout (control_msgs 6.3 and later), `index` filled in.
    Kilted,
    /// Jazzy's layout (control_msgs 5).
    Jazzy,
}

impl FeedbackLayout {
    /// `any`, `kilted` or `jazzy`.
    pub fn parse(s: &str) -> Option<FeedbackLayout> {
        match s {
            "any" => Some(FeedbackLayout::Any),
            "kilted" => Some(FeedbackLayout::Kilted),
            "jazzy" => Some(FeedbackLayout::Jazzy),
            _ => None,
        }
    }
}

/// Where the loop's results go.
pub trait Outputs {
    /// Publish on `joint_states`.
    fn joint_states(&self, msg: JointState);
    /// Publish on `servo_angles`.
    fn servo_angles(&self, msg: JointState);
    /// Publish a `diagnostics` report with this status.
    fn diagnostics(&self, status: DiagnosticStatus);
    /// The controllers' answers, feedback, results and state ([`Effect::AnswerGoal`],
    /// [`Effect::TrajectoryFeedback`], [`Effect::TrajectoryResult`],
    /// [`Effect::GripperFeedback`], [`Effect::GripperResult`],
    /// [`Effect::ControllerState`]).
    fn controllers(&self, effect: Effect);
    /// The peer counts of the watched topics, in [`watched_topics`]' order:
    /// `servo_angles` subscribers, `joint_states` subscribers, `xyz_target` publishers.
    fn peer_counts(&self) -> [usize; 3];
    /// The `joint_states` subscriptions matched now, by GUID (see [`Driver::on_poll`]).
    fn joint_states_readers(&self) -> Vec<driver::ReaderId>;
}

/// The topics whose peers compute_ik watches (resolved names), in
/// [`Outputs::peer_counts`]' order.
pub fn watched_topics(
    servo_angles: &str,
    joint_states: &str,
    xyz_target: &str,
) -> Vec<(String, Peer)> {
    vec![
        (servo_angles.to_string(), Peer::Subscriber),
        (joint_states.to_string(), Peer::Subscriber),
        (xyz_target.to_string(), Peer::Publisher),
    ]
}

/// How often to look at the peer counts (and for new `joint_states` subscribers).
const SUBSCRIBER_POLL: Duration = Duration::from_millis(250);

/// What the loop is handed: the inputs (every subscription, as [`Input`]s), the
/// outputs (publishers and peer counts), the parameters, the peer watch of
/// [`watched_topics`], the `diagnostics` status name, and the shutdown signal.
pub struct Handles<I, O, S> {
    /// Every target topic's samples.
    pub inputs: I,
    /// The publishers.
    pub outputs: O,
    /// The node's parameters (changes apply while running).
    pub params: Params,
    /// The peers of [`watched_topics`].
    pub peers: PeerWatch,
    /// The `diagnostics` status name (`compute_ik: inverse kinematics`).
    pub diag_name: String,
    /// Resolves when the node is to stop.
    pub shutdown: S,
}

/// How long a calibration's caller may stay silent before the arm is given back.
pub fn calibration_lease(params: &Params) -> Duration {
    let s = params
        .f64("calibration_lease")
        .unwrap_or(arbiter::DEFAULT_OWNER_LEASE.as_secs_f64());
    Duration::from_secs_f64(s.clamp(0.5, 3600.0))
}

/// The parameters changed: the controller's settings, the leader's timeout, the
/// calibration lease, then the driver's own ([`Driver::on_params`]).
fn apply_params<M: ArmModel>(driver: &mut Driver<M>, params: &Params) -> Vec<Effect> {
    driver.set_controller_settings(controller_settings(params));
    driver.set_leader_timeout(leader_timeout(params));
    driver.set_calibration_lease(calibration_lease(params));
    driver.on_params(params, std::time::Instant::now(), Time::now())
}

/// The event loop: routes each event to the [`Driver`] and applies what it returns,
/// until `shutdown` resolves or the inputs end. Each arm hands its event on: inputs
/// go to [`Driver::on_inputs`] (after a parameter change that came before them,
/// `EventLoop::params_set_before_inputs`), which hands each to its handler
/// (`xyz_target`'s is two calls from here: `run` → [`Driver::on_inputs`] →
/// `Driver::on_target`).
pub async fn run<M, I, O, S>(core: Pipeline<M>, h: Handles<I, O, S>)
where
    M: ArmModel,
    I: Stream<Item = Input>,
    O: Outputs,
    S: Future<Output = ()>,
{
    let (mut node, inputs, shutdown) = EventLoop::new(core, h);
    let mut subscriber_poll = tokio::time::interval_at(
        tokio::time::Instant::now() + SUBSCRIBER_POLL,
        SUBSCRIBER_POLL,
    );
    tokio::pin!(inputs);
    tokio::pin!(shutdown);
    loop {
        let deadline = node.driver.deadline().map(tokio::time::Instant::from_std);
        let event = tokio::select! {
            _ = &mut shutdown => break,
            _ = sleep_until(deadline), if deadline.is_some() => {
                Event::Deadline(burst::ready_now(&mut inputs))
            }
            _ = node.ticker.tick() => Event::Report,
            _ = subscriber_poll.tick() => Event::Poll,
            Ok(()) = node.param_changes.changed() => Event::Params,
            // a burst (DDS repairing what a network outage held back) is applied as
            // its newest target; a lone target goes at once
            input = inputs.next() => match input {
                Some(first) => Event::Inputs(burst::take_burst(first, &mut inputs)),
                None => break,
            },
        };
        let mut effects = node.sync_params(matches!(event, Event::Params));
        effects.extend(node.on_event(event));
        node.apply(effects);
    }
}

/// `arm_config`'s file is loaded whenever the parameter is set, by the parameter
/// services (off the loop), which apply it ([`Params::loaded`]) once the loop sees the
/// change.
pub fn load_arm_config(params: &Params) -> Result<(), String> {
    params.load_with("arm_config", |path| {
        ArmConfig::load_or_shipped(path)
            .map(|c| std::sync::Arc::new(c) as ros_plumbing::params::Loaded)
            .map_err(|e| e.to_string())
    })
}

/// What woke [`run`]'s loop.
enum Event {
    /// the driver's deadline, with the inputs already waiting
    Deadline(Vec<Input>),
    Report,
    /// the peers' poll
    Poll,
    /// a parameter was set (applied before every event, this one included)
    Params,
    /// inputs arrived: the first and those right behind it
    Inputs(Vec<Input>),
}

/// Sleeps until `deadline` (at once without one: its arm is disabled then).
async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    if let Some(t) = deadline {
        tokio::time::sleep_until(t).await
    }
}

/// What [`run`] holds besides its inputs and shutdown: the driver, the outputs, the
/// parameters and the watch on their changes, the `diagnostics` ticker, the peers.
struct EventLoop<M: ArmModel, O> {
    driver: Driver<M>,
    outputs: O,
    params: Params,
    param_changes: tokio::sync::watch::Receiver<u64>,
    /// the periodic `diagnostics` report (`diagnostics_period`)
    ticker: tokio::time::Interval,
    peers: PeerWatch,
    diag_name: String,
    /// `servo_angles` messages published since the start (in `diagnostics`: with
    /// `calibrating` and `estop`, it shows from outside that nothing was sent meanwhile)
    servo_angles_sent: std::cell::Cell<u64>,
}

impl<M: ArmModel, O: Outputs> EventLoop<M, O> {
    /// Around a driver of `core` (the parameters applied to both), with what `h`
    /// hands in; the inputs and the shutdown signal returned for the loop to poll.
    fn new<I, S>(mut core: Pipeline<M>, h: Handles<I, O, S>) -> (Self, I, S) {
        let mut ticker = diagnostics_ticker(&h.params);
        // (only the first: one made anew by a parameter change keeps tokio's default)
        ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let param_changes = h.params.subscribe();
        if let Err(e) = load_arm_config(&h.params) {
            log::error!("arm_config: {e}");
        }
        core.apply_params(&h.params);
        let mut driver = Driver::new(core);
        driver.set_controller_settings(controller_settings(&h.params));
        driver.set_leader_timeout(leader_timeout(&h.params));
        driver.set_calibration_lease(calibration_lease(&h.params));
        let node = EventLoop {
            driver,
            outputs: h.outputs,
            params: h.params,
            param_changes,
            ticker,
            peers: h.peers,
            diag_name: h.diag_name,
            servo_angles_sent: Default::default(),
        };
        (node, h.inputs, h.shutdown)
    }

    /// The driver's deadline came (`waiting`: the inputs already there). Inputs
    /// already waiting go first: on a busy host the deadline (the leader's timeout
    /// above all) and the samples that meet it can be ready together, and select!
    /// picks at random; a leader sample that had arrived must not be taken for a
    /// pulled cable.
    fn on_deadline(&mut self, waiting: Vec<Input>) -> Vec<Effect> {
        let mut effects = vec![];
        if !waiting.is_empty() {
            effects = self.driver.on_inputs(waiting, Instant::now(), Time::now());
        }
        effects.extend(self.driver.on_time(Instant::now(), Time::now()));
        effects
    }

    /// The event, to the driver (the parameters are synced already).
    fn on_event(&mut self, event: Event) -> Vec<Effect> {
        match event {
            Event::Deadline(waiting) => self.on_deadline(waiting),
            Event::Report => vec![Effect::Report],
            Event::Poll => self.on_poll(),
            Event::Params => vec![],
            Event::Inputs(arrived) => self.driver.on_inputs(arrived, Instant::now(), Time::now()),
        }
    }

    /// The peers' poll: their changes logged (and reported), a new `joint_states`
    /// reader greeted ([`Driver::on_poll`]).
    fn on_poll(&mut self) -> Vec<Effect> {
        let counts = self.outputs.peer_counts();
        let changes = self.peers.update(&counts, Instant::now());
        changes.iter().for_each(|c| c.log());
        let report = (!changes.is_empty()).then_some(Effect::Report);
        let readers = self.outputs.joint_states_readers();
        let greeting = self.driver.on_poll(&readers, Time::now());
        report.into_iter().chain(greeting).collect()
    }

    /// The parameters changed: the `diagnostics` period anew, then [`apply_params`].
    fn on_params(&mut self) -> Vec<Effect> {
        self.ticker = diagnostics_ticker(&self.params);
        apply_params(&mut self.driver, &self.params)
    }

    /// The parameters as they are now, before any event is handled (`woken`: the
    /// loop woke to a set): a set answered before an event's cause was sent (the
    /// calibration wizard's `arm_config`, then its switch back to the arm's
    /// controllers) is in the store already, whichever branch select! picked.
    fn sync_params(&mut self, woken: bool) -> Vec<Effect> {
        if !woken && !self.param_changes.has_changed().unwrap_or(false) {
            return vec![];
        }
        self.param_changes.borrow_and_update();
        self.on_params()
    }

    /// What the driver returned, done: published, answered, reported.
    fn apply(&self, effects: Vec<Effect>) {
        for effect in effects {
            match effect {
                Effect::Publish(step) => {
                    if let Some(servo_angles) = step.servo_angles {
                        self.outputs.servo_angles(servo_angles);
                        self.servo_angles_sent.set(self.servo_angles_sent.get() + 1);
                    }
                    self.outputs.joint_states(step.joint_states);
                }
                Effect::JointStates(msg) => self.outputs.joint_states(msg),
                e @ (Effect::AnswerGoal { .. }
                | Effect::TrajectoryFeedback(..)
                | Effect::TrajectoryResult(..)
                | Effect::GripperFeedback(..)
                | Effect::GripperResult(..)
                | Effect::ControllerState(_)
                | Effect::ListControllers(..)
                | Effect::SwitchController(..)) => self.outputs.controllers(e),
                Effect::Report => self.report(),
            }
        }
    }

    /// A `diagnostics` report: the pipeline's, the controllers', the peers', the
    /// parameters'.
    fn report(&self) {
        let mut s = self.driver.core().diagnostic_status(&self.diag_name);
        s.values.extend(
            self.driver
                .controller_values()
                .into_iter()
                .map(|(key, value)| eezybot_msgs::diagnostic_msgs::KeyValue { key, value }),
        );
        s.values.push(eezybot_msgs::diagnostic_msgs::KeyValue {
            key: "servo_angles_sent".into(),
            value: self.servo_angles_sent.get().to_string(),
        });
        self.peers.annotate(&mut s, Instant::now());
        self.params.annotate(&mut s);
        self.outputs.diagnostics(s);
    }
}

/// The periodic `diagnostics` report's ticker, at `diagnostics_period`.
fn diagnostics_ticker(params: &Params) -> tokio::time::Interval {
    tokio::time::interval(ros_plumbing::diagnostics::diagnostics_period(params))
}
