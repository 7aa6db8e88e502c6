"""Following a leader arm (issue 22, the follower's side): compute_ik follows
leader/joint_states within its motion limits while leader/deadman is true, holds when it
is released, and holds when the samples stop (a pulled cable), saying why in
diagnostics. The leader here is rclpy publishing what serial_node in the leader role
publishes: 100 Hz samples of the joints with the deadman's state.

The verdict is an order of events, never a window of wall time: compute_ik stamps its
joint_states and its diagnostics (published at once when its `leader` state changes) on
this host's clock, and the test takes the time of its own publications on the same
clock. compute_ik's base here turns at a tenth of its rated speed, so that a move is
long enough to be cut in the middle by an event the test waits for."""
import time

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from conftest import COMMANDS, REPO
from test_leader_arm import compute_ik_reports, first_after, record, stamp_ns

ARM = ["base_joint", "shoulder_joint", "elbow_joint", "gripper_joint"]
SHIPPED = (REPO / "config" / "arm.yaml").read_text()
RATED = "base:     { max_velocity_deg_s: 300.0,"
# 30°/s of the servo, 15°/s of base_joint: 0.7 rad of it take 2.7 s
SLOW = "base:     { max_velocity_deg_s: 30.0,"
MOVING_RAD = 0.05  # a move under way: the base this far from where it started


class LeaderRig:
    def __init__(self, launch, observer, tmp_path):
        self.o = observer
        assert RATED in SHIPPED, "config/arm.yaml's base motion limit moved: update SLOW"
        config = tmp_path / "arm.yaml"
        config.write_text(SHIPPED.replace(RATED, SLOW))
        launch("compute_ik", "--ros-args", "-p", f"arm_config:={config}")
        launch("serial_node", "--ros-args", "-p", "port:=mock")
        # compute_ik's commanded joints [(stamp ns, [base, shoulder, elbow, gripper])]
        # (the contract's depth: the last before each hold stays, nothing follows it) and
        # its `leader` state [(stamp ns, state)], every sample kept
        self.joint_states = record(observer, "/joint_states", JointState,
                                   lambda m, _: (stamp_ns(m.header), [m.position[list(m.name).index(n)] for n in ARM]),
                                   depth=None)
        self.reports = []
        record(observer, "/diagnostics", DiagnosticArray, lambda m, _: self.reports.extend(compute_ik_reports(m)))
        self.joints = observer.pub("leader/joint_states", JointState, COMMANDS)
        self.deadman = observer.pub("leader/deadman", Bool, COMMANDS)
        observer.wait_matched(self.joints)
        observer.wait_matched(self.deadman)
        assert observer.spin_until(lambda: self.joint_states, 10)

    def pose(self):
        return self.joint_states[-1][1]

    def lead(self, pose_at, until, what, held=True, deadman=True, timeout=30.0):
        """Publish a leader sample every 10 ms, the pose pose_at(t) at t s since the
        first (and the deadman `held`, unless `deadman` is False: none sent), until
        `until()` holds (`what` says what it waits for); returns the wall time (ns) of
        the first sample."""
        first = time.time_ns()
        start = time.monotonic()
        self.last_sample_ns = None
        while not until():
            t = time.monotonic() - start
            assert t < timeout, f"not within {timeout} s: {what}; compute_ik at {self.pose()}, " \
                                f"its leader states {[v for _, v in self.states()[-4:]]}"
            self.joints.publish(JointState(name=ARM, position=[float(v) for v in pose_at(t)]))
            if deadman:
                self.deadman.publish(Bool(data=held))
            self.last_sample_ns = time.time_ns()
            self.o.spin_for(0.01)
        return first

    def states(self):
        """compute_ik's `leader` states as it reported them, each change once: [(ns, state)]."""
        out = []
        for t, v in self.reports:
            if not out or v != out[-1][1]:
                out.append((t, v))
        return out

    def reported(self, pred, after_ns=0):
        """A predicate: compute_ik reported a `leader` state passing `pred` after after_ns."""
        return lambda: first_after(self.reports, after_ns, pred) is not None

    def moves_since(self, t_ns):
        """compute_ik's joint_states stamped after t_ns: [(ns, pose)]."""
        return [(t, p) for t, p in self.joint_states if t > t_ns]

    def moving_from(self, start):
        """A predicate: the base has moved MOVING_RAD from `start`."""
        return lambda: abs(self.pose()[0] - start[0]) >= MOVING_RAD


def at(pose, target):
    return max(abs(a - b) for a, b in zip(pose, target)) < 1e-9


def test_the_follower_follows_while_the_deadman_is_held_and_holds_on_release(launch, observer, tmp_path):
    rig = LeaderRig(launch, observer, tmp_path)
    home = rig.pose()
    target = [home[0] + 0.3, home[1] - 0.1, home[2] + 0.1, 0.3]
    # released (the deadman never pressed): the leader at `target`, the follower still.
    # compute_ik leaves "no leader" for "holding" only on a leader sample, and would have
    # commanded in the same turn had it followed it
    rig.lead(lambda t: target, rig.reported(lambda v: v == "holding: deadman released"), "compute_ik holding, released",
             deadman=False)
    seen = first_after(rig.reports, 0, lambda v: v == "holding: deadman released")[0]
    assert all(at(p, home) for t, p in rig.joint_states if t < seen), rig.joint_states[-3:]
    # held: a slow sweep of the leader, followed to its end
    rig.lead(lambda t: [home[i] + (target[i] - home[i]) * min(1.0, t / 0.5) for i in range(4)],
             lambda: at(rig.pose(), target), "the follower at the sweep's end")
    assert "following" in [v for _, v in rig.states()], rig.states()
    # moving toward a far pose, the deadman released mid-move: the follower holds where
    # it is, while the leader stays there released for 0.3 s of compute_ik's clock
    far = [home[0] - 0.4, home[1], home[2], 0.0]
    toward = rig.lead(lambda t: far, rig.moving_from(target), "the follower moving toward the far pose")
    rig.lead(lambda t: far, rig.reported(lambda v: v == "holding: deadman released", toward),
             "compute_ik holding on the release", held=False)
    hold = first_after(rig.reports, toward, lambda v: v == "holding: deadman released")[0]
    rig.lead(lambda t: far, rig.reported(lambda v: True, hold + 300_000_000), "compute_ik's report 0.3 s after", held=False)
    # pressed again: followed on to `far`
    repress = rig.lead(lambda t: far, lambda: at(rig.pose(), far), "the follower at the far pose")
    held = [p for t, p in rig.joint_states if t < hold][-1]
    assert far[0] + MOVING_RAD < held[0] <= target[0] - MOVING_RAD, (held, far, target)
    moved = [(t, p) for t, p in rig.joint_states if hold < t < repress and not at(p, held)]
    assert not moved, f"compute_ik moved while the deadman was released, from {held}: {moved[:3]}"
    assert rig.moves_since(repress), "not followed again"


def test_the_follower_holds_when_the_leader_stops_and_says_why(launch, observer, tmp_path):
    rig = LeaderRig(launch, observer, tmp_path)
    home = rig.pose()
    far = [home[0] + 0.45, home[1], home[2], 0.0]
    rig.lead(lambda t: far, rig.moving_from(home), "the follower moving toward the far pose")
    # the cable is pulled: no more samples after the last; compute_ik says why
    pulled = rig.last_sample_ns
    assert observer.spin_until(rig.reported(lambda v: "no leader sample" in v, pulled), 30), rig.states()[-3:]
    hold = first_after(rig.reports, pulled, lambda v: "no leader sample" in v)[0]
    # held for 0.3 s of compute_ik's clock, then the leader back: followed again
    assert observer.spin_until(rig.reported(lambda v: True, hold + 300_000_000), 30), rig.states()[-3:]
    back = rig.lead(lambda t: home, lambda: at(rig.pose(), home), "the follower back home")
    held = [p for t, p in rig.joint_states if t < hold][-1]
    assert home[0] + MOVING_RAD <= held[0] < far[0] - MOVING_RAD, (held, far)
    moved = [(t, p) for t, p in rig.joint_states if hold < t < back and not at(p, held)]
    assert not moved, f"compute_ik moved on after it held at {held}: {moved[:3]}"
