"""--origin file for drill, HPGL, SVG and DXF files (issue #29 point 1): the file's own zero goes to the active work
zero, so each hole or stroke is cut at the work zero plus the file's own coordinates; the travel is checked in
the machine frame before anything moves (one line naming the axis and by how much, exit code 2).  Checked on
the mock's decoded pin log, put in the machine frame.

The files are small and their zero lies away from what they draw: a square of holes or strokes at X 10..20 mm,
Y 10..20 mm of the file.  Drill and HPGL files have Y up (toward the back of the machine: machine y = -Y);
an SVG page has y down (machine y = y).
"""
from __future__ import annotations

import io
import json
from dataclasses import replace

import ezdxf
import numpy as np
import pytest

from cam.drive.session import MachineSession
from cam.drive.state import MachineState, StateHold
from cam.errors import TravelError
from cam.kinds.jobs import JobOptions, prepare_job
from cam.settings import DEFAULT_SETTINGS as S
from cam.verify.pinlog import decode_pin_log, read_pin_log

from conftest import run_cli

CORNERS_MM = [(10.0, 10.0), (20.0, 10.0), (20.0, 20.0), (10.0, 20.0)]
"""The square each file draws, in the file's own frame (mm)."""

FILES = {
    "board.drl": "M48\nMETRIC\nT1C0.800\n%\nG90\nG05\nT1\n"
                 + "".join(f"X{x:.1f}Y{y:.1f}\n" for x, y in CORNERS_MM) + "M30\n",
    # 40 plotter units per mm
    "square.plt": "IN;SP1;PU400,400;PD800,400,800,800,400,800,400,400;PU;\n",
    "square.svg": '<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="100mm" viewBox="0 0 100 100">'
                  '<path d="M10,10 H20 V20 H10 Z" stroke="black" fill="none"/></svg>\n',
}
Y_UP = {"board.drl": True, "square.plt": True, "square.svg": False}


def _square_dxf() -> str:
    """The square as a closed LWPOLYLINE of a DXF in mm (y up, as drawn: machine y = -Y, issue #48 point 2)."""
    doc = ezdxf.new("R2000")
    doc.units = 4
    doc.modelspace().add_lwpolyline(CORNERS_MM, close=True)
    text = io.StringIO()
    doc.write(text)
    return text.getvalue()


FILES["square.dxf"] = _square_dxf()
Y_UP["square.dxf"] = True


def _file(tmp_path, name: str):
    path = tmp_path / name
    path.write_text(FILES[name])
    return path


def _own_steps(name: str) -> set[tuple[int, int]]:
    """The square's corners in machine steps from the file's zero (nearest step; Y flipped for Y-up files)."""
    sign = -1 if Y_UP[name] else 1
    return {(int(round(x / S.mm_per_step_xy)), sign * int(round(y / S.mm_per_step_xy))) for x, y in CORNERS_MM}


def _zero(state, at_mm: str) -> np.ndarray:
    """``cam zero XYZ --at`` a machine point; the work zero in machine steps."""
    r = run_cli("zero", "XYZ", "--at", at_mm, "--state", state)
    assert r.returncode == 0, r.stderr
    where = json.loads(run_cli("where", "--json", "--state", state).stdout)
    return np.array(where["offsets_steps"]["G54"], np.int64)


def _cut(tmp_path, name: str, *flags: str, at_mm: str = "50,50,0") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(zero, home, cut)``: the work zero, where the job started and ended, and the ``(N, 3)`` machine positions
    below the work zero's surface of ``cam drill FILE --yes flags`` on the mock, decoded from its pin log."""
    state, log = tmp_path / "state.json", tmp_path / "job.csv"
    zero = _zero(state, at_mm)
    r = run_cli("drill", _file(tmp_path, name), "--yes", "--state", state, "--pin-log", log, *flags)
    assert r.returncode == 0, r.stderr
    home = np.array(json.loads(run_cli("where", "--json", "--state", state).stdout)["machine_steps"], np.int64)
    pos = decode_pin_log(read_pin_log(log, part="job"), S).position_steps + home  # a job ends at its home
    return zero, home, pos[pos[:, 2] > zero[2]]


@pytest.mark.parametrize("name", list(FILES))
def test_origin_file_cuts_at_the_work_zero_plus_the_files_own_coordinates(tmp_path, name):
    zero, home, cut = _cut(tmp_path, name, "--origin", "file")
    assert tuple(home) == tuple(zero)  # the job's home is the file's zero, at the work zero
    want = {(int(zero[0]) + x, int(zero[1]) + y) for x, y in _own_steps(name)}
    xy = {(int(x), int(y)) for x, y in cut[:, :2]}
    lo = np.array(sorted(want)).min(axis=0)
    hi = np.array(sorted(want)).max(axis=0)
    if name.endswith(".drl"):
        deepest = cut[cut[:, 2] == cut[:, 2].max()]
        assert {(int(x), int(y)) for x, y in deepest[:, :2]} == want  # each hole at the bottom of its plunge
    else:
        assert want <= xy  # every corner of the square is cut
    # nothing is cut outside the square (a drill's plunge and a stroke's cut stay within it, to the step)
    assert cut[:, 0].min() == lo[0] and cut[:, 0].max() == hi[0], (cut[:, :2].min(axis=0), lo)
    assert cut[:, 1].min() == lo[1] and cut[:, 1].max() == hi[1], (cut[:, :2].max(axis=0), hi)


def test_offset_without_origin_puts_the_files_zero_that_far_from_the_work_zero(tmp_path):
    zero, _, cut = _cut(tmp_path, "board.drl", "--offset", "5,7")
    dx, dy = int(round(5 / S.mm_per_step_xy)), int(round(7 / S.mm_per_step_xy))
    deepest = cut[cut[:, 2] == cut[:, 2].max()]
    # the holes' mm are added before rounding: within a step of the sum of the rounded parts
    got = np.array(sorted({(int(x), int(y)) for x, y in deepest[:, :2]}))
    want = np.array(sorted((int(zero[0]) + dx + x, int(zero[1]) + dy + y) for x, y in _own_steps("board.drl")))
    assert np.abs(got - want).max() <= 1, (got, want)


@pytest.mark.parametrize("name, at_mm, axis", [("board.drl", "50,10,0", "Y"), ("square.plt", "50,10,0", "Y"),
                                               ("square.svg", "280,50,0", "X")])
def test_a_file_whose_own_coordinates_leave_the_travel_is_refused_before_anything_moves(tmp_path, name, at_mm,
                                                                                         axis):
    state, log = tmp_path / "state.json", tmp_path / "job.csv"
    zero = _zero(state, at_mm)
    r = run_cli("drill", _file(tmp_path, name), "--origin", "file", "--yes", "--state", state, "--pin-log", log)
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    a = "XY".index(axis)
    lo, hi = S.travel.bounds_steps()[a]
    reach = [int(zero[a]) + v[a] for v in _own_steps(name)]
    beyond = lo - min(reach) if min(reach) < lo else max(reach) - hi
    assert beyond > 0
    assert f"({beyond} steps) beyond the {axis} travel" in lines[0], lines[0]
    assert "G54 work zero" in lines[0] and "cam zero" in lines[0], lines[0]
    where = json.loads(run_cli("where", "--json", "--state", state).stdout)
    assert where["machine_steps"] == [0, 0, 0] and where["position_known"] and where["running"] is None
    assert not log.exists()  # nothing moved


@pytest.mark.parametrize("name", list(FILES))
def test_the_other_origins_still_put_their_point_of_the_cut_on_the_work_zero(tmp_path, name):
    for origin, (ix, iy) in {"upper-left": (0, 0), "lower-left": (0, 1)}.items():
        zero, _, cut = _cut(tmp_path, name, "--origin", origin)
        box = np.array([[cut[:, 0].min(), cut[:, 0].max()], [cut[:, 1].min(), cut[:, 1].max()]])
        assert (box[0, ix], box[1, iy]) == (zero[0], zero[1]), (origin, box, zero)
    zero, _, cut = _cut(tmp_path, name, "--origin", "center")
    mid = (cut[:, :2].min(axis=0) + cut[:, :2].max(axis=0)) // 2
    assert np.abs(mid - zero[:2]).max() <= 1, (mid, zero)


@pytest.mark.parametrize("name", list(FILES))
def test_prepare_job_plans_a_file_placed_by_its_own_zero_from_the_work_zero(tmp_path, name):
    """The library: with a machine state the job's travel is checked from the active work zero; without one from
    the home (a new machine's work zero), where a Y-up file's square lies behind the travel."""
    path = _file(tmp_path, name)
    zero = (1730, 1730, 0)
    state = MachineState(offsets_steps={**MachineState().offsets_steps, "G54": zero})
    job = prepare_job(path, JobOptions(origin="file"), S, machine_state=state)
    extent, cut = job.plan.motion_extent()
    own = np.array(sorted(_own_steps(name)))
    assert cut[0].tolist() == [own[:, 0].min(), own[:, 0].max()]
    assert cut[1].tolist() == [own[:, 1].min(), own[:, 1].max()]
    if Y_UP[name]:
        with pytest.raises(TravelError, match="beyond the Y travel"):
            prepare_job(path, JobOptions(origin="file"), S)
    else:
        assert prepare_job(path, JobOptions(origin="file"), S).plan.motion_extent()[1][1, 0] == own[:, 1].min()


def test_a_session_places_a_job_planned_from_its_own_zero_by_that_zero(tmp_path):
    """The Python API (and the page's session): a job whose options chose ``origin="file"`` is placed by its own
    zero without saying it again to :meth:`MachineSession.start`."""
    hold = StateHold(tmp_path / "m.json", S, "the test")
    try:
        hold.save(replace(hold.state, offsets_steps={**hold.state.offsets_steps, "G54": (1730, 1730, 0)}))
        job = prepare_job(_file(tmp_path, "board.drl"), JobOptions(origin="file"), S, machine_state=hold.state)
        assert job.origin == "file"
        ses = MachineSession("mock", S, state=hold, on_prompt=lambda prompt: "continue")  # the tool change
        assert ses.run(job)["status"] == "finished"
        pos = decode_pin_log(ses.last_job_pin_log, S).position_steps + np.array([1730, 1730, 0])
        deepest = pos[pos[:, 2] == pos[:, 2].max()]
        want = {(1730 + x, 1730 + y) for x, y in _own_steps("board.drl")}
        assert {(int(x), int(y)) for x, y in deepest[:, :2]} == want
    finally:
        hold.close()


def test_a_run_stopped_at_its_first_pause_resumes_at_the_work_zero(tmp_path):
    """--resume of a file placed by its own zero is checked from the work zero too (as the run was)."""
    state, journal, log = tmp_path / "state.json", tmp_path / "j.journal.json", tmp_path / "res.csv"
    zero = _zero(state, "50,50,0")
    path = _file(tmp_path, "board.drl")
    stopped = run_cli("drill", path, "--origin", "file", "--state", state, "--journal", journal)  # no answer: stops
    assert stopped.returncode == 130, stopped.stderr
    r = run_cli("drill", path, "--origin", "file", "--yes", "--state", state, "--resume", journal, "--pin-log", log)
    assert r.returncode == 0, r.stderr
    where = json.loads(run_cli("where", "--json", "--state", state).stdout)
    assert where["machine_steps"] == zero.tolist()  # the job ends at its home: the file's zero, at the work zero
    pos = decode_pin_log(read_pin_log(log, part="job"), S).position_steps + zero
    deepest = pos[pos[:, 2] == pos[:, 2].max()]
    assert {(int(x), int(y)) for x, y in deepest[:, :2]} == {(int(zero[0]) + x, int(zero[1]) + y)
                                                             for x, y in _own_steps("board.drl")}


def test_a_g_code_program_stopped_at_m0_resumes_from_where_it_started(tmp_path):
    """A program is checked in the machine frame from its start, and so is its resumed run: one that goes
    toward the back of the machine (G-code +Y) from a work zero with room there resumes."""
    state, journal = tmp_path / "state.json", tmp_path / "g.journal.json"
    _zero(state, "50,50,0")
    r = run_cli("goto", "0,0,0", "--state", state)
    assert r.returncode == 0, r.stderr
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90\nG0 X10 Y10\nG1 Z-1 F100\nM0\nG1 X20 F200\nG0 Z1\nG0 X0 Y0\nG0 Z0\nM2\n")
    stopped = run_cli("drill", prog, "--state", state, "--journal", journal)
    assert stopped.returncode == 130, stopped.stderr
    r = run_cli("drill", prog, "--yes", "--state", state, "--resume", journal)
    assert r.returncode == 0, r.stderr
    where = json.loads(run_cli("where", "--json", "--state", state).stdout)
    assert where["work_steps"] == [0, 0, 0], where
