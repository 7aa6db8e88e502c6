//! The physics twin behind a pseudo-terminal: the servo_control firmware's protocol (the
//! virtual Arduino's device), its pulses driving the servos of the arm in MuJoCo, in real
//! time:
//!
//!     twin /tmp/arm/tty &
//!     serial_node --ros-args -p port:=/tmp/arm/tty
//!
//! An unstable simulation stops it with the reason (exit 1), its terminal closed: the
//! host sees the device lost, as for an unplugged cable.

use std::process::ExitCode;

const USAGE: &str = "\
twin: the physics twin (MuJoCo) behind a pseudo-terminal, speaking the servo_control
firmware's protocol: serial_node drives it as it drives the arm.

usage: twin [--] PTY_LINK_PATH
       twin --help

PTY_LINK_PATH  the symbolic link to create to the pseudo-terminal (replaced if it
               exists, removed on exit); give it to serial_node as -p port:=PTY_LINK_PATH

Stops on SIGINT/SIGTERM. Exit codes: 0 stopped by a signal, 1 could not serve or the
simulation went unstable (the reason is printed), 2 usage error, 3 built without MuJoCo.
";

fn main() -> ExitCode {
    use serial_node::pty::{parse, Command};
    let args: Vec<String> = std::env::args().skip(1).collect();
    let link = match parse(&args) {
        Ok(Command::Help) => {
            print!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Ok(Command::Serve(link)) => link,
        Err(why) => {
            eprintln!("twin: {why}\nusage: twin [--] PTY_LINK_PATH (see --help)");
            return ExitCode::from(2);
        }
    };
    run(&link)
}

#[cfg(not(feature = "mujoco"))]
fn run(_link: &str) -> ExitCode {
    eprintln!("twin: {}", twin::WITHOUT_MUJOCO);
    ExitCode::from(3)
}

#[cfg(feature = "mujoco")]
fn run(link: &str) -> ExitCode {
    use servo_protocol::device::{Device, DeviceConfig};
    match serve(link, Device::new(DeviceConfig::default())) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("twin: {e}");
            ExitCode::from(1)
        }
    }
}

/// The device's pulses (0.5 µs ticks, 0 = none) drive the twin's servos; the simulation
/// keeps up with the wall clock, a step at a time.
#[cfg(feature = "mujoco")]
fn serve(
    link: &str,
    device: servo_protocol::device::Device,
) -> Result<(), Box<dyn std::error::Error>> {
    use eezybot_kinematics::ArmConfig;
    let config = ArmConfig::shipped()?;
    let urdf = include_str!("../../../urdf/eezybot.urdf");
    let mut sim = twin::sim::Sim::new(urdf, &config, &twin_model::Scene::default())?;
    let mut behind_reported = false;
    serial_node::pty::serve("twin", link, device, |device, now| {
        sim.set_pulses_us(device.pulses().map(|t| f64::from(t) / 2.0));
        let now = now.as_secs_f64();
        // at most 100 ms of physics per tick: a host too slow for real time lags, and
        // says so once, rather than spiral
        let mut budget = (0.1 / sim.timestep()) as u32;
        while sim.time() < now && budget > 0 {
            sim.step().map_err(|e| e.to_string())?;
            budget -= 1;
        }
        if budget == 0 && !behind_reported {
            eprintln!(
                "twin: the simulation is behind real time ({:.2} s at {now:.2} s)",
                sim.time()
            );
            behind_reported = true;
        }
        Ok(())
    })
}
