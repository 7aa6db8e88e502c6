//! The serial link's I/O, a thin shell around [`HostLink`] (the pure state machine of
//! `servo_protocol::host`, which decides what to send and when): a link thread opens
//! the port, writes what the machine says and sleeps until it says; a reader thread per
//! open port feeds it the device's frames. Events go to the node through a channel.
//!
//! The port is behind [`PortOpener`], so the same code drives a real serial port, a
//! pseudo-terminal and the in-process virtual Arduino.

use command_gate::{GateCounters, Stamp};
use eezybot_msgs::Time;
use servo_protocol::device::{DeviceConfig, VirtualArduino};
use servo_protocol::host::{HostConfig, HostLink, Next, Offered};
use servo_protocol::{encode, FrameReader, LeaderState, SERVOS};
use std::io::{self, Read, Write};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use tokio::sync::mpsc::UnboundedSender;

pub use servo_protocol::host::SendStats;

/// What the node shows of the link in its diagnostics, as of one moment.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LinkSnapshot {
    /// the sending side's counters
    pub sent: SendStats,
    /// what the late-hold gate did
    pub gate: GateCounters,
    /// whether the e-stop is engaged (the link is its only keeper)
    pub estop: bool,
}

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
    /// a leader's samples (the leader role), each as it came
    leader: Option<UnboundedSender<LeaderState>>,
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
        let samples = self.machine.take_leader_states();
        if let Some(leader) = &self.leader {
            for s in samples {
                let _ = leader.send(s);
            }
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
    /// Start the link thread; events go to `events`, a leader's samples (the leader
    /// role, `config.role`) to `leader`.
    pub fn start(
        opener: PortOpener,
        config: HostConfig,
        events: UnboundedSender<LinkEvent>,
        leader: Option<UnboundedSender<LeaderState>>,
    ) -> io::Result<Link> {
        let shared = Arc::new((
            Mutex::new(Shared {
                machine: HostLink::new(config, Instant::now()),
                events,
                leader,
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
        self.snapshot().sent
    }

    /// The counters and the e-stop, for diagnostics.
    pub fn snapshot(&self) -> LinkSnapshot {
        lock(&self.shared)
            .map(|s| LinkSnapshot {
                sent: s.machine.stats().clone(),
                gate: *s.machine.gate(),
                estop: s.machine.estop(),
            })
            .unwrap_or_default()
    }

    /// Whether the e-stop is engaged.
    pub fn estop(&self) -> bool {
        self.snapshot().estop
    }

    /// Hand in a stamped command received at `received` (`now`: the wall clock), through
    /// the late-hold gate ([`HostLink::offer`]): it goes at once, or, arriving late, is
    /// held back for a newer one. During an e-stop it is dropped. `None`: the link
    /// thread died.
    pub fn offer(
        &self,
        ticks: [u16; SERVOS],
        stamp: Time,
        received: Instant,
        now: Time,
    ) -> Option<Offered> {
        let secs = |t: Time| t.to_nanos() as f64 * 1e-9;
        let stamp_s = Stamp {
            stamp_s: secs(stamp),
            received_s: secs(now),
        };
        let offered = lock(&self.shared).map(|mut s| {
            let o = s.machine.offer(ticks, stamp, stamp_s, received);
            s.forward();
            o
        });
        self.shared.1.notify_all();
        offered
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

    /// Engage or release the device's emergency stop; returns whether that changed it.
    pub fn set_estop(&self, engaged: bool) -> bool {
        let changed = lock(&self.shared).is_some_and(|mut s| s.machine.set_estop(engaged));
        self.shared.1.notify_all();
        changed
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
                match written {
                    // the wire's trace (`--log-level debug`): what went out, and when the
                    // link decided it (CLOCK_REALTIME), the clock the velocity guard
                    // ramped on
                    Ok(()) if log::log_enabled!(log::Level::Debug) => {
                        let lag = now.elapsed();
                        let decided = SystemTime::now()
                            .checked_sub(lag)
                            .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
                            .unwrap_or_default();
                        log::debug!(
                            "wrote seq {} {:?}, decided at {}.{:09} ({} us before)",
                            frame.seq,
                            frame.msg,
                            decided.as_secs(),
                            decided.subsec_nanos(),
                            lag.as_micros()
                        )
                    }
                    Ok(()) => {}
                    Err(e) => {
                        if let Some(mut s) = lock(&shared) {
                            s.machine.lost(format!("write: {e}"), Instant::now());
                            s.forward();
                        }
                    }
                }
            }
        }
    }
}

/// Reads the device's frames into the machine until the port breaks or a newer
/// session starts.
///
/// A UART's bytes can reach the port one at a time, 87 us apart at 115200 baud (a
/// 16-byte STATE woke this thread 10-16 times): with part of a frame in hand, the
/// reader waits the rest's time on the wire before reading again ([`FrameReader::rest_wait`]:
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
                if let Some(wait) = byte_time.and_then(|t| reader.rest_wait(t)) {
                    std::thread::sleep(wait);
                }
            }
        })
}
