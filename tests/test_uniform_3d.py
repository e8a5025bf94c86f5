"""A uniform depth on a 3D drawing (issue #16 point 4): --depth N cuts every layer at N Z pixels."""
import numpy as np
import pytest

import cam
from cam.digitize.peel3d import peel_layers
from cam.kinds.jobs import JobOptions, prepare_job

from conftest import ROOT, SAMPLES, assert_surface_equal, carve_job
from test_cli import assert_one_line_error, cli


def _want_pocket(name: str, depth_px: int, steps_z: int = 1) -> np.ndarray:
    layer = peel_layers(cam.load_image(SAMPLES / name).classes)
    return np.where(layer > 0, depth_px * steps_z, 0)


@pytest.mark.parametrize("name", ["disc.png", "dumbbell.png"])
def test_plan_with_one_depth_cuts_a_flat_pocket(name):
    d = cam.digitize(cam.load_image(SAMPLES / name))
    surface, _, _ = carve_job(cam.plan(d, depth=7))
    assert_surface_equal(surface, _want_pocket(name, 7))


def test_cli_depth_on_3d_drawing_carves_a_flat_bottom(tmp_path):
    proc = cli("drill", SAMPLES / "heart.png", "--depth", "6", "--pin-log", tmp_path / "p.csv", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    motion = cam.decode_pin_log(tmp_path / "p.csv")
    want = _want_pocket("heart.png", 6)
    assert_surface_equal(cam.carve(motion, want.shape), want)


def test_prepare_job_cut_depth_mm_on_3d_is_uniform():
    job = prepare_job(SAMPLES / "disc.png", JobOptions(cut_depth_mm=0.157))  # 10 Z pixels of 0.0157 mm
    assert job.depth_mm == pytest.approx(0.157)
    surface = cam.carve(cam.decode_pin_log(cam.PinLog(job.steps.t_ns, job.steps.data, job.steps.strobe)), (101, 101))
    assert_surface_equal(surface, _want_pocket("disc.png", 10))


def test_3d_depth_errors():
    assert_one_line_error(cli("drill", SAMPLES / "disc.png", "--depth", "3,4"), "takes one --depth for every layer")
    assert_one_line_error(cli("drill", SAMPLES / "disc.png", "--depth", "3", "--profile", ROOT / "profiles" / "dome.png"),
                          "give a 3D drawing's depth once")
    d = cam.digitize(cam.load_image(SAMPLES / "disc.png"))
    with pytest.raises(cam.PlanError, match="flat-bottomed pocket"):
        cam.plan(d)


def test_2d_default_depth_is_still_10():
    job = prepare_job(SAMPLES / "ellipse.png")
    assert job.depth_mm == pytest.approx(10 * 0.0157)
