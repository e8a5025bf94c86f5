"""The one job model: a sequence of straight moves in machine steps, whatever the job's source.

Every planner returns a :class:`Job`: the drawing planner (:func:`cam.plan`,
a digitized matrix), drill files (:func:`cam.plan_drill`), HPGL
(:func:`cam.plan_hpgl`), jogs and go-tos (:mod:`cam.job.moves`).  Steps
are planned from it (:func:`cam.motion.steps.plan_steps`), it is checked
against the travel before a step is sent, pictured, exported as G-code and
run by the machine session.

Frame (machine steps, relative to where the tool stands when the job
starts, the job's home (0, 0, 0)): ``x`` grows to the right, ``y`` grows
toward the operator (the drawing's row direction), ``z`` grows *deeper*
into the material (0 is the home plane).  Consecutive points are straight
moves; the tool starts at (0, 0, 0) before point 0.

Sign convention for heights and depths (issue #28 point 6), one for every
planner:

* In mm, as the options give them (:mod:`cam.options`), a depth and a height
  are both positive amounts: ``cut_depth_mm`` (> 0) below the surface,
  ``travel_height_mm`` (>= 0) above it.
* In steps, a *Z coordinate* has the frame's sign, +Z deeper: a depth is
  ``depth_steps`` >= 0 and a safe height or travel height is a Z coordinate
  ``safe_z_steps`` <= 0 (above the surface), as :attr:`Job.safe_z_steps`.
* A name ending in ``_z_steps`` is such a coordinate.  The one height kept as
  a positive amount of steps is :attr:`cam.job.drill.DrillPlan.safe_steps`
  (>= 0, the MAXIMUS board's packets want the height); its coordinate is
  ``DrillPlan.safe_z_steps`` = ``-safe_steps``.

Pixels appear only as the optional :class:`PixelFrame` of a drawing job:
where the drawing's pixels lie in this frame, which the carve check and the
drawing pictures need.
"""
from __future__ import annotations

import hashlib
import tempfile
from dataclasses import dataclass, field, fields
from typing import Any, Iterable, Iterator, Optional, Protocol, runtime_checkable

import numpy as np

from ..arrays import column_range, max_at_pixels
from ..errors import TravelError
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..render.picture import encode_png, toolpath_picture

__all__ = ["Job", "JobLike", "PixelFrame", "PlanFingerprint", "CUT", "RETRACT", "TRAVEL", "check_travel", "check_reach",
           "TravelSpan", "check_span", "travel_job", "pause_points", "join_pieces"]

CUT = 0
"""A point at or above the asked depth of what is cut (the tool is in the material or at the surface over it)."""
RETRACT = 1
"""The tool lifted straight up to the surface (or the safe plane) before a travel."""
TRAVEL = 2
"""A move at the surface or the safe plane to above the next point."""


@dataclass(frozen=True)
class PixelFrame:
    """Where a drawing job's pixels lie in machine steps.

    Pixel ``(col, row)`` of the drawing is centred on machine
    ``((col + origin_px[0]) * steps_per_px_xy, (row + origin_px[1]) * steps_per_px_xy)``;
    the drawing's surface is at machine z = ``origin_px[2] * steps_per_px_z``.

    Attributes:
        width_px, height_px: size of the source drawing.
        origin_px: Start At offset ``(x, y, z)`` in pixels.
        steps_per_px_xy, steps_per_px_z: the machine's steps per drawing pixel.
    """

    width_px: int
    height_px: int
    origin_px: tuple[int, int, int] = (0, 0, 0)
    steps_per_px_xy: int = 1
    steps_per_px_z: int = 1

    def to_steps(self, points_px: np.ndarray) -> np.ndarray:
        """``(N, 3)`` int64 pixel points (Start At included) in machine steps."""
        scale = np.array([self.steps_per_px_xy, self.steps_per_px_xy, self.steps_per_px_z], np.int64)
        return np.asarray(points_px, np.int64).reshape(-1, 3) * scale

    def to_px(self, points_steps: np.ndarray) -> np.ndarray:
        """``(N, 3)`` int64 machine points back in pixels (exact for points :meth:`to_steps` made)."""
        scale = np.array([self.steps_per_px_xy, self.steps_per_px_xy, self.steps_per_px_z], np.int64)
        return np.asarray(points_steps, np.int64).reshape(-1, 3) // scale


@dataclass
class Job:
    """Ordered tool positions in machine steps: what every planner returns.

    Attributes:
        points_steps: ``(N, 3)`` int64 ``(x, y, z)`` machine position after each move, steps from the
            job's home (see the module docstring for the frame).
        kind: ``(N,)`` uint8 :data:`CUT`, :data:`RETRACT` or :data:`TRAVEL`.
        target: ``(N,)`` bool, True where the point is at a depth the input asks for.
        pause: ``(N,)`` bool, pause when the tool reaches this point (Pause At, tool changes).
        settings: the machine settings the job was planned for.
        pause_notes: what each pause is for, in order (None: every pause is a "Pause At").
        warnings: planning warnings.
        safe_z_steps: the Z a stop lifts the tool to (the surface or above it).
        pixels: for drawing jobs, where the drawing's pixels lie (see :class:`PixelFrame`).
        source: what the job was planned from (a file name, "jog", ...).
        period_ns: ``(N,)`` int64 nominal step period of each move (a feed), or None: the settings'
            step delays (X/Y, Z, the larger of the two when both move).
        periods: ``(N,)`` int64 step periods each move takes, at least its longest axis's steps (the
            steps are spread over them; a move of length 0 waits), or None: the longest axis's steps.
        move_start: ``(N,)`` bool, where a move of the source begins (a speed ramp segment of the
            ``linear40`` mode), or None: every move.
        rest: ``(N,)`` bool, the machine is at rest before and after this move (a dwell), or None.
        tool: the cutter the job was planned for (:class:`cam.tool.Tool`; None: the point tool).
        probes: a G-code program's probes (G38.2, G38.3), what each asks: the moves after each are planned as if
            it touched at its target, so a machine never runs the job as it is (:mod:`cam.job.gcode_probing` plans
            them from the contact); None or empty: it has none.
    """

    points_steps: np.ndarray
    kind: np.ndarray
    target: np.ndarray
    pause: np.ndarray
    settings: MachineSettings = DEFAULT_SETTINGS
    pause_notes: Optional[list[str]] = None
    warnings: list[str] = field(default_factory=list)
    safe_z_steps: int = 0
    pixels: Optional[PixelFrame] = None
    source: str = ""
    period_ns: Optional[np.ndarray] = None
    periods: Optional[np.ndarray] = None
    move_start: Optional[np.ndarray] = None
    rest: Optional[np.ndarray] = None
    tool: Any = None
    probes: Optional[list[str]] = None

    def __len__(self) -> int:
        return len(self.points_steps)

    @property
    def n_retracts(self) -> int:
        return int(np.count_nonzero(self.kind == RETRACT))

    @property
    def n_targets(self) -> int:
        return int(np.count_nonzero(self.target))

    @property
    def width_px(self) -> int:
        """Drawing width (0 for a job that has no drawing)."""
        return self.pixels.width_px if self.pixels else 0

    @property
    def height_px(self) -> int:
        """Drawing height (0 for a job that has no drawing)."""
        return self.pixels.height_px if self.pixels else 0

    @property
    def origin_px(self) -> tuple[int, int, int]:
        """Start At offset of a drawing job in pixels ((0, 0, 0) for a job that has no drawing)."""
        return self.pixels.origin_px if self.pixels else (0, 0, 0)

    def points_px(self) -> np.ndarray:
        """``(N, 3)`` int64 points in drawing pixels (Start At included); drawing jobs only."""
        if self.pixels is None:
            raise ValueError("this job has no drawing: its points are in machine steps only")
        return self.pixels.to_px(self.points_steps)

    def asked_depth_px(self) -> np.ndarray:
        """``(height_px, width_px)`` int64: deepest z in Z pixels asked at each drawing pixel (0: none).

        Frame: drawing pixels (the Start At offset removed); depth relative to the surface.  Drawing jobs only.
        """
        out = np.zeros((self.height_px, self.width_px), np.int64)
        p = self.points_px()[self.target] - np.asarray(self.origin_px, np.int64)
        return max_at_pixels(out, p[:, 0], p[:, 1], p[:, 2])

    @property
    def deepest_px(self) -> int:
        """The deepest depth asked anywhere, Z pixels below the surface: ``asked_depth_px().max()`` without the
        map (a relief's map and its points in pixels were 200 MB at 2048^2); drawing jobs only."""
        if not self.n_targets:
            return 0
        if self.pixels is None:
            raise ValueError("this job has no drawing: its points are in machine steps only")
        z_px = np.asarray(self.points_steps, np.int64)[self.target, 2] // self.pixels.steps_per_px_z
        return max(0, int(z_px.max()) - int(self.origin_px[2]))

    def pieces(self) -> Iterator["Job"]:
        """The job as consecutive pieces (see :class:`JobLike`): a job held in memory is one piece."""
        yield self

    def joined(self) -> "Job":
        """The whole job in memory (see :class:`JobLike`): itself."""
        return self

    def _repr_png_(self) -> bytes:
        """Notebook picture: see :func:`cam.render.picture.toolpath_picture`."""

        return encode_png(toolpath_picture(self))


_PER_MOVE = ("points_steps", "kind", "target", "pause", "period_ns", "periods", "move_start", "rest")
"""The :class:`Job` fields that hold one row per move (joined by :func:`join_pieces`)."""


@runtime_checkable
class JobLike(Protocol):
    """What every planner gives and the machine session, the step planner, the pictures, the journal and
    G-code export take: a job's moves as consecutive :class:`Job` pieces.

    A :class:`Job` held in memory is one piece (:meth:`Job.pieces` yields itself).  A job made a piece at a
    time (a large HPGL file or drawing, a resumed run of one: :mod:`cam.job.hpgl_stream`,
    :mod:`cam.job.drawing_stream`, :mod:`cam.job.resume_stream`) makes its pieces on demand, each pass anew,
    so nothing per move is held; :meth:`joined` is :func:`join_pieces` of them.  Every piece's points are in
    steps from the job's home (the frame of :class:`Job`); the whole job's attributes are here:

    Attributes:
        settings: the machine settings; safe_z_steps: the Z a stop lifts to (<= 0, +Z deeper).
        source: what the job was planned from; warnings: planning warnings (a first pass may add some).
        pixels: a drawing job's :class:`PixelFrame` (None otherwise); tool: its cutter (None: a point).
    """

    settings: MachineSettings
    safe_z_steps: int
    source: str
    warnings: list[str]
    pixels: Optional[PixelFrame]
    tool: Any

    def pieces(self) -> Iterator[Job]:
        """The moves as consecutive :class:`Job` pieces (each pass makes them anew)."""
        ...

    def joined(self) -> Job:
        """Every move in one :class:`Job` (memory grows with the job)."""
        ...


def join_pieces(pieces: Iterable[Job], like: Any) -> Job:
    """One :class:`Job` of consecutive ``pieces``, with the whole-job attributes of ``like`` (a :class:`JobLike`).

    A per-move field that some pieces leave None (e.g. ``periods``) gets each such piece's default: the
    nominal period 0 for ``period_ns``, the longest axis's steps for ``periods``, every move a ``move_start``,
    no ``rest``.
    """
    parts = list(pieces)
    cols: dict[str, Any] = {}
    for name in _PER_MOVE:
        values = [getattr(p, name) for p in parts]
        if name in ("points_steps", "kind", "target", "pause"):
            dtype = {"points_steps": np.int64, "kind": np.uint8}.get(name, np.bool_)
            shape = (0, 3) if name == "points_steps" else (0,)
            cols[name] = np.concatenate([np.asarray(v, dtype).reshape((-1, 3) if name == "points_steps" else -1)
                                         for v in values]) if values else np.zeros(shape, dtype)
        elif all(v is None for v in values):
            cols[name] = None
        else:
            cols[name] = np.concatenate([_default_column(name, p) if v is None else np.asarray(v)
                                         for p, v in zip(parts, values)])
    notes: list[str] = []
    any_notes = False
    for p in parts:
        n_pauses = int(np.count_nonzero(p.pause))
        if p.pause_notes is not None:
            any_notes = True
            notes += list(p.pause_notes)
        else:
            notes += ["Pause At"] * n_pauses
    warnings = list(getattr(like, "warnings", []) or [])
    for p in parts:
        warnings += [w for w in p.warnings if w not in warnings]
    meta = {f.name: getattr(like, f.name) for f in fields(Job)
            if f.name not in _PER_MOVE and f.name not in ("pause_notes", "warnings") and hasattr(like, f.name)}
    return Job(**cols, **meta, pause_notes=notes if any_notes else getattr(like, "pause_notes", None) or None,
               warnings=warnings)


def _default_column(name: str, piece: Job) -> np.ndarray:
    n = len(piece.points_steps)
    if name == "period_ns":
        return np.zeros(n, np.int64)
    if name == "periods":
        return np.zeros(n, np.int64)  # at least the longest axis's steps: 0 asks for nothing more
    if name == "move_start":
        return np.ones(n, bool)
    return np.zeros(n, bool)  # rest


def _mm(settings: MachineSettings, steps: np.ndarray) -> str:
    x, y, z = settings.mm_per_step_axes
    return f"{steps[0] * x:.3f}, {steps[1] * y:.3f}, {steps[2] * z:.3f} mm"


def check_travel(points_steps: np.ndarray, settings: MachineSettings, pixels: Optional[PixelFrame] = None) -> None:
    """Raise :class:`TravelError` naming the first of ``(N, 3)`` machine points outside the travel.

    ``pixels``: name the point in drawing pixels too (drawing jobs).
    """
    steps = np.asarray(points_steps, np.int64).reshape(-1, 3)
    bounds = settings.travel.bounds_steps()
    lo = np.array([b[0] for b in bounds], np.int64)
    hi = np.array([b[1] for b in bounds], np.int64)
    if not len(steps):
        return
    least, most = column_range(steps)
    if np.all(least >= lo) and np.all(most <= hi):
        return  # the extent is inside: no point to name (one strided pass per column)
    i = int(np.flatnonzero(np.any((steps < lo) | (steps > hi), axis=1))[0])  # some point is outside
    a = int(np.flatnonzero((steps[i] < lo) | (steps[i] > hi))[0])
    xs, ys, zs = (int(v) for v in steps[i])
    if pixels is not None:
        x, y, z = (int(v) for v in pixels.to_px(steps[i])[0])
        where = f"x={x}, y={y}, z={z} px = {xs}, {ys}, {zs} steps"
    else:
        where = f"{xs}, {ys}, {zs} steps = {_mm(settings, steps[i])}"
    raise TravelError(
        f"job leaves the machine travel at point {i} ({where}): {'XYZ'[a]} travel is {lo[a]}..{hi[a]} steps"
    )


def _mm1(value: float) -> str:
    return f"{round(value, 3):g}"


class TravelSpan:
    """Whether a job planned in its own frame fits the machine wherever it is placed (issue #45 point 4).

    A drawing, a relief, or a drill, HPGL or SVG file placed by its extent is planned from its own home
    (0, 0, 0) and placed at the work zero when it runs (:func:`cam.drive.placement.approach_to_work_zero`), where
    every point is checked against the travel in the machine frame (the session's check of the job's extent
    from where it starts).  What is known before then is position-free: the job's extent, its home included
    (it starts and ends there), must be no wider than the travel on each axis.  Fed the job's points in order
    (a piece at a time: the extent so far is kept), :meth:`over` finds the first point that makes it too wide.
    """

    def __init__(self, settings: MachineSettings) -> None:
        self.settings = settings
        self.bounds = np.array(settings.travel.bounds_steps(), np.int64)
        self.lo = np.zeros(3, np.int64)  # the extent so far, the home (0, 0, 0) included
        self.hi = np.zeros(3, np.int64)
        self.n = 0  # points taken in

    def over(self, points_steps: np.ndarray) -> Optional[tuple[int, str]]:
        """Take in ``(N, k)`` points (k = 2: x, y; 3: x, y, z) steps from the job's home, in the job's order: None
        while the extent fits the travel's span, else ``(i, text)``: point ``i`` of them is the first that makes
        it wider than the travel, and what a message says of it (the axis, the travel, the job's extent from its
        home, in steps and mm).  Nothing of a refused batch is taken in.

        >>> span = TravelSpan(DEFAULT_SETTINGS)
        >>> span.over(np.array([[9000, 5], [-300, 2]])) is None  # 9300 steps wide: it fits somewhere
        True
        >>> i, text = span.over(np.array([[100, 0], [-1100, 0]]))
        >>> i, text[:48]
        (1, 'X travel is 0..10000 steps (0..289 mm, 289 mm) a')
        """
        pts = np.asarray(points_steps, np.int64)
        if not pts.size:
            return None
        k = pts.shape[-1]
        pts = pts.reshape(-1, k)
        span = self.bounds[:k, 1] - self.bounds[:k, 0]
        least, most = column_range(pts)
        lo, hi = np.minimum(self.lo[:k], least), np.maximum(self.hi[:k], most)
        if np.all(hi - lo <= span):
            self.lo[:k], self.hi[:k] = lo, hi
            self.n += len(pts)
            return None
        run_lo = np.minimum(np.minimum.accumulate(pts, axis=0), self.lo[:k])
        run_hi = np.maximum(np.maximum.accumulate(pts, axis=0), self.hi[:k])
        wide = run_hi - run_lo > span
        i = int(np.flatnonzero(wide.any(axis=1))[0])
        a = int(np.flatnonzero(wide[i])[0])
        return i, self.describe(a, int(run_lo[i, a]), int(run_hi[i, a]))

    def describe(self, axis: int, lo: int, hi: int) -> str:
        """What a message says of an extent ``lo..hi`` steps (from the job's home) on ``axis`` (0, 1, 2) wider than
        the travel."""
        mm = self.settings.mm_per_step_axes[axis]
        t_lo, t_hi = (int(v) for v in self.bounds[axis])
        name = "XYZ"[axis]
        return (f"{name} travel is {t_lo}..{t_hi} steps ({_mm1(t_lo * mm)}..{_mm1(t_hi * mm)} mm, "
                f"{_mm1((t_hi - t_lo) * mm)} mm) and the job spans {name} {lo}..{hi} steps "
                f"({_mm1(lo * mm)}..{_mm1(hi * mm)} mm, {_mm1((hi - lo) * mm)} mm) from its home: it does not fit "
                f"the machine wherever it is placed")


def check_span(points_steps: np.ndarray, settings: MachineSettings, pixels: Optional[PixelFrame] = None,
               span: Optional[TravelSpan] = None) -> None:
    """Raise :class:`TravelError` when ``(N, 3)`` points of a job planned in its own frame (steps from its home)
    make its extent wider than the travel (:class:`TravelSpan`): one line naming the first such point (its
    index in the job, in drawing pixels too with ``pixels``), the axis, the travel and the job's extent.
    ``span``: the job's extent so far (a job checked a piece at a time, in order; None: these points are the
    whole job).  Where the job goes is checked when it is placed (:func:`check_travel` from there)."""
    span = span if span is not None else TravelSpan(settings)
    first = span.n
    found = span.over(np.asarray(points_steps, np.int64).reshape(-1, 3))
    if found is None:
        return
    i, text = found
    steps = np.asarray(points_steps, np.int64).reshape(-1, 3)[i]
    xs, ys, zs = (int(v) for v in steps)
    if pixels is not None:
        x, y, z = (int(v) for v in pixels.to_px(steps)[0])
        where = f"x={x}, y={y}, z={z} px = {xs}, {ys}, {zs} steps"
    else:
        where = f"{xs}, {ys}, {zs} steps = {_mm(settings, steps)}"
    raise TravelError(f"job leaves the machine travel at point {first + i} ({where}): {text}")


def check_reach(position_steps: np.ndarray, extent_steps: np.ndarray, settings: MachineSettings, what: str) -> None:
    """Refuse a move whose ``(3, 2)`` min/max extent (relative to the tool) leaves the travel from ``position_steps``.

    Raises:
        TravelError: naming the axis, where the tool is and how far the move reaches.
    """
    for a, (lo, hi) in enumerate(settings.travel.bounds_steps()):
        p = int(position_steps[a])
        reach_lo, reach_hi = p + int(extent_steps[a, 0]), p + int(extent_steps[a, 1])
        if reach_lo < lo or reach_hi > hi:
            raise TravelError(f"{what} would leave the {'XYZ'[a]} travel ({lo}..{hi} steps from the home): the tool "
                              f"is at {'XYZ'[a]}={p} and the move reaches {reach_lo}..{reach_hi}")


def travel_job(points_steps: np.ndarray, settings: MachineSettings, *, source: str = "") -> Job:
    """A travel-only job through ``(N, 3)`` machine points (jogs, go-tos, back to the origin).

    No travel check: the caller knows where the tool stands (see :mod:`cam.job.moves`).
    """
    pts = np.asarray(points_steps, np.int64).reshape(-1, 3)
    n = len(pts)
    return Job(points_steps=pts, kind=np.full(n, TRAVEL, np.uint8), target=np.zeros(n, bool),
               pause=np.zeros(n, bool), settings=settings, source=source)


def cut_runs_steps(toolpath: JobLike) -> list[np.ndarray]:
    """Each run of consecutive points of ``toolpath`` below the surface (Z > 0 from its home), ``(N, 2)`` X, Y
    steps from the home, in the order cut; a run that goes on from one piece into the next is one run (the
    pieces streamed, one at a time)."""
    runs: list[np.ndarray] = []
    open_run = False  # the last run of the previous piece reached its end
    for piece in toolpath.pieces():
        pts = np.asarray(piece.points_steps, np.int64).reshape(-1, 3)
        if not len(pts):
            continue
        edges = np.flatnonzero(np.diff(np.r_[0, (pts[:, 2] > 0).astype(np.int8), 0]))
        for a, b in zip(edges[::2], edges[1::2]):
            xy = pts[a:b, :2]
            if a == 0 and open_run:
                xy = np.vstack([runs.pop(), xy])
            runs.append(xy)
        open_run = bool(len(edges)) and edges[-1] == len(pts)
    return runs


def pause_points(toolpath: JobLike) -> np.ndarray:
    """``(P,)`` int64 indices of a job's points that pause (one pass over its pieces)."""
    found, first = [], 0
    for piece in toolpath.pieces():
        found.append(np.flatnonzero(piece.pause) + first)
        first += len(piece.points_steps)
    return np.concatenate(found) if found else np.zeros(0, np.int64)


class PlanFingerprint:
    """sha256 of a job's moves fed a piece at a time, in bounded memory (:func:`cam.job.resume.plan_fingerprint`;
    :func:`cam.motion.chunks.plan_chunks` makes it in its own pass when asked).

    The bytes hashed are those of the whole job's arrays, whatever the pieces: its ``(N, 3)`` int64 points,
    ``0``, its ``(N,)`` uint8 kinds, ``0``, its ``(N,)`` bool pauses, ``0``.  The points go to the hash as
    they come; the kinds and the pauses (two bytes a move) wait in spooled temporary files (on disk past a
    few MiB) until :meth:`hexdigest`.
    """

    SPOOL_BYTES = 8 << 20

    def __init__(self) -> None:
        self._h = hashlib.sha256()
        self._kinds = tempfile.SpooledTemporaryFile(max_size=self.SPOOL_BYTES)
        self._pauses = tempfile.SpooledTemporaryFile(max_size=self.SPOOL_BYTES)

    def add(self, piece: Job) -> None:
        """Hash the moves of ``piece``, the next piece of the job."""
        self._h.update(np.ascontiguousarray(np.asarray(piece.points_steps, np.int64)).tobytes())
        self._kinds.write(np.ascontiguousarray(np.asarray(piece.kind, np.uint8)).tobytes())
        self._pauses.write(np.ascontiguousarray(np.asarray(piece.pause, np.bool_)).tobytes())

    def hexdigest(self) -> str:
        """The fingerprint of the moves added so far (sha256, hex); more may be added after."""
        h = self._h.copy()
        h.update(b"\0")
        for spool in (self._kinds, self._pauses):
            spool.seek(0)
            for chunk in iter(lambda: spool.read(1 << 20), b""):
                h.update(chunk)
            spool.seek(0, 2)  # back to the end: later pieces are appended
            h.update(b"\0")
        return h.hexdigest()

    def close(self) -> None:
        """Let the spooled files go (nothing more may be added)."""
        self._kinds.close()
        self._pauses.close()
