//! `compute_ik`: targets → joint states and servo angles.
//!
//! Subscribes `xyz_target`, `gripper_target`, `joint_target` and `estop`; publishes
//! `joint_states`, `servo_angles` and `diagnostics` (see `shared/INTERFACES.md`).
//! The logic is [`core::IkCore`]; [`run`] is the event loop, handed its inputs and
//! outputs so that tests can drive it without ROS.

#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod core;

use crate::core::{IkCore, MotionMode, MotionSettings, Output};
use eezybot_kinematics::ArmConfig;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::PointStamped;
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
            .validator(|v| match v {
                ParameterValue::String(p) => load_config(p).map(|_| ()).map_err(|e| e.to_string()),
                _ => Ok(()),
            }),
            ParamSpec::new("base_frame", ParameterValue::String("base_link".into()), "frame xyz_target must be given in")
                .validator(|v| match v {
                    ParameterValue::String(s) if s.is_empty() => Err("must not be empty".into()),
                    _ => Ok(()),
                }),
            ParamSpec::new("diagnostics_period", ParameterValue::Double(1.0), "seconds between diagnostics reports")
                .range(ParamRange::Double { min: 0.05, max: 60.0 }),
            ParamSpec::new(
                "motion",
                ParameterValue::String("joint".into()),
                "how xyz targets are moved to: `joint` (every servo within its limits, together) or `line` (the tool on a straight line, refused if any point of it is unreachable)",
            )
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
        ],
    }
}

/// Load the arm configuration named by the `arm_config` parameter.
pub fn load_config(path: &str) -> Result<ArmConfig, eezybot_kinematics::ConfigError> {
    ArmConfig::load_or_shipped(path)
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
/// `xyz_target` followed by a newer one is superseded, and so is a `gripper_target`
/// (latest wins); `joint_target`s (which may name only some joints), e-stops and
/// unreadable samples are all kept. Returns them and how many were superseded.
pub fn coalesce(batch: Vec<Input>) -> (Vec<Input>, usize) {
    burst::latest_wins(batch, |i| match i {
        Input::XyzTarget(_) => Some(0),
        Input::GripperTarget(..) => Some(1),
        _ => None,
    })
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
    mut core: IkCore,
    inputs: impl Stream<Item = Input>,
    outputs: &impl Outputs,
    params: Params,
    diag_name: String,
    mut peers: PeerWatch,
    shutdown: impl Future<Output = ()>,
) {
    let period = |p: &Params| Duration::from_secs_f64(p.f64("diagnostics_period").unwrap_or(1.0));
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
    let report = |core: &IkCore, peers: &PeerWatch| {
        let mut s = core.diagnostic_status(&diag_name);
        peers.annotate(&mut s, Instant::now());
        outputs.diagnostics(s);
    };
    // an xyz_target that arrived late (repaired after a network outage), held back
    // for burst::HOLD_LATE in case a newer one follows
    let mut held = burst::Held::<PointStamped>::default();
    let mut lateness = burst::Lateness::default();
    let mut complaints = Throttle::default();
    core.set_motion(motion_settings(&params));
    // the planned motion: one step per period while moving, the first with the input
    let step_period = |core: &IkCore| Duration::from_secs_f64(core.motion().period_s);
    let mut next_step: Option<tokio::time::Instant> = None;
    tokio::pin!(inputs);
    tokio::pin!(shutdown);
    loop {
        let mut batch = Vec::new();
        let hold_until = held.deadline();
        tokio::select! {
            _ = &mut shutdown => break,
            _ = async { if let Some(t) = next_step { tokio::time::sleep_until(t).await } }, if next_step.is_some() => {
                if let Some(Output { joint_states, servo_angles }) = core.step(Time::now()) {
                    outputs.servo_angles(servo_angles);
                    outputs.joint_states(joint_states);
                }
                next_step = next_step.map(|t| t + step_period(&core)).filter(|_| core.is_moving());
                if next_step.is_none() {
                    report(&core, &peers);
                }
            }
            _ = async { if let Some(t) = hold_until { tokio::time::sleep_until(t).await } }, if hold_until.is_some() => {
                if let Some(m) = held.take_due(tokio::time::Instant::now()) {
                    log::debug!("applying the newest late target");
                    batch.push(Input::XyzTarget(m));
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
                // Values were validated before they were stored; a file that vanished since is reported.
                match load_config(&params.string("arm_config").unwrap_or_default()) {
                    Ok(config) => core.set_config(&config),
                    Err(e) => log::error!("keeping the previous arm configuration: {e}"),
                }
                core.set_base_frame(&params.string("base_frame").unwrap_or_else(|| "base_link".into()));
                core.set_motion(motion_settings(&params));
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
                    if let Input::XyzTarget(m) = &input {
                        let (stamp, now) = (m.header.stamp.to_nanos() as f64 * 1e-9, Time::now().to_nanos() as f64 * 1e-9);
                        if lateness.is_late(stamp, now, Instant::now()) {
                            if let Input::XyzTarget(m) = input {
                                if held.hold(m, tokio::time::Instant::now()) {
                                    log::debug!("a late target superseded by a newer one");
                                    core.count_superseded(1);
                                }
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
            let result = match input {
                Input::XyzTarget(m) => core.handle_xyz_target(&m, Time::now()),
                Input::GripperTarget(v, stamp) => core.handle_gripper_target(v, stamp),
                Input::JointTarget(m) => core.handle_joint_target(&m, Time::now()),
                Input::Estop(engaged) => {
                    if engaged != core.estop() {
                        if engaged {
                            log::warn!(
                                "emergency stop engaged: targets refused until estop is false"
                            )
                        } else {
                            log::info!("emergency stop released")
                        }
                        core.set_estop(engaged);
                        next_step = None;
                        report(&core, &peers);
                    }
                    continue;
                }
                Input::Unreadable(source, e) => Err(core.reject_unreadable(source, e)),
            };
            match result {
                Ok(Output {
                    joint_states,
                    servo_angles,
                }) => {
                    outputs.servo_angles(servo_angles);
                    outputs.joint_states(joint_states);
                    // the next step one period after this first one
                    next_step = core
                        .is_moving()
                        .then(|| tokio::time::Instant::now() + step_period(&core));
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
