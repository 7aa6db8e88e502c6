"""A LeRobot v3.0 dataset recorded from the running graph (issue 34): the leader arm's
firmware in simavr (a recorded hand motion on its potentiometers, the deadman held)
drives the follower (serial_node's virtual Arduino) through serial_node in the leader role
and compute_ik; camera_node's test source draws each frame's stamp into its pixels; the
recorder samples them at 30 fps. Two episodes are started, one saved and one discarded,
through the recorder's command line and `ros2 service call`'s service; then the recorder
is killed (SIGKILL) mid-episode, started again, says it discarded the interrupted
episode, and appends one more.

The dataset is read by independent readers: pyarrow (the parquet files) and PyAV (the
MP4s). The verdict is in the stamps the graph carries, never in wall time: the recorder
says where its frame 0 was (the start's answer), each frame k is at frame 0 + k / fps,
and its action must be the leader's joints newest at that instant (the samples the test
heard, stamped by the leader's serial_node), its image one stamped at or before it."""
import json
import math
import os
import re
import subprocess
import time

import av
import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from conftest import REPO, bin_path, latest_status, status_values
from interop.servo_link import SimulatedUno, write_adc_file
from safety_rig import FIRMWARE
from stamp_code import read_code
from test_leader_arm import LEADER_SECTION, MV, record, stamp_ns

# in a process of its own beside the other tests (the leader's simavr and the encoder
# take a core between them)
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=45), pytest.mark.timeout(600)]

ARM = ["base_joint", "shoulder_joint", "elbow_joint", "gripper_joint"]
SHIPPED = (REPO / "config" / "arm.yaml").read_text()
FPS = 30
# one ADC count of the leader calibration (LEADER_SECTION), per joint: 45° over 256 counts
# for the arm's joints; the claw's opening over 800 counts, times its open angle
GRIPPER_OPEN_RAD = yaml.safe_load(SHIPPED)["geometry"]["gripper_open_rad"]
COUNT_RAD = [math.radians(45.0 / 256)] * 3 + [GRIPPER_OPEN_RAD / 800]
CAMERA = "camera/image_raw/compressed"
# a leader stall: no sample heard for this long (its samples come every 10 ms)
STALL_NS = 150_000_000
STALL_WINDOW_NS = 600_000_000  # how far back a frame in a stall may take its sample
WAIT_NS = 500_000_000  # the recorder's longest wait for a live input (recorder_core max_wait)
MAX_STALENESS_S = 0.25  # the recorder's default


def sweep(period_ms, until_ms):
    """The hand motion: the base, the shoulder and the claw swept slowly back and forth,
    the deadman held throughout. Slowly: a count of each in about 8 leader samples (80 ms),
    so that the leader samples a frame may take (the newest at its instant: the recorder
    and the test may each lose one of a burst to their reliable writer's history of 10)
    lie within a count of each other, while an episode of 3 s still spans tens of counts."""
    points = []
    for t in range(0, until_ms + 1, 250):
        phase = (t % period_ms) / period_ms
        tri = 2 * phase if phase < 0.5 else 2 - 2 * phase  # 0 → 1 → 0
        points.append((t, [(0.5 + 0.05 * tri) * MV, (0.5 - 0.05 * tri) * MV, 0.5 * MV, (0.2 + 0.05 * tri) * MV], True))
    return points


class Graph:
    def __init__(self, launch, observer, domain, tmp_path):
        self.launch, self.o, self.domain = launch, observer, domain
        self.root = tmp_path / "dataset"
        config = tmp_path / "arm.yaml"
        config.write_text(SHIPPED + LEADER_SECTION)
        self.config = config
        self.leader_samples = record(observer, "/leader/joint_states", JointState,
                                     lambda m, _: (stamp_ns(m.header), [m.position[list(m.name).index(n)] for n in ARM]))
        self.diags = observer.sub("/diagnostics", DiagnosticArray)
        launch("compute_ik", "--ros-args", "-p", f"arm_config:={config}")
        launch("serial_node", "--ros-args", "-p", "port:=mock", "-p", f"arm_config:={config}")
        launch("camera_node", "--ros-args", "-p", "device:=test", "-p", "width:=320", "-p", "height:=240",
               "-p", f"fps:={FPS}")
        leader_dir = tmp_path / "leader"
        leader_dir.mkdir()
        write_adc_file(leader_dir / "motion.txt", sweep(8000, 600_000))
        self.leader = SimulatedUno(leader_dir, FIRMWARE, adc_file=leader_dir / "motion.txt")
        launch("serial_node", "--ros-args", "-r", "__node:=leader_arm", "-p", "role:=leader",
               "-p", f"port:={self.leader.tty_path}", "-p", f"arm_config:={config}")
        self.recorder = self.start_recorder()

    def start_recorder(self):
        return self.launch("recorder", "--ros-args", "-p", f"root:={self.root}", "-p", f"image_topics:=[{CAMERA}]",
                           "-p", f"arm_config:={self.config}", "-p", "task:=follow the leader")

    def status(self):
        return status_values(latest_status(self.diags, "recorder"))

    def wait_state(self, state, timeout=30):
        assert self.o.spin_until(lambda: self.status().get("state") == state, timeout), self.status()

    def wait_frames(self, episode, frames, timeout=30):
        """Until the recorder reports episode `episode` recording with at least `frames` frames."""
        def enough():
            s = self.status()
            return s.get("state") == "recording" and s.get("episode") == str(episode) and int(s["frames"]) >= frames
        assert self.o.spin_until(enough, timeout), self.status()

    def cli(self, *args):
        """The recorder's command line; (exit status, output)."""
        r = subprocess.run([bin_path("recorder"), *args], capture_output=True, text=True, timeout=60,
                           env={**os.environ, "ROS_DOMAIN_ID": str(self.domain)})
        return r.returncode, (r.stdout + r.stderr).strip()

    def call(self, service):
        """A std_srvs/Trigger service called as `ros2 service call` does (rclpy): (success, message)."""
        client = self.o.node.create_client(Trigger, service)
        try:
            assert client.wait_for_service(timeout_sec=30), f"no {service}"
            future = client.call_async(Trigger.Request())
            assert self.o.spin_until(future.done, 30), f"{service} did not answer"
            return future.result().success, future.result().message
        finally:
            self.o.node.destroy_client(client)

    def close(self):
        if self.leader.proc.poll() is None:
            self.leader.pull_cable()


def grid_drops(saved):
    """The grid frames a save says were dropped (`; dropped grid frames: 41, 42`)."""
    m = re.search(r"dropped grid frames: ([\d, ]+)(…)?", saved)
    if not m:
        return set()
    assert not m.group(2), f"more frames dropped than the recorder lists: {saved}"
    return {int(x) for x in m.group(1).split(",")}


def frame0_ns(answer):
    m = re.search(r"frame 0 at (-?\d+)\.(\d{9})", answer)
    assert m, answer
    return int(m.group(1)) * 1_000_000_000 + int(m.group(2))


def table(paths):
    """The rows of parquet files, as {column: [values]} (pyarrow, without pandas)."""
    cols = {}
    for p in sorted(paths):
        for k, v in pq.read_table(p).to_pydict().items():
            cols.setdefault(k, []).extend(v)
    return cols


def episode_rows(root, index):
    """Episode `index`'s rows in frame order, as {column: [values]}."""
    data = table((root / "data").glob("*/*.parquet"))
    keep = sorted((f, i) for i, (e, f) in enumerate(zip(data["episode_index"], data["frame_index"])) if e == index)
    return {k: [v[i] for _, i in keep] for k, v in data.items()}


def decode(path):
    """[(pts seconds, stamp ns drawn in the frame)] of every frame of an MP4, by PyAV."""
    out = []
    with av.open(str(path)) as c:
        stream = c.streams.video[0]
        for f in c.decode(stream):
            out.append((float(f.pts * stream.time_base), read_code(f.to_image())))
    return out


@pytest.fixture
def graph(launch, observer, domain, tmp_path):
    g = Graph(launch, observer, domain, tmp_path)
    yield g
    g.close()  # the leader's simavr goes with the test


def test_a_dataset_recorded_from_the_running_graph_reads_with_independent_readers(graph, observer):
    g = graph
    g.wait_state("idle", 60)
    assert observer.spin_until(lambda: len(g.leader_samples) > 20, 30), "no leader samples"
    # episode 0: saved (the command line, the task given there)
    code, out = g.cli("start-episode", "--task", "follow the leader slowly")
    assert code == 0, out
    t0 = frame0_ns(out)
    g.wait_frames(0, 3 * FPS)
    code, saved = g.cli("save-episode")
    assert code == 0 and "saved episode 0" in saved, saved
    # frames a busy host made the recorder drop are left out of the rows; the save says
    # which instants of the grid they were
    dropped = grid_drops(saved)
    # episode 1: discarded, through the services as rclpy (ros2 service call) calls them
    ok, out = g.call("/recorder/start_episode")
    assert ok and "recording episode 1" in out, out
    g.wait_frames(1, FPS // 2)
    ok, out = g.call("/recorder/discard_episode")
    assert ok and "discarded episode 1" in out, out
    g.wait_state("idle")
    assert g.status()["episodes"] == "1", g.status()
    # a save with nothing recording is refused, with why
    code, out = g.cli("save-episode")
    assert code == 1 and "no episode" in out, out

    root = g.root
    info = json.loads((root / "meta/info.json").read_text())
    assert (info["codebase_version"], info["robot_type"], info["fps"]) == ("v3.0", "eezybot_mk2", FPS)
    assert info["features"]["action"]["names"] == ARM
    assert info["features"]["observation.state"]["names"] == ARM
    video = info["features"]["observation.images.camera"]
    assert (video["dtype"], video["shape"]) == ("video", [240, 320, 3])
    assert (info["total_episodes"], info["total_tasks"]) == (1, 1)

    rows = episode_rows(root, 0)
    n = len(rows["frame_index"])
    # row k's instant on the grid: the k-th grid frame not dropped
    grid = [i for i in range(n + len(dropped)) if i not in dropped][:n]
    assert n == info["total_frames"] and n >= 3 * FPS
    # on the grid: frame k at k / fps, contiguous
    assert list(rows["frame_index"]) == list(range(n))
    assert np.allclose(rows["timestamp"], np.arange(n) / FPS, atol=1e-6)
    assert list(rows["index"]) == list(range(n))
    # the task
    tasks = pq.read_table(root / "meta/tasks.parquet").to_pydict()
    assert tasks["task"] == ["follow the leader slowly"] and tasks["task_index"] == [0]
    assert set(rows["task_index"]) == {0}
    # the action is the leader's joints newest at each frame's instant, within an ADC count
    # (the deadman was held throughout: the follower followed)
    # A leader stalled (its simavr starved of CPU on a busy host: no samples for a while,
    # then a burst) may deliver a frame's sample after the recorder decided the frame: the
    # frame then has the newest leader joints the recorder had, or compute_ik's command
    # (the leader's joints it followed last). Those frames may take any leader sample of
    # the stall; the others, the newest at their instant. Stalls must be rare, or the check
    # would say little.
    leader = sorted(g.leader_samples)
    stamps = [t for t, _ in leader]
    stalled = 0
    for k, action in enumerate(rows["action"]):
        t_k = t0 + grid[k] * 1_000_000_000 // FPS
        heard = [v for t, v in leader if t <= t_k]
        assert heard, f"frame {k}: no leader sample before it"
        window = [t for t in stamps if t_k - STALL_WINDOW_NS <= t <= t_k + WAIT_NS]
        in_stall = any(b - a >= STALL_NS for a, b in zip(window, window[1:]))
        candidates = [v for t, v in leader if t_k - STALL_WINDOW_NS <= t <= t_k] if in_stall else [heard[-1]]
        err = min(max(abs(a - b) / c for a, b, c in zip(action, v, COUNT_RAD)) for v in candidates or [heard[-1]])
        stalled += in_stall
        if err > 1.0 + 1e-3:
            near = [(t - t_k, round(v[0], 4)) for t, v in leader if abs(t - t_k) < 600_000_000]
            acts = [round(a[0], 4) for a in rows["action"][max(0, k - 8):k + 8]]
            raise AssertionError(f"frame {k}: action {list(action)} vs the leader's {heard[-1]}: {err} counts "
                                 f"(in a stall: {in_stall}); actions {acts}; heard {near}")
    assert stalled <= n // 4, f"the leader stalled around {stalled} of {n} frames"
    span = [(max(a[j] for a in rows["action"]) - min(a[j] for a in rows["action"])) / COUNT_RAD[j] for j in range(4)]
    assert min(span[0], span[1], span[3]) > 10, f"the leader hardly moved during the episode: {span} counts"
    # the follower's state follows (it lags by its motion limits; here only its range)
    state = np.stack(rows["observation.state"])
    assert np.all(np.isfinite(state))

    # the video: one frame per row, at the rows' timestamps, each drawn at or before its
    # frame's instant and at most max_staleness before it, in order
    ep = table((root / "meta/episodes").glob("*/*.parquet"))
    assert ep["episode_index"] == [0] and ep["length"] == [n]
    key = "videos/observation.images.camera"
    mp4 = root / info["video_path"].format(video_key="observation.images.camera",
                                           chunk_index=int(ep[f"{key}/chunk_index"][0]),
                                           file_index=int(ep[f"{key}/file_index"][0]))
    frames = decode(mp4)
    start = float(ep[f"{key}/from_timestamp"][0])
    frames = [(pts - start, code) for pts, code in frames if pts >= start - 1e-6][:n]
    assert len(frames) == n
    last = None
    for k, (pts, code) in enumerate(frames):
        assert abs(pts - k / FPS) < 1e-4, f"frame {k} at {pts}"
        t_k = t0 + grid[k] * 1_000_000_000 // FPS
        assert code <= t_k and t_k - code <= MAX_STALENESS_S * 1e9, f"frame {k}: drawn at {code}, instant {t_k}"
        assert last is None or code >= last
        last = code
    # stats recomputed from the rows
    stats = json.loads((root / "meta/stats.json").read_text())
    for feature in ["action", "observation.state"]:
        v = np.stack(rows[feature]).astype(np.float64)
        s = stats[feature]
        assert np.allclose(s["min"], v.min(axis=0), atol=1e-6)
        assert np.allclose(s["max"], v.max(axis=0), atol=1e-6)
        assert np.allclose(s["mean"], v.mean(axis=0), atol=1e-5)
        assert np.allclose(s["std"], v.std(axis=0), atol=1e-5)
        assert s["count"] == [n]
    image = stats["observation.images.camera"]
    assert np.array(image["mean"]).shape == (3, 1, 1)
    assert 0.0 <= np.array(image["min"]).min() and np.array(image["max"]).max() <= 1.0

    # killed mid-episode, started again: the interrupted episode is discarded and said so;
    # a resumed recording appends episode 1
    code, out = g.cli("start-episode")
    assert code == 0, out
    g.wait_frames(1, FPS)
    g.recorder.kill_hard()
    g.diags.clear()
    g.recorder = g.start_recorder()
    g.wait_state("idle", 60)
    assert "interrupted and is discarded" in g.status()["last"], g.status()
    assert g.status()["episodes"] == "1"
    code, out = g.cli("start-episode")
    assert code == 0 and "recording episode 1" in out, out
    g.wait_frames(1, FPS)
    code, out = g.cli("save-episode")
    assert code == 0 and "saved episode 1" in out, out
    info = json.loads((root / "meta/info.json").read_text())
    assert info["total_episodes"] == 2
    assert episode_rows(root, 0) == rows, "the finished episode is intact"
    assert len(episode_rows(root, 1)["frame_index"]) >= FPS
