"""The host side of the MAXIMUS drilling machine's RS-232 protocol.

:class:`MaximusBoard` talks to the PIC firmware listed in seed 000 Appendix 1
(or to :mod:`cam.sim.maximus`, which behaves byte for byte like
it) at 115200 baud, 8N1.  Packets are built by pure functions
(:func:`jog_packet`, :func:`offset_packet`, :func:`init_packet`,
:func:`drill_packet`, ...); the board object only sends them and checks the
one-byte replies.  All step fields are L297 clock pulses (half steps when a
mode bit is set), 16-bit, low byte first.

Directions: X and Y steps are positive when the firmware's DIR bit is 1
(away from the HOME switch); Z is height, positive up (DIR_Z = 1 is "Z
down" in the listing).

Open with a device path or a URL: ``MaximusBoard("/dev/ttyUSB0")`` or
:func:`open_maximus` ``("maximus:/dev/ttyUSB0")``.

Safety rules kept by every method:

* every read has a timeout (``timeout_s``); a missing reply is a
  :class:`~cam.errors.PortError`;
* after a missing or unexpected reply nothing more is sent: the firmware's
  state is unknown, the board is marked out of step and every later call
  fails until :meth:`MaximusBoard.handshake` succeeds again (after a reset);
* a limit switch or an emergency stop ends the job with a one-line
  ``PortError`` naming the hole index; the firmware is then back at mode
  selection (Drill mode) or is taken out of Jog mode with the exit packet.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
import serial

from ...errors import PlanError, PortError
from ...settings import DEFAULT_SETTINGS, MachineSettings, Travel
from .protocol import (
    ATOFFSETPOS, BANNER, BAUD_RATE, BYTE_NAMES, DRILLMODE1DONE, DRILLMODE1INITIALIZED, DRILLMODE1ON,
    EMERGENCYSTOP, ISMACHINEREADY, JOGMODEDONE, JOGMODEOFF, JOGMODEON, MACHINEREADY, MACHINESTOPPED,
    ONEHOLEDRILLED, OPENDRILLMODE1, OPENJOGMODE, SWITCH_NAMES,
)

__all__ = [
    "MaximusBoard", "open_maximus", "URL_PREFIX", "MAXIMUS_SETTINGS", "maximus_holes", "drill_arguments",
    "jog_packet", "jog_exit_packet", "offset_packet", "init_packet", "start_drill_packet",
    "drill_packet", "close_drill_packet", "drill_moves",
]

URL_PREFIX = "maximus:"
MAX_FIELD = 0xFFFF  # 16-bit step fields (seed 000, Appendix 1: make16(high, low))

MAXIMUS_SETTINGS = DEFAULT_SETTINGS.replace(
    # one L297 clock pulse moves an axis by the "theoretical resolution of 4.375 microns" of seed 000
    # section 9 (12 mm lead screws, section 3; half steps, as the MODE bits select)
    mm_per_step_xy=0.004375,
    mm_per_step_z=0.004375,
    half_step=True,
    # the protocol's step fields are 16 bits (seed 000 Appendix 1, make16): no move beyond 65535 pulses
    travel=Travel(x_min_steps=0, x_max_steps=MAX_FIELD, y_min_steps=0, y_max_steps=MAX_FIELD,
                  z_min_steps=-MAX_FIELD, z_max_steps=MAX_FIELD),
)
"""The MAXIMUS machine: one "step" is one L297 clock pulse (a half step)."""


def drill_arguments(drill_plan: Any, settings: MachineSettings = MAXIMUS_SETTINGS) -> dict[str, Any]:
    """The :meth:`MaximusBoard.drill` arguments of a :class:`~cam.job.drill.DrillPlan` planned with ``settings``:
    holes in the board's pulses (:func:`maximus_holes`), depth, tool-change prompts and the step mode."""
    return {"holes_steps": maximus_holes(drill_plan.holes_steps), "depth_steps": drill_plan.depth_steps,
            "tool_changes": drill_plan.tool_changes, "half_step": settings.half_step}


def maximus_holes(holes_steps: np.ndarray) -> np.ndarray:
    """Holes of a drill plan in the board's own pulses: ``(N, 2)`` int64 (x, y) with y up.

    :func:`cam.job.drill.plan_drill` gives machine (x, y) with y toward the operator (image rows,
    y = -Y of the drill file); the firmware counts Y up (DIR_Y = 1 is "Y up" in the PC program of
    seed 000 Appendix 2), so y changes sign and the board keeps its handedness.
    """
    xy = np.asarray(holes_steps, np.int64).copy()
    xy[:, 1] = -xy[:, 1]
    return xy
DEFAULT_DELAY = 10  # 10 * 100 us half period: 500 pulses/s
_AXES = {"x": 1, "y": 2, "z": 3}  # Jog configuration bits 7-6: 01 = X, 10 = Y, 11 = Z (Appendix 1 JOG_DATA_INPUT)

# Host-side model of where the firmware is waiting.
_MODE = "mode selection"
_JOG = "jog data input"
_OFFSET = "offset packet"
_INIT = "init packet"
_DRILL = "drill data input"
_UNKNOWN = "unknown"


# ---------------------------------------------------------------------- packets (pure)
def _u16(value: int, what: str) -> bytes:
    if not 0 <= value <= MAX_FIELD:
        raise PlanError(f"{what} = {value} pulses does not fit the 16-bit field (0..{MAX_FIELD})")
    return bytes((value & 0xFF, value >> 8))


def _delay(value: int, what: str = "delay") -> int:
    if not 1 <= int(value) <= 255:
        raise PlanError(f"{what} = {value} must be 1..255 (units of 100 us; pulse rate 5000/{what} Hz)")
    return int(value)


def jog_packet(axis: str, steps: int, *, delay: int = DEFAULT_DELAY, half_step: bool = False,
               spindle: bool = False) -> bytes:
    """The 4-byte Jog Data Packet for a signed move of one axis.

    Byte 0 (seed 000 Appendix 1 JOG_DATA_INPUT; seed 003 "JOG Data Packet"):
    bits 7-6 axis (01 X, 10 Y, 11 Z), bit 5 half step, bit 4 DIR, bit 0
    spindle; bytes 1-2 pulses, low byte first; byte 3 delay.

    >>> jog_packet("x", -300, delay=5).hex()
    '402c0105'
    >>> jog_packet("z", 20, delay=3).hex()   # z up: DIR_Z = 0
    'c0140003'
    """
    key = str(axis).lower()
    if key not in _AXES:
        raise PlanError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
    steps = int(steps)
    positive_dir = 0 if key == "z" else 1  # DIR bit for a positive move
    direction = positive_dir if steps >= 0 else 1 - positive_dir
    config = (_AXES[key] << 6) | (int(bool(half_step)) << 5) | (direction << 4) | int(bool(spindle))
    return bytes([config]) + _u16(abs(steps), f"{key} jog") + bytes([_delay(delay)])


def jog_exit_packet() -> bytes:
    """Four zero bytes: leave Jog mode (seed 000 section 8.3 step 7)."""
    return bytes(4)


def offset_packet(x_steps: int, y_steps: int, z_steps: int, *, delay_x: int = DEFAULT_DELAY,
                  delay_y: int = DEFAULT_DELAY, delay_z: int = DEFAULT_DELAY, half_step: bool = False) -> bytes:
    """The 10-byte Offset Positioning Packet for signed moves (Z first, then X, then Y).

    Byte 0: bits 5-3 mode Z, Y, X; bits 2-0 DIR Z, Y, X (seed 000 Appendix 1
    DRILL_MODE1_INITIALIZE).  Bytes 1-6: X, Y, Z pulses, low byte first;
    bytes 7-9: delays X, Y, Z.

    >>> offset_packet(0, 0, 40).hex()   # Z up 40 pulses
    '000000000028000a0a0a'
    """
    m = int(bool(half_step))
    dir_x = 1 if x_steps > 0 else 0
    dir_y = 1 if y_steps > 0 else 0
    dir_z = 1 if z_steps < 0 else 0  # DIR_Z = 1 is down
    config = (m << 5) | (m << 4) | (m << 3) | (dir_z << 2) | (dir_y << 1) | dir_x
    return (bytes([config]) + _u16(abs(int(x_steps)), "offset x") + _u16(abs(int(y_steps)), "offset y")
            + _u16(abs(int(z_steps)), "offset z")
            + bytes([_delay(delay_x, "delay_x"), _delay(delay_y, "delay_y"), _delay(delay_z, "delay_z")]))


def init_packet(first_steps: int, second_steps: int, *, delay_x: int = DEFAULT_DELAY, delay_y: int = DEFAULT_DELAY,
                delay_z_up: int = DEFAULT_DELAY, delay_z_down: int = DEFAULT_DELAY, half_step: bool = False) -> bytes:
    """The 9-byte Initialize Drill Mode Packet.

    Byte 0: bits 2-0 mode Z, Y, X; bytes 1-2 the first field
    (``drillStepZup``), bytes 3-4 the second (``drillStepZdown``), low byte
    first; bytes 5-8 delays X, Y, Zup, Zdown (seed 000 Appendix 1, "Initialize
    Drill Mode").  As listed, the firmware lowers Z by ``first_steps`` once
    on receipt, then for every hole lowers Z by ``second_steps`` and raises
    it by ``first_steps``.

    >>> init_packet(40, 40, delay_z_down=20).hex()
    '00280028000a0a0a14'
    """
    m = int(bool(half_step))
    return (bytes([(m << 2) | (m << 1) | m]) + _u16(int(first_steps), "init first field")
            + _u16(int(second_steps), "init second field")
            + bytes([_delay(delay_x, "delay_x"), _delay(delay_y, "delay_y"),
                     _delay(delay_z_up, "delay_z_up"), _delay(delay_z_down, "delay_z_down")]))


def start_drill_packet() -> bytes:
    """Drill Data Packet with CDF and SDF set: answered at once, nothing moves (seed 003, SDF)."""
    return bytes([0xC0, 0, 0, 0, 0])


def drill_packet(dx_steps: int, dy_steps: int) -> bytes:
    """The 5-byte Drill Data Packet for one hole, a relative XY move.

    Byte 0: bit 7 CDF (continue drilling) set, bit 6 SDF clear, bit 1 DIR Y,
    bit 0 DIR X; bytes 1-4 |dx|, |dy| pulses, low byte first (seed 000
    Appendix 1 DRILL_MODE1_INPUT; seed 003 "Drill Data Packet").

    >>> drill_packet(300, -2).hex()
    '812c010200'
    """
    config = 0x80 | ((1 if dy_steps > 0 else 0) << 1) | (1 if dx_steps > 0 else 0)
    return bytes([config]) + _u16(abs(int(dx_steps)), "hole dx") + _u16(abs(int(dy_steps)), "hole dy")


def close_drill_packet() -> bytes:
    """Drill Data Packet with CDF clear: leave Drill mode, nothing moves."""
    return bytes(5)


def drill_moves(holes_steps: np.ndarray) -> np.ndarray:
    """Relative moves from the start to each hole in turn.

    Args:
        holes_steps: ``(N, 2)`` integer (x, y) pulses relative to the start.

    Returns:
        ``(N, 2)`` int64 (dx, dy); row i moves from hole i-1 (the start for i = 0) to hole i.

    >>> drill_moves(np.array([[10, 0], [10, 5], [0, 0]])).tolist()
    [[10, 0], [0, 5], [-10, -5]]
    """
    holes = np.asarray(holes_steps)
    if holes.ndim != 2 or holes.shape[1] != 2:
        raise PlanError(f"holes_steps must have shape (N, 2), got {holes.shape}")
    if holes.size and not np.issubdtype(holes.dtype, np.integer):
        if not np.all(np.equal(np.mod(holes, 1), 0)):
            raise PlanError("holes_steps must be whole pulses")
    holes = holes.astype(np.int64)
    moves = np.diff(np.vstack([np.zeros((1, 2), np.int64), holes]), axis=0)
    big = np.flatnonzero(np.abs(moves).max(axis=1, initial=0) > MAX_FIELD) if len(moves) else []
    if len(big):
        raise PlanError(f"the move to hole {int(big[0])} is longer than {MAX_FIELD} pulses")
    return moves


# ---------------------------------------------------------------------- the board
@dataclass
class _Exchange:
    """A packet sent whose reply is still due."""

    what: str  # e.g. "hole index 3"
    expected: int
    moving: bool  # the firmware has interrupts enabled: an emergency stop is honoured
    mode: str  # "jog" or "drill"
    next_state: str


def _name(byte: int) -> str:
    return f"{BYTE_NAMES.get(byte, 'unknown byte')} ({byte:#04x})"


def open_maximus(url: str, timeout_s: float = 2.0) -> "MaximusBoard":
    """Open ``maximus:/dev/ttyUSB0`` (or a bare device path) as a :class:`MaximusBoard`."""
    return MaximusBoard(url, timeout_s=timeout_s)


class MaximusBoard:
    """A MAXIMUS control board on a serial port.

    Args:
        url_or_device: ``"maximus:/dev/ttyUSB0"`` or ``"/dev/ttyUSB0"``.
        timeout_s: the longest wait for any reply; a move must finish within it.
        handshake: do the ISMACHINEREADY / MACHINEREADY handshake now.

    Attributes:
        banner: ``"MAXIMUS_V1.0"`` if the power-up banner was seen, else None.
    """

    def __init__(self, url_or_device: str, timeout_s: float = 2.0, *, handshake: bool = True) -> None:
        device = url_or_device[len(URL_PREFIX):] if url_or_device.startswith(URL_PREFIX) else url_or_device
        if not device:
            raise PortError(f"no device in {url_or_device!r}; use maximus:/dev/ttyUSB0")
        if not timeout_s > 0:
            raise PortError(f"timeout_s must be > 0, got {timeout_s!r}")
        self.device = device
        self.timeout_s = float(timeout_s)
        self.banner: str | None = None
        self._lock = threading.RLock()
        self._state = _UNKNOWN
        self._pending: _Exchange | None = None
        self._reader_active = False
        self._job_active = False
        self._stop_requested = False
        self._estop_sent = False
        self._stop_done = threading.Event()
        self._stop_error: PortError | None = None
        try:
            # seed 000 Appendix 1: "#use rs232(baud=115200, xmit=PIN_C6, rcv=PIN_C7)"; CCS default 8N1
            self._ser = serial.Serial(device, baudrate=BAUD_RATE, bytesize=8, parity="N", stopbits=1,
                                      timeout=self.timeout_s, write_timeout=self.timeout_s)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise PortError(f"cannot open MAXIMUS port {device}: {exc}") from exc
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

    def __enter__(self) -> "MaximusBoard":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def in_step(self) -> bool:
        """False after an error that left the firmware in an unknown state."""
        return self._state != _UNKNOWN

    def _write(self, data: bytes) -> None:
        try:
            self._ser.write(data)
            self._ser.flush()
        except (serial.SerialException, OSError) as exc:
            self._state = _UNKNOWN
            raise PortError(f"cannot write to MAXIMUS port {self.device}: {exc}") from exc

    def _read_byte(self, timeout_s: float | None = None) -> int | None:
        try:
            if timeout_s is not None:
                self._ser.timeout = timeout_s
            data = self._ser.read(1)
        except (serial.SerialException, OSError) as exc:
            self._state = _UNKNOWN
            raise PortError(f"cannot read from MAXIMUS port {self.device}: {exc}") from exc
        finally:
            if timeout_s is not None:
                self._ser.timeout = self.timeout_s
        return data[0] if data else None

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
        MACHINEREADY arrives within ``timeout_s``.
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
                raise PortError(f"cannot read from MAXIMUS port {self.device}: {exc}") from exc
            self._write(bytes([ISMACHINEREADY]))
            deadline = time.monotonic() + self.timeout_s
            while True:
                remaining = deadline - time.monotonic()
                b = self._read_byte(max(remaining, 0.001)) if remaining > 0 else None
                if b is None:
                    self._state = _UNKNOWN
                    raise PortError(f"MAXIMUS board on {self.device} did not answer ISMACHINEREADY (0x61) "
                                    f"within {self.timeout_s:g} s; check the cable and reset the board")
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

    # ------------------------------------------------------------------ one exchange
    def _exchange(self, packet: bytes, ex: _Exchange) -> None:
        """Send ``packet`` and check its reply; raises PortError on anything but ``ex.expected``."""
        with self._lock:
            self._pending = ex
            self._estop_sent = False
            self._stop_done.clear()
            self._reader_active = True
            try:
                self._write(packet)
            except BaseException:
                self._pending = None
                self._reader_active = False
                raise
        try:
            reply = self._read_byte()
        except BaseException:
            with self._lock:
                self._reader_active = False  # the exchange stays pending: emergency_stop() reads its answer
            raise
        self._settle(reply)

    def _take_pending(self) -> tuple[_Exchange, bool]:
        with self._lock:
            ex, estop = self._pending, self._estop_sent
            self._pending = None
            self._reader_active = False
            assert ex is not None
            return ex, estop

    def _settle(self, reply: int | None) -> None:
        """Judge the reply to the pending exchange (called by whichever thread read it)."""
        ex, estop = self._take_pending()
        if estop:
            try:
                error = self._resolve_stop(ex, reply)
            except PortError as exc:
                self._stop_error = error = exc
            finally:
                self._stop_done.set()
            raise error
        if reply is None:
            self._state = _UNKNOWN
            raise PortError(f"MAXIMUS board did not answer within {self.timeout_s:g} s after {ex.what} "
                            f"(expected {_name(ex.expected)}); nothing more sent")
        if reply == ex.expected:
            self._state = ex.next_state
            return
        if reply in SWITCH_NAMES:
            self._after_stop(ex.mode)
            raise PortError(f"limit switch {SWITCH_NAMES[reply]} ({reply:#04x}) tripped during {ex.what}; "
                            f"the board backed off and ended the job")
        if reply == MACHINESTOPPED:
            self._after_stop(ex.mode)
            raise PortError(f"MAXIMUS board reported an emergency stop during {ex.what}; drivers disabled")
        self._state = _UNKNOWN
        raise PortError(f"MAXIMUS board answered {_name(reply)} instead of {_name(ex.expected)} after "
                        f"{ex.what}; nothing more sent")

    def _after_stop(self, mode: str) -> None:
        """After MACHINESTOPPED or a switch byte: Drill mode is at mode selection, Jog mode still in Jog."""
        if mode == "jog":
            self._state = _JOG
            self._leave_jog()
        else:
            self._state = _MODE

    def _leave_jog(self) -> None:
        """Send the Jog exit packet and expect JOGMODEOFF (no motion)."""
        self._exchange(jog_exit_packet(), _Exchange("the Jog exit packet", JOGMODEOFF, False, "jog", _MODE))

    def _resolve_stop(self, ex: _Exchange, reply: int | None) -> PortError:
        """The reply to a move during which EMERGENCYSTOP was sent: the error the job ends with."""
        if reply == MACHINESTOPPED:
            self._after_stop(ex.mode)
            return PortError(f"emergency stop during {ex.what}: the board answered MACHINESTOPPED, "
                             f"drivers disabled")
        if reply is None:
            self._state = _UNKNOWN
            self._stop_error = PortError(f"emergency stop sent during {ex.what} but the board did not "
                                         f"answer within {self.timeout_s:g} s")
            return self._stop_error
        if reply == ex.expected or reply in SWITCH_NAMES:
            # The move ended as the stop byte arrived.  If the UART ISR still caught it,
            # MACHINESTOPPED follows; if not, the firmware took 0x80 as packet data.
            second = self._read_byte(min(0.3, self.timeout_s))
            if second == MACHINESTOPPED:
                self._after_stop(ex.mode)
                return PortError(f"emergency stop at the end of {ex.what}: the board answered "
                                 f"MACHINESTOPPED, drivers disabled")
            self._state = _UNKNOWN
            self._stop_error = PortError(f"emergency stop reached the board after {ex.what} had ended; it "
                                         f"read the stop byte as packet data and is out of step: reset it")
            return self._stop_error
        self._state = _UNKNOWN
        self._stop_error = PortError(f"emergency stop during {ex.what}: the board answered {_name(reply)}")
        return self._stop_error

    # ------------------------------------------------------------------ emergency stop
    def emergency_stop(self) -> bool:
        """Stop the machine now; safe to call from any thread (e.g. on Ctrl-C).

        During a move (the firmware has interrupts enabled) this sends
        EMERGENCYSTOP (0x80) and waits for MACHINESTOPPED: the firmware cuts
        the drivers and returns to mode selection (Drill) or Jog data input
        (Jog; the exit packet follows).  Between moves the firmware would
        read 0x80 as packet data, so nothing is sent: the running job stops
        before its next packet and closes Drill mode with the CDF-clear
        packet, which moves nothing.  (A stop between the offset move and the
        Init move leaves Z ``depth_steps`` above the start; the Init move
        itself cannot be stopped -- the listing runs it with interrupts off.)

        Returns:
            True if a move was stopped (MACHINESTOPPED received), False if no
            move was running.

        Raises:
            PortError: the stop byte was sent but not answered, or arrived
                as the move ended and was taken as packet data.
        """
        with self._lock:
            ex = self._pending
            between_moves = ex is None or not ex.moving
            if between_moves:
                self._stop_requested = True
                # no job left to act on the request (e.g. it was interrupted by Ctrl-C): finish here
                orphan_reply = ex is not None and not self._reader_active
                finish_here = not self._job_active and (ex is None or orphan_reply)
            elif not self._estop_sent:
                self._estop_sent = True
                self._stop_error = None
                self._write(bytes([EMERGENCYSTOP]))
            reader = self._reader_active
        if between_moves:
            if finish_here:
                if ex is not None:
                    try:
                        self._settle(self._read_byte())  # the answer to a packet that moves nothing stoppable
                    except PortError:
                        pass
                if self._state in (_OFFSET, _INIT, _DRILL, _JOG):
                    self._unwind()
            return False
        if reader:
            if not self._stop_done.wait(self.timeout_s + 1.0):
                raise PortError("emergency stop sent; no answer was read within "
                                f"{self.timeout_s + 1.0:g} s")
        else:
            # nobody is reading (the job was interrupted): read the answer here
            try:
                self._settle(self._read_byte())
            except PortError:
                pass
        if self._stop_error is not None:
            raise self._stop_error
        return True

    def _unwind(self) -> None:
        """From a waiting firmware state, get back to mode selection without moving anything."""
        if self._state == _OFFSET:
            self._exchange(offset_packet(0, 0, 0),
                           _Exchange("the closing offset packet", ATOFFSETPOS, True, "drill", _INIT))
        if self._state == _INIT:
            self._exchange(init_packet(0, 0),
                           _Exchange("the closing init packet", DRILLMODE1INITIALIZED, False, "drill", _DRILL))
        if self._state == _DRILL:
            self._exchange(close_drill_packet(),
                           _Exchange("the closing drill packet", DRILLMODE1DONE, False, "drill", _MODE))
        if self._state == _JOG:
            self._leave_jog()

    def _check_stop(self, before: str) -> None:
        """Between moves: if a stop was asked for, close the mode cleanly and end the job."""
        with self._lock:
            if not self._stop_requested:
                return
        self._unwind()
        raise PortError(f"emergency stop before {before}: no move was running; job closed, nothing more sent")

    # ------------------------------------------------------------------ jog
    def jog(self, axis: str, steps: int, *, delay: int = DEFAULT_DELAY, half_step: bool = False,
            spindle: bool = False) -> None:
        """Move one axis by ``steps`` pulses in Jog mode (x, y: + away from HOME; z: + up).

        Opens Jog mode (OPENJOGMODE / JOGMODEON), sends one Jog Data Packet,
        waits for JOGMODEDONE and leaves Jog mode (four zero bytes /
        JOGMODEOFF).  ``delay`` is the half period in units of 100 us.
        """
        self._run_jogs([(axis, steps)], delay=delay, half_step=half_step, spindle=spindle)

    def _run_jogs(self, moves: Sequence[tuple[str, int]], *, delay: int, half_step: bool = False,
                  spindle: bool = False) -> None:
        packets = [(f"jog {a} {int(s)}", jog_packet(a, s, delay=delay, half_step=half_step, spindle=spindle))
                   for a, s in moves]
        self._begin_job()
        try:
            self._require(_MODE)
            self._jog_session(packets)
        except BaseException:
            self._clean_up_after()
            raise
        finally:
            self._end_job()

    def _jog_session(self, packets: Sequence[tuple[str, bytes]]) -> None:
        """OPENJOGMODE, the Jog Data Packets one by one, then the exit packet (job already begun)."""
        self._exchange(bytes([OPENJOGMODE]), _Exchange("OPENJOGMODE", JOGMODEON, False, "jog", _JOG))
        for what, packet in packets:
            self._check_stop(what)
            self._exchange(packet, _Exchange(what, JOGMODEDONE, True, "jog", _JOG))
        self._leave_jog()

    # ------------------------------------------------------------------ drill
    def drill(
        self,
        holes_steps: np.ndarray,
        *,
        depth_steps: int,
        tool_changes: Sequence[tuple[int, str]] = (),
        on_tool_change: Callable[[int, str], None] | None = None,
        delay: int = DEFAULT_DELAY,
        delay_z_down: int | None = None,
        delay_z_up: int | None = None,
        half_step: bool = False,
        return_to_start: bool = True,
        on_hole: Callable[[int], None] | None = None,
    ) -> int:
        """Drill every hole in Drill mode, to the same depth, and bring the head back to the start.

        The firmware, as listed, lowers Z by the Init packet's first field
        once when the packet arrives, and then for every hole lowers Z by the
        second field and raises it by the first.  The PC program of
        Appendix 2 sends (Zup, Zdown - Zup), which drifts by Zdown - 2 Zup per
        hole.  This host sends both fields equal to ``depth_steps`` so every
        hole nets zero Z, and first raises Z by ``depth_steps`` in the Offset
        Positioning Packet, so the Init packet's descent brings the tip back to
        the start height instead of plunging at the start.  Every hole then
        goes from the start height down ``depth_steps`` and back: the start
        height is the travel height (put the tip just above the board).

        Sequence: OPENDRILLMODE1 -> DRILLMODE1ON; Offset packet (Z up
        ``depth_steps``) -> ATOFFSETPOS; Init packet (``depth_steps``,
        ``depth_steps``) -> DRILLMODE1INITIALIZED; the SDF packet (CDF + SDF,
        no motion) -> ONEHOLEDRILLED; one Drill Data Packet per hole (CDF,
        relative XY move) -> ONEHOLEDRILLED; the CDF-clear packet ->
        DRILLMODE1DONE; then, if ``return_to_start``, Jog moves back to the
        start XY.

        Args:
            holes_steps: ``(N, 2)`` integer (x, y) pulses relative to the start position.
            depth_steps: plunge depth in Z pulses, 1..65535.
            tool_changes: ``(index_before_which, message)`` pairs; ``on_tool_change(index,
                message)`` is called, with the head at the start height, before that hole's packet.
            on_tool_change: the callback; it may block (e.g. prompt) and may call
                :meth:`emergency_stop`, which then ends the job before the next hole.
            delay: half period of every axis in units of 100 us (1..255).
            delay_z_down, delay_z_up: Z delays if different from ``delay``.
            half_step: set every axis's L297 to half steps.
            return_to_start: jog X and Y back to the start after the last hole.
            on_hole: called with the number of holes drilled so far after each one (progress).

        Returns:
            The number of holes drilled.

        Raises:
            PlanError: a bad hole list or option (nothing is sent).
            PortError: a timeout, an unexpected reply, a limit switch or an emergency stop;
                the message names the hole index.
        """
        moves = drill_moves(holes_steps)
        depth = int(depth_steps)
        if not 1 <= depth <= MAX_FIELD:
            raise PlanError(f"depth_steps = {depth_steps} must be 1..{MAX_FIELD}")
        dz_down = _delay(delay if delay_z_down is None else delay_z_down, "delay_z_down")
        dz_up = _delay(delay if delay_z_up is None else delay_z_up, "delay_z_up")
        changes: dict[int, list[str]] = {}
        for index, message in tool_changes:
            if not 0 <= int(index) < len(moves):
                raise PlanError(f"tool change before hole {index}: there are {len(moves)} holes")
            changes.setdefault(int(index), []).append(str(message))
        offset = offset_packet(0, 0, depth, delay_x=delay, delay_y=delay, delay_z=dz_up, half_step=half_step)
        init = init_packet(depth, depth, delay_x=delay, delay_y=delay, delay_z_up=dz_up,
                           delay_z_down=dz_down, half_step=half_step)
        holes = [drill_packet(int(dx), int(dy)) for dx, dy in moves]
        back = -moves.sum(axis=0) if len(moves) else np.zeros(2, np.int64)

        self._begin_job()
        drilled = 0
        try:
            self._require(_MODE)
            self._check_stop("Drill mode")
            self._exchange(bytes([OPENDRILLMODE1]),
                           _Exchange("OPENDRILLMODE1", DRILLMODE1ON, False, "drill", _OFFSET))
            self._check_stop("the offset move")
            self._exchange(offset, _Exchange("the offset move (Z up)", ATOFFSETPOS, True, "drill", _INIT))
            self._check_stop("the Init move")
            self._exchange(init, _Exchange("the Init move (Z down, not stoppable)", DRILLMODE1INITIALIZED,
                                           False, "drill", _DRILL))
            self._exchange(start_drill_packet(),
                           _Exchange("the start (SDF) packet", ONEHOLEDRILLED, False, "drill", _DRILL))
            for i, packet in enumerate(holes):
                for message in changes.get(i, []):
                    self._check_stop(f"hole index {i}")
                    if on_tool_change is not None:
                        on_tool_change(i, message)
                self._check_stop(f"hole index {i}")
                self._exchange(packet, _Exchange(f"hole index {i}", ONEHOLEDRILLED, True, "drill", _DRILL))
                drilled += 1
                if on_hole is not None:
                    on_hole(drilled)
            self._exchange(close_drill_packet(),
                           _Exchange("the closing drill packet", DRILLMODE1DONE, False, "drill", _MODE))
            if return_to_start and np.any(back):
                self._check_stop("the return to the start")
                self._jog_session([(f"the return jog {a} {int(s)}", jog_packet(a, int(s), delay=delay,
                                                                               half_step=half_step))
                                   for a, s in zip("xy", back) if s])
        except BaseException:
            self._clean_up_after()
            raise
        finally:
            self._end_job()
        return drilled

    # ------------------------------------------------------------------ job bookkeeping
    def _begin_job(self) -> None:
        with self._lock:
            if self._job_active:
                raise PortError("a MAXIMUS job is already running on this board")
            self._job_active = True
            self._stop_requested = False

    def _end_job(self) -> None:
        with self._lock:
            self._job_active = False

    def _clean_up_after(self) -> None:
        """An exception left a job: if the firmware waits between moves, close its mode quietly.

        During a move (e.g. Ctrl-C while waiting for a reply) nothing is sent:
        :meth:`emergency_stop` deals with the move.
        """
        with self._lock:
            if self._pending is not None or self._state not in (_OFFSET, _INIT, _DRILL, _JOG):
                return
        try:
            self._unwind()
        except PortError:
            pass
