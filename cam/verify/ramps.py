"""Proof on the pin log that a job's speed ramps keep every axis within its limits.

The checker knows nothing about how the plan was made: it decodes the pin
log (a step is a rising clock edge; its time is the write's time), splits
each axis's steps into *runs* and checks three rules per axis, with the
axis's ``s`` = mm per step, ``v_max``, start (pull-in) speed ``v_s`` and
acceleration ``A`` from the machine settings.

Runs.  An axis is at rest before its first step, after its last step, at a
reversal (two consecutive steps in opposite directions), at a pause
(Pause At, tool change: ``pause_writes``) and at a standstill: no step for
longer than :data:`STANDSTILL_STEPS` steps at its start speed (a corner where
the other axes go on while this one waits, then starts again: it stopped,
so it must start again at or below its start speed, as from any rest).  Its steps between two such rests
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
from typing import Iterable, Optional

import numpy as np
from numba import njit

from .._compiled import entry
from ..errors import CamError

from ..settings import DEFAULT_SETTINGS, MachineSettings
from .pinlog import PinLog, iter_pin_log, rising_edges
from ..pins import axis_bits

__all__ = ["RampViolation", "RampReport", "check_ramps", "check_axis_steps", "standstills", "standstill_ns",
           "mark_standstills", "STANDSTILL_STEPS"]

_TOL_NS = 1.0
_TOL_MM_S = 1e-6
STANDSTILL_STEPS = 2.0
"""An interval between two steps of an axis longer than this many steps at its start speed is a stop and a start,
not an interval of one motion (issue #32: an axis that waited 112 ms at a corner restarted at three times its start
speed, within the quantisation tolerance of R2)."""


@njit(cache=True, nogil=True)
def standstill_ns(s_mm: float, v_start: float) -> float:
    """The interval (ns) between two steps of an axis beyond which it stood still: :data:`STANDSTILL_STEPS`
    steps of ``s_mm`` mm at its start speed ``v_start`` (mm/s).  A kernel for kernels; Python calls its
    ``py_func``."""
    return STANDSTILL_STEPS * s_mm / v_start * 1e9


def standstills(t_ns: np.ndarray, s_mm: float, v_start: float) -> np.ndarray:
    """``(n,)`` bool: a standstill right before step j of one axis (``(n,)`` int64 step times ``t_ns``): the
    interval from step j - 1 is longer than :func:`standstill_ns`."""
    out = np.zeros(len(t_ns), bool)
    _standstills_kernel(np.ascontiguousarray(t_ns, np.int64), standstill_ns.py_func(s_mm, v_start), out)
    return out


@njit(cache=True, nogil=True)
def mark_standstills(t_ns, still_ns, brk):
    """Set ``brk[j]`` (``(n,)`` bool) where the interval from step j - 1 to step j (``(n,)`` int64 times ``t_ns``)
    is longer than ``still_ns``: the standstill rule, for :func:`standstills` and the look-ahead planner's judge
    (:func:`cam.motion.ramps._judge_steps`) alike."""
    for j in range(1, t_ns.shape[0]):
        if float(t_ns[j] - t_ns[j - 1]) > still_ns:
            brk[j] = True


@entry
@njit(cache=True, nogil=True)
def _standstills_kernel(t_ns, still_ns, brk):
    """:func:`mark_standstills`, called from Python (:func:`standstills`)."""
    mark_standstills(t_ns, still_ns, brk)



@njit(cache=True, nogil=True)
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
            Zero when called: only the breaks are written.  Pass three empty arrays to only count (nothing to
            record when it passes).

    Returns:
        How many rule breaks were found (0 = the axis passes).
    """
    return check_steps_range(t_ns, slot_of_step, slot_t_ns, brk, s_mm, v_start, v_max, acc, r1, r2, r3, 0,
                             t_ns.shape[0])


@njit(cache=True, nogil=True)
def check_steps_range(t_ns, slot_of_step, slot_t_ns, brk, s_mm, v_start, v_max, acc, r1, r2, r3, j_lo, j_hi):
    """:func:`check_axis_steps` judging only the intervals from steps ``j_lo .. j_hi - 1`` and the pairs around
    them (the arrays hold the steps around them too, which decide whether a judged interval starts or ends a
    run); records only there, and only the breaks (``r1``..``r3`` are zero there when called: the look-ahead
    planner's :func:`~cam.motion.ramps._drop_caps` leaves them so).  A kernel for other kernels (the planner
    re-judges only what changed)."""
    n = t_ns.shape[0]
    n_bad = 0
    record = r1.shape[0] > 0
    s_ns = s_mm * 1e9
    dmin = s_ns / v_max
    ds = s_ns / v_start
    for j in range(max(j_lo, 0), min(j_hi, n - 1)):
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
    last_d1 = -1.0
    last_d2 = -1.0
    last_lo = np.int64(-1)
    last_hi = np.int64(-1)
    last_ex = 0.0
    w_d = -1.0  # the last pair's second interval and its w (the next pair's first interval, most often)
    w_of_d = 0.0
    for j in range(max(j_lo, 1), min(j_hi, n - 1)):
        if brk[j] or brk[j + 1]:
            continue
        d1 = max(float(t_ns[j] - t_ns[j - 1]), 1.0)  # two steps at one time (a broken log): R1 has it already
        d2 = max(float(t_ns[j + 1] - t_ns[j]), 1.0)
        if d1 == d2 or (d1 >= ds and d2 >= ds):
            continue  # same speed, or both at or below the start speed (w = v_start for both)
        w1 = w_of_d if d1 == w_d else max(s_ns / d1, v_start)
        w2 = max(s_ns / d2, v_start)
        w_d, w_of_d = d2, w2
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


@njit(cache=True, nogil=True)
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
    log: PinLog | str | os.PathLike | Iterable[PinLog],
    settings: MachineSettings = DEFAULT_SETTINGS,
    *,
    pause_writes: np.ndarray | list[int] = (),
    stall_writes: np.ndarray | list[int] = (),
    slow_writes: np.ndarray | list[int] = (),
) -> RampReport:
    """Check rules R1..R3 (module docstring) on a pin log.

    Args:
        log: the pin log, a CSV path (read a piece at a time: a log of any length), or consecutive pieces of
            one (e.g. a :class:`~cam.motion.chunks.ChunkedPlan`'s chunks as pin logs); pieces give the report
            the whole log gives.
        settings: mm per step, start / top speed and acceleration per axis; pin map.
        pause_writes: write indices after which the job paused (``StepPlan.pause_writes``): rests.
        stall_writes: write indices a real-time run sent over :data:`cam.drive.runner.STALL_NS` late
            (``RunResult.lateness.stall_writes``): the motors stopped there, not by the plan, so each is a rest
            whose stop is not judged (the host could not help it) while the start after it is (R3, and R2 on):
            the runner must re-ramp.
        slow_writes: write indices a real-time run sent late at all (over
            :data:`cam.drive.runner.JITTER_NS`, 10 us: ``RunResult.lateness.slow_writes``): the slowdown into the
            interval that holds one is not judged (R2), the speed-up out of it is.

    Returns:
        A :class:`RampReport`; ``report.ok`` is the verdict.
    """
    if isinstance(log, PinLog):
        pieces: Iterable[PinLog] = [log]
    elif isinstance(log, (str, os.PathLike)):
        pieces = iter_pin_log(log)
    else:
        pieces = log
    checker = _Checker(settings, np.asarray(pause_writes, np.int64), np.asarray(stall_writes, np.int64),
                       np.asarray(slow_writes, np.int64))
    for piece in pieces:
        checker.add(piece)
    return checker.report()


_RULES = ("R1 top speed", "R2 acceleration", "R3 stop")


class _Checker:
    """:func:`check_ramps` a piece of the log at a time.

    Each axis keeps its last three steps (time, direction, global slot) from one piece to the next, so every
    interval and pair is judged once, in the first piece that holds all it needs: an interval ``g -> g + 1``
    needs steps ``g - 1 .. g + 2`` (whether it starts or ends a run), a pair around ``g`` steps ``g - 1 .. g + 1``
    and the slots next to ``g``'s.  The slots a piece's steps need are passed to the kernel as a short array of
    their own (each step's slot and its two neighbours, in order): the kernel only compares slot indices and
    reads neighbouring slots, which that array keeps.
    """

    def __init__(self, settings: MachineSettings, pause_writes: np.ndarray,
                 stall_writes: np.ndarray = np.zeros(0, np.int64),
                 slow_writes: np.ndarray = np.zeros(0, np.int64)) -> None:
        self.settings = settings
        self.stall_writes = np.sort(stall_writes)
        self.stall_t: list[int] = []
        self.slow_writes = np.sort(slow_writes)
        self.slow_t: list[int] = []
        self.clock, self.dirbit = axis_bits(settings)
        self.limits = settings.axis_limits()
        self.pause_writes = np.sort(pause_writes)
        self.pause_t: list[int] = []
        self.written = 0  # writes read so far
        self.last_t: Optional[int] = None  # the time of the last write read
        self.prev_byte = 0
        self.slot_t: dict[int, int] = {}  # times of the slots the carried steps need
        self.tail_slots: dict[int, int] = {}  # the last two slots read (the neighbours of the next piece's first)
        self.last_slot = -1  # the last slot read
        empty = np.zeros(0, np.int64)
        self.carry = [(empty, np.zeros(0, bool), empty) for _ in range(3)]  # (t, up, slot) of the last steps
        self.first_step = [0, 0, 0]  # global index of carry[a]'s first step
        self.judged = [[0, 1] for _ in range(3)]  # next interval, next pair to judge, per axis
        self.counts = {rule: 0 for rule in _RULES}
        self.found: dict[tuple[str, str], list[RampViolation]] = {}
        self.steps = [0, 0, 0]
        self.pairs = [0, 0, 0]
        self.vtop = [0.0, 0.0, 0.0]

    def add(self, piece: PinLog) -> None:
        t = np.asarray(piece.t_ns, np.int64)
        data = np.asarray(piece.data, np.uint8)
        w0, n = self.written, len(t)
        before = t[:1] if self.last_t is None else np.array([self.last_t], np.int64)
        back = np.flatnonzero(np.diff(np.concatenate([before, t])) < 0)
        if len(back):
            i = int(back[0])
            raise CamError(f"pin log: write {w0 + i} at {int(t[i])} ns is earlier than the write before it; "
                           f"not a log of one run")
        if n:
            self.last_t = int(t[-1])
        at = self.pause_writes[(self.pause_writes >= w0) & (self.pause_writes < w0 + n)]
        self.pause_t += t[at - w0].tolist()
        at = self.stall_writes[(self.stall_writes >= w0) & (self.stall_writes < w0 + n)]
        self.stall_t += t[at - w0].tolist()
        at = self.slow_writes[(self.slow_writes >= w0) & (self.slow_writes < w0 + n)]
        self.slow_t += t[at - w0].tolist()
        odd = w0 + (1 - w0 % 2)  # the first slot write (odd global index) of the piece
        chunk_slot0, chunk_slot_t = (odd - 1) // 2, t[odd - w0::2]
        self.last_slot = max(self.last_slot, chunk_slot0 + len(chunk_slot_t) - 1)
        for a in range(3):
            idx = np.flatnonzero(rising_edges(data, int(self.clock[a]), self.prev_byte))
            self.steps[a] += len(idx)
            ct, cu, cs = self.carry[a]
            self._judge(a, np.concatenate([ct, t[idx]]), np.concatenate([cu, (data[idx] & self.dirbit[a]) != 0]),
                        np.concatenate([cs, (idx + w0 - 1) // 2]), chunk_slot0, chunk_slot_t, final=False)
        if n:
            self.prev_byte = int(data[-1])
        self.written += n
        self.tail_slots.update({chunk_slot0 + k: int(chunk_slot_t[k]) for k in range(max(0, len(chunk_slot_t) - 2),
                                                                                  len(chunk_slot_t))})
        self.tail_slots = {i: v for i, v in self.tail_slots.items() if i >= self.last_slot - 1}

    def report(self) -> RampReport:
        for a in range(3):
            ct, cu, cs = self.carry[a]
            self._judge(a, ct, cu, cs, 0, np.zeros(0, np.int64), final=True)
        found = sorted((v for vs in self.found.values() for v in vs), key=lambda v: -v.excess_mm_s)
        ok = not any(self.counts.values())
        return RampReport(ok, dict(self.counts), found[:10], tuple(self.steps), tuple(self.pairs),  # type: ignore[arg-type]
                          tuple(self.vtop))  # type: ignore[arg-type]

    def _slot_times(self, needed: np.ndarray, chunk_slot0: int, chunk_slot_t: np.ndarray) -> np.ndarray:
        out = np.zeros(len(needed), np.int64)
        inside = (needed >= chunk_slot0) & (needed < chunk_slot0 + len(chunk_slot_t))
        out[inside] = chunk_slot_t[needed[inside] - chunk_slot0]
        for k in np.flatnonzero(~inside).tolist():
            i = int(needed[k])
            out[k] = self.slot_t[i] if i in self.slot_t else self.tail_slots[i]
        return out

    def _judge(self, a: int, ts: np.ndarray, up: np.ndarray, slot: np.ndarray, chunk_slot0: int,
               chunk_slot_t: np.ndarray, final: bool) -> None:
        n = len(ts)
        g0 = self.first_step[a]
        needed = np.unique(np.concatenate([slot - 1, slot, slot + 1])) if n else np.zeros(0, np.int64)
        needed = needed[(needed >= 0) & (needed <= self.last_slot)]  # a later slot: only for steps not judged here
        slot_t = self._slot_times(needed, chunk_slot0, chunk_slot_t)
        s_mm, v_start, v_max, acc = self.limits
        brk = standstills(ts, s_mm[a], v_start[a])
        if n > 1:
            brk[1:] |= up[1:] != up[:-1]
            if self.pause_t:
                pause_t = np.sort(np.asarray(self.pause_t, np.int64))
                brk[1:] |= np.searchsorted(pause_t, ts[:-1], "left") != np.searchsorted(pause_t, ts[1:], "left")
        stalled = np.zeros(n, bool)  # a stall (a late write) between steps j - 1 and j, step j's own included
        if n > 1 and self.stall_t:
            stall_t = np.sort(np.asarray(self.stall_t, np.int64))
            stalled[1:] = np.searchsorted(stall_t, ts[:-1], "right") != np.searchsorted(stall_t, ts[1:], "right")
            brk |= stalled
        r1, r2, r3 = (np.zeros(n) for _ in range(3))
        if n:
            check_axis_steps(ts, np.searchsorted(needed, slot), slot_t, brk, s_mm[a], v_start[a], v_max[a], acc[a],
                             r1, r2, r3)
            r3[:-2][stalled[2:]] = 0.0  # the stop at a stall is the host's lateness, not the plan: not judged
            if n > 2 and self.slow_t:  # the slowdown into an interval that holds a late write is the host's too
                slow_t = np.sort(np.asarray(self.slow_t, np.int64))
                slowed = np.searchsorted(slow_t, ts[:-1], "right") != np.searchsorted(slow_t, ts[1:], "right")
                r2[:-1][slowed & (np.diff(ts) > np.r_[np.inf, np.diff(ts)[:-1]])] = 0.0
        # what this piece judges, in local step indices: intervals j -> j + 1, pairs around j
        i_lo, i_hi = self.judged[a][0] - g0, (n - 1 if final else n - 2)
        p_lo, p_hi = max(self.judged[a][1] - g0, 1), n - 1
        i_hi, p_hi = max(i_hi, i_lo), max(p_hi, p_lo)
        self.judged[a] = [g0 + i_hi, g0 + p_hi]
        ji = np.arange(i_lo, i_hi)
        if len(ji):
            ok_d = np.diff(ts)[ji][~brk[ji + 1]]
            if len(ok_d):
                self.vtop[a] = max(self.vtop[a], float(s_mm[a] * 1e9 / max(int(ok_d.min()), 1)))
        jp = np.arange(p_lo, p_hi)
        self.pairs[a] += int(np.count_nonzero(~brk[jp] & ~brk[jp + 1])) if len(jp) else 0
        name = "xyz"[a]
        for rule, r, js in ((_RULES[0], r1, ji), (_RULES[1], r2, jp), (_RULES[2], r3, ji)):
            bad = js[r[js] > 0]
            if not len(bad):
                continue
            self.counts[rule] += len(bad)
            new = [RampViolation(rule, name, float(ts[j]) / 1e9, float(r[j]))
                   for j in bad[np.argsort(-r[bad], kind="stable")][:10]]
            kept = self.found.setdefault((name, rule), [])
            kept[:] = sorted(kept + new, key=lambda v: -v.excess_mm_s)[:10]
        keep = max(0, n - 3)  # the last three steps go on to the next piece, with the slots they need
        self.carry[a] = (ts[keep:], up[keep:], slot[keep:])
        self.first_step[a] = g0 + keep
        self._keep_slots(needed, slot_t)

    def _keep_slots(self, needed: np.ndarray, slot_t: np.ndarray) -> None:
        have = dict(zip(needed.tolist(), slot_t.tolist()))
        wanted = set()
        for _, _, cs in self.carry:
            for i in cs.tolist():
                wanted.update((i - 1, i, i + 1))
        self.slot_t = {i: self.slot_t.get(i, have.get(i)) for i in wanted if i in have or i in self.slot_t}
