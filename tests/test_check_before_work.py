"""Check before work (part of #20): image sizes are read from the file's header and refused before decoding, a
drawing too large for the travel is refused before it is traced, and a job that leaves the travel before it is
routed.  Behaviour is asserted (nothing decoded, traced or routed, memory bounded), never time."""
import importlib
import struct
import subprocess
import sys
import zlib

import cv2
import numpy as np
import pytest

import cam
from cam.digitize import drawing as drawing_module
from cam.digitize.image_size import image_size_px
from cam.motion.chunks import plan_chunks
from cam.job import drawing as planner
from cam.job.drawing import check_drawing_size, max_drawing_size_px
from cam.kinds.jobs import JobOptions, prepare_job

from conftest import SAMPLES, drawing_from_rows
from test_cli_checks import ENV, cli, refused


def png_header(width, height):
    """A PNG of only its signature and header chunk: it states a size and holds no pixel."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))


def checkerboard(n):
    yy, xx = np.indices((n, n))
    return np.where((xx + yy) % 2 == 0, 0, 255).astype(np.uint8)


# -- image sizes from headers ------------------------------------------------------------------------------------

@pytest.mark.parametrize("ext, params", [
    (".png", []), (".jpg", []), (".jpg", [cv2.IMWRITE_JPEG_PROGRESSIVE, 1]), (".bmp", []), (".tif", []),
    (".tiff", [cv2.IMWRITE_TIFF_COMPRESSION, 1]),
])
@pytest.mark.parametrize("shape", [(1, 1), (3, 7), (158, 300), (17, 1000, 3), (5, 9, 4)])
def test_the_header_size_is_the_decoded_size(ext, params, shape):
    if ext == ".jpg" and len(shape) == 3 and shape[2] == 4:
        pytest.skip("JPEG has no alpha")
    img = np.random.default_rng(1).integers(0, 255, shape, dtype=np.uint8)
    ok, buf = cv2.imencode(ext, img, params)
    assert ok
    decoded = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    assert image_size_px(buf.tobytes()) == (decoded.shape[1], decoded.shape[0])


def test_sizes_of_bytes_that_are_no_known_header():
    assert image_size_px(png_header(16000, 9000)) == (16000, 9000)
    assert image_size_px(b"GIF89a" + bytes(20)) is None
    assert image_size_px(png_header(5, 5)[:20]) is None  # cut before the size
    assert image_size_px(b"\xff\xd8\xff\xe0\x00\x10JFIF\x00") is None  # a JPEG cut before its frame
    assert image_size_px(b"") is None


def test_a_huge_image_is_refused_from_its_header_before_it_is_decoded(tmp_path, monkeypatch):
    path = tmp_path / "huge.png"
    path.write_bytes(png_header(16000, 16000))
    monkeypatch.setattr(drawing_module.cv2, "imdecode", lambda *a: pytest.fail("the image was decoded"))
    with pytest.raises(cam.DrawingError, match=r"huge\.png: the image is 16000x16000 px; a drawing may have at most "
                                               r"32768 px on a side and 16777216 px in all"):
        cam.load_image(path)
    path.write_bytes(png_header(40000, 10))
    with pytest.raises(cam.DrawingError, match="40000x10 px"):
        cam.load_image(path)
    assert drawing_module.drawing_size_px(path) == (40000, 10)


@pytest.mark.slow
def test_a_16000_square_png_is_refused_in_bounded_memory(tmp_path):
    """A 270 KB PNG of 16000 x 16000 zeros ended in MemoryError (and 8000 x 8000 took 1.7 GB): refused from its
    header under a 1 GiB address-space limit, by the library and by every command that reads a drawing."""
    path = tmp_path / "zeros.png"
    assert cv2.imwrite(str(path), np.zeros((16000, 16000), np.uint8))
    assert path.stat().st_size < 400_000
    code = (
        "import resource, sys\n"
        "resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
        "import cam\n"
        "try:\n"
        "    cam.load_image(sys.argv[1])\n"
        "except cam.DrawingError as exc:\n"
        "    print(exc)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, env=ENV,
                          timeout=300)
    assert proc.returncode == 0 and "the image is 16000x16000 px" in proc.stdout, proc.stderr[-2000:]
    for command in (["info", path], ["digitize", path, "-o", tmp_path / "m.txt"], ["drill", path, "--no-progress"],
                    ["preview", path, "-o", tmp_path / "p.png"], ["export", path, "-o", tmp_path / "o.ngc"]):
        refused(cli(*command), "zeros.png", "16000x16000 px")
    refused(cli("drill", SAMPLES / "heart.png", "--profile", path, "--no-progress"), "zeros.png", "16000x16000")
    assert not any((tmp_path / name).exists() for name in ("m.txt", "p.png", "o.ngc"))


def test_an_image_whose_size_cannot_be_read_is_refused(tmp_path):
    path = tmp_path / "anim.png"
    path.write_bytes(b"GIF89a" + bytes(100))
    with pytest.raises(cam.DrawingError, match=r"anim\.png: not a readable image .*PNG, JPEG, BMP, TIFF"):
        cam.load_image(path)


# -- drawings too large for the travel: refused before tracing ----------------------------------------------------

def test_the_largest_drawing_follows_the_travel_and_the_steps_per_pixel():
    s = cam.MachineSettings()
    assert max_drawing_size_px(s) == (1251, 1251)  # 10000 steps at 8 steps per pixel: pixels 0..1250
    wide = s.replace(steps_per_px_xy=1, travel=cam.settings.Travel(-500, 2000, 0, 99))
    assert max_drawing_size_px(wide) == (2501, 100)
    check_drawing_size(1251, 1251, s)
    with pytest.raises(cam.TravelError, match=r"d\.png: the drawing is 1252x10 px; at 8 steps per pixel the machine "
                                              r"travel \(X 0\.\.10000, Y 0\.\.10000 steps\) holds at most 1251x1251 px"):
        check_drawing_size(1252, 10, s, "d.png")


def test_a_drawing_too_large_for_the_travel_is_refused_before_it_is_decoded_or_traced(tmp_path, monkeypatch):
    """The 1500 x 1500 checkerboard: routing ran over 600 s before the travel error."""
    path = tmp_path / "board.png"
    cv2.imwrite(str(path), checkerboard(1500))
    # the drawing kind's reader, digitizer and planner (cam.kinds.drawing loads them when it plans)
    reader, digitizer, planner = (importlib.import_module(m) for m in ("cam.digitize.drawing", "cam.digitize",
                                                                        "cam.job.drawing_stream"))
    for module, name in ((reader, "load_image"), (digitizer, "digitize"), (planner, "plan")):
        monkeypatch.setattr(module, name, lambda *a, _name=name, **k: pytest.fail(f"{_name} ran"))
    with pytest.raises(cam.TravelError, match=r"board\.png: the drawing is 1500x1500 px; .* holds at most 1251x1251"):
        prepare_job(path, JobOptions(depth=(3,)))
    # a machine with 2 steps per pixel holds it: then it is decoded (and traced)
    monkeypatch.setattr(reader, "load_image", lambda *a, **k: pytest.fail("decoded, as it should be"))
    with pytest.raises(pytest.fail.Exception, match="decoded, as it should be"):
        prepare_job(path, JobOptions(depth=(3,)), cam.MachineSettings().replace(steps_per_px_xy=2))


def test_cli_refuses_a_drawing_too_large_for_the_travel_in_one_line(tmp_path):
    path = tmp_path / "board.png"
    cv2.imwrite(str(path), checkerboard(1500))
    for command in (["drill", path, "--depth", "3", "--no-progress"], ["export", path, "-o", tmp_path / "o.ngc"],
                    ["preview", path, "-o", tmp_path / "p.png"]):
        refused(cli(*command), "board.png: the drawing is 1500x1500 px", "at most 1251x1251 px")
    # a digitized matrix for an image too large: refused before it is planned
    matrix = tmp_path / "m.txt"
    matrix.write_text("# cam digitized matrix v1\n# mode=2d width_px=2000 height_px=3 objects=1 points=1\n"
                      "object,x,y,level\n1,1,1,1\n")
    refused(cli("drill", "--load-digitized", matrix, "--no-progress"), "m.txt: the drawing is 2000x3 px")


def _refuse_routing(monkeypatch):
    monkeypatch.setattr(planner, "_route", lambda *a, **k: pytest.fail("a job outside the travel was routed"))


def test_a_job_outside_the_travel_is_refused_before_it_is_routed(monkeypatch):
    """word.png bridges two gaps inside the material (the router runs); made wider than the travel by Start At
    (its home is part of it), or on a machine too small for it, it is refused naming the first point that makes it
    too wide, and the router never runs.  A drawing job is planned in its own frame (issue #45 point 4): what fits
    the travel's span is planned, and checked where it is placed when it runs."""
    d = cam.digitize(cam.load_image(SAMPLES / "word.png"))
    assert cam.plan(d, depth=3).n_targets  # fits: routed as usual
    _refuse_routing(monkeypatch)
    first = r"job leaves the machine travel at point 0 \(x=1259, y=24, z=0 px = 10072, 192, 0 steps\): X travel"
    with pytest.raises(cam.TravelError, match=first):
        cam.plan(d, depth=3, start_at=(1200, 0, 0))
    with pytest.raises(cam.TravelError, match=r"X travel is 0\.\.800 steps"):
        cam.plan(d, depth=3, settings=cam.MachineSettings().replace(travel=cam.settings.Travel(x_max_steps=800)))
    with pytest.raises(cam.TravelError, match=r"Z travel is -640\.\.2000 steps .* and the job spans Z 0\.\.2641"):
        cam.plan(d, depth=2641)  # 2001 fits the 2640 steps of Z travel: placed at a work zero above the home plane
    with pytest.raises(cam.TravelError, match=r"point 0 \(x=0, y=0, z=-2641 px"):  # the safe plane: too high
        cam.plan(d, depth=3, start_at=(0, -3, -2641),
                 settings=cam.MachineSettings().replace(travel=cam.settings.Travel(y_min_steps=-100)))


def test_the_extent_check_agrees_with_the_travel_check():
    """Over Start At offsets around a small travel's edges: the planner's extent check lets through exactly the jobs
    whose extent, the home included, fits the travel's span (the planner asserts it; a drawing job is planned in
    its own frame, issue #45 point 4); run from the home (the step planner), every job with a point outside the
    travel is refused naming a point outside it, and every other job is planned."""
    d = cam.digitize(drawing_from_rows(["..........", ".###...##.", "....#.#...", ".....#....", ".#######.."]))
    settings = cam.MachineSettings().replace(
        steps_per_px_xy=2, travel=cam.settings.Travel(-30, 30, -20, 24, -6, 9))
    lo = np.array([b[0] for b in settings.travel.bounds_steps()])
    hi = np.array([b[1] for b in settings.travel.bounds_steps()])
    planned = refusals = too_wide = 0
    for ox in range(-36, 12, 3):
        for oy in range(-13, 10, 2):
            for oz in (-7, -1, 0, 3):
                try:
                    job = cam.plan(d, depth=[3, 5, 2], start_at=(ox, oy, oz), settings=settings)
                except cam.TravelError as exc:
                    assert "wherever it is placed" in str(exc), str(exc)
                    too_wide += 1
                    continue
                pts = np.vstack([job.points_steps, np.zeros((1, 3), np.int64)])  # the home is part of the job
                assert np.all(pts.max(axis=0) - pts.min(axis=0) <= hi - lo)
                planned += 1
                try:
                    plan_chunks(job)  # run from the home
                except cam.TravelError as exc:
                    steps = [int(v) for v in str(exc).split(" px = ")[1].split(" steps")[0].split(", ")]
                    assert np.any((steps < lo) | (steps > hi)), str(exc)
                    assert np.any((job.points_steps < lo) | (job.points_steps > hi))
                    refusals += 1
                else:
                    assert np.all((job.points_steps >= lo) & (job.points_steps <= hi))
    assert planned > 20 and refusals > 100 and too_wide > 20, (planned, refusals, too_wide)


# -- bridges inside the material: the compiled search finds the plain-Python search's path ------------------------

def test_the_compiled_route_equals_the_reference():
    from support.references import route_reference

    rng = np.random.default_rng(3)
    found = 0
    for _ in range(400):
        h, w = rng.integers(3, 40, 2)
        asked = np.where(rng.random((h, w)) < rng.uniform(0.3, 0.9), rng.integers(1, 4, (h, w)), 0)
        start = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        goal = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        z, max_len = int(rng.integers(1, 4)), int(rng.integers(0, 60))
        got = planner._route(asked, start, goal, z, max_len)
        assert got == route_reference(asked, start, goal, z, max_len), (asked.tolist(), start, goal, z, max_len)
        found += got is not None
    assert 50 < found < 350  # both outcomes seen
    # a checkerboard is one connected material: the path runs along diagonals, the same in both
    board = (checkerboard(61) == 0).astype(np.int64)
    assert planner._route(board, (0, 0), (60, 58), 1, 200) == route_reference(board, (0, 0), (60, 58), 1, 200)


def test_a_drill_depth_outside_the_z_travel_is_refused_before_the_tour(monkeypatch):
    """Placed by its own zero (a machine home): the depths against the Z travel from there.  In its own frame
    (issue #45 point 4): against the Z travel's span (2640 steps), where 40 mm (2548 steps) fits."""
    from cam.job import drill

    holes = cam.parse_excellon("M48\nMETRIC\nT1C0.8\n%\nT1\nX1.0Y-1.0\nX5.0Y-2.0\nX3.0Y-4.0\nM30\n")
    monkeypatch.setattr(drill, "drill_order", lambda *a, **k: pytest.fail("the holes were ordered"))
    with pytest.raises(cam.TravelError, match=r"drill depth 40 mm and safe height 1 mm need Z -64\.\.2548 steps; "
                                              r"the Z travel is -640\.\.2000 steps"):
        cam.plan_drill(holes, cut_depth_mm=40.0, home_steps=(0, 0, 0))
    with pytest.raises(cam.TravelError, match=r"need Z -764\.\.127 steps"):
        cam.plan_drill(holes, travel_height_mm=12.0, home_steps=(0, 0, 0))
    with pytest.raises(cam.TravelError, match=r"drill depth 45 mm and safe height 1 mm need Z -64\.\.2866 steps "
                                              r"\(.* mm\) from the surface, more than the Z travel holds wherever the "
                                              r"work zero is: the Z travel is -640\.\.2000 steps"):
        cam.plan_drill(holes, cut_depth_mm=45.0)
    with pytest.raises(cam.TravelError, match=r"safe height 50 mm need Z -3185\.\.127 steps"):
        cam.plan_drill(holes, travel_height_mm=50.0)
