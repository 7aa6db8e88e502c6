//! What the WAN router (`eezybot_wan_router`) and bridge (`eezybot_wan_bridge`) share:
//! which topics cross and in which direction ([`Side`]), the TLS files of
//! `launch_scripts/wan_certs.sh` ([`TlsFiles`]), the endpoint check and the exit status
//! of a configuration error ([`fail`]); and the bridge's SROS2 enclave ([`sros2`]).

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use rustls::pki_types::{CertificateDer, UnixTime};
use zenoh::config::Config;

pub mod acl;
pub mod cdr;
mod crossing;
pub mod expiry;
pub mod health;
pub mod refusals;
pub use crossing::{Crossing, Side, CROSSING};
pub mod sros2;

/// Exit status for a configuration error: a missing or unusable TLS file, a bad
/// endpoint, a bad argument.
pub const CONFIG_ERROR: i32 = 2;

/// Print `error: MESSAGE` on stderr and exit with [`CONFIG_ERROR`].
pub fn fail(program: &str, message: impl fmt::Display) -> ! {
    eprintln!("{program}: error: {message}");
    std::process::exit(CONFIG_ERROR)
}

/// A ROS namespace as given with `-r __ns:=/arm2`: `/` or `/a/b`, no trailing slash.
pub fn check_namespace(ns: &str) -> Result<String, String> {
    let trimmed = ns.trim_end_matches('/');
    let ok = ns.starts_with('/')
        && trimmed.split('/').skip(1).all(|part| {
            !part.is_empty()
                && part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !part.starts_with(|c: char| c.is_ascii_digit())
        });
    if ok {
        Ok(trimmed.to_string())
    } else {
        Err(format!(
            "bad ROS namespace `{ns}`: / or /name[/name…], names of letters, digits and _"
        ))
    }
}

/// The plugin's allow-list entry for `topic` in namespace `ns` (from [`check_namespace`]):
/// a regular expression matching exactly the full topic name.
pub fn topic_regex(ns: &str, topic: &str) -> String {
    format!("{ns}/{topic}")
}

/// A Zenoh endpoint the router listens on or a bridge connects to: `tls/HOST:PORT` or
/// `tcp/HOST:PORT` (plain, unauthenticated: for tests only).
#[derive(Clone, Debug)]
pub struct Endpoint {
    /// As given, for Zenoh's configuration.
    pub text: String,
    /// `tls` or `tcp`.
    pub tls: bool,
}

/// Check an endpoint ([`Endpoint`]); `what` names it in the error (`ZENOH_ROUTER`).
pub fn check_endpoint(what: &str, text: &str) -> Result<Endpoint, String> {
    let bad = |why: &str| {
        format!("{what}=`{text}` is not an endpoint tls/HOST:PORT (or tcp/HOST:PORT): {why}")
    };
    let (proto, addr) = text.split_once('/').ok_or_else(|| bad("no protocol/"))?;
    let tls = match proto {
        "tls" => true,
        "tcp" => false,
        _ => return Err(bad(&format!("protocol `{proto}` is neither tls nor tcp"))),
    };
    let addr = addr.split(['?', '#']).next().unwrap_or_default();
    let (host, port) = addr.rsplit_once(':').ok_or_else(|| bad("no :PORT"))?;
    if host.is_empty() || host == "[]" {
        return Err(bad("no HOST"));
    }
    match port.parse::<u16>() {
        Ok(p) if p > 0 => {}
        _ => return Err(bad(&format!("port `{port}` is not 1…65535"))),
    }
    zenoh::config::EndPoint::from_str(text).map_err(|e| bad(&e.to_string()))?;
    Ok(Endpoint {
        text: text.to_string(),
        tls,
    })
}

/// The TLS files of one party, from `ZENOH_TLS_DIR` as `launch_scripts/wan_certs.sh`
/// writes it: `ca.pem` (the CA's certificate) and `NAME.pem` + `NAME.key` (the party's
/// certificate and private key; NAME is `router`, `pc` or `pi`).
#[derive(Clone, Debug)]
pub struct TlsFiles {
    /// The CA's certificate: the only issuer the other end may present.
    pub ca: PathBuf,
    /// Own certificate, signed by the CA.
    pub cert: PathBuf,
    /// Own private key.
    pub key: PathBuf,
}

fn read(path: &Path, what: &str) -> Result<Vec<u8>, String> {
    std::fs::read(path).map_err(|e| {
        format!(
            "{what} {}: {e} (make the files with launch_scripts/wan_certs.sh DIR HOST…)",
            path.display()
        )
    })
}

fn first_cert(path: &Path, what: &str) -> Result<CertificateDer<'static>, String> {
    let pem = read(path, what)?;
    let first = rustls_pemfile::certs(&mut pem.as_slice()).next();
    first
        .and_then(Result::ok)
        .ok_or_else(|| format!("{what} {} holds no PEM certificate", path.display()))
}

/// Whose files: the router's must be a TLS server's, a bridge's a client's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// `router.pem`: extended key usage serverAuth.
    Server,
    /// `pc.pem`, `pi.pem`: clientAuth.
    Client,
}

impl TlsFiles {
    /// The files of `name` in `dir`, checked as the other end will: readable PEM, the
    /// certificate signed by the CA of `ca.pem`, valid now and for `role`, the key the
    /// certificate's.
    pub fn load(dir: &str, name: &str, role: Role) -> Result<TlsFiles, String> {
        let dir = Path::new(dir);
        if !dir.is_dir() {
            return Err(format!(
                "ZENOH_TLS_DIR={} is not a directory (make it with launch_scripts/wan_certs.sh {} HOST…)",
                dir.display(),
                dir.display()
            ));
        }
        let files = TlsFiles {
            ca: dir.join("ca.pem"),
            cert: dir.join(format!("{name}.pem")),
            key: dir.join(format!("{name}.key")),
        };
        let ca = first_cert(&files.ca, "CA certificate")?;
        let cert = first_cert(&files.cert, &format!("{name}'s certificate"))?;
        let key_pem = read(&files.key, &format!("{name}'s private key"))?;
        let key = rustls_pemfile::private_key(&mut key_pem.as_slice())
            .ok()
            .flatten()
            .ok_or_else(|| {
                format!(
                    "{name}'s private key {} holds no PEM private key",
                    files.key.display()
                )
            })?;
        let anchor = webpki::anchor_from_trusted_cert(&ca)
            .map_err(|e| format!("CA certificate {} is not usable: {e}", files.ca.display()))?;
        let end_entity = webpki::EndEntityCert::try_from(&cert).map_err(|e| {
            format!(
                "{name}'s certificate {} is not usable: {e}",
                files.cert.display()
            )
        })?;
        let usage = match role {
            Role::Server => webpki::KeyUsage::server_auth(),
            Role::Client => webpki::KeyUsage::client_auth(),
        };
        end_entity
            .verify_for_usage(
                webpki::ALL_VERIFICATION_ALGS,
                &[anchor],
                &[],
                UnixTime::now(),
                usage,
                None,
                None,
            )
            .map_err(|e| {
                format!(
                    "{name}'s certificate {} is not valid under the CA of {} ({e}): the other end would refuse it; make both with the same launch_scripts/wan_certs.sh DIR",
                    files.cert.display(),
                    files.ca.display()
                )
            })?;
        rustls::sign::CertifiedKey::from_der(
            vec![cert],
            key,
            &rustls::crypto::ring::default_provider(),
        )
        .map_err(|e| {
            format!(
                "{name}'s private key {} does not go with {} ({e})",
                files.key.display(),
                files.cert.display()
            )
        })?;
        Ok(files)
    }
}

/// The command line of `program`, word by word: an option's value, `--help` and an
/// unexpected word (usage error: exit [`CONFIG_ERROR`]) as both binaries answer them.
pub struct CommandLine {
    program: &'static str,
    usage: &'static str,
    words: std::iter::Skip<std::env::Args>,
}

impl CommandLine {
    /// The arguments after the program's name.
    pub fn new(program: &'static str, usage: &'static str) -> Self {
        CommandLine {
            program,
            usage,
            words: std::env::args().skip(1),
        }
    }

    /// The value of option `name`, the next word; none: a usage error.
    pub fn value(&mut self, name: &str) -> String {
        let (program, usage) = (self.program, self.usage);
        self.words
            .next()
            .unwrap_or_else(|| fail(program, format!("{name} needs a value\n{usage}")))
    }

    /// `--help`: the usage line on stdout, exit 0.
    pub fn help(&self) -> ! {
        println!("{}", self.usage);
        std::process::exit(0)
    }

    /// A word neither binary expects there: a usage error.
    pub fn unexpected(&self, word: &str) -> ! {
        fail(
            self.program,
            format!("unexpected argument `{word}`\n{}", self.usage),
        )
    }
}

impl Iterator for CommandLine {
    type Item = String;
    fn next(&mut self) -> Option<String> {
        self.words.next()
    }
}

/// Until Ctrl-C or SIGTERM; `program` exits with [`CONFIG_ERROR`] if it cannot listen
/// for SIGTERM.
pub async fn stop_signal(program: &str) {
    use tokio::signal::unix::{signal, SignalKind};
    let mut term = signal(SignalKind::terminate())
        .unwrap_or_else(|e| fail(program, format!("SIGTERM handler: {e}")));
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        _ = term.recv() => {}
    }
}

/// Set `key` of a Zenoh configuration to the JSON5 `value`; a failure is ours (a key
/// Zenoh does not know): `program` exits with [`CONFIG_ERROR`].
pub fn set(program: &str, config: &mut Config, key: &str, value: &str) {
    if let Err(e) = config.insert_json5(key, value) {
        fail(program, format!("Zenoh configuration {key} = {value}: {e}"))
    }
}

/// The settings the router and the bridges share: `mode` (`"router"` or `"client"`),
/// the one endpoint to listen on (the router) or to connect to (a bridge), nothing on
/// the other side, no Zenoh scouting on the LAN (the router is the only peer), and
/// timestamps (the bridges' caches of transient-local publications need them; a router
/// with timestamping keeps them consistent).
pub fn base_config(program: &str, mode: &str, endpoint: &Endpoint) -> Config {
    let mut c = Config::default();
    let (ours, other) = if mode == "router" {
        ("listen", "connect")
    } else {
        ("connect", "listen")
    };
    let mut set = |key: &str, value: &str| set(program, &mut c, key, value);
    set("mode", &json(mode));
    set(
        &format!("{ours}/endpoints"),
        &format!("[{}]", json(&endpoint.text)),
    );
    set(&format!("{other}/endpoints"), "[]");
    set("scouting/multicast/enabled", "false");
    set("scouting/gossip/enabled", "false");
    set("timestamping/enabled", "true");
    c
}

impl TlsFiles {
    /// Mutual TLS with these files: the router listens with them and admits only
    /// clients the CA signed; a bridge connects with them and admits only a router the
    /// CA signed for the name it connects to.
    pub fn configure(&self, program: &str, config: &mut Config, role: Role) {
        let end = match role {
            Role::Server => "listen",
            Role::Client => "connect",
        };
        let mut set = |key: &str, value: &str| set(program, config, key, value);
        set(
            "transport/link/tls/root_ca_certificate",
            &json_path(&self.ca),
        );
        set(
            &format!("transport/link/tls/{end}_certificate"),
            &json_path(&self.cert),
        );
        set(
            &format!("transport/link/tls/{end}_private_key"),
            &json_path(&self.key),
        );
        set("transport/link/tls/enable_mtls", "true");
        if role == Role::Client {
            set("transport/link/tls/verify_name_on_connect", "true");
        }
    }
}

/// A JSON string literal (for Zenoh's `insert_json5`).
pub fn json(s: impl AsRef<str>) -> String {
    serde_json::Value::String(s.as_ref().to_string()).to_string()
}

/// A path as a JSON string literal.
pub fn json_path(p: &Path) -> String {
    json(p.to_string_lossy())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_crossing_topic_goes_where_it_is_subscribed() {
        assert_eq!(
            Side::Pc.outgoing(),
            ["servo_angles", "estop", "robot_description"]
        );
        assert_eq!(
            Side::Pi.outgoing(),
            ["servo_state", "diagnostics", "camera/image_raw/compressed"]
        );
        assert_eq!(Side::Pi.incoming(), ["servo_angles", "estop"]);
        assert_eq!(
            Side::Pc.incoming(),
            [
                "estop",
                "robot_description",
                "servo_state",
                "diagnostics",
                "camera/image_raw/compressed"
            ]
        );
        // what the Pi sends, only the PCs take; the Pi never takes its own kind's topics
        for topic in Side::Pi.outgoing() {
            assert!(!Side::Pi.incoming().contains(&topic), "{topic}");
        }
    }

    #[test]
    fn endpoints() {
        assert!(check_endpoint("E", "tls/example.org:7447").unwrap().tls);
        assert!(!check_endpoint("E", "tcp/10.0.0.1:7447").unwrap().tls);
        assert!(check_endpoint("E", "tls/[::1]:7447").is_ok());
        for bad in [
            "",
            "example.org:7447",
            "udp/h:1",
            "tls/h",
            "tls/h:0",
            "tls/:7447",
            "tls/h:x",
        ] {
            assert!(check_endpoint("E", bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn namespaces() {
        assert_eq!(check_namespace("/").unwrap(), "");
        assert_eq!(check_namespace("/arm2").unwrap(), "/arm2");
        assert_eq!(topic_regex("", "estop"), "/estop");
        assert_eq!(topic_regex("/arm2", "estop"), "/arm2/estop");
        for bad in ["", "arm2", "/a//b", "/a-b", "/2a"] {
            assert!(check_namespace(bad).is_err(), "{bad}");
        }
    }
}
