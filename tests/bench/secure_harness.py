"""The machinery of the SROS2 benchmark (secure_e2e.py) and the secured outage soak
(tests/soak/secure_outages.py): issue 18, item 6.

rclpy from PyPI has no DDS Security, so in a secured graph the probe is
tests/interop/sros2_peer (Debian's Fast DDS 2.9 with its security plugins, driven by
tests/security_rig.py). To compare like with like the SAME peer is the probe of the
unsecured runs too, then with no enclave, and the nodes get no ROS_SECURITY_* at all.

- `Variant`: "unsecured" or "secured" (the keystore of launch_scripts/keystore.sh; the
  nodes under ROS_SECURITY_ENABLE=true, Enforce, `--ros-args --enclave /eezybot/pc`
  (compute_ik) or `/eezybot/pi` (serial_node); the peer under the pc enclave).
- `TimedPeer`: a SecurePeer that also keeps CLOCK_REALTIME (ns) for every line it reads,
  the clock of the header stamps.
- `LatencyRun`: e2e_harness.GraphRun with the peer as the operator and probe instead of
  rclpy, and the nodes started directly (not through pc.sh/pi.sh, whose arguments the
  enclaves are not in): compute_ik and serial_node in one namespace (e2e's "same host"),
  serial_node on pty_tap in front of the firmware in simavr (or the virtual Arduino).
  Its pc_probe is filled from the peer's lines after the run, in e2e_harness.Probe's
  shape, so e2e.analyze() computes (a), (b) and (c) exactly as for e2e.py.
- `start_to_match()`: one node started with the peer already up; the time from the
  node's start to the peer's `matched` lines.
- `OutageGraph`: compute_ik in `pc`, serial_node (port:=mock) in `pi` across a veth, the
  peer in `pc` streaming targets at 50 Hz from a thread; `outage(25)` cuts pi's end of
  the veth, restores it (multicast route re-added: twohost.TwoHosts.restore) and times
  the first servo_state to reach the peer again.
"""
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import e2e_analysis as A  # noqa: E402
import twohost  # noqa: E402
from conftest import DomainLease, NodeProcess, bin_path  # noqa: E402
from e2e_harness import GraphRun, Probe  # noqa: E402
from security_rig import NO_SECURITY, SecurePeer, dds_topic, make_keystore, security_env  # noqa: E402

PC_ENCLAVE, PI_ENCLAVE = "/eezybot/pc", "/eezybot/pi"


# ---------------------------------------------------------------- secured or not
class Variant:
    def __init__(self, name, keystore=None):
        self.name, self.keystore = name, keystore
        self.secured = keystore is not None

    def env(self):
        return security_env(self.keystore) if self.secured else dict(NO_SECURITY)

    def node_args(self, node):
        if not self.secured:
            return []
        return ["--enclave", PI_ENCLAVE if node == "serial_node" else PC_ENCLAVE]

    def peer_enclave(self):
        return self.keystore.enclave(PC_ENCLAVE) if self.secured else None

    def __repr__(self):
        return self.name


def variants(workdir, order="unsecured,secured"):
    """{name: Variant}, the secured one with a new keystore in `workdir`."""
    out = {}
    for name in order.split(","):
        if name == "secured":
            out[name] = Variant(name, make_keystore(Path(workdir) / "keystore"))
        elif name == "unsecured":
            out[name] = Variant(name)
        else:
            raise ValueError(f"unknown variant {name}")
    return out


def probe_binary(kind):
    """The probe program: "fastdds" (tests/interop/sros2_peer, Debian's Fast DDS: None,
    SecurePeer's default) or "rust" (ros_plumbing's ros_probe example: ros2-client over
    RustDDS, as our gui_bridge talks to the graph)."""
    if kind == "fastdds":
        return None
    if kind == "rust":
        return bin_path("examples/ros_probe")
    raise ValueError(f"unknown probe {kind}")


def start_node(node, variant, domain, netns, ros_args=()):
    """One of our binaries, secured or not: a conftest.NodeProcess (pid = the node's:
    `ip netns exec` execs it in place)."""
    args = list(ros_args) + variant.node_args(node)
    return NodeProcess(node, ["--ros-args", *args] if args else [], domain, env=variant.env(), netns=netns)


# ---------------------------------------------------------------- the peer
class TimedPeer(SecurePeer):
    """A SecurePeer whose reader also keeps time.time_ns() of every line (self.real,
    index for index with self.lines)."""

    def __init__(self, *a, **kw):
        self.real = []
        super().__init__(*a, **kw)

    def _read(self):
        for line in self.proc.stdout:
            t_real, t_mono = time.time_ns(), time.monotonic()
            with self._cv:
                self.lines.append((t_mono, line.rstrip("\n")))
                self.real.append(t_real)
                self._cv.notify_all()

    def received_real(self, topic, since=0):
        """[(time.time_ns() the line was read, payload)] of `topic` from line index `since`."""
        prefix = f"recv {dds_topic(topic)} "
        with self._cv:
            rows = list(zip(self.real[since:], self.lines[since:]))
        return [(t, bytes.fromhex(line[len(prefix):])) for t, (_, line) in rows if line.startswith(prefix)]

    def first_line(self, prefix, after_mono=0.0, pred=None):
        """(monotonic time, line) of the first line starting with `prefix` read after
        `after_mono` (and satisfying pred(line)), or None."""
        with self._cv:
            for t, line in self.lines:
                if t >= after_mono and line.startswith(prefix) and (pred is None or pred(line)):
                    return t, line
        return None


def point_payload(xyz, t_ns, frame="base_link"):
    """A PointStamped target's CDR, header.stamp = t_ns (exactly: the key of the reply)."""
    from geometry_msgs.msg import PointStamped

    from interop import cdr

    m = PointStamped()
    m.header.frame_id = frame
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
    m.point.x, m.point.y, m.point.z = (float(v) for v in xyz)
    return cdr.serialize(m)


def joint_state_of(payload):
    """(stamp ns, positions, names) of a JointState's CDR."""
    from sensor_msgs.msg import JointState

    from interop import cdr

    m = cdr.deserialize(payload, JointState())
    return m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, tuple(m.position), tuple(m.name)


def wait_matched(peer, pubs=(), subs=(), timeout=30.0):
    return peer.wait(lambda: all(peer.matched(t, "pub") > 0 for t in pubs)
                     and all(peer.matched(t, "sub") > 0 for t in subs), timeout)


# ---------------------------------------------------------------- (a), (b), CPU: one graph run
class LatencyRun(GraphRun):
    """e2e_harness.GraphRun (layout "same", nodes "graph") with the nodes started
    directly under `variant` and the sros2_peer (same variant) as the operator and probe."""

    def __init__(self, name, path, variant, device="simavr", serial_args=(), clock_ppm=0.0, log=print,
                 probe="fastdds"):
        super().__init__(name, path, layout="same", device=device, nodes="graph", serial_args=serial_args,
                         clock_ppm=clock_ppm, log=log)
        self.variant = variant
        self.peer = None
        self.probe = probe

    def _start(self):
        if twohost.available():
            raise RuntimeError(f"network namespaces are needed: {twohost.available()}")
        self.hosts = twohost.TwoHosts(tag="k")
        self.lease = DomainLease()
        self._start_device()
        pc = self.hosts.pc
        self.procs = [start_node("compute_ik", self.variant, self.lease.id, pc),
                      start_node("serial_node", self.variant, self.lease.id, pc,
                                 ["-p", f"port:={self.serial_port}", *self.serial_args])]
        self.peer = TimedPeer(self.lease.id, enclave=self.variant.peer_enclave(), pubs=("xyz_target",),
                              subs=("servo_angles", "servo_state"), netns=pc, name=f"peer-{self.name}",
                              binary=probe_binary(self.probe))
        self.peer.wait_ready()

    # GraphRun.spin spins rclpy observers; here there are none: the peer's thread reads
    def spin(self, until_monotonic):
        left = until_monotonic - time.monotonic()
        if left > 0:
            time.sleep(left)

    def publish(self, xyz, index, phase):
        t = time.time_ns()
        self.peer.publish("xyz_target", point_payload(xyz, t))
        self.sent.append((t, index, phase))
        return t

    def wait_flowing(self, timeout=40.0):
        """Until a target sent now is answered with servo_state (handshakes included)."""
        t0 = time.time_ns()
        end = time.monotonic() + timeout
        mark = 0
        while time.monotonic() < end:
            self.drive(10, 0.2, "warmup")
            rows = self.peer.received_real("servo_state", mark)
            # a reply to a target carries its stamp (servo_state also comes on its own)
            sent = {t for t, _, _ in self.sent if t >= t0}
            if any(joint_state_of(p)[0] in sent for _, p in rows):
                return
        raise RuntimeError(f"[{self.name}] no servo_state for a target within {timeout:g} s; matched "
                           f"{[(t, self.peer.matched(t, k)) for t, k in (('xyz_target', 'pub'), ('servo_angles', 'sub'), ('servo_state', 'sub'))]}; "
                           f"logs {[str(p.log_path) for p in self.procs]}; peer {self.peer.stderr()[-1500:]}")

    def node_pids(self):
        return {p.name: p.proc.pid for p in self.procs if p.proc.poll() is None}

    def helper_pids(self):
        out = super().helper_pids()
        out.pop("bench probes (this process)", None)
        if self.peer is not None and self.peer.proc.poll() is None:
            out["sros2_peer (probe)"] = self.peer.proc.pid
        out["this Python process (reads the peer)"] = os.getpid()
        return out

    def stop(self):
        if self.peer is not None:
            self.peer_exit = self.peer.close()
            self._fill_probe()
        codes = super().stop()
        if self.peer is not None:
            codes["sros2_peer"] = self.peer_exit
        return codes

    def _fill_probe(self):
        """The peer's recv lines -> self.pc_probe in e2e_harness.Probe's shape:
        stamp -> (reception = the time Python read the line, the same again (no source
        timestamp from the peer), the same again, positions, names)."""
        pr = Probe()
        for topic, table in (("servo_angles", pr.servo_angles), ("servo_state", pr.servo_state)):
            for t, payload in self.peer.received_real(topic):
                st, pos, names = joint_state_of(payload)
                pr.store(table, st, (t, t, t, pos, names))
        self.pc_probe = pr


# ---------------------------------------------------------------- start to first match
START_CASES = {
    # node: (namespace "pc" or "pi", the peer's pubs, the peer's subs, ROS args)
    "compute_ik": ("pc", ("xyz_target",), ("servo_angles",), []),
    "serial_node": ("pi", ("servo_angles",), ("servo_state",), ["-p", "port:=mock"]),
}


def start_to_match(hosts, domain, variant, node, timeout=20.0):
    """A fresh peer in `pc` (ready, then 1 s to settle), then `node` started in its
    namespace: seconds from the node's start to the peer's first `matched` line with a
    count > 0, and to every expected endpoint matched. The peer and the node are stopped."""
    where, pubs, subs, ros_args = START_CASES[node]
    peer = TimedPeer(domain, enclave=variant.peer_enclave(), pubs=pubs, subs=subs, netns=hosts.pc,
                     name=f"peer-start-{node}")
    proc = None
    res = {"node": node, "variant": variant.name}
    try:
        peer.wait_ready()
        time.sleep(1.0)
        t0 = time.monotonic()
        proc = start_node(node, variant, domain, hosts.pc if where == "pc" else hosts.pi, ros_args)
        ok = wait_matched(peer, pubs, subs, timeout)
        t_all = time.monotonic()
        positive = lambda line: int(line.rsplit(" ", 1)[1]) > 0  # noqa: E731
        first = peer.first_line("matched ", t0, positive)
        res["first_match_s"] = first[0] - t0 if first else None
        res["all_matched_s"] = t_all - t0 if ok else None
        auth = peer.first_line("auth ok ", t0)
        res["auth_ok_s"] = auth[0] - t0 if auth else None
        disc = peer.first_line("participant discovered ", t0)
        res["participant_discovered_s"] = disc[0] - t0 if disc else None
        if not ok:
            res["why"] = f"not matched within {timeout:g} s: {proc.output()[-800:]} {peer.stderr()[-800:]}"
    finally:
        if proc is not None:
            res["exit"] = proc.stop()
        res["peer_exit"] = peer.close()
    return res


# ---------------------------------------------------------------- outages
class OutageGraph:
    """compute_ik in hosts.pc, serial_node (port:=mock) in hosts.pi, a TimedPeer in pc
    publishing the smooth path's targets at `rate` from a thread for as long as it lives."""

    def __init__(self, hosts, domain, variant, rate=50.0, log=print):
        self.hosts, self.domain, self.variant, self.rate, self.log = hosts, domain, variant, rate, log
        self.path = A.TargetPath("smooth")
        self.sent = []  # (stamp ns, monotonic)
        self.procs = [start_node("compute_ik", variant, domain, hosts.pc),
                      start_node("serial_node", variant, domain, hosts.pi, ["-p", "port:=mock"])]
        self.peer = TimedPeer(domain, enclave=variant.peer_enclave(), pubs=("xyz_target",),
                              subs=("servo_state",), netns=hosts.pc, name=f"peer-outage-{variant.name}")
        self.peer.wait_ready()
        self._stop = threading.Event()
        self.skipped = 0
        self.thread = threading.Thread(target=self._stream, daemon=True)
        self.thread.start()

    def _stream(self):
        t0 = time.monotonic()
        i = 0
        while not self._stop.is_set():
            due = t0 + i / self.rate
            i += 1
            left = due - time.monotonic()
            if left > 0:
                time.sleep(left)
            elif -left > 0.5 / self.rate:
                self.skipped += 1
                continue
            _, xyz = self.path.next(due - t0)
            t = time.time_ns()
            try:
                self.peer.publish("xyz_target", point_payload(xyz, t))
            except (BrokenPipeError, ValueError):
                return
            self.sent.append((t, time.monotonic()))

    def first_answer(self, after_mono, timeout):
        """Monotonic time of the first servo_state (any, and the first answering a target
        sent after `after_mono`) read after `after_mono`, waiting up to `timeout`: a pair,
        None where none came."""
        end = after_mono + timeout
        any_t = ans_t = None
        while time.monotonic() < end:
            with self.peer._cv:
                rows = [(t, line) for t, line in self.peer.lines if t >= after_mono]
            wanted = set()
            for k in range(len(self.sent) - 1, -1, -1):  # newest first; the thread appends
                s, m = self.sent[k]
                if m < after_mono:
                    break
                wanted.add(s)
            prefix = f"recv {dds_topic('servo_state')} "
            for t, line in rows:
                if not line.startswith(prefix):
                    continue
                if any_t is None:
                    any_t = t
                if joint_state_of(bytes.fromhex(line[len(prefix):]))[0] in wanted:
                    ans_t = t
                    break
            if ans_t is not None:
                break
            time.sleep(0.05)
        return any_t, ans_t

    def wait_flowing(self, timeout=40.0):
        t0 = time.monotonic()
        _, ans = self.first_answer(t0, timeout)
        if ans is None:
            raise RuntimeError(f"[{self.variant}] no servo_state for a target within {timeout:g} s; "
                               f"logs {[str(p.log_path) for p in self.procs]}; peer {self.peer.stderr()[-1500:]}")
        return ans - t0

    def outage(self, seconds=25.0, side="pi", resume_timeout=30.0):
        """Pull `side`'s cable for `seconds` (targets keep streaming), plug it back: the
        seconds from link-up to the first servo_state read by the peer, and to the first
        one answering a target sent after link-up."""
        t_cut = time.monotonic()
        self.hosts.cut(side)
        time.sleep(max(0.0, t_cut + seconds - time.monotonic()))
        self.hosts.restore(side)  # link up, multicast routes re-added
        t_up = time.monotonic()
        any_t, ans_t = self.first_answer(t_up, resume_timeout)
        dropped = [line for t, line in self.peer.said("participant ")
                   if t >= t_cut and (" dropped " in line or " removed " in line)]
        auth = [line for t, line in self.peer.said("auth ok ") if t >= t_up]
        return {"length_s": seconds, "side": side, "variant": self.variant.name,
                "first_servo_state_s": None if any_t is None else any_t - t_up,
                "resume_s": None if ans_t is None else ans_t - t_up,
                "participants_dropped_during": len(dropped), "handshakes_after": len(auth)}

    def close(self):
        self._stop.set()
        self.thread.join(5)
        codes = {"sros2_peer": self.peer.close()}
        for p in self.procs:
            codes[p.name] = p.stop()
        return codes


def keystore_dir():
    return tempfile.mkdtemp(prefix="secure-bench-")
