"""The G-code planner: an RS-274 program to a job in machine steps.

Frames, as for G-code out (:mod:`cam.formats.gcode_export`): machine X steps = X mm / mm per step;
machine Y steps = -Y mm / mm per step (machine Y grows upward, the drawing
frame's rows downward; ``flip_y`` uses +Y); machine Z steps = -Z mm / mm per
step Z (+Z up in G-code, deeper is + in `cam`).  G-code (0, 0, 0) is the home.

Motion is generated so that every position the motors take is the nearest
step to a point on the programmed path: each period moves every axis by at
most one step, and each position is the rounding of the exact path point, so
the decoded motion stays within half a step (per axis) of the program.

The job is the motion itself: per move (a G-code line, an arc's chords) the
planner computes the exact path point at the end of every step period and
rounds it; consecutive periods that step the same axes the same way are one
straight move of the job (so :func:`cam.drive.steps.plan_steps` makes exactly
these periods again), with the move's feed as its nominal period.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import TravelError
from ..formats.gcode import GcodeMove, GcodeProgram
from ..settings import DEFAULT_SETTINGS, MachineSettings
from .model import CUT, TRAVEL, Job

__all__ = ["plan_gcode"]


def _arc_points(p0: np.ndarray, mv: GcodeMove, step_mm: np.ndarray) -> np.ndarray:
    """Points along an arc (mm), close enough that no axis moves more than 0.9 step between them."""
    cx, cy = mv.center
    x1, y1, z1 = mv.end
    a0 = math.atan2(p0[1] - cy, p0[0] - cx)
    a1 = math.atan2(y1 - cy, x1 - cx)
    r = math.hypot(p0[0] - cx, p0[1] - cy)
    if mv.clockwise:
        sweep = -((a0 - a1) % (2 * math.pi))
        if abs(sweep) < 1e-12:
            sweep = -2 * math.pi
    else:
        sweep = (a1 - a0) % (2 * math.pi)
        if abs(sweep) < 1e-12:
            sweep = 2 * math.pi
    arc_len_steps = abs(sweep) * r / min(step_mm[0], step_mm[1])
    dz_steps = abs(z1 - p0[2]) / step_mm[2]
    n = max(1, int(math.ceil(max(arc_len_steps, dz_steps) / 0.9)))
    t = np.arange(1, n + 1) / n
    a = a0 + sweep * t
    pts = np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a), p0[2] + (z1 - p0[2]) * t])
    pts[-1] = (x1, y1, z1)
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

    def _add(self, points: np.ndarray, period_ns: int, periods: np.ndarray, kind: int, *,
             rest: bool = False, pause: bool = False) -> None:
        n = len(points)
        self.points.append(points)
        self.period_ns.append(np.full(n, period_ns, np.int64))
        self.periods.append(periods)
        self.kind.append(np.full(n, kind, np.uint8))
        start = np.zeros(n, bool)
        start[:1] = True
        self.move_start.append(start)
        self.rest.append(np.full(n, rest))
        self.pause.append(np.full(n, pause))
        if n:
            self.at = points[-1]

    def motion(self, positions: np.ndarray, period_ns: int, kind: int) -> None:
        """One G-code move: the rounded position after each of its periods, ``(P, 3)`` int64."""
        signed = np.diff(np.vstack([self.at[None, :], positions]), axis=0)
        assert signed.size == 0 or np.abs(signed).max() <= 1, "a period moved an axis by more than one step"
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

    def job(self, settings: MachineSettings, program: GcodeProgram) -> Job:
        def cat(parts: list[np.ndarray], dtype, width: int = 0) -> np.ndarray:
            if parts:
                return np.concatenate(parts)
            return np.zeros((0, width) if width else 0, dtype)

        pts = cat(self.points, np.int64, 3)
        kind = cat(self.kind, np.uint8)
        return Job(points_steps=pts, kind=kind, target=(kind == CUT) & (pts[:, 2] > 0), pause=cat(self.pause, bool),
                   settings=settings, pause_notes=list(self.pause_notes), warnings=list(program.warnings),
                   source=program.source, period_ns=cat(self.period_ns, np.int64), periods=cat(self.periods, np.int64),
                   move_start=cat(self.move_start, bool), rest=cat(self.rest, bool))


class _Frame:
    """G-code millimetres to machine steps, and the travel in both."""

    def __init__(self, settings: MachineSettings, flip_y: bool) -> None:
        s = settings
        self.to_steps = np.array([1 / s.mm_per_step_xy, (1 if flip_y else -1) / s.mm_per_step_xy, -1 / s.mm_per_step_z])
        self.step_mm = np.array([s.mm_per_step_xy, s.mm_per_step_xy, s.mm_per_step_z])
        self.to_mm_y = s.mm_per_step_xy * (1 if flip_y else -1)
        self.lo = np.array([b[0] for b in s.travel.bounds_steps()], np.float64)
        self.hi = np.array([b[1] for b in s.travel.bounds_steps()], np.float64)
        self.min_period = {True: max(s.delay_xy_ns, s.delay_z_ns), False: s.delay_xy_ns}
        self.delay_z_ns = s.delay_z_ns

    def check(self, way_mm: np.ndarray, way_steps: np.ndarray, where: str) -> None:
        """Refuse a move whose points leave the travel, naming ``where`` (file:line)."""
        outside = np.any((np.rint(way_steps) < self.lo) | (np.rint(way_steps) > self.hi), axis=1)
        if not np.any(outside):
            return
        q = way_mm[int(np.flatnonzero(outside)[0])]
        x_mm = sorted(v * self.step_mm[0] + 0.0 for v in (self.lo[0], self.hi[0]))
        y_mm = sorted(self.to_mm_y * v + 0.0 for v in (self.lo[1], self.hi[1]))
        z_mm = sorted(-v * self.step_mm[2] + 0.0 for v in (self.lo[2], self.hi[2]))
        raise TravelError(
            f"{where}: move to X{q[0]:.3f} Y{q[1]:.3f} Z{q[2]:.3f} mm leaves the machine "
            f"travel (X {x_mm[0]:g}..{x_mm[1]:g} mm, Y {y_mm[0]:g}..{y_mm[1]:g} mm, Z {z_mm[0]:g}..{z_mm[1]:g} mm)"
        )


def _periods(frame: _Frame, mv: GcodeMove, start_mm: np.ndarray, start_steps: np.ndarray, way: np.ndarray,
             way_steps: np.ndarray) -> tuple[np.ndarray, int]:
    """The rounded position after each period of one move (``(P, 3)`` int64) and its period length."""
    starts = np.vstack([start_steps[None, :], way_steps[:-1]])
    d = way_steps - starts  # (W, 3) per sub-segment
    n_sub = np.maximum(1, np.ceil(np.abs(d).max(axis=1) - 1e-9).astype(np.int64))
    length_mm = float(np.sum(np.linalg.norm((way - np.vstack([start_mm[None, :], way[:-1]])), axis=1)))
    total_periods = int(n_sub.sum())
    uses_z = bool(np.any(d[:, 2] != 0))
    floor_ns = frame.min_period[uses_z] if bool(np.any(d[:, :2] != 0)) else frame.delay_z_ns
    if mv.kind == "rapid" or mv.feed_mm_min <= 0:
        per_ns = floor_ns
    else:
        per_ns = max(floor_ns, int(round(length_mm / (mv.feed_mm_min / 60.0) * 1e9 / total_periods)))
    seg = np.repeat(np.arange(len(d)), n_sub)
    first = np.cumsum(n_sub) - n_sub
    k = np.arange(total_periods) - np.repeat(first, n_sub) + 1
    ideal = starts[seg] + d[seg] * (k / n_sub[seg])[:, None]
    return np.floor(ideal + 0.5).astype(np.int64), per_ns  # the nearest step to the exact path point


def plan_gcode(program: GcodeProgram, settings: MachineSettings = DEFAULT_SETTINGS, *, flip_y: bool = False) -> Job:
    """The job of a G-code program (see the module docstring for frames and accuracy).

    Rapids run at the configured step delays; feed moves at their F, never faster than the delays allow;
    :func:`cam.drive.steps.plan_steps` then lengthens periods with the speed ramps of ``settings.ramp``,
    stopping at pauses and dwells.

    Raises:
        TravelError: a move leaves the machine travel (naming the line).
    """
    frame = _Frame(settings, flip_y)
    moves = _Moves()
    cur_mm = np.zeros(3)  # G-code frame
    cur_steps = np.zeros(3)  # the exact path point, in steps
    for mv in program.moves:
        if mv.kind == "pause":
            moves.pause_here(mv.note)
            continue
        if mv.kind == "dwell":
            if mv.seconds > 0:
                moves.dwell(mv.seconds)
            continue
        end = np.array(mv.end, np.float64)
        way = _arc_points(cur_mm, mv, frame.step_mm) if mv.kind == "arc" else end[None, :]
        way_steps = way * frame.to_steps
        frame.check(way, way_steps, f"{program.source}:{mv.line}")
        positions, per_ns = _periods(frame, mv, cur_mm, cur_steps, way, way_steps)
        moves.motion(positions, per_ns, TRAVEL if mv.kind == "rapid" else CUT)
        cur_mm, cur_steps = end, way_steps[-1]
    return moves.job(settings, program)
