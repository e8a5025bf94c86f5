"""The machine state file: where the machine stands, kept from one command to the next (issue #29 points 2-3).

One small JSON file per machine (the machine file and the port) holds the machine position, whether it is
known, whether the machine was homed, the work offsets G54..G59.3 and the active one, the tool, and a
``running`` marker while a command drives the machine.  It is written atomically
(:func:`cam.fileio.atomic_write_text`) and locked: the one command that may drive the machine holds an
``fcntl.flock`` on ``FILE.lock`` beside it, so a second one is refused (:class:`StateBusyError`, naming the
other process).

Frames (every position here says which):

* **machine frame**: steps ``(x, y, z)`` from the machine's home (+x right, +y toward the operator, +z deeper
  into the material); the travel limits (:class:`cam.settings.Travel`) are soft limits in this frame.
* **work frame**: steps from the active work offset's zero, ``work = machine - offset``; each offset is the
  machine position of its zero.

Everything here is pure computation except :func:`read_state`, :func:`write_state`, :func:`state_dir`
(reads the environment) and :class:`MachineLock`.

A missing file is a new machine: the tool at the home, position known, not homed, every offset zero.
"""
from __future__ import annotations

import datetime
import json
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Optional

try:
    import fcntl
except ImportError:  # pragma: no cover - not a POSIX system: no lock (one command at a time is the user's care)
    fcntl = None  # type: ignore[assignment]

from ..errors import BusyError, CamError, TravelError
from ..fileio import atomic_write_text
from ..settings import MachineSettings

__all__ = [
    "STATE_VERSION", "OFFSET_NAMES", "MachineState", "Running", "StateError", "StateBusyError",
    "PositionUnknownError", "parse_state", "read_state", "write_state", "state_dir", "default_state_path",
    "mm_to_steps", "steps_to_mm", "check_in_travel", "MachineLock", "StateHold", "unknown_message", "dump_json",
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
    """Another command drives the machine (the message names its process)."""


class PositionUnknownError(CamError):
    """The machine position is not known: a move needs homing or ``cam where --set`` first."""


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
    """

    position_steps: Steps3 = (0, 0, 0)
    position_known: bool = True
    unknown_reason: str = ""
    homed: bool = False
    offsets_steps: Mapping[str, Steps3] = field(default_factory=_zero_offsets)
    active_offset: str = "G54"
    tool: Optional[str] = None
    running: Optional[Running] = None

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
        }
        return dump_json(values)


def dump_json(values: Mapping[str, Any]) -> str:
    """An object as JSON text, one key a line, each value (a list, an object of lists) on its line."""
    lines = [f"  {json.dumps(k)}: {json.dumps(v, separators=(', ', ': '))}" for k, v in values.items()]
    return "{\n" + ",\n".join(lines) + "\n}\n"


# -- reading and checking ------------------------------------------------------------------------------------

_KEYS = {"cam_machine_state", "position_steps", "position_known", "unknown_reason", "homed", "offsets_steps",
         "active_offset", "tool", "running"}


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
    unknown = sorted(set(values) - _KEYS)
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
                        _running(values["running"]))


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


def read_state(path: str | os.PathLike, settings: MachineSettings) -> MachineState:
    """The state in ``path`` (a missing file: a new machine, :class:`MachineState`'s defaults).

    Raises:
        StateError: the file cannot be read or is broken.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        return MachineState()
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


def unknown_message(state: MachineState) -> str:
    """The one-line error of a move asked for while the position is unknown."""
    return (f"the machine position is unknown ({state.unknown_reason or 'not recorded'}): home the machine "
            f"(cam home) or say where the tool is, in machine mm, with cam where --set X,Y,Z")


# -- where the file is ---------------------------------------------------------------------------------------

def state_dir(environ: Optional[Mapping[str, str]] = None) -> Path:
    """The user's state folder for `cam`: ``$XDG_STATE_HOME/cam``, else ``~/.local/state/cam``."""
    env = os.environ if environ is None else environ
    base = env.get("XDG_STATE_HOME") or ""
    if not os.path.isabs(base):  # the XDG rule: a relative path is ignored
        base = os.path.join(os.path.expanduser("~"), ".local", "state")
    return Path(base) / "cam"


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._]+", "-", text).strip("-.") or "port"


def default_state_path(machine_file: Optional[str], port: str,
                       environ: Optional[Mapping[str, str]] = None) -> Path:
    """The default state file of a machine: ``{state_dir}/{machine file's stem, or "default"}-{port}.json``.

    >>> default_state_path(None, "mock", {"XDG_STATE_HOME": "/s"}).as_posix()
    '/s/cam/default-mock.json'
    >>> default_state_path("shop/mill.toml", "maximus:/dev/ttyUSB0", {"XDG_STATE_HOME": "/s"}).name
    'mill-maximus-dev-ttyUSB0.json'
    """
    machine = _slug(Path(machine_file).stem) if machine_file else "default"
    return state_dir(environ) / f"{machine}-{_slug(str(port))}.json"


# -- units --------------------------------------------------------------------------------------------------

def mm_to_steps(xyz_mm: Any, settings: MachineSettings) -> Steps3:
    """``(x, y, z)`` mm as the nearest whole steps (same frame; +z deeper)."""
    per = (settings.mm_per_step_xy, settings.mm_per_step_xy, settings.mm_per_step_z)
    return tuple(int(round(float(v) / p)) for v, p in zip(xyz_mm, per))  # type: ignore[return-value]


def steps_to_mm(xyz_steps: Any, settings: MachineSettings) -> tuple[float, float, float]:
    """``(x, y, z)`` steps in mm, rounded to 0.1 um (same frame; +z deeper)."""
    per = (settings.mm_per_step_xy, settings.mm_per_step_xy, settings.mm_per_step_z)
    return tuple(round(int(v) * p, 4) for v, p in zip(xyz_steps, per))  # type: ignore[return-value]


# -- the lock -----------------------------------------------------------------------------------------------

class MachineLock:
    """The lock that lets one command at a time drive a machine: ``flock`` on ``STATE.lock`` beside the state
    file, which holds the holder's process id.  The kernel releases it when the process ends, however.

    Args:
        state_path: the state file (the lock file is its name plus ``.lock``).
    """

    def __init__(self, state_path: str | os.PathLike) -> None:
        self.state_path = Path(state_path)
        self.path = self.state_path.with_name(self.state_path.name + ".lock")
        self._fd: Optional[int] = None

    def _open(self) -> int:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            return os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as exc:
            raise StateError(f"machine state file {self.state_path}: cannot open its lock {self.path} "
                             f"({exc.strerror or exc})") from None

    def holder(self) -> Optional[int]:
        """The process id that holds the lock now (0: one whose id is not written yet), or None when free."""
        if fcntl is None:
            return None
        fd = self._open()
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
                return int(text) if text.isdigit() else 0
            fcntl.flock(fd, fcntl.LOCK_UN)
            return None
        finally:
            os.close(fd)

    def acquire(self, what: str = "this command") -> None:
        """Take the lock, or refuse.

        Raises:
            StateBusyError: another process holds it (the message names its process id).
        """
        fd = self._open()
        if fcntl is None:
            self._fd = fd
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
            os.close(fd)
            pid = f"pid {text}" if text.isdigit() else "a process"
            raise StateBusyError(f"{what} refused: another cam command ({pid}) drives the machine of "
                                 f"{self.state_path}; try again when it has ended") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
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

    def __enter__(self) -> "MachineLock":
        self.acquire()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.release()


class StateHold:
    """A command's hold on a machine: the lock (taken here), and the state read under it.

    A ``running`` marker found under the lock was left by a command that ended without recording where the
    tool stopped (SIGKILL, a power cut): the position becomes unknown, and is written so at once.  Every
    position is in the machine frame.

    Args:
        path: the state file.
        settings: the machine's settings (its travel checks every number of the file).
        what: what the command is, for the message that refuses it while another one holds the lock.

    Raises:
        StateBusyError: another command holds the lock; StateError: the file is broken.
    """

    def __init__(self, path: str | os.PathLike, settings: MachineSettings, what: str = "this command") -> None:
        self.path = Path(path)
        self.settings = settings
        self.lock = MachineLock(self.path)
        self.lock.acquire(what)
        try:
            self.existed = self.path.exists()
            """Whether the file was there (False: a new machine, at the home by default)."""
            self.state = read_state(self.path, settings)
            r = self.state.running
            if r is not None:
                self.save(replace(self.state.lost(
                    f"cam (pid {r.pid}: {r.command}) drove the machine from {r.since} and ended without recording "
                    f"where the tool stopped: killed, or a power cut"), running=None))
        except BaseException:
            self.lock.release()
            raise

    def require_known(self) -> None:
        """Refuse a move while the position is unknown (:class:`PositionUnknownError`, one line)."""
        if not self.state.position_known:
            raise PositionUnknownError(unknown_message(self.state))

    def save(self, state: MachineState) -> None:
        """Write ``state`` and keep it as the current one."""
        write_state(self.path, state)
        self.state = state

    def mark_running(self, command: str) -> None:
        """This process drives the machine from now on (the marker a killed command leaves behind)."""
        self.save(replace(self.state, running=Running(os.getpid(), command[:MAX_TEXT], now_text())))

    def record(self, state: MachineState) -> None:
        """Where the command left the machine: ``state`` without the running marker."""
        self.save(replace(state, running=None))

    def close(self) -> None:
        """Let the lock go (a running marker never recorded stays: the next command treats the position as
        unknown)."""
        self.lock.release()

    def __enter__(self) -> "StateHold":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
