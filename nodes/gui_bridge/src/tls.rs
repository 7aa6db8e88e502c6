//! HTTPS and WSS for the web panel and its Foxglove server beyond loopback.
//!
//! The token that opens the panel crosses the network with every connection (in the
//! WebSocket's subprotocol, an `Authorization` header, or `?token=`). Over plain HTTP
//! anyone on the same Wi-Fi reads it, so a listener beyond loopback (`bind` or
//! `foxglove_bind`) speaks TLS with the certificate `tls_cert` and its key `tls_key`
//! (the operator's own, or one of launch_scripts/panel_certs.sh), or the node refuses
//! to start ([`choose`]) unless `insecure_http` says that the token may travel in the
//! clear. A loopback-only node stays plain HTTP, as before.
//!
//! The handshakes run in tasks of their own, at most [`MAX_HANDSHAKES`] at once and
//! each for at most [`HANDSHAKE_TIMEOUT`], so a client that connects and sends nothing
//! (or a byte a minute) holds up no other client's accept ([`TlsListener`]). rustls with
//! the *ring* provider, TLS 1.2 and 1.3, ALPN `http/1.1`.

use crate::linger::{HeadTimed, LingeringListener, LingeringStream};
use axum::serve::Listener;
use ros_plumbing::security::CertificateExpiry;
use rustls::pki_types::pem::PemObject as _;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use std::collections::HashSet;
use std::io;
use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::{mpsc, Semaphore};
use tokio_rustls::server::TlsStream;
use tokio_rustls::TlsAcceptor;

/// How long a client has for its TLS handshake.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// Handshakes under way at once; a connection beyond them is closed at once.
pub const MAX_HANDSHAKES: usize = 64;

/// What a node's listeners speak, from its parameters ([`choose`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Transport {
    /// Plain HTTP and WS, every listener on loopback.
    Plain,
    /// Plain HTTP and WS beyond loopback: `insecure_http` (a warning at start and in
    /// every `diagnostics` report).
    Insecure {
        /// The listeners beyond loopback (`bind 0.0.0.0:8080`).
        beyond: Vec<String>,
    },
    /// HTTPS and WSS on every listener with this certificate and key.
    Tls {
        /// `tls_cert`: the certificate (chain), PEM.
        cert: PathBuf,
        /// `tls_key`: its private key, PEM (PKCS#8, SEC1 or PKCS#1).
        key: PathBuf,
    },
}

impl Transport {
    /// The URL scheme of the panel: `https` or `http`.
    pub fn scheme(&self) -> &'static str {
        match self {
            Transport::Tls { .. } => "https",
            _ => "http",
        }
    }

    /// The standing warning of [`Transport::Insecure`], for the start and `diagnostics`.
    pub fn warning(&self) -> Option<String> {
        match self {
            Transport::Insecure { beyond } => Some(format!(
                "plain HTTP beyond loopback ({}; insecure_http:=true): the access token travels in the clear, anyone on that network can read it and move the arm; give tls_cert and tls_key (launch_scripts/panel_certs.sh)",
                beyond.join(", ")
            )),
            _ => None,
        }
    }
}

/// Why the node does not start: what the operator must change.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TlsError {
    /// A listener beyond loopback, and neither TLS nor `insecure_http`.
    #[error("{} beyond loopback would send the access token in the clear: give tls_cert and tls_key (a certificate for this host's names and addresses; launch_scripts/panel_certs.sh DIR HOST... makes one), or set insecure_http:=true to serve plain HTTP anyway (the token then travels in the clear); README: The panel on a phone or tablet", .beyond.join(" and "))]
    NeedsTls {
        /// The listeners beyond loopback (`bind 0.0.0.0:8080`).
        beyond: Vec<String>,
    },
    /// One of `tls_cert` and `tls_key` without the other.
    #[error("{given} is set but {missing} is empty: HTTPS needs both the certificate and its key")]
    HalfPair {
        /// The parameter given.
        given: &'static str,
        /// The one missing.
        missing: &'static str,
    },
    /// A file that cannot be read or holds nothing usable.
    #[error("{param} {path}: {why}")]
    File {
        /// `tls_cert` or `tls_key`
        param: &'static str,
        /// the file
        path: PathBuf,
        /// what is wrong
        why: String,
    },
    /// rustls refused the pair (the key is not the certificate's, or a kind it cannot use).
    #[error("tls_cert {cert} with tls_key {key}: {why}")]
    Pair {
        /// the certificate file
        cert: PathBuf,
        /// the key file
        key: PathBuf,
        /// rustls's reason
        why: String,
    },
}

/// What the listeners speak. `beyond` names the listeners beyond loopback (empty: all on
/// loopback); `cert` and `key` are the parameters `tls_cert` and `tls_key` (empty = not
/// given), `insecure` is `insecure_http`. A certificate given is used on every listener,
/// loopback ones too.
///
/// # Examples
/// ```
/// use gui_bridge::tls::{choose, Transport};
/// assert_eq!(choose(&[], "", "", false).unwrap(), Transport::Plain);
/// let lan = ["bind 0.0.0.0:8080".to_string()];
/// assert!(choose(&lan, "", "", false).is_err());
/// assert!(matches!(choose(&lan, "", "", true).unwrap(), Transport::Insecure { .. }));
/// assert!(matches!(choose(&lan, "c.pem", "k.pem", false).unwrap(), Transport::Tls { .. }));
/// assert!(choose(&lan, "c.pem", "", false).is_err());
/// ```
pub fn choose(
    beyond: &[String],
    cert: &str,
    key: &str,
    insecure: bool,
) -> Result<Transport, TlsError> {
    let (cert, key) = (cert.trim(), key.trim());
    match (cert.is_empty(), key.is_empty()) {
        (false, false) => Ok(Transport::Tls {
            cert: cert.into(),
            key: key.into(),
        }),
        (false, true) => Err(TlsError::HalfPair {
            given: "tls_cert",
            missing: "tls_key",
        }),
        (true, false) => Err(TlsError::HalfPair {
            given: "tls_key",
            missing: "tls_cert",
        }),
        (true, true) if beyond.is_empty() => Ok(Transport::Plain),
        (true, true) if insecure => Ok(Transport::Insecure {
            beyond: beyond.to_vec(),
        }),
        (true, true) => Err(TlsError::NeedsTls {
            beyond: beyond.to_vec(),
        }),
    }
}

/// A loaded certificate and key: the server configuration both listeners use, and when
/// the certificate runs out (for `diagnostics`).
#[derive(Clone)]
pub struct TlsSetup {
    /// rustls's server configuration (ring, TLS 1.2/1.3, ALPN http/1.1).
    pub config: Arc<rustls::ServerConfig>,
    /// The earliest `notAfter` in `tls_cert` (`None` if unreadable by OpenSSL: logged).
    pub expiry: Option<CertificateExpiry>,
}

impl std::fmt::Debug for TlsSetup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TlsSetup")
            .field("expiry", &self.expiry)
            .finish_non_exhaustive()
    }
}

/// Read the certificate chain `cert` and its key `key` (PEM) into a server configuration.
pub fn load(cert: &Path, key: &Path) -> Result<TlsSetup, TlsError> {
    let file = |param, path: &Path, why: String| TlsError::File {
        param,
        path: path.to_path_buf(),
        why,
    };
    let why = |e: rustls::pki_types::pem::Error| match e {
        rustls::pki_types::pem::Error::Io(e) if e.kind() == io::ErrorKind::NotFound => {
            "no such file".to_string()
        }
        rustls::pki_types::pem::Error::Io(e) if e.kind() == io::ErrorKind::PermissionDenied => {
            "permission denied (it must be readable by the user gui_bridge runs as)".to_string()
        }
        e => e.to_string(),
    };
    let chain = CertificateDer::pem_file_iter(cert)
        .and_then(|certs| certs.collect::<Result<Vec<_>, _>>())
        .map_err(|e| file("tls_cert", cert, why(e)))?;
    if chain.is_empty() {
        return Err(file(
            "tls_cert",
            cert,
            "no PEM certificate in it (-----BEGIN CERTIFICATE-----)".into(),
        ));
    }
    let private = PrivateKeyDer::from_pem_file(key).map_err(|e| match e {
        rustls::pki_types::pem::Error::NoItemsFound => file(
            "tls_key",
            key,
            "no PEM private key in it (-----BEGIN PRIVATE KEY-----, EC or RSA)".into(),
        ),
        e => file("tls_key", key, why(e)),
    })?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let pair = |e: rustls::Error| TlsError::Pair {
        cert: cert.to_path_buf(),
        key: key.to_path_buf(),
        why: e.to_string(),
    };
    let mut config = rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(pair)?
        .with_no_client_auth()
        .with_single_cert(chain, private)
        .map_err(pair)?;
    config.alpn_protocols = vec![b"http/1.1".to_vec()];
    let expiry = match CertificateExpiry::of_pem_chain(cert) {
        Ok(e) => Some(e),
        Err(e) => {
            log::warn!("the expiry of tls_cert cannot be read: {e}");
            None
        }
    };
    Ok(TlsSetup {
        config: Arc::new(config),
        expiry,
    })
}

/// One accepted HTTPS connection: TLS over a lingering TCP stream, its first request
/// head due within the head timeout (counted from the end of the handshake).
pub type TlsIo = HeadTimed<TlsStream<LingeringStream>>;

/// A listener whose connections are handed to `axum::serve` after their TLS handshake,
/// done in a task of each connection's own (see the module's documentation).
pub struct TlsListener {
    ready: mpsc::Receiver<(TlsIo, SocketAddr)>,
    local: SocketAddr,
    accepting: tokio::task::JoinHandle<()>,
}

impl Drop for TlsListener {
    fn drop(&mut self) {
        self.accepting.abort();
    }
}

impl TlsListener {
    /// Accept `tcp`'s connections (it should have no head timeout of its own: the head
    /// arrives encrypted) with `config`; each must then send its first request head
    /// within `head_timeout`.
    pub fn new(
        tcp: LingeringListener,
        config: Arc<rustls::ServerConfig>,
        head_timeout: Duration,
    ) -> io::Result<TlsListener> {
        let local = tcp.local_addr()?;
        let (tx, ready) = mpsc::channel(MAX_HANDSHAKES);
        let accepting = tokio::spawn(accept_loop(
            tcp,
            TlsAcceptor::from(config),
            tx,
            head_timeout,
        ));
        Ok(TlsListener {
            ready,
            local,
            accepting,
        })
    }
}

async fn accept_loop(
    mut tcp: LingeringListener,
    acceptor: TlsAcceptor,
    ready: mpsc::Sender<(TlsIo, SocketAddr)>,
    head_timeout: Duration,
) {
    let pending = Arc::new(Semaphore::new(MAX_HANDSHAKES));
    let failures = Arc::new(FirstFailures::default());
    loop {
        let (mut stream, from) = Listener::accept(&mut tcp).await;
        let Ok(permit) = pending.clone().try_acquire_owned() else {
            log::debug!("{from}: {MAX_HANDSHAKES} TLS handshakes under way already: closed");
            continue;
        };
        stream.set_nodelay();
        let (acceptor, ready, failures) = (acceptor.clone(), ready.clone(), failures.clone());
        tokio::spawn(async move {
            let shaken = tokio::time::timeout(HANDSHAKE_TIMEOUT, acceptor.accept(stream)).await;
            drop(permit);
            match shaken {
                Ok(Ok(tls)) => {
                    let _ = ready.send((HeadTimed::new(tls, head_timeout), from)).await;
                }
                Ok(Err(e)) => failures.log(from.ip(), &e.to_string()),
                Err(_) => log::debug!(
                    "{from}: no TLS handshake within {:.0} s: closed",
                    HANDSHAKE_TIMEOUT.as_secs_f64()
                ),
            }
        });
    }
}

/// The addresses whose failed handshake was logged already: the first failure of each
/// is logged (a browser that does not trust the certificate retries on every reload),
/// the others only at debug level; past 1024 addresses, only at debug level.
#[derive(Default)]
struct FirstFailures(Mutex<HashSet<IpAddr>>);

impl FirstFailures {
    fn log(&self, ip: IpAddr, why: &str) {
        let first = self
            .0
            .lock()
            .map(|mut seen| seen.len() < 1024 && seen.insert(ip))
            .unwrap_or(false);
        if first {
            log::warn!(
                "TLS handshake with {ip} failed: {why} (a browser that does not trust the panel's certificate ends it so: README: The panel on a phone or tablet; further failures of this address are logged at debug level)"
            );
        } else {
            log::debug!("TLS handshake with {ip} failed: {why}");
        }
    }
}

impl Listener for TlsListener {
    type Io = TlsIo;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        match self.ready.recv().await {
            Some(connection) => connection,
            // the accepting task ended (it never does by itself): serve nothing more
            None => std::future::pending().await,
        }
    }

    fn local_addr(&self) -> io::Result<Self::Addr> {
        Ok(self.local)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_refusal_names_every_listener_and_the_two_ways_out() {
        let beyond = vec![
            "bind 0.0.0.0:8080".to_string(),
            "foxglove_bind 0.0.0.0:8765".to_string(),
        ];
        let e = choose(&beyond, "", " ", false).unwrap_err().to_string();
        for part in [
            "bind 0.0.0.0:8080 and foxglove_bind 0.0.0.0:8765",
            "tls_cert and tls_key",
            "panel_certs.sh",
            "insecure_http:=true",
            "in the clear",
        ] {
            assert!(e.contains(part), "{part}: {e}");
        }
        let warning = choose(&beyond, "", "", true).unwrap().warning().unwrap();
        assert!(
            warning.contains("in the clear") && warning.contains("0.0.0.0:8765"),
            "{warning}"
        );
        assert_eq!(choose(&[], "", "", true).unwrap(), Transport::Plain);
        assert_eq!(Transport::Plain.warning(), None);
    }

    #[test]
    fn missing_or_wrong_files_are_named() {
        let dir = std::env::temp_dir().join(format!("gui_bridge_tls_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cert = dir.join("cert.pem");
        std::fs::write(&cert, "not a certificate\n").unwrap();
        let e = load(&dir.join("none.pem"), &dir.join("none.key")).unwrap_err();
        assert!(
            e.to_string().contains("tls_cert") && e.to_string().contains("no such file"),
            "{e}"
        );
        let e = load(&cert, &dir.join("none.key")).unwrap_err();
        assert!(e.to_string().contains("no PEM certificate"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
