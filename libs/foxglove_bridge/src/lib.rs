#![doc = include_str!("../README.md")]

pub mod front;
pub mod recording;
pub mod schemas;
pub mod server;

pub use front::{Admitted, FrontLimits, FrontStats, Gate, Refused, UpgradeRequest};
pub use recording::{McapRecorder, McapTargets, RecordedTarget};
pub use schemas::{ros2msg_schema, topic_spec, TopicSpec, TOPICS};
pub use server::{ClientPublish, ClientSample, FoxgloveBridge, DEFAULT_BIND};

use std::collections::HashMap;
use std::time::{SystemTime, UNIX_EPOCH};

/// What went wrong in this library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FoxgloveBridgeError {
    /// The bind address is not `IP:port`.
    #[error("foxglove_bind {bind:?} is not an address like 127.0.0.1:8765 or [::1]:8765")]
    BadBind {
        /// what was given
        bind: String,
    },
    /// The Foxglove SDK refused to start or failed.
    #[error("Foxglove WebSocket server on {bind}: {source}")]
    Server {
        /// the address
        bind: String,
        /// the SDK's error
        #[source]
        source: foxglove::FoxgloveError,
    },
    /// A sample over [`FrontLimits::max_sample_bytes`], not forwarded.
    #[error("{topic}: a sample of {bytes} bytes is not forwarded (more than {limit})")]
    SampleTooLarge {
        /// the topic (relative name)
        topic: String,
        /// the sample's size
        bytes: usize,
        /// the limit
        limit: usize,
    },
    /// A topic that is not one of the graph's ([`TOPICS`]).
    #[error("{topic:?} is not a topic of the graph")]
    UnknownTopic {
        /// the name given
        topic: String,
    },
    /// Reading or writing an MCAP file.
    #[error("MCAP: {0}")]
    Mcap(#[from] mcap::McapError),
    /// Opening a file.
    #[error("{path}: {source}")]
    Io {
        /// the file
        path: String,
        /// why
        #[source]
        source: std::io::Error,
    },
}

/// The names the topics have on the wire (and therefore in Foxglove and in recordings):
/// by default `/` + the relative name; `namespace` and [`TopicNames::set`] follow a
/// node's `__ns` and `-r old:=new` remappings.
#[derive(Debug, Clone, Default)]
pub struct TopicNames {
    namespace: String,
    remapped: HashMap<&'static str, String>,
}

impl TopicNames {
    /// Names in `namespace` (`/` or empty = the root, `/arm2` → `/arm2/tf`).
    pub fn in_namespace(namespace: &str) -> TopicNames {
        TopicNames {
            namespace: namespace.trim_end_matches('/').to_string(),
            remapped: HashMap::new(),
        }
    }

    /// Every topic's name as a function (e.g. a node's name resolver) says. Topics for
    /// which it gives `None` keep the default name.
    pub fn resolved_by(mut self, resolve: impl Fn(&str) -> Option<String>) -> TopicNames {
        for t in TOPICS {
            if let Some(name) = resolve(t.topic) {
                self.remapped.insert(t.topic, name);
            }
        }
        self
    }

    /// Give the topic `relative` the name `shown`.
    pub fn set(&mut self, relative: &'static str, shown: impl Into<String>) {
        self.remapped.insert(relative, shown.into());
    }

    /// The name of the topic `relative` on the wire.
    ///
    /// # Examples
    /// ```
    /// use foxglove_bridge::TopicNames;
    /// assert_eq!(TopicNames::default().shown("tf"), "/tf");
    /// assert_eq!(TopicNames::in_namespace("/arm2/").shown("tf"), "/arm2/tf");
    /// ```
    pub fn shown(&self, relative: &str) -> String {
        match self.remapped.get(relative) {
            Some(name) => name.clone(),
            None => format!("{}/{relative}", self.namespace),
        }
    }
}

/// Now, in ns since the Unix epoch (the log time of a sample received now).
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}
