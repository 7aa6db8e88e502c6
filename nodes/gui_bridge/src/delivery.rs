//! `once` and `play`: deliver targets to compute_ik and wait for its answer, through its
//! public interfaces only. A target is **taken** when `joint_states` carries its stamp
//! (the first step of the motion it starts carries the target's `header.stamp`), and
//! **refused** when a `diagnostics` status reports a refusal of that stamp (read by
//! [`feedback`]); it **arrived** when `joint_states` has the arm at its joints.
//!
//! compute_ik's `motion` parameter (`joint` / `line`) is set for `--line` and for the
//! program points that name a mode, and put back as it was at the end.

use crate::cli::{DeliveryArgs, OnceArgs, PlayArgs};
use crate::program::{MoveMode, Program};
use crate::ros_outputs::RosOutputs;
use crate::Outputs;
use anyhow::{anyhow, Context as _};
use eezybot_kinematics::Arm;
use eezybot_msgs::diagnostic_msgs::DiagnosticArray;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use futures::StreamExt;
use ros_plumbing::feedback;
use ros_plumbing::remote_params::RemoteParameters;
use ros_plumbing::Subscription;
use ros_plumbing::{topics, ParameterValue, RosNode};
use std::future::Future;
use std::time::Duration;
use tokio::time::Instant;

/// Why a target was not delivered: the command was refused (exit status 1), as
/// opposed to a usage or configuration error.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NotDelivered {
    /// The local reachability check (the same closed form as compute_ik's) refused it.
    #[error("target {xyz:?} refused before sending: {reason}")]
    Unreachable {
        /// the target
        xyz: [f64; 3],
        /// why
        reason: String,
    },
    /// A node refused it (its diagnostics carried the target's stamp).
    #[error("{node} refused {xyz:?}: {reason}")]
    Refused {
        /// the node that refused it, as it names itself
        node: String,
        /// the target
        xyz: [f64; 3],
        /// its `last_rejection`, or its status message
        reason: String,
    },
    /// Nobody subscribes `xyz_target`.
    #[error("nobody subscribes {topic} (is compute_ik running in this ROS domain?)")]
    NobodyListens {
        /// the resolved topic
        topic: String,
    },
    /// No answer in time.
    #[error("no answer from compute_ik within {timeout_s:.1} s ({joint_states} joint_states received meanwhile, none with the target's stamp)")]
    NoAnswer {
        /// how long we waited
        timeout_s: f64,
        /// the `joint_states` messages that came meanwhile
        joint_states: usize,
    },
    /// No `joint_states` came from its publisher in time.
    #[error("{publishers} node(s) publish joint_states, but none of their messages came within {timeout_s:.1} s")]
    NoJointStates {
        /// how long we waited
        timeout_s: f64,
        /// the publishers matched
        publishers: usize,
    },
    /// `calibrate` ended without saving (cancelled, failed, or not started).
    #[error("{0}")]
    NotCalibrated(String),
    /// Taken, but the arm was not there in time.
    #[error("the arm did not arrive at {xyz:?} within {timeout_s:.1} s")]
    DidNotArrive {
        /// the target
        xyz: [f64; 3],
        /// how long we waited
        timeout_s: f64,
    },
}

/// How long a command-line delivery waits at its end for its subscribers to acknowledge
/// the last targets (a subscriber that died without leaving keeps it waiting this long).
pub const DELIVERED_WAIT: Duration = Duration::from_secs(5);

/// `once X Y Z [--gripper G]`: deliver one target (with `--line`, wait until the arm is
/// there), then set the claw.
pub async fn once(
    node: &mut RosNode,
    arm: &Arm,
    args: OnceArgs,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let xyz = args.xyz();
    check(arm, xyz)?;
    tokio::pin!(shutdown);
    let Some(mut motion) = MotionSwitch::engage(node, &args.delivery, false, &mut shutdown).await?
    else {
        return Ok(()); // Ctrl-C while compute_ik's parameters were awaited
    };
    let mut d = Delivery::new(node, &args.delivery)?;
    let node = &*node;
    let work = async {
        if let Some(m) = motion.as_mut() {
            m.set(None).await?;
        }
        d.connect(node).await?;
        d.send(xyz).await?;
        if args.delivery.line {
            // the line is the point: stay until it is drawn
            d.arrival(arm, xyz).await?;
        }
        if let Some(g) = args.gripper {
            d.out.gripper_target(g); // at the target, as a waypoint's gripper
        }
        d.delivered().await;
        println!("delivered {xyz:?}");
        Ok(())
    };
    let result = until_shutdown(work, &mut shutdown).await;
    MotionSwitch::restore(motion).await;
    result
}

/// `play FILE`: each point of the program in turn: set compute_ik's `motion` if the
/// point names a mode (else `line` with `--line`, or as it was), move, arrive, set the
/// claw, dwell; the first refusal stops with its waypoint's number.
pub async fn play(
    node: &mut RosNode,
    arm: &Arm,
    args: PlayArgs,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let path = args.file.display().to_string();
    let text =
        std::fs::read_to_string(&args.file).with_context(|| format!("cannot read {path}"))?;
    let waypoints = Program::parse(&text)
        .map_err(|e| anyhow!("{path}: {e}"))?
        .points;
    let modes = waypoints.iter().any(|w| w.mode.is_some());
    tokio::pin!(shutdown);
    let Some(mut motion) = MotionSwitch::engage(node, &args.delivery, modes, &mut shutdown).await?
    else {
        return Ok(()); // Ctrl-C while compute_ik's parameters were awaited
    };
    let mut d = Delivery::new(node, &args.delivery)?;
    let node = &*node;
    let work = async {
        d.connect(node).await?;
        for (i, w) in waypoints.iter().enumerate() {
            // move, arrive, then set the claw there: the order `record` writes rows in
            let at = || format!("waypoint {}", i + 1);
            check(arm, w.xyz).with_context(at)?;
            if let Some(m) = motion.as_mut() {
                m.set(w.mode).await.with_context(at)?;
            }
            d.send(w.xyz).await.with_context(at)?;
            d.arrival(arm, w.xyz).await.with_context(at)?;
            if let Some(g) = w.gripper {
                d.out.gripper_target(g);
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
        d.delivered().await;
        Ok(())
    };
    let result = until_shutdown(work, &mut shutdown).await;
    MotionSwitch::restore(motion).await;
    result
}

/// Run `work` until it ends or `shutdown` (Ctrl-C: exit 0).
pub async fn until_shutdown(
    work: impl Future<Output = anyhow::Result<()>>,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    tokio::select! {
        r = work => r,
        _ = shutdown => Ok(()),
    }
}

/// The local reachability check (the closed form compute_ik uses for the EezyBot).
fn check(arm: &Arm, xyz: [f64; 3]) -> Result<(), NotDelivered> {
    arm.solve_position(&xyz.into(), 0.0)
        .map(|_| ())
        .map_err(|e| NotDelivered::Unreachable {
            xyz,
            reason: e.to_string(),
        })
}

/// The publishers and subscriptions of a delivery.
struct Delivery {
    out: RosOutputs,
    joint_states: Subscription<JointState>,
    diagnostics: Subscription<DiagnosticArray>,
    topic: String,
    timeout: Duration,
}

impl Delivery {
    fn new(node: &mut RosNode, args: &DeliveryArgs) -> anyhow::Result<Delivery> {
        Ok(Delivery {
            out: RosOutputs::new(node)?,
            joint_states: node.subscribe_to(&topics::JOINT_STATES)?,
            diagnostics: node.subscribe_to(&topics::DIAGNOSTICS)?,
            topic: node.resolve(&topics::XYZ_TARGET)?,
            timeout: args.timeout,
        })
    }

    /// Wait until the subscribers have every target published (the last gripper
    /// target of a `play` with no dwell was lost when the process exited at once), at
    /// most [`DELIVERED_WAIT`].
    async fn delivered(&self) {
        if !self.out.delivered(DELIVERED_WAIT).await {
            log::warn!(
                "a subscriber did not acknowledge the last targets within {DELIVERED_WAIT:?}: it may have missed them"
            );
        }
    }

    /// Wait until someone subscribes `xyz_target` and a first `joint_states` message has
    /// come (compute_ik sends the pose to each new subscriber over its next polls).
    ///
    /// A matched publisher is not enough: with SROS2 our reader counts compute_ik's writer
    /// before we hold its crypto tokens, and what it sends meanwhile waits in its history
    /// (depth 10) for repair, so the first step of the answer, which alone carries the
    /// target's stamp, can be pushed out by the steps after it. A message we could read
    /// shows the whole path is up: its writer has our reader and we decrypt what it sends.
    async fn connect(&self, node: &RosNode) -> Result<(), NotDelivered> {
        let deadline = Instant::now() + self.timeout;
        while self.out.xyz.get_subscription_count(node.node()) == 0 {
            if Instant::now() > deadline {
                return Err(NotDelivered::NobodyListens {
                    topic: self.topic.clone(),
                });
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        let js = self.joint_states.async_stream();
        tokio::pin!(js);
        // any message will do, even one we could not decode: it came through
        tokio::select! {
            _ = tokio::time::sleep_until(deadline) => Err(NotDelivered::NoJointStates {
                timeout_s: self.timeout.as_secs_f64(),
                publishers: self.joint_states.get_publisher_count(node.node()),
            }),
            Some(_) = js.next() => Ok(()),
        }
    }

    /// Publish `xyz` stamped now; wait until `joint_states` carries the stamp (taken)
    /// or a `diagnostics` status reports its refusal (refused).
    async fn send(&mut self, xyz: [f64; 3]) -> Result<(), NotDelivered> {
        let stamp = Time::now();
        self.out.xyz_target(xyz, stamp);
        let deadline = Instant::now() + self.timeout;
        let js = self.joint_states.async_stream();
        let diags = self.diagnostics.async_stream();
        tokio::pin!(js, diags);
        let mut joint_states = 0;
        loop {
            tokio::select! {
                _ = tokio::time::sleep_until(deadline) => return Err(NotDelivered::NoAnswer {
                    timeout_s: self.timeout.as_secs_f64(),
                    joint_states,
                }),
                Some(Ok((m, _))) = js.next() => {
                    if m.header.stamp == stamp {
                        return Ok(());
                    }
                    joint_states += 1;
                }
                Some(Ok((d, _))) = diags.next() => {
                    let refused = feedback::decode(&d).into_iter().find_map(|f| {
                        let node = f.node_or_name().to_string();
                        f.refusal.filter(|r| r.is_for(stamp)).map(|r| (node, r.reason))
                    });
                    if let Some((node, reason)) = refused {
                        return Err(NotDelivered::Refused { node, xyz, reason });
                    }
                }
            }
        }
    }

    /// Wait until `joint_states` has the arm at `xyz` (compute_ik's planned motion ends
    /// exactly on the target's joints).
    async fn arrival(&self, arm: &Arm, xyz: [f64; 3]) -> anyhow::Result<()> {
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
        let deadline = Instant::now() + self.timeout;
        loop {
            tokio::select! {
                _ = tokio::time::sleep_until(deadline) => return Err(NotDelivered::DidNotArrive { xyz, timeout_s: self.timeout.as_secs_f64() }.into()),
                Some(Ok((m, _))) = js.next() => if at_goal(&m) { return Ok(()) },
            }
        }
    }
}

/// compute_ik's `motion` during a delivery: `line` with `--line`, each program point's
/// mode before its move, and put back as it was afterwards.
struct MotionSwitch {
    client: RemoteParameters,
    /// its value before we touched it
    original: ParameterValue,
    /// what we set it to last (or `original`)
    current: ParameterValue,
    /// for points without a mode: `line` with `--line`, else `original`
    default: ParameterValue,
    /// whether we tried to set it (a failed set may still have taken)
    touched: bool,
}

impl MotionSwitch {
    /// With `--line` or `modes` (the program names a mode for some point): connect to
    /// the `motion` of `--ik-node` and read it; the first `set` changes it. `Some(None)`:
    /// nothing to switch; `None`: `shutdown` came first (nothing was changed).
    async fn engage(
        node: &mut RosNode,
        args: &DeliveryArgs,
        modes: bool,
        shutdown: impl Future<Output = ()>,
    ) -> anyhow::Result<Option<Option<MotionSwitch>>> {
        if !args.line && !modes {
            return Ok(Some(None));
        }
        let client = RemoteParameters::new(node, &args.ik_node)?;
        let read = async {
            client
                .wait(node, args.timeout)
                .await
                .map_err(|e| anyhow!(e))?;
            client
                .get("motion")
                .await
                .map_err(|e| anyhow!(e))?
                .ok_or_else(|| {
                    anyhow!(
                        "{} has no `motion` parameter (too old a compute_ik?)",
                        client.node_name()
                    )
                })
        };
        let original = tokio::select! {
            r = read => r?,
            _ = shutdown => return Ok(None),
        };
        let default = if args.line {
            mode_value(MoveMode::Line)
        } else {
            original.clone()
        };
        Ok(Some(Some(MotionSwitch {
            client,
            current: original.clone(),
            original,
            default,
            touched: false,
        })))
    }

    /// Set `motion` for the next move: `mode`, or the default for none; nothing if it
    /// is that already.
    async fn set(&mut self, mode: Option<MoveMode>) -> anyhow::Result<()> {
        let want = mode.map_or_else(|| self.default.clone(), mode_value);
        if want == self.current {
            return Ok(());
        }
        self.touched = true;
        self.client.set("motion", want.clone()).await.map_err(|e| {
            anyhow!(
                "cannot set {}'s motion to {}: {e}",
                self.client.node_name(),
                shown(&want)
            )
        })?;
        log::info!("{} motion:={}", self.client.node_name(), shown(&want));
        self.current = want;
        Ok(())
    }

    /// Put `motion` back as it was (if we changed it).
    async fn restore(switch: Option<MotionSwitch>) {
        let Some(s) = switch else {
            return;
        };
        if !s.touched {
            return;
        }
        match s.client.set("motion", s.original.clone()).await {
            Ok(()) => log::info!(
                "{} motion back to {}",
                s.client.node_name(),
                shown(&s.original)
            ),
            Err(e) => log::error!(
                "could not put {}'s motion back to {}: {e}",
                s.client.node_name(),
                shown(&s.original)
            ),
        }
    }
}

/// A parameter value as written on the command line (`line`, not `String("line")`).
fn shown(value: &ParameterValue) -> String {
    match value {
        ParameterValue::String(s) => s.clone(),
        other => format!("{other:?}"),
    }
}

/// compute_ik's `motion` value for `mode`.
fn mode_value(mode: MoveMode) -> ParameterValue {
    ParameterValue::String(mode.as_str().into())
}
