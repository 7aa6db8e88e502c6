//! The serial link's I/O, a thin shell around [`HostLink`] (the pure state machine of
//! `servo_protocol::host`, which decides what to send and when): a link thread opens
//! the port, writes what the machine says and sleeps until it says; a reader thread per
//! open port feeds it the device's frames. Events go to the node through a channel.
//!
//! The port is behind [`PortOpener`], so the same code drives a real serial port, a
//! pseudo-terminal and the in-process virtual Arduino.

use eezybot_msgs::Time;
use servo_protocol::device::{DeviceConfig, VirtualArduino};
use servo_protocol::host::{HostConfig, HostLink, Next};
use servo_protocol::{encode, FrameReader, SERVOS};
use std::io::{self, Read, Write};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::sync::mpsc::UnboundedSender;

pub use servo_protocol::host::SendStats;

/// What the link reports: the machine's events, tagged with the commands' stamps.
pub type LinkEvent = servo_protocol::host::LinkEvent<Time>;

/// A byte stream to the device that can be split for a reader thread.
pub trait Port: Read + Write + Send {
    /// A second handle on the same port.
    fn try_clone_port(&self) -> io::Result<Box<dyn Port>>;

    /// How long one byte takes on the wire, for a port whose bytes may arrive as they
    /// come off it; `None` for one that delivers whole frames.
    fn byte_time(&self) -> Option<Duration> {
        None
    }
}

impl Port for Box<dyn serialport::SerialPort> {
    fn try_clone_port(&self) -> io::Result<Box<dyn Port>> {
        Ok(Box::new(self.try_clone().map_err(io::Error::other)?))
    }

    fn byte_time(&self) -> Option<Duration> {
        // 8N1: ten bits a byte
        let baud = self.baud_rate().ok().filter(|b| *b > 0)?;
        Some(Duration::from_secs_f64(10.0 / f64::from(baud)))
    }
}

impl Port for VirtualArduino {
    fn try_clone_port(&self) -> io::Result<Box<dyn Port>> {
        Ok(Box::new(self.clone()))
    }
}

/// Opens the port; called again after every disconnection.
pub type PortOpener = Box<dyn FnMut() -> io::Result<Box<dyn Port>> + Send>;

/// A real serial port (or a pseudo-terminal) at `baud`.
pub fn serial_opener(path: String, baud: u32) -> PortOpener {
    Box::new(move || {
        let port = serialport::new(&path, baud)
            .timeout(Duration::from_millis(50))
            .open()
            .map_err(|e| io::Error::other(format!("{path}: {e}")))?;
        Ok(Box::new(port) as Box<dyn Port>)
    })
}

/// The in-process virtual Arduino (`port:=mock`): one device for the node's life, so
/// a reconnection finds it as it was; it cannot be opened while unplugged.
pub fn mock_opener(device: VirtualArduino) -> PortOpener {
    Box::new(move || {
        if device.is_plugged() {
            Ok(Box::new(device.clone()) as Box<dyn Port>)
        } else {
            Err(io::Error::new(
                io::ErrorKind::NotFound,
                "virtual Arduino unplugged",
            ))
        }
    })
}

/// The in-process virtual Arduino with the firmware's default configuration.
pub fn virtual_arduino() -> VirtualArduino {
    VirtualArduino::new(DeviceConfig::default())
}

struct Shared {
    machine: HostLink<Time>,
    events: UnboundedSender<LinkEvent>,
    /// counts the ports opened: a reader of an older port stops
    session: u64,
    shutdown: bool,
}

impl Shared {
    /// Hand the machine's events to the node.
    fn forward(&mut self) {
        for e in self.machine.take_events() {
            let _ = self.events.send(e);
        }
    }
}

type SharedLock = Arc<(Mutex<Shared>, Condvar)>;

fn lock(shared: &SharedLock) -> Option<MutexGuard<'_, Shared>> {
    shared.0.lock().ok()
}

/// The running link. Dropping it does not stop it: call [`Link::shutdown`].
pub struct Link {
    shared: SharedLock,
    thread: Option<JoinHandle<()>>,
}

impl Link {
    /// Start the link thread; events go to `events`.
    pub fn start(
        opener: PortOpener,
        config: HostConfig,
        events: UnboundedSender<LinkEvent>,
    ) -> io::Result<Link> {
        let shared = Arc::new((
            Mutex::new(Shared {
                machine: HostLink::new(config, Instant::now()),
                events,
                session: 0,
                shutdown: false,
            }),
            Condvar::new(),
        ));
        let s = shared.clone();
        let thread = std::thread::Builder::new()
            .name("serial link".into())
            .spawn(move || link_loop(opener, s))?;
        Ok(Link {
            shared,
            thread: Some(thread),
        })
    }

    /// A copy of the sending side's counters.
    pub fn send_stats(&self) -> SendStats {
        lock(&self.shared)
            .map(|s| s.machine.stats().clone())
            .unwrap_or_default()
    }

    /// Hand in the newest command (`received`: when its message arrived). It replaces
    /// one not yet sent; during an e-stop it is dropped.
    pub fn command(&self, ticks: [u16; SERVOS], stamp: Time, received: Instant) {
        if let Some(mut s) = lock(&self.shared) {
            s.machine.command(ticks, stamp, received);
            s.forward();
        }
        self.shared.1.notify_all();
    }

    /// Change the servos' velocity limits (pulse ticks per second).
    pub fn set_velocity_limits(&self, max_ticks_per_s: [f64; SERVOS]) {
        if let Some(mut s) = lock(&self.shared) {
            s.machine.set_velocity_limits(max_ticks_per_s);
        }
    }

    /// Engage or release the device's emergency stop.
    pub fn set_estop(&self, engaged: bool) {
        if let Some(mut s) = lock(&self.shared) {
            s.machine.set_estop(engaged);
        }
        self.shared.1.notify_all();
    }

    /// Stop the threads (waits for them).
    pub fn shutdown(mut self) {
        if let Some(mut s) = lock(&self.shared) {
            s.shutdown = true;
        }
        self.shared.1.notify_all();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The link thread: do what the machine says.
fn link_loop(mut opener: PortOpener, shared: SharedLock) {
    let mut port: Option<(Box<dyn Port>, JoinHandle<()>)> = None;
    let close = |port: &mut Option<(Box<dyn Port>, JoinHandle<()>)>| {
        if let Some((p, reader)) = port.take() {
            drop(p);
            let _ = reader.join(); // it stops at its next read timeout (≤ 50 ms)
        }
    };
    loop {
        let Some(mut s) = lock(&shared) else { return };
        if s.shutdown {
            s.session += 1; // tell the reader
            drop(s);
            close(&mut port);
            return;
        }
        let now = Instant::now();
        let next = s.machine.next(now);
        s.forward();
        if !s.machine.is_open() && port.is_some() {
            // lost (reported by the reader, or a failed write): let go of the port
            s.session += 1;
            drop(s);
            close(&mut port);
            continue;
        }
        match next {
            Next::Wait(until) => {
                let _ = shared
                    .1
                    .wait_timeout(s, until.saturating_duration_since(now));
            }
            Next::Close { .. } => {
                s.session += 1;
                drop(s);
                close(&mut port);
            }
            Next::Open => {
                drop(s);
                close(&mut port);
                let opened = opener().and_then(|p| Ok((p.try_clone_port()?, p)));
                let Some(mut s) = lock(&shared) else { return };
                match opened {
                    Ok((reader_port, writer_port)) => {
                        s.session += 1;
                        let session = s.session;
                        match spawn_reader(reader_port, shared.clone(), session) {
                            Ok(reader) => {
                                s.machine.opened(Instant::now());
                                port = Some((writer_port, reader));
                            }
                            Err(e) => s.machine.open_failed(
                                format!("cannot start the reader: {e}"),
                                Instant::now(),
                            ),
                        }
                    }
                    Err(e) => s.machine.open_failed(e.to_string(), Instant::now()),
                }
                s.forward();
            }
            Next::Send(frame) => {
                drop(s);
                let bytes = encode(&frame);
                // No flush: on a serial port it is tcdrain(), which blocks until the
                // bytes have left the UART (1 ms a frame) and gains nothing.
                let written = match &mut port {
                    Some((p, _)) => p.write_all(&bytes),
                    None => Err(io::Error::new(io::ErrorKind::NotConnected, "no port")),
                };
                if let Err(e) = written {
                    if let Some(mut s) = lock(&shared) {
                        s.machine.lost(format!("write: {e}"), Instant::now());
                        s.forward();
                    }
                }
            }
        }
    }
}

/// The longest a reader waits for the rest of a partial frame before reading again
/// (the protocol drops a partial frame after 5 ms without a byte).
const MAX_FRAME_WAIT: Duration = Duration::from_millis(2);

/// A STATE frame's length: every frame the device sends is one, but for the
/// HELLO_ACK that answers the handshake.
const STATE_FRAME_LEN: usize = servo_protocol::OVERHEAD + 12;

/// How long to wait before reading again when `reader` holds part of a frame: the
/// rest's time on the wire, and one byte's more for its way here, so that one read
/// takes it whole. With only the start byte in, the length is not known yet: a
/// STATE's rest is waited for (a shorter HELLO_ACK is read a little later).
fn rest_of_frame<R: Read>(reader: &FrameReader<R>, byte_time: Duration) -> Option<Duration> {
    let missing = match reader.missing() {
        0 => return None,
        _ if reader.buffered() == 1 => STATE_FRAME_LEN - 1,
        n => n,
    };
    let bytes = u32::try_from(missing + 1).unwrap_or(u32::MAX);
    Some(byte_time.saturating_mul(bytes).min(MAX_FRAME_WAIT))
}

/// Reads the device's frames into the machine until the port breaks or a newer
/// session starts.
///
/// A UART's bytes can reach the port one at a time, 87 us apart at 115200 baud (a
/// 16-byte STATE woke this thread 10-16 times): with part of a frame in hand, the
/// reader waits the rest's time on the wire before reading again ([`rest_of_frame`]:
/// two wake-ups a STATE, for its first bytes and for the rest).
/// The link thread is woken only when a frame changes what it is waiting for.
fn spawn_reader(
    port: Box<dyn Port>,
    shared: SharedLock,
    session: u64,
) -> io::Result<JoinHandle<()>> {
    let byte_time = port.byte_time();
    std::thread::Builder::new()
        .name("serial reader".into())
        .spawn(move || {
            let mut reader = FrameReader::new(port);
            loop {
                let result = reader.read_frames();
                let Some(mut s) = lock(&shared) else { return };
                if s.shutdown || s.session != session {
                    return;
                }
                let now = Instant::now();
                let mut replan = false;
                match result {
                    Ok(frames) => {
                        let any = !frames.is_empty();
                        for item in frames {
                            match item {
                                Ok(frame) => replan |= s.machine.received(frame, now),
                                Err(e) => s.machine.garbage(e.to_string()),
                            }
                        }
                        if any {
                            s.forward();
                        }
                    }
                    Err(e) => {
                        s.machine.lost(format!("read: {e}"), now);
                        s.forward();
                        drop(s);
                        shared.1.notify_all();
                        return;
                    }
                }
                drop(s);
                if replan {
                    shared.1.notify_all();
                }
                if let Some(wait) = byte_time.and_then(|t| rest_of_frame(&reader, t)) {
                    std::thread::sleep(wait);
                }
            }
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use servo_protocol::{DeviceState, Frame, Message, MsgType};

    /// Hands out its chunks, one a read.
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
    fn the_reader_waits_for_the_rest_of_a_frame_a_state_when_only_its_start_is_in() {
        assert_eq!(
            STATE_FRAME_LEN,
            servo_protocol::OVERHEAD + MsgType::State.payload_len()
        );
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
        assert_eq!(rest_of_frame(&r, byte), None, "nothing held");
        r.read_frames().unwrap();
        // the start byte: a STATE's 15 more, and a byte's time for the way here
        assert_eq!(rest_of_frame(&r, byte), Some(byte * 16));
        r.read_frames().unwrap();
        assert_eq!(
            rest_of_frame(&r, byte),
            Some(byte * 13),
            "the length is known"
        );
        assert_eq!(r.read_frames().unwrap().len(), 1);
        assert_eq!(rest_of_frame(&r, byte), None);
        // never longer than the protocol keeps a partial frame
        let mut slow = FrameReader::new(Chunks(vec![state[..1].to_vec()]));
        slow.read_frames().unwrap();
        let at_1200_baud = Duration::from_secs_f64(10.0 / 1200.0);
        assert_eq!(rest_of_frame(&slow, at_1200_baud), Some(MAX_FRAME_WAIT));
    }
}
