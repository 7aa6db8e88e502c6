"""The client side of the Foxglove WebSocket protocol (subprotocol foxglove.sdk.v1), written
from its specification with the `websockets` package: JSON text ops (serverInfo,
advertise, status; subscribe, advertise, …) and binary frames (messageData from the
server, clientMessageData to it). For tests/test_foxglove.py and the CPU benchmark."""
import json
import socket
import struct
import time

from websockets.sync import client as websockets_sync

SUBPROTOCOL = "foxglove.sdk.v1"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class FoxgloveClient:
    """The client side of the Foxglove WebSocket protocol, as much as the tests need."""

    def __init__(self, port, timeout=10.0):
        deadline = time.monotonic() + timeout
        while True:
            try:
                self._connection = websockets_sync.connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL],
                                                           max_size=None, open_timeout=2)
                self.ws = self._connection.__enter__()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        assert self.ws.subprotocol == SUBPROTOCOL
        self.info = None
        self.channels = {}       # topic -> advertised channel
        self.statuses = []
        self.subs = {}           # subscription id -> topic
        self.received = {}       # topic -> [(log_time, payload)]

    def _handle(self, m):
        if isinstance(m, str):
            op = json.loads(m)
            if op["op"] == "serverInfo":
                self.info = op
            elif op["op"] == "advertise":
                for c in op["channels"]:
                    self.channels[c["topic"]] = c
            elif op["op"] == "status":
                self.statuses.append(op)
        elif m[0] == 1:  # messageData
            sub, t = struct.unpack_from("<IQ", m, 1)
            self.received.setdefault(self.subs[sub], []).append((t, bytes(m[13:])))

    def pump(self, seconds):
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                self._handle(self.ws.recv(timeout=left))
            except TimeoutError:
                return

    def pump_until(self, predicate, timeout=10.0):
        end = time.monotonic() + timeout
        while not predicate():
            left = end - time.monotonic()
            if left <= 0:
                return False
            try:
                self._handle(self.ws.recv(timeout=min(left, 0.2)))
            except TimeoutError:
                pass
        return True

    def subscribe(self, *topics):
        subs = []
        for topic in topics:
            sid = len(self.subs) + 1
            self.subs[sid] = topic
            subs.append({"id": sid, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def advertise(self, cid, topic, schema_name):
        self.ws.send(json.dumps({"op": "advertise", "channels": [
            {"id": cid, "topic": topic, "encoding": "cdr", "schemaName": schema_name}]}))

    def publish(self, cid, payload):
        self.ws.send(struct.pack("<BI", 1, cid) + payload)

    def close(self):
        self._connection.__exit__(None, None, None)
