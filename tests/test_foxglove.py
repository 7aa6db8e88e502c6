"""gui_bridge's Foxglove WebSocket server (parameter `foxglove_bind`), seen by a client
written here from the protocol's specification (the `websockets` package; JSON text
ops, binary messageData), decoding what it receives with rclpy's deserialize_message
(Cyclone DDS' IDL for tf2_msgs, which has no rclpy wheel)."""
import errno
import re
import socket
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from rclpy.node import NodeNameNonExistentError
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from foxglove_client import FoxgloveClient, free_port
from interop.idl import TFMessage

TOPIC_TYPES = {
    "/robot_description": "std_msgs/msg/String",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/servo_angles": "sensor_msgs/msg/JointState",
    "/servo_state": "sensor_msgs/msg/JointState",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/xyz_target": "geometry_msgs/msg/PointStamped",
    "/xyz_line_target": "geometry_msgs/msg/PointStamped",
    "/pose_target": "geometry_msgs/msg/PoseStamped",
    "/gripper_target": "std_msgs/msg/Float64",
    "/joint_target": "sensor_msgs/msg/JointState",
    "/estop": "std_msgs/msg/Bool",
}
# the venv's share/ (rclpy is in venv/lib/python3.X/site-packages/rclpy)
VENV_SHARE = Path(__import__("rclpy").__file__).resolve().parents[4] / "share"


def stripped_msg(type_name):
    """A .msg file of the venv's ROS 2 packages without comments and blank lines."""
    text = (VENV_SHARE / f"{type_name}.msg").read_text()
    lines = [re.sub(r"#.*", "", line).rstrip() for line in text.splitlines()]
    return "".join(line + "\n" for line in lines if line)


def check_schema(type_name, schema):
    """Each block of a ros2msg schema is the package's real definition."""
    blocks = schema.split("=" * 80 + "\n")
    assert blocks[0], type_name
    named = [(type_name, blocks[0])]
    for block in blocks[1:]:
        head, _, body = block.partition("\n")
        assert head.startswith("MSG: "), head
        pkg, name = head[5:].split("/")
        named.append((f"{pkg}/msg/{name}", body))
    for name, body in named:
        if name.startswith("tf2_msgs/"):  # no tf2_msgs package in the venv
            assert body == "geometry_msgs/TransformStamped[] transforms\n"
            continue
        assert body == stripped_msg(name), name


def start_graph(launch, observer, *ros_args):
    port, web = free_port(), free_port()
    launch("compute_ik")
    launch("state_publisher")
    gui = launch("gui_bridge", "--ros-args", "-p", f"bind:=127.0.0.1:{web}",
                 "-p", f"foxglove_bind:=127.0.0.1:{port}", *ros_args)
    observer.wait_publisher("/joint_states")
    return gui, port


def test_a_foxglove_client_sees_every_topic_and_decodes_tf_and_joint_states(launch, observer):
    gui, port = start_graph(launch, observer)
    fox = FoxgloveClient(port)
    try:
        assert fox.pump_until(lambda: fox.info and len(fox.channels) == len(TOPIC_TYPES))
        assert fox.info["name"] == "gui_bridge"
        for topic, type_name in TOPIC_TYPES.items():
            c = fox.channels[topic]
            assert (c["encoding"], c["schemaName"], c["schemaEncoding"]) == ("cdr", type_name, "ros2msg"), topic
            check_schema(type_name, c["schema"])
        fox.subscribe(*TOPIC_TYPES)
        # latched topics arrive on subscribing
        assert fox.pump_until(lambda: "/robot_description" in fox.received and "/tf_static" in fox.received)
        urdf = deserialize_message(fox.received["/robot_description"][0][1], String)
        assert "<robot" in urdf.data
        static = TFMessage.deserialize(fox.received["/tf_static"][0][1])
        assert static.transforms

        pub = observer.pub("/xyz_target", PointStamped)
        observer.wait_matched(pub)
        # compute_ik and gui_bridge's Foxglove tap, made when the client subscribed
        observer._wait_discovery(lambda: pub.get_subscription_count() >= 2, "no Foxglove tap on /xyz_target")
        observer.spin_for(0.3)
        target = PointStamped()
        target.header.frame_id = "base_link"
        target.point.x, target.point.y, target.point.z = 0.18, 0.04, 0.14
        pub.publish(target)
        assert fox.pump_until(lambda: "/joint_states" in fox.received and "/tf" in fox.received
                              and "/xyz_target" in fox.received)
        got = deserialize_message(fox.received["/xyz_target"][0][1], PointStamped)
        assert (got.point.x, got.point.y, got.point.z) == (0.18, 0.04, 0.14)
        # the bytes are the wire's, encapsulation header included
        assert fox.received["/xyz_target"][0][1] == serialize_message(target)
        js = deserialize_message(fox.received["/joint_states"][-1][1], JointState)
        assert "base_joint" in js.name and len(js.position) == len(js.name)
        tf = TFMessage.deserialize(fox.received["/tf"][-1][1])
        assert {t.child_frame_id for t in tf.transforms}
        assert fox.pump_until(lambda: "/diagnostics" in fox.received)
        deserialize_message(fox.received["/diagnostics"][-1][1], DiagnosticArray)
        # log times are the reception times (ns since the epoch)
        assert abs(fox.received["/joint_states"][-1][0] / 1e9 - time.time()) < 30
    finally:
        fox.close()


def test_foxglove_panels_publish_targets_only_with_foxglove_publish(launch, observer):
    gui, port = start_graph(launch, observer, "-p", "foxglove_publish:=true")
    got = observer.sub("/xyz_target", PointStamped)
    fox = FoxgloveClient(port)
    try:
        assert fox.pump_until(lambda: fox.info and len(fox.channels) == len(TOPIC_TYPES))
        assert "clientPublish" in fox.info["capabilities"]
        fox.advertise(1, "/xyz_target", "geometry_msgs/msg/PointStamped")
        fox.advertise(2, "/cmd_vel", "geometry_msgs/msg/Twist")
        assert fox.pump_until(lambda: fox.statuses)
        assert "/cmd_vel" in fox.statuses[0]["message"]
        target = PointStamped()
        target.header.frame_id = "base_link"
        target.point.x, target.point.y, target.point.z = 0.2, 0.0, 0.15
        deadline = time.monotonic() + 10
        while not got and time.monotonic() < deadline:  # until gui_bridge's publisher is matched
            fox.publish(1, serialize_message(target))
            observer.spin_for(0.2)
        assert got, "the target published from Foxglove never reached ROS"
        m = got[0][1]
        assert (m.point.x, m.point.y, m.point.z, m.header.frame_id) == (0.2, 0.0, 0.15, "base_link")
    finally:
        fox.close()


def test_foxglove_clients_only_watch_by_default_and_empty_bind_is_off(launch, observer):
    gui, port = start_graph(launch, observer)
    fox = FoxgloveClient(port)
    try:
        assert fox.pump_until(lambda: fox.info is not None)
        assert "clientPublish" not in fox.info["capabilities"]
    finally:
        fox.close()
    web = free_port()
    off = launch("gui_bridge", "--ros-args", "-r", "__node:=gui2", "-p", f"bind:=127.0.0.1:{web}",
                 "-p", "foxglove_bind:=")
    deadline = time.monotonic() + 10
    while "ready in ROS domain" not in off.output() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert "Foxglove WebSocket server off" in off.output()


def test_a_topic_is_subscribed_only_while_a_foxglove_client_watches_it(launch, observer):
    """An idle Foxglove server changes nothing in the graph: gui_bridge subscribes
    servo_angles (say) only while a client subscribes its channel, so compute_ik still sees
    serial_node's subscription go when the link to the Pi goes."""
    gui, port = start_graph(launch, observer)

    def tapped(topic):
        """gui_bridge subscribes `topic`: by topic (DDS endpoints), and by node (not
        before the node itself is discovered)."""
        observer.spin_for(0.1)
        by_topic = "gui_bridge" in [i.node_name for i in observer.node.get_subscriptions_info_by_topic(topic)]
        try:
            by_node = topic in [t for t, _ in observer.node.get_subscriber_names_and_types_by_node("gui_bridge", "/")]
        except NodeNameNonExistentError:
            by_node = False
        return by_topic, by_node

    def wait_for(want, topic="/servo_angles", timeout=10):
        deadline = time.monotonic() + timeout
        while (got := tapped(topic)) != want and time.monotonic() < deadline:
            pass
        return got

    # the taps made at start (every latched topic recorded) are seen first: a tap of
    # servo_angles made with them would be seen by then too
    for topic in ("/tf_static", "/robot_description"):
        assert wait_for((True, True), topic) == (True, True), f"{topic}: latched topics are always subscribed"
    assert tapped("/servo_angles") == (False, False), "subscribed with no Foxglove client"
    for round_ in range(2):  # and again: nothing is left behind by the first round
        fox = FoxgloveClient(port)
        try:
            assert fox.pump_until(lambda: fox.info and len(fox.channels) == len(TOPIC_TYPES))
            fox.subscribe("/servo_angles")
            assert wait_for((True, True)) == (True, True), f"round {round_}: no tap after the client subscribed"
        finally:
            fox.close()
        assert wait_for((False, False)) == (False, False), f"round {round_}: the tap outlived the client"
    assert "Foxglove WebSocket server on ws://127.0.0.1:" in gui.output()


def port_is_taken(port):
    """Whether another program listens on 127.0.0.1:`port` (we cannot bind it)."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server does: TIME_WAIT is no hold
        try:
            s.bind(("127.0.0.1", port))
        except OSError as e:
            if e.errno == errno.EADDRINUSE:
                return True
            raise
    return False


def test_the_foxglove_server_is_on_by_default_on_foxglove_s_port(launch, observer):
    web = free_port()
    # another program (a Foxglove bridge, a second panel, a test elsewhere on this host)
    # may hold the port: then gui_bridge says so and goes on without it
    taken = port_is_taken(8765)
    gui = launch("gui_bridge", "--ros-args", "-p", f"bind:=127.0.0.1:{web}")
    deadline = time.monotonic() + 10
    while "ready in ROS domain" not in gui.output() and time.monotonic() < deadline:
        time.sleep(0.1)
    out = gui.output()
    assert "ready in ROS domain" in out, out
    if taken:
        assert "Foxglove WebSocket server not started" in out, out
        assert port_is_taken(8765), "gui_bridge said the port was taken, and it is free"
        return
    assert "Foxglove WebSocket server on ws://127.0.0.1:8765" in out, out
    # and it is ours there: a client is advertised our channels
    fox = FoxgloveClient(8765)
    try:
        assert fox.pump_until(lambda: fox.info and len(fox.channels) == len(TOPIC_TYPES)), \
            (fox.info, sorted(fox.channels))
        assert {t: c["schemaName"] for t, c in fox.channels.items()} == TOPIC_TYPES
    finally:
        fox.close()
