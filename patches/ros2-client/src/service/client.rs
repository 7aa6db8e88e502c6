#[cfg(any(feature = "mio_06", feature = "mio_1"))]
use std::io;
use std::sync::atomic;

#[cfg(feature = "mio_06")]
use rustdds::mio::{Evented, Poll, PollOpt, Ready, Token};
#[cfg(feature = "mio_1")]
use rustdds::mio1;
use rustdds::{rpc::*, *};
#[allow(unused_imports)]
use log::{debug, error, info, warn};
use futures::{StreamExt, join, pin_mut};

use crate::{
  error::{CreateResult, ReadError, ReadResult, WriteError, WriteResult},
  gid::Gid,
  message::Message,
  message_info::MessageInfo,
  node::Node,
  qos::QosProfile,
  service::*,
};

/// Client end of a ROS2 Service
pub struct Client<Req, Resp>
where
  Req: Message,
  Resp: Message,
{
  service_mapping: ServiceMapping,
  request_sender: DataWriterR<RequestWrapper<Req>>,
  response_receiver: SimpleDataReaderR<ResponseWrapper<Resp>>,
  sequence_number_gen: atomic::AtomicI64, // used by basic and cyclone
  client_guid: GUID,                      // used by the Cyclone ServiceMapping
}

impl<Req, Resp> Client<Req, Resp>
where
  Req: Message + 'static,
  Resp: Message + 'static,
{
  pub(crate) fn new(
    service_mapping: ServiceMapping,
    node: &mut Node,
    request_topic: &Topic,
    response_topic: &Topic,
    qos_request: Option<QosProfile>,
    qos_response: Option<QosProfile>,
  ) -> CreateResult<Self> {
    let request_sender = node
      .create_datawriter::<RequestWrapper<Req>, ServiceSerializerAdapter<RequestWrapper<Req>>>(
        request_topic,
        qos_request,
      )?;
    let response_receiver =
      node.create_simpledatareader
      ::<ResponseWrapper<Resp>, ServiceDeserializerAdapter<ResponseWrapper<Resp>>>(
        response_topic, qos_response)?;

    debug!(
      "Created new Client: request={} response={}",
      request_topic.name(),
      response_topic.name()
    );
    let client_guid = request_sender.guid();
    Ok(Client::<Req, Resp> {
      service_mapping,
      request_sender,
      response_receiver,
      sequence_number_gen: atomic::AtomicI64::new(SequenceNumber::default().into()),
      client_guid,
    })
  }

  /// Send a request to Service Server.
  /// The returned `RmwRequestId` is a token to identify the correct response.
  pub fn send_request(&self, request: Req) -> WriteResult<RmwRequestId, ()> {
    self.increment_sequence_number();
    let gen_rmw_req_id = RmwRequestId {
      writer_gid: Gid::from(self.client_guid),
      sequence_number: i64::from(self.sequence_number()),
    };
    let req_wrapper = RequestWrapper::<Req>::new(
      self.service_mapping,
      gen_rmw_req_id,
      RepresentationIdentifier::CDR_LE,
      request,
    )?;
    let sent_rmw_req_id = self
      .request_sender
      .write_with_options(req_wrapper, self.request_write_options(gen_rmw_req_id))
      .map(RmwRequestId::from)
      .map_err(|e| e.forget_data())?;

    match self.service_mapping {
      ServiceMapping::Enhanced => Ok(sent_rmw_req_id),
      ServiceMapping::Basic | ServiceMapping::Cyclone => Ok(gen_rmw_req_id),
    }
  }

  /// Receive a response from Server
  /// Returns `Ok(None)` if no new responses have arrived.
  /// Note: The response may to someone else's request. Check received
  /// `RmWRequestId` against the one you got when sending request to identify
  /// the correct response. In case you receive someone else's response,
  /// please do receive again.
  pub fn receive_response(&self) -> ReadResult<Option<(RmwRequestId, Resp)>> {
    self.response_receiver.drain_read_notifications();
    let dcc_rw: Option<no_key::DeserializedCacheChange<ResponseWrapper<Resp>>> =
      self.response_receiver.try_take_one()?;

    match dcc_rw {
      None => Ok(None),
      Some(dcc) => {
        let mi = MessageInfo::from(&dcc);
        let res_wrapper = dcc.into_value();
        let (ri, res) = res_wrapper.unwrap(self.service_mapping, mi, self.client_guid)?;
        Ok(Some((self.own_request_id(ri), res)))
      }
    } // match
  }

  /// Send a request to Service Server asynchronously.
  /// The returned `RmwRequestId` is a token to identify the correct response.
  pub async fn async_send_request(&self, request: Req) -> WriteResult<RmwRequestId, ()> {
    let gen_rmw_req_id =
      // we do the req_id generation in an async block so that we do not generate
      // multiple sequence numbers if there are multiple polls to this function
      async {
        self.increment_sequence_number();
         RmwRequestId {
          writer_gid: Gid::from(self.client_guid),
          sequence_number: i64::from(self.sequence_number()),
        }
      }.await;

    let req_wrapper = RequestWrapper::<Req>::new(
      self.service_mapping,
      gen_rmw_req_id,
      RepresentationIdentifier::CDR_LE,
      request,
    )?;
    let sent_rmw_req_id = self
      .request_sender
      .async_write_with_options(req_wrapper, self.request_write_options(gen_rmw_req_id))
      .await
      .map(RmwRequestId::from)
      .map_err(|e| e.forget_data())?;

    let req_id = match self.service_mapping {
      ServiceMapping::Enhanced => sent_rmw_req_id,
      ServiceMapping::Basic | ServiceMapping::Cyclone => gen_rmw_req_id,
    };
    debug!(
      "Sent Request {:?} to {:?}",
      req_id,
      self.request_sender.topic().name()
    );
    Ok(req_id)
  }

  /// Receive a response from Server
  /// The returned Future does not complete until the response has been
  /// received.
  pub async fn async_receive_response(&self, request_id: RmwRequestId) -> ReadResult<Resp> {
    let dcc_stream = self.response_receiver.as_async_stream();
    pin_mut!(dcc_stream);

    loop {
      match dcc_stream.next().await {
        Some(Err(e)) => return Err(e.into()),
        Some(Ok(dcc)) => {
          let mi = MessageInfo::from(&dcc);
          let (req_id, response) =
            dcc
              .into_value()
              .unwrap(self.service_mapping, mi, self.client_guid)?;
          if self.own_request_id(req_id) == request_id {
            return Ok(response);
          } else {
            debug!(
              "Received response for someone else. expected={request_id:?}  received={req_id:?}"
            );
            continue; //
          }
        }
        // This should never occur, because topic do not "end".
        None => return read_error_internal!("SimpleDataReader value stream unexpectedly ended!"),
      }
    } // loop
  }

  pub async fn async_call_service(&self, request: Req) -> Result<Resp, CallServiceError<()>> {
    let req_id = self.async_send_request(request).await?;
    self
      .async_receive_response(req_id)
      .await
      .map_err(CallServiceError::from)
  }

  /// Wait for a Server to be connected to the Request and Response topics.
  ///
  /// This does not distinguish between diagnostinc tools and actual servers.
  /// It is enough that someone has subscribed the Requests, and someone is
  /// a publisher for Responses.
  ///
  /// If the Node has no background Spinner running, this resolves immediately
  /// (an error is logged), since without a Spinner no match events are
  /// delivered.
  pub async fn wait_for_service(&self, my_node: &Node) {
    join!(
      my_node.wait_for_reader(self.request_sender.guid()),
      my_node.wait_for_writer(self.response_receiver.guid())
    );
  }

  // The write options of a request: always a source timestamp, and the
  // related sample identity that the server answers to.
  //
  // Basic and Cyclone: the request's own identity (also in the payload header).
  //
  // Enhanced (no header in the payload): as rmw_fastrtps writes it
  // (`__rmw_send_request`), the GUID of this client's response reader with an
  // unknown sequence number. The server replies to that reader, with the request's
  // sequence number (a Fast DDS server checks that its response writer matched the
  // GUID it finds there), and our `Server` expects the parameter
  // (`RequestWrapper::unwrap` warns "related_sample_identity missing" without it).
  fn request_write_options(&self, generated: RmwRequestId) -> WriteOptions {
    let related = match self.service_mapping {
      ServiceMapping::Enhanced => SampleIdentity {
        writer_guid: self.response_receiver.guid(),
        sequence_number: SequenceNumber::UNKNOWN,
      },
      ServiceMapping::Basic | ServiceMapping::Cyclone => SampleIdentity::from(generated),
    };
    WriteOptionsBuilder::new()
      .source_timestamp(Timestamp::now())
      .related_sample_identity(related)
      .build()
  }

  // A response's request id as `send_request` returned it: with the Enhanced
  // mapping a server answers to our response reader (see `request_write_options`),
  // or, if it ignored the related sample identity, to our request writer.
  fn own_request_id(&self, received: RmwRequestId) -> RmwRequestId {
    if self.service_mapping == ServiceMapping::Enhanced
      && received.writer_gid == Gid::from(self.response_receiver.guid())
    {
      RmwRequestId {
        writer_gid: Gid::from(self.client_guid),
        ..received
      }
    } else {
      received
    }
  }

  fn increment_sequence_number(&self) {
    self
      .sequence_number_gen
      .fetch_add(1, atomic::Ordering::Acquire);
  }

  fn sequence_number(&self) -> SequenceNumber {
    self
      .sequence_number_gen
      .load(atomic::Ordering::Acquire)
      .into()
  }
}

#[derive(Debug)]
pub enum CallServiceError<T> {
  WriteError(WriteError<T>),
  ReadError(ReadError),
}
impl<T> From<WriteError<T>> for CallServiceError<T> {
  fn from(value: WriteError<T>) -> Self {
    CallServiceError::WriteError(value)
  }
}
impl<T> From<ReadError> for CallServiceError<T> {
  fn from(value: ReadError) -> Self {
    CallServiceError::ReadError(value)
  }
}

impl<T> std::fmt::Display for CallServiceError<T> {
  fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
    match self {
      Self::WriteError(err) => {
        write!(f, "Write error: {err}")
      }
      Self::ReadError(err) => {
        write!(f, "Read error: {err}")
      }
    }
  }
}

impl<T> std::error::Error for CallServiceError<T>
where
  T: std::fmt::Debug + 'static,
{
  fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
    Some(match self {
      CallServiceError::WriteError(err) => err,
      CallServiceError::ReadError(err) => err,
    })
  }
}

#[cfg(feature = "mio_06")]
impl<Req, Resp> Evented for Client<Req, Resp>
where
  Req: Message + 'static,
  Resp: Message + 'static,
{
  fn register(&self, poll: &Poll, token: Token, interest: Ready, opts: PollOpt) -> io::Result<()> {
    self.response_receiver.register(poll, token, interest, opts)
  }

  fn reregister(
    &self,
    poll: &Poll,
    token: Token,
    interest: Ready,
    opts: PollOpt,
  ) -> io::Result<()> {
    self
      .response_receiver
      .reregister(poll, token, interest, opts)
  }

  fn deregister(&self, poll: &Poll) -> io::Result<()> {
    self.response_receiver.deregister(poll)
  }
}

#[cfg(feature = "mio_1")]
impl<Req, Resp> mio1::event::Source for Client<Req, Resp>
where
  Req: Message + 'static,
  Resp: Message + 'static,
{
  fn register(
    &mut self,
    registry: &mio1::Registry,
    token: mio1::Token,
    interests: mio1::Interest,
  ) -> io::Result<()> {
    mio1::event::Source::register(&mut self.response_receiver, registry, token, interests)
  }

  fn reregister(
    &mut self,
    registry: &mio1::Registry,
    token: mio1::Token,
    interests: mio1::Interest,
  ) -> io::Result<()> {
    mio1::event::Source::reregister(&mut self.response_receiver, registry, token, interests)
  }

  fn deregister(&mut self, registry: &mio1::Registry) -> io::Result<()> {
    mio1::event::Source::deregister(&mut self.response_receiver, registry)
  }
}

#[cfg(test)]
mod tests {
  use std::time::{Duration, Instant};

  use super::*;
  use crate::{Context, Name, NodeName, NodeOptions, ServiceTypeName};

  fn poll<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
      if let Some(t) = f() {
        return t;
      }
      assert!(Instant::now() < deadline, "{what} did not come within 10 s");
      std::thread::sleep(Duration::from_millis(5));
    }
  }

  // An Enhanced request carries the related sample identity its server needs: the
  // client's response reader (rmw_fastrtps' convention). Without it our own server
  // fell back to the request's sample identity and warned "related_sample_identity
  // missing" at every call. The reply still comes back under the id `send_request`
  // returned.
  #[test]
  fn an_enhanced_request_names_the_response_reader_and_its_reply_is_ours() {
    let context = Context::new().unwrap();
    let options = NodeOptions::new().enable_rosout(false);
    let node_name = NodeName::new("/", "enhanced_client_test").unwrap();
    let mut node = context.new_node(node_name, options).unwrap();
    let name = Name::new("/", "enhanced_client_test_service").unwrap();
    let type_name = ServiceTypeName::new("test_msgs", "Echo");
    let qos = crate::DEFAULT_SUBSCRIPTION_QOS;
    let server = node
      .create_server::<String, String>(
        ServiceMapping::Enhanced,
        &name,
        &type_name,
        qos.clone(),
        qos.clone(),
      )
      .unwrap();
    let client = node
      .create_client::<String, String>(ServiceMapping::Enhanced, &name, &type_name, qos.clone(), qos)
      .unwrap();

    // A request sent before the request endpoints matched is lost (volatile), and so
    // is a reply sent before the response endpoints did, which the client creates
    // second: send again, answering every request the server has, until a reply comes.
    let mut sent = Vec::new();
    let mut answered = Vec::new();
    let (reply_id, reply) = poll("a reply", || {
      sent.push(client.send_request("ping".to_string()).unwrap());
      std::thread::sleep(Duration::from_millis(50));
      while let Some((server_id, request)) = server.receive_request().unwrap() {
        assert_eq!(request, "ping");
        assert_eq!(
          server_id.writer_gid,
          Gid::from(client.response_receiver.guid()),
          "the server answers to the client's response reader"
        );
        server.send_response(server_id, "pong".to_string()).unwrap();
        answered.push(server_id);
      }
      client.receive_response().unwrap()
    });
    // the reply comes under the id send_request returned for a request it answers
    let server_id = answered
      .iter()
      .find(|id| id.sequence_number == reply_id.sequence_number)
      .unwrap_or_else(|| panic!("{reply_id:?} answers none of the requests: {answered:?}"));
    let ours = sent
      .iter()
      .find(|id| id.sequence_number == server_id.sequence_number)
      .copied()
      .unwrap_or_else(|| panic!("{server_id:?} is none of the ids sent: {sent:?}"));
    assert_eq!(ours.writer_gid, Gid::from(client.client_guid));
    assert_eq!((reply_id, reply.as_str()), (ours, "pong"));
  }

  // An answer goes to the client that asked (the response reader its request
  // names), not to every reader of the service's responses. Each client's response
  // reader keeps a few samples (rcl's services default: 10), and answers to other
  // clients that came while it did not read pushed its own out of that history: an
  // rclpy client not spun for 1 s, beside two others asking, lost its answer 5 times
  // in 20. Here a bystander reader in another participant must get none of the
  // answers to a client.
  #[test]
  fn an_answer_goes_only_to_the_client_that_asked() {
    use rustdds::{
      QosPolicyBuilder, StatusEvented, TopicKind,
      policy::{Durability, History, Reliability},
    };

    let context = Context::new().unwrap();
    let options = NodeOptions::new().enable_rosout(false);
    let node_name = NodeName::new("/", "single_reader_answer_test").unwrap();
    let mut node = context.new_node(node_name, options).unwrap();
    let name = Name::new("/", "single_reader_answer_test_service").unwrap();
    let type_name = ServiceTypeName::new("test_msgs", "Echo");
    let qos = crate::DEFAULT_PUBLISHER_QOS;
    let server = node
      .create_server::<String, String>(
        ServiceMapping::Enhanced,
        &name,
        &type_name,
        qos.clone(),
        qos.clone(),
      )
      .unwrap();
    let client = node
      .create_client::<String, String>(
        ServiceMapping::Enhanced,
        &name,
        &type_name,
        qos.clone(),
        qos,
      )
      .unwrap();

    let other = Context::new().unwrap();
    let dp = other.domain_participant();
    let events = dp.status_listener();
    let dds_qos = QosPolicyBuilder::new()
      .reliability(Reliability::Reliable {
        max_blocking_time: rustdds::Duration::from_millis(100),
      })
      .durability(Durability::Volatile)
      .history(History::KeepLast { depth: 100 })
      .build();
    let topic = dp
      .create_topic(
        "rr/single_reader_answer_test_serviceReply".to_string(),
        "test_msgs::srv::dds_::Echo_Response_".to_string(),
        &dds_qos,
        TopicKind::NoKey,
      )
      .unwrap();
    let mut bystander = dp
      .create_subscriber(&dds_qos)
      .unwrap()
      .create_datareader_no_key_cdr::<String>(&topic, None)
      .unwrap();
    poll("the bystander's match with the server", || {
      match events.try_recv_status() {
        Some(DomainParticipantStatusEvent::RemoteWriterMatched { local_reader, .. })
          if local_reader == bystander.guid() =>
        {
          Some(())
        }
        _ => None,
      }
    });

    // the client has had an answer (a request sent before the endpoints matched is
    // lost: ask again), then asks 10 more times
    let mut answered = 0;
    poll("a first reply", || {
      client.send_request("hello".to_string()).unwrap();
      std::thread::sleep(Duration::from_millis(50));
      while let Some((id, request)) = server.receive_request().unwrap() {
        server.send_response(id, request).unwrap();
        answered += 1;
      }
      client.receive_response().unwrap()
    });
    for i in 0..10 {
      client.send_request(format!("again {i}")).unwrap();
      poll("a reply", || {
        while let Some((id, request)) = server.receive_request().unwrap() {
          server.send_response(id, request).unwrap();
          answered += 1;
        }
        client.receive_response().unwrap()
      });
    }
    std::thread::sleep(Duration::from_millis(200));
    let mut seen = Vec::new();
    while let Some(sample) = bystander.take_next_sample().unwrap() {
      seen.push(sample.into_value());
    }
    assert!(
      seen.is_empty(),
      "the bystander got {} of the {answered} answers: {seen:?}",
      seen.len()
    );
  }
}
