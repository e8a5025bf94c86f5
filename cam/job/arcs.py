"""Fitting lines and arcs to a path of points, within a tolerance (G-code out, issue #30 point 4).

A job's cutting path is a polyline: a traced curve or a relief row is thousands of short steps.  G-code can say
the same path in far fewer blocks: a run of points that lie within ``tol_mm`` of one straight segment is one
``G1``, a run that lies within ``tol_mm`` of one circular arc in the XY plane (at one height) is one ``G2``/``G3``.

:func:`fit_path` is greedy: from the first point of what is left it takes the longest run that a line fits, and
the longest that an arc fits (found by doubling the run, then halving back), and takes the arc only when it
reaches :data:`ARC_COST_LINES` times as far as the line (an arc's block is that much longer), and goes on from
that run's end.  Each segment ends on a point of the path, so the fitted path
passes through every point it keeps.  What is checked, for every run taken:

* a line: every point of the run within ``tol_mm`` of the segment from its first point to its last (3D);
* an arc: the circle through the run's first, middle and last point (XY, every point of the run at the first
  one's Z); every point's distance from the circle, plus the largest sagitta of a chord between consecutive
  points (the arc bulges out of the chord by that much), at most ``tol_mm``; the points go round the centre one
  way, each less than half a turn after the one before and all of them less than a full turn (an arc that
  only that stopped, a closed circle, is taken to its middle point, so the rest of the circle is one more arc
  and not an arc a chord short of closing and a line); the radius at
  most ``max_radius_mm`` (a flatter arc is a line to every controller).

So every point of the fitted path lies within ``tol_mm`` of the polyline and every point of the polyline within
``tol_mm`` of the fitted path.  Where the polyline's chords stand for arcs of the source (``on_arc``: an HPGL
circle drawn as chords), the path there is those arcs: an arc is held to the chords' ends only (their
sagitta is not counted), so it lies within ``tol_mm`` of the source's circle rather than of its chords.  Frames: any right-handed mm frame (``ccw`` is counter-clockwise seen from +Z, a
``G3`` in G-code's XY plane).  Pure computation, no I/O.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

__all__ = ["Segment", "fit_path", "arc_centre_for_ends", "DEFAULT_ARC_TOLERANCE_MM", "MAX_RADIUS_MM"]

DEFAULT_ARC_TOLERANCE_MM = 0.01
"""``cam export --arc-tolerance``'s default: 10 micrometres."""
MAX_RADIUS_MM = 1000.0
"""The largest radius an arc is written with (a flatter run is a line)."""
ARC_COST_LINES = 1.8
"""An arc is taken only when it reaches this many times as many points as a line from the same point: its
block (``G2 X Y I J``) is about that many times as long as a line's (``G1 X Y``)."""


@dataclass(frozen=True)
class Segment:
    """One fitted block: from the end of the one before (or the path's first point) to point ``end`` of the path.

    Attributes:
        end: index of the path's point the segment ends on.
        kind: ``"line"``, ``"cw"`` (G2) or ``"ccw"`` (G3).
        centre_mm: an arc's centre (x, y) in the path's frame; None for a line.
    """

    end: int
    kind: str
    centre_mm: Optional[tuple[float, float]] = None


def _line_ok(p: np.ndarray, i: int, j: int, tol_mm: float) -> bool:
    """Every point of ``p[i..j]`` within ``tol_mm`` of the segment ``p[i]``-``p[j]``."""
    if j - i < 2:
        return True
    a, b = p[i], p[j]
    q = p[i + 1:j]
    d = b - a
    dd = float(d @ d)
    if dd == 0.0:
        dist = np.linalg.norm(q - a, axis=1)
    else:
        t = np.clip((q - a) @ d / dd, 0.0, 1.0)
        dist = np.linalg.norm(q - (a + t[:, None] * d), axis=1)
    return bool(dist.max() <= tol_mm)


def _circle(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> Optional[tuple[float, float, float]]:
    """Centre (x, y) and radius of the circle through three XY points; None when they are (nearly) in a line."""
    ax, ay = a
    bx, by = b
    cx, cy = c
    den = 2.0 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    scale = max(abs(bx - ax), abs(by - ay), abs(cx - ax), abs(cy - ay), 1e-12)
    if abs(den) <= 1e-12 * scale * scale:
        return None
    a2, b2, c2 = ax * ax + ay * ay, bx * bx + by * by, cx * cx + cy * cy
    ux = (a2 * (by - cy) + b2 * (cy - ay) + c2 * (ay - by)) / den
    uy = (a2 * (cx - bx) + b2 * (ax - cx) + c2 * (bx - ax)) / den
    return ux, uy, math.hypot(ax - ux, ay - uy)


def _arc_fit(p: np.ndarray, i: int, j: int, tol_mm: float, max_radius_mm: float,
             on_arc: Optional[np.ndarray] = None, max_sweep_rad: float = 2 * math.pi - 1e-6) -> Optional[Segment]:
    """The arc through ``p[i..j]`` within ``tol_mm`` (see the module's rules), or None; ``on_arc[k]``: the path
    from ``p[k - 1]`` to ``p[k]`` is an arc of the source (its chord's sagitta is not counted)."""
    if j - i < 2:
        return None
    run = p[i:j + 1]
    if float(np.abs(run[:, 2] - run[0, 2]).max()) > 1e-9:
        return None
    xy = run[:, :2]
    k = j - i
    closed = bool(np.all(xy[0] == xy[-1]))  # a whole circle (asked with max_sweep_rad above a full turn)
    fit = _circle(xy[0], xy[k // 3], xy[2 * k // 3]) if closed else _circle(xy[0], xy[k // 2], xy[-1])
    if fit is None:
        return None
    ux, uy, r = fit
    if r > max_radius_mm:
        return None
    v = xy - (ux, uy)
    radial = float(np.abs(np.hypot(v[:, 0], v[:, 1]) - r).max())
    cross = v[:-1, 0] * v[1:, 1] - v[:-1, 1] * v[1:, 0]
    dot = (v[:-1] * v[1:]).sum(axis=1)
    turn = np.arctan2(cross, dot)  # signed angle from each point to the next, seen from the centre
    total = float(turn.sum())
    sign = 1.0 if total > 0 else -1.0
    if not (sign * turn > 0).all() or abs(total) >= max_sweep_rad:
        return None
    chords = np.abs(turn) if on_arc is None else np.abs(turn)[~on_arc[i + 1:j + 1]]
    sagitta = r * (1.0 - math.cos(float(chords.max()) / 2.0)) if len(chords) else 0.0
    if radial + sagitta > tol_mm:
        return None
    return Segment(j, "ccw" if sign > 0 else "cw", (float(ux), float(uy)))


def _longest(i: int, n: int, ok: Callable[[int], bool], first: int) -> int:
    """The largest ``j`` (``first <= j < n``) with ``ok(j)``, searched by doubling then halving (``ok(first)`` is
    taken as true); ``first - 1`` when ``ok(first)`` fails."""
    if first >= n or not ok(first):
        return first - 1
    lo, step = first, 2 * (first - i)
    while True:
        hi = min(i + step, n - 1)
        if hi <= lo:
            return lo
        if not ok(hi):
            break
        lo = hi
        if hi == n - 1:
            return lo
        step *= 2
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo


def fit_path(points_mm: np.ndarray, tol_mm: float = DEFAULT_ARC_TOLERANCE_MM, *,
             max_radius_mm: float = MAX_RADIUS_MM, on_arc: Optional[np.ndarray] = None) -> list[Segment]:
    """Lines and XY arcs through ``points_mm`` (``(N, 3)`` mm, N >= 1), each within ``tol_mm`` of the polyline.

    Returns the segments in order; the first starts at ``points_mm[0]``, each ends on a point of the path, the
    last on its last point.  Give it no two equal consecutive points (an arc never spans them).

    ``on_arc``: ``(N,)`` bool, True at ``k`` where the path from point ``k - 1`` to point ``k`` stands for an
    arc of the source that passes through both (an HPGL ``CI``/``AA``/``AR`` drawn as chords): the path there
    is the arc, not its chord, so an arc fitted over it is held to its points only (every point within
    ``tol_mm`` of the fitted circle, the chord's sagitta not counted).

    >>> p = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0.001, 0]])
    >>> fit_path(p, 0.01)
    [Segment(end=3, kind='line', centre_mm=None)]
    """
    if not tol_mm > 0:
        raise ValueError(f"the arc tolerance must be > 0 mm, got {tol_mm!r}")
    full = np.asarray(points_mm, np.float64).reshape(-1, 3)
    # a point in the middle of a straight run (the same direction before and after it) changes nothing: fit
    # the others (far fewer checks on rasters), and give the segments' ends as indices of all the points
    d = np.diff(full, axis=0)
    middle = np.zeros(len(full), bool)
    if len(d) > 1:
        cross = np.cross(d[:-1], d[1:])
        scale = np.linalg.norm(d[:-1], axis=1) * np.linalg.norm(d[1:], axis=1)
        middle[1:-1] = (np.linalg.norm(cross, axis=1) <= 1e-12 * np.maximum(scale, 1e-300)) & \
            ((d[:-1] * d[1:]).sum(axis=1) > 0)
    index = np.flatnonzero(~middle)
    p = full[index]
    arcs = None
    if on_arc is not None:  # a kept chord stands for an arc when every chord it joins does
        plain = np.concatenate([[0], np.cumsum(~np.asarray(on_arc, bool).reshape(-1)[1:])])
        arcs = np.zeros(len(index), bool)
        arcs[1:] = plain[index[1:]] == plain[index[:-1]]
    n = len(p)
    segments: list[Segment] = []
    i = 0
    while i < n - 1:
        j_line = _longest(i, n, lambda j: _line_ok(p, i, j, tol_mm), i + 1)
        j_arc = _longest(i, n, lambda j: _arc_fit(p, i, j, tol_mm, max_radius_mm, arcs) is not None, i + 2)
        arc = _arc_fit(p, i, j_arc, tol_mm, max_radius_mm, arcs) if j_arc - i > ARC_COST_LINES * (j_line - i) \
            else None  # _longest found j_arc fitting, so None here means lines are cheaper
        if arc is not None and j_arc + 1 < n and \
                _arc_fit(p, i, j_arc + 1, tol_mm, max_radius_mm, arcs, math.inf) is not None:
            half = (i + j_arc + 1) // 2  # stopped by the full turn only: half now, the rest closes it
            half_arc = _arc_fit(p, i, half, tol_mm, max_radius_mm, arcs)
            if half_arc is not None:  # (a circle through other points of the half may miss the tolerance)
                j_arc, arc = half, half_arc
        if arc is not None:
            segments.append(Segment(int(index[j_arc]), arc.kind, arc.centre_mm))
            i = j_arc
        else:
            segments.append(Segment(int(index[j_line]), "line"))
            i = j_line
    return segments


def arc_centre_for_ends(start_xy: tuple[float, float], end_xy: tuple[float, float],
                        centre_xy: tuple[float, float]) -> tuple[float, float]:
    """``centre_xy`` moved onto the perpendicular bisector of ``start_xy``-``end_xy`` (the written, rounded
    ends), so the arc's radius at its start and its end agree as controllers require (grbl: 0.005 mm)."""
    sx, sy = start_xy
    ex, ey = end_xy
    mx, my = (sx + ex) / 2, (sy + ey) / 2
    dx, dy = ex - sx, ey - sy
    length = math.hypot(dx, dy)
    if length == 0.0:
        return centre_xy
    nx, ny = -dy / length, dx / length
    k = (centre_xy[0] - mx) * nx + (centre_xy[1] - my) * ny
    return mx + k * nx, my + k * ny
