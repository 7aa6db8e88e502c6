//! The recorder's inputs, from their messages: joints by name, the follower's joints
//! from `servo_state` through the calibration, images, and the features the image
//! topics become.

use eezybot_kinematics::{ArmConfig, ServoId, ACTUATED_JOINTS};
use eezybot_msgs::sensor_msgs::{CompressedImage, Image, JointState};
use eezybot_msgs::Time;
use lerobot_dataset::RawEncoding;
use std::sync::Arc;

/// One input's sample, as the sampler keeps it.
#[derive(Clone, Debug, PartialEq)]
pub enum Sample {
    /// The four actuated joints ([`ACTUATED_JOINTS`] order), rad.
    Joints([f64; 4]),
    /// The leader's deadman: held or not.
    Deadman(bool),
    /// A camera's image (shared: frames clone samples).
    Image(Arc<Picture>),
}

/// An image as it came.
#[derive(Clone, Debug, PartialEq)]
pub enum Picture {
    /// A whole JPEG file (sensor_msgs/CompressedImage, `format` jpeg).
    Jpeg(Vec<u8>),
    /// Raw pixels (sensor_msgs/Image).
    Raw {
        /// Columns, px.
        width: u32,
        /// Rows, px.
        height: u32,
        /// The pixel layout.
        encoding: RawEncoding,
        /// Bytes per row.
        step: u32,
        /// `step * height` bytes.
        data: Vec<u8>,
    },
}

/// The encodings of sensor_msgs/Image taken.
pub const RAW_ENCODINGS: [&str; 5] = ["rgb8", "bgr8", "rgba8", "bgra8", "mono8"];

/// A stamp in ns since the epoch.
pub fn stamp_ns(t: Time) -> i64 {
    t.to_nanos()
}

/// The four actuated joints of a JointState, by name ([`ACTUATED_JOINTS`]): `leader/joint_states`
/// and compute_ik's `joint_states` (which also has the passive joints).
pub fn actuated_joints(msg: &JointState) -> Result<[f64; 4], String> {
    if msg.position.len() != msg.name.len() {
        return Err(format!(
            "{} names but {} positions",
            msg.name.len(),
            msg.position.len()
        ));
    }
    let mut q = [0.0; 4];
    for (slot, joint) in q.iter_mut().zip(ACTUATED_JOINTS) {
        let k = msg
            .name
            .iter()
            .position(|n| n == joint)
            .ok_or_else(|| format!("no {joint}"))?;
        let v = msg.position[k];
        if !v.is_finite() {
            return Err(format!("{joint} is {v}"));
        }
        *slot = v;
    }
    Ok(q)
}

/// The follower's joints (rad, [`ACTUATED_JOINTS`] order; the claw's opening times its
/// open angle, as on `joint_states`) from a `servo_state` report, through the arm's
/// servo calibration.
pub fn follower_joints(msg: &JointState, arm: &ArmConfig) -> Result<[f64; 4], String> {
    if msg.position.len() != msg.name.len() {
        return Err(format!(
            "{} names but {} positions",
            msg.name.len(),
            msg.position.len()
        ));
    }
    let mut rad = [0.0; 4];
    for (slot, id) in rad.iter_mut().zip(ServoId::ALL) {
        let k = msg
            .name
            .iter()
            .position(|n| n == id.name())
            .ok_or_else(|| format!("no {}", id.name()))?;
        let v = msg.position[k];
        if !v.is_finite() {
            return Err(format!("{} is {v}", id.name()));
        }
        *slot = v;
    }
    let s = arm.servos.state_of_angles(rad);
    Ok([
        s.joints.base_rad,
        s.joints.shoulder_rad,
        s.joints.elbow_rad,
        s.gripper_opening * arm.geometry.gripper_open_rad,
    ])
}

/// A CompressedImage as a picture: JPEG only (what the encoder takes as it is).
pub fn compressed_picture(msg: CompressedImage) -> Result<Picture, String> {
    let format = msg.format.to_ascii_lowercase();
    let jpeg = msg.data.starts_with(&[0xFF, 0xD8]);
    if !jpeg {
        return Err(format!(
            "format {:?}: not a JPEG (only JPEG images are recorded)",
            msg.format
        ));
    }
    if !(format.is_empty() || format.contains("jpeg") || format.contains("jpg")) {
        return Err(format!("format {:?} is not JPEG", msg.format));
    }
    Ok(Picture::Jpeg(msg.data))
}

/// An Image as a picture: rgb8, bgr8, rgba8, bgra8 or mono8, whole rows.
pub fn raw_picture(msg: Image) -> Result<Picture, String> {
    let Some(encoding) = RawEncoding::from_ros(&msg.encoding) else {
        return Err(format!(
            "encoding {:?} is not one of {}",
            msg.encoding,
            RAW_ENCODINGS.join(", ")
        ));
    };
    let channels: u64 = match encoding {
        RawEncoding::Rgb8 | RawEncoding::Bgr8 => 3,
        RawEncoding::Rgba8 | RawEncoding::Bgra8 => 4,
        RawEncoding::Mono8 => 1,
    };
    let (w, h, step) = (
        u64::from(msg.width),
        u64::from(msg.height),
        u64::from(msg.step),
    );
    if w == 0 || h == 0 || step < w * channels || (msg.data.len() as u64) < step * h {
        return Err(format!(
            "{}x{} {} with step {} and {} bytes: the rows do not fit",
            msg.width,
            msg.height,
            msg.encoding,
            msg.step,
            msg.data.len()
        ));
    }
    Ok(Picture::Raw {
        width: msg.width,
        height: msg.height,
        encoding,
        step: msg.step,
        data: msg.data,
    })
}

/// Whether an image topic carries sensor_msgs/CompressedImage (image_transport's
/// convention: its name ends in `compressed`), else sensor_msgs/Image.
pub fn is_compressed(topic: &str) -> bool {
    topic.trim_end_matches('/').ends_with("compressed")
}

/// The camera name an image topic is recorded under (`observation.images.<name>`): the
/// topic without its image_transport suffix (`/image_raw/compressed`, `/image_raw`,
/// `/compressed`, `/image`) and leading `/`, the rest's `/` as `_`:
/// `camera/image_raw/compressed` is `camera`, `/wrist/camera/image_raw` `wrist_camera`.
pub fn camera_name(topic: &str) -> Result<String, String> {
    let mut t = topic.trim().trim_matches('/');
    for suffix in ["/compressed", "/image_raw", "/image_rect", "/image"] {
        if let Some(rest) = t.strip_suffix(suffix) {
            t = rest;
        }
    }
    if t.is_empty() || t == "compressed" || t == "image_raw" {
        return Err(format!(
            "{topic:?}: no name left for the camera (name it, e.g. camera/image_raw/compressed)"
        ));
    }
    if !t
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/')
    {
        return Err(format!("{topic:?} is not a ROS topic name"));
    }
    Ok(t.replace('/', "_"))
}

/// The cameras of `image_topics`: (topic, name), names unique.
pub fn cameras(image_topics: &[String]) -> Result<Vec<(String, String)>, String> {
    let mut out: Vec<(String, String)> = Vec::new();
    for topic in image_topics {
        let name = camera_name(topic)?;
        if let Some((other, _)) = out.iter().find(|(_, n)| *n == name) {
            return Err(format!(
                "{topic:?} and {other:?} would both be observation.images.{name}"
            ));
        }
        out.push((topic.clone(), name));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_kinematics::ArmState;

    fn js(names: &[&str], pos: &[f64]) -> JointState {
        JointState {
            name: names.iter().map(|s| s.to_string()).collect(),
            position: pos.to_vec(),
            ..JointState::default()
        }
    }

    #[test]
    fn joints_are_taken_by_name_and_bad_ones_are_refused() {
        let mut names = vec!["alpha_passive"];
        names.extend(ACTUATED_JOINTS.iter().rev());
        let q = actuated_joints(&js(&names, &[9.0, 0.4, 0.3, 0.2, 0.1])).unwrap();
        assert_eq!(q, [0.1, 0.2, 0.3, 0.4]);
        assert!(actuated_joints(&js(&ACTUATED_JOINTS[..3], &[0.0; 3])).is_err());
        assert!(actuated_joints(&js(&ACTUATED_JOINTS, &[0.0, f64::NAN, 0.0, 0.0])).is_err());
        assert!(actuated_joints(&js(&ACTUATED_JOINTS, &[0.0; 3])).is_err());
    }

    #[test]
    fn the_follower_joints_come_back_through_the_calibration() {
        let arm = ArmConfig::shipped().unwrap();
        let mut s = ArmState::default();
        s.joints.base_rad = 0.3;
        s.joints.shoulder_rad = 1.2;
        s.joints.elbow_rad = -0.4;
        s.gripper_opening = 0.5;
        let rad = arm.servos.servo_angles(&s).unwrap().rad;
        let names: Vec<&str> = ServoId::ALL.iter().map(|i| i.name()).collect();
        let q = follower_joints(&js(&names, &rad), &arm).unwrap();
        let want = [0.3, 1.2, -0.4, 0.5 * arm.geometry.gripper_open_rad];
        for (a, b) in q.iter().zip(want) {
            assert!((a - b).abs() < 1e-9, "{q:?} vs {want:?}");
        }
    }

    #[test]
    fn camera_names_come_from_the_topics() {
        assert_eq!(
            camera_name("camera/image_raw/compressed").unwrap(),
            "camera"
        );
        assert_eq!(
            camera_name("/wrist/camera/image_raw").unwrap(),
            "wrist_camera"
        );
        assert_eq!(camera_name("/top/compressed").unwrap(), "top");
        assert!(camera_name("/image_raw/compressed").is_err());
        assert!(camera_name("a b/image_raw").is_err());
        assert!(is_compressed("camera/image_raw/compressed"));
        assert!(!is_compressed("camera/image_raw"));
        let two = ["a/image_raw".to_string(), "/a/compressed".to_string()];
        assert!(cameras(&two).unwrap_err().contains("both"));
    }

    #[test]
    fn images_that_cannot_be_recorded_are_refused() {
        let png = CompressedImage {
            format: "png".into(),
            data: vec![0x89, b'P', b'N', b'G'],
            ..CompressedImage::default()
        };
        assert!(compressed_picture(png).is_err());
        let jpeg = CompressedImage {
            format: "jpeg".into(),
            data: vec![0xFF, 0xD8, 0xFF],
            ..CompressedImage::default()
        };
        assert!(compressed_picture(jpeg).is_ok());
        let short = Image {
            width: 4,
            height: 2,
            encoding: "rgb8".into(),
            step: 12,
            data: vec![0; 23],
            ..Image::default()
        };
        assert!(raw_picture(short).is_err());
        let yuv = Image {
            width: 2,
            height: 1,
            encoding: "yuv422".into(),
            step: 4,
            data: vec![0; 4],
            ..Image::default()
        };
        assert!(raw_picture(yuv).unwrap_err().contains("rgb8"));
    }
}
