"""The host side of the MAXIMUS drilling machine's RS-232 protocol.

:class:`MaximusBoard` talks to the PIC firmware listed in seed 000 Appendix 1
(or to :mod:`cam.sim.maximus`, which behaves byte for byte like
it) at 115200 baud, 8N1.  Packets are built by pure functions
(:func:`jog_packet`, :func:`offset_packet`, :func:`init_packet`,
:func:`drill_packet`, ... in :mod:`.packets`, also importable from here); the board object only sends them and checks the
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
from contextlib import AbstractContextManager
from typing import Any, Callable, Sequence

import numpy as np
import serial

from ...errors import PortError
from ...settings import DEFAULT_SETTINGS, MachineSettings, Travel
from ._link import _CLOSE_DRILL, _DRILL, _INIT, _JOG, _MODE, _OFFSET, _UNKNOWN, _Exchange, _Link
from .packets import (
    DEFAULT_DELAY, MAX_FIELD, _DrillJob, _drill_job, close_drill_packet, drill_moves, drill_packet, init_packet,
    jog_exit_packet, jog_packet, offset_packet, start_drill_packet,
)
from .protocol import (
    ATOFFSETPOS, BANNER, BAUD_RATE, DRILLMODE1INITIALIZED, DRILLMODE1ON, ISMACHINEREADY,
    JOGMODEDONE, JOGMODEON, MACHINEREADY, ONEHOLEDRILLED, OPENDRILLMODE1, OPENJOGMODE,
)

__all__ = [
    "MaximusBoard", "open_maximus", "URL_PREFIX", "MAXIMUS_SETTINGS", "maximus_holes", "drill_arguments",
    "jog_packet", "jog_exit_packet", "offset_packet", "init_packet", "start_drill_packet",
    "drill_packet", "close_drill_packet", "drill_moves",
]

URL_PREFIX = "maximus:"

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


def open_maximus(url: str, timeout_s: float = 2.0) -> "MaximusBoard":
    """Open ``maximus:/dev/ttyUSB0`` (or a bare device path) as a :class:`MaximusBoard`."""
    return MaximusBoard(url, timeout_s=timeout_s)


class MaximusBoard(_Link, AbstractContextManager):
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
        self._run_job(lambda: self._jog_session(packets))

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
        job = _drill_job(holes_steps, depth_steps, tool_changes, delay, delay_z_down, delay_z_up, half_step)
        return self._run_job(lambda: self._drill_session(job, on_tool_change, on_hole,
                                                         delay if return_to_start else None, half_step))

    def _drill_session(self, job: _DrillJob, on_tool_change: Callable[[int, str], None] | None,
                       on_hole: Callable[[int], None] | None, return_delay: int | None, half_step: bool) -> int:
        """Drill mode from OPENDRILLMODE1 to the closing packet, then the jog back (unless ``return_delay``
        is None); returns the number of holes drilled."""
        self._check_stop("Drill mode")
        self._exchange(bytes([OPENDRILLMODE1]), _Exchange("OPENDRILLMODE1", DRILLMODE1ON, False, "drill", _OFFSET))
        self._check_stop("the offset move")
        self._exchange(job.offset, _Exchange("the offset move (Z up)", ATOFFSETPOS, True, "drill", _INIT))
        self._check_stop("the Init move")
        self._exchange(job.init, _Exchange("the Init move (Z down, not stoppable)", DRILLMODE1INITIALIZED,
                                           False, "drill", _DRILL))
        self._exchange(start_drill_packet(),
                       _Exchange("the start (SDF) packet", ONEHOLEDRILLED, False, "drill", _DRILL))
        drilled = 0
        for i, packet in enumerate(job.holes):
            for message in job.changes.get(i, []):
                self._check_stop(f"hole index {i}")
                if on_tool_change is not None:
                    on_tool_change(i, message)
            self._check_stop(f"hole index {i}")
            self._exchange(packet, _Exchange(f"hole index {i}", ONEHOLEDRILLED, True, "drill", _DRILL))
            drilled += 1
            if on_hole is not None:
                on_hole(drilled)
        self._exchange(close_drill_packet(), _CLOSE_DRILL)
        if return_delay is not None and np.any(job.back_steps):
            self._check_stop("the return to the start")
            self._jog_session([(f"the return jog {a} {int(s)}", jog_packet(a, int(s), delay=return_delay,
                                                                           half_step=half_step))
                               for a, s in zip("xy", job.back_steps) if s])
        return drilled
