//! A line-driven ROS 2 peer on our own stack (ros2-client over RustDDS, through
//! `RosNode` as every node of the graph), speaking the protocol of
//! `tests/interop/sros2_peer` (the Fast DDS peer), so that a benchmark can swap one for
//! the other (`tests/bench/secure_e2e.py --probe rust`). With it the operator's side of
//! a secured run costs what our gui_bridge's would, not what Fast DDS's does.
//!
//! ```text
//! ros_probe --domain D --name NAME [--enclave KEYSTORE/enclaves/A/B]
//!           [--pub TOPIC TYPE]... [--sub TOPIC TYPE]...
//! stdin:  TOPIC HEX              publish a sample (CDR with its 4-byte encapsulation header);
//!                                EOF ends the program
//! stdout: ready                  every endpoint exists
//!         matched TOPIC pub|sub N  N remote endpoints match ours now
//!         recv TOPIC HEX         a sample received
//! ```
//!
//! TOPIC is the DDS name (`rt/xyz_target`); the types it knows are PointStamped (to
//! publish), JointState and, on `rt/robot_description`, std_msgs/String (both ways: a
//! sample of any size, for the secured large-sample tests). With `--enclave` the probe runs under that
//! enclave of its keystore (ROS_SECURITY_ENABLE=true, Enforce) and names itself
//! `gui_bridge`, the operator node whose permissions the `/eezybot/pc` enclave grants.

use eezybot_msgs::cdr::{self, hex, unhex};
use eezybot_msgs::geometry_msgs::PointStamped;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::String as StringMsg;
use futures::StreamExt;
use ros_plumbing::{topics, NodeSpec, RosNode, Topic};
use std::io::{BufRead, Write};
use std::process::ExitCode;
use tokio::sync::mpsc;

const POINT: &str = "geometry_msgs::msg::dds_::PointStamped_";
const JOINTS: &str = "sensor_msgs::msg::dds_::JointState_";
const STRING: &str = "std_msgs::msg::dds_::String_";

struct Args {
    domain: String,
    enclave: Option<(String, String)>,
    pubs: Vec<(String, String)>,
    subs: Vec<(String, String)>,
}

fn parse(mut argv: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut a = Args {
        domain: "0".into(),
        enclave: None,
        pubs: vec![],
        subs: vec![],
    };
    while let Some(flag) = argv.next() {
        let mut value = || argv.next().ok_or(format!("{flag} needs a value"));
        match flag.as_str() {
            "--domain" => a.domain = value()?,
            "--name" => {
                value()?;
            }
            "--enclave" => {
                let path = value()?;
                let (keystore, enclave) = path
                    .split_once("/enclaves/")
                    .ok_or(format!("{path}: not a keystore's enclaves/ directory"))?;
                a.enclave = Some((
                    keystore.to_string(),
                    format!("/{}", enclave.trim_end_matches('/')),
                ));
            }
            "--pub" | "--sub" => {
                let pair = (value()?, value()?);
                let known = if flag == "--pub" {
                    [POINT, JOINTS, STRING]
                } else {
                    [JOINTS, STRING, STRING]
                };
                if !known.contains(&pair.1.as_str()) {
                    return Err(format!("{flag} {} {}: type not supported", pair.0, pair.1));
                }
                if flag == "--pub" {
                    a.pubs.push(pair)
                } else {
                    a.subs.push(pair)
                }
            }
            other => return Err(format!("unknown argument {other}")),
        }
    }
    Ok(a)
}

fn say(line: &str) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

/// The contract's JointState topic named `dds` (`rt/servo_angles`).
fn joints_topic(dds: &str) -> Result<&'static Topic<JointState>, String> {
    [
        &topics::SERVO_ANGLES,
        &topics::SERVO_STATE,
        &topics::JOINT_STATES,
        &topics::JOINT_TARGET,
    ]
    .into_iter()
    .find(|t| dds.strip_prefix("rt/") == Some(t.name))
    .ok_or(format!("{dds}: not a JointState topic of the contract"))
}

/// The contract's String topic named `dds` (only `rt/robot_description`).
fn string_topic(dds: &str) -> Result<&'static Topic<StringMsg>, String> {
    (dds.strip_prefix("rt/") == Some(topics::ROBOT_DESCRIPTION.name))
        .then_some(&topics::ROBOT_DESCRIPTION)
        .ok_or(format!("{dds}: the String topic is rt/robot_description"))
}

enum Pub {
    Point(ros_plumbing::TopicPublisher<PointStamped>),
    Joints(ros_plumbing::TopicPublisher<JointState>),
    Text(ros_plumbing::TopicPublisher<StringMsg>),
}

enum Sub {
    Joints(ros2_client::Subscription<JointState>),
    Text(ros2_client::Subscription<StringMsg>),
}

/// A received sample's CDR (with its encapsulation header), or why there is none.
fn encoded<M: serde::Serialize, I, E: std::fmt::Debug>(
    r: Result<(M, I), E>,
) -> Result<Vec<u8>, String> {
    let (m, _) = r.map_err(|e| format!("{e:?}"))?;
    cdr::encode(&m).map_err(|e| e.to_string())
}

async fn main_async() -> Result<(), String> {
    let args = parse(std::env::args().skip(1))?;
    let mut ros_args = vec![
        "--ros-args".to_string(),
        "-r".into(),
        "__node:=gui_bridge".into(),
    ];
    // SAFETY of set_var: before any other thread of this process exists
    std::env::set_var("ROS_DOMAIN_ID", &args.domain);
    match &args.enclave {
        Some((keystore, enclave)) => {
            std::env::set_var("ROS_SECURITY_ENABLE", "true");
            std::env::set_var("ROS_SECURITY_STRATEGY", "Enforce");
            std::env::set_var("ROS_SECURITY_KEYSTORE", keystore);
            ros_args.extend(["--enclave".to_string(), enclave.clone()]);
        }
        None => std::env::remove_var("ROS_SECURITY_ENABLE"),
    }
    let spec = NodeSpec {
        name: "ros_probe",
        description: "a line-driven peer",
        usage: "",
        params: vec![],
    };
    let mut node =
        RosNode::start_with(&spec, ros_args, Some(&args.domain)).map_err(|e| e.to_string())?;

    let mut pubs = Vec::new();
    for (topic, ty) in &args.pubs {
        let p = if ty == POINT && topic == "rt/xyz_target" {
            Pub::Point(
                node.publish_on(&topics::XYZ_TARGET)
                    .map_err(|e| e.to_string())?,
            )
        } else if ty == POINT {
            return Err(format!("{topic}: the PointStamped topic is rt/xyz_target"));
        } else if ty == STRING {
            Pub::Text(
                node.publish_on(string_topic(topic)?)
                    .map_err(|e| e.to_string())?,
            )
        } else {
            Pub::Joints(
                node.publish_on(joints_topic(topic)?)
                    .map_err(|e| e.to_string())?,
            )
        };
        pubs.push((topic.clone(), p, usize::MAX));
    }
    let (tx, mut rx) = mpsc::unbounded_channel::<String>();
    let mut subs = Vec::new();
    for (topic, ty) in &args.subs {
        let sub = if ty == STRING {
            Sub::Text(
                node.subscribe_to(string_topic(topic)?)
                    .map_err(|e| e.to_string())?,
            )
        } else {
            Sub::Joints(
                node.subscribe_to(joints_topic(topic)?)
                    .map_err(|e| e.to_string())?,
            )
        };
        subs.push((topic.clone(), sub));
    }
    let mut sub_counts = vec![usize::MAX; subs.len()];
    // each sample as its CDR again, whatever its type
    let mut streams = futures::stream::select_all(subs.iter().map(|(topic, sub)| {
        let topic = topic.clone();
        match sub {
            Sub::Joints(s) => s
                .async_stream()
                .map(move |r| (topic.clone(), encoded(r)))
                .boxed_local(),
            Sub::Text(s) => s
                .async_stream()
                .map(move |r| (topic.clone(), encoded(r)))
                .boxed_local(),
        }
    }));
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    say("ready");
    let mut poll = tokio::time::interval(std::time::Duration::from_millis(20));
    let shutdown = ros_plumbing::shutdown_signal();
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            line = rx.recv() => {
                let Some(line) = line else { break };
                let mut parts = line.split_whitespace();
                let (Some(topic), Some(payload)) = (parts.next(), parts.next()) else {
                    eprintln!("ros_probe: cannot read `{line}`");
                    continue;
                };
                let Some(bytes) = unhex(payload) else {
                    eprintln!("ros_probe: bad hex for {topic}");
                    continue;
                };
                match pubs.iter().find(|(t, _, _)| t == topic) {
                    Some((_, Pub::Point(p), _)) => match cdr::decode::<PointStamped>(&bytes) {
                        Ok(m) => { p.publish(m); say(&format!("published {topic}")); }
                        Err(e) => eprintln!("ros_probe: {topic}: {e}"),
                    },
                    Some((_, Pub::Joints(p), _)) => match cdr::decode::<JointState>(&bytes) {
                        Ok(m) => { p.publish(m); say(&format!("published {topic}")); }
                        Err(e) => eprintln!("ros_probe: {topic}: {e}"),
                    },
                    Some((_, Pub::Text(p), _)) => match cdr::decode::<StringMsg>(&bytes) {
                        Ok(m) => { p.publish(m); say(&format!("published {topic}")); }
                        Err(e) => eprintln!("ros_probe: {topic}: {e}"),
                    },
                    None => eprintln!("ros_probe: not publishing {topic}"),
                }
            }
            Some((topic, r)) = streams.next() => match r {
                Ok(bytes) => say(&format!("recv {topic} {}", hex(&bytes))),
                Err(e) => eprintln!("ros_probe: {topic}: {e}"),
            },
            _ = poll.tick() => {
                for (topic, p, last) in pubs.iter_mut() {
                    let n = match p {
                        Pub::Point(p) => p.get_subscription_count(node.node()),
                        Pub::Joints(p) => p.get_subscription_count(node.node()),
                        Pub::Text(p) => p.get_subscription_count(node.node()),
                    };
                    if n != *last { *last = n; say(&format!("matched {topic} pub {n}")); }
                }
                for ((topic, s), last) in subs.iter().zip(sub_counts.iter_mut()) {
                    let n = match s {
                        Sub::Joints(s) => s.get_publisher_count(node.node()),
                        Sub::Text(s) => s.get_publisher_count(node.node()),
                    };
                    if n != *last { *last = n; say(&format!("matched {topic} sub {n}")); }
                }
            }
        }
    }
    drop(streams);
    drop(subs);
    drop(pubs);
    node.shutdown().await;
    Ok(())
}

fn main() -> ExitCode {
    ros_plumbing::run_main("ros_probe", 2, main_async)
}
