"""Compiled tracing kernels (numba).

The thesis traced pixel by pixel in Visual Basic; a Python loop per pixel is
still far too slow for large drawings, and OpenCV has no primitive for a
greedy trace in a given neighbour order.  These kernels do exactly what the
reference Python in :mod:`.trace2d` and :mod:`.peel3d` describes, compiled with
numba (``cache=True``: compiled once per machine, then loaded from the cache).
Tests check that both give identical paths.

All images are padded by one pixel of 0 and flattened row-major: pixel
``(row, col)`` of the original is index ``(row + 1) * wp + col + 1``.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .._compiled import entry


@njit(cache=True, nogil=True)
def _walk(flat, cur, offsets, out, n_out):
    """Greedy walk from ``cur`` (already marked); appends visited pixels to ``out``; returns the new length."""
    while True:
        moved = False
        for j in range(offsets.shape[0]):
            q = cur + offsets[j]
            if flat[q] != 0:
                flat[q] = 0
                out[n_out] = q
                n_out += 1
                cur = q
                moved = True
                break
        if not moved:
            return n_out


@entry
@njit(cache=True, nogil=True)
def trace2d_kernel(flat, scan, wp, offsets, min_distance, tool_x, tool_y, from_origin):
    """2D trace of every set pixel of ``flat`` (modified in place).

    ``min_distance``: each object starts at the untraced pixel nearest ``(tool_x, tool_y)``, which is then the end
    of the object before, or, with ``from_origin`` (the thesis's Min Distance rule), stays where it was given.

    Returns ``(path, starts)``: flat indices in cutting order and the start of each object in ``path``
    (``starts[-1] == len(path)``).
    """
    n = scan.shape[0]
    path = np.empty(n, np.int64)
    arm = np.empty(n, np.int64)
    starts = np.empty(n + 1, np.int64)
    n_path = 0
    n_obj = 0
    cursor = 0
    while True:
        s = -1
        if not min_distance:
            while cursor < n and flat[scan[cursor]] == 0:
                cursor += 1
            if cursor == n:
                break
            s = scan[cursor]
        else:
            best = np.int64(1) << 62
            for i in range(n):
                p = scan[i]
                if flat[p] != 0:
                    dx = p % wp - 1 - tool_x
                    dy = p // wp - 1 - tool_y
                    d2 = dx * dx + dy * dy
                    if d2 < best:
                        best = d2
                        s = p
            if s < 0:
                break
        flat[s] = 0
        starts[n_obj] = n_path
        n_obj += 1
        # arm 1 goes into path after the start; arm 2 is collected separately, then joined reversed
        path[n_path] = s
        n1_end = _walk(flat, s, offsets, path, n_path + 1)
        n2 = _walk(flat, s, offsets, arm, 0)
        if n2 > 0:
            n1 = n1_end - n_path  # start + arm 1
            # shift start + arm1 right by n2 and put arm 2 reversed in front
            for i in range(n1 - 1, -1, -1):
                path[n_path + n2 + i] = path[n_path + i]
            for i in range(n2):
                path[n_path + i] = arm[n2 - 1 - i]
            end = n_path + n1 + n2
            first = path[n_path]
            last = path[end - 1]
            if not min_distance:
                flip = last < first
            else:
                d_first = (first % wp - 1 - tool_x) ** 2 + (first // wp - 1 - tool_y) ** 2
                d_last = (last % wp - 1 - tool_x) ** 2 + (last // wp - 1 - tool_y) ** 2
                flip = d_last < d_first
            if flip:
                i, j = n_path, end - 1
                while i < j:
                    path[i], path[j] = path[j], path[i]
                    i += 1
                    j -= 1
            n_path = end
        else:
            n_path = n1_end
        if not from_origin:
            last = path[n_path - 1]
            tool_x = last % wp - 1
            tool_y = last // wp - 1
    starts[n_obj] = n_path
    return path[:n_path], starts[: n_obj + 1]


@entry
@njit(cache=True, nogil=True)
def pad_mask_kernel(classes, value):
    """``(flat, scan)``: the pixels equal to ``value`` as a padded, flattened uint8 mask, and their flat
    indices in scan order -- one pass, no full-size temporaries."""
    h, w = classes.shape
    wp = w + 2
    flat = np.zeros((h + 2) * wp, np.uint8)
    n = 0
    for r in range(h):
        base = (r + 1) * wp + 1
        for c in range(w):
            if classes[r, c] == value:
                flat[base + c] = 1
                n += 1
    scan = np.empty(n, np.int64)
    j = 0
    for r in range(h):
        base = (r + 1) * wp + 1
        for c in range(w):
            if flat[base + c]:
                scan[j] = base + c
                j += 1
    return flat, scan


@njit(cache=True, nogil=True)
def _flood_ring(lay, ring_of, start, k, ring, wp, stack):
    """Mark the 8-connected piece of layer ``k`` (traced pixels hold -k) holding ``start`` as ``ring``.

    Returns how many of its pixels are still untraced.
    """
    left = 0
    stack[0] = start
    n = 1
    ring_of[start] = ring
    while n > 0:
        n -= 1
        p = stack[n]
        if lay[p] > 0:
            left += 1
        for dr in (-wp, 0, wp):
            for dc in (-1, 0, 1):
                q = p + dr + dc
                if abs(lay[q]) == k and ring_of[q] != ring:
                    ring_of[q] = ring
                    stack[n] = q
                    n += 1
    return left


@njit(cache=True, nogil=True)
def _layer_order(lay, n_layers, bounds):
    """Pixels of layers 1.. grouped by layer, scan order within a layer (a counting sort)."""
    fill = bounds.copy()
    order = np.empty(bounds[n_layers + 1], np.int32)
    for i in range(lay.shape[0]):
        k = abs(lay[i])
        if k > 0:
            order[fill[k]] = i
            fill[k] += 1
    return order


@njit(cache=True, nogil=True)
def _layer_bounds(lay):
    """``(n_layers, first, bounds)`` of a layer map: layer k's first pixel in scan order is ``first[k]``
    and its pixels are ``bounds[k]:bounds[k + 1]`` of :func:`_layer_order`."""
    size = lay.shape[0]
    n_layers = 0
    for i in range(size):
        if lay[i] > n_layers:
            n_layers = lay[i]
    counts = np.zeros(n_layers + 2, np.int64)
    first = np.full(n_layers + 2, -1, np.int64)
    for i in range(size):
        k = lay[i]
        if k > 0:
            if counts[k] == 0:
                first[k] = i
            counts[k] += 1
    bounds = np.zeros(n_layers + 2, np.int64)
    for k in range(2, n_layers + 2):
        bounds[k] = bounds[k - 1] + counts[k - 1]
    return n_layers, first, bounds


@njit(cache=True, nogil=True)
def _nearest(lay, order, lo, hi, wp, row, col, ring_of, ring):
    """The untraced pixel of ``order[lo:hi]`` nearest to (``row``, ``col``) of the padded image (ties: the
    first in scan order); only pixels flood-filled as ``ring`` when ``ring > 0``.  -1 if there is none."""
    best = np.int64(1) << 62
    s = -1
    for t in range(lo, hi):
        p = order[t]
        if lay[p] > 0 and (ring == 0 or ring_of[p] == ring):
            dr = p // wp - row
            dc = p % wp - col
            d2 = dr * dr + dc * dc
            if d2 < best:
                best = d2
                s = p
    return s


@njit(cache=True, nogil=True)
def _walk_layer(lay, k, cur, cr, cc, offsets, drow, dcol, xy, n_path):
    """Trace from the untraced pixel ``cur`` (row ``cr``, column ``cc`` of the padded image) of layer ``k``:
    mark it, append it to ``xy`` at ``n_path``, and go on greedily in the Figure 4.15 order within the layer.

    Returns ``(cur, cr, cc, n_path)``: the pixel where the walk stopped and the new path length.
    """
    m = offsets.shape[0]
    moved = True
    while moved:
        lay[cur] = -k
        xy[n_path, 0] = cc - 1
        xy[n_path, 1] = cr - 1
        n_path += 1
        moved = False
        j = 0
        while j < m and not moved:
            q = cur + offsets[j]
            if lay[q] == k:
                cr += drow[j]
                cc += dcol[j]
                cur = q
                moved = True
            j += 1
    return cur, cr, cc, n_path


@njit(cache=True, nogil=True)
def _grown(ring_starts, ring_levels, n_rings):
    """The ring arrays with twice the room, holding their first ``n_rings`` entries."""
    grown_s = np.empty(2 * ring_levels.shape[0] + 1, np.int64)
    grown_s[:n_rings] = ring_starts[:n_rings]
    grown_l = np.empty(2 * ring_levels.shape[0], np.int64)
    grown_l[:n_rings] = ring_levels[:n_rings]
    return grown_s, grown_l


@entry
@njit(cache=True, nogil=True)
def trace_layers_kernel(layer_flat, wp, offsets, drow, dcol):
    """Trace every layer of a padded, flattened layer map into rings (see :mod:`.peel3d`).

    Traced pixels are marked in place by negating their layer number (pass a copy).  A walk
    that stops with pixels of its layer left is the only case that needs more: then the ring's
    extent (its 8-connected piece of the layer) is flood-filled once, and the pixels of every
    layer in scan order (a counting sort) are built once, to find the nearest untraced pixel.

    Returns ``(xy, ring_starts, ring_levels)``: ``xy`` the ``(n, 2)`` int32 (x, y) image pixels
    (unpadded) in path order; ``offsets``/``drow``/``dcol`` give each neighbour as a flat offset
    and as (row, column) steps, so a pixel's row and column are carried along the walk.
    """
    lay = layer_flat
    n_layers, first, bounds = _layer_bounds(lay)
    n_px = bounds[n_layers + 1]
    order = np.empty(0, np.int32)  # _layer_order, made on first need
    ring_of = np.empty(0, np.int32)  # flood-fill marks by ring number (from 1), made on first need
    stack = np.empty(0, np.int32)
    xy = np.empty((n_px, 2), np.int32)
    ring_starts = np.empty(1024 + 1, np.int64)  # grown as needed: rings are few next to pixels
    ring_levels = np.empty(1024, np.int64)
    n_path = 0
    n_rings = 0
    tool = -1
    for k in range(1, n_layers + 1):
        lo = bounds[k]
        hi = bounds[k + 1]
        remaining = hi - lo
        s = first[k]  # a layer's first ring starts at its first pixel in scan order
        while remaining > 0:
            if n_rings == ring_levels.shape[0]:
                ring_starts, ring_levels = _grown(ring_starts, ring_levels, n_rings)
            ring_starts[n_rings] = n_path
            ring_levels[n_rings] = k
            n_rings += 1
            flooded = False
            ring_left = 0
            cur = s
            cr = cur // wp
            cc = cur % wp
            while True:
                n_before = n_path
                cur, cr, cc, n_path = _walk_layer(lay, k, cur, cr, cc, offsets, drow, dcol, xy, n_path)
                remaining -= n_path - n_before
                ring_left -= n_path - n_before
                if remaining == 0:
                    break
                if not flooded:
                    if ring_of.shape[0] == 0:
                        ring_of = np.zeros(lay.shape[0], np.int32)
                        stack = np.empty(n_px + 1, np.int32)
                    ring_left = _flood_ring(lay, ring_of, s, k, n_rings, wp, stack)
                    flooded = True
                if ring_left == 0:
                    break
                # pixels of this ring left behind: go on from the one nearest the tool
                if order.shape[0] == 0:
                    order = _layer_order(lay, n_layers, bounds)
                cur = _nearest(lay, order, lo, hi, wp, cr, cc, ring_of, n_rings)
                cr = cur // wp
                cc = cur % wp
            tool = cur
            if remaining > 0:  # the next ring: the one of the untraced pixel nearest the tool
                if order.shape[0] == 0:
                    order = _layer_order(lay, n_layers, bounds)
                s = _nearest(lay, order, lo, hi, wp, tool // wp, tool % wp, ring_of, 0)
    ring_starts[n_rings] = n_path
    return xy, ring_starts[: n_rings + 1].copy(), ring_levels[:n_rings].copy()


@entry
@njit(cache=True, nogil=True)
def peel_padded_kernel(classes, black, red, white):
    """Layer numbers of a 3D drawing, padded by one pixel, in two chamfer passes (see :mod:`.peel3d`).

    Layer k+1 of a red pixel is 1 + its exact 4-neighbour (L1) distance to the nearest black pixel,
    found by a forward and a backward chamfer pass; black is layer 1, anything else 0.

    Returns ``(padded, suspect)``: the ``(H + 2, W + 2)`` int32 layer map, and True when some red
    pixel touches white, the image border or a pixel of another class -- then the caller runs the
    checks that name the offending pixel (the result is not used).
    """
    h, w = classes.shape
    big = np.int32(1 << 30)
    padded = np.zeros((h + 2, w + 2), np.int32)
    suspect = False
    # forward pass: distance from black above / to the left; also look for red next to non-red non-black
    for r in range(h):
        for c in range(w):
            v = classes[r, c]
            if v == red:
                if r == 0 or c == 0 or r == h - 1 or c == w - 1:
                    suspect = True
                else:
                    for n in (classes[r - 1, c], classes[r + 1, c], classes[r, c - 1], classes[r, c + 1]):
                        if n != black and n != red:
                            suspect = True
                d = big
                if r > 0:
                    d = min(d, padded[r, c + 1] + 1)
                if c > 0:
                    d = min(d, padded[r + 1, c] + 1)
                padded[r + 1, c + 1] = d
            elif v != black:  # black stays at distance 0
                padded[r + 1, c + 1] = big
    # backward pass, then layer numbers: black 1, red distance + 1, others 0
    for r in range(h - 1, -1, -1):
        for c in range(w - 1, -1, -1):
            d = padded[r + 1, c + 1]
            v = classes[r, c]
            if v == red:
                if r < h - 1:
                    d = min(d, padded[r + 2, c + 1] + 1)
                if c < w - 1:
                    d = min(d, padded[r + 1, c + 2] + 1)
                padded[r + 1, c + 1] = d
    for r in range(h):
        for c in range(w):
            v = classes[r, c]
            if v == black:
                padded[r + 1, c + 1] = 1
            elif v == red:
                padded[r + 1, c + 1] += 1
            else:
                padded[r + 1, c + 1] = 0
    return padded, suspect
