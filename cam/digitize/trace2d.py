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

__all__ = ["trace_curves", "trace_curves_reference", "START_RULES", "NEIGHBOURS_2D"]

START_RULES = ("top", "min-distance")

NEIGHBOURS_2D = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
"""(drow, dcol) in the scan order of Figure 4.13: NW, N, NE, W, E, SW, S, SE."""


def _walk(flat: bytearray, start: int, offsets: tuple[int, ...]) -> list[int]:
    """Greedy trace from ``start`` (already marked traced); marks and returns the pixels it visits."""
    path: list[int] = []
    cur = start
    while True:
        for off in offsets:
            q = cur + off
            if flat[q]:
                flat[q] = 0
                path.append(q)
                cur = q
                break
        else:
            return path


def trace_curves(
    black: np.ndarray,
    *,
    start: str = "top",
    tool_xy_px: tuple[int, int] = (0, 0),
    value: int = 1,
) -> list[np.ndarray]:
    """Trace every pixel of ``black`` equal to ``value`` into ordered curves.

    Compiled; the same result as :func:`trace_curves_reference` (see there for the rules).
    ``black`` is a ``(H, W)`` bool mask (``value`` 1 = True) or a class array (``value`` = BLACK).

    >>> import numpy as np
    >>> m = np.zeros((4, 5), bool); m[1, 1:4] = True   # a 3-pixel dash
    >>> [o.tolist() for o in trace_curves(m, start="min-distance", tool_xy_px=(4, 1))]
    [[[3, 1], [2, 1], [1, 1]]]
    """
    from ._kernels import pad_mask_kernel, trace2d_kernel

    if start not in START_RULES:
        raise ValueError(f"start must be one of {START_RULES}, got {start!r}")
    image = np.ascontiguousarray(black)
    image = image.view(np.uint8) if image.dtype == bool else image.astype(np.uint8, copy=False)
    h, w = image.shape
    wp = w + 2
    flat, scan = pad_mask_kernel(image, np.uint8(value))
    offsets = np.array([dr * wp + dc for dr, dc in NEIGHBOURS_2D], np.int64)
    path, starts = trace2d_kernel(flat, scan, wp, offsets, start == "min-distance", int(tool_xy_px[0]),
                                  int(tool_xy_px[1]))
    xy = np.empty((len(path), 2), np.int32)
    xy[:, 0] = path % wp - 1
    xy[:, 1] = path // wp - 1
    return [xy[a:b] for a, b in zip(starts[:-1], starts[1:])]


def trace_curves_reference(
    black: np.ndarray,
    *,
    start: str = "top",
    tool_xy_px: tuple[int, int] = (0, 0),
) -> list[np.ndarray]:
    """Trace every black pixel of ``black`` into ordered curves.

    Args:
        black: ``(H, W)`` bool mask, indexed ``[row, col]``.
        start: ``"top"`` -- each object starts at the first untraced black
            pixel in scan order; ``"min-distance"`` -- at the untraced black
            pixel nearest (Euclidean) the tool's current position, which is
            the end of the previous object, ties going to scan order.
        tool_xy_px: tool position (x, y) before the first object.

    Returns:
        One ``(n, 2)`` int32 array of ``(x, y)`` pixels per object, in cutting
        order.  Every black pixel appears exactly once.  An open curve runs
        end to end: in ``top`` mode from its end first in scan order, in
        ``min-distance`` mode from its end nearest the tool.

    >>> import numpy as np
    >>> m = np.zeros((4, 5), bool); m[1, 1:4] = True   # a 3-pixel dash
    >>> [o.tolist() for o in trace_curves(m, start="min-distance", tool_xy_px=(4, 1))]
    [[[3, 1], [2, 1], [1, 1]]]
    """
    if start not in START_RULES:
        raise ValueError(f"start must be one of {START_RULES}, got {start!r}")
    black = np.asarray(black, bool)
    h, w = black.shape
    wp = w + 2
    padded = np.zeros((h + 2, wp), np.uint8)
    padded[1:-1, 1:-1] = black
    flat = bytearray(padded.tobytes())
    offsets = tuple(dr * wp + dc for dr, dc in NEIGHBOURS_2D)

    scan = np.flatnonzero(padded)  # scan order: row-major
    scan_rows = scan // wp - 1
    scan_cols = scan % wp - 1
    flat_view = np.frombuffer(flat, np.uint8)  # live view: 0 once traced
    objects: list[np.ndarray] = []
    tool_x, tool_y = tool_xy_px
    cursor = 0  # next candidate in scan order (top mode)
    alive_idx = np.arange(len(scan))  # candidates not yet known traced (min-distance mode)

    while True:
        if start == "top":
            while cursor < len(scan) and not flat[scan[cursor]]:
                cursor += 1
            if cursor == len(scan):
                break
            s = int(scan[cursor])
        else:
            alive_idx = alive_idx[flat_view[scan[alive_idx]] != 0]
            if len(alive_idx) == 0:
                break
            d2 = (scan_cols[alive_idx] - tool_x) ** 2 + (scan_rows[alive_idx] - tool_y) ** 2
            s = int(scan[alive_idx[int(np.argmin(d2))]])
        flat[s] = 0
        arm1 = _walk(flat, s, offsets)
        arm2 = _walk(flat, s, offsets)  # non-empty only when s was mid-curve
        path = arm2[::-1] + [s] + arm1
        if arm2:
            first, last = path[0], path[-1]
            if start == "top":
                flip = last < first  # begin at the end first in scan order
            else:
                def d2_of(p: int) -> int:
                    return (p % wp - 1 - tool_x) ** 2 + (p // wp - 1 - tool_y) ** 2

                flip = d2_of(last) < d2_of(first)
            if flip:
                path.reverse()
        idx = np.asarray(path, np.int64)
        obj = np.empty((len(idx), 2), np.int32)
        obj[:, 0] = idx % wp - 1
        obj[:, 1] = idx // wp - 1
        objects.append(obj)
        tool_x, tool_y = int(obj[-1, 0]), int(obj[-1, 1])
    return objects
