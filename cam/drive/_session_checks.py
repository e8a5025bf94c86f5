"""A part of :class:`~cam.drive.session.MachineSession`: what is checked before a job starts, nothing sent.

Like the other parts it keeps no state of its own: it works on the attributes ``MachineSession.__init__`` sets
(``port``, ``backend``, ``settings``, ``state_hold``, ``_lock``, ``_position``); what a machine cannot run its
back end refuses (:meth:`~cam.drive.machines.Backend.check_job`).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import CamError, StalePlanError
from ..job.model import TRAVEL, Job, JobLike, check_reach, check_travel
from ..verify.pinlog import motion_extent
from .chunks import ChunkedPlan
from .steps import StepPlan
from ._session_grbl import SessionGrbl

__all__ = ["SessionChecks"]


class SessionChecks(SessionGrbl):
    """The checks of a job against the machine, its port and the state it was planned in (a mixin)."""

    def check_job(self, job: Any) -> None:
        """Everything :meth:`start` checks before anything moves, without starting (raises CamError)."""
        with self._lock:
            self._check_job(job)

    def _check_job(self, job: Any) -> None:
        settings = getattr(job, "settings", None)
        if settings is not None and (settings.travel != self.settings.travel or settings.pins != self.settings.pins):
            raise CamError("the job was planned for other machine settings; plan it again")
        self._check_planned_in(job)
        if isinstance(job, Job) and len(job) and np.all(job.kind == TRAVEL):
            self.backend.require(self.port, "jog", "a move")
        else:
            self.backend.check_job(self, job)  # what this machine cannot run, before anything moves
        extent = getattr(job, "extent_steps", None)
        if extent is not None:
            check_reach(self._position, extent, self.settings, "the job")
        elif isinstance(job, ChunkedPlan):  # a prepared job's plan started alone: its extent, from here
            check_reach(self._position, job.motion_extent()[0], self.settings, "the job")
        elif isinstance(job, StepPlan):
            check_reach(self._position, motion_extent(job.data, job.settings)[0], self.settings, "the job")
        if isinstance(job, Job):
            check_travel(np.asarray(job.points_steps, np.int64) + self._position, self.settings, job.pixels)
        elif self.backend.can("gcode") and isinstance(job, JobLike) and extent is None:
            # a job kept as pieces (a drawing, an HPGL file...) planned in its own frame: grbl runs its points as
            # they are, no step plan checks them from here (issue #45 point 4)
            for piece in job.pieces():
                check_travel(np.asarray(piece.points_steps, np.int64) + self._position, self.settings, piece.pixels)

    def _check_planned_in(self, job: Any) -> None:
        """Refuse a prepared job planned for another machine state than the session's now (issue #43 point 6): a
        G-code program planned with the tool elsewhere, or a job planned from another work zero
        (:class:`~cam.job.jobs.PlannedIn`; the work offsets compared when the session keeps the state file)."""
        planned = getattr(job, "planned_in", None)
        if planned is None or getattr(job, "resumed", None) is not None:
            return
        st = self.state_hold.state if self.state_hold is not None else None
        why = planned.differs(tuple(int(v) for v in self._position), None if st is None else st.offsets_steps,
                              None if st is None else st.active_offset)
        if why:
            raise StalePlanError(why)

