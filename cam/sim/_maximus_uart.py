"""The PIC's UART as the MAXIMUS firmware emulator serves it: bytes from the host through the pseudo-terminal,
replies (with the faults a test asked for) back to it.

A part of :class:`cam.sim.maximus.MaximusEmulator`.
"""
from __future__ import annotations

import os
import select

from ._maximus_base import BUSY, _Halt


class _Uart:
    """``getc()`` / ``putc()`` and the pseudo-terminal's master side."""

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
