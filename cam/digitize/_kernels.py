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


@njit(cache=True)
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


@njit(cache=True)
def trace2d_kernel(flat, scan, wp, offsets, min_distance, tool_x, tool_y):
    """2D trace of every set pixel of ``flat`` (modified in place).

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
        last = path[n_path - 1]
        tool_x = last % wp - 1
        tool_y = last // wp - 1
    starts[n_obj] = n_path
    return path[:n_path], starts[: n_obj + 1]


@njit(cache=True)
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


@njit(cache=True)
def _find(parent, i):
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit(cache=True)
def trace_layers_kernel(layer_flat, wp, offsets):
    """Trace every layer of a padded, flattened layer map into rings (see :mod:`.peel3d`).

    Returns ``(path, ring_starts, ring_levels)``.
    """
    size = layer_flat.shape[0]
    n_layers = 0
    for i in range(size):
        if layer_flat[i] > n_layers:
            n_layers = layer_flat[i]
    # pixels grouped by layer, scan order within a layer (counting sort)
    counts = np.zeros(n_layers + 2, np.int64)
    for i in range(size):
        counts[layer_flat[i]] += 1
    bounds = np.zeros(n_layers + 2, np.int64)
    for k in range(1, n_layers + 2):
        bounds[k] = bounds[k - 1] + counts[k - 1]
    fill = bounds.copy()
    order = np.empty(size - counts[0], np.int32)  # pixels of layers 1.. only
    for i in range(size):
        k = layer_flat[i]
        if k > 0:
            order[fill[k] - counts[0]] = i
            fill[k] += 1
    # rings: 8-connected pieces of a layer (union-find over forward neighbours)
    parent = np.empty(size, np.int32)
    for i in range(size):
        parent[i] = i
    fwd = np.array([1, wp - 1, wp, wp + 1])
    for i in range(size):
        k = layer_flat[i]
        if k == 0:
            continue
        for j in range(4):
            q = i + fwd[j]
            if q < size and layer_flat[q] == k:
                a = _find(parent, i)
                b = _find(parent, q)
                if a != b:
                    if a < b:
                        parent[b] = a
                    else:
                        parent[a] = b
    untraced = np.zeros(size, np.uint8)
    ring_left = np.zeros(size, np.int32)  # untraced pixels per ring, indexed by the ring's root
    n_roots = 0
    for i in range(size):
        if layer_flat[i] > 0:
            untraced[i] = 1
            r = _find(parent, i)
            if ring_left[r] == 0:
                n_roots += 1
            ring_left[r] += 1
    n_px = size - counts[0]
    path = np.empty(n_px, np.int32)
    ring_starts = np.empty(n_roots + 1, np.int64)  # each ring is traced as one object
    ring_levels = np.empty(n_roots, np.int64)
    n_path = 0
    n_rings = 0
    tool = -1
    for k in range(1, n_layers + 1):
        lo = bounds[k] - counts[0]
        hi = bounds[k + 1] - counts[0]
        if lo == hi:
            continue
        first_ring = True
        remaining = hi - lo
        while remaining > 0:
            if first_ring:
                s = order[lo]
                first_ring = False
            else:
                best = np.int64(1) << 62
                s = -1
                tr = tool // wp
                tc = tool % wp
                for t in range(lo, hi):
                    p = order[t]
                    if untraced[p] != 0:
                        dr = p // wp - tr
                        dc = p % wp - tc
                        d2 = dr * dr + dc * dc
                        if d2 < best:
                            best = d2
                            s = p
            ring = _find(parent, s)
            ring_starts[n_rings] = n_path
            ring_levels[n_rings] = k
            n_rings += 1
            cur = s
            while True:
                untraced[cur] = 0
                path[n_path] = cur
                n_path += 1
                remaining -= 1
                ring_left[ring] -= 1
                # greedy walk in the Figure 4.15 order, within this layer
                while True:
                    moved = False
                    for j in range(offsets.shape[0]):
                        q = cur + offsets[j]
                        if untraced[q] != 0 and layer_flat[q] == k:
                            untraced[q] = 0
                            path[n_path] = q
                            n_path += 1
                            remaining -= 1
                            ring_left[ring] -= 1
                            cur = q
                            moved = True
                            break
                    if not moved:
                        break
                # pixels of this ring left behind: go on from the one nearest the tool
                if ring_left[ring] == 0:
                    break
                best = np.int64(1) << 62
                nxt = -1
                cr = cur // wp
                cc = cur % wp
                for t in range(lo, hi):
                    p = order[t]
                    if untraced[p] != 0 and _find(parent, p) == ring:
                        dr = p // wp - cr
                        dc = p % wp - cc
                        d2 = dr * dr + dc * dc
                        if d2 < best:
                            best = d2
                            nxt = p
                if nxt < 0:
                    break
                cur = nxt
            tool = cur
    ring_starts[n_rings] = n_path
    return path[:n_path], ring_starts[: n_rings + 1], ring_levels[:n_rings]
