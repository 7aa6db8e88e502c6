"""Benchmark: the web panel over HTTPS/WSS against plain HTTP/WS (issue 36 item 4).

gui_bridge on loopback, once plain and once with a certificate of
launch_scripts/panel_certs.sh (the same binary, the same client). Measured by the client:
  - connect: TCP connect (+ the TLS handshake) + the WebSocket upgrade with the token
    subprotocol + the panel's first message (`hello`), for each of --connections new
    connections, one after another;
  - command: a `check` request on one open WebSocket to its answer, --commands times.
p50/p99 in ms. Loopback, so what differs is TLS's own cost (handshake, record layer),
not the network's.

    $EEZYBOT_PYTHON tests/bench/panel_tls.py [--connections 300] [--commands 500]
"""
import argparse
import base64
import json
import os
import socket
import ssl
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("EEZYBOT_BIN_DIR", str(Path(__file__).resolve().parents[2] / "target" / "release"))

from benchkit import stats  # noqa: E402
from conftest import REPO, DomainLease, NodeProcess  # noqa: E402
from foxglove_client import free_port  # noqa: E402

TOKEN = "bench-token-0123456789abcdef"


class Ws:
    """A WebSocket to the panel (TLS when `context`), up to its `hello`."""

    def __init__(self, port, context):
        raw = socket.create_connection(("127.0.0.1", port), timeout=10)
        raw.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock = context.wrap_socket(raw, server_hostname="127.0.0.1") if context else raw
        self.buf = b""
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                           f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                           f"Sec-WebSocket-Protocol: eezybot.panel.v1, token.{TOKEN}\r\n\r\n").encode())
        head = self._until(b"\r\n\r\n")
        if not head.startswith(b"HTTP/1.1 101"):
            raise RuntimeError(head.decode(errors="replace"))
        self.until(lambda m: m.get("t") == "hello")

    def _fill(self):
        chunk = self.sock.recv(65536)
        if not chunk:
            raise ConnectionError("closed by the server")
        self.buf += chunk

    def _until(self, end):
        while end not in self.buf:
            self._fill()
        head, self.buf = self.buf.split(end, 1)
        return head

    def _exact(self, n):
        while len(self.buf) < n:
            self._fill()
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def recv_json(self):
        while True:
            b0, b1 = self._exact(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._exact(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._exact(8))[0]
            payload = self._exact(n)
            if b0 & 0x0F == 1:
                return json.loads(payload)

    def until(self, pred):
        while not pred(m := self.recv_json()):
            pass
        return m

    def send(self, msg):
        payload, mask = json.dumps(msg).encode(), os.urandom(4)
        n = len(payload)
        head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack(">H", n))
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))

    def close(self):
        self.sock.close()


def measure(port, context, connections, commands):
    connect = []
    for _ in range(connections):
        t0 = time.perf_counter()
        ws = Ws(port, context)
        connect.append((time.perf_counter() - t0) * 1000)
        ws.close()
    ws = Ws(port, context)
    command = []
    for i in range(commands):
        t0 = time.perf_counter()
        ws.send({"t": "check", "xyz": [0.2, 0.0, 0.15 + (i % 10) * 1e-3]})
        ws.until(lambda m: m.get("t") in ("check", "refused"))
        command.append((time.perf_counter() - t0) * 1000)
    ws.close()
    return stats(connect), stats(command)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connections", type=int, default=300)
    ap.add_argument("--commands", type=int, default=500)
    args = ap.parse_args()
    lease = DomainLease()
    certs = Path(tempfile.mkdtemp(prefix="panel_tls_bench."))
    subprocess.run([str(REPO / "launch_scripts" / "panel_certs.sh"), str(certs), "127.0.0.1"], check=True,
                   capture_output=True, timeout=60)
    context = ssl.create_default_context(cafile=str(certs / "ca.pem"))
    results = {}
    for name, extra, ctx in (("plain (http/ws)", [], None),
                             ("TLS (https/wss)", ["-p", f"tls_cert:={certs / 'panel.pem'}",
                                                  "-p", f"tls_key:={certs / 'panel.key'}"], context)):
        port = free_port()
        gui = NodeProcess("gui_bridge", ["--ros-args", "-p", f"bind:=127.0.0.1:{port}", "-p", "foxglove_bind:=",
                                         "-p", f"token:={TOKEN}", *extra], lease.id)
        try:
            deadline = time.monotonic() + 20
            while "web panel:" not in gui.output():
                assert time.monotonic() < deadline and gui.proc.poll() is None, gui.output()
                time.sleep(0.05)
            Ws(port, ctx).close()  # warm up
            results[name] = measure(port, ctx, args.connections, args.commands)
        finally:
            gui.stop()
    print(f"gui_bridge from {os.environ['EEZYBOT_BIN_DIR']}; {args.connections} connections, {args.commands} commands")
    for name, (connect, command) in results.items():
        print(f"{name:16}  connect+hello ms {connect}   command ms {command}")
    lease.release()


if __name__ == "__main__":
    main()
