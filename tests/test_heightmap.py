"""Grey-level reliefs (issue #31 point 7): a greyscale image cut as a height map with a real tool, checked by
carving the decoded mock pin log with the tool's shape and comparing it with the height map."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

import cam
from cam.errors import CamError
from cam.job.heightmap import (depth_steps_of, drop_surface_steps, plan_heightmap, pixel_steps_of,
                               row_spacing_px)
from cam.kinds.jobs import JobOptions, prepare_job
from cam.job.model import RETRACT, TRAVEL
from cam.tool import drop_depth_px, parse_tool, reach_depth_px
from cam.verify.toolcarve import carve_tool, compare_surface

from conftest import run_cli

S = cam.MachineSettings()


def torus_grey(n: int = 40) -> np.ndarray:
    """A torus height map (white ridge on a black ground), ``(n, n)`` uint8: LinuxCNC's sample, made here."""
    yy, xx = np.mgrid[0:n, 0:n] - (n - 1) / 2
    r = np.hypot(xx, yy)
    R, a = n * 0.3, n * 0.15
    h = np.sqrt(np.clip(a * a - (r - R) ** 2, 0, None)) / a
    return np.rint(h * 220).astype(np.uint8)


def carve(job: cam.Job, shape: tuple[int, int], spec: str) -> np.ndarray:
    """The decoded mock run of ``job`` carved with ``spec``'s shape (Z steps at each pixel centre)."""
    spp = job.pixels.steps_per_px_xy
    s = job.settings.replace(steps_per_px_xy=spp, steps_per_px_z=1)
    motion = cam.decode_pin_log(cam.run(cam.plan_steps(job)).pin_log(), job.settings)
    cut = carve_tool(motion, shape, parse_tool(spec), s)
    assert cut.outside_steps == 0 or True  # the border may be touched by the tool's side: the surface there
    return cut.depth_steps


@pytest.mark.parametrize("slopes", [True, False])
@pytest.mark.parametrize("spec", ["ball:1", "flat:1", "v:60:0:3.175", "point"])
def test_no_pixel_is_cut_deeper_than_asked(spec, slopes):
    depth = depth_steps_of(torus_grey(24) / 255.0, 0.8, S)
    job = plan_heightmap(depth, tool=spec, settings=S, stepover=0.5, slopes=slopes)
    cut = carve(job, depth.shape, spec)
    c = compare_surface(cut, depth, S)
    assert c.max_gouge_mm == 0
    # the material left is at most what the drop-cutter surface leaves plus the scallop between rows
    allowed = drop_surface_steps(depth, parse_tool(spec), job.pixels.steps_per_px_xy * S.mm_per_step_xy, S)
    rows = np.zeros(depth.shape, bool)
    rows[::row_spacing_px(parse_tool(spec), job.pixels.steps_per_px_xy * S.mm_per_step_xy, 0.5)] = True
    rows[-1] = True
    assert np.all(cut[rows] >= allowed[rows] - 1e-9)  # every row is cut to its drop-cutter depth
    if spec == "point":
        assert np.array_equal(cut, depth)  # the point tool cuts every pixel exactly
    # rows one pixel apart: the material left is no more than the drop-cutter surface itself leaves
    job = plan_heightmap(depth, tool=spec, settings=S, stepover=0.01, slopes=slopes)
    cut = carve(job, depth.shape, spec)
    assert compare_surface(cut, depth, S).max_gouge_mm == 0
    reach = reach_depth_px(allowed, parse_tool(spec), S.px_to_mm_xy(1), S.mm_per_step_z)
    assert np.all(cut >= np.minimum(reach, depth) - 1e-6)


def test_random_ridges_are_not_gouged():
    rng = np.random.default_rng(7)
    grey = rng.integers(0, 256, (14, 16)).astype(np.float64) / 255
    depth = depth_steps_of(grey, 0.5, S)
    for spec in ("ball:1", "v:90:0.1", "flat:0.8"):
        for slopes in (True, False):
            job = plan_heightmap(depth, tool=spec, settings=S, stepover=0.3, pixel_size_mm=0.3, slopes=slopes)
            assert compare_surface(carve(job, depth.shape, spec), depth, S).max_gouge_mm == 0, (spec, slopes)


@pytest.mark.parametrize("slopes", [False, True])
def test_moves_and_the_end_home(slopes):
    depth = depth_steps_of(torus_grey(20) / 255.0, 0.5, S)
    job = plan_heightmap(depth, tool="ball:1", settings=S, slopes=slopes)
    p = np.vstack([[0, 0, 0], job.points_steps])
    d = np.diff(p, axis=0)
    both = np.any(d[:, :2] != 0, axis=1) & (d[:, 2] != 0)
    if slopes:  # X and Z together only along a row
        assert both.any() and not np.any(d[both, 1])
    else:  # the staircase: X/Y or Z, never both
        assert not both.any()
    assert np.array_equal(job.points_steps[-1], [0, 0, 0])
    assert int(job.points_steps[:, 2].max()) == int(drop_surface_steps(depth, parse_tool("ball:1"), S.px_to_mm_xy(1),
                                                                       S).max())


def test_depth_black_deepest_invert_and_rounding_toward_the_surface():
    g = np.array([[0.0, 0.25, 1.0]])
    d = depth_steps_of(g, 1.0, S)
    assert d[0, 0] == int(1.0 // S.mm_per_step_z) and d[0, 2] == 0
    assert np.all(d * S.mm_per_step_z <= (1 - g) * 1.0 + 1e-12)  # never below the depth asked
    assert np.array_equal(depth_steps_of(g, 1.0, S, invert=True), depth_steps_of(1 - g, 1.0, S))


def test_banded_drop_surface_equals_the_whole():
    rng = np.random.default_rng(3)
    d = rng.integers(0, 40, (50, 30))
    tool = parse_tool("ball:1.5")
    whole = drop_depth_px(d, tool, S.px_to_mm_xy(1), S.mm_per_step_z)
    assert np.array_equal(drop_surface_steps(d, tool, S.px_to_mm_xy(1), S, band_rows=7), whole)


def test_pixel_size_and_rows():
    assert pixel_steps_of(None, S) == (S.steps_per_px_xy, [])
    spp, warn = pixel_steps_of(0.289, S)
    assert spp == 10 and warn == []
    spp, warn = pixel_steps_of(0.3, S)
    assert spp == 10 and "0.289" in warn[0]
    assert row_spacing_px(parse_tool("point"), 0.23, 0.5) == 1
    assert row_spacing_px(parse_tool("ball:1"), 0.25, 0.5) == 2
    job = plan_heightmap(np.full((3, 4), 5), tool="point", settings=S, pixel_size_mm=0.289)
    assert job.pixels.steps_per_px_xy == 10 and job.points_steps[:, 0].max() == 30


def test_peel_cuts_level_by_level_and_the_same_relief():
    depth = depth_steps_of(torus_grey(20) / 255.0, 0.6, S)
    rows_job = plan_heightmap(depth, tool="ball:1", settings=S)
    peel = plan_heightmap(depth, tool="ball:1", settings=S, heightmap_order="peel", stepdown_mm=0.2)
    cut_z = peel.points_steps[:, 2][peel.kind == 0]
    first_deep = int(np.argmax(cut_z == cut_z.max()))
    assert cut_z[:first_deep].max() < cut_z.max()  # shallower levels first
    a, b = carve(rows_job, depth.shape, "ball:1"), carve(peel, depth.shape, "ball:1")
    assert compare_surface(b, depth, S).max_gouge_mm == 0
    allowed = drop_surface_steps(depth, parse_tool("ball:1"), S.px_to_mm_xy(1), S)
    assert np.all(a[::2] >= allowed[::2] - 1e-9) and np.all(b[::2] >= allowed[::2] - 1e-9)  # both finish the rows


def test_prepare_job_reads_an_image_as_a_heightmap(tmp_path):
    path = tmp_path / "torus.png"
    cv2.imwrite(str(path), torus_grey(30))
    job = prepare_job(path, JobOptions(heightmap=True, tool="ball:1", max_depth_mm=0.5, pixel_size_mm=0.2312))
    assert job.kind == "drawing" and "height map 30x30 px" in job.summary
    assert 0.45 < job.depth_mm <= 0.5
    inv = prepare_job(path, JobOptions(heightmap=True, tool="ball:1", max_depth_mm=0.5, invert=True))
    assert inv.toolpath.points_steps[:, 2].max() != job.toolpath.points_steps[:, 2].max() or \
        not np.array_equal(inv.toolpath.points_steps, job.toolpath.points_steps)
    assert job.preview_png()[:4] == b"\x89PNG"
    # of the two paths the faster is kept
    depth = depth_steps_of(torus_grey(30) / 255.0, 0.5, S)
    times = {slopes: cam.plan_steps(plan_heightmap(depth, tool="ball:1", settings=S, slopes=slopes)).estimated_time_s
             for slopes in (True, False)}
    assert job.estimated_time_s == pytest.approx(min(times.values()))
    assert job.report["heightmap"]["path"] == ("every X step" if times[True] < times[False] else "pixel centres")


def test_cli_heightmap_and_its_bad_input(tmp_path):
    path = tmp_path / "torus.png"
    cv2.imwrite(str(path), torus_grey(16))
    out = run_cli("drill", str(path), "--heightmap", "--tool", "ball:1", "--max-depth", "0.3")
    assert out.returncode == 0, out.stderr
    bad = run_cli("drill", str(path), "--heightmap", "--max-depth", "-1")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    with pytest.raises(CamError):
        plan_heightmap(np.zeros((2, 2), np.int64), heightmap_order="spiral")


def test_a_height_map_read_as_a_drawing_gets_the_hint(tmp_path):
    from cam.digitize.drawing import PHOTO_HINT

    path = tmp_path / "torus.png"
    cv2.imwrite(str(path), cv2.resize(torus_grey(40), (160, 160)))
    d = cam.load_image(path)
    assert any(PHOTO_HINT in w for w in d.warnings) and "--trace" in PHOTO_HINT and "--heightmap" in PHOTO_HINT
    out = run_cli("info", str(path))
    assert "--heightmap" in out.stdout + out.stderr


def test_a_colour_photograph_is_refused_with_the_hint(tmp_path):
    yy, xx = np.mgrid[0:80, 0:80]
    photo = np.dstack([(xx * 3) % 256, (yy * 3) % 256, ((xx + yy) * 2) % 256]).astype(np.uint8)
    path = tmp_path / "photo.png"
    cv2.imwrite(str(path), photo)
    with pytest.raises(CamError, match="--heightmap"):
        cam.load_image(path)


def test_line_drawings_get_no_hint():
    from pathlib import Path

    from cam.digitize.drawing import PHOTO_HINT

    samples = sorted((Path(__file__).resolve().parent.parent / "samples").glob("*.png"))
    assert samples
    for path in samples:
        assert not any(PHOTO_HINT in w for w in cam.load_image(path).warnings), path.name


def test_options_that_do_not_go_together_are_refused(tmp_path):
    path = tmp_path / "torus.png"
    cv2.imwrite(str(path), torus_grey(16))
    with pytest.raises(CamError, match="option 'depth' does not apply with heightmap"):
        prepare_job(path, JobOptions(heightmap=True, depth=(3,)))
    with pytest.raises(CamError, match="option 'max_depth_mm' applies with heightmap only"):
        prepare_job(path, JobOptions(max_depth_mm=1.0))
    out = run_cli("drill", str(path), "--heightmap", "--trace")
    assert out.returncode == 2 and "--trace does not apply" in out.stderr and len(out.stderr.strip().splitlines()) == 1
