#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod core;
pub mod numeric;
pub mod urdf_arm;

use crate::core::{IkCore, MotionMode, MotionSettings, Notice, Output, Rejection, Source};
use crate::numeric::{Solver, GRIPPER_UP_DEFAULT_DEG};
use crate::urdf_arm::{UrdfArm, UrdfCore};
use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::ArmConfig;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{PointStamped, PoseStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use futures::{Stream, StreamExt};
use ros_plumbing::burst;
use ros_plumbing::logging::Throttle;
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
            ParamSpec::new(
                "arm_config",
                ParameterValue::String(String::new()),
                "arm geometry, limits and servo calibration YAML; empty = the shipped config/arm.yaml",
            )
            .constraints("empty, or an arm_config YAML file that loads")
            .validator(|v| match v {
                ParameterValue::String(p) => ArmConfig::load_or_shipped(p).map(|_| ()).map_err(|e| e.to_string()),
                _ => Ok(()),
            }),
            ParamSpec::new("base_frame", ParameterValue::String("base_link".into()), "frame xyz_target must be given in")
                .constraints("not empty")
                .validator(|v| match v {
                    ParameterValue::String(s) if s.is_empty() => Err("must not be empty".into()),
                    _ => Ok(()),
                }),
            ros_plumbing::diagnostics::diagnostics_period_param(),
            ParamSpec::new(
                "motion",
                ParameterValue::String("joint".into()),
                "how xyz targets are moved to: `joint` (every servo within its limits, together) or `line` (the tool on a straight line, refused if any point of it is unreachable)",
            )
            .constraints("one of: joint, line")
            .validator(|v| match v {
                ParameterValue::String(s) if MotionMode::parse(s).is_some() => Ok(()),
                _ => Err("must be `joint` or `line`".into()),
            }),
            ParamSpec::new(
                "motion_rate",
                ParameterValue::Double(50.0),
                "steps a second of a planned motion on joint_states and servo_angles (the servos' 50 Hz refresh)",
            )
            .range(ParamRange::Double { min: 1.0, max: 500.0 }),
            ParamSpec::new(
                "max_target_age",
                ParameterValue::Double(0.5),
                "targets stamped longer ago than this (s) by compute_ik's clock are refused; a zero stamp means now; 0 = no limit",
            )
            .range(ParamRange::Double { min: 0.0, max: 3600.0 }),
            ParamSpec::new(
                "solver",
                ParameterValue::String("analytic".into()),
                "IK of xyz_target and pose_target: `analytic` (the EezyBot's closed form; dls for an arm without one), `jacobian` (pseudo-inverse), `dls` (damped least squares), `newton` (Newton-Raphson); switchable while running",
            )
            .constraints("one of: analytic, jacobian, dls, newton")
            .validator(|v| match v {
                ParameterValue::String(s) => Solver::check(s).map(|_| ()),
                _ => Ok(()),
            }),
            ParamSpec::new(
                "urdf",
                ParameterValue::String(String::new()),
                "the arm's URDF; empty = the EezyBot (closed form, servo mapping); any other arm is solved numerically on the chain base_link -> tip_link and publishes no servo_angles",
            )
            .read_only()
            .constraints("empty, or a URDF file that loads")
            .validator(|v| match v {
                ParameterValue::String(p) if !p.is_empty() => RobotModel::load(std::path::Path::new(p))
                    .map(|_| ())
                    .map_err(|e| e.to_string()),
                _ => Ok(()),
            }),
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
                "gripper_up_angle",
                ParameterValue::Double(GRIPPER_UP_DEFAULT_DEG),
                "URDF arms: the configuration is reported undesirable (gripper_up) when the tip's z axis is closer than this (deg) to straight up; 0 = no check",
            )
            .range(ParamRange::Double { min: 0.0, max: 180.0 }),
        ],
    }
}

/// The arm compute_ik drives: the EezyBot (closed form and servo mapping) or an arm
/// known by its URDF.
#[derive(Clone, Debug)]
pub enum Core {
    /// The EezyBotArm Mk2.
    EezyBot(Box<IkCore>),
    /// Any other serial arm of a URDF.
    Urdf(Box<UrdfCore>),
}

/// What an accepted target or a motion step publishes.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// Every non-fixed URDF joint.
    pub joint_states: JointState,
    /// The servo horn angles (the EezyBot only).
    pub servo_angles: Option<JointState>,
}

impl From<Output> for Step {
    fn from(o: Output) -> Step {
        Step {
            joint_states: o.joint_states,
            servo_angles: Some(o.servo_angles),
        }
    }
}

impl From<JointState> for Step {
    fn from(joint_states: JointState) -> Step {
        Step {
            joint_states,
            servo_angles: None,
        }
    }
}

impl Core {
    /// The core the parameters describe: the EezyBot unless `urdf` names another arm
    /// (an EezyBot URDF with tip `tool0` is the EezyBot). Errors name the problem.
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
            let eezybot = eezybot_ends && config.arm().serial_chain(&model).is_ok();
            if eezybot {
                let core = IkCore::with_model(&config, &base_frame, model)
                    .map_err(|e| format!("urdf: {e}"))?;
                Core::EezyBot(Box::new(core))
            } else {
                let arm =
                    UrdfArm::new(model, &base, &tip).map_err(|e| format!("urdf {urdf}: {e}"))?;
                Core::Urdf(Box::new(UrdfCore::new(arm, &base_frame)?))
            }
        };
        core.apply_params(params);
        Ok(core)
    }

    /// One line on what is driven, for the start log.
    pub fn describe(&self) -> String {
        match self {
            Core::EezyBot(_) => {
                "the EezyBotArm Mk2 (base_link -> tool0; servo_angles for serial_node)".into()
            }
            Core::Urdf(c) => {
                let chain = c.arm().chain();
                format!(
                    "URDF arm `{}`: {} -> {}, {} joints ({}); no servo_angles",
                    c.arm().model().name,
                    chain.base_link(),
                    chain.tip_link(),
                    chain.dof(),
                    chain
                        .variables()
                        .iter()
                        .map(|v| v.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        }
    }

    /// Whether this arm has servos (publishes `servo_angles`).
    pub fn has_servos(&self) -> bool {
        matches!(self, Core::EezyBot(_))
    }

    /// Apply the run-time parameters: solver, substitution, the gripper-up check,
    /// base frame, motion settings (and the EezyBot's `arm_config`).
    pub fn apply_params(&mut self, params: &Params) {
        let solver = params
            .string("solver")
            .as_deref()
            .and_then(Solver::parse)
            .unwrap_or(Solver::Analytic);
        let substitute = params
            .bool("substitute_nearest")
            .unwrap_or(false)
            .then(|| params.f64("substitute_max_distance").unwrap_or(0.01));
        let base_frame = params
            .string("base_frame")
            .unwrap_or_else(|| "base_link".into());
        let motion = motion_settings(params);
        match self {
            Core::EezyBot(c) => {
                // Values were validated before they were stored; a file that vanished since is reported.
                match ArmConfig::load_or_shipped(&params.string("arm_config").unwrap_or_default()) {
                    Ok(config) => c.set_config(&config),
                    Err(e) => log::error!("keeping the previous arm configuration: {e}"),
                }
                c.set_solver(solver);
                c.set_substitution(substitute);
                c.set_base_frame(&base_frame);
                c.set_motion(motion);
            }
            Core::Urdf(c) => {
                c.set_solver(solver);
                c.set_substitution(substitute);
                c.set_gripper_up(params.f64("gripper_up_angle"));
                c.set_base_frame(&base_frame);
                c.set_motion(motion);
            }
        }
    }

    /// Handle one target input (not `estop`, not unreadable samples).
    pub fn handle(&mut self, input: &Input, now: Time) -> Option<Result<Step, Rejection>> {
        Some(match (self, input) {
            (Core::EezyBot(c), Input::XyzTarget(m)) => c.handle_xyz_target(m, now).map(Step::from),
            (Core::EezyBot(c), Input::PoseTarget(m)) => {
                c.handle_pose_target(m, now).map(Step::from)
            }
            (Core::EezyBot(c), Input::GripperTarget(v, stamp)) => {
                c.handle_gripper_target(*v, *stamp).map(Step::from)
            }
            (Core::EezyBot(c), Input::JointTarget(m)) => {
                c.handle_joint_target(m, now).map(Step::from)
            }
            (Core::Urdf(c), Input::XyzTarget(m)) => c.handle_xyz_target(m, now).map(Step::from),
            (Core::Urdf(c), Input::PoseTarget(m)) => c.handle_pose_target(m, now).map(Step::from),
            (Core::Urdf(c), Input::GripperTarget(v, stamp)) => {
                c.handle_gripper_target(*v, *stamp).map(Step::from)
            }
            (Core::Urdf(c), Input::JointTarget(m)) => c.handle_joint_target(m, now).map(Step::from),
            (c, Input::Unreadable(source, e)) => Err(c.reject_unreadable(*source, e.clone())),
            (_, Input::Estop(_)) => return None,
        })
    }

    /// The next planned step while moving.
    pub fn step(&mut self, now: Time) -> Option<Step> {
        match self {
            Core::EezyBot(c) => c.step(now).map(Step::from),
            Core::Urdf(c) => c.step(now).map(Step::from),
        }
    }

    /// `joint_states` of the commanded state, with this stamp.
    pub fn joint_states(&self, stamp: Time) -> JointState {
        match self {
            Core::EezyBot(c) => c.joint_states(stamp),
            Core::Urdf(c) => c.joint_states(stamp),
        }
    }

    /// The `diagnostics` entry.
    pub fn diagnostic_status(&self, name: &str) -> DiagnosticStatus {
        match self {
            Core::EezyBot(c) => c.diagnostic_status(name),
            Core::Urdf(c) => c.diagnostic_status(name),
        }
    }

    /// Engage or release the emergency stop.
    pub fn set_estop(&mut self, engaged: bool) {
        match self {
            Core::EezyBot(c) => c.set_estop(engaged),
            Core::Urdf(c) => c.set_estop(engaged),
        }
    }

    /// Is the emergency stop engaged?
    pub fn estop(&self) -> bool {
        match self {
            Core::EezyBot(c) => c.estop(),
            Core::Urdf(c) => c.estop(),
        }
    }

    /// Is the arm moving?
    pub fn is_moving(&self) -> bool {
        match self {
            Core::EezyBot(c) => c.is_moving(),
            Core::Urdf(c) => c.is_moving(),
        }
    }

    /// How the arm is moved.
    pub fn motion(&self) -> MotionSettings {
        match self {
            Core::EezyBot(c) => c.motion(),
            Core::Urdf(c) => c.motion(),
        }
    }

    /// Count targets dropped because newer ones arrived with them.
    pub fn count_superseded(&mut self, n: u64) {
        match self {
            Core::EezyBot(c) => c.count_superseded(n),
            Core::Urdf(c) => c.count_superseded(n),
        }
    }

    /// Record a sample that could not be read.
    pub fn reject_unreadable(&mut self, source: Source, error: String) -> Rejection {
        match self {
            Core::EezyBot(c) => c.reject_unreadable(source, error),
            Core::Urdf(c) => c.reject_unreadable(source, error),
        }
    }

    /// What to log besides rejections.
    pub fn take_notices(&mut self) -> Vec<Notice> {
        match self {
            Core::EezyBot(c) => c.take_notices(),
            Core::Urdf(c) => c.take_notices(),
        }
    }
}

/// The motion settings the parameters say.
pub fn motion_settings(params: &Params) -> MotionSettings {
    MotionSettings {
        period_s: 1.0 / params.f64("motion_rate").unwrap_or(50.0),
        mode: params
            .string("motion")
            .as_deref()
            .and_then(MotionMode::parse)
            .unwrap_or(MotionMode::Joint),
        max_target_age_s: params.f64("max_target_age").unwrap_or(0.5),
        ..MotionSettings::default()
    }
}

/// One event for the loop.
#[derive(Clone, Debug)]
pub enum Input {
    /// An `xyz_target` sample.
    XyzTarget(PointStamped),
    /// A `pose_target` sample.
    PoseTarget(PoseStamped),
    /// A `gripper_target` sample and when it arrived.
    GripperTarget(f64, Time),
    /// A `joint_target` sample.
    JointTarget(JointState),
    /// An `estop` sample.
    Estop(bool),
    /// A sample that could not be read (malformed): where, and the error.
    Unreadable(core::Source, String),
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

/// A Cartesian target's stamp (s), for the lateness check.
fn cartesian_stamp(input: &Input) -> Option<f64> {
    match input {
        Input::XyzTarget(m) => Some(m.header.stamp.to_nanos() as f64 * 1e-9),
        Input::PoseTarget(m) => Some(m.header.stamp.to_nanos() as f64 * 1e-9),
        _ => None,
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
    /// The peer counts of the watched topics, in [`watched_topics`]' order:
    /// `servo_angles` subscribers, `joint_states` subscribers, `xyz_target` publishers.
    fn peer_counts(&self) -> [usize; 3];
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

/// Most frequent diagnostics sent at once on a rejection; the periodic report covers the rest.
const MIN_IMMEDIATE_DIAG_GAP: Duration = Duration::from_millis(100);

/// The event loop: runs until `shutdown` resolves or `inputs` ends. `peers` watches
/// the topics of [`watched_topics`].
pub async fn run(
    mut core: Core,
    inputs: impl Stream<Item = Input>,
    outputs: &impl Outputs,
    params: Params,
    diag_name: String,
    mut peers: PeerWatch,
    shutdown: impl Future<Output = ()>,
) {
    let period = ros_plumbing::diagnostics::diagnostics_period;
    let mut ticker = tokio::time::interval(period(&params));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut param_changes = params.subscribe();
    let mut last_immediate = Instant::now() - MIN_IMMEDIATE_DIAG_GAP;
    // A viewer (state_publisher, RViz, the GUI) that joins gets the current pose at once,
    // not at the next target: joint_states, stamped now (no servo moves for it).
    let mut subscriber_poll = tokio::time::interval_at(
        tokio::time::Instant::now() + SUBSCRIBER_POLL,
        SUBSCRIBER_POLL,
    );
    let mut subscribers = 0;
    let mut greet_polls = 0u8;
    let report = |core: &Core, peers: &PeerWatch| {
        let mut s = core.diagnostic_status(&diag_name);
        peers.annotate(&mut s, Instant::now());
        params.annotate(&mut s);
        outputs.diagnostics(s);
    };
    let publish = |step: Step| {
        if let Some(servo_angles) = step.servo_angles {
            outputs.servo_angles(servo_angles);
        }
        outputs.joint_states(step.joint_states);
    };
    // a Cartesian target (xyz or pose) that arrived late (repaired after a network
    // outage), held back for burst::HOLD_LATE in case a newer one follows
    let mut held = burst::Held::<Input>::default();
    let mut lateness = burst::Lateness::default();
    let mut complaints = Throttle::default();
    core.apply_params(&params);
    // the planned motion: one step per period while moving, the first with the input
    let step_period = |core: &Core| Duration::from_secs_f64(core.motion().period_s);
    let mut next_step: Option<tokio::time::Instant> = None;
    tokio::pin!(inputs);
    tokio::pin!(shutdown);
    loop {
        let mut batch = Vec::new();
        let hold_until = held.deadline();
        tokio::select! {
            _ = &mut shutdown => break,
            _ = async { if let Some(t) = next_step { tokio::time::sleep_until(t).await } }, if next_step.is_some() => {
                if let Some(step) = core.step(Time::now()) {
                    publish(step);
                }
                next_step = next_step.map(|t| t + step_period(&core)).filter(|_| core.is_moving());
                if next_step.is_none() {
                    report(&core, &peers);
                }
            }
            _ = async { if let Some(t) = hold_until { tokio::time::sleep_until(t).await } }, if hold_until.is_some() => {
                if let Some(m) = held.take_due(tokio::time::Instant::now()) {
                    log::debug!("applying the newest late target");
                    batch.push(m);
                }
            }
            _ = ticker.tick() => report(&core, &peers),
            _ = subscriber_poll.tick() => {
                let counts = outputs.peer_counts();
                let changes = peers.update(&counts, Instant::now());
                changes.iter().for_each(|c| c.log());
                if !changes.is_empty() {
                    report(&core, &peers);
                }
                let now = counts[1];
                if now > subscribers {
                    // the new reader may match our writer a little after we match it:
                    // send the pose over the next second, not only once
                    greet_polls = 4;
                }
                subscribers = now;
                if greet_polls > 0 {
                    greet_polls -= 1;
                    outputs.joint_states(core.joint_states(Time::now()));
                }
            }
            Ok(()) = param_changes.changed() => {
                let solver = core_solver(&core);
                core.apply_params(&params);
                if core_solver(&core) != solver {
                    log::info!("solver: {}", params.string("solver").unwrap_or_default());
                    report(&core, &peers);
                }
                ticker = tokio::time::interval(period(&params));
            }
            input = inputs.next() => {
                let Some(first) = input else { break };
                // a burst (DDS repairing what a network outage held back) is applied
                // as its newest target; a lone target goes at once
                let arrived = burst::take_burst(first, &mut inputs);
                let (arrived, superseded) = coalesce(arrived);
                if superseded > 0 {
                    log::debug!("{superseded} targets superseded by newer ones that arrived with them");
                    core.count_superseded(superseded as u64);
                }
                for input in arrived {
                    if let Some(stamp) = cartesian_stamp(&input) {
                        let now = Time::now().to_nanos() as f64 * 1e-9;
                        if lateness.is_late(stamp, now, Instant::now()) {
                            if held.hold(input, tokio::time::Instant::now()) {
                                log::debug!("a late target superseded by a newer one");
                                core.count_superseded(1);
                            }
                            continue;
                        }
                        if held.discard() {
                            log::debug!("a late target superseded by a newer one");
                            core.count_superseded(1);
                        }
                    }
                    batch.push(input);
                }
            }
        }
        for input in batch {
            if let Input::Estop(engaged) = input {
                if engaged != core.estop() {
                    if engaged {
                        log::warn!("emergency stop engaged: targets refused until estop is false")
                    } else {
                        log::info!("emergency stop released")
                    }
                    core.set_estop(engaged);
                    next_step = None;
                    report(&core, &peers);
                }
                continue;
            }
            let Some(result) = core.handle(&input, Time::now()) else {
                continue;
            };
            for notice in core.take_notices() {
                if let Some(quiet) = complaints.allow(&notice.kind, Instant::now()) {
                    log::info!("{}{}", notice.text, Throttle::suffix(quiet));
                }
            }
            match result {
                Ok(step) => {
                    publish(step);
                    // The next step one and a half periods after this first one: a
                    // target stream at the motion rate (a 50 Hz teleop) steps the
                    // motion itself, and a fill-in step comes only when targets pause.
                    // With one period, a target a little late behind the timer made two
                    // steps back to back: 52 steps a second for a 50 Hz stream, more than
                    // serial_node's 50 frames a second, so every command waited for a
                    // frame slot (xyz_target -> first byte p50 7.5 ms). Each step is one
                    // planner period of motion whenever it is published, so a later
                    // fill-in never makes a step larger.
                    next_step = core
                        .is_moving()
                        .then(|| tokio::time::Instant::now() + step_period(&core).mul_f64(1.5));
                }
                Err(rejection) => {
                    let kind = format!("{}/{}", rejection.source.topic(), rejection.reason.code());
                    if let Some(quiet) = complaints.allow(&kind, Instant::now()) {
                        log::warn!("{rejection}{}", Throttle::suffix(quiet));
                    }
                    if last_immediate.elapsed() >= MIN_IMMEDIATE_DIAG_GAP {
                        last_immediate = Instant::now();
                        report(&core, &peers);
                    }
                }
            }
        }
    }
}

fn core_solver(core: &Core) -> Solver {
    match core {
        Core::EezyBot(c) => c.solver(),
        Core::Urdf(c) => c.solver(),
    }
}
