"""Seed 004's control unit (``cmd:/dev/parportN``, ``cmd:mock``): one command byte with a strobe pulse per step.

Seed 004 section 3.5: the standalone controller moves the machine by writing command bytes to its control unit on
the parallel port, each with a strobe pulse, at the step's time from a timer interrupt (``X_INC`` = 0x4B).  `cam`
plans and times the steps exactly as for a step/dir port (ramps, look-ahead, pauses); the port turns each step into
its axis's byte from the machine file's ``[commands]`` (:mod:`cam.drive.cmd_port`).  ``cmd:mock`` logs the bytes to
the same pin-log CSV as the mock (decoded with :func:`cam.verify.command_log.commands_to_step_log`).  A job that
needs a command the machine file does not declare is refused before anything moves.
"""
from __future__ import annotations

from typing import Any, Optional

from ...settings import MachineSettings
from ...job.model import Job
from ..machine_job import MachineJob, machine_job
from ..cmd_port import CommandMockPort, CommandParallelPort, check_command_timing, check_commands
from . import Backend, register

__all__ = ["CmdBackend"]

_PREFIX = "cmd:"


class CmdBackend(Backend):
    """``cmd:/dev/parport0`` (the real port through pyparallel) or ``cmd:mock`` (logged)."""

    kind = "cmd"
    example = "cmd:/dev/parport0"
    capabilities = frozenset({"step_dir", "pause", "drill_files", "jog", "resume"})
    cannot = {
        "pin_log": "{port} keeps no pin log: a pin log records the mock's writes (cmd:mock logs command bytes)",
        "home_switches": "{port} (seed 004's control unit) has no switches cam reads: jog to a known place and set "
                         "it (cam where --set X,Y,Z)",
        "probes": "{port} (seed 004's control unit) has no probe input cam reads: {what} needs a step/dir port "
                  "with inputs.probe or grbl",
    }

    def matches(self, name: str) -> bool:
        return name.startswith(_PREFIX) and len(name) > len(_PREFIX)

    def owns(self, port: Any) -> bool:
        return getattr(port, "backend", None) == "cmd"

    def capabilities_of(self, port: Any) -> frozenset[str]:
        """``cmd:mock`` logs its bytes and runs on the simulated clock as the mock does."""
        if port == _PREFIX + "mock" or (port is not None and not isinstance(port, str)
                                         and getattr(port, "pin_log", None) is not None and port.name == "cmd:mock"):
            return self.capabilities | {"pin_log", "simulated"}
        return self.capabilities

    def device(self, port: Any, settings: Optional[MachineSettings] = None) -> Optional[str]:
        if not isinstance(port, str) or self.can("simulated", port):
            return None
        return port[len(_PREFIX):]

    def open_steps(self, name: Any, settings: MachineSettings) -> Any:
        if not isinstance(name, str):
            return name
        check_command_timing(settings)
        inner = name[len(_PREFIX):]
        return CommandMockPort(settings) if inner == "mock" else CommandParallelPort(inner, settings)

    def logging_port(self, name: Any, settings: MachineSettings, **mock_options: Any) -> Any:
        if not (isinstance(name, str) and name == _PREFIX + "mock"):
            return name
        check_command_timing(settings)
        mock_options.pop("switches", None)  # the control unit has no switches cam reads
        return CommandMockPort(settings, **mock_options)

    def check_job(self, session: Any, job: "MachineJob | Job") -> None:
        """Every command byte the job needs is declared in ``[commands]`` (CapabilityError naming the first that
        is not), and three axes' bytes fit in the shortest step period."""
        check_command_timing(session.settings)
        job = machine_job(job)
        if job.moves is not None:  # a step plan alone has no moves left to read: its bytes are checked as sent
            check_commands(job.moves, session.settings)

    def start_moves(self, session: Any, activity: str, job: Any, label: str) -> None:
        self.check_job(session, job)
        super().start_moves(session, activity, job, label)


register(CmdBackend())
