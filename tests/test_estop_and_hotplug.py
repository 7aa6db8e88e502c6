"""Issue 9, items 3 and 4: the e-stop and hot-plug, judged at the pins of the real firmware
in simavr while rclpy streams servo_angles at 50 Hz.

No timing is asserted: each test writes what it measured (e-stop latency, reconnect times)
to test-output/; tests/bench/estop_hotplug.py repeats them for BENCHMARKS.md."""
import json

import pytest
from std_msgs.msg import Bool

from conftest import OUTPUT
from safety_rig import (CYCLES_PER_S, HOLD_US, SERVO_PERIOD_S, A, B, Rig, engaged_estop_frames, pulse_us,
                        reconnect_ms, sent_ticks, step_allowed_us, velocity_limits_us_per_s,
                        velocity_violations)
from interop.servo_link import ESTOP

LIMITS = velocity_limits_us_per_s()


def record(name, **figures):
    OUTPUT.mkdir(parents=True, exist_ok=True)
    with open(OUTPUT / f"{name}.jsonl", "a") as f:
        f.write(json.dumps(figures) + "\n")


def rises(events):
    return [e for e in events.edges if e[2] == 1]


@pytest.mark.parametrize("action", ["hold", "detach"])
def test_estop_stops_the_arm_mid_move_and_a_release_moves_nothing(launch, observer, tmp_path, action):
    rig = Rig(launch, observer, tmp_path, "-p", f"estop_action:={action}")
    try:
        assert rig.spin(until=rig.connected, timeout=15)
        t_pub = rig.estop_mid_move()
        rig.spin(0.5)  # the stream goes on; serial_node drops it
        assert int(rig.diag()["inputs_dropped_in_estop"]) > 0
        rig.release_estop()
        rig.spin(0.5)  # released: nothing moves until a new command
        new = [100.0, 90.0, 95.0, 100.0]
        rig.target = new
        assert rig.spin(until=lambda: rig.at(new), timeout=5)
        rig.spin(0.1)
        assert rig.node.proc.poll() is None
    finally:
        rig.stop()

    ev = rig.events()
    engaged = engaged_estop_frames(ev)
    # (sent again if a reply to a command sent before it still said "running")
    assert engaged and {p for p, _ in engaged} == {1 if action == "hold" else 2}
    c_stop = engaged[0][1]
    c_release = next(c for t, _, p, c in ev.frames() if t == ESTOP and p[0] == 0 and c > c_stop)
    sends = sent_ticks(ev)
    applied = [t for c, t in sends if c < c_stop][-1]  # what the board reports it holds
    first_new = next(t for c, t in sends if c > c_release)
    c_new = next(c for c, _ in sends if c > c_release)
    one_period = SERVO_PERIOD_S * CYCLES_PER_S
    for pin in range(4):
        after = [(c, w) for c, w in ev.pulses(pin) if c_stop < c <= c_new]
        if action == "hold":
            # from the e-stop to the new command every pulse is the command the board had
            assert after and all(abs(w - applied[pin] / 2) <= 1.0 for _, w in after), (pin, applied, after[:3])
        else:
            # at most the pulse of the frame already latched, then none until the new command
            assert all(c <= c_stop + one_period for c, _ in after), (pin, after)
        # the new command starts from there, within the velocity limit, and gets there
        assert abs(first_new[pin] - applied[pin]) / 2 <= step_allowed_us(LIMITS[pin], 0.0), (pin, applied, first_new)
        assert ev.pulses(pin)[-1][1] == pytest.approx(pulse_us(new[pin]), abs=1.0)
    assert velocity_violations(ev, LIMITS) == []
    record("estop", action=action, publish_to_firmware_ms=(ev.wall_ns(c_stop) - t_pub) / 1e6,
           stopped_at_us=[t / 2 for t in applied], was_going_to_us=[pulse_us(d) for d in B])


def test_a_serial_node_started_during_an_estop_moves_nothing(launch, observer, tmp_path):
    estop = observer.pub("/estop", Bool)  # the contract's QoS: latched
    estop.publish(Bool(data=True))
    rig = Rig(launch, observer, tmp_path)
    try:
        assert rig.spin(until=lambda: rig.connected() and rig.diag().get("device_state") == "e-stop", timeout=15)
        assert rig.diag()["estop"] == "true"
        rig.target = B
        rig.spin(1.0)
        assert int(rig.diag()["inputs_dropped_in_estop"]) > 0
        assert rises(rig.events()) == [], "a pulse during the e-stop"
        rig.target = None
        estop.publish(Bool(data=False))
        assert rig.spin(until=lambda: rig.diag().get("device_state") == "idle", timeout=5)
        rig.spin(0.5)
        assert rises(rig.events()) == [], "a pulse after the release, before any new command"
        rig.target = A
        assert rig.spin(until=lambda: rig.at(A), timeout=5)
        rig.spin(0.1)
    finally:
        rig.stop()
    # the first command ramps from the pose the board reported: its hold pose
    assert velocity_violations(rig.events(), LIMITS, start_us=HOLD_US) == []


@pytest.mark.parametrize("kind", ["cable", "reset"])
def test_hot_plug_while_streaming(launch, observer, tmp_path, kind):
    """20 cycles: the USB cable pulled mid-move and plugged back (the board runs on), or the
    board reset (a new simavr: no pulses until the first command, which starts from the
    hold pose). Every reconnect carries on to the newest target, ramped from where the
    board says the arm is."""
    cycles = 20
    rig = Rig(launch, observer, tmp_path)
    try:
        up_at = rig.hotplug_cycles(kind, cycles)
        rig.spin(0.1)
        d = rig.diag()
        assert d["reconnects"] == str(cycles)
        assert rig.node.proc.poll() is None
    finally:
        rig.stop()

    if kind == "cable":
        ev = rig.events()
        assert len([c for c, plugged in ev.cable if plugged]) == cycles
        # the pulses never step faster than the velocity limit: not across a reconnect either
        assert velocity_violations(ev, LIMITS) == []
    else:
        for boot in range(1, cycles + 1):
            assert velocity_violations(rig.events(boot), LIMITS, start_us=HOLD_US) == [], f"boot {boot}"
    record("hotplug", kind=kind, cycles=cycles, reconnect_ms=reconnect_ms(rig, kind, up_at),
           counters={k: d[k] for k in ("reconnects", "frames_sent", "frames_ramped_by_velocity_limit")})
