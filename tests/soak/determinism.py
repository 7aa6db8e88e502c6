#!/usr/bin/env python3
"""Soak: test modules run again and again on a busy host, to show their verdicts do not
depend on how busy it is (issue 32, item 6).

Each module runs `--runs` times in a row, as the test command runs it (`pytest
tests/MODULE`: a module of `own_process` runs in a pytest process of its own, as there),
while `--busy` busy loops (`yes > /dev/null`) keep the cores busy at the same priority.
Prints each run's outcome and duration and, per module, the passed and failed runs; the
output of a failed run is kept in the test output directory. Exits 1 if any run failed.

    $EEZYBOT_PYTHON tests/soak/determinism.py [--runs 20] [--busy 2] [--modules a.py,b.py] [--json FILE]

The default modules are those that run in the background beside the others and those
that had a timing dependency (the issue's list). Run as root for the modules that need
network namespaces; the test binaries come from EEZYBOT_BIN_DIR as for the test command.
"""
import os
import subprocess
import sys
import time
from pathlib import Path

import soaklib  # first: it puts tests/ on sys.path
from conftest import OUTPUT, REPO

MODULES = ",".join([
    # in the background beside the other modules (pytest.mark.background)
    "test_link_outages.py", "test_leader_arm.py", "test_calibration_wizard.py", "test_leader_calibration.py",
    "test_wan.py", "test_wan_outages.py", "test_web_attacks.py",
    # had a wall-clock window or another timing dependency (issue 32's audit)
    "test_security.py", "test_trajectory_action.py", "test_leader_follow.py", "test_serial_node.py",
    "test_keystore.py", "test_wan_files.py", "test_leader_firmware.py", "test_gui_bridge.py",
    "test_web_security.py", "test_fuzz.py", "test_two_hosts.py", "test_linkem.py", "test_mcap.py",
    "test_compute_ik.py", "test_jazzy.py", "test_launch_scripts.py",
    # judged at simavr's pins against the host's clocks (a CI run failed on a starved harness)
    "test_estop_and_hotplug.py",
])


def busy_loops(n):
    """`n` processes of `yes > /dev/null`, at the tests' own priority."""
    return [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(n)]


def run_module(module, trial):
    """One run of tests/`module`: (passed, seconds, the summary line)."""
    started = time.monotonic()
    p = subprocess.run([sys.executable, "-m", "pytest", str(REPO / "tests" / module), "-q", "-p", "no:cacheprovider"],
                       cwd=str(REPO / "tests"), capture_output=True, text=True)
    seconds = time.monotonic() - started
    lines = [line for line in p.stdout.splitlines() if line.strip()]
    summary = lines[-1] if lines else f"(no output; exit {p.returncode})"
    if p.returncode != 0:
        OUTPUT.mkdir(parents=True, exist_ok=True)
        kept = OUTPUT / f"determinism-{Path(module).stem}-{trial}-{os.getpid()}.log"
        kept.write_text(p.stdout + "\n--- stderr\n" + p.stderr)
        summary += f" (output: {kept})"
    return p.returncode == 0, seconds, summary


def main():
    args = soaklib.arguments(__doc__, runs=20, busy=2, modules=MODULES)
    modules = [m for m in args.modules.split(",") if m]
    missing = [m for m in modules if not (REPO / "tests" / m).exists()]
    if missing:
        sys.exit(f"no such test module: {', '.join(missing)}")
    results = []
    loops = busy_loops(args.busy)
    try:
        for module in modules:
            passed = 0
            for trial in range(1, args.runs + 1):
                ok, seconds, summary = run_module(module, trial)
                passed += ok
                results.append({"module": module, "trial": trial, "passed": ok, "seconds": round(seconds, 1),
                                "summary": summary})
                print(f"{module:32} run {trial:2d}/{args.runs}: {'ok  ' if ok else 'FAIL'} {seconds:6.1f} s  {summary}",
                      flush=True)
            print(f"{module:32} {passed} of {args.runs} runs passed, {args.runs - passed} failed", flush=True)
    finally:
        for p in loops:
            p.kill()
            p.wait()
    print(f"\n{len(modules)} modules x {args.runs} runs beside {args.busy} busy loops")
    soaklib.write_json(args.json, {"runs": args.runs, "busy": args.busy}, results=results)
    soaklib.finish([f"{r['module']} run {r['trial']}: {r['summary']}" for r in results if not r["passed"]],
                   len(results), "runs")

if __name__ == "__main__":
    main()
