"""What the stock ROS 2 tools see of our nodes, asked the way they ask it through real rclpy
(`ros2 param describe/list`, `ros2 topic list -t`), and the binaries' command lines."""
import re
import subprocess
import tempfile

import pytest
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, GetParameterTypes, ListParameters

from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from conftest import TOPICS, bin_path, latest_status

ROS_NODES = ["compute_ik", "serial_node", "state_publisher", "camera_node", "recorder", "twin"]
# camera_node: its test source, small and slow (no camera here; the topics are what counts);
# the recorder: its dataset in a folder of this run's, recording both cameras; the physics
# twin (its own link: serial_node runs on the virtual Arduino), its camera small and slow
NODE_ARGS = {"serial_node": ["--ros-args", "-p", "port:=mock"],
             "camera_node": ["--ros-args", "-p", "device:=test", "-p", "width:=160", "-p", "height:=128", "-p", "fps:=5"],
             "recorder": ["--ros-args", "-p", f"root:={tempfile.mkdtemp(prefix='eezybot-ros-cli-')}/dataset",
                          "-p", "image_topics:=[camera/image_raw/compressed, twin/camera/image_raw/compressed]"],
             "twin": ["--ros-args", "-p", f"link:={tempfile.mkdtemp(prefix='eezybot-ros-cli-')}/tty", "-p", "camera_fps:=5",
                      "-p", "camera_width:=160", "-p", "camera_height:=128"]}


def call(observer, client, request, timeout=10):
    assert client.wait_for_service(timeout_sec=timeout), f"{client.srv_name} not offered"
    future = client.call_async(request)
    assert observer.spin_until(future.done, timeout), f"{client.srv_name} did not answer"
    return future.result()


def help_table(name):
    """name -> (description, read-only) from the binary's --help, the other place the
    parameters are documented."""
    out = subprocess.run([bin_path(name), "--help"], capture_output=True, text=True, timeout=30).stdout
    table = {}
    for line in out.split("parameters:\n", 1)[1].splitlines():
        m = re.match(r"  (\S+)\s+(.*) \(default .*\)(, read-only)?$", line)
        if m:
            table[m.group(1)] = (m.group(2), bool(m.group(3)))
    return table


# Ranges and constraints stated in each node's spec, as describe_parameters must report them
# (from_value, to_value); any other parameter has no range.
RANGES = {
    "compute_ik": {"diagnostics_period": (0.05, 60.0), "motion_rate": (1.0, 500.0), "max_target_age": (0.0, 3600.0),
                   "substitute_max_distance": (1e-6, 1.0), "gripper_up_angle": (0.0, 180.0),
                   "goal_tolerance": (0.0, 3.2), "path_tolerance": (0.0, 3.2), "goal_time_tolerance": (0.0, 60.0),
                   "leader_timeout": (0.01, 5.0), "calibration_lease": (0.5, 3600.0)},
    "serial_node": {"baud": (1200, 4_000_000), "send_rate": (1.0, 500.0), "watchdog_ms": (20, 60_000),
                    "heartbeat_period": (0.01, 10.0), "diagnostics_period": (0.05, 60.0)},
    "state_publisher": {"publish_frequency": (0.0, 10_000.0), "diagnostics_period": (0.05, 60.0)},
    "camera_node": {"width": (144, 4096), "height": (128, 4096), "fps": (1, 120), "jpeg_quality": (1, 100),
                    "diagnostics_period": (0.05, 60.0)},
    "recorder": {"fps": (1, 200), "max_staleness": (0.01, 5.0)},
    "twin": {"camera_fps": (0, 60), "camera_width": (16, 1920), "camera_height": (16, 1080), "camera_fovy": (10.0, 120.0),
             "jpeg_quality": (1, 100), "state_rate": (1.0, 500.0), "diagnostics_period": (0.05, 60.0)},
}
CONSTRAINTS = {
    "compute_ik": {"solver": "one of: analytic, jacobian, dls, newton", "motion": "one of: joint, line",
                   "feedback_layout": "one of: any, kilted, jazzy"},
    "serial_node": {"watchdog_action": "one of: hold, detach", "estop_action": "one of: hold, detach"},
    "state_publisher": {"urdf": "a URDF file that loads"},
    "camera_node": {"device": "a device path, or test"},
    "recorder": {"task": "1 to 500 characters, no control characters",
                 "arm_config": "empty, or an arm_config YAML file that loads"},
    "twin": {"arm_config": "empty, or an arm_config YAML file that loads"},
}


@pytest.mark.parametrize("name", ROS_NODES)
def test_describe_parameters_gives_description_type_read_only_and_range(launch, observer, name):
    launch(name, *NODE_ARGS.get(name, []))
    node = observer.node
    listed = call(observer, node.create_client(ListParameters, f"/{name}/list_parameters"),
                  ListParameters.Request()).result.names
    documented = help_table(name)
    assert set(listed) == set(documented) | {"use_sim_time"}, listed

    types = call(observer, node.create_client(GetParameterTypes, f"/{name}/get_parameter_types"),
                 GetParameterTypes.Request(names=[*listed, "no_such_parameter"])).types
    assert types[-1] == ParameterType.PARAMETER_NOT_SET
    described = call(observer, node.create_client(DescribeParameters, f"/{name}/describe_parameters"),
                     DescribeParameters.Request(names=listed)).descriptors
    assert [d.name for d in described] == listed

    for d, t in zip(described, types):
        assert d.type == t != ParameterType.PARAMETER_NOT_SET, d
        assert d.description and "not implemented" not in d.description, d
        if d.name == "use_sim_time":
            assert d.type == ParameterType.PARAMETER_BOOL and not d.read_only
            assert "/clock" in d.description
            continue
        assert (d.description, d.read_only) == documented[d.name], d.name
        expected = RANGES[name].get(d.name)
        if expected is None:
            assert not d.integer_range and not d.floating_point_range, d
        elif d.type == ParameterType.PARAMETER_INTEGER:
            [r] = d.integer_range
            assert (r.from_value, r.to_value, r.step) == (*expected, 0) and not d.floating_point_range, d
        else:
            assert d.type == ParameterType.PARAMETER_DOUBLE
            [r] = d.floating_point_range
            assert (r.from_value, r.to_value, r.step) == (*expected, 0.0) and not d.integer_range, d
        if d.name in CONSTRAINTS[name]:
            assert CONSTRAINTS[name][d.name] in d.additional_constraints, d
    by_name = {d.name: d for d in described}
    if name == "compute_ik":
        # the example: `ros2 param describe /compute_ik diagnostics_period`
        assert by_name["diagnostics_period"].description == "seconds between diagnostics reports"
        assert not by_name["diagnostics_period"].read_only and by_name["urdf"].read_only
    if name == "serial_node":
        assert by_name["port"].read_only and by_name["port"].type == ParameterType.PARAMETER_STRING


def clock_subscriptions(observer):
    return observer.node.get_subscriptions_info_by_topic("/clock")


def test_clock_is_subscribed_only_with_use_sim_time_and_as_rosgraph_clock(launch, observer):
    launch("compute_ik")
    launch("state_publisher", "--ros-args", "-p", "use_sim_time:=true")
    # the control: the same binary with use_sim_time, started after the one judged
    launch("compute_ik", "--ros-args", "-r", "__node:=compute_ik_sim", "-p", "use_sim_time:=true")

    # A /clock reader is listed under no node name (ros2-client's own), so each is told
    # by its participant: the first 12 bytes of its GUID, shared with the node's others.
    def participants(topic, node=None):
        return {bytes(e.endpoint_gid[:12]) for e in observer.node.get_subscriptions_info_by_topic(topic)
                if node is None or e.node_name == node}

    def listed():
        ik, sim, sp = participants("/xyz_target", "compute_ik"), participants("/xyz_target", "compute_ik_sim"), \
            participants("/joint_states", "state_publisher")
        return ik and sim and sp and sim | sp <= participants("/clock")
    assert observer.spin_until(listed, 20), "compute_ik, the control's /clock or state_publisher's /clock not listed"
    # by then the control's /clock reader is listed: compute_ik on system time has none
    clock = participants("/clock")
    assert not clock & participants("/xyz_target", "compute_ik"), "compute_ik subscribes /clock on system time"
    assert clock == participants("/xyz_target", "compute_ik_sim") | participants("/joint_states", "state_publisher")
    subs = clock_subscriptions(observer)
    assert all(e.topic_type == "rosgraph_msgs/msg/Clock" for e in subs), [e.topic_type for e in subs]
    # nobody offers /clock with the wrong type (`ros2 topic list -t`)
    assert dict(observer.node.get_topic_names_and_types()).get("/clock") == ["rosgraph_msgs/msg/Clock"]


def set_use_sim_time(observer, on):
    from rcl_interfaces.msg import Parameter, ParameterValue
    from rcl_interfaces.srv import SetParameters
    setp = observer.node.create_client(SetParameters, "/state_publisher/set_parameters")
    value = ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=on)
    [result] = call(observer, setp, SetParameters.Request(parameters=[Parameter(name="use_sim_time", value=value)])).results
    assert result.successful, result.reason


def test_clock_is_subscribed_when_use_sim_time_is_set_at_run_time(launch, observer):
    launch("state_publisher")
    set_use_sim_time(observer, True)
    assert observer.spin_until(lambda: len(clock_subscriptions(observer)) == 1, 10)
    assert clock_subscriptions(observer)[0].topic_type == "rosgraph_msgs/msg/Clock"


def test_clock_is_unsubscribed_when_use_sim_time_is_cleared_at_run_time(launch, observer):
    """The node deletes its /clock reader and RustDDS disposes it on SEDP. Fast DDS takes
    the disposed endpoint only from the key hash in the inline QoS (it ignores a
    serialized key over 16 bytes); RustDDS sent only the key, so rclpy listed the reader
    for as long as the node lived (patches/README.md, rustdds entry 20)."""
    launch("state_publisher", "--ros-args", "-p", "use_sim_time:=true")
    assert observer.spin_until(lambda: len(clock_subscriptions(observer)) == 1, 10)
    set_use_sim_time(observer, False)
    assert observer.spin_until(lambda: len(clock_subscriptions(observer)) == 0, 10)


def library_warnings(text):
    """WARN and ERROR lines from RustDDS or ros2-client (targets `node:rustdds::…`)."""
    return [line for line in text.splitlines()
            if re.match(r"\[(WARN|ERROR)\] \[[0-9.]+\] \[[^\]]*:(rustdds|ros2_client)", line)]


def test_no_library_warnings_at_start_and_stop_with_an_rclpy_peer(launch, observer):
    """Neither starting next to a Fast DDS peer nor Ctrl-C makes RustDDS or ros2-client
    complain. At shutdown a node drops all its endpoints at once; RustDDS' removal
    channels held 4 and logged `Cannot remove Reader … Full` (42 of 1542 test logs)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import String
    observer.pub("chatter", String)  # a Fast DDS peer with endpoints of its own
    diags = observer.sub("/diagnostics", DiagnosticArray)
    procs = [launch(name, *NODE_ARGS.get(name, [])) for name in ROS_NODES]
    # each node has started next to the peer once its diagnostics reach the peer's
    # reader (it discovered the peer's participant and endpoints; the bound only ends a
    # failure)
    assert observer.spin_until(lambda: all(latest_status(diags, name) for name in ROS_NODES), 30), \
        [name for name in ROS_NODES if not latest_status(diags, name)]
    for p in procs:
        assert p.proc.poll() is None, p.output()
        assert library_warnings(p.output()) == [], p.output()
    for p in procs:
        assert p.stop() == 0
        out = p.log_path.read_text()
        assert library_warnings(out) == [], out[-3000:]


def test_the_running_graph_has_the_topics_of_the_contract(launch, observer):
    """Every topic of tests/data/topics.json (generated from ros_plumbing::topics) is
    published and subscribed by the nodes it names, with its type, reliability and
    durability, as `ros2 topic info -v` shows them."""
    launch("gui_bridge", "--ros-args", "-p", "bind:=127.0.0.1:0")
    for name in ROS_NODES:
        launch(name, *NODE_ARGS.get(name, []))
    reliability = {"reliable": ReliabilityPolicy.RELIABLE, "best effort": ReliabilityPolicy.BEST_EFFORT}
    durability = {"volatile": DurabilityPolicy.VOLATILE, "transient-local": DurabilityPolicy.TRANSIENT_LOCAL}

    def endpoints(topic):
        return (observer.node.get_publishers_info_by_topic(f"/{topic}"),
                observer.node.get_subscriptions_info_by_topic(f"/{topic}"))

    def ours(nodes):
        return {n.split(" ")[0] for n in nodes}  # `gui_bridge (record)`: a mode of gui_bridge it does not run now

    def complete():
        for t in TOPICS.values():
            pubs, subs = endpoints(t["name"])
            # `gui_bridge (calibration)` and the like: a mode of a node, not running now
            want_pubs = {n for n in t["publishers"] if " " not in n}
            want_subs = {n for n in t["subscribers"] if " " not in n}
            if not want_pubs <= {e.node_name for e in pubs} or not want_subs <= {e.node_name for e in subs}:
                return False
        return True

    assert observer.spin_until(complete, 20), {t: [[e.node_name for e in side] for side in endpoints(t)] for t in TOPICS}
    for t in TOPICS.values():
        pubs, subs = endpoints(t["name"])
        for e in pubs + subs:
            if e.node_name not in ours(t["publishers"] + t["subscribers"]):
                continue  # the observer, or a node this topic does not name
            assert e.topic_type == t["type"], (t["name"], e.node_name, e.topic_type)
            assert e.qos_profile.reliability == reliability[t["reliability"]], (t["name"], e.node_name, e.qos_profile)
            assert e.qos_profile.durability == durability[t["durability"]], (t["name"], e.node_name, e.qos_profile)


BINARIES = [*ROS_NODES, "virtual_arduino"]


@pytest.mark.parametrize("name", BINARIES)
def test_help_goes_to_stdout_and_exits_0(name, tmp_path):
    r = subprocess.run([bin_path(name), "--help"], capture_output=True, text=True, timeout=30, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "usage:" in r.stdout and r.stderr == ""
    assert list(tmp_path.iterdir()) == []  # virtual_arduino made a pty link named --help


# (no argument is a bad command line only for virtual_arduino: a ROS node needs none)
BAD_COMMAND_LINES = [pytest.param(name, args, id=f"{id_}-{name}")
                     for id_, args in (("bogus", ["--bogus"]), ("bogus-ros", ["--ros-args", "--bogus"]), ("none", []))
                     for name in BINARIES if args or name == "virtual_arduino"]


@pytest.mark.parametrize("name,args", BAD_COMMAND_LINES)
def test_a_bad_command_line_exits_2(name, args, tmp_path, domain):
    r = subprocess.run([bin_path(name), *args], capture_output=True, text=True, timeout=30, cwd=tmp_path,
                       env={"ROS_DOMAIN_ID": str(domain), "PATH": "/usr/bin:/bin"})
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert r.stdout == "" and name in r.stderr
    assert len(r.stderr.splitlines()) <= 2, r.stderr  # the reason, not DDS teardown chatter
    assert list(tmp_path.iterdir()) == []
