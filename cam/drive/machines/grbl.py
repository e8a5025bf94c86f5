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
from ..grbl_machine import adopt_position, grbl_machine
from ..grbl_probe import start_probe_on_grbl
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

    def home(self, session: Any, axes: Optional[str]) -> bool:
        if axes:
            raise CamError(f"grbl homes all its axes with $H (its own [homing] order, $23-$27); drop axes {axes}")
        session.home_grbl()
        return True

    def start_probe(self, session: Any, probe_run: Any) -> None:
        """Probe with ``G38.2`` (:mod:`cam.drive.grbl_probe`)."""
        start_probe_on_grbl(session, probe_run)


register(GrblBackend())
