#!/usr/bin/env python3
"""Kill the recorder (SIGKILL, as a crash or a pulled plug) at a random moment of an
episode, or of its save, many times over: every episode whose save was answered must stay
intact (its rows, its video frames), the restarted recorder must say what it discarded,
and the dataset must read (pyarrow, PyAV; with --lerobot, lerobot 0.6.1's own loader).

The graph: serial_node's virtual Arduino, compute_ik, camera_node's test source (640x480
at 30 fps unless told otherwise) and the recorder. Each trial saves one episode of a
random length, starts another and kills the recorder at a random point of it (a third of
the trials: right after asking it to save, so that the kill may land inside the save).

    tests/soak/recorder_kills.py --trials 20 --json out.json [--lerobot]
"""
import json
import os
import random
import subprocess
import sys
import time
from pathlib import Path

from soaklib import arguments, domain, finish, write_json

from conftest import NodeProcess, Observer, REPO, bin_path, latest_status, status_values  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402

CAMERA = "camera/image_raw/compressed"


def main():
    args = arguments(__doc__, trials=20, width=640, height=480, fps=30, seed=1, root="", lerobot=0)
    rng = random.Random(args.seed)
    root = Path(args.root) if args.root else Path(f"/tmp/recorder-kills-{int(time.time())}")
    results, failed = [], []
    with domain() as dom:
        o = Observer(dom)
        diags = o.sub("/diagnostics", DiagnosticArray)
        procs = [NodeProcess("serial_node", ["--ros-args", "-p", "port:=mock"], dom),
                 NodeProcess("compute_ik", [], dom),
                 NodeProcess("camera_node", ["--ros-args", "-p", "device:=test", "-p", f"width:={args.width}",
                                             "-p", f"height:={args.height}", "-p", f"fps:={args.fps}"], dom)]

        def status():
            return status_values(latest_status(diags, "recorder"))

        def cli(*a):
            r = subprocess.run([bin_path("recorder"), *a], capture_output=True, text=True, timeout=120,
                               env={**os.environ, "ROS_DOMAIN_ID": str(dom)})
            return r.returncode, (r.stdout + r.stderr).strip()

        def start_recorder():
            diags.clear()
            p = NodeProcess("recorder", ["--ros-args", "-p", f"root:={root}", "-p", f"image_topics:=[{CAMERA}]",
                                         "-p", f"fps:={args.fps}"], dom)
            if not o.spin_until(lambda: status().get("state") == "idle", 60):
                raise RuntimeError(f"the recorder did not become idle: {status()}")
            return p

        saved = {}  # episode index -> frames, as the saves answered
        rec = start_recorder()
        try:
            for trial in range(args.trials):
                r = {"trial": trial}
                code, out = cli("start-episode", "--task", f"trial {trial}")
                if code:
                    r["failed"] = f"start: {out}"
                    results.append(r)
                    break
                o.spin_for(rng.uniform(0.5, 2.0))
                t = time.monotonic()
                code, out = cli("save-episode")
                r["save_s"] = time.monotonic() - t
                if code == 0:
                    idx, frames = out.split("saved episode ")[1].split(" (")[0], out.split("(")[1].split(" frames")[0]
                    saved[int(idx)] = int(frames)
                else:
                    r["failed"] = f"save: {out}"
                cli("start-episode", "--task", f"trial {trial}, killed")
                kill_in_save = trial % 3 == 2
                if kill_in_save:
                    o.spin_for(rng.uniform(0.3, 1.5))
                    subprocess.Popen([bin_path("recorder"), "save-episode"], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, env={**os.environ, "ROS_DOMAIN_ID": str(dom)})
                    o.spin_for(rng.uniform(0.0, 0.4))
                else:
                    o.spin_for(rng.uniform(0.2, 2.0))
                rec.kill_hard()
                r["kill_in_save"] = kill_in_save
                rec = start_recorder()
                r["recovered"] = status().get("last", "")
                # a kill during a save may have finished it: the answer decides nothing here
                info = json.loads((root / "meta/info.json").read_text())
                r["episodes"] = info["total_episodes"]
                results.append(r)
                print(f"trial {trial + 1}: {info['total_episodes']} episodes; {r['recovered'] or 'nothing to recover'}",
                      flush=True)
        finally:
            rec.stop()
            for p in procs:
                p.stop()
            o.close()
    # every saved episode intact: its rows and its video frames
    import av
    from test_recorder import table
    data = table((root / "data").glob("*/*.parquet"))
    cols = table((root / "meta/episodes").glob("*/*.parquet"))
    ep = [dict(zip(cols, values)) for values in zip(*cols.values())]
    info = json.loads((root / "meta/info.json").read_text())
    for idx, frames in saved.items():
        rows = sum(1 for e in data["episode_index"] if e == idx)
        if rows != frames:
            failed.append(f"episode {idx}: {rows} rows, {frames} saved")
    key = "videos/observation.images.camera"
    decoded = {}
    for e in ep:
        path = root / info["video_path"].format(video_key="observation.images.camera",
                                                chunk_index=int(e[f"{key}/chunk_index"]),
                                                file_index=int(e[f"{key}/file_index"]))
        if path not in decoded:
            with av.open(str(path)) as c:
                s = c.streams.video[0]
                decoded[path] = [float(f.pts * s.time_base) for f in c.decode(s)]
        pts = [p for p in decoded[path] if e[f"{key}/from_timestamp"] - 1e-4 <= p < e[f"{key}/to_timestamp"] - 1e-4]
        if len(pts) != int(e["length"]):
            failed.append(f"episode {int(e['episode_index'])}: {len(pts)} video frames, {int(e['length'])} rows")
    if len(ep) != info["total_episodes"]:
        failed.append(f"{len(ep)} episode rows, total_episodes {info['total_episodes']}")
    failed += [f"trial {r['trial'] + 1}: {r['failed']}" for r in results if "failed" in r]
    lerobot = None
    if args.lerobot:
        venv = Path.home() / ".cache/eezybot/lerobot-venv/bin/python"
        p = subprocess.run([str(venv), str(REPO / "tests/lerobot_load.py"), str(root)], capture_output=True, text=True,
                           env={**os.environ, "HF_HUB_OFFLINE": "1"})
        lerobot = p.stdout.strip().splitlines()[-1:] if p.returncode == 0 else f"FAILED: {p.stderr[-2000:]}"
        if p.returncode:
            failed.append(f"lerobot 0.6.1 did not load the dataset: {p.stderr[-500:]}")
    summary = {"trials": len(results), "episodes_saved": len(saved), "episodes_in_dataset": info["total_episodes"],
               "intact": len(saved) - sum(1 for f in failed if f.startswith("episode ")),
               "kills_in_save": sum(1 for r in results if r.get("kill_in_save")),
               "recovered_messages": sum(1 for r in results if r.get("recovered")), "lerobot": lerobot}
    print(json.dumps(summary), flush=True)
    write_json(args.json, summary, trials=results, root=str(root))
    finish(failed, len(results))


if __name__ == "__main__":
    sys.exit(main())
