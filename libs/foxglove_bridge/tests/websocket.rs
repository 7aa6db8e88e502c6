//! The Foxglove WebSocket server as a Foxglove client sees it: a client written here from
//! the protocol's specification (JSON text messages, binary messageData), not the SDK's.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use eezybot_msgs::geometry_msgs::{Point, PointStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::{Header, String as RosString};
use foxglove_bridge::{ros2msg_schema, ClientPublish, FoxgloveBridge, TopicNames, TOPICS};
use futures::{SinkExt, StreamExt};
use serde_json::{json, Value};
use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::Duration;
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;
const WAIT: Duration = Duration::from_secs(5);

async fn connect(addr: SocketAddr) -> Ws {
    let mut request = format!("ws://{addr}").into_client_request().unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let (ws, response) = tokio_tungstenite::connect_async(request).await.unwrap();
    assert_eq!(
        response.headers()["sec-websocket-protocol"],
        "foxglove.sdk.v1"
    );
    ws
}

enum Received {
    Json(Value),
    Binary(Vec<u8>),
}

async fn next(ws: &mut Ws) -> Received {
    loop {
        let m = tokio::time::timeout(WAIT, ws.next())
            .await
            .expect("nothing from the server in time")
            .unwrap()
            .unwrap();
        match m {
            Message::Text(t) => return Received::Json(serde_json::from_str(&t).unwrap()),
            Message::Binary(b) => return Received::Binary(b.to_vec()),
            _ => continue,
        }
    }
}

async fn next_json_op(ws: &mut Ws, op: &str) -> Value {
    loop {
        if let Received::Json(v) = next(ws).await {
            if v["op"] == op {
                return v;
            }
        }
    }
}

/// (subscription id, log time, payload) of the next messageData (opcode 1).
async fn next_message_data(ws: &mut Ws) -> (u32, u64, Vec<u8>) {
    loop {
        if let Received::Binary(b) = next(ws).await {
            if b[0] == 1 {
                let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
                return (sub, t, b[13..].to_vec());
            }
        }
    }
}

/// Every advertised channel by topic.
async fn channels(ws: &mut Ws) -> HashMap<String, Value> {
    let mut by_topic = HashMap::new();
    while by_topic.len() < TOPICS.len() {
        let adv = next_json_op(ws, "advertise").await;
        for c in adv["channels"].as_array().unwrap() {
            by_topic.insert(c["topic"].as_str().unwrap().to_string(), c.clone());
        }
    }
    by_topic
}

fn joint_state(position: f64) -> JointState {
    JointState {
        header: Header {
            frame_id: String::new(),
            ..Default::default()
        },
        name: vec!["base_joint".into()],
        position: vec![position],
        ..Default::default()
    }
}

#[tokio::test]
async fn a_client_sees_every_topic_with_its_ros2msg_schema_and_gets_raw_cdr() {
    let names = TopicNames::in_namespace("/arm2");
    let bridge = FoxgloveBridge::start("127.0.0.1:0", &names, ClientPublish::Off, "test")
        .await
        .unwrap();
    // latched before anyone connects
    let urdf = eezybot_msgs::cdr::encode(&RosString {
        data: "<robot name='eezybot'/>".into(),
    })
    .unwrap();
    bridge.log("robot_description", &urdf, 1_000).unwrap();

    let mut ws = connect(bridge.local_addr()).await;
    let info = next_json_op(&mut ws, "serverInfo").await;
    assert_eq!(info["name"], "test");
    assert!(!info["capabilities"]
        .as_array()
        .unwrap()
        .contains(&json!("clientPublish")));
    let channels = channels(&mut ws).await;
    for t in TOPICS {
        let c = &channels[&format!("/arm2/{}", t.topic)];
        assert_eq!(c["encoding"], "cdr", "{}", t.topic);
        assert_eq!(c["schemaName"], t.type_name);
        assert_eq!(c["schemaEncoding"], "ros2msg");
        assert_eq!(c["schema"], ros2msg_schema(t.type_name).unwrap());
    }

    let id = |topic: &str| channels[topic]["id"].as_u64().unwrap();
    ws.send(Message::text(
        json!({"op": "subscribe", "subscriptions": [
            {"id": 7, "channelId": id("/arm2/robot_description")},
            {"id": 8, "channelId": id("/arm2/joint_states")},
        ]})
        .to_string(),
    ))
    .await
    .unwrap();
    // the latched sample arrives on subscribing, as logged
    let (sub, t, payload) = next_message_data(&mut ws).await;
    assert_eq!((sub, t), (7, 1_000));
    assert_eq!(payload, urdf);

    // give the server a moment to register the subscription, then stream
    tokio::time::sleep(Duration::from_millis(100)).await;
    for i in 0..3 {
        let cdr = eezybot_msgs::cdr::encode(&joint_state(f64::from(i))).unwrap();
        bridge.log("joint_states", &cdr, 2_000 + i as u64).unwrap();
        // not subscribed: not sent
        bridge.log("tf", &[0, 1, 0, 0, 0, 0, 0, 0], 5).unwrap();
    }
    for i in 0..3 {
        let (sub, t, payload) = next_message_data(&mut ws).await;
        assert_eq!((sub, t), (8, 2_000 + i as u64));
        let m: JointState = eezybot_msgs::cdr::decode(&payload).unwrap();
        assert_eq!(m, joint_state(f64::from(i)));
    }
    assert!(bridge.log("cmd_vel", &urdf, 0).is_err());
    bridge.stop().await;
}

#[tokio::test]
async fn foxglove_panels_publish_targets_and_nothing_else() {
    let mut bridge = FoxgloveBridge::start(
        "127.0.0.1:0",
        &TopicNames::default(),
        ClientPublish::Targets { queue: 8 },
        "test",
    )
    .await
    .unwrap();
    let mut samples = bridge.take_client_samples().unwrap();
    let mut ws = connect(bridge.local_addr()).await;
    let info = next_json_op(&mut ws, "serverInfo").await;
    assert!(info["capabilities"]
        .as_array()
        .unwrap()
        .contains(&json!("clientPublish")));
    assert_eq!(info["supportedEncodings"], json!(["cdr"]));

    ws.send(Message::text(
        json!({"op": "advertise", "channels": [
            {"id": 1, "topic": "/xyz_target", "encoding": "cdr", "schemaName": "geometry_msgs/msg/PointStamped"},
            {"id": 2, "topic": "/cmd_vel", "encoding": "cdr", "schemaName": "geometry_msgs/msg/Twist"},
        ]})
        .to_string(),
    ))
    .await
    .unwrap();
    let status = next_json_op(&mut ws, "status").await;
    assert!(
        status["message"].as_str().unwrap().contains("/cmd_vel"),
        "{status}"
    );

    let target = PointStamped {
        header: Header {
            frame_id: "base_link".into(),
            ..Default::default()
        },
        point: Point {
            x: 0.1,
            y: 0.0,
            z: 0.15,
        },
    };
    let cdr = eezybot_msgs::cdr::encode(&target).unwrap();
    for channel in [2u32, 1] {
        let mut frame = vec![1u8];
        frame.extend_from_slice(&channel.to_le_bytes());
        frame.extend_from_slice(&cdr);
        ws.send(Message::binary(frame)).await.unwrap();
    }
    let sample = tokio::time::timeout(WAIT, samples.recv())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(sample.topic, "xyz_target");
    let m: PointStamped = eezybot_msgs::cdr::decode(&sample.cdr).unwrap();
    assert_eq!(m, target);
    // /cmd_vel was not delivered
    assert!(samples.try_recv().is_err());
    bridge.stop().await;
}

#[tokio::test]
async fn the_watched_topics_follow_the_clients_subscriptions() {
    let bridge = FoxgloveBridge::start(
        "127.0.0.1:0",
        &TopicNames::default(),
        ClientPublish::Off,
        "test",
    )
    .await
    .unwrap();
    let mut watched = bridge.watched();
    assert!(
        watched.borrow().is_empty(),
        "nothing watched before a client"
    );
    let wait_for = |watched: &mut tokio::sync::watch::Receiver<_>, want: Vec<&'static str>| {
        let mut watched = watched.clone();
        async move {
            tokio::time::timeout(
                WAIT,
                watched.wait_for(|set: &std::collections::BTreeSet<&str>| {
                    set.iter().copied().eq(want.iter().copied())
                }),
            )
            .await
            .expect("the watched set did not change in time")
            .unwrap();
        }
    };

    let mut a = connect(bridge.local_addr()).await;
    let mut b = connect(bridge.local_addr()).await;
    let chans = channels(&mut a).await;
    let id = |topic: &str| chans[topic]["id"].as_u64().unwrap();
    let subscribe = |sub: u32, topic: &str| {
        Message::text(
            json!({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": id(topic)}]})
                .to_string(),
        )
    };
    a.send(subscribe(1, "/joint_states")).await.unwrap();
    a.send(subscribe(2, "/tf")).await.unwrap();
    wait_for(&mut watched, vec!["joint_states", "tf"]).await;
    // a second client on the same topic: still watched after the first lets go
    channels(&mut b).await;
    b.send(subscribe(9, "/joint_states")).await.unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    a.send(Message::text(
        json!({"op": "unsubscribe", "subscriptionIds": [1, 2]}).to_string(),
    ))
    .await
    .unwrap();
    wait_for(&mut watched, vec!["joint_states"]).await;
    // a client that goes away ends its subscriptions
    a.send(subscribe(3, "/tf")).await.unwrap();
    wait_for(&mut watched, vec!["joint_states", "tf"]).await;
    a.close(None).await.unwrap();
    drop(a);
    wait_for(&mut watched, vec!["joint_states"]).await;
    b.close(None).await.unwrap();
    drop(b);
    wait_for(&mut watched, vec![]).await;
    watched.mark_unchanged();
    bridge.stop().await;
}
