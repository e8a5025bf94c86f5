"""The grid a height map is probed on (issue #46 points 1 and 5): pure computation, no port.

:func:`grid_plan` turns an area (machine mm) into the points to probe (machine steps, serpentine order: each row
the other way round from the one before) ``spacing_mm`` apart, centred on the area grown by a margin;
:func:`height_map_of` turns the probes made there into the :class:`~cam.job.heightmap_level.HeightMap`.  The
session's :meth:`~cam.drive.session.MachineSession.probe_map` (``cam probe grid``, the page's Probe the job's area)
probes them.  Frames: machine steps (+Z deeper) and machine mm (heights up positive).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Optional, Sequence

import numpy as np

from ..errors import PlanError
from ..job.heightmap_level import HeightMap
from ..settings import MachineSettings
from .probing import ProbeResult, grid_axis_mm, serpentine

__all__ = ["GridPlan", "grid_plan", "height_map_of"]


@dataclass(frozen=True)
class GridPlan:
    """The points of a probe grid: ``xs_steps`` (nx,) and ``ys_steps`` (ny,) machine X, Y in steps, ascending;
    ``order`` the ``(i, j)`` (column, row) probed one after the other; ``spacing_mm`` as asked."""

    xs_steps: np.ndarray
    ys_steps: np.ndarray
    order: list[tuple[int, int]]
    spacing_mm: float

    @property
    def points_steps(self) -> list[tuple[int, int]]:
        """The machine ``(x, y)`` steps in the order probed."""
        return [(int(self.xs_steps[i]), int(self.ys_steps[j])) for i, j in self.order]


def grid_plan(area_mm: Sequence[float], spacing_mm: float, settings: MachineSettings, *,
              margin_mm: float = 0.0) -> GridPlan:
    """The grid over ``area_mm`` ``(x0, y0, x1, y1)`` (machine mm) grown by ``margin_mm`` on every side, points
    ``spacing_mm`` apart centred on it (:func:`~cam.drive.probing.grid_axis_mm`), rounded to whole steps.

    Raises:
        PlanError: a bad area, spacing or margin; a spacing under one X or Y step.

    >>> from cam.settings import MachineSettings
    >>> g = grid_plan((0, 0, 10, 5), 5.0, MachineSettings().replace(mm_per_step_xy=0.01))
    >>> g.xs_steps.tolist(), g.ys_steps.tolist(), g.points_steps[:4]
    ([0, 500, 1000], [0, 500], [(0, 0), (500, 0), (1000, 0), (1000, 500)])
    """
    if len(area_mm) != 4 or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                    and math.isfinite(v) for v in area_mm):
        raise PlanError(f"the area must be four numbers of mm X0,Y0,X1,Y1, got {list(area_mm)!r:.80}")
    if isinstance(margin_mm, bool) or not isinstance(margin_mm, (int, float)) or not 0 <= margin_mm <= 1e5:
        raise PlanError(f"the margin must be a number of mm 0..100000, got {margin_mm!r:.40}")
    if isinstance(spacing_mm, bool) or not isinstance(spacing_mm, (int, float)) \
            or not (math.isfinite(spacing_mm) and 0 < spacing_mm <= 1e5):
        raise PlanError(f"the spacing must be a number of mm > 0 (at most 100000), got {spacing_mm!r:.40}")
    if any(abs(v) > 1e6 for v in area_mm):
        raise PlanError(f"the area reaches past a km from the home: {list(area_mm)!r:.80}")
    x0, y0, x1, y1 = (float(v) for v in area_mm)
    per_x, per_y, _ = settings.mm_per_step_axes
    m = float(margin_mm)
    xs = np.rint(grid_axis_mm(x0 - m, x1 + m, float(spacing_mm)) / per_x).astype(np.int64)
    ys = np.rint(grid_axis_mm(y0 - m, y1 + m, float(spacing_mm)) / per_y).astype(np.int64)
    if len(np.unique(xs)) != len(xs) or len(np.unique(ys)) != len(ys):
        raise PlanError(f"a spacing of {spacing_mm:g} mm is less than one X or Y step")
    return GridPlan(xs, ys, serpentine(len(xs), len(ys)), float(spacing_mm))


def height_map_of(plan: GridPlan, results: Sequence[ProbeResult], settings: MachineSettings, *,
                  reference_steps: int, machine: Optional[str] = None, time: Optional[str] = None) -> HeightMap:
    """The height map of the probes ``results`` made at ``plan``'s points in its order (machine mm, heights up
    positive); ``reference_steps``: the work Z zero's machine Z when probed (the map's ``reference_mm``)."""
    if len(results) != len(plan.order):
        raise PlanError(f"{len(results)} probes for a grid of {len(plan.order)} points")
    per_x, per_y, per_z = settings.mm_per_step_axes
    heights = np.zeros((len(plan.ys_steps), len(plan.xs_steps)), np.float64)
    for (i, j), r in zip(plan.order, results):
        heights[j, i] = r.height_mm(settings)
    when = time if time is not None else datetime.now(timezone.utc).isoformat(timespec="seconds")
    return HeightMap(plan.xs_steps * per_x, plan.ys_steps * per_y, heights, reference_mm=-int(reference_steps) * per_z,
                     spacing_mm=plan.spacing_mm, machine=machine, time=when)
