"""The compiled search of the drawing planner's bridges (numba).

A bridge is the shortest 8-connected path inside the material between two
points of a drawing (:func:`cam.job.drawing._route`).  The breadth-first search
ran in Python, about a microsecond per pixel it reached: a 500 x 500
checkerboard, all of it one connected material, took over a minute to plan.
This kernel does the same search in the same order (levels of equal distance,
each pixel's neighbours from the row above to the row below, left to right),
so it finds the same path; a test compares it with the plain-Python search of
``tests/support/references.py``.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .._compiled import entry

__all__ = ["bfs_kernel"]


@entry
@njit(cache=True, nogil=True)
def bfs_kernel(ok, start, goal, max_len, parent):
    """Breadth-first search over the set pixels of ``ok`` from ``start`` to ``goal`` (flat row-major indices).

    Args:
        ok: ``(H, W)`` bool, the pixels a path may step on (``start`` itself need not be one).
        start, goal: flat indices into ``ok``.
        max_len: the longest path (moves) searched for.
        parent: ``(H * W,)`` int32 filled with -2 (unreached); on return, each reached pixel's predecessor
            (-1 at ``start``).

    Returns:
        True when ``goal`` was reached within ``max_len`` moves (follow ``parent`` back from it).
    """
    hh, ww = ok.shape
    queue = np.empty(hh * ww, np.int32)
    parent[start] = -1
    queue[0] = start
    head = 0
    tail = 1
    for _ in range(max_len):
        if head == tail:
            return False
        level_end = tail
        while head < level_end:
            i = queue[head]
            head += 1
            r = i // ww
            c = i - r * ww
            for dr in range(-1, 2):
                rr = r + dr
                if rr < 0 or rr >= hh:
                    continue
                for dc in range(-1, 2):
                    cc = c + dc
                    if (dr != 0 or dc != 0) and 0 <= cc < ww and ok[rr, cc]:
                        j = rr * ww + cc
                        if parent[j] == -2:
                            parent[j] = i
                            if j == goal:
                                return True
                            queue[tail] = j
                            tail += 1
    return False
