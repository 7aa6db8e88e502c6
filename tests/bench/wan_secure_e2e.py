#!/usr/bin/env python3
"""SROS2 and the WAN together, benchmarked (issue 36, item 1): the end-to-end figure (a)
through the Zenoh router with both sites secured against the same path WAN-only, in one
run of this program.

    sudo $EEZYBOT_PYTHON tests/bench/wan_secure_e2e.py [--seconds 60] [--rate 50] [--rounds 2]
        [--json FILE]

Variants (each run in the namespaces pc, wan, pi of tests/wanhost.py, pc.sh in `pc` and
pi.sh in `pi` with SERIAL_PORT=mock, the router in `wan`, mutual TLS to it in both):
  wan          today's WAN mode: TLS on the WAN leg, plain DDS on each LAN.
  wan_secured  the same with SROS2 (Enforce) on both LANs: the nodes under /eezybot/pc and
               /eezybot/pi, the bridges under /eezybot/bridge_pc and /eezybot/bridge_pi of a
               keystore made by launch_scripts/keystore.sh.
--rounds N runs N of each, alternating the order (wan, wan_secured, wan_secured, wan, ...).

The probes are ros_plumbing's ros_probe example (RustDDS, as gui_bridge talks to the
graph) in both variants, secured in the secured one: rclpy from PyPI has no DDS
Security, and Fast DDS 2.9 (sros2_peer) cannot authenticate with the bridge's Cyclone
DDS (docs/security.md, SROS2 with the WAN). The operator probe in `pc` publishes the
targets along e2e_analysis.TargetPath's smooth path at --rate, each stamped with
time.time_ns() just before its line goes to the probe's stdin; a second probe in `pi`
(the pc enclave's identity: it only subscribes servo_angles, which that grant allows)
prints every servo_angles sample it gets. Clocks: CLOCK_REALTIME, one machine.
  (a)         xyz_target -> servo_angles carrying its stamp, read by this program from the
              pi probe's stdout: across compute_ik, the pc bridge, the router and the pi
              bridge (the probes' pipes are inside the figure, the same in both variants).
  round trip  xyz_target -> servo_state carrying its stamp back at the operator (serial_node
              answers each command it applies).
  loss        targets whose servo_angles never reached the pi probe (compute_ik is
              newest-wins: a target replaced before it ran is not answered).
Also the CPU (% of one core over the window) and RSS of both bridges, compute_ik and
serial_node (e2e_harness.CpuWindow).

Target (issue 36): secured overhead on (a), both sites plus WAN, <= 0.5 ms p50 over
WAN-only. Timing is never asserted: the program prints what it measured.

Needs root (ip netns), our binaries (EEZYBOT_BIN_DIR: release ones for figures worth
comparing, cargo build --release --bins --examples), the WAN binaries
(EEZYBOT_WAN_BIN_DIR), openssl. About --seconds + 25 s a run.
"""
import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import e2e_analysis as A  # noqa: E402
import secure_harness as S  # noqa: E402
import wanhost  # noqa: E402
from conftest import REPO, DomainLease, NodeProcess, bin_path  # noqa: E402
from e2e_harness import CpuWindow, descendants, proc_sample  # noqa: E402
from security_rig import NO_SECURITY, make_keystore, security_env  # noqa: E402

TARGET_OVERHEAD_P50_MS = 0.5
VARIANTS = ("wan", "wan_secured")


def log(s):
    print(s, flush=True)


def pids(procs, hosts):
    """{label: pid} of the bridges, compute_ik and serial_node (children of the scripts)
    and the router."""
    out = {}
    for p in procs:
        for c in descendants(p.proc.pid):
            s = proc_sample(c)
            if not s:
                continue
            name = s[0]
            if name.startswith("eezybot_wan"):
                out[f"bridge {p.name[:-3]}"] = c
            elif name in ("compute_ik", "serial_node"):
                out[name] = c
    if hosts.router is not None and hosts.router.poll() is None:
        out["router"] = hosts.router.pid
    return out


def one_run(variant, args, keystore, certs, tag):
    secured = variant == "wan_secured"
    log(f"--- run `{tag}` ({variant}): {args.rate:g} Hz x {args.seconds:g} s")
    lease = DomainLease()
    domain = lease.id
    hosts = wanhost.WanHosts(tag="b")
    procs, peers = [], []
    try:
        hosts.start_router(certs, Path(args.workdir) / f"router-{tag}.log")
        env = {**hosts.graph_env(certs), "EEZYBOT_BIN_DIR": str(Path(bin_path("serial_node")).parent),
               "GUI_BIND": "127.0.0.1:8080", **(security_env(keystore) if secured else NO_SECURITY)}
        procs.append(NodeProcess(str(REPO / "launch_scripts" / "pc.sh"), [], domain, env=env, netns=hosts.pc))
        procs.append(NodeProcess(str(REPO / "launch_scripts" / "pi.sh"), [], domain,
                                 env={**env, "SERIAL_PORT": "mock"}, netns=hosts.pi))
        deadline = time.monotonic() + 60
        while not ("/compute_ik ready" in procs[0].output() and "connected to the router" in procs[1].output()):
            if time.monotonic() > deadline or any(p.proc.poll() is not None for p in procs):
                raise RuntimeError("the graph did not start:\n" + "\n".join(p.output()[-2000:] for p in procs))
            time.sleep(0.1)
        enclave = keystore.enclave("/eezybot/pc") if secured else None
        op = S.TimedPeer(domain, enclave=enclave, pubs=("xyz_target",), subs=("servo_state",), netns=hosts.pc,
                         name=f"operator-{tag}", binary=bin_path("examples/ros_probe"))
        peers.append(op)
        probe = S.TimedPeer(domain, enclave=enclave, subs=("servo_angles",), netns=hosts.pi,
                            name=f"pi-probe-{tag}", binary=bin_path("examples/ros_probe"))
        peers.append(probe)
        if not (S.wait_matched(op, pubs=("xyz_target",), subs=("servo_state",), timeout=60)
                and S.wait_matched(probe, subs=("servo_angles",), timeout=60)):
            raise RuntimeError(f"the probes did not match: {op.stderr()[-1500:]} {probe.stderr()[-1500:]}")
        path = A.TargetPath("smooth")
        t_origin = time.monotonic()

        def drive(seconds):
            sent = []
            period = 1.0 / args.rate
            nxt = time.monotonic()
            end = nxt + seconds
            while nxt < end:
                now = time.monotonic()
                if now < nxt:
                    time.sleep(nxt - now)
                _, xyz = path.next(time.monotonic() - t_origin)
                t = time.time_ns()
                op.publish("xyz_target", S.point_payload(xyz, t))
                sent.append(t)
                nxt += period
            return sent

        # flowing: until a target is answered at the pi probe (the routes exist)
        deadline = time.monotonic() + 60
        while not probe.received_real("servo_angles"):
            if time.monotonic() > deadline:
                raise RuntimeError("no servo_angles reached the pi probe")
            drive(0.2)
        drive(2.0)  # warm-up
        since_probe, since_op = len(probe.real), len(op.real)
        window = CpuWindow(pids(procs, hosts))
        sent = drive(args.seconds)
        cpu = window.close()
        time.sleep(2.0)  # late samples still count
        angles = {S.joint_state_of(p)[0]: t for t, p in probe.received_real("servo_angles", since_probe)}
        states = {}
        for t, p in op.received_real("servo_state", since_op):
            states.setdefault(S.joint_state_of(p)[0], t)
        a = [angles[s] - s for s in sent if s in angles]
        rt = [states[s] - s for s in sent if s in states]
        out = {"variant": variant, "tag": tag, "sent": len(sent), "a": A.summary(a, 1e-6), "a_lost": len(sent) - len(a),
               "round_trip": A.summary(rt, 1e-6), "round_trip_lost": len(sent) - len(rt), "cpu": cpu,
               "load": os.getloadavg()}
        log(f"    (a) p50 {out['a'].get('p50', float('nan')):.3f} ms, p99 {out['a'].get('p99', float('nan')):.3f} ms, "
            f"lost {out['a_lost']}/{len(sent)}; round trip p50 {out['round_trip'].get('p50', float('nan')):.3f} ms; "
            f"load {out['load'][0]:.1f}")
        return out
    finally:
        codes = {p.name: p.close() for p in peers}
        codes.update({p.name: p.stop() for p in procs})
        hosts.close()
        lease.release()
        log(f"    exit codes {codes}, router {hosts.router_code}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--json")
    args = ap.parse_args()
    if wanhost.available():
        sys.exit(f"needs network namespaces: {wanhost.available()}")
    with tempfile.TemporaryDirectory(prefix="wan-secure-e2e-") as workdir:
        args.workdir = workdir
        keystore = make_keystore(Path(workdir) / "keystore")
        certs = wanhost.make_certs(Path(workdir) / "certs")
        results = []
        for k in range(args.rounds):
            order = VARIANTS if k % 2 == 0 else VARIANTS[::-1]
            for v in order:
                results.append(one_run(v, args, keystore, certs, f"{v}-{k + 1}"))
    print(f"\n== (a) xyz_target -> servo_angles in pi, through the router, {args.rate:g} Hz x {args.seconds:g} s "
          f"(binaries {os.environ.get('EEZYBOT_BIN_DIR', 'target/debug')})")
    for r in results:
        a, t = r["a"], r["round_trip"]
        print(f"  {r['tag']:<16} (a) p50 {a['p50']:7.3f}  p99 {a['p99']:7.3f}  max {a['max']:8.3f} ms  lost "
              f"{r['a_lost']}/{r['sent']};  round trip p50 {t['p50']:7.3f}  p99 {t['p99']:7.3f} ms  lost "
              f"{r['round_trip_lost']}/{r['sent']};  load {r['load'][0]:.1f}")
        for label, c in sorted(r["cpu"].items()):
            print(f"      {label:<14} {c['cpu_pct']:5.2f} % of a core, {c['rss_mb']:.1f} MB")
    by = {v: [r for r in results if r["variant"] == v] for v in VARIANTS}
    p50 = {v: statistics.median(r["a"]["p50"] for r in rs) for v, rs in by.items() if rs}
    p99 = {v: statistics.median(r["a"]["p99"] for r in rs) for v, rs in by.items() if rs}
    if len(p50) == 2:
        over = p50["wan_secured"] - p50["wan"]
        print(f"\n  secured overhead on (a): p50 {over:+.3f} ms (median of the runs' p50s: "
              f"{p50['wan_secured']:.3f} vs {p50['wan']:.3f}), p99 {p99['wan_secured'] - p99['wan']:+.3f} ms; "
              f"target <= {TARGET_OVERHEAD_P50_MS} ms p50: {'met' if over <= TARGET_OVERHEAD_P50_MS else 'NOT MET'}")
    if args.json:
        Path(args.json).write_text(json.dumps({"args": {k: v for k, v in vars(args).items() if k != "workdir"},
                                               "results": results}, indent=1, default=str))


if __name__ == "__main__":
    main()
