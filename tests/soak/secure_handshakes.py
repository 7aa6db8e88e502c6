#!/usr/bin/env python3
"""Soak: many SROS2 handshakes between our nodes and a Fast DDS peer (rustdds entry 32).

Each trial starts tests/interop/sros2_peer (Debian's Fast DDS 2.9, pc enclave,
subscribing `servo_state`) in namespace `pc`, then --nodes serial_nodes (port:=mock,
/eezybot/pi enclave) in `pi` across a veth, and passes when the peer has matched every
node's `servo_state` writer within --timeout s. So a trial is --nodes handshakes between
Fast DDS and RustDDS: the peer starts each one (its certificate-derived GUID prefix sorts
lower) with its default key agreement, DH+MODP-2048-256. Before entry 32 about 1 such
handshake in 136 ended with the two sides holding different shared secrets (a DH secret
with a leading zero byte), and that node never matched (its log: `Submessage decoding
failed ... 'Unspecified'`).

    sudo $EEZYBOT_PYTHON tests/soak/secure_handshakes.py [--trials 100] [--nodes 10]
        [--timeout 20] [--json FILE]

100 trials of 10 nodes take about 15 minutes on a quiet 2-core machine. Prints each
trial, the nodes whose logs have decode errors, and the count of failed trials; exits 1
if a trial failed (not every node matched, a node's log has decode errors, or a node did
not exit 0). Timing is not asserted.
"""
import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parent / "bench"))

import secure_harness as S  # noqa: E402
import soaklib  # noqa: E402
import twohost  # noqa: E402
from conftest import DomainLease  # noqa: E402


def trial(hosts, variant, nodes, timeout, index):
    lease = DomainLease()
    peer = S.TimedPeer(lease.id, enclave=variant.peer_enclave(), subs=("servo_state",), netns=hosts.pc,
                       name=f"peer-handshakes{index}")
    procs = []
    try:
        peer.wait_ready()
        t0 = time.monotonic()
        procs = [S.start_node("serial_node", variant, lease.id, hosts.pi, ["-p", "port:=mock"]) for _ in range(nodes)]
        end = t0 + timeout
        matched = None
        while time.monotonic() < end:
            line = peer.first_line(f"matched rt/servo_state sub {nodes}")
            if line:
                matched = line[0] - t0
                break
            time.sleep(0.1)
    finally:
        codes = [p.stop() for p in procs]
        peer.close()
        lease.release()
    bad = [str(p.log_path) for p in procs if "decoding failed" in Path(p.log_path).read_text(errors="replace")]
    return {"trial": index, "all_matched_s": matched, "nodes_with_decode_errors": bad, "exit_codes": codes}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--nodes", type=int, default=10)
    ap.add_argument("--timeout", type=float, default=20.0)
    ap.add_argument("--json")
    args = ap.parse_args()
    if twohost.available():
        sys.exit(f"network namespaces are needed: {twohost.available()}")
    print(f"secure_handshakes: {args.trials} trials x {args.nodes} nodes, binaries "
          f"{os.environ.get('EEZYBOT_BIN_DIR', 'target/release')}, load {os.getloadavg()}", flush=True)
    work = Path(tempfile.mkdtemp(prefix="secure-handshakes-"))
    hosts = twohost.TwoHosts(tag="h")
    out = []
    try:
        variant = S.variants(work, "secured")["secured"]
        for i in range(args.trials):
            r = trial(hosts, variant, args.nodes, args.timeout, i)
            out.append(r)
            ok = r["all_matched_s"] is not None
            print(f"  {i + 1:3d}/{args.trials} {'ok  ' if ok else 'FAIL'} "
                  + (f"all matched {r['all_matched_s']:.2f} s" if ok else f"not all matched in {args.timeout:g} s")
                  + (f"; decode errors in {r['nodes_with_decode_errors']}" if r["nodes_with_decode_errors"] else ""),
                   flush=True)
    finally:
        hosts.close()
        shutil.rmtree(work, ignore_errors=True)
    failed = sum(r["all_matched_s"] is None for r in out)
    with_errors = sum(len(r["nodes_with_decode_errors"]) for r in out)
    print(f"{failed} of {len(out)} trials failed; {with_errors} of {len(out) * args.nodes} handshakes left a node "
          f"with decode errors; load at end {os.getloadavg()}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    soaklib.finish(soaklib.failures(out, trial_failed), len(out))


def trial_failed(r):
    """Why a trial failed (None: it passed)."""
    why = []
    if r["all_matched_s"] is None:
        why.append("not every node matched")
    if r["nodes_with_decode_errors"]:
        why.append(f"decode errors in {r['nodes_with_decode_errors']}")
    if any(c != 0 for c in r["exit_codes"]):
        why.append(f"exit codes {r['exit_codes']}")
    return "; ".join(why)


if __name__ == "__main__":
    main()
