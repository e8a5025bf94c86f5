"""``cam info`` and ``cam preview`` of a G-code program plan it as ``cam drill`` would run it: from the machine
state file's active work zero (read, never changed), so a program whose origin is the stock's centre is shown
after ``cam zero``, not refused as leaving the travel; its depth is measured below the program's Z = 0 wherever
the tool stands (issue #29 point 4)."""
from __future__ import annotations

import json

from conftest import run_cli

CENTRE = "G21 G90\nG0 X-10 Y10\nG1 Z-1 F100\nG1 X10 Y-10\nG0 Z5\nM2\n"


def test_info_and_preview_plan_a_program_from_the_work_zero(tmp_path):
    prog = tmp_path / "centre.ngc"
    prog.write_text(CENTRE)
    state = ["--state", str(tmp_path / "m.json")]
    r = run_cli("info", prog, *state)
    # the home: X-10 is off the table; info says so and still shows the program's extent (issue #44 point 6)
    assert r.returncode == 0 and "not planned where it would run now" in r.stdout \
        and "leaves the machine travel" in r.stdout and "extent in the program's own frame" in r.stdout, r.stdout
    assert run_cli("goto", "100,100,0", "--unit", "mm", "--machine-coords", *state).returncode == 0
    assert run_cli("zero", "XYZ", *state).returncode == 0
    before = (tmp_path / "m.json").read_bytes()
    r = run_cli("info", prog, "--json", *state)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["depth_mm"] == 1.0048 and rep["size_mm"] == [19.999, 19.999], rep  # 692 steps of 0.0289 mm
    assert (tmp_path / "m.json").read_bytes() == before  # read, not written
    r = run_cli("preview", prog, "-o", tmp_path / "c.png", *state)
    assert r.returncode == 0 and (tmp_path / "c.png").stat().st_size > 1000, r.stderr
    assert run_cli("drill", prog, "--yes", *state).returncode == 0  # ends 5 mm above the work zero
    rep = json.loads(run_cli("info", prog, "--json", *state).stdout)
    assert rep["depth_mm"] == 1.0048, rep  # below the program's Z = 0, not below where the tool now stands
