"""Two hosts on one machine: network namespaces `pc` and `pi` (names made unique per
process) joined by a veth pair, or by two TAP devices through the userspace link
emulator `linkem.py` (delay, jitter, loss). Used by test_two_hosts.py, the outage soak
and the end-to-end benchmark.

A "cable pull" takes one end's interface down (the kernel then drops its routes, and
sends fail with "Network is unreachable", as on a Wi-Fi drop); putting it back brings
the interface up and re-adds the multicast route on both ends, as a DHCP client would.
"""
import contextlib
import ctypes
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

_libc = ctypes.CDLL(None, use_errno=True)
_CLONE_NEWNET = 0x40000000


def _ip(*args, check=True):
    r = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and r.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {r.stderr.strip()}")
    return r


@contextlib.contextmanager
def netns(name):
    """Run the body with this thread in network namespace `name` (sockets created and
    threads started in it stay there)."""
    if name is None:
        yield
        return
    home = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
    target = os.open(f"/var/run/netns/{name}", os.O_RDONLY)
    try:
        if _libc.setns(target, _CLONE_NEWNET) != 0:
            raise OSError(ctypes.get_errno(), f"setns into {name}")
        yield
    finally:
        _libc.setns(home, _CLONE_NEWNET)
        os.close(home)
        os.close(target)


def stop_link(link):
    """Stop linkem (linkem.ImpairedLink); its statistics, or None if it did not stop
    cleanly (teardown goes on)."""
    try:
        return link.stop()
    except Exception:  # noqa: BLE001 - teardown goes on
        return None


def available():
    """Why two-host tests cannot run here, or None."""
    if os.geteuid() != 0:
        return "needs root (ip netns)"
    if subprocess.run(["ip", "netns", "list"], capture_output=True, timeout=30).returncode != 0:
        return "ip netns is not available"
    return None


class TwoHosts:
    """Namespaces `self.pc` and `self.pi` with addresses `self.pc_addr`/`self.pi_addr`.

    impaired=None joins them with a veth; impaired=dict(delay_ms=20, jitter_ms=5,
    loss=0.01) joins them with TAPs through linkem.py."""

    def __init__(self, tag="", impaired=None):
        n = os.getpid() % 10000
        self.tag = f"{tag}{n}"
        self.pc, self.pi = f"ezb{self.tag}pc", f"ezb{self.tag}pi"
        self.pc_if, self.pi_if = "eth-pc", "eth-pi"
        net = 100 + (os.getpid() // 7) % 150
        self.pc_addr, self.pi_addr = f"10.{net}.{n % 250}.1", f"10.{net}.{n % 250}.2"
        self.impaired = impaired
        self.link = None
        self.stats = None
        self._up()

    def _up(self):
        for ns in (self.pc, self.pi):
            _ip("netns", "del", ns, check=False)
            _ip("netns", "add", ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        try:
            if self.impaired is None:
                _ip("link", "add", f"v{self.tag}a", "type", "veth", "peer", "name", f"v{self.tag}b")
                _ip("link", "set", f"v{self.tag}a", "netns", self.pc)
                _ip("link", "set", f"v{self.tag}b", "netns", self.pi)
                _ip("-n", self.pc, "link", "set", f"v{self.tag}a", "name", self.pc_if)
                _ip("-n", self.pi, "link", "set", f"v{self.tag}b", "name", self.pi_if)
            else:
                sys.path.insert(0, str(HERE))
                from linkem import ImpairedLink

                self.link = ImpairedLink(self.pc, self.pc_if, self.pi, self.pi_if, **self.impaired)
                self.link.start()
            _ip("-n", self.pc, "addr", "add", f"{self.pc_addr}/24", "dev", self.pc_if)
            _ip("-n", self.pi, "addr", "add", f"{self.pi_addr}/24", "dev", self.pi_if)
            for ns, dev in ((self.pc, self.pc_if), (self.pi, self.pi_if)):
                _ip("-n", ns, "link", "set", dev, "up")
            self._multicast_routes()
        except BaseException:
            self.close()
            raise

    def _multicast_routes(self):
        for ns, dev in ((self.pc, self.pc_if), (self.pi, self.pi_if)):
            _ip("-n", ns, "route", "replace", "224.0.0.0/4", "dev", dev)

    def side(self, which):
        return (self.pc, self.pc_if) if which == "pc" else (self.pi, self.pi_if)

    def cut(self, which):
        """Pull the cable at one end: its interface goes down."""
        ns, dev = self.side(which)
        _ip("-n", ns, "link", "set", dev, "down")

    def restore(self, which):
        """Plug it back: interface up, multicast route re-added on both ends."""
        ns, dev = self.side(which)
        _ip("-n", ns, "link", "set", dev, "up")
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            try:
                self._multicast_routes()
                return
            except RuntimeError:
                time.sleep(0.05)  # the connected route comes back a moment after link up
        self._multicast_routes()

    def popen(self, ns, argv, **kw):
        """A process in namespace `ns`."""
        return subprocess.Popen(["ip", "netns", "exec", ns, *argv], **kw)

    def close(self):
        if self.link is not None:
            self.stats = stop_link(self.link)
            self.link = None
        for ns in (self.pc, self.pi):
            _ip("netns", "del", ns, check=False)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
