"""The servo link protocol (firmware/servo_control/PROTOCOL.md, version 3), written again
from the document for the tests: frames, a decoder, the leader role's LEADER_STATE, and
helpers to run the firmware in simavr (with recorded potentiometer and deadman inputs
for the leader role)."""
import os
import signal
import struct
import subprocess
import termios
import time
import tty
from pathlib import Path

SYNC = 0xA5
PROTOCOL_VERSION = 3
HELLO, HELLO_ACK, SET_PULSES, HEARTBEAT, STATE, ESTOP, CONFIG, ROLE, LEADER_STATE = 1, 2, 3, 4, 5, 6, 7, 8, 9
PAYLOAD_LEN = {HELLO: 1, HELLO_ACK: 6, SET_PULSES: 8, HEARTBEAT: 0, STATE: 12, ESTOP: 1, CONFIG: 3, ROLE: 1,
               LEADER_STATE: 11}
STATES = {0: "idle", 1: "running", 2: "watchdog hold", 3: "watchdog detached", 4: "estop", 5: "leader"}
FOLLOWER, LEADER = 0, 1
CYCLES_PER_US = 16
# The leader role: LEADER_STATE every window of 64 conversions 150 us apart (16 a channel,
# A0 A1 A2 A3 A0 ...); a channel is the sum of its 16 10-bit samples, and 16 x 1024 stands
# for the ADC reference, AVcc (5 V)
LEADER_PERIOD_US = 9600
LEADER_OVERSAMPLING = 16
LEADER_FULL_SCALE = LEADER_OVERSAMPLING * 1024
AVCC_MV = 5000


def crc8(data):
    crc = 0
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def frame(msg_type, seq, payload=b""):
    body = bytes([(msg_type << 4) | len(payload), seq & 0xFF]) + payload
    return bytes([SYNC]) + body + bytes([crc8(body)])


def set_pulses(seq, ticks):
    return frame(SET_PULSES, seq, struct.pack("<4H", *ticks))


def config(seq, watchdog_ms, detach):
    return frame(CONFIG, seq, struct.pack("<HB", watchdog_ms, 1 if detach else 0))


def role(seq, which):
    """ROLE: FOLLOWER (0) or LEADER (1)."""
    return frame(ROLE, seq, bytes([which]))


def frames_sent(tx):
    """(cycle of the first byte, type, payload) of every whole frame in `tx`, the
    (cycle, byte) pairs an AVR sent (the simavr harness's `t` events); a frame cut off at
    the end is left out. The start byte and every CRC are asserted."""
    out, i = [], 0
    while i + 2 <= len(tx):
        assert tx[i][1] == SYNC, f"the AVR sent {tx[i][1]:#x} where a frame starts"
        n = (tx[i + 1][1] & 0x0F) + 4
        if i + n > len(tx):
            break
        body = bytes(b for _, b in tx[i + 1:i + n - 1])
        assert crc8(body) == tx[i + n - 1][1]
        out.append((tx[i][0], body[0] >> 4, body[2:]))
        i += n
    return out


class Decoder:
    def __init__(self):
        self.buf = bytearray()

    def feed(self, data):
        """Append bytes; return the complete, valid frames as (type, seq, payload)."""
        self.buf += data
        out = []
        while True:
            i = self.buf.find(SYNC)
            if i < 0:
                self.buf.clear()
                return out
            del self.buf[:i]
            if len(self.buf) < 2:
                return out
            n = (self.buf[1] & 0x0F) + 4
            if len(self.buf) < n:
                return out
            f = bytes(self.buf[:n])
            if crc8(f[1:-1]) != f[-1] or PAYLOAD_LEN.get(f[1] >> 4) != n - 4:
                del self.buf[:1]
                continue
            out.append((f[1] >> 4, f[2], f[3:-1]))
            del self.buf[:n]


def parse_state(payload):
    ack_seq, state, clamped, rx_errors = payload[:4]
    return {"ack_seq": ack_seq, "state": STATES[state], "clamped": bool(clamped), "rx_errors": rx_errors,
            "ticks": list(struct.unpack("<4H", payload[4:12]))}


def parse_leader_state(payload):
    """A LEADER_STATE: `adc` the four sums (0..16368), `millivolts` what they stand for at
    AVcc = 5 V (sum / 16384 x 5000), `deadman` held throughout the window, `window` its
    number (wraps), `overruns` the device's late samples (wraps)."""
    *adc, buttons, window, overruns = struct.unpack("<4HBBB", payload)
    if buttons > 1:
        raise ValueError(f"buttons byte {buttons:#x}: only bit 0 is defined")
    return {"adc": adc, "millivolts": [a * AVCC_MV / LEADER_FULL_SCALE for a in adc], "deadman": bool(buttons),
            "window": window, "overruns": overruns}


def leader_state(seq, adc, deadman, window, overruns=0):
    """A LEADER_STATE frame (as the device sends it)."""
    return frame(LEADER_STATE, seq, struct.pack("<4HBBB", *adc, 1 if deadman else 0, window & 0xFF, overruns & 0xFF))


def write_adc_file(path, points):
    """servo_sim --adc-file: `points` of (t_ms, [mv0, mv1, mv2, mv3], deadman held)."""
    lines = ["# t_ms mv0 mv1 mv2 mv3 deadman"]
    lines += [f"{t:g} {' '.join(f'{mv:g}' for mv in mvs)} {1 if held else 0}" for t, mvs, held in points]
    Path(path).write_text("\n".join(lines) + "\n")


class SimulatedUno:
    """The servo_control ELF in simavr (firmware/servo_control/build/servo_sim)."""

    def __init__(self, workdir, firmware_dir, boot=0, clock_ppm=0.0, adc_file=None):
        """`boot` > 0: the same board reset (a new simavr process on the same pty link),
        with its own events file. `clock_ppm`: the board's clock error against wall time
        (servo_sim --clock-ppm). `adc_file`: the leader's recorded inputs (A0..A3 and the
        deadman button, servo_sim --adc-file; write_adc_file)."""
        self.workdir = Path(workdir)
        self.tty_path = self.workdir / "tty"
        tag = f"-{boot}" if boot else ""
        self.events_path = self.workdir / f"events{tag}.txt"
        self.log = open(self.workdir / f"servo_sim{tag}.log", "w")
        sim = Path(firmware_dir) / "build" / "servo_sim"
        elf = Path(firmware_dir) / "build" / "servo_control.elf"
        args = [str(sim), str(elf), "--pty-link", str(self.tty_path), "--events", str(self.events_path)]
        if clock_ppm:
            args += ["--clock-ppm", repr(float(clock_ppm))]
        if adc_file:
            args += ["--adc-file", str(adc_file)]
        self.proc = subprocess.Popen(args, stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 10
        while not self.tty_path.exists():
            assert time.monotonic() < deadline, "servo_sim did not create its pty"
            assert self.proc.poll() is None, "servo_sim exited"
            time.sleep(0.01)
        self.fd = None
        self.decoder = Decoder()

    def open(self):
        self.fd = os.open(self.tty_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.fd)
        termios.tcflush(self.fd, termios.TCIOFLUSH)

    def send(self, data):
        os.write(self.fd, data)

    def receive(self, seconds):
        """Frames received within `seconds`."""
        out = []
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                data = os.read(self.fd, 256)
            except BlockingIOError:
                time.sleep(0.005)
                continue
            out += self.decoder.feed(data)
        return out

    def wait_for(self, predicate, seconds=5):
        """The first frame from the board that `predicate` accepts, and the frames the pty
        gave meanwhile. A frame the pty lost is found in the board's own record of the
        bytes it sent (the events file's `t` lines written since the wait began): a test
        starved of CPU does not read, the pty's buffer fills, and servo_sim's writes of
        what the AVR sends then fail (a CI run: 150 LEADER_STATEs and the STATE waited for
        gone between two reads)."""
        end = time.monotonic() + seconds
        seen = []
        record, pos = Decoder(), self.events_path.stat().st_size if self.events_path.exists() else 0
        while time.monotonic() < end:
            for f in self.receive(0.05):
                seen.append(f)
                if predicate(f):
                    return f, seen
            with open(self.events_path, "rb") as log:
                log.seek(pos)
                chunk = log.read()
            cut = chunk.rfind(b"\n") + 1
            pos += cut
            for line in chunk[:cut].decode("ascii", "replace").splitlines():
                p = line.split()
                if len(p) == 3 and p[0] == "t":
                    for f in record.feed(bytes([int(p[2])])):
                        if predicate(f):
                            return f, seen
        raise AssertionError(f"no matching frame in {seconds} s; got {seen}")

    def events(self):
        """Pin edges [(cycle, pin, level)] and bytes delivered to the AVR [(cycle, byte)]."""
        edges, rx = [], []
        for line in self.events_path.read_text().splitlines():
            parts = line.split()
            if len(parts) == 4 and parts[0] == "e":
                edges.append((int(parts[1]), int(parts[2]), int(parts[3])))
            elif len(parts) == 3 and parts[0] == "r":
                rx.append((int(parts[1]), int(parts[2])))
        return edges, rx

    def sim_cycle(self):
        """The simulated cycle of the event file's last whole line (the harness flushes
        it every few ms of simulated time)."""
        with open(self.events_path, "rb") as f:
            f.seek(max(0, os.path.getsize(self.events_path) - 256))
            lines = f.read().split(b"\n")[:-1]
        return int(lines[-1].split()[1]) if lines else 0

    def toggle_cable(self, plugged):
        """Pull the USB cable (the pty goes away, the AVR runs on) or plug it back."""
        self.proc.send_signal(signal.SIGUSR1)
        deadline = time.monotonic() + 5
        while self.tty_path.exists() != plugged:
            assert time.monotonic() < deadline, "servo_sim did not toggle its pty"
            time.sleep(0.002)

    def pull_cable(self):
        """The board is gone at once (SIGKILL: no goodbye), and its device node with it,
        as a USB serial device's does. The node goes first: with a node left behind (a
        killed servo_sim cannot remove its link), a serial_node retrying the port opened
        the pty the kernel gave the next simulated board under the same /dev/pts number,
        another test's (fresh-clone run Q: test_leader_firmware's board got a leader's
        HELLO, CONFIG and ROLE from test_leader_arm's serial_node, and restarted its
        windows)."""
        self.tty_path.unlink(missing_ok=True)
        self.proc.kill()
        self.proc.wait(10)

    def stop(self):
        if self.fd is not None:
            os.close(self.fd)
        self.proc.send_signal(signal.SIGINT)
        code = self.proc.wait(10)
        self.log.close()
        return code


def pulses(edges, pin, after_cycle=0):
    """(rise_cycle, width_us) of every complete pulse on `pin` that starts after `after_cycle`."""
    out, rise = [], None
    for cycle, p, level in edges:
        if p != pin:
            continue
        if level == 1:
            rise = cycle
        elif rise is not None:
            if rise >= after_cycle:
                out.append((rise, (cycle - rise) / CYCLES_PER_US))
            rise = None
    return out
