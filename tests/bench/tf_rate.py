"""Benchmark: state_publisher fed joint_states at 100 Hz by rclpy (the arm's 11 joints).
Reports the node's own joint_states-taken -> tf-published latency (p50/p99 over the
last 1000 messages, from its diagnostics), tf messages received, CPU and RSS.

    $EEZYBOT_PYTHON tests/bench/tf_rate.py [--rate 100] [--seconds 20]
"""
import argparse
import math
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("EEZYBOT_BIN_DIR", str(Path(__file__).resolve().parents[2] / "target" / "release"))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from conftest import DomainLease, NodeProcess, Observer, TfListener  # noqa: E402
from ik_latency import proc_cpu_seconds, proc_rss_mb  # noqa: E402

NAMES = ["base_joint", "shoulder_joint", "elbow_joint", "gripper_joint", "wrist_joint", "crank_joint",
         "drive_link_joint", "level_link_joint", "triangle_joint", "upper_link_joint", "gripper_mimic_joint"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--seconds", type=float, default=20.0)
    args = ap.parse_args()
    lease = DomainLease()
    node = NodeProcess("state_publisher", ["--ros-args", "-p", "diagnostics_period:=0.5"], lease.id)
    obs = Observer(lease.id, "bench")
    tf = TfListener(lease.id)
    diags = obs.sub("/diagnostics", DiagnosticArray)
    pub = obs.pub("/joint_states", JointState)
    obs.wait_matched(pub)
    obs.wait_publisher("/tf")
    obs.spin_for(1.0)
    n = int(args.rate * args.seconds)
    c0, t0 = proc_cpu_seconds(node.proc.pid), time.monotonic()
    start = time.perf_counter()
    for i in range(n):
        a = 1.2 + 0.3 * math.sin(i / 50)
        e = -1.6 + 0.2 * math.cos(i / 70)
        phi = a + e
        msg = JointState(name=NAMES, position=[0.1 * math.sin(i / 30), a, e, 0.3, -phi, phi, a - phi, a, -a, phi, -0.3])
        msg.header.stamp.sec, msg.header.stamp.nanosec = 2000 + i // 1000, (i % 1000) * 1000
        pub.publish(msg)
        deadline = start + (i + 1) / args.rate
        while (remaining := deadline - time.perf_counter()) > 0:
            obs.executor.spin_once(timeout_sec=remaining)
        if i % 20 == 0:
            tf.poll()
    obs.spin_for(1.5)
    tf.poll()
    cpu = (proc_cpu_seconds(node.proc.pid) - c0) / (time.monotonic() - t0) * 100
    rss = proc_rss_mb(node.proc.pid)
    values = {kv.key: kv.value for kv in diags[-1][1].status[0].values}
    code = node.stop()
    obs.close()
    lease.release()
    print(f"joint_states at {args.rate:g} Hz for {args.seconds:g} s: {n} sent, {len(tf.messages)} tf messages received")
    print(f"in-node joint_states -> tf latency us: p50 {values.get('tf_latency_us_p50')}  p99 {values.get('tf_latency_us_p99')}")
    print(f"state_publisher: CPU {cpu:.2f} % of a core, RSS {rss:.1f} MB; exit code {code}")


if __name__ == "__main__":
    main()
