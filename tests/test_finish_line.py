"""The finish line of ``cam drill`` tells a late real-time run (issue #32 point 6): how long it took, how late
it ended and how many stalls, not only the planned machine time."""
import re

import pytest

from cam.cli.drill import finish_line
from cam.cli.execute import Outcome
from cam.drive.runner import FINISHED

from conftest import run_cli, SAMPLES


def test_a_late_run_says_how_late_and_how_many_stalls():
    late = Outcome(FINISHED, machine_time_s=36.0, timing={"max_late_s": 0.166, "stalls": 1856, "late_total_s": 8.6})
    line = finish_line("gear.png", late, "lookahead", 44.6, simulated=False)
    assert "the run took 0:00:45 (36.0 s machine time planned" in line
    assert "8.6 s late: 1856 stalls over 1 ms, the longest 166 ms" in line


def test_an_on_time_run_says_how_long_it_took_and_nothing_about_lateness():
    on_time = Outcome(FINISHED, machine_time_s=2.0, timing={"max_late_s": 0.00002, "stalls": 0, "late_total_s": 0.0})
    line = finish_line("x", on_time, "constant", 2.01, simulated=False)
    assert "the run took 0:00:02 (2.0 s machine time planned, constant ramps)" in line and "late" not in line


@pytest.mark.realtime
def test_a_real_time_mock_run_prints_the_elapsed_time(tmp_path):
    r = run_cli("drill", SAMPLES / "board.drl", "--yes", "--realtime", "--delay", "0.1,0.1", "--ramp", "constant")
    assert r.returncode == 0, r.stderr
    # the elapsed time, and the lateness exactly when the run was late (a busy test machine may make it late)
    assert re.search(r"^job finished: .*; the run took \d+:\d\d:\d\d \(3\.2 s machine time planned, constant ramps"
                     r"(; \d+\.\d s late: \d+ stalls? over 1 ms, the longest \d+ ms(, \d+ re-ramps?)?)?\)$", r.stdout.strip()), r.stdout
