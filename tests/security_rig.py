"""Helpers of tests/test_security.py (SROS2, issue 18): the secured interop peer, the
keystores, the enclaves a test spoils on purpose, and wire captures.

- `peer_binary()` builds tests/interop/sros2_peer/sros2_peer.cpp (Debian's Fast DDS 2.9,
  which has the DDS Security plugins the PyPI wheels lack) into target/sros2_peer/<hash>/,
  once per source version.
- `SecurePeer` runs it (optionally in a network namespace of twohost.py) and speaks its
  line protocol: publishes CDR payloads, collects what it receives and discovers.
- `make_keystore()` makes a keystore with launch_scripts/keystore.sh; `Keystore` derives
  enclaves from it: permissions re-signed without a topic, an expired certificate, a
  corrupt key, another CA.
- `Capture` runs tcpdump on an interface of a namespace.
"""
import fcntl
import hashlib
import os
import re
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

from conftest import OUTPUT, REPO, TOPICS

PEER_SRC = REPO / "tests" / "interop" / "sros2_peer" / "sros2_peer.cpp"
PEER_BUILD = ["g++", "-std=c++17", "-O1", "-Wall"]
PEER_LIBS = ["-lfastrtps", "-lfastcdr"]
KEYSTORE_SH = REPO / "launch_scripts" / "keystore.sh"
ENCLAVE_FILES = ("identity_ca.cert.pem", "cert.pem", "key.pem", "permissions_ca.cert.pem",
                 "governance.p7s", "permissions.p7s")


# ---------------------------------------------------------------------------------------
# the peer

def peer_binary():
    """The built peer, built now if this version of its source has not been (quietly;
    the compiler's output only in the exception if it fails)."""
    key = hashlib.sha256(PEER_SRC.read_bytes() + " ".join(PEER_BUILD + PEER_LIBS).encode()).hexdigest()[:12]
    out_dir = REPO / "target" / "sros2_peer" / key
    exe = out_dir / "sros2_peer"
    if exe.exists():
        return exe
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another pytest process may be building it
        if not exe.exists():
            tmp = out_dir / f"sros2_peer.{os.getpid()}"
            r = subprocess.run([*PEER_BUILD, "-o", str(tmp), str(PEER_SRC), *PEER_LIBS], capture_output=True, text=True)
            if r.returncode != 0:
                raise RuntimeError(f"building {PEER_SRC.name} failed (libfastrtps-dev: launch_scripts/setup_env.sh):\n"
                                   f"{r.stdout}{r.stderr}")
            tmp.rename(exe)
    return exe


def dds_type(ros_type):
    """`sensor_msgs/msg/JointState` -> `sensor_msgs::msg::dds_::JointState_` (the DDS type
    name rmw gives a ROS message type)."""
    package, kind, name = ros_type.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def dds_topic(topic):
    """A ROS topic name of the contract (`xyz_target`) -> its DDS topic (`rt/xyz_target`)."""
    return "rt/" + topic.lstrip("/")


class SecurePeer:
    """sros2_peer with an enclave (or none: plain DDS), publishing and subscribing our
    topics by their contract names (`xyz_target`)."""

    def __init__(self, domain, enclave=None, pubs=(), subs=(), netns=None, name="sros2_peer"):
        OUTPUT.mkdir(parents=True, exist_ok=True)
        self.name = name
        self.err_path = OUTPUT / f"{name}-{os.getpid()}-{time.monotonic_ns()}.err"
        self.err = open(self.err_path, "w")
        argv = [str(peer_binary()), "--domain", str(domain), "--name", name]
        if enclave is not None:
            argv += ["--enclave", str(enclave)]
        for flag, topics in (("--pub", pubs), ("--sub", subs)):
            for t in topics:
                argv += [flag, dds_topic(t), dds_type(TOPICS[t]["type"])]
        if netns:
            argv = ["ip", "netns", "exec", netns, *argv]
        self.lines = []  # (monotonic time, line)
        self._cv = threading.Condition()
        self.proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.err,
                                     text=True, bufsize=1)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            with self._cv:
                self.lines.append((time.monotonic(), line.rstrip("\n")))
                self._cv.notify_all()

    # ---- what it said
    def said(self, prefix):
        with self._cv:
            return [(t, line) for t, line in self.lines if line.startswith(prefix)]

    def wait(self, predicate, timeout):
        """Until predicate() (over this peer's lines) holds, or the timeout: its value."""
        end = time.monotonic() + timeout
        with self._cv:
            while not predicate():
                left = end - time.monotonic()
                if left <= 0 or (self.proc.poll() is not None and not self._reader.is_alive()):
                    break
                self._cv.wait(min(left, 0.1))
        return predicate()

    def ready(self):
        return bool(self.said("ready"))

    def wait_ready(self, timeout=10):
        if not self.wait(self.ready, timeout):
            raise AssertionError(f"{self.name} did not start (exit {self.proc.poll()}): {self.stderr()}")

    def matched(self, topic, kind):
        """How many remote endpoints match our `kind` ("pub"/"sub") of `topic` now."""
        found = self.said(f"matched {dds_topic(topic)} {kind} ")
        return int(found[-1][1].rsplit(" ", 1)[1]) if found else 0

    def received(self, topic):
        """[(monotonic time, payload bytes)] of `topic`, in arrival order."""
        prefix = f"recv {dds_topic(topic)} "
        return [(t, bytes.fromhex(line[len(prefix):])) for t, line in self.said(prefix)]

    def remote_endpoints(self):
        """{(writer|reader, DDS topic)} of the other participants it discovered."""
        return {(line.split(" ")[0], line.split(" ")[1]) for _, line in self.said("writer ") + self.said("reader ")}

    def authenticated(self):
        return {line.split(" ")[2] for _, line in self.said("auth ok ")}

    def auth_failed(self):
        return {line.split(" ")[2] for _, line in self.said("auth failed ")}

    def stderr(self):
        if not self.err.closed:
            self.err.flush()
        return self.err_path.read_text()

    # ---- doing
    def publish(self, topic, payload):
        self.proc.stdin.write(f"{dds_topic(topic)} {bytes(payload).hex()}\n")
        self.proc.stdin.flush()

    def close(self, timeout=10):
        """EOF on stdin ends it: its exit status."""
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._reader.join(5)
        self.err.close()
        return self.proc.returncode


# ---------------------------------------------------------------------------------------
# payloads (rclpy's own serialization: tests/interop/cdr.py)

def point_target(x, y, z, stamp=None, frame="base_link"):
    """A PointStamped target's CDR, stamped `stamp` (wall seconds, default now): returns
    (payload, (sec, nanosec))."""
    from geometry_msgs.msg import PointStamped

    from interop import cdr

    t = time.time() if stamp is None else stamp
    m = PointStamped()
    m.header.frame_id = frame
    m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t - int(t)) * 1e9)
    m.point.x, m.point.y, m.point.z = float(x), float(y), float(z)
    return cdr.serialize(m), (m.header.stamp.sec, m.header.stamp.nanosec)


def joint_state(payload):
    """A sensor_msgs/JointState from its CDR."""
    from sensor_msgs.msg import JointState

    from interop import cdr

    return cdr.deserialize(payload, JointState())


def stamp(msg):
    return msg.header.stamp.sec, msg.header.stamp.nanosec


# ---------------------------------------------------------------------------------------
# keystores

def _run(argv, **kw):
    r = subprocess.run([str(a) for a in argv], capture_output=True, text=True, **kw)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(str(a) for a in argv)} exited {r.returncode}:\n{r.stdout}{r.stderr}")
    return r


def make_keystore(path, *enclaves):
    """A keystore made by launch_scripts/keystore.sh (its CAs new: two keystores are two
    strangers), with its default enclaves and `enclaves` (`/eezybot/tools`) besides."""
    if not KEYSTORE_SH.exists():
        raise FileNotFoundError(f"{KEYSTORE_SH} is missing")
    _run([KEYSTORE_SH, path])
    for e in enclaves:
        _run([KEYSTORE_SH, path, "--enclave", e])
    return Keystore(path)


def security_env(keystore, enclave=None, strategy="Enforce"):
    """The environment that turns SROS2 on for one of our nodes (the enclave through
    ROS_SECURITY_ENCLAVE_OVERRIDE when given; else the node's --enclave argument)."""
    env = {"ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": strategy,
           "ROS_SECURITY_KEYSTORE": str(keystore.root if isinstance(keystore, Keystore) else keystore)}
    if enclave is not None:
        env["ROS_SECURITY_ENCLAVE_OVERRIDE"] = enclave
    return env


NO_SECURITY = {"ROS_SECURITY_ENABLE": "", "ROS_SECURITY_STRATEGY": "", "ROS_SECURITY_KEYSTORE": "",
               "ROS_SECURITY_ENCLAVE_OVERRIDE": ""}


class Keystore:
    """An SROS2 keystore directory: public/, private/, enclaves/."""

    def __init__(self, root):
        self.root = Path(root)

    def enclave(self, name):
        """The directory of enclave `/eezybot/pc`."""
        return self.root / "enclaves" / name.strip("/")

    def _ca(self, which):
        """(certificate, key) of the identity or permissions CA."""
        cert = self.root / "public" / f"{which}_ca.cert.pem"
        key = self.root / "private" / f"{which}_ca.key.pem"
        for p in (cert, key):
            if not p.exists():
                raise FileNotFoundError(f"{p}: not a keystore of the SROS2 layout")
        return cert, key

    def copy_enclave(self, base, name):
        """A new enclave `name` with `base`'s files (same certificate and grant)."""
        dst = self.enclave(name)
        if dst.exists():
            shutil.rmtree(dst)
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copytree(self.enclave(base), dst)
        return dst

    def sign(self, xml_path, p7s_path):
        """S/MIME-sign a governance or permissions document with the permissions CA, as
        sros2 does."""
        cert, key = self._ca("permissions")
        _run(["openssl", "smime", "-sign", "-text", "-in", xml_path, "-out", p7s_path, "-signer", cert, "-inkey", key])

    def without_topic(self, base, name, topic, kind="publish"):
        """Enclave `name`: `base` with permissions re-signed that no longer let it
        `kind` (publish/subscribe) DDS topic `rt/<topic>`."""
        dst = self.copy_enclave(base, name)
        xml = (dst / "permissions.xml").read_text()
        section = re.compile(rf"(<{kind}>.*?</{kind}>)", re.S)
        target = re.compile(rf"\s*<topic>{re.escape(dds_topic(topic))}</topic>")
        if not any(target.search(s) for s in section.findall(xml)):
            raise AssertionError(f"{base}'s permissions do not {kind} {dds_topic(topic)}: nothing to take away")
        xml = section.sub(lambda m: target.sub("", m.group(1)), xml)
        (dst / "permissions.xml").write_text(xml)
        self.sign(dst / "permissions.xml", dst / "permissions.p7s")
        return dst

    def with_expired_certificate(self, base, name):
        """Enclave `name`: `base` with its certificate re-issued by the identity CA (same key,
        same subject) valid only in January 2025."""
        dst = self.copy_enclave(base, name)
        cert, key = self._ca("identity")
        subject = _run(["openssl", "x509", "-in", dst / "cert.pem", "-noout", "-subject", "-nameopt", "RFC2253"]).stdout
        cn = subject.strip().split("CN=", 1)[1].split(",")[0]
        work = dst / ".ca"
        work.mkdir()
        (work / "index.txt").write_text("")
        (work / "serial").write_text("%x\n" % (int(time.time() * 1000) | 1))
        (work / "ca.cnf").write_text(
            "[ca]\ndefault_ca=d\n[d]\ndatabase=index.txt\nnew_certs_dir=.\nserial=serial\n"
            "default_md=sha256\npolicy=p\nunique_subject=no\n[p]\ncommonName=supplied\n")
        _run(["openssl", "req", "-new", "-key", dst / "key.pem", "-subj", "/CN=" + cn.replace("/", "\\/"),
              "-out", work / "req.csr"])
        _run(["openssl", "ca", "-batch", "-config", "ca.cnf", "-cert", cert, "-keyfile", key, "-in", "req.csr",
              "-out", dst / "cert.pem", "-startdate", "20250101000000Z", "-enddate", "20250201000000Z", "-notext"],
             cwd=work)
        shutil.rmtree(work)
        return dst

    def with_corrupt_key(self, base, name):
        """Enclave `name`: `base` with key.pem's base64 body garbled (still PEM-shaped)."""
        dst = self.copy_enclave(base, name)
        lines = (dst / "key.pem").read_text().splitlines()
        body = [i for i, line in enumerate(lines) if line and not line.startswith("-----")]
        for i in body[:2]:
            lines[i] = "A" * len(lines[i])
        (dst / "key.pem").write_text("\n".join(lines) + "\n")
        return dst

    def with_identity_ca_of(self, base, name, other):
        """Enclave `name`: `base` trusting `other` keystore's identity CA instead of its own
        (its certificate was not issued by the CA it names)."""
        dst = self.copy_enclave(base, name)
        shutil.copy(other.root / "public" / "identity_ca.cert.pem", dst / "identity_ca.cert.pem")
        return dst


# ---------------------------------------------------------------------------------------
# the wire

class Capture:
    """tcpdump on `iface` of namespace `netns` (UDP, whole packets) into `path`."""

    def __init__(self, netns, iface, path):
        self.path = Path(path)
        self.log = open(self.path.with_suffix(".log"), "w+")
        self.proc = subprocess.Popen(["ip", "netns", "exec", netns, "tcpdump", "-i", iface, "-s", "0", "-U", "-n",
                                      "-w", str(self.path), "udp"], stdout=self.log, stderr=subprocess.STDOUT)
        end = time.monotonic() + 10
        while time.monotonic() < end:
            if "listening on" in self.path.with_suffix(".log").read_text():
                return
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        raise RuntimeError(f"tcpdump did not start: {self.path.with_suffix('.log').read_text()}")

    def stop(self):
        """Ends the capture: the pcap file's bytes."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.close()
        return self.path.read_bytes()

    def packets(self):
        """How many packets tcpdump says it captured."""
        m = re.search(r"(\d+) packets captured", self.path.with_suffix(".log").read_text())
        return int(m.group(1)) if m else None
