//! `eezybot_sros2`: prints the SROS2 governance and permissions documents of the
//! EezyBot graph ([`ros_plumbing::sros2`]), for `launch_scripts/keystore.sh` to sign,
//! or for a keystore made with `ros2 security`.

use openssl::asn1::{Asn1Time, Asn1TimeRef};
use openssl::nid::Nid;
use openssl::x509::X509;
use ros_plumbing::sros2::{self, Domains, Grant, Role, Validity};
use std::process::ExitCode;

const USAGE: &str = "\
eezybot_sros2: the SROS2 policy documents of the EezyBot graph, generated from the topic
contract (libs/ros_plumbing/src/topics.rs), printed on stdout.

usage:
  eezybot_sros2 governance [--domain N]
  eezybot_sros2 permissions --enclave PATH [--role ROLE] [--namespace NS] [--domain N]
                            [--cert CERT.PEM | --not-before T --not-after T]
  eezybot_sros2 topics --enclave PATH [--role ROLE] [--namespace NS]

  governance    sros2's default governance: authentication required, discovery,
                liveliness and data encrypted, RTPS signed, access control on every topic
  permissions   the permissions.xml of one enclave: subject CN=PATH, its nodes' topics,
                actions, services and parameter services, the ROS graph topics,
                default DENY
  topics        the DDS topic names the enclave may publish and subscribe, one a line
                (`publish rt/servo_state`)

options:
  --enclave PATH   the enclave (/eezybot/pc, /eezybot/pi, /eezybot/bridge_pc, /eezybot/tools ...)
  --role pc|pi|tools|bridge_pc|bridge_pi
                   what runs in it: pc = gui_bridge, compute_ik, state_publisher;
                   pi = serial_node; tools = stock ROS 2 tools (every contract topic
                   both ways, /rosout, every service); bridge_pc, bridge_pi = that
                   site's WAN bridge (eezybot_wan_bridge pc|pi: exactly the topics
                   that cross the WAN there, each way, and ros_discovery_info)
                   (default: pi for /eezybot/pi, bridge_pc and bridge_pi for
                   /eezybot/bridge_pc and /eezybot/bridge_pi, else pc)
  --namespace NS   the nodes' namespace, for -r __ns:=NS (default /)
  --domain N       only ROS domain N (default: every domain, 0 ... 230, sros2's
                   range: Cyclone DDS refuses a document with a higher one)
  --cert FILE      the enclave's certificate: the grant's validity is its validity
                   (and its subject must be CN=PATH)
  --not-before T, --not-after T
                   the validity, YYYY-MM-DDThh:mm:ss UTC (default: from a day ago
                   for ten years, as sros2's certificates)

exit status: 0 printed, 1 a certificate could not be read, 2 usage error";

/// A usage error (exit 2) or another failure (exit 1).
enum Failure {
    Usage(String),
    Other(String),
}

#[derive(Default)]
struct Options {
    enclave: Option<String>,
    role: Option<Role>,
    namespace: Option<String>,
    domain: Option<Domains>,
    cert: Option<String>,
    not_before: Option<String>,
    not_after: Option<String>,
}

fn parse_options(args: &[String]) -> Result<Options, Failure> {
    let mut o = Options::default();
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        let (flag, inline) = match arg.split_once('=') {
            Some((f, v)) if f.starts_with("--") => (f, Some(v.to_string())),
            _ => (arg.as_str(), None),
        };
        let mut value = || -> Result<String, Failure> {
            match &inline {
                Some(v) => Ok(v.clone()),
                None => it
                    .next()
                    .cloned()
                    .ok_or_else(|| Failure::Usage(format!("{flag} needs a value"))),
            }
        };
        match flag {
            "--enclave" | "-e" => o.enclave = Some(value()?),
            "--role" => {
                let v = value()?;
                o.role = Some(Role::parse(&v).ok_or_else(|| {
                    Failure::Usage(format!("--role {v}: pc, pi, tools, bridge_pc or bridge_pi"))
                })?);
            }
            "--namespace" => o.namespace = Some(value()?),
            "--domain" => {
                let v = value()?;
                let n: u32 = v
                    .parse()
                    .map_err(|_| Failure::Usage(format!("--domain {v}: a number 0 ... 230")))?;
                o.domain = Some(Domains::id(n).map_err(|e| Failure::Usage(e.to_string()))?);
            }
            "--cert" => o.cert = Some(value()?),
            "--not-before" => o.not_before = Some(value()?),
            "--not-after" => o.not_after = Some(value()?),
            _ => return Err(Failure::Usage(format!("unknown argument `{arg}`"))),
        }
    }
    Ok(o)
}

fn unix_time(t: &Asn1TimeRef) -> Result<i64, String> {
    let epoch = Asn1Time::from_unix(0).map_err(|e| e.to_string())?;
    let d = epoch.diff(t).map_err(|e| e.to_string())?;
    Ok(i64::from(d.days) * 86_400 + i64::from(d.secs))
}

/// The validity of the certificate at `path`, checking that its subject is
/// `CN=<enclave>`.
fn cert_validity(path: &str, enclave: &str) -> Result<Validity, Failure> {
    let pem = std::fs::read(path).map_err(|e| Failure::Other(format!("{path}: {e}")))?;
    let cert = X509::from_pem(&pem)
        .map_err(|e| Failure::Other(format!("{path}: not a PEM certificate: {e}")))?;
    let cn: Vec<String> = cert
        .subject_name()
        .entries_by_nid(Nid::COMMONNAME)
        .map(|e| String::from_utf8_lossy(e.data().as_slice()).into_owned())
        .collect();
    if cn != [enclave] {
        return Err(Failure::Other(format!(
            "{path}: subject CN={} is not the enclave's CN={enclave}",
            cn.join(",")
        )));
    }
    let nb = unix_time(cert.not_before()).map_err(|e| Failure::Other(format!("{path}: {e}")))?;
    let na = unix_time(cert.not_after()).map_err(|e| Failure::Other(format!("{path}: {e}")))?;
    Validity::from_unix(nb, na).map_err(|e| Failure::Other(format!("{path}: {e}")))
}

fn validity(o: &Options, enclave: &str) -> Result<Validity, Failure> {
    match (&o.cert, &o.not_before, &o.not_after) {
        (Some(cert), None, None) => cert_validity(cert, enclave),
        (None, Some(nb), Some(na)) => {
            Validity::new(nb, na).map_err(|e| Failure::Usage(e.to_string()))
        }
        (None, None, None) => {
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_err(|e| Failure::Other(format!("the clock is before 1970: {e}")))?
                .as_secs();
            let now = i64::try_from(now).unwrap_or(i64::MAX / 2);
            Validity::from_unix(now - 86_400, now + 3650 * 86_400)
                .map_err(|e| Failure::Other(e.to_string()))
        }
        (Some(_), _, _) => Err(Failure::Usage(
            "--cert or --not-before/--not-after, not both".to_string(),
        )),
        _ => Err(Failure::Usage(
            "--not-before and --not-after go together".to_string(),
        )),
    }
}

fn grant(o: &Options) -> Result<Grant, Failure> {
    let enclave = o
        .enclave
        .clone()
        .ok_or_else(|| Failure::Usage("--enclave PATH is required".to_string()))?;
    sros2::check_enclave(&enclave).map_err(|e| Failure::Usage(e.to_string()))?;
    let namespace = o.namespace.clone().unwrap_or_else(|| "/".to_string());
    sros2::check_namespace(&namespace).map_err(|e| Failure::Usage(e.to_string()))?;
    let role = o.role.unwrap_or_else(|| Role::of_enclave(&enclave));
    let validity = validity(o, &enclave)?;
    Ok(Grant {
        role,
        enclave,
        namespace,
        validity,
        domains: o.domain.unwrap_or(Domains::All),
    })
}

fn run(args: &[String]) -> Result<String, Failure> {
    let Some((command, rest)) = args.split_first() else {
        return Err(Failure::Usage("a command is needed".to_string()));
    };
    match command.as_str() {
        "-h" | "--help" | "help" => Ok(format!("{USAGE}\n")),
        "governance" => {
            let o = parse_options(rest)?;
            if o.enclave.is_some() || o.role.is_some() || o.namespace.is_some() || o.cert.is_some()
            {
                return Err(Failure::Usage("governance takes only --domain".to_string()));
            }
            Ok(sros2::governance_xml(o.domain.unwrap_or(Domains::All)))
        }
        "permissions" => {
            let o = parse_options(rest)?;
            let g = grant(&o)?;
            sros2::permissions_xml(&g).map_err(|e| Failure::Usage(e.to_string()))
        }
        "topics" => {
            let o = parse_options(rest)?;
            let g = grant(&o)?;
            let r = g
                .role
                .rules(&g.namespace)
                .map_err(|e| Failure::Usage(e.to_string()))?;
            let mut out = String::new();
            for t in &r.publish {
                out.push_str(&format!("publish {t}\n"));
            }
            for t in &r.subscribe {
                out.push_str(&format!("subscribe {t}\n"));
            }
            Ok(out)
        }
        other => Err(Failure::Usage(format!("unknown command `{other}`"))),
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(text) => {
            print!("{text}");
            ExitCode::SUCCESS
        }
        Err(Failure::Usage(m)) => {
            eprintln!("eezybot_sros2: {m}\n(eezybot_sros2 --help for the usage)");
            ExitCode::from(2)
        }
        Err(Failure::Other(m)) => {
            eprintln!("eezybot_sros2: {m}");
            ExitCode::from(1)
        }
    }
}
