//! The virtual Arduino as a process behind a pseudo-terminal, so that serial_node's real
//! serial-port path can be used without a board:
//!
//!     virtual_arduino /tmp/arm/tty &
//!     serial_node --ros-args -p port:=/tmp/arm/tty
//!
//! Same behaviour as the firmware (protocol, limits, watchdog) with the servos' motion
//! modelled. Stops on SIGINT/SIGTERM (exit 0); killing it is "unplugging the cable".

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use servo_protocol::device::{Device, DeviceConfig};
use std::io::{Read, Write};
use std::os::fd::AsFd;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

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

/// What the command line asks for.
#[derive(Debug, PartialEq)]
enum Command {
    Help,
    Serve(String),
}

/// `args` without argv\[0\]; the error is the usage problem.
fn parse(args: &[String]) -> Result<Command, String> {
    let mut paths = Vec::new();
    let mut options_done = false;
    for arg in args {
        match arg.as_str() {
            "-h" | "--help" if !options_done => return Ok(Command::Help),
            "--" if !options_done => options_done = true,
            a if a.starts_with('-') && a != "-" && !options_done => {
                return Err(format!("unknown option `{a}`"))
            }
            a => paths.push(a.to_string()),
        }
    }
    match <[String; 1]>::try_from(paths) {
        Ok([path]) => Ok(Command::Serve(path)),
        Err(paths) if paths.is_empty() => Err("missing PTY_LINK_PATH".into()),
        Err(paths) => Err(format!("one PTY_LINK_PATH expected, got {}", paths.len())),
    }
}

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
    match serve(&link) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("virtual_arduino: {e}");
            ExitCode::from(1)
        }
    }
}

fn serve(link: &str) -> Result<(), Box<dyn std::error::Error>> {
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, stop.clone())?;
    }
    let pty = openpty(None, None)?;
    let mut tio = tcgetattr(pty.slave.as_fd())?;
    cfmakeraw(&mut tio);
    tcsetattr(pty.slave.as_fd(), SetArg::TCSANOW, &tio)?;
    let slave_path = std::fs::read_link(format!(
        "/proc/self/fd/{}",
        std::os::fd::AsRawFd::as_raw_fd(&pty.slave)
    ))?;
    let _ = std::fs::remove_file(link);
    std::os::unix::fs::symlink(&slave_path, link)?;
    let flags = OFlag::from_bits_truncate(fcntl(pty.master.as_fd(), FcntlArg::F_GETFL)?);
    fcntl(
        pty.master.as_fd(),
        FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK),
    )?;
    let mut master = std::fs::File::from(pty.master);
    eprintln!(
        "virtual_arduino: serving on {link} -> {}",
        slave_path.display()
    );

    let mut device = Device::new(DeviceConfig::default());
    let start = Instant::now();
    let mut buf = [0u8; 256];
    while !stop.load(Ordering::SeqCst) {
        let ready = {
            let mut fds = [PollFd::new(master.as_fd(), PollFlags::POLLIN)];
            poll(&mut fds, PollTimeout::from(2u16)).unwrap_or(0)
        };
        if ready > 0 {
            match master.read(&mut buf) {
                Ok(n) if n > 0 => device.receive(&buf[..n], start.elapsed()),
                _ => {}
            }
        }
        device.tick(start.elapsed());
        let out = device.take_output();
        if !out.is_empty() {
            let _ = master.write_all(&out);
        }
    }
    let _ = std::fs::remove_file(link);
    drop(pty.slave);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(args: &[&str]) -> Result<Command, String> {
        parse(&args.iter().map(|a| a.to_string()).collect::<Vec<_>>())
    }

    #[test]
    fn help_is_not_a_pty_path() {
        assert_eq!(p(&["--help"]), Ok(Command::Help));
        assert_eq!(p(&["-h"]), Ok(Command::Help));
        assert_eq!(p(&["/tmp/tty", "--help"]), Ok(Command::Help));
        assert_eq!(p(&["/tmp/tty"]), Ok(Command::Serve("/tmp/tty".into())));
        assert_eq!(p(&["--", "--help"]), Ok(Command::Serve("--help".into())));
        assert!(p(&["--bogus", "/tmp/tty"]).unwrap_err().contains("--bogus"));
        assert!(p(&[]).is_err());
        assert!(p(&["a", "b"]).is_err());
    }
}
