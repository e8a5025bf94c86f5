"""An HPGL job of any size: :func:`cam.job.hpgl.plan_hpgl`'s moves, read from the file a piece at a time.

:func:`~cam.job.hpgl.plan_hpgl` holds every point of the drawing and of the
job (about 60 bytes per point between the reader's arrays and the job's): a
200 MB file of 40 million points does not fit.  :class:`HpglJobStream` gives
the same moves as a sequence of small :class:`~cam.job.model.Job` pieces,
made from the file each time they are asked for (:meth:`HpglJobStream.pieces`):
the reader streams a chunk of the file, its pen-down points become the
piece's rows, and what joins one piece to the next (the last point, the pen
in the machine, the last row) is carried over.  Concatenated, the pieces
equal ``plan_hpgl`` of the whole drawing, row for row (tested).

A :class:`~cam.drive.chunks.ChunkedPlan` plans a stream a block of moves at a
time (:func:`cam.drive.chunks.plan_chunks`), so a job of any length is
planned, checked, run and pictured in bounded memory.  Nothing per point is
kept between passes: each pass reads the file again.
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Optional

import numpy as np

from ..errors import PlanError
from ..formats.hpgl import CHUNK_BYTES, PLOTTER_UNIT_MM, HpglScan, _points, _Unknown, scan_hpgl
from ..settings import DEFAULT_SETTINGS, MachineSettings
from .hpgl import DEFAULT_CUT_DEPTH_MM, DEFAULT_SAFE_HEIGHT_MM, _check_xy, _z_steps
from .model import CUT, RETRACT, TRAVEL, Job, check_travel, join_pieces

__all__ = ["HpglJobStream", "stream_hpgl", "STREAM_POINTS", "PIECE_POINTS"]

STREAM_POINTS = 1_000_000
"""HPGL files with more pen-down points than this are planned as a stream (:func:`cam.job.jobs.prepare_job`)."""
PIECE_POINTS = 1 << 17
"""Pen-down points read into one piece (at least; a piece ends with a chunk of the file)."""


@dataclass
class _Carry:
    """What joins one piece of the job to the next (see :meth:`HpglJobStream.pieces`)."""

    last_raw: Optional[np.ndarray] = None  # (2,) the last point read (before duplicates were dropped)
    last_kept: Optional[np.ndarray] = None  # (2,) the last point cut (None: none yet)
    last_pen: int = 0  # the last pen selected (0: none yet): the tool in the machine
    prev_tool: int = 0  # the tool of the previous stroke
    last_row: Optional[np.ndarray] = None  # (3,) the last row of the job (None: no row yet)
    n_strokes: int = 0


class _Hashes:
    """The stream's fingerprint: sha256 of the pieces' points, kinds and pauses (see :func:`plan_fingerprint`)."""

    def __init__(self) -> None:
        self.h = hashlib.sha256()

    def add(self, job: Job) -> None:
        for arr, dtype in ((job.points_steps, np.int64), (job.kind, np.uint8), (job.pause, np.bool_)):
            self.h.update(np.ascontiguousarray(np.asarray(arr, dtype)).tobytes())
            self.h.update(b"\0")


@dataclass
class HpglJobStream:
    """The moves of :func:`cam.job.hpgl.plan_hpgl` of an HPGL file, as pieces read from the file on demand.

    It stands for a :class:`~cam.job.model.Job` where a whole job does not fit: :meth:`pieces` gives
    consecutive Jobs (their points in steps from the job's home, as the whole job's), and the attributes
    every job has (``settings``, ``safe_z_steps``, ``source``, ...) are here.  ``len()`` is the number of
    moves, known after a first pass (:meth:`pieces` run to its end; :func:`stream_hpgl` makes one).

    Attributes:
        path: the HPGL file; scan: what a first streamed pass over it found (extent, counts, pens).
        settings, depth_steps, safe_z_steps: the machine settings, the cutting depth and the travel height
            (Z steps, +Z deeper: the travel height is <= 0).
        offset_mm: as :func:`~cam.job.hpgl.plan_hpgl`'s.
        piece_points: pen-down points read into a piece (at least).
        n_moves: moves of the job (-1 until a pass ended); fingerprint: the stream's plan fingerprint
            (after a pass).
    """

    path: Path
    scan: HpglScan
    settings: MachineSettings
    depth_steps: int
    safe_z_steps: int
    offset_mm: Optional[tuple[float, float]] = None
    piece_points: int = PIECE_POINTS
    chunk_bytes: int = CHUNK_BYTES
    n_moves: int = -1
    fingerprint: str = ""
    pause_notes: list[str] = field(default_factory=list)
    # a Job's other attributes, for the code that reads them off any job
    pixels: Any = None
    period_ns: Any = None
    periods: Any = None
    move_start: Any = None
    rest: Any = None
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

    def pieces(self) -> Iterator[Job]:
        """The job's moves as consecutive :class:`~cam.job.model.Job` pieces (each of at least
        ``piece_points`` pen-down points but the last), read from the file.

        Raises:
            ParseError: the file changed into something malformed since it was scanned;
            TravelError: a point lies outside the machine travel (``file:line:column``).
        """
        carry = _Carry()
        hashes = _Hashes()
        notes: list[str] = []
        n_moves = 0
        unknown, counts = _Unknown(), {}
        held: list[tuple[np.ndarray, ...]] = []
        have = 0
        for pb in _points(self.path, source=self.scan.source, progress=None, unknown=unknown, counts=counts,
                          chunk_bytes=self.chunk_bytes):
            if not len(pb.x):
                continue
            held.append((pb.x.copy(), pb.y.copy(), pb.line.copy(), pb.col.copy(), pb.start.copy(), pb.pen.copy()))
            have += len(pb.x)
            if have >= self.piece_points:
                piece = self._piece(held, carry, last=False)
                held, have = [], 0
                if piece is not None:
                    hashes.add(piece)
                    notes += piece.pause_notes or []
                    n_moves += len(piece)
                    yield piece
        piece = self._piece(held, carry, last=True)
        if piece is not None:
            hashes.add(piece)
            notes += piece.pause_notes or []
            n_moves += len(piece)
            yield piece
        self.n_moves, self.fingerprint, self.pause_notes = n_moves, hashes.h.hexdigest(), notes

    def _xy(self, x_pu: np.ndarray, y_pu: np.ndarray) -> np.ndarray:
        """``(N, 2)`` int64 machine steps of plotter points, as :func:`cam.job.hpgl.hpgl_steps` of the whole drawing."""
        s = self.settings
        if self.offset_mm is None:
            x0, _, _, y1 = self.scan.extent_pu  # type: ignore[misc]
            k = PLOTTER_UNIT_MM / s.mm_per_step_xy
            x_steps, y_steps = (x_pu - x0) * k, (y1 - y_pu) * k
        else:
            ox, oy = self.offset_mm
            x_steps = (ox + x_pu * PLOTTER_UNIT_MM) / s.mm_per_step_xy
            y_steps = (oy - y_pu * PLOTTER_UNIT_MM) / s.mm_per_step_xy
        return np.floor(np.column_stack([x_steps, y_steps]) + 0.5).astype(np.int64)

    def _piece(self, held: list[tuple[np.ndarray, ...]], carry: _Carry, *, last: bool) -> Optional[Job]:
        """The rows of the points in ``held`` (``plan_hpgl``'s ``_strokes`` and ``_rows`` with ``carry``);
        ``last``: the job's end (lift, back above the home, down to it) follows."""
        if held:
            x, y, line, col, start, pen = (np.concatenate([h[j] for h in held]) for j in range(6))
        else:
            x = y = np.zeros(0)
            line = col = pen = np.zeros(0, np.int32)
            start = np.zeros(0, bool)
        xy = self._xy(x, y)
        if len(xy):
            _check_xy(_PointsView(self.scan.source, np.column_stack([x, y]), line, col), xy, self.settings)
        depth, safe = self.depth_steps, self.safe_z_steps
        # _strokes: drop a point at the same step as the one before in its stroke
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
        tool = np.where(last_i >= 0, pens[np.maximum(last_i, 0)], carry.last_pen)
        prev_tool = np.concatenate([[carry.prev_tool], tool[:-1]]).astype(np.int64)
        change = (tool != 0) & (tool != prev_tool)
        if len(tool):
            carry.last_pen, carry.prev_tool = int(tool[-1]), int(tool[-1])
        starts = np.flatnonzero(start)
        kept_prev = np.vstack([carry.last_kept[None, :] if carry.last_kept is not None else np.zeros((1, 2), np.int64),
                               xy[:-1]]) if len(xy) else np.zeros((0, 2), np.int64)
        joined = np.zeros(len(starts), bool)
        if len(starts):
            gap = np.abs(xy[starts] - kept_prev[starts]).max(axis=1)
            joined = (gap <= 1) & ~change
            if carry.n_strokes == 0:
                joined[0] = False  # the first stroke of the job always plunges
        carry.n_strokes += len(starts)
        group = np.zeros(len(xy), bool)
        group[starts[~joined]] = True
        pause_group = np.zeros(len(xy), bool)
        pause_group[starts] = change
        # _rows
        rows = np.where(group, 3, 1)
        first = np.cumsum(rows) - rows
        total = int(rows.sum()) + (3 if last else 0)
        pts = np.empty((total, 3), np.int64)
        kind = np.full(total, CUT, np.uint8)
        pause = np.zeros(total, bool)
        gi = np.flatnonzero(group)
        r0 = first[gi]
        pts[r0, :2], pts[r0, 2], kind[r0] = kept_prev[gi], safe, RETRACT
        pts[r0 + 1, :2], pts[r0 + 1, 2], kind[r0 + 1] = xy[gi], safe, TRAVEL
        pts[r0 + 2, :2], pts[r0 + 2, 2] = xy[gi], depth
        pause[r0] = pause_group[gi]
        ci = np.flatnonzero(~group)
        pts[first[ci], :2], pts[first[ci], 2] = xy[ci], depth
        if len(xy):
            carry.last_kept = xy[-1].copy()
        if last:
            end = carry.last_kept if carry.last_kept is not None else np.zeros(2, np.int64)
            pts[-3] = (end[0], end[1], safe)
            kind[-3] = RETRACT
            pts[-2] = (0, 0, safe)
            pts[-1] = (0, 0, 0)
            kind[-2:] = TRAVEL
        # drop moves of length 0 (the job's row 0 stays); a lift, where the pauses are, never repeats the row
        # before it (that one is at the cutting depth), so a pause never moves to another piece
        same = np.zeros(total, bool)
        if total:
            same[1:] = np.all(pts[1:] == pts[:-1], axis=1)
            same[0] = carry.last_row is not None and bool(np.all(pts[0] == carry.last_row))
        if pause[same].any():
            idx = np.maximum.accumulate(np.where(~same, np.arange(total), 0))
            pause[idx[pause & same]] = True
        keep = ~same
        pts, kind, pause = pts[keep], kind[keep], pause[keep]
        if not len(pts):
            return None
        carry.last_row = pts[-1].copy()
        check_travel(pts, self.settings)
        notes = [f"tool change: pen {int(t)}" for t in tool[change]]
        return Job(points_steps=pts, kind=kind, target=(kind == CUT) & (pts[:, 2] == depth), pause=pause,
                   settings=self.settings, warnings=[], pause_notes=notes, source=self.scan.source,
                   safe_z_steps=self.safe_z_steps)

    def to_job(self) -> Job:
        """Every piece joined into one :class:`~cam.job.model.Job` (small files and tests: it holds every point)."""
        parts = list(self.pieces())
        return Job(points_steps=np.concatenate([p.points_steps for p in parts]),
                   kind=np.concatenate([p.kind for p in parts]), target=np.concatenate([p.target for p in parts]),
                   pause=np.concatenate([p.pause for p in parts]), settings=self.settings,
                   warnings=self.warnings, pause_notes=list(self.pause_notes), source=self.source,
                   safe_z_steps=self.safe_z_steps)


@dataclass
class _PointsView:
    """What :func:`cam.job.hpgl._check_xy` reads off a drawing, for one piece's points."""

    source: str
    points_pu: np.ndarray
    point_line: np.ndarray
    point_col: np.ndarray


def stream_hpgl(path: str | os.PathLike, *, settings: MachineSettings = DEFAULT_SETTINGS,
                depth_mm: float = DEFAULT_CUT_DEPTH_MM, safe_height_mm: float = DEFAULT_SAFE_HEIGHT_MM,
                offset_mm: Optional[tuple[float, float]] = None, scan: Optional[HpglScan] = None,
                piece_points: int = PIECE_POINTS, chunk_bytes: int = CHUNK_BYTES) -> HpglJobStream:
    """:func:`cam.job.hpgl.plan_hpgl` of an HPGL file as a :class:`HpglJobStream` (bounded memory).

    Args:
        path: the HPGL file (read once to scan it unless ``scan`` is given, then on every pass).
        settings, depth_mm, safe_height_mm, offset_mm: as :func:`~cam.job.hpgl.plan_hpgl`.
        scan: the file's :func:`~cam.formats.hpgl.scan_hpgl`, if made already.
        piece_points, chunk_bytes: pen-down points per piece (at least), bytes read at a time.

    Raises:
        PlanError: bad options, nothing drawn; ParseError: a malformed file; TravelError: a point outside
        the travel (found as the pieces are made).
    """
    if not (depth_mm > 0) or not (safe_height_mm >= 0):
        raise PlanError("the cutting depth must be > 0 mm and the safe height >= 0 mm")
    scan = scan if scan is not None else scan_hpgl(path, chunk_bytes=chunk_bytes)
    if scan.n_points == 0:
        raise PlanError(f"{scan.source}: nothing to cut (no pen-down moves)")
    depth_steps, safe_steps = _z_steps(depth_mm, safe_height_mm, settings)
    return HpglJobStream(Path(path), scan, settings, depth_steps, safe_steps, offset_mm, int(piece_points),
                         int(chunk_bytes))
