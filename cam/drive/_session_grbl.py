"""A part of :class:`~cam.drive.session.MachineSession`: a grbl board (issue #30 point 2).

:class:`SessionGrbl` runs the session's activities on a grbl port (:mod:`cam.drive.grbl_machine`): the moves of
any job streamed as G-code in a worker thread, the feed override, and grbl's own homing.  Like the other parts
it keeps no state of its own: it works on the attributes ``MachineSession.__init__`` sets (``grbl``, ``port``,
``settings``, ``state_hold``, ``_lock``, ``_position``) and calls the session's methods (``_begin``,
``_spawn``, ``_check_free``, ``log``, ``_bump``).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Optional

import numpy as np

from ..errors import CamError, CapabilityError
from ..job.model import JobLike
from ..values import finite_number
from ._session_frames import SessionFrames
from ._session_parts import Activity
from .grbl_machine import (FEED_OVERRIDE_RANGE, GrblControl, GrblPosition, finish_stop, job_lines, run_on_grbl,
                           steps_to_mpos, travel_advice)
from .grbl_time import grbl_time_s
from .machine_job import JobInput, MachineJob, machine_job
from .journal import JournalSpec
from .machines import require
from .state import check_in_travel

__all__ = ["SessionGrbl"]


class SessionGrbl(SessionFrames):
    """Jobs, moves, the feed override and homing on a grbl board (a mixin; see the module)."""

    def _grbl_job(self, job: "JobInput | MachineJob") -> JobLike:
        """The moves (a :class:`~cam.job.model.JobLike`) grbl runs for ``job``."""
        mj = machine_job(job)
        if mj.moves is None:
            raise CapabilityError(f"{self.port} (a grbl board) runs jobs as G-code: start the job or the prepared "
                                  f"job, not its step plan")
        return mj.moves

    def _launch_grbl(self, name: str, job: Any, label: str, estimated_s: float,
                     journal: Optional[JournalSpec] = None) -> None:
        """Stream ``job`` to grbl in the background.  Its planned machine time is grbl's own
        (:func:`~cam.drive.grbl_time.grbl_time_s` of the lines it will get, from grbl's ``$$``), not the step
        plan's (``estimated_s``, kept only when the lines cannot be timed).  ``journal``: keep the job's journal
        (:mod:`cam.drive.grbl_journal`)."""
        assert self.grbl is not None
        ctl = GrblControl(self.grbl)
        start = tuple(int(v) for v in self._position)
        start_mm = steps_to_mpos(np.asarray(start, np.int64) - np.asarray(self.grbl.base_steps, np.int64),
                                 self.settings)
        estimated_s = grbl_time_s(job_lines(job, start, self.grbl.base_steps, self.settings),
                                  self.grbl.link.settings, start_mm) or estimated_s
        position = GrblPosition(self.grbl, start)  # type: ignore[arg-type]
        total = sum(len(piece) for piece in job.pieces())
        self._begin(Activity(name, label, ctl, total, estimated_s, position))
        self.log(f"{label}: started on {self.port}")
        self._spawn(run_on_grbl, (self, name, job, ctl, label, start, position, total, estimated_s, journal), name)

    def feed_override(self, percent: float) -> None:
        """Set the feed override to ``percent`` (a number 10..200, rounded to a whole percent; grbl's real-time
        override bytes).

        Raises:
            PlanError: not a finite number (text, a boolean, infinity) or outside 10..200 (checked first, on any
            port); CapabilityError: the port has no feed override (not grbl)."""
        lo, hi = FEED_OVERRIDE_RANGE
        pct = int(round(finite_number(percent, "percent", lo=lo, hi=hi, unit="%")))
        require(self.port, "overrides", what="a feed override")
        assert self.grbl is not None
        self.grbl.feed_override(pct)
        self.log(f"feed override {pct} %")
        with self._lock:
            self._bump()

    def home_grbl(self) -> None:
        """Start grbl's homing cycle (``$H``) in the background: the machine frame is then grbl's (the switches'),
        the position known and homed.  Stop and emergency stop end it (grbl's soft reset).

        Raises:
            CapabilityError: not grbl (:meth:`~cam.drive._session_recover.SessionRecover.home` homes every port);
            BusyError.  A homing that fails ends the activity with its one-line reason, the position unknown."""
        require(self.port, "homes_itself", what="homing from the session")
        assert self.grbl is not None
        with self._lock:
            self._check_free()
            if self.state_hold is not None:  # until $H has finished nothing says where the tool is (issue #43)
                self.state_hold.record(self.state_hold.state.lost("homing ($H) did not finish"))
            ctl = GrblControl(self.grbl, stop_resets=True)
            self._begin(Activity("home", "home ($H)", ctl, 1, 0.0))
            self.log("home ($H): started")
            self._spawn(home_on_grbl, (self, ctl), "home")

    def state(self, log_after: int = 0) -> dict[str, Any]:
        """The snapshot (:meth:`SessionFrames.state`); on grbl also its feed override and its own state name."""
        with self._lock:
            snap = super().state(log_after)
            if self.grbl is not None:
                last = self.grbl.last_status()
                snap["grbl"] = {"feed_override_pct": self.grbl.feed_override_pct,
                                "state": last.state if last is not None else "",
                                "warning": self.grbl.warning}
            return snap


def home_on_grbl(session: Any, ctl: GrblControl) -> None:
    """The worker of :meth:`SessionGrbl.home`: ``$H``, the travel checked, the state file told (homed, or the
    position unknown when homing failed)."""
    machine = session.grbl
    error = ""
    pos = None
    try:
        pos = machine.home()
        try:
            check_in_travel(pos, session.settings, "where grbl's $H left the tool")
        except CamError as exc:
            raise CamError(f"{exc}; grbl's machine zero is its homing corner: give the machine file "
                           f"{travel_advice(machine.link.settings, session.settings)}") from None
    except CamError as exc:
        error = "stopped" if ctl.halted else str(exc)
    if ctl.halted:
        try:
            finish_stop(machine, ctl)
        except CamError:
            pass
    moved = None if pos is None else np.asarray(pos, np.int64) - np.asarray(session.position_steps(), np.int64)
    status = "finished" if not error else ("emergency-stopped" if ctl.estopped else "error")
    hold = session.state_hold
    # before the end is booked (issue #43 point 5): whoever sees the session idle sees it homed, or the position
    # unknown; never the position known after a homing that failed (the end booked keeps it so: ended_state)
    if hold is not None and not error:
        hold.record(replace(hold.state.moved_to(tuple(int(v) for v in pos)), homed=True))
    elif hold is not None:
        hold.record(hold.state.lost(f"homing did not finish ({error})"))
    session.log(f"homed: machine {list(pos)} steps" if not error else f"home ($H): {error}",
                "info" if not error else "error")  # before the end: whoever sees it idle sees this line too
    session.finish({"activity": "home", "label": "home ($H)", "status": status,
                    "messages": [error] if error else []}, moved)
