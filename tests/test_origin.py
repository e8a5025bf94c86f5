"""--origin chooses which point of a drill, HPGL or drawing job goes to the active work zero (issue #29 point 1):
the job's cut, decoded from the pin log and put in the machine frame, has that point on the work zero."""
import json

import numpy as np
import pytest

from cam.settings import DEFAULT_SETTINGS
from cam.verify.pinlog import decode_pin_log, read_pin_log

from conftest import SAMPLES, run_cli

ZERO_MM = (50.0, 100.0, 0.0)  # room on every side for the 82 x 62 mm board


def _cut_box(tmp_path, name: str, *flags: str) -> tuple[np.ndarray, np.ndarray]:
    """``(zero_steps, box)``: the work zero and the ``(2, 2)`` [[x0, x1], [y0, y1]] machine steps of the positions
    below the surface of ``cam drill name flags`` run at a work zero of ``ZERO_MM``."""
    state = tmp_path / "state.json"
    r = run_cli("zero", "XYZ", "--at", ",".join(f"{v:g}" for v in ZERO_MM), "--state", state)
    assert r.returncode == 0, r.stderr
    log = tmp_path / "job.csv"
    r = run_cli("drill", SAMPLES / name, "--yes", "--state", state, "--pin-log", log, *flags)
    assert r.returncode == 0, r.stderr
    where = json.loads(run_cli("where", "--json", "--state", state).stdout)
    zero = np.array(where["offsets_steps"]["G54"], np.int64)
    whole = read_pin_log(log)  # every write of the command (issue #44 point 4): from where it started
    pos = decode_pin_log(whole, DEFAULT_SETTINGS).position_steps + np.array(whole.parts[0].start_steps, np.int64)
    job = whole.parts[-1]  # every job ends back at its own home, where it started
    assert job.name == "job" and tuple(where["machine_steps"]) == job.start_steps
    cut = pos[pos[:, 2] > zero[2]]
    return zero, np.array([[cut[:, 0].min(), cut[:, 0].max()], [cut[:, 1].min(), cut[:, 1].max()]])


@pytest.mark.parametrize("name", ["board.drl", "inkscape_star.plt"])
def test_each_origin_puts_its_point_of_the_cut_on_the_work_zero(tmp_path, name):
    for origin, (ix, iy) in {"upper-left": (0, 0), "lower-left": (0, 1)}.items():
        zero, box = _cut_box(tmp_path, name, "--origin", origin)
        assert (box[0, ix], box[1, iy]) == (zero[0], zero[1]), (origin, box, zero)
    zero, box = _cut_box(tmp_path, name, "--origin", "center")
    assert abs((box[0, 0] + box[0, 1]) // 2 - zero[0]) <= 1 and abs((box[1, 0] + box[1, 1]) // 2 - zero[1]) <= 1


def test_the_default_keeps_each_kind_where_it_was(tmp_path):
    """Drill files: the top-left of what is cut (upper-left); drawings: the drawing's top-left pixel (file)."""
    zero, box = _cut_box(tmp_path, "board.drl")
    assert (box[0, 0], box[1, 0]) == (zero[0], zero[1])
    zero, box = _cut_box(tmp_path, "ellipse.png", "--depth", "2")
    same_zero, same_box = _cut_box(tmp_path, "ellipse.png", "--depth", "2", "--origin", "file")
    assert np.array_equal(box, same_box) and box[0, 0] > zero[0] and box[1, 0] > zero[1]  # margin around it


def test_origin_file_of_a_drill_file_at_the_home_is_refused_in_one_line(tmp_path):
    """The board's own zero at a work zero at the home: its holes (Y up, toward the back) leave the Y travel, said
    in one line naming the axis (tests/test_origin_file.py runs it where it fits)."""
    r = run_cli("drill", SAMPLES / "board.drl", "--yes", "--origin", "file")
    assert r.returncode == 2 and "beyond the Y travel" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_an_origin_for_a_g_code_program_is_refused_in_one_line(tmp_path):
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90\nG0 X1 Y-1\nM2\n")
    r = run_cli("drill", prog, "--yes", "--origin", "center")
    assert r.returncode == 2 and "--origin" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
