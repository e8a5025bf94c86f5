"""Speed planning: the length of every step period, with acceleration ramps.

Every job kind (drawings, drill files, G-code) becomes a sequence of step
periods (:mod:`cam.motion.steps`): in each period some axes step once (a DDA
spreads the minor axes of a move over its periods) and the period has a
*nominal* length -- the thesis's constant step delay, or a G-code feed.  This
module only lengthens periods; the path, and so the carve, never changes.

Modes (``MachineSettings.ramp``):

``constant``
    The thesis (``shared/seeds/001``): every period is the constant delay.
``linear40``
    The standalone controller's ramp (``shared/seeds/004``, section 3.5.2,
    "Speed up and slow down"): within each move the delay falls linearly
    over the first 40 steps and rises linearly over the last 40.  Here it
    falls from the delay at which every moving axis is at its start speed to
    the nominal delay; a move shorter than 80 steps peaks in its middle.
``lookahead``
    A planner over the whole job that keeps speed through junctions: the
    speed profile is judged per axis on the step level, so a contour of
    thousands of one-pixel moves keeps its speed wherever each axis steps
    regularly, and slows only where an axis really starts, stops, reverses
    or changes speed.  It satisfies the pin-log rules of
    :mod:`cam.verify.ramps` (checked, not assumed: see below).

The look-ahead planner, with the period index ``k`` as the path parameter and
``u_k`` = 1 / period length (periods per second) as the path speed:

1. Per axis, each interval between two consecutive steps of a run (runs
   split at reversals and at rests: start, end, pauses, dwells) spanning
   ``m`` periods runs at ``s * u / m`` mm/s; so every period of the interval
   gets the caps ``u <= v_max * m / s`` (R1) and, for the first and last
   interval of a run, ``u <= v_s * m / s`` (R3); the pull-in rate
   ``u_pull = min(v_s * m / s)`` (all axes at or below their start speed)
   and the path acceleration ``alpha = min(A * m / s)`` are taken over the
   axes stepping around ``k``.  The nominal period is a cap too.
2. A forward pass ``u_k = min(cap_k, max(sqrt(u_{k-1}^2 + 2 alpha), u_pull))``
   (accelerate; 0 at a rest) and the same backward (decelerate); the
   pointwise minimum of a 1-D path-parametrised problem.
3. The result is checked with the pin-log rules on its own step times; the
   caps of every period under a broken rule drop (an interval too fast for
   the top speed or for a stop, R1 or R3, straight to the rate that meets the
   rule; an acceleration break, R2, by 15 %) and steps 2-3 repeat.  A repeat
   works out again only what the lowered caps reach: the passes from each
   lowered cap until the rates meet the old ones, the periods and edge times
   from the first changed period, and the rules for the steps within three
   steps of a changed period (everything else is bit for bit what it was, and
   passed).  After 25 rounds (not seen on the samples) every period is capped
   at ``u_pull``: then every axis is at or below its start speed everywhere,
   which meets every rule, so the planner always returns a plan that passes.

Everything per period runs compiled (numba) over flat arrays: a window is one
call (:func:`_plan_window`) that lets go of the GIL, so windows are planned
in parallel (:meth:`cam.motion.chunks.ChunkedPlan._windows`) while the send
loop runs.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .._compiled import entry

from ..settings import RAMP_MODES, MachineSettings
from ..verify.ramps import check_steps_range, mark_standstills, standstill_ns
from ..errors import CamError
from ..pins import axis_bits

__all__ = ["RAMP_MODES", "ramp_periods", "linear40_periods", "RAMP_STEPS_LINEAR40", "top_speeds_mm_s",
           "check_delay_speeds"]

RAMP_STEPS_LINEAR40 = 40
"""Steps of the seed's linear delay ramp at each end of a move (004, section 3.5.2)."""

_ROUNDS = 25
_DROP = 0.85
_ALPHA_MARGIN = 0.9


@njit(cache=True, nogil=True)
def _steps_of_axis(high, clk, dbit):
    n = 0
    for k in range(high.shape[0]):
        if high[k] & clk:
            n += 1
    per = np.empty(n, np.int64)
    up = np.empty(n, np.bool_)
    j = 0
    for k in range(high.shape[0]):
        if high[k] & clk:
            per[j] = k
            up[j] = (high[k] & dbit) != 0  # high holds the directions in force with the clocks
            j += 1
    return per, up


@njit(cache=True, nogil=True)
def _breaks(per, up, stop_idx, start_ns, still_ns):
    """Rest before step j: reversal, a stop between the periods of steps j-1 and j, or a certain standstill.

    ``stop_idx``: increasing period indices k with a rest before period k; a rest lies between
    steps in periods p0 < p1 when p0 < k <= p1 for one of them.  ``start_ns``: ``(P + 1,)`` start of each period
    at the nominal lengths (and the end); a standstill: the periods strictly between the two steps last longer
    than ``still_ns`` even at the nominal lengths, which ramps only lengthen.
    """
    n = per.shape[0]
    brk = np.zeros(n, np.bool_)
    i = 0
    for j in range(1, n):
        while i < stop_idx.shape[0] and stop_idx[i] <= per[j - 1]:
            i += 1
        if up[j] != up[j - 1] or (i < stop_idx.shape[0] and stop_idx[i] <= per[j]):
            brk[j] = True
        elif float(start_ns[per[j]] - start_ns[per[j - 1] + 1]) > still_ns:
            brk[j] = True
    return brk


@njit(cache=True, nogil=True)
def _pair_cap(m1, m2, s, v_start, acc, u_hi):
    """Largest steady path rate (<= ``u_hi``) at which intervals of ``m1`` then ``m2`` periods pass R2.

    With the rule's clamps: speeds below the start speed count as the start speed and intervals
    longer than a start-speed step count as one (bisection; ``v_start * m1 / s`` always passes).
    """
    ds = s / v_start
    lo = v_start * m1 / s
    hi = u_hi
    if hi <= lo:
        return hi
    for _ in range(24):
        u = 0.5 * (lo + hi)
        w1 = max(s * u / m1, v_start)
        w2 = max(s * u / m2, v_start)
        dt = 0.5 * (min(m1 / u, ds) + min(m2 / u, ds))
        if abs(w1 - w2) <= acc * dt:
            lo = u
        else:
            hi = u
    return lo


@njit(cache=True, nogil=True)
def _axis_caps(per, brk, s, v_start, v_max, acc, cap, alpha, upull):
    """Step 1 of the planner (module docstring) for one axis: lower ``cap``, ``alpha``, ``upull`` in place."""
    n = per.shape[0]
    memo = np.full((64, 64), -1.0)  # _pair_cap by (shorter, longer) interval: the pass set is u <= u*
    for j in range(n - 1):
        if brk[j + 1]:
            continue
        k1 = per[j]
        k2 = per[j + 1]
        m = k2 - k1
        first = j == 0 or brk[j]
        last = j + 2 >= n or brk[j + 2]
        c = v_max * m / s
        if first or last:
            c = min(c, v_start * m / s)
        a = acc * m / s
        p = v_start * m / s
        if j + 2 < n and not brk[j + 2]:
            # R2 at the step between this interval (m periods) and the next (m2): at a steady path
            # speed u the axis jumps from s u / m to s u / m2.  One step may move a period toward a
            # free slot (the checker's quantisation tolerance), so judge the pair one period closer;
            # the cap is an estimate that saves re-planning rounds, the check still decides.
            m2 = per[j + 2] - k2
            lo_m = min(m, m2)
            hi_m = max(m, m2)
            if hi_m - lo_m > 2:
                if hi_m < memo.shape[0]:
                    if memo[lo_m, hi_m] < 0:
                        memo[lo_m, hi_m] = _pair_cap(lo_m + 1, hi_m - 1, s, v_start, acc, v_max * hi_m / s)
                    c2 = min(memo[lo_m, hi_m], c)
                else:
                    c2 = _pair_cap(lo_m + 1, hi_m - 1, s, v_start, acc, c)
                for k in range(k1, per[j + 2] + 1):
                    if c2 < cap[k]:
                        cap[k] = c2
        for k in range(k1, k2 + 1):
            if c < cap[k]:
                cap[k] = c
            if a < alpha[k]:
                alpha[k] = a
            if p < upull[k]:
                upull[k] = p


@njit(cache=True, nogil=True)
def _passes(cap, alpha, upull, stop_before, fwd, u, changed, dirty, n_dirty, full, runs):
    """Step 2: forward (accelerate, into ``fwd``) then backward (decelerate) passes; ``u`` out.

    ``full``: every period (``dirty`` holds one run, all of them); else only what the caps lowered in the
    ``n_dirty`` runs of ``dirty`` reach: the rates are worked out again from each such run on until they meet the
    old ones (the result is the same to the bit: a period neither pass reaches would come out as it is).
    ``dirty``: sorted, disjoint runs ``(first, last)`` of periods as ``dirty[2 i]``, ``dirty[2 i + 1]``.
    ``changed`` out: where ``u`` changed (all False when ``full``; it is False outside the runs when called).
    Returns the number of runs of periods the backward pass went over, written into ``runs`` (``(4 n_dirty + 4,)``
    int64, as ``dirty``; the backward runs are made in its second half, then moved to the front): they hold every
    period that changed and every period of ``dirty``.
    """
    n = cap.shape[0]
    n_fwd = 0
    k = 0
    for r in range(n_dirty):  # forward: accelerate
        if k > dirty[2 * r + 1]:
            continue  # reached already
        k = max(k, dirty[2 * r])
        if n_fwd and runs[2 * n_fwd - 1] == k - 1:
            n_fwd -= 1  # goes on from the last run
        else:
            runs[2 * n_fwd] = k
        carry = True
        while k < n and (carry or k <= dirty[2 * r + 1]):
            prev = 0.0 if stop_before[k] or k == 0 else fwd[k - 1]
            if prev >= cap[k]:  # cruising at the cap (upull <= cap): no need to accelerate
                v = cap[k]
            else:
                a = alpha[k]
                if k > 0 and alpha[k - 1] < a:
                    a = alpha[k - 1]
                v = np.sqrt(prev * prev + 2.0 * a) if a < np.inf else np.inf
                if upull[k] > v:
                    v = upull[k]
                if cap[k] < v:
                    v = cap[k]
            carry = (not full) and v != fwd[k]
            changed[k] = carry
            fwd[k] = v
            k += 1
        runs[2 * n_fwd + 1] = k - 1
        n_fwd += 1
    # backward: decelerate, from the end of each forward run down (the runs it makes overwrite the forward
    # ones from the top, never ahead of where it reads)
    n_back = 0
    low = n  # the lowest period visited so far
    out_at = 2 * n_fwd  # the backward runs go into runs[out_at:] first, then are moved down
    for r in range(n_fwd - 1, -1, -1):
        top = min(runs[2 * r + 1], low - 1)
        if top < runs[2 * r]:
            continue
        k = top
        carry = True
        while k >= 0 and (carry or k >= runs[2 * r]):
            nxt = 0.0 if stop_before[k + 1] else u[k + 1]
            v = fwd[k]
            if nxt < v:  # else the forward speed here is reachable from what follows
                a = alpha[k]
                if k + 1 < n and alpha[k + 1] < a:
                    a = alpha[k + 1]
                w = np.sqrt(nxt * nxt + 2.0 * a) if a < np.inf else np.inf
                if upull[k] > w:
                    w = upull[k]
                if w < v:
                    v = w
            carry = (not full) and v != u[k]
            changed[k] = carry
            u[k] = v
            k -= 1
        if n_back and runs[out_at + 2 * n_back - 2] == top + 1:
            runs[out_at + 2 * n_back - 2] = k + 1  # joins the run above it
        else:
            runs[out_at + 2 * n_back] = k + 1
            runs[out_at + 2 * n_back + 1] = top
            n_back += 1
        low = k + 1
    for i in range(n_back):  # ascending, to the front
        runs[2 * i] = runs[out_at + 2 * (n_back - 1 - i)]
        runs[2 * i + 1] = runs[out_at + 2 * (n_back - 1 - i) + 1]
    return n_back


@njit(cache=True, nogil=True)
def _periods_from_rates(u, floor_ns, out, mid):
    """Period lengths from the rates (never below the nominal), and each period's rising-edge time
    (start + T // 2, as :func:`cam.motion.steps._writes` places it)."""
    t_ns = 0
    for k in range(u.shape[0]):
        t = np.ceil(1e9 / u[k]) if u[k] > 0 else floor_ns[k]
        out[k] = max(floor_ns[k], np.int64(t))
        mid[k] = t_ns + out[k] // 2
        t_ns += out[k]


@njit(cache=True, nogil=True)
def _reperiods(u, floor_ns, out, mid, changed, cap_dirty, runs, n_runs):
    """:func:`_periods_from_rates` again where the rates ``changed``, in the ``n_runs`` runs of periods of ``runs``
    (as :func:`_passes` gives them: ``changed`` and ``cap_dirty`` are False outside them); clears ``changed`` and
    ``cap_dirty`` there.

    Returns ``(n_spans, spans)``: the spans of periods to judge again (a changed period length, or a cap lowered at
    the last check), each first and last period as ``spans[2 i]``, ``spans[2 i + 1]`` (int64).
    """
    n = u.shape[0]
    need = 0  # spans at most: one per period of the runs
    for r in range(n_runs):
        need += runs[2 * r + 1] - runs[2 * r] + 1
    spans = np.empty(2 * need + 2, np.int64)
    first = -1
    t_ns = 0
    n_spans = 0
    for r in range(n_runs):
        for k in range(runs[2 * r], runs[2 * r + 1] + 1):
            mark = cap_dirty[k]
            cap_dirty[k] = False
            if changed[k]:
                changed[k] = False
                t = np.ceil(1e9 / u[k]) if u[k] > 0 else floor_ns[k]
                per = max(floor_ns[k], np.int64(t))  # as _periods_from_rates
                if per != out[k]:
                    if first < 0:
                        first = k
                        t_ns = mid[k] - out[k] // 2  # the start of period k (the periods before it are the same)
                    out[k] = per
                    mark = True
            if mark:
                if n_spans and spans[2 * n_spans - 1] == k - 1:
                    spans[2 * n_spans - 1] = k
                else:
                    spans[2 * n_spans] = k
                    spans[2 * n_spans + 1] = k
                    n_spans += 1
    if first >= 0:
        for k in range(first, n):
            mid[k] = t_ns + out[k] // 2
            t_ns += out[k]
    return n_spans, spans


@njit(cache=True, nogil=True)
def _judge_axis(per, brk, mid, spans, n_spans, s, v_start, v_max, acc, r1, r2, r3, judged):
    """Step 3 for one axis (``per``: ``(S,)`` periods of its steps, ``brk``: rests before them): the pin-log rules
    (:func:`cam.verify.ramps.check_steps_range`) on the rising edges ``mid``, judged again only for the steps that
    reach into one of the ``n_spans`` spans of periods in ``spans`` (as :func:`_reperiods` writes them; the rest
    passed last time and nothing they depend on changed).  A step reaches from the period before the step three
    before it to the period after the step three after it: what its interval, pair, rests and free slots depend
    on.  Records the breaks in ``r1``..``r3`` (``(S,)``; zero when called, as :func:`_drop_caps` leaves them)
    and the runs of steps judged, ``[j_lo, j_hi)`` as ``judged[2 i]``, ``judged[2 i + 1]`` (``(2 n_spans + 2,)``
    int64, ascending); returns ``(breaks, runs judged)``."""
    n = per.shape[0]
    if n < 2:
        return 0, 0
    still_ns = standstill_ns(s, v_start)
    bad = 0
    n_judged = 0
    j_lo = -1
    j_hi = -1
    for i in range(n_spans + 1):
        if i < n_spans:  # the steps reaching into span i
            a = max(np.searchsorted(per, spans[2 * i] - 1) - 3, 0)
            b = min(np.searchsorted(per, spans[2 * i + 1] + 1, "right") + 3, n)
            if a >= b:
                continue
            if j_lo >= 0 and a <= j_hi:  # overlaps the steps gathered so far
                j_hi = max(j_hi, b)
                continue
        if j_lo >= 0:
            bad += _judge_steps(per, brk, mid, j_lo, j_hi, still_ns, s, v_start, v_max, acc, r1, r2, r3)
            judged[2 * n_judged] = j_lo
            judged[2 * n_judged + 1] = j_hi
            n_judged += 1
        if i < n_spans:
            j_lo, j_hi = a, b
    return bad, n_judged


@njit(cache=True, nogil=True)
def _judge_steps(per, brk, mid, j_lo, j_hi, still_ns, s, v_start, v_max, acc, r1, r2, r3):
    """The rules for steps ``j_lo .. j_hi - 1`` of one axis, with three steps around them for their rests."""
    n = per.shape[0]
    c0 = max(0, j_lo - 3)
    c1 = min(n, j_hi + 3)
    t = np.empty(c1 - c0, np.int64)
    for i in range(c1 - c0):
        t[i] = mid[per[c0 + i]]
    b = brk[c0:c1].copy()
    mark_standstills(t, still_ns, b)  # a standstill, as the checker judges it
    return check_steps_range(t, per[c0:c1], mid, b, s, v_start, v_max, acc, r1[c0:c1], r2[c0:c1], r3[c0:c1],
                             j_lo - c0, j_hi - c0)


@njit(cache=True, nogil=True)
def _drop_caps(per, r1, r2, r3, u, cap, factor, s, v_start, v_max, cap_dirty, judged, n_judged, dirty, n_dirty):
    """Lower the caps of the periods under every broken rule (and mark them in ``cap_dirty``), looking at the
    ``n_judged`` runs of steps :func:`_judge_axis` judged (``judged``; the marks are zero elsewhere).

    A broken top speed (R1) or stop (R3) of an interval of ``m`` periods caps them at the rate that meets the
    rule, ``v * m / s``, at once; any other break (R2), or one whose cap is that low already, to ``factor`` x the
    slowest rate there.  The marks ``r1``..``r3`` are zero again afterwards (for :func:`_judge_axis`, which writes
    only the breaks): a lowered cap is always within reach of the step whose break lowered it.
    Each run of periods whose caps it lowered is added to ``dirty`` (as ``(first, last)`` from ``dirty[2 n_dirty]``
    on; room for one a break); returns ``(breaks, n_dirty)``.
    """
    n = per.shape[0]
    hits = 0
    for i in range(n_judged):
        for j in range(judged[2 * i], judged[2 * i + 1]):
            if not (r1[j] > 0 or r2[j] > 0 or r3[j] > 0):
                continue  # (most steps: nothing written, nothing to reset)
            lo = -1
            hi = -1
            exact = np.inf
            if j + 1 < n and (r1[j] > 0 or r3[j] > 0):
                lo = per[j]
                hi = per[j + 1]
                m = hi - lo
                exact = (v_start if r3[j] > 0 else v_max) * m / s
            if r2[j] > 0 and 0 < j < n - 1:
                lo = per[j - 1]
                hi = per[j + 1]
                exact = np.inf
            r1[j] = 0.0
            r2[j] = 0.0
            r3[j] = 0.0
            if lo < 0:
                continue
            hits += 1
            lowered = False
            for k in range(lo, hi + 1):
                if exact < cap[k]:
                    cap[k] = exact
                    cap_dirty[k] = True
                    lowered = True
            if not lowered:
                slow = np.inf
                for k in range(lo, hi + 1):
                    if u[k] < slow:
                        slow = u[k]
                for k in range(lo, hi + 1):
                    if factor * slow < cap[k]:
                        cap[k] = factor * slow
                        cap_dirty[k] = True
                        lowered = True
            if lowered:
                dirty[2 * n_dirty] = lo
                dirty[2 * n_dirty + 1] = hi
                n_dirty += 1
    return hits, n_dirty


@njit(cache=True, nogil=True)
def _merged_runs(runs, n_runs):
    """Sort the ``n_runs`` runs ``(first, last)`` of ``runs`` (as :func:`_drop_caps` adds them) and join those
    that overlap or touch, in place; returns how many are left."""
    if n_runs == 0:
        return 0
    order = np.argsort(runs[0:2 * n_runs:2], kind="mergesort")
    firsts = runs[0:2 * n_runs:2][order]
    lasts = runs[1:2 * n_runs:2][order]
    m = 0
    for i in range(n_runs):
        if m and firsts[i] <= runs[2 * m - 1] + 1:
            runs[2 * m - 1] = max(runs[2 * m - 1], lasts[i])
        else:
            runs[2 * m] = firsts[i]
            runs[2 * m + 1] = lasts[i]
            m += 1
    return m


def linear40_periods(high: np.ndarray, period_ns: np.ndarray, move_first: np.ndarray, clock, s, v_start) -> np.ndarray:
    """The seed's per-move linear delay ramp (004, section 3.5.2): ``(P,)`` int64 period lengths in ns.

    ``move_first``: ``(M,)`` first period of each ramp segment (a source move), sorted; periods before the first
    are not ramped, the last segment ends with the periods.  ``clock``: the axes' clock bits; ``s``, ``v_start``:
    per-axis mm per step and start speed (:meth:`MachineSettings.axis_limits`).
    """
    n = len(period_ns)
    out = period_ns.copy()
    start_step_ns = np.asarray(s) / np.asarray(v_start) * 1e9  # (3,) one step at the start speed
    bounds = np.append(np.asarray(move_first, np.int64), n)
    for i in range(len(bounds) - 1):
        a, b = int(bounds[i]), int(bounds[i + 1])
        if b <= a:
            continue
        h = high[a:b]
        steps = np.array([np.count_nonzero(h & int(clock[x])) for x in range(3)], np.float64)
        if not steps.any():
            continue  # a dwell
        nominal = period_ns[a:b]
        # the delay at which each moving axis is at its start speed: s / v_s per step, steps/period of the move
        start_ns = float(np.max(start_step_ns * steps / (b - a)))
        k = np.arange(b - a)
        r = np.minimum(np.minimum(k, (b - a - 1) - k), RAMP_STEPS_LINEAR40)
        ramp = np.maximum(start_ns - nominal, 0) * (RAMP_STEPS_LINEAR40 - r) / RAMP_STEPS_LINEAR40
        out[a:b] = nominal + np.ceil(ramp).astype(np.int64)
    return out


def ramp_periods(high: np.ndarray, period_ns: np.ndarray, settings: MachineSettings, *,
                 move_first: np.ndarray | None = None, stops: np.ndarray | None = None) -> np.ndarray:
    """Period lengths with the speed ramps of ``settings.ramp``.

    Args:
        high: ``(P,)`` uint8 data byte at each period's rising edge (the direction bits in force
            during the period | the clocks of the axes that step in it).
        period_ns: ``(P,)`` int64 nominal period lengths (the constant delay or a feed): never shortened.
        settings: pin map and per-axis limits (:meth:`MachineSettings.axis_limits`).
        move_first: ``(M,)`` int64 first period of each move (``linear40`` ramps per move).
        stops: period indices ``i`` in ``0..P`` before which the machine rests (pauses, tool changes,
            both sides of a dwell); the start and the end of the job are rests anyway.  A period in
            which no axis steps is not a rest by itself (a move a fraction of a step longer than its
            steps has one): the axes stepping around it keep their speed through it.

    Returns:
        ``(P,)`` int64 period lengths in ns, each >= the nominal one (``constant``: the nominal
        array itself).
    """
    mode = settings.ramp
    per_ns = np.asarray(period_ns, np.int64)
    n = len(per_ns)
    if mode == "constant" or n == 0:
        return per_ns

    high = np.asarray(high, np.uint8)
    if mode == "linear40":
        clock, _ = axis_bits(settings)
        s_mm, v_start, _, _ = settings.axis_limits()
        mf = np.zeros(1, np.int64) if move_first is None else np.asarray(move_first, np.int64)
        return linear40_periods(high, per_ns, mf, clock, s_mm, v_start)
    return _lookahead(high, per_ns, settings, stops)


def _lookahead(high: np.ndarray, per_ns: np.ndarray, settings: MachineSettings,
               stops: np.ndarray | None, partial: bool = True) -> np.ndarray:
    """The look-ahead planner (module docstring): ``(P,)`` int64 period lengths in ns.

    ``high``: ``(P,)`` uint8, ``per_ns``: ``(P,)`` int64 nominal lengths (P > 0), ``stops`` as
    :func:`ramp_periods`.  ``partial``: repeat rounds work out again only what the lowered caps reach (False: the
    whole window every round; the same periods, for tests).  One compiled call, without the GIL.
    """
    return _plan_window(*_window_args(high, per_ns, settings, stops), partial)[0]


def _window_args(high: np.ndarray, per_ns: np.ndarray, settings: MachineSettings, stops: np.ndarray | None) -> tuple:
    """The arguments of :func:`_plan_window` but ``partial``."""
    n = len(per_ns)
    stop_before = np.zeros(n + 1, bool)
    stop_before[0] = stop_before[n] = True
    if stops is not None and len(stops):
        stop_before[np.asarray(stops, np.int64)] = True
    clock, dirbit = axis_bits(settings)
    s_mm, v_start, v_max, acc = (np.asarray(v, np.float64) for v in settings.axis_limits())
    return (np.ascontiguousarray(high, np.uint8), np.ascontiguousarray(per_ns, np.int64), stop_before,
            np.asarray(clock, np.int64), np.asarray(dirbit, np.int64), s_mm, v_start, v_max, acc)


@entry
@njit(cache=True, nogil=True)
def _plan_window(high, per_ns, stop_before, clock, dirbit, s_mm, v_start, v_max, acc, partial):
    """Steps 1-3 of the planner (module docstring) over one window: ``(out, found)``, the ``(P,)`` int64 period
    lengths and the rule breaks the repeat rounds found (after the first round).

    ``stop_before``: ``(P + 1,)`` bool, a rest before period k (both ends set); ``clock``, ``dirbit``: ``(3,)`` int64
    the axes' bits; ``s_mm``, ``v_start``, ``v_max``, ``acc``: ``(3,)`` float64 per-axis limits.
    """
    n = per_ns.shape[0]
    cap = np.empty(n)
    for k in range(n):
        cap[k] = 1e9 / per_ns[k]
    alpha = np.full(n, np.inf)
    upull = np.full(n, np.inf)
    pers, brks = _axes_steps(high, per_ns, stop_before, clock, dirbit, s_mm, v_start)
    for a in range(3):
        _axis_caps(pers[a], brks[a], s_mm[a], v_start[a], v_max[a], acc[a] * _ALPHA_MARGIN, cap, alpha, upull)
    for k in range(n):
        if cap[k] < upull[k]:
            upull[k] = cap[k]
    return _rounds(pers, brks, per_ns, stop_before, cap, alpha, upull, s_mm, v_start, v_max, acc, partial)


@njit(cache=True, nogil=True)
def _axes_steps(high, per_ns, stop_before, clock, dirbit, s_mm, v_start):
    """``(pers, brks)``: each axis's step periods and the rests before them (:func:`_steps_of_axis`,
    :func:`_breaks`); what they are worked out from is let go on return (a window's planner holds less)."""
    n = per_ns.shape[0]
    stop_idx = np.flatnonzero(stop_before)
    # where an axis certainly stands still (its steps further apart than standstill_ns even
    # at the nominal periods, which ramps only lengthen): a stop and a start of that axis, so the intervals on
    # each side of the wait are capped at its start speed (a corner taken as grbl's junction rule would)
    start_ns = np.zeros(n + 1, np.int64)
    for k in range(n):
        start_ns[k + 1] = start_ns[k] + per_ns[k]
    per_x, up_x = _steps_of_axis(high, clock[0], dirbit[0])
    per_y, up_y = _steps_of_axis(high, clock[1], dirbit[1])
    per_z, up_z = _steps_of_axis(high, clock[2], dirbit[2])
    brks = (_breaks(per_x, up_x, stop_idx, start_ns, standstill_ns(s_mm[0], v_start[0])),
            _breaks(per_y, up_y, stop_idx, start_ns, standstill_ns(s_mm[1], v_start[1])),
            _breaks(per_z, up_z, stop_idx, start_ns, standstill_ns(s_mm[2], v_start[2])))
    return (per_x, per_y, per_z), brks


@njit(cache=True, nogil=True)
def _rounds(pers, brks, per_ns, stop_before, cap, alpha, upull, s_mm, v_start, v_max, acc, partial):
    """Steps 2-3, repeated (module docstring): ``(out, found)`` as :func:`_plan_window`."""
    n = per_ns.shape[0]
    fwd = np.empty(n)
    u = np.empty(n)
    out = np.empty(n, np.int64)
    mid = np.empty(n, np.int64)
    cap_dirty = np.zeros(n, np.bool_)
    changed = np.zeros(n, np.bool_)
    # the rule breaks _judge_axis records (only ever tested > 0: single precision holds any excess it records)
    marks = (np.zeros((3, pers[0].shape[0]), np.float32), np.zeros((3, pers[1].shape[0]), np.float32),
             np.zeros((3, pers[2].shape[0]), np.float32))
    whole = np.empty(2, np.int64)  # every period, as one run
    whole[0] = 0
    whole[1] = n - 1
    dirty = whole  # the runs of periods whose caps the last check lowered
    n_dirty = 1
    found = 0
    for rnd in range(_ROUNDS + 1):
        if rnd == _ROUNDS:
            for k in range(n):  # every axis at or below its start speed: meets every rule
                if upull[k] < cap[k]:
                    cap[k] = upull[k]
        full = rnd == 0 or rnd == _ROUNDS or not partial  # else only what the lowered caps reach is done again
        if full:
            cap_dirty[:] = False
            dirty = whole
            n_dirty = 1
        runs = np.empty(4 * n_dirty + 4, np.int64)
        n_runs = _passes(cap, alpha, upull, stop_before, fwd, u, changed, dirty, n_dirty, full, runs)
        if full:
            _periods_from_rates(u, per_ns, out, mid)
            spans = whole
            n_spans = 1
        else:
            n_spans, spans = _reperiods(u, per_ns, out, mid, changed, cap_dirty, runs, n_runs)
        if rnd == _ROUNDS:
            break
        hits = 0
        n_dirty = 0
        dirty = np.empty(2, np.int64)
        for a in range(3):
            r = marks[a]
            judged = np.empty(2 * n_spans + 2, np.int64)
            broken, n_judged = _judge_axis(pers[a], brks[a], mid, spans, n_spans, s_mm[a], v_start[a], v_max[a],
                                           acc[a], r[0], r[1], r[2], judged)
            if rnd > 0:
                found += broken
            if broken:  # lower the caps where it broke
                if 2 * (n_dirty + broken) > dirty.shape[0]:
                    room = np.empty(2 * (n_dirty + broken), np.int64)
                    room[:2 * n_dirty] = dirty[:2 * n_dirty]
                    dirty = room
                hit, n_dirty = _drop_caps(pers[a], r[0], r[1], r[2], u, cap, _DROP, s_mm[a], v_start[a], v_max[a],
                                          cap_dirty, judged, n_judged, dirty, n_dirty)
                hits += hit
        if hits == 0:
            break
        n_dirty = _merged_runs(dirty, n_dirty)
    return out, found


def top_speeds_mm_s(settings: MachineSettings) -> tuple[float, float, float]:
    """The top speed of X, Y and Z in mm/s: one step per step delay (``delay_xy_ms``, ``delay_z_ms``) and, with
    ramps, no more than the axis's ``max_speed_*_mm_s``."""
    s_mm, _, v_max, _ = settings.axis_limits()
    delays_s = (settings.delay_xy_ns / 1e9, settings.delay_xy_ns / 1e9, settings.delay_z_ns / 1e9)
    by_delay = [s / d for s, d in zip(s_mm, delays_s)]
    if settings.ramp == "constant":
        return tuple(by_delay)  # type: ignore[return-value]
    return tuple(min(v, m) for v, m in zip(by_delay, v_max))  # type: ignore[return-value]


def check_delay_speeds(settings: MachineSettings, what: str = "--delay") -> None:
    """Refuse step delays that ask an axis for more than its top speed with ramps (the delay would not mean what it
    says: the ramps would hold the axis to ``max_speed_*_mm_s``).

    Raises:
        CamError: one line naming the delay, the axis, the speed it asks and the setting that limits it.
    """
    if settings.ramp == "constant":
        return  # no ramps: the delay is the speed
    s_mm, _, v_max, _ = settings.axis_limits()
    delays_ms = (settings.delay_xy_ns / 1e6, settings.delay_xy_ns / 1e6, settings.delay_z_ns / 1e6)
    for a, (s, d_ms, v) in enumerate(zip(s_mm, delays_ms, v_max)):
        asked = s / (d_ms / 1e3)
        if asked > v * (1 + 1e-9):
            name = "xyz"[a]
            least_ms = s / v * 1e3
            raise CamError(f"{what} {d_ms:g} ms asks {name.upper()} for {asked:.3g} mm/s, over its top speed "
                           f"max_speed_{name}_mm_s = {v:g} mm/s: raise max_speed_{name}_mm_s in the machine file, use "
                           f"a delay of {least_ms:.3g} ms or more, or --ramp constant")
