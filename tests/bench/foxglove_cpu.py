"""Benchmark: gui_bridge's CPU with one Foxglove client subscribed to every topic while
rclpy sends xyz_target at 50 Hz (compute_ik and state_publisher running, so joint_states,
tf, servo_angles and diagnostics flow too). Reports gui_bridge's CPU (% of one core,
from /proc/PID/stat over the measuring window) and what the client received.

    $EEZYBOT_PYTHON tests/bench/foxglove_cpu.py [--rate 50] [--seconds 20]
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

from geometry_msgs.msg import PointStamped  # noqa: E402

from conftest import DomainLease, NodeProcess, Observer  # noqa: E402
from foxglove_client import FoxgloveClient, free_port  # noqa: E402
from ik_latency import proc_cpu_seconds  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--no-foxglove", action="store_true", help="baseline: foxglove_bind empty, no client")
    args = ap.parse_args()
    lease = DomainLease()
    port, web = free_port(), free_port()
    nodes = [NodeProcess("compute_ik", [], lease.id), NodeProcess("state_publisher", [], lease.id)]
    gui = NodeProcess("gui_bridge", ["--ros-args", "-p", f"bind:=127.0.0.1:{web}",
                                     "-p", "foxglove_bind:=" + ("" if args.no_foxglove else f"127.0.0.1:{port}")],
                     lease.id)
    nodes.append(gui)
    obs = Observer(lease.id, "bench")
    try:
        pub = obs.pub("/xyz_target", PointStamped)
        obs.wait_matched(pub)
        obs.wait_publisher("/joint_states")
        fox = None
        if not args.no_foxglove:
            fox = FoxgloveClient(port)
            assert fox.pump_until(lambda: fox.info and len(fox.channels) >= 12), "no advertise"
            fox.subscribe(*fox.channels)
            fox.pump(1.0)
            fox.received.clear()
        n = int(args.rate * args.seconds)
        c0, t0 = proc_cpu_seconds(gui.proc.pid), time.monotonic()
        for i in range(n):
            m = PointStamped()
            m.header.frame_id = "base_link"
            m.point.x = 0.18 + 0.03 * math.sin(i / 40)
            m.point.y = 0.05 * math.cos(i / 55)
            m.point.z = 0.14 + 0.02 * math.sin(i / 30)
            pub.publish(m)
            # the client reads while we wait for the next period
            wait = max(0.0, t0 + (i + 1) / args.rate - time.monotonic())
            fox.pump(wait) if fox else time.sleep(wait)
        c1, t1 = proc_cpu_seconds(gui.proc.pid), time.monotonic()
        cpu = 100 * (c1 - c0) / (t1 - t0)
        print(f"gui_bridge CPU {cpu:.1f} % of one core over {t1 - t0:.1f} s at {args.rate:.0f} Hz xyz_target"
              + (" (Foxglove off)" if fox is None else ""))
        if fox:
            fox.pump(0.5)
            counts = {k: len(v) for k, v in sorted(fox.received.items())}
            print(f"Foxglove client received: {counts}")
            fox.close()
    finally:
        obs.close()
        for p in reversed(nodes):
            p.stop()
        lease.release()


if __name__ == "__main__":
    main()
