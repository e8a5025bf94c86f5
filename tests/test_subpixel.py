"""The finer finishing pass of a real tool (cam.job.subpixel): positions between pixel centres take what the
pixel-centre pass leaves, never gouge, and never leave more than the best positions on that grid must."""
from __future__ import annotations

import numpy as np
import pytest

import cam
from cam.job.subpixel import MIN_GAIN_ZPX, finer_grid, finer_grids
from cam.tool import parse_tool
from cam.verify.toolcarve import carve_tool, compare_surface, least_rest_steps
from conftest import carve_job
from test_tools import RELIEFS

SETTINGS = cam.MachineSettings()  # 8 steps per pixel: grids of an eighth, a quarter and half a pixel
STEP_MM = SETTINGS.mm_per_step_z


SLOW_CASES = {
    'test_the_finer_pass_takes_what_the_grid_allows_and_never_gouges[hemisphere-v:60:0]',
      # the fast tier keeps the other cases of these tests (tests/conftest.py)
    'test_the_finer_pass_takes_what_the_grid_allows_and_never_gouges[stepped pyramid-v:60:0]',
}


def _cut(name: str, spec: str, subpixel: bool, settings=SETTINGS):
    drawing, expr = RELIEFS[name]
    d = cam.digitize(drawing())
    profile = cam.profile_from_expr(expr, d.n_layers)
    want, _, _ = carve_job(cam.plan(d, profile=profile, settings=settings))
    job = cam.plan(d, profile=profile, tool=spec, settings=settings, subpixel=subpixel)
    motion = cam.decode_pin_log(cam.run(job).pin_log(), settings)
    cut = carve_tool(motion, want.shape, parse_tool(spec), settings, origin_px=job.origin_px)
    return want, job, compare_surface(cut.depth_steps, want, settings)


@pytest.mark.parametrize("spec", ["ball:1", "flat:1", "v:60:0"])
@pytest.mark.parametrize("name", list(RELIEFS))
def test_the_finer_pass_takes_what_the_grid_allows_and_never_gouges(name, spec):
    want, job, fine = _cut(name, spec, True)
    _, coarse_job, coarse = _cut(name, spec, False)
    assert fine.max_gouge_mm == 0.0 and coarse.max_gouge_mm == 0.0
    # it only adds cuts: never more material left anywhere than without it
    assert np.all(fine.rest_mm <= coarse.rest_mm + 1e-12)
    # and no more than the best positions of its grid must leave, but for what it skips on purpose
    bound = least_rest_steps(want, parse_tool(spec), SETTINGS, k=4)  # it looks at a quarter pixel at least
    excess = fine.rest_mm / STEP_MM - bound
    assert excess.max() <= MIN_GAIN_ZPX + 1e-6, (name, spec, excess.max())
    # its points are not targets: the report's points are the pixel-centre pass's
    assert job.n_targets == coarse_job.n_targets and len(job.points_steps) >= len(coarse_job.points_steps)


def test_a_ball_on_slopes_leaves_far_less():
    """The pyramid sample cut with a 1 mm ball: with the pixel centres alone it leaves 2.9 um on average, up to
    two Z steps on its slopes (each centre's depth rounds up to a whole step differently); the quarter-pixel
    grid takes nearly all of it, in a fraction of the time again."""
    from conftest import ROOT, SAMPLES
    d = cam.digitize(cam.load_image(SAMPLES / "pyramid.png"))
    profile = cam.load_profile(ROOT / "profiles" / "pyramid.png")
    want, _, _ = carve_job(cam.plan(d, profile=profile))
    out = {}
    for subpixel in (False, True):
        job = cam.plan(d, profile=profile, tool="ball:1", subpixel=subpixel)
        plan = cam.plan_steps(job)
        motion = cam.decode_pin_log(cam.run(plan).pin_log(), SETTINGS)
        cut = carve_tool(motion, want.shape, parse_tool("ball:1"), SETTINGS, origin_px=job.origin_px)
        out[subpixel] = (compare_surface(cut.depth_steps, want, SETTINGS), plan.estimated_time_s)
    (coarse, t0), (fine, t1) = out[False], out[True]
    assert fine.max_gouge_mm == 0.0
    assert fine.rest_mean_mm < 0.1 * coarse.rest_mean_mm and fine.rest_p95_mm < 0.1 * coarse.rest_p95_mm
    assert t1 < 1.6 * t0


def test_a_machine_without_finer_steps_plans_as_before():
    """One step per pixel: no position between pixel centres can be reached, and the plan is the same."""
    s = SETTINGS.replace(steps_per_px_xy=1)
    assert finer_grid(s) == 1 and finer_grids(SETTINGS) == [8, 4, 2]
    assert finer_grids(SETTINGS.replace(steps_per_px_xy=6)) == [6, 3, 2]
    drawing, expr = RELIEFS["hemisphere"]
    d = cam.digitize(drawing())
    profile = cam.profile_from_expr(expr, d.n_layers)
    a = cam.plan(d, profile=profile, tool="ball:1", settings=s)
    b = cam.plan(d, profile=profile, tool="ball:1", settings=s, subpixel=False)
    np.testing.assert_array_equal(a.points_steps, b.points_steps)


@pytest.mark.slow
def test_no_cut_leaves_less_than_the_least_rest():
    """least_rest_steps is a floor: the point tool reaches every centre (0 left), a 1 mm flat end mill cannot
    enter a trench one pixel wide (all of it left), and cam's cuts never leave less than it, step grid and all."""
    from cam.tool import POINT
    want = np.zeros((15, 15))
    want[7, 2:13] = 10.0  # a trench one pixel wide, ten Z steps deep
    assert np.all(least_rest_steps(want, POINT, SETTINGS) == 0)
    flat = least_rest_steps(want, parse_tool("flat:1"), SETTINGS)
    assert np.array_equal(flat, want)
    for name in RELIEFS:
        for spec in ("ball:1", "v:60:0"):
            target, _, fine = _cut(name, spec, True)
            floor = least_rest_steps(target, parse_tool(spec), SETTINGS)
            assert np.all(fine.rest_mm / STEP_MM >= floor - 1e-6), (name, spec)


def test_a_relief_too_large_for_the_finer_maps_gets_a_coarser_grid_or_a_warning(monkeypatch):
    """The finer grid's maps are bounded (MAX_CELLS): a relief too large for every grid is planned without the
    pass, with a warning, exactly as subpixel=False plans it."""
    import cam.job.subpixel as sp
    drawing, expr = RELIEFS["hemisphere"]
    d = cam.digitize(drawing())
    profile = cam.profile_from_expr(expr, d.n_layers)
    monkeypatch.setattr(sp, "MAX_CELLS", d.height_px * d.width_px * 3)  # under the half-pixel grid's 4x
    job = cam.plan(d, profile=profile, tool="ball:1")
    plain = cam.plan(d, profile=profile, tool="ball:1", subpixel=False)
    np.testing.assert_array_equal(job.points_steps, plain.points_steps)
    assert any("left out of a relief this large" in w for w in job.warnings)
    monkeypatch.setattr(sp, "MAX_CELLS", d.height_px * d.width_px * 4)  # the half-pixel grid fits
    assert len(cam.plan(d, profile=profile, tool="ball:1").points_steps) > len(plain.points_steps)


def test_nearest_first_keeps_every_curve_and_runs_each_from_its_nearer_end():
    """Every curve once, whole, each run from the end nearer where the one before ended; far shorter travel
    between curves than their traced order."""
    from cam.job.subpixel import nearest_first
    rng = np.random.default_rng(1)
    curves = [rng.integers(0, 2000, 2) + np.cumsum(rng.integers(-1, 2, (int(rng.integers(1, 6)), 2)), axis=0)
              for _ in range(3000)]
    got = nearest_first(curves, (0, 0))
    key = lambda c: tuple(map(tuple, c.tolist()))  # noqa: E731
    assert len(got) == len(curves)
    assert sorted(min(key(c), key(c[::-1])) for c in got) == sorted(min(key(c), key(c[::-1])) for c in curves)
    x, y, jumps = 0, 0, 0
    for c in got:
        first, last = max(abs(c[0] - (x, y))), max(abs(c[-1] - (x, y)))
        assert first <= last
        jumps += first
        x, y = c[-1]
    traced = sum(max(abs(b[0] - a[-1])) for a, b in zip(curves, curves[1:]))
    assert jumps < 0.1 * traced
