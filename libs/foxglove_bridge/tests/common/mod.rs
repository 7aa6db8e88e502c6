//! What the WebSocket test files share: a bridge on a free loopback port, and a Foxglove
//! client written here from the protocol's specification (JSON text messages, binary
//! messageData), not the SDK's.
#![allow(dead_code)] // each test file uses some of it

use foxglove_bridge::{
    ClientPublish, ClientSample, FoxgloveBridge, FrontLimits, Gate, TopicNames, TOPICS,
};
use futures::{SinkExt, StreamExt};
use serde_json::{json, Value};
use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

pub type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;
/// How long a test waits for what must come (it only bounds a failure: cargo runs the
/// test binaries beside each other on a busy host, in debug builds).
pub const WAIT: Duration = Duration::from_secs(30);
/// The subprotocol a Foxglove client asks for (and the server must echo).
const SUBPROTOCOL: &str = "foxglove.sdk.v1";

/// A bridge on a free loopback port, named `test`, behind `gate` and `limits`.
pub async fn start_with(
    names: &TopicNames,
    publish: ClientPublish,
    gate: Gate,
    limits: FrontLimits,
) -> FoxgloveBridge {
    FoxgloveBridge::start_with("127.0.0.1:0", names, publish, "test", gate, limits)
        .await
        .unwrap()
}

/// A bridge on a free loopback port with `names`, the default gate and limits.
pub async fn start_in(names: &TopicNames, publish: ClientPublish) -> FoxgloveBridge {
    start_with(
        names,
        publish,
        foxglove_bridge::front::programs_only(),
        FrontLimits::default(),
    )
    .await
}

/// A bridge on a free loopback port with the default topic names, gate and limits.
pub async fn start(publish: ClientPublish) -> FoxgloveBridge {
    start_in(&TopicNames::default(), publish).await
}

/// The WebSocket handshake to `url` with the Foxglove subprotocol (and `origin`, if
/// any): the client, or the refusal's HTTP status (`403 Forbidden`) or the error.
pub async fn handshake(url: &str, origin: Option<&str>) -> Result<Ws, String> {
    let mut request = url.into_client_request().unwrap();
    let h = request.headers_mut();
    h.insert("Sec-WebSocket-Protocol", SUBPROTOCOL.parse().unwrap());
    if let Some(o) = origin {
        h.insert("Origin", o.parse().unwrap());
    }
    let config = WebSocketConfig::default()
        .max_message_size(None)
        .max_frame_size(None);
    match tokio_tungstenite::connect_async_with_config(request, Some(config), false).await {
        Ok((ws, response)) => {
            assert_eq!(response.headers()["sec-websocket-protocol"], SUBPROTOCOL);
            Ok(ws)
        }
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => Err(r.status().to_string()),
        Err(e) => Err(e.to_string()),
    }
}

/// [`handshake`] with the server at `addr`.
pub async fn try_connect(addr: SocketAddr, origin: Option<&str>) -> Result<Ws, String> {
    handshake(&format!("ws://{addr}"), origin).await
}

/// A client of the server at `addr` (a program: no `Origin`).
pub async fn connect(addr: SocketAddr) -> Ws {
    try_connect(addr, None).await.unwrap()
}

pub enum Received {
    Json(Value),
    Binary(Vec<u8>),
}

/// The next text or binary message, if one comes before `end`.
async fn next_until(ws: &mut Ws, end: Instant) -> Option<Received> {
    loop {
        let left = end.checked_duration_since(Instant::now())?;
        match tokio::time::timeout(left, ws.next()).await {
            Ok(Some(Ok(Message::Text(t)))) => {
                return Some(Received::Json(serde_json::from_str(&t).unwrap()))
            }
            Ok(Some(Ok(Message::Binary(b)))) => return Some(Received::Binary(b.to_vec())),
            Ok(Some(Ok(_))) => continue,
            _ => return None,
        }
    }
}

/// The next JSON message whose `op` is `op`.
pub async fn next_json(ws: &mut Ws, op: &str) -> Value {
    let end = Instant::now() + WAIT;
    loop {
        match next_until(ws, end).await {
            Some(Received::Json(v)) if v["op"] == op => return v,
            Some(_) => continue,
            None => panic!("no {op} from the server in time"),
        }
    }
}

/// The next binary messageData (opcode 1) within `within`, whole, if any.
pub async fn message_data(ws: &mut Ws, within: Duration) -> Option<Vec<u8>> {
    let end = Instant::now() + within;
    loop {
        match next_until(ws, end).await? {
            Received::Binary(b) if b[0] == 1 => return Some(b),
            _ => continue,
        }
    }
}

/// (subscription id, log time, payload) of the next messageData.
pub async fn next_message_data(ws: &mut Ws) -> (u32, u64, Vec<u8>) {
    let b = message_data(ws, WAIT)
        .await
        .expect("no messageData from the server in time");
    let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
    let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
    (sub, t, b[13..].to_vec())
}

/// Every advertised channel by topic.
pub async fn channels(ws: &mut Ws) -> HashMap<String, Value> {
    let mut by_topic = HashMap::new();
    while by_topic.len() < TOPICS.len() {
        let adv = next_json(ws, "advertise").await;
        for c in adv["channels"].as_array().unwrap() {
            by_topic.insert(c["topic"].as_str().unwrap().to_string(), c.clone());
        }
    }
    by_topic
}

/// The next sample a client published to the node (within [`WAIT`]).
pub async fn next_sample(samples: &mut mpsc::Receiver<ClientSample>) -> ClientSample {
    tokio::time::timeout(WAIT, samples.recv())
        .await
        .unwrap()
        .unwrap()
}

/// No (further) client sample has reached the node; `what` names the one that would have.
pub fn assert_no_sample(samples: &mut mpsc::Receiver<ClientSample>, what: &str) {
    assert!(samples.try_recv().is_err(), "{what} reached the node");
}

/// Every advertised channel's id by topic.
pub async fn channel_ids(ws: &mut Ws) -> HashMap<String, u64> {
    let channels = channels(ws).await;
    channels
        .into_iter()
        .map(|(topic, c)| (topic, c["id"].as_u64().unwrap()))
        .collect()
}

/// Subscribe to `channel` as subscription `sub`.
pub fn subscribe(sub: u32, channel: u64) -> Message {
    Message::text(
        json!({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": channel}]})
            .to_string(),
    )
}

/// A client's advertisement of CDR channels: (id, topic, schema name).
pub fn advertise(channels: &[(u32, &str, &str)]) -> Message {
    let channels: Vec<Value> = channels
        .iter()
        .map(|(id, topic, schema)| {
            json!({"id": id, "topic": topic, "encoding": "cdr", "schemaName": schema})
        })
        .collect();
    Message::text(json!({"op": "advertise", "channels": channels}).to_string())
}

/// A client's message (opcode 1) on its advertised `channel`.
pub fn client_message(channel: u32, cdr: &[u8]) -> Message {
    let mut frame = vec![1u8];
    frame.extend_from_slice(&channel.to_le_bytes());
    frame.extend_from_slice(cdr);
    Message::binary(frame)
}

/// The server info's capabilities include `capability`.
pub fn offers(info: &Value, capability: &str) -> bool {
    info["capabilities"]
        .as_array()
        .unwrap()
        .contains(&json!(capability))
}

/// A channel no server advertises, and the subscription that asks for it.
const NO_CHANNEL: u64 = 999_999;
const NO_CHANNEL_SUB: u32 = 999_999;

/// One round trip: a subscription to a channel that does not exist, which the server
/// answers at once with an error status; returns what the client received before that
/// answer. The server handles a client's messages one after the other, so everything the
/// client sent before has been handled (a sample taken, a subscription registered) when
/// the answer comes.
pub async fn round_trip(ws: &mut Ws) -> Vec<Received> {
    ws.send(subscribe(NO_CHANNEL_SUB, NO_CHANNEL))
        .await
        .unwrap();
    let answer = format!("Unknown channel ID: {NO_CHANNEL}");
    let end = Instant::now() + WAIT;
    let mut before = Vec::new();
    loop {
        match next_until(ws, end).await {
            Some(Received::Json(v))
                if v["op"] == "status" && v["message"].as_str() == Some(answer.as_str()) =>
            {
                return before
            }
            Some(r) => before.push(r),
            None => panic!("no answer to the round trip in time"),
        }
    }
}

/// Whether any of `received` is a messageData.
pub fn has_message_data(received: &[Received]) -> bool {
    received
        .iter()
        .any(|r| matches!(r, Received::Binary(b) if b.first() == Some(&1)))
}
