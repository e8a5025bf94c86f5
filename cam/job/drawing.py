"""Stage 3, the drawing planner: a digitized matrix to a job (thesis 4.1.4.5, 4.2.3, B.2).

This module holds the planner's options, maps and rules of the moves; the planner itself makes the job a
piece at a time (:func:`cam.job.drawing_stream.stream_drawing`), and :func:`plan` is its pieces joined: one
path for every size of job.

The planner works in drawing pixels: ``x`` = image column and ``y`` = image
row, plus the Start At offset; ``z`` = depth below the home plane in Z pixels
(+Z is deeper into the material, 0 is the surface when Start At Z is 0).  The
tool starts at (0, 0, 0).  Every move changes either X/Y or Z, never both, so a
point tool's cut can be read off exactly.  The result is a
:class:`~cam.job.model.Job` in machine steps, whose
:class:`~cam.job.model.PixelFrame` says where the pixels lie.

Rules the planner keeps (and tests check):

* points are cut sorted by depth, shallowest first; the sort is stable, so
  within a depth the traced order is kept;
* a move between non-adjacent pixels (Chebyshev distance > 1) first rises to
  the surface, travels there, and plunges at the next point;
* Z never goes below the depth asked for at the pixel the tool is over:
  going deeper, move then plunge; going shallower, lift then move;
* the job ends at (0, 0, 0); it is planned in its own frame, and a job wider
  than the machine travel on some axis is refused when it is planned, naming
  the point that makes it too wide; placed (at the work zero, or where the tool
  stands), a job with any point outside the travel is refused before the first
  step (issue #45 point 4).
"""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from ..arrays import column_range
from ..digitize.digitized import Digitized
from ..errors import PlanError, TravelError
from ..digitize.profile import ProfileLike, as_profile
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ._route import bfs_kernel
from ..digitize.trace2d import trace_curves
from ..tool import Tool, corner_depth_px, drop_depth_px, reach_depth_px
from .model import CUT, RETRACT, TRAVEL, Job

__all__ = ["check_drawing_size", "max_drawing_size_px"]


def max_drawing_size_px(settings: MachineSettings) -> tuple[int, int]:
    """``(width, height)`` of the largest drawing whose pixels fit the machine's X and Y travel at
    ``settings.steps_per_px_xy`` (pixel k lies k x steps per pixel from pixel 0): 1251 x 1251 for the thesis
    machine (10000 steps of travel, 8 steps per pixel)."""
    (x_lo, x_hi), (y_lo, y_hi), _ = settings.travel.bounds_steps()
    spp = settings.steps_per_px_xy
    return (x_hi - x_lo) // spp + 1, (y_hi - y_lo) // spp + 1


def check_drawing_size(width_px: int, height_px: int, settings: MachineSettings, source: str = "<drawing>") -> None:
    """Refuse a drawing larger than the machine's travel holds (:func:`max_drawing_size_px`), wherever it is
    placed; :func:`cam.kinds.jobs.prepare_job` checks it from the file's header, before decoding and tracing.

    Raises:
        TravelError: naming the drawing, its size, the steps per pixel, the travel and the largest size.
    """
    max_w, max_h = max_drawing_size_px(settings)
    if width_px > max_w or height_px > max_h:
        (x_lo, x_hi), (y_lo, y_hi), _ = settings.travel.bounds_steps()
        raise TravelError(f"{source}: the drawing is {width_px}x{height_px} px; at {settings.steps_per_px_xy} steps "
                          f"per pixel the machine travel (X {x_lo}..{x_hi}, Y {y_lo}..{y_hi} steps) holds at most "
                          f"{max_w}x{max_h} px")


def _depths_per_object(depth: int | Sequence[int], n_objects: int) -> tuple[np.ndarray, list[str]]:
    warnings: list[str] = []
    if np.isscalar(depth):
        values = np.full(n_objects, int(depth), np.int64)  # type: ignore[arg-type]
    else:
        values = np.asarray(list(depth), np.int64)  # type: ignore[arg-type]
        if len(values) < n_objects:
            raise PlanError(
                f"{len(values)} depth value(s) given for {n_objects} objects: give one depth per object"
            )
        if len(values) > n_objects:
            warnings.append(f"{len(values)} depth values given for {n_objects} objects; the extra ones are unused")
            values = values[:n_objects]
    return values, warnings


def _pass_order(depth_px: np.ndarray, passes: int) -> list[tuple[int, int]]:
    """``(object index, depth in Z pixels)`` of every block of cut targets, in cutting order.

    Pass k of an object cuts at ceil(d x k / passes) (a pass that goes no deeper, or depth 0, is skipped);
    blocks are sorted by depth, shallowest first, stably, so within a depth pass and object order are kept.
    """
    blocks = []
    for k in range(1, passes + 1):
        for i, d in enumerate(depth_px.tolist()):
            d_k = (int(d) * k + passes - 1) // passes  # ceil(d * k / passes)
            d_prev = (int(d) * (k - 1) + passes - 1) // passes
            if d_k == 0 or (k > 1 and d_k == d_prev):
                continue  # depth 0 skips the object; a pass that goes no deeper is skipped
            blocks.append((i, d_k))
    blocks.sort(key=lambda b: b[1])  # stable
    return blocks


def _pass_targets(digitized: Digitized, depth_px: np.ndarray, passes: int) -> np.ndarray:
    """All ``(M, 3)`` (x, y, z) cut targets in cutting order (see :func:`_pass_order`)."""
    chunks = []
    for i, d in _pass_order(depth_px, passes):
        block = np.empty((len(digitized.objects[i]), 3), np.int64)
        block[:, :2] = digitized.objects[i]
        block[:, 2] = d
        chunks.append(block)
    return np.concatenate(chunks) if chunks else np.zeros((0, 3), np.int64)


def _object_depths(digitized: Digitized, depth: int | Sequence[int] | None, profile: ProfileLike | None,
                   passes: int) -> tuple[np.ndarray, list[str]]:
    """``(depth per object (n_objects,) in Z pixels, warnings)`` from :func:`plan`'s ``depth``/``profile`` options.

    Raises:
        PlanError: bad options (see :func:`plan`; their ranges are checked there, :func:`cam.options.keyword_error`).
    """
    n_obj = len(digitized.objects)
    if n_obj == 0:
        raise PlanError("nothing to cut: the digitized drawing has no objects")
    if digitized.mode == "3d":  # (not both a depth and a profile: a rule of cam.options, asked by plan)
        if profile is None and depth is None:
            raise PlanError("this is a 3D drawing (red interior): give --depth N for a flat-bottomed pocket N Z "
                            "pixels deep, or a profile for its layer depths (--profile FILE, --profile-expr EXPR)")
        if profile is None:
            uniform = np.atleast_1d(np.asarray(depth, np.int64))
            if uniform.size != 1:
                raise PlanError(f"a 3D drawing takes one --depth for every layer (a flat-bottomed pocket), got "
                                f"{uniform.size} values; use a profile for a depth per layer")
            depth_px, warnings = np.full(len(digitized.levels), int(uniform[0]), np.int64), []
        else:
            prof = as_profile(profile, digitized.n_layers)
            depth_px, warnings = prof.depth_of(digitized.levels).astype(np.int64), list(prof.warnings)
    else:
        if profile is not None:
            raise PlanError("a profile applies to 3D drawings only; this drawing is 2D (use --depth)")
        depth_px, warnings = _depths_per_object(10 if depth is None else depth, n_obj)
    return depth_px, warnings


def _roughing_targets(asked: np.ndarray, rough: Tool, stepdown_px: int, stepover: float, settings: MachineSettings
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Tool]:
    """The roughing levels before the finishing pass: ``(targets (M, 3) in cutting order, allowed (H, W),
    corners (H + 1, W + 1), tool)``.

    Level i clears, down to ``i x stepdown_px``, every pixel where the roughing tool may go deeper than the
    level above (:func:`cam.tool.drop_depth_px` over the deepest depth asked at each pixel): its tool centres
    run on rings ``stepover x diameter`` apart inward from the edge of that region, plus any pixel no ring
    comes within the tool's radius of; each ring is traced into curves (the 2D tracer), shallowest level first.
    ``asked``: ``(H, W)`` int64 deepest depth asked at each pixel (Z pixels, drawing frame).
    """
    px_mm, zpx_mm = settings.px_to_mm_xy(1), settings.px_to_mm_z(1)
    allowed = drop_depth_px(asked, rough, px_mm, zpx_mm)
    corners = corner_depth_px(asked, rough, px_mm, zpx_mm) if not rough.is_point else allowed
    spacing_px = max(1, int(stepover * rough.diameter_mm / px_mm))
    radius_px = max(0, int(rough.radius_mm / px_mm))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_px + 1, 2 * radius_px + 1))
    chunks = []
    top = int(allowed.max(initial=0))
    for level in range(stepdown_px, top, stepdown_px):  # the finishing pass takes the last level
        region = allowed > level - stepdown_px
        dist = cv2.distanceTransform(np.pad(region, 1).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        dist = dist[1:-1, 1:-1]
        centres = region & (np.mod(np.rint(dist).astype(np.int64) - 1, spacing_px) == 0)
        covered = cv2.dilate(centres.astype(np.uint8), disc).astype(bool)
        centres |= region & ~covered
        for curve in trace_curves(centres):
            block = np.empty((len(curve), 3), np.int64)
            block[:, :2] = curve
            block[:, 2] = np.minimum(allowed[curve[:, 1], curve[:, 0]], level)
            chunks.append(block)
    empty = np.zeros((0, 3), np.int64)
    return (np.concatenate(chunks) if chunks else empty), allowed, corners, rough


def _pause_map(digitized: Digitized, pause_at: Sequence[tuple[int, int]], shape: tuple[int, int]
               ) -> tuple[np.ndarray, list[str]]:
    """``(pause_px (shape) bool, warnings)``: the Pause At points that are points of the drawing (drawing
    frame), and a warning for each that is not."""
    pause_px = np.zeros(shape, bool)
    notes = []
    if len(pause_at):
        drawn = np.zeros(shape, bool)
        for obj in digitized.objects:
            drawn[obj[:, 1], obj[:, 0]] = True
        for x, y in pause_at:
            if 0 <= int(y) < shape[0] and 0 <= int(x) < shape[1] and drawn[int(y), int(x)]:
                pause_px[int(y), int(x)] = True
            else:
                notes.append(f"Pause At ({x}, {y}) is not a point of the drawing; it has no effect")
    return pause_px, notes


def _drop_maps(asked: np.ndarray, cutter: Tool, settings: MachineSettings
               ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """For the deepest depth asked at each pixel ``asked`` (H, W) (Z pixels, drawing frame): the drop-cutter
    depth of ``cutter`` at each pixel (H, W) (:func:`cam.tool.drop_depth_px`), at each pixel corner
    (H + 1, W + 1) (:func:`cam.tool.corner_depth_px`) and a warning about the material the tool cannot reach
    (none if it reaches all)."""
    px_mm, zpx_mm = settings.px_to_mm_xy(1), settings.px_to_mm_z(1)
    allowed = drop_depth_px(asked, cutter, px_mm, zpx_mm)
    rest = asked - reach_depth_px(allowed, cutter, px_mm, zpx_mm)
    short = np.count_nonzero(rest >= 1)
    note = []
    if short:
        note.append(f"the {cutter.describe()} tool cannot reach the full depth of {short} of "
                    f"{np.count_nonzero(asked)} pixels (up to {settings.px_to_mm_z(float(rest.max())):.3f} mm left; "
                    f"a smaller tool reaches more)")
    return allowed, corner_depth_px(asked, cutter, px_mm, zpx_mm), note


def _guard_diagonals(pts: np.ndarray, kind: np.ndarray, tgt: np.ndarray, pause: np.ndarray, corners: np.ndarray,
                     oz: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Lift every diagonal move inside the material that is deeper than its midpoint allows (``corners``,
    :func:`cam.tool.corner_depth_px`, drawing frame) to that depth: rise at its start, move, sink at its end."""
    if len(pts) < 2:
        return pts, kind, tgt, pause
    step = np.diff(pts, axis=0)
    depth = pts[1:, 2] - oz
    cy = np.clip(np.maximum(pts[:-1, 1], pts[1:, 1]), 0, corners.shape[0] - 1)
    cx = np.clip(np.maximum(pts[:-1, 0], pts[1:, 0]), 0, corners.shape[1] - 1)
    allowed = corners[cy, cx]
    bad = np.flatnonzero((np.abs(step[:, 0]) == 1) & (np.abs(step[:, 1]) == 1) & (step[:, 2] == 0)
                         & (depth > 0) & (depth > allowed))
    if len(bad) == 0:
        return pts, kind, tgt, pause
    lifted = np.maximum(allowed[bad], 0) + oz
    rise = pts[bad].copy()
    rise[:, 2] = lifted
    over = pts[bad + 1].copy()
    over[:, 2] = lifted
    at = np.repeat(bad + 1, 2)
    new = np.empty((2 * len(bad), 3), pts.dtype)
    new[0::2], new[1::2] = rise, over
    return (np.insert(pts, at, new, axis=0), np.insert(kind, at, CUT), np.insert(tgt, at, False),
            np.insert(pause, at, False))


def _fits_travel(targets: np.ndarray, offset_px: tuple[int, int], safe: int, settings: MachineSettings) -> bool:
    """Whether the job fits the machine wherever it is placed, from its extent alone: the box of the targets
    ``(M, 3)`` (drawing frame, Start At Z included) moved by ``offset_px``, the home (0, 0, 0) and the safe plane
    ``safe`` (Z pixels) is no wider than the travel on each axis (:class:`cam.job.model.TravelSpan`).  A drawing
    job is planned in its own frame: where it goes is checked in the machine frame when it is placed (at the
    work zero, or from where the tool stands; issue #45 point 4).

    Bridges run through targets' pixels, lifts and travels at the surface or the safe plane, so no point of
    the job lies outside this box, and its corners' coordinates are all taken by points of the job.
    """
    least, most = column_range(targets)
    lo_px = np.minimum(least + np.array([*offset_px, 0]), [0, 0, safe])
    hi_px = np.maximum(most + np.array([*offset_px, 0]), 0)
    scale = np.array([settings.steps_per_px_xy, settings.steps_per_px_xy, settings.steps_per_px_z], np.int64)
    bounds = np.array(settings.travel.bounds_steps(), np.int64)
    return bool(np.all((hi_px - lo_px) * scale <= bounds[:, 1] - bounds[:, 0]))


def _gap_block(
    cur: tuple[int, int, int], nxt: tuple[int, int, int], on_drawing: bool, asked: np.ndarray,
    settings: MachineSettings, surface: int, safe: int, oz: int, route: bool = True, partial_lift: bool = False,
) -> list[tuple[int, int, int, int]]:
    """Points (x, y, z, kind) from ``cur`` to just before target ``nxt`` across a gap (non-adjacent pixels).

    Inside the material, a route through pixels asked at least this deep is taken when it is quicker
    than lifting, travelling and plunging (and ``route`` allows it); otherwise the tool lifts to the surface
    (the safe plane before the first target), travels, and the caller plunges.  With ``partial_lift`` (the
    finer pass of a real tool, whose material is all but cut) it lifts only as far as the straight staircase
    of pixels side by side between the two needs (the shallowest depth asked along it), if that is below the
    surface, moves along it and the caller plunges.
    """
    cx, cy, cz = cur
    x, y, d = nxt
    out: list[tuple[int, int, int, int]] = []
    bridge = on_drawing and route  # may go through the material
    if bridge:
        cheb = max(abs(x - cx), abs(y - cy))
        xy_period = settings.steps_per_px_xy * settings.delay_xy_ns
        z_period = settings.steps_per_px_z * settings.delay_z_ns
        z = min(cz, d)
        retract_ns = (cz - surface) * z_period + cheb * xy_period + (d - surface) * z_period
        budget_px = min(cheb + 256, (retract_ns - (cz - z) * z_period - (d - z) * z_period) // xy_period)
        route = _route(asked, (cx, cy), (x, y), z - oz, int(budget_px))
        if route is not None:
            if d < cz:
                out.append((cx, cy, d, CUT))
                cz = d
            out.extend((rx, ry, cz, CUT) for rx, ry in route)
            return out
    if bridge and partial_lift:
        cheb = max(abs(x - cx), abs(y - cy))
        steps = np.arange(1, cheb + 1)
        line_x = cx + np.rint(steps * (x - cx) / cheb).astype(np.int64)
        line_y = cy + np.rint(steps * (y - cy) / cheb).astype(np.int64)
        z = min(cz, d, int(asked[line_y, line_x].min()) + oz, int(asked[cy, cx]) + oz)
        if z > surface:
            if z != cz:
                out.append((cx, cy, z, CUT))
            out.extend((int(rx), int(ry), z, CUT) for rx, ry in zip(line_x.tolist(), line_y.tolist()))
            return out
    lift_z = surface if on_drawing else min(cz, safe)
    if cz != lift_z:
        out.append((cx, cy, lift_z, RETRACT))
    if (cx, cy) != (x, y):
        out.append((x, y, lift_z, TRAVEL))
    return out


def _assemble(
    targets: np.ndarray, pause_px: np.ndarray, asked: np.ndarray, settings: MachineSettings,
    surface: int, safe: int, oz: int, home: tuple[int, int] = (0, 0), route: bool = True,
    after: np.ndarray | None = None, last: bool = True, partial_lift: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The planner's rules, vectorised: adjacent moves in bulk, only gaps in Python (tests compare it with a plain loop).

    ``targets``, ``pause_px`` and ``asked`` share one pixel frame; ``home`` is where the job starts and ends
    in that frame; ``route``: bridge gaps inside the material (False: every gap lifts).  A piece of a longer
    job: ``after`` is the target ``(3,)`` cut just before ``targets[0]`` (the moves go on from it), and
    ``last=False`` leaves out the way home; pieces made so, one after the other, equal the whole job.
    Returns ``(points (N, 3), kind (N,), target (N,), pause (N,))``.
    """
    if after is not None:  # every move depends on its two targets only: plan from the one before, drop its rows
        targets = np.vstack([np.asarray(after, np.int64).reshape(1, 3), targets])
    hx, hy = home
    m = len(targets)
    x, y, d = targets[:, 0], targets[:, 1], targets[:, 2]
    cheb = np.zeros(m, np.int64)
    cheb[1:] = np.maximum(np.abs(np.diff(x)), np.abs(np.diff(y)))
    simple = np.zeros(m, bool)
    simple[1:] = cheb[1:] <= 1
    d_prev = np.concatenate([[0], d[:-1]])
    deeper = d >= d_prev
    # slot A: the move before the plunge (deeper) or the lift before the move (shallower); slot B: the target
    a_valid = simple & np.where(deeper, (cheb > 0) & (d > d_prev), cheb > 0)
    b_valid = ~(simple & (cheb == 0) & (d == d_prev))
    gaps = np.flatnonzero(~simple)
    blocks = {}
    extra = np.zeros(m, np.int64)
    for i in gaps.tolist():
        prev = (int(x[i - 1]), int(y[i - 1]), int(d[i - 1])) if i else (hx, hy, 0)
        here = (int(x[i]), int(y[i]), int(d[i]))
        blk = _gap_block(prev, here, i > 0, asked, settings, surface, safe, oz, route, partial_lift)
        if blk and blk[-1][:3] == here:
            blk.pop()  # a route that ends at the target's depth: the target is that point
        blocks[i] = blk
        extra[i] = len(blk)
    counts = a_valid.astype(np.int64) + b_valid + extra
    cx, cy = int(x[-1]), int(y[-1])
    tail = [(cx, cy, safe, RETRACT)] if last else []
    if last and (hx, hy) != (cx, cy):
        tail.append((hx, hy, safe, TRAVEL))
    if last and safe != 0:
        tail.append((hx, hy, 0, TRAVEL))
    start = np.concatenate([[0], np.cumsum(counts)])
    n = int(start[-1]) + len(tail)
    pts = np.empty((n, 3), np.int64)
    kind = np.full(n, CUT, np.uint8)
    tgt = np.zeros(n, bool)
    pause = np.zeros(n, bool)
    # simple transitions, in bulk
    ia = np.flatnonzero(a_valid)
    pos_a = start[ia]
    pts[pos_a, 0] = np.where(deeper[ia], x[ia], x[ia - 1])
    pts[pos_a, 1] = np.where(deeper[ia], y[ia], y[ia - 1])
    pts[pos_a, 2] = np.where(deeper[ia], d_prev[ia], d[ia])
    ib = np.flatnonzero(b_valid)
    pos_b = start[ib] + a_valid[ib] + extra[ib]
    for k in range(3):  # a column at a time: a gather of whole (3,) rows runs about 1.6x slower
        pts[pos_b, k] = targets[ib, k]
    tgt[pos_b] = True
    # gap blocks
    for i, blk in blocks.items():
        for j, (px, py, pz, k) in enumerate(blk):
            pts[start[i] + j] = (px, py, pz)
            kind[start[i] + j] = k
    # pauses: on the target's own point, or the point it merged into
    where = np.empty(m, np.int64)
    where[ib] = pos_b
    merged = np.flatnonzero(~b_valid)
    if len(merged):
        carry = np.where(b_valid, np.arange(m), -1)
        carry = np.maximum.accumulate(carry)
        where[merged] = where[carry[merged]]
        tgt[where[merged]] = True
    flagged = pause_px[y, x]
    pause[where[flagged]] = True
    for j, (px, py, pz, k) in enumerate(tail):
        pts[start[-1] + j] = (px, py, pz)
        kind[start[-1] + j] = k
    if after is not None:
        first = int(start[1])
        return pts[first:], kind[first:], tgt[first:], pause[first:]
    return pts, kind, tgt, pause


def route_window(asked: np.ndarray, start: tuple[int, int], goal: tuple[int, int], z: int,
                 max_len: int) -> tuple[int, int, np.ndarray]:
    """Where a bridge of at most ``max_len`` moves from ``start`` to ``goal`` (x, y pixels) can run:
    ``(x0, y0, ok)``, the window's top-left pixel and its ``(h, w)`` bool mask of pixels asked at least ``z`` deep."""
    h, w = asked.shape
    (sx, sy), (gx, gy) = start, goal
    x0, x1 = max(0, min(sx, gx) - max_len), min(w - 1, max(sx, gx) + max_len)
    y0, y1 = max(0, min(sy, gy) - max_len), min(h - 1, max(sy, gy) + max_len)
    return x0, y0, asked[y0 : y1 + 1, x0 : x1 + 1] >= z


def _route(
    asked: np.ndarray, start: tuple[int, int], goal: tuple[int, int], z: int, max_len: int
) -> list[tuple[int, int]] | None:
    """Shortest 8-connected path from ``start`` to ``goal`` over pixels with ``asked >= z``.

    Returns the pixels after ``start`` up to and including ``goal``, or None
    when there is no such path of at most ``max_len`` moves.  The search is breadth-first in a fixed
    neighbour order (:func:`cam.job._route.bfs_kernel`), within ``max_len`` of the two points.
    """
    if max_len < 2:
        return None
    x0, y0, ok = route_window(asked, start, goal, z, max_len)
    ww = ok.shape[1]
    sx, sy = start
    gx, gy = goal
    parent = np.full(ok.size, -2, np.int32)
    goal_i = (gy - y0) * ww + (gx - x0)
    if not bfs_kernel(ok, (sy - y0) * ww + (sx - x0), goal_i, max_len, parent):
        return None
    path = []
    j = goal_i
    while parent[j] != -1:
        path.append(int(j))
        j = parent[j]
    return [(x0 + k % ww, y0 + k // ww) for k in reversed(path)]
