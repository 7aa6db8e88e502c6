//! Frames of the servo link and their encoding (see `firmware/servo_control/PROTOCOL.md`).
//!
//! ```text
//! 0xA5 | type<<4 | len | seq | payload[len] | crc8(type/len .. payload)
//! ```

/// Start marker of every frame.
pub const SYNC: u8 = 0xA5;
/// Protocol version this code speaks (3: the leader role, [`MsgType::Role`] and
/// [`MsgType::LeaderState`]; a follower's frames are those of version 2).
pub const PROTOCOL_VERSION: u8 = 3;
/// Number of servo channels.
pub const SERVOS: usize = 4;
/// Pulse widths are counted in Timer1 ticks of 0.5 µs (16 MHz / 8).
pub const TICKS_PER_US: u16 = 2;
/// Largest payload a frame can carry (4-bit length).
pub const MAX_PAYLOAD: usize = 15;
/// Bytes around the payload: sync, type/len, seq, crc.
pub const OVERHEAD: usize = 4;

/// Message types (the high nibble of the second byte).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum MsgType {
    /// host → device: protocol version
    Hello = 0x1,
    /// device → host: versions and limits
    HelloAck = 0x2,
    /// host → device: four pulse widths
    SetPulses = 0x3,
    /// host → device: keep-alive
    Heartbeat = 0x4,
    /// device → host: state and applied pulses
    State = 0x5,
    /// host → device: engage/release the emergency stop
    Estop = 0x6,
    /// host → device: watchdog timeout and action
    Config = 0x7,
    /// host → device: follower (drive the servos) or leader (stream the potentiometers)
    Role = 0x8,
    /// device → host, leader role only: the potentiometers and the deadman button of one
    /// sampling window
    LeaderState = 0x9,
}

impl MsgType {
    /// Every message type, in the order of their numbers.
    pub const ALL: [MsgType; 9] = [
        MsgType::Hello,
        MsgType::HelloAck,
        MsgType::SetPulses,
        MsgType::Heartbeat,
        MsgType::State,
        MsgType::Estop,
        MsgType::Config,
        MsgType::Role,
        MsgType::LeaderState,
    ];

    fn from_nibble(n: u8) -> Option<MsgType> {
        MsgType::ALL.into_iter().find(|t| *t as u8 == n)
    }

    /// The payload length this type must have.
    pub fn payload_len(self) -> usize {
        match self {
            MsgType::Hello => 1,
            MsgType::HelloAck => 6,
            MsgType::SetPulses => 8,
            MsgType::Heartbeat => 0,
            MsgType::State => 12,
            MsgType::Estop => 1,
            MsgType::Config => 3,
            MsgType::Role => 1,
            MsgType::LeaderState => 11,
        }
    }
}

/// What the device is for: set by [`Message::Role`], reported in every STATE (the
/// leader's state byte is [`DeviceState::Leader`]). A device powers up, and every HELLO
/// puts it back, in the follower role.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(u8)]
pub enum Role {
    /// Drives the servos on pins 8–11 (version 2's device).
    #[default]
    Follower = 0,
    /// A leader arm (or a box of potentiometers) on a second Uno: no pulses; streams
    /// [`Message::LeaderState`] with A0–A3 and the deadman button on D2.
    Leader = 1,
}

impl Role {
    /// Every role, in the order of their bytes.
    pub const ALL: [Role; 2] = [Role::Follower, Role::Leader];

    /// The role's byte in a ROLE payload.
    pub fn to_byte(self) -> u8 {
        self as u8
    }
    fn from_byte(b: u8) -> Option<Role> {
        Role::ALL.into_iter().find(|r| r.to_byte() == b)
    }
}

/// Leader role: potentiometer channels, A0–A3.
pub const LEADER_CHANNELS: usize = 4;
/// Leader role: ADC samples summed into each channel's value of a LEADER_STATE.
pub const LEADER_OVERSAMPLING: u16 = 16;
/// Leader role: a channel's value that stands for the ADC reference (AVcc, the 5 V that
/// also feeds the potentiometers): 16 samples × 1024 codes. A value `s` means the input
/// was `s / 16384` of AVcc (the datasheet's `ADC = Vin × 1024 / Vref`, summed).
pub const LEADER_FULL_SCALE: u16 = LEADER_OVERSAMPLING * 1024;
/// Leader role: the largest value a channel can report (16 samples of 1023).
pub const LEADER_ADC_MAX: u16 = LEADER_OVERSAMPLING * 1023;
/// Leader role: one sampling window, and so the period of LEADER_STATE: 64 conversions
/// (16 per channel, interleaved A0 A1 A2 A3 A0 …) 150 µs apart, 9.6 ms (104.2 Hz).
pub const LEADER_PERIOD_US: u32 = 9600;

/// What the device does when it stops following commands (watchdog, e-stop).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopAction {
    /// Keep sending the last pulses: the servos hold their position.
    Hold,
    /// Stop the pulses: the servos go limp.
    Detach,
}

/// What the device does on silence longer than its watchdog timeout.
pub type WatchdogAction = StopAction;

/// The device's state, as reported in [`Message::State`] (the number: its byte there).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum DeviceState {
    /// No pulses and no command to follow: powered up (the pose it reports is its
    /// hold pose) or e-stop released after a detaching e-stop (the last command).
    Idle = 0,
    /// Following commands.
    Running = 1,
    /// Watchdog fired: holding the last pulses.
    WatchdogHold = 2,
    /// Watchdog fired: pulses stopped.
    WatchdogDetached = 3,
    /// Emergency stop: holding (or, engaged with [`StopAction::Detach`], no
    /// pulses); commands ignored.
    Estop = 4,
    /// The leader role ([`Role::Leader`]): no pulses, LEADER_STATE streamed; SET_PULSES
    /// and ESTOP change nothing.
    Leader = 5,
}

impl DeviceState {
    /// Every state, in the order of their bytes.
    pub const ALL: [DeviceState; 6] = [
        DeviceState::Idle,
        DeviceState::Running,
        DeviceState::WatchdogHold,
        DeviceState::WatchdogDetached,
        DeviceState::Estop,
        DeviceState::Leader,
    ];

    /// The state's byte in a STATE payload.
    pub fn to_byte(self) -> u8 {
        self as u8
    }
    fn from_byte(b: u8) -> Option<DeviceState> {
        DeviceState::ALL.into_iter().find(|s| s.to_byte() == b)
    }
    /// A short name for logs and diagnostics.
    pub fn name(self) -> &'static str {
        match self {
            DeviceState::Idle => "idle",
            DeviceState::Running => "running",
            DeviceState::WatchdogHold => "watchdog hold",
            DeviceState::WatchdogDetached => "watchdog detached",
            DeviceState::Estop => "e-stop",
            DeviceState::Leader => "leader",
        }
    }
}

/// A decoded message (the payload of a frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Message {
    /// host → device: start a session speaking `version`.
    Hello {
        /// protocol version the host speaks
        version: u8,
    },
    /// device → host: answer to Hello.
    HelloAck {
        /// protocol version the device speaks
        version: u8,
        /// firmware version, major
        firmware_major: u8,
        /// firmware version, minor
        firmware_minor: u8,
        /// number of servo channels
        servos: u8,
        /// current watchdog timeout (ms)
        watchdog_ms: u16,
    },
    /// host → device: pulse widths in 0.5 µs ticks; 0 = no pulses on that channel.
    SetPulses {
        /// ticks for pins 8, 9, 10, 11
        ticks: [u16; SERVOS],
    },
    /// host → device: keep-alive; the device answers with State.
    Heartbeat,
    /// device → host: state, errors and the pulses on the pins.
    State {
        /// sequence number of the frame this answers (or of the last received frame)
        ack_seq: u8,
        /// what the device is doing
        state: DeviceState,
        /// bit 0: the last SetPulses was clamped to the device's limits
        clamped: bool,
        /// frames the device dropped (bad CRC, bad length, unknown type), wrapping
        rx_errors: u8,
        /// where the servos are, ticks: the widths being output; with no pulses (idle,
        /// detached) the pose the device starts from: the last command, or its hold
        /// pose before the first one (0 = none known)
        ticks: [u16; SERVOS],
    },
    /// host → device: engage the emergency stop, holding the pulses or stopping them
    /// (`Some`), or release it (`None`).
    Estop {
        /// engaged, and how; `None`: released
        engaged: Option<StopAction>,
    },
    /// host → device: watchdog settings.
    Config {
        /// silence (ms) after which the watchdog acts
        watchdog_ms: u16,
        /// what it does then
        action: WatchdogAction,
    },
    /// host → device (version 3): take this role. Answered by STATE; taking the role
    /// the device has changes nothing.
    Role {
        /// the role
        role: Role,
    },
    /// device → host (version 3), leader role: one sampling window of the
    /// potentiometers and the deadman button, every [`LEADER_PERIOD_US`].
    LeaderState {
        /// A0–A3: each the sum of [`LEADER_OVERSAMPLING`] 10-bit samples, 0 ..=
        /// [`LEADER_ADC_MAX`]; [`LEADER_FULL_SCALE`] stands for AVcc
        adc: [u16; LEADER_CHANNELS],
        /// the deadman button (D2 to GND) was held at every sample of the window
        deadman: bool,
        /// the window's number (wraps; 0 the first after the ROLE): a gap says
        /// windows were lost (on the wire, or not sent)
        window: u8,
        /// samples taken late so far (the conversion before was not done: the sample
        /// waited for it), wrapping; 0 in normal operation
        overruns: u8,
    },
}

impl Message {
    /// The type of this message.
    pub fn msg_type(&self) -> MsgType {
        match self {
            Message::Hello { .. } => MsgType::Hello,
            Message::HelloAck { .. } => MsgType::HelloAck,
            Message::SetPulses { .. } => MsgType::SetPulses,
            Message::Heartbeat => MsgType::Heartbeat,
            Message::State { .. } => MsgType::State,
            Message::Estop { .. } => MsgType::Estop,
            Message::Config { .. } => MsgType::Config,
            Message::Role { .. } => MsgType::Role,
            Message::LeaderState { .. } => MsgType::LeaderState,
        }
    }
}

/// A frame: a message and its sequence number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame {
    /// Sequence number (wraps).
    pub seq: u8,
    /// The message.
    pub msg: Message,
}

/// CRC-8, polynomial 0x07, init 0 (CRC-8/SMBUS), as in the firmware.
///
/// # Examples
/// ```
/// assert_eq!(servo_protocol::crc8(b"123456789"), 0xF4);
/// ```
pub fn crc8(data: &[u8]) -> u8 {
    let mut crc = 0u8;
    for &b in data {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x07
            } else {
                crc << 1
            };
        }
    }
    crc
}

fn put_u16(out: &mut Vec<u8>, v: u16) {
    out.extend_from_slice(&v.to_le_bytes());
}

/// Encode a frame.
///
/// # Examples
/// ```
/// use servo_protocol::{encode, Frame, Message};
/// let bytes = encode(&Frame { seq: 7, msg: Message::SetPulses { ticks: [2944; 4] } });
/// assert_eq!(bytes.len(), 12); // 1.04 ms at 115200 baud
/// assert_eq!(bytes[0], 0xA5);
/// ```
pub fn encode(frame: &Frame) -> Vec<u8> {
    let mut payload = Vec::with_capacity(MAX_PAYLOAD);
    match frame.msg {
        Message::Hello { version } => payload.push(version),
        Message::HelloAck {
            version,
            firmware_major,
            firmware_minor,
            servos,
            watchdog_ms,
        } => {
            payload.extend_from_slice(&[version, firmware_major, firmware_minor, servos]);
            put_u16(&mut payload, watchdog_ms);
        }
        Message::SetPulses { ticks } => ticks.iter().for_each(|t| put_u16(&mut payload, *t)),
        Message::Heartbeat => {}
        Message::State {
            ack_seq,
            state,
            clamped,
            rx_errors,
            ticks,
        } => {
            payload.extend_from_slice(&[ack_seq, state.to_byte(), u8::from(clamped), rx_errors]);
            ticks.iter().for_each(|t| put_u16(&mut payload, *t));
        }
        Message::Estop { engaged } => payload.push(match engaged {
            None => 0,
            Some(StopAction::Hold) => 1,
            Some(StopAction::Detach) => 2,
        }),
        Message::Config {
            watchdog_ms,
            action,
        } => {
            put_u16(&mut payload, watchdog_ms);
            payload.push(match action {
                WatchdogAction::Hold => 0,
                WatchdogAction::Detach => 1,
            });
        }
        Message::Role { role } => payload.push(role.to_byte()),
        Message::LeaderState {
            adc,
            deadman,
            window,
            overruns,
        } => {
            adc.iter().for_each(|v| put_u16(&mut payload, *v));
            payload.extend_from_slice(&[u8::from(deadman), window, overruns]);
        }
    }
    debug_assert_eq!(payload.len(), frame.msg.msg_type().payload_len());
    let mut out = Vec::with_capacity(payload.len() + OVERHEAD);
    out.push(SYNC);
    out.push(((frame.msg.msg_type() as u8) << 4) | payload.len() as u8);
    out.push(frame.seq);
    out.extend_from_slice(&payload);
    out.push(crc8(&out[1..]));
    out
}

/// Why bytes at the front of the buffer are not a frame. The decoder has dropped
/// them (at least one byte), so decoding can go on.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// Bytes before a start marker.
    #[error("{skipped} byte(s) of garbage before a frame start")]
    Garbage {
        /// how many were dropped
        skipped: usize,
    },
    /// The checksum does not match.
    #[error("bad CRC (got {got:#04x}, computed {computed:#04x})")]
    BadCrc {
        /// the frame's CRC byte
        got: u8,
        /// the CRC of the bytes received
        computed: u8,
    },
    /// Unknown message type.
    #[error("unknown message type {0:#x}")]
    UnknownType(u8),
    /// The length does not fit the type.
    #[error("message type {msg_type:?} needs {expected} payload bytes, frame says {got}")]
    BadLength {
        /// the type
        msg_type: MsgType,
        /// what it needs
        expected: usize,
        /// what the frame says
        got: usize,
    },
    /// A field holds a value the protocol does not define.
    #[error("bad field value: {0}")]
    BadValue(&'static str),
}

fn u16_at(p: &[u8], i: usize) -> u16 {
    u16::from_le_bytes([p[i], p[i + 1]])
}

fn ticks_at(p: &[u8], start: usize) -> [u16; SERVOS] {
    [
        u16_at(p, start),
        u16_at(p, start + 2),
        u16_at(p, start + 4),
        u16_at(p, start + 6),
    ]
}

/// Take one frame from the front of `buf`.
///
/// * `Ok(Some(frame))`: a frame was removed from `buf`;
/// * `Ok(None)`: `buf` holds only the beginning of a frame (or nothing): wait for more bytes;
/// * `Err(e)`: bytes were invalid and were dropped; call again.
///
/// A frame that fails its CRC costs only its start byte, so a `0xA5` inside a
/// payload cannot make the decoder lose the next real frame.
///
/// # Examples
/// ```
/// use servo_protocol::{decode, encode, Frame, Message};
/// let f = Frame { seq: 1, msg: Message::Heartbeat };
/// let mut buf = encode(&f);
/// buf.insert(0, 0x42); // garbage
/// assert!(decode(&mut buf).is_err());
/// assert_eq!(decode(&mut buf), Ok(Some(f)));
/// assert_eq!(decode(&mut buf), Ok(None));
/// ```
pub fn decode(buf: &mut Vec<u8>) -> Result<Option<Frame>, DecodeError> {
    match buf.iter().position(|b| *b == SYNC) {
        None => {
            let skipped = buf.len();
            buf.clear();
            return if skipped == 0 {
                Ok(None)
            } else {
                Err(DecodeError::Garbage { skipped })
            };
        }
        Some(0) => {}
        Some(n) => {
            buf.drain(..n);
            return Err(DecodeError::Garbage { skipped: n });
        }
    }
    if buf.len() < 2 {
        return Ok(None);
    }
    let len = usize::from(buf[1] & 0x0F);
    let total = len + OVERHEAD;
    if buf.len() < total {
        return Ok(None);
    }
    let computed = crc8(&buf[1..total - 1]);
    let got = buf[total - 1];
    let reject = |buf: &mut Vec<u8>, e: DecodeError| {
        buf.drain(..1);
        Err(e)
    };
    if computed != got {
        return reject(buf, DecodeError::BadCrc { got, computed });
    }
    let Some(msg_type) = MsgType::from_nibble(buf[1] >> 4) else {
        let t = buf[1] >> 4;
        return reject(buf, DecodeError::UnknownType(t));
    };
    if len != msg_type.payload_len() {
        return reject(
            buf,
            DecodeError::BadLength {
                msg_type,
                expected: msg_type.payload_len(),
                got: len,
            },
        );
    }
    let seq = buf[2];
    let p = &buf[3..3 + len];
    let msg = match msg_type {
        MsgType::Hello => Message::Hello { version: p[0] },
        MsgType::HelloAck => Message::HelloAck {
            version: p[0],
            firmware_major: p[1],
            firmware_minor: p[2],
            servos: p[3],
            watchdog_ms: u16_at(p, 4),
        },
        MsgType::SetPulses => Message::SetPulses {
            ticks: ticks_at(p, 0),
        },
        MsgType::Heartbeat => Message::Heartbeat,
        MsgType::State => {
            let Some(state) = DeviceState::from_byte(p[1]) else {
                return reject(buf, DecodeError::BadValue("device state"));
            };
            if p[2] > 1 {
                return reject(buf, DecodeError::BadValue("clamped flag"));
            }
            Message::State {
                ack_seq: p[0],
                state,
                clamped: p[2] == 1,
                rx_errors: p[3],
                ticks: ticks_at(p, 4),
            }
        }
        MsgType::Estop => match p[0] {
            0 => Message::Estop { engaged: None },
            1 => Message::Estop {
                engaged: Some(StopAction::Hold),
            },
            2 => Message::Estop {
                engaged: Some(StopAction::Detach),
            },
            _ => return reject(buf, DecodeError::BadValue("estop flag")),
        },
        MsgType::Config => {
            let action = match p[2] {
                0 => WatchdogAction::Hold,
                1 => WatchdogAction::Detach,
                _ => return reject(buf, DecodeError::BadValue("watchdog action")),
            };
            Message::Config {
                watchdog_ms: u16_at(p, 0),
                action,
            }
        }
        MsgType::Role => match Role::from_byte(p[0]) {
            Some(role) => Message::Role { role },
            None => return reject(buf, DecodeError::BadValue("role")),
        },
        MsgType::LeaderState => {
            if p[8] > 1 {
                return reject(buf, DecodeError::BadValue("buttons"));
            }
            Message::LeaderState {
                adc: ticks_at(p, 0),
                deadman: p[8] == 1,
                window: p[9],
                overruns: p[10],
            }
        }
    };
    buf.drain(..total);
    Ok(Some(Frame { seq, msg }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(bytes: &[u8]) -> Result<Option<Frame>, DecodeError> {
        decode(&mut bytes.to_vec())
    }

    #[test]
    fn role_frames_byte_for_byte() {
        let leader = encode(&Frame {
            seq: 3,
            msg: Message::Role { role: Role::Leader },
        });
        let body = [0x81, 0x03, 0x01];
        assert_eq!(leader[..4], [0xA5, 0x81, 0x03, 0x01]);
        assert_eq!(leader[4], crc8(&body));
        assert_eq!(leader.len(), 5);
        assert_eq!(
            one(&leader),
            Ok(Some(Frame {
                seq: 3,
                msg: Message::Role { role: Role::Leader }
            }))
        );
        let follower = encode(&Frame {
            seq: 4,
            msg: Message::Role {
                role: Role::Follower,
            },
        });
        assert_eq!(follower[3], 0);
        // a role the protocol does not define
        let mut bad = vec![0xA5, 0x81, 0x05, 0x02];
        bad.push(crc8(&bad[1..]));
        assert_eq!(one(&bad), Err(DecodeError::BadValue("role")));
    }

    #[test]
    fn leader_state_frames_byte_for_byte() {
        let msg = Message::LeaderState {
            adc: [0, 8192, LEADER_ADC_MAX, 0x1234],
            deadman: true,
            window: 200,
            overruns: 1,
        };
        let bytes = encode(&Frame { seq: 9, msg });
        // 15 bytes: 1.30 ms at 115200 baud, 13.5 % of the wire at 104.2 Hz
        assert_eq!(bytes.len(), 15);
        assert_eq!(
            bytes[..14],
            [0xA5, 0x9B, 0x09, 0x00, 0x00, 0x00, 0x20, 0xF0, 0x3F, 0x34, 0x12, 0x01, 200, 0x01]
        );
        assert_eq!(one(&bytes), Ok(Some(Frame { seq: 9, msg })));
        // the buttons byte: bit 0 only
        let mut bad = bytes[..14].to_vec();
        bad[11] = 0x02;
        bad.push(crc8(&bad[1..]));
        assert_eq!(one(&bad), Err(DecodeError::BadValue("buttons")));
        // a LEADER_STATE with another length is not one
        let mut short = vec![0xA5, 0x9A, 0x01];
        short.extend_from_slice(&[0; 10]);
        short.push(crc8(&short[1..]));
        assert!(matches!(
            one(&short),
            Err(DecodeError::BadLength {
                msg_type: MsgType::LeaderState,
                expected: 11,
                got: 10
            })
        ));
    }

    #[test]
    fn the_leader_scale() {
        assert_eq!(LEADER_FULL_SCALE, 16384);
        assert_eq!(LEADER_ADC_MAX, 16368);
        assert_eq!(
            LEADER_PERIOD_US,
            64 * 150,
            "16 samples × 4 channels, 150 µs apart"
        );
        assert_eq!(DeviceState::Leader.to_byte(), 5);
        assert_eq!(DeviceState::from_byte(5), Some(DeviceState::Leader));
        assert_eq!(DeviceState::from_byte(6), None);
    }
}
