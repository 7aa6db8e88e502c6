#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod action;
pub mod action_client;
pub mod args;
pub mod burst;
pub mod controller_manager;
/// Which topics cross the WAN bridge and in which direction: wan/'s `CROSSING`, the one
/// list, read by wan/'s own workspace and here (the bridges' SROS2 permissions,
/// [`sros2`], and the contract test `tests/crossing.rs`).
#[path = "../../../wan/src/crossing.rs"]
pub mod crossing;
pub mod diagnostics;
pub mod docs;
pub mod episodes;
mod error;
pub mod feedback;
pub mod logging;
pub mod names;
pub mod node;
pub mod params;
pub mod peers;
pub mod publisher;
pub mod qos;
pub mod remote_params;
pub mod samples;
pub mod security;
pub mod service;
pub mod sros2;
pub mod topics;
mod value;

pub use error::PlumbingError;
pub use node::{run_main, shutdown_logged, shutdown_signal, NodeSpec, RosNode, Shutdown};
pub use params::{ParamRange, ParamSpec, Params};
pub use publisher::TopicPublisher;
/// The ros2-client types a node's I/O shell names (so that nodes depend on this crate,
/// not on ros2-client).
pub use ros2_client::{Message, Node, ParameterValue, Subscription};
pub use topics::Topic;
