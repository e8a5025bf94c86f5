"""A part of :class:`~cam.drive.session.MachineSession`: what is checked before a job starts, nothing sent.

Like the other parts it keeps no state of its own: it works on the attributes ``MachineSession.__init__`` sets
(``port``, ``backend``, ``settings``, ``state_hold``, ``_lock``, ``_position``); what a machine cannot run its
back end refuses (:meth:`~cam.drive.machines.Backend.check_job`).
"""
from __future__ import annotations

import numpy as np

from ..errors import CamError, StalePlanError
from ..job.model import Job, check_reach, check_travel
from ..verify.pinlog import motion_extent
from ..motion.chunks import ChunkedPlan
from .machine_job import JobInput, MachineJob, machine_job
from ..motion.steps import StepPlan
from ._session_frames import SessionFrames

__all__ = ["SessionChecks"]


class SessionChecks(SessionFrames):
    """The checks of a job against the machine, its port and the state it was planned in (a mixin)."""

    def check_job(self, job: JobInput) -> None:
        """Everything :meth:`start` checks before anything moves, without starting (raises CamError)."""
        with self._lock:
            self._check_job(machine_job(job))

    def _check_job(self, mj: MachineJob) -> None:
        if mj.probing is not None:  # a program that probes (G38.2/G38.3): a machine without a probe, in one line first
            port = self.port if isinstance(self.port, str) else getattr(self.port, "name", self.port)  # (its name)
            self.backend.require(port, "probes", f"a G-code program that probes ({mj.probing.probes[0]})")
        settings = mj.settings
        if settings is not None and (settings.travel != self.settings.travel or settings.pins != self.settings.pins):
            raise CamError("the job was planned for other machine settings; plan it again")
        self._check_planned_in(mj)
        if mj.travel_only:
            self.backend.require(self.port, "jog", "a move")
        else:
            self.backend.check_job(self, mj)  # what this machine cannot run, before anything moves
        given = mj.given
        if mj.extent_steps is not None:
            check_reach(self._position, mj.extent_steps, self.settings, "the job")
        elif isinstance(given, ChunkedPlan):  # a prepared job's plan started alone: its extent, from here
            check_reach(self._position, given.motion_extent()[0], self.settings, "the job")
        elif isinstance(given, StepPlan):
            check_reach(self._position, motion_extent(given.data, given.settings)[0], self.settings, "the job")
        if isinstance(given, Job):
            check_travel(np.asarray(given.points_steps, np.int64) + self._position, self.settings, given.pixels)
        elif self.backend.can("gcode") and mj.moves is not None and mj.extent_steps is None:
            # a job kept as pieces (a drawing, an HPGL file...) planned in its own frame: grbl runs its points as
            # they are, no step plan checks them from here (issue #45 point 4)
            for piece in mj.moves.pieces():
                check_travel(np.asarray(piece.points_steps, np.int64) + self._position, self.settings, piece.pixels)

    def _check_planned_in(self, mj: MachineJob) -> None:
        """Refuse a prepared job planned for another machine state than the session's now (issue #43 point 6): a
        G-code program planned with the tool elsewhere, or a job planned from another work zero
        (:class:`~cam.kinds.jobs.PlannedIn`; the work offsets compared when the session keeps the state file)."""
        planned = mj.planned_in
        if planned is None or mj.resumed:
            return
        st = self.state_hold.state if self.state_hold is not None else None
        why = planned.differs(tuple(int(v) for v in self._position), None if st is None else st.offsets_steps,
                              None if st is None else st.active_offset)
        if why:
            raise StalePlanError(why)

