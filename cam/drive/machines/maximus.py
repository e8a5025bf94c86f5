"""The MAXIMUS PCB driller's PIC board (``maximus:DEVICE``; seeds 000 and 003): it drills drill files by itself.

The board keeps its own time (a pulse every ``2 * Delay * 100 us``), jogs by packet and drills a list of holes
(:mod:`cam.drive.maximus`); it has no pause, no homing and no step/dir input.  Its settings start from the board's
(:data:`~cam.drive.maximus.board.MAXIMUS_SETTINGS`): one step is one L297 clock pulse of each axis, in that axis's
half or full step mode.
"""
from __future__ import annotations

from typing import Any, Optional

import numpy as np

from ...settings import MachineSettings
from ...kinds import has
from .._session_recover import maximus_cannot_home
from .._session_parts import Activity
from ..activities import BoardControl, BoardWork, drill_work, move_work, run_on_board
from ..machine_job import MachineJob
from ..maximus.board import (MAXIMUS_SETTINGS, board_settings, board_speeds_line, drill_arguments, drill_job,
                             maximus_port, require_drilling)
from . import Backend, register

__all__ = ["MaximusBackend"]

_PREFIX = "maximus:"


class MaximusBackend(Backend):
    """``maximus:/dev/ttyUSB0`` (``maximus`` alone: the machine file's ``[maximus] serial_port``)."""

    kind = "maximus"
    example = "maximus:/dev/ttyUSB0"
    capabilities = frozenset({"drill_files", "jog", "delay", "spindle", "drill_stroke", "keeps_own_time",
                              "drills_alone", "board_settings", "resume"})
    cannot = {
        "pause": "{port} cannot pause a job (the MAXIMUS firmware has no pause): stop it, or wait for a tool change",
        "step_dir": "{port} (the MAXIMUS board) drills drill files (Excellon) and jogs only; {what} needs a "
                    "step/dir port (mock or /dev/parportN)",
        "probes": "{port} (the MAXIMUS board) has no probe input: {what} needs a step/dir port with inputs.probe "
                  "or grbl",
    }

    def matches(self, name: str) -> bool:
        return (name.startswith(_PREFIX) and len(name) > len(_PREFIX)) or name == _PREFIX[:-1]

    def resolve(self, name: Any, settings: MachineSettings) -> Any:
        return maximus_port(name, settings)

    def device(self, port: Any, settings: Optional[MachineSettings] = None) -> Optional[str]:
        if not isinstance(port, str):
            return None
        if port == _PREFIX[:-1]:  # the machine file's serial_port (none: the one-line PortError)
            return None if settings is None else self.resolve(port, settings)[len(_PREFIX):]
        return port[len(_PREFIX):]

    def base_settings(self) -> Optional[MachineSettings]:
        return MAXIMUS_SETTINGS

    def adapt_settings(self, settings: MachineSettings) -> MachineSettings:
        return board_settings(settings)

    def half_step(self, settings: MachineSettings, axis: str) -> bool:
        return bool(getattr(settings.maximus, f"half_step_{axis.lower()}"))

    def speeds_line(self, settings: MachineSettings) -> Optional[str]:
        return board_speeds_line(settings)

    def check_job(self, session: Any, job: MachineJob) -> None:
        """A drill file with a drill plan whose packets fit the board's fields (nothing sent); slots and milled
        holes refused (the firmware drills only)."""
        kind = job.kind
        self.require(session.port, "drill_files", f"a {kind} job")
        if has(kind, "holes"):
            require_drilling(job.given, session.port)
        if job.drill_plan is None:
            self.require(session.port, "step_dir", f"a {kind} job")
        arguments = drill_arguments(job.drill_plan, session.settings)
        drill_job(arguments["holes_steps"], arguments["z_up_steps"], arguments["z_down_steps"],
                  arguments["tool_changes"], session.settings.maximus)

    def start_job(self, session: Any, job: MachineJob, name: str, journal: Any, controller: Any) -> None:
        _launch(session, "job", drill_work(job.prepared, session.settings, session._journal_spec(job, journal)), job,
                name)

    def start_moves(self, session: Any, activity: str, job: Any, label: str) -> None:
        _launch(session, activity, move_work(job.points_steps), None, label,
                              moved_steps=np.asarray(job.points_steps)[-1])

    def home_refusal(self, port: Any) -> None:
        raise maximus_cannot_home(port)

    def spindle(self, session: Any, on: bool) -> None:
        """The board's spindle switch (RB2): a Jog packet of no pulses with the spindle bit
        (:meth:`~cam.drive.maximus.board.MaximusBoard.set_spindle`), as an activity of its own."""
        def work(board: Any, s: Any) -> None:
            board.set_spindle(on)
            s.spindle_switched(on)

        _launch(session, "spindle", work, None, f"spindle {'on' if on else 'off'}")


def _launch(session: Any, name: str, work: BoardWork, job: Optional[MachineJob], label: str,
            moved_steps: Any = (0, 0, 0)) -> None:
    """Run ``work`` on the board in the background (:func:`cam.drive.activities.run_on_board`): a drill job's
    holes are its progress (one for a move)."""
    ctl = BoardControl(session.port)
    holes = None if job is None or job.drill_plan is None else job.drill_plan.holes_steps
    total = len(holes) if holes is not None else 1
    session._begin(Activity(name, label, ctl, total, job.estimated_s if job is not None else 0.0))
    session.log(f"{label}: started on {session.port}")
    session._spawn(run_on_board, (session, name, work, ctl, label, np.asarray(moved_steps, np.int64)), name)


register(MaximusBackend())
