//! A kinematic tree from any URDF (parsed with urdf-rs): validated structure, joint
//! transforms with mimic joints resolved, and link poses.
//!
//! # Examples
//! ```
//! use eezybot_kinematics::urdf::RobotModel;
//! let m = RobotModel::from_urdf_str(r#"<robot name="r">
//!   <link name="a"/><link name="b"/>
//!   <joint name="j" type="prismatic"><parent link="a"/><child link="b"/>
//!     <axis xyz="1 0 0"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>
//! </robot>"#, "inline").unwrap();
//! let poses = m.link_poses(&[("j", 0.25)]);
//! assert!((poses["b"].translation.vector.x - 0.25).abs() < 1e-15);
//! ```

use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// Why a URDF cannot be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum UrdfError {
    /// The file cannot be read.
    #[error("{origin}: cannot read: {message}")]
    Read {
        /// the file
        origin: String,
        /// the I/O error
        message: String,
    },
    /// The XML is malformed or not a URDF.
    #[error("{origin}: not a valid URDF: {message}")]
    Parse {
        /// the file
        origin: String,
        /// what the parser said
        message: String,
    },
    /// Elements are nested deeper than [`MAX_ELEMENT_DEPTH`]: refused before parsing,
    /// as urdf-rs recurses once per level and would overflow the stack.
    #[error("{origin}: elements nested {depth} deep, more than the {limit} a URDF may have")]
    TooDeep {
        /// the file
        origin: String,
        /// the deepest nesting found
        depth: usize,
        /// [`MAX_ELEMENT_DEPTH`]
        limit: usize,
    },
    /// The URDF parses but its structure is not a tree of links.
    #[error("{origin}: {message}")]
    Structure {
        /// the file
        origin: String,
        /// what is wrong
        message: String,
    },
}

/// The deepest element nesting a URDF may have. A real one is about 6 deep
/// (`robot/link/visual/geometry/mesh`, `gazebo/plugin/...`); urdf-rs recurses once per
/// level, so a document nested thousands deep would overflow the stack.
pub const MAX_ELEMENT_DEPTH: usize = 64;

/// The largest URDF file read (16 MiB; a large robot's expanded xacro is about 1 MB), so
/// that a path to an endless file (`/dev/zero`, a FIFO) is refused instead of read forever.
pub const MAX_URDF_BYTES: usize = 16 << 20;

/// Read a URDF file's text: at most [`MAX_URDF_BYTES`] + 1 bytes are read, and a larger
/// file is refused ([`UrdfError::Read`] saying so).
pub fn read_urdf_file(path: &Path) -> Result<String, UrdfError> {
    use std::io::Read;
    let origin = path.display().to_string();
    let read_error = |message: String| UrdfError::Read {
        origin: origin.clone(),
        message,
    };
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_URDF_BYTES as u64 + 1).read_to_end(&mut bytes))
        .map_err(|e| read_error(e.to_string()))?;
    if bytes.len() > MAX_URDF_BYTES {
        return Err(read_error(format!(
            "larger than the {} MiB a URDF may have",
            MAX_URDF_BYTES >> 20
        )));
    }
    String::from_utf8(bytes).map_err(|e| read_error(format!("not UTF-8: {e}")))
}

/// The deepest element nesting of an XML document, found by a linear, non-recursive
/// scan of its markup: start tags (not self-closing) open a level, end tags close one;
/// comments, CDATA sections, processing instructions and declarations (`<!DOCTYPE ...>`)
/// are skipped as the parsers skip them, and `>` inside quoted attribute values does not
/// end a tag. Malformed markup is counted as it comes (never fewer levels than a parser
/// could build before it gives up): this bounds the parse, it does not validate.
fn element_depth(text: &str) -> usize {
    let b = text.as_bytes();
    let find = |from: usize, pat: &[u8]| {
        b.get(from..)
            .and_then(|rest| rest.windows(pat.len()).position(|w| w == pat))
            .map_or(b.len(), |at| from + at + pat.len())
    };
    let (mut i, mut depth, mut deepest) = (0, 0usize, 0usize);
    while let Some(at) = b
        .get(i..)
        .and_then(|rest| rest.iter().position(|&c| c == b'<'))
    {
        let start = i + at;
        let rest = &b[start..];
        if rest.starts_with(b"<!--") {
            i = find(start + 4, b"-->");
        } else if rest.starts_with(b"<![CDATA[") {
            i = find(start + 9, b"]]>");
        } else if rest.starts_with(b"<?") {
            i = find(start + 2, b"?>");
        } else if rest.starts_with(b"<!") {
            // a declaration ends at the first `>`, as RustyXML (urdf-rs's first pass) ends it
            i = find(start + 2, b">");
        } else if rest.starts_with(b"</") {
            depth = depth.saturating_sub(1);
            i = find(start + 2, b">");
        } else {
            // a start tag: `>` ends it unless inside a value quoted after `=`
            let (mut j, mut after_eq, mut self_closing) = (start + 1, false, false);
            while let Some(&c) = b.get(j) {
                match c {
                    b'>' => break,
                    b'"' | b'\'' if after_eq => {
                        j = find(j + 1, &[c]) - 1;
                        after_eq = false;
                    }
                    b'=' => after_eq = true,
                    b' ' | b'\t' | b'\r' | b'\n' => {}
                    _ => after_eq = false,
                }
                self_closing = c == b'/';
                j += 1;
            }
            deepest = deepest.max(depth + 1);
            if !self_closing {
                depth += 1;
            }
            i = j + 1;
        }
    }
    deepest
}

/// How a joint moves.
#[derive(Clone, Debug, PartialEq)]
pub enum JointKind {
    /// Does not move: published once on `tf_static`.
    Fixed,
    /// Rotates about `axis` (unit) within limits.
    Revolute {
        /// unit axis in the joint frame
        axis: Unit<Vector3<f64>>,
        /// (lower, upper) rad
        limits: (f64, f64),
    },
    /// Rotates about `axis` without limits.
    Continuous {
        /// unit axis in the joint frame
        axis: Unit<Vector3<f64>>,
    },
    /// Slides along `axis` within limits.
    Prismatic {
        /// unit axis in the joint frame
        axis: Unit<Vector3<f64>>,
        /// (lower, upper) m
        limits: (f64, f64),
    },
    /// Floating, planar or spherical: not driven by a single position; treated as its
    /// origin only (as robot_state_publisher, which does not publish them).
    Unsupported,
}

/// A mimic relation: value = multiplier · leader + offset.
#[derive(Clone, Debug, PartialEq)]
pub struct Mimic {
    /// Index of the leader joint in [`RobotModel::joints`].
    pub leader: usize,
    /// Multiplier (default 1).
    pub multiplier: f64,
    /// Offset (default 0).
    pub offset: f64,
}

/// One joint of the tree.
#[derive(Clone, Debug, PartialEq)]
pub struct JointModel {
    /// Joint name.
    pub name: String,
    /// How it moves.
    pub kind: JointKind,
    /// Parent link name.
    pub parent: String,
    /// Child link name.
    pub child: String,
    /// Pose of the joint frame in the parent link frame.
    pub origin: Isometry3<f64>,
    /// If it follows another joint.
    pub mimic: Option<Mimic>,
}

impl JointModel {
    /// Does it move with a position (revolute, continuous, prismatic)?
    pub fn is_movable(&self) -> bool {
        matches!(
            self.kind,
            JointKind::Revolute { .. } | JointKind::Continuous { .. } | JointKind::Prismatic { .. }
        )
    }

    /// Pose of the child link frame in the parent link frame at position `q`.
    pub fn transform(&self, q: f64) -> Isometry3<f64> {
        let motion = match &self.kind {
            JointKind::Revolute { axis, .. } | JointKind::Continuous { axis } => {
                Isometry3::from_parts(
                    Translation3::identity(),
                    UnitQuaternion::from_axis_angle(axis, q),
                )
            }
            JointKind::Prismatic { axis, .. } => Isometry3::from_parts(
                Translation3::from(axis.into_inner() * q),
                UnitQuaternion::identity(),
            ),
            JointKind::Fixed | JointKind::Unsupported => Isometry3::identity(),
        };
        self.origin * motion
    }
}

/// A validated URDF tree.
#[derive(Clone, Debug)]
pub struct RobotModel {
    /// Robot name.
    pub name: String,
    /// The root link (the one no joint has as child).
    pub root: String,
    /// Every link name, in file order.
    pub links: Vec<String>,
    /// Joints ordered parents before children (so poses can be accumulated in order).
    pub joints: Vec<JointModel>,
    index: HashMap<String, usize>,
    /// `<limit velocity>` of every movable joint that gives a positive one (rad/s or m/s).
    velocity: HashMap<String, f64>,
}

fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    let [x, y, z] = p.xyz.0;
    let [r, pi, yaw] = p.rpy.0;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(r, pi, yaw),
    )
}

impl RobotModel {
    /// Read and validate a URDF file.
    pub fn load(path: &Path) -> Result<RobotModel, UrdfError> {
        let text = read_urdf_file(path)?;
        Self::from_urdf_str(&text, &path.display().to_string())
    }

    /// Parse and validate URDF text; `origin` names it in errors.
    ///
    /// A document nested deeper than [`MAX_ELEMENT_DEPTH`] is refused before it is
    /// parsed ([`UrdfError::TooDeep`]).
    pub fn from_urdf_str(text: &str, origin: &str) -> Result<RobotModel, UrdfError> {
        let depth = element_depth(text);
        if depth > MAX_ELEMENT_DEPTH {
            return Err(UrdfError::TooDeep {
                origin: origin.to_string(),
                depth,
                limit: MAX_ELEMENT_DEPTH,
            });
        }
        let robot = urdf_rs::read_from_string(text).map_err(|e| UrdfError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        let bad = |message: String| UrdfError::Structure {
            origin: origin.to_string(),
            message,
        };
        if robot.links.is_empty() {
            return Err(bad("the robot has no link".into()));
        }
        let mut links = Vec::new();
        for l in &robot.links {
            if links.contains(&l.name) {
                return Err(bad(format!("link `{}` is defined twice", l.name)));
            }
            links.push(l.name.clone());
        }
        let mut seen_joints: Vec<&str> = Vec::new();
        let mut parent_of: HashMap<&str, &str> = HashMap::new();
        for j in &robot.joints {
            if seen_joints.contains(&j.name.as_str()) {
                return Err(bad(format!("joint `{}` is defined twice", j.name)));
            }
            seen_joints.push(&j.name);
            for (role, l) in [("parent", &j.parent.link), ("child", &j.child.link)] {
                if !links.contains(l) {
                    return Err(bad(format!(
                        "joint `{}`: {role} link `{l}` does not exist",
                        j.name
                    )));
                }
            }
            if let Some(previous) = parent_of.insert(&j.child.link, &j.name) {
                return Err(bad(format!(
                    "link `{}` is the child of two joints, `{previous}` and `{}`",
                    j.child.link, j.name
                )));
            }
        }
        let roots: Vec<&String> = links
            .iter()
            .filter(|l| !parent_of.contains_key(l.as_str()))
            .collect();
        let root = match roots.as_slice() {
            [root] => (*root).clone(),
            [] => return Err(bad("every link is a child: the joints form a loop".into())),
            many => {
                return Err(bad(format!(
                    "several root links ({}): a URDF is one tree",
                    many.iter()
                        .map(|s| s.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )))
            }
        };
        // Order joints from the root outwards (breadth first); what is left over is a loop.
        let mut children: BTreeMap<&str, Vec<&urdf_rs::Joint>> = BTreeMap::new();
        for j in &robot.joints {
            children.entry(j.parent.link.as_str()).or_default().push(j);
        }
        let mut ordered: Vec<&urdf_rs::Joint> = Vec::new();
        let mut frontier = vec![root.as_str()];
        while let Some(link) = frontier.pop() {
            for j in children.get(link).map(Vec::as_slice).unwrap_or_default() {
                ordered.push(j);
                frontier.push(&j.child.link);
            }
        }
        if ordered.len() != robot.joints.len() {
            return Err(bad(
                "some links are not connected to the root (a loop of joints)".into(),
            ));
        }
        let index: HashMap<String, usize> = ordered
            .iter()
            .enumerate()
            .map(|(i, j)| (j.name.clone(), i))
            .collect();
        let mut joints = Vec::with_capacity(ordered.len());
        let mut velocity = HashMap::new();
        for j in &ordered {
            if j.limit.velocity.is_finite() && j.limit.velocity > 0.0 {
                velocity.insert(j.name.clone(), j.limit.velocity);
            }
            let axis = || {
                let v = Vector3::from(j.axis.xyz.0);
                Unit::try_new(v, 1e-12)
                    .ok_or_else(|| bad(format!("joint `{}` has a zero axis", j.name)))
            };
            let limits = || {
                let (lo, hi) = (j.limit.lower, j.limit.upper);
                if lo.is_nan() || hi.is_nan() || lo > hi {
                    Err(bad(format!(
                        "joint `{}` has limits lower {lo} > upper {hi}",
                        j.name
                    )))
                } else {
                    Ok((lo, hi))
                }
            };
            let kind = match j.joint_type {
                urdf_rs::JointType::Fixed => JointKind::Fixed,
                urdf_rs::JointType::Revolute => JointKind::Revolute {
                    axis: axis()?,
                    limits: limits()?,
                },
                urdf_rs::JointType::Continuous => JointKind::Continuous { axis: axis()? },
                urdf_rs::JointType::Prismatic => JointKind::Prismatic {
                    axis: axis()?,
                    limits: limits()?,
                },
                _ => JointKind::Unsupported,
            };
            let mimic = match &j.mimic {
                None => None,
                Some(m) => {
                    let leader = *index.get(&m.joint).ok_or_else(|| {
                        bad(format!(
                            "joint `{}` mimics `{}`, which does not exist",
                            j.name, m.joint
                        ))
                    })?;
                    if ordered[leader].mimic.is_some() {
                        return Err(bad(format!(
                            "joint `{}` mimics `{}`, itself a mimic joint",
                            j.name, m.joint
                        )));
                    }
                    Some(Mimic {
                        leader,
                        multiplier: m.multiplier.unwrap_or(1.0),
                        offset: m.offset.unwrap_or(0.0),
                    })
                }
            };
            joints.push(JointModel {
                name: j.name.clone(),
                kind,
                parent: j.parent.link.clone(),
                child: j.child.link.clone(),
                origin: pose(&j.origin),
                mimic,
            });
        }
        for j in &joints {
            if let Some(m) = &j.mimic {
                if !joints[m.leader].is_movable() {
                    return Err(bad(format!(
                        "joint `{}` mimics `{}`, which does not move",
                        j.name, joints[m.leader].name
                    )));
                }
            }
        }
        Ok(RobotModel {
            name: robot.name,
            root,
            links,
            joints,
            index,
            velocity,
        })
    }

    /// The joint with this name.
    pub fn joint(&self, name: &str) -> Option<&JointModel> {
        self.index.get(name).map(|i| &self.joints[*i])
    }

    /// Index of a joint in [`RobotModel::joints`].
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// The `<limit velocity>` of a joint (rad/s or m/s), if the URDF gives a positive one.
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::urdf::RobotModel;
    /// let m = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/jaco.urdf"))).unwrap();
    /// assert!((m.velocity_limit("jaco_joint_1").unwrap() - 36f64.to_radians()).abs() < 1e-12);
    /// assert_eq!(m.velocity_limit("jaco_end_effector_joint"), None); // fixed
    /// ```
    pub fn velocity_limit(&self, joint: &str) -> Option<f64> {
        self.joint(joint)
            .filter(|j| j.is_movable())
            .and_then(|j| self.velocity.get(&j.name).copied())
    }

    /// Links that are no joint's parent (the ends of the tree), in file order.
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::urdf::RobotModel;
    /// let m = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/jaco.urdf"))).unwrap();
    /// assert_eq!(m.leaf_links(), ["jaco_end_effector"]);
    /// ```
    pub fn leaf_links(&self) -> Vec<&str> {
        self.links
            .iter()
            .filter(|l| !self.joints.iter().any(|j| &j.parent == *l))
            .map(String::as_str)
            .collect()
    }

    /// Joints whose position comes from `joint_states`: movable and not mimic.
    pub fn independent_joints(&self) -> impl Iterator<Item = &JointModel> {
        self.joints
            .iter()
            .filter(|j| j.is_movable() && j.mimic.is_none())
    }

    /// Pose of every link in the root frame for these joint positions (mimic joints
    /// follow their leaders; joints not given are at 0).
    pub fn link_poses(&self, positions: &[(&str, f64)]) -> HashMap<String, Isometry3<f64>> {
        let mut q = vec![0.0; self.joints.len()];
        for (name, value) in positions {
            if let Some(i) = self.joint_index(name) {
                q[i] = *value;
            }
        }
        for (i, j) in self.joints.iter().enumerate() {
            if let Some(m) = &j.mimic {
                q[i] = m.multiplier * q[m.leader] + m.offset;
            }
        }
        let mut poses = HashMap::with_capacity(self.links.len());
        poses.insert(self.root.clone(), Isometry3::identity());
        for (i, j) in self.joints.iter().enumerate() {
            let parent = poses
                .get(&j.parent)
                .copied()
                .unwrap_or_else(Isometry3::identity);
            poses.insert(j.child.clone(), parent * j.transform(q[i]));
        }
        poses
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO: &str = r#"<robot name="r"><link name="a"/><link name="b"/>
        <joint name="j" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint></robot>"#;

    #[test]
    fn structure_errors_name_the_problem() {
        let cases = [
            (
                r#"<robot name="r"><link name="a"/><link name="a"/></robot>"#,
                "defined twice",
            ),
            (
                r#"<robot name="r"><link name="a"/><link name="b"/></robot>"#,
                "several root links",
            ),
            (
                r#"<robot name="r"><link name="a"/><joint name="j" type="fixed"><parent link="a"/><child link="x"/></joint></robot>"#,
                "`x` does not exist",
            ),
            (
                r#"<robot name="r"><link name="a"/><link name="b"/>
                <joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint>
                <joint name="k" type="fixed"><parent link="b"/><child link="a"/></joint></robot>"#,
                "loop",
            ),
            (
                r#"<robot name="r"><link name="a"/><link name="b"/>
                <joint name="j" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 0"/></joint></robot>"#,
                "zero axis",
            ),
            ("<robot name=", "not a valid URDF"),
        ];
        for (text, needle) in cases {
            let err = RobotModel::from_urdf_str(text, "t.urdf")
                .unwrap_err()
                .to_string();
            assert!(err.contains(needle) && err.contains("t.urdf"), "{err}");
        }
    }

    /// A link with `depth` `<tag>` elements nested in it: `depth + 2` levels.
    fn deep_urdf(tag: &str, depth: usize) -> String {
        format!(
            "<robot name='deep'><link name='a'>{}{}</link></robot>",
            format!("<{tag}>").repeat(depth),
            format!("</{tag}>").repeat(depth)
        )
    }

    #[test]
    fn deeply_nested_urdf_is_refused_before_parsing() {
        // refused by the depth count before urdf-rs parses it: TooDeep says so (how long
        // that takes: `cargo bench -p eezybot_kinematics --bench kinematics`)
        for depth in [10_000, 100_000] {
            let err =
                RobotModel::from_urdf_str(&deep_urdf("visual", depth), "deep.urdf").unwrap_err();
            assert!(
                matches!(err, UrdfError::TooDeep { depth: d, limit: 64, .. } if d == depth + 2),
                "{err}"
            );
            let text = err.to_string();
            assert!(
                text.contains("deep.urdf") && text.contains(&format!("{}", depth + 2)),
                "{text}"
            );
        }
    }

    #[test]
    fn nesting_up_to_the_limit_is_parsed() {
        // robot + link + 62 unknown elements = 64 levels: parsed (urdf-rs ignores them)
        let r = RobotModel::from_urdf_str(&deep_urdf("extra", MAX_ELEMENT_DEPTH - 2), "t");
        assert!(r.is_ok(), "{r:?}");
        assert!(matches!(
            RobotModel::from_urdf_str(&deep_urdf("extra", MAX_ELEMENT_DEPTH - 1), "t"),
            Err(UrdfError::TooDeep { depth: 65, .. })
        ));
    }

    #[test]
    fn element_depth_skips_what_is_not_an_element() {
        let cases = [
            ("<a/>", 1),
            ("<a><b/><b></b></a>", 2),
            ("<?xml version='1.0'?><!DOCTYPE robot><a></a>", 1),
            ("<a><!-- <b><c><d> --></a>", 1),
            ("<a><![CDATA[<b><c><d>]]></a>", 1),
            ("<a><?pi <b><c> ?></a>", 1),
            (r#"<a x="<b>" y='/>'><b z = ">"/></a>"#, 2),
            ("<a><b><c></c></b><b></b></a>", 3),
            // malformed: counted as it comes, never fewer levels than exist
            ("<a><b x=\"unterminated><c><d>", 2),
            ("<a'><b><c>", 3),
            ("</a></a><b><c>", 2),
        ];
        for (text, depth) in cases {
            assert_eq!(element_depth(text), depth, "{text}");
        }
    }

    #[test]
    fn shipped_urdfs_are_shallow() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../urdf");
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "urdf") {
                let text = std::fs::read_to_string(&path).unwrap();
                let depth = element_depth(&text);
                assert!((2..=8).contains(&depth), "{}: {depth}", path.display());
            }
        }
    }

    #[test]
    fn comments_and_cdata_do_not_hide_or_add_structure() {
        let text = r#"<?xml version="1.0"?>
            <!-- a comment with <link name="fake"/> and > -->
            <robot name="r"><link name="a"><![CDATA[ <joint> ]]></link><link name="b"/>
            <joint name="j" type="continuous"><parent link="a"/><child link="b"/>
            <axis xyz="0 0 1"/></joint></robot>"#;
        let m = RobotModel::from_urdf_str(text, "t").unwrap();
        assert_eq!(m.links, ["a", "b"]);
    }

    #[test]
    fn continuous_joint_turns_the_child() {
        let m = RobotModel::from_urdf_str(TWO, "t").unwrap();
        let p = m.link_poses(&[("j", std::f64::consts::FRAC_PI_2)]);
        let x = p["b"] * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!((x - nalgebra::Point3::new(0.0, 1.0, 0.0)).norm() < 1e-15);
    }

    #[test]
    fn an_endless_urdf_file_is_refused_not_read_forever() {
        let err = RobotModel::load(Path::new("/dev/zero")).unwrap_err();
        assert!(err.to_string().contains("larger than the 16 MiB"), "{err}");
    }
}
