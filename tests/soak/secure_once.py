#!/usr/bin/env python3
"""Soak: `gui_bridge once` under SROS2 (Enforce), again and again, against the secured
two-host graph of test_security.py: compute_ik in namespace `pc`, serial_node
(port:=mock) in `pi`, the Fast DDS operator and the foreign-CA stranger (tests/interop/
sros2_peer) and an rclpy outsider all present, as in
`test_outsiders_see_nothing_and_cannot_move_the_arm`, which runs one such trial in the
test command.

Each trial is one `once` process in `pc` with the pc enclave, to one of two targets in
turn; it passes when it exits 0 (compute_ik's joint_states carried the target's stamp).
It found two defects (BENCHMARKS.md, "The determinism soak, fourth series"): `once` sent
its target before compute_ik's answer could reach it, and the first step of the answer,
the only one with the target's stamp, was pushed out of compute_ik's history before
repair (1 in 25 beside two busy loops); then compute_ik greeted a new joint_states
subscriber by a rise in the count, which missed a `once` that replaced the last one
between two polls (6 in 165).

    sudo $EEZYBOT_PYTHON tests/soak/secure_once.py [--trials 150] [--busy 2]
        [--timeout 30] [--json FILE]

150 trials take about 9 minutes beside two busy loops on this 2-core machine. Prints
each trial and the count of failed ones; exits 1 if a trial failed or a node did not
exit 0. Timing is printed, not asserted (`--timeout` only ends a failed trial).
"""
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import soaklib  # noqa: E402
import twohost  # noqa: E402
from conftest import DomainLease, Observer, bin_path  # noqa: E402
from security_rig import SecureGraph, SecurePeer, make_keystore, security_env  # noqa: E402

TARGETS = [("0.19", "0.02", "0.16"), ("0.2", "0.0", "0.15")]


def main():
    args = soaklib.arguments(__doc__, trials=150, timeout=30.0, busy=2)
    soaklib.need_two_hosts()
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import JointState

    work = Path(tempfile.mkdtemp(prefix="secure_once-"))
    keystore = make_keystore(work / "keystore")
    foreign = make_keystore(work / "foreign")
    busy = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(args.busy)]
    hosts = twohost.TwoHosts(tag="o")
    lease = DomainLease()
    graph = SecureGraph(hosts, lease.id, keystore)
    peer = graph.operator()
    stranger = SecurePeer(lease.id, enclave=foreign.enclave("/eezybot/pc"), pubs=["xyz_target"],
                          subs=["servo_state"], netns=hosts.pc, name="stranger")
    outsider = Observer(lease.id, name="outsider", netns=hosts.pc)
    outsider.sub("/servo_state", JointState)
    outsider.pub("/xyz_target", PointStamped)
    results, failed = [], []
    try:
        ok = peer.wait(lambda: peer.matched("xyz_target", "pub") > 0 and peer.matched("servo_state", "sub") > 0, 60)
        if not ok:
            failed.append(f"the operator did not match the graph in 60 s\n{graph.logs_tail()}")
        for i in range(args.trials if ok else 0):
            t0 = time.monotonic()
            try:
                r = subprocess.run(["ip", "netns", "exec", hosts.pc, bin_path("gui_bridge"), "once", *TARGETS[i % 2],
                                    "--timeout", str(args.timeout), "--ros-args", "--enclave", "/eezybot/pc"],
                                   capture_output=True, text=True, timeout=args.timeout * 3 + 30,
                                   env={**os.environ, **security_env(keystore), "ROS_DOMAIN_ID": str(lease.id)})
                code, stderr = r.returncode, r.stderr
            except subprocess.TimeoutExpired as e:
                code, stderr = None, f"gui_bridge: did not exit in {e.timeout:.0f} s"
            last = [line for line in stderr.splitlines() if line.startswith("gui_bridge:")]
            results.append({"trial": i, "exit": code, "seconds": round(time.monotonic() - t0, 2),
                            "error": (last[-1] if last else f"exit {code}") if code != 0 else None})
            print(f"trial {i + 1}/{args.trials}: exit {code} in {results[-1]['seconds']:.2f} s"
                  f"{'  ' + results[-1]['error'] if results[-1]['error'] else ''}", flush=True)
    finally:
        outsider.close()
        codes = {p.name: p.close() for p in (peer, stranger)}
        codes.update(graph.close())
        hosts.close()
        lease.release()
        for b in busy:
            b.kill()
    failed += soaklib.failures(results, lambda r: r["error"])
    failed += [f"{name} exited {code}" for name, code in codes.items() if code != 0]
    seconds = [r["seconds"] for r in results if r["exit"] == 0]
    summary = {"trials": len(results), "failed": len(failed), **soaklib.p50_max("once", seconds)}
    print(summary, flush=True)
    soaklib.write_json(args.json, summary, results=results)
    soaklib.finish(failed, len(results))


if __name__ == "__main__":
    main()
