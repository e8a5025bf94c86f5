"""A drawing job of any size: :func:`cam.job.drawing.plan`'s moves, made a piece at a time.

:func:`~cam.job.drawing.plan` holds every target and every move of the job
at once (about 100 bytes per pixel cut between its arrays): a 4096^2 relief
of 13 million pixels takes over 1 GB.  :class:`DrawingJobStream` gives the
same moves as a sequence of small :class:`~cam.job.model.Job` pieces, made
from the digitized matrix each time they are asked for
(:meth:`DrawingJobStream.pieces`).  What the planner needs of the whole job
is a few maps of the drawing (the deepest depth asked at each pixel, for the
routes through the material; Pause At points; a tool's drop-cutter depths),
made once; every move depends only on its two targets, so a piece goes on
from the last target of the piece before.  Concatenated, the pieces equal
``plan`` of the same drawing and options, row for row (tested).

A :class:`~cam.drive.chunks.ChunkedPlan` plans a stream a block of moves at a
time, so a large relief is planned, checked, run and pictured in bounded
memory (:func:`cam.job.jobs.prepare_job` streams drawings of over
:data:`STREAM_TARGETS` cut points).  Roughing (``stepdown_px``) is planned in
memory by :func:`~cam.job.drawing.plan`, and a real tool's finer finishing pass
(:mod:`cam.job.subpixel`, whose maps are 16 times the drawing's) is left out, with a warning: the stream
equals ``plan(..., subpixel=False)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterator, Optional, Sequence

import numpy as np

from ..digitize.digitized import Digitized
from ..digitize.profile import ProfileLike
from ..errors import PlanError
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..tool import Tool, parse_tool
from .subpixel import finer_grid
from .drawing import _assemble, _drop_maps, _fits_travel, _guard_diagonals, _object_depths, _pass_order, _pause_map
from .hpgl_stream import _Hashes
from .model import RETRACT, Job, PixelFrame, check_travel, join_pieces

__all__ = ["DrawingJobStream", "stream_drawing", "STREAM_TARGETS", "PIECE_TARGETS"]

STREAM_TARGETS = 4_000_000
"""Drawings with more cut points than this (targets of every pass) are planned as a stream."""
PIECE_TARGETS = 1 << 16
"""Cut points planned into one piece (at most)."""


@dataclass
class DrawingJobStream:
    """The moves of :func:`cam.job.drawing.plan` of a digitized drawing, as pieces made on demand.

    It stands for a :class:`~cam.job.model.Job` where a whole job does not fit: :meth:`pieces` gives
    consecutive Jobs (their points in steps from the job's home, as the whole job's), and the attributes
    a drawing job has (``settings``, ``safe_z_steps``, ``pixels``, ``tool``, ``warnings``, ...) are here.
    ``len()``, :attr:`n_targets` and :attr:`n_retracts` are known after a first pass (:meth:`pieces` run to
    its end; they make one if none was made).

    Attributes:
        digitized: the traced drawing; order: ``(object index, depth in Z pixels)`` of each block of
            targets in cutting order (:func:`cam.job.drawing._pass_order`).
        asked: ``(H + 2, W + 2)`` deepest depth asked at each pixel, Z pixels below the surface (drawing frame,
            a tool's drop-cutter rule applied); pause_px: ``(H + 2, W + 2)`` bool, the Pause At points.
        allowed, corners: a tool's drop-cutter depth at each pixel ``(H, W)`` and pixel corner
            ``(H + 1, W + 1)`` (None for the point tool).
        pixels: where the drawing's pixels lie; route: whether gaps may be bridged through the material.
        piece_targets: cut points per piece (at most).
    """

    digitized: Digitized
    order: list[tuple[int, int]]
    asked: np.ndarray
    pause_px: np.ndarray
    allowed: Optional[np.ndarray]
    corners: Optional[np.ndarray]
    settings: MachineSettings
    pixels: PixelFrame
    route: bool
    tool: Optional[Tool] = None
    warnings: list[str] = field(default_factory=list)
    piece_targets: int = PIECE_TARGETS
    n_moves: int = -1
    fingerprint: str = ""
    counts: dict[str, int] = field(default_factory=dict)
    # a Job's other attributes, for the code that reads them off any job
    source: str = ""
    pause_notes: Any = None
    period_ns: Any = None
    periods: Any = None
    move_start: Any = None
    rest: Any = None

    @property
    def safe_z_steps(self) -> int:
        return min(0, self.pixels.origin_px[2]) * self.settings.steps_per_px_z

    @property
    def width_px(self) -> int:
        return self.pixels.width_px

    @property
    def height_px(self) -> int:
        return self.pixels.height_px

    @property
    def origin_px(self) -> tuple[int, int, int]:
        return self.pixels.origin_px

    def __len__(self) -> int:
        if self.n_moves < 0:
            for _ in self.pieces():
                pass
        return self.n_moves

    @property
    def n_targets(self) -> int:
        """Points of the job that are cut targets (as :attr:`cam.job.model.Job.n_targets`)."""
        len(self)
        return self.counts["targets"]

    @property
    def n_retracts(self) -> int:
        """Lifts of the job (as :attr:`cam.job.model.Job.n_retracts`)."""
        len(self)
        return self.counts["retracts"]

    @property
    def deepest_px(self) -> int:
        """The deepest depth asked anywhere, Z pixels below the surface."""
        return int(self.asked.max())

    def asked_depth_px(self) -> np.ndarray:
        """``(height_px, width_px)`` int64: deepest z in Z pixels asked at each drawing pixel (0: none)."""
        return self.asked[: self.height_px, : self.width_px].astype(np.int64)

    def _targets(self) -> Iterator[tuple[np.ndarray, bool]]:
        """``((M, 3) int64 targets, last)``: the job's cut targets (x, y, depth below the surface; drawing frame,
        before a tool's limit) in cutting order, at most :attr:`piece_targets` at a time."""
        held: list[np.ndarray] = []
        n = 0
        pending: Optional[np.ndarray] = None
        for i, d in self.order:
            obj = self.digitized.objects[i]
            for s in range(0, len(obj), self.piece_targets):
                part = obj[s : s + self.piece_targets]
                block = np.empty((len(part), 3), np.int64)
                block[:, :2] = part
                block[:, 2] = d
                held.append(block)
                n += len(block)
                while n >= self.piece_targets:
                    joined = np.concatenate(held)
                    if pending is not None:
                        yield pending, False
                    pending = joined[: self.piece_targets]
                    rest = joined[self.piece_targets:]
                    held, n = ([rest] if len(rest) else []), len(rest)
        if held:
            if pending is not None:
                yield pending, False
            pending = np.concatenate(held)
        if pending is not None:
            yield pending, True

    def joined(self) -> Job:
        """Every move in one :class:`~cam.job.model.Job` (:func:`~cam.job.model.join_pieces` of :meth:`pieces`)."""
        return join_pieces(self.pieces(), self)

    def pieces(self) -> Iterator[Job]:
        """The job's moves as consecutive :class:`~cam.job.model.Job` pieces.

        Raises:
            TravelError: a point lies outside the machine travel (found as the pieces are made).
        """
        ox, oy, oz = self.pixels.origin_px
        s = self.settings
        safe = min(0, oz)
        hashes = _Hashes()
        n_moves = n_targets = n_retracts = 0
        after: Optional[np.ndarray] = None  # the last target planned (drawing frame, Start At Z included)
        last_pt: Optional[np.ndarray] = None  # the last point of the job so far (drawing frame)
        for targets, last in self._targets():
            if self.allowed is not None:  # the drop-cutter rule: no deeper than the tool may go at the pixel
                targets[:, 2] = np.minimum(targets[:, 2], self.allowed[targets[:, 1], targets[:, 0]])
                targets = targets[targets[:, 2] > 0]
                if not len(targets) and not last:
                    continue
            targets[:, 2] += oz
            pts, kind, tgt, pause = _assemble(targets, self.pause_px, self.asked, s, oz, safe, oz, home=(-ox, -oy),
                                              route=self.route, after=after, last=last)
            if self.corners is not None:
                if last_pt is not None:  # a diagonal from the last point of the piece before is guarded too
                    pts, kind, tgt, pause = (np.vstack([last_pt, pts]), np.concatenate([kind[:1] * 0, kind]),
                                             np.concatenate([[False], tgt]), np.concatenate([[False], pause]))
                pts, kind, tgt, pause = _guard_diagonals(pts, kind, tgt, pause, self.corners, oz)
                if last_pt is not None:
                    pts, kind, tgt, pause = pts[1:], kind[1:], tgt[1:], pause[1:]
            if len(targets):
                after = targets[-1].copy()
            if len(pts):
                last_pt = pts[-1].copy()
            pts[:, :2] += np.array([ox, oy], np.int64)
            points_steps = self.pixels.to_steps(pts)
            check_travel(points_steps, s, self.pixels)
            piece = Job(points_steps=points_steps, kind=kind, target=tgt, pause=pause, settings=s, warnings=[],
                        safe_z_steps=self.safe_z_steps, pixels=self.pixels, tool=self.tool)
            hashes.add(piece)
            n_moves += len(pts)
            n_targets += int(np.count_nonzero(tgt))
            n_retracts += int(np.count_nonzero(kind == RETRACT))
            yield piece
        self.n_moves, self.fingerprint = n_moves, hashes.h.hexdigest()
        self.counts = {"targets": n_targets, "retracts": n_retracts}

    def to_job(self) -> Job:
        """Every piece joined into one :class:`~cam.job.model.Job` (tests: it holds every point)."""
        parts = list(self.pieces())
        return Job(points_steps=np.concatenate([p.points_steps for p in parts]),
                   kind=np.concatenate([p.kind for p in parts]), target=np.concatenate([p.target for p in parts]),
                   pause=np.concatenate([p.pause for p in parts]), settings=self.settings,
                   warnings=list(self.warnings), safe_z_steps=self.safe_z_steps, pixels=self.pixels,
                   tool=self.tool, pause_notes=self.pause_notes)


def stream_drawing(
    digitized: Digitized,
    *,
    depth: int | Sequence[int] | None = None,
    settings: MachineSettings = DEFAULT_SETTINGS,
    passes: int = 1,
    start_at: tuple[int, int, int] = (0, 0, 0),
    pause_at: Sequence[tuple[int, int]] = (),
    profile: ProfileLike | None = None,
    tool: Tool | str | None = None,
    piece_targets: Optional[int] = None,
) -> DrawingJobStream:
    """:func:`cam.job.drawing.plan` of a digitized drawing as a :class:`DrawingJobStream` (bounded memory).

    Args:
        digitized, depth, settings, passes, start_at, pause_at, profile, tool: as :func:`~cam.job.drawing.plan`
            (no roughing).
        piece_targets: cut points per piece (at most; None: :data:`PIECE_TARGETS`).

    Raises:
        PlanError: bad options, nothing to cut; TravelError: the job leaves the travel (its extent is checked
        here, before a piece is made).
    """
    depth_px, warnings = _object_depths(digitized, depth, profile, passes)
    order = _pass_order(depth_px, passes)
    if not order:
        raise PlanError("nothing to cut: every depth is 0")
    h, w = digitized.height_px, digitized.width_px
    deepest = max(d for _, d in order)
    asked = np.zeros((h + 2, w + 2), np.int32 if deepest < 2**31 else np.int64)
    for i, d in order:  # every point of a block has the same depth: a plain assignment keeps the deepest
        ys, xs = digitized.objects[i][:, 1], digitized.objects[i][:, 0]
        asked[ys, xs] = np.maximum(asked[ys, xs], d)
    cutter = parse_tool(tool, "tool")
    allowed = corners = None
    if digitized.mode == "3d" and not cutter.is_point:
        allowed, corners, note = _drop_maps(asked[:h, :w].astype(np.int64), cutter, settings)
        warnings += note
        if finer_grid(settings) > 1:
            warnings.append("the finer finishing pass between pixel centres (cam.job.subpixel) is left out of a "
                            "drawing this large (planned a piece at a time): the tool leaves a little more")
        asked[:h, :w] = np.maximum(np.minimum(asked[:h, :w], allowed), 0)
        if not asked.any():
            raise PlanError(f"nothing to cut: the {cutter.describe()} tool does not fit into any part of the relief")
    if len(pause_at):
        pause_px, notes = _pause_map(digitized, pause_at, asked.shape)
        warnings += notes
    else:  # read only: no pause anywhere, in no memory
        pause_px = np.broadcast_to(np.zeros(1, bool), asked.shape)
    ox, oy, oz = (int(v) for v in start_at)
    cut = asked > 0
    xs, ys = np.flatnonzero(cut.any(axis=0)), np.flatnonzero(cut.any(axis=1))
    shallowest = int(np.min(asked, where=cut, initial=np.iinfo(asked.dtype).max))
    extent = np.array([[xs[0], ys[0], shallowest + oz], [xs[-1], ys[-1], int(asked.max()) + oz]], np.int64)
    del cut
    frame = PixelFrame(w, h, (ox, oy, oz), settings.steps_per_px_xy, settings.steps_per_px_z)
    fits = _fits_travel(extent, (ox, oy), min(0, oz), settings)
    job = DrawingJobStream(digitized, order, asked, pause_px, allowed, corners, settings, frame, fits,
                           tool=None if cutter.is_point else cutter, warnings=warnings,
                           piece_targets=max(1, int(PIECE_TARGETS if piece_targets is None else piece_targets)))
    if not fits:  # assembled without bridges up to its first point outside the travel, which is named
        for _ in job.pieces():
            pass
        raise AssertionError("a job whose extent leaves the travel passed the travel check")
    return job
