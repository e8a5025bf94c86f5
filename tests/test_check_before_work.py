"""Check before work (part of #20): image sizes are read from the file's header and refused before decoding, a
drawing too large for the travel is refused before it is traced, and a job that leaves the travel before it is
routed.  Behaviour is asserted (nothing decoded, traced or routed, memory bounded), never time."""
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

from conftest import SAMPLES
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
