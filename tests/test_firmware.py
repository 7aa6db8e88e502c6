"""The real servo_control ELF in simavr: pulse widths on PB0..PB3 timed to the cycle,
malformed frames, clamping, the watchdog, the handshake."""
import statistics
import struct

import pytest

from conftest import REPO
from interop.servo_link import (CONFIG, ESTOP, HEARTBEAT, HELLO, HELLO_ACK, STATE, SimulatedUno, config, frame,
                                parse_state, pulses, set_pulses)

FIRMWARE = REPO / "firmware" / "servo_control"
CYCLES_PER_MS = 16_000


@pytest.fixture
def uno(tmp_path):
    u = SimulatedUno(tmp_path, FIRMWARE)
    u.open()
    yield u
    assert u.stop() == 0


def state_reply(uno, seq):
    f, _ = uno.wait_for(lambda f: f[0] == STATE and f[2][0] == seq)
    return parse_state(f[2])


def last_rx_cycle(uno):
    _, rx = uno.events()
    return rx[-1][0]


def medians(uno, after_cycle, frames=6):
    """Median pulse width (us) per pin over `frames` refresh periods after `after_cycle`."""
    uno.receive(frames * 0.02 + 0.1)
    edges, _ = uno.events()
    out = []
    for pin in range(4):
        widths = [w for _, w in pulses(edges, pin, after_cycle)][:frames]
        assert len(widths) >= frames - 1, f"pin {pin}: only {len(widths)} pulses"
        out.append(statistics.median(widths))
    return out


def test_handshake_reports_versions(uno):
    uno.send(frame(HELLO, 1, bytes([1])))
    f, _ = uno.wait_for(lambda f: f[0] == HELLO_ACK)
    version, major, minor, servos, watchdog_ms = struct.unpack("<BBBBH", f[2])
    assert (version, servos, watchdog_ms) == (2, 4, 500)
    assert (major, minor) == (1, 0)


# config.h's hold pose: ROBOT.md's home pose, claw closed (PROTOCOL.md, STATE)
HOLD_TICKS = [2944, 2944, 2944, 2325]


def test_no_pulses_before_the_first_command_and_the_hold_pose_reported(uno):
    uno.send(frame(HEARTBEAT, 1))
    st = state_reply(uno, 1)
    assert st["state"] == "idle" and st["ticks"] == HOLD_TICKS
    uno.receive(0.2)
    edges, _ = uno.events()
    assert all(level == 0 for _, _, level in edges)


@pytest.mark.parametrize("us", [
    (1500, 1500, 1500, 1500),
    (544, 2400, 1000, 2000),
    (1472, 1936.5, 1008, 1163.5),  # half-microsecond ticks
])
def test_each_commanded_pulse_width_appears_on_its_pin(uno, us):
    ticks = [int(round(u * 2)) for u in us]
    uno.send(set_pulses(1, ticks))
    st = state_reply(uno, 1)
    assert st["state"] == "running" and st["ticks"] == ticks and not st["clamped"]
    got = medians(uno, last_rx_cycle(uno))
    for pin, (want, have) in enumerate(zip(us, got)):
        assert have == pytest.approx(want, abs=2.0), f"pin {8 + pin}: {have} us, commanded {want} us"


def test_every_servo_is_refreshed_every_20_ms(uno):
    uno.send(set_pulses(1, [3000] * 4))
    state_reply(uno, 1)
    uno.receive(0.3)
    edges, _ = uno.events()
    for pin in range(4):
        rises = [c for c, _ in pulses(edges, pin)]
        periods = [(b - a) / CYCLES_PER_MS for a, b in zip(rises, rises[1:])]
        assert statistics.median(periods) == pytest.approx(20.0, abs=0.01)


def test_out_of_range_commands_are_clamped_to_the_firmware_table(uno):
    uno.send(set_pulses(1, [100, 9000, 3000, 60000]))
    st = state_reply(uno, 1)
    assert st["clamped"] and st["ticks"] == [1088, 4800, 3000, 4800]
    got = medians(uno, last_rx_cycle(uno))
    assert got == pytest.approx([544, 2400, 1500, 2400], abs=2.0)


def test_malformed_and_corrupted_frames_change_nothing(uno):
    uno.send(set_pulses(1, [3000, 3100, 3200, 3300]))
    before = state_reply(uno, 1)
    good = set_pulses(2, [2000] * 4)
    bad_crc = bytearray(good)
    bad_crc[5] ^= 0x40
    wrong_len = frame(3, 3, b"\x00" * 7)  # SET_PULSES with 7 bytes
    unknown_type = frame(0xC, 4, b"\x01\x02")
    truncated = set_pulses(5, [2500] * 4)[:7]
    uno.send(bytes(bad_crc) + wrong_len + unknown_type + b"\x00\xff\x13\x37" + truncated)
    uno.receive(0.3)
    # a heartbeat after the junk resynchronises and reports the count
    uno.send(frame(HEARTBEAT, 6))
    st = state_reply(uno, 6)
    assert st["ticks"] == before["ticks"] and st["state"] == "running"
    assert st["rx_errors"] > before["rx_errors"]
    got = medians(uno, last_rx_cycle(uno))
    assert got == pytest.approx([1500, 1550, 1600, 1650], abs=2.0)


@pytest.mark.parametrize("detach", [True, False])
def test_watchdog_fires_at_the_configured_simulated_time(uno, detach):
    uno.send(config(1, 200, detach))
    state_reply(uno, 1)
    uno.send(set_pulses(2, [3000] * 4))
    state_reply(uno, 2)
    last_command = last_rx_cycle(uno)
    f, _ = uno.wait_for(lambda f: f[0] == STATE and parse_state(f[2])["state"].startswith("watchdog"), 3)
    assert parse_state(f[2])["state"] == ("watchdog detached" if detach else "watchdog hold")
    uno.receive(0.2)
    edges, _ = uno.events()
    rises = [c for c, _ in pulses(edges, 0, last_command)]
    if detach:
        stopped_after_ms = (rises[-1] - last_command) / CYCLES_PER_MS
        # the last pulse starts within one refresh period after the 200 ms timeout (+1 ms for millis())
        assert 200 - 20 <= stopped_after_ms <= 201 + 20, stopped_after_ms
        assert all(level == 0 for c, _, level in edges if c > rises[-1] + 3 * 16 * 2400)
    else:
        assert (rises[-1] - last_command) / CYCLES_PER_MS > 300  # still pulsing


def test_estop_holds_and_ignores_commands(uno):
    uno.send(set_pulses(1, [3000] * 4))
    state_reply(uno, 1)
    uno.send(frame(ESTOP, 2, b"\x01"))
    assert state_reply(uno, 2)["state"] == "estop"
    uno.send(set_pulses(3, [2000] * 4))
    st = state_reply(uno, 3)
    assert st["state"] == "estop" and st["ticks"] == [3000] * 4
    uno.send(frame(ESTOP, 4, b"\x00"))
    assert state_reply(uno, 4)["state"] == "running"


def test_a_detaching_estop_stops_the_pulses_until_a_new_command(uno):
    """ESTOP 2 stops the pulses at once; after the release nothing goes out (idle,
    reporting the last command as the pose to start from) until a new command."""
    uno.send(set_pulses(1, [3000] * 4))
    state_reply(uno, 1)
    uno.send(frame(ESTOP, 2, b"\x02"))
    assert state_reply(uno, 2)["state"] == "estop"
    stopped_at = last_rx_cycle(uno)
    uno.send(frame(ESTOP, 3, b"\x00"))
    st = state_reply(uno, 3)
    assert st["state"] == "idle" and st["ticks"] == [3000] * 4
    uno.receive(0.1)
    edges, _ = uno.events()
    # the pulse under way when ESTOP arrived may finish: none starts 3 ms after it
    assert not [c for c, _, level in edges if level == 1 and c > stopped_at + 3 * CYCLES_PER_MS]
    uno.send(set_pulses(4, [3100] * 4))
    assert state_reply(uno, 4)["state"] == "running"
    assert medians(uno, last_rx_cycle(uno)) == pytest.approx([1550] * 4, abs=1.0)


# A stray start byte whose length nibble (15) runs over the frames after it: when the 19th
# byte makes that candidate fail, every whole frame behind it must be handled at once, in
# order, each once. protocol.cpp used to return one frame per byte received; the next was
# left in the buffer, and the pause after it made the 5 ms gap rule drop it.
@pytest.mark.parametrize("frames, acks, ticks", [
    # the bad-input campaign's and fuzz_firmware_strict's case, byte for byte
    ([frame(HEARTBEAT, 11), set_pulses(12, [3000] * 4)], [11, 12], [3000] * 4),
    # the most one byte can complete: four frames
    ([frame(HEARTBEAT, seq) for seq in (21, 22, 23, 24)], [21, 22, 23, 24], HOLD_TICKS),
], ids=["heartbeat+set_pulses", "four-heartbeats"])
def test_every_whole_frame_after_a_stray_start_byte_is_handled(uno, frames, acks, ticks):
    data = b"\xa5\x3f" + b"".join(frames) + b"\x00"
    assert len(data) == 19  # the stray candidate's length: the last byte decides it
    uno.send(data)
    replies = uno.receive(0.2)  # a pause far over the 5 ms gap rule
    assert [(t, p[0]) for t, _, p in replies] == [(STATE, a) for a in acks], replies
    states = [parse_state(p) for _, _, p in replies]
    assert states[-1]["ticks"] == ticks
    assert states[0]["rx_errors"] >= 1  # the stray start byte is counted
    if ticks != HOLD_TICKS:
        assert states[-1]["state"] == "running"
        us = [t / 2 for t in ticks]
        assert medians(uno, last_rx_cycle(uno)) == pytest.approx(us, abs=2.0)
    else:
        edges, _ = uno.events()
        assert all(level == 0 for _, _, level in edges)
    # and the link goes on: the next heartbeat is answered with the same pose
    uno.send(frame(HEARTBEAT, acks[-1] + 1))
    assert state_reply(uno, acks[-1] + 1)["ticks"] == ticks
