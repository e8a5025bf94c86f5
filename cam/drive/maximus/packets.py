"""The MAXIMUS protocol's packets, built by pure functions (seed 000 Appendix 1; seed 003).

All step fields are L297 clock pulses (half steps when a mode bit is set), 16-bit, low byte first;
delays are half periods in units of 100 us.  :class:`~cam.drive.maximus.board.MaximusBoard` sends them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ...errors import PlanError

__all__ = [
    "MAX_FIELD", "DEFAULT_DELAY", "jog_packet", "jog_exit_packet", "offset_packet", "init_packet",
    "start_drill_packet", "drill_packet", "close_drill_packet", "drill_moves",
]

MAX_FIELD = 0xFFFF  # 16-bit step fields (seed 000, Appendix 1: make16(high, low))
DEFAULT_DELAY = 10  # 10 * 100 us half period: 500 pulses/s
_AXES = {"x": 1, "y": 2, "z": 3}  # Jog configuration bits 7-6: 01 = X, 10 = Y, 11 = Z (Appendix 1 JOG_DATA_INPUT)


def _u16(value: int, what: str) -> bytes:
    if not 0 <= value <= MAX_FIELD:
        raise PlanError(f"{what} = {value} pulses does not fit the 16-bit field (0..{MAX_FIELD})")
    return bytes((value & 0xFF, value >> 8))


def _delay(value: int, what: str = "delay") -> int:
    if not 1 <= int(value) <= 255:
        raise PlanError(f"{what} = {value} must be 1..255 (units of 100 us; pulse rate 5000/{what} Hz)")
    return int(value)


def jog_packet(axis: str, steps: int, *, delay: int = DEFAULT_DELAY, half_step: bool = False,
               spindle: bool = False) -> bytes:
    """The 4-byte Jog Data Packet for a signed move of one axis.

    Byte 0 (seed 000 Appendix 1 JOG_DATA_INPUT; seed 003 "JOG Data Packet"):
    bits 7-6 axis (01 X, 10 Y, 11 Z), bit 5 half step, bit 4 DIR, bit 0
    spindle; bytes 1-2 pulses, low byte first; byte 3 delay.

    >>> jog_packet("x", -300, delay=5).hex()
    '402c0105'
    >>> jog_packet("z", 20, delay=3).hex()   # z up: DIR_Z = 0
    'c0140003'
    """
    key = str(axis).lower()
    if key not in _AXES:
        raise PlanError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
    steps = int(steps)
    positive_dir = 0 if key == "z" else 1  # DIR bit for a positive move
    direction = positive_dir if steps >= 0 else 1 - positive_dir
    config = (_AXES[key] << 6) | (int(bool(half_step)) << 5) | (direction << 4) | int(bool(spindle))
    return bytes([config]) + _u16(abs(steps), f"{key} jog") + bytes([_delay(delay)])


def jog_exit_packet() -> bytes:
    """Four zero bytes: leave Jog mode (seed 000 section 8.3 step 7)."""
    return bytes(4)


def offset_packet(x_steps: int, y_steps: int, z_steps: int, *, delay_x: int = DEFAULT_DELAY,
                  delay_y: int = DEFAULT_DELAY, delay_z: int = DEFAULT_DELAY, half_step: bool = False) -> bytes:
    """The 10-byte Offset Positioning Packet for signed moves (Z first, then X, then Y).

    Byte 0: bits 5-3 mode Z, Y, X; bits 2-0 DIR Z, Y, X (seed 000 Appendix 1
    DRILL_MODE1_INITIALIZE).  Bytes 1-6: X, Y, Z pulses, low byte first;
    bytes 7-9: delays X, Y, Z.

    >>> offset_packet(0, 0, 40).hex()   # Z up 40 pulses
    '000000000028000a0a0a'
    """
    m = int(bool(half_step))
    dir_x = 1 if x_steps > 0 else 0
    dir_y = 1 if y_steps > 0 else 0
    dir_z = 1 if z_steps < 0 else 0  # DIR_Z = 1 is down
    config = (m << 5) | (m << 4) | (m << 3) | (dir_z << 2) | (dir_y << 1) | dir_x
    return (bytes([config]) + _u16(abs(int(x_steps)), "offset x") + _u16(abs(int(y_steps)), "offset y")
            + _u16(abs(int(z_steps)), "offset z")
            + bytes([_delay(delay_x, "delay_x"), _delay(delay_y, "delay_y"), _delay(delay_z, "delay_z")]))


def init_packet(first_steps: int, second_steps: int, *, delay_x: int = DEFAULT_DELAY, delay_y: int = DEFAULT_DELAY,
                delay_z_up: int = DEFAULT_DELAY, delay_z_down: int = DEFAULT_DELAY, half_step: bool = False) -> bytes:
    """The 9-byte Initialize Drill Mode Packet.

    Byte 0: bits 2-0 mode Z, Y, X; bytes 1-2 the first field
    (``drillStepZup``), bytes 3-4 the second (``drillStepZdown``), low byte
    first; bytes 5-8 delays X, Y, Zup, Zdown (seed 000 Appendix 1, "Initialize
    Drill Mode").  As listed, the firmware lowers Z by ``first_steps`` once
    on receipt, then for every hole lowers Z by ``second_steps`` and raises
    it by ``first_steps``.

    >>> init_packet(40, 40, delay_z_down=20).hex()
    '00280028000a0a0a14'
    """
    m = int(bool(half_step))
    return (bytes([(m << 2) | (m << 1) | m]) + _u16(int(first_steps), "init first field")
            + _u16(int(second_steps), "init second field")
            + bytes([_delay(delay_x, "delay_x"), _delay(delay_y, "delay_y"),
                     _delay(delay_z_up, "delay_z_up"), _delay(delay_z_down, "delay_z_down")]))


def start_drill_packet() -> bytes:
    """Drill Data Packet with CDF and SDF set: answered at once, nothing moves (seed 003, SDF)."""
    return bytes([0xC0, 0, 0, 0, 0])


def drill_packet(dx_steps: int, dy_steps: int) -> bytes:
    """The 5-byte Drill Data Packet for one hole, a relative XY move.

    Byte 0: bit 7 CDF (continue drilling) set, bit 6 SDF clear, bit 1 DIR Y,
    bit 0 DIR X; bytes 1-4 |dx|, |dy| pulses, low byte first (seed 000
    Appendix 1 DRILL_MODE1_INPUT; seed 003 "Drill Data Packet").

    >>> drill_packet(300, -2).hex()
    '812c010200'
    """
    config = 0x80 | ((1 if dy_steps > 0 else 0) << 1) | (1 if dx_steps > 0 else 0)
    return bytes([config]) + _u16(abs(int(dx_steps)), "hole dx") + _u16(abs(int(dy_steps)), "hole dy")


def close_drill_packet() -> bytes:
    """Drill Data Packet with CDF clear: leave Drill mode, nothing moves."""
    return bytes(5)


def drill_moves(holes_steps: np.ndarray) -> np.ndarray:
    """Relative moves from the start to each hole in turn.

    Args:
        holes_steps: ``(N, 2)`` integer (x, y) pulses relative to the start.

    Returns:
        ``(N, 2)`` int64 (dx, dy); row i moves from hole i-1 (the start for i = 0) to hole i.

    >>> drill_moves(np.array([[10, 0], [10, 5], [0, 0]])).tolist()
    [[10, 0], [0, 5], [-10, -5]]
    """
    holes = np.asarray(holes_steps)
    if holes.ndim != 2 or holes.shape[1] != 2:
        raise PlanError(f"holes_steps must have shape (N, 2), got {holes.shape}")
    if holes.size and not np.issubdtype(holes.dtype, np.integer):
        if not np.all(np.equal(np.mod(holes, 1), 0)):
            raise PlanError("holes_steps must be whole pulses")
    holes = holes.astype(np.int64)
    moves = np.diff(np.vstack([np.zeros((1, 2), np.int64), holes]), axis=0)
    big = np.flatnonzero(np.abs(moves).max(axis=1, initial=0) > MAX_FIELD) if len(moves) else []
    if len(big):
        raise PlanError(f"the move to hole {int(big[0])} is longer than {MAX_FIELD} pulses")
    return moves


@dataclass(frozen=True)
class _DrillJob:
    """The packets of one Drill mode job (see :meth:`MaximusBoard.drill`), checked before anything is sent."""

    offset: bytes  # Offset Positioning Packet: Z up by the depth
    init: bytes  # Initialize Drill Mode Packet: both fields the depth
    holes: list[bytes]  # one Drill Data Packet per hole
    changes: dict[int, list[str]]  # hole index -> tool-change messages before it
    back_steps: np.ndarray  # (2,) int64 x, y jog back to the start after the last hole


def _drill_job(holes_steps: np.ndarray, depth_steps: int, tool_changes: Sequence[tuple[int, str]], delay: int,
               delay_z_down: int | None, delay_z_up: int | None, half_step: bool) -> _DrillJob:
    moves = drill_moves(holes_steps)
    depth = int(depth_steps)
    if not 1 <= depth <= MAX_FIELD:
        raise PlanError(f"depth_steps = {depth_steps} must be 1..{MAX_FIELD}")
    dz_down = _delay(delay if delay_z_down is None else delay_z_down, "delay_z_down")
    dz_up = _delay(delay if delay_z_up is None else delay_z_up, "delay_z_up")
    changes: dict[int, list[str]] = {}
    for index, message in tool_changes:
        if not 0 <= int(index) < len(moves):
            raise PlanError(f"tool change before hole {index}: there are {len(moves)} holes")
        changes.setdefault(int(index), []).append(str(message))
    offset = offset_packet(0, 0, depth, delay_x=delay, delay_y=delay, delay_z=dz_up, half_step=half_step)
    init = init_packet(depth, depth, delay_x=delay, delay_y=delay, delay_z_up=dz_up,
                       delay_z_down=dz_down, half_step=half_step)
    holes = [drill_packet(int(dx), int(dy)) for dx, dy in moves]
    back = -moves.sum(axis=0) if len(moves) else np.zeros(2, np.int64)
    return _DrillJob(offset, init, holes, changes, back)
