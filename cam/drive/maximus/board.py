"""The host side of the MAXIMUS drilling machine's RS-232 protocol.

:class:`MaximusBoard` talks to the PIC firmware listed in seed 000 Appendix 1
(or to :mod:`cam.sim.maximus`, which behaves byte for byte like
it) at 115200 baud, 8N1.  Packets are built by pure functions
(:func:`jog_packet`, :func:`offset_packet`, :func:`init_packet`,
:func:`drill_packet`, ... in :mod:`.packets`, also importable from here); the board object only sends them and checks the
one-byte replies.  All step fields are L297 clock pulses (half steps when a
mode bit is set), 16-bit, low byte first.  The machine's settings (Delay bytes,
step modes, inverted axes, the reply margin) are a :class:`~cam.settings.Maximus`.

Directions (the board's frame): X and Y steps are positive when the
firmware's DIR bit is 1 (the PC program's "X right" and "Y up", away from the
HOME switches); Z is height, positive up (DIR_Z = 1 is "Z down" in the
listing).  `cam`'s machine frame has y toward the operator and z deeper:
:func:`to_board` and :func:`from_board` convert.

Open with a device path or a URL: ``MaximusBoard("/dev/ttyUSB0")`` or
:func:`open_maximus` ``("maximus:/dev/ttyUSB0")``.

Safety rules kept by every method:

* every reply is awaited for as long as the move it answers takes at the
  board's Delay settings, plus what a limit switch would add, plus a margin
  (``timeout_s``): a long move never times out, a dead board is found soon;
* a reply that comes sooner than its move could have ended, any byte the
  host did not ask for, a wrong reply or none in time is a link fault
  (:class:`LinkFault`, :mod:`.trust`): nothing more is sent, not even the
  stop byte (the firmware may hold part of a packet that any byte would
  complete into a move), the firmware's state and the head's position are
  unknown, and every later call fails until :meth:`MaximusBoard.handshake`
  succeeds again (after the board is switched off and on); the fault leaves
  a marker file (:func:`~.trust.fault_marker`) and no handshake sends a
  byte on that device while it stands;
* a limit switch or an emergency stop ends the job with a one-line
  ``PortError`` naming the hole (numbered from 1) and the last known position; the
  spindle is switched off and the firmware is back at mode selection;
* the spindle (RB2) runs only while Drill mode drills; it is off for tool
  changes, jogs, travel, at the end and after every stop.
"""
from __future__ import annotations

import os
import threading
import time
from contextlib import AbstractContextManager
from dataclasses import replace
from functools import partial
from typing import Any, Callable, Optional, Sequence

import numpy as np
import serial

from ...errors import CapabilityError, PlanError, PortError, SettingsError
from ...settings import DEFAULT_SETTINGS, MachineSettings, Maximus, Travel
from ._drill import _Drilling, drill_job
from .trust import LinkFault, emulator_speed
from ._link import _CLOSE_DRILL, _DRILL, _INIT, _JOG, _MODE, _OFFSET, _UNKNOWN, _Exchange, _Link
from .packets import (
    MAX_FIELD, close_drill_packet, drill_directions, drill_moved, drill_moves, drill_packet, drill_time_ns, init_packet,
    jog_exit_packet, jog_packet, jog_time_ns, offset_packet, start_drill_packet,
)
from .protocol import (
    ATOFFSETPOS, BANNER, DELAY_UNIT_NS, DRILLMODE1INITIALIZED, DRILLMODE1ON, ISMACHINEREADY,
    JOGMODEDONE, JOGMODEON, MACHINEREADY, ONEHOLEDRILLED, OPENDRILLMODE1, OPENJOGMODE,
)

__all__ = [
    "MaximusBoard", "LinkFault", "open_maximus", "URL_PREFIX", "MAXIMUS_SETTINGS", "maximus_holes", "drill_arguments",
    "board_settings", "board_speeds_line", "with_delays", "maximus_port", "to_board", "from_board", "drill_stroke", "drill_job",
    "jog_packet", "jog_exit_packet", "offset_packet", "init_packet", "start_drill_packet",
    "drill_packet", "close_drill_packet", "drill_moves", "require_drilling",
]

URL_PREFIX = "maximus:"

MAXIMUS_SETTINGS = DEFAULT_SETTINGS.replace(
    # one L297 clock pulse moves an axis by the "theoretical resolution of 4.375 microns" of seed 000
    # section 9 (12 mm lead screws, section 3; half steps, as the MODE bits select)
    mm_per_step_xy=0.004375,
    mm_per_step_z=0.004375,
    half_step=True,
    # the board moves at constant speed, a pulse every 2 * Delay * 100 us (seed 003): Delay 10 = 2 ms
    ramp="constant",
    delay_xy_ms=2.0,
    delay_z_ms=2.0,
    # the protocol's step fields are 16 bits (seed 000 Appendix 1, make16): no move beyond 65535 pulses; the
    # board has no travel of its own but its limit switches, so a job may reach that far from the origin either
    # way (holes measured from the board origin, as the PC program measures them, lie at y <= 0: Y up)
    travel=Travel(x_min_steps=-MAX_FIELD, x_max_steps=MAX_FIELD, y_min_steps=-MAX_FIELD, y_max_steps=MAX_FIELD,
                  z_min_steps=-MAX_FIELD, z_max_steps=MAX_FIELD),
)
"""The MAXIMUS machine: one "step" is one L297 clock pulse (a half step)."""

_DELAY_MS = 2 * DELAY_UNIT_NS / 1e6
"""The step period of one Delay unit in ms: a pulse lasts 2 * Delay * 100 us (seed 003)."""


def board_settings(settings: MachineSettings) -> MachineSettings:
    """``settings`` with the step periods and ramp that the board's Delay bytes give, so that planned times
    (progress, reports) are the board's: constant speed, ``2 * Delay * 0.1 ms`` per pulse; and one step per
    clock pulse of each axis (issue #45 point 5): its ``[maximus]`` mm per full step, halved in half-step mode
    (:meth:`~cam.settings.Maximus.mm_per_pulse`; X and Y may differ).

    Raises:
        SettingsError: a machine file's ``mm_per_step_xy`` / ``mm_per_step_z`` that says otherwise.
    """
    m = settings.maximus
    x, y, z = m.mm_per_pulse()
    for key, given, axes in (("mm_per_step_xy", settings.mm_per_step_xy, ((x, "x"), (y, "y"))),
                             ("mm_per_step_z", settings.mm_per_step_z, ((z, "z"),))):
        if given != MAXIMUS_SETTINGS.mm_per_step_xy and any(abs(given - v) > 1e-12 for v, _ in axes):
            raise SettingsError(f"{key} = {given:g}: on the MAXIMUS board a step is one clock pulse, "
                                + ", ".join(f"{a.upper()} {v:g} mm" for v, a in axes)
                                + " from [maximus] mm_per_full_step_* and half_step_*: set those instead")
    return settings.replace(ramp="constant", delay_xy_ms=round(_DELAY_MS * max(m.delay_x, m.delay_y), 6),
                            delay_z_ms=round(_DELAY_MS * max(m.delay_z_up, m.delay_z_down), 6),
                            mm_per_step_xy=x, mm_per_step_y=0.0 if y == x else y, mm_per_step_z=z)


def board_speeds_line(settings: MachineSettings) -> str:
    """One line: the board's feed of each axis, from its ``[maximus]`` Delay bytes and step modes (constant speed, a
    pulse every ``2 * Delay * 0.1 ms``, seed 003), what ``cam info --port maximus:...`` shows.

    >>> board_speeds_line(MAXIMUS_SETTINGS)[:60]
    'MAXIMUS board speeds (its Delay bytes, constant, no ramps): '
    """
    m = settings.maximus
    x, y, z = m.mm_per_pulse()
    parts = []
    for name, delay, mm, half in (("X", m.delay_x, x, m.half_step_x), ("Y", m.delay_y, y, m.half_step_y),
                                  ("Z up", m.delay_z_up, z, m.half_step_z), ("Z down", m.delay_z_down, z, m.half_step_z)):
        period_ms = _DELAY_MS * delay
        parts.append(f"{name} {mm / period_ms * 1000:.3g} mm/s (Delay {delay}: a pulse every {period_ms:g} ms, "
                     f"{'half' if half else 'full'} steps of {mm:g} mm)")
    return "MAXIMUS board speeds (its Delay bytes, constant, no ramps): " + ", ".join(parts)


def with_delays(settings: MachineSettings, xy_ms: float, z_ms: float) -> MachineSettings:
    """``--delay XY_MS,Z_MS`` on the board: the step periods set its Delay bytes (Delay = period / 0.2 ms,
    seed 003 "Step frekansı = 1 / (2 * Delay * 100 us)"): X and Y from ``xy_ms``, Z up and down from ``z_ms``.

    >>> m = with_delays(MAXIMUS_SETTINGS, 1.0, 4.0).maximus
    >>> m.delay_x, m.delay_y, m.delay_z_up, m.delay_z_down
    (5, 5, 20, 20)

    Raises:
        SettingsError: a period that no Delay byte 1..255 gives (0.2 .. 51 ms).
    """
    delays = []
    for what, ms in (("XY", xy_ms), ("Z", z_ms)):
        d = int(round(ms / _DELAY_MS))
        if not 1 <= d <= 255:
            raise SettingsError(f"--delay {what} {ms:g} ms: the MAXIMUS board's step period is 2 x Delay x 0.1 ms "
                                f"with Delay 1..255, so {_DELAY_MS:g}..{255 * _DELAY_MS:g} ms")
        delays.append(d)
    m = replace(settings.maximus, delay_x=delays[0], delay_y=delays[0], delay_z_up=delays[1], delay_z_down=delays[1])
    return board_settings(settings.replace(maximus=m))


def maximus_port(name: str, settings: MachineSettings) -> str:
    """The port name to open: ``"maximus"`` alone names the machine settings' serial port."""
    if name != URL_PREFIX.rstrip(":"):
        return name
    if not settings.maximus.serial_port:
        raise PortError("--port maximus needs a device: maximus:/dev/ttyUSB0, or serial_port in the [maximus] "
                        "table of the machine file")
    return URL_PREFIX + settings.maximus.serial_port


def to_board(moves_steps: np.ndarray) -> np.ndarray:
    """``(N, 3)`` moves in `cam`'s machine frame (y toward the operator, z deeper) in the board's
    (y up, z height): y and z change sign.

    >>> to_board(np.array([[1, 2, 3]])).tolist()
    [[1, -2, -3]]
    """
    out = np.asarray(moves_steps, np.int64).reshape(-1, 3).copy()
    out[:, 1:] = -out[:, 1:]
    return out


from_board = to_board
"""The board's frame back to `cam`'s (the same sign change)."""


def maximus_holes(holes_steps: np.ndarray) -> np.ndarray:
    """Holes of a drill plan in the board's own pulses: ``(N, 2)`` int64 (x, y) with y up.

    :func:`cam.job.drill.plan_drill` gives machine (x, y) with y toward the operator (image rows,
    y = -Y of the drill file); the firmware counts Y up (DIR_Y = 1 is "Y up" in the PC program of
    seed 000 Appendix 2), so y changes sign and the board keeps its handedness.
    """
    xy = np.asarray(holes_steps, np.int64).copy()
    xy[:, 1] = -xy[:, 1]
    return xy


def drill_stroke(drill_plan: Any, settings: MachineSettings) -> tuple[int, int]:
    """(Z Drill Up, Z Drill Down) in pulses below the board origin for a drill plan: the machine settings'
    when they set them, else the origin is the travel height (Z up 0) and a hole goes down the travel height
    and the cut depth."""
    m = settings.maximus
    if m.drill_stroke_set:
        return m.drill_z_up_steps, m.drill_z_down_steps
    return 0, int(drill_plan.safe_steps) + int(drill_plan.depth_steps)


def drill_arguments(drill_plan: Any, settings: MachineSettings = MAXIMUS_SETTINGS) -> dict[str, Any]:
    """The :meth:`MaximusBoard.drill` arguments of a :class:`~cam.job.drill.DrillPlan` planned with ``settings``:
    holes in the board's pulses (:func:`maximus_holes`), the Z stroke (:func:`drill_stroke`), tool-change
    prompts and the spindle."""
    z_up, z_down = drill_stroke(drill_plan, settings)
    return {"holes_steps": maximus_holes(drill_plan.holes_steps), "z_up_steps": z_up, "z_down_steps": z_down,
            "tool_changes": drill_plan.tool_changes, "spindle": settings.maximus.spindle}


HANDSHAKE_S = 5.0
"""The least time the handshake waits for MACHINEREADY.  It is no move's margin (``timeout_s``, short so that a
board gone silent mid-job is found soon): the board answers in milliseconds, but a busy host or emulator may read
it late, and a short wait there refused a board that was answering."""


def open_maximus(url: str, settings: Optional[Maximus] = None, timeout_s: Optional[float] = None) -> "MaximusBoard":
    """Open ``maximus:/dev/ttyUSB0`` (or a bare device path) as a :class:`MaximusBoard`."""
    return MaximusBoard(url, settings, timeout_s=timeout_s)


def _why(exc: BaseException) -> str:
    """What the system said of a failed port call, in a few words (pyserial repeats the device name)."""
    code = getattr(exc, "errno", None)
    return os.strerror(code) if isinstance(code, int) and code > 0 else (str(exc) or type(exc).__name__)


class MaximusBoard(_Drilling, _Link, AbstractContextManager):
    """A MAXIMUS control board on a serial port.

    Args:
        url_or_device: ``"maximus:/dev/ttyUSB0"`` or ``"/dev/ttyUSB0"``.
        settings: the machine's :class:`~cam.settings.Maximus` settings (default: the PC program's defaults).
        timeout_s: the margin: how long after its move should have ended a reply may come (default
            ``settings.reply_margin_s``); also the wait for replies that end no move.
        handshake: do the ISMACHINEREADY / MACHINEREADY handshake now.

    Attributes:
        banner: ``"MAXIMUS_V1.0"`` if the power-up banner was seen, else None.
        position_pulses: ``(x, y, z)`` board-frame pulses (y up, z height) from where the board was opened, as
            far as confirmed replies tell.
        position_known: False after a link fault (:class:`~.trust.LinkFault`) or an unanswered stop: the head
            may have moved since ``position_pulses``.  After a stopped move ``position_pulses`` is an estimate
            from the time the move ran (the firmware does not say where it stopped), to the nearest whole pulse: a
            pulse the stop left half made is ended at once (``_Link._finish_pulses``), so no later move adds it.
        stop_asked: :meth:`emergency_stop` was called during the current (or last) job.
    """

    def __init__(self, url_or_device: str, settings: Optional[Maximus] = None, *, timeout_s: Optional[float] = None,
                 handshake: bool = True) -> None:
        device = url_or_device[len(URL_PREFIX):] if url_or_device.startswith(URL_PREFIX) else url_or_device
        if not device:
            raise PortError(f"no device in {url_or_device!r}; use maximus:/dev/ttyUSB0")
        self.maximus = settings or Maximus()
        timeout_s = self.maximus.reply_margin_s if timeout_s is None else timeout_s
        if not timeout_s > 0:
            raise PortError(f"timeout_s must be > 0, got {timeout_s!r}")
        self.device = device
        self.timeout_s = float(timeout_s)
        self.banner: str | None = None
        self.position_pulses: tuple[int, int, int] = (0, 0, 0)
        self.position_known = True
        self._time_scale = emulator_speed(device)
        self._send_start_s = time.monotonic()
        self._lock = threading.RLock()
        self._state = _UNKNOWN
        self._pending: _Exchange | None = None
        self._reader_active = False
        self._job_active = False
        self._stop_requested = False
        self._estop_sent = False
        self._estop_sent_s: Optional[float] = None  # the stop byte's write: the clock before it and after it
        self._estop_done_s = 0.0
        self.stop_asked = False
        self._stop_done = threading.Event()
        self._stop_error: PortError | None = None
        self._spindle_on: Optional[bool] = None  # unknown until a Jog packet sets it
        self._last_jog_delay: Optional[int] = None
        self._sent_s = time.monotonic()
        try:
            # seed 000 Appendix 1: "#use rs232(baud=115200, xmit=PIN_C6, rcv=PIN_C7)"; CCS default 8N1
            self._ser = serial.Serial(device, baudrate=self.maximus.baud, bytesize=8, parity="N", stopbits=1,
                                      timeout=self.timeout_s, write_timeout=self.timeout_s)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise PortError(f"cannot open MAXIMUS port {device} ({_why(exc)}): check that the board is plugged in "
                            "and switched on, the device name (ls /dev/ttyUSB* /dev/ttyACM* /dev/ttyS*) and that "
                            "you may use it (the dialout group)") from exc
        if handshake:
            try:
                self.handshake()
            except BaseException:
                self._ser.close()
                raise

    # ------------------------------------------------------------------ plumbing
    def close(self) -> None:
        """Close the serial port."""
        self._ser.close()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def in_step(self) -> bool:
        """False after an error that left the firmware in an unknown state."""
        return self._state != _UNKNOWN

    @property
    def spindle_on(self) -> Optional[bool]:
        """Whether the spindle runs, as the host last set it (None: not known yet)."""
        return self._spindle_on

    def _write(self, data: bytes) -> None:
        try:
            self._ser.write(data)
            self._ser.flush()
        except (serial.SerialException, OSError) as exc:
            self._state = _UNKNOWN
            raise self._port_lost("write to", exc) from exc

    def _read_byte(self, timeout_s: float | None = None) -> int | None:
        try:
            if timeout_s is not None:
                self._ser.timeout = timeout_s
            data = self._ser.read(1)
        except (serial.SerialException, OSError) as exc:
            self._state = _UNKNOWN
            raise self._port_lost("read from", exc) from exc
        finally:
            if timeout_s is not None:
                try:
                    self._ser.timeout = self.timeout_s
                except (serial.SerialException, OSError):  # a port gone: the read's error (or the next) says so
                    self._state = _UNKNOWN
        return data[0] if data else None

    def _port_lost(self, action: str, exc: BaseException) -> PortError:
        """The one-line error of a port that failed while open (unplugged, switched off)."""
        return PortError(f"cannot {action} MAXIMUS port {self.device} ({_why(exc)}): check the cable and that the "
                         "board is switched on; the head's position is unknown: jog it to the board origin again "
                         "before the next job")

    def _require(self, state: str) -> None:
        if self._state == _UNKNOWN:
            raise PortError("the MAXIMUS board is out of step after an earlier error; "
                            "reset the board, then call handshake()")
        if self._state != state:
            raise PortError(f"the MAXIMUS board is at {self._state}, not {state}")

    # ------------------------------------------------------------------ handshake
    def handshake(self) -> None:
        """Send ISMACHINEREADY and wait for MACHINEREADY, skipping the power-up banner.

        The firmware answers 0x61 with 0x62 at power-up and at mode selection
        (seed 000 Appendix 1, main()); anything else it may send first (the
        ``MAXIMUS_V1.0`` banner) is skipped.  Raises PortError if no
        MACHINEREADY arrives within ``timeout_s`` (at least :data:`HANDSHAKE_S`).
        """
        with self._lock:
            if self._pending is not None or self._job_active:
                raise PortError("cannot handshake while a MAXIMUS job is running")
            seen = bytearray()
            try:
                waiting = self._ser.in_waiting
                if waiting:
                    seen += self._ser.read(waiting)
            except (serial.SerialException, OSError) as exc:
                raise self._port_lost("read from", exc) from exc
            self._refuse_after_fault(bytes(seen))  # after a link fault: nothing until the board was reset
            self._write(bytes([ISMACHINEREADY]))
            wait_s = max(self.timeout_s, HANDSHAKE_S)
            deadline = time.monotonic() + wait_s
            while True:
                remaining = deadline - time.monotonic()
                b = self._read_byte(max(remaining, 0.001)) if remaining > 0 else None
                if b is None:
                    self._state = _UNKNOWN
                    raise PortError(f"MAXIMUS board on {self.device} did not answer ISMACHINEREADY (0x61) "
                                    f"within {wait_s:g} s; check the cable and reset the board")
                if b == MACHINEREADY:
                    break
                seen.append(b)
                if len(seen) > 256:
                    self._state = _UNKNOWN
                    raise PortError(f"MAXIMUS board on {self.device} sent {len(seen)} bytes but no MACHINEREADY")
            if BANNER in seen:
                self.banner = BANNER.decode("ascii")
            self._state = _MODE
            self._stop_requested = False

    # ------------------------------------------------------------------ packets of this machine
    def _jog(self, axis: str, pulses: int, *, spindle: bool = False, delay: Optional[int] = None) -> tuple[str, bytes]:
        """A Jog Data Packet of this machine (board frame; Z at the Z-up delay, as the PC program's Jog form)."""
        m = self.maximus
        i = "xyz".index(axis)
        if delay is None:
            # seed 000 Appendix 2, FormJog::FormActivate: "Initial Jog Delays are Machine Delays", Z at machineDelayZup
            delay = (m.delay_x, m.delay_y, m.delay_z_up)[i]
        packet = jog_packet(axis, pulses, delay=delay, half_step=(m.half_step_x, m.half_step_y, m.half_step_z)[i],
                            spindle=spindle, invert=(m.invert_x, m.invert_y, m.invert_z)[i])
        return f"jog {axis} {int(pulses)}", packet

    def _jog_exchange(self, what: str, packet: bytes, axis: str, pulses: int) -> None:
        moved = [0, 0, 0]
        moved["xyz".index(axis)] = int(pulses)
        self._exchange(packet, _Exchange(what, JOGMODEDONE, True, "jog", _JOG, jog_time_ns(packet),
                                         tuple(moved)))  # type: ignore[arg-type]
        self._spindle_on = bool(packet[0] & 1)

    def _jog_session(self, jogs: Sequence[tuple[str, int]], *, spindle: bool = False,
                     delay: Optional[int] = None) -> None:
        """OPENJOGMODE, one Jog Data Packet per (axis, pulses) (longer ones in 16-bit pieces), the exit packet."""
        self._exchange(bytes([OPENJOGMODE]), _Exchange("OPENJOGMODE", JOGMODEON, False, "jog", _JOG))
        for axis, pulses in jogs:
            pieces = [pulses] if abs(pulses) <= MAX_FIELD else _pieces(pulses)
            for piece in pieces:
                what, packet = self._jog(axis, piece, spindle=spindle, delay=delay)
                self._check_stop(what)
                self._jog_exchange(what, packet, axis, piece)
        self._leave_jog()

    # ------------------------------------------------------------------ jog, spindle, travel
    def jog(self, axis: str, steps: int, *, delay: Optional[int] = None, spindle: bool = False) -> None:
        """Move one axis by ``steps`` pulses in Jog mode (board frame: x, y + away from HOME; z + up).

        Opens Jog mode (OPENJOGMODE / JOGMODEON), sends one Jog Data Packet,
        waits for JOGMODEDONE and leaves Jog mode (four zero bytes /
        JOGMODEOFF).  ``delay``: the Delay byte, default the axis's (Z: the Z-up delay).
        """
        key = str(axis).lower()
        if key not in ("x", "y", "z"):
            raise PlanError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
        for piece in _pieces(int(steps)) if abs(int(steps)) > MAX_FIELD else [int(steps)]:
            self._jog(key, piece, delay=delay, spindle=spindle)  # a bad delay: nothing sent
        self._run_job(lambda: self._jog_session([(key, int(steps))], spindle=spindle, delay=delay))

    def set_spindle(self, on: bool) -> None:
        """Switch the spindle (RB2) on or off: a Jog packet of no pulses with the spindle bit (seed 003, Jog
        configuration "Bit0-Spindle: ... [0-Matkap OFF | 1-Matkap ON]")."""
        self._run_job(lambda: self._jog_session([("z", 0)], spindle=bool(on)))

    def move(self, dx_steps: int, dy_steps: int, dz_steps: int) -> None:
        """Travel by ``(dx_steps, dy_steps, dz_steps)`` board-frame pulses (z: height), spindle off: up first,
        then X and Y in one move, then down.

        A move of one axis is a Jog packet.  X and Y together are one Drill Data Packet: the only packet that
        steps both at once (seed 000 Appendix 1, constspeed_xy); it runs in a Drill mode pass whose Offset
        and Init packets move nothing (Init fields 0, so the hole stroke is 0 pulses).
        """
        self._run_job(lambda: self._move_session(int(dx_steps), int(dy_steps), int(dz_steps)))

    def travel(self, moves: np.ndarray) -> None:
        """Several :meth:`move` s one after the other, as one job: ``(N, 3)`` board-frame pulses (z: height)."""
        rows = [tuple(int(v) for v in row) for row in np.asarray(moves, np.int64).reshape(-1, 3)]
        for dx, dy, _ in rows:
            if max(abs(dx), abs(dy)) > MAX_FIELD and dx and dy:
                raise PlanError(f"an XY move of {dx}, {dy} pulses is longer than {MAX_FIELD} pulses")

        def session() -> None:
            for i, (dx, dy, dz) in enumerate(rows):
                if i:
                    self._check_stop(f"move {i + 1} of {len(rows)}")
                self._move_session(dx, dy, dz)

        self._run_job(session)

    def _move_session(self, dx_steps: int, dy_steps: int, dz_steps: int) -> None:
        """One move (board frame, z height): Z up first, X and Y together, Z down last."""
        both = dx_steps != 0 and dy_steps != 0
        first = [("z", dz_steps)] if dz_steps > 0 else []
        last = [("z", dz_steps)] if dz_steps < 0 else []
        if not both:
            middle = [("x", dx_steps)] if dx_steps else [("y", dy_steps)] if dy_steps else []
            jogs = first + middle + last
            if jogs:
                self._jog_session(jogs)
            return
        if first or self._spindle_on is not False:
            self._jog_session(first or [("z", 0)])  # spindle off (a Jog packet sets it), the head up
        self._check_stop("the XY move")
        self._xy_pass(dx_steps, dy_steps)
        if last:
            self._check_stop("lowering the head")
            self._jog_session(last)

    def _xy_pass(self, dx_steps: int, dy_steps: int) -> None:
        """One Drill mode pass whose only motion is the XY move of one Drill Data Packet."""
        m = self.maximus
        if max(abs(dx_steps), abs(dy_steps)) > MAX_FIELD:
            raise PlanError(f"an XY move of {dx_steps}, {dy_steps} pulses is longer than {MAX_FIELD} pulses")
        offset = offset_packet(0, 0, 0, delay_x=m.delay_x, delay_y=m.delay_y, delay_z=m.delay_z_up,
                               half_step=(m.half_step_x, m.half_step_y, m.half_step_z))
        init = init_packet(0, 0, delay_x=m.delay_x, delay_y=m.delay_y, delay_z_up=m.delay_z_up,
                           delay_z_down=m.delay_z_down, half_step=(m.half_step_x, m.half_step_y, m.half_step_z))
        self._exchange(bytes([OPENDRILLMODE1]), _Exchange("OPENDRILLMODE1", DRILLMODE1ON, False, "drill", _OFFSET))
        self._exchange(offset, _Exchange("the offset packet of the XY move", ATOFFSETPOS, True, "drill", _INIT))
        self._exchange(init, _Exchange("the init packet of the XY move", DRILLMODE1INITIALIZED, False, "drill",
                                       _DRILL))
        self._exchange(start_drill_packet(), _Exchange("the start (SDF) packet", ONEHOLEDRILLED, False, "drill",
                                                       _DRILL))
        packet = drill_packet(dx_steps, dy_steps, invert_x=m.invert_x, invert_y=m.invert_y)
        self._exchange(packet, _Exchange(f"the XY move {dx_steps}, {dy_steps}", ONEHOLEDRILLED, True, "drill",
                                         _DRILL, drill_time_ns(packet, init), (dx_steps, dy_steps, 0),
                                         partial(drill_moved, dx_steps, dy_steps, init, whole=True),
                                         partial(drill_directions, dx_steps, dy_steps, init)))
        self._exchange(close_drill_packet(), _CLOSE_DRILL)

    # ------------------------------------------------------------------ drill
    def drill(
        self,
        holes_steps: np.ndarray,
        *,
        z_down_steps: int,
        z_up_steps: int = 0,
        tool_changes: Sequence[tuple[int, str]] = (),
        on_tool_change: Callable[[int, str], None] | None = None,
        spindle: bool = True,
        return_to_start: bool = True,
        on_hole: Callable[[int], None] | None = None,
        before_hole: Callable[[int], None] | None = None,
        start_steps: tuple[int, int] = (0, 0),
        first_number: int = 1,
    ) -> int:
        """Drill every hole in Drill mode, Z Drill Up / Down as the PC program's settings, and come back.

        Z up and Z down are pulses below the start height (the board origin).  The firmware, as listed,
        lowers Z by the Init packet's first field once when the packet arrives, and then for every hole
        lowers Z by the second field and raises it by the first; the PC program of Appendix 2 sends (Zup,
        Zdown - Zup), which drifts by Zdown - 2 Zup per hole.  This host sends both fields equal to
        ``Zdown - Zup`` so every hole goes from Z up to Z down and back, and moves Z by ``Zdown - 2 Zup``
        (up when negative) in the Offset Positioning Packet first, so that the Init packet's descent ends
        at Z up.

        Each tool (each run of one tool) is one Drill mode session: before it the tool-change prompt, with
        the spindle off and the head at the start height; then the spindle on (a Jog packet of no pulses
        with the spindle bit); OPENDRILLMODE1 -> DRILLMODE1ON; the Offset packet -> ATOFFSETPOS; the Init
        packet -> DRILLMODE1INITIALIZED; the SDF packet (no motion) -> ONEHOLEDRILLED; one Drill Data Packet
        per hole (relative XY move, then the stroke) -> ONEHOLEDRILLED; the CDF-clear packet ->
        DRILLMODE1DONE; then a Jog packet raises the head by Z up to the start height with the spindle bit
        clear.  At the end, if ``return_to_start``, X and Y go back to the holes' origin in one move.

        Args:
            holes_steps: ``(N, 2)`` integer board-frame (x, y up) pulses relative to the holes' origin (the start
                position, unless ``start_steps`` says otherwise).
            z_down_steps: the bottom of a hole, pulses below the start height (1..65535).
            z_up_steps: where the head travels between holes, pulses below the start height (0..z_down - 1).
            tool_changes: ``(index_before_which, message)`` pairs; ``on_tool_change(index, message)`` is called,
                spindle off and head at the start height, before that hole.
            on_tool_change: the callback; it may block (e.g. prompt) and may call :meth:`emergency_stop`,
                which then ends the job before the next hole.
            spindle: run the spindle while drilling.
            return_to_start: move X and Y back to the start after the last hole.
            on_hole: called with the number of holes drilled so far after each one (progress).
            before_hole: called with the index of each hole as its packet goes out.
            start_steps: where the head stands, board-frame (x, y) pulses from the holes' origin (a resumed job:
                the first move starts there and the move back ends at the origin); the head at the start height.
            first_number: what messages call the first hole (a resumed job's: its number in the whole job).

        Returns:
            The number of holes drilled.

        Raises:
            PlanError: a bad hole list or option (nothing is sent).
            PortError: a timeout, an unexpected reply, a limit switch or an emergency stop;
                the message names the hole, counted from ``first_number``.
        """
        job = drill_job(holes_steps, int(z_up_steps), int(z_down_steps), tool_changes, self.maximus,
                        start_steps=start_steps, first_number=first_number)
        return self._run_job(lambda: self._drill_session(job, on_tool_change, on_hole, before_hole, bool(spindle),
                                                         return_to_start))


def _pieces(pulses: int) -> list[int]:
    """A long jog as pieces of at most MAX_FIELD pulses (the 16-bit step field)."""
    sign = 1 if pulses > 0 else -1
    n = abs(int(pulses))
    return [sign * min(MAX_FIELD, n - k) for k in range(0, n, MAX_FIELD)]


def require_drilling(job: Any, port: str) -> None:
    """Refuse, in one line, a job the board cannot drill: a drill file with slots, or holes milled with
    ``--mill-holes-over``, is a milling tool path (no :class:`~cam.job.drill.DrillPlan`), and the firmware drills
    only.

    Raises:
        CapabilityError: the job has no drill plan.
    """
    if getattr(job, "drill_plan", None) is None:
        what = getattr(job, "summary", "") or f"a {getattr(job, 'kind', 'step')} job"
        raise CapabilityError(f"{port} (the MAXIMUS board) drills holes only; {what} needs milling (its slots, or "
                              f"holes milled with --mill-holes-over): cut it on a step/dir or grbl port")
