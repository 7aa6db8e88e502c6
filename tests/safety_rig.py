"""serial_node driving the real firmware in simavr, as issue 9's e-stop and hot-plug checks
need it: a 50 Hz servo_angles stream from rclpy, the board's USB cable pulled and the board
reset, and the pin edges read back against the velocity limit of config/arm.yaml.

Used by tests/test_estop_and_hotplug.py (one trial of each kind, 20 hot-plug cycles) and
tests/bench/estop_hotplug.py (the timing figures: e-stop latency, reconnect time).

Clocks: simavr's cycle counter for everything on the board; its `w` events tie a cycle to
CLOCK_REALTIME when the harness read the bytes from the pty, so a time.time_ns() taken in
the test (just before rclpy publishes) can be compared with a board event. serial_node at
`--log-level debug` writes each frame it sends with the moment its link decided it
(`wrote seq N ...`, the clock its velocity guard ramps on): sent_clock reads them back.
The velocity check judges a ramp on it, since the harness, starved of CPU, can read two
frames sent 20 ms apart within one read."""
import bisect
import math
import re
import struct
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from conftest import REPO, latest_status, status_values
from interop.servo_link import ESTOP, SET_PULSES, STATE, Decoder, SimulatedUno, parse_state

FIRMWARE = REPO / "firmware" / "servo_control"
SERVOS = ["base_servo", "shoulder_servo", "elbow_servo", "gripper_servo"]
CYCLES_PER_S = 16_000_000
SERVO_PERIOD_S = 0.020
# ROBOT.md's servo mapping: 544 us at 0 deg, 2400 us at 180 deg
US_PER_DEG = (2400 - 544) / 180
# firmware/servo_control/config.h: the pose a board reports before its first command
HOLD_US = [1472.0, 1472.0, 1472.0, 1162.5]
# two poses (servo horn degrees) a move of about 0.3 s apart at the servos' speed
A = [60.0, 70.0, 110.0, 60.0]
B = [130.0, 110.0, 80.0, 140.0]


def pulse_us(deg):
    return 544 + US_PER_DEG * deg


def velocity_limits_us_per_s():
    """config/arm.yaml's motion limits per servo horn, as pulse width per second."""
    import yaml

    motion = yaml.safe_load((REPO / "config" / "arm.yaml").read_text())["motion"]
    return [motion[j]["max_velocity_deg_s"] * US_PER_DEG for j in ("base", "shoulder", "elbow", "gripper")]


def angles(deg, sec=None):
    m = JointState(name=list(SERVOS), position=[math.radians(d) for d in deg])
    t = time.time() if sec is None else sec
    m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
    return m


WROTE = re.compile(r"^\[DEBUG\] \[[^\]]*\] \[[^\]]*\]: wrote seq (\d+) SetPulses \{ ticks: \[([\d, ]+)\] \}, "
                   r"decided at (\d+)\.(\d{9}) ")
# how much later than the harness's read of a frame serial_node may say it decided it:
# its two clock reads (a monotonic one at the decision, CLOCK_REALTIME after the
# write) can be split by a preemption
DECIDED_SLACK_NS = 50_000_000


def sent_clock(log_text):
    """serial_node's trace of the SET_PULSES it wrote (its log at `--log-level debug`):
    [(CLOCK_REALTIME ns at which its link decided the frame, seq, ticks)]."""
    out = []
    for line in log_text.splitlines():
        m = WROTE.match(line)
        if m:
            seq, ticks, sec, nsec = m.groups()
            decided = int(sec) * 1_000_000_000 + int(nsec)
            out.append((decided, int(seq), tuple(int(t) for t in ticks.split(","))))
    return out


class BoardEvents:
    """One simavr run's event file, parsed; `sent`: serial_node's sent_clock, if it kept one
    (or a function giving it, called when first needed)."""

    def __init__(self, path, sent=None):
        self._sent = sent
        self.edges, self.rx, self.tx, self.walls, self.cable = [], [], [], [], []
        for line in Path(path).read_text().splitlines():
            p = line.split()
            if p[0] == "e" and len(p) == 4:
                self.edges.append((int(p[1]), int(p[2]), int(p[3])))
            elif p[0] == "r" and len(p) == 3:
                self.rx.append((int(p[1]), int(p[2])))
            elif p[0] == "t" and len(p) == 3:
                self.tx.append((int(p[1]), int(p[2])))
            elif p[0] == "w" and len(p) == 3:
                self.walls.append((int(p[1]), int(p[2])))
            elif p[0] == "u" and len(p) == 3:
                self.cable.append((int(p[1]), p[2] == "1"))
        self._wall_cycles = [c for c, _ in self.walls]

    def frames(self):
        """Frames the AVR received, in order: [(type, seq, payload, cycle of the last byte)].
        The cycle is when the harness handed the byte to the UART: the bytes of one read
        share it, and the firmware takes them in at the baud rate after."""
        return self._decode(self.rx)

    def replies(self):
        """Frames the AVR sent: [(type, seq, payload, cycle of the last byte)]."""
        return self._decode(self.tx)

    @staticmethod
    def _decode(stream):
        d, out = Decoder(), []
        for cycle, b in stream:
            out += [(*f, cycle) for f in d.feed(bytes([b]))]
        return out

    def pulses(self, pin):
        """[(rise cycle, width us)] of every complete pulse on `pin`."""
        out, rise = [], None
        for cycle, p, level in self.edges:
            if p != pin:
                continue
            if level == 1:
                rise = cycle
            elif rise is not None:
                out.append((rise, (cycle - rise) / 16))
                rise = None
        return out

    def decided_ns(self, cycle, seq, ticks):
        """When serial_node decided the SET_PULSES (`seq`, `ticks`) the AVR got at `cycle`:
        the latest such frame it wrote before the harness read it (seq wraps at 256, at
        most every 2.5 s), or None without a trace."""
        if not isinstance(self._sent, list):
            self._sent = sorted((self._sent() if callable(self._sent) else self._sent) or [])
        sent = self._sent
        read = self.wall_ns(cycle) + DECIDED_SLACK_NS
        i = bisect.bisect_right(sent, (read, 256, ()))
        return next((sent[j][0] for j in range(i - 1, max(i - 512, 0) - 1, -1)
                     if sent[j][1:] == (seq, ticks)), None)

    def wall_ns(self, cycle):
        """CLOCK_REALTIME of a board cycle: the last pty read at or before it, plus the
        simulated time since."""
        i = bisect.bisect_right(self._wall_cycles, cycle)
        c, ns = self.walls[max(i - 1, 0)]
        return ns + (cycle - c) * 1_000_000_000 // CYCLES_PER_S

    def cycle_after(self, ns):
        """The cycle of the first pty read at or after CLOCK_REALTIME `ns`: the board
        simulated every cycle from it on after `ns` (an order of events, whatever the
        host's load; None: no read after it)."""
        return next((c for c, w in self.walls if w >= ns), None)

    def cycle_before(self, ns):
        """The cycle of the last pty read at or before CLOCK_REALTIME `ns`: the board
        simulated every cycle before it before `ns` (None: no read before it)."""
        return next((c for c, w in reversed(self.walls) if w <= ns), None)


def step_allowed_us(limit_us_per_s, seconds):
    """The most a pulse width may change over `seconds` plus one servo period (two frames
    the host sent within one period land on one pulse), with 1.5 us for the pulse timing."""
    return limit_us_per_s * (seconds + SERVO_PERIOD_S) + 1.5


def sent_ticks(events):
    """[(cycle, ticks)] of every SET_PULSES the AVR received."""
    return [(c, ticks) for c, _, ticks in sent_frames(events)]


def sent_frames(events):
    """[(cycle, seq, ticks)] of every SET_PULSES the AVR received."""
    return [(c, seq, struct.unpack("<4H", p)) for t, seq, p, c in events.frames() if t == SET_PULSES]


def untraced(events):
    """SET_PULSES the board got that serial_node's trace does not show (the velocity
    check's own clock: none may be missing)."""
    return [(c, seq) for c, seq, ticks in sent_frames(events) if events.decided_ns(c, seq, ticks) is None]


def velocity_violations(events, limits_us_per_s, start_us=None):
    """Pulse-width steps faster than the velocity limit, per pin, between consecutive
    pulses. The time between two pulses is the longest of four clocks:
    - simulated time;
    - wall time: a harness starved of CPU falls behind and then hands the AVR what
      serial_node wrote meanwhile all at once, compressing in simulated time a ramp that
      was on time;
    - the wall time between the arrivals of the frames the two pulses show (shown_frame):
      a frame that arrives while a pulse is latched shows one pulse late, and when the
      harness delivered it late too, the next pulse shows a frame sent more than a
      period after it (a CI run: frames 106-107 read late, pulses from frame 105 then
      from 108, 128 us apart in 18.8 ms of pulses but 38.8 ms of frames);
    - serial_node's own, when the events carry its trace (BoardEvents's `sent`): the time
      between the moments its link decided those two frames. The harness reads frames
      late, never early, so the arrivals understate a ramp's time when it read the first
      frame late (a CI run: boot 4 of the reset cycles, 133 us between pulses showing
      frames read 20.6 ms apart).
    `start_us`: where the first SET_PULSES must start from (a board that just booted
    reports its hold pose), judged on the frame, since no pulse precedes it."""
    bad = []
    sends = sent_frames(events)
    for pin, limit in enumerate(limits_us_per_s):
        if start_us is not None and sends:
            first = sends[0][2][pin] / 2
            if abs(first - start_us[pin]) > step_allowed_us(limit, 0.0):
                bad.append((pin, "first frame", start_us[pin], first))
        frames = [(c, ticks[pin] / 2) for c, _, ticks in sends]
        ps = events.pulses(pin)
        for (c0, w0), (c1, w1) in zip(ps, ps[1:]):
            dt = max((c1 - c0) / CYCLES_PER_S, (events.wall_ns(c1) - events.wall_ns(c0)) / 1e9)
            f0, f1 = shown_frame(frames, c0, w0), shown_frame(frames, c1, w1)
            if f0 is not None and f1 is not None:
                dt = max(dt, (events.wall_ns(frames[f1][0]) - events.wall_ns(frames[f0][0])) / 1e9)
                d0, d1 = (events.decided_ns(*sends[f]) for f in (f0, f1))
                if d0 is not None and d1 is not None:
                    dt = max(dt, (d1 - d0) / 1e9)
            if abs(w1 - w0) > step_allowed_us(limit, dt):
                bad.append((pin, c1, w0, w1, round(step_allowed_us(limit, dt), 1)))
    return bad


def shown_frame(frames, rise_cycle, width_us, back=32, tolerance_us=1.0):
    """The index in `frames` ([(cycle, us)] of one pin) of the SET_PULSES frame a pulse
    shows: the latest of the last `back` frames before the pulse's rise whose width is
    the pulse's, or None (a pulse before any frame, or one that shows none of them).
    `back` spans a starved harness's burst: a soak run read five frames at once (580 ms
    late), and the pulse before the last of them showed the first, five back."""
    i = bisect.bisect_left(frames, (rise_cycle, -1.0))
    for j in range(i - 1, max(i - back, 0) - 1, -1):
        if abs(frames[j][1] - width_us) <= tolerance_us:
            return j
    return None


class SerialNodeRig:
    """serial_node (launched by the test's `launch`) on `port`, and rclpy's ends of its
    topics: servo_state and diagnostics read, servo_angles and estop written."""

    def __init__(self, launch, observer, port, diagnostics_period, *params):
        self.o = observer
        self.node = launch("serial_node", "--ros-args", "-p", f"port:={port}",
                           "-p", f"diagnostics_period:={diagnostics_period}", *params)
        self.state = observer.sub("/servo_state", JointState)
        self.diags = observer.sub("/diagnostics", DiagnosticArray)
        self.angles = observer.pub("/servo_angles", JointState)
        self.estop = observer.pub("/estop", Bool)  # the contract's QoS: latched
        observer.wait_matched(self.angles)
        observer.wait_publisher("/diagnostics")

    def status(self):
        """serial_node's latest diagnostics entry, or None."""
        return latest_status(self.diags, "serial_node")


class Rig(SerialNodeRig):
    """serial_node on a board in simavr; rclpy streams."""

    def __init__(self, launch, observer, tmp_path, *params, start_board=True):
        self.tmp, self.launch = Path(tmp_path), launch
        self.boots = []
        if start_board:
            self.boot()
        # at debug, serial_node's trace of what it wrote (sent_clock)
        super().__init__(launch, observer, self.tmp / "tty", 0.1, "--log-level", "debug", *params)
        self.target = None
        self.next_send = 0.0

    @property
    def board(self):
        return self.boots[-1]

    def boot(self):
        """Power the board up (again): a fresh simavr, the same pty link."""
        self.boots.append(SimulatedUno(self.tmp, FIRMWARE, boot=len(self.boots)))

    def events(self, boot=-1):
        return BoardEvents(self.boots[boot].events_path, lambda: sent_clock(self.node.output()))

    def diag(self):
        return status_values(self.status())

    def connected(self, reconnects=0):
        """serial_node reports the board connected, after `reconnects` reconnects."""
        d = self.diag()
        return d.get("connection") == "connected" and int(d.get("reconnects") or 0) == reconnects

    def estop_mid_move(self):
        """At A, a move towards B and 0.1 s into it the e-stop published; returns the wall
        time just before the publish, once the board reports the e-stop engaged."""
        self.target = A
        assert self.spin(until=lambda: self.at(A), timeout=5), self.acked_deg()
        self.target = B  # a move of 0.3 s at the servos' speed
        self.spin(0.1)
        t_pub = time.time_ns()
        self.estop.publish(Bool(data=True))
        assert self.spin(until=lambda: self.diag().get("device_state") == "e-stop", timeout=5), self.diag()
        return t_pub

    def released(self):
        """serial_node and the board are out of the e-stop: the board runs, is idle, or
        holds on its watchdog (a harness starved of CPU can leave the AVR without a frame
        for over 500 ms of simulated time: the pins hold, as they do after a release)."""
        d = self.diag()
        return d.get("estop") == "false" and d.get("device_state") in ("running", "idle", "watchdog hold")

    def release_estop(self):
        """The stream stopped and the e-stop released; returns once the board is out of it."""
        self.target = None
        self.estop.publish(Bool(data=False))
        assert self.spin(until=self.released, timeout=15), self.diag()

    def hotplug_cycles(self, kind, cycles):
        """Once connected and at A, `cycles` hot-plug cycles (hotplug_cycle) of `kind`;
        returns the wall time each was plugged back (or booted)."""
        assert self.spin(until=self.connected, timeout=15), self.diag()
        self.target = A
        assert self.spin(until=lambda: self.at(A), timeout=5), self.acked_deg()
        up_at = []
        for i in range(cycles):
            self.hotplug_cycle(kind, i, up_at)
        return up_at

    def hotplug_cycle(self, kind, i, up_at):
        """Hot-plug cycle `i` of 0, 1, ...: a move towards B (even i) or A (odd i), 0.1 s
        into it the USB cable pulled (kind "cable"; the board runs on) or the board
        stopped (kind "reset"), for 0.3 s; then plugged back (the wall time appended to
        `up_at`) or booted again. Returns when serial_node has reconnected (its i + 1-th
        reconnect) and the board is at the target."""
        self.target = B if i % 2 == 0 else A
        self.spin(0.1)  # mid-move
        if kind == "cable":
            self.board.toggle_cable(False)
        else:
            self.board.stop()
        assert self.spin(until=lambda: self.diag().get("connection") == "disconnected", timeout=5), f"cycle {i}: {self.diag()}"
        self.spin(0.3)
        up_at.append(time.time_ns())
        if kind == "cable":
            self.board.toggle_cable(True)
        else:
            self.boot()
        assert self.spin(until=lambda: self.connected(i + 1), timeout=10), f"cycle {i}: {self.diag()}"
        assert self.spin(until=lambda: self.at(self.target), timeout=5), f"cycle {i}: {self.acked_deg()}"

    def spin(self, seconds=None, until=None, timeout=10.0):
        """Spin rclpy, publishing the current target at 50 Hz (stamped now) when there
        is one; until `until()` holds (returns whether it did) or for `seconds`."""
        end = time.monotonic() + (seconds if seconds is not None else timeout)
        while time.monotonic() < end:
            if until is not None and until():
                return True
            now = time.monotonic()
            if self.target is not None and now >= self.next_send:
                self.angles.publish(angles(self.target))
                self.next_send = max(self.next_send + SERVO_PERIOD_S, now - SERVO_PERIOD_S)
            self.o.executor.spin_once(timeout_sec=max(0.0, min(0.005, self.next_send - time.monotonic())))
        return until() if until is not None else True

    def acked_deg(self):
        """The servo angles the device last acknowledged (servo_state), rounded to 0.1 deg."""
        return [round(math.degrees(a), 1) for a in self.state[-1][1].position] if self.state else None

    def at(self, deg):
        return self.acked_deg() == [round(d, 1) for d in deg]

    def stop(self):
        codes = [b.stop() for b in self.boots if b.proc.poll() is None]
        return codes


def estop_held(events, after_cycle, seq):
    """The board's answer to the ESTOP frame `seq` it got at `after_cycle`: (the cycle of
    the STATE's last byte, the ticks it says its next pulses start from). Sent once the
    firmware has applied the e-stop: from that cycle on the pins show it."""
    return next((c, tuple(parse_state(p)["ticks"])) for t, _, p, c in events.replies()
                if t == STATE and c >= after_cycle and p[0] == seq)


def last_width_change(events, after_cycle, before_cycle=None):
    """The rise of the last pulse, on any pin, whose width differs (by more than 1 us) from
    the pulse before it on that pin, among the pulses after `after_cycle` and before
    `before_cycle`; `after_cycle` if there is none. From there on no servo was given a new
    position: after an e-stop (hold) that moment, not the next pulse's rise (the frame's
    phase), is when the servos are held."""
    last = after_cycle
    for pin in range(4):
        ps = events.pulses(pin)
        for (_, w0), (c1, w1) in zip(ps, ps[1:]):
            if c1 > after_cycle and (before_cycle is None or c1 < before_cycle) and abs(w1 - w0) > 1.0:
                last = max(last, c1)
    return last


def engaged_estop_frames(events):
    """ESTOP frames that engage (payload 1 hold, 2 detach): [(payload, seq, cycle)]."""
    return [(p[0], seq, c) for t, seq, p, c in events.frames() if t == ESTOP and p[0] in (1, 2)]


def set_pulses_cycles(events):
    return [c for t, _, _, c in events.frames() if t == SET_PULSES]


def reconnect_ms(rig, kind, up_at):
    """Per hot-plug cycle of `kind` (Rig.hotplug_cycles, which returned `up_at`): the time
    from plugging back (or booting) to the first SET_PULSES the board received after it, ms."""
    if kind == "cable":
        ev = rig.events()
        plugs = [c for c, plugged in ev.cable if plugged]
        sends = set_pulses_cycles(ev)
        return [(ev.wall_ns(next(c for c in sends if c > c_plug)) - t_up) / 1e6 for t_up, c_plug in zip(up_at, plugs)]
    boots = [rig.events(boot) for boot in range(1, len(up_at) + 1)]
    return [(ev.wall_ns(set_pulses_cycles(ev)[0]) - t_up) / 1e6 for ev, t_up in zip(boots, up_at)]
