"""`recorder replay` (issue 34): an episode recorded from the running graph is played
back through compute_ik's arm_controller (FollowJointTrajectory) and gripper_target,
and moves the follower through the recorded joints, in order, to the last one."""
import json
import os
import subprocess

import pyarrow.parquet as pq
import pytest
from control_msgs.msg import JointTrajectoryControllerState
from sensor_msgs.msg import JointState

from conftest import EVERY, bin_path

# in a process of its own beside the other tests (judged by order and content, not the wall clock)
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=12)]

JOINTS = ["base_joint", "shoulder_joint", "elbow_joint", "gripper_joint"]
ARM = JOINTS[:3]

# Poses inside the joint limits of config/arm.yaml (shoulder + elbow within the
# forearm's -65° … 20°), 0.2 rad or more apart in some joint; the claw in rad
# (0 … gripper_open_rad 0.6)
A = [0.3, 1.4, -1.6, 0.1]
B = [-0.3, 1.7, -1.9, 0.5]
C = [0.1, 1.2, -1.3, 0.3]
ELSEWHERE = [-0.5, 1.5, -1.5, 0.2]

# The commanded joints must come within this of a recorded pose. Each pose is held
# for HOLD_S while recording, so the episode has a run of identical action rows there,
# and the replayed trajectory (straight segments between the rows) holds exactly that
# value over the run: what remains is the float32 rounding of the dataset (< 1e-6
# rad). 0.01 rad is compute_ik's own START_MATCH_RAD, and far below the 0.2 rad or
# more between the poses, so no pose can be taken for another.
TOL = 0.01
# The servos (arm_controller/controller_state's feedback: servo_state as joints) may
# differ by the Arduino's whole-degree servo angles (0.5° of a joint for the base's 2:1
# gear, 1° = 0.017 rad for the others): 0.02 rad, as test_trajectory_action's.
SERVO_TOL = 0.02
HOLD_S = 0.4


def near(q, p, tol):
    return max(abs(a - b) for a, b in zip(q, p)) < tol


def joints(js, names=JOINTS):
    return [js.position[list(js.name).index(n)] for n in names]


def recorder(observer, domain, *args, timeout=60):
    """The recorder binary as a command-line client, in the test's ROS domain, the
    observer spinning meanwhile (its subscriptions take every sample); the completed
    process (stdout, stderr as text)."""
    p = subprocess.Popen([bin_path("recorder"), *args], env={**os.environ, "ROS_DOMAIN_ID": str(domain)},
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if not observer.spin_until(lambda: p.poll() is not None, timeout):
        p.kill()
    out, err = p.communicate(timeout=10)
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)


def passes_in_order(seq, poses, tol):
    """The index in `seq` where each pose of `poses` is first reached, each after the
    previous one's (None where one is never reached)."""
    out, start = [], 0
    for p in poses:
        k = next((i for i in range(start, len(seq)) if near(seq[i], p, tol)), None)
        out.append(k)
        if k is None:
            break
        start = k + 1
    return out


def test_replay_moves_the_follower_through_the_recorded_joints(launch, observer, domain, tmp_path):
    root = tmp_path / "ds"
    launch("compute_ik", "--ros-args", "-p", "max_target_age:=0.0")
    launch("serial_node", "--ros-args", "-p", "port:=mock")
    launch("recorder", "--ros-args", "-p", f"root:={root}")
    joint_states = observer.sub("joint_states", JointState, EVERY)
    state = observer.sub("arm_controller/controller_state", JointTrajectoryControllerState, EVERY)
    target = observer.pub("joint_target", JointState)
    observer.wait_matched(target)
    assert observer.spin_until(lambda: joint_states and state, 15), "compute_ik and serial_node did not start"

    def go(pose):
        """joint_target to `pose` until compute_ik commands it (a first sample may come
        before compute_ik's reader has matched ours: sent again each 0.5 s), then hold it."""
        reached = lambda: near(joints(joint_states[-1][1]), pose, 1e-6)  # noqa: E731
        for _ in range(20):
            target.publish(JointState(name=JOINTS, position=pose))
            if observer.spin_until(reached, 0.5):
                break
        assert reached(), (pose, joints(joint_states[-1][1]))
        observer.spin_for(HOLD_S)

    # record A -> B -> C
    go(A)
    r = recorder(observer, domain, "start-episode", "--task", "replay test")
    assert r.returncode == 0, r.stdout + r.stderr
    observer.spin_for(HOLD_S)
    go(B)
    go(C)
    r = recorder(observer, domain, "save-episode")
    assert r.returncode == 0 and "saved episode 0" in r.stdout, r.stdout + r.stderr

    # what was recorded: the episode's action rows, named as the joints
    info = json.loads((root / "meta/info.json").read_text())
    assert info["features"]["action"]["names"] == JOINTS
    table = pq.read_table(root / "data/chunk-000/file-000.parquet").to_pydict()
    rows = [a for a, e in zip(table["action"], table["episode_index"]) if e == 0]
    assert len(rows) >= 30, len(rows)
    # the recording holds each pose (its rows are the references: float32)
    recorded = []
    for p in (A, B, C):
        row = min(rows, key=lambda a: max(abs(x - y) for x, y in zip(a, p)))
        assert near(row, p, 1e-5), (p, row)
        recorded.append(row)
    assert near(rows[0], A, 1e-5) and near(rows[-1], C, 1e-5), (rows[0], rows[-1])

    # elsewhere, then the replay
    go(ELSEWHERE)
    assert not near(joints(joint_states[-1][1]), A, 0.2)
    n_js, n_state = len(joint_states), len(state)
    r = recorder(observer, domain, "replay", "--root", str(root), "--episode", "0")
    out = r.stdout + r.stderr
    print(out)
    assert r.returncode == 0, out
    assert "replaying episode 0" in out and "done: episode 0 replayed" in out, out

    # the commanded joints passed through the recorded poses in order and end at the
    # last recorded action: the arm's (one trajectory through the frames), and the
    # claw's, which compute_ik moves beside the trajectory at the claw's own limits
    # toward each gripper_target (so it may be a step or two behind the arm)
    assert observer.spin_until(lambda: near(joints(joint_states[-1][1]), rows[-1], TOL), 5), \
        (joints(joint_states[-1][1]), rows[-1])
    commanded = [joints(js) for _, js in joint_states[n_js:]]
    for which, cols in (("arm", slice(0, 3)), ("claw", slice(3, 4))):
        seq = [q[cols] for q in commanded]
        poses = [p[cols] for p in recorded]
        order = passes_in_order(seq, poses, TOL)
        best = [min(seq, key=lambda q: max(abs(a - b) for a, b in zip(q, p))) for p in poses]
        assert None not in order, (which, order, poses, best, len(seq), out)
        # (it left ELSEWHERE first: A was not where it started)
        assert which == "claw" or order[0] > 0
    # the servos followed: their joints (controller_state's feedback) too, in order
    assert observer.spin_until(lambda: near(state[-1][1].feedback.positions, rows[-1][:3], SERVO_TOL), 5), \
        (list(state[-1][1].feedback.positions), rows[-1][:3])
    actual = [list(s.feedback.positions) for _, s in state[n_state:] if len(s.feedback.positions) == 3]
    order = passes_in_order(actual, [p[:3] for p in recorded], SERVO_TOL)
    assert None not in order, order

    # a missing episode is refused with the count, before anything moves
    r = recorder(observer, domain, "replay", "--root", str(root), "--episode", "5", timeout=30)
    assert r.returncode == 1 and "has no episode 5: it has 1" in r.stderr, r.stdout + r.stderr
