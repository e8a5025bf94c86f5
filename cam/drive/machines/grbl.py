"""A grbl 1.1 board (``grbl:DEVICE?baud=N``; grblHAL and FluidNC speak the same): every job and move goes to it
as G-code, and it plans and times its own motion (:mod:`cam.drive.grbl_machine`, :mod:`cam.drive.grbl_link`).

It reports where its tool stands (``MPos``), homes with its own cycle (``$H``), takes a feed override, and
pauses with a feed hold; its planned time is its own (:mod:`cam.drive.grbl_time`).  A job keeps a journal and
resumes from it as on a step/dir port (:mod:`cam.drive.grbl_journal`: how far grbl certainly got, from where it
reports the tool).
"""
from __future__ import annotations

from typing import Any, Optional

import numpy as np

from ...errors import CamError
from ...settings import MachineSettings
from ..grbl_link import parse_grbl_url
from ..machine_job import MachineJob
from ..grbl_machine import GRBL_OFFSETS, adopt_position, grbl_machine
from ..grbl_probe import grbl_set_work_z, start_probe_on_grbl
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
        session._grbl_job(job)  # a job with moves: a step plan has none

    def start_job(self, session: Any, job: MachineJob, name: str, journal: Any, controller: Any) -> None:
        """Stream the job's moves (a resumed job's: from where grbl has the tool); its journal's moves are those
        grbl certainly finished, from where it reports the tool (:mod:`cam.drive.grbl_journal`)."""
        session._launch_grbl("job", session._grbl_job(job), name, job.estimated_s(),
                             session._journal_spec(job, journal))

    def start_moves(self, session: Any, activity: str, job: Any, label: str) -> None:
        session._launch_grbl(activity, job, label, 0.0)

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
        if axes:
            raise CamError(f"grbl homes all its axes with $H (its own [homing] order, $23-$27); drop axes {axes}")
        session.home_grbl()
        return True

    def start_probe(self, session: Any, probe_run: Any) -> None:
        """Probe with ``G38.2`` (:mod:`cam.drive.grbl_probe`)."""
        start_probe_on_grbl(session, probe_run)


register(GrblBackend())
