"""One trial of each measurement of tests/bench/commanders.py (issue 33, item 5): every
commander switched to through controller_manager/switch_controller and moving the arm on
the firmware in simavr, and the e-stop during each one's motion holding the pulses.

The program is run as it is run for BENCHMARKS.md (--trials 1, the binaries of this test
run); the test fails when a trial fails (a refused switch, no servo_angles from the new
commander, a sample its reader missed, no e-stop at the board, a pulse not held), with
the program's reason. No timing is asserted: the figures it prints are kept in
test-output/commanders_bench.json."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import OUTPUT, REPO

pytestmark = pytest.mark.timeout(300)


def test_one_trial_of_each_commander_switch_and_estop():
    OUTPUT.mkdir(parents=True, exist_ok=True)
    out = OUTPUT / "commanders_bench.json"
    env = {**os.environ, "EEZYBOT_BIN_DIR": os.environ.get("EEZYBOT_BIN_DIR", str(REPO / "target" / "debug"))}
    r = subprocess.run([sys.executable, str(Path(REPO, "tests", "bench", "commanders.py")), "--trials", "1",
                        "--json", str(out)], env=env, capture_output=True, text=True, timeout=280)
    assert r.returncode == 0, f"exit {r.returncode}\n{r.stdout[-4000:]}\n{r.stderr[-4000:]}"
    assert "| `teleop`" in r.stdout, r.stdout
