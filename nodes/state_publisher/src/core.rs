//! robot_state_publisher's logic without ROS I/O: URDF + joint states → transforms.

use eezybot_kinematics::urdf::RobotModel;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{Quaternion, Transform, TransformStamped, Vector3};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::tf2_msgs::TFMessage;
use eezybot_msgs::Time;
use nalgebra::Isometry3;
use ros_plumbing::logging::{shorten, NAME_MAX};
use std::collections::HashMap;
use std::fmt;

/// Why a joint of a `joint_states` message was skipped.
#[derive(Clone, Debug, PartialEq)]
pub enum JointProblem {
    /// No joint of that name in the URDF.
    Unknown {
        /// the name
        name: String,
    },
    /// A fixed joint was given a position.
    NotMovable {
        /// the name
        name: String,
    },
    /// The position is NaN or infinite.
    NonFinite {
        /// the name
        name: String,
        /// the value
        value: f64,
    },
    /// A name without a position (fewer positions than names).
    NoPosition {
        /// the name
        name: String,
    },
    /// A joint named again in the same message: its first position is used.
    Duplicate {
        /// the name
        name: String,
    },
    /// More positions than names: the ones past the names belong to no joint.
    SurplusPositions {
        /// names in the message
        names: usize,
        /// positions in the message
        positions: usize,
    },
}

impl fmt::Display for JointProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            JointProblem::Unknown { name } => write!(
                f,
                "unknown joint `{}` (not in the URDF)",
                shorten(name, NAME_MAX)
            ),
            JointProblem::NotMovable { name } => {
                write!(f, "joint `{name}` is fixed and takes no position")
            }
            JointProblem::NonFinite { name, value } => {
                write!(f, "joint `{name}` position is {value}")
            }
            JointProblem::NoPosition { name } => write!(
                f,
                "joint `{name}` has no position (fewer positions than names)"
            ),
            JointProblem::Duplicate { name } => write!(
                f,
                "joint `{name}` is named twice (its first position is used)"
            ),
            JointProblem::SurplusPositions { names, positions } => write!(
                f,
                "{positions} positions for {names} names: the last {} belong to no joint",
                positions - names
            ),
        }
    }
}

struct JointFrames {
    parent: String,
    child: String,
}

/// Turns joint states into transforms for one URDF.
pub struct TfCore {
    model: RobotModel,
    frames: Vec<JointFrames>,
    /// Last position of each joint (index as in `model.joints`), if ever received.
    positions: Vec<Option<f64>>,
    /// Mimic joints of each leader.
    followers: HashMap<usize, Vec<usize>>,
    messages: u64,
    skipped: u64,
    last_problems: Vec<JointProblem>,
}

fn to_msg(iso: &Isometry3<f64>) -> Transform {
    let t = iso.translation.vector;
    let q = iso.rotation.into_inner().coords; // (i, j, k, w)
    Transform {
        translation: Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        rotation: Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        },
    }
}

impl TfCore {
    /// A core for this model; every frame name gets `frame_prefix` in front (as
    /// robot_state_publisher's `frame_prefix`, e.g. `arm2/`).
    pub fn new(model: RobotModel, frame_prefix: &str) -> TfCore {
        let frames = model
            .joints
            .iter()
            .map(|j| JointFrames {
                parent: format!("{frame_prefix}{}", j.parent),
                child: format!("{frame_prefix}{}", j.child),
            })
            .collect();
        let mut followers: HashMap<usize, Vec<usize>> = HashMap::new();
        for (i, j) in model.joints.iter().enumerate() {
            if let Some(m) = &j.mimic {
                followers.entry(m.leader).or_default().push(i);
            }
        }
        let n = model.joints.len();
        TfCore {
            model,
            frames,
            positions: vec![None; n],
            followers,
            messages: 0,
            skipped: 0,
            last_problems: vec![],
        }
    }

    /// The model.
    pub fn model(&self) -> &RobotModel {
        &self.model
    }

    fn stamped(&self, i: usize, q: f64, stamp: Time) -> TransformStamped {
        TransformStamped {
            header: Header {
                stamp,
                frame_id: self.frames[i].parent.clone(),
            },
            child_frame_id: self.frames[i].child.clone(),
            transform: to_msg(&self.model.joints[i].transform(q)),
        }
    }

    /// Every fixed joint, for `tf_static`.
    pub fn static_transforms(&self, stamp: Time) -> TFMessage {
        TFMessage {
            transforms: (0..self.model.joints.len())
                .filter(|i| !self.model.joints[*i].is_movable())
                .map(|i| self.stamped(i, 0.0, stamp))
                .collect(),
        }
    }

    /// Transforms for the joints in `msg` (and the mimic joints that follow them),
    /// stamped with the message's stamp, and the joints that were skipped.
    pub fn handle_joint_states(&mut self, msg: &JointState) -> (TFMessage, Vec<JointProblem>) {
        self.messages += 1;
        let mut problems = Vec::new();
        if msg.position.len() > msg.name.len() {
            problems.push(JointProblem::SurplusPositions {
                names: msg.name.len(),
                positions: msg.position.len(),
            });
        }
        let mut transforms = Vec::with_capacity(msg.name.len() + 2);
        let mut seen = vec![false; self.positions.len()];
        for (k, name) in msg.name.iter().enumerate() {
            let Some(i) = self.model.joint_index(name) else {
                problems.push(JointProblem::Unknown { name: name.clone() });
                continue;
            };
            if std::mem::replace(&mut seen[i], true) {
                problems.push(JointProblem::Duplicate { name: name.clone() });
                continue;
            }
            let joint = &self.model.joints[i];
            if joint.mimic.is_some() {
                continue; // follows its leader, as in robot_state_publisher
            }
            if !joint.is_movable() {
                problems.push(JointProblem::NotMovable { name: name.clone() });
                continue;
            }
            let Some(&q) = msg.position.get(k) else {
                problems.push(JointProblem::NoPosition { name: name.clone() });
                continue;
            };
            if !q.is_finite() {
                problems.push(JointProblem::NonFinite {
                    name: name.clone(),
                    value: q,
                });
                continue;
            }
            self.positions[i] = Some(q);
            transforms.push(self.stamped(i, q, msg.header.stamp));
            for &f in self
                .followers
                .get(&i)
                .map(Vec::as_slice)
                .unwrap_or_default()
            {
                if let Some(m) = &self.model.joints[f].mimic {
                    let qf = m.multiplier * q + m.offset;
                    self.positions[f] = Some(qf);
                    transforms.push(self.stamped(f, qf, msg.header.stamp));
                }
            }
        }
        self.skipped += problems.len() as u64;
        self.last_problems.clone_from(&problems);
        (TFMessage { transforms }, problems)
    }

    /// Movable joints that have never had a position: their child links are not in tf.
    pub fn missing_joints(&self) -> Vec<&str> {
        self.model
            .independent_joints()
            .filter(|j| {
                self.model
                    .joint_index(&j.name)
                    .is_some_and(|i| self.positions[i].is_none())
            })
            .map(|j| j.name.as_str())
            .collect()
    }

    /// Diagnostics: WARN while joints lack a position or the last message had skipped joints.
    pub fn diagnostic_status(&self, name: &str, extra: &[(&str, String)]) -> DiagnosticStatus {
        let missing = self.missing_joints();
        let (level, message) = if self.messages == 0 {
            (
                DiagnosticStatus::WARN,
                "no joint_states received yet".to_string(),
            )
        } else if !missing.is_empty() {
            (
                DiagnosticStatus::WARN,
                format!("no position yet for: {}", missing.join(", ")),
            )
        } else if !self.last_problems.is_empty() {
            let p: Vec<String> = self.last_problems.iter().map(|p| p.to_string()).collect();
            (DiagnosticStatus::WARN, format!("skipped: {}", p.join("; ")))
        } else {
            (DiagnosticStatus::OK, "ok".to_string())
        };
        let mut values = vec![
            ("robot", self.model.name.clone()),
            ("links", self.model.links.len().to_string()),
            ("joint_states_received", self.messages.to_string()),
            ("joints_skipped", self.skipped.to_string()),
            ("missing_joints", missing.join(" ")),
        ];
        if !self.last_problems.is_empty() {
            values.push((
                "last_skipped",
                self.last_problems
                    .iter()
                    .map(|p| p.to_string())
                    .collect::<Vec<_>>()
                    .join("; "),
            ));
        }
        values.extend(extra.iter().map(|(k, v)| (*k, v.clone())));
        ros_plumbing::diagnostics::status(level, name, &self.model.name, &message, &values)
    }
}
