//! docs/parameters.md's compute_ik table is what `compute_ik::spec()` declares, and
//! docs/robot.md's tables of dimensions, joint limits and servos are the shipped
//! `config/arm.yaml` (the defaults compute_ik and serial_node run with).

use eezybot_kinematics::{ArmConfig, ServoCalibration, ServoMotionLimits};
use ros_plumbing::docs;
use std::fmt::Write as _;

const REGENERATE: &str = "cargo test -p compute_ik --test docs";

#[test]
fn the_parameters_page_lists_what_the_node_declares() {
    if let Err(why) = docs::check_node_parameters(&compute_ik::spec()) {
        panic!("{why}");
    }
}

/// A number as the docs write it: shortest form, a real minus sign.
fn num(x: f64) -> String {
    format!("{x}").replace('-', "−")
}

fn dimensions(c: &ArmConfig) -> String {
    let g = &c.geometry;
    let rows = [
        (
            "shoulder height H",
            "shoulder pivot above `base_link`",
            "shoulder_height_m",
            num(g.shoulder_height_m) + " m",
        ),
        (
            "main arm L2",
            "shoulder → elbow pivot",
            "main_arm_m",
            num(g.main_arm_m) + " m",
        ),
        (
            "forearm L3",
            "elbow → wrist pivot W",
            "forearm_m",
            num(g.forearm_m) + " m",
        ),
        (
            "tool offset tool_dx",
            "`tool0` = W + tool_dx forward, horizontal, in the arm's plane",
            "tool_dx_m",
            num(g.tool_dx_m) + " m",
        ),
        (
            "claw swing",
            "finger angle from closed to fully open",
            "gripper_open_rad",
            num(g.gripper_open_rad) + " rad",
        ),
    ];
    let mut s = String::from("| name | meaning | `geometry:` key | default |\n|---|---|---|---|\n");
    for (name, meaning, key, value) in rows {
        let _ = writeln!(s, "| {name} | {meaning} | `{key}` | {value} |");
    }
    s
}

fn joints(c: &ArmConfig) -> String {
    let l = &c.limits_deg;
    let deg = |r: [f64; 2]| format!("{}° … {}°", num(r[0]), num(r[1]));
    let rows = [
        (
            "`base_joint`",
            "θ1: base yaw; 0 = +x, positive counter-clockwise seen from +z",
            "base",
            deg(l.base),
        ),
        (
            "`shoulder_joint`",
            "α: main-arm elevation above horizontal (90° = vertical)",
            "shoulder",
            deg(l.shoulder),
        ),
        (
            "`elbow_joint`",
            "φ − α: forearm angle relative to the main arm (≤ 0; −90° at home)",
            "elbow",
            deg(l.elbow),
        ),
        (
            "(derived) φ = α + elbow",
            "forearm absolute elevation",
            "forearm_elevation",
            deg(l.forearm_elevation),
        ),
    ];
    let mut s = String::from(
        "| joint | meaning | `limits_deg:` key | default limits |\n|---|---|---|---|\n",
    );
    for (joint, meaning, key, limits) in rows {
        let _ = writeln!(s, "| {joint} | {meaning} | `{key}` | {limits} |");
    }
    let _ = writeln!(
        s,
        "| `gripper_joint` | claw opening (`gripper_target` 0 … 1) | | 0 … {} rad |",
        num(c.geometry.gripper_open_rad)
    );
    s
}

/// `offset + gain·input` as a formula, e.g. `90 − 2·θ1`.
fn formula(cal: &ServoCalibration, input: &str) -> String {
    let sign = if cal.gain < 0.0 { "−" } else { "+" };
    let gain = cal.gain.abs();
    let factor = if gain == 1.0 {
        String::new()
    } else {
        format!("{}·", num(gain))
    };
    format!("{} {sign} {factor}{input}", num(cal.offset_deg))
}

fn servos(c: &ArmConfig) -> String {
    let s_ = &c.servos;
    let m = &c.motion;
    let rows: [(&str, &str, &ServoCalibration, &ServoMotionLimits, &str); 4] = [
        ("base (8)", "θ1", &s_.base, &m.base, "θ1 in degrees"),
        (
            "shoulder (9)",
            "α",
            &s_.shoulder,
            &m.shoulder,
            "α in degrees",
        ),
        (
            "elbow (10)",
            "φ",
            &s_.elbow,
            &m.elbow,
            "φ in degrees: the forearm servo sets it directly",
        ),
        (
            "gripper (11)",
            "g",
            &s_.gripper,
            &m.gripper,
            "g = `gripper_target`, 0 closed … 1 open",
        ),
    ];
    let mut s = String::from(
        "| servo (pin) | servo angle (°) | where | allowed | pulse at 0° … 180° | max speed, acceleration |\n\
         |---|---|---|---|---|---|\n",
    );
    for (servo, input, cal, motion, note) in rows {
        let _ = writeln!(
            s,
            "| {servo} | {} | {note} | {}° … {}° | {} … {} µs | {} °/s, {} °/s² |",
            formula(cal, input),
            num(cal.min_deg),
            num(cal.max_deg),
            cal.pulse_min_us,
            cal.pulse_max_us,
            num(motion.max_velocity_deg_s),
            num(motion.max_acceleration_deg_s2),
        );
    }
    s
}

#[test]
fn the_robot_page_holds_the_shipped_arm_config() {
    let config = ArmConfig::shipped().expect("the shipped config/arm.yaml loads");
    let page = docs::repo_root().join("docs/robot.md");
    let sections = [
        ("robot dimensions", dimensions(&config)),
        ("robot joints", joints(&config)),
        ("robot servos", servos(&config)),
    ];
    for (name, table) in sections {
        if let Err(why) = docs::check_section(&page, name, &table, REGENERATE) {
            panic!("{why}");
        }
    }
}
