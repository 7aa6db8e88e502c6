"""A leader arm in simavr driving the physics twin (issue 35): the leader's firmware reads
A0..A3, driven by a recorded hand motion, with the deadman held (servo_sim --adc-file);
serial_node in the leader role publishes leader/joint_states; compute_ik follows; serial_node
drives the twin (`port:=twin`), whose physics moves the arm there. The verdict is where
the twin's joints end up, as the twin publishes them: the leader's motion is in its own
simulated time, and the graph may start late on a busy host (the motion's hold outlasts
any start)."""
import math

import pytest
from sensor_msgs.msg import JointState

from interop.servo_link import SimulatedUno, write_adc_file
from safety_rig import FIRMWARE
from test_leader_arm import LEADER_SECTION, SHIPPED, leader_deg, pots

# in a process of its own, beside the other tests: the recorded motion plays in real time
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=25), pytest.mark.timeout(600)]

# home with the deadman held while the graph starts, the base swept to 22.5° in 2 s, held
HOME_MS = 5000
MOTION = [(0, pots(0.5), True), (HOME_MS, pots(0.5), True), (HOME_MS + 2000, pots(0.625), True),
          (HOME_MS + 120_000, pots(0.625), True)]


def test_a_leader_in_simavr_drives_the_twin(launch, observer, tmp_path):
    config = tmp_path / "arm.yaml"
    config.write_text(SHIPPED + LEADER_SECTION)
    write_adc_file(tmp_path / "motion.txt", MOTION)
    leader = SimulatedUno(tmp_path, FIRMWARE, adc_file=tmp_path / "motion.txt")
    try:
        joints = observer.sub("/twin/joint_states", JointState)
        launch("twin", "--ros-args", "-p", f"link:={tmp_path / 'twin.tty'}", "-p", "camera_fps:=0")
        launch("compute_ik", "--ros-args", "-p", f"arm_config:={config}")
        launch("serial_node", "--ros-args", "-p", f"port:={tmp_path / 'twin.tty'}", "-p", f"arm_config:={config}")
        launch("serial_node", "--ros-args", "-r", "__node:=leader_arm", "-p", "role:=leader",
               "-p", f"port:={leader.tty_path}", "-p", f"arm_config:={config}")

        def joint(name):
            m = joints[-1][1] if joints else None
            return m.position[list(m.name).index(name)] if m else None

        want = math.radians(leader_deg(0.625))
        # the twin's base where the leader's is (the shoulder and forearm at home)
        assert observer.spin_until(lambda: joint("base_joint") is not None
                                   and abs(joint("base_joint") - want) < math.radians(1), 120), \
            (joint("base_joint"), want)
        assert abs(joint("shoulder_joint") - math.radians(90)) < math.radians(2)
        assert abs(joint("crank_joint")) < math.radians(2)
    finally:
        if leader.proc.poll() is None:
            leader.pull_cable()
