"""The graph split across two hosts, as our users run it: launch_scripts/pc.sh in
namespace `pc` (gui_bridge, compute_ik, state_publisher), launch_scripts/pi.sh in `pi`
(serial_node, driving the virtual Arduino behind a pty or the firmware in simavr), and a
real rclpy observer in `pc` that sends targets and reads `servo_state` and
`diagnostics`. Used by test_two_hosts.py, tests/soak/outages.py and the end-to-end
benchmark.

Targets are stamped with the wall clock; serial_node copies a command's stamp into the
`servo_state` that acknowledges it, so every reply says which target it answers and
how long the round trip took (one machine, one clock).
"""
import math
import re
import statistics
import struct
import subprocess
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState

from conftest import EVERY, REPO, NodeProcess, Observer, bin_path, latest_status, status_values
from interop.servo_link import SimulatedUno

FIRMWARE = REPO / "firmware" / "servo_control"
UNREACHABLE = re.compile(r"unreachable", re.IGNORECASE)


def stamp_of(t):
    m = PointStamped()
    m.header.frame_id = "base_link"
    m.header.stamp.sec = int(t)
    m.header.stamp.nanosec = int((t - int(t)) * 1e9)
    return m


def seconds(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def streaming_summary(graph, t0, replies, link_stats, what):
    """The targets `graph` sent since wall time t0 against `replies` (servo_state after
    t0: (arrival, stamp)) that answer them, printed with the round trip and linkem's
    counts (`link_stats`, or None) under the heading `what`. Returns sent (stamps),
    replies (those answering a target), answered (stamps), and longest_unanswered: the
    longest run of consecutive targets, in the order sent, of which none was answered
    (a stall, counted in targets rather than seconds)."""
    sent = [s for _, s in graph.sent if s >= t0]
    # replies to targets (servo_state from a heartbeat is stamped "now")
    replies = [(a, s) for a, s in replies if s in set(sent)]
    answered = {s for _, s in replies}
    rtt = sorted(a - s for a, s in replies)
    link = {d: {k: link_stats[d][k] for k in ("forwarded", "dropped")} for d in ("a_to_b", "b_to_a")} \
        if link_stats else {}
    print(f"\n{what}: {len(sent)} targets, {len(answered)} answered, round trip "
          f"p50 {statistics.median(rtt) * 1e3:.1f} ms, p99 {rtt[int(0.99 * (len(rtt) - 1))] * 1e3:.1f} ms, "
          f"max {rtt[-1] * 1e3:.1f} ms; link {link}")
    run = longest = 0
    for s in sent:
        run = 0 if s in answered else run + 1
        longest = max(longest, run)
    return {"sent": sent, "replies": replies, "answered": answered, "longest_unanswered": longest}


# A frame starts at most 22.5 ms after the one before (firmware/servo_control/config.h);
# a width stored after a frame's pulses were read shows in the next frame.
FRAME_MAX_CYCLES = 22_500 * 16


def hold_across_the_outage(ev, t_heal_ns):
    """A link outage judged on the board's own clock and counts: the last SET_PULSES the
    AVR received from reads before the heal (wall clock `t_heal_ns`, taken before the link
    came up again; an order of events: bytes read after it come at or after the first
    read's cycle) and the first after it.
    Between them serial_node must have sent heartbeats only, and at least one (it kept
    the board's watchdog fed), and from one frame
    after the last command on, every pulse on every pin must show that command's width
    (the arm holds), one a frame in simulated time (the board holds, it does not detach);
    after the first command after the heal, a pin must go on more than 5 us (a new target
    applied). Returns what is wrong, [] when nothing is.

    How many heartbeats reach the board in the silence is not a count to judge: the
    host's link waits for the board's replies, so a simavr starved of CPU gets fewer (9 of
    about 50 in one run on a busy host, with 0.14 s of simulated time in a 5 s cut)."""
    from interop.servo_link import HEARTBEAT, SET_PULSES

    split = ev.cycle_after(t_heal_ns)
    if split is None:
        return ["the board read nothing after the link returned"]
    frames = ev.frames()
    sets = [(c, struct.unpack("<4H", p)) for t, _, p, c in frames if t == SET_PULSES]
    before = [f for f in sets if f[0] < split]
    after = [f for f in sets if f[0] >= split]
    if not before or not after:
        return [f"SET_PULSES: {len(before)} before the heal, {len(after)} after it"]
    (c0, ticks), (c1, _) = before[-1], after[0]
    problems = []
    heartbeats = sum(1 for t, _, _, c in frames if c0 < c < c1 and t == HEARTBEAT)
    others = [t for t, _, _, c in frames if c0 < c < c1 and t != HEARTBEAT]
    print(f"outage: {heartbeats} heartbeats and {(c1 - c0) / 16e6:.2f} s of simulated time between the last "
          f"command before the heal and the first after it")
    if heartbeats < 1 or others:
        problems.append(f"between the last command before the heal and the first after it: {heartbeats} "
                        f"heartbeats (want >= 1) and other frames {others}")
    for pin in range(4):
        held = [w for c, w in ev.pulses(pin) if c0 + FRAME_MAX_CYCLES <= c < c1]
        want_pulses = (c1 - c0) // FRAME_MAX_CYCLES - 2
        if len(held) < want_pulses:
            problems.append(f"pin {pin}: {len(held)} pulses in {(c1 - c0) / 16e6:.2f} s of simulated hold, "
                            f"want >= {want_pulses} (one a frame)")
        off = [w for w in held if abs(w - ticks[pin] / 2) > 1.0]
        if off:
            problems.append(f"pin {pin} moved while the link was down: the last command {ticks[pin] / 2} us, "
                            f"pulses {min(off)}..{max(off)} us")
    moved = [abs(ps[-1][1] - ticks[pin] / 2) for pin in range(4) if (ps := [p for p in ev.pulses(pin) if p[0] > c1])]
    if max(moved, default=0.0) <= 5:
        problems.append("the arm did not go on to a new target after the link returned")
    return problems


class VirtualArduinoPty:
    """The virtual_arduino binary serving a pty (in the root namespace: a pty is a file)."""

    def __init__(self, workdir):
        self.path = Path(workdir) / "arduino"
        self.log = open(Path(workdir) / "virtual_arduino.log", "w")
        self.proc = subprocess.Popen([bin_path("virtual_arduino"), str(self.path)], stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 10
        while not self.path.exists():
            if time.monotonic() > deadline or self.proc.poll() is not None:
                raise RuntimeError("virtual_arduino did not create its pty")
            time.sleep(0.01)

    def stop(self):
        self.proc.terminate()
        try:
            return self.proc.wait(10)
        finally:
            self.log.close()


def delta(now, then, key):
    """How much counter `key` of a diagnostics entry grew from `then` to `now` (None: not
    a number)."""
    try:
        return int(now.get(key, 0)) - int(then.get(key, 0))
    except ValueError:
        return None


class SplitGraph:
    """pc.sh in hosts.pc, pi.sh in hosts.pi, an rclpy observer in hosts.pc (hosts: a
    twohost.TwoHosts, or a wanhost.WanHosts with env=hosts.graph_env(...))."""

    def __init__(self, hosts, domain, workdir, device="virtual", ros_args=(), target_hz=20.0, env=None):
        self.hosts, self.domain = hosts, domain
        self.ros_args = list(ros_args)
        self.target_period = 1.0 / target_hz
        self.procs = []
        self.device = device
        workdir = Path(workdir)
        if device == "simavr":
            self.uno = SimulatedUno(workdir, FIRMWARE)
            port = str(self.uno.tty_path)
        elif device == "virtual":
            self.uno = VirtualArduinoPty(workdir)
            port = str(self.uno.path)
        else:
            self.uno, port = None, "mock"
        # env: more for both scripts (wanhost.WanHosts.graph_env: the WAN mode)
        env = {"EEZYBOT_BIN_DIR": str(Path(bin_path("serial_node")).parent), "GUI_BIND": "127.0.0.1:8080",
               **(env or {})}
        self.pc = NodeProcess(str(REPO / "launch_scripts" / "pc.sh"), self.ros_args, domain, env=env, netns=hosts.pc)
        # on the firmware in simavr, serial_node's trace of the frames it writes
        # (safety_rig.sent_clock: the clock the pins' velocity check reads)
        trace = ["--log-level", "debug"] if device == "simavr" else []
        self.pi = NodeProcess(str(REPO / "launch_scripts" / "pi.sh"), [*self.ros_args, *trace], domain,
                              env={**env, "SERIAL_PORT": port}, netns=hosts.pi)
        self.procs = [self.pc, self.pi]
        ns = self._namespace()
        self.o = Observer(domain, name="operator", netns=hosts.pc)
        # every reply counts (which targets were answered): read with depth 1000
        self.states = self.o.sub(f"{ns}/servo_state", JointState, EVERY)
        self.diags = self.o.sub(f"{ns}/diagnostics", DiagnosticArray)
        self.xyz = self.o.pub(f"{ns}/xyz_target", PointStamped)
        self.sent = []  # (wall time, stamp seconds)
        self._next = time.monotonic()
        self._i = 0

    def _namespace(self):
        for a in self.ros_args:
            if a.startswith("__ns:="):
                return a[len("__ns:="):].rstrip("/")
        return ""

    # ---- driving
    def pump(self, seconds_, send=True):
        """Spin the observer for `seconds_`, sending a new target every period."""
        end = time.monotonic() + seconds_
        while True:
            now = time.monotonic()
            if now >= end:
                return
            if send and now >= self._next:
                self._next = max(self._next + self.target_period, now - self.target_period)
                self.send_target()
            self.o.executor.spin_once(timeout_sec=max(0.0, min(0.005, self._next - now, end - now)))

    def send_target(self):
        self._i += 1
        t = time.time()
        m = stamp_of(t)
        m.point.x = 0.2 + 0.03 * math.sin(self._i * 0.05)
        m.point.y = 0.05 * math.cos(self._i * 0.03)
        m.point.z = 0.15
        self.xyz.publish(m)
        self.sent.append((t, seconds(m.header.stamp)))

    def send_goal(self, goal, timeout=15):
        """One target at `goal` (x, y, z), stamped now; spins until the servo_state that
        answers it (its stamp) arrives, else AssertionError."""
        m = stamp_of(time.time())
        m.point.x, m.point.y, m.point.z = goal
        self.xyz.publish(m)
        want = seconds(m.header.stamp)
        assert self.pump_until(lambda: any(seconds(s.header.stamp) == want for _, s in self.states), timeout,
                               send=False), f"no servo_state for the target\n{self.logs_tail()}"

    def pump_until(self, predicate, timeout, send=True):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            self.pump(0.05, send)
        return predicate()

    def answers_after(self, t_wall):
        """The replies received after wall time t that answer a target sent at or after
        it (a reply to a target carries the target's stamp; servo_state also comes on its
        own, stamped when the device reported: steady while idle)."""
        targets = {s for _, s in self.sent if s >= t_wall}
        return [(a, s) for a, s in self.replies_after(t_wall) if s in targets]

    def replies_after(self, t_wall):
        """servo_state replies received after wall time t (arrival wall time, stamp)."""
        return [(a, s) for a, s in self._replies() if a >= t_wall]

    def _replies(self):
        # Observer stamps arrivals with time.monotonic(); convert to wall time
        offset = time.time() - time.monotonic()
        return [(mono + offset, seconds(m.header.stamp)) for mono, m in self.states]

    def wait_flowing(self, timeout=30):
        """Until a target sent now comes back as servo_state."""
        t0 = time.time()
        ok = self.pump_until(lambda: self.answers_after(t0), timeout)
        if not ok:
            raise AssertionError(f"no servo_state for a target within {timeout} s; observer matched "
                                 f"xyz_target subscribers {self.xyz.get_subscription_count()}, servo_state publishers "
                                 f"{self.o.node.count_publishers(self._namespace() + '/servo_state')}; compute_ik "
                                 f"{self.diag_values('compute_ik')}; serial_node {self.diag_values('serial_node')}\n"
                                 f"{self.logs_tail()}")

    def diag_values(self, node_prefix):
        """The latest diagnostics entry of a node: (level, message, {key: value})."""
        s = latest_status(self.diags, node_prefix)
        return (None, None, {}) if s is None else (s.level, s.message, status_values(s))

    def diag_after(self, node_prefix, t_wall):
        """The first diagnostics entry of a node stamped at or after wall time t, or None."""
        fresh = [(a, m) for a, m in self.diags if seconds(m.header.stamp) >= t_wall]
        for _, arr in fresh:
            for s in arr.status:
                if s.name.startswith(node_prefix):
                    return s
        return None

    def unreachable_lines(self):
        """Log lines about an unreachable network, per launch script."""
        return {p.name: sum(1 for line in p.log_path.read_text().splitlines() if UNREACHABLE.search(line))
                for p in self.procs}

    def logs_tail(self, n=15):
        out = []
        for p in self.procs:
            lines = p.log_path.read_text().splitlines()
            out.append(f"--- {p.name} (last {n} lines)\n" + "\n".join(lines[-n:]))
        return "\n".join(out)

    # ---- one outage
    def outage(self, length, side, resume_timeout=30.0, settle_timeout=30.0):
        """Pull the cable at `side` for `length` s while targets keep coming, then plug it
        back. Returns what happened, judged on what arrived up to two events after the
        heal (the timeouts only bound a failure): the first reply to a target sent after
        it (resumed), then the first reply to a target sent after that one had come back
        (settled). servo_state has one writer, serial_node, and reaches us reliable and in
        order, and serial_node gets compute_ik's servo_angles likewise: a command from the
        outage that serial_node applies after the heal is answered before its answer to a
        newer target, so every stale reply has arrived once the settling one has."""
        self.wait_flowing()
        ns = self._namespace()
        before = {
            "serial": self.diag_values("serial_node")[2],
            "ik": self.diag_values("compute_ik")[2],
            "unreachable": self.unreachable_lines(),
        }
        self.hosts.cut(side)
        t_cut = time.time()
        ik_lost_seen = False
        end = time.monotonic() + length
        while time.monotonic() < end:
            self.pump(0.1)
            level, msg, _ = self.diag_values("compute_ik")
            ik_lost_seen |= bool(msg and "lost" in msg)
        last_before = self.sent[-1][1]
        # the heal's time is taken before the plug goes in: restore() brings the link up
        # first and then re-adds the routes (with retries), and what was queued during
        # the outage crosses, and a command may reach the board, in between (with the time
        # taken after it, that command counted as one before the heal: the hold then
        # ended 10 ms before the next command, with no heartbeat between them, at load 26)
        t_restore = time.time()
        self.hosts.restore(side)
        resumed = self.pump_until(lambda: self.answers_after(t_restore), resume_timeout)
        t_resumed = time.time()
        first_new = min((a for a, _ in self.answers_after(t_restore)), default=None)
        settled = resumed and self.pump_until(lambda: self.answers_after(t_resumed), settle_timeout)
        # the peers lost and regained, as the nodes report them: once each has published
        # diagnostics after the first new answer (their stamps), until every loss is
        # regained (a node looks at its peers at its own pace, and a loss longer than the
        # lease is regained a moment after the data flows again; the timeout only bounds
        # a failure, which the counts then show)
        peer_keys = {("serial_node", "serial"): f"{ns}/servo_angles publishers",
                     ("compute_ik", "ik"): f"{ns}/servo_angles subscribers"}

        def peers_reported():
            if not all(self.diag_after(n, t_resumed) for n, _ in peer_keys):
                return False
            now = {n: self.diag_values(n)[2] for n, _ in peer_keys}
            return all(delta(now[n], before[b], f"{k} lost") == delta(now[n], before[b], f"{k} regained")
                       for (n, b), k in peer_keys.items())

        if settled:
            self.pump_until(peers_reported, settle_timeout)
        after = self.replies_after(t_restore)
        # replies that answer a target (servo_state from a heartbeat is stamped "now")
        targets = {s for _, s in self.sent}
        stamps = [s for _, s in after if s in targets]
        during = {s for w, s in self.sent if t_cut <= w < t_restore}
        result = {
            "length_s": length,
            "side": side,
            "t_cut": t_cut,
            "t_restore": t_restore,
            "resumed": resumed,
            "settled": settled,
            "resume_s": (first_new - t_restore) if first_new is not None else None,
            "wait_s": t_resumed - t_restore,
            # commands applied after the link returned although a newer one had been
            # sent before it returned: targets sent during the outage, but the last one
            "stale": sum(1 for s in stamps if s in during and s != last_before),
            "out_of_order": sum(1 for a, b in zip(stamps, stamps[1:]) if b < a),
            "replies_during_outage": sum(1 for a, _ in self._replies() if t_cut + 0.5 < a < t_restore),
            "ik_reported_lost": ik_lost_seen,
        }
        serial = self.diag_values("serial_node")[2]
        ik = self.diag_values("compute_ik")[2]

        result["serial_angles_lost"] = delta(serial, before["serial"], f"{ns}/servo_angles publishers lost")
        result["serial_angles_regained"] = delta(serial, before["serial"], f"{ns}/servo_angles publishers regained")
        result["ik_angles_lost"] = delta(ik, before["ik"], f"{ns}/servo_angles subscribers lost")
        result["ik_angles_regained"] = delta(ik, before["ik"], f"{ns}/servo_angles subscribers regained")
        now_unreach = self.unreachable_lines()
        result["unreachable_lines"] = {k: now_unreach[k] - before["unreachable"].get(k, 0) for k in now_unreach}
        return result

    def close(self):
        codes = {}
        for p in self.procs:
            codes[p.name] = p.stop()
        try:
            self.o.close()
        finally:
            if self.uno is not None:
                codes["device"] = self.uno.stop()
        return codes
