"""`gui_bridge calibrate [--leader]`: the calibration wizard on the command line
(nodes/gui_bridge/src/calibrate_cli.rs), driven line by line on its standard input, the
way a person at a terminal does: read the status line it prints after every change, jog,
mark, save, quit.

The arm is serial_node's virtual Arduino (`port:=mock`), whose servos are calibrated
exactly as the shipped config/arm.yaml says (servo_deg = offset + gain * input: base
90/-2, main arm 180/-1, forearm 90/+1 with input the forearm elevation phi, claw
60/120). So the shipped angle of each reference is where the arm shows it, and a
calibration marked there is the shipped one again:

    base      A 0°        -> 90°    B 45° left  -> 0°
    forearm   A phi 0°    -> 90°    B phi -45°  -> 45°
    main arm  A 90°       -> 90°    B 45°       -> 135°
    claw      A closed    -> 60°    B open      -> 180°

Every process gets an XDG_CONFIG_HOME of the test's own (the default save path). No
timing is asserted."""
import math
import os
import re
import subprocess
import threading
import time
import types

import pytest
from sensor_msgs.msg import JointState

from calibration_rig import SHIPPED_CONFIG, CalibrationGraph, servo_lines
from conftest import OUTPUT, bin_path, default_sigint

# compute_ik, state_publisher and serial_node on the mock, plus the CLI: the same kind of
# graph as tests/test_gui_bridge.py's, in this pytest process; the limit bounds a hang
pytestmark = [pytest.mark.timeout(90)]

# the steps in the order the wizard takes them: (title, servo, shipped angle of A, of B)
REFERENCES = [("Base", "base", 90.0, 0.0), ("Forearm", "elbow", 90.0, 45.0),
              ("Main arm", "shoulder", 90.0, 135.0), ("Claw", "gripper", 60.0, 180.0)]
SERVO_OF = {title: servo for title, servo, _, _ in REFERENCES}
FINE, COARSE = 0.5, 5.0

# `[jog 1/4 Base] servo at 90.0° (servo_state 90.0°; may jog 80.0° … 100.0°) marks: Base –/–, ...`
STATUS = re.compile(r"^\[(?P<phase>\w+) (?P<step>\d)/4 (?P<title>[^\]]+)\] "
                    r"(?:servo at (?P<cmd>-?[\d.]+)° \(servo_state (?P<state>–|-?[\d.]+°); "
                    r"may jog (?P<lo>-?[\d.]+)° … (?P<hi>-?[\d.]+)°\) )?"
                    r"(?:leader counts [^m]*)?marks: (?P<marks>.*)$")


def parse_marks(text):
    """`Base 90.0/–, Forearm –/–, ...` -> {"Base": (90.0, None), ...}"""
    out = {}
    for part in text.split(", "):
        title, _, ab = part.rpartition(" ")
        out[title] = tuple(None if v == "–" else float(v) for v in ab.split("/"))
    return out


class Status:
    def __init__(self, m, instruction):
        self.phase, self.step, self.title = m["phase"], int(m["step"]), m["title"]
        self.cmd = None if m["cmd"] is None else float(m["cmd"])
        self.jog = None if m["lo"] is None else (float(m["lo"]), float(m["hi"]))
        self.marks = parse_marks(m["marks"])
        self.instruction = instruction

    def __repr__(self):
        return f"<{self.phase} {self.step}/4 {self.title} at {self.cmd} jog {self.jog} marks {self.marks}>"


class Cli:
    """`gui_bridge calibrate` with a pipe on stdin; its stdout read line by line (a
    thread), its stderr (the log) to a file under test-output."""

    def __init__(self, domain, tmp_path, *args):
        OUTPUT.mkdir(parents=True, exist_ok=True)
        self.log_path = OUTPUT / f"gui_bridge-calibrate-{time.monotonic_ns()}.log"
        self.err = open(self.log_path, "w")
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "XDG_CONFIG_HOME": str(tmp_path / "xdg")}
        self.proc = subprocess.Popen([bin_path("gui_bridge"), "calibrate", *args], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=self.err, env=env, text=True, bufsize=1,
                                     preexec_fn=default_sigint)
        self.lines = []
        self.lock = threading.Lock()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self):
        for line in self.proc.stdout:
            with self.lock:
                self.lines.append(line.rstrip("\n"))

    def send(self, line):
        """Send one line; returns the index of the first output line after it."""
        with self.lock:
            n = len(self.lines)
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        return n

    def text(self, since=0):
        with self.lock:
            return "\n".join(self.lines[since:])

    def statuses(self, since=0):
        with self.lock:
            lines = self.lines[since:]
        out = []
        for i, line in enumerate(lines):
            m = STATUS.match(line)
            if m:
                out.append(Status(m, lines[i + 1].strip() if i + 1 < len(lines) else ""))
        return out

    def wait(self, predicate, timeout, what, observer, since=0):
        """The newest status line (printed at or after line `since`) once it satisfies
        `predicate`; spins the observer meanwhile."""
        end = time.monotonic() + timeout
        while True:
            st = self.statuses(since)
            if st and predicate(st[-1]):
                return st[-1]
            if time.monotonic() > end or self.proc.poll() is not None:
                raise AssertionError(f"{what}: not within {timeout} s (exit {self.proc.poll()}); "
                                     f"output:\n{self.text()[-3000:]}\nlog:\n{self.log()[-2000:]}")
            observer.spin_for(0.02)

    def wait_text(self, needle, timeout, observer, since=0):
        end = time.monotonic() + timeout
        while needle not in self.text(since):
            if time.monotonic() > end:
                raise AssertionError(f"{needle!r} not printed within {timeout} s; output:\n{self.text()[-3000:]}")
            observer.spin_for(0.02)

    def quit(self, line="q", timeout=15):
        if line is not None:
            self.send(line)
        self.proc.stdin.close()
        code = self.proc.wait(timeout)
        self.reader.join(5)
        return code

    def log(self):
        self.err.flush()
        return self.log_path.read_text()

    def stop(self):
        """End it if a test left it running: the end of input cancels (compute_ik back)."""
        if self.proc.poll() is None:
            try:
                self.proc.stdin.close()
                self.proc.wait(10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(10)
        self.err.close()


class Graph:
    """compute_ik, state_publisher, serial_node on the mock; servo_state and
    joint_states heard."""

    def __init__(self, launch, observer):
        self.o = observer
        launch("compute_ik")
        launch("state_publisher")
        launch("serial_node", "--ros-args", "-p", "port:=mock")
        self.servo_state = observer.sub("/servo_state", JointState)
        self.joint_states = observer.sub("/joint_states", JointState)
        self.joint_target = observer.pub("/joint_target", JointState)
        observer.wait_matched(self.joint_target)
        observer.wait_publisher("/servo_state")
        assert observer.spin_until(lambda: self.servo_state and self.joint_states, 10), "no servo_state or joint_states"

    def servo_deg(self, servo, msg=None):
        """`servo` (deg) in the servo_state `msg`, by default the newest."""
        msg = msg or self.servo_state[-1][1]
        names = list(msg.name)
        k = next(i for i, n in enumerate(names) if n == servo or n.startswith(servo + "_"))
        return math.degrees(msg.position[k])

    def param(self, node, name):
        # CalibrationGraph.param needs only the observer (as tests/test_leader_calibration.py)
        return CalibrationGraph.param(types.SimpleNamespace(o=self.o), node, name)

    def calibrating(self):
        return CalibrationGraph.calibrating(types.SimpleNamespace(o=self.o))

    # (the bounds of this file's waits only end a failure: debug builds on a busy host)
    def wait_servo(self, servo, deg, timeout=20.0, tolerance=0.05):
        """servo_state shows `servo` at `deg` (what a person waits for before marking)."""
        ok = self.o.spin_until(lambda: abs(self.servo_deg(servo) - deg) <= tolerance, timeout)
        assert ok, f"servo_state: {servo} at {self.servo_deg(servo):.2f}°, not the commanded {deg}°"


@pytest.fixture
def graph(launch, observer, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))  # every process we start
    return Graph(launch, observer)


@pytest.fixture
def cli(domain, tmp_path):
    started = []

    def start(*args):
        c = Cli(domain, tmp_path, *args)
        started.append(c)
        return c

    yield start
    for c in started:
        c.stop()


def jog_to(cli, observer, target):
    """Jog the active servo to `target` (servo deg): coarse steps, then one `j` for the
    rest, each answered by a status line with the new command."""
    st = cli.statuses()[-1]
    while abs(target - st.cmd) > 1e-6:
        diff = target - st.cmd
        if abs(diff) >= COARSE:
            line, step = ("++" if diff > 0 else "--"), math.copysign(COARSE, diff)
        elif abs(diff) == FINE:
            line, step = ("+" if diff > 0 else "-"), diff
        else:
            line, step = f"j {diff:g}", diff
        want = st.cmd + step
        since = cli.send(line)
        st = cli.wait(lambda s: s.cmd is not None and abs(s.cmd - want) < 1e-6, 20, f"`{line}` to {want}°", observer,
                      since)
    return st


def try_mark(cli, graph, title, ref, deg):
    """Wait until servo_state shows the servo at `deg`, then `m` for reference `ref` (0
    A, 1 B). The CLI hears servo_state on a reader of its own, a moment after (or
    before) the observer: a mark it refuses as "not arrived yet" is made again, as a
    person would. Returns (the output's index before the `m` that counted, the status
    line after it)."""
    graph.wait_servo(SERVO_OF[title], deg)
    for _ in range(10):
        since = cli.send("m")
        st = cli.wait(lambda s: s.marks[title][ref] is not None or s.phase == "review"
                      or "has not arrived" in cli.text(since) or f"{title} refused" in cli.text(since),
                      20, f"{title} mark {'AB'[ref]}", graph.o, since)
        if st.marks[title][ref] is None and "has not arrived" in cli.text(since):
            graph.o.spin_for(0.2)
            continue
        return since, st
    raise AssertionError(f"{title} mark {'AB'[ref]}: not arrived every time: {cli.text()[-2000:]}")


def mark(cli, graph, title, ref, deg):
    """A mark the wizard takes (try_mark); the status line after it."""
    since, st = try_mark(cli, graph, title, ref, deg)
    assert st.marks[title][ref] == pytest.approx(deg, abs=0.05), (st, cli.text(since))
    return st


def wait_reference(cli, observer, title, ref):
    """The wizard waits for `title`'s reference `ref` (phase jog)."""
    return cli.wait(lambda s: s.phase == "jog" and s.title == title and f"Reference {'AB'[ref]} of 2" in s.instruction,
                    15, f"{title} reference {'AB'[ref]} next", observer)


def test_the_cli_calibrates_the_mock_arm_to_the_shipped_calibration(graph, cli, observer, tmp_path):
    calibration_file = tmp_path / "arm.yaml"
    c = cli("--ros-args", "-r", "__node:=calibrate", "-p", f"calibration_file:={calibration_file}")
    c.wait_text(f"the result goes to {calibration_file}", 10, observer)
    for title, servo, a, b in REFERENCES:
        for ref, deg in ((0, a), (1, b)):
            wait_reference(c, observer, title, ref)
            jog_to(c, observer, deg)
            mark(c, graph, title, ref, deg)
    st = c.wait(lambda s: s.phase == "review", 10, "every servo derived (review)", observer)
    assert st.marks == {"Base": (90.0, 0.0), "Forearm": (90.0, 45.0), "Main arm": (90.0, 135.0), "Claw": (60.0, 180.0)}
    since = c.send("s")
    # saved, applied, compute_ik back, the test move done (joint_states at the test pose)
    c.wait(lambda s: s.phase == "done", 30, "saved and the test move done", observer, since)
    out = c.text(since)
    assert f"saved to {calibration_file}" in out and "NOT applied" not in out, out
    assert c.quit() == 0, c.text()

    # the file: the shipped calibration (the mock's), the previous file kept as .bak
    shipped, saved = servo_lines(SHIPPED_CONFIG), servo_lines(calibration_file)
    for name in ("base", "shoulder", "elbow", "gripper"):
        for key in ("offset_deg", "gain", "min_deg", "max_deg"):
            assert saved[name][key] == pytest.approx(shipped[name][key], abs=1e-6), (name, key, saved[name])
    backup = calibration_file.with_name(calibration_file.name + ".bak")
    assert backup.exists(), sorted(p.name for p in tmp_path.iterdir())
    assert servo_lines(backup) == shipped  # the file did not exist: made from the shipped one first
    assert not (tmp_path / "xdg" / "eezybot" / "arm.yaml").exists()  # calibration_file, not the default
    # applied live: arm_config on compute_ik and serial_node, the arm given back (calibration inactive)
    for node in ("compute_ik", "serial_node"):
        assert graph.param(node, "arm_config") == str(calibration_file), node
    assert graph.calibrating() is False


def test_a_refused_mark_says_why_and_changes_nothing(graph, cli, observer, tmp_path):
    c = cli("--ros-args", "-r", "__node:=calibrate")
    wait_reference(c, observer, "Base", 0)
    mark(c, graph, "Base", 0, 90.0)
    wait_reference(c, observer, "Base", 1)
    # B (45° left) is at 0°; jogged the wrong way: the marks give a positive gain
    jog_to(c, observer, 95.0)
    since, _ = try_mark(c, graph, "Base", 1, 95.0)
    out = c.text(since)
    assert "Base refused" in out and "opposite direction" in out, out
    st = c.statuses(since)[-1]
    assert st.title == "Base" and st.marks["Base"] == (90.0, None), st
    assert "Reference B of 2" in st.instruction, st
    # the right way works
    jog_to(c, observer, 0.0)
    mark(c, graph, "Base", 1, 0.0)
    st = wait_reference(c, observer, "Forearm", 0)
    assert st.marks["Base"] == (90.0, 0.0), st
    assert c.quit() == 1
    assert not (tmp_path / "xdg" / "eezybot" / "arm.yaml").exists()


def test_quit_before_saving_cancels_and_gives_the_arm_back(graph, cli, observer, tmp_path):
    c = cli("--ros-args", "-r", "__node:=calibrate")
    wait_reference(c, observer, "Base", 0)
    assert graph.calibrating() is True
    jog_to(c, observer, 85.0)
    graph.wait_servo("base", 85.0)
    assert c.quit() == 1, c.text()
    assert "cancelled" in c.log(), c.log()
    assert not (tmp_path / "xdg" / "eezybot").exists(), list((tmp_path / "xdg").rglob("*"))
    assert graph.calibrating() is False
    # compute_ik takes targets again: joint_states move to one
    target = {"base_joint": 20.0, "shoulder_joint": 70.0, "elbow_joint": -100.0, "gripper_joint": 10.0}
    msg = JointState(name=list(target), position=[math.radians(v) for v in target.values()])
    now = time.time()
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
    graph.joint_target.publish(msg)

    def arrived():
        js = graph.joint_states[-1][1]
        q = dict(zip(js.name, js.position))
        return all(abs(q[j] - math.radians(v)) < 1e-3 for j, v in target.items())
    assert observer.spin_until(arrived, 10), graph.joint_states[-1][1]


def test_leader_calibration_without_a_leader_starts_moves_nothing_and_quits(graph, cli, observer):
    n0 = len(graph.servo_state)
    before = [graph.servo_deg(s) for _, s, _, _ in REFERENCES]
    c = cli("--leader", "--ros-args", "-r", "__node:=calibrate")
    c.wait_text("calibrating the leader arm", 10, observer)
    st = wait_reference(c, observer, "Base", 0)
    assert st.cmd is None and "Move the leader by hand" in st.instruction, st
    assert graph.calibrating() is False
    assert c.quit() == 1, c.text()
    # nothing moved while the wizard ran: a sentinel follows it, a joint target where the
    # arm is, stamped; every servo_state from the start up to the device's answer to it
    # (which carries its stamp) shows the servos where they were
    js = graph.joint_states[-1][1]
    q = dict(zip(js.name, js.position))
    joints = ["base_joint", "shoulder_joint", "elbow_joint", "gripper_joint"]
    sentinel = JointState(name=joints, position=[q[j] for j in joints])
    now = time.time()
    sentinel.header.stamp.sec, sentinel.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
    stamp = (sentinel.header.stamp.sec, sentinel.header.stamp.nanosec)
    graph.joint_target.publish(sentinel)

    def stamps():
        return [(m.header.stamp.sec, m.header.stamp.nanosec) for _, m in graph.servo_state[n0:]]
    assert observer.spin_until(lambda: stamp in stamps(), 20), "no servo_state answering the sentinel"
    for _, m in graph.servo_state[n0:n0 + stamps().index(stamp) + 1]:
        assert [graph.servo_deg(s, m) for _, s, _, _ in REFERENCES] == pytest.approx(before, abs=1e-6), m


def test_a_bad_line_prints_the_help_and_goes_on(cli, observer):
    c = cli("--leader", "--ros-args", "-r", "__node:=calibrate")
    wait_reference(c, observer, "Base", 0)
    since = c.send("frobnicate")
    c.wait_text("not a command", 20, observer, since)
    out = c.text(since)
    for word in ("`frobnicate`", "fine jog", "m mark", "s save", "q quit"):
        assert word in out, (word, out)
    assert c.proc.poll() is None
    since = c.send("?")
    c.wait_text("q quit", 20, observer, since)
    assert c.proc.poll() is None
    assert c.quit(None) == 1  # the end of the input cancels
