"""The PIC's UART as the MAXIMUS firmware emulator serves it: bytes from the host through the pseudo-terminal,
each stamped with the time it arrived, and replies (with the faults a test asked for) back to it.

A real PIC takes a byte the moment its stop bit ends: the UART sets RCIF and, with interrupts enabled, the
``serial_isr`` runs at once, in the middle of a ``dly_100us`` if need be (seed 000 Appendix 1: ``#int_rda``,
``enable_interrupts(INT_RDA)`` before each move).  The emulator's thread, though, runs when the operating
system (and its process's GIL) lets it: on a busy computer it is late, then catches up.  So the bytes are not
taken when that thread happens to look, but when they arrived: a reader process of its own waits in ``select``
on the line and stamps each chunk as it comes (cam/sim/_maximus_line.py), and the firmware acts on a byte at the
simulated time of its stamp (:meth:`_Uart._sim_ns`, through the clock's anchor).  Before it lets simulated time
pass a moment, the firmware's thread collects every byte that arrived by then, waiting for one the reader has
not passed on yet.

A part of :class:`cam.sim.maximus.MaximusEmulator`.
"""
from __future__ import annotations

import os
import select
import time
from typing import Optional

from ._maximus_base import BUSY, _Halt
from ._maximus_line import LineReader


class _Uart:
    """``getc()`` / ``putc()``, the line's arrival stamps and the pseudo-terminal's master side."""

    # ------------------------------------------------------------------ the line: bytes stamped as they arrive
    def _open_line(self) -> None:
        """Start the reader process (after the pseudo-terminal is open) when the emulator keeps the firmware's
        timing; a sped-up one (speed None) reads the line in its firmware thread.

        Its arrival stamps matter only on the firmware's clock: sped up, a byte is due as soon as it is there
        (:meth:`_byte_due`).  Sped-up emulators run by the hundred in one test session; since they each started a
        reader process, three whole-suite runs had a sped-up board that did not answer a Jog-mode packet within
        the host's 1.0 s margin (never when run alone), with no pause of the emulator's process measured then (no
        collection, no thread holding the GIL).  The cause is not found; a sped-up emulator does without the
        process it does not need.
        """
        self._line_wake_r, self._line_wake_w = os.pipe()
        os.set_blocking(self._line_wake_w, False)
        reader = LineReader(self._master)
        self._line_reader = reader if self._speed is None else reader.start()

    def _close_line(self) -> None:
        """Stop the reader process (before the pseudo-terminal is closed)."""
        if self._line_reader is not None:
            self._line_reader.stop()
            self._line_reader = None
            for fd in (self._line_wake_r, self._line_wake_w):
                os.close(fd)
            self._line_wake_r = self._line_wake_w = -1  # a late reset() must not write to a reused descriptor

    def _take_bytes(self) -> None:
        """Move every byte that arrived by now into the receive buffer, with its arrival stamp (firmware thread;
        under ``_line``, so that :attr:`~cam.sim.maximus.MaximusEmulator.idle` sees a byte in one place or the
        other)."""
        with self._line:
            if self._line_reader is None:
                return
            for stamp, data in self._line_reader.collect():
                self._arrivals.extend((stamp, b) for b in data)

    def _wait_line(self, timeout_s: float) -> None:
        """Block the firmware's thread until bytes come, a stop or reset wakes it, or ``timeout_s`` passes."""
        if self._line_reader is None:
            return
        try:
            select.select([self._line_reader.wait_fd(), self._line_wake_r], [], [], max(0.0, timeout_s))
        except (OSError, ValueError):
            pass

    def _line_readable(self) -> bool:
        """Whether bytes came that are not in the receive buffer yet: in the line or in the reader's hands (call
        with ``_line`` held)."""
        reader = self._line_reader
        return reader is not None and reader.pending()

    def _discard_line(self) -> None:
        """At power-up: what arrived before is lost (and so are the wake-ups of the reset)."""
        self._take_bytes()
        with self._line:
            self._arrivals.clear()
        try:
            while _readable(self._line_wake_r):
                os.read(self._line_wake_r, 4096)
        except OSError:
            pass

    def _wake_line(self) -> None:
        """Wake the firmware's thread from a wait on the line (stop, reset; any thread)."""
        try:
            os.write(self._line_wake_w, b"x")
        except (OSError, AttributeError):
            pass  # full (it is awake anyway) or closed

    # ------------------------------------------------------------------ the clock: wall time <-> simulated time
    def _wall_s(self, t_ns: int) -> float:
        """When (``time.monotonic``) simulated time ``t_ns`` is due on the wall clock (speed not None)."""
        return self._anchor_real + (t_ns - self._anchor_sim_ns) / 1e9 / self._speed

    def _sim_ns(self, wall_s: float) -> int:
        """The simulated time of a wall-clock time (speed not None)."""
        return self._anchor_sim_ns + int(round((wall_s - self._anchor_real) * 1e9 * self._speed))

    def _anchor(self, wall_s: Optional[float] = None) -> None:
        """The simulated clock runs on from ``wall_s`` (default now) at the current simulated time."""
        self._anchor_real = time.monotonic() if wall_s is None else wall_s
        self._anchor_sim_ns = self._t_ns

    def _byte_due(self, fetch: bool = True) -> bool:
        """Whether the first byte received has arrived by the current simulated time (speed None: by now, or
        with ``fetch`` False by the last reply's write)."""
        if fetch:
            self._take_bytes()
        if not self._arrivals:
            return False
        seen = self._arrivals[0][0]
        if self._speed is None:
            return fetch or seen <= self._reply_wall_s
        return self._sim_ns(seen) <= self._t_ns

    def _arrival_by(self, end_ns: int) -> Optional[int]:
        """The simulated time the first byte received arrived at, if that is by ``end_ns`` (None: no byte
        came by then).  A byte that came while this thread was late is taken at its own time, never sooner."""
        self._take_bytes()
        if not self._arrivals:
            return None
        at = self._sim_ns(self._arrivals[0][0])
        return max(at, self._t_ns) if at <= end_ns else None

    def _wait_for_wall(self, end_ns: int, interruptible: bool) -> bool:
        """Wait until simulated time ``end_ns`` is due on the wall clock; True if a byte that arrived before
        then (``interruptible``: the UART interrupt is on) ends the wait first."""
        target = self._wall_s(end_ns)
        while not (self._stop_event.is_set() or self._reset_event.is_set()):
            now = time.monotonic()  # read first: what is collected next covers every byte that came by then
            self._take_bytes()
            if interruptible and self._arrivals and self._arrivals[0][0] <= target:
                return True
            if now >= target:
                return False
            self._wait_line(target - now)
        return False

    # ------------------------------------------------------------------ getc / putc
    def _getc(self, where: str) -> int:
        """``getc()``: the next byte, waiting for it.  Waiting takes no simulated time: the clock runs on from
        the byte's arrival (or from now, if it was waiting already)."""
        self._state = where
        while True:
            self._check_halt()
            self._take_bytes()
            with self._line:
                if self._arrivals:
                    seen, b = self._arrivals.popleft()
                    self._state = BUSY  # with the byte taken, under the lock: never idle with a byte in hand
                    break
            self._wait_line(0.05)
        with self._lock:
            self._rx_rows.append((self._t_ns, b, where))
        if self._speed is not None and seen > self._wall_s(self._t_ns):
            self._anchor(seen)
        return b

    def _pop_byte(self) -> int:
        """The first byte received (the UART ISR's read)."""
        return self._arrivals.popleft()[1]

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
        self._reply_wall_s = time.monotonic()
        if sent is not None:
            self._write_master(bytes([sent]))

    def _write_master(self, data: bytes) -> None:
        if self._master < 0:
            raise _Halt()
        try:
            os.write(self._master, data)
        except OSError:
            pass  # nobody listening: the bytes are lost, as on a real line


def _readable(fd: int) -> bool:
    return bool(select.select([fd], [], [], 0)[0])
