//! The virtual Arduino as a process behind a pseudo-terminal, so that serial_node's real
//! serial-port path can be used without a board:
//!
//!     virtual_arduino /tmp/arm/tty &
//!     serial_node --ros-args -p port:=/tmp/arm/tty
//!
//! Same behaviour as the firmware (protocol, limits, watchdog) with the servos' motion
//! modelled. Stops on SIGINT/SIGTERM (exit 0); killing it is "unplugging the cable".

use serial_node::pty::{parse, serve, stop_on_signals, Command};
use servo_protocol::device::{Device, DeviceConfig};
use std::process::ExitCode;

const USAGE: &str = "\
virtual_arduino: the virtual Arduino (servo_control firmware's protocol, limits, watchdog
and servo motion) behind a pseudo-terminal, for serial_node's real serial-port path.

usage: virtual_arduino [--] PTY_LINK_PATH
       virtual_arduino --help

PTY_LINK_PATH  the symbolic link to create to the pseudo-terminal (replaced if it
               exists, removed on exit); give it to serial_node as -p port:=PTY_LINK_PATH

Stops on SIGINT/SIGTERM. Exit codes: 0 stopped by a signal, 1 could not serve (no
pseudo-terminal, cannot create the link), 2 usage error.
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let link = match parse(&args) {
        Ok(Command::Help) => {
            print!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Ok(Command::Serve(link)) => link,
        Err(why) => {
            eprintln!(
                "virtual_arduino: {why}\nusage: virtual_arduino [--] PTY_LINK_PATH (see --help)"
            );
            return ExitCode::from(2);
        }
    };
    let served = stop_on_signals().map_err(Into::into).and_then(|stop| {
        let device = Device::new(DeviceConfig::default());
        serve("virtual_arduino", &link, device, &stop, |_, _| Ok(()))
    });
    match served {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("virtual_arduino: {e}");
            ExitCode::from(1)
        }
    }
}
