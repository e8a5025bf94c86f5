"""JPEG and anti-aliased drawings digitize like their clean originals (issue #16 point 3).

Every 2D and 3D sample is saved as JPEG at quality 75 and 90 with 4:2:0 chroma (OpenCV), and anti-aliased
(a soft 3x3 blur, the grey fringe a paint program's smooth line leaves); each must give the clean drawing's
digitized matrix, and its job must carve, decoded from the mock's pin log, exactly the clean job's surface.
"""
import cv2
import numpy as np
import pytest

import cam
from cam.digitize.drawing import BLACK, RED, WHITE

from conftest import SAMPLES, assert_surface_equal, carve_job

SAMPLES_2D_3D = sorted(p.name for p in SAMPLES.glob("*.png"))
VARIANTS = ("jpeg75", "jpeg90", "antialiased")


def _jpeg(bgr: np.ndarray, quality: int) -> np.ndarray:
    params = [cv2.IMWRITE_JPEG_QUALITY, quality]
    if hasattr(cv2, "IMWRITE_JPEG_SAMPLING_FACTOR"):
        params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420]
    ok, buf = cv2.imencode(".jpg", bgr, params)
    assert ok
    return buf


def _variant(tmp_path, name: str, variant: str):
    bgr = cv2.imread(str(SAMPLES / name))
    if variant.startswith("jpeg"):
        path = tmp_path / f"{name[:-4]}_{variant}.jpg"
        _jpeg(bgr, int(variant[4:])).tofile(str(path))
        return path
    kernel = np.array([[1, 2, 1], [2, 12, 2], [1, 2, 1]], np.float32)
    soft = cv2.filter2D(bgr.astype(np.float32), -1, kernel / kernel.sum(), borderType=cv2.BORDER_REPLICATE)
    path = tmp_path / f"{name[:-4]}_aa.png"
    cv2.imwrite(str(path), np.clip(np.rint(soft), 0, 255).astype(np.uint8))
    return path




@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("name", SAMPLES_2D_3D)
def test_variant_digitizes_and_carves_like_the_clean_drawing(tmp_path, name, variant):
    clean = cam.digitize(cam.load_image(SAMPLES / name))
    drawing = cam.load_image(_variant(tmp_path, name, variant))
    assert np.array_equal(drawing.classes, cam.load_image(SAMPLES / name).classes)
    got = cam.digitize(drawing)
    assert got.mode == clean.mode and np.array_equal(got.to_array(), clean.to_array())
    kwargs = {"profile": lambda k: 1 + k // 2} if clean.mode == "3d" else {"depth": 4}
    want, _, _ = carve_job(cam.plan(clean, **kwargs))
    surface, _, _ = carve_job(cam.plan(got, **kwargs))
    assert_surface_equal(surface, want)


def test_pil_jpeg_of_the_heart_is_the_heart(tmp_path):
    """The issue's example: PIL's save('h.jpg', quality=85), 4:2:0 by default."""
    from PIL import Image as image  # Pillow: scikit-image requires it

    path = tmp_path / "h.jpg"
    image.open(SAMPLES / "heart.png").convert("RGB").save(path, quality=85, subsampling=2)
    assert np.array_equal(cam.load_image(path).classes, cam.load_image(SAMPLES / "heart.png").classes)


def test_dark_red_contour_pixel_is_black_and_a_lone_red_pixel_stays_red():
    """A tiny 3D drawing whose contour took the interior's red, as 4:2:0 chroma leaves it."""
    img = np.full((7, 7, 3), 255, np.uint8)
    img[1:6, 1:6] = (120, 0, 0)   # the contour, dark red (luminance 36)
    img[2:5, 2:5] = (255, 0, 0)   # the interior
    classes = cam.load_image(img).classes
    assert (classes[1:6, 1:6][[0, -1]] == BLACK).all() and (classes[2:5, 2:5] == RED).all()
    assert classes[0, 0] == WHITE
    lone = np.full((5, 5, 3), 255, np.uint8)
    lone[2, 1:4] = 0
    lone[2, 2] = (255, 0, 0)      # a profile's origin on its axis
    assert cam.load_image(lone).classes[2, 2] == RED


SAMPLES_3D = ("disc.png", "dumbbell.png", "heart.png", "pyramid.png", "ring.png")


@pytest.mark.slow
@pytest.mark.parametrize("name", SAMPLES_3D)
def test_3d_drawings_at_every_jpeg_quality_from_70_to_95_are_their_originals(name):
    """Issue #32 point 9: every quality 70..95, with and without 4:2:0 chroma, gives the clean drawing's matrix
    (the dumbbell at 73 and 74 had one interior pixel beside the contour, darkened by JPEG's ringing, taken for a
    thin dark line); the matrix decides the cut, so the same matrix cuts the same surface (carved above)."""
    bgr = cv2.imread(str(SAMPLES / name))
    clean = cam.digitize(cam.load_image(SAMPLES / name))
    assert clean.mode == "3d"
    for quality in range(70, 96):
        for sampling in (True, False):
            params = [cv2.IMWRITE_JPEG_QUALITY, quality]
            if sampling and hasattr(cv2, "IMWRITE_JPEG_SAMPLING_FACTOR"):
                params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420]
            ok, buf = cv2.imencode(".jpg", bgr, params)
            rgb = np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[:, :, ::-1])
            got = cam.digitize(cam.load_image(rgb))
            assert np.array_equal(got.to_array(), clean.to_array()), (quality, sampling)


def _jpeg_copies(rgb: np.ndarray, quality: int):
    """``(label, decoded RGB)`` of ``rgb`` saved as JPEG at ``quality`` by OpenCV and by Pillow, each with 4:2:0
    chroma subsampling and without (4:4:4)."""
    import io

    from PIL import Image as image

    bgr = np.ascontiguousarray(rgb[:, :, ::-1])
    for sampling in (cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444):
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
                                             sampling])
        assert ok
        yield f"cv2 q{quality} {'4:2:0' if sampling == cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420 else '4:4:4'}", \
            np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[:, :, ::-1])
    for subsampling, label in ((2, "4:2:0"), (0, "4:4:4")):
        out = io.BytesIO()
        image.fromarray(rgb).save(out, "JPEG", quality=quality, subsampling=subsampling)
        yield f"PIL q{quality} {label}", np.asarray(image.open(io.BytesIO(out.getvalue())).convert("RGB"))


@pytest.mark.parametrize("name", SAMPLES_3D)
def test_every_jpeg_quality_of_every_3d_drawing_digitizes_like_the_png(name):
    """Issue #44 point 2: every quality 60..95 (step 5), OpenCV and Pillow, 4:2:0 and 4:4:4, gives the clean
    drawing's classes and matrix.  Below 70 JPEG dims the red beside the contour to a near-grey (129, 50, 53),
    leaves pale cyan or pink ringing beside the contour on the white, and a contour pixel as bright as (115, 39, 15);
    on the inner side of a diagonal contour a dark interior pixel would have thickened the line."""
    rgb = np.ascontiguousarray(cv2.imread(str(SAMPLES / name))[:, :, ::-1])
    clean = cam.load_image(rgb)
    matrix = cam.digitize(clean).to_array()
    assert cam.digitize(clean).mode == "3d"
    wrong = []
    for quality in range(60, 100, 5):
        for label, decoded in _jpeg_copies(rgb, quality):
            try:
                drawing = cam.load_image(decoded)
                same = (np.array_equal(drawing.classes, clean.classes)
                        and np.array_equal(cam.digitize(drawing).to_array(), matrix))
            except cam.CamError as exc:
                same = str(exc)
            if same is not True:
                wrong.append((label, same))
    assert wrong == []
