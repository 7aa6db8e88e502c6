//! SROS2 policy documents generated from the contract ([`crate::topics`]: its topics,
//! actions and services): the DDS Security governance document and, for each enclave,
//! the permissions document that lets it publish and subscribe exactly what its nodes
//! use.
//!
//! The documents have the shape `ros2 security create_keystore` / `create_enclave` /
//! `create_permission` write (sros2's `policy/defaults/dds/governance.xml` and
//! `policy/templates/dds/permissions.xsl`), so they work with any DDS Security
//! implementation (RustDDS here, Fast DDS and Cyclone DDS in stock ROS 2):
//!
//! - [`governance_xml`]: authentication required, join access control, discovery and
//!   liveliness encrypted, RTPS messages signed, every topic's metadata and data
//!   encrypted with read and write access control (sros2's default governance);
//! - [`permissions_xml`]: one `<grant>` for the enclave's subject `CN=/eezybot/pi`, its
//!   validity (the enclave certificate's), an `<allow_rule>` with the DDS topic names
//!   (`rt/servo_state`, `rq/serial_node/get_parametersRequest`, …) and
//!   `<default>DENY</default>`.
//!
//! The WAN bridges' enclaves (`/eezybot/bridge_pc`, `/eezybot/bridge_pi`,
//! [`Role::Bridge`]) are granted exactly what crosses the WAN at their site, each way
//! ([`crate::crossing::CROSSING`], wan/'s list): the bridge subscribes to what its site
//! sends out and publishes what comes in, and nothing else but `ros_discovery_info`.
//!
//! `launch_scripts/keystore.sh` prints them with the `eezybot_sros2` binary and signs
//! them with the CA (openssl).
//!
//! # Examples
//! ```
//! use ros_plumbing::sros2::{permissions_xml, Domains, Grant, Role, Validity};
//! let grant = Grant {
//!     enclave: "/eezybot/pi".into(),
//!     role: Role::Pi,
//!     namespace: "/".into(),
//!     validity: Validity::new("2026-11-24T00:00:00", "2036-11-22T00:00:00").unwrap(),
//!     domains: Domains::All,
//! };
//! let xml = permissions_xml(&grant).unwrap();
//! assert!(xml.contains("<subject_name>CN=/eezybot/pi</subject_name>"));
//! let rules = Role::Pi.rules("/").unwrap();
//! assert!(rules.publish.contains("rt/servo_state"));
//! assert!(!rules.publish.contains("rt/xyz_target"));
//! ```

use crate::crossing;
use crate::topics;
use std::collections::BTreeSet;
use std::fmt::Write as _;

/// What can be wrong with the input of a policy document.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[non_exhaustive]
pub enum Sros2Error {
    /// An enclave path that is not a ROS namespace (`/eezybot/pi`).
    #[error("enclave `{enclave}` is not valid: {why} (an absolute ROS name such as /eezybot/pc)")]
    Enclave {
        /// The enclave path given.
        enclave: String,
        /// What is wrong with it.
        why: String,
    },
    /// A namespace that is not a ROS namespace (`/arm2`).
    #[error(
        "namespace `{namespace}` is not valid: {why} (an absolute ROS namespace such as /arm2)"
    )]
    Namespace {
        /// The namespace given.
        namespace: String,
        /// What is wrong with it.
        why: String,
    },
    /// A node name that none of the contract's topics, actions or services knows.
    #[error("`{node}` is not one of our nodes ({known})")]
    UnknownNode {
        /// The node name given.
        node: String,
        /// The known ones, comma separated.
        known: String,
    },
    /// A date that is not `YYYY-MM-DDThh:mm:ss`.
    #[error("`{value}` is not a date and time YYYY-MM-DDThh:mm:ss (UTC)")]
    Time {
        /// The text given.
        value: String,
    },
    /// A validity period that ends before it starts.
    #[error("validity ends ({not_after}) before it starts ({not_before})")]
    Validity {
        /// Start.
        not_before: String,
        /// End.
        not_after: String,
    },
    /// A ROS domain id outside 0 … [`MAX_DOMAIN_ID`].
    #[error("ROS domain id {domain} is outside 0 ... {}", MAX_DOMAIN_ID)]
    Domain {
        /// The id given.
        domain: u32,
    },
}

/// The highest ROS domain id a policy document names: sros2's default range, 0 … 230.
/// rcl allows up to 232, but Cyclone DDS's access control refuses a governance or
/// permissions document with a domain id above 230 ("Can not parse governance file":
/// its parser's limit), and the WAN bridge's participant is Cyclone's.
pub const MAX_DOMAIN_ID: u32 = 230;

/// The nodes of the operator's PC (`launch_scripts/pc.sh`; the recorder beside them,
/// where the datasets are kept, and the physics twin, which stands in for the Pi's arm).
pub const PC_NODES: &[&str] = &[
    "gui_bridge",
    "compute_ik",
    "state_publisher",
    "recorder",
    "twin",
];
/// The nodes of the Raspberry Pi (`launch_scripts/pi.sh`; camera_node is in its bundle,
/// for a camera on the arm).
pub const PI_NODES: &[&str] = &["serial_node", "camera_node"];
/// The operator PC's enclave.
pub const PC_ENCLAVE: &str = "/eezybot/pc";
/// The Raspberry Pi's enclave.
pub const PI_ENCLAVE: &str = "/eezybot/pi";
/// The enclave of the operator PC's WAN bridge (`eezybot_wan_bridge pc`).
pub const BRIDGE_PC_ENCLAVE: &str = "/eezybot/bridge_pc";
/// The enclave of the Raspberry Pi's WAN bridge (`eezybot_wan_bridge pi`).
pub const BRIDGE_PI_ENCLAVE: &str = "/eezybot/bridge_pi";
/// The DDS topics of the ROS graph a WAN bridge's participant uses besides the crossing
/// ones (zenoh-plugin-ros2dds reads and writes `ros_discovery_info`; it creates no
/// other topic: no `rosout`, no `parameter_events`, no services).
pub const BRIDGE_GRAPH: &[&str] = &["ros_discovery_info"];
/// The contract topics a WAN bridge publishes of its own, besides what it brings in:
/// its `diagnostics` on its site's LAN (wan/src/health.rs: the WAN link's state and its
/// certificate's expiry), on the Pi's side too.
pub const BRIDGE_OWN_PUBLISH: &[&str] = &["diagnostics"];

/// The parameter services ros2-client starts for every node (`rq/<node>/<srv>Request`,
/// `rr/<node>/<srv>Reply`).
pub const PARAMETER_SERVICES: &[&str] = &[
    "describe_parameters",
    "get_parameters",
    "get_parameter_types",
    "list_parameters",
    "set_parameters",
    "set_parameters_atomically",
];

/// Which node calls which other node's parameter services
/// ([`crate::remote_params::RemoteParameters`]): gui_bridge reads and sets compute_ik's
/// parameters from the web panel, its calibration wizard sets, on saving,
/// `arm_config` on compute_ik and serial_node, and its Record card sets the recorder's
/// `task` ([`crate::episodes::EpisodeClient`], as the recorder's command line does).
pub const REMOTE_PARAMETER_CALLS: &[(&str, &str, &[&str])] = &[
    (
        "gui_bridge",
        "compute_ik",
        &["get_parameters", "set_parameters"],
    ),
    (
        "gui_bridge",
        "serial_node",
        &["get_parameters", "set_parameters"],
    ),
    (
        "gui_bridge",
        "recorder",
        &["get_parameters", "set_parameters"],
    ),
];

/// The topics every ros2-client node uses besides its own (DDS names): the ROS graph
/// (`ros_discovery_info`, published and subscribed), `/parameter_events` (published and
/// subscribed), `/rosout` (published) and `/clock` (subscribed, with `use_sim_time`).
pub const GRAPH_PUBLISH: &[&str] = &["ros_discovery_info", "rt/parameter_events", "rt/rosout"];
/// See [`GRAPH_PUBLISH`].
pub const GRAPH_SUBSCRIBE: &[&str] = &["ros_discovery_info", "rt/parameter_events", "rt/clock"];

/// What an enclave is for: it decides what its permissions allow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// The operator's PC: what gui_bridge, compute_ik, state_publisher and the recorder use.
    Pc,
    /// The Raspberry Pi: what serial_node uses.
    Pi,
    /// Stock ROS 2 tools (`ros2 topic echo`, `ros2 param set`, RViz2, MoveIt,
    /// `ros2 control`) on an operator's machine: every contract topic published and
    /// subscribed, the client side of every contract action and service, `/rosout`
    /// read, and every service (`rq/*`, `rr/*`: a tool's node has a random name and
    /// parameter services of its own, and `ros2 param` calls any node's).
    Tools,
    /// The WAN bridge of a site (`eezybot_wan_bridge pc|pi`): exactly what crosses there
    /// ([`crossing::CROSSING`]): it subscribes to the topics its site sends out
    /// ([`crossing::Side::outgoing`]: it reads them from the local publishers), publishes
    /// those that come in ([`crossing::Side::incoming`]: it writes them to the local
    /// subscribers) and its own diagnostics ([`BRIDGE_OWN_PUBLISH`]), and reads and
    /// writes `ros_discovery_info` ([`BRIDGE_GRAPH`]).
    Bridge(crossing::Side),
}

impl Role {
    /// `pc`, `pi`, `tools`, `bridge_pc` or `bridge_pi`.
    pub fn parse(s: &str) -> Option<Role> {
        match s {
            "pc" => Some(Role::Pc),
            "pi" => Some(Role::Pi),
            "tools" => Some(Role::Tools),
            "bridge_pc" => Some(Role::Bridge(crossing::Side::Pc)),
            "bridge_pi" => Some(Role::Bridge(crossing::Side::Pi)),
            _ => None,
        }
    }

    /// Our nodes that run under this role (none for tools).
    pub fn nodes(self) -> &'static [&'static str] {
        match self {
            Role::Pc => PC_NODES,
            Role::Pi => PI_NODES,
            Role::Tools | Role::Bridge(_) => &[],
        }
    }

    /// What an enclave of this role in `namespace` may publish and subscribe.
    pub fn rules(self, namespace: &str) -> Result<Rules, Sros2Error> {
        if let Role::Bridge(side) = self {
            return bridge_rules(side, namespace);
        }
        let mut r = rules(self.nodes(), namespace)?;
        if self == Role::Tools {
            for t in topics::all() {
                let dds = format!("rt/{}", in_namespace(namespace, t.name));
                r.publish.insert(dds.clone());
                r.subscribe.insert(dds);
            }
            for c in topics::CALLABLES {
                callable_rules(namespace, c, Side::Client, &mut r);
            }
            for pattern in ["rq/*", "rr/*"] {
                r.publish.insert(pattern.to_string());
                r.subscribe.insert(pattern.to_string());
            }
            r.subscribe.insert("rt/rosout".to_string());
        }
        Ok(r)
    }

    /// The role of an enclave when none is given: the Pi's for `/eezybot/pi`, a WAN
    /// bridge's for `/eezybot/bridge_pc` and `/eezybot/bridge_pi`, the operator PC's for
    /// any other (a second operator PC, a tools enclave).
    pub fn of_enclave(enclave: &str) -> Role {
        match enclave {
            PI_ENCLAVE => Role::Pi,
            BRIDGE_PC_ENCLAVE => Role::Bridge(crossing::Side::Pc),
            BRIDGE_PI_ENCLAVE => Role::Bridge(crossing::Side::Pi),
            _ => Role::Pc,
        }
    }

    /// The name `parse` takes (`pc`, `bridge_pi`).
    pub fn name(self) -> &'static str {
        match self {
            Role::Pc => "pc",
            Role::Pi => "pi",
            Role::Tools => "tools",
            Role::Bridge(crossing::Side::Pc) => "bridge_pc",
            Role::Bridge(crossing::Side::Pi) => "bridge_pi",
        }
    }
}

/// The domains a rule applies to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Domains {
    /// Every ROS domain, 0 … [`MAX_DOMAIN_ID`] (`<id_range>`).
    All,
    /// One domain (`<id>`).
    Id(u32),
}

impl Domains {
    /// One domain, checked to be 0 … [`MAX_DOMAIN_ID`].
    pub fn id(domain: u32) -> Result<Domains, Sros2Error> {
        if domain > MAX_DOMAIN_ID {
            return Err(Sros2Error::Domain { domain });
        }
        Ok(Domains::Id(domain))
    }

    fn xml(self, indent: &str) -> String {
        match self {
            Domains::All => format!(
                "{indent}<domains>\n{indent}  <id_range>\n{indent}    <min>0</min>\n{indent}    <max>{MAX_DOMAIN_ID}</max>\n{indent}  </id_range>\n{indent}</domains>\n"
            ),
            Domains::Id(d) => format!("{indent}<domains>\n{indent}  <id>{d}</id>\n{indent}</domains>\n"),
        }
    }
}

/// A validity period, as the permissions document writes it (XSD `dateTime` in UTC
/// without a zone, `2026-11-24T00:08:48`, as sros2 writes the certificate's dates).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Validity {
    not_before: String,
    not_after: String,
}

impl Validity {
    /// From two `YYYY-MM-DDThh:mm:ss` texts (a trailing `Z` is accepted and dropped).
    pub fn new(not_before: &str, not_after: &str) -> Result<Validity, Sros2Error> {
        let nb = parse_time(not_before)?;
        let na = parse_time(not_after)?;
        if na < nb {
            return Err(Sros2Error::Validity {
                not_before: not_before.to_string(),
                not_after: not_after.to_string(),
            });
        }
        Ok(Validity {
            not_before: format_time(nb),
            not_after: format_time(na),
        })
    }

    /// From two Unix times, seconds.
    pub fn from_unix(not_before: i64, not_after: i64) -> Result<Validity, Sros2Error> {
        Validity::new(&format_time(not_before), &format_time(not_after))
    }

    /// Start.
    pub fn not_before(&self) -> &str {
        &self.not_before
    }

    /// End.
    pub fn not_after(&self) -> &str {
        &self.not_after
    }
}

/// Days since 1970-01-01 of a civil date (Howard Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The civil date of a day since 1970-01-01.
pub(crate) fn civil_from_days(z: i64) -> (i64, i64, i64) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    (
        if m <= 2 {
            yoe + era * 400 + 1
        } else {
            yoe + era * 400
        },
        m,
        d,
    )
}

/// Unix seconds as `YYYY-MM-DDThh:mm:ss` (UTC).
pub fn format_time(unix_s: i64) -> String {
    let days = unix_s.div_euclid(86_400);
    let secs = unix_s.rem_euclid(86_400);
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}",
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

/// `YYYY-MM-DDThh:mm:ss` (UTC; a trailing `Z` is accepted) as Unix seconds.
pub fn parse_time(text: &str) -> Result<i64, Sros2Error> {
    let bad = || Sros2Error::Time {
        value: text.to_string(),
    };
    let t = text.strip_suffix('Z').unwrap_or(text);
    let b = t.as_bytes();
    let shape_ok = b.len() == 19
        && b.iter().enumerate().all(|(i, c)| match i {
            4 | 7 => *c == b'-',
            10 => *c == b'T',
            13 | 16 => *c == b':',
            _ => c.is_ascii_digit(),
        });
    if !shape_ok {
        return Err(bad());
    }
    let num = |r: std::ops::Range<usize>| t[r].parse::<i64>().map_err(|_| bad());
    let (y, mo, d, h, mi, s) = (
        num(0..4)?,
        num(5..7)?,
        num(8..10)?,
        num(11..13)?,
        num(14..16)?,
        num(17..19)?,
    );
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let month_days = [
        31,
        if leap { 29 } else { 28 },
        31,
        30,
        31,
        30,
        31,
        31,
        30,
        31,
        30,
        31,
    ];
    if !(1..=12).contains(&mo) || h > 23 || mi > 59 || s > 60 {
        return Err(bad());
    }
    let max_day = month_days.get((mo - 1) as usize).copied().unwrap_or(0);
    if d < 1 || d > max_day {
        return Err(bad());
    }
    Ok(days_from_civil(y, mo, d) * 86_400 + h * 3600 + mi * 60 + s)
}

/// `s` with `&`, `<`, `>`, `"` and `'` escaped for XML text and attributes.
pub fn xml_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

/// Check one token of a ROS name: `[A-Za-z_][A-Za-z0-9_]*` (rcl allows a leading digit
/// in a namespace token but not in a node name; we are strict everywhere).
fn token_problem(token: &str) -> Option<String> {
    let mut chars = token.chars();
    match chars.next() {
        None => Some("it has an empty part (`//` or a trailing `/`)".to_string()),
        Some(c) if !(c.is_ascii_alphabetic() || c == '_') => {
            Some(format!("`{token}` must start with a letter or `_`"))
        }
        Some(_) => chars
            .find(|c| !(c.is_ascii_alphanumeric() || *c == '_'))
            .map(|c| format!("`{token}` has `{c}`: only letters, digits and `_`")),
    }
}

/// What is wrong with an absolute ROS namespace (`/`, `/arm2`, `/eezybot/pi`), if
/// anything.
fn namespace_problem(ns: &str) -> Option<String> {
    if ns == "/" {
        return None;
    }
    let Some(rest) = ns.strip_prefix('/') else {
        return Some("it must start with `/`".to_string());
    };
    rest.split('/').find_map(token_problem)
}

/// Check an enclave path (`/eezybot/pi`).
pub fn check_enclave(enclave: &str) -> Result<(), Sros2Error> {
    checked(enclave, |enclave, why| Sros2Error::Enclave { enclave, why })
}

/// Check a namespace (`/`, `/arm2`).
pub fn check_namespace(namespace: &str) -> Result<(), Sros2Error> {
    checked(namespace, |namespace, why| Sros2Error::Namespace {
        namespace,
        why,
    })
}

/// `ns`'s [`namespace_problem`], if any, as the `error` of it and why.
fn checked(ns: &str, error: fn(String, String) -> Sros2Error) -> Result<(), Sros2Error> {
    namespace_problem(ns).map_or(Ok(()), |why| Err(error(ns.to_string(), why)))
}

/// The node of a role in the contract (`gui_bridge (record)` → `gui_bridge`).
pub fn node_of(role: &str) -> &str {
    role.split(' ').next().unwrap_or(role)
}

/// Roles of the contract that run beside either half of the graph, so that every
/// enclave of our nodes is granted what they use: a leader arm's reader runs on the PC
/// or on the Pi, wherever the leader's cable goes.
pub const EITHER_HALF: &[&str] = &[topics::LEADER_READER];

/// Whether the role `role` of the contract (`compute_ik`, `gui_bridge (record)`) runs
/// in the enclave of `nodes`: its node is one of them, or it is one of [`EITHER_HALF`]
/// (in an enclave of any of our nodes).
fn runs_in(role: &str, nodes: &BTreeSet<&str>) -> bool {
    nodes.contains(node_of(role)) || (EITHER_HALF.contains(&role) && !nodes.is_empty())
}

/// Every role the contract names: the publishers and subscribers of its topics, the
/// servers and clients of its actions and services.
fn contract_roles() -> Vec<&'static str> {
    let topics = topics::all();
    let mut roles: Vec<&'static str> = topics
        .iter()
        .flat_map(|t| t.publishers.iter().chain(t.subscribers))
        .copied()
        .collect();
    roles.extend(
        topics::CALLABLES
            .iter()
            .flat_map(|c| c.servers.iter().chain(c.clients))
            .copied(),
    );
    roles
}

/// Every node of ours the contract names.
pub fn contract_nodes() -> BTreeSet<&'static str> {
    contract_roles().into_iter().map(node_of).collect()
}

/// The DDS topic names an enclave may publish and subscribe.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Rules {
    /// Published (`rt/servo_state`, `rr/serial_node/get_parametersReply`, …), sorted.
    pub publish: BTreeSet<String>,
    /// Subscribed (`rt/servo_angles`, `rq/serial_node/get_parametersRequest`, …), sorted.
    pub subscribe: BTreeSet<String>,
}

/// `<ns>/<name>` without the leading `/` (`arm2/xyz_target`; `xyz_target` in `/`).
fn in_namespace(namespace: &str, name: &str) -> String {
    let ns = namespace.trim_matches('/');
    if ns.is_empty() {
        name.to_string()
    } else {
        format!("{ns}/{name}")
    }
}

/// What the nodes `nodes` in `namespace` publish and subscribe, as DDS topic names:
/// their contract topics (`rt/<ns>/<topic>`), the contract actions and services they
/// serve or call ([`topics::CALLABLES`]), their parameter services (server side), the
/// parameter services they call on other nodes (client side), and the graph topics
/// every node uses ([`GRAPH_PUBLISH`], [`GRAPH_SUBSCRIBE`]). A role of
/// [`EITHER_HALF`] runs in the enclave of any of our nodes.
pub fn rules<S: AsRef<str>>(nodes: &[S], namespace: &str) -> Result<Rules, Sros2Error> {
    check_namespace(namespace)?;
    let known = contract_nodes();
    let nodes: BTreeSet<&str> = nodes.iter().map(|n| n.as_ref()).collect();
    for n in &nodes {
        if !known.contains(n) {
            return Err(Sros2Error::UnknownNode {
                node: n.to_string(),
                known: known.iter().copied().collect::<Vec<_>>().join(", "),
            });
        }
    }
    let mut r = Rules::default();
    for t in topics::all() {
        let dds = format!("rt/{}", in_namespace(namespace, t.name));
        if t.publishers.iter().any(|p| runs_in(p, &nodes)) {
            r.publish.insert(dds.clone());
        }
        if t.subscribers.iter().any(|s| runs_in(s, &nodes)) {
            r.subscribe.insert(dds);
        }
    }
    for c in topics::CALLABLES {
        if c.servers.iter().any(|s| runs_in(s, &nodes)) {
            callable_rules(namespace, c, Side::Server, &mut r);
        }
        if c.clients.iter().any(|s| runs_in(s, &nodes)) {
            callable_rules(namespace, c, Side::Client, &mut r);
        }
    }
    for n in &nodes {
        let fqn = in_namespace(namespace, n);
        for srv in PARAMETER_SERVICES {
            r.subscribe.insert(format!("rq/{fqn}/{srv}Request"));
            r.publish.insert(format!("rr/{fqn}/{srv}Reply"));
        }
    }
    for (caller, callee, services) in REMOTE_PARAMETER_CALLS {
        if nodes.contains(caller) {
            let fqn = in_namespace(namespace, callee);
            for srv in *services {
                r.publish.insert(format!("rq/{fqn}/{srv}Request"));
                r.subscribe.insert(format!("rr/{fqn}/{srv}Reply"));
            }
        }
    }
    r.publish
        .extend(GRAPH_PUBLISH.iter().map(|s| s.to_string()));
    r.subscribe
        .extend(GRAPH_SUBSCRIBE.iter().map(|s| s.to_string()));
    Ok(r)
}

/// What the WAN bridge of `side` in `namespace` publishes and subscribes
/// ([`Role::Bridge`]): the topics of [`crossing::CROSSING`] that come in there
/// (published: the bridge writes them to the local subscribers), those that go out
/// from there (subscribed: it reads them from the local publishers), its own
/// diagnostics ([`BRIDGE_OWN_PUBLISH`], published) and [`BRIDGE_GRAPH`] both ways.
pub fn bridge_rules(side: crossing::Side, namespace: &str) -> Result<Rules, Sros2Error> {
    check_namespace(namespace)?;
    let dds = |t: &str| format!("rt/{}", in_namespace(namespace, t));
    let mut r = Rules::default();
    r.publish.extend(side.incoming().into_iter().map(dds));
    r.publish.extend(BRIDGE_OWN_PUBLISH.iter().map(|t| dds(t)));
    r.subscribe.extend(side.outgoing().into_iter().map(dds));
    for t in BRIDGE_GRAPH {
        r.publish.insert(t.to_string());
        r.subscribe.insert(t.to_string());
    }
    Ok(r)
}

/// The services of a ROS 2 action (`<action>/_action/<service>`).
const ACTION_SERVICES: [&str; 3] = ["send_goal", "cancel_goal", "get_result"];

/// Which end of an action or service.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    /// Takes the requests, publishes the replies (and an action's feedback and status).
    Server,
    /// Publishes the requests, takes the replies (and an action's feedback and status).
    Client,
}

/// The DDS topics of one end of an action or service of the contract, in `namespace`:
/// a service `<s>` is `rq/<s>Request` and `rr/<s>Reply`; an action `<a>` is the three
/// services `<a>/_action/{send_goal,cancel_goal,get_result}` and the topics
/// `rt/<a>/_action/{feedback,status}` (rcl_action's names).
fn callable_rules(namespace: &str, c: &topics::Callable, side: Side, r: &mut Rules) {
    let name = in_namespace(namespace, c.name);
    let services = match c.kind {
        topics::CallableKind::Service => vec![name.clone()],
        topics::CallableKind::Action => ACTION_SERVICES
            .iter()
            .map(|srv| format!("{name}/_action/{srv}"))
            .collect(),
    };
    let (requests, replies) = match side {
        Side::Server => (&mut r.subscribe, &mut r.publish),
        Side::Client => (&mut r.publish, &mut r.subscribe),
    };
    for s in services {
        requests.insert(format!("rq/{s}Request"));
        replies.insert(format!("rr/{s}Reply"));
    }
    if c.kind == topics::CallableKind::Action {
        let topics = ["feedback", "status"].map(|t| format!("rt/{name}/_action/{t}"));
        let feedback_and_status = match side {
            Side::Server => &mut r.publish,
            Side::Client => &mut r.subscribe,
        };
        feedback_and_status.extend(topics);
    }
}

/// One enclave's grant: who (`enclave`, the certificate's `CN`), for what in which
/// namespace, when and in which domains.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Grant {
    /// The enclave path, also the subject `CN=<enclave>` of its certificate.
    pub enclave: String,
    /// What runs in it.
    pub role: Role,
    /// Their namespace (`/`, or `/arm2` for `-r __ns:=/arm2`).
    pub namespace: String,
    /// The validity of the grant (sros2: the enclave certificate's).
    pub validity: Validity,
    /// The domains it applies in.
    pub domains: Domains,
}

const GOVERNANCE_HEAD: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
"#;

const GOVERNANCE_TAIL: &str = r#"      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
"#;

/// The governance document: sros2's default (`policy/defaults/dds/governance.xml`) for
/// `domains`: unauthenticated participants refused, join access control, discovery and
/// liveliness encrypted, RTPS signed, and for every topic read and write access control
/// with metadata and data encrypted.
pub fn governance_xml(domains: Domains) -> String {
    format!(
        "{GOVERNANCE_HEAD}{}{GOVERNANCE_TAIL}",
        domains.xml("      ")
    )
}

fn topics_block(out: &mut String, what: &str, names: &BTreeSet<String>) {
    if names.is_empty() {
        return;
    }
    let _ = writeln!(out, "        <{what}>\n          <topics>");
    for n in names {
        let _ = writeln!(out, "            <topic>{}</topic>", xml_escape(n));
    }
    let _ = writeln!(out, "          </topics>\n        </{what}>");
}

/// The permissions document of one enclave, in the shape of sros2's `permissions.xml`:
/// `<dds><permissions><grant name="/eezybot/pi"><subject_name>CN=/eezybot/pi</subject_name>
/// <validity>…</validity><allow_rule><domains>…</domains><publish>…</publish>
/// <subscribe>…</subscribe></allow_rule><default>DENY</default></grant></permissions></dds>`.
pub fn permissions_xml(grant: &Grant) -> Result<String, Sros2Error> {
    check_enclave(&grant.enclave)?;
    let r = grant.role.rules(&grant.namespace)?;
    let enclave = xml_escape(&grant.enclave);
    let mut out = String::from(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<dds xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" xsi:noNamespaceSchemaLocation=\"http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd\">\n  <permissions>\n",
    );
    let _ = writeln!(out, "    <grant name=\"{enclave}\">");
    let _ = writeln!(out, "      <subject_name>CN={enclave}</subject_name>");
    let _ = writeln!(
        out,
        "      <validity>\n        <not_before>{}</not_before>\n        <not_after>{}</not_after>\n      </validity>",
        grant.validity.not_before, grant.validity.not_after
    );
    out.push_str("      <allow_rule>\n");
    out.push_str(&grant.domains.xml("        "));
    topics_block(&mut out, "publish", &r.publish);
    topics_block(&mut out, "subscribe", &r.subscribe);
    out.push_str("      </allow_rule>\n      <default>DENY</default>\n    </grant>\n  </permissions>\n</dds>\n");
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grant(enclave: &str, role: Role, ns: &str) -> Grant {
        Grant {
            enclave: enclave.into(),
            role,
            namespace: ns.into(),
            validity: Validity::new("2026-11-24T00:08:48", "2036-11-22T00:08:48").unwrap(),
            domains: Domains::All,
        }
    }

    /// The topics inside `<publish>` (or `<subscribe>`) of a permissions document.
    fn section(xml: &str, what: &str) -> Vec<String> {
        let start = xml.find(&format!("<{what}>")).map(|i| i + what.len() + 2);
        let end = xml.find(&format!("</{what}>"));
        match (start, end) {
            (Some(s), Some(e)) => xml[s..e]
                .split("<topic>")
                .skip(1)
                .filter_map(|t| t.split("</topic>").next())
                .map(str::to_string)
                .collect(),
            _ => vec![],
        }
    }

    #[test]
    fn pi_publishes_servo_state_and_cannot_publish_targets() {
        let xml = permissions_xml(&grant(PI_ENCLAVE, Role::Pi, "/")).unwrap();
        let publish = section(&xml, "publish");
        let subscribe = section(&xml, "subscribe");
        assert!(
            publish.contains(&"rt/servo_state".to_string()),
            "{publish:?}"
        );
        assert!(publish.contains(&"rt/diagnostics".to_string()));
        for t in [
            "rt/xyz_target",
            "rt/xyz_line_target",
            "rt/servo_angles",
            "rt/estop",
            "rt/joint_states",
            "rt/tf",
        ] {
            assert!(!publish.contains(&t.to_string()), "{t} in {publish:?}");
        }
        assert!(subscribe.contains(&"rt/servo_angles".to_string()));
        assert!(subscribe.contains(&"rt/estop".to_string()));
        assert!(!subscribe.contains(&"rt/xyz_target".to_string()));
        assert!(!subscribe.contains(&"rt/xyz_line_target".to_string()));
        // its own parameter services, not compute_ik's
        assert!(subscribe.contains(&"rq/serial_node/set_parametersRequest".to_string()));
        assert!(publish.contains(&"rr/serial_node/set_parametersReply".to_string()));
        assert!(!publish.iter().any(|t| t.contains("compute_ik")));
        assert!(!subscribe.iter().any(|t| t.contains("compute_ik")));
    }

    #[test]
    fn the_calibration_wizard_may_call_the_controller_manager() {
        let r = rules(PC_NODES, "/arm2").unwrap();
        for s in ["list_controllers", "switch_controller"] {
            let request = format!("rq/arm2/controller_manager/{s}Request");
            let reply = format!("rr/arm2/controller_manager/{s}Reply");
            // gui_bridge's client and compute_ik's server, in one enclave
            assert!(
                r.publish.contains(&request) && r.subscribe.contains(&reply),
                "{s}"
            );
            assert!(
                r.subscribe.contains(&request) && r.publish.contains(&reply),
                "{s}"
            );
        }
    }

    #[test]
    fn pc_publishes_the_targets_and_calls_compute_ik_parameters() {
        let r = rules(PC_NODES, "/").unwrap();
        for t in [
            "rt/xyz_target",
            "rt/xyz_line_target",
            "rt/gripper_target",
            "rt/joint_target",
            "rt/estop",
            "rt/joint_states",
            "rt/servo_angles",
            "rt/tf",
            "rt/tf_static",
            "rt/robot_description",
            "rt/diagnostics",
        ] {
            assert!(r.publish.contains(t), "{t}");
        }
        assert!(!r.publish.contains("rt/servo_state"));
        assert!(
            !r.publish.contains("rt/pose_target"),
            "only outside tools publish it"
        );
        assert!(r.subscribe.contains("rt/servo_state"));
        assert!(r.subscribe.contains("rt/pose_target"));
        // gui_bridge's client of compute_ik's parameters: request out, reply in
        assert!(r.publish.contains("rq/compute_ik/set_parametersRequest"));
        assert!(r.subscribe.contains("rr/compute_ik/set_parametersReply"));
        // and compute_ik's server side
        assert!(r.subscribe.contains("rq/compute_ik/set_parametersRequest"));
        assert!(r.publish.contains("rr/compute_ik/set_parametersReply"));
        for node in PC_NODES {
            for srv in PARAMETER_SERVICES {
                assert!(r.subscribe.contains(&format!("rq/{node}/{srv}Request")));
                assert!(r.publish.contains(&format!("rr/{node}/{srv}Reply")));
            }
        }
    }

    #[test]
    fn every_enclave_has_the_graph_topics() {
        for nodes in [PC_NODES, PI_NODES] {
            let r = rules(nodes, "/").unwrap();
            for t in ["ros_discovery_info", "rt/parameter_events", "rt/rosout"] {
                assert!(r.publish.contains(t), "{t}");
            }
            for t in ["ros_discovery_info", "rt/parameter_events", "rt/clock"] {
                assert!(r.subscribe.contains(t), "{t}");
            }
            assert!(!r.subscribe.contains("rt/rosout"));
        }
    }

    #[test]
    fn every_contract_endpoint_is_allowed_to_its_enclave() {
        let pc = rules(PC_NODES, "/").unwrap();
        let pi = rules(PI_NODES, "/").unwrap();
        let enclave_of = |node: &str| {
            if PC_NODES.contains(&node) {
                Some(&pc)
            } else if PI_NODES.contains(&node) {
                Some(&pi)
            } else {
                None
            }
        };
        for t in topics::all() {
            let dds = format!("rt/{}", t.name);
            for p in t.publishers {
                let r = enclave_of(node_of(p)).unwrap_or_else(|| panic!("{p} in no enclave"));
                assert!(r.publish.contains(&dds), "{p} publishes {dds}");
            }
            for s in t.subscribers {
                let r = enclave_of(node_of(s)).unwrap_or_else(|| panic!("{s} in no enclave"));
                assert!(r.subscribe.contains(&dds), "{s} subscribes {dds}");
            }
            assert!(
                pc.publish.contains(&dds)
                    || pi.publish.contains(&dds)
                    || pc.subscribe.contains(&dds)
                    || pi.subscribe.contains(&dds),
                "{dds} is in no enclave"
            );
        }
        // and nothing beyond: a topic only the PC's nodes publish is not the Pi's
        for t in topics::all() {
            let dds = format!("rt/{}", t.name);
            let pi_publishes = t.publishers.iter().any(|p| PI_NODES.contains(&node_of(p)));
            assert_eq!(pi.publish.contains(&dds), pi_publishes, "{dds}");
            let pi_subscribes = t.subscribers.iter().any(|p| PI_NODES.contains(&node_of(p)));
            assert_eq!(pi.subscribe.contains(&dds), pi_subscribes, "{dds}");
        }
        for c in topics::CALLABLES {
            let request = |s: &str| format!("rq/{s}Request");
            let first = match c.kind {
                topics::CallableKind::Service => c.name.to_string(),
                topics::CallableKind::Action => format!("{}/_action/send_goal", c.name),
            };
            for s in c.servers {
                let r = enclave_of(node_of(s)).unwrap_or_else(|| panic!("{s} in no enclave"));
                assert!(r.subscribe.contains(&request(&first)), "{s} serves {first}");
            }
            for s in c.clients {
                let r = enclave_of(node_of(s)).unwrap_or_else(|| panic!("{s} in no enclave"));
                assert!(r.publish.contains(&request(&first)), "{s} calls {first}");
            }
            let pi_serves = c.servers.iter().any(|s| PI_NODES.contains(&node_of(s)));
            assert_eq!(
                pi.subscribe.contains(&request(&first)),
                pi_serves,
                "{first}"
            );
        }
        let all: BTreeSet<&str> = PC_NODES.iter().chain(PI_NODES).copied().collect();
        assert_eq!(
            all,
            contract_nodes(),
            "every node of the contract has an enclave"
        );
    }

    #[test]
    fn a_namespace_moves_topics_and_services_but_not_the_absolute_ones() {
        let r = rules(PI_NODES, "/arm2").unwrap();
        assert!(r.publish.contains("rt/arm2/servo_state"));
        assert!(!r.publish.contains("rt/servo_state"));
        assert!(r
            .subscribe
            .contains("rq/arm2/serial_node/get_parametersRequest"));
        assert!(r.publish.contains("rt/rosout"));
        assert!(r.publish.contains("rt/parameter_events"));
        assert!(r.subscribe.contains("rt/clock"));
        let pc = rules(PC_NODES, "/a/b").unwrap();
        assert!(pc
            .publish
            .contains("rq/a/b/compute_ik/get_parametersRequest"));
        assert!(pc.publish.contains("rt/a/b/xyz_target"));
        assert_eq!(rules(PI_NODES, "/").unwrap(), rules(PI_NODES, "/").unwrap());
    }

    #[test]
    fn permissions_have_sros2_shape() {
        let xml = permissions_xml(&grant(PI_ENCLAVE, Role::Pi, "/")).unwrap();
        let order = [
            "<dds ",
            "<permissions>",
            "<grant name=\"/eezybot/pi\">",
            "<subject_name>CN=/eezybot/pi</subject_name>",
            "<validity>",
            "<not_before>2026-11-24T00:08:48</not_before>",
            "<not_after>2036-11-22T00:08:48</not_after>",
            "</validity>",
            "<allow_rule>",
            "<domains>",
            "<id_range>",
            "<min>0</min>",
            "<max>230</max>",
            "</domains>",
            "<publish>",
            "<topics>",
            "</publish>",
            "<subscribe>",
            "</subscribe>",
            "</allow_rule>",
            "<default>DENY</default>",
            "</grant>",
            "</permissions>",
            "</dds>",
        ];
        let mut at = 0;
        for tag in order {
            let i = xml[at..]
                .find(tag)
                .unwrap_or_else(|| panic!("{tag} after {at} in\n{xml}"));
            at += i + tag.len();
        }
        assert_eq!(xml.matches("<grant ").count(), 1);
        assert_eq!(xml.matches("<allow_rule>").count(), 1);
        assert_eq!(xml.matches('<').count(), xml.matches('>').count());
        let one = Grant {
            domains: Domains::id(7).unwrap(),
            ..grant(PI_ENCLAVE, Role::Pi, "/")
        };
        let xml = permissions_xml(&one).unwrap();
        assert!(
            xml.contains("<domains>\n          <id>7</id>\n        </domains>"),
            "{xml}"
        );
        assert!(!xml.contains("id_range"));
    }

    #[test]
    fn governance_is_sros2_default() {
        let xml = governance_xml(Domains::All);
        for line in [
            "<allow_unauthenticated_participants>false</allow_unauthenticated_participants>",
            "<enable_join_access_control>true</enable_join_access_control>",
            "<discovery_protection_kind>ENCRYPT</discovery_protection_kind>",
            "<liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>",
            "<rtps_protection_kind>SIGN</rtps_protection_kind>",
            "<topic_expression>*</topic_expression>",
            "<enable_read_access_control>true</enable_read_access_control>",
            "<enable_write_access_control>true</enable_write_access_control>",
            "<metadata_protection_kind>ENCRYPT</metadata_protection_kind>",
            "<data_protection_kind>ENCRYPT</data_protection_kind>",
            "<min>0</min>",
            "<max>230</max>",
        ] {
            assert!(xml.contains(line), "{line}");
        }
        assert!(governance_xml(Domains::Id(3)).contains("<id>3</id>"));
        assert!(!xml.contains("NONE"));
    }

    #[test]
    fn the_recorder_and_the_panel_s_record_card_are_granted_what_they_use() {
        for ns in ["/", "/arm2"] {
            let pc = rules(PC_NODES, ns).unwrap();
            let pi = rules(PI_NODES, ns).unwrap();
            let at = |s: &str| in_namespace(ns, s);
            for t in [
                "servo_state",
                "joint_states",
                "leader/joint_states",
                "leader/deadman",
                "camera/image_raw/compressed",
            ] {
                assert!(pc.subscribe.contains(&format!("rt/{}", at(t))), "{ns} {t}");
            }
            assert!(pc.publish.contains(&format!("rt/{}", at("diagnostics"))));
            for s in ["start_episode", "save_episode", "discard_episode"] {
                let request = format!("rq/{}Request", at(&format!("recorder/{s}")));
                let reply = format!("rr/{}Reply", at(&format!("recorder/{s}")));
                // the recorder's server and gui_bridge's client, in one enclave
                assert!(
                    pc.subscribe.contains(&request) && pc.publish.contains(&reply),
                    "{s}"
                );
                assert!(
                    pc.publish.contains(&request) && pc.subscribe.contains(&reply),
                    "{s}"
                );
                assert!(!pi.publish.contains(&request) && !pi.subscribe.contains(&request));
            }
            for srv in PARAMETER_SERVICES {
                let request = format!("rq/{}/{srv}Request", at("recorder"));
                assert!(pc.subscribe.contains(&request), "{srv}");
            }
            // the Record card sets the recorder's task
            let set = format!("rq/{}/set_parametersRequest", at("recorder"));
            assert!(pc.publish.contains(&set));
            assert!(!pi.publish.contains(&set));
        }
    }

    #[test]
    fn names_are_escaped_and_checked() {
        assert_eq!(xml_escape("a<b>&\"c'"), "a&lt;b&gt;&amp;&quot;c&apos;");
        assert!(check_enclave("/eezybot/pi").is_ok());
        assert!(check_enclave("/").is_ok());
        for bad in [
            "eezybot/pi",
            "/eezybot/",
            "/eez bot",
            "//x",
            "/a<b",
            "/1abc",
            "",
        ] {
            assert!(check_enclave(bad).is_err(), "{bad}");
        }
        assert!(matches!(
            rules(PI_NODES, "arm2"),
            Err(Sros2Error::Namespace { .. })
        ));
        assert!(matches!(
            rules(&["turtlesim"], "/"),
            Err(Sros2Error::UnknownNode { .. })
        ));
        let g = Grant {
            enclave: "/a&b".into(),
            ..grant(PI_ENCLAVE, Role::Pi, "/")
        };
        assert!(permissions_xml(&g).is_err());
    }

    #[test]
    fn tools_may_use_every_topic_and_service_but_are_still_denied_the_rest() {
        let r = Role::Tools.rules("/arm2").unwrap();
        for t in topics::all() {
            let dds = format!("rt/arm2/{}", t.name);
            assert!(
                r.publish.contains(&dds) && r.subscribe.contains(&dds),
                "{dds}"
            );
        }
        assert!(r.subscribe.contains("rt/rosout") && r.publish.contains("rt/rosout"));
        assert!(r.publish.contains("rq/*") && r.subscribe.contains("rr/*"));
        assert!(!r.publish.contains("*") && !r.publish.contains("rt/*"));
        assert!(
            !r.publish.contains("rt/xyz_target"),
            "not outside its namespace"
        );
        let xml = permissions_xml(&grant("/eezybot/tools", Role::Tools, "/")).unwrap();
        assert!(xml.contains("<topic>rt/pose_target</topic>"));
        assert!(xml.contains("<default>DENY</default>"));
    }

    #[test]
    fn roles() {
        assert_eq!(Role::of_enclave("/eezybot/pi"), Role::Pi);
        assert_eq!(Role::of_enclave("/eezybot/pc"), Role::Pc);
        assert_eq!(Role::of_enclave("/eezybot/pc2"), Role::Pc);
        assert_eq!(Role::parse("pi"), Some(Role::Pi));
        assert_eq!(Role::parse("tools"), Some(Role::Tools));
        assert_eq!(Role::parse("PC"), None);
        for (enclave, role) in [
            (BRIDGE_PC_ENCLAVE, Role::Bridge(crossing::Side::Pc)),
            (BRIDGE_PI_ENCLAVE, Role::Bridge(crossing::Side::Pi)),
        ] {
            assert_eq!(Role::of_enclave(enclave), role);
            assert_eq!(Role::parse(role.name()), Some(role));
        }
    }

    #[test]
    fn a_bridge_may_publish_what_comes_in_and_subscribe_what_goes_out_and_nothing_else() {
        let pi = Role::Bridge(crossing::Side::Pi).rules("/").unwrap();
        let set = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<BTreeSet<_>>();
        assert_eq!(
            pi.publish,
            set(&[
                "ros_discovery_info",
                "rt/diagnostics",
                "rt/estop",
                "rt/servo_angles"
            ])
        );
        assert_eq!(
            pi.subscribe,
            set(&[
                "ros_discovery_info",
                "rt/camera/image_raw/compressed",
                "rt/diagnostics",
                "rt/servo_state"
            ])
        );
        let pc = Role::Bridge(crossing::Side::Pc).rules("/arm2").unwrap();
        assert_eq!(
            pc.publish,
            set(&[
                "ros_discovery_info",
                "rt/arm2/camera/image_raw/compressed",
                "rt/arm2/diagnostics",
                "rt/arm2/estop",
                "rt/arm2/robot_description",
                "rt/arm2/servo_state"
            ])
        );
        assert_eq!(
            pc.subscribe,
            set(&[
                "ros_discovery_info",
                "rt/arm2/estop",
                "rt/arm2/robot_description",
                "rt/arm2/servo_angles"
            ])
        );
        // what one site's bridge writes, the other's reads: the same topics
        for (a, b) in [(&pi, &pc), (&pc, &pi)] {
            for t in a.publish.iter().filter(|t| t.starts_with("rt/")) {
                let name = t.trim_start_matches("rt/").trim_start_matches("arm2/");
                assert!(
                    crossing::CROSSING.iter().any(|c| c.topic == name),
                    "{t} does not cross"
                );
            }
            assert!(!b.publish.contains("rt/xyz_target"));
        }
        assert!(Role::Bridge(crossing::Side::Pc).rules("arm2").is_err());
        assert!(Role::Bridge(crossing::Side::Pc).nodes().is_empty());
        let xml = permissions_xml(&grant(
            BRIDGE_PI_ENCLAVE,
            Role::Bridge(crossing::Side::Pi),
            "/",
        ))
        .unwrap();
        assert!(xml.contains("<subject_name>CN=/eezybot/bridge_pi</subject_name>"));
        assert_eq!(section(&xml, "publish").len(), 4);
    }

    #[test]
    fn times_round_trip() {
        assert_eq!(format_time(0), "1970-01-01T00:00:00");
        assert_eq!(parse_time("1970-01-01T00:00:00").unwrap(), 0);
        assert_eq!(parse_time("2000-03-01T00:00:00Z").unwrap(), 951_868_800);
        for t in [
            -86_401,
            1,
            951_782_400,
            1_764_115_728,
            4_102_444_800,
            253_402_300_799,
        ] {
            assert_eq!(parse_time(&format_time(t)).unwrap(), t, "{t}");
        }
        for bad in [
            "2026-02-30T00:00:00",
            "2026-13-01T00:00:00",
            "2026-1-01T00:00:00",
            "x",
        ] {
            assert!(parse_time(bad).is_err(), "{bad}");
        }
        assert!(Validity::new("2030-01-01T00:00:00", "2020-01-01T00:00:00").is_err());
        let v = Validity::from_unix(0, 86_400).unwrap();
        assert_eq!(v.not_after(), "1970-01-02T00:00:00");
        assert!(Domains::id(231).is_err());
        assert_eq!(Domains::id(230).unwrap(), Domains::Id(230));
    }

    #[test]
    fn compute_ik_serves_the_controllers_and_a_tools_enclave_may_use_them() {
        let pc = Role::Pc.rules("/arm2").unwrap();
        let send_goal = "arm2/arm_controller/follow_joint_trajectory/_action/send_goal";
        assert!(pc.subscribe.contains(&format!("rq/{send_goal}Request")));
        assert!(pc.publish.contains(&format!("rr/{send_goal}Reply")));
        assert!(pc
            .publish
            .contains("rt/arm2/gripper_controller/gripper_cmd/_action/status"));
        assert!(pc
            .subscribe
            .contains("rt/arm2/arm_controller/joint_trajectory"));
        assert!(pc
            .publish
            .contains("rt/arm2/arm_controller/controller_state"));
        let pi = Role::Pi.rules("/arm2").unwrap();
        assert!(!pi.subscribe.iter().any(|t| t.contains("arm_controller")));
        let tools = Role::Tools.rules("/arm2").unwrap();
        assert!(tools
            .publish
            .contains("rt/arm2/arm_controller/joint_trajectory"));
        assert!(tools
            .subscribe
            .contains("rt/arm2/arm_controller/follow_joint_trajectory/_action/feedback"));
    }
}
