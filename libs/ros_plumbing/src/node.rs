//! A ros2-client node set up the ROS way: command line, domain id, names, parameters,
//! logging, with its spinner running.

use crate::args::{self, RosArgs};
use crate::diagnostics::DiagnosticsPublisher;
use crate::error::PlumbingError;
use crate::logging;
use crate::names::Resolver;
use crate::params::{self, ParamSpec, Params};
use crate::publisher::TopicPublisher;
use crate::security::{self, SecurityEnv, SecurityError, SecurityPlan, Strategy};
use crate::topics::{self, Topic};
use eezybot_msgs::RosMessage;
use ros2_client::{
    Context, CreateResult, Name, Node, NodeName, NodeOptions, Publisher, QosProfile, Subscription,
};

/// What a node is: its default name, a one-line description and its parameters.
#[derive(Clone, Debug)]
pub struct NodeSpec {
    /// Default node name (and the name params-file keys and node-specific rules match).
    pub name: &'static str,
    /// One line for `--help`.
    pub description: &'static str,
    /// Usage of the node's own (non-ROS) arguments, for `--help`; empty if none.
    pub usage: &'static str,
    /// Declared parameters.
    pub params: Vec<ParamSpec>,
}

/// The ROS arguments every node takes, as `--help` shows them.
pub const ROS_ARGS_USAGE: &str = "--ros-args [-r __ns:=/NS] [-r __node:=NAME] [-r FROM:=TO] \
     [-p NAME:=VALUE] [--params-file FILE] [--log-level LEVEL] [--enclave /NAME]";

/// The environment every node reads, as `--help` shows it.
pub const ENVIRONMENT_HELP: &str = "ROS_DOMAIN_ID (0..232, default 0); SROS2: \
     ROS_SECURITY_ENABLE (true: on), ROS_SECURITY_STRATEGY (Enforce | Permissive), \
     ROS_SECURITY_KEYSTORE (keystore directory), ROS_SECURITY_ENCLAVE_OVERRIDE (instead of \
     --enclave)";

impl NodeSpec {
    /// The text `--help` prints.
    pub fn help(&self) -> String {
        format!(
            "{}: {}\n\nusage: {} {}[{ROS_ARGS_USAGE}]\n\nenvironment: {ENVIRONMENT_HELP}\n\nparameters:\n{}",
            self.name,
            self.description,
            self.name,
            if self.usage.is_empty() { String::new() } else { format!("{} ", self.usage) },
            self.params_help()
        )
    }

    /// One line per declared parameter: name, description, default, `read-only`.
    pub fn params_help(&self) -> String {
        let mut s = String::new();
        for p in &self.params {
            s.push_str(&format!(
                "  {:<22} {} (default {}){}\n",
                p.name,
                p.description,
                show(&p.default),
                if p.read_only { ", read-only" } else { "" }
            ));
        }
        s
    }
}

fn show(v: &ros2_client::ParameterValue) -> String {
    use ros2_client::ParameterValue as P;
    match v {
        P::Boolean(b) => b.to_string(),
        P::Integer(i) => i.to_string(),
        P::Double(d) => d.to_string(),
        P::String(s) => format!("{s:?}"),
        other => format!("{other:?}"),
    }
}

/// How often each node's DDS participant announces itself (SPDP). Its lease is five
/// periods (5 s): a peer that hears nothing for that long reports it lost, and the
/// first announcement after a network outage rediscovers it, so the graph resumes
/// about a second after the network returns. (RustDDS' default is 10 s, lease 50 s;
/// Fast DDS' is 3 s, lease 20 s.)
pub const SPDP_PUBLISH_PERIOD: std::time::Duration = std::time::Duration::from_secs(1);

/// `ROS_DOMAIN_ID` as rcl reads it: unset or empty means 0.
pub fn domain_id_from_env(value: Option<&str>) -> Result<u16, PlumbingError> {
    match value.map(str::trim) {
        None | Some("") => Ok(0),
        Some(v) => match v.parse::<u16>() {
            Ok(id) if id <= 232 => Ok(id),
            _ => Err(PlumbingError::DomainId {
                value: v.to_string(),
            }),
        },
    }
}

/// ros2-client folds RustDDS' `NotAllowedBySecurity` into `CreateError::Middleware`
/// with this prefix.
const DENIED: &str = "not allowed by security: ";

/// Builds the node's DDS participant, secured with the enclave of `plan` if given.
/// Why [`build_participant`] failed: refused by DDS Security, or anything else (a
/// socket that cannot be opened).
enum BuildError {
    Security(String),
    Other(PlumbingError),
}

impl From<BuildError> for PlumbingError {
    fn from(e: BuildError) -> Self {
        match e {
            BuildError::Security(why) => {
                PlumbingError::Ros(format!("cannot create the DDS participant: {why}"))
            }
            BuildError::Other(e) => e,
        }
    }
}

fn build_participant(
    domain_id: u16,
    plan: Option<&SecurityPlan>,
) -> Result<rustdds::DomainParticipant, BuildError> {
    // User data by unicast only, as Fast DDS does by default: with the multicast
    // group advertised, a Fast DDS writer (rclpy's xyz_target) sent every sample to
    // the group too, and every other node on the host, or across the Wi-Fi link,
    // woke to parse and drop it (patches/README.md, rustdds entry 15).
    let mut builder = rustdds::DomainParticipantBuilder::new(domain_id)
        .spdp_publish_period(SPDP_PUBLISH_PERIOD)
        .user_traffic_multicast(false);
    if let Some(plan) = plan {
        builder = builder.builtin_security(security::participant_files(plan));
    }
    builder.build().map_err(|e| match e {
        rustdds::dds::result::CreateError::NotAllowedBySecurity { reason } => {
            BuildError::Security(reason)
        }
        e => BuildError::Other(PlumbingError::Ros(format!(
            "cannot create the DDS participant: {e}"
        ))),
    })
}

/// rcl's security rules ([`crate::security`]): `None` runs unsecured (security off,
/// or Permissive with an unusable enclave, after a warning); under Enforce an unusable
/// enclave is an error naming the file.
fn security_plan(
    env: &SecurityEnv,
    enclave_arg: Option<&str>,
) -> Result<Option<SecurityPlan>, PlumbingError> {
    let checked = env.plan(enclave_arg).and_then(|plan| match plan {
        None => Ok(None),
        Some(plan) => {
            let keystore = std::path::PathBuf::from(env.keystore.clone().unwrap_or_default());
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| i64::try_from(d.as_secs()).unwrap_or(i64::MAX));
            security::check_enclave(&plan, &keystore, now)
                .map(|()| Some(plan.clone()))
                .map_err(|e| (plan.strategy, e))
        }
    });
    match checked {
        Ok(Some(plan)) => {
            log::info!(
                "security: on, enclave {} ({}), strategy {}",
                plan.enclave,
                plan.dir.display(),
                plan.strategy
            );
            Ok(Some(plan))
        }
        Ok(None) => Ok(None),
        Err((Strategy::Enforce, e)) => Err(e.into()),
        Err((Strategy::Permissive, e)) => {
            log::warn!(
                "security: {e}; ROS_SECURITY_STRATEGY is not Enforce: running WITHOUT security"
            );
            Ok(None)
        }
    }
}

/// A running node: the ros2-client node (spinner started), its name resolver and
/// its parameters.
pub struct RosNode {
    node: Node,
    resolver: Resolver,
    params: Params,
    user_args: Vec<String>,
    domain_id: u16,
    /// The SROS2 enclave in use, `None` when unsecured.
    enclave: Option<String>,
    /// When the enclave's certificate (or its CA) runs out, for the diagnostics.
    certificate: Option<security::CertificateExpiry>,
    spinner: Option<tokio::task::JoinHandle<()>>,
    // Dropped last: the DDS participant outlives the node's entities.
    _context: Context,
}

impl RosNode {
    /// Set up from this process's arguments and environment. `--help`/`-h` prints
    /// the spec's help and exits with 0. Must be called inside a tokio runtime.
    pub fn start(spec: &NodeSpec) -> Result<RosNode, PlumbingError> {
        let argv: Vec<String> = std::env::args().skip(1).collect();
        let (user, _) = args::parse(argv.clone())?;
        if user.iter().any(|a| a == "--help" || a == "-h") {
            print!("{}", spec.help());
            std::process::exit(0);
        }
        Self::start_with(spec, argv, std::env::var("ROS_DOMAIN_ID").ok().as_deref())
    }

    /// Set up from explicit arguments (without argv\[0\]) and `ROS_DOMAIN_ID` value.
    pub fn start_with(
        spec: &NodeSpec,
        argv: Vec<String>,
        domain_env: Option<&str>,
    ) -> Result<RosNode, PlumbingError> {
        let (user_args, ros): (Vec<String>, RosArgs) = args::parse(argv)?;
        if let (true, Some(extra)) = (spec.usage.is_empty(), user_args.first()) {
            // before any DDS entity exists: nothing to announce and tear down again
            return Err(PlumbingError::BadArgument {
                arg: extra.clone(),
                why: format!(
                    "unexpected argument ({} takes none besides --ros-args; see --help)",
                    spec.name
                ),
            });
        }
        logging::init(
            ros.log_level.unwrap_or(log::LevelFilter::Info),
            ros.stdout_logs.unwrap_or(true),
        );
        let domain_id = domain_id_from_env(domain_env)?;
        let name = ros
            .node_name
            .clone()
            .unwrap_or_else(|| spec.name.to_string());
        let resolver = Resolver::new(
            ros.namespace.as_deref().unwrap_or("/"),
            &name,
            spec.name,
            &ros.remaps,
        )?;
        let values = params::initial_values(&spec.params, &ros, &resolver.node_fqn(), &name)?;
        let params = Params::new(values.clone());

        let rosout = ros.rosout_logs.unwrap_or(true);
        let mut options = NodeOptions::new()
            .enable_rosout(rosout)
            .start_parameter_services(true);
        let use_sim_time = values.get(params::USE_SIM_TIME.name)
            == Some(&ros2_client::ParameterValue::Boolean(true));
        for p in spec.params.iter().chain([&*params::USE_SIM_TIME]) {
            let value = values.get(p.name).unwrap_or(&p.default).clone();
            options = options.declare_parameter_with_descriptor(p.name, value, p.descriptor());
        }
        let specs = spec.params.clone();
        let current = params.clone();
        options = options.parameter_validator(Box::new(move |name, value| {
            let check = || {
                let name_shown = logging::shorten(name, logging::NAME_MAX);
                let Some(spec) = specs.iter().find(|s| s.name == name) else {
                    return Err(format!("`{name_shown}` is not a parameter of this node"));
                };
                let checked = spec.check(value)?;
                if spec.read_only && current.get(name).is_some_and(|v| v != checked) {
                    return Err(format!(
                        "`{name_shown}` is read-only: set it on the command line or in a params file"
                    ));
                }
                Ok(())
            };
            check().map_err(|reason| current.note_refusal(name, reason))
        }));
        let store = params.clone();
        options = options.parameter_set_action(Box::new(move |name, value| {
            // the same value again is applied again: a file parameter (arm_config) set to
            // the path it has reloads the file, which may have changed (the calibration
            // wizard saves to the same file each time)
            if store.get(name).as_ref() != Some(value) {
                log::info!("parameter {name} set to {}", show(value));
            } else {
                log::debug!("parameter {name} set again to {}", show(value));
            }
            store.set(name, value.clone());
            Ok(())
        }));

        let plan = security_plan(&SecurityEnv::from_env(), ros.enclave.as_deref())?;
        let participant = build_participant(domain_id, plan.as_ref());
        let (participant, enclave) = match (participant, &plan) {
            (Ok(p), plan) => (p, plan.as_ref().map(|p| p.enclave.clone())),
            (Err(BuildError::Security(why)), Some(plan)) => {
                let refused = SecurityError::Refused {
                    dir: plan.dir.clone(),
                    why,
                };
                if plan.strategy == Strategy::Enforce {
                    return Err(refused.into());
                }
                log::warn!(
                    "security: {refused}; ROS_SECURITY_STRATEGY is not Enforce: running WITHOUT \
                     security"
                );
                (build_participant(domain_id, None)?, None)
            }
            (Err(e), _) => return Err(e.into()),
        };
        let context = Context::from_domain_participant(participant)
            .map_err(|e| PlumbingError::Ros(format!("cannot create the ROS context: {e:?}")))?;
        let node_name =
            NodeName::new(resolver.namespace(), &name).map_err(|e| PlumbingError::Name {
                name: resolver.node_fqn(),
                why: format!("{e:?}"),
            })?;
        let mut node = context.new_node(node_name, options).map_err(|e| {
            PlumbingError::Ros(format!("cannot create node {}: {e:?}", resolver.node_fqn()))
        })?;
        let logger_name = resolver
            .node_fqn()
            .trim_start_matches('/')
            .replace('/', ".");
        logging::attach_node(
            logger_name,
            if rosout {
                Some(node.logging_handle())
            } else {
                None
            },
        );
        let spinner = node.spinner().map_err(|e| match e {
            // the parameter services' topics, refused by the enclave's permissions
            ros2_client::CreateError::Middleware { reason } if reason.starts_with(DENIED) => {
                PlumbingError::from(SecurityError::Denied {
                    action: "create",
                    topic: "the parameter services' topics".into(),
                    enclave: enclave.clone().unwrap_or_else(|| "/".into()),
                    why: reason[DENIED.len()..].to_string(),
                })
            }
            e => PlumbingError::Ros(format!("cannot start the node spinner: {e:?}")),
        })?;
        let spinner = tokio::spawn(async move {
            if let Err(e) = spinner.spin().await {
                log::error!("node spinner stopped: {e:?}");
            }
        });
        log::debug!("node {} up in ROS domain {domain_id}", resolver.node_fqn());
        if use_sim_time {
            log::info!(
                "use_sim_time: the node's clock follows /clock; its messages are still stamped \
                 with the system clock"
            );
        }
        // (the enclave was checked when the plan was made: its certificates read)
        let certificate = match (&enclave, &plan) {
            (Some(_), Some(plan)) => match security::CertificateExpiry::of_enclave(plan) {
                Ok(expiry) => Some(expiry),
                Err(e) => {
                    log::warn!("security: the certificate's expiry cannot be read: {e}");
                    None
                }
            },
            _ => None,
        };
        Ok(RosNode {
            node,
            resolver,
            params,
            user_args,
            domain_id,
            enclave,
            certificate,
            spinner: Some(spinner),
            _context: context,
        })
    }

    /// Stop the spinner (parameter services, discovery) and wait for it, so that every
    /// DDS entity is removed while the participant still runs; then drop the node.
    /// Call it after the node's own publishers and subscriptions are dropped.
    pub async fn shutdown(self) {
        let RosNode {
            node,
            spinner,
            _context,
            ..
        } = self;
        drop(node); // tells the spinner to stop
        if let Some(handle) = spinner {
            if tokio::time::timeout(std::time::Duration::from_secs(2), handle)
                .await
                .is_err()
            {
                log::warn!("node spinner did not stop within 2 s");
            }
        }
    }

    /// The program's own arguments (everything outside `--ros-args … --`).
    pub fn user_args(&self) -> &[String] {
        &self.user_args
    }

    /// Current parameter values (updated by `ros2 param set`).
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// The name resolver (namespace, node name, remaps).
    pub fn resolver(&self) -> &Resolver {
        &self.resolver
    }

    /// The DDS domain in use.
    pub fn domain_id(&self) -> u16 {
        self.domain_id
    }

    /// The ros2-client node.
    pub fn node(&self) -> &Node {
        &self.node
    }

    /// The ros2-client node, to create what this module does not wrap (a service
    /// client).
    pub fn node_mut(&mut self) -> &mut Node {
        &mut self.node
    }

    fn topic<M: RosMessage>(
        &mut self,
        topic: &str,
        qos: &QosProfile,
    ) -> Result<(String, rustdds::Topic), PlumbingError> {
        let resolved = self.resolver.resolve(topic)?;
        let name = Name::parse(&resolved).map_err(|e| PlumbingError::Name {
            name: resolved.clone(),
            why: format!("{e:?}"),
        })?;
        let t = self
            .node
            .create_topic(&name, M::type_name(), qos)
            .map_err(|e| PlumbingError::Ros(format!("cannot create topic {resolved}: {e:?}")))?;
        Ok((resolved, t))
    }

    /// The SROS2 enclave this node runs in, `None` when unsecured.
    pub fn enclave(&self) -> Option<&str> {
        self.enclave.as_deref()
    }

    fn endpoint_error(
        &self,
        action: &'static str,
        topic: String,
        e: ros2_client::CreateError,
    ) -> PlumbingError {
        match e {
            ros2_client::CreateError::Middleware { reason } if reason.starts_with(DENIED) => {
                let reason = reason[DENIED.len()..].to_string();
                SecurityError::Denied {
                    action,
                    topic,
                    enclave: self.enclave.clone().unwrap_or_else(|| "/".into()),
                    why: reason,
                }
                .into()
            }
            e => PlumbingError::Ros(format!("cannot {action} {topic}: {e:?}")),
        }
    }

    /// An endpoint of `topic` (expanded in the node's namespace and remapped), made by
    /// `create`; a failure says what it was to `action` (`publish on`).
    fn endpoint<M: RosMessage, E>(
        &mut self,
        topic: &str,
        qos: QosProfile,
        action: &'static str,
        create: impl FnOnce(&mut Node, &rustdds::Topic, QosProfile) -> CreateResult<E>,
    ) -> Result<E, PlumbingError> {
        let (resolved, t) = self.topic::<M>(topic, &qos)?;
        create(&mut self.node, &t, qos).map_err(|e| self.endpoint_error(action, resolved, e))
    }

    /// A publisher on `topic` (expanded in the node's namespace and remapped).
    pub fn publisher<M: RosMessage>(
        &mut self,
        topic: &str,
        qos: QosProfile,
    ) -> Result<Publisher<M>, PlumbingError> {
        self.endpoint::<M, _>(topic, qos, "publish on", |node, t, qos| {
            node.create_publisher(t, Some(qos))
        })
    }

    /// A subscription to `topic` (expanded in the node's namespace and remapped).
    pub fn subscription<M: RosMessage>(
        &mut self,
        topic: &str,
        qos: QosProfile,
    ) -> Result<Subscription<M>, PlumbingError> {
        self.endpoint::<M, _>(topic, qos, "subscribe to", |node, t, qos| {
            node.create_subscription(t, Some(qos))
        })
    }

    /// A publisher on a topic of the contract, with its name, type and QoS (expanded
    /// in the node's namespace and remapped); its failed writes are logged.
    pub fn publish_on<M: RosMessage>(
        &mut self,
        topic: &Topic<M>,
    ) -> Result<TopicPublisher<M>, PlumbingError> {
        let publisher = self.publisher(topic.name, topic.qos.clone())?;
        Ok(TopicPublisher::new(publisher, topic.name))
    }

    /// A subscription to a topic of the contract, with its name, type and QoS
    /// (expanded in the node's namespace and remapped).
    pub fn subscribe_to<M: RosMessage>(
        &mut self,
        topic: &Topic<M>,
    ) -> Result<Subscription<M>, PlumbingError> {
        self.subscription(topic.name, topic.qos.clone())
    }

    /// Delete a subscription: its reader leaves the DDS graph, and the node stops
    /// listing it in `ros_discovery_info` (for a node that subscribes on demand).
    pub fn unsubscribe<M: 'static>(&mut self, subscription: Subscription<M>) {
        self.node.remove_subscription(subscription);
    }

    /// A topic of the contract as this node names it (namespace, remaps):
    /// `/arm2/xyz_target`.
    pub fn resolve<M: RosMessage>(&self, topic: &Topic<M>) -> Result<String, PlumbingError> {
        self.resolver.resolve(topic.name)
    }

    /// The node's `diagnostics` publisher.
    pub fn diagnostics(&mut self) -> Result<DiagnosticsPublisher, PlumbingError> {
        Ok(
            DiagnosticsPublisher::new(self.publish_on(&topics::DIAGNOSTICS)?)
                .with_certificate(self.certificate.clone()),
        )
    }
}

/// A node's `main`: runs `main` on a single-threaded tokio runtime, prints an error
/// (with its causes, `{:#}`) to stderr as `name: error` and exits with `error_code`.
pub fn run_main<F, E>(
    name: &str,
    error_code: u8,
    main: impl FnOnce() -> F,
) -> std::process::ExitCode
where
    F: std::future::Future<Output = Result<(), E>>,
    E: std::fmt::Display,
{
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("{name}: cannot start the async runtime: {e}");
            return std::process::ExitCode::from(error_code);
        }
    };
    match runtime.block_on(main()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{name}: {e:#}");
            std::process::ExitCode::from(error_code)
        }
    }
}

/// The shutdown signal [`main`] hands a node: resolves on SIGINT or SIGTERM, logged
/// ([`shutdown_logged`]).
pub type Shutdown = std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>>;

/// The whole `main` of a node that takes no arguments of its own: installs the signal
/// handlers first (Ctrl-C while the node starts stops it cleanly), starts the node from
/// this process's arguments and environment ([`RosNode::start`]: `--help`, a stray
/// argument, a bad parameter end it here), runs `body` with the node and the shutdown
/// signal, and after `body` returned `Ok` (its publishers and subscriptions dropped)
/// shuts the node down ([`RosNode::shutdown`]). As [`run_main`] it prints an error as
/// `NAME: error` and exits with 2.
pub fn main<E>(
    spec: NodeSpec,
    body: impl AsyncFnOnce(&mut RosNode, Shutdown) -> Result<(), E>,
) -> std::process::ExitCode
where
    E: From<PlumbingError> + std::fmt::Display,
{
    run_main(spec.name, 2, || async move {
        let shutdown: Shutdown = Box::pin(shutdown_logged());
        let mut node = RosNode::start(&spec)?;
        body(&mut node, shutdown).await?;
        node.shutdown().await;
        Ok::<(), E>(())
    })
}

/// [`shutdown_signal`], logging which signal it was. Like it, the handlers are
/// installed when this is called, not when the future is first polled.
pub fn shutdown_logged() -> impl std::future::Future<Output = ()> {
    let signal = shutdown_signal();
    async move {
        let signal = signal.await;
        log::info!("{signal}: shutting down");
    }
}

/// Resolves on SIGINT or SIGTERM, with the signal's name. The handlers are installed
/// when this is called (inside the runtime), so a signal that comes before the future
/// is first polled (while the node is still starting) is not lost: before, it found no
/// handler and killed the node with the default action (exit by SIGINT, not 0).
pub fn shutdown_signal() -> impl std::future::Future<Output = &'static str> {
    use tokio::signal::unix::{signal, SignalKind};
    let (int, term) = (
        signal(SignalKind::interrupt()),
        signal(SignalKind::terminate()),
    );
    async move {
        match (int, term) {
            (Ok(mut int), Ok(mut term)) => tokio::select! {
                _ = int.recv() => "SIGINT",
                _ = term.recv() => "SIGTERM",
            },
            _ => {
                log::error!("cannot install signal handlers; stop with SIGKILL");
                std::future::pending().await
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn domain_ids() {
        assert_eq!(domain_id_from_env(None).unwrap(), 0);
        assert_eq!(domain_id_from_env(Some("")).unwrap(), 0);
        assert_eq!(domain_id_from_env(Some("42")).unwrap(), 42);
        assert!(domain_id_from_env(Some("233")).is_err());
        assert!(domain_id_from_env(Some("x")).is_err());
        assert!(domain_id_from_env(Some("-1")).is_err());
    }
}
