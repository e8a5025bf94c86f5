import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest

import cam
from cam.render.picture import depth_colours, surface_picture, toolpath_picture, toolpath_svg

from conftest import ROOT, drawing_from_rows
from test_cli import cli

ROWS = ["..........", ".####.....", "..........", "......###.", ".........."]


def _job():
    d = cam.digitize(drawing_from_rows(ROWS))
    return d, cam.plan(d, depth=[2, 8])


def test_toolpath_picture_size_and_colours_under_cuts():
    d, job = _job()
    img = toolpath_picture(job, scale=8)
    assert img.shape == (5 * 8 + 44, 420, 3)
    # centre of pixel (3, 1) is on the shallow cut, (7, 3) on the deep one
    shallow = depth_colours([2], 8)[0]
    deep = depth_colours([8], 8)[0]
    assert img[1 * 8 + 4, 3 * 8 + 4].tolist() == shallow.tolist()
    assert img[3 * 8 + 4, 7 * 8 + 4].tolist() == deep.tolist()
    assert img[0 * 8 + 4, 8 * 8 + 4].tolist() == [255, 255, 255]  # nothing there


def test_svg_parses_and_has_cuts_and_dashed_travel():
    d, job = _job()
    root = ET.fromstring(toolpath_svg(job, scale=8))
    lines = [e for e in root.iter() if e.tag.endswith("line")]
    assert any("stroke-dasharray" in e.attrib for e in lines)
    assert any("stroke-dasharray" not in e.attrib for e in lines)
    assert root.attrib["width"] == "420"


def test_surface_picture_white_where_untouched():
    s = np.zeros((4, 5), np.int64)
    s[1, 1:4] = 5
    img = surface_picture(s, scale=4)
    assert img[0, 0].tolist() == [255, 255, 255]
    assert img[1 * 4 + 2, 2 * 4 + 2].tolist() != [255, 255, 255]


def test_notebook_pictures_are_pngs():
    d, job = _job()
    surface = cam.simulate_surface(job)
    for obj in (cam.load_image(drawing_from_rows(ROWS)), d, job, surface):
        png = obj._repr_png_()
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        assert cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR) is not None


def test_cli_preview_png_svg_and_surface(tmp_path):
    path = tmp_path / "d.png"
    img = np.full((30, 40, 3), 255, np.uint8)
    img[10, 5:30] = 0
    cv2.imwrite(str(path), img)
    assert cli("preview", path, "-o", tmp_path / "p.png", "--scale", "4").returncode == 0
    pic = cv2.imread(str(tmp_path / "p.png"))
    assert pic.shape[:2] == (30 * 4 + 44, 420)
    assert cli("preview", path, "-o", tmp_path / "p.svg").returncode == 0
    ET.parse(tmp_path / "p.svg")
    assert cli("preview", path, "--surface", "-o", tmp_path / "s.png", "--scale", "2").returncode == 0
    s = cv2.imread(str(tmp_path / "s.png"))[:, :, ::-1]
    assert s[10 * 2, 20 * 2].tolist() != [255, 255, 255] and s[2 * 2, 20 * 2].tolist() == [255, 255, 255]
    bad = cli("preview", path, "-o", tmp_path / "p.jpg")
    assert bad.returncode == 2 and "png or .svg" in bad.stderr
    assert cli("drill", path, "--preview", tmp_path / "pre.png", "--no-progress").returncode == 0
    assert (tmp_path / "pre.png").exists()


@pytest.mark.slow
def test_readme_pictures_script_writes_the_previews(tmp_path):
    """docs/make_pictures.py without the browser: the two previews, into a temporary folder (docs/ untouched)."""
    proc = subprocess.run([sys.executable, str(ROOT / "docs" / "make_pictures.py"), "--out", str(tmp_path),
                           "--no-browser"], capture_output=True, text=True, cwd=tmp_path, timeout=300,
                          env={**os.environ, "PYTHONPATH": ""})  # the script finds its own checkout
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gear-preview.png", "heart-surface.png"]
    for name in ("gear-preview.png", "heart-surface.png"):
        img = cv2.imread(str(tmp_path / name))
        assert img is not None and img.shape[0] > 300 and img.shape[1] > 300, name
        colours = np.unique(img.reshape(-1, 3), axis=0)
        assert len(colours) > 20, name  # a picture, not a blank page
        assert 0.01 < (img < 200).any(axis=2).mean() < 0.99, name
        assert str(tmp_path / name) in proc.stdout
