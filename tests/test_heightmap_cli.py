"""``cam info MAP.json`` and ``cam preview MAP.json [--over FILE]`` (issue #46 point 1): a height map shown.

The map is a tilted and bowed surface on a 10 mm grid over machine X 20..120, Y 20..100 mm; its report's numbers
are checked against the grid's own, its picture's pixels against where the map and the job lie: a high point's
colour differs from a low point's, a probed point is ringed, and a job's cuts are drawn in magenta where its XY lies
when it is placed at the work zero (machine X 30, Y 30 mm) as ``cam drill`` places it."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from cam.choices import is_height_map
from cam.job.heightmap_level import HeightMap, save_height_map
from cam.job.map_picture import CUT_RGB, MARGIN_PX, height_map_picture, map_pixel
from cam.sniff import sniff_height_map
from conftest import one_line_error, ok, run_cli

XS, YS = np.arange(20.0, 121.0, 10.0), np.arange(20.0, 101.0, 10.0)


def surface_mm(x, y):
    return 0.1 + 0.0036 * x - 0.001 * y + 0.2 / (50 ** 2 + 40 ** 2) * ((x - 70) ** 2 + (y - 60) ** 2)


def heights() -> np.ndarray:
    gx, gy = np.meshgrid(XS, YS)
    return surface_mm(gx, gy)


def the_map(tmp_path, name="map.json"):
    return save_height_map(HeightMap(XS, YS, heights(), reference_mm=0.2, spacing_mm=10.0, machine="/m/mill.toml",
                                     time="2026-12-01T10:00:00+00:00"), tmp_path / name)


def read_png(path) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def test_a_height_map_is_recognised_by_its_content(tmp_path):
    path = the_map(tmp_path, "surface.dat")
    assert is_height_map(path) and sniff_height_map(path.read_bytes()[:200])
    assert not sniff_height_map(b'{"x_mm": [0, 1], "cam_height_map": 1}')  # its key first, as cam writes it
    assert not sniff_height_map(b"IN;SP1;PU0,0;PD10,10;") and not is_height_map(tmp_path / "none.json")


def test_info_prints_the_grid_area_heights_and_largest_neighbour_difference(tmp_path):
    path = the_map(tmp_path)
    out = ok(run_cli("info", path)).stdout
    h = heights()
    diff = max(np.abs(np.diff(h, axis=1)).max(), np.abs(np.diff(h, axis=0)).max())
    assert "height map, 11 x 9 points (99) probed every 10 mm" in out
    assert "machine X 20.000..120.000, Y 20.000..100.000 mm (100.00 x 80.00 mm" in out
    assert f"min {h.min():.4f}, max {h.max():.4f}, mean {h.mean():.4f} mm (range {h.max() - h.min():.4f} mm)" in out
    assert f"largest neighbour difference: {diff:.4f} mm" in out
    assert "reference (the work Z zero's surface): 0.2000 mm" in out
    assert "/m/mill.toml" in out and "2026-12-01T10:00:00+00:00" in out


def test_info_json_gives_the_same_numbers(tmp_path):
    path = the_map(tmp_path)
    rep = json.loads(ok(run_cli("info", path, "--json")).stdout)
    h = heights()
    assert rep["kind"] == "height map" and rep["source"] == str(path)
    assert rep["grid"] == [11, 9] and rep["points"] == 99 and rep["spacing_mm"] == 10.0
    assert rep["area_mm"] == [20.0, 20.0, 120.0, 100.0] and rep["size_mm"] == [100.0, 80.0]
    assert rep["height_mm"]["min"] == pytest.approx(h.min(), abs=1e-6)
    assert rep["height_mm"]["max"] == pytest.approx(h.max(), abs=1e-6)
    assert rep["height_mm"]["mean"] == pytest.approx(h.mean(), abs=1e-6)
    along_x = np.abs(np.diff(h, axis=1))
    r, c = np.unravel_index(np.argmax(along_x), along_x.shape)
    assert rep["max_neighbour_diff_mm"] == pytest.approx(along_x.max(), abs=1e-6)  # along X here: the tilt's
    assert rep["between_mm"] == [[XS[c], YS[r]], [XS[c + 1], YS[r]]]
    assert rep["reference_mm"] == 0.2 and rep["machine"] == "/m/mill.toml"


def test_preview_draws_heights_as_colours_and_rings_the_probed_points(tmp_path):
    path = the_map(tmp_path)
    out = tmp_path / "map.png"
    assert "height map picture" in ok(run_cli("preview", path, "-o", out)).stdout
    img = read_png(out)
    k = 8.0  # the map's longer side (100 mm) drawn about 800 pixels wide
    assert img.shape[1] == 801 + 2 * MARGIN_PX
    h = heights()
    hi_r, hi_c = np.unravel_index(np.argmax(h), h.shape)
    lo_r, lo_c = np.unravel_index(np.argmin(h), h.shape)

    def near(x_mm, y_mm):  # a pixel 2 mm in from a grid point, clear of its ring
        c, r = map_pixel(HeightMap(XS, YS, h), [x_mm], [y_mm], k)[0]
        return img[int(r), int(c)].astype(int)

    hi_x, hi_y = XS[hi_c] - 2 * np.sign(XS[hi_c] - 70), YS[hi_r] - 2 * np.sign(YS[hi_r] - 60)
    lo_x, lo_y = XS[lo_c] + 2, YS[lo_r] + 2
    high, low = near(hi_x, hi_y), near(lo_x, lo_y)
    assert np.abs(high - low).sum() > 200, (high, low)  # viridis: yellow high, dark blue low
    assert high[0] > low[0] and high[1] > low[1]  # the high end of the scale is the lighter one
    # the same colours as the picture made in Python (the CLI is a thin adapter)
    assert np.array_equal(img, height_map_picture(HeightMap(XS, YS, h, reference_mm=0.2, spacing_mm=10.0)))
    # each probed point is ringed in black: the ring passes 'ring' pixels right of its centre
    ring = int(round(10 * k / 8))
    for x_mm, y_mm in ((20, 20), (70, 60), (120, 100)):
        c, r = np.rint(map_pixel(HeightMap(XS, YS, h), [x_mm], [y_mm], k)[0]).astype(int)
        assert (img[r, c + ring - 1:c + ring + 2] < 40).all(axis=1).any(), (x_mm, y_mm)


def _work_zero_at_30_30(tmp_path):
    state = tmp_path / "state.json"
    ok(run_cli("goto", "1038,1038,0", "--unit", "steps", "--machine-coords", "--state", state))  # 30.0 mm
    ok(run_cli("zero", "XYZ", "--state", state))
    return state


def test_preview_over_draws_the_jobs_cuts_where_cam_drill_would_cut_them(tmp_path):
    path = the_map(tmp_path)
    state = _work_zero_at_30_30(tmp_path)
    plt = tmp_path / "iso.plt"
    plt.write_text("IN;SP1;PU0,0;PD3200,0,3200,2400,0,2400,0,0;PU;SP0;")  # an 80 x 60 mm outline
    out = tmp_path / "over.png"
    said = ok(run_cli("preview", path, "--over", plt, "-o", out, "--state", state)).stdout
    assert "iso.plt over it" in said and "outside" not in said
    img = read_png(out)
    m = HeightMap(XS, YS, heights())

    def colour(x_mm, y_mm):
        c, r = np.rint(map_pixel(m, [x_mm], [y_mm], 8.0)[0]).astype(int)
        return tuple(int(v) for v in img[r, c])

    # placed by its upper-left corner at the work zero: machine X 30..110, Y 30..90 (+Y toward the operator)
    for x_mm, y_mm in ((55, 30), (95, 90), (30, 45), (110, 75), (30, 30), (110, 90)):
        assert colour(x_mm, y_mm) == CUT_RGB, (x_mm, y_mm)
    for x_mm, y_mm in ((55, 34), (70, 60), (26, 45), (114, 75), (115, 95)):
        assert colour(x_mm, y_mm) != CUT_RGB, (x_mm, y_mm)
    # the job moved elsewhere by another --origin is drawn elsewhere
    out2 = tmp_path / "centre.png"
    ok(run_cli("preview", path, "--over", plt, "--origin", "center", "-o", out2, "--state", state))
    assert not np.array_equal(read_png(out2), img)


def test_preview_over_a_drill_file_marks_each_hole_and_says_when_the_job_leaves_the_map(tmp_path):
    path = the_map(tmp_path)
    state = _work_zero_at_30_30(tmp_path)
    drl = tmp_path / "holes.drl"
    drl.write_text("M48\nMETRIC\nT1C0.800\n%\nG90\nG05\nT1\nX10.000Y10.000\nX50.000Y40.000\nM30\n")
    out = tmp_path / "holes.png"
    ok(run_cli("preview", path, "--over", drl, "-o", out, "--state", state))
    img = read_png(out)
    m = HeightMap(XS, YS, heights())
    # the holes' upper-left corner (file X 10, Y 40: Excellon's +Y is up) at the work zero (30, 30): the hole at
    # file (50, 40) 40 mm right of it, the one at (10, 10) 30 mm toward the operator
    for x_mm, y_mm in ((70, 30), (30, 60)):
        c, r = np.rint(map_pixel(m, [x_mm], [y_mm], 8.0)[0]).astype(int)
        assert tuple(int(v) for v in img[r, c]) == CUT_RGB, (x_mm, y_mm)
    far = tmp_path / "far.drl"
    far.write_text("M48\nMETRIC\nT1C0.800\n%\nG90\nG05\nT1\nX0.000Y0.000\nX150.000Y0.000\nM30\n")
    said = ok(run_cli("preview", path, "--over", far, "-o", tmp_path / "far.png", "--state", state)).stdout
    assert "reaches 59.99 mm outside the probed area, past its X max edge" in said  # 150 mm in whole steps


@pytest.mark.parametrize("args, fragments", [
    (["info", "{bad}"], ["bad.json", "key 'x_mm'"]),
    (["preview", "{bad}", "-o", "{tmp}/p.png"], ["bad.json", "key 'x_mm'"]),
    (["preview", "{map}", "-o", "{tmp}/p.svg"], ["p.svg", ".png"]),
    (["preview", "{map}", "--over", "{tmp}/none.plt", "-o", "{tmp}/p.png"], ["--over", "none.plt", "no such file"]),
    (["preview", "{plt}", "--over", "{plt}", "-o", "{tmp}/p.png"], ["--over", "height map"]),
    (["drill", "{map}"], ["is a height map", "--level"]),
    (["export", "{map}", "-o", "{tmp}/x.ngc"], ["is a height map", "--level"]),
])
def test_bad_input_is_one_line_exit_2(tmp_path, args, fragments):
    m = the_map(tmp_path)
    bad = tmp_path / "bad.json"
    bad.write_text('{"cam_height_map": 1, "frame": "machine", "units": "mm", "x_mm": [0, "a"], "y_mm": [0, 1], '
                   '"height_mm": [[0, 0], [0, 0]], "reference_mm": 0, "spacing_mm": 1}')
    plt = tmp_path / "a.plt"
    plt.write_text("IN;SP1;PU0,0;PD400,0;PU;")
    argv = [a.format(bad=bad, tmp=tmp_path, map=m, plt=plt) for a in args]
    one_line_error(run_cli(*argv), *fragments)
