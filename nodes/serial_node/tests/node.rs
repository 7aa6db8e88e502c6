//! serial_node's loop ([`serial_node::run`]) through fake I/O: samples in, `servo_state`
//! and diagnostics out, against the link and its in-process virtual Arduino. Each wait
//! is bounded; nothing here asserts on timing.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use eezybot_kinematics::ServoId;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use futures::channel::mpsc;
use ros_plumbing::peers::PeerWatch;
use ros_plumbing::{ParameterValue, Params};
use serial_node::core::{angles_to_ticks, ticks_to_angles};
use serial_node::link::{self, Link};
use serial_node::{Handles, Input, Io, Outputs};
use servo_protocol::device::VirtualArduino;
use servo_protocol::host::HostConfig;
use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

#[derive(Default)]
struct Fake {
    servo_state: Mutex<Vec<JointState>>,
    diagnostics: Mutex<Vec<DiagnosticStatus>>,
    leader: Mutex<Vec<(Option<JointState>, bool)>>,
}

impl Outputs for Fake {
    fn servo_state(&self, msg: JointState) {
        self.servo_state.lock().unwrap().push(msg);
    }
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.lock().unwrap().push(status);
    }
    fn leader(&self, joints: Option<JointState>, deadman: bool) {
        self.leader.lock().unwrap().push((joints, deadman));
    }
    fn peer_counts(&self) -> Vec<usize> {
        vec![1, 1]
    }
}

impl Fake {
    /// The newest diagnostics value of `key`.
    fn value(&self, key: &str) -> Option<String> {
        let d = self.diagnostics.lock().unwrap();
        let last = d.last()?;
        last.values
            .iter()
            .find(|kv| kv.key == key)
            .map(|kv| kv.value.clone())
    }
}

/// Wait until `pred` holds. The 30 s only bounds a failure: the link and its virtual
/// Arduino run on real threads, which a busy host (debug build, other test binaries
/// beside this one) can hold up for seconds.
async fn until(what: &str, pred: impl Fn() -> bool) {
    let end = Instant::now() + Duration::from_secs(30);
    while !pred() {
        assert!(Instant::now() < end, "never: {what}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// A servo_angles for these pulse widths, stamped `stamp`.
fn angles(ticks: [u16; 4], stamp: Time) -> JointState {
    let cal = serial_node::load_calibration("").unwrap();
    JointState {
        header: Header {
            stamp,
            frame_id: String::new(),
        },
        name: ServoId::ALL.iter().map(|s| s.name().to_string()).collect(),
        position: ticks_to_angles(&cal, &ticks).to_vec(),
        velocity: vec![],
        effort: vec![],
    }
}

#[tokio::test]
async fn samples_reach_the_device_and_the_estop_and_rejections_show_in_diagnostics() {
    let (tx, events) = tokio::sync::mpsc::unbounded_channel();
    let link = Link::start(
        link::mock_opener(link::virtual_arduino()),
        HostConfig::default(),
        tx,
        None,
    )
    .unwrap();
    let fake = Fake::default();
    let (inputs, samples) = mpsc::unbounded::<Input>();
    let (stop, stopped) = futures::channel::oneshot::channel::<()>();
    let io = io_of(
        &link,
        &fake,
        Params::new(BTreeMap::new()),
        "serial_node: servo link",
        None,
    );
    let handles = Handles {
        io,
        inputs: samples,
        events,
        leader: None,
        shutdown: async move {
            let _ = stopped.await;
        },
    };
    let script = async {
        until("connected", || {
            fake.value("connection").as_deref() == Some("connected")
        })
        .await;
        // a command: the device answers, and its servo_state carries the command's stamp
        let stamp = Time::from_nanos(0);
        let target = [3000, 3000, 2900, 2400];
        let cal = serial_node::load_calibration("").unwrap();
        let cmd = angles(target, stamp);
        assert_eq!(angles_to_ticks(&cal, &cmd), Ok(target));
        inputs
            .unbounded_send(Input::ServoAngles(cmd, Instant::now()))
            .unwrap();
        until("the command's servo_state", || {
            fake.servo_state
                .lock()
                .unwrap()
                .iter()
                .any(|m| m.header.stamp == stamp && angles_to_ticks(&cal, m) == Ok(target))
        })
        .await;
        // the e-stop is reported at once, and a command during it is dropped
        inputs.unbounded_send(Input::Estop(true)).unwrap();
        until("the e-stop in diagnostics", || {
            fake.value("estop").as_deref() == Some("true")
        })
        .await;
        inputs
            .unbounded_send(Input::ServoAngles(
                angles([3100, 3000, 2900, 2400], Time::from_nanos(0)),
                Instant::now(),
            ))
            .unwrap();
        until("the dropped command counted", || {
            fake.value("inputs_dropped_in_estop").as_deref() == Some("1")
        })
        .await;
        // a bad sample: its reason at once
        let mut bad = angles(target, stamp);
        bad.name[0] = "tail_servo".into();
        inputs
            .unbounded_send(Input::ServoAngles(bad, Instant::now()))
            .unwrap();
        until("the rejection in diagnostics", || {
            fake.value("last_rejection")
                .is_some_and(|r| r.contains("unknown servo `tail_servo`"))
        })
        .await;
        inputs.unbounded_send(Input::Estop(false)).unwrap();
        until("the release in diagnostics", || {
            fake.value("estop").as_deref() == Some("false")
        })
        .await;
        assert_eq!(
            link.snapshot().sent.sent,
            1,
            "only the first command went out"
        );
        assert_eq!(fake.value("inputs_rejected").as_deref(), Some("1"));
        stop.send(()).unwrap();
    };
    let ((), ()) = futures::join!(serial_node::run(handles), script);
    link.shutdown();
}

/// The newest servo_state's pulse widths.
/// The node's ends on the mock port: `link`, the fake outputs, `params`, the
/// diagnostics name, and the virtual Arduino if the test drives it.
fn io_of<'a>(
    link: &'a Link,
    fake: &'a Fake,
    params: Params,
    diag_name: &str,
    mock: Option<VirtualArduino>,
) -> Io<'a, Fake> {
    Io {
        link,
        outputs: fake,
        params,
        diag_name: diag_name.into(),
        port_name: "mock".into(),
        peers: PeerWatch::new(&serial_node::watched_topics(
            "/servo_angles",
            "/servo_state",
        )),
        mock,
    }
}

fn last_ticks(fake: &Fake) -> Option<[u16; 4]> {
    let cal = serial_node::load_calibration("").unwrap();
    let msgs = fake.servo_state.lock().unwrap();
    angles_to_ticks(&cal, msgs.last()?).ok()
}

#[tokio::test]
async fn mock_stalled_servos_holds_a_servo_in_the_virtual_arduino_until_cleared() {
    let (tx, events) = tokio::sync::mpsc::unbounded_channel();
    let device = link::virtual_arduino();
    let link = Link::start(
        link::mock_opener(device.clone()),
        HostConfig::default(),
        tx,
        None,
    )
    .unwrap();
    let fake = Fake::default();
    let (inputs, samples) = mpsc::unbounded::<Input>();
    let (stop, stopped) = futures::channel::oneshot::channel::<()>();
    let params = Params::new(BTreeMap::from([(
        serial_node::MOCK_STALLED_SERVOS.to_string(),
        ParameterValue::String(String::new()),
    )]));
    let io = io_of(
        &link,
        &fake,
        params.clone(),
        "serial_node: servo link",
        Some(device.clone()),
    );
    let handles = Handles {
        io,
        inputs: samples,
        events,
        leader: None,
        shutdown: async move {
            let _ = stopped.await;
        },
    };
    let send = |ticks| {
        inputs
            .unbounded_send(Input::ServoAngles(
                angles(ticks, Time::now()),
                Instant::now(),
            ))
            .unwrap()
    };
    let script = async {
        until("connected", || {
            fake.value("connection").as_deref() == Some("connected")
        })
        .await;
        let start = [3000, 3000, 3000, 2400];
        send(start);
        until("the first pose", || last_ticks(&fake) == Some(start)).await;
        params.set(
            serial_node::MOCK_STALLED_SERVOS,
            ParameterValue::String("elbow_servo".into()),
        );
        until("the stall in diagnostics", || {
            fake.value("mock_stalled_servos").as_deref() == Some("elbow_servo")
        })
        .await;
        assert_eq!(
            device.device().unwrap().stalled(),
            [false, false, true, false]
        );
        let target = [3200, 3100, 3200, 2500];
        send(target);
        until("the others at the target, the elbow held", || {
            last_ticks(&fake) == Some([3200, 3100, 3000, 2500])
        })
        .await;
        // the link is healthy: the device acknowledged, nothing rejected
        assert_eq!(
            fake.value("frames_rejected_by_device").as_deref(),
            Some("0")
        );
        params.set(
            serial_node::MOCK_STALLED_SERVOS,
            ParameterValue::String(String::new()),
        );
        until("the elbow at its command", || {
            last_ticks(&fake) == Some(target)
        })
        .await;
        assert_eq!(fake.value("mock_stalled_servos"), None);
        stop.send(()).unwrap();
    };
    let ((), ()) = futures::join!(serial_node::run(handles), script);
    link.shutdown();
}

/// The shipped arm config with a leader section: each potentiometer at half scale is
/// the home pose, at three quarters 45° further (the claw: 100 … 900 counts).
fn leader_config(dir: &std::path::Path) -> String {
    let shipped = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/arm.yaml"
    ))
    .unwrap();
    let path = dir.join("arm.yaml");
    std::fs::write(
        &path,
        format!(
            "{shipped}\nleader:\n  adc_max: 1023\n  \
             base: {{ counts_a: 512.0, input_a: 0.0, counts_b: 768.0, input_b: 45.0 }}\n  \
             shoulder: {{ counts_a: 512.0, input_a: 90.0, counts_b: 768.0, input_b: 45.0 }}\n  \
             elbow: {{ counts_a: 512.0, input_a: 0.0, counts_b: 768.0, input_b: -45.0 }}\n  \
             gripper: {{ counts_a: 100.0, input_a: 0.0, counts_b: 900.0, input_b: 1.0 }}\n"
        ),
    )
    .unwrap();
    path.display().to_string()
}

#[tokio::test]
async fn the_leader_role_publishes_the_leaders_joints_and_deadman_and_no_servo_state() {
    use servo_protocol::{LeaderInput, Role};
    let dir = std::env::temp_dir().join(format!("leader-node-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (tx, events) = tokio::sync::mpsc::unbounded_channel();
    let (leader_tx, leader_rx) = tokio::sync::mpsc::unbounded_channel();
    let device = link::virtual_arduino();
    device.set_leader_input(LeaderInput::from_fractions([0.75, 0.5, 0.5, 0.5], true));
    let config = HostConfig {
        role: Role::Leader,
        ..HostConfig::default()
    };
    let link = Link::start(
        link::mock_opener(device.clone()),
        config,
        tx,
        Some(leader_tx),
    )
    .unwrap();
    let fake = Fake::default();
    let (_inputs, samples) = mpsc::unbounded::<Input>();
    let (stop, stopped) = futures::channel::oneshot::channel::<()>();
    let params = Params::new(BTreeMap::from([
        (
            "arm_config".to_string(),
            ParameterValue::String(leader_config(&dir)),
        ),
        ("role".to_string(), ParameterValue::String("leader".into())),
    ]));
    let io = io_of(
        &link,
        &fake,
        params,
        "leader: servo link",
        Some(device.clone()),
    );
    let handles = Handles {
        io,
        inputs: samples,
        events,
        leader: Some(leader_rx),
        shutdown: async move {
            let _ = stopped.await;
        },
    };
    let last = || fake.leader.lock().unwrap().last().cloned();
    let script = async {
        until("a leader sample", || {
            last().is_some_and(|(j, d)| j.is_some() && d)
        })
        .await;
        let (joints, _) = last().unwrap();
        let joints = joints.unwrap();
        let get = |n: &str| joints.position[joints.name.iter().position(|x| x == n).unwrap()];
        // 0.75 of the scale on the base: 45° (within the ADC's one-code truncation)
        assert!(
            (get("base_joint").to_degrees() - 45.0).abs() < 0.1,
            "{joints:?}"
        );
        assert!((get("shoulder_joint").to_degrees() - 90.0).abs() < 0.1);
        assert!((get("elbow_joint").to_degrees() + 90.0).abs() < 0.2);
        device.set_leader_input(LeaderInput::from_fractions([0.75, 0.5, 0.5, 0.5], false));
        until("the deadman released", || last().is_some_and(|(_, d)| !d)).await;
        assert!(
            fake.servo_state.lock().unwrap().is_empty(),
            "a leader published servo_state"
        );
        let _ = stop.send(());
    };
    tokio::join!(serial_node::run(handles), script);
    link.shutdown();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A parameter set before a command was sent applies before it, whichever the loop
/// wakes to first: the calibration wizard sets `arm_config` and then moves the arm
/// through the new calibration. Each round makes both ready before the loop runs
/// again (no await between them), then checks the command was judged by the config
/// set just before it: refused beyond a narrowed base range, taken within the shipped
/// one.
#[tokio::test]
async fn a_command_sent_after_arm_config_was_set_is_judged_by_the_new_config() {
    let dir = std::env::temp_dir().join(format!("arm-config-order-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let shipped = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/arm.yaml"
    ))
    .unwrap();
    let narrowed = shipped.replacen(
        "min_deg: 0.0,  max_deg: 180.0",
        "min_deg: 0.0,  max_deg: 100.0",
        1,
    );
    assert_ne!(narrowed, shipped, "the base's range line");
    let narrow = dir.join("narrow.yaml");
    std::fs::write(&narrow, narrowed).unwrap();
    let narrow = narrow.display().to_string();

    let (tx, events) = tokio::sync::mpsc::unbounded_channel();
    let link = Link::start(
        link::mock_opener(link::virtual_arduino()),
        HostConfig::default(),
        tx,
        None,
    )
    .unwrap();
    let fake = Fake::default();
    let (inputs, samples) = mpsc::unbounded::<Input>();
    let (stop, stopped) = futures::channel::oneshot::channel::<()>();
    let params = Params::new(BTreeMap::new());
    let io = io_of(
        &link,
        &fake,
        params.clone(),
        "serial_node: servo link",
        None,
    );
    let handles = Handles {
        io,
        inputs: samples,
        events,
        leader: None,
        shutdown: async move {
            let _ = stopped.await;
        },
    };
    // the base at 110° (beyond the narrowed 100°), the others where they rest
    let command = |k: i64| JointState {
        header: Header {
            stamp: Time::from_nanos(1_000 + k),
            frame_id: String::new(),
        },
        name: ServoId::ALL.iter().map(|s| s.name().to_string()).collect(),
        position: [110.0f64, 90.0, 90.0, 90.0].map(f64::to_radians).to_vec(),
        velocity: vec![],
        effort: vec![],
    };
    let counter = |key: &str| {
        fake.value(key)
            .and_then(|v| v.parse::<u64>().ok())
            .unwrap_or(0)
    };
    let script = async {
        until("connected", || {
            fake.value("connection").as_deref() == Some("connected")
        })
        .await;
        // the base brought to 110° first, within the shipped range, and its ramp (300°/s
        // from the hold pose's 90°: several frames) finished: a round's refused command
        // must find no frame of an earlier move still going out (a busy host's round
        // took long enough for that ramp to send one mid-round: sent 4, not 3)
        inputs
            .unbounded_send(Input::ServoAngles(command(-1), Instant::now()))
            .unwrap();
        until("the base at 110° (the ramp done)", || {
            fake.servo_state
                .lock()
                .unwrap()
                .last()
                .is_some_and(|m| (m.position[0].to_degrees() - 110.0).abs() < 0.05)
        })
        .await;
        for round in 0..20 {
            let (rejected, sent) = (counter("inputs_rejected"), link.snapshot().sent.sent);
            params.set("arm_config", ParameterValue::String(narrow.clone()));
            inputs
                .unbounded_send(Input::ServoAngles(command(2 * round), Instant::now()))
                .unwrap();
            until("the command refused by the narrowed range", || {
                counter("inputs_rejected") == rejected + 1
            })
            .await;
            assert_eq!(link.snapshot().sent.sent, sent, "round {round}: sent");
            params.set("arm_config", ParameterValue::String(String::new()));
            inputs
                .unbounded_send(Input::ServoAngles(command(2 * round + 1), Instant::now()))
                .unwrap();
            until("the command taken within the shipped range", || {
                link.snapshot().sent.sent > sent
            })
            .await;
            assert_eq!(counter("inputs_rejected"), rejected + 1, "round {round}");
        }
        stop.send(()).unwrap();
    };
    let ((), ()) = futures::join!(serial_node::run(handles), script);
    link.shutdown();
    let _ = std::fs::remove_dir_all(&dir);
}
