"""Issue 22: the leader arm's own calibration (ADC counts -> joint input) comes from the
same wizard as the follower's, end to end.

A modelled leader: the real firmware in the leader role in simavr (servo_sim --adc-file),
whose four potentiometers follow linear models (counts = a + b * input, the forearm's
reversed), moved "by hand" along a recorded motion that holds the leader at each of the
wizard's eight references in calibration order (base, forearm, main arm, claw; the poses
the wizard's view shows, holds included), deadman released throughout, then at a final
pose away from every reference. serial_node in the leader role reports its live counts
on diagnostics (`leader_counts`, every 0.1 s here) and, without a `leader:` section in
its arm_config, publishes no leader/joint_states.

The wizard is driven over the panel's WebSocket (tests/calibration_rig.py's WsWizard;
the browser is covered by tests/test_calibration_wizard.py): started for the leader,
each reference marked once the live counts show the leader there, saved. Then:

- every mark is the modelled counts of its reference;
- the file's `leader:` section holds the four channels as modelled, the previous file is
  kept as `.bak`, and arm_config was set on compute_ik and the leader's serial_node;
- the leader's serial_node now publishes leader/joint_states, and at the final pose its
  joints are the modelled ones within 1°.

No timing is asserted; the motion plays in real time (about 40 s)."""
import json
import math
import types
from pathlib import Path

import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from calibration_rig import SHIPPED_CONFIG, CalibrationGraph, WsWizard, servo_lines
from conftest import latest_status, status_values
from interop.servo_link import SimulatedUno, write_adc_file
from safety_rig import CYCLES_PER_S, FIRMWARE
from test_gui_bridge import free_port

# in a process of its own, beside the other tests (like test_leader_arm.py): the firmware
# in simavr, paced to wall time, mostly waited out (a starved simavr runs slower than real
# time: the limit only bounds a failure)
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=40), pytest.mark.timeout(900)]

AVCC_MV = 5000
ADC_MAX = 1023  # what the `leader:` section is written in (serial_node: fraction x 1024)
CHANNELS = ("base", "shoulder", "elbow", "gripper")  # A0..A3
COUNTS_TOLERANCE = 3.0
JOINT_TOLERANCE_DEG = 1.0

# The leader's potentiometers: counts = a + b * input (input: base_joint, shoulder_joint,
# forearm elevation phi in deg; claw opening 0..1), the forearm's mounted reversed. Over
# every joint's whole input range (base ±45, main arm 42.5..125, phi -65..20, claw 0..1)
# they stay inside the ADC (the wizard refuses a line that leaves it), every reference
# within 5 %..95 % of full scale.
POTS = {
    "base": (512.0, 5.6),        # 0° -> 512, 45° -> 764
    "shoulder": (-52.0, 5.6),    # 200 + 5.6 (input - 45): 45° -> 200, 90° -> 452
    "elbow": (600.0, -5.6),      # reversed: 0° -> 600, -45° -> 852
    "gripper": (300.0, 400.0),   # closed -> 300, open -> 700
}


def model_counts(inputs):
    """The counts A0..A3 of the leader at inputs {channel: input}."""
    return [POTS[c][0] + POTS[c][1] * inputs[c] for c in CHANNELS]


def counts_mv(counts):
    """The millivolts that read as `counts` (an integer): simavr's ADC returns
    mv * 1023 // AVCC (firmware/servo_control/sim/servo_sim.c hands it the mV rounded),
    so the smallest whole mV at or above counts * AVCC / 1023 reads exactly `counts`."""
    return math.ceil(counts * AVCC_MV / ADC_MAX - 1e-9)


# The final pose, away from every reference (inside every limit): base 20° left, main
# arm 70°, forearm 30° below horizontal, the claw half open. Its counts are whole.
FINAL = {"base": 20.0, "shoulder": 70.0, "elbow": -30.0, "gripper": 0.5}

# The motion (simulated ms since the leader's power-up): the first reference held while
# the graph finds the leader, then each reference held DWELL_MS, moved between in MOVE_MS.
# A mark must be taken while the leader holds its reference: the one time bound of this
# test (the recorded motion cannot wait for the wizard), asserted on the leader's own
# clock, with the share of the hold each mark used printed.
FIRST_DWELL_MS = 10_000
DWELL_MS = 3_000
MOVE_MS = 400
CYCLES_PER_MS = CYCLES_PER_S // 1000


def pose_inputs(pose, open_rad):
    """A view's pose {joint: rad} as the potentiometers' inputs."""
    shoulder = math.degrees(pose["shoulder_joint"])
    return {"base": math.degrees(pose["base_joint"]), "shoulder": shoulder,
            "elbow": shoulder + math.degrees(pose["elbow_joint"]), "gripper": pose["gripper_joint"] / open_rad}


def modelled_joints_deg(inputs, open_rad):
    return {"base_joint": inputs["base"], "shoulder_joint": inputs["shoulder"],
            "elbow_joint": inputs["elbow"] - inputs["shoulder"],
            "gripper_joint": math.degrees(inputs["gripper"] * open_rad)}


def motion(references, final):
    """The ADC file's points: each of `references` (counts A0..A3) held in order, then
    `final` held; the deadman released throughout. Returns (points, [(start, end) ms of
    each reference's hold], start ms of the final hold)."""
    points, windows = [], []
    t = 0
    for i, counts in enumerate(references):
        mv = [counts_mv(c) for c in counts]
        start = t
        end = start + (FIRST_DWELL_MS if i == 0 else DWELL_MS)
        points += [(start, mv, False), (end, mv, False)]
        windows.append((start, end))
        t = end + MOVE_MS
    mv = [counts_mv(c) for c in final]
    points += [(t, mv, False), (t + 600_000, mv, False)]
    return points, windows, t


class LeaderWizard(WsWizard):
    """WsWizard that also takes the wizard's view from the snapshot a new client gets
    first (`{"t":"hello",...,"calibration":{...}}`)."""

    def on_message(self, text):
        try:
            m = json.loads(text)
        except (TypeError, ValueError):
            return
        if isinstance(m, dict) and m.get("t") == "hello" and isinstance(m.get("calibration"), dict):
            self.cal = m["calibration"]
            self.cal_count += 1
            return
        super().on_message(text)


def test_the_wizard_calibrates_the_leader_arm(launch, observer, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))  # every process we start
    calibration_file = tmp_path / "arm.yaml"
    gui_port = free_port()
    launch("compute_ik")
    launch("state_publisher")
    launch("gui_bridge", "--ros-args", "-p", f"bind:=127.0.0.1:{gui_port}", "-p", "foxglove_bind:=",
           "-p", f"calibration_file:={calibration_file}")
    launch("serial_node", "--ros-args", "-p", "port:=mock")  # the follower, on the virtual Arduino
    diags = observer.sub("/diagnostics", DiagnosticArray)
    leader_js = observer.sub("/leader/joint_states", JointState)
    params = types.SimpleNamespace(o=observer)  # CalibrationGraph.param needs only the observer

    def leader_diag():
        return status_values(latest_status(diags, "leader_arm"))

    wizard = LeaderWizard(gui_port)
    leader = None
    try:
        # the wizard's references (and the poses it shows for them, holds included)
        wizard.wait(lambda c: c.get("steps"), 15, "the calibration view")
        view = wizard.cal
        open_rad = view["gripper_open_rad"]
        plan = []  # (step index, servo, reference index, reference input, the leader's inputs there)
        for i, step in enumerate(view["steps"]):
            assert CHANNELS[step["channel"]] == step["servo"], step
            for r, ref in enumerate(step["references"]):
                plan.append((i, step["servo"], r, ref["input"], pose_inputs(ref["pose"], open_rad)))
        assert [s for _, s, r, _, _ in plan if r == 0] == ["base", "elbow", "shoulder", "gripper"], plan
        for _, servo, _, want, inputs in plan:  # each pose shows its reference
            assert abs(inputs[servo] - want) < 1e-6, (servo, want, inputs)
        references = [model_counts(inputs) for *_, inputs in plan]
        for counts in references:
            assert all(0.05 * ADC_MAX <= c <= 0.95 * ADC_MAX for c in counts), counts
        final_counts = model_counts(FINAL)
        assert all(c == round(c) for c in final_counts), final_counts

        # the leader: its motion, the firmware in simavr, serial_node in the leader role
        leader_dir = tmp_path / "leader"
        leader_dir.mkdir()
        points, windows, final_start = motion(references, final_counts)
        write_adc_file(leader_dir / "motion.txt", points)
        leader = SimulatedUno(leader_dir, FIRMWARE, adc_file=leader_dir / "motion.txt")
        launch("serial_node", "--ros-args", "-r", "__node:=leader_arm", "-p", "role:=leader",
               "-p", f"port:={leader.tty_path}", "-p", "diagnostics_period:=0.1")
        assert observer.spin_until(lambda: leader_diag().get("connection") == "connected", 30), leader_diag()
        assert observer.spin_until(lambda: "leader_counts" in leader_diag(), 10), leader_diag()
        # the control: without a leader: section, no leader joints
        assert "not calibrated" in leader_diag().get("leader_joints", ""), leader_diag()
        assert not leader_js, leader_js[-1]

        # the wizard, for the leader
        wizard.send("start", arm="leader")
        wizard.wait(lambda c: c.get("active") and c.get("arm") == "leader" and c.get("phase") == "jog", 10,
                    "the leader's calibration started (phase jog)")
        assert wizard.cal.get("jog") is None and wizard.cal.get("commanded_deg") is None, wizard.cal
        n_refused = len(wizard.refusals)
        hold_used_ms = []
        for k, (step_i, servo, r, want, inputs) in enumerate(plan):
            expect = references[k]
            channel = CHANNELS.index(servo)
            # the user moves the leader there: the live counts show it
            wizard.wait(lambda c: c["step"] == step_i and c["reference"] == r and c.get("phase") == "jog", 5,
                        f"{servo} reference {r} next")
            # (judged on the leader's clock: the counts must show it before its hold ends;
            # the wall deadline only bounds a stuck simulation)
            at_ref = lambda c: c.get("counts") and all(abs(g - e) <= COUNTS_TOLERANCE  # noqa: E731
                                                       for g, e in zip(c["counts"], expect))
            wizard.wait(lambda c: at_ref(c) or leader.sim_cycle() > windows[k][1] * CYCLES_PER_MS, 600,
                        f"the leader at {servo} reference {r} ({want}): counts {expect}")
            assert at_ref(wizard.cal), f"the leader held {servo} reference {r} ({want}, counts {expect}) and the " \
                                       f"wizard never showed it: {wizard.cal.get('counts')}; {wizard.log[-5:]}"
            wizard.note(f"{servo} reference {r} ({want}): counts {wizard.cal['counts']}")
            wizard.mark()
            # the mark is the next report's counts of the step's channel
            wizard.wait(lambda c: c["steps"][step_i]["marks"][r] is not None or c["steps"][step_i].get("error")
                        or len(wizard.refusals) > n_refused, 5, f"{servo} reference {r} marked")
            # marked while the leader still held the reference (its clock, read after the
            # mark came back, bounds when the marked counts were sampled)
            hold_used_ms.append(leader.sim_cycle() / CYCLES_PER_MS - windows[k][0])
            assert hold_used_ms[-1] < windows[k][1] - windows[k][0], \
                f"{servo} reference {r} marked {hold_used_ms[-1]:.0f} ms into a hold of {windows[k][1] - windows[k][0]} ms"
            step = wizard.cal["steps"][step_i]
            assert len(wizard.refusals) == n_refused and not step.get("error"), \
                (wizard.refusals[n_refused:], step, wizard.log[-10:])
            assert abs(step["marks"][r] - expect[channel]) <= COUNTS_TOLERANCE, \
                (servo, r, step["marks"], expect[channel], wizard.log[-10:])
        wizard.wait(lambda c: c.get("phase") == "review", 5, "every channel derived (phase review)")
        for step_i, step in enumerate(wizard.cal["steps"]):
            d = step["derived"]
            assert d is not None, step
            ch = CHANNELS.index(step["servo"])
            ra, rb = [references[k] for k, p in enumerate(plan) if p[0] == step_i]
            assert abs(d["counts_a"] - ra[ch]) <= COUNTS_TOLERANCE and abs(d["counts_b"] - rb[ch]) <= COUNTS_TOLERANCE, \
                (step, ra[ch], rb[ch])
        print("\n".join(wizard.log))
        print("simulated ms of each hold used before its mark came back:", [round(u) for u in hold_used_ms])

        # save: the file, its backup, applied live; until then no leader joints at all
        assert not leader_js, leader_js[-1]
        wizard.save()
        wizard.wait(lambda c: c.get("saved") is not None and c.get("phase") != "saving"
                    or len(wizard.refusals) > n_refused, 20, "saved")
        cal = wizard.cal
        saved = cal["saved"] or {}
        assert len(wizard.refusals) == n_refused and cal.get("phase") == "done" and saved.get("path"), \
            (wizard.refusals[n_refused:], cal.get("phase"), cal.get("error"), saved)
        path = Path(saved["path"])
        assert path.resolve() == calibration_file.resolve(), saved
        applied = {n.rsplit("/", 1)[-1] for n in saved.get("applied") or []}
        assert {"compute_ik", "leader_arm", "serial_node"} <= applied and not saved.get("failed"), saved
        backup = path.with_name(path.name + ".bak")
        assert backup.exists() and saved.get("backup") and Path(saved["backup"]).resolve() == backup.resolve(), saved
        assert "leader" not in (yaml.safe_load(backup.read_text()) or {}), "the backup has a leader: section"
        written = yaml.safe_load(path.read_text())
        assert servo_lines(path) == servo_lines(SHIPPED_CONFIG), "the leader's calibration changed the servos"
        section = written.get("leader")
        assert section, f"no leader: section in {path}: {path.read_text()}"
        assert section.get("adc_max", ADC_MAX) == ADC_MAX, section
        for step_i, step in enumerate(cal["steps"]):
            servo = step["servo"]
            ch = CHANNELS.index(servo)
            (ka, _, _, in_a, _), (kb, _, _, in_b, _) = [(k, *p[1:]) for k, p in enumerate(plan) if p[0] == step_i]
            c = section.get(servo)
            assert c and c["input_a"] == in_a and c["input_b"] == in_b, (servo, c, in_a, in_b)
            assert abs(c["counts_a"] - references[ka][ch]) <= COUNTS_TOLERANCE, (servo, c, references[ka][ch])
            assert abs(c["counts_b"] - references[kb][ch]) <= COUNTS_TOLERANCE, (servo, c, references[kb][ch])
        for node in ("compute_ik", "leader_arm", "serial_node"):
            value = CalibrationGraph.param(params, node, "arm_config")
            assert value and Path(value).resolve() == path.resolve(), (node, value)

        # the leader's joints now: at the final pose, the modelled ones
        want = modelled_joints_deg(FINAL, open_rad)

        def at_final():
            if not leader_js:
                return False
            m = leader_js[-1][1]
            got = {n: math.degrees(p) for n, p in zip(m.name, m.position)}
            return set(got) == set(want) and all(abs(got[j] - want[j]) <= JOINT_TOLERANCE_DEG for j in want)

        assert observer.spin_until(lambda: leader_diag().get("leader_joints") == "published", 10), \
            f"the leader's serial_node did not take the leader: section of the arm_config set on it: {leader_diag()}"

        # the leader held at the final pose (its counts there), not on its way
        def counts_at_final():
            got = leader_diag().get("leader_counts", "").split()
            return len(got) == 4 and all(abs(float(g) - e) <= COUNTS_TOLERANCE for g, e in zip(got, final_counts))

        assert observer.spin_until(counts_at_final, 600), (final_counts, leader_diag())
        assert observer.spin_until(at_final, 5), (
            want, [(m.name, [round(math.degrees(p), 2) for p in m.position]) for _, m in leader_js[-3:]],
            leader_diag())
        m = leader_js[-1][1]
        got = {n: math.degrees(p) for n, p in zip(m.name, m.position)}
        print("leader at the final pose:", {j: round(v, 2) for j, v in got.items()}, "modelled", want)
        assert leader_diag().get("leader_deadman") == "released", leader_diag()

        wizard.finish()
        wizard.wait(lambda c: not c.get("active"), 10, "the wizard finished (active false)")
    finally:
        wizard.close()
        # the leader's simavr goes with the test (a harness left running takes a core's sixth)
        if leader is not None and leader.proc.poll() is None:
            leader.stop()
