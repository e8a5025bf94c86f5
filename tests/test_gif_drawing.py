"""GIF drawings are read like PNG (issue #31 point 8: the thesis lists GIF among its inputs).

Each 2D and 3D sample is saved as a GIF (a palette of its own colours: lossless) and must give the PNG's
classes and digitized matrix, and its job must carve, decoded from the mock's pin log, exactly the PNG's
surface.  A GIF's size is read from its header before it is decoded, as a PNG's is; a transparent GIF is
composited over white paper; a damaged one is a one-line error.
"""
import struct

import numpy as np
import pytest
from PIL import Image

import cam
from cam.digitize.image_size import image_size_px
from cam.errors import DrawingError
from cam.kinds import sniff_kind

from conftest import SAMPLES, assert_surface_equal, carve_job

SAMPLE_PNGS = sorted(p.name for p in SAMPLES.glob("*.png"))


def _gif_of(png, path):
    """``png`` saved as a GIF whose palette holds its colours exactly (none of the samples has more than 256)."""
    rgb = Image.open(png).convert("RGB")
    colours = rgb.getcolors(256)
    assert colours is not None, f"{png} has more than 256 colours"
    rgb.quantize(colors=len(colours), method=Image.Quantize.MAXCOVERAGE, dither=Image.Dither.NONE).save(path)
    assert np.array_equal(np.asarray(Image.open(path).convert("RGB")), np.asarray(rgb))  # lossless
    return path


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n not in ("heart.png", "pyramid.png")
                                  else n for n in SAMPLE_PNGS])
def test_gif_digitizes_and_carves_like_the_png(tmp_path, name):
    png = SAMPLES / name
    gif = _gif_of(png, tmp_path / (name[:-4] + ".gif"))
    want_drawing, got_drawing = cam.load_image(png), cam.load_image(gif)
    assert np.array_equal(got_drawing.classes, want_drawing.classes)
    clean, got = cam.digitize(want_drawing), cam.digitize(got_drawing)
    assert got.mode == clean.mode and np.array_equal(got.to_array(), clean.to_array())
    kwargs = {"profile": lambda k: 1 + k // 2} if clean.mode == "3d" else {"depth": 4}
    want, _, _ = carve_job(cam.plan(clean, **kwargs))
    surface, result, _ = carve_job(cam.plan(got, **kwargs))
    assert_surface_equal(surface, want)
    assert surface.min() < 0 or surface.max() > 0  # something was cut


def test_gif_header_gives_its_size_and_the_sniffer_calls_it_a_drawing(tmp_path):
    gif = _gif_of(SAMPLES / "heart.png", tmp_path / "heart.gif")
    w, h = Image.open(SAMPLES / "heart.png").size
    assert image_size_px(gif.read_bytes()[:16]) == (w, h)
    assert image_size_px(b"GIF87a" + struct.pack("<HH", 7, 9)) == (7, 9)
    assert sniff_kind(gif.read_bytes()[:64]) == "drawing"


def test_cli_reports_a_gif_as_the_png(tmp_path, cli_run):
    gif = _gif_of(SAMPLES / "heart.png", tmp_path / "heart.gif")
    png = tmp_path / "heart.png"
    png.write_bytes((SAMPLES / "heart.png").read_bytes())
    r, want = cli_run("info", gif), cli_run("info", png)
    assert r.returncode == 0 and want.returncode == 0, r.stderr + want.stderr
    assert r.stdout.replace("heart.gif", "heart.png") == want.stdout


def test_transparent_gif_is_drawn_on_white_paper(tmp_path):
    """A black line on a transparent background whose colour is black too: the background is paper."""
    img = Image.new("P", (12, 8), 0)
    img.putpalette([0, 0, 0, 0, 0, 0] + [255] * 762)  # 0 black, made transparent; 1 black
    px = img.load()
    for x in range(2, 10):
        px[x, 4] = 1
    path = tmp_path / "t.gif"
    img.save(path, transparency=0)
    want = np.full((8, 12), 255, np.uint8)
    want[4, 2:10] = 0
    assert np.array_equal(cam.load_image(path).classes, cam.load_image(want).classes)


def test_damaged_gif_is_one_line_error(tmp_path):
    path = tmp_path / "bad.gif"
    path.write_bytes(b"GIF89a" + struct.pack("<HH", 20, 10) + b"\x00" * 5)  # a header, then nothing
    with pytest.raises(DrawingError) as exc:
        cam.load_image(path)
    assert "bad.gif" in str(exc.value) and "\n" not in str(exc.value)
