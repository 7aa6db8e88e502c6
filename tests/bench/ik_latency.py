"""Benchmark: rclpy publishes xyz_target -> rclpy receives servo_angles, through the real
compute_ik binary on this host. Also compute_ik's idle CPU and RSS.

    $EEZYBOT_PYTHON tests/bench/ik_latency.py [--rate 100] [--seconds 30] [--bin target/release]

Prints p50/p99/max latency and loss; the matching is by header.stamp, so every
sample is accounted for.
"""
import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
os.environ.setdefault("EEZYBOT_BIN_DIR", str(Path(__file__).resolve().parents[2] / "target" / "release"))

from geometry_msgs.msg import PointStamped  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from conftest import DomainLease, NodeProcess, Observer  # noqa: E402


def proc_cpu_seconds(pid):
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def proc_rss_mb(pid):
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def pct(sorted_values, p):
    return sorted_values[min(len(sorted_values) - 1, int(round(p / 100 * (len(sorted_values) - 1))))]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--idle-seconds", type=float, default=10.0)
    args = ap.parse_args()

    lease = DomainLease()
    node = NodeProcess("compute_ik", [], lease.id)
    obs = Observer(lease.id, "bench")
    received = {}
    obs.node.create_subscription(
        JointState, "/servo_angles",
        lambda m: received.setdefault((m.header.stamp.sec, m.header.stamp.nanosec), time.perf_counter_ns()), 100)
    pub = obs.pub("/xyz_target", PointStamped)
    obs.wait_matched(pub)
    obs.wait_publisher("/servo_angles")

    # idle
    obs.spin_for(1.0)
    c0, t0 = proc_cpu_seconds(node.proc.pid), time.monotonic()
    obs.spin_for(args.idle_seconds)
    idle_cpu = (proc_cpu_seconds(node.proc.pid) - c0) / (time.monotonic() - t0) * 100
    idle_rss = proc_rss_mb(node.proc.pid)

    # load
    sent = {}
    period = 1.0 / args.rate
    n = int(args.seconds * args.rate)
    c0, t0 = proc_cpu_seconds(node.proc.pid), time.monotonic()
    start = time.perf_counter()
    for i in range(n):
        m = PointStamped()
        m.header.frame_id = "base_link"
        # a real stamp (compute_ik refuses targets older than max_target_age), unique per
        # target: the key its servo_angles are matched by
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
        m.point.x, m.point.y, m.point.z = 0.2 + 0.03 * ((i % 100) / 100), 0.02 * ((i % 50) / 50 - 0.5), 0.15
        sent[(m.header.stamp.sec, m.header.stamp.nanosec)] = time.perf_counter_ns()
        pub.publish(m)
        deadline = start + (i + 1) * period
        while True:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                break
            obs.executor.spin_once(timeout_sec=remaining)
    obs.spin_for(1.0)
    load_cpu = (proc_cpu_seconds(node.proc.pid) - c0) / (time.monotonic() - t0) * 100
    load_rss = proc_rss_mb(node.proc.pid)

    lat = sorted((received[k] - t) / 1e6 for k, t in sent.items() if k in received)
    lost = len(sent) - len(lat)
    code = node.stop()
    obs.close()
    lease.release()
    print(f"xyz_target -> servo_angles, {args.rate:g} Hz for {args.seconds:g} s: {len(sent)} sent, {lost} lost")
    print(f"latency ms: p50 {pct(lat, 50):.3f}  p90 {pct(lat, 90):.3f}  p99 {pct(lat, 99):.3f}  max {lat[-1]:.3f}")
    print(f"compute_ik idle: CPU {idle_cpu:.2f} % of a core, RSS {idle_rss:.1f} MB")
    print(f"compute_ik at {args.rate:g} Hz: CPU {load_cpu:.2f} % of a core, RSS {load_rss:.1f} MB; exit code {code}")


if __name__ == "__main__":
    main()
