//! Browser requests and the page.
#![allow(clippy::unwrap_used)]

use gui_bridge::web::*;
use std::time::Instant;

#[test]
fn requests_parse() {
    let r: ClientRequest = serde_json::from_str(r#"{"t":"target","xyz":[0.2,0,0.15]}"#).unwrap();
    assert_eq!(
        r,
        ClientRequest::Target {
            xyz: [0.2, 0.0, 0.15]
        }
    );
    let r: ClientRequest =
        serde_json::from_str(r#"{"t":"joints","q":{"base_joint":0.1}}"#).unwrap();
    assert!(matches!(r, ClientRequest::Joints { .. }));
    assert!(serde_json::from_str::<ClientRequest>(r#"{"t":"launch_missiles"}"#).is_err());
}

#[test]
fn the_page_is_small_and_self_contained() {
    assert!(INDEX_HTML.len() + PANEL_JS.len() + PANEL_CSS.len() < 300_000);
    for file in [INDEX_HTML, PANEL_JS, PANEL_CSS] {
        for forbidden in ["http://", "https://", "//cdn", "@import"] {
            let hits: Vec<&str> = file
                .lines()
                .filter(|l| l.contains(forbidden) && !l.contains("xmlns"))
                .collect();
            assert!(hits.is_empty(), "the page refers to another host: {hits:?}");
        }
    }
}

#[test]
fn the_page_has_no_inline_script_or_style_for_its_csp_to_block() {
    let lower = INDEX_HTML.to_ascii_lowercase();
    assert!(!lower.contains("<style"), "inline <style>");
    assert!(!lower.contains(" style="), "a style attribute");
    assert!(!lower.contains("javascript:"));
    for (at, _) in lower.match_indices("<script") {
        let tag = &lower[at..at + lower[at..].find('>').unwrap()];
        assert!(tag.contains(" src="), "an inline <script>: {tag}");
    }
    for attr in [
        " onclick=",
        " onload=",
        " onerror=",
        " oninput=",
        " onsubmit=",
    ] {
        assert!(!lower.contains(attr), "an inline handler {attr}");
    }
}

fn value(stats: &WebStats, key: &str) -> String {
    stats
        .values()
        .into_iter()
        .find(|(k, _)| *k == key)
        .map(|(_, v)| v)
        .unwrap_or_else(|| panic!("no {key} in {:?}", stats.values()))
}

fn bad_request(reason: &str) -> WebEvent {
    WebEvent::BadRequest {
        from: "127.0.0.1:5000".into(),
        reason: reason.into(),
    }
}

#[test]
fn every_refused_request_is_counted_and_the_last_named() {
    let (mut stats, now) = (WebStats::default(), Instant::now());
    assert_eq!(value(&stats, "rejected"), "0");
    assert_eq!(value(&stats, "last_rejection"), "");
    stats.on_event(bad_request("expected value at line 1 column 1"), now);
    stats.rejected_request(
        "bad_joint_target",
        "gripper_joint = 1e300 is outside its limits 0.0 … 0.6",
        now,
    );
    assert_eq!(value(&stats, "rejected"), "2");
    assert_eq!(value(&stats, "bad_requests"), "1");
    assert_eq!(
        value(&stats, "last_rejection"),
        "gripper_joint = 1e300 is outside its limits 0.0 … 0.6"
    );
    // a long reason is cut to a readable length
    stats.on_event(bad_request(&"x".repeat(1 << 20)), now);
    let last = value(&stats, "last_rejection");
    assert!(
        last.starts_with("bad request: xxx") && last.len() < REASON_MAX + 64,
        "{}",
        last.len()
    );
}

#[test]
fn client_ends_are_counted_by_kind() {
    let (mut stats, now) = (WebStats::default(), Instant::now());
    let mut ended = |port: u16, end: &ClientEnd, bad_requests: u64| {
        let from = format!("127.0.0.1:{port}");
        stats.on_event(WebEvent::Connected, now);
        let end = end.clone();
        stats.on_event(
            WebEvent::Ended {
                from,
                end,
                bad_requests,
            },
            now,
        );
    };
    ended(5000, &ClientEnd::Closed, 0);
    ended(5001, &ClientEnd::Shutdown, 0);
    let pipe = tungstenite::Error::Io(std::io::ErrorKind::BrokenPipe.into());
    let end = ClientEnd::from_error(&pipe, false, 65536);
    assert!(
        matches!(end, ClientEnd::Gone(_)) && end.is_drop(),
        "{end:?}"
    );
    ended(5002, &end, 3);
    ended(5003, &ClientEnd::Oversized { max_bytes: 65536 }, 0);
    let protocol =
        tungstenite::Error::Protocol(tungstenite::error::ProtocolError::NonZeroReservedBits);
    let end = ClientEnd::from_error(&protocol, true, 65536);
    assert!(matches!(end, ClientEnd::ReadError(_)), "{end:?}");
    ended(5004, &end, 0);
    assert_eq!(value(&stats, "clients"), "0");
    assert_eq!(value(&stats, "clients_closed"), "1");
    assert_eq!(value(&stats, "clients_dropped"), "3");
    assert_eq!(value(&stats, "closed_oversized"), "1");
    assert!(value(&stats, "last_client_drop").starts_with("127.0.0.1:5004: read error: "));
    let too_big = tungstenite::Error::Capacity(tungstenite::error::CapacityError::MessageTooLong {
        size: 70000,
        max_size: 65536,
    });
    assert_eq!(
        ClientEnd::from_error(&too_big, true, 65536),
        ClientEnd::Oversized { max_bytes: 65536 }
    );
    assert_eq!(
        ClientEnd::from_error(&tungstenite::Error::ConnectionClosed, false, 65536),
        ClientEnd::Closed
    );
}
