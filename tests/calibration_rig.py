"""The modelled arm of issue 22's calibration test: the real firmware in simavr
(safety_rig.Rig: serial_node on its pty) whose pulses drive a model of a physical arm
with its servo horns mounted otherwise than config/arm.yaml expects, and the code that
drives the calibration wizard against it, shared by tests/test_calibration_wizard.py
(through the browser) and tests/bench/calibration.py (through the WebSocket protocol).

The model. Each servo's horn angle (deg, the Servo library's 0..180) is read from the
pulse width measured on its pin in simavr (544 us at 0°, 2400 us at 180°). The arm's
joint input then follows from the servo's *true* line, horn = offset + gain * input, the
same form as config/arm.yaml's calibration:

    base      input = base_joint (deg)
    shoulder  input = shoulder_joint (deg)
    elbow     input = forearm elevation phi = shoulder_joint + elbow_joint (deg)
    gripper   input = claw opening 0..1; gripper_joint = opening * 0.6 rad

ISSUE_ARM is issue 22's test arm: every horn 7° off, the forearm servo mirrored, and a
claw SG90 closed at 64°, fully open at 172° (the shipped closed 60°/open 180° cannot
reach 187°, so no +7° there).

The driving. A person at the arm jogs the active servo until the arm shows the reference
pose and marks it; here `match_reference` does the same from the modelled joint input:
one coarse step to see which way (and how far) the servo turns the joint, then coarse and
fine steps until the input is as close to the reference as a fine step gets.
"""
import json
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import yaml
from sensor_msgs.msg import JointState

from conftest import REPO, latest_status, status_values
from safety_rig import US_PER_DEG, Rig

PULSE_MIN_US = 544.0
# the order of the firmware's channels (pins 8..11) and of SET_PULSES
SERVOS = ("base", "shoulder", "elbow", "gripper")
GRIPPER_OPEN_RAD = 0.6  # config/arm.yaml geometry.gripper_open_rad
SHIPPED_CONFIG = REPO / "config" / "arm.yaml"
FINE_DEG, COARSE_DEG = 0.5, 5.0  # the wizard's jog steps (libs/kinematics/src/calibration.rs)


# ------------------------------------------------------------------------------------
# The model: pulse -> horn -> joint input -> joints


@dataclass(frozen=True)
class ArmModel:
    """A physical arm: each servo's true line (offset_deg, gain), horn = offset + gain * input."""

    base: tuple
    shoulder: tuple
    elbow: tuple
    gripper: tuple
    name: str = "arm"

    def line(self, servo):
        return getattr(self, servo)


# issue 22's test arm: offsets +7° (base 90, shoulder 180, elbow 90 shipped), the elbow
# reversed (shipped gain +1), the claw closed at 64°, open at 172° (gain 108)
ISSUE_ARM = ArmModel(base=(97.0, -2.0), shoulder=(187.0, -1.0), elbow=(97.0, -1.0), gripper=(64.0, 108.0),
                     name="issue 22 (+7°, elbow reversed, claw 64..172°)")


def horn_deg(width_us):
    """The horn angle of a measured pulse width (ROBOT.md: 544 us at 0°, 2400 us at 180°)."""
    return (width_us - PULSE_MIN_US) / US_PER_DEG


def servo_input(model, servo, horn):
    """The joint input the arm shows with `servo`'s horn at `horn` degrees."""
    offset, gain = model.line(servo)
    return (horn - offset) / gain


def modelled_joints(model, horns):
    """The arm's joints for horn angles {servo: deg}: base_joint, shoulder_joint,
    elbow_joint = phi - shoulder, phi (deg), opening (0..1) and gripper_joint (deg)."""
    base = servo_input(model, "base", horns["base"])
    shoulder = servo_input(model, "shoulder", horns["shoulder"])
    phi = servo_input(model, "elbow", horns["elbow"])
    opening = servo_input(model, "gripper", horns["gripper"])
    return {"base_joint": base, "shoulder_joint": shoulder, "elbow_joint": phi - shoulder, "phi": phi,
            "opening": opening, "gripper_joint": math.degrees(opening * GRIPPER_OPEN_RAD)}


# ------------------------------------------------------------------------------------
# Targets and what a configuration commands for them


JOINTS = ("base_joint", "shoulder_joint", "elbow_joint", "gripper_joint")


@dataclass(frozen=True)
class Target:
    """A joint target: degrees, and the claw's opening 0..1."""

    base: float
    shoulder: float
    elbow: float
    opening: float

    def joints_deg(self):
        return {"base_joint": self.base, "shoulder_joint": self.shoulder, "elbow_joint": self.elbow,
                "gripper_joint": math.degrees(self.opening * GRIPPER_OPEN_RAD)}

    def inputs(self):
        """Each servo's input (config/arm.yaml's convention)."""
        return {"base": self.base, "shoulder": self.shoulder, "elbow": self.shoulder + self.elbow,
                "gripper": self.opening}

    def msg(self):
        """The joint_target message (rad), stamped now."""
        m = JointState(name=list(JOINTS), position=[math.radians(d) for d in self.joints_deg().values()])
        t = time.time()
        m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
        return m

    def __str__(self):
        return f"base {self.base:g}°, shoulder {self.shoulder:g}°, elbow {self.elbow:g}°, claw {self.opening:g}"


def servo_lines(config_path):
    """A configuration's calibration {servo: {offset_deg, gain, min_deg, max_deg, ...}}."""
    return yaml.safe_load(Path(config_path).read_text())["servos"]


def commanded_deg(lines, target):
    """The servo angles a configuration commands for `target` (servo_deg = offset + gain *
    input, inside min_deg..max_deg)."""
    out = {}
    for servo, value in target.inputs().items():
        c = lines[servo]
        out[servo] = min(max(c["offset_deg"] + c["gain"] * value, c["min_deg"]), c["max_deg"])
    return out


def joint_errors(model, horns, target):
    """|modelled joint - commanded| (deg) of each of JOINTS."""
    got = modelled_joints(model, horns)
    want = target.joints_deg()
    return {j: abs(got[j] - want[j]) for j in JOINTS}


# ------------------------------------------------------------------------------------
# The pulses, read as simavr writes them


class PulseTail:
    """Follows a servo_sim events file as it grows: every complete pulse per pin."""

    def __init__(self, events_path):
        self.path = Path(events_path)
        self.offset, self.partial = 0, b""
        self.rise = [None] * 4
        self.pulses = [[] for _ in range(4)]  # [(rise cycle, width us)]

    def poll(self):
        try:
            with open(self.path, "rb") as f:
                f.seek(self.offset)
                data = f.read()
        except FileNotFoundError:
            return
        self.offset += len(data)
        data = self.partial + data
        lines = data.split(b"\n")
        self.partial = lines.pop()  # an incomplete last line (the harness flushes in blocks)
        for line in lines:
            if not line.startswith(b"e "):
                continue
            p = line.split()
            if len(p) != 4:
                continue
            cycle, pin, level = int(p[1]), int(p[2]), int(p[3])
            if not 0 <= pin < 4:
                continue
            if level == 1:
                self.rise[pin] = cycle
            elif self.rise[pin] is not None:
                self.pulses[pin].append((self.rise[pin], (cycle - self.rise[pin]) / 16))
                self.rise[pin] = None
        for ps in self.pulses:
            if len(ps) > 4000:
                del ps[:2000]

    def counts(self):
        """Each pin's newest pulse (its rise cycle; -1 before any): pass one as `after` to
        settled() to wait for pulses newer than it."""
        self.poll()
        return [self._n(pin) for pin in range(4)]

    def _n(self, pin):
        ps = self.pulses[pin]
        return ps[-1][0] if ps else -1  # the last rise cycle identifies the pulse

    def settled(self, pin, n=5, spread_us=1.5, after=None):
        """The mean width of `pin`'s last `n` pulses if they lie within `spread_us` of each
        other (and all rose after the pulse `after` identifies), else None."""
        self.poll()
        ps = self.pulses[pin]
        if len(ps) < n:
            return None
        last = ps[-n:]
        if after is not None and last[0][0] <= after:
            return None
        widths = [w for _, w in last]
        if max(widths) - min(widths) > spread_us:
            return None
        return sum(widths) / n

    def latest_us(self, pin):
        self.poll()
        return self.pulses[pin][-1][1] if self.pulses[pin] else None


# ------------------------------------------------------------------------------------
# The graph: the firmware in simavr, serial_node, compute_ik, state_publisher, gui_bridge


class CalibrationGraph:
    """`launch(name, *args)` starts a node (the tests' fixture or the benchmark's Launcher);
    `tmp` a directory of this run's own. gui_bridge saves its calibration to
    `tmp/arm.yaml` (created from the shipped config when missing); every node starts with
    the shipped calibration (no arm_config)."""

    def __init__(self, launch, observer, tmp, gui_port, gui_args=None):
        self.o, self.tmp = observer, Path(tmp)
        self.calibration_file = self.tmp / "arm.yaml"
        board = self.tmp / "board"
        board.mkdir(exist_ok=True)
        self.rig = Rig(launch, observer, board)
        self.compute_ik = launch("compute_ik")
        self.state_publisher = launch("state_publisher")
        self.gui_port = gui_port
        if gui_args is None:
            gui_args = ("-p", f"calibration_file:={self.calibration_file}")
        self.gui = launch("gui_bridge", "--ros-args", "-p", f"bind:=127.0.0.1:{gui_port}", *gui_args)
        self.joint_target = observer.pub("/joint_target", JointState)
        observer.wait_matched(self.joint_target)
        self.tail = PulseTail(self.rig.board.events_path)
        assert observer.spin_until(self.rig.connected, 15), f"serial_node did not connect: {self.rig.diag()}"

    def stop_board(self):
        """The simavr process goes with the test (a harness left running takes a sixth of a core)."""
        return self.rig.stop()

    def diag(self, node):
        return status_values(latest_status(self.rig.diags, node))

    def horns(self, n=5, spread_us=1.5, after=None):
        """Every horn's settled angle {servo: deg}, or None while any moves."""
        out = {}
        for pin, servo in enumerate(SERVOS):
            w = self.tail.settled(pin, n, spread_us, None if after is None else after[pin])
            if w is None:
                return None
            out[servo] = horn_deg(w)
        return out

    def move(self, target, lines, timeout=30.0, tolerance_deg=0.3):
        """Publish `target` on joint_target and wait until every pulse has settled where
        `lines` (the calibration compute_ik uses) commands it, or until `timeout`.
        Returns (horns, arrived): the settled horn angles (the last measured when it did
        not settle) and whether they are where `lines` put them."""
        want = commanded_deg(lines, target)
        before = self.tail.counts()
        self.joint_target.publish(target.msg())
        end = time.monotonic() + timeout
        again = time.monotonic() + 2.5
        horns = None
        while time.monotonic() < end:
            self.o.spin_for(0.05)
            if time.monotonic() > again:  # refused (a node still busy)? the same target once more
                self.joint_target.publish(target.msg())
                again = end
            horns = self.horns(n=6, after=before)
            if horns and all(abs(horns[s] - want[s]) <= tolerance_deg for s in SERVOS):
                return horns, True
        if horns is None:  # report where it was anyway
            horns = {s: horn_deg(self.tail.latest_us(p) or PULSE_MIN_US) for p, s in enumerate(SERVOS)}
        return horns, False

    def errors_over(self, targets, lines, model):
        """Per target: (target, {joint: |error| deg}, arrived, compute_ik's diagnostics when not)."""
        out = []
        for t in targets:
            horns, arrived = self.move(t, lines)
            out.append((t, joint_errors(model, horns, t), arrived, None if arrived else self.diag("compute_ik")))
        return out

    def param(self, node, name, timeout=10.0):
        """A parameter's value (bool, int, float or str; None when unset or no answer),
        through the node's get_parameters service."""
        from rcl_interfaces.msg import ParameterType
        from rcl_interfaces.srv import GetParameters

        cli = self.o.node.create_client(GetParameters, f"/{node}/get_parameters")
        try:
            if not cli.wait_for_service(timeout_sec=timeout):
                return None
            fut = cli.call_async(GetParameters.Request(names=[name]))
            if not self.o.spin_until(fut.done, timeout) or not fut.result().values:
                return None
            v = fut.result().values[0]
            return {ParameterType.PARAMETER_BOOL: v.bool_value, ParameterType.PARAMETER_INTEGER: v.integer_value,
                    ParameterType.PARAMETER_DOUBLE: v.double_value,
                    ParameterType.PARAMETER_STRING: v.string_value}.get(v.type)
        finally:
            self.o.node.destroy_client(cli)

    def calibrating(self, timeout=10.0):
        """Whether compute_ik's `calibration` controller is active (the wizard holds the
        arm), through controller_manager/list_controllers; None: no answer."""
        from controller_manager_msgs.srv import ListControllers

        cli = self.o.node.create_client(ListControllers, "/controller_manager/list_controllers")
        try:
            if not cli.wait_for_service(timeout_sec=timeout):
                return None
            fut = cli.call_async(ListControllers.Request())
            if not self.o.spin_until(fut.done, timeout):
                return None
            return any(c.name == "calibration" and c.state == "active" for c in fut.result().controller)
        finally:
            self.o.node.destroy_client(cli)


# ------------------------------------------------------------------------------------
# Driving the wizard: its requests ({"t":"calibrate","op":...} on the panel's WebSocket)
# sent by a driver (clicks in the browser, or the JSON itself), which keeps the latest
# `calibration` message the node broadcasts


class WizardFailed(AssertionError):
    pass


class WizardDriver:
    """The common part: the latest `calibration` and `status` messages, refusals, and
    waiting."""

    def __init__(self):
        self.status = None  # the latest {"t":"status",...}: the nodes, compute_ik's controllers
        self.cal = None  # the latest {"t":"calibration",...}
        self.cal_count = 0
        self.refusals = []
        self.log = []
        self.jogs = 0  # jog requests sent

    def on_message(self, text):
        try:
            m = json.loads(text)
        except (TypeError, ValueError):
            return
        if not isinstance(m, dict):
            return
        if m.get("t") == "calibration":
            self.cal = m
            self.cal_count += 1
        elif m.get("t") == "status":
            self.status = m
        elif m.get("t") == "refused":
            self.refusals.append(m.get("reason"))

    def note(self, text):
        self.log.append(text)

    def wait(self, predicate, timeout, what):
        end = time.monotonic() + timeout
        while True:
            if self.cal is not None and predicate(self.cal):
                return self.cal
            if time.monotonic() > end:
                raise WizardFailed(f"{what}: not within {timeout} s; last calibration message: "
                                   f"{json.dumps(self.cal)[:3000]}; refusals: {self.refusals[-5:]}; "
                                   f"log: {self.log[-30:]}")
            self.pump(0.02)

    # what a driver implements
    def pump(self, seconds):
        raise NotImplementedError

    def start(self):
        raise NotImplementedError

    def jog(self, deg):
        raise NotImplementedError

    def mark(self):
        raise NotImplementedError

    def set_alternative(self, on):
        raise NotImplementedError

    def save(self):
        raise NotImplementedError

    def finish(self):
        raise NotImplementedError


def active_reference(cal):
    """(servo, step index, reference index, reference dict) the wizard waits for."""
    step = cal["steps"][cal["step"]]
    r = cal["reference"]
    ref = step["alternative_b"] if r == 1 and step.get("use_alternative") and step.get("alternative_b") else step["references"][r]
    return step["servo"], cal["step"], r, ref


def settle_at_commanded(driver, graph, servo, after, timeout=5.0, tolerance_deg=0.3):
    """The active servo's horn once its pulses have settled at the commanded angle (pulses
    newer than `after`, a PulseTail pulse id); the settled horn after `timeout` otherwise."""
    pin = SERVOS.index(servo)
    end = time.monotonic() + timeout
    last = None
    while time.monotonic() < end:
        w = graph.tail.settled(pin, n=5, spread_us=1.5, after=after)
        cmd = driver.cal.get("commanded_deg") if driver.cal else None
        if w is not None:
            last = horn_deg(w)
            if cmd is None or abs(last - cmd) <= tolerance_deg:
                return last
        driver.pump(0.02)
    if last is None:
        raise WizardFailed(f"{servo}: its pulses never settled (commanded {driver.cal.get('commanded_deg')}°); "
                           f"last pulses {graph.tail.pulses[pin][-5:]}; log: {driver.log[-20:]}")
    driver.note(f"{servo}: settled at {last:.2f}° but commanded {driver.cal.get('commanded_deg')}°")
    return last


def jog_once(driver, deg, timeout=4.0):
    """One jog of `deg` (±FINE_DEG or ±COARSE_DEG); waits until the message shows the new
    commanded angle (clamped into the jog range, as the wizard does). Returns it."""
    cal = driver.cal
    old = cal["commanded_deg"]
    jog = cal.get("jog") or {}
    lo, hi = jog.get("min_deg", 0.0), jog.get("max_deg", 180.0)
    want = min(max(old + deg, lo), hi)
    if abs(want - old) < 1e-9:
        return old  # at the end of the range: the wizard would clamp it to where it is
    driver.jog(deg)
    driver.jogs += 1
    driver.wait(lambda c: c.get("commanded_deg") is not None and abs(c["commanded_deg"] - want) < 1e-6,
                timeout, f"jog {deg:+g}° from {old}° (expected {want}°)")
    return want


def match_reference(driver, graph, model, sensitivity, timeout=60.0):
    """Jog the active servo until the modelled arm shows the active reference as closely
    as a fine step gets (what the user does by eye). `sensitivity` {servo: (input0,
    cmd0)} keeps the first point seen of each servo, to tell its direction and rate.
    Switches to the alternative B when B lies outside the jog range. Returns the input
    the arm shows."""
    deadline = time.monotonic() + timeout
    servo, step_i, ref_i, ref = active_reference(driver.cal)
    want = ref["input"]

    def measure():
        horn = settle_at_commanded(driver, graph, servo, graph.tail.counts()[SERVOS.index(servo)])
        return servo_input(model, servo, horn), driver.cal["commanded_deg"]

    x, cmd = measure()
    if servo not in sensitivity:
        sensitivity[servo] = (x, cmd)
    x0, cmd0 = sensitivity[servo]
    if abs(cmd - cmd0) < 2.0:
        # one coarse step (inside the jog range) shows which way and how far the joint goes
        jog = driver.cal.get("jog") or {"min_deg": 0.0, "max_deg": 180.0}
        d = COARSE_DEG if cmd + COARSE_DEG <= jog["max_deg"] else -COARSE_DEG
        jog_once(driver, d)
        x, cmd = measure()
    while True:
        if time.monotonic() > deadline:
            raise WizardFailed(f"{servo}: reference {ref_i} ({want}) not matched within {timeout} s; log: {driver.log[-20:]}")
        rate = (x - x0) / (cmd - cmd0)  # input per servo degree
        need = (want - x) / rate  # servo degrees to go
        fine_steps = round(need / FINE_DEG)
        driver.note(f"{servo} ref {ref_i}: at {cmd}° the arm shows {x:.3f} (want {want}); {fine_steps} fine steps to go")
        if fine_steps == 0:
            return x
        jog = driver.cal.get("jog") or {"min_deg": 0.0, "max_deg": 180.0}
        goal = cmd + fine_steps * FINE_DEG
        if not jog["min_deg"] - 1e-9 <= goal <= jog["max_deg"] + 1e-9:
            step = driver.cal["steps"][step_i]
            if ref_i == 1 and step.get("alternative_b") and not step.get("use_alternative"):
                driver.note(f"{servo}: {want} needs {goal:.2f}°, outside the jog range "
                            f"{jog['min_deg']}..{jog['max_deg']}: the alternative B")
                driver.set_alternative(True)
                driver.wait(lambda c: c["steps"][step_i].get("use_alternative"), 5, "the alternative B taken")
                # the wizard moves the servo to where the alternative is expected
                driver.wait(lambda c: c.get("phase") == "jog", 10, "the servo at the alternative B's expected angle")
                _, _, _, ref = active_reference(driver.cal)
                want = ref["input"]
                x, cmd = measure()
                continue
            raise WizardFailed(f"{servo}: reference {ref_i} ({want}) needs {goal:.2f}°, outside the jog range "
                               f"{jog['min_deg']}..{jog['max_deg']}; log: {driver.log[-20:]}")
        sign = 1 if fine_steps > 0 else -1
        coarse, fine = divmod(abs(fine_steps), round(COARSE_DEG / FINE_DEG))
        for _ in range(coarse):
            jog_once(driver, sign * COARSE_DEG)
        for _ in range(fine):
            jog_once(driver, sign * FINE_DEG)
        x, cmd = measure()


def run_wizard(driver, graph, model, timeout=400.0):
    """The whole follower calibration: start, both references of every step matched and
    marked, save, the guided test move, finish. Returns the `calibration` message after
    the test move (its `saved` says where it went). (`timeout` only bounds a failure:
    about 40 s on a quiet host, three minutes on a starved one.)"""
    deadline = time.monotonic() + timeout
    driver.start()
    driver.wait(lambda c: c.get("active") and c.get("phase") == "jog", 20, "the wizard started (phase jog)")
    sensitivity = {}
    while True:
        cal = driver.cal
        if time.monotonic() > deadline:
            raise WizardFailed(f"the wizard did not finish its steps within {timeout} s; log: {driver.log[-30:]}")
        errors = [(s["servo"], s["error"]) for s in cal["steps"] if s.get("error")]
        if errors or cal.get("phase") == "failed":
            raise WizardFailed(f"the wizard refused: {errors or cal.get('error')}; log: {driver.log[-30:]}")
        if cal.get("phase") == "review" or (cal.get("phase") != "moving" and all(s.get("derived") for s in cal["steps"])):
            break  # every servo marked and derived
        if cal.get("phase") != "jog":
            driver.pump(0.05)
            continue
        match_reference(driver, graph, model, sensitivity)
        mark_reference(driver)
    driver.note(f"derived: {[(s['servo'], s['derived']) for s in driver.cal['steps']]}")
    n_refused = len(driver.refusals)
    driver.save()
    # saving, then the guided test move (phase "testing"), done when joint_states show it
    # arrived; a save that failed goes back to "review" with the reason
    driver.wait(lambda c: c.get("phase") not in ("review", "saving") or (c.get("phase") == "review" and c.get("saved"))
                or len(driver.refusals) > n_refused, 20, "saved")
    if driver.cal.get("phase") in ("review", "failed") or len(driver.refusals) > n_refused:
        raise WizardFailed(f"not saved: {driver.cal.get('error')}; refusals {driver.refusals[n_refused:]}; "
                           f"saved: {driver.cal.get('saved')}")
    driver.wait(lambda c: (c.get("test") or {}).get("done") or c.get("phase") in ("done", "tested", "failed"), 30,
                "the guided test move done")
    if not (driver.cal.get("test") or {}).get("done"):
        raise WizardFailed(f"the guided test move did not arrive: phase {driver.cal.get('phase')}, "
                           f"error {driver.cal.get('error')}, test {driver.cal.get('test')}")
    tested = driver.cal
    driver.finish()
    driver.wait(lambda c: not c.get("active"), 10, "the wizard finished (active false)")
    return tested


def mark_reference(driver):
    """Mark the active reference; marked again while the wizard refuses (the servo has
    not arrived yet). Returns once the wizard has moved on from it."""
    before = (driver.cal["step"], driver.cal["reference"], driver.cal.get("phase"))
    for attempt in range(10):
        n_refused, error = len(driver.refusals), driver.cal.get("error")
        driver.mark()
        refused = lambda c: len(driver.refusals) > n_refused or c.get("error") not in (None, error)  # noqa: E731
        driver.wait(lambda c: (c["step"], c["reference"], c.get("phase")) != before or refused(c),
                    5, f"mark of step {before[0]} reference {before[1]}")
        if (driver.cal["step"], driver.cal["reference"], driver.cal.get("phase")) != before:
            servo = driver.cal["steps"][before[0]]["servo"]
            driver.note(f"marked {servo} reference {before[1]}: marks {driver.cal['steps'][before[0]]['marks']}")
            return
        driver.note(f"mark refused: {driver.refusals[n_refused:] or driver.cal.get('error')}")
        driver.pump(0.3)
    raise WizardFailed(f"mark refused every time: {driver.refusals[-10:]}, {driver.cal.get('error')}; log: {driver.log[-20:]}")


class WsWizard(WizardDriver):
    """Drives the wizard over the panel's WebSocket JSON protocol (no browser): for the
    benchmark."""

    def __init__(self, port, timeout=15.0):
        super().__init__()
        from websockets.sync.client import connect

        end = time.monotonic() + timeout
        while True:
            try:
                self.ws = connect(f"ws://127.0.0.1:{port}/ws", origin=f"http://127.0.0.1:{port}",
                                  subprotocols=["eezybot.panel.v1"], open_timeout=5, max_size=None)
                break
            except OSError:
                if time.monotonic() > end:
                    raise
                time.sleep(0.2)
        self.lock = threading.Lock()
        self.closed = False
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        try:
            for text in self.ws:
                with self.lock:
                    self.on_message(text)
        except Exception:  # noqa: BLE001 (closed)
            self.closed = True

    def pump(self, seconds):
        time.sleep(seconds)

    def send(self, op, **kw):
        self.ws.send(json.dumps({"t": "calibrate", "op": op, **kw}))

    def start(self):
        self.send("start", arm="follower")

    def jog(self, deg):
        self.send("jog", deg=deg)

    def mark(self):
        self.send("mark")

    def set_alternative(self, on):
        self.send("alternative", on=on)

    def save(self):
        self.send("save")

    def finish(self):
        self.send("finish")

    def cancel(self):
        self.send("cancel")

    def close(self):
        try:
            self.ws.close()
        except Exception:  # noqa: BLE001
            pass

