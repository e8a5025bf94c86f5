"""The HPGL planner: a plotter drawing to a job in machine steps, made a piece at a time (seed 004, section 3.6.2).

One planner for every size of drawing.  The pen-down points come as
:class:`~cam.formats.hpgl.PointBatch` es from a source: an HPGL file read a
chunk at a time on every pass (:func:`cam.formats.hpgl.point_batches`), or a
drawing held in memory, its arrays sliced
(:meth:`cam.formats.hpgl.HpglDrawing.point_batches`).  Each piece's points
become the piece's rows (:func:`_strokes`, :func:`_rows`), and what joins one
piece to the next (the last point, the pen in the machine, the last row) is
carried over (:class:`_Carry`), so the pieces joined are the same job however
the points were batched (tested).  :class:`HpglJobStream` is the job as pieces
(a :class:`~cam.job.model.JobLike`); :func:`cam.job.hpgl.plan_hpgl` is its
pieces joined (:meth:`HpglJobStream.joined`).

A file's job is made from the file each time it is asked for: nothing per
point is kept between passes, so a 200 MB file of 40 million points is
planned, checked, run and pictured in bounded memory
(:func:`cam.motion.chunks.plan_chunks` plans a stream a block of moves at a time).

Frames and units: see :mod:`cam.job.hpgl` (HPGL X right, Y up, plotter
units; machine x = X, y = -Y, nearest step; +Z deeper).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Union

import numpy as np

from ..errors import PlanError, TravelError
from ..options import OPTIONS, keyword_error
from ..formats.hpgl import (CHUNK_BYTES, PLOTTER_UNIT_MM, HpglDrawing, HpglScan, PointBatch, point_batches,
                            scan_hpgl)
from ..settings import DEFAULT_SETTINGS, MachineSettings
from .model import CUT, RETRACT, TRAVEL, Job, PixelFrame, TravelSpan, check_span, check_travel, join_pieces

__all__ = ["HpglJobStream", "stream_hpgl", "xy_steps", "xy_steps_exact", "hpgl_scale", "outside_travel",
           "z_span_check", "STREAM_POINTS", "PIECE_POINTS",
           "DEFAULT_CUT_DEPTH_MM", "DEFAULT_TRAVEL_HEIGHT_MM"]

DEFAULT_CUT_DEPTH_MM: float = OPTIONS["cut_depth_mm"].default_for({"strokes"})
"""A pen stroke's depth (0.5: declared once, with the option)."""
DEFAULT_TRAVEL_HEIGHT_MM: float = OPTIONS["travel_height_mm"].default_for({"placed"})
STREAM_POINTS = 1_000_000
"""HPGL files with more pen-down points than this are read from the file on every pass rather than held
(:func:`cam.kinds.jobs.prepare_job`); either way their job is this planner's pieces."""
PIECE_POINTS = 1 << 17
"""Pen-down points planned into one piece (at least; a piece of a file ends with a chunk of the file)."""


def xy_steps(x_pu: np.ndarray, y_pu: np.ndarray, extent_pu: Optional[tuple[float, float, float, float]],
             settings: MachineSettings, offset_mm: Optional[tuple[float, float]], scale: float = 1.0) -> np.ndarray:
    """``(N, 2)`` int64 machine ``(x, y)`` steps of ``(N,)`` plotter points (HPGL frame, Y up), ``scale`` mm cut
    per mm of the plot.

    ``offset_mm`` None: the drawing's top-left (``x_min``, ``y_max`` of ``extent_pu``, the whole drawing's
    ``(x_min, y_min, x_max, y_max)`` plotter units) at the home; else plotter (0, 0), scaled, at machine
    ``offset_mm``.  Nearest step: ``floor(v + 0.5)`` of the exact position in steps (:func:`xy_steps_exact`).
    """
    exact = xy_steps_exact(x_pu, y_pu, extent_pu, settings, offset_mm, scale)
    return np.floor(exact + 0.5).astype(np.int64)


def xy_steps_exact(x_pu: np.ndarray, y_pu: np.ndarray, extent_pu: Optional[tuple[float, float, float, float]],
                   settings: MachineSettings, offset_mm: Optional[tuple[float, float]],
                   scale: float = 1.0) -> np.ndarray:
    """``(N, 2)`` float64 machine ``(x, y)`` of ``(N,)`` plotter points in steps, before :func:`xy_steps` rounds
    them (the same placement; times ``settings.mm_per_step_xy``: the exact mm, G-code out)."""
    mm_per_pu = PLOTTER_UNIT_MM if scale == 1.0 else PLOTTER_UNIT_MM * scale
    if offset_mm is None:
        x0, _, _, y1 = extent_pu if extent_pu is not None else (0.0, 0.0, 0.0, 0.0)
        k = mm_per_pu / settings.mm_per_step_xy
        x_steps, y_steps = (x_pu - x0) * k, (y1 - y_pu) * k
    else:
        ox, oy = offset_mm
        x_steps = (ox + x_pu * mm_per_pu) / settings.mm_per_step_xy
        y_steps = (oy - y_pu * mm_per_pu) / settings.mm_per_step_xy
    return np.column_stack([x_steps, y_steps])


def hpgl_scale(scan: HpglScan, *, scale: Optional[float] = None, fit_mm: Optional[tuple[float, float]] = None) -> float:
    """mm cut per mm of the plot (its ``SC``/``IP`` scaling applied): :func:`scale_to_fit` of its drawn extent.

    Raises:
        PlanError: both given, a factor that is not > 0, nothing to fit.
    """
    return scale_to_fit(scan.size_mm, scan.source, scale=scale, fit_mm=fit_mm)


def scale_to_fit(size_mm: Callable[[], tuple[float, float]], source: str, *, scale: Optional[float] = None,
                 fit_mm: Optional[tuple[float, float]] = None) -> float:
    """``--scale``/``--fit`` of a vector job (HPGL, SVG): ``scale``, or the largest factor that fits the drawing's
    ``size_mm()`` ``(width, height)`` (asked only when fitting) in ``fit_mm`` keeping its proportions, or 1.

    Raises:
        PlanError: both given, a factor that is not > 0, nothing to fit (named by ``source``).
    """
    wrong = keyword_error({"scale": scale, "fit_mm": fit_mm})  # their ranges, and not both: cam.options
    if wrong is not None:
        raise PlanError(wrong)
    if scale is not None:
        return float(scale)
    if fit_mm is None:
        return 1.0
    fw, fh = (float(v) for v in fit_mm)
    w, h = size_mm()
    if w <= 0 and h <= 0:
        raise PlanError(f"{source}: nothing to fit (the drawing has no extent)")
    return min(fw / w if w > 0 else math.inf, fh / h if h > 0 else math.inf)


def _z_steps(cut_depth_mm: float, travel_height_mm: float, settings: MachineSettings,
             home_z_steps: Optional[int] = 0) -> tuple[int, int]:
    """(cutting depth, safe height) in Z steps (+Z deeper: the safe height is <= 0), checked against the Z travel
    with the job's surface at machine Z ``home_z_steps`` (None: a job planned in its own frame, placed when it
    runs: against the Z travel's span, :func:`z_span_check`)."""
    _, _, (z_lo, z_hi) = settings.travel.bounds_steps()
    depth_steps = int(round(cut_depth_mm / settings.mm_per_step_z))
    safe_z_steps = -int(round(travel_height_mm / settings.mm_per_step_z))
    if depth_steps < 1:
        raise PlanError(f"cutting depth {cut_depth_mm:g} mm is less than one Z step ({settings.mm_per_step_z:g} mm)")
    if home_z_steps is None:
        z_span_check(f"cutting depth {cut_depth_mm:g} mm and safe height {travel_height_mm:g} mm", depth_steps,
                     safe_z_steps, settings)
        return depth_steps, safe_z_steps
    z0 = int(home_z_steps)
    if depth_steps + z0 > z_hi or safe_z_steps + z0 < z_lo:
        surface = f" from a surface at machine Z {z0}" if z0 else ""
        raise TravelError(f"cutting depth {cut_depth_mm:g} mm and safe height {travel_height_mm:g} mm need Z "
                          f"{safe_z_steps + z0}..{depth_steps + z0} steps{surface}; the Z travel is {z_lo}..{z_hi} "
                          "steps")
    return depth_steps, safe_z_steps


def z_span_check(what: str, depth_steps: int, safe_z_steps: int, settings: MachineSettings) -> None:
    """TravelError when a job planned in its own frame (its surface at Z 0, placed when it runs) needs more Z than
    the travel has: from ``safe_z_steps`` (<= 0) to ``depth_steps`` (> 0); ``what`` names the two (issue #45 point 4).

    >>> z_span_check("depth 40 mm", 2548, -64, DEFAULT_SETTINGS) is None  # 2612 of the 2640 steps
    True
    """
    _, _, (z_lo, z_hi) = settings.travel.bounds_steps()
    lo, hi = min(0, int(safe_z_steps)), max(0, int(depth_steps))
    if hi - lo > z_hi - z_lo:
        mm = settings.mm_per_step_z
        raise TravelError(f"{what} need Z {lo}..{hi} steps ({(hi - lo) * mm:.3f} mm) from the surface, more than "
                          f"the Z travel holds wherever the work zero is: the Z travel is {z_lo}..{z_hi} steps "
                          f"({(z_hi - z_lo) * mm:.3f} mm)")


def outside_travel(points_steps: np.ndarray, settings: MachineSettings, *, farthest: bool = False
                   ) -> Optional[tuple[int, str]]:
    """The first of ``(N, 2)`` machine ``(x, y)`` (or ``(N, 3)``) steps outside the travel (``farthest``: the one
    farthest outside), and what a message says of it: ``(index, "machine Y -1.24 mm, 1.24 mm (43 steps) beyond
    the Y travel 0..289 mm")``, its first axis outside (``farthest``: the farthest); None when all are inside.
    The first, not the farthest, is the same point however the points are batched (:class:`HpglJobStream`).

    >>> pts = np.array([[5, 5], [5, -40], [5, -43]])
    >>> outside_travel(pts, DEFAULT_SETTINGS)
    (1, 'machine Y -1.16 mm, 1.16 mm (40 steps) beyond the Y travel 0..289 mm')
    >>> outside_travel(pts, DEFAULT_SETTINGS, farthest=True)[0]
    2
    """
    pts = np.asarray(points_steps, np.int64)
    k = pts.shape[1] if pts.ndim == 2 else 0
    bounds = np.array(settings.travel.bounds_steps()[:k], np.int64).reshape(-1, 2)
    if not len(pts) or not k or (np.all(pts.min(axis=0) >= bounds[:, 0]) and np.all(pts.max(axis=0) <= bounds[:, 1])):
        return None  # the extent is inside (the usual case: two passes)
    over = np.maximum(np.maximum(bounds[:, 0] - pts, pts - bounds[:, 1]), 0)
    if farthest:
        i, a = (int(v) for v in np.unravel_index(int(np.argmax(over)), over.shape))
    else:
        i = int(np.flatnonzero(np.any(over > 0, axis=1))[0])
        a = int(np.flatnonzero(over[i] > 0)[0])
    beyond = int(over[i, a])
    lo, hi = (int(v) for v in bounds[a])
    v = int(pts[i, a])
    mm = settings.mm_per_step_xy if a < 2 else settings.mm_per_step_z
    name = "XYZ"[a]
    return i, (f"machine {name} {v * mm:.2f} mm, {beyond * mm:.2f} mm ({beyond} steps) beyond the {name} travel "
               f"{lo * mm:g}..{hi * mm:g} mm")


def _check_xy(source: str, batch: PointBatch, xy: np.ndarray, settings: MachineSettings,
              span: Optional[TravelSpan] = None) -> None:
    """TravelError naming the first point (``file:line:column``) of ``batch`` whose ``(n, 2)`` machine steps
    ``xy`` leave the travel, the axis and by how much; with ``span`` (a job planned in its own frame: ``xy`` are
    steps from its home, the extent so far in ``span``): the first point that makes the job wider than the
    travel (:class:`~cam.job.model.TravelSpan`)."""
    if span is not None:
        found = span.over(xy)
        if found is not None:
            i, text = found
            raise TravelError(f"{source}:{int(batch.line[i])}:{int(batch.col[i])}: point X{batch.x[i]:g} "
                              f"Y{batch.y[i]:g} (plotter units) lies outside the machine travel: {text}")
        return
    found = outside_travel(xy, settings)
    if found is not None:
        i, beyond = found
        raise TravelError(
            f"{source}:{int(batch.line[i])}:{int(batch.col[i])}: point "
            f"X{batch.x[i]:g} Y{batch.y[i]:g} (plotter units) lies outside the machine travel ({beyond})"
        )


@dataclass
class _Carry:
    """What joins one piece of the job to the next (see :meth:`HpglJobStream.pieces`); machine steps."""

    last_raw: Optional[np.ndarray] = None  # (2,) the last point read (before duplicates were dropped)
    last_kept: Optional[np.ndarray] = None  # (2,) the last point cut (None: none yet)
    tool: int = 0  # the tool in the machine: the last pen selected (0: none yet)
    last_row: Optional[np.ndarray] = None  # (3,) the last row of the job (None: no row yet)
    n_strokes: int = 0
    xy_span: Optional[TravelSpan] = None  # a job planned in its own frame: its points' extent so far
    row_span: Optional[TravelSpan] = None  # and its rows'


def _strokes(xy: np.ndarray, start: np.ndarray, pen: np.ndarray,
             carry: _Carry) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """A piece's points to cut, and where the tool lifts or changes (``carry`` is read and moved on).

    Args:
        xy: ``(n, 2)`` int64 machine steps of the piece's points; start: ``(n,)`` bool, a stroke starts
            there; pen: ``(n,)`` the pen selected at each point (0: none: keep the tool that is in).

    Returns:
        ``xy`` ``(K, 2)`` without the points at the same step as the one before in their stroke;
        ``group`` ``(K,)`` bool, a lift and a plunge before the point (a stroke that does not begin within
        one step of where the last one ended, with the same tool; the job's first always plunges);
        ``pause_group`` ``(K,)`` bool, a tool change before the point; ``before`` ``(K, 2)`` int64 the point
        cut before each (the home before the job's first); the pause notes (``"tool change: pen N"``).
    """
    prev_raw = np.vstack([carry.last_raw[None, :] if carry.last_raw is not None else xy[:1] + 1, xy[:-1]]) \
        if len(xy) else xy
    dup = np.all(xy == prev_raw, axis=1) & ~start
    if len(xy):
        carry.last_raw = xy[-1].copy()
    xy, start = xy[~dup], start[~dup]
    pens = pen[~dup][start].astype(np.int64)
    # the tool of each stroke: pen 0 keeps the one in the machine
    have = np.where(pens != 0, np.arange(len(pens)), -1)
    last_i = np.maximum.accumulate(have) if len(pens) else have
    tool = np.where(last_i >= 0, pens[np.maximum(last_i, 0)], carry.tool)
    prev_tool = np.concatenate([[carry.tool], tool[:-1]]).astype(np.int64)
    change = (tool != 0) & (tool != prev_tool)
    if len(tool):
        carry.tool = int(tool[-1])
    starts = np.flatnonzero(start)
    before = np.vstack([carry.last_kept[None, :] if carry.last_kept is not None else np.zeros((1, 2), np.int64),
                        xy[:-1]]) if len(xy) else np.zeros((0, 2), np.int64)
    joined = np.zeros(len(starts), bool)
    if len(starts):
        gap = np.abs(xy[starts] - before[starts]).max(axis=1)
        joined = (gap <= 1) & ~change
        if carry.n_strokes == 0:
            joined[0] = False  # the first stroke of the job always plunges
    carry.n_strokes += len(starts)
    if len(xy):
        carry.last_kept = xy[-1].copy()
    group = np.zeros(len(xy), bool)
    group[starts[~joined]] = True
    pause_group = np.zeros(len(xy), bool)
    pause_group[starts] = change
    return xy, group, pause_group, before, [f"tool change: pen {int(t)}" for t in tool[change]]


def _rows(xy: np.ndarray, group: np.ndarray, pause_group: np.ndarray, depth_steps: int, safe_z_steps: int, *,
          before: Optional[np.ndarray] = None, finish: bool = True, end_xy: Optional[np.ndarray] = None,
          last_row: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``(R, 3)`` int64 points (machine steps), ``(R,)`` uint8 kinds and ``(R,)`` bool pauses of the
    ``(K, 2)`` points ``xy`` to cut (:func:`_strokes`; :func:`cam.job.svg.plan_svg` plans the whole job with it).

    Before each ``group`` point: lift where the tool is, travel above the point, plunge (a ``pause_group``
    point pauses at the lift).  ``before``: ``(K, 2)`` where the tool is before each point (default: the point
    before it, the home before the first).  ``finish``: the job ends here: lift at ``end_xy`` (default the
    last point), travel to above the home, down to it.  ``last_row``: ``(3,)`` the row before these (the
    previous piece's last; None: the job's row 0 is here, it stays).  Moves of length 0 are dropped.
    """
    if before is None:
        before = np.vstack([np.zeros((1, 2), np.int64), xy[:-1]]) if len(xy) else np.zeros((0, 2), np.int64)
    rows = np.where(group, 3, 1)
    first = np.cumsum(rows) - rows
    total = int(rows.sum()) + (3 if finish else 0)
    pts = np.empty((total, 3), np.int64)
    kind = np.full(total, CUT, np.uint8)
    pause = np.zeros(total, bool)
    gi = np.flatnonzero(group)
    r0 = first[gi]
    pts[r0, :2], pts[r0, 2], kind[r0] = before[gi], safe_z_steps, RETRACT  # lift where the tool is
    pts[r0 + 1, :2], pts[r0 + 1, 2], kind[r0 + 1] = xy[gi], safe_z_steps, TRAVEL  # travel above the stroke
    pts[r0 + 2, :2], pts[r0 + 2, 2] = xy[gi], depth_steps  # plunge
    pause[r0] = pause_group[gi]
    ci = np.flatnonzero(~group)
    pts[first[ci], :2], pts[first[ci], 2] = xy[ci], depth_steps
    if finish:
        end = end_xy if end_xy is not None else (xy[-1] if len(xy) else np.zeros(2, np.int64))
        pts[-3] = (end[0], end[1], safe_z_steps)
        kind[-3] = RETRACT
        pts[-2] = (0, 0, safe_z_steps)
        pts[-1] = (0, 0, 0)
        kind[-2:] = TRAVEL
    # drop moves of length 0 (the job's row 0 stays: a pause at the start needs a point); a pause moves to the
    # kept point.  A lift, where the pauses are, never repeats the row before it (that one is at the cutting
    # depth), so a pause never moves to another piece.
    same = np.zeros(total, bool)
    if total:
        same[1:] = np.all(pts[1:] == pts[:-1], axis=1)
        same[0] = last_row is not None and bool(np.all(pts[0] == last_row))
    if pause[same].any():
        idx = np.maximum.accumulate(np.where(~same, np.arange(total), 0))
        pause[idx[pause & same]] = True
    keep = ~same
    return pts[keep], kind[keep], pause[keep]


def _batch_of(held: list[PointBatch]) -> PointBatch:
    """One :class:`~cam.formats.hpgl.PointBatch` of consecutive batches (none: no points)."""
    if len(held) == 1:
        return held[0]
    if not held:
        return PointBatch(np.zeros(0), np.zeros(0), np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0, bool),
                          np.zeros(0, np.int32))
    return PointBatch(*(np.concatenate([getattr(b, name) for b in held])
                        for name in ("x", "y", "line", "col", "start", "pen")))


@dataclass
class HpglJobStream:
    """The HPGL job as consecutive :class:`~cam.job.model.Job` pieces (a :class:`~cam.job.model.JobLike`):
    :func:`cam.job.hpgl.plan_hpgl` is :meth:`joined`.

    :meth:`pieces` plans them anew on each pass from the points of ``src``: an HPGL file (read a chunk at
    a time: nothing per point is held) or a drawing held in memory.  Their points are in steps from the
    job's home (the frame of :class:`~cam.job.model.Job`); the attributes of the whole job are here.
    ``len()`` is the number of moves, known after a first pass (:meth:`pieces` run to its end).

    Attributes:
        src: the HPGL file, or the drawing; scan: what a first pass over it found (extent, counts, pens).
        settings, depth_steps, safe_z_steps: the machine settings, the cutting depth and the travel height
            (Z steps, +Z deeper: the travel height is <= 0).
        offset_mm: as :func:`~cam.job.hpgl.plan_hpgl`'s; scale: mm cut per mm of the plot (:func:`hpgl_scale`).
        home_steps: the machine position of the job's home (its points are steps from it): the travel is checked
            in the machine frame from there (a file placed by its own zero); None: the job's own frame, a job
            placed when it runs (at the work zero, checked there): checked to fit the travel's span
            (:class:`~cam.job.model.TravelSpan`, issue #45 point 4).
        piece_points: pen-down points planned into a piece (at least); chunk_bytes: bytes of a file read at once.
        n_moves: moves of the job (-1 until a pass ended); pause_notes: its pauses' notes (after a pass).
        pixels, tool: None (no drawing frame; the point tool).
    """

    src: Union[Path, HpglDrawing]
    scan: HpglScan
    settings: MachineSettings
    depth_steps: int
    safe_z_steps: int
    offset_mm: Optional[tuple[float, float]] = None
    scale: float = 1.0
    piece_points: int = PIECE_POINTS
    chunk_bytes: int = CHUNK_BYTES
    home_steps: Optional[tuple[int, int, int]] = None
    n_moves: int = -1
    pause_notes: list[str] = field(default_factory=list)
    pixels: Optional[PixelFrame] = None
    tool: Any = None

    @property
    def source(self) -> str:
        return self.scan.source

    @property
    def warnings(self) -> list[str]:
        return list(self.scan.warnings)

    def __len__(self) -> int:
        if self.n_moves < 0:
            for _ in self.pieces():
                pass
        return self.n_moves

    def joined(self) -> Job:
        """Every move in one :class:`~cam.job.model.Job` (:func:`~cam.job.model.join_pieces` of :meth:`pieces`)."""
        return join_pieces(self.pieces(), self)

    def _batches(self) -> Iterator[PointBatch]:
        """The pen-down points, in order: the file's a chunk at a time, or the drawing's sliced."""
        if isinstance(self.src, HpglDrawing):
            return self.src.point_batches(self.piece_points)
        return point_batches(self.src, source=self.scan.source, chunk_bytes=self.chunk_bytes)

    def pieces(self) -> Iterator[Job]:
        """The job's moves as consecutive :class:`~cam.job.model.Job` pieces (each of at least
        ``piece_points`` pen-down points but the last).

        Raises:
            ParseError: the file changed into something malformed since it was scanned;
            TravelError: a point lies outside the machine travel (``file:line:column``), or (a job planned in its
            own frame) makes the job wider than the travel.
        """
        carry = _Carry()
        if self.home_steps is None:
            carry.xy_span, carry.row_span = TravelSpan(self.settings), TravelSpan(self.settings)
        notes: list[str] = []
        n_moves = have = 0
        held: list[PointBatch] = []
        batches = self._batches()
        while True:
            batch = next(batches, None)
            if batch is not None:
                held.append(batch)
                have += len(batch.x)
                if have < max(1, self.piece_points):
                    continue
            piece = self._piece(_batch_of(held), carry, last=batch is None)
            held, have = [], 0
            if piece is not None:
                notes += piece.pause_notes or []
                n_moves += len(piece)
                yield piece
            if batch is None:
                break
        self.n_moves, self.pause_notes = n_moves, notes

    def _piece(self, batch: PointBatch, carry: _Carry, *, last: bool) -> Optional[Job]:
        """The rows of the points of ``batch`` (None: none are left); ``last``: the job's end follows."""
        xy = xy_steps(batch.x, batch.y, self.scan.extent_pu, self.settings, self.offset_mm, self.scale)
        home = None if self.home_steps is None else np.asarray(self.home_steps, np.int64).reshape(3)
        if home is None:
            _check_xy(self.source, batch, xy, self.settings, carry.xy_span)
        else:
            _check_xy(self.source, batch, xy + home[:2], self.settings)
        xy, group, pause_group, before, notes = _strokes(xy, batch.start, batch.pen, carry)
        pts, kind, pause = _rows(xy, group, pause_group, self.depth_steps, self.safe_z_steps, before=before,
                                 finish=last, end_xy=carry.last_kept, last_row=carry.last_row)
        if not len(pts):
            return None
        carry.last_row = pts[-1].copy()
        if home is None:
            check_span(pts, self.settings, span=carry.row_span)
        else:
            check_travel(pts + home, self.settings)
        return Job(points_steps=pts, kind=kind, target=(kind == CUT) & (pts[:, 2] == self.depth_steps), pause=pause,
                   settings=self.settings, warnings=[], pause_notes=notes, source=self.source,
                   safe_z_steps=self.safe_z_steps)


def stream_hpgl(src: Union[str, os.PathLike, HpglDrawing], *, settings: MachineSettings = DEFAULT_SETTINGS,
                cut_depth_mm: float = DEFAULT_CUT_DEPTH_MM, travel_height_mm: float = DEFAULT_TRAVEL_HEIGHT_MM,
                offset_mm: Optional[tuple[float, float]] = None, scan: Optional[HpglScan] = None,
                piece_points: int = PIECE_POINTS, chunk_bytes: int = CHUNK_BYTES, scale: Optional[float] = None,
                fit_mm: Optional[tuple[float, float]] = None,
                home_steps: Optional[tuple[int, int, int]] = None) -> HpglJobStream:
    """The HPGL job of a file or a drawing as a :class:`HpglJobStream` (a file's: bounded memory).

    Args:
        src: the HPGL file (read once to scan it unless ``scan`` is given, then on every pass), or a drawing
            held in memory (:func:`cam.formats.hpgl.load_hpgl`).
        settings, cut_depth_mm, travel_height_mm, offset_mm: as :func:`~cam.job.hpgl.plan_hpgl`.
        scan: the file's :func:`~cam.formats.hpgl.scan_hpgl`, if made already.
        piece_points, chunk_bytes: pen-down points per piece (at least), bytes read at a time.
        scale, fit_mm: mm cut per mm of the plot, or the ``(width, height)`` mm to fit it in (:func:`hpgl_scale`).
        home_steps: the machine position of the job's home (where ``offset_mm`` is measured from): every point is
            checked against the travel in the machine frame from there (:class:`HpglJobStream`); None: the job's
            own frame (placed when it runs): checked to fit the travel's span.

    Raises:
        PlanError: bad options (both scale and fit_mm), nothing drawn; ParseError: a malformed file; TravelError: the depths outside
        the Z travel, a point outside the travel (found as the pieces are made).
    """
    wrong = keyword_error({"cut_depth_mm": cut_depth_mm, "travel_height_mm": travel_height_mm})  # cam.options
    if wrong is not None:
        raise PlanError(wrong)
    if isinstance(src, HpglDrawing):
        points: Union[Path, HpglDrawing] = src
        scan = src.summary()
    else:
        points = Path(src)
        scan = scan if scan is not None else scan_hpgl(src, chunk_bytes=chunk_bytes)
    if scan.n_points == 0:
        raise PlanError(f"{scan.source}: nothing to cut (no pen-down moves)")
    factor = hpgl_scale(scan, scale=scale, fit_mm=fit_mm)
    home = None if home_steps is None else tuple(int(v) for v in home_steps)
    depth_steps, safe_z_steps = _z_steps(cut_depth_mm, travel_height_mm, settings, None if home is None else home[2])
    return HpglJobStream(points, scan, settings, depth_steps, safe_z_steps, offset_mm, factor,
                         max(1, int(piece_points)), int(chunk_bytes), home)  # type: ignore[arg-type]
