//! [`TopicPublisher`]: a publisher whose failed writes are logged, never fatal.

use eezybot_msgs::RosMessage;
use ros2_client::{Node, Publisher};

/// A publisher on one topic of the contract. A node's loop must go on when a write
/// fails (a full send window, a DDS error): [`publish`](Self::publish) logs a warning
/// naming the topic instead of returning the error.
pub struct TopicPublisher<M: RosMessage> {
    publisher: Publisher<M>,
    topic: &'static str,
}

impl<M: RosMessage> TopicPublisher<M> {
    /// Wrap a publisher created on `topic` (the name as declared, for the log).
    pub fn new(publisher: Publisher<M>, topic: &'static str) -> Self {
        TopicPublisher { publisher, topic }
    }

    /// How many subscriptions are matched now.
    pub fn get_subscription_count(&self, node: &Node) -> usize {
        self.publisher.get_subscription_count(node)
    }

    /// The matched subscriptions now, each by its GUID's 16 bytes, in order. Unlike a
    /// count, these tell a subscription that replaced another between two looks.
    pub fn subscriptions(&self, node: &Node) -> Vec<[u8; 16]> {
        self.publisher
            .get_subscriptions(node)
            .into_iter()
            .map(|g| g.to_bytes())
            .collect()
    }

    /// The topic's name, as declared (before namespace and remapping).
    pub fn topic(&self) -> &'static str {
        self.topic
    }

    /// Wait until every matched reliable subscription has acknowledged everything
    /// published so far, at most `max_wait`: false on timeout. A process that publishes
    /// and exits at once can otherwise lose its last sample.
    pub async fn delivered(&self, max_wait: std::time::Duration) -> bool {
        matches!(
            tokio::time::timeout(max_wait, self.publisher.async_wait_for_acknowledgments()).await,
            Ok(Ok(true))
        )
    }

    /// The ros2-client publisher, for what this type does not wrap.
    pub fn inner(&self) -> &Publisher<M> {
        &self.publisher
    }
}

impl<M: RosMessage + std::fmt::Debug> TopicPublisher<M> {
    /// Publish `msg`; a failed write is logged as `could not publish TOPIC: …`.
    pub fn publish(&self, msg: M) {
        if let Err(e) = self.publisher.publish(msg) {
            log::warn!("could not publish {}: {e:?}", self.topic);
        }
    }
}
