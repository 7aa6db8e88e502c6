"""A second robot: the 6-DOF Kinova Jaco 2 (urdf/jaco.urdf) driven by the same compute_ik
(numerical IK on its URDF chain, position and pose targets, no servo mapping), shown by
state_publisher (tf for every link), and started by `run_graph.sh --arm jaco`. Poses are
checked against the seed report's Table 4.1 DH parameters, written out again here so the
test does not trust the URDF or the code under test."""
import math
import signal
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from conftest import REPO, TfListener, compose_chain, latest_status, status_values
from launch_script import Script, graph_ends, left_alive, reap_scripts  # noqa: F401 (fixture)

JACO_URDF = REPO / "urdf" / "jaco.urdf"
TIP = "jaco_end_effector"
JOINTS = [f"jaco_joint_{i}" for i in range(1, 7)]
LINKS = {"base_link", TIP, *(f"jaco_link_{i}" for i in range(1, 7))}
# Table 4.1 (classical DH): alpha_i, a_i (m), d_i (m)
DH = [(math.pi / 2, 0.0, 0.2755), (math.pi, 0.410, 0.0), (math.pi / 2, 0.0, -0.0098),
      (math.pi / 3, 0.0, -0.25008), (math.pi / 3, 0.0, -0.085563), (math.pi, 0.0, -0.20278)]
VELOCITY = [math.radians(36)] * 3 + [math.radians(48)] * 3  # Kinova's joint speeds


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def dh_fk(q):
    """Tip pose (4x4) of the DH chain: A_i = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)."""
    t = [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]
    for qi, (alpha, a, d) in zip(q, DH):
        ct, st, ca, sa = math.cos(qi), math.sin(qi), math.cos(alpha), math.sin(alpha)
        t = matmul(t, [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1]])
    return t


def quaternion(m):
    """(x, y, z, w) of a rotation matrix."""
    tr = m[0][0] + m[1][1] + m[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return ((m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, 0.25 * s)
    i = max(range(3), key=lambda k: m[k][k])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + m[i][i] - m[j][j] - m[k][k]) * 2
    q = [0.0, 0.0, 0.0, 0.0]
    q[i] = 0.25 * s
    q[j] = (m[j][i] + m[i][j]) / s
    q[k] = (m[k][i] + m[i][k]) / s
    q[3] = (m[k][j] - m[j][k]) / s
    return tuple(q)


def angle_between(q1, q2):
    dot = abs(sum(a * b for a, b in zip(q1, q2)))
    return 2 * math.acos(min(1.0, dot))


def now_stamp():
    t = time.time()
    return int(t), int((t % 1) * 1e9)


def pose_msg(m):
    msg = PoseStamped()
    msg.header.frame_id = "base_link"
    msg.header.stamp.sec, msg.header.stamp.nanosec = now_stamp()
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = m[0][3], m[1][3], m[2][3]
    (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z, msg.pose.orientation.w) = quaternion(m)
    return msg


def point_msg(p):
    msg = PointStamped()
    msg.header.frame_id = "base_link"
    msg.header.stamp.sec, msg.header.stamp.nanosec = now_stamp()
    msg.point.x, msg.point.y, msg.point.z = p
    return msg


def joints_msg(q):
    return JointState(name=list(JOINTS), position=[float(v) for v in q])


class JacoRig:
    def __init__(self, launch, observer, domain, *args):
        self.tf = TfListener(domain)
        self.o = observer
        self.ik = launch("compute_ik", "--ros-args", "-p", f"urdf:={JACO_URDF}", "-p", f"tip_link:={TIP}",
                         "-p", "diagnostics_period:=0.25", *args)
        launch("state_publisher", "--ros-args", "-p", f"urdf:={JACO_URDF}")
        # every step kept (the contract's depth of 10 loses steps when a starved host
        # holds up the observer's spin for 200 ms: the speed check needs them all)
        self.joint_states = observer.sub("/joint_states", JointState,
                                         QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        self.diagnostics = observer.sub("/diagnostics", DiagnosticArray)
        self.pose = observer.pub("/pose_target", PoseStamped)
        self.xyz = observer.pub("/xyz_target", PointStamped)
        self.joints = observer.pub("/joint_target", JointState)
        self.gripper = observer.pub("/gripper_target", Float64)
        for p in (self.pose, self.xyz, self.joints, self.gripper):
            observer.wait_matched(p)
        observer.wait_publisher("/joint_states")
        observer.wait_publisher("/tf")

    def values(self):
        return status_values(latest_status(self.diagnostics, "compute_ik"))

    def tip(self):
        return compose_chain(self.tf.transforms(), "base_link", TIP)

    def wait_tip(self, pos, rot=None, timeout=20):
        def there():
            self.tf.poll()
            try:
                p, r = self.tip()
            except KeyError:
                return False
            return math.dist(p, pos) < 1e-6 and (rot is None or angle_between(r, rot) < 1e-6)
        return self.o.spin_until(there, timeout)

    def wait_rest(self, timeout=20):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            n = len(self.joint_states)
            self.o.spin_for(0.25)
            if len(self.joint_states) == n:
                return
        raise AssertionError("the Jaco did not come to rest")


def test_compute_ik_and_state_publisher_drive_the_jaco_to_poses_and_positions(launch, observer, domain):
    rig = JacoRig(launch, observer, domain)
    # every link of the URDF in tf, from compute_ik's first joint_states
    assert observer.spin_until(lambda: (rig.tf.poll(), LINKS - {"base_link"} <= set(rig.tf.transforms()))[1], 15), rig.tf.transforms().keys()
    for link in LINKS - {"base_link"}:
        compose_chain(rig.tf.transforms(), "base_link", link)
    assert rig.joint_states and rig.joint_states[-1][1].name == JOINTS
    # no servo mapping: nobody publishes servo_angles
    assert observer.node.count_publishers("/servo_angles") == 0
    # two poses from the DH table: tf's tip follows, position and orientation
    n0 = len(rig.joint_states)
    for q in ([0.3, 0.4, -0.5, 0.4, 0.6, -0.3], [0.5, 0.6, -0.3, 0.2, 0.9, -0.1]):
        goal = dh_fk(q)
        rig.pose.publish(pose_msg(goal))
        assert rig.wait_tip([goal[i][3] for i in range(3)], quaternion(goal)), (q, rig.tip(), rig.values())
    rig.wait_rest()
    # the solve is reported in the diagnostics after it (the bound only ends a failure)
    assert observer.spin_until(lambda: rig.values().get("last_solve", "").startswith("dls: converged"), 10), \
        rig.values()
    # the motion stays within the URDF's joint speeds (50 Hz steps)
    steps = [m for _, m in rig.joint_states[n0:]]
    assert len(steps) > 20
    for a, b in zip(steps, steps[1:]):
        for i, (u, v) in enumerate(zip(a.position, b.position)):
            assert abs(v - u) <= VELOCITY[i] * 0.02 + 1e-9, (i, u, v)
    # a position: reached, the tool's orientation kept
    p, r = rig.tip()
    target = (p[0] + 0.03, p[1] - 0.02, p[2] + 0.04)
    rig.xyz.publish(point_msg(target))
    assert rig.wait_tip(target, r), (rig.tip(), rig.values())
    # what the Jaco cannot do is refused with the reason
    rejected = int(rig.values()["rejected"])
    rig.gripper.publish(Float64(data=0.5))
    assert observer.spin_until(lambda: int(rig.values().get("rejected", 0)) > rejected, 10)
    assert rig.values()["last_rejection_code"] == "no_gripper"
    rig.xyz.publish(point_msg((3.0, 0.0, 0.5)))
    assert observer.spin_until(lambda: rig.values().get("last_rejection_code") == "ik_not_converged", 10)
    assert "not reached: the closest the dls solver got" in rig.values()["last_rejection"]


def test_jaco_undesirable_configurations_in_diagnostics(launch, observer, domain):
    """The seed report's upright start pose is singular (joints 2 and 3 aligned) and has
    the gripper facing up: both reported, each with a way out."""
    rig = JacoRig(launch, observer, domain)
    upright = [math.pi, math.pi / 2, -math.pi / 2, 0.0, -math.pi, math.pi]
    rig.joints.publish(joints_msg(upright))
    tip = dh_fk(upright)
    assert rig.wait_tip([tip[i][3] for i in range(3)], quaternion(tip), 30), rig.values()
    assert tip[2][3] == pytest.approx(1.1811, abs=1e-4)  # the report's upright tip height
    assert observer.spin_until(lambda: "gripper_up" in rig.values().get("undesirable", ""), 10), rig.values()
    v = rig.values()
    assert "near_singular" in v["undesirable"], v
    assert "away: jaco_joint_" in v["undesirable:near_singular"], v
    assert v["undesirable:gripper_up"].startswith("the gripper faces upwards"), v
    # move along the suggested direction: no longer singular
    away = dict(part.rsplit(" ", 1) for part in v["undesirable:near_singular"].split("away: ")[1].split(", tool")[0].split(", "))
    moved = [q + 0.2 * float(away.get(n, 0.0)) for q, n in zip(upright, JOINTS)]
    rig.joints.publish(joints_msg(moved))
    rig.o.spin_for(0.5)
    rig.wait_rest(30)
    assert observer.spin_until(lambda: "near_singular" not in rig.values().get("undesirable", "near_singular"), 10), rig.values()


def test_run_graph_arm_jaco_starts_the_jaco_graph(domain, observer):
    s = Script("run_graph.sh", "--arm", "jaco", env={"ROS_DOMAIN_ID": str(domain)})
    try:
        kids = s.children(3)
        pose, states = graph_ends(observer, "/pose_target", PoseStamped, "/joint_states", JointState,
                                  {"compute_ik", "state_publisher", "gui_bridge"})
        assert "serial_node" not in observer.node.get_node_names()
        # published again every half second until answered: compute_ik's reader may learn
        # of our writer a moment after ours matched another node's (gui_bridge's), and a
        # target sent before is lost to it
        sent = set()

        def answered():
            return any((m.header.stamp.sec, m.header.stamp.nanosec) in sent for _, m in states)
        end = time.monotonic() + 20
        while time.monotonic() < end and not answered():
            msg = pose_msg(dh_fk([0.2, 0.3, -0.3, 0.1, 0.4, 0.0]))
            sent.add((msg.header.stamp.sec, msg.header.stamp.nanosec))
            pose.publish(msg)
            observer.spin_until(answered, 0.5)
        assert answered()
        assert states[-1][1].name == JOINTS
        out = s.output()
        assert "Kinova Jaco 2" in out and str(JACO_URDF) in out
    finally:
        code = s.stop(signal.SIGINT)
    assert code == 0, s.output()
    orphans = left_alive(kids)
    assert not orphans, f"orphans left: {orphans}"
    bad = Script("run_graph.sh", "--arm", "ur5", env={"ROS_DOMAIN_ID": str(domain)})
    assert bad.proc.wait(20) == 2
    assert "unknown arm `ur5`" in bad.output()
    bad.log.close()
