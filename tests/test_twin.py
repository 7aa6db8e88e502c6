"""The physics twin behind a pseudo-terminal (nodes/twin: `twin PTY_LINK_PATH`), driven by
serial_node over its real serial-port path, as it drives an Uno: the handshake, commands
acknowledged with their stamps, and a clean stop that the host sees as the device lost.
The twin's physics is checked on simulated time by its own tests (cargo test -p twin
--features mujoco, in the test command)."""
import math
import os
import signal
import subprocess
import time

from conftest import bin_path, status_values
from safety_rig import SerialNodeRig
from test_serial_node import angles


def start_twin(link):
    p = subprocess.Popen([bin_path("twin"), str(link)], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 20
    while not os.path.exists(link):
        assert time.monotonic() < deadline and p.poll() is None, f"twin did not start: {p.stderr.read() if p.poll() is not None else ''}"
        time.sleep(0.01)
    return p


def test_serial_node_drives_the_twin_through_a_pty(launch, observer, tmp_path):
    link = tmp_path / "tty"
    twin = start_twin(link)
    try:
        rig = SerialNodeRig(launch, observer, str(link), 0.2)

        def connection():
            return status_values(rig.status()).get("connection") if rig.status() else None
        assert observer.spin_until(lambda: connection() == "connected", 20)
        rig.angles.publish(angles([70, 110, 80, 120], sec=35))
        assert observer.spin_until(lambda: any(m.header.stamp.sec == 35 for _, m in rig.state), 10)
        assert observer.spin_until(lambda: [round(math.degrees(p)) for p in rig.state[-1][1].position] == [70, 110, 80, 120], 10)
        assert twin.poll() is None, "the twin stopped"
    finally:
        twin.send_signal(signal.SIGINT)
        assert twin.wait(10) == 0
    # its link is gone with it, and serial_node says the device is lost
    assert not os.path.exists(link)
    assert observer.spin_until(lambda: status_values(rig.status()).get("connection") == "disconnected", 15)
