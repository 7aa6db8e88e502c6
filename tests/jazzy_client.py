"""A ROS 2 Jazzy user (rclpy 7.x, Fast DDS 2.14) of our graph: run by the Jazzy venv's
Python (EEZYBOT_JAZZY_PYTHON, launch_scripts/setup_env.sh), driven by
tests/test_jazzy.py, which runs under Kilted and checks what this prints. Imports
nothing of the tests that needs pytest or Kilted.

    python tests/jazzy_client.py --domain N graph --expect NODE... [--endpoints JSON] [--timeout S]
    python tests/jazzy_client.py --domain N target --xyz X Y Z --expect-deg B S E G [--timeout S]
    python tests/jazzy_client.py --domain N params --node NAME [--get PARAM...] [--timeout S]
    python tests/jazzy_client.py --domain N trajectory --move RAD [--timeout S]

Prints one JSON line: what rclpy saw (node names and each node's endpoints; the
joint_states, servo_angles and servo_state a target caused; what the parameter
services answered; what the FollowJointTrajectory action answered)."""
import argparse
import importlib.metadata
import json
import math
import sys
import time
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

# The topic contract (libs/ros_plumbing/src/topics.rs, generated into tests/data).
TOPICS = {t["name"]: t for t in json.loads(
    (Path(__file__).resolve().parent / "data" / "topics.json").read_text())["topics"]}


def qos(topic):
    t = TOPICS[topic.rsplit("/", 1)[-1]]
    return QoSProfile(
        depth=t["depth"],
        reliability={"reliable": ReliabilityPolicy.RELIABLE, "best effort": ReliabilityPolicy.BEST_EFFORT}[t["reliability"]],
        durability={"volatile": DurabilityPolicy.VOLATILE, "transient-local": DurabilityPolicy.TRANSIENT_LOCAL}[t["durability"]],
    )


class Client:
    def __init__(self, domain):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("jazzy_user", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, predicate, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.02)
        return predicate()

    def spin_for(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.02, max(0.0, end - time.monotonic())))

    def wait(self, future, timeout):
        if not self.spin_until(future.done, timeout):
            raise TimeoutError("no answer")
        return future.result()

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def graph(c, a):
    """The node list once every --expect node is in it, and each of those nodes'
    endpoints once each of --endpoints (JSON [[node, "pub"|"sub", topic, type], ...]) is
    there (or at the timeout: the test says what is missing)."""
    t0 = time.monotonic()
    wanted = json.loads(a.endpoints)

    def names():
        return c.node.get_node_names_and_namespaces()

    def endpoints():
        out = {}
        for n, ns in names():
            if n in a.expect:
                out[n] = {
                    "pub": {t: ty for t, ty in c.node.get_publisher_names_and_types_by_node(n, ns)},
                    "sub": {t: ty for t, ty in c.node.get_subscriber_names_and_types_by_node(n, ns)},
                }
        return out

    def complete():
        e = endpoints()
        return all(node in e and e[node][kind].get(topic) == [ty] for node, kind, topic, ty in wanted)

    c.spin_until(lambda: set(a.expect) <= {n for n, _ in names()}, a.timeout)
    listed_s = time.monotonic() - t0
    c.spin_until(complete, max(1.0, a.timeout - listed_s))
    return {"nodes": sorted([n, ns] for n, ns in names()), "listed_s": listed_s,
            "endpoints_s": time.monotonic() - t0, "endpoints": endpoints()}


def target(c, a):
    """Publish one xyz_target stamped now; the first servo_angles it causes and the
    joint_states of that step (which carry its stamp), the last of each once the motion
    has ended (a servo_angles equal to --expect-deg, the servo angles the test knows the
    target's IK puts the arm at), and the servo_state the device answered that step
    with (it carries the step's stamp) once within --device-tol-deg of it."""
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import JointState

    got = {t: [] for t in ("joint_states", "servo_angles", "servo_state")}
    for t in got:
        # every sample kept until taken (the contract's depth of 10 is 0.2 s of steps)
        deep = qos(t)
        deep.depth = 10_000
        c.node.create_subscription(JointState, f"/{t}", lambda m, t=t: got[t].append(m), deep)
    pub = c.node.create_publisher(PointStamped, "/xyz_target", qos("xyz_target"))
    if not c.spin_until(lambda: pub.get_subscription_count() > 0
                        and all(c.node.count_publishers(f"/{t}") > 0 for t in got), a.timeout):
        return {"error": f"not matched: xyz_target subscribers {pub.get_subscription_count()}, "
                         f"publishers {[(t, c.node.count_publishers('/' + t)) for t in got]}"}
    c.spin_for(0.3)  # the remote readers match us too
    msg = PointStamped()
    msg.header.frame_id = "base_link"
    now = time.time()
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
    msg.point.x, msg.point.y, msg.point.z = a.xyz
    stamp = [msg.header.stamp.sec, msg.header.stamp.nanosec]
    n = {t: len(ms) for t, ms in got.items()}
    pub.publish(msg)
    def stamp_of(m):
        return [m.header.stamp.sec, m.header.stamp.nanosec]

    def step_js(sa):
        # the joint_states of a step: its stamp (compute_ik also greets a new
        # joint_states reader with the pose, so they are not counted)
        js = [m for m in got["joint_states"][n["joint_states"]:] if stamp_of(m) == stamp_of(sa)]
        return js[-1] if js else None

    if not c.spin_until(lambda: len(got["servo_angles"]) > n["servo_angles"]
                        and step_js(got["servo_angles"][n["servo_angles"]]), a.timeout):
        return {"error": "no joint_states/servo_angles for the target"}
    first_sa = got["servo_angles"][n["servo_angles"]]

    # the motion's end: a step at the expected angles (the planner may publish it twice,
    # its velocity coming to 0 a step after its position: either is the end)
    def final_steps():
        return [m for m in got["servo_angles"][n["servo_angles"]:]
                if all(abs(math.degrees(p) - e) <= 1e-9 for p, e in zip(m.position, a.expect_deg))]

    def replied():
        # the device's state answering a step from the one that arrived on (its stamp,
        # or a later one's: the last step may come twice), once the servos got there: it
        # reports where they are, and they move on after the last command
        arrived = stamp_of(final_steps()[0])
        return [m for m in got["servo_state"] if stamp_of(m) >= arrived
                and all(abs(math.degrees(p) - e) <= a.device_tol_deg for p, e in zip(m.position, a.expect_deg))]

    if not c.spin_until(lambda: final_steps() and step_js(final_steps()[-1]), a.timeout):
        return {"error": f"no servo_angles at {a.expect_deg}; the last: "
                         f"{[math.degrees(p) for p in got['servo_angles'][-1].position]}"}
    # (and the joint_states of the last final step: the planner's second final step may
    # have come meanwhile, its joint_states not yet)
    if not c.spin_until(lambda: replied() and step_js(final_steps()[-1]), a.timeout):
        last = got["servo_state"][-1] if got["servo_state"] else None
        return {"error": "no servo_state answering the last step within --device-tol-deg of it; the last: "
                         f"{last and (stamp_of(last), [math.degrees(p) for p in last.position])}"}

    def js(m):
        return {"stamp": stamp_of(m), "name": list(m.name), "position": list(m.position)}

    state = replied()[-1]
    last_sa = final_steps()[-1]
    return {
        "stamp": stamp,
        "first": {"joint_states": js(step_js(first_sa)), "servo_angles": js(first_sa)},
        "last": {"joint_states": js(step_js(last_sa)), "servo_angles": js(last_sa), "servo_state": js(state)},
        "arrived_stamp": stamp_of(final_steps()[0]),
        "counts": {t: len(ms) - n[t] for t, ms in got.items()},
    }


def params(c, a):
    """Through Jazzy's own parameter client: list; describe diagnostics_period; get the
    --get parameters; set diagnostics_period out of its range, to a string, to 0.5 (read
    back), and back to what it was."""
    from rclpy.parameter import Parameter, parameter_value_to_python
    from rclpy.parameter_client import AsyncParameterClient

    p = AsyncParameterClient(c.node, a.node)
    if not p.wait_for_services(timeout_sec=a.timeout):
        return {"error": f"the parameter services of {a.node} are not offered"}
    out = {"list": sorted(c.wait(p.list_parameters(), a.timeout).result.names)}
    [d] = c.wait(p.describe_parameters(["diagnostics_period"]), a.timeout).descriptors
    out["describe"] = {"description": d.description, "read_only": d.read_only, "type": d.type,
                       "range": [[r.from_value, r.to_value] for r in d.floating_point_range]}

    def get(names):
        values = c.wait(p.get_parameters(names), a.timeout).values
        return {n: parameter_value_to_python(v) for n, v in zip(names, values)}

    def set_(name, value):
        [r] = c.wait(p.set_parameters([Parameter(name, value=value)]), a.timeout).results
        return {"successful": r.successful, "reason": r.reason}

    out["get"] = get(a.get)
    before = get(["diagnostics_period"])["diagnostics_period"]
    out["set_out_of_range"] = set_("diagnostics_period", 500.0)
    out["set_wrong_type"] = set_("diagnostics_period", "often")
    out["set"] = set_("diagnostics_period", 0.5)
    out["get_after"] = get(["diagnostics_period"])
    out["restore"] = set_("diagnostics_period", before)
    return out


ARM = ["base_joint", "shoulder_joint", "elbow_joint"]


def trajectory(c, a):
    """arm_controller/follow_joint_trajectory from Jazzy's ActionClient: a goal moving the
    base by `--move` rad in 1 s from where joint_states says the arm is (MoveIt's start
    point at 0 s included), then one too fast to be accepted."""
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from rclpy.action import ActionClient
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    states = []
    c.node.create_subscription(JointState, "joint_states", states.append, qos("joint_states"))
    client = ActionClient(c.node, FollowJointTrajectory, "arm_controller/follow_joint_trajectory")
    if not c.spin_until(lambda: client.server_is_ready() and states, a.timeout):
        raise SystemExit("no action server or no joint_states")

    def joints():
        js = states[-1]
        return [js.position[list(js.name).index(n)] for n in ARM]

    def goal(points):
        return FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=ARM, points=[
            JointTrajectoryPoint(positions=p, time_from_start=Duration(sec=int(t), nanosec=int((t % 1) * 1e9)))
            for p, t in points]))

    start = joints()
    end = [start[0] + a.move, start[1], start[2]]
    feedback = []
    sent = client.send_goal_async(goal([(start, 0.0), (end, 1.0)]),
                                  feedback_callback=lambda f: feedback.append(f.feedback))
    handle = c.wait(sent, a.timeout)
    out = {"start": start, "end": end, "accepted": handle.accepted}
    if handle.accepted:
        res = c.wait(handle.get_result_async(), a.timeout)
        # the last joint_states may come after the result: wait for the goal's end point
        # (or the timeout: the test then says how far the arm was)
        c.spin_until(lambda: max(abs(p - q) for p, q in zip(joints(), end)) < 1e-9, a.timeout)
        out.update(status=res.status, error_code=res.result.error_code, error_string=res.result.error_string,
                   feedback=len(feedback), final=joints())
        if feedback:
            f = feedback[-1]
            out.update(feedback_joints=list(f.joint_names), feedback_desired=list(f.desired.positions),
                       feedback_actual=list(f.actual.positions), feedback_error=list(f.error.positions))
    too_fast = c.wait(client.send_goal_async(goal([([end[0] - 0.5, end[1], end[2]], 0.05)])), a.timeout)
    out["too_fast_accepted"] = too_fast.accepted
    return out


def controllers(c, a):
    """ros2_control's controller manager services (compute_ik's), from Jazzy's rclpy with
    Jazzy's controller_manager_msgs 4.x: the list, a STRICT switch refused (it would claim
    the arm's joints twice), one taken, and the list after it."""
    from controller_manager_msgs.srv import ListControllers, SwitchController

    lister = c.node.create_client(ListControllers, "controller_manager/list_controllers")
    switcher = c.node.create_client(SwitchController, "controller_manager/switch_controller")
    for client in (lister, switcher):
        if not client.wait_for_service(timeout_sec=a.timeout):
            return {"error": f"{client.srv_name} is not offered"}

    def listed():
        r = c.wait(lister.call_async(ListControllers.Request()), a.timeout)
        return [{"name": x.name, "state": x.state, "type": x.type, "claimed": list(x.claimed_interfaces),
                 "required": list(x.required_command_interfaces)} for x in r.controller]

    def switch(activate, deactivate):
        req = SwitchController.Request(activate_controllers=activate, deactivate_controllers=deactivate,
                                       strictness=SwitchController.Request.STRICT)
        r = c.wait(switcher.call_async(req), a.timeout)
        return {"ok": r.ok, "message": r.message}

    out = {"before": listed()}
    active = [x["name"] for x in out["before"] if x["state"] == "active"]
    out["refused"] = switch(["leader_follower"], [])
    # whichever of teleop and arm_controller holds the arm (a trajectory may have run)
    # gives it to the other
    holder = "arm_controller" if "arm_controller" in active else "teleop"
    out["to"] = "teleop" if holder == "arm_controller" else "arm_controller"
    out["switched"] = switch([out["to"]], [holder])
    out["after"] = listed()
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    sub = ap.add_subparsers(dest="command", required=True)
    g = sub.add_parser("graph")
    g.add_argument("--expect", nargs="+", required=True)
    g.add_argument("--endpoints", default="[]")
    t = sub.add_parser("target")
    t.add_argument("--xyz", nargs=3, type=float, required=True)
    t.add_argument("--expect-deg", nargs=4, type=float, required=True)
    t.add_argument("--device-tol-deg", type=float, default=0.1)
    p = sub.add_parser("params")
    p.add_argument("--node", required=True)
    p.add_argument("--get", nargs="+", default=["diagnostics_period"])
    j = sub.add_parser("trajectory")
    j.add_argument("--move", type=float, default=0.2)
    m = sub.add_parser("controllers")
    for s in (g, t, p, j, m):
        s.add_argument("--timeout", type=float, default=15.0)
    a = ap.parse_args()
    c = Client(a.domain)
    try:
        result = {"graph": graph, "target": target, "params": params, "trajectory": trajectory,
                  "controllers": controllers}[a.command](c, a)
    finally:
        c.close()
    result["rclpy"] = importlib.metadata.version("ros-rclpy")
    result["rmw"] = rclpy.get_rmw_implementation_identifier()
    print(json.dumps(result))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
