//! The Foxglove WebSocket server: every topic of the graph advertised as a channel with
//! its `ros2msg` schema and message encoding `cdr`; samples logged as the raw bytes
//! received from DDS; the last sample of each latched topic given to every client that
//! subscribes later; targets published by Foxglove panels handed to the node; and
//! which topics some client subscribes ([`FoxgloveBridge::watched`]), so that the node
//! subscribes a ROS topic only while a client watches it.

use crate::schemas::{ros2msg_schema, TopicSpec, TOPICS};
use crate::{FoxgloveBridgeError, TopicNames};
use foxglove::websocket::{Capability, ChannelView, Client, ClientChannel, ServerListener, Status};
use foxglove::{ChannelBuilder, ChannelId, Context, PartialMetadata, RawChannel, Schema};
use std::collections::{BTreeSet, HashMap};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use tokio::sync::{mpsc, watch};

/// The default `foxglove_bind`: loopback only, Foxglove's usual port.
pub const DEFAULT_BIND: &str = "127.0.0.1:8765";

/// Whether Foxglove clients may publish targets.
///
/// The Foxglove SDK does not show the server the WebSocket upgrade request (no `Origin`,
/// `Host` or token), so the web panel's access rules cannot be applied to a Foxglove
/// client: with publishing on, **any** program or web page that can open a WebSocket to
/// the bind address can move the arm. The node decides from its own access rules
/// whether that is acceptable (see the README).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClientPublish {
    /// Clients only watch: the server does not offer the `clientPublish` capability.
    Off,
    /// Clients may publish on the target topics ([`TopicSpec::target`]) with encoding
    /// `cdr`; at most `queue` samples wait for the node (more are dropped, with a warning
    /// to the client).
    Targets {
        /// samples waiting for the node before more are dropped
        queue: usize,
    },
}

/// A sample a Foxglove client published on a target topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClientSample {
    /// The target topic (relative name).
    pub topic: &'static str,
    /// The sample: CDR with its encapsulation header, as the client sent it.
    pub cdr: Vec<u8>,
}

struct Topic {
    spec: &'static TopicSpec,
    channel: Arc<RawChannel>,
}

/// The last sample of a latched topic and its log time (ns).
type LastSample = (Arc<[u8]>, u64);

struct Shared {
    topics: HashMap<&'static str, Topic>,
    by_channel: HashMap<ChannelId, &'static str>,
    by_shown: HashMap<String, &'static TopicSpec>,
    latched: Mutex<HashMap<&'static str, LastSample>>,
    to_node: Option<mpsc::Sender<ClientSample>>,
    /// subscriptions per topic, over every client
    subscriptions: Mutex<HashMap<&'static str, usize>>,
    /// the topics with at least one subscription
    watched: watch::Sender<BTreeSet<&'static str>>,
}

impl Shared {
    /// Count one subscription more (`+1`) or less (`-1`) to `topic`; the watched set
    /// changes when the first one comes or the last one goes.
    fn count(&self, topic: &'static str, delta: isize) {
        let Ok(mut subs) = self.subscriptions.lock() else {
            return;
        };
        let n = subs.entry(topic).or_default();
        *n = n.saturating_add_signed(delta);
        let watched = *n > 0;
        if !watched {
            subs.remove(topic);
        }
        self.watched.send_if_modified(|set| {
            if watched {
                set.insert(topic)
            } else {
                set.remove(topic)
            }
        });
    }
}

/// A running Foxglove WebSocket server for the graph's topics.
pub struct FoxgloveBridge {
    shared: Arc<Shared>,
    // the SDK's server and channels hold it weakly: it lives as long as the bridge
    _context: Arc<Context>,
    server: Option<foxglove::WebSocketServerHandle>,
    local_addr: SocketAddr,
    from_clients: Option<mpsc::Receiver<ClientSample>>,
}

impl std::fmt::Debug for FoxgloveBridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FoxgloveBridge")
            .field("local_addr", &self.local_addr)
            .finish_non_exhaustive()
    }
}

impl FoxgloveBridge {
    /// Serve the Foxglove WebSocket protocol on `bind` (`IP:port`; port 0 = any free
    /// port, see [`FoxgloveBridge::local_addr`]) on the current tokio runtime,
    /// advertising every topic of [`TOPICS`] under its name in `names`.
    pub async fn start(
        bind: &str,
        names: &TopicNames,
        publish: ClientPublish,
        server_name: &str,
    ) -> Result<FoxgloveBridge, FoxgloveBridgeError> {
        let addr: SocketAddr = bind.parse().map_err(|_| FoxgloveBridgeError::BadBind {
            bind: bind.to_string(),
        })?;
        let server_error = |source| FoxgloveBridgeError::Server {
            bind: bind.to_string(),
            source,
        };
        // a context of our own: channels go to this server only
        let context = Context::new();
        let mut topics = HashMap::new();
        let mut by_channel = HashMap::new();
        let mut by_shown = HashMap::new();
        for spec in TOPICS {
            let schema = ros2msg_schema(spec.type_name).ok_or_else(|| {
                FoxgloveBridgeError::UnknownTopic {
                    topic: spec.topic.to_string(),
                }
            })?;
            let shown = names.shown(spec.topic);
            let channel = ChannelBuilder::new(shown.clone())
                .context(&context)
                .message_encoding("cdr")
                .schema(Schema::new(spec.type_name, "ros2msg", schema.into_bytes()))
                .build_raw()
                .map_err(server_error)?;
            by_channel.insert(channel.id(), spec.topic);
            by_shown.insert(shown, spec);
            topics.insert(spec.topic, Topic { spec, channel });
        }
        let (to_node, from_clients) = match publish {
            ClientPublish::Off => (None, None),
            ClientPublish::Targets { queue } => {
                let (tx, rx) = mpsc::channel(queue.max(1));
                (Some(tx), Some(rx))
            }
        };
        let shared = Arc::new(Shared {
            topics,
            by_channel,
            by_shown,
            latched: Mutex::new(HashMap::new()),
            to_node,
            subscriptions: Mutex::new(HashMap::new()),
            watched: watch::Sender::new(BTreeSet::new()),
        });
        let mut server = foxglove::WebSocketServer::new()
            .name(server_name)
            .bind(addr.ip().to_string(), addr.port())
            .context(&context)
            .listener(Arc::new(Listener(shared.clone())));
        if publish != ClientPublish::Off {
            server = server
                .capabilities([Capability::ClientPublish])
                .supported_encodings(["cdr"]);
        }
        let server = server.start().await.map_err(server_error)?;
        let local_addr = SocketAddr::new(addr.ip(), server.port());
        Ok(FoxgloveBridge {
            shared,
            _context: context,
            server: Some(server),
            local_addr,
            from_clients,
        })
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// The samples Foxglove clients publish (once; `None` when publishing is
    /// [`ClientPublish::Off`] or it was taken already).
    pub fn take_client_samples(&mut self) -> Option<mpsc::Receiver<ClientSample>> {
        self.from_clients.take()
    }

    /// Forward one sample of `topic` (relative name) to the clients subscribed to it:
    /// `cdr` exactly as received from DDS, with its 4-byte encapsulation header;
    /// `log_time_ns` = when it was received (ns since the Unix epoch). Costs nothing
    /// beyond a lookup when nobody subscribes, except that the last sample of a latched
    /// topic is kept for later subscribers.
    pub fn log(
        &self,
        topic: &str,
        cdr: &[u8],
        log_time_ns: u64,
    ) -> Result<(), FoxgloveBridgeError> {
        let t = self
            .shared
            .topics
            .get(topic)
            .ok_or_else(|| FoxgloveBridgeError::UnknownTopic {
                topic: topic.to_string(),
            })?;
        if t.spec.latched {
            if let Ok(mut latched) = self.shared.latched.lock() {
                latched.insert(t.spec.topic, (Arc::from(cdr), log_time_ns));
            }
        }
        if t.channel.has_sinks() {
            t.channel.log_with_meta(
                cdr,
                PartialMetadata {
                    log_time: Some(log_time_ns),
                },
            );
        }
        Ok(())
    }

    /// The topics (relative names) that at least one client subscribes, now and as
    /// they change: a node subscribes a ROS topic only while a client watches it.
    pub fn watched(&self) -> watch::Receiver<BTreeSet<&'static str>> {
        self.shared.watched.subscribe()
    }

    /// How many clients are connected.
    pub fn client_count(&self) -> usize {
        self.server.as_ref().map_or(0, |s| s.client_count())
    }

    /// Close every connection and stop listening.
    pub async fn stop(mut self) {
        if let Some(server) = self.server.take() {
            server.stop().wait().await;
        }
    }
}

struct Listener(Arc<Shared>);

impl Listener {
    fn publishable(&self, channel: &ClientChannel) -> Result<&'static TopicSpec, String> {
        let spec = self
            .0
            .by_shown
            .get(&channel.topic)
            .copied()
            .filter(|s| s.target)
            .ok_or_else(|| {
                format!(
                    "{} is not a target topic; this server takes only {}",
                    channel.topic,
                    self.target_names()
                )
            })?;
        if channel.encoding != "cdr" {
            return Err(format!(
                "{}: encoding {:?} is not supported, only \"cdr\"",
                channel.topic, channel.encoding
            ));
        }
        if !channel.schema_name.is_empty()
            && channel.schema_name != spec.type_name
            && channel.schema_name.replacen("/msg/", "/", 1)
                != spec.type_name.replacen("/msg/", "/", 1)
        {
            return Err(format!(
                "{} carries {}, not {}",
                channel.topic, spec.type_name, channel.schema_name
            ));
        }
        Ok(spec)
    }

    fn target_names(&self) -> String {
        let mut names: Vec<&str> = self
            .0
            .by_shown
            .iter()
            .filter(|(_, s)| s.target)
            .map(|(n, _)| n.as_str())
            .collect();
        names.sort_unstable();
        names.join(", ")
    }
}

impl ServerListener for Listener {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        let Some(topic) = self.0.by_channel.get(&channel.id()) else {
            return;
        };
        self.0.count(topic, 1);
        let last = match self.0.latched.lock() {
            Ok(latched) => latched.get(topic).cloned(),
            Err(_) => None,
        };
        if let (Some((cdr, log_time)), Some(t)) = (last, self.0.topics.get(topic)) {
            t.channel.log_with_meta_to_sink(
                &cdr,
                PartialMetadata {
                    log_time: Some(log_time),
                },
                client.sink_id(),
            );
        }
    }

    fn on_unsubscribe(&self, _client: Client, channel: ChannelView) {
        if let Some(topic) = self.0.by_channel.get(&channel.id()) {
            self.0.count(topic, -1);
        }
    }

    fn on_client_advertise(&self, client: Client, channel: &ClientChannel) {
        if let Err(why) = self.publishable(channel) {
            log::warn!("Foxglove client {:?}: {why}", client.id());
            client.send_status(Status::warning(why));
        }
    }

    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        let Some(to_node) = &self.0.to_node else {
            return;
        };
        let Ok(spec) = self.publishable(channel) else {
            return; // said so at advertise
        };
        let sample = ClientSample {
            topic: spec.topic,
            cdr: payload.to_vec(),
        };
        if let Err(e) = to_node.try_send(sample) {
            let why = match e {
                mpsc::error::TrySendError::Full(_) => "the node is behind; sample dropped",
                mpsc::error::TrySendError::Closed(_) => "the node no longer takes targets",
            };
            client.send_status(Status::warning(format!("{}: {why}", channel.topic)));
        }
    }
}
