"""How long grbl takes to run the lines ``cam`` streams to it, by grbl's own motion rules (issue #45 point 4).

grbl 1.1 plans every block as a trapezoid of speed: it accelerates at the block's acceleration, cruises at the
block's nominal speed and decelerates, entering and leaving at the junction speeds its look-ahead allows, and
it stands still at the end of the queue.  The rules, from grbl's documentation (``doc/markdown/settings.md``:
``$11`` junction deviation, ``$110-$112`` max rates, ``$120-$122`` accelerations; the junction model its
``planner.c`` documents): a block's nominal speed is its feed (rapids: the max rate) cut to each axis' max rate
along its direction; its acceleration is the lowest of the axes' accelerations along its direction; the speed
through a corner between blocks of unit directions ``u1``, ``u2`` is limited to
``sqrt(a_j * $11 * s / (1 - s))`` with ``s = sin(theta / 2)``, ``theta`` the angle between ``-u1`` and ``u2``
(a straight join: no limit; a reversal: a stop), ``a_j`` the acceleration along ``u2 - u1``.  The estimate
plans the whole program at once (grbl sees 15 blocks ahead, which for short blocks it may not fill: the
estimate is then a little short) and stops at each pause.

:func:`grbl_time_s` takes the G-code lines of :func:`cam.drive.grbl_machine.job_lines` (``G53G0``/``G53G1``
with ``X``/``Y``/``Z``/``F`` words, absolute mm) and grbl's ``$$``.
"""
from __future__ import annotations

import math
import re
from typing import Iterable, Optional

import numpy as np

__all__ = ["grbl_time_s", "GRBL_DEFAULTS"]

GRBL_DEFAULTS: dict[int, float] = {11: 0.010, 110: 500.0, 111: 500.0, 112: 500.0, 120: 10.0, 121: 10.0, 122: 10.0}
"""grbl 1.1h's defaults (defaults.h) for the settings the estimate reads, used where ``$$`` lacks one."""

_EPS = 1e-9


_MOTION = re.compile(r"G0*([01])(?![\d.])")
_WORD = re.compile(r"([A-FH-Z])([-+]?(?:\d+\.?\d*|\.\d+))")


def _words(line: str) -> dict[str, float]:
    """The value words of a line but its G codes: ``"G53G1X1.5F600"`` -> ``{"X": 1.5, "F": 600.0}``."""
    return {letter: float(value) for letter, value in _WORD.findall(line)}


def _limit_by_axes(value_per_axis: np.ndarray, unit: np.ndarray) -> float:
    """The largest value along ``unit`` that keeps every axis within its own (grbl's
    ``limit_value_by_axis_maximum``)."""
    limit = math.inf
    for v, u in zip(value_per_axis, unit):
        if abs(u) > _EPS:
            limit = min(limit, v / abs(u))
    return limit


def _block_time_s(length_mm: float, v_entry: float, v_nominal: float, v_exit: float, accel: float) -> float:
    """A trapezoid (or triangle) from ``v_entry`` to ``v_exit`` over ``length_mm``, at most ``v_nominal``."""
    accel_mm = max(0.0, (v_nominal ** 2 - v_entry ** 2) / (2 * accel))
    decel_mm = max(0.0, (v_nominal ** 2 - v_exit ** 2) / (2 * accel))
    if accel_mm + decel_mm <= length_mm:
        cruise_mm = length_mm - accel_mm - decel_mm
        return ((v_nominal - v_entry) / accel + (v_nominal - v_exit) / accel + cruise_mm / max(v_nominal, _EPS))
    v_peak = math.sqrt(max(0.0, (2 * accel * length_mm + v_entry ** 2 + v_exit ** 2) / 2))
    v_peak = max(v_peak, v_entry, v_exit)
    return (v_peak - v_entry) / accel + (v_peak - v_exit) / accel


def _planned_time_s(blocks: list[tuple[float, float, float, float]]) -> float:
    """The time of ``blocks`` ``(length mm, nominal speed, acceleration, max entry speed)`` planned from a stop to
    a stop: each block's entry speed the lowest of its junction's and what a stop at the end allows (backward
    pass), then what its entry allows it to reach (forward pass), then each trapezoid's time."""
    if not blocks:
        return 0.0
    n = len(blocks)
    entry = [min(b[3], b[1]) for b in blocks]
    entry[0] = 0.0
    exit_next = 0.0
    for i in range(n - 1, -1, -1):  # each block must be able to slow to the next one's entry (or stop)
        length, _, a, _ = blocks[i]
        entry[i] = min(entry[i], math.sqrt(exit_next ** 2 + 2 * a * length))
        exit_next = entry[i]
    time_s = 0.0
    for i in range(n):  # ... and reach it from its own entry
        length, nominal, a, _ = blocks[i]
        v_exit = entry[i + 1] if i + 1 < n else 0.0
        v_exit = min(v_exit, math.sqrt(entry[i] ** 2 + 2 * a * length))
        if i + 1 < n:
            entry[i + 1] = v_exit
        time_s += _block_time_s(length, entry[i], nominal, v_exit, a)
    return time_s


def _junction_speed(prev_unit: Optional[np.ndarray], unit: np.ndarray, accel: np.ndarray, deviation: float) -> float:
    """The fastest speed through the corner from direction ``prev_unit`` into ``unit`` (grbl's junction
    deviation model; a start or a reversal: a stop; straight on: no limit)."""
    if prev_unit is None:
        return 0.0
    cos_theta = -float(prev_unit @ unit)
    if cos_theta > 0.999999:
        return 0.0
    if cos_theta < -0.999999:
        return math.inf
    junction = unit - prev_unit
    a_junction = _limit_by_axes(accel, junction / max(float(np.linalg.norm(junction)), _EPS))
    sin_half = math.sqrt(0.5 * (1.0 - cos_theta))
    return math.sqrt(max(0.0, a_junction * deviation * sin_half / (1.0 - sin_half)))


def grbl_time_s(lines: Iterable[object], settings: dict[int, float], start_mm: Optional[tuple] = None) -> float:
    """Seconds grbl takes for ``lines`` (G-code strings; anything else, such as a pause marker, is a stop).

    Args:
        lines: ``G53G0``/``G53G1`` lines with absolute ``X``/``Y``/``Z`` mm and ``F`` mm/min words, as
            :func:`cam.drive.grbl_machine.job_lines` makes them.
        settings: grbl's ``$$`` (``$11``, ``$110-$112``, ``$120-$122``; grbl's defaults where missing).
        start_mm: where the tool stands, machine mm (None: at the first line's target, which then takes no time).

    >>> slow = {110: 600.0, 111: 600.0, 112: 600.0, 120: 10.0, 121: 10.0, 122: 10.0}
    >>> grbl_time_s(["G53G1X10F600"], slow, (0, 0, 0))  # a triangle: 10 mm/s is never reached
    2.0
    >>> grbl_time_s(["G53G0X100"], slow, (0, 0, 0))     # 1 s up to 10 mm/s, 9 s at it, 1 s down
    11.0
    >>> grbl_time_s(["G53G1X50F600", "G53G1X100"], slow, (0, 0, 0))  # straight on: no stop between
    11.0
    >>> round(grbl_time_s(["G53G1X50F600", "G53G1Y50"], slow, (0, 0, 0)), 2)  # a right angle: nearly a stop
    11.89
    """
    s = {**GRBL_DEFAULTS, **{k: v for k, v in settings.items() if k in GRBL_DEFAULTS}}
    rate = np.array([s[110], s[111], s[112]]) / 60.0
    accel = np.array([s[120], s[121], s[122]])
    deviation = max(s[11], 0.0)
    pos = None if start_mm is None else np.asarray(start_mm, np.float64)
    feed_mm_s = 0.0
    total_s = 0.0
    blocks: list[tuple[float, float, float, float]] = []  # (length, nominal speed, accel, max entry speed)
    prev_unit: Optional[np.ndarray] = None
    rapid = False  # G0/G1 are modal

    for item in lines:
        if not isinstance(item, str):
            total_s += _planned_time_s(blocks)
            blocks.clear()
            prev_unit = None
            continue
        text = item.upper()
        words = _words(text)
        if "F" in words:
            feed_mm_s = words["F"] / 60.0
        target = None if pos is None else pos.copy()
        for i, axis in enumerate("XYZ"):
            if axis in words:
                if target is None:
                    target = np.full(3, np.nan)
                target[i] = words[axis]
        if target is None:
            continue
        if pos is None or np.isnan(pos).any():
            pos = np.where(np.isnan(target), 0.0, target) if pos is None else np.where(np.isnan(pos), target, pos)
            continue
        d = target - pos
        length = float(np.linalg.norm(d))
        pos = target
        if length < _EPS:
            continue
        unit = d / length
        motion = _MOTION.search(text)
        if motion is not None:
            rapid = motion.group(1) == "0"
        nominal = _limit_by_axes(rate, unit)
        if not rapid:
            nominal = min(nominal, max(feed_mm_s, _EPS))
        blocks.append((length, nominal, _limit_by_axes(accel, unit), _junction_speed(prev_unit, unit, accel, deviation)))
        prev_unit = unit
    return float(total_s + _planned_time_s(blocks))
