"""G-code out: RS-274/NGC for grbl and LinuxCNC from any `cam` toolpath.

Frames and units (also written into every file's header):

* millimetres (G21), absolute (G90), XY plane (G17), feed per minute (G94);
* X = column x steps/pixel x mm/step (Eq. 4.1), so the drawing's left edge is X = 0;
* image rows grow downward but machine Y grows upward, so by default
  Y = -(row x steps/pixel x mm/step): the drawing appears upright with its top
  edge at Y = 0.  ``flip_y=True`` writes Y = +row instead (a mirror image);
* Z = -(depth x steps/pixel Z x mm/step Z) (Eq. 4.2): Z = 0 is the material
  surface, cuts are below it, moves above the surface are G0 at the safe height.

Cutting moves are G1 with the feed the configured delays give (mm/step /
delay); X/Y moves use the X/Y rate, Z moves the Z rate.  A move in the
material that changes X/Y and Z together (a job levelled to a height map,
``--level``) is one straight ``G1 X Y Z``, as the machine cuts it.

A job levelled to a height map (``level``: the map and where the job's home was placed, issue #46 point 2) is
written move for move as the machine runs it: every point of the job in order, each move split where the job's
are (at the map's spacing) and at its levelled Z.  A travel is ``G0 X Y Z`` at the travel height above the
surface *under it* (the travel height's Z steps offset by the map there, rounded to whole steps as the job's own
points are), not at one fixed height; a cut from the travel height comes down to the surface under it first.  Only
where the tool's place is not the job's (the start, around a tool change or pause, the end and its return to X0
Y0) does the program lift to the *clearance plane*: the travel height above the highest probed point, the height
the machine's own stops lift to (:attr:`cam.job.heightmap_level.LevelledJob.safe_z_steps`); there it moves
straight up or down, or across above every probed point.

A job planned for a real cutter (``job.tool``: flat, ball or V, issue #19)
names it: a ``(tool: ball 1 mm, spec ball:1)`` comment in the header and
``T1 M6`` before the first move.  Z is then the tool's tip (the planner's
depths are the tip's), so the program is run with the tool's length offset
measured to its tip.  A point-tool job writes neither.

Targets (``post``, ``cam export --post``, issue #30 point 4): ``generic`` (the default, as above),
``linuxcnc`` and ``grbl``.  All three are written in millimetres (G21), which both controllers take.  Feeds
in mm/min come from the step delays or ``feed_mm_min`` / ``plunge_feed_mm_min`` (Z moves down); a grbl or
LinuxCNC program and every fitted program give ``F`` only where it changes.  ``spindle_rpm`` starts the
spindle with ``M3 S<rpm>`` before the first move and stops it with ``M5`` before the end (and around each
tool change).  A tool change is ``T<n> M6`` for LinuxCNC and generic, and for grbl (which has no tool
changer, and answers ``M6`` with error 20) a comment naming the tool followed by a pause ``M0``: cycle start
goes on with the new tool.  After every tool change and pause (and a first ``T1 M6``) the program goes up to
the safe height and over the next point's X, Y with rapids before it moves on (a controller may move the tool
for a change, or the operator during a pause): every hole is moved to before it is plunged (issue #43 point 9).

Exact geometry: a job's points are machine steps; where the exact mm of a point is known (``exact_xy_mm``:
a drill file's holes, :attr:`cam.job.drill.DrillPlan.holes_mm`, see :func:`exact_geometry`; an SVG file's
curves, :func:`svg_exact_xy_mm`; an HPGL file's points, :func:`hpgl_exact_xy_mm`; ``exact_z_mm``: the drill
depth asked for) it is written instead of the step's position, unless ``snap`` is set.  A mapping that knows
which moves are chords of the source's circles and arcs (``on_arc(from steps, to steps)``: an HPGL ``CI``,
``AA``, ``AR``) has the fitter hold an arc over them to the chords' ends only, so those come out as
``G2``/``G3``.

Arcs (``arc_tolerance_mm``): each run of cutting moves is fitted with lines and XY arcs
(:func:`cam.job.arcs.fit_path`), each within the tolerance of the job's own polyline, and written as
``G1``/``G2``/``G3``; an arc's centre (``I``/``J``) is put on the bisector of its written ends, so the start
and end radii agree to the last written digit.
"""
from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any, Iterator, Optional

import numpy as np

from ..fileio import atomic_write_text
from ..errors import CamError
from ..options import own_zero
from ..job.heightmap_level import height_at
from ..job.arcs import Segment, arc_centre_for_ends, fit_path
from ..job.model import RETRACT, TRAVEL, Job
from ..job.hpgl_stream import hpgl_scale, xy_steps_exact
from ..job.svg import FLATTEN_STEPS, selected_layers, svg_layer_order, svg_scale
from ..formats.hpgl import ARC_MNEMONICS, HpglDrawing, iter_hpgl
from . import kind as kind_named, kind_names
from ..choices import POSTS

__all__ = ["format_mm", "to_gcode", "gcode_pieces", "save_gcode", "feeds_mm_per_min", "exact_geometry", "svg_exact_xy_mm",
           "hpgl_exact_xy_mm", "own_offset", "arc_positions", "POSTS"]

MAX_RUN_POINTS = 50_000
"""The most points of a cutting run held for fitting at once (a longer run is fitted in parts this long)."""


def feeds_mm_per_min(settings) -> tuple[float, float]:
    """(X/Y feed, Z feed) in mm/min that match the step delays: one step per delay."""
    xy = settings.mm_per_step_xy / (settings.delay_xy_ms / 1000.0) * 60.0
    z = settings.mm_per_step_z / (settings.delay_z_ms / 1000.0) * 60.0
    return xy, z


def format_mm(v: float) -> str:
    """``v`` with at most 4 decimals, trailing zeros dropped, no minus zero: how every written number looks.

    >>> format_mm(1.25), format_mm(-0.00001), format_mm(3.0)
    ('1.25', '0', '3')
    """
    s = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _comment(text: str) -> str:
    """``text`` safe inside a G-code comment (no parentheses)."""
    return text.replace("(", "[").replace(")", "]")


def to_gcode(toolpath: Job, **options: Any) -> str:
    """RS-274/NGC text for ``toolpath``: every keyword of :func:`gcode_pieces`.

    Returns:
        The program text, ending with M2.
    """
    return "".join(gcode_pieces(toolpath, **options))


def _point_pieces(toolpath: Any) -> Iterator[tuple[list, list]]:
    """``(points, kinds)`` lists of consecutive pieces of a job (one for a Job; a stream's pieces, one at a time)."""
    for piece in toolpath.pieces():
        yield np.asarray(piece.points_steps).tolist(), np.asarray(piece.kind).tolist()


def exact_geometry(prepared: Any, cut_depth_mm: Optional[float] = None, options: Any = None
                   ) -> tuple[dict[tuple[int, int], tuple[float, float]], dict[int, float]]:
    """``(exact_xy_mm, exact_z_mm)`` of a :class:`cam.kinds.jobs.PreparedJob` for :func:`gcode_pieces`: its kind's
    exact positions (:attr:`cam.kinds.Kind.exact_geometry`: a drill file's holes and drill depth ``cut_depth_mm``
    before rounding to steps, an SVG or DXF file's strokes and an HPGL file's pen-down points and arcs with the
    job's :class:`cam.kinds.jobs.JobOptions` ``options``); empty for other kinds (their points are the job's own).

    A file placed by its own zero (``options.origin`` "file" and no offset) is placed as the planner placed it:
    its zero at the job's home (:func:`own_offset`)."""
    name = getattr(prepared, "kind", None)
    hook = kind_named(name).exact_geometry if name in kind_names() else None
    return ({}, {}) if hook is None else hook(prepared, cut_depth_mm, options)


def own_offset(options: Any) -> Optional[tuple[float, float]]:
    """Where a file's zero goes, as :func:`cam.kinds.jobs.prepare_job` plans it: ``options.offset_mm``, or (0, 0)
    for a file placed by its own zero (``origin`` "file" and no offset); None: by the extent of what is cut."""
    offset = options.offset_mm
    if offset is None and own_zero(lambda name: getattr(options, name, None)):
        offset = (0.0, 0.0)
    return offset


SAMPLE_STEPS = 0.2
"""The spacing, in steps, of the samples of an SVG stroke that :func:`svg_exact_xy_mm` rounds like the planner."""
FLATTEN_MM = 0.0005
"""How close to an SVG curve the polylines :func:`svg_exact_xy_mm` samples are (half a micrometre)."""
MAX_SAMPLES = 2_000_000
"""More samples than this: an SVG drawing is written at its steps (the exact positions would take too much memory)."""


def svg_exact_xy_mm(drawing: Any, settings: Any, *, scale: Optional[float] = None,
                    fit_mm: Optional[tuple[float, float]] = None, offset_mm: Optional[tuple[float, float]] = None,
                    layers: Any = None) -> dict[tuple[int, int], tuple[float, float]]:
    """``{(x steps, y steps): (x mm, y mm)}``: for each step an SVG job's strokes pass through, a point of the
    strokes themselves in it, placed and scaled as :func:`cam.job.svg.plan_svg` places them.

    The strokes are flattened within :data:`FLATTEN_MM` and sampled every :data:`SAMPLE_STEPS` steps; each
    sample goes to the step it rounds to (as the planner rounds its samples), and a step keeps a vertex of the
    strokes that rounds to it (a corner, a stroke's end) or else the sample nearest its centre; a step the
    planner's points reach but no sample does (its polyline is coarser) takes the nearest of the eight around
    it (the mapping's ``get``).  So a job point
    is written on the drawing's own curve, within a step of where the steps put it, and a circle's points lie
    on the circle (an arc fits them).
    """
    part, _ = selected_layers(drawing, svg_layer_order(drawing, layers))
    k = svg_scale(part, scale=scale, fit_mm=fit_mm)
    mm = settings.mm_per_step_xy
    if offset_mm is None:
        coarse = part.polylines(FLATTEN_STEPS * mm / k)  # the planner's placement: its polylines' top-left
        if not coarse:
            return {}
        origin = -np.concatenate(coarse).min(axis=0) * k
    else:
        origin = np.asarray(offset_mm, np.float64)
    polys = [(origin + p * k) / mm for p in part.polylines(FLATTEN_MM / k)]
    polys = [p for p in polys if len(p)]
    if not polys:
        return {}
    samples, vertex = [], []
    total = 0
    for p in polys:
        d = np.diff(p, axis=0)
        n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / SAMPLE_STEPS)).astype(np.int64)
        total += int(n.sum()) + 1
        if total > MAX_SAMPLES:
            return {}
        seg = np.repeat(np.arange(len(d)), n)
        t = (np.arange(len(seg)) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
        samples.append(np.vstack([p[seg] + d[seg] * t[:, None], p[-1:]]))
        vertex.append(np.append(t == 0, True))
    pts = np.concatenate(samples)
    cells = np.floor(pts + 0.5).astype(np.int64)
    off = np.hypot(*(pts - cells).T) - 2.0 * np.concatenate(vertex)  # a vertex first, then the nearest sample
    key = (cells[:, 0] << 32) + cells[:, 1]
    by_off = np.argsort(off, kind="stable")
    _, first = np.unique(key[by_off], return_index=True)
    keep = by_off[first]
    found = _StepPoints(zip(map(tuple, cells[keep].tolist()), map(tuple, (pts[keep] * mm).tolist())))
    found.mm_per_step = mm
    return found


def arc_positions(path: Any) -> set[tuple[int, int]]:
    """``{(line, column)}`` of the circle and arc commands (``CI``, ``AA``, ``AR``) of an HPGL file."""
    return {(c.line, c.column) for c in iter_hpgl(path) if c.name in ARC_MNEMONICS}


def hpgl_exact_xy_mm(drawing: HpglDrawing, settings: Any, *, scale: Optional[float] = None,
                     fit_mm: Optional[tuple[float, float]] = None, offset_mm: Optional[tuple[float, float]] = None,
                     arc_positions: Optional[set[tuple[int, int]]] = None
                     ) -> dict[tuple[int, int], tuple[float, float]]:
    """``{(x steps, y steps): (x mm, y mm)}``: for each step an HPGL job's pen-down points round to, the exact
    position of the first of them, placed and scaled as :func:`cam.job.hpgl.plan_hpgl` places them
    (:func:`cam.job.hpgl_stream.xy_steps_exact`: ``scale``/``fit_mm``, ``offset_mm`` or the drawing's top-left).

    ``arc_positions``: the ``(line, column)`` of the file's ``CI``/``AA``/``AR`` commands.  The reader gives
    every point of a circle or an arc its command's position (a ``PD`` point has its own coordinates'), so a
    point there that starts no stroke ends a chord of the arc: the mapping's :meth:`~_StepPoints.on_arc` says
    which moves between two steps stand for an arc of the file (the fitter then holds an arc to the chords'
    ends, which lie on the file's circle, and not to the chords), and a circle comes out as ``G2``/``G3``.
    """
    pu = drawing.points_pu
    mm = settings.mm_per_step_xy
    found = _StepPoints()
    found.mm_per_step = mm
    if len(pu) == 0:
        return found
    factor = hpgl_scale(drawing.summary(), scale=scale, fit_mm=fit_mm)
    exact = xy_steps_exact(pu[:, 0], pu[:, 1], drawing.extent_pu(), settings, offset_mm, factor)
    cells = np.floor(exact + 0.5).astype(np.int64)
    key = (cells[:, 0] << 32) + cells[:, 1]
    _, first = np.unique(key, return_index=True)
    found.update(zip(map(tuple, cells[first].tolist()), map(tuple, (exact[first] * mm).tolist())))
    start = np.zeros(len(pu), bool)
    start[drawing.stroke_start] = True
    positions = np.asarray(sorted(arc_positions or ()), np.int64).reshape(-1, 2)
    on_arc = ~start & np.isin((np.asarray(drawing.point_line, np.int64) << 32) + drawing.point_col,
                              (positions[:, 0] << 32) + positions[:, 1])
    # the planner drops a point in the step of the one before it: a move joins two steps in a row
    moves = np.flatnonzero(on_arc)
    moves = moves[(moves > 0) & (key[moves] != key[moves - 1])]
    found.arc_moves = set(zip(key[moves - 1].tolist(), key[moves].tolist()))
    return found


class _StepPoints(dict):
    """``{(x steps, y steps): (x mm, y mm)}`` whose :meth:`get` of a step it lacks takes the nearest of the
    eight around it (the planner's coarser polyline may round a sample into a step beside the fine curve's)."""

    mm_per_step: float = 1.0
    arc_moves: set = frozenset()  # type: ignore[assignment]  # {(from key, to key)}: see on_arc

    def on_arc(self, from_steps: tuple[int, int], to_steps: tuple[int, int]) -> bool:
        """Whether the move between these two steps stands for an arc of the source (:func:`hpgl_exact_xy_mm`)."""
        if not self.arc_moves:
            return False
        return ((from_steps[0] << 32) + from_steps[1], (to_steps[0] << 32) + to_steps[1]) in self.arc_moves

    def get(self, key: Any, default: Any = None) -> Any:  # type: ignore[override]
        value = dict.get(self, key)
        if value is not None:
            return value
        x, y = key
        best, best_d = default, 2.0
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                v = dict.get(self, (x + dx, y + dy))
                if v is not None:
                    d = max(abs(v[0] / self.mm_per_step - x), abs(v[1] / self.mm_per_step - y))
                    if d < best_d:
                        best, best_d = v, d
        return best


def _check_options(post: str, feed_mm_min: Optional[float], plunge_feed_mm_min: Optional[float],
                   spindle_rpm: Optional[float], arc_tolerance_mm: Optional[float]) -> None:
    if post not in POSTS:
        raise CamError(f"unknown G-code target '{post}': one of {', '.join(POSTS)}")
    for name, value in (("feed", feed_mm_min), ("plunge feed", plunge_feed_mm_min), ("spindle rpm", spindle_rpm),
                        ("arc tolerance", arc_tolerance_mm)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise CamError(f"the {name} must be a number > 0, got {value!r}")


def gcode_pieces(
    toolpath: Any,
    *,
    flip_y: bool = False,
    travel_height_mm: float = 1.0,
    title: str = "cam job",
    tool_changes: dict[int, tuple[Optional[int], str]] | None = None,
    post: str = "generic",
    feed_mm_min: Optional[float] = None,
    plunge_feed_mm_min: Optional[float] = None,
    spindle_rpm: Optional[float] = None,
    exact_xy_mm: Optional[dict[tuple[int, int], tuple[float, float]]] = None,
    exact_z_mm: Optional[dict[int, float]] = None,
    snap: bool = False,
    arc_tolerance_mm: Optional[float] = None,
    level: Optional[tuple[Any, Any]] = None,
) -> Iterator[str]:
    """The program text for ``toolpath`` in consecutive pieces, made a piece of the job at a time (a job planned
    a piece at a time, :mod:`cam.job.drawing_stream`, :mod:`cam.job.hpgl_stream`, is never held whole).

    Args:
        toolpath: any planned job.
        flip_y: write Y = +row (mirror) instead of the default Y = -row.
        travel_height_mm: height above the surface for moves between cuts.
        title: first comment line.
        tool_changes: ``{point index: (tool number, comment)}`` -- a tool change is written before that point
            (the tool lifted to the travel height, the spindle stopped); tool number None: a pause ``M0`` with
            the comment (a Pause At point, a pause between SVG layers).  Without it, a job planned for a real
            cutter (``toolpath.tool``) gets tool 1 with the tool's shape and size before its first move.
        post: the target, one of :data:`POSTS`.
        feed_mm_min, plunge_feed_mm_min: X/Y (and 3D) feed and Z feed; None: from the step delays.
        spindle_rpm: ``M3 S<rpm>`` before the first move, ``M5`` at the end; None: no spindle commands.
        exact_xy_mm: ``{(x steps, y steps): (x mm, y mm)}`` in the steps' frame (before ``flip_y``): the exact
            position a point of those steps stands for; exact_z_mm: ``{depth steps: depth mm}`` likewise.
        snap: write every point at its steps even where the exact mm is known.
        arc_tolerance_mm: fit lines and arcs to the cutting runs within this many mm; None: one G1 a point.
        level: ``(height map, home steps)``: ``toolpath`` is a job levelled to that
            :class:`~cam.job.heightmap_level.HeightMap` with its home at those machine steps
            (:attr:`cam.kinds.jobs.PreparedJob.levelled_home_steps`): its travels are written levelled too, at
            ``travel_height_mm`` above the surface under each point (see the module).
    """
    probes = getattr(toolpath, "probes", None)
    if probes:  # a program's G38.2/G38.3: the moves after it depend on where it touches (cam.job.gcode_probing)
        raise CamError(f"{probes[0]}: the moves of a program that probes are not written as G-code: after a probe "
                       "they depend on where it touches, known only as it runs (run the program itself)")
    _check_options(post, feed_mm_min, plunge_feed_mm_min, spindle_rpm, arc_tolerance_mm)
    g = _Writer(toolpath, flip_y=flip_y, travel_height_mm=travel_height_mm, post=post, feed_mm_min=feed_mm_min,
                plunge_feed_mm_min=plunge_feed_mm_min, spindle_rpm=spindle_rpm,
                exact_xy={} if snap or not exact_xy_mm else exact_xy_mm,
                exact_z={} if snap or not exact_z_mm else exact_z_mm, arc_tolerance_mm=arc_tolerance_mm,
                level=level)
    g.header(title, snap, bool(tool_changes))
    tool_changes = tool_changes or {}
    i = -1
    for points, kinds in _point_pieces(toolpath):
        yield g.take()  # what the piece before wrote
        for (xp, yp, zp), kind in zip(points, kinds):
            i += 1
            if i in tool_changes:
                g.go_up()
                g.tool_change(*tool_changes[i])
            g.point(xp, yp, zp, kind)
    g.finish()
    yield g.take()


class _Levelling:
    """The height map a written job was levelled to (:func:`gcode_pieces`' ``level``), as the writer needs it: the
    Z offset under a point of the job, and the heights it travels and lifts at, in the job's Z steps (+Z deeper)."""

    def __init__(self, height_map: Any, home_steps: Any, settings: Any, safe_z_mm: float, oz_mm: float) -> None:
        self.map = height_map
        self.home = [int(v) for v in np.asarray(home_steps, np.int64).reshape(3)]
        self.mx, self.my, self.mz = (float(v) for v in settings.mm_per_step_axes)
        self.travel_steps = -int(round(safe_z_mm / self.mz))  # the travel height over the work zero's surface
        self.surface_steps = int(round(oz_mm / self.mz))  # the surface (a drawing's Z origin)
        rise = max(0.0, float(height_map.offsets_mm().max()))  # the highest probed point over the work zero's
        self.clear_steps = self.travel_steps - int(np.ceil(rise / self.mz - 1e-9))

    def offset_steps(self, x_steps: int, y_steps: int) -> float:
        """The Z offset (steps, a higher surface less deep) levelling gives a point of the job, as
        :func:`cam.job.heightmap_level.level_points` computes it."""
        x_mm, y_mm = (x_steps + self.home[0]) * self.mx, (y_steps + self.home[1]) * self.my
        return -(float(height_at(self.map, x_mm, y_mm)) - self.map.reference_mm) / self.mz

    def z_mm(self, nominal_steps: int, offset_steps: float) -> float:
        """The written Z (mm) of a point ``nominal_steps`` deep from the work zero's surface, levelled."""
        return -float(np.rint(nominal_steps + offset_steps)) * self.mz


class _Writer:
    """The state of :func:`gcode_pieces` while it writes: where the tool stands, the cutting run being
    gathered (vertices in mm, fitted and written when the tool lifts), the feed and spindle written last."""

    def __init__(self, toolpath: Any, *, flip_y: bool, travel_height_mm: float, post: str,
                 feed_mm_min: Optional[float], plunge_feed_mm_min: Optional[float], spindle_rpm: Optional[float],
                 exact_xy: Any, exact_z: Any, arc_tolerance_mm: Optional[float],
                 level: Optional[tuple[Any, Any]] = None) -> None:
        s = toolpath.settings
        self.toolpath = toolpath
        self.mm_xy, self.mm_z = s.mm_per_step_xy, s.mm_per_step_z
        self.flip_y = flip_y
        self.y_sign = 1.0 if flip_y else -1.0
        delay_xy, delay_z = feeds_mm_per_min(s)
        self.feeds_asked = feed_mm_min is not None or plunge_feed_mm_min is not None
        self.feed_xy = delay_xy if feed_mm_min is None else float(feed_mm_min)
        self.feed_z = delay_z if plunge_feed_mm_min is None else float(plunge_feed_mm_min)
        self.post = post
        self.exact_xy, self.exact_z = exact_xy, exact_z
        self.tol = arc_tolerance_mm
        self.modal_feed = post != "generic" or arc_tolerance_mm is not None
        self.oz_mm = toolpath.pixels.origin_px[2] * s.steps_per_px_z * self.mm_z if toolpath.pixels else 0.0
        self.safe_z = -self.oz_mm + travel_height_mm
        self.lv = None if level is None else _Levelling(level[0], level[1], s, self.safe_z, self.oz_mm)
        # where the program lifts to when the tool's place is not the job's: the safe plane, or a levelled job's
        # clearance plane (above the highest probed point)
        self.lift_z = self.safe_z if self.lv is None else -self.lv.clear_steps * self.mm_z
        self.high = True  # at the lift plane (a levelled job's travels are below it)
        self.at_steps = (0, 0)  # the job's X, Y steps where the tool stands (the job's home first)
        self.spindle = f"M3 S{format_mm(spindle_rpm)}\n" if spindle_rpm else ""
        self.spindle_on = False  # started before the first cut, and after each tool change
        self.x, self.y, self.z = 0.0, 0.0, self.lift_z
        # False after a tool change or a pause (and a first T1 M6): a controller may have moved the tool for it,
        # so the next move goes back to the safe height and to X, Y with rapids before anything else (issue #43)
        self.xy_known = True
        self.f: Optional[float] = None
        self.above = True  # at the safe plane
        self.run: list[tuple[float, float, float]] = []
        self.run_arc: list[bool] = []  # the move to each vertex of the run stands for an arc of the source
        self.on_arc = getattr(exact_xy, "on_arc", None)
        self.last_steps: Optional[tuple[int, int]] = None  # the job's point before
        self.out = io.StringIO()
        self.w = self.out.write

    def take(self) -> str:
        """The text written since the last call."""
        text = self.out.getvalue()
        self.out.seek(0)
        self.out.truncate()
        return text

    def header(self, title: str, snap: bool, has_tool_changes: bool) -> None:
        w, toolpath = self.w, self.toolpath
        w(f"({_comment(title)})\n")
        w("(generated by cam: units mm, absolute coordinates)\n")
        px = toolpath.pixels  # a drawing job: say it in the drawing's pixels
        unit_x, unit_y, unit_z = ("column", "row", "depth") if px else ("x steps", "y steps", "depth steps")
        k_xy, k_z = (px.steps_per_px_xy, px.steps_per_px_z) if px else (1, 1)
        flip = self.flip_y
        w(f"(X = {unit_x} x {k_xy * self.mm_xy:.4f} mm; Y = {'+' if flip else '-'}{unit_y} x "
          f"{k_xy * self.mm_xy:.4f} mm{' [flipped]' if flip else ' [rows grow down, machine Y grows up]'})\n")
        w(f"(Z = -{unit_z} x {k_z * self.mm_z:.4f} mm; Z = 0 is the material surface; safe height "
          f"{format_mm(self.safe_z)} mm)\n")
        where = "as asked" if self.feeds_asked else "from the step delays"
        w(f"(feeds: X/Y {format_mm(self.feed_xy)} mm/min, Z {format_mm(self.feed_z)} mm/min, {where})\n")
        exact = bool(self.exact_xy or self.exact_z)
        if self.post != "generic" or exact or snap or self.tol is not None:
            geometry = "snapped to the machine's steps" if snap else (
                "exact where the source gives it" if exact else "the job's steps")
            arcs = f"lines and arcs fitted within {format_mm(self.tol)} mm" if self.tol else "one line a point"
            w(f"(target {self.post}; geometry {geometry}; {arcs})\n")
        cutter = getattr(toolpath, "tool", None)
        if cutter is not None and not cutter.is_point:
            w(f"(tool: {_comment(cutter.describe())}, spec {cutter.spec()}; Z is its tip)\n")
        if self.lv is not None:
            w(f"(levelled to a height map: every move's Z offset by the surface under it; travels "
              f"{format_mm(self.safe_z + self.oz_mm)} mm above it; the clearance plane Z{format_mm(self.lift_z)} "
              f"is that above the highest probed point)\n")
        w("G21 G90 G17 G94\n")
        if self.post == "linuxcnc" and self.tol:
            w(f"G64 P{format_mm(self.tol)}\n")  # blend corners no further from the path than the fit
        if cutter is not None and not cutter.is_point and not has_tool_changes:
            if self.post == "grbl":
                w(f"(load tool 1: {_comment(cutter.describe())})\n")
            else:
                w(f"T1 M6 ({_comment(cutter.describe())})\n")
                self.xy_known = False
        w(f"G0 Z{format_mm(self.lift_z)}\n")

    def tool_change(self, n: Optional[int], comment: str) -> None:
        if self.spindle_on:
            self.w("M5\n")
            self.spindle_on = False
        if n is None:  # a pause with no tool (Pause At, between SVG layers): the program stops, cycle start goes on
            self.w(f"(pause: {_comment(comment)}, then cycle start)\nM0\n")
        elif self.post == "grbl":
            self.w(f"(load tool {n}: {_comment(comment)}, then cycle start)\nM0\n")
        else:
            self.w(f"T{n} M6 ({_comment(comment)})\n")
        # a tool change may leave the tool anywhere (a changer's position, a jog during the pause): back up to the
        # safe height now, and to X, Y before the next move (point)
        self.w(f"G0 Z{format_mm(self.lift_z)}\n")
        self.above, self.z, self.high = True, self.lift_z, True
        self.xy_known = False

    def start_spindle(self) -> None:
        if self.spindle and not self.spindle_on:
            self.w(self.spindle)
            self.spindle_on = True

    def feed_word(self, f: float) -> str:
        if self.modal_feed and self.f == f:
            return ""
        self.f = f
        return f" F{format_mm(f)}"

    def flush(self) -> None:
        """Write the gathered cutting run: a G1 a vertex, or fitted lines and arcs."""
        run, w = self.run, self.w
        if len(run) < 2:
            run.clear()
            self.run_arc.clear()
            return
        pts = np.asarray(run, np.float64)
        on_arc = np.asarray(self.run_arc, bool) if any(self.run_arc) else None
        segments = fit_path(pts, self.tol, on_arc=on_arc) if self.tol else \
            [Segment(k, "line") for k in range(1, len(pts))]
        sx, sy, sz = _written(pts[0, 0]), _written(pts[0, 1]), _written(pts[0, 2])
        for seg in segments:
            ex, ey, ez = (float(v) for v in pts[seg.end])
            wx, wy, wz = _written(ex), _written(ey), _written(ez)
            if seg.kind == "line":
                words = ""
                if (wx, wy) != (sx, sy):
                    words += f" X{format_mm(ex)} Y{format_mm(ey)}"
                if wz != sz:
                    words += f" Z{format_mm(ez)}"
                if words:
                    w(f"G1{words}{self.feed_word(self.feed_xy if (wx, wy) != (sx, sy) else self.feed_z)}\n")
            else:
                cx, cy = arc_centre_for_ends((sx, sy), (wx, wy), seg.centre_mm)
                w(f"{'G2' if seg.kind == 'cw' else 'G3'} X{format_mm(ex)} Y{format_mm(ey)} I{format_mm(cx - sx)} J{format_mm(cy - sy)}"
                  f"{self.feed_word(self.feed_xy)}\n")
            sx, sy, sz = wx, wy, wz
        self.x, self.y, self.z = float(pts[-1, 0]), float(pts[-1, 1]), float(pts[-1, 2])
        run.clear()
        self.run_arc.clear()

    def go_up(self) -> None:
        self.flush()
        if self.lv is not None:  # a levelled job: up to the clearance plane (a tool change, the end)
            if not self.high:
                self.w(f"G0 Z{format_mm(self.lift_z)}\n")
                self.above, self.z, self.high = True, self.lift_z, True
            return
        if not self.above:
            self.w(f"G0 Z{format_mm(self.safe_z)}\n")
            self.above, self.z = True, self.safe_z

    def vertex(self, x: float, y: float, z: float, arc: bool = False) -> None:
        if len(self.run) >= MAX_RUN_POINTS:  # by count, not by piece: a job written whole or in pieces is alike
            self.flush()
        if not self.run:
            self.run.append((self.x, self.y, self.z))
            self.run_arc.append(False)
        if (x, y, z) != self.run[-1]:
            self.run.append((x, y, z))
            self.run_arc.append(arc)

    def point(self, xp: int, yp: int, zp: int, kind: int) -> None:
        """One point of the job (machine steps) and its kind."""
        last, self.last_steps = self.last_steps, (xp, yp)
        found = self.exact_xy.get((xp, yp)) if self.exact_xy else None
        if found is not None:
            nx, ny = float(found[0]), self.y_sign * float(found[1])
        else:
            nx, ny = xp * self.mm_xy, self.y_sign * yp * self.mm_xy
        nz = -float(self.exact_z[zp]) if zp in self.exact_z else -zp * self.mm_z
        if self.lv is not None:
            self.levelled_point(xp, yp, zp, kind, nx, ny, nz, last)
            return
        if kind in (RETRACT, TRAVEL) and nz >= -self.oz_mm - 1e-9:
            # at or above the surface: go up to the safe plane, travel there
            self.go_up()
            if (nx, ny) != (self.x, self.y) or not self.xy_known:
                self.w(f"G0 X{format_mm(nx)} Y{format_mm(ny)}\n")
                self.x, self.y, self.xy_known = nx, ny, True
            return
        if not self.xy_known:  # a cut right after a tool change: back over where the tool was first, at safe Z
            self.w(f"G0 X{format_mm(self.x)} Y{format_mm(self.y)}\n")
            self.xy_known = True
        cur = self.run[-1] if self.run else (self.x, self.y, self.z)
        if (nx, ny) != (cur[0], cur[1]):
            if self.above:  # cutting move starting from the safe plane: come down to the surface first
                self.start_spindle()
                self.w(f"G1 Z{format_mm(-self.oz_mm)}{self.feed_word(self.feed_z)}\n")
                self.above, self.z = False, -self.oz_mm
                cur = (cur[0], cur[1], -self.oz_mm)
            elif nz != cur[2] and cur[2] < -self.oz_mm - 1e-9:  # in the material, X/Y and Z together (a levelled
                # or 3D move): one straight move, as the machine cuts it
                self.vertex(nx, ny, nz)
                return
            self.vertex(nx, ny, cur[2], bool(self.on_arc and last is not None and self.on_arc(last, (xp, yp))))
        if nz != cur[2]:
            self.start_spindle()
            self.vertex(nx, ny, nz)
            self.above = False

    def rapid(self, nx: float, ny: float, nz: float) -> None:
        """A levelled job's ``G0`` to ``(nx, ny, nz)``: one straight move, or from the clearance plane across it first
        and then straight down."""
        if self.high and ((nx, ny) != (self.x, self.y) or not self.xy_known):
            self.w(f"G0 X{format_mm(nx)} Y{format_mm(ny)}\n")
            self.x, self.y, self.xy_known = nx, ny, True
        words = f" X{format_mm(nx)} Y{format_mm(ny)}" if (nx, ny) != (self.x, self.y) else ""
        if _written(nz) != _written(self.z):
            words += f" Z{format_mm(nz)}"
        if words:
            self.w(f"G0{words}\n")
        self.x, self.y, self.z = nx, ny, nz
        self.above, self.high = True, False

    def levelled_point(self, xp: int, yp: int, zp: int, kind: int, nx: float, ny: float, nz: float,
                       last: Optional[tuple[int, int]]) -> None:
        """One point of a levelled job (its Z levelled already): a travel at the travel height over the surface under
        it, a cut as the job's straight move (from the travel height: down to the surface first)."""
        lv = self.lv
        assert lv is not None
        off = lv.offset_steps(xp, yp)
        if kind in (RETRACT, TRAVEL) and zp - off <= lv.surface_steps + 0.5:  # at or above the surface under it
            self.flush()
            self.rapid(nx, ny, lv.z_mm(lv.travel_steps, off))
            self.at_steps = (xp, yp)
            return
        if self.high:  # the start, after a tool change: over the tool's point, down to the travel height there
            self.rapid(self.x, self.y, lv.z_mm(lv.travel_steps, lv.offset_steps(*self.at_steps)))
        cur = self.run[-1] if self.run else (self.x, self.y, self.z)
        self.start_spindle()
        if self.above and (nx, ny) != (cur[0], cur[1]):  # a cut across from the travel height: to the surface first
            self.vertex(cur[0], cur[1], lv.z_mm(lv.surface_steps, lv.offset_steps(*self.at_steps)))
            cur = self.run[-1]
        arc = nz == cur[2] and bool(self.on_arc and last is not None and self.on_arc(last, (xp, yp)))
        self.vertex(nx, ny, nz, arc)
        self.above = False
        self.at_steps = (xp, yp)

    def finish(self) -> None:
        self.go_up()
        if (self.x, self.y) != (0.0, 0.0) or not self.xy_known:
            self.w("G0 X0 Y0\n")
        if self.spindle_on:
            self.w("M5\n")
        self.w("M2\n")


def _written(v: float) -> float:
    """``v`` as the program gives it (4 decimals)."""
    return float(format_mm(v))


def save_gcode(toolpath: Job, path: str | os.PathLike, **options) -> Path:
    """Write :func:`to_gcode` output atomically (a piece at a time: :func:`gcode_pieces`)."""
    return atomic_write_text(path, gcode_pieces(toolpath, **options))
