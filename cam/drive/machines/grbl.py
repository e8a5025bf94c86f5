"""A grbl 1.1 board (``grbl:DEVICE?baud=N``; grblHAL and FluidNC speak the same): every job and move goes to it
as G-code, and it plans and times its own motion (:mod:`cam.drive.grbl_machine`, :mod:`cam.drive.grbl_link`).

It reports where its tool stands (``MPos``), homes with its own cycle (``$H``), takes a feed override, and
pauses with a feed hold; its planned time is its own (:mod:`cam.drive.grbl_time`).  A job keeps a journal and
resumes from it as on a step/dir port (:mod:`cam.drive.grbl_journal`: how far grbl certainly got, from where it
reports the tool).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Optional

import numpy as np

from ...errors import CamError, CapabilityError
from ...job.model import JobLike
from ...settings import MachineSettings
from .._session_parts import Activity
from ..grbl_link import parse_grbl_url
from ..grbl_machine import (GRBL_OFFSETS, GrblControl, GrblPosition, adopt_position, finish_stop, grbl_machine,
                            job_lines, run_on_grbl, steps_to_mpos, travel_advice)
from ..grbl_pause_probe import probe_at_grbl_pause
from ..grbl_probe import grbl_set_work_z, start_probe_on_grbl
from ..grbl_program import start_program_on_grbl
from ..grbl_time import grbl_time_s
from ..journal import JournalSpec
from ..machine_job import MachineJob
from ..state import check_in_travel
from . import Backend, register

__all__ = ["GrblBackend"]

_PREFIX = "grbl:"


class GrblBackend(Backend):
    """``grbl:/dev/ttyUSB0`` (``?baud=N``, default 115200)."""

    kind = "grbl"
    example = "grbl:/dev/ttyUSB0"
    capabilities = frozenset({"gcode", "pause", "drill_files", "jog", "overrides", "homes_itself",
                              "reports_position", "keeps_own_time", "resume", "probes"})
    cannot = {
        "step_dir": "{port} (a grbl board) takes G-code and makes its own steps; {what} needs a step/dir port "
                    "(mock or /dev/parportN)",
        "delay": "{port} takes its rates from grbl's own settings ($110-$112); {what} applies to the MAXIMUS board "
                 "only",
        "spindle": "{port}: {what} applies to the MAXIMUS board only (grbl programs switch the spindle with M3/M5)",
    }

    def matches(self, name: str) -> bool:
        return name.startswith(_PREFIX) and len(name) > len(_PREFIX)

    def device(self, port: Any, settings: Optional[MachineSettings] = None) -> Optional[str]:
        return parse_grbl_url(port)[0] if isinstance(port, str) else None

    def attach(self, session: Any) -> None:
        """Connect (once a process per device) and take where grbl says the tool stands, in the state file's
        frame; its warnings and its banner go to the session's log."""
        session.grbl = grbl = grbl_machine(session.port, session.settings)
        if grbl.warning:
            session.log(grbl.warning, "warning")
        if grbl.notice:
            session.log(grbl.notice, "info")
            grbl.notice = ""  # once: the machine is shared by the sessions of this process
        session._position = np.asarray(adopt_position(grbl, session.state_hold, session.log), np.int64)

    def check_job(self, session: Any, job: MachineJob) -> None:
        _moves(session, job)  # a job with moves: a step plan has none

    def start_job(self, session: Any, job: MachineJob, name: str, journal: Any, controller: Any) -> None:
        """Stream the job's moves (a resumed job's: from where grbl has the tool); its journal's moves are those
        grbl certainly finished, from where it reports the tool (:mod:`cam.drive.grbl_journal`)."""
        _launch(session, "job", _moves(session, job), name, job.estimated_s(), session._journal_spec(job, journal))

    def start_moves(self, session: Any, activity: str, job: Any, label: str) -> None:
        _launch(session, activity, job, label, 0.0)

    def feed_override(self, session: Any, percent: int) -> None:
        """grbl's real-time override bytes, to ``percent``."""
        session.grbl.feed_override(percent)

    def state_extra(self, session: Any) -> Optional[dict[str, Any]]:
        """grbl's feed override, its own state name and its settings warning, for the session's snapshot."""
        last = session.grbl.last_status()
        return {"grbl": {"feed_override_pct": session.grbl.feed_override_pct,
                         "state": last.state if last is not None else "", "warning": session.grbl.warning}}

    def rebase(self, session: Any, position_steps: tuple[int, int, int]) -> None:
        """The user's word: grbl unlocked where the tool stands, its MPos read from here."""
        grbl = session.grbl
        if grbl.in_alarm():
            grbl.unlock()
        if grbl.position_steps(grbl.status()) != tuple(position_steps):
            grbl.rebase(tuple(position_steps))

    def work_zero_set(self, session: Any, offset: str, axes: str) -> None:
        if offset in GRBL_OFFSETS:  # grbl's own display agrees (G10 L20)
            session.grbl.set_work_zero(offset, axes)

    def work_z_set(self, session: Any, offset: str, z_steps: int) -> None:
        grbl_set_work_z(session.grbl, offset, int(z_steps), session.settings)

    def offset_used(self, session: Any, offset: str) -> None:
        if offset in GRBL_OFFSETS:
            session.grbl.use_offset(offset)

    def before_unknown_jog(self, session: Any) -> None:
        if session.grbl.in_alarm():  # grbl refuses every move in its alarm: the user jogs
            session.grbl.unlock()
            session.log(f"{session.port}: grbl's alarm unlocked ($X) for this jog; the position stays unknown",
                        "warning")

    def home(self, session: Any, axes: Optional[str]) -> bool:
        """grbl's homing cycle (``$H``) in the background: the machine frame is then grbl's (the switches'), the
        position known and homed.  Stop and emergency stop end it (grbl's soft reset).  A homing that fails ends
        the activity with its one-line reason, the position unknown.  BusyError while something runs."""
        if axes:
            raise CamError(f"grbl homes all its axes with $H (its own [homing] order, $23-$27); drop axes {axes}")
        with session._lock:
            session._check_free()
            if session.state_hold is not None:  # until $H has finished nothing says where the tool is (issue #43)
                session.state_hold.record(session.state_hold.state.lost("homing ($H) did not finish"))
            ctl = GrblControl(session.grbl, stop_resets=True)
            session._begin(Activity("home", "home ($H)", ctl, 1, 0.0))
            session.log("home ($H): started")
            session._spawn(_home_on_grbl, (session, ctl), "home")
        return True

    def start_probe(self, session: Any, probe_run: Any) -> None:
        """Probe with ``G38.2`` (:mod:`cam.drive.grbl_probe`)."""
        start_probe_on_grbl(session, probe_run)

    def start_program(self, session: Any, job: MachineJob, name: str, controller: Any) -> None:
        """A program that probes: its parts streamed, its probes grbl's own G38.2/G38.3
        (:mod:`cam.drive.grbl_program`)."""
        _moves(session, job)  # a job with moves: a step plan has none
        start_program_on_grbl(session, job, name, controller)


def _moves(session: Any, job: MachineJob) -> JobLike:
    """The moves (a :class:`~cam.job.model.JobLike`) grbl runs for ``job``."""
    if job.moves is None:
        raise CapabilityError(f"{session.port} (a grbl board) runs jobs as G-code: start the job or the prepared "
                              f"job, not its step plan")
    return job.moves


def _launch(session: Any, name: str, job: JobLike, label: str, estimated_s: float,
            journal: Optional[JournalSpec] = None) -> None:
    """Stream ``job`` to grbl in the background.  Its planned machine time is grbl's own
    (:func:`~cam.drive.grbl_time.grbl_time_s` of the lines it will get, from grbl's ``$$``), not the step plan's
    (``estimated_s``, kept only when the lines cannot be timed).  ``journal``: keep the job's journal
    (:mod:`cam.drive.grbl_journal`)."""
    grbl = session.grbl
    ctl = GrblControl(grbl)
    start = tuple(int(v) for v in session._position)
    start_mm = steps_to_mpos(np.asarray(start, np.int64) - np.asarray(grbl.base_steps, np.int64), session.settings)
    estimated_s = grbl_time_s(job_lines(job, start, grbl.base_steps, session.settings), grbl.link.settings,
                              start_mm) or estimated_s
    position = GrblPosition(grbl, start)  # type: ignore[arg-type]
    total = sum(len(piece) for piece in job.pieces())
    session._begin(Activity(name, label, ctl, total, estimated_s, position, reach=lambda: _reach(job)))
    session.log(f"{label}: started on {session.port}")
    pause_probe = probe_at_grbl_pause if name == "job" else None  # a tool change's prompt offers probing the tool
    session._spawn(run_on_grbl, (session, name, job, ctl, label, start, position, total, estimated_s, journal,
                                 pause_probe), name)


def _reach(job: JobLike) -> np.ndarray:
    """The lowest and highest steps ``job`` reaches on each axis from where it starts, its start included: (3, 2)
    (a tool probed at a tool change checks the job's shifted Z against the travel)."""
    lo, hi = np.zeros(3, np.int64), np.zeros(3, np.int64)
    for piece in job.pieces():
        pts = np.asarray(piece.points_steps, np.int64).reshape(-1, 3)
        if len(pts):
            lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
    return np.stack([lo, hi], axis=1)


def _home_on_grbl(session: Any, ctl: GrblControl) -> None:
    """The worker of :meth:`GrblBackend.home`: ``$H``, the travel checked, the state file told (homed, or the
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


register(GrblBackend())
