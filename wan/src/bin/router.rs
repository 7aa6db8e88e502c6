//! `eezybot_wan_router`: the Zenoh router both sites' bridges connect to
//! (launch_scripts/router.sh). Listens on one endpoint, TLS with mutual authentication:
//! only a client whose certificate the CA signed (launch_scripts/wan_certs.sh) joins,
//! and each client may send only its role's directions (the certificate's common name,
//! `pc` or `pi`: [`eezybot_wan::acl`]); each refusal is logged
//! ([`eezybot_wan::refusals`]). At start it logs when its certificate (or the CA's) runs
//! out, with a warning within 30 days of it.
//!
//!   --listen EP     ZENOH_LISTEN   default tls/0.0.0.0:7447 (tcp/… unencrypted, tests only)
//!   --tls-dir DIR   ZENOH_TLS_DIR  ca.pem, router.pem, router.key
//!   --print-config                 print the Zenoh configuration and exit
//! Exit status 2 on a configuration error (missing or unreadable TLS file, bad endpoint,
//! an address it cannot listen on).

use eezybot_wan::expiry::{now_unix, CertificateExpiry};
use eezybot_wan::refusals::{Refusals, ACL_TARGET};
use eezybot_wan::{acl, base_config, check_endpoint, fail, CommandLine, Role, TlsFiles};
use tracing_subscriber::filter::{EnvFilter, Targets};
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::Layer;
use zenoh::config::Config;

const PROGRAM: &str = "eezybot_wan_router";
const USAGE: &str =
    "usage: eezybot_wan_router [--listen tls/0.0.0.0:7447] [--tls-dir DIR] [--print-config]";

/// Set `key` to the JSON5 `value` ([`eezybot_wan::set`]).
fn set(config: &mut Config, key: &str, value: &str) {
    eezybot_wan::set(PROGRAM, config, key, value)
}

/// Zenoh's log as `zenoh::init_log_from_env_or("warn")` makes it (RUST_LOG, else
/// warnings), and the access control's refusals at a normal level ([`Refusals`]).
fn init_log() {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn"));
    let fmt = tracing_subscriber::fmt::layer()
        .with_thread_ids(true)
        .with_thread_names(true)
        .with_filter(filter);
    let refusals = Refusals::new(PROGRAM)
        .with_filter(Targets::new().with_target(ACL_TARGET, tracing::Level::TRACE));
    let subscriber = tracing_subscriber::registry().with(fmt).with(refusals);
    let _ = tracing::subscriber::set_global_default(subscriber);
}

#[tokio::main]
async fn main() {
    init_log();
    let env = |name: &str| std::env::var(name).ok().filter(|v| !v.is_empty());
    let mut listen = env("ZENOH_LISTEN");
    let mut tls_dir = env("ZENOH_TLS_DIR");
    let mut print_config = false;
    let mut args = CommandLine::new(PROGRAM, USAGE);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--listen" => listen = Some(args.value("--listen")),
            "--tls-dir" => tls_dir = Some(args.value("--tls-dir")),
            "--print-config" => print_config = true,
            "-h" | "--help" => args.help(),
            s => args.unexpected(s),
        }
    }
    let listen = listen.unwrap_or_else(|| "tls/0.0.0.0:7447".to_string());
    let endpoint = check_endpoint("ZENOH_LISTEN", &listen).unwrap_or_else(|e| fail(PROGRAM, e));

    let mut c = base_config(PROGRAM, "router", &endpoint);
    set(&mut c, "listen/exit_on_failure", "true");
    if endpoint.tls {
        let dir = tls_dir.unwrap_or_else(|| {
            fail(PROGRAM, "ZENOH_TLS_DIR is not set: the directory with ca.pem, router.pem and router.key (launch_scripts/wan_certs.sh)")
        });
        let files =
            TlsFiles::load(&dir, "router", Role::Server).unwrap_or_else(|e| fail(PROGRAM, e));
        files.configure(PROGRAM, &mut c, Role::Server);
        match CertificateExpiry::earliest(&[&files.cert, &files.ca]) {
            Ok(e) => eprintln!("{PROGRAM}: {}", e.summary(now_unix())),
            Err(e) => fail(PROGRAM, e),
        }
        // least privilege: each client certificate's role (its common name)
        set(&mut c, "access_control", &acl::access_control());
    } else {
        eprintln!(
            "{PROGRAM}: WARNING: {} is plain TCP: not encrypted, not authenticated, no access control (tests only)",
            endpoint.text
        );
    }
    if print_config {
        println!("{c}");
        return;
    }
    let session = match zenoh::open(c).await {
        Ok(s) => s,
        Err(e) => fail(PROGRAM, format!("cannot listen on {}: {e}", endpoint.text)),
    };
    let roles = acl::ROLES
        .iter()
        .map(|r| format!("{} may publish {}", r.name(), r.outgoing().join(", ")))
        .collect::<Vec<_>>()
        .join("; ");
    eprintln!(
        "{PROGRAM}: listening on {}{} (id {})",
        endpoint.text,
        if endpoint.tls {
            format!(", TLS with client certificates; roles by certificate: {roles}; anything else is refused and logged")
        } else {
            String::new()
        },
        session.zid()
    );
    eezybot_wan::stop_signal(PROGRAM).await;
    eprintln!("{PROGRAM}: stopping");
    let _ = session.close().await;
}
