#!/usr/bin/env python3
"""Soak: 25 s network outages of the Raspberry Pi with SROS2 on (issue 18, item 6).

compute_ik in namespace `pc`, serial_node (port:=mock, its built-in virtual Arduino) in
`pi` across a veth, both under their enclaves of a keystore made by
launch_scripts/keystore.sh (ROS_SECURITY_ENABLE=true, Enforce, --enclave /eezybot/pc or
/eezybot/pi); the operator is tests/interop/sros2_peer under the pc enclave in `pc`,
sending the smooth path's targets at 50 Hz all the time (rclpy from PyPI has no DDS
Security). Each trial pulls pi's end of the veth for --length s (longer than every lease:
the participants lose each other, and the security handshakes are redone), plugs it back
(multicast route re-added, as a DHCP client does), and records the time from link-up to
the first servo_state read by the peer, and to the first one answering a target sent
after link-up (the resume time), with how many participants the peer dropped and how
many handshakes it completed after. One graph lives through every trial.

    sudo $EEZYBOT_PYTHON tests/soak/secure_outages.py [--trials 20] [--length 25] [--settle 5]
        [--unsecured] [--json FILE]

20 trials of 25 s take about 12 minutes. --unsecured runs the same without security
(the control). It prints each trial and whether the issue's target (resume within 5 s,
20 of 20) is met, and exits 1 if a trial missed it, a process did not exit 0, or the
run was interrupted.
"""
import argparse
import signal
import sys
import time
from pathlib import Path

import soaklib  # first: it puts tests/ on sys.path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))

import secure_harness as S  # noqa: E402
import twohost  # noqa: E402
from conftest import DomainLease  # noqa: E402

RESUME_WITHIN_S = 5.0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--length", type=float, default=25.0, help="seconds the link is down")
    ap.add_argument("--settle", type=float, default=5.0, help="seconds of traffic after a resume before the next cut")
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--unsecured", action="store_true", help="the control: no security anywhere")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    # Ctrl-C or kill (SIGINT, SIGTERM) ends the soak with the trials so far, the nodes
    # stopped and the namespaces deleted (a shell starts background jobs with SIGINT ignored)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.default_int_handler)
    soaklib.need_two_hosts()
    work = S.keystore_dir()
    name = "unsecured" if args.unsecured else "secured"
    variant = S.variants(work, name)[name]
    lease = DomainLease()
    results = []
    codes = skipped = None
    interrupted = False
    t_start = time.time()
    print(f"secure_outages: {args.trials} x {args.length:g} s at pi, {name}, targets at {args.rate:g} Hz, "
          f"ROS domain {lease.id}", flush=True)
    try:
        with twohost.TwoHosts(tag="w") as hosts:
            g = None
            try:
                g = S.OutageGraph(hosts, lease.id, variant, rate=args.rate)
                print(f"first reply {g.wait_flowing(60):.2f} s after start", flush=True)
                for trial in range(args.trials):
                    t_settle = time.monotonic()
                    time.sleep(args.settle)
                    # is the graph answering before this cut (after a trial that did not resume)?
                    before = len([1 for t, _ in g.peer.said("recv rt/servo_state ") if t >= t_settle])
                    r = soaklib.outage(g, results, trial, args.length, "pi", servo_state_in_the_settle_before=before)
                    print(f"trial {trial + 1:2d}: first servo_state {fmt(r['first_servo_state_s'])} after link-up, "
                          f"resumed (a new target answered) after {fmt(r['resume_s'])}; participants dropped "
                          f"{r['participants_dropped_during']}, handshakes after {r['handshakes_after']}; servo_state samples in the "
                          f"{args.settle:g} s before the cut {before}", flush=True)
                    if r["resume_s"] is None:
                        print("  did not resume within 30 s: the soak goes on (the graph may still come back)",
                              flush=True)
            except KeyboardInterrupt:
                interrupted = True
                print("interrupted: the trials so far", flush=True)
            finally:
                if g is not None:
                    codes = g.close()
                    skipped = g.skipped
    finally:
        lease.release()
        import shutil
        shutil.rmtree(work, ignore_errors=True)
    resume = [r["resume_s"] for r in results if r["resume_s"] is not None]
    within = sum(1 for v in resume if v <= RESUME_WITHIN_S)
    summary = {"variant": name, "trials": len(results), "length_s": args.length, "resumed": len(resume),
               "resumed_within_5s": within,
               **soaklib.p50_max("resume", resume),
               **soaklib.p50_max("first_servo_state", (r["first_servo_state_s"] for r in results)),
               "handshakes_after_min": min((r["handshakes_after"] for r in results), default=None),
               "sender_skipped_slots": skipped, "exit_codes": codes}
    print(f"\n{name}: {len(results)} outages of {args.length:g} s at pi: resumed within 5 s {within}/{len(results)} "
          f"(target 20 of 20: {'met' if within == len(results) == 20 else 'NOT MET' if len(results) >= 20 else 'partial run'}); "
          f"resume p50 {fmt(summary['resume_p50_s'])}, max {fmt(summary['resume_max_s'])}; first servo_state p50 "
          f"{fmt(summary['first_servo_state_p50_s'])}, max {fmt(summary['first_servo_state_max_s'])}")
    print(f"exit codes {codes}, sender skipped {skipped} slots, {time.time() - t_start:.0f} s in all")
    soaklib.write_json(args.json, summary, "%Y-%m-%d %H:%M:%S", trials=results)
    bad = soaklib.failures(results, trial_failed)
    bad += [f"{proc} exited {code}" for proc, code in (codes or {}).items() if code != 0]
    if interrupted or len(results) < args.trials:
        bad.append(f"interrupted after {len(results)} of {args.trials} trials")
    soaklib.finish(bad, len(results))


def trial_failed(r):
    """Why a trial failed (None: it passed): it did not resume within 5 s."""
    if r["resume_s"] is None or r["resume_s"] > RESUME_WITHIN_S:
        return f"resumed after {fmt(r['resume_s'])}"
    return None


def fmt(v):
    return "-" if v is None else f"{v:.2f} s"


if __name__ == "__main__":
    main()
