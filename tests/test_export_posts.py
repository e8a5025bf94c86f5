"""G-code for a target (issue #30 point 4): `cam export --post grbl|linuxcnc|generic`, feeds, spindle, tool
changes, exact geometry (no snapping unless --snap) and lines and arcs fitted within --arc-tolerance.

Checked by LinuxCNC's interpreter (rs274) for ``linuxcnc``, by the grbl emulator (cam.sim.grbl, driven by the
host link) for ``grbl``, and the fitted path against the job's own: the same job written one G1 a point (through
rs274) and the mock's decoded pin log."""
from __future__ import annotations

import math
import re
import shutil
import sys
from typing import Any, Callable

import numpy as np
import pytest
from scipy.spatial import cKDTree

import cam
from cam.cli import main
from cam.kinds.gcode_export import to_gcode
from cam.job.arcs import fit_path
from conftest import SAMPLES
from support.lcnc import canonical_polyline_mm, parse_canonical, run_rs274

needs_rs274 = pytest.mark.skipif(shutil.which("rs274") is None, reason="rs274 (linuxcnc-uspace) not installed")

GRBL_WORDS = re.compile(r"^(G0|G1|G2|G3|G17|G21|G90|G94|M0|M2|M3|M5|[XYZIJFS]-?\d+(\.\d+)?)$")
"""The words the grbl post may write: all grbl 1.1 takes (no M6, no G64, no T)."""


def _drill_file(tmp_path, tools=((1, 0.8, [(7.62, 2.54), (10.16, 5.08)]),)):
    body = ["M48", "METRIC"] + [f"T{t}C{d:.3f}" for t, d, _ in tools] + ["%"]
    for t, _, holes in tools:
        body.append(f"T{t}")
        body += [f"X{x:.3f}Y{y:.3f}" for x, y in holes]
    body.append("M30")
    path = tmp_path / "board.drl"
    path.write_text("\n".join(body) + "\n")
    return path


def _code_lines(text: str) -> list[str]:
    return [ln for ln in (re.sub(r"\(.*?\)", "", ln).strip() for ln in text.splitlines()) if ln]


def _canon_path(text: str, tmp_path, name: str) -> tuple[np.ndarray, list]:
    path = tmp_path / name
    path.write_text(text)
    moves = parse_canonical(run_rs274(str(path)))
    pts, _ = canonical_polyline_mm(moves, max_chord_mm=0.004)
    return _dense(pts, 0.004), moves


def _dense(points: np.ndarray, chord_mm: float = 0.002) -> np.ndarray:
    """A polyline split into chords of at most ``chord_mm``."""
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / chord_mm)))
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.concatenate(out)


def _below(points: np.ndarray) -> np.ndarray:
    return points[points[:, 2] < -1e-6]


def _hausdorff(a: np.ndarray, b: np.ndarray) -> float:
    """The larger of the two one-way distances between two point sets (dense polylines)."""
    return float(max(cKDTree(b).query(a)[0].max(), cKDTree(a).query(b)[0].max()))


# ---------------------------------------------------------------------------------------------- fitting


def _segment_points(points: np.ndarray, segments) -> np.ndarray:
    """The fitted path sampled every ~1 micrometre (arcs by their centre and direction, as G2/G3 run)."""
    out = [points[:1]]
    start = points[0]
    for seg in segments:
        end = points[seg.end]
        if seg.kind == "line":
            out.append(_dense(np.array([start, end]), 0.001)[1:])
        else:
            cx, cy = seg.centre_mm
            a0 = math.atan2(start[1] - cy, start[0] - cx)
            a1 = math.atan2(end[1] - cy, end[0] - cx)
            sweep = (a1 - a0) % (2 * math.pi) if seg.kind == "ccw" else -((a0 - a1) % (2 * math.pi))
            r = math.hypot(start[0] - cx, start[1] - cy)
            n = max(2, int(abs(sweep) * r / 0.001))
            a = a0 + sweep * np.arange(1, n + 1) / n
            out.append(np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a), np.full(n, start[2])]))
        start = end
    return np.concatenate(out)


def test_a_circle_is_one_arc_and_a_line_one_line():
    a = np.linspace(0, 1.9 * math.pi, 500)
    circle = np.column_stack([5 * np.cos(a), 5 * np.sin(a), np.zeros_like(a)])
    segs = fit_path(circle, 0.01)
    assert [s.kind for s in segs] == ["ccw"] and segs[0].end == 499
    assert segs[0].centre_mm == pytest.approx((0.0, 0.0), abs=1e-9)
    assert [s.kind for s in fit_path(circle[::-1], 0.01)] == ["cw"]
    line = np.column_stack([np.linspace(0, 10, 50), np.linspace(0, 3, 50), np.linspace(0, -1, 50)])
    assert [(s.kind, s.end) for s in fit_path(line, 0.01)] == [("line", 49)]


@pytest.mark.parametrize("tol", [0.01, 0.05])
def test_fitted_path_stays_within_the_tolerance_of_a_noisy_curve(tol):
    rng = np.random.default_rng(7)
    t = np.linspace(0, 3 * math.pi, 1500)
    r = 4 + 0.5 * np.sin(t / 3)
    pts = np.column_stack([r * np.cos(t), r * np.sin(t), np.zeros_like(t)])
    pts[:, :2] += rng.uniform(-0.004, 0.004, (len(t), 2))
    pts[700:, 2] = -0.5  # a change of depth: an arc never spans it
    segs = fit_path(pts, tol)
    assert len(segs) < len(pts) / 10 and segs[-1].end == len(pts) - 1
    assert any(s.kind != "line" for s in segs)
    assert _hausdorff(_segment_points(pts, segs), _dense(pts, 0.001)) <= tol + 0.001


# ---------------------------------------------------------------------------------------------- exact geometry


def test_holes_are_written_where_the_file_puts_them_unless_snap(tmp_path):
    src = _drill_file(tmp_path)
    out = tmp_path / "exact.ngc"
    assert main(["export", str(src), "-o", str(out), "--offset", "0,10", "--cut-depth", "1.5"]) == 0
    text = out.read_text()
    assert "G0 X7.62 Y-7.46" in text and "G0 X10.16 Y-4.92" in text and "G1 Z-1.5 " in text
    assert "7.6296" not in text
    assert main(["export", str(src), "-o", str(out), "--offset", "0,10", "--cut-depth", "1.5", "--snap"]) == 0
    snapped = out.read_text()
    assert "G0 X7.6296 Y-7.4562" in snapped and "G1 Z-1.5072 " in snapped  # 264 x 0.0289 mm, 96 x 0.0157 mm


@needs_rs274
def test_linuxcnc_drills_the_exact_holes_with_tool_changes_and_spindle(tmp_path):
    src = _drill_file(tmp_path, ((1, 0.8, [(7.62, 2.54), (10.16, 5.08)]), (2, 1.0, [(3.3, 4.4)])))
    out = tmp_path / "lc.ngc"
    assert main(["export", str(src), "-o", str(out), "--post", "linuxcnc", "--offset", "0,10", "--cut-depth",
                 "1.5", "--spindle-rpm", "12000", "--feed", "800", "--plunge-feed", "200"]) == 0
    text = out.read_text()
    code = _code_lines(text)
    assert [ln for ln in code if "M6" in ln] == ["T1 M6", "T2 M6"]
    # the spindle stops before each tool change and starts again before the next cut
    assert [ln for ln in code if ln.startswith(("M3", "M5", "T"))] == \
        ["T1 M6", "M3 S12000", "M5", "T2 M6", "M3 S12000", "M5"]
    canon = run_rs274(str(out))
    assert canon.count("CHANGE_TOOL(") == 2 and canon.count("START_SPINDLE_CLOCKWISE") == 2
    assert "SET_SPINDLE_SPEED(0, 12000.0000)" in canon or "SET_SPINDLE_SPEED(12000.0000)" in canon
    assert "SET_FEED_RATE(200.0000)" in canon
    bottoms = np.array([m.end for m in parse_canonical(canon) if m.kind == "feed" and m.end[2] < 0])
    holes = {(7.62, -7.46), (10.16, -4.92), (3.3, -5.6)}
    assert {(round(x, 6), round(y, 6)) for x, y, _ in bottoms} == holes
    assert np.allclose(bottoms[:, 2], -1.5, atol=1e-6)


def test_grbl_tool_changes_are_a_comment_and_a_pause_in_grbl_words(tmp_path):
    src = _drill_file(tmp_path, ((1, 0.8, [(7.62, 2.54)]), (2, 1.0, [(3.3, 4.4)])))
    out = tmp_path / "g.ngc"
    assert main(["export", str(src), "-o", str(out), "--post", "grbl", "--offset", "0,10",
                 "--spindle-rpm", "9000"]) == 0
    lines = out.read_text().splitlines()
    pauses = [i for i, ln in enumerate(lines) if ln == "M0"]
    assert len(pauses) == 2
    assert all(lines[i - 1].startswith("(load tool ") for i in pauses)
    assert "(load tool 2: T2 1.000 mm" in lines[pauses[1] - 1]
    for ln in _code_lines("\n".join(lines)):
        assert all(GRBL_WORDS.match(w) for w in ln.split()), ln
        assert len(ln) <= 80


def test_feeds_are_the_settings_or_the_options_and_only_written_when_they_change():
    job = cam.plan(cam.digitize(cam.load_image(SAMPLES / "ellipse.png")), depth=3)
    text = to_gcode(job, post="grbl", feed_mm_min=900, plunge_feed_mm_min=120, spindle_rpm=10000)
    code = _code_lines(text)
    feeds = [w for ln in code for w in ln.split() if w.startswith("F")]
    assert set(feeds) == {"F900", "F120"}
    assert len(feeds) <= 2 * sum(ln.startswith("G0 Z") for ln in code)  # at most a change per plunge
    first_cut = next(i for i, ln in enumerate(code) if ln.startswith("G1"))
    assert code[first_cut - 1] == "M3 S10000" and code[-2:] == ["M5", "M2"]
    generic = _code_lines(to_gcode(job))
    assert "M3" not in " ".join(generic) and any(ln.endswith("F346.8") for ln in generic)  # the step delays


def test_bad_target_options_are_one_line_errors(tmp_path, capsys):
    src = _drill_file(tmp_path)
    for bad in (["--post", "marlin"], ["--feed", "-5"]):
        with pytest.raises(SystemExit) as exit_:
            main(["export", str(src), "-o", str(tmp_path / "x.ngc"), *bad])
        assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "--feed must be > 0" in err and "Traceback" not in err
    job = cam.plan(cam.digitize(cam.load_image(SAMPLES / "ellipse.png")), depth=3)
    with pytest.raises(cam.CamError, match="unknown G-code target 'fanuc'"):
        to_gcode(job, post="fanuc")


# ---------------------------------------------------------------------------------------------- arcs, checked


def _drawing_job():
    return cam.plan(cam.digitize(cam.load_image(SAMPLES / "ellipse.png")), depth=3)


def _relief_job():
    d = cam.digitize(cam.load_image(SAMPLES / "disc.png"))
    return cam.plan(d, profile=cam.load_profile(SAMPLES.parent / "profiles" / "dome.png"))


@needs_rs274
@pytest.mark.parametrize("make, tol, ratio", [
    (_drawing_job, 0.01, 0.6),
    pytest.param(_drawing_job, 0.1, 0.35, marks=pytest.mark.slow),
    pytest.param(_relief_job, 0.01, 0.6, marks=pytest.mark.slow),
])
def test_fitted_program_is_shorter_and_within_the_tolerance_of_the_job(tmp_path, make, tol, ratio):
    job = make()
    plain = to_gcode(job, post="linuxcnc")
    fitted = to_gcode(job, post="linuxcnc", arc_tolerance_mm=tol)
    assert len(fitted.splitlines()) < ratio * len(plain.splitlines())
    want, _ = _canon_path(plain, tmp_path, "plain.ngc")
    got, moves = _canon_path(fitted, tmp_path, "fitted.ngc")
    if tol >= 0.1:
        assert sum(m.kind == "arc" for m in moves) > 20
    assert _hausdorff(_below(got), _below(want)) <= tol + 0.003


@needs_rs274
@pytest.mark.slow
def test_fitted_path_follows_the_mocks_pin_log(tmp_path):
    """The fitted program's path against what the job itself drives: the mock's pin log, decoded.  The steps
    stand up to one step off the straight line between two points (the motion is stepped), so the bound is the
    tolerance and a step."""
    job = _drawing_job()
    tol = 0.05
    got, _ = _canon_path(to_gcode(job, post="linuxcnc", arc_tolerance_mm=tol), tmp_path, "f.ngc")
    motion = cam.decode_pin_log(cam.run(job).pin_log(), job.settings)
    s = job.settings
    pos = motion.position_steps.astype(float) * (s.mm_per_step_xy, -s.mm_per_step_xy, -s.mm_per_step_z)
    steps = _below(_dense(pos, 0.005))
    assert _hausdorff(_below(got), steps) <= tol + s.mm_per_step_xy * math.sqrt(2) + 0.003


# ---------------------------------------------------------------------------------------------- grbl emulator


@pytest.fixture
def quick_thread_switches():
    before = sys.getswitchinterval()
    sys.setswitchinterval(0.0005)
    yield
    sys.setswitchinterval(before)


@pytest.mark.slow
@pytest.mark.usefixtures("quick_thread_switches")
def test_grbl_emulator_runs_the_grbl_program_to_the_end_on_the_jobs_path(tmp_path):
    from cam.drive.grbl_link import GrblLink
    from cam.sim.grbl import start_emulator

    job = _drawing_job()
    tol = 0.05
    text = to_gcode(job, post="grbl", arc_tolerance_mm=tol, spindle_rpm=10000, feed_mm_min=3000,
                    plunge_feed_mm_min=1000)
    assert "G2 " in text or "G3 " in text
    emu = start_emulator(speed=None, settings={110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0,
                                                122: 500.0})
    try:
        with GrblLink(f"grbl:{emu.device_path}?baud=115200", welcome_timeout_s=1.0) as link:
            report = link.stream(text.splitlines())   # raises on any error:n or alarm
        assert report.max_outstanding_bytes <= 128
    finally:
        emu.stop()
    assert emu.error is None
    answers = [a for _, _, a in emu.lines()]
    assert answers and all(a == "ok" for a in answers)
    executed = emu.executed()
    assert executed[-1].end_mm == pytest.approx((0.0, 0.0, 1.0), abs=1e-9)   # home at the safe height
    ends = np.array([b.end_mm for b in executed if b.kind != "G0"])
    want, _ = _canon_path(to_gcode(job, post="linuxcnc"), tmp_path, "plain.ngc") if shutil.which("rs274") \
        else (None, None)
    if want is not None:
        d = cKDTree(_below(want)).query(_below(ends))[0]
        assert d.max() <= tol + 0.003


# ---------------------------------------------------------------------------------------------- SVG strokes


CIRCLE_SVG = """<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="40mm" viewBox="0 0 40 40">
<circle cx="20" cy="20" r="15" fill="none" stroke="black"/>
<path d="M 5 5 L 35 5" stroke="black" fill="none"/>
</svg>
"""


def test_every_svg_job_point_gets_a_point_of_the_drawings_own_curves(tmp_path):
    from cam.kinds.gcode_export import svg_exact_xy_mm
    from cam.formats.svg import load_svg

    src = tmp_path / "c.svg"
    src.write_text(CIRCLE_SVG)
    settings = cam.MachineSettings()
    drawing = load_svg(src)
    exact = svg_exact_xy_mm(drawing, settings)
    job = cam.plan_svg(drawing, settings=settings) if hasattr(cam, "plan_svg") else \
        __import__("cam.job.svg", fromlist=["plan_svg"]).plan_svg(drawing, settings=settings)
    mm = settings.mm_per_step_xy
    for xs, ys, _ in np.asarray(job.points_steps).tolist():
        x, y = exact.get((xs, ys))
        assert max(abs(x / mm - xs), abs(y / mm - ys)) <= 1.0    # within a step of the planner's point
        # on the circle (centre (15, 15) mm, the drawing's top-left (5, 5) at the home) or on the line y = 0
        assert min(abs(math.hypot(x - 15, y - 15) - 15), abs(y) + max(0.0, -x, x - 30)) <= 0.001


@needs_rs274
@pytest.mark.slow
def test_an_svg_circle_is_written_on_the_circle_as_a_few_arcs(tmp_path):
    src = tmp_path / "c.svg"
    src.write_text(CIRCLE_SVG)
    out = tmp_path / "c.ngc"
    assert main(["export", str(src), "-o", str(out), "--post", "linuxcnc"]) == 0
    text = out.read_text()
    code = _code_lines(text)
    assert sum(ln.startswith(("G2 ", "G3 ")) for ln in code) <= 8 and len(code) < 40
    got, _ = _canon_path(text, tmp_path, "run.ngc")
    cut = _below(got)
    # placed with the drawing's top-left (5, 5) at the home: the circle's centre at (15, -15) mm
    r = np.hypot(cut[:, 0] - 15.0, cut[:, 1] + 15.0)
    on_line = np.abs(cut[:, 1]) <= 1e-4                        # the straight line at Y = 0 (the circle's tangent)
    r = r[~on_line & (np.abs(r - 15.0) < 0.5)]
    # on the circle within the tolerance, but where the planner joined a straight run of one-step moves
    # (at the circle's flat top, bottom and sides) the job's own chord is kept: up to half a step off
    assert np.quantile(np.abs(r - 15.0), 0.9) <= 0.01 + 0.001
    assert np.abs(r - 15.0).max() <= cam.MachineSettings().mm_per_step_xy / 2 + 0.002
    assert len(r) > 0.8 * (~on_line).sum()
    line = cut[on_line]
    assert line[:, 0].min() == pytest.approx(0.0, abs=1e-4) and line[:, 0].max() == pytest.approx(30.0, abs=1e-4)
    assert main(["export", str(src), "-o", str(out), "--post", "linuxcnc", "--snap"]) == 0
    assert len(_code_lines(out.read_text())) > 10 * len(code)   # at the steps, the circle is a staircase


def _stream_to_grbl_emulator(program: str, at_pause: Callable[[Any], None]) -> Any:
    """Stream ``program`` to the grbl emulator through :class:`cam.drive.grbl_link.GrblLink`, pressing cycle start
    at each pause (``M0``) once the planner is empty, after ``at_pause(emulator)`` has looked at it; returns the
    stopped emulator (its executed blocks and answered lines)."""
    import threading

    from cam.drive.grbl_link import GrblLink
    from cam.sim.grbl import start_emulator

    emu = start_emulator(speed=None, settings={110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0,
                                                122: 500.0})
    try:
        with GrblLink(f"grbl:{emu.device_path}?baud=115200", welcome_timeout_s=1.0) as link:
            done = threading.Event()

            def cycle_start_at_each_pause():
                while not done.is_set():
                    if emu.wait_for(lambda e: e.state == "Hold:0" and e.planner_blocks == 0, 0.2):
                        at_pause(emu)
                        link.resume()
                        emu.wait_for(lambda e: not e.state.startswith("Hold"), 2.0)

            helper = threading.Thread(target=cycle_start_at_each_pause)
            helper.start()
            try:
                link.stream(program.splitlines())
            finally:
                done.set()
                helper.join()
    finally:
        emu.stop()
    return emu


@pytest.mark.slow
@pytest.mark.usefixtures("quick_thread_switches")
def test_grbl_emulator_pauses_at_each_tool_change_and_drills_the_exact_holes(tmp_path):
    src = _drill_file(tmp_path, ((1, 0.8, [(7.62, 2.54), (10.16, 5.08)]), (2, 1.0, [(3.3, 4.4)])))
    out = tmp_path / "g.ngc"
    assert main(["export", str(src), "-o", str(out), "--post", "grbl", "--offset", "0,10", "--cut-depth", "1.5",
                 "--spindle-rpm", "9000", "--feed", "600", "--plunge-feed", "300"]) == 0
    pauses: list[tuple] = []
    emu = _stream_to_grbl_emulator(out.read_text(), lambda e: pauses.append(e.machine_position_mm))
    assert emu.error is None and all(a == "ok" for _, _, a in emu.lines())
    assert len(pauses) == 2 and all(p[2] == pytest.approx(1.0) for p in pauses)   # lifted to the safe height
    bottoms = {(round(b.end_mm[0], 6), round(b.end_mm[1], 6)) for b in emu.executed()
               if b.kind == "G1" and b.end_mm[2] == pytest.approx(-1.5, abs=1e-9)}
    assert bottoms == {(7.62, -7.46), (10.16, -4.92), (3.3, -5.6)}


# ------------------------------------------------------------------------------ every hole moved to (issue #43)

ROOT = SAMPLES.parent
HOLE_FILES = [ROOT / "tests" / "data" / "drill_round2" / "kicad7" / "board-PTH.drl",  # first hole at the home
              ROOT / "samples" / "drill" / "eagle9_metric.drl"]  # five tools, T2 coming back
"""Drill files of several tools.  On the KiCad board the first hole is where the job starts (X0 Y0 after
placing): the first tool change was followed by the plunge alone."""
_CANON_CALL = re.compile(r"^\s*\d+\s+N[.\d]*\s*(\w+)\(")
_SAFE_Z_MM = 1.0  # cam export's travel height for G-code out


def _shared_hole_file(tmp_path):
    """T2's only hole is T1's last: the tour ends the first tool right above the next tool's hole."""
    return _drill_file(tmp_path, ((1, 0.8, [(0.0, 0.0), (5.0, 0.0)]), (2, 1.0, [(5.0, 0.0)])))


def _file_holes_mm(path) -> np.ndarray:
    """Where cam export (no --offset) writes the file's holes, worked out from the file itself: the board's
    top-left (of its holes and slots) at X0 Y0, Y up as on the board; slot ends count as holes (a slot is
    entered at one of its ends).  ``(N, 2)`` mm."""
    from cam.formats.excellon import load_excellon

    holes = load_excellon(path)
    drilled = np.asarray(holes.holes_mm, np.float64).reshape(-1, 2)
    slots = [np.asarray(p, np.float64).reshape(-1, 2) for p in holes.slot_paths_mm]
    every = np.concatenate([drilled] + slots)
    corner = np.array([every[:, 0].min(), every[:, 1].max()])
    ends = [p[[0, -1]] for p in slots]
    return np.concatenate([drilled] + ends) - corner, drilled - corner


def _rs274_events(path) -> list[tuple]:
    """The program as LinuxCNC's interpreter runs it (with a tool table of tools 1..99): ("G0"|"G1", x, y, z) for
    each straight move and ("change",) at each tool change (CHANGE_TOOL) or program stop (M0: PROGRAM_STOP)."""
    table = path.with_suffix(".tbl")
    table.write_text("".join(f"T{n} P{n} Z0 D1 ;tool {n}\n" for n in range(1, 100)))
    text = run_rs274(str(path), tool_table=str(table))
    moves = iter(parse_canonical(text))
    events: list[tuple] = []
    for line in text.splitlines():
        m = _CANON_CALL.match(line)
        if not m:
            continue
        name = m.group(1)
        if name in ("CHANGE_TOOL", "PROGRAM_STOP"):
            events.append(("change",))
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED", "NURBS_FEED"):
            move = next(moves)
            events.append(({"traverse": "G0", "feed": "G1"}.get(move.kind, move.kind), *move.end))
    return events


def _grbl_events(text: str) -> list[tuple]:
    """The grbl program read line by line (every word is one grbl takes; G0/G1 modal, absolute mm): the same
    events as :func:`_rs274_events`, an ``M0`` for "change"."""
    events: list[tuple] = []
    motion, at = None, [0.0, 0.0, 0.0]
    for line in _code_lines(text):
        words = line.split()
        assert all(GRBL_WORDS.match(w) for w in words), line
        moved = False
        for w in words:
            if w in ("G0", "G1", "G2", "G3"):
                motion = w
            elif w[0] in "XYZ":
                at["XYZ".index(w[0])] = float(w[1:])
                moved = True
        if moved:
            assert motion in ("G0", "G1"), line  # a drill program has no arcs
            events.append((motion, *at))
        if "M0" in words:
            events.append(("change",))
    return events


def _check_every_plunge(events: list[tuple], holes_mm: np.ndarray, drilled_mm: np.ndarray, post: str) -> None:
    """Each plunge (a feed from above the surface to below it) goes straight down over a hole of the file; after
    a tool change or a pause the program itself goes up to the safe height and over the hole, with rapids,
    before it plunges; every drilled hole of the file is plunged."""
    tol_mm = 0.5 * cam.MachineSettings().mm_per_step_xy + 1e-4  # each axis: a hole written at its steps
    at = None  # where the interpreter stands
    since_change: list[tuple] | None = None  # the moves since the last tool change or pause
    plunged = []
    n_after_change = 0
    for ev in events:
        if ev[0] == "change":
            since_change = []
            continue
        kind, x, y, z = ev
        if kind == "G1" and z < -1e-9 and at is not None and at[2] >= -1e-9:  # a plunge
            where = f"{post}: plunge at X{x:g} Y{y:g}"
            assert (abs(x - at[0]) < 1e-9 and abs(y - at[1]) < 1e-9), f"{where} is not straight down from {at}"
            d = np.abs(holes_mm - (x, y)).max(axis=1).min()
            assert d <= tol_mm, f"{where} is {d:.4f} mm from the nearest hole of the file"
            if since_change is not None:
                n_after_change += 1
                assert since_change, f"{where}: no move to it after the tool change"
                assert all(k == "G0" for k, *_ in since_change), f"{where}: a cut before the move to it"
                first, last = since_change[0], since_change[-1]
                assert first[3] >= _SAFE_Z_MM - 1e-9, f"{where}: not to the safe height first ({first})"
                assert (last[1], last[2]) == (x, y) and last[3] >= _SAFE_Z_MM - 1e-9, \
                    f"{where}: the move to it after the tool change is not a rapid over it at the safe height"
            plunged.append((x, y))
            since_change = None
        elif since_change is not None:
            since_change.append(ev)
        at = (x, y, z)
    assert n_after_change >= 2, f"{post}: {n_after_change} plunges after a tool change"
    got = np.array(plunged)
    missed = [h for h in drilled_mm if np.abs(got - h).max(axis=1).min() > tol_mm]
    assert not missed, f"{post}: holes never drilled: {missed[:5]}"


@needs_rs274
@pytest.mark.parametrize("post", ["linuxcnc", "grbl", "generic"])
def test_export_moves_to_every_hole_before_plunging(tmp_path, post):
    """Issue #43 point 9: after a tool change (T<n> M6, or grbl's M0) the next hole was plunged with no move to it
    when the tool already stood over it in the program's own reckoning (the first hole at X0 Y0, a tool's first
    hole where the last one ended); a controller that moves for a tool change drilled it wherever the tool was
    left.  Read back by LinuxCNC's interpreter (linuxcnc, generic) or line by line (grbl)."""
    files = HOLE_FILES + [_shared_hole_file(tmp_path)]
    for src in files:
        out = tmp_path / f"{src.stem}-{post}.ngc"
        assert main(["export", str(src), "-o", str(out), "--post", post]) == 0
        text = out.read_text()
        changes = len(re.findall(r"^T\d+ M6\b|^M0$", text, re.M))
        assert changes >= 2, (src.name, changes)
        events = _grbl_events(text) if post == "grbl" else _rs274_events(out)
        assert sum(ev[0] == "change" for ev in events) == changes
        holes_mm, drilled_mm = _file_holes_mm(src)
        _check_every_plunge(events, holes_mm, drilled_mm, f"{post} {src.name}")


def _eagle_drills_xln(tmp_path):
    """The issue's ``eagle_drills.xln``: an old Eagle drill file (``excellon_gen.eagle_inch_2_4``) of three tools
    whose first hole is the board's top-left (X0 Y0 once placed: where the program starts) and whose T2 has one
    hole, at T1's last: both tool changes used to be followed by the plunge alone (``T2 M6`` then ``G1 Z-2``)."""
    import excellon_gen

    board = excellon_gen.Board(holes_mm=np.array([[0.0, 10.16], [5.08, 10.16], [5.08, 10.16], [20.32, 2.54]]),
                               tool=np.array([0, 0, 1, 2]), diameters_mm=[0.8, 1.0, 3.2], size_mm=(25.0, 12.0))
    path = tmp_path / "eagle_drills.xln"
    path.write_text(excellon_gen.eagle_inch_2_4(board).text)
    return path


def _emulator_events(program: str) -> list[tuple]:
    """The grbl program as the grbl emulator runs it (cycle start at each ``M0``): ("G0"|"G1", x, y, z) for each
    block it executed (machine frame = the program's: no offsets) and ("change",) where it held at a pause.  Every
    line must be answered ``ok``."""
    pauses: list[int] = []
    emu = _stream_to_grbl_emulator(program, lambda e: pauses.append(len(e.executed())))
    assert emu.error is None and all(a == "ok" for _, _, a in emu.lines()), emu.lines()
    events: list[tuple] = []
    for k, b in enumerate(emu.executed()):
        events += [("change",)] * pauses.count(k)
        if b.kind in ("G0", "G1"):
            events.append((b.kind, *b.end_mm))
    return events


def _check_plunges_on_grbl(events: list[tuple], holes_mm: np.ndarray, drilled_mm: np.ndarray) -> None:
    """As :func:`_check_every_plunge`, for what grbl executed: a move of no length (the tool already over the
    hole at the safe height) is no block, so after a pause the tool must stand at the safe height over the hole
    when it plunges, with nothing but rapids since the pause."""
    tol_mm = 0.5 * cam.MachineSettings().mm_per_step_xy + 1e-4
    at, since_change, plunged, n_after_change = None, None, [], 0
    for ev in events:
        if ev[0] == "change":
            since_change = []
            continue
        kind, x, y, z = ev
        if kind == "G1" and z < -1e-9 and at is not None and at[2] >= -1e-9:
            where = f"grbl emulator: plunge at X{x:g} Y{y:g}"
            assert abs(x - at[0]) < 1e-6 and abs(y - at[1]) < 1e-6, f"{where} is not straight down from {at}"
            assert np.abs(holes_mm - (x, y)).max(axis=1).min() <= tol_mm, f"{where} is not over a hole"
            if since_change is not None:
                n_after_change += 1
                assert all(k == "G0" for k, *_ in since_change), f"{where}: a cut before the move to it"
                assert at[2] >= _SAFE_Z_MM - 1e-6, f"{where}: not from the safe height ({at})"
            plunged.append((x, y))
            since_change = None
        elif since_change is not None:
            since_change.append(ev)
        at = (x, y, z)
    assert n_after_change >= 2, n_after_change
    got = np.array(plunged)
    assert not [h for h in drilled_mm if np.abs(got - h).max(axis=1).min() > tol_mm]


@needs_rs274
@pytest.mark.usefixtures("quick_thread_switches")
def test_cam_export_eagle_drills_xln_moves_to_each_hole_for_linuxcnc_and_grbl(tmp_path):
    """Issue #43 point 9's own example: ``cam export eagle_drills.xln --post linuxcnc`` read back by rs274, and
    ``--post grbl`` read back line by line and run on the grbl emulator: after ``T1 M6`` and ``T2 M6`` (grbl:
    ``M0``) the program goes up and over the hole before it plunges, and every plunge is a hole of the file."""
    src = _eagle_drills_xln(tmp_path)
    holes_mm, drilled_mm = _file_holes_mm(src)
    assert len(drilled_mm) == 4
    for post in ("linuxcnc", "grbl"):
        out = tmp_path / f"eagle_drills-{post}.ngc"
        assert main(["export", str(src), "--post", post, "-o", str(out)]) == 0
        text = out.read_text()
        assert len(re.findall(r"^T\d+ M6\b|^M0$", text, re.M)) >= 3, text
        if post == "linuxcnc":
            assert re.search(r"^T2 M6\b.*\n(?:\(.*\)\n)*G0 Z", text, re.M), text  # not G1 Z-2 straight after
            _check_every_plunge(_rs274_events(out), holes_mm, drilled_mm, "linuxcnc eagle_drills.xln")
        else:
            _check_every_plunge(_grbl_events(text), holes_mm, drilled_mm, "grbl eagle_drills.xln")
            _check_plunges_on_grbl(_emulator_events(text), holes_mm, drilled_mm)
