"""The SVG planner: the strokes of an SVG file to a job in machine steps.

Frames and units: the drawing's strokes are in mm, x right, y down the page
(:mod:`cam.formats.svg`); machine x = x, machine y = y (y grows toward the
operator, as a drawing's rows do), in steps of ``settings.mm_per_step_xy``.
The drawing is scaled by ``scale`` (or to fit ``fit_mm``), then placed: by
default the top-left of what is cut at the home (0, 0); ``offset_mm=(X, Y)``
instead puts the page's origin (0, 0), scaled, at machine (X, Y) mm from the
home.  The job's points are steps from its home; ``home_steps`` says where the
home is in the machine frame (a file placed by its own zero at a work zero:
``offset_mm`` (0, 0) and the work zero), and the travel is checked there.
Without it the job is planned in its own frame, placed at the work zero when it
runs and checked there; here it must fit the travel's span (issue #45 point 4).

How a curve becomes steps, so that every cut position lies within one step of the exact curve (0.71 + 0.15)
and every point of the curve within one step of a cut position (0.15 + 0.125 + 0.71):

1. Each stroke is flattened to a polyline within 0.15 step of the curve (:meth:`SvgDrawing.polylines`).
2. The polyline is sampled every quarter step or closer and each sample rounded to the nearest step;
   repeated positions are dropped, so consecutive positions are 8-neighbours, each within 0.71 step of the
   polyline.  A position between two 8-neighbours (a staircase corner) is dropped, so the path moves
   diagonally, unless it is where the polyline turns by more than :data:`CORNER_DEG` or a sample that
   rounds to it would be left more than 0.7 step from any cut position; runs of the same unit move are joined into one straight move (which visits the same positions).
3. Strokes are ordered for short travel: from where the tool is, the stroke whose nearer end is nearest
   comes next, cut from that end (a stroke is reversed only when its end is strictly nearer than its
   start).  Layers (:attr:`SvgDrawing.layers <cam.formats.svg.SvgDrawing.layers>`) are cut one after the
   other, in file order or in the order ``layers`` names them (only those), and the nearest-stroke order
   stays within a layer (it starts where the layer before ended).  ``pause_between_layers``: the job pauses
   (lifted, above the end of the layer before) before each layer after the first, with the note
   ``layer 'NAME': change the pen``.
4. Each stroke: lift, travel at the safe height above its start, plunge to the cutting depth, cut, lift; a
   stroke that starts within one step of where the last one ended is cut on without lifting (never across a
   pause).  The job starts and ends at (0, 0, 0).

Duplicates (unless ``keep_duplicates``): before step 2, every straight piece of the polylines (a line, or
one chord of a flattened curve) longer than :data:`MIN_DUPLICATE_STEPS` whose two ends lie within
:data:`DUPLICATE_STEPS` (in x and in y) of the two ends of a piece of the same layer that comes earlier in
file order and is cut, in either direction, traces what is already cut, and is dropped; a stroke is cut in the runs of pieces
left.  A job warning counts them.  (Pieces are compared end to end: a line drawn once as one piece and once
as two is not found.)

The job is made whole, one :class:`~cam.job.model.Job` (a job held in memory is one piece of a
:class:`~cam.job.model.JobLike`), not a piece at a time as HPGL's and G-code's are: the default placement
needs the extent of every stroke (the top-left of what is cut goes to the home), the travel check gives the
drawing's whole extent, and the cutting order (step 3) picks from all the strokes left the one nearest to
where the tool is, so no stroke can be cut before every stroke is known.  What it holds is bounded by the
input anyway: the SVG document is parsed into memory (an XML tree), and its strokes' positions are the job's
rows.

>>> from cam.formats.svg import parse_svg
>>> d = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="10mm" height="10mm" viewBox="0 0 10 10">'
...               '<path d="M0,0 H1 V1" stroke="black"/></svg>')
>>> job = plan_svg(d, cut_depth_mm=0.3)
>>> job.points_steps[job.target][:, :2].tolist()   # 1 mm = 34.6 steps of 0.0289 mm
[[0, 0], [35, 0], [35, 35]]
"""
from __future__ import annotations

import dataclasses
import math
from typing import Optional, Sequence, Union

import numpy as np

from ..errors import PlanError, TravelError
from ..options import OPTIONS, keyword_error
from ..formats.svg import SvgDrawing
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ._svg_kernels import cells_kernel, duplicate_pieces_kernel, nearest_order_kernel
from .hpgl import _rows, _z_steps, scale_to_fit
from .hpgl_stream import outside_travel
from .model import CUT, Job, TravelSpan, check_span, check_travel

__all__ = ["plan_svg", "svg_strokes_steps", "svg_scale", "svg_layer_order", "selected_layers", "DEFAULT_CUT_DEPTH_MM",
           "DEFAULT_TRAVEL_HEIGHT_MM", "DUPLICATE_STEPS", "MIN_DUPLICATE_STEPS"]

DEFAULT_CUT_DEPTH_MM: float = OPTIONS["cut_depth_mm"].default_for({"strokes"})
"""As HPGL's pen-down depth: a vector drawing engraved (declared once, with the option)."""
DEFAULT_TRAVEL_HEIGHT_MM: float = OPTIONS["travel_height_mm"].default_for({"placed"})
FLATTEN_STEPS = 0.15
"""Curves are flattened to within this many steps (the rounding to whole steps takes at most half a step more)."""
SAMPLE_STEPS = 0.25
"""The polylines are sampled at most this many steps apart before rounding."""
CORNER_REACH_STEPS = 0.7
"""A staircase corner is dropped only when each of its samples lies this near a neighbouring kept position."""
DUPLICATE_STEPS = 0.25
"""A piece whose ends lie this near (steps, in x and in y) the ends of a piece already cut is a duplicate."""
MIN_DUPLICATE_STEPS = 2 * DUPLICATE_STEPS
"""Pieces no longer than this (steps) are never duplicates: a piece that short is within a step of its
neighbours, and dropping it would only split its stroke."""


def svg_scale(drawing: SvgDrawing, *, scale: Optional[float] = None,
              fit_mm: Optional[tuple[float, float]] = None) -> float:
    """The factor from the drawing's mm to the job's mm: ``scale``, or the largest that fits ``fit_mm``
    ``(width, height)`` (the drawing keeps its proportions), or 1 (:func:`cam.job.hpgl_stream.scale_to_fit`).

    Raises:
        PlanError: both given, a factor that is not > 0, nothing to fit.
    """
    def size_mm() -> tuple[float, float]:
        x0, y0, x1, y1 = drawing.extent_mm()
        return x1 - x0, y1 - y0

    return scale_to_fit(size_mm, drawing.source, scale=scale, fit_mm=fit_mm)


CORNER_DEG = 20.0
"""A polyline vertex where the direction turns by more than this is a corner: its position is always cut."""


def _cells(poly_steps: np.ndarray) -> np.ndarray:
    """``(M, 2)`` int64 positions of one polyline (float steps): samples at most half a step apart, rounded,
    repeats dropped, staircase corners dropped, runs of one unit move joined (module docstring, step 2)."""
    d = np.diff(poly_steps, axis=0)
    if not len(d):
        return np.floor(poly_steps + 0.5).astype(np.int64)
    n = np.maximum(1, np.ceil(np.abs(d).max(axis=1) / SAMPLE_STEPS)).astype(np.int64)
    seg = np.repeat(np.arange(len(d)), n)
    i_in_seg = np.arange(len(seg)) - np.repeat(np.cumsum(n) - n, n)
    t = i_in_seg / np.repeat(n, n)
    pts = np.vstack([poly_steps[seg] + d[seg] * t[:, None], poly_steps[-1:]])
    # corners: vertices where the polyline turns sharply (and both ends) keep their position
    length = np.hypot(d[:, 0], d[:, 1])
    turn = np.zeros(len(poly_steps), bool)
    turn[[0, -1]] = True
    ok = (length[:-1] > 0) & (length[1:] > 0)
    cos = np.einsum("ij,ij->i", d[:-1], d[1:]) / np.where(ok, length[:-1] * length[1:], 1.0)
    turn[1:-1] = ok & (cos < math.cos(math.radians(CORNER_DEG)))
    fixed = np.append(turn[seg] & (i_in_seg == 0), True)
    cells = np.floor(pts + 0.5).astype(np.int64)
    new = np.ones(len(cells), bool)
    new[1:] = np.any(cells[1:] != cells[:-1], axis=1)
    run = np.cumsum(new) - 1  # the kept position each sample rounds to
    fixed_kept = np.zeros(int(run[-1]) + 1, bool)
    np.logical_or.at(fixed_kept, run, fixed)
    cells = _drop_corners(cells[new], fixed_kept, pts, run)
    if len(cells) < 3:
        return cells
    step = np.diff(cells, axis=0)
    same = np.zeros(len(cells), bool)
    same[1:-1] = np.all(step[1:] == step[:-1], axis=1)  # a point inside a run of one unit move
    return cells[~same]


def _drop_corners(cells: np.ndarray, fixed: np.ndarray, samples: np.ndarray, run: np.ndarray) -> np.ndarray:
    """Drop the corners of staircases so that the path moves diagonally.

    A position (not ``fixed``) whose two neighbours are 8-neighbours of each other is dropped when every
    sample that rounds to it (``samples[run == i]``) lies within :data:`CORNER_REACH_STEPS` of one of those
    neighbours, never two in a row: so every sample stays within that distance of a kept position.
    """
    if len(cells) < 3:
        return cells
    corner = np.zeros(len(cells), bool)
    corner[1:-1] = (np.abs(cells[2:] - cells[:-2]).max(axis=1) <= 1) & ~fixed[1:-1]
    inner = (run > 0) & (run < len(cells) - 1)
    r = run[inner]
    s = samples[inner]
    reach = np.minimum(np.hypot(*(s - cells[r - 1]).T), np.hypot(*(s - cells[r + 1]).T))
    worst = np.zeros(len(cells))
    np.maximum.at(worst, r, reach)
    corner &= worst <= CORNER_REACH_STEPS
    for i in np.flatnonzero(corner):
        if corner[i - 1]:
            corner[i] = False
    return cells[~corner]


def _cells_many(polys: list[np.ndarray]) -> list[np.ndarray]:
    """``[_cells(p) for p in polys]``, by :func:`_cells_joined`."""
    if not polys:
        return []
    bounds = np.zeros(len(polys) + 1, np.int64)
    np.cumsum([len(p) for p in polys], out=bounds[1:])
    cells, cell_bounds = _cells_joined(np.concatenate(polys), bounds)
    return np.split(cells, cell_bounds[1:-1])


def _cells_joined(pts: np.ndarray, bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The positions of :func:`_cells` of every polyline ``pts[bounds[i]:bounds[i + 1]]``, one after another, and
    where each polyline's begin (``(S + 1,)``): one compiled pass over all of them
    (:func:`cam.job._svg_kernels.cells_kernel`: a halftone's 50,000 strokes are not 50,000 passes of a few dozen
    numpy calls each, and a long stroke's millions of samples are never held at once)."""
    found = cells_kernel(np.ascontiguousarray(pts, dtype=float), np.ascontiguousarray(bounds, dtype=np.int64),
                         float(SAMPLE_STEPS), math.cos(math.radians(CORNER_DEG)), float(CORNER_REACH_STEPS))
    cell_bounds = found[len(found) - len(bounds):, 0].copy()
    return found[:cell_bounds[-1]], cell_bounds


def svg_strokes_steps(drawing: SvgDrawing, *, settings: MachineSettings = DEFAULT_SETTINGS,
                      scale: Optional[float] = None, fit_mm: Optional[tuple[float, float]] = None,
                      offset_mm: Optional[tuple[float, float]] = None) -> list[np.ndarray]:
    """Each stroke as ``(M, 2)`` int64 machine ``(x, y)`` steps, in file order and direction (steps 1 and 2
    of the module docstring; every stroke, duplicates kept)."""
    pts, bounds = _polylines_steps(drawing, settings, scale, fit_mm, offset_mm)
    return [_cells(p) for p in np.split(pts, bounds[1:-1])] if len(bounds) > 1 else []


def _polylines_steps(drawing: SvgDrawing, settings: MachineSettings, scale: Optional[float],
                     fit_mm: Optional[tuple[float, float]], offset_mm: Optional[tuple[float, float]]
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Each stroke's polyline (step 1) in float64 machine ``(x, y)`` steps, placed and scaled, one after another
    (``(P, 2)``), and where each begins (``(S + 1,)``, the last ``P``)."""
    k = svg_scale(drawing, scale=scale, fit_mm=fit_mm)
    mm_per_step = settings.mm_per_step_xy
    pts, bounds = drawing.polylines_joined(FLATTEN_STEPS * mm_per_step / k)
    if len(bounds) < 2:
        return pts, bounds
    origin = -(pts.min(axis=0) * k) if offset_mm is None else np.asarray(offset_mm, float)
    return (origin + pts * k) / mm_per_step, bounds


def svg_layer_order(drawing: SvgDrawing, layers: Optional[Union[str, Sequence[str]]] = None) -> list[int]:
    """The layers to cut, as indices of ``drawing.layers()`` in cutting order: all in file order (None), or
    those ``layers`` names (a list, or text of names separated by commas), in that order, each once; a name
    selects its sublayers too, and on a drawing layered by colour any spelling of the colour (``red``).

    Raises:
        PlanError: a name that is no layer of the drawing (one line, naming the layers there are).
    """
    names = drawing.layers()
    if layers is None:
        return list(range(len(names)))
    wanted = [n.strip() for n in (_split_names(layers) if isinstance(layers, str) else layers) if n.strip()]
    if not wanted:
        raise PlanError(f"{drawing.source}: --layers names no layer; the layers are " + _listed(names))
    out: list[int] = []
    for name in wanted:
        found = drawing.find_layers(name)
        if not found:
            raise PlanError(f"{drawing.source}: no layer '{name}'; the layers are " + _listed(names))
        out += [i for i in found if i not in out]
    return out


def _split_names(text: str) -> list[str]:
    """Names separated by commas, a comma inside parentheses kept (``rgb(255,0,0)``)."""
    out, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        depth += (ch == "(") - (ch == ")")
        if ch == "," and depth <= 0:
            out.append(text[start:i])
            start = i + 1
    return out + [text[start:]]


def _listed(names: list[str]) -> str:
    return ", ".join(f"'{n}'" for n in names)


def _drop_duplicates(pts: np.ndarray, bounds: np.ndarray, layer_of: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float]:
    """The polylines ``pts[bounds[i]:bounds[i + 1]]`` (float steps, in cutting order, stroke ``i`` in layer
    ``layer_of[i]``) without the pieces that trace pieces before them in their layer (the module docstring; a line
    drawn in two layers is two pens' lines: both are cut): ``(points, bounds of the runs left, stroke of each run,
    pieces dropped, steps dropped)``, the runs in stroke order."""
    n_strokes = len(bounds) - 1
    owner = np.arange(n_strokes)
    if len(pts) < 2:
        return pts, bounds, owner, 0, 0.0
    a, b = pts[:-1], pts[1:]
    length = np.hypot(*(b - a).T)
    counts = np.diff(bounds) - 1
    piece = np.ones(len(a), bool)
    piece[bounds[1:-1] - 1] = False  # from one stroke's last point to the next one's first: no piece
    piece_layer = np.repeat(np.asarray(layer_of, np.int64), np.maximum(counts, 0))
    where = np.flatnonzero(piece)
    long_piece = length[where] > MIN_DUPLICATE_STEPS
    dropped = np.zeros(len(a), bool)
    dup_steps = 0.0
    for layer in dict.fromkeys(np.asarray(layer_of).tolist()):
        mine = where[long_piece & (piece_layer == layer)]
        if len(mine) > 1 and np.isfinite(a[mine]).all() and np.isfinite(b[mine]).all():  # else refused later
            gone = duplicate_pieces_kernel(a[mine], b[mine], float(DUPLICATE_STEPS))
            dropped[mine[gone]] = True
            dup_steps += float(length[mine[gone]].sum())  # layer by layer, as the warning has always added them
    if not dropped.any():
        return pts, bounds, owner, 0, 0.0
    return (*_runs_left(pts, bounds, dropped), int(dropped.sum()), dup_steps)


def _runs_left(pts: np.ndarray, bounds: np.ndarray, dropped: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The runs of pieces not ``dropped`` (``dropped[j]``: the piece from ``pts[j]`` to ``pts[j + 1]``) of each
    polyline, a polyline none of whose pieces is dropped whole: ``(points, bounds, polyline of each run)``."""
    gone_before = np.r_[0, np.cumsum(dropped)]
    touched = gone_before[bounds[1:] - 1] > gone_before[bounds[:-1]]
    lo, hi, owner = [bounds[:-1][~touched]], [bounds[1:][~touched]], [np.flatnonzero(~touched)]
    for s in np.flatnonzero(touched).tolist():  # only the polylines that lost a piece are cut into runs
        b0, b1 = int(bounds[s]), int(bounds[s + 1])
        edges = np.diff(np.r_[0, (~dropped[b0:b1 - 1]).astype(np.int8), 0])
        r0, r1 = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        lo.append(b0 + r0)
        hi.append(b0 + r1 + 1)
        owner.append(np.full(len(r0), s))
    run_owner = np.concatenate(owner).astype(np.int64)
    keep = np.argsort(run_owner, kind="stable")  # the runs in polyline order, each polyline's in order
    run_lo, run_hi, run_owner = np.concatenate(lo)[keep], np.concatenate(hi)[keep], run_owner[keep]
    sizes = run_hi - run_lo
    run_bounds = np.zeros(len(sizes) + 1, np.int64)
    np.cumsum(sizes, out=run_bounds[1:])
    index = np.arange(run_bounds[-1]) + np.repeat(run_lo - run_bounds[:-1], sizes)
    return pts[index], run_bounds, run_owner


def _order(strokes: list[np.ndarray], at: Optional[np.ndarray] = None) -> list[np.ndarray]:
    """The strokes in cutting order, each forwards or reversed, from ``at`` (the home by default), by
    :func:`_order_ends`."""
    if not strokes:
        return []
    order, backwards = _order_ends(np.array([s[0] for s in strokes]), np.array([s[-1] for s in strokes]), at)
    return [strokes[i][::-1] if back else strokes[i] for i, back in zip(order.tolist(), backwards.tolist())]


def _order_ends(first: np.ndarray, last: np.ndarray, at: Optional[np.ndarray] = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """The cutting order of strokes whose first and last positions are ``first`` and ``last`` (``(N, 2)``), from
    ``at`` (the home by default; step 3 of the module docstring), and which are cut backwards: the nearest stroke
    of a search of every stroke (``np.hypot`` distances, ties to the lowest index), found on a grid
    (:func:`cam.job._svg_kernels.nearest_order_kernel`)."""
    n = len(first)
    ends = np.empty((2 * n, 2))
    ends[:n] = first
    ends[n:] = last
    at = np.zeros(2) if at is None else np.asarray(at, float).reshape(2)
    found = nearest_order_kernel(ends, np.ascontiguousarray(at))
    return found[:n], found[n:].astype(bool)


def plan_svg(
    drawing: SvgDrawing,
    *,
    settings: MachineSettings = DEFAULT_SETTINGS,
    cut_depth_mm: float = DEFAULT_CUT_DEPTH_MM,
    travel_height_mm: float = DEFAULT_TRAVEL_HEIGHT_MM,
    scale: Optional[float] = None,
    fit_mm: Optional[tuple[float, float]] = None,
    offset_mm: Optional[tuple[float, float]] = None,
    layers: Optional[Union[str, Sequence[str]]] = None,
    pause_between_layers: bool = False,
    keep_duplicates: bool = False,
    home_steps: Optional[tuple[int, int, int]] = None,
) -> Job:
    """Plan the engraving of every stroke of an SVG drawing, in machine steps (see the module docstring).

    Args:
        drawing: the strokes (:func:`cam.formats.svg.load_svg`).
        settings: machine settings (mm per step, delays, travel).
        cut_depth_mm: cutting depth below the surface (> 0); travel_height_mm: travel height above it (>= 0).
        scale: mm of the job per mm of the drawing; fit_mm: or ``(width, height)`` mm the drawing is scaled to fit.
        offset_mm: machine position (mm from the home) of the page's origin; None = the top-left of what is
            cut at the home.
        layers: the layers to cut, in this order (names, or text of names separated by commas; see
            :func:`svg_layer_order`); None: every layer in file order.  What is cut (these layers) is what
            ``fit_mm`` fits and the default placement puts at the home.
        pause_between_layers: pause before each layer after the first (a pen or tool change).
        keep_duplicates: cut pieces that trace pieces already cut again (default: once).
        home_steps: the machine position of the job's home (its (0, 0, 0), where ``offset_mm`` is measured
            from): the drawing is checked against the travel in the machine frame from there; None: the job's own
            frame (placed when it runs, where it is checked): it must fit the travel's span.

    Returns:
        A :class:`~cam.job.model.Job`: CUT points at the cutting depth (``target`` marks them), TRAVEL at the
        safe height, RETRACT straight up; its ``pause_notes`` name the layer each pause is for.

    Raises:
        PlanError: bad options, a layer that is not in the drawing, nothing to cut; TravelError: the drawing
        does not fit the travel or, placed at ``home_steps``, leaves it (checked before the job is built, with
        its extent in mm, naming the axis and by how much); in its own frame, the job with its home is wider than
        the travel.
    """
    wrong = keyword_error({"cut_depth_mm": cut_depth_mm, "travel_height_mm": travel_height_mm})  # cam.options
    if wrong is not None:
        raise PlanError(wrong)
    chosen = svg_layer_order(drawing, layers)
    names = drawing.layers()
    part, part_layer = selected_layers(drawing, chosen)
    pts, bounds = _polylines_steps(part, settings, scale, fit_mm, offset_mm)
    if len(bounds) < 2:
        raise PlanError(f"{drawing.source}: nothing to cut (no visible stroke or outline)")
    warnings = list(drawing.warnings)
    owner = np.arange(len(bounds) - 1)
    if not keep_duplicates:
        pts, bounds, owner, n_dup, dup_steps = _drop_duplicates(pts, bounds, part_layer)
        if n_dup:
            warnings.append(f"{n_dup} duplicate segment(s) ({dup_steps * settings.mm_per_step_xy:.1f} mm) trace "
                            "what is already cut: cut once (--keep-duplicates cuts them again)")
    home = None if home_steps is None else np.asarray(home_steps, np.int64).reshape(3)
    _check_extent(drawing, pts, settings, home)  # before the samples are made: their count follows the size
    cells, cell_bounds = _cells_joined(pts, bounds)
    del pts
    depth_steps, safe_z_steps = _z_steps(cut_depth_mm, travel_height_mm, settings, None if home is None else int(home[2]))
    order, backwards, pause_first, notes = _cut_order(cells, cell_bounds, part_layer[owner], chosen,
                                                       names if pause_between_layers else None)
    xy, first = _gather(cells, cell_bounds, order, backwards)
    del cells
    gap = np.full(len(first), 2, np.int64)
    gap[1:] = np.abs(xy[first[1:]] - xy[first[1:] - 1]).max(axis=1)
    group = np.zeros(len(xy), bool)
    pause_group = np.zeros(len(xy), bool)
    group[first[gap > 1]] = True
    group[first[pause_first]] = True  # a pause lifts first, whatever the gap
    pause_group[first[pause_first]] = True
    pts, kind, pause = _rows(xy, group, pause_group, depth_steps, safe_z_steps)
    if home is None:
        check_span(pts, settings)  # its own frame: placed, and checked in the machine frame, when it runs
    else:
        check_travel(pts + home, settings)
    return Job(points_steps=pts, kind=kind, target=(kind == CUT) & (pts[:, 2] == depth_steps), pause=pause,
               settings=settings, warnings=warnings, pause_notes=notes, source=drawing.source)


def _cut_order(cells: np.ndarray, bounds: np.ndarray, run_layer: np.ndarray, chosen: list[int],
               pause_names: Optional[list[str]]) -> tuple[np.ndarray, np.ndarray, list[int], list[str]]:
    """The runs ``cells[bounds[i]:bounds[i + 1]]`` (run ``i`` in layer ``run_layer[i]``) in cutting order: the
    ``chosen`` layers one after the other, each in nearest-stroke order from where the one before ended (step 3):
    ``(runs, cut backwards, where the pauses come (index in the order), their notes)``; ``pause_names``: the layer
    names when the job pauses between layers (None: it does not)."""
    first, last = cells[bounds[:-1]], cells[bounds[1:] - 1]
    order: list[np.ndarray] = []
    backwards: list[np.ndarray] = []
    pause_first: list[int] = []
    notes: list[str] = []
    at = np.zeros(2)
    done = 0
    for layer in chosen:
        mine = np.flatnonzero(run_layer == layer)
        if not len(mine):
            continue  # every piece of it traced another layer's
        if pause_names is not None and done:
            pause_first.append(done)
            notes.append(f"layer '{pause_names[layer]}': change the pen")
        layer_order, back = _order_ends(first[mine], last[mine], at)
        order.append(mine[layer_order])
        backwards.append(back)
        done += len(mine)
        at = (first if back[-1] else last)[order[-1][-1]].astype(float)
    return np.concatenate(order), np.concatenate(backwards), pause_first, notes


def _gather(cells: np.ndarray, bounds: np.ndarray, order: np.ndarray, backwards: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """The positions of the runs ``cells[bounds[i]:bounds[i + 1]]`` in the ``order`` given, each reversed where
    ``backwards``, one after another, and where each run begins among them."""
    sizes = (bounds[1:] - bounds[:-1])[order]
    first = np.zeros(len(order), np.int64)
    np.cumsum(sizes[:-1], out=first[1:])
    within = np.arange(int(sizes.sum())) - np.repeat(first, sizes)
    back = np.repeat(backwards, sizes)
    index = np.where(back, np.repeat(bounds[order + 1] - 1, sizes) - within, np.repeat(bounds[order], sizes) + within)
    return cells[index], first


def selected_layers(drawing: SvgDrawing, chosen: list[int]) -> tuple[SvgDrawing, np.ndarray]:
    """The drawing with only the strokes of the ``chosen`` layers, in that order (file order within a layer),
    and the layer of each of its strokes."""
    layer_of = drawing.layer_of_stroke
    idx = np.concatenate([np.flatnonzero(layer_of == layer) for layer in chosen]) if chosen else np.zeros(0, int)
    idx = idx.astype(np.int64)
    if len(idx) == len(layer_of) and np.array_equal(idx, np.arange(len(idx))):
        return drawing, layer_of
    part = dataclasses.replace(drawing, strokes=[drawing.strokes[i] for i in idx],
                               closed=np.asarray(drawing.closed)[idx], stroke_layer=layer_of[idx])
    return part, layer_of[idx]


def _check_extent(drawing: SvgDrawing, pts: np.ndarray, settings: MachineSettings,
                  home_steps: Optional[np.ndarray]) -> None:
    """TravelError giving the drawing's size in mm when it is larger than the X/Y travel (``pts``: the points of
    the strokes' float polylines in steps, before they are sampled: a drawing metres wide is refused before
    millions of samples are made), or naming the axis and by how much when its extent from machine ``home_steps`` leaves
    the travel (None: a job planned in its own frame, its extent with the home (0, 0) against the travel's span).
    Where a job placed later goes is checked in the machine frame when it is placed (at the work zero, or from
    where the tool stands)."""
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    (x_lo, x_hi), (y_lo, y_hi), _ = settings.travel.bounds_steps()
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or hi[0] - lo[0] > x_hi - x_lo \
            or hi[1] - lo[1] > y_hi - y_lo:
        mm = settings.mm_per_step_xy
        raise TravelError(
            f"{drawing.source}: the drawing is {(hi[0] - lo[0]) * mm:.2f} x {(hi[1] - lo[1]) * mm:.2f} mm "
            f"(X {lo[0] * mm:.2f}..{hi[0] * mm:.2f}, Y {lo[1] * mm:.2f}..{hi[1] * mm:.2f} mm); the travel is "
            f"{(x_hi - x_lo) * mm:g} x {(y_hi - y_lo) * mm:g} mm (make it smaller with --fit or --scale)"
        )
    corners = np.floor(np.array([lo, hi]) + 0.5).astype(np.int64)
    if home_steps is None:
        span = TravelSpan(settings)
        found = span.over(corners)
        if found is not None:
            mm = settings.mm_per_step_xy
            raise TravelError(f"{drawing.source}: the drawing (X {lo[0] * mm:.2f}..{hi[0] * mm:.2f}, Y "
                              f"{lo[1] * mm:.2f}..{hi[1] * mm:.2f} mm from the job's home) lies outside the machine "
                              f"travel: {found[1]}")
        return
    corners = corners + np.asarray(home_steps, np.int64)[:2]
    found = outside_travel(corners, settings, farthest=True)
    if found is not None:
        raise TravelError(f"{drawing.source}: the drawing (X {lo[0] * settings.mm_per_step_xy:.2f}.."
                          f"{hi[0] * settings.mm_per_step_xy:.2f}, Y {lo[1] * settings.mm_per_step_xy:.2f}.."
                          f"{hi[1] * settings.mm_per_step_xy:.2f} mm from the job's home) lies outside the machine "
                          f"travel ({found[1]})")
