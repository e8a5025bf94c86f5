"""Ports opened by name, as pyserial opens URLs: the one place that reads a port name.

* ``"mock"`` -- the thesis's Debug Mode: nothing leaves the PC; every write is
  logged as ``(t_ns, data, strobe)``.  It ships in the library so that every
  job can run, and be checked, with no hardware.
* a device path such as ``"/dev/parport0"`` -- the real port through
  pyparallel (the optional ``cam[parport]`` extra), imported only when such
  a port is opened.
* ``"maximus:DEVICE"`` -- the MAXIMUS PCB driller's PIC board on RS-232
  (:mod:`cam.drive.maximus`): it takes drill files and jogs, not step/dir writes.
* ``"grbl:DEVICE?baud=N"`` -- a grbl 1.1 board on USB serial (:mod:`cam.drive.grbl_machine`): every job
  and move goes to it as G-code; it makes the steps itself.

Which back end a name opens, what it can do, and opening it are :mod:`cam.drive.machines` (one registry:
``open_port``, ``require``).  A step/dir port writes, and reads
its five input pins (:meth:`Port.read_inputs`: home, limit and e-stop switches,
``[inputs]`` of the machine file); *when* to write and what a switch means is the
runner's business.  The mock simulates switches from a schedule
(:class:`SwitchSchedule`: where each closes, in the machine frame).
"""
from __future__ import annotations

import os
import queue
import tempfile
import threading
import time
from pathlib import Path
from typing import IO, Any, Iterator, Optional

import numpy as np

from ..errors import CapabilityError, PortError
from ..settings import INPUT_BITS, MachineSettings
from ..verify.pinlog import HEADER as PIN_LOG_HEADER
from ..verify.pinlog import PinLog, PinLogPart, read_pin_log
from ..pins import axis_bits

__all__ = ["Port", "MockPort", "ParallelPort", "MAXIMUS_PREFIX",
           "GRBL_PREFIX", "SwitchSchedule", "IDLE_INPUTS", "input_mask", "surface_height_mm"]

IDLE_INPUTS = 0xF8
""":meth:`Port.read_inputs` with nothing connected: every input pin high (the port's pull-ups), bits 3..7."""


def input_mask(pin: int) -> int:
    """The bit of input ``pin`` (10, 11, 12, 13, 15) in :meth:`Port.read_inputs` (:data:`cam.settings.INPUT_BITS`)."""
    return 1 << INPUT_BITS[pin]

MAXIMUS_PREFIX = "maximus:"
GRBL_PREFIX = "grbl:"

class Port:
    """A place to send data-register and strobe writes to."""

    name = "port"

    def write(self, data: int, strobe: int, t_ns: int) -> None:
        """Set the data register and pin 1; ``t_ns`` is the job time of the write."""
        raise NotImplementedError

    def write_many(self, t_ns: np.ndarray, data: np.ndarray, strobe: np.ndarray) -> None:
        """Send a batch of writes in order (used by the simulated clock)."""
        for t, d, s in zip(t_ns.tolist(), data.tolist(), strobe.tolist()):
            self.write(d, s, t)

    def read_inputs(self) -> int:
        """The levels of the input pins now: bit 6 = pin 10 (ACK), 7 = pin 11 (BUSY), 5 = pin 12 (PAPER-OUT),
        4 = pin 13 (SELECT), 3 = pin 15 (ERROR), 1 = high (BUSY's hardware inversion undone); the other bits 0.
        A port that reads no inputs returns :data:`IDLE_INPUTS`."""
        return IDLE_INPUTS

    @property
    def reads_inputs(self) -> bool:
        """Whether :meth:`read_inputs` reads real or simulated switches (the runner samples them then)."""
        return False

    def close(self) -> None:
        """Release the port."""

    def __enter__(self) -> "Port":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_HELD_WRITES = 1 << 22
"""Writes a :class:`MockPort` holds in memory (about 40 MB); past them its log goes to a temporary file."""
_SPILL_ROW = np.dtype([("t", "<i8"), ("d", "u1"), ("s", "u1")])
"""One write in a :class:`MockPort`'s temporary file: time (ns), data register, strobe."""
_PENDING_WRITES = 1 << 14
"""Single writes (the real-time clock's) gathered before they join the log."""


_LOG_ROWS = 1 << 18
"""Rows of a streamed pin log formatted at a time, and gathered before they go to its writer thread."""


class _PinLogWriter:
    """Formats a streamed pin log's rows and writes them to its ``.part`` file in a thread of its own, so the
    send loop goes on meanwhile (the CSV is about 40 bytes a step period: the disk, not the loop, sets its pace).

    Holds at most :data:`_LOG_QUEUE` groups of about :data:`_LOG_ROWS` writes.  A failed write is kept in
    :attr:`error` (the rest is dropped); the port raises it at its next write or at the end."""

    def __init__(self, file: IO[bytes]) -> None:
        self.file = file
        self.error: Optional[OSError] = None
        self._queue: "queue.Queue[Optional[list[tuple[np.ndarray, np.ndarray, np.ndarray]]]]" = \
            queue.Queue(maxsize=_LOG_QUEUE)
        self._thread = threading.Thread(target=self._run, name="cam-pin-log", daemon=True)
        self._thread.start()

    def put(self, parts: "list[tuple[np.ndarray, np.ndarray, np.ndarray] | bytes]") -> None:
        """Write these ``(t_ns, data, strobe)`` arrays (int64, uint8, uint8) and bytes (a part's comment line), in
        order, after those put before."""
        self._queue.put(parts)

    def close(self) -> Optional[OSError]:
        """Write what was put and end the thread; the error that stopped the writing, if any."""
        self._queue.put(None)
        self._thread.join()
        return self.error

    def _run(self) -> None:
        from ..motion.kernels import pin_rows_kernel  # numba: only when a pin log streams

        while True:
            parts = self._queue.get()
            if parts is None:
                return
            if self.error is not None:
                continue
            try:
                rows: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
                for item in parts + [b""]:  # runs of rows, and a part's comment line between them
                    if not isinstance(item, bytes):
                        rows.append(item)
                        continue
                    if rows:
                        self._write_rows(rows, pin_rows_kernel)
                        rows = []
                    self.file.write(item)
            except OSError as exc:
                self.error = exc

    def _write_rows(self, rows: list[tuple[np.ndarray, np.ndarray, np.ndarray]], kernel: Any) -> None:
        t_ns, data, strobe = (np.concatenate(a) if len(a) > 1 else a[0] for a in zip(*rows))
        for i in range(0, len(t_ns), _LOG_ROWS):  # the rows np.savetxt(fmt="%d") writes, formatted compiled
            self.file.write(kernel(t_ns[i:i + _LOG_ROWS], data[i:i + _LOG_ROWS].astype(np.int64),
                                   strobe[i:i + _LOG_ROWS].astype(np.int64)))


_LOG_QUEUE = 4
"""Groups of writes a :class:`_PinLogWriter` holds before the send loop waits for the disk."""


class MockPort(Port):
    """The logging mock port.  :meth:`pin_log` returns everything written so far.

    Memory is bounded whatever the job's length: ``pin_log_path`` streams the pin log to this CSV file as the
    writes come (the file appears, whole, at :meth:`finish_pin_log`: written beside it, then renamed);
    without it, the first :data:`_HELD_WRITES` writes are held in memory and the rest go to an anonymous
    temporary file (13 bytes a write), read back only when :meth:`pin_log` or :meth:`pin_log_pieces` asks;
    with ``keep_log=False`` nothing is kept (``cam drill`` on the mock without ``--pin-log``).

    ``switches``: simulated home, limit and e-stop switches (:class:`SwitchSchedule`); the mock then counts the
    steps of its writes, and :meth:`read_inputs` gives the levels at the position they reached.

    One mock may log several runs of a command (``cam drill``'s travel to the work zero, then the job):
    :meth:`begin_part` marks where each begins and goes on with the time line (:class:`PinLogPart`).
    """

    name = "mock"

    def __init__(self, pin_log_path: "str | os.PathLike | None" = None, *, keep_log: bool = True,
                 switches: "Optional[SwitchSchedule]" = None) -> None:
        self.switches = switches
        self.time_offset_ns = 0
        """Added to the time of every write: runs one after another on one port (homing's phases) keep one
        time line in the pin log."""
        self.keep_log = keep_log or pin_log_path is not None
        """False: the writes are counted and dropped, as a real port sends them (a run nobody will decode)."""
        self._t: list[np.ndarray] = []
        self._d: list[np.ndarray] = []
        self._s: list[np.ndarray] = []
        self._held = 0
        self._spill: Optional[IO[bytes]] = None
        self._pending: list[tuple[int, int, int]] = []
        self.pin_log_path = Path(pin_log_path) if pin_log_path is not None else None
        self._file: Optional[IO[bytes]] = None
        self._writer: Optional[_PinLogWriter] = None
        self._to_log: list[tuple[np.ndarray, np.ndarray, np.ndarray] | bytes] = []  # not yet handed to the writer
        self._to_log_n = 0
        self.n_writes = 0
        self.last_t_ns: Optional[int] = None
        self.parts: list[PinLogPart] = []
        """The parts of the command marked so far (:meth:`begin_part`)."""

    @property
    def reads_inputs(self) -> bool:
        return self.switches is not None

    def read_inputs(self) -> int:
        """The simulated switches' levels where the writes so far took the tool (:data:`IDLE_INPUTS` without a
        schedule)."""
        if self.switches is None:
            return IDLE_INPUTS
        return self.switches.levels_now()

    def inputs_along(self, t_ns: np.ndarray, data: np.ndarray) -> np.ndarray:
        """``(K,)`` the input levels before each of these writes, were they sent (nothing is sent): the simulated
        clock looks a batch ahead."""
        assert self.switches is not None
        return self.switches.levels_along(np.asarray(t_ns, np.int64) + self.time_offset_ns, data)

    def write(self, data: int, strobe: int, t_ns: int) -> None:
        if self.switches is not None:
            self.switches.sent_one(int(data), int(t_ns) + self.time_offset_ns)
        self._pending.append((int(t_ns) + self.time_offset_ns, int(data), int(strobe)))
        if len(self._pending) >= _PENDING_WRITES:
            self._flush()

    def write_many(self, t_ns: np.ndarray, data: np.ndarray, strobe: np.ndarray) -> None:
        if self._pending:
            self._flush()
        n = len(t_ns)
        if not n:
            return
        if self.switches is not None:
            self.switches.sent(np.asarray(data, np.uint8), int(t_ns[-1]) + self.time_offset_ns)
        if not self.keep_log:  # counted and dropped (a job's every batch comes here: nothing made for it)
            self.n_writes += n
            self.last_t_ns = int(t_ns[-1]) + self.time_offset_ns
            return
        self._keep(np.asarray(t_ns, np.int64) + self.time_offset_ns, np.asarray(data, np.uint8),
                   np.asarray(strobe, np.uint8))

    def _keep(self, t_ns: np.ndarray, data: np.ndarray, strobe: np.ndarray) -> None:
        if not len(t_ns):
            return
        self.n_writes += len(t_ns)
        self.last_t_ns = int(t_ns[-1])
        if not self.keep_log:
            return
        if self.pin_log_path is None:
            self._hold(t_ns, data, strobe)
            return
        if self._writer is None:
            try:
                self._writer = _PinLogWriter(self._open_log())
            except OSError as exc:
                self._abandon_pin_log(exc)
        elif self._writer.error is not None:
            self._abandon_pin_log(self._writer.error)
        # (t_ns is the port's own, its offset added; data and strobe are copied: the caller's may be reused)
        self._to_log.append((t_ns, np.array(data, np.uint8), np.array(strobe, np.uint8)))
        self._to_log_n += len(t_ns)
        if self._to_log_n >= _LOG_ROWS:
            self._hand_to_writer()

    def begin_part(self, name: str, start_steps: tuple[int, int, int], gap_ns: int = 0) -> PinLogPart:
        """The writes from here on are part ``name`` of the command (``travel``, ``job``), which starts with the
        tool at ``start_steps`` (machine frame): marked in the pin log (its comment line, when it streams), its
        times ``gap_ns`` after the last write so far (the writes' own times run from 0 at the part's start)."""
        self._flush()
        if self.last_t_ns is not None:
            self.time_offset_ns = int(self.last_t_ns) + int(gap_ns)
        part = PinLogPart(str(name), self.n_writes, tuple(int(v) for v in start_steps),  # type: ignore[arg-type]
                          self.time_offset_ns)
        self.parts.append(part)
        if self.keep_log and self.pin_log_path is not None:  # in order with the rows; the file opens at a write
            self._to_log.append((part.line() + "\n").encode("ascii"))
        return part

    def _hand_to_writer(self) -> None:
        if self._to_log and self._writer is not None:
            self._writer.put(self._to_log)
        self._to_log, self._to_log_n = [], 0

    def _hold(self, t_ns: np.ndarray, data: np.ndarray, strobe: np.ndarray) -> None:
        room = max(0, _HELD_WRITES - self._held)
        if room:  # copies: the caller's arrays may be reused
            self._t.append(t_ns[:room].copy())
            self._d.append(data[:room].copy())
            self._s.append(strobe[:room].copy())
            self._held += min(room, len(t_ns))
        if len(t_ns) > room:
            if self._spill is None:
                self._spill = tempfile.TemporaryFile(prefix="cam-pinlog-")
            rows = np.empty(len(t_ns) - room, _SPILL_ROW)
            rows["t"], rows["d"], rows["s"] = t_ns[room:], data[room:], strobe[room:]
            self._spill.write(rows.tobytes())

    def pin_log_pieces(self, writes_per_piece: int = 1 << 20) -> Iterator[PinLog]:
        """Every write so far as consecutive :class:`PinLog` pieces of at most ``writes_per_piece`` writes (bounded
        memory: :func:`cam.verify.ramps.check_ramps` takes them)."""
        self._flush()
        if not self.keep_log:
            raise CapabilityError("this mock port keeps no pin log (opened with keep_log=False)")
        if self.pin_log_path is not None:
            yield self.pin_log()
            return
        for t, d, st in zip(self._t, self._d, self._s):
            for i in range(0, len(t), writes_per_piece):
                yield PinLog(t[i:i + writes_per_piece], d[i:i + writes_per_piece], st[i:i + writes_per_piece])
        if self._spill is not None:
            self._spill.flush()
            self._spill.seek(0)
            while True:
                rows = np.frombuffer(self._spill.read(writes_per_piece * _SPILL_ROW.itemsize), _SPILL_ROW)
                if not len(rows):
                    break
                yield PinLog(rows["t"].copy(), rows["d"].copy(), rows["s"].copy())
            self._spill.seek(0, os.SEEK_END)

    def _part(self) -> Path:
        assert self.pin_log_path is not None
        return self.pin_log_path.with_name(self.pin_log_path.name + ".part")

    def _flush(self) -> None:
        if self._pending:
            arr = np.array(self._pending, np.int64)
            self._pending = []
            self._keep(arr[:, 0], arr[:, 1].astype(np.uint8), arr[:, 2].astype(np.uint8))

    def finish_pin_log(self) -> Optional[Path]:
        """Close the streamed pin log and put it in place (atomically); None when nothing streams."""
        if self.pin_log_path is None:
            return None
        self._flush()
        if self._writer is None and self._to_log and self.keep_log:  # part lines before any write
            try:
                self._writer = _PinLogWriter(self._open_log())
            except OSError as exc:
                self._abandon_pin_log(exc)
        self._hand_to_writer()
        error = self._writer.close() if self._writer is not None else None
        self._writer = None
        if error is not None:
            self._abandon_pin_log(error)
        try:
            log = self._open_log()  # (a run of no writes still gets its header)
            log.flush()
            os.fsync(log.fileno())
            log.close()
            self._file = None
            os.replace(self._part(), self.pin_log_path)
        except OSError as exc:
            self._abandon_pin_log(exc)
        return self.pin_log_path

    def _open_log(self) -> IO[bytes]:
        """The streamed pin log's ``.part`` file, opened with its header line on first use."""
        if self._file is None:
            self._file = open(self._part(), "wb")
            self._file.write((PIN_LOG_HEADER + "\n").encode("ascii"))
        return self._file

    def _abandon_pin_log(self, exc: OSError) -> None:
        """A pin log write failed (a full disk, a lost folder): drop its ``.part`` file, keep counting the writes
        without a log, and raise one line naming the file and the cause."""
        if self._writer is not None:
            self._to_log, self._to_log_n = [], 0
            self._writer.close()
            self._writer = None
        if self._file is not None:
            try:
                self._file.close()
            except OSError:
                pass
            self._file = None
        try:
            os.unlink(self._part())
        except OSError:
            pass
        self.keep_log = False
        assert self.pin_log_path is not None
        raise PortError(f"{self.pin_log_path}: cannot write the pin log ({exc.strerror or exc}); nothing of it was "
                        f"kept") from None

    def pin_log(self) -> PinLog:
        """Every write so far, in order (read back from the file when it streams to one)."""
        self._flush()
        if self.pin_log_path is not None:
            if self._file is not None or self._to_log:
                self.finish_pin_log()
            return read_pin_log(self.pin_log_path)
        pieces = list(self.pin_log_pieces())
        if not pieces:
            return PinLog(np.zeros(0, np.int64), np.zeros(0, np.uint8), np.zeros(0, np.uint8), tuple(self.parts))
        if len(pieces) == 1 and not self.parts:
            return pieces[0]
        return PinLog(*(np.concatenate([getattr(p, f) for p in pieces]) for f in ("t_ns", "data", "strobe")),
                      tuple(self.parts))


class ParallelPort(Port):
    """The PC parallel port through pyparallel (Linux ppdev, e.g. ``/dev/parport0``)."""

    def __init__(self, device: str) -> None:
        self.name = device
        try:
            import parallel  # pyparallel, the optional [parport] extra: imported only when a real port is opened
        except ImportError:
            raise PortError(f"{device}: the parallel port needs pyparallel: pip install 'cam[parport]'") from None
        try:
            self._port = parallel.Parallel(port=device)
        except FileNotFoundError:
            raise PortError(
                f"{device}: no such parallel port (load the driver: 'sudo modprobe ppdev'; list ports: ls /dev/parport*)"
            ) from None
        except PermissionError:
            raise PortError(
                f"{device}: permission denied (add yourself to the 'lp' group: 'sudo usermod -aG lp $USER', then log in again)"
            ) from None
        except OSError as exc:
            raise PortError(f"{device}: cannot open the parallel port ({exc.strerror or exc})") from None

    def write(self, data: int, strobe: int, t_ns: int) -> None:
        try:
            self._port.setData(int(data))
            self._port.setDataStrobe(int(strobe))
        except OSError as exc:  # pragma: no cover - hardware
            raise PortError(f"{self.name}: write failed ({exc.strerror or exc})") from None

    @property
    def reads_inputs(self) -> bool:
        return True

    def read_inputs(self) -> int:
        """The status register's five input pins, one read (ppdev's PPRSTATUS; else pyparallel's ``getIn*``)."""
        try:
            raw = getattr(self._port, "PPRSTATUS", None)
            if raw is not None:  # pyparallel on Linux: the register as it is, BUSY (bit 7) inverted by the hardware
                return (int(raw()) ^ 0x80) & IDLE_INPUTS
            port = self._port  # pyparallel elsewhere: each pin's level (getInBusy undoes the inversion)
            return sum(input_mask(pin) for pin, level in (
                (10, port.getInAcknowledge()), (11, port.getInBusy()), (12, port.getInPaperOut()),
                (13, port.getInSelected()), (15, port.getInError())) if level)
        except OSError as exc:  # pragma: no cover - hardware
            raise PortError(f"{self.name}: reading the input pins failed ({exc.strerror or exc})") from None

    def close(self) -> None:  # pragma: no cover - hardware
        port = getattr(self, "_port", None)
        if port is not None:
            try:
                port.setData(0)
            finally:
                del self._port


def surface_height_mm(surface: Any, x_mm: Any, y_mm: Any) -> Any:
    """The height (mm, up positive) of a probe surface ``(z0, ax, ay, b, cx, cy)`` at machine X, Y in mm:
    ``z0 + ax*x + ay*y + b*((x-cx)^2 + (y-cy)^2)`` (numbers or arrays).

    >>> float(surface_height_mm((-1.0, 0.25, 0.0, 0.5, 2.0, 0.0), 4.0, 0.0))
    2.0
    """
    z0, ax, ay, b, cx, cy = surface
    return z0 + ax * x_mm + ay * y_mm + b * ((x_mm - cx) ** 2 + (y_mm - cy) ** 2)


class SwitchSchedule:
    """The mock port's simulated switches: where each closes, in the machine frame, or when.

    A position switch is closed while the tool's coordinate on its axis is at or beyond a place: a ``_min``
    limit at or below it, a ``_max`` limit at or above it, a home switch on its ``[homing]`` direction's side.
    The e-stop closes at a time of the run (ns, the writes' own times).  The probe (``inputs.probe``) is closed
    while the tool tip, ``-z * mm_per_step_z`` mm high, is at or below the machine file's ``[mock] probe_surface``
    at the tool's X, Y in mm (:func:`surface_height_mm`).  The levels follow the machine file's ``[inputs]`` (a
    closed active-low switch pulls its pin low); unwired pins read high.

    Args:
        settings: the pin map (to count the steps of the writes), ``[inputs]`` and ``[homing]``.
        start_steps: where the tool stands when the port opens (machine frame).
        places: ``switch name -> coordinate in steps`` (``"estop"``: seconds); None: the machine file's
            ``[mock]`` table (:meth:`cam.settings.MockSwitches.places`).

    Raises:
        PortError: a place for a switch the machine file does not wire.
    """

    def __init__(self, settings: MachineSettings, start_steps: tuple[int, int, int] = (0, 0, 0),
                 places: Optional[dict] = None) -> None:
        wired = settings.inputs.wired()
        places = settings.mock.places() if places is None else dict(places)
        clock, dirbit = axis_bits(settings)
        self.clock, self.dirbit = clock.astype(np.int64), dirbit.astype(np.int64)
        self.position_steps = np.asarray(start_steps, np.int64).reshape(3).copy()
        self.last_data = 0
        self.t_ns = 0
        self.wall_ns = 0  # time.monotonic_ns() at the last write (0: none yet)
        self.idle = IDLE_INPUTS
        for pin, high in wired.values():
            self.idle = self.idle & ~input_mask(pin) if high else self.idle | input_mask(pin)
        self.rules: list[tuple[int, bool, int, int, int]] = []  # (mask, active_high, axis, place, side)
        self.timed: list[tuple[int, bool, int]] = []  # (mask, active_high, t_ns)
        surface = settings.mock.surface()
        self.probe: Optional[tuple[int, bool, tuple[float, ...], tuple[float, float, float]]] = None
        """(mask, active_high, surface z0..cy, mm per step X, Y, Z) of the simulated probe, or None."""
        if surface is not None and "probe" in wired:
            pin, high = wired["probe"]
            self.probe = (input_mask(pin), high, surface, settings.mm_per_step_axes)
        for name, place in places.items():
            if name not in wired:
                raise PortError(f"the mock's switch {name} is not wired: give it a pin in [inputs]")
            pin, high = wired[name]
            if name == "estop":
                self.timed.append((input_mask(pin), high, int(round(float(place) * 1e9))))
                continue
            axis = "xyz".index(name.split("_")[1])
            side = (-1 if getattr(settings.homing, f"direction_{name[-1]}") == "-" else 1) \
                if name.startswith("home") else (-1 if name.endswith("min") else 1)
            self.rules.append((input_mask(pin), high, axis, int(place), side))

    def _levels(self, positions: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
        """``(K,)`` levels at ``(K, 3)`` positions and times."""
        closed = {}  # mask -> (K,) closed by any switch on that pin
        for mask, high, axis, place, side in self.rules:
            c = positions[:, axis] <= place if side < 0 else positions[:, axis] >= place
            closed[(mask, high)] = closed.get((mask, high), False) | c
        for mask, high, t in self.timed:
            closed[(mask, high)] = closed.get((mask, high), False) | (t_ns >= t)
        if self.probe is not None:
            mask, high, surface, per = self.probe
            p = np.asarray(positions, np.float64)
            touching = -p[:, 2] * per[2] <= surface_height_mm(surface, p[:, 0] * per[0], p[:, 1] * per[1])
            closed[(mask, high)] = closed.get((mask, high), False) | touching
        levels = np.full(len(positions), self.idle, np.int64)
        for (mask, high), c in closed.items():
            levels = np.where(c, (levels | mask) if high else (levels & ~mask), levels)
        return levels

    def _steps(self, data: np.ndarray, prev: int) -> np.ndarray:
        """``(K, 3)`` the signed step each write makes on each axis."""
        d = np.asarray(data, np.int64)
        before = np.concatenate([[prev], d[:-1]])
        rising = d & ~before
        return np.where((rising[:, None] & self.clock) != 0, np.where(d[:, None] & self.dirbit, 1, -1), 0)

    def levels_along(self, t_ns: np.ndarray, data: np.ndarray) -> np.ndarray:
        """``(K,)`` the levels before each of the writes ``data`` (after those before it), were they sent."""
        steps = self._steps(data, self.last_data)
        before = self.position_steps + np.cumsum(steps, axis=0) - steps
        return self._levels(before, np.asarray(t_ns, np.int64))  # sampled at each write's time, before it

    def levels_now(self) -> int:
        """The levels where the tool stands now (a real-time run's sample: its time runs on from the last
        write's by the wall clock)."""
        t_now = self.t_ns + (time.monotonic_ns() - self.wall_ns if self.wall_ns else 0)
        closed: dict[tuple[int, bool], bool] = {}
        for mask, high, axis, place, side in self.rules:  # plain integers: the real-time runner asks every write
            v = int(self.position_steps[axis])
            closed[(mask, high)] = closed.get((mask, high), False) or (v <= place if side < 0 else v >= place)
        for mask, high, t in self.timed:
            closed[(mask, high)] = closed.get((mask, high), False) or t_now >= t
        if self.probe is not None:
            mask, high, surface, per = self.probe
            x, y, z = (int(v) for v in self.position_steps)
            touching = -z * per[2] <= float(surface_height_mm(surface, x * per[0], y * per[1]))
            closed[(mask, high)] = closed.get((mask, high), False) or touching
        levels = self.idle
        for (mask, high), c in closed.items():
            if c:
                levels = (levels | mask) if high else (levels & ~mask)
        return int(levels)

    def sent_one(self, data: int, t_ns: int) -> None:
        """One write went out at job time ``t_ns`` (:meth:`sent` in plain integers, for the real-time runner)."""
        self.t_ns, self.wall_ns = t_ns, time.monotonic_ns()
        rising = data & ~self.last_data
        if rising:
            for a in range(3):
                if rising & int(self.clock[a]):
                    self.position_steps[a] += 1 if data & int(self.dirbit[a]) else -1
        self.last_data = data

    def sent(self, data: np.ndarray, t_ns: int) -> None:
        """These writes went out, the last at job time ``t_ns``: the tool moved on."""
        self.t_ns, self.wall_ns = t_ns, time.monotonic_ns()
        if len(data):
            self.position_steps = self.position_steps + self._steps(data, self.last_data).sum(axis=0)
            self.last_data = int(data[-1])
