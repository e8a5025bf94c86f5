"""Sketches and photos to drawings (cam.trace, cam trace): synthetic scans with known centre lines.

Each scan is drawn here: thick anti-aliased strokes on off-white paper, a lighting gradient, noise, saved
as JPEG and read back.  The traced curves must lie within 1.5 pixels of the true centre lines, cover them,
and keep the thesis rules (no pixel with more than two black neighbours, nothing on the border, no stray
pixel); the result must digitize and cut on the mock port.
"""

import cv2
import numpy as np
import pytest
from scipy.spatial import cKDTree

import cam
from cam.digitize.drawing import BLACK, RED, Drawing, check_rules, neighbour_count
from cam.digitize.sketch import TracedDrawing, trace

from conftest import ROOT, run_cli

SUB = 16  # cv2's sub-pixel shift: 4 bits


class Scan:
    """A synthetic scan: strokes drawn at 4x and shrunk (anti-aliased), on lit paper, with noise, as JPEG."""

    def __init__(self, h_px=300, w_px=400, thick_px=5, seed=0):
        self.h, self.w, self.thick, self.rng = h_px, w_px, thick_px, np.random.default_rng(seed)
        self.big = np.full((h_px * 4, w_px * 4), 255, np.uint8)
        self.truth: list[np.ndarray] = []

    def polyline(self, pts, closed=False):
        pts = np.asarray(pts, float)
        p = np.rint(pts * 4 * SUB + 1.5 * SUB).astype(np.int32)  # pixel centres: x4 image pixel (4k + 1.5)
        cv2.polylines(self.big, [p.reshape(-1, 1, 2)], closed, 0, self.thick * 4, cv2.LINE_AA, shift=4)
        if closed:
            pts = np.vstack([pts, pts[:1]])
        for a, b in zip(pts[:-1], pts[1:]):
            n = int(np.hypot(*(b - a)) * 8) + 2
            self.truth.append(a + (b - a) * np.linspace(0, 1, n)[:, None])
        return self

    def circle(self, cx, cy, r):
        t = np.linspace(0, 2 * np.pi, 360, endpoint=False)
        return self.polyline(np.c_[cx + r * np.cos(t), cy + r * np.sin(t)], closed=True)

    def dots(self, n, radius_px=1.5):
        for _ in range(n):
            x, y = self.rng.uniform(10, self.w - 10), self.rng.uniform(10, self.h - 10)
            cv2.circle(self.big, (int(x * 4 * SUB), int(y * 4 * SUB)), int(radius_px * 4 * SUB), 0, -1, cv2.LINE_AA, 4)
        return self

    def image(self, quality=80, noise=5.0, light=(0.6, 1.0), colour=False):
        img = cv2.resize(self.big, (self.w, self.h), interpolation=cv2.INTER_AREA).astype(float) / 255
        paper = 238 * np.linspace(*light, self.w)[None, :] * np.linspace(1.0, 0.85, self.h)[:, None]
        out = paper * (0.12 + 0.88 * img) + self.rng.normal(0, noise, (self.h, self.w))  # graphite is not black
        out = np.clip(out, 0, 255).astype(np.uint8)
        if colour:  # warm paper, bluish ink: a phone photo
            out = np.dstack([out, np.clip(out * 0.97, 0, 255), np.clip(out * 0.9 + 8, 0, 255)]).astype(np.uint8)
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, quality])
        assert ok
        flag = cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE
        img = cv2.imdecode(buf, flag)
        return img[:, :, ::-1].copy() if colour else img

    def centre_lines(self):
        return np.concatenate(self.truth)


def assert_follows_the_sketch(d: Drawing, scan: Scan, coverage=0.95):
    """Every black pixel within 1.5 px of a true centre line; the lines covered; the thesis rules kept."""
    assert check_rules(d.classes) == []
    black = d.classes == BLACK
    assert not (black[0].any() or black[-1].any() or black[:, 0].any() or black[:, -1].any())
    assert neighbour_count(black)[black].max() <= 2
    xy = np.argwhere(black)[:, ::-1].astype(float)
    truth = scan.centre_lines()
    far, _ = cKDTree(truth).query(xy)
    assert far.max() <= 1.5, f"a traced pixel lies {far.max():.2f} px from the centre lines at {xy[np.argmax(far)]}"
    near, _ = cKDTree(xy).query(truth)
    assert (near <= 1.5).mean() >= coverage, f"only {(near <= 1.5).mean():.1%} of the centre lines traced"


def shapes(seed=0, thick=5):
    return (Scan(seed=seed, thick_px=thick).circle(110, 150, 60)
            .polyline([(220, 60), (360, 60), (360, 240), (220, 240)], closed=True)
            .polyline([(230, 272), (380, 282)]))


@pytest.mark.parametrize("seed, thick, quality", [(0, 5, 80), (1, 3, 70), (2, 8, 90)])
def test_synthetic_scans_trace_to_their_centre_lines(seed, thick, quality):
    scan = shapes(seed, thick)
    d = trace(scan.image(quality=quality))
    assert isinstance(d, Drawing) and isinstance(d, TracedDrawing)
    assert d.curves == 3 and d.junctions_split == 0
    assert_follows_the_sketch(d, scan)


@pytest.mark.parametrize("thick", [10, 12])
@pytest.mark.parametrize("quality", [70, 90])
def test_thick_strokes_keep_their_square_corners(thick, quality):
    """Thinning rounds a thick stroke's corner (2.24 px inside the drawn corner before corners were redrawn,
    issue #32 point 9): every point of the centre lines, corners included, has a traced pixel within 2 px."""
    scan = shapes(1, thick)
    d = trace(scan.image(quality=quality))
    assert d.curves == 3
    black = d.classes == BLACK
    xy = np.argwhere(black)[:, ::-1].astype(float)
    truth = scan.centre_lines()
    near, _ = cKDTree(xy).query(truth)
    far, _ = cKDTree(truth).query(xy)
    worst = truth[np.argmax(near)]
    assert near.max() <= 2.0, f"the centre line at {worst} is {near.max():.2f} px from the trace"
    assert far.max() <= 1.5 and neighbour_count(black)[black].max() <= 2 and check_rules(d.classes) == []


def test_a_phone_photo_in_colour_with_strong_shading():
    scan = shapes(3)
    d = trace(scan.image(colour=True, light=(0.45, 1.0), noise=7))
    assert d.curves == 3
    assert_follows_the_sketch(d, scan)


def test_specks_are_removed_and_counted():
    scan = shapes(4).dots(12)
    d = trace(scan.image())
    assert d.specks_removed >= 10 and d.curves == 3
    assert_follows_the_sketch(d, scan)


def test_junctions_are_split_so_no_pixel_has_three_neighbours():
    scan = (Scan(seed=5).polyline([(40, 150), (360, 150)])       # a T: the bar stays whole
            .polyline([(200, 150), (200, 40)])
            .polyline([(240, 290), (330, 200)]).polyline([(240, 200), (330, 290)]))  # an X
    d = trace(scan.image())
    assert d.junctions_split >= 2
    assert_follows_the_sketch(d, scan, coverage=0.9)
    black = d.classes == BLACK
    assert black[150, 50:350].all() or black[149:152, 50:350].any(axis=0).all()  # the bar continues


def test_fill_makes_a_3d_drawing_that_digitizes():
    scan = Scan(seed=6).circle(100, 150, 70).polyline([(220, 60), (360, 60), (360, 240), (220, 240)], closed=True)
    d = trace(scan.image(), trace_fill=True)
    assert d.regions_filled == 2 and d.kind == "3d"
    assert (d.classes == RED).sum() > 0.8 * (np.pi * 68 ** 2 + 138 * 178)
    digitized = cam.digitize(d)
    assert digitized.mode == "3d" and len(digitized.objects) >= 2


def test_traced_drawing_cuts_on_the_mock_port(tmp_path):
    scan = shapes(7)
    d = trace(scan.image())
    digitized = cam.digitize(d)
    assert len(digitized.objects) == 3
    job = cam.plan(digitized, depth=2)
    result = cam.run(job)
    surface = cam.carve(cam.decode_pin_log(result.pin_log()), (d.height_px, d.width_px))
    assert np.array_equal(surface > 0, d.classes == BLACK)


def test_blank_paper_gives_an_empty_drawing():
    img = Scan(seed=8).image(noise=6)
    d = trace(img)
    assert d.curves == 0 and not (d.classes == BLACK).any()


def test_large_photos_are_shrunk_first():
    scan = shapes(9)
    img = cv2.resize(scan.image(), (1600, 1200), interpolation=cv2.INTER_CUBIC)
    d = trace(img, max_side_px=400)
    assert (d.width_px, d.height_px) == (400, 300) and d.shrink == 0.25
    assert_follows_the_sketch(d, scan, coverage=0.9)


@pytest.mark.parametrize("image, kw, match", [
    (np.zeros((4, 4), np.uint8), {}, "too small"),
    (np.zeros((20, 20, 2), np.uint8), {}, "image array"),
    (np.zeros((20, 20), np.uint8), {"trace_min_length_px": 1}, "trace_min_length_px must be 2..10000"),
    (np.zeros((20, 20), np.uint8), {"trace_min_length_px": 10_001}, "trace_min_length_px must be 2..10000"),
])
def test_bad_input_is_a_drawing_error(image, kw, match):
    with pytest.raises(cam.DrawingError, match=match):
        trace(image, **kw)


def test_notebook_api():
    d = cam.trace(shapes(10).image())
    assert d._repr_png_()[:4] == b"\x89PNG" and "3 curve(s)" in d.summary()


def cli(*args):
    """``cam ARGS`` in this process (conftest.run_cli)."""
    return run_cli(*args)


def test_cli_trace_then_drill(tmp_path):
    photo = tmp_path / "sketch.jpg"
    cv2.imwrite(str(photo), shapes(11).dots(5).image())
    out = cli("trace", str(photo), "-o", str(tmp_path / "drawing.png"), "--trace-min-length", "8")
    assert out.returncode == 0, out.stderr
    assert "3 curve(s)" in out.stdout and "speck(s)" in out.stdout and "junction(s) split" in out.stdout
    drill = cli("drill", str(tmp_path / "drawing.png"), "--depth", "2")
    assert drill.returncode == 0 and "3 object(s)" in drill.stdout
    assert cli("trace", str(photo), "-o", str(tmp_path / "d3.png"), "--trace-fill").returncode == 0
    assert cli("drill", str(tmp_path / "d3.png"), "--profile-expr", "2").returncode == 0


def test_cli_trace_keeps_its_old_flags_hidden(tmp_path):
    """--min-length and --fill, the old spellings of trace's --trace-min-length and --trace-fill, still work but
    are not in --help (one name per setting there)."""
    photo = tmp_path / "sketch.png"
    cv2.imwrite(str(photo), shapes(11).image())
    new = cli("trace", str(photo), "-o", str(tmp_path / "a.png"), "--trace-min-length", "8", "--trace-fill")
    old = cli("trace", str(photo), "-o", str(tmp_path / "b.png"), "--min-length", "8", "--fill")
    assert new.returncode == old.returncode == 0, (new.stderr, old.stderr)
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    help_text = cli("trace", "--help").stdout
    assert "--trace-min-length" in help_text and "--trace-fill" in help_text
    assert "--min-length" not in help_text.replace("--trace-min-length", "")
    assert "--fill" not in help_text.replace("--trace-fill", "")


@pytest.mark.parametrize("args, fragment", [
    (["missing.jpg", "-o", "d.png"], "not found"),
    (["{photo}", "-o", "d.jpg"], "must end in"),
    (["{photo}", "-o", "d.png", "--trace-min-length", "1"], "--trace-min-length must be 2..10000"),
    (["{photo}", "-o", "d.png", "--min-length", "10001"], "--trace-min-length must be 2..10000"),
])
def test_cli_bad_input_is_one_line(tmp_path, args, fragment):
    photo = tmp_path / "s.png"
    cv2.imwrite(str(photo), shapes(12).image())
    args = [a.format(photo=photo) if "{" in a else (str(tmp_path / a) if a.startswith("d.") else a) for a in args]
    out = cli("trace", *args)
    assert out.returncode == 2 and fragment in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_drill_trace_option_plans_what_trace_then_drill_plans(tmp_path):
    """``cam drill PHOTO --trace`` (and JobOptions.trace) is ``cam trace`` then ``cam drill`` in one step."""
    from cam.digitize.sketch import load_sketch, trace
    from cam.kinds.jobs import JobOptions, prepare_job

    sketch = ROOT / "samples" / "sketch.jpg"
    job = prepare_job(sketch, JobOptions(depth=(2,), trace=True, trace_min_length_px=12), cam.MachineSettings())
    drawing = trace(load_sketch(sketch), trace_min_length_px=12, source=str(sketch))
    expected = cam.plan_steps(cam.plan(cam.digitize(drawing), depth=2, settings=cam.MachineSettings()))
    assert np.array_equal(job.steps.data, expected.data)
    assert any("traced:" in w for w in job.warnings)
    ok = cli("drill", str(sketch), "--trace", "--depth", "2", "--no-progress")
    assert ok.returncode == 0, ok.stderr
    bad = cli("drill", str(ROOT / "samples" / "board.drl"), "--trace")
    assert bad.returncode == 2 and "--trace does not apply" in bad.stderr
