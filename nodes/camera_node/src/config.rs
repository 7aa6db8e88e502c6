//! The node's parameters ([`crate::spec`]) as a typed configuration.

use ros_plumbing::{ParamRange, ParamSpec, ParameterValue, Params};

/// The `device` value of the built-in test source.
pub const TEST_DEVICE: &str = "test";

/// What the node captures and how it names it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Config {
    /// A V4L2 device (`/dev/video0`), or [`TEST_DEVICE`].
    pub device: String,
    /// Width asked of the camera, px.
    pub width: u32,
    /// Height asked of the camera, px.
    pub height: u32,
    /// Frames a second asked of the camera (the test source's grid).
    pub fps: u32,
    /// `header.frame_id` of the images and camera infos.
    pub frame_id: String,
    /// JPEG quality where the node encodes (test source, YUYV cameras), 1-100.
    pub jpeg_quality: u8,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            device: "/dev/video0".into(),
            width: 640,
            height: 480,
            fps: 30,
            frame_id: "camera".into(),
            jpeg_quality: 80,
        }
    }
}

impl Config {
    /// Whether the device is the built-in test source.
    pub fn is_test(&self) -> bool {
        self.device == TEST_DEVICE
    }

    /// The parameters' values (checked against [`params`] at start).
    pub fn from_params(p: &Params) -> Config {
        let d = Config::default();
        let int = |name: &str, default: u32| {
            p.i64(name)
                .and_then(|v| u32::try_from(v).ok())
                .unwrap_or(default)
        };
        Config {
            device: p.string("device").unwrap_or(d.device),
            width: int("width", d.width),
            height: int("height", d.height),
            fps: int("fps", d.fps),
            frame_id: p.string("frame_id").unwrap_or(d.frame_id),
            jpeg_quality: u8::try_from(int("jpeg_quality", u32::from(d.jpeg_quality)))
                .unwrap_or(d.jpeg_quality),
        }
    }
}

fn device_check(device: &str) -> Result<(), String> {
    if device.is_empty() {
        Err("empty: a V4L2 device such as /dev/video0, or `test`".into())
    } else {
        Ok(())
    }
}

/// The parameters, read-only (set at start: a new size or device means reopening the
/// camera, which a restart of the node does).
pub fn params() -> Vec<ParamSpec> {
    let d = Config::default();
    let int = |v: u32| ParameterValue::Integer(i64::from(v));
    vec![
        ParamSpec::new(
            "device",
            ParameterValue::String(d.device),
            "the V4L2 camera (/dev/video0, /dev/v4l/by-id/...); `test` = the built-in test pattern with each frame's stamp drawn in",
        )
        .constraints("a device path, or test")
        .text_check(device_check)
        .read_only(),
        ParamSpec::new("width", int(d.width), "image width asked of the camera, px (the camera may choose another: see diagnostics)")
            .range(ParamRange::Integer { min: 144, max: 4096 })
            .read_only(),
        ParamSpec::new("height", int(d.height), "image height asked of the camera, px")
            .range(ParamRange::Integer { min: 128, max: 4096 })
            .read_only(),
        ParamSpec::new("fps", int(d.fps), "frames a second asked of the camera; the test pattern's rate")
            .range(ParamRange::Integer { min: 1, max: 120 })
            .read_only(),
        ParamSpec::new("frame_id", ParameterValue::String(d.frame_id), "header.frame_id of the images and camera infos")
            .read_only(),
        ParamSpec::new(
            "jpeg_quality",
            int(u32::from(d.jpeg_quality)),
            "JPEG quality where the node encodes (test pattern, YUYV cameras); MJPEG cameras' frames pass as they are",
        )
        .range(ParamRange::Integer { min: 1, max: 100 })
        .read_only(),
    ]
}
