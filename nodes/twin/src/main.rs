//! `twin` binary: the physics twin as a ROS node ([`twin::node`]): the arm in MuJoCo
//! behind a pseudo-terminal speaking the servo_control firmware's protocol, so that
//! `serial_node port:=twin` drives it as it drives the Uno; it publishes
//! `twin/joint_states`, the cube's tf frame and its camera. Built without the `mujoco`
//! feature it says what is missing and exits with 3.
//!
//! `twin --mujoco-check` exits 0 when the twin has its physics (the launch scripts ask
//! before they start it), else says what is missing and exits 3.

use std::process::ExitCode;

/// The launch scripts' question: is this twin built with MuJoCo? (Without it, every
/// start says what is missing and exits 3.)
#[cfg(feature = "mujoco")]
const CHECK: &str = "--mujoco-check";

#[cfg(feature = "mujoco")]
fn main() -> ExitCode {
    if std::env::args().nth(1).as_deref() == Some(CHECK) {
        return ExitCode::SUCCESS;
    }
    ros_plumbing::node::main(twin::spec(), twin::node::serve)
}

#[cfg(not(feature = "mujoco"))]
fn main() -> ExitCode {
    // --help still describes the node (its parameters) without MuJoCo
    if std::env::args().skip(1).any(|a| a == "-h" || a == "--help") {
        return ros_plumbing::node::main(twin::spec(), async |_: &mut ros_plumbing::RosNode, _| {
            Ok::<(), ros_plumbing::PlumbingError>(())
        });
    }
    eprintln!("twin: {}", twin::WITHOUT_MUJOCO);
    ExitCode::from(3)
}
