#!/usr/bin/env python3
"""Who moves the arm (issue 33, item 5), for BENCHMARKS.md: compute_ik's five commanders
switched the ros2_control way, and the e-stop during each one's motion, on the real
firmware in simavr (serial_node on its pty, compute_ik, gui_bridge's calibration wizard,
an rclpy operator). tests/test_commanders_bench.py runs one trial of each measurement;
this program repeats them:

    $EEZYBOT_PYTHON tests/bench/commanders.py [--trials 20] [--json FILE]

Needs release binaries (cargo build --release --bins; EEZYBOT_BIN_DIR overrides
target/release) and the firmware and its harness (make -C firmware/servo_control all sim).

A trial takes the arm through every commander in turn, each from where the one before
left it (controllers as compute_ik lists them; the switch deactivates the active
controllers that claim what the one activated claims, listed before, not timed):

  calibration         from teleop + gripper_controller, the base moved 0.6 rad off its
                      home first: the wizard started over the panel's WebSocket; it
                      switches to `calibration` itself and moves the servos on servo_angles
                      (its first move: the base servo to its home, 69 servo degrees)
  leader_follower     from `calibration` (activated by this program): an rclpy leader
                      streams a pose at 100 Hz with the deadman held (refused while
                      calibrating); switch: leader_follower on, calibration off
  gripper_controller  from leader_follower (holding: deadman released, no samples);
                      then a GripperCommand goal, the claw across its range
  arm_controller      from gripper_controller alone; then a FollowJointTrajectory goal
                      (one point, 1.5 s, the base across its range)
  teleop              from arm_controller; then a joint_target (the base across its range)

Switch, per commander (not calibration: the wizard is the caller there):
  call      time.time_ns() just before rclpy's call_async of switch_controller (STRICT);
  answer    when rclpy has the answer; the command goes out from its done-callback (the
            leader's samples are streaming already);
  first     Fast DDS's reception time, in this program's reader, of the first servo_angles
            the new commander caused: compute_ik's first after the call (for
            leader_follower its second: with the switch compute_ik publishes once where
            servo_state says the arm is, taking it back from calibration, before the
            leader is followed). The reader checks, by publisher and sequence number, that
            it missed no servo_angles sample.
  taken     compute_ik's log line `switch_controller: done` (its clock is CLOCK_REALTIME
            of this machine, as every figure here).
  Printed: call -> answer, call -> first, taken -> first. Calibration: wizard start (the
  WebSocket message sent) -> first, and taken (compute_ik's `calibration active`) -> first,
  where first is the first sample of the wizard's servo_angles writer (its sequence number
  1: made for each calibration).

E-stop, per commander: 0.1 s plus a random 0-20 ms (uniform, --seed) after that first
servo_angles (mid-move: every move here takes 0.3 s or more), rclpy publishes `estop` true
(t_pub = time.time_ns() just before);
once serial_node reports the board in e-stop, the commander's input stops (the leader's
samples, its deadman released) and the e-stop is released. Timed at the board as
tests/bench/estop_hotplug.py times it (serial_node's default estop_action, hold):
  to_board  t_pub -> the board has the whole ESTOP frame;
  to_held   t_pub -> the servos are held: the last change of a pulse width on any pin
            (safety_rig.last_width_change), or the ESTOP frame if none came after it; from
            there no servo is given a new position, and every pulse from the board's
            answer to the next command has the held width (checked). The firmware holds
            what its pins show (PROTOCOL.md), so to_held is to_board unless a pulse that
            had read a new width before the e-stop was handled starts after its last byte;
            before it held the command it had, which the next frame showed.
  to_pins   t_pub -> the rise of the first pulse after that frame: to_board plus the wait
            for the next pulse, up to a servo frame (20 ms), the frame's phase (a pulse
            that repeats the held width). The random delay spreads the e-stop over every
            phase of the frame (the commanders step at 50 Hz, and with the firmware's
            frame sync every step starts a frame: a fixed delay would meet one phase only,
            a different one for each commander). `phase` is the time from the start of
            the frame in progress (the last rise on pin 8) to the ESTOP frame.
  cut      the e-stop cut the move short: the moving servo's held pulse (the base's;
            the claw's for gripper_controller) lies between its width before the first
            servo_angles and the width of the commander's goal, more than 2 us from the
            goal (counted, not a failure).

A failed trial (a refused switch, no servo_angles, a missed sample, no e-stop at the
board, a pulse not held) is printed with its reason and the program exits 1.
"""
import argparse
import json
import math
import os
import platform
import random
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
os.environ.setdefault("EEZYBOT_BIN_DIR", str(HERE.parents[1] / "target" / "release"))

import yaml  # noqa: E402
from builtin_interfaces.msg import Duration  # noqa: E402
from control_msgs.action import FollowJointTrajectory, GripperCommand  # noqa: E402
from controller_manager_msgs.srv import ListControllers, SwitchController  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Bool  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from benchkit import Launcher, stats  # noqa: E402
from calibration_rig import GRIPPER_OPEN_RAD, WsWizard  # noqa: E402
from conftest import COMMANDS, EVERY, REPO, DomainLease, Observer  # noqa: E402
from safety_rig import CYCLES_PER_S, SERVO_PERIOD_S, Rig, engaged_estop_frames, estop_held, last_width_change, pulse_us, sent_ticks  # noqa: E402
from test_gui_bridge import free_port  # noqa: E402

ORDER = ["calibration", "leader_follower", "gripper_controller", "arm_controller", "teleop"]
ARM = ["base_joint", "shoulder_joint", "elbow_joint"]
JOINTS = ARM + ["gripper_joint"]
# two poses (rad) inside config/arm.yaml's limits, the base 1.2 rad apart (its servo
# 137.5°: 0.7 s at its rated speed), the claw 0.5 rad (its servo 100°)
POSES = [[-0.6, 1.2, -1.7, 0.05], [0.6, 1.5, -1.9, 0.55]]
ESTOP_AFTER_S = 0.1
ESTOP_SPREAD_S = SERVO_PERIOD_S
SERVO_LINES = yaml.safe_load((REPO / "config" / "arm.yaml").read_text())["servos"]


def base_us(base_rad):
    """The base servo's pulse width (us) for base_joint (config/arm.yaml's line)."""
    c = SERVO_LINES["base"]
    return pulse_us(c["offset_deg"] + c["gain"] * math.degrees(base_rad))


def claw_us(gripper_rad):
    """The claw servo's pulse width (us) for gripper_joint (opening = it / gripper_open_rad)."""
    c = SERVO_LINES["gripper"]
    return pulse_us(c["offset_deg"] + c["gain"] * gripper_rad / GRIPPER_OPEN_RAD)
LOG_LINE = re.compile(r"^\[(?:INFO|WARN|DEBUG|ERROR)\] \[(\d+)\.(\d{9})\] \[[^\]]*\]: (.*)$")


class TrialFailed(Exception):
    pass


def ms(a_ns, b_ns):
    return (b_ns - a_ns) / 1e6


def log_times(text, message):
    """CLOCK_REALTIME ns of every line of a node's log whose message starts with `message`."""
    out = []
    for line in text.splitlines():
        m = LOG_LINE.match(line)
        if m and m.group(3).startswith(message):
            out.append(int(m.group(1)) * 1_000_000_000 + int(m.group(2)))
    return out


def joint_state(names, positions):
    m = JointState(name=list(names), position=[float(p) for p in positions])
    t = time.time_ns()
    m.header.stamp.sec, m.header.stamp.nanosec = t // 1_000_000_000, t % 1_000_000_000
    return m


class Graph:
    """The firmware in simavr, serial_node (safety_rig.Rig: at debug, the e-stop's
    latched publisher), compute_ik, gui_bridge (its wizard over the WebSocket), and this
    program's rclpy node: the controller manager's clients, both action clients, the
    operator's and the leader's publishers, servo_angles read with DDS's reception times."""

    def __init__(self, domain, tmp, rng):
        self.tmp, self.rng = Path(tmp), rng
        self.o = Observer(domain, "commanders_bench")
        self.launch = Launcher(domain)
        board = self.tmp / "board"
        board.mkdir()
        self.rig = Rig(self.launch, self.o, board)
        self.ik = self.launch("compute_ik")
        self.gui_port = free_port()
        self.gui = self.launch("gui_bridge", "--ros-args", "-p", f"bind:=127.0.0.1:{self.gui_port}",
                               "-p", f"calibration_file:={self.tmp / 'arm.yaml'}", "-p", "foxglove_bind:=")
        n = self.o.node
        # (received ns, source ns, publisher gid, publication sequence number, positions)
        self.angles = []
        n.create_subscription(JointState, "/servo_angles", self._on_angles, EVERY)
        self.joints = []
        n.create_subscription(JointState, "/joint_states",
                              lambda m: self.joints.append([dict(zip(m.name, m.position)).get(j) for j in JOINTS]),
                              EVERY)
        self.lister = n.create_client(ListControllers, "/controller_manager/list_controllers")
        self.switcher = n.create_client(SwitchController, "/controller_manager/switch_controller")
        self.arm = ActionClient(n, FollowJointTrajectory, "arm_controller/follow_joint_trajectory")
        self.claw = ActionClient(n, GripperCommand, "gripper_controller/gripper_cmd")
        self.joint_target = self.o.pub("/joint_target", JointState)
        self.leader = self.o.pub("/leader/joint_states", JointState, COMMANDS)
        self.deadman = self.o.pub("/leader/deadman", Bool, COMMANDS)
        self.leading = None  # the pose the leader streams, or None
        self.deadman_held = False
        self.next_lead = 0.0
        for what, ready in (("list_controllers", self.lister.service_is_ready),
                            ("switch_controller", self.switcher.service_is_ready),
                            ("arm_controller/follow_joint_trajectory", self.arm.server_is_ready),
                            ("gripper_controller/gripper_cmd", self.claw.server_is_ready),
                            ("serial_node connected", self.rig.connected),
                            ("joint_states", lambda: bool(self.joints))):
            if not self.spin(until=ready, timeout=30):
                raise TrialFailed(f"start: no {what}: {self.logs()}")
        for p in (self.joint_target, self.leader, self.deadman):
            self.o.wait_matched(p)
        self.wizard = WsWizard(self.gui_port)
        if not self.spin(until=lambda: self.wizard.status is not None, timeout=15):
            raise TrialFailed("start: the panel sent no status")
        self.compute_ik_gid = None

    def _on_angles(self, m, info):
        self.angles.append((info["received_timestamp"], info["source_timestamp"], bytes(info["publisher_gid"]["data"]),
                            info["publication_sequence_number"], tuple(m.position)))

    def logs(self):
        return " | ".join(f"{p.name}: {p.output()[-600:]}" for p in self.launch.procs)

    # ------------------------------------------------------------------ spinning
    def spin(self, seconds=None, until=None, timeout=10.0):
        """Spin rclpy, the leader streaming (100 Hz) while it leads; until `until()` holds
        (returns whether it did) or for `seconds`."""
        end = time.monotonic() + (seconds if seconds is not None else timeout)
        while time.monotonic() < end:
            if until is not None and until():
                return True
            now = time.monotonic()
            if self.leading is not None and now >= self.next_lead:
                self.leader.publish(joint_state(JOINTS, self.leading))
                self.deadman.publish(Bool(data=self.deadman_held))
                self.next_lead = max(self.next_lead + 0.01, now - 0.01)
            wait = 0.005 if self.leading is None else max(0.0, min(0.005, self.next_lead - time.monotonic()))
            self.o.executor.spin_once(timeout_sec=wait)
        return until() if until is not None else True

    def call(self, client, request, timeout=10.0):
        fut = client.call_async(request)
        if not self.spin(until=fut.done, timeout=timeout):
            raise TrialFailed(f"no answer from {client.srv_name} within {timeout} s")
        return fut.result()

    # ------------------------------------------------------------------ the controllers
    def controllers(self):
        return {c.name: c for c in self.call(self.lister, ListControllers.Request()).controller}

    def holders(self, name):
        """The active controllers that claim an interface `name` needs (a switch to
        `name` deactivates them)."""
        cs = self.controllers()
        need = set(cs[name].required_command_interfaces)
        return [n for n, c in cs.items() if n != name and c.state == "active" and need & set(c.claimed_interfaces)]

    def switch(self, activate, deactivate):
        r = self.call(self.switcher, SwitchController.Request(
            activate_controllers=list(activate), deactivate_controllers=list(deactivate),
            strictness=SwitchController.Request.STRICT))
        if not r.ok:
            raise TrialFailed(f"switch {activate} / off {deactivate} refused: {r.message}")

    def timed_switch(self, name, command=None):
        """Switch to `name` (its holders off), and `command(rec)` from the answer's
        callback; returns {call, answer, command?, deactivated}."""
        off = self.holders(name)
        rec = {"deactivated": off}
        req = SwitchController.Request(activate_controllers=[name], deactivate_controllers=off,
                                       strictness=SwitchController.Request.STRICT)

        def answered(f):
            rec["answer"] = time.time_ns()
            r = f.result()
            rec["ok"], rec["message"] = r.ok, r.message
            if r.ok and command is not None:
                command(rec)

        rec["call"] = time.time_ns()
        fut = self.switcher.call_async(req)
        fut.add_done_callback(answered)
        if not self.spin(until=lambda: "ok" in rec, timeout=10):
            raise TrialFailed(f"switch to {name}: no answer within 10 s")
        if not rec["ok"]:
            raise TrialFailed(f"switch to {name} (off {off}) refused: {rec['message']}")
        return rec

    # ------------------------------------------------------------------ servo_angles
    def first_angles(self, after_ns, nth=1, writer=None, timeout=5.0, what=""):
        """The `nth` servo_angles sample received after `after_ns` (of `writer`, a
        publisher gid, or compute_ik's), checked for a gap in its writer's sequence."""
        gid = writer or self.compute_ik_gid

        def found():
            got = [a for a in self.angles if a[0] > after_ns and (gid is None or a[2] == gid)]
            return got[nth - 1] if len(got) >= nth else None

        if not self.spin(until=lambda: found() is not None, timeout=timeout):
            raise TrialFailed(f"{what}: no servo_angles within {timeout} s of the command: {self.logs()}")
        a = found()
        earlier = [b for b in self.angles if b[2] == a[2] and b[0] < a[0]]
        if earlier and a[3] - 1 != max(b[3] for b in earlier):
            raise TrialFailed(f"{what}: servo_angles samples missed by this program's reader "
                              f"(sequence {max(b[3] for b in earlier)} then {a[3]})")
        return a

    def quiet(self, seconds=0.3, timeout=10.0):
        """No servo_angles for `seconds` (the arm at rest)."""
        return self.spin(until=lambda: not self.angles or time.time_ns() - self.angles[-1][0] > seconds * 1e9,
                         timeout=timeout)

    def far_pose(self):
        """Of POSES, the one whose base is farthest from where the arm is."""
        here = self.joints[-1]
        return max(POSES, key=lambda p: abs(p[0] - here[0]))

    # ------------------------------------------------------------------ the e-stop
    def estop(self, rec, stop_input=None):
        """The e-stop ESTOP_AFTER_S and a random part of ESTOP_SPREAD_S after the first
        servo_angles; released once the board is in it, after `stop_input()`."""
        after_ns = rec["first"][0] + (ESTOP_AFTER_S + self.rng.uniform(0.0, ESTOP_SPREAD_S)) * 1e9
        self.spin(until=lambda: time.time_ns() >= after_ns, timeout=5)
        rec["estop"] = time.time_ns()
        self.rig.estop.publish(Bool(data=True))
        if not self.spin(until=lambda: self.rig.diag().get("device_state") == "e-stop", timeout=5):
            raise TrialFailed(f"e-stop: the board not in e-stop within 5 s: {self.rig.diag()}")
        if stop_input is not None:
            stop_input()
        self.spin(0.1)
        self.rig.estop.publish(Bool(data=False))
        if not self.spin(until=self.rig.released, timeout=15):
            raise TrialFailed(f"e-stop: not released within 15 s: {self.rig.diag()}")

    # ------------------------------------------------------------------ the commanders
    def calibration(self):
        if self.wizard.cal is not None and self.wizard.cal.get("active"):
            raise TrialFailed("calibration: the wizard is still active from before")
        # the base 0.6 rad off its home, where the wizard's first move takes it (0.23 s
        # at its servo's rated speed): teleop has the arm
        self.joint_target.publish(joint_state(ARM, POSES[0][:3]))
        if not self.spin(until=lambda: abs(self.joints[-1][0] - POSES[0][0]) < 0.01, timeout=10):
            raise TrialFailed(f"calibration: the arm did not get to {POSES[0][:3]} before the wizard: {self.joints[-1]}")
        self.quiet()
        # (the wizard's switch deactivates them)
        rec = {"deactivated": self.holders("calibration")}
        n = len(self.angles)
        rec["start"] = time.time_ns()
        self.wizard.start()
        if not self.spin(until=lambda: any(a[2] != self.compute_ik_gid for a in self.angles[n:]), timeout=10):
            raise TrialFailed(f"calibration: no servo_angles from the wizard within 10 s; wizard: "
                              f"{json.dumps(self.wizard.cal)[:800]}; {self.logs()}")
        first = next(a for a in self.angles[n:] if a[2] != self.compute_ik_gid)
        if first[3] != 1:
            raise TrialFailed(f"calibration: this program's reader missed the wizard's first servo_angles "
                              f"(the first it got is the writer's sample {first[3]})")
        rec["first"] = first
        rec["goal"] = (0, pulse_us(math.degrees(first[4][0])))
        self.estop(rec)
        self.wizard.cancel()
        if not self.spin(until=lambda: self.wizard.cal is not None and not self.wizard.cal.get("active"), timeout=15):
            raise TrialFailed(f"calibration: the wizard did not end on cancel: {json.dumps(self.wizard.cal)[:800]}")
        if not self.spin(until=lambda: self.controllers()["calibration"].state == "inactive", timeout=15):
            raise TrialFailed("calibration: still active after the wizard was cancelled")
        self.quiet()
        return rec

    def leader_follower(self):
        self.switch(["calibration"], self.holders("calibration"))
        self.leading, self.deadman_held = self.far_pose(), True
        self.spin(0.2)  # refused while calibrating
        takes = len(log_times(self.ik.output(), "calibrating ended: taking the arm"))
        rec = self.timed_switch("leader_follower")
        took = len(log_times(self.ik.output(), "calibrating ended: taking the arm")) > takes
        # compute_ik takes the arm back from calibration with one servo_angles; then the leader's
        rec["first"] = self.first_angles(rec["call"], nth=2 if took else 1, what="leader_follower")
        rec["goal"] = (0, base_us(self.leading[0]))

        def stop_leading():
            self.leading, self.deadman_held = None, False
            for _ in range(3):
                self.deadman.publish(Bool(data=False))

        self.estop(rec, stop_leading)
        self.quiet()
        return rec

    def gripper_controller(self):
        here = self.joints[-1][3]
        target = max((p[3] for p in POSES), key=lambda g: abs(g - here))
        goal = GripperCommand.Goal()
        goal.command.position, goal.command.max_effort = target, 0.0

        def command(rec):
            rec["command"] = time.time_ns()
            rec["goal"] = self.claw.send_goal_async(goal)

        rec = self.timed_switch("gripper_controller", command)
        rec["first"] = self.first_angles(rec["call"], what="gripper_controller")
        rec["goal"] = (3, claw_us(target))
        self.estop(rec)
        self.quiet()
        return rec

    def arm_controller(self):
        pose = self.far_pose()
        goal = FollowJointTrajectory.Goal()
        goal.trajectory = JointTrajectory(joint_names=ARM, points=[JointTrajectoryPoint(
            positions=pose[:3], time_from_start=Duration(sec=1, nanosec=500_000_000))])

        def command(rec):
            rec["command"] = time.time_ns()
            rec["goal"] = self.arm.send_goal_async(goal)

        rec = self.timed_switch("arm_controller", command)
        rec["first"] = self.first_angles(rec["call"], what="arm_controller")
        rec["goal"] = (0, base_us(pose[0]))
        self.estop(rec)
        self.quiet()
        return rec

    def teleop(self):
        pose = self.far_pose()

        def command(rec):
            rec["command"] = time.time_ns()
            self.joint_target.publish(joint_state(ARM, pose[:3]))

        rec = self.timed_switch("teleop", command)
        rec["first"] = self.first_angles(rec["call"], what="teleop")
        rec["goal"] = (0, base_us(pose[0]))
        self.estop(rec)
        self.quiet()
        return rec

    def recover(self):
        """After a failed trial: the e-stop released, the leader stopped, the wizard
        ended, `calibration` off; back to teleop and gripper_controller."""
        self.leading, self.deadman_held = None, False
        self.deadman.publish(Bool(data=False))
        self.rig.estop.publish(Bool(data=False))
        self.spin(until=self.rig.released, timeout=15)
        if self.wizard.cal is not None and self.wizard.cal.get("active"):
            self.wizard.cancel()
            self.spin(until=lambda: not self.wizard.cal.get("active"), timeout=15)
        cs = self.controllers()
        active = [n for n, c in cs.items() if c.state == "active"]
        want = [n for n in ("teleop", "gripper_controller") if n not in active]
        if want:
            self.switch(want, [n for n in active if n not in ("teleop", "gripper_controller")])
        self.quiet()

    def stop(self):
        self.wizard.close()
        self.rig.stop()
        codes = self.launch.stop()
        self.o.close()
        return codes


def learn_compute_ik(g):
    """compute_ik's servo_angles writer: a joint target before the trials (teleop)."""
    g.quiet()
    n = len(g.angles)
    pose = g.far_pose()
    g.joint_target.publish(joint_state(JOINTS, pose))
    if not g.spin(until=lambda: len(g.angles) > n, timeout=10):
        raise TrialFailed(f"start: compute_ik published no servo_angles for a joint target: {g.logs()}")
    g.compute_ik_gid = g.angles[n][2]
    g.quiet()


# ---------------------------------------------------------------------- analysis
def switch_figures(name, recs, ik_log):
    """Per trial of `name`: call -> answer, call -> first, taken -> first (ms)."""
    done = log_times(ik_log, "calibration active" if name == "calibration" else "switch_controller: done")
    out = []
    for r in recs:
        start = r["start"] if name == "calibration" else r["call"]
        taken = next((t for t in done if t >= start), None)
        f = {"taken_to_first_ms": ms(taken, r["first"][0]) if taken is not None else None}
        if name == "calibration":
            f["start_to_first_ms"] = ms(r["start"], r["first"][0])
        else:
            f.update(call_to_answer_ms=ms(r["call"], r["answer"]), call_to_first_ms=ms(r["call"], r["first"][0]),
                     call_to_taken_ms=ms(r["call"], taken) if taken is not None else None)
        out.append(f)
    return out


def estop_figures(ev, sends, rec):
    """to_board, to_pins (ms) and whether it cut the move, for the e-stop of `rec`;
    raises TrialFailed when the board's pulses did not hold."""
    t_pub = rec["estop"]
    stops = [(seq, c) for _, seq, c in engaged_estop_frames(ev)]
    engaged = next((s for s in stops if ev.wall_ns(s[1]) >= t_pub), None)
    if engaged is None:
        raise TrialFailed("no ESTOP frame reached the board after the publish")
    seq, c_stop = engaged
    c_held, held = estop_held(ev, c_stop, seq)
    first = min(next(c for c, _ in ev.pulses(pin) if c > c_stop) for pin in range(4))
    nxt = next((c for c, _ in sends if c > c_held), None)
    for pin in range(4):
        bad = [(c, w) for c, w in ev.pulses(pin) if c_held < c and (nxt is None or c < nxt) and abs(w - held[pin] / 2) > 1.0]
        if bad:
            raise TrialFailed(f"pin {pin}: pulses not held at {held[pin] / 2} us after the e-stop: {bad[:3]}")
    pin, goal = rec["goal"]
    before = ev.cycle_before(rec["first"][0])
    start = [w for c, w in ev.pulses(pin) if before is not None and c <= before][-1:]
    now = held[pin] / 2
    cut = bool(start) and abs(now - goal) > 2.0 and min(start[0], goal) - 1.0 <= now <= max(start[0], goal) + 1.0
    frame_start = max((c for c, _ in ev.pulses(0) if c <= c_stop), default=None)
    phase = (c_stop - frame_start) / CYCLES_PER_S * 1e3 if frame_start is not None else None
    held_at = last_width_change(ev, c_stop, nxt)
    return {"to_board_ms": ms(t_pub, ev.wall_ns(c_stop)), "to_held_ms": ms(t_pub, ev.wall_ns(held_at)),
            "to_pins_ms": ms(t_pub, ev.wall_ns(first)),
            "frame_to_pins_ms": (first - c_stop) / CYCLES_PER_S * 1e3, "phase_ms": phase, "cut": cut,
            "pin": pin, "start_us": start[0] if start else None, "held_us": now, "goal_us": goal}


def summary(values):
    v = [x for x in values if x is not None]
    return stats(v) if v else None


def fmt(s):
    return "—" if s is None else f"{s['p50']:.2f} / {s['p99']:.2f} / {s['max']:.2f}"


def run(domain, trials, tmp, seed=33, progress=print):
    """Every commander `trials` times; returns (results per commander, failures)."""
    recs = {c: [] for c in ORDER}
    failures = []
    g = Graph(domain, tmp, random.Random(seed))
    try:
        learn_compute_ik(g)
        for i in range(trials):
            for name in ORDER:
                try:
                    rec = getattr(g, name)()
                    rec["trial"] = i
                    recs[name].append(rec)
                except TrialFailed as e:
                    failures.append(f"trial {i + 1}, {name}: {e}")
                    progress(f"FAILED: {failures[-1]}", flush=True)
                    g.recover()
            progress(f"trial {i + 1}/{trials} done", flush=True)
    finally:
        g.stop()
    ev = g.rig.events()
    sends = sent_ticks(ev)
    ik_log = g.ik.output()
    out = {}
    for name in ORDER:
        sw = switch_figures(name, recs[name], ik_log)
        es = []
        for r in recs[name]:
            try:
                es.append(estop_figures(ev, sends, r))
            except (TrialFailed, StopIteration) as e:
                failures.append(f"trial {r['trial'] + 1}, {name}, e-stop at the board: {e or 'no pulse after it'}")
        out[name] = {
            "n": len(recs[name]),
            "deactivated": sorted({tuple(r.get("deactivated", ())) for r in recs[name]}),
            "call_to_answer_ms": summary(f.get("call_to_answer_ms") for f in sw),
            "call_to_first_ms": summary(f.get("call_to_first_ms") for f in sw),
            "start_to_first_ms": summary(f.get("start_to_first_ms") for f in sw),
            "taken_to_first_ms": summary(f.get("taken_to_first_ms") for f in sw),
            "call_to_taken_ms": summary(f.get("call_to_taken_ms") for f in sw),
            "estop_to_board_ms": summary(e["to_board_ms"] for e in es),
            "estop_to_held_ms": summary(e["to_held_ms"] for e in es),
            "estop_to_pins_ms": summary(e["to_pins_ms"] for e in es),
            "estop_frame_to_pins_ms": summary(e["frame_to_pins_ms"] for e in es),
            "estop_cut": sum(e["cut"] for e in es),
            "estop_n": len(es),
            "raw": {"switch": sw, "estop": es},
        }
        missing = [i for i, f in enumerate(sw) if f["taken_to_first_ms"] is None]
        if missing:
            failures.append(f"{name}: compute_ik's log has no switch for trials {[recs[name][i]['trial'] + 1 for i in missing]}")
    return out, failures


def table(out):
    """The switch table and the e-stop table (markdown)."""
    lines = ["| commander | switched from | n | call → answer | call → first `servo_angles` | "
             "compute_ik took the switch → first `servo_angles` |", "|---|---|---|---|---|---|"]
    for name in ORDER:
        r = out[name]
        frm = ", ".join(" + ".join(d) or "nothing" for d in r["deactivated"])
        if name == "calibration":
            frm += " (the wizard's switch)"
            call = f"wizard start → first: {fmt(r['start_to_first_ms'])}"
        else:
            call = fmt(r["call_to_first_ms"])
        lines.append(f"| `{name}` | {frm} | {r['n']} | {fmt(r['call_to_answer_ms'])} | {call} | "
                     f"{fmt(r['taken_to_first_ms'])} |")
    lines += ["", "| e-stop during | n | → ESTOP frame at the board | → servos held (last width change) | "
              "→ next pulse | of which the ESTOP frame → next pulse | cut the move short |",
              "|---|---|---|---|---|---|---|"]
    for name in ORDER:
        r = out[name]
        lines.append(f"| `{name}` | {r['estop_n']} | {fmt(r['estop_to_board_ms'])} | {fmt(r['estop_to_held_ms'])} | "
                     f"{fmt(r['estop_to_pins_ms'])} | {fmt(r['estop_frame_to_pins_ms'])} | "
                     f"{r['estop_cut']}/{r['estop_n']} |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seed", type=int, default=33, help="of the e-stop's random delays")
    ap.add_argument("--json")
    args = ap.parse_args()
    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    meta = {"date": time.strftime("%Y-%m-%d %H:%M:%S %Z"), "commit": commit, "bin_dir": os.environ["EEZYBOT_BIN_DIR"],
            "host": platform.node(), "cores": os.cpu_count(), "seed": args.seed, "loadavg_start": os.getloadavg()}
    print(f"{meta['date']}, checkout {commit}, binaries {meta['bin_dir']}, load {meta['loadavg_start']}", flush=True)
    lease = DomainLease()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            out, failures = run(lease.id, args.trials, tmp, args.seed)
    finally:
        lease.release()
    meta["loadavg_end"] = os.getloadavg()
    print(f"\n{args.trials} trials, ms as p50 / p99 / max; load at the end {meta['loadavg_end']}:")
    print(table(out))
    if args.json:
        Path(args.json).write_text(json.dumps({"meta": meta, "results": out, "failures": failures}, indent=1) + "\n")
    if failures:
        print(f"\n{len(failures)} failed:")
        for f in failures:
            print(f"  {f}")
        sys.exit(1)


if __name__ == "__main__":
    main()
