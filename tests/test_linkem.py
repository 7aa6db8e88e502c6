"""linkem (tests/linkem.py), the userspace delay/jitter/loss link between two namespaces,
checked without ROS: UDP echo RTT, loss rate, multicast, SIGTERM/SIGINT and clean-up.

Bounds are deliberately loose: this is a functional check, timing targets belong to
benchmarks. Skipped only when /dev/net/tun or `ip netns` is unavailable (all but
test_bad_namespace_fails_fast, which needs neither)."""
import contextlib
import itertools
import json
import os
import select
import signal
import socket
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import linkem  # noqa: E402

LINKEM = str(Path(linkem.__file__).resolve())
ADDR_A, ADDR_B = "10.77.0.1", "10.77.0.2"  # each pair of namespaces is private, so fixed addresses are fine
IF_A, IF_B = "lkem_a", "lkem_b"
PORT = 7007
GROUP = "239.255.0.1"
_counter = itertools.count()


def _unavailable():
    if os.geteuid() != 0:
        return "needs root (ip netns, /dev/net/tun)"
    try:
        os.close(os.open("/dev/net/tun", os.O_RDWR))
    except OSError as e:
        return f"/dev/net/tun unavailable: {e}"
    name = f"lkemprobe{os.getpid()}"
    try:
        r = subprocess.run(["ip", "netns", "add", name], capture_output=True, text=True, timeout=30)
    except OSError as e:
        return f"ip netns unavailable: {e}"
    if r.returncode != 0:
        return f"ip netns unavailable: {r.stderr.strip()}"
    subprocess.run(["ip", "netns", "delete", name], capture_output=True, timeout=30)
    return None


@pytest.fixture(scope="module")
def _unavailable_reason():
    return _unavailable()


@pytest.fixture(autouse=True)
def _requirements(request, _unavailable_reason):
    # test_bad_namespace_fails_fast only runs linkem against a namespace that does not
    # exist: it needs neither root nor a TAP, and runs without them
    if _unavailable_reason and request.function is not test_bad_namespace_fails_fast:
        pytest.skip(_unavailable_reason)


def _netns_list():
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, check=True, timeout=30).stdout
    return {line.split()[0] for line in out.splitlines() if line.strip()}


@contextlib.contextmanager
def netns_pair():
    """Two fresh namespaces with names unique to this process; deleted however the body ends."""
    n = next(_counter)
    names = (f"lkemA{os.getpid()}_{n}", f"lkemB{os.getpid()}_{n}")
    made = []
    try:
        for name in names:
            subprocess.run(["ip", "netns", "add", name], check=True, capture_output=True, timeout=30)
            made.append(name)
        yield names
    finally:
        for name in made:
            subprocess.run(["ip", "netns", "delete", name], capture_output=True, timeout=30)


@contextlib.contextmanager
def impaired(**kw):
    """linkem between two fresh namespaces, addressed and up; yields (link, ns_a, ns_b).

    linkem is stopped (and its stats checked by whoever calls stop()) before the
    namespaces are deleted, also when the body fails."""
    with netns_pair() as (ns_a, ns_b):
        link = linkem.ImpairedLink(ns_a, IF_A, ns_b, IF_B, **kw)
        link.start()
        try:
            linkem.bring_up(ns_a, IF_A, f"{ADDR_A}/24")
            linkem.bring_up(ns_b, IF_B, f"{ADDR_B}/24")
            yield link, ns_a, ns_b
        finally:
            if link.proc is not None:
                with contextlib.suppress(RuntimeError):
                    link.stop()


def _udp(ns, addr, port=0):
    with linkem.netns(ns):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    s.bind((addr, port))
    s.setblocking(False)
    return s


def echo(ns_a, ns_b, count, interval, until_first=False, timeout=30):
    """Send `count` numbered datagrams from ns_a to an echo socket in ns_b, `interval` s apart,
    all in this thread; returns {seq: rtt_seconds} of the echoes that came back.
    With until_first, stop at the first echo (ARP warm-up).

    The end is an order of events, not a time: after the last datagram a marker goes
    (again every 0.1 s, since the link may drop it) until one comes back. linkem is FIFO
    each way and the echo socket answers in order, so by then every echo the link did
    not drop is in (`timeout` only bounds a failure)."""
    srv, cli = _udp(ns_b, ADDR_B, PORT), _udp(ns_a, ADDR_A)
    rtts = {}
    try:
        sent = 0
        next_send = time.monotonic()
        give_up = next_send + timeout
        while True:
            now = time.monotonic()
            if now >= next_send and (sent < count or not until_first):
                cli.sendto(struct.pack("!Id", sent, now), (ADDR_B, PORT))
                sent += 1
                next_send += interval if sent < count else 0.1
            if until_first and rtts:
                return rtts
            if any(seq >= count for seq in rtts):
                return {seq: rtt for seq, rtt in rtts.items() if seq < count}
            assert now < give_up, (f"no {'echo' if until_first else 'marker'} came back within {timeout} s; "
                                   f"{len(rtts)} echoes of {sent} datagrams")
            wake = next_send
            for s in select.select([srv, cli], [], [], max(0.0, wake - time.monotonic()))[0]:
                while True:
                    try:
                        data, peer = s.recvfrom(2048)
                    except BlockingIOError:
                        break
                    if s is srv:
                        srv.sendto(data, peer)
                    else:
                        seq, t = struct.unpack("!Id", data)
                        rtts[seq] = time.monotonic() - t
    finally:
        srv.close()
        cli.close()


def warm_up(ns_a, ns_b):
    """Until one echo has come back, so that ARP is resolved on both sides."""
    assert echo(ns_a, ns_b, count=100, interval=0.05, until_first=True), "no echo at all through linkem in 5 s"


def test_rtt_is_twice_the_delay():
    with impaired(delay_ms=20, jitter_ms=5, loss=0.0, seed=1) as (link, ns_a, ns_b):
        warm_up(ns_a, ns_b)
        rtts = echo(ns_a, ns_b, count=200, interval=0.005)
        stats = link.stop()
    assert len(rtts) == 200, f"lost {200 - len(rtts)} echoes with loss 0"
    ms = sorted(v * 1000 for v in rtts.values())
    # how late the host delivers is not the emulator's behaviour, so no upper bound on
    # what was measured: printed, not asserted (tests/bench for figures)
    print(f"\nRTT p50 {statistics.median(ms):.1f} ms, max {ms[-1]:.1f} ms; applied delay p50 "
          f"{stats['a_to_b']['delay_ms']['p50']} / {stats['b_to_a']['delay_ms']['p50']} ms")
    assert ms[0] >= 29.5, f"an echo came back in {ms[0]:.1f} ms, faster than 2 × 15 ms"
    for direction in ("a_to_b", "b_to_a"):
        d = stats[direction]
        assert d["forwarded"] >= 200 and d["dropped"] == 0
        assert d["delay_ms"]["min"] >= 15.0, d  # never released early
        # the delays drawn: uniform in [15, 25] ms, centred on 20 ms (the median of 200+
        # draws is within 2 ms of it); the FIFO clamp keeps each scheduled one within
        # [15, 25] ms too, but moves their median up when the host hands the frames over
        # in bursts (a busy host), so the median is judged on the draws
        sched, drawn = d["scheduled_ms"], d["drawn_ms"]
        assert 15.0 <= drawn["min"] and drawn["max"] <= 25.0, d
        assert 15.0 <= sched["min"] and sched["max"] <= 25.0, d
        assert 18.0 <= drawn["p50"] <= 22.0, d


def test_loss_rate():
    n = 3000
    with impaired(delay_ms=5, jitter_ms=1, loss=0.05, seed=7) as (link, ns_a, ns_b):
        warm_up(ns_a, ns_b)
        rtts = echo(ns_a, ns_b, count=n, interval=0.001)
        stats = link.stop()
    rate = 1 - len(rtts) / n
    # expected 1 - 0.95² = 9.75 %
    assert 0.05 <= rate <= 0.15, f"echo loss {rate:.1%}"
    for direction in ("a_to_b", "b_to_a"):
        d = stats[direction]
        assert d["received"] >= n * 0.9
        assert 0.02 <= d["dropped"] / d["received"] <= 0.09, d
        assert d["received"] == d["forwarded"] + d["dropped"] + d["overflow"] + d["write_errors"] + d["pending_at_exit"]


@pytest.mark.parametrize("src,dst", [("a", "b"), ("b", "a")])
def test_multicast_gets_through(src, dst):
    with impaired(delay_ms=20, jitter_ms=5, loss=0.0) as (link, ns_a, ns_b):
        ns = {"a": (ns_a, ADDR_A), "b": (ns_b, ADDR_B)}
        (src_ns, src_addr), (dst_ns, _) = ns[src], ns[dst]
        with linkem.netns(dst_ns):
            rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        with linkem.netns(src_ns):
            tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            rx.bind((GROUP, PORT))
            # interface INADDR_ANY: the kernel picks it by the 224.0.0.0/4 route, as DDS does
            rx.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                          socket.inet_aton(GROUP) + socket.inet_aton("0.0.0.0"))
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
            got = None
            deadline = time.monotonic() + 5
            while got is None and time.monotonic() < deadline:
                tx.sendto(b"hello " + src.encode(), (GROUP, PORT))
                if select.select([rx], [], [], 0.1)[0]:
                    got = rx.recvfrom(2048)
        finally:
            rx.close()
            tx.close()
        stats = link.stop()
    assert got is not None, f"no multicast datagram from {src} reached {dst}"
    assert got[0] == b"hello " + src.encode() and got[1][0] == src_addr, got
    assert stats[f"{src}_to_{dst}"]["forwarded"] >= 1


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_exits_0_with_stats_and_tap_gone(tmp_path, sig):
    """The exact CLI contract, without ImpairedLink."""
    stats_file = tmp_path / "stats.json"
    with netns_pair() as (ns_a, ns_b):
        proc = subprocess.Popen([sys.executable, LINKEM, "--a", f"{ns_a}:{IF_A}", "--b", f"{ns_b}:{IF_B}",
                                 "--delay-ms", "10", "--jitter-ms", "2", "--loss", "0", "--seed", "3",
                                 "--stats", str(stats_file)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            ready = select.select([proc.stdout], [], [], 10)[0] and proc.stdout.readline()
            assert ready == b"ready\n", (ready, proc.poll())
            linkem.bring_up(ns_a, IF_A, f"{ADDR_A}/24")
            linkem.bring_up(ns_b, IF_B, f"{ADDR_B}/24")
            warm_up(ns_a, ns_b)
            proc.send_signal(sig)
            rc = proc.wait(5)
            err = proc.stderr.read().decode()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
            proc.stdout.close()
            proc.stderr.close()
        assert rc == 0, err
        # non-persistent TAPs: gone with the forwarder
        for ns, ifname in ((ns_a, IF_A), (ns_b, IF_B)):
            r = subprocess.run(["ip", "-n", ns, "link", "show", ifname], capture_output=True, timeout=30)
            assert r.returncode != 0, f"{ifname} still exists in {ns}"
    stats = json.loads(stats_file.read_text())
    for direction in ("a_to_b", "b_to_a"):
        d = stats[direction]
        assert d["received"] >= 1 and d["forwarded"] >= 1, d
        assert set(d["delay_ms"]) >= {"p50", "p99", "max"}
        assert d["delay_ms"]["min"] >= 8.0 and 8.0 <= d["scheduled_ms"]["min"] <= d["scheduled_ms"]["max"] <= 12.0, d


def test_namespaces_and_forwarder_cleaned_up_when_the_body_fails():
    seen = {}
    with pytest.raises(ZeroDivisionError):
        with impaired(delay_ms=1, jitter_ms=0, loss=0.0) as (link, ns_a, ns_b):
            seen.update(names={ns_a, ns_b}, proc=link.proc)
            assert seen["names"] <= _netns_list()
            1 / 0
    assert seen["proc"].poll() == 0, "linkem not stopped (or not cleanly) after a failing body"
    assert not seen["names"] & _netns_list(), "namespaces left behind"


def test_bad_namespace_fails_fast():
    r = subprocess.run([sys.executable, LINKEM, "--a", "no-such-ns-lkem:x", "--b", "no-such-ns-lkem:y"],
                       capture_output=True, text=True, timeout=10)
    assert r.returncode != 0 and "ready" not in r.stdout
    assert "no-such-ns-lkem" in r.stderr
