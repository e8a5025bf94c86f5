"""G-code as a sender runs it (issue #29 point 4): program coordinates are machine coordinates minus the active work
offset (G54..G59.3 from the machine state file, ``cam zero``), G10 L2/L20 change them for the program (kept after
it only with ``--keep-offsets``), G53 moves in the machine frame, G28/G30 go to machine positions.

Real programs whose origin is the stock's lower-left corner or centre (written here in the habits of CamBam, PyCAM,
Fusion 360, pcb2gcode and UGS users) are refused from the home and run after ``cam zero`` at a point with room; the
mock's pin log, decoded, follows LinuxCNC's ``rs274`` run in the same work offsets (a var file) from the same start.
"""
import json
import os
import shutil

import numpy as np
import pytest
from scipy.spatial import cKDTree

import cam
from cam.drive.state import MachineState, read_state, write_state
from cam.formats.gcode import parse_gcode
from cam.kinds.jobs import prepare_job
from support.lcnc import canonical_polyline_mm, parse_canonical, run_rs274

from test_cli import assert_one_line_error, cli

needs_rs274 = pytest.mark.skipif(
    shutil.which("rs274") is None and not os.environ.get("CI"), reason="rs274 (linuxcnc-uspace) not installed"
)

S = cam.MachineSettings()
STEP_MM = np.array([S.mm_per_step_xy, S.mm_per_step_xy, S.mm_per_step_z])
SIGN = np.array([1.0, -1.0, -1.0])  # machine steps (+y toward the operator, +z deeper) -> G-code axes

ZERO = (1730, 6920, 640)
"""The work zero of the tests, machine steps: 50 mm right, 200 mm toward the operator, 10 mm down (room for a
part of up to 150 mm either way, retracts up to 20 mm above it)."""
CENTRE_ZERO = (5190, 3460, 640)
"""The work zero of the centre-origin programs: 150 mm right, 100 mm toward the operator."""

CAMBAM = """( Made using CamBam - http://www.cambam.co.uk )
( plate 4/17/2026 10:42:11 AM )
G21 G90 G64 G40
G0 Z3.0
( T1 : 3.0 )
T1 M6
( Profile1 )
G17
M3 S1000
G0 X5.0 Y5.0
G0 Z1.0
G1 F300.0 Z-0.5
G1 F600.0 X45.0 Y5.0
G3 X50.0 Y10.0 I0.0 J5.0
G1 X50.0 Y30.0
G3 X45.0 Y35.0 I-5.0 J0.0
G1 X5.0 Y35.0
G1 X5.0 Y5.0
G0 Z3.0
M5
M30
"""

PYCAM = """G40 G49 G80 G54 G90
G21
(PyCAM-Toolpath: engrave)
G61
F400.00000
S1000.00000
M3
G04 P1
G0 Z5.0000
G0 X2.0000 Y2.0000
G1 Z-0.3000
G1 X12.0000 Y2.0000
G1 X12.0000 Y22.0000
G1 X2.0000 Y22.0000
G1 X2.0000 Y2.0000
G0 Z5.0000
M5
M2
"""

FUSION = """%
(1001)
(T1  D=3.175 CR=0. - ZMIN=-1. - FLAT END MILL)
G90 G94
G17
G21
G28 G91 Z0.
G90
(2D CONTOUR1)
T1 M6
S10000 M3
G54
G0 X30. Y-4.6
G0 Z15.
G0 Z5.
G1 Z0.6 F333.3
G1 Z-1. F333.3
G1 X30. Y0.
G2 X20. Y10. I-10. J0. F1000.
G1 X0. Y10.
G1 X0. Y0.
G1 X30. Y0.
G0 Z15.
G28 G91 Z0.
G90
G28 G91 X0. Y0.
G90
M5
M30
%
"""

PCB2GCODE = """( pcb2gcode 2.5.0 )
( This file uses 1 mill head. )
G94       ( Millimeters per minute feed rate. )
G21       ( Units == Millimeters. )
G90       ( Absolute coordinates. )
G64 P0.01000 ( set maximum deviation from commanded toolpath )
F600.00000
G00 Z2.00000 ( Retract to tool change height )
M3        ( Spindle on clockwise. )
G04 P1.00000 (Wait for spindle to get up to speed)
G04 P0 ( dwell for no time -- G64 should not smooth over this point )
G00 Z1.00000 ( retract )
G00 X3.81000 Y2.54000 ( rapid move to begin. )
F200.00000
G01 Z-0.05000
G04 P0 ( dwell for no time -- G64 should not smooth over this point )
F600.00000
G01 X3.81000 Y12.70000
G01 X17.78000 Y12.70000
G01 X17.78000 Y2.54000
G01 X3.81000 Y2.54000
G00 Z1.00000 ( retract )
M5        ( Spindle off. )
G04 P1.00000
M9        ( Coolant off. )
M2        ( Program end. )
"""

CENTRE = """; UGS habit: the work zero at the stock's centre
G21 G90 G17
G0 Z5
G0 X-20 Y0
G1 Z-0.5 F150
G2 X-20 Y0 I20 J0 F500
G1 X-20 Y-15
G1 X20 Y-15
G1 X20 Y15
G1 X-20 Y15
G1 X-20 Y0
G0 Z5
G0 X0 Y0
M2
"""

PROGRAMS = {"cambam": (CAMBAM, ZERO), "pycam": (PYCAM, ZERO), "fusion": (FUSION, ZERO),
            "pcb2gcode": (PCB2GCODE, ZERO), "centre": (CENTRE, CENTRE_ZERO)}


def _mm(steps) -> np.ndarray:
    """Machine steps as G-code mm (machine frame)."""
    return np.asarray(steps, np.float64) * STEP_MM * SIGN


def _state_at(zero, **offsets) -> MachineState:
    """The tool at ``zero`` (machine steps), G54's zero there (``cam zero XYZ``), other offsets as given."""
    state = MachineState().with_offset("G54", zero).moved_to(zero)
    for name, z in offsets.items():
        state = state.with_offset(name.replace("_", "."), z)
    return state


def _rs274(tmp_path, text: str, state: MachineState) -> list:
    """rs274's canonical moves of ``text`` in the state's work offsets (a var file, inches), from where the state
    says the tool stands (a G53 rapid there first, dropped), in machine mm."""
    names = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")
    lines = [f"5220 {names.index(state.active_offset) + 1}.0"]
    for k, name in enumerate(names):
        for i, v in enumerate(_mm(state.offsets_steps[name])):
            lines.append(f"{5221 + 20 * k + i} {float(v) / 25.4!r}")
    var = tmp_path / "rs274.var"
    var.write_text("\n".join(lines) + "\n")
    x, y, z = (float(v) for v in _mm(state.position_steps))
    src = tmp_path / "rs274.ngc"
    body = text.replace("%\n", "")  # rs274 reads the '%' lines as the program's ends: the start line goes first
    src.write_text(f"G21 G53 G0 X{x!r} Y{y!r} Z{z!r}\n" + body)
    moves = parse_canonical(run_rs274(str(src), var_file=str(var)))
    assert moves[0].kind == "traverse" and np.allclose(moves[0].end, (x, y, z), atol=1e-3)
    return moves


def _decoded(pin_log, start) -> np.ndarray:
    """The mock's pin log decoded, as machine G-code mm from ``start`` (machine steps)."""
    motion = cam.decode_pin_log(pin_log, S)
    return _mm(np.asarray(motion.position_steps) + np.asarray(start))


def _assert_follows(decoded_mm: np.ndarray, canon: list) -> None:
    """Every decoded position within half a step of rs274's path, and every rs274 end point reached (``canon``'s
    first move, the G53 rapid from rs274's machine zero to the start, is where the path starts)."""
    pts, _ = canonical_polyline_mm(canon, max_chord_mm=0.02)  # a chord's sagitta under 1e-5 mm (radius >= 5 mm)
    pts, canon = pts[1:], canon[1:]
    a, b = pts[:-1] / STEP_MM, pts[1:] / STEP_MM  # dense samples of the path, in steps, 0.05 step apart at most
    n = np.maximum(1, np.ceil(np.abs(b - a).max(axis=1) / 0.05)).astype(np.int64)
    seg = np.repeat(np.arange(len(n)), n)
    k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n) + 1
    dense = np.vstack([a[:1], a[seg] + (b - a)[seg] * (k / n[seg])[:, None]])
    dist, _ = cKDTree(dense).query(decoded_mm / STEP_MM, p=np.inf)
    assert dist.max() <= 0.5 + 0.05, f"decoded motion strays {dist.max():.3f} steps from rs274's path"
    ends = np.array([m.end for m in canon]) / STEP_MM
    d_end, _ = cKDTree(decoded_mm / STEP_MM).query(ends, p=np.inf)
    assert d_end.max() <= 0.5 + 1e-6, "a programmed end point is not reached"


def _drill(tmp_path, name: str, state_file, *flags):
    return cli("drill", tmp_path / name, "--state", state_file, "--pin-log", tmp_path / f"{name}.csv",
               "--no-progress", "--yes", *flags)


# -- real programs: refused from the home, run after cam zero, as rs274 runs them -----------------------------------

@needs_rs274
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in ("cambam", "fusion", "centre")
                                  else n for n in PROGRAMS])
def test_a_program_placed_at_the_work_zero_follows_rs274(tmp_path, name):
    text, zero = PROGRAMS[name]
    (tmp_path / f"{name}.ngc").write_text(text)
    state_file = tmp_path / "state.json"
    # a fresh machine: the tool at the home, every offset 0; the part's lower-left (or centre) there leaves the
    # travel, named in machine mm before anything moves
    proc = _drill(tmp_path, f"{name}.ngc", state_file)
    assert_one_line_error(proc, f"{name}.ngc:", "leaves the machine travel")
    assert not (tmp_path / f"{name}.ngc.csv").exists()
    # cam zero where the tool stands, at a point with room
    write_state(state_file, MachineState().moved_to(zero))
    z = cli("zero", "XYZ", "--state", state_file)
    assert z.returncode == 0, z.stderr
    state = read_state(state_file, S)
    assert state.work_zero_steps() == zero
    proc = _drill(tmp_path, f"{name}.ngc", state_file)
    assert proc.returncode == 0, proc.stderr
    decoded = _decoded(tmp_path / f"{name}.ngc.csv", zero)
    _assert_follows(decoded, _rs274(tmp_path, text, state))
    # the state records where the program left the tool (machine frame)
    end = read_state(state_file, S).position_steps
    assert np.allclose(_mm(end), decoded[-1])
    assert end != zero
    # run again from there: the cut is at the work zero again, not where the tool stood
    (tmp_path / f"{name}.ngc.csv").unlink()
    proc = _drill(tmp_path, f"{name}.ngc", state_file)
    assert proc.returncode == 0, proc.stderr
    again = _decoded(tmp_path / f"{name}.ngc.csv", end)
    _assert_follows(again, _rs274(tmp_path, text, read_state(state_file, S).moved_to(end)))
    below = lambda p: {tuple(np.round(q, 6)) for q in p[p[:, 2] < _mm(zero)[2] - 1e-9]}  # noqa: E731
    assert below(again) == below(decoded)  # what is cut below the work zero's surface: the same both times


def test_offsets_from_the_state_move_the_cut():
    """The same program in two work offsets: the cut moves by their difference, in G-code's axes."""
    text = "G21 G90\nG0 Z2\nG0 X5 Y5\nG1 Z-0.5 F200\nG1 X15 F400\nG1 Y12\nG0 Z2\nM2\n"
    a = parse_gcode(text, work_offsets_mm={"G54": (10.0, -100.0, -5.0)}, start_mm=(10.0, -100.0, -5.0))
    b = parse_gcode(text, work_offsets_mm={"G54": (10.0, -100.0, -5.0), "G55": (40.0, -60.0, -5.0)},
                    active_offset="G55", start_mm=(10.0, -100.0, -5.0))
    shift = np.array([m.end for m in b.moves[1:]]) - np.array([m.end for m in a.moves[1:]])  # after G0 Z2
    assert np.allclose(shift, (30.0, 40.0, 0.0))
    # the moves are given from where the tool stands (here G54's zero): G0 X5 Y5 at Z2 in G54
    assert np.allclose(a.moves[1].end, (5.0, 5.0, 2.0))


def test_a_job_planned_in_the_state_is_checked_in_the_machine_frame(tmp_path):
    """The travel check is in the machine frame, before anything moves: the same program fits from a work zero
    with room and is refused, naming its line and the move in machine mm, from one without."""
    path = tmp_path / "p.ngc"
    path.write_text("G21 G90\nG0 Z2\nG0 X0 Y0\nG1 Z-0.5 F200\nG1 X100 Y50 F400\nG0 Z2\nM2\n")
    job = prepare_job(path, settings=S, machine_state=_state_at(ZERO))
    assert job.report["start_steps"] == list(ZERO)
    with pytest.raises(cam.TravelError, match=r"p\.ngc:5: move to machine X149\.997 Y-35\.550 Z10\.548 mm leaves the "
                       r"machine travel \(machine X 0\.\.289, Y 0\.\.289, Z -10\.048\.\.31\.4 mm; the machine frame"):
        prepare_job(path, settings=S, machine_state=_state_at((1730, 500, 640)))


# -- G10 L2 / L20 in a program, --keep-offsets ---------------------------------------------------------------------

G10_PROGRAM = """G21 G90 G17
G10 L2 P2 X20 Y-30 Z0 (G55 from the machine's home, machine mm)
G10 L20 P1 X-10 Y-10 (G54: the tool is at X-10 Y-10 now)
G0 Z3
G0 X0 Y0
G1 Z-0.4 F200
G1 X8 F400
G55
G0 Z3
G0 X10 Y-10
G1 Z-0.4 F200
G1 Y-20 F400
G0 Z3
M2
"""


@needs_rs274
def test_g10_changes_offsets_for_the_program_only(tmp_path):
    (tmp_path / "g10.ngc").write_text(G10_PROGRAM)
    state_file = tmp_path / "state.json"
    state = _state_at(ZERO)
    write_state(state_file, state)
    proc = _drill(tmp_path, "g10.ngc", state_file)
    assert proc.returncode == 0, proc.stderr
    _assert_follows(_decoded(tmp_path / "g10.ngc.csv", ZERO), _rs274(tmp_path, G10_PROGRAM, state))
    assert "note: the program sets work offset G54, G55 (G10) for itself only; --keep-offsets keeps it" \
        in proc.stderr
    after = read_state(state_file, S)
    assert after.offsets_steps == state.offsets_steps and after.active_offset == "G54"


def test_keep_offsets_keeps_what_the_program_set(tmp_path):
    (tmp_path / "g10.ngc").write_text(G10_PROGRAM)
    state_file = tmp_path / "state.json"
    write_state(state_file, _state_at(ZERO))
    proc = _drill(tmp_path, "g10.ngc", state_file, "--keep-offsets")
    assert proc.returncode == 0, proc.stderr
    assert "work offset G54, G55 kept as the program set it (--keep-offsets)" in proc.stderr
    after = read_state(state_file, S)
    g55 = np.round(np.array([20.0, -30.0, 0.0]) / STEP_MM * SIGN).astype(int)
    assert after.offsets_steps["G55"] == tuple(g55)
    # G54: its X Y where the tool was at line 3 (the work zero) minus (-10, -10) mm; its Z unchanged
    g54 = np.array(ZERO) + np.round(np.array([10.0, 10.0, 0.0]) / STEP_MM * SIGN).astype(int)
    assert after.offsets_steps["G54"] == tuple(int(v) for v in g54)
    assert after.active_offset == "G54"  # M2 ends in G54, as LinuxCNC's M2 does


def test_keep_offsets_refuses_an_offset_outside_the_travel_before_anything_moves(tmp_path):
    (tmp_path / "far.ngc").write_text("G21\nG10 L2 P3 X-50\nG0 Z1\nM2\n")
    state_file = tmp_path / "state.json"
    write_state(state_file, _state_at(ZERO))
    before = state_file.read_text()
    proc = _drill(tmp_path, "far.ngc", state_file, "--keep-offsets")
    assert_one_line_error(proc, "work offset G56 as the program sets it (--keep-offsets)", "X travel")
    assert not (tmp_path / "far.ngc.csv").exists()
    assert json.loads(state_file.read_text())["position_steps"] == json.loads(before)["position_steps"]
    # without --keep-offsets the program runs (the offset holds for it only)
    assert _drill(tmp_path, "far.ngc", state_file).returncode == 0


def test_keep_offsets_is_for_gcode_programs(tmp_path):
    drill = tmp_path / "b.drl"
    drill.write_text("M48\nMETRIC\nT1C0.8\n%\nT1\nX1.0Y1.0\nM30\n")
    assert_one_line_error(cli("drill", drill, "--keep-offsets", "--state", tmp_path / "s.json"),
                          "--keep-offsets", "not a G-code program")


# -- G53 and G28/G30: machine positions ------------------------------------------------------------------------------

MACHINE_MOVES = """G21 G90
G0 Z2
G0 X4 Y4
G53 G0 X100 Y-150 (machine frame, whatever the offset)
G1 Z-0.3 F200
G1 X10 Y4 F400
G0 Z2
G30 (to G30's machine position, the home by default)
M2
"""


@needs_rs274
def test_g53_and_g30_are_machine_positions(tmp_path):
    (tmp_path / "m.ngc").write_text(MACHINE_MOVES)
    state_file = tmp_path / "state.json"
    state = _state_at(ZERO)
    write_state(state_file, state)
    proc = _drill(tmp_path, "m.ngc", state_file)
    assert proc.returncode == 0, proc.stderr
    decoded = _decoded(tmp_path / "m.ngc.csv", ZERO)
    _assert_follows(decoded, _rs274(tmp_path, MACHINE_MOVES, state))
    g53 = np.round(np.array([100.0, -150.0]) / STEP_MM[:2] * SIGN[:2]).astype(int)
    motion = cam.decode_pin_log(tmp_path / "m.ngc.csv", S)
    reached = np.asarray(motion.position_steps)[:, :2] + np.array(ZERO[:2])
    assert (reached == g53).all(axis=1).any()  # G53 X100 Y-150 reached in the machine frame
    assert read_state(state_file, S).position_steps == (0, 0, 0)  # G30: the machine's home


def test_g28_goes_to_the_machine_files_position(tmp_path):
    """G28's position is a machine position (the machine file's g28_*_mm), wherever the work zero is."""
    settings = cam.MachineSettings(g28_x_mm=10.0, g28_y_mm=-20.0, g28_z_mm=0.0)
    path = tmp_path / "h.ngc"
    path.write_text("G21 G90\nG0 Z2\nG0 X5 Y5\nG28 G91 Z0\nG90\nG28\nM2\n")
    for zero in (ZERO, CENTRE_ZERO):
        job = prepare_job(path, settings=settings, machine_state=_state_at(zero))
        end = np.asarray(job.toolpath.points_steps)[-1] + np.asarray(zero)
        assert tuple(int(v) for v in end) == (round(10.0 / S.mm_per_step_xy), round(20.0 / S.mm_per_step_xy), 0)


def test_where_the_tool_stands_is_where_the_program_starts():
    """An incremental program runs from where the tool stands (as a sender runs it), not from the work zero."""
    text = "G21 G91\nG1 X1 Y2 Z-1 F100\nM2\n"
    prog = parse_gcode(text, start_mm=(30.0, -40.0, 5.0), work_offsets_mm={"G54": (10.0, -10.0, 0.0)})
    assert np.allclose(prog.moves[0].end, (1.0, 2.0, -1.0))
    # #5420.. read the program position: machine minus the work offset
    prog = parse_gcode("G21\n#1=#5420\n#2=#5421\nG0 X#1 Y#2\nM2\n", start_mm=(30.0, -40.0, 5.0),
                       work_offsets_mm={"G54": (10.0, -10.0, 0.0)})
    assert np.allclose(prog.moves[0].end, (0.0, 0.0, 0.0))


def test_pieces_of_a_program_in_the_state_join_to_the_whole(tmp_path):
    """The one-path rule with a start and work offsets: any piece size, a file streamed or a program held, the
    same job; the G10 offsets the program leaves are those of its last pass."""
    from cam.formats.gcode import load_gcode, open_gcode
    from cam.job.gcode import steps_to_gcode_mm, stream_gcode

    path = tmp_path / "g10.ngc"
    path.write_text(G10_PROGRAM.replace("M2\n", "") + PYCAM)
    state = _state_at(ZERO).moved_to((2000, 7000, 600))
    frame = dict(start_mm=steps_to_gcode_mm(state.position_steps, S),
                 work_offsets_mm={k: steps_to_gcode_mm(v, S) for k, v in state.offsets_steps.items()})
    whole = stream_gcode(load_gcode(path, **frame), S, home_steps=state.position_steps).joined()
    for k in (1, 3, 1000):
        f = open_gcode(path, **frame)
        job = stream_gcode(f, S, piece_moves=k, home_steps=state.position_steps).joined()
        assert np.array_equal(job.points_steps, whole.points_steps)
        assert np.array_equal(job.period_ns, whole.period_ns)
        assert f.end_offsets_mm == load_gcode(path, **frame).work_offsets_mm
        assert f.end_offsets_mm["G55"] == pytest.approx((20.0, -30.0, 0.0))
