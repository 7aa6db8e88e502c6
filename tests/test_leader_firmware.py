"""The real servo_control ELF in simavr in the leader role (PROTOCOL.md, version 3): after
the handshake and ROLE leader, LEADER_STATE frames come every 9.6 ms of simulated time
(>= 100 Hz), their sums are exactly 16 samples of what servo_sim drove on A0..A3 (a
recorded hand motion: steps and ramps, --adc-file), the deadman bit follows D2, no
servo pulse goes out, and ROLE follower or a HELLO ends it all. Every time here is
simulated time (cycles in servo_sim's event file), never the wall clock."""
import statistics
import struct
import time

import pytest

from conftest import REPO
from interop.servo_link import (AVCC_MV, FOLLOWER, HEARTBEAT, HELLO, HELLO_ACK, LEADER, LEADER_FULL_SCALE,
                                LEADER_PERIOD_US, LEADER_STATE, ROLE, STATE, Decoder, SimulatedUno, frame, frames_sent,
                                leader_state, parse_leader_state, parse_state, pulses, role, set_pulses,
                                write_adc_file)

FIRMWARE = REPO / "firmware" / "servo_control"
CYCLES_PER_MS = 16_000
PERIOD_CYCLES = LEADER_PERIOD_US * 16
UART_BYTE_CYCLES = 16_000_000 * 10 / 115_200  # a byte at 115200 baud, 8N1
# what simavr's ADC returns for a voltage: (mv * 1023) // AVCC (its scale; the datasheet's
# is mv * 1024 / AVCC, truncated; either way within 2 codes of the voltage)
LSB_MV = AVCC_MV / 1024


def simavr_code(mv):
    return min(1023, mv * 1023 // AVCC_MV)


# A recorded hand motion (simulated ms): steady, a step, the deadman released for half a
# second, ramps in both directions, a 3 ms release inside the ramp, then steady again.
STEADY_A = [1000, 2000, 3000, 4000]
STEADY_B = [5000, 0, 2500, 1234]
RAMP_FROM, RAMP_TO = [0, 5000, 1000, 2500], [5000, 0, 3000, 2500]
MOTION = [
    (0, STEADY_A, True),
    (1000, STEADY_A, True),
    (1000, STEADY_B, True),  # a step
    (1500, STEADY_B, False),  # deadman released
    (2000, STEADY_B, True),
    (2000, RAMP_FROM, True),  # a step to the ramps' start
    (2500, [RAMP_FROM[c] + (RAMP_TO[c] - RAMP_FROM[c]) * 500 / 2000 for c in range(4)], False),  # 3 ms release
    (2503, [RAMP_FROM[c] + (RAMP_TO[c] - RAMP_FROM[c]) * 503 / 2000 for c in range(4)], True),
    (4000, RAMP_TO, True),
]
SEGMENTS = {"steady A": (300, 1000), "steady B": (1000, 2000), "ramps": (2000, 4000), "steady end": (4000, 4600)}


def driven_mv(t_ms, ch):
    """The file's voltage at `t_ms` (as servo_sim interpolates it)."""
    i = max(k for k, p in enumerate(MOTION) if p[0] <= t_ms)
    if i + 1 == len(MOTION) or MOTION[i + 1][0] == MOTION[i][0]:
        return MOTION[i][1][ch]
    (t0, a, _), (t1, b, _) = MOTION[i], MOTION[i + 1]
    return a[ch] + (b[ch] - a[ch]) * (t_ms - t0) / (t1 - t0)


def sim_events(path):
    """From servo_sim's event file: the AVR's frames [(cycle of the first byte, type,
    payload)], conversions [(cycle, channel, mv)], D2 changes [(cycle, level)], pin edges."""
    tx, conversions, d2, edges = [], [], [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == "t":
            tx.append((int(parts[1]), int(parts[2])))
        elif len(parts) == 4 and parts[0] == "a":
            conversions.append((int(parts[1]), int(parts[2]), int(parts[3])))
        elif len(parts) == 3 and parts[0] == "d":
            d2.append((int(parts[1]), int(parts[2])))
        elif len(parts) == 4 and parts[0] == "e":
            edges.append((int(parts[1]), int(parts[2]), int(parts[3])))
    return frames_sent(tx), conversions, d2, edges


def run_until_sim_ms(uno, ms, heartbeat_s=0.1, seq=100):
    """Keep the link alive as a host does (a HEARTBEAT every 100 ms, or none:
    `heartbeat_s` None) until the simulation reaches `ms`; the frames received. (The
    deadline only bounds a failure: a starved simavr runs slower than real time.)"""
    got = []
    deadline = time.monotonic() + ms / 1000 * 10 + 30
    while uno.sim_cycle() < ms * CYCLES_PER_MS:
        assert time.monotonic() < deadline, "the simulation does not get on"
        if heartbeat_s:
            seq += 1
            uno.send(frame(HEARTBEAT, seq & 0xFF))
        got += uno.receive(heartbeat_s or 0.1)
    return got


def test_the_python_side_speaks_protocol_md_s_leader_examples():
    """servo_link.py, written from PROTOCOL.md, against its examples (the Rust side's
    tests/properties.rs checks the same bytes): ROLE and LEADER_STATE encode to them, the
    decoder takes them, the scale is the page's."""
    doc = (FIRMWARE / "PROTOCOL.md").read_text()
    role_frame = role(2, LEADER)
    leader_frame = leader_state(0x31, [4096, 8192, 12288, 16368], True, 8)
    for f in (role_frame, leader_frame):
        assert f.hex(" ").upper() in doc
    got = Decoder().feed(b"\x00\xa5" + role_frame + leader_frame)
    assert [(t, seq) for t, seq, _ in got] == [(ROLE, 2), (LEADER_STATE, 0x31)]
    s = parse_leader_state(got[1][2])
    assert s == {"adc": [4096, 8192, 12288, 16368], "millivolts": [1250.0, 2500.0, 3750.0, 16368 / 16384 * 5000],
                 "deadman": True, "window": 8, "overruns": 0}
    bad = bytearray(leader_frame[3:-1])
    bad[8] = 2
    with pytest.raises(ValueError):
        parse_leader_state(bytes(bad))
    # a LEADER_STATE one byte short is no frame
    short = frame(LEADER_STATE, 1, bytes(10))
    assert Decoder().feed(short) == []


def run_past(uno, pred, ms):
    """Keep the link alive (a HEARTBEAT every 50 ms: the event file grows only with
    what happens on the board, and an idle AVR does nothing else) until the event file
    holds the frame the AVR sent that `pred(cycle, type, payload)` picks and the
    simulation has run `ms` of simulated time past it; that frame's cycle. What did not
    happen by then did not happen in `ms` of the board's time, however busy the host."""
    deadline = time.monotonic() + ms / 1000 * 10 + 30
    cycle, k = None, 0
    while cycle is None or uno.sim_cycle() < cycle + ms * CYCLES_PER_MS:
        assert time.monotonic() < deadline, "the simulation does not get on"
        uno.send(frame(HEARTBEAT, 100 + k % 100))  # sequence numbers no test step uses
        k += 1
        uno.receive(0.05)
        if cycle is None:
            frames, *_ = sim_events(uno.events_path)
            cycle = next((c for c, kind, p in frames if pred(c, kind, p)), None)
    return cycle


@pytest.fixture
def leader(tmp_path):
    adc = tmp_path / "motion.txt"
    write_adc_file(adc, MOTION)
    u = SimulatedUno(tmp_path, FIRMWARE, adc_file=adc)
    u.open()
    yield u
    assert u.stop() == 0


def handshake_and_lead(uno):
    uno.send(frame(HELLO, 1, bytes([3])))
    f, _ = uno.wait_for(lambda f: f[0] == HELLO_ACK)
    version, major, minor, servos, watchdog_ms = struct.unpack("<BBBBH", f[2])
    assert (version, major, minor, servos) == (3, 1, 1, 4)
    uno.send(role(2, LEADER))
    f, _ = uno.wait_for(lambda f: f[0] == STATE and f[2][0] == 2)
    st = parse_state(f[2])
    assert st["state"] == "leader" and st["ticks"] == [2944, 2944, 2944, 2325], st


def windows_of(frames, conversions):
    """Each LEADER_STATE of the one leader session in the log with the 64 conversions it
    sums: the ROLE's handling converts once to be rid of the ADC's slow first conversion,
    then starts conversion 0 (A0); each Timer2 interrupt reads one and starts the next.
    Also the cycles of the window's 64 interrupts (when each started the next)."""
    assert len(conversions) > 2 and conversions[0][1] == 0 and conversions[1][1] == 0, conversions[:3]
    convs = conversions[1:]
    out = []
    for cycle, kind, payload in frames:
        if kind != LEADER_STATE:
            continue
        s = parse_leader_state(payload)
        w = len(out)
        assert s["window"] == w % 256, f"window {s['window']} where {w % 256} is due: a window lost"
        window = convs[64 * w:64 * w + 64]
        # the interrupts: the one that read each conversion started the next (logged)
        isrs = [c[0] for c in convs[64 * w + 1:64 * w + 65]]
        if len(isrs) < 64:
            break  # the log ends inside this window
        out.append((cycle, s, window, isrs))
    return out


def test_leader_streams_every_9_6_ms_with_exact_oversampled_values_and_the_deadman(leader):
    handshake_and_lead(leader)
    # a command to a leader: ignored, answered with the role
    leader.send(set_pulses(3, [3000] * 4))
    f, _ = leader.wait_for(lambda f: f[0] == STATE and f[2][0] == 3)
    assert parse_state(f[2])["state"] == "leader"
    got = run_until_sim_ms(leader, 4700)
    # every heartbeat answered, in the leader role
    states = [parse_state(p) for t, _, p in got if t == STATE]
    assert states and all(s["state"] == "leader" for s in states)
    frames, conversions, d2, edges = sim_events(leader.events_path)

    # no pulses, ever: a leader drives nothing
    assert not [e for e in edges if e[2] == 1], edges[:5]

    windows = windows_of(frames, conversions)
    starts = [c for c, *_ in windows]

    # the rate, in simulated time: one window every 9.6 ms, never missed, none late. On
    # the wire (a frame's first byte), each LEADER_STATE within 3 ms of its window's end
    # but for the time the UART spent on the frames before it: a STATE answering a
    # heartbeat goes first, 16 bytes, 1.4 ms, and a host busy elsewhere may hand the board
    # several heartbeats at once, which its loop handles before the window (measured on a
    # host loaded far past its cores: at most 0.86 ms)
    span = [c for c in starts if 1000 * CYCLES_PER_MS <= c < 4000 * CYCLES_PER_MS]
    rate = (len(span) - 1) / ((span[-1] - span[0]) / 16e6)
    gaps = [(b - a) / CYCLES_PER_MS for a, b in zip(starts, starts[1:])]
    assert len(span) >= 300 and rate >= 100, (len(span), rate)
    on_wire = [(c, (4 + len(p)) * UART_BYTE_CYCLES) for c, _, p in frames]  # (first byte, cycles on the wire)

    def uart_idle_us(t0, t1):
        """The time between t0 and t1 the UART sent nothing (frames go one after another)."""
        busy = sum(max(0, min(t1, c + n) - max(t0, c)) for c, n in on_wire if c < t1)
        return (t1 - t0 - busy) / 16

    idle = [uart_idle_us(isrs[-1], c) for c, _, _, isrs in windows]
    assert max(idle) <= 3000, max(idle)
    # and where the windows end (each one's last interrupt): 9.6 ms to the cycle
    ends = [isrs[-1] for *_, isrs in windows]
    window_rate = (len(ends) - 1) / ((ends[-1] - ends[0]) / 16e6)
    assert window_rate == pytest.approx(1e6 / LEADER_PERIOD_US, rel=1e-4)
    assert all(abs(b - a - PERIOD_CYCLES) < 16 * 40 for a, b in zip(ends, ends[1:]))
    assert all(s["overruns"] == 0 for _, s, _, _ in windows)
    # 64 conversions a window, channels interleaved A0 A1 A2 A3, 150 us apart
    period_us = [(b - a) / 16 for a, b in zip(windows[5][3], windows[5][3][1:])]
    assert statistics.median(period_us) == pytest.approx(150, abs=0.5), period_us
    assert [ch for _, ch, _ in windows[5][2]] == [0, 1, 2, 3] * 16

    # every sum: exactly the 16 samples of its channel (simavr's 10-bit codes of the
    # voltages servo_sim drove at each conversion's start)
    for _, s, window, _ in windows:
        want = [sum(simavr_code(mv) for _, ch, mv in window if ch == c) for c in range(4)]
        assert s["adc"] == want, (s, window[:4])

    # against the recorded motion: each channel's value, converted as the host does
    # (sum / 16384 x 5 V), is within 2 codes (9.8 mV) of the mean voltage driven over
    # its samples; on a steady input it is that voltage's code x 16
    report = {}
    for name, (t0, t1) in SEGMENTS.items():
        errs = []
        for _, s, window, _ in windows:
            first, last = window[0][0] / CYCLES_PER_MS, window[-1][0] / CYCLES_PER_MS
            if first < t0 + 1 or last > t1 - 1:
                continue  # a window across a step
            for c in range(4):
                mv = statistics.mean(driven_mv(cy / CYCLES_PER_MS, c) for cy, ch, _ in window if ch == c)
                got_mv = s["adc"][c] / LEADER_FULL_SCALE * AVCC_MV
                errs.append(got_mv - mv)
                if name.startswith("steady"):
                    assert s["adc"][c] == 16 * simavr_code(round(mv)), (name, c, s["adc"][c], mv)
        assert len(errs) >= 4 * 40, (name, len(errs))
        assert all(-2 * LSB_MV - 0.5 <= e <= 0.5 for e in errs), (name, min(errs), max(errs))
        report[name] = (len(errs) // 4, min(errs), max(errs))
    # the ramps are averaged, not sampled once: sums between multiples of 16
    ramp = [s for c, s, _, _ in windows if 2100 * CYCLES_PER_MS < c < 3900 * CYCLES_PER_MS]
    assert sum(s["adc"][0] % 16 != 0 for s in ramp) > len(ramp) // 2

    # the deadman bit: set when D2 was low at all 64 samples of the window (each read
    # right after its interrupt starts the next conversion)
    def level(cycle):
        lv = 1
        for c, v in d2:
            if c > cycle:
                break
            lv = v
        return lv

    checked, cleared = 0, []
    for cycle, s, _, isrs in windows:
        # a read within a few us of an edge may see either level; the window's bit is
        # due whenever the other reads decide it (one released read clears it)
        near = {i for i in isrs if any(abs(c - i) < 200 for c, _ in d2)}
        clear = [level(i) for i in isrs if i not in near]
        if 1 in clear:
            want = False
        elif not near:
            want = True
        else:
            continue
        assert s["deadman"] == want, (cycle / CYCLES_PER_MS, s, [level(i) for i in isrs])
        checked += 1
        if not want and 2400 < cycle / CYCLES_PER_MS < 2600:
            cleared.append(cycle / CYCLES_PER_MS)
    assert checked >= len(windows) - 8
    # the 3 ms release at 2500 ms clears the one or two windows it falls in
    assert 1 <= len(cleared) <= 2, cleared
    released = [s["deadman"] for c, s, _, _ in windows if 1510 < c / CYCLES_PER_MS < 1990]
    assert released and not any(released)
    held = [s["deadman"] for c, s, _, _ in windows if 2020 < c / CYCLES_PER_MS < 2490]
    assert held and all(held)

    print(f"{len(windows)} LEADER_STATEs; rate over 1-4 s simulated: {rate:.3f} Hz on the wire, windows "
          f"{window_rate:.4f} Hz; intervals "
          f"{min(gaps):.3f}-{max(gaps):.3f} ms, each at most {max(idle):.0f} us late but for the UART; error (host's conversion - mean driven mV) per segment "
          f"(windows, min, max mV): " + "; ".join(f"{k} {n} {lo:+.2f}..{hi:+.2f}" for k, (n, lo, hi) in report.items()))


def test_the_leader_streams_through_host_silence_and_role_follower_or_hello_end_it(leader):
    handshake_and_lead(leader)
    # the host goes silent for 1.5 s (three watchdog timeouts): the stream goes on, and
    # no watchdog STATE comes (a leader has nothing to hold or stop)
    got = run_until_sim_ms(leader, 1800, heartbeat_s=None)
    assert not [f for f in got if f[0] == STATE]
    frames, *_ = sim_events(leader.events_path)
    late = [c for c, kind, _ in frames if kind == LEADER_STATE and c > 1200 * CYCLES_PER_MS]
    assert len(late) >= 55, len(late)  # 600 ms of 9.6 ms windows

    # ROLE follower: idle, the stream stops (none in the 300 ms of simulated time after
    # the answer), and the board follows commands again
    leader.send(role(10, FOLLOWER))
    f, _ = leader.wait_for(lambda f: f[0] == STATE and f[2][0] == 10)
    assert parse_state(f[2])["state"] == "idle"
    stop = run_past(leader, lambda c, kind, p: kind == STATE and p[0] == 10, 300)
    frames, *_ = sim_events(leader.events_path)
    assert not [c for c, kind, _ in frames if kind == LEADER_STATE and c > stop]
    leader.send(set_pulses(11, [3000] * 4))
    f, _ = leader.wait_for(lambda f: f[0] == STATE and f[2][0] == 11)
    assert parse_state(f[2])["state"] == "running"
    running = run_past(leader, lambda c, kind, p: kind == STATE and p[0] == 11, 100)
    *_, edges = sim_events(leader.events_path)
    # every pulse ever the command's (none before it), and every pin pulsing: 100 ms of
    # simulated time hold 5 servo frames
    widths = [w for pin in range(4) for _, w in pulses(edges, pin)]
    assert widths and all(w == pytest.approx(1500, abs=1) for w in widths), widths[:8]
    assert all(len(pulses(edges, pin, running)) >= 3 for pin in range(4)), [pulses(edges, pin, running) for pin in range(4)]

    # leader again (the pulses stop at once), then a HELLO: a new session, a follower
    leader.send(role(12, LEADER))
    f, _ = leader.wait_for(lambda f: f[0] == STATE and f[2][0] == 12)
    assert parse_state(f[2])["state"] == "leader"
    lead = run_past(leader, lambda c, kind, p: kind == STATE and p[0] == 12, 100)
    frames, *_, edges = sim_events(leader.events_path)
    again = [parse_leader_state(p)["window"] for c, kind, p in frames if kind == LEADER_STATE and c > lead]
    assert again[:3] == [0, 1, 2], "a new stream counts from 0"
    # the pulse under way may end: none starts from 3 ms after the ROLE's answer to the
    # 100 ms of simulated time past it
    assert not [c for c, _, level in edges if level == 1 and c > lead + 3 * CYCLES_PER_MS]
    leader.send(frame(HELLO, 13, bytes([3])))
    leader.wait_for(lambda f: f[0] == HELLO_ACK)
    leader.send(frame(HEARTBEAT, 14))
    f, _ = leader.wait_for(lambda f: f[0] == STATE and f[2][0] == 14)
    assert parse_state(f[2])["state"] == "idle"
    run_past(leader, lambda c, kind, p: kind == STATE and p[0] == 14, 200)
    frames, *_ = sim_events(leader.events_path)
    hello = next(c for c, kind, p in frames if kind == HELLO_ACK and c > lead)
    assert not [c for c, kind, _ in frames if kind == LEADER_STATE and c > hello]
