"""libs/lerobot_dataset's files read by an independent reader (pyarrow, numpy and PyAV,
no lerobot): the dataset written by its `write_demo` example (2 episodes saved, 1
discarded), then the example killed with SIGKILL in the middle of an episode and the
dataset resumed; each without and with the demo's two cameras (a JPEG one and a raw bgr8
one). Checked: info.json's totals and features, the frames (count, indices, timestamps
on the 1/fps grid), tasks.parquet's pandas index metadata and tasks, the episodes table,
and every statistic recomputed with numpy as lerobot 0.6.1 computes it
(`compute_stats.py`: histogram quantiles per episode, count-weighted aggregation). With
cameras: every video frame decoded by PyAV (count == rows, pts == the episode's
from_timestamp + timestamp, each quadrant the colour write_demo drew), info.json's video
features, the episodes table's video columns, the image stats recomputed from the frames
given."""
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import av
import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import bin_path

# in a process of its own beside the other tests (judged by order and content, not the wall clock)
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=15)]

FPS = 30
JOINTS = ["base_joint", "shoulder_joint", "elbow_joint", "gripper_joint"]
FEATURES = ["observation.state", "action", "timestamp", "frame_index", "episode_index", "index", "task_index"]
QUANTILES = [(0.01, "q01"), (0.10, "q10"), (0.50, "q50"), (0.90, "q90"), (0.99, "q99")]


def demo(*args, timeout=30):
    return subprocess.run([str(bin_path("examples/write_demo")), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, check=True).stdout


# write_demo's cameras: key -> (camera number in colour(), height, width)
CAMERAS = {"observation.images.front": (0, 240, 320), "observation.images.wrist": (1, 120, 160)}
VIDEO_INFO = {"is_depth_map": False, "video.codec": "av1", "video.pix_fmt": "yuv420p", "video.fps": FPS,
              "video.channels": 3, "has_audio": False, "video.g": 2, "video.crf": 30, "video.preset": 12,
              "video.fast_decode": 0, "video.video_backend": "pyav", "video.extra_options": {}}
# JPEG (front) and AV1 at CRF 30, solid quadrants: a quadrant's centre within 8 levels
COLOUR_TOLERANCE = 8


def colour(index, q, camera):
    """write_demo's colour of quadrant q (0 top left … 3 bottom right) of the frame with
    dataset index `index`."""
    k = index * 4 + q + camera * 2
    return np.array([(37 * k + 40) % 216 + 20, (91 * k + 10) % 216 + 20, (53 * k + 90) % 216 + 20])


def pattern(index, camera, h, w):
    """The frame write_demo gave, (h, w, 3) uint8."""
    img = np.empty((h, w, 3), dtype=np.uint8)
    for q, (ys, xs) in enumerate([(slice(0, h // 2), slice(0, w // 2)), (slice(0, h // 2), slice(w // 2, w)),
                                  (slice(h // 2, h), slice(0, w // 2)), (slice(h // 2, h), slice(w // 2, w))]):
        img[ys, xs] = colour(index, q, camera)
    return img


def sample_indices(n):
    """lerobot's estimate_num_samples and sample_indices."""
    num = max(min(100, n), min(int(n ** 0.75), 10_000))
    return np.round(np.linspace(0, n - 1, num)).astype(int).tolist()


def downsample(img_chw):
    """lerobot's auto_downsample_height_width."""
    _, h, w = img_chw.shape
    if max(w, h) < 300:
        return img_chw
    f = int(w / 150) if w > h else int(h / 150)
    return img_chw[:, ::f, ::f]


def image_stats(frames):
    """lerobot's compute_episode_stats for a video feature: the sampled frames,
    downsampled, per channel, / 255; count = frames sampled."""
    idx = sample_indices(len(frames))
    imgs = np.stack([downsample(frames[i].transpose(2, 0, 1)) for i in idx])
    pixels = imgs.transpose(0, 2, 3, 1).reshape(-1, 3).astype(np.float32)  # uint8 promoted
    st = lerobot_feature_stats(pixels)
    out = {k: v / 255 for k, v in st.items() if k != "count"}
    out["count"] = np.array([len(idx)])
    return out


def check_videos(root, lengths):
    """The cameras' videos decoded with PyAV against the rows and write_demo's frames."""
    info, data, episodes, _, stats = read_dataset(root)
    assert info["video_path"] == "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    assert list(info["features"])[2:4] == list(CAMERAS)
    starts = np.cumsum([0] + lengths)
    index = data.column("index").to_numpy()
    timestamps = data.column("timestamp").to_numpy()
    for key, (camera, h, w) in CAMERAS.items():
        feature = info["features"][key]
        assert {k: feature[k] for k in ("dtype", "shape", "names")} == {
            "dtype": "video", "shape": [h, w, 3], "names": ["height", "width", "channels"]}
        assert feature["info"] == {**VIDEO_INFO, "video.height": h, "video.width": w}, feature["info"]
        col = lambda name: episodes.column(f"videos/{key}/{name}").to_pylist()  # noqa: E731
        assert str(episodes.schema.field(f"videos/{key}/from_timestamp").type) == "double"
        # decode every file of the camera once
        decoded = {}
        for chunk, file in sorted(set(zip(col("chunk_index"), col("file_index")))):
            path = root / f"videos/{key}/chunk-{chunk:03d}/file-{file:03d}.mp4"
            with av.open(str(path)) as container:
                stream = container.streams.video[0]
                assert stream.codec_context.name in ("libdav1d", "av1", "libaom-av1"), stream.codec_context.name
                decoded[(chunk, file)] = [(float(f.pts * stream.time_base), f.to_ndarray(format="rgb24"))
                                          for f in container.decode(stream)]
        per_episode = []
        for e, length in enumerate(lengths):
            frames = decoded[(col("chunk_index")[e], col("file_index")[e])]
            start, end = col("from_timestamp")[e], col("to_timestamp")[e]
            assert abs(end - start - length / FPS) < 1e-9, (key, e, start, end)
            mine = [(t, img) for t, img in frames if start - 1e-6 <= t < end - 1e-6]
            assert len(mine) == length, (key, e, len(mine), length)
            given = []
            for k, (t, img) in enumerate(mine):
                row = starts[e] + k
                # the frame lerobot asks for: from_timestamp + the row's timestamp
                assert abs(t - (start + float(timestamps[row]))) < 1e-6, (key, e, k, t, start, timestamps[row])
                assert img.shape == (h, w, 3)
                for q, (y, x) in enumerate([(h // 4, w // 4), (h // 4, 3 * w // 4),
                                            (3 * h // 4, w // 4), (3 * h // 4, 3 * w // 4)]):
                    want = colour(int(index[row]), q, camera)
                    diff = np.abs(img[y, x].astype(int) - want).max()
                    assert diff <= COLOUR_TOLERANCE, (key, e, k, q, img[y, x], want)
                given.append(pattern(int(index[row]), camera, h, w))
            # the image stats from the frames given: exact for the raw camera (its pixels
            # reach the counts unchanged), within the JPEG's loss for the other
            mine = image_stats(given)
            per_episode.append(mine)
            tol = 1e-6 if key.endswith("wrist") else 3 / 255
            for k, v in mine.items():
                stored = np.array(episodes.column(f"stats/{key}/{k}")[e].as_py())
                want_shape = (1,) if k == "count" else (3, 1, 1)
                assert stored.shape == want_shape, (key, k, stored.shape)
                assert np.allclose(stored.ravel(), v, rtol=0, atol=tol), (key, e, k, stored.ravel(), v)
        agg = aggregate(per_episode)
        tol = 1e-6 if key.endswith("wrist") else 3 / 255
        for k, v in agg.items():
            assert np.allclose(np.array(stats[key][k]).ravel(), v, rtol=0, atol=tol), (key, k, stats[key][k], v)


def ffmpeg_running(root):
    """ffmpeg processes working on `root` (their command line names it)."""
    found = []
    for pid in os.listdir("/proc"):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if cmd and cmd[0].endswith(b"ffmpeg") and any(str(root).encode() in a for a in cmd):
            found.append(int(pid))
    return found


def lerobot_feature_stats(x):
    """lerobot's get_feature_stats(x, axis=0) for x of shape (frames, dims): the moments in
    float64; the histogram quantiles in x's own precision, as lerobot (float32 features get
    float32 bin edges: NumPy 2 keeps `float32 - 1e-10` in float32), int64 in float64."""
    if x.dtype != np.float32:
        x = x.astype(np.float64)
    n = x.shape[0]
    x64 = x.astype(np.float64)
    out = {"min": x64.min(0), "max": x64.max(0), "mean": x64.mean(0)}
    if n < 2:
        out["std"] = x64.std(0)
        out.update({k: out["mean"].copy() for _, k in QUANTILES})
    else:
        out["std"] = np.sqrt(np.maximum(0, (x64 ** 2).mean(0) - out["mean"] ** 2))
        vals = {k: [] for _, k in QUANTILES}
        for d in range(x.shape[1]):
            edges = np.linspace(x[:, d].min() - 1e-10, x[:, d].max() + 1e-10, 5001)
            hist, _ = np.histogram(x[:, d], bins=edges)
            cumsum = np.cumsum(hist)
            for q, k in QUANTILES:
                target = q * n
                idx = np.searchsorted(cumsum, target)
                if idx == 0:
                    v = edges[0]
                elif idx >= len(cumsum):
                    v = edges[-1]
                else:
                    before, in_bin = cumsum[idx - 1], cumsum[idx] - cumsum[idx - 1]
                    v = edges[idx] if in_bin == 0 else edges[idx] + (target - before) / in_bin * (edges[idx + 1] - edges[idx])
                vals[k].append(v)
        out.update({k: np.array(v) for k, v in vals.items()})
    out["count"] = np.array([n])
    return out


def aggregate(parts):
    """lerobot's aggregate_feature_stats."""
    counts = np.array([p["count"][0] for p in parts], dtype=np.float64)
    total = counts.sum()
    means = np.stack([p["mean"] for p in parts])
    mean = (means * counts[:, None]).sum(0) / total
    var = ((np.stack([p["std"] ** 2 for p in parts]) + (means - mean) ** 2) * counts[:, None]).sum(0) / total
    out = {"min": np.stack([p["min"] for p in parts]).min(0), "max": np.stack([p["max"] for p in parts]).max(0),
           "mean": mean, "std": np.sqrt(var), "count": np.array([int(total)])}
    for _, k in QUANTILES:
        out[k] = (np.stack([p[k] for p in parts]) * counts[:, None]).sum(0) / total
    return out


def columns(table):
    """Each feature as an array of its stored dtype, shape (frames, dims)."""
    out = {}
    for name in FEATURES:
        col = table.column(name).combine_chunks()
        if name in ("observation.state", "action"):
            out[name] = np.asarray(col.flatten()).reshape(len(col), -1)
        else:
            out[name] = np.asarray(col).reshape(-1, 1)
    return out


def read_dataset(root):
    info = json.loads((root / "meta/info.json").read_text())
    data = pq.read_table(sorted(str(p) for p in (root / "data").glob("*/*.parquet")))
    episodes = pq.read_table(sorted(str(p) for p in (root / "meta/episodes").glob("*/*.parquet")))
    tasks_file = pq.read_table(root / "meta/tasks.parquet")
    stats = json.loads((root / "meta/stats.json").read_text())
    return info, data, episodes, tasks_file, stats


def check_dataset(root, lengths, tasks_by_episode):
    info, data, episodes, tasks_file, stats = read_dataset(root)
    n = sum(lengths)
    assert info["codebase_version"] == "v3.0" and info["fps"] == FPS
    assert info["robot_type"] == "eezybot_mk2"
    assert (info["total_episodes"], info["total_frames"]) == (len(lengths), n)
    assert info["splits"] == {"train": f"0:{len(lengths)}"}
    assert info["features"]["observation.state"] == {"dtype": "float32", "shape": [4], "names": JOINTS}
    assert info["features"]["timestamp"] == {"dtype": "float32", "shape": [1], "names": None}

    # the data: types as lerobot writes them, frames on the grid
    assert str(data.schema.field("observation.state").type) == "fixed_size_list<item: float>[4]"
    assert str(data.schema.field("timestamp").type) == "float"
    assert str(data.schema.field("index").type) == "int64"
    assert data.num_rows == n
    cols = columns(data)
    assert (cols["index"][:, 0] == np.arange(n)).all()
    assert cols["observation.state"].dtype == np.float32 and cols["index"].dtype == np.int64
    ep = cols["episode_index"][:, 0].astype(int)
    fi = cols["frame_index"][:, 0].astype(int)
    starts = np.cumsum([0] + lengths)
    for e, length in enumerate(lengths):
        assert (ep[starts[e]:starts[e + 1]] == e).all()
        assert (fi[starts[e]:starts[e + 1]] == np.arange(length)).all()
    ts = data.column("timestamp").to_numpy()
    assert np.array_equal(ts, (fi / FPS).astype(np.float32)), "timestamps on the 1/fps grid"

    # tasks: the task string is pandas' index (the metadata lerobot's loader needs)
    pandas_md = json.loads(tasks_file.schema.metadata[b"pandas"])
    assert pandas_md["index_columns"] == ["task"]
    tasks = dict(zip(tasks_file.column("task").to_pylist(), tasks_file.column("task_index").to_pylist()))
    assert info["total_tasks"] == len(tasks)
    ti = cols["task_index"][:, 0].astype(int)
    for e, task in enumerate(tasks_by_episode):
        assert (ti[starts[e]:starts[e + 1]] == tasks[task]).all()

    # the episodes table
    assert episodes.column("episode_index").to_pylist() == list(range(len(lengths)))
    assert episodes.column("length").to_pylist() == lengths
    assert episodes.column("tasks").to_pylist() == [[t] for t in tasks_by_episode]
    assert episodes.column("dataset_from_index").to_pylist() == list(starts[:-1])
    assert episodes.column("dataset_to_index").to_pylist() == list(starts[1:])

    # the stats, recomputed: per episode (the episodes table), then aggregated (stats.json)
    for name in FEATURES:
        per_episode = []
        for e in range(len(lengths)):
            mine = lerobot_feature_stats(cols[name][starts[e]:starts[e + 1]])
            per_episode.append(mine)
            for k, v in mine.items():
                stored = np.array(episodes.column(f"stats/{name}/{k}")[e].as_py())
                assert np.allclose(stored, v, rtol=0, atol=1e-6), (name, e, k, stored, v)
        agg = aggregate(per_episode)
        for k, v in agg.items():
            assert np.allclose(np.array(stats[name][k]), v, rtol=0, atol=1e-6), (name, k, stats[name][k], v)
        # and the moments equal those of the whole data
        assert np.allclose(stats[name]["mean"], cols[name].astype(np.float64).mean(0), atol=1e-6)
        assert np.allclose(stats[name]["std"], cols[name].astype(np.float64).std(0), atol=1e-6)
    return data


@pytest.mark.parametrize("cameras", [False, True], ids=["no_camera", "cameras"])
def test_written_dataset_reads(tmp_path, cameras):
    root = tmp_path / "ds"
    flags = ["--cameras"] if cameras else []
    out = demo(root, *flags)
    assert "WROTE 2 episodes, 135 frames" in out, out
    check_dataset(root, [90, 45], ["pick up the cube", "wave"])
    if cameras:
        check_videos(root, [90, 45])
        # both episodes appended to one file per camera
        assert sorted(p.relative_to(root).as_posix() for p in (root / "videos").rglob("*") if p.is_file()) == [
            f"videos/{k}/chunk-000/file-000.mp4" for k in CAMERAS]
    else:
        assert not (root / "videos").exists()
    assert sorted((root / ".recording").iterdir()) == []


@pytest.mark.parametrize("cameras", [False, True], ids=["no_camera", "cameras"])
def test_kill_mid_episode_then_resume(tmp_path, cameras):
    root = tmp_path / "ds"
    flags = ["--cameras"] if cameras else []
    demo(root, *flags)
    finished = {p: p.read_bytes() for p in (root / "data").rglob("*.parquet")}
    finished_videos = {p: p.read_bytes() for p in (root / "videos").rglob("*.mp4")}
    proc = subprocess.Popen([str(bin_path("examples/write_demo")), str(root), "--stop-mid-episode", *flags],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "IN_EPISODE"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL
    if cameras:
        # the killed writer's ffmpeg see their input end and exit by themselves
        deadline = time.monotonic() + 10
        while ffmpeg_running(root) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert ffmpeg_running(root) == []
        assert any(p.name.startswith("observation.images.") for p in (root / ".recording").iterdir())
    # killed mid-episode: the dataset is the two finished episodes, as they were
    check_dataset(root, [90, 45], ["pick up the cube", "wave"])
    assert {p: p.read_bytes() for p in (root / "data").rglob("*.parquet")} == finished
    assert {p: p.read_bytes() for p in (root / "videos").rglob("*.mp4")} == finished_videos

    out = demo(root, "--resume", *flags)
    recovery = json.loads(next(line for line in out.splitlines() if line.startswith("RECOVERY"))[len("RECOVERY "):])
    assert recovery["interrupted"] == {"episode_index": 2, "task": "interrupted", "frames": 20}, recovery
    if cameras:
        # the interrupted episode's camera files, removed and named
        assert {f".recording/{k}.counts" for k in CAMERAS} <= set(recovery["removed_episode_files"]), recovery
    else:
        assert recovery["removed_episode_files"] == []
    assert "WROTE 3 episodes, 195 frames" in out, out
    data = check_dataset(root, [90, 45, 60], ["pick up the cube", "wave", "pick up the cube"])
    # resumed into a new data file, as lerobot's resume does
    assert sorted(p.name for p in (root / "data/chunk-000").iterdir()) == ["file-000.parquet", "file-001.parquet"]
    assert data.num_rows == 195
    assert sorted((root / ".recording").iterdir()) == []
    if cameras:
        # and each camera into a new video file
        for k in CAMERAS:
            assert sorted(p.name for p in (root / f"videos/{k}/chunk-000").iterdir()) == ["file-000.mp4", "file-001.mp4"]
        check_videos(root, [90, 45, 60])
