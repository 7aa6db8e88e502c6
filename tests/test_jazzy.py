"""Our graph as a ROS 2 Jazzy user sees it: most users run Jazzy (the LTS), whose rclpy
(7.x, Fast DDS 2.14) is another implementation of the graph and the services than the
Kilted one the other tests use. tests/jazzy_client.py runs in the Jazzy venv
(EEZYBOT_JAZZY_PYTHON, made by launch_scripts/setup_env.sh) against the whole graph
(compute_ik, state_publisher, serial_node on the virtual Arduino, gui_bridge), started
once for the module in a domain of its own, and prints what it saw; the checks are here.
Expected values come from ROBOT.md (tests/robot_facts.py) and the topic contract, not
from the code under test."""
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import TOPICS, DomainLease, NodeProcess, bin_path
from robot_facts import ik, servo_deg

HERE = Path(__file__).resolve().parent
GRAPH = {"compute_ik": [], "state_publisher": [], "serial_node": ["--ros-args", "-p", "port:=mock"],
         "gui_bridge": ["--ros-args", "-p", "bind:=127.0.0.1:0"]}
SERVOS = ["base_servo", "shoulder_servo", "elbow_servo", "gripper_servo"]
GRIPPER_CLOSED_DEG = 60.0  # ROBOT.md: the gripper servo at opening 0


def jazzy_env():
    """This environment for a process of the Jazzy venv: without what the Kilted wheels'
    bootstrap put in it (their library path, and the flag that stops the Jazzy wheels'
    own bootstrap from setting theirs)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("_ROS_WHEELS_BOOTSTRAP_COMPLETE", "PYTHONPATH", "AMENT_PREFIX_PATH")}
    kept = [p for p in env.get("LD_LIBRARY_PATH", "").split(os.pathsep) if p and not p.startswith(sys.prefix)]
    env["LD_LIBRARY_PATH"] = os.pathsep.join(kept)
    env["RMW_IMPLEMENTATION"] = "rmw_fastrtps_cpp"
    return env


def jazzy(domain, *args, timeout=60):
    """Run tests/jazzy_client.py under Jazzy; its JSON result."""
    python = os.environ.get("EEZYBOT_JAZZY_PYTHON")
    if not python:
        pytest.fail("EEZYBOT_JAZZY_PYTHON is not set: source launch_scripts/setup_env.sh (tests/run_all.sh does)")
    out = subprocess.run([python, str(HERE / "jazzy_client.py"), "--domain", str(domain), *args],
                         capture_output=True, text=True, timeout=timeout, env=jazzy_env())
    assert out.returncode == 0, f"jazzy_client.py {' '.join(args)} exited {out.returncode}:\n{out.stderr[-3000:]}"
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert "error" not in result, result["error"]
    assert result["rclpy"].startswith("7.") and result["rmw"] == "rmw_fastrtps_cpp", result
    return result


@pytest.fixture(scope="module")
def graph():
    """The whole graph, for every test of the module: its ROS domain."""
    lease = DomainLease()
    procs = [NodeProcess(name, args, lease.id) for name, args in GRAPH.items()]
    try:
        yield lease.id
    finally:
        codes = [(p.log_path.name, p.stop()) for p in procs]
        lease.release()
    bad = [(n, c) for n, c in codes if c != 0]
    assert not bad, f"nodes did not exit cleanly: {bad}"


def test_jazzy_sees_every_node_and_its_topics_with_the_contracts_types(graph):
    # every endpoint the contract gives a node of the graph, with the contract's type
    # ("gui_bridge (record)" and the like are not plain node names: left out)
    wanted = [[node, kind, f"/{name}", t["type"]] for name, t in TOPICS.items()
              for kind, nodes in (("pub", t["publishers"]), ("sub", t["subscribers"])) for node in nodes if node in GRAPH]
    seen = jazzy(graph, "graph", "--expect", *GRAPH, "--endpoints", json.dumps(wanted))
    assert sorted(map(tuple, seen["nodes"])) == sorted([(n, "/") for n in GRAPH] + [("jazzy_user", "/")])
    e = seen["endpoints"]
    missing = [f"{node} {kind} {topic} {ty}: {e[node][kind].get(topic)}"
               for node, kind, topic, ty in wanted if e[node][kind].get(topic) != [ty]]
    assert not missing, missing
    print(f"Jazzy's node list complete in {seen['listed_s']:.2f} s, endpoints in {seen['endpoints_s']:.2f} s")


def test_a_target_from_jazzy_comes_back_in_joint_states_servo_angles_and_servo_state(graph):
    goal = (0.2, 0.05, 0.15)
    expected = [*servo_deg(*goal), GRIPPER_CLOSED_DEG]
    # (pulses are whole microseconds: the virtual Arduino is there within 0.1 deg)
    r = jazzy(graph, "target", "--xyz", *map(str, goal), "--expect-deg", *map(str, expected), "--device-tol-deg", "0.1")
    # the first step of the motion carries the target's stamp
    assert r["first"]["joint_states"]["stamp"] == r["stamp"]
    assert r["first"]["servo_angles"]["stamp"] == r["stamp"]
    # at rest where ROBOT.md puts it
    js = dict(zip(r["last"]["joint_states"]["name"], r["last"]["joint_states"]["position"]))
    assert [js["base_joint"], js["shoulder_joint"], js["elbow_joint"]] == pytest.approx(ik(*goal), abs=1e-9)
    assert js["gripper_joint"] == 0.0
    sa = r["last"]["servo_angles"]
    assert sa["name"] == SERVOS
    assert [math.degrees(a) for a in sa["position"]] == pytest.approx(expected, abs=1e-9)
    # and the virtual Arduino there (its pulses are whole microseconds: 0.1 deg), in an
    # answer to the step that arrived or a later one (its stamp)
    st = r["last"]["servo_state"]
    assert st["stamp"] >= r["arrived_stamp"], (st["stamp"], r["arrived_stamp"])
    assert st["name"] == SERVOS
    assert [math.degrees(a) for a in st["position"]] == pytest.approx(expected, abs=0.1)


def documented_parameters(name):
    """The parameter names of the binary's --help."""
    out = subprocess.run([bin_path(name), "--help"], capture_output=True, text=True, timeout=30).stdout
    return {m.group(1) for m in re.finditer(r"^  (\S+)\s", out.split("parameters:\n", 1)[1], re.M)}


@pytest.mark.parametrize("node,get", [
    ("compute_ik", {"base_frame": "base_link", "solver": "analytic", "diagnostics_period": 1.0}),
    ("serial_node", {"port": "mock", "baud": 115200, "diagnostics_period": 1.0}),
])
def test_parameters_through_jazzys_parameter_client(graph, node, get):
    r = jazzy(graph, "params", "--node", node, "--get", *get)
    assert set(r["list"]) == documented_parameters(node) | {"use_sim_time"}
    assert r["describe"] == {"description": "seconds between diagnostics reports", "read_only": False,
                             "type": 3, "range": [[0.05, 60.0]]}  # 3: PARAMETER_DOUBLE
    assert r["get"] == get
    assert not r["set_out_of_range"]["successful"] and "outside" in r["set_out_of_range"]["reason"]
    assert not r["set_wrong_type"]["successful"] and r["set_wrong_type"]["reason"]
    assert r["set"]["successful"], r["set"]
    assert r["get_after"] == {"diagnostics_period": 0.5}
    assert r["restore"]["successful"], r["restore"]


def test_a_trajectory_goal_from_jazzys_action_client(graph):
    """arm_controller/follow_joint_trajectory from Jazzy's rclpy ActionClient, with
    Jazzy's control_msgs 5 (no `index` in the feedback): the default feedback_layout
    `any` is read by it. Succeeds, with feedback; a too fast goal is rejected."""
    r = jazzy(graph, "trajectory", "--move", "0.2")
    assert r["accepted"], r
    assert (r["status"], r["error_code"], r["error_string"]) == (4, 0, ""), r  # 4: STATUS_SUCCEEDED
    assert max(abs(a - b) for a, b in zip(r["final"], r["end"])) < 1e-9, r
    assert r["feedback"] > 5 and r["feedback_joints"] == ["base_joint", "shoulder_joint", "elbow_joint"], r
    assert len(r["feedback_desired"]) == len(r["feedback_actual"]) == 3, r
    assert all(abs(e - (d - q)) < 1e-9 for e, d, q in zip(r["feedback_error"], r["feedback_desired"], r["feedback_actual"]))
    assert not r["too_fast_accepted"], r


def test_the_controller_manager_from_jazzys_rclpy(graph):
    """controller_manager/list_controllers and switch_controller (compute_ik's arbiter) from
    Jazzy's rclpy, with Jazzy's controller_manager_msgs: the five controllers, a refused
    switch with its reason, a switch taken and seen in the list."""
    r = jazzy(graph, "controllers")
    names = [x["name"] for x in r["before"]]
    assert names == ["teleop", "arm_controller", "gripper_controller", "leader_follower", "calibration"], r
    by = {x["name"]: x for x in r["before"]}
    assert by["gripper_controller"]["state"] == "active" and by["leader_follower"]["state"] == "inactive", r
    assert by["gripper_controller"]["claimed"] == ["gripper_joint/position"], r
    assert by["arm_controller"]["required"] == ["base_joint/position", "shoulder_joint/position",
                                                "elbow_joint/position"], r
    assert not r["refused"]["ok"] and "double_claim" in r["refused"]["message"], r
    assert r["switched"]["ok"], r
    after = {x["name"]: x["state"] for x in r["after"]}
    other = {"teleop": "arm_controller", "arm_controller": "teleop"}[r["to"]]
    assert after[r["to"]] == "active" and after[other] == "inactive", r
