//! What the panel shows of the physics twin's scene (docs/twin.md): its cube, read from
//! `tf`, and its camera, read from an image topic (`camera_view`). Both are read with
//! bounded readers of their own instead of the whole message: any DDS peer may publish
//! on `tf` (a TFMessage of thousands of transforms, frame names of megabytes) or on the
//! image topic (an image of a gigabyte), and the panel keeps only what it shows: the
//! transform of the frame `cube` (its names at most [`NAME_MAX`] bytes kept), and an
//! image of at most [`MAX_CAMERA_IMAGE_BYTES`]. Nothing else of a sample is copied.
//!
//! [`CubeView`] and [`CameraView`] are the panel's side, without I/O: the cube's pose to
//! the browsers at most [`CUBE_VIEW_RATE_HZ`] a second and only when it moved, hidden
//! once no cube frame came for [`CUBE_STALE_AFTER`]; the camera's images passed on at
//! most `camera_view_fps` a second while a browser watches, a bigger one than
//! [`MAX_CAMERA_IMAGE_BYTES`] or one that is no JPEG or PNG refused and counted.

use crate::message::ToClient;
use axum::body::Bytes;
use eezybot_msgs::geometry_msgs::{Quaternion, Transform, TransformStamped, Vector3};
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::tf2_msgs::TFMessage;
use eezybot_msgs::Time;
use ros_plumbing::logging::{shorten, Throttle};
use serde::de::{self, DeserializeSeed, Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize, Serializer};
use std::fmt;
use std::time::{Duration, Instant};

/// The twin's cube frame (a child of `base_link`).
pub const CUBE_FRAME: &str = "cube";
/// The longest frame name (or image format) kept; a longer one is read past, not copied.
pub const NAME_MAX: usize = 64;
/// The largest camera image passed on to browsers, bytes; a bigger one is refused
/// (counted, logged) without being copied.
pub const MAX_CAMERA_IMAGE_BYTES: usize = crate::web::MAX_IMAGE_BYTES;
/// How often the browsers get the cube's pose, at most.
pub const CUBE_VIEW_RATE_HZ: f64 = 20.0;
/// No cube frame for this long: the cube is hidden (the twin stopped).
pub const CUBE_STALE_AFTER: Duration = Duration::from_secs(2);
/// A move of the cube smaller than this (m) is no change for the browsers.
pub const CUBE_MOVE_M: f64 = 1e-4;
/// A turn of the cube smaller than this (rad) is no change for the browsers.
pub const CUBE_TURN_RAD: f64 = 2e-3;
/// `camera_view_fps`' default.
pub const CAMERA_VIEW_FPS: f64 = 5.0;

/// A name as read: its text if it is at most [`NAME_MAX`] bytes, else only its length.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Name {
    /// the text
    Kept(String),
    /// longer than [`NAME_MAX`]: this many bytes, not copied
    Long(usize),
}

impl Name {
    /// The text, if kept.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Name::Kept(s) => Some(s),
            Name::Long(_) => None,
        }
    }
}

impl fmt::Display for Name {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Name::Kept(s) => write!(f, "{s}"),
            Name::Long(n) => write!(f, "(a name of {n} bytes)"),
        }
    }
}

/// Reads a string as a [`Name`] (the deserializer lends it: nothing is copied beyond
/// [`NAME_MAX`] bytes).
pub(crate) struct NameSeed;

impl<'de> DeserializeSeed<'de> for NameSeed {
    type Value = Name;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Name, D::Error> {
        d.deserialize_str(self)
    }
}

impl<'de> Visitor<'de> for NameSeed {
    type Value = Name;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a string")
    }
    fn visit_str<E: de::Error>(self, s: &str) -> Result<Name, E> {
        Ok(if s.len() <= NAME_MAX {
            Name::Kept(s.to_string())
        } else {
            Name::Long(s.len())
        })
    }
}

/// Whether a string is exactly `self.0`, read without copying it.
struct IsName(&'static str);

impl<'de> DeserializeSeed<'de> for IsName {
    type Value = bool;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<bool, D::Error> {
        d.deserialize_str(self)
    }
}

impl<'de> Visitor<'de> for IsName {
    type Value = bool;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a string")
    }
    fn visit_str<E: de::Error>(self, s: &str) -> Result<bool, E> {
        Ok(s == self.0)
    }
}

/// A `std_msgs/Header` as its stamp and its frame as a [`Name`].
pub(crate) struct HeaderSeed;

impl<'de> DeserializeSeed<'de> for HeaderSeed {
    type Value = (Time, Name);
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_struct("Header", &["stamp", "frame_id"], self)
    }
}

impl<'de> Visitor<'de> for HeaderSeed {
    type Value = (Time, Name);
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a std_msgs/Header")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let stamp: Time = next(&mut seq, 0)?;
        let frame = seq
            .next_element_seed(NameSeed)?
            .ok_or_else(|| de::Error::invalid_length(1, &self))?;
        Ok((stamp, frame))
    }
}

fn next<'de, T: Deserialize<'de>, A: SeqAccess<'de>>(
    seq: &mut A,
    at: usize,
) -> Result<T, A::Error> {
    seq.next_element()?
        .ok_or_else(|| de::Error::invalid_length(at, &"more fields"))
}

/// The cube's transform, as read from `tf`.
#[derive(Clone, Debug, PartialEq)]
pub struct CubeTransform {
    /// the header's stamp
    pub stamp: Time,
    /// the parent frame (`base_link` from the twin)
    pub parent: Name,
    /// the cube's pose in the parent frame
    pub transform: Transform,
}

/// A `tf2_msgs/TFMessage` as the panel reads it: the transform of [`CUBE_FRAME`] (the
/// last, if the message has several), and how many transforms the message had. The
/// other transforms are read past: their frame names are not copied.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CubeTf {
    /// the cube's transform, if the message has one
    pub cube: Option<CubeTransform>,
    /// the message's transforms, the cube's included
    pub transforms: usize,
}

impl eezybot_msgs::RosMessage for CubeTf {
    const PACKAGE: &'static str = "tf2_msgs";
    const NAME: &'static str = "TFMessage";
}
impl ros2_client::Message for CubeTf {}

impl Serialize for CubeTf {
    /// As a TFMessage with the cube's transform only (the panel never publishes one;
    /// a message type must be both ways).
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let transforms = self
            .cube
            .iter()
            .map(|c| TransformStamped {
                header: Header {
                    stamp: c.stamp,
                    frame_id: c.parent.as_str().unwrap_or_default().to_string(),
                },
                child_frame_id: CUBE_FRAME.into(),
                transform: c.transform,
            })
            .collect();
        TFMessage { transforms }.serialize(s)
    }
}

impl<'de> Deserialize<'de> for CubeTf {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<CubeTf, D::Error> {
        d.deserialize_struct("TFMessage", &["transforms"], TfVisitor)
    }
}

struct TfVisitor;

impl<'de> Visitor<'de> for TfVisitor {
    type Value = CubeTf;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a tf2_msgs/TFMessage")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<CubeTf, A::Error> {
        seq.next_element_seed(TransformsSeed)?
            .ok_or_else(|| de::Error::invalid_length(0, &self))
    }
}

struct TransformsSeed;

impl<'de> DeserializeSeed<'de> for TransformsSeed {
    type Value = CubeTf;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<CubeTf, D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for TransformsSeed {
    type Value = CubeTf;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence of geometry_msgs/TransformStamped")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<CubeTf, A::Error> {
        let mut tf = CubeTf::default();
        while let Some(cube) = seq.next_element_seed(TransformSeed)? {
            tf.transforms += 1;
            if cube.is_some() {
                tf.cube = cube;
            }
        }
        Ok(tf)
    }
}

/// One `TransformStamped`: the cube's, or `None` for any other frame.
struct TransformSeed;

impl<'de> DeserializeSeed<'de> for TransformSeed {
    type Value = Option<CubeTransform>;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_struct(
            "TransformStamped",
            &["header", "child_frame_id", "transform"],
            self,
        )
    }
}

impl<'de> Visitor<'de> for TransformSeed {
    type Value = Option<CubeTransform>;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a geometry_msgs/TransformStamped")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let (stamp, parent) = seq
            .next_element_seed(HeaderSeed)?
            .ok_or_else(|| de::Error::invalid_length(0, &self))?;
        let is_cube = seq
            .next_element_seed(IsName(CUBE_FRAME))?
            .ok_or_else(|| de::Error::invalid_length(1, &self))?;
        let transform: Transform = next(&mut seq, 2)?;
        Ok(is_cube.then_some(CubeTransform {
            stamp,
            parent,
            transform,
        }))
    }
}

/// An image's bytes as read: kept when at most [`MAX_CAMERA_IMAGE_BYTES`], else only
/// their count.
#[derive(Clone, Debug, PartialEq)]
pub enum ImageData {
    /// the image file's bytes
    Kept(Bytes),
    /// more than [`MAX_CAMERA_IMAGE_BYTES`]: this many, not copied
    TooBig(usize),
}

/// A `sensor_msgs/CompressedImage` as the panel reads it: the stamp, the format (as a
/// [`Name`]) and the data, kept only up to [`MAX_CAMERA_IMAGE_BYTES`].
#[derive(Clone, Debug, PartialEq)]
pub struct CameraImage {
    /// acquisition time
    pub stamp: Time,
    /// `jpeg`, `png`, …
    pub format: Name,
    /// the image file
    pub data: ImageData,
}

impl eezybot_msgs::RosMessage for CameraImage {
    const PACKAGE: &'static str = "sensor_msgs";
    const NAME: &'static str = "CompressedImage";
}
impl ros2_client::Message for CameraImage {}

impl Serialize for CameraImage {
    /// As a CompressedImage (an image over the limit with no data).
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        eezybot_msgs::sensor_msgs::CompressedImage {
            header: Header {
                stamp: self.stamp,
                frame_id: String::new(),
            },
            format: self.format.as_str().unwrap_or_default().to_string(),
            data: match &self.data {
                ImageData::Kept(b) => b.to_vec(),
                ImageData::TooBig(_) => vec![],
            },
        }
        .serialize(s)
    }
}

impl<'de> Deserialize<'de> for CameraImage {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<CameraImage, D::Error> {
        d.deserialize_struct(
            "CompressedImage",
            &["header", "format", "data"],
            ImageVisitor,
        )
    }
}

struct ImageVisitor;

impl<'de> Visitor<'de> for ImageVisitor {
    type Value = CameraImage;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sensor_msgs/CompressedImage")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<CameraImage, A::Error> {
        let (stamp, _frame) = seq
            .next_element_seed(HeaderSeed)?
            .ok_or_else(|| de::Error::invalid_length(0, &self))?;
        let format = seq
            .next_element_seed(NameSeed)?
            .ok_or_else(|| de::Error::invalid_length(1, &self))?;
        let data = seq
            .next_element_seed(DataSeed)?
            .ok_or_else(|| de::Error::invalid_length(2, &self))?;
        Ok(CameraImage {
            stamp,
            format,
            data,
        })
    }
}

/// A `uint8[]` read as bytes (in CDR the same layout: a length, then the bytes), copied
/// only when small enough.
struct DataSeed;

impl<'de> DeserializeSeed<'de> for DataSeed {
    type Value = ImageData;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<ImageData, D::Error> {
        d.deserialize_bytes(self)
    }
}

impl<'de> Visitor<'de> for DataSeed {
    type Value = ImageData;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("bytes")
    }
    fn visit_bytes<E: de::Error>(self, b: &[u8]) -> Result<ImageData, E> {
        Ok(if b.len() <= MAX_CAMERA_IMAGE_BYTES {
            ImageData::Kept(Bytes::copy_from_slice(b))
        } else {
            ImageData::TooBig(b.len())
        })
    }
    /// A deserializer that hands the bytes one by one (not CDR): read past those over
    /// the limit.
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<ImageData, A::Error> {
        let mut kept = Vec::new();
        let mut n = 0usize;
        while let Some(b) = seq.next_element::<u8>()? {
            if n < MAX_CAMERA_IMAGE_BYTES {
                kept.push(b);
            }
            n += 1;
        }
        Ok(if n <= MAX_CAMERA_IMAGE_BYTES {
            ImageData::Kept(kept.into())
        } else {
            ImageData::TooBig(n)
        })
    }
}

/// The cube as the browsers see it: its pose sent on change, at most
/// [`CUBE_VIEW_RATE_HZ`] a second; hidden once no cube frame came for
/// [`CUBE_STALE_AFTER`]. Only a cube in `base_frame` (the 3D view's root) is shown.
#[derive(Debug)]
pub struct CubeView {
    base_frame: String,
    /// the latest cube heard, and when
    latest: Option<(Transform, Instant)>,
    /// what the browsers were last told (None: no cube)
    shown: Option<Transform>,
    sent_at: Option<Instant>,
    /// transforms of the cube in another frame than `base_frame`, ignored
    other_parent: u64,
    last_other_parent: Option<String>,
    complaints: Throttle,
}

impl CubeView {
    /// The view of a cube in `base_frame`.
    pub fn new(base_frame: &str) -> CubeView {
        CubeView {
            base_frame: base_frame.to_string(),
            latest: None,
            shown: None,
            sent_at: None,
            other_parent: 0,
            last_other_parent: None,
            complaints: Throttle::default(),
        }
    }

    /// The message for the browsers now (also what one that connects gets).
    pub fn message(&self) -> ToClient {
        ToClient::cube(self.shown.as_ref())
    }

    /// A `tf` message: its cube (if any) becomes the latest; to the browsers if it
    /// moved and the rate allows. Returns the message to send, and a log line.
    pub fn on_tf(
        &mut self,
        tf: CubeTf,
        now: Instant,
    ) -> (Option<ToClient>, Option<(log::Level, String)>) {
        let Some(cube) = tf.cube else {
            return (None, None);
        };
        if cube.parent.as_str() != Some(self.base_frame.as_str()) {
            self.other_parent += 1;
            let text = shorten(&cube.parent.to_string(), crate::web::REASON_MAX).into_owned();
            self.last_other_parent = Some(text.clone());
            let log = self.complaints.allow("parent", now).map(|quiet| {
                (
                    log::Level::Warn,
                    format!(
                        "tf: the frame `{CUBE_FRAME}` in `{text}`, not in `{}`, is not shown{}",
                        self.base_frame,
                        Throttle::suffix(quiet)
                    ),
                )
            });
            return (None, log);
        }
        let t = cube.transform;
        let finite = [
            t.translation.x,
            t.translation.y,
            t.translation.z,
            t.rotation.x,
            t.rotation.y,
            t.rotation.z,
            t.rotation.w,
        ]
        .iter()
        .all(|v| v.is_finite());
        if !finite {
            self.other_parent += 1;
            self.last_other_parent = Some("a pose that is not finite".into());
            return (None, None);
        }
        self.latest = Some((t, now));
        (self.due(now), None)
    }

    /// Time passed: a held-back move goes out, a cube not heard for
    /// [`CUBE_STALE_AFTER`] is hidden.
    pub fn on_tick(&mut self, now: Instant) -> Option<ToClient> {
        if let Some((_, at)) = self.latest {
            if now.saturating_duration_since(at) >= CUBE_STALE_AFTER {
                self.latest = None;
            }
        }
        if self.latest.is_none() {
            return self.shown.take().map(|_| ToClient::cube(None));
        }
        self.due(now)
    }

    /// The latest pose, if it differs from the one shown and the rate allows.
    fn due(&mut self, now: Instant) -> Option<ToClient> {
        let (t, _) = self.latest?;
        if self.shown.is_some_and(|s| !moved(&s, &t)) {
            return None;
        }
        let period = Duration::from_secs_f64(1.0 / CUBE_VIEW_RATE_HZ);
        if self
            .sent_at
            .is_some_and(|at| now.saturating_duration_since(at) < period)
        {
            return None;
        }
        self.sent_at = Some(now);
        self.shown = Some(t);
        Some(ToClient::cube(Some(&t)))
    }

    /// Whether a held-back change waits for the next tick.
    pub fn pending(&self) -> bool {
        match (&self.latest, &self.shown) {
            (Some((t, _)), Some(s)) => moved(s, t),
            (Some(_), None) => true,
            (None, _) => false,
        }
    }

    /// Its `diagnostics` values.
    pub fn values(&self) -> Vec<(&'static str, String)> {
        let cube = match &self.shown {
            Some(t) => format!(
                "{:.4}, {:.4}, {:.4}",
                t.translation.x, t.translation.y, t.translation.z
            ),
            None => "none".into(),
        };
        vec![
            ("cube", cube),
            ("cube_ignored", self.other_parent.to_string()),
            (
                "last_cube_ignored",
                self.last_other_parent.clone().unwrap_or_default(),
            ),
        ]
    }
}

fn moved(a: &Transform, b: &Transform) -> bool {
    let d = |u: &Vector3, v: &Vector3| {
        ((u.x - v.x).powi(2) + (u.y - v.y).powi(2) + (u.z - v.z).powi(2)).sqrt()
    };
    let dot =
        |p: &Quaternion, q: &Quaternion| (p.x * q.x + p.y * q.y + p.z * q.z + p.w * q.w).abs();
    // the angle between two unit quaternions: 2 acos |p·q| (p and −p are one turn)
    let turn = 2.0 * dot(&a.rotation, &b.rotation).clamp(0.0, 1.0).acos();
    d(&a.translation, &b.translation) > CUBE_MOVE_M || turn > CUBE_TURN_RAD
}

/// What became of a camera image.
#[derive(Clone, Debug, PartialEq)]
pub enum CameraOutcome {
    /// passed on to the browsers
    Forward(Bytes),
    /// dropped: too soon after the last one, or no browser watches
    Skipped,
    /// refused (not shown, counted): why
    Refused(String),
}

/// The camera view: images of `camera_view` to the browsers, at most `fps` a second,
/// only while a browser is connected; an image over [`MAX_CAMERA_IMAGE_BYTES`] or not a
/// JPEG or PNG refused with a counted reason.
#[derive(Debug)]
pub struct CameraView {
    period: Duration,
    sent_at: Option<Instant>,
    received: u64,
    forwarded: u64,
    refused: u64,
    last_refusal: Option<String>,
    complaints: Throttle,
}

impl CameraView {
    /// A view passing on at most `fps` images a second.
    pub fn new(fps: f64) -> CameraView {
        let fps = if fps.is_finite() && fps > 0.0 {
            fps
        } else {
            CAMERA_VIEW_FPS
        };
        CameraView {
            period: Duration::from_secs_f64(1.0 / fps),
            sent_at: None,
            received: 0,
            forwarded: 0,
            refused: 0,
            last_refusal: None,
            complaints: Throttle::default(),
        }
    }

    /// An image came, with `watchers` browsers connected. Returns the outcome and a
    /// log line for a refusal (the first at once, then at most one per 5 s).
    pub fn on_image(
        &mut self,
        image: CameraImage,
        watchers: u64,
        now: Instant,
    ) -> (CameraOutcome, Option<(log::Level, String)>) {
        self.received += 1;
        let refusal = match &image.data {
            ImageData::TooBig(n) => Some(format!(
                "an image of {n} bytes is over the camera view's {MAX_CAMERA_IMAGE_BYTES} bytes"
            )),
            ImageData::Kept(b) if image_kind(b).is_none() => Some(format!(
                "an image of format `{}` is no JPEG or PNG",
                image.format
            )),
            ImageData::Kept(_) => None,
        };
        if let Some(reason) = refusal {
            self.refused += 1;
            self.last_refusal = Some(reason.clone());
            let log = self.complaints.allow("camera", now).map(|quiet| {
                (
                    log::Level::Warn,
                    format!(
                        "camera view: {reason}: not shown{}",
                        Throttle::suffix(quiet)
                    ),
                )
            });
            return (CameraOutcome::Refused(reason), log);
        }
        let ImageData::Kept(bytes) = image.data else {
            return (CameraOutcome::Skipped, None);
        };
        if watchers == 0
            || self
                .sent_at
                .is_some_and(|at| now.saturating_duration_since(at) < self.period)
        {
            return (CameraOutcome::Skipped, None);
        }
        self.sent_at = Some(now);
        self.forwarded += 1;
        (CameraOutcome::Forward(bytes), None)
    }

    /// Its `diagnostics` values.
    pub fn values(&self) -> Vec<(&'static str, String)> {
        vec![
            ("camera_images", self.received.to_string()),
            ("camera_images_shown", self.forwarded.to_string()),
            ("camera_images_refused", self.refused.to_string()),
            (
                "last_camera_refusal",
                self.last_refusal.clone().unwrap_or_default(),
            ),
        ]
    }
}

/// `image/jpeg` or `image/png` by the file's first bytes, or None.
pub fn image_kind(data: &[u8]) -> Option<&'static str> {
    if data.starts_with(&[0xFF, 0xD8, 0xFF]) {
        Some("image/jpeg")
    } else if data.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some("image/png")
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_msgs::sensor_msgs::CompressedImage;

    fn ts(parent: &str, child: &str, x: f64) -> TransformStamped {
        TransformStamped {
            header: Header {
                stamp: Time::from_nanos(5),
                frame_id: parent.into(),
            },
            child_frame_id: child.into(),
            transform: Transform {
                translation: Vector3 {
                    x,
                    y: 0.0,
                    z: 0.0675,
                },
                rotation: Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                    w: 1.0,
                },
            },
        }
    }

    fn read(msg: &TFMessage) -> CubeTf {
        eezybot_msgs::cdr::decode(&eezybot_msgs::cdr::encode(msg).unwrap()).unwrap()
    }

    #[test]
    fn the_cube_is_found_among_other_frames_and_the_rest_is_read_past() {
        let msg = TFMessage {
            transforms: vec![
                ts("base_link", "base_rot", 9.0),
                ts("base_link", "cube", 0.2),
                ts("base_rot", "main_arm", 9.0),
            ],
        };
        let tf = read(&msg);
        assert_eq!(tf.transforms, 3);
        let cube = tf.cube.clone().unwrap();
        assert_eq!(cube.parent, Name::Kept("base_link".into()));
        assert_eq!(cube.transform.translation.x, 0.2);
        assert_eq!(cube.stamp, Time::from_nanos(5));
        // the arm's frames alone: no cube
        let arm = TFMessage {
            transforms: vec![ts("base_link", "base_rot", 1.0)],
        };
        assert_eq!(read(&arm).cube, None);
        // and back as a TFMessage
        let again: TFMessage =
            eezybot_msgs::cdr::decode(&eezybot_msgs::cdr::encode(&tf).unwrap()).unwrap();
        assert_eq!(again.transforms, vec![ts("base_link", "cube", 0.2)]);
    }

    #[test]
    fn thousands_of_transforms_and_huge_names_are_read_without_keeping_them() {
        let huge = "x".repeat(1 << 20);
        let mut transforms: Vec<_> = (0..5000)
            .map(|i| ts("base_link", &format!("f{i}"), 1.0))
            .collect();
        transforms.push(ts(&huge, &huge, 1.0));
        transforms.push(ts(&huge, "cube", 0.1));
        let tf = read(&TFMessage { transforms });
        assert_eq!(tf.transforms, 5002);
        assert_eq!(tf.cube.unwrap().parent, Name::Long(1 << 20));
        // a truncated message is an error, never a panic
        let bytes = eezybot_msgs::cdr::encode(&TFMessage {
            transforms: vec![ts("base_link", "cube", 0.1)],
        })
        .unwrap();
        for cut in 4..bytes.len() {
            let _ = eezybot_msgs::cdr::decode::<CubeTf>(&bytes[..cut]);
        }
    }

    fn image(data: Vec<u8>, format: &str) -> CameraImage {
        let msg = CompressedImage {
            header: Header::default(),
            format: format.into(),
            data,
        };
        eezybot_msgs::cdr::decode(&eezybot_msgs::cdr::encode(&msg).unwrap()).unwrap()
    }

    #[test]
    fn an_image_is_kept_up_to_the_limit_and_counted_beyond() {
        let jpeg = [vec![0xFF, 0xD8, 0xFF, 0xE0], vec![7; 100]].concat();
        let read = image(jpeg.clone(), "jpeg");
        assert_eq!(read.format, Name::Kept("jpeg".into()));
        assert_eq!(read.data, ImageData::Kept(Bytes::from(jpeg)));
        let big = image(vec![0xFF; MAX_CAMERA_IMAGE_BYTES + 1], "jpeg");
        assert_eq!(big.data, ImageData::TooBig(MAX_CAMERA_IMAGE_BYTES + 1));
    }

    #[test]
    fn the_camera_view_throttles_refuses_and_waits_for_a_browser() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let jpeg = || image([vec![0xFF, 0xD8, 0xFF, 0xE0], vec![1; 10]].concat(), "jpeg");
        let mut view = CameraView::new(5.0);
        assert_eq!(view.on_image(jpeg(), 0, ms(0)).0, CameraOutcome::Skipped);
        assert!(matches!(
            view.on_image(jpeg(), 1, ms(10)).0,
            CameraOutcome::Forward(_)
        ));
        assert_eq!(view.on_image(jpeg(), 1, ms(100)).0, CameraOutcome::Skipped);
        assert!(matches!(
            view.on_image(jpeg(), 2, ms(210)).0,
            CameraOutcome::Forward(_)
        ));
        let (out, log) = view.on_image(
            image(vec![0; MAX_CAMERA_IMAGE_BYTES + 5], "jpeg"),
            1,
            ms(900),
        );
        assert!(matches!(out, CameraOutcome::Refused(r) if r.contains("over")));
        assert!(log.is_some());
        let (out, _) = view.on_image(image(b"GIF89a".to_vec(), "gif"), 1, ms(1000));
        assert!(matches!(out, CameraOutcome::Refused(r) if r.contains("`gif`")));
        let values = view.values();
        assert!(values.contains(&("camera_images", "6".into())));
        assert!(values.contains(&("camera_images_shown", "2".into())));
        assert!(values.contains(&("camera_images_refused", "2".into())));
    }

    fn cube_tf(parent: &str, x: f64) -> CubeTf {
        read(&TFMessage {
            transforms: vec![ts(parent, "cube", x)],
        })
    }

    #[test]
    fn the_cube_goes_out_on_change_at_a_bounded_rate_and_hides_when_silent() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut view = CubeView::new("base_link");
        assert_eq!(view.message(), ToClient::cube(None));
        let (sent, _) = view.on_tf(cube_tf("base_link", 0.2), ms(0));
        assert!(matches!(sent, Some(ToClient::Cube { p: Some(p), .. }) if p[0] == 0.2));
        // the same pose again: nothing; a move within the period: held back
        assert_eq!(view.on_tf(cube_tf("base_link", 0.2), ms(10)).0, None);
        assert_eq!(view.on_tf(cube_tf("base_link", 0.21), ms(20)).0, None);
        assert!(view.pending());
        let held = view.on_tick(ms(60));
        assert!(matches!(held, Some(ToClient::Cube { p: Some(p), .. }) if p[0] == 0.21));
        assert!(!view.pending());
        // another frame's cube is ignored, counted
        let (sent, log) = view.on_tf(cube_tf("world", 0.5), ms(100));
        assert_eq!(sent, None);
        assert!(log.is_some());
        assert!(view.values().contains(&("cube_ignored", "1".into())));
        // silent: hidden once, after CUBE_STALE_AFTER
        assert_eq!(view.on_tick(ms(1900)), None);
        assert_eq!(view.on_tick(ms(2100)), Some(ToClient::cube(None)));
        assert_eq!(view.on_tick(ms(2600)), None);
        assert_eq!(view.message(), ToClient::cube(None));
    }
}
