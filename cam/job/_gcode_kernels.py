"""The compiled loop of the G-code planner (numba): a program's straight moves become job rows.

:func:`cam.job.gcode.plan_gcode` plans every straight move period by period
(each period to the step nearest its exact path point); this kernel does that
for a block of consecutive straight moves and merges the periods that step the
same way into one row each.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .._compiled import entry

__all__ = ["straight_rows_kernel"]


@entry
@njit(cache=True, nogil=True)
def straight_rows_kernel(starts, d, n, at):
    """The job rows of consecutive straight moves, one per run of periods that step the same way.

    Period ``k`` (1..``n[i]``) of move ``i`` goes to the nearest step to its exact path point,
    ``floor(starts[i] + d[i] * (k / n[i]) + 0.5)`` (the arithmetic of :func:`cam.job.gcode._periods`); consecutive
    periods of one move that step the same way (each axis -1, 0 or +1) make one row.

    Args:
        starts, d: ``(W, 3)`` float64 exact start of each move and its way, in steps; n: ``(W,)`` int64 periods of
            each move (>= 1); at: ``(3,)`` int64 the rounded position before the first move.

    Returns:
        ``(points, count, move_of, first)``: ``(R, 3)`` int64 the position at each row's end, ``(R,)`` int64 its
        periods, ``(R,)`` int64 its move, ``(R,)`` bool whether it begins its move.
    """
    total = 0
    for i in range(n.shape[0]):
        total += n[i]
    points = np.empty((total, 3), np.int64)
    count = np.empty(total, np.int64)
    move_of = np.empty(total, np.int64)
    first = np.empty(total, np.bool_)
    r = -1
    p0, p1, p2 = at[0], at[1], at[2]
    s0, s1, s2 = np.int64(0), np.int64(0), np.int64(0)
    for i in range(n.shape[0]):
        ni = n[i]
        for k in range(1, ni + 1):
            q = k / ni
            x = np.int64(np.floor(starts[i, 0] + d[i, 0] * q + 0.5))
            y = np.int64(np.floor(starts[i, 1] + d[i, 1] * q + 0.5))
            z = np.int64(np.floor(starts[i, 2] + d[i, 2] * q + 0.5))
            a0, a1, a2 = x - p0, y - p1, z - p2
            if k == 1 or a0 != s0 or a1 != s1 or a2 != s2:
                r += 1
                count[r] = 0
                move_of[r] = i
                first[r] = k == 1
                s0, s1, s2 = a0, a1, a2
            count[r] += 1
            points[r, 0], points[r, 1], points[r, 2] = x, y, z
            p0, p1, p2 = x, y, z
    return points[:r + 1].copy(), count[:r + 1].copy(), move_of[:r + 1].copy(), first[:r + 1].copy()
