//! The front of the Foxglove server (issue 18 item 7): what an attacker's client gets.
//! Each test is a probe that got through before the front existed.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use eezybot_msgs::geometry_msgs::PointStamped;
use eezybot_msgs::std_msgs::String as RosString;
use foxglove_bridge::{
    Admitted, ClientPublish, FoxgloveBridge, FrontLimits, Gate, Refused, TopicNames,
};
use futures::{SinkExt, StreamExt};
use serde_json::{json, Value};
use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;
const WAIT: Duration = Duration::from_secs(5);

async fn try_connect(addr: SocketAddr, origin: Option<&str>) -> Result<Ws, String> {
    let mut request = format!("ws://{addr}").into_client_request().unwrap();
    let h = request.headers_mut();
    h.insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    if let Some(o) = origin {
        h.insert("Origin", o.parse().unwrap());
    }
    let config = WebSocketConfig::default()
        .max_message_size(None)
        .max_frame_size(None);
    match tokio_tungstenite::connect_async_with_config(request, Some(config), false).await {
        Ok((ws, _)) => Ok(ws),
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => Err(r.status().to_string()),
        Err(e) => Err(e.to_string()),
    }
}

async fn next_json(ws: &mut Ws, op: &str) -> Value {
    loop {
        let m = tokio::time::timeout(WAIT, ws.next())
            .await
            .unwrap()
            .unwrap()
            .unwrap();
        if let Message::Text(t) = m {
            let v: Value = serde_json::from_str(&t).unwrap();
            if v["op"] == op {
                return v;
            }
        }
    }
}

/// Every advertised channel: topic → id.
async fn channel_ids(ws: &mut Ws) -> std::collections::HashMap<String, u64> {
    let mut ids = std::collections::HashMap::new();
    while ids.len() < foxglove_bridge::TOPICS.len() {
        let adv = next_json(ws, "advertise").await;
        for c in adv["channels"].as_array().unwrap() {
            ids.insert(
                c["topic"].as_str().unwrap().to_string(),
                c["id"].as_u64().unwrap(),
            );
        }
    }
    ids
}

async fn subscribe(ws: &mut Ws, id: u64) {
    let op = json!({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": id}]});
    ws.send(Message::text(op.to_string())).await.unwrap();
}

/// A binary messageData within `within`, if any.
async fn message_data(ws: &mut Ws, within: Duration) -> Option<Vec<u8>> {
    let end = Instant::now() + within;
    loop {
        let left = end.checked_duration_since(Instant::now())?;
        match tokio::time::timeout(left, ws.next()).await {
            Ok(Some(Ok(Message::Binary(b)))) if b[0] == 1 => return Some(b.to_vec()),
            Ok(Some(Ok(_))) => continue,
            _ => return None,
        }
    }
}

fn urdf() -> Vec<u8> {
    eezybot_msgs::cdr::encode(&RosString {
        data: "<robot name='secret'/>".into(),
    })
    .unwrap()
}

fn target() -> Vec<u8> {
    let mut frame = vec![1u8];
    frame.extend_from_slice(&1u32.to_le_bytes());
    frame.extend_from_slice(&eezybot_msgs::cdr::encode(&PointStamped::default()).unwrap());
    frame
}

fn advertise_xyz() -> Message {
    Message::text(
        json!({"op": "advertise", "channels": [{"id": 1, "topic": "/xyz_target",
            "encoding": "cdr", "schemaName": "geometry_msgs/msg/PointStamped"}]})
        .to_string(),
    )
}

#[tokio::test]
async fn a_web_page_s_origin_is_refused_with_403() {
    let bridge = FoxgloveBridge::start(
        "127.0.0.1:0",
        &TopicNames::default(),
        ClientPublish::Off,
        "t",
    )
    .await
    .unwrap();
    let r = try_connect(bridge.local_addr(), Some("http://evil.example")).await;
    assert_eq!(r.err().as_deref(), Some("403 Forbidden"));
    assert!(
        try_connect(bridge.local_addr(), None).await.is_ok(),
        "a program passes"
    );
    assert_eq!(bridge.front_stats().refused.load(Ordering::Relaxed), 1);
}

#[tokio::test]
async fn the_gate_decides_who_connects_and_who_publishes() {
    // a gate as gui_bridge's: a token in the URL, and only then publishing
    let gate: Gate = Arc::new(|req: &foxglove_bridge::UpgradeRequest| match req.query() {
        Some("token=good") => Ok(Admitted { may_publish: true }),
        Some("token=watch") => Ok(Admitted { may_publish: false }),
        _ => Err(Refused {
            status: 401,
            reason: "needs the token".into(),
        }),
    });
    let mut bridge = FoxgloveBridge::start_with(
        "127.0.0.1:0",
        &TopicNames::default(),
        ClientPublish::Targets { queue: 8 },
        "t",
        gate,
        FrontLimits::default(),
    )
    .await
    .unwrap();
    let mut samples = bridge.take_client_samples().unwrap();
    let addr = bridge.local_addr();
    let connect = |q: &'static str| async move {
        let mut request = format!("ws://{addr}/{q}").into_client_request().unwrap();
        request
            .headers_mut()
            .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
        tokio_tungstenite::connect_async(request).await
    };
    match connect("").await {
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => assert_eq!(r.status(), 401),
        other => panic!("admitted without a token: {:?}", other.map(|_| ())),
    }
    // a watcher: no clientPublish offered, and its samples go nowhere
    let (mut watcher, _) = connect("?token=watch").await.unwrap();
    let info = next_json(&mut watcher, "serverInfo").await;
    assert!(
        !info["capabilities"]
            .as_array()
            .unwrap()
            .contains(&json!("clientPublish")),
        "{info}"
    );
    watcher.send(advertise_xyz()).await.unwrap();
    watcher.send(Message::binary(target())).await.unwrap();
    let status = next_json(&mut watcher, "status").await;
    assert!(
        status["message"]
            .as_str()
            .unwrap()
            .contains("does not take samples"),
        "{status}"
    );
    // the publisher's sample arrives, and it is the only one
    let (mut publisher, _) = connect("?token=good").await.unwrap();
    let info = next_json(&mut publisher, "serverInfo").await;
    assert!(info["capabilities"]
        .as_array()
        .unwrap()
        .contains(&json!("clientPublish")));
    publisher.send(advertise_xyz()).await.unwrap();
    publisher.send(Message::binary(target())).await.unwrap();
    let s = tokio::time::timeout(WAIT, samples.recv())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(s.topic, "xyz_target");
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert!(
        samples.try_recv().is_err(),
        "the watcher's sample reached the node"
    );
    bridge.stop().await;
}

#[tokio::test]
async fn a_connection_to_the_sdk_s_own_port_gets_no_data_and_cannot_publish() {
    let mut bridge = FoxgloveBridge::start(
        "127.0.0.1:0",
        &TopicNames::default(),
        ClientPublish::Targets { queue: 8 },
        "t",
    )
    .await
    .unwrap();
    bridge.log("robot_description", &urdf(), 1).unwrap();
    let mut samples = bridge.take_client_samples().unwrap();
    // a page that found the SDK's port by trying ports: its Origin is not checked there
    let mut sneak = try_connect(bridge.sdk_addr(), Some("http://evil.example"))
        .await
        .unwrap();
    let ids = channel_ids(&mut sneak).await;
    subscribe(&mut sneak, ids["/robot_description"]).await;
    sneak.send(advertise_xyz()).await.unwrap();
    sneak.send(Message::binary(target())).await.unwrap();
    // the same through the front gets the latched URDF at once
    let mut front = try_connect(bridge.local_addr(), None).await.unwrap();
    let ids = channel_ids(&mut front).await;
    subscribe(&mut front, ids["/robot_description"]).await;
    assert!(
        message_data(&mut front, WAIT).await.is_some(),
        "the front's client got nothing"
    );
    bridge.log("robot_description", &urdf(), 2).unwrap();
    assert_eq!(
        message_data(&mut sneak, Duration::from_millis(500)).await,
        None,
        "data leaked"
    );
    assert!(
        samples.try_recv().is_err(),
        "a sample from the SDK's port reached the node"
    );
    bridge.stop().await;
}

#[tokio::test]
async fn connections_over_the_cap_are_refused_with_503() {
    let limits = FrontLimits {
        max_clients: 4,
        ..FrontLimits::default()
    };
    let bridge = FoxgloveBridge::start_with(
        "127.0.0.1:0",
        &TopicNames::default(),
        ClientPublish::Off,
        "t",
        foxglove_bridge::front::programs_only(),
        limits,
    )
    .await
    .unwrap();
    let mut open = Vec::new();
    let mut refused = 0;
    for _ in 0..20 {
        match try_connect(bridge.local_addr(), None).await {
            Ok(ws) => open.push(ws),
            Err(e) => {
                assert_eq!(e, "503 Service Unavailable");
                refused += 1;
            }
        }
    }
    assert_eq!((open.len(), refused), (4, 16));
    // a slot frees when a client goes
    drop(open.pop());
    let deadline = Instant::now() + WAIT;
    while try_connect(bridge.local_addr(), None).await.is_err() {
        assert!(Instant::now() < deadline, "the slot was not freed");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test]
async fn a_10_mib_message_closes_the_client_with_1009_before_it_is_read() {
    let bridge = FoxgloveBridge::start(
        "127.0.0.1:0",
        &TopicNames::default(),
        ClientPublish::Off,
        "t",
    )
    .await
    .unwrap();
    let mut ws = try_connect(bridge.local_addr(), None).await.unwrap();
    next_json(&mut ws, "serverInfo").await;
    let _ = ws.send(Message::binary(vec![0u8; 10 * 1024 * 1024])).await;
    let mut code = None;
    let end = Instant::now() + WAIT;
    while let Ok(Some(m)) = tokio::time::timeout_at(end.into(), ws.next()).await {
        match m {
            Ok(Message::Close(Some(f))) => {
                code = Some(u16::from(f.code));
                break;
            }
            Ok(_) => continue,
            Err(_) => break,
        }
    }
    assert_eq!(
        bridge
            .front_stats()
            .closed_oversized
            .load(Ordering::Relaxed),
        1
    );
    // the close frame may be lost to a reset of the unread rest; when it comes it is 1009
    assert!(matches!(code, None | Some(1009)), "{code:?}");
    // and the server serves the next client
    assert!(try_connect(bridge.local_addr(), None).await.is_ok());
}

#[tokio::test]
async fn a_half_open_connection_is_answered_408_when_its_head_times_out() {
    let limits = FrontLimits {
        header_timeout: Duration::from_millis(300),
        ..FrontLimits::default()
    };
    let bridge = FoxgloveBridge::start_with(
        "127.0.0.1:0",
        &TopicNames::default(),
        ClientPublish::Off,
        "t",
        foxglove_bridge::front::programs_only(),
        limits,
    )
    .await
    .unwrap();
    let mut s = TcpStream::connect(bridge.local_addr()).await.unwrap();
    s.write_all(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        .await
        .unwrap();
    let mut answer = String::new();
    // the behaviour is a timeout: answered within a generous bound of it
    tokio::time::timeout(WAIT, s.read_to_string(&mut answer))
        .await
        .unwrap()
        .unwrap();
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    assert_eq!(
        bridge.front_stats().header_timeouts.load(Ordering::Relaxed),
        1
    );
}

#[tokio::test]
async fn the_sdk_s_own_refusal_reaches_the_client_whole() {
    let bridge = FoxgloveBridge::start(
        "127.0.0.1:0",
        &TopicNames::default(),
        ClientPublish::Off,
        "t",
    )
    .await
    .unwrap();
    // no subprotocol: the SDK answers 400 with its reason
    let mut s = TcpStream::connect(bridge.local_addr()).await.unwrap();
    s.write_all(
        b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
          Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
    )
    .await
    .unwrap();
    let mut answer = String::new();
    tokio::time::timeout(WAIT, s.read_to_string(&mut answer))
        .await
        .unwrap()
        .unwrap();
    assert!(answer.starts_with("HTTP/1.1 400"), "{answer}");
    assert!(answer.contains("sec-websocket-protocol"), "{answer}");
}
