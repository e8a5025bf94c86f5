"""The one-pass compiled colour classification gives exactly the classes of the plain numpy reference
(tests/support/references.py): on every sample, on JPEG copies of them, and on random noise images."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

import cam
from cam.digitize.drawing import _classify_pixels, check_rules
from support.references import check_rules_reference, classify_reference

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = sorted(p for p in list((ROOT / "samples").glob("*.png")) + list((ROOT / "samples").glob("*.jpg"))
                 + list((ROOT / "profiles").glob("*.png")))


def _rgb(path: Path) -> np.ndarray:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    return np.ascontiguousarray(bgr[:, :, ::-1])


def _same(rgb: np.ndarray) -> None:
    ours, n_bad, first, n_black = _classify_pixels(rgb)
    ref = classify_reference(rgb)
    assert np.array_equal(ours, ref), f"{int((ours != ref).sum())} pixels differ"
    assert n_bad == int((ref == 255).sum()) and n_black == int((ref == 1).sum())
    if n_bad:
        assert first == int(np.flatnonzero(ref.ravel() == 255)[0])
    bgr = np.ascontiguousarray(rgb[:, :, ::-1])
    assert np.array_equal(_classify_pixels(bgr, bgr=True)[0], ref)


def test_there_are_samples():
    assert len(SAMPLES) >= 10


@pytest.mark.parametrize("path", SAMPLES, ids=lambda p: p.name)
def test_every_sample_and_its_jpeg_copies(path):
    rgb = _rgb(path)
    _same(rgb)
    for quality in (50, 70, 73, 74, 75, 80, 85, 90, 95):
        ok, buf = cv2.imencode(".jpg", rgb[:, :, ::-1].copy(), [cv2.IMWRITE_JPEG_QUALITY, quality])
        _same(np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[:, :, ::-1]))


@pytest.mark.parametrize("seed", range(6))
def test_uniform_noise(seed):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(1, 90, 2)
    _same(rng.integers(0, 256, (h, w, 3), dtype=np.uint8))


@pytest.mark.parametrize("seed", range(12))
def test_palette_noise_exercises_every_rule(seed):
    """Near-palette colours (white, black, red, dark red, blue, greys) with noise: the contour and thin-line
    rules fire often, the hue tolerance edges are crossed."""
    rng = np.random.default_rng(100 + seed)
    palette = np.array([[255, 255, 255], [0, 0, 0], [255, 0, 0], [120, 10, 20], [60, 5, 10], [0, 0, 255],
                        [128, 128, 128], [200, 60, 30], [200, 30, 90]], np.int16)
    h, w = rng.integers(2, 120, 2)
    idx = rng.integers(0, len(palette), (h, w))
    if seed % 3 == 0:  # blocks: large red areas with dark lines, as in a 3D drawing
        idx = np.kron(rng.integers(0, len(palette), (h // 4 + 1, w // 4 + 1)), np.ones((4, 4), int))[:h, :w]
    noise = rng.normal(0, [5, 20, 45][seed % 3], (h, w, 3))
    _same(np.clip(palette[idx] + noise, 0, 255).astype(np.uint8))


@pytest.mark.slow
def test_every_colour_once():
    """All 2^24 colours in one image (a 4096 x 4096 array): the per-pixel rules agree everywhere."""
    v = np.arange(1 << 24, dtype=np.uint32)
    rgb = np.stack([(v >> 16) & 255, (v >> 8) & 255, v & 255], -1).astype(np.uint8).reshape(4096, 4096, 3)
    ours = _classify_pixels(rgb)[0]
    ref = classify_reference(rgb)
    assert np.array_equal(ours, ref)


@pytest.mark.parametrize("seed", range(8))
def test_rule_warnings_equal_the_reference(seed):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(1, 60, 2)
    classes = (rng.random((h, w)) < [0.05, 0.2, 0.5, 0.8][seed % 4]).astype(np.uint8)
    assert check_rules(classes) == check_rules_reference(classes)


def test_file_and_array_give_the_same_drawing(tmp_path):
    rgb = _rgb(ROOT / "samples" / "heart.png")
    path = tmp_path / "h.png"
    cv2.imwrite(str(path), rgb[:, :, ::-1])
    a, b = cam.load_image(path), cam.load_image(rgb)
    assert np.array_equal(a.classes, b.classes) and a.warnings == b.warnings


def test_unknown_pixel_of_a_file_is_named_in_rgb(tmp_path):
    img = np.full((4, 5, 3), 255, np.uint8)
    img[1, 1] = 0
    img[2, 3] = (10, 200, 60)  # RGB
    path = tmp_path / "g.png"
    cv2.imwrite(str(path), img[:, :, ::-1])
    with pytest.raises(cam.DrawingError, match=r"1 pixel\(s\).*\(x=3, y=2\).*RGB \(10, 200, 60\)"):
        cam.load_image(path)
