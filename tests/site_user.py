"""A ROS 2 user at one site of the WAN tests (test_wan.py): a real rclpy process of its
own, as a user's would be (Fast DDS in a process that has had participants in another
network namespace no longer discovers anything in its own, so every site's user is a
separate process, started with `ip netns exec`).

    python tests/site_user.py --domain N --for S [--sub TOPIC]...
        [--until TOPIC]... [--estop true|false] [--estop-rate HZ] [--topics]

Subscribes to each TOPIC of the contract with its QoS (latched ones transient-local),
for S seconds, or until each --until TOPIC (one of the --sub) has a sample (at most S
seconds). --estop publishes that value on /estop (latched): once then (or at the start
without --until), or every 1/HZ s with --estop-rate; after a single one it stays 5 s
more (a late reader gets it; what it subscribes goes on counting). --topics lists the topic names this site's DDS graph has. Prints
one JSON line: {"got": {topic: {"count": n, "first": ..., "last": ...}}, "estops_sent": n,
"topics": [...], "statuses": {name: {"level": n, "message": ...}} (of /diagnostics: each
status name's last)}."""
import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from std_msgs.msg import Bool  # noqa: E402

from conftest import msg_type, qos  # noqa: E402


def summary(m):
    """What the test compares: the text's length and head, the flag, the positions."""
    if hasattr(m, "data"):
        return m.data if isinstance(m.data, bool) else {"len": len(m.data), "head": m.data[:200]}
    if hasattr(m, "position"):
        return list(m.position)
    return str(m)[:200]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--for", dest="seconds", type=float, required=True)
    ap.add_argument("--sub", action="append", default=[])
    ap.add_argument("--until", action="append", default=[])
    ap.add_argument("--estop", choices=["true", "false"])
    ap.add_argument("--estop-rate", type=float)
    ap.add_argument("--topics", action="store_true")
    a = ap.parse_args()
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=a.domain)
    node = rclpy.create_node("site_user", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    got = {t: [] for t in a.sub}
    for t in a.sub:
        node.create_subscription(msg_type(t), t, lambda m, t=t: got[t].append(m), qos(t))
    estop = node.create_publisher(Bool, "/estop", qos("/estop")) if a.estop else None
    sent = 0
    next_estop = time.monotonic() if a.estop and not a.until else None
    end = time.monotonic() + a.seconds
    linger_end = None
    while time.monotonic() < end:
        now = time.monotonic()
        if a.until and next_estop is None and linger_end is None and all(got[t] for t in a.until):
            if estop is None:
                break
            next_estop = now
        if next_estop is not None and now >= next_estop:
            estop.publish(Bool(data=a.estop == "true"))
            sent += 1
            if a.estop_rate:
                next_estop = now + 1.0 / a.estop_rate
            else:
                next_estop = float("inf")
                linger_end = now + 5.0
        if linger_end is not None and now >= linger_end:
            break
        executor.spin_once(timeout_sec=0.02)
    result = {"got": {t: {"count": len(ms), "first": summary(ms[0]) if ms else None,
                          "last": summary(ms[-1]) if ms else None} for t, ms in got.items()},
              "estops_sent": sent}
    # diagnostics: each status name's last level and message
    statuses = {}
    for m in got.get("/diagnostics", []):
        for st in m.status:
            statuses[st.name] = {"level": st.level[0] if isinstance(st.level, bytes) else st.level,
                                 "message": st.message[:200]}
    if statuses:
        result["statuses"] = statuses
    if a.topics:
        result["topics"] = sorted(n for n, _ in node.get_topic_names_and_types())
    print(json.dumps(result), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=context)


if __name__ == "__main__":
    main()
