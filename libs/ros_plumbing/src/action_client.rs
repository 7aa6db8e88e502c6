//! A client of one ROS 2 action, as `ros2 action send_goal` uses one: wait for the
//! server, send a goal (accepted or rejected), ask for its result, cancel it. The
//! recorder's `replay` drives `arm_controller/follow_joint_trajectory` with it.
//!
//! The action is named as [`crate::episodes::EpisodeClient`] names a recorder's
//! services: relative to the server node's namespace (`compute_ik` →
//! `/arm_controller/follow_joint_trajectory`, `/arm2/compute_ik` →
//! `/arm2/arm_controller/follow_joint_trajectory`).

use crate::action::{GoalEnd, GoalId};
use crate::topics::{Callable, CallableKind};
use crate::{PlumbingError, RosNode};
use ros2_client::action::{ActionClientQosPolicies, GoalStatusEnum};
use ros2_client::{ActionTypeName, Message, Name, ServiceMapping};
use std::time::Duration;

/// The QoS of rcl_action's client defaults, matching [`crate::action::server_qos`].
pub fn client_qos() -> ActionClientQosPolicies {
    ActionClientQosPolicies {
        goal_service: crate::qos::SERVICES,
        result_service: crate::qos::SERVICES,
        cancel_service: crate::qos::SERVICES,
        feedback_subscription: crate::qos::reliable(10),
        status_subscription: crate::qos::latched(1),
    }
}

/// A client of one action. `G`, `R`, `F`: goal, result, feedback.
pub struct ActionClient<G, R, F>
where
    G: Message + Clone,
    R: Message + Clone,
    F: Message,
{
    client: ros2_client::action::ActionClient<G, R, F>,
    name: String,
}

impl<G, R, F> ActionClient<G, R, F>
where
    G: Message + Clone + 'static,
    R: Message + Clone + 'static,
    F: Message + 'static,
{
    /// The client of `action` as served by the node named `node` (in our namespace,
    /// or absolute).
    pub fn new(ros: &mut RosNode, node: &str, action: &Callable) -> Result<Self, PlumbingError> {
        if action.kind != CallableKind::Action {
            return Err(PlumbingError::Ros(format!(
                "{} is a service, not an action",
                action.name
            )));
        }
        let node_name = ros.resolver().resolve(node)?;
        let namespace = match node_name.rfind('/') {
            Some(0) | None => String::new(),
            Some(i) => node_name[..i].to_string(),
        };
        let full = format!("{namespace}/{}", action.name);
        let ros_name = Name::parse(&full).map_err(|e| PlumbingError::Name {
            name: full.clone(),
            why: format!("{e:?}"),
        })?;
        let client = ros
            .node_mut()
            .create_action_client(
                ServiceMapping::Enhanced,
                &ros_name,
                &ActionTypeName::new(action.package, action.type_name),
                client_qos(),
            )
            .map_err(|e| PlumbingError::Ros(format!("cannot be a client of {full}: {e:?}")))?;
        Ok(ActionClient { client, name: full })
    }

    /// The action's full name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Wait until the goal, result and cancel services answer, at most `timeout`.
    pub async fn wait(&self, ros: &RosNode, timeout: Duration) -> Result<(), String> {
        let node = ros.node();
        let all = async {
            self.client.goal_client().wait_for_service(node).await;
            self.client.result_client().wait_for_service(node).await;
            self.client.cancel_client().wait_for_service(node).await;
        };
        tokio::time::timeout(timeout, all).await.map_err(|_| {
            format!(
                "no server of {} within {:.0} s (is its node running in this ROS domain?)",
                self.name,
                timeout.as_secs_f64()
            )
        })
    }

    /// Send `goal`: its id if the server accepted it, `None` if it rejected it.
    pub async fn send_goal(&self, goal: G, timeout: Duration) -> Result<Option<GoalId>, String> {
        let (id, response) = tokio::time::timeout(timeout, self.client.async_send_goal(goal))
            .await
            .map_err(|_| {
                format!(
                    "{} did not answer the goal within {:.0} s",
                    self.name,
                    timeout.as_secs_f64()
                )
            })?
            .map_err(|e| format!("{}: sending the goal: {e:?}", self.name))?;
        Ok(response
            .accepted
            .then(|| GoalId::from_bytes(*id.uuid.as_bytes())))
    }

    /// The result of an accepted goal, once it ended: how, and the server's result.
    pub async fn result(&self, id: GoalId) -> Result<(GoalEnd, R), String> {
        let (status, result) = self
            .client
            .async_request_result(ros_goal_id(id))
            .await
            .map_err(|e| format!("{}: asking for the result: {e:?}", self.name))?;
        let end = match status {
            GoalStatusEnum::Succeeded => GoalEnd::Succeeded,
            GoalStatusEnum::Aborted => GoalEnd::Aborted,
            GoalStatusEnum::Canceled => GoalEnd::Canceled,
            other => {
                return Err(format!(
                    "{}: the result came with status {other:?}, not an end",
                    self.name
                ))
            }
        };
        Ok((end, result))
    }

    /// Ask the server to cancel goal `id`: whether it agreed (the goal then ends as
    /// canceled, its result saying so).
    pub async fn cancel(&self, id: GoalId, timeout: Duration) -> Result<bool, String> {
        let response = tokio::time::timeout(
            timeout,
            self.client
                .async_cancel_goal(ros_goal_id(id), ros2_client::builtin_interfaces::Time::ZERO),
        )
        .await
        .map_err(|_| format!("{} did not answer the cancel request", self.name))?
        .map_err(|e| format!("{}: canceling: {e:?}", self.name))?;
        Ok(!response.goals_canceling.is_empty())
    }
}

fn ros_goal_id(id: GoalId) -> ros2_client::action::GoalId {
    ros2_client::action::GoalId {
        uuid: uuid::Uuid::from_bytes(*id.as_bytes()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::action::{ActionRequest, ActionServer};
    use crate::NodeSpec;

    #[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
    struct Order {
        order: i32,
    }
    impl Message for Order {}

    fn node(name: &'static str, domain: &str) -> RosNode {
        let spec = NodeSpec {
            name,
            description: "",
            usage: "",
            params: vec![],
        };
        RosNode::start_with(&spec, vec![], Some(domain)).unwrap()
    }

    /// A client in one participant, a server in another: a goal accepted and its
    /// result, a goal rejected, a goal canceled.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn goals_are_answered_finished_and_canceled() {
        // a domain of this process's own, and a name of its own in it
        let domain = (120 + std::process::id() % 100).to_string();
        let name: &'static str =
            Box::leak(format!("action_client_test_{}", std::process::id()).into_boxed_str());
        let callable: &'static Callable = Box::leak(Box::new(Callable {
            kind: CallableKind::Action,
            name,
            package: "test_msgs",
            type_name: "Fibonacci",
            servers: &[],
            clients: &[],
        }));
        let mut server_node = node("action_client_server", &domain);
        let resolver = server_node.resolver().clone();
        let server: ActionServer<Order, Order, Order> = ActionServer::new(
            server_node.node_mut(),
            &resolver,
            name,
            "test_msgs",
            "Fibonacci",
        )
        .unwrap();
        let mut client_node = node("action_client_client", &domain);
        let client: ActionClient<Order, Order, Order> =
            ActionClient::new(&mut client_node, "action_client_server", callable).unwrap();
        assert_eq!(client.name(), format!("/{name}"));

        // the server: a negative order is rejected, 0 runs until canceled, any other
        // succeeds at once with twice the order
        let serve = async {
            loop {
                match server.next().await {
                    ActionRequest::Goal { ticket, id, goal } => {
                        if goal.order < 0 {
                            server.reject(ticket);
                        } else {
                            server.accept(ticket);
                            if goal.order > 0 {
                                let result = Order {
                                    order: goal.order * 2,
                                };
                                server.finish(id, GoalEnd::Succeeded, result);
                            }
                        }
                    }
                    ActionRequest::Cancel(ids) => {
                        for id in ids {
                            server.finish(id, GoalEnd::Canceled, Order { order: -1 });
                        }
                    }
                    ActionRequest::Unreadable(e) => panic!("{e}"),
                }
            }
        };
        let t = Duration::from_secs(20);
        let asks = async {
            client.wait(&client_node, t).await.unwrap();
            let id = client.send_goal(Order { order: 21 }, t).await.unwrap();
            let id = id.expect("accepted");
            let (end, result) = client.result(id).await.unwrap();
            assert_eq!((end, result.order), (GoalEnd::Succeeded, 42));

            assert_eq!(
                client.send_goal(Order { order: -1 }, t).await.unwrap(),
                None
            );

            let id = client.send_goal(Order { order: 0 }, t).await.unwrap();
            let id = id.expect("accepted");
            assert!(client.cancel(id, t).await.unwrap());
            let (end, result) = client.result(id).await.unwrap();
            assert_eq!((end, result.order), (GoalEnd::Canceled, -1));
        };
        tokio::select! {
            _ = serve => unreachable!(),
            _ = asks => {}
        }
    }
}
