"""Levelling a job to a probed surface (issue #46 point 2): a height map, its file, and every move split and lifted.

A warped board is cut at the same depth everywhere when each point of the job is offset in Z by how far the
surface under it lies above or below the surface where the work Z zero was set.  ``cam probe grid`` writes the
surface as a :class:`HeightMap` (``--out MAP.json``); ``--level MAP.json`` (:attr:`cam.kinds.jobs.JobOptions.level`)
levels a job by it.

Frames and units:

* The map is in the **machine frame, mm**: ``X = x_steps * mm_per_step_x``, ``Y = y_steps * mm_per_step_y``
  from the machine's home, +Y toward the operator (cam's machine frame).
* ``height_mm`` is the surface's height, **up positive**, mm: a probe contact at machine ``z_steps`` is
  ``height = -z_steps * mm_per_step_z`` (cam's +Z is deeper).
* ``reference_mm`` is the height of the surface where the work Z zero was set: a job's Z is measured from
  there, so a point over surface height ``h`` is offset by ``-(h - reference_mm) / mm_per_step_z`` Z steps (a
  higher surface: less deep).

Between the probed points the surface is taken **bilinear** (:func:`height_at`).  Every move, rapids and
travels included, is split into moves at most the map's spacing long in XY (:func:`level_points`): Z is
interpolated linearly along the move first, then offset, then rounded to whole steps.  A point outside the
probed area is refused, naming how far outside and past which edge, unless ``extrapolate``: then the edge
cells' bilinear patches are **extended** past the edge (a tilted board stays exact there; a bow is continued
by its edge cells' slope).  A map whose neighbouring points differ by more than ``max_diff_mm`` (default 1 mm)
is refused (:func:`check_map`: a missed contact or a probe that hit a clamp).

:class:`LevelledJob` levels any :class:`~cam.job.model.JobLike` a piece at a time (bounded memory: one piece
and its split moves); a job held in memory is its pieces joined (:func:`level_job`).

The file (JSON, UTF-8)::

    {"cam_height_map": 1, "frame": "machine", "units": "mm",
     "x_mm": [0.0, 10.0, ...], "y_mm": [0.0, 10.0, ...],
     "height_mm": [[h(x0, y0), h(x1, y0), ...], [h(x0, y1), ...], ...],
     "reference_mm": 0.12, "spacing_mm": 10.0, "machine": "mill.toml", "time": "2026-12-01T10:00:00"}

``height_mm`` holds one row per ``y_mm``, each ``len(x_mm)`` long.  Other keys are ignored.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Optional

import numpy as np

from ..errors import CamError, ParseError, PlanError
from ..fileio import atomic_write_text, read_bytes
from ..settings import MachineSettings
from .model import Job, JobLike, join_pieces

__all__ = ["HeightMap", "Levelled", "LevelledJob", "MAP_VERSION", "MAX_MAP_BYTES", "MAX_MAP_POINTS",
           "DEFAULT_MAX_DIFF_MM", "save_height_map", "load_height_map", "height_at", "check_map", "outside_text",
           "level_points", "level_job", "map_summary"]

MAP_VERSION = 1
"""The ``cam_height_map`` value of the file format this module reads and writes."""
MAX_MAP_BYTES = 64 << 20
"""The largest height map file read (64 MiB: a million points with room to spare)."""
MAX_MAP_POINTS = 1 << 20
"""The most points a height map may hold (a 1 m square probed every millimetre)."""
DEFAULT_MAX_DIFF_MM = 1.0
"""How much two neighbouring points of a map may differ before :func:`check_map` refuses it, mm."""
_EDGE_MM = 1e-6
"""How far (mm) a point may lie past an edge and still count as inside (a step's mm rounded in floats)."""


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _problem(x: np.ndarray, y: np.ndarray, h: np.ndarray, reference_mm: Any, spacing_mm: Any
             ) -> Optional[tuple[str, str]]:
    """``(key, why)`` of the first thing wrong with a map's arrays and numbers, or None."""
    for key, axis in (("x_mm", x), ("y_mm", y)):
        if axis.ndim != 1 or len(axis) < 2:
            return key, f"needs at least 2 points (a map of at least 2 x 2), got {axis.size}"
        bad = np.flatnonzero(~np.isfinite(axis))
        if len(bad):
            return key, f"value {bad[0]} is {float(axis[bad[0]])!r}, not a finite number"
        down = np.flatnonzero(np.diff(axis) <= 0)
        if len(down):
            i = int(down[0]) + 1
            return key, f"must be ascending: value {i} ({axis[i]:g}) is not above value {i - 1} ({axis[i - 1]:g})"
    if x.size * y.size > MAX_MAP_POINTS:
        return "height_mm", f"{x.size} x {y.size} points, more than {MAX_MAP_POINTS:,}"
    if h.shape != (len(y), len(x)):
        return "height_mm", f"must be {len(y)} rows (one per y_mm) of {len(x)} values (one per x_mm), got shape " \
                            f"{h.shape}"
    bad2 = np.argwhere(~np.isfinite(h))
    if len(bad2):
        r, c = (int(v) for v in bad2[0])
        return "height_mm", f"row {r} value {c} is {float(h[r, c])!r}, not a finite number"
    if isinstance(reference_mm, bool) or not isinstance(reference_mm, (int, float, np.floating, np.integer)) \
            or not math.isfinite(float(reference_mm)):
        return "reference_mm", f"must be a finite number, got {_shown(reference_mm)}"
    if isinstance(spacing_mm, bool) or not isinstance(spacing_mm, (int, float, np.floating, np.integer)) \
            or not (math.isfinite(float(spacing_mm)) and float(spacing_mm) > 0):
        return "spacing_mm", f"must be a number > 0, got {_shown(spacing_mm)}"
    return None


def _frozen(values: Any) -> np.ndarray:
    a = np.array(values, np.float64)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class HeightMap:
    """A probed surface: heights on a grid in the machine frame (see the module docstring for the frames).

    Attributes:
        x_mm: ``(NX,)`` float64 machine X of the grid's columns, mm, strictly ascending (NX >= 2).
        y_mm: ``(NY,)`` float64 machine Y of its rows, mm, strictly ascending (NY >= 2; +Y toward the operator).
        height_mm: ``(NY, NX)`` float64 surface height at ``(x_mm[c], y_mm[r])`` in row ``r``, column ``c``, mm,
            up positive (``-z_steps * mm_per_step_z`` of the probe's contact).
        reference_mm: the surface height where the work Z zero was set (offsets are ``height - reference``).
        spacing_mm: the spacing the grid was probed at (moves are split at most this long, or the grid's
            smallest spacing when less).
        machine: the machine file the map was probed on (None: the built-in settings).
        time: when it was probed (ISO 8601).

    Raises:
        CamError: naming the field, for arrays of the wrong shape, not ascending, not finite, or too many points.

    >>> m = HeightMap([0, 10], [0, 10], [[0.0, 0.1], [0.2, 0.3]], reference_mm=0.0, spacing_mm=10)
    >>> round(float(height_at(m, 5.0, 5.0)), 6)
    0.15
    """

    x_mm: np.ndarray
    y_mm: np.ndarray
    height_mm: np.ndarray
    reference_mm: float = 0.0
    spacing_mm: float = 10.0
    machine: Optional[str] = None
    time: str = ""

    def __post_init__(self) -> None:
        try:
            x, y, h = _frozen(self.x_mm), _frozen(self.y_mm), _frozen(self.height_mm)
        except (TypeError, ValueError) as exc:
            raise CamError(f"height map: x_mm, y_mm and height_mm must be numbers ({exc})") from None
        problem = _problem(x, y, h, self.reference_mm, self.spacing_mm)
        if problem is not None:
            raise CamError(f"height map: {problem[0]} {problem[1]}")
        object.__setattr__(self, "x_mm", x)
        object.__setattr__(self, "y_mm", y)
        object.__setattr__(self, "height_mm", h)
        object.__setattr__(self, "reference_mm", float(self.reference_mm))
        object.__setattr__(self, "spacing_mm", float(self.spacing_mm))

    @property
    def shape(self) -> tuple[int, int]:
        """``(NY, NX)``: rows and columns of the grid."""
        return self.height_mm.shape  # type: ignore[return-value]

    @property
    def split_mm(self) -> float:
        """The longest XY move levelling leaves whole, mm: the spacing, or the grid's finest when that is less."""
        return float(min(self.spacing_mm, np.diff(self.x_mm).min(), np.diff(self.y_mm).min()))

    def offsets_mm(self) -> np.ndarray:
        """``(NY, NX)`` float64 ``height_mm - reference_mm``: how far above the work zero's surface each point is."""
        return self.height_mm - self.reference_mm

    def to_json(self) -> dict[str, Any]:
        """The map as the file's JSON object (see the module docstring)."""
        return {"cam_height_map": MAP_VERSION, "frame": "machine", "units": "mm",
                "x_mm": self.x_mm.tolist(), "y_mm": self.y_mm.tolist(), "height_mm": self.height_mm.tolist(),
                "reference_mm": self.reference_mm, "spacing_mm": self.spacing_mm, "machine": self.machine,
                "time": self.time}


def save_height_map(height_map: HeightMap, path: str | os.PathLike) -> Path:
    """Write ``height_map`` to ``path`` as JSON (one grid row a line), atomically
    (:func:`cam.fileio.atomic_write_text`); :func:`load_height_map` reads it back exactly (every float to its last
    digit)."""
    d = height_map.to_json()
    rows = d.pop("height_mm")
    head = json.dumps(d)[:-1]
    body = ",\n  ".join(json.dumps(r) for r in rows)
    return atomic_write_text(path, f'{head}, "height_mm": [\n  {body}\n]}}\n')


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number a height map may hold")


def _numbers(where: str, key: str, value: Any, inner: Optional[int] = None) -> list:
    """A JSON list of numbers (``inner``: of lists of numbers, each that long), else ParseError naming the key."""
    if not isinstance(value, list):
        raise ParseError(f"{where}: key '{key}' must be a list of numbers, got {_shown(value)}")
    rows = value if inner is not None else [value]
    for r, row in enumerate(rows):
        if inner is not None and not isinstance(row, list):
            raise ParseError(f"{where}: key '{key}' row {r} must be a list of numbers, got {_shown(row)}")
        for c, v in enumerate(row):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                at = f"row {r} value {c}" if inner is not None else f"value {c}"
                raise ParseError(f"{where}: key '{key}' {at} must be a number, got {_shown(v)}")
        if inner is not None and len(row) != inner:
            raise ParseError(f"{where}: key '{key}' row {r} has {len(row)} values, x_mm has {inner}")
    return value


def load_height_map(path: str | os.PathLike) -> HeightMap:
    """Read a height map file (see the module docstring) and check it.

    Raises:
        ParseError: one line naming the file and the bad key or value: not found, larger than
        :data:`MAX_MAP_BYTES`, not JSON, another format or version, a missing key, NaN or infinity, an axis
        not ascending, rows of the wrong length, fewer than 2 x 2 or more than :data:`MAX_MAP_POINTS` points.
    """
    p, raw = read_bytes(path, max_bytes=MAX_MAP_BYTES, what="a height map file")
    where = str(p)
    try:
        data = json.loads(raw.decode("utf-8"), parse_constant=_no_constant)
    except UnicodeDecodeError:
        raise ParseError(f"{where}: not a height map (not UTF-8 text)") from None
    except RecursionError:
        raise ParseError(f"{where}: not a height map (nested too deep)") from None
    except ValueError as exc:
        raise ParseError(f"{where}: not a height map JSON file ({str(exc).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise ParseError(f"{where}: not a height map (a JSON object with key 'cam_height_map' is)")
    for key, want in (("cam_height_map", MAP_VERSION), ("frame", "machine"), ("units", "mm")):
        if key not in data:
            raise ParseError(f"{where}: key '{key}' missing (a cam height map has '{key}': {json.dumps(want)})")
        got = data[key]
        if got != want or isinstance(got, bool):
            raise ParseError(f"{where}: key '{key}' must be {json.dumps(want)}, got {_shown(got)}")
    for key in ("x_mm", "y_mm", "height_mm", "reference_mm", "spacing_mm"):
        if key not in data:
            raise ParseError(f"{where}: key '{key}' missing")
    x = _numbers(where, "x_mm", data["x_mm"])
    y = _numbers(where, "y_mm", data["y_mm"])
    if len(x) * len(y) > MAX_MAP_POINTS:
        raise ParseError(f"{where}: key 'height_mm' {len(x)} x {len(y)} points, more than {MAX_MAP_POINTS:,}")
    h = data["height_mm"]
    if isinstance(h, list) and len(h) != len(y):
        raise ParseError(f"{where}: key 'height_mm' has {len(h)} rows, y_mm has {len(y)}")
    h = _numbers(where, "height_mm", h, inner=len(x))
    machine, when = data.get("machine"), data.get("time", "")
    if machine is not None and not isinstance(machine, str):
        raise ParseError(f"{where}: key 'machine' must be a file name or null, got {_shown(machine)}")
    if not isinstance(when, str):
        raise ParseError(f"{where}: key 'time' must be text (ISO 8601), got {_shown(when)}")
    try:
        xa, ya = np.array(x, np.float64).reshape(-1), np.array(y, np.float64).reshape(-1)
        ha = np.array(h, np.float64).reshape(len(y), len(x))
    except OverflowError:
        raise ParseError(f"{where}: a number too large for a height map") from None
    problem = _problem(xa, ya, ha, data["reference_mm"], data["spacing_mm"])
    if problem is not None:
        raise ParseError(f"{where}: key '{problem[0]}' {problem[1]}")
    return HeightMap(xa, ya, ha, float(data["reference_mm"]), float(data["spacing_mm"]), machine, when)


def height_at(height_map: HeightMap, x_mm: Any, y_mm: Any) -> np.ndarray:
    """The surface height (mm, up positive) at machine ``(x_mm, y_mm)``, bilinear between the grid's points.

    ``x_mm`` and ``y_mm`` are numbers or arrays of any shapes that broadcast together; the result has their
    broadcast shape (float64).  Exact at the grid's points and for any plane ``a + b x + c y`` (and ``x y``
    terms).  Past the grid's edge the edge cell's bilinear patch is extended (not clamped): see
    :func:`outside_text` for what refuses such points.

    >>> m = HeightMap([0, 10, 20], [0, 10], [[0, 1, 2], [1, 2, 3]], spacing_mm=10)
    >>> height_at(m, np.array([0, 5, 15, 25]), 5.0).tolist()
    [0.5, 1.0, 2.0, 3.0]
    """
    xs, ys = np.broadcast_arrays(np.asarray(x_mm, np.float64), np.asarray(y_mm, np.float64))
    gx, gy, h = height_map.x_mm, height_map.y_mm, height_map.height_mm
    ix = np.clip(np.searchsorted(gx, xs, side="right") - 1, 0, len(gx) - 2)
    iy = np.clip(np.searchsorted(gy, ys, side="right") - 1, 0, len(gy) - 2)
    tx = (xs - gx[ix]) / (gx[ix + 1] - gx[ix])
    ty = (ys - gy[iy]) / (gy[iy + 1] - gy[iy])
    low = h[iy, ix] + tx * (h[iy, ix + 1] - h[iy, ix])
    high = h[iy + 1, ix] + tx * (h[iy + 1, ix + 1] - h[iy + 1, ix])
    return low + ty * (high - low)


def check_map(height_map: HeightMap, *, max_diff_mm: float = DEFAULT_MAX_DIFF_MM) -> HeightMap:
    """Refuse a map two of whose neighbouring points (along X or along Y) differ by more than ``max_diff_mm``:
    a probe that missed the surface or touched a clamp, which would drive the tool into the board.  Returns
    the map.

    Raises:
        CamError: naming the two points (machine X, Y and height, mm) and the difference.
    """
    if not (isinstance(max_diff_mm, (int, float)) and math.isfinite(max_diff_mm) and max_diff_mm > 0):
        raise CamError(f"max_diff_mm must be a number > 0, got {_shown(max_diff_mm)}")
    h = height_map.height_mm
    along_x, along_y = np.abs(np.diff(h, axis=1)), np.abs(np.diff(h, axis=0))
    worst = max(float(along_x.max()), float(along_y.max()))
    if worst <= max_diff_mm:
        return height_map
    if float(along_x.max()) >= float(along_y.max()):
        r, c = np.unravel_index(int(np.argmax(along_x)), along_x.shape)
        a, b = (int(r), int(c)), (int(r), int(c) + 1)
    else:
        r, c = np.unravel_index(int(np.argmax(along_y)), along_y.shape)
        a, b = (int(r), int(c)), (int(r) + 1, int(c))

    def point(rc: tuple[int, int]) -> str:
        return (f"X {height_map.x_mm[rc[1]]:g}, Y {height_map.y_mm[rc[0]]:g} mm "
                f"(height {h[rc]:.4g} mm)")

    raise CamError(f"height map: neighbouring points {point(a)} and {point(b)} differ by {worst:.4g} mm, more than "
                   f"{max_diff_mm:g} mm: a probe that missed or touched something else? probe again")


def map_summary(height_map: HeightMap) -> dict[str, Any]:
    """What ``cam info MAP.json`` says of a map, JSON-able: the grid (``points``, ``grid``: ``[NX, NY]``), the
    spacing it was probed at (``spacing_mm``) and its finest (``cell_mm``: ``[dx, dy]``), the probed area in
    machine mm (``area_mm``: ``[x0, y0, x1, y1]``, ``size_mm``), the heights (``height_mm``: min, max, mean, and
    ``range_mm``), the largest difference between two neighbouring points (``max_neighbour_diff_mm``, with both
    points' machine ``[x, y]`` in ``between_mm``), ``reference_mm``, ``machine`` and ``time``.

    >>> s = map_summary(HeightMap([0, 10, 20], [0, 10], [[0.0, 0.1, 0.4], [0.2, 0.3, 0.5]], spacing_mm=10))
    >>> s["grid"], s["area_mm"], s["height_mm"], s["max_neighbour_diff_mm"], s["between_mm"]
    ([3, 2], [0.0, 0.0, 20.0, 10.0], {'min': 0.0, 'max': 0.5, 'mean': 0.25}, 0.3, [[10.0, 0.0], [20.0, 0.0]])
    """
    h = height_map.height_mm
    gx, gy = height_map.x_mm, height_map.y_mm
    along_x, along_y = np.abs(np.diff(h, axis=1)), np.abs(np.diff(h, axis=0))
    if float(along_x.max()) >= float(along_y.max()):
        r, c = (int(v) for v in np.unravel_index(int(np.argmax(along_x)), along_x.shape))
        worst, between = float(along_x[r, c]), [[gx[c], gy[r]], [gx[c + 1], gy[r]]]
    else:
        r, c = (int(v) for v in np.unravel_index(int(np.argmax(along_y)), along_y.shape))
        worst, between = float(along_y[r, c]), [[gx[c], gy[r]], [gx[c], gy[r + 1]]]

    def mm(v: Any) -> float:
        return round(float(v), 6)

    return {"kind": "height map", "points": int(h.size), "grid": [len(gx), len(gy)],
            "spacing_mm": mm(height_map.spacing_mm),
            "cell_mm": [mm(np.diff(gx).min()), mm(np.diff(gy).min())],
            "area_mm": [mm(gx[0]), mm(gy[0]), mm(gx[-1]), mm(gy[-1])],
            "size_mm": [mm(gx[-1] - gx[0]), mm(gy[-1] - gy[0])],
            "height_mm": {"min": mm(h.min()), "max": mm(h.max()), "mean": mm(h.mean())},
            "range_mm": mm(h.max() - h.min()), "max_neighbour_diff_mm": mm(worst),
            "between_mm": [[mm(v) for v in p] for p in between], "reference_mm": mm(height_map.reference_mm),
            "machine": height_map.machine, "time": height_map.time}


def outside_text(height_map: HeightMap, x_mm: Any, y_mm: Any, *, name_point: bool = True) -> Optional[str]:
    """None when every machine ``(x_mm, y_mm)`` (arrays of one shape) lies in the probed area, else what a message
    says of the farthest outside: how far (mm) past which edge, and (``name_point``) the point.

    >>> m = HeightMap([0, 100], [0, 80], np.zeros((2, 2)), spacing_mm=10)
    >>> outside_text(m, np.array([50.0, 103.5]), np.array([20.0, 40.0]))
    'the job reaches 3.5 mm outside the probed area, past its X max edge (X 100 mm), at machine X 103.5, Y 40 mm'
    """
    xs = np.asarray(x_mm, np.float64).reshape(-1)
    ys = np.asarray(y_mm, np.float64).reshape(-1)
    if not xs.size:
        return None
    x0, x1 = float(height_map.x_mm[0]), float(height_map.x_mm[-1])
    y0, y1 = float(height_map.y_mm[0]), float(height_map.y_mm[-1])
    past = np.stack([x0 - xs, xs - x1, y0 - ys, ys - y1])  # (4, N): how far past each edge
    side, i = np.unravel_index(int(np.argmax(past)), past.shape)
    d = float(past[side, i])
    if d <= _EDGE_MM:
        return None
    edge = (f"X min edge (X {x0:g} mm)", f"X max edge (X {x1:g} mm)", f"Y min edge (Y {y0:g} mm)",
            f"Y max edge (Y {y1:g} mm, toward the operator)")[int(side)]
    text = f"the job reaches {d:.4g} mm outside the probed area, past its {edge}"
    return f"{text}, at machine X {xs[i]:.4g}, Y {ys[i]:.4g} mm" if name_point else text


@dataclass(frozen=True)
class Levelled:
    """What :func:`level_points` gives.

    Attributes:
        points_steps: ``(M, 3)`` int64 the levelled points, machine frame, steps (M >= N: the moves split).
        move_of: ``(M,)`` int64 the index of the source move (its end point, 0..N-1) each point lies on.
        t: ``(M,)`` float64 how far along its source move each point lies (0 < t <= 1; exactly 1 at its end).
    """

    points_steps: np.ndarray
    move_of: np.ndarray
    t: np.ndarray

    @property
    def is_end(self) -> np.ndarray:
        """``(M,)`` bool: the point is its source move's end (the source's own point)."""
        return self.t == 1.0


def level_points(points_steps: Any, height_map: HeightMap, settings: MachineSettings, *,
                 start_steps: Any = None, extrapolate: bool = False) -> Levelled:
    """Split every move at the map's spacing and offset each point's Z by the surface under it.

    Args:
        points_steps: ``(N, 3)`` int64 consecutive tool positions, machine frame, steps (+Z deeper): move ``i``
            goes from point ``i - 1`` (from ``start_steps`` for ``i = 0``) to point ``i``.
        height_map: the surface; settings: the machine's mm per step.
        start_steps: ``(3,)`` where the tool stands before point 0, machine frame (None: point 0 is not split,
            only offset).  The start itself is not moved.
        extrapolate: level points outside the probed area by the edge cells' patches extended (else refused).

    Returns:
        :class:`Levelled`: a move longer in XY than :attr:`HeightMap.split_mm` becomes ``ceil(length / split)``
        equal moves; each point's Z is the move's Z interpolated linearly at it, offset by
        ``-(height_at - reference_mm) / mm_per_step_z`` steps (a higher surface: less deep), rounded to whole
        steps; X and Y are rounded to whole steps (a source point keeps its own).

    Raises:
        PlanError: a point outside the probed area (without ``extrapolate``), naming how far and past which edge.

    >>> m = HeightMap([0, 10], [0, 10], [[0.0, 0.0], [0.0, 0.0]], spacing_mm=5)
    >>> s = MachineSettings()
    >>> lv = level_points(np.array([[300, 0, 0]]), m, s, start_steps=(0, 0, 0))  # 8.67 mm: two moves
    >>> lv.points_steps.tolist(), lv.move_of.tolist()
    ([[150, 0, 0], [300, 0, 0]], [0, 0])
    """
    pts = np.asarray(points_steps, np.int64).reshape(-1, 3)
    n = len(pts)
    if not n:
        return Levelled(np.zeros((0, 3), np.int64), np.zeros(0, np.int64), np.zeros(0, np.float64))
    mx, my, mz = (float(v) for v in settings.mm_per_step_axes)
    before = np.empty_like(pts)
    before[1:] = pts[:-1]
    before[0] = pts[0] if start_steps is None else np.asarray(start_steps, np.int64).reshape(3)
    dxy_mm = np.hypot((pts[:, 0] - before[:, 0]) * mx, (pts[:, 1] - before[:, 1]) * my)
    k = np.maximum(1, np.ceil(dxy_mm / height_map.split_mm - 1e-9)).astype(np.int64)
    total = int(k.sum())
    move_of = np.repeat(np.arange(n, dtype=np.int64), k)
    first = np.cumsum(k) - k
    j = np.arange(total, dtype=np.int64) - first[move_of] + 1
    t = j / k[move_of]
    a, b = before[move_of].astype(np.float64), pts[move_of].astype(np.float64)
    p = a + (b - a) * t[:, None]
    end = j == k[move_of]
    p[end] = pts[move_of[end]]
    t[end] = 1.0
    x_mm, y_mm = np.rint(p[:, 0]) * mx, np.rint(p[:, 1]) * my
    if not extrapolate:
        text = outside_text(height_map, x_mm, y_mm)
        if text is not None:
            raise PlanError(f"{text}: probe a larger area, or level with --level-extrapolate (the edge cells "
                            f"extended)")
    offset_steps = -(height_at(height_map, x_mm, y_mm) - height_map.reference_mm) / mz
    out = np.empty((total, 3), np.int64)
    out[:, :2] = np.rint(p[:, :2])
    out[:, 2] = np.rint(p[:, 2] + offset_steps)
    return Levelled(out, move_of, t)


def _split_periods(periods: np.ndarray, lv: Levelled) -> np.ndarray:
    """``(M,)`` the source moves' ``periods`` shared among their split moves (in proportion, summing to each)."""
    p = np.asarray(periods, np.int64)[lv.move_of].astype(np.float64)
    t_before = np.zeros(len(lv.t))
    t_before[1:] = lv.t[:-1]
    t_before[np.r_[True, lv.move_of[1:] != lv.move_of[:-1]]] = 0.0
    return (np.rint(p * lv.t) - np.rint(p * t_before)).astype(np.int64)


@dataclass
class LevelledJob:
    """A job levelled to a height map, made a piece at a time from the source job's pieces (a
    :class:`~cam.job.model.JobLike`; bounded memory: a piece and its split moves).

    Each piece's points are in steps from the job's home (the source's frame); ``home_steps`` places that home in
    the machine frame, where the map is.  A split move's parts carry its kind, nominal period and rest; its
    ``periods`` are shared among them; only its last part keeps its pause and its target (the source's
    points are what the input asks for) and only its first part starts a ramp segment (``move_start``).

    Attributes:
        source_job: the job to level; height_map: the surface; home_steps: ``(3,)`` the job's home, machine frame.
        extrapolate: level past the probed area's edges (see :func:`level_points`).
    """

    source_job: Any
    height_map: HeightMap
    home_steps: tuple[int, int, int]
    extrapolate: bool = False
    warnings: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        src = self.source_job
        self.settings: MachineSettings = src.settings
        self.source: str = src.source
        self.pixels = src.pixels
        self.tool = src.tool
        self.pause_notes = getattr(src, "pause_notes", None)
        self.warnings = list(getattr(src, "warnings", []) or []) + [w for w in self.warnings]
        # a stop lifts the tool to the safe plane above the highest probed point, not above the work zero's
        rise = max(0.0, float(self.height_map.offsets_mm().max()))
        self.safe_z_steps: int = int(src.safe_z_steps) - int(math.ceil(rise / self.settings.mm_per_step_z - 1e-9))

    def pieces(self) -> Iterator[Job]:
        """The levelled moves as consecutive :class:`Job` pieces, a source piece at a time."""
        home = np.asarray(self.home_steps, np.int64).reshape(3)
        prev = np.zeros(3, np.int64)  # the tool stands at the job's home before its first move
        for piece in self.source_job.pieces():
            pts = np.asarray(piece.points_steps, np.int64).reshape(-1, 3)
            if not len(pts):
                continue
            lv = level_points(pts + home, self.height_map, self.settings, start_steps=prev + home,
                              extrapolate=self.extrapolate)
            prev = pts[-1].copy()
            yield _levelled_piece(piece, lv, home, self.safe_z_steps)

    def joined(self) -> Job:
        """Every levelled move in one :class:`Job`."""
        return join_pieces(self.pieces(), self)


def _levelled_piece(piece: Job, lv: Levelled, home: np.ndarray, safe_z_steps: int) -> Job:
    m, end = lv.move_of, lv.is_end
    first = np.r_[True, m[1:] != m[:-1]]

    def per(values: Optional[np.ndarray], dtype: Any) -> Optional[np.ndarray]:
        return None if values is None else np.asarray(values, dtype)[m]

    move_start = np.asarray(piece.move_start, bool)[m] if piece.move_start is not None else np.ones(len(m), bool)
    return Job(points_steps=lv.points_steps - home, kind=np.asarray(piece.kind, np.uint8)[m],
               target=np.asarray(piece.target, bool)[m] & end, pause=np.asarray(piece.pause, bool)[m] & end,
               settings=piece.settings, pause_notes=piece.pause_notes, warnings=list(piece.warnings),
               safe_z_steps=safe_z_steps, pixels=piece.pixels, source=piece.source,
               period_ns=per(piece.period_ns, np.int64),
               periods=None if piece.periods is None else _split_periods(piece.periods, lv),
               move_start=move_start & first, rest=per(piece.rest, bool), tool=piece.tool)


def level_job(job: JobLike, height_map: HeightMap, home_steps: Any, *, extrapolate: bool = False) -> Any:
    """``job`` (a :class:`~cam.job.model.JobLike`, points in steps from its home) levelled to ``height_map`` with
    its home at machine ``home_steps``: a :class:`Job` for a job held in memory (its levelled pieces joined),
    else a :class:`LevelledJob` made a piece at a time."""
    home = tuple(int(v) for v in np.asarray(home_steps, np.int64).reshape(3))
    levelled = LevelledJob(job, height_map, home, extrapolate=extrapolate)  # type: ignore[arg-type]
    return levelled.joined() if isinstance(job, Job) else levelled
