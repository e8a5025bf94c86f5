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
* ``$`` (help), ``$$``, ``$x=val`` (checked: error 3, 4, 6, 10), ``$#``, ``$G``, ``$I`` (``[VER:1.1h.20190830:
  build info]`` and ``[OPT:V,15,128]``), ``$I=`` (the build info, ``build_info`` at power-up), ``$N``, ``$Nx=``,
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

The parts: this module (the port, the clock, the thread, the controls), ``_grbl_motion`` (planner and
motion, homing, limits), ``_grbl_realtime`` (real-time bytes and status reports), ``_grbl_system`` (lines,
answers and ``$`` commands), ``_grbl_gcode`` (the G-code parser) and ``_grbl_base`` (constants and types).

Logs, for tests: :meth:`GrblEmulator.executed` (one :class:`ExecutedBlock` per planner block run, with its line
number and exact start and end machine positions), :meth:`GrblEmulator.lines` (every line taken, with its
answer), :attr:`GrblEmulator.events` (overflows, starvations, alarms, resets).
"""
from __future__ import annotations

import argparse
import os
import select
import termios
import threading
import time
import tty
from collections import deque
from contextlib import AbstractContextManager
from typing import Any, Callable, Optional, Sequence

from ._serve import serve_until_stopped
from ..errors import CamError, PortError
from ._grbl_base import (BOOT_WALL_S, DEFAULT_SETTINGS, LINE_MAX_CHARS, LOG_HEADER, PLANNER_BLOCKS, RX_BUFFER_BYTES,
                         TICK_S, UNLOCK_MSG, WELCOME,
                         Block, ExecutedBlock, GrblCodeError, ParserState)
from ._grbl_gcode import _GCode
from ._grbl_motion import _Motion
from ._grbl_probe import _Probe, parse_surface_spec
from ._grbl_realtime import _Realtime
from ._grbl_system import _System

__all__ = ["GrblEmulator", "ExecutedBlock", "DEFAULT_SETTINGS", "WELCOME", "start_emulator", "main"]


class GrblEmulator(_System, _GCode, _Realtime, _Motion, _Probe, AbstractContextManager):
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
        build_info: the board's build info in its EEPROM, which ``$I`` reports (``[VER:1.1h.20190830:NAME]``)
            and ``$I=NAME`` sets: two emulators with different ones are two boards that tell themselves apart.
        probe_surface: the work's surface its probe touches (``G38.2``...: :mod:`cam.sim._grbl_probe`), ``(z0, ax,
            ay, b, cx, cy)`` in grbl's machine frame (mm, up positive) or that as text; None: no probe (nothing
            touches).
    """

    def __init__(self, *, speed: Optional[float] = 1.0, settings: Optional[dict[int, float]] = None,
                 baud: int = 115200, latency_s: float = 0.001, reset_on_open: bool = True,
                 start_mm: Sequence[float] = (-100.0, -100.0, -10.0), log_path: Optional[str] = None,
                 build_info: str = "", rx_buffer_bytes: int = RX_BUFFER_BYTES, planner_blocks: int = PLANNER_BLOCKS,
                 welcome: str = WELCOME, probe_surface: "Optional[Sequence[float] | str]" = None) -> None:
        if speed is not None and not speed > 0:
            raise CamError(f"speed must be > 0 or None, got {speed!r}")
        if not baud > 0:
            raise CamError(f"baud must be > 0, got {baud!r}")
        self.settings: dict[int, float] = dict(DEFAULT_SETTINGS)
        for key, value in (settings or {}).items():
            if int(key) not in DEFAULT_SETTINGS:
                raise CamError(f"grbl has no setting ${key}")
            self.settings[int(key)] = float(value)
        self.rx_buffer_bytes = int(rx_buffer_bytes)   # grblHAL: 1024; FluidNC: its own
        self.planner_size = int(planner_blocks)       # planner blocks; grblHAL: 100 and more
        self.welcome = welcome                        # grblHAL: "GrblHAL 1.1f ['$' or '$HELP' for help]"
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
        if len(build_info) > LINE_MAX_CHARS or not all(" " < ch < "\x7f" and ch not in "()[];" for ch in build_info):
            raise CamError(f"build_info must be at most {LINE_MAX_CHARS} printable characters without spaces, "
                           f"brackets or ';' (what $I= can store), got {build_info!r}")
        self.build_info = build_info
        """The build info in the EEPROM (``$I`` reports it, ``$I=`` sets it; kept across resets)."""
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
        self._probe_surface = parse_surface_spec(probe_surface) if isinstance(probe_surface, str) else \
            (None if probe_surface is None else parse_surface_spec(",".join(str(float(v)) for v in probe_surface)))
        self._prb: tuple[list[float], bool] = ([0.0, 0.0, 0.0], False)  # the last probe's [PRB:...] (kept by $#)
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
        self._planner: deque[Block] = deque()
        self._s_mm = 0.0
        self._v = 0.0
        self._actions: Optional[deque] = None
        self._probe: Optional[dict] = None  # the probing cycle under way (cam.sim._grbl_probe)
        self._answered = False
        self._hold = False
        self._pause = False          # M0 / M1 program pause
        self._timed: Optional[tuple[float, Callable[[], None]]] = None
        self._critical = False
        self._check = False
        self._dry_at: Optional[float] = None
        self._parser = ParserState()
        self._parser_pos = list(self._pos)
        self._status_due = False
        self._wco_count = 0
        self._ov_count = 1
        self._last_ov = (100, 100, 100)
        self._spindle_stopped = False
        if alarm_code is not None:
            self._alarm = True
        self._state = "Alarm" if self._alarm else "Idle"
        self._send(self.welcome)
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
            except GrblCodeError as exc:
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
        self._tx.clear()   # what the board said at power-up went to no one: no host had the port open
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

    @property
    def state(self) -> str:
        """grbl's state as a status report shows it (``Idle``, ``Run``, ``Hold:0``...); queries return copies."""
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
                    self._flush_tx(discard=hup or boot_at is not None)
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

    def _flush_tx(self, discard: bool) -> None:
        """Write the replies whose time has come; with no host on the port (or the board restarting) they
        are lost, as on a real line."""
        out = bytearray()
        while self._tx and (self._tx[0][0] <= self._t or self._speed is None):
            out += self._tx.popleft()[1]
        if out and not discard:
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


    # ------------------------------------------------------------------ status


    # ------------------------------------------------------------------ motion


    # ------------------------------------------------------------------ lines


    # ------------------------------------------------------------------ $ commands


    # ------------------------------------------------------------------ g-code




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
    parser.add_argument("--probe-surface", metavar="Z0,AX,AY,B,CX,CY",
                        help="the surface the probe touches (G38.2): z0 + ax*x + ay*y + b*((x-cx)^2 + (y-cy)^2), "
                        "machine mm (write it --probe-surface=-5,0.01: it may start with '-')")
    args = parser.parse_args(argv)
    settings: dict[int, float] = {}
    for item in args.set:
        key, _, value = item.partition("=")
        try:
            settings[int(key.lstrip("$"))] = float(value)
        except ValueError:
            raise CamError(f"--set {item!r}: expected N=VALUE, e.g. 22=1") from None
    try:
        surface = parse_surface_spec(args.probe_surface) if args.probe_surface else None
    except ValueError as exc:
        raise CamError(f"--probe-surface: {exc}") from None
    emulator = start_emulator(speed=args.speed or None, baud=args.baud, settings=settings, log_path=args.log,
                              probe_surface=surface)
    print(emulator.device_path, flush=True)
    return serve_until_stopped(emulator)


if __name__ == "__main__":
    raise SystemExit(main())
