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
import math
import os
import re
import shutil
import signal
import struct
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
            r = subprocess.run([*PEER_BUILD, "-o", str(tmp), str(PEER_SRC), *PEER_LIBS], capture_output=True, text=True,
                               timeout=600)
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

    def __init__(self, domain, enclave=None, pubs=(), subs=(), netns=None, name="sros2_peer", binary=None):
        """`binary`: another program speaking sros2_peer's protocol (the RustDDS
        ros_probe example of ros_plumbing, for benchmarks); default the Fast DDS peer."""
        OUTPUT.mkdir(parents=True, exist_ok=True)
        self.name = name
        self.err_path = OUTPUT / f"{name}-{os.getpid()}-{time.monotonic_ns()}.err"
        self.err = open(self.err_path, "w")
        argv = [str(binary or peer_binary()), "--domain", str(domain), "--name", name]
        if enclave is not None:
            argv += ["--enclave", str(enclave)]
        for flag, topics in (("--pub", pubs), ("--sub", subs)):
            for t in topics:
                argv += [flag, dds_topic(t), dds_type(TOPICS[t]["type"])]
        if netns:
            argv = ["ip", "netns", "exec", netns, *argv]
        self.lines = []  # (monotonic time, line)
        self.published = []  # (topic, payload) in the order written
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

    def endpoint_participants(self, kind, topic):
        """{GUID prefix} of the participants whose `kind` ("writer"/"reader") of `topic`
        it discovered."""
        return {line.split(" ")[3] for _, line in self.said(f"{kind} {dds_topic(topic)} ")}

    def participants_named(self, name):
        """{GUID prefix} of the participants named `name` it discovered (their SPDP
        announcement, in clear even in a secured domain)."""
        return {line.split(" ")[2] for _, line in self.said("participant discovered ") if line.split(" ", 3)[3:] == [name]}

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
        self.published.append((topic, bytes(payload)))

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
            self.proc.wait(10)
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
    from conftest import bin_path

    if not KEYSTORE_SH.exists():
        raise FileNotFoundError(f"{KEYSTORE_SH} is missing")
    # the eezybot_sros2 the tests run with (target/debug), not a release build of its own
    env = {**os.environ, "EEZYBOT_BIN_DIR": str(Path(bin_path("eezybot_sros2")).parent)}
    _run([KEYSTORE_SH, path], env=env)
    for e in enclaves:
        _run([KEYSTORE_SH, path, "--enclave", e], env=env)
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
        return self.with_certificate_dates(base, name, "20250101000000Z", "20250201000000Z")

    def with_certificate_dates(self, base, name, start, end):
        """Enclave `name`: `base` with its certificate re-issued by the identity CA (same key,
        same subject, so its permissions still name it) valid from `start` to `end`
        (openssl's YYYYMMDDHHMMSSZ)."""
        dst = self.copy_enclave(base, name)
        cert, key = self._ca("identity")
        subject = _run(["openssl", "x509", "-in", dst / "cert.pem", "-noout", "-subject", "-nameopt", "RFC2253"]).stdout
        cn = subject.strip().split("CN=", 1)[1].split(",")[0]
        work = dst / ".ca"
        work.mkdir()
        (work / "index.txt").write_text("")
        (work / "serial").write_text("%016x\n" % int(time.time() * 1000))
        (work / "ca.cnf").write_text(
            "[ca]\ndefault_ca=d\n[d]\ndatabase=index.txt\nnew_certs_dir=.\nserial=serial\n"
            "default_md=sha256\npolicy=p\nunique_subject=no\n[p]\ncommonName=supplied\n")
        _run(["openssl", "req", "-new", "-key", dst / "key.pem", "-subj", "/CN=" + cn.replace("/", "\\/"),
              "-out", work / "req.csr"])
        _run(["openssl", "ca", "-batch", "-config", "ca.cnf", "-cert", cert, "-keyfile", key, "-in", "req.csr",
              "-out", dst / "cert.pem", "-startdate", start, "-enddate", end, "-notext"],
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
    """tcpdump on `iface` of namespace `netns` (UDP, or the packets of `expression`;
    whole packets; `any`: every interface of the namespace) into `path`; `promiscuous=False` leaves the interface as it is (a
    change of its flags is a network change to a browser, which then aborts its loads)."""

    def __init__(self, netns, iface, path, expression="udp", promiscuous=True):
        self.path = Path(path)
        self.log = open(self.path.with_suffix(".log"), "w+")
        self.proc = subprocess.Popen(["ip", "netns", "exec", netns, "tcpdump", "-i", iface, *([] if promiscuous else ["-p"]), "-s", "0", "-U", "-n",
                                      "-w", str(self.path), expression], stdout=self.log, stderr=subprocess.STDOUT)
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
                self.proc.wait(10)
        self.log.close()
        return self.path.read_bytes()

    def packets(self):
        """How many packets tcpdump says it captured."""
        m = re.search(r"(\d+) packets captured", self.path.with_suffix(".log").read_text())
        return int(m.group(1)) if m else None


# ---------------------------------------------------------------------------------------
# a graph across two hosts, secured or not

from robot_facts import servo_deg  # noqa: E402,F401  (ROBOT.md, not the code under test)


class SecureGraph:
    """compute_ik in namespace hosts.pc and serial_node (port:=mock) in hosts.pi, each
    under its enclave of `keystore` given with `--ros-args --enclave` (or with no
    security at all when keystore is None)."""

    def __init__(self, hosts, domain, keystore=None, pc_enclave="/eezybot/pc", pi_enclave="/eezybot/pi"):
        from conftest import NodeProcess

        self.hosts, self.domain, self.keystore = hosts, domain, keystore
        env = security_env(keystore) if keystore is not None else dict(NO_SECURITY)
        # No age limit on targets: these tests are about who may talk, not stale targets
        # (test_compute_ik's), and on a busy host a target can take longer than the
        # default 0.5 s to arrive, which compute_ik refuses.
        ik_args = ["--ros-args", "-p", "max_target_age:=0.0"] + (["--enclave", pc_enclave] if keystore is not None else [])
        serial_args = ["--ros-args", "-p", "port:=mock"] + (["--enclave", pi_enclave] if keystore is not None else [])
        self.procs = []
        self.ik = NodeProcess("compute_ik", ik_args, domain, env=env, netns=hosts.pc)
        self.procs.append(self.ik)
        self.serial = NodeProcess("serial_node", serial_args, domain, env=env, netns=hosts.pi)
        self.procs.append(self.serial)

    def operator(self, netns=None, enclave="default", pubs=("xyz_target",), subs=("servo_angles", "servo_state"),
                 name="operator"):
        """A SecurePeer under the pc enclave of the graph's keystore (or plain when the
        graph is), in `netns` (default: the pc host)."""
        if enclave == "default":
            enclave = self.keystore.enclave("/eezybot/pc") if self.keystore is not None else None
        return SecurePeer(self.domain, enclave=enclave, pubs=pubs, subs=subs,
                          netns=self.hosts.pc if netns is None else netns, name=name)

    def logs_tail(self, n=15):
        out = []
        for p in self.procs:
            lines = p.output().splitlines()
            out.append(f"--- {p.name} (last {n} lines)\n" + "\n".join(lines[-n:]))
        return "\n".join(out)

    def close(self):
        """Stops the nodes (SIGINT): {name: exit status}."""
        return {p.name: p.stop() for p in self.procs}


def drive(peer, xyz, timeout=30.0, period=0.5):
    """Publish a target stamped now every `period` until serial_node's servo_state
    answers one of them (serial_node copies the command's stamp): returns
    (sent stamps, the answered stamp) or (sent, None) after the timeout."""
    sent = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        payload, st = point_target(*xyz)
        peer.publish("xyz_target", payload)
        sent.append(st)
        if peer.wait(lambda: answered_stamp(peer, sent), period):
            return sent, answered_stamp(peer, sent)
    return sent, answered_stamp(peer, sent)


def answered_stamp(peer, sent):
    """The first of the `sent` stamps that a servo_state the peer received carries
    (serial_node copies the command's stamp), or None."""
    wanted = set(sent)
    for _, payload in peer.received("servo_state"):
        st = stamp(joint_state(payload))
        if st in wanted:
            return st
    return None


def wait_at(peer, topic, expected_deg, tolerance_deg=0.1, timeout=30.0):
    """Until `topic`'s newest message has its first servos within `tolerance_deg` of
    `expected_deg` (where the target puts the arm, known in advance: an event, not a
    quiet period; the timeout only bounds a failure): that message, or the newest (None
    if none came) once the timeout has passed."""
    end = time.monotonic() + timeout
    while True:
        got = peer.received(topic)
        last = joint_state(got[-1][1]) if got else None
        if last is not None and all(abs(math.degrees(a) - e) < tolerance_deg
                                    for a, e in zip(last.position, expected_deg)):
            return last
        if time.monotonic() >= end:
            return last
        time.sleep(0.05)


def wait_at_rest(peer, topic="servo_state", quiet=0.5, timeout=10.0):
    """Until `topic`'s positions have not changed for `quiet` s (repeats of the same
    state, as a heartbeat sends, count as no change): its last message, or None if none
    came."""
    end = time.monotonic() + timeout
    while True:
        got = [(t, joint_state(p)) for t, p in peer.received(topic)]
        if got:
            last = tuple(got[-1][1].position)
            since = got[-1][0]
            for t, m in reversed(got):
                if tuple(m.position) != last:
                    break
                since = t
            if time.monotonic() - since >= quiet:
                return got[-1][1]
        if time.monotonic() >= end:
            return got[-1][1] if got else None
        time.sleep(quiet / 4)


# pcap link types: the IPv4 packet's offset in a frame, and where its EtherType is
_LINK_TYPES = {1: (14, 12), 113: (16, 14), 276: (20, 0)}  # Ethernet, Linux cooked (SLL, SLL2: `-i any`)


def ipv4_packets(pcap):
    """The IPv4 packets of a pcap capture (Ethernet, as tcpdump writes on a veth, or
    Linux cooked, as it writes with `-i any`), in capture order."""
    magic = pcap[:4]
    if magic == b"\xd4\xc3\xb2\xa1" or magic == b"\x4d\x3c\xb2\xa1":
        endian = "<"
    elif magic in (b"\xa1\xb2\xc3\xd4", b"\xa1\xb2\x3c\x4d"):
        endian = ">"
    else:
        raise ValueError("not a pcap file")
    linktype = struct.unpack(endian + "I", pcap[20:24])[0]
    if linktype not in _LINK_TYPES:
        raise ValueError(f"pcap link type {linktype}, not Ethernet or Linux cooked")
    start, ethertype = _LINK_TYPES[linktype]
    pos = 24
    while pos + 16 <= len(pcap):
        incl = struct.unpack(endian + "I", pcap[pos + 8:pos + 12])[0]
        frame = pcap[pos + 16:pos + 16 + incl]
        pos += 16 + incl
        if len(frame) >= start + 20 and frame[ethertype:ethertype + 2] == b"\x08\x00":
            yield frame[start:]


def tcp_streams(pcap):
    """The bytes of each TCP connection's direction in a pcap capture, {(source,
    destination, source port, destination port): bytes}: segments in sequence order, a
    retransmitted or twice-captured one (loopback with `-i any`) once."""
    segments = {}
    for ip in ipv4_packets(pcap):
        if ip[9] != 6:
            continue
        ihl = (ip[0] & 15) * 4
        total = struct.unpack(">H", ip[2:4])[0]
        tcp = ip[ihl:total]
        if len(tcp) < 20:
            continue
        body = tcp[(tcp[12] >> 4) * 4:]
        if body:
            key = (ip[12:16], ip[16:20], *struct.unpack(">HH", tcp[0:4]))
            segments.setdefault(key, {})[struct.unpack(">I", tcp[4:8])[0]] = body
    return {key: b"".join(parts[seq] for seq in sorted(parts)) for key, parts in segments.items()}


def udp_datagrams(pcap):
    """The UDP payloads (RTPS messages) of a pcap capture (ipv4_packets), with IPv4
    fragments reassembled, in capture order."""
    out, frags = [], {}
    for ip in ipv4_packets(pcap):
        ihl = (ip[0] & 15) * 4
        total = struct.unpack(">H", ip[2:4])[0]
        ident, flags_off = struct.unpack(">HH", ip[4:8])
        if ip[9] != 17:  # UDP
            continue
        body = ip[ihl:total]
        more, offset = bool(flags_off & 0x2000), (flags_off & 0x1FFF) * 8
        if not more and offset == 0:
            out.append(body[8:])
            continue
        key = (ip[12:16], ip[16:20], ident)
        parts = frags.setdefault(key, {})
        parts[offset] = body
        if not more:
            parts["end"] = offset + len(body)
        if "end" in parts:
            data, at = b"", 0
            while at in parts:
                data += parts[at]
                at += len(parts[at])
            if at == parts["end"]:
                out.append(data[8:])
                del frags[key]
    return out


# the text of a `<topic>` element, found by either of its tags (a fragment boundary may cut
# the other one off): printable, no whitespace, no angle bracket
PERMISSIONS_TOPIC = re.compile(rb"<topic>[\x21-\x3b\x3d\x3f-\x7e]*|[\x21-\x3b\x3d\x3f-\x7e]*</topic>")


def handshake_permissions_removed(datagram):
    """A datagram with the `<topic>` elements of permissions documents taken out. A PKI-DH
    handshake message carries its participant's signed permissions document (`c.perm`)
    unencrypted, as the DDS Security specification has it, often split over several
    DATA_FRAG submessages; nothing else on the wire is XML. What is left is what must
    not show a topic name."""
    return PERMISSIONS_TOPIC.sub(b"<topic/>", datagram)


# ---------------------------------------------------------------------------------------
# samples of every size (issue 36, item 3)

def string_sample(length, index=0):
    """A std_msgs/String's CDR whose text is `length` bytes (1 to 65527: a 64 KiB sample
    at most), printable, and different for every `index` and every position, so that a
    lost, reordered or corrupted fragment shows."""
    head = f"{index}:{length}:".encode()
    body = bytes(0x21 + (i * 7 + index * 13 + (i >> 8) * 31) % 94 for i in range(length))
    text = (head + body[len(head):])[:length]
    return b"\x00\x01\x00\x00" + struct.pack("<I", length + 1) + text + b"\x00"


def exchange(sender, receiver, topic, sizes, timeout=10.0, first_index=0):
    """Each size in turn: `sender` publishes a String sample of it and waits until
    `receiver` has it (lock-step, so the latched topic's keep-last-1 history never drops
    one). Returns [(size, verdict, seconds)], the verdict `ok`, `corrupt` (a sample with
    its index and size arrived, other bytes) or `lost` (nothing of it within `timeout`).
    Other samples on the topic (another publisher's) are ignored."""
    out = []
    for n, size in enumerate(sizes, start=first_index):
        payload = string_sample(size, n)
        before = len(receiver.received(topic))

        def since():
            return [p for _, p in receiver.received(topic)[before:]]
        t0 = time.monotonic()
        sender.publish(topic, payload)
        arrived = receiver.wait(lambda: payload in since(), timeout)
        seconds = time.monotonic() - t0
        if arrived:
            out.append((size, "ok", seconds))
        else:
            # the text starts with "index:size:" (cut to `size` bytes)
            head = b"\x00\x01\x00\x00" + struct.pack("<I", size + 1) + f"{n}:{size}:".encode()[:size]
            out.append((size, "corrupt" if any(p.startswith(head) for p in since()) else "lost", None))
    return out
