//! Who holds one of the panel's client places (issue 36 item 6): on a panel without a
//! token, 32 connections that sent nothing had taken every place and the operator's
//! browser got 503. Each test runs the web server (`web::router`) on a free port of
//! loopback with real WebSocket clients; the bridge loop's end of the channels is the test.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use futures::{SinkExt, StreamExt};
use gui_bridge::access::{AccessPolicy, Token};
use gui_bridge::web::{request_channels, router, ClientRequest, Limits, Requests, WebState};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpStream;
use tokio::sync::broadcast;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// A bound for what must happen, never a pace: only a failure waits it out.
const WAIT: Duration = Duration::from_secs(30);

const TOKEN: &str = "0123456789abcdef0123";

/// The web server with `token` (none: a loopback panel without one); its address and the
/// loop's end of its channels (the events drained, as the loop would).
async fn serve(token: Option<&str>) -> (SocketAddr, Requests) {
    let limits = Limits::default();
    let (senders, mut requests) = request_channels(&limits);
    let state = WebState::new(
        broadcast::channel(16).0,
        senders,
        Arc::new(|| r#"{"t":"hello"}"#.to_string()),
        AccessPolicy::new(token.map(|t| Token::new(t).unwrap())),
        limits,
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let app = router(state).into_make_service_with_connect_info::<SocketAddr>();
    tokio::spawn(async move { axum::serve(listener, app).await });
    let mut events = std::mem::replace(&mut requests.events, tokio::sync::mpsc::channel(1).1);
    tokio::spawn(async move { while events.recv().await.is_some() {} });
    (addr, requests)
}

/// A WebSocket to the panel (the page's subprotocols, `token` if any), once it has its
/// hello; or the HTTP status of the refusal.
async fn connect(addr: SocketAddr, token: Option<&str>) -> Result<Ws, u16> {
    let mut request = format!("ws://{addr}/ws").into_client_request().unwrap();
    let protocols = match token {
        Some(t) => format!("eezybot.panel.v1, token.{t}"),
        None => "eezybot.panel.v1".into(),
    };
    request
        .headers_mut()
        .insert("sec-websocket-protocol", protocols.parse().unwrap());
    match tokio_tungstenite::connect_async(request).await {
        Ok((mut ws, _)) => {
            // the hello comes after the server has seated or queued this client
            let first = tokio::time::timeout(WAIT, ws.next()).await.unwrap();
            assert!(matches!(first, Some(Ok(Message::Text(_)))), "{first:?}");
            Ok(ws)
        }
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => Err(r.status().as_u16()),
        Err(e) => panic!("{e}"),
    }
}

async fn say(ws: &mut Ws, json: &str) {
    ws.send(Message::Text(json.into())).await.unwrap();
}

/// The close frame the server ends `ws` with: its code and reason.
async fn close_frame(ws: &mut Ws) -> (CloseCode, String) {
    loop {
        match tokio::time::timeout(WAIT, ws.next()).await.unwrap() {
            Some(Ok(Message::Close(Some(f)))) => return (f.code, f.reason.to_string()),
            Some(Ok(_)) => continue,
            other => panic!("no close frame: {other:?}"),
        }
    }
}

/// The next e-stop request the loop gets.
async fn estop(requests: &mut Requests) -> ClientRequest {
    tokio::time::timeout(WAIT, requests.estops.recv())
        .await
        .expect("no e-stop reached the loop")
        .unwrap()
        .request
}

#[tokio::test]
async fn connections_that_send_nothing_hold_no_place_and_the_operator_always_gets_in() {
    let (addr, mut requests) = serve(None).await;
    // more silent connections than there are places
    let mut silent = Vec::new();
    for _ in 0..40 {
        silent.push(
            connect(addr, None)
                .await
                .expect("a silent connection refused"),
        );
    }
    // the operator's page: admitted, its hello takes a place, its e-stop reaches the loop
    let mut operator = connect(addr, None).await.expect("the operator refused");
    say(&mut operator, r#"{"t":"hello"}"#).await;
    say(&mut operator, r#"{"t":"estop","on":true}"#).await;
    assert_eq!(
        estop(&mut requests).await,
        ClientRequest::Estop { on: true }
    );
    // the waiting room holds 32: the 9 oldest silent ones (40, and the operator's
    // connection before its hello) were told to try later
    for ws in &mut silent[..9] {
        let (code, reason) = close_frame(ws).await;
        assert_eq!(code, CloseCode::Again);
        assert!(reason.contains("sends nothing holds no place"), "{reason}");
    }
    // the newest 31 still wait: each one's first request takes one of the 31 places left
    for ws in &mut silent[9..] {
        say(ws, r#"{"t":"estop","on":false}"#).await;
        assert_eq!(
            estop(&mut requests).await,
            ClientRequest::Estop { on: false }
        );
    }
}

#[tokio::test]
async fn places_are_taken_by_first_requests_and_by_the_token_at_upgrade() {
    // without a token: 32 clients that spoke hold every place; the 33rd's first request
    // is answered with 1013 and the reason
    let (addr, mut requests) = serve(None).await;
    let mut placed = Vec::new();
    for _ in 0..32 {
        let mut ws = connect(addr, None).await.unwrap();
        say(&mut ws, r#"{"t":"hello"}"#).await;
        placed.push(ws);
    }
    let mut late = connect(addr, None).await.unwrap();
    say(&mut late, r#"{"t":"estop","on":true}"#).await;
    let end = tokio::time::timeout(WAIT, late.next()).await.unwrap();
    let Some(Ok(Message::Close(Some(f)))) = end else {
        panic!("{end:?}")
    };
    assert_eq!(f.code, CloseCode::Again);
    assert_eq!(f.reason.as_str(), "32 clients are connected already");
    // one leaves (its place is given back as its task ends, with its close answered): the
    // next one's request is taken (the late e-stop was not)
    let mut leaving = placed.pop().unwrap();
    leaving.close(None).await.unwrap();
    while leaving.next().await.is_some() {}
    let mut next = connect(addr, None).await.unwrap();
    say(&mut next, r#"{"t":"estop","on":false}"#).await;
    assert_eq!(
        estop(&mut requests).await,
        ClientRequest::Estop { on: false }
    );
    // with a token: a client that presented it is placed at its upgrade, the 33rd gets 503
    let (addr, _requests) = serve(Some(TOKEN)).await;
    assert_eq!(connect(addr, None).await.err(), Some(401));
    let mut holders = Vec::new();
    for _ in 0..32 {
        holders.push(connect(addr, Some(TOKEN)).await.unwrap());
    }
    assert_eq!(connect(addr, Some(TOKEN)).await.err(), Some(503));
}
