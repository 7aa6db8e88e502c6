"""serial_node with the virtual Arduino (in-process and behind a pty), a misbehaving
device, and the real firmware in simavr at the end of the whole chain."""
import math
import os
import signal
import statistics
import subprocess
import time

import pytest
from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters

from conftest import REPO, bin_path, status_values
from interop.servo_link import HELLO, HELLO_ACK, STATE, Decoder, SimulatedUno, frame, pulses
from safety_rig import SerialNodeRig
import struct

SERVOS = ["base_servo", "shoulder_servo", "elbow_servo", "gripper_servo"]
FIRMWARE = REPO / "firmware" / "servo_control"


def angles(deg, sec=0):
    m = JointState(name=list(SERVOS), position=[math.radians(d) for d in deg])
    m.header.stamp.sec = sec
    return m


def pulse_us(deg):
    """ROBOT.md / the Servo library: 544 us at 0 deg, 2400 us at 180 deg."""
    return 544 + (2400 - 544) * deg / 180


class SerialRig(SerialNodeRig):
    def __init__(self, launch, observer, port="mock", *extra):
        super().__init__(launch, observer, port, 0.2, *extra)

    def diag(self):
        """serial_node's latest diagnostics entry (other nodes publish there too): (status, values)."""
        s = self.status()
        return s, status_values(s)

    def wait_diag(self, pred, timeout=10):
        return self.o.spin_until(lambda: self.diag()[0] is not None and pred(*self.diag()), timeout)


def test_mock_arduino_acknowledges_with_the_command_stamp(launch, observer):
    rig = SerialRig(launch, observer)
    assert rig.wait_diag(lambda s, v: v.get("connection") == "connected")
    rig.angles.publish(angles([80, 100, 70, 120], sec=42))
    assert observer.spin_until(lambda: any(m.header.stamp.sec == 42 for _, m in rig.state), 10)
    # the modelled horns reach the command at servo speed; heartbeats report them
    assert observer.spin_until(lambda: [round(math.degrees(p), 1) for p in rig.state[-1][1].position] == [80.0, 100.0, 70.0, 120.0], 5)
    assert rig.wait_diag(lambda s, v: int(v["frames_sent"]) >= 1 and int(v["frames_acknowledged"]) >= 1 and v["last_rtt_ms"])


def test_servo_state_is_a_steady_stream_while_idle(launch, observer):
    """As ros2_control's joint_state_broadcaster: servo_state keeps coming while nothing
    moves (each heartbeat's STATE reply, 10 Hz by default), stamped when the device
    reported, so a user who subscribes after a move (`ros2 topic echo --once`) gets the
    arm's state at once, and its positions are the ones the device holds."""
    rig = SerialRig(launch, observer)
    assert rig.wait_diag(lambda s, v: v.get("connection") == "connected")
    rig.angles.publish(angles([80, 100, 70, 120], sec=42))
    assert observer.spin_until(lambda: [round(math.degrees(p), 1) for p in rig.state[-1][1].position]
                               == [80.0, 100.0, 70.0, 120.0], 10)
    observer.spin_for(1)  # the move is over
    idle = observer.sub("/servo_state", JointState)  # a late subscriber
    t0 = time.monotonic()
    assert observer.spin_until(lambda: idle, 2), "no servo_state within 2 s of subscribing, while idle"
    first_s = time.monotonic() - t0
    observer.spin_for(3)
    window = [(t, m) for t, m in idle if t >= t0 + 0.5]
    rate = (len(window) - 1) / (window[-1][0] - window[0][0])
    print(f"\nidle servo_state: first {first_s * 1e3:.0f} ms after subscribing, {rate:.1f} Hz")
    # the rate is the benchmark's business; here: it does not stop (25 expected in 2.5 s)
    assert len(window) >= 12, f"{len(window)} idle servo_state in 2.5 s ({rate:.1f} Hz)"
    assert {tuple(round(math.degrees(p), 1) for p in m.position) for _, m in window} == {(80.0, 100.0, 70.0, 120.0)}
    now = time.time()
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in window]
    assert all(now - 5 < s <= now + 0.1 for s in stamps), "idle servo_state is not stamped when the device reported"
    assert stamps == sorted(stamps)


# the firmware's hold pose (config.h): the device reports it before the first command,
# so a first command at it needs no ramp
HOLD_DEG = [90, 90, 90, 60]


def test_bad_servo_angles_are_refused_and_nothing_is_sent(launch, observer):
    rig = SerialRig(launch, observer)
    assert rig.wait_diag(lambda s, v: v.get("connection") == "connected")
    rig.angles.publish(angles(HOLD_DEG))
    assert rig.wait_diag(lambda s, v: v["frames_sent"] == "1")
    bad = [
        (angles([90, 90, 90, 30]), "outside its range"),        # gripper below 60 deg
        (angles([90, math.nan, 90, 90]), "is nan"),
        (JointState(name=["base_servo"], position=[1.0]), "no position"),
        (JointState(name=SERVOS + ["x"], position=[1.0] * 5), "unknown servo"),
    ]
    for i, (msg, text) in enumerate(bad, start=1):
        rig.angles.publish(msg)
        assert rig.wait_diag(lambda s, v: v["inputs_rejected"] == str(i)), text
        assert text in rig.diag()[1]["last_rejection"].lower()
    observer.spin_for(0.3)
    assert rig.diag()[1]["frames_sent"] == "1"
    assert rig.node.proc.poll() is None


def test_latest_wins_at_1khz(launch, observer):
    rig = SerialRig(launch, observer)
    assert rig.wait_diag(lambda s, v: v.get("connection") == "connected")
    assert rig.diag()[1]["frames_sent"] == "0"
    start = time.monotonic()
    n = 0
    while n < 2000:
        rig.angles.publish(angles([60 + (n % 60), 90, 90, 90]))
        n += 1
        observer.executor.spin_once(timeout_sec=0.0005)
    last = 60 + ((n - 1) % 60)
    observer.spin_for(1.0)
    sent = int(rig.diag()[1]["frames_sent"])
    window = time.monotonic() - start  # every frame counted was sent within it
    rate = 100  # serial_node's default send_rate (frames a second; a token bucket of 2)
    print(f"\n{n} commands in {window:.2f} s: {sent} frames (at most {rate * window + 2:.0f})")
    # at most the rate however fast commands come (a slower host sends fewer, never
    # more); many commands to a frame: latest wins, none is queued
    assert sent <= rate * window + 2, f"{sent} frames in {window:.2f} s for {n} commands: more than the {rate} Hz rate"
    assert 2 <= sent <= n // 5, f"{sent} frames for {n} commands"
    # the newest command is the one applied
    assert observer.spin_until(lambda: round(math.degrees(rig.state[-1][1].position[0]), 1) == last, 3)


def test_estop_drops_commands_until_released(launch, observer):
    rig = SerialRig(launch, observer)
    assert rig.wait_diag(lambda s, v: v.get("connection") == "connected")
    rig.angles.publish(angles(HOLD_DEG))
    assert rig.wait_diag(lambda s, v: v["frames_sent"] == "1")
    rig.estop.publish(Bool(data=True))
    assert rig.wait_diag(lambda s, v: v["device_state"] == "e-stop")
    rig.angles.publish(angles([100, 90, 90, 60]))
    observer.spin_for(0.5)
    assert rig.diag()[1]["frames_sent"] == "1"
    assert rig.diag()[1]["inputs_dropped_in_estop"] == "1"
    rig.estop.publish(Bool(data=False))
    assert rig.wait_diag(lambda s, v: v["device_state"] == "running")
    observer.spin_for(0.3)
    assert rig.diag()[1]["frames_sent"] == "1", "a command from during the e-stop was sent"
    # a new command ramps (10 deg at the base servo's 300 deg/s: two frames)
    rig.angles.publish(angles([110, 90, 90, 60], sec=5))
    assert observer.spin_until(lambda: rig.state and round(math.degrees(rig.state[-1][1].position[0]), 1) == 110.0, 5)
    assert int(rig.diag()[1]["frames_sent"]) >= 2


def set_stalled_servos(observer, value):
    """`ros2 param set /serial_node mock_stalled_servos VALUE` through the parameter
    service; returns the SetParametersResult."""
    cli = observer.node.create_client(SetParameters, "/serial_node/set_parameters")
    try:
        assert cli.wait_for_service(timeout_sec=15), "no /serial_node/set_parameters"
        pv = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
        fut = cli.call_async(SetParameters.Request(parameters=[Parameter(name="mock_stalled_servos", value=pv)]))
        assert observer.spin_until(fut.done, 15), "set_parameters did not answer"
        [result] = fut.result().results
        return result
    finally:
        observer.node.destroy_client(cli)


def test_mock_stalled_servos_holds_a_servo_where_it_stopped_until_cleared(launch, observer):
    """The virtual Arduino's simulated stall (an obstacle): the stalled servo's
    servo_state stays where it was while the others follow the command, the link stays
    healthy, diagnostics say so; cleared, the servo reaches its command."""
    rig = SerialRig(launch, observer)
    assert rig.wait_diag(lambda s, v: v.get("connection") == "connected")
    deg = lambda: [round(math.degrees(p), 1) for p in rig.state[-1][1].position] if rig.state else None  # noqa: E731
    rig.angles.publish(angles([80, 100, 70, 120]))
    assert observer.spin_until(lambda: deg() == [80.0, 100.0, 70.0, 120.0], 10)
    # an unknown name is refused, with the names there are; nothing changes
    bad = set_stalled_servos(observer, "elbow")
    assert not bad.successful and "unknown servo `elbow`" in bad.reason and "elbow_servo" in bad.reason, bad
    assert set_stalled_servos(observer, "elbow_servo").successful
    assert rig.wait_diag(lambda s, v: v.get("mock_stalled_servos") == "elbow_servo"
                         and "simulated stall: elbow_servo" in s.message)
    sent = int(rig.diag()[1]["frames_acknowledged"])
    rig.angles.publish(angles([100, 110, 90, 140]))
    assert observer.spin_until(lambda: deg() == [100.0, 110.0, 70.0, 140.0], 10), deg()
    observer.spin_for(0.5)  # idle: the heartbeats' reports hold it there too
    assert deg() == [100.0, 110.0, 70.0, 140.0]
    # the protocol did not notice: acknowledged, nothing rejected, still connected
    assert rig.wait_diag(lambda s, v: int(v["frames_acknowledged"]) > sent)
    _, v = rig.diag()
    assert (v["connection"], v["frames_rejected_by_device"], v["inputs_rejected"]) == ("connected", "0", "0"), v
    # cleared: the elbow moves on to its latest command
    assert set_stalled_servos(observer, "").successful
    assert observer.spin_until(lambda: deg() == [100.0, 110.0, 90.0, 140.0], 10), deg()
    assert rig.wait_diag(lambda s, v: "mock_stalled_servos" not in v and "stall" not in s.message)


def start_virtual_arduino(link):
    p = subprocess.Popen([bin_path("virtual_arduino"), str(link)], stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 10
    while not os.path.exists(link):
        assert time.monotonic() < deadline and p.poll() is None, "virtual_arduino did not start"
        time.sleep(0.01)
    return p


def test_missing_port_then_unplug_and_replug(launch, observer, tmp_path):
    link = tmp_path / "tty"
    rig = SerialRig(launch, observer, str(link))
    # no device yet: the node keeps running and says why
    assert rig.wait_diag(lambda s, v: s.level == b"\x02" and "No such file" in s.message)
    dev = start_virtual_arduino(link)
    try:
        assert rig.wait_diag(lambda s, v: v.get("connection") == "connected", 15)
        rig.angles.publish(angles([70, 95, 85, 100], sec=7))
        assert observer.spin_until(lambda: any(m.header.stamp.sec == 7 for _, m in rig.state), 10)
        # unplug
        dev.kill()
        dev.wait(10)
        assert rig.wait_diag(lambda s, v: v.get("connection") == "disconnected")
        n_state = len(rig.state)
        # replug: handshake again and continue from the newest command, unasked
        dev = start_virtual_arduino(link)
        assert rig.wait_diag(lambda s, v: v.get("connection") == "connected" and v["reconnects"] == "1", 15)
        assert observer.spin_until(lambda: len(rig.state) > n_state
                                   and [round(math.degrees(p)) for p in rig.state[-1][1].position] == [70, 95, 85, 100], 10)
        assert rig.node.proc.poll() is None
    finally:
        dev.send_signal(signal.SIGINT)
        assert dev.wait(5) == 0


def test_mock_stalled_servos_has_no_effect_on_a_real_port(launch, observer, tmp_path):
    """On a serial port (here the virtual Arduino behind a pty) the stall cannot be
    simulated: the value is accepted, diagnostics say it has no effect, the servo moves."""
    link = tmp_path / "tty"
    dev = start_virtual_arduino(link)
    try:
        rig = SerialRig(launch, observer, str(link))
        assert rig.wait_diag(lambda s, v: v.get("connection") == "connected", 15)
        assert set_stalled_servos(observer, "elbow_servo").successful
        assert rig.wait_diag(lambda s, v: v.get("mock_stalled_servos") == "elbow_servo (no effect: not the virtual Arduino)")
        rig.angles.publish(angles([80, 100, 70, 120]))
        assert observer.spin_until(lambda: rig.state and [round(math.degrees(p), 1) for p in rig.state[-1][1].position]
                                   == [80.0, 100.0, 70.0, 120.0], 10)
        assert "stall" not in rig.diag()[0].message
    finally:
        dev.send_signal(signal.SIGINT)
        assert dev.wait(5) == 0


def test_garbage_from_the_device_is_counted_and_ignored(launch, observer, tmp_path):
    """A device that answers the handshake but also sends noise and broken frames."""
    import pty
    import tty
    master, slave = pty.openpty()
    tty.setraw(slave)
    link = tmp_path / "tty"
    os.symlink(os.ttyname(slave), link)
    os.set_blocking(master, False)
    rig = SerialRig(launch, observer, str(link))
    decoder, seq = Decoder(), 0
    try:
        def serve(seconds):
            nonlocal seq
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                observer.executor.spin_once(timeout_sec=0.01)
                try:
                    data = os.read(master, 256)
                except BlockingIOError:
                    continue
                for msg_type, s, _ in decoder.feed(data):
                    seq += 1
                    if msg_type == HELLO:
                        reply = frame(HELLO_ACK, seq, struct.pack("<BBBBH", 2, 9, 9, 4, 500))
                    else:
                        reply = frame(STATE, seq, struct.pack("<BBBB4H", s, 1, 0, 0, 3000, 3000, 3000, 3000))
                    broken = bytearray(reply)
                    broken[-1] ^= 0xFF
                    os.write(master, b"\x00garbage\xff" + bytes(broken) + reply)
        serve(2.0)
        assert rig.diags and rig.diag()[1].get("connection") == "connected"
        assert int(rig.diag()[1]["garbage_from_device"]) > 0
        rig.angles.publish(angles([90, 90, 90, 90], sec=5))
        serve(1.0)
        assert any(m.header.stamp.sec == 5 for _, m in rig.state)
        assert rig.node.proc.poll() is None
    finally:
        os.close(master)
        os.close(slave)


def test_target_to_pulses_through_the_firmware_in_simavr(launch, observer, tmp_path):
    """rclpy xyz_target -> compute_ik -> serial_node -> pty -> servo_control in simavr:
    the pulse widths on pins 8..11 are ROBOT.md's servo mapping, within 2 us."""
    uno = SimulatedUno(tmp_path, FIRMWARE)
    try:
        launch("compute_ik")
        rig = SerialRig(launch, observer, str(uno.tty_path))
        sa = observer.sub("/servo_angles", JointState)
        xyz = observer.pub("/xyz_target", PointStamped)
        observer.wait_matched(xyz)
        assert rig.wait_diag(lambda s, v: v.get("connection") == "connected", 15)
        for i, p in enumerate([(0.2, 0.05, 0.15), (0.16, -0.08, 0.21)]):
            m = PointStamped()
            m.header.frame_id = "base_link"
            t = time.time()
            m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
            m.point.x, m.point.y, m.point.z = p
            xyz.publish(m)
            assert observer.spin_until(lambda: any(s.header.stamp == m.header.stamp for _, s in rig.state), 10)
            # compute_ik streams the motion: the last servo_angles is where it ends
            n = len(sa)
            observer.spin_for(1.5)
            assert len(sa) > n or sa, "no servo_angles"
            deg = [math.degrees(a) for a in sa[-1][1].position]
            # serial_node ramps to it within the servos' speed limit: wait until it is there
            assert observer.spin_until(lambda: [round(math.degrees(a), 1) for a in rig.state[-1][1].position]
                                       == [round(d, 1) for d in deg], 5), (rig.state[-1][1].position, deg)
            acked_at = uno.events()[1][-1][0]
            observer.spin_for(0.25)
            edges, _ = uno.events()
            for pin in range(4):
                widths = [w for _, w in pulses(edges, pin, acked_at)][2:9]
                assert statistics.median(widths) == pytest.approx(pulse_us(deg[pin]), abs=2.0), f"pin {8 + pin}"
    finally:
        code = uno.stop()
    assert code == 0
