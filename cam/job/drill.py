"""PCB drilling jobs: a hole list to a job in machine steps for the step/dir machine.

Frames: drill files use the board frame (X right, Y up, mm).  The machine
frame is `cam`'s (+X right, +Y toward the operator = image rows, +Z deeper),
so a board seen from above keeps its handedness with machine y = -Y.  By
default the board's top-left corner (smallest X, largest Y of its holes) is
placed where the tool stands when the job starts (the home, (0, 0, 0)), so
every hole lies inside the travel; ``offset_mm=(X, Y)`` instead puts the
board origin (0, 0) at machine (X, Y) mm from the home.  ``mirror_x`` mirrors
the board about its vertical axis for drilling from the back side.

The drill cycle for each hole (thesis-machine step/dir port): rapid at the
safe height to above the hole, plunge to the drill depth, retract to the
safe height.  With ``drill_order="tour"`` (the default) holes are grouped by tool,
smallest diameter first, and within a tool drilled in a short tour from the
current position (:func:`cam.job.drill_order.drill_order`); with
``drill_order="file"`` they are drilled exactly in the file's order, tools
included.  Before each tool (each change of tool, in file order) the job
pauses with a prompt naming the tool and its diameter.

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
from ..settings import DEFAULT_SETTINGS, MachineSettings
from .model import CUT, RETRACT, TRAVEL, Job, PixelFrame, check_travel, join_pieces
from .drill_order import drill_order

__all__ = ["DrillPlan", "DrillJobStream", "plan_drill", "DEFAULT_CUT_DEPTH_MM", "DEFAULT_TRAVEL_HEIGHT_MM"]

DEFAULT_CUT_DEPTH_MM = 2.0
"""Through a 1.6 mm board with a little margin into the spoil board."""
DEFAULT_TRAVEL_HEIGHT_MM = 1.0


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
    """

    toolpath: Job
    holes_steps: np.ndarray
    hole_index: np.ndarray
    tool_sequence: list[tuple[int, float, int]]
    depth_steps: int = 0
    safe_steps: int = 0

    @property
    def safe_z_steps(self) -> int:
        """The Z coordinate the tool travels at between holes, in steps (<= 0: above the surface; +Z is deeper)."""
        return -self.safe_steps

    @property
    def tool_changes(self) -> list[tuple[int, str]]:
        """``[(index of the first hole of a tool in drilling order, its prompt)]``, one per tool."""
        firsts = np.cumsum([0] + [n for _, _, n in self.tool_sequence])[:-1]
        return [(int(i), note) for i, note in zip(firsts, self.toolpath.pause_notes or [])]


def _machine_mm(holes_mm: np.ndarray, offset_mm, mirror_x: bool) -> np.ndarray:
    xy = np.asarray(holes_mm, np.float64).copy()
    if mirror_x:
        xy[:, 0] = -xy[:, 0]
    if offset_mm is None:
        ox, oy = -xy[:, 0].min(), xy[:, 1].max()
    else:
        ox, oy = offset_mm
    return np.column_stack([ox + xy[:, 0], oy - xy[:, 1]])


def plan_drill(
    holes,
    *,
    settings: MachineSettings = DEFAULT_SETTINGS,
    cut_depth_mm: float = DEFAULT_CUT_DEPTH_MM,
    travel_height_mm: float = DEFAULT_TRAVEL_HEIGHT_MM,
    offset_mm: tuple[float, float] | None = None,
    mirror_x: bool = False,
    drill_order: str = "tour",
) -> DrillPlan:
    """Plan the drilling of a :class:`~cam.formats.excellon.HoleList`.

    Args:
        holes: the hole list (board frame, mm).
        settings: machine settings (mm per step, delays, travel).
        cut_depth_mm: drill depth below the surface; travel_height_mm: travel height above it.
        offset_mm: machine position (mm from the home) of the board origin; None = board top-left at the home.
        mirror_x: mirror for drilling from the back side.
        drill_order: "tour" (tools smallest first, a short tour per tool) or "file" (the file's order of holes and
            tools: a prompt at each change of tool).

    Raises:
        PlanError: bad options; TravelError: a hole outside the travel (naming the hole and its line).
    """

    if cut_depth_mm <= 0 or travel_height_mm < 0:
        raise PlanError("drill depth must be > 0 mm and the safe height >= 0 mm")
    if drill_order not in ("tour", "file"):
        raise PlanError(f"drill_order must be 'tour' or 'file', got {drill_order!r}")
    if len(holes.holes_mm) == 0:
        raise PlanError(f"{holes.source}: no holes to drill")
    machine_mm = _machine_mm(holes.holes_mm, offset_mm, mirror_x)
    steps_xy = np.rint(machine_mm / settings.mm_per_step_xy).astype(np.int64)
    _check_holes(holes, machine_mm, steps_xy, settings)
    depth_steps = int(round(cut_depth_mm / settings.mm_per_step_z))
    if depth_steps < 1:
        raise PlanError(f"drill depth {cut_depth_mm:g} mm is less than one Z step (mm_per_step_z = "
                        f"{settings.mm_per_step_z:g} mm): nothing would be drilled")
    safe_z_steps = -int(round(travel_height_mm / settings.mm_per_step_z))
    _, _, (z_lo, z_hi) = settings.travel.bounds_steps()
    if depth_steps > z_hi or safe_z_steps < z_lo:  # before the tour: a million holes take a while to order
        raise TravelError(f"drill depth {cut_depth_mm:g} mm and safe height {travel_height_mm:g} mm need Z "
                          f"{safe_z_steps}..{depth_steps} steps; the Z travel is {z_lo}..{z_hi} steps")
    runs = _tool_runs(holes, machine_mm, drill_order)
    stream = DrillJobStream(runs, steps_xy, [float(holes.tools[t]) for t, _ in runs], depth_steps, safe_z_steps,
                            settings, str(holes.source), list(holes.warnings))
    toolpath = stream.joined()
    order_arr = np.concatenate([idx for _, idx in runs]).astype(np.int64)
    sequence = [(tool, float(holes.tools[tool]), len(idx)) for tool, idx in runs]
    return DrillPlan(toolpath, steps_xy[order_arr], order_arr, sequence, depth_steps, -safe_z_steps)


def _tool_runs(holes, machine_mm: np.ndarray, order: str) -> list[tuple[int, np.ndarray]]:
    """``[(tool, hole indices)]`` in drilling order.

    "file": the file's order, one run per change of tool (T2 before T1 stays so, and a tool that comes
    back gets a run of its own).  "tour": one run per tool, smallest diameter first, each a short path
    from where the previous one ended; the last tool's path is planned with the way back to the home
    (the job ends there), so the whole job travels a short closed tour.
    """
    tools_of = np.asarray(holes.tool_of_hole, np.int64)
    if order == "file":
        starts = np.flatnonzero(np.r_[True, tools_of[1:] != tools_of[:-1]])
        ends = np.r_[starts[1:], len(tools_of)]
        return [(int(tools_of[a]), np.arange(a, b)) for a, b in zip(starts, ends)]
    runs = []
    home = (0.0, 0.0)
    cur = np.array(home)
    tools = sorted(set(tools_of.tolist()), key=lambda t: (holes.tools[t], t))
    for k, tool in enumerate(tools):
        idx = np.flatnonzero(tools_of == tool)
        idx = idx[drill_order(machine_mm[idx], start_mm=tuple(cur), end_mm=home if k == len(tools) - 1 else None)]
        runs.append((tool, idx))
        cur = machine_mm[idx[-1]]
    return runs


def _check_holes(holes, machine_mm: np.ndarray, steps_xy: np.ndarray, settings: MachineSettings) -> None:
    """TravelError naming the first hole (``file:line``) whose ``(N, 2)`` machine (x, y) steps leave the travel."""
    lo = np.array([b[0] for b in settings.travel.bounds_steps()])
    hi = np.array([b[1] for b in settings.travel.bounds_steps()])
    bad = np.flatnonzero(np.any((steps_xy < lo[:2]) | (steps_xy > hi[:2]), axis=1))
    if len(bad):
        i = int(bad[0])
        lines = getattr(holes, "line_of_hole", None)
        where = f"{holes.source}:{int(lines[i])}" if lines is not None and len(lines) > i else holes.source
        raise TravelError(
            f"{where}: hole {i + 1} at X{holes.holes_mm[i, 0]:.3f} Y{holes.holes_mm[i, 1]:.3f} mm lies "
            f"outside the machine travel (machine {machine_mm[i, 0]:.2f}, {machine_mm[i, 1]:.2f} mm)"
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

    def joined(self) -> Job:
        """Every move in one :class:`~cam.job.model.Job` (:func:`~cam.job.model.join_pieces` of :meth:`pieces`)."""
        return join_pieces(self.pieces(), self)

    def pieces(self) -> Iterator[Job]:
        """One piece per tool run (see the class docstring); each checked against the travel."""
        for k in range(len(self.runs)):
            yield self._piece(k)

    def _note(self, k: int) -> str:
        tool, idx = self.runs[k]
        return f"tool change: T{tool} {self.diameters_mm[k]:.3f} mm ({len(idx)} holes)"

    def _piece(self, k: int) -> Job:
        """Run ``k``: (the first run) a lift, or a point at the home, where the first tool change pauses; each
        hole above, down, up; the last row pauses for the next run's tool, or (the last run) home."""
        safe, last = self.travel_z_steps, k == len(self.runs) - 1
        idx = self.runs[k][1]
        head = [(0, 0, safe)] if k == 0 else []
        holes = np.empty((3 * len(idx), 3), np.int64)
        holes[:, :2] = np.repeat(self.steps_xy[idx], 3, axis=0)
        holes[:, 2] = np.tile([safe, self.depth_steps, safe], len(idx))
        tail = ([(0, 0, safe)] + ([(0, 0, 0)] if safe != 0 else [])) if last else []
        pts = np.vstack([np.array(head, np.int64).reshape(-1, 3), holes, np.array(tail, np.int64).reshape(-1, 3)])
        kind = np.concatenate([np.full(len(head), RETRACT if safe != 0 else TRAVEL, np.uint8),
                               np.tile(np.array([TRAVEL, CUT, RETRACT], np.uint8), len(idx)),
                               np.full(len(tail), TRAVEL, np.uint8)])
        pause = np.zeros(len(pts), bool)
        notes = []
        if k == 0:
            pause[0] = True
            notes.append(self._note(0))
        if not last:
            pause[len(head) + len(holes) - 1] = True
            notes.append(self._note(k + 1))
        check_travel(pts, self.settings)
        return Job(points_steps=pts, kind=kind, target=kind == CUT, pause=pause, settings=self.settings,
                   warnings=list(self.warnings) if k == 0 else [], pause_notes=notes, source=self.source)
