//! `recorder replay`: an episode's `action` played back through the graph, as LeRobot's
//! `replay` plays one back on the robot.
//!
//! The arm's joints (`base_joint`, `shoulder_joint`, `elbow_joint`) go to compute_ik's
//! `arm_controller` as one FollowJointTrajectory goal, a point per frame at
//! `time_from_start` = lead-in + `timestamp` / speed; the claw (`gripper_joint`, not an
//! arm_controller joint) goes to `gripper_controller` as `gripper_target` openings
//! (`gripper_joint` / `gripper_open_rad`), each sent at its frame's time while the
//! trajectory runs, and compute_ik moves the claw beside the trajectory at its limits.
//!
//! compute_ik refuses a first point at 0 s away from where the arm is, and a trajectory
//! over the servos' velocity limits (it never slows one down). So the first frame comes
//! after a lead-in from where the arm is (compute_ik's commanded joints,
//! `joint_states`) at [`LEAD_IN_PACE`] of the limits, at least [`LEAD_IN_MIN_S`]; and the
//! points carry positions only (compute_ik joins them with straight segments, at the
//! recorded speeds times `speed`), each step no faster than [`PACE_MARGIN`] of the
//! limits (`--arm-config`'s `motion`, the shipped config/arm.yaml's by default): a
//! recording of a motion at the limits, sampled at its fps from commands that came at
//! compute_ik's own rate, has steps of a little more than a frame's motion (measured:
//! 1.1 times the base's limit), and a `--speed` above 1 asks for more; those steps
//! take the time the servos need, and the replay says how many and how much later it
//! ends.
//!
//! As with `ros2 action send_goal`, nothing is switched first: a goal takes the arm for
//! `arm_controller` (preempting teleop), and `gripper_target` the claw for
//! `gripper_controller`, unless the arbiter will not let them (a leader following, the
//! calibration wizard, the e-stop): the goal is then rejected, and the reason is
//! compute_ik's (its `diagnostics`' `last_trajectory`).

use eezybot_kinematics::ArmConfig;
use eezybot_msgs::builtin_interfaces::Duration as RosDuration;
use eezybot_msgs::control_msgs::{
    FollowJointTrajectoryFeedbackJazzy, FollowJointTrajectoryGoal, FollowJointTrajectoryResult,
};
use eezybot_msgs::diagnostic_msgs::DiagnosticArray;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Float64;
use eezybot_msgs::trajectory_msgs::{JointTrajectory, JointTrajectoryPoint};
use futures::StreamExt;
use lerobot_dataset::read::EpisodeRows;
use ros_plumbing::action::GoalEnd;
use ros_plumbing::action_client::ActionClient;
use ros_plumbing::{topics, RosNode, Subscription};
use std::path::PathBuf;
use std::time::Duration;

/// The claw's joint: not one of arm_controller's, it goes through `gripper_target`.
pub const GRIPPER_JOINT: &str = "gripper_joint";

/// The arm's joints, arm_controller's: an episode's action must name them.
pub const ARM_JOINTS: [&str; 3] = ["base_joint", "shoulder_joint", "elbow_joint"];

/// The shortest lead-in (s) from where the arm is to the episode's first frame.
pub const LEAD_IN_MIN_S: f64 = 0.5;

/// The lead-in's pace: this share of each servo's velocity limit, at most.
pub const LEAD_IN_PACE: f64 = 0.25;

/// A replayed step is no faster than this share of each servo's velocity limit
/// (compute_ik refuses a step over the limit itself).
pub const PACE_MARGIN: f64 = 0.95;

/// A claw opening change smaller than this (of 0 closed … 1 open) is not sent.
pub const CLAW_STEP: f64 = 0.002;

/// How long to wait for compute_ik's action server and first `joint_states`.
pub const WAIT: Duration = Duration::from_secs(20);

/// How long to wait for compute_ik's reason after a rejection.
pub const REASON_WAIT: Duration = Duration::from_millis(2500);

/// What `recorder replay` was asked.
#[derive(Clone, Debug, PartialEq)]
pub struct Request {
    /// The dataset folder.
    pub root: PathBuf,
    /// The episode's index.
    pub episode: u64,
    /// compute_ik's node name (its namespace is the action's).
    pub node: String,
    /// Playback speed (2 = twice as fast).
    pub speed: f64,
    /// The arm config with `gripper_open_rad` (empty: the shipped one).
    pub arm_config: String,
}

/// The replay of one episode: the trajectory goal and the claw's openings in time.
#[derive(Clone, Debug, PartialEq)]
pub struct Replay {
    /// arm_controller's goal: the arm joints, a point per frame.
    pub goal: FollowJointTrajectoryGoal,
    /// `(s after the goal is accepted, opening)`: the claw's targets, in time order.
    pub claw: Vec<(f64, f64)>,
    /// From where the arm is to the first frame (s).
    pub lead_in_s: f64,
    /// The whole goal (s): lead-in and the episode at `speed`.
    pub duration_s: f64,
    /// Each frame's time (s after acceptance), for progress.
    pub frame_times: Vec<f64>,
    /// The steps between frames that were slowed to the servos' limits.
    pub slowed: usize,
    /// And the time they added (s).
    pub added_s: f64,
}

/// The velocity limits of the servos' axes, as compute_ik plans them: the base joint,
/// the shoulder joint, the forearm's elevation (shoulder + elbow: the elbow servo sets
/// it), rad/s; the claw's opening, per second.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits(pub [f64; 4]);

impl Limits {
    /// The limits of an arm config's `motion` through its servo calibration.
    pub fn of(config: &ArmConfig) -> Limits {
        Limits(config.motion.input_limits(&config.servos).map(|(v, _)| v))
    }

    /// The shortest time (s) from axes `a` to axes `b` at `share` of the limits.
    fn time(&self, a: &[f64; 4], b: &[f64; 4], share: f64) -> f64 {
        (0..4)
            .map(|i| (b[i] - a[i]).abs() / (self.0[i] * share))
            .filter(|t| t.is_finite())
            .fold(0.0, f64::max)
    }
}

/// The servos' axes of joints (base, shoulder, elbow) and a claw opening.
fn axes(base: f64, shoulder: f64, elbow: f64, opening: f64) -> [f64; 4] {
    [base, shoulder, shoulder + elbow, opening]
}

/// Plan the replay of `episode` (its `action` rows) from `here` (compute_ik's
/// `joint_states`) at `speed`, within the servos' `limits`, the claw's joint angle
/// turned into an opening with `gripper_open_rad`.
pub fn plan(
    episode: &EpisodeRows,
    here: &JointState,
    speed: f64,
    limits: &Limits,
    gripper_open_rad: f64,
) -> Result<Replay, String> {
    if !(speed.is_finite() && speed > 0.0) {
        return Err(format!("speed {speed} is not a positive number"));
    }
    if !(gripper_open_rad.is_finite() && gripper_open_rad > 0.0) {
        return Err(format!(
            "gripper_open_rad {gripper_open_rad} is not positive"
        ));
    }
    if episode.rows.is_empty() {
        return Err(format!("episode {} has no frames", episode.episode_index));
    }
    let names = &episode.names;
    let of = |n: &str| names.iter().position(|x| x == n);
    let gripper = of(GRIPPER_JOINT);
    let arm: Vec<usize> = ARM_JOINTS.iter().filter_map(|n| of(n)).collect();
    if arm.len() != ARM_JOINTS.len() || names.len() != arm.len() + usize::from(gripper.is_some()) {
        return Err(format!(
            "the episode's action names {} where this arm's are {} and {GRIPPER_JOINT}",
            names.join(", "),
            ARM_JOINTS.join(", ")
        ));
    }
    let position = |n: &str| -> Result<f64, String> {
        let k = here.name.iter().position(|x| x == n).ok_or_else(|| {
            format!(
                "joint_states has no {n} (it has {}): is it this arm's compute_ik?",
                here.name.join(", ")
            )
        })?;
        here.position
            .get(k)
            .copied()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("joint_states gives {n} no position"))
    };
    let opening = |rad: f64| (rad / gripper_open_rad).clamp(0.0, 1.0);
    let here_axes = {
        let claw = match gripper {
            Some(_) => opening(position(GRIPPER_JOINT)?),
            None => 0.0,
        };
        axes(
            position(ARM_JOINTS[0])?,
            position(ARM_JOINTS[1])?,
            position(ARM_JOINTS[2])?,
            claw,
        )
    };
    let frame_axes: Vec<[f64; 4]> = episode
        .rows
        .iter()
        .map(|r| {
            let v = |i: usize| f64::from(r[i]);
            axes(
                v(arm[0]),
                v(arm[1]),
                v(arm[2]),
                gripper.map_or(0.0, |g| opening(v(g))),
            )
        })
        .collect();
    let lead_in_s = limits
        .time(&here_axes, &frame_axes[0], LEAD_IN_PACE)
        .max(LEAD_IN_MIN_S);
    let mut frame_times = vec![lead_in_s];
    let (mut slowed, mut added_s) = (0, 0.0);
    for k in 1..episode.rows.len() {
        let dt = f64::from(episode.timestamps[k] - episode.timestamps[k - 1]) / speed;
        if dt.is_nan() || dt <= 0.0 {
            return Err(format!(
                "frame {k} has timestamp {} after frame {}'s {}: timestamps must increase",
                episode.timestamps[k],
                k - 1,
                episode.timestamps[k - 1]
            ));
        }
        let need = limits.time(&frame_axes[k - 1], &frame_axes[k], PACE_MARGIN);
        if need > dt {
            slowed += 1;
            added_s += need - dt;
        }
        frame_times.push(frame_times[k - 1] + dt.max(need));
    }
    let points = episode
        .rows
        .iter()
        .zip(&frame_times)
        .map(|(row, &t)| JointTrajectoryPoint {
            positions: arm.iter().map(|&i| f64::from(row[i])).collect(),
            time_from_start: RosDuration::from_secs_f64(t),
            ..Default::default()
        })
        .collect();
    let goal = FollowJointTrajectoryGoal {
        trajectory: JointTrajectory {
            joint_names: ARM_JOINTS.map(String::from).to_vec(),
            points,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut claw: Vec<(f64, f64)> = Vec::new();
    if gripper.is_some() {
        for (k, (a, &t)) in frame_axes.iter().zip(&frame_times).enumerate() {
            // the first frame's opening at once: the claw gets there in the lead-in
            let at = if k == 0 { 0.0 } else { t };
            match claw.last() {
                Some(&(_, last)) if (a[3] - last).abs() < CLAW_STEP => {}
                _ => claw.push((at, a[3])),
            }
        }
        // the last frame's opening exactly
        let last = frame_axes[frame_axes.len() - 1][3];
        if claw.last().is_some_and(|&(_, o)| o != last) {
            claw.push((frame_times[frame_times.len() - 1], last));
        }
    }
    Ok(Replay {
        goal,
        claw,
        lead_in_s,
        duration_s: frame_times[frame_times.len() - 1],
        frame_times,
        slowed,
        added_s,
    })
}

/// The name of a FollowJointTrajectory error code.
pub fn code_name(code: i32) -> &'static str {
    match code {
        FollowJointTrajectoryResult::SUCCESSFUL => "SUCCESSFUL",
        FollowJointTrajectoryResult::INVALID_GOAL => "INVALID_GOAL",
        FollowJointTrajectoryResult::INVALID_JOINTS => "INVALID_JOINTS",
        FollowJointTrajectoryResult::OLD_HEADER_TIMESTAMP => "OLD_HEADER_TIMESTAMP",
        FollowJointTrajectoryResult::PATH_TOLERANCE_VIOLATED => "PATH_TOLERANCE_VIOLATED",
        FollowJointTrajectoryResult::GOAL_TOLERANCE_VIOLATED => "GOAL_TOLERANCE_VIOLATED",
        _ => "unknown",
    }
}

/// How many frames are due by `t` (s after acceptance).
fn frames_due(frame_times: &[f64], t: f64) -> usize {
    frame_times.partition_point(|&f| f <= t)
}

/// compute_ik's `last_trajectory` in a `diagnostics` sample, if it is there.
fn last_trajectory(msg: &DiagnosticArray, node: &str) -> Option<String> {
    let prefix = format!("{node}:");
    msg.status
        .iter()
        .filter(|s| s.name.starts_with(&prefix))
        .flat_map(|s| s.values.iter())
        .find(|kv| kv.key == "last_trajectory")
        .map(|kv| kv.value.clone())
}

type TrajectoryClient = ActionClient<
    FollowJointTrajectoryGoal,
    FollowJointTrajectoryResult,
    FollowJointTrajectoryFeedbackJazzy,
>;

/// Play the episode back; `Ok` when the goal succeeded, else why not (exit status
/// [`crate::cli::EXIT_REFUSED`]).
pub async fn run(request: Request, ros_args: Vec<String>) -> anyhow::Result<()> {
    // Ctrl-C from here on: before the goal, nothing was sent; after, it is canceled
    let mut interrupted = Box::pin(ros_plumbing::shutdown_signal());
    let episode = lerobot_dataset::read::read_actions(&request.root, request.episode)?;
    let arm = eezybot_kinematics::ArmConfig::load_or_shipped(&request.arm_config)
        .map_err(|e| anyhow::anyhow!("arm config: {e}"))?;
    let domain = std::env::var("ROS_DOMAIN_ID").ok();
    let spec = ros_plumbing::NodeSpec {
        name: "recorder_replay",
        description: "plays a recorded episode back through compute_ik",
        usage: "",
        params: vec![],
    };
    let mut ros = RosNode::start_with(&spec, ros_args, domain.as_deref())?;
    let result = async {
        let client: TrajectoryClient =
            ActionClient::new(&mut ros, &request.node, &topics::FOLLOW_JOINT_TRAJECTORY)?;
        let joint_states = ros.subscribe_to(&topics::JOINT_STATES)?;
        let diagnostics = ros.subscribe_to(&topics::DIAGNOSTICS)?;
        let claw = ros.publish_on(&topics::GRIPPER_TARGET)?;
        let node_base = request
            .node
            .rsplit('/')
            .next()
            .unwrap_or(&request.node)
            .to_string();
        tokio::select! {
            r = client.wait(&ros, WAIT) => r.map_err(anyhow::Error::msg)?,
            s = &mut interrupted => anyhow::bail!("{s}: stopped before anything was sent"),
        }
        let here = tokio::select! {
            h = first_joint_states(&joint_states) => h.map_err(anyhow::Error::msg)?,
            s = &mut interrupted => anyhow::bail!("{s}: stopped before anything was sent"),
        };
        let replay = plan(
            &episode,
            &here,
            request.speed,
            &Limits::of(&arm),
            arm.geometry.gripper_open_rad,
        )
        .map_err(anyhow::Error::msg)?;
        println!(
            "replaying episode {} of {} ({} frames, {:.1} s at speed {}; {:.1} s to reach its first frame) through {}",
            episode.episode_index,
            request.root.display(),
            episode.rows.len(),
            replay.duration_s - replay.lead_in_s,
            request.speed,
            replay.lead_in_s,
            client.name()
        );
        if replay.slowed > 0 {
            println!(
                "  {} of its {} steps are faster than the servos allow: slowed to their limits, {:.3} s later in all",
                replay.slowed,
                episode.rows.len() - 1,
                replay.added_s
            );
        }
        // a refusal already in compute_ik's diagnostics is not this goal's
        let mut before = None;
        while let Ok(Some((m, _))) = diagnostics.take() {
            if let Some(t) = last_trajectory(&m, &node_base) {
                before = Some(t);
            }
        }
        let id = tokio::select! {
            r = client.send_goal(replay.goal.clone(), WAIT) => r.map_err(anyhow::Error::msg)?,
            s = &mut interrupted => anyhow::bail!("{s}: stopped while the goal was being sent"),
        };
        let Some(id) = id else {
            let why = refusal(&diagnostics, &node_base, before).await;
            let hint = if why.contains("limit of") {
                " (the replay is paced by --arm-config's motion limits: give it compute_ik's arm_config)"
            } else {
                ""
            };
            anyhow::bail!("{} rejected the goal: {why}{hint}", client.name());
        };
        let accepted = tokio::time::Instant::now();
        let mut claw_next = 0;
        let mut reported = 0usize;
        let mut result = Box::pin(client.result(id));
        let mut tick = tokio::time::interval(Duration::from_millis(10));
        let mut last_print = accepted;
        let outcome = loop {
            tokio::select! {
                r = &mut result => break r.map_err(anyhow::Error::msg)?,
                s = &mut interrupted => {
                    println!("{s}: canceling the replay");
                    let agreed = client.cancel(id, WAIT).await.map_err(anyhow::Error::msg)?;
                    if !agreed {
                        println!("{} did not cancel the goal (it had ended?)", client.name());
                    }
                    let r = tokio::time::timeout(WAIT, &mut result).await
                        .map_err(|_| anyhow::anyhow!("no result after the cancel"))?
                        .map_err(anyhow::Error::msg)?;
                    break r;
                }
                _ = tick.tick() => {
                    let t = accepted.elapsed().as_secs_f64();
                    while claw_next < replay.claw.len() && replay.claw[claw_next].0 <= t {
                        claw.publish(Float64 { data: replay.claw[claw_next].1 });
                        claw_next += 1;
                    }
                    let due = frames_due(&replay.frame_times, t);
                    if last_print.elapsed() >= Duration::from_secs(1) && due != reported {
                        println!(
                            "  {:5.1} / {:.1} s   frame {due} / {}",
                            t,
                            replay.duration_s,
                            replay.frame_times.len()
                        );
                        reported = due;
                        last_print = tokio::time::Instant::now();
                    }
                }
            }
        };
        // openings not yet sent (the goal ended early): the claw goes to the last one
        if claw_next < replay.claw.len() && outcome.0 == GoalEnd::Succeeded {
            if let Some(&(_, o)) = replay.claw.last() {
                claw.publish(Float64 { data: o });
            }
        }
        let (end, r) = outcome;
        match end {
            GoalEnd::Succeeded => {
                println!(
                    "done: episode {} replayed ({} frames in {:.1} s)",
                    episode.episode_index,
                    episode.rows.len(),
                    accepted.elapsed().as_secs_f64()
                );
                Ok(())
            }
            GoalEnd::Aborted => anyhow::bail!(
                "the replay was aborted ({}): {}",
                code_name(r.error_code),
                r.error_string
            ),
            GoalEnd::Canceled => anyhow::bail!("the replay was canceled: {}", r.error_string),
        }
    }
    .await;
    ros.shutdown().await;
    result
}

/// The first `joint_states` sample (compute_ik's commanded joints: where a trajectory
/// starts from).
async fn first_joint_states(sub: &Subscription<JointState>) -> Result<JointState, String> {
    let mut stream = Box::pin(sub.async_stream());
    let next = tokio::time::timeout(WAIT, async {
        loop {
            match stream.next().await {
                Some(Ok((m, _))) if !m.name.is_empty() => return Some(m),
                Some(_) => continue,
                None => return None,
            }
        }
    })
    .await;
    match next {
        Ok(Some(m)) => Ok(m),
        _ => Err(format!(
            "no joint_states within {:.0} s: is compute_ik running in this ROS domain?",
            WAIT.as_secs_f64()
        )),
    }
}

/// Why compute_ik rejected the goal: the refusal in its diagnostics' `last_trajectory`
/// (another than `before`, unless no other comes within [`REASON_WAIT`]).
async fn refusal(
    diagnostics: &Subscription<DiagnosticArray>,
    node: &str,
    before: Option<String>,
) -> String {
    let mut stream = Box::pin(diagnostics.async_stream());
    let mut same = None;
    let _ = tokio::time::timeout(REASON_WAIT, async {
        while let Some(r) = stream.next().await {
            let Ok((m, _)) = r else { continue };
            match last_trajectory(&m, node) {
                Some(t) if t.contains("follow_joint_trajectory goal refused") => {
                    if Some(&t) != before.as_ref() {
                        same = Some(t);
                        return;
                    }
                    same = Some(t);
                }
                _ => {}
            }
        }
    })
    .await;
    same.map(|t| {
        t.trim_start_matches("follow_joint_trajectory goal ")
            .to_string()
    })
    .unwrap_or_else(|| format!("{node} gave no reason in its diagnostics"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const J: [&str; 4] = [
        "base_joint",
        "shoulder_joint",
        "elbow_joint",
        "gripper_joint",
    ];

    fn episode(rows: Vec<[f32; 4]>, fps: u32) -> EpisodeRows {
        EpisodeRows {
            episode_index: 3,
            fps,
            total_episodes: 4,
            feature: "action".into(),
            names: J.iter().map(|s| s.to_string()).collect(),
            timestamps: (0..rows.len())
                .map(|k| (k as f64 / f64::from(fps)) as f32)
                .collect(),
            rows: rows.into_iter().map(|r| r.to_vec()).collect(),
        }
    }

    fn here(p: [f64; 4]) -> JointState {
        JointState {
            // compute_ik's joint_states: the actuated joints and the passive ones
            name: [
                "base_joint",
                "shoulder_joint",
                "elbow_joint",
                "gripper_joint",
                "link_a",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect(),
            position: vec![p[0], p[1], p[2], p[3], 0.7],
            ..Default::default()
        }
    }

    /// Limits far above every step of these tests but the ones meant to pass them.
    const FAST: Limits = Limits([10.0, 10.0, 10.0, 10.0]);

    #[test]
    fn a_point_per_frame_after_a_lead_in_and_the_claw_beside() {
        let rows = vec![
            [0.0, 1.1, -1.2, 0.3],
            [0.05, 1.1, -1.2, 0.3],
            [0.1, 1.12, -1.2, 0.15],
            [0.1, 1.14, -1.2, 0.0],
        ];
        let ep = episode(rows.clone(), 10);
        let r = plan(&ep, &here([0.0, 1.1, -1.2, 0.3]), 1.0, &FAST, 0.6).unwrap();
        // at the first frame already: the shortest lead-in
        assert_eq!(r.lead_in_s, LEAD_IN_MIN_S);
        let t = &r.goal.trajectory;
        assert_eq!(t.joint_names, ARM_JOINTS);
        assert_eq!(t.points.len(), 4);
        for (k, p) in t.points.iter().enumerate() {
            let want: Vec<f64> = rows[k][..3].iter().map(|&v| f64::from(v)).collect();
            assert_eq!(p.positions, want);
            assert!(p.velocities.is_empty());
            let at = p.time_from_start.as_secs_f64();
            assert!((at - (0.5 + k as f64 * 0.1)).abs() < 1e-6, "{at}");
        }
        assert!((r.duration_s - 0.8).abs() < 1e-6);
        assert_eq!((r.slowed, r.added_s), (0, 0.0));
        // the claw: its first opening at once, each change at its frame
        assert_eq!(r.claw.len(), 3);
        assert_eq!(r.claw[0].0, 0.0);
        assert!((r.claw[0].1 - 0.5).abs() < 1e-6);
        assert!((r.claw[1].0 - 0.7).abs() < 1e-6 && (r.claw[1].1 - 0.25).abs() < 1e-6);
        assert!((r.claw[2].0 - 0.8).abs() < 1e-6 && r.claw[2].1 == 0.0);
        // the action's columns in another order: the same replay
        let mut shuffled = ep.clone();
        shuffled.names = [
            "gripper_joint",
            "elbow_joint",
            "base_joint",
            "shoulder_joint",
        ]
        .map(String::from)
        .to_vec();
        shuffled.rows = rows.iter().map(|r| vec![r[3], r[2], r[0], r[1]]).collect();
        let again = plan(&shuffled, &here([0.0, 1.1, -1.2, 0.3]), 1.0, &FAST, 0.6).unwrap();
        assert_eq!(again, r);
    }

    #[test]
    fn speed_scales_the_times_and_a_far_start_lengthens_the_lead_in() {
        let rows = vec![
            [0.5, 1.0, -1.0, 0.0],
            [0.5, 1.02, -1.02, 0.0],
            [0.5, 1.04, -1.04, 0.0],
        ];
        let limits = Limits([2.0, 5.0, 5.0, 4.0]);
        let r = plan(
            &episode(rows, 30),
            &here([-0.5, 1.0, -1.0, 0.0]),
            2.0,
            &limits,
            0.6,
        )
        .unwrap();
        // the base 1 rad away at a quarter of its 2 rad/s
        assert!((r.lead_in_s - 1.0 / (2.0 * LEAD_IN_PACE)).abs() < 1e-9);
        let times: Vec<f64> = r
            .goal
            .trajectory
            .points
            .iter()
            .map(|p| p.time_from_start.as_secs_f64())
            .collect();
        assert!((times[1] - times[0] - 1.0 / 60.0).abs() < 1e-6, "{times:?}");
        assert!((times[2] - times[0] - 2.0 / 60.0).abs() < 1e-6, "{times:?}");
        assert_eq!(r.slowed, 0);
        // the claw never moves: one target, at once
        assert_eq!(r.claw, vec![(0.0, 0.0)]);
        assert_eq!(frames_due(&r.frame_times, 0.0), 0);
        assert_eq!(frames_due(&r.frame_times, r.duration_s), 3);
    }

    #[test]
    fn steps_over_the_servos_limits_are_slowed_to_them() {
        // 0.1 rad of shoulder in a frame of 1/30 s is 3 rad/s: the shoulder's own
        // axis allows it, but the forearm's elevation (shoulder + elbow) moves 0.2 rad
        let rows = vec![
            [0.0, 1.0, -1.0, 0.0],
            [0.0, 1.1, -0.9, 0.0],
            [0.0, 1.1, -0.9, 0.0],
        ];
        let limits = Limits([5.0, 5.0, 4.0, 4.0]);
        let here = here([0.0, 1.0, -1.0, 0.0]);
        let r = plan(&episode(rows, 30), &here, 1.0, &limits, 0.6).unwrap();
        let step = r.frame_times[1] - r.frame_times[0];
        assert!((step - 0.2 / (4.0 * PACE_MARGIN)).abs() < 1e-6, "{step}");
        assert!((r.frame_times[2] - r.frame_times[1] - 1.0 / 30.0).abs() < 1e-6);
        assert_eq!(r.slowed, 1);
        assert!((r.added_s - (step - 1.0 / 30.0)).abs() < 1e-6);
        // the shipped arm: the base joint at half its servo's 300 °/s
        let shipped = Limits::of(&ArmConfig::shipped().unwrap());
        assert!(
            (shipped.0[0] - 150f64.to_radians()).abs() < 1e-9,
            "{shipped:?}"
        );
        assert!((shipped.0[3] - 500.0 / 120.0).abs() < 1e-9, "{shipped:?}");
    }

    #[test]
    fn episodes_that_cannot_be_replayed_say_why() {
        let here = here([0.0, 1.0, -1.0, 0.0]);
        let ep = episode(vec![[0.0, 1.0, -1.0, 0.0]], 30);
        assert!(plan(&ep, &here, 0.0, &FAST, 0.6)
            .unwrap_err()
            .contains("speed 0"));
        let mut other = ep.clone();
        other.names[0] = "wrist_joint".into();
        let e = plan(&other, &here, 1.0, &FAST, 0.6).unwrap_err();
        assert!(
            e.contains("action names wrist_joint, shoulder_joint"),
            "{e}"
        );
        let mut js = here.clone();
        js.name[1] = "other".into();
        let e = plan(&ep, &js, 1.0, &FAST, 0.6).unwrap_err();
        assert!(e.contains("joint_states has no shoulder_joint"), "{e}");
        let mut empty = ep.clone();
        empty.rows.clear();
        empty.timestamps.clear();
        assert!(plan(&empty, &here, 1.0, &FAST, 0.6)
            .unwrap_err()
            .contains("no frames"));
        let mut stuck = episode(vec![[0.0, 1.0, -1.0, 0.0]; 2], 30);
        stuck.timestamps[1] = 0.0;
        let e = plan(&stuck, &here, 1.0, &FAST, 0.6).unwrap_err();
        assert!(e.contains("timestamps must increase"), "{e}");
        // without the claw: the arm alone
        let mut arm_only = ep.clone();
        arm_only.names.pop();
        arm_only.rows = vec![vec![0.0, 1.0, -1.0]];
        let r = plan(&arm_only, &here, 1.0, &FAST, 0.6).unwrap();
        assert!(r.claw.is_empty() && r.goal.trajectory.points.len() == 1);
    }

    #[test]
    fn compute_ik_refusals_are_found_in_its_diagnostics() {
        use eezybot_msgs::diagnostic_msgs::{DiagnosticStatus, KeyValue};
        let msg = DiagnosticArray {
            status: vec![
                DiagnosticStatus {
                    name: "serial_node: link".into(),
                    values: vec![KeyValue {
                        key: "last_trajectory".into(),
                        value: "no".into(),
                    }],
                    ..Default::default()
                },
                DiagnosticStatus {
                    name: "compute_ik: inverse kinematics".into(),
                    values: vec![KeyValue {
                        key: "last_trajectory".into(),
                        value: "follow_joint_trajectory goal refused (INVALID_GOAL): e-stop".into(),
                    }],
                    ..Default::default()
                },
            ],
            ..Default::default()
        };
        assert_eq!(
            last_trajectory(&msg, "compute_ik").as_deref(),
            Some("follow_joint_trajectory goal refused (INVALID_GOAL): e-stop")
        );
        assert_eq!(last_trajectory(&msg, "compute"), None);
    }
}
