import re

import numpy as np
import pytest

import cam
from cam.digitize.profile import as_profile, load_profile, profile_from_csv, profile_from_expr
from cam.errors import PlanError


def profile_image(depths, below=True, h=12):
    """Axes with the origin at (2, 2) (below=True: depth grows downward) and one blue pixel per layer."""
    w = len(depths) + 5
    img = np.full((h, w, 3), 255, np.uint8)
    r0 = 2 if below else h - 3
    img[r0, 2:w - 1] = 0           # layer axis
    if below:
        img[2:h - 1, 2] = 0        # depth axis, down
    else:
        img[1:r0 + 1, 2] = 0       # depth axis, up
    img[r0, 2] = (255, 0, 0)       # red origin
    for k, d in enumerate(depths, start=1):
        img[r0 + d if below else r0 - d, 2 + k] = (0, 0, 255)
    return img


@pytest.mark.parametrize("below", [True, False])
def test_profile_drawing_depth_per_layer(below):
    prof = load_profile(profile_image([1, 2, 4, 4, 7], below=below))
    assert prof.depth_px.tolist() == [1, 2, 4, 4, 7] and prof.n_layers == 5


def test_two_blue_pixels_in_a_column_warn_and_take_the_farthest():
    img = profile_image([1, 2, 4])
    img[5, 4] = (0, 0, 255)  # second blue pixel in column 4 (layer 2), farther from the axis
    prof = load_profile(img)
    assert "layers 2 have more than one blue pixel" in prof.warnings[0]
    assert prof.depth_px[1] > 2


def test_missing_origin_or_axes():
    img = profile_image([1, 2])
    img[2, 2] = 0
    with pytest.raises(cam.DrawingError, match="no red origin"):
        load_profile(img)
    img = profile_image([1, 2])
    img[2, 3:] = 255
    img[2 + 1, 3] = (0, 0, 255)
    with pytest.raises(cam.DrawingError, match="horizontal"):
        load_profile(img)


def test_gap_in_curve_is_an_error():
    img = profile_image([1, 2, 3])
    img[:, 4] = np.where((img[:, 4] == (0, 0, 255)).all(axis=1)[:, None], 255, img[:, 4])
    with pytest.raises(cam.DrawingError, match="layer 2"):
        load_profile(img)


def test_expression_csv_sequence_and_function(tmp_path):
    assert profile_from_expr("k*k", 4).depth_px.tolist() == [1, 4, 9, 16]
    assert profile_from_expr("n - k + 1", 3).depth_px.tolist() == [3, 2, 1]
    for bad in ("__import__('os')", "k.real", "open('x')", "k +"):
        with pytest.raises(cam.PlanError):
            profile_from_expr(bad, 3)
    f = tmp_path / "p.csv"
    f.write_text("layer,depth\n1,2\n2,3.4\n3,5\n")
    assert profile_from_csv(f).depth_px.tolist() == [2, 3, 5]
    f.write_text("2\n3\nx\n")
    with pytest.raises(cam.ParseError, match="p.csv:3"):
        profile_from_csv(f)
    assert as_profile([1, 2], 2).depth_px.tolist() == [1, 2]
    assert as_profile(lambda k: 3 * k, 3).depth_px.tolist() == [3, 6, 9]
    with pytest.raises(cam.PlanError, match="layer 2"):
        as_profile([1, -2], 2)


@pytest.mark.parametrize("expr, fragment", [
    ("9**9**9", "out of range"), ("'a'*10**10", "not allowed"), ("__import__('os').getcwd()", "not allowed"),
    ("k.real", "not allowed"), ("(lambda: 1)()", "not allowed"), ("9" * 400, "out of range"),
    ("1e300*1e300", "out of range"), ("k" + "+k" * 300, "at most"), ("1/(k-1)", "k=1"),
])
def test_profile_expressions_are_evaluated_safely_and_bounded(expr, fragment):
    """A small evaluator, never eval: no names but k, n, pi, e and the math functions; bounded numbers."""
    with pytest.raises(PlanError, match=re.escape(fragment)):
        profile_from_expr(expr, 5)


def test_profile_depths_are_bounded():
    with pytest.raises(PlanError, match="layer 2"):
        profile_from_expr("k * 600000", 3)
