//! `gui_bridge` binary: the web panel (default), or the command-line driver:
//!
//! ```text
//! gui_bridge                                   web page on http://127.0.0.1:8080 (parameter `bind`)
//! gui_bridge --once 0.2 0 0.15 [--gripper 0.5] publish one target, exit when compute_ik took it
//! gui_bridge --play waypoints.csv              play x,y,z,gripper,dwell rows: move, arrive, set
//!                                              the claw, dwell
//! gui_bridge --play waypoints.csv --line       the same in straight lines (compute_ik's
//!                                              `motion` set to `line` meanwhile, then put back)
//! gui_bridge --record taught.csv               save what the operator sends, as such rows
//! ```

use anyhow::{anyhow, bail, Context as _};
use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use eezybot_msgs::geometry_msgs::{Point, PointStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::{Bool, Float64, Header, String as StringMsg};
use eezybot_msgs::Time;
use futures::StreamExt;
use gui_bridge::access::{self, AccessPolicy, Token, TokenSource};
use gui_bridge::teleop::{format_waypoint, parse_waypoints, Teleop, Waypoint, WAYPOINT_HEADER};
use gui_bridge::web::{Limits, WebState};
use gui_bridge::{Input, Outputs};
use ros2_client::{Publisher, Subscription};
use ros_plumbing::diagnostics::DiagnosticsPublisher;
use ros_plumbing::peers::PeerWatch;
use ros_plumbing::{qos, ParameterValue, RosNode};
use std::io::Write as _;
use std::net::{IpAddr, SocketAddr};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

struct RosOutputs {
    xyz: Publisher<PointStamped>,
    gripper: Publisher<Float64>,
    joints: Publisher<JointState>,
    estop: Publisher<Bool>,
    diagnostics: DiagnosticsPublisher,
    frame: String,
}

impl Outputs for RosOutputs {
    fn xyz_target(&self, xyz: [f64; 3], stamp: Time) {
        let msg = PointStamped {
            header: Header {
                stamp,
                frame_id: self.frame.clone(),
            },
            point: Point {
                x: xyz[0],
                y: xyz[1],
                z: xyz[2],
            },
        };
        if let Err(e) = self.xyz.publish(msg) {
            log::warn!("could not publish xyz_target: {e:?}");
        }
    }
    fn gripper_target(&self, opening: f64) {
        if let Err(e) = self.gripper.publish(Float64 { data: opening }) {
            log::warn!("could not publish gripper_target: {e:?}");
        }
    }
    fn joint_target(&self, positions: &[(String, f64)], stamp: Time) {
        let msg = JointState {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            name: positions.iter().map(|(n, _)| n.clone()).collect(),
            position: positions.iter().map(|(_, v)| *v).collect(),
            velocity: vec![],
            effort: vec![],
        };
        if let Err(e) = self.joints.publish(msg) {
            log::warn!("could not publish joint_target: {e:?}");
        }
    }
    fn estop(&self, engaged: bool) {
        if let Err(e) = self.estop.publish(Bool { data: engaged }) {
            log::warn!("could not publish estop: {e:?}");
        }
    }
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.publish(vec![status]);
    }
}

enum Mode {
    Web,
    Once { xyz: [f64; 3], gripper: Option<f64> },
    Play(String),
    Record(String),
}

/// The command line after the ROS arguments.
struct Cli {
    mode: Mode,
    timeout: Duration,
    /// `--line`: straight Cartesian lines (compute_ik's `motion:=line`) for `--once`/`--play`
    line: bool,
}

fn parse_mode(args: &[String]) -> anyhow::Result<Cli> {
    let mut mode = Mode::Web;
    let mut line = false;
    let mut gripper = None;
    let mut timeout = Duration::from_secs(15);
    let mut it = args.iter();
    let num = |s: Option<&String>, what: &str| -> anyhow::Result<f64> {
        let s = s.ok_or_else(|| anyhow!("{what} is missing"))?;
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| anyhow!("{what} `{s}` is not a number"))
    };
    while let Some(a) = it.next() {
        match a.as_str() {
            "--once" => {
                mode = Mode::Once {
                    xyz: [
                        num(it.next(), "X")?,
                        num(it.next(), "Y")?,
                        num(it.next(), "Z")?,
                    ],
                    gripper: None,
                }
            }
            "--gripper" => gripper = Some(num(it.next(), "gripper opening")?),
            "--play" => {
                mode = Mode::Play(
                    it.next()
                        .ok_or_else(|| anyhow!("--play needs a CSV file"))?
                        .clone(),
                )
            }
            "--record" => {
                mode = Mode::Record(
                    it.next()
                        .ok_or_else(|| anyhow!("--record needs a CSV file"))?
                        .clone(),
                )
            }
            "--timeout" => timeout = Duration::from_secs_f64(num(it.next(), "timeout")?.max(0.1)),
            "--line" => line = true,
            other => bail!("unexpected argument `{other}` (see --help)"),
        }
    }
    if let Mode::Once { gripper: g, .. } = &mut mode {
        *g = gripper;
    }
    if line && !matches!(mode, Mode::Once { .. } | Mode::Play(_)) {
        bail!("--line goes with --once or --play");
    }
    Ok(Cli {
        mode,
        timeout,
        line,
    })
}

/// Waits for the effect of one target: compute_ik's `joint_states` carrying its stamp
/// (taken), or its diagnostics naming a rejection.
struct Delivery<'a> {
    node: &'a RosNode,
    joint_states: &'a Subscription<JointState>,
    diagnostics: &'a Subscription<DiagnosticArray>,
    rejected_seen: Option<u64>,
}

impl<'a> Delivery<'a> {
    /// Ready to send once someone subscribes `xyz_target`.
    async fn connect(
        node: &'a RosNode,
        joint_states: &'a Subscription<JointState>,
        diagnostics: &'a Subscription<DiagnosticArray>,
        outputs: &RosOutputs,
        timeout: Duration,
    ) -> anyhow::Result<Delivery<'a>> {
        let d = Delivery {
            node,
            joint_states,
            diagnostics,
            rejected_seen: None,
        };
        d.wait_for_subscriber(&outputs.xyz, timeout).await?;
        tokio::time::sleep(Duration::from_millis(200)).await; // let the reader see our writer too
        Ok(d)
    }

    /// Wait until someone subscribes `xyz_target`.
    async fn wait_for_subscriber(
        &self,
        publisher: &Publisher<PointStamped>,
        timeout: Duration,
    ) -> anyhow::Result<()> {
        let deadline = Instant::now() + timeout;
        while publisher.get_subscription_count(self.node.node()) == 0 {
            if Instant::now() > deadline {
                bail!(
                    "nobody subscribes {} (is compute_ik running in this ROS domain?)",
                    self.node.resolver().resolve("xyz_target")?
                );
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        Ok(())
    }

    /// Publish `xyz` (after the local reachability check) and wait for compute_ik.
    async fn send(
        &mut self,
        out: &RosOutputs,
        arm: &eezybot_kinematics::Arm,
        xyz: [f64; 3],
        timeout: Duration,
    ) -> anyhow::Result<()> {
        arm.solve_position(&xyz.into(), 0.0)
            .map_err(|e| anyhow!("target {xyz:?} refused before sending: {e}"))?;
        let stamp = Time::now();
        out.xyz_target(xyz, stamp);
        let deadline = tokio::time::Instant::now() + timeout;
        let js = self.joint_states.async_stream();
        let diags = self.diagnostics.async_stream();
        tokio::pin!(js);
        tokio::pin!(diags);
        loop {
            tokio::select! {
                _ = tokio::time::sleep_until(deadline) => bail!("no answer from compute_ik within {:.1} s", timeout.as_secs_f64()),
                Some(Ok((m, _))) = js.next() => if m.header.stamp == stamp { return Ok(()) },
                Some(Ok((d, _))) = diags.next() => {
                    for s in d.status.iter().filter(|s| s.name.starts_with("compute_ik")) {
                        let get = |k: &str| s.values.iter().find(|kv| kv.key == k).map(|kv| kv.value.clone());
                        let rejected: u64 = get("rejected").and_then(|v| v.parse().ok()).unwrap_or(0);
                        if self.rejected_seen.is_some_and(|n| rejected > n) && get("last_rejection_topic").as_deref() == Some("xyz_target") {
                            bail!("compute_ik rejected {xyz:?}: {}", get("last_rejection").unwrap_or_default());
                        }
                        self.rejected_seen = Some(rejected);
                    }
                }
            }
        }
    }

    /// Wait until compute_ik's `joint_states` has the arm at `xyz` (its planned motion
    /// ends exactly on the target's joints).
    async fn arrival(
        &self,
        arm: &eezybot_kinematics::Arm,
        xyz: [f64; 3],
        timeout: Duration,
    ) -> anyhow::Result<()> {
        let goal = arm
            .solve_position(&xyz.into(), 0.0)
            .map_err(|e| anyhow!("target {xyz:?}: {e}"))?;
        let want = [goal.base_rad, goal.shoulder_rad, goal.elbow_rad];
        let names = &eezybot_kinematics::ACTUATED_JOINTS[..3];
        let at_goal = |m: &JointState| {
            names.iter().zip(want).all(|(n, w)| {
                m.name
                    .iter()
                    .position(|x| x == n)
                    .and_then(|i| m.position.get(i))
                    .is_some_and(|p| (p - w).abs() < 1e-6)
            })
        };
        let js = self.joint_states.async_stream();
        tokio::pin!(js);
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            tokio::select! {
                _ = tokio::time::sleep_until(deadline) => bail!("the arm did not arrive at {xyz:?} within {:.1} s", timeout.as_secs_f64()),
                Some(Ok((m, _))) = js.next() => if at_goal(&m) { return Ok(()) },
            }
        }
    }
}

/// compute_ik's `motion` set to `line` for a playback, and put back afterwards.
struct LineMotion {
    client: ros_plumbing::remote_params::RemoteParameters,
    previous: ParameterValue,
}

impl LineMotion {
    async fn engage(node: &mut RosNode, timeout: Duration) -> anyhow::Result<LineMotion> {
        let client = ros_plumbing::remote_params::RemoteParameters::new(node, "compute_ik")?;
        client.wait(node, timeout).await.map_err(|e| anyhow!(e))?;
        let previous = client
            .get("motion")
            .await
            .map_err(|e| anyhow!(e))?
            .ok_or_else(|| {
                anyhow!(
                    "{} has no `motion` parameter (too old a compute_ik?)",
                    client.node_name()
                )
            })?;
        client
            .set("motion", ParameterValue::String("line".into()))
            .await
            .map_err(|e| anyhow!(e))?;
        log::info!("{} motion:=line for this playback", client.node_name());
        Ok(LineMotion { client, previous })
    }

    async fn restore(self) {
        match self.client.set("motion", self.previous.clone()).await {
            Ok(()) => log::info!(
                "{} motion back to {:?}",
                self.client.node_name(),
                self.previous
            ),
            Err(e) => log::error!(
                "could not put compute_ik's motion back to {:?}: {e}",
                self.previous
            ),
        }
    }
}

async fn main_async() -> anyhow::Result<()> {
    let spec = gui_bridge::spec();
    let mut node = RosNode::start(&spec)?;
    let Cli {
        mode,
        timeout,
        line,
    } = parse_mode(node.user_args())?;
    let params = node.params().clone();
    let arm = gui_bridge::load_arm(&params.string("arm_config").unwrap_or_default())
        .map_err(anyhow::Error::msg)?;
    let outputs = RosOutputs {
        xyz: node.publisher("xyz_target", qos::COMMANDS)?,
        gripper: node.publisher("gripper_target", qos::COMMANDS)?,
        joints: node.publisher("joint_target", qos::COMMANDS)?,
        estop: node.publisher("estop", qos::ESTOP)?,
        diagnostics: node.diagnostics()?,
        frame: params
            .string("base_frame")
            .unwrap_or_else(|| "base_link".into()),
    };
    let joint_states = node.subscription::<JointState>("joint_states", qos::COMMANDS)?;
    let diagnostics = node.subscription::<DiagnosticArray>("diagnostics", qos::DIAGNOSTICS)?;
    let shutdown = ros_plumbing::shutdown_logged();
    let line_motion = if line {
        Some(LineMotion::engage(&mut node, timeout).await?)
    } else {
        None
    };
    let result = match mode {
        Mode::Once { xyz, gripper } => {
            let deliver = async {
                let mut d =
                    Delivery::connect(&node, &joint_states, &diagnostics, &outputs, timeout)
                        .await?;
                d.send(&outputs, &arm, xyz, timeout).await?;
                if line {
                    // the line is the point: stay until it is drawn
                    d.arrival(&arm, xyz, timeout).await?;
                }
                if let Some(g) = gripper {
                    outputs.gripper_target(g); // at the target, as a waypoint's gripper
                }
                println!("delivered {xyz:?}");
                anyhow::Ok(())
            };
            tokio::select! {
                r = deliver => r,
                _ = shutdown => Ok(()),
            }
        }
        Mode::Play(path) => {
            let text =
                std::fs::read_to_string(&path).with_context(|| format!("cannot read {path}"))?;
            let waypoints = parse_waypoints(&text).map_err(|e| anyhow!("{path}: {e}"))?;
            let mut d =
                Delivery::connect(&node, &joint_states, &diagnostics, &outputs, timeout).await?;
            let play = async {
                for (i, w) in waypoints.iter().enumerate() {
                    // move, arrive, then set the claw there: the order --record writes
                    // rows in
                    d.send(&outputs, &arm, w.xyz, timeout)
                        .await
                        .with_context(|| format!("waypoint {}", i + 1))?;
                    d.arrival(&arm, w.xyz, timeout)
                        .await
                        .with_context(|| format!("waypoint {}", i + 1))?;
                    if let Some(g) = w.gripper {
                        outputs.gripper_target(g);
                    }
                    println!(
                        "waypoint {}/{}: {:?} gripper {:?}, dwell {:.2} s",
                        i + 1,
                        waypoints.len(),
                        w.xyz,
                        w.gripper,
                        w.dwell_s
                    );
                    tokio::time::sleep(Duration::from_secs_f64(w.dwell_s)).await;
                }
                anyhow::Ok(())
            };
            tokio::select! {
                r = play => r,
                _ = shutdown => Ok(()),
            }
        }
        Mode::Record(path) => record(&mut node, &path, shutdown).await,
        Mode::Web => {
            web(
                &mut node,
                arm,
                &outputs,
                &joint_states,
                &diagnostics,
                params,
                shutdown,
            )
            .await
        }
    };
    if let Some(l) = line_motion {
        l.restore().await;
    }
    drop(outputs);
    drop((joint_states, diagnostics));
    node.shutdown().await;
    result
}

async fn record(
    node: &mut RosNode,
    path: &str,
    shutdown: impl std::future::Future<Output = ()>,
) -> anyhow::Result<()> {
    let mut file = std::fs::File::create(path).with_context(|| format!("cannot create {path}"))?;
    writeln!(file, "{WAYPOINT_HEADER}")?;
    let targets = node.subscription::<PointStamped>("xyz_target", qos::COMMANDS)?;
    let gripper = node.subscription::<Float64>("gripper_target", qos::COMMANDS)?;
    println!(
        "recording {} and {} into {path}; Ctrl-C to stop",
        node.resolver().resolve("xyz_target")?,
        node.resolver().resolve("gripper_target")?
    );
    let (t, g) = (targets.async_stream(), gripper.async_stream());
    tokio::pin!(t, g, shutdown);
    let mut pending: Option<(Waypoint, Instant)> = None;
    let mut opening: Option<f64> = None;
    let mut rows = 0;
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            Some(Ok((m, _))) = t.next() => {
                if let Some((mut w, at)) = pending.take() {
                    w.dwell_s = at.elapsed().as_secs_f64();
                    writeln!(file, "{}", format_waypoint(&w))?;
                    rows += 1;
                }
                pending = Some((Waypoint { xyz: [m.point.x, m.point.y, m.point.z], gripper: opening, dwell_s: 0.0 }, Instant::now()));
            }
            Some(Ok((m, _))) = g.next() => {
                opening = Some(m.data);
                if let Some((w, _)) = pending.as_mut() {
                    w.gripper = opening;
                }
            }
        }
    }
    if let Some((w, _)) = pending {
        writeln!(file, "{}", format_waypoint(&w))?;
        rows += 1;
    }
    file.flush()?;
    println!("recorded {rows} waypoints into {path}");
    Ok(())
}

async fn web(
    node: &mut RosNode,
    arm: eezybot_kinematics::Arm,
    outputs: &RosOutputs,
    joint_states: &Subscription<JointState>,
    diagnostics: &Subscription<DiagnosticArray>,
    params: ros_plumbing::Params,
    shutdown: impl std::future::Future<Output = ()>,
) -> anyhow::Result<()> {
    let rate = params.f64("rate").unwrap_or(50.0);
    let teleop = Arc::new(Mutex::new(Teleop::new(arm, rate)));
    let description =
        node.subscription::<StringMsg>("robot_description", qos::ROBOT_DESCRIPTION)?;
    let servo_state = node.subscription::<JointState>("servo_state", qos::COMMANDS)?;
    let estop = node.subscription::<Bool>("estop", qos::ESTOP)?;
    let (to_browsers, _) = tokio::sync::broadcast::channel(256);
    let limits = Limits::default();
    let (req_tx, req_rx) = gui_bridge::web::request_channels(&limits);
    let t = teleop.clone();
    let p = params.clone();
    let bind = params
        .string("bind")
        .unwrap_or_else(|| "127.0.0.1:8080".into());
    let listener = tokio::net::TcpListener::bind(&bind)
        .await
        .with_context(|| format!("cannot listen on {bind}"))?;
    let local = listener
        .local_addr()
        .with_context(|| format!("cannot tell the address bound for {bind}"))?;
    let (token, source) = access::resolve_token(
        &params.string("token").unwrap_or_default(),
        local.ip().is_loopback(),
        || {
            let mut bytes = [0u8; access::GENERATED_TOKEN_BYTES];
            getrandom::fill(&mut bytes).map_err(|e| e.to_string())?;
            Ok(bytes)
        },
    )?;
    hide_token_parameter(node, &params, source);
    let state = WebState::new(
        to_browsers.clone(),
        req_tx,
        Arc::new(move || {
            t.lock()
                .map(|t| gui_bridge::hello_json(&t, p.f64("rate").unwrap_or(50.0)))
                .unwrap_or_default()
        }),
        AccessPolicy::new(token.clone(), local.port()),
        limits,
    );
    let web_stats = state.stats.clone();
    let url = format!("http://{local}/");
    log::info!(
        "{} ready in ROS domain {}: web panel on {url} ({}) -> {}",
        node.resolver().node_fqn(),
        node.domain_id(),
        match source {
            TokenSource::None => "loopback only, no token",
            TokenSource::Generated => "token required, generated",
            TokenSource::Parameter => "token required, from the token parameter",
        },
        node.resolver().resolve("xyz_target")?
    );
    print_panel_urls(local, token.as_ref());
    let server = tokio::spawn(async move {
        let app =
            gui_bridge::web::router(state).into_make_service_with_connect_info::<SocketAddr>();
        if let Err(e) = axum::serve(listener, app).await {
            log::error!("web server stopped: {e}");
        }
    });
    // a sample that cannot be read becomes Input::Unreadable: logged and counted
    let unreadable = |topic: &'static str, e: &dyn std::fmt::Debug| Input::Unreadable {
        topic,
        error: format!("{e:?}"),
    };
    let inputs = futures::stream::select_all([
        joint_states
            .async_stream()
            .map(move |r| match r {
                Ok((m, _)) => Input::JointStates(m),
                Err(e) => unreadable("joint_states", &e),
            })
            .boxed(),
        description
            .async_stream()
            .map(move |r| match r {
                Ok((m, _)) => Input::RobotDescription(m.data),
                Err(e) => unreadable("robot_description", &e),
            })
            .boxed(),
        diagnostics
            .async_stream()
            .map(move |r| match r {
                Ok((m, _)) => Input::Diagnostics(m),
                Err(e) => unreadable("diagnostics", &e),
            })
            .boxed(),
        servo_state
            .async_stream()
            .map(move |r| match r {
                Ok((m, _)) => Input::ServoState(m),
                Err(e) => unreadable("servo_state", &e),
            })
            .boxed(),
        estop
            .async_stream()
            .map(move |r| match r {
                Ok((m, _)) => Input::Estop(m.data),
                Err(e) => unreadable("estop", &e),
            })
            .boxed(),
    ]);
    let reporting = gui_bridge::Reporting {
        name: format!("{}: operator panel", node.resolver().node_name()),
        url,
        peers: PeerWatch::new(&gui_bridge::watched_topics(
            &node.resolver().resolve("xyz_target")?,
            &node.resolver().resolve("servo_state")?,
        )),
        counts: || {
            vec![
                outputs.xyz.get_subscription_count(node.node()),
                servo_state.get_publisher_count(node.node()),
            ]
        },
        web: web_stats,
    };
    gui_bridge::run(
        teleop,
        inputs,
        req_rx,
        to_browsers,
        outputs,
        params,
        reporting,
        shutdown,
    )
    .await;
    server.abort();
    Ok(())
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
/// standard output only (never in the log, which also goes to `/rosout`).
fn print_panel_urls(local: SocketAddr, token: Option<&Token>) {
    let query = token
        .map(|t| format!("?token={}", t.reveal()))
        .unwrap_or_default();
    let mut out = std::io::stdout().lock();
    for ip in panel_addresses(local) {
        let _ = writeln!(
            out,
            "web panel: http://{}/{query}",
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

fn main() -> ExitCode {
    ros_plumbing::run_main("gui_bridge", 1, main_async)
}
