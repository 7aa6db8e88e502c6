//! The serial link to the device, on its own threads: connect (with back-off),
//! handshake, send the newest command at most once per send period (latest wins,
//! nothing queues), heartbeats, e-stop, and the device's replies back as events.
//!
//! The port is behind [`PortOpener`], so the same code drives a real serial port, a
//! pseudo-terminal and the in-process virtual Arduino.

use eezybot_msgs::Time;
use servo_protocol::device::{DeviceConfig, VirtualArduino};
use servo_protocol::{
    encode, DecodeError, DeviceState, Frame, FrameReader, Message, WatchdogAction,
    PROTOCOL_VERSION, SERVOS,
};
use std::io::{self, Read, Write};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::sync::mpsc::UnboundedSender;

/// A byte stream to the device that can be split for a reader thread.
pub trait Port: Read + Write + Send {
    /// A second handle on the same port.
    fn try_clone_port(&self) -> io::Result<Box<dyn Port>>;
}

impl Port for Box<dyn serialport::SerialPort> {
    fn try_clone_port(&self) -> io::Result<Box<dyn Port>> {
        Ok(Box::new(self.try_clone().map_err(io::Error::other)?))
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

/// The in-process virtual Arduino (`port:=mock`): one device for the node's life,
/// so a reconnection finds it as it was.
pub fn mock_opener(device: VirtualArduino) -> PortOpener {
    Box::new(move || Ok(Box::new(device.clone()) as Box<dyn Port>))
}

/// Link settings.
#[derive(Clone, Copy, Debug)]
pub struct LinkConfig {
    /// Least time between two SET_PULSES frames (the servo refresh period, 20 ms).
    pub send_period: Duration,
    /// Send a HEARTBEAT when nothing was sent for this long.
    pub heartbeat_period: Duration,
    /// Device watchdog timeout sent in CONFIG.
    pub watchdog_ms: u16,
    /// Device watchdog action sent in CONFIG.
    pub watchdog_action: WatchdogAction,
}

/// What the link reports to the node.
#[derive(Clone, Debug, PartialEq)]
pub enum LinkEvent {
    /// The port is open and the device answered the handshake.
    Connected {
        /// firmware version
        firmware: (u8, u8),
    },
    /// The port could not be opened, or was lost.
    Disconnected {
        /// why
        reason: String,
        /// seconds until the next attempt
        retry_in: Duration,
    },
    /// The device speaks another protocol version.
    VersionMismatch {
        /// the device's version
        device: u8,
    },
    /// A STATE reply.
    State {
        /// the frame it answers
        ack_seq: u8,
        /// device state
        state: DeviceState,
        /// the last command was clamped by the device
        clamped: bool,
        /// the device's count of dropped frames
        rx_errors: u8,
        /// pulse widths being output
        ticks: [u16; SERVOS],
        /// if it answers a SET_PULSES of ours: that command's stamp and the round trip
        answered: Option<(Time, Duration)>,
    },
    /// Bytes from the device that were not a valid frame.
    Garbage {
        /// why
        error: String,
    },
}

/// Counters of the sending side, read by the node for diagnostics (kept here rather
/// than sent as events: one thread wake-up less per command).
#[derive(Clone, Debug, Default)]
pub struct SendStats {
    /// SET_PULSES frames written.
    pub sent: u64,
    /// The last (up to) 1000 delays from a command's arrival to its first byte written, µs.
    pub latency_us: std::collections::VecDeque<f64>,
}

#[derive(Default)]
struct Shared {
    /// Newest command: ticks, its stamp, when it was handed in; `generation` counts them.
    latest: Option<([u16; SERVOS], Time, Instant)>,
    generation: u64,
    estop: bool,
    estop_generation: u64,
    shutdown: bool,
}

/// Sequence numbers of recent SET_PULSES with their stamps and send times.
#[derive(Default)]
struct InFlight {
    slots: Vec<(u8, Time, Instant)>,
}

impl InFlight {
    fn record(&mut self, seq: u8, stamp: Time, at: Instant) {
        if self.slots.len() >= 32 {
            self.slots.remove(0);
        }
        self.slots.push((seq, stamp, at));
    }
    fn take(&mut self, seq: u8) -> Option<(Time, Instant)> {
        let i = self.slots.iter().position(|(s, _, _)| *s == seq)?;
        let (_, stamp, at) = self.slots.remove(i);
        Some((stamp, at))
    }
}

/// The running link. Dropping it does not stop it: call [`Link::shutdown`].
pub struct Link {
    shared: Arc<(Mutex<Shared>, Condvar)>,
    stats: Arc<Mutex<SendStats>>,
    thread: Option<JoinHandle<()>>,
}

impl Link {
    /// Start the link threads; events go to `events`.
    pub fn start(
        opener: PortOpener,
        config: LinkConfig,
        events: UnboundedSender<LinkEvent>,
    ) -> io::Result<Link> {
        let shared = Arc::new((Mutex::new(Shared::default()), Condvar::new()));
        let stats = Arc::new(Mutex::new(SendStats::default()));
        let (s, st) = (shared.clone(), stats.clone());
        let thread = std::thread::Builder::new()
            .name("serial link".into())
            .spawn(move || writer_loop(opener, config, s, st, events))?;
        Ok(Link {
            shared,
            stats,
            thread: Some(thread),
        })
    }

    /// A copy of the sending side's counters.
    pub fn send_stats(&self) -> SendStats {
        self.stats.lock().map(|s| s.clone()).unwrap_or_default()
    }

    /// Hand in the newest command (`received`: when its message arrived); an older one
    /// not yet sent is dropped.
    pub fn command(&self, ticks: [u16; SERVOS], stamp: Time, received: Instant) {
        let (lock, cv) = &*self.shared;
        if let Ok(mut s) = lock.lock() {
            s.latest = Some((ticks, stamp, received));
            s.generation += 1;
        }
        cv.notify_all();
    }

    /// Engage or release the device's emergency stop. Commands handed in while it is
    /// engaged are dropped: after a release the arm moves only on a new command.
    pub fn set_estop(&self, engaged: bool) {
        let (lock, cv) = &*self.shared;
        if let Ok(mut s) = lock.lock() {
            if s.estop != engaged {
                s.estop = engaged;
                s.estop_generation += 1;
            }
        }
        cv.notify_all();
    }

    /// Stop the threads (waits for them).
    pub fn shutdown(mut self) {
        let (lock, cv) = &*self.shared;
        if let Ok(mut s) = lock.lock() {
            s.shutdown = true;
        }
        cv.notify_all();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn is_shutdown(shared: &(Mutex<Shared>, Condvar)) -> bool {
    shared.0.lock().map(|s| s.shutdown).unwrap_or(true)
}

/// Sleep up to `d`, waking early on shutdown.
fn nap(shared: &(Mutex<Shared>, Condvar), d: Duration) {
    let (lock, cv) = shared;
    if let Ok(s) = lock.lock() {
        let _ = cv.wait_timeout_while(s, d, |s| !s.shutdown);
    }
}

/// Connection state shared by the writer and its reader thread.
#[derive(Default)]
struct Session {
    hello_ack: Option<(u8, u8, u8)>,
    broken: Option<String>,
}

fn writer_loop(
    mut opener: PortOpener,
    config: LinkConfig,
    shared: Arc<(Mutex<Shared>, Condvar)>,
    stats: Arc<Mutex<SendStats>>,
    events: UnboundedSender<LinkEvent>,
) {
    let mut backoff = Duration::from_millis(250);
    let mut w = Writer {
        config,
        shared: shared.clone(),
        stats,
        events: events.clone(),
        in_flight: Arc::new(Mutex::new(InFlight::default())),
        seq: 0,
    };
    while !is_shutdown(&shared) {
        let port = match opener() {
            Ok(p) => p,
            Err(e) => {
                let _ = events.send(LinkEvent::Disconnected {
                    reason: e.to_string(),
                    retry_in: backoff,
                });
                nap(&shared, backoff);
                backoff = (backoff * 2).min(Duration::from_secs(4));
                continue;
            }
        };
        match w.run_session(port) {
            Ok(()) => break, // shutdown
            Err((reason, connected)) => {
                if connected {
                    backoff = Duration::from_millis(250); // it worked before: retry soon
                }
                let _ = events.send(LinkEvent::Disconnected {
                    reason,
                    retry_in: backoff,
                });
                nap(&shared, backoff);
                backoff = (backoff * 2).min(Duration::from_secs(4));
            }
        }
    }
}

fn spawn_reader(
    port: Box<dyn Port>,
    session: Arc<(Mutex<Session>, Condvar)>,
    shared: Arc<(Mutex<Shared>, Condvar)>,
    in_flight: Arc<Mutex<InFlight>>,
    events: UnboundedSender<LinkEvent>,
) -> io::Result<JoinHandle<()>> {
    std::thread::Builder::new()
        .name("serial reader".into())
        .spawn(move || {
            let mut reader = FrameReader::new(port);
            loop {
                if is_shutdown(&shared)
                    || session.0.lock().map(|s| s.broken.is_some()).unwrap_or(true)
                {
                    return;
                }
                let frames = match reader.read_frames() {
                    Ok(f) => f,
                    Err(e) => {
                        if let Ok(mut s) = session.0.lock() {
                            s.broken.get_or_insert(format!("read: {e}"));
                        }
                        session.1.notify_all();
                        shared.1.notify_all();
                        return;
                    }
                };
                for item in frames {
                    match item {
                        Err(DecodeError::Garbage { .. }) | Err(_) => {
                            if let Err(e) = item {
                                let _ = events.send(LinkEvent::Garbage {
                                    error: e.to_string(),
                                });
                            }
                        }
                        Ok(Frame {
                            msg:
                                Message::HelloAck {
                                    version,
                                    firmware_major,
                                    firmware_minor,
                                    ..
                                },
                            ..
                        }) => {
                            if let Ok(mut s) = session.0.lock() {
                                s.hello_ack = Some((version, firmware_major, firmware_minor));
                            }
                            session.1.notify_all();
                        }
                        Ok(Frame {
                            msg:
                                Message::State {
                                    ack_seq,
                                    state,
                                    clamped,
                                    rx_errors,
                                    ticks,
                                },
                            ..
                        }) => {
                            let answered = in_flight
                                .lock()
                                .ok()
                                .and_then(|mut f| f.take(ack_seq))
                                .map(|(stamp, at)| (stamp, at.elapsed()));
                            let _ = events.send(LinkEvent::State {
                                ack_seq,
                                state,
                                clamped,
                                rx_errors,
                                ticks,
                                answered,
                            });
                        }
                        Ok(other) => {
                            let _ = events.send(LinkEvent::Garbage {
                                error: format!(
                                    "unexpected {:?} from the device",
                                    other.msg.msg_type()
                                ),
                            });
                        }
                    }
                }
            }
        })
}

/// What the writer thread keeps across connections.
struct Writer {
    config: LinkConfig,
    shared: Arc<(Mutex<Shared>, Condvar)>,
    stats: Arc<Mutex<SendStats>>,
    events: UnboundedSender<LinkEvent>,
    in_flight: Arc<Mutex<InFlight>>,
    seq: u8,
}

impl Writer {
    /// One connection: handshake, then commands until the port breaks (`Err`, with
    /// whether the handshake had succeeded) or shutdown (`Ok`).
    fn run_session(&mut self, mut port: Box<dyn Port>) -> Result<(), (String, bool)> {
        let session = Arc::new((Mutex::new(Session::default()), Condvar::new()));
        let reader_port = port
            .try_clone_port()
            .map_err(|e| (format!("cannot split the port: {e}"), false))?;
        let reader = spawn_reader(
            reader_port,
            session.clone(),
            self.shared.clone(),
            self.in_flight.clone(),
            self.events.clone(),
        )
        .map_err(|e| (format!("cannot start the reader: {e}"), false))?;
        let mut connected = false;
        let result = self
            .session_body(&mut port, &session, &mut connected)
            .map_err(|e| (e, connected));
        if let Ok(mut s) = session.0.lock() {
            s.broken.get_or_insert_with(|| "session over".into());
        }
        drop(port);
        let _ = reader.join();
        result
    }
}

fn send(port: &mut Box<dyn Port>, seq: &mut u8, msg: Message) -> Result<u8, String> {
    *seq = seq.wrapping_add(1);
    port.write_all(&encode(&Frame { seq: *seq, msg }))
        .map_err(|e| format!("write: {e}"))?;
    port.flush().map_err(|e| format!("write: {e}"))?;
    Ok(*seq)
}

impl Writer {
    fn session_body(
        &mut self,
        port: &mut Box<dyn Port>,
        session: &Arc<(Mutex<Session>, Condvar)>,
        connected: &mut bool,
    ) -> Result<(), String> {
        let Writer {
            config,
            shared,
            stats,
            events,
            in_flight,
            seq,
        } = self;
        // Handshake: a Uno resets when the port opens; its bootloader takes ~1.5 s.
        let deadline = Instant::now() + Duration::from_secs(4);
        let firmware = loop {
            if is_shutdown(shared) {
                return Ok(());
            }
            if Instant::now() > deadline {
                return Err(
                    "no answer to HELLO within 4 s (is the servo_control firmware on the board?)"
                        .into(),
                );
            }
            send(
                port,
                seq,
                Message::Hello {
                    version: PROTOCOL_VERSION,
                },
            )?;
            let (lock, cv) = &**session;
            let guard = lock.lock().map_err(|_| "poisoned".to_string())?;
            let (guard, _) = cv
                .wait_timeout_while(guard, Duration::from_millis(250), |s| {
                    s.hello_ack.is_none() && s.broken.is_none()
                })
                .map_err(|_| "poisoned".to_string())?;
            if let Some(b) = &guard.broken {
                return Err(b.clone());
            }
            if let Some((version, major, minor)) = guard.hello_ack {
                if version != PROTOCOL_VERSION {
                    let _ = events.send(LinkEvent::VersionMismatch { device: version });
                    return Err(format!(
                        "device speaks protocol {version}, this node {PROTOCOL_VERSION}"
                    ));
                }
                break (major, minor);
            }
        };
        send(
            port,
            seq,
            Message::Config {
                watchdog_ms: config.watchdog_ms,
                action: config.watchdog_action,
            },
        )?;
        let _ = events.send(LinkEvent::Connected { firmware });
        *connected = true;

        // The device starts with the e-stop released; tell it the current state, then
        // continue from the newest command.
        let (mut sent_generation, mut sent_estop_generation, mut estop_sent) =
            (0u64, u64::MAX, false);
        let mut last_command_sent: Option<Instant> = None;
        let mut last_any_sent = Instant::now();
        loop {
            let (lock, cv) = &**shared;
            let mut s = lock.lock().map_err(|_| "poisoned".to_string())?;
            loop {
                if s.shutdown {
                    return Ok(());
                }
                if let Some(b) = session.0.lock().ok().and_then(|x| x.broken.clone()) {
                    return Err(b);
                }
                let now = Instant::now();
                let estop_due = s.estop_generation != sent_estop_generation;
                let command_waiting =
                    s.generation != sent_generation && s.latest.is_some() && !s.estop;
                let command_allowed_at = last_command_sent
                    .map(|t| t + config.send_period)
                    .unwrap_or(now);
                let heartbeat_at = last_any_sent + config.heartbeat_period;
                if estop_due
                    || (command_waiting && now >= command_allowed_at)
                    || now >= heartbeat_at
                {
                    break;
                }
                let wake = if command_waiting {
                    command_allowed_at.min(heartbeat_at)
                } else {
                    heartbeat_at
                };
                s = cv
                    .wait_timeout(s, wake.saturating_duration_since(now))
                    .map_err(|_| "poisoned".to_string())?
                    .0;
            }
            // Decide under the lock, write without it.
            let now = Instant::now();
            let estop = s.estop;
            let estop_due = s.estop_generation != sent_estop_generation;
            sent_estop_generation = s.estop_generation;
            let command = if !estop
                && s.generation != sent_generation
                && now
                    >= last_command_sent
                        .map(|t| t + config.send_period)
                        .unwrap_or(now)
            {
                sent_generation = s.generation;
                s.latest
            } else {
                if estop {
                    // commands during an e-stop are dropped, not kept for later
                    sent_generation = s.generation;
                }
                None
            };
            drop(s);
            if estop_due && (estop || estop_sent) {
                send(port, seq, Message::Estop { engaged: estop })?;
                estop_sent = estop;
                last_any_sent = Instant::now();
            }
            if let Some((ticks, stamp, handed_in)) = command {
                let next = seq.wrapping_add(1);
                if let Ok(mut f) = in_flight.lock() {
                    f.record(next, stamp, Instant::now());
                }
                let latency = handed_in.elapsed();
                send(port, seq, Message::SetPulses { ticks })?;
                if let Ok(mut st) = stats.lock() {
                    st.sent += 1;
                    if st.latency_us.len() == 1000 {
                        st.latency_us.pop_front();
                    }
                    st.latency_us.push_back(latency.as_secs_f64() * 1e6);
                }
                last_command_sent = Some(Instant::now());
                last_any_sent = Instant::now();
            } else if Instant::now() >= last_any_sent + config.heartbeat_period {
                send(port, seq, Message::Heartbeat)?;
                last_any_sent = Instant::now();
            }
        }
    }
}

/// The in-process virtual Arduino with the firmware's default configuration.
pub fn virtual_arduino() -> VirtualArduino {
    VirtualArduino::new(DeviceConfig::default())
}
