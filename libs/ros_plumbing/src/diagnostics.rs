//! Publishing `diagnostics` (diagnostic_msgs/DiagnosticArray).

use eezybot_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use ros2_client::Publisher;

/// Build one status entry.
///
/// # Examples
/// ```
/// use ros_plumbing::diagnostics::status;
/// use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
/// let s = status(DiagnosticStatus::WARN, "compute_ik: inverse kinematics", "eezybot_arm",
///                "target out of reach", &[("rejected", "3".into())]);
/// assert_eq!(s.values[0].key, "rejected");
/// ```
pub fn status(
    level: u8,
    name: &str,
    hardware_id: &str,
    message: &str,
    values: &[(&str, String)],
) -> DiagnosticStatus {
    DiagnosticStatus {
        level,
        name: name.to_string(),
        message: message.to_string(),
        hardware_id: hardware_id.to_string(),
        values: values
            .iter()
            .map(|(k, v)| KeyValue {
                key: (*k).to_string(),
                value: v.clone(),
            })
            .collect(),
    }
}

/// Publishes a node's diagnostics on `diagnostics`.
pub struct DiagnosticsPublisher {
    publisher: Publisher<DiagnosticArray>,
}

impl DiagnosticsPublisher {
    /// Wrap a publisher created on the `diagnostics` topic.
    pub fn new(publisher: Publisher<DiagnosticArray>) -> Self {
        DiagnosticsPublisher { publisher }
    }

    /// Publish these statuses stamped now. A failed write is logged, never fatal.
    pub fn publish(&self, status: Vec<DiagnosticStatus>) {
        let msg = DiagnosticArray {
            header: Header {
                stamp: Time::now(),
                frame_id: String::new(),
            },
            status,
        };
        if let Err(e) = self.publisher.publish(msg) {
            log::warn!("could not publish diagnostics: {e:?}");
        }
    }
}
