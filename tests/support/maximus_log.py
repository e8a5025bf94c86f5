"""Oracles for the MAXIMUS emulator's port log: axis positions and drilled holes read back from pin writes.

Test-only: the library never reads its own emulator's log.
"""
from __future__ import annotations

from typing import Iterable

import numpy as np

from cam.drive.maximus.protocol import AXIS_PINS, PORT_B, PORT_D
from cam.sim.maximus import PortLog

__all__ = ["decode_port_log", "hole_strokes", "drilled_holes"]


def _as_port_log(log: PortLog | Iterable[tuple[int, str | int, int]]) -> PortLog:
    return log if isinstance(log, PortLog) else PortLog.from_rows(log)


def decode_port_log(log: PortLog | Iterable[tuple[int, str | int, int]]) -> np.ndarray:
    """Read the axis positions back out of the port B/D writes.

    A step is a rising edge of an axis's STEP bit while its ENABLE bit is
    high; X and Y count +1 when DIR is 1, Z counts -1 when DIR_Z is 1 (down),
    so z is height.  The first write to each port sets its level without
    counting a step.

    Args:
        log: a :class:`PortLog` or ``(t_ns, port, value)`` rows.

    Returns:
        ``(M, 3)`` int64: x, y, z in L297 clock pulses after each write,
        relative to the position at the first write (the emulator's power-up).

    >>> rows = [(0, "D", 0xFF), (0, "D", 0xFD), (100000, "D", 0xFF), (200000, "D", 0xFB), (200000, "D", 0xF9), (300000, "D", 0xFB)]
    >>> decode_port_log(rows)[:, 0].tolist()
    [0, 0, 1, 1, 1, 0]
    """
    log = _as_port_log(log)
    m = len(log)
    deltas = np.zeros((m, 3), np.int64)
    if m == 0:
        return deltas
    for port in (PORT_B, PORT_D):
        idx = np.flatnonzero(log.port == port)
        if len(idx) == 0:
            continue
        cur = log.value[idx].astype(np.int64)
        prev = np.concatenate([cur[:1], cur[:-1]])
        for axis, (p, step_b, dir_b, en_b, sign) in enumerate(AXIS_PINS):
            if p != port:
                continue
            rise = ((cur >> step_b) & 1 == 1) & ((prev >> step_b) & 1 == 0) & ((cur >> en_b) & 1 == 1)
            d = np.where((cur >> dir_b) & 1 == 1, sign, -sign)
            deltas[idx, axis] = np.where(rise, d, 0)
    return np.cumsum(deltas, axis=0)


def hole_strokes(log: PortLog | Iterable[tuple[int, str | int, int]]) -> np.ndarray:
    """Every Z stroke that went down and came back up with X and Y standing still.

    Returns:
        ``(N, 5)`` int64 rows ``(x, y, z_top, z_bottom, z_end)`` in pulses:
        the XY position, the height where the descent began, the lowest
        height, and the height where the following ascent ended.
    """
    pos = decode_port_log(log)
    out: list[tuple[int, int, int, int, int]] = []
    if len(pos) == 0:
        return np.zeros((0, 5), np.int64)
    prev = np.vstack([pos[:1] * 0, pos[:-1]])
    changed = np.flatnonzero(np.any(pos != prev, axis=1))
    phase = None  # None, "down" or "up"
    top = bottom = 0
    last = np.zeros(3, np.int64)
    for i in changed.tolist():
        before = prev[i]
        now = pos[i]
        if now[0] != before[0] or now[1] != before[1]:
            if phase == "up":
                out.append((int(before[0]), int(before[1]), top, bottom, int(before[2])))
            phase = None
            last = now
            continue
        dz = int(now[2] - before[2])
        if dz < 0:
            if phase == "up":
                out.append((int(before[0]), int(before[1]), top, bottom, int(before[2])))
                phase = None
            if phase is None:
                phase, top = "down", int(before[2])
        elif dz > 0 and phase == "down":
            phase, bottom = "up", int(before[2])
        last = now
    if phase == "up":
        out.append((int(last[0]), int(last[1]), top, bottom, int(last[2])))
    return np.array(out, np.int64).reshape(-1, 5)


def drilled_holes(log: PortLog | Iterable[tuple[int, str | int, int]]) -> list[tuple[int, int]]:
    """The ``(x_pulses, y_pulses)`` of every place where Z went down and came back, in drilling order."""
    return [(int(r[0]), int(r[1])) for r in hole_strokes(log)]
