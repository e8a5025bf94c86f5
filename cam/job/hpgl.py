"""HPGL to one job in machine steps, held in memory (seed 004, section 3.6.2).

Frames and units (as :mod:`cam.job.drill`): HPGL X right, Y up, plotter units
(the file's ``SC``/``IP`` scaling already applied by the reader), times ``scale``
mm cut per mm plotted (``fit_mm`` picks it; 1 by default).
Machine x = X, machine y = -Y (toward the operator), in steps of
``settings.mm_per_step_xy``, rounded to the nearest step (the seed truncates:
``xsteps = xcoord * 250 / 254`` in integer arithmetic, 004 section 3.6.2).  By
default the drawing's top-left corner (smallest X, largest Y of its pen-down
points) is placed at the home (0, 0); ``offset_mm=(X, Y)`` instead puts
plotter (0, 0), scaled, at machine (X, Y) mm from the home.

There is one HPGL planner, :mod:`cam.job.hpgl_stream`, which makes the job a
piece at a time; :func:`plan_hpgl` is its pieces joined into one
:class:`~cam.job.model.Job`, whether the drawing is held in memory or read
from its file.

>>> from cam.formats.hpgl import parse_hpgl
>>> d = parse_hpgl(b"IN;SP1;PU0,0;PD400,0,400,-400;PU;", source="sq.plt")
>>> job = plan_hpgl(d, cut_depth_mm=0.5, travel_height_mm=1.0)
>>> job.points_steps[job.kind == CUT][:, :2].tolist()     # 10 mm = 346 steps of 0.0289 mm
[[0, 0], [346, 0], [346, 346]]
>>> job.pause_notes
['tool change: pen 1']
"""
from __future__ import annotations

import os
from typing import Optional, Union

import numpy as np

from ..formats.hpgl import HpglDrawing
from ..settings import DEFAULT_SETTINGS, MachineSettings
from .hpgl_stream import DEFAULT_CUT_DEPTH_MM, DEFAULT_TRAVEL_HEIGHT_MM, hpgl_scale, stream_hpgl, xy_steps
from .hpgl_stream import _rows, _z_steps, scale_to_fit  # noqa: F401  (cam.job.svg plans its strokes with them)
from .model import CUT, Job  # noqa: F401  (CUT: the doctest)

__all__ = ["plan_hpgl", "hpgl_steps", "DEFAULT_CUT_DEPTH_MM", "DEFAULT_TRAVEL_HEIGHT_MM"]


def hpgl_steps(drawing: HpglDrawing, *, settings: MachineSettings = DEFAULT_SETTINGS,
               offset_mm: Optional[tuple[float, float]] = None, scale: Optional[float] = None,
               fit_mm: Optional[tuple[float, float]] = None) -> np.ndarray:
    """``(N, 2)`` int64 machine ``(x, y)`` steps of every point of ``drawing`` (see the module docstring).

    Nearest step: ``floor(v + 0.5)`` of the exact position in steps (:func:`cam.job.hpgl_stream.xy_steps`).
    """
    pu = drawing.points_pu
    if len(pu) == 0:
        return np.zeros((0, 2), np.int64)
    factor = hpgl_scale(drawing.summary(), scale=scale, fit_mm=fit_mm)
    return xy_steps(pu[:, 0], pu[:, 1], drawing.extent_pu(), settings, offset_mm, factor)


def plan_hpgl(
    drawing: Union[HpglDrawing, str, os.PathLike],
    *,
    settings: MachineSettings = DEFAULT_SETTINGS,
    cut_depth_mm: float = DEFAULT_CUT_DEPTH_MM,
    travel_height_mm: float = DEFAULT_TRAVEL_HEIGHT_MM,
    offset_mm: Optional[tuple[float, float]] = None,
    scale: Optional[float] = None,
    fit_mm: Optional[tuple[float, float]] = None,
    home_steps: Optional[tuple[int, int, int]] = None,
) -> Job:
    """Plan the cutting of an HPGL drawing, in machine steps: the pieces of
    :func:`cam.job.hpgl_stream.stream_hpgl` joined.

    Each stroke: travel at the safe height to its first point, plunge to the cutting depth, cut
    through its points (one straight move per pen-down segment), lift.  A stroke that starts within
    one step of where the previous one ended, with the same tool, is cut on without lifting.  When the
    pen changes (the first ``SP`` too), the job pauses at the safe height with the note
    ``"tool change: pen N"`` (004 section 3.6.2: ``SPn`` means the drill bit is changed).  The job
    starts and ends at (0, 0, 0); a stop lifts the tool to the safe height (``safe_z_steps``).

    Args:
        drawing: the strokes (:func:`cam.formats.hpgl.load_hpgl`), or the HPGL file (read a chunk at a time).
        settings: machine settings (mm per step, delays, travel).
        cut_depth_mm: cutting depth below the surface (> 0); travel_height_mm: travel height above it (>= 0).
        offset_mm: machine position (mm from the home) of plotter (0, 0), scaled; None = the drawing's top-left at
            the home.
        scale: mm cut per mm of the plot (after its own ``SC``/``IP`` scaling); fit_mm: or the ``(width, height)``
            mm to scale it to fit, keeping its proportions (as SVG's ``--scale`` and ``--fit``).
        home_steps: the machine position of the job's home, its (0, 0, 0): the travel is checked in the machine
            frame from there (a file placed by its own zero at a work zero, ``offset_mm`` (0, 0)); None: the job's
            own frame (placed when it runs, where it is checked): it must fit the travel's span.

    Returns:
        A :class:`~cam.job.model.Job` in machine steps: CUT points at the
        cutting depth (``target`` marks them), TRAVEL at the safe height, RETRACT straight up.

    Raises:
        PlanError: bad options, nothing drawn; TravelError: a point outside the travel (or, in its own frame, one
        that makes the job wider than the travel), ``file:line:column``;
        ParseError: a malformed file.
    """
    return stream_hpgl(drawing, settings=settings, cut_depth_mm=cut_depth_mm, travel_height_mm=travel_height_mm,
                       offset_mm=offset_mm, scale=scale, fit_mm=fit_mm, home_steps=home_steps).joined()
