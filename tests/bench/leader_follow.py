#!/usr/bin/env python3
"""Leader potentiometer change -> follower pulse width (issue 22), with both firmwares in
simavr, for BENCHMARKS.md. tests/test_leader_arm.py checks the behaviour; this program
times it over many steps:

    $EEZYBOT_PYTHON tests/bench/leader_follow.py [--steps 20] [--json FILE]

Needs release binaries (cargo build --release --bins; EEZYBOT_BIN_DIR overrides
target/release) and the firmware and its harness (make -C firmware/servo_control all sim).

The leader's base potentiometer steps between two positions every 1.5 s of the recorded
motion (servo_sim --adc-file), the deadman held. Per step:
  latency   the leader's ADC first converts the new voltage on A0 (its `a` event's cycle,
            tied to wall time by the harness's `w` events) -> the follower's first base
            pulse (pin 8) that moved toward the new pose (more than 2 us from the width it
            held), its rise tied to wall time the same way.
  settled   the follower's base pulse 1.2 s after the step against the leader's pose, in
            joint degrees.
"""
import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
os.environ.setdefault("EEZYBOT_BIN_DIR", str(HERE.parents[1] / "target" / "release"))

from benchkit import Launcher, stats  # noqa: E402
from conftest import DomainLease, Observer  # noqa: E402
from interop.servo_link import SimulatedUno, write_adc_file  # noqa: E402
from safety_rig import CYCLES_PER_S, FIRMWARE, BoardEvents, Rig  # noqa: E402
from test_leader_arm import LEADER_SECTION, SHIPPED, base_us, pots  # noqa: E402

STEP_S = 1.5
POSES = (0.5, 0.625)  # base fractions: home and 22.5° left
START_S = 6.0  # the first step, after the graph is up


def joint_deg(fraction):
    return (fraction * 1024 - 512) * 45.0 / 256


def adc_events(path):
    """[(cycle, channel, mv)] of the leader's conversions."""
    out = []
    for line in Path(path).read_text().splitlines():
        p = line.split()
        if p[0] == "a" and len(p) == 4:
            out.append((int(p[1]), int(p[2]), int(p[3])))
    return out


def run(steps, tmp):
    lease = DomainLease()
    launch = Launcher(lease.id)
    o = Observer(lease.id)
    tmp = Path(tmp)
    config = tmp / "arm.yaml"
    config.write_text(SHIPPED + LEADER_SECTION)
    motion, t = [(0, pots(POSES[0]), True)], START_S
    for k in range(steps):
        a, b = POSES[k % 2], POSES[(k + 1) % 2]
        motion += [(t * 1000, pots(a), True), (t * 1000, pots(b), True)]
        t += STEP_S
    end_s = t + 1.0
    follower = leader = None
    try:
        (tmp / "follower").mkdir()
        follower = Rig(launch, o, tmp / "follower", "-p", f"arm_config:={config}")
        launch("compute_ik", "--ros-args", "-p", f"arm_config:={config}")
        (tmp / "leader").mkdir()
        write_adc_file(tmp / "leader" / "motion.txt", motion)
        leader = SimulatedUno(tmp / "leader", FIRMWARE, adc_file=tmp / "leader" / "motion.txt")
        launch("serial_node", "--ros-args", "-r", "__node:=leader_arm", "-p", "role:=leader",
               "-p", f"port:={leader.tty_path}", "-p", f"arm_config:={config}")
        started = time.monotonic()
        o.spin_for(max(0.0, end_s - (time.monotonic() - started)))
        leader.proc.terminate()
        leader.proc.wait(10)
        lev, fev = BoardEvents(leader.events_path), BoardEvents(follower.board.events_path)
        conv = adc_events(leader.events_path)
        pulses = [(fev.wall_ns(c), w) for c, w in fev.pulses(0)]
        latencies, settled = [], []
        for k in range(steps):
            step_ms = (START_S + k * STEP_S) * 1000
            new = POSES[(k + 1) % 2]
            # the first conversion of A0 at the new voltage after the step (simulated time)
            want_mv = int(pots(new)[0])
            c_step = next((c for c, ch, mv in conv if ch == 0 and c >= step_ms * CYCLES_PER_S / 1000
                           and abs(mv - want_mv) <= 2), None)
            if c_step is None:
                continue
            t_step = lev.wall_ns(c_step)
            before = [w for t, w in pulses if t < t_step]
            if not before:
                continue
            held = before[-1]
            moved = next((t for t, w in pulses if t >= t_step and abs(w - held) > 2.0), None)
            if moved is not None:
                latencies.append((moved - t_step) / 1e6)
            at = [w for t, w in pulses if t >= t_step + 1.2e9]
            if at:
                settled.append(abs(at[0] - base_us(joint_deg(new))) / (2 * (2400 - 544) / 180))
        return {"latency_ms": stats(latencies), "settled_error_deg": stats(settled),
                "steps": steps, "measured": len(latencies)}
    finally:
        # both boards' simavr go with the run
        if leader is not None and leader.proc.poll() is None:
            leader.proc.kill()
            leader.proc.wait(10)
        if follower is not None:
            follower.stop()
        launch.stop()
        o.close()
        lease.release()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--json")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        r = run(a.steps, tmp)
    print(f"leader potentiometer -> follower pulse, {r['measured']} of {r['steps']} steps:")
    print(f"  latency ms p50 / p99 / max: {r['latency_ms']['p50']} / {r['latency_ms']['p99']} / {r['latency_ms']['max']}"
          "   targets p50 <= 30, p99 <= 50")
    s = r["settled_error_deg"]
    print(f"  settled error (joint deg) p50 / p99 / max: {s['p50']} / {s['p99']} / {s['max']}   target <= 1")
    if a.json:
        Path(a.json).write_text(json.dumps(r, indent=1))


if __name__ == "__main__":
    main()
