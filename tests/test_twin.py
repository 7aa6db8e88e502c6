"""The physics twin in the graph (nodes/twin, docs/twin.md): `twin` is a ROS node that serves
the servo link protocol behind a pseudo-terminal; `serial_node port:=twin` drives it as it
drives an Uno, and the twin publishes what its physics does: twin/joint_states (every
joint, passive ones included), the cube's tf frame, its camera. Judged by order and by the
messages' own stamps (simulated time on the wall clock's epoch), never by the host's
speed. The physics itself is checked on simulated time by `cargo test -p twin --features
mujoco` (in the test command)."""
import io
import math
import os
import signal
import time
from pathlib import Path

from geometry_msgs.msg import PointStamped
from PIL import Image
from sensor_msgs.msg import CameraInfo, CompressedImage, JointState

from conftest import TfListener, bin_path, latest_status, status_values
from safety_rig import SerialNodeRig
from test_serial_node import angles, start_at_link


def stamp_s(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def twin_status(diags):
    s = latest_status(diags, "twin")
    return status_values(s) if s else {}


class TwinRig(SerialNodeRig):
    """The twin (a node of the test's `launch`) and serial_node on `port:=twin`; rclpy reads
    the twin's topics."""

    def __init__(self, launch, observer, *twin_params):
        self.twin = launch("twin", "--ros-args", "-p", "camera_fps:=10", *twin_params)
        self.joints = observer.sub("/twin/joint_states", JointState)
        self.images = observer.sub("/twin/camera/image_raw/compressed", CompressedImage)
        self.infos = observer.sub("/twin/camera/camera_info", CameraInfo)
        super().__init__(launch, observer, "twin", 0.2)

    def connected(self):
        s = self.status()
        return s is not None and status_values(s).get("connection") == "connected"

    def joint(self, name, msg=None):
        m = msg or self.joints[-1][1]
        return m.position[list(m.name).index(name)]


def test_serial_node_port_twin_drives_the_physics(launch, observer, domain):
    rig = TwinRig(launch, observer)
    assert observer.spin_until(rig.connected, 30), "serial_node never connected to the twin"
    assert observer.spin_until(lambda: len(rig.joints) > 10, 10)
    # every movable URDF joint, as the physics has them
    names = set(rig.joints[-1][1].name)
    assert {"base_joint", "shoulder_joint", "elbow_joint", "crank_joint", "wrist_joint",
            "gripper_joint", "gripper_mimic_joint"} <= names, names
    # home: main arm up, forearm level (the arm was limp until serial_node's first
    # command, as an unpowered arm is, and drooped against its stops); the passive crank
    # follows the forearm servo (phi = horn - 90 deg)
    rig.angles.publish(angles([90, 90, 90, 60], sec=1))

    def at_home():
        return (abs(rig.joint("base_joint")) < math.radians(1) and abs(rig.joint("crank_joint")) < math.radians(2)
                and abs(rig.joint("shoulder_joint") - math.radians(90)) < math.radians(2))
    assert observer.spin_until(at_home, 10), \
        {n: round(math.degrees(p), 1) for n, p in zip(rig.joints[-1][1].name, rig.joints[-1][1].position)}
    # a 40 degree turn of the base servo: 20 degrees of the base, through the 2:1 gear
    n = len(rig.joints)
    rig.angles.publish(angles([50, 90, 90, 60], sec=2))
    assert observer.spin_until(lambda: abs(rig.joint("base_joint") - math.radians(20)) < math.radians(1), 10), \
        math.degrees(rig.joint("base_joint"))
    # the physics took time to get there: at the MG995's 300 deg/s the horn needs 0.13 s,
    # and the twin's own stamps show a motion through intermediate angles
    moving = [m for _, m in rig.joints[n:] if math.radians(2) < rig.joint("base_joint", m) < math.radians(18)]
    assert moving, "the base jumped: no state between the two poses"
    first = next(m for _, m in rig.joints[n:] if rig.joint("base_joint", m) > math.radians(1))
    done = next(m for _, m in rig.joints[n:] if abs(rig.joint("base_joint", m) - math.radians(20)) < math.radians(1))
    assert 0.08 < stamp_s(done.header.stamp) - stamp_s(first.header.stamp) < 1.0
    # the cube, as a tf frame of base_link, on its stand
    tf = TfListener(domain)
    try:
        assert observer.spin_until(lambda: "cube" in tf.transforms(), 10)
        cube = tf.transforms()["cube"]
        assert cube.header.frame_id == "base_link"
        t = cube.transform.translation
        assert abs(t.x - 0.2) < 0.01 and abs(t.y) < 0.01 and 0.05 < t.z < 0.08, (t.x, t.y, t.z)
    finally:
        tf.close()
    # the camera: JPEG 640 x 480, each image with its camera info
    assert observer.spin_until(lambda: rig.images and rig.infos, 20)
    img = rig.images[-1][1]
    assert img.format == "jpeg"
    assert Image.open(io.BytesIO(bytes(img.data))).size == (640, 480)
    info = rig.infos[-1][1]
    assert (info.width, info.height) == (640, 480) and info.k[0] > 0
    assert observer.spin_until(lambda: twin_status(rig.diags).get("camera_frames", "0") != "0", 10)
    v = twin_status(rig.diags)
    assert float(v["loop_error_mm"]) < 1.0, v


def start_twin(link, domain):
    return start_at_link([bin_path("twin"), "--ros-args", "-p", f"link:={link}", "-p", "camera_fps:=0"], link,
                         env=dict(os.environ, ROS_DOMAIN_ID=str(domain)), timeout=30)


def test_a_stopped_twin_is_a_lost_device(launch, observer, tmp_path, domain):
    """At a link of the user's choosing, the twin serves until stopped; its link goes with
    it, and serial_node reports the device lost, as for an unplugged cable."""
    link = tmp_path / "tty"
    twin = start_twin(link, domain)
    try:
        rig = SerialNodeRig(launch, observer, str(link), 0.2)
        assert observer.spin_until(lambda: status_values(rig.status()).get("connection") == "connected"
                                   if rig.status() else False, 30)
        rig.angles.publish(angles([70, 110, 80, 120], sec=35))
        assert observer.spin_until(lambda: any(m.header.stamp.sec == 35 for _, m in rig.state), 10)
        assert twin.poll() is None, "the twin stopped"
    finally:
        twin.send_signal(signal.SIGINT)
        assert twin.wait(10) == 0
    assert not os.path.exists(link)
    assert observer.spin_until(lambda: status_values(rig.status()).get("connection") == "disconnected", 15)


def test_run_graph_with_serial_port_twin(domain, observer):
    """`SERIAL_PORT=twin run_graph.sh -r __ns:=/arm3`: the twin starts beside the graph in
    its namespace, serial_node drives it, a target moves the twin's arm there, and Ctrl-C
    stops everything (no orphan) with exit code 0."""
    from launch_script import Script, graph_ends, left_alive, reap_scripts  # noqa: F401 (fixture)

    s = Script("run_graph.sh", "-r", "__ns:=/arm3", env={"ROS_DOMAIN_ID": str(domain), "SERIAL_PORT": "twin"})
    try:
        kids = s.children(5, timeout=40)
        joints = observer.sub("/arm3/twin/joint_states", JointState)
        xyz, state = graph_ends(observer, "/arm3/xyz_target", PointStamped, "/arm3/servo_state", JointState,
                                {"compute_ik", "state_publisher", "serial_node", "gui_bridge", "twin"})
        assert "physics twin" in s.output()
        target = PointStamped()
        target.header.frame_id = "base_link"
        target.point.x, target.point.y, target.point.z = 0.2, 0.1, 0.15

        def base():
            m = joints[-1][1] if joints else None
            return m.position[list(m.name).index("base_joint")] if m else None
        want = math.atan2(0.1, 0.2)
        end = time.monotonic() + 30
        while time.monotonic() < end and not (base() is not None and abs(base() - want) < math.radians(1)):
            xyz.publish(target)  # (repeated: the first may precede serial_node's handshake)
            observer.spin_until(lambda: base() is not None and abs(base() - want) < math.radians(1), 1)
        assert base() is not None and abs(base() - want) < math.radians(1), (base(), s.output())
    finally:
        code = s.stop()
    assert code == 0, s.output()
    assert not left_alive(kids), s.output()


def board_timeline(events_path):
    """From servo_sim's event file: the board's epoch (wall ns at power-up, from its first
    `w` line) and each servo pin's pulses [(end s, width us)] on the board's clock."""
    epoch, rise, pulses = None, {}, {p: [] for p in range(4)}
    for line in Path(events_path).read_text().splitlines():
        f = line.split()
        if len(f) >= 3 and f[0] == "w" and epoch is None:
            epoch = int(f[2]) - int(f[1]) * 1000 // 16
        elif len(f) == 4 and f[0] == "e":
            cycle, pin, level = int(f[1]), int(f[2]), int(f[3])
            if level:
                rise[pin] = cycle
            elif pin in rise:
                pulses[pin].append((cycle / 16e6, (cycle - rise.pop(pin)) / 16.0))
    return epoch, pulses


def test_the_firmware_in_simavr_drives_the_twin_by_its_pin_pulses(launch, observer, tmp_path):
    """The highest-fidelity chain: serial_node -> the real firmware's UART (servo_control in
    simavr) -> its PWM edges on pins 8-11 -> the twin's servos, in lock-step with the
    board's simulated clock (the twin's `pulse_events`). Judged on that clock: the twin's
    stamps and the board's pulses are both simulated time."""
    from interop.servo_link import SimulatedUno
    from safety_rig import FIRMWARE

    board = SimulatedUno(tmp_path, FIRMWARE)
    try:
        launch("twin", "--ros-args", "-p", f"pulse_events:={board.events_path}", "-p", "camera_fps:=0")
        joints = observer.sub("/twin/joint_states", JointState)
        rig = SerialNodeRig(launch, observer, str(board.tty_path), 0.2)
        assert observer.spin_until(lambda: status_values(rig.status()).get("connection") == "connected"
                                   if rig.status() else False, 30)

        def base():
            m = joints[-1][1]
            return m.position[list(m.name).index("base_joint")]
        # home, then the base servo from 90 to 50 degrees: 20 degrees of base_joint
        rig.angles.publish(angles([90, 90, 90, 60], sec=1))
        assert observer.spin_until(lambda: joints and abs(base()) < math.radians(1), 20)
        n = len(joints)
        rig.angles.publish(angles([50, 90, 90, 60], sec=2))
        assert observer.spin_until(lambda: abs(base() - math.radians(20)) < math.radians(0.7), 20), math.degrees(base())
    finally:
        board.proc.send_signal(signal.SIGINT)
        board.proc.wait(10)
    epoch, pulses = board_timeline(board.events_path)
    assert epoch is not None
    # the pin's last new width: where serial_node's ramp (300 deg/s) ended, on the board
    base_pulses = pulses[0]
    final = base_pulses[-1][1]
    assert abs(final - (544 + (2400 - 544) * 50 / 180)) < 2, final
    settled_pulse = next(t for t, w in base_pulses if abs(w - final) < 0.5)
    # the twin's base on the same clock: it reached the command after the pin did, and
    # within a servo's settling (a fraction of a second of simulated time)
    def sim_s(m):
        return (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec - epoch) / 1e9
    reached = next(sim_s(m) for _, m in joints[n:]
                   if abs(m.position[list(m.name).index("base_joint")] - math.radians(20)) < math.radians(0.7))
    assert settled_pulse - 0.2 < reached < settled_pulse + 0.3, (settled_pulse, reached)
    # and it moved through the pins' ramp: states between the two poses
    moving = [m for _, m in joints[n:] if math.radians(2) < m.position[list(m.name).index("base_joint")] < math.radians(18)]
    assert len(moving) >= 5


def test_a_miscalibrated_config_shows_in_the_twin_as_on_a_real_arm(launch, observer, tmp_path):
    """The twin is an arm assembled to the shipped calibration: a graph whose config says
    the base servo's centre is 95 degrees (5 off) commands 95 for a target straight ahead,
    and the twin's base turns to where 95 puts the real arm, 2.5 degrees right of ahead
    (the 2:1 gear), while compute_ik believes it at 0."""
    from test_leader_arm import SHIPPED
    config = tmp_path / "arm.yaml"
    text = SHIPPED.replace("base:     { offset_deg: 90.0,", "base:     { offset_deg: 95.0,")
    assert text != SHIPPED, "config/arm.yaml's base calibration line moved: update the test"
    config.write_text(text)
    link = tmp_path / "twin.tty"
    joints = observer.sub("/twin/joint_states", JointState)
    commanded = observer.sub("/joint_states", JointState)
    launch("twin", "--ros-args", "-p", f"link:={link}", "-p", "camera_fps:=0")
    launch("compute_ik", "--ros-args", "-p", f"arm_config:={config}")
    rig = SerialNodeRig(launch, observer, str(link), 0.2)
    assert observer.spin_until(lambda: status_values(rig.status()).get("connection") == "connected"
                               if rig.status() else False, 30)
    xyz = observer.pub("/xyz_target", PointStamped)
    observer.wait_matched(xyz)

    def base(msgs):
        m = msgs[-1][1] if msgs else None
        return m.position[list(m.name).index("base_joint")] if m else None
    target = PointStamped()
    target.header.frame_id = "base_link"
    target.point.x, target.point.y, target.point.z = 0.2, 0.0, 0.15
    want = math.radians(-2.5)
    end = time.monotonic() + 30
    while time.monotonic() < end and not (base(joints) is not None and abs(base(joints) - want) < math.radians(0.5)):
        xyz.publish(target)  # (again until answered: compute_ik may match us a moment late)
        observer.spin_until(lambda: base(joints) is not None and abs(base(joints) - want) < math.radians(0.5), 1)
    assert abs(base(joints) - want) < math.radians(0.5), math.degrees(base(joints))
    assert abs(base(commanded)) < 1e-6, "compute_ik commands straight ahead"


def test_a_trajectory_within_the_servo_speed_tracks_and_a_faster_one_lags(launch, observer, tmp_path):
    """Through the graph (arm_controller/joint_trajectory -> compute_ik -> serial_node ->
    the twin): the config's motion limits raised far above an MG995's (1500 deg/s), so
    that the graph lets a too-fast trajectory through, as it would to a real arm whose
    config overstates its servos. A sweep of the base at a sixth of the servo's speed is
    tracked by the twin within 3 degrees of what compute_ik commands at each stamp; one
    at twice its speed lags it by tens of degrees (the virtual Arduino would not: its
    servos are as fast as the config says)."""
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from conftest import COMMANDS
    from test_leader_arm import SHIPPED
    fast = SHIPPED.replace("base:     { max_velocity_deg_s: 300.0, max_acceleration_deg_s2: 1200.0 }",
                           "base:     { max_velocity_deg_s: 1500.0, max_acceleration_deg_s2: 60000.0 }")
    assert fast != SHIPPED, "config/arm.yaml's base motion line moved: update the test"
    config = tmp_path / "arm.yaml"
    config.write_text(fast)
    link = tmp_path / "twin.tty"
    twin = observer.sub("/twin/joint_states", JointState)
    commanded = observer.sub("/joint_states", JointState)
    launch("twin", "--ros-args", "-p", f"link:={link}", "-p", "camera_fps:=0")
    launch("compute_ik", "--ros-args", "-p", f"arm_config:={config}", "-p", "max_target_age:=0.0")
    rig = SerialNodeRig(launch, observer, str(link), 0.2, "-p", f"arm_config:={config}")
    assert observer.spin_until(lambda: status_values(rig.status()).get("connection") == "connected"
                               if rig.status() else False, 30)
    topic = observer.pub("arm_controller/joint_trajectory", JointTrajectory, COMMANDS)
    observer.wait_matched(topic)

    def joint(m, name="base_joint"):
        return m.position[list(m.name).index(name)]

    def stamp(m):
        return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9

    def sweep(to_base, seconds):
        """A base sweep to `to_base` (rad) in `seconds`; the largest lag (deg) of the twin
        behind compute_ik's commanded base over the sweep and 0.5 s after, judged at the
        twin's stamps (the command newest at each)."""
        n_cmd, n_twin = len(commanded), len(twin)
        point = JointTrajectoryPoint(positions=[to_base, math.radians(90), math.radians(-90)],
                                     time_from_start=Duration(sec=int(seconds), nanosec=int((seconds % 1) * 1e9)))
        topic.publish(JointTrajectory(joint_names=["base_joint", "shoulder_joint", "elbow_joint"], points=[point]))
        assert observer.spin_until(lambda: len(commanded) > n_cmd and abs(joint(commanded[-1][1]) - to_base) < 1e-6, 10)
        done = stamp(commanded[-1][1])
        assert observer.spin_until(lambda: len(twin) > n_twin and stamp(twin[-1][1]) > done + 0.5
                                   and abs(joint(twin[-1][1]) - to_base) < math.radians(1), 10)
        cmds = [(stamp(m), joint(m)) for _, m in commanded[n_cmd:]]
        lags = []
        for _, m in twin[n_twin:]:
            t = stamp(m)
            newest = [q for s, q in cmds if s <= t]
            if newest and t <= done + 0.5:
                lags.append(abs(math.degrees(joint(m) - newest[-1])))
        assert len(lags) > 10
        return max(lags)

    # home, at rest
    assert sweep(0.0, 1.0) < 90
    slow = sweep(math.radians(25), 1.0)      # 25 deg of the base in 1 s: 50 deg/s of the servo
    fast_lag = sweep(math.radians(-25), 0.1)  # 50 deg of the base in 0.1 s: 1000 deg/s of the servo
    print(f"twin behind compute_ik: {slow:.2f} deg at 50 deg/s of the servo, {fast_lag:.1f} deg at 1000 deg/s")
    assert slow < 3.0, slow
    assert fast_lag > 20.0, fast_lag


def test_a_scripted_pick_through_the_graph_lifts_the_cube_by_its_tf(launch, observer, domain, tmp_path):
    """One trial of the pick through the graph (tests/twin_pick.py): the claw closes on the
    cube and lifts it 5 cm, as the cube's tf frame shows (tests/soak/twin_pick.py runs
    seeded trials: BENCHMARKS.md)."""
    from twin_pick import PickGraph, expected_start_z, gripped
    g = PickGraph(launch, observer, domain, tmp_path / "twin.tty", (0.2, 0.01))
    try:
        assert abs(g.cube_z() - expected_start_z()) < 0.003, g.cube_z()
        rise = g.pick()
        assert gripped(rise), f"the cube rose {rise * 1e3:.1f} mm"
    finally:
        g.close()
