#!/usr/bin/env python3
"""linkem: a userspace link emulator (delay, jitter, loss) between two network namespaces.

This kernel has no `tc netem`, so the "impaired Wi-Fi" tests join the operator-PC and
Raspberry Pi namespaces not by a veth but by two TAP devices, one in each namespace,
with this forwarder copying Ethernet frames between them.

    python tests/linkem.py --a NS_A:IF_A --b NS_B:IF_B [--delay-ms 20] [--jitter-ms 5]
                           [--loss 0.01] [--seed N] [--stats FILE] [--reorder] [--limit 10000] [--no-rt]

* NS_A / NS_B are existing namespaces (`ip netns add`, listed in /var/run/netns/).
  IF_A / IF_B are TAP devices (IFF_TAP | IFF_NO_PI, non-persistent) that linkem creates
  inside them: its (only) thread enters each namespace in turn with setns(CLONE_NEWNET),
  opens /dev/net/tun and returns to its original namespace. The devices vanish when
  linkem exits. Addresses, link state and routes are the caller's job, e.g.
      ip -n NS addr add 10.9.0.1/24 dev IF; ip -n NS link set IF up
      ip -n NS route add 224.0.0.0/4 dev IF
  (or `bring_up()` below).
* Every frame read from one TAP is written to the other. Each frame is independently
  dropped with probability --loss, else released after a delay drawn uniformly from
  [delay - jitter, delay + jitter] ms (clamped at 0).
* Order: by default each direction is FIFO, like a real Wi-Fi link (802.11 delivers in
  order per traffic class, and DDS/UDP tests should not see reordering a real link would
  not produce): a frame's release time is max(its drawn time, the previous frame's
  release time in the same direction). When frames arrive closer together than the
  jitter this shifts the applied delays upwards; the stats report the delays actually
  applied. --reorder releases every frame at its own drawn time (netem's behaviour with
  jitter), so frames may overtake one another.
* Scheduling: one heap of pending frames; select() with a microsecond timeout to the
  next release (no sleep loops, no spinning). A frame is never released early.
  linkem runs at SCHED_FIFO priority 1 when allowed (--no-rt: don't), as netem runs in
  the kernel: on a loaded 2-core machine a normal-priority forwarder was measured up to
  tens of ms late at p99, at FIFO 1 under the same load p99 < 0.5 ms. It uses ~5 % of a
  core at 500 frames/s, so it cannot starve anything (and RT throttling caps it anyway).
* Prints exactly `ready` on stdout (flushed) once both TAPs are open.
* SIGTERM / SIGINT: stop, write --stats, exit 0. Frames still queued are discarded and
  counted as `pending_at_exit`.
* --stats FILE (JSON), per direction `a_to_b` / `b_to_a`:
    received, forwarded, dropped (random loss), overflow (queue over --limit),
    write_errors (e.g. the destination link is down), pending_at_exit,
    delay_ms:     applied delay, read() to the start of write(): p50, p99, max, min, mean
    scheduled_ms: the delay that was scheduled (after the FIFO clamp), same fields
    drawn_ms:     the delay drawn (before the FIFO clamp), same fields: how the sender
                  paced its frames does not move these, only which frames are clamped
    late_ms:      applied minus scheduled, i.e. the timing error, same fields
  plus `config` (with `realtime`: whether SCHED_FIFO was granted) and `duration_s`.

As a module: `ImpairedLink` runs linkem as a subprocess; `netns()` runs code in a named
namespace on the current thread (sockets created there stay in that namespace);
`bring_up()` configures one end.
"""
import argparse
import contextlib
import ctypes
import errno
import fcntl
import gc
import heapq
import json
import os
import random
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from array import array

CLONE_NEWNET = 0x40000000
TUNSETIFF = 0x400454CA
IFF_TAP = 0x0002
IFF_NO_PI = 0x1000
IFNAMSIZ = 16
NETNS_DIR = "/var/run/netns"
READ_SIZE = 65536
READ_BURST = 64  # frames read from one TAP per wake-up, at most

_libc = ctypes.CDLL(None, use_errno=True)
_libc.setns.argtypes = (ctypes.c_int, ctypes.c_int)
_libc.setns.restype = ctypes.c_int


def _setns(fd):
    if _libc.setns(fd, CLONE_NEWNET) != 0:
        e = ctypes.get_errno()
        raise OSError(e, f"setns(CLONE_NEWNET): {os.strerror(e)}")


@contextlib.contextmanager
def netns(name):
    """Run the body in network namespace `name` (on the calling thread only), then return.

    Sockets and TAP fds opened in the body stay attached to that namespace."""
    path = name if name.startswith("/") else os.path.join(NETNS_DIR, name)
    target = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        orig = os.open("/proc/thread-self/ns/net", os.O_RDONLY | os.O_CLOEXEC)
        try:
            _setns(target)
            try:
                yield
            finally:
                _setns(orig)
        finally:
            os.close(orig)
    finally:
        os.close(target)


def open_tap(ns, ifname):
    """A non-blocking fd of a new non-persistent TAP device `ifname` inside namespace `ns`."""
    if not 0 < len(ifname.encode()) < IFNAMSIZ:
        raise ValueError(f"interface name {ifname!r} must be 1..{IFNAMSIZ - 1} bytes")
    with netns(ns):
        fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK | os.O_CLOEXEC)
        try:
            ifr = struct.pack(f"{IFNAMSIZ}sH22x", ifname.encode(), IFF_TAP | IFF_NO_PI)
            fcntl.ioctl(fd, TUNSETIFF, ifr)
        except BaseException:
            os.close(fd)
            raise
    return fd


def bring_up(ns, ifname, cidr, multicast_route=True):
    """What the caller of linkem does on each side: address, link up, multicast route."""
    cmds = [["ip", "-n", ns, "addr", "add", cidr, "dev", ifname], ["ip", "-n", ns, "link", "set", ifname, "up"]]
    if multicast_route:
        cmds.append(["ip", "-n", ns, "route", "add", "224.0.0.0/4", "dev", ifname])
    for c in cmds:
        subprocess.run(c, check=True, capture_output=True, text=True, timeout=30)


def _summary(values):
    """p50/p99/max/min/mean in ms of an array of seconds (nearest-rank percentiles)."""
    if not values:
        return {"p50": None, "p99": None, "max": None, "min": None, "mean": None}
    s = sorted(values)
    n = len(s)

    def pct(p):
        return round(s[min(n - 1, max(0, -(-p * n // 100) - 1))] * 1000.0, 4)

    return {"p50": pct(50), "p99": pct(99), "max": round(s[-1] * 1000.0, 4), "min": round(s[0] * 1000.0, 4),
            "mean": round(sum(s) / n * 1000.0, 4)}


class _Direction:
    def __init__(self, name, src, dst):
        self.name, self.src, self.dst = name, src, dst
        self.received = self.forwarded = self.dropped = self.overflow = self.write_errors = 0
        self.queued = 0
        self.last_release = 0.0
        self.applied = array("d")
        self.scheduled = array("d")
        self.drawn = array("d")

    def stats(self):
        late = array("d", (a - s for a, s in zip(self.applied, self.scheduled)))
        return {"received": self.received, "forwarded": self.forwarded, "dropped": self.dropped,
                "overflow": self.overflow, "write_errors": self.write_errors, "pending_at_exit": self.queued,
                "delay_ms": _summary(self.applied), "scheduled_ms": _summary(self.scheduled),
                "drawn_ms": _summary(self.drawn), "late_ms": _summary(late)}


class Forwarder:
    def __init__(self, fd_a, fd_b, delay_ms=20.0, jitter_ms=5.0, loss=0.01, seed=None, fifo=True, limit=10000):
        self.dirs = (_Direction("a_to_b", fd_a, fd_b), _Direction("b_to_a", fd_b, fd_a))
        self.by_fd = {fd_a: self.dirs[0], fd_b: self.dirs[1]}
        self.lo = max(0.0, (delay_ms - jitter_ms) / 1000.0)
        self.hi = max(0.0, (delay_ms + jitter_ms) / 1000.0)
        self.loss, self.fifo, self.limit = loss, fifo, limit
        self.rng = random.Random(seed)
        self.heap = []  # (release, seq, direction, read_time, frame)
        self.seq = 0
        self.stop = False
        self.wake_r, self.wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)

    def request_stop(self, *_):
        self.stop = True
        try:
            os.write(self.wake_w, b"x")
        except OSError:
            pass

    def _read(self, d):
        rng, heap = self.rng, self.heap
        for _ in range(READ_BURST):
            try:
                frame = os.read(d.src, READ_SIZE)
            except BlockingIOError:
                return
            except OSError as e:
                if e.errno in (errno.EINTR, errno.EAGAIN):
                    return
                raise
            now = time.monotonic()
            if not frame:
                return
            d.received += 1
            if self.loss > 0 and rng.random() < self.loss:
                d.dropped += 1
                continue
            if d.queued >= self.limit:
                d.overflow += 1
                continue
            release = now + rng.uniform(self.lo, self.hi)
            d.drawn.append(release - now)
            if self.fifo:
                if release < d.last_release:
                    release = d.last_release
                d.last_release = release
            self.seq += 1
            heapq.heappush(heap, (release, self.seq, d, now, frame))
            d.queued += 1

    def _release_due(self):
        heap = self.heap
        now = time.monotonic()
        while heap and heap[0][0] <= now:
            release, _, d, read_time, frame = heapq.heappop(heap)
            d.queued -= 1
            try:
                os.write(d.dst, frame)
            except OSError:
                d.write_errors += 1  # EIO while the destination link is down, etc.
            else:
                d.forwarded += 1
                d.applied.append(now - read_time)
                d.scheduled.append(release - read_time)
            now = time.monotonic()

    def run(self):
        rfds = [self.dirs[0].src, self.dirs[1].src, self.wake_r]
        by_fd = self.by_fd
        while not self.stop:
            self._release_due()
            timeout = max(0.0, self.heap[0][0] - time.monotonic()) if self.heap else None
            try:
                readable, _, _ = select.select(rfds, [], [], timeout)
            except InterruptedError:
                continue
            for fd in readable:
                d = by_fd.get(fd)
                if d is not None:
                    self._read(d)
                else:
                    try:
                        os.read(self.wake_r, 64)
                    except BlockingIOError:
                        pass

    def stats(self):
        return {d.name: d.stats() for d in self.dirs}


def _endpoint(text):
    ns, sep, ifname = text.partition(":")
    if not sep or not ns or not ifname:
        raise argparse.ArgumentTypeError(f"expected NS:IF, got {text!r}")
    return ns, ifname


def main(argv=None):
    p = argparse.ArgumentParser(description="Userspace link emulator: two TAPs in two namespaces, delay/jitter/loss.")
    p.add_argument("--a", required=True, type=_endpoint, metavar="NS_A:IF_A")
    p.add_argument("--b", required=True, type=_endpoint, metavar="NS_B:IF_B")
    p.add_argument("--delay-ms", type=float, default=20.0)
    p.add_argument("--jitter-ms", type=float, default=5.0)
    p.add_argument("--loss", type=float, default=0.01, help="drop probability per frame, 0..1")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--stats", default=None, metavar="FILE", help="write JSON stats here on exit")
    p.add_argument("--reorder", action="store_true", help="no per-direction FIFO: frames may overtake")
    p.add_argument("--limit", type=int, default=10000, help="max frames queued per direction")
    p.add_argument("--no-rt", action="store_true", help="keep the normal scheduling policy (default: SCHED_FIFO 1)")
    args = p.parse_args(argv)
    if not 0.0 <= args.loss <= 1.0 or args.delay_ms < 0 or args.jitter_ms < 0 or args.limit < 1:
        p.error("need 0 <= loss <= 1, delay >= 0, jitter >= 0, limit >= 1")

    fwd = None
    stop_early = []
    signal.signal(signal.SIGTERM, lambda *_: stop_early.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop_early.append(1))
    started = time.monotonic()
    try:
        fd_a = open_tap(*args.a)
        fd_b = open_tap(*args.b)
    except (OSError, ValueError) as e:
        print(f"linkem: cannot open the TAPs: {e}", file=sys.stderr)
        return 1
    realtime = False
    if not args.no_rt:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            realtime = True
        except OSError as e:
            print(f"linkem: no SCHED_FIFO ({e}); timing will suffer on a loaded machine", file=sys.stderr)
    fwd = Forwarder(fd_a, fd_b, args.delay_ms, args.jitter_ms, args.loss, args.seed, not args.reorder, args.limit)
    signal.signal(signal.SIGTERM, fwd.request_stop)
    signal.signal(signal.SIGINT, fwd.request_stop)
    # Everything allocated so far lives forever: keep it out of the collector's way so
    # that a full collection cannot delay a release by milliseconds.
    gc.freeze()
    if stop_early:
        fwd.stop = True
    else:
        sys.stdout.write("ready\n")
        sys.stdout.flush()
        fwd.run()
    if args.stats:
        out = fwd.stats()
        out["config"] = {"a": ":".join(args.a), "b": ":".join(args.b), "delay_ms": args.delay_ms,
                         "jitter_ms": args.jitter_ms, "loss": args.loss, "seed": args.seed,
                         "fifo": not args.reorder, "limit": args.limit,
                         "realtime": realtime}
        out["duration_s"] = round(time.monotonic() - started, 3)
        tmp = f"{args.stats}.tmp{os.getpid()}"
        with open(tmp, "w") as f:
            json.dump(out, f, indent=1)
        os.replace(tmp, args.stats)
    return 0


class ImpairedLink:
    """Two namespaces joined by TAPs through linkem: start() returns when ready; stop() terminates and returns the stats dict.

    Also a context manager (start on enter, stop on exit). The caller still assigns the
    addresses and brings the links up (see bring_up())."""

    def __init__(self, ns_a, if_a, ns_b, if_b, delay_ms=20, jitter_ms=5, loss=0.01, seed=None, python=sys.executable,
                 reorder=False, limit=None, realtime=True):
        self.argv = [python, os.path.abspath(__file__), "--a", f"{ns_a}:{if_a}", "--b", f"{ns_b}:{if_b}",
                     "--delay-ms", str(delay_ms), "--jitter-ms", str(jitter_ms), "--loss", str(loss)]
        if seed is not None:
            self.argv += ["--seed", str(seed)]
        if reorder:
            self.argv.append("--reorder")
        if limit is not None:
            self.argv += ["--limit", str(limit)]
        if not realtime:
            self.argv.append("--no-rt")
        self.proc = None
        self.returncode = None
        self.stats = None
        self._dir = None

    @property
    def pid(self):
        return self.proc.pid if self.proc else None

    def _stderr(self):
        try:
            with open(os.path.join(self._dir, "stderr")) as f:
                return f.read().strip()
        except OSError:
            return ""

    def start(self, timeout=10):
        self._dir = tempfile.mkdtemp(prefix="linkem-")
        self.stats_path = os.path.join(self._dir, "stats.json")
        with open(os.path.join(self._dir, "stderr"), "w") as err:
            self.proc = subprocess.Popen(self.argv + ["--stats", self.stats_path], stdin=subprocess.DEVNULL,
                                         stdout=subprocess.PIPE, stderr=err, bufsize=0)
        try:
            deadline = time.monotonic() + timeout
            line = b""
            while not line.endswith(b"\n"):
                left = deadline - time.monotonic()
                if left <= 0 or not select.select([self.proc.stdout], [], [], left)[0]:
                    self._kill()
                    raise TimeoutError(f"linkem not ready after {timeout} s: {self._stderr()}")
                chunk = self.proc.stdout.read(64)
                if not chunk:
                    self.proc.wait(10)
                    raise RuntimeError(f"linkem exited with {self.proc.returncode} before ready: {self._stderr()}")
                line += chunk
            if line.strip() != b"ready":
                self._kill()
                raise RuntimeError(f"linkem said {line!r} instead of ready: {self._stderr()}")
        except BaseException:
            self._remove_dir()  # the error has its stderr already
            raise
        return self

    def _remove_dir(self):
        """The temporary directory of this run (stats and stderr), gone."""
        shutil.rmtree(self._dir, ignore_errors=True)

    def _kill(self):
        if self.proc and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def stop(self, timeout=5):
        """SIGTERM, wait, return the stats dict (raises if linkem failed or wrote none)."""
        if self.proc is None:
            return self.stats
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self._kill()
        self.proc.stdout.close()
        self.returncode = self.proc.returncode
        self.proc = None
        err = self._stderr()
        try:
            with open(self.stats_path) as f:
                self.stats = json.load(f)
        except (OSError, ValueError):
            self.stats = None
        finally:
            self._remove_dir()
        if self.returncode != 0 or self.stats is None:
            raise RuntimeError(f"linkem exited with {self.returncode}, stats {'missing' if self.stats is None else 'written'}: {err}")
        return self.stats

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


if __name__ == "__main__":
    sys.exit(main())
