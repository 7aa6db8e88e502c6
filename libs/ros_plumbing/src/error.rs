//! Errors of the plumbing layer.

use std::path::PathBuf;

/// Why a node could not be set up.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlumbingError {
    /// A command-line argument is malformed.
    #[error("bad argument `{arg}`: {why}")]
    BadArgument {
        /// the argument
        arg: String,
        /// what is wrong
        why: String,
    },
    /// `ROS_DOMAIN_ID` is not a number in 0..=232.
    #[error("ROS_DOMAIN_ID=`{value}` is not a domain id (an integer 0..=232)")]
    DomainId {
        /// the environment value
        value: String,
    },
    /// A parameters file could not be read or parsed.
    #[error("parameters file {path}: {why}")]
    ParamsFile {
        /// the file
        path: PathBuf,
        /// what is wrong
        why: String,
    },
    /// A parameter value is of the wrong type or out of range.
    #[error("parameter `{name}`: {why}")]
    Parameter {
        /// the parameter
        name: String,
        /// what is wrong
        why: String,
    },
    /// A node or topic name is not a valid ROS name.
    #[error("invalid name `{name}`: {why}")]
    Name {
        /// the name
        name: String,
        /// what is wrong
        why: String,
    },
    /// SROS2 is on but cannot be used (under `ROS_SECURITY_STRATEGY=Enforce`), or
    /// access control refused an endpoint.
    #[error("security: {0}")]
    Security(crate::security::SecurityError),
    /// ros2-client refused to create something.
    #[error("ROS 2: {0}")]
    Ros(String),
}

// Not `#[from]`: that would make the security error the source as well, and `{:#}`
// (run_main) would print its message twice.
impl From<crate::security::SecurityError> for PlumbingError {
    fn from(e: crate::security::SecurityError) -> Self {
        PlumbingError::Security(e)
    }
}
