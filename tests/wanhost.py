"""Sites on different networks, on one machine: network namespaces `pc`, `wan` and `pi`
(names made unique per process), plus `pc2` (a second operator PC) and `stranger` (a
client the router must refuse). `wan` holds the Zenoh router's address ROUTER on its
loopback and one link to each site; each site has a route to ROUTER only, and `wan` does
not forward: nothing passes between two sites except through the router (a process in
`wan`). Each site is its own DDS "LAN" (a multicast route on its link).

The Pi's link is a veth, or two TAP devices through the userspace link emulator
linkem.py (delay, jitter, loss). A "cable pull" at a site takes its interface down (the
kernel drops its routes); putting it back re-adds the route to the router and the
multicast route, as a DHCP client would.

Used by test_wan.py, tests/soak/wan_outages.py and tests/bench/wan_e2e.py. Exposes
`pc` and `pi` (namespace names) and `cut`/`restore`, as twohost.TwoHosts does, so
split_graph.SplitGraph runs on it with the WAN environment (`graph_env`)."""
import os
import subprocess
import sys
import time
from pathlib import Path

from twohost import _ip, available, stop_link  # noqa: F401 - available: re-exported for the tests

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
ROUTER = "10.77.0.1"
PORT = 7447
# site -> subnet number of its link to `wan` (10.77.K.0/24: wan .1, the site .2)
SITES = {"pc": 1, "pi": 2, "pc2": 3, "stranger": 4}
WAN_BINARIES = ("eezybot_wan_router", "eezybot_wan_bridge", "examples/acl_probe")


def wan_bin_dir():
    """The WAN binaries (wan/, and its example acl_probe): EEZYBOT_WAN_BIN_DIR (the test
    command builds them there), else wan/target/release, built now if missing."""
    d = os.environ.get("EEZYBOT_WAN_BIN_DIR")
    if d:
        return Path(d)
    d = REPO / "wan" / "target" / "release"
    if not all((d / b).exists() for b in WAN_BINARIES):
        print("building wan/ (cargo build --release; the first build takes several minutes)", file=sys.stderr)
        subprocess.run(["cargo", "build", "--release", "--quiet", "--bins", "--examples"], cwd=REPO / "wan", check=True)
    return d


def make_certs(directory, *clients):
    """launch_scripts/wan_certs.sh DIRECTORY ROUTER [--client NAME]...: a CA of its own."""
    argv = [str(REPO / "launch_scripts" / "wan_certs.sh"), str(directory), ROUTER]
    for c in clients:
        argv += ["--client", c]
    subprocess.run(argv, check=True, capture_output=True, text=True, timeout=120)
    return Path(directory)


class WanHosts:
    """Namespaces per site in `sites` (default pc, pi) and `wan`; `impaired` (a dict of
    linkem.ImpairedLink arguments) puts the emulator on the Pi's link."""

    def __init__(self, tag="", sites=("pc", "pi"), impaired=None):
        n = os.getpid() % 10000
        self.tag = f"{tag}{n}"
        self.wan = f"ezb{self.tag}wan"
        self.ns = {s: f"ezb{self.tag}{s}" for s in sites}
        self.pc, self.pi = self.ns.get("pc"), self.ns.get("pi")
        self.impaired = impaired
        self.link = None
        self.stats = None
        self.router = None
        self.router_code = None  # the router's exit status, once close() stopped it
        self._up()

    def _up(self):
        for ns in (self.wan, *self.ns.values()):
            _ip("netns", "del", ns, check=False)
            _ip("netns", "add", ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        try:
            subprocess.run(["ip", "netns", "exec", self.wan, "sysctl", "-qw", "net.ipv4.ip_forward=0"], check=True)
            _ip("-n", self.wan, "addr", "add", f"{ROUTER}/32", "dev", "lo")
            for site, ns in self.ns.items():
                k = SITES[site]
                wan_if = f"w-{site}"
                if site == "pi" and self.impaired is not None:
                    sys.path.insert(0, str(HERE))
                    from linkem import ImpairedLink

                    self.link = ImpairedLink(ns, "eth0", self.wan, wan_if, **self.impaired)
                    self.link.start()
                else:
                    a, b = f"v{self.tag}{site}a", f"v{self.tag}{site}b"
                    _ip("link", "add", a, "type", "veth", "peer", "name", b)
                    _ip("link", "set", a, "netns", self.wan)
                    _ip("link", "set", b, "netns", ns)
                    _ip("-n", self.wan, "link", "set", a, "name", wan_if)
                    _ip("-n", ns, "link", "set", b, "name", "eth0")
                _ip("-n", self.wan, "addr", "add", f"10.77.{k}.1/24", "dev", wan_if)
                _ip("-n", ns, "addr", "add", f"10.77.{k}.2/24", "dev", "eth0")
                _ip("-n", self.wan, "link", "set", wan_if, "up")
                _ip("-n", ns, "link", "set", "eth0", "up")
                self._routes(site)
        except BaseException:
            self.close()
            raise

    def _routes(self, site):
        k = SITES[site]
        ns = self.ns[site]
        _ip("-n", ns, "route", "replace", f"{ROUTER}/32", "via", f"10.77.{k}.1")
        _ip("-n", ns, "route", "replace", "224.0.0.0/4", "dev", "eth0")

    def start_router(self, tls_dir, log_path, listen=None):
        """launch_scripts/router.sh in `wan`, listening on tls/ROUTER:PORT."""
        self.router_log = open(log_path, "w")
        env = {**os.environ, "ZENOH_TLS_DIR": str(tls_dir), "ZENOH_LISTEN": listen or f"tls/{ROUTER}:{PORT}",
               "EEZYBOT_WAN_BIN_DIR": str(wan_bin_dir())}
        self.router = subprocess.Popen(["ip", "netns", "exec", self.wan, str(REPO / "launch_scripts" / "router.sh")],
                                       stdout=self.router_log, stderr=subprocess.STDOUT, env=env)
        return self.router

    def graph_env(self, tls_dir, cert=None):
        """The environment that puts pc.sh / pi.sh in WAN mode through this router."""
        env = {"ZENOH_ROUTER": f"tls/{ROUTER}:{PORT}", "ZENOH_TLS_DIR": str(tls_dir),
               "EEZYBOT_WAN_BIN_DIR": str(wan_bin_dir())}
        if cert:
            env["ZENOH_CERT"] = cert
        return env

    def cut(self, site):
        """Pull the cable at one site: its interface goes down."""
        _ip("-n", self.ns[site], "link", "set", "eth0", "down")

    def restore(self, site):
        """Plug it back: interface up, the routes re-added."""
        _ip("-n", self.ns[site], "link", "set", "eth0", "up")
        deadline = time.monotonic() + 30  # only bounds a failure
        while True:
            try:
                self._routes(site)
                return
            except RuntimeError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)  # the connected route comes back a moment after link up

    def popen(self, site, argv, **kw):
        """A process at `site` (or in `wan`)."""
        ns = self.wan if site == "wan" else self.ns[site]
        return subprocess.Popen(["ip", "netns", "exec", ns, *argv], **kw)

    def close(self):
        if self.router is not None:
            self.router.terminate()
            try:
                self.router.wait(10)
            except subprocess.TimeoutExpired:
                self.router.kill()
                self.router.wait(10)
            self.router_log.close()
            self.router_code = self.router.returncode
            self.router = None
        if self.link is not None:
            self.stats = stop_link(self.link)
            self.link = None
        for ns in (*self.ns.values(), self.wan):
            _ip("netns", "del", ns, check=False)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
