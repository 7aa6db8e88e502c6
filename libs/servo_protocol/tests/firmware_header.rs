//! The firmware's protocol constants are this crate's: the section of
//! `firmware/servo_control/protocol.h` between `// generated: frame constants` and
//! `// end generated: frame constants` (the version, the frame's sizes, the message
//! types with their payload lengths, the state byte, the role byte, the leader role's
//! sampling) is rendered here from `frame.rs`,
//! and this test fails when the header holds anything else. After changing a constant,
//! `EEZYBOT_BLESS=1 cargo test -p servo_protocol --test firmware_header` rewrites the
//! section; then rebuild the firmware (`make -C firmware/servo_control`).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use servo_protocol::{
    DeviceState, MsgType, Role, LEADER_CHANNELS, LEADER_OVERSAMPLING, LEADER_PERIOD_US,
    MAX_PAYLOAD, OVERHEAD, PROTOCOL_VERSION, SYNC,
};
use std::fmt::Write as _;
use std::path::Path;

const HEADER: &str = "firmware/servo_control/protocol.h";
const SECTION: &str = "frame constants";
const REGENERATE: &str = "EEZYBOT_BLESS=1 cargo test -p servo_protocol --test firmware_header";

/// `HelloAck` → `HELLO_ACK`: a variant's name as the C enumerator's tail.
fn c_name(variant: impl std::fmt::Debug) -> String {
    let mut out = String::new();
    for (i, c) in format!("{variant:?}").chars().enumerate() {
        if c.is_ascii_uppercase() && i > 0 {
            out.push('_');
        }
        out.push(c.to_ascii_uppercase());
    }
    out
}

/// The section's body, as the header holds it.
fn render() -> String {
    let mut s = format!(
        "// Written from libs/servo_protocol/src/frame.rs, the one source of these values; after\n\
         // a change there: {REGENERATE}\n\
         #define PROTOCOL_VERSION {PROTOCOL_VERSION}\n\
         #define PROTO_SYNC 0x{SYNC:02X}\n\
         #define PROTO_MAX_PAYLOAD {MAX_PAYLOAD}\n\
         #define PROTO_OVERHEAD {OVERHEAD}\n\
         \n\
         enum MsgType {{\n"
    );
    for t in MsgType::ALL {
        let _ = writeln!(s, "  MSG_{} = {:#x},", c_name(t), t as u8);
    }
    s.push_str("};\n\n// The state byte of a STATE payload.\nenum DeviceState {\n");
    for state in DeviceState::ALL {
        let _ = writeln!(s, "  STATE_{} = {},", c_name(state), state.to_byte());
    }
    s.push_str("};\n\n// The role byte of a ROLE payload.\nenum DeviceRole {\n");
    for role in Role::ALL {
        let _ = writeln!(s, "  ROLE_{} = {},", c_name(role), role.to_byte());
    }
    let _ = write!(
        s,
        "}};\n\n\
         // The leader role's sampling: a LEADER_STATE every LEADER_PERIOD_US, each channel\n\
         // the sum of LEADER_OVERSAMPLING samples.\n\
         #define LEADER_CHANNELS {LEADER_CHANNELS}\n\
         #define LEADER_OVERSAMPLING {LEADER_OVERSAMPLING}\n\
         #define LEADER_PERIOD_US {LEADER_PERIOD_US}\n"
    );
    s.push_str(
        "\n\
         // Payload length each type must have, or -1 for an unknown type.\n\
         static inline int8_t proto_payload_len(uint8_t type) {\n  switch (type) {\n",
    );
    for t in MsgType::ALL {
        let _ = writeln!(s, "    case MSG_{}: return {};", c_name(t), t.payload_len());
    }
    s.push_str("    default: return -1;\n  }\n}\n");
    s
}

#[test]
fn protocol_h_holds_the_constants_of_frame_rs() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(HEADER);
    let text = std::fs::read_to_string(&path).unwrap();
    let (begin, end) = (
        format!("// generated: {SECTION}\n"),
        format!("// end generated: {SECTION}\n"),
    );
    let start = text.find(&begin).expect("no begin marker") + begin.len();
    let stop = start + text[start..].find(&end).expect("no end marker");
    let want = render();
    if text[start..stop] == want {
        return;
    }
    if std::env::var("EEZYBOT_BLESS").is_ok_and(|v| v == "1") {
        let text = format!("{}{want}{}", &text[..start], &text[stop..]);
        std::fs::write(&path, text).unwrap();
        return;
    }
    panic!(
        "{HEADER}: the section `{SECTION}` differs from frame.rs; regenerate it with\n  \
         {REGENERATE}\nIt should read:\n\n{want}"
    );
}

#[test]
fn c_names_are_the_firmware_s() {
    assert_eq!(c_name(MsgType::HelloAck), "HELLO_ACK");
    assert_eq!(c_name(DeviceState::WatchdogDetached), "WATCHDOG_DETACHED");
    assert_eq!(c_name(MsgType::Estop), "ESTOP");
    assert_eq!(c_name(MsgType::LeaderState), "LEADER_STATE");
    assert_eq!(c_name(Role::Follower), "FOLLOWER");
}
