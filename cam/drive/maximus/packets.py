"""The MAXIMUS protocol's packets, built by pure functions, and the time the firmware takes to answer them
(seed 000 Appendix 1; seed 003).

All step fields are L297 clock pulses (half steps when a mode bit is set), 16-bit, low byte first;
delays are half periods in units of 100 us.  :class:`~cam.drive.maximus.board.MaximusBoard` sends them.

Directions are the board's own: x and y grow when their DIR bit is 1 (the PC program's "X right" and
"Y up", seed 000 Appendix 2 ``drillOneHole``), z is height (DIR_Z = 1 is "Z down", Appendix 1).  An
``invert`` flag flips an axis's DIR bit (the PC program's ``machineInvertDir``).
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ...errors import PlanError
from .protocol import DEBOUNCE_NS, DELAY_UNIT_NS, STEPSBACKATLIMIT

__all__ = [
    "MAX_FIELD", "DEFAULT_DELAY", "jog_packet", "jog_exit_packet", "finish_pulse_packet", "offset_packet",
    "init_packet", "start_drill_packet", "drill_packet", "close_drill_packet", "drill_moves", "pulses_ns",
    "jog_time_ns", "offset_time_ns", "init_time_ns", "drill_time_ns", "switch_time_ns", "drill_moved",
    "drill_directions", "jog_moved", "stopped_between",
]

MAX_FIELD = 0xFFFF  # 16-bit step fields (seed 000, Appendix 1: make16(high, low))
DEFAULT_DELAY = 10  # 10 * 100 us half period: 500 pulses/s
_AXES = {"x": 1, "y": 2, "z": 3}  # Jog configuration bits 7-6: 01 = X, 10 = Y, 11 = Z (Appendix 1 JOG_DATA_INPUT)


def _u16(value: int, what: str) -> bytes:
    if not 0 <= value <= MAX_FIELD:
        raise PlanError(f"{what} = {value} pulses does not fit the 16-bit field (0..{MAX_FIELD})")
    return bytes((value & 0xFF, value >> 8))


def _modes(half_step: bool | Sequence[bool]) -> tuple[int, int, int]:
    """The MODE bits (x, y, z) from one flag for every axis or one per axis."""
    if isinstance(half_step, (bool, int, np.bool_)):
        return (int(bool(half_step)),) * 3  # type: ignore[return-value]
    mx, my, mz = (int(bool(v)) for v in half_step)
    return mx, my, mz


def _delay(value: int, what: str = "delay") -> int:
    if not 1 <= int(value) <= 255:
        raise PlanError(f"{what} = {value} must be 1..255 (units of 100 us; pulse rate 5000/{what} Hz)")
    return int(value)


def jog_packet(axis: str, steps: int, *, delay: int = DEFAULT_DELAY, half_step: bool = False,
               spindle: bool = False, invert: bool = False) -> bytes:
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
    direction = (positive_dir if steps >= 0 else 1 - positive_dir) ^ int(bool(invert))
    config = (_AXES[key] << 6) | (int(bool(half_step)) << 5) | (direction << 4) | int(bool(spindle))
    return bytes([config]) + _u16(abs(steps), f"{key} jog") + bytes([_delay(delay)])


def jog_exit_packet() -> bytes:
    """Four zero bytes: leave Jog mode (seed 000 section 8.3 step 7)."""
    return bytes(4)


def finish_pulse_packet(axis: str, direction: int, *, delay: int = DEFAULT_DELAY, half_step: bool = False,
                        spindle: bool = False, invert: bool = False) -> bytes:
    """A Jog Data Packet of no pulses whose DIR bit is that of a move of ``direction`` (+1 or -1, board frame).

    ``constspeed(0, ...)`` makes no pulse; it only ends with ``output_bit(STEP, 1)``, the listing's "Add last step"
    (seed 000 Appendix 1), which puts the STEP pin back to its idle level.  An emergency stop that came between a
    pulse's falling and rising edge left that pin low, and this is then the pulse's rising edge: one step, now, in
    ``direction`` (without it, the next move of the axis makes it, in that move's direction: cam.sim.maximus point
    14).  With the pin high it does nothing.

    >>> finish_pulse_packet("x", -1, delay=5).hex(), finish_pulse_packet("z", -1, delay=3).hex()   # z down: DIR_Z = 1
    ('40000005', 'd0000003')
    """
    if direction not in (1, -1):
        raise PlanError(f"direction must be +1 or -1, got {direction!r}")
    packet = jog_packet(axis, direction, delay=delay, half_step=half_step, spindle=spindle, invert=invert)
    return packet[:1] + bytes(2) + packet[3:]


def offset_packet(x_steps: int, y_steps: int, z_steps: int, *, delay_x: int = DEFAULT_DELAY,
                  delay_y: int = DEFAULT_DELAY, delay_z: int = DEFAULT_DELAY, half_step: bool | Sequence[bool] = False,
                  invert: Sequence[bool] = (False, False, False)) -> bytes:
    """The 10-byte Offset Positioning Packet for signed moves (Z first, then X, then Y).

    Byte 0: bits 5-3 mode Z, Y, X; bits 2-0 DIR Z, Y, X (seed 000 Appendix 1
    DRILL_MODE1_INITIALIZE).  Bytes 1-6: X, Y, Z pulses, low byte first;
    bytes 7-9: delays X, Y, Z.

    >>> offset_packet(0, 0, 40).hex()   # Z up 40 pulses
    '000000000028000a0a0a'
    """
    mx, my, mz = _modes(half_step)
    ix, iy, iz = (int(bool(v)) for v in invert)
    dir_x = (1 if x_steps > 0 else 0) ^ ix
    dir_y = (1 if y_steps > 0 else 0) ^ iy
    dir_z = (1 if z_steps < 0 else 0) ^ iz  # DIR_Z = 1 is down
    config = (mz << 5) | (my << 4) | (mx << 3) | (dir_z << 2) | (dir_y << 1) | dir_x
    return (bytes([config]) + _u16(abs(int(x_steps)), "offset x") + _u16(abs(int(y_steps)), "offset y")
            + _u16(abs(int(z_steps)), "offset z")
            + bytes([_delay(delay_x, "delay_x"), _delay(delay_y, "delay_y"), _delay(delay_z, "delay_z")]))


def init_packet(first_steps: int, second_steps: int, *, delay_x: int = DEFAULT_DELAY, delay_y: int = DEFAULT_DELAY,
                delay_z_up: int = DEFAULT_DELAY, delay_z_down: int = DEFAULT_DELAY,
                half_step: bool | Sequence[bool] = False) -> bytes:
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
    mx, my, mz = _modes(half_step)
    return (bytes([(mz << 2) | (my << 1) | mx]) + _u16(int(first_steps), "init first field")
            + _u16(int(second_steps), "init second field")
            + bytes([_delay(delay_x, "delay_x"), _delay(delay_y, "delay_y"),
                     _delay(delay_z_up, "delay_z_up"), _delay(delay_z_down, "delay_z_down")]))


def start_drill_packet() -> bytes:
    """Drill Data Packet with CDF and SDF set: answered at once, nothing moves (seed 003, SDF)."""
    return bytes([0xC0, 0, 0, 0, 0])


def drill_packet(dx_steps: int, dy_steps: int, *, invert_x: bool = False, invert_y: bool = False) -> bytes:
    """The 5-byte Drill Data Packet for one hole, a relative XY move.

    Byte 0: bit 7 CDF (continue drilling) set, bit 6 SDF clear, bit 1 DIR Y,
    bit 0 DIR X; bytes 1-4 |dx|, |dy| pulses, low byte first (seed 000
    Appendix 1 DRILL_MODE1_INPUT; seed 003 "Drill Data Packet").

    >>> drill_packet(300, -2).hex()
    '812c010200'
    """
    dir_x = (1 if dx_steps > 0 else 0) ^ int(bool(invert_x))
    dir_y = (1 if dy_steps > 0 else 0) ^ int(bool(invert_y))
    config = 0x80 | (dir_y << 1) | dir_x
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
        raise PlanError(f"the move to hole {int(big[0]) + 1} is longer than {MAX_FIELD} pulses")
    return moves




# --- How long the firmware takes: seed 000, Appendix 1, constspeed(): "Build conststep number of step pulses //
# Frequency = 1/(2*delay*100us)", each pulse dly_100us(delay) high and dly_100us(delay) low.

def pulses_ns(n_pulses: int, delay: int) -> int:
    """``n_pulses`` pulses at Delay ``delay``: ``n * 2 * delay * 100 us``.

    >>> pulses_ns(500, 10) / 1e9   # Delay 10: 500 pulses per second
    1.0
    """
    return int(n_pulses) * 2 * int(delay) * DELAY_UNIT_NS


def switch_time_ns(back_off_delay: int) -> int:
    """The most a limit switch adds to a move: the debounce and the X/Y back-off at the last Jog delay
    (isr_ext: ``constspeed2(STEPSBACKATLIMIT, axisDelay, ...)``)."""
    return DEBOUNCE_NS + pulses_ns(STEPSBACKATLIMIT, back_off_delay)


def _field(packet: bytes, i: int) -> int:
    return packet[i] | (packet[i + 1] << 8)


def jog_time_ns(packet: bytes) -> int:
    """The move of a Jog Data Packet: its pulses at its delay (JOG_DATA_INPUT: ``constspeed(axisStep,
    axisDelay, ...)``).  The exit packet moves nothing.

    >>> jog_time_ns(jog_packet("x", 1000, delay=10)) / 1e9
    2.0
    """
    if packet[0] >> 6 == 0:
        return 0
    return pulses_ns(_field(packet, 1), packet[3])


def offset_time_ns(packet: bytes) -> int:
    """The Offset Positioning Packet's moves, one axis after the other (DRILL_MODE1_INITIALIZE: Z at
    ``DelayZup`` = byte 9, then X at byte 7, then Y at byte 8)."""
    return (pulses_ns(_field(packet, 5), packet[9]) + pulses_ns(_field(packet, 1), packet[7])
            + pulses_ns(_field(packet, 3), packet[8]))


def init_time_ns(packet: bytes) -> int:
    """The Initialize Drill Mode Packet's descent: its first field at ``DelayZup`` (byte 7), as listed."""
    return pulses_ns(_field(packet, 1), packet[7])


def drill_time_ns(packet: bytes, init: bytes) -> int:
    """One Drill Data Packet after the Init packet ``init``: the dog-leg XY move (constspeed_xy: both axes
    together for the shorter count at the slower delay, then the longer axis alone at its own), Z down by
    the Init packet's second field at DelayZdown, Z up by its first at DelayZup.  The closing packet (CDF
    clear) and the start packet (SDF set) move nothing.

    >>> init = init_packet(100, 100, delay_x=2, delay_y=5, delay_z_up=1, delay_z_down=4)
    >>> drill_time_ns(drill_packet(30, 4), init) / 1e6   # 4 at Delay 5, 26 X at 2, 100 down at 4, 100 up at 1
    114.4
    """
    if not packet[0] >> 7 or packet[0] & 0x40:
        return 0
    nx, ny = _field(packet, 1), _field(packet, 3)
    delay_x, delay_y, delay_z_up, delay_z_down = init[5], init[6], init[7], init[8]
    both = min(nx, ny)
    alone_ns = pulses_ns(nx - both, delay_x) if nx > ny else pulses_ns(ny - both, delay_y)
    return (pulses_ns(both, max(delay_x, delay_y)) + alone_ns + pulses_ns(_field(init, 3), delay_z_down)
            + pulses_ns(_field(init, 1), delay_z_up))


def _done(elapsed_ns: int, n_pulses: int, delay: int, whole: bool = False) -> tuple[int, int]:
    """Pulses of a run of ``n_pulses`` at Delay ``delay`` made within ``elapsed_ns``, and the time left after it.

    A pulse's rising edge (the step) comes at the end of its period, its falling edge half way (``constspeed``: the
    STEP pin idles high; each pulse is ``dly_100us(delay)`` high, then low, then the rise).  ``whole``: count the
    pulse whose falling edge has come too, as if its rising edge followed at once (what a stop there leaves, once
    :func:`finish_pulse_packet` has ended the pulse): the pulses to the nearest whole period."""
    period_ns = pulses_ns(1, delay)
    if not n_pulses or not period_ns:
        return n_pulses, elapsed_ns
    late_ns = period_ns // 2 if whole else 0
    k = min(int(n_pulses), (max(0, int(elapsed_ns)) + late_ns) // period_ns)
    return k, elapsed_ns - pulses_ns(n_pulses, delay) if k == n_pulses else 0


def drill_moved(dx_steps: int, dy_steps: int, init: bytes, elapsed_ns: int, *, whole: bool = False
                ) -> tuple[int, int, int]:
    """How far a Drill Data Packet of the XY move ``(dx_steps, dy_steps)`` (board frame) has moved the head
    ``elapsed_ns`` into its move, as :func:`drill_time_ns` times it: the dog-leg XY move, then Z down by the
    Init packet's second field and up by its first.  Returns board-frame ``(x, y, height)`` pulses: the host's
    estimate of where an emergency stop left the head (the firmware does not say).  ``whole``: a pulse half made
    (its falling edge come, not its rising one) counts, as once :func:`finish_pulse_packet` has ended it, in the
    directions :func:`drill_directions` gives.

    >>> init = init_packet(100, 100, delay_x=10, delay_y=10, delay_z_up=10, delay_z_down=10)   # 2 ms a pulse
    >>> drill_moved(300, -100, init, 250_000_000), drill_moved(300, -100, init, 700_000_000)
    ((125, -100, 0), (300, -100, -50))
    >>> drill_moved(300, -100, init, 251_500_000), drill_moved(300, -100, init, 251_500_000, whole=True)
    ((125, -100, 0), (126, -100, 0))
    """
    nx, ny = abs(int(dx_steps)), abs(int(dy_steps))
    delay_x, delay_y, delay_z_up, delay_z_down = init[5], init[6], init[7], init[8]
    both, t = _done(elapsed_ns, min(nx, ny), max(delay_x, delay_y), whole)
    x = y = both
    if t > 0 and nx != ny:
        alone, t = _done(t, abs(nx - ny), delay_x if nx > ny else delay_y, whole)
        x, y = (both + alone, both) if nx > ny else (both, both + alone)
    down, t = _done(t, _field(init, 3), delay_z_down, whole) if t > 0 else (0, 0)
    up, _ = _done(t, _field(init, 1), delay_z_up, whole) if t > 0 else (0, 0)
    sx, sy = (1 if dx_steps >= 0 else -1), (1 if dy_steps >= 0 else -1)
    return sx * x, sy * y, up - down


def drill_directions(dx_steps: int, dy_steps: int, init: bytes, elapsed_ns: int) -> tuple[int, int, int]:
    """The direction (+1, -1; 0: the axis does not move) in which each axis of a Drill Data Packet's move steps
    ``elapsed_ns`` into it: X and Y their move's, Z down (-1) until its descent has ended, then up.

    >>> init = init_packet(100, 100, delay_x=10, delay_y=10, delay_z_up=10, delay_z_down=10)   # 2 ms a pulse
    >>> drill_directions(300, 0, init, 250_000_000), drill_directions(300, 0, init, 900_000_000)
    ((1, 0, -1), (1, 0, 1))
    """
    nx, ny = abs(int(dx_steps)), abs(int(dy_steps))
    delay_x, delay_y, delay_z_down = init[5], init[6], init[8]
    both = min(nx, ny)
    descent_ends_ns = (pulses_ns(both, max(delay_x, delay_y)) + pulses_ns(nx - both, delay_x)
                       + pulses_ns(ny - both, delay_y) + pulses_ns(_field(init, 3), delay_z_down))
    z = 0 if not (_field(init, 3) or _field(init, 1)) else -1 if elapsed_ns < descent_ends_ns else 1
    return (int(np.sign(dx_steps)), int(np.sign(dy_steps)), z)


def jog_moved(moved: Sequence[int], move_ns: int, elapsed_ns: int, *, whole: bool = False) -> tuple[int, ...]:
    """How far a move of one axis at one Delay (a Jog packet, an Offset packet of one axis) of ``moved`` pulses
    (per axis, board frame) taking ``move_ns`` has moved the head ``elapsed_ns`` into it; ``whole`` as in
    :func:`drill_moved`.

    >>> jog_moved((0, -100, 0), 200_000_000, 51_500_000), jog_moved((0, -100, 0), 200_000_000, 51_500_000, whole=True)
    ((0, -25, 0), (0, -26, 0))
    """
    n = max(abs(int(d)) for d in moved)
    if not n or not move_ns:
        return tuple(int(d) for d in moved)
    period_ns = int(move_ns) // n
    k = min(n, (max(0, int(elapsed_ns)) + (period_ns // 2 if whole else 0)) // period_ns)
    return tuple((1 if d > 0 else -1) * k if d else 0 for d in moved)


def stopped_between(progress: Callable[[int], Sequence[int]], earliest_ns: int, latest_ns: int
                    ) -> tuple[tuple[int, ...], int]:
    """Where a move stopped whose stop came between ``earliest_ns`` and ``latest_ns`` into it (the host knows
    the time only so well: it cannot tell when, within its own write calls, the packet and the stop byte left):
    the pulses ``progress`` gives the middle of that time, and how many pulses either end lies from them.

    >>> init = init_packet(100, 100, delay_x=10, delay_y=10, delay_z_up=10, delay_z_down=10)   # 2 ms a pulse
    >>> stopped_between(lambda t: drill_moved(300, 0, init, t), 250_000_000, 250_100_000)
    ((125, 0, 0), 0)
    >>> stopped_between(lambda t: drill_moved(300, 0, init, t), 240_000_000, 260_000_000)   # 20 ms: 5 pulses
    ((125, 0, 0), 5)
    """
    lo, mid, hi = (np.asarray(progress(int(t)), np.int64)
                   for t in (earliest_ns, (earliest_ns + latest_ns) // 2, latest_ns))
    bound = int(max(np.abs(mid - lo).max(initial=0), np.abs(hi - mid).max(initial=0)))
    return tuple(int(v) for v in mid), bound
