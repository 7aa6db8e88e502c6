#!/usr/bin/env python3
"""Trajectory execution of compute_ik's arm_controller (issue 21), for BENCHMARKS.md: a
MoveIt-like trajectory at the servos' speed limits sent through the
FollowJointTrajectory action by rclpy's ActionClient, and the time from a goal to the
arm's first motion.

    $EEZYBOT_PYTHON tests/bench/trajectory.py [--device virtual,simavr] [--runs 3]
        [--goals 60] [--fraction 0.97] [--lead base|elbow] [--ik-param motion_rate:=100]
        [--json FILE]

Needs release binaries (cargo build --release --bins; EEZYBOT_BIN_DIR overrides
target/release) and, for `simavr`, the firmware and its harness (make -C
firmware/servo_control all sim). The graph: compute_ik and serial_node, the Arduino
being the virtual one inside serial_node (`virtual`: port:=mock) or the servo_control
ELF in simavr behind a pty (`simavr`: tests/interop/servo_link.SimulatedUno), a private
ROS_DOMAIN_ID (conftest.DomainLease). Timing is never asserted: the program prints what
it measured and, where the issue sets a target, whether it was met; it exits non-zero
only when something failed (a goal refused or not finished, a node that died).

The trajectory (`tracking`, --runs per device): 6 points through the workspace after
MoveIt's start point at 0 s (the arm is first taken there by a slow goal), with
velocities (time_parameterize: the base sweeps -40 -> +40 -> 0 deg on trapezoidal
profiles at --fraction of its servo's velocity and acceleration limits, the shoulder
and the forearm's elevation on cosine profiles), timed by the same cubic Hermite rule
as libs/motion/src/trajectory.rs so that every segment stays within --fraction of the
servos' limits of config/arm.yaml (on the planner's axes: base, shoulder and the
forearm's elevation shoulder + elbow, which the elbow servo sets). header.stamp = the
send time + 0.1 s, so every point is due at a known instant on this machine's
CLOCK_REALTIME: stamp + time_from_start.
  (i)   tracking error, per joint and overall (the largest of the three joints at
        each sample), p50/p99/max of |error|:
        servo_state vs the trajectory at the instant the reply's stamp names (serial_node
        stamps each reply with its command's stamp: the servos against the plan, link
        latency not counted), also against the command of that stamp and the one
        before it (whether a reply reports its own command); the action feedback's
        error (desired now - the latest servo_state, as compute_ik reports it: the
        link's latency is in it); and
        compute_ik's own commands (joint_states) against the trajectory at their stamps.
        servo_state is turned back into joints here from config/arm.yaml's servo
        mapping, and compared with the feedback's `actual` (a wrong "actual" would show).
  (ii)  per point: lateness = DDS reception time of the first joint_states within
        0.03 rad (every joint) of the point, from 0.3 s before it but not before the
        previous point was due, minus the point's due time (target <= 20 ms; negative:
        early); and the error = the closest joint_states received within +-20 ms of the
        due time (target <= 0.03 rad). Also by joint_states' own stamps (compute_ik's
        step times, without the delivery).
  (iii) the last joint_states vs the last point (target: exactly, 0 rad).
  And serial_node's `frames_ramped_by_velocity_limit` during each trajectory (its
  velocity guard cutting a step short: the servo then lags the command).
The goals (`first motion`, --goals per device): a 0.15 rad base move over 0.4 s from
where the arm is, MoveIt's start point first, header.stamp zero (as MoveIt sends), one
after the other:
  accepted       time.time_ns() just before send_goal_async -> the goal response's
                 future done (rclpy's executor; its callback delay is in it)
  first motion   -> DDS reception time of the first joint_states that moved towards the
                 goal (target p50 <= 20 ms)
  first step     -> DDS reception time of the first joint_states of the goal (moved or
                 not: compute_ik's first step comes at once, at t = 0)
"""
import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
os.environ.setdefault("EEZYBOT_BIN_DIR", str(HERE.parents[1] / "target" / "release"))

import yaml  # noqa: E402
from action_msgs.msg import GoalStatus  # noqa: E402
from builtin_interfaces.msg import Duration, Time  # noqa: E402
from control_msgs.action import FollowJointTrajectory  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from conftest import REPO, DomainLease, NodeProcess, Observer, latest_status, status_values  # noqa: E402
from interop.servo_link import SimulatedUno  # noqa: E402

FIRMWARE = REPO / "firmware" / "servo_control"
ARM = ["base_joint", "shoulder_joint", "elbow_joint"]
SERVOS = ["base_servo", "shoulder_servo", "elbow_servo"]
CFG = yaml.safe_load((REPO / "config" / "arm.yaml").read_text())
CAL = [CFG["servos"][k] for k in ("base", "shoulder", "elbow")]
# the planner's axes (base, shoulder, forearm elevation): each servo's limit over |gain|
AXIS_VMAX = [math.radians(CFG["motion"][k]["max_velocity_deg_s"]) / abs(c["gain"])
             for k, c in zip(("base", "shoulder", "elbow"), CAL)]
AXIS_AMAX = [math.radians(CFG["motion"][k]["max_acceleration_deg_s2"]) / abs(c["gain"])
             for k, c in zip(("base", "shoulder", "elbow"), CAL)]
TOL_RAD = 0.03       # issue 21: within 0.03 rad of each point ...
LATE_S = 0.020       # ... no later than 20 ms
FIRST_MOTION_S = 0.020  # goal -> first motion, p50
LEAD_S = 0.1         # header.stamp = send time + this (the tracking runs)
DEEP = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)

# ---------------------------------------------------------------- the arm's mapping
def axes_of(j):
    return [j[0], j[1], j[1] + j[2]]


def joints_of(a):
    return [a[0], a[1], a[2] - a[1]]


def servo_state_joints(msg):
    """servo_state (servo horn angles, rad) back to the arm joints, by config/arm.yaml's
    mapping: servo deg = offset + gain * input deg (base: base_joint, shoulder:
    shoulder_joint, elbow: the forearm's elevation)."""
    a = []
    for name, c in zip(SERVOS, CAL):
        deg = math.degrees(msg.position[list(msg.name).index(name)])
        a.append(math.radians((deg - c["offset_deg"]) / c["gain"]))
    return joints_of(a)


def arm_joints(js):
    names = list(js.name)
    return [js.position[names.index(n)] for n in ARM]


# ---------------------------------------------------------------- cubic Hermite (libs/motion/src/trajectory.rs)
class Segment:
    def __init__(self, p0, v0, p1, v1, dt):
        d = p1 - p0
        self.c = (p0, v0, (3 * d - (2 * v0 + v1) * dt) / dt ** 2, (-2 * d + (v0 + v1) * dt) / dt ** 3)
        self.dt = dt

    def at(self, tau):
        c0, c1, c2, c3 = self.c
        return c0 + tau * (c1 + tau * (c2 + tau * c3))

    def max_speed(self):
        _, c1, c2, c3 = self.c
        taus = [0.0, self.dt]
        if c3 != 0.0:
            t = -c2 / (3 * c3)
            if 0.0 < t < self.dt:
                taus.append(t)
        return max(abs(c1 + tau * (2 * c2 + 3 * c3 * tau)) for tau in taus)

    def max_acceleration(self):
        _, _, c2, c3 = self.c
        return max(abs(2 * c2), abs(2 * c2 + 6 * c3 * self.dt))


class Plan:
    """Knots in axis space: times (0 first), positions, velocities (the start at rest)."""

    def __init__(self, times, positions, velocities):
        self.times, self.positions, self.velocities = times, positions, velocities

    def seg(self, k, j):
        return Segment(self.positions[k][j], self.velocities[k][j], self.positions[k + 1][j],
                       self.velocities[k + 1][j], self.times[k + 1] - self.times[k])

    def sample_axes(self, t):
        if t >= self.times[-1]:
            return list(self.positions[-1])
        t = max(t, 0.0)
        k = max(0, min(sum(1 for x in self.times if x <= t) - 1, len(self.times) - 2))
        return [self.seg(k, j).at(t - self.times[k]) for j in range(3)]

    def sample(self, t):
        return joints_of(self.sample_axes(t))

    def peaks(self):
        """Per axis: the largest velocity and acceleration over the whole trajectory, as a
        fraction of the axis's limit."""
        v = [max(self.seg(k, j).max_speed() for k in range(len(self.times) - 1)) / AXIS_VMAX[j] for j in range(3)]
        a = [max(self.seg(k, j).max_acceleration() for k in range(len(self.times) - 1)) / AXIS_AMAX[j]
             for j in range(3)]
        return v, a


def _feasible(p0, v0, p1, v1, dt, vmax, amax, slack=1e-9):
    """Every axis of the segment within vmax and amax (trajectory.rs's check; `slack`
    relative, for rounding)."""
    for j in range(3):
        s = Segment(p0[j], v0[j], p1[j], v1[j], dt)
        if s.max_speed() > vmax[j] * (1 + slack) or s.max_acceleration() > amax[j] * (1 + slack):
            return False
    return True


def trapezoid(x0, x1, v, a, t):
    """Position and velocity at `t` of a rest-to-rest move x0 -> x1 at speed `v`,
    acceleration `a` (a triangle when too short to cruise)."""
    d, sgn = abs(x1 - x0), math.copysign(1.0, x1 - x0)
    tr = min(v / a, math.sqrt(d / a))
    vp = a * tr
    tc = max(0.0, (d - a * tr * tr) / vp)
    total = 2 * tr + tc
    t = min(max(t, 0.0), total)
    if t < tr:
        x, w = a * t * t / 2, a * t
    elif t < tr + tc:
        x, w = a * tr * tr / 2 + vp * (t - tr), vp
    else:
        r = total - t
        x, w = d - a * r * r / 2, a * r
    return x0 + sgn * x, sgn * w, total


def cosine(x0, x1, T, t):
    t = min(max(t, 0.0), T)
    return x0 + (x1 - x0) * (1 - math.cos(math.pi * t / T)) / 2, (x1 - x0) * math.pi / (2 * T) * math.sin(math.pi * t / T)


# The strokes (deg, from -> to) of each axis (base, shoulder, forearm elevation), by which
# servo leads at its limits: the base (the slowest axis: 150 deg/s at the joint through
# the 2:1 gear), or the elbow servo (the forearm's elevation, 300 deg/s).
STROKES = {
    "base": [[(-40, 40), (40, 0)], [(70, 95), (95, 75)], [(-50, 5), (5, -30)]],
    "elbow": [[(-12, 12), (12, 0)], [(70, 95), (95, 75)], [(-60, 15), (15, -30)]],
}


def time_parameterize(fraction, lead="base"):
    """A MoveIt-like trajectory (what a time-optimal parameterization samples into
    points): the `lead` axis (STROKES) moves out and back on trapezoidal speed profiles at
    `fraction` of its servo's velocity and acceleration limits, the other axes follow on
    cosine profiles of the same strokes. The points are the profiles sampled where the
    lead's profile changes (end of the ramp, the middle of the cruise, start of the
    braking, the end): positions and velocities. Between them the controller interpolates
    cubic Hermite segments (libs/motion/src/trajectory.rs), which follow a
    constant-acceleration ramp and a cruise exactly; a segment whose Hermite curve would
    need more than `fraction` of a limit (velocity: at an end or where it turns;
    acceleration: at an end) would be lengthened by 1 ms steps until it does not (none
    is: the followers stay well within their limits). Times in ns, as sent."""
    vmax = [v * fraction for v in AXIS_VMAX]
    amax = [a * fraction for a in AXIS_AMAX]
    strokes = [[(math.radians(a), math.radians(b)) for a, b in axis] for axis in STROKES[lead]]
    li = {"base": 0, "elbow": 2}[lead]
    knots = [(0.0, [axis[0][0] for axis in strokes], [0.0] * 3)]  # (t, axes, velocities)
    t0 = 0.0
    for stroke in range(2):
        a0, a1 = strokes[li][stroke]
        _, _, total = trapezoid(a0, a1, vmax[li], amax[li], 0.0)
        tr = min(vmax[li] / amax[li], math.sqrt(abs(a1 - a0) / amax[li]))
        # a cruise: its ends and middle; else (a triangle, or nearly): half-way up and down
        ts = [tr, total / 2, total - tr, total] if total - 2 * tr > 0.05 else [tr / 2, tr, total - tr / 2, total]
        for t in ts:
            x, v = [], []
            for j in range(3):
                if j == li:
                    xj, vj, _ = trapezoid(a0, a1, vmax[li], amax[li], t)
                else:
                    xj, vj = cosine(*strokes[j][stroke], total, t)
                x.append(xj)
                v.append(vj)
            knots.append((t0 + t, x, v))
        t0 += total
    times, positions, velocities = [0.0], [knots[0][1]], [knots[0][2]]
    for k in range(1, len(knots)):
        dt = knots[k][0] - knots[k - 1][0]
        while not _feasible(knots[k - 1][1], knots[k - 1][2], knots[k][1], knots[k][2], dt, vmax, amax, 1e-6):
            dt += 0.001
        times.append(round(times[-1] + dt, 9))
        positions.append(knots[k][1])
        velocities.append(knots[k][2])
    velocities[-1] = [0.0] * 3
    plan = Plan(times, positions, velocities)
    v, a = plan.peaks()
    assert max(v) <= fraction * (1 + 1e-6) and max(a) <= fraction * (1 + 1e-6), (v, a)
    # within the joint limits all the way (compute_ik checks the points only, and clamps
    # a command outside them: the benchmark's trajectory must not need that)
    lim = {k: (math.radians(lo), math.radians(hi)) for k, (lo, hi) in CFG["limits_deg"].items()}
    for i in range(int(times[-1] * 1000) + 1):
        q = plan.sample(i / 1000)
        for value, key in ((q[0], "base"), (q[1], "shoulder"), (q[2], "elbow"), (q[1] + q[2], "forearm_elevation")):
            assert lim[key][0] <= value <= lim[key][1], (key, i, math.degrees(value))
    return plan


def duration_msg(s):
    ns = int(round(s * 1e9))
    return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_msg(ns):
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def trajectory_msg(plan, stamp_ns_=0):
    """The JointTrajectory (joint space) of an axis-space plan, MoveIt's start point at 0 s first."""
    pts = []
    for t, p, v in zip(plan.times, plan.positions, plan.velocities):
        pts.append(JointTrajectoryPoint(positions=joints_of(p), velocities=joints_of(v), time_from_start=duration_msg(t)))
    return _traj(stamp_ns_, pts)


def _traj(stamp_ns_, pts):
    m = JointTrajectory(joint_names=ARM, points=pts)
    m.header.stamp = stamp_msg(stamp_ns_)
    return m


# ---------------------------------------------------------------- statistics
def pct(sorted_values, p):
    return sorted_values[min(len(sorted_values) - 1, int(round(p / 100 * (len(sorted_values) - 1))))]


def stats(values, scale=1.0):
    v = sorted(abs(x) * scale for x in values)
    if not v:
        return {"n": 0}
    return {"n": len(v), "p50": pct(v, 50), "p99": pct(v, 99), "max": v[-1]}


def signed_stats(values, scale=1.0):
    v = sorted(x * scale for x in values)
    if not v:
        return {"n": 0}
    return {"n": len(v), "min": v[0], "p50": pct(v, 50), "p99": pct(v, 99), "max": v[-1]}


# ---------------------------------------------------------------- the graph
class Graph:
    """compute_ik and serial_node on the virtual Arduino or the firmware in simavr, and an
    rclpy node with the action client and subscriptions that keep DDS reception times."""

    def __init__(self, device, domain, workdir, ik_params=()):
        self.device, self.procs, self.uno = device, [], None
        port = "mock"
        if device == "simavr":
            self.uno = SimulatedUno(workdir, FIRMWARE)
            port = str(self.uno.tty_path)
        self.o = Observer(domain, "trajectory_bench")
        self.procs.append(NodeProcess("compute_ik", ["--ros-args", "-p", "max_target_age:=0.0",
                                                      *[a for p in ik_params for a in ("-p", p)]], domain))
        self.procs.append(NodeProcess("serial_node", ["--ros-args", "-p", f"port:={port}"], domain))
        n = self.o.node
        self.js, self.ss, self.diags = [], [], []
        n.create_subscription(JointState, "/joint_states", self._keep(self.js), DEEP)
        n.create_subscription(JointState, "/servo_state", self._keep(self.ss), DEEP)
        n.create_subscription(DiagnosticArray, "/diagnostics", lambda m: self.diags.append((time.monotonic(), m)), DEEP)
        self.arm = ActionClient(n, FollowJointTrajectory, "arm_controller/follow_joint_trajectory")
        if not self.o.spin_until(self.arm.server_is_ready, 20):
            raise RuntimeError("arm_controller/follow_joint_trajectory was not discovered")
        if not self.o.spin_until(lambda: self.js and self.ss, 20):
            raise RuntimeError("no joint_states or servo_state: " + self.logs())
        self.o.spin_for(0.5)

    @staticmethod
    def _keep(table):
        # (DDS reception ns, stamp ns, joints)
        def cb(m, info):
            joints = arm_joints(m) if "base_joint" in m.name else servo_state_joints(m)
            table.append((info["received_timestamp"], stamp_ns(m.header), joints))
        return cb

    def joints(self):
        return self.js[-1][2]

    def send(self, goal, feedback=None, timeout=10):
        """(handle, t_send ns, t_accepted ns)."""
        done = {}
        t0 = time.time_ns()
        fut = self.arm.send_goal_async(goal, feedback_callback=feedback)
        fut.add_done_callback(lambda f: done.setdefault("t", time.time_ns()))
        if not self.o.spin_until(fut.done, timeout):
            raise RuntimeError("the goal was not answered")
        return fut.result(), t0, done.get("t", time.time_ns())

    def result(self, handle, timeout=20):
        fut = handle.get_result_async()
        if not self.o.spin_until(fut.done, timeout):
            raise RuntimeError("no result")
        return fut.result()

    def refusal(self):
        return status_values(latest_status(self.diags, "compute_ik")).get("last_trajectory", "?")

    def serial_counter(self, key):
        """A counter of serial_node's diagnostics, from a report that came after now."""
        n = len(self.diags)
        self.o.spin_until(lambda: any(s.name.startswith("serial_node") for _, a in self.diags[n:] for s in a.status), 5)
        return int(self.serial_diag().get(key, 0))

    def serial_diag(self):
        return status_values(latest_status(self.diags, "serial_node"))

    def move_to(self, joints, seconds=2.0):
        """A slow goal to `joints` (linear, within every limit), waited for."""
        goal = FollowJointTrajectory.Goal(trajectory=_traj(0, [JointTrajectoryPoint(
            positions=list(joints), time_from_start=duration_msg(seconds))]))
        h, _, _ = self.send(goal)
        if not h.accepted:
            raise RuntimeError(f"a move to {joints} was refused: {self.refusal()}")
        r = self.result(h)
        if r.status != GoalStatus.STATUS_SUCCEEDED:
            raise RuntimeError(f"a move to {joints} did not succeed: {r.status} {r.result.error_string}")
        self.o.spin_for(0.3)

    def logs(self):
        return " | ".join(f"{p.name}: {p.output()[-400:]}" for p in self.procs)

    def close(self):
        codes = [p.stop() for p in self.procs]
        self.o.close()
        if self.uno is not None:
            codes.append(self.uno.stop())
        return codes


# ---------------------------------------------------------------- (a) tracking
def tracking_run(g, plan_template, fraction):
    p0 = joints_of(plan_template.positions[0])
    g.move_to(p0)
    # the start exactly where compute_ik has the arm (its last command)
    start = g.joints()
    plan = Plan(plan_template.times, [axes_of(start)] + plan_template.positions[1:], plan_template.velocities)
    ramped0 = g.serial_counter("frames_ramped_by_velocity_limit")
    n_js, n_ss = len(g.js), len(g.ss)
    feedback = []
    stamp = time.time_ns() + int(LEAD_S * 1e9)
    goal = FollowJointTrajectory.Goal(trajectory=trajectory_msg(plan, stamp))
    h, t_send, t_acc = g.send(goal, feedback=lambda f: feedback.append((time.time_ns(), f.feedback)))
    if not h.accepted:
        raise RuntimeError(f"the trajectory was refused: {g.refusal()}")
    res = g.result(h, timeout=plan.times[-1] + 10)
    g.o.spin_for(0.5)
    if res.status != GoalStatus.STATUS_SUCCEEDED:
        raise RuntimeError(f"the trajectory did not succeed: status {res.status}: {res.result.error_string}")
    ramped = g.serial_counter("frames_ramped_by_velocity_limit") - ramped0
    js, ss = g.js[n_js:], g.ss[n_ss:]
    dur = plan.times[-1]
    t_of = lambda ns: (ns - stamp) / 1e9  # noqa: E731  seconds from the trajectory's start

    # (i) tracking
    servo_err = [[], [], []]      # servo_state vs the plan at its stamp
    for _, st, q in ss:
        t = t_of(st)
        if 0.0 <= t <= dur:
            d = plan.sample(t)
            for j in range(3):
                servo_err[j].append(q[j] - d[j])
    js_by_stamp = {st: q for _, st, q in g.js}
    stamps = sorted(js_by_stamp)
    order = {st: i for i, st in enumerate(stamps)}
    same_cmd = [[], [], []]        # servo_state vs the command (joint_states) of its own stamp
    prev_cmd = [[], [], []]        # ... and vs the command before it
    for _, st, q in ss:
        if 0.0 <= t_of(st) <= dur and st in order and order[st] > 0:
            c, pc = js_by_stamp[st], js_by_stamp[stamps[order[st] - 1]]
            for j in range(3):
                same_cmd[j].append(q[j] - c[j])
                prev_cmd[j].append(q[j] - pc[j])
    cmd_err = [[], [], []]         # joint_states vs the plan at its stamp
    for _, st, q in js:
        t = t_of(st)
        if 0.0 <= t <= dur + 0.1:
            d = plan.sample(t)
            for j in range(3):
                cmd_err[j].append(q[j] - d[j])
    fb_err = [[], [], []]          # the feedback's error (desired now - latest servo_state)
    fb_desired_off = []            # feedback.desired vs the plan at the feedback's stamp
    actual_mismatch = 0            # feedback.actual that is no recent servo_state as converted here
    for t_rx, f in feedback:
        for j in range(3):
            if len(f.error.positions) == 3:
                fb_err[j].append(f.error.positions[j])
        d = plan.sample(t_of(stamp_ns(f.header)))
        fb_desired_off.append(max(abs(a - b) for a, b in zip(f.desired.positions, d)))
        recent = [q for rx, _, q in g.ss if t_rx - 300_000_000 <= rx <= t_rx]
        if f.actual.positions and not any(max(abs(a - b) for a, b in zip(f.actual.positions, q)) < 1e-6 for q in recent):
            actual_mismatch += 1

    # (ii) per point
    points = []
    for i in range(1, len(plan.times)):
        due = stamp + int(round(plan.times[i] * 1e9))
        # from 0.3 s before the point, but not before the previous point was due (the arm
        # may pass the same place earlier, e.g. on the way out)
        since = max(due - 300_000_000, stamp + int(round(plan.times[i - 1] * 1e9)))
        target = joints_of(plan.positions[i])
        dist = [(rx, st, max(abs(a - b) for a, b in zip(q, target))) for rx, st, q in js]
        within = [rx for rx, _, e in dist if e <= TOL_RAD and rx >= since]
        near = [e for rx, _, e in dist if abs(rx - due) <= LATE_S * 1e9]
        near_st = [e for _, st, e in dist if abs(st - due) <= LATE_S * 1e9]
        first_st = [st for _, st, e in dist if e <= TOL_RAD and st >= since]
        points.append({
            "point": i, "t": plan.times[i],
            "late_ms": (within[0] - due) / 1e6 if within else None,
            "err_rad": min(near) if near else None,
            "late_stamp_ms": (first_st[0] - due) / 1e6 if first_st else None,
            "err_stamp_rad": min(near_st) if near_st else None,
        })
    # (iii) the end
    final = js[-1][2]
    end_err = max(abs(a - b) for a, b in zip(final, joints_of(plan.positions[-1])))
    return {"servo": servo_err, "same_cmd": same_cmd, "prev_cmd": prev_cmd, "command": cmd_err,
            "ramped": ramped, "feedback": fb_err, "points": points, "end_err": end_err,
            "feedback_desired_off_max": max(fb_desired_off) if fb_desired_off else None,
            "feedback_n": len(feedback), "actual_mismatch": actual_mismatch,
            "accepted_ms": (t_acc - t_send) / 1e6, "n_joint_states": len(js), "n_servo_state": len(ss)}


# ---------------------------------------------------------------- (b) goal -> first motion
def goal_trials(g, n):
    g.move_to([0.0, math.radians(85.0), math.radians(-105.0)])
    out = {"accepted": [], "first_motion": [], "first_step": [], "refused": 0, "failed": 0}
    for i in range(n):
        here = g.joints()
        sign = 1.0 if i % 2 == 0 else -1.0
        target = [here[0] + sign * 0.15, here[1], here[2]]
        goal = FollowJointTrajectory.Goal(trajectory=_traj(0, [
            JointTrajectoryPoint(positions=list(here), velocities=[0.0] * 3, time_from_start=duration_msg(0.0)),
            JointTrajectoryPoint(positions=target, velocities=[0.0] * 3, time_from_start=duration_msg(0.4))]))
        n_js = len(g.js)
        h, t_send, t_acc = g.send(goal)
        if not h.accepted:
            out["refused"] += 1
            continue
        r = g.result(h)
        if r.status != GoalStatus.STATUS_SUCCEEDED:
            out["failed"] += 1
        g.o.spin_for(0.1)
        new = [(rx, q) for rx, _, q in g.js[n_js:] if rx >= t_send]
        moved = [rx for rx, q in new if sign * (q[0] - here[0]) > 1e-9]
        out["accepted"].append((t_acc - t_send) / 1e6)
        if new:
            out["first_step"].append((new[0][0] - t_send) / 1e6)
        if moved:
            out["first_motion"].append((moved[0] - t_send) / 1e6)
    return out


# ---------------------------------------------------------------- report
def fmt(s, unit_scale=1.0, digits=4):
    if not s.get("n"):
        return "-"
    return " / ".join(f"{s[k] * unit_scale:.{digits}f}" for k in ("p50", "p99", "max"))


def summarize(device, runs, goals, serial_diag):
    out = {"device": device, "runs": len(runs)}
    for kind in ("servo", "same_cmd", "prev_cmd", "feedback", "command"):
        per_joint = [stats([e for r in runs for e in r[kind][j]]) for j in range(3)]
        overall = stats([max(abs(r[kind][j][k]) for j in range(3)) for r in runs for k in range(len(r[kind][0]))])
        out[kind] = {"per_joint": dict(zip(ARM, per_joint)), "overall_maxabs": overall}
    pts = [p for r in runs for p in r["points"]]
    out["points"] = pts
    late = [p["late_ms"] for p in pts]
    errs = [p["err_rad"] for p in pts]
    out["points_late_met"] = sum(1 for x in late if x is not None and x <= LATE_S * 1e3)
    out["points_err_met"] = sum(1 for x in errs if x is not None and x <= TOL_RAD)
    out["points_n"] = len(pts)
    out["end_err_max"] = max((r["end_err"] for r in runs), default=None)
    out["feedback_desired_off_max"] = max((r["feedback_desired_off_max"] or 0.0 for r in runs), default=None)
    out["actual_mismatch"] = sum(r["actual_mismatch"] for r in runs)
    out["feedback_n"] = sum(r["feedback_n"] for r in runs)
    out["ramped_per_run"] = [r["ramped"] for r in runs]
    out["accepted_ms_tracking"] = [round(r["accepted_ms"], 2) for r in runs]
    out["goals"] = {k: (signed_stats(v) if isinstance(v, list) else v) for k, v in goals.items()}
    out["serial_node"] = {k: serial_diag.get(k) for k in ("frames_sent", "frames_ramped_by_velocity_limit", "frames_rejected",
                                                          "reconnects", "round_trip_ms") if k in serial_diag}
    return out


def print_tracking(s):
    print("tracking error (rad), p50 / p99 / max of |error|:")
    print(f"  {'':44s} {'base_joint':>24s} {'shoulder_joint':>24s} {'elbow_joint':>24s} {'overall (max over joints)':>26s}")
    names = {"servo": "servo_state vs plan at the reply's stamp",
             "same_cmd": "servo_state vs the command of its stamp",
             "prev_cmd": "servo_state vs the command before that",
             "feedback": "action feedback error (desired now - actual)",
             "command": "joint_states vs plan at its stamp"}
    for kind in ("servo", "same_cmd", "prev_cmd", "feedback", "command"):
        pj = s[kind]["per_joint"]
        print(f"  {names[kind]:44s} " + " ".join(f"{fmt(pj[j]):>24s}" for j in ARM) + f" {fmt(s[kind]['overall_maxabs']):>26s}")
    print(f"  feedback.desired vs the plan at the feedback's stamp: max {s['feedback_desired_off_max']:.2e} rad; "
          f"feedback.actual not a servo_state as converted here: {s['actual_mismatch']} of {s['feedback_n']}")
    print(f"points (ii): lateness target <= {LATE_S * 1e3:.0f} ms, error target <= {TOL_RAD} rad")
    print(f"  {'pt':>3s} {'t (s)':>7s} {'late (ms), min..max':>22s} {'err (rad), max':>15s} "
          f"{'late by stamp (ms)':>20s} {'err by stamp, max':>18s}   (over {s['runs']} runs; negative = early)")
    f = lambda v, d: "-" if v is None else f"{v:.{d}f}"  # noqa: E731
    for i in sorted({p["point"] for p in s["points"]}):
        ps = [p for p in s["points"] if p["point"] == i]
        late = [p["late_ms"] for p in ps if p["late_ms"] is not None]
        lst = [p["late_stamp_ms"] for p in ps if p["late_stamp_ms"] is not None]
        err = [p["err_rad"] for p in ps if p["err_rad"] is not None]
        est = [p["err_stamp_rad"] for p in ps if p["err_stamp_rad"] is not None]
        missing = len(ps) - len(late)
        rng = lambda v: f"{min(v):.1f}..{max(v):.1f}" if v else "-"  # noqa: E731
        print(f"  {i:>3d} {ps[0]['t']:>7.3f} {rng(late) + (f' ({missing} never)' if missing else ''):>22s} "
              f"{f(max(err) if err else None, 4):>15s} {rng(lst):>20s} {f(max(est) if est else None, 4):>18s}")
    late = [p["late_ms"] for p in s["points"] if p["late_ms"] is not None]
    print(f"  lateness met {s['points_late_met']}/{s['points_n']} (max {max(late):.1f} ms); error within +-20 ms met "
          f"{s['points_err_met']}/{s['points_n']}")
    print(f"end (iii): last joint_states vs the last point, max over runs {s['end_err_max']:.3g} rad "
          f"({'met' if s['end_err_max'] == 0.0 else 'NOT exact'})")


def print_summary(s):
    dev = s["device"]
    print(f"\n=== {dev}: {s['runs']} tracking runs ===")
    if s["runs"]:
        print_tracking(s)
    g = s["goals"]
    print(f"goals (b): {g['accepted'].get('n', 0)} accepted, {g['refused']} refused, {g['failed']} not succeeded; ms, "
          "min / p50 / p99 / max:")
    for k in ("accepted", "first_step", "first_motion"):
        st = g[k]
        line = " / ".join(f"{st[q]:.1f}" for q in ("min", "p50", "p99", "max")) if st.get("n") else "-"
        extra = ""
        if k == "first_motion" and st.get("n"):
            extra = f"   target p50 <= {FIRST_MOTION_S * 1e3:.0f} ms: {'met' if st['p50'] <= FIRST_MOTION_S * 1e3 else 'NOT met'}"
        print(f"  send -> {k:14s} {line}{extra}")
    print(f"serial_node: frames ramped by its velocity guard during each trajectory: {s['ramped_per_run']}; "
          f"at the end: {s['serial_node']}")


def machine():
    load = os.getloadavg()
    try:
        cpu = next(l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name"))
    except (OSError, StopIteration):
        cpu = platform.processor()
    return {"cpu": cpu, "cores": os.cpu_count(), "loadavg_at_end": [round(x, 2) for x in load],
            "kernel": platform.release(), "bin_dir": os.environ["EEZYBOT_BIN_DIR"]}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="virtual,simavr", help="virtual, simavr or both (comma-separated)")
    ap.add_argument("--runs", type=int, default=3, help="tracking runs per device")
    ap.add_argument("--goals", type=int, default=60, help="goals per device for goal -> first motion")
    ap.add_argument("--fraction", type=float, default=0.97, help="of the velocity and acceleration limits")
    ap.add_argument("--lead", choices=sorted(STROKES), default="base",
                    help="the servo whose limits the trajectory runs at (default: base)")
    ap.add_argument("--ik-param", action="append", default=[], metavar="NAME:=VALUE",
                    help="a parameter for compute_ik (repeatable), e.g. motion_rate:=100")
    ap.add_argument("--json")
    args = ap.parse_args()

    template = time_parameterize(args.fraction, args.lead)
    v, a = template.peaks()
    print(f"trajectory: {len(template.times) - 1} points after the start, {template.times[-1]:.3f} s; "
          f"times {[round(t, 4) for t in template.times[1:]]}")
    print("  peak velocity / limit (base, shoulder, elbow servo): " + ", ".join(f"{x:.3f}" for x in v)
          + "; peak acceleration / limit: " + ", ".join(f"{x:.3f}" for x in a))
    out = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "machine": machine(), "fraction": args.fraction,
           "ik_params": args.ik_param, "lead": args.lead,
           "times": template.times, "peak_velocity_fraction": v, "peak_acceleration_fraction": a, "devices": []}
    lease = DomainLease()
    ok = True
    try:
        for device in [d.strip() for d in args.device.split(",") if d.strip()]:
            with tempfile.TemporaryDirectory() as tmp:
                g = Graph(device, lease.id, Path(tmp), args.ik_param)
                try:
                    runs = [tracking_run(g, template, args.fraction) for _ in range(args.runs)]
                    goals = goal_trials(g, args.goals)
                    g.o.spin_for(1.5)
                    s = summarize(device, runs, goals, g.serial_diag())
                except Exception as e:  # an error, not a missed target
                    print(f"{device}: ERROR {e}\n{g.logs()}", file=sys.stderr)
                    ok = False
                    s = None
                finally:
                    codes = g.close()
                if any(c not in (0, None) for c in codes):
                    print(f"{device}: a process exited with {codes}", file=sys.stderr)
                    ok = False
            if s is not None:
                print_summary(s)
                out["devices"].append(s)
    finally:
        lease.release()
    out["machine"]["loadavg_at_end"] = [round(x, 2) for x in os.getloadavg()]
    print(f"\nmachine: {out['machine']}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
