//! The web side: serves the page and a WebSocket; JSON messages in both directions.

use axum::extract::ws::{Message as WsMessage, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::header;
use axum::response::{Html, IntoResponse};
use axum::routing::get;
use axum::Router;
use serde::Deserialize;
use tokio::sync::{broadcast, mpsc};

/// The page: one file, no build step, no request to any other host.
pub const INDEX_HTML: &str = include_str!("../web/index.html");

/// A message from a browser.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "t", rename_all = "snake_case")]
pub enum ClientRequest {
    /// Move to a point.
    Target {
        /// m
        xyz: [f64; 3],
    },
    /// Move by a step.
    Jog {
        /// m
        d: [f64; 3],
    },
    /// Claw opening.
    Gripper {
        /// 0 … 1
        v: f64,
    },
    /// Joint mode.
    Joints {
        /// name → rad
        q: std::collections::BTreeMap<String, f64>,
    },
    /// Emergency stop.
    Estop {
        /// engaged?
        on: bool,
    },
    /// Is this point reachable? (nothing is sent)
    Check {
        /// m
        xyz: [f64; 3],
    },
}

/// A browser's request and where to answer it.
#[derive(Debug)]
pub struct FromClient {
    /// The request.
    pub request: ClientRequest,
    /// Replies for that browser only.
    pub reply: mpsc::UnboundedSender<String>,
}

/// What every WebSocket handler shares.
#[derive(Clone)]
pub struct WebState {
    /// Messages for every browser.
    pub broadcast: broadcast::Sender<String>,
    /// Requests to the bridge loop.
    pub requests: mpsc::UnboundedSender<FromClient>,
    /// Builds the snapshot a new browser gets first.
    pub hello: std::sync::Arc<dyn Fn() -> String + Send + Sync>,
}

/// The router: `/` the page, `/ws` the WebSocket.
pub fn router(state: WebState) -> Router {
    Router::new()
        .route(
            "/",
            get(|| async { ([(header::CACHE_CONTROL, "no-store")], Html(INDEX_HTML)) }),
        )
        .route("/ws", get(ws_handler))
        .with_state(state)
}

async fn ws_handler(ws: WebSocketUpgrade, State(state): State<WebState>) -> impl IntoResponse {
    ws.on_upgrade(move |socket| client(socket, state))
}

async fn client(mut socket: WebSocket, state: WebState) {
    let mut all = state.broadcast.subscribe();
    let (reply_tx, mut replies) = mpsc::unbounded_channel::<String>();
    if socket
        .send(WsMessage::Text((state.hello)().into()))
        .await
        .is_err()
    {
        return;
    }
    loop {
        tokio::select! {
            incoming = socket.recv() => {
                let Some(Ok(msg)) = incoming else { break };
                let WsMessage::Text(text) = msg else { continue };
                match serde_json::from_str::<ClientRequest>(&text) {
                    Ok(request) => {
                        let _ = state.requests.send(FromClient { request, reply: reply_tx.clone() });
                    }
                    Err(e) => {
                        log::warn!("bad request from a browser ignored: {e}");
                        let _ = reply_tx.send(serde_json::json!({"t": "refused", "reason": format!("bad request: {e}")}).to_string());
                    }
                }
            }
            Some(text) = replies.recv() => {
                if socket.send(WsMessage::Text(text.into())).await.is_err() { break }
            }
            out = all.recv() => match out {
                Ok(text) => if socket.send(WsMessage::Text(text.into())).await.is_err() { break },
                Err(broadcast::error::RecvError::Lagged(_)) => continue,
                Err(broadcast::error::RecvError::Closed) => break,
            },
        }
    }
}
