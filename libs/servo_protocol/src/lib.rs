#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod device;
mod frame;
pub mod host;

pub use frame::{
    crc8, decode, encode, DecodeError, DeviceState, Frame, Message, MsgType, StopAction,
    WatchdogAction, MAX_PAYLOAD, OVERHEAD, PROTOCOL_VERSION, SERVOS, SYNC, TICKS_PER_US,
};

use std::io::{self, Read};

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
}
