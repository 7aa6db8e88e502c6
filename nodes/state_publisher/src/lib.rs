#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod core;

use crate::core::TfCore;
use eezybot_kinematics::urdf::RobotModel;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::TransformStamped;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::tf2_msgs::TFMessage;
use eezybot_msgs::Time;
use futures::{Stream, StreamExt};
use ros_plumbing::diagnostics::LatencyWindow;
use ros_plumbing::logging::Throttle;
use ros_plumbing::peers::{Peer, PeerWatch};
use ros_plumbing::{ParamRange, ParamSpec, ParameterValue, Params};
use std::collections::BTreeMap;
use std::future::Future;
use std::path::Path;
use std::time::{Duration, Instant};

/// The URDF shipped in `urdf/eezybot.urdf`, compiled in: what the `urdf` parameter's
/// default (`""`) publishes, so the binary needs no file of the source tree at run time.
pub const SHIPPED_URDF: &str = include_str!("../../../urdf/eezybot.urdf");

/// How logs and errors name [`SHIPPED_URDF`].
pub const SHIPPED_URDF_ORIGIN: &str = "urdf/eezybot.urdf (built in)";

/// The node's description and parameters.
pub fn spec() -> ros_plumbing::NodeSpec {
    ros_plumbing::NodeSpec {
        name: "state_publisher",
        description: "URDF + joint_states -> tf, tf_static and robot_description (like robot_state_publisher)",
        usage: "",
        params: vec![
            ParamSpec::new(
                "urdf",
                ParameterValue::String(String::new()),
                "path of the URDF to publish; empty = the EezyBotArm URDF built into this binary (urdf/eezybot.urdf)",
            )
                .constraints("empty, or a URDF file that loads")
                .validator(|v| match v {
                    ParameterValue::String(p) => load_urdf(p).map(|_| ()),
                    _ => Ok(()),
                }),
            ParamSpec::new("frame_prefix", ParameterValue::String(String::new()), "prefix for every frame id, e.g. arm2/"),
            ParamSpec::new(
                "publish_frequency",
                ParameterValue::Double(0.0),
                "most tf messages a second for movable joints (latest wins); 0 = one per joint_states",
            )
            .range(ParamRange::Double { min: 0.0, max: 10_000.0 }),
            ros_plumbing::diagnostics::diagnostics_period_param(),
        ],
    }
}

/// A parsed URDF with its text.
#[derive(Clone, Debug)]
pub struct Description {
    /// The model.
    pub model: RobotModel,
    /// The file's text, as published on `robot_description`.
    pub text: String,
}

/// Read and validate a URDF file; `""` is the built-in [`SHIPPED_URDF`]. The error names
/// the file and the problem.
pub fn load_urdf(path: &str) -> Result<Description, String> {
    if path.is_empty() {
        return parse_urdf(SHIPPED_URDF.to_string(), SHIPPED_URDF_ORIGIN);
    }
    let text =
        eezybot_kinematics::urdf::read_urdf_file(Path::new(path)).map_err(|e| e.to_string())?;
    parse_urdf(text, path)
}

fn parse_urdf(text: String, origin: &str) -> Result<Description, String> {
    let model = RobotModel::from_urdf_str(&text, origin).map_err(|e| e.to_string())?;
    Ok(Description { model, text })
}

/// How logs name the `urdf` parameter's value: the path, or the built-in URDF for `""`.
pub fn urdf_origin(path: &str) -> &str {
    if path.is_empty() {
        SHIPPED_URDF_ORIGIN
    } else {
        path
    }
}

/// Where the loop's results go.
pub trait Outputs {
    /// Publish on `tf`.
    fn tf(&self, msg: TFMessage);
    /// Publish on `tf_static`.
    fn tf_static(&self, msg: TFMessage);
    /// Publish on `robot_description`.
    fn robot_description(&self, urdf: String);
    /// Publish a `diagnostics` report.
    fn diagnostics(&self, status: DiagnosticStatus);
    /// The number of `joint_states` publishers matched now.
    fn joint_states_publishers(&self) -> usize;
}

/// One event for the loop.
#[derive(Clone, Debug)]
pub enum Input {
    /// A `joint_states` sample and when it was taken from the reader.
    JointStates(JointState, Instant),
    /// A sample that could not be read.
    Unreadable(String),
}

/// The loop: runs until `shutdown` resolves or `inputs` ends.
pub async fn run(
    description: Description,
    inputs: impl Stream<Item = Input>,
    outputs: &impl Outputs,
    params: Params,
    diag_name: String,
    joint_states_topic: String,
    shutdown: impl Future<Output = ()>,
) {
    let mut peers = PeerWatch::new(&[(joint_states_topic, Peer::Publisher)]);
    let mut peer_poll = tokio::time::interval(Duration::from_millis(250));
    let prefix = |p: &Params| p.string("frame_prefix").unwrap_or_default();
    let mut core = TfCore::new(description.model, &prefix(&params));
    outputs.robot_description(description.text);
    outputs.tf_static(core.static_transforms(Time::now()));
    let period = ros_plumbing::diagnostics::diagnostics_period;
    let min_interval = |p: &Params| {
        let f = p.f64("publish_frequency").unwrap_or(0.0);
        (f > 0.0).then(|| Duration::from_secs_f64(1.0 / f))
    };
    let mut ticker = tokio::time::interval(period(&params));
    let mut param_changes = params.subscribe();
    // µs from taking a `joint_states` sample to having published its tf
    let mut latency = LatencyWindow::new(1000);
    let mut last_tf = Instant::now() - Duration::from_secs(3600);
    let mut pending: BTreeMap<String, TransformStamped> = BTreeMap::new();
    let mut pending_since: Option<Instant> = None;
    let mut unreadable = 0u64;
    let mut complaints = Throttle::default();
    tokio::pin!(inputs);
    tokio::pin!(shutdown);
    loop {
        let flush_at = match (min_interval(&params), pending.is_empty()) {
            (Some(iv), false) => Some(tokio::time::Instant::from_std(last_tf + iv)),
            _ => None,
        };
        tokio::select! {
            _ = &mut shutdown => break,
            _ = ticker.tick() => {
                let mut extra = latency.p50_p99(["tf_latency_us_p50", "tf_latency_us_p99"]);
                extra.push(("unreadable_samples", unreadable.to_string()));
                let mut status = core.diagnostic_status(&diag_name, &extra);
                peers.annotate(&mut status, Instant::now());
                params.annotate(&mut status);
                outputs.diagnostics(status);
            }
            _ = peer_poll.tick() => {
                peers.update(&[outputs.joint_states_publishers()], Instant::now()).iter().for_each(|c| c.log());
            }
            _ = async { if let Some(t) = flush_at { tokio::time::sleep_until(t).await } }, if flush_at.is_some() => {
                outputs.tf(TFMessage { transforms: std::mem::take(&mut pending).into_values().collect() });
                last_tf = Instant::now();
                if let Some(t0) = pending_since.take() {
                    latency.push(t0.elapsed().as_secs_f64() * 1e6);
                }
            }
            Ok(()) = param_changes.changed() => {
                let path = params.string("urdf").unwrap_or_default();
                match load_urdf(&path) {
                    Ok(d) => {
                        core = TfCore::new(d.model, &prefix(&params));
                        pending.clear();
                        outputs.robot_description(d.text);
                        outputs.tf_static(core.static_transforms(Time::now()));
                        log::info!("publishing {} with frame prefix `{}`", urdf_origin(&path), prefix(&params));
                    }
                    Err(e) => log::error!("keeping the previous URDF: {e}"),
                }
                ticker = tokio::time::interval(period(&params));
            }
            input = inputs.next() => {
                let Some(input) = input else { break };
                let (msg, taken) = match input {
                    Input::JointStates(msg, taken) => (msg, taken),
                    Input::Unreadable(e) => {
                        unreadable += 1;
                        log::warn!("unreadable joint_states sample ignored: {e}");
                        continue;
                    }
                };
                let (tf, problems) = core.handle_joint_states(&msg);
                for p in &problems {
                    let kind = format!("{:?}", std::mem::discriminant(p));
                    if let Some(quiet) = complaints.allow(&kind, Instant::now()) {
                        log::warn!("joint_states: {p}; skipped{}", Throttle::suffix(quiet));
                    }
                }
                if tf.transforms.is_empty() {
                    continue;
                }
                match min_interval(&params) {
                    Some(iv) if last_tf.elapsed() < iv => {
                        for t in tf.transforms {
                            pending.insert(t.child_frame_id.clone(), t);
                        }
                        pending_since.get_or_insert(taken);
                    }
                    _ => {
                        let transforms = if pending.is_empty() {
                            tf.transforms
                        } else {
                            for t in tf.transforms {
                                pending.insert(t.child_frame_id.clone(), t);
                            }
                            std::mem::take(&mut pending).into_values().collect()
                        };
                        outputs.tf(TFMessage { transforms });
                        last_tf = Instant::now();
                        pending_since = None;
                        latency.push(taken.elapsed().as_secs_f64() * 1e6);
                    }
                }
            }
        }
    }
}
