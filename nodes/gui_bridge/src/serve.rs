//! `serve` (the default): the web panel, wired to ROS, and the start line with its URL.

use crate::access::{self, AccessPolicy, Token, TokenSource};
use crate::linger::{self, LingeringListener};
use crate::ros_outputs::RosOutputs;
use crate::tls::{self, Transport};
use crate::web::{Limits, WebState};
use crate::Input;
use anyhow::Context as _;
use axum::serve::ListenerExt as _;
use futures::StreamExt;
use ros_plumbing::peers::PeerWatch;
use ros_plumbing::{topics, ParameterValue, RosNode};
use std::future::Future;
use std::io::Write as _;
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;

/// Serve the panel on the `bind` parameter's address until `shutdown`.
pub async fn serve(
    node: &mut RosNode,
    arm: eezybot_kinematics::Arm,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let params = node.params().clone();
    let mut outputs = RosOutputs::new(node)?;
    // what goes on to the browsers is read by bounded readers (bounded.rs): any DDS peer
    // may publish a URDF of 16,000 joints or joint states of 30,000 names
    let joint_states = node.subscription::<crate::bounded::Joints>(
        topics::JOINT_STATES.name,
        topics::JOINT_STATES.qos.clone(),
    )?;
    let diagnostics = node.subscribe_to(&topics::DIAGNOSTICS)?;
    let rate = params.f64("rate").unwrap_or(50.0);
    let description = node.subscription::<crate::bounded::Description>(
        topics::ROBOT_DESCRIPTION.name,
        topics::ROBOT_DESCRIPTION.qos.clone(),
    )?;
    let servo_state = node.subscribe_to(&topics::SERVO_STATE)?;
    let estop = node.subscribe_to(&topics::ESTOP)?;
    let leader_joints = node.subscription::<crate::bounded::Joints>(
        topics::LEADER_JOINT_STATES.name,
        topics::LEADER_JOINT_STATES.qos.clone(),
    )?;
    let leader_deadman = node.subscribe_to(&topics::LEADER_DEADMAN)?;
    // the twin's cube and camera, read by bounded readers (scene.rs): at start, so the
    // graph shows the contract's endpoints whether or not a twin runs
    let tf = node.subscription::<crate::scene::CubeTf>(topics::TF.name, topics::TF.qos.clone())?;
    let camera_topic = params
        .string("camera_view")
        .map(|t| t.trim().to_string())
        .filter(|t| !t.is_empty());
    let camera = match &camera_topic {
        Some(topic) => {
            let sub = node.subscription::<crate::scene::CameraImage>(
                topic,
                topics::TWIN_CAMERA_IMAGE.qos.clone(),
            )?;
            log::info!(
                "camera view: {} (at most {} images a second to the browsers)",
                node.resolver().resolve(topic)?,
                params
                    .f64("camera_view_fps")
                    .unwrap_or(crate::scene::CAMERA_VIEW_FPS)
            );
            Some(sub)
        }
        None => {
            log::info!("no camera view (camera_view is empty)");
            None
        }
    };
    let (camera_tx, camera_rx) = tokio::sync::watch::channel(None);
    let (to_browsers, _) = tokio::sync::broadcast::channel(256);
    let limits = Limits::default();
    let (req_tx, req_rx) = crate::web::request_channels(&limits);
    let bind = params
        .string("bind")
        .unwrap_or_else(|| "127.0.0.1:8080".into());
    let listener = tokio::net::TcpListener::bind(&bind)
        .await
        .with_context(|| format!("cannot listen on {bind}"))?;
    let local = listener
        .local_addr()
        .with_context(|| format!("cannot tell the address bound for {bind}"))?;
    // a token whenever the panel or the Foxglove server listens beyond loopback: both
    // take the same one
    let foxglove_bind = params.string("foxglove_bind").unwrap_or_default();
    let (token, source) = access::resolve_token(
        &params.string("token").unwrap_or_default(),
        local.ip().is_loopback() && crate::foxglove::bind_is_loopback(&foxglove_bind),
        || {
            let mut bytes = [0u8; access::GENERATED_TOKEN_BYTES];
            getrandom::fill(&mut bytes).map_err(|e| e.to_string())?;
            Ok(bytes)
        },
    )?;
    hide_token_parameter(node, &params, source);
    // HTTPS beyond loopback, or plain HTTP only when insecure_http says so
    let mut beyond = vec![];
    if !local.ip().is_loopback() {
        beyond.push(format!("bind {}", bind.trim()));
    }
    if !crate::foxglove::bind_is_loopback(&foxglove_bind) {
        beyond.push(format!("foxglove_bind {}", foxglove_bind.trim()));
    }
    let transport = tls::choose(
        &beyond,
        &params.string("tls_cert").unwrap_or_default(),
        &params.string("tls_key").unwrap_or_default(),
        params.bool("insecure_http").unwrap_or(false),
    )?;
    let tls_setup = match &transport {
        Transport::Tls { cert, key } => {
            let setup = tls::load(cert, key)?;
            log::info!(
                "HTTPS and WSS with the certificate {}{}",
                cert.display(),
                setup
                    .expiry
                    .as_ref()
                    .map(|e| format!(
                        " (valid until {})",
                        ros_plumbing::diagnostics::utc_date(e.not_after)
                    ))
                    .unwrap_or_default()
            );
            outputs = outputs.also_certificate(setup.expiry.clone());
            Some(setup)
        }
        Transport::Insecure { .. } => {
            if let Some(warning) = transport.warning() {
                log::warn!("{warning}");
            }
            None
        }
        Transport::Plain => {
            if params.bool("insecure_http").unwrap_or(false) {
                log::info!("insecure_http has no effect: every listener is on loopback");
            }
            None
        }
    };
    let over_tls = tls_setup.is_some();
    let desk = crate::desk::Desk::new(crate::program_dir(
        &params.string("program_dir").unwrap_or_default(),
    ));
    log::info!("waypoint programs in {}", desk.dir().display());
    let names = crate::NodeNames::from_params(&params);
    let mut panel = crate::panel::Panel::new(arm, rate, desk, node.resolver().node_name())
        .with_node_names(names.clone())
        .with_scene(
            &params
                .string("base_frame")
                .unwrap_or_else(|| "base_link".into()),
            camera_topic.as_deref(),
        );
    let arm_config = params.string("arm_config").unwrap_or_default();
    match eezybot_kinematics::ArmConfig::load_or_shipped(&arm_config) {
        Ok(config) => {
            if let Err(e) = panel.enable_calibration(config) {
                log::warn!("no calibration wizard: {e}");
            }
        }
        Err(e) => log::warn!("no calibration wizard: {e}"),
    }
    let calibration_path = crate::calibration_ros::calibration_path(
        &params.string("calibration_file").unwrap_or_default(),
        &arm_config,
    );
    // the recorder's clients now, so that they are matched before a button is pressed
    let recorder = crate::recorder_ros::RosRecorder::new(node, &names.recorder);
    log::info!(
        "the recording card works with the recorder node `{}`",
        names.recorder
    );
    // what a browser that connects gets first: the bridge loop keeps it current
    let (snapshot, view) = tokio::sync::watch::channel(panel.snapshot());
    // from here on shared with the Foxglove server, which subscribes topics on demand
    let node = std::cell::RefCell::new(node);
    let p = params.clone();
    let urdf_view = view.clone();
    let state = WebState::new(
        to_browsers.clone(),
        req_tx,
        Arc::new(move || view.borrow().hello(p.f64("rate").unwrap_or(50.0))),
        AccessPolicy::new(token.clone()).over_tls(over_tls),
        limits,
    )
    .with_urdf(Arc::new(move || urdf_view.borrow().urdf.clone()))
    .with_camera(camera_rx);
    let foxglove = crate::foxglove::serve(
        &node,
        AccessPolicy::new(token.clone()).over_tls(over_tls),
        tls_setup.as_ref().map(|t| t.config.clone()),
    )
    .await?;
    let web =
        crate::web::WebStats::default().with_foxglove(foxglove.as_ref().map(|f| f.front.clone()));
    let scheme = transport.scheme();
    let url = format!("{scheme}://{local}/");
    // no borrow of the node may live across an await: the Foxglove server borrows it
    let (panel_name, xyz_target, servo_state_topic) = {
        let ros = node.borrow();
        let xyz_target = ros.resolve(&topics::XYZ_TARGET)?;
        log::info!(
            "{} ready in ROS domain {}: web panel on {url} ({}) -> {xyz_target}",
            ros.resolver().node_fqn(),
            ros.domain_id(),
            match source {
                TokenSource::None => "loopback only, no token",
                TokenSource::Generated => "token required, generated",
                TokenSource::Parameter => "token required, from the token parameter",
            },
        );
        (
            format!("{}: operator panel", ros.resolver().node_name()),
            xyz_target,
            ros.resolve(&topics::SERVO_STATE)?,
        )
    };
    print_panel_urls(scheme, local, token.as_ref());
    let tcp = LingeringListener::new(listener, linger::LINGER);
    let app = crate::web::router(state).into_make_service_with_connect_info::<SocketAddr>();
    let server = match tls_setup {
        Some(setup) => {
            // the head arrives encrypted: its deadline is kept on the decrypted stream
            // (`tap_io` for axum's ConnectInfo, which it gives a tapped listener's address;
            // TCP_NODELAY is set before the handshake)
            let listener = tls::TlsListener::new(tcp, setup.config, linger::HEAD_TIMEOUT)
                .with_context(|| format!("cannot serve HTTPS on {local}"))?
                .tap_io(|_| {});
            tokio::spawn(async move {
                if let Err(e) = axum::serve(listener, app).await {
                    log::error!("web server stopped: {e}");
                }
            })
        }
        None => tokio::spawn(async move {
            let listener = tcp
                .with_head_timeout(linger::HEAD_TIMEOUT)
                .tap_io(|s| s.set_nodelay());
            if let Err(e) = axum::serve(listener, app).await {
                log::error!("web server stopped: {e}");
            }
        }),
    };
    let mut streams = vec![
        bounded_inputs(&joint_states, topics::JOINT_STATES.name, |j| {
            j.into_input(topics::JOINT_STATES.name, Input::JointStates)
        }),
        bounded_inputs(
            &description,
            topics::ROBOT_DESCRIPTION.name,
            crate::bounded::Description::into_input,
        ),
        inputs_of(&diagnostics, &topics::DIAGNOSTICS, Input::Diagnostics),
        inputs_of(&servo_state, &topics::SERVO_STATE, Input::ServoState),
        inputs_of(&estop, &topics::ESTOP, |m| Input::Estop(m.data)),
        bounded_inputs(&leader_joints, topics::LEADER_JOINT_STATES.name, |j| {
            j.into_input(topics::LEADER_JOINT_STATES.name, Input::LeaderJoints)
        }),
        inputs_of(&leader_deadman, &topics::LEADER_DEADMAN, |m| {
            Input::LeaderDeadman(m.data)
        }),
        ros_plumbing::samples::inputs(&tf, Input::Tf, |error| Input::Unreadable {
            topic: topics::TF.name,
            error,
        }),
    ];
    if let Some(camera) = &camera {
        streams.push(ros_plumbing::samples::inputs(
            camera,
            Input::CameraImage,
            |error| Input::Unreadable {
                topic: "camera_view",
                error,
            },
        ));
    }
    let inputs = futures::stream::select_all(streams);
    let reporting = crate::Reporting {
        name: panel_name,
        url,
        peers: PeerWatch::new(&crate::watched_topics(&xyz_target, &servo_state_topic)),
        counts: || {
            let ros = node.borrow();
            vec![
                outputs.xyz.get_subscription_count(ros.node()),
                servo_state.get_publisher_count(ros.node()),
            ]
        },
        transport,
    };
    let calibration =
        crate::calibration_ros::RosCalibration::new(&node, calibration_path, &names.ik);
    log::info!(
        "the calibration wizard saves to {}",
        calibration.path().display()
    );
    let panel = crate::run(
        panel,
        crate::Handles {
            inputs,
            requests: req_rx,
            web,
            to_browsers,
            snapshot,
            outputs: &outputs,
            params,
            reporting,
            calibration: &calibration,
            recorder: &recorder,
            camera: camera_tx,
            shutdown,
        },
    );
    match foxglove {
        // the Foxglove forwarding never ends by itself: the panel's shutdown ends both
        Some(foxglove) => {
            tokio::select! {
                _ = panel => {}
                _ = foxglove.forwarding => {}
            }
        }
        None => panel.await,
    }
    server.abort();
    Ok(())
}

/// The samples of `topic` (read by `subscription`) as the panel's inputs; a sample that
/// cannot be read becomes [`Input::Unreadable`] (logged and counted).
fn inputs_of<'a, M: eezybot_msgs::RosMessage>(
    subscription: &'a ros_plumbing::Subscription<M>,
    topic: &ros_plumbing::Topic<M>,
    input: fn(M) -> Input,
) -> futures::stream::BoxStream<'a, Input> {
    let topic = topic.name;
    subscription
        .async_stream()
        .map(move |r| match r {
            Ok((m, _)) => input(m),
            Err(e) => Input::Unreadable {
                topic,
                error: format!("{e:?}"),
            },
        })
        .boxed()
}

/// The samples of `topic` read by a bounded reader (bounded.rs), as the panel's inputs:
/// `input` of each (the sample or its refusal), [`Input::Unreadable`] for one that
/// cannot be read.
fn bounded_inputs<'a, M: eezybot_msgs::RosMessage>(
    subscription: &'a ros_plumbing::Subscription<M>,
    topic: &'static str,
    input: fn(M) -> Input,
) -> futures::stream::BoxStream<'a, Input> {
    ros_plumbing::samples::inputs(subscription, input, move |error| Input::Unreadable {
        topic,
        error,
    })
}

/// From now on the `token` parameter reads `(generated)` or `(hidden)`, so that
/// `ros2 param get` (and `ros2 param dump`) never shows the secret: anyone in the ROS
/// domain may read parameters.
fn hide_token_parameter(node: &RosNode, params: &ros_plumbing::Params, source: TokenSource) {
    let Some(shown) = source.shown_as() else {
        return;
    };
    // the store first: the read-only check compares with it and lets the same value pass
    params.set("token", ParameterValue::String(shown.into()));
    if let Err(e) = node
        .node()
        .set_parameter("token", ParameterValue::String(shown.into()))
    {
        log::warn!("the token parameter could not be hidden from `ros2 param get`: {e}");
    }
}

/// The addresses a panel bound to `local` is reached at: `local` itself, or for an
/// unspecified address (0.0.0.0, [::]) this host's addresses, loopback first.
fn panel_addresses(local: SocketAddr) -> Vec<IpAddr> {
    if !local.ip().is_unspecified() {
        return vec![local.ip()];
    }
    let mut found: Vec<IpAddr> = vec![];
    #[cfg(unix)]
    if let Ok(addrs) = nix::ifaddrs::getifaddrs() {
        for a in addrs {
            let Some(addr) = a.address else { continue };
            let ip = if let Some(v4) = addr.as_sockaddr_in() {
                IpAddr::V4(v4.ip())
            } else if let Some(v6) = addr.as_sockaddr_in6() {
                // link-local addresses need a zone in a URL: leave them out
                if !local.is_ipv6() || (v6.ip().segments()[0] & 0xffc0) == 0xfe80 {
                    continue;
                }
                IpAddr::V6(v6.ip())
            } else {
                continue;
            };
            if !found.contains(&ip) {
                found.push(ip);
            }
        }
    }
    if found.is_empty() {
        found.push(local.ip());
    }
    found.sort_by_key(|ip| !ip.is_loopback());
    found
}

/// The start line meant for the operator: the panel's URL(s) with the token, on
/// standard output only (never in the log, which also goes to `/rosout`). The token
/// goes in the fragment (`#token=`), which the browser never sends to a server (no
/// request line, proxy log or Referer has it); the page moves it to its origin's
/// storage and out of the address bar.
fn print_panel_urls(scheme: &str, local: SocketAddr, token: Option<&Token>) {
    let query = token
        .map(|t| format!("#token={}", t.reveal()))
        .unwrap_or_default();
    let mut out = std::io::stdout().lock();
    for ip in panel_addresses(local) {
        let _ = writeln!(
            out,
            "web panel: {scheme}://{}/{query}",
            SocketAddr::new(ip, local.port())
        );
    }
    if token.is_some() {
        let _ = writeln!(
            out,
            "web panel: every client needs the token above; anyone who has it can move the arm (README: Exposing the web panel safely)"
        );
    }
    let _ = out.flush();
}
