//! `serial_node` binary: sets up ROS and the serial link and runs [`serial_node::run`].

use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Bool;
use ros_plumbing::diagnostics::DiagnosticsPublisher;
use ros_plumbing::peers::PeerWatch;
use ros_plumbing::Subscription;
use ros_plumbing::{samples, topics, RosNode, Shutdown, TopicPublisher};
use serial_node::link::{self, Link};
use serial_node::{Input, Outputs};
use servo_protocol::host::HostConfig;
use servo_protocol::{Role, StopAction};
use std::process::ExitCode;
use std::time::{Duration, Instant};

struct RosOutputs<'a> {
    node: &'a ros_plumbing::Node,
    angles: &'a Subscription<JointState>,
    servo_state: TopicPublisher<JointState>,
    diagnostics: DiagnosticsPublisher,
    /// the leader role's `leader/joint_states` and `leader/deadman`
    leader: Option<(TopicPublisher<JointState>, TopicPublisher<Bool>)>,
}

impl Outputs for RosOutputs<'_> {
    fn servo_state(&self, msg: JointState) {
        self.servo_state.publish(msg);
    }
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.publish(vec![status]);
    }
    fn leader(&self, joints: Option<JointState>, deadman: bool) {
        if let Some((joint_states, button)) = &self.leader {
            if let Some(j) = joints {
                joint_states.publish(j);
            }
            button.publish(Bool { data: deadman });
        }
    }
    fn peer_counts(&self) -> Vec<usize> {
        vec![
            self.angles.get_publisher_count(self.node),
            self.servo_state.get_subscription_count(self.node),
        ]
    }
}

fn main() -> ExitCode {
    ros_plumbing::node::main(serial_node::spec(), serve)
}

/// Open the link, subscribe, publish and run the node until `shutdown`.
async fn serve(node: &mut RosNode, shutdown: Shutdown) -> anyhow::Result<()> {
    let params = node.params().clone();
    let mut port = params.string("port").unwrap_or_default();
    if port == serial_node::TWIN_PORT {
        // the physics twin of this domain and namespace, behind its pseudo-terminal
        let link =
            serial_node::pty::twin_link(u32::from(node.domain_id()), node.resolver().namespace());
        log::info!(
            "port `twin`: the physics twin's link {} (start it with `twin`: docs/twin.md)",
            link.display()
        );
        port = link.to_string_lossy().into_owned();
    }
    let baud = params.i64("baud").unwrap_or(115_200);
    let leader_role = params.string("role").as_deref() == Some("leader");
    let stop_action = |name: &str| {
        if params.string(name).as_deref() == Some("detach") {
            StopAction::Detach
        } else {
            StopAction::Hold
        }
    };
    let config = HostConfig {
        send_period: Duration::from_secs_f64(1.0 / params.f64("send_rate").unwrap_or(100.0)),
        heartbeat_period: Duration::from_secs_f64(params.f64("heartbeat_period").unwrap_or(0.1)),
        watchdog_ms: u16::try_from(params.i64("watchdog_ms").unwrap_or(500)).unwrap_or(u16::MAX),
        watchdog_action: stop_action("watchdog_action"),
        estop_action: stop_action("estop_action"),
        role: if leader_role {
            Role::Leader
        } else {
            Role::Follower
        },
        ..HostConfig::default()
    };
    let mock = (port == "mock").then(link::virtual_arduino);
    let opener = match &mock {
        Some(device) => link::mock_opener(device.clone()),
        None => link::serial_opener(port.clone(), u32::try_from(baud).unwrap_or(115_200)),
    };
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    let (leader_tx, leader_rx) = if leader_role {
        let (t, r) = tokio::sync::mpsc::unbounded_channel();
        (Some(t), Some(r))
    } else {
        (None, None)
    };
    let link = Link::start(opener, config, tx, leader_tx)?;

    let angles = node.subscribe_to(&topics::SERVO_ANGLES)?;
    let estop = node.subscribe_to(&topics::ESTOP)?;
    let servo_state = node.publish_on(&topics::SERVO_STATE)?;
    let diagnostics = node.diagnostics()?;
    let peers = PeerWatch::new(&serial_node::watched_topics(
        &node.resolve(&topics::SERVO_ANGLES)?,
        &node.resolve(&topics::SERVO_STATE)?,
    ));
    let leader = if leader_role {
        Some((
            node.publish_on(&topics::LEADER_JOINT_STATES)?,
            node.publish_on(&topics::LEADER_DEADMAN)?,
        ))
    } else {
        None
    };
    let outputs = RosOutputs {
        node: node.node(),
        angles: &angles,
        servo_state,
        diagnostics,
        leader,
    };
    let inputs = futures::stream::select(
        samples::inputs(
            &angles,
            |m| Input::ServoAngles(m, Instant::now()),
            Input::Unreadable,
        ),
        samples::readable_inputs(&estop, &topics::ESTOP, |m| Input::Estop(m.data)),
    );
    if leader_role {
        log::info!(
            "{} is a leader arm's reader: {} -> {}, {}",
            node.resolver().node_fqn(),
            if port == "mock" {
                "the virtual Arduino".to_string()
            } else {
                port.clone()
            },
            node.resolve(&topics::LEADER_JOINT_STATES)?,
            node.resolve(&topics::LEADER_DEADMAN)?,
        );
    }
    log::info!(
        "{} ready in ROS domain {}: {} -> {} ({}), replies on {}",
        node.resolver().node_fqn(),
        node.domain_id(),
        node.resolve(&topics::SERVO_ANGLES)?,
        if port == "mock" {
            "the virtual Arduino".to_string()
        } else {
            format!("{port} at {baud} baud")
        },
        format_args!(
            "{:.0} frames/s at most",
            1.0 / config.send_period.as_secs_f64()
        ),
        node.resolve(&topics::SERVO_STATE)?,
    );
    let diag_name = format!("{}: servo link", node.resolver().node_name());
    let io = serial_node::Io {
        link: &link,
        outputs: &outputs,
        params,
        diag_name,
        port_name: port,
        peers,
        mock,
    };
    serial_node::run(serial_node::Handles {
        io,
        inputs,
        events: rx,
        leader: leader_rx,
        shutdown,
    })
    .await;
    link.shutdown();
    Ok(())
}
