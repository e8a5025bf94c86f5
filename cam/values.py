"""Numbers a user hands the machine, checked in one place (issue #43 point 8).

Every coordinate, step count and percent that reaches the machine session from a front end (the web API's JSON,
the command line's flags, the Python API) is checked here before it is used: it must be a number of the
documented type (an ``int`` or a ``float``: no text, no booleans, no lists), finite, and in range *after* its
conversion to machine steps, so no unit conversion can overflow to infinity or to an integer no machine has.
A bad one is a :class:`~cam.errors.PlanError` (a :class:`~cam.errors.CamError`: one line, exit code 2 from the
CLI, 400 from the API) naming the field.

Standard library only (with numpy's scalar types accepted when numpy is loaded).
"""
from __future__ import annotations

import math
import numbers
from typing import Any, Optional

from .errors import PlanError

__all__ = ["MAX_ABS_STEPS", "FEED_OVERRIDE_RANGE", "finite_number", "whole_number", "xyz_numbers", "xyz_steps", "steps_in_range", "shown",
           "format_duration"]

FEED_OVERRIDE_RANGE = (10, 200)
"""A feed override's limits, percent (grbl's config.h defaults: MIN 10, MAX 200; checked on every machine first)."""

MAX_ABS_STEPS = 1_000_000_000
"""The most machine steps any position or move may be from its origin either way (no machine has that much
travel: 29 km at 0.0289 mm a step); every count converted from another unit must fit, so none overflows int64."""


def shown(value: Any, limit: int = 40) -> str:
    """``value`` as an error message shows it: its repr, cut to ``limit`` characters (a number of 4000 digits,
    a long text).

    >>> shown("123"), shown(10 ** 50)
    ("'123'", '100000000000000000000000000000000000000...')
    """
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 1] + "..."


def _is_number(value: Any) -> bool:
    """An int or a float (numpy's too), not a bool (JSON's ``true`` is no number)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and type(value).__name__ != "bool_"


def finite_number(value: Any, name: str, *, lo: Optional[float] = None, hi: Optional[float] = None,
                  unit: str = "") -> float:
    """``value`` as a float when it is a finite number within ``lo..hi`` (either may be None: no bound).

    >>> finite_number(12, "percent", lo=10, hi=200)
    12.0

    Raises:
        PlanError: naming ``name``: not a number (text, a boolean, a list, None), NaN, infinite, an integer too
        large for a float (10^400), or outside the range.
    """
    if not _is_number(value):
        raise PlanError(f"{name} must be a number, got {shown(value)}")
    try:
        out = float(value)
    except OverflowError:
        out = math.inf
    range_text = _range_text(lo, hi, unit)
    if not math.isfinite(out):
        raise PlanError(f"{name} must be a finite number{range_text}, got {shown(value)}")
    if (lo is not None and out < lo) or (hi is not None and out > hi):
        raise PlanError(f"{name} must be{range_text}, got {out:g}")
    return out


def whole_number(value: Any, name: str, *, lo: Optional[int] = None, hi: Optional[int] = None) -> int:
    """``value`` as an int when it is a whole number (an int, or a float with no fraction) within ``lo..hi``.

    Raises:
        PlanError: naming ``name`` (as :func:`finite_number`, and for a fraction).
    """
    number = finite_number(value, name, lo=lo, hi=hi)
    if not number.is_integer():
        raise PlanError(f"{name} must be a whole number, got {shown(value)}")
    return int(value) if isinstance(value, numbers.Integral) else int(number)


def xyz_numbers(value: Any, name: str) -> tuple[float, float, float]:
    """``value`` as three finite floats when it is a list (or tuple) of exactly three numbers, X, Y, Z.

    >>> xyz_numbers([1, 2.5, 0], "xyz")
    (1.0, 2.5, 0.0)

    Raises:
        PlanError: naming ``name`` and the axis: not a list of three (text such as ``"123"``, an object), or an
        entry that is no finite number (text, a boolean, NaN, infinity).
    """
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):  # a numpy array: its Python numbers
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise PlanError(f"{name} must be a list of 3 numbers X, Y, Z, got {shown(value)}")
    x, y, z = (finite_number(v, f"{name} {axis}") for v, axis in zip(value, "XYZ"))
    return x, y, z


def xyz_steps(value: Any, name: str) -> tuple[int, int, int]:
    """``value`` as three whole numbers of machine steps X, Y, Z (a list, a tuple or a numpy array), each at most
    :data:`MAX_ABS_STEPS` either way.

    Raises:
        PlanError: naming ``name`` and the axis (as :func:`xyz_numbers`, and for a fraction or a count too large).
    """
    xyz = value.tolist() if hasattr(value, "tolist") and not isinstance(value, (str, bytes)) else value
    xyz_numbers(xyz, name)
    x, y, z = (whole_number(v, f"{name} {axis}", lo=-MAX_ABS_STEPS, hi=MAX_ABS_STEPS) for v, axis in zip(xyz, "XYZ"))
    return x, y, z


def steps_in_range(steps: float, name: str, *, max_abs_steps: int = MAX_ABS_STEPS, asked: str = "") -> int:
    """A step count worked out from a user's number (after its unit's conversion) as the nearest int, when it is
    finite and at most ``max_abs_steps`` either way.

    >>> steps_in_range(228.57, "steps")
    229

    Raises:
        PlanError: naming ``name`` and what was ``asked`` (e.g. ``"1e+308 mm"``): infinite, NaN or too large.
    """
    what = f" ({asked})" if asked else ""
    try:
        value = float(steps)
    except OverflowError:
        value = math.inf
    if not math.isfinite(value) or abs(value) > max_abs_steps:
        amount = f"{value:.3g} steps" if math.isfinite(value) else "more steps than a number holds"
        raise PlanError(f"{name} must be at most {max_abs_steps} steps either way, got {amount}{what}")
    return int(round(value))


def _range_text(lo: Optional[float], hi: Optional[float], unit: str) -> str:
    """`` lo..hi unit`` (or ``>= lo``, ``<= hi``) for a message, "" without bounds."""
    u = f" {unit}" if unit else ""
    if lo is not None and hi is not None:
        return f" {lo:g}..{hi:g}{u}"
    if lo is not None:
        return f" >= {lo:g}{u}"
    if hi is not None:
        return f" <= {hi:g}{u}"
    return ""


def format_duration(seconds: float) -> str:
    """``H:MM:SS``, rounded to the second: how every machine time is shown.

    >>> format_duration(3725.4)
    '1:02:05'
    """
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"
