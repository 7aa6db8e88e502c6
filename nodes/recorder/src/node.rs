//! The node's loop: its inputs offered to the sampler, the frames due written, the
//! episode requests (services, the deadman) through [`Episodes`], the writer's results
//! answered and reported.

use crate::compose::{self, FIRST_CAMERA, INPUTS};
use crate::inputs::{self, Picture, Sample};
use crate::report::{self, State, View};
use crate::writer::{self, Done, Job, Opened};
use crate::{Config, ROBOT_TYPE};
use eezybot_kinematics::{ArmConfig, ACTUATED_JOINTS};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::std_srvs::TriggerResponse;
use lerobot_dataset::DatasetSpec;
use recorder_core::episode::{Effect, Episodes, Phase, Request};
use recorder_core::{Sampler, SamplerConfig, Tick};
use ros_plumbing::service::Ticket;
use ros_plumbing::Params;
use std::sync::{mpsc, Arc};
use std::time::Duration;

/// How often the entry goes out while recording (and at once on every change).
pub const REPORT_RECORDING: Duration = Duration::from_millis(500);
/// How often the entry goes out otherwise.
pub const REPORT_IDLE: Duration = Duration::from_secs(2);
/// How many dropped frames an episode's save lists by their grid index (the rows are
/// contiguous: the list tells which instants they skip).
pub const DROPS_LISTED: usize = 100;

/// How long a frame may wait for a live input's samples (recorder_core's `max_wait`).
pub const MAX_WAIT: Duration = Duration::from_millis(500);

/// An episode service.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Call {
    /// `recorder/start_episode`
    Start,
    /// `recorder/save_episode`
    Save,
    /// `recorder/discard_episode`
    Discard,
}

/// What the loop takes in.
#[derive(Debug)]
pub enum Input {
    /// `servo_state`
    ServoState(eezybot_msgs::sensor_msgs::JointState),
    /// compute_ik's `joint_states`
    Command(eezybot_msgs::sensor_msgs::JointState),
    /// `leader/joint_states`
    Leader(eezybot_msgs::sensor_msgs::JointState),
    /// `leader/deadman`
    Deadman(bool),
    /// camera `k`'s image (or why it cannot be recorded), stamped
    Image(usize, eezybot_msgs::Time, Result<Picture, String>),
    /// a request to an episode service
    Call(Call, Ticket),
    /// a sample that could not be read, on this topic
    Unreadable(String, String),
}

/// Where results go.
pub trait Outputs {
    /// Publish the `diagnostics` entry.
    fn diagnostics(&self, status: DiagnosticStatus);
    /// Answer a service request.
    fn answer(&self, call: Call, ticket: Ticket, response: TriggerResponse);
}

struct Running {
    index: u64,
    task: String,
    t0_ns: i64,
    rows: u64,
    dropped: u64,
    /// the grid's frames dropped, in order (the first [`DROPS_LISTED`])
    dropped_at: Vec<u64>,
    started: bool,
    /// Saving: the frames up to the request are still being decided.
    ending: bool,
}

impl Running {
    /// A frame of the grid dropped.
    fn drop_at(&mut self, index: u64) {
        self.dropped += 1;
        if self.dropped_at.len() < DROPS_LISTED {
            self.dropped_at.push(index);
        }
    }

    /// `; dropped grid frames: 41, 42` (empty without drops; `…` past [`DROPS_LISTED`]).
    fn dropped_text(&self) -> String {
        if self.dropped_at.is_empty() {
            return String::new();
        }
        let mut list: Vec<String> = self.dropped_at.iter().map(u64::to_string).collect();
        if self.dropped > self.dropped_at.len() as u64 {
            list.push("…".into());
        }
        format!("; dropped grid frames: {}", list.join(", "))
    }
}

/// The recorder's state between events.
pub struct Recorder {
    node: String,
    config: Config,
    arm: Arc<ArmConfig>,
    sampler: Sampler<Sample>,
    episodes: Episodes,
    /// each camera's image size, once heard
    sizes: Vec<Option<(u32, u32)>>,
    opened: Option<Opened>,
    opening: bool,
    refused: Option<String>,
    running: Option<Running>,
    pending: Vec<(Call, Ticket)>,
    jobs: mpsc::SyncSender<Job>,
    dropped_total: u64,
    last_drop: Option<String>,
    last: String,
    warning: Option<String>,
    rejected: u64,
    last_rejection: Option<String>,
    task_param: String,
}

fn trigger(success: bool, message: impl Into<String>) -> TriggerResponse {
    TriggerResponse {
        success,
        message: message.into(),
    }
}

impl Recorder {
    /// A recorder named `node` with `config`, its writer taking `jobs`.
    pub fn new(
        node: &str,
        config: Config,
        arm: Arc<ArmConfig>,
        task: &str,
        deadman_episodes: bool,
        jobs: mpsc::SyncSender<Job>,
    ) -> Result<Recorder, String> {
        let mut names: Vec<(String, recorder_core::Need)> =
            INPUTS.iter().map(|(n, k)| (n.to_string(), *k)).collect();
        for (topic, _) in &config.cameras {
            names.push((topic.clone(), recorder_core::Need::Required));
        }
        let refs: Vec<(&str, recorder_core::Need)> =
            names.iter().map(|(n, k)| (n.as_str(), *k)).collect();
        let sampler = Sampler::new(
            SamplerConfig {
                fps: config.fps,
                max_staleness: config.max_staleness,
                wait: Duration::from_millis(50).min(config.max_staleness),
                max_wait: MAX_WAIT.max(config.max_staleness),
            },
            &refs,
        )
        .map_err(|e| e.to_string())?;
        Ok(Recorder {
            node: node.to_string(),
            sizes: vec![None; config.cameras.len()],
            config,
            arm,
            sampler,
            episodes: Episodes::new(task, deadman_episodes),
            opened: None,
            opening: false,
            refused: None,
            running: None,
            pending: vec![],
            jobs,
            dropped_total: 0,
            last_drop: None,
            last: String::new(),
            warning: None,
            rejected: 0,
            last_rejection: None,
            task_param: task.to_string(),
        })
    }

    /// The dataset's spec once every camera's size is known.
    fn dataset_spec(&self) -> Option<DatasetSpec> {
        let mut spec = DatasetSpec::new(
            self.config.fps,
            ROBOT_TYPE,
            &ACTUATED_JOINTS,
            &ACTUATED_JOINTS,
        );
        for ((_, name), size) in self.config.cameras.iter().zip(&self.sizes) {
            let (w, h) = (*size)?;
            spec = spec.with_camera(name, w, h);
        }
        Some(spec)
    }

    /// Ask the writer to open the dataset once every camera's size is known.
    pub fn open_when_ready(&mut self) {
        if self.opened.is_some() || self.opening || self.refused.is_some() {
            return;
        }
        if let Some(spec) = self.dataset_spec() {
            self.opening = true;
            self.send(Job::Open {
                root: self.config.root.clone(),
                spec,
                resume: self.config.resume,
            });
        }
    }

    fn send(&mut self, job: Job) {
        if self.jobs.send(job).is_err() {
            self.refused = Some("the dataset writer stopped".into());
        }
    }

    fn reject(&mut self, what: &str, why: String) {
        self.rejected += 1;
        if self.rejected == 1 || self.rejected % 100 == 0 {
            log::warn!("{what} not recorded ({} so far): {why}", self.rejected);
        }
        self.last_rejection = Some(format!("{what}: {why}"));
    }

    /// Parameters changed: the task of the next episodes, deadman episodes, the
    /// calibration.
    pub fn params(&mut self, p: &Params) {
        if let Some(task) = p.string("task") {
            self.task_param = task.trim().to_string();
            self.episodes.set_default_task(&self.task_param);
        }
        if let Some(config) = p.loaded::<ArmConfig>("arm_config") {
            self.arm = config;
        }
        let deadman = p.bool("deadman_episodes").unwrap_or(false);
        if deadman != self.episodes.deadman_episodes() {
            self.episodes.set_deadman_episodes(deadman);
            log::info!("deadman episodes {}", if deadman { "on" } else { "off" });
        }
    }

    /// An input, at `now`.
    pub fn input(&mut self, input: Input, now: i64, out: &impl Outputs) {
        match input {
            Input::ServoState(m) => match inputs::follower_joints(&m, &self.arm) {
                Ok(q) => {
                    self.sampler
                        .offer(compose::STATE, m.header.stamp.to_nanos(), Sample::Joints(q))
                }
                Err(e) => self.reject("servo_state", e),
            },
            Input::Command(m) => match inputs::actuated_joints(&m) {
                Ok(q) => self.sampler.offer(
                    compose::COMMAND,
                    m.header.stamp.to_nanos(),
                    Sample::Joints(q),
                ),
                Err(e) => self.reject("joint_states", e),
            },
            Input::Leader(m) => match inputs::actuated_joints(&m) {
                Ok(q) => self.sampler.offer(
                    compose::LEADER,
                    m.header.stamp.to_nanos(),
                    Sample::Joints(q),
                ),
                Err(e) => self.reject("leader/joint_states", e),
            },
            Input::Deadman(held) => {
                // std_msgs/Bool has no stamp: the time it came
                self.sampler
                    .offer(compose::DEADMAN, now, Sample::Deadman(held));
                let fx = self.episodes.deadman(held, now);
                if !fx.is_empty() {
                    self.carry_out(fx, None, now);
                    self.tick(now);
                    self.report(now, out);
                }
            }
            Input::Image(k, stamp, picture) => match picture {
                Ok(p) => {
                    let size = match crate::writer::image(&p).size() {
                        Ok(size) => size,
                        Err(e) => {
                            let topic = self.config.cameras[k].0.clone();
                            self.reject(&topic, e);
                            return;
                        }
                    };
                    match self.sizes[k] {
                        None => {
                            self.sizes[k] = Some(size);
                            self.open_when_ready();
                        }
                        Some(s) if s != size => {
                            let topic = self.config.cameras[k].0.clone();
                            self.reject(
                                &topic,
                                format!(
                                    "{}x{} while the dataset's camera is {}x{}",
                                    size.0, size.1, s.0, s.1
                                ),
                            );
                            return;
                        }
                        Some(_) => {}
                    }
                    self.sampler.offer(
                        FIRST_CAMERA + k,
                        stamp.to_nanos(),
                        Sample::Image(Arc::new(p)),
                    );
                }
                Err(e) => {
                    let topic = self.config.cameras[k].0.clone();
                    self.reject(&topic, e);
                }
            },
            Input::Call(call, ticket) => self.call(call, ticket, now, out),
            Input::Unreadable(topic, e) => self.reject(&topic, format!("unreadable: {e}")),
        }
    }

    fn call(&mut self, call: Call, ticket: Ticket, now: i64, out: &impl Outputs) {
        let request = match call {
            Call::Start => {
                if let Some(why) = &self.refused {
                    let why = why.clone();
                    out.answer(
                        call,
                        ticket,
                        trigger(false, format!("not recording: {why}")),
                    );
                    return;
                }
                if self.opened.is_none() {
                    let why = self.waiting_for();
                    out.answer(call, ticket, trigger(false, why));
                    return;
                }
                Request::Start { task: None }
            }
            Call::Save => Request::Save,
            Call::Discard => Request::Discard,
        };
        match self.episodes.request(request, now) {
            Ok(fx) => {
                self.carry_out(fx, Some((call, ticket)), now);
                self.tick(now);
            }
            Err(e) => out.answer(call, ticket, trigger(false, e.to_string())),
        }
        self.report(now, out);
    }

    fn waiting_for(&self) -> String {
        let missing: Vec<&str> = self
            .config
            .cameras
            .iter()
            .zip(&self.sizes)
            .filter(|(_, s)| s.is_none())
            .map(|((t, _), _)| t.as_str())
            .collect();
        if missing.is_empty() {
            "the dataset is being opened".into()
        } else {
            format!(
                "waiting for the first image of {} (its size makes the dataset's)",
                missing.join(", ")
            )
        }
    }

    fn carry_out(&mut self, fx: Vec<Effect>, ticket: Option<(Call, Ticket)>, now: i64) {
        for e in fx {
            match e {
                Effect::Begin { task, t0_ns } => {
                    self.sampler.start(t0_ns);
                    self.running = Some(Running {
                        index: self.opened.as_ref().map_or(0, |o| o.episodes),
                        task: task.clone(),
                        t0_ns,
                        rows: 0,
                        dropped: 0,
                        dropped_at: vec![],
                        started: false,
                        ending: false,
                    });
                    self.send(Job::Begin(task));
                }
                // the frames up to now are written first (they may wait for samples on
                // their way); then the save ([`Recorder::tick`])
                Effect::Save => match self.running.as_mut() {
                    Some(run) => {
                        run.ending = true;
                        self.sampler.end_at(now);
                    }
                    None => self.send(Job::Save),
                },
                Effect::Discard => {
                    self.sampler.stop();
                    self.send(Job::Discard);
                }
            }
        }
        if let Some(t) = ticket {
            self.pending.push(t);
        }
    }

    fn answer_pending(&mut self, call: Call, success: bool, message: &str, out: &impl Outputs) {
        if let Some(k) = self.pending.iter().position(|(c, _)| *c == call) {
            let (c, t) = self.pending.remove(k);
            out.answer(c, t, trigger(success, message));
        }
    }

    /// The frames due by `now`, written.
    pub fn tick(&mut self, now: i64) {
        let ticks = self.sampler.poll(now);
        for t in ticks {
            let Some(run) = self.running.as_mut() else {
                break;
            };
            match t {
                Tick::Frame(f) => match compose::compose(&f, self.config.cameras.len()) {
                    Some(row) => {
                        run.rows += 1;
                        let index = row.grid_index;
                        if self.jobs.try_send(Job::Row(Box::new(row))).is_err() {
                            run.rows -= 1;
                            run.drop_at(index);
                            self.dropped_total += 1;
                            self.last_drop = Some("the writer fell behind".into());
                        }
                    }
                    None => {
                        run.drop_at(f.index);
                        self.dropped_total += 1;
                    }
                },
                Tick::Dropped(d) => {
                    run.drop_at(d.index);
                    self.dropped_total += 1;
                    let why: Vec<String> = d
                        .stale
                        .iter()
                        .map(|(name, age)| match age {
                            Some(a) => format!("{name} {:.3} s old", *a as f64 * 1e-9),
                            None => format!("nothing on {name} yet"),
                        })
                        .collect();
                    let why = why.join(", ");
                    if run.dropped == 1 || run.dropped % 30 == 0 {
                        log::warn!(
                            "episode {}: frame {} dropped ({} so far): {why}",
                            run.index,
                            d.index,
                            run.dropped
                        );
                    }
                    self.last_drop = Some(why);
                }
            }
        }
        if self.running.as_ref().is_some_and(|r| r.ending) && self.sampler.finished() {
            self.sampler.stop();
            if let Some(run) = self.running.as_mut() {
                run.ending = false;
            }
            self.send(Job::Save);
        }
    }

    /// When the next frame is due, ns.
    pub fn next_due(&self) -> Option<i64> {
        self.sampler.next_due()
    }

    /// What the writer did.
    pub fn done(&mut self, d: Done, now: i64, out: &impl Outputs) {
        match d {
            Done::Opened(Ok(o)) => {
                self.opening = false;
                let what = if o.created { "created" } else { "opened" };
                log::info!(
                    "dataset {what}: {} ({} episodes, {} frames)",
                    self.config.root.display(),
                    o.episodes,
                    o.frames
                );
                if let Some(r) = &o.recovered {
                    log::warn!("recovered after a crash: {r}");
                    self.warning = Some(format!("recovered after a crash: {r}"));
                    self.last = format!("recovered after a crash: {r}");
                }
                self.opened = Some(o);
            }
            Done::Opened(Err(e)) => {
                self.opening = false;
                log::error!("{e}: nothing is recorded (nothing in the folder was touched)");
                self.refused = Some(e);
            }
            Done::Began(Ok(index)) => {
                if let Some(r) = self.running.as_mut() {
                    r.index = index;
                    r.started = true;
                    // frame 0's instant, for aligning the episode with other records (bags)
                    let t0 = format!(
                        "{}.{:09}",
                        r.t0_ns.div_euclid(1_000_000_000),
                        r.t0_ns.rem_euclid(1_000_000_000)
                    );
                    log::info!("recording episode {index}: {:?} (frame 0 at {t0})", r.task);
                    let msg = format!("recording episode {index}: {} (frame 0 at {t0})", r.task);
                    self.answer_pending(Call::Start, true, &msg, out);
                }
            }
            Done::Began(Err(e)) => {
                self.sampler.stop();
                self.running = None;
                log::error!("cannot begin an episode: {e}");
                // nothing began, so there is nothing to discard
                self.episodes.failed(&e);
                self.answer_pending(Call::Start, false, &e, out);
            }
            Done::RowDropped(index, e) => {
                if let Some(run) = self.running.as_mut() {
                    run.rows = run.rows.saturating_sub(1);
                    run.drop_at(index);
                    self.dropped_total += 1;
                    if run.dropped == 1 || run.dropped % 30 == 0 {
                        log::warn!(
                            "episode {}: a frame dropped ({} so far): {e}",
                            run.index,
                            run.dropped
                        );
                    }
                }
                self.last_drop = Some(e);
                return;
            }
            Done::RowFailed(e) => {
                log::error!("recording stopped: {e} (the finished episodes are intact)");
                let fx = self.episodes.failed(&e);
                self.carry_out(fx, None, now);
            }
            Done::Saved(Ok((s, took))) => {
                let seconds = s.frames as f64 / f64::from(self.config.fps);
                let (dropped, at) = self
                    .running
                    .as_ref()
                    .map_or((0, String::new()), |r| (r.dropped, r.dropped_text()));
                let msg = format!(
                    "saved episode {} ({} frames, {seconds:.1} s, {dropped} dropped) in {:.0} ms{at}",
                    s.episode_index,
                    s.frames,
                    took.as_secs_f64() * 1e3
                );
                log::info!("{msg}");
                self.episodes.saved(Ok(s.frames as u64));
                if let Some(o) = self.opened.as_mut() {
                    o.episodes = s.episode_index + 1;
                    o.frames += s.frames as u64;
                }
                self.running = None;
                self.warning = None;
                self.last = msg.clone();
                self.answer_pending(Call::Save, true, &msg, out);
            }
            Done::Saved(Err(e)) => {
                let msg = format!(
                    "episode not saved: {e} (kept: save again once there is room, or discard it)"
                );
                log::error!("{msg}");
                self.episodes.saved(Err(e));
                self.last = msg.clone();
                self.answer_pending(Call::Save, false, &msg, out);
            }
            Done::Discarded(r) => {
                let index = self.running.as_ref().map_or(0, |r| r.index);
                let msg = match &r {
                    Ok(frames) => format!("discarded episode {index} ({frames} frames)"),
                    Err(e) => format!("discarding episode {index}: {e}"),
                };
                log::info!("{msg}");
                self.running = None;
                self.last = msg.clone();
                self.answer_pending(Call::Discard, r.is_ok(), &msg, out);
            }
        }
        self.report(now, out);
    }

    /// The view the entry shows at `now`.
    pub fn view(&self, now: i64) -> View {
        let state = if let Some(why) = &self.refused {
            State::Stopped(why.clone())
        } else {
            match self.episodes.phase() {
                Phase::Stopped(why) => State::Stopped(why.clone()),
                Phase::Recording { .. } => State::Recording,
                Phase::Saving => State::Saving,
                Phase::Idle if self.opened.is_none() => State::Waiting(self.waiting_for()),
                Phase::Idle => State::Idle,
            }
        };
        let episodes = self.opened.as_ref().map_or(0, |o| o.episodes);
        let (task, episode, frames, elapsed_s, dropped) = match &self.running {
            Some(r) => (
                r.task.clone(),
                r.index,
                r.rows,
                (now - r.t0_ns).max(0) as f64 * 1e-9,
                r.dropped,
            ),
            None => (self.task_param.clone(), episodes, 0, 0.0, 0),
        };
        View {
            state,
            task,
            episode,
            episodes,
            frames,
            elapsed_s,
            dropped,
            dropped_total: self.dropped_total,
            last_drop: self.last_drop.clone(),
            fps: self.config.fps,
            root: self.config.root.display().to_string(),
            cameras: self
                .config
                .cameras
                .iter()
                .map(|(_, n)| format!("observation.images.{n}"))
                .collect(),
            last: self.last.clone(),
            warning: self.warning.clone(),
        }
    }

    /// Publish the entry.
    pub fn report(&self, now: i64, out: &impl Outputs) {
        let mut s = report::report(&self.node, &self.view(now));
        if let Some(r) = &self.last_rejection {
            s.values.push(eezybot_msgs::diagnostic_msgs::KeyValue {
                key: "rejected".into(),
                value: self.rejected.to_string(),
            });
            s.values.push(eezybot_msgs::diagnostic_msgs::KeyValue {
                key: ros_plumbing::diagnostics::LAST_REJECTION_KEY.into(),
                value: r.clone(),
            });
        }
        out.diagnostics(s);
    }

    /// Whether an episode is recording (the entry goes out more often).
    pub fn recording(&self) -> bool {
        self.running.is_some()
    }

    /// At shutdown: an episode in progress is saved (a clean stop keeps the
    /// demonstration; a crash leaves it for the next start to discard).
    pub fn shutdown(&mut self, now: i64) -> bool {
        match self.episodes.request(Request::Save, now) {
            Ok(fx) => {
                log::info!("stopping: saving the episode in progress");
                self.carry_out(fx, None, now);
                // no more samples will be read: the last frames are decided with what came
                let all_due =
                    now.saturating_add(i64::try_from(MAX_WAIT.as_nanos()).unwrap_or(0) + 1);
                self.tick(all_due);
                true
            }
            Err(_) => false,
        }
    }
}

/// Start the writer thread; its results come through `done`.
pub fn start_writer(
    done: tokio::sync::mpsc::UnboundedSender<Done>,
) -> std::io::Result<(mpsc::SyncSender<Job>, std::thread::JoinHandle<()>)> {
    let (tx, rx) = mpsc::sync_channel(writer::QUEUE);
    let handle = std::thread::Builder::new()
        .name("dataset writer".into())
        .spawn(move || {
            writer::run(rx, |d| {
                let _ = done.send(d);
            })
        })?;
    Ok((tx, handle))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn running() -> Running {
        Running {
            index: 0,
            task: "t".into(),
            t0_ns: 0,
            rows: 0,
            dropped: 0,
            dropped_at: vec![],
            started: true,
            ending: false,
        }
    }

    #[test]
    fn a_save_lists_the_grid_frames_dropped() {
        let mut r = running();
        assert_eq!(r.dropped_text(), "");
        r.drop_at(41);
        r.drop_at(42);
        assert_eq!(r.dropped_text(), "; dropped grid frames: 41, 42");
        for k in 0..DROPS_LISTED as u64 {
            r.drop_at(100 + k);
        }
        assert_eq!(r.dropped, DROPS_LISTED as u64 + 2);
        assert!(r.dropped_text().ends_with(", …"), "{}", r.dropped_text());
    }
}
