"""The HPGL planner: a plotter drawing to a job in machine steps (seed 004, section 3.6.2).

Frames and units (as :mod:`cam.job.drill`): HPGL X right, Y up, plotter units.
Machine x = X, machine y = -Y (toward the operator), in steps of
``settings.mm_per_step_xy``, rounded to the nearest step (the seed truncates:
``xsteps = xcoord * 250 / 254`` in integer arithmetic, 004 section 3.6.2).  By
default the drawing's top-left corner (smallest X, largest Y of its pen-down
points) is placed at the home (0, 0); ``offset_mm=(X, Y)`` instead puts
plotter (0, 0) at machine (X, Y) mm from the home.

>>> from cam.formats.hpgl import parse_hpgl
>>> d = parse_hpgl(b"IN;SP1;PU0,0;PD400,0,400,-400;PU;", source="sq.plt")
>>> job = plan_hpgl(d, depth_mm=0.5, safe_height_mm=1.0)
>>> job.points_steps[job.kind == CUT][:, :2].tolist()     # 10 mm = 346 steps of 0.0289 mm
[[0, 0], [346, 0], [346, 346]]
>>> job.pause_notes
['tool change: pen 1']
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from ..errors import PlanError, TravelError
from ..formats.hpgl import PLOTTER_UNIT_MM, HpglDrawing
from ..settings import DEFAULT_SETTINGS, MachineSettings
from .model import CUT, RETRACT, TRAVEL, Job, check_travel

__all__ = ["plan_hpgl", "hpgl_steps", "DEFAULT_CUT_DEPTH_MM", "DEFAULT_SAFE_HEIGHT_MM"]

DEFAULT_CUT_DEPTH_MM = 0.5
DEFAULT_SAFE_HEIGHT_MM = 1.0


def hpgl_steps(drawing: HpglDrawing, *, settings: MachineSettings = DEFAULT_SETTINGS,
               offset_mm: Optional[tuple[float, float]] = None) -> np.ndarray:
    """``(N, 2)`` int64 machine ``(x, y)`` steps of every point of ``drawing`` (see the module docstring).

    Nearest step: ``floor(v + 0.5)`` of the exact position in steps.
    """
    pu = drawing.points_pu
    k = PLOTTER_UNIT_MM / settings.mm_per_step_xy
    if len(pu) == 0:
        return np.zeros((0, 2), np.int64)
    if offset_mm is None:
        x_steps = (pu[:, 0] - pu[:, 0].min()) * k
        y_steps = (pu[:, 1].max() - pu[:, 1]) * k
    else:
        ox, oy = offset_mm
        x_steps = (ox + pu[:, 0] * PLOTTER_UNIT_MM) / settings.mm_per_step_xy
        y_steps = (oy - pu[:, 1] * PLOTTER_UNIT_MM) / settings.mm_per_step_xy
    return np.floor(np.column_stack([x_steps, y_steps]) + 0.5).astype(np.int64)


def plan_hpgl(
    drawing: HpglDrawing,
    *,
    settings: MachineSettings = DEFAULT_SETTINGS,
    depth_mm: float = DEFAULT_CUT_DEPTH_MM,
    safe_height_mm: float = DEFAULT_SAFE_HEIGHT_MM,
    offset_mm: Optional[tuple[float, float]] = None,
) -> Job:
    """Plan the cutting of an HPGL drawing, in machine steps.

    Each stroke: travel at the safe height to its first point, plunge to the cutting depth, cut
    through its points (one straight move per pen-down segment), lift.  A stroke that starts within
    one step of where the previous one ended, with the same tool, is cut on without lifting.  When the
    pen changes (the first ``SP`` too), the job pauses at the safe height with the note
    ``"tool change: pen N"`` (004 section 3.6.2: ``SPn`` means the drill bit is changed).  The job
    starts and ends at (0, 0, 0).

    Args:
        drawing: the strokes (:func:`cam.formats.hpgl.load_hpgl`).
        settings: machine settings (mm per step, delays, travel).
        depth_mm: cutting depth below the surface (> 0); safe_height_mm: travel height above it (>= 0).
        offset_mm: machine position (mm from the home) of plotter (0, 0); None = the drawing's top-left at the home.

    Returns:
        A :class:`~cam.job.model.Job` in machine steps: CUT points at the
        cutting depth (``target`` marks them), TRAVEL at the safe height, RETRACT straight up.

    Raises:
        PlanError: bad options, nothing drawn; TravelError: a point outside the travel, ``file:line:column``.
    """
    if not (depth_mm > 0) or not (safe_height_mm >= 0):
        raise PlanError("the cutting depth must be > 0 mm and the safe height >= 0 mm")
    if len(drawing.points_pu) == 0:
        raise PlanError(f"{drawing.source}: nothing to cut (no pen-down moves)")
    xy = hpgl_steps(drawing, settings=settings, offset_mm=offset_mm)
    _check_xy(drawing, xy, settings)
    depth_steps, safe_steps = _z_steps(depth_mm, safe_height_mm, settings)
    xy, group, pause_group, tool, change = _strokes(drawing, xy)
    pts, kind, pause = _rows(xy, group, pause_group, depth_steps, safe_steps)
    check_travel(pts, settings)
    notes = [f"tool change: pen {int(t)}" for t in tool[change]]
    return Job(points_steps=pts, kind=kind, target=(kind == CUT) & (pts[:, 2] == depth_steps), pause=pause,
               settings=settings, warnings=list(drawing.warnings), pause_notes=notes, source=drawing.source)


def _check_xy(drawing: HpglDrawing, xy: np.ndarray, settings: MachineSettings) -> None:
    """TravelError naming the first point (``file:line:column``) whose ``(N, 2)`` machine steps leave the travel."""
    (x_lo, x_hi), (y_lo, y_hi), _ = settings.travel.bounds_steps()
    bad = np.flatnonzero((xy[:, 0] < x_lo) | (xy[:, 0] > x_hi) | (xy[:, 1] < y_lo) | (xy[:, 1] > y_hi))
    if len(bad):
        i = int(bad[0])
        mm = settings.mm_per_step_xy
        raise TravelError(
            f"{drawing.source}:{int(drawing.point_line[i])}:{int(drawing.point_col[i])}: point "
            f"X{drawing.points_pu[i, 0]:g} Y{drawing.points_pu[i, 1]:g} (plotter units) lies outside the machine "
            f"travel (machine {xy[i, 0] * mm:.2f}, {xy[i, 1] * mm:.2f} mm; travel X {x_lo * mm:g}..{x_hi * mm:g} mm, "
            f"Y {y_lo * mm:g}..{y_hi * mm:g} mm)"
        )


def _z_steps(depth_mm: float, safe_height_mm: float, settings: MachineSettings) -> tuple[int, int]:
    """(cutting depth, safe height) in Z steps (+Z deeper: the safe height is <= 0), checked against the Z travel."""
    _, _, (z_lo, z_hi) = settings.travel.bounds_steps()
    depth_steps = int(round(depth_mm / settings.mm_per_step_z))
    safe_steps = -int(round(safe_height_mm / settings.mm_per_step_z))
    if depth_steps < 1:
        raise PlanError(f"cutting depth {depth_mm:g} mm is less than one Z step ({settings.mm_per_step_z:g} mm)")
    if depth_steps > z_hi or safe_steps < z_lo:
        raise TravelError(f"cutting depth {depth_mm:g} mm and safe height {safe_height_mm:g} mm need Z "
                          f"{safe_steps}..{depth_steps} steps; the Z travel is {z_lo}..{z_hi} steps")
    return depth_steps, safe_steps


def _strokes(drawing: HpglDrawing, xy: np.ndarray) -> tuple[np.ndarray, ...]:
    """The points to cut and where the tool lifts or changes.

    Args:
        xy: ``(N, 2)`` int64 machine steps of every point of ``drawing``.

    Returns:
        ``xy`` ``(K, 2)`` without the points at the same step as the one before in their stroke;
        ``group`` ``(K,)`` bool, a lift and a plunge before the point (a stroke that does not join
        the previous one); ``pause_group`` ``(K,)`` bool, a tool change before the point;
        ``tool`` ``(S,)`` the pen in the machine for each stroke; ``change`` ``(S,)`` bool, the
        stroke starts with a tool change.
    """
    n = len(xy)
    is_start = np.zeros(n, bool)
    is_start[drawing.stroke_start] = True
    # a point at the same step as the one before it in its stroke adds nothing
    dup = np.zeros(n, bool)
    dup[1:] = np.all(xy[1:] == xy[:-1], axis=1) & ~is_start[1:]
    keep = ~dup
    xy, is_start = xy[keep], is_start[keep]
    n = len(xy)
    # the tool in the machine for each stroke: pen 0 (none selected) keeps the tool that is in
    pens = drawing.stroke_pen.astype(np.int64)
    have = np.where(pens != 0, np.arange(len(pens)), -1)
    last = np.maximum.accumulate(have) if len(pens) else have
    tool = np.where(last >= 0, pens[np.maximum(last, 0)], 0)
    prev_tool = np.concatenate([[0], tool[:-1]])
    change = (tool != 0) & (tool != prev_tool)
    # strokes that begin within one step of the previous stroke's end continue without a lift
    starts = np.flatnonzero(is_start)
    joined = np.zeros(len(starts), bool)
    if len(starts) > 1:
        gap = np.abs(xy[starts[1:]] - xy[starts[1:] - 1]).max(axis=1)
        joined[1:] = (gap <= 1) & ~change[1:]
    group = np.zeros(n, bool)
    group[starts[~joined]] = True
    pause_group = np.zeros(n, bool)
    pause_group[starts] = change
    return xy, group, pause_group, tool, change


def _rows(xy: np.ndarray, group: np.ndarray, pause_group: np.ndarray, depth_steps: int,
          safe_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The job's ``(R, 3)`` int64 points, ``(R,)`` kinds and ``(R,)`` pauses from the points of :func:`_strokes`.

    Before each group: lift where the tool is, travel above the point, plunge; at the end: lift, travel
    to above the home, down to the home.  Moves of length 0 are dropped.
    """
    rows = np.where(group, 3, 1)
    first = np.cumsum(rows) - rows
    total = int(rows.sum()) + 3
    pts = np.empty((total, 3), np.int64)
    kind = np.full(total, CUT, np.uint8)
    pause = np.zeros(total, bool)
    gi = np.flatnonzero(group)
    prev = np.zeros((len(gi), 2), np.int64)
    prev[gi > 0] = xy[gi[gi > 0] - 1]
    r0 = first[gi]
    pts[r0, :2], pts[r0, 2], kind[r0] = prev, safe_steps, RETRACT  # lift where the tool is
    pts[r0 + 1, :2], pts[r0 + 1, 2], kind[r0 + 1] = xy[gi], safe_steps, TRAVEL  # travel above the stroke
    pts[r0 + 2, :2], pts[r0 + 2, 2] = xy[gi], depth_steps  # plunge
    pause[r0] = pause_group[gi]
    ci = np.flatnonzero(~group)
    pts[first[ci], :2], pts[first[ci], 2] = xy[ci], depth_steps
    end = xy[-1]
    pts[-3] = (end[0], end[1], safe_steps)
    kind[-3] = RETRACT
    pts[-2] = (0, 0, safe_steps)
    pts[-1] = (0, 0, 0)
    kind[-2:] = TRAVEL
    # drop moves of length 0 (row 0 stays: a pause at the start needs a point); a pause moves to the kept point
    same = np.zeros(total, bool)
    same[1:] = np.all(pts[1:] == pts[:-1], axis=1)
    keep_row = ~same
    if pause[same].any():
        idx = np.maximum.accumulate(np.where(keep_row, np.arange(total), 0))
        pause[idx[pause & same]] = True
    return pts[keep_row], kind[keep_row], pause[keep_row]
