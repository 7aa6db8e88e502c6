//! Which topics cross the WAN and in which direction: pure constants, with no
//! dependency, so that the main workspace includes this file too
//! (`ros_plumbing::crossing`): its SROS2 permissions of the bridges' enclaves
//! (`ros_plumbing::sros2`, `Role::Bridge`: exactly what crosses, each way) are made from
//! [`CROSSING`], and its test of the topic contract (libs/ros_plumbing/tests/crossing.rs)
//! checks [`CROSSING`] against `ros_plumbing::topics`: every crossing topic is in the
//! contract, published on its `from` side and subscribed on each `to` side, and every
//! topic published on one side and subscribed on the other crosses.

use std::str::FromStr;

/// Which half of the graph a bridge serves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The operator's PC: compute_ik, state_publisher, gui_bridge (launch_scripts/pc.sh).
    Pc,
    /// The Raspberry Pi: serial_node (launch_scripts/pi.sh).
    Pi,
}

/// The topics that cross the WAN: each with the side whose nodes publish it and the
/// sides whose nodes subscribe to it from across the router. That is the part of the
/// topic contract (libs/ros_plumbing/src/topics.rs, checked by
/// libs/ros_plumbing/tests/crossing.rs) that one site needs from another;
/// everything else stays on its LAN (the targets, joint_states, tf and tf_static, each
/// site's `rosout`, `parameter_events` and `ros_discovery_info`). No services, actions
/// or parameters cross.
///
/// | topic | from | to | QoS |
/// |---|---|---|---|
/// | `servo_angles` | PC (compute_ik) | Pi (serial_node) | reliable, volatile |
/// | `estop` | PC (gui_bridge) | Pi (serial_node), other PCs (their panels) | reliable, transient-local (latched) |
/// | `robot_description` | PC (state_publisher) | other PCs (RViz2, their panels) | reliable, transient-local (latched) |
/// | `servo_state` | Pi (serial_node) | PCs (gui_bridge, compute_ik, tools) | reliable, volatile |
/// | `diagnostics` | Pi (serial_node) | PCs (gui_bridge, tools); the PC's own stay on its LAN | reliable, volatile |
/// | `camera/image_raw/compressed` | Pi (camera_node) | PCs (recorder) | best effort, volatile (sensor data) |
///
/// PC to PC: a second operator PC whose bridge joins later gets the latched
/// `robot_description` and the current `estop` from the first (the plugin's
/// transient-local cache); its own e-stop reaches the Pi and the first PC. A bridge's
/// DDS readers ignore its own writers, so nothing loops back.
pub const CROSSING: &[Crossing] = &[
    Crossing {
        topic: "servo_angles",
        from: Side::Pc,
        to: &[Side::Pi],
    },
    Crossing {
        topic: "estop",
        from: Side::Pc,
        to: &[Side::Pi, Side::Pc],
    },
    Crossing {
        topic: "robot_description",
        from: Side::Pc,
        to: &[Side::Pc],
    },
    Crossing {
        topic: "servo_state",
        from: Side::Pi,
        to: &[Side::Pc],
    },
    Crossing {
        topic: "diagnostics",
        from: Side::Pi,
        to: &[Side::Pc],
    },
    Crossing {
        topic: "camera/image_raw/compressed",
        from: Side::Pi,
        to: &[Side::Pc],
    },
];

/// One topic of [`CROSSING`].
#[derive(Clone, Copy, Debug)]
pub struct Crossing {
    /// The topic's name relative to the nodes' namespace.
    pub topic: &'static str,
    /// The side whose local publishers the bridge sends out.
    pub from: Side,
    /// The sides whose bridges write it to their local subscribers.
    pub to: &'static [Side],
}

impl Side {
    /// The name on the command line and of the client certificate (`pc`, `pi`).
    pub fn name(self) -> &'static str {
        match self {
            Side::Pc => "pc",
            Side::Pi => "pi",
        }
    }

    /// Topics whose local publishers this side's bridge sends out ([`CROSSING`]).
    pub fn outgoing(self) -> Vec<&'static str> {
        CROSSING
            .iter()
            .filter(|c| c.from == self)
            .map(|c| c.topic)
            .collect()
    }

    /// Topics whose local subscribers this side's bridge feeds from the WAN.
    pub fn incoming(self) -> Vec<&'static str> {
        CROSSING
            .iter()
            .filter(|c| c.to.contains(&self))
            .map(|c| c.topic)
            .collect()
    }
}

impl FromStr for Side {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "pc" => Ok(Side::Pc),
            "pi" => Ok(Side::Pi),
            _ => Err(format!("unknown side `{s}`: pc or pi")),
        }
    }
}
