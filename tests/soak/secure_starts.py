#!/usr/bin/env python3
"""Soak: the whole graph started again and again under SROS2 Enforce, to find a start
where a node never gets ready (a deadlock in the secured discovery, patches/README.md
rustdds entry 33).

Each start runs `launch_scripts/run_graph.sh` on the virtual Arduino with security on
(one keystore made at the beginning) in a ROS domain of its own and waits until its four
nodes said they are ready. A start where one did not within `--ready` seconds is a
failure: the backtraces of every thread of each node that is not ready (gdb, when it is
installed) and the script's log are kept in the test output directory. `--parallel`
graphs start at the same time, each with its own domain and web port, which makes the
host busier. Exits 1 if any start failed.

    $EEZYBOT_PYTHON tests/soak/secure_starts.py [--starts 400] [--parallel 2] [--ready 40] [--json FILE]
"""
import os
import re
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import soaklib  # first: it puts tests/ on sys.path
from conftest import OUTPUT, REPO, bin_path

READY = " ready in ROS domain "
NODES = ("compute_ik", "state_publisher", "gui_bridge", "serial_node")


def node_pids(session):
    """{pid: name} of our nodes in the process session `session`."""
    found = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            comm = stat[stat.index("(") + 1:stat.rindex(")")]
            sid = int(stat[stat.rindex(")") + 2:].split()[3])
        except (OSError, ValueError, IndexError):
            continue
        if sid == session and comm in NODES:
            found[int(d.name)] = comm
    return found


def one_start(n, lane, keystore, ready_s, keep):
    """Start the graph once; the start's record."""
    with soaklib.domain() as domain:
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_SECURITY_ENABLE": "true",
               "ROS_SECURITY_STRATEGY": "Enforce", "ROS_SECURITY_KEYSTORE": str(keystore), "SERIAL_PORT": "mock",
               "GUI_BIND": f"127.0.0.1:{18100 + domain}", "EEZYBOT_BIN_DIR": str(Path(bin_path("serial_node")).parent)}
        log = keep / f"secure-start-{n}.log"
        started = time.monotonic()
        with open(log, "w") as out:
            p = subprocess.Popen([str(REPO / "launch_scripts" / "run_graph.sh"), "--log-level", "info"], env=env,
                                 stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        ready_at = None
        while p.poll() is None and time.monotonic() - started < ready_s:
            if log.read_text().count(READY) >= len(NODES):
                ready_at = time.monotonic() - started
                break
            time.sleep(0.1)
        text = log.read_text()
        record = {"start": n, "lane": lane, "domain": domain, "ready": ready_at is not None,
                  "ready_s": ready_at and round(ready_at, 2), "exited": p.poll(),
                  "not_ready": [m for m in NODES if not re.search(rf"\b{m}\b[^\n]*{READY}", text)],
                  "lock_lines": text.count("I need my lock!!")}
        if ready_at is None:
            for pid, name in node_pids(p.pid).items():
                if name in record["not_ready"] and shutil.which("gdb"):
                    bt = keep / f"secure-start-{n}-{name}.bt"
                    with open(bt, "w") as f:
                        subprocess.run(["gdb", "-p", str(pid), "-batch", "-ex", "thread apply all bt"], stdout=f,
                                       stderr=subprocess.STDOUT, timeout=120)
            record["kept"] = str(log)
        try:
            os.killpg(p.pid, signal.SIGINT)
            p.wait(20)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        if ready_at is not None:
            log.unlink()
        return record


def main():
    args = soaklib.arguments(__doc__, starts=400, parallel=2, ready=40.0)
    keep = OUTPUT / f"secure-starts-{os.getpid()}"
    keep.mkdir(parents=True, exist_ok=True)
    keystore = Path(tempfile.mkdtemp(prefix="secure-starts-")) / "keystore"
    made = subprocess.run([str(REPO / "launch_scripts" / "keystore.sh"), str(keystore)], capture_output=True, text=True,
                          env={**os.environ, "EEZYBOT_BIN_DIR": str(Path(bin_path("serial_node")).parent)})
    if made.returncode != 0:
        raise SystemExit(f"keystore.sh failed:\n{made.stdout}{made.stderr}")
    results, lock, t0 = [], threading.Lock(), time.time()
    counter = iter(range(1, args.starts + 1))

    def lane(k):
        while True:
            with lock:
                n = next(counter, None)
            if n is None:
                return
            r = one_start(n, k, keystore, args.ready, keep)
            with lock:
                results.append(r)
                print(f"start {n:4d} (lane {k}): " + (f"ready in {r['ready_s']} s" if r["ready"] else
                      f"NOT READY in {args.ready:g} s: {', '.join(r['not_ready'])} (exit {r['exited']}, "
                      f"{r['lock_lines']} 'I need my lock' lines; kept {r['kept']})"), flush=True)

    lanes = [threading.Thread(target=lane, args=(k,)) for k in range(1, args.parallel + 1)]
    for t in lanes:
        t.start()
    for t in lanes:
        t.join()
    results.sort(key=lambda r: r["start"])
    failed = [r for r in results if not r["ready"]]
    summary = {"starts": len(results), "parallel": args.parallel, "not_ready": len(failed),
               **soaklib.p50_max("ready", (r["ready_s"] for r in results)), "seconds": round(time.time() - t0)}
    print(f"all: {summary}")
    soaklib.write_json(args.json, summary, starts=results)
    shutil.rmtree(keystore.parent, ignore_errors=True)
    soaklib.finish(soaklib.failures([{**r, "trial": r["start"] - 1} for r in results],
                                    lambda r: not r["ready"] and f"{', '.join(r['not_ready'])} not ready "
                                    f"(exit {r['exited']}, {r['lock_lines']} 'I need my lock' lines)", name="start"),
                   len(results), "starts")


if __name__ == "__main__":
    main()
