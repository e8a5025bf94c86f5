"""Sharp corners for traced sketches: thinning rounds the corner of a thick stroke (issue #32 point 9).

A skeleton of a stroke ``w`` pixels wide cuts a square corner short by about ``w / 4``: at 10 px and more the
traced line passes 2-3 px inside the corner of the drawn centre line.  :func:`sharpen_corners` finds, on each
traced curve, a turn between two straight runs, intersects the two runs' lines, and when the intersection lies
within the stroke's half width of the traced corner it redraws the corner through it: the traced line then
meets at the corner the drawing's centre lines meet at.  Frames: ``(row, col)`` pixels.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from scipy import ndimage

__all__ = ["sharpen_corners", "curve_paths"]

MIN_HALF_WIDTH_PX = 3.0
"""Strokes thinner than twice this keep their corners as thinned (thinning cuts them by a pixel at most)."""
TURN_DEG = 40.0
"""A turn sharper than this between the runs before and after a point makes it a corner candidate."""
STRAIGHT_PX = 1.0
"""Each of the two runs must lie within this of its line (a curve is not a corner)."""

_EIGHT = np.ones((3, 3), bool)


def curve_paths(skel: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """Each 8-connected curve of a thinned mask (no pixel with three neighbours) as ``((N, 2) int (row, col)
    pixels in order, closed)``; a piece that is not a simple path is left out."""
    labels, n = ndimage.label(skel, structure=_EIGHT)
    out = []
    for sl, lab in zip(ndimage.find_objects(labels), range(1, n + 1)):
        if sl is None:
            continue
        pix = np.argwhere(labels[sl] == lab) + np.array([sl[0].start, sl[1].start])
        path = _walk({(int(r), int(c)) for r, c in pix})
        if path is not None:
            out.append(path)
    return out


def _walk(pix: set[tuple[int, int]]) -> "tuple[np.ndarray, bool] | None":
    def nbrs(p: tuple[int, int]) -> list[tuple[int, int]]:
        return [(p[0] + dr, p[1] + dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                if (dr or dc) and (p[0] + dr, p[1] + dc) in pix]

    ends = [p for p in pix if len(nbrs(p)) == 1]
    if any(len(nbrs(p)) > 2 for p in pix) or len(ends) not in (0, 2):
        return None
    start = min(ends) if ends else min(pix)
    order, seen, prev, cur = [start], {start}, None, start
    while True:
        nxt = [q for q in nbrs(cur) if q != prev and q not in seen]
        if not nxt:
            break
        prev, cur = cur, nxt[0]
        order.append(cur)
        seen.add(cur)
    if len(order) != len(pix):
        return None
    return np.asarray(order, np.int64), not ends


def _line_fit(pts: np.ndarray) -> "tuple[np.ndarray, np.ndarray] | None":
    """(a point, unit direction) of the least-squares line through ``pts``, or None when they are not straight."""
    centre = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - centre)
    direction = vt[0]
    off = (pts - centre) @ vt[1]
    return (centre, direction) if np.abs(off).max() <= STRAIGHT_PX else None


def _intersection(a: tuple, b: tuple) -> "np.ndarray | None":
    (p, u), (q, v) = a, b
    m = np.array([u, -v]).T
    if abs(np.linalg.det(m)) < 0.2:  # nearly parallel
        return None
    t = np.linalg.solve(m, q - p)
    return p + t[0] * u


def _corners(path: np.ndarray, closed: bool, k: int) -> list[int]:
    """Indices of the sharpest point of each run of turns over :data:`TURN_DEG` (reach ``k`` either way)."""
    m = len(path)
    idx = np.arange(m) if closed else np.arange(3 * k, m - 3 * k)
    if len(idx) == 0:
        return []
    a = path[(idx - k) % m] if closed else path[idx - k]
    c = path[(idx + k) % m] if closed else path[idx + k]
    u, v = (path[idx] - a).astype(float), (c - path[idx]).astype(float)
    cos = (u * v).sum(axis=1) / np.maximum(np.hypot(*u.T) * np.hypot(*v.T), 1e-9)
    turn = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    sharp = turn > TURN_DEG
    found = []
    runs, nr = ndimage.label(sharp)
    for j in range(1, nr + 1):
        members = np.flatnonzero(runs == j)
        found.append(int(idx[members[np.argmax(turn[members])]]))
    return found


def sharpen_corners(skel: np.ndarray, ink: np.ndarray) -> tuple[np.ndarray, int]:
    """Redraw the rounded corners of thick strokes' curves through their lines' intersection (see the module).

    Args:
        skel: ``(H, W)`` bool thinned curves (no pixel with three neighbours).
        ink: ``(H, W)`` bool the ink they were thinned from (its distance transform gives the half widths).

    Returns:
        The new mask (8-connected curves, not yet minimal: the caller thins staircase corners) and the number of
        corners redrawn.  A corner whose new line would touch another curve is left as it was.
    """
    half = ndimage.distance_transform_edt(ink)
    labels, _ = ndimage.label(skel, structure=_EIGHT)
    out = skel.copy()
    done = 0
    for path, closed in curve_paths(skel):
        r_px = float(np.median(half[path[:, 0], path[:, 1]]))
        if r_px < MIN_HALF_WIDTH_PX:
            continue
        k = int(math.ceil(r_px)) + 2
        m = len(path)
        if m < 6 * k + 1:
            continue
        own = labels[path[0, 0], path[0, 1]]
        for c in _corners(path, closed, k):
            before = path[[(c - j) % m for j in range(3 * k, k - 1, -1)]].astype(float)
            after = path[[(c + j) % m for j in range(k, 3 * k + 1)]].astype(float)
            la, lb = _line_fit(before), _line_fit(after)
            x = None if la is None or lb is None else _intersection(la, lb)
            if x is None or np.hypot(*(x - path[c])) > r_px + 1.0:
                continue
            _redraw(out, labels, own, path, c, k, x, closed)
            done += 1
    return out, done


def _redraw(out: np.ndarray, labels: np.ndarray, own: int, path: np.ndarray, c: int, k: int, x: np.ndarray,
            closed: bool) -> None:
    """Replace the path's pixels strictly between ``c - k`` and ``c + k`` by lines through ``x``."""
    m = len(path)
    a, b = path[(c - k) % m], path[(c + k) % m]
    xr = np.rint(x).astype(np.int64)
    canvas = np.zeros(out.shape, np.uint8)
    cv2.line(canvas, (int(a[1]), int(a[0])), (int(xr[1]), int(xr[0])), 1, 1, cv2.LINE_8)
    cv2.line(canvas, (int(xr[1]), int(xr[0])), (int(b[1]), int(b[0])), 1, 1, cv2.LINE_8)
    new = canvas.astype(bool)
    near = cv2.dilate(canvas, np.ones((3, 3), np.uint8)).astype(bool)
    if np.any(near & (labels > 0) & (labels != own)):  # it would touch another curve: leave the corner
        return
    inner = [(c + j) % m for j in range(-k + 1, k)]
    out[path[inner, 0], path[inner, 1]] = False
    out |= new
