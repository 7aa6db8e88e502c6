//! Browser requests and the page.
#![allow(clippy::unwrap_used)]

use gui_bridge::web::*;

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
    assert!(INDEX_HTML.len() < 300_000);
    for forbidden in ["http://", "https://", "//cdn", "@import"] {
        let hits: Vec<&str> = INDEX_HTML
            .lines()
            .filter(|l| l.contains(forbidden) && !l.contains("xmlns"))
            .collect();
        assert!(hits.is_empty(), "the page refers to another host: {hits:?}");
    }
}
