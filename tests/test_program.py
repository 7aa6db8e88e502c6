"""`gui_bridge play` of a waypoint program (nodes/gui_bridge/src/program.rs: rows of
x,y,z,gripper,dwell,mode,name): a point of mode `line` goes on xyz_line_target (a
straight line), the others on xyz_target (as compute_ik's `motion` says: joint), and
compute_ik's `motion` is never set."""
import math
import os
import subprocess

from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState

from conftest import bin_path
from test_gui_bridge import motion_param, run_cli, tool_of


def row(xyz, rest):
    return ",".join(map(str, xyz)) + "," + rest


def test_play_sends_each_point_on_its_modes_topic_and_never_sets_motion(launch, observer, domain, tmp_path):
    launch("compute_ik")
    states = observer.sub("/joint_states", JointState)
    lines = observer.sub("/xyz_line_target", PointStamped)
    plain = observer.sub("/xyz_target", PointStamped)
    observer.wait_publisher("/joint_states")
    assert motion_param(observer) == "joint"
    a, b, c = (0.2, -0.06, 0.12), (0.17, 0.07, 0.2), (0.2, 0.0, 0.15)
    script = tmp_path / "program.csv"
    script.write_text("x,y,z,gripper,dwell,mode,name\n"
                      f"{row(a, ',0.2,joint,start')}\n"
                      f"{row(b, ',0.2,line,draw, straight')}\n"  # a comma in a name: part of it
                      f"{row(c, '0.5,0,,home')}\n")
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    cli = subprocess.Popen([bin_path("gui_bridge"), "play", str(script), "--timeout", "20"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    motions = set()
    while cli.poll() is None:
        observer.spin_for(0.05)
        motions.add(motion_param(observer))
    out, err = cli.communicate(timeout=10)
    assert cli.returncode == 0, err
    assert out.count("waypoint ") == 3, out
    assert motions == {"joint"}, motions
    # b on xyz_line_target, a and c on xyz_target (the observer's readers match
    # gui_bridge's new writers on their own time: a, sent once compute_ik's reader had
    # matched, may go before the observer's did; b and c go after a was reached)
    observer.spin_for(0.2)
    assert [(m.point.x, m.point.y, m.point.z) for _, m in lines] == [b]
    seen = [(m.point.x, m.point.y, m.point.z) for _, m in plain]
    assert seen in ([a, c], [c]), seen
    # a to b (mode line): on the straight segment; b to c (no mode: joint, as compute_ik
    # was): off it
    tools = [tool_of(m) for _, m in states]
    start = max(i for i, t in enumerate(tools) if math.dist(t, a) < 1e-9)
    end = next(i for i, t in enumerate(tools) if i > start and math.dist(t, b) < 1e-9)
    assert end - start > 5

    def off_segment(t, p, q):
        pq = [qi - pi for pi, qi in zip(p, q)]
        n = math.sqrt(sum(v * v for v in pq))
        s = sum((ti - pi) * v for ti, pi, v in zip(t, p, pq)) / n
        return math.dist(t, [pi + s * v / n for pi, v in zip(p, pq)])

    assert max(off_segment(t, a, b) for t in tools[start:end + 1]) < 1e-4
    last_b = max(i for i, t in enumerate(tools) if math.dist(t, b) < 1e-9)
    assert math.dist(tools[-1], c) < 1e-9
    assert max(off_segment(t, b, c) for t in tools[last_b:]) > 5e-4
    # a line through the base axis named by the program (no --line): refused before the
    # move, with compute_ik's reason naming the line's topic and the waypoint's number
    bad = tmp_path / "through_the_base.csv"
    bad.write_text("x,y,z,gripper,dwell,mode,name\n0.08,0.075,0.15,,0,,\n0.08,-0.075,0.15,,0,line,across\n")
    r = run_cli(domain, "play", str(bad), "--timeout", "20", timeout=60)
    assert r.returncode == 1 and "waypoint 2" in r.stderr and "along the line" in r.stderr, r.stderr
    assert "on xyz_line_target" in r.stderr, r.stderr
    assert motion_param(observer) == "joint"


def test_play_names_the_line_of_a_bad_program(domain, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,z,gripper,dwell,mode,name\n0.2,0,0.15,,0,line,a\n0.2,0,0.15,,0,fly,b\n")
    r = run_cli(domain, "play", str(bad))
    assert r.returncode == 2 and "line 3" in r.stderr and "fly" in r.stderr, r.stderr
