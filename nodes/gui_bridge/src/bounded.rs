//! Bounded readers of the inputs whose content the panel passes to the browsers:
//! `robot_description` (the joint sliders, the 3D view, `/robot.urdf`) and the joint
//! states (`joint_states` for the live view, `leader/joint_states` shown beside it). Any
//! DDS peer may publish on them. Issue 36: a latched URDF of 16,000 joints held the
//! node's event loop for 12 s (the URDF model's checks are quadratic in the links) and
//! made every panel's first message 0.7 MB, for as long as it stayed latched; 30,000-name
//! `leader/joint_states` messages became a megabyte to every browser 20 times a second,
//! dropped the clients and took the node to 0.55–0.95 GB.
//!
//! So each sample is read here, as scene.rs reads `tf` and the camera: a description of
//! more than [`MAX_DESCRIPTION_BYTES`] or with more than [`MAX_JOINTS`] `<joint>`
//! elements, a joint state of more than [`MAX_JOINTS`] names or with a name over
//! [`NAME_MAX`] bytes, is refused as it is read, without being copied (the deserializer
//! lends the text), and becomes [`crate::Input::Refused`] with the reason:
//! `robot_description refused: 16000 joints > 256`. [`RefusedInputs`] keeps what is
//! refused now, for the page (a banner), the log (throttled) and `diagnostics`.

use crate::message::InputRefusal;
use crate::scene::{HeaderSeed, Name, NameSeed};
use crate::Input;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use ros_plumbing::logging::{shorten, Throttle};
use serde::de::{self, DeserializeSeed, Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize, Serializer};
use std::collections::BTreeMap;
use std::fmt;
use std::time::Instant;

pub use crate::scene::NAME_MAX;

/// The largest `robot_description` taken, bytes (a real robot's URDF, the PR2's
/// expanded from xacro, is about 400 KB; the EezyBot's 12 KB).
pub const MAX_DESCRIPTION_BYTES: usize = 1024 * 1024;
/// The most joints a `robot_description` may have, and the most names a joint state may
/// carry. With as many, the panel's first message stays under 100 KB and its `pose`
/// messages under 64 KB.
pub const MAX_JOINTS: usize = 256;

/// A `std_msgs/String` on `robot_description` as the panel reads it: its size, how many
/// `<joint` elements it has, and its text only when both are within the limits.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Description {
    /// the URDF, when within [`MAX_DESCRIPTION_BYTES`] and [`MAX_JOINTS`]
    pub text: Option<String>,
    /// its length in bytes
    pub bytes: usize,
    /// its `<joint …>` elements
    pub joints: usize,
}

impl Description {
    /// Read `text` as a sample would be.
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::bounded::Description;
    /// let d = Description::read("<robot name='r'><joint name='a'/><joint_x/></robot>");
    /// assert_eq!((d.joints, d.text.is_some()), (1, true));
    /// assert_eq!(d.refusal(), None);
    /// let big = "<joint/>".repeat(300);
    /// assert_eq!(Description::read(&big).refusal().as_deref(), Some("300 joints > 256"));
    /// ```
    pub fn read(text: &str) -> Description {
        let joints = joint_elements(text);
        let kept = text.len() <= MAX_DESCRIPTION_BYTES && joints <= MAX_JOINTS;
        Description {
            text: kept.then(|| text.to_string()),
            bytes: text.len(),
            joints,
        }
    }

    /// The panel's input: the URDF, or its refusal.
    pub fn into_input(self) -> Input {
        let topic = ros_plumbing::topics::ROBOT_DESCRIPTION.name;
        match (self.refusal(), self.text) {
            (None, Some(text)) => Input::RobotDescription(text),
            (reason, _) => Input::Refused {
                topic,
                reason: reason.unwrap_or_default(),
            },
        }
    }

    /// Why it is refused (None: taken).
    pub fn refusal(&self) -> Option<String> {
        if self.joints > MAX_JOINTS {
            Some(format!("{} joints > {MAX_JOINTS}", self.joints))
        } else if self.bytes > MAX_DESCRIPTION_BYTES {
            Some(format!("{} bytes > {MAX_DESCRIPTION_BYTES}", self.bytes))
        } else {
            None
        }
    }
}

/// The `<joint` elements of a URDF (`<joint ` … `>`, `<joint>`, `<joint/>`; not
/// `<joint_state…`): a count without parsing, in one pass.
fn joint_elements(text: &str) -> usize {
    text.match_indices("<joint")
        .filter(|(at, m)| {
            text.as_bytes()
                .get(at + m.len())
                .is_some_and(|b| b.is_ascii_whitespace() || matches!(b, b'>' | b'/'))
        })
        .count()
}

impl eezybot_msgs::RosMessage for Description {
    const PACKAGE: &'static str = "std_msgs";
    const NAME: &'static str = "String";
}
impl ros2_client::Message for Description {}

impl Serialize for Description {
    /// As a `std_msgs/String` (a refused one empty; the panel never publishes one).
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        eezybot_msgs::std_msgs::String {
            data: self.text.clone().unwrap_or_default(),
        }
        .serialize(s)
    }
}

impl<'de> Deserialize<'de> for Description {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Description, D::Error> {
        d.deserialize_struct("String", &["data"], DescriptionVisitor)
    }
}

struct DescriptionVisitor;

impl<'de> Visitor<'de> for DescriptionVisitor {
    type Value = Description;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a std_msgs/String")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Description, A::Error> {
        seq.next_element_seed(DescriptionSeed)?
            .ok_or_else(|| de::Error::invalid_length(0, &self))
    }
}

/// The string itself, lent by the deserializer: copied only when taken.
struct DescriptionSeed;

impl<'de> DeserializeSeed<'de> for DescriptionSeed {
    type Value = Description;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Description, D::Error> {
        d.deserialize_str(self)
    }
}

impl<'de> Visitor<'de> for DescriptionSeed {
    type Value = Description;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a string")
    }
    fn visit_str<E: de::Error>(self, s: &str) -> Result<Description, E> {
        Ok(Description::read(s))
    }
}

/// A `sensor_msgs/JointState` as the panel reads it: its stamp, and its names and
/// positions, at most [`MAX_JOINTS`] of each; the velocities and efforts are read past.
#[derive(Clone, Debug, PartialEq)]
pub struct Joints {
    /// the header's stamp
    pub stamp: Time,
    /// the first [`MAX_JOINTS`] names (a name over [`NAME_MAX`] bytes is not kept)
    pub names: Vec<String>,
    /// the first [`MAX_JOINTS`] positions
    pub positions: Vec<f64>,
    /// how many names the message has
    pub count: usize,
    /// the length of the first name over [`NAME_MAX`] bytes, if any
    pub long_name: Option<usize>,
}

impl Joints {
    /// Why it is refused (None: taken).
    pub fn refusal(&self) -> Option<String> {
        if self.count > MAX_JOINTS {
            Some(format!("{} names > {MAX_JOINTS}", self.count))
        } else {
            self.long_name
                .map(|n| format!("a joint name of {n} bytes > {NAME_MAX}"))
        }
    }

    /// The panel's input from `topic`: `taken` of the message, or its refusal.
    pub fn into_input(self, topic: &'static str, taken: fn(JointState) -> Input) -> Input {
        match self.refusal() {
            Some(reason) => Input::Refused { topic, reason },
            None => taken(self.into_joint_state()),
        }
    }

    /// The message with its names and positions (no velocities or efforts: the panel
    /// shows none).
    pub fn into_joint_state(self) -> JointState {
        JointState {
            header: Header {
                stamp: self.stamp,
                frame_id: String::new(),
            },
            name: self.names,
            position: self.positions,
            velocity: vec![],
            effort: vec![],
        }
    }
}

impl eezybot_msgs::RosMessage for Joints {
    const PACKAGE: &'static str = "sensor_msgs";
    const NAME: &'static str = "JointState";
}
impl ros2_client::Message for Joints {}

impl Serialize for Joints {
    /// As a `JointState` with what was kept (the panel never publishes one).
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.clone().into_joint_state().serialize(s)
    }
}

impl<'de> Deserialize<'de> for Joints {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Joints, D::Error> {
        d.deserialize_struct(
            "JointState",
            &["header", "name", "position", "velocity", "effort"],
            JointsVisitor,
        )
    }
}

struct JointsVisitor;

impl<'de> Visitor<'de> for JointsVisitor {
    type Value = Joints;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sensor_msgs/JointState")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Joints, A::Error> {
        let missing = |at| de::Error::invalid_length(at, &"five fields");
        let (stamp, _frame) = seq
            .next_element_seed(HeaderSeed)?
            .ok_or_else(|| missing(0))?;
        let (names, count, long_name) = seq
            .next_element_seed(NamesSeed)?
            .ok_or_else(|| missing(1))?;
        let (positions, _) = seq
            .next_element_seed(FloatsSeed(MAX_JOINTS))?
            .ok_or_else(|| missing(2))?;
        for at in [3, 4] {
            seq.next_element_seed(FloatsSeed(0))?
                .ok_or_else(|| missing(at))?;
        }
        Ok(Joints {
            stamp,
            names,
            positions,
            count,
            long_name,
        })
    }
}

/// A `string[]`: the first [`MAX_JOINTS`] names kept, all counted, the first one over
/// [`NAME_MAX`] bytes noted.
struct NamesSeed;

impl<'de> DeserializeSeed<'de> for NamesSeed {
    type Value = (Vec<String>, usize, Option<usize>);
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for NamesSeed {
    type Value = (Vec<String>, usize, Option<usize>);
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence of strings")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let (mut kept, mut count, mut long) = (Vec::new(), 0usize, None);
        while let Some(name) = seq.next_element_seed(NameSeed)? {
            match name {
                Name::Kept(s) if kept.len() < MAX_JOINTS => kept.push(s),
                Name::Kept(_) => {}
                Name::Long(n) => {
                    long.get_or_insert(n);
                }
            }
            count += 1;
        }
        Ok((kept, count, long))
    }
}

/// A `float64[]`: the first `.0` values kept, all counted.
struct FloatsSeed(usize);

impl<'de> DeserializeSeed<'de> for FloatsSeed {
    type Value = (Vec<f64>, usize);
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for FloatsSeed {
    type Value = (Vec<f64>, usize);
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence of float64")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let (mut kept, mut count) = (Vec::new(), 0usize);
        while let Some(v) = seq.next_element::<f64>()? {
            if kept.len() < self.0 {
                kept.push(v);
            }
            count += 1;
        }
        Ok((kept, count))
    }
}

/// The inputs refused: what is refused now, per topic (cleared when the topic's next
/// sample is taken), for the page; counted and named for `diagnostics`; logged at most
/// once per topic per [`Throttle::PERIOD`].
#[derive(Debug, Default)]
pub struct RefusedInputs {
    count: u64,
    now: BTreeMap<&'static str, String>,
    last: Option<(Instant, String)>,
    complaints: Throttle,
}

impl RefusedInputs {
    /// A sample of `topic` refused for `reason` at `now`: whether what the page shows
    /// changed, and the line to log (if any).
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::bounded::RefusedInputs;
    /// let (mut r, t) = (RefusedInputs::default(), std::time::Instant::now());
    /// let (changed, line) = r.refused("robot_description", "16000 joints > 256", t);
    /// assert!(changed && line.unwrap().1.contains("robot_description refused: 16000 joints > 256"));
    /// assert_eq!(r.refused("robot_description", "16000 joints > 256", t), (false, None));
    /// assert!(r.taken("robot_description") && r.view().is_empty());
    /// ```
    pub fn refused(
        &mut self,
        topic: &'static str,
        reason: &str,
        now: Instant,
    ) -> (bool, Option<(log::Level, String)>) {
        self.count += 1;
        let reason = shorten(reason, crate::web::REASON_MAX).into_owned();
        self.last = Some((now, format!("{topic}: {reason}")));
        let changed = self.now.get(topic) != Some(&reason);
        if changed {
            self.now.insert(topic, reason.clone());
        }
        let line = self.complaints.allow(topic, now).map(|quiet| {
            (
                log::Level::Warn,
                format!(
                    "{topic} refused: {reason}; the panel keeps what it had{}",
                    Throttle::suffix(quiet)
                ),
            )
        });
        (changed, line)
    }

    /// A sample of `topic` was taken: whether what the page shows changed (a refusal of
    /// it is over).
    pub fn taken(&mut self, topic: &str) -> bool {
        self.now.remove(topic).is_some()
    }

    /// What is refused now, for the page.
    pub fn view(&self) -> Vec<InputRefusal> {
        self.now
            .iter()
            .map(|(topic, reason)| InputRefusal {
                topic,
                reason: reason.clone(),
            })
            .collect()
    }

    /// The latest refusal and when.
    pub fn last(&self) -> Option<&(Instant, String)> {
        self.last.as_ref()
    }

    /// Its `diagnostics` values.
    pub fn values(&self) -> [(&'static str, String); 2] {
        [
            ("inputs_refused", self.count.to_string()),
            (
                "last_input_refused",
                self.last
                    .as_ref()
                    .map(|(_, t)| t.clone())
                    .unwrap_or_default(),
            ),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_msgs::std_msgs::String as RosString;

    fn chain(joints: usize) -> String {
        let links: String = (0..=joints)
            .map(|i| format!("<link name='l{i}'/>"))
            .collect();
        let js: String = (0..joints)
            .map(|i| {
                format!("<joint name='j{i}' type='revolute'>\n<parent link='l{i}'/><child link='l{}'/></joint>", i + 1)
            })
            .collect();
        format!("<robot name='r'>{links}{js}</robot>")
    }

    #[test]
    fn a_description_within_the_limits_is_taken_whole() {
        let text = chain(MAX_JOINTS);
        let cdr = eezybot_msgs::cdr::encode(&RosString { data: text.clone() }).unwrap();
        let d: Description = eezybot_msgs::cdr::decode(&cdr).unwrap();
        assert_eq!(d.text.as_deref(), Some(text.as_str()));
        assert_eq!((d.joints, d.refusal()), (MAX_JOINTS, None));
    }

    #[test]
    fn a_description_over_the_limits_is_refused_and_not_kept() {
        let text = chain(16_000);
        let cdr = eezybot_msgs::cdr::encode(&RosString { data: text }).unwrap();
        let d: Description = eezybot_msgs::cdr::decode(&cdr).unwrap();
        assert_eq!(d.text, None);
        assert_eq!(d.refusal().as_deref(), Some("16000 joints > 256"));
        let long = format!(
            "<robot name='r'><!-- {} --></robot>",
            "x".repeat(MAX_DESCRIPTION_BYTES)
        );
        let d = Description::read(&long);
        assert_eq!(d.text, None);
        assert_eq!(
            d.refusal(),
            Some(format!("{} bytes > {MAX_DESCRIPTION_BYTES}", long.len()))
        );
    }

    fn joint_state(names: usize, name_len: usize) -> Vec<u8> {
        let name: Vec<String> = (0..names)
            .map(|i| format!("{i:0>width$}", width = name_len))
            .collect();
        let js = JointState {
            header: Header {
                stamp: Time::new(7, 9),
                frame_id: "base".into(),
            },
            position: (0..names).map(|i| i as f64).collect(),
            velocity: vec![1.0; names],
            effort: vec![2.0; names],
            name,
        };
        eezybot_msgs::cdr::encode(&js).unwrap()
    }

    #[test]
    fn joint_states_within_the_limits_are_read_whole_and_over_them_refused() {
        let j: Joints = eezybot_msgs::cdr::decode(&joint_state(4, 10)).unwrap();
        assert_eq!(j.refusal(), None);
        assert_eq!(j.stamp, Time::new(7, 9));
        assert_eq!(j.names.len(), 4);
        assert_eq!(j.positions, vec![0.0, 1.0, 2.0, 3.0]);
        let js = j.into_joint_state();
        assert_eq!(js.name[3], "0000000003");
        let j: Joints = eezybot_msgs::cdr::decode(&joint_state(30_000, 8)).unwrap();
        assert_eq!(j.refusal().as_deref(), Some("30000 names > 256"));
        assert_eq!((j.names.len(), j.positions.len()), (MAX_JOINTS, MAX_JOINTS));
        let j: Joints = eezybot_msgs::cdr::decode(&joint_state(2, 100)).unwrap();
        assert_eq!(
            j.refusal().as_deref(),
            Some("a joint name of 100 bytes > 64")
        );
    }

    #[test]
    fn refusals_show_until_the_topic_s_next_sample_is_taken_and_are_logged_throttled() {
        let (mut r, t0) = (RefusedInputs::default(), Instant::now());
        assert!(r.refused("leader/joint_states", "30000 names > 256", t0).0);
        for _ in 0..100 {
            assert_eq!(
                r.refused("leader/joint_states", "30000 names > 256", t0),
                (false, None)
            );
        }
        let later = t0 + Throttle::PERIOD;
        let (_, line) = r.refused("leader/joint_states", "30000 names > 256", later);
        assert!(line.unwrap().1.contains("100 more like it"));
        assert_eq!(r.view().len(), 1);
        assert!(!r.taken("joint_states"));
        assert!(r.taken("leader/joint_states"));
        assert!(!r.taken("leader/joint_states"));
        assert!(r.view().is_empty());
        assert_eq!(r.values()[0].1, "102");
        assert_eq!(r.values()[1].1, "leader/joint_states: 30000 names > 256");
    }
}
