#!/usr/bin/env python3
"""The seed's compute_IK node (the ROS 1 Python original, ../shared/seeds/002_*.txt,
section 3.3, 3.4 and 4.2), written again for rclpy so that it runs in the same benchmark
harness as our compute_ik (tests/bench/e2e.py --case f, g). Its printxyz.py is not in
the report; this follows the report's equations and what it says of the program:

* IK (report eq. 3.1-3.7, lengths in mm as the report's 147 and 135):
    c = sqrt(x^2 + y^2), s = sqrt(x^2 + y^2 + z^2)           (s from the base origin)
    th1 = acos(y / c)                                          (base, from +y, sign lost)
    th2 = acos(c / s)
    th3 = acos((147^2 - s^2 - 135^2) / (-2 s 135))
    th4 = 90 - th2 - th3                                       (main arm)
    th6 = acos((s^2 - 147^2 - 135^2) / (-2 147 135))
    th7 = 90 - th6
    th5 = th4 - th7                                            (forearm / "V-arm")
    open-chain joints: th12 = 90 - th6 (chain 4)
  No reach check: a target for which an acos argument leaves [-1, 1] (or c = 0) raises,
  as in the original; rospy logs a callback's exception and goes on, and so does this
  node (one stderr line, no output for that target).
* "All the nodes are set to publish ... at a maximum frequency of 10Hz" (section 4.2.1).
  `--cap loop` (default): the usual rospy loop, `rate = rospy.Rate(10)`, publishing the
  newest result each cycle: a 10 Hz timer publishes the result of the newest target if
  one arrived since the last cycle (the rospy loop would republish the same values every
  cycle; not repeating them changes nothing the benchmark measures). `--cap gate`: the
  other reading of the report (its measured ~1 ms from receive to publish): compute and
  publish in the callback, but drop a target that comes less than 0.1 s after the last
  one published.
* "The data ... rounded down to 4 decimal points" (section 4.2.2, ROBOT.md: "its data
  link kept only 4 decimals of the joint values"): every published value is
  round(value, 4), in radians.
* Topics: the harness's names and types (xyz_target in metres -> mm; joint_states and
  servo_angles as sensor_msgs/JointState, standing for the seed's /joint_states and
  /Ard_angle). The header stamp is copied from the target (the seed stamped at publish
  time, which would hide the wait for the 10 Hz cycle from the harness).

    python tests/bench/seed_ik_node.py [--cap loop|gate]   (ROS_DOMAIN_ID from the environment)
"""
import math
import sys

SERVO_NAMES = ["base_servo", "shoulder_servo", "elbow_servo", "gripper_servo"]
JOINT_NAMES = ["base_joint", "shoulder_joint", "elbow_joint", "chain4_joint"]
RATE_HZ = 10.0
DECIMALS = 4


def seed_equations(x_m, y_m, z_m):
    """The seed's joint variables in degrees: (th1, th4, th5, th12). Raises ValueError
    (acos outside [-1, 1]) or ZeroDivisionError (c = 0 or s = 0) as the original did."""
    x, y, z = x_m * 1000.0, y_m * 1000.0, z_m * 1000.0
    c = math.sqrt(x ** 2 + y ** 2)
    s = math.sqrt(x ** 2 + y ** 2 + z ** 2)
    th1 = math.degrees(math.acos(y / c))
    th2 = math.degrees(math.acos(c / s))
    th3 = math.degrees(math.acos((147 ** 2 - s ** 2 - 135 ** 2) / (-2 * s * 135)))
    th4 = 90 - th2 - th3
    th6 = math.degrees(math.acos((s ** 2 - 147 ** 2 - 135 ** 2) / (-2 * 147 * 135)))
    th7 = 90 - th6
    th5 = th4 - th7
    th12 = 90 - th6
    return th1, th4, th5, th12


def seed_outputs(x_m, y_m, z_m):
    """(servo_angles, joint_states) positions as the seed node publishes them, before the
    4-decimal rounding: radians. The seed's /Ard_angle mapping to servo degrees is not in
    the report; its three joint variables stand for the servo angles, claw closed."""
    th1, th4, th5, th12 = seed_equations(x_m, y_m, z_m)
    servo = [math.radians(th1), math.radians(th4), math.radians(th5), math.radians(60.0)]
    joints = [math.radians(th1), math.radians(th4), math.radians(th5), math.radians(th12)]
    return servo, joints


def main():
    import argparse
    import time

    import rclpy
    from geometry_msgs.msg import PointStamped
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from rclpy_main import spinning

    ap = argparse.ArgumentParser()
    ap.add_argument("--cap", choices=["loop", "gate"], default="loop")
    args, ros_args = ap.parse_known_args()
    rclpy.init(args=[sys.argv[0], *ros_args])
    node = rclpy.create_node("seed_compute_ik")
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    pub_servo = node.create_publisher(JointState, "servo_angles", qos)
    pub_joints = node.create_publisher(JointState, "joint_states", qos)
    newest = []  # [PointStamped] not yet published
    errors = [0]
    last_published = [-1e9]

    def on_target(msg):
        newest[:] = [msg]
        if args.cap == "gate":
            if time.monotonic() - last_published[0] >= 1.0 / RATE_HZ:
                cycle()
            newest.clear()

    def cycle():
        if not newest:
            return
        msg = newest.pop()
        try:
            servo, joints = seed_outputs(msg.point.x, msg.point.y, msg.point.z)
        except (ValueError, ZeroDivisionError) as e:  # rospy: logged, the node goes on
            errors[0] += 1
            sys.stderr.write(f"[seed_compute_ik] callback error for ({msg.point.x}, {msg.point.y}, {msg.point.z}): {e}\n")
            return
        for pub, names, values in ((pub_servo, SERVO_NAMES, servo), (pub_joints, JOINT_NAMES, joints)):
            out = JointState(name=names, position=[round(v, DECIMALS) for v in values])
            out.header.stamp = msg.header.stamp
            pub.publish(out)
        last_published[0] = time.monotonic()

    node.create_subscription(PointStamped, "xyz_target", on_target, qos)
    if args.cap == "loop":
        node.create_timer(1.0 / RATE_HZ, cycle)
    with spinning(node):
        rclpy.spin(node)
    sys.stderr.write(f"[seed_compute_ik] {errors[0]} targets failed in the seed's equations\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
