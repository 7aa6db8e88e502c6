"""libs/lerobot_dataset's files read by an independent reader (pyarrow and numpy, no
lerobot): the dataset written by its `write_demo` example (2 episodes saved, 1
discarded), then the example killed with SIGKILL in the middle of an episode and the
dataset resumed. Checked: info.json's totals and features, the frames (count, indices,
timestamps on the 1/fps grid), tasks.parquet's pandas index metadata and tasks, the
episodes table, and every statistic recomputed with numpy as lerobot 0.6.1 computes it
(`compute_stats.py`: histogram quantiles per episode, count-weighted aggregation)."""
import json
import signal
import subprocess
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from conftest import bin_path

FPS = 30
JOINTS = ["base_joint", "shoulder_joint", "elbow_joint", "gripper_joint"]
FEATURES = ["observation.state", "action", "timestamp", "frame_index", "episode_index", "index", "task_index"]
QUANTILES = [(0.01, "q01"), (0.10, "q10"), (0.50, "q50"), (0.90, "q90"), (0.99, "q99")]


def demo(*args, timeout=30):
    return subprocess.run([str(bin_path("examples/write_demo")), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, check=True).stdout


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
        for q, k in QUANTILES:
            vals = []
            for d in range(x.shape[1]):
                edges = np.linspace(x[:, d].min() - 1e-10, x[:, d].max() + 1e-10, 5001)
                hist, _ = np.histogram(x[:, d], bins=edges)
                cumsum = np.cumsum(hist)
                target = q * n
                idx = np.searchsorted(cumsum, target)
                if idx == 0:
                    v = edges[0]
                elif idx >= len(cumsum):
                    v = edges[-1]
                else:
                    before, in_bin = cumsum[idx - 1], cumsum[idx] - cumsum[idx - 1]
                    v = edges[idx] if in_bin == 0 else edges[idx] + (target - before) / in_bin * (edges[idx + 1] - edges[idx])
                vals.append(v)
            out[k] = np.array(vals)
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


def test_written_dataset_reads(tmp_path):
    root = tmp_path / "ds"
    out = demo(root)
    assert "WROTE 2 episodes, 135 frames" in out, out
    check_dataset(root, [90, 45], ["pick up the cube", "wave"])


def test_kill_mid_episode_then_resume(tmp_path):
    root = tmp_path / "ds"
    demo(root)
    finished = {p: p.read_bytes() for p in (root / "data").rglob("*.parquet")}
    proc = subprocess.Popen([str(bin_path("examples/write_demo")), str(root), "--stop-mid-episode"],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "IN_EPISODE"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL
    # killed mid-episode: the dataset is the two finished episodes, as they were
    check_dataset(root, [90, 45], ["pick up the cube", "wave"])
    assert {p: p.read_bytes() for p in (root / "data").rglob("*.parquet")} == finished

    out = demo(root, "--resume")
    recovery = json.loads(next(line for line in out.splitlines() if line.startswith("RECOVERY"))[len("RECOVERY "):])
    assert recovery["interrupted"] == {"episode_index": 2, "task": "interrupted", "frames": 20}, recovery
    assert "WROTE 3 episodes, 195 frames" in out, out
    data = check_dataset(root, [90, 45, 60], ["pick up the cube", "wave", "pick up the cube"])
    # resumed into a new data file, as lerobot's resume does
    assert sorted(p.name for p in (root / "data/chunk-000").iterdir()) == ["file-000.parquet", "file-001.parquet"]
    assert data.num_rows == 195
    assert not Path(root / ".recording/episode.jsonl").exists()
