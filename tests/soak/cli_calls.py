#!/usr/bin/env python3
"""Soak: compute_ik's controller manager answers each new `ros2 control` process.

compute_ik runs once; each round starts `ros2 control switch_controllers` (arm_controller
and teleop in turns, --strict) and then `ros2 control list_controllers`, each a new
process of this venv's `ros2` (ros2controlcli on rclpy and Fast DDS), as a user types
them. A call fails when ros2controlcli had no answer within rcl's 10 s (it warns
"Failed getting a result" and asks again) or exits non-zero. Issue 33: 24 of 440 such
calls had no answer in 10 s before ros_plumbing's waiting answers were sent from a
pending next() (the switch made, its retry refused as not active).

    $EEZYBOT_PYTHON tests/soak/cli_calls.py [--rounds 100] [--json FILE]

About 2.5 s a round here. Exits 1 if a call failed or compute_ik did not exit 0.
"""
import os
import subprocess
import sys
import time
from pathlib import Path

import soaklib  # first: it puts tests/ on sys.path
from conftest import NodeProcess

ROS2 = Path(sys.executable).parent / "ros2"
SWITCHES = [("arm_controller", "teleop"), ("teleop", "arm_controller")]


def call(env, *args):
    """One `ros2 control ...` process: its record (the seconds it took, whether an
    answer was missing in 10 s, its exit code)."""
    t0 = time.monotonic()
    p = subprocess.run([str(ROS2), "control", *args], capture_output=True, text=True, env=env, timeout=120,
                       stdin=subprocess.DEVNULL)
    return {"call": " ".join(args), "s": round(time.monotonic() - t0, 2), "at": time.time(),
            "unanswered": p.stderr.count("Failed getting a result"), "exit": p.returncode,
            "stderr": p.stderr[-2000:] if p.returncode or "Failed getting a result" in p.stderr else ""}


def main():
    args = soaklib.arguments(__doc__, rounds=100)
    assert ROS2.exists(), f"{ROS2} is missing: launch_scripts/install_ros2cli.sh"
    results, failed = [], []
    with soaklib.domain() as domain:
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "RCUTILS_COLORIZED_OUTPUT": "0"}
        node = NodeProcess("compute_ik", [], domain)
        try:
            time.sleep(2)
            for i in range(args.rounds):
                activate, deactivate = SWITCHES[i % 2]
                for r in (call(env, "switch_controllers", "--activate", activate, "--deactivate", deactivate,
                               "--strict"),
                          call(env, "list_controllers")):
                    r["round"] = i + 1
                    results.append(r)
                    bad = r["unanswered"] or r["exit"]
                    print(f"round {i + 1:3d} {r['call'].split()[0]:>18}: {r['s']:5.1f} s"
                          + (f"  FAILED: {r['unanswered']} unanswered, exit {r['exit']}" if bad else ""), flush=True)
        finally:
            code = node.stop()
            subprocess.run([str(ROS2), "daemon", "stop"], capture_output=True, env=env, timeout=60)
    if code != 0:
        failed.append(f"compute_ik exited {code} (log: {node.log_path})")
    failed += [f"round {r['round']} {r['call']}: {r['unanswered']} call(s) unanswered in 10 s, exit {r['exit']}"
               for r in results if r["unanswered"] or r["exit"]]
    summary = {"calls": len(results), "unanswered": sum(1 for r in results if r["unanswered"]),
               "failed_exit": sum(1 for r in results if r["exit"]),
               **soaklib.p50_max("call", (r["s"] for r in results))}
    print(f"{summary['calls']} calls: {summary['unanswered']} without an answer in 10 s, "
          f"{summary['failed_exit']} exited non-zero; call p50 {summary['call_p50_s']:.2f} s, max {summary['call_max_s']:.2f} s")
    soaklib.write_json(args.json, summary, calls=results, compute_ik_log=str(node.log_path))
    soaklib.finish(failed, len(results), "calls")


if __name__ == "__main__":
    main()
