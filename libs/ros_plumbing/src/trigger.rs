//! A client of a `std_srvs/srv/Trigger` service (an empty request; a success flag and a
//! message back), as `ros2 service call <name> std_srvs/srv/Trigger` reaches it: for a
//! node's commands without arguments, e.g. the recorder's `recorder/start_episode`,
//! which gui_bridge's panel calls.
//!
//! # Examples
//! ```
//! use ros_plumbing::trigger::{outcome, TriggerResponse};
//! let ok = TriggerResponse { success: true, message: "recording episode 3: pick".into() };
//! assert_eq!(outcome(ok), Ok("recording episode 3: pick".to_string()));
//! let no = TriggerResponse { success: false, message: "not recording".into() };
//! assert_eq!(outcome(no), Err("not recording".to_string()));
//! ```

use crate::{PlumbingError, RosNode};
use ros2_client::{Client, Name, ServiceMapping, ServiceTypeName};
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// [Trigger](https://github.com/ros2/common_interfaces/blob/rolling/std_srvs/srv/Trigger.srv)'s
/// request: empty (the one-byte placeholder every empty ROS 2 structure has).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TriggerRequest {
    /// Always 0.
    pub structure_needs_at_least_one_member: u8,
}

/// Trigger's response.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TriggerResponse {
    /// Whether the service did it.
    pub success: bool,
    /// What it did, or why not.
    pub message: String,
}

impl ros2_client::Message for TriggerRequest {}
impl ros2_client::Message for TriggerResponse {}

/// A response as a result: `Ok(message)` when it succeeded, `Err(message)` when not.
pub fn outcome(response: TriggerResponse) -> Result<String, String> {
    if response.success {
        Ok(response.message)
    } else {
        Err(response.message)
    }
}

/// A client of one Trigger service.
pub struct TriggerClient {
    name: String,
    client: Client<TriggerRequest, TriggerResponse>,
}

impl TriggerClient {
    /// The client of service `service` (a name in our namespace, or absolute; remapped).
    pub fn new(ros: &mut RosNode, service: &str) -> Result<Self, PlumbingError> {
        let name = ros.resolver().resolve(service)?;
        let ros_name = Name::parse(&name).map_err(|e| PlumbingError::Name {
            name: name.clone(),
            why: format!("{e:?}"),
        })?;
        let qos = crate::qos::SERVICES;
        let client = ros
            .node_mut()
            .create_client(
                ServiceMapping::Enhanced,
                &ros_name,
                &ServiceTypeName::new("std_srvs", "Trigger"),
                qos.clone(),
                qos,
            )
            .map_err(|e| PlumbingError::Ros(format!("{name}: {e:?}")))?;
        Ok(TriggerClient { name, client })
    }

    /// The service's resolved name (`/recorder/start_episode`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Wait until a server of the service is matched, at most `timeout` (a request sent
    /// before is lost).
    pub async fn wait(&self, ros: &RosNode, timeout: Duration) -> Result<(), String> {
        tokio::time::timeout(timeout, self.client.wait_for_service(ros.node()))
            .await
            .map_err(|_| {
                format!(
                    "{} does not answer within {:.0} s (is its node running in this ROS domain?)",
                    self.name,
                    timeout.as_secs_f64()
                )
            })
    }

    /// Call the service: `Ok(message)` when it succeeded, `Err` with its message when it
    /// did not, or with why there was no answer (`timeout` passed, or the call failed).
    pub async fn call(&self, timeout: Duration) -> Result<String, String> {
        match tokio::time::timeout(
            timeout,
            self.client.async_call_service(TriggerRequest::default()),
        )
        .await
        {
            Ok(Ok(response)) => outcome(response),
            Ok(Err(e)) => Err(format!("{}: {e:?}", self.name)),
            Err(_) => Err(format!(
                "no answer from {} within {:.0} s",
                self.name,
                timeout.as_secs_f64()
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_request_and_response_are_trigger_s_cdr() {
        // std_srvs/Trigger: the request a single octet, the response a bool and a string
        let request = eezybot_msgs::cdr::encode(&TriggerRequest::default()).unwrap();
        assert_eq!(request[4..], [0u8]);
        let response = TriggerResponse {
            success: true,
            message: "ok".into(),
        };
        let bytes = eezybot_msgs::cdr::encode(&response).unwrap();
        // bool, 3 bytes of padding, u32 length with the NUL, the text and NUL
        assert_eq!(bytes[4..], [1, 0, 0, 0, 3, 0, 0, 0, b'o', b'k', 0]);
        let back: TriggerResponse = eezybot_msgs::cdr::decode(&bytes).unwrap();
        assert_eq!(back, response);
    }
}
