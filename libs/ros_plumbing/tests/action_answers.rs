//! An action server's answer waits for its client's response reader to match.
//!
//! A client (rmw_fastrtps', ros2-client's Enhanced one) names its response reader in
//! each request, and asks as soon as *its* side has matched the server. When the
//! request comes before the SEDP announcement of that reader (lost and repaired, or
//! late under load), an answer written at once goes to nobody: both ends are
//! VOLATILE. Staged here with a raw RustDDS client whose request names a reader that
//! does not exist yet (the next GUID its participant hands out), created only after
//! the goal was accepted. Without the wait in `ActionServer`, no answer comes. The
//! server's next request is awaited all along, as compute_ik's loop does: the waiting
//! answer goes from that pending `next()` (tests/service_answers.rs says why).

mod common;

use std::time::{Duration, Instant};

use common::RawClient;
use ros2_client::action::{GoalId, SendGoalRequest, SendGoalResponse};
use ros2_client::{Context, Message, NodeName, NodeOptions};
use ros_plumbing::action::{ActionRequest, ActionServer};
use ros_plumbing::names::Resolver;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct Order {
    order: i32,
}
impl Message for Order {}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_goal_answer_waits_for_the_clients_response_reader() {
    let mut node = Context::new()
        .unwrap()
        .new_node(
            NodeName::new("/", "action_answer_waits").unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    let spinner = node.spinner().unwrap();
    tokio::spawn(spinner.spin());
    let resolver = Resolver::new("/", "action_answer_waits", "action_answer_waits", &[]).unwrap();
    let server: ActionServer<Order, Order, Order> = ActionServer::new(
        &mut node,
        &resolver,
        "answer_waits",
        "test_msgs",
        "Fibonacci",
    )
    .unwrap();
    let mut client: RawClient<SendGoalRequest<Order>, SendGoalResponse> = RawClient::new(
        (
            "rq/answer_waits/_action/send_goalRequest",
            "test_msgs::action::dds_::Fibonacci_SendGoal_Request_",
        ),
        (
            "rr/answer_waits/_action/send_goalReply",
            "test_msgs::action::dds_::Fibonacci_SendGoal_Response_",
        ),
    )
    .await;

    let goal_id = GoalId::new_random();
    client.ask(SendGoalRequest {
        goal_id,
        goal: Order { order: 5 },
    });
    let ticket = match tokio::time::timeout(Duration::from_secs(10), server.next()).await {
        Ok(ActionRequest::Goal { ticket, id, goal }) => {
            assert_eq!(goal.order, 5);
            assert_eq!(id.as_bytes(), goal_id.uuid.as_bytes());
            ticket
        }
        other => panic!(
            "expected the goal, got {:?}",
            other.map(|_| "another request")
        ),
    };
    // as in compute_ik's loop: the next request is awaited when the goal is accepted
    let mut next = Box::pin(server.next());
    assert!(futures::poll!(&mut next).is_pending(), "no other request");
    server.accept(ticket);
    // the server runs on for a while before the client's reader exists
    tokio::select! {
        _ = &mut next => panic!("no other request was made"),
        _ = tokio::time::sleep(Duration::from_millis(300)) => {}
    }

    let mut reader = client.reader();
    // less than the server's 10 s after which an answer goes unmatched
    let deadline = Instant::now() + Duration::from_secs(8);
    let answer = loop {
        if let Some(sample) = reader.take_next_sample().unwrap() {
            break sample.into_value();
        }
        assert!(Instant::now() < deadline, "no answer in 8 s");
        tokio::select! {
            _ = &mut next => panic!("no other request was made"),
            _ = tokio::time::sleep(Duration::from_millis(10)) => {}
        }
    };
    assert!(answer.accepted, "{answer:?}");
}
