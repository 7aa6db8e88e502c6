"""RTPS-level interoperability of our nodes (RustDDS, patches/rustdds) with the two DDS
implementations ROS 2 users run: Fast DDS (rclpy's default RMW) and Cyclone DDS
(rmw_cyclonedds_cpp).

- A Cyclone DDS application that talks to our nodes prints nothing about them: RustDDS'
  pre-emptive ACKNACK with sequence-number base 0 (the form Fast DDS needs) was dropped
  by Cyclone DDS as a malformed packet, one stderr line per matched writer, in every
  Cyclone DDS application on the network (patches/README.md, rustdds entry 11).
- What `ros2 topic pub --once` does (a new participant publishes one sample as soon as
  it is matched, then leaves) reaches compute_ik every time: Fast DDS answers our reader's
  pre-emptive ACKNACK with a HEARTBEAT at once only in that base-0 form (entry 6), and
  ignores a request for a sample it sent a moment before, so our reader repeats it
  (entry 18).
"""
import os
import subprocess
import sys
import textwrap
import time

from geometry_msgs.msg import PointStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from conftest import Observer

CYCLONE_READER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, sys.argv[2])
    from conftest import TfListener
    tf = TfListener(int(sys.argv[1]))
    print("ready", flush=True)
    end = time.monotonic() + 15
    while time.monotonic() < end and not ("tool0" in tf.static and "main_arm" in tf.dynamic):
        tf.poll()
        time.sleep(0.05)
    time.sleep(1.0)  # what each side sends after matching (ACKNACKs, HEARTBEATs)
    tf.poll()
    print(len(tf.static), len(tf.dynamic))
""")


def test_a_cyclone_dds_reader_of_our_tf_prints_no_malformed_packets(launch, observer, domain):
    # The nodes first: a Cyclone DDS reader started before them found neither of them
    # within 15 s in a full test run (its own announcements come at its start, and are
    # then seldom). tf is volatile and
    # comes only when the arm moves (and for about a second after state_publisher
    # starts), so targets keep it coming until the reader, however late it matches on a
    # busy host, has seen it.
    launch("compute_ik")
    launch("state_publisher")
    reader = subprocess.Popen([sys.executable, "-c", CYCLONE_READER, str(domain), os.path.dirname(__file__)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert reader.stdout.readline().strip() == "ready", reader.stderr.read()[-2000:]
        targets = observer.pub("/xyz_target", PointStamped)
        end, i = time.monotonic() + 60, 0
        while reader.poll() is None and time.monotonic() < end:
            i += 1
            m = PointStamped()
            m.header.frame_id = "base_link"
            m.point.x, m.point.y, m.point.z = 0.2, 0.02 * (i % 2), 0.15
            targets.publish(m)
            observer.spin_until(lambda: reader.poll() is not None, 0.3)
        stdout, stderr = reader.communicate(timeout=10)
    finally:
        if reader.poll() is None:
            reader.kill()
            reader.wait()
    run = subprocess.CompletedProcess(reader.args, reader.returncode, stdout, stderr)
    assert run.returncode == 0, run.stderr[-2000:]
    static, dynamic = (int(x) for x in run.stdout.split())
    assert static > 0 and dynamic > 0, (run.stdout, run.stderr[-2000:])
    malformed = [line for line in run.stderr.splitlines() if "malformed packet" in line]
    assert not malformed, f"{len(malformed)} lines, e.g. {malformed[0]}"


# How long a one-shot publisher stays after publishing. Its sample usually reaches
# compute_ik before compute_ik has matched its writer (Fast DDS matches our reader first,
# and publishes at once), so it comes by repair, once our reader has the writer's
# discovery data. When that data is a late joiner's repair too, Fast DDS sends it 100 ms
# after our request at the soonest (edp_nack_response_delay), and 300-400 ms later under
# load (tshark of 600 trials with both cores busy: 2 lost of 600 at 0.3 s, 0 of 400 at
# 1 s). A sample Fast DDS ignores our first request for is repaired by the repetition 25
# or 75 ms later (entry 18), else only by its next periodic HEARTBEAT, 3 s later.
# Publish -> joint_states with the target's stamp, beside two busy loops (120 samples,
# 2026-11-29): p50 59 ms, p99 288 ms, max 349 ms, so 1 s keeps 3.5x over the p99.
ONE_SHOT_STAYS_S = 1.0


def test_one_sample_from_a_fresh_fast_dds_publisher_that_leaves_reaches_compute_ik(launch, observer, domain):
    """Ten times: a new rclpy participant publishes one target as soon as compute_ik's
    reader is matched and is gone ONE_SHOT_STAYS_S later, as `ros2 topic pub --once` is
    (it publishes once it sees a subscription, and exits soon after)."""
    launch("compute_ik")
    # every step of every motion (compute_ik streams 50 a second): the stamps we look for
    # are the first ones
    joints = observer.sub("/joint_states", JointState, QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    observer.wait_publisher("/joint_states")
    sent = []
    for i in range(10):
        once = Observer(domain, name=f"once_{i}")
        try:
            pub = once.pub("/xyz_target", PointStamped)
            assert once.spin_until(lambda: pub.get_subscription_count() > 0, Observer.MATCH_TIMEOUT)
            m = PointStamped()
            m.header.frame_id = "base_link"
            t = time.time()
            m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
            m.point.x, m.point.y, m.point.z = 0.2, 0.02 * (i % 3 - 1), 0.15
            published = time.monotonic()
            pub.publish(m)
            sent.append(((m.header.stamp.sec, m.header.stamp.nanosec), published))
            observer.spin_for(ONE_SHOT_STAYS_S)  # the publisher's DDS threads deliver meanwhile
        finally:
            once.close()
    # compute_ik's first step of each motion carries the target's stamp
    def received():
        stamps = {(j.header.stamp.sec, j.header.stamp.nanosec) for _, j in joints}
        return [s for s, _ in sent if s not in stamps]
    observer.spin_until(lambda: not received(), 10)
    assert not received(), f"{len(received())} of {len(sent)} never reached compute_ik"
    # ONE_SHOT_STAYS_S is a requirement with a bound: printed for the benchmark table, the
    # time from the publish to the joint_states carrying its stamp (an upper bound of the
    # time the sample took to reach compute_ik)
    first = {}
    for t, j in joints:
        first.setdefault((j.header.stamp.sec, j.header.stamp.nanosec), t)
    waits = sorted(first[s] - published for s, published in sent)
    print(f"\npublish -> joint_states with its stamp, ms: {' '.join(f'{w * 1e3:.0f}' for w in waits)}")
