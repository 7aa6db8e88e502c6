"""launch_scripts/run_graph.sh, pc.sh and pi.sh as a user runs them: ROS domain and ROS
arguments for every node, what runs where, the serial port choice (never the virtual
Arduino behind the user's back on a Pi), prebuilt binaries, and Ctrl-C / SIGTERM
stopping every child with exit code 0."""
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState

from conftest import bin_path, default_sigint, latest_status, status_values
from launch_script import SCRIPTS, STARTED, Script, default_sigint, graph_ends, left_alive, node_processes, reap_scripts  # noqa: F401 (fixture)


def now_stamp():
    t = time.time()
    return int(t), int((t % 1) * 1e9)


def target_answered(observer, xyz, state, y):
    """Targets at (0.2, y, 0.15), each stamped when published on `xyz`: whether
    servo_state answers one of them (with its stamp) on `state` within 20 s. Published
    again every half second until then: the nodes' readers may learn of our writer a
    moment after ours matched them, and a target sent before is lost to them."""
    sent = set()

    def answered():
        return any((x.header.stamp.sec, x.header.stamp.nanosec) in sent for _, x in state)

    end = time.monotonic() + 20
    while time.monotonic() < end:
        m = PointStamped()
        m.header.frame_id = "base_link"
        m.header.stamp.sec, m.header.stamp.nanosec = now_stamp()
        m.point.x, m.point.y, m.point.z = 0.2, y, 0.15
        sent.add((m.header.stamp.sec, m.header.stamp.nanosec))
        xyz.publish(m)
        if observer.spin_until(answered, min(0.5, max(0.0, end - time.monotonic()))):
            return True
    return answered()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl_c", "sigterm"])
def test_run_graph_runs_every_node_with_the_ros_arguments_and_stops_them_all(sig, domain, observer):
    """`run_graph.sh -r __ns:=/arm2` in a domain: every node runs there under /arm2 with
    the built-in virtual Arduino (no board here), a target gets an answer, and Ctrl-C or
    SIGTERM stops every node (no orphan) with exit code 0."""
    s = Script("run_graph.sh", "-r", "__ns:=/arm2", env={"ROS_DOMAIN_ID": str(domain), "SERIAL_PORT": ""})
    try:
        kids = s.children(4)
        xyz, state = graph_ends(observer, "/arm2/xyz_target", PointStamped, "/arm2/servo_state", JointState,
                                {"compute_ik", "state_publisher", "serial_node", "gui_bridge"})
        assert {ns for n, ns in observer.node.get_node_names_and_namespaces() if n == "compute_ik"} == {"/arm2"}
        assert target_answered(observer, xyz, state, 0.0)
        out = s.output()
        assert f"ROS domain {domain}" in out and "virtual Arduino" in out
        for node in ("compute_ik", "state_publisher", "gui_bridge", "serial_node"):
            assert node in out
    finally:
        code = s.stop(sig)
    assert code == 0, s.output()
    orphans = left_alive(kids)
    assert not orphans, f"orphans left: {orphans}"


def test_pc_and_pi_scripts_split_the_graph(domain, observer):
    """pc.sh runs gui_bridge, compute_ik and state_publisher; pi.sh runs serial_node
    (SERIAL_PORT=mock: the virtual Arduino, because we asked); together they answer a
    target. Each says what runs where."""
    pc = Script("pc.sh", env={"ROS_DOMAIN_ID": str(domain)})
    pi = Script("pi.sh", env={"ROS_DOMAIN_ID": str(domain), "SERIAL_PORT": "mock"})
    try:
        assert len(pc.children(3)) == 3
        assert len(pi.children(1)) == 1
        xyz, state = graph_ends(observer, "/xyz_target", PointStamped, "/servo_state", JointState,
                                {"compute_ik", "state_publisher", "serial_node", "gui_bridge"})
        assert target_answered(observer, xyz, state, 0.05)
        assert "running here (operator PC): compute_ik, state_publisher, gui_bridge" in pc.output()
        assert "expected on the Pi" in pc.output()
        assert "serial_node with the built-in virtual Arduino" in pi.output()
    finally:
        codes = (pc.stop(), pi.stop())
    assert codes == (0, 0), pc.output() + pi.output()


def test_pi_script_never_falls_back_to_the_virtual_arduino(domain, observer):
    """No board (no /dev/eezybot, no /dev/ttyACM0) and no SERIAL_PORT: pi.sh warns and
    serial_node waits for /dev/eezybot; it does not quietly drive a virtual arm."""
    if Path("/dev/eezybot").exists() or Path("/dev/ttyACM0").exists():
        pytest.skip("a serial device is plugged in here")
    pi = Script("pi.sh", env={"ROS_DOMAIN_ID": str(domain), "SERIAL_PORT": ""})
    diags = observer.sub("/diagnostics", DiagnosticArray)
    try:
        pi.children(1)
        assert pi.wait_output("WARNING: no Arduino")
        observer.wait_publisher("/diagnostics")

        assert observer.spin_until(lambda: latest_status(diags, "serial_node") is not None, 10)
        values = status_values(latest_status(diags, "serial_node"))
        assert values["port"] == "/dev/eezybot"
        assert values["connection"] != "connected"
        assert "virtual" not in pi.output().split("WARNING")[1].split("\n")[0]
    finally:
        code = pi.stop()
    assert code == 0


def test_a_bundle_uses_its_own_binaries_without_cargo(domain, tmp_path):
    """A copy of the Pi bundle layout (bin/ next to launch_scripts/), on a PATH with no
    cargo: pi.sh runs the bundled serial_node."""
    bundle = tmp_path / "eezybot-pi"
    (bundle / "bin").mkdir(parents=True)
    shutil.copytree(SCRIPTS, bundle / "launch_scripts")
    shutil.copy(bin_path("serial_node"), bundle / "bin" / "serial_node")
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "SERIAL_PORT": "mock", "PATH": "/usr/bin:/bin"}
    env.pop("EEZYBOT_BIN_DIR", None)
    log = tmp_path / "pi.log"
    with open(log, "w") as f:
        proc = subprocess.Popen([str(bundle / "launch_scripts" / "pi.sh")], stdout=f, stderr=subprocess.STDOUT,
                                env=env, text=True, start_new_session=True, preexec_fn=default_sigint)
    STARTED.append(proc.pid)
    try:
        # its start-up done (the banner, which names the binaries, comes before this line)
        end = time.monotonic() + 20
        while "] running here" not in log.read_text():
            assert time.monotonic() < end and proc.poll() is None, f"pi.sh did not start:\n{log.read_text()}"
            time.sleep(0.1)
        kids = list(node_processes(proc.pid))
        assert kids, "pi.sh started nothing"
        exe = os.readlink(f"/proc/{kids[0]}/exe")
        assert exe == str(bundle / "bin" / "serial_node")
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(20)
    out = log.read_text()
    assert proc.returncode == 0, out
    assert "cargo" not in out and str(bundle / "bin") in out


def group_alive(pgid):
    """Live (not zombie) processes of process group `pgid`."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            out.append(int(stat.parent.name))
    return out


def release(fifo, timeout=20):
    """Let the process blocked reading `fifo` go on: open it for writing (at once once
    the reader has it open) and write one line."""
    end = time.monotonic() + timeout
    while True:
        try:
            fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
            break
        except OSError:  # ENXIO: its reader has not opened it yet
            assert time.monotonic() < end, f"nobody reads {fifo}"
            time.sleep(0.05)
    try:
        os.write(fd, b"go\n")
    finally:
        os.close(fd)


@pytest.mark.parametrize("script", ["run_graph.sh", "pc.sh", "pi.sh"])
def test_ctrl_c_while_starting_leaves_nothing_behind(script, domain, tmp_path):
    """Ctrl-C while the script is still starting up (its nodes are running, it is printing
    where: a `hostname` that waits for the test holds it there): every node started is
    stopped and the script exits 0. Before the fix the signal was only trapped once the
    script waited on its nodes, so the script went on to wait forever, or died leaving its
    nodes running."""
    # The first `hostname` blocks on a FIFO until the test writes to it, so the signal
    # comes while the script is provably in its start-up, however busy the host.
    held, go = tmp_path / "held", tmp_path / "go"
    os.mkfifo(go)
    shim = tmp_path / "hostname"
    shim.write_text(f"#!/bin/sh\nif mkdir {held} 2>/dev/null; then read _ < {go}; fi\n"
                    f"exec {shutil.which('hostname')} \"$@\"\n")
    shim.chmod(0o755)
    s = Script(script, env={"ROS_DOMAIN_ID": str(domain), "SERIAL_PORT": "mock",
                            "PATH": f"{tmp_path}:{os.environ['PATH']}"})
    try:
        s.children(1)
        end = time.monotonic() + 20
        while not held.exists():
            assert time.monotonic() < end and s.proc.poll() is None, f"the script never asked for its host name:\n{s.output()}"
            time.sleep(0.05)
        # the script's own lines (gui_bridge, already running, prints its URL too)
        assert "] running here" not in s.output() and "] web panel" not in s.output()
        s.proc.send_signal(signal.SIGINT)
        # bash runs the trap once the command it waits for (the held `hostname`) is done
        release(go)
        code = s.proc.wait(20)
    finally:
        if s.proc.poll() is None:
            s.stop(signal.SIGKILL)
        s.stop()
    assert code == 0, s.output()
    end = time.monotonic() + 20
    while time.monotonic() < end and group_alive(s.proc.pid):
        time.sleep(0.1)
    assert not group_alive(s.proc.pid), s.output()


def test_a_signal_between_a_nodes_start_and_its_record_stops_it_too(tmp_path):
    """The trap can run between a node's `&` and eezybot_start recording its pid (fresh-
    clone run T: run_graph.sh, signalled as serial_node started, stopped the other three,
    then waited for serial_node forever). lib.sh is driven to that point exactly: one node
    recorded, one started and not yet recorded, then SIGINT. Both are stopped, the script
    exits 0. (The fake nodes exit 0 on SIGINT, as ours do.)"""
    import sys
    node = tmp_path / "node"
    node.write_text(f"#!{sys.executable}\nimport signal, sys, time\n"
                    "signal.signal(signal.SIGINT, lambda *_: sys.exit(0))\ntime.sleep(300)\n")
    node.chmod(0o755)
    pids = tmp_path / "pids"
    driver = tmp_path / "driver.sh"
    driver.write_text(f"""#!/bin/bash
EEZYBOT_SCRIPT=race
source {SCRIPTS / "lib.sh"}
EEZYBOT_BIN={tmp_path}
eezybot_start node
"$EEZYBOT_BIN/node" --ros-args &
echo "${{EEZYBOT_PIDS[0]}} $!" > {pids}
kill -INT $$
EEZYBOT_PIDS+=($!)
EEZYBOT_NAMES+=(node)
eezybot_wait
""")
    driver.chmod(0o755)
    # (SIGINT as a user's shell has it: the test command's runner ignores it, and bash
    # cannot trap a signal ignored when it started)
    proc = subprocess.Popen([str(driver)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, preexec_fn=default_sigint)
    try:
        out, _ = proc.communicate(timeout=60)  # (the bound only ends a failure: it hung)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, out
    recorded, unrecorded = map(int, pids.read_text().split())
    assert not group_alive(proc.pid), out
    assert "stopping node" in out, out
    for pid in (recorded, unrecorded):
        assert not Path(f"/proc/{pid}").exists() or "Z" in Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]


def test_a_node_that_dies_stops_the_others(domain):
    """When one node exits (here serial_node: an unusable port argument), the script
    stops the rest and exits with that node's code."""
    s = Script("run_graph.sh", "-p", "baud:=-1", env={"ROS_DOMAIN_ID": str(domain), "SERIAL_PORT": "mock"})
    try:
        code = s.proc.wait(30)
    finally:
        if s.proc.poll() is None:
            s.stop()
    assert code != 0
    assert "serial_node exited" in s.output() or "exited (code" in s.output(), s.output()


def test_run_graph_loads_the_calibration_the_wizard_saved(domain, tmp_path):
    """A calibration saved by the wizard ($XDG_CONFIG_HOME/eezybot/arm.yaml) is what
    run_graph.sh gives compute_ik, serial_node and gui_bridge (`arm_config`), and it
    says so; ARM_CONFIG= (empty) asks for the shipped one instead."""
    saved = tmp_path / "eezybot" / "arm.yaml"
    saved.parent.mkdir()
    shutil.copy(Path(__file__).resolve().parent.parent / "config" / "arm.yaml", saved)
    env = {"ROS_DOMAIN_ID": str(domain), "SERIAL_PORT": "mock", "XDG_CONFIG_HOME": str(tmp_path)}
    s = Script("run_graph.sh", env=env)
    try:
        nodes = s.nodes(4)
        for node in ("compute_ik", "serial_node", "gui_bridge"):
            assert f"arm_config:={saved}" in nodes[node], (node, nodes[node])
        assert not any(a.startswith("arm_config:=") for a in nodes["state_publisher"])
        assert f"arm configuration: {saved}" in s.output()
    finally:
        code = s.stop()
    assert code == 0, s.output()
    s = Script("run_graph.sh", env={**env, "ARM_CONFIG": ""})
    try:
        nodes = s.nodes(4)
        assert not any(a.startswith("arm_config:=") for argv in nodes.values() for a in argv), nodes
        assert "arm configuration: the shipped config/arm.yaml" in s.output()
    finally:
        code = s.stop()
    assert code == 0, s.output()
