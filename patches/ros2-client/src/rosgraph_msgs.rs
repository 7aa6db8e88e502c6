//! Message types of [rosgraph_msgs](https://index.ros.org/p/rosgraph_msgs/).

use serde::{Deserialize, Serialize};

use crate::{builtin_interfaces::Time, message::Message};

/// [rosgraph_msgs/msg/Clock](https://github.com/ros2/rcl_interfaces/blob/rolling/rosgraph_msgs/msg/Clock.msg):
/// the simulated time a simulator publishes on `/clock`, followed by nodes
/// whose `use_sim_time` parameter is true.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Clock {
  /// The current time.
  pub clock: Time,
}

impl Message for Clock {}
