//! `acl_probe`: a bare Zenoh client of the WAN router, holding one client certificate,
//! that publishes a sensor_msgs/JointState on a key at a rate: what someone with a
//! certificate copied off a Pi's SD card could do without our bridge. The check of the
//! router's access control (tests/test_wan_acl.py): under the `pi` certificate nothing
//! it publishes on `servo_angles` gets through; under the `pc` certificate it does.
//!
//!   acl_probe --router tls/HOST:PORT --tls-dir DIR --cert NAME [--key servo_angles]
//!             [--rate 20] [--position RAD]... [--name SERVO]...
//!
//! Prints `connected` once the router let it in, then `sent N` every second; runs until
//! SIGTERM or Ctrl-C (exit 0). Exit 2 on a configuration error.

use eezybot_wan::{base_config, cdr, check_endpoint, fail, CommandLine, Role, TlsFiles};

const PROGRAM: &str = "acl_probe";
const USAGE: &str = "usage: acl_probe --router tls/HOST:PORT --tls-dir DIR --cert NAME \
[--key servo_angles] [--rate HZ] [--name SERVO --position RAD]...";

#[tokio::main]
async fn main() {
    zenoh::init_log_from_env_or("warn");
    let mut args = CommandLine::new(PROGRAM, USAGE);
    let (mut router, mut dir, mut cert) = (None, None, None);
    let mut key = "servo_angles".to_string();
    let mut rate = 20.0_f64;
    let mut names = Vec::new();
    let mut positions = Vec::new();
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--router" => router = Some(args.value("--router")),
            "--tls-dir" => dir = Some(args.value("--tls-dir")),
            "--cert" => cert = Some(args.value("--cert")),
            "--key" => key = args.value("--key"),
            "--rate" => {
                rate = args
                    .value("--rate")
                    .parse()
                    .unwrap_or_else(|e| fail(PROGRAM, format!("--rate: {e}")))
            }
            "--name" => names.push(args.value("--name")),
            "--position" => positions.push(
                args.value("--position")
                    .parse::<f64>()
                    .unwrap_or_else(|e| fail(PROGRAM, format!("--position: {e}"))),
            ),
            "-h" | "--help" => args.help(),
            s => args.unexpected(s),
        }
    }
    let router = router.unwrap_or_else(|| fail(PROGRAM, USAGE));
    let endpoint = check_endpoint("--router", &router).unwrap_or_else(|e| fail(PROGRAM, e));
    let mut c = base_config(PROGRAM, "client", &endpoint);
    if endpoint.tls {
        let (dir, cert) = (
            dir.unwrap_or_else(|| fail(PROGRAM, "--tls-dir is needed")),
            cert.unwrap_or_else(|| fail(PROGRAM, "--cert is needed")),
        );
        TlsFiles::load(&dir, &cert, Role::Client)
            .unwrap_or_else(|e| fail(PROGRAM, e))
            .configure(PROGRAM, &mut c, Role::Client);
    }
    if !(rate > 0.0 && rate <= 1000.0) {
        fail(PROGRAM, "--rate: 0 < HZ <= 1000");
    }
    let session = zenoh::open(c)
        .await
        .unwrap_or_else(|e| fail(PROGRAM, format!("connecting: {e}")));
    println!("connected as {}", session.zid());
    // Session puts, not a declared publisher: a publisher sends only where the router
    // said a subscriber is, and the router does not tell a role of subscribers to a topic
    // it may not publish; a put each time goes to the router whatever it said, so what
    // stops it is the router's refusal of the put itself.
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    let mut tick = tokio::time::interval(std::time::Duration::from_secs_f64(1.0 / rate));
    let mut report = tokio::time::interval(std::time::Duration::from_secs(1));
    let mut sent = 0u64;
    let stop = eezybot_wan::stop_signal(PROGRAM);
    tokio::pin!(stop);
    loop {
        tokio::select! {
            _ = tick.tick() => {
                let payload = cdr::joint_state(cdr::now_nanos(), &names, &positions);
                if session.put(&key, payload).await.is_ok() {
                    sent += 1;
                }
            }
            _ = report.tick() => println!("sent {sent}"),
            _ = &mut stop => break,
        }
    }
    println!("sent {sent}");
    let _ = session.close().await;
}
