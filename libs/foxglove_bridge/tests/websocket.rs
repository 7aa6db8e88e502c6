//! The Foxglove WebSocket server as a Foxglove client sees it (the client of
//! `common`, written from the protocol's specification, not the SDK's).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use common::{
    advertise, assert_no_sample, channel_ids, channels, client_message, connect, next_json,
    next_message_data, next_sample, offers, round_trip, start, start_in, subscribe, WAIT,
};
use eezybot_msgs::geometry_msgs::{Point, PointStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::{Header, String as RosString};
use foxglove_bridge::{ros2msg_schema, ClientPublish, TopicNames, TOPICS};
use futures::SinkExt;
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;

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
    let bridge = start_in(&names, ClientPublish::Off).await;
    // latched before anyone connects
    let urdf = eezybot_msgs::cdr::encode(&RosString {
        data: "<robot name='eezybot'/>".into(),
    })
    .unwrap();
    bridge.log("robot_description", &urdf, 1_000).unwrap();

    let mut watched = bridge.watched();
    let mut ws = connect(bridge.local_addr()).await;
    let info = next_json(&mut ws, "serverInfo").await;
    assert_eq!(info["name"], "test");
    assert!(!offers(&info, "clientPublish"));
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

    // the subscription is registered (its client's sink among joint_states' own) before
    // the watched set has the topic: stream once it has
    tokio::time::timeout(WAIT, watched.wait_for(|w| w.contains("joint_states")))
        .await
        .expect("joint_states not watched in time")
        .unwrap();
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
    let mut bridge = start(ClientPublish::Targets { queue: 8 }).await;
    let mut samples = bridge.take_client_samples().unwrap();
    let mut ws = connect(bridge.local_addr()).await;
    let info = next_json(&mut ws, "serverInfo").await;
    assert!(offers(&info, "clientPublish"));
    assert_eq!(info["supportedEncodings"], json!(["cdr"]));

    ws.send(advertise(&[
        (1, "/xyz_target", "geometry_msgs/msg/PointStamped"),
        (2, "/cmd_vel", "geometry_msgs/msg/Twist"),
    ]))
    .await
    .unwrap();
    let status = next_json(&mut ws, "status").await;
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
        ws.send(client_message(channel, &cdr)).await.unwrap();
    }
    let sample = next_sample(&mut samples).await;
    assert_eq!(sample.topic, "xyz_target");
    let m: PointStamped = eezybot_msgs::cdr::decode(&sample.cdr).unwrap();
    assert_eq!(m, target);
    assert_no_sample(&mut samples, "the /cmd_vel sample");
    bridge.stop().await;
}

#[tokio::test]
async fn the_watched_topics_follow_the_clients_subscriptions() {
    let bridge = start(ClientPublish::Off).await;
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
    let ids = channel_ids(&mut a).await;
    let subscribe = |sub: u32, topic: &str| subscribe(sub, ids[topic]);
    a.send(subscribe(1, "/joint_states")).await.unwrap();
    a.send(subscribe(2, "/tf")).await.unwrap();
    wait_for(&mut watched, vec!["joint_states", "tf"]).await;
    // a second client on the same topic (registered once a later request of b's is
    // answered): still watched after the first lets go, and b still gets its samples
    channels(&mut b).await;
    b.send(subscribe(9, "/joint_states")).await.unwrap();
    round_trip(&mut b).await;
    a.send(Message::text(
        json!({"op": "unsubscribe", "subscriptionIds": [1, 2]}).to_string(),
    ))
    .await
    .unwrap();
    wait_for(&mut watched, vec!["joint_states"]).await;
    let cdr = eezybot_msgs::cdr::encode(&joint_state(1.0)).unwrap();
    bridge.log("joint_states", &cdr, 7).unwrap();
    assert_eq!(next_message_data(&mut b).await, (9, 7, cdr));
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
