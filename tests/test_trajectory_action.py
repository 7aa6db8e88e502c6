"""arm_controller and gripper_controller (issue 21) driven by real rclpy clients:
control_msgs' FollowJointTrajectory and GripperCommand actions, the
arm_controller/joint_trajectory topic and arm_controller/controller_state, against
compute_ik and serial_node on the virtual Arduino."""
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory, GripperCommand
from control_msgs.msg import GripperCommand as GripperCommandMsg
from control_msgs.msg import JointTolerance, JointTrajectoryControllerState
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.action import ActionClient
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from conftest import COMMANDS, status_values, latest_status
from test_serial_node import set_stalled_servos

ARM = ["base_joint", "shoulder_joint", "elbow_joint"]
Fjt = FollowJointTrajectory.Result


def duration(s):
    return Duration(sec=int(s), nanosec=int(round((s - int(s)) * 1e9)))


def point(positions, t, velocities=()):
    return JointTrajectoryPoint(positions=list(positions), velocities=list(velocities), time_from_start=duration(t))


class Rig:
    """compute_ik and serial_node (port mock), an rclpy ActionClient for each action,
    and subscriptions to what comes out."""

    def __init__(self, launch, observer, *ik_args):
        self.o = observer
        self.ik = launch("compute_ik", "--ros-args", "-p", "max_target_age:=0.0", *ik_args)
        self.serial = launch("serial_node", "--ros-args", "-p", "port:=mock")
        self.joint_states = observer.sub("joint_states", JointState)
        self.servo_state = observer.sub("servo_state", JointState)
        self.servo_angles = observer.sub("servo_angles", JointState)
        self.controller_state = observer.sub("arm_controller/controller_state", JointTrajectoryControllerState, COMMANDS)
        self.diags = observer.sub("diagnostics", DiagnosticArray)
        self.arm = ActionClient(observer.node, FollowJointTrajectory, "arm_controller/follow_joint_trajectory")
        self.gripper = ActionClient(observer.node, GripperCommand, "gripper_controller/gripper_cmd")
        self.topic = observer.pub("arm_controller/joint_trajectory", JointTrajectory, COMMANDS)
        self.estop = observer.pub("estop", Bool)
        assert observer.spin_until(lambda: self.arm.server_is_ready() and self.gripper.server_is_ready(), 15), \
            "the action servers were not discovered"
        assert observer.spin_until(lambda: self.joint_states and self.servo_state, 10)

    def joints(self, js=None):
        """The arm joints of a joint_states message (the latest by default)."""
        js = js if js is not None else self.joint_states[-1][1]
        return [js.position[js.name.index(n)] for n in ARM]

    def send(self, goal, client=None, feedback=None):
        """Send a goal; the goal handle once answered."""
        client = client or self.arm
        fut = client.send_goal_async(goal, feedback_callback=feedback)
        assert self.o.spin_until(fut.done, 10), "the goal was not answered"
        return fut.result()

    def result(self, handle, timeout=15):
        fut = handle.get_result_async()
        assert self.o.spin_until(fut.done, timeout), "no result"
        return fut.result()

    def goal(self, points, names=ARM, **kw):
        return FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=list(names), points=points), **kw)

    def still(self, seconds=0.3):
        """Whether joint_states stopped changing (no new message, or the same pose), once
        what was in flight when the goal ended has arrived."""
        self.o.spin_for(0.1)
        n = len(self.joint_states)
        self.o.spin_for(seconds)
        return all(self.joints(js) == self.joints(self.joint_states[n - 1][1]) for _, js in self.joint_states[n - 1:])


def test_a_trajectory_goal_is_executed_in_time_with_feedback_and_succeeds(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    mid = [start[0] + 0.2, start[1] + 0.1, start[2] - 0.1]
    end = [start[0] + 0.3, start[1] + 0.15, start[2] - 0.2]
    feedback = []
    goal = rig.goal([point(start, 0.0), point(mid, 0.8, [0.15, 0.08, -0.1]), point(end, 1.6, [0, 0, 0])])
    n0 = len(rig.joint_states)
    handle = rig.send(goal, feedback=lambda f: feedback.append(f.feedback))
    assert handle.accepted
    res = rig.result(handle)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res
    assert res.result.error_code == Fjt.SUCCESSFUL
    # the commanded joints pass through every point and end exactly at the last one
    observer.spin_for(0.2)
    moved = [rig.joints(js) for _, js in rig.joint_states[n0:]]
    for p in (mid, end):
        assert min(max(abs(a - b) for a, b in zip(q, p)) for q in moved) < 0.03, p
    assert max(abs(a - b) for a, b in zip(moved[-1], end)) < 1e-9
    # feedback: the controller's joints; desired, actual (servo_state) and their error
    assert len(feedback) > 10
    f = feedback[-1]
    assert list(f.joint_names) == ARM
    assert len(f.desired.positions) == 3 and len(f.actual.positions) == 3
    assert all(abs(e - (d - a)) < 1e-9 for e, d, a in zip(f.error.positions, f.desired.positions, f.actual.positions))
    # servo_state ends where the trajectory does (the Arduino applied it)
    observer.spin_for(0.3)
    state = rig.controller_state[-1][1]
    assert list(state.joint_names) == ARM
    assert max(abs(a - b) for a, b in zip(state.feedback.positions, end)) < 0.02, state.feedback.positions
    assert state.output.positions and max(abs(a - b) for a, b in zip(state.output.positions, end)) < 1e-9


def test_infeasible_goals_are_rejected_before_anything_moves(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    observer.spin_for(0.3)
    n_angles = len(rig.servo_angles)
    too_fast = rig.goal([point([start[0] + 0.5, start[1], start[2]], 0.1)])
    out_of_limits = rig.goal([point([start[0], start[1], 2.5], 3.0)])
    unknown_joint = rig.goal([point(start + [0.0], 1.0)], names=ARM + ["wrist_joint"])
    missing_joint = rig.goal([point(start[:2], 1.0)], names=ARM[:2])
    backwards = rig.goal([point(start, 1.0), point(start, 0.5)])
    for goal in (too_fast, out_of_limits, unknown_joint, missing_joint, backwards):
        assert not rig.send(goal).accepted, goal
    observer.spin_for(0.3)
    assert len(rig.servo_angles) == n_angles, "a refused trajectory moved a servo"
    # the reason, with the joint and the limit, in diagnostics
    rig.send(too_fast)
    assert observer.spin_until(lambda: "limit" in status_values(latest_status(rig.diags, "compute_ik")).get("last_trajectory", ""), 5)
    text = status_values(latest_status(rig.diags, "compute_ik"))["last_trajectory"]
    assert "INVALID_GOAL" in text and "base servo" in text and "velocity limit" in text, text


def test_cancel_stops_the_arm_where_it_is(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    handle = rig.send(rig.goal([point([start[0] + 0.5, start[1], start[2]], 3.0)]))
    assert handle.accepted
    observer.spin_for(0.6)
    fut = handle.cancel_goal_async()
    assert observer.spin_until(fut.done, 5)
    assert len(fut.result().goals_canceling) == 1
    res = rig.result(handle)
    assert res.status == GoalStatus.STATUS_CANCELED
    q = rig.joints()
    assert start[0] + 0.02 < q[0] < start[0] + 0.45, q
    assert rig.still()


def test_a_new_goal_preempts_the_running_one(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    first = rig.send(rig.goal([point([start[0] + 0.5, start[1], start[2]], 3.0)]))
    observer.spin_for(0.5)
    q = rig.joints()
    target = [q[0], q[1] + 0.1, q[2]]
    second = rig.send(rig.goal([point(target, 1.0)]))
    assert first.accepted and second.accepted
    assert rig.result(first).status == GoalStatus.STATUS_CANCELED
    assert rig.result(second).status == GoalStatus.STATUS_SUCCEEDED
    observer.spin_for(0.2)
    assert max(abs(a - b) for a, b in zip(rig.joints(), target)) < 1e-9


def test_estop_aborts_the_running_goal_and_refuses_new_ones(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    handle = rig.send(rig.goal([point([start[0] + 0.5, start[1], start[2]], 3.0)]))
    observer.wait_matched(rig.estop)
    observer.spin_for(0.4)
    try:
        rig.estop.publish(Bool(data=True))
        res = rig.result(handle)
        assert res.status == GoalStatus.STATUS_ABORTED
        assert "emergency stop" in res.result.error_string
        assert rig.still()
        assert not rig.send(rig.goal([point(start, 1.0)])).accepted
    finally:
        rig.estop.publish(Bool(data=False))
        observer.spin_for(0.3)


def test_a_blocked_servo_violates_the_path_tolerance(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    assert set_stalled_servos(observer, "elbow_servo").successful
    tol = [JointTolerance(name="elbow_joint", position=0.05)]
    end = [start[0], start[1], start[2] - 0.4]
    handle = rig.send(rig.goal([point(end, 2.0)], path_tolerance=tol))
    assert handle.accepted, status_values(latest_status(rig.diags, "compute_ik")).get("last_trajectory")
    res = rig.result(handle)
    assert res.status == GoalStatus.STATUS_ABORTED
    assert res.result.error_code == Fjt.PATH_TOLERANCE_VIOLATED, res.result
    assert "elbow_joint" in res.result.error_string
    assert rig.still()
    assert set_stalled_servos(observer, "").successful


def test_a_trajectory_on_the_topic_is_executed(launch, observer):
    rig = Rig(launch, observer)
    observer.wait_matched(rig.topic)
    start = rig.joints()
    end = [start[0] - 0.2, start[1], start[2] + 0.1]
    n0 = len(rig.joint_states)
    rig.topic.publish(JointTrajectory(joint_names=ARM, points=[point(end, 1.0)]))
    assert observer.spin_until(lambda: max(abs(a - b) for a, b in zip(rig.joints(), end)) < 1e-9, 5)
    times = [t for t, js in rig.joint_states[n0:]]
    assert times[-1] - times[0] > 0.8, "the trajectory's 1 s took no time"
    # a refused one changes nothing
    observer.spin_for(0.3)
    n = len(rig.servo_angles)
    rig.topic.publish(JointTrajectory(joint_names=ARM, points=[point([0.0, 0.0, 9.0], 1.0)]))
    observer.spin_for(0.5)
    assert len(rig.servo_angles) == n


def test_the_gripper_action_opens_the_claw_and_refuses_out_of_range(launch, observer):
    rig = Rig(launch, observer)
    handle = rig.send(GripperCommand.Goal(command=GripperCommandMsg(position=0.5, max_effort=0.0)), rig.gripper)
    assert handle.accepted
    res = rig.result(handle)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res
    assert res.result.reached_goal and abs(res.result.position - 0.5) < 0.02, res.result
    observer.spin_for(0.2)
    js = rig.joint_states[-1][1]
    assert abs(js.position[js.name.index("gripper_joint")] - 0.5) < 1e-9
    bad = GripperCommand.Goal(command=GripperCommandMsg(position=5.0))
    assert not rig.send(bad, rig.gripper).accepted
