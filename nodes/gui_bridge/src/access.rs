//! Who may use the web panel: the access policy for its page and its WebSocket, as pure
//! functions over what a request says (`Host`, `Origin`, a token) and how the server is
//! configured (bind address, token). No I/O: a server hands in a request's
//! [`RequestFacts`] and acts on the answer, so the web panel and any later server that
//! lets clients publish (the Foxglove bridge) follow the same rules.
//!
//! The rules, in the order they are checked:
//! 1. **Origin.** A browser names the page a request comes from in `Origin`; it must be
//!    the panel's own: `http://` + the request's `Host` (`https://` when gui_bridge
//!    serves TLS itself, [`AccessPolicy::over_tls`], or behind a TLS proxy that says
//!    `X-Forwarded-Proto: https`), comparing scheme, host (case-insensitive)
//!    and port (80/443 when omitted). A request without `Origin` comes from a program,
//!    not from a web page (browsers always send it on WebSocket upgrades), so no page
//!    can drive the arm through it; it passes this rule (Jupyter does the same) but not
//!    the token rule. `Origin: null` (sandboxed frames, `file://` pages) is refused.
//! 2. **Host, without a token.** A panel without a token answers only to a loopback
//!    name (`127.x.x.x`, `[::1]`, `localhost`): a page of another site whose name was
//!    made to resolve to 127.0.0.1 (DNS rebinding) sends its own name as `Host` and its
//!    own origin, which rule 1 alone would let through.
//! 3. **Token.** When the panel has a token (always when `bind` or `foxglove_bind` is
//!    not a loopback address), every request but the page itself must present it:
//!    `?token=` in the URL, an `Authorization: token …`/`Bearer …` header, or (the
//!    page's WebSocket) a WebSocket subprotocol `token.…` next to [`PANEL_PROTOCOL`].
//!    The first of these present decides; it is compared in constant time.
//!
//! There is no cookie: cookies are not isolated by port, so every other server on the
//! same host (another program on 127.0.0.1) would receive it. The page (public code,
//! the same for everyone) keeps the token in its own origin's `localStorage`, which no
//! other port or site can read, and sends it itself, as a subprotocol on its WebSocket
//! and an `Authorization` header on its `fetch`es: nothing sends it without the page's
//! say-so (no ambient authority), and it is not in the WebSocket's URL (proxy logs).

use std::fmt;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr};

/// Bytes of a generated token (48 hex characters, 192 bits, as Jupyter's).
pub const GENERATED_TOKEN_BYTES: usize = 24;
/// Shortest token accepted from the `token` parameter.
pub const MIN_TOKEN_LEN: usize = 16;
/// Longest token accepted from the `token` parameter.
pub const MAX_TOKEN_LEN: usize = 256;
/// What the `token` parameter reads (`ros2 param get`) when the token was generated.
pub const SHOWN_GENERATED: &str = "(generated)";
/// What the `token` parameter reads when the token was set at start.
pub const SHOWN_HIDDEN: &str = "(hidden)";
/// The WebSocket subprotocol of the panel's page. The page offers it together with
/// `token.` + the token; the server answers with this one (never the token's).
pub const PANEL_PROTOCOL: &str = "eezybot.panel.v1";

/// The secret that opens a panel. `Debug` does not show it; [`Token::reveal`] does, for
/// the one start line meant for the operator.
#[derive(Clone, PartialEq, Eq)]
pub struct Token(String);

impl fmt::Debug for Token {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Token(…)")
    }
}

impl Token {
    /// A token given by the operator: 16 … 256 characters that need no escaping in a
    /// URL and may stand in a WebSocket subprotocol (`A-Z a-z 0-9 - . _ ~`).
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::access::Token;
    /// assert!(Token::new("correct-horse-battery-staple").is_ok());
    /// assert!(Token::new("short").is_err());
    /// assert!(Token::new("has spaces in it, and commas").is_err());
    /// ```
    pub fn new(text: &str) -> Result<Token, AccessError> {
        let len = text.chars().count();
        if !(MIN_TOKEN_LEN..=MAX_TOKEN_LEN).contains(&len) {
            return Err(AccessError::BadToken {
                why: format!(
                    "it has {len} characters, not {MIN_TOKEN_LEN} … {MAX_TOKEN_LEN} (make one with `openssl rand -hex 24`)"
                ),
            });
        }
        if let Some(c) = text.chars().find(|c| !is_token_char(*c)) {
            return Err(AccessError::BadToken {
                why: format!(
                    "it contains {:?}; use only A-Z a-z 0-9 - . _ ~ so that it fits a URL unescaped",
                    c
                ),
            });
        }
        Ok(Token(text.to_string()))
    }

    /// A token from random bytes (hex).
    pub fn from_random(bytes: &[u8; GENERATED_TOKEN_BYTES]) -> Token {
        Token(bytes.iter().map(|b| format!("{b:02x}")).collect())
    }

    /// The secret itself.
    pub fn reveal(&self) -> &str {
        &self.0
    }

    /// Is `presented` this token? Constant time in the token's content (the length is
    /// not secret: a generated token always has 48 characters).
    pub fn matches(&self, presented: &str) -> bool {
        let (a, b) = (self.0.as_bytes(), presented.as_bytes());
        if a.len() != b.len() {
            return false;
        }
        let diff = a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y));
        std::hint::black_box(diff) == 0
    }
}

fn is_token_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '-' | '.' | '_' | '~')
}

/// Where a panel's token came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TokenSource {
    /// No token: the panel is bound to a loopback address and none was set.
    None,
    /// Generated at start (bind is not loopback and none was set).
    Generated,
    /// Set by the `token` parameter.
    Parameter,
}

impl TokenSource {
    /// What the `token` parameter should read from now on, so that `ros2 param get`
    /// never shows the secret (None: leave it as it is).
    pub fn shown_as(self) -> Option<&'static str> {
        match self {
            TokenSource::None => None,
            TokenSource::Generated => Some(SHOWN_GENERATED),
            TokenSource::Parameter => Some(SHOWN_HIDDEN),
        }
    }
}

/// A configuration the panel cannot start with.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum AccessError {
    /// The `token` parameter is not a usable token (the message never contains it).
    #[error("the `token` parameter is not usable: {why}")]
    BadToken {
        /// why
        why: String,
    },
    /// The `token` parameter is the placeholder a hidden token reads as.
    #[error("the `token` parameter is `(hidden)`, which is what `ros2 param get` shows for a token set at start: pass the token itself, or leave it empty to generate one")]
    HiddenPlaceholder,
    /// No random numbers for a token.
    #[error("cannot generate an access token: {0}")]
    NoRandomness(String),
}

/// Accepts what the `token` parameter may hold: empty, a placeholder, or a token.
pub fn check_token_parameter(text: &str) -> Result<(), String> {
    if text.is_empty() || text == SHOWN_GENERATED || text == SHOWN_HIDDEN {
        return Ok(());
    }
    Token::new(text).map(|_| ()).map_err(|e| e.to_string())
}

/// The panel's token from the `token` parameter and whether `bind` is a loopback
/// address: the parameter's token if set; else a generated one (from `random`) when
/// `bind` is not loopback; else none. An empty parameter and `(generated)` (what a
/// generated token reads as) both mean "generate if needed".
///
/// # Examples
/// ```
/// use gui_bridge::access::{resolve_token, TokenSource};
/// let fixed = || Ok([7u8; 24]);
/// assert_eq!(resolve_token("", true, fixed).unwrap().1, TokenSource::None);
/// assert_eq!(resolve_token("", false, fixed).unwrap().1, TokenSource::Generated);
/// assert_eq!(resolve_token("0123456789abcdefXYZ", true, fixed).unwrap().1, TokenSource::Parameter);
/// ```
pub fn resolve_token(
    parameter: &str,
    bind_is_loopback: bool,
    random: impl FnOnce() -> Result<[u8; GENERATED_TOKEN_BYTES], String>,
) -> Result<(Option<Token>, TokenSource), AccessError> {
    match parameter {
        SHOWN_HIDDEN => Err(AccessError::HiddenPlaceholder),
        "" | SHOWN_GENERATED if bind_is_loopback => Ok((None, TokenSource::None)),
        "" | SHOWN_GENERATED => {
            let bytes = random().map_err(AccessError::NoRandomness)?;
            Ok((Some(Token::from_random(&bytes)), TokenSource::Generated))
        }
        text => Ok((Some(Token::new(text)?), TokenSource::Parameter)),
    }
}

/// What a request says about itself (header values as received; `None` = absent).
#[derive(Clone, Copy, Debug, Default)]
pub struct RequestFacts<'a> {
    /// `Host`
    pub host: Option<&'a str>,
    /// `Origin`
    pub origin: Option<&'a str>,
    /// `X-Forwarded-Proto` (set by a TLS reverse proxy)
    pub forwarded_proto: Option<&'a str>,
    /// `token` from the URL's query
    pub query_token: Option<&'a str>,
    /// from `Authorization: token …` or `Authorization: Bearer …`
    pub header_token: Option<&'a str>,
    /// from a WebSocket subprotocol `token.…` ([`protocol_token`])
    pub protocol_token: Option<&'a str>,
}

/// How an admitted request proved itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Credential {
    /// The panel has no token.
    NotNeeded,
    /// `?token=` in the URL.
    Query,
    /// The `Authorization` header.
    Header,
    /// The WebSocket subprotocol `token.…`.
    Protocol,
    /// No token was asked for: the page itself ([`AccessPolicy::check_page`]).
    PageOnly,
}

/// A request the policy lets in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Admission {
    /// How it proved itself.
    pub by: Credential,
}

/// Why a request is refused. The texts are the short reasons sent with the HTTP answer
/// and logged; none contains a token.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Refusal {
    /// No `Host` header (HTTP/1.1 requires one).
    #[error("no Host header")]
    NoHost,
    /// `Host` is not a loopback name on a panel without a token.
    #[error("Host `{host}` is not a loopback name and this panel has no access token (a page of another site that made its name resolve to this machine looks like this); open the panel as http://127.0.0.1:PORT/ or http://localhost:PORT/, or give gui_bridge a token")]
    HostNotLoopback {
        /// the Host header, shortened
        host: String,
    },
    /// `Origin` is another page's.
    #[error("Origin `{origin}` is not this panel's own origin {expected}: another web page may not drive the arm")]
    ForeignOrigin {
        /// the Origin header, shortened
        origin: String,
        /// what it should have been
        expected: String,
    },
    /// No token presented to a panel that has one.
    #[error("this panel needs its access token: open the URL with ?token=… that gui_bridge printed when it started")]
    NoToken,
    /// A wrong token.
    #[error("wrong access token: open the URL with ?token=… that gui_bridge printed when it started (a generated token changes each time gui_bridge starts)")]
    WrongToken,
}

impl Refusal {
    /// The HTTP status to answer with: 401 when a token is missing, 400 without `Host`,
    /// 403 otherwise.
    pub fn status(&self) -> u16 {
        match self {
            Refusal::NoToken => 401,
            Refusal::NoHost => 400,
            _ => 403,
        }
    }

    /// A short name of the reason, for counters (`origin`, `host`, `token`).
    pub fn kind(&self) -> &'static str {
        match self {
            Refusal::ForeignOrigin { .. } => "origin",
            Refusal::NoHost | Refusal::HostNotLoopback { .. } => "host",
            Refusal::NoToken | Refusal::WrongToken => "token",
        }
    }
}

/// The access policy of one server: its token (if any).
#[derive(Clone, Debug)]
pub struct AccessPolicy {
    token: Option<Token>,
    /// the server speaks TLS itself: its pages' origin is `https://` + `Host`
    tls: bool,
}

impl AccessPolicy {
    /// The policy of a server with this token.
    pub fn new(token: Option<Token>) -> AccessPolicy {
        AccessPolicy { token, tls: false }
    }

    /// The server speaks TLS itself (`tls_cert`): the panel's own origin is `https://` +
    /// `Host` (whatever `X-Forwarded-Proto` says).
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::access::{AccessPolicy, RequestFacts};
    /// let https = AccessPolicy::new(None).over_tls(true);
    /// let from = |origin| RequestFacts { host: Some("127.0.0.1:8080"), origin: Some(origin), ..Default::default() };
    /// assert!(https.check(&from("https://127.0.0.1:8080")).is_ok());
    /// assert!(https.check(&from("http://127.0.0.1:8080")).is_err());
    /// ```
    pub fn over_tls(mut self, tls: bool) -> AccessPolicy {
        self.tls = tls;
        self
    }

    /// Does every request need the token?
    pub fn token_required(&self) -> bool {
        self.token.is_some()
    }

    /// The rules for the page itself (`/`): `Origin` and, without a token, `Host`; no
    /// token is asked for, because the page is the same public code for everyone and
    /// takes the token from its own origin's storage (a reload has no token in the URL).
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::access::{AccessPolicy, RequestFacts, Token};
    /// let locked = AccessPolicy::new(Some(Token::new("0123456789abcdef0123").unwrap()));
    /// let page = RequestFacts { host: Some("192.168.1.5:8080"), ..Default::default() };
    /// assert!(locked.check_page(&page).is_ok());
    /// assert!(locked.check(&page).is_err());
    /// ```
    pub fn check_page(&self, req: &RequestFacts<'_>) -> Result<Admission, Refusal> {
        self.check_origins(req, None, false)
    }

    /// Let this request in, or say why not (rules in the [module docs](self)).
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::access::{AccessPolicy, RequestFacts, Refusal};
    /// let open = AccessPolicy::new(None);
    /// let page = RequestFacts { host: Some("127.0.0.1:8080"), origin: Some("http://127.0.0.1:8080"), ..Default::default() };
    /// assert!(open.check(&page).is_ok());
    /// let evil = RequestFacts { origin: Some("http://evil.example"), ..page };
    /// assert!(matches!(open.check(&evil), Err(Refusal::ForeignOrigin { .. })));
    /// ```
    pub fn check(&self, req: &RequestFacts<'_>) -> Result<Admission, Refusal> {
        self.check_origins(req, None, true)
    }

    /// [`AccessPolicy::check`] for a server that serves no page of its own (the Foxglove
    /// server): a request with an `Origin` must come from one of `origins` (e.g.
    /// `https://app.foxglove.dev`) instead of from this server's own origin; the `Host`
    /// and token rules are the panel's.
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::access::{AccessPolicy, RequestFacts, Refusal};
    /// let open = AccessPolicy::new(None);
    /// let app = ["https://app.foxglove.dev".to_string()];
    /// let from = |origin| RequestFacts { host: Some("127.0.0.1:8765"), origin, ..Default::default() };
    /// assert!(open.check_listed_origins(&from(None), &app).is_ok());
    /// assert!(open.check_listed_origins(&from(Some("https://app.foxglove.dev")), &app).is_ok());
    /// let evil = open.check_listed_origins(&from(Some("http://evil.example")), &app);
    /// assert!(matches!(evil, Err(Refusal::ForeignOrigin { .. })));
    /// ```
    pub fn check_listed_origins(
        &self,
        req: &RequestFacts<'_>,
        origins: &[String],
    ) -> Result<Admission, Refusal> {
        self.check_origins(req, Some(origins), true)
    }

    fn check_origins(
        &self,
        req: &RequestFacts<'_>,
        listed: Option<&[String]>,
        token_rule: bool,
    ) -> Result<Admission, Refusal> {
        let host = req.host.map(str::trim).filter(|h| !h.is_empty());
        if let (Some(origin), Some(listed)) = (req.origin, listed) {
            let actual = parse_origin(origin);
            if actual.is_none() || !listed.iter().any(|l| parse_origin(l) == actual) {
                return Err(Refusal::ForeignOrigin {
                    origin: shorten(origin),
                    expected: shorten(&format!("one of: {}", listed.join(", "))),
                });
            }
        } else if let Some(origin) = req.origin {
            let scheme = match req.forwarded_proto.map(forwarded_scheme) {
                _ if self.tls => "https",
                Some(Some(s)) => s,
                _ => "http",
            };
            let Some(host) = host else {
                return Err(Refusal::NoHost);
            };
            let expected = Authority::parse(host, scheme);
            let actual = parse_origin(origin);
            if expected.is_none() || actual.is_none() || actual != expected {
                return Err(Refusal::ForeignOrigin {
                    origin: shorten(origin),
                    expected: format!("{scheme}://{}", shorten(host)),
                });
            }
        }
        let Some(token) = &self.token else {
            let host = host.ok_or(Refusal::NoHost)?;
            return match Authority::parse(host, "http") {
                Some(a) if is_loopback_name(&a.host) => Ok(Admission {
                    by: Credential::NotNeeded,
                }),
                _ => Err(Refusal::HostNotLoopback {
                    host: shorten(host),
                }),
            };
        };
        if !token_rule {
            return Ok(Admission {
                by: Credential::PageOnly,
            });
        }
        let (presented, by) = [
            (req.query_token, Credential::Query),
            (req.header_token, Credential::Header),
            (req.protocol_token, Credential::Protocol),
        ]
        .into_iter()
        .find_map(|(t, by)| t.map(|t| (t, by)))
        .ok_or(Refusal::NoToken)?;
        if token.matches(presented) {
            Ok(Admission { by })
        } else {
            Err(Refusal::WrongToken)
        }
    }
}

/// `https` or `http` from an `X-Forwarded-Proto` value (its first entry).
fn forwarded_scheme(value: &str) -> Option<&'static str> {
    let first = value.split(',').next()?.trim();
    if first.eq_ignore_ascii_case("https") {
        Some("https")
    } else if first.eq_ignore_ascii_case("http") {
        Some("http")
    } else {
        None
    }
}

/// At most 100 characters of a header value, control characters replaced, for
/// messages and logs (the value is the client's, not ours).
fn shorten(s: &str) -> String {
    ros_plumbing::logging::printable(s, 100)
}

/// Scheme, host and port of an origin, normalised for comparison.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Authority {
    scheme: &'static str,
    /// lower case; IPv6 without brackets; no trailing dot
    host: String,
    port: u16,
}

impl Authority {
    /// `host[:port]` (as in `Host`) under `scheme`, whose default port applies.
    fn parse(authority: &str, scheme: &'static str) -> Option<Authority> {
        let default_port = match scheme {
            "https" => 443,
            _ => 80,
        };
        let (host, port) = if let Some(rest) = authority.strip_prefix('[') {
            let (h, after) = rest.split_once(']')?;
            h.parse::<Ipv6Addr>().ok()?;
            let port = match after {
                "" => None,
                p => Some(p.strip_prefix(':')?),
            };
            (h, port)
        } else {
            match authority.split_once(':') {
                Some((h, p)) => (h, Some(p)),
                None => (authority, None),
            }
        };
        let port = match port {
            None => default_port,
            Some(p) if !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()) => p.parse().ok()?,
            Some(_) => return None,
        };
        let host = host.strip_suffix('.').unwrap_or(host).to_ascii_lowercase();
        let valid = !host.is_empty()
            && host
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b':'));
        valid.then_some(Authority { scheme, host, port })
    }
}

/// An `Origin` header (`scheme://host[:port]`); `None` for `null`, other schemes and
/// anything malformed.
fn parse_origin(origin: &str) -> Option<Authority> {
    let (scheme, rest) = origin.trim().split_once("://")?;
    let scheme = if scheme.eq_ignore_ascii_case("http") {
        "http"
    } else if scheme.eq_ignore_ascii_case("https") {
        "https"
    } else {
        return None;
    };
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    if rest.contains(['/', '?', '#', '@']) {
        return None;
    }
    Authority::parse(rest, scheme)
}

/// `localhost`, `*.localhost`, or a loopback IP address.
fn is_loopback_name(host: &str) -> bool {
    if host == "localhost" || host.ends_with(".localhost") {
        return true;
    }
    match host.parse::<IpAddr>() {
        Ok(IpAddr::V4(a)) => a.is_loopback(),
        Ok(IpAddr::V6(a)) => {
            a.is_loopback()
                || a.to_ipv4_mapped()
                    .is_some_and(|v4: Ipv4Addr| v4.is_loopback())
        }
        Err(_) => false,
    }
}

/// `token` from a URL query (`a=1&token=…`), as sent (a valid token needs no escaping).
pub fn query_token(query: Option<&str>) -> Option<&str> {
    query?.split('&').find_map(|kv| kv.strip_prefix("token="))
}

/// The token of an `Authorization: token …` or `Authorization: Bearer …` header.
pub fn authorization_token(value: &str) -> Option<&str> {
    let (scheme, rest) = value.trim().split_once(' ')?;
    (scheme.eq_ignore_ascii_case("token") || scheme.eq_ignore_ascii_case("bearer"))
        .then(|| rest.trim())
}

/// The token of a `Sec-WebSocket-Protocol` header value: the offered subprotocol
/// `token.…` (the page offers [`PANEL_PROTOCOL`] and this one).
///
/// # Examples
/// ```
/// use gui_bridge::access::protocol_token;
/// assert_eq!(protocol_token("eezybot.panel.v1, token.abc"), Some("abc"));
/// assert_eq!(protocol_token("eezybot.panel.v1"), None);
/// ```
pub fn protocol_token(value: &str) -> Option<&str> {
    value
        .split(',')
        .find_map(|p| p.trim().strip_prefix("token."))
}

#[cfg(test)]
mod tests {
    use super::*;

    const TOKEN: &str = "0123456789abcdef0123";

    fn open() -> AccessPolicy {
        AccessPolicy::new(None)
    }

    fn locked() -> AccessPolicy {
        AccessPolicy::new(Some(Token::new(TOKEN).unwrap()))
    }

    fn req<'a>(host: &'a str, origin: Option<&'a str>) -> RequestFacts<'a> {
        RequestFacts {
            host: Some(host),
            origin,
            ..Default::default()
        }
    }

    #[test]
    fn same_origin_passes_and_another_origin_is_refused() {
        let p = open();
        for (host, origin) in [
            ("127.0.0.1:8080", "http://127.0.0.1:8080"),
            ("LOCALHOST:8080", "http://localhost:8080"),
            ("localhost:8080", "http://LocalHost:8080/"),
            ("[::1]:8080", "http://[::1]:8080"),
            ("localhost", "http://localhost:80"),
            ("localhost:80", "http://localhost"),
            ("localhost.", "http://localhost"),
        ] {
            assert!(p.check(&req(host, Some(origin))).is_ok(), "{host} {origin}");
        }
        for (host, origin) in [
            ("127.0.0.1:8080", "http://evil.example"),
            ("127.0.0.1:8080", "http://127.0.0.1:8081"),
            ("127.0.0.1:8080", "https://127.0.0.1:8080"),
            ("127.0.0.1:8080", "http://127.0.0.1"),
            ("127.0.0.1", "https://127.0.0.1"),
            ("127.0.0.1:8080", "null"),
            ("127.0.0.1:8080", "file://"),
            ("127.0.0.1:8080", "chrome-extension://abcdef"),
            ("127.0.0.1:8080", "http://127.0.0.1:8080.evil.example"),
            ("127.0.0.1:8080", "http://user@127.0.0.1:8080"),
            ("127.0.0.1:8080", "http://127.0.0.1:8080/page"),
            ("127.0.0.1:8080", ""),
            ("127.0.0.1:8080", "http://127.0.0.1:+8080"),
            ("127.0.0.1:8080", "http://127.0.0.1:99999"),
            ("[::1]:8080", "http://[::1]x:8080"),
        ] {
            let r = p.check(&req(host, Some(origin)));
            assert!(
                matches!(r, Err(Refusal::ForeignOrigin { .. })),
                "{host} {origin}: {r:?}"
            );
            assert_eq!(r.unwrap_err().status(), 403);
        }
    }

    #[test]
    fn a_tls_proxy_may_say_the_page_was_https() {
        let p = locked();
        let facts = RequestFacts {
            host: Some("panel.example"),
            origin: Some("https://panel.example"),
            forwarded_proto: Some("https"),
            query_token: Some(TOKEN),
            ..Default::default()
        };
        assert!(p.check(&facts).is_ok());
        // without the proxy's word the page's own origin is http://Host
        let plain = RequestFacts {
            forwarded_proto: None,
            ..facts
        };
        assert!(matches!(
            p.check(&plain),
            Err(Refusal::ForeignOrigin { .. })
        ));
        let junk = RequestFacts {
            forwarded_proto: Some("gopher"),
            ..facts
        };
        assert!(p.check(&junk).is_err());
    }

    #[test]
    fn no_origin_is_a_program_and_passes_the_origin_rule() {
        assert!(open().check(&req("127.0.0.1:8080", None)).is_ok());
        assert_eq!(
            locked().check(&req("127.0.0.1:8080", None)),
            Err(Refusal::NoToken)
        );
    }

    #[test]
    fn without_a_token_only_loopback_names_are_answered() {
        let p = open();
        for host in [
            "127.0.0.1:8080",
            "127.0.0.2:8080",
            "localhost:8080",
            "panel.localhost:8080",
            "[::1]:8080",
            "[::ffff:127.0.0.1]:8080",
        ] {
            assert!(p.check(&req(host, None)).is_ok(), "{host}");
        }
        // DNS rebinding: the attacker's name, its own origin
        for (host, origin) in [
            ("evil.example:8080", Some("http://evil.example:8080")),
            ("192.168.1.5:8080", None),
            ("localhost.evil.example:8080", None),
            ("0.0.0.0:8080", None),
        ] {
            let r = p.check(&req(host, origin));
            assert!(
                matches!(r, Err(Refusal::HostNotLoopback { .. })),
                "{host}: {r:?}"
            );
        }
        assert_eq!(p.check(&RequestFacts::default()), Err(Refusal::NoHost));
        assert_eq!(Refusal::NoHost.status(), 400);
    }

    #[test]
    fn with_a_token_every_request_presents_it() {
        let p = locked();
        let base = req("192.168.1.5:8080", Some("http://192.168.1.5:8080"));
        assert_eq!(p.check(&base), Err(Refusal::NoToken));
        assert_eq!(Refusal::NoToken.status(), 401);
        let q = RequestFacts {
            query_token: Some(TOKEN),
            ..base
        };
        assert_eq!(
            p.check(&q),
            Ok(Admission {
                by: Credential::Query
            })
        );
        let h = RequestFacts {
            header_token: Some(TOKEN),
            ..base
        };
        assert_eq!(p.check(&h).unwrap().by, Credential::Header);
        let c = RequestFacts {
            protocol_token: Some(TOKEN),
            ..base
        };
        assert_eq!(p.check(&c).unwrap().by, Credential::Protocol);
        for wrong in ["", "0123456789abcdef012", "0123456789abcdef0124", "x"] {
            let w = RequestFacts {
                query_token: Some(wrong),
                ..base
            };
            assert_eq!(p.check(&w), Err(Refusal::WrongToken), "{wrong:?}");
            assert_eq!(Refusal::WrongToken.status(), 403);
        }
        // the first credential present decides
        let both = RequestFacts {
            query_token: Some(TOKEN),
            protocol_token: Some("stale-token-of-a-previous-run"),
            ..base
        };
        assert!(p.check(&both).is_ok());
        let stale = RequestFacts {
            query_token: Some("stale-token-of-a-previous-run"),
            protocol_token: Some(TOKEN),
            ..base
        };
        assert_eq!(p.check(&stale), Err(Refusal::WrongToken));
        // any Host (a LAN address, a name) is fine once the token is right
        let named = RequestFacts {
            host: Some("arm-pc.lan:8080"),
            origin: None,
            query_token: Some(TOKEN),
            ..Default::default()
        };
        assert!(p.check(&named).is_ok());
        // the token does not excuse another origin
        let evil = RequestFacts {
            origin: Some("http://evil.example"),
            ..q
        };
        assert!(matches!(p.check(&evil), Err(Refusal::ForeignOrigin { .. })));
    }

    #[test]
    fn the_page_needs_no_token_but_keeps_the_origin_and_host_rules() {
        let page = req("192.168.1.5:8080", None);
        assert_eq!(locked().check_page(&page).unwrap().by, Credential::PageOnly);
        assert_eq!(locked().check(&page), Err(Refusal::NoToken));
        let evil = req("192.168.1.5:8080", Some("http://evil.example"));
        assert!(matches!(
            locked().check_page(&evil),
            Err(Refusal::ForeignOrigin { .. })
        ));
        let rebound = req("evil.example:8080", None);
        assert!(matches!(
            open().check_page(&rebound),
            Err(Refusal::HostNotLoopback { .. })
        ));
    }

    #[test]
    fn token_parameter_resolution() {
        let no_random = || Err::<[u8; GENERATED_TOKEN_BYTES], _>("no entropy".to_string());
        let r = resolve_token("", true, no_random).unwrap();
        assert_eq!((r.0, r.1), (None, TokenSource::None));
        let (t, s) = resolve_token("", false, || Ok([0xab; GENERATED_TOKEN_BYTES])).unwrap();
        assert_eq!(s, TokenSource::Generated);
        assert_eq!(t.unwrap().reveal(), "ab".repeat(GENERATED_TOKEN_BYTES));
        let (_, s) =
            resolve_token(SHOWN_GENERATED, false, || Ok([1; GENERATED_TOKEN_BYTES])).unwrap();
        assert_eq!(s, TokenSource::Generated);
        assert_eq!(
            resolve_token("", false, no_random).unwrap_err(),
            AccessError::NoRandomness("no entropy".into())
        );
        let (t, s) = resolve_token(TOKEN, true, no_random).unwrap();
        assert_eq!((t.unwrap().reveal(), s), (TOKEN, TokenSource::Parameter));
        assert_eq!(
            resolve_token(SHOWN_HIDDEN, false, no_random).unwrap_err(),
            AccessError::HiddenPlaceholder
        );
        let e = resolve_token("hunter2", false, no_random).unwrap_err();
        assert!(e.to_string().contains("7 characters"), "{e}");
        assert!(
            !e.to_string().contains("hunter2"),
            "an error must not show the token"
        );
        assert_eq!(TokenSource::Generated.shown_as(), Some(SHOWN_GENERATED));
        assert_eq!(TokenSource::Parameter.shown_as(), Some(SHOWN_HIDDEN));
        assert_eq!(TokenSource::None.shown_as(), None);
        for ok in ["", SHOWN_GENERATED, SHOWN_HIDDEN, TOKEN] {
            assert!(check_token_parameter(ok).is_ok(), "{ok}");
        }
        assert!(check_token_parameter("with space 0123456789").is_err());
    }

    #[test]
    fn tokens_compare_exactly_and_never_print() {
        let t = Token::new(TOKEN).unwrap();
        assert!(t.matches(TOKEN));
        assert!(!t.matches(&TOKEN.to_uppercase()));
        assert!(!t.matches(&format!("{TOKEN}0")));
        assert_eq!(format!("{t:?}"), "Token(…)");
        assert!(!format!("{:?}", locked()).contains(TOKEN));
    }

    #[test]
    fn credentials_are_found_where_clients_put_them() {
        assert_eq!(query_token(Some("token=abc")), Some("abc"));
        assert_eq!(query_token(Some("x=1&token=abc&y=2")), Some("abc"));
        assert_eq!(query_token(Some("mytoken=abc")), None);
        assert_eq!(query_token(None), None);
        assert_eq!(authorization_token("token abc"), Some("abc"));
        assert_eq!(authorization_token("Bearer abc "), Some("abc"));
        assert_eq!(authorization_token("Basic YWJj"), None);
        assert_eq!(protocol_token("eezybot.panel.v1,token.abc"), Some("abc"));
        assert_eq!(protocol_token("token"), None);
    }

    #[test]
    fn refusal_texts_are_short_and_safe() {
        let long = format!("http://{}\u{7}.example", "a".repeat(500));
        let r = open()
            .check(&req("127.0.0.1:8080", Some(&long)))
            .unwrap_err();
        let text = r.to_string();
        assert!(text.len() < 400 && !text.contains('\u{7}'), "{text}");
        assert_eq!(r.kind(), "origin");
    }
}
