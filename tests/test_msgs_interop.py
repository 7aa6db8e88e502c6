"""Byte-for-byte check of eezybot_msgs against real ROS 2 serialization, both ways.

rclpy's serialize_message (Fast CDR, from the ROS 2 wheels), or Cyclone DDS for
tf2_msgs/TFMessage, against our structs as ros2-client serializes them.
"""
import subprocess

import pytest

from conftest import bin_path
from interop.cases import cases
from interop.cdr import canonical, deserialize, padding_mask, serialize

CASES = cases()


@pytest.fixture(scope="module")
def rust_vectors():
    out = subprocess.run([bin_path("examples/cdr_vectors"), "encode"], check=True, capture_output=True, text=True,
                         timeout=60).stdout
    vectors = {}
    for line in out.splitlines():
        name, ros_type, hexbytes = line.split(" ")
        vectors[name] = (ros_type, bytes.fromhex(hexbytes))
    return vectors


def test_both_sides_have_the_same_cases(rust_vectors):
    assert sorted(rust_vectors) == sorted(name for name, _ in CASES)


@pytest.mark.parametrize("name,msg", CASES, ids=[c[0] for c in CASES])
def test_rust_bytes_equal_ros2_bytes(rust_vectors, name, msg):
    ros_type, ours = rust_vectors[name]
    theirs = serialize(msg)
    pad, length = padding_mask(msg)
    # Fast CDR hands back its whole buffer: the CDR stream, then slack up to its size
    # estimate (Bool: 1 byte of data in 4). The slack is not part of the message.
    assert len(theirs) >= length, "padding model disagrees with the ROS 2 serializer"
    theirs = theirs[:length]
    assert len(ours) == length, f"{name}: {len(ours)} bytes, the CDR stream has {length}"
    diffs = [i for i in range(len(ours)) if i not in pad and ours[i] != theirs[i]]
    assert not diffs, f"{name} ({ros_type}) differs at bytes {diffs}:\n ours   {ours.hex()}\n theirs {theirs.hex()}"
    assert all(ours[i] == 0 for i in pad), "ros2-client writes zero padding"


@pytest.mark.parametrize("name,msg", CASES, ids=[c[0] for c in CASES])
def test_ros2_decodes_rust_bytes_to_the_same_value(rust_vectors, name, msg):
    _, ours = rust_vectors[name]
    decoded = deserialize(ours, msg)
    assert canonical(decoded) == canonical(msg)


def test_rust_decodes_ros2_bytes_to_the_same_value():
    lines = "".join(f"{name} {serialize(msg).hex()}\n" for name, msg in CASES)
    out = subprocess.run([bin_path("examples/cdr_vectors"), "decode"], input=lines, check=True, capture_output=True, text=True,
                         timeout=60).stdout
    verdicts = dict(line.split(" ", 1) for line in out.splitlines())
    assert set(verdicts) == {name for name, _ in CASES}
    bad = {k: v for k, v in verdicts.items() if v != "OK"}
    assert not bad, bad
