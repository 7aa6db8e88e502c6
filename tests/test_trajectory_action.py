"""arm_controller and gripper_controller (issue 21) driven by real rclpy clients:
control_msgs' FollowJointTrajectory and GripperCommand actions, the
arm_controller/joint_trajectory topic and arm_controller/controller_state, against
compute_ik and serial_node on the virtual Arduino."""
import time

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

    def moving(self, feedback, start):
        """Spin until `feedback` (a feedback callback's list) shows the arm's desired
        position away from `start`: the goal is under way."""
        assert self.o.spin_until(lambda: any(max(abs(d - s) for d, s in zip(f.desired.positions, start)) > 0.01
                                             for f in feedback), 15), "no feedback showed the arm moving"

    def still(self, after):
        """The arm's commanded joints once the goal ended, which must hold still: `after`
        is time.time() once its result was in (compute_ik sends the result after its last
        step). compute_ik publishes joint_states only when they change, but
        controller_state comes with every servo_state, stamped by compute_ik's clock, the
        one the stamps here are on: three of them stamped after `after` must show one
        commanded pose (their output), and every joint_states stamped after `after` that
        pose too."""
        later = lambda: [m for _, m in self.controller_state if stamp_s(m.header.stamp) > after]  # noqa: E731
        assert self.o.spin_until(lambda: len(later()) >= 3, 10), "no controller_state after the goal ended"
        poses = {tuple(m.output.positions) for m in later()}
        assert len(poses) == 1, f"the arm kept moving after the goal ended: {sorted(poses)}"
        [pose] = poses
        moved = [self.joints(js) for _, js in self.joint_states if stamp_s(js.header.stamp) > after]
        assert all(max(abs(a - b) for a, b in zip(q, pose)) < 1e-9 for q in moved), (pose, moved)
        # (the last step's joint_states may come after the other topics' messages)
        assert self.o.spin_until(lambda: max(abs(a - b) for a, b in zip(self.joints(), pose)) < 1e-9, 10), \
            (pose, self.joints())
        return list(pose)

    def first_at(self, pose, since):
        """The stamp of the first joint_states after index `since` exactly at `pose`."""
        return next(stamp_s(js.header.stamp) for _, js in self.joint_states[since:]
                    if max(abs(a - b) for a, b in zip(self.joints(js), pose)) < 1e-9)


def stamp_s(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def near(q, p, tol=1e-9):
    return max(abs(a - b) for a, b in zip(q, p)) < tol


def nothing_sent_between(rig, t0, t1):
    """No servo_angles stamped between t0 and t1 (time.time()): judged once one stamped
    after t1 has come (one writer's messages arrive in order), from a goal sent after
    t1."""
    assert rig.o.spin_until(lambda: rig.servo_angles and stamp_s(rig.servo_angles[-1][1].header.stamp) > t1, 15), \
        "the goal sent afterwards moved nothing"
    return [m for _, m in rig.servo_angles if t0 < stamp_s(m.header.stamp) < t1] == []


def test_a_trajectory_goal_is_executed_over_its_duration_with_feedback_and_succeeds(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    mid = [start[0] + 0.2, start[1] + 0.1, start[2] - 0.1]
    end = [start[0] + 0.3, start[1] + 0.15, start[2] - 0.2]
    feedback = []
    goal = rig.goal([point(start, 0.0), point(mid, 0.8, [0.15, 0.08, -0.1]), point(end, 1.6, [0, 0, 0])])
    n0 = len(rig.joint_states)
    sent = time.time()
    handle = rig.send(goal, feedback=lambda f: feedback.append(f.feedback))
    assert handle.accepted
    res = rig.result(handle)
    ended = time.time()
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res
    assert res.result.error_code == Fjt.SUCCESSFUL
    # the commanded joints end exactly at the last point and hold there, having passed
    # through every point
    assert near(rig.still(ended), end)
    moved = [rig.joints(js) for _, js in rig.joint_states[n0:]]
    for p in (mid, end):
        assert min(max(abs(a - b) for a, b in zip(q, p)) for q in moved) < 0.03, p
    # over the trajectory's 1.6 s: compute_ik runs it on its clock, the one it stamps
    # joint_states with, from when the goal came (after `sent`), so no step before
    # 1.6 s after that is at the end
    assert rig.first_at(end, n0) - sent >= 1.6, "the trajectory's 1.6 s took less"
    # feedback: the controller's joints; desired, actual (servo_state) and their error
    assert len(feedback) >= 2
    f = feedback[-1]
    assert list(f.joint_names) == ARM
    assert len(f.desired.positions) == 3 and len(f.actual.positions) == 3
    assert all(abs(e - (d - a)) < 1e-9 for e, d, a in zip(f.error.positions, f.desired.positions, f.actual.positions))
    # servo_state reaches where the trajectory ends (the Arduino applied it)
    assert observer.spin_until(lambda: max(abs(a - b) for a, b in zip(rig.controller_state[-1][1].feedback.positions, end))
                               < 0.02, 10), rig.controller_state[-1][1].feedback.positions
    state = rig.controller_state[-1][1]
    assert list(state.joint_names) == ARM
    assert state.output.positions and max(abs(a - b) for a, b in zip(state.output.positions, end)) < 1e-9


def test_infeasible_goals_are_rejected_before_anything_moves(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    too_fast = rig.goal([point([start[0] + 0.5, start[1], start[2]], 0.1)])
    out_of_limits = rig.goal([point([start[0], start[1], 2.5], 3.0)])
    unknown_joint = rig.goal([point(start + [0.0], 1.0)], names=ARM + ["wrist_joint"])
    missing_joint = rig.goal([point(start[:2], 1.0)], names=ARM[:2])
    backwards = rig.goal([point(start, 1.0), point(start, 0.5)])
    t0 = time.time()
    for goal in (too_fast, out_of_limits, unknown_joint, missing_joint, backwards):
        assert not rig.send(goal).accepted, goal
    # nothing moved from the refusals until a good goal sent after them
    t1 = time.time()
    assert rig.send(rig.goal([point([start[0], start[1] + 0.05, start[2]], 0.5)])).accepted
    assert nothing_sent_between(rig, t0, t1), "a refused trajectory moved a servo"
    # the reason, with the joint and the limit, in diagnostics
    rig.send(too_fast)
    assert observer.spin_until(lambda: "limit" in status_values(latest_status(rig.diags, "compute_ik")).get("last_trajectory", ""), 5)
    text = status_values(latest_status(rig.diags, "compute_ik"))["last_trajectory"]
    assert "INVALID_GOAL" in text and "base servo" in text and "velocity limit" in text, text


# The goals the next tests stop halfway: 0.5 rad of the base in 20 s, so that however
# late a stop comes within the tests' deadlines, the arm is far from the goal.
FAR_S = 20.0


def test_cancel_stops_the_arm_where_it_is(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    goal = [start[0] + 0.5, start[1], start[2]]
    feedback = []
    handle = rig.send(rig.goal([point(goal, FAR_S)]), feedback=lambda f: feedback.append(f.feedback))
    assert handle.accepted
    rig.moving(feedback, start)
    fut = handle.cancel_goal_async()
    assert observer.spin_until(fut.done, 5)
    assert len(fut.result().goals_canceling) == 1
    res = rig.result(handle)
    assert res.status == GoalStatus.STATUS_CANCELED
    q = rig.still(time.time())
    # where it was when cancelled: past where the feedback had seen it, short of the goal
    assert start[0] + 0.01 < q[0] < goal[0] - 0.1, q


def test_a_new_goal_preempts_the_running_one(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    feedback = []
    first = rig.send(rig.goal([point([start[0] + 0.5, start[1], start[2]], FAR_S)]),
                     feedback=lambda f: feedback.append(f.feedback))
    rig.moving(feedback, start)
    q = rig.joints()
    target = [q[0], q[1] + 0.1, q[2]]
    second = rig.send(rig.goal([point(target, 1.0)]))
    assert first.accepted and second.accepted
    assert rig.result(first).status == GoalStatus.STATUS_CANCELED
    assert rig.result(second).status == GoalStatus.STATUS_SUCCEEDED
    assert near(rig.still(time.time()), target)


def test_estop_aborts_the_running_goal_and_refuses_new_ones(launch, observer):
    rig = Rig(launch, observer)
    start = rig.joints()
    feedback = []
    handle = rig.send(rig.goal([point([start[0] + 0.5, start[1], start[2]], FAR_S)]),
                      feedback=lambda f: feedback.append(f.feedback))
    observer.wait_matched(rig.estop)
    rig.moving(feedback, start)
    try:
        rig.estop.publish(Bool(data=True))
        res = rig.result(handle)
        assert res.status == GoalStatus.STATUS_ABORTED
        assert "emergency stop" in res.result.error_string
        q = rig.still(time.time())
        assert start[0] < q[0] < start[0] + 0.4, q
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
    rig.still(time.time())
    assert set_stalled_servos(observer, "").successful


def test_a_trajectory_on_the_topic_is_executed(launch, observer):
    rig = Rig(launch, observer)
    observer.wait_matched(rig.topic)
    start = rig.joints()
    end = [start[0] - 0.2, start[1], start[2] + 0.1]
    n0 = len(rig.joint_states)
    sent = time.time()
    rig.topic.publish(JointTrajectory(joint_names=ARM, points=[point(end, 1.0)]))
    assert observer.spin_until(lambda: near(rig.joints(), end), 5)
    # over its 1 s, on compute_ik's clock (its joint_states stamps), from when it came
    assert rig.first_at(end, n0) - sent >= 1.0, "the trajectory's 1 s took less"
    # a refused one moves nothing: judged once it was refused (diagnostics say so), by
    # the stamps of what a good one sent afterwards brings
    t0 = time.time()
    rig.topic.publish(JointTrajectory(joint_names=ARM, points=[point([0.0, 0.0, 9.0], 1.0)]))
    assert observer.spin_until(lambda: "refused (INVALID_GOAL)" in status_values(latest_status(rig.diags, "compute_ik"))
                               .get("last_trajectory", ""), 10), "the bad trajectory was not refused"
    t1 = time.time()
    rig.topic.publish(JointTrajectory(joint_names=ARM, points=[point(start, 1.0)]))
    assert nothing_sent_between(rig, t0, t1), "a refused trajectory moved a servo"


def test_the_gripper_action_opens_the_claw_and_refuses_out_of_range(launch, observer):
    rig = Rig(launch, observer)
    handle = rig.send(GripperCommand.Goal(command=GripperCommandMsg(position=0.5, max_effort=0.0)), rig.gripper)
    assert handle.accepted
    res = rig.result(handle)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res
    assert res.result.reached_goal and abs(res.result.position - 0.5) < 0.02, res.result
    gripper = lambda: rig.joint_states[-1][1].position[rig.joint_states[-1][1].name.index("gripper_joint")]  # noqa: E731
    assert observer.spin_until(lambda: abs(gripper() - 0.5) < 1e-9, 10), gripper()
    bad = GripperCommand.Goal(command=GripperCommandMsg(position=5.0))
    assert not rig.send(bad, rig.gripper).accepted
