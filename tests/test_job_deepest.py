"""Job.deepest_px is the deepest depth asked (the report's depth) without the per-pixel map."""
import pytest

import cam

from conftest import SAMPLES


@pytest.mark.parametrize("name", ["pyramid.png", "gear.png"])
def test_deepest_px_is_the_deepest_of_the_asked_depth_map(name):
    d = cam.digitize(cam.load_image(SAMPLES / name))
    depth = 6 if d.mode == "3d" else [4 + i for i in range(len(d.objects))]
    job = cam.plan(d, depth=depth, start_at=(3, 4, 2), passes=2)
    assert job.deepest_px == int(job.asked_depth_px().max()) > 0


def test_a_streamed_drawing_with_roughing_knows_its_deepest_depth_without_the_map():
    from cam.job.drawing_stream import stream_drawing

    d = cam.digitize(cam.load_image(SAMPLES / "pyramid.png"))
    job = stream_drawing(d, depth=6, tool="ball:1", rough_tool="flat:2", stepdown_mm=0.05)
    assert job.roughing is not None
    assert job.deepest_px == int(job.asked_depth_px().max()) > 0
