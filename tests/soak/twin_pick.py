#!/usr/bin/env python3
"""The scripted pick through the graph against the physics twin, over seeded trials
(issue 35's target: the cube lifted 5 cm in at least 19 of 20): each trial a fresh graph
(the twin, compute_ik, serial_node) with the cube at a seeded place on its stand
(x 0.19-0.21 m, y -0.03-0.03 m), the pick of tests/twin_pick.py, judged by the cube's tf
frame. Exits 1 when fewer than --need trials lifted it.

    tests/soak/twin_pick.py --trials 20 --seed 35 --json out.json
"""
import random
import sys
import tempfile
import time
from pathlib import Path

from soaklib import arguments, domain, finish, write_json  # first: it puts tests/ on sys.path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
from benchkit import Launcher  # noqa: E402
from conftest import Observer  # noqa: E402
from twin_pick import PickGraph, gripped  # noqa: E402


def main():
    a = arguments(__doc__, trials=20, seed=35, need=19)
    rng = random.Random(a.seed)
    results = []
    for trial in range(a.trials):
        xy = (round(0.2 + rng.uniform(-0.01, 0.01), 4), round(rng.uniform(-0.03, 0.03), 4))
        with domain() as d:
            o = Observer(d)
            launch = Launcher(d)
            t0 = time.monotonic()
            try:
                g = PickGraph(launch, o, d, Path(tempfile.mkdtemp(prefix="twin-pick-")) / "tty", xy)
                try:
                    rise = g.pick()
                finally:
                    g.close()
                error = None
            except AssertionError as e:
                rise, error = float("nan"), str(e)
            finally:
                codes = launch.stop()
                o.close()
        r = {"trial": trial + 1, "cube_xy": xy, "rise_mm": round(rise * 1e3, 1), "lifted": gripped(rise),
             "seconds": round(time.monotonic() - t0, 1), "exit_codes": codes, "error": error}
        results.append(r)
        print(r, flush=True)
    lifted = sum(r["lifted"] for r in results)
    summary = {"trials": a.trials, "lifted": lifted, "seed": a.seed}
    print(summary, flush=True)
    write_json(a.json, summary, results=results)
    failed = [] if lifted >= a.need else [f"lifted in {lifted} of {a.trials} trials, {a.need} needed"]
    failed += [f"trial {r['trial']}: a node exited with {r['exit_codes']}" for r in results if any(r["exit_codes"])]
    finish(failed, a.trials)


if __name__ == "__main__":
    main()
