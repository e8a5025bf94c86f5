"""Step/dir back ends: the logging mock (``mock``) and the PC parallel port (``/dev/parportN``).

`cam` times every step itself (thesis chapter 3: a clock and a direction bit per axis on the data register, the
Half/Full* line on the strobe pin); the session's own flows (a step plan, homing on the switches of ``[inputs]``)
are what these back ends do, the defaults of :class:`~cam.drive.machines.Backend`.
"""
from __future__ import annotations

from typing import Any

from ...settings import MachineSettings
from ..ports import MockPort, ParallelPort, Port
from ..probing import start_probe_on_steps
from ..program_probe import start_program_on_steps
from . import Backend, register

__all__ = ["MockBackend", "ParportBackend"]

_STEP_DIR = frozenset({"step_dir", "pause", "drill_files", "jog", "home_switches", "resume", "probes"})


class _StepDir(Backend):
    """What both step/dir back ends do alike: probing on the probe input of ``[inputs]`` (``cam probe``, and a G-code
    program's G38.2/G38.3)."""

    def start_probe(self, session: Any, probe_run: Any) -> None:
        start_probe_on_steps(session, probe_run)

    def start_program(self, session: Any, job: Any, name: str, controller: Any) -> None:
        start_program_on_steps(session, job, name, controller)


class MockBackend(_StepDir):
    """``mock``: nothing leaves the PC; every write is logged (the thesis's Debug Mode)."""

    kind = "mock"
    example = "mock"
    capabilities = _STEP_DIR | {"simulated", "pin_log"}

    def matches(self, name: str) -> bool:
        return name == "mock"

    def owns(self, port: Any) -> bool:
        return isinstance(port, MockPort) and getattr(port, "backend", None) is None

    def open_steps(self, name: Any, settings: MachineSettings) -> Any:
        return name if self.owns(name) else MockPort()

    def logging_port(self, name: Any, settings: MachineSettings, **mock_options: Any) -> Any:
        return MockPort(**mock_options)


class ParportBackend(_StepDir):
    """``/dev/parportN``: the real parallel port through pyparallel."""

    kind = "parport"
    example = "/dev/parport0"
    capabilities = _STEP_DIR

    def matches(self, name: str) -> bool:
        return name.startswith("/dev/")

    def owns(self, port: Any) -> bool:
        return isinstance(port, Port) and not isinstance(port, MockPort) and getattr(port, "backend", None) is None

    def open_steps(self, name: Any, settings: MachineSettings) -> Any:
        return name if not isinstance(name, str) else ParallelPort(name)


register(MockBackend())
register(ParportBackend())
