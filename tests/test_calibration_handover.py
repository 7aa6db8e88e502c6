"""Issue 33, item 3: the calibration wizard takes the arm from compute_ik through its
controller manager (`calibration` activated by switch_controller) and gives it back when
nobody is left to finish: the last browser leaving, or gui_bridge gone (compute_ik's
lease on `calibration` runs out).

The wizard is driven over the panel's WebSocket (calibration_rig.WsWizard); the arm is
serial_node on the real firmware in simavr. Who holds the arm is read from
controller_manager/list_controllers, as `ros2 control list_controllers` shows it."""

import pytest
from sensor_msgs.msg import JointState

from calibration_rig import CalibrationGraph, WsWizard
from test_gui_bridge import free_port

pytestmark = [pytest.mark.own_process, pytest.mark.timeout(600)]

TARGET = {"base_joint": 0.2, "shoulder_joint": 1.2, "elbow_joint": -1.7, "gripper_joint": 0.1}


def controllers_shown(wizard):
    """What the panel shows as moving the arm (compute_ik's active controllers)."""
    return (wizard.status or {}).get("controllers")


def wizard_holds_the_arm(graph, wizard):
    """The wizard started; compute_ik's `calibration` is active before the first jog,
    and the panel shows it."""
    assert graph.o.spin_until(lambda: controllers_shown(wizard) == "teleop, gripper_controller", 15), \
        wizard.status
    wizard.start()
    wizard.wait(lambda c: c.get("active") and c.get("phase") in ("moving", "jog"), 30, "the wizard started")
    assert graph.calibrating() is True
    assert graph.o.spin_until(lambda: controllers_shown(wizard) == "calibration", 15), wizard.status


def takes_targets_again(graph, observer):
    """compute_ik moves the arm on a joint target: joint_states reach it."""
    seen = []
    sub = observer.node.create_subscription(JointState, "/joint_states", seen.append, 10)
    try:
        msg = JointState(name=list(TARGET), position=list(TARGET.values()))
        for _ in range(60):
            msg.header.stamp = observer.node.get_clock().now().to_msg()
            graph.joint_target.publish(msg)
            if observer.spin_until(lambda: any(
                    all(abs(dict(zip(m.name, m.position)).get(j, 99) - v) < 0.01 for j, v in TARGET.items())
                    for m in seen), 0.5):
                return True
        return False
    finally:
        observer.node.destroy_subscription(sub)


def test_the_last_browser_leaving_gives_the_arm_back(launch, observer, tmp_path):
    port = free_port()
    graph = CalibrationGraph(launch, observer, tmp_path, port)
    try:
        wizard = WsWizard(port)
        wizard_holds_the_arm(graph, wizard)
        # while it holds the arm, compute_ik takes no target
        wizard.close()
        assert observer.spin_until(lambda: graph.calibrating() is False, 15), graph.calibrating()
        assert takes_targets_again(graph, observer)
    finally:
        graph.stop_board()


def test_the_arm_comes_back_after_the_lease_when_gui_bridge_is_gone(launch, observer, tmp_path):
    port = free_port()
    graph = CalibrationGraph(launch, observer, tmp_path, port)
    try:
        wizard = WsWizard(port)
        wizard_holds_the_arm(graph, wizard)
        # gui_bridge killed: nobody renews the lease, nobody gives the arm back
        graph.gui.kill_hard()
        wizard.close()
        # compute_ik's calibration_lease is 10 s: the bound only ends a failure
        assert observer.spin_until(lambda: graph.calibrating() is False, 40), graph.calibrating()
        # and says why
        assert observer.spin_until(
            lambda: "within the lease" in graph.diag("compute_ik").get("last_switch_controller", ""), 10), \
            graph.diag("compute_ik")
        assert takes_targets_again(graph, observer)
    finally:
        graph.stop_board()
