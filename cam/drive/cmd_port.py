"""Command-byte ports: a control unit that takes one byte per step instead of step/dir pins (issue #45 point 2).

Seed 004 section 3.5: the standalone controller drives the CNC machine's control unit with *commands* on the
parallel port.  Each step of an axis is one data byte (``#define X_INC (0x4B)``: one step in +X, 0.0254 mm)
latched by a strobe pulse, sent at the step's time by a timer interrupt; the step rate, ramps included, is
how fast the bytes come.  The machine file's ``[commands]`` table (:class:`cam.settings.Commands`) gives the
bytes.

`cam` plans every job as step/dir writes (:mod:`cam.motion.steps`); here those writes become command writes,
a pure translation (:func:`step_writes_to_commands`):

* every rising clock edge of an axis in a step/dir write (a clock bit high in this write, low in the one
  before, :func:`cam.pins.axis_bits`) is that axis's command byte: ``<axis>_plus`` with the axis's
  direction bit high in the write (a step toward + of the machine frame, +Z deeper), ``<axis>_minus`` with
  it low;
* the byte is written with strobe 1 at the write's time, and strobe goes back to 0 ``strobe_us`` later (the
  data held); several axes stepping in one write go X, then Y, then Z, each ``byte_gap_us`` after the one
  before.  No byte goes sooner than ``byte_gap_us`` after the byte before it (a byte due sooner waits:
  every later byte moves with it);
* writes with no rising clock edge (the clock-low half of a step, a direction change) send nothing.

So a command pin log's row pairs are ``(t, byte, 1), (t + strobe, byte, 0)``.  :func:`cam.verify.command_log.
commands_to_step_log` reads one back into step/dir writes that :func:`cam.verify.pinlog.decode_pin_log`
decodes into the same motion.

Ports: :class:`CommandMockPort` (the mock: its pin log holds the command writes) and
:class:`CommandParallelPort` (a real parallel port: byte, strobe high, ``strobe_us`` busy-wait, strobe low).
Both send ``[commands] init`` (when declared) once, before the first byte.  Before a job runs,
:func:`check_commands` refuses one that needs a byte the machine file does not declare, and
:func:`check_command_timing` a machine whose fastest step is too short for three bytes.
"""
from __future__ import annotations

import time
from typing import Any, Iterable, Optional

import numpy as np

from ..errors import CapabilityError, PortError
from ..settings import MachineSettings
from ..pins import axis_bits
from .ports import MockPort, ParallelPort

__all__ = ["step_writes_to_commands", "CommandMockPort", "CommandParallelPort", "needed_commands", "check_commands",
           "check_command_timing", "STEP_KEYS"]

STEP_KEYS = (("x_plus", "x_minus"), ("y_plus", "y_minus"), ("z_plus", "z_minus"))
"""The ``[commands]`` keys of a step of X, Y, Z toward + and toward -."""

_AXIS_NAMES = "XYZ"


def _ns(us: float) -> int:
    return int(round(us * 1000.0))


def _undeclared(key: str, why: str, others: str = "") -> CapabilityError:
    return CapabilityError(f"[commands] {key} is not declared{others}: {why} (give the control unit's byte for it in the "
                           f"machine file's [commands] table)")


def _step_bytes(settings: MachineSettings) -> np.ndarray:
    """``(3, 2)`` int64: the byte of a step of X, Y, Z toward - (column 0) and toward + (column 1); -1: none."""
    c = settings.commands
    return np.array([[getattr(c, minus), getattr(c, plus)] for plus, minus in STEP_KEYS], np.int64)


def step_writes_to_commands(t_ns: np.ndarray, data: np.ndarray, strobe: np.ndarray, prev_data: int,
                            settings: MachineSettings, *, after_ns: Optional[int] = None
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The command writes of a stretch of step/dir writes (the module docstring gives the rules).

    Args:
        t_ns: ``(M,)`` int64 time of each step/dir write (ns), ascending.
        data: ``(M,)`` uint8 data register of each write (``settings.pins``' clock and direction bits).
        strobe: ``(M,)`` the step/dir writes' pin 1 (half/full step): not used, the strobe is the commands'.
        prev_data: the data register before the first write (0 at the start of a job): a stretch translated
            after another gives the last data of that one, so a job translated chunk by chunk gives the same
            writes as translated whole.
        settings: ``pins`` (which bits are clocks and directions) and ``commands`` (bytes, strobe, gap).
        after_ns: the time of the last command byte sent before this stretch (None: none): the first byte
            here goes no sooner than ``byte_gap_us`` after it.

    Returns:
        ``(t_ns, data, strobe)``: ``(2B,)`` int64, uint8, uint8 for the ``B`` command bytes: each byte's write
        with strobe 1, then the same byte with strobe 0 ``strobe_us`` later.

    Raises:
        CapabilityError: a step needs a byte ``[commands]`` does not declare (the message names the key).

    >>> from cam.settings import MachineSettings, Commands
    >>> s = MachineSettings(commands=Commands(x_plus=0x4B, y_plus=0x4C))
    >>> clock, dirbit = axis_bits(s)          # X and Y step toward + at 1 ms: two bytes, 20 us apart
    >>> d = np.array([clock[0] | clock[1] | dirbit[0] | dirbit[1], dirbit[0] | dirbit[1]], np.uint8)
    >>> t, b, st = step_writes_to_commands(np.array([1_000_000, 2_000_000]), d, np.zeros(2, np.uint8), 0, s)
    >>> t.tolist(), [hex(v) for v in b], st.tolist()
    ([1000000, 1010000, 1020000, 1030000], ['0x4b', '0x4b', '0x4c', '0x4c'], [1, 0, 1, 0])
    """
    t_ns = np.asarray(t_ns, np.int64)
    d = np.asarray(data, np.uint8)
    if len(t_ns) != len(d):
        raise ValueError(f"t_ns and data differ in length ({len(t_ns)} and {len(d)})")
    clock, dirbit = axis_bits(settings)
    clocks = np.uint8(np.bitwise_or.reduce(clock))
    prev = np.empty_like(d)
    if len(d):
        prev[0] = np.uint8(int(prev_data) & 0xFF)
        prev[1:] = d[:-1]
    rising = d & ~prev & clocks
    at = np.flatnonzero(rising)
    if not len(at):
        return np.zeros(0, np.int64), np.zeros(0, np.uint8), np.zeros(0, np.uint8)
    steps = (rising[at, None] & clock[None, :]) != 0  # (K, 3): the axes stepping in each write with an edge
    plus = (d[at, None] & dirbit[None, :]) != 0  # (K, 3): toward +
    table = _step_bytes(settings)
    codes = table[np.arange(3)[None, :], plus.astype(np.int64)]  # (K, 3) the byte each axis would send
    missing = steps & (codes < 0)
    if missing.any():
        k, a = np.argwhere(missing)[0]
        key = STEP_KEYS[a][0 if plus[k, a] else 1]
        raise _undeclared(key, f"the job steps toward {'+' if plus[k, a] else '-'}{_AXIS_NAMES[a]}")
    gap_ns, strobe_ns = _ns(settings.commands.byte_gap_us), _ns(settings.commands.strobe_us)
    order = np.cumsum(steps, axis=1) - 1  # X, then Y, then Z within a write
    due = (t_ns[at, None] + order * gap_ns)[steps]  # (B,) each byte's time, row-major: write by write, x y z
    byte = codes[steps].astype(np.uint8)
    # no byte sooner than gap_ns after the one before: t'_i = max(due_i, t'_{i-1} + gap), i.e.
    # t'_i = i * gap + max_{j <= i}(due_j - j * gap), the last byte before this stretch (after_ns) as j = -1
    idx = np.arange(len(due), dtype=np.int64) * gap_ns
    lead = due - idx
    if after_ns is not None:
        np.maximum(lead, int(after_ns) + gap_ns, out=lead)  # (after_ns + gap) - 0 * gap: the j = -1 term
    sent = np.maximum.accumulate(lead) + idx
    n = len(sent)
    out_t = np.empty(2 * n, np.int64)
    out_t[0::2], out_t[1::2] = sent, sent + strobe_ns
    out_d = np.repeat(byte, 2)
    out_s = np.tile(np.array([1, 0], np.uint8), n)
    return out_t, out_d, out_s


class _Translator:
    """What a command port keeps from call to call: the last step/dir data, the last byte's time, whether the
    ``init`` byte went."""

    def __init__(self, settings: MachineSettings) -> None:
        self.settings = settings
        clock, _ = axis_bits(settings)
        self.clocks = int(np.bitwise_or.reduce(clock))
        self.last_data = 0
        self.last_byte_ns: Optional[int] = None  # the port's own time line
        self.init = settings.commands.init
        self.init_sent = settings.commands.init < 0

    def translate(self, t_ns: np.ndarray, data: np.ndarray, offset_ns: int = 0
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The command writes of these step/dir writes, times in the caller's frame (``offset_ns`` added to
        them makes the port's), the ``init`` byte first when it has not gone yet."""
        pre_t: list[int] = []
        if not self.init_sent and len(t_ns):
            t0 = int(t_ns[0])
            pre_t = [t0, t0 + _ns(self.settings.commands.strobe_us)]
            self.init_sent = True
            self.last_byte_ns = t0 + offset_ns
        after = None if self.last_byte_ns is None else self.last_byte_ns - offset_ns
        t, d, s = step_writes_to_commands(t_ns, data, np.zeros(0, np.uint8), self.last_data, self.settings,
                                          after_ns=after)
        if len(data):
            self.last_data = int(data[-1])
        if len(t):
            self.last_byte_ns = int(t[-2]) + offset_ns
        if pre_t:
            t = np.concatenate([np.array(pre_t, np.int64), t])
            d = np.concatenate([np.array([self.init, self.init], np.uint8), d])
            s = np.concatenate([np.array([1, 0], np.uint8), s])
        return t, d, s

    def quiet(self, data: int) -> bool:
        """Whether one write ``data`` sends nothing (no rising clock edge, the init byte gone): noted if so."""
        if self.init_sent and not (data & ~self.last_data & self.clocks):
            self.last_data = data
            return True
        return False


class CommandMockPort(MockPort):
    """The mock port of a command-byte control unit: its pin log holds the command writes
    (:func:`step_writes_to_commands`), not the step/dir writes it is given.

    Args:
        settings: the machine settings (``pins`` of the writes it is given, ``commands``).
        **mockport_kwargs: as :class:`~cam.drive.ports.MockPort` (``pin_log_path``, ``keep_log``); no
            ``switches``: a command port reads no inputs.

    Raises:
        CapabilityError: ``switches`` given; a write needs a byte ``[commands]`` does not declare.
    """

    name = "cmd:mock"
    backend = "cmd"
    """The back end that owns this port (:mod:`cam.drive.machines`)."""

    def __init__(self, settings: MachineSettings, **mockport_kwargs: Any) -> None:
        if mockport_kwargs.get("switches") is not None:
            raise CapabilityError("a command port reads no switches: its control unit takes bytes and answers "
                                  "nothing (run without the mock's simulated switches)")
        mockport_kwargs.pop("switches", None)
        super().__init__(**mockport_kwargs)
        self.settings = settings
        self._commands = _Translator(settings)

    @property
    def reads_inputs(self) -> bool:
        return False

    def write(self, data: int, strobe: int, t_ns: int) -> None:
        if self._commands.quiet(int(data)):
            return
        t, d, s = self._commands.translate(np.array([int(t_ns)], np.int64), np.array([int(data)], np.uint8),
                                           self.time_offset_ns)
        for ti, di, si in zip(t.tolist(), d.tolist(), s.tolist()):
            super().write(di, si, ti)

    def write_many(self, t_ns: np.ndarray, data: np.ndarray, strobe: np.ndarray) -> None:
        t, d, s = self._commands.translate(np.asarray(t_ns, np.int64), np.asarray(data, np.uint8),
                                           self.time_offset_ns)
        super().write_many(t, d, s)


class CommandParallelPort(ParallelPort):
    """A command-byte control unit on a real parallel port (pyparallel, as :class:`~cam.drive.ports.ParallelPort`).

    Each command byte goes out as the seed's controller sends it: the data register, strobe high, a busy-wait
    of ``strobe_us``, strobe low; a byte waits until ``byte_gap_us`` after the one before.  The real-time
    runner calls :meth:`write` at each step/dir write's time, so the bytes go at the steps' times; a batch
    (:meth:`write_many`) goes out at once, byte after byte.

    Args:
        device: the port, e.g. ``/dev/parport0`` (its name is then ``cmd:/dev/parport0``).
        settings: the machine settings (``pins`` of the writes it is given, ``commands``).

    Raises:
        PortError: the port cannot be opened (as :class:`~cam.drive.ports.ParallelPort`).
    """

    backend = "cmd"

    def __init__(self, device: str, settings: MachineSettings) -> None:
        super().__init__(device)
        self.name = f"cmd:{device}"
        self.settings = settings
        self._commands = _Translator(settings)
        self._strobe_ns = _ns(settings.commands.strobe_us)
        self._gap_ns = _ns(settings.commands.byte_gap_us)
        self._last_wall_ns: Optional[int] = None

    @property
    def reads_inputs(self) -> bool:
        return False

    def write(self, data: int, strobe: int, t_ns: int) -> None:
        if self._commands.quiet(int(data)):
            return
        _, d, _ = self._commands.translate(np.array([int(t_ns)], np.int64), np.array([int(data)], np.uint8))
        self._send(d[0::2].tolist())

    def write_many(self, t_ns: np.ndarray, data: np.ndarray, strobe: np.ndarray) -> None:
        _, d, _ = self._commands.translate(np.asarray(t_ns, np.int64), np.asarray(data, np.uint8))
        self._send(d[0::2].tolist())

    def _send(self, command_bytes: Iterable[int]) -> None:
        port = self._port
        try:
            for byte in command_bytes:
                if self._last_wall_ns is not None:
                    _spin_until(self._last_wall_ns + self._gap_ns)
                port.setData(int(byte))
                port.setDataStrobe(1)
                began = self._last_wall_ns = time.monotonic_ns()
                _spin_until(began + self._strobe_ns)
                port.setDataStrobe(0)
        except OSError as exc:  # pragma: no cover - hardware
            raise PortError(f"{self.name}: write failed ({exc.strerror or exc})") from None


def _spin_until(wall_ns: int) -> None:
    """Busy-wait until ``time.monotonic_ns()`` reaches ``wall_ns`` (tens of microseconds: no sleep is that fine)."""
    while time.monotonic_ns() < wall_ns:
        pass


def needed_commands(points_steps: np.ndarray, *, from_steps: Optional[np.ndarray] = None) -> set[str]:
    """The step commands (``x_plus`` .. ``z_minus``) moves through these points need.

    Args:
        points_steps: ``(N, 3)`` int positions (x, y, z) in machine steps (+Z deeper), in the order the tool
            goes through them.
        from_steps: ``(3,)`` where the tool stands before the first point, in the points' frame (None: the moves
            between the points alone).

    >>> sorted(needed_commands(np.array([[0, 0, 0], [5, 0, 2], [3, 4, 2]])))
    ['x_minus', 'x_plus', 'y_plus', 'z_plus']
    """
    pts = np.asarray(points_steps, np.int64).reshape(-1, 3)
    if from_steps is not None:
        pts = np.concatenate([np.asarray(from_steps, np.int64).reshape(1, 3), pts])
    if len(pts) < 2:
        return set()
    diff = np.diff(pts, axis=0)
    up, down = (diff > 0).any(axis=0), (diff < 0).any(axis=0)
    return {key for a in range(3) for key, used in zip(STEP_KEYS[a], (up[a], down[a])) if used}


def check_commands(job_or_pieces: Any, settings: MachineSettings, *,
                   start_steps: Optional[tuple[int, int, int]] = None) -> None:
    """Refuse, before anything moves, a job that needs a command ``[commands]`` does not declare.

    ``job_or_pieces``: a :class:`~cam.job.model.JobLike` (its :meth:`pieces`, one at a time: bounded memory),
    an iterable of pieces (each with ``points_steps``) or an ``(N, 3)`` array of points.  The tool starts at
    the job's home (0, 0, 0).  A job that goes deeper needs ``z_minus`` too: a stop lifts the tool.

    ``start_steps``: where the tool stands in the machine frame when the job starts (as
    :func:`~cam.motion.chunks.plan_chunks` takes it).  The job's points are steps from there, so it changes no
    byte the job needs; it is not read.

    Raises:
        CapabilityError: one line naming the first undeclared key (and any others).
    """
    if hasattr(job_or_pieces, "pieces"):
        pieces: Iterable[Any] = job_or_pieces.pieces()
    elif isinstance(job_or_pieces, np.ndarray):
        pieces = [job_or_pieces]
    else:
        pieces = job_or_pieces
    needed: set[str] = set()
    last = np.zeros(3, np.int64)
    for piece in pieces:
        pts = np.asarray(getattr(piece, "points_steps", piece), np.int64).reshape(-1, 3)
        if not len(pts):
            continue
        needed |= needed_commands(pts, from_steps=last)
        last = pts[-1]
    stepped = set(needed)
    if "z_plus" in needed:
        needed.add("z_minus")  # a stop lifts the tool out of the material
    declared = settings.commands.declared()
    missing = [key for plus_minus in STEP_KEYS for key in plus_minus if key in needed and key not in declared]
    if missing:
        key = missing[0]
        others = f" (nor {', '.join(missing[1:])})" if len(missing) > 1 else ""
        sign, axis = ("+" if key.endswith("plus") else "-"), key[0].upper()
        why = f"the job steps toward {sign}{axis}" if key in stepped else "a stop lifts the tool out of the cut"
        raise _undeclared(key, why, others)


def check_command_timing(settings: MachineSettings) -> None:
    """Refuse a machine whose fastest step is shorter than three command bytes (every axis stepping at once):
    ``3 * byte_gap_us + strobe_us``.

    The fastest step of an axis is ``mm_per_step / speed`` at its top speed: ``max_speed_*_mm_s``, or one step
    per step delay (``delay_xy_ms``, ``delay_z_ms``) where that is faster (the ``constant`` ramp mode).

    Raises:
        CapabilityError: one line naming the axis, its step period and the time the bytes need.
    """
    c = settings.commands
    need_us = 3 * c.byte_gap_us + c.strobe_us
    s_mm, _, v_max, _ = settings.axis_limits()
    delays_s = (settings.delay_xy_ms / 1e3, settings.delay_xy_ms / 1e3, settings.delay_z_ms / 1e3)
    for a in range(3):
        by_delay = s_mm[a] / delays_s[a] if settings.ramp == "constant" else 0.0
        v = max(v_max[a], by_delay)
        period_us = s_mm[a] / v * 1e6
        if period_us < need_us:
            a_name = "xyz"[a]
            where = f"max_speed_{a_name}_mm_s = {v_max[a]:g}" if v == v_max[a] else \
                f"one step per {'delay_z_ms' if a == 2 else 'delay_xy_ms'}, {v:.4g} mm/s"
            raise CapabilityError(
                f"[commands] {_AXIS_NAMES[a]} steps every {period_us:.4g} us at its top speed ({where}), sooner "
                f"than three command bytes take (3 x byte_gap_us + strobe_us = {need_us:g} us): lower the speed "
                f"or the byte gap")
