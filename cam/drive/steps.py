"""Stage 4: the step plan -- every parallel-port write of a job, with its time.

Signals (thesis chapter 3): a step is a rising edge of an axis's clock bit;
the direction bit, set for the + direction, is written half a step period
before the edge.  Each step period of length ``T`` starting at ``t`` makes two
writes::

    t + T/2 : direction bits | clock bits of the axes that step   (rising edges)
    t + T   : direction bits of the next period, clocks low         (falling edges)

so the last write of a job lands exactly at the end of its last period, and
the job time is the sum of its periods.  X and Y step together in diagonal
moves (Eq. 4.4): a move of (dx, dy, dz) steps takes max(|dx|, |dy|, |dz|)
periods, the shorter axes spread evenly over them (a DDA).  The period is the
X/Y delay when X or Y moves, the Z delay for Z-only moves, and the larger of
the two when both move.  Those are the *nominal* periods (the thesis's constant
delay); :func:`cam.drive.ramps.ramp_periods` then lengthens them with the
speed ramps of ``settings.ramp`` (look-ahead, the seed's 40-step ramp, or none).

Pin 1 (strobe) carries Half/Full* and is held low for full steps.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..settings import MachineSettings
from ..job.model import Job, check_travel
from ._kernels import periods_kernel, writes_kernel
from .pins import axis_bits
from .ramps import ramp_periods

__all__ = ["StepPlan", "plan_steps", "port_writes"]



@dataclass
class StepPlan:
    """All port writes of a job.

    Attributes:
        t_ns: ``(M,)`` int64 scheduled time of each write, ns from the job start (non-decreasing).
        data: ``(M,)`` uint8 data register (pins 2..9) after each write.
        strobe: ``(M,)`` uint8 level of pin 1 after each write.
        point_write: ``(N,)`` int64 index of the write at which toolpath point i is reached.
        pause_writes: ``(P,)`` int64 write indices after which the job pauses (Pause At).
        steps_total: ``(3,)`` int64 steps made by X, Y, Z (absolute).
        settings: the machine settings.
        end_steps: machine position (x, y, z) in steps after the last write.
        safe_z_steps: Z a stop lifts the tool to (the surface or above it).
        pause_notes: what each pause is for (same order as ``pause_writes``), e.g. a tool change.
    """

    t_ns: np.ndarray
    data: np.ndarray
    strobe: np.ndarray
    point_write: np.ndarray
    pause_writes: np.ndarray
    steps_total: np.ndarray
    settings: MachineSettings
    end_steps: tuple[int, int, int] = (0, 0, 0)
    safe_z_steps: int = 0
    pause_notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def estimated_time_s(self) -> float:
        """Machine time of the job in seconds (pauses excluded)."""
        return float(self.t_ns[-1]) / 1e9 if len(self.t_ns) else 0.0


def port_writes(
    step_signed: np.ndarray,
    period_ns: np.ndarray,
    settings: MachineSettings,
    *,
    move_first: np.ndarray | None = None,
    stops: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The port writes of a sequence of step periods, with the speed ramps of ``settings.ramp``.

    Args:
        step_signed: ``(P, 3)`` int, the step each axis (X, Y, Z) makes in each period: -1, 0 or +1.
        period_ns: ``(P,)`` int64 nominal length of each period (lengthened by the ramps, never shortened).
        settings: pin map, Half/Full*, ramp mode and axis limits.
        move_first: ``(M,)`` first period of each move; stops: period indices before which the machine
            rests (pauses); see :func:`cam.drive.ramps.ramp_periods`.

    Returns:
        ``(t_ns, data, strobe)``, each ``(1 + 2P,)``: an initial write at t = 0 that sets the first
        directions, then per period the rising edges at mid-period and the falling edges (with the
        next period's directions) at its end.  An idle axis keeps its last direction.
    """
    step_signed = np.asarray(step_signed)
    per = np.asarray(period_ns, np.int64)
    n_periods = len(per)
    clock, dirbit = axis_bits(settings)
    dir_data = np.zeros(n_periods, np.int64)
    clock_data = np.zeros(n_periods, np.int64)
    rows = np.arange(n_periods)
    for a in range(3):
        moving = step_signed[:, a] != 0
        last = np.maximum.accumulate(np.where(moving, rows, -1))
        positive = np.where(last >= 0, step_signed[np.maximum(last, 0), a] > 0, False)
        dir_data |= positive.astype(np.int64) * int(dirbit[a])
        clock_data |= moving.astype(np.int64) * int(clock[a])
    high, dirs = (dir_data | clock_data).astype(np.uint8), dir_data.astype(np.uint8)
    per = ramp_periods(high, per, settings, move_first=move_first, stops=stops)
    return _writes(high, dirs, per, settings)


def _writes(
    high: np.ndarray, dirs: np.ndarray, per: np.ndarray, settings: MachineSettings
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Writes of periods given their rising-edge data, direction data and lengths (see the module docstring)."""
    t_ns, data = writes_kernel(np.asarray(high, np.uint8), np.asarray(dirs, np.uint8), np.asarray(per, np.int64))
    m = len(t_ns)
    strobe = np.full(m, 1 if settings.half_step else 0, np.uint8)
    return t_ns, data, strobe


def plan_steps(job: Job, *, start_steps: tuple[int, int, int] = (0, 0, 0)) -> StepPlan:
    """Turn a job into the timed port writes that make it (vectorised, no Python loop per step).

    Args:
        job: the moves, in steps relative to where the tool stands when it starts.
        start_steps: where the tool stands in the machine frame: the job is checked against the
            travel from there.

    Raises:
        TravelError: a point of the job is outside the machine travel (nothing is planned).
    """
    s = job.settings
    check_travel(np.asarray(job.points_steps, np.int64) + np.asarray(start_steps, np.int64), s, job.pixels)
    pts = np.vstack([np.zeros((1, 3), np.int64), np.asarray(job.points_steps, np.int64).reshape(-1, 3)])
    delta = np.diff(pts, axis=0)  # (N, 3) per move
    clock, dirbit = axis_bits(s)
    n_min = np.zeros(len(job), np.int64) if job.periods is None else np.asarray(job.periods, np.int64)
    high, dirs, per, n_per_move = periods_kernel(
        pts, s.delay_xy_ns, s.delay_z_ns, clock.astype(np.int64), dirbit.astype(np.int64), n_min
    )
    if job.period_ns is not None:
        per = np.repeat(np.asarray(job.period_ns, np.int64), n_per_move)
    point_period = np.cumsum(n_per_move)
    first = point_period - n_per_move
    stops = point_period[job.pause]
    if job.rest is not None:
        stops = np.sort(np.concatenate([stops, first[job.rest], point_period[job.rest]]))
    move_first = first if job.move_start is None else first[job.move_start]
    per = ramp_periods(high, per, s, move_first=move_first, stops=stops)
    t_ns, data, strobe = _writes(high, dirs, per, s)

    point_write = 2 * point_period
    pause_writes = point_write[job.pause]
    end = tuple(int(v) for v in pts[-1])
    return StepPlan(
        t_ns=t_ns,
        data=data,
        strobe=strobe,
        point_write=point_write,
        pause_writes=pause_writes,
        steps_total=np.abs(delta).sum(axis=0),
        settings=s,
        end_steps=end,  # type: ignore[arg-type]
        safe_z_steps=int(job.safe_z_steps),
        pause_notes=list(job.pause_notes) if job.pause_notes is not None else ["Pause At"] * len(pause_writes),
        warnings=list(job.warnings),
    )
