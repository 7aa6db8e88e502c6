//! The twin's MuJoCo model (MJCF), generated from the URDF and the arm config.
//!
//! What the URDF cannot say and this adds (docs/twin.md):
//! - **the closed linkage:** the URDF's open chains are closed again by three `connect`
//!   equalities ([`CLOSURES`]): the forearm drive's link pinned to the forearm's rear
//!   lever, the levelling triangle on the elbow axle, the upper link pinned to the front
//!   plate. The mimic tags those loops imply are left out (the loops make them); a mimic
//!   between two joints of one parent link (the claw's second finger) is a gear pair, a
//!   joint equality;
//! - **what turns what:** a torque motor on each driven joint ([`crate::drive::Drive`]:
//!   `crank_joint` for the forearm servo), its rotor inertia as the joint's armature,
//!   its gear train's friction as the joint's frictionloss;
//!   every other joint is passive, its pins a little damped;
//! - **mass:** each link's from its shapes, PLA's density and print fill, plus the
//!   servos it carries ([`crate::mass`]);
//! - **contacts:** the claw's fingers (with friction) grip the cube; the arm's other
//!   parts touch only the table; no two parts of the arm touch each other (the linkage's
//!   links overlap at their pins, where contacts would lock it);
//! - **the scene:** a table, a stand with a 25 mm cube on it, a light, and the camera.

use std::collections::HashMap;
use std::fmt::Write as _;

use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::ArmConfig;
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use urdf_rs::{Geometry, JointType};

use crate::drive::Drive;
use crate::mass::{MassProperties, Shape, PLA_DENSITY, PRINT_FILL};
use crate::TwinModelError;

/// One loop of the linkage, closed by a MuJoCo `connect` equality: a point of `body1`
/// (`anchor1`, its frame) stays on a point of `body2` (`anchor2`).
#[derive(Clone, Debug, PartialEq)]
pub struct Closure {
    /// The equality's name.
    pub name: &'static str,
    /// The first body (a URDF link).
    pub body1: &'static str,
    /// The pin in `body1`'s frame (m).
    pub anchor1: [f64; 3],
    /// The second body.
    pub body2: &'static str,
    /// The same pin in `body2`'s frame, where the URDF's zero pose puts it (m).
    pub anchor2: [f64; 3],
}

/// Which pin closes each loop (body1, where on it, body2): the far end of the 135 mm
/// drive link on the forearm's rear lever; the elbow axle (the main arm's end) through
/// the levelling triangle; the far end of the 147 mm upper link on the front plate.
pub const CLOSURES: [(&str, &str, Pin, &str); 3] = [
    ("forearm_drive", "drive_link", Pin::MainArmLength, "forearm"),
    (
        "levelling_triangle",
        "main_arm",
        Pin::ElbowAxle,
        "triangle_link",
    ),
    (
        "front_plate_level",
        "upper_link",
        Pin::ForearmLength,
        "front_plate",
    ),
];

/// Where a closure's pin is on its first body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pin {
    /// `(main_arm_m, 0, 0)`: the end of a link as long as the main arm.
    MainArmLength,
    /// `(forearm_m, 0, 0)`: the end of a link as long as the forearm.
    ForearmLength,
    /// The elbow joint's origin.
    ElbowAxle,
}

/// Servo masses (kg) where they ride (link, position in its frame): the main-arm and
/// forearm servos on the turntable's cheeks, the claw's SG90 under the front plate (the
/// base servo is in the fixed base). Datasheets: MG995 55 g, SG90 9 g.
pub const SERVO_MASSES: [(&str, f64, [f64; 3]); 3] = [
    ("turntable", 0.055, [0.0, 0.04, 0.064]),
    ("turntable", 0.055, [0.0, -0.04, 0.064]),
    ("front_plate", 0.009, [0.02, 0.0, -0.02]),
];

/// The cube's side (m), mass (kg) and friction, and the fingers' friction: PLA on PLA
/// (docs/twin.md).
pub const CUBE_SIDE_M: f64 = 0.025;
/// A 25 mm cube printed in PLA at half fill: 15.6 cm³ · 1.24 g/cm³ · 0.5 ≈ 10 g.
pub const CUBE_MASS_KG: f64 = 0.010;
/// Sliding friction coefficient of PLA on PLA (static, dry: 0.4–0.6 in published
/// measurements; 0.6).
pub const PLA_FRICTION: f64 = 0.6;

/// The scene around the arm.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The camera's position in `base_link` (m).
    pub camera_pos: [f64; 3],
    /// The point it looks at (m).
    pub camera_target: [f64; 3],
    /// Its vertical field of view (deg).
    pub camera_fovy_deg: f64,
    /// The images' size (px): the offscreen buffer.
    pub image_size: (u32, u32),
    /// The cube's centre on its stand, x and y in `base_link` (m).
    pub cube_xy: [f64; 2],
    /// The stand's height above the table (m): the claw reaches no lower than about
    /// 5 cm (docs/robot.md's workspace), so the cube waits on a stand.
    pub stand_height_m: f64,
    /// Stall torque of each servo (servo_angles order) as a part of its datasheet's.
    pub torque_scale: [f64; 4],
    /// The physics step (s).
    pub timestep_s: f64,
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            // behind and above the arm's left shoulder, looking over it at the table
            camera_pos: [-0.2, 0.24, 0.4],
            camera_target: [0.14, 0.0, 0.09],
            camera_fovy_deg: 55.0,
            image_size: (640, 480),
            cube_xy: [0.2, 0.0],
            stand_height_m: 0.055,
            torque_scale: [1.0; 4],
            timestep_s: 0.001,
        }
    }
}

/// The generated model and what the twin needs to drive and check it.
#[derive(Clone, Debug)]
pub struct TwinModel {
    /// The MJCF document.
    pub mjcf: String,
    /// The four servo drives, in `servo_angles` order.
    pub drives: [Drive; 4],
    /// The loop closures.
    pub closures: Vec<Closure>,
    /// Every movable URDF joint, in file order (what `twin/joint_states` carries).
    pub joints: Vec<String>,
    /// Each link's mass (kg), for docs and checks.
    pub masses: Vec<(String, f64)>,
}

/// A geom's collision role.
#[derive(Clone, Copy, PartialEq)]
enum Contact {
    /// Table and stand: collide with everything but each other.
    Environment,
    /// The claw's fingers: the cube and the table.
    Finger,
    /// The rest of the arm: the table only.
    Arm,
}

impl Contact {
    /// MuJoCo's (contype, conaffinity): bit 0 environment, 1 cube, 2 fingers, 3 arm; a
    /// pair collides when one's type meets the other's affinity.
    fn bits(self) -> (u32, u32) {
        match self {
            Contact::Environment => (1, 2 | 4 | 8),
            Contact::Finger => (4, 1 | 2),
            Contact::Arm => (8, 1),
        }
    }
}
const CUBE_BITS: (u32, u32) = (2, 1 | 4);

/// Builds the twin's model from URDF text (`origin` names it in errors), the arm
/// config the twin is assembled to, and the scene.
pub fn build(
    urdf_text: &str,
    origin: &str,
    config: &ArmConfig,
    scene: &Scene,
) -> Result<TwinModel, TwinModelError> {
    let robot = urdf_rs::read_from_string(urdf_text)
        .map_err(|e| TwinModelError::Urdf(format!("{origin}: {e}")))?;
    let model = RobotModel::from_urdf_str(urdf_text, origin)
        .map_err(|e| TwinModelError::Urdf(e.to_string()))?;
    let drives = Drive::all(&config.servos, &config.geometry);
    for d in &drives {
        if model.joint(d.joint).is_none() {
            return Err(TwinModelError::Urdf(format!(
                "{origin} has no joint `{}`, which a servo drives",
                d.joint
            )));
        }
    }
    let closures = closures(&model, config)?;
    let mut out = Writer::default();
    let materials: HashMap<&str, [f64; 4]> = robot
        .materials
        .iter()
        .filter_map(|m| m.color.as_ref().map(|c| (m.name.as_str(), c.rgba.0)))
        .collect();

    let mut children: HashMap<&str, Vec<&urdf_rs::Joint>> = HashMap::new();
    for j in &robot.joints {
        children.entry(j.parent.link.as_str()).or_default().push(j);
    }
    let links: HashMap<&str, &urdf_rs::Link> =
        robot.links.iter().map(|l| (l.name.as_str(), l)).collect();
    // a mimic tag on a joint of a closed loop is what the loop makes; any other (the
    // claw's second finger) is a gear pair
    let in_loops = loop_joints(&robot);
    let gears: Vec<(&str, &str, f64, f64)> = robot
        .joints
        .iter()
        .filter(|j| !in_loops.contains(&j.name.as_str()))
        .filter_map(|j| {
            let m = j.mimic.as_ref()?;
            Some((
                j.name.as_str(),
                m.joint.as_str(),
                m.multiplier.unwrap_or(1.0),
                m.offset.unwrap_or(0.0),
            ))
        })
        .collect();

    let (w, h) = scene.image_size;
    let _ = writeln!(out.s, "<mujoco model=\"{}_twin\">", robot.name);
    out.line(1, "<!-- Generated by libs/twin_model from the URDF and the arm config: change those, not this. -->");
    out.line(1, "<compiler angle=\"radian\" autolimits=\"true\"/>");
    out.line(
        1,
        &format!(
        "<option timestep=\"{}\" integrator=\"implicitfast\" cone=\"elliptic\" impratio=\"10\"/>",
        num(scene.timestep_s)
    ),
    );
    out.line(1, &format!("<visual><global offwidth=\"{w}\" offheight=\"{h}\"/><quality shadowsize=\"1024\" offsamples=\"0\"/><headlight ambient=\"0.35 0.35 0.35\" diffuse=\"0.5 0.5 0.5\"/></visual>"));
    out.line(1, "<asset>");
    out.line(2, "<texture name=\"sky\" type=\"skybox\" builtin=\"gradient\" rgb1=\"0.55 0.65 0.8\" rgb2=\"0.1 0.12 0.15\" width=\"64\" height=\"512\"/>");
    out.line(2, "<texture name=\"wood\" type=\"2d\" builtin=\"checker\" rgb1=\"0.72 0.6 0.45\" rgb2=\"0.68 0.56 0.42\" width=\"256\" height=\"256\"/>");
    out.line(
        2,
        "<material name=\"table\" texture=\"wood\" texrepeat=\"8 8\" reflectance=\"0.05\"/>",
    );
    out.line(1, "</asset>");
    out.line(1, "<default>");
    out.line(2, "<joint damping=\"0.002\" frictionloss=\"0.0005\"/>");
    out.line(
        2,
        &format!(
            "<geom friction=\"{} 0.005 0.0001\" solref=\"0.004 1\"/>",
            num(PLA_FRICTION)
        ),
    );
    out.line(
        2,
        "<equality solref=\"0.004 1\" solimp=\"0.95 0.99 0.001\"/>",
    );
    out.line(1, "</default>");
    out.line(1, "<worldbody>");
    out.line(2, "<light name=\"sun\" pos=\"0.3 -0.3 1.0\" dir=\"-0.3 0.3 -1\" directional=\"true\" castshadow=\"true\"/>");
    let env = Contact::Environment.bits();
    out.line(2, &format!(
        "<geom name=\"table\" type=\"box\" size=\"0.32 0.32 0.01\" pos=\"0.12 0 -0.01\" material=\"table\" contype=\"{}\" conaffinity=\"{}\"/>",
        env.0, env.1
    ));
    let [cx, cy] = scene.cube_xy;
    let sh = scene.stand_height_m;
    out.line(2, &format!(
        "<geom name=\"stand\" type=\"box\" size=\"0.02 0.02 {}\" pos=\"{} {} {}\" rgba=\"0.3 0.3 0.32 1\" contype=\"{}\" conaffinity=\"{}\"/>",
        num(sh / 2.0), num(cx), num(cy), num(sh / 2.0), env.0, env.1
    ));
    let (xaxis, yaxis) = look_at(scene.camera_pos, scene.camera_target);
    out.line(
        2,
        &format!(
            "<camera name=\"scene\" pos=\"{}\" xyaxes=\"{} {}\" fovy=\"{}\"/>",
            vec3(scene.camera_pos),
            vec3(xaxis),
            vec3(yaxis),
            num(scene.camera_fovy_deg)
        ),
    );
    // the root link is the world
    let root = model.root.as_str();
    let link = links
        .get(root)
        .ok_or_else(|| TwinModelError::Urdf(format!("{origin}: no root link")))?;
    let mut masses = Vec::new();
    geoms(&mut out, 2, link, &materials, Contact::Arm);
    body_children(
        &mut out,
        2,
        root,
        &children,
        &links,
        &materials,
        &drives,
        &mut masses,
    )?;
    let c = CUBE_SIDE_M / 2.0;
    out.line(
        2,
        &format!(
            "<body name=\"cube\" pos=\"{} {} {}\">",
            num(cx),
            num(cy),
            num(sh + c)
        ),
    );
    out.line(3, "<freejoint name=\"cube_joint\"/>");
    out.line(3, &format!(
        "<geom name=\"cube\" type=\"box\" size=\"{c} {c} {c}\" mass=\"{}\" rgba=\"0.85 0.15 0.12 1\" condim=\"4\" contype=\"{}\" conaffinity=\"{}\"/>",
        num(CUBE_MASS_KG), CUBE_BITS.0, CUBE_BITS.1, c = num(c)
    ));
    out.line(2, "</body>");
    out.line(1, "</worldbody>");
    out.line(1, "<equality>");
    for cl in &closures {
        out.line(
            2,
            &format!(
                "<connect name=\"{}\" body1=\"{}\" body2=\"{}\" anchor=\"{}\"/>",
                cl.name,
                cl.body1,
                cl.body2,
                vec3(cl.anchor1)
            ),
        );
    }
    for (joint, leader, multiplier, offset) in &gears {
        out.line(2, &format!(
            "<joint name=\"{joint}_gear\" joint1=\"{joint}\" joint2=\"{leader}\" polycoef=\"{} {} 0 0 0\"/>",
            num(*offset), num(*multiplier)
        ));
    }
    out.line(1, "</equality>");
    out.line(1, "<actuator>");
    for (d, scale) in drives.iter().zip(scene.torque_scale) {
        // (the motor's torque: the stall torque at the horn plus the gear friction it
        // overcomes there)
        let limit = d.ratio.abs() * (d.spec.stall_torque_nm * scale + d.spec.gear_friction_nm);
        out.line(
            2,
            &format!(
                "<motor name=\"{}\" joint=\"{}\" ctrlrange=\"{} {}\"/>",
                d.servo.name(),
                d.joint,
                num(-limit),
                num(limit)
            ),
        );
    }
    out.line(1, "</actuator>");
    out.line(0, "</mujoco>");
    let joints = model
        .joints
        .iter()
        .filter(|j| j.is_movable())
        .map(|j| j.name.clone())
        .collect();
    Ok(TwinModel {
        mjcf: out.s,
        drives,
        closures,
        joints,
        masses,
    })
}

/// The joints on the closures' loops: for each, those on one body's path to the root
/// but not on the other's.
fn loop_joints<'a>(robot: &'a urdf_rs::Robot) -> Vec<&'a str> {
    let parent: HashMap<&str, &urdf_rs::Joint> = robot
        .joints
        .iter()
        .map(|j| (j.child.link.as_str(), j))
        .collect();
    let path = |start: &str| -> Vec<&'a str> {
        let mut link = start.to_string();
        let mut joints = Vec::new();
        while let Some(j) = parent.get(link.as_str()) {
            joints.push(j.name.as_str());
            link = j.parent.link.clone();
        }
        joints
    };
    let mut out = Vec::new();
    for (_, body1, _, body2) in CLOSURES {
        let (a, b) = (path(body1), path(body2));
        out.extend(a.iter().filter(|j| !b.contains(j)));
        out.extend(b.iter().filter(|j| !a.contains(j)));
    }
    out
}

/// The closures' anchors: `anchor1` from the geometry, `anchor2` where the URDF's zero
/// pose (in which every loop is closed: each passive joint is 0 when α = φ = 0) puts it.
fn closures(model: &RobotModel, config: &ArmConfig) -> Result<Vec<Closure>, TwinModelError> {
    let poses = model.link_poses(&[]);
    let g = &config.geometry;
    let elbow = model
        .joint("elbow_joint")
        .ok_or_else(|| TwinModelError::Urdf("no elbow_joint".into()))?
        .origin
        .translation
        .vector;
    CLOSURES
        .iter()
        .map(|&(name, body1, pin, body2)| {
            let p1 = match pin {
                Pin::MainArmLength => Vector3::new(g.main_arm_m, 0.0, 0.0),
                Pin::ForearmLength => Vector3::new(g.forearm_m, 0.0, 0.0),
                Pin::ElbowAxle => elbow,
            };
            let pose = |b: &str| -> Result<Isometry3<f64>, TwinModelError> {
                poses.get(b).copied().ok_or_else(|| {
                    TwinModelError::Urdf(format!("no link `{b}` for the loop {name}"))
                })
            };
            let p2 = pose(body2)?.inverse() * (pose(body1)? * Point3::from(p1));
            Ok(Closure {
                name,
                body1,
                anchor1: p1.into(),
                body2,
                anchor2: p2.coords.into(),
            })
        })
        .collect()
}

#[allow(clippy::too_many_arguments)]
fn body_children(
    out: &mut Writer,
    depth: usize,
    parent: &str,
    children: &HashMap<&str, Vec<&urdf_rs::Joint>>,
    links: &HashMap<&str, &urdf_rs::Link>,
    materials: &HashMap<&str, [f64; 4]>,
    drives: &[Drive; 4],
    masses: &mut Vec<(String, f64)>,
) -> Result<(), TwinModelError> {
    for j in children.get(parent).map(Vec::as_slice).unwrap_or_default() {
        let child = j.child.link.as_str();
        let link = links
            .get(child)
            .ok_or_else(|| TwinModelError::Urdf(format!("no link `{child}`")))?;
        let [x, y, z] = j.origin.xyz.0;
        let [r, p, yw] = j.origin.rpy.0;
        let q = UnitQuaternion::from_euler_angles(r, p, yw);
        let shapes = shapes(link);
        // a fixed frame without geometry (tool0, wrist_pivot) is a site on its parent
        if matches!(j.joint_type, JointType::Fixed)
            && shapes.is_empty()
            && !children.contains_key(child)
        {
            out.line(
                depth,
                &format!(
                    "<site name=\"{child}\" pos=\"{}\" quat=\"{}\" size=\"0.003\"/>",
                    vec3([x, y, z]),
                    quat(&q)
                ),
            );
            continue;
        }
        out.line(
            depth,
            &format!(
                "<body name=\"{child}\" pos=\"{}\" quat=\"{}\">",
                vec3([x, y, z]),
                quat(&q)
            ),
        );
        let axis = j.axis.xyz.0;
        match j.joint_type {
            JointType::Revolute | JointType::Continuous | JointType::Prismatic => {
                let kind = if matches!(j.joint_type, JointType::Prismatic) {
                    "slide"
                } else {
                    "hinge"
                };
                let mut attrs = format!(
                    "name=\"{}\" type=\"{kind}\" axis=\"{}\"",
                    j.name,
                    vec3(axis)
                );
                // every pin's limits are its mechanical stops (a passive joint's are where
                // the linkage puts it at the driven joints' limits: within them they never
                // bind, and they keep a limp arm from folding the linkage over)
                if matches!(j.joint_type, JointType::Revolute | JointType::Prismatic) {
                    let _ = write!(
                        attrs,
                        " range=\"{} {}\"",
                        num(j.limit.lower),
                        num(j.limit.upper)
                    );
                }
                if let Some(d) = drives.iter().find(|d| d.joint == j.name) {
                    let _ = write!(
                        attrs,
                        " armature=\"{}\" frictionloss=\"{}\"",
                        num(d.ratio * d.ratio * d.spec.rotor_inertia_kg_m2),
                        num(d.ratio.abs() * d.spec.gear_friction_nm)
                    );
                }
                out.line(depth + 1, &format!("<joint {attrs}/>"));
            }
            _ => {}
        }
        let extras: Vec<(f64, Vector3<f64>)> = SERVO_MASSES
            .iter()
            .filter(|(l, _, _)| *l == child)
            .map(|(_, m, at)| (*m, Vector3::from(*at)))
            .collect();
        let solids: Vec<(Shape, Vector3<f64>)> =
            shapes.iter().map(|(s, at, _)| (*s, *at)).collect();
        if let Some(mp) = MassProperties::of(&solids, PLA_DENSITY * PRINT_FILL, &extras) {
            let i = mp.inertia;
            out.line(
                depth + 1,
                &format!(
                    "<inertial pos=\"{}\" mass=\"{}\" fullinertia=\"{} {} {} {} {} {}\"/>",
                    vec3(mp.com.into()),
                    num(mp.mass),
                    num(i[(0, 0)]),
                    num(i[(1, 1)]),
                    num(i[(2, 2)]),
                    num(i[(0, 1)]),
                    num(i[(0, 2)]),
                    num(i[(1, 2)])
                ),
            );
            masses.push((child.to_string(), mp.mass));
        }
        let role = if link.name.starts_with("claw") {
            Contact::Finger
        } else {
            Contact::Arm
        };
        geoms(out, depth + 1, link, materials, role);
        body_children(
            out,
            depth + 1,
            child,
            children,
            links,
            materials,
            drives,
            masses,
        )?;
        out.line(depth, "</body>");
    }
    Ok(())
}

/// A link's collision shapes: (shape, centre, rotation).
fn shapes(link: &urdf_rs::Link) -> Vec<(Shape, Vector3<f64>, UnitQuaternion<f64>)> {
    link.collision
        .iter()
        .filter_map(|c| {
            let shape = match &c.geometry {
                Geometry::Box { size } => Shape::Box(size.0),
                Geometry::Cylinder { radius, length } => Shape::Cylinder {
                    radius: *radius,
                    length: *length,
                },
                _ => return None,
            };
            let [r, p, y] = c.origin.rpy.0;
            Some((
                shape,
                Vector3::from(c.origin.xyz.0),
                UnitQuaternion::from_euler_angles(r, p, y),
            ))
        })
        .collect()
}

fn geoms(
    out: &mut Writer,
    depth: usize,
    link: &urdf_rs::Link,
    materials: &HashMap<&str, [f64; 4]>,
    role: Contact,
) {
    let rgba = link
        .visual
        .iter()
        .find_map(|v| v.material.as_ref())
        .and_then(|m| {
            m.color
                .as_ref()
                .map(|c| c.rgba.0)
                .or_else(|| materials.get(m.name.as_str()).copied())
        })
        .unwrap_or([0.6, 0.6, 0.6, 1.0]);
    let (contype, conaffinity) = role.bits();
    let extra = if role == Contact::Finger {
        " condim=\"4\""
    } else {
        ""
    };
    for (shape, at, q) in shapes(link) {
        let (kind, size) = match shape {
            Shape::Box([x, y, z]) => (
                "box",
                format!("{} {} {}", num(x / 2.0), num(y / 2.0), num(z / 2.0)),
            ),
            Shape::Cylinder { radius, length } => {
                ("cylinder", format!("{} {}", num(radius), num(length / 2.0)))
            }
        };
        out.line(depth, &format!(
            "<geom type=\"{kind}\" size=\"{size}\" pos=\"{}\" quat=\"{}\" rgba=\"{}\" contype=\"{contype}\" conaffinity=\"{conaffinity}\"{extra}/>",
            vec3(at.into()), quat(&q), rgba.map(num).join(" ")
        ));
    }
}

/// MuJoCo's camera frame for looking from `pos` at `target`, z up: (x axis, y axis).
fn look_at(pos: [f64; 3], target: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let forward = (Vector3::from(target) - Vector3::from(pos)).normalize();
    let mut right = forward.cross(&Vector3::z());
    if right.norm() < 1e-9 {
        right = Vector3::x(); // looking straight down or up
    }
    let right = right.normalize();
    let up = right.cross(&forward);
    (right.into(), up.into())
}

#[derive(Default)]
struct Writer {
    s: String,
}

impl Writer {
    fn line(&mut self, depth: usize, text: &str) {
        let _ = writeln!(self.s, "{}{text}", "  ".repeat(depth));
    }
}

fn num(x: f64) -> String {
    // Rust's shortest exact form; MuJoCo reads it
    if x == 0.0 {
        "0".into()
    } else {
        format!("{x}")
    }
}

fn vec3(v: [f64; 3]) -> String {
    format!("{} {} {}", num(v[0]), num(v[1]), num(v[2]))
}

fn quat(q: &UnitQuaternion<f64>) -> String {
    format!("{} {} {} {}", num(q.w), num(q.i), num(q.j), num(q.k))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped() -> TwinModel {
        let urdf = include_str!("../../../urdf/eezybot.urdf");
        build(
            urdf,
            "urdf/eezybot.urdf",
            &ArmConfig::shipped().unwrap(),
            &Scene::default(),
        )
        .unwrap()
    }

    #[test]
    fn every_movable_joint_is_in_the_model_and_the_fixed_frames_are_sites() {
        let m = shipped();
        for j in &m.joints {
            assert!(m.mjcf.contains(&format!("<joint name=\"{j}\"")), "{j}");
        }
        assert!(m.mjcf.contains("<site name=\"tool0\""));
        assert!(m.mjcf.contains("<site name=\"wrist_pivot\""));
        assert_eq!(m.joints.len(), 11);
    }

    #[test]
    fn the_loops_are_closed_and_only_the_claw_is_geared() {
        let m = shipped();
        assert_eq!(m.mjcf.matches("<connect ").count(), 3);
        assert_eq!(m.mjcf.matches("_gear\" joint1=").count(), 1);
        assert!(m.mjcf.contains(
            "joint1=\"gripper_mimic_joint\" joint2=\"gripper_joint\" polycoef=\"0 -1 0 0 0\""
        ));
        // the levelling triangle pins the main arm's end
        let tri = &m.closures[1];
        assert_eq!(tri.anchor1, [0.135, 0.0, 0.0]);
        // on the triangle, the elbow axle is 38 mm forward, 22 mm sideways and 20 mm
        // below the levelling link's end (docs/robot.md's fixed pivot, reversed)
        let [x, y, z] = tri.anchor2;
        assert!(
            (x - 0.038).abs() < 1e-9 && (y - 0.022).abs() < 1e-9 && (z + 0.0202).abs() < 1e-9,
            "{:?}",
            tri.anchor2
        );
    }

    #[test]
    fn masses_are_those_of_printed_pla_and_servos() {
        let m = shipped();
        let mass = |l: &str| m.masses.iter().find(|(n, _)| n == l).unwrap().1;
        // main arm: a 155 x 12 x 20 mm envelope at half fill of 1.24 g/cm³: 23 g
        assert!((mass("main_arm") - 0.155 * 0.012 * 0.02 * 620.0).abs() < 1e-9);
        // the turntable carries two MG995
        assert!(mass("turntable") > 0.11);
        let total: f64 = m.masses.iter().map(|(_, k)| k).sum();
        assert!((0.2..0.5).contains(&total), "{total} kg");
    }

    #[test]
    fn the_camera_looks_at_its_target() {
        let s = Scene::default();
        let (x, y) = look_at(s.camera_pos, s.camera_target);
        let f = (Vector3::from(s.camera_target) - Vector3::from(s.camera_pos)).normalize();
        // MuJoCo's camera looks along −z = −(x × y)
        let z = Vector3::from(x).cross(&Vector3::from(y));
        assert!((z + f).norm() < 1e-12);
        assert!(Vector3::from(y).z > 0.0, "up is up");
    }

    #[test]
    fn a_torque_scale_halves_a_motor_range() {
        let mut s = Scene::default();
        s.torque_scale[1] = 0.5;
        let urdf = include_str!("../../../urdf/eezybot.urdf");
        let m = build(urdf, "u", &ArmConfig::shipped().unwrap(), &s).unwrap();
        // half the stall torque, and the gear friction the motor overcomes besides
        let mg995 = crate::servo::ServoSpec::MG995;
        let limit = mg995.stall_torque_nm * 0.5 + mg995.gear_friction_nm;
        assert!(m.mjcf.contains(&format!(
            "<motor name=\"shoulder_servo\" joint=\"shoulder_joint\" ctrlrange=\"{} {}\"/>",
            num(-limit),
            num(limit)
        )));
    }
}
