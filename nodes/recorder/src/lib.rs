#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod cli;
pub mod compose;
pub mod inputs;
pub mod node;
pub mod replay;
pub mod report;
pub mod writer;

use eezybot_kinematics::ArmConfig;
use ros_plumbing::{ParamRange, ParamSpec, ParameterValue, Params};
use std::path::PathBuf;
use std::time::Duration;

/// info.json's `robot_type`.
pub const ROBOT_TYPE: &str = "eezybot_mk2";

/// The `task` parameter's default.
pub const DEFAULT_TASK: &str = "teleoperated demonstration";

/// The node's description and parameters.
pub fn spec() -> ros_plumbing::NodeSpec {
    ros_plumbing::NodeSpec {
        name: "recorder",
        description: "LeRobot v3.0 datasets recorded live from the running graph: observation.state (servo_state through the calibration), action (the leader's joints while following, else compute_ik's commanded joints), observation.images.<camera> (MP4); episodes through recorder/start_episode, save_episode, discard_episode (std_srvs/srv/Trigger). Commands: start-episode [--task T], save-episode, discard-episode (a running recorder), replay --episode N (an episode played back on the arm); recorder COMMAND --help",
        usage: "",
        params: params(),
    }
}

fn params() -> Vec<ParamSpec> {
    vec![
        ParamSpec::new(
            "root",
            ParameterValue::String(String::new()),
            "the dataset folder (created if absent or empty; appended to if it holds a LeRobot v3.0 dataset with the same features and fps); empty = $XDG_DATA_HOME/eezybot/datasets/eezybot_mk2 (~/.local/share/eezybot/datasets/eezybot_mk2)",
        )
        .read_only(),
        ParamSpec::new("fps", ParameterValue::Integer(30), "frames a second: the sampling grid and the dataset's fps")
            .range(ParamRange::Integer { min: 1, max: 200 })
            .read_only(),
        ParamSpec::new(
            "task",
            ParameterValue::String(DEFAULT_TASK.into()),
            "the task of the episodes started from now on (LeRobot's task string; the panel's task field sets it)",
        )
        .constraints("1 to 500 characters, no control characters")
        .text_check(|s| {
            let s = s.trim();
            if s.is_empty() || s.chars().count() > recorder_core::episode::TASK_MAX || s.chars().any(char::is_control) {
                Err("must be 1 to 500 characters of text, without control characters".into())
            } else {
                Ok(())
            }
        }),
        ParamSpec::new(
            "image_topics",
            ParameterValue::StringArray(vec![]),
            "the cameras recorded, one image topic each: a name ending in `compressed` is sensor_msgs/CompressedImage (JPEG), else sensor_msgs/Image (rgb8, bgr8, mono8); `camera/image_raw/compressed` becomes observation.images.camera",
        )
        .read_only()
        .validator(|v| match v {
            ParameterValue::StringArray(t) => inputs::cameras(t).map(|_| ()),
            _ => Ok(()),
        }),
        ParamSpec::new(
            "max_staleness",
            ParameterValue::Double(0.25),
            "the oldest (s) the follower's state and each camera's image may be at a frame's instant; a frame with an older one is dropped and counted, never filled in (servo_state comes at least every heartbeat_period, 0.1 s, when the arm is idle)",
        )
        .range(ParamRange::Double { min: 0.01, max: 5.0 })
        .read_only(),
        ParamSpec::new(
            "deadman_episodes",
            ParameterValue::Boolean(false),
            "an episode runs while the leader's deadman is held: pressing it starts one of `task`, releasing it saves it",
        ),
        ParamSpec::new(
            "resume",
            ParameterValue::Boolean(true),
            "append to the dataset already in `root` (after checking its features and fps); false = refuse a root that is not empty",
        )
        .read_only(),
        ParamSpec::file(
            "arm_config",
            "the arm's servo calibration (servo_state -> joints), YAML; empty = the shipped config/arm.yaml",
            "empty, or an arm_config YAML file that loads",
            |p| ArmConfig::load_or_shipped(p).map(|_| ()).map_err(|e| e.to_string()),
        ),
    ]
}

/// The settings read at start.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// The dataset folder.
    pub root: PathBuf,
    /// Frames a second.
    pub fps: u32,
    /// (topic, camera name) of each camera.
    pub cameras: Vec<(String, String)>,
    /// The staleness limit.
    pub max_staleness: Duration,
    /// Append to an existing dataset.
    pub resume: bool,
}

/// The default dataset folder: `$XDG_DATA_HOME/eezybot/datasets/eezybot_mk2`.
pub fn default_root() -> PathBuf {
    let data = std::env::var_os("XDG_DATA_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/share")))
        .unwrap_or_else(|| PathBuf::from("."));
    data.join("eezybot/datasets").join(ROBOT_TYPE)
}

impl Config {
    /// The parameters' values (checked against [`spec`] at start).
    pub fn from_params(p: &Params) -> Result<Config, String> {
        let root = p.string("root").unwrap_or_default();
        let topics = p.get_as::<Vec<String>>("image_topics").unwrap_or_default();
        Ok(Config {
            root: if root.trim().is_empty() {
                default_root()
            } else {
                PathBuf::from(root)
            },
            fps: p
                .i64("fps")
                .and_then(|v| u32::try_from(v).ok())
                .unwrap_or(30),
            cameras: inputs::cameras(&topics)?,
            max_staleness: Duration::from_secs_f64(p.f64("max_staleness").unwrap_or(0.25)),
            resume: p.bool("resume").unwrap_or(true),
        })
    }
}

/// `arm_config`'s file, loaded whenever the parameter is set (off the loop).
pub fn load_arm_config(params: &Params) -> Result<(), String> {
    params.load_with("arm_config", |path| {
        ArmConfig::load_or_shipped(path)
            .map(|c| std::sync::Arc::new(c) as ros_plumbing::params::Loaded)
            .map_err(|e| e.to_string())
    })
}
