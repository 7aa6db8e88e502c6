#!/usr/bin/env python3
"""Computes the SRDF's <disable_collisions> pairs from urdf/eezybot.urdf.

What it does (python3 + numpy, no ROS):

1. Reads every link's <collision> boxes and cylinders and every joint of the URDF.
2. Samples the arm over what MoveIt can plan: a grid over base_joint, shoulder_joint,
   elbow_joint within config/arm.yaml's per-joint limits and gripper_joint within
   0 .. gripper_open_rad. MoveIt cannot enforce the coupled forearm_elevation limit
   (shoulder + elbow), so by default the grid covers the whole box of per-joint limits
   (--coupled restricts it to the arm's real workspace). The passive joints are set
   from the linkage relations (PASSIVE below, the same as libs/kinematics
   PassiveJoints::from_arm), then every URDF <mimic> joint from its tag: the claw's
   second finger, and the three linkage joints that follow one joint
   (drive_link_joint, level_link_joint, triangle_joint), whose tags must state
   PASSIVE's relation (checked: the script stops otherwise).
3. Checks every pair of links with collision geometry in every sample: boxes with the
   separating-axis test, a cylinder as the square prism around it (conservative: it can
   only find more contacts, never fewer). Two shapes that overlap by less than
   TOUCH_M (1e-6 m) count as apart.
4. Classifies each pair like MoveIt Setup Assistant does:
   - Adjacent: a joint connects the two links (through fixed joints too);
   - Default:  the pair collides at the home pose (compute_ik's start state);
   - Always:   the pair collides in every sample;
   - Never:    the pair collides in no sample;
   - User:     a pair the real mechanism pins together (LOOP_PINS: the closed loops the
               URDF models open) that overlaps in some samples because the boxes are
               coarse where the pin is: it touches by design, like an adjacent pair.
   Pairs that collide in some samples only stay enabled: they are real self-collisions
   (or contacts MoveIt must know about), printed with the share of samples.

It also checks that the URDF's open chains close (the parallelogram pins meet), which
is the evidence that the passive joints are the linear functions in PASSIVE and that
the URDF's mimic tags (which override PASSIVE for their joints) are right, offsets
included.

Usage: compute_disabled_collisions.py [--urdf PATH] [--arm-config PATH] [--srdf]
  --srdf prints the <disable_collisions> block for config/eezybot_arm_mk2.srdf.
"""
import argparse
import itertools
import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
TOUCH_M = 1e-6

# Passive joint = sum(coefficient * actuated joint): PassiveJoints::from_arm in
# libs/kinematics/src/lib.rs (phi = shoulder + elbow).
PASSIVE = {
    "wrist_joint": {"shoulder_joint": -1.0, "elbow_joint": -1.0},
    "crank_joint": {"shoulder_joint": 1.0, "elbow_joint": 1.0},
    "drive_link_joint": {"elbow_joint": -1.0},
    "level_link_joint": {"shoulder_joint": 1.0},
    "triangle_joint": {"shoulder_joint": -1.0},
    "upper_link_joint": {"shoulder_joint": 1.0, "elbow_joint": 1.0},
}
# Links that the real linkage pins together although no URDF joint joins them (the
# loop closures that the open-chain URDF cuts, docs/robot.md "The linkage in a tree").
LOOP_PINS = {
    ("drive_link", "forearm"),      # drive link -> forearm's rear lever
    ("front_plate", "upper_link"),  # upper link -> front plate's upper pin
    ("forearm", "triangle_link"),   # triangle link on the elbow axle
    ("main_arm", "triangle_link"),
    ("crank", "main_arm"),          # crank on the shoulder axle
}
HOME = {"base_joint": 0.0, "shoulder_joint": math.pi / 2, "elbow_joint": -math.pi / 2, "gripper_joint": 0.0}


def vec(text, default="0 0 0"):
    return np.array([float(x) for x in (text or default).split()])


def load_urdf(path):
    root = ET.parse(path).getroot()
    links = {}
    for link in root.findall("link"):
        shapes = []
        for col in link.findall("collision"):
            origin = col.find("origin")
            xyz = vec(origin.get("xyz") if origin is not None else None)
            rpy = vec(origin.get("rpy") if origin is not None else None)
            if np.any(rpy != 0):
                raise SystemExit(f"{link.get('name')}: collision rpy is not supported")
            geom = col.find("geometry")[0]
            if geom.tag == "box":
                half = vec(geom.get("size")) / 2
            elif geom.tag == "cylinder":  # z-axis cylinder -> square prism around it
                r, h = float(geom.get("radius")), float(geom.get("length"))
                half = np.array([r, r, h / 2])
            else:
                raise SystemExit(f"{link.get('name')}: {geom.tag} is not supported")
            shapes.append((xyz, half))
        links[link.get("name")] = shapes
    joints = {}
    for j in root.findall("joint"):
        origin = j.find("origin")
        if origin is not None and np.any(vec(origin.get("rpy")) != 0):
            raise SystemExit(f"{j.get('name')}: joint rpy is not supported")
        axis = j.find("axis")
        mimic = j.find("mimic")
        joints[j.get("name")] = {
            "type": j.get("type"),
            "parent": j.find("parent").get("link"),
            "child": j.find("child").get("link"),
            "xyz": vec(origin.get("xyz") if origin is not None else None),
            "axis": vec(axis.get("xyz")) if axis is not None else np.array([1.0, 0, 0]),
            "mimic": None if mimic is None else (mimic.get("joint"), float(mimic.get("multiplier", 1)), float(mimic.get("offset", 0))),
        }
    return links, joints


def mimic_tag_problems(joints):
    """Linkage joints whose URDF <mimic> tag is not PASSIVE's relation (one leader, the
    same multiplier, offset 0): [text]. Joints without a tag are not checked."""
    problems = []
    for name, terms in PASSIVE.items():
        mimic = joints[name]["mimic"]
        if mimic is None:
            continue
        leader, mult, off = mimic
        if terms != {leader: mult} or off != 0.0:
            problems.append(f"{name}: <mimic joint={leader} multiplier={mult:g} offset={off:g}> "
                            f"but the linkage gives {terms}")
    return problems


def rotation(axis, q):
    """Rodrigues: rotation matrices for angles q (N,) about a unit axis -> (N, 3, 3)."""
    a = axis / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    s, c = np.sin(q)[:, None, None], np.cos(q)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


def joint_values(samples, joints):
    """Every non-fixed joint's value for each sample of the actuated joints."""
    values = dict(samples)
    for name, terms in PASSIVE.items():
        values[name] = sum(c * samples[j] for j, c in terms.items())
    for name, j in joints.items():
        if j["mimic"]:
            leader, mult, off = j["mimic"]
            values[name] = mult * values[leader] + off
    return values


def forward(joints, values, n):
    """World rotation (N,3,3) and position (N,3) of every link."""
    children = {}
    for name, j in joints.items():
        children.setdefault(j["parent"], []).append(name)
    roots = {j["parent"] for j in joints.values()} - {j["child"] for j in joints.values()}
    (root,) = roots
    pose = {root: (np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)))}
    stack = [root]
    while stack:
        parent = stack.pop()
        R, p = pose[parent]
        for name in children.get(parent, []):
            j = joints[name]
            p_child = p + R @ j["xyz"]
            if j["type"] == "fixed":
                R_child = R
            else:
                R_child = R @ rotation(j["axis"], values[name])
            pose[j["child"]] = (R_child, p_child)
            stack.append(j["child"])
    return pose


def world_boxes(links, pose):
    """link -> list of (centre (N,3), axes (N,3,3) columns, half extents (3,))."""
    out = {}
    for link, shapes in links.items():
        if not shapes:
            continue
        R, p = pose[link]
        out[link] = [(p + R @ xyz, R, half) for xyz, half in shapes]
    return out


def obb_overlap(c1, R1, h1, c2, R2, h2):
    """Separating-axis test, vectorised over samples: True where the boxes overlap by
    more than TOUCH_M along every axis."""
    d = c2 - c1
    axes = [R1[:, :, i] for i in range(3)] + [R2[:, :, i] for i in range(3)]
    for i in range(3):
        for k in range(3):
            cr = np.cross(R1[:, :, i], R2[:, :, k])
            norm = np.linalg.norm(cr, axis=1, keepdims=True)
            axes.append(np.where(norm > 1e-9, cr / np.maximum(norm, 1e-12), R1[:, :, i]))
    overlap = np.ones(len(c1), dtype=bool)
    for a in axes:
        r1 = sum(h1[i] * np.abs(np.einsum("nj,nj->n", a, R1[:, :, i])) for i in range(3))
        r2 = sum(h2[i] * np.abs(np.einsum("nj,nj->n", a, R2[:, :, i])) for i in range(3))
        dist = np.abs(np.einsum("nj,nj->n", a, d))
        overlap &= dist < r1 + r2 - TOUCH_M
    return overlap


def link_collisions(boxes, a, b):
    hit = np.zeros(len(boxes[a][0][0]), dtype=bool)
    for (c1, R1, h1), (c2, R2, h2) in itertools.product(boxes[a], boxes[b]):
        hit |= obb_overlap(c1, R1, h1, c2, R2, h2)
    return hit


def samples_from(arm_config, steps=13, gripper_steps=3, coupled=False):
    cfg = yaml.safe_load(Path(arm_config).read_text())
    lim = {k: [math.radians(v) for v in vals] for k, vals in cfg["limits_deg"].items()}
    grid = []
    for t, s, e, g in itertools.product(
        np.linspace(*lim["base"], steps), np.linspace(*lim["shoulder"], steps),
        np.linspace(*lim["elbow"], steps), np.linspace(0.0, cfg["geometry"]["gripper_open_rad"], gripper_steps),
    ):
        phi = s + e
        if not coupled or lim["forearm_elevation"][0] - 1e-9 <= phi <= lim["forearm_elevation"][1] + 1e-9:
            grid.append((t, s, e, g))
    grid.append(tuple(HOME[k] for k in ("base_joint", "shoulder_joint", "elbow_joint", "gripper_joint")))
    arr = np.array(grid)
    return {"base_joint": arr[:, 0], "shoulder_joint": arr[:, 1], "elbow_joint": arr[:, 2], "gripper_joint": arr[:, 3]}


def adjacent_pairs(links, joints):
    """Pairs of links with geometry joined by one joint, looking through links without
    geometry and fixed joints (Setup Assistant's 'Adjacent')."""
    parent_of = {j["child"]: j["parent"] for j in joints.values()}
    pairs = set()
    for child in parent_of:
        if not links.get(child):
            continue
        p = parent_of.get(child)
        while p is not None and not links.get(p):
            p = parent_of.get(p)
        if p is not None:
            pairs.add(tuple(sorted((p, child))))
    return pairs


def closure_errors(joints, links, pose):
    """How far apart the pins of the closed loops are (m), max over samples: the
    URDF models each loop open, so these close only if PASSIVE is right."""
    def point(link, xyz):
        R, p = pose[link]
        return p + R @ np.asarray(xyz, dtype=float)

    def plane(d):
        """The loops are planar in the turntable's x-z plane and the side links sit at
        other y: the difference in the turntable frame, its y dropped."""
        R = pose["turntable"][0]
        local = np.einsum("nji,nj->ni", R, d)
        return local[:, [0, 2]]

    L2 = joints["elbow_joint"]["xyz"][0]
    L3 = joints["wrist_joint"]["xyz"][0]
    crank = -joints["drive_link_joint"]["xyz"][0]
    out = {
        # drive link's far end = the forearm's rear lever (crank length behind the elbow)
        "drive_link end = forearm rear lever": point("drive_link", [L2, 0, 0]) - point("forearm", [-crank, 0, 0]),
        # the triangle link's elbow pin (level link parallel to the main arm)
        "triangle_link elbow pin = elbow axis": point("triangle_link", -joints["level_link_joint"]["xyz"] + joints["shoulder_joint"]["xyz"]) - point("forearm", [0, 0, 0]),
        # upper link's far end = the front plate's upper pin
        "upper_link end = front plate pin": point("upper_link", [L3, 0, 0]) - point("front_plate", joints["upper_link_joint"]["xyz"] + joints["level_link_joint"]["xyz"] - joints["shoulder_joint"]["xyz"]),
    }
    errs = {k: float(np.max(np.linalg.norm(plane(v), axis=1))) for k, v in out.items()}
    # the front plate stays level: its x axis has no z component
    errs["front_plate level (|x_z|)"] = float(np.max(np.abs(pose["front_plate"][0][:, 2, 0])))
    errs["triangle_link level (|x_z|)"] = float(np.max(np.abs(pose["triangle_link"][0][:, 2, 0])))
    return errs


def classify(urdf, arm_config, steps=13, coupled=False):
    links, joints = load_urdf(urdf)
    problems = mimic_tag_problems(joints)
    if problems:
        raise SystemExit("URDF mimic tags disagree with the linkage:\n  " + "\n  ".join(problems))
    samples = samples_from(arm_config, steps, coupled=coupled)
    n = len(samples["base_joint"])
    values = joint_values(samples, joints)
    pose = forward(joints, values, n)
    boxes = world_boxes(links, pose)
    home = {k: np.array([v]) for k, v in HOME.items()}
    home_pose = forward(joints, joint_values(home, joints), 1)
    home_boxes = world_boxes(links, home_pose)
    adjacent = adjacent_pairs(links, joints)
    result, sometimes = {}, {}
    for a, b in itertools.combinations(sorted(boxes), 2):
        pair = (a, b)
        hits = link_collisions(boxes, a, b)
        if pair in adjacent:
            result[pair] = "Adjacent"
        elif link_collisions(home_boxes, a, b)[0]:
            result[pair] = "Always" if hits.all() else "Default"
        elif hits.all():
            result[pair] = "Always"
        elif not hits.any():
            result[pair] = "Never"
        elif pair in LOOP_PINS:
            result[pair] = "User"
        else:
            sometimes[pair] = float(hits.mean())
    return result, sometimes, n, closure_errors(joints, links, pose)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--urdf", default=REPO / "urdf" / "eezybot.urdf")
    ap.add_argument("--arm-config", default=REPO / "config" / "arm.yaml")
    ap.add_argument("--steps", type=int, default=13)
    ap.add_argument("--coupled", action="store_true", help="sample only within the coupled forearm_elevation limit")
    ap.add_argument("--srdf", action="store_true", help="print the SRDF block only")
    args = ap.parse_args()
    result, sometimes, n, closures = classify(args.urdf, args.arm_config, args.steps, args.coupled)
    if args.srdf:
        for (a, b), reason in sorted(result.items()):
            print(f'  <disable_collisions link1="{a}" link2="{b}" reason="{reason}"/>')
        return 0
    region = "the coupled limits" if args.coupled else "the per-joint limits"
    print(f"{n} samples (grid {args.steps}^3 x 3 gripper steps within {region}, plus home)")
    for reason in ("Adjacent", "Always", "Default", "Never", "User"):
        pairs = sorted(p for p, r in result.items() if r == reason)
        print(f"{reason}: {len(pairs)}")
        for a, b in pairs:
            print(f"  {a} - {b}")
    print(f"left enabled (collide in some samples): {len(sometimes)}")
    for (a, b), share in sorted(sometimes.items()):
        print(f"  {a} - {b}: {share:.2%} of samples")
    print("loop closures (max over samples):")
    for k, v in closures.items():
        print(f"  {k}: {v:.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
