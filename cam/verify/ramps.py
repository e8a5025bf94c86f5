"""Proof on the pin log that a job's speed ramps keep every axis within its limits.

The checker knows nothing about how the plan was made: it decodes the pin
log (a step is a rising clock edge; its time is the write's time), splits
each axis's steps into *runs* and checks three rules per axis, with the
axis's ``s`` = mm per step, ``v_max``, start (pull-in) speed ``v_s`` and
acceleration ``A`` from the machine settings.

Runs.  An axis is at rest before its first step, after its last step, at a
reversal (two consecutive steps in opposite directions) and at a pause
(Pause At, tool change: ``pause_writes``).  Its steps between two such rests
form a run; the interval between the last step of one run and the first of
the next is not a motion and is not judged.

Speeds.  Interval ``d_j = t_{j+1} - t_j`` between consecutive steps of a run
has speed ``v_j = s / d_j``, the axis's mean speed over it.

R1 (top speed).  ``d_j >= s / v_max`` for every interval.

R3 (stops).  The first and the last interval of every run is at or below the
start speed: ``d >= s / v_s``.  A motor can start from rest and stop at once
at its pull-in speed, so every rest is reached at or below it.

R2 (acceleration).  For consecutive intervals ``d1, d2`` of a run (sharing
the middle step), with ``w(d) = max(s / d, v_s)`` (speeds up to the pull-in
speed are reachable at once, so only the part above it costs acceleration)::

    |w(d2') - w(d1')| <= A * (min(d1', D_s) + min(d2', D_s)) / 2,   D_s = s / v_s

where ``d1' = d1 + e``, ``d2' = d2 - e``: the middle step moved by ``e``.  The
mean speed over an interval is the speed at the interval's middle for a
constantly accelerating motor, so ``(d1 + d2) / 2`` is the time between the two
speeds and a constant-acceleration motion meets the rule exactly; an interval
longer than ``D_s`` (an axis slower than its pull-in speed) counts only ``D_s``.

Quantisation tolerance, ``e``.  Every axis steps on a shared grid of step
slots, one per period (a DDA): in each period the major axis steps and the
minor axes step when their exact position has crossed the next step, so a
minor-axis step is up to one slot late or early against a smooth motion (and
a move a fraction of a step longer than its steps has a slot in which no
axis steps).  So the middle step may be moved (``e``) by up to one period
toward a *free slot*: a slot strictly between the axis's own neighbouring
steps at which it did not step, next to the step's own slot.  One period is
the smaller of the two slot gaps around the step's slot (so a long dwell
next to a step does not widen it).  An axis that steps in consecutive slots
(the major axis of a move) has no free slot and so no tolerance.  Slots are
the middle-of-period writes: a pin log of a step plan is one write that sets
the first directions, then two writes per period (middle: rising clocks;
end: clocks low), so the slots are the writes at odd indices.  ``e`` is tried at 0, at both limits and at the value that makes
``d1' = d2'`` when that is inside the limits; the pair passes if one of them
passes.  Each pair is judged with its own ``e`` (a relaxation: the middle
step is not held to the same ``e`` in the neighbouring pairs).  A DDA pattern
of intervals of m and m + 1 slots (any straight line) thus passes at any
steady speed, while a burst (steps in consecutive slots after a pause of
several slots, as in a staircase of 8-step pixel moves) is judged with the
burst's first interval lengthened by one slot only.

Write times are integer ns and a rising edge is written at ``start + T // 2``
of its period, so R1 and R3 allow 1 ns; R2 allows 1e-6 mm/s of rounding.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from .._compiled import entry

from ..settings import DEFAULT_SETTINGS, MachineSettings
from .pinlog import PinLog, read_pin_log, rising_edges
from ..drive.pins import axis_bits

__all__ = ["RampViolation", "RampReport", "check_ramps", "check_axis_steps"]

_TOL_NS = 1.0
_TOL_MM_S = 1e-6


@njit(cache=True)
def _pair_excess(d1, d2, e_lo, e_hi, s_ns, vs, acc, ds_ns):
    """Smallest R2 excess (mm/s) of the pair over the tried shifts of the middle step."""
    best = np.inf
    estar = 0.5 * (d2 - d1)
    for c in range(4):
        if c == 0:
            e = 0.0
        elif c == 1:
            e = -e_lo
        elif c == 2:
            e = e_hi
        else:
            if estar < -e_lo or estar > e_hi:
                continue
            e = estar
        a = d1 + e
        b = d2 - e
        if a <= 0.0 or b <= 0.0:
            continue
        w1 = max(s_ns / a, vs)
        w2 = max(s_ns / b, vs)
        dt_s = (min(a, ds_ns) + min(b, ds_ns)) * 0.5e-9
        ex = abs(w2 - w1) - acc * dt_s
        if ex < best:
            best = ex
    return best


@entry
@njit(cache=True, nogil=True)
def check_axis_steps(t_ns, slot_of_step, slot_t_ns, brk, s_mm, v_start, v_max, acc, r1, r2, r3):
    """Rules R1..R3 (module docstring) for the steps of one axis.

    Args:
        t_ns: ``(n,)`` int64 step times, increasing.
        slot_of_step, slot_t_ns: the slot of each step and the slot times (see "Quantisation tolerance" above).
        brk: ``(n,)`` bool, a rest (reversal or pause) right before step j.
        s_mm, v_start, v_max, acc: mm per step, start and top speed (mm/s), acceleration (mm/s^2).
        r1, r3: ``(n,)`` float64 out: speed excess (mm/s) of the interval from step j to j + 1 (0 = ok).
        r2: ``(n,)`` float64 out: acceleration excess (mm/s) of the pair around step j (0 = ok).
            Pass three empty arrays to only count (the planner's check: nothing to record when it passes).

    Returns:
        How many rule breaks were found (0 = the axis passes).
    """
    n = t_ns.shape[0]
    n_bad = 0
    record = r1.shape[0] > 0
    s_ns = s_mm * 1e9
    dmin = s_ns / v_max
    ds = s_ns / v_start
    for j in range(n - 1):
        if record:
            r1[j] = 0.0
            r3[j] = 0.0
        if brk[j + 1]:
            continue
        d = float(t_ns[j + 1] - t_ns[j])
        if d + _TOL_NS < dmin:
            if record:
                r1[j] = s_ns / max(d, 1.0) - v_max
            n_bad += 1
        first = j == 0 or brk[j]
        last = j + 2 >= n or brk[j + 2]
        if (first or last) and d + _TOL_NS < ds:
            if record:
                r3[j] = s_ns / max(d, 1.0) - v_start
            n_bad += 1
    if n > 0 and record:
        r1[n - 1] = 0.0
        r3[n - 1] = 0.0
        r2[0] = 0.0
        r2[n - 1] = 0.0
    last_d1 = -1.0
    last_d2 = -1.0
    last_lo = np.int64(-1)
    last_hi = np.int64(-1)
    last_ex = 0.0
    for j in range(1, n - 1):
        if record:
            r2[j] = 0.0
        if brk[j] or brk[j + 1]:
            continue
        d1 = float(t_ns[j] - t_ns[j - 1])
        d2 = float(t_ns[j + 1] - t_ns[j])
        if d1 == d2:
            continue  # same speed
        w1 = max(s_ns / d1, v_start)
        w2 = max(s_ns / d2, v_start)
        if abs(w2 - w1) <= acc * (min(d1, ds) + min(d2, ds)) * 0.5e-9 + _TOL_MM_S:
            continue  # passes unshifted (the common case)
        q_lo, q_hi = _shift_limits(slot_of_step, slot_t_ns, j)
        if d1 != last_d1 or d2 != last_d2 or q_lo != last_lo or q_hi != last_hi:
            # a DDA pattern repeats the same pair over and over: judge each new one once
            last_d1, last_d2, last_lo, last_hi = d1, d2, q_lo, q_hi
            last_ex = _pair_excess(d1, d2, float(q_lo), float(q_hi), s_ns, v_start, acc, ds)
        if last_ex > _TOL_MM_S:
            if record:
                r2[j] = last_ex
            n_bad += 1
    return n_bad


@njit(cache=True)
def _shift_limits(slot_of_step, slot_t_ns, j):
    """How far step ``j`` of one axis may move toward a free slot: ``(q_lo_ns, q_hi_ns)``, one period
    (the smaller slot gap around its slot) on a side where the axis left a slot free, else 0."""
    n = slot_of_step.shape[0]
    i = slot_of_step[j]
    quantum = np.int64(-1)
    if i > 0:
        quantum = slot_t_ns[i] - slot_t_ns[i - 1]
    if i + 1 < slot_t_ns.shape[0]:
        g = slot_t_ns[i + 1] - slot_t_ns[i]
        if quantum < 0 or g < quantum:
            quantum = g
    q_lo = np.int64(0)
    q_hi = np.int64(0)
    if quantum >= 0:
        if j > 0 and i - 1 > slot_of_step[j - 1]:
            q_lo = quantum
        if j + 1 < n and i + 1 < slot_of_step[j + 1]:
            q_hi = quantum
    return q_lo, q_hi


@dataclass
class RampViolation:
    """One broken rule: ``rule`` "R1 top speed" / "R2 acceleration" / "R3 stop", at ``t_s`` on ``axis``."""

    rule: str
    axis: str
    t_s: float
    excess_mm_s: float

    def __str__(self) -> str:
        return f"{self.rule} on {self.axis} at t={self.t_s:.6f} s: {self.excess_mm_s:.4g} mm/s over the limit"


@dataclass
class RampReport:
    """Result of :func:`check_ramps`.

    Attributes:
        ok: no rule broken.
        counts: violations per rule name.
        worst: up to 10 worst violations (largest excess first).
        steps: steps checked per axis (x, y, z).
        pairs: acceleration pairs checked per axis.
        max_speed_mm_s: highest interval speed per axis.
    """

    ok: bool
    counts: dict[str, int]
    worst: list[RampViolation]
    steps: tuple[int, int, int]
    pairs: tuple[int, int, int]
    max_speed_mm_s: tuple[float, float, float]
    notes: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """One line: ok, or the counts and the worst violation."""
        if self.ok:
            return f"ramps ok: {sum(self.steps)} steps, {sum(self.pairs)} acceleration pairs checked"
        parts = ", ".join(f"{n} x {rule}" for rule, n in self.counts.items() if n)
        return f"ramps broken: {parts}; worst: {self.worst[0]}"

    def raise_if_broken(self) -> None:
        """AssertionError with the summary when a rule is broken."""
        if not self.ok:
            raise AssertionError(self.summary() + "\n" + "\n".join(str(v) for v in self.worst))


def check_ramps(
    log: PinLog | str | os.PathLike,
    settings: MachineSettings = DEFAULT_SETTINGS,
    *,
    pause_writes: np.ndarray | list[int] = (),
) -> RampReport:
    """Check rules R1..R3 (module docstring) on a pin log.

    Args:
        log: the pin log (or a CSV path).
        settings: mm per step, start / top speed and acceleration per axis; pin map.
        pause_writes: write indices after which the job paused (``StepPlan.pause_writes``): rests.

    Returns:
        A :class:`RampReport`; ``report.ok`` is the verdict.
    """
    if not isinstance(log, PinLog):
        log = read_pin_log(log)
    t = np.asarray(log.t_ns, np.int64)
    data = np.asarray(log.data, np.uint8)
    clock, dirbit = axis_bits(settings)
    s_mm, v_start, v_max, acc = settings.axis_limits()
    rising = [rising_edges(data, int(clock[a])) for a in range(3)]
    slot_t = t[1::2]  # period middles (module docstring)
    pause_t = np.sort(t[np.asarray(pause_writes, np.int64)]) if len(pause_writes) else np.zeros(0, np.int64)
    counts = {"R1 top speed": 0, "R2 acceleration": 0, "R3 stop": 0}
    found: list[RampViolation] = []
    steps, pairs, vtop = [], [], []
    for a, name in enumerate("xyz"):
        idx = np.flatnonzero(rising[a])
        ts = t[idx]
        n = len(ts)
        steps.append(n)
        up = (data[idx] & dirbit[a]) != 0
        brk = np.zeros(n, bool)
        if n > 1:
            brk[1:] = up[1:] != up[:-1]
            if len(pause_t):
                # a pause at time p lies between steps j-1 and j when t[j-1] <= p < t[j]
                brk[1:] |= np.searchsorted(pause_t, ts[:-1], "left") != np.searchsorted(pause_t, ts[1:], "left")
        r1, r2, r3 = (np.zeros(n) for _ in range(3))
        check_axis_steps(ts, (idx - 1) // 2, slot_t, brk, s_mm[a], v_start[a], v_max[a], acc[a], r1, r2, r3)
        inner = np.ones(max(n - 2, 0), bool)
        if n > 2:
            inner &= ~brk[1:-1] & ~brk[2:]
        pairs.append(int(inner.sum()))
        d = np.diff(ts)
        ok_d = d[~brk[1:]] if n > 1 else d
        vtop.append(float(s_mm[a] * 1e9 / ok_d.min()) if len(ok_d) else 0.0)
        for rule, r in (("R1 top speed", r1), ("R2 acceleration", r2), ("R3 stop", r3)):
            bad = np.flatnonzero(r > 0)
            counts[rule] += len(bad)
            for j in bad[np.argsort(-r[bad])][:10]:
                found.append(RampViolation(rule, name, float(ts[j]) / 1e9, float(r[j])))
    found.sort(key=lambda v: -v.excess_mm_s)
    ok = not any(counts.values())
    return RampReport(ok, counts, found[:10], tuple(steps), tuple(pairs), tuple(vtop))  # type: ignore[arg-type]
