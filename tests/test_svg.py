"""SVG in: the reader (shapes, transforms, units, visibility, text), the planner, and the carve check.

The carve check runs each job on the mock port, decodes the pin log and compares every position where the
tool went below the surface with the exact curve the SVG describes (computed here from the geometry, not
by the library): every cut position within one step of the curve, every sample of the curve within one
step of a cut position.
"""
import json
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

import cam
from cam.errors import CamError, ParseError, TravelError
from cam.formats.svg import parse_svg
from cam.job.svg import plan_svg, svg_strokes_steps

from conftest import ROOT, run_cli

SLOW_CASES = {'test_cubic_bezier_cuts_within_one_step'}
"""Cases that run in the slow tier only (tests/conftest.py): the same checks keep faster cases here."""


S = cam.MachineSettings()
MM = S.mm_per_step_xy


def svg(body: str, size: str = 'width="100mm" height="100mm" viewBox="0 0 100 100"') -> str:
    return f'<svg xmlns="http://www.w3.org/2000/svg" {size}>{body}</svg>'


def cut_positions(job: cam.Job) -> np.ndarray:
    """Unique ``(K, 2)`` machine (x, y) steps where the decoded motion is below the surface, all at full depth."""
    result = cam.run(job)
    assert result.status == "finished"
    motion = cam.decode_pin_log(result.pin_log(), job.settings)
    pos = motion.position_steps
    depth = int(job.points_steps[job.target][:, 2].max())
    below = pos[:, 2] > 0
    assert np.all(pos[below, 2] <= depth)
    cut = np.unique(pos[below, :2], axis=0)
    full = np.unique(pos[pos[:, 2] == depth, :2], axis=0)
    assert len(cut) == len(full), "a position was cut shallower than the depth"
    assert motion.final_steps == (0, 0, 0)
    return cut


def assert_cuts_the_curves(job: cam.Job, curves_mm: list[np.ndarray]) -> tuple[float, float]:
    """Every cut position within one step of the exact curves, every curve sample within one step of a cut.

    ``curves_mm``: dense samples (spacing well under a step) of each exact curve in machine mm.
    Returns the two largest distances in steps.
    """
    cut = cut_positions(job).astype(float)
    exact = np.concatenate(curves_mm) / MM
    d_cut, _ = cKDTree(exact).query(cut)
    d_curve, _ = cKDTree(cut).query(exact)
    assert d_cut.max() <= 1.0, f"a cut position lies {d_cut.max():.3f} steps from the curve at {cut[np.argmax(d_cut)]}"
    assert d_curve.max() <= 1.0, f"the curve at {exact[np.argmax(d_curve)]} is {d_curve.max():.3f} steps from any cut"
    return float(d_cut.max()), float(d_curve.max())


def dense(fn, length_mm: float) -> np.ndarray:
    t = np.linspace(0.0, 1.0, max(10, int(length_mm / MM * 8)))
    return np.array([fn(v) for v in t])


def circle(cx, cy, r, a0=0.0, a1=2 * math.pi):
    return dense(lambda t: (cx + r * math.cos(a0 + (a1 - a0) * t), cy + r * math.sin(a0 + (a1 - a0) * t)),
                 abs(a1 - a0) * r)


def segment(p, q):
    p, q = np.asarray(p, float), np.asarray(q, float)
    return dense(lambda t: p + (q - p) * t, float(np.hypot(*(q - p))))


def cubic(p0, p1, p2, p3, transform=lambda p: p):
    p0, p1, p2, p3 = (np.asarray(v, float) for v in (p0, p1, p2, p3))
    f = lambda t: transform((1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * p1 + 3 * (1 - t) * t * t * p2 + t ** 3 * p3)
    return dense(f, 4 * float(np.abs(np.diff([p0, p1, p2, p3], axis=0)).sum()))


def plan(text, **kw):
    kw.setdefault("offset_mm", (0.0, 0.0))  # the page origin at the home: machine mm = page mm
    return plan_svg(parse_svg(text, source="t.svg"), cut_depth_mm=0.3, travel_height_mm=0.5, **kw)


# ---------------------------------------------------------------- the carve check on known geometry


@pytest.mark.parametrize("r_mm", [0.3, 2.0, 7.5, 23.0])
def test_circle_of_radius_r_cuts_within_one_step(r_mm):
    job = plan(svg(f'<circle cx="30" cy="40" r="{r_mm}" fill="none" stroke="black"/>'))
    assert_cuts_the_curves(job, [circle(30, 40, r_mm)])


def test_rectangle_cuts_its_four_sides_and_corners():
    job = plan(svg('<rect x="3.3" y="7.1" width="20.25" height="9.5" fill="none" stroke="#000"/>'))
    corners = [(3.3, 7.1), (23.55, 7.1), (23.55, 16.6), (3.3, 16.6), (3.3, 7.1)]
    assert_cuts_the_curves(job, [segment(a, b) for a, b in zip(corners, corners[1:])])
    cut = {tuple(p) for p in cut_positions(job).tolist()}
    for x, y in corners:  # each corner at its nearest step
        assert (int(math.floor(x / MM + 0.5)), int(math.floor(y / MM + 0.5))) in cut


def test_cubic_bezier_cuts_within_one_step():
    job = plan(svg('<path d="M5,50 C20,5 60,95 90,30" fill="none" stroke="black"/>'))
    assert_cuts_the_curves(job, [cubic((5, 50), (20, 5), (60, 95), (90, 30))])


def test_nested_transforms_are_applied():
    text = svg('<g transform="translate(40,30) rotate(30)"><g transform="scale(2,1.5) translate(1,2)">'
               '<path d="M0,0 C5,-10 10,10 15,0" fill="none" stroke="black"/></g></g>')
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))

    def transform(p):
        x, y = (p[0] + 1) * 2, (p[1] + 2) * 1.5
        return np.array([40 + c * x - s * y, 30 + s * x + c * y])

    job = plan(text)
    assert_cuts_the_curves(job, [cubic((0, 0), (5, -10), (10, 10), (15, 0), transform)])


def test_arcs_quadratics_ellipse_polygon_polyline_and_line():
    text = svg('<path d="M10,20 A10,10 0 0 1 30,20" stroke="black" fill="none"/>'
               '<path d="M40,10 Q50,30 60,10" stroke="black" fill="none"/>'
               '<ellipse cx="50" cy="60" rx="20" ry="8" stroke="black" fill="none"/>'
               '<polygon points="5,80 15,90 5,95" stroke="black" fill="none"/>'
               '<polyline points="70,80 80,95 90,80" stroke="black" fill="none"/>'
               '<line x1="60" y1="40" x2="95" y2="45" stroke="black"/>')
    quad = dense(lambda t: (1 - t) ** 2 * np.array([40, 10]) + 2 * (1 - t) * t * np.array([50, 30])
                 + t * t * np.array([60, 10]), 40)
    ellipse = dense(lambda t: (50 + 20 * math.cos(2 * math.pi * t), 60 + 8 * math.sin(2 * math.pi * t)), 90)
    curves = [circle(20, 20, 10, math.pi, 2 * math.pi), quad, ellipse,
              segment((5, 80), (15, 90)), segment((15, 90), (5, 95)), segment((5, 95), (5, 80)),
              segment((70, 80), (80, 95)), segment((80, 95), (90, 80)), segment((60, 40), (95, 45))]
    assert_cuts_the_curves(plan(text), curves)


@pytest.mark.parametrize("size, k_mm", [
    ('width="2in" height="1in" viewBox="0 0 200 100"', 25.4 * 2 / 200),
    ('width="96" height="96"', 25.4 / 96),                     # px at 96 dpi, no viewBox
    ('width="10cm" height="5cm" viewBox="0 0 50 25"', 2.0),
    ('width="40mm" height="40mm" viewBox="-10 -10 20 20"', 2.0),  # a viewBox with its origin elsewhere
])
def test_physical_units_and_viewbox(size, k_mm):
    text = svg('<path d="M1,2 L11,2 L11,7" stroke="black" fill="none"/>', size)
    d = parse_svg(text)
    shift = 10 * k_mm if "-10" in size else 0.0
    want = (np.array([[1, 2], [11, 2], [11, 7]]) * k_mm + shift)
    assert np.abs(d.polylines(1e-3)[0] - want).max() < 1e-6 * 100  # svgelements' mm is 0.0393701 in
    job = plan(text)
    assert_cuts_the_curves(job, [segment(want[0], want[1]), segment(want[1], want[2])])


@pytest.mark.slow
def test_random_cubics_cut_within_one_step():
    rng = np.random.default_rng(16)
    for _ in range(3):
        p = rng.uniform(2, 60, (4, 2)).round(2)
        job = plan(svg(f'<path d="M{p[0,0]},{p[0,1]} C{p[1,0]},{p[1,1]} {p[2,0]},{p[2,1]} {p[3,0]},{p[3,1]}" '
                       'stroke="black" fill="none"/>'))
        assert_cuts_the_curves(job, [cubic(*p)])


def test_the_check_sees_a_wrong_cut():
    bad = plan(svg('<circle cx="10" cy="10" r="5" fill="none" stroke="black"/>'), offset_mm=(2 * MM, 0.0))
    with pytest.raises(AssertionError, match="steps from"):
        assert_cuts_the_curves(bad, [circle(10, 10, 5)])


# ---------------------------------------------------------------- what is cut, placement, order


def test_visibility_rules_and_counts():
    d = parse_svg(svg('<rect x="1" y="1" width="5" height="5"/>'                      # filled: its outline
                      '<rect x="1" y="1" width="5" height="5" style="display:none" stroke="black"/>'
                      '<circle cx="5" cy="5" r="2" visibility="hidden" stroke="black"/>'
                      '<g visibility="hidden"><circle cx="5" cy="5" r="3" stroke="black"/></g>'
                      '<circle cx="5" cy="5" r="4" fill="none" stroke="none"/>'
                      '<line x1="0" y1="0" x2="9" y2="0"/>'                             # a line without stroke
                      '<path d="M20,20 L30,20 L30,30" fill="blue"/>'))                 # a fill closes it
    assert d.element_counts == {"rect": 1, "path": 1}
    assert d.closed.tolist() == [True, True]
    assert np.allclose(d.polylines(0.01)[1][-1], [20.0, 20.0])


def test_text_is_an_error_asking_for_paths():
    with pytest.raises(ParseError, match="convert the text to paths"):
        parse_svg(svg('<text x="5" y="5">LOGO</text>'))


@pytest.mark.parametrize("text", [b"", b"<svg", b"hello", b"<html><body/></html>"])
def test_not_an_svg_is_a_parse_error(text):
    with pytest.raises(ParseError):
        d = parse_svg(text)
        plan_svg(d)


def test_nothing_visible_is_a_plan_error():
    with pytest.raises(cam.PlanError, match="nothing to cut"):
        plan(svg('<circle cx="5" cy="5" r="4" fill="none"/>'))


def test_scale_fit_and_offset_place_the_drawing():
    text = svg('<rect x="10" y="20" width="30" height="10" stroke="black" fill="none"/>')
    d = parse_svg(text)
    default = np.concatenate(svg_strokes_steps(d))
    assert default.min(axis=0).tolist() == [0, 0]  # top-left of what is cut at the home
    assert default.max(axis=0).tolist() == [round(30 / MM), round(10 / MM)]
    doubled = np.concatenate(svg_strokes_steps(d, scale=2.0))
    assert doubled.max(axis=0).tolist() == [round(60 / MM), round(20 / MM)]
    fitted = np.concatenate(svg_strokes_steps(d, fit_mm=(15.0, 100.0)))
    assert fitted.max(axis=0).tolist() == [round(15 / MM), round(5 / MM)]
    placed = np.concatenate(svg_strokes_steps(d, offset_mm=(1.0, 2.0)))
    assert placed.min(axis=0).tolist() == [round(11 / MM), round(22 / MM)]
    with pytest.raises(CamError, match="not both"):
        svg_strokes_steps(d, scale=2.0, fit_mm=(1.0, 1.0))
    with pytest.raises(TravelError, match="--fit"):
        plan_svg(d, scale=20.0)


def test_strokes_keep_their_direction_unless_reversing_shortens_travel():
    # line 2's end (x 11) is nearer to where line 1 ends than its start (x 30): reversed; line 3's start
    # (32, 5) is nearer to where line 2 then ends (30, 1) than its end: kept
    job = plan(svg('<path d="M1,1 H10" stroke="black"/><path d="M30,1 H11" stroke="black"/>'
                   '<path d="M32,5 H50" stroke="black"/>'))
    xs = np.round(job.points_steps[job.target][:, 0] * MM).astype(int).tolist()
    assert xs == [1, 10, 11, 30, 32, 50]
    travels = np.flatnonzero(job.kind == cam.job.model.TRAVEL)[:-1]  # (the last one goes down to the home)
    assert all(job.points_steps[i - 1, 2] < 0 and job.points_steps[i, 2] < 0 for i in travels)  # lifted first


# ---------------------------------------------------------------- the command line and the web options


def cli(*args, cwd=None):
    """``cam ARGS`` in this process (conftest.run_cli)."""
    return run_cli(*args, cwd=cwd)


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_cli_drill_info_preview_export(tmp_path):
    logo = write(tmp_path, "logo.svg", svg('<circle cx="10" cy="10" r="8" stroke="black" fill="none"/>'
                                           '<path d="M22,2 C30,2 30,18 38,18" stroke="black" fill="none"/>'))
    out = cli("drill", str(logo), "--cut-depth", "0.3", "--pin-log", str(tmp_path / "pins.csv"),
              "--report", str(tmp_path / "r.json"))
    assert out.returncode == 0, out.stderr
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["kind"] == "svg" and rep["strokes"] == 2 and abs(rep["depth_mm"] - 0.3) < 0.01
    info = cli("info", str(logo))
    assert info.returncode == 0 and "2 strokes" in info.stdout and "1 circle, 1 path" in info.stdout
    assert cli("preview", str(logo), "-o", str(tmp_path / "p.png"), "--fit", "50x50").returncode == 0
    assert (tmp_path / "p.png").stat().st_size > 1000
    assert cli("export", str(logo), "-o", str(tmp_path / "l.ngc"), "--scale", "0.5").returncode == 0
    assert "G1" in (tmp_path / "l.ngc").read_text()


@pytest.mark.parametrize("args, fragment", [
    (["--fit", "50"], "WIDTHxHEIGHT"),
    (["--scale", "2", "--fit", "5x5"], "cannot be given together"),
    (["--depth", "3"], "does not apply"),
])
def test_cli_bad_options_are_one_line(tmp_path, args, fragment):
    logo = write(tmp_path, "logo.svg", svg('<circle cx="10" cy="10" r="8" stroke="black"/>'))
    out = cli("drill", str(logo), *args)
    assert out.returncode == 2 and fragment in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_cli_text_is_one_line_and_nothing_moves(tmp_path):
    logo = write(tmp_path, "logo.svg", svg('<text x="1" y="5">Hi</text>'))
    out = cli("drill", str(logo), "--pin-log", str(tmp_path / "pins.csv"))
    assert out.returncode == 2 and "convert the text to paths" in out.stderr
    assert not (tmp_path / "pins.csv").exists()


def test_scale_on_a_drawing_is_refused(tmp_path):
    out = cli("drill", str(ROOT / "samples" / "ellipse.png"), "--scale", "2")
    assert out.returncode == 2 and "applies to dxf and hpgl and svg" in out.stderr


def test_prepare_job_and_web_options(tmp_path):
    logo = write(tmp_path, "logo.svg", svg('<rect x="1" y="1" width="10" height="10" stroke="black"/>'))
    import cam.kinds.jobs

    opts = cam.kinds.jobs.JobOptions.from_mapping({"fit_mm": "20x40", "cut_depth_mm": "0.2"})
    job = cam.kinds.jobs.prepare_job(logo, opts)
    assert job.kind == "svg" and abs(job.size_mm[0] - 20) < 0.1 and abs(job.size_mm[1] - 20) < 0.1
    assert job.preview_png()[:4] == b"\x89PNG"
    with pytest.raises(CamError, match="does not apply"):
        cam.kinds.jobs.prepare_job(logo, cam.kinds.jobs.JobOptions(depth=(3,)))


def test_notebook_pictures():
    d = cam.parse_svg(svg('<circle cx="10" cy="10" r="8" stroke="black"/>'))
    assert d._repr_png_()[:4] == b"\x89PNG"
    assert cam.plan_svg(d)._repr_png_()[:4] == b"\x89PNG"
