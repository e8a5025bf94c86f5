"""Grey-level reliefs: a greyscale image read as a height map and cut with a real tool (issue #31 point 7).

``cam drill relief.png --heightmap --tool ball:1 --max-depth 2 --pixel-size 0.25``

* **Depth.** Each pixel's grey ``g`` (0 black .. 1 white, the luma of a
  colour image, 16-bit images at their full depth) asks for ``(1 - g) x
  max_depth_mm`` below the surface (black deepest), or ``g x max_depth_mm``
  with ``invert``, as LinuxCNC's ``image-to-gcode`` reads one.  The depth is
  taken in whole Z steps, rounded *up* toward the surface: the target the
  job cuts to is never below the depth asked.
* **Pixels.** A pixel is ``pixel_size_mm`` wide (default the machine's
  drawing pixel), rounded to whole X/Y steps (a warning names the size used
  when it differs).  Pixel ``(col, row)`` is centred ``col``, ``row`` pixels
  right of and toward the operator from where the tool stands when the job
  starts, as a drawing's.
* **No gouge.** Over each pixel centre the tip goes no deeper than the
  drop-cutter depth (:func:`cam.tool.drop_depth_px`: the least, over the
  pixels under the tool, of their depth plus the tool's rise there),
  worked out in bands of rows (memory bounded by the band, whatever the
  image's height).  Along a row the tool follows the drop-cutter depth at every X step
  (:func:`sub_drop_steps`), X and Z together, where the step planner's DDA
  keeps every position it passes through at or above it (:func:`_row_fine`),
  or, at pixel centres only, a staircase: every move between two pixel
  centres side by side changes X/Y or Z, never both, at a depth no deeper
  than both ends allow (going deeper it moves then plunges, going shallower
  it lifts then moves); a pixel centre is then nearest one end of every
  move, so no position along it cuts any pixel centre below its target.
  :func:`cam.kinds.drawing` plans both and keeps the one with the shorter
  machine time.
* **Order.** ``rows``: rows ``stepover`` x the tool's diameter apart (at
  least one pixel; every row for the point tool), the last row always cut,
  zig-zag along X, each row from its first to its last pixel with any
  depth; from one row to the next the tool goes along the row and down the
  column at the shallowest allowed depth on the way.  ``peel``: the
  thesis's order, the relief taken level by level, shallowest first
  (levels ``stepdown_mm`` apart, default an eighth of the depth), each
  level the same rows over the pixels it still has material at, cut no
  deeper than the level; the last level is the finished relief.

:func:`plan_heightmap` is the planner (a :class:`~cam.job.model.Job` in
machine steps with its :class:`~cam.job.model.PixelFrame`: ``steps_per_px_z``
is 1, depths are Z steps); the drawing kind (:mod:`cam.kinds.drawing`) makes the job of
:func:`cam.kinds.jobs.prepare_job` for ``JobOptions(heightmap=True)``.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ..digitize.drawing import read_image
from ..errors import CamError
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..tool import POINT, Tool, drop_depth_px, footprint_px, lowest_under_footprint, parse_tool, tool_of_settings
from .model import CUT, RETRACT, TRAVEL, Job, PixelFrame, check_span

__all__ = ["DEFAULT_MAX_DEPTH_MM", "BAND_ROWS", "grey_of_image", "load_heightmap", "depth_steps_of",
           "drop_surface_steps", "sub_drop_steps", "pixel_steps_of", "row_spacing_px", "plan_heightmap",
           ]

DEFAULT_MAX_DEPTH_MM = 1.0
"""The depth of the deepest grey when ``max_depth_mm`` is not given."""
BAND_ROWS = 128
"""Rows of the drop-cutter surface worked out at once (memory: a band and a tool's reach above and below it)."""
PEEL_LEVELS = 8
"""Levels of the peeling order when no ``stepdown_mm`` is given."""


def grey_of_image(img: np.ndarray, *, bgr: bool = False) -> np.ndarray:
    """``(H, W)`` float64 grey 0 (black) .. 1 (white) of a decoded image: grey, RGB(A) or BGR(A), uint8 or
    uint16 (a transparent pixel is white paper)."""
    a = np.asarray(img)
    top = 65535.0 if a.dtype == np.uint16 else 255.0
    if a.dtype == bool:
        a, top = np.where(a, 0.0, 1.0), 1.0
    a = a.astype(np.float64) / top
    if a.ndim == 2:
        return a
    colour = a[:, :, :3][:, :, ::-1] if bgr else a[:, :, :3]
    grey = colour @ np.array([0.299, 0.587, 0.114])
    if a.shape[2] == 4:
        grey = grey * a[:, :, 3] + (1.0 - a[:, :, 3])
    return np.clip(grey, 0.0, 1.0)


def load_heightmap(path: str | Path) -> np.ndarray:
    """The grey of an image file (PNG, BMP, JPEG, TIFF, GIF; size checked before decoding), ``(H, W)`` float64
    0 (black) .. 1 (white).

    Raises:
        CamError: unreadable, too large.
    """
    img, bgr = read_image(Path(path))  # the drawings' reader: the same formats and size checks
    return grey_of_image(img, bgr=bgr)


def depth_steps_of(grey: np.ndarray, max_depth_mm: float, settings: MachineSettings = DEFAULT_SETTINGS,
                   invert: bool = False) -> np.ndarray:
    """``(H, W)`` int64 depth asked at each pixel in whole Z steps below the surface: ``(1 - grey) x
    max_depth_mm`` (``grey x max_depth_mm`` inverted), rounded toward the surface (never below the depth asked).

    >>> depth_steps_of(np.array([[0.0, 0.5, 1.0]]), 1.57).tolist()
    [[100, 50, 0]]
    """
    g = np.asarray(grey, np.float64)
    d_mm = (g if invert else 1.0 - g) * float(max_depth_mm)
    return np.floor(d_mm / settings.mm_per_step_z + 1e-9).astype(np.int64).clip(0)


def pixel_steps_of(pixel_size_mm: Optional[float], settings: MachineSettings) -> tuple[int, list[str]]:
    """X/Y steps per height-map pixel for ``pixel_size_mm`` (None: the machine's drawing pixel), and a warning
    when the size had to be rounded to whole steps by more than 1 %."""
    if pixel_size_mm is None:
        return settings.steps_per_px_xy, []
    spp = max(1, int(round(pixel_size_mm / settings.mm_per_step_xy)))
    used = spp * settings.mm_per_step_xy
    if abs(used - pixel_size_mm) > 0.01 * pixel_size_mm:
        return spp, [f"--pixel-size {pixel_size_mm:g} mm is not a whole number of X/Y steps "
                     f"({settings.mm_per_step_xy:g} mm): pixels are {used:.4g} mm ({spp} steps)"]
    return spp, []


def drop_surface_steps(depth_steps: np.ndarray, tool: Tool, px_mm: float, settings: MachineSettings = DEFAULT_SETTINGS,
                       band_rows: int = BAND_ROWS) -> np.ndarray:
    """``(H, W)`` int64: the deepest the tool's tip may go (Z steps) with its axis over each pixel centre without
    cutting any pixel centre below ``depth_steps`` (:func:`cam.tool.drop_depth_px`), in bands of ``band_rows``
    rows with the tool's reach above and below each (the same result as all at once; outside the image is
    the surface)."""
    d = np.asarray(depth_steps, np.int64)
    if tool.is_point:
        return d.copy()
    reach = int(math.ceil(tool.radius_mm / px_mm)) + 1
    out = np.empty_like(d)
    h = d.shape[0]
    for r0 in range(0, h, band_rows):
        r1 = min(h, r0 + band_rows)
        a0, a1 = max(0, r0 - reach), min(h, r1 + reach)
        out[r0:r1] = drop_depth_px(d[a0:a1], tool, px_mm, settings.mm_per_step_z)[r0 - a0:r1 - a0]
    return out


def sub_drop_steps(depth_steps: np.ndarray, tool: Tool, px_mm: float, steps_per_px: int,
                   settings: MachineSettings = DEFAULT_SETTINGS, band_rows: int = BAND_ROWS) -> np.ndarray:
    """``(H, W, steps_per_px)`` int64: the drop-cutter depth (as :func:`drop_surface_steps`) with the tool's axis
    ``m`` X steps right of each pixel centre, ``m = 0 .. steps_per_px - 1`` (``m = 0``: the centre itself), in
    bands of rows."""
    d = np.asarray(depth_steps, np.int64)
    h, w = d.shape
    out = np.empty((h, w, steps_per_px), np.int64)
    if tool.is_point:
        out[:] = 0
        out[:, :, 0] = d
        return out
    feet = [footprint_px(tool, px_mm, settings.mm_per_step_z, centre=(m / steps_per_px, 0.0))
            for m in range(steps_per_px)]
    reach = int(math.ceil(tool.radius_mm / px_mm)) + 2
    for r0 in range(0, h, band_rows):
        r1 = min(h, r0 + band_rows)
        a0, a1 = max(0, r0 - reach), min(h, r1 + reach)
        for m, (dy, dx, rise) in enumerate(feet):
            low = lowest_under_footprint(d[a0:a1], dy, dx, rise, (a1 - a0, w), 0)[r0 - a0:r1 - a0]
            out[r0:r1, :, m] = np.maximum(low, 0)
    out[:, :, 0] = np.minimum(out[:, :, 0], d)
    return out


def _sub_along(sub_row: np.ndarray, xs: np.ndarray, steps_per_px: int) -> np.ndarray:
    """``(len(xs), steps_per_px)``: the drop-cutter depths of a row (``sub_row``, :func:`sub_drop_steps`) at X
    step ``m`` from each pixel of ``xs`` toward the next (``xs`` side by side, either way)."""
    if len(xs) < 2 or xs[1] > xs[0]:
        return sub_row[xs]
    n = steps_per_px
    out = np.empty((len(xs), n), np.int64)
    out[:, 0] = sub_row[xs, 0]
    left = np.maximum(xs - 1, 0)
    out[:, 1:] = sub_row[left][:, :0:-1]  # X = x - m / n = (x - 1) + (n - m) / n
    return out


def row_spacing_px(tool: Tool, px_mm: float, stepover: float) -> int:
    """Rows ``stepover`` x the tool's diameter apart in whole pixels (at least 1; 1 for the point tool)."""
    if tool.is_point:
        return 1
    return max(1, int(math.floor(stepover * tool.diameter_mm / px_mm + 1e-9)))


def _rows(h: int, spacing: int) -> list[int]:
    rows = list(range(0, h, spacing))
    if rows[-1] != h - 1:
        rows.append(h - 1)
    return rows


class _Path:
    """Points (x, y in X/Y steps, z in Z steps) and their kinds, appended a move at a time."""

    def __init__(self, steps_per_px: int) -> None:
        self.spp = steps_per_px
        self.pts: list[np.ndarray] = [np.zeros((0, 3), np.int64)]
        self.kind: list[np.ndarray] = [np.zeros(0, np.uint8)]
        self.target: list[np.ndarray] = [np.zeros(0, bool)]
        self.at = np.zeros(3, np.int64)

    def add(self, pts_steps: Any, kind: int, target: Any = False) -> None:
        pts = np.asarray(pts_steps, np.int64).reshape(-1, 3)
        if len(pts) and np.array_equal(pts[0], self.at):
            pts = pts[1:]
            target = np.asarray(target, bool)[1:] if np.ndim(target) else target
        if not len(pts):
            return
        self.pts.append(pts)
        self.kind.append(np.full(len(pts), kind, np.uint8))
        self.target.append(np.broadcast_to(np.asarray(target, bool), (len(pts),)).copy())
        self.at = pts[-1].copy()

    def go(self, x: int, y: int, z_cap: int, allowed: np.ndarray) -> None:
        """From the pixel centre where the tool is to pixel (x, y)'s centre, along its row then down the column,
        at the shallowest depth allowed on the way (never deeper than where it is nor than ``z_cap``)."""
        s = self.spp
        x0, y0, z0 = int(self.at[0]) // s, int(self.at[1]) // s, int(self.at[2])
        xs = allowed[y0, min(x0, x):max(x0, x) + 1]
        ys = allowed[min(y0, y):max(y0, y) + 1, x]
        z = int(max(0, min(z0, int(xs.min()), int(ys.min()), z_cap)))
        self.add([(x0 * s, y0 * s, z)], RETRACT)
        self.add([(x * s, y0 * s, z)], TRAVEL)
        self.add([(x * s, y * s, z)], TRAVEL)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return np.vstack(self.pts), np.concatenate(self.kind), np.concatenate(self.target)


def _row_fine(y_steps: int, x0_steps: int, way: int, sub_t: np.ndarray, steps_per_px: int
              ) -> tuple[np.ndarray, np.ndarray]:
    """The path along a row at every X step: ``sub_t[t]`` is the drop-cutter depth ``t`` X steps from the
    first pixel centre ``x0_steps`` the way ``way`` (+1 or -1).

    A move of one X step going deeper passes through its start's X at depths down to one step above its
    end (the step planner's DDA steps X in its last period), so it goes to at most one step below the
    depth allowed where it starts, and the rest is a plunge at its end.  Going up, a move stays at or
    above both ends.  Runs of equal moves are joined (the DDA passes the same positions).  Returns the
    points ``(K, 3)`` in steps (the first included) and whether each is at a pixel centre's own depth.
    """
    d = np.asarray(sub_t, np.int64)
    t = np.arange(len(d))
    arrive = np.r_[d[0], np.minimum(d[1:], d[:-1] + 1)]
    extra = d > arrive
    n = len(d) + int(np.count_nonzero(extra))
    pos = np.arange(len(d)) + np.r_[0, np.cumsum(extra)[:-1]]
    x = np.empty(n, np.int64)
    z = np.empty(n, np.int64)
    tgt = np.zeros(n, bool)
    x[pos], z[pos] = t, arrive
    x[pos[extra] + 1], z[pos[extra] + 1] = t[extra], d[extra]
    centre = t % steps_per_px == 0
    tgt[pos[centre & ~extra]] = True
    tgt[pos[centre & extra] + 1] = True
    pts = np.column_stack([x0_steps + way * x, np.full(n, y_steps, np.int64), z])
    if len(pts) > 2:  # a point between two equal moves is dropped (a run of equal moves is one)
        v = np.diff(pts, axis=0)
        keep = np.r_[True, np.any(v[1:] != v[:-1], axis=1), True]
        pts, tgt = pts[keep], tgt[keep]
    return pts, tgt


def _row_points(y: int, xs: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The staircase through pixels ``xs`` (side by side, in cutting order) of row ``y`` at depths ``z``:
    going deeper, move then plunge; going shallower, lift then move.  Points ``(K, 3)`` in pixels (Z in
    steps) and whether each is at a pixel's own depth; runs at one depth are one move."""
    n = len(xs)
    nxt_z = np.r_[z[1:], z[-1]]
    deeper = nxt_z > z
    # between pixel k and k + 1: (x_{k+1}, z_k) going deeper, (x_k, z_{k+1}) going shallower
    mid_x = np.where(deeper, np.r_[xs[1:], xs[-1]], xs)
    mid_z = np.where(deeper, z, nxt_z)
    px = np.empty(2 * n, np.int64)
    pz = np.empty(2 * n, np.int64)
    px[0::2], pz[0::2] = xs, z
    px[1::2], pz[1::2] = mid_x, mid_z
    tgt = np.zeros(2 * n, bool)
    tgt[0::2] = True
    pts = np.column_stack([px, np.full(2 * n, y, np.int64), pz])
    keep = np.ones(2 * n, bool)
    keep[1:] = np.any(pts[1:] != pts[:-1], axis=1)
    pts, tgt = pts[keep], tgt[keep] | np.r_[False, tgt[1:]][keep]
    if len(pts) > 2:  # a point inside a straight run (same z or same x on both sides, going on) adds nothing
        a, b, c = pts[:-2], pts[1:-1], pts[2:]
        inner = (((a[:, 2] == b[:, 2]) & (b[:, 2] == c[:, 2]) & ((b[:, 0] - a[:, 0]) * (c[:, 0] - b[:, 0]) > 0))
                 | ((a[:, 0] == b[:, 0]) & (b[:, 0] == c[:, 0]) & ((b[:, 2] - a[:, 2]) * (c[:, 2] - b[:, 2]) > 0)))
        keep = np.r_[True, ~inner, True]
        pts, tgt = pts[keep], tgt[keep]
    return pts, tgt


def plan_heightmap(
    depth_steps: np.ndarray, *, tool: Tool | str | None = None, settings: MachineSettings = DEFAULT_SETTINGS,
    pixel_size_mm: Optional[float] = None, stepover: float = 0.5, heightmap_order: str = "rows",
    stepdown_mm: Optional[float] = None, slopes: bool = True, source: str = "<heightmap>",
) -> Job:
    """The job that cuts the relief ``depth_steps`` with ``tool`` (see the module docstring).

    Args:
        depth_steps: ``(H, W)`` int depth asked at each pixel centre, Z steps below the surface
            (:func:`depth_steps_of`).
        tool: the cutter (a :class:`~cam.tool.Tool` or a spec, None: the point tool).
        pixel_size_mm: a pixel's width (None: the machine's drawing pixel), rounded to whole steps.
        stepover: rows' spacing as a fraction of the tool's diameter (at least one pixel).
        heightmap_order: ``"rows"`` or ``"peel"`` (level by level, shallowest first).
        stepdown_mm: the levels' spacing of ``peel`` (None: an eighth of the deepest depth).
        slopes: follow the drop-cutter depth at every X step along the rows, moving X and Z together
            (:func:`_row_fine`); False: pixel centres only, in a staircase (as the point tool always is).

    Returns:
        A :class:`~cam.job.model.Job` from and back to where the tool stands, with its pixel frame.

    Raises:
        CamError: a bad order; TravelError: the relief is wider (or deeper) than the machine travel (it is
        planned in its own frame: where it runs is checked when it is placed).
    """
    d = np.asarray(depth_steps, np.int64)
    if d.ndim != 2 or not d.size:
        raise CamError(f"{source}: a height map must be a non-empty 2-D array")
    if heightmap_order not in ("rows", "peel"):
        raise CamError(f"{source}: heightmap order must be 'rows' or 'peel', got {heightmap_order!r}")
    cutter = parse_tool(tool) if tool is not None else POINT
    spp, warnings = pixel_steps_of(pixel_size_mm, settings)
    px_mm = spp * settings.mm_per_step_xy
    h, w = d.shape
    frame = PixelFrame(w, h, (0, 0, 0), spp, 1)  # depths are Z steps: one step per Z unit of the frame
    # planned in its own frame, placed at the work zero when it runs (checked there): it must fit the travel's span
    check_span(np.array([[0, 0, 0], [(w - 1) * spp, (h - 1) * spp, int(d.max(initial=0))]]), settings, frame)
    allowed = drop_surface_steps(d, cutter, px_mm, settings)
    sub = sub_drop_steps(d, cutter, px_mm, spp, settings) if slopes and not cutter.is_point else None
    rows = _rows(h, row_spacing_px(cutter, px_mm, stepover))
    deepest = int(allowed.max(initial=0))
    if heightmap_order == "peel" and deepest > 0:
        step = (max(1, int(round(stepdown_mm / settings.mm_per_step_z))) if stepdown_mm
                else max(1, math.ceil(deepest / PEEL_LEVELS)))
        levels = list(range(step, deepest, step)) + [deepest]
    else:
        levels = [deepest]
    path = _Path(spp)
    flip = False
    previous = 0
    for level in levels:
        cap = np.minimum(allowed, level)
        for y in rows:
            # the pixels of this row with material left above this level
            todo = np.flatnonzero(cap[y] > previous) if level != levels[0] else np.flatnonzero(cap[y] > 0)
            if not len(todo):
                continue
            xs = np.arange(todo[0], todo[-1] + 1)
            if flip:
                xs = xs[::-1]
            flip = not flip
            z = cap[y, xs]
            path.go(int(xs[0]), y, int(z[0]), allowed)
            if sub is None or len(xs) < 2:
                pts, tgt = _row_points(y, xs, z)
                path.add(pts * np.array([spp, spp, 1]), CUT, tgt)
            else:
                along = np.minimum(_sub_along(sub[y], xs, spp).reshape(-1)[:(len(xs) - 1) * spp + 1], level)
                pts, tgt = _row_fine(y * spp, int(xs[0]) * spp, 1 if xs[-1] > xs[0] else -1, along, spp)
                path.add(pts, CUT, tgt)
        previous = level
    if path.at[2]:  # lift where it stands, then home at the surface
        path.add([(path.at[0], path.at[1], 0)], RETRACT)
    path.add([(0, 0, 0)], TRAVEL)
    pts_steps, kind, tgt = path.arrays()
    rest = d - allowed
    if cutter.is_point:
        pass
    elif rest.max(initial=0) > 0:
        warnings.append(f"{source}: the {cutter.describe()} cannot reach every hollow of the relief: over pixel "
                        f"centres it leaves up to {rest.max() * settings.mm_per_step_z:.3f} mm")
    n = len(pts_steps)
    return Job(points_steps=pts_steps, kind=kind, target=tgt, pause=np.zeros(n, bool), settings=settings,
               warnings=warnings, safe_z_steps=0, pixels=frame, source=source, tool=None if cutter.is_point else cutter)


