"""The 3D report's object count labels in 16 bits and falls back to 32 when there are more components."""
import numpy as np

from cam.render.report import _components


def test_components_counted_in_16_bits_and_past_them():
    few = np.zeros((64, 64), np.uint8)
    few[10:20, 10:20] = 1
    few[40:50, 40:60] = 1
    assert _components(few) == 3  # the background and two objects
    many = np.zeros((1024, 1024), np.uint8)
    many[::4, ::4] = 1  # 65,536 separate dots: more labels than 16 bits hold
    assert _components(many) == 65_537
