"""compute_ik as a real process, driven and observed by real rclpy (Fast DDS)."""
import math
import signal
import subprocess
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseStamped
from rcl_interfaces.msg import Log, Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64

from conftest import ROSOUT, Observer, bin_path, qos

# in a process of its own, beside the other modules (conftest: `background`): judged by
# the steps compute_ik publishes, their stamps and sentinels, not by time
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=70)]

# ROBOT.md, written out again here so the test does not trust the code under test.
H, L2, L3, TOOL_DX = 0.094, 0.135, 0.147, 0.0393
GRIPPER_OPEN_RAD = 0.6
SERVOS = ["base_servo", "shoulder_servo", "elbow_servo", "gripper_servo"]
PASSIVE = ["wrist_joint", "crank_joint", "drive_link_joint", "level_link_joint", "triangle_joint", "upper_link_joint"]


def fk(base, shoulder, elbow):
    phi = shoulder + elbow
    r = L2 * math.cos(shoulder) + L3 * math.cos(phi) + TOOL_DX
    return (r * math.cos(base), r * math.sin(base), H + L2 * math.sin(shoulder) + L3 * math.sin(phi))


def servo_deg(base, shoulder, elbow, opening):
    d = math.degrees
    return [90 - 2 * d(base), 180 - d(shoulder), 90 + d(shoulder + elbow), 60 + 120 * opening]


def now_stamp(offset=0.0):
    """(sec, nanosec) of the wall clock (compute_ik refuses targets older than
    max_target_age, 0.5 s by default)."""
    t = time.time() + offset
    return int(t), int((t % 1) * 1e9)


def target(x, y, z, frame="base_link", sec=None, nanosec=0):
    """A target stamped now (or at sec/nanosec)."""
    m = PointStamped()
    m.header.frame_id = frame
    if sec is None:
        sec, nanosec = now_stamp()
    m.header.stamp.sec, m.header.stamp.nanosec = sec, nanosec
    m.point.x, m.point.y, m.point.z = float(x), float(y), float(z)
    return m


def deep(topic):
    """The contract's QoS of `topic` with a history deep enough to keep every step."""
    profile = qos(topic)
    profile.depth = 10_000
    return profile


def joint_target(names, positions):
    return JointState(name=list(names), position=[float(p) for p in positions])


class IkRig:
    """compute_ik plus an observer wired to all its topics under namespace `ns`."""

    def __init__(self, launch, observer, *args, ns=""):
        self.proc = launch("compute_ik", *args)
        self.sentinels = 0  # settle's sentinels published (each an input the node counts)
        self.o = observer
        # every step kept until taken (the contract's depth of 10 is 0.2 s of steps: a
        # busy host's rclpy spin can fall further behind, and a lost step reads as a jump)
        self.joint_states = observer.sub(f"{ns}/joint_states", JointState, deep(f"{ns}/joint_states"))
        self.servo_angles = observer.sub(f"{ns}/servo_angles", JointState, deep(f"{ns}/servo_angles"))
        self.diagnostics = observer.sub(f"{ns}/diagnostics", DiagnosticArray)
        self.xyz = observer.pub(f"{ns}/xyz_target", PointStamped)
        self.gripper = observer.pub(f"{ns}/gripper_target", Float64)
        self.joints = observer.pub(f"{ns}/joint_target", JointState)
        self.estop = observer.pub(f"{ns}/estop", Bool)  # the contract's QoS: latched
        for p in (self.xyz, self.gripper, self.joints, self.estop):
            observer.wait_matched(p)
        for topic in ("joint_states", "servo_angles", "diagnostics"):
            observer.wait_publisher(f"{ns}/{topic}")

    def send_and_wait(self, publisher, msg, stamp=None, timeout=30, arrived=None):
        """Publish, wait for the first servo_angles and joint_states it causes (which
        carry its stamp), then for the end of the planned motion, judged by content and
        order: the step that puts the arm where the message asks (`arrived(joints)`, by
        default from the message itself: its IK is known in advance), then a sentinel's
        step (see `settle`). Returns the motion's last joint_states and servo_angles."""
        arrived = arrived or goal_of(msg)
        n_sa = len(self.servo_angles)
        publisher.publish(msg)
        ok = self.o.spin_until(lambda: len(self.servo_angles) > n_sa and self.step_js(self.servo_angles[n_sa][1]), timeout)
        assert ok, "no servo_angles/joint_states for a valid input"
        sa = self.servo_angles[n_sa][1]
        js = self.step_js(sa)
        if stamp is not None:
            assert stamp_of(sa) == stamp
            assert stamp_of(js) == stamp
        self.wait_arrived(n_sa, arrived, timeout)
        return self.settle(n_sa, timeout)

    def step_js(self, sa):
        """The joint_states of the step whose servo_angles is `sa` (the same stamp;
        compute_ik also greets a new joint_states reader with the pose, so joint_states
        are not counted)."""
        js = [m for _, m in self.joint_states if stamp_of(m) == stamp_of(sa)]
        return js[-1] if js else None

    def wait_arrived(self, n_sa, arrived, timeout=30):
        """Until a step since n_sa has its joint_states here and `arrived` holds for its
        joints: the motion has reached its end."""
        def done():
            if len(self.servo_angles) == n_sa:
                return False
            js = self.step_js(self.servo_angles[-1][1])
            return js is not None and arrived(joints_of(js))
        if not self.o.spin_until(done, timeout):
            last = joints_of(self.joint_states[-1][1]) if self.joint_states else None
            raise AssertionError(f"the planned motion did not end where it was sent; last joint_states {last}")

    def settle(self, n_sa, timeout=30):
        """The planner lands on the goal, then may publish that step once more (the
        velocity comes to 0 a step after the position arrives): a sentinel, a joint
        target of the base where it is (the arm stays where it is), stamped, is
        published, and every step before its own is the motion's. Returns the motion's
        last joint_states and servo_angles."""
        here = joints_of(self.step_js(self.servo_angles[-1][1]))
        sent = set()

        def sentinel_seen():
            # a fresh sentinel every 2 s until one's step is here: on a busy host one may
            # arrive later than max_target_age and be refused as too old
            if not sent or now_stamp()[0] - max(sent)[0] >= 2:
                sentinel = joint_target(["base_joint"], [here["base_joint"]])
                sentinel.header.stamp.sec, sentinel.header.stamp.nanosec = now_stamp()
                sent.add(stamp_of(sentinel))
                self.joints.publish(sentinel)
            return any(stamp_of(m) in sent for _, m in self.servo_angles[n_sa:]) \
                and self.step_js(self.servo_angles[-1][1]) is not None
        assert self.o.spin_until(sentinel_seen, timeout), "no step for the sentinel"
        self.sentinels += len(sent)
        stamps = [stamp_of(m) for _, m in self.servo_angles[n_sa:]]
        i = n_sa + next(k for k, st in enumerate(stamps) if st in sent)
        assert all(st in sent for st in stamps[i - n_sa:]), "steps after the sentinel's: the motion went on"
        last, sentinel_step = self.servo_angles[i - 1][1], self.servo_angles[i][1]
        assert list(sentinel_step.position) == pytest.approx(list(last.position), abs=1e-12), "the sentinel moved the arm"
        return self.step_js(last), last

    def first_step_after(self, n_sa, publisher, sentinel, timeout=30):
        """Publish `sentinel` (a valid target with a stamp of its own that leaves the arm
        where it is) and wait for its step: the first servo_angles after the first n_sa
        must be it, so whatever came before the sentinel caused none."""
        publisher.publish(sentinel)
        want = stamp_of(sentinel)
        assert self.o.spin_until(lambda: any(stamp_of(m) == want for _, m in self.servo_angles[n_sa:]), timeout), \
            "no servo_angles for the sentinel target"
        first = self.servo_angles[n_sa][1]
        assert stamp_of(first) == want, f"servo_angles stamped {stamp_of(first)} before the sentinel's {want}"

    def last_diag(self):
        status = self.diagnostics[-1][1].status[0]
        return status, {kv.key: kv.value for kv in status.values}

    def rejected_count(self):
        if not self.diagnostics:
            return 0
        return int(self.last_diag()[1]["rejected"])


def joints_of(js):
    return dict(zip(js.name, js.position))


def stamp_of(m):
    return (m.header.stamp.sec, m.header.stamp.nanosec)


ARM = ("base_joint", "shoulder_joint", "elbow_joint")


def goal_of(msg):
    """What a target's last step holds, known in advance: the tool at the asked point
    (whatever solver got it there, within the 1e-9 m the tests assert), the claw at the
    asked opening, the asked joints at their values."""
    if isinstance(msg, (PointStamped, PoseStamped)):
        p = msg.point if isinstance(msg, PointStamped) else msg.pose.position
        return lambda q: math.dist(fk(*[q[j] for j in ARM]), (p.x, p.y, p.z)) <= 1e-9
    if isinstance(msg, Float64):
        return lambda q: abs(q["gripper_joint"] - msg.data * GRIPPER_OPEN_RAD) <= 1e-12
    if isinstance(msg, JointState):
        return lambda q: all(abs(q[n] - v) <= 1e-12 for n, v in zip(msg.name, msg.position))
    raise TypeError(msg)


def check_state(js, sa, opening):
    q = joints_of(js)
    base, shoulder, elbow = q["base_joint"], q["shoulder_joint"], q["elbow_joint"]
    phi = shoulder + elbow
    # every passive joint, derived from ROBOT.md's parallelograms
    expected_passive = {
        "wrist_joint": -phi, "crank_joint": phi, "drive_link_joint": shoulder - phi,
        "level_link_joint": shoulder, "triangle_joint": -shoulder, "upper_link_joint": phi,
    }
    for name, value in expected_passive.items():
        assert q[name] == pytest.approx(value, abs=1e-12), name
    assert q["gripper_joint"] == pytest.approx(opening * GRIPPER_OPEN_RAD, abs=1e-12)
    assert q["gripper_mimic_joint"] == pytest.approx(-opening * GRIPPER_OPEN_RAD, abs=1e-12)
    assert sa.name == SERVOS
    got_deg = [math.degrees(r) for r in sa.position]
    assert got_deg == pytest.approx(servo_deg(base, shoulder, elbow, opening), abs=1e-9)
    return base, shoulder, elbow


def test_targets_in_joint_states_and_servo_angles_out(launch, observer):
    rig = IkRig(launch, observer)
    for i, p in enumerate([(0.2, 0.05, 0.15), (0.15, -0.1, 0.2), (0.25, 0.0, 0.1), (0.19, 0.0, 0.08)]):
        stamp = now_stamp()
        js, sa = rig.send_and_wait(rig.xyz, target(*p, sec=stamp[0], nanosec=stamp[1]), stamp)
        assert set(js.name) == {"base_joint", "shoulder_joint", "elbow_joint", "gripper_joint", *PASSIVE, "gripper_mimic_joint"}
        base, shoulder, elbow = check_state(js, sa, 0.0)
        assert fk(base, shoulder, elbow) == pytest.approx(p, abs=1e-9)
        assert elbow <= 0
    # the claw alone: the arm stays where it is
    arm_before = [joints_of(js)[j] for j in ("base_joint", "shoulder_joint", "elbow_joint")]
    js, sa = rig.send_and_wait(rig.gripper, Float64(data=0.5))
    check_state(js, sa, 0.5)
    assert [joints_of(js)[j] for j in ("base_joint", "shoulder_joint", "elbow_joint")] == arm_before
    assert math.degrees(sa.position[3]) == pytest.approx(120.0)
    # joint mode, an empty frame meaning base_link
    js, sa = rig.send_and_wait(rig.joints, joint_target(["base_joint", "shoulder_joint", "elbow_joint"], [0.1, 1.4, -1.7]))
    assert [joints_of(js)[j] for j in ("base_joint", "shoulder_joint", "elbow_joint")] == [0.1, 1.4, -1.7]
    check_state(js, sa, 0.5)
    js, sa = rig.send_and_wait(rig.xyz, target(0.2, 0.0, 0.15, frame=""))
    assert fk(*[joints_of(js)[j] for j in ("base_joint", "shoulder_joint", "elbow_joint")]) == pytest.approx((0.2, 0, 0.15), abs=1e-9)


# (topic, message, last_rejection_code, text in last_rejection, reason_code: the stable
# code other nodes read through ros_plumbing::feedback)
BAD_INPUTS = [
    ("xyz", target(1.0, 0.0, 0.1), "too_far", "out of reach", "unreachable"),
    ("xyz", target(0.10, 0.0, 0.15), "out_of_limits:elbow_joint", "elbow_joint", "out_of_limits"),
    ("xyz", target(-0.2, 0.0, 0.15), "out_of_limits:base_joint", "base_joint", "out_of_limits"),
    ("xyz", target(0.26, 0.0, 0.1), "out_of_limits:shoulder_joint", "shoulder_joint", "out_of_limits"),
    ("xyz", target(math.nan, 0.0, 0.15), "non_finite_target", "NaN", "not_finite"),
    ("xyz", target(0.2, math.inf, 0.15), "non_finite_target", "inf", "not_finite"),
    ("xyz", target(0.2, 0.0, 0.15, frame="map"), "wrong_frame", "`map`", "wrong_frame"),
    ("gripper", Float64(data=1.5), "gripper_out_of_range", "1.5", "out_of_limits"),
    ("gripper", Float64(data=math.nan), "gripper_out_of_range", "NaN", "out_of_limits"),
    ("joints", joint_target(["wrist_joint"], [0.0]), "unknown_joint", "wrist_joint", "bad_joints"),
    ("joints", joint_target(["shoulder_joint"], [2.5]), "out_of_limits:shoulder_joint", "shoulder_joint", "out_of_limits"),
    ("joints", joint_target(["elbow_joint"], [math.nan]), "non_finite_joint:elbow_joint", "NaN", "not_finite"),
    ("joints", JointState(name=["base_joint", "elbow_joint"], position=[0.1]), "length_mismatch", "2 names but 1 positions", "bad_joints"),
    ("joints", joint_target(["gripper_joint"], [1.0]), "out_of_limits:gripper_joint", "gripper_joint", "out_of_limits"),
]


def test_bad_inputs_give_a_reason_and_no_servo_angles(launch, observer):
    rig = IkRig(launch, observer)
    good = (0.2, 0.05, 0.15)
    js, _ = rig.send_and_wait(rig.xyz, target(*good))
    kept = joints_of(js)
    publishers = {"xyz": rig.xyz, "gripper": rig.gripper, "joints": rig.joints}
    for i, (topic, msg, code, text, reason) in enumerate(BAD_INPUTS, start=1):
        n_sa = len(rig.servo_angles)
        if hasattr(msg, "header"):
            msg.header.stamp.sec, msg.header.stamp.nanosec = now_stamp()  # not refused as old
        publishers[topic].publish(msg)
        assert observer.spin_until(lambda: rig.rejected_count() >= i, 10), f"no diagnostics for {code}"
        status, values = rig.last_diag()
        assert values["last_rejection_code"] == code
        assert values["reason_code"] == reason, (code, values["reason_code"])
        assert text in values["last_rejection"], values["last_rejection"]
        assert status.level == b"\x01"  # WARN
        # no servo_angles for it: the first one after it is the sentinel's, a target
        # where the arm already is
        rig.first_step_after(n_sa, rig.xyz, target(*good))
    # the last good state was kept: a claw-only change shows the same arm joints
    js, _ = rig.send_and_wait(rig.gripper, Float64(data=0.25))
    for j in ("base_joint", "shoulder_joint", "elbow_joint"):
        assert joints_of(js)[j] == kept[j]
    # back to OK once an input is accepted
    assert observer.spin_until(lambda: rig.last_diag()[0].level == b"\x00", 5)
    # a log line for every kind of rejection (repeats of one kind within 5 s are counted
    # in diagnostics, not logged again)
    log = rig.proc.output()
    first_of_kind = {}
    for topic, _, code, text, _ in BAD_INPUTS:
        first_of_kind.setdefault((topic, code), text)
    lines = [line for line in log.splitlines() if "rejected:" in line]
    assert len(lines) == len(first_of_kind), lines
    for (topic, code), text in first_of_kind.items():
        assert any(text in line for line in lines), f"{code} not logged"


def test_diagnostics_keep_coming_and_go_to_rosout_too(launch, observer):
    rosout = observer.sub("/rosout", Log, ROSOUT)
    rig = IkRig(launch, observer)
    n0 = len(rig.diagnostics)
    # with no input at all (about once a second: the bound only ends a failure)
    assert observer.spin_until(lambda: len(rig.diagnostics) - n0 >= 3, 15), "diagnostics stopped coming"
    stamps = [stamp_of(m) for _, m in rig.diagnostics[n0:]]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps), stamps
    status, values = rig.last_diag()
    assert status.name == "compute_ik: inverse kinematics"
    assert status.level == b"\x00"
    rig.xyz.publish(target(2.0, 0.0, 0.0))
    assert observer.spin_until(lambda: any("rejected" in m.msg and m.name == "compute_ik" for _, m in rosout), 10)


def test_estop_blocks_targets_until_released(launch, observer):
    rig = IkRig(launch, observer)
    rig.estop.publish(Bool(data=True))
    assert observer.spin_until(lambda: rig.diagnostics and rig.last_diag()[1].get("estop") == "true", 10)
    n_sa = len(rig.servo_angles)
    rig.xyz.publish(target(0.2, 0.0, 0.15))
    assert observer.spin_until(lambda: rig.last_diag()[1].get("last_rejection_code") == "estop", 10)
    assert rig.last_diag()[1]["reason_code"] == "estop"
    rig.estop.publish(Bool(data=False))
    assert observer.spin_until(lambda: rig.last_diag()[1].get("estop") == "false", 10)
    # the refused target moved nothing: the first step after it is the next target's
    sentinel = target(0.2, 0.0, 0.15)
    rig.first_step_after(n_sa, rig.xyz, sentinel)
    rig.wait_arrived(n_sa, goal_of(sentinel))


def test_namespace_moves_every_topic(launch, observer):
    root_angles = observer.sub("/servo_angles", JointState)
    rig = IkRig(launch, observer, "--ros-args", "-r", "__ns:=/arm2", ns="/arm2")
    rig.send_and_wait(rig.xyz, target(0.2, 0.0, 0.15))
    names = observer.node.get_publisher_names_and_types_by_node("compute_ik", "/arm2")
    topics = {t for t, _ in names} - {"/rosout", "/parameter_events"}
    # the trajectory controllers' state and the actions' feedback and status move too
    actions = {f"/arm2/{a}/_action/{t}" for a in ("arm_controller/follow_joint_trajectory", "gripper_controller/gripper_cmd")
               for t in ("feedback", "status")}
    assert topics == {"/arm2/joint_states", "/arm2/servo_angles", "/arm2/diagnostics",
                      "/arm2/arm_controller/controller_state"} | actions, topics
    subs = {t for t, _ in observer.node.get_subscriber_names_and_types_by_node("compute_ik", "/arm2")}
    assert {"/arm2/xyz_target", "/arm2/gripper_target", "/arm2/joint_target", "/arm2/estop",
            "/arm2/servo_state", "/arm2/arm_controller/joint_trajectory"} <= subs
    # (nothing on /servo_angles: its only publisher would be compute_ik, listed in full above)
    assert root_angles == [] and observer.node.count_publishers("/servo_angles") == 0


def test_remap_and_params_file(launch, observer, tmp_path):
    params = tmp_path / "ik.yaml"
    # keys match the node name after remapping, as in rcl
    params.write_text("ik:\n  ros__parameters:\n    base_frame: arm_base\n    diagnostics_period: 0.5\n")
    rig_proc = launch("compute_ik", "--ros-args", "--params-file", str(params), "-r", "xyz_target:=goal", "-r", "__node:=ik")
    angles = observer.sub("/servo_angles", JointState)
    goal = observer.pub("/goal", PointStamped)
    observer.wait_matched(goal)
    observer.wait_publisher("/servo_angles")
    goal.publish(target(0.2, 0.0, 0.15, frame="arm_base"))
    assert observer.spin_until(lambda: angles, 10)
    assert ("ik", "/") in observer.node.get_node_names_and_namespaces()
    assert rig_proc.proc.poll() is None


def call(observer, client, request, timeout=10):
    assert client.wait_for_service(timeout_sec=timeout), f"{client.srv_name} not offered"
    future = client.call_async(request)
    assert observer.spin_until(future.done, timeout)
    return future.result()


def test_parameters_through_the_standard_services(launch, observer):
    rig = IkRig(launch, observer)
    node = observer.node
    listed = call(observer, node.create_client(ListParameters, "/compute_ik/list_parameters"), ListParameters.Request())
    assert {"arm_config", "base_frame", "diagnostics_period", "use_sim_time"} <= set(listed.result.names)

    get = node.create_client(GetParameters, "/compute_ik/get_parameters")
    values = call(observer, get, GetParameters.Request(names=["base_frame", "diagnostics_period"])).values
    assert values[0].string_value == "base_link"
    assert values[1].double_value == 1.0

    setp = node.create_client(SetParameters, "/compute_ik/set_parameters")

    def set_param(name, **value):
        v = ParameterValue(**value)
        return call(observer, setp, SetParameters.Request(parameters=[Parameter(name=name, value=v)])).results[0]

    out_of_range = set_param("diagnostics_period", type=ParameterType.PARAMETER_DOUBLE, double_value=500.0)
    assert not out_of_range.successful and "outside" in out_of_range.reason
    missing = set_param("arm_config", type=ParameterType.PARAMETER_STRING, string_value="/nonexistent/arm.yaml")
    assert not missing.successful and "/nonexistent/arm.yaml" in missing.reason
    assert set_param("base_frame", type=ParameterType.PARAMETER_STRING, string_value="world").successful
    values = call(observer, get, GetParameters.Request(names=["base_frame"])).values
    assert values[0].string_value == "world"
    # the new value is in force
    rig.send_and_wait(rig.xyz, target(0.2, 0.0, 0.15, frame="world"))
    rejected = rig.rejected_count()
    rig.xyz.publish(target(0.2, 0.0, 0.15, frame="base_link"))
    assert observer.spin_until(lambda: rig.rejected_count() > rejected, 10)
    assert rig.last_diag()[1]["last_rejection_code"] == "wrong_frame"


def test_a_custom_calibration_file_is_used(launch, observer, tmp_path):
    cfg = tmp_path / "arm.yaml"
    cfg.write_text("servos:\n  base: { offset_deg: 95.0, gain: -2.0, min_deg: 0.0, max_deg: 180.0, pulse_min_us: 544, pulse_max_us: 2400 }\n")
    rig = IkRig(launch, observer, "--ros-args", "-p", f"arm_config:={cfg}")
    js, sa = rig.send_and_wait(rig.xyz, target(0.2, 0.0, 0.15))
    assert math.degrees(sa.position[0]) == pytest.approx(95.0, abs=1e-9)


def test_a_deeply_nested_arm_config_is_refused_at_once_and_the_calibration_kept(launch, observer, tmp_path):
    """YAML nested thousands deep took the parser seconds to minutes (it is quadratic in
    the nesting): now refused before parsing, in the reply, a log line and diagnostics."""
    cfg = tmp_path / "arm.yaml"
    cfg.write_text("servos:\n  base: { offset_deg: 95.0, gain: -2.0, min_deg: 0.0, max_deg: 180.0, pulse_min_us: 544, pulse_max_us: 2400 }\n")
    rig = IkRig(launch, observer, "--ros-args", "-p", f"arm_config:={cfg}", "-p", "diagnostics_period:=0.2")
    deep = tmp_path / "deep.yaml"
    deep.write_text("geometry: " + "[" * 10_000 + "]" * 10_000 + "\n")
    [result] = set_params(observer, "compute_ik", arm_config=str(deep))
    assert not result.successful and "10000 `[` or `{`" in result.reason and str(deep) in result.reason
    assert observer.spin_until(lambda: "last_parameter_refusal" in rig.last_diag()[1], 5)
    diag = rig.last_diag()[1]
    assert diag["parameters_refused"] == "1" and diag["last_parameter_refusal"].startswith("arm_config: ")
    assert observer.spin_until(lambda: "parameter arm_config refused" in rig.proc.output(), 5)
    _, sa = rig.send_and_wait(rig.xyz, target(0.2, 0.0, 0.15))
    assert math.degrees(sa.position[0]) == pytest.approx(95.0, abs=1e-9)


def test_domains_do_not_hear_each_other(launch, observer, domain, other_domain):
    """A participant in another domain neither hears compute_ik nor reaches it, while a
    control made at the same moment in compute_ik's domain discovers it and hears its
    servo_angles within the same window: the stranger's silence is not a short wait."""
    stranger = Observer(other_domain, "stranger")
    control = Observer(domain, "control")
    try:
        rig = IkRig(launch, observer)
        heard = stranger.sub("/servo_angles", JointState)
        pub = stranger.pub("/xyz_target", PointStamped)
        control_heard = control.sub("/servo_angles", JointState)
        control_pub = control.pub("/xyz_target", PointStamped)  # never publishes: shows the match only

        def control_sees():
            return (control_pub.get_subscription_count() > 0 and control.node.count_publishers("/servo_angles") > 0
                    and ("compute_ik", "/") in control.node.get_node_names_and_namespaces())

        def spin_both(until, timeout=30):
            end = time.monotonic() + timeout
            while not until() and time.monotonic() < end:
                pub.publish(target(0.2, 0.0, 0.15))  # the stranger keeps trying all along
                stranger.spin_for(0.05)
                control.spin_for(0.05)
            return until()

        assert spin_both(control_sees), "the control did not discover compute_ik in its domain"
        stamp = now_stamp()
        rig.send_and_wait(rig.xyz, target(0.21, 0.0, 0.15, sec=stamp[0], nanosec=stamp[1]), stamp)
        taken = now_stamp()  # the node has handled both our inputs (the sentinel's step is here)
        assert spin_both(lambda: control_heard), "the control heard no servo_angles in compute_ik's domain"
        assert heard == []
        assert pub.get_subscription_count() == 0
        assert ("compute_ik", "/") not in stranger.node.get_node_names_and_namespaces()
        # only our own inputs reached the node (the target and send_and_wait's sentinels):
        # a report made after they were handled counts them (the stranger published all along)
        assert observer.spin_until(lambda: rig.diagnostics and stamp_of(rig.diagnostics[-1][1]) > taken, 10)
        assert rig.last_diag()[1]["received"] == str(1 + rig.sentinels), rig.last_diag()[1]
    finally:
        control.close()
        stranger.close()


def test_sigterm_exits_with_zero(launch, observer):
    rig = IkRig(launch, observer)
    assert rig.proc.stop(signal.SIGTERM) == 0


@pytest.mark.parametrize(
    "args,env,message",
    [
        (["--ros-args", "-p", "nope:=1"], {}, "not a parameter"),
        (["--ros-args", "-p", "diagnostics_period:=0.0"], {}, "outside"),
        (["--ros-args", "-p", "base_frame:=3"], {}, "expected a string"),
        (["--ros-args", "-r"], {}, "needs a value"),
        (["--ros-args", "--params-file", "/nonexistent/p.yaml"], {}, "/nonexistent/p.yaml"),
        (["--ros-args", "-r", "__ns:=/bad ns"], {}, "bad ns"),
        (["stray"], {}, "unexpected argument"),
        ([], {"ROS_DOMAIN_ID": "999"}, "ROS_DOMAIN_ID"),
    ],
)
def test_bad_command_lines_exit_nonzero_with_a_reason(args, env, message, domain):
    import os
    run_env = {**os.environ, "ROS_DOMAIN_ID": str(domain), **env}
    r = subprocess.run([bin_path("compute_ik"), *args], capture_output=True, text=True, env=run_env, timeout=20)
    assert r.returncode != 0
    assert message in r.stderr, r.stderr


def test_a_jump_is_streamed_as_a_motion_within_the_servo_limits(launch, observer):
    """A 30 deg base move (60 deg of its servo through the 2:1 gear) is a stream of
    steps 20 ms apart, each servo within config/arm.yaml's motion limits (300 deg/s,
    1200 deg/s^2), joint_states following it; the first step carries the target's
    stamp, the later ones when they were planned."""
    rig = IkRig(launch, observer)
    n = len(rig.servo_angles)
    stamp = now_stamp()
    msg = joint_target(["base_joint"], [math.radians(30)])
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    rig.send_and_wait(rig.joints, msg, stamp)
    steps = [m for _, m in rig.servo_angles[n:-1]]  # the last is send_and_wait's sentinel
    assert len(steps) > 15, f"{len(steps)} steps"
    base = [math.degrees(m.position[0]) for m in steps]
    v = [(b - a) / 0.02 for a, b in zip([90.0] + base, base)]
    acc = [(b - a) / 0.02 for a, b in zip([0.0] + v, v)]
    assert max(abs(x) for x in v) <= 300 + 1e-6
    assert max(abs(x) for x in acc) <= 1200 + 1e-3
    assert base[-1] == pytest.approx(30.0, abs=1e-9)
    later = [(m.header.stamp.sec, m.header.stamp.nanosec) for m in steps[1:]]
    assert all(s != stamp for s in later) and later == sorted(later)
    # joint_states follow the same motion
    by_stamp = {stamp_of(m): m for _, m in rig.joint_states}
    js = [joints_of(by_stamp[stamp_of(m)])["base_joint"] for m in steps]
    assert js[-1] == pytest.approx(math.radians(30), abs=1e-12)


def test_targets_older_than_max_target_age_are_refused(launch, observer):
    rig = IkRig(launch, observer, "--ros-args", "-p", "max_target_age:=0.5")
    n = len(rig.servo_angles)
    rig.xyz.publish(target(0.2, 0.0, 0.15, sec=now_stamp(-2.0)[0], nanosec=now_stamp(-2.0)[1]))
    assert observer.spin_until(lambda: rig.diagnostics and rig.last_diag()[1].get("last_rejection_code") == "stale", 10)
    assert "older than max_target_age" in rig.last_diag()[1]["last_rejection"]
    assert rig.last_diag()[1]["stale"] == "1"
    # it moved nothing: the first step after it is the next (fresh) target's
    sentinel = target(0.2, 0.0, 0.15)
    rig.first_step_after(n, rig.xyz, sentinel)
    rig.wait_arrived(n, goal_of(sentinel))
    # a zero stamp means now
    rig.send_and_wait(rig.xyz, target(0.2, 0.0, 0.15, sec=0, nanosec=0))


def test_a_straight_line_leaving_the_workspace_is_refused_before_the_move(launch, observer):
    rig = IkRig(launch, observer, "--ros-args", "-p", "motion:=line")
    rig.send_and_wait(rig.xyz, target(0.08, 0.075, 0.15))
    n = len(rig.servo_angles)
    rig.xyz.publish(target(0.08, -0.075, 0.15))  # through r < 0.102 m around the base axis
    assert observer.spin_until(lambda: rig.last_diag()[1].get("last_rejection_code") == "line_leaves_workspace", 10)
    assert "% along the line" in rig.last_diag()[1]["last_rejection"]
    # it moved nothing: the first step after it is the sentinel's, where the arm is
    rig.first_step_after(n, rig.xyz, target(0.08, 0.075, 0.15))


# --- issue 10: solvers, undesirable configurations, nearest point, pose_target ---

def set_params(observer, node_name, **values):
    """Set parameters through /<node>/set_parameters; returns the SetParametersResult list."""
    setp = observer.node.create_client(SetParameters, f"/{node_name}/set_parameters")
    params = []
    for name, v in values.items():
        if isinstance(v, bool):
            pv = ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=v)
        elif isinstance(v, float):
            pv = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v)
        else:
            pv = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=v)
        params.append(Parameter(name=name, value=pv))
    return call(observer, setp, SetParameters.Request(parameters=params)).results


AGREEMENT_TARGETS = [(0.2, 0.05, 0.15), (0.15, -0.1, 0.2), (0.25, 0.0, 0.1), (0.12, 0.06, 0.24)]


def test_every_solver_switched_at_run_time_agrees_with_the_closed_form(launch, observer):
    """`ros2 param set /compute_ik solver …` while running: jacobian, dls and newton put
    the arm where the closed form does, within 1e-9 m (tool) on the same targets; an
    unknown solver is refused with the valid ones. (max_target_age off: the targets'
    staleness is not what this test is about, and a host starved for half a second made
    compute_ik refuse one as stale, rightly, once.)"""
    rig = IkRig(launch, observer, "--ros-args", "-p", "max_target_age:=0.0")
    arm = ("base_joint", "shoulder_joint", "elbow_joint")
    closed = []
    for p in AGREEMENT_TARGETS:
        js, _ = rig.send_and_wait(rig.xyz, target(*p))
        closed.append([joints_of(js)[j] for j in arm])
    bad = set_params(observer, "compute_ik", solver="levenberg")[0]
    assert not bad.successful
    assert "levenberg" in bad.reason and "analytic, jacobian, dls, newton" in bad.reason, bad.reason
    for solver in ("jacobian", "dls", "newton"):
        assert set_params(observer, "compute_ik", solver=solver)[0].successful
        for p, q_closed in zip(AGREEMENT_TARGETS, closed):
            js, sa = rig.send_and_wait(rig.xyz, target(*p))
            q = [joints_of(js)[j] for j in arm]
            check_state(js, sa, 0.0)  # passive joints and servo mapping as before
            assert math.dist(fk(*q), fk(*q_closed)) <= 1e-9, (solver, p)
            assert math.dist(fk(*q), p) <= 1e-9, (solver, p)
            assert q == pytest.approx(q_closed, abs=1e-7), (solver, p)
        assert observer.spin_until(lambda: rig.last_diag()[1].get("solver") == solver, 5)
        assert rig.last_diag()[1]["last_solve"].startswith(f"{solver}: converged"), rig.last_diag()[1]
    # an unreachable target is refused by the numerical solver with the distance it got to
    rejected = rig.rejected_count()
    rig.xyz.publish(target(0.5, 0.0, 0.15))
    assert observer.spin_until(lambda: rig.rejected_count() > rejected, 10)
    values = rig.last_diag()[1]
    assert values["last_rejection_code"] == "ik_not_converged"
    assert values["last_rejection"].startswith("not reached: the closest the newton solver got within the joint limits is 0.2"), values
    # back to the closed form
    assert set_params(observer, "compute_ik", solver="analytic")[0].successful
    js, _ = rig.send_and_wait(rig.xyz, target(*AGREEMENT_TARGETS[0]))
    assert [joints_of(js)[j] for j in arm] == closed[0]


def test_undesirable_configurations_are_in_diagnostics_with_a_way_out(launch, observer):
    rig = IkRig(launch, observer, "--ros-args", "-p", "diagnostics_period:=0.2")
    assert observer.spin_until(lambda: rig.diagnostics and rig.last_diag()[1].get("undesirable") == "none", 5)
    # the shoulder at its upper limit (125 deg)
    rig.send_and_wait(rig.joints, joint_target(["shoulder_joint", "elbow_joint"], [math.radians(125), math.radians(-110)]))
    key = "undesirable:at_limit:shoulder_joint:upper"
    assert observer.spin_until(lambda: key in rig.last_diag()[1], 5), rig.last_diag()[1]
    status, values = rig.last_diag()
    assert "at_limit:shoulder_joint:upper" in values["undesirable"]
    assert "away: shoulder_joint -1.00" in values[key], values[key]
    assert status.level == b"\x00"  # an accepted target: still OK
    # the forearm elevation phi half a degree above its lower limit (-65 deg): the coupling constraint
    rig.send_and_wait(rig.joints, joint_target(["shoulder_joint", "elbow_joint"], [math.radians(60), math.radians(-124.5)]))
    key = "undesirable:at_limit:forearm_elevation:lower"
    assert observer.spin_until(lambda: key in rig.last_diag()[1], 5), rig.last_diag()[1]
    assert "shoulder_joint +0.71, elbow_joint +0.71" in rig.last_diag()[1][key]
    # the away direction works: a step along it clears the report
    rig.send_and_wait(rig.joints, joint_target(["shoulder_joint", "elbow_joint"], [math.radians(65), math.radians(-120)]))
    assert observer.spin_until(lambda: rig.last_diag()[1].get("undesirable") == "none", 5), rig.last_diag()[1]


def test_a_target_just_outside_is_replaced_by_the_nearest_reachable_point_when_asked(launch, observer):
    rosout = observer.sub("/rosout", Log, ROSOUT)
    rig = IkRig(launch, observer)
    outside = (0.29, 0.0, 0.15)  # ROBOT.md: at z = 0.15 the tool reaches r 0.278 at most
    rejected = rig.rejected_count()
    rig.xyz.publish(target(*outside))
    assert observer.spin_until(lambda: rig.rejected_count() > rejected, 10)
    assert rig.last_diag()[1]["substitute_nearest"] == "off"
    assert set_params(observer, "compute_ik", substitute_nearest=True, substitute_max_distance=0.02)[0].successful
    # where the nearest point is the node knows, not the test: once its diagnostics say
    # the substituted motion has ended, every step before the sentinel's is the motion's
    n_sa = len(rig.servo_angles)
    rig.xyz.publish(target(*outside))
    assert observer.spin_until(lambda: rig.last_diag()[1].get("substitutions") == "1"
                               and rig.last_diag()[1]["motion"] == "at rest", 10), rig.last_diag()[1]
    js, _ = rig.settle(n_sa)
    reached = fk(*[joints_of(js)[j] for j in ("base_joint", "shoulder_joint", "elbow_joint")])
    d = math.dist(reached, outside)
    assert 0.005 < d < 0.02, d
    assert abs(reached[1]) < 1e-6 and reached[2] == pytest.approx(0.15, abs=0.01)
    assert observer.spin_until(lambda: rig.last_diag()[1].get("substitutions") == "1", 5)
    values = rig.last_diag()[1]
    assert "xyz_target (0.2900, 0.0000, 0.1500) m is out of reach" in values["last_substitution"]
    assert f"{d:.4f} m away" in values["last_substitution"], (d, values["last_substitution"])
    assert observer.spin_until(lambda: any("nearest reachable point" in m.msg for _, m in rosout), 5)
    # farther out than substitute_max_distance: refused as before
    rejected = rig.rejected_count()
    rig.xyz.publish(target(0.5, 0.0, 0.15))
    assert observer.spin_until(lambda: rig.rejected_count() > rejected, 10)
    assert rig.last_diag()[1]["last_rejection_code"] == "too_far"


def pose_target(x, y, z, q=(0.0, 0.0, 0.0, 1.0)):
    m = PoseStamped()
    m.header.frame_id = "base_link"
    m.header.stamp.sec, m.header.stamp.nanosec = now_stamp()
    m.pose.position.x, m.pose.position.y, m.pose.position.z = float(x), float(y), float(z)
    m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = map(float, q)
    return m


def test_pose_target_moves_the_eezybot_to_its_position_and_reports_the_orientation(launch, observer):
    """The EezyBot (3 DOF) takes a pose position first: the tool goes where xyz_target
    would put it, and diagnostics say how far the orientation asked is from the one its
    level claw takes. A quaternion that is no rotation is refused."""
    rig = IkRig(launch, observer)
    pose = observer.pub("/pose_target", PoseStamped)
    observer.wait_matched(pose)
    yaw = math.atan2(0.05, 0.2)
    level = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))  # what the claw takes there
    before = None
    for q, off in ((level, 0.0), ((0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4)), None)):
        js, _ = rig.send_and_wait(pose, pose_target(0.2, 0.05, 0.15, q))
        assert math.dist(fk(*[joints_of(js)[j] for j in ("base_joint", "shoulder_joint", "elbow_joint")]), (0.2, 0.05, 0.15)) < 1e-9
        assert observer.spin_until(lambda: rig.last_diag()[1].get("last_pose_target") not in (None, before), 5)
        text = before = rig.last_diag()[1]["last_pose_target"]
        taken = float(text.split("the orientation taken is ")[1].split("°")[0])
        if off is not None:
            assert taken == pytest.approx(off, abs=0.01), text
        else:
            assert taken > 80, text
    rejected = rig.rejected_count()
    pose.publish(pose_target(0.2, 0.0, 0.15, (0.0, 0.0, 0.0, 0.0)))
    assert observer.spin_until(lambda: rig.rejected_count() > rejected, 10)
    assert rig.last_diag()[1]["last_rejection_code"] == "bad_orientation"
    assert rig.last_diag()[1]["last_rejection_topic"] == "pose_target"
