"""Shared fixtures: binaries, a private ROS_DOMAIN_ID per test, real rclpy observers,
and launching our nodes as real processes."""
import fcntl
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

OUTPUT = Path(os.environ.get("EEZYBOT_TEST_OUTPUT", REPO / "test-output"))

COMMANDS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def bin_path(rel):
    """A binary of ours, from EEZYBOT_BIN_DIR (default target/debug)."""
    path = Path(os.environ.get("EEZYBOT_BIN_DIR", REPO / "target" / "debug")) / rel
    if not path.exists():
        raise FileNotFoundError(f"{path} is missing: run `cargo build --workspace --bins --examples` (tests/run_all.sh does)")
    return str(path)


class DomainLease:
    """A ROS_DOMAIN_ID no other test on this machine holds (flock on a file per id)."""

    DIR = Path("/tmp/eezybot-test-domains")

    def __init__(self):
        self.DIR.mkdir(exist_ok=True)
        start = (os.getpid() * 7) % 100
        for i in range(130):
            domain = 100 + (start + i) % 130
            f = open(self.DIR / f"{domain}.lock", "w")
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.close()
                continue
            self.file, self.id = f, domain
            return
        raise RuntimeError("no free ROS domain id for the test")

    def release(self):
        self.file.close()


@pytest.fixture
def domain():
    lease = DomainLease()
    yield lease.id
    lease.release()


@pytest.fixture
def other_domain(domain):
    lease = DomainLease()
    yield lease.id
    lease.release()


class Observer:
    """A real rclpy node in its own context and domain."""

    def __init__(self, domain_id, name="observer"):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def sub(self, topic, msg_type, qos=COMMANDS):
        got = []
        self.node.create_subscription(msg_type, topic, lambda m: got.append((time.monotonic(), m)), qos)
        return got

    def pub(self, topic, msg_type, qos=COMMANDS):
        return self.node.create_publisher(msg_type, topic, qos)

    def spin_for(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.02, max(0.0, end - time.monotonic())))

    def spin_until(self, predicate, timeout=10.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.02)
        return predicate()

    def wait_matched(self, publisher, timeout=15.0):
        """Our publisher is matched by the node's subscription."""
        assert self.spin_until(lambda: publisher.get_subscription_count() > 0, timeout), f"nobody subscribes {publisher.topic_name}"

    def wait_publisher(self, topic, timeout=15.0):
        """Someone publishes `topic` (so our subscription is matched from their side too)."""
        assert self.spin_until(lambda: self.node.count_publishers(topic) > 0, timeout), f"nobody publishes {topic}"
        self.spin_for(0.3)  # let the remote writer see our reader too

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def observer(domain):
    o = Observer(domain)
    yield o
    o.close()


class NodeProcess:
    """One of our binaries, running with its own ROS_DOMAIN_ID."""

    def __init__(self, name, args, domain_id, env=None):
        OUTPUT.mkdir(parents=True, exist_ok=True)
        self.log_path = OUTPUT / f"{name}-{os.getpid()}-{time.monotonic_ns()}.log"
        self.log = open(self.log_path, "w")
        full_env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), **(env or {}))
        self.proc = subprocess.Popen([bin_path(name), *args], stdout=self.log, stderr=subprocess.STDOUT, env=full_env)

    def stop(self, sig=signal.SIGINT, timeout=10):
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.close()
        return self.proc.returncode

    def output(self):
        self.log.flush()
        return self.log_path.read_text()


@pytest.fixture
def launch(domain):
    """launch(binary, *args, domain_id=None) starts a node; all are stopped with SIGINT afterwards
    and must exit with 0."""
    procs = []

    def start(name, *args, domain_id=None, env=None):
        p = NodeProcess(name, list(args), domain if domain_id is None else domain_id, env)
        procs.append(p)
        return p

    yield start
    codes = [(p.log_path.name, p.stop()) for p in procs]
    bad = [(n, c) for n, c in codes if c != 0]
    assert not bad, f"nodes did not exit cleanly: {bad}"
