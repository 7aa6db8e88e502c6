//! An action server's answer waits for its client's response reader to match.
//!
//! A client (rmw_fastrtps', ros2-client's Enhanced one) names its response reader in
//! each request, and asks as soon as *its* side has matched the server. When the
//! request comes before the SEDP announcement of that reader (lost and repaired, or
//! late under load), an answer written at once goes to nobody: both ends are
//! VOLATILE. Staged here with a raw RustDDS client whose request names a reader that
//! does not exist yet (the next GUID its participant hands out), created only after
//! the goal was accepted. Without the wait in `ActionServer`, no answer comes.

use std::time::{Duration, Instant};

use ros2_client::action::{GoalId, SendGoalRequest, SendGoalResponse};
use ros2_client::{Context, Message, NodeName, NodeOptions};
use ros_plumbing::action::{ActionRequest, ActionServer};
use ros_plumbing::names::Resolver;
use rustdds::policy::{Durability, History, Reliability};
use rustdds::{
    DomainParticipantStatusEvent, QosPolicyBuilder, RTPSEntity, SampleIdentity, SequenceNumber,
    StatusEvented, TopicKind, WriteOptionsBuilder, GUID,
};
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

    let client = Context::new().unwrap();
    let dp = client.domain_participant();
    let events = dp.status_listener();
    let qos = QosPolicyBuilder::new()
        .reliability(Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(100),
        })
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
        .build();
    let topic = |name: &str, ty: &str| {
        dp.create_topic(name.to_string(), ty.to_string(), &qos, TopicKind::NoKey)
            .unwrap()
    };
    let requests = topic(
        "rq/answer_waits/_action/send_goalRequest",
        "test_msgs::action::dds_::Fibonacci_SendGoal_Request_",
    );
    let replies = topic(
        "rr/answer_waits/_action/send_goalReply",
        "test_msgs::action::dds_::Fibonacci_SendGoal_Response_",
    );
    let writer = dp
        .create_publisher(&qos)
        .unwrap()
        .create_datawriter_no_key_cdr::<SendGoalRequest<Order>>(&requests, None)
        .unwrap();
    let subscriber = dp.create_subscriber(&qos).unwrap();
    // entity ids are handed out in order: the reader created next gets the next key
    // (bytes 12..15 of the GUID), kind 0x04 (a user-defined reader, no key)
    let mut bytes = writer.guid().to_bytes();
    let next = u32::from_be_bytes([0, bytes[12], bytes[13], bytes[14]]) + 1;
    bytes[12..15].copy_from_slice(&next.to_be_bytes()[1..]);
    bytes[15] = 0x04;
    let reader_guid = GUID::from_bytes(bytes);

    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match events.try_recv_status() {
            Some(DomainParticipantStatusEvent::RemoteReaderMatched { local_writer, .. })
                if local_writer == writer.guid() =>
            {
                break
            }
            Some(_) => {}
            None => {
                assert!(
                    Instant::now() < deadline,
                    "the server's goal service did not match"
                );
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
        }
    }
    let options = WriteOptionsBuilder::new()
        .related_sample_identity(SampleIdentity {
            writer_guid: reader_guid,
            sequence_number: SequenceNumber::from(1),
        })
        .build();
    let goal_id = GoalId::new_random();
    let goal = SendGoalRequest {
        goal_id,
        goal: Order { order: 5 },
    };
    writer.write_with_options(goal, options).unwrap();

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
    server.accept(ticket);
    // the server runs on for a while before the client's reader exists
    let _ = tokio::time::timeout(Duration::from_millis(300), server.next()).await;

    let mut reader = subscriber
        .create_datareader_no_key_cdr::<SendGoalResponse>(&replies, None)
        .unwrap();
    assert_eq!(
        reader.guid(),
        reader_guid,
        "the reader got the GUID the request named"
    );
    let deadline = Instant::now() + Duration::from_secs(10);
    let answer = loop {
        if let Some(sample) = reader.take_next_sample().unwrap() {
            break sample.into_value();
        }
        assert!(Instant::now() < deadline, "no answer in 10 s");
        let _ = tokio::time::timeout(Duration::from_millis(10), server.next()).await;
    };
    assert!(answer.accepted, "{answer:?}");
}
