//! `compute_ik` binary: sets up ROS and runs [`compute_ik::run`].

use compute_ik::core::Source;
use compute_ik::{ArmModel, Core, Handles, Input, Outputs, Pipeline};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::PointStamped;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use ros_plumbing::diagnostics::DiagnosticsPublisher;
use ros_plumbing::peers::PeerWatch;
use ros_plumbing::Subscription;
use ros_plumbing::{samples, topics, RosNode, Shutdown, TopicPublisher};
use std::process::ExitCode;

struct RosOutputs<'a> {
    node: &'a ros_plumbing::Node,
    xyz: &'a Subscription<PointStamped>,
    joint_states: TopicPublisher<JointState>,
    /// the EezyBot's servos; an arm without a servo mapping has none
    servo_angles: Option<TopicPublisher<JointState>>,
    diagnostics: DiagnosticsPublisher,
}

impl Outputs for RosOutputs<'_> {
    fn joint_states(&self, msg: JointState) {
        self.joint_states.publish(msg);
    }
    fn servo_angles(&self, msg: JointState) {
        if let Some(p) = &self.servo_angles {
            p.publish(msg);
        }
    }
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.publish(vec![status]);
    }
    fn peer_counts(&self) -> [usize; 3] {
        [
            self.servo_angles
                .as_ref()
                .map_or(0, |p| p.get_subscription_count(self.node)),
            self.joint_states.get_subscription_count(self.node),
            self.xyz.get_publisher_count(self.node),
        ]
    }
}

fn main() -> ExitCode {
    ros_plumbing::node::main(
        compute_ik::spec(),
        async |node, shutdown| -> anyhow::Result<()> {
            let params = node.params().clone();
            match Core::from_params(&params).map_err(anyhow::Error::msg)? {
                Core::EezyBot(core) => serve(*core, node, params, shutdown).await,
                Core::Urdf(core) => serve(*core, node, params, shutdown).await,
            }
        },
    )
}

/// Subscribe, publish and run the node for this arm until `shutdown`.
async fn serve<M: ArmModel>(
    core: Pipeline<M>,
    node: &mut RosNode,
    params: ros_plumbing::Params,
    shutdown: Shutdown,
) -> anyhow::Result<()> {
    let arm = core.model();

    let xyz = node.subscribe_to(&topics::XYZ_TARGET)?;
    let gripper = node.subscribe_to(&topics::GRIPPER_TARGET)?;
    let joints = node.subscribe_to(&topics::JOINT_TARGET)?;
    let pose = node.subscribe_to(&topics::POSE_TARGET)?;
    let estop = node.subscribe_to(&topics::ESTOP)?;
    let joint_states = node.publish_on(&topics::JOINT_STATES)?;
    let servo_angles = if arm.has_servos() {
        Some(node.publish_on(&topics::SERVO_ANGLES)?)
    } else {
        None
    };
    let diagnostics = node.diagnostics()?;
    let peers = PeerWatch::new(&compute_ik::watched_topics(
        &node.resolve(&topics::SERVO_ANGLES)?,
        &node.resolve(&topics::JOINT_STATES)?,
        &node.resolve(&topics::XYZ_TARGET)?,
    ));
    let outputs = RosOutputs {
        node: node.node(),
        xyz: &xyz,
        joint_states,
        servo_angles,
        diagnostics,
    };

    let inputs = futures::stream::select_all([
        samples::inputs(&xyz, Input::XyzTarget, |e| {
            Input::Unreadable(Source::XyzTarget, e)
        }),
        samples::inputs(
            &gripper,
            |m| Input::GripperTarget(m.data, Time::now()),
            |e| Input::Unreadable(Source::GripperTarget, e),
        ),
        samples::inputs(&joints, Input::JointTarget, |e| {
            Input::Unreadable(Source::JointTarget, e)
        }),
        samples::inputs(&pose, Input::PoseTarget, |e| {
            Input::Unreadable(Source::PoseTarget, e)
        }),
        samples::readable_inputs(&estop, &topics::ESTOP, |m| Input::Estop(m.data)),
    ]);

    let diag_name = format!("{}: inverse kinematics", node.resolver().node_name());
    log::info!(
        "{} ready in ROS domain {}: {} -> {}{}; arm: {}",
        node.resolver().node_fqn(),
        node.domain_id(),
        node.resolve(&topics::XYZ_TARGET)?,
        node.resolve(&topics::JOINT_STATES)?,
        if arm.has_servos() {
            format!(", {}", node.resolve(&topics::SERVO_ANGLES)?)
        } else {
            String::new()
        },
        arm.describe()
    );
    let handles = Handles {
        inputs,
        outputs,
        params,
        peers,
        diag_name,
        shutdown,
    };
    compute_ik::run(core, handles).await;
    Ok(())
}
