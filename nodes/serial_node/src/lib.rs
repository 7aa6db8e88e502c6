#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod core;
pub mod link;
pub mod pty;

/// The `port` value of the physics twin ([`pty::twin_link`]).
pub const TWIN_PORT: &str = "twin";

use crate::core::{angles_to_ticks, parse_servo_list, servo_list_text, ticks_to_angles};
use crate::link::{Link, LinkEvent, LinkSnapshot};
use eezybot_kinematics::{ArmConfig, LeaderCalibration, ServoCalibrations, ServoId};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use futures::{Stream, StreamExt};
use ros_plumbing::burst;
use ros_plumbing::diagnostics::p50_p99;
use ros_plumbing::logging::Throttle;
use ros_plumbing::peers::{Peer, PeerWatch};
use ros_plumbing::{ParamRange, ParamSpec, ParameterValue, Params};
use servo_protocol::device::VirtualArduino;
use servo_protocol::host::Offered;
use servo_protocol::{DeviceState, LeaderState, SERVOS};
use std::future::Future;
use std::time::{Duration, Instant};
use tokio::sync::mpsc::UnboundedReceiver;

/// The node's description and parameters.
pub fn spec() -> ros_plumbing::NodeSpec {
    let int = |name, default, min, max, what| {
        ParamSpec::new(name, ParameterValue::Integer(default), what)
            .range(ParamRange::Integer { min, max })
            .read_only()
    };
    let stop_action = |name, what| {
        ParamSpec::new(name, ParameterValue::String("hold".into()), what)
            .constraints("one of: hold, detach")
            .text_check(|s| match s {
                "hold" | "detach" => Ok(()),
                _ => Err("must be `hold` or `detach`".into()),
            })
            .read_only()
    };
    ros_plumbing::NodeSpec {
        name: "serial_node",
        description: "servo_angles -> the Arduino (servo_control firmware) over a serial port; its replies -> servo_state",
        usage: "",
        params: vec![
            ParamSpec::new(
                "port",
                ParameterValue::String("/dev/ttyACM0".into()),
                "serial device of the Arduino, `mock` for the built-in virtual Arduino, or `twin` for the physics twin running on this host in this domain and namespace (docs/twin.md)",
            )
            .read_only(),
            int("baud", 115_200, 1_200, 4_000_000, "serial speed"),
            ParamSpec::new("send_rate", ParameterValue::Double(100.0), "most SET_PULSES frames a second on average (latest wins; above the command rate, so commands never wait)")
                .range(ParamRange::Double { min: 1.0, max: 500.0 })
                .read_only(),
            int("watchdog_ms", 500, 20, 60_000, "device holds/detaches after this much silence"),
            stop_action("watchdog_action", "`hold` or `detach` on watchdog"),
            stop_action("estop_action", "`hold` (the servos keep their position) or `detach` (the pulses stop, servos go limp) on e-stop"),
            ParamSpec::new("heartbeat_period", ParameterValue::Double(0.1), "seconds of silence before a HEARTBEAT (its STATE reply is servo_state while idle)")
                .range(ParamRange::Double { min: 0.01, max: 10.0 })
                .read_only(),
            ParamSpec::file(
                "arm_config",
                "servo calibration (pulse ranges) and motion limits (the velocity guard) YAML; empty = the shipped config/arm.yaml",
                "empty, or an arm_config YAML file that loads",
                |p| load_calibration(p).map(|_| ()),
            ),
            ParamSpec::new(
                "role",
                ParameterValue::String("follower".into()),
                "`follower`: drives the servos (servo_angles -> the Arduino, servo_state back); `leader`: reads a leader arm's potentiometers and deadman button (firmware 1.1, protocol 3) and publishes leader/joint_states (the follower's joints, by arm_config's leader: calibration) and leader/deadman, with every sample (104 Hz)",
            )
            .constraints("one of: follower, leader")
            .text_check(|s| match s {
                "follower" | "leader" => Ok(()),
                _ => Err("must be `follower` or `leader`".into()),
            })
            .read_only(),
            ParamSpec::new(
                MOCK_STALLED_SERVOS,
                ParameterValue::String(String::new()),
                "simulation, port `mock` only: these servos are stalled (blocked, as by an obstacle): each stays where it was when the stall began and the virtual Arduino reports it there, while its commands are acknowledged as usual; emptied, they move on to their latest command. No effect on a real port (a warning says so)",
            )
            .constraints("empty, or servo names separated by commas: base_servo, shoulder_servo, elbow_servo, gripper_servo")
            .text_check(|s| parse_servo_list(s).map(|_| ())),
            ros_plumbing::diagnostics::diagnostics_period_param(),
        ],
    }
}

/// The parameter that simulates stalled servos in the virtual Arduino.
pub const MOCK_STALLED_SERVOS: &str = "mock_stalled_servos";

/// The servo calibration from the `arm_config` file (empty: the shipped one).
pub fn load_calibration(path: &str) -> Result<ServoCalibrations, String> {
    ArmConfig::load_or_shipped(path)
        .map(|c| c.servos)
        .map_err(|e| e.to_string())
}

/// One event for the loop.
#[derive(Clone, Debug)]
pub enum Input {
    /// A `servo_angles` sample and when it was taken.
    ServoAngles(JointState, Instant),
    /// An `estop` sample.
    Estop(bool),
    /// A sample that could not be read.
    Unreadable(String),
}

/// Where the loop's results go.
pub trait Outputs {
    /// Publish on `servo_state`.
    fn servo_state(&self, msg: JointState);
    /// Publish a `diagnostics` report.
    fn diagnostics(&self, status: DiagnosticStatus);
    /// Publish a leader sample: `leader/joint_states` (`None` when none of its channels
    /// is calibrated) and `leader/deadman`.
    fn leader(&self, joints: Option<JointState>, deadman: bool);
    /// The peer counts of the watched topics ([`watched_topics`]): `servo_angles`
    /// publishers, `servo_state` subscribers.
    fn peer_counts(&self) -> Vec<usize>;
}

/// The topics whose peers serial_node watches, in [`Outputs::peer_counts`]' order.
pub fn watched_topics(servo_angles: &str, servo_state: &str) -> Vec<(String, Peer)> {
    vec![
        (servo_angles.to_string(), Peer::Publisher),
        (servo_state.to_string(), Peer::Subscriber),
    ]
}

/// How often the peer counts are looked at.
const PEER_POLL: Duration = Duration::from_millis(250);

/// Of the inputs that arrived together, the ones to act on, in order: a
/// `servo_angles` sample followed by a newer one is superseded (latest wins), so a
/// burst moves the arm to the newest command only, never through stale ones.
/// Returns the inputs kept and how many were superseded.
pub fn coalesce(batch: Vec<Input>) -> (Vec<Input>, usize) {
    burst::latest_wins(batch, |i| matches!(i, Input::ServoAngles(..)).then_some(()))
}

/// What the node knows about the link, for diagnostics.
#[derive(Debug, Default)]
pub struct LinkStatus {
    connected: Option<(u8, u8)>,
    ever_connected: bool,
    last_disconnect: Option<String>,
    device_state: Option<DeviceState>,
    clamped: bool,
    device_rx_errors: Option<u8>,
    acked: u64,
    garbage: u64,
    reconnects: u64,
    last_rtt: Option<Duration>,
    rejected_inputs: u64,
    superseded_inputs: u64,
    dropped_in_estop: u64,
    /// when the newest servo_angles was handed to the link
    last_command: Option<Instant>,
    last_rejection: Option<String>,
    /// the settings the device was given, shown with its state: the device's
    /// watchdog (`500 ms, hold`) and what the e-stop does
    pub settings: Vec<(&'static str, String)>,
    /// the servos `mock_stalled_servos` names (empty: none) and whether the virtual
    /// Arduino simulates their stall (false: a real port, where it has no effect)
    pub simulated_stall: (String, bool),
    /// the leader role's latest sample: deadman held, joints calibrated, overruns, and
    /// its readings in 10-bit ADC counts (what the `leader:` calibration is written in)
    pub leader: Option<(bool, bool, u8, [f64; 4])>,
}

fn time_s(t: Time) -> f64 {
    t.to_nanos() as f64 * 1e-9
}

impl LinkStatus {
    /// Update from a link event; returns the `servo_state` to publish, if any.
    pub fn on_event(&mut self, event: LinkEvent, cal: &ServoCalibrations) -> Option<JointState> {
        match event {
            LinkEvent::Connected { firmware } => {
                log::info!(
                    "device answered: servo_control firmware {}.{}",
                    firmware.0,
                    firmware.1
                );
                if self.ever_connected {
                    self.reconnects += 1;
                }
                self.ever_connected = true;
                self.connected = Some(firmware);
                None
            }
            LinkEvent::Disconnected { reason, retry_in } => {
                if self.connected.is_some()
                    || self.last_disconnect.as_deref() != Some(reason.as_str())
                {
                    log::warn!(
                        "serial link down: {reason}; retrying in {:.2} s",
                        retry_in.as_secs_f64()
                    );
                }
                self.connected = None;
                self.device_state = None;
                self.last_disconnect = Some(reason);
                None
            }
            LinkEvent::VersionMismatch { device } => {
                log::error!("the device speaks protocol version {device}; flash firmware/servo_control of this release");
                None
            }
            LinkEvent::Garbage { error } => {
                self.garbage += 1;
                log::debug!("ignored bytes from the device: {error}");
                None
            }
            LinkEvent::DroppedInEstop => {
                self.dropped_in_estop += 1;
                None
            }
            LinkEvent::LateApplied { tag } => {
                log::debug!(
                    "applying the newest late servo_angles (stamped {:.3} s ago)",
                    time_s(Time::now()) - time_s(tag)
                );
                None
            }
            LinkEvent::State {
                state,
                clamped,
                rx_errors,
                ticks,
                answered,
                ..
            } => {
                if self.device_state != Some(state) {
                    match state {
                        DeviceState::WatchdogHold | DeviceState::WatchdogDetached => {
                            log::warn!("device watchdog fired: {}", state.name())
                        }
                        _ => log::info!("device state: {}", state.name()),
                    }
                }
                if clamped && !self.clamped {
                    log::warn!(
                        "the device clamped a command to its own limits (firmware config.h)"
                    );
                }
                self.device_state = Some(state);
                self.clamped = clamped;
                self.device_rx_errors = Some(rx_errors);
                let stamp = match answered {
                    Some((stamp, rtt)) => {
                        self.acked += 1;
                        self.last_rtt = Some(rtt);
                        stamp
                    }
                    // a heartbeat's or the watchdog's report: published too, stamped now,
                    // so servo_state is a steady stream (every reply while moving, one a
                    // heartbeat_period when idle), as joint_state_broadcaster's is
                    None => Time::now(),
                };
                Some(JointState {
                    header: Header {
                        stamp,
                        frame_id: String::new(),
                    },
                    name: ServoId::ALL.iter().map(|s| s.name().to_string()).collect(),
                    position: ticks_to_angles(cal, &ticks).to_vec(),
                    velocity: vec![],
                    effort: vec![],
                })
            }
        }
    }

    /// The diagnostics entry at `now`; `link` holds the link's counters and e-stop.
    pub fn diagnostic_status(
        &self,
        name: &str,
        port: &str,
        link: &LinkSnapshot,
        now: Instant,
    ) -> DiagnosticStatus {
        let sent = &link.sent;
        let (level, message) = match (&self.connected, self.device_state) {
            (None, _) => (
                DiagnosticStatus::ERROR,
                format!(
                    "not connected: {}",
                    self.last_disconnect.as_deref().unwrap_or("connecting")
                ),
            ),
            (
                Some(_),
                Some(
                    s @ (DeviceState::WatchdogHold
                    | DeviceState::WatchdogDetached
                    | DeviceState::Estop),
                ),
            ) => (DiagnosticStatus::WARN, format!("device {}", s.name())),
            (Some(_), _) if link.estop => (DiagnosticStatus::WARN, "e-stop engaged".to_string()),
            (Some(_), _) if self.last_rejection.is_some() => (
                DiagnosticStatus::WARN,
                format!(
                    "servo_angles rejected: {}",
                    self.last_rejection.as_deref().unwrap_or_default()
                ),
            ),
            (Some(_), s) => (
                DiagnosticStatus::OK,
                format!(
                    "connected, device {}{}",
                    s.map(|s| s.name()).unwrap_or("idle"),
                    match &self.simulated_stall {
                        (servos, true) if !servos.is_empty() =>
                            format!(" (simulated stall: {servos})"),
                        _ => String::new(),
                    }
                ),
            ),
        };
        let mut values = vec![
            ("port", port.to_string()),
            (
                "connection",
                if self.connected.is_some() {
                    "connected".into()
                } else {
                    "disconnected".into()
                },
            ),
            (
                "device_state",
                self.device_state
                    .map(|s| s.name().to_string())
                    .unwrap_or_default(),
            ),
            ("frames_sent", sent.sent.to_string()),
            ("frames_acknowledged", self.acked.to_string()),
            (
                "frames_rejected_by_device",
                self.device_rx_errors
                    .map(|n| n.to_string())
                    .unwrap_or_default(),
            ),
            ("garbage_from_device", self.garbage.to_string()),
            ("reconnects", self.reconnects.to_string()),
            (
                "last_rtt_ms",
                self.last_rtt
                    .map(|d| format!("{:.3}", d.as_secs_f64() * 1e3))
                    .unwrap_or_default(),
            ),
            ("clamped_by_device", self.clamped.to_string()),
            ("inputs_rejected", self.rejected_inputs.to_string()),
            (
                "inputs_superseded",
                (self.superseded_inputs + link.gate.superseded + sent.superseded).to_string(),
            ),
            ("inputs_dropped_in_estop", self.dropped_in_estop.to_string()),
            ("frames_ramped_by_velocity_limit", sent.ramped.to_string()),
            (
                "last_servo_angles_s_ago",
                self.last_command
                    .map(|t| format!("{:.3}", now.saturating_duration_since(t).as_secs_f64()))
                    .unwrap_or_default(),
            ),
            ("estop", link.estop.to_string()),
        ];
        values.extend(self.settings.iter().map(|(k, v)| (*k, v.clone())));
        match &self.simulated_stall {
            (servos, _) if servos.is_empty() => {}
            (servos, true) => values.push((MOCK_STALLED_SERVOS, servos.clone())),
            (servos, false) => values.push((
                MOCK_STALLED_SERVOS,
                format!("{servos} (no effect: not the virtual Arduino)"),
            )),
        }
        if let Some((a, b)) = self.connected {
            values.push(("firmware", format!("{a}.{b}")));
        }
        if let Some((deadman, calibrated, overruns, counts)) = self.leader {
            values.push((
                "leader_counts",
                counts
                    .iter()
                    .map(|c| format!("{c:.1}"))
                    .collect::<Vec<_>>()
                    .join(" "),
            ));
            values.push((
                "leader_deadman",
                if deadman { "held" } else { "released" }.into(),
            ));
            values.push((
                "leader_joints",
                if calibrated {
                    "published".into()
                } else {
                    "not calibrated (arm_config has no leader: section)".into()
                },
            ));
            values.push(("leader_overruns", overruns.to_string()));
        }
        if let Some(d) = &self.last_disconnect {
            values.push(("last_disconnect", d.clone()));
        }
        if let Some(r) = &self.last_rejection {
            values.push(("last_rejection", r.clone()));
        }
        values.extend(p50_p99(
            sent.latency_us.iter().copied(),
            ["send_latency_us_p50", "send_latency_us_p99"],
        ));
        ros_plumbing::diagnostics::status(level, name, port, &message, &values)
    }
}

/// What the node's handlers ([`Node`]) work with: the link, the outputs, the
/// parameters and the names in its diagnostics.
pub struct Io<'a, O> {
    /// the serial link
    pub link: &'a Link,
    /// where results go
    pub outputs: &'a O,
    /// the node's parameters
    pub params: Params,
    /// the diagnostics entry's name
    pub diag_name: String,
    /// the port, as the diagnostics show it
    pub port_name: String,
    /// watches the topics of [`watched_topics`]
    pub peers: PeerWatch,
    /// the in-process virtual Arduino the link talks to (`port:=mock`), whose
    /// simulated stalls follow `mock_stalled_servos`; `None` for a real port
    pub mock: Option<VirtualArduino>,
}

/// What [`run`] works with: the handlers' [`Io`], and the sources of the loop.
pub struct Handles<'a, I, O, S> {
    /// for the handlers
    pub io: Io<'a, O>,
    /// `servo_angles` and `estop` samples
    pub inputs: I,
    /// the link's events
    pub events: UnboundedReceiver<LinkEvent>,
    /// a leader's samples (the leader role; `None`: a follower)
    pub leader: Option<UnboundedReceiver<LeaderState>>,
    /// resolves when the node is to stop
    pub shutdown: S,
}

/// What woke the loop.
enum Event {
    Report,
    PeerPoll,
    /// a parameter was set (applied before every event, this one included)
    Params,
    Link(LinkEvent),
    Leader(LeaderState),
    /// the inputs waiting: the first and those right behind it
    Inputs(Vec<Input>),
}

/// The loop: runs until `shutdown` resolves or `inputs` ends. Each input, link event
/// and timer goes to one handler of [`Node`].
pub async fn run<O: Outputs>(
    h: Handles<'_, impl Stream<Item = Input>, O, impl Future<Output = ()>>,
) {
    let Handles {
        io,
        inputs,
        mut events,
        leader,
        shutdown,
    } = h;
    let (has_leader, mut leader) = match leader {
        Some(rx) => (true, rx),
        None => (false, tokio::sync::mpsc::unbounded_channel().1),
    };
    let period = ros_plumbing::diagnostics::diagnostics_period;
    let params = io.params.clone();
    let mut ticker = tokio::time::interval(period(&params));
    let mut param_changes = params.subscribe();
    let mut peer_poll = tokio::time::interval(PEER_POLL);
    peer_poll.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut node = Node::new(io);
    tokio::pin!(inputs);
    tokio::pin!(shutdown);
    loop {
        let event = tokio::select! {
            _ = &mut shutdown => break,
            _ = ticker.tick() => Event::Report,
            _ = peer_poll.tick() => Event::PeerPoll,
            Ok(()) = param_changes.changed() => Event::Params,
            Some(event) = events.recv() => Event::Link(event),
            Some(sample) = leader.recv(), if has_leader => Event::Leader(sample),
            // a burst (DDS repairing what a network outage held back) moves the arm to
            // its newest command only; a lone command goes at once
            input = inputs.next() => match input {
                Some(first) => Event::Inputs(burst::take_burst(first, &mut inputs)),
                None => break,
            },
        };
        // The parameters as they are now, before the event: a set answered before the
        // event's cause was sent (the calibration wizard's arm_config, then its test
        // move) is in the store already, whichever branch select! picked.
        if param_changes.has_changed().unwrap_or(false) || matches!(event, Event::Params) {
            param_changes.borrow_and_update();
            node.on_params();
            ticker = tokio::time::interval(period(&params));
        }
        node.on_loop_event(event);
    }
}

/// The node's state between inputs, and a handler for each kind of input.
pub struct Node<'a, O> {
    io: Io<'a, O>,
    status: LinkStatus,
    cal: ServoCalibrations,
    /// the leader role's potentiometer calibration (`leader:` of arm_config) and the
    /// claw's opening (rad)
    leader: (Option<LeaderCalibration>, f64),
    complaints: Throttle,
    /// the servos stalled in the virtual Arduino (`mock_stalled_servos`), as applied
    stalled: [bool; SERVOS],
}

impl<'a, O: Outputs> Node<'a, O> {
    /// Load the calibration and motion limits (`arm_config`) and give the link its
    /// velocity limits.
    pub fn new(io: Io<'a, O>) -> Self {
        let params = &io.params;
        // loaded again whenever the parameter is set, by the parameter services (off the
        // loop): the loop only applies what was loaded
        if let Err(e) = params.load_with("arm_config", |path| {
            ArmConfig::load_or_shipped(path)
                .map(|c| std::sync::Arc::new(c) as ros_plumbing::params::Loaded)
                .map_err(|e| e.to_string())
        }) {
            log::error!("arm_config: {e}");
        }
        let config = params
            .loaded::<ArmConfig>("arm_config")
            .map(|c| (*c).clone())
            .unwrap_or_default();
        io.link
            .set_velocity_limits(config.motion.ticks_per_s(&config.servos));
        let setting = |name: &str| params.string(name).unwrap_or_else(|| "hold".into());
        let status = LinkStatus {
            settings: vec![
                (
                    "device_watchdog",
                    format!(
                        "{} ms, {}",
                        params.i64("watchdog_ms").unwrap_or(500),
                        setting("watchdog_action")
                    ),
                ),
                ("estop_action", setting("estop_action")),
            ],
            ..LinkStatus::default()
        };
        let mut node = Node {
            io,
            status,
            cal: config.servos,
            leader: (config.leader, config.geometry.gripper_open_rad),
            complaints: Throttle::default(),
            stalled: [false; SERVOS],
        };
        node.apply_stall();
        node
    }

    /// Hand `mock_stalled_servos` to the virtual Arduino if it changed (a real port
    /// cannot simulate a stall: a warning says it has no effect).
    fn apply_stall(&mut self) {
        let text = self
            .io
            .params
            .string(MOCK_STALLED_SERVOS)
            .unwrap_or_default();
        // checked by the parameter's spec; a value that does not parse changes nothing
        let Ok(stalled) = parse_servo_list(&text) else {
            return;
        };
        if stalled == self.stalled {
            return;
        }
        self.stalled = stalled;
        let names = servo_list_text(&stalled);
        self.status.simulated_stall = (names.clone(), self.io.mock.is_some());
        match &self.io.mock {
            Some(device) => {
                device.set_stalled(stalled);
                if names.is_empty() {
                    log::info!("virtual Arduino: no servo stalled any more");
                } else {
                    log::warn!(
                        "virtual Arduino: simulating a stall of {names}: they stay where they are, whatever they are commanded"
                    );
                }
            }
            None if names.is_empty() => {}
            None => log::warn!(
                "{MOCK_STALLED_SERVOS} ({names}) has no effect: port `{}` is not the virtual Arduino (`mock`)",
                self.io.port_name
            ),
        }
        self.report();
    }

    /// Publish the diagnostics entry now.
    pub fn report(&self) {
        let now = Instant::now();
        let snapshot = self.io.link.snapshot();
        let mut s =
            self.status
                .diagnostic_status(&self.io.diag_name, &self.io.port_name, &snapshot, now);
        self.io.peers.annotate(&mut s, now);
        self.io.outputs.diagnostics(s);
    }

    /// Look at the peer counts; log and report a change.
    pub fn on_peer_poll(&mut self) {
        let changes = self
            .io
            .peers
            .update(&self.io.outputs.peer_counts(), Instant::now());
        changes.iter().for_each(|c| c.log());
        if !changes.is_empty() {
            self.report();
        }
    }

    /// What woke the loop, to its handler (the parameters synced already).
    fn on_loop_event(&mut self, event: Event) {
        match event {
            Event::Report => self.report(),
            Event::PeerPoll => self.on_peer_poll(),
            Event::Params => {}
            Event::Link(event) => self.on_event(event),
            Event::Leader(sample) => self.on_leader_state(&sample),
            Event::Inputs(burst) => {
                for input in self.coalesce(burst) {
                    match input {
                        Input::ServoAngles(msg, received) => self.on_servo_angles(&msg, received),
                        Input::Estop(engaged) => self.on_estop(engaged),
                        Input::Unreadable(e) => self.on_unreadable(&e),
                    }
                }
            }
        }
    }

    /// The parameters changed: load `arm_config` again (the servos' calibration, motion
    /// limits and a leader's calibration; the previous ones kept if it does not load),
    /// and apply `mock_stalled_servos`.
    pub fn on_params(&mut self) {
        self.apply_stall();
        match self
            .io
            .params
            .loaded::<ArmConfig>("arm_config")
            .ok_or("it did not load")
        {
            Ok(c) => {
                self.cal = c.servos;
                self.io
                    .link
                    .set_velocity_limits(c.motion.ticks_per_s(&self.cal));
                // a leader's potentiometer calibration too (the wizard saves it live)
                self.leader = (c.leader, c.geometry.gripper_open_rad);
            }
            Err(e) => log::error!(
                "keeping the previous calibration, motion limits and leader calibration: {e}"
            ),
        }
    }

    /// An event of the link: publish the `servo_state` it brings, if any.
    pub fn on_event(&mut self, event: LinkEvent) {
        if let Some(msg) = self.status.on_event(event, &self.cal) {
            // a leader drives no servos: its reports are not servo_state
            if self.io.params.string("role").as_deref() != Some("leader") {
                self.io.outputs.servo_state(msg);
            }
        }
    }

    /// A leader's sample: its joints (by the leader calibration) and its deadman.
    pub fn on_leader_state(&mut self, sample: &LeaderState) {
        let (cal, open_rad) = &self.leader;
        let joints = cal
            .as_ref()
            .map(|c| crate::core::leader_joints(c, *open_rad, sample.fractions()));
        let msg = joints.filter(|j| !j.is_empty()).map(|j| JointState {
            header: Header {
                stamp: Time::now(),
                frame_id: String::new(),
            },
            name: j.iter().map(|(n, _)| n.to_string()).collect(),
            position: j.iter().map(|(_, v)| *v).collect(),
            velocity: vec![],
            effort: vec![],
        });
        if msg.is_none() {
            if let Some(quiet) = self.complaints.allow("leader/uncalibrated", Instant::now()) {
                log::warn!(
                    "leader: no leader: calibration in arm_config: only leader/deadman is published (calibrate the leader arm with the wizard){}",
                    Throttle::suffix(quiet)
                );
            }
        }
        let scale = f64::from(
            cal.as_ref()
                .map_or(eezybot_kinematics::DEFAULT_ADC_MAX, |c| c.adc_max),
        ) + 1.0;
        let counts = sample.fractions().map(|f| f * scale);
        self.status.leader = Some((sample.deadman, msg.is_some(), sample.overruns, counts));
        self.io.outputs.leader(msg, sample.deadman);
    }

    /// Of inputs that arrived together, the ones to handle, in order: a
    /// `servo_angles` followed by a newer one is superseded ([`coalesce`]) and counted.
    pub fn coalesce(&mut self, batch: Vec<Input>) -> Vec<Input> {
        let (batch, superseded) = coalesce(batch);
        if superseded > 0 {
            log::debug!(
                "{superseded} servo_angles superseded by a newer one that arrived with them"
            );
            self.status.superseded_inputs += superseded as u64;
        }
        batch
    }

    /// A `servo_angles` sample: checked, turned into pulse widths and offered to the
    /// link (late-hold and e-stop are the link's), or rejected with its reason.
    pub fn on_servo_angles(&mut self, msg: &JointState, received: Instant) {
        match angles_to_ticks(&self.cal, msg) {
            Ok(ticks) => {
                self.status.last_rejection = None;
                self.status.last_command = Some(received);
                let stamp = msg.header.stamp;
                if let Some(Offered::Held { age_s }) =
                    self.io.link.offer(ticks, stamp, received, Time::now())
                {
                    log::debug!(
                        "a late servo_angles (stamped {age_s:.3} s ago) held back for a newer one"
                    );
                }
            }
            Err(r) => {
                let kind = format!("{:?}", std::mem::discriminant(&r));
                if let Some(quiet) = self.complaints.allow(&kind, Instant::now()) {
                    log::warn!("servo_angles rejected: {r}{}", Throttle::suffix(quiet));
                }
                self.status.rejected_inputs += 1;
                let first = self.status.last_rejection.is_none();
                self.status.last_rejection = Some(r.to_string());
                if first {
                    self.report();
                }
            }
        }
    }

    /// An `estop` sample: engage or release the link's e-stop; a change is logged
    /// and reported at once.
    pub fn on_estop(&mut self, engaged: bool) {
        if self.io.link.set_estop(engaged) {
            if engaged {
                log::warn!("emergency stop engaged: the device holds, commands are dropped")
            } else {
                log::info!("emergency stop released: waiting for a new command")
            }
            self.report();
        }
    }

    /// A sample that could not be read: counted and logged.
    pub fn on_unreadable(&mut self, e: &str) {
        self.status.rejected_inputs += 1;
        self.status.last_rejection = Some(format!("unreadable sample: {e}"));
        log::warn!("unreadable sample ignored: {e}");
    }
}
