//! The recorder's `diagnostics` entry, which the panel shows: its state, the episode
//! in progress, the dataset's episodes and what went wrong.

use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use ros_plumbing::diagnostics::status;

/// Where the recorder is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum State {
    /// Waiting for the first image of each camera (their size) to open the dataset.
    Waiting(String),
    /// The dataset is open; no episode runs.
    Idle,
    /// An episode runs.
    Recording,
    /// An episode is being written out.
    Saving,
    /// Nothing is recorded, for this reason (a refused folder, a full disk).
    Stopped(String),
}

impl State {
    /// The `state` key's value.
    pub fn key(&self) -> &'static str {
        match self {
            State::Waiting(_) => "waiting",
            State::Idle => "idle",
            State::Recording => "recording",
            State::Saving => "saving",
            State::Stopped(_) => "stopped",
        }
    }
}

/// What the entry shows.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// The state.
    pub state: State,
    /// The running episode's task, else the `task` parameter.
    pub task: String,
    /// The running episode's index, else the next one's.
    pub episode: u64,
    /// Episodes in the dataset.
    pub episodes: u64,
    /// Frames of the running episode.
    pub frames: u64,
    /// Seconds since the running episode began.
    pub elapsed_s: f64,
    /// Frames dropped in the running episode.
    pub dropped: u64,
    /// Frames dropped since the node started.
    pub dropped_total: u64,
    /// The last drop's reason (which inputs were how old).
    pub last_drop: Option<String>,
    /// Frames a second.
    pub fps: u32,
    /// The dataset folder.
    pub root: String,
    /// The cameras' feature names.
    pub cameras: Vec<String>,
    /// The last episode action's outcome, or what the start repaired.
    pub last: String,
    /// Something to warn about that is not an error (an interrupted episode recovered).
    pub warning: Option<String>,
}

/// The `diagnostics` status of a recorder named `node`.
pub fn report(node: &str, v: &View) -> DiagnosticStatus {
    let (level, message) = match &v.state {
        State::Stopped(why) => (DiagnosticStatus::ERROR, format!("not recording: {why}")),
        State::Waiting(what) => (DiagnosticStatus::WARN, what.clone()),
        State::Recording if v.dropped > 0 => (
            DiagnosticStatus::WARN,
            format!(
                "recording episode {}: {} frames dropped ({})",
                v.episode,
                v.dropped,
                v.last_drop.as_deref().unwrap_or("inputs too old")
            ),
        ),
        State::Recording => (
            DiagnosticStatus::OK,
            format!("recording episode {} ({:?})", v.episode, v.task),
        ),
        State::Saving => (
            DiagnosticStatus::OK,
            format!("saving episode {}", v.episode),
        ),
        State::Idle => match &v.warning {
            Some(w) => (DiagnosticStatus::WARN, w.clone()),
            None => (
                DiagnosticStatus::OK,
                format!("ready: {} episodes in {}", v.episodes, v.root),
            ),
        },
    };
    let reason = match &v.state {
        State::Stopped(why) | State::Waiting(why) => why.clone(),
        _ => String::new(),
    };
    status(
        level,
        node,
        &v.root,
        &message,
        &[
            ("state", v.state.key().to_string()),
            ("task", v.task.clone()),
            ("episode", v.episode.to_string()),
            ("episodes", v.episodes.to_string()),
            ("frames", v.frames.to_string()),
            ("elapsed_s", format!("{:.1}", v.elapsed_s)),
            ("dropped", v.dropped.to_string()),
            ("dropped_total", v.dropped_total.to_string()),
            ("fps", v.fps.to_string()),
            ("root", v.root.clone()),
            ("cameras", v.cameras.join(",")),
            ("last", v.last.clone()),
            ("reason", reason),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(state: State) -> View {
        View {
            state,
            task: "pick".into(),
            episode: 2,
            episodes: 2,
            frames: 0,
            elapsed_s: 0.0,
            dropped: 0,
            dropped_total: 0,
            last_drop: None,
            fps: 30,
            root: "/d".into(),
            cameras: vec!["observation.images.camera".into()],
            last: String::new(),
            warning: None,
        }
    }

    fn value<'a>(s: &'a DiagnosticStatus, k: &str) -> &'a str {
        &s.values.iter().find(|v| v.key == k).unwrap().value
    }

    #[test]
    fn the_entry_names_the_state_and_why() {
        let s = report("recorder", &view(State::Idle));
        assert_eq!(
            (s.level, value(&s, "state")),
            (DiagnosticStatus::OK, "idle")
        );
        let s = report("recorder", &view(State::Stopped("disk full".into())));
        assert_eq!(s.level, DiagnosticStatus::ERROR);
        assert_eq!(value(&s, "reason"), "disk full");
        assert!(s.message.contains("disk full"));
        let mut v = view(State::Recording);
        v.dropped = 3;
        v.last_drop = Some("servo_state 0.31 s old".into());
        let s = report("recorder", &v);
        assert_eq!(s.level, DiagnosticStatus::WARN);
        assert!(s.message.contains("3 frames dropped"), "{}", s.message);
        assert_eq!(value(&s, "cameras"), "observation.images.camera");
    }
}
