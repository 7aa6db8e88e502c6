//! Commands that arrive together are a burst: after a network outage, DDS repairs
//! what the outage held back, in datagrams a fraction of a millisecond apart and
//! in rounds some milliseconds apart. A node that moves an arm applies only the
//! newest command of a burst, never the stale ones on the way. [`take_burst`]
//! takes what arrived together (never waiting); the node decides which of its inputs
//! supersede which ([`latest_wins`]); [`Lateness`] recognises a command that arrives late
//! (its stamp is old), which the node holds back ([`Held`]) for at most [`HOLD_LATE`]
//! in case a newer one follows.

use futures::{FutureExt, Stream, StreamExt};

/// `first` and every input that is ready with it (arrived together: a burst). Never
/// waits: a lone input, or a live stream at any rate, goes at once. A burst that DDS
/// repairs in several rounds is handled by [`Lateness`] and [`Held`]: its commands
/// are late, and each round's newest replaces the one held.
pub fn take_burst<T, S>(first: T, inputs: &mut S) -> Vec<T>
where
    S: Stream<Item = T> + Unpin,
{
    let mut batch = vec![first];
    while let Some(Some(more)) = inputs.next().now_or_never() {
        batch.push(more);
    }
    batch
}

/// Keep, in order, the inputs that no later input of the same `kind` supersedes
/// (`kind` None: never superseded, e.g. an e-stop). Returns them and how many were
/// dropped.
///
/// # Examples
/// ```
/// use ros_plumbing::burst::latest_wins;
/// let (kept, dropped) = latest_wins(vec![1, 10, 2, 3, 20], |i| (*i < 10).then_some("small"));
/// assert_eq!((kept, dropped), (vec![10, 3, 20], 2));
/// ```
pub fn latest_wins<T, K: PartialEq>(
    batch: Vec<T>,
    kind: impl Fn(&T) -> Option<K>,
) -> (Vec<T>, usize) {
    let kinds: Vec<Option<K>> = batch.iter().map(&kind).collect();
    let mut dropped = 0;
    let kept = batch
        .into_iter()
        .enumerate()
        .filter(|(n, _)| {
            let superseded = kinds[*n]
                .as_ref()
                .is_some_and(|k| kinds[n + 1..].iter().any(|later| later.as_ref() == Some(k)));
            dropped += usize::from(superseded);
            !superseded
        })
        .map(|(_, i)| i)
        .collect();
    (kept, dropped)
}

// The late-hold rule lives in `command_gate` (one copy for every node); `Held` stays
// here for the nodes that have not moved to `command_gate::CommandGate` yet.
pub use command_gate::{Lateness, HOLD_LATE, LATE_BY};

/// The late command a node holds back for [`HOLD_LATE`] in case a newer one follows.
/// A later late command replaces it but does not extend the deadline: whatever the
/// stamps say, the newest command reaches the arm at most [`HOLD_LATE`] after the
/// first one was held, so a stream that always looks late (coarse stamps, another
/// clock) is delayed, never starved.
#[derive(Debug)]
pub struct Held<T> {
    held: Option<(T, tokio::time::Instant)>,
}

impl<T> Default for Held<T> {
    fn default() -> Self {
        Self { held: None }
    }
}

impl<T> Held<T> {
    /// Hold `item` (a late command). Returns whether it replaced a held one.
    pub fn hold(&mut self, item: T, now: tokio::time::Instant) -> bool {
        let until = self.held.take().map(|(_, until)| until);
        let replaced = until.is_some();
        self.held = Some((item, until.unwrap_or(now + HOLD_LATE)));
        replaced
    }

    /// Drop the held command (a live one superseded it, or the e-stop). Returns
    /// whether there was one.
    pub fn discard(&mut self) -> bool {
        self.held.take().is_some()
    }

    /// When the held command is due, if there is one.
    pub fn deadline(&self) -> Option<tokio::time::Instant> {
        self.held.as_ref().map(|(_, until)| *until)
    }

    /// The held command, if its deadline has come.
    pub fn take_due(&mut self, now: tokio::time::Instant) -> Option<T> {
        if self.deadline().is_some_and(|until| until <= now) {
            self.held.take().map(|(item, _)| item)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use futures::stream;
    use std::time::Duration;

    // tokio's clock, paused: only an await with nothing else to do moves it on
    #[tokio::test(start_paused = true)]
    async fn what_is_ready_comes_together_and_nothing_waits() {
        // two ready now, one more 1 ms later: not waited for
        let later = stream::once(async {
            tokio::time::sleep(Duration::from_millis(1)).await;
            4
        });
        let mut s = Box::pin(
            stream::iter(vec![2, 3])
                .chain(later)
                .chain(stream::pending()),
        );
        let t = tokio::time::Instant::now();
        assert_eq!(take_burst(1, &mut s), vec![1, 2, 3]);
        // the later one stayed in the stream, and comes once its 1 ms has passed
        assert_eq!(t.elapsed(), Duration::ZERO);
        assert_eq!(s.next().await, Some(4));
        assert_eq!(t.elapsed(), Duration::from_millis(1));
        let mut lone = stream::pending::<u32>();
        assert_eq!(take_burst(5, &mut lone), vec![5]);
    }

    #[test]
    fn a_stream_of_late_commands_is_delayed_never_starved() {
        // one late command every 20 ms: each replaces the held one, and the newest
        // is due 30 ms after the first was held, not 30 ms after the last
        let t0 = tokio::time::Instant::now();
        let mut held = Held::default();
        let mut applied = vec![];
        for i in 0..10u32 {
            let now = t0 + Duration::from_millis(20 * u64::from(i));
            if let Some(c) = held.take_due(now) {
                applied.push((i, c));
            }
            held.hold(i, now);
        }
        // every second step applies the newest of the two held since the last one
        assert_eq!(applied, [(2, 1), (4, 3), (6, 5), (8, 7)]);
        assert_eq!(held.take_due(t0 + Duration::from_millis(180)), None);
        assert_eq!(held.take_due(t0 + Duration::from_millis(190)), Some(9));
        held.hold(10, t0);
        assert!(held.discard());
        assert_eq!(held.deadline(), None);
    }

    #[test]
    fn unkinded_inputs_are_never_dropped() {
        let (kept, dropped) = latest_wins(vec![1, 2, 3], |_| None::<u8>);
        assert_eq!((kept, dropped), (vec![1, 2, 3], 0));
    }
}
