"""Profiles as people draw them (issue #16 point 2): the curve may touch or run along an axis."""
import numpy as np
import pytest

import cam

W, K, R, B = (255, 255, 255), (0, 0, 0), (255, 0, 0), (0, 0, 255)


def _profile(depths, *, thick_at=None):
    """Origin at (x=1, y=1), layer axis to the right on row 1, depth axis down column 1; depth k = row 1 + k."""
    h, w = max(depths) + 4, len(depths) + 4
    img = np.full((h, w, 3), 255, np.uint8)
    img[1, 1:w - 1] = K
    img[1:h - 1, 1] = K
    img[1, 1] = R
    for k, d in enumerate(depths):
        img[1 + d, 2 + k] = B
        if thick_at == k:
            img[d, 2 + k] = B  # a second, nearer pixel in the column
    return img


def test_curve_starting_on_the_layer_axis_is_depth_zero():
    prof = cam.load_profile(_profile([0, 0, 1, 2, 3]))
    assert prof.depth_px.tolist() == [0, 0, 1, 2, 3] and prof.warnings == ()


def test_curve_running_along_the_axis_then_dropping():
    prof = cam.load_profile(_profile([0, 0, 0, 4, 4, 0]))
    assert prof.depth_px.tolist() == [0, 0, 0, 4, 4, 0]


def test_several_blue_pixels_in_a_column_take_the_farthest_with_a_warning():
    prof = cam.load_profile(_profile([2, 3, 3], thick_at=1))
    assert prof.depth_px.tolist() == [2, 3, 3]
    assert len(prof.warnings) == 1 and "layers 2 have more than one blue pixel" in prof.warnings[0]


def test_a_gap_in_the_curve_is_still_an_error():
    img = _profile([1, 1, 1])
    img[2, 3] = W
    with pytest.raises(cam.DrawingError, match=r"layer 2 \(column 3\) has no blue depth pixel"):
        cam.load_profile(img)


def _shapes():
    for n in (20, 40, 80):
        k = np.arange(1, n + 1)
        yield n, "dome", (np.rint(20 * np.sqrt(1 - ((n - k) / n) ** 2)) + 2).astype(int).tolist()
        yield n, "cone", (np.rint(k * 20 / n) + 2).astype(int).tolist()
        yield n, "steps", (3 + 5 * (k > n // 2)).astype(int).tolist()


def _saved(img, variant):
    import cv2

    if variant == "blur":  # anti-aliased: every pixel off the palette, no clean red origin left
        return cv2.GaussianBlur(img, (3, 3), 0.6)
    ok, buf = cv2.imencode(".jpg", img[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(variant[1:])])  # 4:2:0 colour
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)[:, :, ::-1].copy()


@pytest.mark.parametrize("variant", ["q75", "q90", "blur"])
@pytest.mark.parametrize("n,shape,depths", list(_shapes()), ids=lambda v: str(v)[:8])
def test_jpeg_and_anti_aliased_profiles_read_as_their_clean_originals(n, shape, depths, variant):
    clean = np.pad(_profile(depths), ((6, 6), (6, 6), (0, 0)), constant_values=255)
    assert cam.load_profile(clean).depth_px.tolist() == depths
    prof = cam.load_profile(_saved(clean, variant))
    assert prof.depth_px.tolist() == depths
    assert "read as a photo-like drawing" in prof.warnings[0]


@pytest.mark.parametrize("variant", ["q75", "q90", "blur"])
def test_a_jpeg_cone_drawn_from_the_surface_starts_at_depth_0(variant):
    """The issue's case: a cone drawn from the surface, its curve starting on the layer axis."""
    depths = [0, 0, 1, 1, 2, 3, 3, 4, 5, 5, 6, 7, 7, 8, 9, 9, 10, 11, 11, 12]
    clean = np.pad(_profile(depths), ((6, 6), (6, 6), (0, 0)), constant_values=255)
    got = cam.load_profile(_saved(clean, variant)).depth_px.tolist()
    assert got == depths


def test_a_jpeg_profile_file_plans_the_same_relief_as_the_clean_one(tmp_path):
    import cv2

    depths = (np.rint(np.arange(1, 41) * 20 / 40) + 2).astype(int).tolist()
    clean = np.pad(_profile(depths), ((6, 6), (6, 6), (0, 0)), constant_values=255)
    cv2.imwrite(str(tmp_path / "p.png"), clean[:, :, ::-1])
    cv2.imwrite(str(tmp_path / "p.jpg"), clean[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, 80])
    assert cam.load_profile(tmp_path / "p.jpg").depth_px.tolist() == cam.load_profile(tmp_path / "p.png").depth_px.tolist()
