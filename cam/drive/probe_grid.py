"""The grid a height map is probed on (issue #46 points 1 and 5): pure computation, no port.

:func:`grid_plan` turns an area (machine mm) into the points to probe (machine steps, serpentine order: each row
the other way round from the one before) ``spacing_mm`` apart, centred on the area grown by a margin;
:func:`height_map_of` turns the probes made there into the :class:`~cam.job.heightmap_level.HeightMap`.  The
session's :meth:`~cam.drive.session.MachineSession.probe_map` (``cam probe grid``, the page's Probe the job's area)
probes them.  Frames: machine steps (+Z deeper) and machine mm (heights up positive).

:class:`GridApproach` is how a grid is probed after its first point (each point a neighbour of the one before, as
the serpentine order makes them): the first point is probed from the safe height asked, at most the depth asked;
each later one from heights the contacts so far give (:meth:`GridApproach.heights`):

* the tool retracts from the probe and travels to the next point at ``margin_mm`` above the previous contact plus
  the map's neighbour limit (``limit_mm``, :data:`~cam.job.heightmap_level.DEFAULT_MAX_DIFF_MM`: a map whose
  neighbouring points differ by more is refused by levelling), and never below the highest contact so far plus
  ``margin_mm``: over any surface a usable map can be probed on, the travel is at least ``margin_mm`` above the
  next point's surface;
* over the next point it rapids down to the guard height, the previous contact plus the neighbour limit (as high
  as a usable map's surface can be there), then moves down at the approach's feed (``feed_mm_min``: Z's start
  speed, the fastest a probe may run on a step/dir machine) to ``approach_mm`` above the surface expected there
  (the previous contact), a guarded move that stops where the probe closes (a surface higher than expected stops
  it: then the probe starts ``approach_mm`` above that contact), and only then probes at the probe feed;
* the probe's depth is bounded: at most down to ``limit_mm`` below the previous contact (a deeper contact would
  be refused by the neighbour limit), and never below the deepest point the first probe could reach.

No move runs toward the surface faster than a probe's feed where a usable map's surface could be, and the probe
feed covers about ``approach_mm`` a point instead of the whole safe height (OpenCNCPilot's procedure starts each
probe 1 mm above the previous contact and travels there; ``benchmarks/bench_probe.py`` compares them).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Optional, Sequence

import numpy as np

from ..errors import PlanError
from ..job.heightmap_level import DEFAULT_MAX_DIFF_MM, HeightMap
from ..settings import MachineSettings
from .probing import ProbeResult, grid_axis_mm, serpentine

__all__ = ["GridApproach", "GridPlan", "grid_plan", "height_map_of", "TRAVEL_MARGIN_MM", "APPROACH_MM"]

TRAVEL_MARGIN_MM = 0.5
"""How far above the highest surface a usable map allows at the next point the tool travels, mm."""
APPROACH_MM = 0.3
"""How far above the surface expected at a point the guarded move down stops and the probe feed begins, mm."""


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


@dataclass(frozen=True)
class GridApproach:
    """How the points of a grid after its first are approached and probed (see the module), in machine Z steps.

    Attributes:
        limit_steps: the map's neighbour limit (two neighbouring points differ by at most this much).
        margin_steps: the travel's clearance above the highest surface the limit allows at the next point.
        approach_steps: how far above the expected surface the probe starts.
        feed_mm_min: the guarded move's feed down from the guard height (mm/min; a probe's feed if that is faster).
    """

    limit_steps: int
    margin_steps: int
    approach_steps: int
    feed_mm_min: float = 20.0

    @classmethod
    def of(cls, settings: MachineSettings, *, limit_mm: float = DEFAULT_MAX_DIFF_MM,
           margin_mm: float = TRAVEL_MARGIN_MM, approach_mm: float = APPROACH_MM) -> "GridApproach":
        """The approach in ``settings``' Z steps (each at least one step), its guarded move at Z's start speed.

        Raises:
            PlanError: a limit, margin or approach that is not a number of mm > 0 (at most 1000).
        """
        for name, v in (("the neighbour limit", limit_mm), ("the travel margin", margin_mm),
                        ("the approach", approach_mm)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 < v <= 1000):
                raise PlanError(f"{name} must be a number of mm > 0 (at most 1000), got {v!r:.40}")
        per = settings.mm_per_step_z
        limit, margin, approach = (max(1, int(math.ceil(v / per - 1e-9))) for v in (limit_mm, margin_mm, approach_mm))
        return cls(limit, margin, approach, float(settings.start_speed_z_mm_s) * 60.0)

    def heights(self, contacts_z: Sequence[int], floor_z: int) -> tuple[int, int, int, int]:
        """``(travel_z, guard_z, start_z, depth_steps)`` for the next point, machine Z steps (+Z deeper): the height
        to travel to it at, the height a rapid down over it stops at, the height the guarded move below that stops at
        (where its probe starts) and how far the probe goes down at most.

        Args:
            contacts_z: the machine Z of every contact so far, in the order probed (at least one; the last is the
                next point's neighbour).
            floor_z: the deepest machine Z any probe of the grid may reach.

        >>> a = GridApproach(limit_steps=64, margin_steps=32, approach_steps=20)
        >>> a.heights([50, 52, 49], floor_z=400)  # travel 96 above the last contact, guard 64, start 20 above it
        (-47, -15, 29, 84)
        """
        if not len(contacts_z):
            raise PlanError("the approach to a grid's point needs a contact before it")
        z = np.asarray(contacts_z, np.int64)
        prev, top = int(z[-1]), int(z.min())
        travel = min(prev - self.limit_steps, top) - self.margin_steps
        guard = prev - self.limit_steps
        start = max(guard, prev - self.approach_steps)
        lowest = min(prev + self.limit_steps, int(floor_z))
        return travel, guard, start, max(1, lowest - start)


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
