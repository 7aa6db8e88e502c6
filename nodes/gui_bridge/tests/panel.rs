//! The panel's core on a fixed clock: events in, effects out, no I/O.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use eezybot_kinematics::ArmJoints;
use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use gui_bridge::desk::Desk;
use gui_bridge::panel::{Clock, Effect, Panel};
use gui_bridge::teleop::Command;
use gui_bridge::web::{ClientRequest, ProgramOp};
use gui_bridge::Input;
use ros_plumbing::feedback::{self, ReasonCode, Refusal};
use serde_json::Value;
use std::time::{Duration, Instant};

fn panel(test: &str) -> Panel {
    let dir = std::env::temp_dir().join(format!("gui_bridge_panel_{test}_{}", std::process::id()));
    let arm = gui_bridge::load_arm("").unwrap();
    Panel::new(arm, 50.0, Desk::new(dir), "gui_bridge")
}

/// `ms` milliseconds after `t0`, on both clocks (the wall clock starts at 1000 s).
fn at(t0: Instant, ms: u64) -> Clock {
    Clock {
        now: t0 + Duration::from_millis(ms),
        wall: Time::new(1000, (ms * 1_000_000) as u32),
    }
}

fn published(effects: &[Effect]) -> Vec<Command> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::Publish { command, .. } => Some(command.clone()),
            _ => None,
        })
        .collect()
}

/// The messages to every browser (`broadcast: true`) or to the requester, as JSON.
fn told(effects: &[Effect], broadcast: bool) -> Vec<Value> {
    effects
        .iter()
        .filter_map(|e| match (e, broadcast) {
            (Effect::Broadcast(m), true) | (Effect::Answer(m), false) => {
                Some(serde_json::from_str(&m.to_text()).unwrap())
            }
            _ => None,
        })
        .collect()
}

fn of_kind<'a>(messages: &'a [Value], t: &str) -> Vec<&'a Value> {
    messages.iter().filter(|m| m["t"] == t).collect()
}

fn target(xyz: [f64; 3]) -> ClientRequest {
    ClientRequest::Target { xyz }
}

/// A target published on `xyz_target`.
fn on_xyz_target(xyz: [f64; 3]) -> Command {
    Command::Target { xyz, line: false }
}

#[test]
fn targets_go_out_at_the_rate_latest_wins_and_the_estop_first() {
    let mut p = panel("rate");
    let t0 = Instant::now();
    let e = p.on_request(target([0.2, 0.0, 0.15]), at(t0, 0));
    assert_eq!(told(&e, false)[0]["t"], "ack");
    assert!(e
        .iter()
        .any(|e| matches!(e, Effect::Snapshot(s) if s.target == [0.2, 0.0, 0.15])));
    assert!(p.publish_due(at(t0, 0).now));
    let e = p.on_tick(at(t0, 0));
    assert_eq!(published(&e), [on_xyz_target([0.2, 0.0, 0.15])]);
    let sent = told(&e, true);
    assert_eq!(sent[0]["t"], "sent");
    assert_eq!(sent[0]["stamp_ns"], 1_000_000_000_000_i64);
    // within the 20 ms of 50/s: the latest of three waits, the e-stop does not
    for y in [0.01, 0.02, 0.03] {
        p.on_request(target([0.2, y, 0.15]), at(t0, 5));
    }
    assert!(!p.publish_due(at(t0, 5).now));
    assert_eq!(p.next_wakeup(at(t0, 5).now), Some(at(t0, 20).now));
    p.on_request(ClientRequest::Estop { on: true }, at(t0, 6));
    assert!(p.publish_due(at(t0, 6).now));
    assert_eq!(published(&p.on_tick(at(t0, 6))), [Command::Estop(true)]);
    assert!(published(&p.on_tick(at(t0, 10))).is_empty());
    assert_eq!(
        published(&p.on_tick(at(t0, 20))),
        [on_xyz_target([0.2, 0.03, 0.15])]
    );
}

#[test]
fn a_refused_request_is_answered_counted_and_sends_nothing() {
    let mut p = panel("refused");
    let t0 = Instant::now();
    let e = p.on_request(target([1.0, 0.0, 0.1]), at(t0, 0));
    let answer = &told(&e, false)[0];
    assert_eq!(answer["t"], "refused");
    assert_eq!(answer["reachable"], false);
    assert!(answer["reason"].as_str().unwrap().contains("out of reach"));
    assert!(e.iter().any(|e| matches!(
        e,
        Effect::Rejected {
            kind: "unreachable",
            ..
        }
    )));
    assert!(!p.publish_due(at(t0, 0).now));
    // a check answers and sends nothing either way
    let e = p.on_request(
        ClientRequest::Check {
            xyz: [0.2, 0.0, 0.15],
        },
        at(t0, 1),
    );
    let answer = &told(&e, false)[0];
    assert_eq!(
        (answer["t"].as_str(), answer["reachable"].as_bool()),
        (Some("check"), Some(true))
    );
    assert!(answer["joints"]["base_joint"].is_f64());
    assert_eq!(p.next_wakeup(at(t0, 1).now), None);
}

/// The panel's diagnostics entry of compute_ik refusing the target stamped `stamp`.
fn refusal_of(stamp: Time) -> DiagnosticArray {
    let refusal = Refusal::new(stamp, ReasonCode::Unreachable, "out of reach", "xyz_target");
    DiagnosticArray {
        header: Header::default(),
        status: vec![ros_plumbing::diagnostics::status(
            DiagnosticStatus::WARN,
            "ik2: inverse kinematics",
            "eezybot_arm",
            "xyz_target rejected",
            &feedback::encode(&refusal),
        )],
    }
}

fn program_messages(effects: &[Effect]) -> Vec<Value> {
    told(effects, true)
        .into_iter()
        .filter(|m| m["t"] == "program")
        .collect()
}

/// `joint_states` with the EezyBot's tool at `xyz`.
fn joint_states_at(xyz: [f64; 3]) -> Input {
    let arm = gui_bridge::load_arm("").unwrap();
    let q = arm.solve_position(&xyz.into(), 0.0).unwrap();
    Input::JointStates(JointState {
        name: ["base_joint", "shoulder_joint", "elbow_joint"]
            .map(String::from)
            .to_vec(),
        position: vec![q.base_rad, q.shoulder_rad, q.elbow_rad],
        ..Default::default()
    })
}

/// Teach `points` (the target moved to each first; no `joint_states` yet, so the target
/// is taught) with their modes, from `t0`; returns the time after.
fn teach(p: &mut Panel, t0: Instant, points: &[([f64; 3], Option<&str>)]) -> u64 {
    let mut ms = 0;
    for (i, (xyz, mode)) in points.iter().enumerate() {
        p.on_request(target(*xyz), at(t0, ms));
        p.on_request(ClientRequest::Program(ProgramOp::Teach), at(t0, ms + 1));
        let mode = ProgramOp::Mode {
            i,
            mode: mode.map(String::from),
        };
        p.on_request(ClientRequest::Program(mode), at(t0, ms + 2));
        ms += 30;
    }
    ms
}

#[test]
fn a_program_sends_each_point_on_its_kinds_topic_in_order_and_an_estop_stops_it() {
    let mut p = panel("kinds");
    let t0 = Instant::now();
    let (a, b, c) = ([0.2, 0.0, 0.15], [0.18, 0.05, 0.12], [0.22, -0.04, 0.18]);
    let mut ms = teach(
        &mut p,
        t0,
        &[(a, None), (b, Some("line")), (c, Some("joint"))],
    );
    let play = ProgramOp::Play { looping: false };
    let mut phases = vec![];
    let mut effects = p.on_request(ClientRequest::Program(play), at(t0, ms));
    let mut sent = vec![];
    for next in [Some(a), Some(b), Some(c), None] {
        ms += 30;
        effects.extend(p.on_tick(at(t0, ms)));
        let published = published(&effects);
        let told = told(&effects, true);
        phases.extend(
            program_messages(&effects)
                .iter()
                .map(|m| m["player"]["phase"].as_str().unwrap_or("").to_string()),
        );
        sent.extend(
            published.into_iter().zip(
                of_kind(&told, "sent")
                    .into_iter()
                    .map(|m| m["topic"].clone()),
            ),
        );
        // the arm arrives: the next point is sent at once, nothing between
        effects = next.map_or_else(Vec::new, |xyz| {
            p.on_input(joint_states_at(xyz), at(t0, ms + 1))
        });
    }
    let line = |xyz| Command::Target { xyz, line: true };
    assert_eq!(
        sent,
        [
            (on_xyz_target(a), Value::from("xyz_target")),
            (line(b), Value::from("xyz_line_target")),
            (on_xyz_target(c), Value::from("xyz_target")),
        ]
    );
    assert!(
        phases
            .iter()
            .all(|ph| ["moving", "dwelling", "finished"].contains(&ph.as_str())),
        "{phases:?}"
    );
    assert_eq!(phases.last().map(String::as_str), Some("finished"));

    // played again: compute_ik's e-stop on the topic stops it
    let play = ProgramOp::Play { looping: true };
    p.on_request(ClientRequest::Program(play), at(t0, ms + 100));
    assert_eq!(published(&p.on_tick(at(t0, ms + 130))), [on_xyz_target(a)]);
    let e = p.on_input(Input::Estop(true), at(t0, ms + 140));
    assert_eq!(of_kind(&told(&e, true), "estop").len(), 1);
    assert_eq!(
        program_messages(&e).last().unwrap()["player"]["phase"],
        "stopped"
    );
    assert!(!p.publish_due(at(t0, ms + 200).now));
}

#[test]
fn compute_iks_refusal_of_the_players_target_stops_it_and_shows_on_the_status() {
    // compute_ik runs as ik2 here (refusal_of), and the panel is told so (ik_node)
    let mut p = panel("refusal").with_node_names(gui_bridge::NodeNames {
        ik: "ik2".into(),
        ..Default::default()
    });
    let t0 = Instant::now();
    p.on_request(ClientRequest::Program(ProgramOp::Teach), at(t0, 0));
    p.on_request(
        ClientRequest::Program(ProgramOp::Play { looping: false }),
        at(t0, 1),
    );
    let clock = at(t0, 2);
    assert_eq!(published(&p.on_tick(clock)).len(), 1);
    // a refusal of another target changes nothing
    let e = p.on_input(Input::Diagnostics(refusal_of(Time::new(999, 0))), at(t0, 3));
    assert!(program_messages(&e)
        .iter()
        .all(|m| m["player"]["phase"] != "failed"));
    let e = p.on_input(Input::Diagnostics(refusal_of(clock.wall)), at(t0, 4));
    let last = program_messages(&e)
        .pop()
        .unwrap_or_else(|| panic!("the desk changed: {e:?}"));
    assert_eq!(last["player"]["phase"], "failed");
    assert_eq!(last["message"], "stopped at point 1: refused: out of reach");
    let status = &told(&p.on_status_tick(at(t0, 5)), true)[0];
    assert_eq!(status["last_rejection"], "out of reach");
    let names: Vec<&str> = status["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["ik2", "state_publisher", "serial_node"]);
    // not heard for 3 s: shown down
    let status = &told(&p.on_status_tick(at(t0, 4000)), true)[0];
    assert_eq!(status["nodes"][0]["up"], false);
}

#[test]
fn joint_states_make_the_live_view_and_a_later_browsers_hello() {
    let mut p = panel("pose");
    let t0 = Instant::now();
    let q = ArmJoints::HOME;
    let js = JointState {
        name: [
            "base_joint",
            "shoulder_joint",
            "elbow_joint",
            "gripper_joint",
        ]
        .map(String::from)
        .to_vec(),
        position: vec![q.base_rad, q.shoulder_rad, q.elbow_rad, 0.2],
        ..Default::default()
    };
    let e = p.on_input(Input::JointStates(js), at(t0, 0));
    let pose = &told(&e, true)[0];
    assert_eq!(pose["t"], "pose");
    assert_eq!(pose["joints"]["shoulder_joint"], q.shoulder_rad);
    assert_eq!(pose["gripper"], 0.2);
    assert!(pose["tool"].as_array().is_some_and(|t| t.len() == 3));
    let Some(Effect::Snapshot(s)) = e.last() else {
        panic!("no snapshot: {e:?}")
    };
    let hello: Value = serde_json::from_str(&s.hello(50.0)).unwrap();
    assert_eq!(&hello["pose"], pose);
    assert_eq!(hello["program"]["t"], "program");
    // a joint_states without the arm's joints shows nothing
    let e = p.on_input(Input::JointStates(JointState::default()), at(t0, 1));
    assert!(told(&e, true).is_empty());
}

#[test]
fn latency_is_measured_on_replies_to_our_own_targets_only() {
    let mut p = panel("latency");
    let t0 = Instant::now();
    p.on_request(target([0.2, 0.0, 0.15]), at(t0, 0));
    p.on_tick(at(t0, 0));
    let reply = |stamp| {
        Input::ServoState(JointState {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            ..Default::default()
        })
    };
    assert!(told(&p.on_input(reply(Time::new(5, 0)), at(t0, 1)), true).is_empty());
    let e = p.on_input(reply(at(t0, 0).wall), at(t0, 2));
    let latency = &told(&e, true)[0];
    assert_eq!(
        (latency["t"].as_str(), latency["ms"].as_f64()),
        (Some("latency"), Some(2.0))
    );
    assert_eq!(latency["n"], 1);
}

#[test]
fn an_unusable_robot_description_is_logged_and_changes_nothing() {
    let mut p = panel("urdf");
    let t0 = Instant::now();
    let e = p.on_input(Input::RobotDescription("<robot".into()), at(t0, 0));
    assert!(
        matches!(e.as_slice(), [Effect::Log(log::Level::Warn, _)]),
        "{e:?}"
    );
    assert!(p.snapshot().urdf.is_none());
    let urdf =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../urdf/jaco.urdf"))
            .unwrap();
    let e = p.on_input(Input::RobotDescription(urdf), at(t0, 1));
    let all = told(&e, true);
    let robot = &of_kind(&all, "robot")[0]["robot"];
    assert_eq!(
        (robot["eezybot"].as_bool(), robot["urdf"].as_str()),
        (Some(false), Some("robot.urdf?rev=1"))
    );
    assert!(p.snapshot().urdf.is_some());
    // no closed form for this arm: a check says so
    let e = p.on_request(
        ClientRequest::Check {
            xyz: [0.2, 0.0, 0.15],
        },
        at(t0, 2),
    );
    assert!(told(&e, false)[0]["reachable"].is_null());
}

/// A chain arm of `n` revolute joints with names of 40 characters.
fn chain_urdf(n: usize) -> String {
    let name = |kind: &str, i: usize| format!("{kind}_{i:0>34}");
    let links: String = (0..=n)
        .map(|i| format!("<link name='{}'/>", name("link", i)))
        .collect();
    let joints: String = (0..n)
        .map(|i| {
            format!(
                "<joint name='{}' type='revolute'><parent link='{}'/><child link='{}'/>\
                 <origin xyz='0 0 0.01'/><axis xyz='0 0 1'/>\
                 <limit lower='-1' upper='1' effort='1' velocity='1'/></joint>",
                name("joint", i),
                name("link", i),
                name("link", i + 1)
            )
        })
        .collect();
    format!("<robot name='chain'>{links}{joints}</robot>")
}

#[test]
fn a_refused_input_is_shown_until_taken_and_the_largest_arm_taken_stays_small_for_the_browsers() {
    use gui_bridge::bounded::MAX_JOINTS;
    let mut p = panel("refused");
    let t0 = Instant::now();
    let refused = Input::Refused {
        topic: "robot_description",
        reason: "16000 joints > 256".into(),
    };
    let e = p.on_input(refused.clone(), at(t0, 0));
    // logged, shown to every browser and in what a browser gets when it connects
    assert!(e
        .iter()
        .any(|x| matches!(x, Effect::Log(log::Level::Warn, t)
        if t.starts_with("robot_description refused: 16000 joints > 256"))));
    let shown = serde_json::json!([{"topic": "robot_description", "reason": "16000 joints > 256"}]);
    assert_eq!(
        of_kind(&told(&e, true), "inputs_refused")[0]["inputs"],
        shown
    );
    let hello: Value = serde_json::from_str(&p.snapshot().hello(50.0)).unwrap();
    assert_eq!(hello["inputs_refused"], shown);
    // the same again changes nothing the page shows
    assert!(told(&p.on_input(refused, at(t0, 1)), true).is_empty());
    // diagnostics: WARN, counted and named
    let web = gui_bridge::web::WebStats::default();
    let status = p.report(
        "gui_bridge: operator panel",
        "http://x/",
        &web,
        at(t0, 2).now,
    );
    let values: std::collections::HashMap<_, _> = status
        .values
        .iter()
        .map(|kv| (kv.key.as_str(), kv.value.as_str()))
        .collect();
    assert_eq!(status.level, DiagnosticStatus::WARN);
    assert!(
        status.message.contains("refused an input"),
        "{}",
        status.message
    );
    assert_eq!(values["inputs_refused"], "2");
    assert_eq!(
        values["last_input_refused"],
        "robot_description: 16000 joints > 256"
    );
    // an arm of the most joints taken: the refusal is over, and the first message of a
    // browser and the live view's pose stay small
    let e = p.on_input(Input::RobotDescription(chain_urdf(MAX_JOINTS)), at(t0, 3));
    let all = told(&e, true);
    assert_eq!(
        of_kind(&all, "inputs_refused")[0]["inputs"],
        serde_json::json!([])
    );
    assert_eq!(
        of_kind(&all, "robot")[0]["robot"]["joints"]
            .as_array()
            .unwrap()
            .len(),
        MAX_JOINTS
    );
    let hello = p.snapshot().hello(50.0);
    let names: Vec<String> = (0..MAX_JOINTS).map(|i| format!("joint_{i:0>34}")).collect();
    let js = JointState {
        position: vec![0.5; names.len()],
        name: names,
        ..JointState::default()
    };
    let e = p.on_input(Input::JointStates(js), at(t0, 4));
    let pose = e
        .iter()
        .find_map(|x| match x {
            Effect::Broadcast(m) if m.to_text().starts_with(r#"{"t":"pose""#) => Some(m.to_text()),
            _ => None,
        })
        .unwrap();
    println!(
        "{MAX_JOINTS} joints: hello {} bytes, pose {} bytes",
        hello.len(),
        pose.len()
    );
    assert!(hello.len() < 100_000, "{}", hello.len());
    assert!(pose.len() < 64 * 1024, "{}", pose.len());
}

/// A `diagnostics` report of the recorder's (a status named `name`) in `state`.
fn recorder_report(name: &str, state: &str, episodes: u64) -> Input {
    use eezybot_msgs::diagnostic_msgs::KeyValue;
    let kv = |k: &str, v: String| KeyValue {
        key: k.into(),
        value: v,
    };
    Input::Diagnostics(DiagnosticArray {
        header: Header::default(),
        status: vec![DiagnosticStatus {
            level: 0,
            name: name.into(),
            message: format!("{state}, {episodes} episodes"),
            hardware_id: "/tmp/ds".into(),
            values: vec![
                kv("state", state.into()),
                kv("episodes", episodes.to_string()),
                kv("episode", episodes.to_string()),
                kv("elapsed_s", "0.0".into()),
            ],
        }],
    })
}

fn record(op: &str, task: Option<&str>) -> ClientRequest {
    let mut m = serde_json::json!({"t": "record", "op": op});
    if let Some(t) = task {
        m["task"] = t.into();
    }
    serde_json::from_value(m).unwrap()
}

fn record_work(effects: &[Effect]) -> Vec<gui_bridge::recording::RecordWork> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::Record(w) => Some(w.clone()),
            _ => None,
        })
        .collect()
}

#[test]
fn the_recording_card_calls_the_recorder_named_by_recorder_node_once_it_reports() {
    use gui_bridge::recording::{RecordDone, RecordOp, RecordWork};
    let mut p = panel("record").with_node_names(gui_bridge::NodeNames {
        recorder: "rec2".into(),
        ..Default::default()
    });
    let t0 = Instant::now();
    // a browser that connects first: the card, saying no recorder runs
    let hello: Value = serde_json::from_str(&p.snapshot().hello(50.0)).unwrap();
    assert_eq!(hello["recorder"]["node"], "rec2");
    assert_eq!(hello["recorder"]["up"], false);
    assert_eq!(hello["recorder"]["can_start"], false);
    // no recorder: refused, counted, nothing called
    let e = p.on_request(record("start", Some("pick")), at(t0, 0));
    assert!(record_work(&e).is_empty());
    let answer = told(&e, false);
    assert_eq!(answer[0]["t"], "refused");
    assert!(answer[0]["reason"]
        .as_str()
        .unwrap()
        .contains("no recorder running"));
    assert!(e
        .iter()
        .any(|e| matches!(e, Effect::Rejected { kind: "record", .. })));
    // a recorder of another name changes nothing; rec2's report shows on every page
    let e = p.on_input(recorder_report("recorder", "idle", 0), at(t0, 10));
    assert!(of_kind(&told(&e, true), "recorder").is_empty());
    let e = p.on_input(recorder_report("rec2", "idle", 4), at(t0, 20));
    let card = told(&e, true);
    let card = of_kind(&card, "recorder")[0].clone();
    assert_eq!(
        (card["up"].clone(), card["episodes"].clone()),
        (true.into(), 4.into())
    );
    assert_eq!(card["can_start"], true);
    // start: the task set, then start_episode, off the loop; one call at a time
    let e = p.on_request(record("start", Some(" pick the cube ")), at(t0, 30));
    assert_eq!(
        record_work(&e),
        [RecordWork::Start {
            task: "pick the cube".into()
        }]
    );
    assert_eq!(of_kind(&told(&e, true), "recorder")[0]["busy"], "start");
    let e = p.on_request(record("save", None), at(t0, 40));
    assert!(record_work(&e).is_empty());
    assert_eq!(told(&e, false)[0]["t"], "refused");
    let e = p.on_record_done(
        RecordDone {
            op: RecordOp::Start,
            result: Ok("recording episode 4: pick the cube".into()),
        },
        at(t0, 50),
    );
    let card = told(&e, true);
    let card = of_kind(&card, "recorder")[0].clone();
    assert_eq!(card["call"]["ok"], true);
    assert_eq!(card["call"]["text"], "recording episode 4: pick the cube");
    // what a browser that connects now gets
    assert!(e.iter().any(|e| matches!(e, Effect::Snapshot(_))));
    let e = p.on_input(recorder_report("rec2", "recording", 4), at(t0, 60));
    let card = told(&e, true);
    assert_eq!(of_kind(&card, "recorder")[0]["can_save"], true);
    // the teleop goes on meanwhile (the call never holds the loop)
    let e = p.on_request(target([0.2, 0.0, 0.15]), at(t0, 70));
    assert_eq!(told(&e, false)[0]["t"], "ack");
    assert_eq!(
        record_work(&p.on_request(record("save", None), at(t0, 80))),
        [RecordWork::Save]
    );
    // the recorder silent: the card says so on the next status tick, and refuses
    let e = p.on_record_done(
        RecordDone {
            op: RecordOp::Save,
            result: Err("no answer from /rec2/save_episode within 30 s".into()),
        },
        at(t0, 90),
    );
    assert_eq!(of_kind(&told(&e, true), "recorder")[0]["call"]["ok"], false);
    let e = p.on_status_tick(at(t0, 6000));
    let card = told(&e, true);
    let card = of_kind(&card, "recorder")[0].clone();
    assert_eq!(
        (card["up"].clone(), card["can_save"].clone()),
        (false.into(), false.into())
    );
    assert!(card["note"].as_str().unwrap().contains("not reporting"));
}

/// A `tf` message with the cube in `parent` at `x`, as the panel reads it.
fn cube_tf(parent: &str, x: f64) -> Input {
    use eezybot_msgs::geometry_msgs::{Transform, TransformStamped, Vector3};
    let msg = eezybot_msgs::tf2_msgs::TFMessage {
        transforms: vec![TransformStamped {
            header: Header {
                stamp: Time::new(1, 0),
                frame_id: parent.into(),
            },
            child_frame_id: "cube".into(),
            transform: Transform {
                translation: Vector3 {
                    x,
                    y: 0.0,
                    z: 0.0675,
                },
                ..Transform::default()
            },
        }],
    };
    let bytes = eezybot_msgs::cdr::encode(&msg).unwrap();
    Input::Tf(eezybot_msgs::cdr::decode(&bytes).unwrap())
}

#[test]
fn the_twins_cube_goes_to_the_browsers_and_a_later_hello_and_hides_when_silent() {
    let t0 = Instant::now();
    let mut p = panel("cube").with_scene("base_link", Some("twin/camera/image_raw/compressed"));
    let hello: Value = serde_json::from_str(&p.snapshot().hello(50.0)).unwrap();
    assert!(hello["cube"]["p"].is_null());
    assert_eq!(hello["camera"], "twin/camera/image_raw/compressed");
    let fx = p.on_input(cube_tf("base_link", 0.2), at(t0, 0));
    let cubes = told(&fx, true);
    assert_eq!(of_kind(&cubes, "cube")[0]["p"][0], 0.2);
    let hello: Value = serde_json::from_str(&p.snapshot().hello(50.0)).unwrap();
    assert_eq!(hello["cube"]["p"], serde_json::json!([0.2, 0.0, 0.0675]));
    // a cube of another frame: nothing told
    let fx = p.on_input(cube_tf("world", 0.3), at(t0, 100));
    assert!(of_kind(&told(&fx, true), "cube").is_empty());
    // silent for 2 s: hidden, for every browser and a later one
    let fx = p.on_status_tick(at(t0, 2500));
    let hidden = told(&fx, true);
    assert!(of_kind(&hidden, "cube")[0]["p"].is_null());
    let hello: Value = serde_json::from_str(&p.snapshot().hello(50.0)).unwrap();
    assert!(hello["cube"]["p"].is_null());
}
