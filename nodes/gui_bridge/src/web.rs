//! The web side: serves the page and a WebSocket; JSON messages in both directions.
//!
//! Every request passes the [access policy](crate::access) first. Each client is
//! bounded: messages up to [`Limits::max_message_bytes`] (a bigger one closes that
//! client with code 1009 and the reason), a bounded queue of replies (the bridge loop
//! drops a reply rather than wait for a slow client), and one request in flight to the
//! bridge loop at a time (a flooding client waits for the loop, so it neither queues
//! memory nor gets ahead of other clients). E-stop requests travel on their own channel,
//! which the loop serves before anything else, so no flood delays another client's e-stop.
//!
//! What happens to the connections (refusals, bad requests, ends) goes to the bridge
//! loop as [`WebEvent`]s, on a channel of their own: the loop keeps the counters
//! ([`WebStats`]), and the server's tasks share no lock but the [`WaitingRoom`]'s.
//!
//! **Who holds one of the [`Limits::max_clients`] places.** A client that presented the
//! panel's token holds one from its upgrade (503 when all are taken). On a panel without
//! a token, where any program on this machine passes the access policy, a client takes a
//! place only with its first request (the page sends `{"t": "hello"}` as soon as it is
//! connected): until then it waits in the [`WaitingRoom`], which holds at most
//! [`Limits::max_waiting`] and makes room for a newcomer by closing the one that has
//! waited longest (code 1013). So connections that send nothing hold no place, however
//! many are opened, and the operator's page, which speaks at once, always gets in
//! (issue 36: 32 silent connections had taken every place, and the operator's browser
//! got 503).

use crate::access::{self, AccessPolicy, RequestFacts};
use axum::body::Bytes;
use axum::extract::ws::{CloseFrame, Message as WsMessage, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::middleware::Next;
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use axum::Extension;
use axum::Router;
use futures::SinkExt as _;
use ros_plumbing::logging::shorten;
use serde::Deserialize;
use std::collections::VecDeque;
use std::fmt;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::{broadcast, mpsc, watch, Notify, OwnedSemaphorePermit, Semaphore};

pub mod stats;
pub use stats::{LogLine, WebEvent, WebStats};

/// The page: its HTML, no inline script or style (its Content-Security-Policy allows
/// none), no build step, no request to any other host.
pub const INDEX_HTML: &str = include_str!("../web/index.html");
/// The page's script, served at `/panel.js` to anyone (public code, the same for every
/// panel; the token is not in it).
pub const PANEL_JS: &str = include_str!("../web/panel.js");
/// The page's style sheet, served at `/panel.css` to anyone.
pub const PANEL_CSS: &str = include_str!("../web/panel.css");

/// The page's Content-Security-Policy for a request with this `Host`: scripts, styles,
/// images and connections from the panel itself only (its WebSocket named explicitly,
/// `ws://HOST` and `wss://HOST`, for browsers whose `'self'` does not cover `ws:`), no
/// plugins, no `<base>`, no form posts, no framing. A script a URDF might carry can
/// neither run as the page nor call another host.
///
/// # Examples
/// ```
/// let csp = gui_bridge::web::content_security_policy(Some("127.0.0.1:8080"));
/// assert!(csp.contains("script-src 'self';") && csp.contains("ws://127.0.0.1:8080"));
/// // a Host that could break out of the header is left out
/// assert!(!gui_bridge::web::content_security_policy(Some("x; script-src *")).contains("script-src *"));
/// ```
pub fn content_security_policy(host: Option<&str>) -> String {
    let ws = host
        .map(str::trim)
        .filter(|h| {
            !h.is_empty()
                && h.bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b".-:[]".contains(&b))
        })
        .map(|h| format!(" ws://{h} wss://{h}"))
        .unwrap_or_default();
    format!(
        "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; \
         connect-src 'self'{ws}; frame-ancestors 'none'; object-src 'none'; base-uri 'none'; \
         form-action 'none'"
    )
}

/// The page's icon (SVG), served at `/favicon.ico` to anyone: it is no secret, and a
/// page refused for its token still gets it (no console error for a missing icon).
pub const FAVICON_SVG: &str = include_str!("../web/favicon.svg");

/// The 3D live view: `three` and `urdf-loader` from the npm registry, bundled by
/// `web/viewer3d/build.sh` (checked in with its lockfile, so building the node needs no
/// network), served at `/viewer3d.js` to anyone (public code, like the icon).
pub const VIEWER3D_JS: &str = include_str!("../web/viewer3d.js");
/// The same, gzip-compressed at build time (`gzip -9 -n`): what goes over the wire to
/// any client that accepts gzip.
pub const VIEWER3D_JS_GZ: &[u8] = include_bytes!("../web/viewer3d.js.gz");

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
    /// The waypoint program: teach, edit, play, save, load.
    Program(ProgramOp),
    /// The calibration wizard (`{"t": "calibrate", "op": …}`).
    Calibrate(CalibrateOp),
    /// The recording card (`{"t": "record", "op": "start", "task": …}`, `save`,
    /// `discard`): calls on the recorder node.
    Record(RecordRequest),
    /// The page's first message (`{"t": "hello"}`): nothing to do but to take a client's
    /// place on a panel without a token ([`WaitingRoom`]); never sent to the bridge loop.
    Hello,
}

/// What a browser asks of the recorder ([`crate::recording::RecordOp`]).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "op", rename_all = "snake_case")]
pub enum RecordRequest {
    /// Set the recorder's `task` parameter to `task`, then start an episode.
    Start {
        /// the task field's text
        task: String,
    },
    /// Save the episode.
    Save,
    /// Discard the episode.
    Discard,
}

impl RecordRequest {
    /// The call and the task text of a start.
    pub fn op(&self) -> (crate::recording::RecordOp, Option<&str>) {
        use crate::recording::RecordOp;
        match self {
            RecordRequest::Start { task } => (RecordOp::Start, Some(task)),
            RecordRequest::Save => (RecordOp::Save, None),
            RecordRequest::Discard => (RecordOp::Discard, None),
        }
    }
}

/// What a browser asks of the calibration wizard ([`crate::calibrate::Op`]).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "op", rename_all = "snake_case")]
pub enum CalibrateOp {
    /// Begin: `arm` is `follower` (the default) or `leader`.
    Start {
        /// which arm
        #[serde(default)]
        arm: Option<String>,
    },
    /// Move the active servo by `deg` servo degrees.
    Jog {
        /// servo degrees, at most 5 either way
        deg: f64,
    },
    /// Mark the current reference.
    Mark,
    /// Undo the last mark.
    Back,
    /// Use reference B's alternative.
    Alternative {
        /// use it
        on: bool,
    },
    /// Save and apply, then the test move.
    Save,
    /// The test move again.
    Test,
    /// Leave without saving.
    Cancel,
    /// Leave after saving.
    Finish,
}

impl CalibrateOp {
    /// The wizard's operation, or why the request is no valid one.
    pub fn into_op(self) -> Result<crate::calibrate::Op, String> {
        use crate::calibrate::{Arm, Op};
        Ok(match self {
            CalibrateOp::Start { arm } => {
                let arm = arm.unwrap_or_else(|| "follower".into());
                Op::Start(Arm::parse(&arm).ok_or_else(|| {
                    format!(
                        "calibrate: arm must be `follower` or `leader`, not `{}`",
                        shorten(&arm, 40)
                    )
                })?)
            }
            CalibrateOp::Jog { deg } => Op::Jog(deg),
            CalibrateOp::Mark => Op::Mark,
            CalibrateOp::Back => Op::Back,
            CalibrateOp::Alternative { on } => Op::Alternative(on),
            CalibrateOp::Save => Op::Save,
            CalibrateOp::Test => Op::Test,
            CalibrateOp::Cancel => Op::Cancel,
            CalibrateOp::Finish => Op::Finish,
        })
    }
}

/// What a browser does with the waypoint program (`{"t": "program", "op": …}`).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "op", rename_all = "snake_case")]
pub enum ProgramOp {
    /// Append where the arm is now (its tool, and the claw as last set).
    Teach,
    /// Rename point `i`.
    Rename {
        /// index
        i: usize,
        /// new name
        name: String,
    },
    /// Move point `from` to index `to`.
    Move {
        /// index
        from: usize,
        /// index
        to: usize,
    },
    /// Delete point `i`.
    Remove {
        /// index
        i: usize,
    },
    /// Dwell at point `i` for `s` seconds.
    Dwell {
        /// index
        i: usize,
        /// seconds
        s: f64,
    },
    /// How to move to point `i`: `joint`, `line`, or null (compute_ik's setting).
    Mode {
        /// index
        i: usize,
        /// `joint`, `line` or none
        mode: Option<String>,
    },
    /// Play the program, once or in a loop.
    Play {
        /// start over after the last point
        #[serde(default, rename = "loop")]
        looping: bool,
    },
    /// Stop playing.
    Stop,
    /// Save the program under this name on the node's host.
    Save {
        /// `[A-Za-z0-9_-]{1,64}`
        name: String,
        /// replace a program of that name (without it, an existing one is kept and the
        /// panel asks)
        #[serde(default)]
        overwrite: bool,
    },
    /// Load a saved program.
    Load {
        /// `[A-Za-z0-9_-]{1,64}`
        name: String,
    },
}

/// A browser's request and where to answer it.
#[derive(Debug)]
pub struct FromClient {
    /// The request.
    pub request: ClientRequest,
    /// Replies for that browser only (bounded: answer with `try_send`, never wait).
    pub reply: mpsc::Sender<String>,
}

/// How much one client may hold of the node's resources.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Largest WebSocket message (and frame) accepted, bytes.
    pub max_message_bytes: usize,
    /// Replies queued for one client before further ones are dropped.
    pub reply_queue: usize,
    /// Requests queued to the bridge loop from all clients (each client has at most
    /// one in flight).
    pub request_queue: usize,
    /// E-stop requests queued to the bridge loop.
    pub estop_queue: usize,
    /// [`WebEvent`]s queued to the bridge loop (a task with one more waits for room).
    pub event_queue: usize,
    /// Clients connected at once.
    pub max_clients: usize,
    /// Connections that have sent nothing yet on a panel without a token, at once (the
    /// [`WaitingRoom`]); beyond, the one that has waited longest is closed.
    pub max_waiting: usize,
    /// Largest amount of outgoing data buffered for one client, bytes.
    pub max_write_buffer_bytes: usize,
    /// A client that does not take a message within this time is dropped.
    pub send_timeout: Duration,
}

impl Default for Limits {
    fn default() -> Limits {
        Limits {
            max_message_bytes: 64 * 1024,
            reply_queue: 32,
            request_queue: 64,
            estop_queue: 16,
            event_queue: 256,
            max_clients: 32,
            max_waiting: 32,
            // room for one camera image and its frame header
            max_write_buffer_bytes: MAX_IMAGE_BYTES + 64 * 1024,
            send_timeout: Duration::from_secs(10),
        }
    }
}

/// The bridge loop's ends of the channels from the web server.
#[derive(Debug)]
pub struct Requests {
    /// E-stop engage/release: served first.
    pub estops: mpsc::Receiver<FromClient>,
    /// Everything else.
    pub others: mpsc::Receiver<FromClient>,
    /// What happened to the connections, for the loop's [`WebStats`].
    pub events: mpsc::Receiver<WebEvent>,
}

/// The web server's ends of the channels to the bridge loop.
#[derive(Clone, Debug)]
pub struct RequestSenders {
    estops: mpsc::Sender<FromClient>,
    others: mpsc::Sender<FromClient>,
    events: mpsc::Sender<WebEvent>,
}

impl RequestSenders {
    /// Queue a request for the bridge loop (e-stops on their own channel), waiting
    /// while its queue is full. `Err` gives it back when the loop has stopped.
    pub async fn send(&self, from: FromClient) -> Result<(), FromClient> {
        self.channel(&from.request)
            .send(from)
            .await
            .map_err(|e| e.0)
    }

    /// Queue a request without waiting. `Err` gives it back when the queue is full or
    /// the loop has stopped.
    pub fn try_send(&self, from: FromClient) -> Result<(), FromClient> {
        self.channel(&from.request)
            .try_send(from)
            .map_err(|e| match e {
                mpsc::error::TrySendError::Full(f) | mpsc::error::TrySendError::Closed(f) => f,
            })
    }

    /// Report what happened to a connection to the loop's [`WebStats`], waiting while
    /// the queue is full (a flood of refused requests is answered at the pace the loop
    /// counts it, as a flood of requests is); nothing once the loop has stopped.
    pub async fn report(&self, event: WebEvent) {
        let _ = self.events.send(event).await;
    }

    fn channel(&self, request: &ClientRequest) -> &mpsc::Sender<FromClient> {
        if matches!(request, ClientRequest::Estop { .. }) {
            &self.estops
        } else {
            &self.others
        }
    }
}

/// Bounded request (and event) channels between the clients and the bridge loop.
pub fn request_channels(limits: &Limits) -> (RequestSenders, Requests) {
    let (estop_tx, estops) = mpsc::channel(limits.estop_queue.max(1));
    let (tx, others) = mpsc::channel(limits.request_queue.max(1));
    let (event_tx, events) = mpsc::channel(limits.event_queue.max(1));
    (
        RequestSenders {
            estops: estop_tx,
            others: tx,
            events: event_tx,
        },
        Requests {
            estops,
            others,
            events,
        },
    )
}

/// The length reasons are cut to in log lines, diagnostics and answers.
pub const REASON_MAX: usize = 200;

/// The largest message broadcast to the browsers: a larger one is dropped, counted and
/// logged, never sent (it would fill half of a client's write buffer, and the broadcast
/// channel keeps 256 messages). The inputs are bounded so that none comes near it
/// (bounded.rs); the largest legitimate one, a program of 1000 points, is about 150 KB.
pub const MAX_BROADCAST_BYTES: usize = 1024 * 1024;

/// The largest image the panel passes to a browser (the camera view's; scene.rs refuses
/// bigger ones as it reads them), so that one fits a client's write buffer.
pub const MAX_IMAGE_BYTES: usize = 2 * 1024 * 1024;

/// How a client's connection ended.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ClientEnd {
    /// The client closed it with the closing handshake (a page closed or reloaded).
    Closed,
    /// The client went away without closing: connection reset, broken pipe, end of stream.
    Gone(String),
    /// Receiving failed: a WebSocket protocol violation or another I/O error.
    ReadError(String),
    /// Sending failed.
    WriteError(String),
    /// A message over [`Limits::max_message_bytes`] (closed with code 1009 and the reason).
    Oversized {
        /// the limit
        max_bytes: usize,
    },
    /// The client did not take a message within [`Limits::send_timeout`].
    Stalled {
        /// the timeout
        timeout: Duration,
    },
    /// It had sent nothing, and the [`WaitingRoom`] made room for a newer connection
    /// (closed with code 1013 and the reason).
    Evicted {
        /// the room's size
        max_waiting: usize,
    },
    /// Its first request came when all [`Limits::max_clients`] places were taken (closed
    /// with code 1013; reported as [`WebEvent::Busy`] too).
    Full {
        /// the limit
        max_clients: usize,
    },
    /// The node stops.
    Shutdown,
}

impl ClientEnd {
    /// Short name for diagnostics and log throttling, e.g. `client/read_error`.
    pub fn kind(&self) -> &'static str {
        match self {
            ClientEnd::Closed => "client/closed",
            ClientEnd::Gone(_) => "client/gone",
            ClientEnd::ReadError(_) => "client/read_error",
            ClientEnd::WriteError(_) => "client/write_error",
            ClientEnd::Oversized { .. } => "client/oversized",
            ClientEnd::Stalled { .. } => "client/stalled",
            ClientEnd::Evicted { .. } => "client/evicted",
            ClientEnd::Full { .. } => "client/full",
            ClientEnd::Shutdown => "client/shutdown",
        }
    }

    /// Whether the panel dropped the client (counted in `clients_dropped`),
    /// rather than the client or the node ending the connection in order.
    pub fn is_drop(&self) -> bool {
        !matches!(
            self,
            ClientEnd::Closed | ClientEnd::Shutdown | ClientEnd::Full { .. }
        )
    }

    /// How loud its log line is: debug for an orderly end, info for a client that went
    /// away, warn for errors.
    pub fn level(&self) -> log::Level {
        match self {
            ClientEnd::Closed | ClientEnd::Shutdown | ClientEnd::Full { .. } => log::Level::Debug,
            ClientEnd::Gone(_) | ClientEnd::Evicted { .. } => log::Level::Info,
            _ => log::Level::Warn,
        }
    }

    /// The end a failed receive (`reading`) or send means.
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::web::ClientEnd;
    /// let reset = tungstenite::Error::Io(std::io::ErrorKind::ConnectionReset.into());
    /// assert!(matches!(ClientEnd::from_error(&reset, true, 65536), ClientEnd::Gone(_)));
    /// let pipe = tungstenite::Error::Io(std::io::ErrorKind::BrokenPipe.into());
    /// assert!(matches!(ClientEnd::from_error(&pipe, false, 65536), ClientEnd::Gone(_)));
    /// ```
    pub fn from_error(e: &tungstenite::Error, reading: bool, max_bytes: usize) -> ClientEnd {
        use std::io::ErrorKind;
        use tungstenite::error::ProtocolError;
        let text = || shorten(&e.to_string(), REASON_MAX).into_owned();
        match e {
            tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed => {
                ClientEnd::Closed
            }
            tungstenite::Error::Capacity(_) if reading => ClientEnd::Oversized { max_bytes },
            tungstenite::Error::Protocol(ProtocolError::ResetWithoutClosingHandshake) => {
                ClientEnd::Gone(text())
            }
            tungstenite::Error::Io(io)
                if matches!(
                    io.kind(),
                    ErrorKind::BrokenPipe
                        | ErrorKind::ConnectionReset
                        | ErrorKind::ConnectionAborted
                        | ErrorKind::UnexpectedEof
                ) =>
            {
                ClientEnd::Gone(text())
            }
            _ if reading => ClientEnd::ReadError(text()),
            _ => ClientEnd::WriteError(text()),
        }
    }

    /// [`ClientEnd::from_error`] for axum's error (which wraps tungstenite's).
    fn from_axum(e: axum::Error, reading: bool, max_bytes: usize) -> ClientEnd {
        let inner = e.into_inner();
        match inner.downcast_ref::<tungstenite::Error>() {
            Some(t) => ClientEnd::from_error(t, reading, max_bytes),
            None => {
                let text = shorten(&inner.to_string(), REASON_MAX).into_owned();
                if reading {
                    ClientEnd::ReadError(text)
                } else {
                    ClientEnd::WriteError(text)
                }
            }
        }
    }
}

impl fmt::Display for ClientEnd {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ClientEnd::Closed => write!(f, "closed by the client"),
            ClientEnd::Gone(e) => write!(f, "gone without closing the connection ({e})"),
            ClientEnd::ReadError(e) => write!(f, "read error: {e}"),
            ClientEnd::WriteError(e) => write!(f, "write error: {e}"),
            ClientEnd::Oversized { max_bytes } => {
                write!(
                    f,
                    "message larger than {max_bytes} bytes (closed with 1009)"
                )
            }
            ClientEnd::Stalled { timeout } => {
                write!(f, "took no message within {:.1} s", timeout.as_secs_f64())
            }
            ClientEnd::Evicted { max_waiting } => write!(
                f,
                "sent nothing while {max_waiting} newer connections came (closed with 1013)"
            ),
            ClientEnd::Full { max_clients } => write!(
                f,
                "its first request came with {max_clients} clients connected (closed with 1013)"
            ),
            ClientEnd::Shutdown => write!(f, "the node stops"),
        }
    }
}

/// What every request handler shares.
#[derive(Clone)]
pub struct WebState {
    /// Messages for every browser.
    pub broadcast: broadcast::Sender<String>,
    /// Requests to the bridge loop.
    pub requests: RequestSenders,
    /// Builds the snapshot a new browser gets first.
    pub hello: Arc<dyn Fn() -> String + Send + Sync>,
    /// Who may connect.
    pub access: Arc<AccessPolicy>,
    /// Per-client limits.
    pub limits: Limits,
    /// Room for [`Limits::max_clients`] clients: the one thing the accept path must know
    /// at once (a semaphore, no lock); the counters are the bridge loop's ([`WebStats`]).
    pub slots: Arc<Semaphore>,
    /// Connections without a place yet (a panel without a token: until their first
    /// request).
    pub waiting: Arc<WaitingRoom>,
    /// The URDF the page's 3D view loads from `/robot.urdf` (None: not known yet). Over
    /// HTTP, not in a WebSocket message: a URDF can be larger than a client's write buffer.
    pub urdf: Arc<dyn Fn() -> Option<Arc<str>> + Send + Sync>,
    /// The camera view's latest image (a JPEG or PNG file), sent to every client as a
    /// binary message when it changes: a client still sending the last one skips to the
    /// newest, nothing queues.
    pub camera: watch::Receiver<Option<Bytes>>,
}

impl WebState {
    /// The state for a server with these parts; `slots` sized from `limits`.
    pub fn new(
        broadcast: broadcast::Sender<String>,
        requests: RequestSenders,
        hello: Arc<dyn Fn() -> String + Send + Sync>,
        access: AccessPolicy,
        limits: Limits,
    ) -> WebState {
        WebState {
            broadcast,
            requests,
            hello,
            access: Arc::new(access),
            slots: Arc::new(Semaphore::new(limits.max_clients)),
            waiting: Arc::new(WaitingRoom::new(limits.max_waiting)),
            limits,
            urdf: Arc::new(|| None),
            camera: watch::channel(None).1,
        }
    }

    /// Where the camera view's images come from.
    pub fn with_camera(mut self, camera: watch::Receiver<Option<Bytes>>) -> WebState {
        self.camera = camera;
        self
    }

    /// Where `/robot.urdf` gets the URDF from.
    pub fn with_urdf(mut self, urdf: Arc<dyn Fn() -> Option<Arc<str>> + Send + Sync>) -> WebState {
        self.urdf = urdf;
        self
    }
}

/// The router: `/` the page, `/ws` the WebSocket, both behind the access policy;
/// `/favicon.ico` the icon, open to all.
/// Serve it with `into_make_service_with_connect_info::<SocketAddr>()` so refusals
/// name the client's address.
pub fn router(state: WebState) -> Router {
    Router::new()
        .route("/", get(page))
        .route("/ws", get(ws_handler))
        .route("/robot.urdf", get(robot_urdf))
        .layer(axum::middleware::from_fn_with_state(state.clone(), guard))
        .route("/favicon.ico", get(favicon))
        .route("/viewer3d.js", get(viewer3d))
        .route("/panel.js", get(panel_js))
        .route("/panel.css", get(panel_css))
        .with_state(state)
}

/// Whether `Accept-Encoding` lists gzip (with a non-zero q).
fn accepts_gzip(headers: &HeaderMap) -> bool {
    headers
        .get_all(header::ACCEPT_ENCODING)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|coding| {
            let mut parts = coding.split(';').map(str::trim);
            let name = parts.next().unwrap_or_default();
            let q_zero = parts.any(|p| {
                p.strip_prefix("q=")
                    .and_then(|q| q.parse::<f64>().ok())
                    .is_some_and(|q| q == 0.0)
            });
            (name.eq_ignore_ascii_case("gzip") || name == "*") && !q_zero
        })
}

async fn viewer3d(headers: HeaderMap) -> Response {
    let common = [
        (header::CONTENT_TYPE, "text/javascript; charset=utf-8"),
        (header::CACHE_CONTROL, "max-age=3600"),
        (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        (header::VARY, "Accept-Encoding"),
    ];
    if accepts_gzip(&headers) {
        (common, [(header::CONTENT_ENCODING, "gzip")], VIEWER3D_JS_GZ).into_response()
    } else {
        (common, VIEWER3D_JS).into_response()
    }
}

async fn panel_js() -> impl IntoResponse {
    (
        [
            (header::CONTENT_TYPE, "text/javascript; charset=utf-8"),
            (header::CACHE_CONTROL, "no-cache"),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        PANEL_JS,
    )
}

async fn panel_css() -> impl IntoResponse {
    (
        [
            (header::CONTENT_TYPE, "text/css; charset=utf-8"),
            (header::CACHE_CONTROL, "no-cache"),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        PANEL_CSS,
    )
}

async fn favicon() -> impl IntoResponse {
    (
        [
            (header::CONTENT_TYPE, "image/svg+xml"),
            (header::CACHE_CONTROL, "max-age=86400"),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        FAVICON_SVG,
    )
}

/// The URDF of `robot_description`, for the page's 3D view, as plain text: any DDS peer
/// can publish a `robot_description`, and as `application/xml` an XHTML `<script>` in it
/// would run in the panel's origin when the URL is opened. As `text/plain` with
/// `nosniff` a browser only shows it; the sandbox CSP is a second wall.
async fn robot_urdf(State(state): State<WebState>) -> Response {
    match (state.urdf)() {
        Some(text) => (
            [
                (header::CONTENT_TYPE, "text/plain; charset=utf-8"),
                (header::CACHE_CONTROL, "no-store"),
                (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
                (
                    header::CONTENT_SECURITY_POLICY,
                    "sandbox; default-src 'none'",
                ),
            ],
            text.to_string(),
        )
            .into_response(),
        None => (StatusCode::NOT_FOUND, "no robot_description yet\n").into_response(),
    }
}

async fn page(headers: HeaderMap) -> Response {
    let host = headers.get(header::HOST).and_then(|v| v.to_str().ok());
    let csp = HeaderValue::from_str(&content_security_policy(host)).unwrap_or_else(|_| {
        HeaderValue::from_static(
            "default-src 'self'; frame-ancestors 'none'; object-src 'none'; base-uri 'none'",
        )
    });
    (
        [
            (header::CACHE_CONTROL, HeaderValue::from_static("no-store")),
            // no other site may frame the panel (clickjacking the e-stop's release)
            (header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY")),
            (header::CONTENT_SECURITY_POLICY, csp),
            // the URL may carry the token: never send it on as a referrer
            (
                header::REFERRER_POLICY,
                HeaderValue::from_static("no-referrer"),
            ),
            (
                header::X_CONTENT_TYPE_OPTIONS,
                HeaderValue::from_static("nosniff"),
            ),
        ],
        Html(INDEX_HTML),
    )
        .into_response()
}

/// What a request says, from its headers and URL.
fn facts<'a>(headers: &'a HeaderMap, query: Option<&'a str>) -> RequestFacts<'a> {
    let text = |name: header::HeaderName| headers.get(name).and_then(|v| v.to_str().ok());
    RequestFacts {
        host: text(header::HOST),
        origin: text(header::ORIGIN),
        forwarded_proto: headers
            .get("x-forwarded-proto")
            .and_then(|v| v.to_str().ok()),
        query_token: access::query_token(query),
        header_token: text(header::AUTHORIZATION).and_then(access::authorization_token),
        protocol_token: headers
            .get_all(header::SEC_WEBSOCKET_PROTOCOL)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .find_map(access::protocol_token),
    }
}

/// Applies the access policy to every request.
async fn guard(State(state): State<WebState>, request: Request, next: Next) -> Response {
    let who = request
        .extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map(|c| c.0);
    let facts = facts(request.headers(), request.uri().query());
    // the page is public code and finds its token in its own origin's storage: only the
    // Origin and Host rules apply to it; everything else needs the token
    let decision = if request.uri().path() == "/" {
        state.access.check_page(&facts)
    } else {
        state.access.check(&facts)
    };
    match decision {
        Ok(admission) => {
            let mut request = request;
            request.extensions_mut().insert(admission);
            next.run(request).await
        }
        Err(refusal) => {
            let what = format!("{} {}", request.method(), request.uri().path());
            let event = WebEvent::Refused {
                who,
                what,
                refusal: refusal.clone(),
            };
            state.requests.report(event).await;
            let status = StatusCode::from_u16(refusal.status()).unwrap_or(StatusCode::FORBIDDEN);
            let mut response = (
                status,
                [(header::CACHE_CONTROL, "no-store")],
                format!("{status}: {refusal}\n"),
            )
                .into_response();
            if status == StatusCode::UNAUTHORIZED {
                response.headers_mut().insert(
                    header::WWW_AUTHENTICATE,
                    HeaderValue::from_static("token realm=\"eezybot panel\""),
                );
            }
            response
        }
    }
}

/// Where a client stands: in one of the [`Limits::max_clients`] places, or waiting for
/// its first request in the [`WaitingRoom`] (a panel without a token).
enum Seat {
    Placed {
        /// the place, given back when the client goes
        _slot: OwnedSemaphorePermit,
    },
    Waiting(Waiting),
}

/// Until `leave` is notified; never without one.
async fn told_to_leave(leave: Option<Arc<Notify>>) {
    match leave {
        Some(leave) => leave.notified().await,
        None => std::future::pending().await,
    }
}

async fn ws_handler(
    ws: WebSocketUpgrade,
    State(state): State<WebState>,
    connect_info: Option<Extension<ConnectInfo<SocketAddr>>>,
    admission: Option<Extension<access::Admission>>,
) -> Response {
    let who = connect_info.map(|c| c.0 .0);
    // a client that presented the token takes its place now; on a panel without one, a
    // client waits for its first request (any program here passes the policy)
    let token = admission.is_some_and(|a| {
        matches!(
            a.0.by,
            access::Credential::Query | access::Credential::Header | access::Credential::Protocol
        )
    });
    let placed = if token {
        let Ok(slot) = state.slots.clone().try_acquire_owned() else {
            let max_clients = state.limits.max_clients;
            state
                .requests
                .report(WebEvent::Busy { who, max_clients })
                .await;
            return (
                StatusCode::SERVICE_UNAVAILABLE,
                format!(
                    "503: {} clients are connected already\n",
                    state.limits.max_clients
                ),
            )
                .into_response();
        };
        Some(slot)
    } else {
        None
    };
    let l = state.limits;
    let from = who.map_or_else(|| "(unknown address)".to_string(), |a| a.to_string());
    let (events, failed_from) = (state.requests.clone(), from.clone());
    // the page offers its protocol and `token.…`: the answer names its protocol only
    ws.protocols([access::PANEL_PROTOCOL])
        .max_message_size(l.max_message_bytes)
        .max_frame_size(l.max_message_bytes)
        .max_write_buffer_size(l.max_write_buffer_bytes)
        .on_failed_upgrade(move |e: axum::Error| {
            let event = WebEvent::UpgradeFailed {
                from: failed_from,
                error: e.to_string(),
            };
            // called where it cannot wait: the report waits in a task of its own
            tokio::spawn(async move { events.report(event).await });
        })
        .on_upgrade(move |socket| async move {
            let seat = match placed {
                Some(slot) => Seat::Placed { _slot: slot },
                None => Seat::Waiting(state.waiting.enter()),
            };
            state.requests.report(WebEvent::Connected).await;
            let mut bad_requests = 0;
            let end = client(socket, &state, (who, &from), seat, &mut bad_requests).await;
            // a broken connection ends this client's task only: counted, logged, gone
            let event = WebEvent::Ended {
                from,
                end,
                bad_requests,
            };
            state.requests.report(event).await;
        })
}

/// A client's send: gives up on a broken connection or after the send timeout.
async fn send(socket: &mut WebSocket, msg: WsMessage, state: &WebState) -> Result<(), ClientEnd> {
    match tokio::time::timeout(state.limits.send_timeout, socket.send(msg)).await {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => Err(ClientEnd::from_axum(
            e,
            false,
            state.limits.max_message_bytes,
        )),
        Err(_) => Err(ClientEnd::Stalled {
            timeout: state.limits.send_timeout,
        }),
    }
}

fn refused(reason: &str) -> WsMessage {
    let answer = crate::message::ToClient::Refused {
        reason: reason.to_string(),
        reachable: None,
    };
    WsMessage::Text(answer.to_text().into())
}

/// A message from `from` that is no request (`reason`: why not): counted in `bad`,
/// reported, refused.
async fn bad_request(
    socket: &mut WebSocket,
    state: &WebState,
    from: &str,
    bad: &mut u64,
    reason: &str,
) -> Result<(), ClientEnd> {
    *bad += 1;
    let event = WebEvent::BadRequest {
        from: from.to_string(),
        reason: reason.to_string(),
    };
    state.requests.report(event).await;
    send(socket, refused(&format!("bad request: {reason}")), state).await
}

/// Close `socket` with code 1013 (try again later) and `reason`.
async fn try_later(socket: &mut WebSocket, state: &WebState, reason: String) {
    let close = CloseFrame {
        code: 1013,
        reason: reason.into(),
    };
    let _ = send(socket, WsMessage::Close(Some(close)), state).await;
}

/// Serve one client (`who`: its address, and as text) until its connection ends; how it
/// ended. Besides the JSON messages it gets the camera view's images, each a binary
/// message (the image file). A waiting client ([`Seat::Waiting`]) takes a place with its
/// first request, or leaves when the [`WaitingRoom`] makes room for a newer one. `bad`
/// counts the messages from it that were no request.
async fn client(
    mut socket: WebSocket,
    state: &WebState,
    (who, from): (Option<SocketAddr>, &str),
    mut seat: Seat,
    bad: &mut u64,
) -> ClientEnd {
    let mut all = state.broadcast.subscribe();
    let (reply_tx, mut replies) = mpsc::channel::<String>(state.limits.reply_queue.max(1));
    if let Err(end) = send(&mut socket, WsMessage::Text((state.hello)().into()), state).await {
        return end;
    }
    let max_bytes = state.limits.max_message_bytes;
    // images from now on: an image from before this client came may be stale
    let mut camera = state.camera.clone();
    camera.borrow_and_update();
    let mut camera_open = true;
    loop {
        let leave = match &seat {
            Seat::Waiting(w) => Some(w.leave.clone()),
            Seat::Placed { .. } => None,
        };
        tokio::select! {
            () = told_to_leave(leave) => {
                let max_waiting = state.limits.max_waiting;
                let reason = "room made for a newer connection: one that sends nothing holds no place";
                try_later(&mut socket, state, reason.into()).await;
                return ClientEnd::Evicted { max_waiting };
            }
            incoming = socket.recv() => {
                let text = match incoming {
                    None => return ClientEnd::Closed,
                    Some(Ok(WsMessage::Close(_))) => {
                        // the library queued the answering close frame: send it before
                        // the connection is dropped, so the close handshake completes
                        let _ = tokio::time::timeout(state.limits.send_timeout, socket.flush()).await;
                        return ClientEnd::Closed;
                    }
                    Some(Ok(WsMessage::Text(text))) => text,
                    Some(Ok(WsMessage::Binary(_))) => {
                        let reason = "binary messages are not understood";
                        if let Err(end) = bad_request(&mut socket, state, from, bad, reason).await { return end }
                        continue;
                    }
                    Some(Ok(_)) => continue, // ping/pong: answered by the library
                    Some(Err(e)) => {
                        let end = ClientEnd::from_axum(e, true, max_bytes);
                        if let ClientEnd::Oversized { .. } = end {
                            let reason = format!("message larger than {max_bytes} bytes");
                            let close = CloseFrame { code: 1009, reason: reason.into() };
                            let _ = send(&mut socket, WsMessage::Close(Some(close)), state).await;
                        }
                        return end;
                    }
                };
                match serde_json::from_str::<ClientRequest>(&text) {
                    Ok(request) => {
                        if matches!(seat, Seat::Waiting(_)) {
                            // its first request: a place, if one is free
                            let Ok(slot) = state.slots.clone().try_acquire_owned() else {
                                let max_clients = state.limits.max_clients;
                                state.requests.report(WebEvent::Busy { who, max_clients }).await;
                                try_later(&mut socket, state, format!("{max_clients} clients are connected already")).await;
                                return ClientEnd::Full { max_clients };
                            };
                            seat = Seat::Placed { _slot: slot };
                        }
                        if request == ClientRequest::Hello {
                            continue;
                        }
                        // waits while the loop is busy: this client's next message stays
                        // unread (TCP holds it), other clients take their turns
                        if state.requests.send(FromClient { request, reply: reply_tx.clone() }).await.is_err() {
                            return ClientEnd::Shutdown;
                        }
                    }
                    Err(e) => {
                        let reason = shorten(&e.to_string(), REASON_MAX).into_owned();
                        if let Err(end) = bad_request(&mut socket, state, from, bad, &reason).await { return end }
                    }
                }
            }
            Some(text) = replies.recv() => {
                if let Err(end) = send(&mut socket, WsMessage::Text(text.into()), state).await { return end }
            }
            out = all.recv() => match out {
                Ok(text) => if let Err(end) = send(&mut socket, WsMessage::Text(text.into()), state).await { return end },
                Err(broadcast::error::RecvError::Lagged(_)) => continue,
                Err(broadcast::error::RecvError::Closed) => return ClientEnd::Shutdown,
            },
            changed = camera.changed(), if camera_open => match changed {
                Ok(()) => {
                    let image = camera.borrow_and_update().clone();
                    if let Some(image) = image {
                        if let Err(end) = send(&mut socket, WsMessage::Binary(image), state).await { return end }
                    }
                }
                // no camera view (its sender is gone)
                Err(_) => camera_open = false,
            },
        }
    }
}

/// Connections that have not sent their first request yet, on a panel without a token:
/// at most `max`, oldest first. A newcomer beyond makes the oldest leave (its
/// [`Waiting::leave`] is notified; its task closes it with 1013). Shared by the server's
/// tasks behind a lock held only to enter and leave (at most `max` entries).
#[derive(Debug)]
pub struct WaitingRoom {
    max: usize,
    queue: Mutex<Queue>,
}

/// The [`WaitingRoom`]'s entries.
#[derive(Debug, Default)]
struct Queue {
    /// the next entry's number
    next: u64,
    /// (number, its leave signal), oldest first
    entries: VecDeque<(u64, Arc<Notify>)>,
}

impl WaitingRoom {
    /// A room for `max` connections (at least one).
    pub fn new(max: usize) -> WaitingRoom {
        WaitingRoom {
            max: max.max(1),
            queue: Mutex::new(Queue::default()),
        }
    }

    fn queue(&self) -> std::sync::MutexGuard<'_, Queue> {
        // a poisoned lock only means a panic elsewhere while it was held: the queue is
        // still consistent (each change is one push or remove)
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Enter; the oldest leave while the room is full. The guard leaves when dropped.
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::web::WaitingRoom;
    /// let room = std::sync::Arc::new(WaitingRoom::new(2));
    /// let (_a, b) = (room.enter(), room.enter());
    /// let _c = room.enter(); // _a is told to leave (its `leave` is notified)
    /// assert_eq!(room.len(), 2);
    /// drop(b);
    /// assert_eq!(room.len(), 1);
    /// ```
    pub fn enter(self: &Arc<Self>) -> Waiting {
        let leave = Arc::new(Notify::new());
        let mut q = self.queue();
        let id = q.next;
        q.next += 1;
        while q.entries.len() >= self.max {
            if let Some((_, oldest)) = q.entries.pop_front() {
                oldest.notify_one();
            }
        }
        q.entries.push_back((id, leave.clone()));
        Waiting {
            id,
            leave,
            room: self.clone(),
        }
    }

    /// How many wait now.
    pub fn len(&self) -> usize {
        self.queue().entries.len()
    }

    /// Whether none waits.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A place in the [`WaitingRoom`], left when dropped.
#[derive(Debug)]
pub struct Waiting {
    id: u64,
    /// Notified when the room makes room for a newer connection: leave then.
    pub leave: Arc<Notify>,
    room: Arc<WaitingRoom>,
}

impl Drop for Waiting {
    fn drop(&mut self) {
        self.room.queue().entries.retain(|(id, _)| *id != self.id);
    }
}
