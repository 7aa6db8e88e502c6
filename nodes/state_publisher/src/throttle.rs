//! The `publish_frequency` throttle of `tf`, a pure machine on an injected clock: at
//! most one tf message per interval; the transforms of the samples that come sooner
//! are merged (latest wins per frame) and published at the end of the interval.

use eezybot_msgs::geometry_msgs::TransformStamped;
use eezybot_msgs::tf2_msgs::TFMessage;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// A `tf` message to publish now, and when the oldest `joint_states` sample in it was
/// taken (for the latency figures).
#[derive(Clone, Debug, PartialEq)]
pub struct Flush {
    /// the message
    pub msg: TFMessage,
    /// when its oldest sample was taken
    pub taken: Instant,
}

/// Throttles `tf` to [`TfThrottle::min_interval`]. See the [module](self).
#[derive(Clone, Debug, Default)]
pub struct TfThrottle {
    min_interval: Option<Duration>,
    last_tf: Option<Instant>,
    pending: BTreeMap<String, TransformStamped>,
    pending_since: Option<Instant>,
}

impl TfThrottle {
    /// A throttle at `publish_frequency` messages a second (0: none, one per sample).
    pub fn new(publish_frequency: f64) -> Self {
        TfThrottle {
            min_interval: Self::interval(publish_frequency),
            ..TfThrottle::default()
        }
    }

    /// The shortest time between two messages at `publish_frequency` (0: no limit).
    pub fn interval(publish_frequency: f64) -> Option<Duration> {
        (publish_frequency > 0.0).then(|| Duration::from_secs_f64(1.0 / publish_frequency))
    }

    /// The shortest time between two messages, if any.
    pub fn min_interval(&self) -> Option<Duration> {
        self.min_interval
    }

    /// Change the frequency (the parameter changed); what is pending stays pending.
    pub fn set_frequency(&mut self, publish_frequency: f64) {
        self.min_interval = Self::interval(publish_frequency);
    }

    /// Forget what is pending (a new URDF: other frames).
    pub fn clear(&mut self) {
        self.pending.clear();
        self.pending_since = None;
    }

    /// The transforms of a sample taken at `taken`, handed in at `now`: a message to
    /// publish now (with anything pending merged in), or nothing if the last one went
    /// out less than an interval ago (then they wait for [`TfThrottle::flush_at`]).
    pub fn offer(
        &mut self,
        transforms: Vec<TransformStamped>,
        taken: Instant,
        now: Instant,
    ) -> Option<Flush> {
        if transforms.is_empty() {
            return None;
        }
        let too_soon = match (self.min_interval, self.last_tf) {
            (Some(iv), Some(last)) => now.saturating_duration_since(last) < iv,
            _ => false,
        };
        if too_soon {
            self.merge(transforms);
            self.pending_since.get_or_insert(taken);
            return None;
        }
        let transforms = if self.pending.is_empty() {
            transforms
        } else {
            self.merge(transforms);
            std::mem::take(&mut self.pending).into_values().collect()
        };
        self.last_tf = Some(now);
        self.pending_since = None;
        Some(Flush {
            msg: TFMessage { transforms },
            taken,
        })
    }

    /// When the pending transforms are due, if any are.
    pub fn flush_at(&self) -> Option<Instant> {
        match (self.min_interval, self.last_tf, self.pending.is_empty()) {
            (Some(iv), Some(last), false) => Some(last + iv),
            _ => None,
        }
    }

    /// The pending transforms as one message, if [`TfThrottle::flush_at`] has come at
    /// `now`.
    pub fn flush(&mut self, now: Instant) -> Option<Flush> {
        if self.flush_at().is_none_or(|at| now < at) {
            return None;
        }
        let msg = TFMessage {
            transforms: std::mem::take(&mut self.pending).into_values().collect(),
        };
        self.last_tf = Some(now);
        let taken = self.pending_since.take().unwrap_or(now);
        Some(Flush { msg, taken })
    }

    fn merge(&mut self, transforms: Vec<TransformStamped>) {
        for t in transforms {
            self.pending.insert(t.child_frame_id.clone(), t);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_msgs::geometry_msgs::Transform;
    use eezybot_msgs::std_msgs::Header;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// A transform of `child` whose x says which sample it came from.
    fn tf(child: &str, sample: f64) -> TransformStamped {
        let mut transform = Transform::default();
        transform.translation.x = sample;
        TransformStamped {
            header: Header::default(),
            child_frame_id: child.into(),
            transform,
        }
    }

    fn frames(f: &Flush) -> Vec<(String, f64)> {
        f.msg
            .transforms
            .iter()
            .map(|t| (t.child_frame_id.clone(), t.transform.translation.x))
            .collect()
    }

    #[test]
    fn without_a_frequency_every_sample_is_published_at_once() {
        let t0 = Instant::now();
        let mut th = TfThrottle::new(0.0);
        for i in 0..5 {
            let now = t0 + ms(i);
            let f = th.offer(vec![tf("a", i as f64)], now, now).unwrap();
            assert_eq!(frames(&f), [("a".to_string(), i as f64)]);
            assert_eq!(th.flush_at(), None);
        }
        assert_eq!(th.offer(vec![], t0, t0 + ms(9)), None, "nothing to publish");
    }

    #[test]
    fn at_10_hz_a_100_hz_stream_is_merged_and_published_every_100_ms() {
        let t0 = Instant::now();
        let mut th = TfThrottle::new(10.0);
        let mut published = vec![];
        for i in 0..100u64 {
            let now = t0 + ms(10 * i);
            // the shell flushes when the deadline has come, then hands in the sample
            if th.flush_at().is_some_and(|at| at <= now) {
                published.push((now, th.flush(now).unwrap()));
            }
            // sample i moves joint a; every third also joint b
            let mut sample = vec![tf("a", i as f64)];
            if i % 3 == 0 {
                sample.push(tf("b", i as f64));
            }
            if let Some(f) = th.offer(sample, now - ms(1), now) {
                published.push((now, f));
            }
        }
        let times: Vec<_> = published.iter().map(|(t, _)| *t - t0).collect();
        assert_eq!(times, (0..10).map(|k| ms(100 * k)).collect::<Vec<_>>());
        // the first goes at once; each later one holds the newest of each frame since,
        // taken from the oldest sample in it (for the latency)
        assert_eq!(
            frames(&published[0].1),
            [("a".into(), 0.0), ("b".into(), 0.0)]
        );
        assert_eq!(
            frames(&published[1].1),
            [("a".into(), 9.0), ("b".into(), 9.0)]
        );
        assert_eq!(published[1].1.taken, t0 + ms(10) - ms(1));
        assert_eq!(
            frames(&published[2].1),
            [("a".into(), 19.0), ("b".into(), 18.0)]
        );
    }

    #[test]
    fn a_sample_after_a_quiet_interval_goes_at_once_with_what_was_pending() {
        let t0 = Instant::now();
        let mut th = TfThrottle::new(20.0); // 50 ms
        assert!(th.offer(vec![tf("a", 1.0)], t0, t0).is_some());
        assert_eq!(th.offer(vec![tf("b", 2.0)], t0 + ms(10), t0 + ms(10)), None);
        assert_eq!(th.flush_at(), Some(t0 + ms(50)));
        assert_eq!(th.flush(t0 + ms(49)), None, "not due yet");
        // the shell was late to flush: the next sample takes the pending one along
        let f = th
            .offer(vec![tf("a", 3.0)], t0 + ms(60), t0 + ms(60))
            .unwrap();
        assert_eq!(frames(&f), [("a".into(), 3.0), ("b".into(), 2.0)]);
        assert_eq!(f.taken, t0 + ms(60), "latency from the sample that sent it");
        assert_eq!(th.flush_at(), None);
    }

    #[test]
    fn a_new_frequency_applies_to_what_follows_and_clear_forgets_the_pending() {
        let t0 = Instant::now();
        let mut th = TfThrottle::new(10.0);
        assert!(th.offer(vec![tf("a", 1.0)], t0, t0).is_some());
        assert_eq!(th.offer(vec![tf("a", 2.0)], t0, t0 + ms(20)), None);
        th.set_frequency(50.0); // 20 ms
        assert_eq!(th.min_interval(), Some(ms(20)));
        assert_eq!(th.flush_at(), Some(t0 + ms(20)));
        th.clear();
        assert_eq!(th.flush_at(), None);
        assert_eq!(th.flush(t0 + ms(100)), None);
        th.set_frequency(0.0);
        assert!(th.offer(vec![tf("a", 3.0)], t0, t0 + ms(21)).is_some());
    }
}
