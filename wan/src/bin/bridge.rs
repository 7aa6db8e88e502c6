//! `eezybot_wan_bridge pc|pi`: the DDS graph of one site (the operator's PC or the
//! Raspberry Pi) joined to the other through a Zenoh router, hosting
//! zenoh-plugin-ros2dds as the official zenoh-bridge-ros2dds does. Only the topics of
//! [`eezybot_wan::CROSSING`] cross, each in its direction; nothing else (no services,
//! actions or parameters). See wan/README.md.
//!
//! Configuration (a flag wins over its environment variable):
//!   --router EP     ZENOH_ROUTER   tls/HOST:PORT (or tcp/HOST:PORT, unencrypted, for tests)
//!   --tls-dir DIR   ZENOH_TLS_DIR  ca.pem, NAME.pem, NAME.key (launch_scripts/wan_certs.sh)
//!   --cert NAME                    client certificate name (default: the side, pc or pi)
//!   --domain N      ROS_DOMAIN_ID  DDS domain (default 0)
//!   --namespace NS                 the nodes' ROS namespace (-r __ns:=NS), default /
//!   --enclave PATH                 SROS2: the DDS participant's enclave when
//!                                  ROS_SECURITY_ENABLE=true (default /eezybot/bridge_SIDE;
//!                                  ROS_SECURITY_ENCLAVE_OVERRIDE wins, as in rcl), in
//!                                  ROS_SECURITY_KEYSTORE; ROS_SECURITY_STRATEGY=Enforce:
//!                                  an unusable enclave is a configuration error
//!   --print-config                 print the Zenoh configuration and exit (after the
//!                                  checks, the enclave's included)
//! Exit status 2 on a configuration error (missing or unreadable TLS file, bad endpoint,
//! under Enforce an enclave that is missing or that Cyclone DDS refuses).
//!
//! Its own `diagnostics` on the site's LAN, once a second ([`eezybot_wan::health`]):
//! whether the router is connected and, over TLS, when its certificate (or the CA's)
//! runs out, a warning within 30 days of it (also said on stderr at start).

use eezybot_wan::sros2::{self, Strategy};
use eezybot_wan::{
    base_config, check_endpoint, check_namespace, fail, json, topic_regex, CommandLine, Role, Side,
    TlsFiles,
};
use zenoh::config::Config;
use zenoh::internal::plugins::PluginsManager;
use zenoh::internal::runtime::RuntimeBuilder;
use zenoh_plugin_trait::Plugin;

const PROGRAM: &str = "eezybot_wan_bridge";
const USAGE: &str = "usage: eezybot_wan_bridge pc|pi [--router tls/HOST:PORT] [--tls-dir DIR] \
[--cert NAME] [--domain N] [--namespace /NS] [--enclave /PATH] [--print-config]";

struct Args {
    side: Side,
    router: Option<String>,
    tls_dir: Option<String>,
    cert: Option<String>,
    domain: Option<String>,
    namespace: String,
    enclave: Option<String>,
    print_config: bool,
}

fn parse_args() -> Args {
    let mut args = CommandLine::new(PROGRAM, USAGE);
    let mut side = None;
    let mut router = None;
    let mut tls_dir = None;
    let mut cert = None;
    let mut domain = None;
    let mut namespace = "/".to_string();
    let mut enclave = None;
    let mut print_config = false;
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--router" => router = Some(args.value("--router")),
            "--tls-dir" => tls_dir = Some(args.value("--tls-dir")),
            "--cert" => cert = Some(args.value("--cert")),
            "--domain" => domain = Some(args.value("--domain")),
            "--namespace" => namespace = args.value("--namespace"),
            "--enclave" => enclave = Some(args.value("--enclave")),
            "--print-config" => print_config = true,
            "-h" | "--help" => args.help(),
            s if side.is_none() && !s.starts_with('-') => {
                side = Some(s.parse::<Side>().unwrap_or_else(|e| fail(PROGRAM, e)))
            }
            s => args.unexpected(s),
        }
    }
    let env = |name: &str| std::env::var(name).ok().filter(|v| !v.is_empty());
    Args {
        side: side.unwrap_or_else(|| fail(PROGRAM, format!("which side: pc or pi?\n{USAGE}"))),
        router: router.or_else(|| env("ZENOH_ROUTER")),
        tls_dir: tls_dir.or_else(|| env("ZENOH_TLS_DIR")),
        cert,
        domain: domain.or_else(|| env("ROS_DOMAIN_ID")),
        namespace,
        enclave,
        print_config,
    }
}

/// Set `key` to the JSON5 `value` ([`eezybot_wan::set`]).
fn set(config: &mut Config, key: &str, value: &str) {
    eezybot_wan::set(PROGRAM, config, key, value)
}

/// The DDS domain: `--domain` or `ROS_DOMAIN_ID`, 0…232, default 0.
fn domain(args: &Args) -> u32 {
    match args.domain.as_deref() {
        None => 0,
        Some(d) => match d.parse::<u32>() {
            Ok(n) if n <= 232 => n,
            _ => fail(PROGRAM, format!("ROS_DOMAIN_ID=`{d}` is not 0…232")),
        },
    }
}

fn config(args: &Args) -> Config {
    let router = args.router.as_deref().unwrap_or_else(|| {
        fail(
            PROGRAM,
            "ZENOH_ROUTER is not set: the router's endpoint, tls/HOST:PORT",
        )
    });
    let router = check_endpoint("ZENOH_ROUTER", router).unwrap_or_else(|e| fail(PROGRAM, e));
    let domain = domain(args);
    let ns = check_namespace(&args.namespace).unwrap_or_else(|e| fail(PROGRAM, e));
    let side = args.side;
    let regexes = |topics: Vec<&str>| {
        let list: Vec<String> = topics.iter().map(|t| json(topic_regex(&ns, t))).collect();
        format!("[{}]", list.join(", "))
    };

    let mut c = base_config(PROGRAM, "client", &router);
    // Keep trying the router forever, at start and after a loss (an outage of the WAN).
    set(&mut c, "connect/timeout_ms", "-1");
    set(&mut c, "connect/exit_on_failure", "false");
    set(
        &mut c,
        "connect/retry",
        "{ period_init_ms: 500, period_max_ms: 2000, period_increase_factor: 2 }",
    );
    // As zenoh-bridge-ros2dds: the admin space and the plugin (timestamps: base_config).
    set(&mut c, "adminspace/enabled", "true");
    set(&mut c, "plugins_loading/enabled", "true");
    if router.tls {
        let name = args.cert.as_deref().unwrap_or(side.name());
        let dir = args.tls_dir.as_deref().unwrap_or_else(|| {
            fail(PROGRAM, format!("ZENOH_TLS_DIR is not set: the directory with ca.pem, {name}.pem and {name}.key (launch_scripts/wan_certs.sh)"))
        });
        TlsFiles::load(dir, name, Role::Client)
            .unwrap_or_else(|e| fail(PROGRAM, e))
            .configure(PROGRAM, &mut c, Role::Client);
    } else {
        eprintln!(
            "{PROGRAM}: WARNING: {} is plain TCP: not encrypted, not authenticated (tests only)",
            router.text
        );
    }
    let plugin = format!(
        r#"{{
            nodename: {node},
            domain: {domain},
            allow: {{
                publishers: {out},
                subscribers: {inc},
                service_servers: [], service_clients: [],
                action_servers: [], action_clients: [],
            }},
        }}"#,
        node = json(format!("eezybot_wan_bridge_{}", side.name())),
        out = regexes(side.outgoing()),
        inc = regexes(side.incoming()),
    );
    set(&mut c, "plugins/ros2dds", &plugin);
    c
}

#[tokio::main]
async fn main() {
    zenoh::init_log_from_env_or("warn,zenoh_plugin_ros2dds=info");
    let args = parse_args();
    let config = config(&args);
    let secured = security(&args);
    if args.print_config {
        println!("{config}");
        return;
    }
    // The plugin reads ROS_DISTRO for the format of ros_discovery_info ("assuming iron"
    // otherwise); we target Jazzy.
    if std::env::var_os("ROS_DISTRO").is_none() {
        std::env::set_var("ROS_DISTRO", "jazzy");
    }
    let side = args.side;
    let expiry = certificate(&args);
    if let Some(e) = &expiry {
        eprintln!("{PROGRAM}: {}", e.summary(eezybot_wan::expiry::now_unix()));
    }
    eprintln!(
        "{PROGRAM}: {} side, ROS domain {}, router {}; out: {}; in: {}; {}",
        side.name(),
        args.domain.as_deref().unwrap_or("0"),
        args.router.as_deref().unwrap_or_default(),
        side.outgoing().join(", "),
        side.incoming().join(", "),
        match &secured {
            Some(e) => format!("DDS secured, SROS2 enclave {}", e.name),
            None => "DDS unsecured".to_string(),
        }
    );
    let mut plugins = PluginsManager::static_plugins_only();
    plugins.declare_static_plugin::<zenoh_plugin_ros2dds::ROS2Plugin, &str>("ros2dds", true);
    tracing::info!(
        "zenoh-plugin-ros2dds {}",
        zenoh_plugin_ros2dds::ROS2Plugin::PLUGIN_LONG_VERSION
    );
    let mut runtime = match RuntimeBuilder::new(config)
        .plugins_manager(plugins)
        .build()
        .await
    {
        Ok(r) => r,
        Err(e) => fail(PROGRAM, format!("starting Zenoh: {e}")),
    };
    let connected = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    eezybot_wan::health::spawn(
        PROGRAM,
        args.domain
            .as_deref()
            .and_then(|d| d.parse().ok())
            .unwrap_or(0),
        eezybot_wan::health::Health {
            node: format!("eezybot_wan_bridge_{}", side.name()),
            namespace: check_namespace(&args.namespace).unwrap_or_default(),
            router: args.router.clone().unwrap_or_default(),
            expiry,
            connected: connected.clone(),
        },
    );
    // start() returns once connected to the router (it retries forever); until then,
    // say so every 10 s: a refused certificate or plain TCP to a TLS router is only
    // logged at debug level by Zenoh.
    let router = args.router.as_deref().unwrap_or_default();
    let began = std::time::Instant::now();
    let mut tick = tokio::time::interval(std::time::Duration::from_secs(10));
    tick.tick().await;
    let for_health = runtime.clone();
    let start = runtime.start();
    tokio::pin!(start);
    loop {
        tokio::select! {
            started = &mut start => {
                if let Err(e) = started {
                    fail(PROGRAM, format!("starting Zenoh: {e}"))
                }
                break;
            }
            _ = tick.tick() => eprintln!(
                "{PROGRAM}: not connected to the router {router} after {} s, still trying: is it running and reachable, and were its certificate and ours made by the same CA (wan_certs.sh)? The reason of each attempt: RUST_LOG=zenoh::net::runtime::orchestrator=debug",
                began.elapsed().as_secs()
            ),
            _ = signal() => std::process::exit(0),
        }
    }
    eprintln!("{PROGRAM}: connected to the router {router}");
    watch_router(for_health, connected).await;
    signal().await;
    std::process::exit(0)
}

/// The certificate's end (and the CA's), when the router is dialled over TLS with
/// usable files (checked already by [`config`]).
fn certificate(args: &Args) -> Option<eezybot_wan::expiry::CertificateExpiry> {
    let router = check_endpoint("ZENOH_ROUTER", args.router.as_deref()?).ok()?;
    if !router.tls {
        return None;
    }
    let name = args.cert.as_deref().unwrap_or(args.side.name());
    let files = TlsFiles::load(args.tls_dir.as_deref()?, name, Role::Client).ok()?;
    eezybot_wan::expiry::CertificateExpiry::earliest(&[&files.cert, &files.ca]).ok()
}

/// Keep `connected` current (whether the runtime has a router), every second, in a
/// task of its own.
async fn watch_router(
    runtime: zenoh::internal::runtime::Runtime,
    connected: std::sync::Arc<std::sync::atomic::AtomicBool>,
) {
    let session = match zenoh::session::init(runtime.into()).await {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{PROGRAM}: the router's state for diagnostics: {e}");
            return;
        }
    };
    tokio::spawn(async move {
        loop {
            let n = session.info().routers_zid().await.count();
            connected.store(n > 0, std::sync::atomic::Ordering::Relaxed);
            tokio::time::sleep(std::time::Duration::from_secs(1)).await;
        }
    });
}

/// SROS2 for the plugin's DDS participant ([`sros2`]): when `ROS_SECURITY_ENABLE=true`,
/// the enclave's files are checked, Cyclone DDS is asked to make a participant with
/// them (one that sends nothing: [`sros2::ISOLATED`]), and `CYCLONEDDS_URI` gets the
/// enclave's configuration for the plugin's participant. An unusable enclave stops the
/// bridge under Enforce (exit status 2); otherwise it warns and runs unsecured, as our
/// nodes do. The enclave in use, or None.
fn security(args: &Args) -> Option<sros2::Enclave> {
    let default = sros2::default_enclave(args.side);
    let arg = args.enclave.as_deref().unwrap_or(&default);
    let user_uri = std::env::var("CYCLONEDDS_URI").ok();
    let checked =
        sros2::plan(|name| std::env::var(name).ok(), arg).and_then(|plan| match plan {
            None => Ok(None),
            Some(enclave) => {
                let uri =
                    sros2::with_fragment(user_uri.as_deref(), &sros2::cyclone_config(&enclave));
                match cyclone_takes(domain(args), &uri) {
                    Ok(()) => Ok(Some((enclave, uri))),
                    Err(why) => Err((
                        enclave.strategy,
                        format!(
                            "enclave {} ({}): Cyclone DDS refused it{}: {why} (its reason is logged above)",
                            enclave.name,
                            enclave.dir.display(),
                            if user_uri.is_some() {
                                " or the CYCLONEDDS_URI it is added to"
                            } else {
                                ""
                            }
                        ),
                    )),
                }
            }
        });
    match checked {
        Ok(None) => None,
        Ok(Some((enclave, uri))) => {
            eprintln!(
                "{PROGRAM}: SROS2 on: enclave {} ({}), strategy {}",
                enclave.name,
                enclave.dir.display(),
                enclave.strategy
            );
            std::env::set_var("CYCLONEDDS_URI", uri);
            Some(enclave)
        }
        Err((Strategy::Enforce, why)) => fail(
            PROGRAM,
            format!("{why}; ROS_SECURITY_STRATEGY=Enforce: not starting unsecured"),
        ),
        Err((Strategy::Permissive, why)) => {
            eprintln!("{PROGRAM}: WARNING: {why}; ROS_SECURITY_STRATEGY is not Enforce: the bridge's DDS participant runs unsecured (secured nodes will not talk to it)");
            None
        }
    }
}

/// Whether Cyclone DDS makes a participant in `domain` with the configuration `uri`:
/// the enclave checked as the plugin's participant will be (certificates, key,
/// signatures, the permissions for this domain). The participant is isolated
/// ([`sros2::ISOLATED`]: nothing sent) and deleted at once; `CYCLONEDDS_URI` is as
/// before afterwards.
fn cyclone_takes(domain: u32, uri: &str) -> Result<(), String> {
    let before = std::env::var_os("CYCLONEDDS_URI");
    std::env::set_var("CYCLONEDDS_URI", format!("{uri},{}", sros2::ISOLATED));
    // SAFETY: plain C calls with no pointers of ours: a null QoS and listener; the
    // handle returned is used only to delete that participant.
    let participant =
        unsafe { cyclors::dds_create_participant(domain, std::ptr::null(), std::ptr::null()) };
    let result = if participant < 0 {
        // SAFETY: dds_strretcode returns a static C string for any code.
        let why = unsafe { std::ffi::CStr::from_ptr(cyclors::dds_strretcode(participant)) };
        Err(why.to_string_lossy().into_owned())
    } else {
        // SAFETY: a participant made here and used by nothing else.
        unsafe { cyclors::dds_delete(participant) };
        Ok(())
    };
    match before {
        Some(v) => std::env::set_var("CYCLONEDDS_URI", v),
        None => std::env::remove_var("CYCLONEDDS_URI"),
    }
    result
}

/// Ctrl-C or SIGTERM ([`eezybot_wan::stop_signal`]).
async fn signal() {
    eezybot_wan::stop_signal(PROGRAM).await
}
