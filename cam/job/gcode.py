"""The G-code planner: an RS-274 program to a job in machine steps.

Frames, as for G-code out (:mod:`cam.kinds.gcode_export`): machine X steps = X mm / mm per step;
machine Y steps = -Y mm / mm per step (machine Y grows upward, the drawing
frame's rows downward; ``flip_y`` uses +Y); machine Z steps = -Z mm / mm per
step Z (+Z up in G-code, deeper is + in `cam`).  G-code (0, 0, 0) is the job's zero: where the tool
stands when it starts (``home_steps`` in the machine frame; the interpreter gives the moves from there).

Motion is generated so that every position the motors take is the nearest
step to a point on the programmed path: each period moves every axis by at
most one step, and each position is the rounding of the exact path point, so
the decoded motion stays within half a step (per axis) of the program.

The job is the motion itself: per move (a G-code line, the points of an arc
or of a G5/G5.1 spline, no axis more than 0.9 step apart) the planner
computes the exact path point at the end of every step period and rounds
it; consecutive periods that step the same axes the same way are one
straight move of the job (so :func:`cam.motion.steps.plan_steps` makes exactly
these periods again), with the move's feed as its nominal period.

The job is made a piece at a time (:class:`GcodeJobStream`, a :class:`~cam.job.model.JobLike`) from the
program's moves in batches (:meth:`cam.formats.gcode.GcodeProgram.move_batches` of a program held in memory,
:meth:`cam.formats.gcode.GcodeFile.move_batches` of a file interpreted a line at a time); what a move needs from
the moves before it (where the last one ended, exactly and rounded, and the program's time so far) is carried
from piece to piece (:class:`_Planner`), and no move's rows depend on the next move, so the pieces joined are
the same job at any piece size.  :func:`plan_gcode` is :func:`stream_gcode`'s pieces joined.  Consecutive
straight moves are planned together (:func:`_straight_run`) with the arithmetic of one move at a time.
"""
from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, field
from itertools import chain
from typing import Any, Iterator, Optional, Union

import numpy as np

from ._gcode_kernels import straight_rows_kernel
from ..errors import PlanError, TravelError
from ..formats.gcode import PLANE_AXES, GcodeFile, GcodeMove, GcodeProgram
from ..limits import MAX_MOVE_PERIODS, MAX_MOVE_S, MAX_PROGRAM_S
from ..settings import DEFAULT_SETTINGS, MachineSettings
from .model import CUT, TRAVEL, Job, PixelFrame, join_pieces

__all__ = ["plan_gcode", "stream_gcode", "GcodeJobStream", "PIECE_MOVES", "STREAM_MOVES", "steps_to_gcode_mm",
           "gcode_mm_to_steps", "program_extent_mm", "work_zero_range_mm"]

PIECE_MOVES = 1 << 12
"""Program moves planned into one piece of a :class:`GcodeJobStream` (at most: see :data:`PIECE_ROWS`)."""
_MOTIONS = ("rapid", "feed", "arc", "spline", "probe")
"""The kinds of :class:`~cam.formats.gcode.GcodeMove` that move the tool (a probe, G38.2/G38.3, planned as the feed
move to its target: as if it touched there, :mod:`cam.job.gcode_probing`)."""
PIECE_ROWS = 1 << 17
"""A piece ends after the move that makes its rows this many or more."""
STREAM_MOVES = 1 << 20
"""A G-code job of more moves (rows) than this is kept as its pieces, made again on each pass, rather than held
joined (:func:`cam.kinds.jobs.prepare_job`, :meth:`GcodeJobStream.held`)."""


@dataclass(frozen=True)
class _Arc:
    """An arc of one G-code move in machine-frame mm, in its plane's axes ``axes`` = (first, second, third)
    (:data:`cam.formats.gcode.PLANE_AXES`: (0, 1, 2) for XY, (2, 0, 1) for XZ, (1, 2, 0) for YZ): the centre
    ``(cx_mm, cy_mm)`` in the first and second axes, radius, start angle and signed sweep (rad) in that
    frame, and the third axis from ``z0_mm`` to ``z1_mm`` along it (helical)."""

    cx_mm: float
    cy_mm: float
    r_mm: float
    a0_rad: float
    sweep_rad: float
    z0_mm: float
    z1_mm: float
    axes: tuple[int, int, int] = (0, 1, 2)

    @classmethod
    def of(cls, p0: np.ndarray, mv: GcodeMove) -> "_Arc":
        """The arc of ``mv`` from ``p0`` (mm); G2 sweeps clockwise, a zero sweep is a full circle, and
        ``mv.turns`` - 1 more full turns are added."""
        axes = PLANE_AXES[mv.plane]
        first, second, third = axes
        cx, cy = mv.center
        x1, y1, z1 = mv.end[first], mv.end[second], mv.end[third]
        a0 = math.atan2(p0[second] - cy, p0[first] - cx)
        a1 = math.atan2(y1 - cy, x1 - cx)
        if mv.clockwise:
            sweep = -((a0 - a1) % (2 * math.pi))
            if abs(sweep) < 1e-12:
                sweep = -2 * math.pi
            sweep -= 2 * math.pi * (mv.turns - 1)
        else:
            sweep = (a1 - a0) % (2 * math.pi)
            if abs(sweep) < 1e-12:
                sweep = 2 * math.pi
            sweep += 2 * math.pi * (mv.turns - 1)
        return cls(cx, cy, math.hypot(p0[first] - cx, p0[second] - cy), a0, sweep, float(p0[third]), float(z1), axes)

    def at(self, t: np.ndarray) -> np.ndarray:
        """``(len(t), 3)`` points (mm, X Y Z) at fractions ``t`` (0..1) of the arc."""
        a = self.a0_rad + self.sweep_rad * t
        out = np.empty((len(t), 3))
        first, second, third = self.axes
        out[:, first] = self.cx_mm + self.r_mm * np.cos(a)
        out[:, second] = self.cy_mm + self.r_mm * np.sin(a)
        out[:, third] = self.z0_mm + (self.z1_mm - self.z0_mm) * t
        return out

    def n_points(self, step_mm: np.ndarray) -> int:
        """How many points :func:`_curve_points` takes: no axis moves more than 0.9 step between two."""
        first, second, third = self.axes
        arc_len_steps = abs(self.sweep_rad) * self.r_mm / min(step_mm[first], step_mm[second])
        dz_steps = abs(self.z1_mm - self.z0_mm) / step_mm[third]
        return max(1, int(math.ceil(max(arc_len_steps, dz_steps) / 0.9)))

    def crossings(self, axis: int, value_mm: float) -> list[float]:
        """The fractions t in 0..1 where the arc's coordinate ``axis`` (0 X, 1 Y, 2 Z) equals ``value_mm``."""
        first, second, third = self.axes
        if axis == third:
            dz = self.z1_mm - self.z0_mm
            t = (value_mm - self.z0_mm) / dz if dz else -1.0
            return [t] if 0 <= t <= 1 else []
        c = (value_mm - (self.cx_mm if axis == first else self.cy_mm)) / self.r_mm
        if not -1 <= c <= 1:
            return []
        bases = (math.acos(c), -math.acos(c)) if axis == first else (math.asin(c), math.pi - math.asin(c))
        out = []
        turns = int(abs(self.sweep_rad) // (2 * math.pi)) + 3
        for base in bases:
            for k in range(-turns, turns + 1):
                t = (base + 2 * math.pi * k - self.a0_rad) / self.sweep_rad
                if 0 <= t <= 1:
                    out.append(t)
        return out

    def box_mm(self) -> tuple[np.ndarray, np.ndarray]:
        """The arc's bounding box ``(lo, hi)``, ``(3,)`` mm each, computed from its ends and the axis
        extremes it sweeps over (nothing sampled)."""
        ts = [0.0, 1.0]
        reach = int(abs(self.sweep_rad) // (math.pi / 2)) + 8
        for k in range(-reach, reach + 1):  # the angles k * pi/2 the sweep passes: the circle's extremes
            t = (k * math.pi / 2 - self.a0_rad) / self.sweep_rad
            if 0 <= t <= 1:
                ts.append(t)
        pts = self.at(np.array(ts))
        return pts.min(axis=0), pts.max(axis=0)


@dataclass(frozen=True, eq=False)
class _Bezier:
    """The Bezier curve of one G5 (cubic) or G5.1 (quadratic) move: ``points_mm``, ``(degree + 1, 3)`` machine-frame
    mm, the start (where the last move ended), the move's inner control points and its end.  It has the
    interface of :class:`_Arc` (``at``, ``n_points``, ``crossings``, ``box_mm``) so that it is checked against
    the travel and sampled the same way."""

    points_mm: np.ndarray

    @classmethod
    def of(cls, p0: np.ndarray, mv: GcodeMove) -> "_Bezier":
        """The curve of the spline move ``mv`` from ``p0`` (mm)."""
        return cls(np.vstack([np.asarray(p0, np.float64)[None, :], np.array(mv.controls, np.float64).reshape(-1, 3),
                              np.array(mv.end, np.float64)[None, :]]))

    @property
    def degree(self) -> int:
        return len(self.points_mm) - 1

    def _power(self) -> np.ndarray:
        """``(degree + 1, 3)`` coefficients of the curve as a polynomial in t, lowest power first:
        C(n, k) times the k-th forward difference of the control points."""
        n = self.degree
        return np.array([math.comb(n, k) * np.diff(self.points_mm, k, axis=0)[0] for k in range(n + 1)])

    def at(self, t: np.ndarray) -> np.ndarray:
        """``(len(t), 3)`` points (mm, X Y Z) at parameters ``t`` (0..1), in the Bernstein form."""
        t = np.asarray(t, np.float64)[:, None]
        n = self.degree
        return sum(math.comb(n, k) * (1 - t) ** (n - k) * t ** k * self.points_mm[k][None, :] for k in range(n + 1))

    def n_points(self, step_mm: np.ndarray) -> int:
        """How many points :func:`_curve_points` takes: no axis moves more than 0.9 step between two.  The
        derivative of the curve is a Bezier curve through ``degree`` times the control points' differences,
        so no coordinate changes faster than ``degree x`` the largest of them over t = 0..1."""
        speed_steps = self.degree * np.abs(np.diff(self.points_mm, axis=0) / step_mm).max()
        return max(1, int(math.ceil(speed_steps / 0.9)))

    def _roots(self, coeffs: np.ndarray) -> list[float]:
        """The real roots in 0..1 of the polynomial ``coeffs`` (lowest power first)."""
        c = np.trim_zeros(np.asarray(coeffs, np.float64), "b")
        if len(c) < 2:
            return []
        r = np.roots(c[::-1])
        scale = max(1.0, float(np.abs(c).max()))
        real = r[np.abs(r.imag) <= 1e-9 * scale].real
        return [min(1.0, max(0.0, float(t))) for t in real if -1e-12 <= t <= 1 + 1e-12]

    def crossings(self, axis: int, value_mm: float) -> list[float]:
        """The parameters t in 0..1 where the curve's coordinate ``axis`` (0 X, 1 Y, 2 Z) equals ``value_mm``."""
        c = self._power()[:, axis].copy()
        c[0] -= value_mm
        return self._roots(c)

    def box_mm(self) -> tuple[np.ndarray, np.ndarray]:
        """The curve's bounding box ``(lo, hi)``, ``(3,)`` mm each: its ends and the extremes where a
        coordinate's derivative is zero (nothing sampled)."""
        c = self._power()
        ts = [0.0, 1.0]
        for axis in range(3):
            ts += self._roots(c[1:, axis] * np.arange(1, len(c)))
        pts = self.at(np.array(ts))
        return pts.min(axis=0), pts.max(axis=0)


_Curve = _Arc | _Bezier
"""A move sampled into points: an arc (G2/G3) or a spline (G5/G5.1)."""


def _curve_points(curve: _Curve, n: int, end_mm: np.ndarray) -> np.ndarray:
    """``(n, 3)`` points along an arc or a spline (mm), the last one exactly the move's end (see
    :meth:`_Arc.n_points`): each is a point of the exact curve."""
    pts = curve.at(np.arange(1, n + 1) / n)
    pts[-1] = end_mm
    return pts


class _Moves:
    """Collects the job's moves: runs of step periods that step the same axes the same way."""

    def __init__(self) -> None:
        self.points: list[np.ndarray] = []
        self.period_ns: list[np.ndarray] = []
        self.periods: list[np.ndarray] = []
        self.kind: list[np.ndarray] = []
        self.move_start: list[np.ndarray] = []
        self.rest: list[np.ndarray] = []
        self.pause: list[np.ndarray] = []
        self.pause_notes: list[str] = []
        self.at = np.zeros(3, np.int64)  # where the last move ends, steps
        self.origin = np.zeros(3, np.int64)  # where the job starts (its pieces' points are from there), steps
        self.n_rows = 0  # rows collected since the last piece

    def _add(self, points: np.ndarray, period_ns: int, periods: np.ndarray, kind: int, *,
             rest: bool = False, pause: bool = False) -> None:
        n = len(points)
        start = np.zeros(n, bool)
        start[:1] = True
        self.rows(points, np.full(n, period_ns, np.int64), periods, np.full(n, kind, np.uint8), start)
        self.rest[-1] = np.full(n, rest)
        self.pause[-1] = np.full(n, pause)

    def rows(self, points: np.ndarray, period_ns: np.ndarray, periods: np.ndarray, kind: np.ndarray,
             move_start: np.ndarray) -> None:
        """Rows of the job, each a column ``(n,)`` (``points`` ``(n, 3)`` int64 steps); no rest, no pause."""
        n = len(points)
        self.points.append(points)
        self.period_ns.append(period_ns)
        self.periods.append(periods)
        self.kind.append(kind)
        self.move_start.append(move_start)
        self.rest.append(np.zeros(n, bool))
        self.pause.append(np.zeros(n, bool))
        self.n_rows += n
        if n:
            self.at = points[-1]

    def motion(self, positions: np.ndarray, period_ns: int, kind: int, where: str = "") -> None:
        """One G-code move (at ``where``, file:line): the rounded position after each of its periods, ``(P, 3)``
        int64.

        Raises:
            PlanError: a period would move an axis by more than one step (an inner rule of the planner broken:
                named, not a traceback).
        """
        signed = np.diff(np.vstack([self.at[None, :], positions]), axis=0)
        if signed.size and np.abs(signed).max() > 1:
            raise PlanError(f"{where or 'G-code'}: this move would step an axis more than once in one step period "
                            f"(a planner fault: please report the file)")
        if len(signed) == 0:
            return
        change = np.ones(len(signed), bool)
        change[1:] = np.any(signed[1:] != signed[:-1], axis=1)
        first = np.flatnonzero(change)
        last = np.append(first[1:], len(signed)) - 1
        self._add(positions[last], period_ns, last - first + 1, kind)

    def dwell(self, seconds: float) -> None:
        """The machine rests where it is for ``seconds`` (one period of that length, no step)."""
        self._add(self.at[None, :].copy(), int(round(seconds * 1e9)), np.ones(1, np.int64), TRAVEL, rest=True)

    def pause_here(self, note: str) -> None:
        """The job pauses where the tool stands (a zero-length move that takes no time)."""
        self._add(self.at[None, :].copy(), 0, np.zeros(1, np.int64), TRAVEL, pause=True)
        self.pause_notes.append(note)

    def piece(self, settings: MachineSettings, source: str, warnings: list[str]) -> Job:
        """The rows collected since the last piece, as a :class:`~cam.job.model.Job` piece; then none are."""
        def cat(parts: list[np.ndarray], dtype, width: int = 0) -> np.ndarray:
            if parts:
                return np.concatenate(parts)
            return np.zeros((0, width) if width else 0, dtype)

        pts = cat(self.points, np.int64, 3) - self.origin
        kind = cat(self.kind, np.uint8)
        job = Job(points_steps=pts, kind=kind, target=(kind == CUT) & (pts[:, 2] > 0), pause=cat(self.pause, bool),
                  settings=settings, pause_notes=list(self.pause_notes), warnings=list(warnings), source=source,
                  period_ns=cat(self.period_ns, np.int64), periods=cat(self.periods, np.int64),
                  move_start=cat(self.move_start, bool), rest=cat(self.rest, bool))
        self.points, self.period_ns, self.periods, self.kind = [], [], [], []
        self.move_start, self.rest, self.pause, self.pause_notes = [], [], [], []
        self.n_rows = 0
        return job


class _Frame:
    """G-code millimetres to machine steps, and the travel in both."""

    def __init__(self, settings: MachineSettings, flip_y: bool, home_steps=(0, 0, 0)) -> None:
        s = settings
        self.to_steps = np.array([1 / s.mm_per_step_xy, (1 if flip_y else -1) / s.mm_per_step_xy, -1 / s.mm_per_step_z])
        self.step_mm = np.array([s.mm_per_step_xy, s.mm_per_step_xy, s.mm_per_step_z])
        # the travel in the job's frame: its zero is at machine ``home_steps`` (where the tool stands at the start)
        self.home = np.asarray(home_steps, np.float64).reshape(3)
        self.lo = np.array([b[0] for b in s.travel.bounds_steps()], np.float64) - self.home
        self.hi = np.array([b[1] for b in s.travel.bounds_steps()], np.float64) - self.home
        self.min_period = {True: max(s.delay_xy_ns, s.delay_z_ns), False: s.delay_xy_ns}
        self.delay_z_ns = s.delay_z_ns

    def outside(self, way_steps: np.ndarray) -> np.ndarray:
        """``(W,)`` bool: which of ``(W, 3)`` exact path points (steps) round to a step outside the travel."""
        return np.any((np.rint(way_steps) < self.lo) | (np.rint(way_steps) > self.hi), axis=1)

    def check(self, way_mm: np.ndarray, way_steps: np.ndarray, where: str) -> None:
        """Refuse a move whose points leave the travel, naming ``where`` (file:line)."""
        outside = self.outside(way_steps)
        if np.any(outside):
            self.refuse(way_mm[int(np.flatnonzero(outside)[0])], where)

    def refuse(self, q_mm: np.ndarray, where: str) -> None:
        """Raise the TravelError of a move that leaves the travel at ``q_mm`` (the first point outside, G-code mm
        from where the tool started): the point and the travel in the machine frame as ``cam where``, ``cam
        zero --at`` and ``cam goto`` give it (machine mm from the home, +Y toward the operator, +Z deeper), the
        frame named (the program's own coordinates are its line's)."""
        lo, hi = self.lo + self.home, self.hi + self.home
        q = (np.asarray(q_mm, np.float64) * self.to_steps + self.home) * self.step_mm + 0.0
        x_mm, y_mm, z_mm = (sorted(v * self.step_mm[a] + 0.0 for v in (lo[a], hi[a])) for a in range(3))
        raise TravelError(
            f"{where}: move to machine X{q[0]:.3f} Y{q[1]:.3f} Z{q[2]:.3f} mm leaves the machine travel (machine "
            f"X {x_mm[0]:g}..{x_mm[1]:g}, Y {y_mm[0]:g}..{y_mm[1]:g}, Z {z_mm[0]:g}..{z_mm[1]:g} mm; the machine "
            "frame of cam where and cam goto: from the home, +Y toward the operator, +Z deeper)"
        )

    def box_mm(self) -> tuple[np.ndarray, np.ndarray]:
        """The travel in G-code mm, ``(lo, hi)`` ``(3,)`` each: every point that rounds to a step inside it
        (half a step beyond the last steps)."""
        a = (self.lo - 0.5) / self.to_steps
        b = (self.hi + 0.5) / self.to_steps
        return np.minimum(a, b), np.maximum(a, b)

    def check_curve(self, arc: _Curve, n: int, end_mm: np.ndarray, where: str) -> None:
        """Refuse an arc or a spline that leaves the travel before it is sampled, naming the first of its ``n``
        points outside (:func:`_curve_points`); its bounding box and the points where it crosses the travel's
        bounds are computed, not sampled, so a huge curve costs nothing."""
        lo, hi = self.box_mm()
        a_lo, a_hi = arc.box_mm()
        if np.all(a_lo >= lo) and np.all(a_hi <= hi):
            return
        ts = sorted({0.0, 1.0, *(t for axis in range(3) for bound in (lo[axis], hi[axis])
                                 for t in arc.crossings(axis, float(bound)))})
        for t0, t1 in zip(ts[:-1], ts[1:]):
            mid = arc.at(np.array([(t0 + t1) / 2]))
            if not np.any(self.outside(mid * self.to_steps)):
                continue
            k0 = min(n, int(math.floor(t0 * n)) + 1)  # the first point after the crossing, and a few more
            ks = np.arange(k0, min(n, k0 + 64) + 1)
            pts = arc.at(ks / n)
            if ks[-1] == n:
                pts[-1] = end_mm
            out = np.flatnonzero(self.outside(pts * self.to_steps))
            self.refuse(pts[int(out[0])] if len(out) else mid[0], where)
        # only grazing the travel's edge (rounding): the sampled points decide, as for a line


def _periods(frame: _Frame, mv: GcodeMove, start_mm: np.ndarray, start_steps: np.ndarray, way: np.ndarray,
             way_steps: np.ndarray, where: str) -> tuple[np.ndarray, int]:
    """The rounded position after each period of one move (``(P, 3)`` int64) and its period length.

    Raises:
        PlanError: the move takes more than :data:`~cam.limits.MAX_MOVE_PERIODS` periods or, at its feed, more
            than :data:`~cam.limits.MAX_MOVE_S` (naming ``where``), checked before the periods are made.
    """
    starts = np.vstack([start_steps[None, :], way_steps[:-1]])
    d = way_steps - starts  # (W, 3) per sub-segment
    n_sub = np.maximum(1, np.ceil(np.abs(d).max(axis=1) - 1e-9).astype(np.int64))
    length_mm = float(np.sum(np.linalg.norm((way - np.vstack([start_mm[None, :], way[:-1]])), axis=1)))
    total_periods = int(n_sub.sum())
    if total_periods > MAX_MOVE_PERIODS:
        raise PlanError(f"{where}: the move takes {total_periods} step periods; one move may take at most "
                        f"{MAX_MOVE_PERIODS}")
    uses_z = bool(np.any(d[:, 2] != 0))
    floor_ns = frame.min_period[uses_z] if bool(np.any(d[:, :2] != 0)) else frame.delay_z_ns
    if mv.kind == "rapid" or (mv.feed_mm_min <= 0 and mv.minutes <= 0):
        per_ns = floor_ns
    else:
        duration_s = mv.minutes * 60.0 if mv.minutes > 0 else length_mm / (mv.feed_mm_min / 60.0)
        if duration_s > MAX_MOVE_S:
            raise PlanError(f"{where}: at F{mv.feed_mm_min:g} mm/min this {length_mm:g} mm move takes "
                            f"{duration_s / 3600:.4g} h; one move may take at most {MAX_MOVE_S / 3600:g} h")
        per_ns = max(floor_ns, int(round(duration_s * 1e9 / total_periods)))
    seg = np.repeat(np.arange(len(d)), n_sub)
    first = np.cumsum(n_sub) - n_sub
    k = np.arange(total_periods) - np.repeat(first, n_sub) + 1
    ideal = starts[seg] + d[seg] * (k / n_sub[seg])[:, None]
    return np.floor(ideal + 0.5).astype(np.int64), per_ns  # the nearest step to the exact path point


RUN_PERIODS = 1 << 18
"""Step periods of straight moves planned at once by :func:`_straight_run` (a longer move is planned alone)."""


@dataclass
class _Run:
    """Consecutive straight moves (G0, G1 and the like) planned at once: the job's rows of them, and where they
    leave the planner (see :func:`_straight_run`)."""

    points: np.ndarray  # (R, 3) int64 steps
    period_ns: np.ndarray  # (R,) int64
    periods: np.ndarray  # (R,) int64
    kind: np.ndarray  # (R,) uint8
    move_start: np.ndarray  # (R,) bool
    end_mm: np.ndarray  # (3,) the last move's end, G-code frame
    end_steps: np.ndarray  # (3,) its exact path point in steps
    program_ns: int


def _straight_run(frame: _Frame, mvs: list[GcodeMove], start_mm: np.ndarray, start_steps: np.ndarray,
                  at: np.ndarray, program_ns: int) -> Optional[_Run]:
    """The rows of consecutive straight moves ``mvs`` from ``start_mm`` (the exact point ``start_steps``, the
    rounded position ``at``), computed for all of them at once with the very arithmetic :func:`_periods` and
    :meth:`_Moves.motion` do for one move, so the rows are the same (tested).  None when a move breaks a rule
    (the travel, its periods or time, the program's time): the caller then plans them one by one, which names
    the line."""
    ends = np.array([mv.end for mv in mvs], np.float64).reshape(-1, 3)
    way_steps = ends * frame.to_steps
    if np.any(frame.outside(way_steps)):
        return None
    starts = np.vstack([start_steps[None, :], way_steps[:-1]])
    d = way_steps - starts
    n = np.maximum(1, np.ceil(np.abs(d).max(axis=1) - 1e-9).astype(np.int64))
    if int(n.max()) > MAX_MOVE_PERIODS:
        return None
    length_mm = np.linalg.norm(ends - np.vstack([start_mm[None, :], ends[:-1]]), axis=1)
    any_xy, uses_z = np.any(d[:, :2] != 0, axis=1), d[:, 2] != 0
    floor_ns = np.where(any_xy, np.where(uses_z, frame.min_period[True], frame.min_period[False]), frame.delay_z_ns)
    feed = np.array([mv.feed_mm_min for mv in mvs], np.float64)
    minutes = np.array([mv.minutes for mv in mvs], np.float64)
    rapid = np.array([mv.kind == "rapid" for mv in mvs]) | ((feed <= 0) & (minutes <= 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        duration_s = np.where(minutes > 0, minutes * 60.0, length_mm / (feed / 60.0))
        if np.any(~rapid & (duration_s > MAX_MOVE_S)):
            return None
        per_ns = np.where(rapid, floor_ns, np.maximum(floor_ns, np.rint(np.where(rapid, 0.0, duration_s) * 1e9 / n)
                                                      .astype(np.int64)))
    times = program_ns + np.cumsum(per_ns * n)
    if times[-1] > MAX_PROGRAM_S * 1e9:
        return None
    points, count, move_of, is_first = straight_rows_kernel(np.ascontiguousarray(starts), np.ascontiguousarray(d),
                                                            n.astype(np.int64), np.asarray(at, np.int64))
    kind = np.where(np.array([mv.kind == "rapid" for mv in mvs]), TRAVEL, CUT).astype(np.uint8)
    return _Run(points, per_ns[move_of], count, kind[move_of], is_first, ends[-1], way_steps[-1], int(times[-1]))


class _Planner:
    """Plans a program's moves one after the other, carrying what joins one piece to the next: where the last
    move ended (in mm, its exact path point in steps, and the rounded position the rows reached) and the
    program's time so far."""

    def __init__(self, settings: MachineSettings, flip_y: bool, source: str, home_steps=(0, 0, 0),
                 start_mm=None, start_steps=None) -> None:
        self.settings, self.source = settings, source
        self.frame = _Frame(settings, flip_y, home_steps)
        self.moves = _Moves()
        self.cur_mm = np.zeros(3)  # G-code frame
        self.cur_steps = np.zeros(3)  # the exact path point, in steps
        self.program_ns = 0  # the program's time so far at its feeds and dwells
        if start_mm is not None:  # a part of a program that probes: from where its probe left the tool
            self.cur_mm = np.asarray(start_mm, np.float64).reshape(3).copy()
            self.cur_steps = self.cur_mm * self.frame.to_steps
            self.moves.at = np.asarray(start_steps, np.int64).reshape(3).copy()
            self.moves.origin = self.moves.at.copy()

    def move(self, mv: GcodeMove) -> None:
        """Plan one move (see :func:`plan_gcode` for the checks)."""
        where = f"{mv.file or self.source}:{mv.line}"
        if mv.kind == "pause":
            self.moves.pause_here(mv.note)
            return
        if mv.kind == "dwell":
            if mv.seconds > 0:
                self.moves.dwell(mv.seconds)
                self.program_ns = _add_time(self.program_ns, int(round(mv.seconds * 1e9)), where)
            return
        frame = self.frame
        end = np.array(mv.end, np.float64)
        if mv.kind in ("arc", "spline"):
            curve = _Arc.of(self.cur_mm, mv) if mv.kind == "arc" else _Bezier.of(self.cur_mm, mv)
            n = curve.n_points(frame.step_mm)
            frame.check_curve(curve, n, end, where)  # before anything is sampled
            if n > MAX_MOVE_PERIODS:
                raise PlanError(f"{where}: the {mv.kind} takes at least {n} step periods; one move may take at "
                                f"most {MAX_MOVE_PERIODS}")
            way = _curve_points(curve, n, end)
        else:
            way = end[None, :]
        way_steps = way * frame.to_steps
        frame.check(way, way_steps, where)
        positions, per_ns = _periods(frame, mv, self.cur_mm, self.cur_steps, way, way_steps, where)
        self.moves.motion(positions, per_ns, TRAVEL if mv.kind == "rapid" else CUT, where)
        self.program_ns = _add_time(self.program_ns, per_ns * len(positions), where)
        self.cur_mm, self.cur_steps = end, way_steps[-1]

    def plan(self, mvs: list[GcodeMove], piece_rows: int) -> Iterator[None]:
        """Plan ``mvs`` in order (consecutive straight moves at once, :func:`_straight_run`); yields whenever
        ``piece_rows`` rows or more wait for :meth:`piece` (between two moves)."""
        i = 0
        step_mm = float(self.frame.step_mm.min())
        while i < len(mvs):
            j = i
            periods = 0
            while j < len(mvs) and mvs[j].kind in ("rapid", "feed") and (j == i or periods < RUN_PERIODS):
                a, b = mvs[j].end, mvs[j - 1].end if j > i else self.cur_mm
                periods += int(max(abs(a[0] - b[0]), abs(a[1] - b[1]), abs(a[2] - b[2])) / step_mm) + 1
                j += 1
            run = _straight_run(self.frame, mvs[i:j], self.cur_mm, self.cur_steps, self.moves.at, self.program_ns) \
                if j > i + 1 else None
            if run is None:
                j = i + 1
                self.move(mvs[i])
            else:
                self.moves.rows(run.points, run.period_ns, run.periods, run.kind, run.move_start)
                self.cur_mm, self.cur_steps, self.program_ns = run.end_mm, run.end_steps, run.program_ns
            i = j
            if self.moves.n_rows >= piece_rows:
                yield

    def piece(self, warnings: list[str]) -> Job:
        """The rows planned since the last piece, with the ``warnings`` first given meanwhile."""
        return self.moves.piece(self.settings, self.source, warnings)


_SPILL_COLUMNS = (("points_steps", np.int64, 3), ("kind", np.uint8, 1), ("target", np.bool_, 1),
                  ("pause", np.bool_, 1), ("period_ns", np.int64, 1), ("periods", np.int64, 1),
                  ("move_start", np.bool_, 1), ("rest", np.bool_, 1))
"""The per-move columns of a G-code piece as :class:`_Spill` stores them (name, dtype, values per move)."""
_SPILL_BYTES = sum(np.dtype(dtype).itemsize * width for _, dtype, width in _SPILL_COLUMNS)


class _Spill:
    """A pass's pieces kept in an anonymous temporary file (45 bytes a move), read back by later passes: the
    program is interpreted once however often its job is read, and nothing per move stays in memory.  Each
    piece's notes and warnings stay in memory (a few per piece); reads use their own offsets, so passes may run
    side by side."""

    def __init__(self) -> None:
        self.file = tempfile.TemporaryFile(prefix="cam-gcode-")
        self.index: list[tuple[int, int, list[str], list[str]]] = []  # (offset, moves, notes, warnings)
        self.end = 0

    def write(self, piece: Job) -> None:
        data = b"".join(np.ascontiguousarray(getattr(piece, name), dtype).tobytes()
                        for name, dtype, _ in _SPILL_COLUMNS)
        self.file.write(data)
        self.index.append((self.end, len(piece), list(piece.pause_notes or []), list(piece.warnings)))
        self.end += len(data)

    def pieces(self, settings: MachineSettings, source: str) -> Iterator[Job]:
        self.file.flush()
        for offset, n, notes, warnings in self.index:
            buf = bytearray(os.pread(self.file.fileno(), n * _SPILL_BYTES, offset))
            cols, at = {}, 0
            for name, dtype, width in _SPILL_COLUMNS:
                size = n * width * np.dtype(dtype).itemsize
                cols[name] = np.frombuffer(buf, dtype, n * width, at).reshape((n, 3) if width == 3 else n)
                at += size
            yield Job(**cols, settings=settings, pause_notes=list(notes), warnings=list(warnings), source=source)


@dataclass
class GcodeJobStream:
    """The G-code job as consecutive :class:`~cam.job.model.Job` pieces (a :class:`~cam.job.model.JobLike`):
    :func:`plan_gcode` is :meth:`joined`.

    :meth:`pieces` plans them anew on each pass from the moves of ``src`` (or, with :attr:`spill`, reads back the
    first whole pass's): a :class:`~cam.formats.gcode.GcodeFile` (interpreted again a line at a time: nothing per
    line or per move is held) or a :class:`~cam.formats.gcode.GcodeProgram` held in memory.  Each piece is the
    rows of a batch of about ``piece_moves`` program moves (the interpreter never splits a line's moves), ended
    early after the move that brings its rows to :data:`PIECE_ROWS` (a move is never split: a piece holds at most
    one move's :data:`~cam.limits.MAX_MOVE_PERIODS` rows more); what joins it to the next is carried over
    (:class:`_Planner`), so the pieces joined are the same job whatever the piece size (tested).  Every check of
    :func:`plan_gcode` (travel, a move's periods and time, the program's time so far) is made as the piece of
    its move is made, naming the line.

    Attributes:
        src: the program; settings: the machine settings; flip_y: G-code +Y is machine +Y.
        piece_moves: program moves planned into one piece.
        n_moves: the job's moves (rows), -1 until a pass ended; n_program_moves: the program's moves (the same).
        n_motions: the program's moves that go somewhere (a G0, G1, arc, spline or cycle move that ends elsewhere
            than it starts, or a full circle), -1 until a pass ended: 0 is a program that makes no moves.
        pause_notes, warnings: the job's (the warnings: a file's, once a pass ended).
        spill: keep the first whole pass's pieces in a temporary file for the later passes (:class:`_Spill`).
        safe_z_steps: 0 (a stop lifts to the home plane); pixels, tool: None (no drawing frame; the point tool).
        home_steps: the machine position of the job's zero, where the tool stands when it starts (the program's
            ``start_mm``): the travel is checked in the machine frame, before anything moves.
        start_mm, start_steps: a part of a program that probes (:mod:`cam.job.gcode_probing`): where its moves
            start, G-code mm and the steps the tool stands at (from the program's start, ``home_steps``); its pieces'
            points are from there.  None: the program's start.
        probes: what each probe (G38.2, G38.3) of the program asks, in order (``file:line: G38.2 down at most 10
            mm at F60 mm/min``), once a pass ended; its moves after a probe are planned as if it touched at its
            target (a machine runs them planned from the contact: :mod:`cam.job.gcode_probing`).
        probe_feeds_mm_min: each probe's feed, in the same order.
    """

    src: Union[GcodeProgram, GcodeFile]
    settings: MachineSettings = DEFAULT_SETTINGS
    flip_y: bool = False
    piece_moves: int = PIECE_MOVES
    n_moves: int = -1
    n_program_moves: int = -1
    n_motions: int = -1
    pause_notes: list[str] = field(default_factory=list)
    safe_z_steps: int = 0
    pixels: Optional[PixelFrame] = None
    tool: Any = None
    spill: bool = False
    _spilled: Optional[_Spill] = field(default=None, repr=False)
    _spilling: bool = field(default=False, repr=False)
    home_steps: tuple[int, int, int] = (0, 0, 0)
    start_mm: Optional[tuple[float, float, float]] = None
    start_steps: Optional[tuple[int, int, int]] = None
    _probes: list[tuple[str, float]] = field(default_factory=list, repr=False)

    @property
    def source(self) -> str:
        return self.src.source

    @property
    def probes(self) -> Optional[list[str]]:
        """What each probe of the program asks (see the class docstring; a pass is made when none has ended), or
        None: it has none (as :attr:`cam.job.model.Job.probes`)."""
        if self.n_moves < 0:
            len(self)
        return [text for text, _ in self._probes] or None

    @property
    def probe_feeds_mm_min(self) -> list[float]:
        """Each probe's feed (mm/min), in the order of :attr:`probes`."""
        if self.n_moves < 0:
            len(self)
        return [feed for _, feed in self._probes]

    @property
    def warnings(self) -> list[str]:
        return list(self.src.warnings)

    def __getstate__(self) -> dict:
        """Pickled (to another process: the page's worker) without its spill, a temporary file of this process:
        the receiver plans the program again on its first pass."""
        return {**self.__dict__, "_spilled": None, "_spilling": False}

    def __len__(self) -> int:
        if self.n_moves < 0:
            for _ in self.pieces():
                pass
        return self.n_moves

    def joined(self) -> Job:
        """Every move in one :class:`~cam.job.model.Job` (:func:`~cam.job.model.join_pieces` of :meth:`pieces`)."""
        return join_pieces(self.pieces(), self)

    def held(self, max_moves: int) -> Optional[Job]:
        """:meth:`joined` if the job has at most ``max_moves`` moves, else None (found in one pass, in which the
        pieces are never all held for a larger job; with :attr:`spill` the pass goes on to the end, spilling)."""
        parts: Optional[list[Job]] = []
        rows = 0
        for piece in self.pieces():
            rows += len(piece)
            if parts is not None and rows <= max_moves:
                parts.append(piece)
                continue
            parts = None
            if not self.spill:
                return None
        return None if parts is None else join_pieces(parts, self)

    def pieces(self) -> Iterator[Job]:
        """The job's moves as consecutive :class:`~cam.job.model.Job` pieces (at least one; see the class
        docstring for their size).

        Raises:
            ParseError: the program is malformed (``file:line``, when its line is reached);
            TravelError, PlanError: as :func:`plan_gcode`.
        """
        if self._spilled is not None:
            yield from self._spilled.pieces(self.settings, self.source)
            return
        spill = _Spill() if self.spill and not self._spilling else None
        self._spilling |= spill is not None
        try:
            for piece in self._planned():
                if spill is not None:
                    spill.write(piece)
                yield piece
            if spill is not None:
                self._spilled, spill = spill, None
        finally:
            if spill is not None:
                self._spilling = False
                spill.file.close()

    def _planned(self) -> Iterator[Job]:
        """The pieces, planned from the program's moves (see :meth:`pieces`)."""
        planner = _Planner(self.settings, self.flip_y, self.source, self.home_steps, self.start_mm, self.start_steps)
        notes: list[str] = []
        warnings: list[str] = []
        probes: list[tuple[str, float]] = []
        n_rows = n_program = n_motions = 0
        given = False
        # the moves are given from where the tool starts
        last_end_mm: tuple[float, float, float] = self.start_mm or (0.0, 0.0, 0.0)  # type: ignore[assignment]
        for batch in self.src.move_batches(self.piece_moves):
            warnings += batch.warnings
            for mv in batch.moves:
                if mv.kind == "probe":
                    probes.append((f"{mv.file or self.source}:{mv.line}: {mv.note} down at most "
                                   f"{last_end_mm[2] - mv.end[2]:.4g} mm at F{mv.feed_mm_min:g} mm/min",
                                   mv.feed_mm_min))
                if mv.kind in _MOTIONS:
                    n_motions += mv.end != last_end_mm or mv.kind == "arc"
                    last_end_mm = mv.end
            for _ in chain(planner.plan(batch.moves, PIECE_ROWS), [None]):
                if planner.moves.n_rows:
                    piece = planner.piece(warnings)
                    warnings, given = [], True
                    notes += piece.pause_notes or []
                    n_rows += len(piece)
                    yield piece
            n_program += len(batch.moves)
        if warnings or not given:
            yield planner.piece(warnings)
        self.n_moves, self.n_program_moves, self.pause_notes = n_rows, n_program, notes
        self.n_motions, self._probes = n_motions, probes


def stream_gcode(src: Union[GcodeProgram, GcodeFile], settings: MachineSettings = DEFAULT_SETTINGS, *,
                 flip_y: bool = False, piece_moves: int = PIECE_MOVES, spill: bool = False,
                 home_steps: tuple[int, int, int] = (0, 0, 0)) -> GcodeJobStream:
    """The job of a G-code program as a :class:`GcodeJobStream` (a :class:`~cam.formats.gcode.GcodeFile`'s: bounded
    memory; a :class:`~cam.formats.gcode.GcodeProgram`'s moves are sliced).  See :func:`plan_gcode`.

    ``spill``: the first pass that runs to the end keeps its pieces in a temporary file, which later passes read
    instead of interpreting and planning the program again (the same pieces).  ``home_steps``: the machine
    position of the job's zero (see :class:`GcodeJobStream`)."""
    return GcodeJobStream(src, settings, bool(flip_y), max(1, int(piece_moves)), spill=bool(spill),
                          home_steps=tuple(int(v) for v in home_steps))  # type: ignore[arg-type]


def plan_gcode(program: Union[GcodeProgram, GcodeFile], settings: MachineSettings = DEFAULT_SETTINGS, *,
               flip_y: bool = False) -> Job:
    """The job of a G-code program (see the module docstring for frames and accuracy): the pieces of
    :func:`stream_gcode` joined.

    Rapids run at the configured step delays; feed moves at their F, never faster than the delays allow;
    :func:`cam.motion.steps.plan_steps` then lengthens periods with the speed ramps of ``settings.ramp``,
    stopping at pauses and dwells.

    Every move is checked before its points are made: an arc's bounding box against the travel (a huge
    arc is refused at once, naming its first point outside), the number of its step periods against
    :data:`~cam.limits.MAX_MOVE_PERIODS`, its duration at its feed against :data:`~cam.limits.MAX_MOVE_S`,
    and the program's time so far against :data:`~cam.limits.MAX_PROGRAM_S`.

    Raises:
        TravelError: a move leaves the machine travel (naming the line and the first point outside).
        PlanError: a move too long or too slow, a program too long (naming the line).
    """
    return stream_gcode(program, settings, flip_y=flip_y).joined()


def steps_to_gcode_mm(xyz_steps: Any, settings: MachineSettings = DEFAULT_SETTINGS, *, flip_y: bool = False
                      ) -> tuple[float, float, float]:
    """A machine-frame position in steps as G-code mm (X right, Y = -y steps or +y with ``flip_y``, Z up), the
    inverse of the planner's frame: what the interpreter's ``start_mm`` and ``work_offsets_mm`` take."""
    to = _Frame(settings, flip_y).to_steps
    return tuple(float(int(v) / t) + 0.0 for v, t in zip(xyz_steps, to))  # type: ignore[return-value]


def gcode_mm_to_steps(xyz_mm: Any, settings: MachineSettings = DEFAULT_SETTINGS, *, flip_y: bool = False
                      ) -> tuple[int, int, int]:
    """G-code mm (see :func:`steps_to_gcode_mm`) as the nearest machine steps."""
    to = _Frame(settings, flip_y).to_steps
    return tuple(int(math.floor(float(v) * t + 0.5)) for v, t in zip(xyz_mm, to))  # type: ignore[return-value]


def _add_time(program_ns: int, move_ns: int, where: str) -> int:
    """The program's time after one more move or dwell; more than :data:`~cam.limits.MAX_PROGRAM_S` is refused."""
    total_ns = program_ns + move_ns
    if total_ns > MAX_PROGRAM_S * 1e9:
        raise PlanError(f"{where}: the program takes more than {MAX_PROGRAM_S / 86400:g} days up to this line")
    return total_ns


def program_extent_mm(program: Union[GcodeProgram, GcodeFile]) -> Optional[tuple[np.ndarray, np.ndarray]]:
    """The box ``(lo, hi)`` (``(3,)`` mm each, G-code axes: +Y up, +Z up) that the program's moves reach, in the
    frame its moves are given in (its own frame when it runs from its work zero with the offsets 0: the default of
    :func:`cam.formats.gcode.open_gcode`); arcs and splines by their exact bounding boxes.  None: no moves.

    Nothing is planned, so a program that leaves the travel from where it would run now still has its extent
    (``cam info`` from a fresh state).  Reads the program a batch of moves at a time (bounded memory).
    """
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    p0 = np.zeros(3)
    for batch in program.move_batches(PIECE_MOVES):
        for mv in batch.moves:
            if mv.kind not in _MOTIONS:
                continue
            end = np.array(mv.end, np.float64)
            if mv.kind == "arc":
                a, b = _Arc.of(p0, mv).box_mm()
            elif mv.kind == "spline":
                a, b = _Bezier.of(p0, mv).box_mm()
            else:
                a = b = end
            lo, hi = np.minimum(lo, a), np.maximum(hi, b)
            p0 = end
    return None if not np.all(np.isfinite(lo)) else (lo + 0.0, hi + 0.0)


def work_zero_range_mm(extent_mm: tuple[np.ndarray, np.ndarray], settings: MachineSettings = DEFAULT_SETTINGS, *,
                       flip_y: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Where a work zero may stand for a program of extent ``extent_mm`` (:func:`program_extent_mm`) to stay in
    the machine travel: ``(lo, hi)`` ``(3,)`` each in the machine frame of ``cam where``, ``cam zero --at`` and
    ``cam goto`` (machine mm from the home, +Y toward the operator unless ``flip_y``, +Z deeper); an axis with
    ``lo > hi`` is one the program is too large for."""
    s = settings
    sign = np.array([1.0, 1.0 if flip_y else -1.0, -1.0])
    step_mm = np.array([s.mm_per_step_xy, s.mm_per_step_xy, s.mm_per_step_z])
    bounds = np.array(s.travel.bounds_steps(), np.float64) * step_mm[:, None]  # (3, 2) machine mm
    a, b = sign * extent_mm[0], sign * extent_mm[1]  # the extent's reach in the machine's sense
    reach_lo, reach_hi = np.minimum(a, b), np.maximum(a, b)
    return bounds[:, 0] - reach_lo + 0.0, bounds[:, 1] - reach_hi + 0.0
