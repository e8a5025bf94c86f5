"""HPGL circles and arcs come out of `cam export --post grbl|linuxcnc` as G2/G3 (issue #30 point 4).

The exporter writes an HPGL job's points at their exact mm (:func:`cam.kinds.gcode_export.hpgl_exact_xy_mm`,
placed as the HPGL planner places them) and knows which moves are chords of a ``CI``/``AA``/``AR``, so the arc
fitter holds an arc to the chords' ends (on the file's circle) and not to the chords.  Checked against the
circles the file describes, through LinuxCNC's rs274 for the linuxcnc post."""
from __future__ import annotations

import io
import math
import re
import shutil

import numpy as np
import pytest

import cam
from cam.cli import main
from cam.kinds.gcode_export import hpgl_exact_xy_mm
from cam.formats.hpgl import iter_hpgl, load_hpgl
from cam.job.hpgl import plan_hpgl
from cam.job.model import CUT
from support.lcnc import canonical_polyline_mm, parse_canonical, run_rs274

needs_rs274 = pytest.mark.skipif(shutil.which("rs274") is None, reason="rs274 (linuxcnc-uspace) not installed")

# a circle r 800 pu (20 mm) about (2000, 2000) and a quarter arc r 1000 pu (25 mm) about (4000, 3000) from
# (4000, 2000) to (5000, 3000); placed by default with the drawing's top-left (1200, 3000) at the home:
# machine x = (X - 1200) * 0.025, written Y = -(3000 - Y) * 0.025
CIRCLE_ARC = b"IN;SP1;PU2000,2000;CI800;PU4000,2000;PD;AA4000,3000,90;PU;"
CIRCLE_MM = (20.0, -25.0, 20.0)  # centre x, y (as written), radius
ARC_MM = (70.0, 0.0, 25.0)
TOL = 0.01

ARC_WORD = re.compile(r"^G([23]) X(\S+) Y(\S+) I(\S+) J(\S+)")


def _export(tmp_path, data: bytes, *args: str, name: str = "c.plt") -> str:
    src = tmp_path / name
    src.write_bytes(data)
    out = tmp_path / (name + ".ngc")
    assert main(["export", str(src), "-o", str(out), *args]) == 0
    return out.read_text()


def _code(text: str) -> list[str]:
    return [ln for ln in (re.sub(r"\(.*?\)", "", ln).strip() for ln in text.splitlines()) if ln]


def _arcs(text: str) -> list[tuple[float, float, float]]:
    """``(centre x, centre y, radius)`` of each G2/G3, from its start (the point before it) and I, J."""
    out, x, y = [], 0.0, 0.0
    for ln in _code(text):
        m = ARC_WORD.match(ln)
        if m:
            cx, cy = x + float(m.group(4)), y + float(m.group(5))
            out.append((cx, cy, math.hypot(x - cx, y - cy)))
        for axis, v in re.findall(r"([XY])(-?[\d.]+)", ln):
            if axis == "X":
                x = float(v)
            else:
                y = float(v)
    return out


def _arc_lines(text: str) -> int:
    return sum(ln.startswith(("G2 ", "G3 ")) for ln in _code(text))


def test_a_circle_and_an_arc_are_written_as_a_few_arcs_on_their_own_circles(tmp_path):
    text = _export(tmp_path, CIRCLE_ARC, "--post", "grbl")
    code = _code(text)
    assert _arc_lines(text) == 3                       # the circle in two halves, the quarter arc in one
    assert not [ln for ln in code if ln.startswith("G1 X")]   # no chord is left as a line
    arcs = _arcs(text)
    for cx, cy, r in arcs[:2]:
        assert (cx, cy, r) == pytest.approx(CIRCLE_MM, abs=2e-4)
    assert arcs[2] == pytest.approx(ARC_MM, abs=2e-4)
    assert "G3 X95 Y0 I0 J25" in text                  # the arc ends where AA puts it: (5000, 3000)


def test_relative_arcs_and_arcs_inside_a_stroke_of_lines_are_arcs_between_the_lines(tmp_path):
    # a line, a half circle r 500 pu (AR: centre relative to the pen), clockwise, a line, all one stroke
    text = _export(tmp_path, b"IN;SP1;PU0,0;PD1000,0;AR0,500,-180;PD0,1000;PU;", "--post", "grbl")
    code = [ln for ln in _code(text) if ln.startswith(("G1 X", "G2 ", "G3 "))]
    assert [ln.split()[0] for ln in code] == ["G1", "G2", "G1"] or \
        [ln.split()[0] for ln in code] == ["G1", "G2", "G2", "G1"]
    for cx, cy, r in _arcs(text):    # top-left (0, 1000) at the home: the centre (1000, 500) at (25, -12.5)
        assert (cx, cy, r) == pytest.approx((25.0, -12.5, 12.5), abs=2e-4)


def test_every_hpgl_job_point_maps_to_its_exact_point_within_a_step():
    settings = cam.MachineSettings()
    drawing = load_hpgl(io.BytesIO(CIRCLE_ARC), source="c.plt")
    positions = {(c.line, c.column) for c in iter_hpgl(io.BytesIO(CIRCLE_ARC)) if c.name in ("CI", "AA")}
    assert positions == {(1, 20), (1, 41)}
    exact = hpgl_exact_xy_mm(drawing, settings, arc_positions=positions)
    job = plan_hpgl(drawing, settings=settings)
    mm = settings.mm_per_step_xy
    cut = np.asarray(job.points_steps)[job.kind == CUT]
    assert len(cut) > 50
    for xs, ys, _ in cut.tolist():
        x, y = exact.get((xs, ys))
        assert max(abs(x / mm - xs), abs(y / mm - ys)) <= 0.5 + 1e-9
        on_circle = abs(math.hypot(x - 20.0, -y + 25.0) - 20.0)
        on_arc = abs(math.hypot(x - 70.0, -y - 0.0) - 25.0)
        assert min(on_circle, on_arc) <= 1e-9
    assert len(exact.arc_moves) == 72 + 18           # every chord of both, and no other move
    assert exact.on_arc((1384, 865), (1381, 805)) and not exact.on_arc((1381, 805), (1384, 865))


@needs_rs274
def test_linuxcnc_runs_the_arcs_within_the_tolerance_of_the_files_circles(tmp_path):
    text = _export(tmp_path, CIRCLE_ARC, "--post", "linuxcnc")
    assert _arc_lines(text) == 3
    path = tmp_path / "run.ngc"
    path.write_text(text)
    moves = parse_canonical(run_rs274(str(path)))
    assert sum(mv.kind == "arc" for mv in moves) == 3
    pts, _ = canonical_polyline_mm(moves, max_chord_mm=0.01)
    cut = pts[pts[:, 2] < -0.1]
    d_circle = np.abs(np.hypot(cut[:, 0] - 20.0, cut[:, 1] + 25.0) - 20.0)
    d_arc = np.abs(np.hypot(cut[:, 0] - 70.0, cut[:, 1]) - 25.0)
    near = np.minimum(d_circle, d_arc)
    assert near.max() <= TOL                         # every point cut lies on the file's own circles
    on_arc = d_arc < d_circle                        # ... the quarter only: from (70, -25) to (95, 0)
    assert cut[on_arc, 0].min() >= 70.0 - 1e-3 and cut[on_arc, 1].max() <= 1e-3
    # and the whole of each is cut: every point of the file's circle and arc lies near the path
    t = np.linspace(0, 2 * math.pi, 721)
    want = np.vstack([np.column_stack([20 + 20 * np.cos(t), -25 + 20 * np.sin(t)]),
                      np.column_stack([70 + 25 * np.cos(t[:181] / 4 - math.pi / 2),
                                       25 * np.sin(t[:181] / 4 - math.pi / 2)])])
    gap = np.min(np.hypot(want[:, None, 0] - cut[None, :, 0], want[:, None, 1] - cut[None, :, 1]), axis=1)
    assert gap.max() <= 0.01 + TOL


def test_snap_or_a_zero_tolerance_writes_lines_as_before(tmp_path):
    snapped = _export(tmp_path, CIRCLE_ARC, "--post", "grbl", "--snap")
    assert _arc_lines(snapped) == 0 and sum(ln.startswith("G1 X") for ln in _code(snapped)) >= 72 + 18
    lines = _export(tmp_path, CIRCLE_ARC, "--post", "grbl", "--arc-tolerance", "0")
    assert _arc_lines(lines) == 0
    g1 = [ln for ln in _code(lines) if ln.startswith("G1 X")]
    assert len(g1) == 72 + 18                          # a line a chord (5 degrees), at the chords' exact ends
    for ln in g1:
        x, y = (float(v) for v in re.findall(r"[XY](-?[\d.]+)", ln)[:2])
        assert min(abs(math.hypot(x - 20, y + 25) - 20), abs(math.hypot(x - 70, y) - 25)) <= 1e-4


@pytest.mark.parametrize("args, centre_mm, radius_mm", [
    (("--scale", "2"), (40.0, -50.0), 40.0),
    (("--fit", "30x30"), None, None),
    (("--offset", "10,90"), (60.0, -40.0), 20.0),      # plotter (0, 0) at (10, 90) mm: Y written -(90 - Y)
    (("--origin", "center"), (20.0, -25.0), 20.0),     # placed when it runs: the job's own frame as by default
])
def test_placement_options_move_the_arcs_with_the_job(tmp_path, args, centre_mm, radius_mm):
    text = _export(tmp_path, CIRCLE_ARC, "--post", "grbl", *args)
    snapped = _export(tmp_path, CIRCLE_ARC, "--post", "grbl", "--snap", "--arc-tolerance", "0", *args,
                      name="s.plt")
    assert _arc_lines(text) == 3
    arcs = _arcs(text)
    assert arcs[0] == pytest.approx(arcs[1], abs=2e-4)
    if centre_mm is not None:
        assert arcs[0] == pytest.approx((*centre_mm, radius_mm), abs=2e-4)
    # the arcs pass within a step of the planner's own points (the snapped program's)
    cx, cy, r = arcs[0]
    mm = cam.MachineSettings().mm_per_step_xy
    pts = [tuple(float(v) for v in re.findall(r"[XY](-?[\d.]+)", ln)[:2]) for ln in _code(snapped)
           if ln.startswith("G1 X")]
    near = [abs(math.hypot(x - cx, y - cy) - r) for x, y in pts]
    assert sum(d <= mm for d in near) >= 70


def test_a_file_placed_by_its_own_zero_keeps_its_arcs(tmp_path):
    text = _export(tmp_path, b"IN;SP1;PU2000,-2000;CI800;PU;", "--post", "grbl", "--origin", "file")
    arcs = _arcs(text)
    assert len(arcs) == 2
    for a in arcs:   # plotter (0, 0) at the program's zero: the centre at (50, -50) mm
        assert a == pytest.approx((50.0, -50.0, 20.0), abs=2e-4)
