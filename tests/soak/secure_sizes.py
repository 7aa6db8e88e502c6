#!/usr/bin/env python3
"""Soak: secured samples of every size between our nodes' stack and Fast DDS, both ways,
under SROS2 Enforce (issue 36, item 3; patches/README.md rustdds entry 34).

Our side is ros_plumbing's ros_probe example (ros2-client over RustDDS through RosNode,
as every node of the graph, pc enclave); the other is tests/interop/sros2_peer (Debian's
Fast DDS 2.9 with its DDS Security plugins, tools enclave, as RViz2 or `ros2 topic` would
run). `--samples` std_msgs/String samples on `robot_description` go each way, one at a
time (the topic is latched, keep last 1), of sizes drawn log-uniformly from 1 byte to
64 KiB (65,536 bytes with the CDR header: the text is 1 to 65,527 bytes; seeded, the
same every run) with the edges always in: 1-4 bytes, each residue mod 4 past the
fragmentation threshold and at 64 KiB. Each sample's bytes differ by its index and
position, so a lost, swapped or corrupted fragment shows. A sample not received within
`--timeout` s is lost; one received with other bytes is corrupt. Exits 1 if any was.
test_security.py's `test_fast_dds_and_our_nodes_exchange_secured_samples_of_every_size`
runs one trial of it (12 sizes each way) in the test command.

    $EEZYBOT_PYTHON tests/soak/secure_sizes.py [--samples 1000] [--timeout 10] [--json FILE]
"""
import math
import random
import statistics
import tempfile
from pathlib import Path

import soaklib  # first: it puts tests/ on sys.path
from conftest import bin_path
from security_rig import SecurePeer, exchange, make_keystore

TOPIC = "robot_description"
EDGES = [1, 2, 3, 4, 1500, 1501, 1502, 1503, 65524, 65525, 65526, 65527]


def sizes(count, seed):
    rng = random.Random(seed)
    drawn = [max(1, min(65527, round(math.exp(rng.uniform(0, math.log(65527)))))) for _ in range(count - len(EDGES))]
    return EDGES + drawn


def summary(results):
    lost = [s for s, v, _ in results if v == "lost"]
    corrupt = [s for s, v, _ in results if v == "corrupt"]
    seconds = sorted(t for _, v, t in results if v == "ok")
    p = (lambda q: seconds[min(len(seconds) - 1, int(q * len(seconds)))] * 1000) if seconds else (lambda q: None)
    return {"samples": len(results), "ok": len(seconds), "lost": len(lost), "corrupt": len(corrupt),
            "lost_sizes": lost[:20], "corrupt_sizes": corrupt[:20], "bytes": sum(s for s, _, _ in results),
            "p50_ms": p(0.5), "p99_ms": p(0.99), "max_ms": p(1.0)}


def main():
    args = soaklib.arguments(__doc__, samples=1000, timeout=10.0, seed=36)
    work = Path(tempfile.mkdtemp(prefix="secure_sizes-"))
    keystore = make_keystore(work / "keystore", "/eezybot/tools")
    plan = sizes(args.samples, args.seed)
    with soaklib.domain() as domain:
        tool = SecurePeer(domain, enclave=keystore.enclave("/eezybot/tools"), pubs=[TOPIC], subs=[TOPIC],
                          name="fastdds_tool")
        ours = SecurePeer(domain, enclave=keystore.enclave("/eezybot/pc"), pubs=[TOPIC], subs=[TOPIC],
                          name="ros_probe", binary=bin_path("examples/ros_probe"))
        failed = []
        try:
            tool.wait_ready()
            ours.wait_ready()
            if not ours.wait(lambda: ours.matched(TOPIC, "pub") >= 1 and tool.matched(TOPIC, "pub") >= 1, 60):
                soaklib.finish([f"not matched in 60 s\n{tool.stderr()[-2000:]}\n{ours.stderr()[-2000:]}"], 0)
            runs = {}
            for name, sender, receiver, first in (("ours_to_fastdds", ours, tool, 0),
                                                  ("fastdds_to_ours", tool, ours, len(plan))):
                results = exchange(sender, receiver, TOPIC, plan, args.timeout, first_index=first)
                runs[name] = summary(results)
                print(f"{name}: {runs[name]}", flush=True)
                failed += [f"{name}: {r['lost']} lost {r['lost_sizes']}, {r['corrupt']} corrupt {r['corrupt_sizes']}"
                           for r in [runs[name]] if r["lost"] or r["corrupt"]]
            print(f"sizes: median {statistics.median(plan)} B, {sum(1 for s in plan if s > 1400)} of {len(plan)} "
                  f"fragmented (over ~1.4 KB)", flush=True)
            soaklib.write_json(args.json, runs, sizes=plan)
        finally:
            codes = {p.name: p.close() for p in (tool, ours)}
        failed += [f"{n} exited {c}" for n, c in codes.items() if c != 0]
        soaklib.finish(failed, 2 * len(plan), "samples")


if __name__ == "__main__":
    main()
