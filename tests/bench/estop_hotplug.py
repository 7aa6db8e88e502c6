#!/usr/bin/env python3
"""E-stop latency and hot-plug reconnect time at the pins of the real firmware in simavr
(issue 9, items 3 and 4), for BENCHMARKS.md. tests/test_estop_and_hotplug.py checks the
behaviour; this program times it over many trials:

    $EEZYBOT_PYTHON tests/bench/estop_hotplug.py [--trials 20] [--cycles 20] [--json FILE]

Needs release binaries (cargo build --release --bins; EEZYBOT_BIN_DIR overrides
target/release) and the firmware and its harness (make -C firmware/servo_control all sim).

E-stop, per action (hold, detach), --trials times, each mid-move (50 Hz stream, 0.1 s into
a move of 0.3 s):
  to_board   time.time_ns() just before rclpy publishes `estop` -> the board has the whole
             ESTOP frame (its last byte's cycle, tied to wall time by the harness's `w`
             events): from here no command moves a servo.
  to_held    hold: -> the servos are held, the last change of a pulse width on any pin
             (safety_rig.last_width_change), or the ESTOP frame if none came after it:
             the firmware holds what its pins show, so no servo gets a new position
             after its frame unless a pulse that had read one starts meanwhile.
  to_pins    -> the pin shows it: hold, the rise of the first pulse after that (every
             pulse from then on has the held width, checked; the wait for it is the
             servo frame's phase); detach, the first 20 ms servo frame with no pulse
             (the last pulse's rise + 20 ms).
Hot-plug, --cycles of each kind (the cable pulled for 0.3 s mid-move, the board reset):
  reconnect  plugged back (time.time_ns() after the pty is there again) -> the board has
             the first SET_PULSES of the new session.
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
from safety_rig import CYCLES_PER_S, SERVO_PERIOD_S, A, Rig, engaged_estop_frames, estop_held, last_width_change, reconnect_ms, sent_ticks, velocity_limits_us_per_s, velocity_violations  # noqa: E402


def estop_trials(domain, action, trials, tmp):
    o = Observer(domain)
    launch = Launcher(domain)
    rig = Rig(launch, o, tmp, "-p", f"estop_action:={action}")
    published = []
    try:
        assert rig.spin(until=rig.connected, timeout=15), "serial_node did not connect"
        for i in range(trials):
            published.append(rig.estop_mid_move())
            rig.spin(0.2)
            rig.release_estop()
        rig.target = A
        assert rig.spin(until=lambda: rig.at(A), timeout=5)
    finally:
        rig.stop()
        launch.stop()
        o.close()
    ev = rig.events()
    # serial_node may resend an ESTOP frame (the device's STATE did not show it yet):
    # each trial's stop is the first one after its publish
    stops = [(seq, c) for _, seq, c in engaged_estop_frames(ev)]
    engaged = [next(s for s in stops if ev.wall_ns(s[1]) >= t_pub) for t_pub in published]
    assert len(set(engaged)) == trials, (len(stops), trials)
    sends = sent_ticks(ev)
    to_board, to_held, to_pins = [], [], []
    for t_pub, (seq, c_stop) in zip(published, engaged):
        to_board.append((ev.wall_ns(c_stop) - t_pub) / 1e6)
        # what the board answered it holds, and from when the pins show it
        c_held, held = estop_held(ev, c_stop, seq)
        if action == "hold":
            first = min(next(c for c, _ in ev.pulses(pin) if c > c_stop) for pin in range(4))
            for pin in range(4):
                nxt = next(c for c, _ in sends if c > c_held)
                assert all(abs(w - held[pin] / 2) <= 1.0 for c, w in ev.pulses(pin) if c_held < c < nxt)
            to_pins.append((ev.wall_ns(first) - t_pub) / 1e6)
            to_held.append((ev.wall_ns(last_width_change(ev, c_stop, nxt)) - t_pub) / 1e6)
        else:
            last = max([c for pin in range(4) for c, _ in ev.pulses(pin) if c < c_stop + SERVO_PERIOD_S * CYCLES_PER_S])
            gone = last + int(SERVO_PERIOD_S * CYCLES_PER_S)
            to_pins.append((ev.wall_ns(gone) - t_pub) / 1e6)
    return {"to_board_ms": stats(to_board), "to_pins_ms": stats(to_pins),
            **({"to_held_ms": stats(to_held)} if to_held else {}),
            "velocity_violations": len(velocity_violations(ev, velocity_limits_us_per_s()))}


def hotplug_cycles(domain, kind, cycles, tmp):
    o = Observer(domain)
    launch = Launcher(domain)
    rig = Rig(launch, o, tmp)
    try:
        up = rig.hotplug_cycles(kind, cycles)
        counters = {k: rig.diag()[k] for k in ("reconnects", "frames_sent", "frames_ramped_by_velocity_limit")}
    finally:
        rig.stop()
        launch.stop()
        o.close()
    return {"reconnect_ms": stats(reconnect_ms(rig, kind, up)), "counters": counters}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--cycles", type=int, default=20)
    ap.add_argument("--json")
    args = ap.parse_args()
    lease = DomainLease()
    out = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "bin_dir": os.environ["EEZYBOT_BIN_DIR"]}
    try:
        for action in ("hold", "detach"):
            with tempfile.TemporaryDirectory() as tmp:
                out[f"estop_{action}"] = r = estop_trials(lease.id, action, args.trials, tmp)
            print(f"e-stop ({action}), {args.trials} trials: publish -> board {r['to_board_ms']} ms, "
                  f"-> servos held {r.get('to_held_ms', '-')} ms, -> pins {r['to_pins_ms']} ms; "
                  f"velocity-limit violations {r['velocity_violations']}")
        for kind in ("cable", "reset"):
            with tempfile.TemporaryDirectory() as tmp:
                out[f"hotplug_{kind}"] = r = hotplug_cycles(lease.id, kind, args.cycles, tmp)
            print(f"hot-plug ({kind}), {args.cycles} cycles: reconnect {r['reconnect_ms']} ms; {r['counters']}")
    finally:
        lease.release()
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
