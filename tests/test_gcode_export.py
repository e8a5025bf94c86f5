"""G-code out, checked by LinuxCNC's own interpreter (rs274 from Debian's linuxcnc-uspace)."""
import os
import shutil

import pytest

import cam
from cam.kinds.gcode_export import feeds_mm_per_min, to_gcode
from support.lcnc import carve_canonical, parse_canonical, run_rs274

from conftest import ROOT, SAMPLES, carve_job, assert_surface_equal, drawing_from_rows

needs_rs274 = pytest.mark.skipif(
    shutil.which("rs274") is None and not os.environ.get("CI"), reason="rs274 (linuxcnc-uspace) not installed"
)

JOBS = [(name, dict(depth=5, passes=2)) for name in
        ["ellipse.png", "two_curves.png", "gear.png", "word.png", "stamp.png"]]
JOBS += [(name, dict(profile=ROOT / "profiles" / prof))
         for name in ["disc.png", "pyramid.png", "heart.png", "dumbbell.png", "ring.png"]
         for prof in ["dome.png", "cone.png", "pyramid.png", "flat.png"]]
FAST_JOBS = 5 + 4  # the 2D samples and each profile on the first relief; the other reliefs in the slow tier


SLOW_CASES = {
    'test_rs274_accepts_export_and_carves_the_same[disc.png-/profiles/pyramid.png]',
      # the fast tier keeps the other cases of these tests (tests/conftest.py)
    'test_rs274_accepts_export_and_carves_the_same[disc.png-/profiles/flat.png]',
    'test_rs274_accepts_export_and_carves_the_same[disc.png-/profiles/dome.png]',
}


def test_header_units_feeds_and_end():
    d = cam.digitize(drawing_from_rows(["......", ".##...", "......"]))
    g = to_gcode(cam.plan(d, depth=3))
    lines = g.splitlines()
    assert "G21 G90 G17 G94" in lines and lines[-1] == "M2"
    assert "Y = -row" in g
    xy, z = feeds_mm_per_min(cam.MachineSettings())
    assert xy == pytest.approx(0.0289 / 0.005 * 60) and z == pytest.approx(0.0157 / 0.005 * 60)
    assert "G1 X0.4624 Y-0.2312 F346.8" in lines  # pixel (2, 1) at 8 steps/px x 0.0289 mm
    assert "G1 Z-0.0471 F188.4" in lines          # 3 Z px x 0.0157 mm
    assert "G1 X0.4624 Y0.2312 F346.8" in to_gcode(cam.plan(d, depth=3), flip_y=True)


@needs_rs274
@pytest.mark.parametrize("name, options", [j if i < FAST_JOBS else pytest.param(*j, marks=pytest.mark.slow)
                                           for i, j in enumerate(JOBS)], ids=[f"{n}-{o.get('profile', '2d')}".replace(str(ROOT), "") for n, o in JOBS])
def test_rs274_accepts_export_and_carves_the_same(tmp_path, name, options):
    d = cam.digitize(cam.load_image(SAMPLES / name))
    if "profile" in options:
        options = {**options, "profile": cam.load_profile(options["profile"])}
    job = cam.plan(d, **options)
    path = tmp_path / "job.ngc"
    cam.save_gcode(job, path)
    moves = parse_canonical(run_rs274(str(path)))
    assert any(m.kind == "feed" for m in moves)
    theirs = carve_canonical(moves, (d.height_px, d.width_px), job.settings)
    ours, _, _ = carve_job(job)
    assert_surface_equal(theirs, ours)


@needs_rs274
def test_flip_y_mirrors(tmp_path):
    d = cam.digitize(cam.load_image(SAMPLES / "word.png"))
    job = cam.plan(d, depth=3)
    (tmp_path / "f.ngc").write_text(to_gcode(job, flip_y=True))
    theirs = carve_canonical(parse_canonical(run_rs274(str(tmp_path / "f.ngc"))), (d.height_px, d.width_px),
                             job.settings, flip_y=True)
    ours, _, _ = carve_job(job)
    assert_surface_equal(theirs, ours)


def test_tool_changes_are_t_m6_with_comment():
    d = cam.digitize(drawing_from_rows(["......", ".##...", "......", "...##.", "......"]))
    job = cam.plan(d, depth=[2, 3])
    g = to_gcode(job, tool_changes={0: (1, "0.8 mm drill"), 4: (2, "1.0 mm drill")})
    lines = g.splitlines()
    assert "T1 M6 (0.8 mm drill)" in lines and "T2 M6 (1.0 mm drill)" in lines
    # the tool is above the surface at each change
    i = lines.index("T2 M6 (1.0 mm drill)")
    assert lines[i - 1].startswith("G0 Z")
