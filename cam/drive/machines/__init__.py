"""Machines as one protocol: a port's name picks its back end from one registry (issue #45 point 1).

Every kind of machine `cam` drives is one :class:`Backend` in :data:`REGISTRY`, one module each:

* :mod:`~cam.drive.machines.stepdir` -- ``mock`` (the logging mock, the default) and ``/dev/parportN`` (step and
  direction pulses timed by `cam`, thesis chapter 3);
* :mod:`~cam.drive.machines.cmd` -- ``cmd:/dev/parportN`` and ``cmd:mock``: seed 004's control unit, one command
  byte with a strobe pulse per step;
* :mod:`~cam.drive.machines.maximus` -- ``maximus:DEVICE``: the MAXIMUS PCB driller's PIC board (it drills drill
  files by itself, seeds 000 and 003);
* :mod:`~cam.drive.machines.grbl` -- ``grbl:DEVICE``: a grbl 1.1 (grblHAL, FluidNC) board fed G-code.

A back end says what it can do (:attr:`Backend.capabilities`, :data:`CAPABILITY_MEANINGS`) and does the machine's
part of each flow for the session (:class:`~cam.drive.session.MachineSession`): resolve its name, the machine
settings it runs with, start a job or a move, home.  The session keeps only what every machine shares (one
activity at a time, the state file, the journal, the log); the command line and the page ask
:func:`can` for a capability, never for a port's name.  A new machine is one module and one line of
:data:`REGISTRY`.
"""
from __future__ import annotations

from typing import Any, Optional

from ...choices import DEFAULT_PORT
from ...errors import CapabilityError, PortError
from ...settings import DEFAULT_SETTINGS, MachineSettings
from ...motion.chunks import plan_chunks
from ..machine_job import MachineJob
from ..ports import Port

__all__ = ["Backend", "REGISTRY", "CAPABILITY_MEANINGS", "DEFAULT_PORT", "backend_of", "can", "require",
           "open_port", "port_kind", "port_choices_help"]

CAPABILITY_MEANINGS = {
    "simulated": "nothing leaves the PC: the position is simulated, the run may use a simulated clock",
    "step_dir": "cam times every step itself (step/dir pulses or command bytes): any job, ramps, look-ahead",
    "pin_log": "every write is logged to a pin-log CSV",
    "pause": "a running job can be paused and resumed",
    "drill_files": "drill files (Excellon) run on it",
    "jog": "single-axis jogs",
    "delay": "step delays set as the board's Delay bytes",
    "spindle": "a spindle switch cam sets",
    "drill_stroke": "Z Drill Up / Down kept by the board",
    "gcode": "jobs are streamed as G-code; the board plans its own motion",
    "overrides": "a feed override while a job runs",
    "home_switches": "homing by cam on home switches it reads (the mock's are simulated)",
    "homes_itself": "the board homes with its own cycle ($H)",
    "reports_position": "the board reports where its tool stands",
    "keeps_own_time": "the board times its own moves (cam's step plan does not)",
    "drills_alone": "the board drills a hole by itself: a job is a list of holes, resumed at the next hole",
    "board_settings": "its machine settings start from the board's own (resolution, step modes)",
    "resume": "a stopped job resumes from its journal",
    "probes": "a touch probe: Z probed down to the work's surface (cam probe; the mock's is simulated)",
}
"""Every capability a back end may have, in one line each (``cam info --port`` lists a port's)."""

_CANNOT = {
    "pause": "{port} cannot pause a job: stop it, or wait for a tool change",
    "pin_log": "{port} keeps no pin log: a pin log records the mock port's writes (--port mock or cmd:mock)",
    "step_dir": "{port} cannot run {what}: it needs a port cam times itself (mock, /dev/parportN, cmd:...)",
    "drill_files": "{port} cannot drill {what}",
    "jog": "{port} cannot jog",
    "delay": "{port} takes its step delays from the machine settings; {what} applies to the MAXIMUS board only",
    "spindle": "{port} has no spindle switch; {what} applies to the MAXIMUS board only",
    "drill_stroke": "{port} takes its drill depth from each job; {what} applies to the MAXIMUS board only",
    "gcode": "{port} is not a grbl board; {what} applies to grbl ports (grbl:/dev/ttyUSB0) only",
    "overrides": "{port} has no feed override; {what} applies to grbl ports (grbl:/dev/ttyUSB0) only",
    "homes_itself": "{port} is not a grbl board; {what} applies to grbl ports only",
    "home_switches": "{port} has no home switches cam reads; {what} needs a step/dir port with [inputs]",
    "reports_position": "{port} does not report where its tool stands; {what} applies to grbl ports only",
    "resume": "{port} cannot resume a job from a journal",
    "probes": "{port} has no probe input cam reads; {what} needs a step/dir port with inputs.probe (the mock with "
              "[mock] probe_surface) or grbl",
}


class Backend:
    """One kind of machine behind a port name (a subclass per module; one instance in :data:`REGISTRY`).

    Subclasses set :attr:`kind`, :attr:`example`, :attr:`capabilities` and override :meth:`matches`; the flows a
    machine does its own way (:meth:`start_job`, :meth:`start_moves`, :meth:`home`, :meth:`attach`) default to
    what a step/dir port does.
    """

    kind = ""
    """The back end's name (``"mock"``, ``"parport"``, ``"cmd"``, ``"maximus"``, ``"grbl"``)."""
    example = ""
    """A port name it opens, for messages."""
    capabilities: frozenset[str] = frozenset()
    cannot: dict[str, str] = {}
    """Its own wording of a refusal (``{port}``, ``{what}``), where the general one would mislead."""

    def matches(self, name: str) -> bool:
        """Whether the port name ``name`` opens this back end."""
        raise NotImplementedError

    def owns(self, port: Port) -> bool:
        """Whether an open port object belongs to this back end (a port a caller opened and passes on)."""
        return False

    def capabilities_of(self, port: Any) -> frozenset[str]:
        """What the port ``port`` of this back end can do (:attr:`capabilities`; ``cmd:mock`` adds the mock's)."""
        return self.capabilities

    def can(self, capability: str, port: Any = None) -> bool:
        """Whether this back end (the port ``port`` of it) has ``capability`` (a key of
        :data:`CAPABILITY_MEANINGS`)."""
        return capability in self.capabilities_of(port)

    def require(self, port: Any, capability: str, what: str = "this job") -> None:
        """Refuse what this back end cannot do, in the one line every front end shows (CapabilityError)."""
        if capability not in self.capabilities_of(port):
            text = self.cannot.get(capability) or _CANNOT[capability]
            raise CapabilityError(text.format(port=str(port), what=what))

    # -- the machine's side of each flow ------------------------------------------------------
    def resolve(self, name: Any, settings: MachineSettings) -> Any:
        """The port the session opens for ``name`` (the MAXIMUS board's ``maximus`` alone: the machine file's
        serial port)."""
        return name

    def device(self, port: Any, settings: Optional[MachineSettings] = None) -> Optional[str]:
        """The device the port name opens (its lock and its missing-device message), or None: nothing real (a
        mock), an open port object, or a name whose device only the settings give when they are not given."""
        if not isinstance(port, str) or self.can("simulated", port):
            return None
        return port

    def base_settings(self) -> Optional[MachineSettings]:
        """The settings a machine file of this machine starts from (None: `cam`'s defaults)."""
        return None

    def adapt_settings(self, settings: MachineSettings) -> MachineSettings:
        """The settings the session runs with, from the machine file's (a board derives its resolution)."""
        return settings

    def half_step(self, settings: MachineSettings, axis: str) -> bool:
        """Whether one machine step of ``axis`` (``x``, ``y``, ``z``) is half a motor step."""
        return settings.half_step

    def speeds_line(self, settings: MachineSettings) -> Optional[str]:
        """Its own line of speeds for ``cam info`` (None: the step/dir line from the settings' ramps)."""
        return None

    def open_steps(self, name: Any, settings: MachineSettings) -> Port:
        """Open a port `cam` writes steps to (back ends with ``step_dir``)."""
        raise CapabilityError(_CANNOT["step_dir"].format(port=str(name), what="a step/dir job"))

    def logging_port(self, name: Any, settings: MachineSettings, **mock_options: Any) -> Any:
        """The port a command runs a job on when it keeps or streams the pin log itself (back ends with
        ``pin_log``: a mock of this process, ``mock_options`` as :class:`~cam.drive.ports.MockPort` takes them);
        else ``name`` as given."""
        return name

    def attach(self, session: Any) -> None:
        """The session opened on this machine (grbl: connect, and take where the board says the tool stands)."""

    def check_job(self, session: Any, job: MachineJob) -> None:
        """Refuse, before anything moves, a job this machine cannot run (beyond the travel, checked by the session)."""

    def start_job(self, session: Any, job: MachineJob, name: str, journal: Any, controller: Any) -> None:
        """Start ``job`` (checked, placed) in the background: a step plan from where the tool stands."""
        spec = session._journal_spec(job, journal)
        plan = session._plan(job)
        session._launch_steps("job", plan, name, job.estimated_s if job.plan is not None else
                              (lambda: plan.estimated_time_s), controller, spec)

    def start_moves(self, session: Any, activity: str, job: Any, label: str) -> None:
        """Start a travel-only job (a jog, a go-to, the way to a work zero) in the background."""
        plan = plan_chunks(job, start_steps=tuple(int(v) for v in session._position))
        session._launch_steps(activity, plan, label, lambda: plan.estimated_time_s)

    def home(self, session: Any, axes: Optional[str]) -> bool:
        """Home this machine its own way and return True; False: the session homes on switches it reads."""
        return False

    def start_probe(self, session: Any, probe_run: Any) -> None:
        """Start a probing activity (a :class:`~cam.drive.probing.ProbeRun`, checked by the session) through the
        session's ``_launch_probe``; a machine without a probe refuses in one line."""
        self.require(session.port, "probes", "probing")

    def start_program(self, session: Any, job: MachineJob, name: str, controller: Any) -> None:
        """Start a G-code program that probes (``job.probing``: :mod:`cam.drive.program_probe`), checked by the
        session, in the background; a machine without a probe refuses in one line."""
        self.require(session.port, "probes", "a G-code program that probes (G38.2/G38.3)")

    def spindle(self, session: Any, on: bool) -> None:
        """Switch the spindle on or off (back ends with ``spindle``; the session checked the capability and that
        nothing runs) in the background (issue #47 point 7)."""
        self.require(session.port, "spindle", "the spindle switch")

    def feed_override(self, session: Any, percent: int) -> None:
        """Set the feed override (back ends with ``overrides``; the session checked the number and the capability)."""
        raise CapabilityError(_CANNOT["overrides"].format(port=str(session.port), what="a feed override"))

    def state_extra(self, session: Any) -> Optional[dict[str, Any]]:
        """What this machine adds to the session's snapshot (its own state, overrides), or None."""
        return None

    # -- the machine's own frame, kept with the session's (a board that keeps its own position: grbl) ------------
    def rebase(self, session: Any, position_steps: tuple[int, int, int]) -> None:
        """The session's frame was redefined (Set position, an origin without a state file): the tool stands at
        ``position_steps`` (machine frame) from now on."""

    def work_zero_set(self, session: Any, offset: str, axes: str) -> None:
        """Work offset ``offset``'s zero of ``axes`` was set where the tool stands."""

    def work_z_set(self, session: Any, offset: str, z_steps: int) -> None:
        """Work offset ``offset``'s Z zero was set at machine Z ``z_steps`` (a probe's contact)."""

    def offset_used(self, session: Any, offset: str) -> None:
        """Work offset ``offset`` is the active one now."""

    def before_unknown_jog(self, session: Any) -> None:
        """A jog with the position unknown is about to start (soft limits off)."""

    def home_refusal(self, port: Any) -> None:
        """Refuse homing in one line on a machine that can do neither (CapabilityError saying what it can do
        instead); nothing on the others."""
        if not (self.can("homes_itself", port) or self.can("home_switches", port)):
            self.require(port, "home_switches", "homing")

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.kind}>"


REGISTRY: list[Backend] = []
"""Every back end, in the order port names are tried (the first that matches opens the port)."""


def register(backend: Backend) -> Backend:
    """Add ``backend`` to :data:`REGISTRY` (each machine module registers its own)."""
    REGISTRY.append(backend)
    return backend


def _load() -> None:
    """Import the back ends once (each registers itself): at the first port named, so that ``--help`` and the
    modules every back end imports (ports, chunks) do not load them."""
    if REGISTRY:
        return
    from . import cmd, grbl, maximus, stepdir  # noqa: F401 - the one line per machine

    order = {"cmd": 0, "maximus": 1, "grbl": 2, "mock": 3, "parport": 4}  # prefixes before plain device paths
    REGISTRY.sort(key=lambda b: order.get(b.kind, 2))


def backend_of(port: Any) -> Backend:
    """The back end a port name (or an open port object) belongs to.

    >>> [backend_of(n).kind for n in ("mock", "/dev/parport0", "cmd:mock", "maximus:/dev/ttyUSB0", "grbl:COM3")]
    ['mock', 'parport', 'cmd', 'maximus', 'grbl']

    Raises:
        PortError: a name no back end opens (the message lists them).
    """
    _load()
    if not isinstance(port, str):
        for b in REGISTRY:
            if b.owns(port):
                return b
        raise PortError(f"a port object {type(port).__name__} that no machine back end owns")
    for b in REGISTRY:
        if b.matches(port):
            return b
    names = ", ".join(b.example for b in REGISTRY)
    raise PortError(f"unknown port '{port}' (use one of: {names})")


def port_choices_help() -> str:
    """The port names the registry opens, for ``--help`` texts (one example per back end)."""
    _load()
    return ", ".join(b.example for b in REGISTRY) + f" (default {DEFAULT_PORT})"


def can(port: Any, capability: str) -> bool:
    """Whether the machine behind ``port`` (a name or an open port) has ``capability``."""
    if capability not in CAPABILITY_MEANINGS:
        raise ValueError(f"unknown capability {capability!r}")
    return backend_of(port).can(capability, port)


def require(port: Any, capability: str, *, what: str = "this job") -> None:
    """Refuse what the machine behind ``port`` cannot do, with the one message every front end shows.

    Raises:
        CapabilityError: it lacks ``capability``; PortError: an unknown port name.
    """
    backend_of(port).require(port, capability, what)


def port_kind(port: Any) -> str:
    """The back end's name for a port name (or an open port): ``"mock"``, ``"parport"``, ``"cmd"``, ``"maximus"``,
    ``"grbl"`` (for messages and the state file; front ends ask :func:`can` instead).

    >>> port_kind("mock"), port_kind("/dev/parport0"), port_kind("maximus:/dev/ttyUSB0"), port_kind("grbl:COM3")
    ('mock', 'parport', 'maximus', 'grbl')

    Raises:
        PortError: an unknown name.
    """
    return backend_of(port).kind


def open_port(name: Any = DEFAULT_PORT, settings: Optional[MachineSettings] = None) -> Port:
    """Open a port `cam` writes steps to, by name: ``mock``, a device path (``/dev/parport0``), ``cmd:...`` (its
    command bytes from ``settings``' ``[commands]``).  A Port passes through.

    Raises:
        CapabilityError: a board that makes its own steps (MAXIMUS, grbl: see :mod:`cam.drive.session`);
        PortError: an unknown name or a port that cannot be opened.
    """
    if isinstance(name, Port):
        return name
    backend = backend_of(name)
    backend.require(name, "step_dir", "a step/dir job")
    return backend.open_steps(name, settings or DEFAULT_SETTINGS)
