//! SROS2 (DDS Security) for the bridge's DDS participant: the site's LAN may be secured
//! (`ROS_SECURITY_ENABLE=true`, launch_scripts/keystore.sh), and the bridge then joins it
//! under an enclave of its own, `/eezybot/bridge_pc` or `/eezybot/bridge_pi`, whose
//! permissions are exactly what crosses the WAN there ([`crate::CROSSING`], each way).
//!
//! The variables are read as rcl (and our nodes, `ros_plumbing::security`) read them:
//! - `ROS_SECURITY_ENABLE=true` (exactly) turns security on; anything else leaves it off.
//! - `ROS_SECURITY_STRATEGY=Enforce` (exactly) refuses to run without security: an
//!   unusable enclave stops the bridge (exit status 2) with a message naming the file.
//!   Anything else is *Permissive*: the bridge warns and runs unsecured.
//! - `ROS_SECURITY_KEYSTORE` is the keystore; the enclave is
//!   `ROS_SECURITY_ENCLAVE_OVERRIDE` if set, else `--enclave` (default
//!   `/eezybot/bridge_SIDE`); its six files are in `$KEYSTORE/enclaves/<enclave>`.
//!
//! The plugin creates its participant with no QoS, so the files cannot go in as
//! participant properties (as rmw_cyclonedds passes them): they go in as Cyclone DDS
//! configuration, `<Domain><Security>` in `CYCLONEDDS_URI` ([`cyclone_config`]), which
//! the plugin appends to its own settings. The three plugins (authentication, access
//! control, cryptography) are Cyclone's built-in ones, compiled into the bridge (cyclors'
//! `dds_security` feature, static build: no `<Library>` element, no .so file).

use std::path::{Path, PathBuf};

/// The files of an enclave, by their SROS2 names (as `keystore.sh` and `ros2 security`
/// make them).
pub const ENCLAVE_FILES: [&str; 6] = [
    "identity_ca.cert.pem",
    "cert.pem",
    "key.pem",
    "permissions_ca.cert.pem",
    "governance.p7s",
    "permissions.p7s",
];

/// What to do when security is on but the enclave cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// Stop (exit status 2).
    Enforce,
    /// Warn and run without security.
    Permissive,
}

impl std::fmt::Display for Strategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Strategy::Enforce => "Enforce",
            Strategy::Permissive => "Permissive",
        })
    }
}

/// Security is on: this enclave, in this directory, under this strategy.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Enclave {
    /// The enclave's name (`/eezybot/bridge_pi`).
    pub name: String,
    /// Its directory (`$ROS_SECURITY_KEYSTORE/enclaves/eezybot/bridge_pi`), absolute.
    pub dir: PathBuf,
    /// [`Strategy`]
    pub strategy: Strategy,
}

/// The default enclave of a side's bridge: `/eezybot/bridge_pc`, `/eezybot/bridge_pi`.
pub fn default_enclave(side: crate::Side) -> String {
    format!("/eezybot/bridge_{}", side.name())
}

/// An absolute name of `[A-Za-z0-9_]` components, none starting with a digit (rcl's
/// enclave names).
pub fn valid_enclave_name(name: &str) -> bool {
    name.starts_with('/')
        && name.len() < 256
        && name[1..].split('/').all(|c| {
            !c.is_empty()
                && !c.starts_with(|ch: char| ch.is_ascii_digit())
                && c.chars().all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
        })
}

/// The bridge's enclave from the `ROS_SECURITY_*` variables (read through `lookup`) and
/// `--enclave` (`enclave_arg`): `Ok(None)` when security is off, the enclave when its
/// six files are there and readable, else the strategy and why not (naming the file).
/// Cyclone DDS checks the rest (certificates, signatures, the permissions themselves)
/// when the participant is made.
pub fn plan(
    lookup: impl Fn(&str) -> Option<String>,
    enclave_arg: &str,
) -> Result<Option<Enclave>, (Strategy, String)> {
    if lookup("ROS_SECURITY_ENABLE").as_deref() != Some("true") {
        return Ok(None);
    }
    let strategy = if lookup("ROS_SECURITY_STRATEGY").as_deref() == Some("Enforce") {
        Strategy::Enforce
    } else {
        Strategy::Permissive
    };
    let fail = |why: String| Err((strategy, why));
    let keystore = match lookup("ROS_SECURITY_KEYSTORE") {
        Some(k) if !k.trim().is_empty() => PathBuf::from(k.trim()),
        _ => return fail("ROS_SECURITY_ENABLE is true but ROS_SECURITY_KEYSTORE is not set: set it to the keystore directory (launch_scripts/keystore.sh DIR makes one)".to_string()),
    };
    let name = lookup("ROS_SECURITY_ENCLAVE_OVERRIDE")
        .filter(|e| !e.is_empty())
        .unwrap_or_else(|| enclave_arg.to_string());
    if !valid_enclave_name(&name) {
        return fail(format!(
            "enclave `{name}` is not a valid enclave name (an absolute path of letters, digits and _, such as /eezybot/bridge_pi)"
        ));
    }
    let keystore = std::path::absolute(&keystore).unwrap_or(keystore);
    let dir = name
        .split('/')
        .filter(|c| !c.is_empty())
        .fold(keystore.join("enclaves"), |d, c| d.join(c));
    if !dir.is_dir() {
        return fail(format!(
            "enclave {name}: directory {} does not exist (no such enclave in keystore {}; make it with launch_scripts/keystore.sh {} --enclave {name})",
            dir.display(),
            keystore.display(),
            keystore.display()
        ));
    }
    for f in ENCLAVE_FILES {
        let path = dir.join(f);
        if let Err(e) = std::fs::File::open(&path) {
            let why = match e.kind() {
                std::io::ErrorKind::NotFound => "no such file".to_string(),
                std::io::ErrorKind::PermissionDenied => {
                    "permission denied (the key must be readable by the user the bridge runs as)"
                        .to_string()
                }
                _ => e.to_string(),
            };
            return fail(format!("{}: cannot read it: {why}", path.display()));
        }
    }
    Ok(Some(Enclave {
        name,
        dir,
        strategy,
    }))
}

/// `s` with `&`, `<`, `>`, `"` and `'` escaped for XML text.
fn xml_escape(s: &str) -> String {
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

fn file_uri(path: &Path) -> String {
    xml_escape(&format!("file:{}", path.display()))
}

/// The Cyclone DDS configuration that puts the participant under `enclave`: its
/// identity (certificate, key, identity CA) and access control (permissions CA,
/// governance, permissions), as `<CycloneDDS><Domain><Security>…`, inline XML for
/// `CYCLONEDDS_URI`. The governance's protection kinds (discovery, liveliness, RTPS
/// messages, each topic's metadata and data) are Cyclone's to apply, as every other
/// participant of the keystore does.
pub fn cyclone_config(enclave: &Enclave) -> String {
    let f = |name: &str| file_uri(&enclave.dir.join(name));
    format!(
        "<CycloneDDS><Domain><Security>\
<Authentication>\
<IdentityCertificate>{cert}</IdentityCertificate>\
<IdentityCA>{identity_ca}</IdentityCA>\
<PrivateKey>{key}</PrivateKey>\
<IncludeOptionalFields>true</IncludeOptionalFields>\
</Authentication>\
<AccessControl>\
<PermissionsCA>{permissions_ca}</PermissionsCA>\
<Governance>{governance}</Governance>\
<Permissions>{permissions}</Permissions>\
</AccessControl>\
</Security></Domain></CycloneDDS>",
        cert = f("cert.pem"),
        identity_ca = f("identity_ca.cert.pem"),
        key = f("key.pem"),
        permissions_ca = f("permissions_ca.cert.pem"),
        governance = f("governance.p7s"),
        permissions = f("permissions.p7s"),
    )
}

/// A Cyclone DDS configuration fragment that keeps a participant to itself: no
/// multicast, no peers, not even localhost (which Cyclone adds by itself when it has
/// no multicast: its SPDP then went to every participant index's port on 127.0.0.1),
/// no participant index: nothing is sent, nothing discovered. The bridge's check that
/// Cyclone takes the enclave creates one such participant before the plugin starts.
pub const ISOLATED: &str =
    "<CycloneDDS><Domain><General><AllowMulticast>false</AllowMulticast></General>\
<Discovery><ParticipantIndex>none</ParticipantIndex><Peers AddLocalhost=\"false\"></Peers>\
<Tag>eezybot_wan_bridge_enclave_check</Tag></Discovery></Domain></CycloneDDS>";

/// `CYCLONEDDS_URI` with `fragment` appended: the user's configuration first (an
/// `<Interfaces>` element, say), then ours.
pub fn with_fragment(user: Option<&str>, fragment: &str) -> String {
    match user.map(str::trim).filter(|u| !u.is_empty()) {
        Some(u) => format!("{u},{fragment}"),
        None => fragment.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(vars: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let vars: Vec<(String, String)> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |name| vars.iter().find(|(k, _)| k == name).map(|(_, v)| v.clone())
    }

    fn keystore(tag: &str, files: &[&str]) -> PathBuf {
        let root =
            std::env::temp_dir().join(format!("eezybot-wan-sros2-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let dir = root.join("enclaves/eezybot/bridge_pi");
        std::fs::create_dir_all(&dir).unwrap();
        for f in files {
            std::fs::write(dir.join(f), "x").unwrap();
        }
        root
    }

    #[test]
    fn off_unless_exactly_true() {
        for v in ["", "1", "TRUE", "True", "false"] {
            let e = env(&[("ROS_SECURITY_ENABLE", v), ("ROS_SECURITY_KEYSTORE", "/k")]);
            assert_eq!(plan(e, "/eezybot/bridge_pi"), Ok(None), "{v}");
        }
    }

    #[test]
    fn the_enclave_and_its_files() {
        let root = keystore("ok", &ENCLAVE_FILES);
        let ks = root.to_string_lossy().to_string();
        let base = [
            ("ROS_SECURITY_ENABLE", "true"),
            ("ROS_SECURITY_STRATEGY", "Enforce"),
            ("ROS_SECURITY_KEYSTORE", ks.as_str()),
        ];
        let e = plan(env(&base), "/eezybot/bridge_pi").unwrap().unwrap();
        assert_eq!(e.strategy, Strategy::Enforce);
        assert_eq!(e.dir, root.join("enclaves/eezybot/bridge_pi"));
        let xml = cyclone_config(&e);
        assert!(xml.contains(&format!(
            "<Permissions>file:{}/enclaves/eezybot/bridge_pi/permissions.p7s</Permissions>",
            root.display()
        )));
        assert!(!xml.contains("<Library"), "the built-in plugins: {xml}");
        // another enclave: none there
        let (strategy, why) = plan(env(&base), "/eezybot/bridge_pc").unwrap_err();
        assert_eq!(strategy, Strategy::Enforce);
        assert!(why.contains("--enclave /eezybot/bridge_pc"), "{why}");
        // the override wins, as in rcl
        let mut over = base.to_vec();
        over.push(("ROS_SECURITY_ENCLAVE_OVERRIDE", "/eezybot/bridge_pi"));
        assert!(plan(env(&over), "/eezybot/bridge_pc").unwrap().is_some());
        // permissive: the same error, for the caller to warn about
        let (strategy, _) = plan(
            env(&[
                ("ROS_SECURITY_ENABLE", "true"),
                ("ROS_SECURITY_KEYSTORE", &ks),
            ]),
            "/nowhere",
        )
        .unwrap_err();
        assert_eq!(strategy, Strategy::Permissive);
        std::fs::remove_dir_all(root).unwrap();
    }

    #[test]
    fn a_missing_file_or_keystore_is_named() {
        let root = keystore("missing", &ENCLAVE_FILES[..5]);
        let ks = root.to_string_lossy().to_string();
        let (_, why) = plan(
            env(&[
                ("ROS_SECURITY_ENABLE", "true"),
                ("ROS_SECURITY_KEYSTORE", &ks),
            ]),
            "/eezybot/bridge_pi",
        )
        .unwrap_err();
        assert!(
            why.contains("permissions.p7s: cannot read it: no such file"),
            "{why}"
        );
        let (_, why) = plan(env(&[("ROS_SECURITY_ENABLE", "true")]), "/a").unwrap_err();
        assert!(why.contains("ROS_SECURITY_KEYSTORE is not set"), "{why}");
        for bad in ["eezybot/x", "/a//b", "/a-b", "/1a", "/"] {
            let (_, why) = plan(
                env(&[
                    ("ROS_SECURITY_ENABLE", "true"),
                    ("ROS_SECURITY_KEYSTORE", &ks),
                ]),
                bad,
            )
            .unwrap_err();
            assert!(why.contains("not a valid enclave name"), "{bad}: {why}");
        }
        std::fs::remove_dir_all(root).unwrap();
    }

    #[test]
    fn paths_are_escaped_and_fragments_follow_the_users() {
        let e = Enclave {
            name: "/x".into(),
            dir: PathBuf::from("/a&b/<c>"),
            strategy: Strategy::Permissive,
        };
        assert!(cyclone_config(&e).contains("file:/a&amp;b/&lt;c&gt;/cert.pem"));
        assert_eq!(with_fragment(None, "<X/>"), "<X/>");
        assert_eq!(with_fragment(Some("  "), "<X/>"), "<X/>");
        assert_eq!(
            with_fragment(Some("file:///u.xml"), "<X/>"),
            "file:///u.xml,<X/>"
        );
    }
}
