#!/usr/bin/env python3
"""Where the SROS2 overhead of (a) goes: secure_e2e.py's latency run, split at the wire.

    sudo $EEZYBOT_PYTHON tests/bench/secure_hops.py [--seconds 60] [--rounds 2]
        [--order unsecured,secured] [--device simavr|virtual] [--json F]

secure_e2e.py's (a) (`xyz_target` -> `servo_angles`) is read at the probe, and the probe
is tests/interop/sros2_peer (Debian's Fast DDS 2.9) in both variants, because rclpy from
PyPI has no DDS Security. So (a) holds the PEER's own encryption of the target and
decryption of the reply, besides our node's. Here the same run is captured on the `pc`
namespace's loopback (tcpdump, kernel CLOCK_REALTIME, the clock of the stamps), and
every target is cut into three hops:

  peer out    t0 (the target's header.stamp, just before the line goes into the peer's
              stdin) -> the first datagram from the peer's sockets to compute_ik's after t0
              (the peer's pipe, Fast DDS's serialization and, secured, its encryption);
  compute_ik  that datagram -> the first datagram from compute_ik's sockets to the peer's
              carrying a `servo_angles` DATA (RustDDS's receive path, decryption, the IK,
              the planner, serialization, encryption and send: our node, wire to wire);
  peer in     that datagram -> the time Python read the peer's `recv rt/servo_angles`
              line (Fast DDS's receive path, decryption, the pipe).

The sockets of each process are read with `ss -uanp` in the namespace while the graph
runs; only datagrams to a user-traffic unicast port (RTPS: 7400 + 250 * domain + 11 +
2 * participant id) count, so discovery traffic is left out. Datagrams are told apart by size: a DATA of servo_angles is the largest datagram
compute_ik sends the peer in the 20 ms after a target (its ACKNACKs and HEARTBEATs are
smaller, secured or not), and a target's the largest the peer sends compute_ik. Targets
whose datagrams are not found are counted, not guessed. Timing is never asserted.

Needs what secure_e2e.py needs, and tcpdump.
"""
import argparse
import bisect
import json
import re
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import e2e  # noqa: E402
import e2e_analysis as A  # noqa: E402
import secure_harness as S  # noqa: E402
from e2e_harness import CpuWindow  # noqa: E402
from secure_harness import joint_state_of  # noqa: E402


def log(s):
    print(s, flush=True)


# ---------------------------------------------------------------- capture
def read_pcap(path):
    """[(t_ns, src_port, dst_port, udp_payload_len)] of the UDP/IPv4 datagrams of a
    nanosecond pcap of a loopback (DLT_EN10MB with zero MACs on lo)."""
    data = Path(path).read_bytes()
    if len(data) < 24:
        return []
    magic = struct.unpack("<I", data[:4])[0]
    if magic != 0xA1B23C4D:
        raise ValueError(f"{path}: not a little-endian nanosecond pcap (magic {magic:#x})")
    linktype = struct.unpack("<I", data[20:24])[0]
    l2 = {1: 14, 113: 16, 276: 20}.get(linktype)
    if l2 is None:
        raise ValueError(f"{path}: link type {linktype}")
    out, off = [], 24
    while off + 16 <= len(data):
        sec, nsec, incl, _orig = struct.unpack("<IIII", data[off:off + 16])
        pkt = data[off + 16:off + 16 + incl]
        off += 16 + incl
        ip = pkt[l2:]
        if len(ip) < 28 or ip[0] >> 4 != 4 or ip[9] != 17:
            continue
        ihl = (ip[0] & 0x0F) * 4
        sport, dport, ulen = struct.unpack(">HHH", ip[ihl:ihl + 6])
        out.append((sec * 1_000_000_000 + nsec, sport, dport, ulen - 8))
    return out


def udp_ports(netns, pid):
    """The local UDP ports of process `pid`'s sockets in `netns`."""
    text = subprocess.run(["ip", "netns", "exec", netns, "ss", "-uanp"], capture_output=True, text=True,
                          timeout=10).stdout
    ports = set()
    for line in text.splitlines():
        if f"pid={pid}," not in line:
            continue
        m = re.search(r"\s(\S+):(\d+)\s+\S+:\S+\s", line)
        if m:
            ports.add(int(m.group(2)))
    return ports


# ---------------------------------------------------------------- one run
def hops_run(variant, args, tag):
    """One run, its capture in a temporary directory removed whether or not it succeeds."""
    pcap_dir = Path(tempfile.mkdtemp(prefix="secure-hops-"))
    try:
        return captured_run(variant, args, tag, pcap_dir / f"{tag}.pcap")
    finally:
        shutil.rmtree(pcap_dir, ignore_errors=True)


def captured_run(variant, args, tag, pcap):
    log(f"--- run `{tag}` ({variant}): {args.rate:g} Hz x {args.seconds:g} s, capture on the pc namespace's lo")
    run = S.LatencyRun(tag, A.TargetPath("smooth"), variant, device=args.device, clock_ppm=e2e.clock_ppm(args),
                       log=log)
    dump = None
    domain = None
    try:
        run.start()
        run.wait_flowing()
        ns = run.hosts.pc
        domain = run.lease.id
        pids = run.node_pids()
        ports = {"compute_ik": udp_ports(ns, pids["compute_ik"]), "peer": udp_ports(ns, run.peer.proc.pid)}
        dump = subprocess.Popen(["ip", "netns", "exec", ns, "tcpdump", "-i", "lo", "-w", str(pcap), "-U", "-n",
                                 "--time-stamp-precision=nano", "udp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1.0)
        run.drive(args.rate, 2.0, "warmup")
        window = CpuWindow({**run.node_pids(), **run.helper_pids()})
        t_measure = time.time_ns()
        run.drive(args.rate, args.seconds, "measure")
        cpu = window.close()
        run.spin(time.monotonic() + 1.0)
    finally:
        if dump is not None:
            dump.terminate()
            dump.wait(timeout=10)
        run.stop()
    grams = read_pcap(pcap)
    shutil.rmtree(run.workdir, ignore_errors=True)
    return analyse(variant.name, run, grams, ports, domain, t_measure, cpu)


def analyse(name, run, grams, ports, domain, t_measure, cpu):
    ik, peer = ports["compute_ik"], ports["peer"]
    base = 7400 + 250 * domain

    def user(port):  # a participant's user-traffic unicast port: base + 11 + 2 * participant id
        return (port - base) >= 11 and (port - base) % 2 == 1

    to_ik = [(t, n) for t, s, d, n in grams if s in peer and d in ik and user(d)]
    to_peer = [(t, n) for t, s, d, n in grams if s in ik and d in peer and user(d)]
    replies = {}
    for t, payload in run.peer.received_real("servo_angles"):
        st = joint_state_of(payload)[0]
        replies.setdefault(st, t)
    hops = {"peer_out": [], "compute_ik": [], "peer_in": [], "total": []}
    missing = {"no reply": 0, "no target datagram": 0, "no reply datagram": 0}
    sent = [t for t, _, phase in run.sent if phase == "measure" and t >= t_measure]
    def largest_between(grams, after, before):
        """The time of the largest of the first 8 datagrams in [after, before], or None."""
        i = bisect.bisect_left(grams, (after, -1))
        cand = [g for g in grams[i:i + 8] if g[0] <= before]
        return max(cand, key=lambda g: g[1])[0] if cand else None

    for t0 in sent:
        t1 = replies.get(t0)
        if t1 is None:
            missing["no reply"] += 1
            continue
        w1 = largest_between(to_ik, t0, t1)
        if w1 is None:
            missing["no target datagram"] += 1
            continue
        w2 = largest_between(to_peer, w1, t1)
        if w2 is None:
            missing["no reply datagram"] += 1
            continue
        hops["peer_out"].append((w1 - t0) / 1e6)
        hops["compute_ik"].append((w2 - w1) / 1e6)
        hops["peer_in"].append((t1 - w2) / 1e6)
        hops["total"].append((t1 - t0) / 1e6)
    sizes = {"to compute_ik": sorted({n for _, n in to_ik}), "to the peer": sorted({n for _, n in to_peer})}
    return {"variant": name, "sent": len(sent), "missing": missing, "ports": {k: sorted(v) for k, v in ports.items()},
            "datagram_sizes": sizes, "cpu": cpu,
            "stats": {h: stats(v) for h, v in hops.items()}}


def stats(v):
    if not v:
        return {"n": 0}
    v = sorted(v)
    return {"n": len(v), "p50": statistics.median(v), "p99": v[min(len(v) - 1, int(0.99 * len(v)))], "max": v[-1]}


def report(results):
    log("\n== (a) cut at the wire: p50 / p99 ms")
    by = {}
    for r in results:
        s = r["stats"]
        log(f" {r['variant']:<9} n {s['total'].get('n', 0):4d}/{r['sent']}  "
            + "  ".join(f"{h} {s[h]['p50']:.3f}/{s[h]['p99']:.3f}" for h in ("peer_out", "compute_ik", "peer_in", "total")
                        if s[h].get("n"))
            + f"   missing {r['missing']}  sizes {r['datagram_sizes']}")
        by.setdefault(r["variant"], []).append(s)
    if {"secured", "unsecured"} <= by.keys():
        log(" secured - unsecured, mean of the runs' p50s:")
        for h in ("peer_out", "compute_ik", "peer_in", "total"):
            m = {v: statistics.mean(s[h]["p50"] for s in by[v] if s[h].get("n")) for v in by}
            log(f"   {h:<11} {m['unsecured']:.3f} -> {m['secured']:.3f} ms: {m['secured'] - m['unsecured']:+.3f} ms")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--order", default="unsecured,secured")
    ap.add_argument("--device", choices=["simavr", "virtual"], default="simavr")
    ap.add_argument("--avr-clock-ppm", type=float)
    ap.add_argument("--json")
    args = ap.parse_args()
    if not shutil.which("tcpdump"):
        sys.exit("tcpdump is needed")
    log(f"secure_hops on {e2e.machine_line() if hasattr(e2e, 'machine_line') else ''} load {__import__('os').getloadavg()}")
    work = Path(tempfile.mkdtemp(prefix="secure-hops-ks-"))
    try:
        vs = S.variants(work, args.order)
        results = []
        for rnd in range(args.rounds):
            names = list(vs) if rnd % 2 == 0 else list(vs)[::-1]
            for name in names:
                results.append(hops_run(vs[name], args, f"{name}{rnd}"))
        report(results)
        if args.json:
            Path(args.json).write_text(json.dumps(results, indent=1))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    log(f"load at end {__import__('os').getloadavg()}")


if __name__ == "__main__":
    main()
