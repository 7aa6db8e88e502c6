//! What the driver tests share (`tests/driver.rs`, `tests/calibrating.rs`): a fixed
//! clock, a driver on the EezyBot, and readers of its effects.
#![allow(dead_code)]
use compute_ik::driver::{Driver, Effect};
use compute_ik::eezybot::{EezyBot, IkCore};
use compute_ik::Input;
use eezybot_kinematics::ArmConfig;
use eezybot_msgs::geometry_msgs::{Point, PointStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use std::time::{Duration, Instant};

pub fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

/// The wall clock of the test: `t0_wall` at the monotonic `t0`, advancing with it.
pub struct Clock {
    pub t0: Instant,
    pub t0_wall: Time,
}

impl Clock {
    pub fn new() -> Clock {
        Clock {
            t0: Instant::now(),
            t0_wall: Time::from_nanos(1_700_000_000_000_000_000),
        }
    }
    pub fn at(&self, t: Duration) -> (Instant, Time) {
        (self.t0 + t, self.wall(t))
    }
    pub fn wall(&self, t: Duration) -> Time {
        Time::from_nanos(self.t0_wall.to_nanos() + t.as_nanos() as i64)
    }
}

pub fn driver() -> Driver<EezyBot> {
    Driver::new(IkCore::new(&ArmConfig::default(), "base_link"))
}

pub fn xyz(x: f64, y: f64, z: f64, stamp: Time) -> Input {
    Input::XyzTarget(PointStamped {
        header: Header {
            stamp,
            frame_id: String::new(),
        },
        point: Point { x, y, z },
    })
}

pub fn published(effects: &[Effect]) -> Vec<&JointState> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::Publish(s) => Some(&s.joint_states),
            _ => None,
        })
        .collect()
}

pub fn position(js: &JointState, name: &str) -> f64 {
    js.position[js.name.iter().position(|n| n == name).unwrap()]
}

/// The controller's diagnostics value `key` (`leader`, `last_trajectory`, ...).
pub fn controller_value(d: &Driver<EezyBot>, key: &str) -> String {
    d.controller_values()
        .into_iter()
        .find(|(k, _)| k == key)
        .unwrap()
        .1
}

pub fn leader_value(d: &Driver<EezyBot>) -> String {
    controller_value(d, "leader")
}

pub const ARM: [&str; 3] = ["base_joint", "shoulder_joint", "elbow_joint"];

// ---- the controller manager's services, as a client calls them ----

/// The client that sends [`switch`] and [`active`]'s requests.
pub fn caller() -> ros_plumbing::service::Caller {
    ros_plumbing::service::Caller([7; 12])
}

pub fn switch(n: u64, activate: &[&str], deactivate: &[&str]) -> Input {
    use eezybot_msgs::controller_manager_msgs::SwitchControllerRequest;
    Input::SwitchController(
        ros_plumbing::service::Ticket(n),
        caller(),
        SwitchControllerRequest {
            activate_controllers: activate.iter().map(|s| s.to_string()).collect(),
            deactivate_controllers: deactivate.iter().map(|s| s.to_string()).collect(),
            strictness: SwitchControllerRequest::STRICT,
            ..Default::default()
        },
    )
}

pub fn switched(effects: &[Effect]) -> Option<(bool, String)> {
    effects.iter().find_map(|e| match e {
        Effect::SwitchController(_, r) => Some((r.ok, r.message.clone())),
        _ => None,
    })
}

pub fn active(d: &mut Driver<EezyBot>, now: std::time::Instant, wall: Time) -> Vec<String> {
    let e = d.on_inputs(
        vec![Input::ListControllers(
            ros_plumbing::service::Ticket(99),
            caller(),
        )],
        now,
        wall,
    );
    let list = e
        .iter()
        .find_map(|e| match e {
            Effect::ListControllers(_, r) => Some(r.clone()),
            _ => None,
        })
        .expect("answered");
    list.controller
        .into_iter()
        .filter(|c| c.state == "active")
        .map(|c| c.name)
        .collect()
}
