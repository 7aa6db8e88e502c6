#!/usr/bin/env python3
"""End-to-end benchmark of the teleop graph (issue 8, item 6): the real binaries started
by launch_scripts/pc.sh and pi.sh in network namespaces, the real firmware in simavr
behind a timing pty, and rclpy probes. Prints p50 / p99 / max / loss per case, and every
figure as JSON (--json) for BENCHMARKS.md.

    $EEZYBOT_PYTHON tests/bench/e2e.py [--case a,b,...|all] [--seconds 60] [--json FILE]

Needs root (ip netns), release binaries (cargo build --release --bins; EEZYBOT_BIN_DIR
overrides target/release) and the firmware + harness (make -C firmware/servo_control all
sim). Timing is never asserted: the program prints what it measured and, where the issue
sets a target, whether it was met.

Cases; each selects runs, a run is shared by every case that needs it. A run takes about
--seconds + 15 s (start, discovery, 2 s warm-up, drain, stop); at the defaults:
  a  xyz_target -> servo_angles, same host                       run same       ~75 s
  b  xyz_target -> first byte of its SET_PULSES frame on the port run same
  c  xyz_target -> the pulse width changing on a pin, in simavr   run same
  d  (a)-(c) across the namespaces pc/pi (veth), and impaired     split, impaired ~2.5 min
     (linkem: 20 ms +- 5 ms, 1 % loss)
  e  50 Hz for --seconds, loss at every stage (run same); 1 kHz    burst          ~35 s
     bursts (--bursts x --burst-seconds, --burst-gap at 50 Hz between)
  f  the seed's node (seed_ik_node.py) vs compute_ik alone        ik_alone, seed ~2.5 min
  g  precision: f64 bit-exact vs the seed's 4 decimals            same, split, seed
  h  CPU and RSS of every node, 50 Hz teleoperation through the   teleop         ~75 s
     web panel's WebSocket (and from the rclpy operator, run same)
  all: 7 runs, about 8-9 minutes.

The layout: tests/twohost.py's namespaces `pc` and `pi` (the "same host" runs put pi.sh
in `pc` too, so no traffic leaves the namespaces this program creates), a private
ROS_DOMAIN_ID (conftest.DomainLease). The targets (e2e_analysis.TargetPath, --path): by
default an operator sweeping the arm, smoothly and within config/arm.yaml's motion limits,
so that every command's pulse widths reach the wire as commanded and identify it; the
operator probe (rclpy, in `pc`) publishes them at --rate; a slot it reaches more than half
a period late is skipped (counted), never caught up in a burst.

Clocks: CLOCK_REALTIME of this one machine, except simavr's cycle counter, which is only
compared with itself.
  t0  header.stamp of the target = time.time_ns() just before rclpy publishes it;
  (a) Fast DDS's reception timestamp of the servo_angles sample carrying that stamp in the
      probe (set by Fast DDS's receive thread: the probe's Python callback delay is not
      counted; it is in the JSON, with compute_ik's own write time, the source timestamp);
  (b) pty_tap.py's time for the chunk holding the frame's start byte (serial_node's
      write() readable at the device end of the pty; the kernel hands pty data over in a
      kworker, whose scheduling delay on a busy machine is in this figure too). The frame
      is tied to its target through the pulse widths: compute_ik's servo_angles for that
      stamp, turned into ticks as serial_node does (e2e_analysis.angle_to_ticks), checked
      against serial_node's own servo_state for that stamp (serial_node maps the
      device's ack_seq back to the command's stamp): `servo_state_widths_agree`.
  (c) = (b) + the simulated time from the cycle at which simavr handed the same frame's
      start byte to the AVR's UART (`r` event; same seq and widths) to the rise of the
      first pulse on the pin whose width is no longer an older command's (`e` events),
      16 MHz cycles. One sample per (command, pin whose width it changes). The two clocks
      are never subtracted from each other: they meet at one event, the frame's first
      byte leaving the host / entering the UART; what lies between (the second pty, the
      harness reading it every 250 us of simulated time, its pacing to wall time) is left
      out, as a real board's USB transfer would be. `clock_map` reports the spread and
      drift of (tap time - cycle time) so the harness can be judged; the drift is the
      simulated board's clock error, set (--avr-clock-ppm) so that the servo frame's
      phase against the 50 Hz commands sweeps the whole 20 ms once per run, as a real
      Uno's resonator (+-0.5 %) sweeps it every few seconds; paced exactly, the phase
      stayed where the run started it, and (c)'s p50 was that phase: 12.3, 18.2 and
      20.2 ms in three runs of the same build. simavr models the
      UART's byte time (86.8 us at 115200): the frame's 1.04 ms on the wire is inside.
  Loss: a target is lost at a stage when no sample with its stamp (or its widths) got
  there. The nodes are newest-wins (a newer command waiting replaces an older one), so
  "to this or a newer target" rows give the time until the output carried this target
  or a newer one: what the operator waits for, whatever was dropped on the way.
"""
import argparse
import datetime
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import e2e_analysis as A  # noqa: E402
from e2e_harness import REPO, CpuWindow, GraphRun, WebSocketOperator  # noqa: E402
from seed_ik_node import seed_outputs  # noqa: E402

IMPAIRMENT = dict(delay_ms=20, jitter_ms=5, loss=0.01)
CASE_RUNS = {"a": ["same"], "b": ["same"], "c": ["same"], "d": ["split", "impaired"], "e": ["same", "burst"],
             "f": ["ik_alone", "seed"], "g": ["same", "split", "seed"], "h": ["teleop"]}
TARGETS = {"a": {"p50": 1.0}, "b": {"p50": 1.5, "p99": 3.0}, "c": {"p50": 12.0, "p99": 22.0},
           "a_across": {"p50": 2.0}, "b_across": {"p50": 2.0}}


def ms(ns_values):
    return A.summary(ns_values, 1e-6)


# ---------------------------------------------------------------- one graph run
SERVO_FRAME_S = 0.020


def clock_ppm(args):
    """simavr's clock error for a run: by default the one that slides the firmware's 20 ms
    servo frame once past the operator's clock in --seconds, so that every phase between
    a command and the frame is met equally often, as with a real Uno's resonator
    (+-0.5 %, a whole frame every 4 s or faster)."""
    if args.avr_clock_ppm is not None:
        return args.avr_clock_ppm
    return SERVO_FRAME_S / args.seconds * 1e6


def graph_run(name, args, layout="same", nodes="graph", seed_cap="loop", drive="rclpy"):
    log = lambda s: print(s, flush=True)  # noqa: E731
    log(f"--- run `{name}`: layout {layout}, nodes {nodes}, device {args.device if nodes == 'graph' else '-'}, "
        f"{'bursts' if drive == 'burst' else f'{args.rate:g} Hz x {args.seconds:g} s'}, driven by {drive}, "
        f"path {args.path}")
    serial_args = ["-p", f"send_rate:={args.send_rate:g}"] if args.send_rate else []
    path = A.TargetPath(args.path)
    run = GraphRun(name, path, layout=layout, device=args.device, nodes=nodes, impairment=IMPAIRMENT,
                   seed_cap=seed_cap, serial_args=serial_args, firmware=args.firmware,
                   clock_ppm=clock_ppm(args), log=log)
    t_start = time.time()
    ws = None
    try:
        run.start()
        run.wait_flowing()
        send = None
        if drive == "ws":
            ws = WebSocketOperator("127.0.0.1", 8080, netns=run.hosts.pc)
            run.ws_sent = 0

            def send(xyz, index, phase):
                ws.send_text(json.dumps({"t": "target", "xyz": list(xyz)}))
                if phase == "measure":
                    run.ws_sent += 1
        # warm-up at the measuring rate (discovery settles, caches warm), then measure
        run.drive(args.rate, 2.0, "warmup", send)
        pids = {**run.node_pids(), **run.helper_pids()}
        window = CpuWindow(pids)
        t_measure = time.time_ns()
        if drive == "burst":
            for k in range(args.bursts):
                run.drive(args.burst_rate, args.burst_seconds, f"burst{k}")
                run.drive(args.rate, args.burst_gap, f"gap{k}")
        else:
            run.drive(args.rate, args.seconds, "measure", send)
        cpu = window.close()
        t_end = time.time_ns()
        run.spin(time.monotonic() + (6.0 if layout == "impaired" else 2.0))  # late replies still count
    finally:
        if ws is not None:
            ws.close()
        run.stop()
    log(f"    done in {time.time() - t_start:.0f} s; exit codes {run.exit_codes}")
    return {"run": run, "cpu": cpu, "t_measure": t_measure, "t_end": t_end, "path": path, "layout": layout,
            "nodes": nodes, "drive": drive, "ws_sent": getattr(run, "ws_sent", None)}


# ---------------------------------------------------------------- analysis of a run
def analyze(r, args):
    run, path = r["run"], r["path"]
    sent = [(s, i) for s, i, phase in run.sent if phase == "measure"]
    pc, pi = run.pc_probe, run.pi_probe
    out = {"config": {"layout": r["layout"], "nodes": r["nodes"], "drive": r["drive"], "path": path.kind,
                      "device": args.device if r["nodes"] == "graph" else None,
                      "impairment": IMPAIRMENT if r["layout"] == "impaired" else None,
                      "rate_hz": args.rate, "seconds": args.seconds, "serial_node_send_rate": args.send_rate or "default"},
           "sent": len(sent), "exit_codes": run.exit_codes, "cpu": r["cpu"],
           "probe_duplicates": pc.duplicates}
    if getattr(run, "link_stats", None):
        out["linkem"] = run.link_stats
    # (a) xyz_target -> servo_angles at the probe in pc (same namespace as compute_ik)
    got = [(s, pc.servo_angles[s]) for s, _ in sent if s in pc.servo_angles]
    out["a"] = {"lost": len(sent) - len(got), "latency_ms": ms(v[0] - s for s, v in got),
                "callback_ms": ms(v[2] - s for s, v in got),
                "compute_ik_write_ms": ms(v[1] - s for s, v in got)}
    if pc.joint_states:
        out["a"]["joint_states_lost"] = sum(1 for s, _ in sent if s not in pc.joint_states)
    outputs = [(v[0], k) for k, v in pc.servo_angles.items()]
    out["a"]["this_or_newer_ms"] = ms(A.this_or_newer([s for s, _ in sent], outputs))
    out["a"]["lost_evidence"] = lost_evidence(sent, pc.servo_angles)
    out["sender_skipped_slots"] = run.skipped
    if pi is not None:
        got_pi = [(s, pi.servo_angles[s]) for s, _ in sent if s in pi.servo_angles]
        out["a_across"] = {"lost": len(sent) - len(got_pi), "latency_ms": ms(v[0] - s for s, v in got_pi),
                           "compute_ik_write_ms": ms(v[1] - s for s, v in got_pi)}
        same_bits = sum(1 for s, v in got_pi if s in pc.servo_angles and pc.servo_angles[s][3] == v[3])
        out["a_across"]["bit_identical_to_pc_probe"] = [same_bits, sum(1 for s, _ in got_pi if s in pc.servo_angles)]
    if r["nodes"] != "graph":
        return out
    diag = next((v for k, v in pc.diagnostics.items() if k.startswith("serial_node")), {})
    out["serial_node_diagnostics"] = diag
    if r["drive"] == "ws":
        out["ws_sent"] = r["ws_sent"]
        targets_seen = [s for s in pc.xyz_target if r["t_measure"] <= s <= r["t_end"]]
        out["h_teleop"] = {"ws_sent": r["ws_sent"], "xyz_target_published": len(targets_seen),
                           "servo_angles_for_them": sum(1 for s in targets_seen if s in pc.servo_angles),
                           "servo_state_for_them": sum(1 for s in targets_seen if s in pc.servo_state),
                           "latency_gui_stamp_to_servo_angles_ms": ms(pc.servo_angles[s][0] - s for s in targets_seen
                                                                        if s in pc.servo_angles)}
        return out
    # (b) frames on the wire, tied to stamps through their widths
    host, dev = A.read_tap_log(run.tap_log)
    frames = A.set_pulses_frames(A.parse_frames(host))
    by_ticks = {}
    for s, v in pc.servo_angles.items():
        by_ticks.setdefault(A.ticks_of(v[3]), []).append(s)
    ambiguous = sum(1 for v in by_ticks.values() if len(v) > 1)
    on_wire = {}  # stamp -> (frame index, t_first)
    unmatched_frames = 0
    for k, (seq, ticks, t0, t1) in enumerate(frames):
        stamps = by_ticks.get(ticks)
        if not stamps or len(stamps) > 1:
            unmatched_frames += 1
            continue
        on_wire.setdefault(stamps[0], (k, t0))
    # serial_node's own stamp -> acknowledged widths, to check the tie
    checked = agree = 0
    for s, v in pc.servo_state.items():
        if s in pc.servo_angles:
            checked += 1
            reported = tuple(A.ticks_from_reported(a, c) for a, c in zip(v[3], A.CAL))
            agree += reported == A.ticks_of(pc.servo_angles[s][3])
    with_angles = [s for s, _ in got]
    lat_b = [on_wire[s][1] - s for s in with_angles if s in on_wire]
    out["b"] = {"lost": len(with_angles) - len(lat_b), "latency_ms": ms(lat_b), "frames_on_wire": len(frames),
                "frames_not_tied_to_a_target": unmatched_frames, "ambiguous_widths": ambiguous,
                "servo_state_widths_agree": [agree, checked],
                "acknowledged": sum(1 for s in with_angles if s in pc.servo_state),
                "note": "lost = targets whose servo_angles arrived but whose command never went on the wire "
                        "(serial_node: newest command wins, at most send_rate frames/s)"}
    wire_times = [t0 for _, _, t0, _ in frames]
    if len(wire_times) > 1:
        span = (wire_times[-1] - wire_times[0]) / 1e9
        out["b"]["frames_per_s"] = (len(wire_times) - 1) / span if span > 0 else None
        out["b"]["frame_gap_ms"] = ms(b - a for a, b in zip(wire_times, wire_times[1:]))
    wire_outputs = []
    for seq, ticks, t0, t1 in frames:
        st = by_ticks.get(ticks)
        if st and len(st) == 1:
            wire_outputs.append((t0, st[0]))
    out["b"]["this_or_newer_ms"] = ms(A.this_or_newer([s for s, _ in sent], wire_outputs))
    # the rate limiter's own delay: first byte time minus the probe's reception of servo_angles
    out["b"]["held_by_rate_limit_ms"] = ms(on_wire[s][1] - pc.servo_angles[s][0] for s in with_angles if s in on_wire)
    if args.device != "simavr":
        return out
    # (c) the same frames inside the AVR, and the pulses
    rx, tx, edges = A.read_sim_events(run.uno.events_path)
    sim_frames = A.set_pulses_frames(A.parse_frames(rx))
    pulses = A.pin_pulses(edges)
    # pair tap frames and simavr frames: the same sequence of (seq, widths), in order
    pair = {}
    j = 0
    for k, (seq, ticks, _, _) in enumerate(frames):
        jj = j
        while jj < len(sim_frames) and (sim_frames[jj][0], sim_frames[jj][1]) != (seq, ticks):
            jj += 1
        if jj < len(sim_frames):
            pair[k] = jj
            j = jj + 1
    offsets = []
    for k, jj in pair.items():
        offsets.append((frames[k][2], frames[k][2] - sim_frames[jj][2] * 1e9 / A.CYCLES_PER_S))
    # per (command, pin whose width it changes): the rise of the first pulse whose width is
    # no longer the previous command's = the pin showing this command, or a newer one that
    # superseded it before its slot came (newest wins); `exact_ms` keeps only the former
    c_rise, c_fall, c_exact, c_all, sim_part, per_pin = [], [], [], [], [], {p: [] for p in range(4)}
    superseded = missing = pin_changes = ambiguous_pins = unexplained = 0
    not_seen_stamps, untimed_stamps = set(), set()
    width_err = []  # us, measured minus commanded, of the pulses that showed this command
    changed_stamps = set()
    for s in with_angles:
        if s not in on_wire or on_wire[s][0] not in pair:
            continue
        jj = pair[on_wire[s][0]]
        if jj == 0:
            continue
        seq, new, r_first, _ = sim_frames[jj]
        older = [f[1] for f in sim_frames[max(0, jj - 12):jj]][::-1]  # the pin may show one ~2 frames old
        newer = [f[1] for f in sim_frames[jj + 1:jj + 25]]
        host_ns = on_wire[s][1] - s
        rises = []
        for pin in range(4):
            if new[pin] == older[0][pin]:
                continue
            pin_changes += 1
            if any(abs(o[pin] - new[pin]) <= A.WIDTH_SEPARATION_TICKS for o in older):
                ambiguous_pins += 1  # too close to an older command's width to be told apart
                continue
            res = A.first_new_width(pulses[pin], r_first, [o[pin] for o in older], new[pin], [n[pin] for n in newer])
            if res is None:
                missing += 1
                not_seen_stamps.add(s)
                continue
            kind, rise, fall = res
            if kind == "unexplained":
                unexplained += 1
                continue
            sim_ns = (rise - r_first) * 1e9 / A.CYCLES_PER_S
            c_rise.append(host_ns + sim_ns)
            c_fall.append(host_ns + (fall - r_first) * 1e9 / A.CYCLES_PER_S)
            sim_part.append(sim_ns)
            per_pin[pin].append(host_ns + sim_ns)
            rises.append(host_ns + sim_ns)
            if kind == "superseded":
                superseded += 1
            else:
                c_exact.append(host_ns + sim_ns)
                width_err.append((fall - rise) / A.CYCLES_PER_TICK / 2 - new[pin] / 2)
        if rises:
            changed_stamps.add(s)
            c_all.append(max(rises))
        elif s not in not_seen_stamps:
            untimed_stamps.add(s)  # every pin it changes is too close to an older width to be timed
    on_wire_with_angles = [s for s in with_angles if s in on_wire]
    out["c"] = {"commands": len(on_wire_with_angles), "lost": len(not_seen_stamps - changed_stamps),
                "commands_not_timed": len(untimed_stamps),
                "latency_ms": ms(c_rise), "latency_to_fall_ms": ms(c_fall), "exact_width_ms": ms(c_exact),
                "latency_all_pins_ms": ms(c_all), "sim_part_ms": ms(sim_part),
                "per_pin_ms": {8 + p: ms(v) for p, v in per_pin.items() if v},
                "pin_changes": pin_changes, "pin_changes_superseded": superseded, "pin_changes_not_seen": missing,
                "pin_changes_not_timed_width_seen_before": ambiguous_pins, "width_tolerance_ticks": A.WIDTH_TOLERANCE_TICKS,
                "pulses_with_an_unexplained_width": unexplained,
                "width_error_us": A.summary(width_err), "width_abs_error_us": A.summary(abs(e) for e in width_err),
                "samples": "one per (command, pin whose width it changes): rise of the first pulse whose width is no "
                           "longer the previous command's (this command's width, or a newer one's that superseded it)",
                "frames_paired_tap_to_simavr": [len(pair), len(frames)]}
    if offsets:
        tt = [t for t, _ in offsets]
        oo = [o for _, o in offsets]
        n = len(tt)
        mt, mo = sum(tt) / n, sum(oo) / n
        var = sum((t - mt) ** 2 for t in tt)
        slope = sum((t - mt) * (o - mo) for t, o in zip(tt, oo)) / var if var > 0 else 0.0
        resid = [o - (mo + slope * (t - mt)) for t, o in zip(tt, oo)]
        base = min(resid)
        out["c"]["clock_map"] = {
            "what": "tap time of a frame's first byte minus its simavr cycle time, less its linear drift (the "
                    "simulated board's clock error, --avr-clock-ppm); spread = harness pickup + pacing",
            "spread_ms": ms(r - base for r in resid),
            "drift_ppm": slope * 1e6,
            "avr_clock_ppm_set": run.clock_ppm,
        }
    out["end_to_end_50hz"] = {"sent": len(sent), "servo_angles": len(got), "on_wire": len(on_wire_with_angles),
                              "acknowledged": out["b"]["acknowledged"],
                              "on_pins": len(on_wire_with_angles) - out["c"]["lost"],
                              "on_pins_timed": len(changed_stamps)}
    return out


def lost_evidence(sent, table):
    """What the targets that never came back looked like. compute_ik drops a target when a
    newer one is already waiting when it gets to it (newest wins, burst::latest_wins) and
    counts that nowhere (only its debug log says so), so the cause cannot be read off;
    this gives the evidence: how long before the next target it was sent, and how late
    the next target's servo_angles came out (compute_ik's source timestamp): a late
    successor means compute_ik had not run for about a period."""
    stamps = [s for s, _ in sent]
    gaps, successor = [], []
    for k, s in enumerate(stamps):
        if s in table:
            continue
        if k + 1 < len(stamps):
            gaps.append(stamps[k + 1] - s)
        nxt = next((t for t in stamps[k + 1:] if t in table), None)
        if nxt is not None:
            successor.append(table[nxt][1] - nxt)
    return {"gap_to_next_sent_ms": ms(gaps), "next_delivered_target_write_delay_ms": ms(successor),
            "all_targets_write_delay_ms": ms(v[1] - s for s, v in ((s, table[s]) for s in stamps if s in table))}


def by_window(sent, table, width_ns):
    """Per window of `width_ns` from the first target: [sent, delivered, p50 latency ms]."""
    out = []
    for s in sent:
        w = (s - sent[0]) // width_ns
        while len(out) <= w:
            out.append([0, 0, []])
        out[w][0] += 1
        if s in table:
            out[w][1] += 1
            out[w][2].append(table[s] - s)
    return [[n, d, ms(v).get("p50")] for n, d, v in out]


def longest_gap(times_ns):
    return max((b - a for a, b in zip(times_ns, times_ns[1:])), default=0) / 1e6


def analyze_bursts(r, args):
    """1 kHz bursts: per burst, latency of the first and the last quarter of its targets."""
    run = r["run"]
    pc = run.pc_probe
    host, _ = A.read_tap_log(run.tap_log)
    frames = A.set_pulses_frames(A.parse_frames(host))
    by_ticks = {}
    for s, v in pc.servo_angles.items():
        by_ticks.setdefault(A.ticks_of(v[3]), []).append(s)
    wire = {}
    for seq, ticks, t0, _ in frames:
        st = by_ticks.get(ticks)
        if st and len(st) == 1:
            wire.setdefault(st[0], t0)
    bursts = []
    for k in range(args.bursts):
        sent = [s for s, _, phase in run.sent if phase == f"burst{k}"]
        if not sent:
            continue
        dur = (sent[-1] - sent[0]) / 1e9
        quarter = max(1, len(sent) // 4)
        first, last = sent[:quarter], sent[-quarter:]

        def lat(ss, table):
            return [table[s] - s for s in ss if s in table]

        a_tab = {s: v[0] for s, v in pc.servo_angles.items()}
        a_newer = A.this_or_newer(sent, [(v[0], k) for k, v in pc.servo_angles.items()])
        b_newer = A.this_or_newer(sent, [(t, s) for s, t in wire.items()])
        frames_in = [t0 for _, _, t0, _ in frames if sent[0] <= t0 <= sent[-1]]
        on_wire = [s for s in sent if s in wire]
        bursts.append({
            "sent": len(sent), "achieved_hz": (len(sent) - 1) / dur if dur > 0 else None,
            "a_lost": sum(1 for s in sent if s not in pc.servo_angles),
            "a_first_quarter_ms": ms(lat(first, a_tab)), "a_last_quarter_ms": ms(lat(last, a_tab)),
            "b_on_wire": len(on_wire), "b_frames_per_s": len(frames_in) / dur if dur > 0 else None,
            "b_age_first_quarter_ms": ms(lat([s for s in on_wire if s <= first[-1]], wire)),
            "b_age_last_quarter_ms": ms(lat([s for s in on_wire if s >= last[0]], wire)),
            "b_age_all_ms": ms(lat(on_wire, wire)),
            "slots_skipped_by_the_sender": run.skipped.get(f"burst{k}", 0),
            "a_this_or_newer_first_quarter_ms": ms(a_newer[:quarter]),
            "a_this_or_newer_last_quarter_ms": ms(a_newer[-quarter:]),
            "a_this_or_newer_ms": ms(a_newer),
            "b_this_or_newer_first_quarter_ms": ms(b_newer[:quarter]),
            "b_this_or_newer_last_quarter_ms": ms(b_newer[-quarter:]),
            "b_this_or_newer_ms": ms(b_newer),
            "a_by_100ms": by_window(sent, a_tab, 100_000_000),
            "compute_ik_longest_silence_ms": longest_gap(sorted(pc.servo_angles[s][1] for s in sent
                                                                if s in pc.servo_angles)),
            "wire_longest_gap_ms": longest_gap(sorted(frames_in)),
        })
    diag = next((v for k, v in pc.diagnostics.items() if k.startswith("serial_node")), {})
    return {"bursts": bursts, "serial_node_diagnostics": diag, "cpu": r["cpu"], "exit_codes": run.exit_codes}


def precision(same, split, seed_run):
    """(g): what arrives, bit for bit, and what the seed's 4 decimals cost."""
    out = {}
    if same is not None:
        pc, path = same["run"].pc_probe, same["path"]
        idx = {s: i for s, i, _ in same["run"].sent}
        exact = total = 0
        fk_err = []
        ticks_changed = 0
        fk_err_4dp = []
        for s, js in pc.joint_states.items():
            if s not in pc.servo_angles or s not in idx:
                continue
            pos = dict(zip(js[4], js[3]))
            q = [pos["base_joint"], pos["shoulder_joint"], pos["elbow_joint"]]
            total += 1
            # the three arm servos (the claw's comes from gripper_target, not from these joints)
            exact += list(pc.servo_angles[s][3][:3]) == A.servo_angles_from_joints(*q)[:3]
            target = path.xyz(idx[s])
            fk_err.append(math.dist(A.fk(*q), target))
            q4 = [round(v, 4) for v in q]
            fk_err_4dp.append(math.dist(A.fk(*q4), target))
            sa = pc.servo_angles[s][3]
            ticks_changed += A.ticks_of([round(v, 4) for v in sa]) != A.ticks_of(sa)
        out["ours"] = {
            "servo_angles_bit_identical_to_joint_states_mapping": [exact, total],
            "fk_of_received_joint_states_vs_target_m": A.summary(fk_err),
            "what": "servo_angles recomputed in Python from the received joint_states with compute_ik's f64 "
                    "operations equal the received servo_angles bit for bit: neither topic lost a bit; FK of the "
                    "received joint values lands on the target to the last bits of an f64",
        }
        out["ours_through_a_4_decimal_link"] = {
            "fk_error_m": A.summary(fk_err_4dp),
            "commands_whose_pulse_width_changes": [ticks_changed, total],
            "what": "our received joint values rounded to 4 decimals (the seed's link): position error of "
                    "tool0, and how many commands would get another 0.5 us pulse width",
        }
    if split is not None and split["run"].pi_probe is not None:
        pc, pi = split["run"].pc_probe, split["run"].pi_probe
        both = [s for s in pi.servo_angles if s in pc.servo_angles]
        out["across_hosts"] = {"servo_angles_bit_identical_pc_vs_pi": [
            sum(1 for s in both if pc.servo_angles[s][3] == pi.servo_angles[s][3]), len(both)]}
    if seed_run is not None:
        pc, path = seed_run["run"].pc_probe, seed_run["path"]
        idx = {s: i for s, i, _ in seed_run["run"].sent}
        errs, exact, total = [], 0, 0
        for s, v in pc.servo_angles.items():
            if s not in idx:
                continue
            servo, _ = seed_outputs(*path.xyz(idx[s]))
            total += 1
            exact += list(v[3]) == servo
            errs += [abs(a - b) for a, b in zip(v[3], servo)]
        sent_pts = [path.xyz(i) for _, i, phase in seed_run["run"].sent if phase == "measure"]
        fails = sum(1 for p in sent_pts if _seed_fails(p))
        out["seed"] = {"values_bit_identical_to_unrounded": [exact, total], "abs_error_rad": A.summary(errs),
                       "targets_its_equations_cannot_solve": [fails, len(sent_pts)],
                       "what": "the seed node's published values vs its own unrounded f64 result for the same target"}
    return out


def _seed_fails(p):
    try:
        seed_outputs(*p)
        return False
    except (ValueError, ZeroDivisionError):
        return True


# ---------------------------------------------------------------- printing
def verdict(stats, target):
    if not target or not stats or stats.get("n", 0) == 0:
        return ""
    bad = [f"{k} {stats[k]:.3g} > {v:g}" for k, v in target.items() if stats[k] > v]
    return "target " + " ".join(f"{k}<={v:g}" for k, v in target.items()) + (": NOT MET (" + ", ".join(bad) + ")" if bad
                                                                               else ": met")


def row(label, stats, lost=None, total=None, target=None):
    if not stats or stats.get("n", 0) == 0:
        print(f"  {label:<46} no samples" + (f"  lost {lost}/{total}" if lost is not None else ""))
        return
    loss = f"  lost {lost}/{total}" if lost is not None else ""
    print(f"  {label:<46} p50 {stats['p50']:8.3f}  p99 {stats['p99']:8.3f}  max {stats['max']:8.3f} ms  n {stats['n']}"
          f"{loss}  {verdict(stats, target)}")


def skipped_note(r):
    n = (r.get("sender_skipped_slots") or {}).get("measure", 0)
    return f" ({n} slots skipped: the bench itself was not scheduled in time)" if n else ""


def print_cases(cases, res, args):
    same, split, imp = res.get("same"), res.get("split"), res.get("impaired")
    if any(c in cases for c in "abc") and same:
        print(f"\n== (a)-(c) same host (one namespace), {args.rate:g} Hz x {args.seconds:g} s, device {args.device}"
              f"{skipped_note(same)}")
        n = same["sent"]
        if "a" in cases:
            row("(a) xyz_target -> servo_angles", same["a"]["latency_ms"], same["a"]["lost"], n, TARGETS["a"])
            row("    to this or a newer target (newest wins)", same["a"]["this_or_newer_ms"])
            row("    (compute_ik's write, source timestamp)", same["a"]["compute_ik_write_ms"])
            row("    (probe's Python callback, for reference)", same["a"]["callback_ms"])
            if same["a"]["lost"]:
                ev = same["a"]["lost_evidence"]
                gap = ev["gap_to_next_sent_ms"].get("p50", float("nan"))
                nxt = ev["next_delivered_target_write_delay_ms"].get("p50", float("nan"))
                every = ev["all_targets_write_delay_ms"].get("p50", float("nan"))
                print(f"      lost targets: sent {gap:.1f} ms (p50) before the next one; compute_ik wrote the next "
                      f"delivered one {nxt:.2f} ms (p50) after its stamp, {every:.2f} ms for all targets")
        if "b" in cases and "b" in same:
            b = same["b"]
            row("(b) xyz_target -> first byte on the port", b["latency_ms"], b["lost"], n - same["a"]["lost"], TARGETS["b"])
            row("    to this or a newer command (newest wins)", b["this_or_newer_ms"])
            row("    (servo_angles at the probe -> first byte)", b["held_by_rate_limit_ms"])
            d = same.get("serial_node_diagnostics", {})
            print(f"      serial_node's own servo_angles taken -> first byte written (diagnostics, last 1000): "
                  f"p50 {d.get('send_latency_us_p50', '?')} us, p99 {d.get('send_latency_us_p99', '?')} us")
            gap = b.get("frame_gap_ms", {})
            print(f"      frames on the wire {b['frames_on_wire']} ({b.get('frames_per_s', 0) or 0:.1f}/s, gap p50 "
                  f"{gap.get('p50', float('nan')):.2f} ms, p99 {gap.get('p99', float('nan')):.2f} ms), acknowledged "
                  f"{b['acknowledged']}, widths agree with servo_state {b['servo_state_widths_agree']}"
                  + (" (the virtual Arduino reports its modelled horn, not the command)" if args.device == "virtual"
                     else ""))
        if "c" in cases and "c" in same:
            c = same["c"]
            row("(c) xyz_target -> new pulse width on the pin", c["latency_ms"], c["lost"], c["commands"], TARGETS["c"])
            for pin, st in c["per_pin_ms"].items():
                row(f"    pin {pin}", st)
            row("    only pulses with exactly this command's width", c["exact_width_ms"])
            row("    to the end of that pulse", c["latency_to_fall_ms"])
            row("    all changed pins of a command", c["latency_all_pins_ms"])
            row("    simulated part only (UART byte -> rise)", c["sim_part_ms"])
            if "clock_map" in c:
                cm = c["clock_map"]
                print(f"      clock map (tap - cycle time) spread p50 {cm['spread_ms']['p50']:.3f} p99 "
                      f"{cm['spread_ms']['p99']:.3f} ms, drift {cm['drift_ppm']:.0f} ppm "
                      f"(simulated board's clock set {cm['avr_clock_ppm_set']:.0f} ppm fast)")
            print(f"      of {c['pin_changes']} pin changes: {c['pin_changes_superseded']} superseded by a newer command "
                  f"before their slot, {c['pin_changes_not_seen']} not seen, {c['pulses_with_an_unexplained_width']} "
                  f"unexplained, {c['pin_changes_not_timed_width_seen_before']} not timed (width seen shortly before)")
            we = c["width_abs_error_us"]
            if we.get("n"):
                print(f"      pulse width - commanded, |error|: p50 {we['p50']:.3f} us, p99 {we['p99']:.3f} us, "
                      f"max {we['max']:.3f} us")
    if "d" in cases:
        for label, r in (("veth", split), ("impaired " + json.dumps(IMPAIRMENT), imp)):
            if not r:
                continue
            print(f"\n== (d) across the namespaces pc -> pi, {label}, {args.rate:g} Hz x {args.seconds:g} s{skipped_note(r)}")
            n = r["sent"]
            tgt = (lambda k: TARGETS.get(k)) if label == "veth" else (lambda k: None)
            row("(a) xyz_target -> servo_angles in pi", r["a_across"]["latency_ms"], r["a_across"]["lost"], n,
                tgt("a_across"))
            row("    (servo_angles in pc, same ns as compute_ik)", r["a"]["latency_ms"], r["a"]["lost"], n)
            if "b" in r:
                row("(b) xyz_target -> first byte (pi)", r["b"]["latency_ms"], r["b"]["lost"], n - r["a"]["lost"],
                    tgt("b_across"))
            if "c" in r:
                row("(c) xyz_target -> new pulse width", r["c"]["latency_ms"], r["c"]["lost"], r["c"]["commands"])
    if "e" in cases:
        if same and "end_to_end_50hz" in same:
            e = same["end_to_end_50hz"]
            print(f"\n== (e) {args.rate:g} Hz for {args.seconds:g} s, same host: every target through every stage")
            print(f"  sent {e['sent']} -> servo_angles {e['servo_angles']} -> on the wire {e['on_wire']} "
                  f"(acknowledged {e['acknowledged']}) -> on the pins {e['on_pins']}: "
                  + ("zero loss" if e["sent"] == e["on_pins"] else f"LOST {e['sent'] - e['on_pins']}: "
                     f"{e['sent'] - e['servo_angles']} in compute_ik, "
                     f"{e['servo_angles'] - e['on_wire']} replaced in serial_node before their send slot, "
                     f"{e['on_wire'] - e['on_pins']} never on a pin"))
            print(f"  (on the pins: a pulse showed each command's width or a newer one's on every pin it changes; "
                  f"{e['on_pins'] - e['on_pins_timed']} of them could not be timed, see (c))")
        if res.get("burst"):
            print(f"\n== (e) bursts: {args.bursts} x {args.burst_seconds:g} s at {args.burst_rate:g} Hz, "
                  f"{args.burst_gap:g} s at {args.rate:g} Hz between")
            print("  latency to the first output carrying the target or a newer one (newest wins), p50 / p99 ms, "
                  "first and last quarter of each burst:")
            for k, b in enumerate(res["burst"]["bursts"]):
                def pp(st):
                    return f"{st.get('p50', float('nan')):.2f}/{st.get('p99', float('nan')):.2f}"
                print(f"  burst {k}: {b['sent']} sent at {b['achieved_hz'] or 0:.0f} Hz "
                      f"({b['slots_skipped_by_the_sender']} slots skipped); (a) "
                      f"{pp(b['a_this_or_newer_first_quarter_ms'])} -> {pp(b['a_this_or_newer_last_quarter_ms'])}, "
                      f"{b['sent'] - b['a_lost']} targets came out; (b) {pp(b['b_this_or_newer_first_quarter_ms'])} -> "
                      f"{pp(b['b_this_or_newer_last_quarter_ms'])}, {b['b_frames_per_s'] or 0:.1f} frames/s; longest silence: "
                      f"compute_ik {b['compute_ik_longest_silence_ms']:.0f} ms, wire {b['wire_longest_gap_ms']:.0f} ms")
    if "f" in cases and res.get("seed") and res.get("ik_alone"):
        ours, seed = res["ik_alone"], res["seed"]
        print(f"\n== (f) seed's node (rclpy, acos IK, 10 Hz cap `{args.seed_cap}`, 4 decimals) vs compute_ik, alone, "
              f"{args.rate:g} Hz x {args.seconds:g} s, same harness")
        row("compute_ik: xyz_target -> servo_angles", ours["a"]["latency_ms"], ours["a"]["lost"], ours["sent"])
        row("seed:       xyz_target -> servo_angles", seed["a"]["latency_ms"], seed["a"]["lost"], seed["sent"])
        f = res["f"]
        print("  ratios seed / ours: " + ", ".join(f"{k} {v:.1f}x" if isinstance(v, float) else f"{k} {v}"
                                                   for k, v in f["ratios"].items()))
        print(f"  seed losses: {f['seed_loss']}")
    if "g" in cases and res.get("g"):
        g = res["g"]
        print("\n== (g) precision")
        if "ours" in g:
            o = g["ours"]
            bits = o["servo_angles_bit_identical_to_joint_states_mapping"]
            fk_max = o["fk_of_received_joint_states_vs_target_m"].get("max", float("nan"))
            print(f"  ours: servo_angles == mapping(joint_states) bit for bit: {bits}; "
                  f"FK(received joints) - target: max {fk_max:.3g} m")
            f4 = g["ours_through_a_4_decimal_link"]
            print(f"  the same values through a 4-decimal link: FK error max {f4['fk_error_m'].get('max', float('nan')):.3g} m; "
                  f"pulse width changed for {f4['commands_whose_pulse_width_changes']} commands")
        if "across_hosts" in g:
            print(f"  servo_angles in pc and in pi bit-identical: {g['across_hosts']['servo_angles_bit_identical_pc_vs_pi']}")
        if "seed" in g:
            sd = g["seed"]
            print(f"  seed: values bit-identical to its own f64 result {sd['values_bit_identical_to_unrounded']}, "
                  f"abs error max {sd['abs_error_rad'].get('max', float('nan')):.3g} rad; its equations fail for "
                  f"{sd['targets_its_equations_cannot_solve']} of the targets")
    if "h" in cases:
        for label, r in (("50 Hz teleoperation through the web panel (WebSocket -> gui_bridge)", res.get("teleop")),
                         (f"{args.rate:g} Hz from the rclpy operator (run `same`)", same)):
            if not r:
                continue
            print(f"\n== (h) CPU and RSS, {label}")
            for k, v in sorted(r["cpu"].items()):
                note = ""
                if k == "serial_node":
                    note = "  target < 2 %, < 15 MB: " + ("met" if v["cpu_pct"] < 2 and v["rss_mb"] < 15 else "NOT MET")
                print(f"  {k:<32} CPU {v['cpu_pct']:6.2f} % of a core   RSS {v['rss_mb']:6.1f} MB "
                      f"(peak {v['rss_peak_mb']:.1f}){note}")
            if "h_teleop" in r:
                t = r["h_teleop"]
                print(f"  web panel: {t['ws_sent']} targets sent on the WebSocket, gui_bridge published "
                      f"{t['xyz_target_published']} (at most 50/s, newest first), servo_angles for "
                      f"{t['servo_angles_for_them']}, servo_state for {t['servo_state_for_them']}")
                row("  gui_bridge's stamp -> servo_angles", t["latency_gui_stamp_to_servo_angles_ms"])


# ---------------------------------------------------------------- main
def print_load_and_write_json(meta, targets, res, args, lead=""):
    """The end of a benchmark run: the load average at its start and end (`meta`, from
    machine(), with loadavg_end), after `lead`; the machine, `targets` and the results
    `res` written to --json if given."""
    print(f"\n{lead}load average at start {meta['loadavg_start']}, at end {meta['loadavg_end']} "
          f"({meta['cores']} cores; other work on this machine shows in these figures)")
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": meta, "targets": targets, "results": res}, indent=1,
                                              default=str))
        print(f"wrote {args.json}")


def machine():
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor())
    rev = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"],
                                capture_output=True, text=True).stdout.strip())
    return {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "host": platform.node(), "cpu": cpu, "cores": os.cpu_count(), "kernel": platform.release(),
            "python": platform.python_version(), "git": rev + (" (modified)" if dirty else ""),
            "bin_dir": os.environ.get("EEZYBOT_BIN_DIR"), "loadavg_start": os.getloadavg()}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", default="all", help="comma-separated cases a..h, or all")
    ap.add_argument("--seconds", type=float, default=60.0, help="measuring time per run (default 60)")
    ap.add_argument("--rate", type=float, default=50.0, help="target rate (default 50 Hz)")
    ap.add_argument("--device", choices=["simavr", "virtual"], default="simavr",
                    help="the Arduino: the firmware in simavr (default; needed for c) or virtual_arduino")
    ap.add_argument("--avr-clock-ppm", type=float,
                    help="simavr's clock error against wall time, ppm (default: 20 ms / --seconds, one sweep of "
                         "the servo frame's phase per run; 0 = paced exactly, the phase fixed for the run)")
    ap.add_argument("--bursts", type=int, default=5)
    ap.add_argument("--burst-seconds", type=float, default=2.0)
    ap.add_argument("--burst-rate", type=float, default=1000.0)
    ap.add_argument("--burst-gap", type=float, default=2.0, help="seconds at --rate between bursts")
    ap.add_argument("--seed-cap", choices=["loop", "gate"], default="loop", help="how the seed node caps at 10 Hz")
    ap.add_argument("--send-rate", type=float, help="serial_node's send_rate (default: the node's own, 100 Hz); "
                    "for experiments only, the cases' targets are for the defaults")
    ap.add_argument("--path", choices=["smooth", "random"], default="smooth",
                    help="the targets (e2e_analysis.TargetPath): a smooth sweep within the motion limits (default), "
                         "or random jumps")
    ap.add_argument("--firmware", default=str(REPO / "firmware" / "servo_control"),
                    help="the servo_control directory whose build/ holds servo_control.elf and servo_sim "
                         "(default: this tree's; it must speak the protocol version of the serial_node in use)")
    ap.add_argument("--keep", action="store_true", help="keep each run's directory (pty_tap log, simavr events)")
    ap.add_argument("--json", help="write every figure here")
    args = ap.parse_args()
    cases = "abcdefgh" if args.case == "all" else args.case.replace(",", "")
    if set(cases) - set("abcdefgh"):
        ap.error(f"unknown case in {args.case}")
    needed = []
    for c in cases:
        for r in CASE_RUNS[c]:
            if r not in needed and not (r == "burst" and args.bursts == 0):
                needed.append(r)
    meta = machine()
    meta["args"] = vars(args)
    est = sum(15 + (args.bursts * (args.burst_seconds + args.burst_gap) if r == "burst" else args.seconds)
              + (4 if r == "impaired" else 0) for r in needed)
    print(f"e2e benchmark {meta['date']} on {meta['host']} ({meta['cpu']}, {meta['cores']} cores), "
          f"load {meta['loadavg_start']}, binaries {meta['bin_dir']}; runs {needed}, about {est / 60:.1f} min",
          flush=True)
    kinds = {"same": {}, "split": {"layout": "split"}, "impaired": {"layout": "impaired"}, "burst": {"drive": "burst"},
             "ik_alone": {"nodes": "compute_ik"}, "seed": {"nodes": "seed", "seed_cap": args.seed_cap},
             "teleop": {"drive": "ws"}}
    raw, res = {}, {}
    for name in needed:
        raw[name] = graph_run(name, args, **kinds[name])
        res[name] = analyze_bursts(raw[name], args) if name == "burst" else analyze(raw[name], args)
        res[name]["workdir"] = str(raw[name]["run"].workdir) if args.keep else None
        if not args.keep:  # the tap log and simavr's events, analysed by now
            shutil.rmtree(raw[name]["run"].workdir, ignore_errors=True)
    if "ik_alone" in res and "seed" in res:
        o, s = res["ik_alone"], res["seed"]
        ratios = {}
        for k in ("p50", "p99", "max"):
            if o["a"]["latency_ms"].get("n") and s["a"]["latency_ms"].get("n"):
                ratios[f"latency {k}"] = s["a"]["latency_ms"][k] / o["a"]["latency_ms"][k]
        ratios["delivered (ours / seed)"] = ((o["sent"] - o["a"]["lost"]) / max(1, s["sent"] - s["a"]["lost"]))
        cpu_o = next((v for k, v in o["cpu"].items() if k == "compute_ik"), None)
        cpu_s = next((v for k, v in s["cpu"].items() if k.startswith("seed")), None)
        if cpu_o and cpu_s:
            ratios["CPU"] = cpu_s["cpu_pct"] / max(cpu_o["cpu_pct"], 1e-9)
            ratios["RSS"] = cpu_s["rss_mb"] / cpu_o["rss_mb"]
        sent_idx = [i for _, i, phase in raw["seed"]["run"].sent if phase == "measure"]
        acos = sum(1 for i in sent_idx if _seed_fails(raw["seed"]["path"].xyz(i)))
        res["f"] = {"ratios": ratios, "seed_loss": {
            "sent": s["sent"], "lost": s["a"]["lost"], "its_equations_fail (acos/division)": acos,
            "dropped_by_the_10_hz_cap": s["a"]["lost"] - acos}}
    if "g" in cases:
        res["g"] = precision(raw.get("same"), raw.get("split"), raw.get("seed"))
    meta["loadavg_end"] = os.getloadavg()
    print_cases(cases, res, args)
    print_load_and_write_json(meta, TARGETS, res, args)


if __name__ == "__main__":
    main()
