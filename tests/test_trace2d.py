import numpy as np
import pytest

import cam
from cam.digitize.trace2d import START_RULES, trace_curves

from conftest import drawing_from_rows


def paths(img, **kw):
    return [o.tolist() for o in cam.digitize(img, **kw).objects]


def test_neighbour_order_nw_n_ne_w_e_sw_s_se():
    # from the start pixel (2,1) both E (3,1) and SW (1,2) and S (2,2) are black ends of arms;
    # the trace takes E first (order NW N NE W E SW S SE), then the other arm is joined.
    m = np.zeros((5, 6), bool)
    m[1, 2] = m[1, 3] = True  # start (2,1), east (3,1)
    m[2, 1] = True            # south-west (1,2)
    objs = trace_curves(m, start="top")
    assert len(objs) == 1
    # the ends are (3,1) and (1,2); (3,1) comes first in scan order, so the object starts there
    assert objs[0].tolist() == [[3, 1], [2, 1], [1, 2]]


def test_closed_square_ends_next_to_start():
    img = drawing_from_rows([
        ".......",
        "..###..",
        ".#...#.",
        ".#...#.",
        "..###..",
        ".......",
    ])
    (obj,) = paths(img)
    assert obj == [[2, 1], [3, 1], [4, 1], [5, 2], [5, 3], [4, 4], [3, 4], [2, 4], [1, 3], [1, 2]]
    assert max(abs(obj[-1][0] - obj[0][0]), abs(obj[-1][1] - obj[0][1])) == 1


ARCH = [
    ".........",
    "...###...",
    "..#...#..",
    "..#...#..",
    "..#...#..",
    ".........",
]


def test_open_curve_started_mid_curve_is_one_object_top():
    # the top pixel (3,1) is in the middle of the arch
    assert paths(drawing_from_rows(ARCH), start="top") == [
        [[2, 4], [2, 3], [2, 2], [3, 1], [4, 1], [5, 1], [6, 2], [6, 3], [6, 4]]
    ]


def test_open_curve_min_distance_starts_at_end_nearest_tool():
    m = drawing_from_rows(ARCH) == 0
    (obj,) = trace_curves(m, start="min-distance", tool_xy_px=(8, 5))
    assert obj[0].tolist() == [6, 4] and obj[-1].tolist() == [2, 4]


def test_two_open_curves_count_two_in_both_modes():
    img = drawing_from_rows([
        "..............",
        "...###...#....",
        "..#...#...#...",
        "..#...#....#..",
        "..#...#...#...",
        ".........#....",
        "..............",
    ])
    for start in ("top", "min-distance"):
        objs = cam.digitize(img, start=start).objects
        assert len(objs) == 2, start
        assert sum(len(o) for o in objs) == int((img == 0).sum())


def test_min_distance_orders_objects_by_nearness_to_tool():
    img = drawing_from_rows([
        "..........",
        ".......##.",
        "..........",
        "..........",
        ".##.......",
        "..........",
    ])
    top = paths(img, start="top")
    near = paths(img, start="min-distance")
    assert top == [[[7, 1], [8, 1]], [[1, 4], [2, 4]]]
    # (1,4) is nearer the origin than (7,1); after it the tool is at (2,4)
    assert near == [[[1, 4], [2, 4]], [[7, 1], [8, 1]]]


def test_every_black_pixel_traced_once_with_junctions():
    img = drawing_from_rows([
        ".........",
        ".#######.",
        "....#....",
        "....#....",
        "....#....",
        ".........",
    ])
    d = cam.digitize(img)
    pts = np.concatenate(d.objects)
    assert len(pts) == len({tuple(p) for p in pts.tolist()}) == int((img == 0).sum())
    assert any("more than two black neighbours" in w for w in d.warnings)


def test_stray_pixel_warns_count():
    img = drawing_from_rows([".......", ".###...", ".......", ".....#.", "......."])
    d = cam.digitize(img)
    assert len(d.objects) == 2
    assert any("single-pixel" in w and "(5, 3)" in w for w in d.warnings)


def test_unknown_start_rule():
    with pytest.raises(cam.CamError, match="start rule"):
        cam.digitize(drawing_from_rows([".....", ".###.", "....."]), start="left")


def test_to_array_rows_object_x_y_level():
    d = cam.digitize(drawing_from_rows(["......", ".##...", "...##.", "......"]))
    assert d.to_array().tolist() == [[1, 1, 1, 1], [1, 2, 1, 1], [1, 3, 2, 1], [1, 4, 2, 1]]


def test_compiled_tracer_equals_reference_on_random_curves():
    import cv2
    from support.references import trace_curves_reference

    rng = np.random.default_rng(7)
    m = np.zeros((120, 160), np.uint8)
    for _ in range(12):
        c = (int(rng.integers(15, 145)), int(rng.integers(15, 105)))
        cv2.ellipse(m, c, (int(rng.integers(4, 14)), int(rng.integers(3, 10))), 0, 0, int(rng.integers(90, 361)),
                    1, 1, cv2.LINE_8)
    for start in START_RULES:
        a = trace_curves(m > 0, start=start)
        b = trace_curves_reference(m > 0, start=start)
        assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b))
