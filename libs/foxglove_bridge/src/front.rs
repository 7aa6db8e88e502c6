//! The door of the Foxglove WebSocket server: what the SDK cannot do itself.
//!
//! The Foxglove SDK (0.25) accepts every TCP connection on its own listener, shows the
//! server neither the upgrade request (no `Origin`, `Host`, URL or `Authorization`) nor
//! the client's address, has no limit on connections, and reads messages of up to 64 MiB
//! (tungstenite's default). So the SDK's server listens on no port at all (our copy of the
//! SDK, patches/foxglove: `WebSocketServer::start_without_listener`), and this front
//! listens on `foxglove_bind`:
//!
//! 1. at most [`FrontLimits::max_pending`] connections may be sending their request head,
//!    and each has [`FrontLimits::header_timeout`] to send it, at most
//!    [`FrontLimits::max_header_bytes`] long (a half-open connection is not held);
//! 2. the head is handed to the node's [`Gate`] (the web panel's rules: `Origin`, `Host`,
//!    token), which admits it (and says whether this client may publish) or refuses it
//!    with an HTTP status;
//! 3. at most [`FrontLimits::max_clients`] clients at once (503 beyond);
//! 4. an admitted client is joined to the SDK's server through an in-process pipe
//!    ([`tokio::io::duplex`], handed over with `foxglove::StreamAcceptor`); its frames are
//!    checked on the way in, and a message over [`FrontLimits::max_message_bytes`] closes
//!    it with 1009 before its payload is read (nothing of it is buffered).
//!
//! With a TLS configuration ([`crate::FoxgloveBridge::start_secure`]) the front speaks
//! `wss://`: each connection's handshake runs in its own task, within
//! [`FrontLimits::header_timeout`] and counted among the pending connections, so a slow
//! or silent client holds up no other; the request head is then read from the decrypted
//! stream as above.
//!
//! Before our copy of the SDK had `start_without_listener`, the SDK listened on a free
//! port of 127.0.0.1, where a page of any origin could connect (found by trying ports)
//! and send four 64 MiB messages to take the node to 363 MB (issue 36). Now every
//! connection the SDK serves is one the front made. The front still introduces each one:
//! its first message to the SDK advertises a client channel (id [`INTRODUCTION_CHANNEL`])
//! whose topic is a random 128-bit introduction, known only to this process, and which
//! says whether that client may publish. The server's listener ([`crate::server`]) sends
//! samples only to clients introduced so, and takes samples only from clients introduced
//! as publishers.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpListener;
use tokio::sync::Semaphore;

/// The client channel id the introduction is advertised under (and unadvertised at once).
pub(crate) const INTRODUCTION_CHANNEL: u32 = u32::MAX;

/// Bytes each way in the pipe between the front and the SDK's server for one client.
const PIPE_BYTES: usize = 64 * 1024;

/// The upgrade request of a Foxglove client, as the [`Gate`] sees it.
#[derive(Debug, Clone, Default)]
pub struct UpgradeRequest {
    /// The client's address.
    pub peer: Option<SocketAddr>,
    /// The request target: path and query (`/?token=…`).
    pub target: String,
    /// Header names (lower case) and values, as received.
    pub headers: Vec<(String, String)>,
}

impl UpgradeRequest {
    /// The first value of header `name` (lower case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }

    /// The query of the request target, if any.
    pub fn query(&self) -> Option<&str> {
        self.target.split_once('?').map(|(_, q)| q)
    }
}

/// What the [`Gate`] lets in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Admitted {
    /// May this client publish on the target topics (when the server takes samples)?
    pub may_publish: bool,
}

/// Why the [`Gate`] refuses a client: the HTTP status and a short reason (sent back).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refused {
    /// 400, 401, 403 …
    pub status: u16,
    /// One line, no secret in it.
    pub reason: String,
}

/// The node's access decision for one upgrade request.
pub type Gate = Arc<dyn Fn(&UpgradeRequest) -> Result<Admitted, Refused> + Send + Sync>;

/// The default gate of [`crate::FoxgloveBridge::start`]: programs only (a request with an
/// `Origin` comes from a web page and is refused), each may publish when the server
/// takes samples.
pub fn programs_only() -> Gate {
    Arc::new(|req: &UpgradeRequest| match req.header("origin") {
        None => Ok(Admitted { may_publish: true }),
        Some(origin) => Err(Refused {
            status: 403,
            reason: format!(
                "Origin {:?}: web pages may not connect",
                origin.chars().take(100).collect::<String>()
            ),
        }),
    })
}

/// The front's limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrontLimits {
    /// Clients connected at once.
    pub max_clients: usize,
    /// Connections still sending their request head at once.
    pub max_pending: usize,
    /// Time to send the request head.
    pub header_timeout: Duration,
    /// Longest request head.
    pub max_header_bytes: usize,
    /// Largest message from a client (every frame of a fragmented message together).
    pub max_message_bytes: u64,
    /// Largest sample the server forwards to its clients (and keeps as a latched topic's
    /// last): a larger one is refused ([`crate::FoxgloveBridge::log`]) and counted in
    /// [`FrontStats::oversized_samples`]. Any DDS peer may publish a URDF of megabytes;
    /// each client's queue holds up to 1024 samples.
    pub max_sample_bytes: usize,
}

impl Default for FrontLimits {
    fn default() -> FrontLimits {
        FrontLimits {
            max_clients: 16,
            max_pending: 64,
            header_timeout: Duration::from_secs(10),
            max_header_bytes: 16 * 1024,
            max_message_bytes: 1024 * 1024,
            // a camera image of the panel's largest (gui_bridge's MAX_IMAGE_BYTES)
            max_sample_bytes: 2 * 1024 * 1024,
        }
    }
}

/// Counters of the front.
#[derive(Debug, Default)]
pub struct FrontStats {
    /// Refused by the gate.
    pub refused: std::sync::atomic::AtomicU64,
    /// Refused because [`FrontLimits::max_clients`] were connected, or too many pending.
    pub refused_busy: std::sync::atomic::AtomicU64,
    /// Closed for a message over [`FrontLimits::max_message_bytes`].
    pub closed_oversized: std::sync::atomic::AtomicU64,
    /// Dropped for sending no complete request head (or TLS handshake) in time.
    pub header_timeouts: std::sync::atomic::AtomicU64,
    /// TLS handshakes that failed (a client that does not trust the certificate).
    pub tls_failures: std::sync::atomic::AtomicU64,
    /// Samples not forwarded for being over [`FrontLimits::max_sample_bytes`].
    pub oversized_samples: std::sync::atomic::AtomicU64,
}

/// Introductions handed out to the front's own connections: random topic → may publish.
#[derive(Debug, Default)]
pub(crate) struct Introductions(Mutex<HashMap<String, bool>>);

impl Introductions {
    /// A new introduction for a connection (`None` without random numbers).
    fn issue(&self, may_publish: bool) -> Option<String> {
        let mut bytes = [0u8; 16];
        getrandom::fill(&mut bytes).ok()?;
        let text: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        let topic = format!("/.gui_bridge_front/{text}");
        self.0.lock().ok()?.insert(topic.clone(), may_publish);
        Some(topic)
    }

    /// Take the introduction `topic` (once): whether it is one, and may publish.
    pub(crate) fn redeem(&self, topic: &str) -> Option<bool> {
        self.0.lock().ok()?.remove(topic)
    }
}

pub(crate) struct Front {
    pub(crate) gate: Gate,
    pub(crate) limits: FrontLimits,
    /// where the SDK's server takes the connections the front joins to it
    pub(crate) sdk: foxglove::StreamAcceptor,
    pub(crate) introductions: Arc<Introductions>,
    pub(crate) stats: Arc<FrontStats>,
    /// Does the SDK's server take samples at all?
    pub(crate) publishing: bool,
    /// refusals logged already (address, status)
    pub(crate) logged: Mutex<std::collections::HashSet<(std::net::IpAddr, u16)>>,
    /// `wss://`: every connection's TLS handshake first
    pub(crate) tls: Option<tokio_rustls::TlsAcceptor>,
}

impl Front {
    /// Serve `listener` until the task is aborted.
    pub(crate) async fn run(self: Arc<Self>, listener: TcpListener) {
        let clients = Arc::new(Semaphore::new(self.limits.max_clients));
        let pending = Arc::new(Semaphore::new(self.limits.max_pending));
        loop {
            let Ok((stream, peer)) = listener.accept().await else {
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            };
            let Ok(head_permit) = pending.clone().try_acquire_owned() else {
                self.count(&self.stats.refused_busy);
                drop(stream); // too many half-open connections: no task for this one
                continue;
            };
            let (front, clients) = (self.clone(), clients.clone());
            tokio::spawn(async move {
                let _ = stream.set_nodelay(true);
                match front.tls.clone() {
                    None => front.connection(stream, peer, head_permit, clients).await,
                    Some(tls) => {
                        let shaken =
                            tokio::time::timeout(front.limits.header_timeout, tls.accept(stream))
                                .await;
                        match shaken {
                            Ok(Ok(stream)) => {
                                front.connection(stream, peer, head_permit, clients).await;
                            }
                            Ok(Err(e)) => {
                                front.count(&front.stats.tls_failures);
                                log::debug!("Foxglove client {peer}: TLS handshake failed: {e}");
                            }
                            Err(_) => {
                                front.count(&front.stats.header_timeouts);
                                log::debug!("Foxglove client {peer}: no TLS handshake in time");
                            }
                        }
                    }
                }
            });
        }
    }

    /// Is this the first refusal of `ip` with `status` (so it is logged)? A client retrying
    /// every second logs one line; past 1024 addresses refusals are only counted.
    fn first_refusal(&self, ip: std::net::IpAddr, status: u16) -> bool {
        let Ok(mut logged) = self.logged.lock() else {
            return false;
        };
        logged.len() < 1024 && logged.insert((ip, status))
    }

    fn count(&self, c: &std::sync::atomic::AtomicU64) {
        c.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }

    async fn connection<S: AsyncRead + AsyncWrite + Unpin>(
        &self,
        mut client: S,
        peer: SocketAddr,
        head_permit: tokio::sync::OwnedSemaphorePermit,
        clients: Arc<Semaphore>,
    ) {
        let read = tokio::time::timeout(
            self.limits.header_timeout,
            read_head(&mut client, self.limits.max_header_bytes),
        )
        .await;
        drop(head_permit);
        let (head, rest) = match read {
            Err(_) => {
                self.count(&self.stats.header_timeouts);
                let _ = answer(&mut client, 408, "no complete request head in time").await;
                return;
            }
            Ok(Err(HeadError::TooLong)) => {
                let _ = answer(&mut client, 431, "request head too long").await;
                return;
            }
            Ok(Err(HeadError::Io)) => return,
            Ok(Ok(r)) => r,
        };
        let Some(mut request) = parse_head(&head) else {
            let _ = answer(&mut client, 400, "not an HTTP request").await;
            return;
        };
        request.peer = Some(peer);
        let admitted = match (self.gate)(&request) {
            Ok(a) => a,
            Err(refused) => {
                self.count(&self.stats.refused);
                if self.first_refusal(peer.ip(), refused.status) {
                    log::warn!(
                        "Foxglove client {peer} refused: {} {} (further refusals of this address with this status are counted, not logged)",
                        refused.status,
                        refused.reason
                    );
                }
                let _ = answer(&mut client, refused.status, &refused.reason).await;
                return;
            }
        };
        let Ok(_slot) = clients.try_acquire_owned() else {
            self.count(&self.stats.refused_busy);
            let why = format!("{} clients are connected already", self.limits.max_clients);
            let _ = answer(&mut client, 503, &why).await;
            return;
        };
        let may_publish = admitted.may_publish && self.publishing;
        if let Err(e) = self.join(client, peer, &request, rest, may_publish).await {
            log::debug!("Foxglove client {peer}: {e}");
        }
    }

    /// Join an admitted client to the SDK's server until either side ends.
    async fn join<S: AsyncRead + AsyncWrite + Unpin>(
        &self,
        client: S,
        peer: SocketAddr,
        request: &UpgradeRequest,
        early: Vec<u8>,
        may_publish: bool,
    ) -> std::io::Result<()> {
        let introduction = self
            .introductions
            .issue(may_publish)
            .ok_or_else(|| std::io::Error::other("no random numbers for an introduction"))?;
        // the SDK's end of the pipe: its buffer bounds what waits in it either way
        let (mut inner, sdk_end) = tokio::io::duplex(PIPE_BYTES);
        if !self.sdk.serve(sdk_end, peer) {
            return Err(std::io::Error::other("the SDK's server no longer runs"));
        }
        // the request as the SDK needs it: no token, no cookie, no URL
        let mut head = String::from("GET / HTTP/1.1\r\n");
        for (name, value) in &request.headers {
            if !matches!(name.as_str(), "authorization" | "cookie") {
                head.push_str(&format!("{name}: {value}\r\n"));
            }
        }
        head.push_str("\r\n");
        inner.write_all(head.as_bytes()).await?;
        let (mut client_rd, mut client_wr) = tokio::io::split(client);
        let (mut inner_rd, mut inner_wr) = tokio::io::split(inner);
        // the SDK's answer, then its first message (serverInfo), on to the client
        let (answer_head, mut buffered) = read_head(&mut inner_rd, 64 * 1024)
            .await
            .map_err(|_| std::io::Error::other("no answer from the SDK's server"))?;
        client_wr.write_all(&answer_head).await?;
        if !answer_head.starts_with(b"HTTP/1.1 101") {
            // the SDK refused the upgrade (e.g. no subprotocol): its reason on to the client
            client_wr.write_all(&buffered).await?;
            let rest = tokio::io::copy(&mut inner_rd, &mut client_wr);
            let _ = tokio::time::timeout(Duration::from_secs(5), rest).await;
            return Ok(());
        }
        let (info, after) = read_frame(&mut inner_rd, &mut buffered).await?;
        client_wr
            .write_all(&server_info_for(&info, may_publish))
            .await?;
        client_wr.write_all(&after).await?;
        // the introduction, before anything of the client's
        let intro = serde_json::json!({"op": "advertise", "channels": [{
            "id": INTRODUCTION_CHANNEL, "topic": introduction, "encoding": "cdr", "schemaName": ""}]});
        // (it stays advertised: its unadvertising when the client goes ends the client's
        // entry in the listener)
        inner_wr
            .write_all(&masked_text_frame(&intro.to_string()))
            .await?;
        let mut checker = FrameChecker::new(self.limits.max_message_bytes);
        let outcome = tokio::select! {
            _ = tokio::io::copy(&mut inner_rd, &mut client_wr) => Ok(()),
            r = checker.pump(early, &mut client_rd, &mut inner_wr) => r,
        };
        if outcome.is_err() {
            self.count(&self.stats.closed_oversized);
            // (after a partly copied message of the server's this close frame is garbage
            // to the client; it is dropped either way)
            let reason = format!(
                "message larger than {} bytes",
                self.limits.max_message_bytes
            );
            let _ = client_wr.write_all(&close_frame(1009, &reason)).await;
        }
        let _ = client_wr.shutdown().await;
        let _ = inner_wr.shutdown().await;
        Ok(())
    }
}

/// The SDK's serverInfo frame for a client: without `clientPublish` (and the encodings it
/// takes) when this client may not publish.
fn server_info_for(frame: &Frame, may_publish: bool) -> Vec<u8> {
    if may_publish || frame.opcode != 1 {
        return frame.raw.clone();
    }
    let Ok(mut info) = serde_json::from_slice::<serde_json::Value>(&frame.payload) else {
        return frame.raw.clone();
    };
    if let Some(caps) = info.get_mut("capabilities").and_then(|c| c.as_array_mut()) {
        caps.retain(|c| c != "clientPublish");
    }
    if let Some(obj) = info.as_object_mut() {
        obj.remove("supportedEncodings");
    }
    server_text_frame(&info.to_string())
}

#[derive(Debug)]
enum HeadError {
    Io,
    TooLong,
}

/// Read up to the end of an HTTP head (`\r\n\r\n`): the head, and what came after it.
async fn read_head<R: AsyncRead + Unpin>(
    r: &mut R,
    max: usize,
) -> Result<(Vec<u8>, Vec<u8>), HeadError> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            return Ok((buf, rest));
        }
        if buf.len() > max {
            return Err(HeadError::TooLong);
        }
        let n = r.read(&mut chunk).await.map_err(|_| HeadError::Io)?;
        if n == 0 {
            return Err(HeadError::Io);
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// A GET request head: target and headers (`None` if it is not one).
fn parse_head(head: &[u8]) -> Option<UpgradeRequest> {
    let text = std::str::from_utf8(head).ok()?;
    let mut lines = text.split("\r\n");
    let mut first = lines.next()?.split(' ');
    let (method, target, version) = (first.next()?, first.next()?, first.next()?);
    if method != "GET" || !version.starts_with("HTTP/1.") {
        return None;
    }
    let mut headers = Vec::new();
    for line in lines.filter(|l| !l.is_empty()) {
        let (name, value) = line.split_once(':')?;
        headers.push((name.trim().to_ascii_lowercase(), value.trim().to_string()));
    }
    Some(UpgradeRequest {
        peer: None,
        target: target.to_string(),
        headers,
    })
}

/// A plain HTTP answer that ends the connection.
async fn answer<W: AsyncWrite + Unpin>(
    w: &mut W,
    status: u16,
    reason: &str,
) -> std::io::Result<()> {
    let phrase = match status {
        400 => "Bad Request",
        401 => "Unauthorized",
        403 => "Forbidden",
        408 => "Request Timeout",
        431 => "Request Header Fields Too Large",
        503 => "Service Unavailable",
        _ => "Error",
    };
    let body = format!("{status}: {reason}\n");
    let text = format!(
        "HTTP/1.1 {status} {phrase}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\nConnection: close\r\nCache-Control: no-store\r\n\r\n{body}",
        body.len()
    );
    w.write_all(text.as_bytes()).await?;
    w.shutdown().await
}

/// One whole WebSocket frame (server to client, unmasked: the serverInfo).
struct Frame {
    opcode: u8,
    payload: Vec<u8>,
    raw: Vec<u8>,
}

/// Read one frame from `r`, `buf` holding what was read already; the frame and the bytes
/// read past it.
async fn read_frame<R: AsyncRead + Unpin>(
    r: &mut R,
    buf: &mut Vec<u8>,
) -> std::io::Result<(Frame, Vec<u8>)> {
    let mut chunk = [0u8; 4096];
    loop {
        if let Some(h) = FrameHeader::parse(buf) {
            let total = h.header_len + usize::try_from(h.payload_len).unwrap_or(usize::MAX);
            if h.payload_len > 16 * 1024 * 1024 {
                return Err(std::io::Error::other("serverInfo too large"));
            }
            if buf.len() >= total {
                let rest = buf.split_off(total);
                let raw = std::mem::take(buf);
                let payload = raw[h.header_len..].to_vec();
                return Ok((
                    Frame {
                        opcode: h.opcode,
                        payload,
                        raw,
                    },
                    rest,
                ));
            }
        }
        let n = r.read(&mut chunk).await?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// A frame header (RFC 6455 5.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct FrameHeader {
    fin: bool,
    opcode: u8,
    header_len: usize,
    payload_len: u64,
}

impl FrameHeader {
    /// The header at the start of `b`, if complete.
    fn parse(b: &[u8]) -> Option<FrameHeader> {
        let (b0, b1) = (*b.first()?, *b.get(1)?);
        let masked = b1 & 0x80 != 0;
        let (len, mut at) = match b1 & 0x7f {
            126 => (u64::from(u16::from_be_bytes([*b.get(2)?, *b.get(3)?])), 4),
            127 => {
                let bytes: [u8; 8] = b.get(2..10)?.try_into().ok()?;
                (u64::from_be_bytes(bytes), 10)
            }
            n => (u64::from(n), 2),
        };
        if masked {
            at += 4;
        }
        (b.len() >= at).then_some(FrameHeader {
            fin: b0 & 0x80 != 0,
            opcode: b0 & 0x0f,
            header_len: at,
            payload_len: len,
        })
    }
}

/// A client's message went over the limit.
#[derive(Debug, PartialEq, Eq)]
pub(crate) struct Oversized;

/// Copies a client's frames on, checking each header before its payload: a message (all
/// its fragments) over the limit stops the copy before its payload is read.
pub(crate) struct FrameChecker {
    limit: u64,
    /// bytes of the current frame's payload still to copy
    remaining: u64,
    /// the size of the message so far (fragments)
    message: u64,
}

impl FrameChecker {
    pub(crate) fn new(limit: u64) -> FrameChecker {
        FrameChecker {
            limit,
            remaining: 0,
            message: 0,
        }
    }

    /// Take `buf`: the bytes to pass on now (the rest stays in `buf` until more come).
    pub(crate) fn feed(&mut self, buf: &mut Vec<u8>) -> Result<Vec<u8>, Oversized> {
        let mut out = Vec::with_capacity(buf.len());
        let mut at = 0;
        while at < buf.len() {
            if self.remaining > 0 {
                let n = usize::try_from(self.remaining)
                    .unwrap_or(usize::MAX)
                    .min(buf.len() - at);
                out.extend_from_slice(&buf[at..at + n]);
                at += n;
                self.remaining -= n as u64;
                continue;
            }
            let Some(h) = FrameHeader::parse(&buf[at..]) else {
                break; // an incomplete header: wait for more
            };
            if h.opcode < 8 {
                // data: a new message (1, 2) or a fragment of the current one (0)
                if h.opcode != 0 {
                    self.message = 0;
                }
                self.message = self.message.saturating_add(h.payload_len);
                if self.message > self.limit {
                    return Err(Oversized);
                }
                if h.fin {
                    self.message = 0;
                }
            } else if h.payload_len > 125 {
                return Err(Oversized); // control frames are at most 125 bytes
            }
            out.extend_from_slice(&buf[at..at + h.header_len]);
            at += h.header_len;
            self.remaining = h.payload_len;
        }
        buf.drain(..at);
        Ok(out)
    }

    /// Copy from `from` to `to` until either ends; `early` = bytes read already.
    async fn pump<R: AsyncRead + Unpin, W: AsyncWrite + Unpin>(
        &mut self,
        early: Vec<u8>,
        from: &mut R,
        to: &mut W,
    ) -> Result<(), Oversized> {
        let mut buf = early;
        let mut chunk = vec![0u8; 16 * 1024];
        loop {
            let out = self.feed(&mut buf)?;
            if !out.is_empty() && to.write_all(&out).await.is_err() {
                return Ok(());
            }
            match from.read(&mut chunk).await {
                Ok(0) | Err(_) => return Ok(()),
                Ok(n) => buf.extend_from_slice(&chunk[..n]),
            }
        }
    }
}

fn frame_header(opcode: u8, len: usize, masked: bool) -> Vec<u8> {
    let mask_bit = if masked { 0x80 } else { 0 };
    let mut out = vec![0x80 | opcode];
    if len < 126 {
        out.push(mask_bit | len as u8);
    } else if let Ok(l) = u16::try_from(len) {
        out.push(mask_bit | 126);
        out.extend_from_slice(&l.to_be_bytes());
    } else {
        out.push(mask_bit | 127);
        out.extend_from_slice(&(len as u64).to_be_bytes());
    }
    out
}

/// A text frame from the server (unmasked).
fn server_text_frame(text: &str) -> Vec<u8> {
    let mut out = frame_header(1, text.len(), false);
    out.extend_from_slice(text.as_bytes());
    out
}

/// A text frame from a client (masked, as RFC 6455 requires; the key need not be secret
/// between the front and the SDK on loopback).
fn masked_text_frame(text: &str) -> Vec<u8> {
    let key = [0x5a, 0x17, 0xc3, 0x81];
    let mut out = frame_header(1, text.len(), true);
    out.extend_from_slice(&key);
    out.extend(text.bytes().enumerate().map(|(i, b)| b ^ key[i % 4]));
    out
}

/// A close frame from the server with `code` and `reason`.
pub(crate) fn close_frame(code: u16, reason: &str) -> Vec<u8> {
    let mut payload = code.to_be_bytes().to_vec();
    payload.extend_from_slice(&reason.as_bytes()[..reason.len().min(120)]);
    let mut out = frame_header(8, payload.len(), false);
    out.extend_from_slice(&payload);
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn client_frame(opcode: u8, fin: bool, len: usize) -> Vec<u8> {
        let mut f = frame_header(opcode, len, true);
        if !fin {
            f[0] &= 0x7f;
        }
        f.extend_from_slice(&[1, 2, 3, 4]);
        f.extend(std::iter::repeat_n(0u8, len));
        f
    }

    #[test]
    fn frames_within_the_limit_pass_whole_in_any_chunking() {
        let mut all = client_frame(1, true, 10);
        all.extend(client_frame(2, true, 300));
        all.extend(client_frame(2, false, 70_000));
        all.extend(client_frame(9, true, 4));
        all.extend(client_frame(0, true, 20_000));
        for chunk in [1, 3, 7, 1000, all.len()] {
            let mut checker = FrameChecker::new(100_000);
            let (mut buf, mut out) = (Vec::new(), Vec::new());
            for piece in all.chunks(chunk) {
                buf.extend_from_slice(piece);
                out.extend(checker.feed(&mut buf).unwrap());
            }
            assert_eq!(out, all, "chunk {chunk}");
        }
    }

    #[test]
    fn a_message_over_the_limit_is_stopped_at_its_header() {
        // the 10 MiB message of the probe: refused on its first 14 bytes
        let mut buf = frame_header(2, 10 * 1024 * 1024, true);
        buf.extend_from_slice(&[0; 4]);
        assert_eq!(FrameChecker::new(1 << 20).feed(&mut buf), Err(Oversized));
        // fragments add up
        let mut c = FrameChecker::new(100);
        let mut b = client_frame(1, false, 60);
        assert!(c.feed(&mut b).is_ok());
        let mut b = client_frame(0, true, 60);
        assert_eq!(c.feed(&mut b), Err(Oversized));
        // an oversized control frame is a protocol violation
        let mut b = frame_header(9, 200, true);
        b.extend_from_slice(&[0; 4]);
        assert_eq!(FrameChecker::new(1000).feed(&mut b), Err(Oversized));
    }

    #[test]
    fn a_head_is_parsed_and_its_query_found() {
        let r = parse_head(b"GET /?token=abc HTTP/1.1\r\nHost: 127.0.0.1:8765\r\nOrigin: http://evil.example\r\n\r\n").unwrap();
        assert_eq!(r.query(), Some("token=abc"));
        assert_eq!(r.header("host"), Some("127.0.0.1:8765"));
        assert_eq!(r.header("origin"), Some("http://evil.example"));
        assert!(parse_head(b"POST / HTTP/1.1\r\n\r\n").is_none());
        assert!(parse_head(b"\x16\x03\x01").is_none());
    }

    #[test]
    fn server_info_loses_client_publish_for_a_watcher() {
        let info = r#"{"op":"serverInfo","capabilities":["clientPublish","time"],"supportedEncodings":["cdr"]}"#;
        let raw = server_text_frame(info);
        let mut buf = raw.clone();
        let h = FrameHeader::parse(&buf).unwrap();
        let frame = Frame {
            opcode: h.opcode,
            payload: buf.split_off(h.header_len),
            raw,
        };
        let watcher = server_info_for(&frame, false);
        let text = String::from_utf8_lossy(&watcher[2..]).to_string();
        assert!(
            !text.contains("clientPublish") && text.contains("time"),
            "{text}"
        );
        assert_eq!(server_info_for(&frame, true), frame.raw);
    }
}
