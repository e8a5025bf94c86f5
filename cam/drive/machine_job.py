"""The one typed job that crosses into a machine (issue #45 point 1).

A front end hands the session a job in one of five shapes: a :class:`~cam.job.model.Job` (moves in memory), a
:class:`~cam.job.model.JobLike` kept as pieces, a :class:`~cam.kinds.jobs.PreparedJob` (a file planned with its
options), a :class:`~cam.motion.chunks.ChunkedPlan` or a :class:`~cam.motion.steps.StepPlan` (steps already
timed).  :func:`machine_job` reads it once, by its type, into a :class:`MachineJob`: the session and every back
end read those typed fields, never the shape's attributes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional, Union

import numpy as np

from ..errors import CapabilityError
from ..job.drill import DrillPlan
from ..job.gcode_probing import ProbingProgram
from ..kinds.jobs import PlannedIn, PreparedJob
from ..job.model import TRAVEL, Job, JobLike
from ..settings import MachineSettings
from ..motion.chunks import ChunkedPlan
from ..motion.steps import StepPlan

__all__ = ["MachineJob", "JobInput", "machine_job"]

JobInput = Union[Job, JobLike, PreparedJob, ChunkedPlan, StepPlan]
"""What :meth:`~cam.drive.session.MachineSession.start` takes."""


@dataclass(frozen=True)
class MachineJob:
    """A job as a machine sees it.

    Attributes:
        given: the object the front end gave (journals and resumes of a prepared job read it).
        prepared: the prepared job (a file planned with its options), else None.
        kind: a prepared job's file kind (``drawing``, ``excellon``, ``gcode``...); ``moves`` for moves alone,
            ``steps`` for a step plan alone.
        name: what the log calls it.
        settings: the machine settings it was planned with (None: moves alone, planned by the session).
        moves: its moves in steps from its home (None: a step plan alone, whose moves are gone).
        plan: its step plan when one was made (a prepared job's, a plan given), else None.
        drill_plan: a drill file's holes (boards that drill by themselves take it), else None.
        extent_steps: ``(3, 2)`` int64 reach from its home (a prepared job's), else None.
        planned_in: the machine state its plan holds for (:class:`~cam.kinds.jobs.PlannedIn`), else None.
        resumed: a run resumed from a journal (it starts where the tool stands).
        travel_only: moves that travel only (a jog, a go-to).
        origin: a prepared job's own ``--origin`` (:func:`cam.drive.placement.origin_anchor`), else None.
        levelled_home_steps: a job levelled to a height map: the machine position it was levelled for (it starts
            there, :func:`cam.drive.placement.placed_home`), else None.
        estimated_s: its machine time in seconds, worked out when called (a pass over a plan's ramps).
        probing: a G-code program that probes (:class:`~cam.job.gcode_probing.ProbingProgram`): a machine that
            probes runs it a part at a time from each probe's contact (:mod:`cam.drive.program_probe`), never its
            ``plan`` (as if each probe touched at its target); None: no probe.
    """

    given: JobInput
    prepared: Optional[PreparedJob]
    kind: str
    name: str
    settings: Optional[MachineSettings]
    moves: Optional[JobLike]
    plan: Optional[Union[ChunkedPlan, StepPlan]]
    drill_plan: Optional[DrillPlan]
    extent_steps: Optional[np.ndarray]
    planned_in: Optional[PlannedIn]
    resumed: bool
    travel_only: bool
    estimated_s: Callable[[], float]
    origin: Optional[str] = None
    levelled_home_steps: Optional[tuple[int, int, int]] = None
    probing: Optional[ProbingProgram] = None


def machine_job(job: JobInput) -> MachineJob:
    """Read ``job`` once, by its type, into a :class:`MachineJob`.

    Raises:
        CapabilityError: not one of the five shapes (:data:`JobInput`); the moves (or a plan of them) of a G-code
        program that probes, planned as if each probe touched at its target (:attr:`cam.job.model.Job.probes`):
        only the prepared program runs, from each probe's contact.
    """
    if isinstance(job, MachineJob):
        return job
    if not isinstance(job, PreparedJob):
        _refuse_nominal(job)
    if isinstance(job, PreparedJob):
        plan = job.plan if isinstance(job.plan, (ChunkedPlan, StepPlan)) else None
        moves = plan.job if isinstance(plan, ChunkedPlan) else (job.toolpath if isinstance(job.toolpath, JobLike)
                                                                 else None)
        return MachineJob(job, job, job.kind, job.name or job.source, job.settings, moves, plan,
                          job.drill_plan if isinstance(job.drill_plan, DrillPlan) else None,
                          np.asarray(job.extent_steps, np.int64), job.planned_in, job.resumed is not None, False,
                          lambda: float(job.estimated_time_s), job.origin, _levelled_home(job), job.probing)
    if isinstance(job, StepPlan):
        return MachineJob(job, None, "steps", "step plan", job.settings, None, job, None, None, None, False, False,
                          lambda: float(job.estimated_time_s))
    if isinstance(job, ChunkedPlan):
        return MachineJob(job, None, "steps", job.job.source or "step plan", job.settings, job.job, job, None, None,
                          None, False, False, lambda: float(job.estimated_time_s))
    if isinstance(job, Job):
        travel = bool(len(job)) and bool(np.all(job.kind == TRAVEL))
        return MachineJob(job, None, "moves", job.source or "moves", job.settings, job, None, None, None, None,
                          False, travel, lambda: 0.0)
    if isinstance(job, JobLike):
        return MachineJob(job, None, "moves", job.source or "moves", job.settings, job, None, None, None, None,
                          False, False, lambda: 0.0)
    raise CapabilityError(f"a machine cannot run a {type(job).__name__}: give a Job, a prepared job or a step plan")


def _refuse_nominal(job: JobInput) -> None:
    """Refuse the moves of a program that probes, planned as if each probe touched at its target (a job, a job kept
    as pieces, a chunked plan of one): run as they are, the tool would go on as if the work were there."""
    moves = job.job if isinstance(job, ChunkedPlan) else job
    probes = getattr(moves, "probes", None) if isinstance(moves, (Job, JobLike)) else None
    if probes:
        raise CapabilityError(f"{probes[0]}: these moves of a program that probes are planned as if each probe "
                              "touched at its target; a machine runs the program itself, a part at a time from where "
                              "each probe touches: give it the prepared job (cam drill, cam.prepare_job)")


def _levelled_home(job: PreparedJob) -> Optional[tuple[int, int, int]]:
    home = getattr(job, "levelled_home_steps", None)  # a field of prepared jobs levelled to a height map (#46)
    return None if home is None else (int(home[0]), int(home[1]), int(home[2]))
