"""The live view of a job (issue #47 points 1-3): its path in machine mm, the tool's position in the job's own
units, its holes with their states, and starting it at a hole (computation only: nothing here moves).

A front end (the web page) draws :func:`job_track`'s path and holes, then the tool where the machine reports it
(the session's snapshot, never the plan), converted to the job's own units by :func:`to_job_units`; a drill job's
holes get their states (:data:`HOLE_STATES`) from the session's progress (:func:`hole_states`).

Frames: machine positions are steps from the machine's home (+X right, +Y toward the operator, +Z deeper), as the
session gives them; a job's *home* is the machine position its own frame's (0, 0, 0) has when it runs (the work
zero it is placed at, or where the tool stood when it started).  A drawing's units are its pixels ``(col, row,
z)``, as the thesis's GUI showed them; a drill file's are the file's own board frame (X right, Y up) in the file's
unit (inch, with mil beside it, or mm); any other job's are mm from its home.
"""
from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from ..errors import CamError, PlanError
from ..formats.excellon import load_excellon
from ..kinds.jobs import resume_job
from ..kinds import has
from ..job.model import CUT, Job, cut_runs_steps
from ..job.resume import Journal
from ..render.picture import LEGEND_PX, auto_scale, canvas_size_px
from ..settings import MachineSettings
from ..values import shown
from .maximus.resume import resume_board_job

__all__ = ["JobUnits", "HOLE_STATES", "TABLE_UNITS", "MAX_TRACK_POINTS", "job_units", "to_job_units", "job_track",
           "preview_frame", "remaining_time_s",
           "drill_holes", "hole_states", "hole_writes", "start_at_hole", "excellon_file_units"]

HOLE_STATES = ("to do", "drilling", "done", "skipped")
"""A hole's state in the hole table."""
TABLE_UNITS = {"mm": 1.0, "inch": 1 / 25.4, "mil": 1000 / 25.4}
"""The hole table's units: how many of each one mm is."""
MAX_TRACK_POINTS = 100_000
"""The most points :func:`job_track` sends: a longer path is thinned evenly (the page draws, it does not cut)."""
MM_PER_INCH = 25.4


@dataclass(frozen=True)
class JobUnits:
    """Where a job's own units lie in the machine frame: unit ``u`` of axis ``a`` is
    ``(machine_steps[a] - origin_steps[a]) / steps_per_unit[a]`` (a negative ``steps_per_unit``: the axis points the
    other way, as a drill file's Y up against the machine's Y toward the operator).

    Attributes:
        unit: what the numbers are ("px", "inch", "mm").
        origin_steps: the machine position (steps) of the units' zero.
        steps_per_unit: machine steps per unit, per axis (x, y, z).
        also: further units of the same frame, ``(name, how many per unit)`` (inch: ``("mil", 1000)``).
    """

    unit: str
    origin_steps: tuple[float, float, float]
    steps_per_unit: tuple[float, float, float]
    also: tuple[tuple[str, float], ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {"unit": self.unit, "origin_steps": list(self.origin_steps),
                "steps_per_unit": list(self.steps_per_unit), "also": [list(a) for a in self.also]}


def to_job_units(position_steps: Any, units: JobUnits) -> dict[str, Any]:
    """A machine position (steps) in the job's own units: ``{"unit": ..., "xyz": [x, y, z], OTHER: [...]}`` (one
    key per unit of ``units.also``), rounded to 4 decimals (pixels: whole pixels and a tenth).

    >>> u = JobUnits("px", (100, 200, 0), (10, 10, 5))
    >>> to_job_units((150, 260, 25), u)
    {'unit': 'px', 'xyz': [5.0, 6.0, 5.0]}
    >>> to_job_units((254, 0, 0), JobUnits("inch", (0, 0, 0), (100 * 25.4, -100 * 25.4, 100 * 25.4), (("mil", 1000),)))
    {'unit': 'inch', 'xyz': [0.1, -0.0, 0.0], 'mil': [100.0, -0.0, 0.0]}
    """
    pos = np.asarray(position_steps, np.float64).reshape(3)
    xyz = (pos - np.asarray(units.origin_steps, np.float64)) / np.asarray(units.steps_per_unit, np.float64)
    digits = 1 if units.unit == "px" else 4
    out: dict[str, Any] = {"unit": units.unit, "xyz": [round(float(v), digits) for v in xyz]}
    for name, per in units.also:
        out[name] = [round(float(v) * per, 2) for v in xyz]
    return out


def excellon_file_units(path: str, given: Optional[str] = None) -> str:
    """A drill file's unit, "inch" or "mm": ``given`` (the ``excellon_units`` option: "inch" or "metric") when
    set, else the first ``INCH`` / ``METRIC`` (``M72`` / ``M71``) of the file, else Excellon's default, inch.

    >>> import tempfile, os
    >>> f = tempfile.NamedTemporaryFile("w", suffix=".drl", delete=False); _ = f.write("M48\\nMETRIC,TZ\\nT1C0.8\\n%\\n"); f.close()
    >>> excellon_file_units(f.name), excellon_file_units(f.name, "inch"); os.unlink(f.name)
    ('mm', 'inch')
    """
    if given:
        return "inch" if str(given).lower().startswith("inch") else "mm"
    try:
        with open(path, "r", encoding="latin-1") as handle:
            head = handle.read(64 * 1024)
    except OSError as exc:
        raise CamError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    m = re.search(r"^\s*(INCH|METRIC|M72|M71)\b", head, re.MULTILINE | re.IGNORECASE)
    if m is None:
        return "inch"
    return "inch" if m.group(1).upper() in ("INCH", "M72") else "mm"


def drill_holes(job: Any, options: Any = None) -> Optional[dict[str, Any]]:
    """A drill job's holes in drilling order (None for another job, or one with slots or milled holes: no
    :attr:`~cam.kinds.jobs.PreparedJob.drill_plan`): ``{"board_mm": (N, 2) file frame X right, Y up, mm, "tools":
    (N,) tool numbers, "diameters_mm": (N,), "units": the file's unit, "origin_mm": (2,) machine mm from the job's
    home of the file's (0, 0), "sign_x": -1 when mirrored}``, read again from the file with ``options``' Excellon
    settings (a :class:`~cam.kinds.jobs.JobOptions`)."""
    plan = getattr(job, "drill_plan", None)
    if plan is None or not has(getattr(job, "kind", None), "holes"):
        return None
    units = getattr(options, "excellon_units", None)
    holes = load_excellon(job.source, excellon_units=units, excellon_digits=getattr(options, "excellon_digits", None),
                          excellon_zeros=getattr(options, "excellon_zeros", None))
    index = np.asarray(plan.hole_index, np.int64)
    board = np.asarray(holes.holes_mm, np.float64).reshape(-1, 2)[index]
    tools = np.asarray(holes.tool_of_hole, np.int64)[index]
    sign_x = -1.0 if getattr(options, "mirror_x", False) else 1.0
    machine = (np.asarray(plan.holes_mm, np.float64).reshape(-1, 2) if plan.holes_mm is not None else
               np.asarray(plan.holes_steps, np.float64).reshape(-1, 2) * np.asarray(job.settings.mm_per_step_axes[:2]))
    # machine x = ox + sign X, machine y = oy - Y (cam.job.drill): the file's zero from the first hole
    origin = (machine[0, 0] - sign_x * board[0, 0], machine[0, 1] + board[0, 1]) if len(board) else (0.0, 0.0)
    return {"board_mm": board, "tools": tools, "diameters_mm": np.array([holes.tools.get(int(t), 0.0) for t in tools]),
            "units": excellon_file_units(job.source, units), "origin_mm": origin, "sign_x": sign_x}


def job_units(job: Any, home_steps: Any, settings: MachineSettings, holes: Optional[dict[str, Any]] = None
              ) -> JobUnits:
    """The job's own units where it runs from ``home_steps`` (machine steps of its home): a drawing's pixels (its
    :class:`~cam.job.model.PixelFrame`), a drill file's board frame in the file's unit (``holes`` from
    :func:`drill_holes`), else mm from its home."""
    home = np.asarray(home_steps, np.float64).reshape(3)
    per = np.asarray(settings.mm_per_step_axes, np.float64)
    pixels = getattr(getattr(job, "toolpath", None), "pixels", None)
    if has(getattr(job, "kind", None), "pixels") and pixels is not None:
        scale = np.array([pixels.steps_per_px_xy, pixels.steps_per_px_xy, pixels.steps_per_px_z], np.float64)
        origin = home + np.asarray(pixels.origin_px, np.float64) * scale
        return JobUnits("px", tuple(float(v) for v in origin), tuple(float(v) for v in scale))
    if holes is not None:
        inch = holes["units"] == "inch"
        mm_per_unit = MM_PER_INCH if inch else 1.0
        ox, oy = holes["origin_mm"]
        origin = (home[0] + ox / per[0], home[1] + oy / per[1], home[2])
        spu = (holes["sign_x"] * mm_per_unit / per[0], -mm_per_unit / per[1], mm_per_unit / per[2])
        return JobUnits("inch" if inch else "mm", tuple(float(v) for v in origin), tuple(float(v) for v in spu),
                        (("mil", 1000.0),) if inch else ())
    return JobUnits("mm", tuple(float(v) for v in home), tuple(float(1 / p) for p in per))


def preview_frame(job: Any) -> dict[str, Any]:
    """Where the job's preview picture (:meth:`~cam.kinds.jobs.PreparedJob.preview_picture`) draws its moves: picture
    pixel ``(col, row) = origin_px + px_per_step * (x, y)`` for a point ``(x, y)`` in steps from the job's home, and
    the picture's ``width`` and ``height`` (the legend below it included), so a page can draw over the picture.

    The same arithmetic as the picture's: a drawing job held whole (:func:`cam.render.picture.toolpath_picture`:
    drawing pixel ``p`` at ``(p + 0.5) x scale``), any other job :func:`cam.kinds.jobs.motion_picture` (its extent,
    a 12-pixel margin, 800 pixels on the longer side).
    """
    toolpath = getattr(job, "toolpath", None)
    if has(getattr(job, "kind", None), "pixels") and isinstance(toolpath, Job) and toolpath.pixels:
        w, h = canvas_size_px(toolpath)
        k = auto_scale(w, h)
        per = toolpath.pixels.steps_per_px_xy
        return {"origin_px": [k // 2, k // 2], "px_per_step": [k / per, k / per],
                "width": max(w * k, 420), "height": h * k + LEGEND_PX}
    extent = np.asarray(job.extent_steps, np.int64)
    lo = extent[:2, 0]
    span = np.maximum(1, extent[:2, 1] - lo)
    margin, target = 12, 800
    k = (target - 2 * margin) / float(span.max())
    w = int(np.rint(span[0] * k)) + 2 * margin + 1
    h = int(np.rint(span[1] * k)) + 2 * margin + 1
    return {"origin_px": [float(margin - lo[0] * k), float(margin - lo[1] * k)], "px_per_step": [k, k],
            "width": max(w, 420), "height": h + LEGEND_PX}


def _cut_runs_steps(job: Any) -> list[np.ndarray]:
    """Each run of the job's path below the surface (:func:`cam.job.model.cut_runs_steps`), ``(N, 2)`` steps from
    the home; none for a job without a toolpath."""
    toolpath = getattr(getattr(job, "plan", None), "job", None) or getattr(job, "toolpath", None)
    return [] if toolpath is None else cut_runs_steps(toolpath)


def job_track(job: Any, home_steps: Any, settings: MachineSettings, holes: Optional[dict[str, Any]] = None
              ) -> dict[str, Any]:
    """What the page draws under the live tool: JSON-able, machine mm (x, y) where the job runs from
    ``home_steps``: ``cuts_mm`` (each run of the path below the surface, a hole's bottom one point; thinned evenly
    to at most :data:`MAX_TRACK_POINTS` points in all), ``holes_mm`` (a drill job's holes in drilling order, else
    []), ``home_mm`` and ``home_steps``, ``mm_per_step``, ``extent_mm`` ``[x0, y0, x1, y1]`` of both and the home,
    ``picture`` (:func:`preview_frame`: where the preview draws) and ``units`` (:func:`job_units`)."""
    per = np.asarray(settings.mm_per_step_axes, np.float64)
    home = np.asarray(home_steps, np.float64).reshape(3)
    runs = _cut_runs_steps(job)
    total = sum(len(r) for r in runs)
    every = max(1, -(-total // MAX_TRACK_POINTS))
    cuts = []
    for r in runs:
        kept = r if every == 1 or len(r) <= 2 else np.vstack([r[::every], r[-1:]])
        cuts.append(np.round((kept + home[:2]) * per[:2], 4))
    plan = getattr(job, "drill_plan", None)
    holes_mm = (np.round((np.asarray(plan.holes_steps, np.float64).reshape(-1, 2) + home[:2]) * per[:2], 4)
                if plan is not None else np.zeros((0, 2)))
    pts = np.vstack([np.zeros((0, 2))] + cuts + [holes_mm, (home[:2] * per[:2])[None]])
    units = job_units(job, home, settings, holes)
    return {"cuts_mm": [c.tolist() for c in cuts], "holes_mm": holes_mm.tolist(),
            "home_mm": [round(float(v), 4) for v in home * per], "home_steps": [int(v) for v in home],
            "mm_per_step": [float(v) for v in per], "picture": preview_frame(job),
            "extent_mm": [float(pts[:, 0].min()), float(pts[:, 1].min()), float(pts[:, 0].max()),
                          float(pts[:, 1].max())],
            "units": units.to_json(), "thinned": every > 1}


def hole_writes(job: Any) -> Optional[np.ndarray]:
    """``(N, 2)`` int64 for each hole of a step/dir drill job's plan, in drilling order: the write at which the tool
    stands above it (its drilling begins) and the write at which it is back up (done); None without a drill plan.
    A job started at a hole (:func:`start_at_hole`) has rows for the holes it drills only."""
    toolpath = getattr(job, "toolpath", None)
    if getattr(job, "drill_plan", None) is None and getattr(job, "resumed", None) is None:
        return None
    if toolpath is None:
        return None
    kinds = np.concatenate([np.asarray(p.kind, np.uint8) for p in toolpath.pieces()] or [np.zeros(0, np.uint8)])
    bottoms = np.flatnonzero(kinds == CUT)
    writes = np.asarray(job.plan.full_point_write(), np.int64)
    if not len(bottoms) or len(writes) != len(kinds):
        return np.zeros((0, 2), np.int64)
    before = writes[np.maximum(bottoms - 1, 0)]
    after = writes[np.minimum(bottoms + 1, len(writes) - 1)]
    return np.column_stack([before, after])


def hole_states(n_holes: int, *, first: int = 0, done: int = 0, drilling: bool = False) -> list[str]:
    """Each hole's state (:data:`HOLE_STATES`) in drilling order: the ``first`` holes skipped (a job started at hole
    ``first + 1``), the next ``done`` done, the one after them drilling when ``drilling``, the rest to do.

    >>> hole_states(5, first=1, done=2, drilling=True)
    ['skipped', 'done', 'done', 'drilling', 'to do']
    """
    out = ["skipped"] * min(first, n_holes)
    out += ["done"] * max(0, min(done, n_holes - len(out)))
    if drilling and len(out) < n_holes:
        out.append("drilling")
    return out + ["to do"] * (n_holes - len(out))


def start_at_hole(job: Any, hole: Any, position_steps: tuple[int, int, int], *, board: bool) -> Any:
    """The drill job ``job`` started at hole number ``hole`` (1-based, drilling order; the page's Start At), from
    where the tool stands (``position_steps``, steps from the job's home): the holes before it are skipped, and
    the run is the resume of a stop after them (the library's own resume: :func:`cam.kinds.jobs.resume_job` on a
    step/dir port, :func:`cam.drive.maximus.resume.resume_board_job` on a MAXIMUS board), so the tool lifts, travels
    to the hole and the hole's tool is asked for.

    Raises:
        PlanError: no drill plan, or ``hole`` not a whole number of the job's holes (one line).
    """
    plan = getattr(job, "drill_plan", None)
    if plan is None:
        raise PlanError(f"{getattr(job, 'name', 'the job')}: Start At needs a drill job of holes only (no slots or "
                        "milled holes)")
    n = len(np.asarray(plan.hole_index))
    if isinstance(hole, bool) or not isinstance(hole, int) or not 1 <= hole <= n:
        raise PlanError(f"hole must be a whole number 1..{n}, got {shown(hole)}")
    k = hole - 1
    base = dict(identity=job.identity, plan_sha256=job.plan_sha256, source=job.source, state="stopped",
                position_steps=tuple(int(v) for v in position_steps))
    if board:
        journal = Journal(moves=n, last_move=k - 1, holes_done=k,
                          hole_order=tuple(int(v) for v in np.asarray(plan.hole_index).tolist()), **base)
        out = resume_board_job(job, journal, where=f"Start At hole {hole}")
    else:
        toolpath = job.toolpath
        kinds = np.concatenate([np.asarray(p.kind, np.uint8) for p in toolpath.pieces()])
        pauses = np.concatenate([np.asarray(p.pause, bool) for p in toolpath.pieces()])
        last = int(np.flatnonzero(kinds == CUT)[k]) - 2  # the point before the travel to the hole
        journal = Journal(moves=len(kinds), last_move=last, pause_pending=bool(pauses[last]), **base)
        out = resume_job(job, journal, position_steps=base["position_steps"], where=f"Start At hole {hole}")
    report = dict(out.report, started_at_hole=hole)
    return dataclasses.replace(out, report=report, summary=f"{job.summary}, started at hole {hole} of {n}")


def remaining_time_s(machine_s_left: float, feed_override_pct: Optional[float] = None) -> float:
    """The time a running job has left, as a page shows it (issue #47 point 7): its machine time left (which stands
    still while the job is paused or waits at a prompt) at the feed override (``None``: none, 100 %); an estimate
    that stretches the rapids with the feeds.

    >>> remaining_time_s(60.0), remaining_time_s(60.0, 50), remaining_time_s(60.0, 200)
    (60.0, 120.0, 30.0)
    """
    pct = 100.0 if feed_override_pct is None else float(feed_override_pct)
    if not pct > 0:
        raise PlanError(f"feed_override_pct must be > 0, got {shown(feed_override_pct)}")
    return round(max(0.0, float(machine_s_left)) * 100.0 / pct, 2)
