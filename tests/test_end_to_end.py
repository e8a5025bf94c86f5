"""Every sample, run on the mock port, decoded and carved, must equal what the drawing asks for."""
import json

import numpy as np
import pytest

import cam
from cam.digitize.drawing import BLACK

from conftest import ROOT, SAMPLES, assert_surface_equal, carve_job, expected_surface_2d

SAMPLES_2D = ["ellipse.png", "two_curves.png", "gear.png", "word.png", "stamp.png"]


@pytest.fixture(scope="module", params=SAMPLES_2D)
def sample(request):
    return SAMPLES / request.param


@pytest.mark.parametrize("start", ["top", "min-distance"])
def test_sample_carves_exactly(sample, start):
    drawing = cam.load_image(sample)
    assert drawing.warnings == [], sample.name  # the shipped samples keep the rules
    d = cam.digitize(drawing, start=start)
    depths = [3 + 2 * i for i in range(len(d.objects))]
    job = cam.plan(d, depth=depths)
    surface, result, motion = carve_job(job)
    want = expected_surface_2d(d, depths, job.settings)
    # every black pixel is cut to its object's depth, nothing else below the surface
    assert np.array_equal(want > 0, drawing.classes == BLACK)
    assert_surface_equal(surface, want)
    assert motion.final_steps == (0, 0, 0)
    plan = cam.plan_steps(job)
    last_t_s = result.pin_log().t_ns[-1] / 1e9
    assert abs(last_t_s - plan.estimated_time_s) <= 0.01 * plan.estimated_time_s


def test_sample_object_counts_equal_curve_counts():
    import cv2
    for name in SAMPLES_2D:
        drawing = cam.load_image(SAMPLES / name)
        n_curves, _ = cv2.connectedComponents(drawing.black.astype(np.uint8), connectivity=8)
        for start in ("top", "min-distance"):
            assert len(cam.digitize(drawing, start=start).objects) == n_curves - 1, (name, start)


def test_passes_start_at_and_reloaded_matrix_carve_the_same(tmp_path):
    drawing = cam.load_image(SAMPLES / "gear.png")
    d = cam.digitize(drawing, start="min-distance")
    cam.save_digitized(d, tmp_path / "gear.txt")
    again = cam.load_digitized(tmp_path / "gear.txt")
    job = cam.plan(again, depth=[7, 4], passes=3, start_at=(5, 9, 2))
    surface, result, motion = carve_job(job)
    assert_surface_equal(surface, expected_surface_2d(d, [7, 4], job.settings))
    assert motion.final_steps == (0, 0, 0)


def test_thesis_ellipse_dimensions_and_time():
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    rep = cam.image_report(d)
    assert (rep["width_px"], rep["height_px"]) == (286, 144)  # Figure 5.1
    assert rep["width_mm"] == pytest.approx(286 * 8 * 0.0289, abs=1e-3)
    job = cam.plan(d, depth=1)
    plan = cam.plan_steps(job)
    rep = cam.job_report(d, job, plan)
    assert rep["objects"] == 1 and rep["retracts"] == 1
    # diagonal moves: each 1-pixel move is 8 periods of 5 ms, plus travel and Z
    assert rep["estimated_time_s"] > d.n_points * 8 * 0.005
    json.dumps(rep)


SAMPLES_3D = ["disc.png", "pyramid.png", "heart.png", "dumbbell.png", "ring.png"]
PROFILES = ["dome.png", "cone.png", "pyramid.png", "flat.png"]


@pytest.mark.parametrize("name", SAMPLES_3D)
@pytest.mark.parametrize("profile_name", PROFILES)
def test_3d_sample_carves_exactly(name, profile_name):
    from cam.digitize.peel3d import peel_layers
    from cam.digitize.drawing import WHITE

    drawing = cam.load_image(SAMPLES / name)
    assert drawing.kind == "3d" and drawing.warnings == []
    d = cam.digitize(drawing)
    profile = cam.load_profile(ROOT / "profiles" / profile_name)
    job = cam.plan(d, profile=profile)
    surface, result, motion = carve_job(job)
    # target: every black and red pixel at profile(layer), white untouched -- computed independently
    layer = peel_layers(drawing.classes)
    want = np.where(layer > 0, profile.depth_px[np.maximum(layer, 1) - 1], 0) * job.settings.steps_per_px_z
    assert np.all(want[drawing.classes == WHITE] == 0)
    assert_surface_equal(surface, want)
    assert motion.final_steps == (0, 0, 0)
    rep = cam.job_report(d, job, cam.plan_steps(job))
    assert rep["retracts"] <= rep["rings"] + rep["objects"]
    assert rep["layers"] == int(layer.max())
