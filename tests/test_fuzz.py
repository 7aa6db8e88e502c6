"""The firmware's frame parser and the sketch's logic fuzzed on the host (libFuzzer with
ASan and UBSan; firmware/servo_control/fuzz/README.md): a short run of each target in
the test command, and the one finding so far (fixed), on the host and on the real ELF in simavr.
Long runs: `make -C firmware/servo_control fuzz RUNS=1000000`."""
import shutil
import subprocess

import pytest

from conftest import REPO
from interop.servo_link import HEARTBEAT, STATE, SimulatedUno, frame, parse_state, set_pulses

# the fuzzers' build and runs have limits of their own (600 s each), above the default
# in a process of its own beside the other tests (judged by order and content, not the wall clock)
pytestmark = [pytest.mark.own_process, pytest.mark.background(seconds=25), pytest.mark.timeout(1300)]

FIRMWARE = REPO / "firmware" / "servo_control"
FUZZ_DIR = FIRMWARE / "build" / "fuzz"
SHORT_RUNS = 20_000


@pytest.fixture(scope="module")
def fuzzers():
    assert shutil.which("clang++"), "clang++ is missing: launch_scripts/setup_env.sh installs clang and libclang-rt-14-dev"
    build = subprocess.run(["make", "-C", str(FIRMWARE), "fuzz-build"], capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout[-2000:] + build.stderr[-3000:]
    return FUZZ_DIR


def run_fuzzer(fuzzers, target, runs, tmp_path):
    """`runs` runs from an empty corpus with a fixed seed (deterministic); the output."""
    corpus = tmp_path / f"corpus-{target}"
    corpus.mkdir()
    p = subprocess.run([str(fuzzers / f"fuzz_{target}"), f"-runs={runs}", "-seed=1", "-print_final_stats=1",
                        f"-dict={FIRMWARE / 'fuzz' / 'protocol.dict'}", f"-artifact_prefix={tmp_path}/", str(corpus)],
                       capture_output=True, text=True, timeout=600)
    return p.returncode, p.stderr


def finding(out):
    """The harness's account of a finding (what broke, the step, both sides' answers)."""
    keep = ("INVARIANT", "  ", "step ", "Test unit written", "Done ", "ERROR: AddressSanitizer", "runtime error")
    lines = [line for line in out.splitlines() if line.startswith(keep) and not line.lstrip().startswith("#")]
    return "\n".join(lines[-12:]) or out[-1500:]


@pytest.mark.parametrize("target", ["decoder", "firmware"])
def test_a_short_fuzz_run_finds_nothing(fuzzers, target, tmp_path):
    """protocol.cpp against PROTOCOL.md's decoder; the whole sketch (pulse table within
    config.h, replies, watchdog, e-stop, resynchronisation) against PROTOCOL.md's device."""
    code, out = run_fuzzer(fuzzers, target, SHORT_RUNS, tmp_path)
    assert code == 0 and f"Done {SHORT_RUNS} runs" in out, finding(out)


def test_the_strict_model_finds_no_frame_held_back(fuzzers, tmp_path):
    """fuzz_firmware_strict: every frame is handled as soon as its last byte is in.
    100,000 runs (about 20 s): the held-back frame this model caught took 19,000-43,000
    runs to find; `make -C firmware/servo_control fuzz RUNS=1000000` is the soak."""
    code, out = run_fuzzer(fuzzers, "firmware_strict", 100_000, tmp_path)
    assert code == 0, finding(out)


def test_a_complete_frame_after_a_stray_start_byte_is_handled(tmp_path):
    """Line noise `A5 3F` (a start byte whose length nibble says 15), then a HEARTBEAT and a
    SET_PULSES in one write, then a pause as between two heartbeats: both frames are whole
    and valid, so both must be answered and the pulses applied."""
    uno = SimulatedUno(tmp_path, FIRMWARE)
    uno.open()
    try:
        uno.send(b"\xa5\x3f" + frame(HEARTBEAT, 11) + set_pulses(12, [3000] * 4) + b"\x00")
        # nothing more is sent until both are answered: a frame the parser holds back
        # until the next bytes come is never answered here (the 30 s only bound that)
        _, seen = uno.wait_for(lambda f: f[0] == STATE and f[2][0] == 12, 30)
        acks = [parse_state(p)["ack_seq"] for t, _, p in seen if t == STATE]
        uno.send(frame(HEARTBEAT, 13))
        f, _ = uno.wait_for(lambda f: f[0] == STATE and f[2][0] == 13)
        ticks = parse_state(f[2])["ticks"]
    finally:
        assert uno.stop() == 0
    assert acks == [11, 12] and ticks == [3000] * 4, (acks, ticks)

