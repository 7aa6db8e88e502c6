#!/usr/bin/env python3
"""The recorder at work (issue 34's benchmark): the graph with one camera (camera_node's
test source, 640x480 at 30 fps unless told otherwise), serial_node's virtual Arduino,
compute_ik and the recorder; episodes of --seconds each are recorded and saved. Measured,
per episode: the recorder's CPU (its own threads, % of one core, from /proc: utime +
stime over the episode) and its peak RSS; the encoder's CPU (the recorder's ffmpeg
children, separately); frames made and dropped (the recorder's diagnostics); the
dataset's growth (bytes per minute of episode); and the time from the save request to
the saved answer (the command line's round trip, and the writer's own figure).

    tests/bench/recorder.py --episodes 3 --seconds 60 --json out.json
    tests/bench/recorder.py --cameras 0   # no camera: the recorder without video
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402

from benchkit import Launcher  # noqa: E402
from conftest import DomainLease, Observer, bin_path, latest_status, status_values  # noqa: E402

CLK = os.sysconf("SC_CLK_TCK")


def cpu_ticks(pid):
    """utime + stime of a process (its threads), in clock ticks."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])


def rss_kb(pid):
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def children(pid):
    """The pids of a process's children, whichever of its threads started them (the
    recorder's ffmpeg encoders are the writer thread's)."""
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return out


def tree_size(root):
    return sum(p.stat().st_size for p in Path(root).rglob("*") if p.is_file())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episodes", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--cameras", type=int, default=1, choices=[0, 1])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--fps", type=int, default=30)
    ap.add_argument("--root", type=Path, default=None)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    root = a.root or Path(f"/tmp/recorder-bench-{int(time.time())}")
    shutil.rmtree(root, ignore_errors=True)
    lease = DomainLease()
    o = Observer(lease.id)
    diags = o.sub("/diagnostics", DiagnosticArray)
    launch = Launcher(lease.id)
    env = {**os.environ, "ROS_DOMAIN_ID": str(lease.id)}
    out = []
    try:
        launch("serial_node", "--ros-args", "-p", "port:=mock")
        launch("compute_ik")
        topics = []
        if a.cameras:
            launch("camera_node", "--ros-args", "-p", "device:=test", "-p", f"width:={a.width}",
                   "-p", f"height:={a.height}", "-p", f"fps:={a.fps}")
            topics = ["camera/image_raw/compressed"]
        rec = launch("recorder", "--ros-args", "-p", f"root:={root}", "-p", f"fps:={a.fps}",
                     "-p", f"image_topics:=[{','.join(topics)}]")
        status = lambda: status_values(latest_status(diags, "recorder"))  # noqa: E731
        assert o.spin_until(lambda: status().get("state") == "idle", 60), status()
        pid = rec.proc.pid
        for ep in range(a.episodes):
            size0 = tree_size(root)
            r = subprocess.run([bin_path("recorder"), "start-episode", "--task", f"bench {ep}"], env=env,
                               capture_output=True, text=True, timeout=60)
            assert r.returncode == 0, r.stdout + r.stderr
            t0, c0 = time.monotonic(), cpu_ticks(pid)
            enc0 = {c: cpu_ticks(c) for c in children(pid)}
            peak = 0
            while time.monotonic() - t0 < a.seconds:
                o.spin_for(0.5)
                peak = max(peak, rss_kb(pid))
                for c in children(pid):
                    enc0.setdefault(c, 0)
            enc = sum(cpu_ticks(c) - t for c, t in enc0.items() if Path(f"/proc/{c}").exists())
            elapsed, c1 = time.monotonic() - t0, cpu_ticks(pid)
            st = status()
            t = time.monotonic()
            r = subprocess.run([bin_path("recorder"), "save-episode"], env=env, capture_output=True, text=True,
                               timeout=120)
            save_s = time.monotonic() - t
            assert r.returncode == 0, r.stdout + r.stderr
            m = re.search(r"saved episode \d+ \((\d+) frames, [\d.]+ s, (\d+) dropped\) in (\d+) ms", r.stdout)
            frames, dropped, writer_ms = (int(m.group(1)), int(m.group(2)), int(m.group(3))) if m else (None, None, None)
            grown = tree_size(root) - size0
            row = {"episode": ep, "seconds": round(elapsed, 1), "recorder_cpu_pct": round(100 * (c1 - c0) / CLK / elapsed, 1),
                   "encoder_cpu_pct": round(100 * enc / CLK / elapsed, 1), "recorder_rss_mb": round(peak / 1024, 1),
                   "frames": frames, "dropped": dropped, "dropped_during": int(st.get("dropped", 0)),
                   "bytes_per_min": int(grown / elapsed * 60), "stop_to_saved_s": round(save_s, 3),
                   "writer_save_ms": writer_ms}
            print(json.dumps(row), flush=True)
            out.append(row)
    finally:
        launch.stop()
        o.close()
        lease.release()
    if a.json:
        a.json.write_text(json.dumps({"date": time.strftime("%Y-%m-%d"), "args": {k: str(v) for k, v in vars(a).items()},
                                      "episodes": out}, indent=1))


if __name__ == "__main__":
    main()
