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
delay); the speed ramps of ``settings.ramp`` (look-ahead, the seed's 40-step
ramp, or none) then lengthen them.  Every step plan is made a chunk at a time
(:mod:`cam.drive.chunks`); :class:`StepPlan` is one held whole.

Pin 1 (strobe) carries Half/Full* and is held low for full steps.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterator

import numpy as np

from ..job.model import JobLike
from ..settings import MachineSettings

if TYPE_CHECKING:
    from .chunks import StepChunk

__all__ = ["StepPlan", "plan_steps"]



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

    def chunks(self) -> Iterator["StepChunk"]:
        """The writes as one chunk (what the runner sends, as :meth:`cam.drive.chunks.ChunkedPlan.chunks`)."""
        from .chunks import StepChunk

        yield StepChunk(0, self.t_ns, self.data, self.strobe)


def plan_steps(job: JobLike, *, start_steps: tuple[int, int, int] = (0, 0, 0)) -> StepPlan:
    """Every timed port write of a job at once: the chunks of :func:`cam.drive.chunks.plan_chunks` joined.

    The machine session, :func:`cam.run`, ``cam drill`` and the page all run the chunked plan; this is the
    same writes held in memory (about 20 bytes per step period), for pictures of every write and tests.

    Args:
        job: the moves, in steps relative to where the tool stands when it starts.
        start_steps: where the tool stands in the machine frame: the job is checked against the
            travel from there.

    Raises:
        TravelError: a point of the job is outside the machine travel (nothing is planned).
    """
    from .chunks import plan_chunks

    return plan_chunks(job, start_steps=start_steps).to_plan()
