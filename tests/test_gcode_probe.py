"""A G-code program's own probes, ``G38.2``/``G38.3`` (issue #46 point 2), with LinuxCNC's semantics.

The interpreter (:mod:`cam.formats._gcode_probe`): a straight feed move toward the target that stops where the probe
trips; #5061..#5063 the trip point in the coordinate system of the probe, #5070 whether it tripped; refused as rs274
refuses it (no feed, inverse time, cutter compensation on, a target too close) and along X/Y or upward (cam probes
down Z); nothing after a probe is read before the probe has run.  On a machine (:mod:`cam.drive.program_probe`) the
moves after a probe are planned from where it touched: on the mock with a tilted surface the cut after
``G38.2 / G92 Z0 / G1 Z-0.2`` is 0.2 mm below the surface formula at the probe point, decoded from the pin log; a
``G38.2`` that never trips is one line and the position stays known; a ``G38.3`` that never trips goes on from its
target; grbl probes with its own ``G38.2``; the MAXIMUS board and ``cmd:`` refuse in one line before anything
moves; ``cam info``/``cam preview`` say the probes, ``cam export`` refuses."""
from __future__ import annotations

import math
import shutil

import numpy as np
import pytest

import cam
from cam.drive.grbl_machine import close_grbl_machines
from cam.drive.ports import MockPort, surface_height_mm
from cam.drive.session import MachineSession
from cam.drive.state import read_state
from cam.errors import CapabilityError, ParseError
from cam.formats.gcode import open_gcode, parse_gcode
from cam.sim.grbl import start_emulator
from cam.verify.pinlog import decode_pin_log, read_pin_log
from conftest import one_line_error, ok, run_cli
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)
from support.lcnc import parse_canonical, run_rs274

TILT = (-0.6, 0.004, -0.003, 0.0, 0.0, 0.0)
"""A tilted surface: 0.4 mm up over 100 mm of X, 0.3 mm down over 100 mm of Y (machine frame, +Y toward the
operator), 0.55 mm below the home at the probe point (20, 10) mm."""

PROGRAM = """G21 G90 G17
G0 X20 Y-10
G38.2 Z-10 F60
G92 Z0
G1 Z-0.2 F100
G1 X30 F200
G1 Y-20
G0 Z2
M2
"""
"""The issue's program: probe down at the probe point, its contact the program's Z zero, cut 0.2 mm below it."""


def machine_file(tmp_path, surface=TILT):
    path = tmp_path / "probe-machine.toml"
    path.write_text('start_speed_z_mm_s = 1.2\n[inputs]\nprobe = "!13"\nestop = "!15"\n[travel]\nz_min_steps = -2000\n'
                    f'z_max_steps = 2000\n[mock]\nprobe_surface = "{",".join(str(v) for v in surface)}"\n')
    return path


def contact_step(settings, x_steps: int, y_steps: int, surface=TILT) -> int:
    """The first Z step (+Z deeper) at or below the surface at machine (x, y) steps: where the mock's probe closes."""
    h = float(surface_height_mm(surface, x_steps * settings.mm_per_step_xy, y_steps * settings.mm_per_step_xy))
    return math.ceil(-h / settings.mm_per_step_z - 1e-9)


# -- the interpreter -----------------------------------------------------------------------------------------

def test_a_probe_is_a_feed_move_to_its_target_and_its_trip_point_the_parameters():
    """Without a machine a probe trips at its target: #5061..#5063 hold it in the coordinate system it was made in
    (G92 changed after it does not change them), in the program's units; G38.2 stays the motion mode."""
    p = parse_gcode("G21 G90\nG0 X5 Y3 Z2\nG38.2 Z-10 F50\nG92 Z0\nG1 Z-0.2 F100\nG0 Z[#5063 + 2]\n"
                    "G20 G38.2 Z-0.5 F2\nZ-0.7\nG0 X[#5061] Y[#5062 * #5070]\n")
    kinds = [(m.kind, m.line, m.end, m.feed_mm_min, m.note) for m in p.moves]
    assert kinds[1] == ("probe", 3, (5.0, 3.0, -10.0), 50.0, "G38.2")
    assert kinds[2][:3] == ("feed", 5, (5.0, 3.0, -10.2))
    assert kinds[3][:3] == ("rapid", 6, (5.0, 3.0, -18.0))  # #5063 = -10 before the G92: machine -10 - 8
    assert kinds[4][0] == "probe" and kinds[4][2][2] == pytest.approx(-10 - 12.7) and kinds[4][3] == pytest.approx(50.8)
    assert kinds[5][0] == "probe" and kinds[5][1] == 8  # modal: a line of axis words probes again
    assert p.moves[-1].end[:2] == pytest.approx((5.0, 3.0))  # #5061, #5062 in inches, back in mm; #5070 = 1


RS274_PROBES = """G21 G90
G10 L2 P1 X1 Y2 Z3
G54 G0 X5 Y3 Z2
G38.2 Z-10 F50
G10 L2 P1 Z0
G0 Z[#5063 + 2]
G38.3 Z-15
G0 X[#5061 + 1] Y[#5062] Z[#5063 + 1]
G20 G38.2 Z-1 F2
G21 G0 Z[#5063 * 25.4 + 3]
M2
"""
"""Each probe's result read back, the frame changed between a probe and its use (#5061..#5063 stay in the frame
of the probe), in inches too."""


@pytest.mark.skipif(shutil.which("rs274") is None, reason="rs274 (linuxcnc-uspace) not installed")
def test_without_a_machine_a_probe_trips_at_its_target_as_rs274_alone_runs_it(tmp_path):
    """LinuxCNC's interpreter alone (``rs274``, which has no probe) runs a probe to its target and gives that to
    #5061..#5063: cam's moves without a machine end where rs274's do (its STRAIGHT_PROBE, STRAIGHT_TRAVERSE, in
    machine mm), each parameter in the coordinate system of its probe and the program's units."""
    path = tmp_path / "probes.ngc"
    path.write_text(RS274_PROBES)
    canon = parse_canonical(run_rs274(str(path)))
    moves = [m for m in parse_gcode(RS274_PROBES).moves if m.kind in ("rapid", "feed", "probe")]
    assert [m.kind for m in moves] == ["rapid", "probe", "rapid", "probe", "rapid", "probe", "rapid"]
    assert len(canon) == len(moves)
    for want, got in zip(canon, moves):
        assert got.end == pytest.approx(want.end, abs=1e-3), (got, want)


@pytest.mark.parametrize("text, fragment", [
    ("G21\nG38.2 Z-5\n", "G38.2 without a feed rate 'F'"),
    ("G21\nG93 G38.2 Z-5 F2\n", "inverse time feed mode (G93)"),
    ("G21\nG41.1 D2 G1 X5 F10\nG38.2 Z-5\n", "G38.2 while cutter radius compensation is on"),
    ("G21\nG38.3 X5 Z-5 F20\n", "a probe along X is not supported"),
    ("G21\nG38.2 Y-1 Z-5 F20\n", "a probe along Y is not supported"),
    ("G21\nG38.2 Z5 F20\n", "G38.2 upward is not supported"),
    ("G21\nG38.2 Z-0.2 F20\n", "less than 0.254 mm"),
    ("G21\nG38.4 Z-5 F20\n", "'G38.4': probing away from the work"),
    ("G21\nG38.5 Z-5 F20\n", "'G38.5': probing away from the work"),
    ("G21\nG53 G38.2 Z-5 F20\n", "G53 works with G0 or G1 only"),
    ("G21\nG38.2 Z-5 R1 F20\n", "I, J, K or R given without G2/G3"),
])
def test_a_probe_is_refused_before_it_moves_as_rs274_refuses_it(text, fragment):
    with pytest.raises(ParseError) as err:
        parse_gcode(text)
    assert fragment in str(err.value) and "\n" not in str(err.value) and "<gcode>:" in str(err.value)


def test_the_interpreter_reads_nothing_after_a_probe_before_it_has_run(tmp_path):
    """The batch ends with the probe; the line after it (here an error) is read only once the next batch is asked
    for, and then the interpreter asks where the probe tripped: the program goes on from there."""
    path = tmp_path / "p.ngc"
    path.write_text("G21\nG38.3 Z-10 F60\nG0 Z[#5063 + 1]\nG1 X[1 + #5070] F100\nG38.2 Z-20\nG0 Z0\nQ1\n")
    asked = []

    def probed(move):
        asked.append(move.line)
        return None if move.line == 2 else (1.0, 0.0, -12.5)

    batches = open_gcode(path).move_batches(1000, probed=probed)
    first = next(batches)
    assert [m.kind for m in first.moves] == ["probe"] and asked == []
    second = next(batches)
    assert asked == [2]  # G38.3 did not trip: its target, #5070 = 0
    assert [(m.kind, m.end) for m in second.moves] == [("rapid", (0.0, 0.0, -9.0)), ("feed", (1.0, 0.0, -9.0)),
                                                        ("probe", (1.0, 0.0, -20.0))]
    with pytest.raises(ParseError, match=r"p.ngc:7: unsupported word 'Q1'"):
        next(batches)
    assert asked == [2, 5]


# -- the mock ------------------------------------------------------------------------------------------------

def _decoded(tmp_path, pins, settings):
    home = np.array(read_pin_log(pins).parts[-1].start_steps, np.int64)
    pos = decode_pin_log(read_pin_log(pins), settings, part="job").position_steps + home
    return pos[np.r_[True, np.any(pos[1:] != pos[:-1], axis=1)]]  # each position once


def test_gcode_program_probes_and_cuts_from_the_contact(tmp_path):
    """``G38.2 Z-10 F60 / G92 Z0 / G1 Z-0.2 F100 / G1 X30 ...`` on the mock with a tilted surface: decoded from the
    pin log, the probe went straight down at the probe point and stopped on the first step at or below the
    surface formula (never toward the target beyond it), and every cut move after it is at that contact plus
    0.2 mm: 0.2 mm below the surface at the probe point, within a step."""
    machine, state, pins = machine_file(tmp_path), tmp_path / "state.json", tmp_path / "pins.csv"
    program = tmp_path / "probe.ngc"
    program.write_text(PROGRAM)
    proc = ok(run_cli("drill", program, "--machine", machine, "--state", state, "--pin-log", pins, "--yes"))
    assert "1 probe(s)" in proc.stdout and "probe.ngc:3: G38.2 touched at height" in proc.stderr
    s = cam.load_settings(machine)
    mx, mz = s.mm_per_step_xy, s.mm_per_step_z
    px, py = round(20 / mx), round(10 / mx)  # the probe point, machine steps (+Y toward the operator)
    c = contact_step(s, px, py)
    depth = round(0.2 / mz)
    pos = _decoded(tmp_path, pins, s)
    at_probe = np.flatnonzero(np.all(pos[:, :2] == (px, py), axis=1))
    down = pos[at_probe[0]:at_probe[-1] + 1]
    assert np.all(down[:, :2] == (px, py)) and np.all(np.diff(down[:, 2]) == 1)  # straight down, step by step
    assert down[0, 2] == 0 and down[-1, 2] == c + depth  # the contact, then the cut 0.2 mm below it
    cut = pos[at_probe[-1] + 1:]
    cut = cut[:int(np.argmax(cut[:, 2] < c + depth))]  # until the lift
    assert len(cut) > 100 and np.all(cut[:, 2] == c + depth)
    assert cut[-1, 0] == round(30 / mx) and cut[-1, 1] == round(20 / mx)
    surface_mm = float(surface_height_mm(TILT, px * mx, py * mx))
    below_mm = (c + depth) * mz + surface_mm  # how far below the surface the cut is at the probe point
    # within the contact's step (the first at or below the surface) and half a step (0.2 mm in whole steps)
    assert 0 <= c * mz + surface_mm < mz and abs(below_mm - 0.2) <= 1.5 * mz, below_mm
    st = read_state(state, s)
    assert st.position_known and st.position_steps == tuple(int(v) for v in pos[-1])
    assert st.position_steps[2] == c - round(2 / mz)  # G0 Z2 from the contact: the program's Z zero was there


def test_a_g38_2_that_never_touches_is_one_line_and_the_position_stays_known(tmp_path):
    machine, state = machine_file(tmp_path), tmp_path / "state.json"
    program = tmp_path / "short.ngc"
    program.write_text("G21 G90\nG0 X20 Y-10\nG38.2 Z-0.3 F60\nG1 X30 F200\nM2\n")  # the surface is 0.55 mm down
    line = one_line_error(run_cli("drill", program, "--machine", machine, "--state", state, "--yes"),
                          "short.ngc:3: G38.2 found no contact down to its target", "position known")
    s = cam.load_settings(machine)
    st = read_state(state, s)
    assert st.position_known and st.position_steps == (round(20 / s.mm_per_step_xy), round(10 / s.mm_per_step_xy), 0)
    assert "machine Z 19 steps" in line  # 0.3 mm is 19.1 steps: the probe stops short of the target, never past it


def test_a_g38_3_that_never_touches_goes_on_from_its_target(tmp_path):
    """#5070 is 0 and #5063 the target: ``G1 X[5 + #5070]`` cuts to X5 at the target's depth, ``G0 Z[#5063 + 1]``
    lifts to 0.7 mm above the start."""
    machine, pins = machine_file(tmp_path), tmp_path / "pins.csv"
    program = tmp_path / "maybe.ngc"
    program.write_text("G21 G90\nG38.3 Z-0.3 F60\nG1 X[5 + #5070] F200\nG0 Z[#5063 + 1]\nM2\n")
    proc = ok(run_cli("drill", program, "--machine", machine, "--state", tmp_path / "state.json", "--pin-log", pins,
                      "--yes"))
    assert "G38.3 touched nothing down to its target" in proc.stderr
    s = cam.load_settings(machine)
    pos = _decoded(tmp_path, pins, s)
    moving_x = np.flatnonzero(np.diff(pos[:, 0]) != 0) + 1
    assert pos[:, 2].max() == 19 and np.all(pos[moving_x, 2] == 19)  # the X move at the target's depth
    assert tuple(pos[-1]) == (round(5 / s.mm_per_step_xy), 0, round(-0.7 / s.mm_per_step_z))


def test_the_nominal_moves_of_a_program_that_probes_are_never_run_or_written(tmp_path):
    """The prepared job's toolpath and plan are the program as if each probe touched at its target: a session
    refuses them alone, and G-code out refuses them; the prepared job itself runs."""
    program = tmp_path / "probe.ngc"
    program.write_text(PROGRAM)
    s = cam.load_settings(machine_file(tmp_path))
    job = cam.prepare_job(program, settings=s)
    assert job.report["probes"] == [f"{program}:3: G38.2 down at most 10 mm at F60 mm/min"]
    for given in (job.toolpath, job.plan):
        with pytest.raises(CapabilityError, match="planned as if each probe touched at its target"):
            MachineSession(MockPort(), s).start(given)
    with pytest.raises(cam.CamError, match="not written as G-code"):
        cam.to_gcode(job.toolpath)
    with pytest.raises(cam.CamError, match="cannot be resumed"):
        cam.resume_job(job, None)  # refused before the journal is read
    session = MachineSession(MockPort(), s)
    session.start(job)
    session.wait_idle(60)
    assert session.last_run["status"] == "finished" and session.last_run["probes"] == 1


def test_info_and_preview_say_the_probes_and_export_refuses(tmp_path):
    machine, program = machine_file(tmp_path), tmp_path / "probe.ngc"
    program.write_text(PROGRAM)
    info = ok(run_cli("info", program, "--machine", machine)).stdout
    assert "probe.ngc:3: G38.2 down at most 10 mm at F60 mm/min" in info
    assert "the moves after a probe depend on where it touches" in info and "as if each touched at its target" in info
    preview = ok(run_cli("preview", program, "--machine", machine, "-o", tmp_path / "p.png")).stdout
    assert (tmp_path / "p.png").stat().st_size > 0 and "depend on where it touches" in preview
    one_line_error(run_cli("export", program, "-o", tmp_path / "out.nc", "--machine", machine), "G-code already")
    assert not (tmp_path / "out.nc").exists()


@pytest.mark.parametrize("port", ["cmd:mock", "maximus:/dev/ttyUSB9"])
def test_machines_without_a_probe_refuse_a_program_that_probes_before_anything_moves(port, tmp_path):
    program, state = tmp_path / "probe.ngc", tmp_path / "state.json"
    program.write_text(PROGRAM)
    machine = machine_file(tmp_path)
    s = cam.load_settings(machine)
    job = cam.prepare_job(program, settings=s)
    with pytest.raises(CapabilityError, match=r"has no probe input.*a G-code program that probes \(.*probe.ngc:3: G38.2"):
        MachineSession(port, s).start(job)
    if port == "cmd:mock":
        one_line_error(run_cli("drill", program, "--port", port, "--machine", machine, "--state", state, "--yes"),
                       "cmd:mock", "no probe input", "probe.ngc:3: G38.2")
    else:  # the board refuses G-code programs before they are planned
        one_line_error(run_cli("drill", program, "--port", port, "--state", state, "--yes"), port, "gcode job")
    assert not state.exists() or read_state(state, s).position_steps == (0, 0, 0)


def test_a_step_dir_probe_feed_over_zs_start_speed_is_refused_naming_the_line(tmp_path):
    program = tmp_path / "fast.ngc"
    program.write_text("G21\nG38.2 Z-5 F100\nM2\n")  # Z starts at 1.2 mm/s = 72 mm/min in this machine file
    one_line_error(run_cli("drill", program, "--machine", machine_file(tmp_path), "--state", tmp_path / "s.json",
                           "--yes"), "fast.ngc:2:", "faster than Z's start speed")


# -- grbl ----------------------------------------------------------------------------------------------------

GRBL = cam.MachineSettings()
FAST = {110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0, 122: 500.0,
        100: 1 / GRBL.mm_per_step_xy, 101: 1 / GRBL.mm_per_step_xy, 102: 1 / GRBL.mm_per_step_z}
GRBL_TILT = (-0.6, 0.004, 0.003, 0.0, 0.0, 0.0)
"""The tilted surface in grbl's frame (its Y is cam's -Y): the same surface as :data:`TILT`."""


def test_grbl_probes_with_its_own_g38_2_and_cuts_from_the_contact(tmp_path):
    emu = start_emulator(speed=20.0, settings=FAST, probe_surface=GRBL_TILT)
    try:
        program = tmp_path / "probe.ngc"
        program.write_text(PROGRAM)
        job = cam.prepare_job(program, settings=GRBL)
        session = MachineSession(f"grbl:{emu.device_path}", GRBL)
        session.start(job)
        assert session.wait_idle(120)
        assert session.last_run["status"] == "finished", session.last_run
        probes = [text for _, text, _ in emu.lines() if "G38" in text]
        assert len(probes) == 1 and probes[0].startswith("G91G38.2Z-") and probes[0].endswith("F60")
        assert float(probes[0][len("G91G38.2Z-"):-len("F60")]) <= 10.0  # never below the program's target
        mx, mz = GRBL.mm_per_step_xy, GRBL.mm_per_step_z
        px, py = round(20 / mx), round(10 / mx)
        c = contact_step(GRBL, px, py)
        cut_mm = -(c + round(0.2 / mz)) * mz  # grbl's Z: up positive
        cuts = [b for b in emu.executed() if b.kind == "G1" and b.start_mm[:2] != b.end_mm[:2]]
        assert len(cuts) >= 2 and all(abs(b.end_mm[2] - cut_mm) < 1e-3 for b in cuts), (cut_mm, cuts)
        assert abs(-cut_mm - 0.2 + float(surface_height_mm(GRBL_TILT, px * mx, -py * mx))) <= 1.5 * mz
    finally:
        close_grbl_machines()
        emu.stop()
    assert emu.error is None
