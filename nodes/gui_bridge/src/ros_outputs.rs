//! [`Outputs`] on ROS topics: the publishers of the targets, `estop` and `diagnostics`.

use crate::Outputs;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{Point, PointStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::{Bool, Float64, Header};
use eezybot_msgs::Time;
use ros_plumbing::diagnostics::DiagnosticsPublisher;
use ros_plumbing::{topics, PlumbingError, RosNode, TopicPublisher};

/// The node's publishers.
pub struct RosOutputs {
    /// `xyz_target`
    pub xyz: TopicPublisher<PointStamped>,
    /// `xyz_line_target`
    pub xyz_line: TopicPublisher<PointStamped>,
    gripper: TopicPublisher<Float64>,
    joints: TopicPublisher<JointState>,
    estop: TopicPublisher<Bool>,
    diagnostics: DiagnosticsPublisher,
    frame: String,
}

impl RosOutputs {
    /// Create the publishers; targets carry the `base_frame` parameter as frame_id.
    pub fn new(node: &mut RosNode) -> Result<RosOutputs, PlumbingError> {
        let frame = node
            .params()
            .string("base_frame")
            .unwrap_or_else(|| "base_link".into());
        Ok(RosOutputs {
            xyz: node.publish_on(&topics::XYZ_TARGET)?,
            xyz_line: node.publish_on(&topics::XYZ_LINE_TARGET)?,
            gripper: node.publish_on(&topics::GRIPPER_TARGET)?,
            joints: node.publish_on(&topics::JOINT_TARGET)?,
            estop: node.publish_on(&topics::ESTOP)?,
            diagnostics: node.diagnostics()?,
            frame,
        })
    }
}

impl RosOutputs {
    /// Every `diagnostics` report also carries the expiry of this certificate (the web
    /// panel's TLS certificate), or of the node's SROS2 certificate if that runs out first.
    pub fn also_certificate(
        mut self,
        expiry: Option<ros_plumbing::security::CertificateExpiry>,
    ) -> Self {
        if let Some(expiry) = expiry {
            self.diagnostics = self.diagnostics.also_certificate(expiry);
        }
        self
    }

    /// The publisher of `xyz_target`, or with `line` of `xyz_line_target`.
    pub fn xyz_publisher(&self, line: bool) -> &TopicPublisher<PointStamped> {
        if line {
            &self.xyz_line
        } else {
            &self.xyz
        }
    }

    /// Wait until the subscribers of the four target topics have acknowledged every
    /// target published, at most `max_wait` (false on timeout): before a command-line
    /// delivery exits, so its last target is not lost with the process.
    pub async fn delivered(&self, max_wait: std::time::Duration) -> bool {
        let (xyz, xyz_line, gripper, joints) = tokio::join!(
            self.xyz.delivered(max_wait),
            self.xyz_line.delivered(max_wait),
            self.gripper.delivered(max_wait),
            self.joints.delivered(max_wait)
        );
        xyz && xyz_line && gripper && joints
    }
}

impl Outputs for RosOutputs {
    fn xyz_target(&self, xyz: [f64; 3], line: bool, stamp: Time) {
        let msg = PointStamped {
            header: Header {
                stamp,
                frame_id: self.frame.clone(),
            },
            point: Point {
                x: xyz[0],
                y: xyz[1],
                z: xyz[2],
            },
        };
        self.xyz_publisher(line).publish(msg);
    }
    fn gripper_target(&self, opening: f64) {
        self.gripper.publish(Float64 { data: opening });
    }
    fn joint_target(&self, positions: &[(String, f64)], stamp: Time) {
        let msg = JointState {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            name: positions.iter().map(|(n, _)| n.clone()).collect(),
            position: positions.iter().map(|(_, v)| *v).collect(),
            velocity: vec![],
            effort: vec![],
        };
        self.joints.publish(msg);
    }
    fn estop(&self, engaged: bool) {
        self.estop.publish(Bool { data: engaged });
    }
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.publish(vec![status]);
    }
}
