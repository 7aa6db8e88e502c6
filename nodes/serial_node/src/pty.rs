//! A [`Device`] served behind a pseudo-terminal, so that serial_node's real serial-port
//! path can be used without a board: the `virtual_arduino` binary, and the physics twin's
//! (`nodes/twin`), whose servos follow the device's pulses.

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use servo_protocol::device::Device;
use std::io::{Read, Write};
use std::os::fd::AsFd;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What the command line asks for.
#[derive(Debug, PartialEq)]
pub enum Command {
    /// `--help`.
    Help,
    /// Serve behind a link at this path.
    Serve(String),
}

/// `args` without argv\[0\]; the error is the usage problem.
pub fn parse(args: &[String]) -> Result<Command, String> {
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

/// A flag that SIGINT and SIGTERM set: a process's [`serve`] stops on them.
pub fn stop_on_signals() -> std::io::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, stop.clone())?;
    }
    Ok(stop)
}

/// The pseudo-terminal link of the physics twin in a ROS domain and namespace: where
/// `twin` serves by default and what `serial_node port:=twin` opens (the twin must run
/// on serial_node's host, as the Arduino's cable would).
pub fn twin_link(domain: u32, namespace: &str) -> std::path::PathBuf {
    let ns: String = namespace
        .trim_matches('/')
        .chars()
        .map(|c| if c == '/' { '_' } else { c })
        .collect();
    let name = if ns.is_empty() {
        format!("domain-{domain}.tty")
    } else {
        format!("domain-{domain}-{ns}.tty")
    };
    std::env::temp_dir().join("eezybot-twin").join(name)
}

/// Serves `device` behind a new pseudo-terminal, linked at `link` (replaced if it
/// exists, removed when serving ends; its folder made if missing), until `stop` is set
/// (`Ok`) or until `each_tick` fails (that error: the link is removed and the terminal
/// closed, which the host sees as an unplugged cable). `each_tick` runs about every 2 ms,
/// after the device has taken the host's bytes and its own tick, with the time since
/// serving began. `name` prefixes the log line.
pub fn serve(
    name: &str,
    link: &str,
    mut device: Device,
    stop: &AtomicBool,
    mut each_tick: impl FnMut(&Device, Duration) -> Result<(), String>,
) -> Result<(), Box<dyn std::error::Error>> {
    if let Some(dir) = std::path::Path::new(link)
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
    {
        std::fs::create_dir_all(dir)?;
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
    eprintln!("{name}: serving on {link} -> {}", slave_path.display());

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
        if let Err(why) = each_tick(&device, start.elapsed()) {
            let _ = std::fs::remove_file(link);
            return Err(why.into());
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
    fn a_failing_tick_ends_serving_with_its_reason_and_takes_the_link_away() {
        let dir = std::env::temp_dir().join(format!("pty-test-{}", std::process::id()));
        let link = dir.join("sub").join("tty");
        let stop = AtomicBool::new(false);
        let mut ticks = 0;
        let result = serve(
            "test",
            link.to_str().unwrap(),
            Device::new(servo_protocol::device::DeviceConfig::default()),
            &stop,
            |_, _| {
                ticks += 1;
                // the link is there while it serves (its folder made)
                assert!(link.symlink_metadata().is_ok());
                if ticks == 3 {
                    Err("the simulation went unstable".into())
                } else {
                    Ok(())
                }
            },
        );
        assert_eq!(
            result.unwrap_err().to_string(),
            "the simulation went unstable"
        );
        assert!(
            link.symlink_metadata().is_err(),
            "the link is gone: the host sees the device lost"
        );
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn the_twin_link_is_per_domain_and_namespace() {
        let a = twin_link(7, "/");
        assert!(a.ends_with("eezybot-twin/domain-7.tty"), "{a:?}");
        assert!(twin_link(7, "/arm2/left").ends_with("eezybot-twin/domain-7-arm2_left.tty"));
        assert_ne!(twin_link(8, "/"), a);
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
