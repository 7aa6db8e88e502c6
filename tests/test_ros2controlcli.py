"""`ros2 control list_controllers` and `ros2 control switch_controllers`, ros2_control's own
command line (ros2controlcli with ros2cli and ros2_control's Python controller_manager
module, their upstream source vendored in tests/interop/ros2cli and installed into the
test venv by launch_scripts/install_ros2cli.sh), against compute_ik's controller manager
(issue 33). Each command runs as a subprocess, the `ros2` script of this venv, in the
test's domain; judged by what it prints and its exit code, checked against the
services' answers from a real rclpy client, never by the wall clock."""
import os
import subprocess
import sys
from pathlib import Path

import pytest
from controller_manager_msgs.srv import ListControllers

ROS2 = Path(sys.executable).parent / "ros2"
NAMES = ["teleop", "arm_controller", "gripper_controller", "leader_follower", "calibration"]
TYPES = {"teleop": "eezybot/TeleopController",
         "arm_controller": "joint_trajectory_controller/JointTrajectoryController",
         "gripper_controller": "position_controllers/GripperActionController",
         "leader_follower": "eezybot/LeaderFollowerController",
         "calibration": "eezybot/CalibrationController"}
AT_START = {"teleop": "active", "arm_controller": "inactive", "gripper_controller": "active",
            "leader_follower": "inactive", "calibration": "inactive"}
ARM = ["base_joint/position", "shoulder_joint/position", "elbow_joint/position"]
CLAW = ["gripper_joint/position"]
# the controller manager's answers come within 10 s or the module retries (3 times)
CLI_TIMEOUT_S = 90


class Cli:
    """`ros2 ...` as a subprocess in the test's domain, and compute_ik's list_controllers
    asked from the observer (rclpy) to compare with what it prints."""

    def __init__(self, domain, observer):
        # PYTHONFAULTHANDLER: a crash of the command shows its Python stack in the message
        self.env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "RCUTILS_COLORIZED_OUTPUT": "0",
                    "PYTHONFAULTHANDLER": "1"}
        self.o = observer
        self.clients = {}
        self.used = False

    def run(self, *args):
        assert ROS2.exists(), (f"{ROS2} is missing: ros2cli and ros2controlcli are not installed in this venv "
                               f"(launch_scripts/install_ros2cli.sh {Path(sys.executable).parent.parent})")
        self.used = True
        return subprocess.run([str(ROS2), *args], capture_output=True, text=True, env=self.env,
                              timeout=CLI_TIMEOUT_S, stdin=subprocess.DEVNULL)

    def control(self, verb, *args):
        """`ros2 control VERB ARGS`: (exit code, stdout, the command with its exit code,
        stdout and stderr for an assertion's message)."""
        p = self.run("control", verb, *args)
        return p.returncode, p.stdout, f"ros2 control {verb} {' '.join(args)} -> exit {p.returncode}\n" \
                                       f"stdout:\n{p.stdout}\nstderr:\n{p.stderr}"

    def listed(self, *args):
        """`ros2 control list_controllers ARGS` as {name: (type, state, {heading: [items]})},
        in the printed order."""
        code, out, why = self.control("list_controllers", *args)
        assert code == 0, why
        rows, heading = {}, None
        for line in out.splitlines():
            if not line.strip():
                continue
            if not line.startswith("\t"):
                name, type_, state = line.split()
                rows[name] = (type_, state, {})
            elif not line.startswith("\t\t"):
                heading = line.strip().rstrip(":")
                rows[name][2][heading] = []
            else:
                rows[name][2][heading].append(line.strip())
        return rows, why

    def connect(self, manager="/controller_manager"):
        """The observer's list_controllers client of `manager`, made once, before the
        first command: not a client made just before it asks."""
        self.clients[manager] = self.o.node.create_client(ListControllers, f"{manager}/list_controllers")
        assert self.clients[manager].wait_for_service(timeout_sec=30), self.clients[manager].srv_name

    def answer(self, manager="/controller_manager"):
        """The list_controllers answer from rclpy: {name: ControllerState}."""
        client = self.clients[manager]
        future = client.call_async(ListControllers.Request())
        assert self.o.spin_until(future.done, 30), f"no answer from {client.srv_name}"
        return {c.name: c for c in future.result().controller}

    def stop_daemon(self):
        """The ros2 daemon the first command spawned (in this domain) is stopped."""
        if self.used:
            subprocess.run([str(ROS2), "daemon", "stop"], capture_output=True, env=self.env, timeout=CLI_TIMEOUT_S)


@pytest.fixture
def cli(domain, observer):
    c = Cli(domain, observer)
    yield c
    c.stop_daemon()


def states(rows):
    return {n: r[1] for n, r in rows.items()}


def test_list_controllers_prints_the_five_commanders_as_the_service_lists_them(launch, cli):
    launch("compute_ik")
    cli.connect()
    answer = cli.answer()
    rows, why = cli.listed()
    assert list(rows) == NAMES == list(answer), why
    assert {n: r[0] for n, r in rows.items()} == TYPES, why
    assert states(rows) == {n: c.state for n, c in answer.items()} == AT_START, why
    # the interfaces, as --verbose prints them
    rows, why = cli.listed("--verbose")
    assert list(rows) == NAMES, why
    for name, (_, _, detail) in rows.items():
        assert detail["claimed interfaces"] == list(answer[name].claimed_interfaces), why
        assert detail["required command interfaces"] == list(answer[name].required_command_interfaces), why
    assert rows["teleop"][2]["claimed interfaces"] == ARM and rows["gripper_controller"][2]["claimed interfaces"] == CLAW
    assert rows["leader_follower"][2]["required command interfaces"] == ARM + CLAW


def test_switch_controllers_switches_and_list_controllers_shows_it(launch, cli):
    launch("compute_ik")
    cli.connect()
    code, out, why = cli.control("switch_controllers", "--activate", "arm_controller", "--deactivate", "teleop",
                                 "--strict")
    assert code == 0 and "refused" not in out, why
    # the switch was made when the command returned
    after = {**AT_START, "teleop": "inactive", "arm_controller": "active"}
    assert {n: c.state for n, c in cli.answer().items()} == after, why
    rows, why = cli.listed("--claimed-interfaces")
    assert states(rows) == after, why
    assert rows["arm_controller"][2]["claimed interfaces"] == ARM and rows["teleop"][2]["claimed interfaces"] == [], why
    # and back, with the verb's default strictness (0: the manager's default, strict)
    code, out, why = cli.control("switch_controllers", "--activate", "teleop", "--deactivate", "arm_controller")
    assert code == 0, why
    rows, why = cli.listed()
    assert states(rows) == AT_START, why


def test_a_refused_switch_prints_its_reason_exits_non_zero_and_changes_nothing(launch, cli):
    launch("compute_ik")
    cli.connect()
    code, out, why = cli.control("switch_controllers", "--activate", "leader_follower", "--strict")
    assert code == 1 and "double_claim" in out and "leader_follower" in out and "base_joint/position" in out, why
    # strict: all or nothing, so teleop stays active
    code, out, why = cli.control("switch_controllers", "--activate", "arm_controler", "--deactivate", "teleop",
                                 "--strict")
    assert code == 1 and "unknown_controller" in out and "arm_controler" in out, why
    # best effort, nothing of it possible
    code, out, why = cli.control("switch_controllers", "--activate", "arm_controler", "--best-effort")
    assert code == 1 and "nothing switched" in out and "unknown_controller" in out, why
    code, out, why = cli.control("switch_controllers", "--deactivate", "calibration", "--strict")
    assert code == 1 and "not_active" in out and "calibration" in out, why
    assert {n: c.state for n, c in cli.answer().items()} == AT_START
    rows, why = cli.listed()
    assert states(rows) == AT_START, why


def test_a_namespaced_controller_manager_is_reached_with_its_name(launch, cli):
    launch("compute_ik", "--ros-args", "-r", "__ns:=/arm2")
    manager = "/arm2/controller_manager"
    cli.connect(manager)
    rows, why = cli.listed("-c", manager)
    assert list(rows) == NAMES and states(rows) == AT_START, why
    code, out, why = cli.control("switch_controllers", "--activate", "arm_controller", "--deactivate", "teleop",
                                 "--strict", "-c", manager)
    assert code == 0, why
    after = {**AT_START, "teleop": "inactive", "arm_controller": "active"}
    assert {n: c.state for n, c in cli.answer(manager).items()} == after
    rows, why = cli.listed("--controller-manager", manager)
    assert states(rows) == after, why
