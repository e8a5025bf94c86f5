"""Drill order: a short path through the holes of one tool.

The tool stands at ``start_mm`` when a tool's holes begin; the path visits
every hole once and either ends at the last hole (the next tool starts where
this one ended) or goes on to ``end_mm`` (the last tool of a job: back to
where the job started, so the machine travels a closed tour).  Frame: machine
(x, y) in mm, any origin; only distances matter.

Method (all compiled with numba, ``cache=True``):

0. Holes at the same place are drilled one after another: the path is
   planned through the distinct places.
1. Up to :data:`EXACT_MAX` places: the exact shortest open path (Held-Karp
   dynamic programme over subsets).
2. Otherwise, a nearest-neighbour path from the start (exact nearest
   neighbour, found on a uniform grid), then local search with neighbour
   lists (the ``K_NEIGHBOURS`` nearest holes of each hole, from the same
   grid) and a work queue of holes whose edges changed ("don't-look bits"):
   2-opt (reverse a stretch of the path) and Or-opt (move a run of 1 to 3
   holes elsewhere, either way round).
3. Iterated local search: a local double-bridge kick (swap two adjacent
   short stretches of the path), repaired by the same local search, kept
   only if the path got shorter, else undone.  The number of kicks is fixed
   by the hole count and the random generator is seeded, so the order is
   deterministic: the same holes always give the same path.

Every step only ever shortens the nearest-neighbour path, so the result is
never longer than :func:`nearest_neighbour_order` (checked at the end).

Both are handled as a path array ``[start, h1, ..., hN, end]`` whose start and
end never move: for the open path a virtual ``end`` at distance 0 from
everything, for the closed tour the real end point.  On TSPLIB's drilling
instances the closed tour is within 2 % of the proven optimum (benchmark rows).

>>> import numpy as np
>>> pts = np.array([[3.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
>>> drill_order(pts, start_mm=(0.0, 0.0)).tolist()
[1, 2, 0]
>>> float(tour_length_mm(pts, drill_order(pts), (0.0, 0.0)))
3.0
>>> float(tour_length_mm(pts, drill_order(pts, end_mm=(0.0, 0.0)), (0.0, 0.0), end_mm=(0.0, 0.0)))
6.0
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._compiled import entry

from ..errors import PlanError

__all__ = ["drill_order", "nearest_neighbour_order", "tour_length_mm", "EXACT_MAX", "K_NEIGHBOURS"]

EXACT_MAX = 12
"""Up to this many holes the exact shortest open path is computed."""
K_NEIGHBOURS = 10
"""Candidate neighbours per hole in the local search."""
KICKS_PER_HOLE = 12
"""Iterated-local-search kicks per hole (fixed, so the result is deterministic)."""
MAX_KICKS = 400_000
"""Upper bound on the kicks for very large hole sets (keeps the time about linear)."""
_KICK_SEGMENT = 50
_SEED = 20030


def _check_points(points_mm: np.ndarray, start_mm) -> tuple[np.ndarray, np.ndarray]:
    pts = np.ascontiguousarray(np.asarray(points_mm, dtype=np.float64))
    if pts.size == 0:
        pts = pts.reshape(0, 2)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise PlanError(f"drill points must be an (N, 2) array, got shape {pts.shape}")
    pts = pts.reshape(-1, 2)
    start = np.asarray(start_mm, dtype=np.float64).reshape(-1)
    if start.shape != (2,):
        raise PlanError(f"the tour start must be (x, y) mm, got {start_mm!r}")
    if not (np.isfinite(pts).all() and np.isfinite(start).all()):
        raise PlanError("drill points and the tour start must be finite numbers")
    return pts, start


def tour_length_mm(points_mm: np.ndarray, order: np.ndarray, start_mm: tuple[float, float] = (0.0, 0.0),
                   end_mm: tuple[float, float] | None = None) -> float:
    """Length in mm of the path from ``start_mm`` through ``points_mm[order]`` (and on to ``end_mm`` if given).

    Args:
        points_mm: ``(N, 2)`` float (x, y) mm.
        order: ``(N,)`` int indices into ``points_mm`` (a permutation, or any subset).
        start_mm: (x, y) mm where the tool stands before the first hole.
        end_mm: (x, y) mm where the tool goes after the last hole (``start_mm``: the closed tour), or None.
    """
    pts, start = _check_points(points_mm, start_mm)
    order = np.asarray(order, dtype=np.int64)
    path = [start[None, :], pts[order]]
    if end_mm is not None:
        path.append(_check_points(np.zeros((0, 2)), end_mm)[1][None, :])
    path = np.vstack(path)
    return float(np.hypot(*np.diff(path, axis=0).T).sum())


def nearest_neighbour_order(points_mm: np.ndarray, start_mm: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Greedy nearest-neighbour path from ``start_mm``: always go to the nearest hole not yet drilled.

    Ties go to the lowest index.  Exact (a grid only speeds up the search).

    Args:
        points_mm: ``(N, 2)`` float (x, y) mm.
        start_mm: (x, y) mm of the tool before the first hole.

    Returns:
        ``(N,)`` int64 permutation of ``range(N)``: the drilling order.

    >>> nearest_neighbour_order(np.array([[5.0, 0.0], [1.0, 0.0], [-2.0, 0.0]])).tolist()
    [1, 2, 0]
    """
    pts, start = _check_points(points_mm, start_mm)
    if len(pts) == 0:
        return np.zeros(0, np.int64)
    return _nn_path(pts, start)


def drill_order(points_mm: np.ndarray, start_mm: tuple[float, float] = (0.0, 0.0),
                end_mm: tuple[float, float] | None = None) -> np.ndarray:
    """A short path from ``start_mm`` through every point once: open (ending anywhere) or on to ``end_mm``.

    With ``end_mm=start_mm`` it is the closed tour a job travels when it returns to where it started.

    Args:
        points_mm: ``(N, 2)`` float (x, y) mm of the holes (duplicates allowed).
        start_mm: (x, y) mm where the tool stands before the first hole.
        end_mm: (x, y) mm where the tool goes after the last hole, or None (the path ends at the last hole).

    Returns:
        ``(N,)`` int64 permutation of ``range(N)``: the drilling order.  Deterministic, never longer (with the
        way to ``end_mm`` counted) than :func:`nearest_neighbour_order`, exact up to :data:`EXACT_MAX` points.

    Raises:
        PlanError: points not ``(N, 2)`` or not finite.
    """
    pts, start = _check_points(points_mm, start_mm)
    end = None if end_mm is None else _check_points(pts, end_mm)[1]
    n = len(pts)
    if n == 0:
        return np.zeros(0, np.int64)
    if n == 1:
        return np.zeros(1, np.int64)
    uniq, inverse = np.unique(pts, axis=0, return_inverse=True)
    if len(uniq) < n:  # duplicates: solve on distinct points, drill each point's copies one after another
        groups = np.argsort(inverse.reshape(-1), kind="stable")
        first = np.searchsorted(inverse.reshape(-1)[groups], np.arange(len(uniq) + 1))
        return np.concatenate([groups[first[u]:first[u + 1]]
                               for u in drill_order(uniq, start, end_mm)]).astype(np.int64)
    if n <= EXACT_MAX:
        return _exact_path(pts, start, start if end is None else end, end is not None)
    nn = _nn_path(pts, start)
    # index n = the start, n + 1 = the end (for an open path a virtual end at distance 0 from everything)
    xy = np.vstack([pts, start[None, :]] + ([] if end is None else [end[None, :]]))
    neigh = _knn(xy, min(K_NEIGHBOURS, n))
    tour = np.empty(n + 2, np.int64)
    tour[0] = n
    tour[1:n + 1] = nn
    tour[n + 1] = n + 1
    kicks = min(KICKS_PER_HOLE * n, MAX_KICKS)
    _improve(xy, tour, neigh, kicks, _KICK_SEGMENT, _SEED, end is not None)
    order = tour[1:n + 1].copy()
    if tour_length_mm(pts, order, start, end) > tour_length_mm(pts, nn, start, end):  # pragma: no cover
        return nn
    return order


# ---------------------------------------------------------------- compiled kernels


@entry
@njit(cache=True, nogil=True)
def _exact_path(pts, start, end, to_end):
    """Held-Karp over subsets: the shortest path from ``start`` through all ``pts`` (N <= ~15), open or, with
    ``to_end``, on to ``end``."""
    n = pts.shape[0]
    full = (1 << n) - 1
    inf = np.inf
    cost = np.full((1 << n, n), inf)
    prev = np.full((1 << n, n), -1, np.int64)
    dist = np.empty((n, n))
    for a in range(n):
        for b in range(n):
            dist[a, b] = math.hypot(pts[a, 0] - pts[b, 0], pts[a, 1] - pts[b, 1])
    for a in range(n):
        cost[1 << a, a] = math.hypot(pts[a, 0] - start[0], pts[a, 1] - start[1])
    for mask in range(1, full + 1):
        for last in range(n):
            c = cost[mask, last]
            if c == inf or not (mask >> last) & 1:
                continue
            for nxt in range(n):
                if (mask >> nxt) & 1:
                    continue
                m2 = mask | (1 << nxt)
                c2 = c + dist[last, nxt]
                if c2 < cost[m2, nxt]:
                    cost[m2, nxt] = c2
                    prev[m2, nxt] = last
    best = 0
    best_cost = np.inf
    for a in range(n):
        c = cost[full, a]
        if to_end:
            c += math.hypot(pts[a, 0] - end[0], pts[a, 1] - end[1])
        if c < best_cost:
            best_cost = c
            best = a
    order = np.empty(n, np.int64)
    mask = full
    cur = best
    for k in range(n - 1, -1, -1):
        order[k] = cur
        p = prev[mask, cur]
        mask ^= 1 << cur
        cur = p
    return order


@njit(cache=True, nogil=True)
def _grid(xy, idx):
    """Bucket the points ``xy[idx]`` in a uniform grid of about 2 points per cell.

    Returns ``(x0, y0, cell, gx, gy, cell_start, items)``: the points of cell ``(cx, cy)`` are
    ``items[cell_start[cy * gx + cx]:cell_start[cy * gx + cx + 1]]``.
    """
    m = idx.shape[0]
    x0 = np.inf
    y0 = np.inf
    x1 = -np.inf
    y1 = -np.inf
    for t in range(m):
        p = idx[t]
        x0 = min(x0, xy[p, 0])
        y0 = min(y0, xy[p, 1])
        x1 = max(x1, xy[p, 0])
        y1 = max(y1, xy[p, 1])
    w = x1 - x0
    h = y1 - y0
    cell = math.sqrt(w * h * 2.0 / m)
    if not cell > 0:
        cell = max(w, h) * 2.0 / m
    if not cell > 0:
        cell = 1.0
    gx = int(w / cell) + 1
    gy = int(h / cell) + 1
    while gx * gy > 4 * m + 16:  # very elongated sets: fewer, larger cells
        cell *= 2.0
        gx = int(w / cell) + 1
        gy = int(h / cell) + 1
    count = np.zeros(gx * gy + 1, np.int64)
    cell_of = np.empty(m, np.int64)
    for t in range(m):
        p = idx[t]
        cx = min(int((xy[p, 0] - x0) / cell), gx - 1)
        cy = min(int((xy[p, 1] - y0) / cell), gy - 1)
        cell_of[t] = cy * gx + cx
        count[cy * gx + cx + 1] += 1
    cell_start = np.cumsum(count)
    fill = cell_start[:-1].copy()
    items = np.empty(m, np.int64)
    for t in range(m):  # in index order within each cell
        c = cell_of[t]
        items[fill[c]] = idx[t]
        fill[c] += 1
    return x0, y0, cell, gx, gy, cell_start, items


@entry
@njit(cache=True, nogil=True)
def _nn_path(pts, start):
    """Exact nearest-neighbour path from ``start`` (ties: lowest index), on a grid with removal."""
    n = pts.shape[0]
    x0, y0, cell, gx, gy, cell_start, items = _grid(pts, np.arange(n))
    alive = cell_start[1:] - cell_start[:-1]  # points left per cell, kept at the front of each cell
    where = np.empty(n, np.int64)
    for t in range(n):
        where[items[t]] = t
    order = np.empty(n, np.int64)
    cx_ = start[0]
    cy_ = start[1]
    rmax = max(gx, gy) + 1
    for step in range(n):
        ccx = int(math.floor((cx_ - x0) / cell))
        ccy = int(math.floor((cy_ - y0) / cell))
        best = -1
        best_d2 = np.inf
        r = 0
        if step == 0:  # the start may lie far outside the grid: scan every hole once
            for p in range(n):
                dx = pts[p, 0] - cx_
                dy = pts[p, 1] - cy_
                d2 = dx * dx + dy * dy
                if d2 < best_d2:
                    best_d2 = d2
                    best = p
        while step > 0:
            for yy in range(ccy - r, ccy + r + 1):
                if yy < 0 or yy >= gy:
                    continue
                edge_row = yy == ccy - r or yy == ccy + r
                xstep = 1 if edge_row else 2 * r
                if r == 0:
                    xstep = 1
                xx = ccx - r
                while xx <= ccx + r:
                    if 0 <= xx < gx:
                        c = yy * gx + xx
                        s = cell_start[c]
                        for t in range(s, s + alive[c]):
                            p = items[t]
                            dx = pts[p, 0] - cx_
                            dy = pts[p, 1] - cy_
                            d2 = dx * dx + dy * dy
                            if d2 < best_d2 or (d2 == best_d2 and p < best):
                                best_d2 = d2
                                best = p
                    xx += xstep
            # every point not yet scanned lies at least this far away
            reach = _ring_reach(cx_, cy_, x0, y0, cell, ccx, ccy, r)
            if best >= 0 and best_d2 < reach * reach:
                break
            if r > rmax:
                break
            r += 1
        order[step] = best
        # remove `best` from its cell: swap with the last alive point of the cell
        _grid_remove(pts[best, 0], pts[best, 1], best, x0, y0, cell, gx, gy, cell_start, items, where, alive)
        cx_ = pts[best, 0]
        cy_ = pts[best, 1]
    return order


@njit(cache=True, nogil=True)
def _grid_remove(x, y, item, x0, y0, cell, gx, gy, cell_start, items, where, alive):
    """Take ``item`` (at ``(x, y)``) out of its grid cell (:func:`_grid`): it swaps places with the cell's last item
    still there, and the cell holds one item less."""
    c = min(max(int((y - y0) / cell), 0), gy - 1) * gx + min(max(int((x - x0) / cell), 0), gx - 1)
    t = where[item]
    last = cell_start[c] + alive[c] - 1
    q = items[last]
    items[t] = q
    where[q] = t
    items[last] = item
    where[item] = last
    alive[c] -= 1


@njit(cache=True, nogil=True)
def _ring_reach(px, py, x0, y0, cell, ccx, ccy, r):
    """Distance from (px, py) to the outside of the box of cells within Chebyshev ring ``r`` of (ccx, ccy)."""
    lo_x = x0 + (ccx - r) * cell
    hi_x = x0 + (ccx + r + 1) * cell
    lo_y = y0 + (ccy - r) * cell
    hi_y = y0 + (ccy + r + 1) * cell
    return max(0.0, min(min(px - lo_x, hi_x - px), min(py - lo_y, hi_y - py)))


@entry
@njit(cache=True, nogil=True)
def _knn(xy, k):
    """``(M, k)`` int64: the ``k`` nearest other points of each point, nearest first (ties: lowest index)."""
    m = xy.shape[0]
    x0, y0, cell, gx, gy, cell_start, items = _grid(xy, np.arange(m))
    out = np.empty((m, k), np.int64)
    bd = np.empty(k)
    bi = np.empty(k, np.int64)
    for p in range(m):
        px = xy[p, 0]
        py = xy[p, 1]
        ccx = min(int((px - x0) / cell), gx - 1)
        ccy = min(int((py - y0) / cell), gy - 1)
        nb = 0
        r = 0
        while True:
            for yy in range(ccy - r, ccy + r + 1):
                if yy < 0 or yy >= gy:
                    continue
                edge_row = yy == ccy - r or yy == ccy + r
                xstep = 1 if (edge_row or r == 0) else 2 * r
                xx = ccx - r
                while xx <= ccx + r:
                    if 0 <= xx < gx:
                        c = yy * gx + xx
                        for t in range(cell_start[c], cell_start[c + 1]):
                            q = items[t]
                            if q == p:
                                continue
                            dx = xy[q, 0] - px
                            dy = xy[q, 1] - py
                            d2 = dx * dx + dy * dy
                            if nb == k and (d2 > bd[k - 1] or (d2 == bd[k - 1] and q > bi[k - 1])):
                                continue
                            j = nb if nb < k else k - 1
                            while j > 0 and (bd[j - 1] > d2 or (bd[j - 1] == d2 and bi[j - 1] > q)):
                                bd[j] = bd[j - 1]
                                bi[j] = bi[j - 1]
                                j -= 1
                            bd[j] = d2
                            bi[j] = q
                            if nb < k:
                                nb += 1
                    xx += xstep
            reach = _ring_reach(px, py, x0, y0, cell, ccx, ccy, r)
            if nb == k and bd[k - 1] < reach * reach:
                break
            if r > gx + gy:
                break
            r += 1
        for j in range(k):
            out[p, j] = bi[j]
    return out


@njit(cache=True, inline="always")
def _d(xy, a, b, free):
    if a == free or b == free:
        return 0.0
    dx = xy[a, 0] - xy[b, 0]
    dy = xy[a, 1] - xy[b, 1]
    return math.sqrt(dx * dx + dy * dy)


@njit(cache=True, nogil=True)
def _reverse(tour, pos, i, j):
    while i < j:
        a = tour[i]
        b = tour[j]
        tour[i] = b
        pos[b] = i
        tour[j] = a
        pos[a] = j
        i += 1
        j -= 1


@njit(cache=True, nogil=True)
def _push(queue, inq, head_tail, city, end):
    if city == end or inq[city]:
        return
    inq[city] = True
    cap = queue.shape[0]
    queue[head_tail[1] % cap] = city
    head_tail[1] += 1


@njit(cache=True, nogil=True)
def _n_nearer(xy, neigh, x, limit, free):
    """How many of ``x``'s neighbours (nearest first) lie nearer to it than ``limit``."""
    k = neigh.shape[1]
    t = 0
    while t < k and _d(xy, x, neigh[x, t], free) < limit:
        t += 1
    return t


@njit(cache=True, nogil=True)
def _two_opt(xy, tour, pos, neigh, a, end, free, span, queue, inq, ht):
    """Best-first 2-opt move around ``a``; applies it and returns the gain (0: none).

    On the side of ``a``'s successor and then of its predecessor: the path edges ``a - b`` and ``c - d``
    (``d`` next to ``c`` on the same side) become ``a - c`` and ``b - d``.
    """
    eps = 1e-12
    k = neigh.shape[1]
    pa = pos[a]
    for side in (1, -1):
        if pa + side < 0:
            break
        b = tour[pa + side]
        dab = _d(xy, a, b, free)
        for t in range(k):
            c = neigh[a, t]
            dac = _d(xy, a, c, free)
            if dac >= dab - eps:
                break
            pc = pos[c]
            if pc + side < 0 or pc + side > end:
                continue
            dd = tour[pc + side]
            if c == b or dd == a:
                continue
            gain = dab + _d(xy, c, dd, free) - dac - _d(xy, b, dd, free)
            if gain > eps:
                lo, hi = (pa + 1, pc) if pa < pc else (pc + 1, pa)
                if side < 0:
                    lo, hi = lo - 1, hi - 1
                _reverse(tour, pos, lo, hi)
                span[0] = min(span[0], lo)
                span[1] = max(span[1], hi)
                for city in (a, b, c, dd):
                    _push(queue, inq, ht, city, end)
                return gain
    return 0.0


@njit(cache=True, nogil=True)
def _move_run(tour, pos, i, j, pu, span):
    """Move the run ``tour[i..j]`` (1 to 3 holes, already turned the way it goes in) to just after position
    ``pu`` (outside the run), shifting the holes in between; widens ``span`` to what changed."""
    length = j - i + 1
    seg0 = tour[i]
    seg1 = tour[i + 1] if length > 1 else 0
    seg2 = tour[i + 2] if length > 2 else 0
    if pu > j:
        for q in range(j + 1, pu + 1):
            city = tour[q]
            tour[q - length] = city
            pos[city] = q - length
        base = pu - length + 1
        span[0] = min(span[0], i)
        span[1] = max(span[1], pu)
    else:
        for q in range(i - 1, pu, -1):
            city = tour[q]
            tour[q + length] = city
            pos[city] = q + length
        base = pu + 1
        span[0] = min(span[0], pu + 1)
        span[1] = max(span[1], j)
    tour[base] = seg0
    pos[seg0] = base
    if length > 1:
        tour[base + 1] = seg1
        pos[seg1] = base + 1
    if length > 2:
        tour[base + 2] = seg2
        pos[seg2] = base + 2


@njit(cache=True, nogil=True)
def _or_opt(xy, tour, pos, neigh, a, end, free, span, queue, inq, ht):
    """Or-opt around ``a``: move a run of 1-3 holes that ends at ``a`` between two other neighbours."""
    eps = 1e-12
    n_last = end - 1
    pa = pos[a]
    if pa == 0:
        return 0.0
    for length in range(1, 4):
        for side in range(2 if length > 1 else 1):
            i = pa if side == 0 else pa - length + 1
            j = i + length - 1
            if i < 1 or j > n_last:
                continue
            s1 = tour[i]
            s2 = tour[j]
            p = tour[i - 1]
            nx = tour[j + 1]
            removed = _d(xy, p, s1, free) + _d(xy, s2, nx, free) - _d(xy, p, nx, free)
            if removed <= eps:
                continue
            for e_ in range(2):
                x = s1 if e_ == 0 else s2
                other = s2 if e_ == 0 else s1
                for t in range(_n_nearer(xy, neigh, x, removed - eps, free)):
                    c = neigh[x, t]
                    pc = pos[c]
                    if i <= pc <= j:
                        continue
                    for gap in range(2):
                        if gap == 0:  # between c and its successor, x next to c
                            if pc == end:
                                continue
                            u = c
                            v = tour[pc + 1]
                            pu = pc
                            first = x
                            last = other
                        else:  # between c's predecessor and c, x next to c
                            if pc == 0:
                                continue
                            u = tour[pc - 1]
                            v = c
                            pu = pc - 1
                            first = other
                            last = x
                        if i - 1 <= pu <= j:
                            continue
                        added = _d(xy, u, first, free) + _d(xy, last, v, free) - _d(xy, u, v, free)
                        gain = removed - added
                        if gain > eps:
                            if first != s1:
                                _reverse(tour, pos, i, j)
                            _move_run(tour, pos, i, j, pu, span)
                            for city in (p, nx, s1, s2, u, v):
                                _push(queue, inq, ht, city, end)
                            return gain
    return 0.0


@njit(cache=True, nogil=True)
def _local_search(xy, tour, pos, neigh, end, free, span, queue, inq, ht):
    """Run 2-opt and Or-opt until no queued hole has an improving move; returns the total gain (mm)."""
    total = 0.0
    cap = queue.shape[0]
    while ht[0] < ht[1]:
        a = queue[ht[0] % cap]
        ht[0] += 1
        inq[a] = False
        g = _two_opt(xy, tour, pos, neigh, a, end, free, span, queue, inq, ht)
        if g == 0.0:
            g = _or_opt(xy, tour, pos, neigh, a, end, free, span, queue, inq, ht)
        total += g
    return total


@entry
@njit(cache=True, nogil=True)
def _improve(xy, tour, neigh, kicks, max_segment, seed, closed):
    """Improve the path ``tour`` = ``[start, holes..., end]`` in place (see the module docstring).

    ``xy`` is ``(N + 1, 2)`` with the start last (index N) and the virtual end (index N + 1) at distance 0 from
    everything, or, ``closed``, ``(N + 2, 2)`` with the real end last.
    """
    np.random.seed(seed)
    m = tour.shape[0]  # N + 2
    end = m - 1
    n = m - 2
    free = -1 if closed else end  # closed: the end is the start again, at its real distance
    pos = np.empty(m, np.int64)
    for i in range(m):
        pos[tour[i]] = i
    queue = np.empty(m + 1, np.int64)
    inq = np.zeros(m, np.bool_)
    ht = np.zeros(2, np.int64)
    span = np.zeros(2, np.int64)
    for i in range(m - 1):
        _push(queue, inq, ht, tour[i], end)
    _local_search(xy, tour, pos, neigh, end, free, span, queue, inq, ht)
    if n < 8:
        return
    saved = tour.copy()
    buf = np.empty(2 * max_segment + 2, np.int64)
    for _ in range(kicks):
        # double bridge on a short stretch: A B C D -> A C B D, B = [i, j), C = [j, k)
        lb = 1 + np.random.randint(0, min(max_segment, n // 3))
        lc = 1 + np.random.randint(0, min(max_segment, n // 3))
        i = 1 + np.random.randint(0, n - lb - lc + 1)
        j = i + lb
        kk = j + lc
        a0 = tour[i - 1]
        b0 = tour[i]
        b1 = tour[j - 1]
        c0 = tour[j]
        c1 = tour[kk - 1]
        d0 = tour[kk]
        delta = (_d(xy, a0, c0, free) + _d(xy, c1, b0, free) + _d(xy, b1, d0, free)
                 - _d(xy, a0, b0, free) - _d(xy, b1, c0, free) - _d(xy, c1, d0, free))
        t = 0
        for q in range(j, kk):
            buf[t] = tour[q]
            t += 1
        for q in range(i, j):
            buf[t] = tour[q]
            t += 1
        for q in range(t):
            city = buf[q]
            tour[i + q] = city
            pos[city] = i + q
        span[0] = i
        span[1] = kk - 1
        for city in (a0, b0, b1, c0, c1, d0):
            _push(queue, inq, ht, city, end)
        gain = _local_search(xy, tour, pos, neigh, end, free, span, queue, inq, ht)
        lo = span[0]
        hi = span[1]
        if delta - gain < -1e-9:
            for q in range(lo, hi + 1):
                saved[q] = tour[q]
        else:
            for q in range(lo, hi + 1):
                city = saved[q]
                tour[q] = city
                pos[city] = q
