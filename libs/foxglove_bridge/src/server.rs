//! The Foxglove WebSocket server: every topic of the graph advertised as a channel with
//! its `ros2msg` schema and message encoding `cdr`; samples logged as the raw bytes
//! received from DDS; the last sample of each latched topic given to every client that
//! subscribes later; targets published by Foxglove panels handed to the node; and
//! which topics some client subscribes ([`FoxgloveBridge::watched`]), so that the node
//! subscribes a ROS topic only while a client watches it.

use crate::front::{self, Front, FrontLimits, FrontStats, Gate, Introductions};
use crate::schemas::{ros2msg_schema, TopicSpec, TOPICS};
use crate::{FoxgloveBridgeError, TopicNames};
use foxglove::websocket::{
    Capability, ChannelView, Client, ClientChannel, ClientChannelId, ClientId, ServerListener,
    Status,
};
use foxglove::{ChannelBuilder, ChannelId, Context, PartialMetadata, RawChannel, Schema, SinkId};
use std::collections::{BTreeSet, HashMap};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use tokio::sync::{mpsc, watch};

/// The default `foxglove_bind`: loopback only, Foxglove's usual port.
pub const DEFAULT_BIND: &str = "127.0.0.1:8765";

/// Whether Foxglove clients may publish targets.
///
/// Which clients may connect, and which of them may publish, the node's [`Gate`]
/// decides from each upgrade request ([`crate::front`]); with [`ClientPublish::Off`] no
/// client publishes whatever the gate says.
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
    /// the sinks of the introduced clients subscribed to each topic: samples go only there
    sinks: Mutex<HashMap<&'static str, HashMap<ClientId, SinkId>>>,
    /// introductions the front handed out and not yet redeemed
    introductions: Arc<Introductions>,
    /// clients the front introduced, and whether each may publish
    introduced: Mutex<HashMap<ClientId, bool>>,
}

impl Shared {
    /// Did the front introduce this client (None: no: a connection that did not come
    /// through the front, which the SDK, listening on no port, no longer has)? Some(may
    /// publish) if so.
    fn introduced(&self, client: &Client) -> Option<bool> {
        self.introduced.lock().ok()?.get(&client.id()).copied()
    }

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
    front: tokio::task::JoinHandle<()>,
    front_stats: Arc<FrontStats>,
    max_sample_bytes: usize,
}

impl Drop for FoxgloveBridge {
    fn drop(&mut self) {
        self.front.abort();
    }
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
    /// advertising every topic of [`TOPICS`] under its name in `names`, to programs only
    /// ([`front::programs_only`]: a request with an `Origin` is refused) with the default
    /// [`FrontLimits`].
    pub async fn start(
        bind: &str,
        names: &TopicNames,
        publish: ClientPublish,
        server_name: &str,
    ) -> Result<FoxgloveBridge, FoxgloveBridgeError> {
        Self::start_with(
            bind,
            names,
            publish,
            server_name,
            front::programs_only(),
            FrontLimits::default(),
        )
        .await
    }

    /// [`FoxgloveBridge::start`] with the node's `gate` in front of every connection and
    /// these `limits` ([`crate::front`]).
    pub async fn start_with(
        bind: &str,
        names: &TopicNames,
        publish: ClientPublish,
        server_name: &str,
        gate: Gate,
        limits: FrontLimits,
    ) -> Result<FoxgloveBridge, FoxgloveBridgeError> {
        Self::start_secure(bind, names, publish, server_name, gate, limits, None).await
    }

    /// [`FoxgloveBridge::start_with`], the front speaking TLS (`wss://`) with `tls` when
    /// given ([`crate::front`]).
    pub async fn start_secure(
        bind: &str,
        names: &TopicNames,
        publish: ClientPublish,
        server_name: &str,
        gate: Gate,
        limits: FrontLimits,
        tls: Option<Arc<tokio_rustls::rustls::ServerConfig>>,
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
            sinks: Mutex::new(HashMap::new()),
            introductions: Arc::new(Introductions::default()),
            introduced: Mutex::new(HashMap::new()),
        });
        // the front's listener first: a taken port is the error the operator knows
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .map_err(|e| server_error(foxglove::FoxgloveError::Bind(e)))?;
        let local_addr = listener
            .local_addr()
            .map_err(|e| server_error(foxglove::FoxgloveError::Bind(e)))?;
        // the SDK's server behind the front, on no port of its own (patches/foxglove): it
        // serves only the connections the front hands it. clientPublish always (the front
        // introduces its connections with a client channel), taken from the serverInfo of
        // a client that may not publish
        let server = foxglove::WebSocketServer::new()
            .name(server_name)
            .context(&context)
            .listener(Arc::new(Listener(shared.clone())))
            .capabilities([Capability::ClientPublish])
            .supported_encodings(["cdr"])
            .start_without_listener()
            .await
            .map_err(server_error)?;
        let front_stats = Arc::new(FrontStats::default());
        let front = Arc::new(Front {
            gate,
            limits,
            sdk: server.stream_acceptor(),
            introductions: shared.introductions.clone(),
            stats: front_stats.clone(),
            publishing: publish != ClientPublish::Off,
            logged: Mutex::new(std::collections::HashSet::new()),
            tls: tls.map(tokio_rustls::TlsAcceptor::from),
        });
        let front = tokio::spawn(front.run(listener));
        Ok(FoxgloveBridge {
            shared,
            _context: context,
            server: Some(server),
            local_addr,
            from_clients,
            front,
            front_stats,
            max_sample_bytes: limits.max_sample_bytes,
        })
    }

    /// The front's counters (refusals, busy, oversized messages, header timeouts).
    pub fn front_stats(&self) -> Arc<FrontStats> {
        self.front_stats.clone()
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
    /// topic is kept for later subscribers. A sample over
    /// [`FrontLimits::max_sample_bytes`] is refused (counted in
    /// [`FrontStats::oversized_samples`]; a latched topic keeps its last one).
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
        if cdr.len() > self.max_sample_bytes {
            self.front_stats
                .oversized_samples
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            return Err(FoxgloveBridgeError::SampleTooLarge {
                topic: topic.to_string(),
                bytes: cdr.len(),
                limit: self.max_sample_bytes,
            });
        }
        if t.spec.latched {
            if let Ok(mut latched) = self.shared.latched.lock() {
                latched.insert(t.spec.topic, (Arc::from(cdr), log_time_ns));
            }
        }
        // to the introduced clients subscribed, each by its sink (never to all sinks: every
        // client is a sink, introduced or not)
        let sinks: Vec<SinkId> = match self.shared.sinks.lock() {
            Ok(s) => s
                .get(t.spec.topic)
                .map(|m| m.values().copied().collect())
                .unwrap_or_default(),
            Err(_) => Vec::new(),
        };
        for sink in sinks {
            t.channel.log_with_meta_to_sink(
                cdr,
                PartialMetadata {
                    log_time: Some(log_time_ns),
                },
                Some(sink),
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
        self.front.abort();
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
        let (Some(_), Some(sink)) = (self.0.introduced(&client), client.sink_id()) else {
            client.send_status(Status::error(
                "this connection was not introduced by the server's front".to_string(),
            ));
            return;
        };
        if let Ok(mut sinks) = self.0.sinks.lock() {
            if sinks
                .entry(topic)
                .or_default()
                .insert(client.id(), sink)
                .is_some()
            {
                return; // subscribed already
            }
        }
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

    fn on_unsubscribe(&self, client: Client, channel: ChannelView) {
        if let Some(topic) = self.0.by_channel.get(&channel.id()) {
            let was = self
                .0
                .sinks
                .lock()
                .ok()
                .and_then(|mut s| s.get_mut(topic)?.remove(&client.id()));
            if was.is_some() {
                self.0.count(topic, -1);
            }
        }
    }

    fn on_client_advertise(&self, client: Client, channel: &ClientChannel) {
        if channel.id == ClientChannelId::new(front::INTRODUCTION_CHANNEL) {
            if let Some(may_publish) = self.0.introductions.redeem(&channel.topic) {
                if let Ok(mut i) = self.0.introduced.lock() {
                    i.insert(client.id(), may_publish);
                }
                return;
            }
        }
        match self.0.introduced(&client) {
            Some(true) => {}
            Some(false) => {
                client.send_status(Status::warning(format!(
                    "{}: this server does not take samples from this client",
                    channel.topic
                )));
                return;
            }
            None => return,
        }
        if let Err(why) = self.publishable(channel) {
            log::warn!("Foxglove client {:?}: {why}", client.id());
            client.send_status(Status::warning(why));
        }
    }

    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        let Some(to_node) = &self.0.to_node else {
            return;
        };
        if self.0.introduced(&client) != Some(true) {
            return; // not introduced by the front as a publisher: said so at advertise
        }
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

    fn on_client_unadvertise(&self, client: Client, channel: &ClientChannel) {
        // the introduction stays advertised until the client goes: then this comes
        if channel.id == ClientChannelId::new(front::INTRODUCTION_CHANNEL) {
            if let Ok(mut i) = self.0.introduced.lock() {
                i.remove(&client.id());
            }
        }
    }
}
