"""Watching a MAXIMUS host's waits in tests (issue #44 point 3: waits are for conditions, not for fixed times).

A :class:`~cam.drive.maximus.board.MaximusBoard` waits for each reply as long as its move takes plus its reply margin
``timeout_s``.  In tests whose replies all come, the margin is :data:`GUARD_MARGIN_S`: a failure guard only, since
every wait ends as its reply comes, however busy the computer.  A test that makes one exchange go unanswered gives
the board a short margin from that exchange on (:func:`short_margin_from`), so the host finds the silence soon, and
checks how long the host waited against that margin (:func:`record_reads`), not against the wall clock.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Optional

GUARD_MARGIN_S = 30.0
"""The reply margin of a board whose replies all come: how long a reply may be late before the test fails."""


def guard_machine_file(folder: Any) -> str:
    """A machine file (``--machine``) of the built-in MAXIMUS machine whose reply margin is :data:`GUARD_MARGIN_S`,
    in ``folder``: for command-line runs whose replies all come, the margin a failure guard only."""
    from pathlib import Path

    path = Path(folder) / "guard-margin.toml"
    path.write_text(f"[maximus]\nreply_margin_s = {GUARD_MARGIN_S}\n", encoding="ascii")
    return str(path)


@dataclass(frozen=True)
class Read:
    """One wait of the host for a byte."""

    timeout_s: float  # how long it was ready to wait
    waited_s: float  # how long it waited
    byte: Optional[int]  # what came (None: nothing in time)


def record_reads(board: Any) -> list[Read]:
    """The host's reads on ``board`` from now on, appended to the returned list as they end."""
    reads: list[Read] = []
    read_byte = board._read_byte

    def recorded(timeout_s: Optional[float] = None) -> Optional[int]:
        t0 = time.monotonic()
        try:
            byte = read_byte(timeout_s)
        finally:
            waited = time.monotonic() - t0
        reads.append(Read(board.timeout_s if timeout_s is None else float(timeout_s), waited, byte))
        return byte

    board._read_byte = recorded
    return reads


def silent_read(reads: list[Read]) -> Read:
    """The one read that found nothing in time (the exchange that went unanswered)."""
    silent = [r for r in reads if r.byte is None]
    assert len(silent) == 1, reads
    return silent[0]


def short_margin_from(board: Any, offset: int, margin_s: float) -> None:
    """From the packet holding the host's byte number ``offset`` on (counted from the first byte ``board`` writes
    from now on, 0 first), the board's reply margin is ``margin_s``.  The board takes ``timeout_s`` for an exchange
    after its packet is written, so the exchange of that packet already waits that long."""
    written = [0]
    write = board._write

    def counted(data: bytes) -> None:
        write(data)
        written[0] += len(data)
        if written[0] > offset:
            board.timeout_s = float(margin_s)

    board._write = counted


def writes_after_fault(board: Any) -> list[bytes]:
    """What ``board`` writes after it finds a link fault (its ``_fault``), appended as it writes: nothing, as the
    safety rules say (cam.drive.maximus.board)."""
    after: list[bytes] = []
    faulted = [False]
    fault, write = board._fault, board._write

    def found(*args: Any, **kwargs: Any) -> Any:
        faulted[0] = True
        return fault(*args, **kwargs)

    def watched(data: bytes) -> None:
        if faulted[0]:
            after.append(bytes(data))
        write(data)

    board._fault, board._write = found, watched
    return after
