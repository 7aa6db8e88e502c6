"""Pure helpers of the end-to-end benchmark (e2e.py): statistics, the arm's kinematics
and servo mapping written again from ROBOT.md / config/arm.yaml (for choosing targets and
for the precision checks), parsing the pty tap's log and the simavr harness's event log
into protocol frames, and pairing commands with pulses. No ROS here."""
import bisect
import math
import random
import struct
import sys
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from interop.servo_link import PAYLOAD_LEN, SET_PULSES, SYNC, crc8  # noqa: E402

REPO = HERE.parents[1]
CYCLES_PER_S = 16_000_000
CYCLES_PER_TICK = 8  # Timer1 prescaler 8: one 0.5 us tick


# ---------------------------------------------------------------- statistics
def pct(sorted_values, p):
    """Nearest-rank percentile of sorted values (as tests/bench/ik_latency.py)."""
    return sorted_values[min(len(sorted_values) - 1, int(round(p / 100 * (len(sorted_values) - 1))))]


def summary(values, scale=1.0):
    """n, p50, p90, p99, max, min, mean of `values` times `scale` (None entries skipped)."""
    v = sorted(x * scale for x in values if x is not None)
    if not v:
        return {"n": 0}
    return {"n": len(v), "p50": pct(v, 50), "p90": pct(v, 90), "p99": pct(v, 99), "max": v[-1], "min": v[0],
            "mean": sum(v) / len(v)}


def this_or_newer(sent, outputs):
    """For each sent stamp: the time from it to the first output (time, stamp) carrying it
    or a newer stamp, None if none came. With newest-wins nodes this is what an operator
    waits for whatever was dropped on the way; it also counts the time a node says nothing."""
    outs = sorted(outputs)
    run_max, m = [], float("-inf")
    for _, st in outs:
        m = max(m, st)
        run_max.append(m)
    res = []
    for s in sent:
        i = bisect.bisect_left(run_max, s)
        res.append(outs[i][0] - s if i < len(outs) else None)
    return res


# ---------------------------------------------------------------- the arm (ROBOT.md, config/arm.yaml)
ARM = yaml.safe_load((REPO / "config" / "arm.yaml").read_text())
G = ARM["geometry"]
H, L2, L3, DX = G["shoulder_height_m"], G["main_arm_m"], G["forearm_m"], G["tool_dx_m"]
LIM = {k: (math.radians(a), math.radians(b)) for k, (a, b) in ARM["limits_deg"].items()}
CAL = [ARM["servos"][k] for k in ("base", "shoulder", "elbow", "gripper")]
R2D = 180.0 / math.pi  # Rust's f64::to_degrees multiplies by this constant, so does math.degrees
D2R = math.pi / 180.0  # ... and to_radians by this one


def ik(x, y, z, margin_deg=0.0):
    """ROBOT.md's closed-form IK: (base, shoulder, elbow) in rad, or None if out of reach or
    outside the joint limits shrunk by `margin_deg`."""
    base = math.atan2(y, x)
    r = math.hypot(x, y) - DX
    h = z - H
    s2 = r * r + h * h
    if not (L2 - L3) ** 2 <= s2 <= (L2 + L3) ** 2:
        return None
    cos_e = (s2 - L2 * L2 - L3 * L3) / (2 * L2 * L3)
    sin_e = -math.sqrt(((L2 + L3) ** 2 - s2) * (s2 - (L2 - L3) ** 2)) / (2 * L2 * L3)
    elbow = math.atan2(sin_e, cos_e)
    shoulder = math.atan2(h, r) - math.atan2(L3 * sin_e, L2 + L3 * cos_e)
    m = math.radians(margin_deg)
    for value, (lo, hi) in ((base, LIM["base"]), (shoulder, LIM["shoulder"]), (elbow, LIM["elbow"]),
                            (shoulder + elbow, LIM["forearm_elevation"])):
        if not lo + m <= value <= hi - m:
            return None
    return base, shoulder, elbow


def fk(base, shoulder, elbow):
    """ROBOT.md's FK: tool0 in base_link (m), the same operations as the kinematics crate."""
    phi = shoulder + elbow
    r = L2 * math.cos(shoulder) + L3 * math.cos(phi) + DX
    z = H + L2 * math.sin(shoulder) + L3 * math.sin(phi)
    return r * math.cos(base), r * math.sin(base), z


def servo_angles_from_joints(base, shoulder, elbow, opening=0.0):
    """compute_ik's servo mapping with its order of f64 operations (libs/kinematics
    servo.rs: offset + gain * input.to_degrees(), clamped, .to_radians()): given the
    joint_states values it sent, the servo_angles it sent, bit for bit."""
    inputs = [base * R2D, shoulder * R2D, (shoulder + elbow) * R2D, opening]
    out = []
    for c, v in zip(CAL, inputs):
        deg = c["offset_deg"] + c["gain"] * v
        out.append(min(max(deg, c["min_deg"]), c["max_deg"]) * D2R)
    return out


def _round_half_away(v):
    return math.floor(v + 0.5) if v >= 0 else -math.floor(-v + 0.5)


def angle_to_ticks(rad, c):
    """serial_node's angles_to_ticks for one servo (nodes/serial_node/src/core.rs)."""
    deg = rad * R2D
    deg = min(max(deg, c["min_deg"]), c["max_deg"]) * D2R * R2D
    lo, hi = float(c["pulse_min_us"]), float(c["pulse_max_us"])
    us = lo + (hi - lo) * deg / 180.0
    return int(min(max(_round_half_away(us * 2.0), 1), 65535))


def ticks_of(servo_rad):
    return tuple(angle_to_ticks(a, c) for a, c in zip(servo_rad, CAL))


def ticks_from_reported(rad, c):
    """The pulse width a servo_state angle stands for (inverse of serial_node's
    ticks_to_angle, exact after rounding)."""
    lo, hi = float(c["pulse_min_us"]), float(c["pulse_max_us"])
    return int(round((rad * R2D / 180.0 * (hi - lo) + lo) * 2.0))


def random_targets(n, seed=8, min_step_ticks=40):
    """`n` reachable targets (1 degree inside every limit), pseudo-random with `seed`,
    each moving the base, shoulder and elbow servos by at least `min_step_ticks`
    (0.5 us ticks) from the previous one, so that every command changes the pulse width
    on pins 8, 9 and 10 and the ticks identify the command. The arm would jump: with a
    velocity limit in the path (compute_ik planning, serial_node's guard) the widths on
    the wire are no longer the commanded ones, and (b)/(c) cannot tie frames to targets."""
    rnd = random.Random(seed)
    out, prev = [], None
    while len(out) < n:
        th = math.radians(rnd.uniform(-42, 42))
        r = rnd.uniform(0.10, 0.28)
        z = rnd.uniform(0.05, 0.28)
        x, y = r * math.cos(th), r * math.sin(th)
        q = ik(x, y, z, margin_deg=1.0)
        if q is None:
            continue
        t = ticks_of(servo_angles_from_joints(*q))
        if prev is not None and min(abs(a - b) for a, b in zip(t[:3], prev[:3])) < min_step_ticks:
            continue
        out.append((x, y, z))
        prev = t
    return out


class TargetPath:
    """The operator's targets.

    `smooth` (default): an operator sweeping the arm, a Lissajous path in joint space
    (base +-30 deg at 2 rad/s, shoulder 90 +- 18 deg at 3.5 rad/s, forearm elevation
    -15 +- 20 deg at 3.2 rad/s; every limit holds with 1 degree to spare), sampled at the
    time each target is sent: the servos move at up to 120 deg/s and 240 deg/s^2, inside
    config/arm.yaml's motion limits, so nothing on the way has to slow them down and the
    commanded widths reach the wire unchanged. At 50 Hz a command moves the fastest pin by
    35 ticks (p50), up to 50.
    `random`: random_targets(), a jump of 20 us or more on every arm pin each command;
    only meaningful while nothing limits the servos' velocity.

    next(t_s) gives (index, xyz) for a target sent t_s after the path's origin; xyz(index)
    gives it back for the analysis."""

    def __init__(self, kind="smooth", seed=8, n_random=20000):
        self.kind = kind
        self.seed = seed
        rnd = random.Random(seed)
        self.phase = [rnd.uniform(0, 2 * math.pi) for _ in range(3)]
        self.random = random_targets(n_random, seed) if kind == "random" else None
        self.count = 0

    def joints(self, t):
        base = math.radians(30) * math.sin(2.0 * t + self.phase[0])
        shoulder = math.radians(90 + 18 * math.sin(3.5 * t + self.phase[1]))
        phi = math.radians(-15 + 20 * math.sin(3.2 * t + self.phase[2]))
        return base, shoulder, phi - shoulder

    def xyz(self, index):
        if self.kind == "random":
            return self.random[index % len(self.random)]
        return fk(*self.joints(index / 1000.0))

    def next(self, t_s):
        if self.kind == "random":
            self.count += 1
            index = self.count
        else:
            index = int(round(t_s * 1000.0))  # one target per millisecond of path time at most
        return index, self.xyz(index)


# ---------------------------------------------------------------- protocol frames in byte logs
def parse_frames(chunks):
    """Frames in a byte stream given as [(time, bytes)]: [(type, seq, payload, t_first,
    t_last)], t_first = time of the chunk holding the start byte. The receiver's rule of
    PROTOCOL.md: on a bad length or CRC drop only the start byte."""
    buf = bytearray()
    times = []
    for t, data in chunks:
        buf += data
        times += [t] * len(data)
    out, i, n = [], 0, len(buf)
    while i < n:
        if buf[i] != SYNC:
            i += 1
            continue
        if i + 2 > n:
            break
        length = (buf[i + 1] & 0x0F) + 4
        if i + length > n:
            break
        f = bytes(buf[i:i + length])
        mtype = f[1] >> 4
        if crc8(f[1:-1]) != f[-1] or PAYLOAD_LEN.get(mtype) != length - 4:
            i += 1
            continue
        out.append((mtype, f[2], f[3:-1], times[i], times[i + length - 1]))
        i += length
    return out


def read_tap_log(path):
    """The pty tap's log: host->device and device->host chunks, [(ns, bytes)] each."""
    host, dev = [], []
    for line in Path(path).read_text().splitlines():
        if line.startswith("#"):
            continue
        tag, t, data = line.split()
        (host if tag == "h" else dev).append((int(t), bytes.fromhex(data)))
    return host, dev


def set_pulses_frames(frames):
    """[(seq, ticks tuple, t_first, t_last)] of the SET_PULSES frames."""
    return [(seq, struct.unpack("<4H", p), t0, t1) for mtype, seq, p, t0, t1 in frames if mtype == SET_PULSES]


def read_sim_events(path):
    """simavr harness events: bytes into the AVR [(cycle, bytes)], bytes out of it, and
    pin edges [(cycle, pin, level)]."""
    rx, tx, edges = [], [], []
    for line in Path(path).read_text().splitlines():
        p = line.split()
        if len(p) == 4 and p[0] == "e":
            edges.append((int(p[1]), int(p[2]), int(p[3])))
        elif len(p) == 3 and p[0] == "r":
            rx.append((int(p[1]), bytes([int(p[2])])))
        elif len(p) == 3 and p[0] == "t":
            tx.append((int(p[1]), bytes([int(p[2])])))
    return rx, tx, edges


def pin_pulses(edges, pins=4):
    """Per pin: [(rise_cycle, fall_cycle)] of every complete pulse."""
    out = [[] for _ in range(pins)]
    rise = [None] * pins
    for cycle, pin, level in edges:
        if level:
            rise[pin] = cycle
        elif rise[pin] is not None:
            out[pin].append((rise[pin], cycle))
            rise[pin] = None
    return out


WIDTH_TOLERANCE_TICKS = 16  # 8 us: farther than this from every command's width, a pulse is "unexplained"
WIDTH_SEPARATION_TICKS = 4  # a pin change this close to an older command's width is not timed


def first_new_width(pulses, after_cycle, older, new, newer, tol=WIDTH_TOLERANCE_TICKS):
    """On one pin: the first pulse rising at or after `after_cycle` that does not show an
    older command (`older`: widths of the commands before this one, the last first; a
    pin may still show one older than the previous, after a late latch). Each pulse is
    attributed to the command of the nearest width within `tol` ticks. Returns
    ("applied", rise, fall) for this command's width `new`, ("superseded", rise, fall)
    for a newer command's (`newer`) that got there first, ("unexplained", rise, fall) if
    no command is within `tol`, or None if the log ends first. The firmware outputs
    widths to within a tick, but another interrupt can delay one edge by up to ~7 us
    (seen in simavr), hence the tolerance; the error of every applied pulse is
    reported, so a wrong attribution (an error of a whole command step) would show."""
    i = bisect.bisect_left(pulses, (after_cycle, -1))
    for rise, fall in pulses[i:]:
        w = (fall - rise) / CYCLES_PER_TICK
        cands = [(abs(w - new), 0, "applied")] + [(abs(w - o), 1, "older") for o in older] + \
                [(abs(w - n), 2, "superseded") for n in newer]
        d, _, kind = min(cands)
        if d > tol:
            return ("unexplained", rise, fall)
        if kind == "older":
            continue
        return (kind, rise, fall)
    return None
