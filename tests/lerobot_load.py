"""Loads a dataset written by libs/lerobot_dataset with lerobot 0.6.1's own loader,
offline: every frame, the tasks, the stats, and action chunks through `delta_timestamps`.
Not in the test command (lerobot's venv is 5.4 GB): run it by hand in that venv.

    python3.12 -m venv ~/.cache/eezybot/lerobot-venv
    ~/.cache/eezybot/lerobot-venv/bin/pip install "lerobot[dataset]==0.6.1"
    cargo build -p lerobot_dataset --examples
    ~/.cache/eezybot/lerobot-venv/bin/python tests/lerobot_load.py [DIR]

Without DIR it writes one with `write_demo` (target/debug/examples, or
EEZYBOT_BIN_DIR/examples) in a temporary folder; `--cameras` (with or without DIR) has it
write the demo's two cameras too. With cameras, every frame's decoded images are checked
against the demo's pattern (four quadrants of `colour(index, quadrant, camera)`, as
write_demo draws them). Exits non-zero on any mismatch.
The stats tolerances (absolute) are for joint angles in radians: for values near 1e6
lerobot's float32 mean is itself off by more than 1e-6.

On this machine lerobot prints a long torchcodec traceback (FFmpeg's shared libraries
are not installed) and falls back to PyAV, which decodes the AV1 videos (its wheel
bundles libdav1d).
"""
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ["HF_HUB_OFFLINE"] = "1"

import numpy as np  # noqa: E402
import torch  # noqa: E402
from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402

CHUNK = 10
# the demo's cameras: feature -> (camera number in colour(), height, width)
DEMO_CAMERAS = {"observation.images.front": (0, 240, 320), "observation.images.wrist": (1, 120, 160)}
# JPEG (front) and AV1 at CRF 30 on solid quadrants: the centre of a quadrant within this
# many levels of 255
COLOUR_TOLERANCE = 8


def colour(index, q, camera):
    """write_demo's colour of quadrant q of the frame with dataset index `index`."""
    k = index * 4 + q + camera * 2
    return np.array([(37 * k + 40) % 216 + 20, (91 * k + 10) % 216 + 20, (53 * k + 90) % 216 + 20])


def stamp_of(img):
    """The stamp camera_node's test source drew into a decoded frame (float (3, h, w))."""
    from PIL import Image

    from stamp_code import read_code
    pixels = (img.permute(1, 2, 0).numpy() * 255).round().clip(0, 255).astype(np.uint8)
    return read_code(Image.fromarray(pixels))


def check_image(key, index, img, shape=None):
    """img: lerobot's decoded frame, float (3, h, w) in [0, 1]. A demo camera's quadrants
    are checked against their colours (returns the worst difference); another camera's
    frame only for its shape and range (returns 0)."""
    if key not in DEMO_CAMERAS:
        assert tuple(img.shape) == (3, *shape), (key, img.shape, shape)
        assert 0.0 <= float(img.min()) and float(img.max()) <= 1.0
        return 0.0
    camera, h, w = DEMO_CAMERAS[key]
    assert tuple(img.shape) == (3, h, w), (key, img.shape)
    worst = 0.0
    for q, (y, x) in enumerate([(h // 4, w // 4), (h // 4, 3 * w // 4), (3 * h // 4, w // 4), (3 * h // 4, 3 * w // 4)]):
        got = img[:, y, x].numpy() * 255
        diff = float(np.max(np.abs(got - colour(index, q, camera))))
        assert diff <= COLOUR_TOLERANCE, (key, index, q, got, colour(index, q, camera))
        worst = max(worst, diff)
    return worst


def main():
    args = [a for a in sys.argv[1:] if a != "--cameras"]
    if args:
        root = Path(args[0])
    else:
        bin_dir = Path(os.environ.get("EEZYBOT_BIN_DIR", Path(__file__).resolve().parents[1] / "target" / "debug"))
        root = Path(tempfile.mkdtemp()) / "ds"
        extra = ["--cameras"] if "--cameras" in sys.argv else []
        subprocess.run([str(bin_dir / "examples" / "write_demo"), str(root), *extra], check=True)
    info = json.loads((root / "meta/info.json").read_text())
    fps = info["fps"]
    video_keys = [k for k, f in info["features"].items() if f["dtype"] == "video"]

    ds = LeRobotDataset("local/eezybot_demo", root=root)
    print(ds)
    assert ds.num_frames == info["total_frames"], (ds.num_frames, info["total_frames"])
    assert ds.num_episodes == info["total_episodes"]
    assert ds.fps == fps
    assert ds.meta.video_keys == video_keys, (ds.meta.video_keys, video_keys)
    tasks = set()
    worst_colour = 0.0
    # camera_node's test source: the stamps drawn in the decoded frames of each episode
    # must not go back in time (a camera whose first frame carries no code, such as the
    # physics twin's, is not the test source: its frames are only decoded and checked)
    stamps = {}
    uncoded = set()
    shapes = {k: tuple(info["features"][k]["shape"][:2]) for k in video_keys}
    for i in range(len(ds)):
        item = ds[i]
        assert item["index"].item() == i
        assert item["observation.state"].shape == (4,) and item["action"].shape == (4,)
        # timestamp is float32: within its rounding (4e-6 at a minute)
        t = item["frame_index"].item() / fps
        assert abs(item["timestamp"].item() - t) <= 1e-6 + t * 2.0 ** -23, (item["timestamp"], t)
        assert isinstance(item["task"], str) and item["task"] != "0", item["task"]
        tasks.add(item["task"])
        for key in video_keys:
            worst_colour = max(worst_colour, check_image(key, i, item[key], shapes[key]))
            if key not in DEMO_CAMERAS and key not in uncoded:
                try:
                    stamps.setdefault((key, item["episode_index"].item()), []).append(stamp_of(item[key]))
                except AssertionError:
                    if stamps.get((key, item["episode_index"].item())):
                        raise  # a test source's frame that lost its code
                    uncoded.add(key)
                    stamps.pop((key, item["episode_index"].item()), None)
                    print(f"{key}: no stamp code in its frames (not camera_node's test source): decoded, not read")
    print("frames", len(ds), "tasks", sorted(tasks))
    if video_keys:
        print(f"decoded {len(ds)} frames of {video_keys}: every quadrant within {worst_colour:.1f} levels of its colour")
    for (key, e), s in sorted(stamps.items()):
        assert all(a <= b for a, b in zip(s, s[1:])), (key, e, s)
    if stamps:
        print(f"the test source's stamps, read from {sum(map(len, stamps.values()))} decoded frames, go forward "
              f"in each of {len(stamps)} episode(s)")
    stats = ds.meta.stats
    for k in ("observation.state", "action", *video_keys):
        assert set(stats[k]) >= {"min", "max", "mean", "std", "count", "q01", "q99"}, stats[k].keys()
    for k in video_keys:
        assert tuple(np.asarray(stats[k]["mean"]).shape) == (3, 1, 1), np.asarray(stats[k]["mean"]).shape
        print(k, "stats mean", np.asarray(stats[k]["mean"]).ravel())
    print("stats mean action", np.asarray(stats["action"]["mean"]))

    # every per-episode stat (the episodes table) against lerobot's own get_feature_stats
    # on the frames it loaded. It computes float32 features in float32: the same
    # histogram (our bin edges are float32 too), so the quantiles agree to 1e-6; its std,
    # sqrt(E[x²] - E[x]²) in float32, loses digits to cancellation where ours (float64)
    # does not: 1e-5 for std
    import pyarrow.parquet as pq
    from lerobot.datasets.compute_stats import get_feature_stats

    table = pq.read_table(sorted(str(p) for p in (root / "meta/episodes").glob("*/*.parquet")))
    worst = {}
    for e in range(ds.num_episodes):
        ep = ds.meta.episodes[e]
        rows = [ds.hf_dataset[i] for i in range(ep["dataset_from_index"], ep["dataset_to_index"])]
        for key in ("observation.state", "action", "timestamp", "frame_index", "index"):
            values = np.stack([np.asarray(r[key]) for r in rows])
            ours_dtype = np.float32 if key in ("observation.state", "action", "timestamp") else np.int64
            theirs = get_feature_stats(values.astype(ours_dtype), axis=0, keepdims=values.ndim == 1)
            for k, v in theirs.items():
                stored = np.asarray(table.column(f"stats/{key}/{k}")[e].as_py(), dtype=np.float64)
                if k == "std":
                    # lerobot's float32 sqrt(E[x²] - E[x]²) of a constant 1.57 rad is about
                    # 1e-3, not 0: ours is checked against the float64 std of the same
                    # frames, theirs only within its cancellation error
                    exact = np.std(values.astype(np.float64), axis=0, keepdims=values.ndim == 1)
                    assert float(np.max(np.abs(stored - exact))) < 1e-5, (e, key, stored, exact)
                    # (E[x²] - E[x]² off by tens of float32 ulps of E[x²]: 2.2e-3 seen)
                    cancel = np.sqrt(64 * np.finfo(np.float32).eps * np.mean(values.astype(np.float64) ** 2, axis=0))
                    assert np.all(np.abs(stored - np.asarray(v, dtype=np.float64)) <= 1e-5 + cancel), (e, key, stored, v)
                if k == "mean":
                    # lerobot's float32 mean of 1360 values of 1.5708 is 4e-6 off: ours is
                    # checked against the float64 mean, theirs within float32's summation error
                    exact = np.mean(values.astype(np.float64), axis=0, keepdims=values.ndim == 1)
                    assert float(np.max(np.abs(stored - exact))) < 1e-6, (e, key, stored, exact)
                    summed = 64 * np.finfo(np.float32).eps * np.max(np.abs(values.astype(np.float64)), axis=0)
                    assert np.all(np.abs(stored - np.asarray(v, dtype=np.float64)) <= 1e-6 + summed), (e, key, stored, v)
                diff = float(np.max(np.abs(stored - np.asarray(v, dtype=np.float64))))
                worst[k] = max(worst.get(k, 0.0), diff)
                assert k in ("std", "mean") or diff < 1e-6, (e, key, k, stored, v)
    print("per-episode stats equal lerobot's get_feature_stats; largest differences:",
          {k: f"{v:.1e}" for k, v in worst.items()})

    # action chunks as ACT asks for them
    chunked = LeRobotDataset("local/eezybot_demo", root=root,
                             delta_timestamps={"action": [t / fps for t in range(CHUNK)]})
    ep = chunked.meta.episodes[0]
    last = ep["dataset_to_index"] - 1
    first = chunked[0]
    assert first["action"].shape == (CHUNK, 4), first["action"].shape
    assert not first["action_is_pad"].any()
    # the chunk is the next CHUNK frames' actions
    for j in range(CHUNK):
        assert torch.equal(first["action"][j], ds[j]["action"])
    end = chunked[last]
    assert end["action_is_pad"][1:].all() and not end["action_is_pad"][0]
    print("action chunks ok: shape", tuple(first["action"].shape), "padding at the episode's end",
          end["action_is_pad"].tolist())
    print("LOADED OK")


if __name__ == "__main__":
    main()
