"""Shared fixtures: binaries, a private ROS_DOMAIN_ID per test, real rclpy observers,
and launching our nodes as real processes."""
import faulthandler
import fcntl
import importlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
import twohost  # noqa: E402  (after the path insert)

OUTPUT = Path(os.environ.get("EEZYBOT_TEST_OUTPUT", REPO / "test-output"))

# The contract (topics, actions, services), declared once in libs/ros_plumbing/src/topics.rs;
# this file is generated from it and checked against it by libs/ros_plumbing/tests/contract.rs.
CONTRACT = json.loads((REPO / "tests" / "data" / "topics.json").read_text())
TOPICS = {t["name"]: t for t in CONTRACT["topics"]}
ACTIONS = {a["name"]: a for a in CONTRACT["actions"]}
SERVICES = {s["name"]: s for s in CONTRACT["services"]}


def topic_entry(topic):
    """Our topic `topic` (`/arm2/estop`, `estop`, `/arm2/camera/camera_info`) in the
    contract, or None: the longest tail of its name that the contract has (names with a
    slash, such as `leader/deadman`, included)."""
    parts = topic.strip("/").split("/")
    for i in range(len(parts)):
        t = TOPICS.get("/".join(parts[i:]))
        if t is not None:
            return t
    return None


def qos(topic):
    """The QoS of one of our topics as the contract declares it."""
    t = topic_entry(topic)
    if t is None:
        raise KeyError(f"{topic} is not a topic of the contract (tests/data/topics.json)")
    return QoSProfile(
        depth=t["depth"],
        reliability={"reliable": ReliabilityPolicy.RELIABLE, "best effort": ReliabilityPolicy.BEST_EFFORT}[t["reliability"]],
        durability={"volatile": DurabilityPolicy.VOLATILE, "transient-local": DurabilityPolicy.TRANSIENT_LOCAL}[t["durability"]],
    )


def msg_type(topic):
    """The rclpy message class of one of our topics (`std_msgs/msg/Bool` -> Bool)."""
    package, _, name = topic_entry(topic)["type"].split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


# the two profiles of the contract, for topics that are not ours (`/rosout`) and old call sites
COMMANDS = qos("xyz_target")  # reliable, volatile, keep last 10
LATCHED = qos("estop")  # reliable, transient-local, keep last 1
# rcl's /rosout: reliable, transient-local, keep last 1000. A reader of less depth loses
# lines whenever the test does not spin for a while (a browser step on a busy host).
ROSOUT = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
# a reader that must see every sample of a stream (the contract's depth is 10): a test
# starved of CPU cannot take them as they come, and a reliable writer hands over what
# the reader's history holds
EVERY = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def default_sigint():
    """A child's `preexec_fn`: SIGINT as a terminal delivers it, even when this harness
    runs in the background (a shell starts background jobs with SIGINT ignored, and a
    launch script, bash, cannot trap a signal that was ignored when it started)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


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

    # How long discovery may take before a test fails (it takes 0.2-1.5 s here).
    MATCH_TIMEOUT = 10.0

    def __init__(self, domain_id, name="observer", netns=None):
        self.netns = netns  # a network namespace (twohost.py) to live in, or None
        with twohost.netns(netns):
            self.context = rclpy.Context()
            rclpy.init(context=self.context, domain_id=domain_id)
            self.node = rclpy.create_node(name, context=self.context)
            self.executor = SingleThreadedExecutor(context=self.context)
            self.executor.add_node(self.node)

    @staticmethod
    def _qos(topic, profile):
        """`profile` if given, else the contract's for our topics, else COMMANDS."""
        if profile is not None:
            return profile
        return qos(topic) if topic_entry(topic) else COMMANDS

    def sub(self, topic, msg_type, qos=None):
        got = []
        with twohost.netns(self.netns):
            self.node.create_subscription(msg_type, topic, lambda m: got.append((time.monotonic(), m)), self._qos(topic, qos))
        return got

    def pub(self, topic, msg_type, qos=None):
        with twohost.netns(self.netns):
            return self.node.create_publisher(msg_type, topic, self._qos(topic, qos))

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

    def _wait_discovery(self, predicate, what):
        """Discovery between our nodes (RustDDS) and rclpy (Fast DDS) is not retried or
        worked around: a node that is not discovered in time fails the test."""
        if not self.spin_until(predicate, self.MATCH_TIMEOUT):
            raise AssertionError(f"{what} within {self.MATCH_TIMEOUT} s (discovery failed)")

    def wait_matched(self, publisher):
        """Our publisher is matched by the node's subscription."""
        self._wait_discovery(lambda: publisher.get_subscription_count() > 0, f"nobody subscribes {publisher.topic_name}")
        # the node's reader may match our writer a moment after ours matched it; until
        # then a volatile reader misses what is published. A guess, not an event: nothing
        # rclpy shows tells when a RustDDS reader has matched our writer (the two SEDP
        # directions are independent; wait_for_all_acked was measured to prove nothing
        # toward RustDDS readers). A test that must not lose its first sample sends it
        # again until its effect comes (a sentinel), or waits for the node's own report.
        self.spin_for(0.3)

    def wait_publisher(self, topic):
        """Someone publishes `topic` (so our subscription is matched from their side too)."""
        self._wait_discovery(lambda: self.node.count_publishers(topic) > 0, f"nobody publishes {topic}")
        self.spin_for(0.3)  # let the remote writer see our reader too

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def latest_status(diags, node):
    """The newest DiagnosticStatus of `node` (its name starts with it) among `diags`, an
    Observer.sub list of DiagnosticArray (other nodes publish there too), or None."""
    for _, arr in reversed(diags):
        for s in arr.status:
            if s.name.startswith(node):
                return s
    return None


def status_values(status):
    """A DiagnosticStatus's values as {key: value} ({} for None)."""
    return {kv.key: kv.value for kv in status.values} if status is not None else {}


@pytest.fixture
def observer(domain):
    o = Observer(domain)
    yield o
    o.close()


class NodeProcess:
    """One of our binaries (or a launch script, given by path), running with its own
    ROS_DOMAIN_ID, optionally in a network namespace."""

    def __init__(self, name, args, domain_id, env=None, netns=None):
        OUTPUT.mkdir(parents=True, exist_ok=True)
        self.name = Path(name).name
        self.log_path = OUTPUT / f"{self.name}-{os.getpid()}-{time.monotonic_ns()}.log"
        self.log = open(self.log_path, "w")
        exe = str(name) if "/" in str(name) else bin_path(name)
        self.argv = [*(["ip", "netns", "exec", netns] if netns else []), exe, *args]
        self.env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), **(env or {})}
        self.proc = subprocess.Popen(self.argv, stdout=self.log, stderr=subprocess.STDOUT, env=self.env,
                                     preexec_fn=default_sigint)
        # the exit status the launch fixture expects at the end (SIGKILLed by the test: -9)
        self.expect_exit = 0

    def kill_hard(self, timeout=10):
        """SIGKILL, as a crash or a pulled plug would end it; the launch fixture then
        expects -9 of it instead of a clean exit."""
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout)
        self.expect_exit = -signal.SIGKILL

    def stop(self, sig=signal.SIGINT, timeout=10):
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.dump_stacks()
                self.proc.kill()
                self.proc.wait(10)
        self.log.close()
        return self.proc.returncode

    def output(self):
        if not self.log.closed:  # (stopped: flushed and closed already)
            self.log.flush()
        return self.log_path.read_text()

    def dump_stacks(self):
        """A process that ignored the stop signal: append what it is (`info proc`: a
        binary of ours, or the harness's forked child before exec) and every thread's
        stack to its log, before it is killed."""
        self.log.write(f"\n--- did not stop within the timeout; pid {self.proc.pid}:\n")
        self.log.flush()
        try:
            subprocess.run(["gdb", "-p", str(self.proc.pid), "-batch", "-ex", "info proc", "-ex", "thread apply all bt"],
                           stdout=self.log, stderr=subprocess.STDOUT, timeout=60)
        except (OSError, subprocess.TimeoutExpired) as e:
            self.log.write(f"(no stacks: {e})\n")


CHROMIUM = "/usr/bin/chromium"
# --enable-unsafe-swiftshader: WebGL (the 3D view) through SwiftShader, Chromium's software
# renderer, without the deprecation warning of the automatic fallback
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


@pytest.fixture(scope="module")
def browser():
    """Chromium through Playwright, one per test module."""
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture
def launch(domain, observer):
    """launch(binary, *args, domain_id=None) starts a node; all are stopped with SIGINT afterwards
    and must exit with 0."""
    procs = []

    def start(name, *args, domain_id=None, env=None):
        p = NodeProcess(name, list(args), domain if domain_id is None else domain_id, env)
        procs.append(p)
        return p

    yield start
    codes = [(p.log_path.name, p.stop(), p.expect_exit) for p in procs]
    bad = [(n, c) for n, c, expected in codes if c != expected]
    assert not bad, f"nodes did not exit cleanly: {bad}"


class TfListener:
    """Reads `tf` and `tf_static` with Cyclone DDS (there is no tf2_msgs wheel for rclpy)
    and keeps the latest transform of every child frame."""

    def __init__(self, domain_id, ns=""):
        from cyclonedds.core import Policy, Qos
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic
        from cyclonedds.util import duration

        from interop.idl import TFMessage

        self.participant = DomainParticipant(domain_id)
        # the contract's QoS of tf (volatile) and tf_static (transient-local)
        reliable = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(TOPICS["tf"]["depth"]))
        latched = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
                      Policy.History.KeepLast(TOPICS["tf_static"]["depth"]))
        self.tf_reader = DataReader(self.participant, Topic(self.participant, f"rt{ns}/tf", TFMessage), qos=reliable)
        self.static_reader = DataReader(self.participant, Topic(self.participant, f"rt{ns}/tf_static", TFMessage), qos=latched)
        self.dynamic = {}   # child -> TransformStamped
        self.static = {}
        self.messages = []  # every tf message, in arrival order

    def poll(self):
        for msg in self.static_reader.take(N=100):
            for t in msg.transforms:
                self.static[t.child_frame_id] = t
        for msg in self.tf_reader.take(N=1000):
            self.messages.append(msg)
            for t in msg.transforms:
                self.dynamic[t.child_frame_id] = t

    def transforms(self):
        self.poll()
        return {**self.static, **self.dynamic}

    def close(self):
        self.participant = None


def compose_chain(transforms, root, frame):
    """Position and rotation (quaternion xyzw) of `frame` in `root`, from child->TransformStamped."""
    def qmul(a, b):
        ax, ay, az, aw = a
        bx, by, bz, bw = b
        return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)

    def rotate(q, v):
        x, y, z, w = qmul(qmul(q, (*v, 0.0)), (-q[0], -q[1], -q[2], q[3]))
        return (x, y, z)

    chain = []
    f = frame
    while f != root:
        if f not in transforms:
            raise KeyError(f"no transform reaches {f} (from {frame} towards {root})")
        chain.append(transforms[f])
        f = transforms[f].header.frame_id
        if len(chain) > 100:
            raise RuntimeError("tf loop")
    pos, rot = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)
    for t in reversed(chain):  # root-most first
        tr, q = t.transform.translation, t.transform.rotation
        r = rotate(rot, (tr.x, tr.y, tr.z))
        pos = (pos[0] + r[0], pos[1] + r[1], pos[2] + r[2])
        rot = qmul(rot, (q.x, q.y, q.z, q.w))
    return pos, rot


# ---------------------------------------------------------------------------------------
# A per-test timeout: a test that hangs fails, with the stack where it hung, and the run
# goes on. SIGALRM raises in the main thread (where tests run) once the limit of a phase
# (setup, call, teardown) has passed; should the main thread be stuck where Python
# cannot raise (inside a C call), faulthandler dumps every thread's stack and ends the
# process a minute later, so that a run can never hang. No test here takes over 70 s.

TEST_TIMEOUT_S = float(os.environ.get("EEZYBOT_TEST_TIMEOUT", "300"))
_STDERR = 2


def phase_timeout_s(item):
    """The limit of each phase of `item`, in seconds."""
    marker = item.get_closest_marker("timeout")
    return float(marker.args[0]) if marker is not None else TEST_TIMEOUT_S


class PhaseTimedOut(Exception):
    """A test phase over its limit (raised by the SIGALRM handler)."""


def _timed_phase(item, phase):
    limit = phase_timeout_s(item)

    def expired(signum, frame):
        raise PhaseTimedOut(f"{item.nodeid}: {phase} took over {limit:.0f} s (the per-test timeout, "
                           f"tests/conftest.py; pytest.mark.timeout to change it)")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, limit)
    faulthandler.dump_traceback_later(limit + 60, exit=True, file=_STDERR)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        faulthandler.cancel_dump_traceback_later()
        signal.signal(signal.SIGALRM, previous)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item):
    yield from _timed_phase(item, "setup")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    yield from _timed_phase(item, "call")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item):
    yield from _timed_phase(item, "teardown")


# A failed test's tmp_path (servo_sim's event file, node logs, recordings) is copied to
# the test output directory after its fixtures are torn down (the simulations stopped and
# their files closed): pytest keeps only the last three runs' temporary directories, and
# every module of its own process is a run, so the evidence of a failure in a long test
# command would otherwise be gone by its end. Files over KEEP_MAX_BYTES are left out.

KEEP_MAX_BYTES = 64 << 20


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if report.when in ("setup", "call") and report.failed:
        item.eezybot_failed = True
    if report.when == "teardown" and getattr(item, "eezybot_failed", False):
        tmp = item.funcargs.get("tmp_path") if hasattr(item, "funcargs") else None
        if tmp is not None and Path(tmp).is_dir():
            _keep_failed_files(Path(tmp), OUTPUT / "failed" / re.sub(r"[^\w.-]+", "_", item.nodeid))


def _keep_failed_files(src, dest):
    for f in sorted(src.rglob("*")):
        try:
            if f.is_file() and not f.is_symlink() and f.stat().st_size <= KEEP_MAX_BYTES:
                target = dest / f.relative_to(src)
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(f, target)
        except OSError:
            pass  # a socket, a file gone meanwhile: keep the rest


# ---------------------------------------------------------------------------------------
# Tests that need root (network namespaces, TAP devices, installing into /etc) skip
# without it, with a reason that says "needs root" (NEEDS_ROOT). They are counted apart
# in the summary line ("N skipped (need root)") and listed at the end, so that a run
# without root cannot look complete.

NEEDS_ROOT = "needs root"
ROOT_SKIPPED = "skipped (need root)"


def _skip_reason(report):
    longrepr = report.longrepr
    if isinstance(longrepr, tuple) and len(longrepr) == 3:
        return str(longrepr[2])
    return str(longrepr or "")


def pytest_report_teststatus(report, config):
    if report.skipped and NEEDS_ROOT in _skip_reason(report):
        return ROOT_SKIPPED, "s", ("SKIPPED (needs root)", {"yellow": True})
    return None


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if _OWN_PROCESS_SPANS:
        # where the time of the modules in processes of their own went (the background
        # lanes run beside the rest: the session's own end is the last number here or
        # pytest's total)
        terminalreporter.write_sep("-", "modules in processes of their own (s since the session's start)")
        for module, (start, end) in sorted(_OWN_PROCESS_SPANS.items(), key=lambda kv: kv[1]):
            terminalreporter.write_line(f"{start:7.1f} -> {end:7.1f}  ({end - start:6.1f} s)  {Path(module).name}")
    skipped = terminalreporter.stats.get(ROOT_SKIPPED, [])
    if not skipped:
        return
    files = sorted({r.nodeid.split("::")[0] for r in skipped})
    n = len(skipped)
    terminalreporter.write_sep("=", f"{n} test{'s' if n != 1 else ''} did not run: {'they need' if n != 1 else 'it needs'} root",
                               yellow=True, bold=True)
    terminalreporter.write_line(f"not run here: {', '.join(files)}; run tests/run_all.sh as root for the whole suite")


# ---------------------------------------------------------------------------------------
# Modules whose rclpy participants live in network namespaces run in a pytest process of
# their own. Fast DDS keeps process-wide state about the network interfaces: a
# participant created in namespace `pc` after one in the root namespace announced the
# root namespace's address (192.0.2.2 here), which nobody in `pc` can reach, so it
# discovered nothing; and the other way round. Mark such a module with
# `pytestmark = [pytest.mark.own_process, ...]`.

# Every process a test starts is kept from the user's saved calibration: gui_bridge's
# wizard saves to $XDG_CONFIG_HOME/eezybot/arm.yaml, and the launch scripts read it when
# it exists. So from the session's start $XDG_CONFIG_HOME is an empty directory of the
# session's own, whatever the caller's was; a test that needs its own sets it
# (monkeypatch.setenv, or a process's env=). Removed at the session's end.
_XDG_CONFIG_HOME = None


def pytest_configure(config):
    global _STDERR, _XDG_CONFIG_HOME
    _XDG_CONFIG_HOME = tempfile.mkdtemp(prefix="eezybot-test-xdg-")
    os.environ["XDG_CONFIG_HOME"] = _XDG_CONFIG_HOME
    config.addinivalue_line("markers", "own_process: run this module's tests in a pytest process of their own")
    config.addinivalue_line("markers", "background(seconds=60): (with own_process) that process may run alongside the "
                                       "other tests; `seconds`, about how long it takes, orders the lanes (longest first)")
    config.addinivalue_line("markers", "alone: (with own_process) that process runs while no background module runs: "
                                       "something it asserts depends on how busy the host is")
    config.addinivalue_line("markers", "timeout(seconds): this test's limit for each of setup, call and teardown "
                                       f"(default {TEST_TIMEOUT_S:.0f} s, EEZYBOT_TEST_TIMEOUT)")
    _STDERR = os.dup(2)  # the terminal's stderr (output capture is suspended here)


_OWN_PROCESS_RESULTS = {}
# Such a module marked `background` too (test_link_outages.py: link outages, mostly
# waited out, whose checks do not depend on how busy the host is) runs in a pytest
# process of its own from the end of collection, alongside the other tests; its results
# are reported where pytest reaches them. Background modules run in BACKGROUND_LANES
# lanes, each taking the next module when its last one ends, the longest first: a
# module's marker says about how long it takes (`pytest.mark.background(seconds=60)`).
# EEZYBOT_BACKGROUND_LANES sets the number; EEZYBOT_OWN_PROCESS_SERIAL=1 runs each where
# pytest reaches it instead, as every other own_process module is. A module marked
# `alone` (test_two_hosts.py: the partition's count of stale commands depends on how
# busy the host is) runs after the other foreground modules, once the lanes are done.
BACKGROUND_LANES = int(os.environ.get("EEZYBOT_BACKGROUND_LANES", "2"))
_OWN_PROCESS_DONE = {}  # module -> threading.Event, set when its results are in
_OWN_PROCESS_RUNNING = []  # the module processes under way, to end them if the session ends first
_OWN_PROCESS_SPANS = {}  # module -> (start, end), seconds since the session started
_SESSION_START = time.monotonic()


def _background_seconds(item):
    marker = item.get_closest_marker("background")
    return float(marker.kwargs.get("seconds", 60)) if marker is not None else 0.0


def _lanes_on(config):
    return not (os.environ.get("EEZYBOT_OWN_PROCESS") or os.environ.get("EEZYBOT_OWN_PROCESS_SERIAL")
                or config.option.collectonly)


def _in_background(item):
    return item.get_closest_marker("own_process") is not None and item.get_closest_marker("background") is not None


def _alone(item):
    return item.get_closest_marker("own_process") is not None and item.get_closest_marker("alone") is not None


def pytest_collection_modifyitems(session, config, items):
    """The background modules' tests are reported last: where pytest reaches one before its
    lane has run it, it waits for it, and the modules after it would wait too. Before them
    come the modules that run alone (`alone`): they wait for the lanes to finish."""
    if _lanes_on(config):
        items[:] = ([i for i in items if not _in_background(i) and not _alone(i)]
                    + [i for i in items if _alone(i) and not _in_background(i)]
                    + [i for i in items if _in_background(i)])


def pytest_collection_finish(session):
    if not _lanes_on(session.config):
        return
    first_items = {}
    for item in session.items:
        if _in_background(item):
            first_items.setdefault(str(item.fspath), item)
    for module in first_items:
        _OWN_PROCESS_DONE[module] = threading.Event()
    todo = sorted(first_items.items(), key=lambda kv: -_background_seconds(kv[1]))
    lock = threading.Lock()

    def lane():
        while True:
            with lock:
                if not todo:
                    return
                module, item = todo.pop(0)
            try:
                _run_module_in_own_process(item)
            finally:
                _OWN_PROCESS_DONE[module].set()

    for n in range(min(BACKGROUND_LANES, len(todo))):
        threading.Thread(target=lane, name=f"background lane {n}", daemon=True).start()


def pytest_unconfigure(config):
    for proc in _OWN_PROCESS_RUNNING:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(10)
    if _XDG_CONFIG_HOME is not None:
        shutil.rmtree(_XDG_CONFIG_HOME, ignore_errors=True)


def _run_module_in_own_process(item):
    module = str(item.fspath)
    if module not in _OWN_PROCESS_RESULTS:
        ids = [i.nodeid for i in item.session.items if str(i.fspath) == module]
        with tempfile.TemporaryDirectory() as tmp:
            junit = Path(tmp) / "junit.xml"
            started = time.monotonic()
            # each test there has its own timeout; this bounds the whole module's process
            limit = sum(3 * phase_timeout_s(i) for i in item.session.items if str(i.fspath) == module) + 120
            argv = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "-s", "-o", "junit_logging=all",
                    f"--junitxml={junit}", *ids]
            child = subprocess.Popen(argv, cwd=str(item.session.config.rootpath), stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env={**os.environ, "EEZYBOT_OWN_PROCESS": "1"})
            _OWN_PROCESS_RUNNING.append(child)
            try:
                out, err = child.communicate(timeout=limit)
            except subprocess.TimeoutExpired:
                child.kill()
                try:
                    out, err = child.communicate(timeout=30)
                except subprocess.TimeoutExpired:  # its nodes hold the pipes
                    out, err = "", ""
                err += f"\n(killed after {limit:.0f} s)"
            finally:
                _OWN_PROCESS_RUNNING.remove(child)
            proc = subprocess.CompletedProcess(argv, child.returncode, out, err)
            cases = {}
            if junit.exists():
                for case in ET.parse(junit).getroot().iter("testcase"):
                    cases[case.get("name")] = case
            _OWN_PROCESS_RESULTS[module] = (cases, proc, time.monotonic() - started)
            _OWN_PROCESS_SPANS[module] = (started - _SESSION_START, time.monotonic() - _SESSION_START)
    return _OWN_PROCESS_RESULTS[module]


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_protocol(item, nextitem):
    if os.environ.get("EEZYBOT_OWN_PROCESS") or item.get_closest_marker("own_process") is None:
        return None
    from _pytest.reports import TestReport

    item.ihook.pytest_runtest_logstart(nodeid=item.nodeid, location=item.location)
    done = _OWN_PROCESS_DONE.get(str(item.fspath))
    if done is not None:
        done.wait()  # the background run (bounded by its module's limit)
    if _alone(item) and str(item.fspath) not in _OWN_PROCESS_RESULTS:
        for background in _OWN_PROCESS_DONE.values():
            background.wait()  # (each bounded by its module's limit)
    cases, proc, _ = _run_module_in_own_process(item)
    case = cases.get(item.name)
    outcome, longrepr, duration, sections = "passed", None, 0.0, []
    if case is None:
        outcome = "failed"
        longrepr = (f"{item.nodeid} did not run in its own process (exit {proc.returncode})\n"
                    f"{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}")
    else:
        duration = float(case.get("time") or 0.0)
        for tag in ("failure", "error"):
            bad = case.find(tag)
            if bad is not None:
                outcome = "failed"
                longrepr = f"{bad.get('message', '')}\n{bad.text or ''}"
        skipped = case.find("skipped")
        if skipped is not None and outcome == "passed":
            outcome = "skipped"
            longrepr = (str(item.fspath), item.location[1] or 0, skipped.get("message", "skipped"))
        out = case.find("system-out")
        if out is not None and out.text:
            sections.append(("Captured stdout call", out.text))
    report = TestReport(item.nodeid, item.location, {k: 1 for k in item.keywords}, outcome, longrepr, "call",
                        sections=sections, duration=duration)
    item.ihook.pytest_runtest_logreport(report=report)
    item.ihook.pytest_runtest_logfinish(nodeid=item.nodeid, location=item.location)
    return True


def descendants(pid):
    """Every process below `pid` (from /proc/*/task/*/children)."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                kids = [int(c) for c in (task / "children").read_text().split()]
            except OSError:
                continue
            out += kids
            todo += kids
    return out
