//! A subscription's samples as a node's inputs: every node's loop takes one stream of
//! its own input type, each topic's samples mapped into it.

use crate::topics::Topic;
use eezybot_msgs::RosMessage;
use futures::stream::{BoxStream, StreamExt};
use ros2_client::Subscription;

/// Every sample of `subscription` as an input: one that was read through `sample`, one
/// that could not be read through `unreadable`, with the error (`{:?}`).
pub fn inputs<'a, M: RosMessage, I: Send + 'a>(
    subscription: &'a Subscription<M>,
    sample: impl Fn(M) -> I + Send + 'a,
    unreadable: impl Fn(String) -> I + Send + 'a,
) -> BoxStream<'a, I> {
    subscription
        .async_stream()
        .map(move |r| match r {
            Ok((m, _)) => sample(m),
            Err(e) => unreadable(format!("{e:?}")),
        })
        .boxed()
}

/// The samples of a latched state (`estop`) as inputs: one that cannot be read is
/// left out with a warning, so that the state is never guessed from a broken sample
/// (the current one stands).
pub fn readable_inputs<'a, M: RosMessage, I: Send + 'a>(
    subscription: &'a Subscription<M>,
    topic: &Topic<M>,
    sample: impl Fn(M) -> I + Send + Sync + 'a,
) -> BoxStream<'a, I> {
    let topic = topic.name;
    subscription
        .async_stream()
        .filter_map(move |r| {
            let input = match r {
                Ok((m, _)) => Some(sample(m)),
                Err(e) => {
                    log::warn!("unreadable sample on {topic} ignored: {e:?}");
                    None
                }
            };
            std::future::ready(input)
        })
        .boxed()
}
