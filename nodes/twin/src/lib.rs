#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

#[cfg(feature = "mujoco")]
pub mod camera;
#[cfg(feature = "mujoco")]
pub mod lockstep;
#[cfg(feature = "mujoco")]
pub mod node;
#[cfg(feature = "mujoco")]
pub mod sim;

use eezybot_kinematics::ArmConfig;
use ros_plumbing::{ParamRange, ParamSpec, ParameterValue, Params};
use twin_model::Scene;

/// What a twin built without MuJoCo says, and how to get it.
pub const WITHOUT_MUJOCO: &str = "this twin was built without MuJoCo (the `mujoco` feature). \
Install MuJoCo's library and build the twin with it:\n  \
. launch_scripts/install_mujoco.sh --env\n  \
cargo build --release -p twin --features mujoco\n\
Everything else (the graph with the virtual Arduino, port:=mock) works without it.";

/// The node's description and parameters.
pub fn spec() -> ros_plumbing::NodeSpec {
    let d = Config::default();
    let s = &d.scene;
    let f = |v: f64| ParameterValue::Double(v);
    let arr = |v: &[f64]| ParameterValue::DoubleArray(v.to_vec());
    let int = |name, v: u32, lo: i64, hi: i64, about| {
        ParamSpec::new(name, ParameterValue::Integer(i64::from(v)), about)
            .range(ParamRange::Integer { min: lo, max: hi })
            .read_only()
    };
    let mut params = vec![
        ParamSpec::new(
            "link",
            ParameterValue::String(String::new()),
            "the pseudo-terminal's link that serial_node opens; empty: the one `serial_node port:=twin` finds for this domain and namespace",
        )
        .read_only(),
        ParamSpec::new(
            "pulse_events",
            ParameterValue::String(String::new()),
            "instead of serving a pseudo-terminal, follow the servo pins of the firmware in simavr: the event file of servo_sim (--events), its pin edges driving the servos in lock-step with the board's simulated clock; empty: serve `link`",
        )
        .read_only(),
        ParamSpec::file(
            "arm_config",
            "the arm the twin is assembled to (its servo calibration, read backwards, turns pulses into joint angles); empty: the shipped config/arm.yaml",
            "empty, or an arm_config YAML file that loads",
            |p| ArmConfig::load_or_shipped(p).map(|_| ()).map_err(|e| e.to_string()),
        )
        .read_only(),
        int("camera_fps", d.camera_fps, 0, 60, "frames a second of the twin's camera on twin/camera/image_raw/compressed; 0: no camera"),
        int("camera_width", s.image_size.0, 16, 1920, "the camera's image width, px"),
        int("camera_height", s.image_size.1, 16, 1080, "the camera's image height, px"),
        ParamSpec::new("camera_pos", arr(&s.camera_pos), "the camera's position in base_link, m (x, y, z)").read_only(),
        ParamSpec::new("camera_target", arr(&s.camera_target), "the point the camera looks at, in base_link, m").read_only(),
        ParamSpec::new("camera_fovy", f(s.camera_fovy_deg), "the camera's vertical field of view, deg")
            .range(ParamRange::Double { min: 10.0, max: 120.0 })
            .read_only(),
        ParamSpec::new("cube_xy", arr(&s.cube_xy), "where the cube (on its stand) starts, x and y in base_link, m").read_only(),
        ParamSpec::new(
            "torque_scale",
            arr(&s.torque_scale),
            "each servo's stall torque as a part of its datasheet's (base, shoulder, elbow, gripper): a weak supply, a worn servo",
        )
        .read_only(),
        int("jpeg_quality", u32::from(d.jpeg_quality), 1, 100, "JPEG quality of the camera's images"),
        ParamSpec::new("state_rate", f(d.state_rate_hz), "twin/joint_states and the cube's tf frame, per second")
            .range(ParamRange::Double { min: 1.0, max: 500.0 })
            .read_only(),
    ];
    params.push(ros_plumbing::diagnostics::diagnostics_period_param());
    ros_plumbing::NodeSpec {
        name: "twin",
        description: "the physics twin: the arm in MuJoCo behind a pseudo-terminal speaking the servo link protocol (serial_node port:=twin); publishes twin/joint_states, the cube's tf frame and its camera",
        usage: "",
        params,
    }
}

/// The node's parameters as a typed configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// The pseudo-terminal's link; empty: [`serial_node::pty::twin_link`].
    pub link: String,
    /// A servo_sim event file to follow instead (empty: serve the link).
    pub pulse_events: String,
    /// The arm config file the twin is assembled to; empty: the shipped one.
    pub arm_config: String,
    /// The scene: camera, cube, torque scales.
    pub scene: Scene,
    /// Camera frames a second (0: none).
    pub camera_fps: u32,
    /// JPEG quality.
    pub jpeg_quality: u8,
    /// twin/joint_states and tf per second.
    pub state_rate_hz: f64,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            link: String::new(),
            pulse_events: String::new(),
            arm_config: String::new(),
            scene: Scene::default(),
            camera_fps: 30,
            jpeg_quality: 80,
            state_rate_hz: 100.0,
        }
    }
}

impl Config {
    /// The parameters' values (checked against [`spec`] at start); an array of the wrong
    /// length is an error naming it.
    pub fn from_params(p: &Params) -> Result<Config, String> {
        let d = Config::default();
        let int = |name: &str, default: u32| {
            p.i64(name)
                .and_then(|v| u32::try_from(v).ok())
                .unwrap_or(default)
        };
        let array = |name: &str, default: &[f64]| -> Result<Vec<f64>, String> {
            match p.get(name) {
                Some(ParameterValue::DoubleArray(v))
                    if v.len() == default.len() && v.iter().all(|x| x.is_finite()) =>
                {
                    Ok(v)
                }
                Some(ParameterValue::DoubleArray(v)) => Err(format!(
                    "{name} needs {} finite numbers, got {v:?}",
                    default.len()
                )),
                _ => Ok(default.to_vec()),
            }
        };
        let three = |name: &str, default: [f64; 3]| -> Result<[f64; 3], String> {
            let v = array(name, &default)?;
            Ok([v[0], v[1], v[2]])
        };
        let s = &d.scene;
        let xy = array("cube_xy", &s.cube_xy)?;
        let torque = array("torque_scale", &s.torque_scale)?;
        if torque.iter().any(|t| *t <= 0.0 || *t > 4.0) {
            return Err(format!(
                "torque_scale: each between 0 (excluded) and 4, got {torque:?}"
            ));
        }
        let scene = Scene {
            camera_pos: three("camera_pos", s.camera_pos)?,
            camera_target: three("camera_target", s.camera_target)?,
            camera_fovy_deg: p.f64("camera_fovy").unwrap_or(s.camera_fovy_deg),
            image_size: (
                int("camera_width", s.image_size.0),
                int("camera_height", s.image_size.1),
            ),
            cube_xy: [xy[0], xy[1]],
            torque_scale: [torque[0], torque[1], torque[2], torque[3]],
            ..Scene::default()
        };
        Ok(Config {
            link: p.string("link").unwrap_or_default(),
            pulse_events: p.string("pulse_events").unwrap_or_default(),
            arm_config: p.string("arm_config").unwrap_or_default(),
            scene,
            camera_fps: int("camera_fps", d.camera_fps),
            jpeg_quality: u8::try_from(int("jpeg_quality", u32::from(d.jpeg_quality)))
                .unwrap_or(d.jpeg_quality),
            state_rate_hz: p.f64("state_rate").unwrap_or(d.state_rate_hz),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[test]
    fn defaults_are_the_parameters_defaults() {
        let values: BTreeMap<String, ParameterValue> = spec()
            .params
            .iter()
            .map(|p| (p.name.to_string(), p.default.clone()))
            .collect();
        assert_eq!(
            Config::from_params(&Params::new(values)).unwrap(),
            Config::default()
        );
    }

    #[test]
    fn a_short_array_is_refused_with_its_name() {
        let mut values = BTreeMap::new();
        values.insert(
            "camera_pos".to_string(),
            ParameterValue::DoubleArray(vec![0.1, 0.2]),
        );
        assert!(Config::from_params(&Params::new(values))
            .unwrap_err()
            .contains("camera_pos"));
        let mut values = BTreeMap::new();
        values.insert(
            "torque_scale".to_string(),
            ParameterValue::DoubleArray(vec![1.0, 0.0, 1.0, 1.0]),
        );
        assert!(Config::from_params(&Params::new(values))
            .unwrap_err()
            .contains("torque_scale"));
    }
}
