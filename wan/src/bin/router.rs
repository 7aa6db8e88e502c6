//! `eezybot_wan_router`: the Zenoh router both sites' bridges connect to
//! (launch_scripts/router.sh). Listens on one endpoint, TLS with mutual authentication:
//! only a client whose certificate the CA signed (launch_scripts/wan_certs.sh) joins.
//!
//!   --listen EP     ZENOH_LISTEN   default tls/0.0.0.0:7447 (tcp/… unencrypted, tests only)
//!   --tls-dir DIR   ZENOH_TLS_DIR  ca.pem, router.pem, router.key
//!   --print-config                 print the Zenoh configuration and exit
//! Exit status 2 on a configuration error (missing or unreadable TLS file, bad endpoint,
//! an address it cannot listen on).

use eezybot_wan::{base_config, check_endpoint, fail, CommandLine, Role, TlsFiles};
use zenoh::config::Config;

const PROGRAM: &str = "eezybot_wan_router";
const USAGE: &str =
    "usage: eezybot_wan_router [--listen tls/0.0.0.0:7447] [--tls-dir DIR] [--print-config]";

/// Set `key` to the JSON5 `value` ([`eezybot_wan::set`]).
fn set(config: &mut Config, key: &str, value: &str) {
    eezybot_wan::set(PROGRAM, config, key, value)
}

#[tokio::main]
async fn main() {
    zenoh::init_log_from_env_or("warn");
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
        TlsFiles::load(&dir, "router", Role::Server)
            .unwrap_or_else(|e| fail(PROGRAM, e))
            .configure(PROGRAM, &mut c, Role::Server);
    } else {
        eprintln!(
            "{PROGRAM}: WARNING: {} is plain TCP: not encrypted, not authenticated (tests only)",
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
    eprintln!(
        "{PROGRAM}: listening on {}{} (id {})",
        endpoint.text,
        if endpoint.tls {
            ", TLS with client certificates"
        } else {
            ""
        },
        session.zid()
    );
    eezybot_wan::stop_signal(PROGRAM).await;
    eprintln!("{PROGRAM}: stopping");
    let _ = session.close().await;
}
