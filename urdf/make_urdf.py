#!/usr/bin/env python3
"""Writes urdf/eezybot.urdf from the dimensions of docs/robot.md.

The closed linkages of the EezyBotArm Mk2 are modelled as open chains (docs/robot.md's
chains 1-4): passive joints whose angles compute_ik publishes on
joint_states (see eezybot_kinematics::PassiveJoints). The three that follow one
actuated joint linearly carry a <mimic> tag (drive_link_joint = -elbow,
level_link_joint = shoulder, triangle_joint = -shoulder, offset 0: their zero is the
kinematics' zero), so that a tool that reads only the URDF (MoveIt, RViz) poses them
from the actuated joints; wrist_joint, crank_joint and upper_link_joint follow
shoulder + elbow, which <mimic> cannot say. The fixed frame wrist_pivot is there for
MoveIt's IK (moveit_config/README.md). Inertias are those of the
boxes/cylinders drawn, with plausible masses of the printed parts and servos.
Run it after changing a dimension; `cargo test -p eezybot_kinematics` checks
that the URDF and the kinematics library agree.
"""
import math
from pathlib import Path

H, L2, L3, TOOL_DX = 0.094, 0.135, 0.147, 0.0393
BASE_TOP = 0.030                   # turntable plane above base_link
CRANK, PIVOT = 0.057, (-0.038, 0.0202)
SIDE = 0.022                       # lateral offset of the side linkages
UPPER_PIN = (0.0, 0.03)            # upper-link pins above the elbow / wrist pivots
GRIPPER_OPEN = 0.6
deg = math.radians

COLORS = {
    "grey": "0.35 0.35 0.38 1", "orange": "0.95 0.45 0.05 1", "blue": "0.15 0.35 0.85 1",
    "black": "0.1 0.1 0.1 1", "white": "0.9 0.9 0.9 1",
}


def fmt(*v):
    return " ".join(f"{x:.6g}" for x in v)


def box_inertia(m, sx, sy, sz):
    return m * (sy**2 + sz**2) / 12, m * (sx**2 + sz**2) / 12, m * (sx**2 + sy**2) / 12


def cyl_inertia(m, r, h):
    return m * (3 * r * r + h * h) / 12, m * (3 * r * r + h * h) / 12, m * r * r / 2


def link(name, color, mass, shapes, com=(0, 0, 0)):
    """shapes: list of ('box', (sx,sy,sz), (x,y,z)) or ('cyl', (r,h), (x,y,z))."""
    vis = []
    kind, size, _ = shapes[0]
    ixx, iyy, izz = box_inertia(mass, *size) if kind == "box" else cyl_inertia(mass, *size)
    for kind, size, xyz in shapes:
        geom = f'<box size="{fmt(*size)}"/>' if kind == "box" else f'<cylinder radius="{fmt(size[0])}" length="{fmt(size[1])}"/>'
        vis.append(
            f'    <visual>\n      <origin xyz="{fmt(*xyz)}" rpy="0 0 0"/>\n      <geometry>{geom}</geometry>\n'
            f'      <material name="{color}"/>\n    </visual>\n'
            f'    <collision>\n      <origin xyz="{fmt(*xyz)}" rpy="0 0 0"/>\n      <geometry>{geom}</geometry>\n    </collision>\n'
        )
    return (
        f'  <link name="{name}">\n' + "".join(vis)
        + f'    <inertial>\n      <origin xyz="{fmt(*com)}" rpy="0 0 0"/>\n      <mass value="{fmt(mass)}"/>\n'
        f'      <inertia ixx="{ixx:.3e}" ixy="0" ixz="0" iyy="{iyy:.3e}" iyz="0" izz="{izz:.3e}"/>\n    </inertial>\n  </link>\n'
    )


def joint(name, kind, parent, child, xyz, axis=None, limits=None, mimic=None, comment=None):
    s = f"  <!-- {comment} -->\n" if comment else ""
    s += f'  <joint name="{name}" type="{kind}">\n    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
    s += f'    <origin xyz="{fmt(*xyz)}" rpy="0 0 0"/>\n'
    if axis:
        s += f'    <axis xyz="{fmt(*axis)}"/>\n'
    if limits:
        lo, hi, vel = limits
        s += f'    <limit lower="{lo:.6f}" upper="{hi:.6f}" effort="1.0" velocity="{vel:g}"/>\n'
    if mimic:
        s += f'    <mimic joint="{mimic[0]}" multiplier="{mimic[1]:g}" offset="0"/>\n'
    return s + "  </joint>\n"


PITCH = (0, -1, 0)  # positive angle = elevation (x towards +z)
MG995 = 5.2         # rad/s, 0.2 s per 60 deg
SG90 = 8.7          # rad/s, 0.12 s per 60 deg
alpha = (deg(42.5), deg(125))
elbow = (deg(-145), deg(-60))
phi = (deg(-65), deg(20))

parts = []
parts.append(link("base_link", "grey", 0.35, [("cyl", (0.06, BASE_TOP), (0, 0, BASE_TOP / 2))], (0, 0, BASE_TOP / 2)))
parts.append(joint("base_joint", "revolute", "base_link", "turntable", (0, 0, BASE_TOP), (0, 0, 1), (deg(-45), deg(45), MG995 / 2),
                   comment="theta1: base yaw through the 25->50 tooth gear pair"))
parts.append(link("turntable", "grey", 0.12, [
    ("cyl", (0.045, 0.01), (0, 0, 0.005)),
    ("box", (0.03, 0.006, H - BASE_TOP), (0, 0.03, (H - BASE_TOP) / 2)),
    ("box", (0.03, 0.006, H - BASE_TOP), (0, -0.03, (H - BASE_TOP) / 2)),
], (0, 0, 0.02)))
parts.append(joint("shoulder_joint", "revolute", "turntable", "main_arm", (0, 0, H - BASE_TOP), PITCH, (*alpha, MG995),
                   comment="alpha: main-arm elevation above horizontal"))
parts.append(link("main_arm", "orange", 0.05, [("box", (L2 + 0.02, 0.012, 0.02), (L2 / 2, 0, 0))], (L2 / 2, 0, 0)))
parts.append(joint("elbow_joint", "revolute", "main_arm", "forearm", (L2, 0, 0), PITCH, (*elbow, MG995),
                   comment="phi - alpha: forearm relative to the main arm (the forearm servo sets phi through chain 2)"))
parts.append(link("forearm", "orange", 0.06, [("box", (L3 + CRANK, 0.012, 0.016), ((L3 - CRANK) / 2, 0, 0))], ((L3 - CRANK) / 2, 0, 0)))
# A frame for MoveIt's IK of the 3-DOF arm (moveit_config: group `arm` is the chain
# base_link -> wrist_pivot). tool0 hangs below the passive wrist_joint (= -phi), which a
# URDF <mimic> cannot express (it follows two joints), so no solver that only knows the
# actuated joints can place tool0; this point is on the forearm itself, at the wrist
# pivot (wrist_joint's origin). tool0 = wrist_pivot + (TOOL_DX, 0, 0) in the turntable's
# (level) frame: the plate stays level. No geometry, so no collision pairs change.
parts.append(joint("wrist_pivot_joint", "fixed", "forearm", "wrist_pivot", (L3, 0, 0),
                   comment="wrist pivot on the forearm, for MoveIt's IK: tool0 = this point + tool_dx, level"))
parts.append('  <link name="wrist_pivot"/>\n')
parts.append(joint("wrist_joint", "revolute", "forearm", "front_plate", (L3, 0, 0), PITCH, (-phi[1], -phi[0], MG995),
                   comment="passive, = -phi: the parallelograms keep the front plate level"))
parts.append(link("front_plate", "white", 0.03, [("box", (0.01, 0.05, 0.045), (0.005, 0, 0.005)),
                                                 ("box", (TOOL_DX, 0.03, 0.008), (TOOL_DX / 2, 0, -0.012))], (0.01, 0, 0)))
parts.append(joint("tool0_joint", "fixed", "front_plate", "tool0", (TOOL_DX, 0, 0), comment="tool point: wrist pivot + tool_dx, level"))
parts.append('  <link name="tool0"/>\n')
parts.append(joint("gripper_joint", "revolute", "front_plate", "claw_left", (0.012, 0.012, -0.006), (0, 0, 1), (0, GRIPPER_OPEN, SG90),
                   comment="claw opening (SG90): 0 closed"))
parts.append(link("claw_left", "black", 0.005, [("box", (0.045, 0.005, 0.015), (0.0225, 0, 0))], (0.0225, 0, 0)))
parts.append(joint("gripper_mimic_joint", "revolute", "front_plate", "claw_right", (0.012, -0.012, -0.006), (0, 0, 1), (-GRIPPER_OPEN, 0, SG90),
                   mimic=("gripper_joint", -1), comment="second finger, geared to the first"))
parts.append(link("claw_right", "black", 0.005, [("box", (0.045, 0.005, 0.015), (0.0225, 0, 0))], (0.0225, 0, 0)))
# chain 2: forearm drive
parts.append(joint("crank_joint", "revolute", "turntable", "crank", (0, SIDE, H - BASE_TOP), PITCH, (*phi, MG995),
                   comment="passive chain 2, = phi: crank on the shoulder axis, driven by the forearm servo"))
parts.append(link("crank", "blue", 0.008, [("box", (CRANK, 0.005, 0.012), (-CRANK / 2, 0, 0))], (-CRANK / 2, 0, 0)))
parts.append(joint("drive_link_joint", "revolute", "crank", "drive_link", (-CRANK, 0, 0), PITCH, (-elbow[1], -elbow[0], MG995),
                   mimic=("elbow_joint", -1),
                   comment="passive, = alpha - phi = -elbow (a URDF mimic): 135 mm link parallel to the main arm, pinned to the forearm's rear lever"))
parts.append(link("drive_link", "blue", 0.01, [("box", (L2, 0.005, 0.008), (L2 / 2, 0, 0))], (L2 / 2, 0, 0)))
# chains 3 and 4: levelling
parts.append(joint("level_link_joint", "revolute", "turntable", "level_link", (PIVOT[0], -SIDE, H - BASE_TOP + PIVOT[1]), PITCH, (*alpha, MG995),
                   mimic=("shoulder_joint", 1),
                   comment="passive chain 3, = alpha (a URDF mimic): 135 mm link from the fixed pivot, parallel to the main arm"))
parts.append(link("level_link", "blue", 0.01, [("box", (L2, 0.005, 0.008), (L2 / 2, 0, 0))], (L2 / 2, 0, 0)))
tri_elbow = (-PIVOT[0], SIDE, -PIVOT[1])
tri_upper = (-PIVOT[0] + UPPER_PIN[0], 0, -PIVOT[1] + UPPER_PIN[1])
parts.append(joint("triangle_joint", "revolute", "level_link", "triangle_link", (L2, 0, 0), PITCH, (-alpha[1], -alpha[0], MG995),
                   mimic=("shoulder_joint", -1),
                   comment="passive, = -alpha (a URDF mimic): the triangle link pivots on the elbow axle and stays level"))
parts.append(link("triangle_link", "blue", 0.01, [("box", (0.045, 0.005, 0.04), (0.02, 0, 0))], (0.02, 0, 0)))
parts.append(joint("upper_link_joint", "revolute", "triangle_link", "upper_link", tri_upper, PITCH, (*phi, MG995),
                   comment="passive chain 4, = phi: 147 mm link parallel to the forearm, pinned to the front plate"))
parts.append(link("upper_link", "blue", 0.01, [("box", (L3, 0.005, 0.008), (L3 / 2, 0, 0))], (L3 / 2, 0, 0)))

materials = "".join(f'  <material name="{n}"><color rgba="{c}"/></material>\n' for n, c in COLORS.items())
text = (
    '<?xml version="1.0"?>\n<!-- EezyBotArm Mk2. Generated by urdf/make_urdf.py from the dimensions in docs/robot.md: edit the script, not this. -->\n'
    '<robot name="eezybot_arm_mk2">\n' + materials + "".join(parts) + "</robot>\n"
)
Path(__file__).with_name("eezybot.urdf").write_text(text)
print(f"wrote {Path(__file__).with_name('eezybot.urdf')}")
