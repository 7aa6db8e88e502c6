"""gui_bridge's MCAP recordings (`record FILE.mcap`, `play FILE.mcap`), read with the
`mcap` and `mcap-ros2-support` packages: the profile, every channel's ros2msg schema
and CDR encoding, message counts; and a recording played back, in order and restamped
(its pace is checked on a simulated clock by gui_bridge's unit test of `play`)."""
import os
import re
import signal
import subprocess
import threading

from geometry_msgs.msg import PointStamped
from mcap import reader as mcap_reader
from mcap_ros2 import decoder as mcap_ros2_decoder
from std_msgs.msg import Float64

from conftest import bin_path

RECORDED = {
    "/xyz_target": "geometry_msgs/msg/PointStamped",
    "/xyz_line_target": "geometry_msgs/msg/PointStamped",
    "/pose_target": "geometry_msgs/msg/PoseStamped",
    "/gripper_target": "std_msgs/msg/Float64",
    "/joint_target": "sensor_msgs/msg/JointState",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/robot_description": "std_msgs/msg/String",
    "/servo_state": "sensor_msgs/msg/JointState",
}
TARGETS = [(0.20, 0.00, 0.15), (0.18, 0.05, 0.12), (0.22, -0.04, 0.18)]
GAPS_S = [0.0, 0.6, 0.9]


def read(path):
    with open(path, "rb") as f:
        reader = mcap_reader.make_reader(f, decoder_factories=[mcap_ros2_decoder.DecoderFactory()])
        header, summary = reader.get_header(), reader.get_summary()
        messages = [(channel.topic, schema.name, message.log_time, ros)
                    for schema, channel, message, ros in reader.iter_decoded_messages()]
    return header, summary, messages


class Output:
    """A process's output lines, read as they come (a thread), so that a test can wait
    for a line while the process runs."""

    def __init__(self, proc):
        self.lines = []
        self.thread = threading.Thread(target=self._read, args=(proc.stdout,), daemon=True)
        self.thread.start()

    def _read(self, stream):
        for line in stream:
            self.lines.append(line)

    def has(self, text):
        return any(text in line for line in list(self.lines))

    def text(self):
        self.thread.join(15)
        return "".join(self.lines)

    def own(self):
        """Its own lines, not its libraries' (`[INFO] [stamp] [gui_bridge:rustdds::…]: …`
        at debug level)."""
        return "".join(line for line in list(self.lines) if not re.match(r"\[\w+\] \[[\d.]+\] \[[^\]]*:", line))


def record_session(launch, observer, domain, path):
    """Record compute_ik's motion through TARGETS (and one gripper target) into `path`;
    returns compute_ik's process (still running) and the recorder's output."""
    ik = launch("compute_ik")
    launch("state_publisher")
    observer.wait_publisher("/joint_states")
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    # at debug level the recorder says each target it has written
    rec = subprocess.Popen([bin_path("gui_bridge"), "record", str(path), "--ros-args", "--log-level", "debug"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    out = Output(rec)
    xyz = observer.pub("/xyz_target", PointStamped)
    grip = observer.pub("/gripper_target", Float64)
    # Two readers on each, compute_ik's and the recorder's, before the first target: our
    # writers send to the recorder from then on (reliable: a sample that reaches the
    # recorder's reader before that reader knows our writer is sent again on the
    # writer's next heartbeat).
    assert observer.spin_until(lambda: xyz.get_subscription_count() >= 2 and grip.get_subscription_count() >= 2, 30), \
        f"the recorder's subscriptions were not matched: {xyz.get_subscription_count()}, {grip.get_subscription_count()}"
    for (x, y, z), gap in zip(TARGETS, GAPS_S):
        observer.spin_for(gap)  # the pace being recorded (an input, not a verdict)
        m = PointStamped()
        m.header.frame_id = "base_link"
        m.point.x, m.point.y, m.point.z = x, y, z
        xyz.publish(m)
    grip.publish(Float64(data=0.5))
    # Ctrl-C once the recorder has written the last target and the gripper target (the
    # deadline only bounds a failure)
    last = [f"/xyz_target: sample {len(TARGETS)} recorded", "/gripper_target: sample 1 recorded"]
    reported = observer.spin_until(lambda: all(out.has(line) for line in last), 30)
    rec.send_signal(signal.SIGINT)
    rec.wait(15)
    assert reported, f"the recorder did not report {last}:\n{out.own()}"
    assert rec.returncode == 0, out.text()
    return ik, out.own()


def reported_counts(out):
    """The recorder's last line's count of each topic: `recorded N messages into F: /a 3, /b 0`."""
    line = next(line for line in out.splitlines() if line.startswith("recorded "))
    return {topic: int(n) for topic, n in (item.split(" ") for item in line.split(": ", 1)[1].split(", "))}


def test_record_writes_ros2msg_schemas_and_cdr_that_the_mcap_packages_read(launch, observer, domain, tmp_path):
    path = tmp_path / "run.mcap"
    _, out = record_session(launch, observer, domain, path)
    header, summary, messages = read(path)
    assert header.profile == "ros2"
    channels = {c.topic: c for c in summary.channels.values()}
    assert set(channels) == set(RECORDED)
    for topic, type_name in RECORDED.items():
        c = channels[topic]
        schema = summary.schemas[c.schema_id]
        assert (c.message_encoding, schema.name, schema.encoding) == ("cdr", type_name, "ros2msg"), topic
    counts = {}
    for topic, _, _, _ in messages:
        counts[topic] = counts.get(topic, 0) + 1
    assert counts["/xyz_target"] == len(TARGETS)
    assert counts["/gripper_target"] == 1
    assert counts["/robot_description"] == 1
    assert counts["/tf_static"] >= 1
    assert counts["/joint_states"] > 10 and counts["/tf"] > 10
    assert summary.statistics.message_count == len(messages)
    # what it says it recorded is what the file holds
    assert reported_counts(out) == {topic: counts.get(topic, 0) for topic in RECORDED}, out
    xyz = [(round(m.point.x, 4), round(m.point.y, 4), round(m.point.z, 4))
           for topic, _, _, m in messages if topic == "/xyz_target"]
    assert xyz == TARGETS
    urdf = next(m for topic, _, _, m in messages if topic == "/robot_description")
    assert "<robot" in urdf.data


def test_play_republishes_the_recorded_targets_in_order_restamped(launch, observer, domain, tmp_path):
    path = tmp_path / "run.mcap"
    ik, _ = record_session(launch, observer, domain, path)
    _, _, messages = read(path)
    recorded_times = [t for topic, _, t, _ in messages if topic == "/xyz_target"]
    # `play` waits for a subscriber of xyz_target before its first target: with
    # compute_ik gone, that subscriber is our reader.
    assert ik.stop() == 0, ik.output()

    got = observer.sub("/xyz_target", PointStamped)
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    play = subprocess.Popen([bin_path("gui_bridge"), "play", str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env)
    observer.spin_until(lambda: play.poll() is not None, 60)
    out, _ = play.communicate(timeout=10)
    assert play.returncode == 0, out
    assert observer.spin_until(lambda: len(got) >= len(TARGETS), 10), f"{len(got)} of {len(TARGETS)} targets arrived"
    assert [(round(m.point.x, 4), round(m.point.y, 4), round(m.point.z, 4)) for _, m in got] == TARGETS
    # Stamped anew when played: later than the recording took them (a player that kept
    # the recorded stamps, older than their log times, fails here).
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in got]
    assert all(s > recorded_times[-1] for s in stamps), f"not restamped: {stamps} vs recorded at {recorded_times}"
    assert stamps == sorted(stamps), stamps
