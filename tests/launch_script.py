"""A script of launch_scripts/ (run_graph.sh, pc.sh, pi.sh) run as a user runs it, in a
session of its own with its output logged to test-output/, and the node processes below
it. Used by tests/test_launch_scripts.py, tests/test_keystore.py and tests/test_jaco.py;
a test module that starts scripts imports the `reap_scripts` fixture too."""
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from conftest import OUTPUT, REPO, bin_path, default_sigint, descendants

SCRIPTS = REPO / "launch_scripts"
ROS_NODES = {"compute_ik", "state_publisher", "gui_bridge", "serial_node"}
NODES = ROS_NODES | {"virtual_arduino", "twin"}

# the process groups of the scripts started (each leads a session of its own)
STARTED = []


@pytest.fixture(autouse=True)
def reap_scripts():
    """Whatever a test does or fails at, no script's process group outlives it: a node
    left running would answer the next test in the same ROS domain."""
    yield
    while STARTED:
        pgid = STARTED.pop()
        try:
            os.killpg(pgid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def node_processes(pid):
    """{pid: (binary name, argv)} of our node processes below `pid` (not the scripts' own
    short-lived helpers such as dirname or hostname)."""
    out = {}
    for kid in descendants(pid):
        try:
            exe = Path(os.readlink(f"/proc/{kid}/exe")).name
            argv = Path(f"/proc/{kid}/cmdline").read_bytes().split(b"\0")[:-1]
        except OSError:
            continue
        if exe in NODES:
            out[kid] = (exe, [a.decode() for a in argv])
    return out


def alive(pid):
    """The process runs (it exists and is not a zombie)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def left_alive(pids, timeout=10):
    """Those of `pids` still running once every one has ended or `timeout` has passed (a
    node stopped by its script may take a moment to exit; the bound only ends a failure)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and any(alive(p) for p in pids):
        time.sleep(0.05)
    return [p for p in pids if alive(p)]


def graph_ends(observer, command, command_type, answer, answer_type, nodes):
    """rclpy's ends of the graph a script started: a publisher of `command` and the list
    `answer` is received into, once both are matched and every node of `nodes` is in the
    node list."""
    pub = observer.pub(command, command_type)
    got = observer.sub(answer, answer_type)
    observer.wait_matched(pub)
    observer.wait_publisher(answer)
    assert observer.spin_until(lambda: set(nodes) <= set(observer.node.get_node_names()), 15), \
        observer.node.get_node_names()
    return pub, got


class Script:
    """launch_scripts/`name` with `args`, our binaries from EEZYBOT_BIN_DIR, the web panel
    on a free loopback port, and `env` over this environment."""

    def __init__(self, name, *args, env=None, log_prefix=""):
        OUTPUT.mkdir(parents=True, exist_ok=True)
        self.log_path = OUTPUT / f"{log_prefix}{name}-{os.getpid()}-{time.monotonic_ns()}.log"
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen([str(SCRIPTS / name), *args], stdout=self.log, stderr=subprocess.STDOUT,
                                     env={**os.environ, "EEZYBOT_BIN_DIR": str(Path(bin_path("compute_ik")).parent),
                                          "GUI_BIND": "127.0.0.1:0", **(env or {})},
                                     start_new_session=True, preexec_fn=default_sigint)
        STARTED.append(self.proc.pid)

    def output(self):
        if not self.log.closed:
            self.log.flush()
        return self.log_path.read_text()

    def wait_output(self, text, timeout=20):
        end = time.monotonic() + timeout
        while time.monotonic() < end and text not in self.output():
            if self.proc.poll() is not None:
                break
            time.sleep(0.1)
        return text in self.output()

    def running(self, n, names=NODES, timeout=20):
        """Once at least `n` node processes of `names` run below the script:
        {pid: (binary name, argv)} of them. Fails if that takes over `timeout` or the
        script exits first."""
        end = time.monotonic() + timeout
        while time.monotonic() < end and self.proc.poll() is None:
            found = {pid: p for pid, p in node_processes(self.proc.pid).items() if p[0] in names}
            if len(found) >= n:
                return found
            time.sleep(0.1)
        raise AssertionError(f"{len(node_processes(self.proc.pid))} nodes running, expected {n}"
                             f"{'' if self.proc.poll() is None else f' (the script exited with {self.proc.returncode})'}:"
                             f"\n{self.output()}")

    def children(self, n, timeout=20):
        """The pids of at least `n` node processes (the virtual Arduino's too) below the script."""
        return list(self.running(n, timeout=timeout))

    def nodes(self, n, timeout=20):
        """{ROS node binary: argv} of at least `n` ROS nodes below the script."""
        return dict(self.running(n, ROS_NODES, timeout).values())

    def stop(self, sig=signal.SIGINT, timeout=20):
        """Signal the script (if it still runs) and return its exit code; only a script
        that has not exited by `timeout` has its process group killed (so that nodes it
        left behind stay for the test to find)."""
        try:
            if self.proc.poll() is None:
                self.proc.send_signal(sig)
            return self.proc.wait(timeout)
        finally:
            if self.proc.poll() is None:
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.log.close()
