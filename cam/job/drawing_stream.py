"""The drawing planner: a digitized matrix to a job made a piece at a time, whatever its size.

:func:`stream_drawing` is the one drawing planner; :func:`cam.plan` (:func:`plan`, here) is its
pieces joined (:meth:`DrawingJobStream.joined`).  The rules of the moves are those of
:mod:`cam.job.drawing` (:func:`~cam.job.drawing._assemble`, :func:`~cam.job.drawing._guard_diagonals`).

A :class:`DrawingJobStream` gives the job's moves as a sequence of small :class:`~cam.job.model.Job`
pieces, made each time they are asked for (:meth:`DrawingJobStream.pieces`).  What the planner needs of the
whole job is made once, when it is planned: a few maps of the drawing (the deepest depth asked at each
pixel, for the routes through the material; Pause At points; a tool's drop-cutter depths), the roughing
levels' targets and the finer pass's positions.  Every move depends only on its two targets, so a piece
goes on from the last target of the piece before: the pieces, joined, are the same job row for row
whatever their size (tested from one target a piece up).

The job has up to three parts, each starting where the one before ended:

1. roughing (``stepdown_mm``, 3D): levels cut by the roughing tool from the home back to the home, a
   tool-change pause there when the finishing tool is another;
2. the pixel-centre pass: the drawing's targets of every pass, each no deeper than the tool's drop-cutter
   rule allows;
3. a real tool's finer finishing pass between pixel centres (:mod:`cam.job.subpixel`), on its finer grid,
   to the home.  Its positions are bounded (:data:`cam.job.subpixel.MAX_CELLS`, a coarser grid or none with
   a warning beyond), alike for every job.

Memory: the maps (a few bytes per pixel, the finer pass's per finer position) and the roughing and finer
targets are held; nothing per move of the pixel-centre pass.  A :class:`~cam.motion.chunks.ChunkedPlan`
plans the stream a block of moves at a time (:func:`cam.kinds.jobs.prepare_job` keeps a drawing of over
:data:`STREAM_TARGETS` cut points as a stream, a smaller one joined: the same moves).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Generator, Iterator, Optional, Sequence

import numpy as np

from ..digitize.digitized import Digitized
from ..digitize.profile import ProfileLike
from ..errors import PlanError
from ..options import keyword_error
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..tool import Tool, parse_tool, reach_depth_px
from .drawing import (_assemble, _drop_maps, _fits_travel, _guard_diagonals, _object_depths, _pass_order,
                      _pause_map, _roughing_targets)
from .model import RETRACT, Job, PixelFrame, TravelSpan, check_span, join_pieces
from .subpixel import finer_grids, rest_positions

__all__ = ["plan", "DrawingJobStream", "stream_drawing", "depth_px_of", "stepdown_px_of", "STREAM_TARGETS",
           "PIECE_TARGETS"]

STREAM_TARGETS = 2_000_000
"""Drawings with more cut points than this (targets of every pass) are kept as a stream by
:func:`cam.kinds.jobs.prepare_job` (smaller ones are joined into one Job: the same moves).  A 2048^2 relief (3.3M
points) joined took a `cam drill` process to 515-553 MB; as a stream 371 MB (and 2 s longer: every pass over the
job plans its pieces again)."""
PIECE_TARGETS = 1 << 16
"""Cut points planned into one piece (at most)."""


@dataclass(frozen=True)
class _Part:
    """A part of a drawing job (roughing, the pixel-centre pass, the finer pass), planned a piece at a time.

    Attributes:
        targets: ``(M, 3)`` int64 ``(x, y, depth)`` in cutting order: positions of the part's grid (drawing
            frame, ``k`` per pixel), depth in Z pixels below the surface (None: the pixel-centre pass, whose
            targets are made from the drawing, :meth:`DrawingJobStream._targets`).
        asked: ``(h + 2, w + 2)`` deepest depth the routes may run at, at each position (the grid's h x w).
        corners: ``(h + 1, w + 1)`` drop-cutter depth at the midpoints of diagonal moves (None: a point tool).
        k: positions per pixel of the grid (1: pixels).
        change_note: a tool change at the part's last point (at the home), or None.
        finer: the finer pass: goes on from the last target before, lifts partly (see
            :func:`cam.job.drawing._gap_block`), its points are not targets.
        reached: ``(H, W)`` deepest target at each drawing pixel (roughing; None: the finer pass).
    """

    targets: Optional[np.ndarray]
    asked: np.ndarray
    corners: Optional[np.ndarray]
    k: int = 1
    change_note: Optional[str] = None
    finer: bool = False
    reached: Optional[np.ndarray] = None


@dataclass
class DrawingJobStream:
    """A drawing job (:func:`stream_drawing`) as pieces made on demand: a :class:`~cam.job.model.JobLike`.

    :meth:`pieces` gives consecutive Jobs (their points in steps from the job's home), :meth:`joined` the
    whole :class:`~cam.job.model.Job`; the attributes a drawing job has (``settings``, ``safe_z_steps``,
    ``pixels``, ``tool``, ``warnings``, ...) are here.  ``len()``, :attr:`n_targets`, :attr:`n_retracts` and
    :attr:`pause_notes` are known after a first pass (:meth:`pieces` run to its end; they make one if none was).

    Attributes:
        digitized: the traced drawing; order: ``(object index, depth in Z pixels)`` of each block of
            targets in cutting order (:func:`cam.job.drawing._pass_order`).
        asked: ``(H + 2, W + 2)`` deepest depth asked at each pixel, Z pixels below the surface (drawing frame,
            a tool's drop-cutter rule applied); pause_px: ``(H + 2, W + 2)`` bool, the Pause At points.
        allowed, corners: a tool's drop-cutter depth at each pixel ``(H, W)`` and pixel corner
            ``(H + 1, W + 1)`` (None for the point tool).
        pixels: where the drawing's pixels lie; route: whether gaps may be bridged through the material.
        roughing, finer: the roughing part before the pixel-centre pass and the finer pass after it (None: none).
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
    roughing: Optional[_Part] = None
    finer: Optional[_Part] = None
    piece_targets: int = PIECE_TARGETS
    source: str = ""
    counts: dict[str, int] = field(default_factory=dict)

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

    def _count(self, key: str) -> int:
        if not self.counts:
            for _ in self.pieces():
                pass
        return self.counts[key]

    def __len__(self) -> int:
        return self._count("moves")

    @property
    def n_targets(self) -> int:
        """Points of the job that are cut targets (as :attr:`cam.job.model.Job.n_targets`)."""
        return self._count("targets")

    @property
    def n_retracts(self) -> int:
        """Lifts of the job (as :attr:`cam.job.model.Job.n_retracts`)."""
        return self._count("retracts")

    @property
    def pause_notes(self) -> Optional[list[str]]:
        """What each pause is for, as :attr:`cam.job.model.Job.pause_notes` (None: every pause is a Pause At)."""
        if self.roughing is None or self.roughing.change_note is None:
            return None
        return [self.roughing.change_note] + ["Pause At"] * (self._count("pauses") - 1)

    def asked_depth_px(self) -> np.ndarray:
        """``(height_px, width_px)`` int64: deepest target depth in Z pixels at each drawing pixel (0: none)."""
        out = self.asked[: self.height_px, : self.width_px].astype(np.int64)
        if self.roughing is not None:
            np.maximum(out, self.roughing.reached, out=out)
        return out

    @property
    def deepest_px(self) -> int:
        """The deepest target depth anywhere, Z pixels below the surface: ``asked_depth_px().max()`` without making
        that map (an int64 copy of the drawing's size: 134 MB at 4096^2)."""
        deepest = int(self.asked[: self.height_px, : self.width_px].max(initial=0))
        if self.roughing is not None:
            deepest = max(deepest, int(self.roughing.reached.max(initial=0)))
        return deepest

    def _targets(self) -> Iterator[tuple[np.ndarray, bool]]:
        """``((M, 3) int64 targets, last)``: the pixel-centre pass's cut targets (x, y, depth below the surface;
        drawing frame, a tool's drop-cutter rule applied) in cutting order, at most :attr:`piece_targets` at a
        time before the drop-cutter rule leaves some out."""
        n_max = self.piece_targets
        held: list[np.ndarray] = []
        n = 0
        pending: Optional[np.ndarray] = None
        for i, d in self.order:
            obj = self.digitized.objects[i]
            for s in range(0, len(obj), n_max):
                part = obj[s : s + n_max]
                block = np.empty((len(part), 3), np.int64)
                block[:, :2] = part
                block[:, 2] = d
                held.append(block)
                n += len(block)
                while n >= n_max:
                    joined = np.concatenate(held)
                    if pending is not None:
                        yield self._dropped(pending), False
                    pending, rest = joined[:n_max], joined[n_max:]
                    held, n = ([rest] if len(rest) else []), len(rest)
        if held:
            if pending is not None:
                yield self._dropped(pending), False
            pending = np.concatenate(held)
        if pending is not None:
            yield self._dropped(pending), True

    def _dropped(self, targets: np.ndarray) -> np.ndarray:
        """``targets`` (M, 3) no deeper than the tool may go at each pixel; those left at depth 0 left out."""
        if self.allowed is None:
            return targets
        targets[:, 2] = np.minimum(targets[:, 2], self.allowed[targets[:, 1], targets[:, 0]])
        return targets[targets[:, 2] > 0]

    def _held(self, targets: np.ndarray) -> Iterator[tuple[np.ndarray, bool]]:
        """``((m, 3) targets, last)``: held targets, at most :attr:`piece_targets` at a time (copies)."""
        n_max = self.piece_targets
        for s in range(0, len(targets), n_max):
            yield targets[s : s + n_max].copy(), s + n_max >= len(targets)

    def joined(self) -> Job:
        """Every move in one :class:`~cam.job.model.Job` (:func:`~cam.job.model.join_pieces` of :meth:`pieces`)."""
        return join_pieces(self.pieces(), self)

    def pieces(self) -> Iterator[Job]:
        """The job's moves as consecutive :class:`~cam.job.model.Job` pieces: roughing, the pixel-centre pass,
        the finer pass (see the module docstring).

        Raises:
            TravelError: the job is wider than the machine travel on some axis (found as the pieces are made;
            the job is planned in its own frame, placed and checked in the machine frame when it runs).
        """
        counts = {"moves": 0, "targets": 0, "retracts": 0, "pauses": 0}
        span = TravelSpan(self.settings)  # the job's extent so far: it must fit the travel wherever it is placed
        if self.roughing is not None:
            yield from self._part(self._held(self.roughing.targets), self.roughing, None, True, counts, span)
        centres = _Part(None, self.asked, self.corners)
        after = yield from self._part(self._targets(), centres, None, self.finer is None, counts, span,
                                      pause_px=self.pause_px)
        if self.finer is not None:
            yield from self._part(self._held(self.finer.targets), self.finer, after, True, counts, span)
        self.counts = counts

    def _part(self, chunks: Iterator[tuple[np.ndarray, bool]], part: _Part, after_px: Optional[np.ndarray],
              home: bool, counts: dict[str, int], span: TravelSpan, pause_px: Optional[np.ndarray] = None
              ) -> Generator[Job, None, Optional[np.ndarray]]:
        """The pieces of one part of the job from its targets ``chunks`` (see :meth:`_targets`): planned on the
        part's grid (drawing frame, ``part.k`` positions per pixel, Start At Z added here), from ``after_px``
        (the last target before, drawing pixels; None: from the home) to the home if ``home``.  Returns the
        part's last target (drawing frame, Start At Z included) once its pieces are made."""
        ox, oy, oz = self.pixels.origin_px
        k = part.k
        s = self.settings if k == 1 else self.settings.replace(steps_per_px_xy=self.settings.steps_per_px_xy // k)
        frame = self.pixels if k == 1 else PixelFrame(self.width_px * k, self.height_px * k, (ox * k, oy * k, oz),
                                                      s.steps_per_px_xy, s.steps_per_px_z)
        if pause_px is None:  # read only: no pause anywhere, in no memory
            pause_px = np.broadcast_to(np.zeros(1, bool), part.asked.shape)
        after = None if after_px is None else np.array([after_px[0] * k, after_px[1] * k, after_px[2]], np.int64)
        last_pt = after  # the last point so far: a diagonal from it into the next piece is guarded too
        for targets, last in chunks:
            if not len(targets) and not last:
                continue
            targets[:, 2] += oz
            pts, kind, tgt, pause = _assemble(targets, pause_px, part.asked, s, oz, min(0, oz), oz,
                                              home=(-ox * k, -oy * k), route=self.route, after=after,
                                              last=last and home, partial_lift=part.finer)
            if part.corners is not None:
                pts, kind, tgt, pause = _guard_after(last_pt, pts, kind, tgt, pause, part.corners, oz)
            if len(targets):
                after = targets[-1].copy()
            if len(pts):
                last_pt = pts[-1].copy()
            pts[:, :2] += np.array([ox * k, oy * k], np.int64)
            notes = None
            if last and part.change_note is not None:
                pause[-1] = True
                notes = [part.change_note]
            if part.finer:
                tgt, pause = np.zeros(len(pts), bool), np.zeros(len(pts), bool)
            yield self._piece(frame.to_steps(pts), kind, tgt, pause, notes, counts, span)
        return after

    def _piece(self, points_steps: np.ndarray, kind: np.ndarray, tgt: np.ndarray, pause: np.ndarray,
               notes: Optional[list[str]], counts: dict[str, int], span: TravelSpan) -> Job:
        """One piece of the job, its extent so far (``span``) checked against the travel's span: the job is
        planned in its own frame and placed when it runs (:class:`~cam.job.model.TravelSpan`; the point that
        makes it too wide named by its index in the job and its pixel)."""
        check_span(points_steps, self.settings, self.pixels, span)
        counts["moves"] += len(points_steps)
        counts["targets"] += int(np.count_nonzero(tgt))
        counts["retracts"] += int(np.count_nonzero(kind == RETRACT))
        counts["pauses"] += int(np.count_nonzero(pause))
        return Job(points_steps=points_steps, kind=kind, target=tgt, pause=pause, settings=self.settings,
                   warnings=[], safe_z_steps=self.safe_z_steps, pixels=self.pixels, tool=self.tool,
                   pause_notes=notes)


def _guard_after(last_pt: Optional[np.ndarray], pts: np.ndarray, kind: np.ndarray, tgt: np.ndarray,
                 pause: np.ndarray, corners: np.ndarray, oz: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`cam.job.drawing._guard_diagonals` of a piece whose moves go on from ``last_pt`` (the last point
    before it, the piece's frame; None: the first piece)."""
    if last_pt is None:
        return _guard_diagonals(pts, kind, tgt, pause, corners, oz)
    pts, kind, tgt, pause = _guard_diagonals(np.vstack([last_pt, pts]), np.concatenate([kind[:1] * 0, kind]),
                                             np.concatenate([[False], tgt]), np.concatenate([[False], pause]),
                                             corners, oz)
    return pts[1:], kind[1:], tgt[1:], pause[1:]


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
    stepdown_mm: float | None = None,
    stepover: float = 0.5,
    rough_tool: Tool | str | None = None,
    subpixel: bool = True,
    piece_targets: Optional[int] = None,
    cut_depth_mm: float | None = None,
) -> DrawingJobStream:
    """Plan the job of a digitized drawing as a :class:`DrawingJobStream` (see :func:`plan`,
    which is this joined, for the options).

    Args:
        piece_targets: cut points per piece (at most; None: :data:`PIECE_TARGETS`).

    Raises:
        PlanError: bad options, nothing to cut; TravelError: the job does not fit the travel wherever it is placed
        (its extent, the home included, is checked here against the travel's span before a piece is made; the
        first point that makes it too wide is named).  A job planned in its own frame: where it runs is checked
        when it is placed (issue #45 point 4).
    """
    wrong = keyword_error({"depth": depth, "cut_depth_mm": cut_depth_mm, "profile": profile, "passes": passes,
                           "stepdown_mm": stepdown_mm, "stepover": stepover, "rough_tool": rough_tool})  # cam.options
    if wrong is not None:
        raise PlanError(wrong)
    if cut_depth_mm is not None:
        depth = depth_px_of(cut_depth_mm, settings)
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
    roughing = _roughing_part(asked[:h, :w], digitized.mode, cutter, rough_tool, stepdown_mm, stepover, settings,
                              warnings)
    allowed = corners = finer = None
    if digitized.mode == "3d" and not cutter.is_point:
        allowed, corners, finer = _tool_maps(digitized, order, asked, cutter, settings, subpixel, warnings)
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
                           tool=None if cutter.is_point else cutter, warnings=warnings, roughing=roughing,
                           finer=finer,
                           piece_targets=max(1, int(PIECE_TARGETS if piece_targets is None else piece_targets)))
    if not fits:  # assembled without bridges up to its first point that makes it too wide, which is named
        for _ in job.pieces():
            pass
        raise AssertionError("a job whose extent is wider than the travel passed the travel check")
    return job


def _tool_maps(digitized: Digitized, order: list[tuple[int, int]], asked: np.ndarray, cutter: Tool,
               settings: MachineSettings, subpixel: bool, warnings: list[str]
               ) -> tuple[np.ndarray, np.ndarray, Optional[_Part]]:
    """A real tool on a 3D drawing: ``(allowed (H, W), corners (H + 1, W + 1), finer pass or None)``, the
    drop-cutter depths (:func:`cam.job.drawing._drop_maps`) of the deepest depth asked at each pixel,
    ``asked`` ``(H + 2, W + 2)``, which is then limited to them in place; warnings are added to ``warnings``.

    Raises:
        PlanError: the tool fits into no part of the relief.
    """
    h, w = digitized.height_px, digitized.width_px
    depth_px = asked[:h, :w].astype(np.int64)
    allowed, corners, note = _drop_maps(depth_px, cutter, settings)
    warnings += note
    asked[:h, :w] = np.maximum(np.minimum(asked[:h, :w], allowed), 0)
    if not asked.any():
        raise PlanError(f"nothing to cut: the {cutter.describe()} tool does not fit into any part of the relief")
    if not subpixel:
        return allowed, corners, None
    last_xy = (0, 0)  # the pixel-centre pass's last target: the finer pass starts near it
    for i, d in reversed(order):
        obj = digitized.objects[i]
        left = np.flatnonzero(np.minimum(d, allowed[obj[:, 1], obj[:, 0]]) > 0)
        if len(left):
            last_xy = (int(obj[left[-1], 0]), int(obj[left[-1], 1]))
            break
    reach = reach_depth_px(allowed, cutter, settings.px_to_mm_xy(1), settings.px_to_mm_z(1))
    fine = rest_positions(depth_px, reach, cutter, settings, start_xy_px=last_xy)
    if fine is None:
        if finer_grids(settings):
            warnings.append(f"the finer finishing pass between pixel centres (cam.job.subpixel) is left out of a "
                            f"relief this large ({h} x {w} pixels): the tool leaves a little more")
        return allowed, corners, None
    f_targets, f_allowed, f_corners, k = fine
    if not len(f_targets):
        return allowed, corners, None
    f_asked = np.zeros((f_allowed.shape[0] + 2, f_allowed.shape[1] + 2), np.int32)
    f_asked[: f_allowed.shape[0], : f_allowed.shape[1]] = f_allowed
    return allowed, corners, _Part(f_targets, f_asked, f_corners, k=int(k), finer=True)


def depth_px_of(cut_depth_mm: float, settings: MachineSettings) -> int:
    """A depth for every object in Z pixels: ``cut_depth_mm`` over one Z pixel's mm, rounded to the nearest.  The
    one place the drawing planner converts the job option ``cut_depth_mm`` (``--cut-depth``).

    Raises:
        PlanError: out of the option's range, or less than half a Z pixel (it would cut nothing).
    """
    wrong = keyword_error({"cut_depth_mm": cut_depth_mm})
    if wrong is not None:
        raise PlanError(wrong)
    depth_px = int(round(cut_depth_mm / settings.px_to_mm_z(1)))
    if depth_px < 1:
        raise PlanError(f"a cut depth of {cut_depth_mm:g} mm is less than one Z pixel ({settings.px_to_mm_z(1):g} mm)")
    return depth_px


def stepdown_px_of(stepdown_mm: float, settings: MachineSettings) -> int:
    """The roughing levels' spacing in Z pixels: ``stepdown_mm`` over one Z pixel's mm
    (:meth:`~cam.settings.MachineSettings.px_to_mm_z`), rounded down, at least 1 (a step-down finer than one
    Z pixel roughs a pixel a level).  The one place the step-down is converted: the planner, the command line
    and the page all give ``stepdown_mm`` (:data:`cam.options.OPTIONS`)."""
    return max(1, int(stepdown_mm / settings.px_to_mm_z(1) + 1e-9))


def _roughing_part(depth_px: np.ndarray, mode: str, cutter: Tool, rough_tool: Tool | str | None,
                   stepdown_mm: Optional[float], stepover: float, settings: MachineSettings, warnings: list[str]
                   ) -> Optional[_Part]:
    """The roughing part of a 3D relief whose deepest depth asked at each pixel is ``depth_px`` ``(H, W)`` (Z pixels)
    (:func:`cam.job.drawing._roughing_targets`), or None (no ``stepdown_mm``, or nothing to rough: a warning).

    Raises:
        PlanError: roughing asked for a 2D drawing, or a bad step-down, step-over or tool.
    """
    if stepdown_mm is None:
        return None
    if mode != "3d":
        raise PlanError("roughing (a step-down) applies to 3D reliefs; a 2D drawing's lines are cut at once")
    wrong = keyword_error({"stepdown_mm": stepdown_mm, "stepover": stepover})
    if wrong is not None:
        raise PlanError(wrong)
    stepdown_px = stepdown_px_of(float(stepdown_mm), settings)
    rough = parse_tool(rough_tool, "rough tool") if rough_tool else cutter
    depth_px = np.asarray(depth_px, np.int64)
    targets, allowed, corners, rough = _roughing_targets(depth_px, rough, stepdown_px, float(stepover), settings)
    if not len(targets):
        warnings.append(f"nothing to rough: the {rough.describe()} tool goes no deeper than one step-down "
                        f"({float(stepdown_mm):g} mm, {stepdown_px} Z pixels) anywhere; the relief is finished "
                        f"at once")
        return None
    h, w = depth_px.shape
    asked = np.zeros((h + 2, w + 2), np.int64)
    asked[:h, :w] = allowed
    reached = np.zeros((h, w), np.int64)
    np.maximum.at(reached, (targets[:, 1], targets[:, 0]), targets[:, 2])
    note = None
    if rough != cutter:  # the roughing part ends at the home: change the tool there
        note = f"tool change: put in the finishing tool ({cutter.describe()}; roughing used {rough.describe()})"
    return _Part(targets, asked, None if rough.is_point else corners, change_note=note, reached=reached)


def plan(
    digitized: Digitized,
    *,
    depth: int | Sequence[int] | None = None,
    settings: MachineSettings = DEFAULT_SETTINGS,
    passes: int = 1,
    start_at: tuple[int, int, int] = (0, 0, 0),
    pause_at: Sequence[tuple[int, int]] = (),
    profile: ProfileLike | None = None,
    tool: Tool | str | None = None,
    stepdown_mm: float | None = None,
    stepover: float = 0.5,
    rough_tool: Tool | str | None = None,
    subpixel: bool = True,
    cut_depth_mm: float | None = None,
) -> Job:
    """Plan the job of a digitized drawing (the drawing planner: pixels in, machine steps out).

    Args:
        digitized: the traced objects.
        depth: Z pixels below the surface -- one number for every object
            (Delta Z Uniform) or one per object (Delta Z1..Zn).  0 skips an object.
            None = 10 for a 2D drawing.  On a 3D drawing one number cuts every
            layer at that depth (a flat-bottomed pocket), instead of a profile.
        settings: machine settings (steps per pixel, travel).
        passes: Repeat Drill -- cut the whole path ``passes`` times, each
            pass deeper (pass k cuts ceil(depth x k / passes)).
        start_at: Start At ``(x, y, z)`` offset in pixels for the whole job.
        pause_at: Pause At drawing points ``(x, y)``; the job pauses each time
            the tool reaches one at its cutting depth.
        profile: for 3D drawings (or a uniform ``depth``; refused for 2D): depth per
            layer -- a :class:`~cam.digitize.profile.Profile`, a profile drawing or CSV
            path, a sequence of depths (layer 1 first) or a function of the
            layer number.  A ring of layer k is cut at profile(k).
        tool: the cutter (:class:`~cam.tool.Tool` or text such as ``"ball:1"``; None: the point tool).  On
            a 3D drawing each point's depth is limited by the drop-cutter rule (:func:`cam.tool.drop_depth_px`)
            so the tool never cuts below the asked depth at any pixel under it; points the tool cannot
            lower into at all are left out, and a warning says how much material it leaves.  On a 2D
            drawing the curves are the tool's centre line and the depth sets the groove's width.
        stepdown_mm: 3D only: rough the relief first in levels this many mm apart (each level clears
            what the roughing tool can reach down to it, in rings ``stepover`` x its diameter apart), then
            finish it with ``tool`` (None: no roughing).  The job option of the same name (``--stepdown``);
            the levels are whole Z pixels apart (:func:`stepdown_px_of`).
        stepover: the roughing rings' spacing as a fraction of the roughing tool's diameter (0 < s <= 1).
        rough_tool: the roughing tool (None: ``tool``); a different one adds a tool-change pause at the
            home between roughing and finishing.
        subpixel: 3D with a real tool: after the pixel centres, finish at the positions between them (on the
            finest grid the machine's steps reach, up to a quarter pixel) that leave less material
            (:mod:`cam.job.subpixel`).  Its points are not targets (``target`` False).
        cut_depth_mm: instead of ``depth``, one depth in mm for every object: the job option of the same name
            (``--cut-depth``), whole Z pixels by :func:`depth_px_of`.

    Returns:
        The :class:`~cam.job.model.Job` in machine steps, with its :class:`~cam.job.model.PixelFrame`,
        ending at (0, 0, 0).

    Raises:
        PlanError: fewer depths than objects, bad options; TravelError: the job is wider than the travel
        (see :func:`stream_drawing`).
    """
    return stream_drawing(digitized, depth=depth, settings=settings, passes=passes, start_at=start_at,
                          pause_at=pause_at, profile=profile, tool=tool, stepdown_mm=stepdown_mm, stepover=stepover,
                          rough_tool=rough_tool, subpixel=subpixel, cut_depth_mm=cut_depth_mm).joined()
