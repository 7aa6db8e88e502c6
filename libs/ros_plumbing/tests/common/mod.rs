//! A raw RustDDS client of one service, for the answer tests: its requests name a
//! response reader that does not exist yet (the next GUID its participant hands out),
//! created only when the test says so, as a client whose reader the server learns of
//! after its request.

// test support: a failure to set the client up fails the test, as in the tests
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use ros2_client::Context;
use rustdds::no_key::{DataReader, DataWriter};
use rustdds::policy::{Durability, History, Reliability};
use rustdds::{
    DomainParticipantStatusEvent, QosPolicies, QosPolicyBuilder, RTPSEntity, SampleIdentity,
    SequenceNumber, StatusEvented, Subscriber, Topic, TopicKind, WriteOptionsBuilder, GUID,
};
use serde::{de::DeserializeOwned, Serialize};

pub struct RawClient<Req: Serialize, Resp> {
    /// kept: the participant of the writer and the reader
    _context: Context,
    writer: DataWriter<Req>,
    subscriber: Subscriber,
    replies: Topic,
    /// the response reader each request names; created by [`RawClient::reader`]
    reader_guid: GUID,
    sent: i64,
    _resp: std::marker::PhantomData<Resp>,
}

fn qos() -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(100),
        })
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
        .build()
}

impl<Req: Serialize + 'static, Resp: DeserializeOwned + 'static> RawClient<Req, Resp> {
    /// A client of the service whose topics and types are given, once its request
    /// writer has matched the server's request reader (10 s at most).
    pub async fn new(requests: (&str, &str), replies: (&str, &str)) -> Self {
        let context = Context::new().unwrap();
        let dp = context.domain_participant();
        let events = dp.status_listener();
        let topic = |(name, ty): (&str, &str)| {
            dp.create_topic(name.to_string(), ty.to_string(), &qos(), TopicKind::NoKey)
                .unwrap()
        };
        let request_topic = topic(requests);
        let replies = topic(replies);
        let writer = dp
            .create_publisher(&qos())
            .unwrap()
            .create_datawriter_no_key_cdr::<Req>(&request_topic, None)
            .unwrap();
        let subscriber = dp.create_subscriber(&qos()).unwrap();
        // entity ids are handed out in order: the reader created next gets the next key
        // (bytes 12..15 of the GUID), kind 0x04 (a user-defined reader, no key)
        let mut bytes = writer.guid().to_bytes();
        let next = u32::from_be_bytes([0, bytes[12], bytes[13], bytes[14]]) + 1;
        bytes[12..15].copy_from_slice(&next.to_be_bytes()[1..]);
        bytes[15] = 0x04;
        let reader_guid = GUID::from_bytes(bytes);

        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            match events.try_recv_status() {
                Some(DomainParticipantStatusEvent::RemoteReaderMatched {
                    local_writer, ..
                }) if local_writer == writer.guid() => break,
                Some(_) => {}
                None => {
                    assert!(
                        Instant::now() < deadline,
                        "the server's request reader did not match"
                    );
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
            }
        }
        RawClient {
            _context: context,
            writer,
            subscriber,
            replies,
            reader_guid,
            sent: 0,
            _resp: std::marker::PhantomData,
        }
    }

    /// Send `request`, naming the response reader (Enhanced mapping, as rmw_fastrtps).
    pub fn ask(&mut self, request: Req) {
        self.sent += 1;
        let options = WriteOptionsBuilder::new()
            .related_sample_identity(SampleIdentity {
                writer_guid: self.reader_guid,
                sequence_number: SequenceNumber::from(self.sent),
            })
            .build();
        if let Err(e) = self.writer.write_with_options(request, options) {
            panic!("cannot send the request: {:?}", e.forget_data());
        }
    }

    /// The response reader the requests name, created now.
    pub fn reader(&self) -> DataReader<Resp> {
        let reader = self
            .subscriber
            .create_datareader_no_key_cdr::<Resp>(&self.replies, None)
            .unwrap();
        assert_eq!(
            reader.guid(),
            self.reader_guid,
            "the reader got the GUID the requests named"
        );
        reader
    }
}
