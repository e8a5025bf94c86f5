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
(``speed=None``: no sleeping at all).

Interrupts are emulated where they can happen: while the listing has them
enabled (from just before a Jog, Offset or Drill move until just after its
reply) the emulator checks the UART and the limit-switch flag after every port
write and around each reply.  A received byte is then consumed by the UART
ISR; only EMERGENCYSTOP (0x80) does anything.

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
    drivers disabled until the next Jog or Offset packet enables them.
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
import select
import sys
import termios
import threading
import time
import tty
from collections import deque
from dataclasses import dataclass
from typing import Iterable, Iterator, Sequence

import numpy as np

from ..errors import CamError, PortError

__all__ = ["MaximusEmulator", "PortLog", "start_emulator", "main"]

from ..drive.maximus.protocol import *  # noqa: F401,F403  (the protocol, declared once)
from ..drive.maximus.protocol import AXIS_PINS, STEP_PIN

# Where the firmware waits for a byte (its labels; the 9-byte Init read has no label of its own).
POWER_UP = "POWER_UP"
MODE_SELECTION = "MODE_SELECTION"
JOG_DATA_INPUT = "JOG_DATA_INPUT"
DRILL_MODE1_INITIALIZE = "DRILL_MODE1_INITIALIZE"
INITIALIZE_DRILL_MODE = "INITIALIZE_DRILL_MODE"
DRILL_MODE1_INPUT = "DRILL_MODE1_INPUT"
BUSY = "BUSY"


class _Goto(Exception):
    """``goto_address(...)`` out of an interrupt service routine."""

    def __init__(self, label: str) -> None:
        super().__init__(label)
        self.label = label


class _PowerOn(Exception):
    """The board is reset: start again at ``main()``."""


class _Halt(Exception):
    """The emulator is stopped."""


@dataclass
class _ReplyFault:
    kind: str  # "drop", "corrupt" or "late"
    match: int | None
    skip: int
    value: float


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


class MaximusEmulator:
    """The PIC firmware of seed 000 Appendix 1, served on a pseudo-terminal.

    Use :func:`start_emulator` to create and start one.

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
        self._pressed = 0
        self._injected = 0
        self._inject_now: int | None = None
        self._t_ns = 0
        self._anchor_real = time.monotonic()
        self._anchor_sim_ns = 0
        self._rx: deque[int] = deque()
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
        self._thread = threading.Thread(target=self._serve, name="maximus-firmware", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the firmware thread and close the pseudo-terminal."""
        self._stop_event.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = -1

    def reset(self) -> None:
        """Press the reset button: the firmware starts again at ``main()`` and prints its banner."""
        self._reset_event.set()
        self._wake.set()

    def __enter__(self) -> "MaximusEmulator":
        return self

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

    def wait_for_state(self, state: str, timeout_s: float = 2.0) -> bool:
        """Wait until the firmware waits for a byte at ``state``; False on timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self._state == state:
                return True
            time.sleep(0.002)
        return self._state == state

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
                    self._rx.clear()
                    self._drain_master()
                    continue
        except _Halt:
            return
        except BaseException as exc:  # a bug: keep it for the tests to see
            self.error = exc
            self._state = "CRASHED"

    def _drain_master(self) -> None:
        while self._master >= 0:
            r, _, _ = select.select([self._master], [], [], 0)
            if not r:
                return
            try:
                if not os.read(self._master, 4096):
                    return
            except OSError:
                return

    def _check_halt(self) -> None:
        if self._stop_event.is_set():
            raise _Halt()
        if self._reset_event.is_set():
            raise _PowerOn()

    # ------------------------------------------------------------------ main()
    def _main(self) -> None:
        """``main()`` of Appendix 1, with its labels as a state machine."""
        self._gie = self._int_ext = self._int_rda = self._intf = False
        self._output_port(PORT_B, POWER_UP_B)
        self._output_port(PORT_D, POWER_UP_D)
        self._write_master(BANNER)
        self.power_ups += 1
        self._gie = False  # disable_interrupts(GLOBAL)
        while self._getc(POWER_UP) != ISMACHINEREADY:
            pass
        self._putc(MACHINEREADY)
        label = MODE_SELECTION
        steps = {
            MODE_SELECTION: self._mode_selection,
            JOG_DATA_INPUT: self._jog_data_input,
            DRILL_MODE1_INITIALIZE: self._drill_mode1_initialize,
            DRILL_MODE1_INPUT: self._drill_mode1_input,
        }
        while True:
            try:
                label = steps[label]()
            except _Goto as jump:
                label = jump.label

    def _mode_selection(self) -> str:
        b = self._getc(MODE_SELECTION)
        self._log_packet("mode", bytes([b]))
        if b == ISMACHINEREADY:
            self._putc(MACHINEREADY)
            return MODE_SELECTION
        if b == OPENJOGMODE:
            self._putc(JOGMODEON)
            return JOG_DATA_INPUT
        if b == OPENDRILLMODE1:
            self._putc(DRILLMODE1ON)
            return DRILL_MODE1_INITIALIZE
        if b == OPENDRILLMODE2:  # "!Not Completed!"
            self._putc(DRILLMODE2ON)
            return JOG_DATA_INPUT
        return JOG_DATA_INPUT  # no case matched: execution falls through to the JOG_DATA_INPUT label

    def _jog_data_input(self) -> str:
        self._machine_mode = 0
        data = self._read_packet(4, JOG_DATA_INPUT, "jog")
        self._intf = False  # bit_clear(*0x0B,1)
        if (data[0] >> 6) == 0:
            self._putc(JOGMODEOFF)
            self._gie = False
            return MODE_SELECTION
        axis_step = data[1] | (data[2] << 8)
        self._axis_delay = data[3]
        config = data[0]
        axis_select = (config & 0xC0) >> 6
        axis_mode = int(bool(config & 0x20))
        axis_dir = int(bool(config & 0x10))
        spindle = config & 0x01
        self._begin_move()
        self._enable_interrupts()
        self._output_bit(ENABLE_X, 1)
        self._output_bit(ENABLE_Y, 1)
        self._output_bit(ENABLE_Z, 1)
        self._output_bit(SPINDLE_BIT, spindle)
        pins = {1: (MODE_X, DIR_X), 2: (MODE_Y, DIR_Y), 3: (MODE_Z, DIR_Z)}
        mode_pin, dir_pin = pins[axis_select]
        self._output_bit(mode_pin, axis_mode)
        self._output_bit(dir_pin, axis_dir)
        self._constspeed(axis_step, self._axis_delay, axis_select)
        self._reply_after_move(JOGMODEDONE)
        return JOG_DATA_INPUT

    def _drill_mode1_initialize(self) -> str:
        self._machine_mode = 1
        d = self._read_packet(10, DRILL_MODE1_INITIALIZE, "offset")
        self._intf = False  # bit_clear(*0x0B,1)
        config = d[0]
        step_x = d[1] | (d[2] << 8)
        step_y = d[3] | (d[4] << 8)
        step_z = d[5] | (d[6] << 8)
        self._delay_x, self._delay_y, self._delay_z_up = d[7], d[8], d[9]
        self._begin_move()
        self._enable_interrupts()
        self._output_bit(ENABLE_X, 1)
        self._output_bit(ENABLE_Y, 1)
        self._output_bit(ENABLE_Z, 1)
        self._output_bit(MODE_X, int(bool(config & 0x08)))
        self._output_bit(MODE_Y, int(bool(config & 0x10)))
        self._output_bit(MODE_Z, int(bool(config & 0x20)))
        self._output_bit(DIR_X, int(bool(config & 0x01)))
        self._output_bit(DIR_Y, int(bool(config & 0x02)))
        self._output_bit(DIR_Z, int(bool(config & 0x04)))
        self._constspeed(step_z, self._delay_z_up, 3)
        self._constspeed(step_x, self._delay_x, 1)
        self._constspeed(step_y, self._delay_y, 2)
        self._reply_after_move(ATOFFSETPOS)
        # Initialize Drill Mode: read and run with interrupts disabled
        d = self._read_packet(9, INITIALIZE_DRILL_MODE, "init")
        config = d[0]
        self._drill_step_z_up = d[1] | (d[2] << 8)
        self._drill_step_z_down = d[3] | (d[4] << 8)
        self._delay_x, self._delay_y, self._delay_z_up, self._delay_z_down = d[5], d[6], d[7], d[8]
        self._output_bit(MODE_X, int(bool(config & 0x01)))
        self._output_bit(MODE_Y, int(bool(config & 0x02)))
        self._output_bit(MODE_Z, int(bool(config & 0x04)))
        self._output_bit(DIR_Z, 1)  # Z down
        self._constspeed(self._drill_step_z_up, self._delay_z_up, 3)
        self._putc(DRILLMODE1INITIALIZED)
        return DRILL_MODE1_INPUT

    def _drill_mode1_input(self) -> str:
        d = self._read_packet(5, DRILL_MODE1_INPUT, "drill")
        if not (d[0] >> 7):  # Continue Drilling Flag reset: leave Drill mode
            self._putc(DRILLMODE1DONE)
            self._gie = False
            return MODE_SELECTION
        if (d[0] & 0x40) >> 6:  # Start Drilling Flag set: answer without moving
            self._putc(ONEHOLEDRILLED)
            self._gie = False
            return DRILL_MODE1_INPUT
        config = d[0]
        step_x = d[1] | (d[2] << 8)
        step_y = d[3] | (d[4] << 8)
        self._output_bit(DIR_X, int(bool(config & 0x01)))
        self._output_bit(DIR_Y, int(bool(config & 0x02)))
        self._begin_move()
        self._enable_interrupts()
        self._constspeed_xy(step_x, step_y, self._delay_x, self._delay_y)
        self._output_bit(DIR_Z, 1)  # Z down
        self._constspeed(self._drill_step_z_down, self._delay_z_down, 3)
        self._output_bit(DIR_Z, 0)  # Z up
        self._constspeed(self._drill_step_z_up, self._delay_z_up, 3)
        self._reply_after_move(ONEHOLEDRILLED)
        return DRILL_MODE1_INPUT

    def _reply_after_move(self, reply: int) -> None:
        """The end of a move: reply with interrupts still enabled, then disable them."""
        if self._inject_now is not None:  # a move with no pulse: the injected switch trips now
            self._press_injected()
        self._poll_interrupts()
        self._putc(reply)
        # putc() returns as the byte starts out (87 us on the line); disable_interrupts follows a few
        # instructions later, long before a host can answer: only bytes already received count here.
        self._poll_interrupts(fetch=False)
        self._gie = False  # disable_interrupts(GLOBAL)

    # ------------------------------------------------------------------ motion
    def _constspeed(self, n: int, delay: int, pin: int) -> None:
        """``constspeed()`` / ``constspeed2()``: n pulses of period 2 * delay * 100 us on one axis."""
        step = STEP_PIN[pin]
        for _ in range(n):
            self._output_bit(step, 1)
            self._dly_100us(delay)
            self._output_bit(step, 0)
            self._dly_100us(delay)
        self._output_bit(step, 1)  # "Add last step": back to the idle level

    def _constspeed_xy(self, step_x: int, step_y: int, delay_x: int, delay_y: int) -> None:
        """``constspeed_xy()``: the dog-leg XY move."""
        delay_xy = delay_y if delay_x < delay_y else delay_x
        if step_x > step_y:
            step_xy, axis, step_more = step_y, 0, step_x - step_y
        else:
            step_xy, axis, step_more = step_x, 1, step_y - step_x
        for _ in range(step_xy):
            self._output_bit(STEP_X, 1)
            self._output_bit(STEP_Y, 1)
            self._dly_100us(delay_xy)
            self._output_bit(STEP_X, 0)
            self._output_bit(STEP_Y, 0)
            self._dly_100us(delay_xy)
        self._output_bit(STEP_X, 1)
        self._output_bit(STEP_Y, 1)
        pin, delay = (STEP_X, delay_x) if axis == 0 else (STEP_Y, delay_y)
        for _ in range(step_more):
            self._output_bit(pin, 1)
            self._dly_100us(delay)
            self._output_bit(pin, 0)
            self._dly_100us(delay)
        self._output_bit(pin, 1)

    def _dly_100us(self, n: int) -> None:
        self._advance(n * DELAY_UNIT_NS)

    def _advance(self, ns: int) -> None:
        self._t_ns += ns
        self._check_halt()
        if self._speed is None or ns == 0:
            return
        target = self._anchor_real + (self._t_ns - self._anchor_sim_ns) / 1e9 / self._speed
        ahead = target - time.monotonic()
        if ahead > 0.001:
            self._wake.wait(ahead)
            self._check_halt()

    def _anchor(self) -> None:
        self._anchor_real = time.monotonic()
        self._anchor_sim_ns = self._t_ns

    # ------------------------------------------------------------------ pins
    def _output_bit(self, pin: tuple[int, int], value: int) -> None:
        port, bit = pin
        old = self._ports[port]
        self._output_port(port, (old & ~(1 << bit)) | ((1 if value else 0) << bit))

    def _output_port(self, port: int, value: int) -> None:
        old = self._ports[port]
        self._ports[port] = value
        with self._lock:
            self._port_rows.append((self._t_ns, port, value))
        for axis, (p, step_b, dir_b, en_b, sign) in enumerate(AXIS_PINS):
            if p != port:
                continue
            if (value >> step_b) & 1 and not (old >> step_b) & 1 and (value >> en_b) & 1:
                self._pos[axis] += sign if (value >> dir_b) & 1 else -sign
                self._after_step()
        if self._gie:
            self._poll_interrupts()

    def _after_step(self) -> None:
        if self._inject_now is not None:
            self._press_injected()
        else:
            self._update_switches()

    def _press_injected(self) -> None:
        self._injected |= self._inject_now or 0
        self._inject_now = None
        self._update_switches()

    def _update_switches(self) -> None:
        bits = self._injected
        x, y, z = self._pos
        tx, ty, tz = self._travel
        if tx is not None:
            bits |= HOME_SWITCH_X if x < tx[0] else 0
            bits |= LIMIT_SWITCH_X if x > tx[1] else 0
        if ty is not None:
            bits |= HOME_SWITCH_Y if y < ty[0] else 0
            bits |= LIMIT_SWITCH_Y if y > ty[1] else 0
        if tz is not None:
            bits |= HOME_SWITCH_Z if z > tz[1] else 0
            bits |= LIMIT_SWITCH_Z if z < tz[0] else 0
        if self._pressed == 0 and bits != 0:
            self._intf = True  # the AND gate's output falls: RB0 H_TO_L edge
        self._pressed = bits

    def _input_a(self) -> int:
        return 0x3F & ~self._pressed  # RA0..RA5, switches active low

    # ------------------------------------------------------------------ interrupts
    def _begin_move(self) -> None:
        self.moves_started += 1
        with self._lock:
            for trip in self._trips:
                if trip[1] > 0:
                    trip[1] -= 1
                    continue
                self._inject_now = trip[0]
                self._trips.remove(trip)
                break

    def _enable_interrupts(self) -> None:
        self._int_ext = self._int_rda = True
        self._gie = True
        self._poll_interrupts()

    def _poll_interrupts(self, fetch: bool = True) -> None:
        while self._gie:
            if self._int_ext and self._intf:
                self._isr_ext()
                continue
            if self._int_rda:
                if fetch:
                    self._fill_rx(0.0)
                if self._rx:
                    self._isr_rda()
                    continue
            return

    def _isr_ext(self) -> None:
        """``isr_ext()``: a limit switch was pressed."""
        self._gie = False
        self._advance(DEBOUNCE_NS)
        conditions = self._input_a()
        self._injected = 0
        self._update_switches()
        if conditions == 0x3E:  # RA0 = 0
            self._output_bit(DIR_X, 1)
            self._constspeed(STEPSBACKATLIMIT, self._axis_delay, 1)
            self._putc(HOME_SWITCH_X)
        elif conditions == 0x3D:  # RA1 = 0
            self._output_bit(DIR_X, 0)
            self._constspeed(STEPSBACKATLIMIT, self._axis_delay, 1)
            self._putc(LIMIT_SWITCH_X)
        elif conditions == 0x3B:  # RA2 = 0
            self._output_bit(DIR_Y, 1)
            self._constspeed(STEPSBACKATLIMIT, self._axis_delay, 2)
            self._putc(HOME_SWITCH_Y)
        elif conditions == 0x37:  # RA3 = 0
            self._output_bit(DIR_Y, 0)
            self._constspeed(STEPSBACKATLIMIT, self._axis_delay, 2)
            self._putc(LIMIT_SWITCH_Y)
        elif conditions == 0x2F:  # RA4 = 0
            self._putc(HOME_SWITCH_Z)
        elif conditions == 0x1F:  # RA5 = 0
            self._putc(LIMIT_SWITCH_Z)
        else:  # 0x3F (released) or several switches: return from the ISR
            self._intf = False
            self._gie = True
            return
        raise _Goto(JOG_DATA_INPUT if self._machine_mode == 0 else MODE_SELECTION)

    def _isr_rda(self) -> None:
        """``serial_isr()``: a byte arrived during a move."""
        self._gie = False
        b = self._rx.popleft()
        with self._lock:
            self._rx_rows.append((self._t_ns, b, "isr"))
        if b == EMERGENCYSTOP:
            self._output_bit(ENABLE_X, 0)
            self._output_bit(ENABLE_Y, 0)
            self._output_bit(ENABLE_Z, 0)
            self._putc(MACHINESTOPPED)
            raise _Goto(JOG_DATA_INPUT if self._machine_mode == 0 else MODE_SELECTION)
        self._gie = True  # any other byte: read and forgotten

    # ------------------------------------------------------------------ UART
    def _fill_rx(self, timeout_s: float) -> None:
        if self._master < 0:
            raise _Halt()
        try:
            r, _, _ = select.select([self._master], [], [], timeout_s)
            if r:
                data = os.read(self._master, 4096)
                self._rx.extend(data)
        except OSError:
            self._wake.wait(max(timeout_s, 0.01))

    def _getc(self, where: str) -> int:
        self._state = where
        while not self._rx:
            self._check_halt()
            self._fill_rx(0.05)
        b = self._rx.popleft()
        with self._lock:
            self._rx_rows.append((self._t_ns, b, where))
        self._state = BUSY
        self._anchor()
        return b

    def _read_packet(self, n: int, where: str, kind: str) -> bytes:
        data = bytes(self._getc(where) for _ in range(n))
        self._log_packet(kind, data)
        return data

    def _log_packet(self, kind: str, data: bytes) -> None:
        with self._lock:
            self._packets.append((kind, data))

    def _putc(self, byte: int) -> None:
        sent: int | None = byte
        delay_s = self.late_reply_s
        with self._lock:
            for fault in list(self._faults):
                if fault.match is not None and fault.match != byte:
                    continue
                if fault.skip > 0:
                    fault.skip -= 1
                    continue
                self._faults.remove(fault)
                if fault.kind == "drop":
                    sent = None
                elif fault.kind == "corrupt" and sent is not None:
                    sent = sent ^ int(fault.value)
                elif fault.kind == "late":
                    delay_s += fault.value
        if delay_s > 0:
            self._wake.wait(delay_s)
            self._check_halt()
            self._anchor()
        with self._lock:
            self._tx_rows.append((self._t_ns, byte, sent))
        if sent is not None:
            self._write_master(bytes([sent]))

    def _write_master(self, data: bytes) -> None:
        if self._master < 0:
            raise _Halt()
        try:
            os.write(self._master, data)
        except OSError:
            pass  # nobody listening: the bytes are lost, as on a real line


def start_emulator(
    *,
    speed: float | None = 1.0,
    travel_x_pulses: tuple[int, int] | None = None,
    travel_y_pulses: tuple[int, int] | None = None,
    travel_z_pulses: tuple[int, int] | None = None,
    late_reply_s: float = 0.0,
    axis_delay: int = 0,
) -> MaximusEmulator:
    """Start a MAXIMUS firmware emulator on a new pseudo-terminal (Unix only).

    Returns the running :class:`MaximusEmulator`; open its ``device_path``
    with pyserial (or ``MaximusBoard``), call ``stop()`` when done.  The
    arguments are those of :class:`MaximusEmulator`.
    """
    if not hasattr(os, "openpty"):
        raise PortError("the MAXIMUS emulator needs pseudo-terminals (Linux, macOS)")
    try:
        return MaximusEmulator(
            speed=speed, travel_x_pulses=travel_x_pulses, travel_y_pulses=travel_y_pulses,
            travel_z_pulses=travel_z_pulses, late_reply_s=late_reply_s, axis_delay=axis_delay,
        ).start()
    except OSError as exc:
        raise PortError(f"cannot open a pseudo-terminal for the MAXIMUS emulator: {exc}") from exc


def _travel_arg(values: Sequence[int] | None) -> tuple[int, int] | None:
    return None if values is None else (int(values[0]), int(values[1]))


def main(argv: Sequence[str] | None = None) -> int:
    """Serve an emulated MAXIMUS board until Ctrl-C; prints the device path to open."""
    parser = argparse.ArgumentParser(prog="python -m cam.sim.maximus", description=main.__doc__)
    parser.add_argument("--speed", type=float, default=1.0,
                        help="simulated seconds per real second (0 = never sleep); default 1")
    for axis in "xyz":
        parser.add_argument(f"--travel-{axis}", type=int, nargs=2, metavar=("LOW", "HIGH"),
                            help=f"{axis.upper()} travel ends in pulses from power-up (limit switches)")
    args = parser.parse_args(argv)
    emulator = start_emulator(
        speed=args.speed or None,
        travel_x_pulses=_travel_arg(args.travel_x),
        travel_y_pulses=_travel_arg(args.travel_y),
        travel_z_pulses=_travel_arg(args.travel_z),
    )
    print(emulator.device_path, flush=True)
    try:
        while emulator.error is None:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        emulator.stop()
    if emulator.error is not None:
        print(f"emulator stopped: {emulator.error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
