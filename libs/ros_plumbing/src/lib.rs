//! ROS 2 plumbing shared by every EezyBot node, so no node repeats it:
//!
//! * [`burst`]: a burst of commands (DDS repairing an outage) applied as its newest;
//! * [`args`]: the `--ros-args` command line (`-r`, `-p`, `--params-file`, `--log-level`);
//! * [`names`]: absolute name expansion and remapping (ros2-client makes `rt//x` of
//!   relative root names; we never hand it one);
//! * [`params`]: declared parameters with defaults and ranges, served to `ros2 param`;
//! * [`topics`]: every topic of `shared/INTERFACES.md`, declared once: name, type, QoS;
//! * [`qos`]: the QoS profiles the topics use;
//! * [`publisher`]: [`TopicPublisher`], publishing that logs a failed write;
//! * [`logging`]: the `log` crate on stderr and `/rosout`;
//! * [`diagnostics`]: `diagnostics` publishing, the refusal keys, latency percentiles;
//! * [`peers`]: the remote ends of a node's topics, and when they are lost and regained;
//! * [`remote_params`]: another node's parameters, through its parameter services;
//! * [`node`]: [`RosNode`] ties them together around a ros2-client node, honouring
//!   `ROS_DOMAIN_ID`; [`shutdown_signal`] for SIGINT/SIGTERM.

#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod args;
pub mod burst;
pub mod diagnostics;
mod error;
pub mod logging;
pub mod names;
pub mod node;
pub mod params;
pub mod peers;
pub mod publisher;
pub mod qos;
pub mod remote_params;
pub mod topics;

pub use error::PlumbingError;
pub use node::{run_main, shutdown_logged, shutdown_signal, NodeSpec, RosNode};
pub use params::{ParamRange, ParamSpec, Params};
pub use publisher::TopicPublisher;
pub use ros2_client::ParameterValue;
pub use topics::Topic;
