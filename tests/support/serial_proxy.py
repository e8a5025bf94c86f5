"""A fault-injecting serial line between a host and a board, on pseudo-terminals (issue #33).

:class:`PtyProxy` opens the board's device (the emulator's pty) as a host would and offers a pty of its own
(:attr:`PtyProxy.device_path`) for the host.  A thread forwards bytes both ways as they come, in real time,
and on request drops a byte the host sent, adds bytes towards the host after a delay, floods the host, or
cuts the cable (forwards nothing more either way).  Offsets count the bytes the host has sent since the
proxy started (``to_board``, before any fault).

For line protocols (grbl) two hooks edit whole lines: ``host_line_filter(n, line)`` gets each line the host
sends (n from 0, its end of line included; real-time bytes, ``?!~``, 0x18 and 0x80 up, pass at once and are
not part of a line) and returns the bytes to forward instead; ``board_line_filter(line)`` does the same for
the board's lines.  Both run in the proxy's thread."""
from __future__ import annotations

import os
import select
import termios
import threading
import time
import tty
from dataclasses import dataclass, field
from typing import Callable, Optional


@dataclass
class _Injection:
    after_offset: int  # once the host has sent this many bytes ...
    delay_s: float  # ... this long after that byte came ...
    data: bytes  # ... these bytes go to the host
    due_s: float | None = None


@dataclass
class PtyProxy:
    board_device: str
    drop_offsets: set[int] = field(default_factory=set)
    drop_reply_offsets: set[int] = field(default_factory=set)
    cut_after_offset: int | None = None
    to_board: bytearray = field(default_factory=bytearray)
    to_host: bytearray = field(default_factory=bytearray)
    injected: bytearray = field(default_factory=bytearray)
    host_line_filter: Optional[Callable[[int, bytes], bytes]] = None
    board_line_filter: Optional[Callable[[bytes], bytes]] = None

    def __post_init__(self) -> None:
        self._board = os.open(self.board_device, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self._board, termios.TCSANOW)
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave, termios.TCSANOW)
        self.device_path = os.ttyname(self._slave)
        os.set_blocking(self._master, False)  # a host that stops reading never stalls the other direction
        os.set_blocking(self._board, False)
        self._injections: list[_Injection] = []
        self._lock = threading.Lock()
        self._pass = threading.Lock()  # held while the thread forwards what it read: see drained
        self._stop = threading.Event()
        self.cut = False
        self.forwarded = 0  # bytes the board was given
        self._host_line = bytearray()
        self._host_lines = 0
        self._board_line = bytearray()
        self._thread = threading.Thread(target=self._run, name="pty-proxy", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ faults
    def inject(self, data: bytes, *, after_offset: int, delay_s: float = 0.0) -> None:
        """Send ``data`` to the host ``delay_s`` after the host's byte number ``after_offset`` - 1 came."""
        with self._lock:
            self._injections.append(_Injection(after_offset, delay_s, bytes(data)))

    # ------------------------------------------------------------------ forwarding
    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                readable, _, _ = select.select([self._master, self._board], [], [], 0.001)
            except (OSError, ValueError):
                return
            now = time.monotonic()
            with self._pass:
                if self._master in readable:
                    self._from_host(self._read(self._master), now)
                if self._board in readable:
                    self._from_board(self._read(self._board))
            self._due_injections(time.monotonic())

    @property
    def drained(self) -> bool:
        """Whether every byte written to either side by now has been passed on (or dropped, as asked)."""
        with self._pass:
            try:
                return not select.select([self._master, self._board], [], [], 0)[0]
            except (OSError, ValueError):
                return True

    def wait_drained(self, timeout_s: float = 30.0) -> bool:
        """Wait until :attr:`drained`; False if not within ``timeout_s`` (a failure guard)."""
        deadline = time.monotonic() + timeout_s
        while not self.drained:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.002)
        return True

    @staticmethod
    def _read(fd: int) -> bytes:
        try:
            return os.read(fd, 4096)
        except OSError:
            return b""

    def _from_host(self, data: bytes, now: float) -> None:
        out = bytearray()
        for b in data:
            offset = len(self.to_board)
            self.to_board.append(b)
            if self.cut_after_offset is not None and offset >= self.cut_after_offset:
                self.cut = True
            if not self.cut and offset not in self.drop_offsets:
                if self.host_line_filter is None or b in b"?!~\x18" or b >= 0x80:
                    out.append(b)
                else:
                    self._host_line.append(b)
                    if b == 0x0A:
                        out += self.host_line_filter(self._host_lines, bytes(self._host_line))
                        self._host_lines += 1
                        self._host_line.clear()
            with self._lock:
                for inj in self._injections:
                    if inj.due_s is None and len(self.to_board) >= inj.after_offset:
                        inj.due_s = now + inj.delay_s
        if out:
            self._write(self._board, bytes(out))
            self.forwarded += len(out)

    def _from_board(self, data: bytes) -> None:
        out = bytearray()
        for b in data:
            offset = len(self.to_host)
            self.to_host.append(b)
            if not self.cut and offset not in self.drop_reply_offsets:
                if self.board_line_filter is None:
                    out.append(b)
                else:
                    self._board_line.append(b)
                    if b == 0x0A:
                        out += self.board_line_filter(bytes(self._board_line))
                        self._board_line.clear()
        if out:
            self._write(self._master, bytes(out))

    def _due_injections(self, now: float) -> None:
        with self._lock:
            due = [inj for inj in self._injections if inj.due_s is not None and inj.due_s <= now]
            for inj in due:
                self._injections.remove(inj)
        for inj in due:
            self.injected += inj.data
            self._write(self._master, inj.data)

    @staticmethod
    def _write(fd: int, data: bytes) -> None:
        view = memoryview(data)
        give_up_s = time.monotonic() + 0.5  # a full pty buffer: what does not fit is lost, as on a real line
        while view and time.monotonic() < give_up_s:
            try:
                n = os.write(fd, view)
            except BlockingIOError:
                time.sleep(0.0005)
                continue
            except OSError:
                return
            view = view[n:]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        for fd in (self._master, self._slave, self._board):
            try:
                os.close(fd)
            except OSError:
                pass

    def __enter__(self) -> "PtyProxy":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
