import numpy as np
import pytest

import cam
from cam.digitize.peel3d import peel_layers, trace_layers
from cam.digitize.drawing import BLACK, RED, WHITE

from conftest import assert_surface_equal, carve_job


def drawing3d(rows):
    """RGB image from rows: '#' black, 'r' red, anything else white."""
    h, w = len(rows), max(len(r) for r in rows)
    img = np.full((h, w, 3), 255, np.uint8)
    for y, line in enumerate(rows):
        for x, ch in enumerate(line):
            if ch == "#":
                img[y, x] = 0
            elif ch == "r":
                img[y, x] = (255, 0, 0)
    return img


SMALL = [
    ".......",
    "..###..",
    ".#rrr#.",
    ".#rrr#.",
    ".#rrr#.",
    "..###..",
    ".......",
]


def test_layers_peel_inward_by_4_adjacency():
    d = cam.load_image(drawing3d(SMALL))
    assert d.kind == "3d"
    assert peel_layers(d.classes).tolist() == [
        [0, 0, 0, 0, 0, 0, 0],
        [0, 0, 1, 1, 1, 0, 0],
        [0, 1, 2, 2, 2, 1, 0],
        [0, 1, 2, 3, 2, 1, 0],
        [0, 1, 2, 2, 2, 1, 0],
        [0, 0, 1, 1, 1, 0, 0],
        [0, 0, 0, 0, 0, 0, 0],
    ]


def test_rings_traced_in_figure_4_15_order():
    dg = cam.digitize(drawing3d(SMALL))
    assert dg.mode == "3d"
    assert dg.levels.tolist() == [1, 2, 3]
    # layer 1 starts at its first pixel in scan order, then N, E, S, W, SE, NE, NW, SW
    assert dg.objects[0].tolist() == [[2, 1], [3, 1], [4, 1], [5, 2], [5, 3], [5, 4], [4, 5], [3, 5], [2, 5], [1, 4],
                                      [1, 3], [1, 2]]
    assert dg.objects[1].tolist() == [[2, 2], [3, 2], [4, 2], [4, 3], [4, 4], [3, 4], [2, 4], [2, 3]]
    assert dg.objects[2].tolist() == [[3, 3]]
    assert dg.to_array()[:, 3].tolist() == [1] * 12 + [2] * 8 + [3]


def test_every_pixel_traced_once_and_rings_split_at_a_neck():
    img = np.full((40, 80, 3), 255, np.uint8)
    import cv2
    mask = np.zeros((40, 80), np.uint8)
    cv2.circle(mask, (20, 20), 14, 1, -1)
    cv2.circle(mask, (58, 20), 14, 1, -1)
    mask[18:23, 20:58] = 1  # neck 5 px wide
    inner = cv2.erode(mask, np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8))
    img[mask > 0] = (255, 0, 0)
    img[(mask > 0) & (inner == 0)] = 0
    dg = cam.digitize(img)
    pts = np.concatenate(dg.objects)
    assert len(pts) == len({tuple(p) for p in pts.tolist()}) == int(mask.sum())
    per_layer = np.bincount(dg.levels)
    assert per_layer.max() >= 2  # some layers split into one ring per lobe
    assert min(len(o) for o, lv in zip(dg.objects, dg.levels) if lv < dg.n_layers) > 1  # no stray 1-pixel rings
    job = cam.plan(dg, profile=lambda k: k)
    surface, _, motion = carve_job(job)
    assert_surface_equal(surface, peel_layers(cam.load_image(img).classes).astype(np.int64))
    rep = cam.job_report(dg, job, cam.plan_steps(job))
    assert rep["retracts"] <= rep["rings"] + rep["objects"]


def test_open_contour_names_a_leaking_pixel():
    rows = list(SMALL)
    rows[5] = "..#.#.."
    rows[5] = "..#r#.."
    rows[6] = "...r..."
    with pytest.raises(cam.DrawingError, match=r"open: red pixel \(x=3, y=6\)"):
        cam.digitize(drawing3d(rows))


def test_red_without_contour():
    rows = [".....", ".rr..", ".....", "..#..", "..#.."]
    with pytest.raises(cam.DrawingError, match=r"red region at \(x=1, y=1\) has no black contour"):
        cam.digitize(drawing3d(rows))


def test_3d_needs_a_profile_and_profile_must_be_long_enough():
    dg = cam.digitize(drawing3d(SMALL))
    with pytest.raises(cam.PlanError, match="give --depth N for a flat-bottomed pocket"):
        cam.plan(dg)
    with pytest.raises(cam.PlanError, match="profile has 2 layers, the object has 3"):
        cam.plan(dg, profile=[1, 2])


def test_small_3d_carves_to_profile_depths():
    dg = cam.digitize(drawing3d(SMALL))
    job = cam.plan(dg, profile=[2, 5, 9], settings=cam.MachineSettings().replace(steps_per_px_z=2))
    surface, result, motion = carve_job(job)
    layer = peel_layers(cam.load_image(drawing3d(SMALL)).classes)
    want = np.choose(layer, [0, 2, 5, 9]) * 2
    assert_surface_equal(surface, want)
    assert motion.final_steps == (0, 0, 0)
    assert job.n_retracts == 1  # one ring leads into the next without lifting


def test_digitized_3d_round_trip(tmp_path):
    dg = cam.digitize(drawing3d(SMALL))
    cam.save_digitized(dg, tmp_path / "m.txt")
    back = cam.load_digitized(tmp_path / "m.txt")
    assert back.mode == "3d" and np.array_equal(back.to_array(), dg.to_array())
    assert np.array_equal(back.levels, dg.levels)


def test_compiled_ring_tracer_equals_reference():
    import cv2
    from support.references import trace_layers_reference

    mask = np.zeros((90, 120), np.uint8)
    cv2.ellipse(mask, (45, 45), (35, 25), 20, 0, 360, 1, -1)
    cv2.circle(mask, (90, 50), 22, 1, -1)
    mask[40:46, 60:80] = 1
    inner = cv2.erode(mask, np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8))
    classes = np.where(mask > 0, RED, WHITE).astype(np.uint8)
    classes[(mask > 0) & (inner == 0)] = BLACK
    layer = peel_layers(classes)
    a, la = trace_layers(layer)
    b, lb = trace_layers_reference(layer)
    assert np.array_equal(la, lb) and len(a) == len(b)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


def _blobs(seed: int, shape=(80, 110)) -> np.ndarray:
    """Classes of a random 3D drawing: filled ellipses (some nested, some with holes) with black rims."""
    import cv2

    rng = np.random.default_rng(seed)
    mask = np.zeros(shape, np.uint8)
    for _ in range(6):
        c = (int(rng.integers(10, shape[1] - 10)), int(rng.integers(10, shape[0] - 10)))
        ax = (int(rng.integers(3, 25)), int(rng.integers(3, 20)))
        cv2.ellipse(mask, c, ax, float(rng.uniform(0, 180)), 0, 360, int(rng.integers(0, 2)), -1)
    mask[:2] = mask[-2:] = 0
    mask[:, :2] = mask[:, -2:] = 0
    inner = cv2.erode(mask, np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8))
    classes = np.where(mask > 0, RED, WHITE).astype(np.uint8)
    classes[(mask > 0) & (inner == 0)] = BLACK
    return classes


@pytest.mark.parametrize("seed", range(8))
def test_compiled_peel_equals_the_checked_peel(seed):
    from cam.digitize.peel3d import peel_layers_padded

    classes = _blobs(seed)
    padded = peel_layers_padded(classes)
    assert padded.shape == (classes.shape[0] + 2, classes.shape[1] + 2)
    assert not padded[0].any() and not padded[-1].any() and not padded[:, 0].any() and not padded[:, -1].any()
    assert np.array_equal(padded[1:-1, 1:-1], peel_layers(classes))


def test_compiled_peel_falls_back_to_the_named_errors():
    from cam.digitize.peel3d import peel_layers_padded

    classes = _blobs(3)
    r, c = np.argwhere(classes == BLACK)[0]
    classes[r, c] = WHITE  # a gap in the rim: red now touches white
    with pytest.raises(cam.DrawingError, match=r"open: red pixel"):
        peel_layers_padded(classes)


@pytest.mark.parametrize("seed", range(8))
def test_compiled_ring_tracer_equals_reference_on_random_reliefs(seed):
    """Overlapping ellipses with holes: layers that split into several rings and walks that stop early."""
    from cam.digitize.peel3d import peel_layers_padded, trace_padded
    from support.references import trace_layers_reference

    classes = _blobs(seed)
    layer = peel_layers(classes)
    padded = peel_layers_padded(classes)
    a, la = trace_padded(padded)
    assert np.array_equal(padded[1:-1, 1:-1], layer)  # not in place: the caller's array is untouched
    b, lb = trace_layers_reference(layer)
    assert np.array_equal(la, lb) and len(a) == len(b)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
