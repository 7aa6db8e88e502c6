//! `gui_bridge` binary: the web panel (`serve`, the default), or the command-line driver
//! (`once`, `play`, `record`; also spelt `--once X Y Z`, `--play FILE`, `--record FILE`).
//! `gui_bridge --help` says it all; [`gui_bridge::cli`] parses it.
//!
//! Exit status: 0 done, 1 a target refused (or not taken or reached in time), 2 a usage
//! or configuration error.

use gui_bridge::cli::{self, Cli, Command, EXIT_REFUSED, EXIT_USAGE};
use gui_bridge::delivery::{self, NotDelivered};
use gui_bridge::{foxglove, record, serve};
use ros_plumbing::RosNode;
use std::process::ExitCode;

fn main() -> ExitCode {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let cli = match cli::user_args(&argv) {
        Ok(user) => cli::parse(&user).unwrap_or_else(|e| e.exit()),
        Err(e) => {
            eprintln!("gui_bridge: {e}");
            return ExitCode::from(EXIT_USAGE);
        }
    };
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("gui_bridge: cannot start the async runtime: {e}");
            return ExitCode::from(EXIT_USAGE);
        }
    };
    match runtime.block_on(run(cli, argv)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("gui_bridge: {e:#}");
            let refused = e.chain().any(|c| c.is::<NotDelivered>());
            ExitCode::from(if refused { EXIT_REFUSED } else { EXIT_USAGE })
        }
    }
}

/// Start the node (ROS arguments, `ROS_DOMAIN_ID`, parameters) and run the command.
async fn run(cli: Cli, argv: Vec<String>) -> anyhow::Result<()> {
    // signal handlers first: Ctrl-C while the node starts stops it cleanly
    let shutdown = ros_plumbing::shutdown_logged();
    let domain = std::env::var("ROS_DOMAIN_ID").ok();
    let mut node = RosNode::start_with(&gui_bridge::spec(), argv, domain.as_deref())?;
    let arm_config = node.params().string("arm_config").unwrap_or_default();
    let arm = gui_bridge::load_arm(&arm_config).map_err(anyhow::Error::msg)?;
    let result = match cli.command.unwrap_or(Command::Serve) {
        Command::Serve => serve::serve(&mut node, arm, shutdown).await,
        Command::Once(args) => delivery::once(&mut node, &arm, args, shutdown).await,
        Command::Play(args) if foxglove::is_mcap(&args.file) => {
            foxglove::play_mcap(&mut node, &args.file, args.delivery.timeout, shutdown).await
        }
        Command::Play(args) => delivery::play(&mut node, &arm, args, shutdown).await,
        Command::Record(args) if foxglove::is_mcap(&args.file) => {
            foxglove::record_mcap(&mut node, &args.file, shutdown).await
        }
        Command::Record(args) => record::record(&mut node, &args.file, shutdown).await,
        Command::Calibrate(args) => {
            gui_bridge::calibrate_cli::calibrate(&mut node, args.leader, shutdown).await
        }
    };
    node.shutdown().await;
    result
}
