//! The Foxglove SDK's server listens on no port (issue 36 item 6): before, it listened on
//! a free port of 127.0.0.1, where a page of any origin connected past the front and got
//! the server info and the channel list, and four unfinished 64 MiB messages took the
//! node to 363 MB. A test binary of its own: it counts this process's listening sockets,
//! which another test's bridge would add to.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use common::{channel_ids, connect, next_json, next_message_data, start, subscribe};
use eezybot_msgs::std_msgs::String as RosString;
use foxglove_bridge::ClientPublish;
use futures::SinkExt;
use std::collections::BTreeSet;

/// The TCP ports this process listens on (its sockets' inodes in /proc/net/tcp{,6}).
fn listening_ports() -> BTreeSet<u16> {
    let inodes: BTreeSet<String> = std::fs::read_dir("/proc/self/fd")
        .unwrap()
        .filter_map(|e| std::fs::read_link(e.ok()?.path()).ok())
        .filter_map(|t| {
            let t = t.to_string_lossy().into_owned();
            Some(t.strip_prefix("socket:[")?.strip_suffix(']')?.to_string())
        })
        .collect();
    let mut ports = BTreeSet::new();
    for table in ["/proc/net/tcp", "/proc/net/tcp6"] {
        let Ok(text) = std::fs::read_to_string(table) else {
            continue;
        };
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            // st 0A: LISTEN; f[9]: the inode
            if f.len() > 9 && f[3] == "0A" && inodes.contains(f[9]) {
                let port = f[1].rsplit(':').next().unwrap();
                ports.insert(u16::from_str_radix(port, 16).unwrap());
            }
        }
    }
    ports
}

#[tokio::test]
async fn the_sdk_listens_on_no_port_and_the_front_still_serves() {
    let before = listening_ports();
    let bridge = start(ClientPublish::Targets { queue: 8 }).await;
    let urdf = eezybot_msgs::cdr::encode(&RosString {
        data: "<robot name='r'/>".into(),
    })
    .unwrap();
    bridge.log("robot_description", &urdf, 1).unwrap();
    let added: BTreeSet<u16> = listening_ports().difference(&before).copied().collect();
    assert_eq!(
        added,
        BTreeSet::from([bridge.local_addr().port()]),
        "the bridge listens on more than its own address"
    );
    // a client through the front: the server info, the channels, the latched sample
    let mut ws = connect(bridge.local_addr()).await;
    next_json(&mut ws, "serverInfo").await;
    let ids = channel_ids(&mut ws).await;
    ws.send(subscribe(1, ids["/robot_description"]))
        .await
        .unwrap();
    assert_eq!(next_message_data(&mut ws).await, (1, 1, urdf));
    bridge.stop().await;
}
