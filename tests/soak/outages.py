#!/usr/bin/env python3
"""Soak: network outages between the operator's PC and the Raspberry Pi.

The graph runs split across network namespaces `pc` (launch_scripts/pc.sh) and `pi`
(launch_scripts/pi.sh, serial_node driving the virtual Arduino behind a pty), with an
rclpy operator in `pc` sending targets at 20 Hz all the time. Each trial pulls the cable
at one end for a while and plugs it back (multicast route re-added, as a DHCP client
does), then records when the first servo_state for a target sent after the link
returned arrived, whether any command from the outage was applied after it, whether
the peers were reported lost and regained, and how many unreachable-network lines
were logged. One graph lives through every trial, as in a long teleoperation session.

    $EEZYBOT_PYTHON tests/soak/outages.py [--trials 20] [--lengths 3,12,25,60]
        [--sides pc,pi] [--json FILE]

20 trials of 3, 12, 25 and 60 s at each end take about 75 minutes.
"""
import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import twohost  # noqa: E402
from conftest import DomainLease  # noqa: E402
from split_graph import SplitGraph  # noqa: E402

RESUME_WITHIN_S = 5.0  # issue 8: the graph resumes within 5 s of the link returning


def summarize(results):
    rows = []
    for key in sorted({(r["length_s"], r["side"]) for r in results}):
        rs = [r for r in results if (r["length_s"], r["side"]) == key]
        resume = sorted(r["resume_s"] for r in rs if r["resume_s"] is not None)
        rows.append({
            "length_s": key[0], "side": key[1], "trials": len(rs),
            "resumed_within_5s": sum(1 for r in rs if r["resume_s"] is not None and r["resume_s"] <= RESUME_WITHIN_S),
            "resume_p50_s": statistics.median(resume) if resume else None,
            "resume_max_s": resume[-1] if resume else None,
            "stale_applied": sum(r["stale"] for r in rs),
            "out_of_order": sum(r["out_of_order"] for r in rs),
            "lost_and_regained_reported": sum(1 for r in rs if (r["serial_angles_lost"] or 0) >= 1
                                              and (r["serial_angles_regained"] or 0) >= 1),
            "unreachable_lines_max": max(max(r["unreachable_lines"].values()) for r in rs),
        })
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--lengths", default="3,12,25,60")
    ap.add_argument("--sides", default="pc,pi")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    if twohost.available():
        sys.exit(f"cannot run: {twohost.available()}")
    lengths = [float(x) for x in args.lengths.split(",")]
    sides = args.sides.split(",")
    lease = DomainLease()
    results = []
    t_start = time.time()
    with tempfile.TemporaryDirectory() as work, twohost.TwoHosts(tag="q") as hosts:
        g = SplitGraph(hosts, lease.id, work, device="virtual")
        try:
            g.wait_flowing(60)
            for trial in range(args.trials):
                for length in lengths:
                    for side in sides:
                        r = g.outage(length, side)
                        r["trial"] = trial
                        results.append(r)
                        print(f"trial {trial + 1:2d}  {length:4.0f} s at {side}: resumed after "
                              f"{r['resume_s'] if r['resume_s'] is None else round(r['resume_s'], 2)} s, "
                              f"stale {r['stale']}, lost/regained {r['serial_angles_lost']}/{r['serial_angles_regained']}, "
                              f"unreachable lines {r['unreachable_lines']}", flush=True)
        finally:
            codes = g.close()
            lease.release()
    summary = summarize(results)
    print(f"\n{'outage':>7} {'side':>4} {'resumed<=5s':>12} {'p50 s':>6} {'max s':>6} {'stale':>5} "
          f"{'lost+regained':>13} {'unreach.':>8}")
    for row in summary:
        print(f"{row['length_s']:6.0f}s {row['side']:>4} {row['resumed_within_5s']:>6}/{row['trials']:<5} "
              f"{row['resume_p50_s'] or float('nan'):6.2f} {row['resume_max_s'] or float('nan'):6.2f} "
              f"{row['stale_applied']:5d} {row['lost_and_regained_reported']:>9}/{row['trials']:<3} "
              f"{row['unreachable_lines_max']:8d}")
    print(f"exit codes {codes}, {time.time() - t_start:.0f} s in all")
    if args.json:
        args.json.write_text(json.dumps({"date": time.strftime("%Y-%m-%d"), "summary": summary,
                                         "trials": results, "exit_codes": codes}, indent=1))


if __name__ == "__main__":
    main()
