"""G-code out with a real tool (issue #19): the program names the tool, and LinuxCNC's interpreter (rs274) runs a
path that, carved with the same tool, is the surface `cam`'s own mock run carves."""
import os
import shutil

import numpy as np
import pytest

import cam
from cam.kinds.gcode_export import to_gcode
from cam.tool import parse_tool
from cam.verify.toolcarve import carve_tool, compare_surface
from support.lcnc import canonical_motion, canonical_time_s, parse_canonical, run_rs274

from conftest import ROOT, SAMPLES, carve_job, drawing_from_rows

SLOW_CASES = {'test_rs274_path_carved_with_the_tool_equals_cams_carve[disc.png-dome.png-ball:1]'}
"""Cases run in the slow tier only (tests/conftest.py): the fast tier stays under 3 minutes."""

needs_rs274 = pytest.mark.skipif(
    shutil.which("rs274") is None and not os.environ.get("CI"), reason="rs274 (linuxcnc-uspace) not installed"
)

TOOLS = ["ball:1", "flat:1", "v:60:0.1"]
RELIEFS = [("disc.png", "dome.png"), ("pyramid.png", "cone.png"), ("ring.png", "pyramid.png")]


def _relief(drawing: str, profile: str) -> tuple[cam.Digitized, cam.Profile]:
    return cam.digitize(cam.load_image(SAMPLES / drawing)), cam.load_profile(ROOT / "profiles" / profile)


def _target_steps(d: cam.Digitized, profile: cam.Profile) -> np.ndarray:
    """The relief asked for, Z steps at each pixel centre: the point tool's plan carved (the point planner cuts
    every pixel exactly to its asked depth, a property its own tests check)."""
    surface, _, _ = carve_job(cam.plan(d, profile=profile))
    return surface


def test_point_tool_program_names_no_tool():
    d = cam.digitize(drawing_from_rows(["......", ".##...", "......"]))
    g = to_gcode(cam.plan(d, depth=3))
    assert "tool:" not in g and "M6" not in g


@pytest.mark.parametrize("spec, comment", [("ball:1", "ball 1 mm"), ("flat:1", "flat 1 mm"),
                                           ("v:60:0.1", "V 60 deg, tip 0.1 mm, 3.175 mm shank")])
def test_program_carries_t_and_the_tool_comment(spec, comment):
    d, prof = _relief("disc.png", "dome.png")
    job = cam.plan(d, profile=prof, tool=spec)
    lines = to_gcode(job).splitlines()
    assert f"(tool: {comment}, spec {parse_tool(spec).spec()}; Z is its tip)" in lines
    change = lines.index(f"T1 M6 ({comment})")
    first_move = next(i for i, ln in enumerate(lines) if ln.startswith(("G0", "G1")))
    assert change < first_move and lines.index("G21 G90 G17 G94") < change


def test_explicit_tool_changes_replace_the_job_tool():
    d, prof = _relief("disc.png", "dome.png")
    job = cam.plan(d, profile=prof, tool="ball:1")
    lines = to_gcode(job, tool_changes={0: (3, "3 mm drill")}).splitlines()
    assert "T3 M6 (3 mm drill)" in lines and not any(ln.startswith("T1") for ln in lines)


def test_cli_export_writes_the_tool(tmp_path):
    from cam.cli import main

    out = tmp_path / "disc.ngc"
    assert main(["export", str(SAMPLES / "disc.png"), "--profile", str(ROOT / "profiles" / "dome.png"),
                 "--tool", "ball:1", "-o", str(out)]) == 0
    text = out.read_text()
    assert "(tool: ball 1 mm, spec ball:1; Z is its tip)" in text and "T1 M6 (ball 1 mm)" in text


@needs_rs274
@pytest.mark.parametrize("drawing, profile, spec", [
    # the ball on the dome in the fast tier; every other pair in the slow one
    pytest.param(d, p, t, marks=() if i == j == 0 else pytest.mark.slow)
    for i, (d, p) in enumerate(RELIEFS) for j, t in enumerate(TOOLS)
])
def test_rs274_path_carved_with_the_tool_equals_cams_carve(tmp_path, drawing, profile, spec):
    """rs274's canonical feed moves become the step positions a stepper passes through (every G-code coordinate
    `cam` writes is a whole number of steps, checked; its cutting moves are along an axis or at 45 degrees, so
    the positions between are those of the DDA the step plan uses).  Both sets of positions are carved with the
    same :func:`carve_tool`, so the surfaces must agree to rounding: the tolerance is 1e-9 Z steps, far under
    the half step at which a carve would read a different step."""
    tool = parse_tool(spec)
    d, prof = _relief(drawing, profile)
    job = cam.plan(d, profile=prof, tool=tool)
    path = tmp_path / "relief.ngc"
    cam.save_gcode(job, path)
    text = path.read_text()
    assert "T1 M6" in text and f"(tool: {tool.describe()}" in text
    moves = parse_canonical(run_rs274(str(path)))
    theirs_motion = canonical_motion(moves, job.settings, exact=True)
    shape = (job.height_px, job.width_px)
    theirs = carve_tool(theirs_motion, shape, tool, job.settings, origin_px=job.origin_px)

    result = cam.run(job)
    motion = cam.decode_pin_log(result.pin_log(), job.settings)
    ours = carve_tool(motion, shape, tool, job.settings, origin_px=job.origin_px)

    # the same step positions below the surface, in both
    below = lambda p: {tuple(q) for q in p[p[:, 2] > job.origin_px[2] * job.settings.steps_per_px_z].tolist()}
    assert below(theirs_motion.position_steps) == below(motion.position_steps)
    assert ours.depth_steps.max() > 0
    np.testing.assert_allclose(theirs.depth_steps, ours.depth_steps, rtol=0, atol=1e-9)
    assert theirs.outside_steps == pytest.approx(ours.outside_steps, abs=1e-9)
    # and the cut never goes below the relief (the drop-cutter rule), through LinuxCNC too
    target = _target_steps(d, prof)
    assert compare_surface(theirs.depth_steps, target, job.settings).max_gouge_mm == 0


def test_canonical_time_is_the_longest_axis_at_its_speed():
    s = cam.MachineSettings()
    from support.lcnc import CanonMove

    moves = [CanonMove("feed", (5.78, 0.0, 0.0)), CanonMove("traverse", (5.78, 5.78, -3.14)),
             CanonMove("feed", (0.0, 0.0, 0.0))]
    assert canonical_time_s(moves, s) == pytest.approx(1.0 + 1.0 + 1.0)


needs_itg = pytest.mark.skipif(not (os.path.exists("/usr/bin/image-to-gcode") and shutil.which("rs274")),
                               reason="image-to-gcode or rs274 (linuxcnc-uspace) not installed")


@needs_itg
@pytest.mark.slow
def test_image_to_gcode_frame_meets_cams(tmp_path):
    """The benchmark's image-to-gcode frame: its cut of a dome with a ball 1 mm lies on the target (gouge and rest
    within a couple of Z steps), and the same path moved by one pixel either way cuts far more wrongly -- so the
    comparison is not off by a pixel."""
    import sys

    sys.path.insert(0, str(ROOT / "benchmarks"))
    import tools_vs_i2g as bench

    s = cam.MachineSettings()
    d, prof = _relief("disc.png", "dome.png")
    target = bench.target_steps(d, prof, s)
    assert np.array_equal(target, _target_steps(d, prof))
    tool = parse_tool("ball:1")
    on = bench.cut_by_itg(target, tool, 0, 1.0, s, tmp_path)
    assert on.max_gouge_mm <= 2 * s.mm_per_step_z and on.rest_mean_mm < 0.1 * s.mm_per_step_z
    for shift in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        off = bench.cut_by_itg(target, tool, 0, 1.0, s, tmp_path, shift_px=shift)
        assert off.max_gouge_mm > 2 * on.max_gouge_mm and off.rest_mean_mm > 5 * on.rest_mean_mm, shift
    ours = bench.cut_by_cam(d, prof, tool, target, s)
    assert ours.max_gouge_mm == 0 and ours.time_s < on.time_s


@needs_itg
@pytest.mark.slow
def test_benchmark_rows_print(tmp_path):
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "run.py"), "--quick", "--only", "17"],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = [ln for ln in proc.stdout.splitlines() if ln.startswith("| tool ")]
    assert len(rows) == 6  # the quick reliefs (the 128^2 dome, disc + dome) x ball, flat, V
    assert all("max gouge 0.00 vs" in r for r in rows)  # cam never gouges
