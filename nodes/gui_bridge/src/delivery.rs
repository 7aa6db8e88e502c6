//! `once` and `play`: deliver targets to compute_ik and wait for its answer, through its
//! public interfaces only. A target is **taken** when `joint_states` carries its stamp
//! (the first step of the motion it starts carries the target's `header.stamp`), and
//! **refused** when a `diagnostics` status reports a refusal of that stamp (read by
//! [`feedback`]); it **arrived** when `joint_states` has the arm at its joints.
//!
//! A line move (`--line`, a program point of mode `line`: [`ProgramPoint::line`]) goes
//! on `xyz_line_target`, any other on `xyz_target`: the move's kind travels with each
//! target, and compute_ik's parameters are left alone.

use crate::cli::{DeliveryArgs, OnceArgs, PlayArgs};
use crate::program::{MoveMode, Program, ProgramPoint};
use crate::ros_outputs::RosOutputs;
use crate::teleop::xyz_topic;
use crate::Outputs;
use anyhow::{anyhow, Context as _};
use eezybot_kinematics::Arm;
use eezybot_msgs::diagnostic_msgs::DiagnosticArray;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::Time;
use futures::StreamExt;
use ros_plumbing::feedback;
use ros_plumbing::Subscription;
use ros_plumbing::{topics, RosNode};
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
    #[error("{node} refused {xyz:?}{}: {reason}", on_topic(.topic))]
    Refused {
        /// the node that refused it, as it names itself
        node: String,
        /// the target
        xyz: [f64; 3],
        /// the topic it says the target came on (`xyz_line_target`); empty if not said
        topic: String,
        /// its `last_rejection`, or its status message
        reason: String,
    },
    /// Nobody subscribes the target topic (`xyz_target` or `xyz_line_target`).
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

/// ` on TOPIC`, or nothing for a topic not said.
fn on_topic(topic: &str) -> String {
    if topic.is_empty() {
        String::new()
    } else {
        format!(" on {topic}")
    }
}

/// How long a command-line delivery waits at its end for its subscribers to acknowledge
/// the last targets (a subscriber that died without leaving keeps it waiting this long).
pub const DELIVERED_WAIT: Duration = Duration::from_secs(5);

/// `once X Y Z [--gripper G]`: deliver one target (with `--line`, on `xyz_line_target`,
/// and wait until the arm is there), then set the claw.
pub async fn once(
    node: &mut RosNode,
    arm: &Arm,
    args: OnceArgs,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let xyz = args.xyz();
    check(arm, xyz)?;
    let line = ProgramPoint::at(xyz).line(base_mode(&args.delivery));
    let mut d = Delivery::new(node, &args.delivery)?;
    let node = &*node;
    let work = async {
        d.connect(node, &[line]).await?;
        d.send(xyz, line).await?;
        if line {
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
    until_shutdown(work, shutdown).await
}

/// `play FILE`: each point of the program in turn: move (on `xyz_line_target` if the
/// point's mode is `line`, or it names none and `--line` is given; else on
/// `xyz_target`), arrive, set the claw, dwell; the first refusal stops with its
/// waypoint's number.
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
    let base = base_mode(&args.delivery);
    let lines: Vec<bool> = waypoints.iter().map(|w| w.line(base)).collect();
    let mut d = Delivery::new(node, &args.delivery)?;
    let node = &*node;
    let work = async {
        d.connect(node, &lines).await?;
        for (i, (w, &line)) in waypoints.iter().zip(&lines).enumerate() {
            // move, arrive, then set the claw there: the order `record` writes rows in
            let at = || format!("waypoint {}", i + 1);
            check(arm, w.xyz).with_context(at)?;
            d.send(w.xyz, line).await.with_context(at)?;
            d.arrival(arm, w.xyz).await.with_context(at)?;
            if let Some(g) = w.gripper {
                d.out.gripper_target(g);
            }
            println!(
                "waypoint {}/{}: {:?}{} gripper {:?}, dwell {:.2} s",
                i + 1,
                waypoints.len(),
                w.xyz,
                if line { " (line)" } else { "" },
                w.gripper,
                w.dwell_s
            );
            tokio::time::sleep(Duration::from_secs_f64(w.dwell_s)).await;
        }
        d.delivered().await;
        Ok(())
    };
    until_shutdown(work, shutdown).await
}

/// How the points without a mode are moved to: `line` with `--line`.
fn base_mode(args: &DeliveryArgs) -> Option<MoveMode> {
    args.line.then_some(MoveMode::Line)
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

/// Whether `refusal` is of our target stamped `stamp`, sent on `xyz_line_target` with
/// `line` (else on `xyz_target`): its stamp, and its topic when it says one.
fn is_ours(refusal: &feedback::Refusal, stamp: Time, line: bool) -> bool {
    refusal.is_for(stamp) && (refusal.topic.is_empty() || refusal.topic == xyz_topic(line).name)
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
    /// the resolved names of `xyz_target` and `xyz_line_target`
    topics: [String; 2],
    timeout: Duration,
}

impl Delivery {
    fn new(node: &mut RosNode, args: &DeliveryArgs) -> anyhow::Result<Delivery> {
        Ok(Delivery {
            out: RosOutputs::new(node)?,
            joint_states: node.subscribe_to(&topics::JOINT_STATES)?,
            diagnostics: node.subscribe_to(&topics::DIAGNOSTICS)?,
            topics: [
                node.resolve(xyz_topic(false))?,
                node.resolve(xyz_topic(true))?,
            ],
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

    /// Wait until someone subscribes each target topic the targets go on (`lines`: each
    /// target's kind, [`xyz_topic`]) and a first `joint_states` message has come
    /// (compute_ik sends the pose to each new subscriber over its next polls).
    ///
    /// A matched publisher is not enough: with SROS2 our reader counts compute_ik's writer
    /// before we hold its crypto tokens, and what it sends meanwhile waits in its history
    /// (depth 10) for repair, so the first step of the answer, which alone carries the
    /// target's stamp, can be pushed out by the steps after it. A message we could read
    /// shows the whole path is up: its writer has our reader and we decrypt what it sends.
    async fn connect(&self, node: &RosNode, lines: &[bool]) -> Result<(), NotDelivered> {
        let deadline = Instant::now() + self.timeout;
        for line in [false, true].into_iter().filter(|l| lines.contains(l)) {
            let publisher = self.out.xyz_publisher(line);
            while publisher.get_subscription_count(node.node()) == 0 {
                if Instant::now() > deadline {
                    return Err(NotDelivered::NobodyListens {
                        topic: self.topics[usize::from(line)].clone(),
                    });
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
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

    /// Publish `xyz` stamped now, on `xyz_line_target` with `line`, else on
    /// `xyz_target`; wait until `joint_states` carries the stamp (taken) or a
    /// `diagnostics` status reports the refusal of that stamp (refused: compute_ik's
    /// reason names the topic).
    async fn send(&mut self, xyz: [f64; 3], line: bool) -> Result<(), NotDelivered> {
        let stamp = Time::now();
        self.out.xyz_target(xyz, line, stamp);
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
                        f.refusal.filter(|r| is_ours(r, stamp, line)).map(|r| (node, r))
                    });
                    if let Some((node, r)) = refused {
                        let (topic, reason) = (r.topic, r.reason);
                        return Err(NotDelivered::Refused { node, xyz, topic, reason });
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

#[cfg(test)]
mod tests {
    use super::*;
    use ros_plumbing::feedback::{ReasonCode, Refusal};

    #[test]
    fn a_refusal_is_ours_by_its_stamp_and_the_topic_the_target_went_on() {
        let stamp = Time::new(7, 5);
        let on = |topic| {
            Refusal::new(
                stamp,
                ReasonCode::LineBlocked,
                "leaves the workspace",
                topic,
            )
        };
        assert!(is_ours(&on("xyz_line_target"), stamp, true));
        assert!(!is_ours(&on("xyz_line_target"), stamp, false));
        assert!(is_ours(&on("xyz_target"), stamp, false));
        assert!(!is_ours(&on("xyz_target"), stamp, true));
        assert!(is_ours(&on(""), stamp, true), "a topic not said");
        assert!(!is_ours(&on("xyz_line_target"), Time::new(7, 6), true));
        let e = NotDelivered::Refused {
            node: "compute_ik".into(),
            xyz: [0.08, -0.075, 0.15],
            topic: "xyz_line_target".into(),
            reason: "leaves the workspace".into(),
        };
        assert_eq!(
            e.to_string(),
            "compute_ik refused [0.08, -0.075, 0.15] on xyz_line_target: leaves the workspace"
        );
    }
}
