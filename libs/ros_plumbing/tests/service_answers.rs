//! A service answer waits for its client's response reader to match, and goes once it
//! has, while the server's next request is awaited.
//!
//! compute_ik awaits its servers' next requests all the time: the `next()` that will
//! return the following request is already pending when the request before it is
//! answered. An answer that had to wait was only looked at again when `next()` came
//! round, at the following request: a `ros2 control` client whose response reader was
//! matched a moment after its request (the node's match map is kept by the spinner, a
//! task of its own) got no answer in rcl's 10 s, and then two answers when it asked
//! again (issue 33). Staged with a raw RustDDS client whose request names a reader
//! that does not exist yet, created only after the answer was given.

mod common;

use std::time::{Duration, Instant};

use common::RawClient;
use ros2_client::{Context, Message, NodeName, NodeOptions};
use ros_plumbing::names::Resolver;
use ros_plumbing::service::ServiceServer;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct Sum {
    a: i64,
    b: i64,
}
impl Message for Sum {}

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct Total {
    sum: i64,
}
impl Message for Total {}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_answer_goes_once_the_reader_matched_while_the_next_request_is_awaited() {
    let mut node = Context::new()
        .unwrap()
        .new_node(
            NodeName::new("/", "service_answer_waits").unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    let spinner = node.spinner().unwrap();
    tokio::spawn(spinner.spin());
    let resolver = Resolver::new("/", "service_answer_waits", "service_answer_waits", &[]).unwrap();
    let server: ServiceServer<Sum, Total> = ServiceServer::new(
        &mut node,
        &resolver,
        "service_answer_waits",
        "example_interfaces",
        "AddTwoInts",
    )
    .unwrap();
    let mut client: RawClient<Sum, Total> = RawClient::new(
        (
            "rq/service_answer_waitsRequest",
            "example_interfaces::srv::dds_::AddTwoInts_Request_",
        ),
        (
            "rr/service_answer_waitsReply",
            "example_interfaces::srv::dds_::AddTwoInts_Response_",
        ),
    )
    .await;

    client.ask(Sum { a: 2, b: 3 });
    let (ticket, _, request) = tokio::time::timeout(Duration::from_secs(10), server.next())
        .await
        .expect("no request in 10 s")
        .unwrap();
    // as in compute_ik's loop: the next request is awaited when this one is answered
    let mut next = Box::pin(server.next());
    assert!(futures::poll!(&mut next).is_pending(), "no other request");
    server.answer(
        ticket,
        Total {
            sum: request.a + request.b,
        },
    );
    // the server runs on for a while before the client's reader exists
    tokio::select! {
        r = &mut next => panic!("no other request was made: {r:?}"),
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
            r = &mut next => panic!("no other request was made: {r:?}"),
            _ = tokio::time::sleep(Duration::from_millis(10)) => {}
        }
    };
    assert_eq!(answer.sum, 5);
}
