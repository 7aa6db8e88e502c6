//! The command line: `serve` (the web panel, also with no command), `once`, `play` and
//! `record`, each also spelt as a flag (`--once X Y Z`, `--play FILE`, `--record FILE`,
//! the forms the README has always shown). The ROS arguments after `--ros-args` are
//! not ours: [`user_args`] leaves them to ROS.
//!
//! Exit status: [`EXIT_OK`], [`EXIT_REFUSED`] (a target was refused or never taken),
//! [`EXIT_USAGE`] (usage or configuration error, as every other node of the graph).

use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand};
use std::path::PathBuf;
use std::time::Duration;

/// Done (or stopped by Ctrl-C / SIGTERM).
pub const EXIT_OK: u8 = 0;
/// A target was refused (by the local reachability check or by compute_ik), or was not
/// taken or reached in time.
pub const EXIT_REFUSED: u8 = 1;
/// A usage or configuration error (arguments, parameters, files, the web address).
pub const EXIT_USAGE: u8 = 2;

/// `gui_bridge`'s own arguments.
#[derive(Debug, Parser)]
#[command(
    name = "gui_bridge",
    about = "gui_bridge: operator input (web page, keyboard, gamepad, command line) -> xyz_target / xyz_line_target / gripper_target / joint_target / estop",
    override_usage = "gui_bridge [serve]                                  [--ros-args ...]\n       \
                      gui_bridge once X Y Z [--gripper G] [--line] [--timeout S] [--ros-args ...]\n       \
                      gui_bridge play FILE.csv|FILE.mcap [--line] [--timeout S] [--ros-args ...]\n       \
                      gui_bridge record FILE.csv|FILE.mcap                 [--ros-args ...]\n       \
                      gui_bridge calibrate [--leader]                       [--ros-args ...]\n       \
                      (the commands are also flags: --once X Y Z, --play FILE, --record FILE)"
)]
pub struct Cli {
    /// What to do; none: `serve`.
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// One mode of the node.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// The web panel (the default): http://127.0.0.1:8080/ (parameter `bind`)
    Serve,
    /// Publish one target; exit 0 once compute_ik took it, 1 if it was refused
    #[command(long_flag = "once", allow_negative_numbers = true)]
    Once(OnceArgs),
    /// Play x,y,z,gripper,dwell(,mode,name) rows: move, arrive, set the claw, dwell
    #[command(long_flag = "play")]
    Play(PlayArgs),
    /// Save every target the operator sends as such rows, until Ctrl-C
    #[command(long_flag = "record")]
    Record(RecordArgs),
    /// Calibrate the arm's servos (or a leader arm's potentiometers) step by step from
    /// the terminal: jog, mark two reference poses per joint, save and apply. Type ? for
    /// the commands. Exit 0 saved, 1 cancelled
    Calibrate(CalibrateArgs),
}

/// `calibrate`
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Calibrate a leader arm's potentiometers (serial_node role:=leader) instead of
    /// the servos
    #[arg(long)]
    pub leader: bool,
}

/// `once X Y Z`
#[derive(Debug, Args)]
pub struct OnceArgs {
    /// Target x of tool0 in metres (base_frame)
    #[arg(value_parser = finite)]
    pub x: f64,
    /// Target y in metres
    #[arg(value_parser = finite)]
    pub y: f64,
    /// Target z in metres
    #[arg(value_parser = finite)]
    pub z: f64,
    /// Claw opening to set once there: 0.0 closed … 1.0 open
    #[arg(long, value_name = "G", value_parser = opening)]
    pub gripper: Option<f64>,
    /// How to deliver
    #[command(flatten)]
    pub delivery: DeliveryArgs,
}

impl OnceArgs {
    /// The target position.
    pub fn xyz(&self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
}

/// `play FILE`
#[derive(Debug, Args)]
pub struct PlayArgs {
    /// CSV file of x,y,z,gripper,dwell rows (as `record` writes), optionally with
    /// mode and name columns (mode `line`: a straight line, on xyz_line_target; `joint`:
    /// on xyz_target, moved as compute_ik's `motion` says, joint unless started
    /// otherwise; empty: as --line says); or an MCAP recording (`.mcap`: its targets are
    /// published again at their recorded times, each on its own topic)
    #[arg(value_name = "FILE.csv|FILE.mcap")]
    pub file: PathBuf,
    /// How to deliver
    #[command(flatten)]
    pub delivery: DeliveryArgs,
}

/// `record FILE`
#[derive(Debug, Args)]
pub struct RecordArgs {
    /// CSV file to write (replaced); `.mcap`: an MCAP recording of the targets,
    /// joint_states, tf, tf_static, robot_description and servo_state
    #[arg(value_name = "FILE.csv|FILE.mcap")]
    pub file: PathBuf,
}

/// How `once` and `play` deliver targets.
#[derive(Debug, Args, Clone)]
pub struct DeliveryArgs {
    /// Straight Cartesian lines: the targets (of a program, those whose row names no
    /// mode) go on xyz_line_target instead of xyz_target; compute_ik's parameters are
    /// left alone
    #[arg(long)]
    pub line: bool,
    /// Seconds to wait for each answer (compute_ik listening, taking, arriving)
    #[arg(long, value_name = "S", default_value = "15", value_parser = seconds)]
    pub timeout: Duration,
}

fn finite(s: &str) -> Result<f64, String> {
    s.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("`{s}` is not a finite number"))
}

fn opening(s: &str) -> Result<f64, String> {
    finite(s).and_then(|v| {
        (0.0..=1.0)
            .contains(&v)
            .then_some(v)
            .ok_or_else(|| format!("{v} is outside 0.0 (closed) … 1.0 (open)"))
    })
}

fn seconds(s: &str) -> Result<Duration, String> {
    let v = finite(s)?;
    if !(0.1..=86_400.0).contains(&v) {
        return Err(format!("{v} s is outside 0.1 … 86400 s"));
    }
    Ok(Duration::from_secs_f64(v))
}

/// Our arguments out of a whole command line (without argv\[0\]): what comes before
/// `--ros-args` and after its closing `--`. A malformed ROS argument is an error.
pub fn user_args(argv: &[String]) -> Result<Vec<String>, ros_plumbing::PlumbingError> {
    ros_plumbing::args::parse(argv.iter().cloned()).map(|(user, _)| user)
}

/// Parse our arguments (without argv\[0\]). `--help` and usage errors come back as
/// a [`clap::Error`], whose `exit()` prints them and exits 0 or [`EXIT_USAGE`].
pub fn parse(user: &[String]) -> Result<Cli, clap::Error> {
    let matches = Cli::command()
        .after_help(ros_help(&crate::spec()))
        .try_get_matches_from(
            std::iter::once("gui_bridge".to_string()).chain(user.iter().cloned()),
        )?;
    Cli::from_arg_matches(&matches)
}

/// The part of `--help` about ROS: its arguments, the environment, the parameters
/// and the exit status.
pub fn ros_help(spec: &ros_plumbing::NodeSpec) -> String {
    use ros_plumbing::node::{ENVIRONMENT_HELP, ROS_ARGS_USAGE};
    format!(
        "ROS arguments (after gui_bridge's own):\n  {ROS_ARGS_USAGE} [--]\n\n\
         Environment:\n  {ENVIRONMENT_HELP}\n\nParameters (-p NAME:=VALUE):\n{}\n\
         Exit status: {EXIT_OK} done, {EXIT_REFUSED} refused (a target refused, or not taken or \
         reached in time), {EXIT_USAGE} usage or configuration error\n",
        spec.params_help()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cli(args: &str) -> Result<Cli, clap::Error> {
        let argv: Vec<String> = args.split_whitespace().map(String::from).collect();
        parse(&user_args(&argv).unwrap())
    }

    #[test]
    fn no_command_is_serve() {
        assert!(cli("").unwrap().command.is_none());
        assert!(matches!(
            cli("serve").unwrap().command,
            Some(Command::Serve)
        ));
        let c = cli("--ros-args -p bind:=127.0.0.1:0 -r __ns:=/arm2").unwrap();
        assert!(c.command.is_none());
    }

    #[test]
    fn the_old_flags_still_work() {
        let Some(Command::Once(o)) = cli("--once 0.2 0.0 0.15 --gripper 0.5").unwrap().command
        else {
            panic!("not once")
        };
        assert_eq!((o.xyz(), o.gripper), ([0.2, 0.0, 0.15], Some(0.5)));
        assert!(!o.delivery.line);
        assert_eq!(o.delivery.timeout, Duration::from_secs(15));
        let Some(Command::Once(o)) = cli("--once 0.2 -0.05 0.15 --line --timeout 20")
            .unwrap()
            .command
        else {
            panic!("not once")
        };
        assert_eq!(o.xyz(), [0.2, -0.05, 0.15]);
        assert!(o.delivery.line);
        assert_eq!(o.delivery.timeout, Duration::from_secs(20));
        let Some(Command::Play(p)) = cli("--play taught.csv --line").unwrap().command else {
            panic!("not play")
        };
        assert_eq!(p.file, PathBuf::from("taught.csv"));
        assert!(p.delivery.line);
        let Some(Command::Record(r)) = cli("--record taught.csv").unwrap().command else {
            panic!("not record")
        };
        assert_eq!(r.file, PathBuf::from("taught.csv"));
        // the ROS arguments are left to ROS, before or after ours
        let Some(Command::Once(o)) =
            cli("--once 0.2 0 0.15 --ros-args -r __node:=cli -p rate:=20 -- --gripper 1")
                .unwrap()
                .command
        else {
            panic!("not once")
        };
        assert_eq!(o.gripper, Some(1.0));
    }

    #[test]
    fn the_commands_work() {
        assert!(matches!(
            cli("once 0.2 0 0.15").unwrap().command,
            Some(Command::Once(_))
        ));
        assert!(matches!(
            cli("play a.csv --timeout 3").unwrap().command,
            Some(Command::Play(_))
        ));
        assert!(matches!(
            cli("record a.csv").unwrap().command,
            Some(Command::Record(_))
        ));
    }

    #[test]
    fn usage_errors_exit_2_and_help_0() {
        for bad in [
            "--bogus",
            "--once 0.2 0",
            "--once 0.2 nan 0.1",
            "--once 0.2 0 0.1 --gripper 1.5",
            "--record a.csv --line",
            "serve --line",
            "--play a.csv --timeout 0",
            "record",
        ] {
            let e = cli(bad).err().unwrap_or_else(|| panic!("`{bad}` accepted"));
            assert_eq!(e.exit_code(), i32::from(EXIT_USAGE), "{bad}: {e}");
        }
        let help = cli("--help").err().unwrap();
        assert_eq!(help.exit_code(), 0);
        let text = help.render().to_string();
        for word in [
            "serve",
            "once",
            "play",
            "record",
            "--ros-args",
            "ROS_DOMAIN_ID",
            "bind",
            "Exit status",
        ] {
            assert!(text.contains(word), "{word} missing from\n{text}");
        }
    }
}
