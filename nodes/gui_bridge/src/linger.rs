//! The web server's TCP connections, closed the way HTTP servers close them (a
//! "lingering close", as Apache and nginx do).
//!
//! The server may drop a connection while its client is still sending: a WebSocket
//! message over the size limit is refused after its frame header, with a close frame
//! (code 1009 and the reason). A socket closed with unread data in it makes the kernel
//! answer with a reset, which throws away what the client has not read yet, the close
//! frame included: the client's send fails (`EPIPE`) and a browser reports 1006
//! (abnormal closure) instead of the reason. So a dropped connection first sends its
//! FIN after everything written, then reads and discards what still arrives until
//! the client closes its side, for at most [`LINGER`]; only then is the socket closed.
//!
//! With [`LingeringListener::with_head_timeout`] a connection must also send its first
//! request head (up to the blank line) within that time, or its reads fail with
//! `TimedOut` and the server drops it: a client that opens connections and sends
//! nothing (or a byte a minute) holds no connection for long, and it has not been
//! authenticated yet (hyper has no such timeout unless given a timer, and axum's
//! `serve` gives none). Over TLS the head is read from the decrypted stream:
//! [`HeadTimed`] around the TLS stream does the same there.

use axum::serve::Listener;
use std::future::Future as _;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt as _, AsyncWrite, AsyncWriteExt as _, ReadBuf};
use tokio::net::{TcpListener, TcpStream};

/// How long a dropped connection keeps reading what its client still sends. A 1 MB
/// message takes 0.4 s at 20 Mbit/s (a slow Wi-Fi link); a client still sending after
/// this is reset.
pub const LINGER: Duration = Duration::from_secs(2);

/// How long a web client has to send its first request head.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(10);

/// A TCP listener whose connections close with a lingering close.
pub struct LingeringListener {
    tcp: TcpListener,
    linger: Duration,
    head_timeout: Option<Duration>,
}

impl LingeringListener {
    /// Serve the connections of `tcp`; each dropped one reads for at most `linger`.
    pub fn new(tcp: TcpListener, linger: Duration) -> Self {
        LingeringListener {
            tcp,
            linger,
            head_timeout: None,
        }
    }

    /// Each connection must send its first request head within `timeout`.
    pub fn with_head_timeout(mut self, timeout: Duration) -> Self {
        self.head_timeout = Some(timeout);
        self
    }
}

/// The first request head of a connection, until its blank line arrives.
struct HeadDeadline {
    sleep: Pin<Box<tokio::time::Sleep>>,
    timeout: Duration,
    /// how much of `\r\n\r\n` the bytes so far end with
    matched: usize,
}

impl HeadDeadline {
    fn new(timeout: Duration) -> HeadDeadline {
        HeadDeadline {
            sleep: Box::pin(tokio::time::sleep(timeout)),
            timeout,
            matched: 0,
        }
    }

    /// Take in bytes read; true once the head is complete.
    fn complete_after(&mut self, bytes: &[u8]) -> bool {
        const END: &[u8] = b"\r\n\r\n";
        for &b in bytes {
            self.matched = if b == END[self.matched] {
                self.matched + 1
            } else if b == b'\r' {
                1
            } else {
                0
            };
            if self.matched == END.len() {
                return true;
            }
        }
        false
    }
}

impl Listener for LingeringListener {
    type Io = LingeringStream;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        let (tcp, from) = Listener::accept(&mut self.tcp).await;
        let stream = LingeringStream {
            tcp: Some(tcp),
            linger: self.linger,
            head: self.head_timeout.map(HeadDeadline::new),
        };
        (stream, from)
    }

    fn local_addr(&self) -> io::Result<Self::Addr> {
        self.tcp.local_addr()
    }
}

/// One accepted connection: a [`TcpStream`] that lingers when dropped.
pub struct LingeringStream {
    /// `None` only inside `drop`.
    tcp: Option<TcpStream>,
    linger: Duration,
    /// the first request head is still to come by this deadline
    head: Option<HeadDeadline>,
}

impl LingeringStream {
    /// The stream; gone only inside `drop`, where nothing polls it any more.
    fn tcp(&mut self) -> io::Result<Pin<&mut TcpStream>> {
        self.tcp
            .as_mut()
            .map(Pin::new)
            .ok_or_else(|| io::ErrorKind::NotConnected.into())
    }

    /// Send small writes at once (the panel's 50 Hz state messages; no Nagle delay).
    pub fn set_nodelay(&mut self) {
        if let Some(tcp) = &self.tcp {
            if let Err(e) = tcp.set_nodelay(true) {
                log::debug!("TCP_NODELAY not set: {e}");
            }
        }
    }
}

impl AsyncRead for LingeringStream {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let tcp = this.tcp.as_mut().ok_or(io::ErrorKind::NotConnected)?;
        read_before(&mut this.head, Pin::new(tcp), cx, buf)
    }
}

/// Read from `inner`, failing with `TimedOut` once `head`'s deadline passes before the
/// end of the first request head (then `head` is `None`: no deadline any more).
fn read_before<R: AsyncRead + ?Sized>(
    head: &mut Option<HeadDeadline>,
    inner: Pin<&mut R>,
    cx: &mut Context<'_>,
    buf: &mut ReadBuf<'_>,
) -> Poll<io::Result<()>> {
    if let Some(h) = head.as_mut() {
        if h.sleep.as_mut().poll(cx).is_ready() {
            let why = format!(
                "no complete request head within {:.0} s",
                h.timeout.as_secs_f64()
            );
            return Poll::Ready(Err(io::Error::new(io::ErrorKind::TimedOut, why)));
        }
    }
    let before = buf.filled().len();
    let read = inner.poll_read(cx, buf);
    if let (Poll::Ready(Ok(())), Some(h)) = (&read, head.as_mut()) {
        if h.complete_after(&buf.filled()[before..]) {
            *head = None;
        }
    }
    read
}

/// A stream (a TLS stream over a [`LingeringStream`]) whose first request head must
/// arrive within a time, as [`LingeringListener::with_head_timeout`] asks of a plain one.
pub struct HeadTimed<S> {
    inner: S,
    head: Option<HeadDeadline>,
}

impl<S> HeadTimed<S> {
    /// `inner`, whose reads fail with `TimedOut` if no complete request head came within
    /// `timeout` from now.
    pub fn new(inner: S, timeout: Duration) -> Self {
        HeadTimed {
            inner,
            head: Some(HeadDeadline::new(timeout)),
        }
    }

    /// The stream inside.
    pub fn get_mut(&mut self) -> &mut S {
        &mut self.inner
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for HeadTimed<S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        read_before(&mut this.head, Pin::new(&mut this.inner), cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for HeadTimed<S> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.get_mut().inner).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.get_mut().inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_shutdown(cx)
    }
}

impl AsyncWrite for LingeringStream {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        self.get_mut().tcp()?.poll_write(cx, buf)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        self.get_mut().tcp()?.poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.tcp.as_ref().is_some_and(|t| t.is_write_vectored())
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.get_mut().tcp()?.poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.get_mut().tcp()?.poll_shutdown(cx)
    }
}

impl Drop for LingeringStream {
    fn drop(&mut self) {
        let Some(tcp) = self.tcp.take() else { return };
        // outside a runtime (the server is gone): the socket just closes
        if let Ok(runtime) = tokio::runtime::Handle::try_current() {
            runtime.spawn(linger(tcp, self.linger));
        }
    }
}

/// Send FIN after what is queued, then read and discard until the peer's FIN, an
/// error or `within`; the socket closes when this returns.
async fn linger(mut tcp: TcpStream, within: Duration) {
    // fails harmlessly when hyper has shut the write side already
    let _ = tcp.shutdown().await;
    let mut sink = [0u8; 16 * 1024];
    let _ = tokio::time::timeout(within, async {
        while let Ok(n) = tcp.read(&mut sink).await {
            if n == 0 {
                break;
            }
        }
    })
    .await;
}
