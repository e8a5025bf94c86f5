"""Jogs, Go To and back to the origin: travel-only jobs in machine steps.

Every position here is relative to the job's home, where the tool stands
when the job starts (see :mod:`cam.job.model`).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from ..errors import PlanError
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..values import MAX_ABS_STEPS, finite_number, shown, steps_in_range
from .model import Job, PixelFrame, check_reach, check_travel, travel_job

__all__ = ["goto", "jog", "to_origin", "jog_steps", "AXES", "JOG_UNITS"]

AXES = ("x", "y", "z")

JOG_UNITS = {"steps": None, "full-steps": None, "0.1mm": 0.1, "mm": 1.0, "0.1in": 2.54}
"""Jog units: machine steps, full motor steps, and the MAXIMUS PC program's Jog form units in mm (seed 000
Appendix 2, ``TFormJog::ToolBtnXrightClick``: "100 um", "1 mm", "2.54 mm" and "Full Steps")."""


def jog_steps(axis: str, amount: float, unit: str = "steps", *, settings: MachineSettings = DEFAULT_SETTINGS,
              half_step: bool = False, max_steps: int = MAX_ABS_STEPS) -> int:
    """A jog of ``amount`` in ``unit`` as a whole number of machine steps (rounded to the nearest).

    ``"full-steps"`` are motor steps: two machine steps when the axis runs in half steps (``half_step``), as
    the PC program's ``(machineMode + 1) * N``.  The count is checked after the conversion (at most
    ``max_steps`` either way), so no unit makes it overflow (:func:`cam.values.steps_in_range`).

    >>> jog_steps("x", 1, "mm", settings=DEFAULT_SETTINGS.replace(mm_per_step_xy=0.004375))
    229
    >>> jog_steps("z", 3, "full-steps", half_step=True)
    6

    Raises:
        PlanError: an unknown axis or unit, an amount that is no finite number (text, a boolean), a count that
        is not whole in a step unit, or more than ``max_steps`` steps; each naming the field.
    """
    a = str(axis).lower()
    if a not in AXES:
        raise PlanError(f"axis must be x, y or z, got {shown(axis)}")
    if not isinstance(unit, str) or unit not in JOG_UNITS:
        raise PlanError(f"jog unit must be one of {', '.join(JOG_UNITS)}, got {shown(unit)}")
    value = finite_number(amount, "steps")
    if unit in ("steps", "full-steps"):
        if not value.is_integer():
            raise PlanError(f"a jog in {unit} needs a whole number of steps, got {shown(amount)}")
        n = value * (2 if unit == "full-steps" and half_step else 1)
    else:
        mm_per_step = settings.mm_per_step_axes["xyz".index(a)]
        n = value * JOG_UNITS[unit] / mm_per_step
    return steps_in_range(n, "steps", max_abs_steps=max_steps, asked=f"a jog of {value:g} {unit}")


def goto(position_px: tuple[int, int, int], *, settings: MachineSettings = DEFAULT_SETTINGS) -> Job:
    """Go To (thesis 4.1.2): from (0, 0, 0) travel at Z = 0 to drawing pixel ``(x, y)``, then move Z, and stop.

    ``position_px`` is in drawing pixels (the thesis's unit); the job is in machine steps.

    Raises:
        TravelError: the point is outside the machine travel.
    """
    frame = PixelFrame(0, 0, (0, 0, 0), settings.steps_per_px_xy, settings.steps_per_px_z)
    x, y, z = (int(v) for v in position_px)
    pts_px = list(dict.fromkeys(p for p in ((x, y, 0), (x, y, z)) if p != (0, 0, 0)))
    points_steps = frame.to_steps(np.array(pts_px, np.int64).reshape(-1, 3))
    check_travel(points_steps, settings, frame)
    return travel_job(points_steps, settings, source="go to")


def jog(axis: str, steps: int, *, settings: MachineSettings = DEFAULT_SETTINGS,
        position_steps: Optional[tuple[int, int, int]] = None) -> Job:
    """Move one axis by ``steps`` machine steps.

    Args:
        axis: "x", "y" or "z" (any case).
        steps: signed step count, not 0.
        position_steps: where the tool stands in the machine frame, if known: the jog is then refused
            when it would leave the travel.

    Raises:
        PlanError: a bad axis or count; TravelError: the jog leaves the travel.
    """
    a = str(axis).lower()
    if a not in AXES:
        raise PlanError(f"axis must be x, y or z, got {axis!r}")
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps == 0:
        raise PlanError(f"a jog needs a whole, non-zero number of steps, got {steps!r}")
    move = np.zeros(3, np.int64)
    move[AXES.index(a)] = int(steps)
    if position_steps is not None:
        extent = np.column_stack([np.minimum(move, 0), np.maximum(move, 0)])
        check_reach(np.asarray(position_steps, np.int64), extent, settings, f"a jog of {a.upper()} {steps:+d} steps")
    return travel_job(move[None, :], settings, source=f"jog {a.upper()} {int(steps):+d} steps")


def to_origin(position_steps: tuple[int, int, int], *, settings: MachineSettings = DEFAULT_SETTINGS) -> Job:
    """Back to the home from ``position_steps``: lift out of the material first (to Z = 0 when below it),
    travel at that height, then move Z to the home.  The job is relative to where the tool stands.

    Returns an empty job when the tool is at the home already.
    """
    x, y, z = (int(v) for v in position_steps)
    safe = min(z, 0)
    rel: list[tuple[int, int, int]] = []
    for p in ((x, y, safe), (0, 0, safe), (0, 0, 0)):
        r = (p[0] - x, p[1] - y, p[2] - z)
        if r != (0, 0, 0) and (not rel or rel[-1] != r):
            rel.append(r)
    return travel_job(np.array(rel, np.int64).reshape(-1, 3), settings, source="go to origin")
