"""The MAXIMUS emulator's receive line: a small reader process stamps the host's bytes as they arrive.

A PIC takes a byte the moment its stop bit ends (cam/sim/_maximus_uart.py), so the emulator needs each byte's
arrival time.  Its firmware thread runs in its caller's Python process (a test's pytest, a server), where a
thread waits for the CPU and for the GIL behind that process's other threads (switch interval 5 ms): a reader
*thread* there stamped bytes 10-16 ms late on a busy computer, several pulses at 2 ms a pulse.  So a process of
its own, with one thread and nothing else to do, owns the read side of the pseudo-terminal's master: blocked in
``select``, it stamps each chunk with ``time.monotonic()`` as it wakes and passes ``(stamp, bytes)`` on a pipe.
``CLOCK_MONOTONIC`` is system-wide, so its stamps compare with the emulator's clock.  It asks for SCHED_FIFO,
else nice -5 (where allowed; best effort), so a busy computer wakes it first.

It runs this file as a script (``python -I -S``: standard library only, started in a few milliseconds).  On its
stdout::

    b"R"                            ready (after its priority is set)
    b"B" + stamp (8 bytes, float)   select woke: bytes are there (written before the read)
    b"D" + length (2 bytes) + data  what that read got
    b"E"                            that read failed (nothing)

Its stdin is its lifeline: at end of file (the emulator stopped, or its process died) it exits.  Because ``B``
goes out before the read, the emulator knows every byte that arrived by a given moment: those still in the master
(readable) and those read but not yet passed on (a ``B`` without its ``D``) are waited for (:meth:`LineReader.
collect`).  If the process cannot start, or dies, the emulator reads the master itself, stamping with its own clock.
"""
from __future__ import annotations

import os
import select
import signal
import struct
import subprocess
import sys
import time

_STAMP = struct.Struct("<d")
_LENGTH = struct.Struct("<H")
_READY_S = 5.0  # how long start() waits for the reader's first byte
_STUCK_S = 1.0  # how long collect() waits for a read the reader has under way


def _readable(fd: int) -> bool:
    try:
        return bool(select.select([fd], [], [], 0)[0])
    except (OSError, ValueError):
        return False


class LineReader:
    """The emulator's side of the reader process on pseudo-terminal master ``master``."""

    def __init__(self, master: int) -> None:
        self._master = master
        self._proc: subprocess.Popen | None = None
        self._out = -1
        self._buf = bytearray()
        self._stamp = 0.0
        self._open = False  # a B record whose D or E has not come yet
        self.alive = False
        self.priority = ""  # what the reader got: "fifo", "nice" or "" (its parent's)

    def start(self) -> "LineReader":
        """Start the reader process and wait for it to be ready; if it cannot start, this side reads instead."""
        try:
            self._proc = subprocess.Popen([sys.executable, "-I", "-S", os.path.abspath(__file__), str(self._master)],
                                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, pass_fds=(self._master,),
                                          close_fds=True)
        except (OSError, ValueError):
            return self
        self._out = self._proc.stdout.fileno()  # type: ignore[union-attr]
        os.set_blocking(self._out, False)
        self.alive = True
        deadline = time.monotonic() + _READY_S
        while self.alive and len(self._buf) < 2 and time.monotonic() < deadline:
            select.select([self._out], [], [], max(0.0, deadline - time.monotonic()))
            self._read_pipe()
        if self._buf[:1] == b"R":
            self.priority = {b"F": "fifo", b"N": "nice"}.get(bytes(self._buf[1:2]), "")
            del self._buf[:2]
        else:
            self.stop()  # not ready in time: read here
        return self

    def stop(self) -> None:
        """End the reader process (its stdin closes) and wait for it."""
        proc, self._proc, self.alive = self._proc, None, False
        if proc is None:
            return
        try:
            proc.stdin.close()  # type: ignore[union-attr]
            proc.wait(timeout=2.0)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
        proc.stdout.close()  # type: ignore[union-attr]
        self._out = -1

    def wait_fd(self) -> int:
        """The descriptor that becomes readable when bytes come."""
        return self._out if self.alive else self._master

    def collect(self) -> list[tuple[float, bytes]]:
        """Every chunk that arrived by this call and was not collected before, with the time it arrived.  A byte
        still in the master, or read and not yet passed on, is waited for (at most ``_STUCK_S``)."""
        chunks: list[tuple[float, bytes]] = []
        deadline = None
        while self.alive:
            waiting = _readable(self._master)  # first: bytes that came by now and the reader has not read...
            self._read_pipe()  # ...then what it passed on (a read it began by now shows as an open B)
            chunks += self._records()
            if not (waiting or self._open) or not self.alive:
                break
            now = time.monotonic()
            deadline = deadline or now + _STUCK_S
            if now >= deadline:
                return chunks  # a reader that hangs must not hang the firmware
            select.select([self._out], [], [], deadline - now)
        if not self.alive:
            chunks += self._read_here()
        return chunks

    def pending(self) -> bool:
        """Whether bytes have arrived that :meth:`collect` has not returned yet: in the master, in the pipe, or read
        by the reader and not passed on (call it where :meth:`collect` cannot run meanwhile)."""
        if _readable(self._master):
            return True
        return self.alive and (self._open or bool(self._buf) or _readable(self._out))

    def _read_pipe(self) -> None:
        while True:
            try:
                data = os.read(self._out, 65536)
            except BlockingIOError:
                return
            except (OSError, ValueError):
                data = b""
            if not data:
                self.alive, self._open = False, False  # the reader is gone
                return
            self._buf += data

    def _records(self) -> list[tuple[float, bytes]]:
        chunks, buf = [], self._buf
        while buf:
            kind = buf[:1]
            if kind == b"B" and len(buf) >= 1 + _STAMP.size:
                self._stamp, self._open = _STAMP.unpack_from(buf, 1)[0], True
                del buf[:1 + _STAMP.size]
            elif kind == b"D" and len(buf) >= 1 + _LENGTH.size \
                    and len(buf) >= 1 + _LENGTH.size + _LENGTH.unpack_from(buf, 1)[0]:
                end = 1 + _LENGTH.size + _LENGTH.unpack_from(buf, 1)[0]
                chunks.append((self._stamp, bytes(buf[1 + _LENGTH.size:end])))
                self._open = False
                del buf[:end]
            elif kind == b"E":
                self._open = False
                del buf[:1]
            else:
                break  # a record not complete yet
        return chunks

    def _read_here(self) -> list[tuple[float, bytes]]:
        """Without a reader process: what the master holds, stamped now."""
        if not _readable(self._master):
            return []
        stamp = time.monotonic()
        try:
            data = os.read(self._master, 4096)
        except (OSError, ValueError):
            return []
        return [(stamp, data)] if data else []


# ---------------------------------------------------------------------- the reader process
def _raise_priority() -> bytes:
    """SCHED_FIFO if allowed (it only ever blocks in select: it cannot hold a CPU), else nice -5, else nothing."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))  # type: ignore[attr-defined]
        return b"F"
    except (AttributeError, OSError):
        pass
    try:
        os.nice(-5)
        return b"N"
    except OSError:
        return b"-"


def _write_all(fd: int, data: bytes) -> None:
    while data:
        data = data[os.write(fd, data):]


def _reader_main(master: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C for the emulator's process group: it ends by stdin
    out, life = sys.stdout.fileno(), sys.stdin.fileno()
    _write_all(out, b"R" + _raise_priority())
    while True:
        ready, _, _ = select.select([master, life], [], [])
        stamp = time.monotonic()
        if life in ready:
            return  # the emulator stopped (or died): end of file
        _write_all(out, b"B" + _STAMP.pack(stamp))
        try:
            data = os.read(master, 4096)
        except OSError:
            data = b""
        if data:
            _write_all(out, b"D" + _LENGTH.pack(len(data)) + data)
        else:
            _write_all(out, b"E")
            time.sleep(0.01)  # the line failed (nobody holds the slave side): look again soon


if __name__ == "__main__":
    try:
        _reader_main(int(sys.argv[1]))
    except (BrokenPipeError, KeyboardInterrupt):
        pass
