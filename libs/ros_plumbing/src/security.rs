//! SROS2 (DDS Security) in every node, configured the ROS 2 way.
//!
//! rcl's rules, which every node of ours follows:
//! - `ROS_SECURITY_ENABLE=true` (exactly) turns security on; anything else leaves it off,
//!   and the node runs as before.
//! - `ROS_SECURITY_STRATEGY=Enforce` refuses to run without security: a missing,
//!   unreadable, expired or mismatched file stops the node (exit status 2) with a
//!   message naming the file. Any other value is *Permissive*: the node warns and runs
//!   unsecured.
//! - The enclave's files are in `$ROS_SECURITY_KEYSTORE/enclaves/<enclave>`, where the
//!   enclave is `ROS_SECURITY_ENCLAVE_OVERRIDE` if set, else the ROS argument
//!   `--enclave /NAME` (`-e /NAME`), else `/`.
//! - An enclave holds the six files of an SROS2 keystore: `identity_ca.cert.pem`,
//!   `cert.pem`, `key.pem`, `permissions_ca.cert.pem`, `governance.p7s` and
//!   `permissions.p7s` (unencrypted key, as `ros2 security create_enclave` writes it).
//!
//! Before the DDS participant is built, [`check_enclave`] reads every file and checks
//! what can be checked locally (PEM syntax, certificate validity dates, the certificate
//! issued by the identity CA, the key belonging to the certificate, the documents signed
//! by the permissions CA), so that a bad file is named with what is wrong with it rather
//! than surfacing as a failed handshake. RustDDS then validates the permissions
//! themselves (subject, validity, rules).
//!
//! # Examples
//! ```
//! use ros_plumbing::security::{SecurityEnv, Strategy};
//! let env = SecurityEnv::from_lookup(|name| match name {
//!     "ROS_SECURITY_ENABLE" => Some("true".into()),
//!     "ROS_SECURITY_STRATEGY" => Some("Enforce".into()),
//!     "ROS_SECURITY_KEYSTORE" => Some("/home/pi/keystore".into()),
//!     _ => None,
//! });
//! let plan = env.plan(Some("/eezybot/pi")).unwrap().unwrap();
//! assert_eq!(plan.strategy, Strategy::Enforce);
//! assert_eq!(plan.dir, std::path::Path::new("/home/pi/keystore/enclaves/eezybot/pi"));
//! ```

use openssl::asn1::Asn1Time;
use openssl::pkcs7::{Pkcs7, Pkcs7Flags};
use openssl::pkey::{PKey, Private};
use openssl::stack::Stack;
use openssl::x509::store::X509StoreBuilder;
use openssl::x509::X509;
use std::fmt;
use std::path::{Path, PathBuf};

/// The environment variables of SROS2, as `--help` lists them.
pub const ENVIRONMENT_HELP: &str = "ROS_SECURITY_ENABLE (true: SROS2 on), ROS_SECURITY_STRATEGY \
     (Enforce | Permissive), ROS_SECURITY_KEYSTORE (keystore directory), \
     ROS_SECURITY_ENCLAVE_OVERRIDE (enclave, instead of --enclave)";

/// What to do when security is on but the enclave cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// Stop the node (exit status 2).
    Enforce,
    /// Warn and run without security.
    Permissive,
}

impl fmt::Display for Strategy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Strategy::Enforce => "Enforce",
            Strategy::Permissive => "Permissive",
        })
    }
}

/// The `ROS_SECURITY_*` variables, as read from the environment.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SecurityEnv {
    /// `ROS_SECURITY_ENABLE`
    pub enable: Option<String>,
    /// `ROS_SECURITY_STRATEGY`
    pub strategy: Option<String>,
    /// `ROS_SECURITY_KEYSTORE`
    pub keystore: Option<String>,
    /// `ROS_SECURITY_ENCLAVE_OVERRIDE`
    pub enclave_override: Option<String>,
}

/// Security is on: this enclave, in this directory, under this strategy.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SecurityPlan {
    /// The enclave's name (`/eezybot/pi`).
    pub enclave: String,
    /// Its directory (`$ROS_SECURITY_KEYSTORE/enclaves/eezybot/pi`).
    pub dir: PathBuf,
    /// [`Strategy`]
    pub strategy: Strategy,
}

/// Why security cannot be used as configured. Each names the file (or variable) and
/// what is wrong with it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SecurityError {
    /// `ROS_SECURITY_KEYSTORE` is unset or empty.
    #[error("ROS_SECURITY_ENABLE is true but ROS_SECURITY_KEYSTORE is not set: set it to the keystore directory (launch_scripts/keystore.sh DIR makes one)")]
    NoKeystore,
    /// The enclave name is not an absolute ROS name.
    #[error("enclave `{enclave}` is not a valid enclave name (an absolute path of letters, digits and _, such as /eezybot/pc)")]
    BadEnclaveName {
        /// the name
        enclave: String,
    },
    /// The enclave's directory does not exist.
    #[error("enclave {enclave}: directory {} does not exist (no such enclave in keystore {}; make it with launch_scripts/keystore.sh {} --enclave {enclave})", dir.display(), keystore.display(), keystore.display())]
    NoEnclave {
        /// the enclave
        enclave: String,
        /// where it was looked for
        dir: PathBuf,
        /// the keystore
        keystore: PathBuf,
    },
    /// A file of the enclave is missing or cannot be read.
    #[error("{}: cannot read it: {why}", path.display())]
    Unreadable {
        /// the file
        path: PathBuf,
        /// the OS error
        why: String,
    },
    /// A file does not hold what it should (not PEM, not a certificate, not a key,
    /// not S/MIME).
    #[error("{}: {why}", path.display())]
    Malformed {
        /// the file
        path: PathBuf,
        /// what is wrong
        why: String,
    },
    /// A certificate has expired.
    #[error("{}: the certificate expired on {not_after} (check the clock: `date -u`; renew the enclave)", path.display())]
    Expired {
        /// the file
        path: PathBuf,
        /// its notAfter
        not_after: String,
    },
    /// A certificate is not valid yet: usually this machine's clock is behind.
    #[error("{}: the certificate is not valid before {not_before}; this machine's clock says {now} (a Raspberry Pi without network time starts in the past: check `date -u`)", path.display())]
    NotYetValid {
        /// the file
        path: PathBuf,
        /// its notBefore
        not_before: String,
        /// the clock now
        now: String,
    },
    /// Two files do not belong together (a certificate of another CA, a key of another
    /// certificate, a document signed by another CA).
    #[error("{}: {why}", path.display())]
    Mismatch {
        /// the file
        path: PathBuf,
        /// what does not match
        why: String,
    },
    /// Access control refused to create an endpoint: the enclave's permissions do not
    /// allow it.
    #[error("access control refused to {action} {topic}: the permissions of enclave {enclave} do not allow it ({why})")]
    Denied {
        /// `publish on` or `subscribe to`
        action: &'static str,
        /// the resolved topic name
        topic: String,
        /// the enclave
        enclave: String,
        /// RustDDS' reason
        why: String,
    },
    /// The files passed the local checks but RustDDS refused them (permissions,
    /// governance, subject).
    #[error("enclave {}: DDS Security refused it: {why}", dir.display())]
    Refused {
        /// the enclave directory
        dir: PathBuf,
        /// RustDDS' reason
        why: String,
    },
}

/// The files of an enclave, by their SROS2 names.
pub const IDENTITY_CA: &str = "identity_ca.cert.pem";
/// The participant's certificate.
pub const CERT: &str = "cert.pem";
/// The participant's private key.
pub const KEY: &str = "key.pem";
/// The permissions CA's certificate.
pub const PERMISSIONS_CA: &str = "permissions_ca.cert.pem";
/// The signed governance document.
pub const GOVERNANCE: &str = "governance.p7s";
/// The signed permissions document.
pub const PERMISSIONS: &str = "permissions.p7s";

impl SecurityEnv {
    /// Read the variables from this process's environment.
    pub fn from_env() -> SecurityEnv {
        Self::from_lookup(|name| std::env::var(name).ok())
    }

    /// Read the variables through `lookup` (for tests).
    pub fn from_lookup(lookup: impl Fn(&str) -> Option<String>) -> SecurityEnv {
        SecurityEnv {
            enable: lookup("ROS_SECURITY_ENABLE"),
            strategy: lookup("ROS_SECURITY_STRATEGY"),
            keystore: lookup("ROS_SECURITY_KEYSTORE"),
            enclave_override: lookup("ROS_SECURITY_ENCLAVE_OVERRIDE"),
        }
    }

    /// Whether security is on: `ROS_SECURITY_ENABLE` is exactly `true`, as rcl reads it.
    pub fn enabled(&self) -> bool {
        self.enable.as_deref() == Some("true")
    }

    /// The strategy: `Enforce` exactly, as rcl reads it; anything else is permissive.
    pub fn strategy(&self) -> Strategy {
        if self.strategy.as_deref() == Some("Enforce") {
            Strategy::Enforce
        } else {
            Strategy::Permissive
        }
    }

    /// Where this node's enclave is: `None` when security is off. `enclave_arg` is the
    /// `--enclave` ROS argument. The error comes with the strategy the caller applies.
    pub fn plan(
        &self,
        enclave_arg: Option<&str>,
    ) -> Result<Option<SecurityPlan>, (Strategy, SecurityError)> {
        if !self.enabled() {
            return Ok(None);
        }
        let strategy = self.strategy();
        let fail = |e| Err((strategy, e));
        let keystore = match self.keystore.as_deref().map(str::trim) {
            None | Some("") => return fail(SecurityError::NoKeystore),
            Some(k) => PathBuf::from(k),
        };
        let enclave = match self.enclave_override.as_deref().filter(|s| !s.is_empty()) {
            Some(e) => e,
            None => enclave_arg.unwrap_or("/"),
        };
        if !valid_enclave_name(enclave) {
            return fail(SecurityError::BadEnclaveName {
                enclave: enclave.to_string(),
            });
        }
        let dir = enclave
            .split('/')
            .filter(|c| !c.is_empty())
            .fold(keystore.join("enclaves"), |d, c| d.join(c));
        Ok(Some(SecurityPlan {
            enclave: enclave.to_string(),
            dir,
            strategy,
        }))
    }
}

/// An absolute name of `[A-Za-z0-9_]` components (rcl's enclave name rules), or `/`.
pub fn valid_enclave_name(name: &str) -> bool {
    name == "/"
        || (name.starts_with('/')
            && name.len() < 256
            && name[1..].split('/').all(|c| {
                !c.is_empty()
                    && !c.starts_with(|ch: char| ch.is_ascii_digit())
                    && c.chars().all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
            }))
}

fn read(path: &Path) -> Result<Vec<u8>, SecurityError> {
    std::fs::read(path).map_err(|e| SecurityError::Unreadable {
        path: path.to_path_buf(),
        why: match e.kind() {
            std::io::ErrorKind::NotFound => "no such file".to_string(),
            std::io::ErrorKind::PermissionDenied => {
                "permission denied (the key must be readable by the user the node runs as)"
                    .to_string()
            }
            _ => e.to_string(),
        },
    })
}

fn malformed(path: &Path, why: impl Into<String>) -> SecurityError {
    SecurityError::Malformed {
        path: path.to_path_buf(),
        why: why.into(),
    }
}

fn certificate(path: &Path) -> Result<X509, SecurityError> {
    let pem = read(path)?;
    X509::from_pem(&pem).map_err(|_| malformed(path, "not a PEM certificate"))
}

/// When an enclave's identity runs out: the earlier `notAfter` of its certificate and of
/// the identity CA that issued it (either one expired stops the node at its next start).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CertificateExpiry {
    /// The file whose certificate runs out first.
    pub path: PathBuf,
    /// Its `notAfter`, seconds since the Unix epoch.
    pub not_after: i64,
}

impl CertificateExpiry {
    /// Reads the enclave's certificate and identity CA (checked already by
    /// [`check_enclave`]).
    pub fn of_enclave(plan: &SecurityPlan) -> Result<CertificateExpiry, SecurityError> {
        let mut earliest: Option<CertificateExpiry> = None;
        for name in [CERT, IDENTITY_CA] {
            let path = plan.dir.join(name);
            let cert = certificate(&path)?;
            let not_after = not_after_unix(&path, &cert)?;
            earliest = CertificateExpiry::earlier(earliest, CertificateExpiry { path, not_after });
        }
        earliest.ok_or_else(|| malformed(&plan.dir, "no certificate"))
    }

    /// The earliest `notAfter` of the certificates in a PEM file (a TLS server's chain:
    /// its own certificate, and any CA certificates after it), named by that file.
    pub fn of_pem_chain(path: &Path) -> Result<CertificateExpiry, SecurityError> {
        let pem = read(path)?;
        let chain =
            X509::stack_from_pem(&pem).map_err(|_| malformed(path, "not a PEM certificate"))?;
        let mut earliest = None;
        for cert in &chain {
            let not_after = not_after_unix(path, cert)?;
            earliest = CertificateExpiry::earlier(
                earliest,
                CertificateExpiry {
                    path: path.to_path_buf(),
                    not_after,
                },
            );
        }
        earliest.ok_or_else(|| malformed(path, "no certificate in it"))
    }

    /// Whichever of `a` and `b` runs out first (`b` when `a` is `None`).
    pub fn earlier(
        a: Option<CertificateExpiry>,
        b: CertificateExpiry,
    ) -> Option<CertificateExpiry> {
        match a {
            Some(a) if a.not_after <= b.not_after => Some(a),
            _ => Some(b),
        }
    }
}

/// A certificate's `notAfter` in seconds since the Unix epoch.
fn not_after_unix(path: &Path, cert: &X509) -> Result<i64, SecurityError> {
    let epoch = Asn1Time::from_unix(0).map_err(|e| malformed(path, e.to_string()))?;
    let d = epoch
        .diff(cert.not_after())
        .map_err(|e| malformed(path, format!("bad notAfter: {e}")))?;
    Ok(i64::from(d.days) * 86_400 + i64::from(d.secs))
}

/// The certificate is valid at `now` (seconds since the Unix epoch).
fn check_dates(path: &Path, cert: &X509, now: i64) -> Result<(), SecurityError> {
    // time_t is 32 bits on armv7 (infallible where it is 64)
    #[allow(irrefutable_let_patterns, clippy::useless_conversion)]
    let Ok(now_t) = now.try_into() else {
        return Err(malformed(
            path,
            format!("the clock ({now} s) does not fit this system's time_t"),
        ));
    };
    let now_asn1 = Asn1Time::from_unix(now_t).map_err(|e| malformed(path, e.to_string()))?;
    let before = now_asn1
        .diff(cert.not_before())
        .map_err(|e| malformed(path, format!("bad notBefore: {e}")))?;
    // diff is `other - self`: positive means notBefore lies ahead of now
    if before.days > 0 || (before.days == 0 && before.secs > 0) {
        return Err(SecurityError::NotYetValid {
            path: path.to_path_buf(),
            not_before: cert.not_before().to_string(),
            now: now_asn1.to_string(),
        });
    }
    let after = now_asn1
        .diff(cert.not_after())
        .map_err(|e| malformed(path, format!("bad notAfter: {e}")))?;
    if after.days < 0 || (after.days == 0 && after.secs < 0) {
        return Err(SecurityError::Expired {
            path: path.to_path_buf(),
            not_after: cert.not_after().to_string(),
        });
    }
    Ok(())
}

/// A signed document (`governance.p7s`, `permissions.p7s`) is S/MIME signed by the
/// permissions CA; returns the signed content.
fn check_signed(path: &Path, ca: &X509) -> Result<Vec<u8>, SecurityError> {
    let smime = read(path)?;
    let (pkcs7, detached) =
        Pkcs7::from_smime(&smime).map_err(|_| malformed(path, "not an S/MIME signed document"))?;
    let mut signers = Stack::new().map_err(|e| malformed(path, e.to_string()))?;
    signers
        .push(ca.clone())
        .map_err(|e| malformed(path, e.to_string()))?;
    let store = X509StoreBuilder::new()
        .map_err(|e| malformed(path, e.to_string()))?
        .build();
    let mut content = Vec::new();
    // NOINTERN: the signer must be the permissions CA given here, not a certificate
    // the document carries itself; NOVERIFY: the CA is trusted as configured, its own
    // chain is not checked against a system store.
    pkcs7
        .verify(
            &signers,
            &store,
            detached.as_deref(),
            Some(&mut content),
            Pkcs7Flags::NOINTERN | Pkcs7Flags::NOVERIFY,
        )
        .map_err(|_| SecurityError::Mismatch {
            path: path.to_path_buf(),
            why: format!("not signed by the permissions CA ({PERMISSIONS_CA})"),
        })?;
    Ok(content)
}

/// Read and check every file of the enclave in `dir` at time `now` (seconds since the
/// Unix epoch). The first problem found is returned, naming its file.
pub fn check_enclave(
    plan: &SecurityPlan,
    keystore_hint: &Path,
    now: i64,
) -> Result<(), SecurityError> {
    let dir = &plan.dir;
    if !dir.is_dir() {
        return Err(SecurityError::NoEnclave {
            enclave: plan.enclave.clone(),
            dir: dir.clone(),
            keystore: keystore_hint.to_path_buf(),
        });
    }
    let identity_ca_path = dir.join(IDENTITY_CA);
    let cert_path = dir.join(CERT);
    let key_path = dir.join(KEY);
    let permissions_ca_path = dir.join(PERMISSIONS_CA);

    let identity_ca = certificate(&identity_ca_path)?;
    check_dates(&identity_ca_path, &identity_ca, now)?;
    let cert = certificate(&cert_path)?;
    check_dates(&cert_path, &cert, now)?;
    let ca_key = identity_ca.public_key().map_err(|_| {
        malformed(
            &identity_ca_path,
            "the certificate holds no usable public key",
        )
    })?;
    if !cert.verify(&ca_key).unwrap_or(false) {
        return Err(SecurityError::Mismatch {
            path: cert_path,
            why: format!(
                "not issued by the identity CA in {} (a certificate of another keystore?)",
                identity_ca_path.display()
            ),
        });
    }
    let key_pem = read(&key_path)?;
    let key: PKey<Private> = PKey::private_key_from_pem(&key_pem)
        .map_err(|_| malformed(&key_path, "not an unencrypted PEM private key"))?;
    let cert_key = cert
        .public_key()
        .map_err(|_| malformed(&cert_path, "the certificate holds no usable public key"))?;
    if !cert_key.public_eq(&key) {
        return Err(SecurityError::Mismatch {
            path: key_path,
            why: format!("not the private key of {}", cert_path.display()),
        });
    }
    let permissions_ca = certificate(&permissions_ca_path)?;
    check_dates(&permissions_ca_path, &permissions_ca, now)?;
    check_signed(&dir.join(GOVERNANCE), &permissions_ca)?;
    let permissions = check_signed(&dir.join(PERMISSIONS), &permissions_ca)?;
    if !String::from_utf8_lossy(&permissions).contains("<permissions") {
        return Err(malformed(
            &dir.join(PERMISSIONS),
            "the signed content is not a permissions document",
        ));
    }
    Ok(())
}

/// The security configuration RustDDS takes for a checked enclave.
pub fn participant_files(plan: &SecurityPlan) -> rustdds::DomainParticipantSecurityConfigFiles {
    rustdds::DomainParticipantSecurityConfigFiles::with_ros_default_names(&plan.dir, String::new())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(vars: &[(&str, &str)]) -> SecurityEnv {
        let vars: Vec<(String, String)> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        SecurityEnv::from_lookup(move |name| {
            vars.iter().find(|(k, _)| k == name).map(|(_, v)| v.clone())
        })
    }

    #[test]
    fn off_unless_exactly_true() {
        for v in ["", "1", "TRUE", "True", "yes", "false"] {
            let e = env(&[("ROS_SECURITY_ENABLE", v), ("ROS_SECURITY_KEYSTORE", "/k")]);
            assert_eq!(e.plan(Some("/a")), Ok(None), "{v}");
        }
        assert_eq!(env(&[]).plan(None), Ok(None));
    }

    #[test]
    fn strategy_is_enforce_only_when_spelled_so() {
        assert_eq!(
            env(&[("ROS_SECURITY_STRATEGY", "Enforce")]).strategy(),
            Strategy::Enforce
        );
        for v in ["enforce", "Permissive", "", "ENFORCE"] {
            assert_eq!(
                env(&[("ROS_SECURITY_STRATEGY", v)]).strategy(),
                Strategy::Permissive
            );
        }
        assert_eq!(env(&[]).strategy(), Strategy::Permissive);
    }

    #[test]
    fn the_override_beats_the_argument_which_beats_the_root() {
        let base = [
            ("ROS_SECURITY_ENABLE", "true"),
            ("ROS_SECURITY_KEYSTORE", "/ks"),
        ];
        let plan = env(&base).plan(None).unwrap().unwrap();
        assert_eq!(plan.enclave, "/");
        assert_eq!(plan.dir, Path::new("/ks/enclaves"));
        let plan = env(&base).plan(Some("/eezybot/pc")).unwrap().unwrap();
        assert_eq!(plan.dir, Path::new("/ks/enclaves/eezybot/pc"));
        let mut over = base.to_vec();
        over.push(("ROS_SECURITY_ENCLAVE_OVERRIDE", "/eezybot/pi"));
        let plan = env(&over).plan(Some("/eezybot/pc")).unwrap().unwrap();
        assert_eq!(plan.enclave, "/eezybot/pi");
        assert_eq!(plan.dir, Path::new("/ks/enclaves/eezybot/pi"));
    }

    #[test]
    fn no_keystore_and_bad_names_are_errors_with_the_strategy() {
        let e = env(&[
            ("ROS_SECURITY_ENABLE", "true"),
            ("ROS_SECURITY_STRATEGY", "Enforce"),
        ]);
        assert_eq!(
            e.plan(None),
            Err((Strategy::Enforce, SecurityError::NoKeystore))
        );
        let e = env(&[
            ("ROS_SECURITY_ENABLE", "true"),
            ("ROS_SECURITY_KEYSTORE", "/k"),
        ]);
        for bad in ["eezybot/pc", "/a//b", "/a/", "/../x", "/a b", "/1a"] {
            assert!(
                matches!(
                    e.plan(Some(bad)),
                    Err((Strategy::Permissive, SecurityError::BadEnclaveName { .. }))
                ),
                "{bad}"
            );
        }
    }

    #[test]
    fn a_missing_enclave_is_named() {
        let plan = SecurityPlan {
            enclave: "/eezybot/nowhere".into(),
            dir: PathBuf::from("/nonexistent/enclaves/eezybot/nowhere"),
            strategy: Strategy::Enforce,
        };
        let e = check_enclave(&plan, Path::new("/nonexistent"), 0).unwrap_err();
        assert!(matches!(e, SecurityError::NoEnclave { .. }));
        assert!(
            e.to_string()
                .contains("/nonexistent/enclaves/eezybot/nowhere"),
            "{e}"
        );
    }
    /// A keystore enclave made with OpenSSL, as `ros2 security create_enclave` lays it out.
    mod keystore {
        use openssl::asn1::Asn1Time;
        use openssl::bn::BigNum;
        use openssl::ec::{EcGroup, EcKey};
        use openssl::hash::MessageDigest;
        use openssl::nid::Nid;
        use openssl::pkcs7::{Pkcs7, Pkcs7Flags};
        use openssl::pkey::{PKey, Private};
        use openssl::stack::Stack;
        use openssl::x509::{X509Name, X509};
        use std::path::{Path, PathBuf};

        pub const DAY: i64 = 86_400;

        pub fn now() -> i64 {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_secs() as i64
        }

        pub fn key() -> PKey<Private> {
            let group = EcGroup::from_curve_name(Nid::X9_62_PRIME256V1).unwrap();
            PKey::from_ec_key(EcKey::generate(&group).unwrap()).unwrap()
        }

        /// A certificate for `subject` with `key`, signed by `issuer` (self-signed if None),
        /// valid from `from` to `to` (Unix seconds).
        pub fn cert(
            subject: &str,
            key: &PKey<Private>,
            issuer: Option<(&X509, &PKey<Private>)>,
            from: i64,
            to: i64,
        ) -> X509 {
            let mut name = X509Name::builder().unwrap();
            name.append_entry_by_text("CN", subject).unwrap();
            let name = name.build();
            let mut b = X509::builder().unwrap();
            b.set_version(2).unwrap();
            b.set_serial_number(&BigNum::from_u32(1).unwrap().to_asn1_integer().unwrap())
                .unwrap();
            b.set_subject_name(&name).unwrap();
            match issuer {
                Some((ca, _)) => b.set_issuer_name(ca.subject_name()).unwrap(),
                None => b.set_issuer_name(&name).unwrap(),
            }
            b.set_pubkey(key).unwrap();
            b.set_not_before(&Asn1Time::from_unix(from).unwrap())
                .unwrap();
            b.set_not_after(&Asn1Time::from_unix(to).unwrap()).unwrap();
            b.sign(issuer.map_or(key, |(_, k)| k), MessageDigest::sha256())
                .unwrap();
            b.build()
        }

        pub fn signed(doc: &str, ca: &X509, key: &PKey<Private>) -> Vec<u8> {
            let flags = Pkcs7Flags::TEXT | Pkcs7Flags::DETACHED;
            let p7 = Pkcs7::sign(ca, key, &Stack::new().unwrap(), doc.as_bytes(), flags).unwrap();
            p7.to_smime(doc.as_bytes(), flags).unwrap()
        }

        pub struct Ca {
            pub cert: X509,
            pub key: PKey<Private>,
        }

        impl Ca {
            pub fn new(name: &str) -> Ca {
                Ca::short_lived(name, 3650)
            }

            /// A CA valid from a day ago for `days` days.
            pub fn short_lived(name: &str, days: i64) -> Ca {
                let key = key();
                let t = now();
                Ca {
                    cert: cert(name, &key, None, t - DAY, t + days * DAY),
                    key,
                }
            }
        }

        /// Writes a good enclave for `/eezybot/pc` into a new directory.
        /// `dir`'s key.pem.
        pub fn write_key(dir: &Path, key: &PKey<Private>) {
            write(dir, "key.pem", &key.private_key_to_pem_pkcs8().unwrap());
        }

        /// `dir`'s cert.pem: `/eezybot/pc`'s certificate of `key`, issued by `ca`, valid
        /// from `from` to `to` (s since the epoch).
        pub fn write_cert(dir: &Path, key: &PKey<Private>, ca: &Ca, from: i64, to: i64) {
            let cert = cert("/eezybot/pc", key, Some((&ca.cert, &ca.key)), from, to);
            write(dir, "cert.pem", &cert.to_pem().unwrap());
        }

        /// A keystore's enclave directory for one test; the keystore is deleted when
        /// this is dropped.
        pub struct Enclave {
            keystore: PathBuf,
            dir: PathBuf,
        }

        impl std::ops::Deref for Enclave {
            type Target = Path;
            fn deref(&self) -> &Path {
                &self.dir
            }
        }

        impl Drop for Enclave {
            fn drop(&mut self) {
                let _ = std::fs::remove_dir_all(&self.keystore);
            }
        }

        pub fn enclave(test: &str, ca: &Ca) -> Enclave {
            let keystore = std::env::temp_dir()
                .join(format!("eezybot-security-{}-{test}", std::process::id()));
            let dir = keystore.join("enclaves/eezybot/pc");
            let _ = std::fs::remove_dir_all(&keystore);
            std::fs::create_dir_all(&dir).unwrap();
            let key = key();
            write_key(&dir, &key);
            write_cert(&dir, &key, ca, now() - DAY, now() + 365 * DAY);
            write(&dir, "identity_ca.cert.pem", &ca.cert.to_pem().unwrap());
            write(&dir, "permissions_ca.cert.pem", &ca.cert.to_pem().unwrap());
            write(
                &dir,
                "governance.p7s",
                &signed("<dds><domain_access_rules/></dds>", &ca.cert, &ca.key),
            );
            write(
                &dir,
                "permissions.p7s",
                &signed(
                    "<dds><permissions><grant/></permissions></dds>",
                    &ca.cert,
                    &ca.key,
                ),
            );
            Enclave { keystore, dir }
        }

        pub fn write(dir: &Path, name: &str, bytes: &[u8]) {
            std::fs::write(dir.join(name), bytes).unwrap();
        }
    }

    #[test]
    fn the_expiry_is_the_earlier_of_the_certificate_and_its_ca() {
        let (ca, dir) = good_enclave("expiry");
        let plan = SecurityPlan {
            enclave: "/eezybot/pc".into(),
            dir: dir.to_path_buf(),
            strategy: Strategy::Enforce,
        };
        // the enclave's certificate: a year; the CA: ten
        let e = CertificateExpiry::of_enclave(&plan).unwrap();
        assert!(e.path.ends_with("cert.pem"), "{e:?}");
        assert!(
            (e.not_after - (keystore::now() + 365 * 86_400)).abs() <= 5,
            "{e:?}"
        );
        // a CA that ends first is the one named
        let short = keystore::Ca::short_lived("ca", 20);
        keystore::write(&dir, "identity_ca.cert.pem", &short.cert.to_pem().unwrap());
        let e = CertificateExpiry::of_enclave(&plan).unwrap();
        assert!(e.path.ends_with("identity_ca.cert.pem"), "{e:?}");
        assert!(
            (e.not_after - (keystore::now() + 20 * 86_400)).abs() <= 5,
            "{e:?}"
        );
        drop(ca);
    }

    #[test]
    fn a_pem_chain_expires_with_its_earliest_certificate() {
        let (ca, dir) = good_enclave("chain");
        let short = keystore::Ca::short_lived("ca", 20);
        let mut chain = std::fs::read(dir.join(CERT)).unwrap();
        chain.extend(short.cert.to_pem().unwrap());
        keystore::write(&dir, "chain.pem", &chain);
        let e = CertificateExpiry::of_pem_chain(&dir.join("chain.pem")).unwrap();
        assert!(e.path.ends_with("chain.pem"), "{e:?}");
        assert!(
            (e.not_after - (keystore::now() + 20 * 86_400)).abs() <= 5,
            "{e:?}"
        );
        keystore::write(&dir, "empty.pem", b"no certificate here\n");
        assert!(CertificateExpiry::of_pem_chain(&dir.join("empty.pem")).is_err());
        drop(ca);
    }

    fn checked(dir: &Path) -> Result<(), SecurityError> {
        let plan = SecurityPlan {
            enclave: "/eezybot/pc".into(),
            dir: dir.to_path_buf(),
            strategy: Strategy::Enforce,
        };
        check_enclave(&plan, dir, keystore::now())
    }

    /// A CA and a good enclave of it, for `test`.
    fn good_enclave(test: &str) -> (keystore::Ca, keystore::Enclave) {
        let ca = keystore::Ca::new("ca");
        let dir = keystore::enclave(test, &ca);
        (ca, dir)
    }

    /// Why `dir` is refused; the refusal must name `file` and be a
    /// `SecurityError::$kind`.
    macro_rules! refused {
        ($dir:expr, $file:expr, $kind:ident) => {{
            let e = checked($dir).unwrap_err();
            assert!(e.to_string().contains(&format!("/{}:", $file)), "{e}");
            assert!(matches!(e, SecurityError::$kind { .. }), "{e}");
            e
        }};
    }

    #[test]
    fn a_good_enclave_passes() {
        assert_eq!(checked(&good_enclave("good").1), Ok(()));
    }

    #[test]
    fn a_missing_or_corrupt_key_is_named() {
        let (_, dir) = good_enclave("corrupt-key");
        keystore::write(&dir, "key.pem", b"-----BEGIN PRIVATE KEY-----\nAAAA\n");
        refused!(&dir, "key.pem", Malformed);
        std::fs::remove_file(dir.join("key.pem")).unwrap();
        let e = refused!(&dir, "key.pem", Unreadable);
        assert!(e.to_string().contains("no such file"), "{e}");
    }

    #[test]
    fn the_key_of_another_certificate_is_a_mismatch() {
        let (_, dir) = good_enclave("other-key");
        keystore::write_key(&dir, &keystore::key());
        refused!(&dir, "key.pem", Mismatch);
    }

    #[test]
    fn an_expired_or_future_certificate_is_named_with_its_dates() {
        let (ca, dir) = good_enclave("expired");
        let key = keystore::key();
        let t = keystore::now();
        keystore::write_key(&dir, &key);
        keystore::write_cert(&dir, &key, &ca, t - 30 * keystore::DAY, t - keystore::DAY);
        refused!(&dir, "cert.pem", Expired);
        keystore::write_cert(&dir, &key, &ca, t + keystore::DAY, t + 30 * keystore::DAY);
        let e = refused!(&dir, "cert.pem", NotYetValid);
        assert!(e.to_string().contains("clock"), "{e}");
    }

    #[test]
    fn a_certificate_of_another_ca_is_a_mismatch() {
        let (_, dir) = good_enclave("wrong-ca");
        let foreign = keystore::Ca::new("foreign");
        keystore::write(
            &dir,
            "identity_ca.cert.pem",
            &foreign.cert.to_pem().unwrap(),
        );
        refused!(&dir, "cert.pem", Mismatch);
    }

    #[test]
    fn documents_signed_by_another_ca_are_mismatches() {
        let ca = keystore::Ca::new("ca");
        let foreign = keystore::Ca::new("foreign");
        for file in ["governance.p7s", "permissions.p7s"] {
            let dir = keystore::enclave(&format!("foreign-{file}"), &ca);
            let doc = "<dds><permissions><grant/></permissions></dds>";
            keystore::write(
                &dir,
                file,
                &keystore::signed(doc, &foreign.cert, &foreign.key),
            );
            refused!(&dir, file, Mismatch);
            keystore::write(&dir, file, b"<dds/>");
            refused!(&dir, file, Malformed);
        }
    }
}
