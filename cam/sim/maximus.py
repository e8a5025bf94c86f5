"""An emulator of the MAXIMUS drilling machine's PIC16F877 firmware on a pseudo-terminal.

The firmware listed in Appendix 1 of the MAXIMUS report (seed
``000_a742bf5900f8b33c.txt``, "APPENDIX 1 - PIC Source Code") is the
authority.  :class:`MaximusEmulator` runs that program, statement by statement,
in a background thread: it prints the same banner, answers the same bytes with
the same bytes (and answers nothing where the listing answers nothing), parses
the same packets, drives the same pins of output ports B and D in the same
order, and honours the same interrupts.  The host opens
:attr:`MaximusEmulator.device_path` with pyserial exactly as it would open
``/dev/ttyUSB0``.

Pin meaning (Appendix 1 ``#define`` block; the same as Table 7-3 in section 7.4.2)::

    port D  bit 0 MODE_X   bit 1 STEP_X   bit 2 DIR_X   bit 3 ENABLE_X
            bit 4 MODE_Y   bit 5 STEP_Y   bit 6 DIR_Y   bit 7 ENABLE_Y
    port B  bit 2 SPINDLE  bit 4 MODE_Z   bit 5 STEP_Z  bit 6 DIR_Z   bit 7 ENABLE_Z
            (bit 0 is the RB0/INT limit-switch input; bits 1 and 3 are unused outputs)

Each axis pin goes to an L297: a step is a rising edge of STEP (the L297's
CLOCK "step occurs on the rising edge", seed 000 Appendix 4 pin 18), MODE high
selects half steps (Appendix 4 pin 19) and ENABLE low de-energises the motor
(Appendix 4 pin 10).  Directions, as the decoder reads them: X and Y count
+1 per step when DIR is 1 (the firmware backs off the HOME switches with
DIR = 1, and the PC program sets DIR = 1 for "X right" / "Y up"); Z counts
-1 per step when DIR_Z is 1, because the listing marks ``output_bit(DIR_Z,1)``
as "Z down" -- so decoded z is height, positive up.  All counts are L297 clock
pulses (half steps when MODE is high), the unit of every step field in the
protocol.

Timing model: a simulated firmware clock.  ``dly_100us(n)`` advances it by
``n * 100 us`` and the limit-switch debounce ``delay_ms(300)`` by 300 ms;
instructions, UART transfers and the time spent waiting for host bytes take no
simulated time.  One step pulse of ``constspeed`` therefore lasts
``2 * delay * 100 us`` (f = 5000 / delay Hz).  ``t_ns`` in :meth:`port_log`
is on this clock, so logs are deterministic.  In real time the emulator paces
itself so that simulated time runs ``speed`` times faster than the wall clock
(``speed=None``: no sleeping at all), never ahead of it.  Each byte from the host
is stamped with the wall clock as it arrives (a reader process of its own waits
on the line, so a busy computer or the caller's threads do not make the stamps
late: cam/sim/_maximus_line.py) and the firmware takes it at that simulated
time, as the PIC's UART interrupt does: in the middle of a delay, and after a
late thread has caught up with the pulses due before it, never sooner
(cam/sim/_maximus_uart.py).

Interrupts are emulated where they can happen: while the listing has them
enabled (from just before a Jog, Offset or Drill move until just after its
reply) the emulator checks the limit-switch flag after every port write, and a
byte is served at its arrival's time.  A received byte is then consumed by the UART
ISR; only EMERGENCYSTOP (0x80) does anything.  Outside a move a packet is
read byte by byte (``getc()`` with interrupts off, as listed): a packet that
lost a byte on the line waits, silent and still, and the next byte, whatever
it is (0x80 included), completes it (docs/maximus.md, "When the link fails").

Listing vs prose
----------------
Where Appendix 1 (the listing) and the report's prose (sections 7.5.2, 8.3,
8.4), the PC program (Appendix 2) or the Turkish article (seed 003) disagree,
the emulator follows the listing:

1. Power-up prints the banner ``MAXIMUS_V1.0`` (12 bytes, no line end) before
   waiting for ISMACHINEREADY; section 7.5.2 does not mention it.  Until
   ISMACHINEREADY (0x61) arrives every other byte is read and dropped without
   an answer.
2. At mode selection a byte that matches none of 0x61/0x63/0x67/0x71 gets no
   answer and falls through the ``switch`` into JOG_DATA_INPUT: the firmware
   is then in Jog mode without having sent JOGMODEON.  0x61 at mode selection
   is answered with MACHINEREADY again.  OPENDRILLMODE2 (0x71) answers
   DRILLMODE2ON and also enters JOG_DATA_INPUT (marked "Not Completed").
3. Jog mode ends when *both* top bits of the configuration byte are 0
   (``(dataIn[0] >> 6) == 0``); the listing's comment says "bit7 = 0".
   Section 8.3 sends four zero bytes, which satisfies both.
4. Jog configuration bit 0 drives SPINDLE_BIT (RB2) on every Jog move; the
   spindle pin is not in Table 7-3.  Drill mode never touches it.
5. Step fields are used as L297 clock-pulse counts as they come; the Turkish
   article calls them full steps (the PC program multiplies by mode + 1).
6. The Offset Positioning Packet moves Z first, then X, then Y, one axis
   after the other, Z at the third delay byte (``DelayZup`` in the listing).
7. The Initialize Drill Mode Packet lowers Z by its *first* 16-bit field
   (``drillStepZup``) at ``DelayZup``; the Turkish article says it lowers by
   DrillStepZdown.  This move runs with interrupts disabled: no emergency
   stop and no limit-switch handling during it.
8. Each hole lowers Z by the Init packet's *second* field (``drillStepZdown``,
   at DelayZdown) and raises it by its *first* (``drillStepZup``, at
   DelayZup).  The PC program sends second field = Zdown - Zup, so as listed
   the head drifts by Zdown - 2 * Zup per hole unless Zdown = 2 * Zup.
9. The listing's comments call Drill Data bytes 1-4 "drillStepZup/Zdown" low
   and high bytes; the code uses them as StepX and StepY.
10. XY moves are a dog-leg: both axes step together at the slower delay
    max(DelayX, DelayY) for min(nx, ny) pulses, then the longer axis alone at
    its own delay.
11. ``constspeed`` ends with ``output_bit(STEP, 1) // Add last step``.  The
    STEP pins idle high (``output_d(0xFF)``, ``output_b(0xF0)``), so this only
    restores the idle level: n requested pulses give exactly n rising edges.
12. Section 8.4 step 11 says the PIC answers the closing packet with
    "JOGMODE1DONE"; the listing sends DRILLMODE1DONE (0x70).
13. ``PACKETLENGTH 10`` is commented "length of Drill Data Packet"; the Drill
    Data Packet is 5 bytes, 10 is the Offset Positioning Packet.
14. Emergency stop (0x80) is honoured only while interrupts are enabled (a Jog,
    Offset or Drill move and its reply); any other byte arriving then is read
    by the UART ISR and lost.  Outside a move 0x80 is ordinary packet data.
    After MACHINESTOPPED (0x81) the firmware returns to JOG_DATA_INPUT in Jog
    mode (still in Jog mode) and to MODE_SELECTION in Drill mode, with all
    drivers disabled until the next Jog or Offset packet enables them.  A stop
    that lands between a pulse's falling and rising edge leaves that STEP pin
    low, so the next move of that axis makes one rising edge more than it asks
    (its first ``output_bit(STEP, 1)`` is a rise; see point 11).
15. Limit switches (section 7.4.3: "any state change ... will interrupt") only
    interrupt on a falling edge of the AND gate (``ext_int_edge(H_TO_L)``),
    i.e. when a switch is pressed, and only during a move.  The ISR waits
    300 ms, reads port A, backs X or Y off STEPSBACKATLIMIT (700) pulses at
    ``axisDelay`` -- the delay of the last *Jog* packet, 0 until one is
    received -- and sends only the switch byte (no JOGMODEDONE /
    ONEHOLEDRILLED).  Z switches get no back-off.  Then it returns to
    JOG_DATA_INPUT in Jog mode and to MODE_SELECTION in Drill mode.
    ERRORLIMITSWITCH (0x90) is defined but never sent (its ``putc`` is
    commented out); no switch or several switches at once make the ISR return
    and the move continue.
16. The printed ISR has a stray ``}`` after ``putc(LIMIT_SWITCH_Z)`` (a page
    break); it is read as the same ``switch`` continuing with ``case 0x3F``
    and ``default``.
17. The INTF flag is cleared after the Jog and Offset packets but not after a
    Drill Data Packet, so a switch pressed while interrupts were off (e.g.
    during the Init move) interrupts the next hole as soon as it starts.
18. ``#use delay(clock=2000000)`` declares 2 MHz, but the HS fuse, the
    ``dly_100us`` comment ("20Mhz oscillator") and 115200 baud (out of reach
    of the UART at 2 MHz) all say 20 MHz.  In ``dly_100us`` the
    ``delay_cycles(4)`` is outside the loop (no braces).  The emulator takes
    one delay unit as 100 us, the figure the listing's comments and
    section 7.5.2's packet figures use.
19. The Turkish article's Offset packet table says bit 5 is the mode of the
    "Y" axis; the listing uses it for MODE_Z.

Not emulated byte for byte: the UART's two-byte receive FIFO and its overrun
lock-up (the emulator buffers any number of bytes), instruction execution
time, and the CCS ``int1`` conversion (taken as "non-zero is 1").
"""
from __future__ import annotations

import argparse
import os
import sys
import termios
import threading
import time
import tty
from collections import deque
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any, Iterable, Iterator, Sequence

import numpy as np

from ..drive.maximus.protocol import (
    LIMIT_SWITCH_X, PORT_B, PORT_D, POWER_UP_B, POWER_UP_D, SPINDLE_BIT, SWITCH_NAMES,
)
from ._maximus_base import (  # noqa: F401  (the labels are part of this module's names)
    BUSY, DRILL_MODE1_INITIALIZE, DRILL_MODE1_INPUT, INITIALIZE_DRILL_MODE, JOG_DATA_INPUT, MODE_SELECTION, POWER_UP,
    _Halt, _PowerOn, _ReplyFault,
)
from ..drive.maximus.trust import EMULATOR_SPEEDS_ENV, clear_fault_marker
from ..drive.maximus.switch_options import add_maximus_switch_options
from ._maximus_hardware import _Hardware
from ._maximus_program import _Program
from ._maximus_uart import _Uart
from ._serve import serve_until_stopped
from ..errors import CamError, PortError

__all__ = [
    "MaximusEmulator", "PortLog", "start_emulator", "main", "HOLE_LOG_HEADER", "SWITCH_OPTIONS", "travel_error",
    # where the firmware waits (the listing's labels), for tests and tools that watch it
    "POWER_UP", "MODE_SELECTION", "JOG_DATA_INPUT", "DRILL_MODE1_INITIALIZE", "INITIALIZE_DRILL_MODE",
    "DRILL_MODE1_INPUT", "BUSY",
]


HOLE_LOG_HEADER = "hole,x_halfsteps,y_halfsteps,z_bottom_halfsteps,spindle"
"""The header of ``--log FILE.csv`` (see :meth:`MaximusEmulator.hole_log`)."""


@dataclass(frozen=True)
class PortLog:
    """Writes to output ports B and D, in order.

    Attributes:
        t_ns: ``(M,)`` int64, simulated firmware time of each write (see the module's timing model).
        port: ``(M,)`` uint8, ``PORT_B`` (``ord("B")``) or ``PORT_D`` (``ord("D")``).
        value: ``(M,)`` uint8, the whole port after the write.

    Iterating yields ``(t_ns, "B" | "D", value)`` tuples.
    """

    t_ns: np.ndarray
    port: np.ndarray
    value: np.ndarray

    def __len__(self) -> int:
        return len(self.t_ns)

    def __iter__(self) -> Iterator[tuple[int, str, int]]:
        for t, p, v in zip(self.t_ns.tolist(), self.port.tolist(), self.value.tolist()):
            yield t, chr(p), v

    @classmethod
    def from_rows(cls, rows: Iterable[tuple[int, str | int, int]]) -> "PortLog":
        """Build a log from ``(t_ns, port, value)`` rows; port is ``"B"``/``"D"`` or its code."""
        rows = list(rows)
        t = np.array([int(r[0]) for r in rows], np.int64)
        p = np.array([ord(r[1]) if isinstance(r[1], str) else int(r[1]) for r in rows], np.uint8)
        v = np.array([int(r[2]) for r in rows], np.uint8)
        if np.any((p != PORT_B) & (p != PORT_D)):
            raise CamError("port log rows must name port 'B' or 'D'")
        return cls(t, p, v)


class MaximusEmulator(_Program, _Hardware, _Uart, AbstractContextManager):
    """The PIC firmware of seed 000 Appendix 1, served on a pseudo-terminal.

    Use :func:`start_emulator` to create and start one.  The firmware's program, the board it drives and
    its UART are the parts ``_Program``, ``_Hardware`` and ``_Uart`` (``cam/sim/_maximus_*.py``); this class
    holds their state, starts and stops them, injects faults and keeps the logs.

    Args:
        speed: simulated seconds per real second (1.0 = the firmware's own
            timing); ``None`` never sleeps.
        travel_x_pulses, travel_y_pulses, travel_z_pulses: ``(low, high)``
            travel ends in pulses from the power-up position, or ``None`` for
            no switches on that axis.  X/Y: HOME is pressed below ``low`` and
            LIMIT above ``high``.  Z (height, positive up): HOME above
            ``high``, LIMIT below ``low``.
        late_reply_s: real seconds added before every reply byte.
        axis_delay: initial value of the firmware's global ``axisDelay`` (the
            limit-switch back-off delay until a Jog packet sets it).
        log_path: a CSV file to write one row per drilled hole to, as it is
            drilled (see :meth:`hole_log`), or None.
    """

    def __init__(
        self,
        *,
        speed: float | None = 1.0,
        travel_x_pulses: tuple[int, int] | None = None,
        travel_y_pulses: tuple[int, int] | None = None,
        travel_z_pulses: tuple[int, int] | None = None,
        late_reply_s: float = 0.0,
        axis_delay: int = 0,
        log_path: str | os.PathLike | None = None,
    ) -> None:
        if speed is not None and not speed > 0:
            raise CamError(f"emulator speed must be > 0 or None, got {speed!r}")
        self._speed = speed
        self._travel = (travel_x_pulses, travel_y_pulses, travel_z_pulses)
        self.late_reply_s = float(late_reply_s)
        self._lock = threading.Lock()
        self._stop_event = threading.Event()
        self._reset_event = threading.Event()
        self._wake = threading.Event()
        self._faults: list[_ReplyFault] = []
        self._trips: list[list[int]] = []  # [switch, skip_moves]
        self._master = -1
        self._slave = -1
        self.device_path = ""
        self._thread: threading.Thread | None = None
        # logs
        self._port_rows: list[tuple[int, int, int]] = []
        self._rx_rows: list[tuple[int, int, str]] = []
        self._tx_rows: list[tuple[int, int, int | None]] = []
        self._packets: list[tuple[str, bytes]] = []
        # machine state
        self._ports = {PORT_B: POWER_UP_B, PORT_D: POWER_UP_D}  # first power-up writes set the idle levels
        self._pos = [0, 0, 0]
        self._half_steps = [0, 0, 0]
        self._holes: list[tuple[int, int, int, int, int]] = []
        self._log_file = None
        if log_path is not None:
            try:
                self._log_file = open(log_path, "w", encoding="ascii", newline="")
            except OSError as exc:
                raise CamError(f"--log {log_path}: cannot write there ({exc.strerror or exc})") from None
            self._log_file.write(HOLE_LOG_HEADER + "\n")
            self._log_file.flush()
        self._pressed = 0
        self._injected = 0
        self._inject_now: int | None = None
        self._t_ns = 0
        self._anchor_real = time.monotonic()
        self._anchor_sim_ns = 0
        self._arrivals: deque[tuple[float, int]] = deque()  # (time.monotonic() it came, byte): the UART's buffer
        self._line_reader = None  # the reader process that stamps them (cam/sim/_maximus_line.py); firmware thread only
        self._line = threading.Lock()  # held as bytes move from the reader into _arrivals and out of it (see idle)
        self._reply_wall_s = 0.0  # when the last reply was written
        self._gie = False
        self._int_ext = False
        self._int_rda = False
        self._intf = False
        self._machine_mode = 0  # currentMachineMode: 0 = Jog, 1 = Drill
        self._axis_delay = int(axis_delay) & 0xFF
        self._state = POWER_UP
        self.moves_started = 0
        self.power_ups = 0  # banners printed so far
        self.error: BaseException | None = None
        # main()'s locals that survive from one label to the next
        self._delay_x = self._delay_y = self._delay_z_up = self._delay_z_down = 0
        self._drill_step_z_up = self._drill_step_z_down = 0

    # ------------------------------------------------------------------ control
    def start(self) -> "MaximusEmulator":
        """Open the pseudo-terminal pair and power the board up."""
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave, termios.TCSANOW)  # no echo, no line editing, 8 bit clean
        self.device_path = os.ttyname(self._slave)
        if self._speed != 1.0:
            _register_speed(self.device_path, self._speed)
        clear_fault_marker(self.device_path)  # a board just switched on holds no half packet
        self._open_line()
        self._thread = threading.Thread(target=self._serve, name="maximus-firmware", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the firmware thread and close the pseudo-terminal."""
        self._stop_event.set()
        self._wake.set()
        self._wake_line()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._close_line()
        for fd in (self._master, self._slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = -1
        if self.device_path and self._speed != 1.0:
            _register_speed(self.device_path, 1.0)
        if self._log_file is not None:
            self._log_file.close()
            self._log_file = None

    def reset(self) -> None:
        """Press the reset button: the firmware starts again at ``main()`` and prints its banner."""
        clear_fault_marker(self.device_path)
        self._reset_event.set()
        self._wake.set()
        self._wake_line()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def state(self) -> str:
        """Where the firmware is: the label whose ``getc()`` it waits in, or ``"BUSY"``."""
        return self._state

    @property
    def position_pulses(self) -> tuple[int, int, int]:
        """The emulator's own (x, y, z) count of enabled step pulses since power-up."""
        return tuple(self._pos)  # type: ignore[return-value]

    def wait_for_state(self, state: str, timeout_s: float = 30.0) -> bool:
        """Wait until the firmware waits for a byte at ``state``; False if it does not within ``timeout_s`` (a
        failure guard: a busy computer may take its time, so it is long)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self._state == state:
                return True
            time.sleep(0.002)
        return self._state == state

    @property
    def idle(self) -> bool:
        """Whether the firmware waits for a byte (at a label, not ``"BUSY"``) and none has come that it has not
        read: every byte written to the line by now is acted on, so nothing more moves or answers until the
        next one."""
        with self._line:
            if self._state in (BUSY, "CRASHED") or self._arrivals:
                return False
            return not self._line_readable()

    def wait_until_idle(self, timeout_s: float = 30.0) -> bool:
        """Wait until the firmware is :attr:`idle`: it has acted on every byte written to it so far (a move it
        was given has ended, its answer is written) and waits for the next.  False if not within ``timeout_s``
        (a failure guard).  What a test checks after it (nothing more was sent, nothing moves) is then settled,
        on a busy computer as on an idle one."""
        deadline = time.monotonic() + timeout_s
        while not self.idle:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.002)
        return True

    # ------------------------------------------------------------------ faults
    def drop_next_reply(self, *, match: int | None = None, skip: int = 0) -> None:
        """Do not send the next reply byte (the next one equal to ``match``, after skipping ``skip`` of them)."""
        self._add_fault(_ReplyFault("drop", match, skip, 0.0))

    def corrupt_next_reply(self, *, xor_mask: int = 0xFF, match: int | None = None, skip: int = 0) -> None:
        """Send the next reply byte XOR ``xor_mask`` instead (selection as in :meth:`drop_next_reply`)."""
        if not 0 < xor_mask <= 0xFF:
            raise CamError("xor_mask must be 1..255")
        self._add_fault(_ReplyFault("corrupt", match, skip, float(xor_mask)))

    def delay_next_reply(self, seconds: float, *, match: int | None = None, skip: int = 0) -> None:
        """Hold the next reply byte back ``seconds`` real seconds (the firmware waits too)."""
        self._add_fault(_ReplyFault("late", match, skip, float(seconds)))

    def trip_limit_switch(self, switch: int = LIMIT_SWITCH_X, *, skip_moves: int = 0) -> None:
        """Press ``switch`` at the first step pulse of the next move (after ``skip_moves`` moves).

        A move is a Jog packet, an Offset Positioning Packet or a Drill Data
        Packet that makes the firmware enable interrupts.  The switch is let go
        once the ISR has read port A.
        """
        if switch not in SWITCH_NAMES:
            raise CamError(f"not a switch byte: {switch:#04x}")
        with self._lock:
            self._trips.append([switch, int(skip_moves)])

    def _add_fault(self, fault: _ReplyFault) -> None:
        with self._lock:
            self._faults.append(fault)

    # ------------------------------------------------------------------ logs
    def port_log(self) -> PortLog:
        """Every write to ports B and D so far (see :class:`PortLog`)."""
        with self._lock:
            rows = list(self._port_rows)
        if not rows:
            return PortLog(np.zeros(0, np.int64), np.zeros(0, np.uint8), np.zeros(0, np.uint8))
        arr = np.array(rows, np.int64)
        return PortLog(arr[:, 0], arr[:, 1].astype(np.uint8), arr[:, 2].astype(np.uint8))

    def rx_log(self) -> list[tuple[int, int, str]]:
        """Every byte the firmware read: ``(t_ns, byte, where)``, where is a label or ``"isr"``."""
        with self._lock:
            return list(self._rx_rows)

    def tx_log(self) -> list[tuple[int, int, int | None]]:
        """Every reply: ``(t_ns, byte the listing sends, byte actually sent or None if dropped)``."""
        with self._lock:
            return list(self._tx_rows)

    def hole_log(self) -> list[tuple[int, int, int, int, int]]:
        """One row per drilled hole, at the bottom of its stroke: ``(hole, x_halfsteps, y_halfsteps,
        z_bottom_halfsteps, spindle)``.  Positions are motor half steps from the power-up position (a clock
        pulse counts 1 with the axis's MODE high, 2 with it low), X right, Y up, Z height (negative below the
        power-up height); ``spindle`` is RB2 (1: running).  ``hole`` counts from 1 since power-up."""
        with self._lock:
            return list(self._holes)

    def _log_hole(self) -> None:
        spindle_port, spindle_bit = SPINDLE_BIT
        row = (len(self._holes) + 1, *self._half_steps, (self._ports[spindle_port] >> spindle_bit) & 1)
        with self._lock:
            self._holes.append(row)  # type: ignore[arg-type]
        if self._log_file is not None:
            self._log_file.write(",".join(str(v) for v in row) + "\n")
            self._log_file.flush()

    def packet_log(self) -> list[tuple[str, bytes]]:
        """Every complete packet read: kind ``"mode"``, ``"jog"``, ``"offset"``, ``"init"`` or ``"drill"``."""
        with self._lock:
            return list(self._packets)

    # ------------------------------------------------------------------ thread
    def _serve(self) -> None:
        try:
            while True:
                try:
                    self._main()
                except _PowerOn:
                    self._reset_event.clear()
                    if not self._stop_event.is_set():
                        self._wake.clear()
                    self._discard_line()
                    continue
        except _Halt:
            return
        except BaseException as exc:  # a bug: keep it for the tests to see
            self.error = exc
            self._state = "CRASHED"

    def _check_halt(self) -> None:
        if self._stop_event.is_set():
            raise _Halt()
        if self._reset_event.is_set():
            raise _PowerOn()



def _register_speed(device: str, speed: float | None) -> None:
    """List (or, at speed 1, unlist) ``device`` in the host's ``CAM_MAXIMUS_EMULATOR_SPEEDS``: an emulator that
    runs faster than the firmware answers sooner than a real board could, which the host refuses unless it
    knows (:mod:`cam.drive.maximus.trust`).  Hosts in this process and in processes it starts read it."""
    items = [item for item in os.environ.get(EMULATOR_SPEEDS_ENV, "").split(",")
             if item and item.rpartition("=")[0] != device]
    if speed != 1.0:
        items.append(f"{device}={'inf' if speed is None else repr(float(speed))}")
    if items:
        os.environ[EMULATOR_SPEEDS_ENV] = ",".join(items)
    else:
        os.environ.pop(EMULATOR_SPEEDS_ENV, None)


def start_emulator(**options: Any) -> MaximusEmulator:
    """Start a MAXIMUS firmware emulator on a new pseudo-terminal (Unix only).

    Returns the running :class:`MaximusEmulator`; open its ``device_path``
    with pyserial (or ``MaximusBoard``), call ``stop()`` when done.  The
    keyword arguments are those of :class:`MaximusEmulator`.
    """
    if not hasattr(os, "openpty"):
        raise PortError("the MAXIMUS emulator needs pseudo-terminals (Linux, macOS)")
    try:
        return MaximusEmulator(**options).start()
    except OSError as exc:
        raise PortError(f"cannot open a pseudo-terminal for the MAXIMUS emulator: {exc}") from exc


def _travel_arg(values: Sequence[int] | None) -> tuple[int, int] | None:
    return None if values is None else (int(values[0]), int(values[1]))


SWITCH_OPTIONS = {name.lower().replace("_switch_", "-"): byte for byte, name in SWITCH_NAMES.items()}
"""The switch byte of each ``--trip`` name: ``home-x`` (HOME_SWITCH_X), ``limit-x``, ``home-y``, ... ``limit-z``."""


def travel_error(args: argparse.Namespace) -> str | None:
    """What is wrong with the ``--travel-AXIS LOW HIGH`` options (LOW must be below HIGH), or None."""
    for axis in "xyz":
        ends = getattr(args, f"travel_{axis}", None)
        if ends is not None and not ends[0] < ends[1]:
            return f"--travel-{axis} LOW HIGH needs LOW < HIGH, got {ends[0]} {ends[1]}"
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Serve an emulated MAXIMUS board until Ctrl-C; prints the device path to open."""
    parser = argparse.ArgumentParser(prog="python -m cam.sim.maximus", description=main.__doc__)
    parser.add_argument("--speed", type=float, default=1.0,
                        help="simulated seconds per real second (0 = never sleep); default 1")
    parser.add_argument("--log", metavar="FILE.csv", help=f"write one row per drilled hole: {HOLE_LOG_HEADER}")
    add_maximus_switch_options(parser)
    args = parser.parse_args(argv)
    if travel_error(args):
        parser.error(str(travel_error(args)))
    emulator = start_emulator(
        speed=args.speed or None,
        travel_x_pulses=_travel_arg(args.travel_x),
        travel_y_pulses=_travel_arg(args.travel_y),
        travel_z_pulses=_travel_arg(args.travel_z),
        axis_delay=args.axis_delay,
        log_path=args.log,
    )
    for name, skip in args.trip:
        emulator.trip_limit_switch(SWITCH_OPTIONS[name], skip_moves=skip)
    print(emulator.device_path, flush=True)
    if emulator._speed != 1.0:
        print(f"faster than the firmware: start hosts with {EMULATOR_SPEEDS_ENV}="
              f"{os.environ.get(EMULATOR_SPEEDS_ENV, '')} (they refuse replies sooner than a real board's)",
              file=sys.stderr, flush=True)
    return serve_until_stopped(emulator)


if __name__ == "__main__":
    raise SystemExit(main())
