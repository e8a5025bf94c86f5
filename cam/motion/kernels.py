"""Compiled step-plan kernels (numba): the per-period loop of :mod:`cam.motion.chunks`, a stretch at a time.

It makes exactly what the vectorised reference makes (tests compare them) without the
``(periods, 3)`` temporaries, so planning tens of millions of steps stays fast and small.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .._compiled import entry


@njit(cache=True, inline="always")
def _dda_axis(r, ad, n, d, dir_state, axis, clock_bit):
    """One period of one axis's DDA (``ad`` steps over ``n`` periods, remainder ``r``): the remainder after it
    and the axis's clock bit if it steps in it (its direction, ``d``'s sign, then goes into ``dir_state``)."""
    r += ad
    if r >= n:
        dir_state[axis] = 1 if d > 0 else 0
        return r - n, clock_bit
    return r, 0


@njit(cache=True, nogil=True)
def _fill_periods(pts, delay_xy_ns, delay_z_ns, clock, dirbit, n_per_move, nominal, dir_state, i0, k0,
                  high, dirs, period):
    """The step loop of :func:`stretch_kernel`: fill ``high``, ``dirs`` and ``period`` (each ``(P,)``) with the periods
    of the moves from period ``k0`` of move ``i0`` on, until they are full or the moves end.

    Returns ``(p, i_end, k_end)``: the periods filled and where the next stretch starts.
    """
    n_moves = pts.shape[0] - 1
    max_periods = high.shape[0]
    p = 0
    i = i0
    k_start = k0
    while i < n_moves and p < max_periods:
        n = n_per_move[i]
        if k_start >= n:
            i += 1
            k_start = 0
            continue
        d0 = pts[i + 1, 0] - pts[i, 0]
        d1 = pts[i + 1, 1] - pts[i, 1]
        d2 = pts[i + 1, 2] - pts[i, 2]
        xy = d0 != 0 or d1 != 0
        if nominal[i] > 0:
            per = nominal[i]
        elif xy and d2 != 0:
            per = max(delay_xy_ns, delay_z_ns)
        elif xy:
            per = delay_xy_ns
        else:
            per = delay_z_ns
        ad0, ad1, ad2 = abs(d0), abs(d1), abs(d2)
        # an axis steps in period k when floor(k * ad / n) grows: carried as the remainder of k * ad
        # modulo n (ad <= n, so at most one step a period), without a division per period; a stretch
        # that starts inside a move takes the remainders after k_start periods
        r0 = (k_start * ad0) % n
        r1 = (k_start * ad1) % n
        r2 = (k_start * ad2) % n
        k_stop = min(n, k_start + (max_periods - p))
        for _k in range(k_start, k_stop):
            r0, c0 = _dda_axis(r0, ad0, n, d0, dir_state, 0, clock[0])
            r1, c1 = _dda_axis(r1, ad1, n, d1, dir_state, 1, clock[1])
            r2, c2 = _dda_axis(r2, ad2, n, d2, dir_state, 2, clock[2])
            clk = c0 | c1 | c2
            dd = dir_state[0] * dirbit[0] + dir_state[1] * dirbit[1] + dir_state[2] * dirbit[2]
            high[p] = dd | clk
            dirs[p] = dd
            period[p] = per
            p += 1
        if k_stop >= n:
            i += 1
            k_start = 0
        else:
            k_start = k_stop
    return p, i, k_start


@entry
@njit(cache=True, nogil=True)
def stretch_kernel(pts, delay_xy_ns, delay_z_ns, clock, dirbit, n_per_move, nominal, dir_state, i0, k0, max_periods):
    """Up to ``max_periods`` periods of the moves between rows of ``pts``, from period ``k0`` of move ``i0`` on.

    What :func:`periods_kernel` makes for the same moves, a stretch at a time (bounded memory).

    Args:
        pts: ``(N + 1, 3)`` int64 positions in steps, the start first.
        n_per_move: ``(N,)`` int64 periods of each move; nominal: ``(N,)`` int64 nominal period of each move
            (0: the delays by the axes that move).
        dir_state: ``(3,)`` int64 direction bit in force per axis, updated in place (carried between stretches).

    Returns:
        ``(high, dirs, period_ns, i_end, k_end)``: the periods and where the next stretch starts.
    """
    high = np.empty(max_periods, np.uint8)
    dirs = np.empty(max_periods, np.uint8)
    period = np.empty(max_periods, np.int64)
    p, i, k = _fill_periods(pts, delay_xy_ns, delay_z_ns, clock, dirbit, n_per_move, nominal, dir_state, i0, k0,
                            high, dirs, period)
    return high[:p], dirs[:p], period[:p], i, k


@entry
@njit(cache=True, nogil=True)
def chunk_writes_kernel(high, dirs, per, next_dirs, t0):
    """Writes of consecutive periods inside a job: ``(2P,)`` times and data, the first period starting at
    ``t0`` ns; the last period's falling edge writes ``next_dirs`` (the next period's directions)."""
    n = per.shape[0]
    t_ns = np.empty(2 * n, np.int64)
    data = np.empty(2 * n, np.uint8)
    t = t0
    for k in range(n):
        t_ns[2 * k] = t + per[k] // 2
        data[2 * k] = high[k]
        t += per[k]
        t_ns[2 * k + 1] = t
        data[2 * k + 1] = dirs[k + 1] if k + 1 < n else next_dirs
    return t_ns, data


@entry
@njit(cache=True, nogil=True)
def pin_rows_kernel(t_ns, data, strobe):
    """The pin log CSV rows ``t_ns,data,strobe\\n`` of writes, as ``np.savetxt(fmt="%d", delimiter=",")``
    writes them, in ASCII bytes.

    Args:
        t_ns: ``(M,)`` int64 times (>= 0); data, strobe: ``(M,)`` int64 register and strobe values (>= 0).

    Returns:
        ``(K,)`` uint8 the text of the M rows.
    """
    n = t_ns.shape[0]
    out = np.empty(n * 30 + 1, np.uint8)
    pairs = np.empty(200, np.uint8)  # "00" .. "99": two digits a division
    for v in range(100):
        pairs[2 * v] = 48 + v // 10
        pairs[2 * v + 1] = 48 + v % 10
    k = 0
    for i in range(n):
        k = _put_int(out, k, t_ns[i], pairs)
        out[k] = 44
        k = _put_int(out, k + 1, data[i], pairs)
        out[k] = 44
        k = _put_int(out, k + 1, strobe[i], pairs)
        out[k] = 10
        k += 1
    return out[:k]


@njit(cache=True, inline="always")
def _put_int(out, k, v, pairs):
    """Write integer ``v`` in decimal at ``out[k:]``; returns the index after it."""
    if v < 0:
        out[k] = 45
        k += 1
        v = -v
    if v < 10:
        out[k] = 48 + v
        return k + 1
    m = 1  # the number of digits
    x = v
    while x >= 10:
        x //= 10
        m += 1
    e = k + m
    while v >= 100:
        r = v % 100
        v //= 100
        e -= 2
        out[e] = pairs[2 * r]
        out[e + 1] = pairs[2 * r + 1]
    if v >= 10:
        e -= 2
        out[e] = pairs[2 * v]
        out[e + 1] = pairs[2 * v + 1]
    else:
        e -= 1
        out[e] = 48 + v
    return k + m


@entry
@njit(cache=True, nogil=True)
def net_steps_kernel(data, prev_byte, clock, dirbit, ends):
    """``(K, 3)`` int64 steps each axis made over the writes ``data[:ends[k]]``, as
    :func:`cam.verify.pinlog.net_steps` counts them (a step per rising clock, + with its direction bit set), in one
    pass without temporaries: the send loop counts a chunk once up to every pause in it.

    Args:
        data: ``(M,)`` uint8 data register after each write; prev_byte: the register before the first.
        clock, dirbit: ``(3,)`` int64 clock and direction bit of X, Y, Z.
        ends: ``(K,)`` int64 ascending write counts, each at most M.
    """
    cx, cy, cz = clock[0], clock[1], clock[2]
    dx, dy, dz = dirbit[0], dirbit[1], dirbit[2]
    out = np.empty((ends.shape[0], 3), np.int64)
    x = np.int64(0)
    y = np.int64(0)
    z = np.int64(0)
    prev = np.int64(prev_byte)
    i = 0
    for k in range(ends.shape[0]):
        while i < ends[k]:  # without branches: the steps of the minor axes come irregularly
            d = np.int64(data[i])
            rising = d & ~prev
            x += np.int64((rising & cx) != 0) * (2 * np.int64((d & dx) != 0) - 1)
            y += np.int64((rising & cy) != 0) * (2 * np.int64((d & dy) != 0) - 1)
            z += np.int64((rising & cz) != 0) * (2 * np.int64((d & dz) != 0) - 1)
            prev = d
            i += 1
        out[k, 0], out[k, 1], out[k, 2] = x, y, z
    return out


@entry
@njit(cache=True, nogil=True)
def move_periods_kernel(pts, prev):
    """Periods of the moves to ``(B, 3)`` int64 points ``pts`` from ``(3,)`` ``prev`` (the longest axis's steps of
    each, ``(B,)`` int64) and the steps each axis makes over them (``(3,)`` int64)."""
    n = pts.shape[0]
    npm = np.empty(n, np.int64)
    steps = np.zeros(3, np.int64)
    p0, p1, p2 = prev[0], prev[1], prev[2]
    for i in range(n):
        a0, a1, a2 = abs(pts[i, 0] - p0), abs(pts[i, 1] - p1), abs(pts[i, 2] - p2)
        npm[i] = max(a0, max(a1, a2))
        steps[0] += a0
        steps[1] += a1
        steps[2] += a2
        p0, p1, p2 = pts[i, 0], pts[i, 1], pts[i, 2]
    return npm, steps


@njit(cache=True, inline="always")
def _widen(box, a, v):
    if v < box[a, 0]:
        box[a, 0] = v
    if v > box[a, 1]:
        box[a, 1] = v


@entry
@njit(cache=True, nogil=True)
def move_extent_kernel(pts, n_per_move, extent, cut):
    """:func:`cam.motion.chunks.move_extent` in one pass: widen ``extent`` and ``cut`` (``(3, 2)`` int64 min/max,
    in place) by the positions the moves between rows of ``(B + 1, 3)`` int64 ``pts`` take the tool through,
    ``(B,)`` int64 ``n_per_move`` periods each.  A move that enters the work (z from <= 0 to > 0) is cut from
    the first period k with ``z_a + floor(k |dz| / n) >= 1``; one that leaves it up to the last such period."""
    for i in range(pts.shape[0]):
        for a in range(3):
            _widen(extent, a, pts[i, a])
        if pts[i, 2] > 0:
            for a in range(3):
                _widen(cut, a, pts[i, a])
    for i in range(pts.shape[0] - 1):
        n = n_per_move[i]
        za, zb = pts[i, 2], pts[i + 1, 2]
        if n <= 0 or (za > 0) == (zb > 0):
            continue
        adz = abs(zb - za)
        if zb > 0:  # enters: k = ceil((1 - za) n / |dz|)
            k = -((-(1 - za) * n) // adz)
        else:  # leaves: k = ceil(za n / |dz|) - 1
            k = -((-za * n) // adz) - 1
        for a in range(3):
            d = pts[i + 1, a] - pts[i, a]
            step = (k * abs(d)) // n
            _widen(cut, a, pts[i, a] + step if d > 0 else pts[i, a] - step)
