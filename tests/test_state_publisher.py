"""state_publisher as a real process: tf read by Cyclone DDS, the rest by rclpy."""
import math
import time
import subprocess
import xml.etree.ElementTree as ET

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from conftest import REPO, TfListener, bin_path, compose_chain

ARM_URDF = REPO / "urdf" / "eezybot.urdf"
TEST_URDF = REPO / "tests" / "data" / "test_robot.urdf"


def urdf_links(path):
    return {link.get("name") for link in ET.parse(path).getroot().findall("link")}


def target(x, y, z):
    """A target stamped now (compute_ik refuses old ones)."""
    m = PointStamped()
    m.header.frame_id = "base_link"
    t = time.time()
    m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
    m.point.x, m.point.y, m.point.z = x, y, z
    return m


def wait_tf(observer, tf, predicate, timeout=10):
    return observer.spin_until(lambda: (tf.poll(), predicate())[1], timeout)


def test_tool0_in_tf_is_the_target_and_every_link_is_connected(launch, observer, domain):
    tf = TfListener(domain)
    launch("state_publisher")
    launch("compute_ik")
    pub = observer.pub("/xyz_target", PointStamped)
    observer.wait_matched(pub)
    observer.wait_publisher("/tf")
    links = urdf_links(ARM_URDF)
    assert wait_tf(observer, tf, lambda: len(tf.static) > 0)
    for i, p in enumerate([(0.2, 0.05, 0.15), (0.15, -0.1, 0.2), (0.25, 0.0, 0.1)]):
        pub.publish(target(*p))

        def arrived():  # compute_ik streams the motion: wait until the arm is there
            try:
                return compose_chain(tf.transforms(), "base_link", "tool0")[0] == pytest.approx(p, abs=1e-9)
            except KeyError:
                return False
        assert wait_tf(observer, tf, arrived), f"tf never reached target {p}"
        transforms = tf.transforms()
        pos, rot = compose_chain(transforms, "base_link", "tool0")
        assert pos == pytest.approx(p, abs=1e-9)
        # tool0 stays level: its rotation is the base yaw only
        yaw = math.atan2(p[1], p[0])
        assert rot[0] == pytest.approx(0, abs=1e-9) and rot[1] == pytest.approx(0, abs=1e-9)
        assert abs(rot[2]) == pytest.approx(abs(math.sin(yaw / 2)), abs=1e-9)
    # every URDF link is in the tree and reaches base_link
    transforms = tf.transforms()
    assert set(transforms) | {"base_link"} == links
    for link in links - {"base_link"}:
        compose_chain(transforms, "base_link", link)


def test_late_subscriber_gets_description_and_static(launch, observer, domain):
    proc = launch("state_publisher")
    observer.spin_until(lambda: ("state_publisher", "/") in observer.node.get_node_names_and_namespaces(), 15)
    observer.spin_for(2.0)  # the node has published long before anyone listens
    description = observer.sub("/robot_description", String)  # the contract's QoS: latched
    assert observer.spin_until(lambda: description, 15), "no robot_description for a late subscriber"
    assert description[-1][1].data == ARM_URDF.read_text()
    tf = TfListener(domain)
    assert wait_tf(observer, tf, lambda: "tool0" in tf.static), "no tf_static for a late subscriber"
    assert tf.static["tool0"].header.frame_id == "front_plate"
    assert tf.static["tool0"].transform.translation.x == pytest.approx(0.0393, abs=1e-12)
    assert proc.proc.poll() is None


def test_any_urdf_with_frame_prefix_and_mimic(launch, observer, domain):
    tf = TfListener(domain)
    launch("state_publisher", "--ros-args", "-p", f"urdf:={TEST_URDF}", "-p", "frame_prefix:=r1/")
    pub = observer.pub("/joint_states", JointState)
    observer.wait_matched(pub)
    assert wait_tf(observer, tf, lambda: "r1/mount" in tf.static)
    assert tf.static["r1/mount"].header.frame_id == "r1/base"
    msg = JointState(name=["wheel_joint", "slider_joint", "finger_a_joint"], position=[7.0, 0.3, 0.4])
    msg.header.stamp.sec = 55
    pub.publish(msg)
    assert wait_tf(observer, tf, lambda: {"r1/wheel", "r1/carriage", "r1/finger_a", "r1/finger_b"} <= set(tf.dynamic))
    d = tf.dynamic
    assert d["r1/carriage"].transform.translation.z == pytest.approx(0.3)
    assert d["r1/wheel"].transform.rotation.x == pytest.approx(math.sin(3.5))
    assert d["r1/finger_b"].transform.rotation.z == pytest.approx(math.sin(-0.35))  # -2 * 0.4 + 0.1
    assert all(t.header.stamp.sec == 55 for t in d.values())
    # the carriage's finger in the base frame: mount yaw pi/2, slider up 0.3
    pos, _ = compose_chain(tf.transforms(), "r1/base", "r1/finger_a")
    assert pos == pytest.approx((-0.05, 0.0, 0.4), abs=1e-12)


def test_bad_joint_states_are_skipped_with_diagnostics(launch, observer, domain):
    tf = TfListener(domain)
    proc = launch("state_publisher", "--ros-args", "-p", f"urdf:={TEST_URDF}", "-p", "diagnostics_period:=0.2")
    diags = observer.sub("/diagnostics", DiagnosticArray)
    pub = observer.pub("/joint_states", JointState)
    observer.wait_matched(pub)
    observer.wait_publisher("/diagnostics")
    pub.publish(JointState(name=["nope", "slider_joint", "wheel_joint"], position=[1.0, math.nan, 2.0]))
    assert wait_tf(observer, tf, lambda: "wheel" in tf.dynamic)
    assert "carriage" not in tf.dynamic and "nope" not in tf.dynamic

    def last():
        s = diags[-1][1].status[0]
        return s, {kv.key: kv.value for kv in s.values}

    assert observer.spin_until(lambda: diags and "nope" in last()[1].get("last_skipped", ""), 10)
    status, values = last()
    assert status.level == b"\x01"
    assert "joint `slider_joint` position is nan" in values["last_skipped"].lower()
    assert set(values["missing_joints"].split()) == {"slider_joint", "finger_a_joint"}
    assert proc.proc.poll() is None, "bad input must not stop the node"
    out = proc.output()
    assert "unknown joint `nope`" in out and "slider_joint" in out


@pytest.mark.parametrize("content,message", [
    (None, "cannot read"),
    ("<robot name='x'><link name='a'/><link name='a'/></robot>", "defined twice"),
    ("<robot name='x'><link name='a'>", "not a valid URDF"),
    pytest.param("<robot name='x'><link name='a'>" + "<visual>" * 10_000 + "</visual>" * 10_000 + "</link></robot>",
                 "nested 10002 deep, more than the 64", id="nested-10000-deep"),
])
def test_bad_urdf_exits_nonzero_naming_file_and_problem(tmp_path, domain, content, message):
    import os
    path = tmp_path / "bad.urdf"
    if content is not None:
        path.write_text(content)
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    r = subprocess.run([bin_path("state_publisher"), "--ros-args", "-p", f"urdf:={path}"], capture_output=True, text=True, env=env, timeout=20)
    assert r.returncode != 0
    assert str(path) in r.stderr and message in r.stderr, r.stderr


def test_a_deeply_nested_urdf_parameter_is_refused_and_the_model_kept(launch, observer, domain, tmp_path):
    """urdf-rs recursed once per element: a URDF nested 10 000 deep overflowed the stack
    (SIGABRT). Now refused before parsing, in the reply, a log line and diagnostics."""
    tf = TfListener(domain)
    proc = launch("state_publisher", "--ros-args", "-p", f"urdf:={TEST_URDF}", "-p", "diagnostics_period:=0.2")
    diags = observer.sub("/diagnostics", DiagnosticArray)
    observer.wait_publisher("/diagnostics")
    deep = tmp_path / "deep.urdf"
    deep.write_text("<robot name='deep'><link name='a'>" + "<visual>" * 10_000 + "</visual>" * 10_000 + "</link></robot>")
    cli = observer.node.create_client(SetParameters, "/state_publisher/set_parameters")
    assert cli.wait_for_service(timeout_sec=15)
    value = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=str(deep))
    fut = cli.call_async(SetParameters.Request(parameters=[Parameter(name="urdf", value=value)]))
    assert observer.spin_until(fut.done, 10)
    result = fut.result().results[0]
    assert not result.successful and "nested 10002 deep, more than the 64" in result.reason, result

    def refusal():
        values = {kv.key: kv.value for kv in diags[-1][1].status[0].values} if diags else {}
        return values.get("last_parameter_refusal", "")

    assert observer.spin_until(lambda: refusal().startswith("urdf: "), 5)
    assert observer.spin_until(lambda: "parameter urdf refused" in proc.output(), 5)
    # the model in use is still the test robot's
    pub = observer.pub("/joint_states", JointState)
    observer.wait_matched(pub)
    pub.publish(JointState(name=["wheel_joint"], position=[1.0]))
    assert wait_tf(observer, tf, lambda: "wheel" in tf.dynamic)
    assert proc.proc.poll() is None


def test_arm_is_in_tf_before_any_target(launch, observer, domain):
    """compute_ik sends its current pose to a joint_states subscriber that joins, so a
    viewer shows the whole arm at once (home: tool0 at L3 + tool_dx forward, H + L2 up)."""
    tf = TfListener(domain)
    launch("compute_ik")
    launch("state_publisher")
    observer.wait_publisher("/tf")
    assert wait_tf(observer, tf, lambda: "main_arm" in tf.dynamic and "tool0" in tf.static, 15)
    pos, _ = compose_chain(tf.transforms(), "base_link", "tool0")
    assert pos == pytest.approx((0.147 + 0.0393, 0.0, 0.094 + 0.135), abs=1e-9)
