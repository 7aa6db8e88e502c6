//! The web server's lingering close: a connection dropped while its client is still
//! sending delivers what the server wrote last, then closes without a reset.
#![allow(clippy::unwrap_used)]

use axum::serve::Listener as _;
use gui_bridge::linger::LingeringListener;
use std::io::{Read as _, Write as _};
use std::time::Duration;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};

/// More than the kernel's send and receive buffers together can hold, so most of it is
/// still unsent when the server drops the connection.
const SENT: usize = 32 << 20;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_connection_dropped_mid_upload_says_its_last_words_and_closes_cleanly() {
    let tcp = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let mut listener = LingeringListener::new(tcp, Duration::from_secs(10));
    let at = listener.local_addr().unwrap();
    let client = std::thread::spawn(move || {
        let mut s = std::net::TcpStream::connect(at).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        let mut w = s.try_clone().unwrap();
        let upload = std::thread::spawn(move || w.write_all(&vec![0x5a; SENT]));
        let mut got = Vec::new();
        let read = s.read_to_end(&mut got);
        (upload.join().unwrap(), read, got)
    });
    // like a WebSocket refusing an oversized message: read the start, answer, drop
    let (mut conn, _) = listener.accept().await;
    let mut head = [0u8; 100];
    conn.read_exact(&mut head).await.unwrap();
    conn.write_all(b"1009 message too big").await.unwrap();
    conn.flush().await.unwrap();
    drop(conn);
    let (upload, read, got) = tokio::task::spawn_blocking(move || client.join().unwrap())
        .await
        .unwrap();
    assert!(upload.is_ok(), "the client's upload failed: {upload:?}");
    assert!(read.is_ok(), "the client's read failed: {read:?}");
    assert_eq!(got, b"1009 message too big");
}

#[tokio::test]
async fn a_lingering_connection_gives_up_on_a_client_that_never_closes() {
    let tcp = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let mut listener = LingeringListener::new(tcp, Duration::from_millis(200));
    let at = listener.local_addr().unwrap();
    let mut client = tokio::net::TcpStream::connect(at).await.unwrap();
    let (conn, _) = listener.accept().await;
    drop(conn);
    // the server's FIN comes at once; the socket itself closes after the linger time
    let mut buf = [0u8; 16];
    assert_eq!(client.read(&mut buf).await.unwrap(), 0);
    let start = std::time::Instant::now();
    loop {
        // still open: writes are accepted; once closed, the server resets
        if client.write_all(b"still here").await.is_err() {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "the server never closed"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test]
async fn a_connection_that_sends_no_complete_head_in_time_is_dropped() {
    let tcp = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let mut listener = LingeringListener::new(tcp, Duration::from_millis(100))
        .with_head_timeout(Duration::from_millis(300));
    let at = listener.local_addr().unwrap();
    // half a head: the read fails with TimedOut when the time is up
    let mut slow = tokio::net::TcpStream::connect(at).await.unwrap();
    slow.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n")
        .await
        .unwrap();
    let (mut conn, _) = listener.accept().await;
    let mut buf = vec![0u8; 1024];
    let mut got = 0;
    let err = loop {
        match tokio::time::timeout(Duration::from_secs(10), conn.read(&mut buf[got..])).await {
            Ok(Ok(n)) => got += n,
            Ok(Err(e)) => break e,
            Err(_) => panic!("no timeout: the read waited on"),
        }
    };
    assert_eq!(err.kind(), std::io::ErrorKind::TimedOut);
    // a whole head in time: reads go on after the deadline (the body, a WebSocket)
    let mut quick = tokio::net::TcpStream::connect(at).await.unwrap();
    quick
        .write_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        .await
        .unwrap();
    let (mut conn, _) = listener.accept().await;
    let mut head = [0u8; 27];
    conn.read_exact(&mut head).await.unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    quick.write_all(b"frames").await.unwrap();
    let mut more = [0u8; 6];
    conn.read_exact(&mut more).await.unwrap();
    assert_eq!(&more, b"frames");
}
