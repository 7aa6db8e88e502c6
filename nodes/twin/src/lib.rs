#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

#[cfg(feature = "mujoco")]
pub mod sim;

/// What a twin built without MuJoCo says, and how to get it.
pub const WITHOUT_MUJOCO: &str = "this twin was built without MuJoCo (the `mujoco` feature). \
Install MuJoCo's library and build the twin with it:\n  \
. launch_scripts/install_mujoco.sh --env\n  \
cargo build --release -p twin --features mujoco\n\
Everything else (the graph with the virtual Arduino, port:=mock) works without it.";
