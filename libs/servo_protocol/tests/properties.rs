//! decode(encode(f)) = f under any chunking; arbitrary bytes never panic the decoder;
#![allow(clippy::single_match)]
//! corrupted frames are never accepted as different frames.
#![allow(clippy::unwrap_used)]

use proptest::prelude::*;
use servo_protocol::{
    decode, encode, DeviceState, Frame, Message, Role, StopAction, WatchdogAction,
};

fn message() -> impl Strategy<Value = Message> {
    let ticks = prop::array::uniform4(any::<u16>());
    let state = prop_oneof![
        Just(DeviceState::Idle),
        Just(DeviceState::Running),
        Just(DeviceState::WatchdogHold),
        Just(DeviceState::WatchdogDetached),
        Just(DeviceState::Estop),
        Just(DeviceState::Leader)
    ];
    prop_oneof![
        any::<u8>().prop_map(|version| Message::Hello { version }),
        (
            any::<u8>(),
            any::<u8>(),
            any::<u8>(),
            any::<u8>(),
            any::<u16>()
        )
            .prop_map(
                |(version, firmware_major, firmware_minor, servos, watchdog_ms)| {
                    Message::HelloAck {
                        version,
                        firmware_major,
                        firmware_minor,
                        servos,
                        watchdog_ms,
                    }
                }
            ),
        ticks.prop_map(|ticks| Message::SetPulses { ticks }),
        Just(Message::Heartbeat),
        (any::<u8>(), state, any::<bool>(), any::<u8>(), ticks).prop_map(
            |(ack_seq, state, clamped, rx_errors, ticks)| Message::State {
                ack_seq,
                state,
                clamped,
                rx_errors,
                ticks
            }
        ),
        prop_oneof![
            Just(None),
            Just(Some(StopAction::Hold)),
            Just(Some(StopAction::Detach))
        ]
        .prop_map(|engaged| Message::Estop { engaged }),
        (any::<u16>(), any::<bool>()).prop_map(|(watchdog_ms, d)| Message::Config {
            watchdog_ms,
            action: if d {
                WatchdogAction::Detach
            } else {
                WatchdogAction::Hold
            }
        }),
        prop_oneof![Just(Role::Follower), Just(Role::Leader)]
            .prop_map(|role| Message::Role { role }),
        (
            prop::array::uniform4(any::<u16>()),
            any::<bool>(),
            any::<u8>(),
            any::<u8>()
        )
            .prop_map(|(adc, deadman, window, overruns)| Message::LeaderState {
                adc,
                deadman,
                window,
                overruns
            }),
    ]
}

fn frames() -> impl Strategy<Value = Vec<Frame>> {
    prop::collection::vec(
        (any::<u8>(), message()).prop_map(|(seq, msg)| Frame { seq, msg }),
        1..20,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 3000, ..ProptestConfig::default() })]

    #[test]
    fn roundtrip_under_any_chunking(frames in frames(), cuts in prop::collection::vec(1usize..20, 0..40)) {
        let stream: Vec<u8> = frames.iter().flat_map(encode).collect();
        let mut buf = Vec::new();
        let mut got = Vec::new();
        let mut pos = 0;
        let mut cuts = cuts.into_iter();
        while pos < stream.len() {
            let n = cuts.next().unwrap_or(stream.len()).min(stream.len() - pos);
            buf.extend_from_slice(&stream[pos..pos + n]);
            pos += n;
            loop {
                match decode(&mut buf) {
                    Ok(Some(f)) => got.push(f),
                    Ok(None) => break,
                    Err(e) => prop_assert!(false, "valid stream rejected: {e}"),
                }
            }
        }
        prop_assert_eq!(got, frames);
        prop_assert!(buf.is_empty());
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let mut buf = bytes;
        let mut rounds = 0;
        loop {
            rounds += 1;
            prop_assert!(rounds < 2000, "decoder does not make progress");
            match decode(&mut buf) {
                Ok(None) => break,
                Ok(Some(_)) | Err(_) => {}
            }
        }
    }

    #[test]
    fn garbage_between_frames_costs_nothing_but_garbage(frames in frames(), junk in prop::collection::vec(any::<u8>(), 0..30)) {
        // junk without a start marker between every two frames
        let junk: Vec<u8> = junk.into_iter().filter(|b| *b != servo_protocol::SYNC).collect();
        let mut buf: Vec<u8> = frames.iter().flat_map(|f| { let mut v = junk.clone(); v.extend(encode(f)); v }).collect();
        let mut got = vec![];
        loop {
            match decode(&mut buf) {
                Ok(Some(f)) => got.push(f),
                Ok(None) => break,
                Err(_) => {}
            }
        }
        prop_assert_eq!(got, frames);
    }

    #[test]
    fn a_flipped_bit_is_never_a_different_frame(frame in (any::<u8>(), message()).prop_map(|(seq, msg)| Frame { seq, msg }), bit in 8usize..96) {
        let mut bytes = encode(&frame);
        let bit = bit % (bytes.len() * 8 - 8) + 8; // never the start marker
        bytes[bit / 8] ^= 1 << (bit % 8);
        let mut buf = bytes;
        loop {
            match decode(&mut buf) {
                Ok(Some(f)) => prop_assert!(false, "corrupted frame accepted as {f:?}"),
                Ok(None) => break,
                Err(_) => {}
            }
        }
    }
}

#[test]
fn a_four_servo_command_is_12_bytes() {
    let f = Frame {
        seq: 0,
        msg: Message::SetPulses { ticks: [2944; 4] },
    };
    let bytes = encode(&f).len();
    assert_eq!(bytes, 12);
    // and PROTOCOL.md's figure for it is this length on the wire at 115200 baud, 10 bits
    // a byte (8 data, start and stop)
    let wire_ms = bytes as f64 * 10.0 / 115_200.0 * 1e3;
    let said = format!("**{bytes} bytes = {wire_ms:.2} ms on the wire**");
    let doc = include_str!("../../../firmware/servo_control/PROTOCOL.md");
    assert!(doc.contains(&said), "PROTOCOL.md does not say {said}");
}

#[test]
fn protocol_md_example_frame() {
    let f = Frame {
        seq: 7,
        msg: Message::SetPulses { ticks: [2944; 4] },
    };
    let hex: Vec<String> = encode(&f).iter().map(|b| format!("{b:02X}")).collect();
    let doc = include_str!("../../../firmware/servo_control/PROTOCOL.md");
    assert!(
        doc.contains(&hex.join(" ")),
        "PROTOCOL.md example is not {}",
        hex.join(" ")
    );
}

#[test]
fn protocol_md_leader_examples() {
    let doc = include_str!("../../../firmware/servo_control/PROTOCOL.md");
    let hex = |f: &Frame| -> String {
        encode(f)
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let role = Frame {
        seq: 2,
        msg: Message::Role { role: Role::Leader },
    };
    let leader = Frame {
        seq: 0x31,
        msg: Message::LeaderState {
            adc: [4096, 8192, 12288, 16368],
            deadman: true,
            window: 8,
            overruns: 0,
        },
    };
    for f in [role, leader] {
        assert!(
            doc.contains(&hex(&f)),
            "PROTOCOL.md has no example {}",
            hex(&f)
        );
    }
    // and what the example says the sums stand for: 1250, 2500, 3750 mV and the top
    let s = servo_protocol::LeaderState::from_frame(&leader).unwrap();
    assert_eq!(
        [0, 1, 2].map(|i| s.millivolts(i, 5000.0)),
        [1250.0, 2500.0, 3750.0]
    );
    assert_eq!(s.adc[3], servo_protocol::LEADER_ADC_MAX);
}
