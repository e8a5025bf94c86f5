"""Compiled steps of the SVG planner (numba): the duplicate search and the cutting order.

Both were Python loops over the strokes (one KD-tree query per stroke, one
greedy pass over the near pairs of two million pieces): a 50,000-circle
halftone spent 7 s in them (issue #32 point 5).  These kernels make the same
decisions with the same floating-point arithmetic (``math.hypot`` is the C
library's ``hypot``, as ``np.hypot`` is), so :mod:`cam.job.svg` plans the
same job; tests compare them with plain numpy searches of every pair.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._compiled import entry
from .drill_order import _grid, _grid_remove

__all__ = ["duplicate_pieces_kernel", "nearest_order_kernel"]


@entry
@njit(cache=True, nogil=True)
def duplicate_pieces_kernel(a, b, near):
    """Which pieces trace an earlier piece that is kept.

    Args:
        a, b: ``(K, 2)`` float64, each piece's two ends (in file order), finite numbers.
        near: the largest difference (in x and in y, each end) of two pieces that trace each other; a power
            of two.

    Returns:
        ``(K,)`` bool: piece ``h`` is dropped when some piece ``l < h`` that is not dropped has
        ``|a[l] - a[h]| <= near`` and ``|b[l] - b[h]| <= near`` (each coordinate), or the same with ``a[l]`` and
        ``b[l]`` swapped (the piece the other way round).
    """
    k = a.shape[0]
    gone = np.zeros(k, np.bool_)
    if k < 2:
        return gone
    # a grid of cells of side `near` times a power of two (so that x / side is exact), about one piece end a
    # cell: the ends of two pieces that trace each other lie in the same or neighbouring cells
    lo_x = np.inf
    hi_x = -np.inf
    lo_y = np.inf
    hi_y = -np.inf
    for r in range(k):
        lo_x = min(lo_x, a[r, 0], b[r, 0])
        hi_x = max(hi_x, a[r, 0], b[r, 0])
        lo_y = min(lo_y, a[r, 1], b[r, 1])
        hi_y = max(hi_y, a[r, 1], b[r, 1])
    side = near
    while ((hi_x - lo_x) / side + 1.0) * ((hi_y - lo_y) / side + 1.0) > 2.0 * k + 16.0:
        side *= 2.0
    cx0 = np.floor(lo_x / side)
    cy0 = np.floor(lo_y / side)
    gx = np.int64(np.floor(hi_x / side) - cx0) + 1
    gy = np.int64(np.floor(hi_y / side) - cy0) + 1
    cell_of = np.empty(2 * k, np.int64)  # each piece by its first end (r < k), then by its second (r - k)
    start = np.zeros(gx * gy + 1, np.int64)
    for r in range(2 * k):
        p = r if r < k else r - k
        x = a[p, 0] if r < k else b[p, 0]
        y = a[p, 1] if r < k else b[p, 1]
        c = np.int64(np.floor(y / side) - cy0) * gx + np.int64(np.floor(x / side) - cx0)
        cell_of[r] = c
        start[c + 1] += 1
    for c in range(gx * gy):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(2 * k, np.int64)
    for r in range(2 * k):
        items[fill[cell_of[r]]] = r
        fill[cell_of[r]] += 1
    for h in range(1, k):
        cx = np.int64(np.floor(a[h, 0] / side) - cx0)
        cy = np.int64(np.floor(a[h, 1] / side) - cy0)
        for yy in range(max(cy - 1, 0), min(cy + 2, gy)):
            for t in range(start[yy * gx + max(cx - 1, 0)], start[yy * gx + min(cx + 2, gx)]):
                r = items[t]
                p = r if r < k else r - k
                if p >= h or gone[p]:
                    continue
                if r < k:
                    same = abs(a[p, 0] - a[h, 0]) <= near and abs(a[p, 1] - a[h, 1]) <= near \
                        and abs(b[p, 0] - b[h, 0]) <= near and abs(b[p, 1] - b[h, 1]) <= near
                else:
                    same = abs(b[p, 0] - a[h, 0]) <= near and abs(b[p, 1] - a[h, 1]) <= near \
                        and abs(a[p, 0] - b[h, 0]) <= near and abs(a[p, 1] - b[h, 1]) <= near
                if same:
                    gone[h] = True
                    break
            if gone[h]:
                break
    return gone


@entry
@njit(cache=True, nogil=True)
def nearest_order_kernel(ends, at):
    """The greedy nearest-stroke order.

    Args:
        ends: ``(2 N, 2)`` float64: the first points of the ``N`` strokes, then their last points.
        at: ``(2,)`` float64, where the tool stands.

    Returns:
        ``(2 N,)`` int64: the strokes in cutting order (first ``N``), then 1 where that stroke is cut
        backwards.  From ``at``, the next stroke is the one left whose nearer end is nearest
        (``math.hypot``; ties: the lowest index), cut backwards when its last point is strictly nearer than
        its first; ``at`` becomes the point it ends at.
    """
    m = ends.shape[0]
    n = m // 2
    out = np.zeros(m, np.int64)
    if n == 0:
        return out
    x0, y0, cell, gx, gy, cell_start, items = _grid(ends, np.arange(m))
    alive = cell_start[1:] - cell_start[:-1]  # ends left per cell, kept at the front of each cell
    where = np.empty(m, np.int64)
    for t in range(m):
        where[items[t]] = t
    size = 1.0
    for t in range(m):
        size = max(size, abs(ends[t, 0]), abs(ends[t, 1]))
    ax = at[0]
    ay = at[1]
    for step in range(n):
        best = _nearest_end(ends, ax, ay, x0, y0, cell, gx, gy, cell_start, items, alive, size)
        s = best if best < n else best - n
        out[step] = s
        d_start = math.hypot(ends[s, 0] - ax, ends[s, 1] - ay)
        d_end = math.hypot(ends[s + n, 0] - ax, ends[s + n, 1] - ay)
        backwards = d_end < d_start
        out[n + step] = 1 if backwards else 0
        for e in (s, s + n):  # both ends leave the grid
            _grid_remove(ends[e, 0], ends[e, 1], e, x0, y0, cell, gx, gy, cell_start, items, where, alive)
        e = s if backwards else s + n
        ax = ends[e, 0]
        ay = ends[e, 1]
    return out


@njit(cache=True, nogil=True)
def _nearest_in_cell(ends, ax, ay, c, cell_start, items, alive, n, best, best_s, best_d):
    """The nearest so far ``(best end, its stroke, distance)`` after the ends left in grid cell ``c`` (ties to the
    lowest stroke)."""
    for t in range(cell_start[c], cell_start[c] + alive[c]):
        e = items[t]
        s = e if e < n else e - n
        d = math.hypot(ends[e, 0] - ax, ends[e, 1] - ay)
        if d < best_d or (d == best_d and s < best_s):
            best, best_s, best_d = e, s, d
    return best, best_s, best_d


@njit(cache=True, nogil=True)
def _nearest_end(ends, ax, ay, x0, y0, cell, gx, gy, cell_start, items, alive, size):
    """The end left (index into ``ends``) of the stroke whose nearer end is nearest ``(ax, ay)``, ties to the
    lowest stroke; rings of grid cells around the point until no end outside them can be as near (by a
    margin for the rounding of the ring's bounds); from outside the grid, every end."""
    n = ends.shape[0] // 2
    best = -1
    best_s = -1
    best_d = np.inf
    ccx_f = math.floor((ax - x0) / cell)
    ccy_f = math.floor((ay - y0) / cell)
    if not (0 <= ccx_f < gx and 0 <= ccy_f < gy):
        for c in range(gx * gy):
            best, best_s, best_d = _nearest_in_cell(ends, ax, ay, c, cell_start, items, alive, n, best, best_s, best_d)
        return best
    ccx = int(ccx_f)
    ccy = int(ccy_f)
    margin = 1e-9 * (size + abs(ax) + abs(ay) + cell)
    r = 0
    while True:
        for yy in range(ccy - r, ccy + r + 1):
            if yy < 0 or yy >= gy:
                continue
            xstep = 1 if (r == 0 or yy == ccy - r or yy == ccy + r) else 2 * r
            xx = ccx - r
            while xx <= ccx + r:
                if 0 <= xx < gx:
                    best, best_s, best_d = _nearest_in_cell(ends, ax, ay, yy * gx + xx, cell_start, items, alive, n,
                                                            best, best_s, best_d)
                xx += xstep
        if r > gx + gy:
            return best
        # every end not yet looked at lies at least this far away
        reach = min(min(ax - (x0 + (ccx - r) * cell), x0 + (ccx + r + 1) * cell - ax),
                    min(ay - (y0 + (ccy - r) * cell), y0 + (ccy + r + 1) * cell - ay))
        if best >= 0 and best_d < reach - margin:
            return best
        r += 1


@entry
@njit(cache=True, nogil=True)
def cells_kernel(vert, poly_start, sample_steps, corner_cos, reach_steps):
    """The step positions of many polylines (step 2 of :mod:`cam.job.svg`), one polyline at a time.

    Args:
        vert: ``(V, 2)`` float64, the polylines' vertices one after the other (float steps).
        poly_start: ``(P + 1,)`` int64, where each polyline's vertices begin in ``vert`` (and the end).
        sample_steps: the samples' largest spacing in x or in y along a segment.
        corner_cos: a vertex where the cosine of the turn is below this is a sharp corner.
        reach_steps: a staircase corner is dropped only when each of its samples lies this near a neighbour.

    Returns:
        ``(M, 2)`` int64 positions of every polyline one after the other, then, as the last ``P + 1`` rows'
        first column, where each polyline's positions begin (and the end).

    Each segment gets ``max(1, ceil(longer side / sample_steps))`` samples ``d * (j / n) + v``, the polyline's
    last vertex one more; each is rounded (``floor(x + 0.5)``) and repeats dropped.  A position is fixed when a
    sample of it is a polyline's end or a sharp corner.  A position that is not fixed, not an end, whose two
    neighbours are 8-neighbours of each other and whose samples all lie within ``reach_steps``
    (``math.hypot``) of one of them is a staircase corner; of consecutive corners every other one is dropped,
    from the first.  Then a position between two equal unit moves is dropped (the moves are joined).
    """
    n_poly = poly_start.shape[0] - 1
    out = np.empty((max(64, vert.shape[0]) + n_poly + 1, 2), np.int64)
    starts = np.zeros(n_poly + 1, np.int64)
    cell = np.empty((64, 2), np.int64)  # one polyline's positions before corners are dropped
    fixed = np.empty(64, np.bool_)
    worst = np.empty(64)
    begin = np.empty((64, 2), np.int64)  # the segment and sample each position's samples begin at
    used = 0
    for p in range(n_poly):
        v0 = poly_start[p]
        v1 = poly_start[p + 1]
        starts[p] = used
        if v1 - v0 < 2:
            for v in range(v0, v1):
                out = _room(out, used + 1 + n_poly + 1)
                out[used, 0] = np.int64(np.floor(vert[v, 0] + 0.5))
                out[used, 1] = np.int64(np.floor(vert[v, 1] + 0.5))
                used += 1
            continue
        # the positions, and which are fixed
        k = 0
        px = 0.0
        py = 0.0
        plen = 0.0
        for i in range(v0, v1):
            if i == v1 - 1:  # the last vertex, a sample of its own
                dx = dy = 0.0
                ns = 1
                turn = True
            else:
                dx = vert[i + 1, 0] - vert[i, 0]
                dy = vert[i + 1, 1] - vert[i, 1]
                ns = max(np.int64(1), np.int64(np.ceil(max(abs(dx), abs(dy)) / sample_steps)))
                length = math.hypot(dx, dy)
                turn = i == v0 or _sharp(px, py, plen, dx, dy, length, corner_cos)
                px = dx
                py = dy
                plen = length
            for j in range(ns):
                t = j / ns
                cx = np.int64(np.floor(dx * t + vert[i, 0] + 0.5))
                cy = np.int64(np.floor(dy * t + vert[i, 1] + 0.5))
                if k == 0 or cx != cell[k - 1, 0] or cy != cell[k - 1, 1]:
                    if k == cell.shape[0]:
                        cell, fixed, worst, begin = _grow(cell, fixed, worst, begin)
                    cell[k, 0] = cx
                    cell[k, 1] = cy
                    fixed[k] = turn and j == 0
                    begin[k, 0] = i
                    begin[k, 1] = j
                    k += 1
                elif turn and j == 0:
                    fixed[k - 1] = True
        _corner_reach(vert, v1, sample_steps, cell, fixed, begin, k, worst)
        out = _room(out, used + k + n_poly + 1)
        used = _keep(cell, fixed, worst, k, reach_steps, out, used)
    starts[n_poly] = used
    out = _room(out, used + n_poly + 1)
    out[used:used + n_poly + 1, 0] = starts
    out[used:used + n_poly + 1, 1] = 0
    return out[:used + n_poly + 1]


@njit(cache=True, nogil=True)
def _sharp(px, py, plen, dx, dy, length, corner_cos):
    """Whether the turn from segment ``(px, py)`` (length ``plen``) to ``(dx, dy)`` is sharper than the corner
    angle (numpy's arithmetic: a zero-length segment never turns, a zero product of lengths divides to an
    infinity or not-a-number)."""
    ok = plen > 0 and length > 0
    dot = px * dx + py * dy
    den = plen * length if ok else 1.0
    if den != 0:
        cos = dot / den
    elif dot > 0:
        cos = np.inf
    elif dot < 0:
        cos = -np.inf
    else:
        cos = np.nan
    return ok and cos < corner_cos


@njit(cache=True, nogil=True)
def _corner_reach(vert, v1, sample_steps, cell, fixed, begin, k, worst):
    """``worst[r]``: the farthest any sample of position ``r`` lies from the nearer of its two neighbours, for
    the positions that may be staircase corners (not fixed, not an end, the neighbours 8-neighbours of each
    other; 0 for the others): their samples made again from where they begin, as :func:`cells_kernel` made
    them."""
    for r in range(k):
        worst[r] = 0.0
        if r == 0 or r == k - 1 or fixed[r] or abs(cell[r + 1, 0] - cell[r - 1, 0]) > 1 \
                or abs(cell[r + 1, 1] - cell[r - 1, 1]) > 1:
            continue
        i = begin[r, 0]
        j = begin[r, 1]
        done = False
        while not done and i < v1:
            if i == v1 - 1:
                dx = dy = 0.0
                ns = 1
            else:
                dx = vert[i + 1, 0] - vert[i, 0]
                dy = vert[i + 1, 1] - vert[i, 1]
                ns = max(np.int64(1), np.int64(np.ceil(max(abs(dx), abs(dy)) / sample_steps)))
            while j < ns:
                t = j / ns
                x = dx * t + vert[i, 0]
                y = dy * t + vert[i, 1]
                if np.int64(np.floor(x + 0.5)) != cell[r, 0] or np.int64(np.floor(y + 0.5)) != cell[r, 1]:
                    done = True  # the next position's samples
                    break
                reach = min(math.hypot(x - cell[r - 1, 0], y - cell[r - 1, 1]),
                            math.hypot(x - cell[r + 1, 0], y - cell[r + 1, 1]))
                worst[r] = max(worst[r], reach)
                j += 1
            i += 1
            j = 0


@njit(cache=True, nogil=True)
def _keep(cell, fixed, worst, k, reach_steps, out, used):
    """Write one polyline's positions to ``out`` from row ``used`` without its dropped staircase corners and
    the positions inside runs of one unit move; return the rows used."""
    first = used
    dropped_last = False
    for i in range(k):
        corner = 0 < i < k - 1 and not fixed[i] and worst[i] <= reach_steps \
            and abs(cell[i + 1, 0] - cell[i - 1, 0]) <= 1 and abs(cell[i + 1, 1] - cell[i - 1, 1]) <= 1
        if corner and not dropped_last:
            dropped_last = True
            continue
        dropped_last = False
        out[used, 0] = cell[i, 0]
        out[used, 1] = cell[i, 1]
        used += 1
    # a position between two equal moves goes (decided on the positions left, all at once)
    w = first + 1
    for i in range(first + 1, used - 1):
        if out[i, 0] - out[i - 1, 0] == out[i + 1, 0] - out[i, 0] \
                and out[i, 1] - out[i - 1, 1] == out[i + 1, 1] - out[i, 1]:
            continue
        out[w, 0] = out[i, 0]
        out[w, 1] = out[i, 1]
        w += 1
    if used - first > 1:  # the last position
        out[w, 0] = out[used - 1, 0]
        out[w, 1] = out[used - 1, 1]
        w += 1
    return w


@njit(cache=True, nogil=True)
def _room(out, rows):
    """``out``, or a copy twice as long when it has fewer than ``rows`` rows."""
    if rows <= out.shape[0]:
        return out
    bigger = np.empty((max(rows, 2 * out.shape[0]), 2), np.int64)
    bigger[:out.shape[0]] = out
    return bigger


@njit(cache=True, nogil=True)
def _grow(cell, fixed, worst, begin):
    """The buffers of one polyline's positions, twice as long."""
    n = cell.shape[0]
    cell2 = np.empty((2 * n, 2), np.int64)
    cell2[:n] = cell
    fixed2 = np.empty(2 * n, np.bool_)
    fixed2[:n] = fixed
    begin2 = np.empty((2 * n, 2), np.int64)
    begin2[:n] = begin
    return cell2, fixed2, np.empty(2 * n), begin2
