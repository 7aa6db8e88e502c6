"""Following a leader arm (issue 22, the follower's side): compute_ik follows
leader/joint_states within its motion limits while leader/deadman is true, holds when it
is released, and holds when the samples stop (a pulled cable), saying why in
diagnostics. The leader here is rclpy publishing what serial_node in the leader role
publishes: 100 Hz samples of the joints with the deadman's state."""
import math

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from conftest import COMMANDS, latest_status, status_values

ARM = ["base_joint", "shoulder_joint", "elbow_joint", "gripper_joint"]


class LeaderRig:
    def __init__(self, launch, observer):
        self.o = observer
        launch("compute_ik")
        launch("serial_node", "--ros-args", "-p", "port:=mock")
        self.joint_states = observer.sub("joint_states", JointState)
        self.diags = observer.sub("diagnostics", DiagnosticArray)
        self.joints = observer.pub("leader/joint_states", JointState, COMMANDS)
        self.deadman = observer.pub("leader/deadman", Bool, COMMANDS)
        observer.wait_matched(self.joints)
        observer.wait_matched(self.deadman)
        assert observer.spin_until(lambda: self.joint_states, 10)

    def pose(self):
        js = self.joint_states[-1][1]
        return [js.position[list(js.name).index(n)] for n in ARM]

    def lead(self, pose_at, seconds, held=True):
        """Publish leader samples every 10 ms for `seconds`: the pose pose_at(t)."""
        t = 0.0
        while t < seconds:
            self.joints.publish(JointState(name=ARM, position=[float(v) for v in pose_at(t)]))
            self.deadman.publish(Bool(data=held))
            self.o.spin_for(0.01)
            t += 0.01

    def leader_state(self):
        return status_values(latest_status(self.diags, "compute_ik")).get("leader", "")


def test_the_follower_follows_while_the_deadman_is_held_and_holds_on_release(launch, observer):
    rig = LeaderRig(launch, observer)
    home = rig.pose()
    target = [home[0] + 0.3, home[1] - 0.1, home[2] + 0.1, 0.3]
    # released: the leader moves, the follower does not
    rig.lead(lambda t: target, 0.3, held=False)
    assert max(abs(a - b) for a, b in zip(rig.pose(), home)) < 1e-9, rig.pose()
    # held: a slow sweep of the leader, followed to its end
    rig.lead(lambda t: [home[i] + (target[i] - home[i]) * min(1.0, t / 0.5) for i in range(4)], 0.8)
    observer.spin_for(0.2)
    assert max(abs(a - b) for a, b in zip(rig.pose(), target)) < 1e-9, rig.pose()
    # (diagnostics said so while it followed; after the sweep, the samples stopped)
    states = [kv.value for _, arr in rig.diags for st in arr.status if st.name.startswith("compute_ik")
              for kv in st.values if kv.key == "leader"]
    assert "following" in states, states
    # moving toward a far pose, the deadman released: the follower holds where it is
    far = [home[0] - 0.4, home[1], home[2], 0.0]
    rig.lead(lambda t: far, 0.1)
    rig.deadman.publish(Bool(data=False))
    observer.spin_for(0.1)
    held = rig.pose()
    assert far[0] < held[0] < target[0], held
    rig.lead(lambda t: far, 0.3, held=False)
    assert max(abs(a - b) for a, b in zip(rig.pose(), held)) < 1e-9, (rig.pose(), held)
    assert observer.spin_until(lambda: "deadman released" in rig.leader_state(), 3), rig.leader_state()


def test_the_follower_holds_when_the_leader_stops_and_says_why(launch, observer):
    rig = LeaderRig(launch, observer)
    home = rig.pose()
    far = [home[0] + 0.45, home[1], home[2], 0.0]
    rig.lead(lambda t: far, 0.1)
    # the cable is pulled: no more samples
    observer.spin_for(0.1)
    held = rig.pose()
    observer.spin_for(0.5)
    assert rig.pose() == held and held[0] < far[0], (rig.pose(), held)
    assert observer.spin_until(lambda: "no leader sample" in rig.leader_state(), 3), rig.leader_state()
    assert not math.isclose(held[0], home[0])
