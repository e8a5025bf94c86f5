"""A command port's pin log read back as step/dir writes (the reverse of :mod:`cam.drive.cmd_port`).

A command-byte control unit (seed 004 section 3.5; ``[commands]``, :class:`cam.settings.Commands`) takes one
data byte per step, latched by a strobe pulse.  :func:`commands_to_step_log` turns the bytes of such a pin log
back into the step/dir writes :func:`cam.verify.pinlog.decode_pin_log` decodes, so every proof that reads a
step/dir pin log (decode, carve, the ramp rules) reads a command port's too.
"""
from __future__ import annotations

import numpy as np

from ..errors import CamError
from ..settings import MachineSettings
from .pinlog import PinLog, PinLogPart

__all__ = ["commands_to_step_log"]

_STEP_KEYS = (("x_plus", "x_minus"), ("y_plus", "y_minus"), ("z_plus", "z_minus"))
"""The ``[commands]`` keys of a step of X, Y, Z toward + and toward - (as :data:`cam.drive.cmd_port.STEP_KEYS`)."""
_QUIET_KEYS = ("init", "spindle_on", "spindle_off")
"""Declared bytes that make no step: skipped."""


def commands_to_step_log(log: PinLog, settings: MachineSettings) -> PinLog:
    """The step/dir writes of a command pin log: each step time's bytes as the two writes a step/dir port makes.

    Each rising edge of the strobe (0 before the first write) latches that write's data byte, looked up in
    ``settings.commands``: a step byte of axis ``a`` toward + (``<a>_plus``) or - (``<a>_minus``) becomes a
    write with that axis's clock bit high at the byte's time, then one with every clock low at the next row's
    time (the strobe's fall); the bytes of one step time (a diagonal step's X and Y bytes, a gap apart:
    :func:`_bursts`) are one write with each of their clock bits high, as a step/dir port steps them; every
    direction bit holds the last direction its axis stepped in (low before its
    first step), so the clock's rising edge has its step's direction, as :func:`~cam.verify.pinlog.
    decode_pin_log` reads it.  ``init`` and the spindle bytes make no writes.  The strobe column is the
    step/dir port's Half/Full* level: 1 with ``settings.half_step``, else 0.  The log's parts
    (:class:`~cam.verify.pinlog.PinLogPart`) keep their names, starts and times, their first rows moved to
    where their first steps are.

    Args:
        log: a command port's writes (:class:`cam.drive.cmd_port.CommandMockPort`'s pin log).
        settings: ``commands`` (the bytes) and ``pins`` (the step/dir bits of the writes made).

    Returns:
        A :class:`~cam.verify.pinlog.PinLog` of ``2 G`` step/dir writes for the ``G`` step times.

    Raises:
        CamError: a latched byte ``[commands]`` does not declare (naming the write, 0-based, and the byte).

    >>> from cam.settings import Commands
    >>> s = MachineSettings(commands=Commands(x_plus=0x4B, x_minus=0x4C, init=0x01))
    >>> cmd = PinLog(np.array([0, 10, 500, 510, 900, 910]), np.array([1, 1, 0x4B, 0x4B, 0x4C, 0x4C], np.uint8),
    ...              np.array([1, 0, 1, 0, 1, 0], np.uint8))
    >>> steps = commands_to_step_log(cmd, s)          # X: clock on pin 6 (bit 4), direction on pin 7 (bit 5)
    >>> steps.t_ns.tolist(), steps.data.tolist()
    ([500, 510, 900, 910], [48, 32, 16, 0])
    """
    t_ns = np.asarray(log.t_ns, np.int64)
    data = np.asarray(log.data, np.uint8)
    strobe = np.asarray(log.strobe, np.uint8) != 0
    n = len(data)
    before = np.empty(n, bool)
    if n:
        before[0] = False
        before[1:] = strobe[:-1]
    latched = np.flatnonzero(strobe & ~before)  # (L,) rows whose byte the unit takes
    code = np.full(256, -1, np.int64)  # byte -> 2 * axis + (1: toward +, 0: toward -); -2: no step
    for a, (plus, minus) in enumerate(_STEP_KEYS):
        for key, up in ((plus, 1), (minus, 0)):
            byte = getattr(settings.commands, key)
            if byte >= 0:
                code[byte] = 2 * a + up
    for key in _QUIET_KEYS:
        byte = getattr(settings.commands, key)
        if byte >= 0:
            code[byte] = -2
    meaning = code[data[latched]]
    unknown = np.flatnonzero(meaning == -1)
    if len(unknown):
        row = int(latched[unknown[0]])
        raise CamError(f"command pin log write {row}: byte 0x{int(data[row]):02X} is no command of the machine "
                       f"file's [commands] table")
    rows = latched[meaning >= 0]  # (S,) the step bytes' rows
    meaning = meaning[meaning >= 0]
    axis, up = meaning // 2, meaning % 2
    p = settings.pins
    clock = np.array([1 << p.bit(f"clock_{a}") for a in "xyz"], np.uint8)
    dirbit = np.array([1 << p.bit(f"dir_{a}") for a in "xyz"], np.uint8)
    s = len(rows)
    held = np.zeros(s, np.uint8)  # the direction bits after each step byte
    index = np.arange(s)
    for a in range(3):
        mine = axis == a
        last = np.maximum.accumulate(np.where(mine, index, -1))  # the latest step of this axis, up to each byte
        high = (last >= 0) & (up[np.maximum(last, 0)] == 1)
        held |= np.where(high, dirbit[a], 0).astype(np.uint8)
    first, last = _bursts(t_ns[rows], axis, int(round(settings.commands.byte_gap_us * 1000)))
    g = len(first)
    out_t = np.empty(2 * g, np.int64)
    out_d = np.empty(2 * g, np.uint8)
    out_t[0::2] = t_ns[rows[first]]
    out_t[1::2] = t_ns[np.minimum(rows[last] + 1, max(n - 1, 0))] if s else t_ns[rows[last]]
    clocks = np.bitwise_or.reduceat(clock[axis], first) if s else np.zeros(0, np.uint8)
    out_d[0::2] = held[last] | clocks
    out_d[1::2] = held[last]
    out_s = np.full(2 * g, 1 if settings.half_step else 0, np.uint8)
    rows = rows[first]
    parts = tuple(PinLogPart(part.name, 2 * int(np.searchsorted(rows, part.first_row)), part.start_steps,
                             part.t0_ns) for part in log.parts)
    return PinLog(out_t, out_d, out_s, parts)


def _bursts(t_ns: np.ndarray, axis: np.ndarray, gap_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """``(first, last)``: ``(G,)`` indices of the first and last step byte of each burst.  A burst is the bytes one
    step time sent (a diagonal step: X then Y, ``byte_gap_us`` apart): each byte at most one gap after the one
    before, within two gaps of the burst's first, of an axis not yet in it.  Its axes step together, as a
    step/dir port steps them in one write: the control unit's motors take tens of microseconds' bytes as one
    step time (a step lasts a step period, at least three gaps and a strobe long)."""
    s = len(t_ns)
    if s == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    start = np.ones(s, bool)
    first_of = np.arange(s)
    mask = (1 << axis).astype(np.int64)
    for i in np.flatnonzero(np.diff(t_ns) <= gap_ns) + 1:  # only bytes close after another: diagonal steps
        g = int(first_of[i - 1])
        if t_ns[i] - t_ns[g] <= 2 * gap_ns and not mask[i - 1] & (1 << int(axis[i])):
            start[i] = False
            first_of[i] = g
            mask[i] = mask[i - 1] | (1 << int(axis[i]))
    first = np.flatnonzero(start)
    return first, np.append(first[1:], s) - 1
