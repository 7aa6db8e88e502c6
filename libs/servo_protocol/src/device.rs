//! The device side of the protocol, as the firmware implements it, with the servos'
//! motion modelled: the virtual Arduino (`port:=mock`, or the `virtual_arduino` binary
//! behind a pseudo-terminal).
//!
//! [`Device`] is pure (time is passed in); [`VirtualArduino`] wraps it as a
//! `Read + Write` byte stream on the real clock, like a serial port.
//!
//! A simulation feature the firmware does not have: a **stalled servo**
//! ([`Device::set_stalled`]), as when the arm hits an obstacle. Its pulses go on as
//! commanded and the protocol answers as usual, but its horn stays where it was when
//! the stall began, and so does what STATE reports for it; un-stalled, it moves on to
//! its latest command at servo speed. (The real firmware has no position feedback: it
//! reports what it commands.)
//!
//! **The leader role** (protocol version 3) is simulated too: after a ROLE leader the
//! device stops its pulses and streams LEADER_STATE every sampling window
//! ([`LEADER_PERIOD_US`]), with the potentiometers' voltages and the deadman button set
//! from code ([`Device::set_leader_input`], [`VirtualArduino::set_leader_input`]), so a
//! leader host runs without hardware. Each channel is 16 samples of the datasheet's code
//! for the input at the window's end (the firmware averages over the window); the
//! deadman bit is set when the button was held throughout the window, as the firmware's.

use crate::frame::{
    decode, encode, DeviceState, Frame, Message, Role, StopAction, WatchdogAction,
    LEADER_OVERSAMPLING, LEADER_PERIOD_US, PROTOCOL_VERSION, SERVOS,
};
use crate::leader::LeaderInput;
use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// A partial frame older than this is dropped, as the firmware does (`FRAME_GAP_MS`).
pub const FRAME_GAP: Duration = Duration::from_millis(5);

/// Firmware version the virtual device reports (the firmware's own constants).
pub const FIRMWARE_VERSION: (u8, u8) = (1, 1);

/// The leader role's sampling window: a LEADER_STATE every 9.6 ms.
pub const LEADER_PERIOD: Duration = Duration::from_micros(LEADER_PERIOD_US as u64);

/// Servo speed in ticks per second: `deg_per_s` × ticks per degree (0.5 µs ticks, 544–2400 µs over 180°).
const fn ticks_per_s(deg_per_s: f64) -> f64 {
    deg_per_s * (4800.0 - 1088.0) / 180.0
}

/// The firmware's hold pose (`config.h` `HOLD_TICKS`): ROBOT.md's home pose (base 0°,
/// main arm vertical, forearm horizontal: every arm servo at 90°, 1472 µs) with the claw
/// closed (60°, 1163 µs). The device reports it until the first command.
pub const HOLD_TICKS: [u16; SERVOS] = [2944, 2944, 2944, 2325];

/// What the device is configured with (the firmware's `config.h`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviceConfig {
    /// Per channel (min, max) ticks; commands are clamped into them.
    pub limits: [(u16, u16); SERVOS],
    /// The pose it assumes the arm is in at power-up, reported until the first command.
    pub hold: [u16; SERVOS],
    /// Watchdog timeout at power-up (ms).
    pub watchdog_ms: u16,
    /// Watchdog action at power-up.
    pub watchdog_action: WatchdogAction,
    /// Horn speed of each servo (ticks/s): MG995 ≈ 0.2 s per 60°, SG90 ≈ 0.12 s per 60°.
    pub speed_ticks_per_s: [f64; SERVOS],
}

impl Default for DeviceConfig {
    fn default() -> Self {
        DeviceConfig {
            limits: [(1088, 4800); SERVOS],
            hold: HOLD_TICKS,
            watchdog_ms: 500,
            watchdog_action: WatchdogAction::Hold,
            speed_ticks_per_s: [
                ticks_per_s(300.0),
                ticks_per_s(300.0),
                ticks_per_s(300.0),
                ticks_per_s(500.0),
            ],
        }
    }
}

/// The device: protocol, limits, watchdog and servo motion.
#[derive(Clone, Debug)]
pub struct Device {
    config: DeviceConfig,
    watchdog_ms: u16,
    watchdog_action: WatchdogAction,
    state: DeviceState,
    /// Commanded pulses after clamping (0 = none on that channel); the hold pose
    /// before the first command.
    applied: [u16; SERVOS],
    /// Whether pulses go out.
    output: bool,
    /// Modelled horn positions (ticks).
    horn: [f64; SERVOS],
    /// Simulated stalls: a stalled servo's horn does not move.
    stalled: [bool; SERVOS],
    clamped: bool,
    rx_errors: u8,
    last_seq: u8,
    tx_seq: u8,
    last_rx: Duration,
    last_tick: Duration,
    last_byte: Duration,
    rx: Vec<u8>,
    out: Vec<u8>,
    role: Role,
    /// the simulated potentiometers and deadman button
    leader_input: LeaderInput,
    /// leader role: the end of the current sampling window, its number, and whether
    /// the deadman button was released at some moment of it
    window_end: Duration,
    window: u8,
    released_in_window: bool,
}

impl Device {
    /// A device just powered up (idle: no pulses until the first command; the arm is
    /// assumed to be in the hold pose).
    pub fn new(config: DeviceConfig) -> Device {
        Device {
            watchdog_ms: config.watchdog_ms,
            watchdog_action: config.watchdog_action,
            horn: config.hold.map(f64::from),
            config,
            state: DeviceState::Idle,
            applied: config.hold,
            output: false,
            stalled: [false; SERVOS],
            clamped: false,
            rx_errors: 0,
            last_seq: 0,
            tx_seq: 0,
            last_rx: Duration::ZERO,
            last_tick: Duration::ZERO,
            last_byte: Duration::ZERO,
            rx: Vec::new(),
            out: Vec::new(),
            role: Role::Follower,
            leader_input: LeaderInput::default(),
            window_end: Duration::ZERO,
            window: 0,
            released_in_window: true,
        }
    }

    /// The device's role ([`Message::Role`]; a HELLO makes it a follower).
    pub fn role(&self) -> Role {
        self.role
    }

    /// The simulated leader inputs ([`Device::set_leader_input`]).
    pub fn leader_input(&self) -> LeaderInput {
        self.leader_input
    }

    /// Set the simulated potentiometers (A0–A3, millivolts) and deadman button from
    /// `now` on; in the leader role, the windows that ended before `now` are sent with
    /// the inputs before. A release of the deadman button at any moment of a window
    /// clears its deadman bit.
    pub fn set_leader_input(&mut self, input: LeaderInput, now: Duration) {
        self.tick(now);
        if !input.deadman {
            self.released_in_window = true;
        }
        self.leader_input = input;
    }

    /// Current state.
    pub fn state(&self) -> DeviceState {
        self.state
    }

    /// Pulses on the pins (ticks, 0 = none).
    pub fn pulses(&self) -> [u16; SERVOS] {
        if self.output {
            self.applied
        } else {
            [0; SERVOS]
        }
    }

    /// Modelled horn positions (ticks).
    pub fn horn(&self) -> [f64; SERVOS] {
        self.horn
    }

    /// Which servos are stalled ([`Device::set_stalled`]).
    pub fn stalled(&self) -> [bool; SERVOS] {
        self.stalled
    }

    /// Simulate stalled (blocked) servos from `now` on: a servo that becomes stalled
    /// stays where it is now (where STATE reports it: its horn while pulses go out,
    /// else the pose a command would start from), whatever it is commanded; STATE
    /// reports it there, and the protocol is not affected (commands are acknowledged,
    /// pulses go out as commanded). A servo no longer stalled follows its latest
    /// command again at servo speed, from where it stopped (without pulses: as any
    /// idle servo, it is reported at the pose a command would start from).
    pub fn set_stalled(&mut self, stalled: [bool; SERVOS], now: Duration) {
        self.tick(now);
        for (i, &stall) in stalled.iter().enumerate() {
            if stall && !self.stalled[i] && !self.output && self.applied[i] != 0 {
                // no pulses: the servo is at the pose a command would start from
                self.horn[i] = f64::from(self.applied[i]);
            }
        }
        self.stalled = stalled;
    }

    /// Frames dropped so far (wrapping).
    pub fn rx_errors(&self) -> u8 {
        self.rx_errors
    }

    fn reply(&mut self, msg: Message) {
        self.tx_seq = self.tx_seq.wrapping_add(1);
        self.out.extend(encode(&Frame {
            seq: self.tx_seq,
            msg,
        }));
    }

    fn state_msg(&self) -> Message {
        // Where the servos are: the modelled horn while pulses go out (and always for a
        // stalled one: it is where it stopped); without pulses, the pose the next
        // command starts from (the last command, or the hold pose).
        let ticks = std::array::from_fn(|i| {
            if self.output || self.stalled[i] {
                self.horn[i].round() as u16
            } else {
                self.applied[i]
            }
        });
        Message::State {
            ack_seq: self.last_seq,
            state: self.state,
            clamped: self.clamped,
            rx_errors: self.rx_errors,
            ticks,
        }
    }

    /// Bytes from the host, arriving at `now` (time since power-up).
    pub fn receive(&mut self, bytes: &[u8], now: Duration) {
        self.tick(now);
        if !self.rx.is_empty() && now.saturating_sub(self.last_byte) > FRAME_GAP {
            self.rx.clear(); // the rest of that frame is not coming
            self.rx_errors = self.rx_errors.wrapping_add(1);
        }
        self.last_byte = now;
        self.rx.extend_from_slice(bytes);
        loop {
            match decode(&mut self.rx) {
                Ok(None) => break,
                Err(_) => self.rx_errors = self.rx_errors.wrapping_add(1),
                Ok(Some(frame)) => self.handle(frame, now),
            }
        }
    }

    fn handle(&mut self, frame: Frame, now: Duration) {
        self.last_seq = frame.seq;
        match frame.msg {
            Message::Hello { .. } => {
                self.last_rx = now;
                // a new session: a leader becomes a follower again, without pulses
                if self.role == Role::Leader {
                    self.role = Role::Follower;
                    self.state = DeviceState::Idle;
                }
                let (firmware_major, firmware_minor) = FIRMWARE_VERSION;
                self.reply(Message::HelloAck {
                    version: PROTOCOL_VERSION,
                    firmware_major,
                    firmware_minor,
                    servos: SERVOS as u8,
                    watchdog_ms: self.watchdog_ms,
                });
                return;
            }
            Message::SetPulses { ticks } => {
                self.last_rx = now;
                // a leader drives nothing: ignored, and the STATE says why
                if self.state != DeviceState::Estop && self.role == Role::Follower {
                    let mut clamped = false;
                    for (i, t) in ticks.iter().enumerate() {
                        let (lo, hi) = self.config.limits[i];
                        self.applied[i] = if *t == 0 {
                            0
                        } else {
                            clamped |= *t < lo || *t > hi;
                            (*t).clamp(lo, hi)
                        };
                    }
                    if !self.output {
                        // pulses start where the horn is assumed to be: at the target
                        for i in 0..SERVOS {
                            if self.applied[i] != 0 && !self.stalled[i] {
                                self.horn[i] = f64::from(self.applied[i]);
                            }
                        }
                    }
                    self.clamped = clamped;
                    self.output = true;
                    self.state = DeviceState::Running;
                }
            }
            Message::Heartbeat => self.last_rx = now,
            // a leader has no pulses to hold or stop
            Message::Estop { .. } if self.role == Role::Leader => self.last_rx = now,
            Message::Estop { engaged } => {
                self.last_rx = now;
                match engaged {
                    Some(action) => {
                        self.state = DeviceState::Estop;
                        if action == StopAction::Detach {
                            self.output = false;
                        }
                    }
                    // released: holding pulses go on, stopped ones wait for a command
                    None if self.state == DeviceState::Estop => {
                        self.state = if self.output {
                            DeviceState::Running
                        } else {
                            DeviceState::Idle
                        };
                    }
                    None => {}
                }
            }
            Message::Config {
                watchdog_ms,
                action,
            } => {
                self.last_rx = now;
                self.watchdog_ms = watchdog_ms.max(20);
                self.watchdog_action = action;
            }
            Message::Role { role } => {
                self.last_rx = now;
                if role != self.role {
                    self.role = role;
                    match role {
                        Role::Leader => {
                            // the pulses stop; the windows start now
                            self.output = false;
                            self.state = DeviceState::Leader;
                            self.window_end = now + LEADER_PERIOD;
                            self.window = 0;
                            self.released_in_window = !self.leader_input.deadman;
                        }
                        Role::Follower => self.state = DeviceState::Idle,
                    }
                }
            }
            // device-to-host messages are not for a device
            Message::HelloAck { .. } | Message::State { .. } | Message::LeaderState { .. } => {
                self.rx_errors = self.rx_errors.wrapping_add(1);
                return;
            }
        }
        let msg = self.state_msg();
        self.reply(msg);
    }

    /// Let time pass: servo motion and the watchdog.
    pub fn tick(&mut self, now: Duration) {
        let dt = now.saturating_sub(self.last_tick).as_secs_f64();
        self.last_tick = now;
        if self.output {
            for i in 0..SERVOS {
                if self.applied[i] != 0 && !self.stalled[i] {
                    let target = f64::from(self.applied[i]);
                    let step = self.config.speed_ticks_per_s[i] * dt;
                    let d = target - self.horn[i];
                    self.horn[i] = if d.abs() <= step {
                        target
                    } else {
                        self.horn[i] + step * d.signum()
                    };
                }
            }
        }
        if self.state == DeviceState::Running
            && now.saturating_sub(self.last_rx) > Duration::from_millis(self.watchdog_ms.into())
        {
            self.state = match self.watchdog_action {
                WatchdogAction::Hold => DeviceState::WatchdogHold,
                WatchdogAction::Detach => {
                    self.output = false;
                    DeviceState::WatchdogDetached
                }
            };
            let msg = self.state_msg();
            self.reply(msg);
        }
        while self.role == Role::Leader && self.window_end <= now {
            let input = self.leader_input;
            let msg = Message::LeaderState {
                adc: std::array::from_fn(|i| input.code(i) * LEADER_OVERSAMPLING),
                deadman: input.deadman && !self.released_in_window,
                window: self.window,
                overruns: 0,
            };
            self.reply(msg);
            self.window = self.window.wrapping_add(1);
            self.window_end += LEADER_PERIOD;
            self.released_in_window = !input.deadman;
        }
    }

    /// Bytes the device has sent since the last call.
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.out)
    }
}

struct Shared {
    device: Device,
    start: Instant,
    to_host: VecDeque<u8>,
    plugged: bool,
}

/// A [`Device`] on the real clock behind a `Read + Write` byte stream, as a serial
/// port is. Clones share the device (one for a reader thread, one for a writer).
#[derive(Clone)]
pub struct VirtualArduino {
    shared: Arc<(Mutex<Shared>, Condvar)>,
    read_timeout: Duration,
}

impl VirtualArduino {
    /// A device powered up now.
    pub fn new(config: DeviceConfig) -> VirtualArduino {
        VirtualArduino {
            shared: Arc::new((
                Mutex::new(Shared {
                    device: Device::new(config),
                    start: Instant::now(),
                    to_host: VecDeque::new(),
                    plugged: true,
                }),
                Condvar::new(),
            )),
            read_timeout: Duration::from_millis(50),
        }
    }

    /// How long `read` waits for bytes before `TimedOut`.
    pub fn set_read_timeout(&mut self, timeout: Duration) {
        self.read_timeout = timeout;
    }

    /// Simulate pulling the USB cable (false) or plugging it back (true, a fresh power-up).
    pub fn set_plugged(&self, plugged: bool) {
        let (lock, cv) = &*self.shared;
        if let Ok(mut s) = lock.lock() {
            if plugged && !s.plugged {
                // a fresh power-up; a simulated stall is the rig's, not the device's, and
                // the knobs stay where they are: both stay
                let stalled = s.device.stalled();
                let input = s.device.leader_input();
                s.device = Device::new(s.device.config);
                s.start = Instant::now();
                s.device.set_stalled(stalled, Duration::ZERO);
                s.device.set_leader_input(input, Duration::ZERO);
                s.to_host.clear();
            }
            s.plugged = plugged;
        }
        cv.notify_all();
    }

    /// Simulate stalled servos from now on ([`Device::set_stalled`]); kept over a replug.
    pub fn set_stalled(&self, stalled: [bool; SERVOS]) {
        let (lock, cv) = &*self.shared;
        if let Ok(mut s) = lock.lock() {
            let now = s.start.elapsed();
            s.device.set_stalled(stalled, now);
            Self::pump(&mut s);
        }
        cv.notify_all();
    }

    /// Set the simulated leader inputs from now on ([`Device::set_leader_input`]): the
    /// potentiometers' voltages on A0–A3 and the deadman button; they stay over a
    /// replug (they are the knobs, not the board).
    pub fn set_leader_input(&self, input: LeaderInput) {
        let (lock, cv) = &*self.shared;
        if let Ok(mut s) = lock.lock() {
            let now = s.start.elapsed();
            s.device.set_leader_input(input, now);
            Self::pump(&mut s);
        }
        cv.notify_all();
    }

    /// Whether the cable is plugged in.
    pub fn is_plugged(&self) -> bool {
        self.shared.0.lock().map(|s| s.plugged).unwrap_or(false)
    }

    /// Let the device's clock run (watchdog, motion) and collect its output.
    fn pump(s: &mut Shared) {
        let now = s.start.elapsed();
        s.device.tick(now);
        let out = s.device.take_output();
        s.to_host.extend(out);
    }

    /// A snapshot of the device (for tests and diagnostics).
    pub fn device(&self) -> Option<Device> {
        let (lock, _) = &*self.shared;
        lock.lock().ok().map(|mut s| {
            Self::pump(&mut s);
            s.device.clone()
        })
    }
}

fn unplugged() -> io::Error {
    io::Error::new(io::ErrorKind::BrokenPipe, "virtual Arduino unplugged")
}

impl Read for VirtualArduino {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let (lock, cv) = &*self.shared;
        let deadline = Instant::now() + self.read_timeout;
        let mut s = lock
            .lock()
            .map_err(|_| io::Error::other("virtual Arduino poisoned"))?;
        loop {
            if !s.plugged {
                return Err(unplugged());
            }
            Self::pump(&mut s);
            if !s.to_host.is_empty() {
                let n = buf.len().min(s.to_host.len());
                for (dst, src) in buf.iter_mut().zip(s.to_host.drain(..n)) {
                    *dst = src;
                }
                return Ok(n);
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    "no bytes from the virtual Arduino",
                ));
            }
            // wake at least every 5 ms so the watchdog can fire on time
            let wait = (deadline - now).min(Duration::from_millis(5));
            s = cv
                .wait_timeout(s, wait)
                .map_err(|_| io::Error::other("virtual Arduino poisoned"))?
                .0;
        }
    }
}

impl Write for VirtualArduino {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let (lock, cv) = &*self.shared;
        let mut s = lock
            .lock()
            .map_err(|_| io::Error::other("virtual Arduino poisoned"))?;
        if !s.plugged {
            return Err(unplugged());
        }
        let now = s.start.elapsed();
        s.device.receive(buf, now);
        Self::pump(&mut s);
        cv.notify_all();
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    fn states(d: &mut Device) -> Vec<Message> {
        let mut out = d.take_output();
        let mut v = vec![];
        while let Ok(Some(f)) = decode(&mut out) {
            v.push(f.msg);
        }
        v
    }

    fn send(d: &mut Device, seq: u8, msg: Message, now: Duration) {
        d.receive(&encode(&Frame { seq, msg }), now);
    }

    #[test]
    fn clamps_to_its_table_and_says_so() {
        let mut d = Device::new(DeviceConfig::default());
        send(
            &mut d,
            1,
            Message::SetPulses {
                ticks: [100, 3000, 9000, 0],
            },
            ms(0),
        );
        assert_eq!(d.pulses(), [1088, 3000, 4800, 0]);
        match states(&mut d).as_slice() {
            [Message::State {
                ack_seq: 1,
                state: DeviceState::Running,
                clamped: true,
                ..
            }] => {}
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn watchdog_holds_or_detaches_at_the_configured_time() {
        for (action, expect) in [
            (WatchdogAction::Hold, DeviceState::WatchdogHold),
            (WatchdogAction::Detach, DeviceState::WatchdogDetached),
        ] {
            let mut d = Device::new(DeviceConfig::default());
            send(
                &mut d,
                1,
                Message::Config {
                    watchdog_ms: 300,
                    action,
                },
                ms(0),
            );
            send(&mut d, 2, Message::SetPulses { ticks: [2944; 4] }, ms(10));
            states(&mut d);
            d.tick(ms(300));
            assert_eq!(d.state(), DeviceState::Running);
            d.tick(ms(311));
            assert_eq!(d.state(), expect);
            assert!(
                matches!(states(&mut d).as_slice(), [Message::State { state, .. }] if *state == expect)
            );
            assert_eq!(d.pulses() == [0; 4], action == WatchdogAction::Detach);
        }
    }

    #[test]
    fn horn_moves_at_servo_speed() {
        let mut d = Device::new(DeviceConfig::default());
        send(&mut d, 1, Message::SetPulses { ticks: [2944; 4] }, ms(0));
        // 60 degrees in ticks
        let sixty = (4800.0 - 1088.0) / 3.0;
        send(
            &mut d,
            2,
            Message::SetPulses {
                ticks: [2944 + sixty as u16; 4],
            },
            ms(10),
        );
        d.tick(ms(110)); // 0.1 s: MG995 half way, SG90 further
        let h = d.horn();
        assert!((h[0] - (2944.0 + sixty / 2.0)).abs() < 2.0, "{h:?}");
        assert!(h[3] > h[0]);
        d.tick(ms(220));
        assert!((d.horn()[0] - (2944.0 + sixty.floor())).abs() < 1e-9);
    }

    /// A device following a command of 3000 ticks (seq 1, at 0 ms), then e-stopped with
    /// `action` (seq 2, at 1 ms).
    fn estopped_while_running(action: StopAction) -> Device {
        let mut d = Device::new(DeviceConfig::default());
        send(&mut d, 1, Message::SetPulses { ticks: [3000; 4] }, ms(0));
        let estop = Message::Estop {
            engaged: Some(action),
        };
        send(&mut d, 2, estop, ms(1));
        d
    }

    #[test]
    fn estop_ignores_commands_until_released() {
        let mut d = estopped_while_running(StopAction::Hold);
        send(&mut d, 3, Message::SetPulses { ticks: [4000; 4] }, ms(2));
        assert_eq!(d.pulses(), [3000; 4]);
        assert_eq!(d.state(), DeviceState::Estop);
        send(&mut d, 4, Message::Estop { engaged: None }, ms(3));
        assert_eq!(d.state(), DeviceState::Running);
        assert_eq!(d.pulses(), [3000; 4]);
    }

    #[test]
    fn a_detaching_estop_stops_the_pulses_and_a_release_waits_for_a_command() {
        let mut d = estopped_while_running(StopAction::Detach);
        assert_eq!((d.state(), d.pulses()), (DeviceState::Estop, [0; 4]));
        send(&mut d, 3, Message::Estop { engaged: None }, ms(2));
        assert_eq!((d.state(), d.pulses()), (DeviceState::Idle, [0; 4]));
        // it reports the pose a command starts from: the last one
        assert!(matches!(
            states(&mut d).last(),
            Some(Message::State {
                ticks: [3000, 3000, 3000, 3000],
                ..
            })
        ));
        send(&mut d, 4, Message::SetPulses { ticks: [3010; 4] }, ms(3));
        assert_eq!((d.state(), d.pulses()), (DeviceState::Running, [3010; 4]));
    }

    #[test]
    fn before_the_first_command_it_reports_its_hold_pose() {
        let mut d = Device::new(DeviceConfig::default());
        send(&mut d, 1, Message::Heartbeat, ms(0));
        assert_eq!(d.pulses(), [0; 4]);
        assert!(matches!(
            states(&mut d).as_slice(),
            [Message::State { state: DeviceState::Idle, ticks, .. }] if *ticks == HOLD_TICKS
        ));
    }

    #[test]
    fn garbage_is_counted_and_changes_nothing() {
        let mut d = Device::new(DeviceConfig::default());
        send(&mut d, 1, Message::SetPulses { ticks: [3000; 4] }, ms(0));
        let mut bad = encode(&Frame {
            seq: 2,
            msg: Message::SetPulses { ticks: [4000; 4] },
        });
        bad[5] ^= 0x10;
        d.receive(&bad, ms(1));
        d.receive(&[0x00, 0xFF, 0xA5, 0x13], ms(2));
        assert_eq!(d.pulses(), [3000; 4]);
        // the dangling partial frame is dropped after the gap: the next frame works
        send(&mut d, 3, Message::SetPulses { ticks: [3500; 4] }, ms(20));
        assert_eq!(d.pulses(), [3500; 4]);
        assert!(d.rx_errors() >= 1);
    }

    fn reported(d: &mut Device) -> [u16; SERVOS] {
        match states(d).last() {
            Some(Message::State { ticks, .. }) => *ticks,
            other => panic!("no STATE: {other:?}"),
        }
    }

    #[test]
    fn a_stalled_servo_stays_where_it_stopped_and_the_link_does_not_notice() {
        let mut d = Device::new(DeviceConfig::default());
        send(&mut d, 1, Message::SetPulses { ticks: [2944; 4] }, ms(0));
        states(&mut d);
        // the elbow (channel 2) hits an obstacle at 2944 ticks
        d.set_stalled([false, false, true, false], ms(5));
        assert_eq!(d.stalled(), [false, false, true, false]);
        send(&mut d, 2, Message::SetPulses { ticks: [3200; 4] }, ms(10));
        // acknowledged as any command, pulses as commanded
        match states(&mut d).as_slice() {
            [Message::State {
                ack_seq: 2,
                state: DeviceState::Running,
                clamped: false,
                ..
            }] => {}
            other => panic!("{other:?}"),
        }
        assert_eq!(d.pulses(), [3200; 4]);
        d.tick(ms(1000));
        send(&mut d, 3, Message::Heartbeat, ms(1000));
        assert_eq!(reported(&mut d), [3200, 3200, 2944, 3200]);
        assert_eq!(d.horn()[2], 2944.0);
        // un-stalled: it moves on to its latest command at servo speed
        d.set_stalled([false; 4], ms(1000));
        send(&mut d, 4, Message::Heartbeat, ms(1001));
        let elbow = reported(&mut d)[2];
        assert!(elbow < 3200, "jumped to its target: {elbow}");
        d.tick(ms(1500));
        send(&mut d, 5, Message::Heartbeat, ms(1500));
        assert_eq!(reported(&mut d), [3200; 4]);
    }

    #[test]
    fn a_servo_stalled_mid_move_stops_there() {
        let mut d = Device::new(DeviceConfig::default());
        send(&mut d, 1, Message::SetPulses { ticks: [2944; 4] }, ms(0));
        send(&mut d, 2, Message::SetPulses { ticks: [4000; 4] }, ms(10));
        d.set_stalled([true, false, false, false], ms(60)); // 50 ms into the move
        let stopped = d.horn()[0];
        assert!(stopped > 2944.0 && stopped < 4000.0, "{stopped}");
        d.tick(ms(2000));
        assert_eq!(d.horn()[0], stopped);
        assert_eq!(d.horn()[1], 4000.0);
        states(&mut d);
        send(&mut d, 3, Message::Heartbeat, ms(2000));
        assert_eq!(reported(&mut d)[0], stopped.round() as u16);
    }

    #[test]
    fn a_stall_holds_without_pulses_too() {
        // before the first command the arm is assumed in the hold pose: stalled there, the
        // first command moves the others only
        let mut d = Device::new(DeviceConfig::default());
        d.set_stalled([false, true, false, false], ms(0));
        send(&mut d, 1, Message::SetPulses { ticks: [3000; 4] }, ms(1));
        assert_eq!(reported(&mut d), [3000, HOLD_TICKS[1], 3000, 3000]);
        // a detaching e-stop: the stalled servo is still reported where it is
        let estop = Message::Estop {
            engaged: Some(StopAction::Detach),
        };
        send(&mut d, 2, estop, ms(2));
        assert_eq!(reported(&mut d), [3000, HOLD_TICKS[1], 3000, 3000]);
        // un-stalled without pulses: reported, like the others, at the pose a command
        // starts from
        d.set_stalled([false; 4], ms(3));
        send(&mut d, 3, Message::Heartbeat, ms(4));
        assert_eq!(reported(&mut d), [3000; 4]);
    }

    fn leader_states(msgs: &[Message]) -> Vec<([u16; 4], bool, u8)> {
        msgs.iter()
            .filter_map(|m| match m {
                Message::LeaderState {
                    adc,
                    deadman,
                    window,
                    overruns: 0,
                } => Some((*adc, *deadman, *window)),
                _ => None,
            })
            .collect()
    }

    /// A device that followed a command, then took the leader role at 100 ms.
    fn leading() -> Device {
        let mut d = Device::new(DeviceConfig::default());
        d.set_leader_input(
            LeaderInput {
                millivolts: [0.0, 1000.0, 2500.0, 5000.0],
                deadman: true,
            },
            ms(0),
        );
        send(&mut d, 1, Message::SetPulses { ticks: [3000; 4] }, ms(0));
        states(&mut d);
        send(&mut d, 2, Message::Role { role: Role::Leader }, ms(100));
        d
    }

    #[test]
    fn the_leader_role_stops_the_pulses_and_streams_a_window_every_9_6_ms() {
        let mut d = leading();
        assert_eq!(d.role(), Role::Leader);
        assert_eq!((d.state(), d.pulses()), (DeviceState::Leader, [0; 4]));
        assert!(matches!(
            states(&mut d).as_slice(),
            [Message::State {
                ack_seq: 2,
                state: DeviceState::Leader,
                ticks: [3000, 3000, 3000, 3000],
                ..
            }]
        ));
        // one second: 104 windows, numbered from 0, the datasheet's codes × 16
        d.tick(ms(1100));
        let got = leader_states(&states(&mut d));
        assert_eq!(got.len(), 104);
        assert!(got
            .iter()
            .enumerate()
            .all(
                |(i, (adc, deadman, window))| *adc == [0, 204 * 16, 512 * 16, 1023 * 16]
                    && *deadman
                    && usize::from(*window) == i % 256
            ));
        // the watchdog has nothing to do with a leader
        assert_eq!(d.state(), DeviceState::Leader);
    }

    #[test]
    fn a_leader_ignores_commands_and_the_estop_and_a_hello_ends_the_role() {
        let mut d = leading();
        states(&mut d);
        send(&mut d, 3, Message::SetPulses { ticks: [4000; 4] }, ms(101));
        send(
            &mut d,
            4,
            Message::Estop {
                engaged: Some(StopAction::Hold),
            },
            ms(102),
        );
        // taking the role it has changes nothing: the windows go on
        send(&mut d, 5, Message::Role { role: Role::Leader }, ms(103));
        let replies = states(&mut d);
        assert_eq!(replies.len(), 3);
        assert!(replies.iter().all(|m| matches!(
            m,
            Message::State {
                state: DeviceState::Leader,
                ticks: [3000, 3000, 3000, 3000],
                ..
            }
        )));
        assert_eq!(d.pulses(), [0; 4]);
        d.tick(ms(120));
        assert_eq!(
            leader_states(&states(&mut d))
                .iter()
                .map(|s| s.2)
                .collect::<Vec<_>>(),
            vec![0, 1]
        );
        send(&mut d, 6, Message::Hello { version: 3 }, ms(121));
        assert_eq!((d.role(), d.state()), (Role::Follower, DeviceState::Idle));
        d.tick(ms(500));
        assert!(leader_states(&states(&mut d)).is_empty());
        // a follower again: the next command ramps from where it was
        send(&mut d, 7, Message::SetPulses { ticks: [3100; 4] }, ms(501));
        assert_eq!(d.pulses(), [3100; 4]);
    }

    #[test]
    fn role_follower_ends_the_stream_and_waits_for_a_command() {
        let mut d = leading();
        d.tick(ms(130));
        send(
            &mut d,
            3,
            Message::Role {
                role: Role::Follower,
            },
            ms(130),
        );
        let msgs = states(&mut d);
        assert_eq!(leader_states(&msgs).len(), 3);
        assert!(matches!(
            msgs.last(),
            Some(Message::State {
                ack_seq: 3,
                state: DeviceState::Idle,
                ..
            })
        ));
        d.tick(ms(300));
        assert!(states(&mut d).is_empty());
        assert_eq!(d.pulses(), [0; 4]);
    }

    #[test]
    fn the_deadman_bit_needs_the_button_held_throughout_the_window() {
        let mut d = leading();
        states(&mut d);
        let held = |deadman| LeaderInput {
            millivolts: [0.0; 4],
            deadman,
        };
        // windows end at 109.6, 119.2, 128.8, 138.4 ms: a release of 1 ms inside the
        // second clears its bit only
        d.set_leader_input(held(false), ms(112));
        d.set_leader_input(held(true), ms(113));
        d.tick(ms(139));
        let bits: Vec<bool> = leader_states(&states(&mut d)).iter().map(|s| s.1).collect();
        assert_eq!(bits, vec![true, false, true, true]);
        // pressed within a window: the next whole one is the first held
        d.set_leader_input(held(false), ms(140));
        d.set_leader_input(held(true), ms(150));
        d.tick(ms(168));
        let bits: Vec<bool> = leader_states(&states(&mut d)).iter().map(|s| s.1).collect();
        assert_eq!(bits, vec![false, false, true]);
    }

    #[test]
    fn a_virtual_leader_streams_what_the_code_sets() {
        let mut v = VirtualArduino::new(DeviceConfig::default());
        v.set_read_timeout(ms(20));
        v.set_leader_input(LeaderInput::from_fractions([0.25, 0.5, 0.75, 0.0], true));
        v.write_all(&encode(&Frame {
            seq: 1,
            msg: Message::Role { role: Role::Leader },
        }))
        .unwrap();
        let mut buf = Vec::new();
        let mut chunk = [0u8; 256];
        let mut leader = vec![];
        let deadline = Instant::now() + Duration::from_secs(2);
        while leader.len() < 3 && Instant::now() < deadline {
            if let Ok(n) = v.read(&mut chunk) {
                buf.extend_from_slice(&chunk[..n]);
            }
            while let Ok(Some(f)) = decode(&mut buf) {
                if let Some(s) = crate::leader::LeaderState::from_frame(&f) {
                    leader.push(s);
                }
            }
        }
        assert!(leader.len() >= 3);
        assert_eq!(leader[0].fractions(), [0.25, 0.5, 0.75, 0.0]);
        assert!(leader[0].deadman);
        // the knobs stay over a replug; the board comes back a follower
        v.set_plugged(false);
        v.set_plugged(true);
        let d = v.device().unwrap();
        assert_eq!(d.role(), Role::Follower);
        assert_eq!(d.leader_input().millivolts[1], 2500.0);
    }

    #[test]
    fn a_stall_outlives_a_replug() {
        let v = VirtualArduino::new(DeviceConfig::default());
        v.set_stalled([false, false, false, true]);
        v.set_plugged(false);
        v.set_plugged(true);
        assert_eq!(
            v.device().map(|d| d.stalled()),
            Some([false, false, false, true])
        );
    }
}
