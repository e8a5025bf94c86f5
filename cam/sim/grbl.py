"""An emulator of a grbl 1.1 controller on a pseudo-terminal (a test bench, not host code).

Written from grbl's documented serial interface (gnea/grbl ``doc/markdown/interface.md``, ``commands.md``,
``settings.md`` and the code tables in ``doc/csv/``), not from its source.  :class:`GrblEmulator` serves one
board in a background thread; a host opens :attr:`GrblEmulator.device_path` with pyserial as it would open
``/dev/ttyUSB0`` (``grbl:PATH`` for :mod:`cam.drive.grbl_link`).

What it answers, as grbl 1.1h does:

* the welcome line ``Grbl 1.1h ['$' for help]`` at power-up, after a soft reset and (``reset_on_open``, the
  Arduino's reset when a host opens the port) whenever a host opens the device; ``[MSG:'$H'|'$X' to unlock]``
  after it while in alarm (homing enabled at power-up, a reset in motion, a limit);
* one ``ok`` or ``error:n`` per line received (``\\r`` and ``\\n`` each end a line, an empty line is ``ok``);
  lines longer than 80 characters after stripping spaces and comments are ``error:11``;
* the real-time bytes, taken out of the stream as they arrive: ``?`` status report, ``!`` feed hold, ``~``
  cycle start, 0x18 soft reset (``ALARM:3`` first if it was moving), 0x85 jog cancel, the feed (0x90-0x94),
  rapid (0x95-0x97) and spindle (0x99-0x9D) overrides, 0x9E spindle stop, 0xA0/0xA1 coolant toggles;
* status reports ``<Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:0.000,0.000,0.000>``: ``MPos`` or ``WPos`` by
  ``$10`` bit 0, ``Bf:blocks,bytes`` by bit 1, ``WCO`` in the first report after a reset, after an offset
  changed and every 10 (moving) or 30 (idle) reports, ``Ov`` (with ``A:``) one report after a reset, after a
  change and every 10 / 20 reports;
* ``$`` (help), ``$$``, ``$x=val`` (checked: error 3, 4, 6, 10), ``$#``, ``$G``, ``$I``, ``$N``, ``$Nx=``,
  ``$C``, ``$X``, ``$H`` (``$22=1``; error 5 otherwise), ``$J=`` jogging, ``$RST=``;
* G-code: G0 G1 G2 G3 (offset and radius arcs in G17/G18/G19, cut into chords within ``$12``) G4 G10 L2/L20
  G17-G19 G20 G21 G28 G28.1 G30 G30.1 G40 G43.1 G49 G53 G54-G59 G61 G80 G90 G91 G91.1 G92 G92.1 G93 G94,
  M0 M1 M2 M30 M3 M4 M5 M7 M8 M9, F S T N; the grbl error codes for what it refuses (unsupported 20,
  modal group 21, undefined feed 22, repeated word 25, missing axis words 26, G53 with arcs 30, ...);
* alarms: ``ALARM:1`` (hard limit, injected by :meth:`GrblEmulator.trip_hard_limit`), ``ALARM:2`` (soft
  limits, ``$20=1``), ``ALARM:3`` (reset while moving), ``ALARM:9`` (homing switch not found); g-code is then
  ``error:9`` until ``$X`` or ``$H``, and after a limit nothing at all is taken until a soft reset.

The machine: a 128-byte serial receive buffer and a planner of 15 blocks, as grbl on an Uno.  Bytes cross the
line at ``baud`` (10 bits a byte, plus ``latency_s`` each way for the USB adapter), so a host that sends more
than the receive buffer holds loses bytes: the emulator counts them (:attr:`GrblEmulator.overflow_bytes`,
``events``).  A line leaves the receive buffer when the parser takes it; a motion waits there for room in the
planner and is answered ``ok`` once queued.  Each block moves at its feed (or the axes' ``$110-$112`` rate for
rapids, times the override) with the ``$120-$122`` acceleration along its direction, in a trapezoid whose
entry and exit speeds come from a look-ahead over the queued blocks (junction speeds from ``$11``, every
block able to stop by the end of the queue); positions are exact at every block end.  The planner running dry
while the job goes on is a *starvation* (:attr:`GrblEmulator.starvation_count`): a block finished and left
nothing queued behind the running one (or nothing at all), and another motion came within a second, with no
dwell, pause, ``$`` command or other line that waits for the machine in between.  (A planner with one block
has nothing to look ahead to: the machine slows down to be able to stop at that block's end.)

Time: a simulated clock that runs ``speed`` times faster than the wall clock (``speed=None``: as fast as it
can, never sleeping).  Motion advances in ticks of 1 ms of simulated time; the serial line and the latency are
on the same clock.  Machine coordinates: as grbl's with homing toward +X+Y+Z, the machine space is
``[-$13x, 0]``; the emulated carriage starts at ``start_mm`` (machine coordinates of power-up are 0 there).

Logs, for tests: :meth:`GrblEmulator.executed` (one :class:`ExecutedBlock` per planner block run, with its line
number and exact start and end machine positions), :meth:`GrblEmulator.lines` (every line taken, with its
answer), :attr:`GrblEmulator.events` (overflows, starvations, alarms, resets).
"""
from __future__ import annotations

import argparse
import math
import os
import re
import select
import sys
import termios
import threading
import time
import tty
from collections import deque
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Sequence

from ..errors import CamError, PortError

__all__ = ["GrblEmulator", "ExecutedBlock", "DEFAULT_SETTINGS", "WELCOME", "start_emulator", "main"]

WELCOME = "Grbl 1.1h ['$' for help]"
RX_BUFFER_BYTES = 128
PLANNER_BLOCKS = 15
LINE_MAX_CHARS = 80
TICK_S = 0.001
BOOT_WALL_S = 0.02     # a host opened the port: the board restarts this long after (the host's open has flushed)
STARVE_WINDOW_S = 1.0   # a planner dry for longer than this before the next motion: the host paused, not starved
MM_PER_INCH = 25.4

# grbl's $$ as listed in interface.md (defaults.h values), with $10=1 (MPos reports, grbl 1.1's default).
DEFAULT_SETTINGS: dict[int, float] = {
    0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0,
    20: 0, 21: 0, 22: 0, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 1.0, 30: 1000, 31: 0, 32: 0,
    100: 250.0, 101: 250.0, 102: 250.0, 110: 500.0, 111: 500.0, 112: 500.0,
    120: 10.0, 121: 10.0, 122: 10.0, 130: 200.0, 131: 200.0, 132: 200.0,
}
_INT_SETTINGS = {0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 30, 31, 32}
_BOOL_SETTINGS = {4, 5, 6, 13, 20, 21, 22, 32}
HELP = "[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]"
UNLOCK_MSG = "[MSG:'$H'|'$X' to unlock]"

# real-time bytes (commands.md, "Realtime commands")
RT_RESET, RT_STATUS, RT_HOLD, RT_START = 0x18, ord("?"), ord("!"), ord("~")
RT_DOOR, RT_JOG_CANCEL = 0x84, 0x85
RT_SPINDLE_STOP, RT_FLOOD, RT_MIST = 0x9E, 0xA0, 0xA1


class _GrblError(Exception):
    """A line refused with ``error:code``."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


@dataclass(frozen=True)
class ExecutedBlock:
    """One planner block the emulated machine ran to its end (or was halted in: ``halted``).

    ``line`` counts the lines the emulator took since power-up, from 1 (every line, ``$`` commands and empty
    lines too); ``kind`` is ``G0``, ``G1``, ``G2``, ``G3`` (one chord of an arc), ``G28``, ``G30``, ``jog``
    or ``home``; positions are machine coordinates in mm; ``feed_mm_min`` the programmed rate (rapids: the
    axes' maximum); ``t_end_s`` the simulated time the block ended."""

    line: int
    kind: str
    start_mm: tuple[float, float, float]
    end_mm: tuple[float, float, float]
    feed_mm_min: float
    t_end_s: float
    halted: bool = False


@dataclass
class _Block:
    line: int
    kind: str
    start: list[float]
    end: list[float]
    feed_mm_min: float          # programmed (G93: from the block's duration); rapids: max rate
    rapid: bool
    jog: bool = False
    length_mm: float = 0.0
    unit: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_mm_s2: float = 0.0
    max_mm_s: float = 0.0
    junction_mm_s: float = 0.0  # the most this block may be entered at (0 when it starts from a stop)


@dataclass
class _Parser:
    """grbl's g-code parser state (the modal groups, offsets and the planned position)."""

    motion: int = 0
    plane: int = 17
    inches: bool = False
    incremental: bool = False
    inverse_time: bool = False
    wcs: int = 0               # 0..5 = G54..G59
    spindle: int = 5
    coolant: set = field(default_factory=set)
    feed: float = 0.0          # mm/min (or 1/min with G93)
    rpm: float = 0.0
    tool: int = 0
    tlo_mm: float = 0.0
    g92_mm: list = field(default_factory=lambda: [0.0, 0.0, 0.0])


_WORD = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")
_SETTING = re.compile(r"^\$(\d+)=(.*)$")
_NUM = re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)$")


def _preparse(raw: str) -> str:
    """grbl's pre-parser: drop spaces and control characters, ``( )`` comments and ``;`` to the end, upper case."""
    out = []
    depth = 0
    for ch in raw:
        if depth:
            if ch == ")":
                depth = 0
            continue
        if ch == "(":
            depth = 1
        elif ch == ";":
            break
        elif ch > " " and ord(ch) < 0x7F:
            out.append(ch.upper())
    return "".join(out)


def _fmt(values: Sequence[float], inches: bool = False) -> str:
    if inches:
        return ",".join(f"{v / MM_PER_INCH:.4f}" for v in values)
    return ",".join(f"{v:.3f}" for v in values)


class GrblEmulator(AbstractContextManager):
    """A grbl 1.1 board on a pseudo-terminal (see the module docstring).

    Args:
        speed: simulated seconds per wall-clock second (1 = real time; ``None``: never sleep).
        settings: ``$`` settings to change from :data:`DEFAULT_SETTINGS` (``{22: 1}`` enables homing).
        baud: the serial line's rate (bytes take 10 bits each way).
        latency_s: the USB adapter's delay, each way, in simulated seconds.
        reset_on_open: restart the firmware (power-up: position 0, welcome line) when a host opens the port,
            as an Arduino does when pyserial raises DTR.
        start_mm: where the carriage stands at power-up, in the homed machine frame (for ``$H``'s travel).
        log_path: also write each executed block as a CSV row (see :data:`LOG_HEADER`).
    """

    def __init__(self, *, speed: Optional[float] = 1.0, settings: Optional[dict[int, float]] = None,
                 baud: int = 115200, latency_s: float = 0.001, reset_on_open: bool = True,
                 start_mm: Sequence[float] = (-100.0, -100.0, -10.0), log_path: Optional[str] = None) -> None:
        if speed is not None and not speed > 0:
            raise CamError(f"speed must be > 0 or None, got {speed!r}")
        if not baud > 0:
            raise CamError(f"baud must be > 0, got {baud!r}")
        self.settings: dict[int, float] = dict(DEFAULT_SETTINGS)
        for key, value in (settings or {}).items():
            if int(key) not in DEFAULT_SETTINGS:
                raise CamError(f"grbl has no setting ${key}")
            self.settings[int(key)] = float(value)
        self._speed = speed
        self._byte_s = 10.0 / baud
        self._latency_s = float(latency_s)
        self._reset_on_open = reset_on_open
        self._start_mm = [float(v) for v in start_mm]
        self._log_path = log_path
        self._log_file: Any = None
        self._lock = threading.Lock()
        self._stop_event = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._master = -1
        self.device_path = ""
        self.error: Optional[BaseException] = None
        # persistent data (EEPROM): work offsets, G28/G30 positions, startup lines
        self._wcs_mm = [[0.0, 0.0, 0.0] for _ in range(6)]
        self._g28_mm = [0.0, 0.0, 0.0]
        self._g30_mm = [0.0, 0.0, 0.0]
        self._startup = ["", ""]
        # logs and counters (kept across resets)
        self._executed: list[ExecutedBlock] = []
        self._lines: list[tuple[int, str, str]] = []
        self.events: list[tuple[float, str]] = []
        self.overflow_bytes = 0
        self.clock_slip_s = 0.0
        self.starvation_count = 0
        self.max_rx_bytes = 0
        self._t = 0.0
        self._line_no = 0
        self._trips: list[list[int]] = []
        self._power_up()

    # ------------------------------------------------------------------ power / reset
    def _power_up(self) -> None:
        if hasattr(self, "_pos"):   # a reset of the board: the carriage stays where it is
            self._phys_offset = [self._pos[i] + self._phys_offset[i] for i in range(3)]
        else:
            self._phys_offset = list(self._start_mm)   # physical position = machine position + offset
        self._pos = [0.0, 0.0, 0.0]
        self._homed = False
        self._alarm = bool(self.settings[22])
        self._feed_ov = self._rapid_ov = self._spindle_ov = 100
        self._reset_state(alarm_code=None, power_up=True)

    def _reset_state(self, alarm_code: Optional[int], power_up: bool = False) -> None:
        self._rx: deque[int] = deque()
        self._wire: deque[tuple[float, int]] = getattr(self, "_wire", deque())   # bytes after a reset still come
        self._tx: deque[tuple[float, bytes]] = getattr(self, "_tx", deque())
        self._planner: deque[_Block] = deque()
        self._s_mm = 0.0
        self._v = 0.0
        self._actions: Optional[deque] = None
        self._answered = False
        self._hold = False
        self._pause = False          # M0 / M1 program pause
        self._timed: Optional[tuple[float, Callable[[], None]]] = None
        self._critical = False
        self._check = False
        self._dry_at: Optional[float] = None
        self._parser = _Parser()
        self._parser_pos = list(self._pos)
        self._status_due = False
        self._wco_count = 0
        self._ov_count = 1
        self._last_ov = (100, 100, 100)
        self._spindle_stopped = False
        if alarm_code is not None:
            self._alarm = True
        self._state = "Alarm" if self._alarm else "Idle"
        self._send(WELCOME)
        if self._alarm:
            self._send(UNLOCK_MSG)
        else:
            self._run_startup_lines()

    def _run_startup_lines(self) -> None:
        for line in self._startup:
            if not line:
                continue
            try:
                self._parse_gcode(line, 0, queue=False)
                self._send(f">{line}:ok")
            except _GrblError as exc:
                self._send(f">{line}:error:{exc.code}")
            self._actions = None

    def _soft_reset(self) -> None:
        moving = self._v > 1e-9 or self._state in ("Run", "Jog", "Home")
        if self._state == "Home":
            code: Optional[int] = 6
        else:
            code = 3 if moving else None
        self._halt_motion()
        self._event("soft reset" + (f" in motion: ALARM:{code}" if code else ""))
        if code is not None:
            self._send(f"ALARM:{code}")
        self._reset_state(alarm_code=code)

    def _halt_motion(self) -> None:
        """Stop at once where the carriage is (a reset or a limit): the running block is logged as halted."""
        if self._planner:
            blk = self._planner[0]
            self._log_block(blk, list(self._pos), halted=True)
        self._planner.clear()
        self._v = 0.0
        self._s_mm = 0.0
        self._timed = None

    def _raise_alarm(self, code: int, critical: bool) -> None:
        self._halt_motion()
        self._alarm = True
        self._critical = critical
        self._state = "Alarm"
        self._actions = None
        self._event(f"ALARM:{code}")
        self._send(f"ALARM:{code}")
        if critical:
            self._send("[MSG:Reset to continue]")

    # ------------------------------------------------------------------ control
    def start(self) -> "GrblEmulator":
        """Open the pseudo-terminal and start the firmware thread."""
        master, slave = os.openpty()
        tty.setraw(slave, termios.TCSANOW)
        self.device_path = os.ttyname(slave)
        os.close(slave)   # a host opening the device is then seen (the master stops hanging up)
        os.set_blocking(master, False)
        self._master = master
        if self._log_path:
            self._log_file = open(self._log_path, "w", encoding="utf-8")
            self._log_file.write(LOG_HEADER + "\n")
        self._wall0 = time.monotonic()
        self._t0 = self._t
        # the most simulated time one pass may run without looking at the port (2 ms of wall time, at least
        # 20 ms simulated): a thread held up (load, the GIL) slips the clock rather than run the planner dry
        self._max_lag_s = max(0.02, 0.002 * (self._speed or 0.0))
        self._thread = threading.Thread(target=self._serve, name="grbl-firmware", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the firmware thread and close the pseudo-terminal."""
        self._stop_event.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self.unplug()
        if self._log_file is not None:
            self._log_file.close()
            self._log_file = None

    def unplug(self) -> None:
        """Pull the USB cable: the pseudo-terminal closes, the host's next read or write fails."""
        with self._lock:
            if self._master >= 0:
                try:
                    os.close(self._master)
                except OSError:
                    pass
                self._master = -1

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def trip_hard_limit(self, *, after_blocks: int = 0, fraction: float = 0.5) -> None:
        """Trip a limit switch (``ALARM:1``, hard limits on or not) when the motion ``after_blocks`` blocks
        from now has covered ``fraction`` of its length."""
        with self._lock:
            self._trips.append([int(after_blocks), float(fraction)])

    # ------------------------------------------------------------------ queries (thread-safe copies)
    @property
    def state(self) -> str:
        """grbl's machine state as a status report shows it (``Idle``, ``Run``, ``Hold:0``, ``Alarm``...)."""
        with self._lock:
            return self._state_text()

    @property
    def machine_position_mm(self) -> tuple[float, float, float]:
        with self._lock:
            return tuple(self._pos)  # type: ignore[return-value]

    @property
    def planner_blocks(self) -> int:
        with self._lock:
            return len(self._planner)

    @property
    def time_s(self) -> float:
        """The simulated clock."""
        return self._t

    def executed(self) -> list[ExecutedBlock]:
        with self._lock:
            return list(self._executed)

    def lines(self) -> list[tuple[int, str, str]]:
        """Every line taken: ``(line number, text as received, answer)`` (answer ``ok``, ``error:n`` or
        ``pending`` while it waits for the planner)."""
        with self._lock:
            return list(self._lines)

    def wait_for(self, predicate: Callable[["GrblEmulator"], bool], timeout_s: float = 5.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate(self):
                return True
            time.sleep(0.002)
        return predicate(self)

    # ------------------------------------------------------------------ thread
    def _sim_now(self, busy: bool) -> float:
        if self._speed is None:
            return self._t + (0.05 if busy else 0.0)
        return self._t0 + (time.monotonic() - self._wall0) * self._speed

    def _busy(self) -> bool:
        held = self._hold and self._v <= 1e-9
        return bool(self._wire or self._tx or self._timed or (self._planner and not held and not self._critical))

    def _serve(self) -> None:
        poller = select.poll()
        hung_up = True
        boot_at: Optional[float] = None
        try:
            poller.register(self._master, select.POLLIN)
            while not self._stop_event.is_set():
                with self._lock:
                    if self._master < 0:
                        return
                    events = poller.poll(0)
                    hup = any(ev & select.POLLHUP for _, ev in events)
                    if hung_up and not hup and self._reset_on_open:
                        boot_at = time.monotonic() + BOOT_WALL_S
                    hung_up = hup
                    if boot_at is not None and time.monotonic() >= boot_at:
                        boot_at = None
                        self._host_opened()
                    if not hup:
                        self._read_master(self._t)
                    now = self._sim_now(self._busy())
                    if now - self._t > self._max_lag_s:   # this thread was held up: the clock slips instead
                        self.clock_slip_s += now - self._t - self._max_lag_s
                        self._t0 -= now - self._t - self._max_lag_s
                        now = self._t + self._max_lag_s
                    self._advance(now)
                    self._flush_tx(hup or boot_at is not None)
                    busy = self._busy()
                wait_s = 0.0005 if busy or boot_at is not None else 0.02
                if self._speed is None and busy:
                    continue
                if hup:
                    time.sleep(wait_s)
                else:
                    poller.poll(wait_s * 1000.0)
        except BaseException as exc:  # a bug: keep it for the tests to see
            self.error = exc

    def _host_opened(self) -> None:
        self._event("host opened the port: the board restarts")
        if self._reset_on_open:
            self._tx.clear()
            self._wire.clear()
            self._power_up()

    def _read_master(self, now: float) -> None:
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        last = self._wire[-1][0] if self._wire else now
        for b in data:
            last = max(last, now + self._latency_s) + self._byte_s
            self._wire.append((last, b))

    def _flush_tx(self, hold_back: bool) -> None:
        if hold_back:
            return
        out = bytearray()
        while self._tx and (self._tx[0][0] <= self._t or self._speed is None):
            out += self._tx.popleft()[1]
        if out:
            try:
                os.write(self._master, bytes(out))
            except OSError:
                pass  # nobody reading or the buffer full: the bytes are lost, as on a real line

    def _send(self, text: str) -> None:
        data = (text + "\r\n").encode("ascii")
        ready = max(self._t + self._latency_s, self._tx[-1][0] if self._tx else 0.0) + len(data) * self._byte_s
        self._tx.append((ready, data))

    def _event(self, text: str) -> None:
        self.events.append((self._t, text))

    # ------------------------------------------------------------------ the clock
    def _advance(self, to: float) -> None:
        while self._t < to - 1e-12:
            self._deliver()
            self._service()
            if self._planner or self._timed:
                dt = min(TICK_S, to - self._t)
                self._motion(dt)
                self._t += dt
                self._timed_check()
            else:
                nxt = self._wire[0][0] if self._wire else to
                self._t = min(max(nxt, self._t), to)
        self._deliver()
        self._service()

    def _timed_check(self) -> None:
        if self._timed is not None and self._t >= self._timed[0] - 1e-12:
            done = self._timed[1]
            self._timed = None
            done()

    def _deliver(self) -> None:
        while self._wire and self._wire[0][0] <= self._t + 1e-12:
            self._rx_byte(self._wire.popleft()[1])

    def _rx_byte(self, b: int) -> None:
        if b == RT_RESET:
            self._soft_reset()
        elif b == RT_STATUS:
            if not self._critical and self._state != "Home":
                self._send(self._status_report())
        elif b == RT_HOLD:
            self._feed_hold()
        elif b == RT_START:
            self._cycle_start()
        elif b >= 0x80:
            self._realtime_ext(b)
        else:
            if len(self._rx) >= RX_BUFFER_BYTES:
                self._service()  # the parser may free room first, as grbl's would between two bytes
            if len(self._rx) >= RX_BUFFER_BYTES:
                self.overflow_bytes += 1
                self._event(f"serial receive buffer overflow: byte {b:#04x} lost")
                return
            self._rx.append(b)
            self.max_rx_bytes = max(self.max_rx_bytes, len(self._rx))

    def _realtime_ext(self, b: int) -> None:
        before = (self._feed_ov, self._rapid_ov, self._spindle_ov)
        if b == RT_JOG_CANCEL:
            if self._state == "Jog":
                self._hold = True
        elif 0x90 <= b <= 0x94:
            self._feed_ov = 100 if b == 0x90 else self._feed_ov + {0x91: 10, 0x92: -10, 0x93: 1, 0x94: -1}[b]
            self._feed_ov = min(200, max(10, self._feed_ov))
        elif 0x95 <= b <= 0x97:
            self._rapid_ov = {0x95: 100, 0x96: 50, 0x97: 25}[b]
        elif 0x99 <= b <= 0x9D:
            self._spindle_ov = 100 if b == 0x99 else self._spindle_ov + {0x9A: 10, 0x9B: -10, 0x9C: 1, 0x9D: -1}[b]
            self._spindle_ov = min(200, max(10, self._spindle_ov))
        elif b == RT_SPINDLE_STOP:
            if self._state == "Hold":
                self._spindle_stopped = not self._spindle_stopped
        elif b in (RT_FLOOD, RT_MIST):
            if self._state in ("Idle", "Run", "Hold"):
                self._parser.coolant ^= {8 if b == RT_FLOOD else 7}
        if (self._feed_ov, self._rapid_ov, self._spindle_ov) != before:
            self._ov_count = 0

    def _feed_hold(self) -> None:
        if self._state in ("Idle", "Run", "Jog"):
            self._hold = True
            if self._state != "Jog":
                self._state = "Hold"
            self._dry_at = None

    def _cycle_start(self) -> None:
        if self._state == "Hold" and self._v <= 1e-9:
            self._hold = False
            self._pause = False
            self._spindle_stopped = False
            self._state = "Run" if self._planner else "Idle"

    # ------------------------------------------------------------------ status
    def _state_text(self) -> str:
        if self._state == "Hold":
            return "Hold:1" if self._v > 1e-9 else "Hold:0"
        return self._state

    def _wco(self) -> list[float]:
        p = self._parser
        off = [self._wcs_mm[p.wcs][i] + p.g92_mm[i] for i in range(3)]
        off[2] += p.tlo_mm
        return off

    def _status_report(self) -> str:
        inches = bool(self.settings[13])
        mask = int(self.settings[10])
        wco = self._wco()
        if mask & 1:
            fields = [self._state_text(), "MPos:" + _fmt(self._pos, inches)]
        else:
            fields = [self._state_text(), "WPos:" + _fmt([self._pos[i] - wco[i] for i in range(3)], inches)]
        if mask & 2:
            fields.append(f"Bf:{PLANNER_BLOCKS - len(self._planner)},{RX_BUFFER_BYTES - len(self._rx)}")
        feed = self._v * 60.0 / (MM_PER_INCH if inches else 1.0)
        fields.append(f"FS:{feed:.1f},{self._rpm_now():.0f}" if inches else f"FS:{feed:.0f},{self._rpm_now():.0f}")
        moving = self._state in ("Run", "Jog", "Hold", "Home")
        wco_now = self._wco_count <= 0
        if wco_now:
            fields.append("WCO:" + _fmt(wco, inches))
            self._wco_count = 10 if moving else 30
        self._wco_count -= 1
        ov = (self._feed_ov, self._rapid_ov, self._spindle_ov)
        if self._ov_count <= 0 and not wco_now:
            fields.append("Ov:%d,%d,%d" % ov)
            acc = ("S" if self._parser.spindle == 3 else "C" if self._parser.spindle == 4 else "")
            acc += "".join(sorted(("F" if c == 8 else "M") for c in self._parser.coolant))
            if acc:
                fields.append("A:" + acc)
            self._ov_count = 10 if moving else 20
        elif not wco_now:
            self._ov_count -= 1
        return "<" + "|".join(fields) + ">"

    def _rpm_now(self) -> float:
        if self._parser.spindle == 5 or self._spindle_stopped:
            return 0.0
        return min(self.settings[30], self._parser.rpm * self._spindle_ov / 100.0)

    # ------------------------------------------------------------------ motion
    def _nominal_mm_s(self, blk: _Block) -> float:
        if blk.jog:
            v = blk.feed_mm_min / 60.0
        elif blk.rapid:
            v = blk.max_mm_s * self._rapid_ov / 100.0
        else:
            v = blk.feed_mm_min / 60.0 * self._feed_ov / 100.0
        return max(1e-6, min(v, blk.max_mm_s))

    def _exit_speed(self) -> float:
        """The most the running block may leave at: a backward pass over the queue, ending stopped."""
        v_next = 0.0
        for k in range(len(self._planner) - 1, 0, -1):
            blk = self._planner[k]
            v_next = min(blk.junction_mm_s, self._nominal_mm_s(blk),
                         math.sqrt(v_next * v_next + 2.0 * blk.accel_mm_s2 * blk.length_mm))
        return v_next

    def _motion(self, dt: float) -> None:
        while dt > 1e-12 and self._planner and not self._critical:
            blk = self._planner[0]
            a = blk.accel_mm_s2
            rem = blk.length_mm - self._s_mm
            if self._hold:
                v1 = max(0.0, self._v - a * dt)
                if self._v <= 1e-9:
                    self._v = 0.0
                    if self._state == "Jog":   # a jog cancel: stopped, the other jog blocks flushed
                        self._log_block(blk, list(self._pos), halted=True)
                        self._planner.clear()
                        self._s_mm = 0.0
                        self._hold = False
                        self._state = "Idle"
                        self._parser_pos = list(self._pos)
                    return
            else:
                v_exit = self._exit_speed()
                v_cap = math.sqrt(v_exit * v_exit + 2.0 * a * max(rem, 0.0))
                v_nom = self._nominal_mm_s(blk)
                v1 = min(self._v + a * dt, v_nom, v_cap)
                if v1 < self._v - a * dt and v_cap >= v_nom:   # an override dropped: slow down at a
                    v1 = self._v - a * dt
            ds = 0.5 * (self._v + v1) * dt
            if not self._hold:
                ds = max(ds, 0.5 * a * dt * dt)
            self._check_trip(blk, ds)
            if self._critical:
                return
            if ds >= rem - 1e-12:
                v_avg = max(0.5 * (self._v + v1), 1e-9)
                used = min(dt, rem / v_avg) if rem > 0 else 0.0
                v_end = self._v + (v1 - self._v) * (used / dt)
                self._v = v_end if self._hold else min(v_end, self._exit_speed())
                self._finish_block()
                dt -= max(used, 1e-9)
                continue
            self._s_mm += ds
            self._v = v1
            self._pos = [blk.start[i] + blk.unit[i] * self._s_mm for i in range(3)]
            dt = 0.0

    def _check_trip(self, blk: _Block, ds: float) -> None:
        if not self._trips:
            return
        trip = self._trips[0]
        if trip[0] > 0:
            return
        at = blk.length_mm * trip[1]
        if self._s_mm + ds >= at:
            self._trips.pop(0)
            self._s_mm = at
            self._pos = [blk.start[i] + blk.unit[i] * at for i in range(3)]
            self._raise_alarm(1, critical=True)

    def _finish_block(self) -> None:
        blk = self._planner.popleft()
        self._pos = list(blk.end)
        self._s_mm = 0.0
        self._log_block(blk, blk.end, halted=False)
        if self._trips and self._trips[0][0] > 0:
            self._trips[0][0] -= 1
        if self._state == "Run" and len(self._planner) <= 1 and self._dry_at is None:
            self._dry_at = self._t   # nothing queued behind the running block: no look-ahead left
        if not self._planner:
            self._v = 0.0
            if self._state in ("Run", "Jog"):
                self._state = "Idle"

    def _log_block(self, blk: _Block, end: Sequence[float], halted: bool) -> None:
        row = ExecutedBlock(blk.line, blk.kind, tuple(blk.start), tuple(end), blk.feed_mm_min, self._t, halted)
        self._executed.append(row)  # type: ignore[arg-type]
        if self._log_file is not None:
            self._log_file.write(",".join(str(v) for v in (
                row.line, row.kind, *(f"{c:.4f}" for c in row.start_mm), *(f"{c:.4f}" for c in row.end_mm),
                f"{row.feed_mm_min:.1f}", f"{row.t_end_s:.4f}", int(halted))) + "\n")
            self._log_file.flush()

    def _make_block(self, line: int, kind: str, start: list[float], end: list[float], feed_mm_min: float,
                    rapid: bool, jog: bool = False) -> Optional[_Block]:
        delta = [end[i] - start[i] for i in range(3)]
        length = math.sqrt(sum(d * d for d in delta))
        if length < 1e-9:
            return None
        unit = tuple(d / length for d in delta)
        accel = min(self.settings[120 + i] / abs(unit[i]) for i in range(3) if abs(unit[i]) > 1e-12)
        max_mm_s = min(self.settings[110 + i] / 60.0 / abs(unit[i]) for i in range(3) if abs(unit[i]) > 1e-12)
        if rapid:
            feed_mm_min = max_mm_s * 60.0
        return _Block(line, kind, list(start), list(end), feed_mm_min, rapid, jog, length, unit,  # type: ignore[arg-type]
                      accel, max_mm_s)

    def _junction(self, prev: _Block, blk: _Block) -> float:
        """The entry speed a corner allows (``$11`` junction deviation, the centripetal model)."""
        cos_turn = -sum(prev.unit[i] * blk.unit[i] for i in range(3))   # cos of the angle between the paths
        if cos_turn > 0.999999:
            return 0.0          # a reversal
        a = min(prev.accel_mm_s2, blk.accel_mm_s2)
        limit = min(self._nominal_mm_s(prev), self._nominal_mm_s(blk))
        if cos_turn < -0.999999:
            return limit        # straight on
        sin_half = math.sqrt(0.5 * (1.0 - cos_turn))
        return min(limit, math.sqrt(a * self.settings[11] * sin_half / (1.0 - sin_half)))

    def _queue_block(self, blk: _Block) -> None:
        if self._planner:
            blk.junction_mm_s = self._junction(self._planner[-1], blk)
        if self._dry_at is not None and not blk.jog and self._t - self._dry_at <= STARVE_WINDOW_S:
            self.starvation_count += 1
            self._event(f"planner starved: nothing queued behind the running block for "
                        f"{self._t - self._dry_at:.4f} s before line {blk.line}")
        self._dry_at = None
        self._planner.append(blk)
        if self._state == "Idle":
            self._state = "Jog" if blk.jog else "Run"

    # ------------------------------------------------------------------ lines
    def _take_line(self) -> Optional[str]:
        for i, b in enumerate(self._rx):
            if b in (10, 13):
                data = bytes(self._rx.popleft() for _ in range(i))
                self._rx.popleft()
                return data.decode("latin-1")
        return None

    def _service(self) -> None:
        while not self._critical:
            if self._actions is not None:
                if not self._run_actions():
                    return
                self._actions = None
                self._answer("ok")
                continue
            if self._timed is not None:
                return
            raw = self._take_line()
            if raw is None:
                return
            self._line_no += 1
            with_lock_row = (self._line_no, raw, "pending")
            self._lines.append(with_lock_row)
            self._answered = False
            try:
                self._handle_line(raw)
            except _GrblError as exc:
                self._actions = None
                self._answer(f"error:{exc.code}")
                continue
            if self._actions is None and not self._answered:
                self._answer("ok")

    def _answer(self, text: str) -> None:
        for k in range(len(self._lines) - 1, -1, -1):
            if self._lines[k][2] == "pending":
                self._lines[k] = (self._lines[k][0], self._lines[k][1], text)
                break
        self._send(text)

    def _run_actions(self) -> bool:
        """Run the current line's actions in order; False while one has to wait (planner full, sync, pause)."""
        while self._actions:
            if self._timed is not None:
                return False
            kind, arg = self._actions[0]
            if kind == "block":
                if len(self._planner) >= PLANNER_BLOCKS:
                    return False
                self._queue_block(arg)
            elif kind == "sync":
                if self._planner or self._state == "Hold" or self._timed is not None:
                    return False
                self._dry_at = None
            elif kind == "call":
                arg()
                if self._actions is None:   # it raised an alarm: the line is not answered
                    return False
            elif kind == "wait":   # a dwell or the homing cycle: the callable starts it and sets _timed
                arg()
                self._actions.popleft()
                return False
            elif kind == "pause":
                self._state = "Hold"
                self._hold = True
                self._pause = True
                self._actions[0] = ("paused", None)
                return False
            elif kind == "paused":
                if self._pause:
                    return False
            self._actions.popleft()
        return self._timed is None

    def _handle_line(self, raw: str) -> None:
        line = _preparse(raw)
        if len(line) > LINE_MAX_CHARS:
            raise _GrblError(11)
        if not line:
            return
        if line.startswith("$"):
            self._system_command(line)
            return
        if self._state == "Alarm":
            raise _GrblError(9)
        if self._state == "Jog":
            raise _GrblError(9)
        self._parse_gcode(line, self._line_no, queue=True)

    # ------------------------------------------------------------------ $ commands
    def _require_idle(self) -> None:
        if self._state not in ("Idle", "Alarm", "Check"):
            raise _GrblError(8)

    def _system_command(self, line: str) -> None:
        self._dry_at = None
        if line == "$":
            self._send(HELP)
        elif line == "$$":
            self._require_idle()
            for key in sorted(self.settings):
                value = self.settings[key]
                self._send(f"${key}={int(value)}" if key in _INT_SETTINGS else f"${key}={value:.3f}")
        elif line == "$#":
            self._require_idle()
            for k in range(6):
                self._send(f"[G{54 + k}:{_fmt(self._wcs_mm[k])}]")
            self._send(f"[G28:{_fmt(self._g28_mm)}]")
            self._send(f"[G30:{_fmt(self._g30_mm)}]")
            self._send(f"[G92:{_fmt(self._parser.g92_mm)}]")
            self._send(f"[TLO:{self._parser.tlo_mm:.3f}]")
            self._send("[PRB:0.000,0.000,0.000:0]")
        elif line == "$G":
            p = self._parser
            motion = {0: "G0", 1: "G1", 2: "G2", 3: "G3", 80: "G80"}[p.motion]
            coolant = " ".join(f"M{c}" for c in sorted(p.coolant)) or "M9"
            self._send(f"[GC:{motion} G{54 + p.wcs} G{p.plane} {'G20' if p.inches else 'G21'} "
                       f"{'G91' if p.incremental else 'G90'} {'G93' if p.inverse_time else 'G94'} M{p.spindle} "
                       f"{coolant} T{p.tool} F{p.feed / (MM_PER_INCH if p.inches else 1):.0f} S{p.rpm:.0f}]")
        elif line == "$I":
            self._send("[VER:1.1h.20190830:]")
            self._send(f"[OPT:V,{PLANNER_BLOCKS},{RX_BUFFER_BYTES}]")
        elif line == "$N":
            for k, text in enumerate(self._startup):
                self._send(f"$N{k}={text}")
        elif line.startswith("$N") and "=" in line:
            self._require_idle()
            idx = line[2:line.index("=")]
            if idx not in ("0", "1"):
                raise _GrblError(3)
            self._startup[int(idx)] = line[line.index("=") + 1:]
        elif line == "$C":
            self._require_idle()
            if self._state == "Alarm":
                raise _GrblError(9)
            if self._check:
                self._send("[MSG:Disabled]")
                self._answer("ok")
                self._answered = True
                self._reset_state(alarm_code=None)
                return
            self._check = True
            self._state = "Check"
            self._send("[MSG:Enabled]")
        elif line == "$X":
            self._dry_at = None
            if self._state == "Alarm":
                self._alarm = False
                self._state = "Idle"
                self._parser_pos = list(self._pos)
                self._send("[MSG:Caution: Unlocked]")
                self._event("alarm unlocked ($X)")
        elif line == "$H":
            self._require_idle()
            if not self.settings[22]:
                raise _GrblError(5)
            self._actions = deque([("wait", self._start_homing)])
        elif line.startswith("$J="):
            self._jog(line[3:])
        elif line.startswith("$RST="):
            self._require_idle()
            what = line[5:]
            if what not in ("$", "#", "*"):
                raise _GrblError(3)
            if what in ("$", "*"):
                self.settings = dict(DEFAULT_SETTINGS)
            if what in ("#", "*"):
                self._wcs_mm = [[0.0, 0.0, 0.0] for _ in range(6)]
                self._g28_mm = [0.0, 0.0, 0.0]
                self._g30_mm = [0.0, 0.0, 0.0]
            self._send("[MSG:Restoring defaults]")
        elif line == "$SLP":
            raise _GrblError(3)
        else:
            m = _SETTING.match(line)
            if not m:
                raise _GrblError(3)
            self._require_idle()
            key = int(m.group(1))
            if key not in self.settings:
                raise _GrblError(3)
            if not _NUM.match(m.group(2)):
                raise _GrblError(2)
            value = float(m.group(2))
            if value < 0:
                raise _GrblError(4)
            if key == 0 and value < 3:
                raise _GrblError(6)
            if key == 20 and value and not self.settings[22]:
                raise _GrblError(10)
            if key in _BOOL_SETTINGS:
                value = 1.0 if value else 0.0
            self.settings[key] = float(int(value)) if key in _INT_SETTINGS else value

    def _start_homing(self) -> None:
        """``$H``: Z up to its switch, then X and Y together, at the seek rate, then the pull-off."""
        self._state = "Home"
        phys = [self._pos[i] + self._phys_offset[i] for i in range(3)]
        seek_mm_s = self.settings[25] / 60.0
        pull = self.settings[27]
        ends = []
        for i in range(3):
            travel = self.settings[130 + i]
            toward_minus = int(self.settings[23]) >> i & 1
            ends.append(-travel if toward_minus else 0.0)
        if any(abs(phys[i] - ends[i]) > 1.5 * self.settings[130 + i] for i in range(3)):
            self._timed = (self._t, lambda: self._raise_alarm(9, critical=False))
            return
        t_z = abs(ends[2] - phys[2]) / seek_mm_s
        t_xy = max(abs(ends[0] - phys[0]), abs(ends[1] - phys[1])) / seek_mm_s
        t_locate = 3 * 2 * pull / (self.settings[24] / 60.0)
        start = list(self._pos)

        def done() -> None:
            for i in range(3):
                toward_minus = int(self.settings[23]) >> i & 1
                machine = (-self.settings[130 + i] + pull) if toward_minus else -pull
                phys_end = ends[i] + (pull if toward_minus else -pull)
                self._phys_offset[i] = phys_end - machine
                self._pos[i] = machine
            self._parser_pos = list(self._pos)
            self._homed = True
            self._alarm = False
            self._state = "Idle"
            self._executed.append(ExecutedBlock(self._line_no, "home", tuple(start), tuple(self._pos),  # type: ignore[arg-type]
                                                self.settings[25], self._t))
            self._event("homed")
            self._run_startup_lines()

        self._timed = (self._t + t_z + t_xy + t_locate, done)

    def _jog(self, text: str) -> None:
        if self._state not in ("Idle", "Jog"):
            raise _GrblError(8 if self._state != "Alarm" else 9)
        words = self._words(text)
        inches, incremental, machine = self._parser.inches, self._parser.incremental, False
        axes: dict[int, float] = {}
        feed: Optional[float] = None
        for letter, value in words:
            if letter == "G" and value in (20, 21, 90, 91, 53):
                if value in (20, 21):
                    inches = value == 20
                elif value in (90, 91):
                    incremental = value == 91
                else:
                    machine = True
            elif letter in "XYZ":
                axes["XYZ".index(letter)] = value
            elif letter == "F":
                feed = value
            else:
                raise _GrblError(16)
        if not axes:
            raise _GrblError(26)
        if feed is None or feed <= 0:
            raise _GrblError(22)
        scale = MM_PER_INCH if inches else 1.0
        base = list(self._parser_pos)
        target = list(base)
        wco = self._wco()
        for i, v in axes.items():
            v *= scale
            target[i] = base[i] + v if incremental else (v if machine else v + wco[i])
        if self.settings[20] and not self._within_travel(target):
            raise _GrblError(15)
        blk = self._make_block(self._line_no, "jog", base, target, feed * scale, rapid=False, jog=True)
        if blk is not None:
            self._parser_pos = list(target)
            self._actions = deque([("block", blk)])

    def _within_travel(self, target: Sequence[float]) -> bool:
        # either homing direction leaves grbl's machine space at [-travel, 0] (zero at the switch end)
        return all(-self.settings[130 + i] - 1e-6 <= target[i] <= 1e-6 for i in range(3))

    # ------------------------------------------------------------------ g-code
    @staticmethod
    def _words(line: str) -> list[tuple[str, float]]:
        words = []
        pos = 0
        while pos < len(line):
            if not line[pos].isalpha():
                raise _GrblError(1)
            m = _WORD.match(line, pos)
            if not m:
                raise _GrblError(2)
            words.append((m.group(1), float(m.group(2))))
            pos = m.end()
        return words

    def _parse_gcode(self, line: str, line_no: int, queue: bool) -> None:
        """Check a block completely (grbl executes nothing of a block it refuses), then set the parser state
        and list the actions (planner blocks, waits, calls) that run in grbl's order of execution."""
        words = self._words(line)
        g_groups: dict[str, float] = {}
        m_groups: dict[str, int] = {}
        values: dict[str, float] = {}
        for letter, value in words:
            if letter == "G":
                code = round(value, 1)
                if code in (0, 1, 2, 3, 80):
                    group = "motion"
                elif code in (4, 10, 28, 28.1, 30, 30.1, 53, 92, 92.1):
                    group = "nonmodal"
                elif code in (17, 18, 19):
                    group = "plane"
                elif code in (90, 91):
                    group = "distance"
                elif code == 91.1:
                    group = "arc"
                elif code in (93, 94):
                    group = "feedmode"
                elif code in (20, 21):
                    group = "units"
                elif code == 40:
                    group = "cutter"
                elif code in (43.1, 49):
                    group = "tlo"
                elif code in (54, 55, 56, 57, 58, 59):
                    group = "wcs"
                elif code in (59.1, 59.2, 59.3):
                    raise _GrblError(29)
                elif code == 61:
                    group = "path"
                else:
                    raise _GrblError(20)
                if group in g_groups:
                    raise _GrblError(21)
                g_groups[group] = code
            elif letter == "M":
                if value != int(value):
                    raise _GrblError(20)
                code = int(value)
                if code in (0, 1, 2, 30):
                    group = "stop"
                elif code in (3, 4, 5):
                    group = "spindle"
                elif code in (7, 8, 9):
                    group = "coolant"
                else:
                    raise _GrblError(20)
                if group in m_groups and group != "coolant":
                    raise _GrblError(21)
                m_groups[group] = code
            elif letter in "FIJKLNPRSTXYZ":
                if letter in values:
                    raise _GrblError(25)
                values[letter] = value
            else:
                raise _GrblError(20)
        p = self._parser
        inches = {20: True, 21: False}.get(int(g_groups.get("units", 20 if p.inches else 21)), p.inches)
        scale = MM_PER_INCH if inches else 1.0
        if "N" in values and not 0 <= values["N"] <= 9999999:
            raise _GrblError(27)
        for letter in "FST":
            if letter in values and values[letter] < 0:
                raise _GrblError(4)
        if "T" in values and values["T"] != int(values["T"]):
            raise _GrblError(23)
        if "T" in values and values["T"] > 255:
            raise _GrblError(38)
        nonmodal = g_groups.get("nonmodal")
        motion = int(g_groups["motion"]) if "motion" in g_groups else p.motion
        axis = {i: values["XYZ"[i]] * scale for i in range(3) if "XYZ"[i] in values}
        axis_cmd = None
        if nonmodal in (10, 28, 30, 92):
            axis_cmd = "nonmodal"
            if "motion" in g_groups and axis:
                raise _GrblError(24)
        elif axis:
            axis_cmd = "motion"
        if axis_cmd == "motion" and motion == 80 and axis:
            raise _GrblError(31)
        inverse_time = {93: True, 94: False}.get(int(g_groups.get("feedmode", 93 if p.inverse_time else 94)))
        feed = p.feed
        if "F" in values:
            feed = values["F"] * (1.0 if inverse_time else scale)
        elif inverse_time:
            feed = 0.0
        plane = int(g_groups.get("plane", p.plane))
        incremental = {90: False, 91: True}.get(int(g_groups.get("distance", 91 if p.incremental else 90)))
        wcs = int(g_groups["wcs"]) - 54 if "wcs" in g_groups else p.wcs
        tlo = p.tlo_mm
        if g_groups.get("tlo") == 43.1:
            if "Z" not in values or set(axis) - {2}:
                raise _GrblError(37)
            tlo = axis.pop(2)
            if not axis:
                axis_cmd = None
        elif g_groups.get("tlo") == 49:
            tlo = 0.0
        g92 = list(p.g92_mm)
        wcs_table = [list(r) for r in self._wcs_mm]
        actions: deque = deque()
        used = set("NFST") | ({"X", "Y", "Z"} if axis_cmd else set())

        def coord_offset(i: int) -> float:
            return wcs_table[wcs][i] + g92[i] + (tlo if i == 2 else 0.0)

        if "spindle" in m_groups or ("S" in values and p.spindle != 5):
            if p.spindle != 5 or m_groups.get("spindle", 5) != 5:
                actions.append(("sync", None))
        if "coolant" in m_groups:
            actions.append(("sync", None))
        if nonmodal == 4:
            if "P" not in values:
                raise _GrblError(28)
            if values["P"] < 0:
                raise _GrblError(4)
            used.add("P")
            dwell_s = values["P"]
            actions.append(("sync", None))
            actions.append(("wait", lambda: self._start_dwell(dwell_s)))
        new_wcs_row: Optional[tuple[int, list[float]]] = None
        base = list(self._parser_pos)
        if nonmodal == 10:
            if "L" not in values or "P" not in values:
                raise _GrblError(28)
            used |= {"L", "P"}
            if values["L"] not in (2, 20):
                raise _GrblError(20)
            if values["P"] != int(values["P"]) or not 0 <= values["P"] <= 6:
                raise _GrblError(29)
            row = wcs if int(values["P"]) == 0 else int(values["P"]) - 1
            if not axis:
                raise _GrblError(26)
            new = list(wcs_table[row])
            for i, v in axis.items():
                if values["L"] == 2:
                    new[i] = v
                else:
                    new[i] = base[i] - g92[i] - (tlo if i == 2 else 0.0) - v
            new_wcs_row = (row, new)
            wcs_table[row] = new
        if nonmodal == 92:
            if not axis:
                raise _GrblError(26)
            for i, v in axis.items():
                g92[i] = base[i] - wcs_table[wcs][i] - (tlo if i == 2 else 0.0) - v
        elif nonmodal == 92.1:
            g92 = [0.0, 0.0, 0.0]
        g53 = nonmodal == 53
        if g53 and motion not in (0, 1):
            raise _GrblError(30)
        # targets
        target = list(base)
        if axis_cmd is not None and nonmodal not in (10, 92):
            for i, v in axis.items():
                if g53:
                    target[i] = v
                elif incremental:
                    target[i] = base[i] + v
                else:
                    target[i] = v + coord_offset(i)
        blocks: list[_Block] = []
        end = list(base)
        if nonmodal in (28, 30):
            stored = self._g28_mm if nonmodal == 28 else self._g30_mm
            via = target if axis else list(base)
            blk = self._make_block(line_no, f"G{int(nonmodal)}", base, via, 0.0, rapid=True)
            if blk is not None:
                blocks.append(blk)
            blk = self._make_block(line_no, f"G{int(nonmodal)}", via, list(stored), 0.0, rapid=True)
            if blk is not None:
                blocks.append(blk)
            end = list(stored)
        elif nonmodal in (28.1, 30.1):
            pos = list(base)
            actions.append(("call", lambda: self._store_position(nonmodal, pos)))
        if axis_cmd == "motion" and nonmodal not in (28, 30):
            if motion in (1, 2, 3):
                if inverse_time and "F" not in values:
                    raise _GrblError(22)
                if not inverse_time and feed <= 0:
                    raise _GrblError(22)
            if motion in (0, 1):
                rate = feed
                if motion == 1 and inverse_time:
                    length = math.dist(base, target)
                    rate = length * feed
                blk = self._make_block(line_no, f"G{motion}", base, target, rate, rapid=motion == 0)
                if blk is not None:
                    blocks.append(blk)
                end = target
            elif motion in (2, 3):
                blocks.extend(self._arc(line_no, motion, plane, base, target, axis, values, scale, feed,
                                        inverse_time, used))
                end = target
        unused = set(values) - used
        if unused:
            raise _GrblError(36)
        if self.settings[20] and blocks and not all(self._within_travel(b.end) for b in blocks):
            actions = deque([("call", lambda: self._raise_alarm(2, critical=True))])
            self._actions = actions
            return
        # commit the parser state
        p.inches, p.inverse_time, p.plane, p.incremental = inches, bool(inverse_time), plane, bool(incremental)
        p.motion = motion
        if "F" in values or inverse_time:
            p.feed = feed
        if "S" in values:
            p.rpm = values["S"]
        if "T" in values:
            p.tool = int(values["T"])
        offsets_before = self._wco()
        p.wcs, p.tlo_mm, p.g92_mm = wcs, tlo, g92
        if new_wcs_row is not None:
            self._wcs_mm[new_wcs_row[0]] = new_wcs_row[1]
        if self._wco() != offsets_before:
            self._wco_count = 0
        if "spindle" in m_groups:
            spindle = m_groups["spindle"]
            actions.append(("call", lambda: setattr(self._parser, "spindle", spindle)))
        if "coolant" in m_groups:
            c = m_groups["coolant"]
            actions.append(("call", lambda: self._set_coolant(c)))
        if not self._check:
            actions.extend(("block", b) for b in blocks)
        self._parser_pos = list(end)
        stop = m_groups.get("stop")
        if stop is not None and not self._check:
            actions.append(("sync", None))
            if stop in (0, 1):
                actions.append(("pause", None))
            else:
                actions.append(("call", self._program_end))
        if queue and actions:
            self._actions = actions

    def _set_coolant(self, code: int) -> None:
        if code == 9:
            self._parser.coolant = set()
        else:
            self._parser.coolant.add(code)

    def _store_position(self, which: float, pos: list[float]) -> None:
        if which == 28.1:
            self._g28_mm = list(pos)
        else:
            self._g30_mm = list(pos)

    def _program_end(self) -> None:
        p = self._parser
        p.motion, p.plane, p.incremental, p.inverse_time, p.wcs = 1, 17, False, False, 0
        p.spindle, p.coolant = 5, set()
        self._feed_ov = self._rapid_ov = self._spindle_ov = 100
        self._wco_count = 0
        self._send("[MSG:Pgm End]")

    def _start_dwell(self, seconds: float) -> None:
        self._timed = (self._t + seconds, lambda: None)

    def _arc(self, line_no: int, motion: int, plane: int, base: list[float], target: list[float],
             axis: dict[int, float], values: dict[str, float], scale: float, feed: float, inverse_time: bool,
             used: set) -> list[_Block]:
        a0, a1, lin = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}[plane]
        if a0 not in axis and a1 not in axis:
            raise _GrblError(32)
        used |= {"I", "J", "K", "R"}   # grbl takes any I J K with an arc, in or out of its plane
        x0, y0 = base[a0], base[a1]
        x1, y1 = target[a0], target[a1]
        clockwise = motion == 2
        if "R" in values:
            r = values["R"] * scale
            dx, dy = x1 - x0, y1 - y0
            chord2 = dx * dx + dy * dy
            if chord2 < 1e-18:
                raise _GrblError(33)
            h2 = r * r - chord2 / 4.0
            if h2 < -1e-9 * max(1.0, r * r):
                raise _GrblError(34)
            h = math.sqrt(max(h2, 0.0)) / math.sqrt(chord2)
            if not clockwise:
                h = -h
            if r < 0:
                h = -h
                r = -r
            cx = x0 + 0.5 * (dx - dy * h * 2.0)
            cy = y0 + 0.5 * (dy + dx * h * 2.0)
        else:
            letters = "IJK"
            if letters[a0] not in values and letters[a1] not in values:
                raise _GrblError(35)
            cx = x0 + values.get(letters[a0], 0.0) * scale
            cy = y0 + values.get(letters[a1], 0.0) * scale
            r = math.hypot(x0 - cx, y0 - cy)
            r_end = math.hypot(x1 - cx, y1 - cy)
            if abs(r_end - r) > 0.005 and abs(r_end - r) > 0.001 * r:
                raise _GrblError(33)
        t0 = math.atan2(y0 - cy, x0 - cx)
        t1 = math.atan2(y1 - cy, x1 - cx)
        sweep = t1 - t0
        if clockwise:
            if sweep >= -1e-12:
                sweep -= 2.0 * math.pi
        elif sweep <= 1e-12:
            sweep += 2.0 * math.pi
        if "R" in values and abs(abs(sweep) - 2 * math.pi) < 1e-9:
            sweep = 0.0
        tol = self.settings[12]
        if r <= tol:
            n = 1
        else:
            step = 2.0 * math.acos(max(-1.0, 1.0 - tol / r))
            n = max(1, int(math.ceil(abs(sweep) / step - 1e-9)))
        length = math.hypot(abs(sweep) * r, target[lin] - base[lin])
        rate = length * feed if inverse_time else feed
        blocks = []
        prev = list(base)
        for k in range(1, n + 1):
            if k == n:
                pt = list(target)
            else:
                ang = t0 + sweep * k / n
                pt = list(base)
                pt[a0] = cx + r * math.cos(ang)
                pt[a1] = cy + r * math.sin(ang)
                pt[lin] = base[lin] + (target[lin] - base[lin]) * k / n
            blk = self._make_block(line_no, f"G{motion}", prev, pt, rate, rapid=False)
            if blk is not None:
                blocks.append(blk)
                prev = pt
        return blocks


LOG_HEADER = "line,kind,x0_mm,y0_mm,z0_mm,x1_mm,y1_mm,z1_mm,feed_mm_min,t_end_s,halted"
"""The columns of the ``log_path`` CSV: machine coordinates of each executed block's start and end."""


def start_emulator(**options: Any) -> GrblEmulator:
    """Start a grbl emulator on a new pseudo-terminal (Unix only); the keyword arguments are
    :class:`GrblEmulator`'s.  Open its ``device_path`` (``grbl:PATH``), call ``stop()`` when done."""
    if not hasattr(os, "openpty"):
        raise PortError("the grbl emulator needs pseudo-terminals (Linux, macOS)")
    try:
        return GrblEmulator(**options).start()
    except OSError as exc:
        raise PortError(f"cannot open a pseudo-terminal for the grbl emulator: {exc}") from exc


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Serve an emulated grbl 1.1 board until Ctrl-C; prints the device path to open."""
    parser = argparse.ArgumentParser(prog="python -m cam.sim.grbl", description=main.__doc__)
    parser.add_argument("--speed", type=float, default=1.0,
                        help="simulated seconds per real second (0 = never sleep); default 1")
    parser.add_argument("--baud", type=int, default=115200)
    parser.add_argument("--log", metavar="FILE.csv", help=f"write one row per executed block: {LOG_HEADER}")
    parser.add_argument("--set", action="append", default=[], metavar="N=VALUE",
                        help="a $ setting to change from grbl's defaults, e.g. --set 22=1 (repeatable)")
    args = parser.parse_args(argv)
    settings: dict[int, float] = {}
    for item in args.set:
        key, _, value = item.partition("=")
        try:
            settings[int(key.lstrip("$"))] = float(value)
        except ValueError:
            raise CamError(f"--set {item!r}: expected N=VALUE, e.g. 22=1") from None
    emulator = start_emulator(speed=args.speed or None, baud=args.baud, settings=settings, log_path=args.log)
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
