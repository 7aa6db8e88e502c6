"""The machinery of the end-to-end benchmark (e2e.py): one run of the graph, as users run
it (launch_scripts/pc.sh and pi.sh), in network namespaces of tests/twohost.py (both
scripts in `pc` for "same host", pi.sh in `pi` across the veth or the impaired link),
the device (the firmware in simavr, or the virtual Arduino) behind pty_tap.py, and rclpy
probes that send targets and record what comes back with the DDS reception time.

Clocks: every time here is CLOCK_REALTIME in ns (header stamps = time.time_ns() when a
target is published; Fast DDS's reception timestamp in the probes; pty_tap's clock), all
on this one machine. simavr's cycle counter is only compared with itself (see e2e.py).
"""
import base64
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
os.environ.setdefault("EEZYBOT_BIN_DIR", str(REPO / "target" / "release"))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PointStamped  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

import twohost  # noqa: E402
from conftest import DomainLease, NodeProcess, Observer, bin_path  # noqa: E402
from interop.servo_link import SimulatedUno  # noqa: E402

FIRMWARE = REPO / "firmware" / "servo_control"
# The probes keep every sample (the nodes' writers keep 10; a deep reader history only
# makes sure a slow Python probe never overwrites one before it is read).
DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


# ---------------------------------------------------------------- processes: CPU and RSS
def children(pid):
    out = []
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{tid}/children") as f:
                out += [int(c) for c in f.read().split()]
    except OSError:
        pass
    return out


def descendants(pid):
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        for c in children(p):
            out.append(c)
            todo.append(c)
    return out


def proc_sample(pid):
    """(name, cpu seconds, VmRSS MB, VmHWM MB) of a process, or None if it is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        status = Path(f"/proc/{pid}/status").read_text()
        comm = Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return None
    fields = stat.rsplit(")", 1)[1].split()
    cpu = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    kb = {line.split(":")[0]: int(line.split()[1]) for line in status.splitlines() if line.startswith(("VmRSS", "VmHWM"))}
    return comm, cpu, kb.get("VmRSS", 0) / 1024, kb.get("VmHWM", 0) / 1024


class CpuWindow:
    """CPU (% of one core) and memory of named processes over a window."""

    def __init__(self, pids):
        self.pids = pids  # {label: pid}
        self.t0 = time.monotonic()
        self.c0 = {k: proc_sample(p) for k, p in pids.items()}

    def close(self):
        dt = time.monotonic() - self.t0
        out = {}
        for k, p in self.pids.items():
            a, b = self.c0.get(k), proc_sample(p)
            if a is None or b is None:
                continue
            out[k] = {"process": b[0], "cpu_pct": (b[1] - a[1]) / dt * 100, "rss_mb": b[2], "rss_peak_mb": b[3],
                      "window_s": dt}
        return out


# ---------------------------------------------------------------- a minimal WebSocket client
class WebSocketOperator:
    """A browser's WebSocket to gui_bridge's panel (RFC 6455, text frames), enough to
    send what the page sends ({"t": "target", "xyz": [...]}) and to read (and drop) what
    the panel broadcasts, as an open browser tab would."""

    def __init__(self, host, port, netns=None, timeout=15.0):
        deadline = time.monotonic() + timeout
        while True:
            try:
                with twohost.netns(netns):
                    self.sock = socket.create_connection((host, port), timeout=2)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET /ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                           f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\nOrigin: http://{host}:{port}\r\n\r\n")
                          .encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("gui_bridge closed the WebSocket handshake")
            head += chunk
        if not head.startswith(b"HTTP/1.1 101"):
            raise ConnectionError(f"gui_bridge refused the WebSocket: {head[:200]!r}")
        self.received_bytes = len(head.split(b"\r\n\r\n", 1)[1])
        self.sock.settimeout(None)
        self.lock = threading.Lock()
        self.closed = False
        self.reader = threading.Thread(target=self._drain, daemon=True)
        self.reader.start()

    def _drain(self):
        while not self.closed:
            try:
                data = self.sock.recv(65536)
            except OSError:
                return
            if not data:
                return
            self.received_bytes += len(data)

    def send_text(self, text):
        payload = text.encode()
        mask = os.urandom(4)
        n = len(payload)
        head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack(">H", n))
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        with self.lock:
            self.sock.sendall(head + mask + masked)

    def close(self):
        self.closed = True
        try:
            self.sock.sendall(bytes([0x88, 0x80]) + os.urandom(4))
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.sock.close()


# ---------------------------------------------------------------- one run of the graph
class Probe:
    """What one rclpy probe records, keyed by header stamp (ns): the first arrival of each
    stamp, with Fast DDS's reception time, the writer's source time, and the values."""

    def __init__(self):
        self.servo_angles = {}
        self.joint_states = {}
        self.servo_state = {}
        self.xyz_target = {}
        self.duplicates = 0
        self.diagnostics = {}  # status name -> {key: value}, the latest

    def store(self, table, key, value):
        if key in table:
            self.duplicates += 1
        else:
            table[key] = value


class GraphRun:
    """One configuration of the graph, started and stopped as a whole.

    layout: "same" (pc.sh and pi.sh both in namespace pc), "split" (pi.sh in pi, over a
    veth) or "impaired" (pi.sh in pi, over linkem with `impairment`).
    device: "simavr" (the firmware's ELF in simavr) or "virtual" (virtual_arduino); both
    behind pty_tap.py. nodes: "graph" (pc.sh + pi.sh), "compute_ik" (that binary alone)
    or "seed" (seed_ik_node.py alone): the last two have no serial side.
    hosts_factory (optional): `hosts_factory(run)` makes the namespaces instead of
    twohost.TwoHosts (something with `pc`, `pi`, `link` and `close()`, e.g. wanhost's
    WanHosts with its router started); env (optional): more environment for pc.sh and
    pi.sh (e.g. WanHosts.graph_env). Without them, nothing changes.
    """

    def __init__(self, name, path, layout="same", device="simavr", nodes="graph", impairment=None, seed_cap="loop",
                 serial_args=(), firmware=FIRMWARE, clock_ppm=0.0, log=print, hosts_factory=None, env=None):
        self.name, self.layout, self.device, self.nodes = name, layout, device, nodes
        self.clock_ppm = clock_ppm  # simavr's clock error (servo_sim --clock-ppm)
        self.impairment = impairment
        self.seed_cap = seed_cap
        self.serial_args = list(serial_args)  # extra ROS arguments for serial_node (pi.sh)
        self.log = log
        self.workdir = Path(tempfile.mkdtemp(prefix=f"e2e-{name}-"))
        self.hosts = self.lease = self.uno = self.tap = self.dev_proc = self.pi_probe_proc = None
        self.procs = []
        self.observers = []
        self.pc_probe, self.pi_probe = Probe(), None
        self.path = path  # e2e_analysis.TargetPath: the targets
        self.firmware = Path(firmware)  # firmware/servo_control, built (make all sim)
        self.t_origin = None  # time.monotonic() of the path's origin
        self.sent = []  # (stamp ns, path index, phase)
        self.skipped = {}  # phase -> slots skipped because this process was late
        self.serial_port = None
        self.hosts_factory = hosts_factory
        self.extra_env = dict(env or {})

    # ---- start
    def start(self):
        try:
            self._start()
        except BaseException:
            self.stop()
            raise
        return self

    def _start(self):
        if twohost.available():
            raise RuntimeError(f"network namespaces are needed: {twohost.available()}")
        impaired = self.impairment if self.layout == "impaired" else None
        if self.hosts_factory is not None:
            self.hosts = self.hosts_factory(self)
        else:
            self.hosts = twohost.TwoHosts(tag="e", impaired=impaired)
        self.lease = DomainLease()
        if self.nodes == "graph":
            self._start_device()
        self._start_nodes()
        self.op = Observer(self.lease.id, name="bench_operator", netns=self.hosts.pc)
        self.observers.append(self.op)
        self._subscribe(self.op, self.pc_probe, serial=self.nodes == "graph")
        if self.layout != "same" and self.nodes == "graph":
            # a probe next to serial_node, in its own process (see probe_proc.py)
            self.pi_probe_out = self.workdir / "pi_probe.json"
            self.pi_probe_status = self.workdir / "pi_probe.status"
            self.pi_probe_proc = NodeProcess(sys.executable, [str(HERE / "probe_proc.py"), str(self.pi_probe_out),
                                                              str(self.pi_probe_status), "/servo_angles"],
                                             self.lease.id, netns=self.hosts.pi)
        with twohost.netns(self.hosts.pc):
            self.xyz = self.op.node.create_publisher(PointStamped, "/xyz_target", DEEP)

    def _start_device(self):
        if self.device == "simavr":
            for f in ("servo_sim", "servo_control.elf"):
                if not (self.firmware / "build" / f).exists():
                    raise FileNotFoundError(f"{self.firmware / 'build' / f} is missing: make -C {self.firmware} all sim")
            self.uno = SimulatedUno(self.workdir, self.firmware, clock_ppm=self.clock_ppm)
            device_path = str(self.uno.tty_path)
        else:
            path = self.workdir / "arduino"
            self.dev_log = open(self.workdir / "virtual_arduino.log", "w")
            self.dev_proc = subprocess.Popen([bin_path("virtual_arduino"), str(path)], stdout=self.dev_log,
                                             stderr=subprocess.STDOUT)
            deadline = time.monotonic() + 10
            while not path.exists():
                if time.monotonic() > deadline or self.dev_proc.poll() is not None:
                    raise RuntimeError("virtual_arduino did not create its pty")
                time.sleep(0.01)
            device_path = str(path)
        self.serial_port = str(self.workdir / "tap")
        self.tap_log = self.workdir / "tap.log"
        self.tap = subprocess.Popen([sys.executable, str(HERE / "pty_tap.py"), device_path, self.serial_port,
                                     str(self.tap_log)], stdout=subprocess.PIPE, stderr=open(self.workdir / "tap.err", "w"))
        if self.tap.stdout.readline().strip() != b"ready":
            raise RuntimeError(f"pty_tap did not start: {(self.workdir / 'tap.err').read_text()}")

    def _start_nodes(self):
        env = {"EEZYBOT_BIN_DIR": os.environ["EEZYBOT_BIN_DIR"], "GUI_BIND": "127.0.0.1:8080", **self.extra_env}
        pc, pi = self.hosts.pc, (self.hosts.pc if self.layout == "same" else self.hosts.pi)
        if self.nodes == "graph":
            self.procs = [NodeProcess(str(REPO / "launch_scripts" / "pc.sh"), [], self.lease.id, env=env, netns=pc),
                          NodeProcess(str(REPO / "launch_scripts" / "pi.sh"), self.serial_args, self.lease.id,
                                      env={**env, "SERIAL_PORT": self.serial_port}, netns=pi)]
        elif self.nodes == "compute_ik":
            self.procs = [NodeProcess("compute_ik", [], self.lease.id, env=env, netns=pc)]
        else:
            self.procs = [NodeProcess(sys.executable, [str(HERE / "seed_ik_node.py"), "--cap", self.seed_cap],
                                      self.lease.id, env=env, netns=pc)]

    def _subscribe(self, obs, probe, serial, joint_states=True):
        def keep(table):
            return lambda m, info: probe.store(table, stamp_ns(m.header), (
                info["received_timestamp"], info["source_timestamp"], time.time_ns(), tuple(m.position), tuple(m.name)))

        with twohost.netns(obs.netns):
            n = obs.node
            n.create_subscription(JointState, "/servo_angles", keep(probe.servo_angles), DEEP)
            if joint_states:
                n.create_subscription(JointState, "/joint_states", keep(probe.joint_states), DEEP)
            if serial:
                n.create_subscription(JointState, "/servo_state", keep(probe.servo_state), DEEP)
                n.create_subscription(DiagnosticArray, "/diagnostics", lambda m: probe.diagnostics.update(
                    {s.name: {kv.key: kv.value for kv in s.values} for s in m.status}), DEEP)
            n.create_subscription(PointStamped, "/xyz_target", lambda m, info: probe.store(
                probe.xyz_target, stamp_ns(m.header), (info["received_timestamp"], (m.point.x, m.point.y, m.point.z))), DEEP)

    # ---- processes
    def node_pids(self):
        """{node name: pid} of every node process (the launch scripts' children)."""
        out = {}
        for p in self.procs:
            if p.proc.poll() is not None:
                continue
            if p.name.startswith("python"):
                out["seed_compute_ik (rclpy)"] = p.proc.pid
                continue
            if not p.name.endswith(".sh"):
                out[p.name] = p.proc.pid
                continue
            for c in descendants(p.proc.pid):
                s = proc_sample(c)
                if s and s[0] in ("compute_ik", "state_publisher", "serial_node", "gui_bridge"):
                    out[s[0]] = c
        return out

    def helper_pids(self):
        out = {}
        if self.uno is not None:
            out["servo_sim (simavr, harness)"] = self.uno.proc.pid
        if self.dev_proc is not None:
            out["virtual_arduino (harness)"] = self.dev_proc.pid
        if self.tap is not None:
            out["pty_tap (harness)"] = self.tap.pid
        if self.hosts is not None and self.hosts.link is not None:
            out["linkem (harness)"] = self.hosts.link.pid
        out["bench probes (this process)"] = os.getpid()
        return out

    # ---- driving
    def spin(self, until_monotonic):
        """Spin every probe until the given time.monotonic()."""
        while True:
            now = time.monotonic()
            if now >= until_monotonic:
                return
            first = True
            for o in self.observers:
                o.executor.spin_once(timeout_sec=min(0.002, until_monotonic - now) if first else 0)
                first = False

    def publish(self, xyz, index, phase):
        m = PointStamped()
        m.header.frame_id = "base_link"
        t = time.time_ns()
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(t, 1_000_000_000)
        m.point.x, m.point.y, m.point.z = xyz
        self.xyz.publish(m)
        self.sent.append((t, index, phase))
        return t

    def next_target(self, due):
        """The path's target for a slot due at time.monotonic() `due`."""
        if self.t_origin is None:
            self.t_origin = due
        return self.path.next(due - self.t_origin)

    def drive(self, rate, seconds, phase, send=None):
        """Send the path's targets at `rate` for `seconds` (deadline schedule, no drift;
        `send(xyz, index, phase)`, default: publish on xyz_target). A slot this process
        reaches more than half a period late (it was not scheduled: the machine is busy)
        is skipped, not caught up: sending the backlog back to back would be a burst,
        which the nodes rightly reduce to its newest target. Skipped slots are counted in
        self.skipped[phase]."""
        send = send or self.publish
        n = int(round(rate * seconds))
        t0 = time.monotonic()
        for i in range(n):
            due = t0 + i / rate
            self.spin(due)
            if time.monotonic() > due + 0.5 / rate:
                self.skipped[phase] = self.skipped.get(phase, 0) + 1
                continue
            index, xyz = self.next_target(due)
            send(xyz, index, phase)
        self.spin(t0 + n / rate)

    def wait_flowing(self, timeout=25.0):
        """Until a target sent now comes back (servo_state, or servo_angles without a
        serial side). Nothing is restarted: a graph that does not answer fails the run."""
        t0 = time.time_ns()
        end = time.monotonic() + timeout
        table = self.pc_probe.servo_state if self.nodes == "graph" else self.pc_probe.servo_angles
        while time.monotonic() < end:
            self.drive(10, 0.1, "warmup")
            # a reply to a target carries its stamp (servo_state also comes on its own,
            # stamped when the device reported: steady while idle)
            sent = {t for t, _, _ in self.sent if t >= t0}
            if any(s in sent for s in table):
                self._wait_pi_probe()
                return
        raise RuntimeError(f"[{self.name}] no reply to targets within {timeout:g} s; logs: "
                           f"{[str(p.log_path) for p in self.procs]}")

    def _wait_pi_probe(self, timeout=20.0):
        if self.pi_probe_proc is None:
            return
        end = time.monotonic() + timeout
        while not self.pi_probe_status.exists():
            if time.monotonic() > end:
                raise RuntimeError(f"[{self.name}] the probe in {self.hosts.pi} never saw a servo_angles publisher: "
                                   f"{self.pi_probe_proc.output()[-2000:]}")
            self.drive(10, 0.1, "warmup")
        self.drive(10, 0.5, "warmup")

    def _collect_pi_probe(self):
        code = self.pi_probe_proc.stop()
        self.pi_probe = Probe()
        try:
            data = json.loads(self.pi_probe_out.read_text())
        except (OSError, ValueError) as e:
            raise RuntimeError(f"the probe in pi left no data (exit {code}): {e}; {self.pi_probe_proc.output()[-2000:]}")
        self.pi_probe.duplicates = data["duplicates"]
        self.pi_probe.servo_angles = {int(k): (v[0], v[1], v[2], tuple(v[3]), tuple(v[4]))
                                      for k, v in data["tables"]["/servo_angles"].items()}
        return code

    # ---- stop
    def stop(self):
        codes = {}
        if self.pi_probe_proc is not None:
            try:
                codes["pi_probe"] = self._collect_pi_probe()
            except Exception as e:  # noqa: BLE001 - teardown goes on
                codes["pi_probe"] = repr(e)
            self.pi_probe_proc = None
        for p in self.procs:
            try:
                codes[p.name] = p.stop()
            except Exception as e:  # noqa: BLE001 - teardown goes on
                codes[p.name] = repr(e)
        for o in self.observers:
            try:
                o.close()
            except Exception:  # noqa: BLE001
                pass
        self.observers = []
        if self.tap is not None and self.tap.poll() is None:
            self.tap.send_signal(signal.SIGTERM)
            try:
                codes["pty_tap"] = self.tap.wait(10)
            except subprocess.TimeoutExpired:
                self.tap.kill()
                self.tap.wait()
        if self.uno is not None and self.uno.proc.poll() is None:
            codes["servo_sim"] = self.uno.stop()
        if self.dev_proc is not None and self.dev_proc.poll() is None:
            self.dev_proc.terminate()
            codes["virtual_arduino"] = self.dev_proc.wait(10)
            self.dev_log.close()
        if self.hosts is not None:
            self.hosts.close()
            self.link_stats = self.hosts.stats
            self.hosts = None
        if self.lease is not None:
            self.lease.release()
            self.lease = None
        self.exit_codes = codes
        return codes
