#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]
//!
//! # Example
//! ```
//! use recorder_core::{Need, Sampler, SamplerConfig, Tick};
//!
//! let ms = 1_000_000i64;
//! let config = SamplerConfig { fps: 10, ..SamplerConfig::default() };
//! let mut s = Sampler::new(config, &[("state", Need::Required), ("leader", Need::Optional)]).unwrap();
//! s.start(0);
//! s.offer(0, -5 * ms, 1.0); // state, stamped 5 ms before the episode began
//! s.offer(0, 95 * ms, 2.0);
//! s.offer(0, 120 * ms, 3.0); // after frame 1's instant (100 ms): not for frame 1
//! let ticks = s.poll(100 * ms + 50 * ms); // frame 1 is due at 100 ms + the 50 ms wait
//! assert_eq!(ticks.len(), 2);
//! let Tick::Frame(f) = &ticks[1] else { panic!("{ticks:?}") };
//! assert_eq!((f.index, f.values[0], f.values[1]), (1, Some(2.0), None));
//! assert_eq!(f.ages_ns[0], Some(5 * ms));
//! ```

use std::collections::VecDeque;
use std::time::Duration;

pub mod episode;

/// How many samples an input keeps: enough for a second at 200 Hz; a flood of samples
/// pushes out the oldest, never grows memory.
pub const HISTORY: usize = 256;

/// Whether a frame needs an input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Need {
    /// Too old or missing: the frame is dropped.
    Required,
    /// Too old or missing: the frame has `None` for it.
    Optional,
    /// A command, which stands until the next one: the newest sample at or before the
    /// instant whatever its age (`None` before the first).
    Held,
}

/// The sampler's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplerConfig {
    /// Frames a second (LeRobot's `fps`).
    pub fps: u32,
    /// The oldest a sample may be at a frame's instant.
    pub max_staleness: Duration,
    /// How long after a frame's instant it is decided at the earliest (for samples still
    /// on their way).
    pub wait: Duration,
    /// How long after its instant a frame may wait for a live input's samples: a frame is
    /// decided once every live input (one with a sample within `max_staleness` before the
    /// instant) has a sample stamped after it, or at this at the latest.
    pub max_wait: Duration,
}

impl Default for SamplerConfig {
    fn default() -> Self {
        SamplerConfig {
            fps: 30,
            max_staleness: Duration::from_millis(100),
            wait: Duration::from_millis(50),
            max_wait: Duration::from_millis(500),
        }
    }
}

/// A setting the sampler cannot work with.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ConfigError {
    /// `fps` is 0 or over 1000.
    #[error("fps {0} is outside 1..=1000")]
    Fps(u32),
    /// No inputs, or more than 64.
    #[error("{0} inputs: a recorder samples 1 to 64")]
    Inputs(usize),
    /// A staleness limit under one frame, a wait longer than the staleness limit, or a
    /// longest wait shorter than the wait.
    #[error("max_staleness {max_staleness:?} must be at least one frame ({frame:?}) and at least wait ({wait:?}), and max_wait at least wait")]
    Staleness {
        /// The limit.
        max_staleness: Duration,
        /// One frame at the fps.
        frame: Duration,
        /// The wait.
        wait: Duration,
    },
}

/// A frame: the instant `t0 + index / fps` and each input's sample for it.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame<V> {
    /// Frame number in the episode, from 0 (dropped ones included).
    pub index: u64,
    /// The frame's instant, ns on the inputs' clock.
    pub t_ns: i64,
    /// Per input: its sample (`None`: an optional input without a fresh one).
    pub values: Vec<Option<V>>,
    /// Per input: how old the sample used was at the instant (`None` with the value).
    pub ages_ns: Vec<Option<i64>>,
}

/// A frame left out: which required inputs were too old (their age at the instant,
/// `None`: nothing heard from them yet).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Dropped {
    /// Frame number in the episode.
    pub index: u64,
    /// The frame's instant, ns.
    pub t_ns: i64,
    /// The inputs that were too old, by name, with their samples' ages.
    pub stale: Vec<(String, Option<i64>)>,
}

/// What a grid instant gave.
#[derive(Clone, Debug, PartialEq)]
pub enum Tick<V> {
    /// A frame for the dataset.
    Frame(Frame<V>),
    /// A frame dropped, counted.
    Dropped(Dropped),
}

/// What the sampler did, for diagnostics.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Frames made.
    pub frames: u64,
    /// Frames dropped.
    pub dropped: u64,
    /// Per input, the frames it dropped (a frame two inputs dropped counts for both).
    pub dropped_by: Vec<u64>,
    /// Samples offered for an input that does not exist, or stamped too far back to
    /// be used for any frame to come.
    pub ignored: u64,
}

struct Input<V> {
    name: String,
    need: Need,
    /// (stamp ns, value), oldest first, stamps non-decreasing.
    samples: VecDeque<(i64, V)>,
}

/// The grid and the newest samples of each input (see the crate's documentation).
pub struct Sampler<V> {
    config: SamplerConfig,
    inputs: Vec<Input<V>>,
    /// The episode's start, ns (`None`: not started).
    t0: Option<i64>,
    /// The episode's end, ns: no frame after it (`None`: not ending).
    end: Option<i64>,
    /// The next frame to decide.
    next: u64,
    counters: Counters,
}

impl<V: Clone> Sampler<V> {
    /// A sampler of `inputs` (name, need), in that order.
    pub fn new(config: SamplerConfig, inputs: &[(&str, Need)]) -> Result<Self, ConfigError> {
        if config.fps == 0 || config.fps > 1000 {
            return Err(ConfigError::Fps(config.fps));
        }
        if inputs.is_empty() || inputs.len() > 64 {
            return Err(ConfigError::Inputs(inputs.len()));
        }
        let frame = Duration::from_nanos(1_000_000_000 / u64::from(config.fps));
        if config.max_staleness < frame
            || config.max_staleness < config.wait
            || config.max_wait < config.wait
        {
            return Err(ConfigError::Staleness {
                max_staleness: config.max_staleness,
                frame,
                wait: config.wait,
            });
        }
        Ok(Sampler {
            config,
            inputs: inputs
                .iter()
                .map(|(name, need)| Input {
                    name: name.to_string(),
                    need: *need,
                    samples: VecDeque::new(),
                })
                .collect(),
            t0: None,
            end: None,
            next: 0,
            counters: Counters {
                dropped_by: vec![0; inputs.len()],
                ..Counters::default()
            },
        })
    }

    /// Begin an episode at `t0_ns`: frame 0 is that instant. The samples heard before
    /// stay (a frame may use one stamped before the start); the counters go on.
    pub fn start(&mut self, t0_ns: i64) {
        self.t0 = Some(t0_ns);
        self.end = None;
        self.next = 0;
    }

    /// End the episode at `end_ns`: the frames up to it are still decided as they come
    /// due; then [`Sampler::finished`].
    pub fn end_at(&mut self, end_ns: i64) {
        if self.t0.is_some() {
            self.end = Some(end_ns);
        }
    }

    /// Whether an ending episode has had all its frames decided.
    pub fn finished(&self) -> bool {
        match (self.end, self.instant(self.next)) {
            (Some(end), Some(t)) => t > end,
            _ => false,
        }
    }

    /// End the episode: no more frames until the next [`Sampler::start`].
    pub fn stop(&mut self) {
        self.t0 = None;
        self.end = None;
    }

    /// Whether an episode is running.
    pub fn running(&self) -> bool {
        self.t0.is_some()
    }

    /// The instant of frame `index` of the running episode, ns.
    pub fn instant(&self, index: u64) -> Option<i64> {
        let t0 = self.t0?;
        let offset = i128::from(index) * 1_000_000_000 / i128::from(self.config.fps);
        i64::try_from(i128::from(t0) + offset).ok()
    }

    /// A sample of input `input` (its index in [`Sampler::new`]'s list), stamped
    /// `stamp_ns`. Samples may come out of order; one stamped too far back for any
    /// frame to come is ignored (and counted).
    pub fn offer(&mut self, input: usize, stamp_ns: i64, value: V) {
        let horizon = self.horizon();
        let Some(i) = self.inputs.get_mut(input) else {
            self.counters.ignored += 1;
            return;
        };
        // the newest sample at or before the horizon is still needed (for the next
        // frame): a sample older than that one is not
        let superseded = i
            .samples
            .front()
            .is_some_and(|(s, _)| stamp_ns < *s && horizon.is_some_and(|h| *s <= h));
        if superseded {
            self.counters.ignored += 1;
            return;
        }
        let at = i.samples.partition_point(|(s, _)| *s <= stamp_ns);
        i.samples.insert(at, (stamp_ns, value));
        if i.samples.len() > HISTORY {
            i.samples.pop_front();
        }
        Self::prune(i, horizon);
    }

    /// The frames due by `now_ns`, in order: a frame is due from its instant plus the
    /// wait, once every live input has a sample stamped after the instant (no sample
    /// stamped before it is still to come: an input's stamps do not go back), or from its
    /// instant plus `max_wait` whatever came.
    pub fn poll(&mut self, now_ns: i64) -> Vec<Tick<V>> {
        let wait = i64::try_from(self.config.wait.as_nanos()).unwrap_or(i64::MAX);
        let max_wait = i64::try_from(self.config.max_wait.as_nanos()).unwrap_or(i64::MAX);
        let mut out = vec![];
        while let Some(t) = self.instant(self.next) {
            if self.end.is_some_and(|end| t > end) {
                break;
            }
            if t.saturating_add(wait) > now_ns
                || (t.saturating_add(max_wait) > now_ns && self.awaits_live_input(t))
            {
                break;
            }
            out.push(self.decide(self.next, t));
            self.next += 1;
        }
        let horizon = self.horizon();
        for i in &mut self.inputs {
            Self::prune(i, horizon);
        }
        out
    }

    /// When the next frame may be due (poll then, and again after samples came), ns.
    pub fn next_due(&self) -> Option<i64> {
        let wait = i64::try_from(self.config.wait.as_nanos()).unwrap_or(i64::MAX);
        let max_wait = i64::try_from(self.config.max_wait.as_nanos()).unwrap_or(i64::MAX);
        let t = self.instant(self.next)?;
        if self.end.is_some_and(|end| t > end) {
            return None;
        }
        let earliest = t.saturating_add(wait);
        if self.awaits_live_input(t) {
            Some(t.saturating_add(max_wait).max(earliest))
        } else {
            Some(earliest)
        }
    }

    /// Whether an input that is live at instant `t` (its newest sample within
    /// `max_staleness` before it) has nothing stamped after `t` yet.
    fn awaits_live_input(&self, t: i64) -> bool {
        let max_age = i64::try_from(self.config.max_staleness.as_nanos()).unwrap_or(i64::MAX);
        self.inputs.iter().any(|i| {
            i.samples
                .back()
                .is_some_and(|(s, _)| *s <= t && t - *s <= max_age)
        })
    }

    /// What the sampler did so far.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// The inputs' names, in order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.inputs.iter().map(|i| i.name.as_str())
    }

    fn decide(&mut self, index: u64, t: i64) -> Tick<V> {
        let max_age = i64::try_from(self.config.max_staleness.as_nanos()).unwrap_or(i64::MAX);
        let mut values = Vec::with_capacity(self.inputs.len());
        let mut ages = Vec::with_capacity(self.inputs.len());
        let mut stale = vec![];
        for (k, i) in self.inputs.iter().enumerate() {
            let newest = i.samples.iter().rev().find(|(s, _)| *s <= t);
            let age = newest.map(|(s, _)| t - s);
            match newest {
                Some((_, v)) if i.need == Need::Held || age.is_some_and(|a| a <= max_age) => {
                    values.push(Some(v.clone()));
                    ages.push(age);
                }
                _ if i.need != Need::Required => {
                    values.push(None);
                    ages.push(None);
                }
                _ => {
                    self.counters.dropped_by[k] += 1;
                    stale.push((i.name.clone(), age));
                }
            }
        }
        if stale.is_empty() {
            self.counters.frames += 1;
            Tick::Frame(Frame {
                index,
                t_ns: t,
                values,
                ages_ns: ages,
            })
        } else {
            self.counters.dropped += 1;
            Tick::Dropped(Dropped {
                index,
                t_ns: t,
                stale,
            })
        }
    }

    /// The instant of the next frame to decide (`None`: no episode).
    fn horizon(&self) -> Option<i64> {
        self.instant(self.next)
    }

    /// Drop the samples no frame to come can use: of those at or before the horizon,
    /// only the newest.
    fn prune(i: &mut Input<V>, horizon: Option<i64>) {
        let Some(h) = horizon else {
            // between episodes: the newest sample is all a start needs
            while i.samples.len() > 1 {
                i.samples.pop_front();
            }
            return;
        };
        let at_or_before = i.samples.partition_point(|(s, _)| *s <= h);
        for _ in 1..at_or_before {
            i.samples.pop_front();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const MS: i64 = 1_000_000;

    /// A sampler that decides each frame at its instant plus the wait (max_wait = wait):
    /// the rule of which sample, apart from how long a frame waits for live inputs.
    fn sampler(fps: u32) -> Sampler<i64> {
        let config = SamplerConfig {
            fps,
            max_wait: SamplerConfig::default().wait,
            ..SamplerConfig::default()
        };
        Sampler::new(
            config,
            &[
                ("state", Need::Required),
                ("image", Need::Required),
                ("leader", Need::Optional),
            ],
        )
        .unwrap()
    }

    fn frames(ticks: &[Tick<i64>]) -> Vec<&Frame<i64>> {
        ticks
            .iter()
            .filter_map(|t| match t {
                Tick::Frame(f) => Some(f),
                Tick::Dropped(_) => None,
            })
            .collect()
    }

    #[test]
    fn a_held_input_stands_however_old_and_is_none_before_the_first() {
        let config = SamplerConfig {
            fps: 10,
            max_wait: SamplerConfig::default().wait,
            ..SamplerConfig::default()
        };
        let mut s = Sampler::new(
            config,
            &[("state", Need::Required), ("command", Need::Held)],
        )
        .unwrap();
        s.start(0);
        s.offer(0, -MS, 1);
        let first = s.poll(50 * MS);
        assert_eq!(frames(&first)[0].values, [Some(1), None]);
        s.offer(1, 10 * MS, 7); // one command, then none for 10 s
        for k in 1..100 {
            s.offer(0, k * 100 * MS, 1);
        }
        let ticks = s.poll(10_000 * MS);
        let f = frames(&ticks);
        assert_eq!(f.len(), 99, "no frame dropped for an old command");
        assert!(f.iter().all(|f| f.values[1] == Some(7)));
        assert_eq!(f.last().unwrap().ages_ns[1], Some(9_890 * MS));
    }

    #[test]
    fn the_grid_does_not_drift() {
        let mut s = sampler(30);
        s.start(1_000 * MS);
        assert_eq!(s.instant(0), Some(1_000 * MS));
        assert_eq!(s.instant(1), Some(1_000 * MS + 33_333_333));
        // after an hour, still on k / fps
        assert_eq!(s.instant(30 * 3600), Some(1_000 * MS + 3600 * 1_000 * MS));
    }

    #[test]
    fn a_frame_takes_the_newest_sample_at_or_before_its_instant_never_a_later_one() {
        let mut s = sampler(10);
        s.start(0);
        for (stamp, v) in [(-10, 1), (99, 2), (100, 3), (101, 4)] {
            s.offer(0, stamp * MS, v);
            s.offer(1, stamp * MS, v * 10);
        }
        let ticks = s.poll(150 * MS);
        let f = frames(&ticks);
        assert_eq!(f.len(), 2);
        assert_eq!(f[0].values, [Some(1), Some(10), None]);
        assert_eq!(f[0].ages_ns, [Some(10 * MS), Some(10 * MS), None]);
        // stamped at the instant itself counts; 101 ms does not
        assert_eq!(f[1].values, [Some(3), Some(30), None]);
        assert_eq!(f[1].ages_ns[0], Some(0));
    }

    #[test]
    fn a_frame_waits_for_late_samples_then_is_decided_once() {
        let mut s = sampler(10);
        s.start(0);
        s.offer(0, -MS, 1);
        s.offer(1, -MS, 1);
        assert!(s.poll(49 * MS).is_empty(), "due only at 0 + 50 ms");
        assert_eq!(s.next_due(), Some(50 * MS));
        assert_eq!(frames(&s.poll(50 * MS)).len(), 1);
        assert!(s.poll(50 * MS).is_empty(), "a frame is decided once");
        // a sample for frame 1, stamped 90 ms, arriving at 140 ms, is in time
        s.offer(0, 90 * MS, 2);
        s.offer(1, 90 * MS, 2);
        let t = s.poll(150 * MS);
        assert_eq!(frames(&t)[0].values[0], Some(2));
    }

    #[test]
    fn too_old_drops_the_frame_and_names_the_input_never_fills_it_in() {
        let mut s = sampler(10);
        s.start(0);
        s.offer(0, 0, 1);
        s.offer(1, 0, 1);
        // the image stops after 0 ms; state goes on
        for k in 1..5 {
            s.offer(0, k * 100 * MS, 1 + k);
        }
        let ticks = s.poll(450 * MS);
        assert_eq!(ticks.len(), 5);
        // frame 1: the image is 100 ms old, the limit: kept
        assert!(matches!(&ticks[1], Tick::Frame(f) if f.ages_ns[1] == Some(100 * MS)));
        // frames 2..4: 200, 300, 400 ms old: dropped, the image named
        for (k, t) in ticks.iter().enumerate().skip(2) {
            let Tick::Dropped(d) = t else { panic!("{t:?}") };
            assert_eq!(d.index, k as u64);
            assert_eq!(d.stale, [("image".to_string(), Some(k as i64 * 100 * MS))]);
        }
        assert_eq!(s.counters().frames, 2);
        assert_eq!(s.counters().dropped, 3);
        assert_eq!(s.counters().dropped_by, [0, 3, 0]);
    }

    #[test]
    fn an_input_never_heard_drops_every_frame_an_optional_one_gives_none() {
        let mut s = sampler(10);
        s.start(0);
        s.offer(1, 0, 7);
        s.offer(2, 0, 9); // the leader, optional
        let t = s.poll(50 * MS);
        assert_eq!(
            t,
            [Tick::Dropped(Dropped {
                index: 0,
                t_ns: 0,
                stale: vec![("state".into(), None)]
            })]
        );
        s.offer(0, 80 * MS, 1);
        s.offer(1, 80 * MS, 7);
        let t = s.poll(150 * MS);
        // the leader's sample of 0 ms is 100 ms old at frame 1: still fresh
        assert_eq!(frames(&t)[0].values, [Some(1), Some(7), Some(9)]);
        let t = s.poll(250 * MS);
        // 200 ms old at frame 2: optional, so None, the frame kept
        assert!(
            matches!(&t[0], Tick::Dropped(_)),
            "state and image are 120 ms old"
        );
        s.offer(0, 290 * MS, 2);
        s.offer(1, 290 * MS, 8);
        let t = s.poll(350 * MS);
        assert_eq!(frames(&t)[0].values, [Some(2), Some(8), None]);
    }

    #[test]
    fn a_new_episode_starts_its_grid_at_its_own_start() {
        let mut s = sampler(10);
        s.start(0);
        s.offer(0, 0, 1);
        s.offer(1, 0, 1);
        assert_eq!(s.poll(50 * MS).len(), 1);
        s.stop();
        assert!(s.poll(10_000 * MS).is_empty(), "no frames between episodes");
        assert_eq!(s.next_due(), None);
        s.offer(0, 1_000 * MS, 2);
        s.offer(1, 1_000 * MS, 2);
        s.start(1_010 * MS);
        let t = s.poll(1_060 * MS);
        assert_eq!(frames(&t)[0].index, 0);
        assert_eq!(
            frames(&t)[0].values[0],
            Some(2),
            "a sample from before the start"
        );
    }

    #[test]
    fn bad_settings_are_refused() {
        let bad = |fps, stale_ms, wait_ms| {
            Sampler::<i64>::new(
                SamplerConfig {
                    fps,
                    max_staleness: Duration::from_millis(stale_ms),
                    wait: Duration::from_millis(wait_ms),
                    max_wait: Duration::from_millis(500),
                },
                &[("a", Need::Required)],
            )
            .err()
        };
        assert_eq!(bad(0, 100, 50), Some(ConfigError::Fps(0)));
        assert!(matches!(
            bad(30, 20, 10),
            Some(ConfigError::Staleness { .. })
        ));
        assert!(matches!(
            bad(30, 100, 200),
            Some(ConfigError::Staleness { .. })
        ));
        assert_eq!(bad(30, 100, 50), None);
        assert_eq!(
            Sampler::<i64>::new(SamplerConfig::default(), &[]).err(),
            Some(ConfigError::Inputs(0))
        );
    }

    #[test]
    fn a_frame_waits_for_every_live_input_to_pass_its_instant_up_to_max_wait() {
        let config = SamplerConfig {
            fps: 10,
            ..SamplerConfig::default()
        };
        let inputs = [
            ("state", Need::Required),
            ("image", Need::Required),
            ("leader", Need::Optional),
        ];
        let mut s = Sampler::new(config, &inputs).unwrap();
        s.start(0);
        // state and image live (samples just before frame 0), the leader silent
        s.offer(0, -MS, 1);
        s.offer(1, -MS, 1);
        assert!(
            s.poll(60 * MS).is_empty(),
            "live inputs have not passed frame 0 yet"
        );
        assert_eq!(s.next_due(), Some(500 * MS));
        // a late sample stamped before the instant still makes it in
        s.offer(0, -MS / 2, 2);
        s.offer(0, 5 * MS, 3);
        assert!(
            s.poll(70 * MS).is_empty(),
            "the image has not passed it yet"
        );
        s.offer(1, 20 * MS, 3);
        let t = s.poll(70 * MS);
        assert_eq!(frames(&t)[0].values, [Some(2), Some(1), None]);
        // a live input gone silent: frame 1 waits for it up to max_wait, then is decided
        s.offer(0, 150 * MS, 4);
        assert!(s.poll(599 * MS).is_empty());
        let t = s.poll(600 * MS);
        assert_eq!(frames(&t)[0].values, [Some(3), Some(3), None]);
    }

    #[test]
    fn an_ending_episode_decides_its_last_frames_then_is_finished() {
        let mut s = sampler(10);
        s.start(0);
        s.end_at(250 * MS);
        assert!(!s.finished());
        s.offer(0, 300 * MS, 1);
        s.offer(1, 300 * MS, 1);
        s.offer(0, -MS, 0);
        s.offer(1, -MS, 0);
        let t = s.poll(10_000 * MS);
        assert_eq!(
            t.len(),
            3,
            "frames at 0, 100 and 200 ms: none after the end"
        );
        assert!(s.finished());
        assert_eq!(s.next_due(), None);
    }

    #[test]
    fn a_flood_of_samples_keeps_memory_bounded() {
        let mut s = sampler(30);
        s.start(0);
        for k in 0..100_000 {
            s.offer(0, k * 1_000, k); // 1 MHz, far beyond any topic
        }
        assert!(s.inputs[0].samples.len() <= HISTORY);
        s.offer(7, 0, 0);
        assert_eq!(s.counters().ignored, 1, "no such input");
    }

    proptest! {
        /// Whatever order samples come in, each frame holds, per input, exactly the
        /// newest sample stamped at or before its instant, if that one is fresh enough;
        /// frames come out once each, in order, and every grid instant is a frame or a
        /// drop.
        #[test]
        fn frames_are_the_newest_fresh_samples_in_any_arrival_order(
            stamps in proptest::collection::vec((0usize..2, 0i64..2_000), 1..200),
            shuffle in proptest::collection::vec(0usize..200, 0..200),
        ) {
            let mut order: Vec<usize> = (0..stamps.len()).collect();
            for (i, j) in shuffle.iter().enumerate() {
                let n = order.len();
                order.swap(i % n, j % n);
            }
            let mut s = sampler(20);
            s.start(0);
            // every sample arrives before the first frame is decided
            for &i in &order {
                let (input, ms) = stamps[i];
                s.offer(input, ms * MS, ms);
            }
            let ticks = s.poll(2_100 * MS);
            prop_assert_eq!(ticks.len(), 42); // 0..=2050 ms every 50 ms: 42 instants
            for (k, t) in ticks.iter().enumerate() {
                let instant = k as i64 * 50 * MS;
                let expect: Vec<Option<i64>> = (0..2)
                    .map(|input| {
                        stamps
                            .iter()
                            .filter(|(i, ms)| *i == input && ms * MS <= instant)
                            .map(|(_, ms)| *ms)
                            .max()
                            .filter(|ms| instant - ms * MS <= 100 * MS)
                    })
                    .collect();
                match t {
                    Tick::Frame(f) => {
                        prop_assert_eq!(f.index, k as u64);
                        prop_assert_eq!(&f.values[..2], &expect[..]);
                    }
                    Tick::Dropped(d) => {
                        prop_assert_eq!(d.index, k as u64);
                        prop_assert!(expect.iter().any(Option::is_none));
                    }
                }
            }
        }
    }
}
