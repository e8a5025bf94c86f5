"""PCB drilling jobs: a hole list to a job in machine steps for the step/dir machine.

Frames: drill files use the board frame (X right, Y up, mm).  The machine
frame is `cam`'s (+X right, +Y toward the operator = image rows, +Z deeper),
so a board seen from above keeps its handedness with machine y = -Y.  By
default the board's top-left corner (smallest X, largest Y of its holes) is
placed where the tool stands when the job starts (the home, (0, 0, 0)), so
every hole lies inside the travel; ``offset_mm=(X, Y)`` instead puts the
board origin (0, 0) at machine (X, Y) mm from the home.  ``mirror_x`` mirrors
the board about its vertical axis for drilling from the back side.  The job's
points are steps from its home; ``home_steps`` says where that home is in the
machine frame (a file placed by its own zero at a work zero: ``offset_mm``
(0, 0) and the work zero), and every hole is checked against the travel there.
Without it the job is planned in its own frame, placed at the work zero when it
runs and checked there; here it must fit the travel's span on each axis (the
hole or slot that makes it too wide is named; issue #45 point 4).

The drill cycle for each hole (thesis-machine step/dir port): rapid at the
safe height to above the hole, plunge to the drill depth, retract to the
safe height.  With ``drill_order="tour"`` (the default) holes are grouped by tool,
smallest diameter first, and within a tool drilled in a short tour from the
current position (:func:`cam.job.drill_order.drill_order`); with
``drill_order="file"`` they are drilled exactly in the file's order, tools
included.  Before each tool (each change of tool, in file order) the job
pauses with a prompt naming the tool and its diameter.

Slots and large holes are milled (issue #31 point 4): a ``G85`` slot or a
routed slot (``M15`` ... ``M16``) of the hole list is cut with its tool --
above its start, down to the drill depth, along the slot at that depth, up.
With ``mill_holes_over_mm=B`` every hole whose tool is larger than ``B`` is
milled with a ``B`` mm bit instead: down at the centre, then concentric
circles at the drill depth, out to the one whose cut just reaches the hole's
edge (never beyond it), then up.  Tools of equal diameter are one run: no
tool change between KiCad's T3 and T4 of 1.000 mm.  A run mills its slots and
milled holes after its holes, each from the nearest end of where it stands.

The job is made a piece per tool run (:class:`DrillJobStream`, a
:class:`~cam.job.model.JobLike`), and :func:`plan_drill`'s toolpath is the
pieces joined.  The order must be known before the first piece: a tour
visits all of a tool's holes, and the runs come smallest tool first, so the
hole list is read whole (it is bounded by :data:`~cam.limits.MAX_HOLES`, and
a :class:`DrillPlan` keeps every hole in drilling order for a MAXIMUS board
anyway); each run's rows are made only when its piece is.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterator, Optional

import numpy as np

from ..errors import PlanError, TravelError
from ..options import OPTIONS, keyword_error
from ..settings import DEFAULT_SETTINGS, MachineSettings
from .model import CUT, RETRACT, TRAVEL, Job, PixelFrame, TravelSpan, check_span, check_travel, join_pieces
from .drill_order import drill_order
from .hpgl_stream import outside_travel, z_span_check

__all__ = ["DrillPlan", "DrillJobStream", "plan_drill", "DEFAULT_CUT_DEPTH_MM", "DEFAULT_TRAVEL_HEIGHT_MM"]

DEFAULT_CUT_DEPTH_MM: float = OPTIONS["cut_depth_mm"].default_for({"holes"})
"""Through a 1.6 mm board with a little margin into the spoil board (2.0: declared once, with the option)."""
DEFAULT_TRAVEL_HEIGHT_MM: float = OPTIONS["travel_height_mm"].default_for({"placed"})


@dataclass
class DrillPlan:
    """A planned drilling job.

    Attributes:
        toolpath: the :class:`~cam.job.model.Job` (machine steps).
        holes_steps: ``(N, 2)`` int64 machine (x, y) steps of each hole, in drilling order.
        hole_index: ``(N,)`` index of each drilled hole in the source hole list.
        tool_sequence: ``[(tool, diameter_mm, n_holes)]`` in drilling order, one entry per tool change
            (a tool may come back in file order).
        depth_steps: the drill depth below the surface in Z steps.
        safe_steps: the travel height above the surface in Z steps, a height (>= 0); the tool travels at the Z
            coordinate ``safe_z_steps`` = ``-safe_steps`` (<= 0, as :attr:`cam.job.model.Job.safe_z_steps`).
        n_slots: slots milled (``G85`` and routed); n_milled: holes milled with the ``mill_holes_over_mm`` bit.
        extent_steps: ``(2, 2)`` int64 smallest and largest machine (x, y) steps of every hole and milled path.
        holes_mm: ``(N, 2)`` machine (x, y) mm of each hole in drilling order, before rounding to steps (exact
            G-code out, :mod:`cam.kinds.gcode_export`).
    """

    toolpath: Job
    holes_steps: np.ndarray
    hole_index: np.ndarray
    tool_sequence: list[tuple[int, float, int]]
    depth_steps: int = 0
    safe_steps: int = 0
    n_slots: int = 0
    n_milled: int = 0
    extent_steps: Optional[np.ndarray] = None
    holes_mm: Optional[np.ndarray] = None

    @property
    def safe_z_steps(self) -> int:
        """The Z coordinate the tool travels at between holes, in steps (<= 0: above the surface; +Z is deeper)."""
        return -self.safe_steps

    @property
    def tool_changes(self) -> list[tuple[int, str]]:
        """``[(index of the first hole of a tool in drilling order, its prompt)]``, one per tool."""
        firsts = np.cumsum([0] + [n for _, _, n in self.tool_sequence])[:-1]
        return [(int(i), note) for i, note in zip(firsts, self.toolpath.pause_notes or [])]


def _machine_mm(holes_mm: np.ndarray, offset_mm, mirror_x: bool, extent_mm: Optional[np.ndarray] = None
                ) -> np.ndarray:
    """Board mm to machine mm; ``extent_mm``: the points whose top-left goes to the home (default the holes)."""
    xy = np.asarray(holes_mm, np.float64).reshape(-1, 2).copy()
    ref = xy if extent_mm is None else np.asarray(extent_mm, np.float64).reshape(-1, 2).copy()
    if mirror_x:
        xy[:, 0] = -xy[:, 0]
        ref[:, 0] = -ref[:, 0]
    if offset_mm is None:
        ox, oy = -ref[:, 0].min(), ref[:, 1].max()
    else:
        ox, oy = offset_mm
    return np.column_stack([ox + xy[:, 0], oy - xy[:, 1]])


def milled_hole_path_mm(centre_mm, hole_mm: float, bit_mm: float, margin_mm: float = 0.0) -> np.ndarray:
    """The path (``(K, 2)`` mm) of a ``bit_mm`` bit milling a round hole of ``hole_mm`` at ``centre_mm``: the
    centre (where it goes down), then concentric circles at most 0.8 bit apart out to the radius where the bit's
    edge reaches the hole's edge less ``margin_mm``, each of chords within 0.01 mm of the circle (all inside
    it).  :func:`plan_drill` gives a margin of 1.5 X/Y steps: the points are rounded to steps and the
    machine's straight moves between them to steps again, and neither may take the cut out of the hole.

    >>> p = milled_hole_path_mm((0.0, 0.0), 3.0, 1.0)
    >>> p[0].tolist(), round(float(np.hypot(*p[1:].T).max()), 6)
    ([0.0, 0.0], 1.0)
    """
    cx, cy = (float(v) for v in centre_mm)
    r_max = (hole_mm - bit_mm) / 2 - margin_mm
    pts = [(cx, cy)]
    if r_max <= 0:
        return np.array(pts, np.float64)
    n_rings = max(1, int(np.ceil(r_max / (0.8 * bit_mm))))
    for radius in r_max * np.arange(1, n_rings + 1) / n_rings:
        n = max(8, int(np.ceil(np.pi / np.arccos(max(-1.0, 1 - 0.01 / radius)))) if radius > 0.01 else 8)
        a = 2 * np.pi * np.arange(n + 1) / n
        pts += list(zip(cx + radius * np.cos(a), cy + radius * np.sin(a)))
    return np.array(pts, np.float64)


def plan_drill(
    holes,
    *,
    settings: MachineSettings = DEFAULT_SETTINGS,
    cut_depth_mm: float = DEFAULT_CUT_DEPTH_MM,
    travel_height_mm: float = DEFAULT_TRAVEL_HEIGHT_MM,
    offset_mm: tuple[float, float] | None = None,
    mirror_x: bool = False,
    drill_order: str = "tour",
    mill_holes_over_mm: Optional[float] = None,
    home_steps: Optional[tuple[int, int, int]] = None,
) -> DrillPlan:
    """Plan the drilling of a :class:`~cam.formats.excellon.HoleList`: its holes drilled, its slots milled.

    Args:
        holes: the hole list (board frame, mm).
        settings: machine settings (mm per step, delays, travel).
        cut_depth_mm: drill depth below the surface; travel_height_mm: travel height above it.
        offset_mm: machine position (mm from the home) of the board origin; None = board top-left at the home.
        mirror_x: mirror for drilling from the back side.
        drill_order: "tour" (tools smallest first, a short tour per tool) or "file" (the file's order of holes and
            tools: a prompt at each change of tool).
        mill_holes_over_mm: mill every hole whose tool is larger than this with a bit of this diameter (None:
            drill every hole with its own tool).
        home_steps: the machine position of the job's home (its (0, 0, 0), where ``offset_mm`` is measured from):
            the holes, paths and depths are checked against the travel in the machine frame from there; None: the
            job's own frame (placed when it runs, where it is checked): they must fit the travel's span.

    Raises:
        PlanError: bad options; TravelError: a hole outside the travel, or (in its own frame) one that makes the
        job wider than the travel (naming the hole and its line).
    """

    wrong = keyword_error({"cut_depth_mm": cut_depth_mm, "travel_height_mm": travel_height_mm,
                           "mill_holes_over_mm": mill_holes_over_mm})  # their ranges: cam.options
    if wrong is not None:
        raise PlanError(wrong)
    if drill_order not in ("tour", "file"):
        raise PlanError(f"drill_order must be 'tour' or 'file', got {drill_order!r}")
    slot_paths = list(getattr(holes, "slot_paths_mm", []) or [])
    if len(holes.holes_mm) == 0 and not slot_paths:
        raise PlanError(f"{holes.source}: no holes to drill")
    # milled paths: the slots with their tools, then the holes larger than the mill bit with the bit
    tool_of = np.asarray(holes.tool_of_hole, np.int64)
    drilled = np.arange(len(tool_of))
    paths_mm = [np.asarray(p, np.float64) for p in slot_paths]
    path_dia = [float(holes.tools[int(t)]) for t in getattr(holes, "tool_of_slot", [])]
    path_tool = [int(t) for t in getattr(holes, "tool_of_slot", [])]
    n_milled = 0
    if mill_holes_over_mm is not None:
        big = np.array([holes.tools[int(t)] > mill_holes_over_mm + 1e-9 for t in tool_of], bool)
        drilled = np.flatnonzero(~big)
        bit_tool = next((t for t, d in sorted(holes.tools.items()) if abs(d - mill_holes_over_mm) <= 1e-6), -1)
        for i in np.flatnonzero(big):
            paths_mm.append(milled_hole_path_mm(holes.holes_mm[i], float(holes.tools[int(tool_of[i])]),
                                                mill_holes_over_mm, 1.5 * settings.mm_per_step_xy))
            path_dia.append(float(mill_holes_over_mm))
            path_tool.append(bit_tool)
        n_milled = int(big.sum())
    every_mm = np.concatenate([np.asarray(holes.holes_mm, np.float64).reshape(-1, 2)] + paths_mm)
    own = home_steps is None  # the job's own frame: it must fit the travel's span (placed and checked when it runs)
    home = np.zeros(3, np.int64) if own else np.asarray(home_steps, np.int64).reshape(3)
    span = TravelSpan(settings) if own else None
    machine_mm = _machine_mm(holes.holes_mm, offset_mm, mirror_x, every_mm)
    per_xy = np.asarray(settings.mm_per_step_axes[:2])  # X and Y may differ (a MAXIMUS board, issue #45 point 5)
    steps_xy = np.rint(machine_mm / per_xy).astype(np.int64)
    _check_holes(holes, steps_xy + home[:2], settings, span)
    paths_steps = [np.rint(_machine_mm(p, offset_mm, mirror_x, every_mm) / per_xy).astype(np.int64)
                   for p in paths_mm]
    for k, p in enumerate(paths_steps):
        if k < len(slot_paths):
            _check_holes_path(holes, k, p + home[:2], settings, span)
        elif span is not None:
            found = span.over(p)
            if found is not None:
                raise TravelError(f"{holes.source}: a milled hole lies outside the machine travel: {found[1]}")
        else:
            check_travel(np.column_stack([p, np.zeros(len(p), np.int64)]) + home, settings)
    depth_steps, safe_z_steps = _drill_z_steps(cut_depth_mm, travel_height_mm, settings,
                                               None if own else int(home[2]))
    runs = _tool_runs(holes, machine_mm, drill_order, drilled)
    runs3, diameters = _with_paths(runs, [float(holes.tools[t]) for t, _ in runs], paths_steps, path_dia, path_tool,
                                   machine_mm / per_xy, drill_order, len(slot_paths))
    notes = _notes(holes, runs3, diameters, len(slot_paths), mill_holes_over_mm)
    stream = DrillJobStream([(t, idx) for t, idx, _ in runs3], steps_xy, diameters, depth_steps, safe_z_steps,
                            settings, str(holes.source), list(holes.warnings), paths_steps=paths_steps,
                            path_runs=[pidx for _, _, pidx in runs3], notes=notes,
                            home_steps=None if own else tuple(int(v) for v in home))  # type: ignore[arg-type]
    toolpath = stream.joined()
    order_arr = np.concatenate([np.zeros(0, np.int64)] + [idx for _, idx, _ in runs3]).astype(np.int64)
    sequence = [(tool, dia, len(idx)) for (tool, idx, _), dia in zip(runs3, diameters)]
    cut = np.concatenate([steps_xy[order_arr]] + paths_steps).reshape(-1, 2)
    extent = np.array([cut.min(axis=0), cut.max(axis=0)], np.int64)
    return DrillPlan(toolpath, steps_xy[order_arr], order_arr, sequence, depth_steps, -safe_z_steps,
                     n_slots=len(slot_paths), n_milled=n_milled, extent_steps=extent,
                     holes_mm=machine_mm[order_arr])


def _drill_z_steps(cut_depth_mm: float, travel_height_mm: float, settings: MachineSettings,
                   home_z_steps: Optional[int]) -> tuple[int, int]:
    """(drill depth, travel Z) in Z steps (+Z deeper: the travel Z is <= 0), checked against the Z travel with the
    board's surface at machine Z ``home_z_steps`` (None: a job planned in its own frame, against the Z travel's
    span) before the tour: a million holes take a while to order."""
    depth_steps = int(round(cut_depth_mm / settings.mm_per_step_z))
    if depth_steps < 1:
        raise PlanError(f"drill depth {cut_depth_mm:g} mm is less than one Z step (mm_per_step_z = "
                        f"{settings.mm_per_step_z:g} mm): nothing would be drilled")
    safe_z_steps = -int(round(travel_height_mm / settings.mm_per_step_z))
    if home_z_steps is None:
        z_span_check(f"drill depth {cut_depth_mm:g} mm and safe height {travel_height_mm:g} mm", depth_steps,
                     safe_z_steps, settings)
        return depth_steps, safe_z_steps
    _, _, (z_lo, z_hi) = settings.travel.bounds_steps()
    if depth_steps + home_z_steps > z_hi or safe_z_steps + home_z_steps < z_lo:
        surface = f" from a surface at machine Z {home_z_steps}" if home_z_steps else ""
        raise TravelError(f"drill depth {cut_depth_mm:g} mm and safe height {travel_height_mm:g} mm need Z "
                          f"{safe_z_steps + home_z_steps}..{depth_steps + home_z_steps} steps{surface}; the Z "
                          f"travel is {z_lo}..{z_hi} steps")
    return depth_steps, safe_z_steps


def _with_paths(runs, diameters, paths_steps, path_dia, path_tool, holes_steps_f, order, n_slots: int):
    """The hole runs with the milled paths joined to the run of their diameter: ``([(tool, hole indices, path
    indices)], diameters)``.  Paths of a diameter no run drills get a run of their own (in "tour" among the runs
    by diameter; in "file" at the end).  Within a run the paths come after the holes, each the nearest next
    (entered at its nearer end: a slot may be cut either way; a milled hole starts at its centre)."""
    out = [[t, idx, []] for t, idx in runs]
    dias = list(diameters)
    for k, dia in enumerate(path_dia):
        at = [j for j, d in enumerate(dias) if abs(d - dia) <= 1e-6]
        if at:
            out[at[-1] if order == "file" else at[0]][2].append(k)
            continue
        tool = path_tool[k]
        if order == "file":
            pos = len(out)
        else:
            pos = next((j for j, d in enumerate(dias) if d > dia), len(out))
        out.insert(pos, [tool, np.zeros(0, np.int64), [k]])
        dias.insert(pos, dia)
    result = []
    for tool, idx, pks in out:
        if pks:
            cur = holes_steps_f[idx[-1]] if len(idx) else np.zeros(2)
            left, ordered = list(pks), []
            while left:
                fwd = [float(np.abs(paths_steps[k][0] - cur).max()) for k in left]
                back = [float(np.abs(paths_steps[k][-1] - cur).max()) if k < n_slots else np.inf for k in left]
                j = int(np.argmin(np.minimum(fwd, back)))
                k = left.pop(j)
                if back[j] < fwd[j]:
                    paths_steps[k] = paths_steps[k][::-1].copy()  # a slot is cut from its nearer end
                ordered.append(k)
                cur = paths_steps[k][-1]
            pks = ordered
        result.append((tool, idx, np.array(pks, np.int64)))
    return result, dias


def _notes(holes, runs3, diameters, n_slots: int, bit_mm) -> list[str]:
    """Each run's tool-change prompt: the tool (and the tools of the same size drilled with it), its holes,
    slots and milled holes."""
    notes = []
    for (tool, idx, pks), dia in zip(runs3, diameters):
        same = sorted({int(t) for t in np.asarray(holes.tool_of_hole)[idx]} - {tool})
        same += sorted({int(t) for k, t in enumerate(getattr(holes, "tool_of_slot", [])) if k in set(pks.tolist())}
                       - {tool} - set(same))
        name = f"T{tool}" if tool >= 0 else "mill bit"
        if same:
            name += " = " + " = ".join(f"T{t}" for t in same)
        what = [f"{len(idx)} holes"]
        n_slot = int(np.count_nonzero(pks < n_slots))
        if n_slot:
            what.append(f"{n_slot} slots milled")
        if len(pks) - n_slot:
            what.append(f"{len(pks) - n_slot} holes over {bit_mm:g} mm milled")
        notes.append(f"tool change: {name} {dia:.3f} mm ({', '.join(what)})")
    return notes


def _check_holes_path(holes, k: int, path_steps: np.ndarray, settings: MachineSettings,
                      span: Optional[TravelSpan] = None) -> None:
    """TravelError naming slot ``k`` (``file:line``) when its ``(K, 2)`` machine steps leave the travel, the axis
    and by how much; with ``span`` (the job's own frame, its extent so far): when it makes the job wider than the
    travel."""
    found = outside_travel(path_steps, settings) if span is None else span.over(path_steps)
    if found is not None:
        lines = getattr(holes, "line_of_slot", [])
        where = f"{holes.source}:{int(lines[k])}" if len(lines) > k else holes.source
        said = f": {found[1]}" if span is not None else f" ({found[1]})"
        raise TravelError(f"{where}: slot {k + 1} lies outside the machine travel{said}")


def _tool_runs(holes, machine_mm: np.ndarray, order: str, drilled: Optional[np.ndarray] = None
               ) -> list[tuple[int, np.ndarray]]:
    """``[(tool, hole indices)]`` in drilling order; ``drilled``: the indices of the holes to drill (default all).

    Tools of equal diameter (within 1e-6 mm) are one tool: the run is named after the lowest-numbered of them.
    "file": the file's order, one run per change of diameter (T2 before T1 stays so, and a tool that comes
    back gets a run of its own).  "tour": one run per diameter, smallest first, each a short path
    from where the previous one ended; the last tool's path is planned with the way back to the home
    (the job ends there), so the whole job travels a short closed tour.
    """
    all_tools = np.asarray(holes.tool_of_hole, np.int64)
    drilled = np.arange(len(all_tools)) if drilled is None else np.asarray(drilled, np.int64)
    if len(drilled) == 0:
        return []
    # one name per diameter: the lowest tool number of that size
    same = {}
    for t, d in sorted(holes.tools.items()):
        same.setdefault(round(float(d), 6), t)
    canon = {t: same[round(float(d), 6)] for t, d in holes.tools.items()}
    tools_of = np.array([canon[int(t)] for t in all_tools[drilled]], np.int64)
    if order == "file":
        starts = np.flatnonzero(np.r_[True, tools_of[1:] != tools_of[:-1]])
        ends = np.r_[starts[1:], len(tools_of)]
        return [(int(tools_of[a]), drilled[a:b]) for a, b in zip(starts, ends)]
    runs = []
    home = (0.0, 0.0)
    cur = np.array(home)
    tools = sorted(set(tools_of.tolist()), key=lambda t: (holes.tools[t], t))
    for k, tool in enumerate(tools):
        idx = drilled[tools_of == tool]
        idx = idx[drill_order(machine_mm[idx], start_mm=tuple(cur), end_mm=home if k == len(tools) - 1 else None)]
        runs.append((tool, idx))
        cur = machine_mm[idx[-1]]
    return runs


def _check_holes(holes, steps_xy: np.ndarray, settings: MachineSettings, span: Optional[TravelSpan] = None) -> None:
    """TravelError naming the first hole (``file:line``) whose ``(N, 2)`` machine (x, y) steps leave the travel, the
    axis and by how much; with ``span`` (the job's own frame: steps from its home, its extent so far): the first
    hole that makes the job wider than the travel (:class:`~cam.job.model.TravelSpan`)."""
    found = outside_travel(steps_xy, settings) if span is None else span.over(steps_xy)
    if found is not None:
        i, beyond = found
        lines = getattr(holes, "line_of_hole", None)
        where = f"{holes.source}:{int(lines[i])}" if lines is not None and len(lines) > i else holes.source
        said = f": {beyond}" if span is not None else f" ({beyond})"
        raise TravelError(
            f"{where}: hole {i + 1} at X{holes.holes_mm[i, 0]:.3f} Y{holes.holes_mm[i, 1]:.3f} mm lies "
            f"outside the machine travel{said}"
        )


@dataclass
class DrillJobStream:
    """The drilling job as consecutive :class:`~cam.job.model.Job` pieces, one per tool run (a
    :class:`~cam.job.model.JobLike`): :func:`plan_drill`'s ``toolpath`` is :meth:`joined`.

    The drilling order must be known first (a tour per tool needs all of the tool's holes), so the runs and the
    holes' steps are held (a few numbers a hole, as :class:`DrillPlan` keeps them); a run's rows are made when
    its piece is: the first piece starts with the lift to the safe height, every piece pauses for its tool
    change before its first hole (at the safe height where the tool stands) and drills its holes (above the
    hole, down, up), and the last goes home.

    Attributes:
        runs: ``[(tool, hole indices)]`` in drilling order; steps_xy: ``(N, 2)`` int64 machine (x, y) steps of
            every hole of the source list; diameters_mm: each run's tool diameter.
        depth_steps: the drill depth (Z steps, > 0); travel_z_steps: the travel height, a Z coordinate (<= 0).
        settings, source, warnings: the machine settings, the file, the hole list's warnings.
        safe_z_steps: the Z a stop lifts to, 0 (the surface, as drilling jobs have always had it).
        pixels, tool: None (no drawing frame; the point tool).
        paths_steps: ``(K, 2)`` int64 machine (x, y) steps of each milled path (slots, milled holes); path_runs:
            each run's path indices, milled after its holes (above the first point, down, along at the drill
            depth, up at the last); notes: each run's tool-change prompt (default: tool, diameter, holes).
        home_steps: the machine position of the job's home: each piece is checked against the travel from there
            (None: the job's own frame; each piece is checked to keep the job within the travel's span).
    """

    runs: list[tuple[int, np.ndarray]]
    steps_xy: np.ndarray
    diameters_mm: list[float]
    depth_steps: int
    travel_z_steps: int
    settings: MachineSettings = DEFAULT_SETTINGS
    source: str = ""
    warnings: list[str] = field(default_factory=list)
    safe_z_steps: int = 0
    pixels: Optional[PixelFrame] = None
    tool: Any = None
    paths_steps: list[np.ndarray] = field(default_factory=list)
    path_runs: Optional[list[np.ndarray]] = None
    notes: Optional[list[str]] = None
    home_steps: Optional[tuple[int, int, int]] = None

    def joined(self) -> Job:
        """Every move in one :class:`~cam.job.model.Job` (:func:`~cam.job.model.join_pieces` of :meth:`pieces`)."""
        return join_pieces(self.pieces(), self)

    def pieces(self) -> Iterator[Job]:
        """One piece per tool run (see the class docstring); each checked against the travel (in its own frame:
        the job's extent so far against the travel's span)."""
        span = TravelSpan(self.settings) if self.home_steps is None else None
        for k in range(len(self.runs)):
            yield self._piece(k, span)

    def _note(self, k: int) -> str:
        if self.notes is not None:
            return self.notes[k]
        tool, idx = self.runs[k]
        return f"tool change: T{tool} {self.diameters_mm[k]:.3f} mm ({len(idx)} holes)"

    def _paths(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Run ``k``'s milled paths as rows and their kinds: above the first point, down to the drill depth, along
        the path at that depth (repeated points dropped), up at the last."""
        if self.path_runs is None or not len(self.path_runs[k]):
            return np.zeros((0, 3), np.int64), np.zeros(0, np.uint8)
        rows, kinds = [], []
        for j in self.path_runs[k]:
            p = np.asarray(self.paths_steps[int(j)], np.int64).reshape(-1, 2)
            p = p[np.r_[True, np.any(p[1:] != p[:-1], axis=1)]]
            n = len(p)
            block = np.empty((n + 3, 3), np.int64)
            block[0, :2], block[0, 2] = p[0], self.travel_z_steps
            block[1, :2], block[1, 2] = p[0], self.depth_steps
            block[2:n + 1, :2], block[2:n + 1, 2] = p[1:], self.depth_steps
            block[n + 1, :2], block[n + 1, 2] = p[-1], self.travel_z_steps
            block = block[:n + 2]
            rows.append(block)
            kinds.append(np.concatenate([[TRAVEL], np.full(n, CUT), [RETRACT]]).astype(np.uint8))
        return np.vstack(rows), np.concatenate(kinds)

    def _piece(self, k: int, span: Optional[TravelSpan] = None) -> Job:
        """Run ``k``: (the first run) a lift, or a point at the home, where the first tool change pauses; each
        hole above, down, up; the last row pauses for the next run's tool, or (the last run) home."""
        safe, last = self.travel_z_steps, k == len(self.runs) - 1
        idx = self.runs[k][1]
        head = [(0, 0, safe)] if k == 0 else []
        holes = np.empty((3 * len(idx), 3), np.int64)
        holes[:, :2] = np.repeat(self.steps_xy[idx], 3, axis=0)
        holes[:, 2] = np.tile([safe, self.depth_steps, safe], len(idx))
        paths, path_kinds = self._paths(k)
        tail = ([(0, 0, safe)] + ([(0, 0, 0)] if safe != 0 else [])) if last else []
        pts = np.vstack([np.array(head, np.int64).reshape(-1, 3), holes, paths,
                         np.array(tail, np.int64).reshape(-1, 3)])
        kind = np.concatenate([np.full(len(head), RETRACT if safe != 0 else TRAVEL, np.uint8),
                               np.tile(np.array([TRAVEL, CUT, RETRACT], np.uint8), len(idx)), path_kinds,
                               np.full(len(tail), TRAVEL, np.uint8)])
        pause = np.zeros(len(pts), bool)
        notes = []
        if k == 0:
            pause[0] = True
            notes.append(self._note(0))
        if not last:
            pause[len(head) + len(holes) + len(paths) - 1] = True
            notes.append(self._note(k + 1))
        if self.home_steps is None:
            check_span(pts, self.settings, span=span)
        else:
            check_travel(pts + np.asarray(self.home_steps, np.int64), self.settings)
        return Job(points_steps=pts, kind=kind, target=kind == CUT, pause=pause, settings=self.settings,
                   warnings=list(self.warnings) if k == 0 else [], pause_notes=notes, source=self.source)
