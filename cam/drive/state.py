"""The machine state file: where the machine stands, kept from one command to the next (issue #29 points 2-3).

One small JSON file per machine holds the machine position, whether it is known, whether the machine was
homed, the work offsets G54..G59.3 and the active one, the tool, the machine file it was kept with
(:class:`MachineRecord`), the board it was kept with when the board can say what it is (grbl's ``$I``:
:meth:`StateHold.bind_board`), and a ``running`` marker while a command drives the machine.  On a real port
(parallel port, MAXIMUS, grbl) the file belongs to the port, named after the machine's stable device name when
the system gives one (``/dev/serial/by-id``: :func:`serial_by_id`); on the mock, a simulated machine, to the
port and its machine file.  It is written atomically (:func:`cam.fileio.atomic_write_text`) and locked: the one command
that may drive the machine holds an ``fcntl.flock`` on ``FILE.lock`` beside it, and on a real port also one on
the device itself (:class:`DeviceLock`: a lock file named after the device's real path, and the device), so a
second one is refused (:class:`StateBusyError`, naming the other process and its command; issue #43 point 4).

Frames (every position here says which):

* **machine frame**: steps ``(x, y, z)`` from the machine's home (+x right, +y toward the operator, +z deeper
  into the material); the travel limits (:class:`cam.settings.Travel`) are soft limits in this frame.
* **work frame**: steps from the active work offset's zero, ``work = machine - offset``; each offset is the
  machine position of its zero.

Everything here is pure computation except :func:`read_state`, :func:`write_state`, :func:`state_dir`
(from :mod:`cam.fileio`: reads the environment) and :class:`MachineLock`.

A missing file is a new machine, every offset zero, not homed: on the mock the tool at the home, position known;
on a real port the position **unknown** (a new machine, or a ``--state`` typo: nothing says where the tool
stands; issue #43 point 5).
"""
from __future__ import annotations

import datetime
import hashlib
import json
import os
import re
import stat
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Optional

try:
    import fcntl
except ImportError:  # pragma: no cover - not a POSIX system: no lock (one command at a time is the user's care)
    fcntl = None  # type: ignore[assignment]

from ..errors import BusyError, CamError, PortError, TravelError
from ..fileio import atomic_write_text, state_dir
from ..settings import MAX_TRAVEL_STEPS, MachineSettings, Travel
from .machines import backend_of, can, port_kind

__all__ = [
    "STATE_VERSION", "OFFSET_NAMES", "MachineState", "Running", "StateError", "StateBusyError",
    "PositionUnknownError", "ToolProbe", "parse_state", "read_state", "write_state", "state_dir", "default_state_path",
    "mm_to_steps", "steps_to_mm", "check_in_travel", "MachineLock", "StateHold", "unknown_message", "dump_json",
    "MachineRecord", "MachineFileError", "machine_record", "recorded_machine", "new_machine_state", "DeviceLock",
    "port_device", "is_real_port", "serial_by_id", "SERIAL_BY_ID", "soft_limits_off", "still_unknown",
]

STATE_VERSION = 1
"""The version of the state file's layout (``"cam_machine_state"``)."""

OFFSET_NAMES = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")
"""The work offsets, as G-code names them (G54 is the default active one)."""

MAX_TEXT = 500
"""The longest text (tool, command, reason) the file may hold."""


class StateError(CamError):
    """The state file cannot be read or is not a valid state of this machine (the message names the file)."""


class StateBusyError(BusyError):
    """Another command drives the machine (the message names its process; a lock's refusal also says it in
    ``holder_pid``, None when not written yet, and ``holder_command``, e.g. ``"cam serve"``)."""

    holder_pid: Optional[int] = None
    holder_command: str = ""


class PositionUnknownError(CamError):
    """The machine position is not known: a move needs homing or ``cam where --set`` first."""


class MachineFileError(StateError):
    """The machine file given is not the one the port's state file records (the message names both)."""


@dataclass(frozen=True)
class MachineRecord:
    """The machine file a state file was kept with.

    Attributes:
        path: its absolute path (None: the built-in settings, no ``--machine``).
        sha256: the hex sha256 of its bytes when it was recorded (None: the built-in settings).
    """

    path: Optional[str] = None
    sha256: Optional[str] = None

    def named(self) -> str:
        """How a message names it: the path, or "the built-in settings"."""
        return self.path if self.path is not None else "the built-in settings (no --machine)"


@dataclass(frozen=True)
class ToolProbe:
    """The probe that set the work Z zero (``cam probe z``; issue #46 point 1): where the tool then in the spindle
    touched the plate or sensor (``contact_steps``, machine frame) and the plate's thickness (mm).  ``cam probe
    tool`` probes the next tool at the same X, Y and shifts the work Z by the difference of the contacts."""

    contact_steps: tuple[int, int, int]
    plate_mm: float = 0.0


@dataclass(frozen=True)
class Running:
    """The marker of a command that drives the machine now: its process id, what it is, since when (ISO)."""

    pid: int
    command: str
    since: str


def _zero_offsets() -> dict[str, tuple[int, int, int]]:
    return {name: (0, 0, 0) for name in OFFSET_NAMES}


Steps3 = tuple[int, int, int]


@dataclass(frozen=True)
class MachineState:
    """What the state file says.

    Attributes:
        position_steps: the machine position, machine frame (steps from the home).
        position_known: False after an end nobody recorded (a killed command, a power cut) or an emergency
            stop; a move then needs homing or ``cam where --set``.
        unknown_reason: why the position is unknown ("" when known).
        homed: the machine frame was set by homing (False: by the user's word or a new file).
        offsets_steps: each work offset's zero, machine frame.
        active_offset: the work offset moves and ``cam where`` use (one of :data:`OFFSET_NAMES`).
        tool: the cutter in the spindle as the last job named it (None: not said).
        running: the command that drives the machine now (None: none).
        machine: the machine file the state was kept with (None: not recorded, a file of an older cam).
        board: what the board the state was kept with says it is (grbl's ``$I``; None: not recorded, or a board
            that cannot say, such as MAXIMUS).
        tool_probe: the probe contact of the tool that set the work Z (:class:`ToolProbe`; None: none, or the
            machine frame was said anew since, ``cam where --set``).
    """

    position_steps: Steps3 = (0, 0, 0)
    position_known: bool = True
    unknown_reason: str = ""
    homed: bool = False
    offsets_steps: Mapping[str, Steps3] = field(default_factory=_zero_offsets)
    active_offset: str = "G54"
    tool: Optional[str] = None
    running: Optional[Running] = None
    machine: Optional[MachineRecord] = None
    board: Optional[str] = None
    tool_probe: Optional[ToolProbe] = None

    def work_zero_steps(self, name: Optional[str] = None) -> Steps3:
        """The zero of work offset ``name`` (default: the active one), machine frame."""
        return tuple(self.offsets_steps[name or self.active_offset])  # type: ignore[return-value]

    def to_work(self, machine_steps: Steps3, name: Optional[str] = None) -> Steps3:
        """A machine-frame position in the work frame of ``name`` (default: the active offset)."""
        zero = self.work_zero_steps(name)
        return tuple(int(p) - int(z) for p, z in zip(machine_steps, zero))  # type: ignore[return-value]

    def to_machine(self, work_steps: Steps3, name: Optional[str] = None) -> Steps3:
        """A work-frame position of ``name`` (default: the active offset) in the machine frame."""
        zero = self.work_zero_steps(name)
        return tuple(int(p) + int(z) for p, z in zip(work_steps, zero))  # type: ignore[return-value]

    def moved_to(self, position_steps: Steps3) -> "MachineState":
        """The tool at ``position_steps`` (machine frame), position known."""
        return replace(self, position_steps=tuple(int(v) for v in position_steps), position_known=True,
                       unknown_reason="")

    def lost(self, reason: str, position_steps: Optional[Steps3] = None) -> "MachineState":
        """The position is unknown from now on (``position_steps``: the best guess kept, machine frame)."""
        pos = self.position_steps if position_steps is None else tuple(int(v) for v in position_steps)
        return replace(self, position_steps=pos, position_known=False, unknown_reason=reason[:MAX_TEXT],
                       homed=False)

    def with_offset(self, name: str, zero_steps: Steps3) -> "MachineState":
        """Work offset ``name``'s zero set to ``zero_steps`` (machine frame)."""
        offsets = dict(self.offsets_steps)
        offsets[name] = tuple(int(v) for v in zero_steps)  # type: ignore[assignment]
        return replace(self, offsets_steps=offsets)

    def to_json(self) -> str:
        """The file's text."""
        values = {
            "cam_machine_state": STATE_VERSION,
            "position_steps": list(self.position_steps),
            "position_known": self.position_known,
            "unknown_reason": self.unknown_reason,
            "homed": self.homed,
            "offsets_steps": {name: list(self.offsets_steps[name]) for name in OFFSET_NAMES},
            "active_offset": self.active_offset,
            "tool": self.tool,
            "running": None if self.running is None else vars(self.running),
            "machine_file": None if self.machine is None else vars(self.machine),
            "board": self.board,
        }
        if self.tool_probe is not None:  # absent when none: the files of an older cam read the same
            values["tool_probe"] = {"contact_steps": list(self.tool_probe.contact_steps),
                                    "plate_mm": self.tool_probe.plate_mm}
        return dump_json(values)


def dump_json(values: Mapping[str, Any]) -> str:
    """An object as JSON text, one key a line, each value (a list, an object of lists) on its line."""
    lines = [f"  {json.dumps(k)}: {json.dumps(v, separators=(', ', ': '))}" for k, v in values.items()]
    return "{\n" + ",\n".join(lines) + "\n}\n"


# -- reading and checking ------------------------------------------------------------------------------------

_KEYS = {"cam_machine_state", "position_steps", "position_known", "unknown_reason", "homed", "offsets_steps",
         "active_offset", "tool", "running"}
_OPTIONAL_KEYS = {"machine_file", "board", "tool_probe"}  # absent from the files of an older cam: not recorded


def check_in_travel(position_steps: Any, settings: MachineSettings, what: str) -> None:
    """Refuse a machine-frame position outside the travel, naming the axis and by how much.

    Raises:
        TravelError: ``"{what} is outside the X travel (0..10000 steps): 10500 is 500 steps beyond"``.
    """
    for a, (lo, hi) in enumerate(settings.travel.bounds_steps()):
        v = int(position_steps[a])
        if not lo <= v <= hi:
            beyond = lo - v if v < lo else v - hi
            raise TravelError(f"{what} is outside the {'XYZ'[a]} travel ({lo}..{hi} steps from the home): "
                              f"{v} is {beyond} steps beyond")


def soft_limits_off(settings: MachineSettings) -> MachineSettings:
    """``settings`` with no travel limits: a jog while the position is unknown (nothing says where the limits are;
    issue #45 point 3)."""
    wide = Travel(-MAX_TRAVEL_STEPS, MAX_TRAVEL_STEPS, -MAX_TRAVEL_STEPS, MAX_TRAVEL_STEPS, -MAX_TRAVEL_STEPS,
                  MAX_TRAVEL_STEPS)
    return replace(settings, travel=wide)


def still_unknown(end: MachineState, reason: str, settings: MachineSettings) -> MachineState:
    """The state after a jog made while the position was unknown (``reason``: why it was): still unknown (a jog
    does not make it known; the reason an end of its own gives, else the one before), the guess kept inside the
    travel (a state file holds no position outside it)."""
    bounds = settings.travel.bounds_steps()
    guess = tuple(min(max(int(v), lo), hi) for v, (lo, hi) in zip(end.position_steps, bounds))
    return end.lost(end.unknown_reason or reason, guess)  # type: ignore[arg-type]


def _steps3(value: Any, key: str) -> Steps3:
    if not isinstance(value, list) or len(value) != 3 \
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        raise ValueError(f"{key} must be 3 whole numbers of steps, got {json.dumps(value)[:80]}")
    return tuple(value)  # type: ignore[return-value]


def _text(value: Any, key: str, optional: bool = False) -> Any:
    if value is None and optional:
        return None
    if not isinstance(value, str) or len(value) > MAX_TEXT or any(ord(c) < 32 for c in value):
        raise ValueError(f"{key} must be a line of text (at most {MAX_TEXT} characters)")
    return value


def _flag(value: Any, key: str) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{key} must be true or false, got {json.dumps(value)[:40]}")
    return value


def _running(value: Any) -> Optional[Running]:
    if value is None:
        return None
    if not isinstance(value, dict) or set(value) != {"pid", "command", "since"}:
        raise ValueError("running must be null or {pid, command, since}")
    pid = value["pid"]
    if not isinstance(pid, int) or isinstance(pid, bool) or not 0 < pid < 2**31:
        raise ValueError(f"running.pid must be a process id, got {json.dumps(pid)[:40]}")
    return Running(pid, _text(value["command"], "running.command"), _text(value["since"], "running.since"))


def _machine(value: Any) -> Optional[MachineRecord]:
    if value is None:
        return None
    if not isinstance(value, dict) or set(value) != {"path", "sha256"}:
        raise ValueError("machine_file must be null or {path, sha256}")
    path, digest = value["path"], value["sha256"]
    if path is not None and (not isinstance(path, str) or not path or len(path) > 4096 or "\x00" in path):
        raise ValueError("machine_file.path must be null or a path")
    if digest is not None and (not isinstance(digest, str) or not re.fullmatch(r"[0-9a-f]{64}", digest)):
        raise ValueError("machine_file.sha256 must be null or 64 hex digits")
    return MachineRecord(path, digest)


def _tool_probe(value: Any, settings: MachineSettings) -> Optional[ToolProbe]:
    if value is None:
        return None
    if not isinstance(value, dict) or set(value) != {"contact_steps", "plate_mm"}:
        raise ValueError("tool_probe must be null or {contact_steps, plate_mm}")
    contact = _steps3(value["contact_steps"], "tool_probe.contact_steps")
    check_in_travel(contact, settings, "tool_probe.contact_steps")
    plate = value["plate_mm"]
    if isinstance(plate, bool) or not isinstance(plate, (int, float)) or not 0 <= plate <= 1000:
        raise ValueError(f"tool_probe.plate_mm must be a number of mm 0..1000, got {json.dumps(plate)[:40]}")
    return ToolProbe(contact, float(plate))


def _offsets(value: Any, settings: MachineSettings) -> dict[str, Steps3]:
    if not isinstance(value, dict):
        raise ValueError("offsets_steps must be an object of work offsets (G54..G59.3)")
    offsets = _zero_offsets()
    for name, zero in value.items():
        if name not in OFFSET_NAMES:
            raise ValueError(f"offsets_steps: unknown work offset {name[:20]!r} (known: {', '.join(OFFSET_NAMES)})")
        offsets[name] = _steps3(zero, f"offsets_steps.{name}")
        check_in_travel(offsets[name], settings, f"offsets_steps.{name}")
    return offsets


def _state_of(values: Any, settings: MachineSettings) -> MachineState:
    if not isinstance(values, dict) or values.get("cam_machine_state") != STATE_VERSION:
        raise ValueError(f"not a cam machine state file (no \"cam_machine_state\": {STATE_VERSION})")
    unknown = sorted(set(values) - _KEYS - _OPTIONAL_KEYS)
    if unknown:
        raise ValueError(f"unknown key {unknown[0][:40]!r}")
    missing = sorted(_KEYS - set(values))
    if missing:
        raise ValueError(f"the key {missing[0]!r} is missing")
    position = _steps3(values["position_steps"], "position_steps")
    check_in_travel(position, settings, "position_steps")
    active = values["active_offset"]
    if active not in OFFSET_NAMES:
        raise ValueError(f"active_offset must be one of {', '.join(OFFSET_NAMES)}, got {json.dumps(active)[:40]}")
    known = _flag(values["position_known"], "position_known")
    reason = _text(values["unknown_reason"], "unknown_reason")
    return MachineState(position, known, "" if known else reason, _flag(values["homed"], "homed"),
                        _offsets(values["offsets_steps"], settings), active, _text(values["tool"], "tool", True),
                        _running(values["running"]), _machine(values.get("machine_file")),
                        _text(values.get("board"), "board", True), _tool_probe(values.get("tool_probe"), settings))


def parse_state(text: str, settings: MachineSettings, where: str | os.PathLike) -> MachineState:
    """The state a file's ``text`` holds, every number checked against ``settings``' travel.

    Raises:
        StateError: one line naming ``where`` and what is wrong.
    """
    try:
        return _state_of(json.loads(text), settings)
    except json.JSONDecodeError as exc:
        detail = f"not JSON ({exc.msg} at line {exc.lineno})"
    except (ValueError, TravelError) as exc:
        detail = str(exc)
    raise StateError(f"machine state file {where} is broken: {detail}; fix it, or delete it and say where the tool "
                     f"is with cam where --set X,Y,Z")


def is_real_port(port: Any) -> bool:
    """Whether ``port`` (a name, or an open port) drives a real machine: anything but the mock (None: the mock)."""
    if port is None:
        return False
    return not can(port, "simulated")


def new_machine_state(port: Any = None, path: str | os.PathLike = "") -> MachineState:
    """The state of a machine whose state file ``path`` is missing.  The mock (``port`` None or ``"mock"``), a
    simulated machine: at its home, position known.  A real port: position unknown, since nothing says where its
    tool stands (a new machine, or a typo in ``--state``)."""
    if not is_real_port(port):
        return MachineState()
    return MachineState().lost(f"{port} has no state file {path}: a new machine, or a typo in --state")


def read_state(path: str | os.PathLike, settings: MachineSettings, port: Any = None) -> MachineState:
    """The state in ``path``; a missing file is a new machine (:func:`new_machine_state` of ``port``: on a real
    port the position unknown).

    Raises:
        StateError: the file cannot be read or is broken.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        return new_machine_state(port, p)
    except OSError as exc:
        raise StateError(f"machine state file {p}: cannot read ({exc.strerror or exc})") from None
    if len(raw) > 1 << 16:
        raise StateError(f"machine state file {p} is broken: {len(raw)} bytes, far too long for a state; fix it, or "
                         f"delete it and say where the tool is with cam where --set X,Y,Z")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = "\x00"  # not JSON: parse_state says so
    return parse_state(text, settings, p)


def recorded_machine(path: str | os.PathLike) -> Optional[MachineRecord]:
    """The machine file a state file records, read without the machine's settings (they come from it) and
    without the lock; None when the file is missing, records none, or cannot be read (the command's own read
    of it then says what is wrong)."""
    try:
        values = json.loads(Path(path).read_bytes()[: 1 << 16].decode("utf-8"))
        return _machine(values.get("machine_file")) if isinstance(values, dict) else None
    except (OSError, ValueError):
        return None


def machine_record(machine_file: Optional[str | os.PathLike]) -> MachineRecord:
    """The record of ``machine_file`` (None: the built-in settings): its absolute path and the sha256 of its bytes.

    Raises:
        StateError: the file cannot be read.
    """
    if machine_file is None:
        return MachineRecord()
    p = Path(os.path.abspath(os.path.expanduser(os.fspath(machine_file))))
    try:
        digest = hashlib.sha256(p.read_bytes()).hexdigest()
    except OSError as exc:
        raise StateError(f"machine file {p}: cannot read ({exc.strerror or exc})") from None
    return MachineRecord(str(p), digest)


def write_state(path: str | os.PathLike, state: MachineState) -> None:
    """Write ``state`` to ``path`` atomically (its folder is made when missing)."""
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StateError(f"machine state file {p}: cannot make its folder ({exc.strerror or exc})") from None
    atomic_write_text(p, state.to_json())


def now_text() -> str:
    """The time now, ISO 8601 in UTC to the second (the ``running`` marker's ``since``)."""
    return datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()


def unknown_message(state: MachineState, port: Any = None) -> str:
    """The one-line error of a move asked for while the position is unknown: what makes it known again, for the
    command line and the page alike (issue #45 point 3) - Home where the port can home (``cam home`` or the
    page's Home; a MAXIMUS board cannot), Set position on the page or ``cam where --set X,Y,Z`` - and that a jog
    is allowed meanwhile to find the work, its soft limits off.  On the mock (``port`` None or ``"mock"``) also
    how to start the simulated machine again at its home: ``cam where --set=0,0,0``."""
    why = f"the machine position is unknown ({state.unknown_reason or 'not recorded'})"
    jog = "; a jog is allowed meanwhile to find the work (soft limits off)"
    if isinstance(port, str) and is_real_port(port) and port_kind(port) == "maximus":
        return (f"{why}: the board cannot home, so say where the head is, in machine mm, with Set position on the "
                f"page or cam where --set X,Y,Z (e.g. 0,0,0 where the board origin is){jog}")
    if not is_real_port(port):  # the mock: a simulated machine, nothing really stands anywhere (issue #44 point 7)
        return (f"{why}: on the mock (a simulated machine) start it again at its home with cam where --set=0,0,0, "
                f"or Home on the page or home the machine (cam home), or say where the tool is, in machine mm, with "
                f"Set position on the page or cam where --set X,Y,Z{jog}")
    return (f"{why}: Home on the page or home the machine (cam home), or say where the tool is, in machine mm, with "
            f"Set position on the page or cam where --set X,Y,Z{jog}")


# -- where the file is ---------------------------------------------------------------------------------------

def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._]+", "-", text).strip("-.") or "port"


SERIAL_BY_ID = "/dev/serial/by-id"
"""Where udev keeps a stable name of each USB serial device (the adapter's maker, model and serial number)."""


def serial_by_id(device: str, environ: Optional[Mapping[str, str]] = None) -> Optional[str]:
    """The stable name of the serial device ``device``: its link's name in ``/dev/serial/by-id`` (given directly,
    or the link there that points at ``device``), or None when there is none (no such folder, a pseudo-terminal,
    a parallel port).  ``$CAM_SERIAL_BY_ID`` names another folder to look in (tests).

    >>> serial_by_id("/dev/serial/by-id/usb-FTDI_FT232R_A9ABCDEF-if00-port0")
    'usb-FTDI_FT232R_A9ABCDEF-if00-port0'
    """
    env = os.environ if environ is None else environ
    folder = os.path.abspath(env.get("CAM_SERIAL_BY_ID") or SERIAL_BY_ID)
    given = os.path.abspath(device)
    if os.path.dirname(given) in (folder, SERIAL_BY_ID):
        return os.path.basename(given)
    real = os.path.realpath(device)
    try:
        names = sorted(os.listdir(folder))
    except OSError:
        return None
    return next((name for name in names if os.path.realpath(os.path.join(folder, name)) == real), None)


def default_state_path(machine_file: Optional[str], port: str,
                       environ: Optional[Mapping[str, str]] = None) -> Path:
    """The default state file of a machine.  The mock (a simulated machine for each machine file):
    ``{state_dir}/{machine file's stem, or "default"}-mock.json``.  A real port: the state belongs to the port
    (the machine on it), whatever ``--machine`` says (the file records its machine file: :class:`MachineRecord`):
    a grbl or MAXIMUS board whose device has a stable name (:func:`serial_by_id`: the USB adapter's, whichever
    ``/dev/ttyUSBn`` it got today) ``{state_dir}/{grbl|maximus}-by-id-{that name}.json``, else
    ``{state_dir}/{port, without its ?options}.json`` (issue #44 point 5).

    >>> default_state_path(None, "mock", {"XDG_STATE_HOME": "/s"}).as_posix()
    '/s/cam/default-mock.json'
    >>> default_state_path("shop/mill.toml", "mock", {"XDG_STATE_HOME": "/s"}).name
    'mill-mock.json'
    >>> default_state_path("shop/mill.toml", "maximus:/dev/ttyUSB0", {"XDG_STATE_HOME": "/s"}).name
    'maximus-dev-ttyUSB0.json'
    >>> default_state_path(None, "grbl:/dev/ttyACM0?baud=115200", {"XDG_STATE_HOME": "/s"}).name
    'grbl-dev-ttyACM0.json'
    """
    if is_real_port(str(port)):
        kind = port_kind(str(port))
        device = port_device(str(port)) if kind in ("grbl", "maximus") else None  # serial: a stable by-id name
        stable = serial_by_id(device, environ) if device is not None else None
        if stable is not None:
            return state_dir(environ) / f"{kind}-by-id-{_slug(stable)}.json"
        return state_dir(environ) / f"{_slug(str(port).partition('?')[0])}.json"
    machine = _slug(Path(machine_file).stem) if machine_file else "default"
    return state_dir(environ) / f"{machine}-{_slug(str(port))}.json"


# -- units --------------------------------------------------------------------------------------------------

def mm_to_steps(xyz_mm: Any, settings: MachineSettings) -> Steps3:
    """``(x, y, z)`` mm as the nearest whole steps (same frame; +z deeper)."""
    per = settings.mm_per_step_axes
    return tuple(int(round(float(v) / p)) for v, p in zip(xyz_mm, per))  # type: ignore[return-value]


def steps_to_mm(xyz_steps: Any, settings: MachineSettings) -> tuple[float, float, float]:
    """``(x, y, z)`` steps in mm, rounded to 0.1 um (same frame; +z deeper)."""
    per = settings.mm_per_step_axes
    return tuple(round(int(v) * p, 4) for v, p in zip(xyz_steps, per))  # type: ignore[return-value]


# -- the locks ----------------------------------------------------------------------------------------------

def _holder_text(fd: int) -> tuple[Optional[int], str]:
    """What a lock file says of its holder: (process id or None, its command or "")."""
    text = os.pread(fd, 600, 0).decode("utf-8", "replace").strip()
    pid, _, command = text.partition(" ")
    return (int(pid) if pid.isdigit() else None), command.strip()


def _holder_words(fd: int) -> str:
    pid, command = _holder_text(fd)
    who = f"pid {pid}" if pid is not None else "a process"
    return f"{who}: {command}" if command else who


class _LockFile:
    """An ``flock`` on a lock file that holds its holder's process id and command (one line).  The kernel
    releases it when the process ends, however; a lock is one open file, so a second holder in the same process
    is refused too."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._fd: Optional[int] = None

    def _open_error(self, exc: OSError) -> CamError:
        return StateError(f"cannot open the lock {self.path} ({exc.strerror or exc})")

    def _open(self) -> int:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            return os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as exc:
            raise self._open_error(exc) from None

    def holder(self) -> Optional[int]:
        """The process id that holds the lock now (0: one whose id is not written yet), or None when free."""
        if fcntl is None:
            return None
        fd = self._open()
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                pid, _ = _holder_text(fd)
                return 0 if pid is None else pid
            fcntl.flock(fd, fcntl.LOCK_UN)
            return None
        finally:
            os.close(fd)

    def _refusal(self, what: str, holder: str) -> CamError:
        return StateBusyError(f"{what} refused: {self.path} is held by another cam command ({holder})")

    def acquire(self, what: str = "this command") -> None:
        """Take the lock, or refuse.  ``what``: the command, written for the next one's refusal to name.

        Raises:
            StateBusyError: another process (or another hold of this one) holds it, named in the message.
        """
        fd = self._open()
        if fcntl is None:
            self._fd = fd
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder_words(fd)
            pid, command = _holder_text(fd)
            os.close(fd)
            refusal = self._refusal(what, holder)
            refusal.holder_pid, refusal.holder_command = pid, command  # type: ignore[attr-defined]
            raise refusal from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()} {' '.join(what.split())[:MAX_TEXT]}\n".encode("utf-8"), 0)
        self._fd = fd

    def release(self) -> None:
        """Let the lock go (the lock file stays: removing it would race with the next holder)."""
        if self._fd is not None:
            fd, self._fd = self._fd, None
            if fcntl is not None:
                os.ftruncate(fd, 0)
                fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)

    @property
    def held(self) -> bool:
        """Whether this object holds the lock."""
        return self._fd is not None

    def __enter__(self) -> "_LockFile":
        self.acquire()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.release()


class MachineLock(_LockFile):
    """The lock that lets one command at a time drive a machine: ``flock`` on ``STATE.lock`` beside the state
    file, which holds the holder's process id and command.

    Args:
        state_path: the state file (the lock file is its name plus ``.lock``).
    """

    def __init__(self, state_path: str | os.PathLike) -> None:
        self.state_path = Path(state_path)
        super().__init__(self.state_path.with_name(self.state_path.name + ".lock"))

    def _open_error(self, exc: OSError) -> CamError:
        return StateError(f"machine state file {self.state_path}: cannot open its lock {self.path} "
                          f"({exc.strerror or exc})")

    def _refusal(self, what: str, holder: str) -> CamError:
        return StateBusyError(f"{what} refused: another cam command ({holder}) drives the machine of "
                              f"{self.state_path}; try again when it has ended")


def port_device(port: Any, settings: Optional[MachineSettings] = None) -> Optional[str]:
    """The device a port name opens (``/dev/parport0``, a grbl or MAXIMUS board's serial device), or None: the
    mock, an open port object, or a bare ``maximus`` without the settings that name its device.

    Raises:
        PortError: a bare ``maximus`` whose settings name no serial port."""
    if not isinstance(port, str):
        return None
    return backend_of(port).device(port, settings)


def missing_device_message(port: str, device: str) -> str:
    """One line for a real port whose device does not exist: what to check, in the words the port's own open
    would use."""
    kind = port_kind(port)
    if kind in ("parport", "cmd"):
        return (f"cannot open parallel port {device} (No such file or directory): load the kernel driver "
                f"(sudo modprobe ppdev), check the name (ls /dev/parport*) and that you may use it (the lp group)")
    name = {"maximus": "MAXIMUS", "grbl": "grbl"}.get(kind, kind)
    return (f"cannot open {name} port {device} (No such file or directory): check that the board is plugged in "
            f"and switched on, the device name (ls /dev/ttyUSB* /dev/ttyACM* /dev/ttyS*) and that you may use it "
            f"(the dialout group)")


class DeviceLock(_LockFile):
    """One port, one user (issue #43 point 4): the lock on a machine's device itself, whatever state file a
    command keeps.  An ``flock`` on ``{state_dir}/ports/{the device's real path}.lock`` (holding the holder's
    process id and command), and, on a character device, an ``flock`` on the device too (which also keeps out
    other programs that lock it, such as pyserial's ``exclusive=True``, and users with another state folder).

    Args:
        device: the device path (a symbolic link is resolved: two names of one device are one lock).
        port: the port name, for messages.
    """

    def __init__(self, device: str, port: Optional[str] = None,
                 environ: Optional[Mapping[str, str]] = None) -> None:
        self.device = device
        self.real = os.path.realpath(device)
        self.port = port or device
        self._device_fd: Optional[int] = None
        super().__init__(state_dir(environ) / "ports" / f"{_slug(self.real)}.lock")

    def _refusal(self, what: str, holder: str) -> CamError:
        return StateBusyError(f"{what} refused: {self.port} ({self.real}) is in use by another cam command "
                              f"({holder}); try again when it has ended")

    def acquire(self, what: str = "this command") -> None:
        """Take the lock file's lock and the device's own, or refuse (:class:`StateBusyError`, one line)."""
        super().acquire(what)
        try:
            self._lock_device(what)
        except BaseException:
            super().release()
            raise

    def _lock_device(self, what: str) -> None:
        if fcntl is None:
            return
        try:
            if not stat.S_ISCHR(os.stat(self.real).st_mode):
                return  # not a device (a missing one: opening the port says so)
            fd = os.open(self.real, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return  # no such device, or not ours to open: opening the port says so in its own words
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise StateBusyError(f"{what} refused: {self.port} ({self.real}) is in use by another program (it holds "
                                 f"a lock on the device); try again when it has ended") from None
        except OSError:
            os.close(fd)  # a device that cannot be locked: the lock file alone
            return
        self._device_fd = fd

    def release(self) -> None:
        """Let both locks go."""
        if self._device_fd is not None:
            fd, self._device_fd = self._device_fd, None
            try:
                fcntl.flock(fd, fcntl.LOCK_UN)
            finally:
                os.close(fd)
        super().release()


class StateHold:
    """A command's hold on a machine: the locks (taken here), and the state read under them.

    A ``running`` marker found under the lock was left by a command that ended without recording where the
    tool stopped (SIGKILL, a power cut): the position becomes unknown, and is written so at once.  Every
    position is in the machine frame.

    On a real ``port`` the device's own lock (:class:`DeviceLock`) is taken first, a missing file is a position
    unknown (:func:`new_machine_state`), and a ``machine`` file other than the one the state records is refused
    (:class:`MachineFileError`, naming both) unless ``machine_changed``: the new one is then recorded and the
    position is unknown.  On the mock another machine file is recorded as it comes.

    Args:
        path: the state file.
        settings: the machine's settings (its travel checks every number of the file).
        what: what the command is, for the message that refuses it while another one holds the lock (and the
            one that refuses the next while this one does).
        port: the port name the machine is driven on (None: not said yet; :meth:`bind_port` says it, as
            :class:`~cam.drive.session.MachineSession` does).
        machine: the machine file the command runs with (:func:`machine_record`; None: not said, nothing
            checked or recorded).
        machine_changed: the user says the machine on this port changed (``--machine-changed``).

    Raises:
        StateBusyError: another command holds a lock; StateError: the file is broken; MachineFileError.
    """

    def __init__(self, path: str | os.PathLike, settings: MachineSettings, what: str = "this command", *,
                 port: Optional[str] = None, machine: Optional[MachineRecord] = None,
                 machine_changed: bool = False) -> None:
        self.path = Path(path)
        self.settings = settings
        self.what = what
        self.port: Optional[str] = None
        self.device_lock: Optional[DeviceLock] = None
        self.machine = machine
        self.board: Optional[str] = None
        """What the board on the port says it is (:meth:`bind_board`; None: not said): every write records it."""
        self.warnings: list[str] = []
        """What the command should say on stderr (a machine file changed since it was recorded)."""
        self._fresh = False  # a missing file nothing has been written to yet
        self.lock = MachineLock(self.path)
        try:
            self._lock_device(port)
            self.lock.acquire(what)
            self.existed = self.path.exists()
            """Whether the file was there (False: a new machine: at the home on the mock, else unknown)."""
            self._fresh = not self.existed
            self.state = read_state(self.path, settings)
            r = self.state.running
            if r is not None:
                self.save(replace(self.state.lost(
                    f"cam (pid {r.pid}: {r.command}) drove the machine from {r.since} and ended without recording "
                    f"where the tool stopped: killed, or a power cut"), running=None))
            if port is not None:
                self.bind_port(port)
            self._check_machine(machine_changed)
        except BaseException:
            self.close()
            raise

    def _lock_device(self, port: Any) -> None:
        device = port_device(port, self.settings)
        if device is not None and self.device_lock is None:
            lock = DeviceLock(device, str(port))
            lock.acquire(self.what)
            self.device_lock = lock

    def bind_port(self, port: Any) -> None:
        """Say which port the machine is driven on (once; the session does): on a real port its device's lock is
        taken (if not yet) and a missing file, nothing written to it yet, is a position unknown.

        Raises:
            StateBusyError: another command uses the device; StateError: the hold is another port's.
        """
        name = port if isinstance(port, str) else None
        if self.port is not None:
            if name is not None and port_device(name, self.settings) != port_device(self.port, self.settings):
                raise StateError(f"machine state file {self.path} is held for {self.port}, not {name}")
            return
        self._lock_device(name)
        self.port = name if name is not None else ("mock" if not is_real_port(port) else None)
        if self._fresh and is_real_port(port):
            self.state = replace(new_machine_state(port, self.path), machine=self.state.machine)

    def _check_machine(self, machine_changed: bool) -> None:
        given, recorded = self.machine, self.state.machine
        if given is None:
            return
        if recorded is None or recorded == given:
            self.state = replace(self.state, machine=given)
            return
        if recorded.path == given.path:
            self.warnings.append(f"machine file {given.path} changed since the state file {self.path} recorded it: "
                                 f"if its steps per mm or travel changed, home the machine (cam home) or say where "
                                 f"the tool is (cam where --set X,Y,Z)")
            self.state = replace(self.state, machine=given)
            return
        if not is_real_port(self.port):  # the mock: a simulated machine, the new file recorded as it comes
            self.state = replace(self.state, machine=given)
            return
        if not machine_changed:
            raise MachineFileError(
                f"{self.what} refused: the state file {self.path} of {self.port} records machine file "
                f"{recorded.named()}, not {given.named()}: drop --machine to use the recorded one, or add "
                f"--machine-changed if the machine on this port changed (its position is then unknown)")
        self.save(replace(self.state.lost(f"the machine changed (--machine-changed): {recorded.named()} -> "
                                          f"{given.named()}"), machine=given))

    def bind_board(self, identity: Optional[str], where: str) -> str:
        """Say what the board on the port says it is (grbl's ``$I``; None: it cannot say, nothing is checked),
        and hold it against the one the state file records (issue #44 point 5).  Another one makes the position
        unknown, recorded at once with the new board; the one-line reason, naming both, is returned for the log
        ("" when it is the recorded board, or the file records none: the board is recorded then, at once when
        the file exists, and by every write from now on).  ``where``: the device, for the reason."""
        if identity is None:
            return ""
        recorded, self.board = self.state.board, identity[:MAX_TEXT]
        if recorded == self.board:
            return ""
        if recorded is None:
            if self._fresh:  # a new file: the board goes with its first write
                self.state = replace(self.state, board=self.board)
            else:
                self.save(self.state)
            return ""
        reason = f"another board on {where}: it says {self.board}, the state file recorded {recorded}"
        self.save(self.state.lost(reason))
        return self.state.unknown_reason

    def require_known(self) -> None:
        """Refuse a move while the position is unknown (:class:`PositionUnknownError`, one line).  A real port
        with no state file and no device either is refused for the device (:func:`missing_device_message`): a
        typo in ``--port`` is what the user has to fix first, not the position."""
        if not self.state.position_known:
            if not self.existed and self.port is not None:
                device = port_device(self.port, self.settings)
                if device is not None and not os.path.exists(device):
                    raise PortError(missing_device_message(str(self.port), device))
            raise PositionUnknownError(unknown_message(self.state, self.port))

    def save(self, state: MachineState) -> None:
        """Write ``state`` and keep it as the current one (with the hold's machine file and board, when it has
        them)."""
        if self.machine is not None and state.machine != self.machine:
            state = replace(state, machine=self.machine)
        if self.board is not None and state.board != self.board:
            state = replace(state, board=self.board)
        write_state(self.path, state)
        self.state = state
        self._fresh = False

    def mark_running(self, command: str) -> None:
        """This process drives the machine from now on (the marker a killed command leaves behind)."""
        self.save(replace(self.state, running=Running(os.getpid(), command[:MAX_TEXT], now_text())))

    def record(self, state: MachineState) -> None:
        """Where the command left the machine: ``state`` without the running marker."""
        self.save(replace(state, running=None))

    def close(self) -> None:
        """Let the locks go (a running marker never recorded stays: the next command treats the position as
        unknown)."""
        self.lock.release()
        if self.device_lock is not None:
            self.device_lock.release()

    def __enter__(self) -> "StateHold":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
