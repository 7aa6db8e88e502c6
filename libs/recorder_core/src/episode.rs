//! The recorder's episodes as a state machine: start, save and discard (from the panel,
//! the command line or `recorder/*_episode` services), optionally an episode while the
//! leader's deadman is held, and a save that fails (a full disk) stopping the recording
//! with its reason. Pure: the node does the effects and reports how they ended.
//!
//! ```
//! use recorder_core::episode::{Effect, Episodes, Request};
//!
//! let mut e = Episodes::new("pick the cube", false);
//! let fx = e.request(Request::Start { task: None }, 1_000).unwrap();
//! assert_eq!(fx, [Effect::Begin { task: "pick the cube".into(), t0_ns: 1_000 }]);
//! assert!(e.request(Request::Start { task: None }, 2_000).is_err()); // already recording
//! let fx = e.request(Request::Save, 5_000).unwrap();
//! assert_eq!(fx, [Effect::Save]);
//! e.saved(Ok(120));
//! assert_eq!((e.status().episodes, e.status().recording), (1, false));
//! ```

/// What a user asks.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Request {
    /// Begin an episode, of this task (`None`: the `task` parameter's).
    Start {
        /// The task string LeRobot stores with the episode.
        task: Option<String>,
    },
    /// End the episode and keep it.
    Save,
    /// End the episode and throw it away.
    Discard,
}

/// What the node must do, in order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Effect {
    /// Start the sampler's grid at `t0_ns` and write frames for `task`.
    Begin {
        /// The episode's task.
        task: String,
        /// The episode's start (frame 0), ns.
        t0_ns: i64,
    },
    /// Stop the grid, write the episode out, then call [`Episodes::saved`].
    Save,
    /// Stop the grid and throw the episode's frames away.
    Discard,
}

/// A request that cannot be done now, with why.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// Start while an episode runs or is being saved.
    #[error("an episode is already {0}: save or discard it first")]
    Busy(&'static str),
    /// Save or discard with no episode.
    #[error("no episode is being recorded")]
    NotRecording,
    /// An empty task, or one LeRobot could not store.
    #[error("the task must be 1 to {max} characters of text, without control characters", max = TASK_MAX)]
    Task,
    /// The last save failed: recording is stopped until it is acknowledged.
    #[error("recording stopped: {0}")]
    Stopped(String),
}

/// The longest task string taken.
pub const TASK_MAX: usize = 500;

/// Where the episodes are.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Nothing recorded now.
    Idle,
    /// An episode runs.
    Recording {
        /// Its task.
        task: String,
        /// Its start, ns.
        t0_ns: i64,
        /// Started by the leader's deadman (released: saved).
        by_deadman: bool,
    },
    /// An episode is being written out.
    Saving,
    /// A save failed (a full disk): nothing more is recorded until [`Episodes::resume`].
    Stopped(String),
}

/// What the panel and `diagnostics` show.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Status {
    /// An episode runs.
    pub recording: bool,
    /// The running (or last) episode's task.
    pub task: String,
    /// Episodes saved in this session.
    pub episodes: u64,
    /// Episodes discarded in this session.
    pub discarded: u64,
    /// The running episode's start, ns (the panel shows the time since).
    pub since_ns: Option<i64>,
    /// Why recording stopped, when it did.
    pub stopped: Option<String>,
}

/// The episodes of one recorder.
#[derive(Clone, Debug)]
pub struct Episodes {
    default_task: String,
    deadman_episodes: bool,
    phase: Phase,
    last_task: String,
    saved: u64,
    discarded: u64,
    /// A save failed and its episode is still in the writer (save it again or discard it).
    unsaved: bool,
}

impl Episodes {
    /// Episodes of `default_task` unless a start names one; with `deadman_episodes`, an
    /// episode runs while the leader's deadman is held.
    pub fn new(default_task: &str, deadman_episodes: bool) -> Episodes {
        Episodes {
            default_task: default_task.to_string(),
            deadman_episodes,
            phase: Phase::Idle,
            last_task: default_task.to_string(),
            saved: 0,
            discarded: 0,
            unsaved: false,
        }
    }

    /// The task of the episodes started without one (the `task` parameter, changed at
    /// run time); the running episode keeps its own.
    pub fn set_default_task(&mut self, task: &str) {
        self.default_task = task.to_string();
        if !matches!(self.phase, Phase::Recording { .. } | Phase::Saving) {
            self.last_task = task.to_string();
        }
    }

    /// Whether the leader's deadman runs episodes.
    pub fn deadman_episodes(&self) -> bool {
        self.deadman_episodes
    }

    /// Let the leader's deadman run episodes, or not (an episode it runs goes on until
    /// saved or discarded otherwise).
    pub fn set_deadman_episodes(&mut self, on: bool) {
        self.deadman_episodes = on;
    }

    /// The phase now.
    pub fn phase(&self) -> &Phase {
        &self.phase
    }

    /// A user's request at `now_ns`.
    pub fn request(&mut self, r: Request, now_ns: i64) -> Result<Vec<Effect>, Refused> {
        match (r, &self.phase) {
            // the episode whose save failed: save it again (room was made) or discard it
            (Request::Save, Phase::Stopped(_)) if self.unsaved => {
                self.phase = Phase::Saving;
                Ok(vec![Effect::Save])
            }
            (Request::Discard, Phase::Stopped(_)) if self.unsaved => {
                self.phase = Phase::Idle;
                self.unsaved = false;
                self.discarded += 1;
                Ok(vec![Effect::Discard])
            }
            (Request::Start { .. }, Phase::Stopped(why)) if self.unsaved => Err(Refused::Stopped(
                format!("{why} (save or discard the episode not saved first)"),
            )),
            // asking to record again after a stop is the user's go-ahead (the disk has room)
            (Request::Start { task }, Phase::Stopped(_)) => {
                let task = task.unwrap_or_else(|| self.default_task.clone());
                self.begin(task, now_ns, false)
            }
            (_, Phase::Stopped(why)) => Err(Refused::Stopped(why.clone())),
            (Request::Start { task }, Phase::Idle) => {
                let task = task.unwrap_or_else(|| self.default_task.clone());
                self.begin(task, now_ns, false)
            }
            (Request::Start { .. }, Phase::Recording { .. }) => Err(Refused::Busy("recording")),
            (Request::Start { .. }, Phase::Saving) => Err(Refused::Busy("being saved")),
            (Request::Save, Phase::Recording { .. }) => {
                self.phase = Phase::Saving;
                Ok(vec![Effect::Save])
            }
            (Request::Discard, Phase::Recording { .. }) => {
                self.phase = Phase::Idle;
                self.discarded += 1;
                Ok(vec![Effect::Discard])
            }
            (Request::Save | Request::Discard, _) => Err(Refused::NotRecording),
        }
    }

    /// The leader's deadman changed (`held`). With deadman episodes, pressing it starts
    /// an episode of the default task and releasing it saves that episode; an episode
    /// started otherwise is not touched.
    pub fn deadman(&mut self, held: bool, now_ns: i64) -> Vec<Effect> {
        if !self.deadman_episodes {
            return vec![];
        }
        match (&self.phase, held) {
            (Phase::Idle, true) => self
                .begin(self.default_task.clone(), now_ns, true)
                .unwrap_or_default(),
            (
                Phase::Recording {
                    by_deadman: true, ..
                },
                false,
            ) => {
                self.phase = Phase::Saving;
                vec![Effect::Save]
            }
            _ => vec![],
        }
    }

    /// How the last [`Effect::Save`] ended: the frames written, or why it failed. A
    /// failure stops recording with that reason (what was saved before stays).
    pub fn saved(&mut self, outcome: Result<u64, String>) {
        if self.phase != Phase::Saving {
            return;
        }
        match outcome {
            Ok(_) => {
                self.saved += 1;
                self.unsaved = false;
                self.phase = Phase::Idle;
            }
            Err(why) => {
                self.unsaved = true;
                self.phase = Phase::Stopped(why);
            }
        }
    }

    /// Writing failed while recording (a full disk): stop, keep nothing of the running
    /// episode. Returns the effect that ends it.
    pub fn failed(&mut self, why: &str) -> Vec<Effect> {
        let running = matches!(self.phase, Phase::Recording { .. });
        self.phase = Phase::Stopped(why.to_string());
        if running {
            self.discarded += 1;
            vec![Effect::Discard]
        } else {
            vec![]
        }
    }

    /// Record again after a stop (the user freed the disk).
    pub fn resume(&mut self) {
        if matches!(self.phase, Phase::Stopped(_)) {
            self.phase = Phase::Idle;
        }
    }

    /// What to show.
    pub fn status(&self) -> Status {
        let (recording, since_ns, stopped) = match &self.phase {
            Phase::Recording { t0_ns, .. } => (true, Some(*t0_ns), None),
            Phase::Stopped(why) => (false, None, Some(why.clone())),
            Phase::Idle | Phase::Saving => (false, None, None),
        };
        Status {
            recording,
            task: self.last_task.clone(),
            episodes: self.saved,
            discarded: self.discarded,
            since_ns,
            stopped,
        }
    }

    fn begin(
        &mut self,
        task: String,
        t0_ns: i64,
        by_deadman: bool,
    ) -> Result<Vec<Effect>, Refused> {
        let task = task.trim().to_string();
        if task.is_empty() || task.chars().count() > TASK_MAX || task.chars().any(char::is_control)
        {
            return Err(Refused::Task);
        }
        self.last_task = task.clone();
        self.phase = Phase::Recording {
            task: task.clone(),
            t0_ns,
            by_deadman,
        };
        Ok(vec![Effect::Begin { task, t0_ns }])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_request_in_every_phase() {
        use Request::*;
        fn start() -> Request {
            Start { task: None }
        }
        fn idle() -> Episodes {
            Episodes::new("t", false)
        }
        fn recording() -> Episodes {
            let mut e = idle();
            e.request(start(), 0).unwrap();
            e
        }
        fn saving() -> Episodes {
            let mut e = recording();
            e.request(Save, 1).unwrap();
            e
        }
        fn stopped() -> Episodes {
            let mut e = saving();
            e.saved(Err("disk full".into()));
            e
        }
        type Case = (fn() -> Episodes, Request, Result<Vec<Effect>, Refused>);
        let begin = Ok(vec![Effect::Begin {
            task: "t".into(),
            t0_ns: 5,
        }]);
        let cases: Vec<Case> = vec![
            (idle, start(), begin),
            (idle, Save, Err(Refused::NotRecording)),
            (idle, Discard, Err(Refused::NotRecording)),
            (recording, start(), Err(Refused::Busy("recording"))),
            (recording, Save, Ok(vec![Effect::Save])),
            (recording, Discard, Ok(vec![Effect::Discard])),
            (saving, start(), Err(Refused::Busy("being saved"))),
            (saving, Save, Err(Refused::NotRecording)),
            (saving, Discard, Err(Refused::NotRecording)),
            (
                stopped,
                start(),
                Err(Refused::Stopped(
                    "disk full (save or discard the episode not saved first)".into(),
                )),
            ),
            (stopped, Save, Ok(vec![Effect::Save])),
            (stopped, Discard, Ok(vec![Effect::Discard])),
        ];
        for (make, request, expect) in cases {
            let mut e = make();
            let before = e.phase().clone();
            assert_eq!(
                e.request(request.clone(), 5),
                expect,
                "{before:?} + {request:?}"
            );
        }
    }

    #[test]
    fn a_task_is_named_by_the_start_or_the_parameter_and_checked() {
        let mut e = Episodes::new("default", false);
        let fx = e
            .request(
                Request::Start {
                    task: Some("  stack the cubes ".into()),
                },
                0,
            )
            .unwrap();
        assert_eq!(
            fx,
            [Effect::Begin {
                task: "stack the cubes".into(),
                t0_ns: 0
            }]
        );
        e.request(Request::Discard, 1).unwrap();
        for bad in ["", "   ", "a\nb", &"x".repeat(TASK_MAX + 1)] {
            let r = e.request(
                Request::Start {
                    task: Some(bad.to_string()),
                },
                2,
            );
            assert_eq!(r, Err(Refused::Task), "{bad:?}");
            assert_eq!(e.phase(), &Phase::Idle);
        }
        assert_eq!(e.status().discarded, 1);
    }

    #[test]
    fn the_deadman_runs_an_episode_while_held_when_asked_to() {
        let mut off = Episodes::new("t", false);
        assert!(off.deadman(true, 0).is_empty());
        let mut e = Episodes::new("t", true);
        assert_eq!(
            e.deadman(true, 10),
            [Effect::Begin {
                task: "t".into(),
                t0_ns: 10
            }]
        );
        assert!(e.deadman(true, 11).is_empty(), "held again: nothing new");
        assert_eq!(e.deadman(false, 20), [Effect::Save]);
        e.saved(Ok(3));
        assert_eq!(e.status().episodes, 1);
        // an episode the user started is not ended by the deadman
        e.request(Request::Start { task: None }, 30).unwrap();
        assert!(e.deadman(false, 31).is_empty());
        assert!(e.deadman(true, 32).is_empty());
        assert!(e.status().recording);
    }

    #[test]
    fn a_failed_save_stops_recording_with_its_reason_until_resumed() {
        let mut e = Episodes::new("t", false);
        e.request(Request::Start { task: None }, 0).unwrap();
        e.request(Request::Save, 1).unwrap();
        e.saved(Ok(10));
        e.request(Request::Start { task: None }, 2).unwrap();
        assert_eq!(e.failed("No space left on device"), [Effect::Discard]);
        let s = e.status();
        assert_eq!(
            (s.episodes, s.discarded),
            (1, 1),
            "the saved one stays counted"
        );
        assert_eq!(s.stopped.as_deref(), Some("No space left on device"));
        assert!(e.request(Request::Save, 3).is_err(), "nothing left to save");
        // asking to record again is the go-ahead
        assert!(e.request(Request::Start { task: None }, 4).is_ok());
        assert_eq!(e.status().since_ns, Some(4));
        // a save that fails keeps its episode: saved again once there is room
        e.request(Request::Save, 5).unwrap();
        e.saved(Err("No space left on device".into()));
        assert!(e.request(Request::Start { task: None }, 6).is_err());
        assert_eq!(e.request(Request::Save, 7), Ok(vec![Effect::Save]));
        e.saved(Ok(3));
        assert_eq!(e.status().episodes, 2);
    }
}
