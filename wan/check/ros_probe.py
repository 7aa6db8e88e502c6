"""A ROS 2 publisher or subscriber for checking the WAN bridges by hand (rclpy; run
with the project's venv: `. launch_scripts/setup_env.sh; $EEZYBOT_PYTHON ...`).

  ros_probe.py pub TOPIC joint|bool [--latched] [--count N] [--rate HZ] [--linger S]
  ros_probe.py sub TOPIC joint|bool [--latched] [--timeout S] [--count N]

The QoS is the contract's: reliable, keep last 10 (volatile) or keep last 1
(transient-local with --latched). `pub` publishes positions [i, i+0.5] (joint) or True
(bool), one line per sample; `sub` prints each sample with its age in ms (from the
header stamp, joint) and exits 0 after --count samples, 1 at --timeout without one.
"""
import argparse
import sys
import time

import rclpy
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool


def qos(latched):
    return QoSProfile(
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        history=HistoryPolicy.KEEP_LAST,
        depth=1 if latched else 10,
    )


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("role", choices=["pub", "sub"])
    ap.add_argument("topic")
    ap.add_argument("type", choices=["joint", "bool"])
    ap.add_argument("--latched", action="store_true")
    ap.add_argument("--count", type=int, default=None)
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--timeout", type=float, default=20.0)
    ap.add_argument("--linger", type=float, default=0.0)
    a = ap.parse_args()
    msg_type = JointState if a.type == "joint" else Bool
    rclpy.init()
    node = rclpy.create_node(f"probe_{a.role}_{a.topic.strip('/').replace('/', '_')}")
    out = sys.stdout
    if a.role == "pub":
        pub = node.create_publisher(msg_type, a.topic, qos(a.latched))
        count = a.count if a.count is not None else 1_000_000
        for i in range(count):
            if a.type == "joint":
                m = JointState()
                m.header.stamp = node.get_clock().now().to_msg()
                m.name = ["base", "shoulder"]
                m.position = [float(i), i + 0.5]
            else:
                m = Bool(data=True)
            pub.publish(m)
            print(f"pub {a.topic} #{i}", file=out, flush=True)
            rclpy.spin_once(node, timeout_sec=1.0 / a.rate)
        end = time.monotonic() + a.linger
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
        return 0
    got = []

    def on_msg(m):
        if a.type == "joint":
            now = node.get_clock().now().nanoseconds
            stamp = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
            print(f"sub {a.topic} position={list(m.position)} age_ms={(now - stamp) / 1e6:.1f}", file=out, flush=True)
        else:
            print(f"sub {a.topic} data={m.data}", file=out, flush=True)
        got.append(m)

    node.create_subscription(msg_type, a.topic, on_msg, qos(a.latched))
    end = time.monotonic() + a.timeout
    want = a.count or 1
    while time.monotonic() < end and len(got) < (a.count or 10**9):
        rclpy.spin_once(node, timeout_sec=0.1)
    print(f"sub {a.topic}: {len(got)} samples", file=out, flush=True)
    return 0 if len(got) >= want else 1


if __name__ == "__main__":
    sys.exit(main())
