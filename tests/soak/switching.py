#!/usr/bin/env python3
"""Soak: the five commanders switched at random for `--minutes` on the virtual Arduino
(issue 33's target: no period commanded twice). compute_ik and serial_node
(`port:=mock`, the in-process virtual Arduino) run in a domain of their own; one rclpy
node plays every commander at once and at random: `switch_controller` calls (random
sets, strict or best effort), teleop targets, FollowJointTrajectory and GripperCommand
goals, a leader arm streaming at 50 Hz with its deadman pressed and released, the
calibration wizard's direct servo jogs while `calibration` is active, and the e-stop.

What is checked, from outside, by order and content (never by the clock):
- double command: no servo_angles moves a servo further from the one before it than
  its speed (config/arm.yaml) allows in a period, or in the time between their stamps
  if longer. Each commander steps within the limits once a period, so two commanders
  moving one joint in the same periods show as a longer step (serial_node's count of
  frames its velocity guard ramped is printed, not judged: the guard measures a step
  against the time since the frame before it was sent, so a full-speed step that
  arrives a few ms early after the one before is ramped too);
- calibration excludes everything else: every compute_ik `diagnostics` report with
  `calibrating` true shows the same `servo_angles_sent` count within one calibration
  (compute_ik published no servo_angles meanwhile);
- the e-stop holds: within one e-stop, every compute_ik report with `estop` true shows
  one `servo_angles_sent`, and every `servo_state` after serial_node's first report of
  the e-stop shows the same angles;
- every switch_controller call is answered, and the nodes exit 0 at the end.

    $EEZYBOT_PYTHON tests/soak/switching.py [--minutes 10] [--seed 1] [--json FILE]

Prints a line a minute and the counts at the end; exits 1 if a check failed.
test_controller_manager.py runs one short trial (`--minutes 0.5`) in the test command.
"""
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import soaklib  # noqa: E402
from conftest import COMMANDS, LATCHED, Observer, bin_path, status_values  # noqa: E402

CONTROLLERS = ["teleop", "arm_controller", "gripper_controller", "leader_follower", "calibration"]
ARM = ["base_joint", "shoulder_joint", "elbow_joint"]
# joint ranges well inside config/arm.yaml's limits (forearm elevation = shoulder + elbow)
BASE, SHOULDER, ELBOW = (-0.5, 0.5), (1.35, 1.75), (-1.85, -1.45)
SERVOS = ["base_servo", "shoulder_servo", "elbow_servo", "gripper_servo"]
PERIOD_S = 0.02  # compute_ik's motion_rate, 50 Hz


def stamp_s(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


class Soak:
    def __init__(self, domain, seed, work):
        from control_msgs.action import FollowJointTrajectory, GripperCommand
        from controller_manager_msgs.srv import ListControllers, SwitchController
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PointStamped
        from rclpy.action import ActionClient
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Bool

        self.rng = random.Random(seed)
        env = {"ROS_DOMAIN_ID": str(domain)}
        self.logs = []
        self.procs = []
        for name, args in [("compute_ik", ["--ros-args", "-p", "max_target_age:=0.0", "-p", "leader_timeout:=0.5",
                                           "-p", "calibration_lease:=5.0", "-p", "diagnostics_period:=0.2"]),
                           ("serial_node", ["--ros-args", "-p", "port:=mock", "-p", "diagnostics_period:=0.2"])]:
            log = open(work / f"{name}.log", "w")
            self.logs.append(log)
            self.procs.append(subprocess.Popen([bin_path(name), *args], stdout=log, stderr=subprocess.STDOUT,
                                                   env={**os.environ, **env}))
        self.o = Observer(domain)
        n = self.o.node
        self.list_client = n.create_client(ListControllers, "/controller_manager/list_controllers")
        self.switch_client = n.create_client(SwitchController, "/controller_manager/switch_controller")
        self.arm = ActionClient(n, FollowJointTrajectory, "arm_controller/follow_joint_trajectory")
        self.gripper = ActionClient(n, GripperCommand, "gripper_controller/gripper_cmd")
        self.types = dict(FollowJointTrajectory=FollowJointTrajectory, GripperCommand=GripperCommand,
                          SwitchController=SwitchController, ListControllers=ListControllers,
                          PointStamped=PointStamped, JointState=JointState, Bool=Bool)
        self.xyz = self.o.pub("/xyz_target", PointStamped)
        self.estop_pub = self.o.pub("/estop", Bool, LATCHED)
        self.leader = self.o.pub("/leader/joint_states", JointState, COMMANDS)
        self.deadman = self.o.pub("/leader/deadman", Bool, COMMANDS)
        self.servo_angles = self.o.pub("/servo_angles", JointState)
        self.servo_state = self.o.sub("/servo_state", JointState)
        # every servo_angles (compute_ik's and the soak's own jogs), for a failure's context
        self.angles_seen = self.o.sub("/servo_angles", JointState,
                                      __import__("rclpy.qos").qos.QoSProfile(depth=1000))
        self.diagnostics = self.o.sub("/diagnostics", DiagnosticArray)
        for c in (self.list_client, self.switch_client):
            assert c.wait_for_service(timeout_sec=60), c.srv_name
        assert self.o.spin_until(lambda: self.arm.server_is_ready() and self.gripper.server_is_ready(), 60)
        assert self.o.spin_until(lambda: self.servo_state, 60), "no servo_state from serial_node"
        self.counts = {k: 0 for k in ["switches", "switches_ok", "targets", "trajectory_goals", "gripper_goals",
                                      "leader_sessions", "jogs", "estops", "calibrations"]}
        self.failures = []
        self.deadman_on = False
        self.estop_on = False
        self.leader_phase = 0.0
        self.read = 0  # diagnostics messages judged so far
        self.angles_read = 0  # servo_angles judged so far
        import yaml
        motion = yaml.safe_load((HERE.parent.parent / "config" / "arm.yaml").read_text())["motion"]
        # the most a servo may move between two steps (deg), and per second
        self.speed = {f"{k}_servo": v["max_velocity_deg_s"] for k, v in motion.items()}
        self.ramped = "0"
        self.history = []  # (monotonic s, what the soak did), for a failure's context

    # ---------------------------------------------------------------- the commanders

    def call(self, client, request):
        future = client.call_async(request)
        if not self.o.spin_until(future.done, 30):
            self.failures.append(f"no answer from {client.srv_name}")
            return None
        return future.result()

    def active(self):
        r = self.call(self.list_client, self.types["ListControllers"].Request())
        return [c.name for c in r.controller if c.state == "active"] if r else []

    def switch(self):
        S = self.types["SwitchController"]
        active = self.active()
        inactive = [c for c in CONTROLLERS if c not in active]
        activate = self.rng.sample(inactive, k=min(len(inactive), self.rng.choice([0, 1, 1, 2])))
        deactivate = self.rng.sample(active, k=min(len(active), self.rng.choice([0, 1, 2, 2])))
        strict = self.rng.random() < 0.6
        r = self.call(self.switch_client, S.Request(activate_controllers=activate, deactivate_controllers=deactivate,
                                                    strictness=S.Request.STRICT if strict else S.Request.BEST_EFFORT))
        self.counts["switches"] += 1
        self.note(f"switch +{activate} -{deactivate} {'strict' if strict else 'best effort'}: "
                  f"{'ok' if r is not None and r.ok else (r.message if r else 'no answer')}")
        if r is not None and r.ok:
            self.counts["switches_ok"] += 1
            if "calibration" in activate and "calibration" in self.active():
                self.counts["calibrations"] += 1

    def target(self):
        m = self.types["PointStamped"]()
        m.header.frame_id = "base_link"
        m.point.x, m.point.y, m.point.z = (self.rng.uniform(0.17, 0.22), self.rng.uniform(-0.06, 0.06),
                                          self.rng.uniform(0.12, 0.18))
        self.xyz.publish(m)
        self.counts["targets"] += 1
        self.note("target")

    def joints(self):
        return [self.rng.uniform(*BASE), self.rng.uniform(*SHOULDER), self.rng.uniform(*ELBOW)]

    def trajectory(self):
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
        F = self.types["FollowJointTrajectory"]
        points = [JointTrajectoryPoint(positions=self.joints(), time_from_start=Duration(sec=2 * (i + 1)))
                  for i in range(self.rng.choice([1, 2]))]
        self.arm.send_goal_async(F.Goal(trajectory=JointTrajectory(joint_names=ARM, points=points)))
        self.counts["trajectory_goals"] += 1
        self.note("trajectory goal")

    def gripper_goal(self):
        from control_msgs.msg import GripperCommand as Cmd
        G = self.types["GripperCommand"]
        self.gripper.send_goal_async(G.Goal(command=Cmd(position=self.rng.uniform(0.0, 1.0), max_effort=0.0)))
        self.counts["gripper_goals"] += 1
        self.note("gripper goal")

    def leader_sample(self):
        self.leader_phase += 0.02
        q = [0.3 * math.sin(self.leader_phase * 0.7), 1.55 + 0.15 * math.sin(self.leader_phase * 0.5),
             -1.65 + 0.15 * math.sin(self.leader_phase * 0.3)]
        self.leader.publish(self.types["JointState"](name=ARM, position=q))
        self.deadman.publish(self.types["Bool"](data=self.deadman_on))

    def jog(self):
        """The wizard's jog: one servo half a degree from the last servo_angles sent
        (compute_ik's last step, or the last jog: where serial_node commands the servos;
        servo_state lags it by the link's round trip)."""
        last = self.angles_seen[-1][1]
        deg = [p * 180.0 / 3.141592653589793 for p in last.position]
        i = self.rng.randrange(3)
        deg[i] = min(max(deg[i] + self.rng.choice([-0.5, 0.5]), 20.0), 160.0)
        m = self.types["JointState"](name=SERVOS, position=[d * 3.141592653589793 / 180.0 for d in deg])
        m.header.stamp = self.o.node.get_clock().now().to_msg()
        self.servo_angles.publish(m)
        self.counts["jogs"] += 1
        self.note(f"jog {SERVOS[i]} to {deg[i]:.1f}")

    def estop(self, on):
        self.estop_pub.publish(self.types["Bool"](data=on))
        self.estop_on = on
        self.note(f"estop {on}")
        if on:
            self.counts["estops"] += 1

    # ---------------------------------------------------------------- the checks

    def judge_angles(self):
        """Every servo_angles since the last call against the one before it: no servo
        moves further than its speed allows in a period (or in the time between their
        stamps, if longer). Each commander steps within the limits once a period, so two
        commanders moving a joint in the same periods show as a longer step."""
        seen = self.angles_seen
        for i in range(max(self.angles_read, 1), len(seen)):
            (_, a), (_, b) = seen[i - 1], seen[i]
            dt = max(PERIOD_S, stamp_s(b.header.stamp) - stamp_s(a.header.stamp))
            for name, x, y in zip(b.name, a.position, b.position):
                step, most = abs(y - x) * 180 / math.pi, self.speed[name] * dt * 1.01 + 0.01
                if step > most:
                    self.failures.append(f"{name} stepped {step:.2f} deg in one step (at most {most:.2f}): "
                                         f"the soak's last moves: {self.recent()}")
        self.angles_read = len(seen)

    def judge(self):
        """Judge the diagnostics and servo_state received since the last call."""
        self.judge_angles()
        new = self.diagnostics[self.read:]
        self.read = len(self.diagnostics)
        for _, arr in new:
            for s in arr.status:
                v = status_values(s)
                if s.name.startswith("compute_ik"):
                    self.judge_compute_ik(v)
                elif s.name.startswith("serial_node"):
                    self.judge_serial_node(v)

    def judge_compute_ik(self, v):
        sent = v.get("servo_angles_sent")
        for key in ("calibrating", "estop"):
            held = getattr(self, f"held_{key}", None)
            if v.get(key) == "true" and sent is not None:
                if held is None:
                    setattr(self, f"held_{key}", sent)
                elif held != sent:
                    self.failures.append(f"compute_ik sent servo_angles while {key}: {held} -> {sent}")
                    setattr(self, f"held_{key}", sent)
            else:
                setattr(self, f"held_{key}", None)

    def judge_serial_node(self, v):
        # (frames serial_node's velocity guard ramped: reported, not judged; a burst of
        # steps at full speed coalesced by the link ramps too)
        self.ramped = v.get("frames_ramped_by_velocity_limit", self.ramped)
        if v.get("estop") == "true":
            if getattr(self, "estop_seen_at", None) is None:
                self.estop_seen_at = len(self.servo_state)
        else:
            self.check_held_servo_state()
            self.estop_seen_at = None

    def jumps(self, n=3):
        """The `n` largest changes between consecutive servo_angles received (deg), with
        when they came (s ago), their stamps' difference and the messages' stamps."""
        t = time.monotonic()
        seen = self.angles_seen[-500:]
        steps = []
        for (_, a), (at, b) in zip(seen, seen[1:]):
            d, i = max((abs(x - y) * 180 / math.pi, i) for i, (x, y) in enumerate(zip(a.position, b.position)))
            steps.append((d, f"{b.name[i]} {d:.1f} deg -{t - at:.2f} s (stamps {stamp_s(a.header.stamp):.3f} -> "
                             f"{stamp_s(b.header.stamp):.3f})"))
        return [text for _, text in sorted(steps, reverse=True)[:n]]

    def note(self, what):
        self.history.append((time.monotonic(), what))
        del self.history[:-200]

    def recent(self, n=8):
        t = time.monotonic()
        return [f"-{t - at:.2f} s {what}" for at, what in self.history[-n:]]

    def check_held_servo_state(self):
        at = getattr(self, "estop_seen_at", None)
        if at is None:
            return
        held = [tuple(round(p, 9) for p in m.position) for _, m in self.servo_state[at + 1:]]
        if len(set(held)) > 1:
            self.failures.append(f"servo_state moved during an e-stop: {sorted(set(held))[:3]}")

    # ---------------------------------------------------------------- the run

    def run(self, minutes):
        end = time.monotonic() + minutes * 60
        next_print = time.monotonic() + 60
        next_leader = time.monotonic()
        while time.monotonic() < end:
            now = time.monotonic()
            if now >= next_leader:
                self.leader_sample()
                next_leader = now + 0.02
            r = self.rng.random()
            if self.estop_on:
                if r < 0.05:
                    self.estop(False)
            elif r < 0.04:
                self.switch()
            elif r < 0.10:
                self.target()
            elif r < 0.12:
                self.trajectory()
            elif r < 0.14:
                self.gripper_goal()
            elif r < 0.15:
                self.deadman_on = not self.deadman_on
                self.note(f"deadman {self.deadman_on}")
                self.counts["leader_sessions"] += self.deadman_on
            elif r < 0.155:
                self.estop(True)
            elif r < 0.25 and getattr(self, "held_calibrating", None) is not None and self.angles_seen:
                self.jog()
            self.o.spin_for(0.02)
            self.judge()
            if now >= next_print:
                print(f"{time.strftime('%H:%M:%S')} {self.counts} failures {len(self.failures)}", flush=True)
                next_print = now + 60
        if self.estop_on:
            self.estop(False)
        self.deadman_on = False
        self.o.spin_for(1.0)
        self.judge()

    def close(self):
        codes = []
        for p in self.procs:
            p.send_signal(signal.SIGINT)
        for p in self.procs:
            try:
                codes.append(p.wait(20))
            except subprocess.TimeoutExpired:
                p.kill()
                codes.append(p.wait(10))
        for log in self.logs:
            log.close()
        self.o.close()
        if any(codes):
            self.failures.append(f"the nodes exited with {codes}")


def main():
    args = soaklib.arguments(__doc__, minutes=10.0, seed=1)
    work = Path(tempfile.mkdtemp(prefix="switching-"))
    with soaklib.domain() as domain:
        soak = Soak(domain, args.seed, work)
        try:
            soak.run(args.minutes)
        finally:
            soak.close()
    print(f"{args.minutes} min, seed {args.seed}: {soak.counts}; serial_node frames ramped: {soak.ramped}; "
          f"logs: {work}")
    soaklib.write_json(args.json, {"minutes": args.minutes, "seed": args.seed, **soak.counts,
                                   "frames_ramped": soak.ramped},
                       failures=soak.failures)
    soaklib.finish(soak.failures, 1, f"run of {args.minutes} min")

if __name__ == "__main__":
    main()
