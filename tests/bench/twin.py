#!/usr/bin/env python3
"""The physics twin at work (issue 35's benchmark): the `twin` node (release build:
EEZYBOT_BIN_DIR) behind serial_node, with its camera at --fps (default 30) and
--width x --height (default 640 x 480), the arm swept between two targets by compute_ik
for --seconds. Measured: the twin's real-time factor (simulated seconds per wall second,
from its diagnostics), the camera frames received a second (an rclpy subscriber) and
those the twin dropped, the twin's CPU (all its threads, % of one core, from /proc) and
its peak RSS; --fps 0 is the headless twin.

    EEZYBOT_BIN_DIR=target/release tests/bench/twin.py --seconds 30 --json out.json
"""
import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PointStamped  # noqa: E402
from sensor_msgs.msg import CompressedImage  # noqa: E402

from benchkit import Launcher  # noqa: E402
from conftest import DomainLease, Observer, latest_status, status_values  # noqa: E402
from recorder import cpu_ticks, rss_kb  # noqa: E402

CLK = os.sysconf("SC_CLK_TCK")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--fps", type=int, default=30)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    lease = DomainLease()
    o = Observer(lease.id)
    diags = o.sub("/diagnostics", DiagnosticArray)
    images = o.sub("/twin/camera/image_raw/compressed", CompressedImage)
    launch = Launcher(lease.id)
    link = Path(tempfile.mkdtemp(prefix="twin-bench-")) / "tty"
    try:
        twin = launch("twin", "--ros-args", "-p", f"link:={link}", "-p", f"camera_fps:={a.fps}",
                      "-p", f"camera_width:={a.width}", "-p", f"camera_height:={a.height}")
        launch("compute_ik")
        launch("serial_node", "--ros-args", "-p", f"port:={link}")
        xyz = o.pub("/xyz_target", PointStamped)
        o.wait_matched(xyz)
        status = lambda name: status_values(latest_status(diags, name))  # noqa: E731
        assert o.spin_until(lambda: status("serial_node").get("connection") == "connected", 60), status("serial_node")
        pid = twin.proc.pid
        n0, c0, t0 = len(images), cpu_ticks(pid), time.monotonic()
        s0 = float(status("twin").get("sim_time_s", "0"))
        peak, side = 0, 1
        while time.monotonic() - t0 < a.seconds:
            m = PointStamped()
            m.header.frame_id = "base_link"
            m.point.x, m.point.y, m.point.z = 0.2, 0.1 * side, 0.15
            xyz.publish(m)
            side = -side
            o.spin_for(1.0)
            peak = max(peak, rss_kb(pid))
        wall = time.monotonic() - t0
        cpu = (cpu_ticks(pid) - c0) / CLK / wall * 100
        v = status("twin")
        sim = float(v.get("sim_time_s", "0")) - s0
        result = {
            "seconds": round(wall, 1), "fps_asked": a.fps, "size": [a.width, a.height],
            "real_time_factor": round(sim / wall, 3) if sim > 0 else None,
            "frames_per_s": round((len(images) - n0) / wall, 2),
            "camera_dropped": int(v.get("camera_dropped", "0")),
            "twin_cpu_pct": round(cpu, 1), "twin_peak_rss_mb": round(peak / 1024, 1),
            "loop_error_mm": float(v.get("loop_error_mm", "nan")),
        }
        print(json.dumps(result))
        if a.json:
            a.json.write_text(json.dumps(result, indent=1) + "\n")
    finally:
        launch.stop()
        lease.release()


if __name__ == "__main__":
    main()
