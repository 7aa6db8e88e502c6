"""Benchmark serial_node (release build) against the virtual Arduino behind a pty (the
real serial-port path), or in-process (--mock).

1. 20 Hz servo_angles for 10 s: in-node latency servo_angles taken -> first byte written
   (p50/p99 from its diagnostics), CPU and RSS.
2. 50 Hz for 10 s: CPU and RSS.
3. 1 kHz for 10 s: frames sent per second (must stay at the configured 50), and the age of
   each acknowledged command (publish -> servo_state with its stamp) in the first and in the
   last second: flat if nothing queues.
"""
import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("EEZYBOT_BIN_DIR", str(Path(__file__).resolve().parents[2] / "target" / "release"))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from conftest import DomainLease, NodeProcess, Observer, bin_path  # noqa: E402
from ik_latency import proc_cpu_seconds, proc_rss_mb  # noqa: E402

SERVOS = ["base_servo", "shoulder_servo", "elbow_servo", "gripper_servo"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mock", action="store_true")
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bench(args, tmp)


def bench(args, tmp):
    """The three runs, the virtual Arduino's pty in the directory `tmp`."""
    lease = DomainLease()
    dev = None
    if args.mock:
        port = "mock"
    else:
        port = f"{tmp}/tty"
        dev = subprocess.Popen([bin_path("virtual_arduino"), port], stderr=subprocess.DEVNULL)
        while not os.path.exists(port):
            time.sleep(0.01)
    node = NodeProcess("serial_node", ["--ros-args", "-p", f"port:={port}", "-p", "diagnostics_period:=0.5"], lease.id)
    obs = Observer(lease.id, "bench")
    diags = obs.sub("/diagnostics", DiagnosticArray)
    published = {}
    ages = []
    obs.node.create_subscription(JointState, "/servo_state", lambda m: (
        ages.append((time.perf_counter(), time.perf_counter() - published[(m.header.stamp.sec, m.header.stamp.nanosec)]))
        if (m.header.stamp.sec, m.header.stamp.nanosec) in published else None), 100)
    pub = obs.pub("/servo_angles", JointState)
    obs.wait_matched(pub)
    obs.wait_publisher("/servo_state")
    obs.spin_for(1.0)

    def values():
        return {kv.key: kv.value for kv in diags[-1][1].status[0].values}

    def drive(rate, seconds, tag):
        n = int(rate * seconds)
        c0, t0 = proc_cpu_seconds(node.proc.pid), time.monotonic()
        sent0 = int(values()["frames_sent"])
        start = time.perf_counter()
        for i in range(n):
            m = JointState(name=SERVOS, position=[math.radians(60 + (i % 60)), 1.6, 1.5, 2.0])
            m.header.stamp.sec, m.header.stamp.nanosec = tag, i
            published[(tag, i)] = time.perf_counter()
            pub.publish(m)
            deadline = start + (i + 1) / rate
            while (remaining := deadline - time.perf_counter()) > 0:
                obs.executor.spin_once(timeout_sec=remaining)
        obs.spin_for(1.0)
        elapsed = time.monotonic() - t0
        cpu = (proc_cpu_seconds(node.proc.pid) - c0) / elapsed * 100
        sent = int(values()["frames_sent"]) - sent0
        return n, cpu, sent, start

    n, cpu, sent, _ = drive(20, args.seconds, 1)
    v = values()
    print(f"port {port}: 20 Hz for {args.seconds:g} s: {n} commands, {sent} frames sent")
    print(f"  in-node servo_angles -> first byte written us: p50 {v.get('send_latency_us_p50')}  p99 {v.get('send_latency_us_p99')}")
    print(f"  last round trip (frame written -> STATE read) ms: {v.get('last_rtt_ms')}")
    print(f"  CPU {cpu:.2f} % of a core, RSS {proc_rss_mb(node.proc.pid):.1f} MB")
    n, cpu, sent, _ = drive(50, args.seconds, 2)
    print(f"50 Hz for {args.seconds:g} s: {n} commands, {sent} frames; CPU {cpu:.2f} % of a core, RSS {proc_rss_mb(node.proc.pid):.1f} MB")
    ages.clear()
    n, cpu, sent, start = drive(1000, args.seconds, 3)
    first = [a for t, a in ages if t - start < 1.0]
    last = [a for t, a in ages if args.seconds - 1.0 <= t - start < args.seconds]
    print(f"1 kHz for {args.seconds:g} s: {n} commands, {sent} frames = {sent / args.seconds:.1f} frames/s; CPU {cpu:.2f} %")
    print(f"  command age at its servo_state ms: first second median {statistics.median(first) * 1e3:.2f}, "
          f"last second median {statistics.median(last) * 1e3:.2f} (flat = nothing queues)")
    print(f"  RSS {proc_rss_mb(node.proc.pid):.1f} MB; exit code {node.stop()}")
    obs.close()
    if dev:
        dev.terminate()
        dev.wait()
    lease.release()


if __name__ == "__main__":
    main()
