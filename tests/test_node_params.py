"""Parameters at valid non-default values, through the running nodes: what each one
changes is observed on the wire or on the topics, not read back from the node.

No assertion here is a wall-clock bound that a slow host can break: a rate limit is
checked as a count of messages against the time that the test itself saw go by (a
slower host sends fewer, never more), and a setting the node hands on (baud, watchdog)
is read where it arrives (the port's termios, the device's CONFIG frame)."""
import fcntl
import math
import os
import pty
import struct
import termios
import time
import tty

from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState

from conftest import TfListener
from robot_facts import servo_deg
from interop.servo_link import CONFIG, HEARTBEAT, HELLO, HELLO_ACK, SET_PULSES, STATE, Decoder, frame

SERVOS = ["base_servo", "shoulder_servo", "elbow_servo", "gripper_servo"]
BASE_95_TICKS = round(2 * (544 + 1856 * 95 / 180))


def seconds(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_now(msg):
    t = time.time()
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
    return msg


# ---------------------------------------------------------------------------------------
# serial_node: a device of the test's own behind a pty, which records every frame

def port_speed(fd):
    """(input, output) baud of a tty, from Linux's termios2 (TCGETS2): serial_node sets
    it as a number (BOTHER), which termios.tcgetattr cannot show."""
    fmt = "4I B 19B 2I"  # c_iflag, c_oflag, c_cflag, c_lflag, c_line, c_cc[19], c_ispeed, c_ospeed
    size = struct.calcsize(fmt)
    tcgets2 = (2 << 30) | (size << 16) | (ord("T") << 8) | 0x2A  # _IOR('T', 0x2A, struct termios2)
    fields = struct.unpack(fmt, fcntl.ioctl(fd, tcgets2, bytes(size)))
    cflag, ispeed, ospeed = fields[2], fields[-2], fields[-1]
    if cflag & termios.CBAUD != 0o010000:  # not BOTHER: one of the B* constants
        names = {getattr(termios, n): int(n[1:]) for n in dir(termios) if n[:1] == "B" and n[1:].isdigit()}
        ispeed = ospeed = names.get(cflag & termios.CBAUD)
    return ispeed, ospeed


class FakeDevice:
    """The Arduino's side of a pty: answers HELLO with HELLO_ACK and every other frame
    with a STATE (running, servos where the last SET_PULSES put them), and keeps each
    frame as (arrival time, type, payload)."""

    def __init__(self, tmp_path):
        self.master, self.slave = pty.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.link = tmp_path / "tty"
        os.symlink(os.ttyname(self.slave), self.link)
        self.decoder, self.seq = Decoder(), 0
        self.ticks = (3000, 3000, 3000, 3000)
        self.frames = []

    def serve(self, observer, seconds, publish=None, until=None):
        """Answer for `seconds` (or until `until()` holds), spinning rclpy; `publish()` is
        called every millisecond."""
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (until is not None and until()):
            if publish is not None:
                publish()
            observer.executor.spin_once(timeout_sec=0.001)
            try:
                data = os.read(self.master, 4096)
            except BlockingIOError:
                continue
            now = time.monotonic()
            for msg_type, s, payload in self.decoder.feed(data):
                self.frames.append((now, msg_type, payload))
                self.seq += 1
                if msg_type == HELLO:
                    reply = frame(HELLO_ACK, self.seq, struct.pack("<BBBBH", payload[0], 1, 0, 4, 500))
                else:
                    if msg_type == SET_PULSES:
                        self.ticks = struct.unpack("<4H", payload)
                    reply = frame(STATE, self.seq, struct.pack("<BBBB4H", s, 1, 0, 0, *self.ticks))
                os.write(self.master, reply)

    def of(self, msg_type, since=0.0):
        return [(t, p) for t, m, p in self.frames if m == msg_type and t >= since]

    def close(self):
        os.close(self.master)
        os.close(self.slave)


def start_serial_node(launch, observer, tmp_path, *params):
    dev = FakeDevice(tmp_path)
    proc = launch("serial_node", "--ros-args", "-p", f"port:={dev.link}", *params)
    angles = observer.pub("/servo_angles", JointState)
    observer.wait_matched(angles)
    # the handshake: HELLO, then CONFIG
    deadline = time.monotonic() + 15
    while not dev.of(CONFIG) and time.monotonic() < deadline:
        dev.serve(observer, 0.1)
    assert dev.of(CONFIG), f"no CONFIG after the handshake; frames {[m for _, m, _ in dev.frames]}\n{proc.output()}"
    return dev, proc, angles


def test_serial_node_hands_the_watchdog_settings_and_the_baud_to_the_device(launch, observer, tmp_path):
    """watchdog_ms 1500 and watchdog_action detach (defaults 500, hold) are what the
    device is told in CONFIG; baud 57600 (default 115200) is what the port is set to."""
    dev, _, _ = start_serial_node(launch, observer, tmp_path, "-p", "watchdog_ms:=1500",
                                  "-p", "watchdog_action:=detach", "-p", "baud:=57600")
    try:
        (_, payload), = dev.of(CONFIG)[:1]
        assert struct.unpack("<HB", payload) == (1500, 1), f"CONFIG {payload.hex()}: (watchdog_ms, detach) expected (1500, 1)"
        assert port_speed(dev.slave) == (57600, 57600), f"port speed (in, out) {port_speed(dev.slave)}, not 57600"
    finally:
        dev.close()


def test_serial_node_keeps_the_device_fed_at_the_heartbeat_period(launch, observer, tmp_path):
    """heartbeat_period 0.5 s (default 0.1): with no command, a HEARTBEAT comes after
    each 0.5 s of silence, so at most one per 0.5 s of the test's time (at the default,
    three times as many as the bound below)."""
    period = 0.5
    dev, _, _ = start_serial_node(launch, observer, tmp_path, "-p", f"heartbeat_period:={period}")
    try:
        t0 = time.monotonic()  # every heartbeat counted below is sent after this
        dev.serve(observer, 4.0)
        beats = dev.of(HEARTBEAT, since=t0)
        window = time.monotonic() - t0
        bound = window / period + 1
        print(f"\n{len(beats)} heartbeats in {window:.2f} s (at most {bound:.1f})")
        assert len(beats) >= 3, f"{len(beats)} heartbeats in {window:.2f} s of silence: the watchdog is not fed"
        assert len(beats) <= bound, f"{len(beats)} heartbeats in {window:.2f} s: more than one per {period} s"
        assert not dev.of(SET_PULSES), "pulses without a command"
    finally:
        dev.close()


def test_serial_node_sends_at_most_send_rate_frames_a_second(launch, observer, tmp_path):
    """send_rate 5 (default 100): 300 commands, one a millisecond or as fast as the
    host allows, reach the device as at most 5 SET_PULSES a second of the time they
    took (a token bucket of 2, so 5 x the time seen + 2), the newest command last."""
    rate = 5.0
    dev, _, angles = start_serial_node(launch, observer, tmp_path, "-p", f"send_rate:={rate}")
    try:
        n = 0

        def publish(deg):
            nonlocal n
            n += 1
            angles.publish(JointState(name=list(SERVOS), position=[math.radians(d) for d in (deg, 90, 90, 90)]))

        t0 = time.monotonic()
        # base 90-94 deg (within a step the servos take at once, no ramp), then 95 deg
        # (a count, not a time: a slow host takes longer and the bound grows with it)
        dev.serve(observer, 60.0, publish=lambda: publish(90 + n % 5), until=lambda: n >= 300)
        assert n == 300, f"{n} commands published in 60 s"
        publish(95)
        # until the 95 deg command's frame (base: 544 + 1856 x 95 / 180 us in 0.5 us
        # ticks, serial_node's default calibration): the bound only ends a failure
        dev.serve(observer, 15.0, until=lambda: any(struct.unpack("<4H", p)[0] == BASE_95_TICKS
                                                     for _, p in dev.of(SET_PULSES, since=t0)))
        window = time.monotonic() - t0
        sent = dev.of(SET_PULSES, since=t0)
        bound = rate * window + 2
        print(f"\n{n} commands, {len(sent)} SET_PULSES in {window:.2f} s (at most {bound:.1f})")
        assert 2 <= len(sent) <= bound, f"{len(sent)} SET_PULSES in {window:.2f} s: more than {rate} a second"
        # the base servo's widths grow (or all shrink) with the angle: the newest
        # command, 95 deg, is beyond every earlier one's 90-94 deg
        base = [struct.unpack("<4H", p)[0] for _, p in sent]
        assert all(b < base[-1] for b in base[:-1]) or all(b > base[-1] for b in base[:-1]), \
            f"the last frame is not the newest command: base widths {base}"
    finally:
        dev.close()


# ---------------------------------------------------------------------------------------
# state_publisher: publish_frequency

def test_state_publisher_throttles_tf_to_publish_frequency(launch, observer, domain):
    """publish_frequency 4 (default 0: one tf per joint_states): 200 joint_states at
    about 200 Hz give at most 4 tf messages a second of the time they took, the newest
    position last (latest wins)."""
    freq = 4.0
    tf = TfListener(domain)
    try:
        launch("state_publisher", "--ros-args", "-p", f"publish_frequency:={freq}")
        js = observer.pub("/joint_states", JointState)
        observer.wait_matched(js)
        deadline = time.monotonic() + 10
        while not tf.static and time.monotonic() < deadline:
            tf.poll()
            observer.spin_for(0.05)
        tf.poll()
        tf.messages.clear()
        t0 = time.monotonic()
        n = 0
        while n < 200:  # a count: a slow host takes longer, and the bound grows with it
            n += 1
            js.publish(stamp_now(JointState(name=["base_joint"], position=[0.001 * (n % 100)])))
            observer.spin_for(0.005)
            tf.poll()
        js.publish(stamp_now(JointState(name=["base_joint"], position=[0.5])))

        def turntable_angle():  # base_joint's child, about z
            t = tf.dynamic.get("turntable")
            return None if t is None else 2 * math.atan2(t.transform.rotation.z, t.transform.rotation.w)

        # until the newest joint_states is in tf (the bound only ends a failure)
        end = time.monotonic() + 15
        while time.monotonic() < end and not (turntable_angle() is not None and abs(turntable_angle() - 0.5) < 1e-6):
            observer.spin_for(0.05)
            tf.poll()
        window = time.monotonic() - t0
        bound = freq * window + 1
        print(f"\n{n + 1} joint_states, {len(tf.messages)} tf messages in {window:.2f} s (at most {bound:.1f})")
        assert 2 <= len(tf.messages) <= bound, f"{len(tf.messages)} tf messages in {window:.2f} s: more than {freq} a second"
        angle = turntable_angle()
        assert angle is not None, f"no base_joint in tf: {sorted(tf.dynamic)}"
        assert abs(angle - 0.5) < 1e-6, f"the last tf is not the newest joint_states: base_joint at {angle} rad, not 0.5"
    finally:
        tf.close()


# ---------------------------------------------------------------------------------------
# compute_ik: motion_rate

def test_compute_ik_steps_a_motion_at_motion_rate(launch, observer):
    """motion_rate 10 (default 50): a planned motion's steps on servo_angles come at
    most 10 a second of compute_ik's own clock (the stamps of the steps after the first,
    which carries the target's stamp: zero, so when it arrived), and there are several
    of them (at the default rate, five times as many)."""
    rate = 10.0
    launch("compute_ik", "--ros-args", "-p", f"motion_rate:={rate}")
    sa = observer.sub("/servo_angles", JointState)
    xyz = observer.pub("/xyz_target", PointStamped)
    observer.wait_matched(xyz)
    observer.wait_publisher("/servo_angles")
    n0 = len(sa)
    # a zero stamp means now: never refused as too old on a slow host, and the first
    # step carries the instant the target arrived (on this host's clock: later than
    # `sent`, so nothing compute_ik published before it is taken for it)
    m = PointStamped()
    m.header.frame_id = "base_link"
    m.point.x, m.point.y, m.point.z = 0.16, -0.08, 0.21
    sent = time.time()
    xyz.publish(m)
    assert observer.spin_until(lambda: any(seconds(s.header.stamp) >= sent for _, s in sa[n0:]), 30), "no first step"
    first = next(seconds(s.header.stamp) for _, s in sa[n0:] if seconds(s.header.stamp) >= sent)
    # the motion ends at the target's IK (known in advance: ROBOT.md's servo angles)
    final = servo_deg(m.point.x, m.point.y, m.point.z)
    assert observer.spin_until(lambda: all(abs(math.degrees(a) - d) <= 1e-9 for a, d in zip(sa[-1][1].position, final)), 30), \
        f"the motion did not end at {final}: the last step {[math.degrees(a) for a in sa[-1][1].position]}"
    steps = [s for _, s in sa[n0:]]
    i = next(k for k, s in enumerate(steps) if seconds(s.header.stamp) == first)
    later = [seconds(s.header.stamp) for s in steps[i + 1:]]
    assert len(later) >= 3, f"{len(later) + 1} steps: not a planned motion"
    # step k comes no sooner than k periods after the target arrived, the first step's
    # stamp: so k <= (its stamp - the first's) x rate, however late
    # (or in a catch-up burst) a step may come on a loaded host
    span = later[-1] - first
    bound = span * rate
    print(f"\n{len(later) + 1} steps; the last {span:.3f} s after the target (at most {bound:.1f} steps after the first)")
    assert len(later) <= bound, f"{len(later)} steps within {span:.3f} s of the target: more than {rate} a second"
