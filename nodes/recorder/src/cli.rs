//! The command line: without a command the node runs; with one, this process is a
//! client of a running recorder (its episode services and `task` parameter).

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use ros_plumbing::episodes::{EpisodeCall, EpisodeClient};
use ros_plumbing::RosNode;
use std::time::Duration;

/// Exit status of a command the recorder refused or did not answer (usage errors: 2).
pub const EXIT_REFUSED: u8 = 1;

/// How long a command waits for the recorder, and for its answer (a save writes the
/// episode out first).
pub const CALL_TIMEOUT: Duration = Duration::from_secs(30);

#[derive(Parser, Debug)]
#[command(
    name = "recorder",
    about = "Records LeRobot v3.0 datasets from the running graph (the node, without a command), or drives a running recorder"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

/// A command for a running recorder.
#[derive(Subcommand, Debug, Clone, PartialEq)]
pub enum Command {
    /// Begin an episode (of TASK, else the recorder's `task` parameter).
    StartEpisode {
        /// The episode's task (sets the recorder's `task` parameter first).
        #[arg(long)]
        task: Option<String>,
        /// The recorder's node name.
        #[arg(long, default_value = "recorder")]
        node: String,
    },
    /// End the episode and keep it.
    SaveEpisode {
        /// The recorder's node name.
        #[arg(long, default_value = "recorder")]
        node: String,
    },
    /// End the episode and throw it away.
    DiscardEpisode {
        /// The recorder's node name.
        #[arg(long, default_value = "recorder")]
        node: String,
    },
    /// Play a recorded episode's `action` back through compute_ik: the arm as one
    /// arm_controller/follow_joint_trajectory goal (a point per frame, after a lead-in
    /// from where the arm is), the claw as gripper_target openings at their frames'
    /// times. Exits 0 when the goal succeeded, 1 when it was rejected, aborted or
    /// canceled (Ctrl-C cancels it).
    Replay {
        /// The dataset folder (default: the recorder's, $XDG_DATA_HOME/eezybot/datasets/eezybot_mk2).
        #[arg(long)]
        root: Option<std::path::PathBuf>,
        /// The episode's index (0 is the first).
        #[arg(long)]
        episode: u64,
        /// compute_ik's node name (the action is in its namespace).
        #[arg(long, default_value = "compute_ik")]
        node: String,
        /// Playback speed: 2 is twice as fast (compute_ik refuses a replay its servos
        /// cannot follow, naming the joint and limit: try a lower speed).
        #[arg(long, default_value_t = 1.0, value_parser = speed)]
        speed: f64,
        /// The arm config whose geometry's gripper_open_rad turns gripper_joint (rad)
        /// into the claw's opening (default: the shipped config/arm.yaml).
        #[arg(long, default_value = "")]
        arm_config: String,
    },
}

fn speed(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 10.0 => Ok(v),
        _ => Err(format!(
            "{s} is not a speed between 0 and 10 (1 = as recorded)"
        )),
    }
}

/// Parse our arguments (without argv\[0\]; ROS arguments after `--ros-args` are left
/// for the node). `None`: run the node.
pub fn parse(argv: &[String]) -> Result<Option<Command>, clap::Error> {
    // anything but a command is the node's: its --help lists the parameters, and it
    // refuses a bad argument or ROS argument in one line
    let user = match ros_plumbing::args::parse(argv.iter().cloned()) {
        Ok((user, _)) if is_command(&user) => user,
        _ => return Ok(None),
    };
    let matches = Cli::command().try_get_matches_from(
        std::iter::once("recorder".to_string()).chain(user.iter().cloned()),
    )?;
    Ok(Cli::from_arg_matches(&matches)?.command)
}

fn is_command(user: &[String]) -> bool {
    user.first().is_some_and(|a| {
        ["start-episode", "save-episode", "discard-episode", "replay"].contains(&a.as_str())
    })
}

/// Run `command` against the recorder, printing its answer; an answer of "not done" is
/// an error (exit status 1 through the caller).
pub async fn run(command: Command, argv: Vec<String>) -> anyhow::Result<()> {
    let domain = std::env::var("ROS_DOMAIN_ID").ok();
    let spec = ros_plumbing::NodeSpec {
        name: "recorder_cli",
        description: "a command-line client of a recorder",
        usage: "",
        params: vec![],
    };
    // the node's arguments are the ROS ones only (the command's are ours)
    let ros_args: Vec<String> = match argv.iter().position(|a| a == "--ros-args") {
        Some(i) => argv[i..].to_vec(),
        None => vec![],
    };
    let (call, node, task) = match &command {
        Command::StartEpisode { task, node } => (EpisodeCall::Start, node, task.clone()),
        Command::SaveEpisode { node } => (EpisodeCall::Save, node, None),
        Command::DiscardEpisode { node } => (EpisodeCall::Discard, node, None),
        Command::Replay {
            root,
            episode,
            node,
            speed,
            arm_config,
        } => {
            let request = crate::replay::Request {
                root: root.clone().unwrap_or_else(crate::default_root),
                episode: *episode,
                node: node.clone(),
                speed: *speed,
                arm_config: arm_config.clone(),
            };
            return crate::replay::run(request, ros_args).await;
        }
    };
    let mut ros = RosNode::start_with(&spec, ros_args, domain.as_deref())?;
    let client = EpisodeClient::new(&mut ros, node)?;
    let result = async {
        client.wait(&ros, call, CALL_TIMEOUT).await?;
        if let Some(t) = task {
            client.set_task(&ros, &t, CALL_TIMEOUT).await?;
        }
        client.call(call, CALL_TIMEOUT).await
    }
    .await;
    ros.shutdown().await;
    let answer = result.map_err(anyhow::Error::msg)?;
    if answer.success {
        println!("{}", answer.message);
        Ok(())
    } else {
        anyhow::bail!("{}", answer.message)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(a: &[&str]) -> Vec<String> {
        a.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn no_command_runs_the_node_and_commands_parse() {
        assert_eq!(parse(&args(&[])).unwrap(), None);
        assert_eq!(
            parse(&args(&["--ros-args", "-p", "fps:=15"])).unwrap(),
            None
        );
        assert_eq!(parse(&args(&["--help"])).unwrap(), None);
        assert_eq!(
            parse(&args(&[
                "start-episode",
                "--task",
                "pick the cube",
                "--ros-args",
                "-r",
                "__ns:=/a"
            ]))
            .unwrap(),
            Some(Command::StartEpisode {
                task: Some("pick the cube".into()),
                node: "recorder".into()
            })
        );
        assert_eq!(
            parse(&args(&["save-episode", "--node", "rec2"])).unwrap(),
            Some(Command::SaveEpisode {
                node: "rec2".into()
            })
        );
        assert_eq!(
            parse(&args(&[
                "replay",
                "--root",
                "/d",
                "--episode",
                "2",
                "--speed",
                "0.5"
            ]))
            .unwrap(),
            Some(Command::Replay {
                root: Some("/d".into()),
                episode: 2,
                node: "compute_ik".into(),
                speed: 0.5,
                arm_config: String::new(),
            })
        );
        assert!(parse(&args(&["replay", "--root", "/d"])).is_err());
        assert!(parse(&args(&["replay", "--episode", "0", "--speed", "0"])).is_err());
        assert!(parse(&args(&["replay", "--help"])).is_err());
        // not a command: the node's (which refuses a stray argument in one line)
        assert_eq!(parse(&args(&["stop"])).unwrap(), None);
        assert!(parse(&args(&["save-episode", "--bogus"])).is_err());
    }
}
