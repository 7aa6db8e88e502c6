#!/usr/bin/env python3
"""WAN benchmark (issue 20, item 4): the end-to-end benchmark's (a)-(c) through the Zenoh
router against the direct LAN path, in one run of this program, plus the bridges' and
the router's CPU and RSS and the bytes a second on the WAN leg at 50 Hz.

    $EEZYBOT_PYTHON tests/bench/wan_e2e.py [--seconds 60] [--runs lan,wan[,wan_impaired]]
        [--device simavr|virtual] [--json FILE]

Runs (each in a process of its own, one after the other; a Fast DDS participant in a
process that had participants in another namespace's set discovers nothing, so the
probes of two layouts never share a process):
  lan           e2e.py's case (d) veth run: pc.sh in `pc`, pi.sh in `pi`, one veth
                between them, plain DDS across (twohost.TwoHosts).
  wan           the same graph in wanhost.WanHosts' namespaces pc, wan, pi: pc.sh and
                pi.sh in WAN mode (ZENOH_ROUTER=tls/10.77.0.1:7447, a CA of its own from
                wan_certs.sh), each starting eezybot_wan_bridge beside its nodes; the
                router (router.sh) in `wan`; clean veths, no delay. Nothing passes between
                pc and pi except through the router.
  wan_impaired  optional: as `wan` with linkem on the Pi's link to the router
                (--impairment, default 40 +- 10 ms each way, 2 % loss).
Everything else is e2e.py's: the operator probe (rclpy, in `pc`) sends targets along
e2e_analysis.TargetPath's smooth path at --rate (50 Hz) for --seconds after a 2 s warm-up;
the firmware runs in simavr behind pty_tap.py; e2e.analyze() computes the figures:
  (a) xyz_target -> servo_angles received by a probe in `pi` (probe_proc.py, Fast DDS's
      reception time), i.e. after the WAN leg in `wan`;
  (b) xyz_target -> the first byte of its SET_PULSES frame on the serial port (pi side);
  (c) xyz_target -> the pulse width changing on a pin, in simavr;
  round trip: xyz_target -> servo_state for that command back at the operator probe in
      `pc` (serial_node's reply after the device's ack: across the WAN both ways);
  the link alone, each way, probe to probe: servo_angles from the operator probe in `pc`
      (beside compute_ik) to the probe in `pi` (beside serial_node), and servo_state from a
      second probe in `pi` (probe_proc.py, beside serial_node) to the operator probe: the
      latency and the loss of the link itself, without compute_ik's and serial_node's
      newest-wins drops (the zero-loss target is judged on these), with the seconds of the
      window in which samples were lost.
The router's added latency: the `wan` run's p50/p99 minus the `lan` run's. The link's own
delay is zero on the clean runs (veths), so the added latency is that difference.

Also, during the --seconds window of each run:
  CPU (% of one core, utime+stime from /proc/PID/stat over the window) and RSS (VmRSS,
  VmHWM from /proc/PID/status at the end) of every node, of each bridge (the
  eezybot_wan_bridge child of pc.sh and of pi.sh) and of the router
  (e2e_harness.CpuWindow);
  bytes on the Pi's link to the router: the counters of its interface (eth0 in `pi`,
  `ip -s -j link`: Ethernet frames, both directions) before and after the window, and
  the TCP connection's own counters (`ss -ti` in `pi`: bytes_sent/bytes_received are
  TLS bytes, the TCP payload; segs_out/segs_in segments, pure ACKs included);
  the Pi bridge's connection to the router, polled once a second (ss): a new local port is
  the session made anew (the TCP counters are then not comparable and are left out);
  the pi namespace's UDP counters (/proc/net/snmp: receive-buffer drops);
  the payload: the serialized CDR size (rclpy raw subscriptions at the operator probe,
  encapsulation header included, as the bridge forwards it) of every servo_angles sample
  (PC -> Pi) and of every servo_state and serial_node's diagnostics sample (Pi -> PC)
  received in the window, per second.

Targets (issue 20): added latency over the link's own delay p50 <= 2 ms; zero loss at
50 Hz on a clean link; WAN bytes at 50 Hz <= 2x the payload; Pi-side bridge RSS <= 40 MB
and CPU < 5 % at 50 Hz. Timing is never asserted: the program prints what it measured and
whether each target is met.

Needs root (ip netns), release binaries (cargo build --release --bins; EEZYBOT_BIN_DIR),
the WAN binaries (cd wan && cargo build --release; EEZYBOT_WAN_BIN_DIR), openssl (the
certificates) and the firmware and its harness (make -C firmware/servo_control all sim).
About (--seconds + 25 s) per run.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

RUNS = ("lan", "wan", "wan_impaired")
TARGETS = {"added_latency_p50_ms": 2.0, "loss_at_50hz_clean": 0, "wan_bytes_over_payload": 2.0,
           "pi_bridge_rss_mb": 40.0, "pi_bridge_cpu_pct": 5.0}
ETH_HEADER = 14  # bytes on a veth per frame besides IP (the interface counters count them)


def log(s):
    print(s, flush=True)


def ms(values):
    import e2e_analysis as A
    return A.summary(values, 1e-6)


# ---------------------------------------------------------------- counters on a link
def link_counters(ns, ifname):
    """Bytes and packets of an interface in a namespace (`ip -s -j link`)."""
    out = subprocess.run(["ip", "-n", ns, "-s", "-j", "link", "show", "dev", ifname], capture_output=True, text=True,
                         check=True, timeout=30).stdout
    st = json.loads(out)[0]["stats64"]
    return {"rx_bytes": st["rx"]["bytes"], "rx_packets": st["rx"]["packets"], "rx_multicast": st["rx"].get("multicast"),
            "rx_dropped": st["rx"].get("dropped"), "tx_bytes": st["tx"]["bytes"], "tx_packets": st["tx"]["packets"],
            "tx_dropped": st["tx"].get("dropped")}


SS_KEYS = ("bytes_sent", "bytes_retrans", "bytes_acked", "bytes_received", "segs_out", "segs_in", "data_segs_out",
           "data_segs_in")


def tcp_counters(ns, peer):
    """The TCP connections of namespace `ns` to `peer` (ss -ti): their counters, summed,
    and how many connections."""
    out = subprocess.run(["ip", "netns", "exec", ns, "ss", "-tinH", "state", "established", "dst", peer],
                         capture_output=True, text=True, check=True, timeout=30).stdout
    tot = {k: 0 for k in SS_KEYS}
    conns = 0
    ports = []
    for line in out.splitlines():
        m = re.match(r"\s*\d+\s+\d+\s+\S+:(\d+)\s+\S+:\d+", line)
        if m:
            conns += 1
            ports.append(int(m.group(1)))
        for k in SS_KEYS:
            m = re.search(rf"\b{k}:(\d+)", line)
            if m:
                tot[k] += int(m.group(1))
    tot["connections"] = conns
    tot["ports"] = sorted(ports)
    return tot


class ConnectionWatch:
    """The local ports of `ns`'s TCP connections to `peer`, once a second (ss in the
    namespace) in a thread: a new port is the bridge's session to the router made anew."""

    def __init__(self, ns, peer, t0_ns, period=1.0):
        import threading
        self.ns, self.peer, self.t0, self.period = ns, peer, t0_ns, period
        self.seen = []  # [seconds since t0, ports]
        self.stop_event = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stop_event.wait(self.period):
            try:
                ports = tcp_counters(self.ns, self.peer)["ports"]
            except (subprocess.SubprocessError, OSError):
                continue
            self.seen.append([(time.time_ns() - self.t0) / 1e9, ports])

    def close(self):
        self.stop_event.set()
        self.thread.join(10)
        changes, last = [], None
        for t, ports in self.seen:
            if last is not None and ports != last:
                changes.append([round(t, 1), last, ports])
            last = ports
        return {"polls": len(self.seen), "changes": changes,
                "seconds_without_connection": sum(self.period for _, p in self.seen if not p)}


def udp_counters(ns):
    """The namespace's UDP counters (/proc/net/snmp): RcvbufErrors = datagrams dropped
    because a socket's receive buffer was full (a DDS reader not reading)."""
    out = subprocess.run(["ip", "netns", "exec", ns, "cat", "/proc/net/snmp"], capture_output=True, text=True,
                         check=True, timeout=30).stdout
    rows = [line.split()[1:] for line in out.splitlines() if line.startswith("Udp:")]
    return {k: int(v) for k, v in zip(rows[0], rows[1])} if len(rows) >= 2 else {}


def net_snapshot(hosts, kind):
    """Every counter of the run's links, now."""
    snap = {"t": time.monotonic()}
    if kind == "lan":
        snap["pi_link"] = link_counters(hosts.pi, hosts.pi_if)
        snap["pi_udp"] = udp_counters(hosts.pi)
        return snap
    import wanhost
    snap["pi_link"] = link_counters(hosts.pi, "eth0")
    snap["pc_link"] = link_counters(hosts.pc, "eth0")
    snap["pi_tcp"] = tcp_counters(hosts.pi, wanhost.ROUTER)
    snap["pc_tcp"] = tcp_counters(hosts.pc, wanhost.ROUTER)
    snap["pi_udp"] = udp_counters(hosts.pi)
    return snap


def net_delta(a, b):
    dt = b["t"] - a["t"]
    out = {"window_s": dt}
    for k in a:
        if k == "t":
            continue
        if a[k].get("ports") != b[k].get("ports"):
            # a connection made anew in the window: its counters started again from 0
            out[k] = {"reconnected": True, "ports_before": a[k].get("ports"), "ports_after": b[k].get("ports")}
            continue
        out[k] = {f: (b[k][f] - a[k][f]) if isinstance(a[k][f], int) and isinstance(b[k][f], int) else None
                  for f in a[k]}
        out[k]["connections"] = b[k].get("connections")
        out[k] = {f: v for f, v in out[k].items() if v is not None}
    return out


# ---------------------------------------------------------------- the payload, as it crosses
class PayloadCounter:
    """Raw (serialized CDR) samples at the operator probe in `pc`: size and reception
    time of every servo_angles, servo_state and serial_node diagnostics sample."""

    def __init__(self, run):
        import twohost
        from diagnostic_msgs.msg import DiagnosticArray
        from e2e_harness import DEEP
        from rclpy.serialization import deserialize_message
        from sensor_msgs.msg import JointState

        self.samples = {"servo_angles": [], "servo_state": [], "diagnostics_serial_node": [], "diagnostics_other": []}

        def keep(name):
            return lambda raw, info: self.samples[name].append((info["received_timestamp"], len(raw)))

        def diag(raw, info):
            m = deserialize_message(raw, DiagnosticArray)
            ours = any(s.name.startswith("serial_node") for s in m.status)
            self.samples["diagnostics_serial_node" if ours else "diagnostics_other"].append(
                (info["received_timestamp"], len(raw)))

        with twohost.netns(run.op.netns):
            n = run.op.node
            n.create_subscription(JointState, "/servo_angles", keep("servo_angles"), DEEP, raw=True)
            n.create_subscription(JointState, "/servo_state", keep("servo_state"), DEEP, raw=True)
            n.create_subscription(DiagnosticArray, "/diagnostics", diag, DEEP, raw=True)

    def window(self, t0, t1):
        """Per topic: samples, bytes, mean size, per second in [t0, t1] (ns)."""
        dt = (t1 - t0) / 1e9
        out = {}
        for k, v in self.samples.items():
            sizes = [n for t, n in v if t0 <= t <= t1]
            out[k] = {"samples": len(sizes), "bytes": sum(sizes), "mean_size": sum(sizes) / len(sizes) if sizes else None,
                      "min_size": min(sizes, default=None), "max_size": max(sizes, default=None),
                      "samples_per_s": len(sizes) / dt, "bytes_per_s": sum(sizes) / dt}
        return out


# ---------------------------------------------------------------- one run (in a process of its own)
def wan_pids(run):
    """{label: pid} of the bridges (pc.sh's and pi.sh's eezybot_wan_bridge) and the router."""
    from e2e_harness import descendants, proc_sample
    out = {}
    for p in run.procs:
        if not p.name.endswith(".sh") or p.proc.poll() is not None:
            continue
        side = p.name[:-3]
        for c in descendants(p.proc.pid):
            s = proc_sample(c)
            if s and s[0].startswith("eezybot_wan"):
                out[f"bridge {side} (eezybot_wan_bridge {side})"] = c
    router = getattr(run.hosts, "router", None)
    if router is not None and router.poll() is None:
        out["router (eezybot_wan_router)"] = router.pid
    return out


def worker(kind, args):
    import e2e
    import e2e_analysis as A
    import wanhost
    from e2e_harness import CpuWindow, GraphRun

    impaired = json.loads(args.impairment) if kind == "wan_impaired" else None
    certs_dir = certs = None
    if kind != "lan":
        certs_dir = Path(tempfile.mkdtemp(prefix="wan-e2e-certs-"))
        certs = wanhost.make_certs(certs_dir / "ca")

    def wan_hosts(run):
        """wanhost.WanHosts with the router started; pc.sh and pi.sh get its WAN environment."""
        hosts = wanhost.WanHosts(tag="b", impaired=impaired)
        try:
            hosts.start_router(certs, run.workdir / "router.log")
            run.extra_env.update(hosts.graph_env(certs))
        except BaseException:
            hosts.close()
            raise
        return hosts

    log(f"--- run `{kind}`: {'direct veth (DDS)' if kind == 'lan' else 'through the router'}"
        f"{' impaired ' + json.dumps(impaired) if impaired else ''}, device {args.device}, "
        f"{args.rate:g} Hz x {args.seconds:g} s")
    path = A.TargetPath("smooth")
    run = GraphRun(kind, path, layout="split", device=args.device, firmware=args.firmware,
                   clock_ppm=e2e.clock_ppm(args), log=log,
                   hosts_factory=None if kind == "lan" else wan_hosts)
    t_start = time.time()
    state_probe = None
    try:
        run.start()
        payload = PayloadCounter(run)
        # servo_state as serial_node publishes it on the Pi's LAN (a probe beside it, in a
        # process of its own): what the way back lost, and when it left
        from conftest import NodeProcess
        state_out, state_status = run.workdir / "pi_state.json", run.workdir / "pi_state.status"
        state_probe = NodeProcess(sys.executable, [str(HERE / "probe_proc.py"), str(state_out), str(state_status),
                                                   "/servo_state"], run.lease.id, netns=run.hosts.pi)
        run.wait_flowing(timeout=90 if kind != "lan" else 25)
        run.drive(args.rate, 2.0, "warmup")
        pids = {**run.node_pids(), **run.helper_pids(), **wan_pids(run)}
        net0 = net_snapshot(run.hosts, kind)
        window = CpuWindow(pids)
        t_measure = time.time_ns()
        watch = ConnectionWatch(run.hosts.pi, wanhost.ROUTER, t_measure) if kind != "lan" else None
        run.drive(args.rate, args.seconds, "measure")
        t_end = time.time_ns()
        cpu = window.close()
        net1 = net_snapshot(run.hosts, kind)
        connections = watch.close() if watch else None
        run.spin(time.monotonic() + (8.0 if impaired else 2.0))  # late replies still count
        router_log = None
        if kind != "lan":
            router_log = (run.workdir / "router.log")
    finally:
        pi_state = {}
        if state_probe is not None:
            state_probe.stop()
            try:
                pi_state = {int(k): v for k, v in json.loads(state_out.read_text())["tables"]["/servo_state"].items()}
            except (OSError, ValueError, KeyError) as e:
                log(f"    the servo_state probe in pi left no data: {e}")
        run.stop()
    log(f"    done in {time.time() - t_start:.0f} s; exit codes {run.exit_codes}")
    r = {"run": run, "cpu": cpu, "t_measure": t_measure, "t_end": t_end, "path": path, "layout": "split",
         "nodes": "graph", "drive": "rclpy", "ws_sent": None}
    out = e2e.analyze(r, args)
    out["config"]["run"] = kind
    out["config"]["impairment"] = impaired
    sent = [s for s, _, phase in run.sent if phase == "measure"]
    st = run.pc_probe.servo_state
    out["round_trip"] = {"lost": sum(1 for s in sent if s not in st),
                         "latency_ms": ms(st[s][0] - s for s in sent if s in st),
                         "what": "xyz_target -> servo_state with that stamp at the operator probe in pc"}
    out["crossing"] = crossing(run, sent, pi_state, t_measure, t_end)
    out["net"] = net_delta(net0, net1)
    out["pi_router_connection"] = connections
    out["payload"] = payload.window(t_measure, t_end)
    out["pids"] = pids
    if router_log is not None and router_log.exists():
        out["router_log_tail"] = router_log.read_text()[-1500:]
    logs = {}
    for p in run.procs:
        try:
            logs[p.name] = str(p.log_path)
        except Exception:  # noqa: BLE001
            pass
    out["logs"] = logs
    import shutil
    if not args.keep:
        shutil.rmtree(run.workdir, ignore_errors=True)
        if certs_dir is not None:
            shutil.rmtree(certs_dir, ignore_errors=True)
    return out


def crossing(run, sent, pi_state, t_measure, t_end):
    """The link alone, each way, from probe to probe (Fast DDS reception times, one clock):
    servo_angles from the operator probe in pc (beside compute_ik) to the probe in pi
    (beside serial_node), for the targets sent in the window; servo_state from the probe
    in pi to the operator probe in pc, for the samples serial_node published in the
    window. Losses of compute_ik (newest wins) and of serial_node (replaced before its
    frame slot) are not in these figures."""
    pc, pi = run.pc_probe, run.pi_probe
    out = {}
    if pi is not None:
        both = [s for s in sent if s in pc.servo_angles]
        got = [s for s in both if s in pi.servo_angles]
        lat = [pi.servo_angles[s][0] - pc.servo_angles[s][0] for s in got]
        out["servo_angles_pc_to_pi"] = {"in_pc": len(both), "lost": len(both) - len(got), "latency_ms": ms(lat),
                                        "over_20ms": slow_windows(got, lat),
                                        "per_second_lost": per_second(both, set(got), t_measure)}
    left = [s for s, v in pi_state.items() if t_measure <= v[0] <= t_end]
    got = [s for s in left if s in pc.servo_state]
    lat = [pc.servo_state[s][0] - pi_state[s][0] for s in got]
    out["servo_state_pi_to_pc"] = {"in_pi": len(left), "lost": len(left) - len(got), "latency_ms": ms(lat),
                                   "over_20ms": slow_windows(got, lat),
                                   "per_second_lost": per_second(left, set(got), t_measure)}
    return out


def per_second(stamps, got, t0):
    """Lost samples per second of the window: [[second, samples, lost], ...] (seconds
    with a loss only)."""
    rows = {}
    for s in stamps:
        k = max(0, (s - t0) // 1_000_000_000)
        row = rows.setdefault(k, [k, 0, 0])
        row[1] += 1
        row[2] += s not in got
    return [r for _, r in sorted(rows.items()) if r[2]]


def slow_windows(stamps, lat_ns, limit_ns=20_000_000):
    """How many samples took over 20 ms, and in how many distinct seconds of the run."""
    slow = [s for s, v in zip(stamps, lat_ns) if v > limit_ns]
    return {"samples": len(slow), "distinct_seconds": len({s // 1_000_000_000 for s in slow})}


# ---------------------------------------------------------------- the comparison
def wan_bytes(res):
    """Bytes a second on the Pi's link to the router against the payload, each way."""
    net, pay = res["net"], res["payload"]
    dt = net["window_s"]
    out_payload = pay["servo_angles"]["bytes_per_s"]
    back_payload = pay["servo_state"]["bytes_per_s"] + pay["diagnostics_serial_node"]["bytes_per_s"]
    link = net["pi_link"]
    d = {"window_s": dt,
         "payload_to_pi_Bps": out_payload, "payload_from_pi_Bps": back_payload,
         "link_to_pi_Bps": link["rx_bytes"] / dt, "link_from_pi_Bps": link["tx_bytes"] / dt,
         "link_to_pi_pkts_per_s": link["rx_packets"] / dt, "link_from_pi_pkts_per_s": link["tx_packets"] / dt}
    d["ratio_to_pi"] = d["link_to_pi_Bps"] / out_payload if out_payload else None
    d["ratio_from_pi"] = d["link_from_pi_Bps"] / back_payload if back_payload else None
    tot_pay = out_payload + back_payload
    d["ratio_total"] = (d["link_to_pi_Bps"] + d["link_from_pi_Bps"]) / tot_pay if tot_pay else None
    tcp = net.get("pi_tcp")
    if tcp and tcp.get("reconnected"):
        d["tcp_reconnected"] = True
    elif tcp:
        d["tls_to_pi_Bps"] = tcp["bytes_received"] / dt
        d["tls_from_pi_Bps"] = tcp["bytes_sent"] / dt
        d["segs_to_pi_per_s"] = tcp["segs_in"] / dt
        d["segs_from_pi_per_s"] = tcp["segs_out"] / dt
        d["data_segs_to_pi_per_s"] = tcp["data_segs_in"] / dt
        d["data_segs_from_pi_per_s"] = tcp["data_segs_out"] / dt
        d["retransmitted_bytes"] = tcp["bytes_retrans"]
        d["tcp_connections"] = tcp["connections"]
        # what the interface carried that was not this TCP connection (DDS multicast
        # discovery of the Pi's LAN leaving on eth0, ARP...): frames minus TCP payload and
        # 66 bytes of Ethernet + IP + TCP (with timestamps) per segment
        d["headers_per_segment_assumed"] = ETH_HEADER + 20 + 32
        d["other_to_pi_Bps"] = d["link_to_pi_Bps"] - d["tls_to_pi_Bps"] - d["segs_to_pi_per_s"] * 66
        d["other_from_pi_Bps"] = d["link_from_pi_Bps"] - d["tls_from_pi_Bps"] - d["segs_from_pi_per_s"] * 66
        d["tcp_only_ratio_to_pi"] = ((d["tls_to_pi_Bps"] + d["segs_to_pi_per_s"] * 66) / out_payload
                                     if out_payload else None)
        d["tcp_only_ratio_from_pi"] = ((d["tls_from_pi_Bps"] + d["segs_from_pi_per_s"] * 66) / back_payload
                                       if back_payload else None)
        d["tcp_only_ratio_total"] = ((d["tls_to_pi_Bps"] + d["tls_from_pi_Bps"]
                                      + (d["segs_to_pi_per_s"] + d["segs_from_pi_per_s"]) * 66) / tot_pay
                                     if tot_pay else None)
        # per data segment (one Zenoh batch in one TLS record, one sample at 50 Hz):
        # TLS + Zenoh bytes beyond the payload
        n_out = pay["servo_angles"]["samples_per_s"]
        n_back = pay["servo_state"]["samples_per_s"] + pay["diagnostics_serial_node"]["samples_per_s"]
        if n_out:
            d["tls_bytes_per_servo_angles_sample"] = d["tls_to_pi_Bps"] / n_out
            d["payload_per_servo_angles_sample"] = out_payload / n_out
        if n_back:
            d["tls_bytes_per_sample_from_pi"] = d["tls_from_pi_Bps"] / n_back
            d["payload_per_sample_from_pi"] = back_payload / n_back
    return d


def fmt(st, k):
    v = (st or {}).get(k)
    return f"{v:8.3f}" if v is not None else "       -"


def met(ok):
    return "met" if ok else "NOT MET"


def report(res, args):
    runs = [k for k in RUNS if k in res]
    print(f"\n== (a)-(c), {args.rate:g} Hz x {args.seconds:g} s, device {args.device}: p50 / p99 / max ms, lost")
    rows = [("(a) xyz_target -> servo_angles in pi", lambda r: (r["a_across"]["latency_ms"], r["a_across"]["lost"],
                                                                r["sent"])),
            ("    (servo_angles in pc, beside compute_ik)", lambda r: (r["a"]["latency_ms"], r["a"]["lost"], r["sent"])),
            ("(b) xyz_target -> first byte on the port", lambda r: (r["b"]["latency_ms"], r["b"]["lost"],
                                                                    r["sent"] - r["a"]["lost"])),
            ("(c) xyz_target -> new pulse width on a pin", lambda r: (r["c"]["latency_ms"], r["c"]["lost"],
                                                                      r["c"]["commands"])),
            ("round trip: xyz_target -> servo_state in pc", lambda r: (r["round_trip"]["latency_ms"],
                                                                       r["round_trip"]["lost"], r["sent"])),
            ("link alone: servo_angles, probe in pc -> probe in pi",
             lambda r: (r["crossing"]["servo_angles_pc_to_pi"]["latency_ms"],
                        r["crossing"]["servo_angles_pc_to_pi"]["lost"], r["crossing"]["servo_angles_pc_to_pi"]["in_pc"])),
            ("link alone: servo_state, probe in pi -> probe in pc",
             lambda r: (r["crossing"]["servo_state_pi_to_pc"]["latency_ms"],
                        r["crossing"]["servo_state_pi_to_pc"]["lost"], r["crossing"]["servo_state_pi_to_pc"]["in_pi"]))]
    for label, get in rows:
        print(f"  {label}")
        for k in runs:
            try:
                st, lost, n = get(res[k])
            except KeyError:
                print(f"      {k:<13} no data")
                continue
            print(f"      {k:<13} p50 {fmt(st, 'p50')}  p99 {fmt(st, 'p99')}  max {fmt(st, 'max')}  "
                  f"n {st.get('n', 0):5d}  lost {lost}/{n}")
        if "lan" in res and "wan" in res:
            try:
                a, b = get(res["lan"])[0], get(res["wan"])[0]
                print(f"      {'router adds':<13} p50 {b['p50'] - a['p50']:8.3f}  p99 {b['p99'] - a['p99']:8.3f}  "
                      f"max {b['max'] - a['max']:8.3f}")
            except (KeyError, TypeError):
                pass
    cmp = {}
    if "lan" in res and "wan" in res:
        lan, wan = res["lan"], res["wan"]
        added = wan["a_across"]["latency_ms"]["p50"] - lan["a_across"]["latency_ms"]["p50"]
        added_b = wan["b"]["latency_ms"]["p50"] - lan["b"]["latency_ms"]["p50"]
        cmp["added_latency_a_p50_ms"] = added
        cmp["added_latency_b_p50_ms"] = added_b
        lost = wan["a_across"]["lost"]
        cmp["wan_loss_a"] = lost
        cr = wan["crossing"]
        lost_out, lost_back = cr["servo_angles_pc_to_pi"]["lost"], cr["servo_state_pi_to_pc"]["lost"]
        cmp["wan_link_loss"] = {"servo_angles": lost_out, "servo_state": lost_back}
        print(f"\n  target: the router adds <= {TARGETS['added_latency_p50_ms']:g} ms p50 (clean link, its own delay 0): "
              f"(a) {added:+.3f} ms, (b) {added_b:+.3f} ms: {met(added <= TARGETS['added_latency_p50_ms'])}")
        print(f"  target: zero loss at 50 Hz on a clean link, the link alone (probe to probe, each way): "
              f"servo_angles {lost_out} of {cr['servo_angles_pc_to_pi']['in_pc']} lost, servo_state {lost_back} of "
              f"{cr['servo_state_pi_to_pc']['in_pi']} lost: {met(lost_out == 0 and lost_back == 0)}; "
              f"samples over 20 ms: {cr['servo_angles_pc_to_pi']['over_20ms']}, {cr['servo_state_pi_to_pc']['over_20ms']}")
        print(f"          end to end (nodes' newest-wins drops included): (a) {lost} of {wan['sent']} lost in pi "
              f"({wan['a']['lost']} of them already at compute_ik), (b) {wan['b']['lost']}, (c) {wan['c']['lost']}, "
              f"round trip {wan['round_trip']['lost']}; lan: (a) {lan['a_across']['lost']}, (b) {lan['b']['lost']}, "
              f"round trip {lan['round_trip']['lost']}"
              + ("" if not wan.get("sender_skipped_slots", {}).get("measure") else
                 f" ({wan['sender_skipped_slots']['measure']} slots skipped by the bench itself)"))
    print("\n== CPU (% of one core) and RSS over the 50 Hz window")
    for k in runs:
        print(f"  run `{k}`")
        for name, v in sorted(res[k]["cpu"].items()):
            note = ""
            if name.startswith("bridge pi") and k == "wan":
                ok = v["rss_mb"] <= TARGETS["pi_bridge_rss_mb"] and v["cpu_pct"] < TARGETS["pi_bridge_cpu_pct"]
                cmp["pi_bridge"] = {"cpu_pct": v["cpu_pct"], "rss_mb": v["rss_mb"], "met": ok}
                note = f"  target RSS <= 40 MB, CPU < 5 %: {met(ok)}"
            print(f"    {name:<40} CPU {v['cpu_pct']:6.2f} %   RSS {v['rss_mb']:6.1f} MB (peak {v['rss_peak_mb']:.1f})"
                  f"{note}")
    print("\n== bytes a second on the Pi's link (interface counters of its eth0; to pi = rx, from pi = tx)")
    for k in runs:
        d = wan_bytes(res[k])
        res[k]["wan_bytes"] = d
        p = res[k]["payload"]
        print(f"  run `{k}`: payload to pi {d['payload_to_pi_Bps']:.0f} B/s (servo_angles "
              f"{p['servo_angles']['samples_per_s']:.1f}/s x {p['servo_angles']['mean_size'] or 0:.1f} B); "
              f"from pi {d['payload_from_pi_Bps']:.0f} B/s (servo_state {p['servo_state']['samples_per_s']:.1f}/s x "
              f"{p['servo_state']['mean_size'] or 0:.1f} B, serial_node diagnostics "
              f"{p['diagnostics_serial_node']['samples_per_s']:.2f}/s x {p['diagnostics_serial_node']['mean_size'] or 0:.0f} B)")
        print(f"    link to pi {d['link_to_pi_Bps']:.0f} B/s ({d['link_to_pi_pkts_per_s']:.1f} pkt/s) = "
              f"{d['ratio_to_pi'] or 0:.2f}x payload; from pi {d['link_from_pi_Bps']:.0f} B/s "
              f"({d['link_from_pi_pkts_per_s']:.1f} pkt/s) = {d['ratio_from_pi'] or 0:.2f}x; both ways "
              f"{d['ratio_total'] or 0:.2f}x")
        if d.get("tcp_reconnected"):
            print("    the Pi's TCP connection to the router was made anew in the window: its counters are not comparable")
        udp = res[k]["net"].get("pi_udp") or {}
        if udp:
            print(f"    UDP in the pi namespace over the window: {udp.get('OutDatagrams', 0)} sent, "
                  f"{udp.get('InDatagrams', 0)} received, {udp.get('RcvbufErrors', 0)} dropped for a full receive "
                  f"buffer, {udp.get('SndbufErrors', 0)} send buffer errors")
        if res[k].get("pi_router_connection"):
            c = res[k]["pi_router_connection"]
            print(f"    the Pi bridge's connection to the router, polled {c['polls']} times: "
                  f"{len(c['changes'])} changes {c['changes'][:6]}, ~{c['seconds_without_connection']:.0f} s without")
        if "tls_to_pi_Bps" in d:
            print(f"    TCP connection to the router ({d['tcp_connections']}): TLS bytes to pi {d['tls_to_pi_Bps']:.0f} B/s "
                  f"in {d['segs_to_pi_per_s']:.1f} seg/s ({d['data_segs_to_pi_per_s']:.1f} with data), from pi "
                  f"{d['tls_from_pi_Bps']:.0f} B/s in {d['segs_from_pi_per_s']:.1f} seg/s "
                  f"({d['data_segs_from_pi_per_s']:.1f} with data); retransmitted {d['retransmitted_bytes']} B")
            print(f"    per servo_angles sample: {d.get('tls_bytes_per_servo_angles_sample', 0):.1f} TLS bytes for "
                  f"{d.get('payload_per_servo_angles_sample', 0):.1f} B payload; per sample from pi: "
                  f"{d.get('tls_bytes_per_sample_from_pi', 0):.1f} TLS bytes for {d.get('payload_per_sample_from_pi', 0):.1f} B")
            print(f"    TCP alone (TLS bytes + 66 B Ethernet/IP/TCP per segment): {d['tcp_only_ratio_to_pi']:.2f}x to pi, "
                  f"{d['tcp_only_ratio_from_pi']:.2f}x from pi, {d['tcp_only_ratio_total']:.2f}x both ways; "
                  f"other traffic on the link (DDS multicast of the Pi's LAN, ARP): {d['other_to_pi_Bps']:.0f} B/s in, "
                  f"{d['other_from_pi_Bps']:.0f} B/s out")
            if k == "wan":
                # the WAN leg is the TCP connection to the router: the Pi's LAN multicast also
                # leaves on this namespace's one interface, but never reaches a router
                ok = d["tcp_only_ratio_total"] <= TARGETS["wan_bytes_over_payload"]
                cmp["wan_bytes_ratio_total"] = d["tcp_only_ratio_total"]
                cmp["wan_bytes_ratio_to_pi"] = d["tcp_only_ratio_to_pi"]
                cmp["wan_bytes_ratio_from_pi"] = d["tcp_only_ratio_from_pi"]
                cmp["wan_bytes_met"] = ok
                print(f"    target: WAN bytes at 50 Hz <= 2x the payload (the TCP connection to the router, "
                      f"frames as on the wire): {d['tcp_only_ratio_total']:.2f}x both ways (to pi "
                      f"{d['tcp_only_ratio_to_pi']:.2f}x, from pi {d['tcp_only_ratio_from_pi']:.2f}x): {met(ok)}; "
                      f"the interface's counters with the Pi's LAN multicast: {d['ratio_total']:.2f}x")
    for k in runs:
        cr = res[k].get("crossing", {})
        for way, v in cr.items():
            if v.get("per_second_lost"):
                print(f"  run `{k}`, {way}: lost in these seconds of the window [second, samples, lost]: "
                      f"{v['per_second_lost'][:12]}")
    if "wan_impaired" in res:
        imp = res["wan_impaired"]
        print(f"\n== impaired WAN {json.dumps(imp['config']['impairment'])}: see the rows `wan_impaired` above; "
              f"linkem: {json.dumps(imp.get('linkem'))[:300]}")
    return cmp


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0, help="measuring time per run (default 60)")
    ap.add_argument("--rate", type=float, default=50.0, help="target rate (default 50 Hz)")
    ap.add_argument("--runs", default="lan,wan", help="comma-separated, in order: lan, wan, wan_impaired "
                    "(default lan,wan)")
    ap.add_argument("--impairment", default=json.dumps(dict(delay_ms=40, jitter_ms=10, loss=0.02)),
                    help="linkem's arguments for wan_impaired, JSON (default 40 +- 10 ms, 2 %% loss)")
    ap.add_argument("--device", choices=["simavr", "virtual"], default="simavr")
    ap.add_argument("--avr-clock-ppm", type=float, help="as e2e.py's")
    ap.add_argument("--firmware", default=str(HERE.parents[1] / "firmware" / "servo_control"))
    ap.add_argument("--keep", action="store_true", help="keep each run's directory")
    ap.add_argument("--json", help="write every figure here")
    ap.add_argument("--worker", choices=RUNS, help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    args = ap.parse_args()
    args.send_rate = None  # e2e.analyze: serial_node's default
    args.path = "smooth"
    if args.worker:
        res = worker(args.worker, args)
        Path(args.out).write_text(json.dumps(res, default=str))
        return 0
    runs = [r for r in args.runs.split(",") if r]
    if set(runs) - set(RUNS):
        ap.error(f"unknown run in {args.runs}")
    import e2e
    meta = e2e.machine()
    meta["args"] = vars(args)
    meta["wan_bin_dir"] = os.environ.get("EEZYBOT_WAN_BIN_DIR")
    log(f"WAN benchmark {meta['date']} on {meta['host']} ({meta['cpu']}, {meta['cores']} cores), load "
        f"{meta['loadavg_start']}, commit {meta['git']}; runs {runs}, about {len(runs) * (args.seconds + 30) / 60:.1f} min")
    res = {}
    passthrough = ["--seconds", str(args.seconds), "--rate", str(args.rate), "--impairment", args.impairment,
                   "--device", args.device, "--firmware", args.firmware] + (["--keep"] if args.keep else []) + (
        ["--avr-clock-ppm", str(args.avr_clock_ppm)] if args.avr_clock_ppm is not None else [])
    for kind in runs:
        with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
            out = Path(f.name)
        p = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", kind, "--out", str(out),
                            *passthrough])
        if p.returncode != 0 or not out.stat().st_size:
            log(f"run `{kind}` failed (exit {p.returncode})")
            out.unlink(missing_ok=True)
            continue
        res[kind] = json.loads(out.read_text())
        out.unlink()
    meta["loadavg_end"] = os.getloadavg()
    if res:
        res["comparison"] = report(res, args)
    e2e.print_load_and_write_json(meta, TARGETS, res, args)
    return 0 if len(res) > len(runs) else 1


if __name__ == "__main__":
    sys.exit(main())
