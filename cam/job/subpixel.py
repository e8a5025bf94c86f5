"""The finer finishing pass of a relief cut with a real tool: tool positions between pixel centres.

With its axis over pixel centres only, a ball or V cutter on a slope leaves
material that a position a fraction of a pixel away would take: the drop-cutter
depth changes between centres, and the machine's Z steps round every depth up
(shallower) by up to one Z pixel, differently at different positions.  This
pass looks at every position of a grid ``k`` times finer than the pixels
(``k`` divides the machine's steps per pixel, at most :data:`MAX_K`; the finest whose useful positions
are no more than the pixels cut, see :func:`rest_positions`), finds
those whose drop-cutter depth (:func:`sub_depth_px`: the same rule, with the
axis there) cuts some pixel centre at least :data:`MIN_GAIN_ZPX` deeper than
the pixel-centre pass does, and cuts them: level by level, shallowest first,
each level traced into curves, with the planner's rules (a move between
positions side by side at a depth both ends allow, a diagonal lifted to its
midpoint's depth, anything else retracts or follows a route through positions
allowed at least that deep).

The rules stay safe on the finer grid: every pixel centre is a point of it, so
a move between two positions side by side is nearest every pixel centre at
one of its ends, and a diagonal one at its midpoint (as for pixels,
:func:`cam.tool.corner_depth_px`).

Frames: the finer grid's position ``(a, b)`` (row, column) has its axis at
pixel coordinates ``(a / k, b / k)`` (pixel centres at whole numbers); depths
in Z pixels below the surface.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from ..digitize.trace2d import trace_curves
from ..settings import MachineSettings
from ..tool import Tool, footprint_px, lowest_under_footprint
from .drill_order import nearest_neighbour_order

__all__ = ["MAX_K", "MIN_GAIN_ZPX", "finer_grid", "finer_grids", "sub_depth_px", "rest_positions", "nearest_first"]

MAX_K = 8
"""The finest grid looked at: an eighth of a pixel (every step of the thesis machine's 8 per pixel)."""
BUDGET_BELOW_K = 4
"""Grids up to this fine (a quarter pixel) are used whatever they find; finer ones only within the budget."""
MAX_CELLS = 1 << 24
"""The most positions of a finer grid looked at (its maps are int32: 64 MB each); a larger relief gets a
coarser grid, and none beyond it at half a pixel (with a warning).  The bound is on the relief's positions
alone: a job held in memory and one made a piece at a time (:mod:`cam.job.drawing_stream`, which plans both)
get the same pass."""
MIN_GAIN_ZPX = 0.25
"""A position is cut when it takes at least this much more (Z pixels) off some pixel centre."""


def finer_grids(settings: MachineSettings) -> list[int]:
    """The grids the machine reaches exactly, finest first: every ``k`` > 1 that divides its steps per pixel,
    at most :data:`MAX_K` (none: no finer pass)."""
    spp = int(settings.steps_per_px_xy)
    return [k for k in range(min(MAX_K, spp), 1, -1) if spp % k == 0]


def finer_grid(settings: MachineSettings) -> int:
    """``k``: the finest grid of :func:`finer_grids` (1: none)."""
    return max(finer_grids(settings), default=1)


def sub_depth_px(depth_px: np.ndarray, tool: Tool, px_mm: float, zpx_mm: float, k: int,
                 offset: float = 0.0) -> np.ndarray:
    """The drop-cutter depth (as :func:`cam.tool.drop_depth_px`, whole Z pixels rounded down once, >= 0; int32) with
    the axis at every position ``((a + offset) / k, (b + offset) / k)`` pixels.

    Args:
        depth_px: ``(H, W)`` int target depth of each pixel centre (Z pixels; outside: the surface).
        offset: 0 for the finer grid's positions ``(H k, W k)``; -0.5 for the midpoints of its diagonal moves,
            ``(H k + 1, W k + 1)``, entry ``(a, b)`` between positions ``(a - 1, b - 1)`` and ``(a, b)``.
    """
    d = np.asarray(depth_px, np.int64)
    h, w = d.shape
    extra = 1 if offset else 0
    out = np.zeros((h * k + extra, w * k + extra), np.int32)
    for sy in range(k):
        for sx in range(k):
            dy, dx, rise = footprint_px(tool, px_mm, zpx_mm, centre=((sx + offset) / k, (sy + offset) / k))
            rows, cols = len(range(sy, h * k + extra, k)), len(range(sx, w * k + extra, k))
            low = lowest_under_footprint(d, dy, dx, rise, (h + extra, w + extra), 0)
            out[sy::k, sx::k] = np.clip(low[:rows, :cols], 0, np.iinfo(np.int32).max)
    return out


def rest_positions(depth_px: np.ndarray, reach_px: np.ndarray, tool: Tool, settings: MachineSettings,
                   start_xy_px: tuple[int, int] = (0, 0)) -> Optional[tuple[np.ndarray, np.ndarray, np.ndarray, int]]:
    """The finer pass on the finest grid whose useful positions are no more than the pixels cut (a machine-time
    budget: a ball on a curved relief finds many on an eighth-pixel grid, a flat end mill few), and on a
    quarter-pixel grid (:data:`BUDGET_BELOW_K`) whatever it finds:
    ``(targets (M, 3), allowed (H k, W k), corners (H k + 1, W k + 1), k)``, or None (no grid fits
    :data:`MAX_CELLS`, or the machine has none).

    Args:
        depth_px: ``(H, W)`` target depth of each pixel centre (Z pixels).
        reach_px: ``(H, W)`` float: how deep the pixel-centre pass cuts each pixel centre
            (:func:`cam.tool.reach_depth_px`).
        start_xy_px: where the tool comes from (the pixel-centre pass's last pixel).

    Returns:
        ``targets``: finer-grid positions ``(b, a, depth)`` (column, row, Z pixels) in cutting order: traced
        into curves, each starting at the end nearest where the one before ended (the material left is
        thinner than a few Z pixels, so no order by depth is needed: each position is cut at its own
        drop-cutter depth); ``allowed``: the drop-cutter depth at every position (where routes may run);
        ``corners``: at the midpoints of its diagonal moves.
    """
    d = np.asarray(depth_px, np.int64)
    h, w = d.shape
    grids = [k for k in finer_grids(settings) if h * w * k * k <= MAX_CELLS]
    budget = int(np.count_nonzero(d > 0))
    px_mm, zpx_mm = settings.px_to_mm_xy(1), settings.px_to_mm_z(1)
    for n, k in enumerate(grids):
        allowed, useful = _useful(d, np.asarray(reach_px, np.float64), tool, settings, k)
        if np.count_nonzero(useful) <= budget or k <= BUDGET_BELOW_K or n == len(grids) - 1:
            chunks = []
            for curve in nearest_first(trace_curves(useful), (start_xy_px[0] * k, start_xy_px[1] * k)):
                block = np.empty((len(curve), 3), np.int64)
                block[:, :2] = curve
                block[:, 2] = allowed[curve[:, 1], curve[:, 0]]
                chunks.append(block)
            targets = np.concatenate(chunks) if chunks else np.zeros((0, 3), np.int64)
            return targets, allowed, sub_depth_px(d, tool, px_mm, zpx_mm, k, offset=-0.5), k
    return None


def _useful(d: np.ndarray, reach: np.ndarray, tool: Tool, settings: MachineSettings, k: int
            ) -> tuple[np.ndarray, np.ndarray]:
    """``(allowed (H k, W k), useful (H k, W k) bool)``: the drop-cutter depth at every position of the grid
    ``k`` and whether it takes at least :data:`MIN_GAIN_ZPX` more off some pixel centre than ``reach``."""
    h, w = d.shape
    px_mm, zpx_mm = settings.px_to_mm_xy(1), settings.px_to_mm_z(1)
    allowed = sub_depth_px(d, tool, px_mm, zpx_mm, k)
    useful = np.zeros(allowed.shape, bool)
    for sy in range(k):
        for sx in range(k):
            if sy == 0 and sx == 0:
                continue  # the pixel centres: cut already
            a = allowed[sy::k, sx::k].astype(np.float64)  # (H, W): the position (i + sy/k, j + sx/k)
            dy, dx, rise = footprint_px(tool, px_mm, zpx_mm, centre=(sx / k, sy / k))
            gain = np.full((h, w), -np.inf)
            for oy, ox, r in zip(dy.tolist(), dx.tolist(), rise.tolist()):
                # the position over pixel (i, j) cuts pixel (i + oy, j + ox) down to a - r
                y0, y1, x0, x1 = max(0, -oy), min(h, h - oy), max(0, -ox), min(w, w - ox)
                if y0 >= y1 or x0 >= x1:
                    continue
                g = a[y0:y1, x0:x1] - r - reach[y0 + oy:y1 + oy, x0 + ox:x1 + ox]
                np.maximum(gain[y0:y1, x0:x1], g, out=gain[y0:y1, x0:x1])
            useful[sy::k, sx::k] = (gain >= MIN_GAIN_ZPX) & (a > 0)
    return allowed, useful


def nearest_first(curves: list[np.ndarray], start_xy: tuple[int, int]) -> list[np.ndarray]:
    """``curves`` (each ``(n, 2)`` (x, y)) in a short order: the drill planner's nearest-neighbour path
    (:func:`cam.job.drill_order.nearest_neighbour_order`, compiled) through the middles of their ends from
    ``start_xy``, each curve run from its end nearer where the one before ended.

    >>> c = [np.array([[9, 0], [8, 0]]), np.array([[0, 0], [1, 0]]), np.array([[5, 0], [4, 0]])]
    >>> [x.tolist() for x in nearest_first(c, (0, 0))]
    [[[0, 0], [1, 0]], [[4, 0], [5, 0]], [[8, 0], [9, 0]]]
    """
    if not curves:
        return []
    ends = np.array([[c[0][0], c[0][1], c[-1][0], c[-1][1]] for c in curves], np.float64)
    order = nearest_neighbour_order((ends[:, :2] + ends[:, 2:]) / 2, (float(start_xy[0]), float(start_xy[1])))
    out: list[np.ndarray] = []
    x, y = start_xy
    for i in order.tolist():
        c = curves[i]
        first = max(abs(int(c[0][0]) - x), abs(int(c[0][1]) - y))
        last = max(abs(int(c[-1][0]) - x), abs(int(c[-1][1]) - y))
        c = c if first <= last else c[::-1]
        out.append(c)
        x, y = int(c[-1][0]), int(c[-1][1])
    return out


