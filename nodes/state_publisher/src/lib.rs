#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod core;
pub mod throttle;

use crate::core::TfCore;
use crate::throttle::{Flush, TfThrottle};
use eezybot_kinematics::urdf::RobotModel;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::tf2_msgs::TFMessage;
use eezybot_msgs::Time;
use futures::{Stream, StreamExt};
use ros_plumbing::diagnostics::LatencyWindow;
use ros_plumbing::logging::Throttle;
use ros_plumbing::peers::{Peer, PeerWatch};
use ros_plumbing::{ParamRange, ParamSpec, ParameterValue, Params};
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
            ParamSpec::file(
                "urdf",
                "path of the URDF to publish; empty = the EezyBotArm URDF built into this binary (urdf/eezybot.urdf)",
                "empty, or a URDF file that loads",
                |p| load_urdf(p).map(|_| ()),
            ),
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

/// What the node's handlers ([`Node`]) work with: the outputs, the parameters and
/// the names in its diagnostics.
pub struct Io<'a, O> {
    /// where results go
    pub outputs: &'a O,
    /// the node's parameters
    pub params: Params,
    /// the diagnostics entry's name
    pub diag_name: String,
    /// the resolved `joint_states` topic, whose publishers are watched
    pub joint_states_topic: String,
}

/// What [`run`] works with: the URDF to publish first, the handlers' [`Io`], and the
/// sources of the loop.
pub struct Handles<'a, I, O, S> {
    /// the URDF to publish first
    pub description: Description,
    /// for the handlers
    pub io: Io<'a, O>,
    /// `joint_states` samples
    pub inputs: I,
    /// resolves when the node is to stop
    pub shutdown: S,
}

/// The loop: runs until `shutdown` resolves or `inputs` ends. Each input and timer
/// goes to one handler of [`Node`].
pub async fn run<O: Outputs>(
    h: Handles<'_, impl Stream<Item = Input>, O, impl Future<Output = ()>>,
) {
    let params = h.io.params.clone();
    let (inputs, shutdown) = (h.inputs, h.shutdown);
    let mut node = Node::new(h.description, h.io);
    let mut peer_poll = tokio::time::interval(Duration::from_millis(250));
    let period = ros_plumbing::diagnostics::diagnostics_period;
    let mut ticker = tokio::time::interval(period(&params));
    let mut param_changes = params.subscribe();
    tokio::pin!(inputs);
    tokio::pin!(shutdown);
    loop {
        let flush_at = node.throttle.flush_at().map(tokio::time::Instant::from_std);
        tokio::select! {
            _ = &mut shutdown => break,
            _ = ticker.tick() => node.report(),
            _ = peer_poll.tick() => node.on_peer_poll(),
            _ = async { if let Some(t) = flush_at { tokio::time::sleep_until(t).await } }, if flush_at.is_some() => {
                node.on_flush(Instant::now());
            }
            Ok(()) = param_changes.changed() => {
                node.on_params();
                ticker = tokio::time::interval(period(&params));
            }
            input = inputs.next() => match input {
                None => break,
                Some(Input::JointStates(msg, taken)) => node.on_joint_states(&msg, taken),
                Some(Input::Unreadable(e)) => node.on_unreadable(&e),
            },
        }
    }
}

/// The node's state between inputs, and a handler for each kind of input.
pub struct Node<'a, O> {
    io: Io<'a, O>,
    peers: PeerWatch,
    core: TfCore,
    throttle: TfThrottle,
    /// µs from taking a `joint_states` sample to having published its tf
    latency: LatencyWindow,
    unreadable: u64,
    complaints: Throttle,
}

impl<'a, O: Outputs> Node<'a, O> {
    /// Publish `robot_description` and `tf_static` for `description`.
    pub fn new(description: Description, io: Io<'a, O>) -> Self {
        let core = TfCore::new(description.model, &prefix(&io.params));
        io.outputs.robot_description(description.text);
        io.outputs.tf_static(core.static_transforms(Time::now()));
        Node {
            peers: PeerWatch::new(&[(io.joint_states_topic.clone(), Peer::Publisher)]),
            core,
            throttle: TfThrottle::new(io.params.f64("publish_frequency").unwrap_or(0.0)),
            io,
            latency: LatencyWindow::new(1000),
            unreadable: 0,
            complaints: Throttle::default(),
        }
    }

    /// Publish the diagnostics entry now.
    pub fn report(&self) {
        let mut extra = self
            .latency
            .p50_p99(["tf_latency_us_p50", "tf_latency_us_p99"]);
        extra.push(("unreadable_samples", self.unreadable.to_string()));
        let mut status = self.core.diagnostic_status(&self.io.diag_name, &extra);
        self.peers.annotate(&mut status, Instant::now());
        self.io.params.annotate(&mut status);
        self.io.outputs.diagnostics(status);
    }

    /// Look at the `joint_states` publishers; log a change.
    pub fn on_peer_poll(&mut self) {
        self.peers
            .update(&[self.io.outputs.joint_states_publishers()], Instant::now())
            .iter()
            .for_each(|c| c.log());
    }

    /// The throttle's interval is over at `now`: publish what is pending.
    pub fn on_flush(&mut self, now: Instant) {
        if let Some(f) = self.throttle.flush(now) {
            self.publish(f);
        }
    }

    /// The parameters changed: the throttle's frequency, and the URDF and frame
    /// prefix (kept if the URDF does not load).
    pub fn on_params(&mut self) {
        self.throttle
            .set_frequency(self.io.params.f64("publish_frequency").unwrap_or(0.0));
        let path = self.io.params.string("urdf").unwrap_or_default();
        match load_urdf(&path) {
            Ok(d) => {
                self.core = TfCore::new(d.model, &prefix(&self.io.params));
                self.throttle.clear();
                self.io.outputs.robot_description(d.text);
                self.io
                    .outputs
                    .tf_static(self.core.static_transforms(Time::now()));
                log::info!(
                    "publishing {} with frame prefix `{}`",
                    urdf_origin(&path),
                    prefix(&self.io.params)
                );
            }
            Err(e) => log::error!("keeping the previous URDF: {e}"),
        }
    }

    /// A `joint_states` sample taken at `taken`: its transforms go out through the
    /// throttle; what is wrong with it is logged (throttled).
    pub fn on_joint_states(&mut self, msg: &JointState, taken: Instant) {
        let (tf, problems) = self.core.handle_joint_states(msg);
        let now = Instant::now();
        for p in &problems {
            let kind = format!("{:?}", std::mem::discriminant(p));
            if let Some(quiet) = self.complaints.allow(&kind, now) {
                log::warn!("joint_states: {p}; skipped{}", Throttle::suffix(quiet));
            }
        }
        if let Some(f) = self.throttle.offer(tf.transforms, taken, now) {
            self.publish(f);
        }
    }

    /// A sample that could not be read: counted and logged.
    pub fn on_unreadable(&mut self, e: &str) {
        self.unreadable += 1;
        log::warn!("unreadable joint_states sample ignored: {e}");
    }

    /// Publish a tf message; its latency counts from its oldest sample's taking.
    fn publish(&mut self, f: Flush) {
        self.io.outputs.tf(f.msg);
        self.latency.push(f.taken.elapsed().as_secs_f64() * 1e6);
    }
}

fn prefix(p: &Params) -> String {
    p.string("frame_prefix").unwrap_or_default()
}
