//! `compute_ik` binary: sets up ROS and runs [`compute_ik::run`].

use compute_ik::core::Source;
use compute_ik::driver::Effect;
use compute_ik::pipeline::GoalRequest;
use compute_ik::{ArmModel, Core, FeedbackLayout, Handles, Input, Outputs, Pipeline};
use eezybot_msgs::control_msgs::{
    FollowJointTrajectoryFeedback, FollowJointTrajectoryFeedbackJazzy, FollowJointTrajectoryGoal,
    FollowJointTrajectoryResult, GripperCommandGoal, GripperCommandResult,
    JointTrajectoryControllerState,
};
use eezybot_msgs::controller_manager_msgs::{
    ListControllersRequest, ListControllersResponse, SwitchControllerRequest,
    SwitchControllerResponse,
};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::PointStamped;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use futures::StreamExt;
use ros_plumbing::action::{ActionRequest, ActionServer};
use ros_plumbing::diagnostics::DiagnosticsPublisher;
use ros_plumbing::peers::PeerWatch;
use ros_plumbing::service::ServiceServer;
use ros_plumbing::Subscription;
use ros_plumbing::{samples, topics, RosNode, Shutdown, TopicPublisher};
use std::process::ExitCode;

/// FollowJointTrajectory feedback in the layout `feedback_layout` asks for (serialized
/// as the variant it holds).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
enum FeedbackWire {
    Kilted(FollowJointTrajectoryFeedback),
    Jazzy(FollowJointTrajectoryFeedbackJazzy),
}
impl ros_plumbing::Message for FeedbackWire {}

type TrajectoryServer =
    ActionServer<FollowJointTrajectoryGoal, FollowJointTrajectoryResult, FeedbackWire>;
type GripperServer = ActionServer<GripperCommandGoal, GripperCommandResult, GripperCommandResult>;

/// The controller manager's services (ros2_control's interface).
struct Manager {
    list: ServiceServer<ListControllersRequest, ListControllersResponse>,
    switch: ServiceServer<SwitchControllerRequest, SwitchControllerResponse>,
}

/// arm_controller's and gripper_controller's endpoints (the EezyBot's).
struct Controllers {
    trajectory: TrajectoryServer,
    gripper: GripperServer,
    state: TopicPublisher<JointTrajectoryControllerState>,
    layout: FeedbackLayout,
}

struct RosOutputs<'a> {
    node: &'a ros_plumbing::Node,
    xyz: &'a Subscription<PointStamped>,
    joint_states: TopicPublisher<JointState>,
    /// the EezyBot's servos; an arm without a servo mapping has none
    servo_angles: Option<TopicPublisher<JointState>>,
    diagnostics: DiagnosticsPublisher,
    controllers: Option<&'a Controllers>,
    manager: &'a Manager,
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
    fn controllers(&self, effect: Effect) {
        match effect {
            Effect::ListControllers(ticket, r) => return self.manager.list.answer(ticket, r),
            Effect::SwitchController(ticket, r) => return self.manager.switch.answer(ticket, r),
            _ => {}
        }
        let Some(c) = self.controllers else { return };
        match effect {
            Effect::AnswerGoal {
                ticket,
                accepted,
                gripper,
            } => match (gripper, accepted) {
                (false, true) => c.trajectory.accept(ticket),
                (false, false) => c.trajectory.reject(ticket),
                (true, true) => c.gripper.accept(ticket),
                (true, false) => c.gripper.reject(ticket),
            },
            Effect::TrajectoryFeedback(id, f) => {
                let wire = match c.layout {
                    FeedbackLayout::Kilted => FeedbackWire::Kilted(*f),
                    FeedbackLayout::Any => FeedbackWire::Kilted(FollowJointTrajectoryFeedback {
                        index: 0,
                        multi_dof_index: 0,
                        ..*f
                    }),
                    FeedbackLayout::Jazzy => FeedbackWire::Jazzy((*f).into()),
                };
                c.trajectory.feedback(id, wire);
            }
            Effect::TrajectoryResult(id, end, r) => c.trajectory.finish(id, end, r),
            Effect::GripperFeedback(id, f) => c.gripper.feedback(id, f),
            Effect::GripperResult(id, end, r) => c.gripper.finish(id, end, r),
            Effect::ControllerState(m) => c.state.publish(*m),
            _ => {}
        }
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
    fn joint_states_readers(&self) -> Vec<compute_ik::driver::ReaderId> {
        self.joint_states.subscriptions(self.node)
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
    let xyz_line = node.subscribe_to(&topics::XYZ_LINE_TARGET)?;
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
    let controllers = match arm.controller_map() {
        None => None,
        Some(_) => {
            let resolver = node.resolver().clone();
            let layout =
                FeedbackLayout::parse(&params.string("feedback_layout").unwrap_or_default())
                    .unwrap_or(FeedbackLayout::Any);
            let trajectory = ActionServer::new(
                node.node_mut(),
                &resolver,
                topics::FOLLOW_JOINT_TRAJECTORY.name,
                topics::FOLLOW_JOINT_TRAJECTORY.package,
                topics::FOLLOW_JOINT_TRAJECTORY.type_name,
            )?;
            let gripper = ActionServer::new(
                node.node_mut(),
                &resolver,
                topics::GRIPPER_CMD.name,
                topics::GRIPPER_CMD.package,
                topics::GRIPPER_CMD.type_name,
            )?;
            Some(Controllers {
                trajectory,
                gripper,
                state: node.publish_on(&topics::CONTROLLER_STATE)?,
                layout,
            })
        }
    };
    let trajectory_topic = match &controllers {
        Some(_) => Some(node.subscribe_to(&topics::JOINT_TRAJECTORY)?),
        None => None,
    };
    let leader = match &controllers {
        Some(_) => Some((
            node.subscribe_to(&topics::LEADER_JOINT_STATES)?,
            node.subscribe_to(&topics::LEADER_DEADMAN)?,
        )),
        None => None,
    };
    let servo_state = match &controllers {
        Some(_) => Some(node.subscribe_to(&topics::SERVO_STATE)?),
        None => None,
    };
    let manager = {
        let resolver = node.resolver().clone();
        Manager {
            list: ServiceServer::new(
                node.node_mut(),
                &resolver,
                topics::LIST_CONTROLLERS.name,
                topics::LIST_CONTROLLERS.package,
                topics::LIST_CONTROLLERS.type_name,
            )?,
            switch: ServiceServer::new(
                node.node_mut(),
                &resolver,
                topics::SWITCH_CONTROLLER.name,
                topics::SWITCH_CONTROLLER.package,
                topics::SWITCH_CONTROLLER.type_name,
            )?,
        }
    };
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
        controllers: controllers.as_ref(),
        manager: &manager,
    };

    let inputs = futures::stream::select_all([
        samples::inputs(&xyz, Input::XyzTarget, |e| {
            Input::Unreadable(Source::XyzTarget, e)
        }),
        samples::inputs(&xyz_line, Input::XyzLineTarget, |e| {
            Input::Unreadable(Source::XyzLineTarget, e)
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
    let mut controller_inputs = Vec::new();
    if let Some(t) = &trajectory_topic {
        controller_inputs.push(
            samples::readable_inputs(t, &topics::JOINT_TRAJECTORY, Input::Trajectory).boxed_local(),
        );
    }
    if let Some(s) = &servo_state {
        controller_inputs.push(
            samples::readable_inputs(s, &topics::SERVO_STATE, Input::ServoState).boxed_local(),
        );
    }
    if let Some((joints, deadman)) = &leader {
        controller_inputs.push(
            samples::readable_inputs(joints, &topics::LEADER_JOINT_STATES, Input::LeaderJoints)
                .boxed_local(),
        );
        controller_inputs.push(
            samples::readable_inputs(deadman, &topics::LEADER_DEADMAN, |m| {
                Input::LeaderDeadman(m.data)
            })
            .boxed_local(),
        );
    }
    controller_inputs.push(service_inputs(&manager.list, |t, c, _| {
        Input::ListControllers(t, c)
    }));
    controller_inputs.push(service_inputs(&manager.switch, Input::SwitchController));
    if let Some(c) = &controllers {
        controller_inputs.push(action_inputs(&c.trajectory, Input::TrajectoryGoal));
        controller_inputs.push(action_inputs(&c.gripper, Input::GripperGoal));
    }
    let inputs = futures::stream::select(inputs, futures::stream::select_all(controller_inputs));

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

/// An action server's goals and accepted cancels as inputs; a request that cannot be
/// read is logged and left out.
fn action_inputs<'a, G, R, F>(
    server: &'a ActionServer<G, R, F>,
    goal: fn(GoalRequest<G>) -> Input,
) -> futures::stream::LocalBoxStream<'a, Input>
where
    G: ros_plumbing::Message + Clone + 'static,
    R: ros_plumbing::Message + Clone + Default + 'static,
    F: ros_plumbing::Message + 'static,
{
    futures::stream::unfold(server, move |server| async move {
        loop {
            let input = match server.next().await {
                ActionRequest::Goal {
                    ticket,
                    id,
                    goal: g,
                } => goal(GoalRequest {
                    ticket,
                    id,
                    goal: Box::new(g),
                }),
                ActionRequest::Cancel(ids) => Input::Cancel(ids),
                ActionRequest::Unreadable(e) => {
                    log::warn!("{}: unreadable request ignored: {e}", server.name());
                    continue;
                }
            };
            return Some((input, server));
        }
    })
    .boxed_local()
}

/// A service's requests as inputs; a request that cannot be read is logged and left out.
fn service_inputs<'a, Req, Resp>(
    server: &'a ServiceServer<Req, Resp>,
    input: fn(ros_plumbing::service::Ticket, ros_plumbing::service::Caller, Req) -> Input,
) -> futures::stream::LocalBoxStream<'a, Input>
where
    Req: ros_plumbing::Message + Clone + 'static,
    Resp: ros_plumbing::Message + 'static,
{
    futures::stream::unfold(server, move |server| async move {
        loop {
            match server.next().await {
                Ok((ticket, caller, request)) => {
                    return Some((input(ticket, caller, request), server))
                }
                Err(e) => log::warn!("unreadable request ignored: {e}"),
            }
        }
    })
    .boxed_local()
}
