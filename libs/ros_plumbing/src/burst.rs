//! Commands that arrive together are a burst: after a network outage, the datagrams
//! the sender's kernel queued for the unreachable host, then DDS' repairs of what the
//! outage held back, a fraction of a millisecond apart and in rounds some milliseconds
//! apart. A node that moves an arm applies only the
//! newest command of a burst, never the stale ones on the way. [`take_burst`]
//! takes what arrived together (never waiting); the node decides which of its inputs
//! supersede which ([`latest_wins`]); [`Lateness`] recognises a command that arrives late
//! (its stamp is old), which the node holds back until no newer one followed for
//! [`HOLD_LATE`] (`command_gate::CommandGate`, the one copy of that rule).

use futures::{FutureExt, Stream, StreamExt};

/// `first` and every input that is ready with it (arrived together: a burst). Never
/// waits: a lone input, or a live stream at any rate, goes at once. A burst that comes
/// in several rounds is handled by [`Lateness`] and `command_gate::CommandGate`:
/// its commands are late, and each round's newest replaces the one held.
pub fn take_burst<T, S>(first: T, inputs: &mut S) -> Vec<T>
where
    S: Stream<Item = T> + Unpin,
{
    let mut batch = vec![first];
    batch.extend(ready_now(inputs));
    batch
}

/// Every input that is ready now, in order (none: empty). Never waits. A node handles
/// these before a deadline that came due with them: on a busy host the deadline (e.g.
/// "no sample for 50 ms") and the input that meets it can be ready at once, and
/// `select!` picks among ready branches at random.
pub fn ready_now<T, S>(inputs: &mut S) -> Vec<T>
where
    S: Stream<Item = T> + Unpin,
{
    let mut batch = vec![];
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

// The late-hold rule lives in `command_gate` (one copy for every node).
pub use command_gate::{Lateness, HOLD_LATE, LATE_BY};

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

    #[tokio::test(start_paused = true)]
    async fn ready_now_takes_what_is_ready_and_may_take_nothing() {
        let later = stream::once(async {
            tokio::time::sleep(Duration::from_millis(1)).await;
            3
        });
        let mut s = Box::pin(
            stream::iter(vec![1, 2])
                .chain(later)
                .chain(stream::pending()),
        );
        assert_eq!(ready_now(&mut s), vec![1, 2]);
        assert_eq!(ready_now(&mut s), Vec::<i32>::new());
        tokio::time::sleep(Duration::from_millis(1)).await;
        assert_eq!(ready_now(&mut s), vec![3]);
    }

    #[test]
    fn unkinded_inputs_are_never_dropped() {
        let (kept, dropped) = latest_wins(vec![1, 2, 3], |_| None::<u8>);
        assert_eq!((kept, dropped), (vec![1, 2, 3], 0));
    }
}
