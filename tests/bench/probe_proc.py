#!/usr/bin/env python3
"""An rclpy probe in its own process (so it can live in another network namespace than
the benchmark's own probe: two rclpy contexts of one process in two namespaces do not
discover anyone from the second one). Records every sample of the given JointState
topics with Fast DDS's reception and source timestamps, keyed by header stamp, and
writes them as JSON when stopped (SIGINT/SIGTERM).

    python probe_proc.py OUT.json STATUS_FILE TOPIC...

STATUS_FILE gets `matched` once every topic has a publisher (ROS_DOMAIN_ID from the
environment). Floats go through JSON with repr, so they come back bit for bit.
"""
import json
import sys
import time


def main():
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from rclpy_main import spinning

    out_path, status_path, topics = sys.argv[1], sys.argv[2], sys.argv[3:]
    rclpy.init()
    node = rclpy.create_node("bench_probe")
    qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    tables = {t: {} for t in topics}
    dup = [0]

    def keep(table):
        def cb(m, info):
            key = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
            if key in table:
                dup[0] += 1
                return
            table[key] = [info["received_timestamp"], info["source_timestamp"], time.time_ns(), list(m.position),
                          list(m.name)]
        return cb

    for t in topics:
        node.create_subscription(JointState, t, keep(tables[t]), qos)
    matched = False
    with spinning(node):
        while rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.1)
            if not matched and all(node.count_publishers(t) > 0 for t in topics):
                matched = True
                with open(status_path, "w") as f:
                    f.write("matched\n")
    with open(out_path, "w") as f:
        json.dump({"tables": {t: {str(k): v for k, v in tab.items()} for t, tab in tables.items()},
                   "duplicates": dup[0]}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
