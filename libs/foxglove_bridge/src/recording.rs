//! MCAP recordings of the graph's samples: `ros2msg` schemas and CDR messages, as
//! rosbag2 writes them (profile `ros2`), so Foxglove, `ros2 bag play` (with the MCAP
//! storage plugin) and the `mcap` tools read them; and the targets read back for replay.

use crate::schemas::{ros2msg_schema, topic_spec, TopicSpec, TOPICS};
use crate::{FoxgloveBridgeError, TopicNames};
use std::collections::{BTreeMap, HashMap};
use std::io::{Seek, Write};
use std::path::Path;

/// MCAP chunk size: a crash loses at most the samples of the open chunk.
const CHUNK_BYTES: u64 = 256 * 1024;

/// Writes samples into an MCAP file: one channel per recorded topic
/// ([`TopicSpec::recorded`]), each with its `ros2msg` schema and encoding `cdr`.
pub struct McapRecorder<W: Write + Seek> {
    writer: mcap::Writer<W>,
    channels: HashMap<&'static str, u16>,
    sequence: u32,
    written: u64,
}

impl<W: Write + Seek> std::fmt::Debug for McapRecorder<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapRecorder")
            .field("channels", &self.channels)
            .field("written", &self.written)
            .finish_non_exhaustive()
    }
}

impl McapRecorder<std::fs::File> {
    /// Create (or replace) `path` and write the header, schemas and channels.
    pub fn create(path: &Path, names: &TopicNames) -> Result<Self, FoxgloveBridgeError> {
        let file = std::fs::File::create(path).map_err(|source| FoxgloveBridgeError::Io {
            path: path.display().to_string(),
            source,
        })?;
        McapRecorder::new(file, names)
    }
}

impl<W: Write + Seek> McapRecorder<W> {
    /// Start a recording into `out`, naming each channel as `names` does.
    pub fn new(out: W, names: &TopicNames) -> Result<Self, FoxgloveBridgeError> {
        let options = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!(
                "eezybot foxglove_bridge ",
                env!("CARGO_PKG_VERSION")
            ))
            .compression(None)
            .chunk_size(Some(CHUNK_BYTES));
        let mut writer = options.create(out)?;
        let mut channels = HashMap::new();
        for spec in TOPICS.iter().filter(|t| t.recorded) {
            let schema =
                ros2msg_schema(spec.type_name).ok_or(FoxgloveBridgeError::UnknownTopic {
                    topic: spec.topic.to_string(),
                })?;
            let schema_id = writer.add_schema(spec.type_name, "ros2msg", schema.as_bytes())?;
            let id =
                writer.add_channel(schema_id, &names.shown(spec.topic), "cdr", &BTreeMap::new())?;
            channels.insert(spec.topic, id);
        }
        Ok(McapRecorder {
            writer,
            channels,
            sequence: 0,
            written: 0,
        })
    }

    /// Is `topic` (relative name) one this recording keeps?
    pub fn records(&self, topic: &str) -> bool {
        self.channels.contains_key(topic)
    }

    /// Write one sample of `topic` (relative name): `cdr` as on the wire, with its
    /// 4-byte encapsulation header; `log_time_ns` = when it was received (ns since the
    /// Unix epoch). A topic this recording does not keep is ignored (`Ok(false)`).
    pub fn write(
        &mut self,
        topic: &str,
        cdr: &[u8],
        log_time_ns: u64,
    ) -> Result<bool, FoxgloveBridgeError> {
        let Some(&channel_id) = self.channels.get(topic) else {
            return Ok(false);
        };
        self.sequence = self.sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.writer.write_to_known_channel(&header, cdr)?;
        self.written += 1;
        Ok(true)
    }

    /// How many samples were written.
    pub fn written(&self) -> u64 {
        self.written
    }

    /// Close the last chunk and write the summary (indexes, statistics). The file is
    /// complete and readable only after this.
    pub fn finish(mut self) -> Result<u64, FoxgloveBridgeError> {
        self.writer.finish()?;
        Ok(self.written)
    }
}

/// One recorded target, ready to be published again.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordedTarget {
    /// The target topic, relative name (`xyz_target`, `pose_target`, `gripper_target`,
    /// `joint_target`).
    pub topic: &'static str,
    /// The sample as recorded (CDR with its encapsulation header).
    pub cdr: Vec<u8>,
    /// When it was recorded, ns since the Unix epoch.
    pub log_time_ns: u64,
}

/// The targets of an MCAP recording, in the order they were recorded.
///
/// A channel is a target when the last segment of its topic is a target topic's name
/// (so a recording made in namespace `/arm2` plays into any namespace), its message
/// encoding is `cdr` and its schema is that topic's type.
#[derive(Debug, Clone, Default)]
pub struct McapTargets {
    targets: Vec<RecordedTarget>,
}

impl McapTargets {
    /// Read the targets of the MCAP file at `path`.
    pub fn open(path: &Path) -> Result<McapTargets, FoxgloveBridgeError> {
        let bytes = std::fs::read(path).map_err(|source| FoxgloveBridgeError::Io {
            path: path.display().to_string(),
            source,
        })?;
        McapTargets::from_bytes(&bytes)
    }

    /// Read the targets of an MCAP file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<McapTargets, FoxgloveBridgeError> {
        let mut targets = Vec::new();
        let mut kinds: HashMap<u16, Option<&'static TopicSpec>> = HashMap::new();
        for message in mcap::MessageStream::new(bytes)? {
            let message = message?;
            let spec = *kinds
                .entry(message.channel.id)
                .or_insert_with(|| target_spec(&message.channel));
            if let Some(spec) = spec {
                targets.push(RecordedTarget {
                    topic: spec.topic,
                    cdr: message.data.into_owned(),
                    log_time_ns: message.log_time,
                });
            }
        }
        // chunks may overlap in time; replay follows log time (stable: equal times keep
        // the file's order)
        targets.sort_by_key(|t| t.log_time_ns);
        Ok(McapTargets { targets })
    }

    /// The targets, oldest first.
    pub fn targets(&self) -> &[RecordedTarget] {
        &self.targets
    }

    /// How many targets there are.
    pub fn len(&self) -> usize {
        self.targets.len()
    }

    /// No targets at all.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }
}

impl IntoIterator for McapTargets {
    type Item = RecordedTarget;
    type IntoIter = std::vec::IntoIter<RecordedTarget>;
    fn into_iter(self) -> Self::IntoIter {
        self.targets.into_iter()
    }
}

fn target_spec(channel: &mcap::Channel<'_>) -> Option<&'static TopicSpec> {
    let last = channel.topic.rsplit('/').next().unwrap_or_default();
    let spec = topic_spec(last).filter(|s| s.target)?;
    let schema = channel.schema.as_ref()?;
    (channel.message_encoding == "cdr" && schema.name == spec.type_name).then_some(spec)
}
