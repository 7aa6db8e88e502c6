"""An episode recorded with the physics twin's camera (issue 35): the twin behind serial_node
(`port:=` its link), compute_ik, and the recorder taking `twin/camera/image_raw/compressed`
as it takes a webcam's. The arm moves during the episode; the dataset is read by
independent readers, pyarrow (the parquet files) and PyAV (the MP4): the twin's camera is
`observation.images.twin_camera`, one decoded frame per dataset frame, and the pictures
show the arm moving. (lerobot 0.6.1 itself loads such a folder: tests/lerobot_load.py DIR,
by hand in its 5.4 GB venv, on the dataset this test leaves in $EEZYBOT_KEEP_DATASETS when
that is set; BENCHMARKS.md has the run.)"""
import json
import os
import shutil
import subprocess
from pathlib import Path

import av
import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped

from conftest import bin_path, latest_status, status_values
from test_recorder import episode_rows

# in a process of its own beside the other tests (the AV1 encoder takes most of a core)
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=30), pytest.mark.timeout(600)]

CAMERA = "twin/camera/image_raw/compressed"
W, H = 320, 240


def test_an_episode_with_the_twin_camera_reads_as_a_lerobot_dataset(launch, observer, domain, tmp_path):
    root = tmp_path / "dataset"
    link = tmp_path / "twin.tty"
    diags = observer.sub("/diagnostics", DiagnosticArray)
    launch("twin", "--ros-args", "-p", f"link:={link}", "-p", f"camera_width:={W}", "-p", f"camera_height:={H}")
    launch("compute_ik")
    launch("serial_node", "--ros-args", "-p", f"port:={link}")
    launch("recorder", "--ros-args", "-p", f"root:={root}", "-p", f"image_topics:=[{CAMERA}]",
           "-p", "task:=reach over the cube")
    xyz = observer.pub("/xyz_target", PointStamped)
    observer.wait_matched(xyz)

    def status(name):
        return status_values(latest_status(diags, name))
    assert observer.spin_until(lambda: status("serial_node").get("connection") == "connected", 30), status("serial_node")
    assert observer.spin_until(lambda: status("recorder").get("state") == "idle", 30), status("recorder")

    def cli(*args):
        r = subprocess.run([bin_path("recorder"), *args], capture_output=True, text=True, timeout=60,
                           env={**os.environ, "ROS_DOMAIN_ID": str(domain)})
        return r.returncode, (r.stdout + r.stderr).strip()
    code, out = cli("start-episode")
    assert code == 0, out

    def frames():
        s = status("recorder")
        return int(s["frames"]) if s.get("state") == "recording" else 0
    # a reach to the left, then to the right, while it records
    for i, y in enumerate((0.1, -0.1)):
        target = PointStamped()
        target.header.frame_id = "base_link"
        target.point.x, target.point.y, target.point.z = 0.2, y, 0.15
        xyz.publish(target)
        assert observer.spin_until(lambda: frames() >= 45 * (i + 1), 30), status("recorder")
    code, out = cli("save-episode")
    assert code == 0, out

    info = json.loads((root / "meta" / "info.json").read_text())
    feature = info["features"]["observation.images.twin_camera"]
    assert feature["dtype"] == "video" and feature["shape"] == [H, W, 3], feature
    assert info["total_episodes"] == 1
    rows = episode_rows(root, 0)
    n = len(rows["frame_index"])
    assert n == info["total_frames"] and n >= 90
    videos = sorted((root / "videos" / "observation.images.twin_camera").glob("*/*.mp4"))
    assert videos, "no video"
    with av.open(str(videos[0])) as c:
        pictures = [f.to_ndarray(format="rgb24") for f in c.decode(c.streams.video[0])]
    assert len(pictures) == n and pictures[0].shape == (H, W, 3)
    # the arm moved in the camera's view: the first and last pictures differ well beyond
    # the encoder's noise, and the base joint moved in the recorded state
    assert np.abs(pictures[0].astype(int) - pictures[-1].astype(int)).mean() > 2.0
    base = [s[0] for s in rows["observation.state"]]
    assert max(base) - min(base) > 0.3
    if os.environ.get("EEZYBOT_KEEP_DATASETS"):
        shutil.copytree(root, Path(os.environ["EEZYBOT_KEEP_DATASETS"]) / "test_twin_record", dirs_exist_ok=True)
