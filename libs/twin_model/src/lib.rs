#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod drive;
pub mod mass;
pub mod mjcf;
pub mod pulses;
pub mod servo;

pub use drive::Drive;
pub use mjcf::{build, Closure, Scene, TwinModel};
pub use servo::{Servo, ServoSpec};

/// Why the twin's model could not be made.
#[derive(Debug, thiserror::Error)]
pub enum TwinModelError {
    /// The URDF could not be read, or lacks a link or joint the twin needs.
    #[error("URDF: {0}")]
    Urdf(String),
}
