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

The starts are spread evenly over every (order, hosts) combination; ~5 s each. Exits 1
if a start failed either way (a start whose nodes did not exit 0 stops the soak with an
error).
"""
import itertools
import time

import soaklib  # first: it puts tests/ on sys.path
from startup import run_in_subprocess


def main():
    args = soaklib.arguments(__doc__, starts=204, orders="together,rclpy_first,nodes_first", hosts="one,split")
    combos = list(itertools.product(args.orders.split(","), args.hosts.split(",")))
    if any(h == "split" for _, h in combos):
        soaklib.need_two_hosts("run split starts")
    results = []
    t0 = time.time()
    for i in range(args.starts):
        order, where = combos[i % len(combos)]
        with soaklib.domain() as domain:
            r = run_in_subprocess(domain, order=order, split=where == "split")
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
        row = {"order": order, "hosts": where, "starts": len(rs),
               "node_list_failures": sum(1 for r in rs if r["missing_nodes"]),
               "endpoint_failures": sum(1 for r in rs if r["missing_endpoints"]),
               **soaklib.p50_max("node_list", (r["node_list_s"] for r in rs)),
               **soaklib.p50_max("endpoints", (r["endpoints_s"] for r in rs))}
        summary.append(row)
        print(f"{order:>11} {where:>5} {len(rs):6d} {row['node_list_failures']:17d} {row['endpoint_failures']:17d} "
              f"{row['node_list_p50_s'] or float('nan'):9.2f}/{row['node_list_max_s'] or float('nan'):<9.2f} "
              f"{row['endpoints_p50_s'] or float('nan'):9.2f}/{row['endpoints_max_s'] or float('nan'):<9.2f}")
    total = len(results)
    print(f"all: {total} starts, node list missing in {sum(r['node_list_failures'] for r in summary)}, "
          f"endpoints missing in {sum(r['endpoint_failures'] for r in summary)}; {time.time() - t0:.0f} s")
    soaklib.write_json(args.json, summary, starts=results)
    soaklib.finish(soaklib.failures(results, lambda r: (r["missing_nodes"] or r["missing_endpoints"]) and
                                    f"{r['order']} {r['hosts']}: missing nodes {r['missing_nodes']}, endpoints "
                                    f"{r['missing_endpoints']}", name="start"), len(results), "starts")


if __name__ == "__main__":
    main()
