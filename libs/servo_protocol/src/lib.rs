#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod device;
mod frame;
pub mod host;
pub mod leader;

pub use frame::{
    crc8, decode, encode, DecodeError, DeviceState, Frame, Message, MsgType, Role, StopAction,
    WatchdogAction, LEADER_ADC_MAX, LEADER_CHANNELS, LEADER_FULL_SCALE, LEADER_OVERSAMPLING,
    LEADER_PERIOD_US, MAX_PAYLOAD, OVERHEAD, PROTOCOL_VERSION, SERVOS, SYNC, TICKS_PER_US,
};
pub use leader::{LeaderInput, LeaderState};

use std::io::{self, Read};
use std::time::Duration;

/// The longest [`FrameReader::rest_wait`] waits for the rest of a partial frame (the
/// protocol drops a partial frame after 5 ms without a byte).
pub const MAX_FRAME_WAIT: Duration = Duration::from_millis(2);

/// A STATE frame's length.
const STATE_FRAME_LEN: usize = OVERHEAD + 12;

/// Reads frames from a byte stream, keeping partial frames between reads.
pub struct FrameReader<R: Read> {
    port: R,
    buf: Vec<u8>,
    chunk: Box<[u8]>,
}

impl<R: Read> FrameReader<R> {
    /// Wrap a byte stream.
    pub fn new(port: R) -> Self {
        FrameReader {
            port,
            buf: Vec::with_capacity(256),
            chunk: vec![0; 256].into_boxed_slice(),
        }
    }

    /// Read what is available (one `read` call; it may block up to the stream's
    /// timeout) and decode every complete frame. Invalid bytes come back as `Err`
    /// items, already dropped. A timeout yields an empty list.
    pub fn read_frames(&mut self) -> io::Result<Vec<Result<Frame, DecodeError>>> {
        match self.port.read(&mut self.chunk) {
            Ok(0) => return Err(io::Error::new(io::ErrorKind::UnexpectedEof, "port closed")),
            Ok(n) => self.buf.extend_from_slice(&self.chunk[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut
                        | io::ErrorKind::WouldBlock
                        | io::ErrorKind::Interrupted
                ) =>
            {
                return Ok(vec![])
            }
            Err(e) => return Err(e),
        }
        let mut out = vec![];
        loop {
            match decode(&mut self.buf) {
                Ok(None) => break,
                Ok(Some(f)) => out.push(Ok(f)),
                Err(e) => out.push(Err(e)),
            }
        }
        Ok(out)
    }

    /// Bytes held since the last read: a partial frame, or the start of one.
    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// How long to wait before reading again when part of a frame is held, for a
    /// port whose bytes arrive as they come off the wire, `byte_time` apart: the rest's
    /// time on the wire, and one byte's more for its way here, so that one read takes
    /// it whole; never longer than [`MAX_FRAME_WAIT`]. With only the start byte in, the
    /// length is not known yet: a STATE's rest is waited for (every frame a device sends
    /// is one, but for the HELLO_ACK that answers the handshake, which is read a
    /// little later, and a leader's LEADER_STATE, a byte shorter, read a byte time
    /// later than it could be). `None` when no partial frame is held.
    pub fn rest_wait(&self, byte_time: Duration) -> Option<Duration> {
        let missing = match self.missing() {
            0 => return None,
            _ if self.buffered() == 1 => STATE_FRAME_LEN - 1,
            n => n,
        };
        let bytes = u32::try_from(missing + 1).unwrap_or(u32::MAX);
        Some(byte_time.saturating_mul(bytes).min(MAX_FRAME_WAIT))
    }

    /// Bytes still to come before the partial frame held since the last read is whole
    /// (0 when none is held). A reader of a port that delivers bytes one at a time as
    /// they come off the wire (a UART behind a pseudo-terminal, some USB adapters) can
    /// wait for that many byte times instead of waking for each byte.
    pub fn missing(&self) -> usize {
        match self.buf.as_slice() {
            [] => 0,
            [_] => OVERHEAD - 1,
            [_, type_len, ..] => {
                (usize::from(type_len & 0x0F) + OVERHEAD).saturating_sub(self.buf.len())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stream that hands out its bytes in the given chunks, one per read.
    struct Chunks(Vec<Vec<u8>>);

    impl Read for Chunks {
        fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
            if self.0.is_empty() {
                return Err(io::ErrorKind::TimedOut.into());
            }
            let c = self.0.remove(0);
            out[..c.len()].copy_from_slice(&c);
            Ok(c.len())
        }
    }

    #[test]
    fn missing_counts_the_bytes_a_partial_frame_still_needs() {
        let state = encode(&Frame {
            seq: 7,
            msg: Message::State {
                ack_seq: 6,
                state: DeviceState::Running,
                clamped: false,
                rx_errors: 0,
                ticks: [3000; SERVOS],
            },
        });
        assert_eq!(state.len(), 16);
        // garbage, then the frame a byte at a time, then two bytes of the next one
        let mut chunks = vec![vec![0x00, 0x11]];
        chunks.extend(state.iter().map(|b| vec![*b]));
        chunks.push(state[..2].to_vec());
        let mut r = FrameReader::new(Chunks(chunks));
        assert!(r.read_frames().unwrap().iter().all(Result::is_err));
        assert_eq!(r.missing(), 0, "garbage is dropped, not waited for");
        assert!(r.read_frames().unwrap().is_empty());
        assert_eq!(
            r.missing(),
            OVERHEAD - 1,
            "the start byte alone: at least an empty frame"
        );
        assert_eq!(r.buffered(), 1);
        for held in 2..state.len() {
            assert!(r.read_frames().unwrap().is_empty());
            assert_eq!(r.missing(), state.len() - held);
            assert_eq!(r.buffered(), held);
        }
        let frames = r.read_frames().unwrap();
        assert_eq!(frames.len(), 1);
        assert!(frames[0].is_ok());
        assert_eq!(r.missing(), 0);
        assert!(r.read_frames().unwrap().is_empty());
        assert_eq!(r.missing(), 14);
        assert!(r.read_frames().unwrap().is_empty(), "a timeout");
        assert_eq!(r.missing(), 14);
    }

    #[test]
    fn the_reader_waits_for_the_rest_of_a_frame_a_state_when_only_its_start_is_in() {
        assert_eq!(STATE_FRAME_LEN, OVERHEAD + MsgType::State.payload_len());
        let state = encode(&Frame {
            seq: 1,
            msg: Message::State {
                ack_seq: 1,
                state: DeviceState::Running,
                clamped: false,
                rx_errors: 0,
                ticks: [3000; SERVOS],
            },
        });
        let byte = Duration::from_micros(87);
        let mut r = FrameReader::new(Chunks(vec![
            state[..1].to_vec(),
            state[1..4].to_vec(),
            state[4..].to_vec(),
        ]));
        assert_eq!(r.rest_wait(byte), None, "nothing held");
        r.read_frames().unwrap();
        // the start byte: a STATE's 15 more, and a byte's time for the way here
        assert_eq!(r.rest_wait(byte), Some(byte * 16));
        r.read_frames().unwrap();
        assert_eq!(r.rest_wait(byte), Some(byte * 13), "the length is known");
        assert_eq!(r.read_frames().unwrap().len(), 1);
        assert_eq!(r.rest_wait(byte), None);
        // never longer than the protocol keeps a partial frame
        let mut slow = FrameReader::new(Chunks(vec![state[..1].to_vec()]));
        slow.read_frames().unwrap();
        let at_1200_baud = Duration::from_secs_f64(10.0 / 1200.0);
        assert_eq!(slow.rest_wait(at_1200_baud), Some(MAX_FRAME_WAIT));
    }
}
