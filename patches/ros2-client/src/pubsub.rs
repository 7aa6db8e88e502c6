#[cfg(any(feature = "mio_06", feature = "mio_1"))]
use std::io;
use std::marker::PhantomData;

#[cfg(feature = "mio_06")]
use rustdds::mio::{Evented, Poll, PollOpt, Ready, Token};
#[cfg(feature = "mio_1")]
use rustdds::mio1;
use rustdds::{serialization::CdrDeserializeSeedDecoder, *};
use futures::{
  Future, pin_mut,
  stream::{FusedStream, StreamExt},
};
use serde::{Serialize, de::DeserializeOwned};

use super::{gid::Gid, message_info::MessageInfo, node::Node};
use crate::error::{ReadError, ReadResult, WriteResult};

/// A ROS2 Publisher
///
/// Corresponds to a simplified [`DataWriter`](rustdds::no_key::DataWriter)in
/// DDS
pub struct Publisher<M: Serialize> {
  datawriter: no_key::DataWriterCdr<M>,
}

impl<M: Serialize> Publisher<M> {
  // These must be created from Node
  pub(crate) fn new(datawriter: no_key::DataWriterCdr<M>) -> Publisher<M> {
    Publisher { datawriter }
  }

  pub fn publish(&self, message: M) -> WriteResult<(), M> {
    self
      .datawriter
      .write(message, Some(Timestamp::now()))
      .map_err(Into::into)
  }

  /// Waits until every matched reliable subscription has acknowledged everything
  /// published so far, at most `max_wait`: `Ok(true)` when they have (at once for a
  /// best-effort publisher, or with no reliable subscription), `Ok(false)` on
  /// timeout. A process that exits right after `publish` can lose the sample
  /// otherwise (rclcpp's `Publisher::wait_for_all_acked`).
  pub fn wait_for_acknowledgments(&self, max_wait: std::time::Duration) -> WriteResult<bool, ()> {
    self
      .datawriter
      .wait_for_acknowledgments(max_wait)
      .map_err(Into::into)
  }

  /// [`Publisher::wait_for_acknowledgments`] without a timeout (bring your own).
  pub async fn async_wait_for_acknowledgments(&self) -> WriteResult<bool, ()> {
    self
      .datawriter
      .async_wait_for_acknowledgments()
      .await
      .map_err(Into::into)
  }

  pub fn assert_liveliness(&self) -> WriteResult<(), ()> {
    self.datawriter.assert_liveliness().map_err(Into::into)
  }

  pub fn guid(&self) -> rustdds::GUID {
    self.datawriter.guid()
  }

  pub fn gid(&self) -> Gid {
    self.guid().into()
  }

  /// Returns the count of currently matched subscribers.
  ///
  /// `my_node` must be the Node that created this Publisher, or the result is
  /// undefined.
  pub fn get_subscription_count(&self, my_node: &Node) -> usize {
    my_node.get_subscription_count(self.guid())
  }

  /// The GUIDs of the currently matched subscriptions, in order (DDS's
  /// `get_matched_subscriptions`). A count cannot tell a subscription that
  /// replaced another between two looks from no change at all; these can.
  ///
  /// `my_node` must be the Node that created this Publisher, or the result is
  /// undefined.
  pub fn get_subscriptions(&self, my_node: &Node) -> Vec<rustdds::GUID> {
    my_node.get_subscriptions(self.guid())
  }

  /// Waits until there is at least one matched subscription on this topic,
  /// possibly forever.
  ///
  /// `my_node` must be the Node that created this Subscription, or the length
  /// of the wait is undefined.
  pub fn wait_for_subscription(&self, my_node: &Node) -> impl Future<Output = ()> + Send {
    my_node.wait_for_reader(self.guid())
  }

  pub async fn async_publish(&self, message: M) -> WriteResult<(), M> {
    self
      .datawriter
      .async_write(message, Some(Timestamp::now()))
      .await
      .map_err(Into::into)
  }
}
// ----------------------------------------------------
// ----------------------------------------------------
// ----------------------------------------------------
// ----------------------------------------------------
// ----------------------------------------------------

/// A ROS2 Subscription
///
/// Corresponds to a (simplified) [`DataReader`](rustdds::no_key::DataReader) in
/// DDS
pub struct Subscription<M> {
  datareader: no_key::SimpleDataReaderCdr<M>,
}

impl<M> Subscription<M>
where
  M: 'static,
{
  // These must be created from Node
  pub(crate) fn new(datareader: no_key::SimpleDataReaderCdr<M>) -> Subscription<M> {
    Subscription { datareader }
  }

  pub fn take_seed<S>(&self, seed: S) -> ReadResult<Option<(M, MessageInfo)>>
  where
    S: for<'de> serde::de::DeserializeSeed<'de, Value = M> + Clone,
    M: 'static,
  {
    self.datareader.drain_read_notifications();
    let decoder = CdrDeserializeSeedDecoder::new(seed, PhantomData::<()>);
    let ds: Option<no_key::DeserializedCacheChange<M>> =
      self.datareader.try_take_one_with(decoder)?;
    Ok(ds.map(dcc_to_value_and_messageinfo))
  }

  // Returns an async Stream of messages with MessageInfo metadata
  pub fn async_stream_seed<'a, S>(
    &'a self,
    seed: S,
  ) -> impl FusedStream<Item = ReadResult<(M, MessageInfo)>> + 'a
  where
    S: for<'de> serde::de::DeserializeSeed<'de, Value = M> + Clone + 'a,
    M: 'static,
  {
    let decoder = CdrDeserializeSeedDecoder::new(seed, PhantomData::<()>);
    self
      .datareader
      .as_async_stream_with(decoder)
      .map(|result| result.map_err(Into::into).map(dcc_to_value_and_messageinfo))
  }
}

impl<M: 'static + DeserializeOwned> Subscription<M> {
  pub fn take(&self) -> ReadResult<Option<(M, MessageInfo)>> {
    self.datareader.drain_read_notifications();
    let ds: Option<no_key::DeserializedCacheChange<M>> = self.datareader.try_take_one()?;
    Ok(ds.map(dcc_to_value_and_messageinfo))
  }

  pub async fn async_take(&self) -> ReadResult<(M, MessageInfo)> {
    let async_stream = self.datareader.as_async_stream();
    pin_mut!(async_stream);
    match async_stream.next().await {
      Some(Err(e)) => Err(e.into()),
      Some(Ok(ds)) => Ok(dcc_to_value_and_messageinfo(ds)),
      // Stream from SimpleDataReader is not supposed to ever end.
      None => {
        read_error_internal!("async_take(): SimpleDataReader value stream unexpectedly ended!")
      }
    }
  }

  // Returns an async Stream of messages with MessageInfo metadata
  pub fn async_stream(&self) -> impl FusedStream<Item = ReadResult<(M, MessageInfo)>> + '_ {
    self
      .datareader
      .as_async_stream()
      .map(|result| result.map_err(Into::into).map(dcc_to_value_and_messageinfo))
  }
}

impl<M> Subscription<M>
where
  M: 'static,
{
  pub fn guid(&self) -> rustdds::GUID {
    self.datareader.guid()
  }

  pub fn gid(&self) -> Gid {
    self.guid().into()
  }

  /// Returns the count of currently matched Publishers.
  ///
  /// `my_node` must be the Node that created this Subscription, or the result
  /// is undefined.
  pub fn get_publisher_count(&self, my_node: &Node) -> usize {
    my_node.get_publisher_count(self.guid())
  }

  /// Waits until there is at least one matched publisher on this topic,
  /// possibly forever.
  ///
  /// `my_node` must be the Node that created this Subscription, or the length
  /// of the wait is undefined.
  pub fn wait_for_publisher(&self, my_node: &Node) -> impl Future<Output = ()> + Send {
    my_node.wait_for_writer(self.guid())
  }
}

// helper
#[inline]
fn dcc_to_value_and_messageinfo<M>(dcc: no_key::DeserializedCacheChange<M>) -> (M, MessageInfo) {
  let mi = MessageInfo::from(&dcc);
  (dcc.into_value(), mi)
}

#[cfg(feature = "mio_06")]
impl<D> Evented for Subscription<D>
where
  D: DeserializeOwned,
{
  // We just delegate all the operations to datareader, since it
  // already implements Evented
  fn register(&self, poll: &Poll, token: Token, interest: Ready, opts: PollOpt) -> io::Result<()> {
    self.datareader.register(poll, token, interest, opts)
  }

  fn reregister(
    &self,
    poll: &Poll,
    token: Token,
    interest: Ready,
    opts: PollOpt,
  ) -> io::Result<()> {
    self.datareader.reregister(poll, token, interest, opts)
  }

  fn deregister(&self, poll: &Poll) -> io::Result<()> {
    self.datareader.deregister(poll)
  }
}

#[cfg(feature = "mio_1")]
impl<D> mio1::event::Source for Subscription<D>
where
  D: DeserializeOwned,
{
  fn register(
    &mut self,
    registry: &mio1::Registry,
    token: mio1::Token,
    interests: mio1::Interest,
  ) -> io::Result<()> {
    mio1::event::Source::register(&mut self.datareader, registry, token, interests)
  }

  fn reregister(
    &mut self,
    registry: &mio1::Registry,
    token: mio1::Token,
    interests: mio1::Interest,
  ) -> io::Result<()> {
    mio1::event::Source::reregister(&mut self.datareader, registry, token, interests)
  }

  fn deregister(&mut self, registry: &mio1::Registry) -> io::Result<()> {
    mio1::event::Source::deregister(&mut self.datareader, registry)
  }
}

#[cfg(test)]
mod tests {
  use super::*;
  use crate::{Context, MessageTypeName, Name, Node, NodeName, NodeOptions};
  use rustdds::Topic;

  fn test_node(name: &str, context: Context) -> Node {
    Node::new(
      NodeName::new("/", name).unwrap(),
      NodeOptions::new().enable_rosout(false),
      context,
    )
    .unwrap()
  }

  /// A std_msgs/String topic named `/name`.
  fn test_topic(node: &mut Node, name: &str) -> Topic {
    node
      .create_topic(
        &Name::new("/", name).unwrap(),
        MessageTypeName::new("std_msgs", "String"),
        &crate::DEFAULT_PUBLISHER_QOS,
      )
      .unwrap()
  }

  // A subscription that replaces another between two looks has a GUID of its own:
  // the count stays 1, the GUIDs tell (compute_ik greets a new joint_states
  // subscriber with the pose; by the count it missed a `gui_bridge once` started
  // while the previous one's reader was being removed, and that one waited 30 s).
  #[test]
  fn a_subscription_that_replaces_another_is_told_apart_by_its_guid() {
    use std::time::{Duration, Instant};

    let node = |name: &str| test_node(name, Context::new().unwrap());
    let topic = |node: &mut Node| test_topic(node, "replaced");
    let mut sender = node("replaced_sender");
    let t = topic(&mut sender);
    let publisher = sender.create_publisher::<String>(&t, None).unwrap();
    let spinner = sender.spinner().unwrap();
    std::thread::spawn(move || futures::executor::block_on(spinner.spin()));
    assert!(publisher.get_subscriptions(&sender).is_empty());

    // (the bound only ends a failure: a removal comes by reliable SEDP)
    let wait_for = |what: &str, want: &dyn Fn(&[rustdds::GUID]) -> bool| {
      let deadline = Instant::now() + Duration::from_secs(60);
      loop {
        let got = publisher.get_subscriptions(&sender);
        if want(&got) {
          return got;
        }
        assert!(Instant::now() < deadline, "{what}: {got:?}");
        std::thread::sleep(Duration::from_millis(10));
      }
    };
    let mut receiver = node("replaced_receiver");
    let t = topic(&mut receiver);
    let first = receiver.create_subscription::<String>(&t, None).unwrap();
    let first_guid = first.guid();
    let got = wait_for("the first match", &|g| !g.is_empty());
    assert_eq!(got, vec![first_guid]);
    assert_eq!(publisher.get_subscription_count(&sender), 1);

    // the subscription deleted (announced by reliable SEDP; a participant that leaves
    // says so best-effort, and if that is lost only its lease ends it), another made
    let second = receiver.create_subscription::<String>(&t, None).unwrap();
    drop(first);
    let got = wait_for("the replacement", &|g| g == [second.guid()]);
    assert_eq!(got, vec![second.guid()]);
    assert_ne!(second.guid(), first_guid);
  }

  // A publisher waits until its subscriptions have what it published: then the
  // sample is in the subscriber's cache (a command-line tool that publishes and
  // exits at once lost its last sample: gui_bridge's `play`).
  #[test]
  fn a_publisher_waits_until_its_subscription_has_the_sample() {
    use std::time::{Duration, Instant};

    use rustdds::DomainParticipantStatusEvent;

    let node = test_node;
    let topic = |node: &mut Node| test_topic(node, "acknowledged");
    let sender_context = Context::new().unwrap();
    let events = sender_context.domain_participant().status_listener();
    let mut sender = node("ack_sender", sender_context);
    let t = topic(&mut sender);
    let publisher = sender.create_publisher::<String>(&t, None).unwrap();
    // nobody subscribes: nothing to wait for
    publisher.publish("to nobody".into()).unwrap();
    assert!(publisher
      .wait_for_acknowledgments(Duration::ZERO)
      .unwrap());

    let mut receiver = node("ack_receiver", Context::new().unwrap());
    let t = topic(&mut receiver);
    let subscription = receiver.create_subscription::<String>(&t, None).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
      match events.try_recv_status() {
        Some(DomainParticipantStatusEvent::RemoteReaderMatched { local_writer, .. })
          if local_writer == publisher.guid() =>
        {
          break
        }
        Some(_) => {}
        None => {
          assert!(Instant::now() < deadline, "the subscription did not match");
          std::thread::sleep(Duration::from_millis(10));
        }
      }
    }
    // (the default QoS keeps the last sample: one at a time)
    for i in 0..3 {
      publisher.publish(format!("sample {i}")).unwrap();
      assert!(publisher
        .wait_for_acknowledgments(Duration::from_secs(10))
        .unwrap());
      let taken = subscription.take().unwrap().map(|(m, _)| m);
      assert_eq!(taken, Some(format!("sample {i}")));
    }
  }
}
