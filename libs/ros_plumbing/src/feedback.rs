//! What a node tells the others about itself in `diagnostics`, typed: its health
//! ([`Health`]) and, for a node that takes targets (compute_ik), the target it refused
//! last ([`Refusal`], with a stable [`ReasonCode`]). The producer [`encode`]s a refusal
//! into the status's values; a reader [`decode`]s a `DiagnosticArray` into one
//! [`Feedback`] a status, instead of reading the keys and the prose itself.
//!
//! The keys stay those people and older readers know ([`LAST_REJECTION_KEY`] with the
//! human reason, [`REJECTED_STAMP_KEY`] with the refused target's stamp); the code is
//! one more key, [`REASON_CODE_KEY`].
//!
//! # Examples
//! ```
//! use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
//! use eezybot_msgs::Time;
//! use ros_plumbing::feedback::{self, Health, ReasonCode, Refusal};
//! let refusal = Refusal::new(Time::new(7, 5), ReasonCode::Unreachable, "out of reach", "xyz_target");
//! let status = ros_plumbing::diagnostics::status(
//!     DiagnosticStatus::WARN, "compute_ik: inverse kinematics", "eezybot_arm",
//!     "xyz_target rejected: out of reach", &feedback::encode(&refusal));
//! let array = DiagnosticArray { status: vec![status], ..Default::default() };
//! let heard = feedback::decode(&array);
//! assert_eq!(heard[0].node.as_deref(), Some("compute_ik"));
//! assert_eq!(heard[0].health, Health::Warn);
//! let got = heard[0].refusal.as_ref().unwrap();
//! assert!(got.is_for(Time::new(7, 5)));
//! assert_eq!((got.code, got.reason.as_str()), (ReasonCode::Unreachable, "out of reach"));
//! ```

use crate::diagnostics::status_node;
pub use crate::diagnostics::{stamp_text, LAST_REJECTION_KEY, REJECTED_STAMP_KEY};
use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use eezybot_msgs::Time;
use std::fmt;

/// The `diagnostics` key of a refusal's [`ReasonCode`] (`unreachable`, `stale`, …).
pub const REASON_CODE_KEY: &str = "reason_code";

/// The `diagnostics` key of the topic the refused target came on (`xyz_target`).
pub const REJECTED_TOPIC_KEY: &str = "last_rejection_topic";

/// The `diagnostics` key of the controllers active now (compute_ik's arbiter:
/// `teleop, gripper_controller`).
pub const ACTIVE_CONTROLLERS_KEY: &str = "active_controllers";

/// The `diagnostics` key of the last `switch_controller`'s outcome (`done`, or why not),
/// or of a controller the arbiter deactivated by itself (a calibration's lease ran out).
pub const LAST_SWITCH_KEY: &str = "last_switch_controller";

/// Why a target was refused, as a stable code: what a reader may act on. The human
/// reason ([`Refusal::reason`]) says more, and may change wording; the code does not.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ReasonCode {
    /// Out of the arm's reach (too far, too close, no solution found).
    Unreachable,
    /// A joint, the gripper or a servo would leave its limits.
    OutOfLimits,
    /// Stamped longer ago than the node accepts (`max_target_age`).
    Stale,
    /// Given in another frame than the arm's base frame.
    WrongFrame,
    /// A value is NaN or infinite.
    NotFinite,
    /// The emergency stop is engaged.
    Estop,
    /// The arm is being calibrated (compute_ik's `calibration` controller is active): the wizard drives the
    /// servos, no target is taken.
    Calibrating,
    /// A straight-line move would leave the workspace (or jump at a singularity).
    LineBlocked,
    /// A `joint_target` naming an unknown joint, one twice, none, or with a different
    /// number of names and positions.
    BadJoints,
    /// An orientation that is not a rotation.
    BadOrientation,
    /// A `gripper_target` for an arm without a gripper.
    NoGripper,
    /// The sample could not be read.
    Unreadable,
    /// The solver failed for another reason (the arm's chain is unusable).
    SolverFailed,
    /// Another commander holds the joints (the leader arm while its deadman is held):
    /// compute_ik's arbiter, `controller_manager/list_controllers` says who.
    Held,
    /// A code this reader does not know (a newer sender), or none given.
    Other,
}

impl ReasonCode {
    /// Every code, in a fixed order.
    pub const ALL: [ReasonCode; 15] = [
        ReasonCode::Unreachable,
        ReasonCode::OutOfLimits,
        ReasonCode::Stale,
        ReasonCode::WrongFrame,
        ReasonCode::NotFinite,
        ReasonCode::Estop,
        ReasonCode::Calibrating,
        ReasonCode::LineBlocked,
        ReasonCode::BadJoints,
        ReasonCode::BadOrientation,
        ReasonCode::NoGripper,
        ReasonCode::Unreadable,
        ReasonCode::SolverFailed,
        ReasonCode::Held,
        ReasonCode::Other,
    ];

    /// The stable snake_case code, the value of [`REASON_CODE_KEY`].
    pub fn code(self) -> &'static str {
        match self {
            ReasonCode::Unreachable => "unreachable",
            ReasonCode::OutOfLimits => "out_of_limits",
            ReasonCode::Stale => "stale",
            ReasonCode::WrongFrame => "wrong_frame",
            ReasonCode::NotFinite => "not_finite",
            ReasonCode::Estop => "estop",
            ReasonCode::Calibrating => "calibrating",
            ReasonCode::LineBlocked => "line_blocked",
            ReasonCode::BadJoints => "bad_joints",
            ReasonCode::BadOrientation => "bad_orientation",
            ReasonCode::NoGripper => "no_gripper",
            ReasonCode::Unreadable => "unreadable",
            ReasonCode::SolverFailed => "solver_failed",
            ReasonCode::Held => "held",
            ReasonCode::Other => "other",
        }
    }

    /// The code of this text; [`ReasonCode::Other`] for one it does not know.
    pub fn parse(code: &str) -> ReasonCode {
        ReasonCode::ALL
            .into_iter()
            .find(|c| c.code() == code)
            .unwrap_or(ReasonCode::Other)
    }
}

impl fmt::Display for ReasonCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.code())
    }
}

/// A refused target, as the node that refused it reports it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Refusal {
    /// The refused target's `header.stamp` as [`stamp_text`] writes it (a sender finds
    /// its own target by it, [`Refusal::is_for`]).
    pub stamp: String,
    /// Why, as a code.
    pub code: ReasonCode,
    /// Why, for people (`out of reach: …`).
    pub reason: String,
    /// The topic it came on; empty when not said.
    pub topic: String,
}

impl Refusal {
    /// The refusal of the target stamped `stamp`.
    pub fn new(stamp: Time, code: ReasonCode, reason: &str, topic: &str) -> Refusal {
        Refusal {
            stamp: stamp_text(stamp),
            code,
            reason: reason.to_string(),
            topic: topic.to_string(),
        }
    }

    /// Whether this is the refusal of the target stamped `stamp`.
    pub fn is_for(&self, stamp: Time) -> bool {
        self.stamp == stamp_text(stamp)
    }
}

/// The values a refusal adds to the refusing node's status: the human reason
/// ([`LAST_REJECTION_KEY`]), the topic, the stamp ([`REJECTED_STAMP_KEY`]) and the code
/// ([`REASON_CODE_KEY`]), for [`crate::diagnostics::status`].
pub fn encode(refusal: &Refusal) -> Vec<(&'static str, String)> {
    vec![
        (LAST_REJECTION_KEY, refusal.reason.clone()),
        (REJECTED_TOPIC_KEY, refusal.topic.clone()),
        (REJECTED_STAMP_KEY, refusal.stamp.clone()),
        (REASON_CODE_KEY, refusal.code.code().to_string()),
    ]
}

/// A status's level, typed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Health {
    /// `OK` (0)
    Ok,
    /// `WARN` (1)
    Warn,
    /// `ERROR` (2)
    Error,
    /// `STALE` (3)
    Stale,
    /// Any other level byte (kept as sent).
    Unknown(u8),
}

impl Health {
    /// From `DiagnosticStatus.level`.
    pub fn from_level(level: u8) -> Health {
        match level {
            DiagnosticStatus::OK => Health::Ok,
            DiagnosticStatus::WARN => Health::Warn,
            DiagnosticStatus::ERROR => Health::Error,
            DiagnosticStatus::STALE => Health::Stale,
            other => Health::Unknown(other),
        }
    }

    /// The `DiagnosticStatus.level` byte.
    pub fn level(self) -> u8 {
        match self {
            Health::Ok => DiagnosticStatus::OK,
            Health::Warn => DiagnosticStatus::WARN,
            Health::Error => DiagnosticStatus::ERROR,
            Health::Stale => DiagnosticStatus::STALE,
            Health::Unknown(l) => l,
        }
    }
}

/// One status of a `diagnostics` report, read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Feedback {
    /// The status's name as sent (`compute_ik: inverse kinematics`).
    pub name: String,
    /// The node that sent it, by the `NODE: TASK` convention
    /// ([`crate::diagnostics::status_node`]); `None` when the name is not a node's.
    pub node: Option<String>,
    /// The task (empty when the name has none, or is not a node's).
    pub task: String,
    /// `hardware_id`.
    pub hardware_id: String,
    /// Its level.
    pub health: Health,
    /// Its message.
    pub message: String,
    /// The target the node refused last, if it reports one.
    pub refusal: Option<Refusal>,
    /// The controllers active now ([`ACTIVE_CONTROLLERS_KEY`]), if it reports them.
    pub controllers: Option<String>,
    /// The last switch of controllers ([`LAST_SWITCH_KEY`]), if it reports one.
    pub last_switch: Option<String>,
}

impl Feedback {
    /// The node's name, else the status's name.
    pub fn node_or_name(&self) -> &str {
        self.node.as_deref().unwrap_or(&self.name)
    }

    /// One status, read. A refusal is reported when the status carries
    /// [`REJECTED_STAMP_KEY`]; its reason is [`LAST_REJECTION_KEY`]'s value, else the
    /// status's message; its code [`ReasonCode::Other`] when none is given.
    pub fn of_status(s: &DiagnosticStatus) -> Feedback {
        let value = |k: &str| {
            s.values
                .iter()
                .find(|kv| kv.key == k)
                .map(|kv| kv.value.as_str())
        };
        let refusal = value(REJECTED_STAMP_KEY).map(|stamp| Refusal {
            stamp: stamp.to_string(),
            code: value(REASON_CODE_KEY).map_or(ReasonCode::Other, ReasonCode::parse),
            reason: value(LAST_REJECTION_KEY).unwrap_or(&s.message).to_string(),
            topic: value(REJECTED_TOPIC_KEY).unwrap_or_default().to_string(),
        });
        let (node, task) = match status_node(&s.name) {
            Some((n, t)) => (Some(n.to_string()), t.to_string()),
            None => (None, String::new()),
        };
        Feedback {
            name: s.name.clone(),
            node,
            task,
            hardware_id: s.hardware_id.clone(),
            health: Health::from_level(s.level),
            message: s.message.clone(),
            refusal,
            controllers: value(ACTIVE_CONTROLLERS_KEY).map(str::to_string),
            last_switch: value(LAST_SWITCH_KEY).map(str::to_string),
        }
    }
}

/// Every status of a `diagnostics` report, read, in order.
pub fn decode(array: &DiagnosticArray) -> Vec<Feedback> {
    array.status.iter().map(Feedback::of_status).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnostics::status;

    fn array(statuses: Vec<DiagnosticStatus>) -> DiagnosticArray {
        DiagnosticArray {
            status: statuses,
            ..Default::default()
        }
    }

    #[test]
    fn every_code_round_trips_and_codes_are_distinct_snake_case() {
        for c in ReasonCode::ALL {
            assert_eq!(ReasonCode::parse(c.code()), c);
            assert!(c
                .code()
                .chars()
                .all(|ch| ch.is_ascii_lowercase() || ch == '_'));
            assert_eq!(
                ReasonCode::ALL
                    .iter()
                    .filter(|d| d.code() == c.code())
                    .count(),
                1
            );
        }
        assert_eq!(
            ReasonCode::parse("a_code_from_the_future"),
            ReasonCode::Other
        );
    }

    #[test]
    fn a_refusal_round_trips_through_a_status() {
        let stamp = Time::new(1712345678, 123);
        for code in ReasonCode::ALL {
            let sent = Refusal::new(stamp, code, "target stamped 0.9 s ago", "pose_target");
            let mut values = vec![("received", "3".to_string())];
            values.extend(encode(&sent));
            let s = status(
                DiagnosticStatus::WARN,
                "ik2: inverse kinematics",
                "hw",
                "msg",
                &values,
            );
            let heard = decode(&array(vec![s]));
            assert_eq!(heard.len(), 1);
            assert_eq!(heard[0].refusal.as_ref(), Some(&sent));
            assert!(sent.is_for(stamp));
            assert!(!sent.is_for(Time::new(1712345678, 124)));
        }
    }

    #[test]
    fn encode_keeps_the_keys_readers_know() {
        let r = Refusal::new(Time::new(1, 2), ReasonCode::Stale, "too old", "xyz_target");
        let kv = encode(&r);
        let get = |k: &str| {
            kv.iter()
                .find(|(key, _)| *key == k)
                .map(|(_, v)| v.as_str())
        };
        assert_eq!(get("last_rejection"), Some("too old"));
        assert_eq!(get("last_rejection_stamp"), Some("1.000000002"));
        assert_eq!(get("last_rejection_topic"), Some("xyz_target"));
        assert_eq!(get("reason_code"), Some("stale"));
    }

    #[test]
    fn an_older_sender_without_a_code_or_reason_is_read_too() {
        let s = status(
            DiagnosticStatus::WARN,
            "compute_ik: inverse kinematics",
            "eezybot_arm",
            "xyz_target rejected: out of reach",
            &[(REJECTED_STAMP_KEY, "5.000000000".into())],
        );
        let heard = Feedback::of_status(&s);
        let r = heard.refusal.unwrap();
        assert_eq!(r.code, ReasonCode::Other);
        assert_eq!(r.reason, "xyz_target rejected: out of reach");
        assert!(r.is_for(Time::new(5, 0)));
        assert_eq!(r.topic, "");
    }

    #[test]
    fn health_and_node_are_read_and_a_status_without_a_refusal_has_none() {
        let statuses = vec![
            status(DiagnosticStatus::OK, "serial_node: link", "pi", "ok", &[]),
            status(DiagnosticStatus::ERROR, "::::", "", "bad name", &[]),
            status(7, "state_publisher", "", "odd level", &[]),
        ];
        let heard = decode(&array(statuses));
        assert_eq!(heard.len(), 3);
        assert_eq!(
            (
                heard[0].node.as_deref(),
                heard[0].task.as_str(),
                heard[0].health
            ),
            (Some("serial_node"), "link", Health::Ok)
        );
        assert_eq!(heard[0].hardware_id, "pi");
        assert!(heard[0].refusal.is_none());
        assert_eq!(
            (heard[1].node.as_deref(), heard[1].node_or_name()),
            (None, "::::")
        );
        assert_eq!(heard[1].health, Health::Error);
        assert_eq!(heard[2].health, Health::Unknown(7));
        assert_eq!(heard[2].node_or_name(), "state_publisher");
        for l in 0..=8u8 {
            assert_eq!(Health::from_level(l).level(), l);
        }
    }
}
