//! The host side of the servo link as a pure state machine: what to send next is a
//! function of time and state ([`HostLink::next`]); the bytes that come back, the
//! port opening or breaking, a new command and the e-stop are inputs. No threads, no
//! ports: a thin I/O shell (`serial_node`'s link thread) opens the port, writes what
//! [`HostLink::next`] says, and feeds back what it reads.
//!
//! The link is latest-wins: a new command replaces the one being sent, SET_PULSES go
//! out at most at the send rate on average, and each servo's pulse moves by at most its
//! velocity limit per second (the last guard against anything that publishes servo
//! angles directly), starting from where the device says the servos are.
//!
//! The send rate (100/s by default) is above the rate of any command stream (a planner
//! sends 50/s), so a command never waits for a frame slot: at a rate equal to the
//! command rate, one command that waited made every later one wait as long. The
//! velocity guard judges motion per servo frame ([`SERVO_FRAME`], the 20 ms in which a
//! servo sees one pulse): a frame may move a servo by its limit times the time since
//! the last frame, at most one servo frame's worth; when it had to cut a step short,
//! the rest follows one servo frame later, so a ramp moves at the limit and a planned
//! stream that arrives early now and then is cut by the early part only. The e-stop
//! lives here only: while engaged, commands are dropped; after its release nothing
//! moves until a new command, which ramps from where the arm is.
//!
//! A stamped command goes through the late-hold gate ([`HostLink::offer`], the rule of
//! [`command_gate`]): one that arrives late (what a network outage held back, sent
//! when the link returned) is held for a newer one, and [`HostLink::next`] applies it
//! when none came within [`command_gate::HOLD_LATE`] (while a burst is coming in, at
//! most [`command_gate::HOLD_MAX`]). The wait is part of [`Next::Wait`], so the shell needs no
//! timer of its own.
//!
//! **The leader role** (protocol version 3): with [`HostConfig::role`] (or
//! [`HostLink::set_role`]) [`Role::Leader`], the link asks the device for the leader
//! role right after CONFIG and sends nothing else but HEARTBEATs: no pulses, no e-stop
//! (a leader drives no servos). Each LEADER_STATE the device streams (104.2 Hz) is
//! decoded into a [`LeaderState`], queued for [`HostLink::take_leader_states`] and
//! counted in [`HostLink::leader_stats`] (windows lost, the device's late samples). A
//! device whose STATE says it lost the role (or, for a follower link, took it) is told
//! again. A follower link drives a version-2 device as well (version 3 changed nothing
//! of a follower's frames); the leader role needs version 3.
//!
//! # Examples
//! ```
//! use servo_protocol::host::{HostConfig, HostLink, LinkEvent, Next};
//! use servo_protocol::device::Device;
//! use servo_protocol::{decode, Message};
//! use std::time::{Duration, Instant};
//!
//! let t0 = Instant::now();
//! let mut link = HostLink::<u32>::new(HostConfig::default(), t0);
//! let mut device = Device::new(Default::default());
//! assert_eq!(link.next(t0), Next::Open);
//! link.opened(t0);
//! link.command([3000; 4], 7, t0); // tagged 7, e.g. the command's stamp
//! // drive the link against the device model until the command is answered
//! let mut now = t0;
//! let mut answered = None;
//! while answered.is_none() && now < t0 + Duration::from_secs(2) {
//!     match link.next(now) {
//!         Next::Send(frame) => device.receive(&servo_protocol::encode(&frame), now - t0),
//!         Next::Wait(until) => now = until,
//!         other => panic!("{other:?}"),
//!     }
//!     let mut out = device.take_output();
//!     while let Ok(Some(f)) = decode(&mut out) {
//!         link.received(f, now);
//!     }
//!     for e in link.take_events() {
//!         if let LinkEvent::State { answered: Some((tag, _)), ticks, .. } = e {
//!             answered = Some((tag, ticks));
//!         }
//!     }
//! }
//! assert_eq!(answered.map(|a| a.0), Some(7));
//! ```

use crate::frame::{
    DeviceState, Frame, Message, Role, StopAction, WatchdogAction, PROTOCOL_VERSION,
};
use crate::leader::LeaderState;
use crate::SERVOS;
use command_gate::{CommandGate, GateCounters, Stamp, Verdict};
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// How many SET_PULSES frames may go out back to back: the send rate is an average
/// (a token bucket of this size).
pub const SEND_BURST: f64 = 2.0;

/// A servo's refresh period: it sees one pulse every 20 ms, so this is the time step of
/// the velocity guard.
pub const SERVO_FRAME: Duration = Duration::from_millis(20);

/// The oldest protocol version a follower link drives: version 3 added the leader role
/// and left a follower's frames as version 2 had them.
pub const OLDEST_FOLLOWER_VERSION: u8 = 2;

/// The protocol version the leader role needs.
pub const LEADER_VERSION: u8 = 3;

/// The most LEADER_STATEs [`HostLink::take_leader_states`] keeps (2.5 s at 104.2 Hz); a
/// shell that does not take them loses the oldest.
pub const LEADER_QUEUE: usize = 256;

/// Link settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HostConfig {
    /// One over the most SET_PULSES frames a second, on average ([`SEND_BURST`] may go
    /// back to back): 10 ms, twice a planner's command rate, so commands never queue.
    pub send_period: Duration,
    /// Send a HEARTBEAT when nothing was sent for this long.
    pub heartbeat_period: Duration,
    /// HELLO is repeated this often until HELLO_ACK comes.
    pub hello_period: Duration,
    /// No HELLO_ACK within this: the port is closed and opened again (a Uno's
    /// bootloader takes ~1.5 s after the port opens).
    pub handshake_timeout: Duration,
    /// Device watchdog timeout, sent in CONFIG.
    pub watchdog_ms: u16,
    /// Device watchdog action, sent in CONFIG.
    pub watchdog_action: WatchdogAction,
    /// What an engaged e-stop makes the device do: hold the pulses or stop them.
    pub estop_action: StopAction,
    /// Each servo's velocity limit, ticks per second (`f64::INFINITY`: none).
    pub max_ticks_per_s: [f64; SERVOS],
    /// First wait before opening the port again; doubles on each failure.
    pub retry_min: Duration,
    /// Longest wait between two attempts.
    pub retry_max: Duration,
    /// The device's role: [`Role::Follower`] drives the servos (commands, e-stop);
    /// [`Role::Leader`] asks the device for the leader role after CONFIG and takes its
    /// LEADER_STATEs ([`HostLink::take_leader_states`]); commands and the e-stop are not
    /// sent to a leader.
    pub role: Role,
}

impl Default for HostConfig {
    fn default() -> Self {
        HostConfig {
            send_period: Duration::from_millis(10),
            heartbeat_period: Duration::from_millis(100),
            hello_period: Duration::from_millis(250),
            handshake_timeout: Duration::from_secs(4),
            watchdog_ms: 500,
            watchdog_action: WatchdogAction::Hold,
            estop_action: StopAction::Hold,
            max_ticks_per_s: [f64::INFINITY; SERVOS],
            retry_min: Duration::from_millis(100),
            retry_max: Duration::from_millis(500),
            role: Role::Follower,
        }
    }
}

/// What the shell must do now.
#[derive(Clone, Debug, PartialEq)]
pub enum Next {
    /// Open the port, then call [`HostLink::opened`] or [`HostLink::open_failed`].
    Open,
    /// Write this frame (on failure, call [`HostLink::lost`]).
    Send(Frame),
    /// Close the port (the handshake failed), then ask again.
    Close {
        /// why
        reason: String,
    },
    /// Nothing until this instant, a frame from the device, or a new input.
    Wait(Instant),
}

/// What the link reports. `T` is the tag handed in with each command (its stamp).
#[derive(Clone, Debug, PartialEq)]
pub enum LinkEvent<T> {
    /// The port is open and the device answered the handshake.
    Connected {
        /// firmware version
        firmware: (u8, u8),
    },
    /// The port could not be opened, or was lost.
    Disconnected {
        /// why
        reason: String,
        /// until the next attempt
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
        /// where the servos are (see [`Message::State`])
        ticks: [u16; SERVOS],
        /// if it answers a SET_PULSES of ours: that command's tag and the round trip
        answered: Option<(T, Duration)>,
    },
    /// A frame the device should not send (device-to-host only), or bytes that were
    /// not a frame.
    Garbage {
        /// why
        error: String,
    },
    /// A command handed in during an engaged e-stop: dropped.
    DroppedInEstop,
    /// A command held back for arriving late ([`HostLink::offer`]) became the command:
    /// no newer one came within [`command_gate::HOLD_LATE`].
    LateApplied {
        /// its tag
        tag: T,
    },
}

/// What [`HostLink::offer`] did with a command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Offered {
    /// It is the command now.
    Now,
    /// It arrived late: held back for a newer one, applied by [`HostLink::next`] at
    /// the gate's deadline if none comes.
    Held {
        /// seconds from its stamp to its reception
        age_s: f64,
    },
    /// The e-stop is engaged: dropped (and reported as [`LinkEvent::DroppedInEstop`]).
    DroppedInEstop,
}

/// What came of the leader role's stream ([`HostLink::leader_stats`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LeaderStats {
    /// LEADER_STATEs received (every session).
    pub frames: u64,
    /// Windows missing between two LEADER_STATEs of a session (gaps in their window
    /// counter: frames lost on the wire, or not sent).
    pub windows_lost: u64,
    /// The device's count of late samples, as of its last LEADER_STATE (wraps).
    pub overruns: u8,
    /// The last LEADER_STATE of this session, and when it came.
    pub last: Option<(LeaderState, Instant)>,
}

/// Counters of the sending side, for diagnostics.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SendStats {
    /// SET_PULSES frames sent.
    pub sent: u64,
    /// Of those, frames limited by the velocity guard (a command that asked for a
    /// faster move).
    pub ramped: u64,
    /// The last (up to) 1000 delays from a command's arrival to its first frame, µs.
    pub latency_us: VecDeque<f64>,
    /// Commands replaced by a newer one before any frame of theirs went out (latest
    /// wins: a link that could not send meanwhile, a port being reopened).
    pub superseded: u64,
}

#[derive(Clone, Debug)]
enum Phase {
    Closed {
        retry_at: Instant,
        backoff: Duration,
    },
    Handshake {
        deadline: Instant,
        next_hello: Instant,
    },
    Connected {
        config_sent: bool,
    },
}

#[derive(Clone, Debug)]
struct Command<T> {
    ticks: [u16; SERVOS],
    tag: T,
    received: Instant,
    /// its first frame has gone out (latency recorded)
    started: bool,
}

/// The host side of the link. See the [module](self).
#[derive(Clone, Debug)]
pub struct HostLink<T> {
    config: HostConfig,
    phase: Phase,
    seq: u8,
    estop: bool,
    /// the device's e-stop as far as we know this session (None: not told yet)
    device_estop: Option<bool>,
    /// the newest command, until its pulses have been sent
    command: Option<Command<T>>,
    /// the newest command ever handed in (sent again after a reconnection)
    newest: Option<([u16; SERVOS], T)>,
    /// the pulses last sent this session, or else the pose the device reported
    at: Option<[u16; SERVOS]>,
    last_pulses_sent: Option<Instant>,
    /// SET_PULSES frames that may go now (the token bucket), as of `credit_at`
    credit: f64,
    credit_at: Instant,
    last_sent: Instant,
    in_flight: VecDeque<(u8, T, Instant)>,
    connected_once: bool,
    events: Vec<LinkEvent<T>>,
    stats: SendStats,
    /// the late-hold gate: a late command with its tag and reception
    gate: CommandGate<([u16; SERVOS], T, Instant)>,
    /// the device's protocol version, this session
    device_version: Option<u8>,
    /// the device's role as far as we know this session (a HELLO makes it a follower),
    /// and the sequence number of the last ROLE sent until a STATE answers it or a later
    /// frame: STATEs that answer older frames say nothing of the role
    device_role: Option<Role>,
    role_seq: Option<u8>,
    /// the device's last word this session (a STATE answering our last ROLE or later, a
    /// LEADER_STATE) said it leads
    device_leads: bool,
    /// the window of the last LEADER_STATE, to count gaps from (none after a ROLE: the
    /// device's counter may start again)
    gap_base: Option<u8>,
    /// LEADER_STATEs not taken yet
    leader: VecDeque<LeaderState>,
    leader_stats: LeaderStats,
}

impl<T: Clone> HostLink<T> {
    /// A link whose port is not open yet.
    pub fn new(config: HostConfig, now: Instant) -> Self {
        HostLink {
            config,
            phase: Phase::Closed {
                retry_at: now,
                backoff: config.retry_min,
            },
            seq: 0,
            estop: false,
            device_estop: None,
            command: None,
            newest: None,
            at: None,
            last_pulses_sent: None,
            credit: SEND_BURST,
            credit_at: now,
            last_sent: now,
            in_flight: VecDeque::new(),
            connected_once: false,
            events: Vec::new(),
            stats: SendStats::default(),
            gate: CommandGate::new(),
            device_version: None,
            device_role: None,
            role_seq: None,
            device_leads: false,
            gap_base: None,
            leader: VecDeque::new(),
            leader_stats: LeaderStats::default(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &HostConfig {
        &self.config
    }

    /// Change the servos' velocity limits (ticks per second), from the next frame on.
    pub fn set_velocity_limits(&mut self, max_ticks_per_s: [f64; SERVOS]) {
        self.config.max_ticks_per_s = max_ticks_per_s;
    }

    /// Whether a port is open (handshake under way, or connected).
    pub fn is_open(&self) -> bool {
        !matches!(self.phase, Phase::Closed { .. })
    }

    /// Whether the handshake has succeeded on the open port.
    pub fn is_connected(&self) -> bool {
        matches!(self.phase, Phase::Connected { .. })
    }

    /// Whether the e-stop is engaged.
    pub fn estop(&self) -> bool {
        self.estop
    }

    /// The counters of the sending side.
    pub fn stats(&self) -> &SendStats {
        &self.stats
    }

    /// What the late-hold gate did ([`HostLink::offer`]).
    pub fn gate(&self) -> &GateCounters {
        self.gate.counters()
    }

    /// The role this link wants the device in.
    pub fn role(&self) -> Role {
        self.config.role
    }

    /// Ask for another role from now on (on the open session, once connected: a ROLE
    /// frame goes out at the next [`HostLink::next`]); returns whether that changed it.
    /// A device that speaks protocol version 2 cannot lead: asking one for the leader
    /// role reports [`LinkEvent::VersionMismatch`] and closes the port.
    pub fn set_role(&mut self, role: Role, now: Instant) -> bool {
        if self.config.role == role {
            return false;
        }
        self.config.role = role;
        if let Some(version) = self.device_version {
            if role == Role::Leader && version < LEADER_VERSION {
                self.refuse_version(version, now);
            }
        }
        true
    }

    /// Whether the device is in the leader role: connected, and its last word (a STATE
    /// answering the ROLE or later, or a LEADER_STATE) said so.
    pub fn leader_active(&self) -> bool {
        self.is_connected() && self.config.role == Role::Leader && self.device_leads
    }

    /// The LEADER_STATEs received since the last call, oldest first (at most
    /// [`LEADER_QUEUE`]).
    pub fn take_leader_states(&mut self) -> Vec<LeaderState> {
        self.leader.drain(..).collect()
    }

    /// What came of the leader role's stream.
    pub fn leader_stats(&self) -> &LeaderStats {
        &self.leader_stats
    }

    /// The events since the last call.
    pub fn take_events(&mut self) -> Vec<LinkEvent<T>> {
        std::mem::take(&mut self.events)
    }

    /// The newest command, tagged (e.g. with its stamp), handed in at `now`. It
    /// replaces any command not yet fully sent (and one held late); during an e-stop it
    /// is dropped. It bypasses the late-hold gate: see [`HostLink::offer`].
    pub fn command(&mut self, ticks: [u16; SERVOS], tag: T, now: Instant) {
        self.gate.discard();
        self.apply(ticks, tag, now);
    }

    /// A stamped command received at `now`, through the late-hold gate: it becomes the
    /// command at once ([`HostLink::command`]), or, arriving late, is held back for a
    /// newer one (which replaces it, or drops it if live; the gate's `superseded`
    /// counts both) and applied by [`HostLink::next`] when none came in time. During
    /// an e-stop it is dropped.
    pub fn offer(&mut self, ticks: [u16; SERVOS], tag: T, stamp: Stamp, now: Instant) -> Offered {
        if self.estop {
            self.events.push(LinkEvent::DroppedInEstop);
            return Offered::DroppedInEstop;
        }
        match self.gate.offer((ticks, tag, now), stamp, now) {
            Verdict::Pass {
                item: (ticks, tag, now),
                ..
            } => {
                self.apply(ticks, tag, now);
                Offered::Now
            }
            // (TooOld never comes: this gate has no maximum age)
            Verdict::Held { age_s, .. } | Verdict::TooOld { age_s, .. } => Offered::Held { age_s },
        }
    }

    fn apply(&mut self, ticks: [u16; SERVOS], tag: T, now: Instant) {
        if self.estop {
            self.events.push(LinkEvent::DroppedInEstop);
            return;
        }
        self.newest = Some((ticks, tag.clone()));
        if self.command.as_ref().is_some_and(|c| !c.started) {
            self.stats.superseded += 1;
        }
        self.command = Some(Command {
            ticks,
            tag,
            received: now,
            started: false,
        });
    }

    /// Engage or release the e-stop; returns whether that changed it. Engaging drops
    /// the command being sent and one held late; after a release the servos move only
    /// on a new command.
    pub fn set_estop(&mut self, engaged: bool) -> bool {
        if engaged {
            self.command = None;
            self.gate.discard();
        }
        let changed = self.estop != engaged;
        self.estop = engaged;
        changed
    }

    /// The port opened: start the handshake.
    pub fn opened(&mut self, now: Instant) {
        self.phase = Phase::Handshake {
            deadline: now + self.config.handshake_timeout,
            next_hello: now,
        };
        self.at = None;
        self.last_pulses_sent = None;
        self.device_estop = None;
        self.in_flight.clear();
        self.device_version = None;
        self.device_role = None;
        self.role_seq = None;
        self.device_leads = false;
        self.gap_base = None;
        self.leader_stats.last = None;
    }

    /// The port could not be opened: try again later.
    pub fn open_failed(&mut self, reason: String, now: Instant) {
        let backoff = match self.phase {
            Phase::Closed { backoff, .. } => backoff,
            _ => self.config.retry_min,
        };
        self.close(reason, now, backoff);
    }

    /// The port broke (read or write error, device gone): close and try again soon.
    pub fn lost(&mut self, reason: String, now: Instant) {
        let backoff = self.config.retry_min;
        self.close(reason, now, backoff);
    }

    fn close(&mut self, reason: String, now: Instant, retry_in: Duration) {
        self.events
            .push(LinkEvent::Disconnected { reason, retry_in });
        self.phase = Phase::Closed {
            retry_at: now + retry_in,
            backoff: (retry_in * 2).min(self.config.retry_max),
        };
        self.at = None;
        self.in_flight.clear();
        self.device_version = None;
        self.device_leads = false;
    }

    /// The device speaks `version`, which cannot do what we want: a firmware upgrade
    /// is needed, no point in trying every 100 ms.
    fn refuse_version(&mut self, version: u8, now: Instant) {
        self.events
            .push(LinkEvent::VersionMismatch { device: version });
        let reason = if self.config.role == Role::Leader && version < LEADER_VERSION {
            format!("device speaks protocol {version}; the leader role needs {LEADER_VERSION}")
        } else {
            format!("device speaks protocol {version}, this node {PROTOCOL_VERSION}")
        };
        self.close(reason, now, self.config.retry_max);
    }

    /// Whether a device speaking `version` can take our role.
    fn version_fits(&self, version: u8) -> bool {
        match self.config.role {
            Role::Follower => (OLDEST_FOLLOWER_VERSION..=PROTOCOL_VERSION).contains(&version),
            Role::Leader => version == PROTOCOL_VERSION,
        }
    }

    /// Bytes from the device that were not a frame.
    pub fn garbage(&mut self, error: String) {
        self.events.push(LinkEvent::Garbage { error });
    }

    /// A frame from the device. Returns whether what [`HostLink::next`] says may have
    /// changed (the handshake's answer, the first pose, the device's e-stop differing
    /// from ours), so a shell sleeping until its last `Wait` must ask again; the
    /// acknowledgements of a running stream return `false`.
    pub fn received(&mut self, frame: Frame, now: Instant) -> bool {
        match frame.msg {
            Message::HelloAck {
                version,
                firmware_major,
                firmware_minor,
                ..
            } => {
                if !matches!(self.phase, Phase::Handshake { .. }) {
                    return false; // a late answer to a repeated HELLO
                }
                if !self.version_fits(version) {
                    self.refuse_version(version, now);
                    return true;
                }
                self.phase = Phase::Connected { config_sent: false };
                self.device_version = Some(version);
                // a HELLO puts a device in the follower role (version 2: the only one)
                self.device_role = Some(Role::Follower);
                self.role_seq = None;
                if self.connected_once && !self.estop {
                    // the newest command goes out again, ramping from where the device is
                    if let Some((ticks, tag)) = self.newest.clone() {
                        self.command = Some(Command {
                            ticks,
                            tag,
                            received: now,
                            started: true,
                        });
                    }
                }
                self.connected_once = true;
                self.events.push(LinkEvent::Connected {
                    firmware: (firmware_major, firmware_minor),
                });
                true
            }
            Message::State {
                ack_seq,
                state,
                clamped,
                rx_errors,
                ticks,
            } => {
                if !self.is_connected() {
                    return false;
                }
                let mut replan = false;
                // the device's role, from a STATE that answers our last ROLE or a later
                // frame (one answering an older frame may predate it)
                let reported = if state == DeviceState::Leader {
                    Role::Leader
                } else {
                    Role::Follower
                };
                let current = self.role_seq.is_none_or(|r| ack_seq.wrapping_sub(r) < 128);
                if current {
                    // the answers come in order: every later STATE is as new
                    self.role_seq = None;
                    self.device_leads = reported == Role::Leader;
                    if self.device_role != Some(reported) {
                        replan |= reported != self.config.role;
                        self.device_role = Some(reported);
                    }
                }
                // the pose the device reports is where the next pulses start, until we
                // have sent pulses of our own this session
                // and under an e-stop the pose it holds: it drops a command it had not
                // shown yet (PROTOCOL.md), and the first after the release ramps from there
                if self.last_pulses_sent.is_none() || state == DeviceState::Estop {
                    replan |= self.at != Some(ticks);
                    self.at = Some(ticks);
                }
                // the device's e-stop differs from ours (reset, or engaged before a
                // reconnection): tell it again
                let device_estop = state == DeviceState::Estop;
                if self.device_estop.is_some() && device_estop != self.estop {
                    replan |= self.device_estop != Some(device_estop);
                    self.device_estop = Some(device_estop);
                }
                let answered = self
                    .in_flight
                    .iter()
                    .position(|(s, _, _)| *s == ack_seq)
                    .and_then(|i| self.in_flight.remove(i))
                    .map(|(_, tag, at)| (tag, now.saturating_duration_since(at)));
                self.events.push(LinkEvent::State {
                    ack_seq,
                    state,
                    clamped,
                    rx_errors,
                    ticks,
                    answered,
                });
                replan
            }
            Message::LeaderState { .. } => {
                if !self.is_connected() {
                    return false;
                }
                let Some(state) = LeaderState::from_frame(&frame) else {
                    return false;
                };
                if self.config.role != Role::Leader {
                    // a follower link's device leads: the STATEs say so (every answer
                    // does), and it is told (ROLE follower); frames still in flight
                    // after that are no news
                    return false;
                }
                self.device_leads = true;
                let stats = &mut self.leader_stats;
                stats.frames += 1;
                if let Some(base) = self.gap_base {
                    stats.windows_lost +=
                        u64::from(state.window.wrapping_sub(base).wrapping_sub(1));
                }
                self.gap_base = Some(state.window);
                stats.overruns = state.overruns;
                stats.last = Some((state, now));
                if self.leader.len() == LEADER_QUEUE {
                    self.leader.pop_front();
                }
                self.leader.push_back(state);
                false
            }
            other => {
                self.events.push(LinkEvent::Garbage {
                    error: format!("unexpected {:?} from the device", other.msg_type()),
                });
                false
            }
        }
    }

    fn frame(&mut self, msg: Message, now: Instant) -> Next {
        self.seq = self.seq.wrapping_add(1);
        self.last_sent = now;
        Next::Send(Frame { seq: self.seq, msg })
    }

    /// What to do at `now`. A [`Next::Send`] counts as sent: if writing it fails,
    /// call [`HostLink::lost`]. A command held late becomes the command at its
    /// deadline: a [`Next::Wait`] is never past it.
    pub fn next(&mut self, now: Instant) -> Next {
        if let Some((ticks, tag, received)) = self.gate.take_due(now) {
            self.events
                .push(LinkEvent::LateApplied { tag: tag.clone() });
            self.apply(ticks, tag, received);
        }
        match self.next_action(now) {
            Next::Wait(until) => Next::Wait(self.gate.deadline().map_or(until, |d| d.min(until))),
            other => other,
        }
    }

    fn next_action(&mut self, now: Instant) -> Next {
        match self.phase.clone() {
            Phase::Closed { retry_at, .. } => {
                if now >= retry_at {
                    Next::Open
                } else {
                    Next::Wait(retry_at)
                }
            }
            Phase::Handshake {
                deadline,
                next_hello,
            } => {
                if now >= deadline {
                    let reason = format!(
                        "no answer to HELLO within {:.1} s (is the servo_control firmware on the board?)",
                        self.config.handshake_timeout.as_secs_f64()
                    );
                    let backoff = self.config.retry_min;
                    self.close(reason.clone(), now, backoff);
                    Next::Close { reason }
                } else if now >= next_hello {
                    self.phase = Phase::Handshake {
                        deadline,
                        next_hello: now + self.config.hello_period,
                    };
                    self.frame(
                        Message::Hello {
                            version: PROTOCOL_VERSION,
                        },
                        now,
                    )
                } else {
                    Next::Wait(next_hello.min(deadline))
                }
            }
            Phase::Connected { config_sent } => {
                if !config_sent {
                    self.phase = Phase::Connected { config_sent: true };
                    return self.frame(
                        Message::Config {
                            watchdog_ms: self.config.watchdog_ms,
                            action: self.config.watchdog_action,
                        },
                        now,
                    );
                }
                // the device's role differs from ours (after the HELLO a leader link's
                // does; a follower's only if the device took the leader role): tell it
                let role = self.config.role;
                if self.device_role != Some(role) {
                    self.device_role = Some(role);
                    let next = self.frame(Message::Role { role }, now);
                    self.role_seq = Some(self.seq);
                    self.gap_base = None;
                    return next;
                }
                if role == Role::Leader {
                    // a leader drives nothing: heartbeats only
                    let heartbeat_due = self.last_sent + self.config.heartbeat_period;
                    if now >= heartbeat_due {
                        return self.frame(Message::Heartbeat, now);
                    }
                    return Next::Wait(heartbeat_due);
                }
                // a device starts released: tell it only when it matters
                let told = self.device_estop.unwrap_or(false);
                if told != self.estop || (self.device_estop.is_none() && self.estop) {
                    self.device_estop = Some(self.estop);
                    let engaged = self.estop.then_some(self.config.estop_action);
                    return self.frame(Message::Estop { engaged }, now);
                }
                self.device_estop = Some(self.estop);
                let pulses_due = self.pulses_due(now);
                if self.command.is_some() && !self.estop {
                    if self.at.is_none() {
                        // where the servos are is not known yet: ask
                        if now
                            >= self.last_sent
                                + self.config.heartbeat_period.min(self.config.send_period)
                        {
                            return self.frame(Message::Heartbeat, now);
                        }
                    } else if now >= pulses_due {
                        return self.send_pulses(now);
                    }
                }
                let heartbeat_due = self.last_sent + self.config.heartbeat_period;
                if now >= heartbeat_due {
                    return self.frame(Message::Heartbeat, now);
                }
                let mut wake = heartbeat_due;
                if self.command.is_some() && !self.estop {
                    wake = wake.min(if self.at.is_some() {
                        pulses_due
                    } else {
                        self.last_sent + self.config.send_period
                    });
                }
                Next::Wait(wake)
            }
        }
    }

    /// Frames the token bucket holds at `now`.
    fn credit(&self, now: Instant) -> f64 {
        let refill = now.saturating_duration_since(self.credit_at).as_secs_f64()
            / self.config.send_period.as_secs_f64().max(1e-6);
        (self.credit + refill).min(SEND_BURST)
    }

    /// When the next SET_PULSES may go: when the token bucket holds a frame, and for
    /// the rest of a step the guard cut short, one servo frame after the last pulses.
    fn pulses_due(&self, now: Instant) -> Instant {
        let credit = self.credit(now);
        let slot = if credit >= 1.0 {
            now
        } else {
            now + self.config.send_period.mul_f64(1.0 - credit)
        };
        match (&self.command, self.last_pulses_sent) {
            (Some(c), Some(last)) if c.started => slot.max(last + SERVO_FRAME),
            _ => slot,
        }
    }

    /// The next SET_PULSES toward the command: each servo at most its velocity limit
    /// times the time since the last pulses (at most one servo frame) away from where
    /// it is.
    fn send_pulses(&mut self, now: Instant) -> Next {
        let (Some(command), Some(at)) = (self.command.clone(), self.at) else {
            return Next::Wait(now + self.config.send_period);
        };
        let dt = self
            .last_pulses_sent
            .map_or(SERVO_FRAME, |t| now.saturating_duration_since(t))
            .min(SERVO_FRAME)
            .as_secs_f64();
        let mut ticks = [0u16; SERVOS];
        let mut limited = false;
        for i in 0..SERVOS {
            let (from, to) = (at[i], command.ticks[i]);
            let max_step = self.config.max_ticks_per_s[i] * dt;
            ticks[i] = if to == 0 || from == 0 || f64::from(from.abs_diff(to)) <= max_step {
                to
            } else {
                limited = true;
                let step = max_step.floor().max(1.0) as u16;
                if to > from {
                    from.saturating_add(step).min(to)
                } else {
                    from.saturating_sub(step).max(to)
                }
            };
        }
        if !command.started {
            if self.stats.latency_us.len() == 1000 {
                self.stats.latency_us.pop_front();
            }
            self.stats.latency_us.push_back(
                now.saturating_duration_since(command.received)
                    .as_secs_f64()
                    * 1e6,
            );
        }
        self.stats.sent += 1;
        self.stats.ramped += u64::from(limited);
        self.at = Some(ticks);
        self.last_pulses_sent = Some(now);
        self.credit = self.credit(now) - 1.0;
        self.credit_at = now;
        let reached = ticks == command.ticks;
        self.command = if reached {
            None
        } else {
            Some(Command {
                started: true,
                ..command.clone()
            })
        };
        let next = self.frame(Message::SetPulses { ticks }, now);
        if let Next::Send(f) = &next {
            if self.in_flight.len() == 32 {
                self.in_flight.pop_front();
            }
            self.in_flight.push_back((f.seq, command.tag, now));
        }
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::{Device, DeviceConfig, FIRMWARE_VERSION, HOLD_TICKS};
    use crate::leader::LeaderInput;
    use crate::{decode, encode, MsgType};

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// The default config with the velocity guard at `ticks_per_s` on every servo.
    fn ramping(ticks_per_s: f64) -> HostConfig {
        HostConfig {
            max_ticks_per_s: [ticks_per_s; SERVOS],
            ..HostConfig::default()
        }
    }

    /// The link against the device model on a fake clock: every frame the link sends
    /// reaches the device at once, its replies come straight back.
    struct Rig {
        t0: Instant,
        now: Instant,
        link: HostLink<u32>,
        device: Device,
        plugged: bool,
        sent: Vec<(Duration, Message)>,
        events: Vec<(Duration, LinkEvent<u32>)>,
    }

    impl Rig {
        fn new(config: HostConfig) -> Rig {
            let t0 = Instant::now();
            Rig {
                t0,
                now: t0,
                link: HostLink::new(config, t0),
                device: Device::new(DeviceConfig::default()),
                plugged: true,
                sent: vec![],
                events: vec![],
            }
        }

        fn t(&self) -> Duration {
            self.now - self.t0
        }

        /// Run the shell's loop until `until` (ms since start). Like serial_node's link
        /// thread, it asks [`HostLink::next`] again only when its `Wait` is over, after
        /// an input (every call starts with one: the tests hand commands in between) or
        /// when [`HostLink::received`] says a frame changed the plan.
        fn run_until(&mut self, until_ms: u64) {
            let until = self.t0 + ms(until_ms);
            let mut asleep_until: Option<Instant> = None;
            while self.now < until {
                let action = match asleep_until {
                    Some(t) if self.now < t => Next::Wait(t),
                    _ => self.link.next(self.now),
                };
                asleep_until = None;
                match action {
                    Next::Open => {
                        if self.plugged {
                            self.link.opened(self.now)
                        } else {
                            self.link.open_failed("no such device".into(), self.now)
                        }
                    }
                    Next::Close { .. } => {}
                    Next::Send(f) => {
                        self.sent.push((self.t(), f.msg));
                        if self.plugged {
                            self.device.receive(&encode(&f), self.t());
                        } else {
                            self.link.lost("write: unplugged".into(), self.now);
                        }
                    }
                    Next::Wait(t) => {
                        asleep_until = Some(t);
                        // the device may speak up meanwhile (watchdog): 1 ms steps
                        self.now = t
                            .min(self.now + ms(1))
                            .max(self.now + Duration::from_micros(100));
                        self.device.tick(self.t());
                    }
                }
                if asleep_until.is_none() {
                    continue; // the device answers while the shell waits, not at once
                }
                let mut out = self.device.take_output();
                while let Ok(Some(f)) = decode(&mut out) {
                    if self.link.received(f, self.now) {
                        asleep_until = None;
                    }
                }
                let t = self.t();
                self.events
                    .extend(self.link.take_events().into_iter().map(|e| (t, e)));
            }
        }

        fn pulses_sent(&self) -> Vec<(Duration, [u16; SERVOS])> {
            self.sent
                .iter()
                .filter_map(|(t, m)| match m {
                    Message::SetPulses { ticks } => Some((*t, *ticks)),
                    _ => None,
                })
                .collect()
        }
    }

    #[test]
    fn handshake_config_then_the_command_within_one_send_period() {
        let mut r = Rig::new(HostConfig::default());
        r.link.command([3000; 4], 1, r.now);
        r.run_until(50);
        let kinds: Vec<_> = r.sent.iter().map(|(_, m)| m.msg_type()).collect();
        use crate::MsgType::*;
        assert_eq!(&kinds[..3], &[Hello, Config, SetPulses], "{kinds:?}");
        assert_eq!(r.device.pulses(), [3000; 4]);
        assert!(r.events.iter().any(
            |(_, e)| matches!(e, LinkEvent::Connected { firmware } if *firmware == FIRMWARE_VERSION)
        ));
        // a follower link never asks for a role
        assert!(r
            .sent
            .iter()
            .all(|(_, m)| m.msg_type() != crate::MsgType::Role));
        assert!(r.events.iter().any(|(_, e)| matches!(
            e,
            LinkEvent::State {
                answered: Some((1, _)),
                ..
            }
        )));
    }

    #[test]
    fn latest_wins_at_the_send_rate_on_average_and_heartbeats_when_idle() {
        let mut r = Rig::new(HostConfig::default());
        r.run_until(10);
        for k in 0..100u16 {
            // a command every 2 ms for 200 ms
            r.link.command([2000 + k; 4], u32::from(k), r.now);
            let next = r.t().as_millis() as u64 + 2;
            r.run_until(next);
        }
        r.run_until(600);
        let pulses = r.pulses_sent();
        // 100 frames/s on average: never three within one send period
        assert!(
            pulses.windows(3).all(|w| w[2].0 - w[0].0 >= ms(10)),
            "{pulses:?}"
        );
        assert!((20..=24).contains(&pulses.len()), "{}", pulses.len());
        assert_eq!(
            pulses.last().unwrap().1,
            [2099; 4],
            "the newest command is the last sent"
        );
        // idle afterwards: heartbeats every 100 ms keep the device's watchdog fed
        let hb: Vec<_> = r
            .sent
            .iter()
            .filter(|(t, m)| *t > ms(300) && *m == Message::Heartbeat)
            .collect();
        assert!(
            hb.len() >= 2 && r.device.state() == DeviceState::Running,
            "{hb:?}"
        );
    }

    /// A 50 Hz stream, each command 20 ms ± 3 ms after its slot (a planner over DDS),
    /// after a burst of three 5 ms apart. `step` ticks per command. Returns the
    /// rig, the commands' arrival times (ms since start) and their ticks.
    fn jittered_stream(config: HostConfig, step: u16) -> (Rig, Vec<(Duration, [u16; SERVOS])>) {
        let mut r = Rig::new(config);
        r.link.command(HOLD_TICKS, 0, r.now);
        r.run_until(100);
        let mut seed = 12345u32;
        let mut jitter = move || {
            seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12345);
            Duration::from_micros(u64::from((seed >> 16) % 6000))
        };
        let mut pose = HOLD_TICKS;
        let mut commands = vec![];
        for k in 0..3u32 {
            pose = pose.map(|p| p + step);
            r.link.command(pose, k, r.now);
            commands.push((r.t(), pose));
            r.run_until(r.t().as_millis() as u64 + 5);
        }
        let mut due = r.now;
        for k in 3..153u32 {
            due += ms(20);
            let at = due - ms(3) + jitter();
            let until = (at - r.t0).as_micros() as u64;
            // run to the arrival, 100 µs resolution
            while r.now + Duration::from_micros(100) < r.t0 + Duration::from_micros(until) {
                let next = r.now + Duration::from_micros(100);
                r.run_until((next - r.t0).as_millis() as u64);
                if r.now < next {
                    r.now = next;
                }
            }
            pose = pose.map(|p| p + step);
            r.link.command(pose, k, r.now);
            commands.push((r.t(), pose));
            r.run_until(r.t().as_millis() as u64 + 1);
        }
        r.run_until(r.t().as_millis() as u64 + 500);
        (r, commands)
    }

    /// For each command: how long after its arrival its first frame went out.
    fn send_delays(r: &Rig, commands: &[(Duration, [u16; SERVOS])]) -> Vec<Duration> {
        let pulses = r.pulses_sent();
        commands
            .iter()
            .zip(commands.iter().skip(1).map(|c| c.0).chain([Duration::MAX]))
            .filter_map(|(&(t, _), next)| {
                pulses
                    .iter()
                    .find(|(sent, _)| *sent >= t && *sent < next)
                    .map(|(sent, _)| *sent - t)
            })
            .collect()
    }

    #[test]
    fn a_jittered_50_hz_stream_after_a_burst_goes_out_on_arrival() {
        let (r, commands) = jittered_stream(HostConfig::default(), 1);
        let delays = send_delays(&r, &commands);
        assert_eq!(delays.len(), commands.len(), "every command was sent");
        assert!(
            delays[3..].iter().all(|d| *d < ms(1)),
            "a command waited for a frame slot: {delays:?}"
        );
        assert_eq!(
            r.pulses_sent().last().unwrap().1,
            commands.last().unwrap().1
        );
        // at a send rate equal to the command rate, the burst leaves a wait behind that
        // the stream never drains (why the default is twice the command rate)
        let slow = HostConfig {
            send_period: ms(20),
            ..HostConfig::default()
        };
        let (r, commands) = jittered_stream(slow, 1);
        let delays = send_delays(&r, &commands);
        let waited = delays.iter().filter(|d| **d >= ms(1)).count();
        assert!(waited > delays.len() / 2, "{waited} of {}", delays.len());
    }

    #[test]
    fn a_stream_at_the_velocity_limit_moves_at_the_limit_without_waiting() {
        // 1000 ticks/s: 20 ticks a servo frame, and the planner sends 20-tick steps
        let config = ramping(1000.0);
        let (r, commands) = jittered_stream(config, 20);
        let pulses = r.pulses_sent();
        for w in pulses.windows(2) {
            let dt = (w[1].0 - w[0].0).min(SERVO_FRAME).as_secs_f64();
            for i in 0..SERVOS {
                assert!(
                    f64::from(w[1].1[i].abs_diff(w[0].1[i])) <= 1000.0 * dt + 1.0,
                    "faster than the limit: {w:?}"
                );
            }
        }
        let delays = send_delays(&r, &commands);
        assert!(delays[3..].iter().all(|d| *d < ms(1)), "{delays:?}");
        // commands that came early were cut (the guard judged them), and the rest of a
        // step cut short followed one servo frame later: few extra frames
        let ramped = r.link.stats().ramped;
        assert!(
            ramped > 0 && pulses.len() <= 2 * commands.len(),
            "{} {ramped}",
            pulses.len()
        );
        assert_eq!(pulses.last().unwrap().1, commands.last().unwrap().1);
    }

    #[test]
    fn a_command_replaced_before_any_of_its_frames_went_out_is_counted_superseded() {
        let mut r = Rig::new(HostConfig::default());
        r.run_until(100); // connected
        r.link.command([3000; 4], 1, r.now);
        r.link.command([3010; 4], 2, r.now); // before the link sent 1
        assert_eq!(r.link.stats().superseded, 1);
        r.run_until(200);
        assert_eq!(r.pulses_sent().last().unwrap().1, [3010; 4]);
        // a command whose frame went out was answered: replacing it is no supersession
        r.link.command([3020; 4], 3, r.now);
        r.run_until(300);
        r.link.command([3030; 4], 4, r.now);
        assert_eq!(r.link.stats().superseded, 1);
        assert!(!r.pulses_sent().iter().any(|(_, t)| *t == [3000; 4]));
    }

    #[test]
    fn a_jump_is_ramped_at_the_velocity_limit_from_the_devices_hold_pose() {
        let mut r = Rig::new(ramping(1000.0));
        r.link.command([3944, 2944, 1944, 2325], 1, r.now);
        r.run_until(1500);
        let pulses = r.pulses_sent();
        // starts one step from the hold pose, never more than 20 ticks (1000/s × 20 ms) a frame
        let first = pulses[0].1;
        for i in 0..SERVOS {
            assert!(first[i].abs_diff(HOLD_TICKS[i]) <= 20, "{first:?}");
        }
        for w in pulses.windows(2) {
            let dt = (w[1].0 - w[0].0).as_secs_f64().min(0.02);
            for i in 0..SERVOS {
                assert!(
                    f64::from(w[1].1[i].abs_diff(w[0].1[i])) <= 1000.0 * dt + 1.0,
                    "{w:?}"
                );
            }
        }
        assert_eq!(pulses.last().unwrap().1, [3944, 2944, 1944, 2325]);
        // 1000 ticks at 1000 ticks/s: about a second, 50 frames
        assert!((49..=52).contains(&pulses.len()), "{}", pulses.len());
        assert!(r.link.stats().ramped >= 48);
    }

    #[test]
    fn estop_lives_here_commands_are_dropped_and_after_release_nothing_moves() {
        let mut r = Rig::new(HostConfig::default());
        r.link.command([3000; 4], 1, r.now);
        r.run_until(100);
        r.link.set_estop(true);
        r.run_until(110);
        assert!(matches!(
            r.sent.last(),
            Some((
                _,
                Message::Estop {
                    engaged: Some(StopAction::Hold)
                }
            ))
        ));
        assert_eq!(r.device.state(), DeviceState::Estop);
        let n = r.pulses_sent().len();
        r.link.command([4000; 4], 2, r.now);
        r.run_until(300);
        assert_eq!(
            r.pulses_sent().len(),
            n,
            "a command during the e-stop went out"
        );
        assert!(r
            .events
            .iter()
            .any(|(_, e)| *e == LinkEvent::DroppedInEstop));
        r.link.set_estop(false);
        r.run_until(600);
        assert!(r
            .sent
            .iter()
            .any(|(_, m)| *m == Message::Estop { engaged: None }));
        assert_eq!(
            r.pulses_sent().len(),
            n,
            "something moved after the release without a command"
        );
        assert_eq!(r.device.pulses(), [3000; 4]);
        r.link.command([3100; 4], 3, r.now);
        r.run_until(700);
        assert_eq!(r.device.pulses(), [3100; 4]);
    }

    #[test]
    fn after_a_holding_estop_the_next_command_ramps_from_the_pose_the_device_holds() {
        // The firmware holds what its pins show and drops a command not shown yet
        // (PROTOCOL.md): its STATE under the e-stop says so, and the ramp after the
        // release starts there, not from the dropped command.
        let mut r = Rig::new(ramping(500.0));
        r.link.command(HOLD_TICKS, 1, r.now);
        r.run_until(100);
        r.link.set_estop(true);
        r.run_until(120);
        let sent = r.pulses_sent().last().unwrap().1;
        let held = sent.map(|t| t - 10);
        r.link.received(
            Frame {
                seq: 200,
                msg: Message::State {
                    ack_seq: 0,
                    state: DeviceState::Estop,
                    clamped: false,
                    rx_errors: 0,
                    ticks: held,
                },
            },
            r.now,
        );
        r.link.set_estop(false);
        r.run_until(200);
        let n = r.pulses_sent().len();
        r.link.command(sent.map(|t| t + 1000), 2, r.now);
        r.run_until(260);
        let first = r.pulses_sent()[n].1;
        let step = (500.0 * SERVO_FRAME.as_secs_f64()) as u16;
        assert_eq!(
            first,
            held.map(|t| t + step),
            "must start where the device holds"
        );
    }

    #[test]
    fn a_detaching_estop_stops_the_pulses_and_the_next_command_ramps_from_the_last() {
        let config = HostConfig {
            estop_action: StopAction::Detach,
            ..ramping(500.0)
        };
        let mut r = Rig::new(config);
        r.link.command(HOLD_TICKS, 1, r.now);
        r.run_until(100);
        r.link.set_estop(true);
        r.run_until(120);
        assert_eq!(r.device.pulses(), [0; 4]);
        r.link.set_estop(false);
        r.run_until(200);
        assert_eq!(r.device.state(), DeviceState::Idle);
        let n = r.pulses_sent().len();
        r.link.command([3944, 2944, 2944, 2325], 2, r.now);
        r.run_until(260);
        let first = r.pulses_sent()[n].1;
        assert!(
            first[0].abs_diff(2944) <= 10,
            "{first:?}: must start where the arm was"
        );
    }

    #[test]
    fn unplug_and_replug_reconnects_and_resends_the_newest_ramping_from_where_the_device_is() {
        let mut r = Rig::new(ramping(2000.0));
        r.link.command([3000; 4], 1, r.now);
        r.run_until(200);
        // unplugged: writes fail, opening fails with back-off up to 500 ms
        r.plugged = false;
        r.run_until(1200);
        assert!(!r.link.is_connected());
        let attempts = r
            .events
            .iter()
            .filter(|(_, e)| matches!(e, LinkEvent::Disconnected { .. }))
            .count();
        assert!((3..=6).contains(&attempts), "{attempts}");
        // meanwhile a new command; then the board is plugged back, reset: hold pose
        r.link.command([3400; 4], 2, r.now);
        r.device = Device::new(DeviceConfig::default());
        r.plugged = true;
        let replug = r.t();
        r.run_until(2500);
        let (connected_at, _) = r
            .events
            .iter()
            .rev()
            .find(|(_, e)| matches!(e, LinkEvent::Connected { .. }))
            .unwrap();
        assert!(
            *connected_at - replug < ms(600),
            "reconnect took {:?}",
            *connected_at - replug
        );
        let after: Vec<_> = r
            .pulses_sent()
            .into_iter()
            .filter(|(t, _)| *t > replug)
            .collect();
        // the first pulses start from the hold pose the device reported, not from 3000
        assert!(
            after[0]
                .1
                .iter()
                .zip(HOLD_TICKS)
                .all(|(a, h)| a.abs_diff(h) <= 40),
            "{:?}",
            after[0]
        );
        assert_eq!(after.last().unwrap().1, [3400; 4]);
    }

    /// Live commands tagged `first..first + n`, every 20 ms, 2 ms on the way (wall
    /// seconds = ms since the rig's start / 1000), each run for 20 ms.
    fn offer_live(r: &mut Rig, first: u32, n: u32) {
        for k in first..first + n {
            let received_s = r.t().as_secs_f64();
            let stamp = Stamp {
                stamp_s: received_s - 0.002,
                received_s,
            };
            assert_eq!(
                r.link.offer([2900 + k as u16; 4], k, stamp, r.now),
                Offered::Now
            );
            let next = r.t().as_millis() as u64 + 20;
            r.run_until(next);
        }
    }

    /// A command stamped `age_s` before now, offered now.
    fn offer_late(r: &mut Rig, ticks: u16, tag: u32, age_s: f64) -> Offered {
        let received_s = r.t().as_secs_f64();
        let stamp = Stamp {
            stamp_s: received_s - age_s,
            received_s,
        };
        r.link.offer([ticks; 4], tag, stamp, r.now)
    }

    #[test]
    fn a_late_burst_is_held_and_only_its_newest_goes_out_once_it_is_over() {
        let mut r = Rig::new(HostConfig::default());
        r.run_until(50);
        offer_live(&mut r, 0, 5);
        let n = r.pulses_sent().len();
        // a 3 s outage: three commands stamped during it arrive 10 ms apart, each 50 ms
        // of stamps newer (catching up with the present)
        let back = r.t();
        assert!(
            matches!(offer_late(&mut r, 3300, 100, 2.0), Offered::Held { age_s } if (age_s - 2.0).abs() < 1e-9)
        );
        r.run_until(back.as_millis() as u64 + 10);
        assert!(matches!(
            offer_late(&mut r, 3310, 101, 1.96),
            Offered::Held { .. }
        ));
        r.run_until(back.as_millis() as u64 + 20);
        assert!(matches!(
            offer_late(&mut r, 3320, 102, 1.92),
            Offered::Held { .. }
        ));
        let last = back + ms(20);
        r.run_until(last.as_millis() as u64 + 49);
        assert_eq!(r.pulses_sent().len(), n, "a held command went out early");
        // HOLD_LATE after the last of the burst, the newest goes
        r.run_until(last.as_millis() as u64 + 60);
        let after: Vec<_> = r.pulses_sent().into_iter().skip(n).collect();
        assert_eq!(after.len(), 1, "{after:?}");
        assert!(
            after[0].0 >= last + command_gate::HOLD_LATE
                && after[0].0 < last + command_gate::HOLD_LATE + ms(2),
            "{after:?}"
        );
        assert_eq!(after[0].1, [3320; 4]);
        assert!(r
            .events
            .iter()
            .any(|(_, e)| *e == LinkEvent::LateApplied { tag: 102 }));
        assert_eq!(r.link.gate().superseded, 2);
        // its latency counts from its arrival: the hold is in it
        let latency = *r.link.stats().latency_us.back().unwrap();
        assert!((50_000.0..52_000.0).contains(&latency), "{latency}");
    }

    /// A link that had live commands 2900-2904 for 100 ms, and now holds a late one
    /// (3300, tagged 100).
    fn holding_a_late_command() -> Rig {
        let mut r = Rig::new(HostConfig::default());
        r.run_until(50);
        offer_live(&mut r, 0, 5);
        let held = offer_late(&mut r, 3300, 100, 2.0);
        assert!(matches!(held, Offered::Held { .. }), "{held:?}");
        r
    }

    #[test]
    fn a_live_command_drops_the_late_one_held() {
        let mut r = holding_a_late_command();
        r.run_until(r.t().as_millis() as u64 + 5);
        offer_live(&mut r, 10, 1);
        r.run_until(r.t().as_millis() as u64 + 200);
        assert_eq!(r.device.pulses(), [2910; 4]);
        assert!(r.pulses_sent().iter().all(|(_, p)| *p != [3300; 4]));
        assert_eq!(r.link.gate().superseded, 1);
    }

    #[test]
    fn the_estop_drops_the_late_command_held_and_late_ones_during_it() {
        let mut r = holding_a_late_command();
        assert!(r.link.set_estop(true));
        assert!(!r.link.set_estop(true), "engaged already");
        assert_eq!(offer_late(&mut r, 3400, 101, 2.0), Offered::DroppedInEstop);
        r.run_until(r.t().as_millis() as u64 + 100);
        // released within the hold: nothing of what came before moves the arm
        assert!(r.link.set_estop(false));
        r.run_until(r.t().as_millis() as u64 + 200);
        assert_eq!(r.device.pulses(), [2904; 4]);
        assert_eq!(
            r.events
                .iter()
                .filter(|(_, e)| *e == LinkEvent::DroppedInEstop)
                .count(),
            1
        );
        assert!(!r.link.estop());
    }

    #[test]
    fn a_silent_device_is_given_up_and_retried() {
        let mut r = Rig::new(HostConfig::default());
        r.device = Device::new(DeviceConfig::default());
        // a device that never answers: every frame lost
        let mut now = r.t0;
        let mut closes = 0;
        while now < r.t0 + ms(9000) {
            match r.link.next(now) {
                Next::Open => r.link.opened(now),
                Next::Close { reason } => {
                    closes += 1;
                    assert!(reason.contains("no answer to HELLO"));
                }
                Next::Send(f) => assert!(matches!(f.msg, Message::Hello { .. })),
                Next::Wait(t) => now = t,
            }
        }
        assert_eq!(closes, 2);
    }

    #[test]
    fn another_protocol_version_is_reported_and_not_driven() {
        let mut r = Rig::new(HostConfig::default());
        assert_eq!(r.link.next(r.now), Next::Open);
        r.link.opened(r.now);
        assert!(matches!(
            r.link.next(r.now),
            Next::Send(Frame {
                msg: Message::Hello { .. },
                ..
            })
        ));
        r.link.received(
            Frame {
                seq: 1,
                msg: Message::HelloAck {
                    version: 1,
                    firmware_major: 1,
                    firmware_minor: 0,
                    servos: 4,
                    watchdog_ms: 500,
                },
            },
            r.now,
        );
        assert!(!r.link.is_connected());
        let ev = r.link.take_events();
        assert_eq!(ev[0], LinkEvent::VersionMismatch { device: 1 });
        assert!(matches!(r.link.next(r.now), Next::Wait(_)));
    }

    fn hello_ack(version: u8) -> Frame {
        Frame {
            seq: 1,
            msg: Message::HelloAck {
                version,
                firmware_major: 1,
                firmware_minor: 0,
                servos: 4,
                watchdog_ms: 500,
            },
        }
    }

    /// A link of `role` past its HELLO, answered by a device speaking `version`.
    fn answered(role: Role, version: u8) -> (HostLink<u32>, Instant) {
        let t0 = Instant::now();
        let mut link = HostLink::new(
            HostConfig {
                role,
                ..HostConfig::default()
            },
            t0,
        );
        assert_eq!(link.next(t0), Next::Open);
        link.opened(t0);
        assert!(matches!(
            link.next(t0),
            Next::Send(Frame {
                msg: Message::Hello {
                    version: PROTOCOL_VERSION
                },
                ..
            })
        ));
        link.received(hello_ack(version), t0);
        (link, t0)
    }

    #[test]
    fn a_follower_link_drives_a_version_2_device_a_leader_link_does_not() {
        let (mut link, t0) = answered(Role::Follower, 2);
        assert!(link.is_connected());
        assert!(matches!(
            link.next(t0),
            Next::Send(Frame {
                msg: Message::Config { .. },
                ..
            })
        ));
        // and asking it to lead is refused: version 2 has no leader role
        assert!(link.set_role(Role::Leader, t0));
        assert!(!link.is_connected());
        assert!(link
            .take_events()
            .contains(&LinkEvent::VersionMismatch { device: 2 }));
        let (mut link, _) = answered(Role::Leader, 2);
        assert!(!link.is_connected());
        let events = link.take_events();
        assert_eq!(events[0], LinkEvent::VersionMismatch { device: 2 });
        assert!(
            matches!(&events[1], LinkEvent::Disconnected { reason, .. } if reason.contains("leader role needs 3"))
        );
        // nor does either link drive a version it does not know
        for role in [Role::Follower, Role::Leader] {
            for version in [1, 4] {
                let (link, _) = answered(role, version);
                assert!(!link.is_connected(), "{role:?} {version}");
            }
        }
    }

    /// A leader link against the device model, the knobs at a quarter, half, three
    /// quarters and the top, the deadman held.
    fn leader_rig() -> Rig {
        let mut r = Rig::new(HostConfig {
            role: Role::Leader,
            ..HostConfig::default()
        });
        r.device.set_leader_input(
            LeaderInput::from_fractions([0.25, 0.5, 0.75, 1.0], true),
            Duration::ZERO,
        );
        r
    }

    #[test]
    fn a_leader_link_asks_for_the_role_then_only_heartbeats_and_takes_the_stream() {
        let mut r = leader_rig();
        // commands and the e-stop are for followers: never sent to a leader
        r.link.command([3000; 4], 1, r.now);
        r.link.set_estop(true);
        r.run_until(1000);
        let kinds: Vec<_> = r.sent.iter().map(|(_, m)| m.msg_type()).collect();
        assert_eq!(
            &kinds[..3],
            &[MsgType::Hello, MsgType::Config, MsgType::Role],
            "{kinds:?}"
        );
        assert!(
            kinds[3..].iter().all(|k| *k == MsgType::Heartbeat),
            "{kinds:?}"
        );
        assert!((9..=11).contains(&(kinds.len() - 3)), "{kinds:?}");
        assert_eq!(r.sent[2].1, Message::Role { role: Role::Leader });
        assert_eq!(r.device.role(), Role::Leader);
        assert_eq!(r.device.pulses(), [0; 4]);
        assert!(r.link.leader_active());
        // a window every 9.6 ms from the ROLE on: about 104 in the second
        let states = r.link.take_leader_states();
        assert!((100..=104).contains(&states.len()), "{}", states.len());
        for (i, s) in states.iter().enumerate() {
            assert_eq!(usize::from(s.window), i);
            assert_eq!(s.fractions(), [0.25, 0.5, 0.75, 1023.0 / 1024.0]);
            assert!(s.deadman);
        }
        assert!(r.link.take_leader_states().is_empty(), "taken");
        let stats = r.link.leader_stats().clone();
        assert_eq!(stats.frames, states.len() as u64);
        assert_eq!((stats.windows_lost, stats.overruns), (0, 0));
        assert_eq!(stats.last.map(|l| l.0), states.last().copied());
        // the STATEs say "leader" (the device's state byte 5)
        assert!(r.events.iter().any(|(_, e)| matches!(
            e,
            LinkEvent::State {
                state: DeviceState::Leader,
                ..
            }
        )));
        assert_eq!(r.device.state(), DeviceState::Leader);
    }

    #[test]
    fn a_leader_that_lost_its_role_is_told_again() {
        // soon, and after more frames than half the sequence numbers (20 s of heartbeats)
        for lost_at in [300, 20_000] {
            leader_loses_its_role_at(lost_at);
        }
    }

    fn leader_loses_its_role_at(lost_at: u64) {
        let mut r = leader_rig();
        r.run_until(lost_at);
        // the board reset behind the port's back: a follower, silent
        r.device = Device::new(DeviceConfig::default());
        r.device
            .set_leader_input(LeaderInput::from_fractions([0.1; 4], false), Duration::ZERO);
        let before = r.link.take_leader_states().len();
        assert!(before > 20);
        r.run_until(lost_at + 400);
        assert_eq!(r.device.role(), Role::Leader, "told again");
        let roles = r
            .sent
            .iter()
            .filter(|(_, m)| matches!(m, Message::Role { .. }))
            .count();
        assert_eq!(roles, 2);
        let after = r.link.take_leader_states();
        assert!(after.len() > 20, "{}", after.len());
        // the new stream counts from 0 again: windows lost are counted, not hidden
        assert_eq!(after[0].window, 0);
        assert!(after.iter().all(|s| !s.deadman && s.adc == [102 * 16; 4]));
        assert!(r.link.leader_active());
        assert_eq!(
            r.link.leader_stats().windows_lost,
            0,
            "a new stream is no gap"
        );
    }

    #[test]
    fn windows_lost_on_the_wire_are_counted() {
        let mut r = leader_rig();
        r.run_until(100);
        r.link.take_leader_states();
        let base = r.link.leader_stats().last.unwrap().0.window;
        let w = |n: u8, seq: u8| Frame {
            seq,
            msg: Message::LeaderState {
                adc: [0; 4],
                deadman: false,
                window: base.wrapping_add(n),
                overruns: n,
            },
        };
        let lost0 = r.link.leader_stats().windows_lost;
        assert!(
            !r.link.received(w(1, 200), r.now),
            "no replan for the stream"
        );
        r.link.received(w(4, 201), r.now);
        r.link.received(w(5, 202), r.now);
        let stats = r.link.leader_stats();
        assert_eq!(stats.windows_lost - lost0, 2);
        assert_eq!(stats.overruns, 5);
        assert_eq!(
            r.link
                .take_leader_states()
                .iter()
                .map(|s| (s.seq, s.window.wrapping_sub(base)))
                .collect::<Vec<_>>(),
            vec![(200, 1), (201, 4), (202, 5)]
        );
    }

    #[test]
    fn a_follower_links_device_that_leads_is_told_to_follow() {
        let mut r = Rig::new(HostConfig::default());
        r.link.command([3000; 4], 1, r.now);
        r.run_until(100);
        assert_eq!(r.device.pulses(), [3000; 4]);
        // something made the device a leader (line noise that passed the CRC)
        r.device.receive(
            &encode(&Frame {
                seq: 99,
                msg: Message::Role { role: Role::Leader },
            }),
            r.t(),
        );
        r.device.take_output();
        r.run_until(400);
        assert_eq!(r.device.role(), Role::Follower);
        assert!(r.sent.iter().any(|(_, m)| *m
            == Message::Role {
                role: Role::Follower
            }));
        // its LEADER_STATEs are not queued for a follower
        assert!(r.link.take_leader_states().is_empty());
        assert!(!r.link.leader_active());
        // idle after the role: the next command ramps from where it was
        r.link.command([3100; 4], 2, r.now);
        r.run_until(500);
        assert_eq!(r.device.pulses(), [3100; 4]);
    }

    #[test]
    fn the_role_can_change_on_an_open_link() {
        let mut r = Rig::new(HostConfig::default());
        r.run_until(100);
        assert!(!r.link.leader_active());
        r.device
            .set_leader_input(LeaderInput::from_fractions([0.5; 4], true), r.t());
        assert!(r.link.set_role(Role::Leader, r.now));
        assert!(!r.link.set_role(Role::Leader, r.now), "no change");
        r.run_until(300);
        assert!(r.link.leader_active());
        assert_eq!(r.device.state(), DeviceState::Leader);
        assert!(r.link.take_leader_states().len() > 15);
        assert!(r.link.set_role(Role::Follower, r.now));
        r.run_until(400);
        assert_eq!(r.device.state(), DeviceState::Idle);
        assert!(!r.link.leader_active());
        r.link.command([3000; 4], 1, r.now);
        r.run_until(500);
        assert_eq!(r.device.pulses(), [3000; 4]);
    }
}
