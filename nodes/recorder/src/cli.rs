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
}

/// Parse our arguments (without argv\[0\]; ROS arguments after `--ros-args` are left
/// for the node). `None`: run the node.
pub fn parse(argv: &[String]) -> Result<Option<Command>, clap::Error> {
    let user = match ros_plumbing::args::parse(argv.iter().cloned()) {
        Ok((user, _)) => user,
        Err(e) => {
            return Err(Cli::command().error(clap::error::ErrorKind::InvalidValue, e.to_string()))
        }
    };
    // the node's own --help lists its parameters: leave it to the node
    if user.is_empty() || user.iter().any(|a| a == "--help" || a == "-h") && !is_command(&user) {
        return Ok(None);
    }
    let matches = Cli::command().try_get_matches_from(
        std::iter::once("recorder".to_string()).chain(user.iter().cloned()),
    )?;
    Ok(Cli::from_arg_matches(&matches)?.command)
}

fn is_command(user: &[String]) -> bool {
    user.first()
        .is_some_and(|a| ["start-episode", "save-episode", "discard-episode"].contains(&a.as_str()))
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
    let mut ros = RosNode::start_with(&spec, ros_args, domain.as_deref())?;
    let (call, node, task) = match &command {
        Command::StartEpisode { task, node } => (EpisodeCall::Start, node, task.clone()),
        Command::SaveEpisode { node } => (EpisodeCall::Save, node, None),
        Command::DiscardEpisode { node } => (EpisodeCall::Discard, node, None),
    };
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
        assert!(parse(&args(&["stop"])).is_err());
    }
}
