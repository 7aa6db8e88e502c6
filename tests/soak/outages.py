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
        [--sides pc,pi] [--mode lan|wan] [--json FILE]

20 trials of 3, 12, 25 and 60 s at each end take about 75 minutes. Exits 1 if a trial
failed (no resume within 5 s, a stale or out-of-order command, a cut longer than the
lease without the lost and regained peer reported) or a process did not exit 0.

--mode wan: the WAN mode (issue 20) instead of one LAN: namespaces pc, wan and pi
(tests/wanhost.py), launch_scripts/router.sh in `wan` with certificates of its own,
pc.sh and pi.sh with ZENOH_ROUTER (each starts its bridge); a cut takes a site's link
to the router down. `--mode wan --sides pi`: the Pi's WAN link, about 40 minutes.
"""
import tempfile
import time
from pathlib import Path

import soaklib  # first: it puts tests/ on sys.path
import twohost
import wanhost
from split_graph import SplitGraph

RESUME_WITHIN_S = 5.0  # issue 8: the graph resumes within 5 s of the link returning
# a cut longer than the lease loses the peers: our DDS participants' 5 s, Zenoh's 10 s
LEASE_S = {"lan": 5.0, "wan": 10.0}


def trial_failed(r, mode):
    """Why an outage trial failed (None: it passed): no resume within 5 s, a command of
    the outage applied after it or out of order, or a cut longer than the lease whose
    lost and regained peer serial_node did not report."""
    why = []
    if r["resume_s"] is None or r["resume_s"] > RESUME_WITHIN_S:
        why.append(f"resumed after {r['resume_s']} s")
    if r["stale"] or r["out_of_order"]:
        why.append(f"stale {r['stale']}, out of order {r['out_of_order']}")
    if r["length_s"] > LEASE_S[mode] and not ((r["serial_angles_lost"] or 0) >= 1 and (r["serial_angles_regained"] or 0) >= 1):
        why.append(f"lost/regained {r['serial_angles_lost']}/{r['serial_angles_regained']} not reported")
    return "; ".join(why)


def summarize(results):
    rows = []
    for key in sorted({(r["length_s"], r["side"]) for r in results}):
        rs = [r for r in results if (r["length_s"], r["side"]) == key]
        rows.append({
            "length_s": key[0], "side": key[1], "trials": len(rs),
            "resumed_within_5s": sum(1 for r in rs if r["resume_s"] is not None and r["resume_s"] <= RESUME_WITHIN_S),
            **soaklib.p50_max("resume", (r["resume_s"] for r in rs)),
            "stale_applied": sum(r["stale"] for r in rs),
            "out_of_order": sum(r["out_of_order"] for r in rs),
            "lost_and_regained_reported": sum(1 for r in rs if (r["serial_angles_lost"] or 0) >= 1
                                              and (r["serial_angles_regained"] or 0) >= 1),
            "unreachable_lines_max": max(max(r["unreachable_lines"].values()) for r in rs),
        })
    return rows


def hosts_for(mode):
    """The namespaces: pc and pi on one link (lan), or pc, wan and pi (wan)."""
    return wanhost.WanHosts(tag="q") if mode == "wan" else twohost.TwoHosts(tag="q")


def main():
    args = soaklib.arguments(__doc__, trials=20, lengths="3,12,25,60", sides="pc,pi", mode="lan")
    soaklib.need_two_hosts()
    if args.mode not in ("lan", "wan"):
        raise SystemExit(f"--mode {args.mode}: lan or wan")
    lengths = [float(x) for x in args.lengths.split(",")]
    sides = args.sides.split(",")
    results = []
    t_start = time.time()
    with soaklib.domain() as domain, tempfile.TemporaryDirectory() as work, hosts_for(args.mode) as hosts:
        env = None
        if args.mode == "wan":
            certs = wanhost.make_certs(Path(work) / "certs")
            hosts.start_router(certs, Path(work) / "router.log")
            env = hosts.graph_env(certs)
        g = SplitGraph(hosts, domain, work, device="virtual", env=env)
        try:
            g.wait_flowing(60)
            for trial in range(args.trials):
                for length in lengths:
                    for side in sides:
                        r = soaklib.outage(g, results, trial, length, side)
                        print(f"trial {trial + 1:2d}  {length:4.0f} s at {side}: resumed after "
                              f"{r['resume_s'] if r['resume_s'] is None else round(r['resume_s'], 2)} s, "
                              f"stale {r['stale']}, lost/regained {r['serial_angles_lost']}/{r['serial_angles_regained']}, "
                              f"unreachable lines {r['unreachable_lines']}", flush=True)
        finally:
            codes = g.close()
    summary = summarize(results)
    print(f"\n{'outage':>7} {'side':>4} {'resumed<=5s':>12} {'p50 s':>6} {'max s':>6} {'stale':>5} "
          f"{'lost+regained':>13} {'unreach.':>8}")
    for row in summary:
        print(f"{row['length_s']:6.0f}s {row['side']:>4} {row['resumed_within_5s']:>6}/{row['trials']:<5} "
              f"{row['resume_p50_s'] or float('nan'):6.2f} {row['resume_max_s'] or float('nan'):6.2f} "
              f"{row['stale_applied']:5d} {row['lost_and_regained_reported']:>9}/{row['trials']:<3} "
              f"{row['unreachable_lines_max']:8d}")
    print(f"exit codes {codes}, {time.time() - t_start:.0f} s in all")
    soaklib.write_json(args.json, summary, trials=results, exit_codes=codes, mode=args.mode)
    bad = soaklib.failures(results, lambda r: trial_failed(r, args.mode))
    bad += [f"{proc} exited {code}" for proc, code in codes.items() if code != 0]
    soaklib.finish(bad, len(results))


if __name__ == "__main__":
    main()
