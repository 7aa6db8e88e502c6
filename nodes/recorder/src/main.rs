//! `recorder` binary: the node (the default), or a command-line client of a running
//! one (`start-episode`, `save-episode`, `discard-episode`, `replay`); `recorder --help`.

use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::{CompressedImage, Image};
use eezybot_msgs::std_srvs::{TriggerRequest, TriggerResponse};
use futures::stream::{BoxStream, LocalBoxStream, StreamExt};
use recorder::cli;
use recorder::node::{self, Call, Input, Outputs, Recorder};
use recorder::{inputs, Config};
use ros_plumbing::diagnostics::DiagnosticsPublisher;
use ros_plumbing::qos;
use ros_plumbing::service::{ServiceServer, Ticket};
use ros_plumbing::{samples, topics, RosNode, Shutdown};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

type Trigger = ServiceServer<TriggerRequest, TriggerResponse>;

struct RosOutputs {
    diagnostics: DiagnosticsPublisher,
    start: Trigger,
    save: Trigger,
    discard: Trigger,
}

impl Outputs for RosOutputs {
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.publish(vec![status]);
    }
    fn answer(&self, call: Call, ticket: Ticket, response: TriggerResponse) {
        match call {
            Call::Start => self.start.answer(ticket, response),
            Call::Save => self.save.answer(ticket, response),
            Call::Discard => self.discard.answer(ticket, response),
        }
    }
}

fn main() -> ExitCode {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    match cli::parse(&argv) {
        Ok(None) => ros_plumbing::node::main(recorder::spec(), serve),
        Ok(Some(command)) => {
            ros_plumbing::run_main("recorder", cli::EXIT_REFUSED, || cli::run(command, argv))
        }
        Err(e) => e.exit(),
    }
}

fn trigger(node: &mut RosNode, c: &topics::Callable) -> anyhow::Result<Trigger> {
    let resolver = node.resolver().clone();
    Ok(ServiceServer::new(
        node.node_mut(),
        &resolver,
        c.name,
        c.package,
        c.type_name,
    )?)
}

fn service_inputs(server: &Trigger, call: Call) -> LocalBoxStream<'_, Input> {
    futures::stream::unfold(server, move |server| async move {
        loop {
            match server.next().await {
                Ok((ticket, _, _)) => return Some((Input::Call(call, ticket), server)),
                Err(e) => log::warn!("unreadable request ignored: {e}"),
            }
        }
    })
    .boxed_local()
}

/// Subscribe the contract's inputs and the cameras, serve the episode services, start
/// the writer and run the loop until `shutdown`.
async fn serve(node: &mut RosNode, shutdown: Shutdown) -> anyhow::Result<()> {
    let params = node.params().clone();
    recorder::load_arm_config(&params).map_err(anyhow::Error::msg)?;
    let config = Config::from_params(&params).map_err(anyhow::Error::msg)?;
    let arm = match params.loaded::<eezybot_kinematics::ArmConfig>("arm_config") {
        Some(a) => a,
        None => Arc::new(eezybot_kinematics::ArmConfig::shipped()?),
    };
    let servo_state = node.subscribe_to(&topics::SERVO_STATE)?;
    let joint_states = node.subscribe_to(&topics::JOINT_STATES)?;
    let leader = node.subscribe_to(&topics::LEADER_JOINT_STATES)?;
    let deadman = node.subscribe_to(&topics::LEADER_DEADMAN)?;
    let mut compressed = vec![];
    let mut raw = vec![];
    for (k, (topic, _)) in config.cameras.iter().enumerate() {
        if inputs::is_compressed(topic) {
            compressed.push((
                k,
                topic.clone(),
                node.subscription::<CompressedImage>(topic, qos::SENSOR_DATA)?,
            ));
        } else {
            raw.push((
                k,
                topic.clone(),
                node.subscription::<Image>(topic, qos::SENSOR_DATA)?,
            ));
        }
    }
    let outputs = RosOutputs {
        diagnostics: node.diagnostics()?,
        start: trigger(node, &topics::START_EPISODE)?,
        save: trigger(node, &topics::SAVE_EPISODE)?,
        discard: trigger(node, &topics::DISCARD_EPISODE)?,
    };
    let (done_tx, mut done_rx) = tokio::sync::mpsc::unbounded_channel();
    let (jobs, writer) = node::start_writer(done_tx)?;
    let name = node.resolver().node_name().to_string();
    let task = params.string("task").unwrap_or_default();
    let deadman_episodes = params.bool("deadman_episodes").unwrap_or(false);
    let mut rec = Recorder::new(&name, config.clone(), arm, &task, deadman_episodes, jobs)
        .map_err(anyhow::Error::msg)?;
    log::info!(
        "{} ready in ROS domain {}: {} fps into {}{}",
        node.resolver().node_fqn(),
        node.domain_id(),
        config.fps,
        config.root.display(),
        if config.cameras.is_empty() {
            String::new()
        } else {
            format!(
                ", cameras {}",
                config
                    .cameras
                    .iter()
                    .map(|(t, _)| t.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }
    );

    let mut topic_streams: Vec<BoxStream<'_, Input>> = vec![
        samples::inputs(&servo_state, Input::ServoState, |e| {
            Input::Unreadable("servo_state".into(), e)
        }),
        samples::inputs(&joint_states, Input::Command, |e| {
            Input::Unreadable("joint_states".into(), e)
        }),
        samples::inputs(&leader, Input::Leader, |e| {
            Input::Unreadable("leader/joint_states".into(), e)
        }),
        samples::inputs(
            &deadman,
            |b| Input::Deadman(b.data),
            |e| Input::Unreadable("leader/deadman".into(), e),
        ),
    ];
    for (k, topic, sub) in &compressed {
        let (k, t1, t2) = (*k, topic.clone(), topic.clone());
        let _ = t1;
        topic_streams.push(samples::inputs(
            sub,
            move |m: CompressedImage| {
                Input::Image(k, m.header.stamp, inputs::compressed_picture(m))
            },
            move |e| Input::Unreadable(t2.clone(), e),
        ));
    }
    for (k, topic, sub) in &raw {
        let (k, t2) = (*k, topic.clone());
        topic_streams.push(samples::inputs(
            sub,
            move |m: Image| Input::Image(k, m.header.stamp, inputs::raw_picture(m)),
            move |e| Input::Unreadable(t2.clone(), e),
        ));
    }
    let topic_inputs = futures::stream::select_all(topic_streams);
    let calls = futures::stream::select_all([
        service_inputs(&outputs.start, Call::Start),
        service_inputs(&outputs.save, Call::Save),
        service_inputs(&outputs.discard, Call::Discard),
    ]);
    let mut inputs = futures::stream::select(topic_inputs.boxed_local(), calls);

    let mut param_changes = params.subscribe();
    let now = || eezybot_msgs::Time::now().to_nanos();
    rec.open_when_ready();
    rec.report(now(), &outputs);
    let mut next_report = tokio::time::Instant::now() + node::REPORT_IDLE;
    tokio::pin!(shutdown);
    loop {
        let due = rec.next_due().map(|t| {
            let wait = (t - now()).max(0) as u64;
            tokio::time::Instant::now() + Duration::from_nanos(wait)
        });
        tokio::select! {
            _ = &mut shutdown => break,
            _ = sleep_until(due) => rec.tick(now()),
            _ = tokio::time::sleep_until(next_report) => {
                rec.report(now(), &outputs);
                next_report = tokio::time::Instant::now()
                    + if rec.recording() { node::REPORT_RECORDING } else { node::REPORT_IDLE };
            }
            Ok(()) = param_changes.changed() => rec.params(&params),
            Some(d) = done_rx.recv() => rec.done(d, now(), &outputs),
            i = inputs.next() => match i {
                Some(i) => {
                    // a parameter set before this input was answered before it was sent
                    // (the panel sets `task`, then starts): apply it first, whichever
                    // branch select! would have taken first
                    if param_changes.has_changed().unwrap_or(false) {
                        param_changes.borrow_and_update();
                        rec.params(&params);
                    }
                    let was = rec.recording();
                    rec.input(i, now(), &outputs);
                    if rec.recording() != was {
                        next_report = tokio::time::Instant::now();
                    }
                }
                None => break,
            },
        }
    }
    // a clean stop saves the episode in progress, then waits for the writer
    if rec.shutdown(now()) {
        while let Some(d) = done_rx.recv().await {
            let saved = matches!(d, recorder::writer::Done::Saved(_));
            rec.done(d, now(), &outputs);
            if saved {
                break;
            }
        }
    }
    drop(rec);
    if writer.join().is_err() {
        log::error!("the dataset writer panicked");
    }
    Ok(())
}

/// Sleeps until `deadline` (never without one).
async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(t) => tokio::time::sleep_until(t).await,
        None => std::future::pending().await,
    }
}
