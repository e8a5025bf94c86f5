"""A planner's inner rule, broken, is a one-line error naming the file and line, not a bare assert (issue #32
point 4)."""
import numpy as np
import pytest

from cam.errors import CamError
from cam.job.gcode import CUT, _Moves


def test_a_move_stepping_an_axis_twice_in_one_period_is_a_named_error():
    moves = _Moves()
    moves.motion(np.array([[1, 0, 0], [2, 1, 0]], np.int64), 5_000_000, CUT, "part.ngc:12")
    with pytest.raises(CamError, match=r"^part\.ngc:13: .*more than once in one step period"):
        moves.motion(np.array([[4, 1, 0]], np.int64), 5_000_000, CUT, "part.ngc:13")
