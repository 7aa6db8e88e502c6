//! [`Outputs`] on ROS topics: the publishers of the targets, `estop` and `diagnostics`.

use crate::Outputs;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{Point, PointStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::{Bool, Float64, Header};
use eezybot_msgs::Time;
use ros2_client::Publisher;
use ros_plumbing::diagnostics::DiagnosticsPublisher;
use ros_plumbing::{qos, PlumbingError, RosNode};

/// The node's publishers.
pub struct RosOutputs {
    /// `xyz_target`
    pub xyz: Publisher<PointStamped>,
    gripper: Publisher<Float64>,
    joints: Publisher<JointState>,
    estop: Publisher<Bool>,
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
            xyz: node.publisher("xyz_target", qos::COMMANDS)?,
            gripper: node.publisher("gripper_target", qos::COMMANDS)?,
            joints: node.publisher("joint_target", qos::COMMANDS)?,
            estop: node.publisher("estop", qos::ESTOP)?,
            diagnostics: node.diagnostics()?,
            frame,
        })
    }
}

impl Outputs for RosOutputs {
    fn xyz_target(&self, xyz: [f64; 3], stamp: Time) {
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
        if let Err(e) = self.xyz.publish(msg) {
            log::warn!("could not publish xyz_target: {e:?}");
        }
    }
    fn gripper_target(&self, opening: f64) {
        if let Err(e) = self.gripper.publish(Float64 { data: opening }) {
            log::warn!("could not publish gripper_target: {e:?}");
        }
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
        if let Err(e) = self.joints.publish(msg) {
            log::warn!("could not publish joint_target: {e:?}");
        }
    }
    fn estop(&self, engaged: bool) {
        if let Err(e) = self.estop.publish(Bool { data: engaged }) {
            log::warn!("could not publish estop: {e:?}");
        }
    }
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.publish(vec![status]);
    }
}
