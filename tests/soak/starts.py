#!/usr/bin/env python3
"""Soak: start-up discovery between our four nodes and a user's rclpy (Fast DDS) process.

Each start launches compute_ik, state_publisher, serial_node and gui_bridge and an
rclpy participant together, or one second apart in either order, on one host or split
across the `pc`/`pi` namespaces (tests/startup.py), and counts two failures:
  * node list: a node of ours still missing from rclpy's node list after 20 s (node
    names travel on ros_discovery_info);
  * endpoints: an endpoint of ours never discovered or matched within 20 s.
No node is ever restarted.

    $EEZYBOT_PYTHON tests/soak/starts.py [--starts 204] [--orders together,rclpy_first,nodes_first]
        [--hosts one,split] [--json FILE]

The starts are spread evenly over every (order, hosts) combination; ~5 s each.
"""
import argparse
import itertools
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import twohost  # noqa: E402
from conftest import DomainLease  # noqa: E402
from startup import run_in_subprocess  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--starts", type=int, default=204)
    ap.add_argument("--orders", default="together,rclpy_first,nodes_first")
    ap.add_argument("--hosts", default="one,split")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    combos = list(itertools.product(args.orders.split(","), args.hosts.split(",")))
    if any(h == "split" for _, h in combos) and twohost.available():
        sys.exit(f"cannot run split starts: {twohost.available()}")
    results = []
    t0 = time.time()
    for i in range(args.starts):
        order, where = combos[i % len(combos)]
        lease = DomainLease()
        try:
            r = run_in_subprocess(lease.id, order=order, split=where == "split")
        finally:
            lease.release()
        results.append(r)
        bad = r["missing_nodes"] or r["missing_endpoints"]
        print(f"start {i + 1:3d} {order:>11} {where:>5}: node list {r['node_list_s'] and round(r['node_list_s'], 2)} s, "
              f"endpoints {r['endpoints_s'] and round(r['endpoints_s'], 2)} s"
              + (f"  FAILED missing nodes {r['missing_nodes']} endpoints {r['missing_endpoints']} logs {r['logs']}"
                 if bad else ""), flush=True)
    summary = []
    print(f"\n{'order':>11} {'hosts':>5} {'starts':>6} {'node list missing':>17} {'endpoints missing':>17} "
          f"{'node list p50/max s':>20} {'endpoints p50/max s':>20}")
    for order, where in combos:
        rs = [r for r in results if r["order"] == order and r["hosts"] == ("split" if where == "split" else "one")]
        nl = sorted(r["node_list_s"] for r in rs if r["node_list_s"] is not None)
        ep = sorted(r["endpoints_s"] for r in rs if r["endpoints_s"] is not None)
        row = {"order": order, "hosts": where, "starts": len(rs),
               "node_list_failures": sum(1 for r in rs if r["missing_nodes"]),
               "endpoint_failures": sum(1 for r in rs if r["missing_endpoints"]),
               "node_list_p50_s": statistics.median(nl) if nl else None, "node_list_max_s": nl[-1] if nl else None,
               "endpoints_p50_s": statistics.median(ep) if ep else None, "endpoints_max_s": ep[-1] if ep else None}
        summary.append(row)
        print(f"{order:>11} {where:>5} {len(rs):6d} {row['node_list_failures']:17d} {row['endpoint_failures']:17d} "
              f"{row['node_list_p50_s'] or float('nan'):9.2f}/{row['node_list_max_s'] or float('nan'):<9.2f} "
              f"{row['endpoints_p50_s'] or float('nan'):9.2f}/{row['endpoints_max_s'] or float('nan'):<9.2f}")
    total = len(results)
    print(f"all: {total} starts, node list missing in {sum(r['node_list_failures'] for r in summary)}, "
          f"endpoints missing in {sum(r['endpoint_failures'] for r in summary)}; {time.time() - t0:.0f} s")
    if args.json:
        args.json.write_text(json.dumps({"date": time.strftime("%Y-%m-%d"), "summary": summary, "starts": results},
                                        indent=1))


if __name__ == "__main__":
    main()
