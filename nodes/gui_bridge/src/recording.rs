//! The panel's recording card (issue 34): the recorder node's state as its
//! `diagnostics` report it (a status named `recorder`, or the `recorder_node`
//! parameter's name), and the episode calls the card makes on it (the `task` parameter
//! set, then `<recorder>/start_episode`; `save_episode`, `discard_episode`: std_srvs
//! Trigger). Pure: the bridge loop runs the calls off its hot path
//! ([`crate::RecorderControl`]) and hands their outcome back
//! ([`RecordCard::on_done`]); what the page shows is [`RecordCard::view`].

use crate::message::{RecordCallView, RecordView};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use ros_plumbing::logging::shorten;
use std::time::{Duration, Instant};

/// The longest task the recorder takes (recorder_core's `TASK_MAX`).
pub const TASK_MAX: usize = 500;
/// The recorder is up while it was heard within this (it reports every 2 s when idle).
pub const UP_WITHIN: Duration = Duration::from_secs(5);
/// The longest text of the recorder's (message, reason, paths) the card shows.
const TEXT_MAX: usize = 300;

/// What the recorder does, from its status's `state`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RecState {
    /// the dataset is not open yet: waiting for the first image of each camera
    /// (`reason` says which)
    Waiting,
    /// no episode
    Idle,
    /// an episode runs
    Recording,
    /// an episode is being written out
    Saving,
    /// recording stopped (a full disk, a dataset refused): `reason` says why
    Stopped,
    /// a state this panel does not know (a newer recorder): shown, no button enabled
    Other(String),
}

impl RecState {
    fn parse(s: &str) -> RecState {
        match s {
            "waiting" => RecState::Waiting,
            "idle" => RecState::Idle,
            "recording" => RecState::Recording,
            "saving" => RecState::Saving,
            "stopped" => RecState::Stopped,
            other => RecState::Other(shorten(other, 40).into_owned()),
        }
    }

    /// As the recorder writes it.
    pub fn as_str(&self) -> &str {
        match self {
            RecState::Waiting => "waiting",
            RecState::Idle => "idle",
            RecState::Recording => "recording",
            RecState::Saving => "saving",
            RecState::Stopped => "stopped",
            RecState::Other(s) => s,
        }
    }
}

/// One report of the recorder's, read from its `diagnostics` status. A value missing
/// or unreadable is `None` (shown as unknown), never a reason to drop the report.
#[derive(Clone, Debug, PartialEq)]
pub struct RecorderReport {
    /// 0 OK, 1 WARN, 2 ERROR
    pub level: u8,
    /// its one human line
    pub message: String,
    /// `state`
    pub state: RecState,
    /// the episode's task (recording), else the `task` parameter
    pub task: Option<String>,
    /// the episode being recorded (recording, saving), else the next one
    pub episode: Option<u64>,
    /// episodes saved in the dataset
    pub episodes: Option<u64>,
    /// frames of the episode in progress
    pub frames: Option<u64>,
    /// seconds since the episode started, as reported
    pub elapsed_s: Option<f64>,
    /// frames dropped in the episode in progress
    pub dropped: Option<u64>,
    /// frames dropped since the recorder started
    pub dropped_total: Option<u64>,
    /// frames a second
    pub fps: Option<f64>,
    /// the dataset's folder
    pub root: Option<String>,
    /// the cameras' feature names, comma-separated
    pub cameras: Option<String>,
    /// the last episode action's outcome line
    pub last: Option<String>,
    /// why recording stopped (or what it waits for)
    pub reason: Option<String>,
}

/// Whether `status` is the recorder's: named `node` (the contract's `recorder`), or
/// `node: …` as the other nodes name theirs.
pub fn is_recorder(status: &DiagnosticStatus, node: &str) -> bool {
    let name = status.name.trim();
    name == node || name.split_once(':').is_some_and(|(n, _)| n.trim() == node)
}

/// The recorder's report in `status` (see [`is_recorder`]).
pub fn parse(status: &DiagnosticStatus) -> RecorderReport {
    let get = |key: &str| {
        status
            .values
            .iter()
            .rev()
            .find(|kv| kv.key == key)
            .map(|kv| kv.value.trim())
    };
    let text = |key: &str| {
        get(key)
            .filter(|v| !v.is_empty())
            .map(|v| shorten(v, TEXT_MAX).into_owned())
    };
    let count = |key: &str| get(key).and_then(|v| v.parse::<u64>().ok());
    let real = |key: &str| {
        get(key)
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| v.is_finite() && *v >= 0.0)
    };
    RecorderReport {
        level: status.level,
        message: shorten(status.message.trim(), TEXT_MAX).into_owned(),
        state: RecState::parse(get("state").unwrap_or("")),
        task: get("task").map(|t| shorten(t, TASK_MAX).into_owned()),
        episode: count("episode"),
        episodes: count("episodes"),
        frames: count("frames"),
        elapsed_s: real("elapsed_s"),
        dropped: count("dropped"),
        dropped_total: count("dropped_total"),
        fps: real("fps"),
        root: text("root").or_else(|| {
            let h = status.hardware_id.trim();
            (!h.is_empty()).then(|| shorten(h, TEXT_MAX).into_owned())
        }),
        cameras: get("cameras").map(|c| shorten(c, TEXT_MAX).into_owned()),
        last: text("last"),
        reason: text("reason"),
    }
}

/// A call of the card's on the recorder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordOp {
    /// the `task` parameter set, then `start_episode`
    Start,
    /// `save_episode`
    Save,
    /// `discard_episode`
    Discard,
}

impl RecordOp {
    /// `start`, `save`, `discard`.
    pub fn name(self) -> &'static str {
        match self {
            RecordOp::Start => "start",
            RecordOp::Save => "save",
            RecordOp::Discard => "discard",
        }
    }

    /// The recorder's service for it (`start_episode`), under its node's name.
    pub fn service(self) -> &'static str {
        match self {
            RecordOp::Start => "start_episode",
            RecordOp::Save => "save_episode",
            RecordOp::Discard => "discard_episode",
        }
    }
}

/// What the loop is to do on the recorder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RecordWork {
    /// Set `task`, then call `start_episode`.
    Start {
        /// the task text
        task: String,
    },
    /// Call `save_episode`.
    Save,
    /// Call `discard_episode`.
    Discard,
}

impl RecordWork {
    /// Which call.
    pub fn op(&self) -> RecordOp {
        match self {
            RecordWork::Start { .. } => RecordOp::Start,
            RecordWork::Save => RecordOp::Save,
            RecordWork::Discard => RecordOp::Discard,
        }
    }
}

/// How a call ended: the recorder's message (`Ok`: it did it), or its refusal, or why
/// there was no answer (a timeout, no such service, the parameter refused).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RecordDone {
    /// the call
    pub op: RecordOp,
    /// its outcome
    pub result: Result<String, String>,
}

/// The task a start is to set: the field's text, trimmed; refused when empty, longer
/// than [`TASK_MAX`] characters, or with control characters (what the recorder refuses
/// too).
pub fn check_task(task: &str) -> Result<String, String> {
    let t = task.trim();
    if t.is_empty() {
        return Err(
            "record: type the task of the episode first (what the arm is shown doing)".into(),
        );
    }
    if t.chars().count() > TASK_MAX {
        return Err(format!(
            "record: the task is longer than {TASK_MAX} characters"
        ));
    }
    if t.chars().any(char::is_control) {
        return Err("record: the task has control characters (a line break, a tab)".into());
    }
    Ok(t.to_string())
}

/// The card: the recorder's last report, the call in flight, the last call's outcome.
#[derive(Debug)]
pub struct RecordCard {
    node: String,
    report: Option<(RecorderReport, Instant)>,
    busy: Option<(RecordOp, Instant)>,
    outcome: Option<(RecordOp, Result<String, String>)>,
    /// whether the recorder was up when the view was last made
    shown_up: bool,
}

impl RecordCard {
    /// The card of the recorder node named `node`.
    pub fn new(node: &str) -> RecordCard {
        RecordCard {
            node: node.to_string(),
            report: None,
            busy: None,
            outcome: None,
            shown_up: false,
        }
    }

    /// The recorder's node name.
    pub fn node(&self) -> &str {
        &self.node
    }

    /// Read a `diagnostics` status: `true` when it was the recorder's.
    pub fn on_status(&mut self, status: &DiagnosticStatus, now: Instant) -> bool {
        if !is_recorder(status, &self.node) {
            return false;
        }
        self.report = Some((parse(status), now));
        true
    }

    /// The recorder was heard within [`UP_WITHIN`].
    pub fn up(&self, now: Instant) -> bool {
        self.report
            .as_ref()
            .is_some_and(|(_, at)| now.saturating_duration_since(*at) < UP_WITHIN)
    }

    /// Whether the recorder's being up changed since the last view (the loop then sends
    /// the card again).
    pub fn up_changed(&self, now: Instant) -> bool {
        self.up(now) != self.shown_up
    }

    fn state(&self) -> Option<&RecState> {
        self.report.as_ref().map(|(r, _)| &r.state)
    }

    /// Whether `op` may be asked now: the recorder up, no call in flight, and its state
    /// the one `op` needs (idle to start, recording to save or discard); else why not.
    pub fn allowed(&self, op: RecordOp, now: Instant) -> Result<(), String> {
        if !self.up(now) {
            return Err(format!(
                "record: no recorder running (no report from the node `{}` on diagnostics within {} s)",
                self.node,
                UP_WITHIN.as_secs()
            ));
        }
        if let Some((busy, _)) = self.busy {
            return Err(format!(
                "record: the recorder has not answered the last {} yet",
                busy.name()
            ));
        }
        let state = self
            .state()
            .cloned()
            .unwrap_or(RecState::Other(String::new()));
        let ok = match op {
            RecordOp::Start => state == RecState::Idle,
            RecordOp::Save | RecordOp::Discard => state == RecState::Recording,
        };
        if ok {
            return Ok(());
        }
        let why = match &state {
            RecState::Stopped => "recording is stopped (see the reason)".to_string(),
            RecState::Waiting => "the recorder waits for its inputs (see the reason)".into(),
            RecState::Recording => "an episode is being recorded: save or discard it first".into(),
            RecState::Saving => "an episode is being saved".into(),
            RecState::Idle => "no episode is being recorded".into(),
            RecState::Other(s) => format!("the recorder's state is `{s}`"),
        };
        Err(format!("record: cannot {} now: {why}", op.name()))
    }

    /// A browser asks for `op` (with the task field's text for a start): the work for
    /// the loop, or why not.
    pub fn request(
        &mut self,
        op: RecordOp,
        task: Option<&str>,
        now: Instant,
    ) -> Result<RecordWork, String> {
        self.allowed(op, now)?;
        let work = match op {
            RecordOp::Start => RecordWork::Start {
                task: check_task(task.unwrap_or(""))?,
            },
            RecordOp::Save => RecordWork::Save,
            RecordOp::Discard => RecordWork::Discard,
        };
        self.busy = Some((op, now));
        Ok(work)
    }

    /// A call ended.
    pub fn on_done(&mut self, done: RecordDone) {
        self.busy = None;
        self.outcome = Some((done.op, done.result));
    }

    /// What the page shows.
    pub fn view(&mut self, now: Instant) -> RecordView {
        let up = self.up(now);
        self.shown_up = up;
        let (r, age) = match &self.report {
            Some((r, at)) => (Some(r), Some(now.saturating_duration_since(*at))),
            None => (None, None),
        };
        let can = |op| self.allowed(op, now).is_ok();
        let note = if up {
            None
        } else if r.is_some() {
            Some(format!(
                "the recorder `{}` is not reporting any more (last heard {:.0} s ago): is it running?",
                self.node,
                age.unwrap_or_default().as_secs_f64()
            ))
        } else {
            Some(format!(
                "no recorder running: nothing heard from the node `{}` (README: Recording demonstrations)",
                self.node
            ))
        };
        RecordView {
            node: self.node.clone(),
            up,
            note,
            state: r.map(|r| r.state.as_str().to_string()),
            level: r.map(|r| r.level),
            message: r.map(|r| r.message.clone()),
            task: r.and_then(|r| r.task.clone()),
            episode: r.and_then(|r| r.episode),
            episodes: r.and_then(|r| r.episodes),
            frames: r.and_then(|r| r.frames),
            elapsed_s: r.and_then(|r| r.elapsed_s),
            age_s: age.map(|a| a.as_secs_f64()),
            dropped: r.and_then(|r| r.dropped),
            dropped_total: r.and_then(|r| r.dropped_total),
            fps: r.and_then(|r| r.fps),
            root: r.and_then(|r| r.root.clone()),
            cameras: r.and_then(|r| r.cameras.clone()),
            last: r.and_then(|r| r.last.clone()),
            reason: r.and_then(|r| r.reason.clone()),
            busy: self.busy.map(|(op, _)| op.name()),
            can_start: can(RecordOp::Start),
            can_save: can(RecordOp::Save),
            can_discard: can(RecordOp::Discard),
            call: self.outcome.as_ref().map(|(op, result)| RecordCallView {
                op: op.name(),
                ok: result.is_ok(),
                text: shorten(
                    match result {
                        Ok(t) | Err(t) => t,
                    },
                    TEXT_MAX,
                )
                .into_owned(),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_msgs::diagnostic_msgs::KeyValue;

    fn status(name: &str, level: u8, values: &[(&str, &str)]) -> DiagnosticStatus {
        DiagnosticStatus {
            level,
            name: name.into(),
            message: "recording episode 3".into(),
            hardware_id: "/data/eezybot_mk2".into(),
            values: values
                .iter()
                .map(|(k, v)| KeyValue {
                    key: (*k).into(),
                    value: (*v).into(),
                })
                .collect(),
        }
    }

    const RECORDING: &[(&str, &str)] = &[
        ("state", "recording"),
        ("task", "pick the cube"),
        ("episode", "3"),
        ("episodes", "3"),
        ("frames", "412"),
        ("elapsed_s", "13.7"),
        ("dropped", "2"),
        ("dropped_total", "5"),
        ("fps", "30"),
        ("root", "/data/eezybot_mk2"),
        ("cameras", "observation.images.camera"),
        ("last", "saved episode 2 (300 frames, 10.0 s)"),
    ];

    #[test]
    fn a_report_is_read_key_by_key() {
        let r = parse(&status("recorder", 1, RECORDING));
        assert_eq!(r.state, RecState::Recording);
        assert_eq!(r.level, 1);
        assert_eq!(r.task.as_deref(), Some("pick the cube"));
        assert_eq!(
            (r.episode, r.episodes, r.frames),
            (Some(3), Some(3), Some(412))
        );
        assert_eq!(r.elapsed_s, Some(13.7));
        assert_eq!((r.dropped, r.dropped_total), (Some(2), Some(5)));
        assert_eq!(r.fps, Some(30.0));
        assert_eq!(r.root.as_deref(), Some("/data/eezybot_mk2"));
        assert_eq!(r.cameras.as_deref(), Some("observation.images.camera"));
        assert_eq!(
            r.last.as_deref(),
            Some("saved episode 2 (300 frames, 10.0 s)")
        );
        assert_eq!(r.reason, None);
    }

    #[test]
    fn bad_values_are_unknown_not_a_lost_report() {
        let r = parse(&status(
            "recorder",
            2,
            &[
                ("state", "exploded"),
                ("episode", "-1"),
                ("episodes", "many"),
                ("elapsed_s", "NaN"),
                ("fps", "-30"),
                ("frames", ""),
                ("reason", "disk full: 0 bytes left on /data"),
            ],
        ));
        assert_eq!(r.state, RecState::Other("exploded".into()));
        assert_eq!((r.episode, r.episodes, r.frames), (None, None, None));
        assert_eq!((r.elapsed_s, r.fps), (None, None));
        // no root key: the hardware id is the dataset root
        assert_eq!(r.root.as_deref(), Some("/data/eezybot_mk2"));
        assert_eq!(
            r.reason.as_deref(),
            Some("disk full: 0 bytes left on /data")
        );
        let r = parse(&status("recorder", 0, &[]));
        assert_eq!(r.state, RecState::Other(String::new()));
        let long = "x".repeat(10_000);
        let r = parse(&status(
            "recorder",
            0,
            &[("task", &long), ("reason", &long)],
        ));
        assert!(r.task.unwrap().len() < 700);
        assert!(r.reason.unwrap().len() < 400);
    }

    #[test]
    fn the_recorder_is_found_by_its_node_name() {
        let s = |name: &str| status(name, 0, &[]);
        assert!(is_recorder(&s("recorder"), "recorder"));
        assert!(is_recorder(&s("recorder: episodes"), "recorder"));
        assert!(is_recorder(&s("rec2"), "rec2"));
        assert!(!is_recorder(&s("recorder"), "rec2"));
        assert!(!is_recorder(&s("recorder_old"), "recorder"));
        assert!(!is_recorder(
            &s("compute_ik: inverse kinematics"),
            "recorder"
        ));
    }

    /// (can_start, can_save, can_discard) of the card with a report in `state`.
    fn buttons(card: &mut RecordCard, now: Instant) -> (bool, bool, bool) {
        let v = card.view(now);
        (v.can_start, v.can_save, v.can_discard)
    }

    #[test]
    fn the_buttons_follow_the_recorder_s_state() {
        let t0 = Instant::now();
        let mut card = RecordCard::new("recorder");
        // nobody heard: everything off, and the card says so
        assert_eq!(buttons(&mut card, t0), (false, false, false));
        let v = card.view(t0);
        assert!(!v.up && v.note.unwrap().contains("no recorder running"));
        assert!(v.state.is_none());
        for (state, expected) in [
            ("waiting", (false, false, false)),
            ("idle", (true, false, false)),
            ("recording", (false, true, true)),
            ("saving", (false, false, false)),
            ("stopped", (false, false, false)),
            ("rebooting", (false, false, false)),
        ] {
            assert!(card.on_status(&status("recorder", 0, &[("state", state)]), t0));
            assert_eq!(buttons(&mut card, t0), expected, "{state}");
            assert_eq!(card.view(t0).state.as_deref(), Some(state));
        }
        // another node's report changes nothing
        assert!(!card.on_status(
            &status("compute_ik: inverse kinematics", 0, &[("state", "idle")]),
            t0
        ));
        assert_eq!(card.view(t0).state.as_deref(), Some("rebooting"));
        // silent for UP_WITHIN: off again, with what was last heard
        card.on_status(&status("recorder", 0, &[("state", "idle")]), t0);
        assert!(!card.up_changed(t0));
        let later = t0 + UP_WITHIN;
        assert!(card.up_changed(later));
        let v = card.view(later);
        assert!(!v.up && (v.can_start, v.can_save) == (false, false));
        assert!(v.note.unwrap().contains("not reporting any more"));
        assert_eq!(v.state.as_deref(), Some("idle"));
        assert!(!card.up_changed(later));
    }

    #[test]
    fn one_call_at_a_time_and_its_outcome_is_shown() {
        let t0 = Instant::now();
        let mut card = RecordCard::new("recorder");
        let why = card.request(RecordOp::Start, Some("pick"), t0).unwrap_err();
        assert!(why.contains("no recorder running"), "{why}");
        card.on_status(&status("recorder", 0, &[("state", "idle")]), t0);
        // the task is checked before anything is sent
        for bad in ["", "   ", "a\nb", &"x".repeat(TASK_MAX + 1)] {
            assert!(
                card.request(RecordOp::Start, Some(bad), t0).is_err(),
                "{bad:?}"
            );
        }
        assert!(card.request(RecordOp::Start, None, t0).is_err());
        assert!(card
            .request(RecordOp::Save, None, t0)
            .unwrap_err()
            .contains("no episode"));
        let work = card.request(RecordOp::Start, Some("  pick the cube "), t0);
        assert_eq!(
            work,
            Ok(RecordWork::Start {
                task: "pick the cube".into()
            })
        );
        let v = card.view(t0);
        assert_eq!(v.busy, Some("start"));
        assert_eq!(
            (v.can_start, v.can_save, v.can_discard),
            (false, false, false)
        );
        // a second click while the first call runs is refused
        let why = card.request(RecordOp::Start, Some("pick"), t0).unwrap_err();
        assert!(why.contains("not answered the last start"), "{why}");
        card.on_done(RecordDone {
            op: RecordOp::Start,
            result: Ok("recording episode 0: pick the cube".into()),
        });
        card.on_status(&status("recorder", 0, &[("state", "recording")]), t0);
        let v = card.view(t0);
        assert_eq!(v.busy, None);
        let call = v.call.unwrap();
        assert_eq!((call.op, call.ok), ("start", true));
        assert_eq!(call.text, "recording episode 0: pick the cube");
        assert_eq!(
            (v.can_start, v.can_save, v.can_discard),
            (false, true, true)
        );
        assert_eq!(card.request(RecordOp::Save, None, t0), Ok(RecordWork::Save));
        // a call that timed out is shown as failed, and the buttons come back
        card.on_done(RecordDone {
            op: RecordOp::Save,
            result: Err("no answer from /recorder/save_episode within 30 s".into()),
        });
        let v = card.view(t0);
        let call = v.call.unwrap();
        assert_eq!((call.op, call.ok), ("save", false));
        assert!(call.text.contains("no answer"));
        assert!(v.can_save);
    }

    #[test]
    fn the_view_carries_the_report_and_its_age() {
        let t0 = Instant::now();
        let mut card = RecordCard::new("recorder");
        card.on_status(&status("recorder", 0, RECORDING), t0);
        let v = card.view(t0 + Duration::from_millis(300));
        assert_eq!(v.episode, Some(3));
        assert_eq!(v.episodes, Some(3));
        assert_eq!(v.frames, Some(412));
        assert_eq!(v.elapsed_s, Some(13.7));
        assert!((v.age_s.unwrap() - 0.3).abs() < 1e-9);
        assert_eq!((v.dropped, v.dropped_total), (Some(2), Some(5)));
        assert_eq!(v.task.as_deref(), Some("pick the cube"));
        assert_eq!(v.message.as_deref(), Some("recording episode 3"));
        assert_eq!(v.node, "recorder");
    }

    /// The recording card's fields, as `web/panel.js`'s `showRecorder()` reads them.
    #[test]
    fn the_recording_card_is_the_message_the_page_reads() {
        use crate::message::ToClient;
        use serde_json::json;
        let t0 = std::time::Instant::now();
        let mut card = RecordCard::new("recorder");
        let kv = |k: &str, v: &str| KeyValue {
            key: k.into(),
            value: v.into(),
        };
        card.on_status(
            &DiagnosticStatus {
                level: 0,
                name: "recorder".into(),
                message: "recording episode 3".into(),
                hardware_id: "/d".into(),
                values: vec![
                    kv("state", "recording"),
                    kv("episode", "3"),
                    kv("elapsed_s", "1.5"),
                ],
            },
            t0,
        );
        card.on_done(RecordDone {
            op: RecordOp::Start,
            result: Ok("recording episode 3: pick".into()),
        });
        let v: serde_json::Value =
            serde_json::from_str(&ToClient::Recorder(Box::new(card.view(t0))).to_text()).unwrap();
        assert_eq!(
            v,
            json!({"t": "recorder", "node": "recorder", "up": true, "note": null,
                   "state": "recording", "level": 0, "message": "recording episode 3",
                   "task": null, "episode": 3, "episodes": null, "frames": null,
                   "elapsed_s": 1.5, "age_s": 0.0, "dropped": null, "dropped_total": null,
                   "fps": null, "root": "/d", "cameras": null, "last": null, "reason": null,
                   "busy": null, "can_start": false, "can_save": true, "can_discard": true,
                   "call": {"op": "start", "ok": true, "text": "recording episode 3: pick"}})
        );
    }
}
