"""2D digitizing (thesis 4.1.4.2): black 1-pixel curves to ordered pixel paths.

The image is scanned row by row, top to bottom, each row left to right.  A
trace steps to the first untraced black 8-neighbour in the order of Figure
4.13::

    1 2 3        NW N  NE
    4 X 5   =    W  X  E
    6 7 8        SW S  SE

and stops when none is left.  Beyond the thesis: when the trace stops and
its start pixel still has an untraced neighbour, the start lay in the middle
of an open curve; the other arm is traced too and the two arms are joined,
so that every curve is one object running from one end to the other (the
thesis counts 3 objects for the 2 curves of Figure 4.14).
"""
from __future__ import annotations

import numpy as np

from ..choices import START_RULES
from ._kernels import pad_mask_kernel, trace2d_kernel

__all__ = ["trace_curves", "START_RULES", "NEIGHBOURS_2D"]

NEIGHBOURS_2D = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
"""(drow, dcol) in the scan order of Figure 4.13: NW, N, NE, W, E, SW, S, SE."""


def trace_curves(
    black: np.ndarray,
    *,
    start: str = "top",
    tool_xy_px: tuple[int, int] = (0, 0),
    value: int = 1,
) -> list[np.ndarray]:
    """Trace every pixel of ``black`` equal to ``value`` into ordered curves.

    Compiled (tests compare it with a plain-Python reference).

    Args:
        black: ``(H, W)`` bool mask (``value`` 1 = True) or a class array (``value`` = BLACK),
            indexed ``[row, col]``.
        start: ``"top"`` -- each object starts at the first untraced black
            pixel in scan order; ``"min-distance"`` -- at the untraced black
            pixel nearest (Euclidean) the tool's current position, which is
            the end of the previous object, ties going to scan order;
            ``"thesis"`` -- the thesis's own Min Distance rule (4.1.4.2): at
            the untraced black pixel nearest the origin, ``tool_xy_px``, for
            every object (the objects then come in order of that distance).
        tool_xy_px: tool position (x, y) before the first object (the origin
            of ``"thesis"``).

    Returns:
        One ``(n, 2)`` int32 array of ``(x, y)`` pixels per object, in cutting
        order.  Every black pixel appears exactly once.  An open curve runs
        end to end: in ``top`` mode from its end first in scan order, in
        ``min-distance`` mode from its end nearest the tool, in ``thesis``
        mode from its end nearest the origin.

    >>> import numpy as np
    >>> m = np.zeros((4, 5), bool); m[1, 1:4] = True   # a 3-pixel dash
    >>> [o.tolist() for o in trace_curves(m, start="min-distance", tool_xy_px=(4, 1))]
    [[[3, 1], [2, 1], [1, 1]]]
    """
    if start not in START_RULES:
        raise ValueError(f"start must be one of {START_RULES}, got {start!r}")
    image = np.ascontiguousarray(black)
    image = image.view(np.uint8) if image.dtype == bool else image.astype(np.uint8, copy=False)
    h, w = image.shape
    wp = w + 2
    flat, scan = pad_mask_kernel(image, np.uint8(value))
    offsets = np.array([dr * wp + dc for dr, dc in NEIGHBOURS_2D], np.int64)
    path, starts = trace2d_kernel(flat, scan, wp, offsets, start != "top", int(tool_xy_px[0]),
                                  int(tool_xy_px[1]), start == "thesis")
    xy = np.empty((len(path), 2), np.int32)
    xy[:, 0] = path % wp - 1
    xy[:, 1] = path // wp - 1
    return [xy[a:b] for a, b in zip(starts[:-1], starts[1:])]


