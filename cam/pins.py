"""The step/direction pin map as data-register bit masks (thesis chapter 3, Tables 3.2/3.3)."""
from __future__ import annotations

import numpy as np

from .settings import MachineSettings

__all__ = ["axis_bits"]


def axis_bits(settings: MachineSettings) -> tuple[np.ndarray, np.ndarray]:
    """(clock_bit_values, dir_bit_values): ``(3,)`` uint8 data-register masks for X, Y, Z."""
    p = settings.pins
    clock = np.array([1 << p.bit("clock_x"), 1 << p.bit("clock_y"), 1 << p.bit("clock_z")], np.uint8)
    direction = np.array([1 << p.bit("dir_x"), 1 << p.bit("dir_y"), 1 << p.bit("dir_z")], np.uint8)
    return clock, direction
