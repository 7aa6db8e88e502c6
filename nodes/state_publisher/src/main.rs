//! `state_publisher` binary: sets up ROS and runs [`state_publisher::run`].

use anyhow::Context as _;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::String as StringMsg;
use eezybot_msgs::tf2_msgs::TFMessage;
use ros_plumbing::diagnostics::DiagnosticsPublisher;
use ros_plumbing::Subscription;
use ros_plumbing::{samples, topics, RosNode, Shutdown, TopicPublisher};
use state_publisher::{load_urdf, urdf_origin, Input, Outputs};
use std::process::ExitCode;
use std::time::Instant;

struct RosOutputs<'a> {
    node: &'a ros_plumbing::Node,
    joint_states: &'a Subscription<JointState>,
    tf: TopicPublisher<TFMessage>,
    tf_static: TopicPublisher<TFMessage>,
    robot_description: TopicPublisher<StringMsg>,
    diagnostics: DiagnosticsPublisher,
}

impl Outputs for RosOutputs<'_> {
    fn tf(&self, msg: TFMessage) {
        self.tf.publish(msg);
    }
    fn tf_static(&self, msg: TFMessage) {
        self.tf_static.publish(msg);
    }
    fn robot_description(&self, urdf: String) {
        self.robot_description.publish(StringMsg { data: urdf });
    }
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.publish(vec![status]);
    }
    fn joint_states_publishers(&self) -> usize {
        self.joint_states.get_publisher_count(self.node)
    }
}

fn main() -> ExitCode {
    ros_plumbing::node::main(state_publisher::spec(), serve)
}

/// Load the URDF, subscribe, publish and run the node until `shutdown`.
async fn serve(node: &mut RosNode, shutdown: Shutdown) -> anyhow::Result<()> {
    let params = node.params().clone();
    let path = params.string("urdf").unwrap_or_default();
    let description = load_urdf(&path)
        .map_err(anyhow::Error::msg)
        .context("urdf")?;
    let joint_states = node.subscribe_to(&topics::JOINT_STATES)?;
    let tf = node.publish_on(&topics::TF)?;
    let tf_static = node.publish_on(&topics::TF_STATIC)?;
    let robot_description = node.publish_on(&topics::ROBOT_DESCRIPTION)?;
    let diagnostics = node.diagnostics()?;
    let outputs = RosOutputs {
        node: node.node(),
        joint_states: &joint_states,
        tf,
        tf_static,
        robot_description,
        diagnostics,
    };
    let inputs = samples::inputs(
        &joint_states,
        |m| Input::JointStates(m, Instant::now()),
        Input::Unreadable,
    );
    log::info!(
        "{} ready in ROS domain {}: {} ({} links) on {}, {}, {}",
        node.resolver().node_fqn(),
        node.domain_id(),
        urdf_origin(&path),
        description.model.links.len(),
        node.resolve(&topics::ROBOT_DESCRIPTION)?,
        node.resolve(&topics::TF_STATIC)?,
        node.resolve(&topics::TF)?
    );
    let diag_name = format!("{}: robot state", node.resolver().node_name());
    let topic = node.resolve(&topics::JOINT_STATES)?;
    let io = state_publisher::Io {
        outputs: &outputs,
        params,
        diag_name,
        joint_states_topic: topic,
    };
    state_publisher::run(state_publisher::Handles {
        description,
        io,
        inputs,
        shutdown,
    })
    .await;
    Ok(())
}
