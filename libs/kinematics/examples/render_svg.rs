//! Draws the URDF as an SVG: side view (x-z) and top view (x-y) of every visual,
//! at the home pose and at a reaching pose. Used for the README's picture:
//!
//!     cargo run -p eezybot_kinematics --example render_svg -- urdf/eezybot.urdf docs/eezybot_arm.svg

use eezybot_kinematics::urdf::RobotModel;
use eezybot_kinematics::{Arm, ArmState};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::fmt::Write as _;

type P2 = (f64, f64);

fn hull(mut pts: Vec<P2>) -> Vec<P2> {
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let cross = |o: P2, a: P2, b: P2| (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0);
    let mut lower: Vec<P2> = vec![];
    for p in &pts {
        while lower.len() >= 2 && cross(lower[lower.len() - 2], lower[lower.len() - 1], *p) <= 0.0 {
            lower.pop();
        }
        lower.push(*p);
    }
    let mut upper: Vec<P2> = vec![];
    for p in pts.iter().rev() {
        while upper.len() >= 2 && cross(upper[upper.len() - 2], upper[upper.len() - 1], *p) <= 0.0 {
            upper.pop();
        }
        upper.push(*p);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

struct Shape {
    points: Vec<Point3<f64>>,
    color: String,
}

fn shapes(robot: &urdf_rs::Robot, poses: &HashMap<String, Isometry3<f64>>) -> Vec<Shape> {
    let colors: HashMap<&str, [f64; 4]> = robot
        .materials
        .iter()
        .filter_map(|m| m.color.as_ref().map(|c| (m.name.as_str(), c.rgba.0)))
        .collect();
    let mut out = vec![];
    for link in &robot.links {
        let Some(pose) = poses.get(&link.name) else {
            continue;
        };
        for v in &link.visual {
            let [x, y, z] = v.origin.xyz.0;
            let [r, p, w] = v.origin.rpy.0;
            let local = Isometry3::from_parts(
                Translation3::new(x, y, z),
                UnitQuaternion::from_euler_angles(r, p, w),
            );
            let corners: Vec<Point3<f64>> = match &v.geometry {
                urdf_rs::Geometry::Box { size } => {
                    let [sx, sy, sz] = size.0;
                    (0..8)
                        .map(|i| {
                            let f =
                                |bit: i32, s: f64| if i & bit == 0 { -s / 2.0 } else { s / 2.0 };
                            Point3::new(f(1, sx), f(2, sy), f(4, sz))
                        })
                        .collect()
                }
                urdf_rs::Geometry::Cylinder { radius, length } => (0..24)
                    .flat_map(|k| {
                        let a = k as f64 / 12.0 * std::f64::consts::PI;
                        [-1.0, 1.0].map(|s| {
                            Point3::new(radius * a.cos(), radius * a.sin(), s * length / 2.0)
                        })
                    })
                    .collect(),
                _ => continue,
            };
            let rgba = v
                .material
                .as_ref()
                .and_then(|m| colors.get(m.name.as_str()))
                .copied()
                .unwrap_or([0.6, 0.6, 0.6, 1.0]);
            out.push(Shape {
                points: corners.iter().map(|c| pose * (local * c)).collect(),
                color: format!(
                    "rgb({},{},{})",
                    (rgba[0] * 255.0) as u8,
                    (rgba[1] * 255.0) as u8,
                    (rgba[2] * 255.0) as u8
                ),
            });
        }
    }
    out
}

/// One view: `axes` picks the plane (0 = x, 1 = y, 2 = z); shapes are drawn far to near along `depth`.
fn view(
    svg: &mut String,
    shapes: &[Shape],
    axes: (usize, usize),
    depth: usize,
    origin: P2,
    scale: f64,
    title: &str,
) {
    let mut order: Vec<&Shape> = shapes.iter().collect();
    let mean = |s: &Shape| s.points.iter().map(|p| p[depth]).sum::<f64>() / s.points.len() as f64;
    // side view looks along -y (far = +y); top view looks down (far = low z)
    order.sort_by(|a, b| {
        if depth == 1 {
            mean(b).total_cmp(&mean(a))
        } else {
            mean(a).total_cmp(&mean(b))
        }
    });
    let _ = writeln!(
        svg,
        r#"<text x="{:.0}" y="24" font-family="sans-serif" font-size="15">{title}</text>"#,
        origin.0 - 40.0
    );
    for s in order {
        let pts = hull(
            s.points
                .iter()
                .map(|p| (origin.0 + p[axes.0] * scale, origin.1 - p[axes.1] * scale))
                .collect(),
        );
        let d: Vec<String> = pts.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
        let _ = writeln!(
            svg,
            r#"<polygon points="{}" fill="{}" stroke="black" stroke-width="0.6" fill-opacity="0.92"/>"#,
            d.join(" "),
            s.color
        );
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, urdf_path, out_path] = args.as_slice() else {
        return Err("usage: render_svg URDF OUT.svg".into());
    };
    let text = std::fs::read_to_string(urdf_path)?;
    let robot = urdf_rs::read_from_string(&text)?;
    let model = RobotModel::from_urdf_str(&text, urdf_path)?;
    let arm = Arm::default();
    let reach = ArmState {
        joints: arm.solve_position(&Vector3::new(0.24, 0.06, 0.09), 0.0)?,
        gripper_opening: 0.8,
    };
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="1450" height="440" viewBox="0 0 1450 440" style="background:#fff">"#
    );
    for (i, (state, label)) in [
        (ArmState::default(), "home (side)"),
        (reach, "tool0 at 0.24, 0.06, 0.09 (side)"),
    ]
    .iter()
    .enumerate()
    {
        let poses = model.link_poses(&state.joint_positions(&arm.geometry));
        let s = shapes(&robot, &poses);
        let x0 = 130.0 + i as f64 * 680.0;
        view(&mut svg, &s, (0, 2), 1, (x0, 420.0), 1300.0, label);
        view(&mut svg, &s, (0, 1), 2, (x0 + 450.0, 230.0), 500.0, "top");
    }
    svg.push_str("</svg>\n");
    std::fs::write(out_path, svg)?;
    println!("wrote {out_path}");
    Ok(())
}
