"""Probing: find the work's surface with a touch probe (issue #46 points 1 and 3).

A probe moves Z down (+Z, deeper) at the probe feed until the probe input closes, at most a bounded depth, and
notes where it closed (the *contact*, machine steps), then lifts back to where it began.  One probing activity of
the machine session (:meth:`cam.drive.session.MachineSession.probe_z`, ``probe_grid``) probes one point where the
tool stands, or a grid of points, each from a safe height (travelled to at that height, lifted back to it after
the probe: no move between points below it).  The e-stop, a stop and the limit switches are served throughout.

Each machine does its part through a *prober* (:class:`Prober`: travel, probe, close):

* a step/dir port (:class:`StepDirProber`: the mock, a parallel port): probing is homing-like, a run of
  :func:`cam.drive.homing.seek` on Z toward +Z at the probe feed that ends at the first step where the probe
  input (``[inputs] probe``) is closed; the mock closes it at the machine file's ``[mock] probe_surface``
  (:class:`~cam.drive.ports.SwitchSchedule`).  The feed is at most Z's start speed, so Z stops at once;
* grbl (:mod:`cam.drive.grbl_probe`): ``G38.2`` and its ``[PRB:x,y,z:1]``;
* the MAXIMUS board and the ``cmd:`` control unit have no probe input: refused in one line (capability
  ``probes``).

A probe that does not touch within its depth ends the activity in one line (:class:`ProbeError`), the tool
lifted back and its position known.  Frames: machine steps, +Z deeper; a contact at ``z_steps`` is the height
``-z_steps * mm_per_step_z`` mm (up positive).

The grid's geometry (:func:`grid_axis_mm`, :func:`serpentine`, :func:`job_area_mm`) is here too; its height map
is :class:`cam.job.heightmap_level.HeightMap`.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence

import numpy as np

from ..errors import CamError, CapabilityError, PlanError
from ..job.model import cut_runs_steps, travel_job
from ..settings import INPUT_BITS, MachineSettings
from ..motion.chunks import plan_chunks
from .homing import seek
from .machines import open_port
from .placement import placed_kinds, placed_home
from .ports import MockPort, SwitchSchedule
from .runner import EMERGENCY_STOPPED, FINISHED, LIMIT_STOPPED, STOPPED, SWITCHED, Controller, run

__all__ = ["ProbeError", "ProbeResult", "ProbeRun", "Prober", "StepDirProber", "probe_worker", "DEFAULT_FEED_MM_MIN",
           "DEFAULT_DEPTH_MM", "check_step_dir_probe", "grid_axis_mm", "serpentine", "job_area_mm", "job_cuts_mm",
           "start_probe_on_steps", "step_dir_feed"]

Steps3 = tuple[int, int, int]

DEFAULT_FEED_MM_MIN = 20.0
"""The probe feed when none is given (mm/min; on a step/dir machine at most Z's start speed)."""
DEFAULT_DEPTH_MM = 5.0
"""How far ``cam probe z`` probes down at most when no depth is given (mm)."""


class ProbeError(CamError):
    """A probe that could not be made or found nothing: refused before anything moved (no probe input, a feed too
    fast, the probe closed before it moved) or no contact within its depth.  The position stays known."""


class ProbeEnded(CamError):
    """A run of the probing activity ended before its end: a stop, an emergency stop or a limit switch
    (``status``: the runner's)."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class ProbeResult:
    """One probe, machine frame (steps, +Z deeper): where it began, where the probe first touched (None: no contact
    within ``depth_steps``), and where the tool stands after its lift.  ``note``: what the machine said of a
    probe that found nothing (grbl's alarm), else ""."""

    start_steps: Steps3
    contact_steps: Optional[Steps3]
    end_steps: Steps3
    depth_steps: int
    note: str = ""

    @property
    def touched(self) -> bool:
        return self.contact_steps is not None

    def height_mm(self, settings: MachineSettings) -> float:
        """The contact's height in mm, up positive (``-z * mm_per_step_z``)."""
        if self.contact_steps is None:
            raise ProbeError("this probe found no contact")
        return -int(self.contact_steps[2]) * settings.mm_per_step_z

    def as_dict(self) -> dict[str, Any]:
        return {"start_steps": list(self.start_steps), "end_steps": list(self.end_steps),
                "contact_steps": None if self.contact_steps is None else list(self.contact_steps),
                "depth_steps": int(self.depth_steps)}


@dataclass(frozen=True)
class ProbeRun:
    """What one probing activity does: probe each of ``points`` (machine X, Y in steps; None: where the tool
    stands) from ``safe_z_steps`` (machine Z; None: from where the tool stands), at most ``depth_steps`` deeper,
    at ``feed_mm_min``; each probe lifts back to where it began.

    ``approach``: a grid whose points are each a neighbour of the one before (a
    :class:`~cam.drive.probe_grid.GridApproach`): only its first point is probed from ``safe_z_steps``; each later
    one is travelled to at a clearance above the contacts so far, approached down to just above the surface
    expected there (a rapid as far as the map's neighbour limit allows, then a guarded move at the approach's feed
    that stops where the probe closes) and probed from there with a bounded depth (never below ``safe_z_steps +
    depth_steps``).  None: every point from ``safe_z_steps``."""

    points: tuple[Optional[tuple[int, int]], ...]
    depth_steps: int
    feed_mm_min: float
    safe_z_steps: Optional[int] = None
    label: str = "probe Z"
    approach: Any = None


class Prober:
    """A machine's part of probing (one per activity, made in its worker thread).  Positions machine frame."""

    def position(self) -> Steps3:
        """Where the tool stands now."""
        raise NotImplementedError

    def travel(self, target_steps: Steps3) -> None:
        """Go to ``target_steps``: up to its Z first when deeper, across at that height, then down to it."""
        raise NotImplementedError

    def probe(self, depth_steps: int, feed_mm_min: float) -> ProbeResult:
        """Probe down at most ``depth_steps`` at ``feed_mm_min`` and lift back to where it began.

        Raises:
            ProbeError: the probe was closed before it moved; ProbeEnded: a stop, an emergency stop, a limit."""
        raise NotImplementedError

    def descend(self, depth_steps: int, feed_mm_min: float) -> Optional[Steps3]:
        """Move down at most ``depth_steps`` at ``feed_mm_min``, stopping where the probe closes (a guarded move:
        a surface higher than expected stops it, it never runs into it); no lift.  Returns where the probe
        closed, or None (the tool then ``depth_steps`` lower).

        Raises:
            ProbeError: the probe was closed before it moved; ProbeEnded: a stop, an emergency stop, a limit."""
        raise NotImplementedError

    def close(self, ctl: Any, fault: str) -> tuple[Optional[Steps3], str]:
        """After the last move: ``(where the tool stands or None when unknown, why the position is lost or "")``;
        ``fault``: an error that ended the activity mid-move ("" none)."""
        raise NotImplementedError


def step_dir_feed(settings: MachineSettings, feed_mm_min: Optional[float]) -> float:
    """The probe feed on a step/dir machine: ``feed_mm_min`` (default :data:`DEFAULT_FEED_MM_MIN`, or Z's start
    speed when that is slower), at most Z's start speed so that Z stops on the step the probe closes.

    Raises:
        ProbeError: a feed faster than Z's start speed (one line naming both)."""
    most = settings.start_speed_z_mm_s * 60.0
    if feed_mm_min is None:
        return min(DEFAULT_FEED_MM_MIN, most)
    if feed_mm_min > most + 1e-9:
        raise ProbeError(f"a probe feed of {feed_mm_min:g} mm/min is faster than Z's start speed ({most:.4g} mm/min, "
                         f"start_speed_z_mm_s): a step/dir drive stops on the step the probe closes only up to it; "
                         f"give a feed of at most {most:.4g}")
    return float(feed_mm_min)


class StepDirProber(Prober):
    """Probing on a step/dir port (the mock with its simulated probe, or a parallel port): every move is a run of
    the runner on one open port, so a mock's pin log holds them all on one time line."""

    def __init__(self, session: Any, port: Any, ctl: Controller) -> None:
        self.settings: MachineSettings = session.settings
        self.realtime = bool(session.realtime)
        self.ctl = ctl
        self.opened = open_port(port, self.settings)
        self.own_port = not isinstance(port, MockPort) and self.opened is not port
        self.pos = np.asarray(session.position_steps(), np.int64).copy()
        self.in_run = False  # a run was under way when an error came: where the tool is, nobody knows

    @classmethod
    def on_port(cls, port: Any, settings: MachineSettings, realtime: bool, ctl: Any,
                position_steps: Steps3) -> "StepDirProber":
        """A prober on a port that is open already (a job's, while it waits at a tool change: never closed
        here), the tool at ``position_steps`` (machine frame)."""
        self = cls.__new__(cls)
        self.settings, self.realtime, self.ctl = settings, bool(realtime), ctl
        self.opened, self.own_port = port, False
        self.pos = np.asarray(position_steps, np.int64).copy()
        self.in_run = False
        return self

    def position(self) -> Steps3:
        return tuple(int(v) for v in self.pos)  # type: ignore[return-value]

    def _ended(self, result: Any, what: str) -> None:
        if result.status not in (FINISHED, SWITCHED):
            raise ProbeEnded(result.status, f"{what}: " + "; ".join(result.messages or [result.status]))

    def _moves(self, rel_steps: Sequence[Sequence[int]], what: str) -> None:
        """A travel through points relative to where the tool stands (the machine's ramps and speeds)."""
        if not len(rel_steps):
            return
        self.in_run = True
        plan = plan_chunks(travel_job(np.asarray(rel_steps, np.int64).reshape(-1, 3), self.settings, source=what),
                           start_steps=self.position())
        result = run(plan, self.opened, realtime=self.realtime, controller=self.ctl)
        if isinstance(self.opened, MockPort):  # the next run's writes go on from this one's time
            self.opened.time_offset_ns += int(round(result.machine_time_s * 1e9)) + int(self.settings.delay_xy_ns)
        self.pos = self.pos + np.asarray(result.position_steps, np.int64)
        self.in_run = False
        self._ended(result, what)

    def travel(self, target_steps: Steps3) -> None:
        x, y, z = (int(v) for v in target_steps)
        x0, y0, z0 = self.position()
        rel: list[tuple[int, int, int]] = []
        if z0 > z:  # deeper than the safe height: up first
            rel.append((0, 0, z - z0))
        if (x, y) != (x0, y0):
            rel.append((x - x0, y - y0, z - z0 if z0 > z else 0))
        if z0 < z:  # above it: across first, then down to it
            rel.append((x - x0, y - y0, z - z0))
        self._moves(rel, "to the next probe point")

    def probe(self, depth_steps: int, feed_mm_min: float) -> ProbeResult:
        start = self.position()
        contact = self.descend(depth_steps, feed_mm_min)
        self._moves([(0, 0, start[2] - int(self.pos[2]))] if int(self.pos[2]) != start[2] else [], "probe lift")
        return ProbeResult(start, contact, self.position(), int(depth_steps))

    def descend(self, depth_steps: int, feed_mm_min: float) -> Optional[Steps3]:
        start = self.position()
        if self.opened.reads_inputs and _probe_closed(self.opened.read_inputs(), self.settings):
            raise ProbeError(f"the probe (inputs.probe) is closed before probing at machine Z {start[2]} steps: the "
                             f"tool touches the work already, or the pin is wired or set the wrong way round "
                             f"(\"!N\" active low); lift the tool and probe again")
        self.in_run = True
        result = seek(self.opened, self.settings, 2, int(depth_steps), feed_mm_min / 60.0, until=("probe", True),
                      realtime=self.realtime, controller=self.ctl, source="probe")
        self.in_run = False
        self.pos = self.pos + np.asarray(result.position_steps, np.int64)
        if result.status not in (SWITCHED, FINISHED):
            raise ProbeEnded(result.status, "probing: " + "; ".join(result.messages or [result.status]))
        return self.position() if result.status == SWITCHED else None

    def close(self, ctl: Any, fault: str) -> tuple[Optional[Steps3], str]:
        if self.own_port:
            try:
                self.opened.close()
            except CamError as exc:
                fault = fault or str(exc)
        lost = f"probing failed while moving ({fault})" if fault and self.in_run else ""
        return self.position(), lost


def _probe_closed(levels: int, settings: MachineSettings) -> bool:
    """Whether the probe input reads closed in ``levels`` (a port's :meth:`~cam.drive.ports.Port.read_inputs`)."""
    pin, high = settings.inputs.wired()["probe"]
    return bool(levels & (1 << INPUT_BITS[pin])) == high


def check_step_dir_probe(session: Any) -> None:
    """A step/dir machine's probe is there: a probe input in ``[inputs]`` and, on the mock, a simulated surface.

    Raises:
        ProbeError: no probe input wired; CapabilityError: the mock without a probe surface."""
    s = session.settings
    if "probe" not in s.inputs.wired():
        raise ProbeError("no probe input in the machine file: wire it in [inputs] (probe = \"!13\", a pin of its "
                         "own; see docs/machine-and-ports.md)")
    if session.backend.can("simulated", session.port) and s.mock.surface() is None:
        raise CapabilityError("the mock port has no surface to probe: give it in the machine file's [mock] "
                              "table (probe_surface = \"z0,ax,ay,b,cx,cy\"; see docs/machine-and-ports.md)")


def start_probe_on_steps(session: Any, probe_run: ProbeRun) -> None:
    """Start a probing activity on a step/dir port (the step/dir back ends' ``start_probe``): the probe input and,
    on the mock, its simulated surface checked first; the feed checked against Z's start speed.

    Raises:
        ProbeError: no probe input wired, a feed too fast; CapabilityError: the mock without a probe surface."""
    s = session.settings
    check_step_dir_probe(session)
    feed = step_dir_feed(s, probe_run.feed_mm_min)
    port: Any = session.port
    if session.backend.can("simulated", session.port):
        switches = SwitchSchedule(s, tuple(int(v) for v in session.position_steps()))
        if isinstance(session.port, MockPort):
            session.port.switches = switches
        else:
            port = MockPort(switches=switches)
    run_ = dataclasses.replace(probe_run, feed_mm_min=feed)
    ctl = Controller()
    session._launch_probe(run_, ctl, lambda: StepDirProber(session, port, ctl))


def _mm(v: float) -> str:
    return f"{v:.4f}".rstrip("0").rstrip(".") if abs(v) >= 5e-5 else "0"


def point_line(k: int, n: int, r: ProbeResult, settings: MachineSettings, reference_steps: Optional[int]) -> str:
    """The progress line of probe ``k`` (0-based) of ``n``."""
    x, y = r.start_steps[0] * settings.mm_per_step_axes[0], r.start_steps[1] * settings.mm_per_step_axes[1]
    where = f"probe {k + 1}/{n} at X={_mm(x)} Y={_mm(y)} mm"
    if r.contact_steps is None:
        return f"{where}: no contact"
    h = r.height_mm(settings)
    above = "" if reference_steps is None else \
        f", {_mm(h + reference_steps * settings.mm_per_step_z)} mm from the work Z zero"
    return f"{where}: surface at height {_mm(h)} mm (machine Z {r.contact_steps[2]} steps{above})"


def missed_line(r: ProbeResult, settings: MachineSettings) -> str:
    """The one line of a probe that touched nothing."""
    per = settings.mm_per_step_z
    lowest = r.start_steps[2] + r.depth_steps
    return (f"probe: no contact within {_mm(r.depth_steps * per)} mm below height {_mm(-r.start_steps[2] * per)} mm "
            f"(machine Z {r.start_steps[2]} steps): the tool went down to height {_mm(-lowest * per)} mm and is back "
            f"at {_mm(-r.end_steps[2] * per)} mm, position known" + (f" ({r.note})" if r.note else "")
            + "; probe from lower down or give a larger depth")


def _approach(prober: Prober, probe_run: ProbeRun, xy: tuple[int, int], results: Sequence[ProbeResult]) -> int:
    """A grid's later point approached (:meth:`cam.drive.probe_grid.GridApproach.heights`): across at the travel
    height, a rapid down to the guard height, a guarded move down to where the probe starts (a surface higher than
    expected stops it: the probe then starts the approach above that contact).  Returns the probe's depth."""
    a = probe_run.approach
    travel_z, guard_z, start_z, depth = a.heights([int(r.contact_steps[2]) for r in results],  # type: ignore
                                                  probe_run.safe_z_steps + probe_run.depth_steps)  # type: ignore
    lowest = start_z + depth
    prober.travel((xy[0], xy[1], travel_z))
    prober.travel((xy[0], xy[1], guard_z))
    if start_z > guard_z:
        touched = prober.descend(start_z - guard_z, max(float(a.feed_mm_min), float(probe_run.feed_mm_min)))
        if touched is not None:  # higher than expected: the probe starts the approach above where it touched
            start_z = max(travel_z, int(touched[2]) - a.approach_steps)
            prober.travel((xy[0], xy[1], start_z))
    return max(1, lowest - start_z)


def activity_end(exc: BaseException) -> tuple[str, list[str], str]:
    """How a probing activity (points, or a program's parts and probes) that raised ``exc`` ended: its status,
    its one-line messages and the link fault it leaves ("" none: the position is still known)."""
    if isinstance(exc, ProbeEnded):
        return exc.status, [str(exc)], ""
    if isinstance(exc, ProbeError):
        return "error", [str(exc)], ""
    if isinstance(exc, CamError):
        return "error", [str(exc)], str(exc)
    line = f"internal error: {type(exc).__name__}: {exc}"
    return "error", [line], line


def halted_status(ctl: Any, status: str) -> str:
    """``status``, or what the controller ``ctl`` says ended the activity: an emergency stop, or a stop that
    made it fail."""
    if getattr(ctl, "estop_requested", False) or getattr(ctl, "estopped", False):
        return EMERGENCY_STOPPED
    if status == "error" and getattr(ctl, "halted", False):
        return STOPPED
    return status


def probe_worker(session: Any, ctl: Any, make_prober: Callable[[], Prober], probe_run: ProbeRun) -> None:
    """The worker thread of a probing activity: each point travelled to (at the safe height, or a grid's later
    points as its ``approach`` says) and probed, a detail line per point, then the end booked
    (:meth:`~cam.drive.session.MachineSession.finish`): the results in
    ``last_run["probe"]`` and the session's ``last_probe``."""
    s = session.settings
    start = session.position_steps()
    st = session.state_hold.state if session.state_hold is not None else None
    reference = None if st is None else int(st.work_zero_steps()[2])
    results: list[ProbeResult] = []
    status, messages, fault = FINISHED, [], ""
    prober: Optional[Prober] = None
    n = len(probe_run.points)
    try:
        prober = make_prober()
        for k, xy in enumerate(probe_run.points):
            depth = probe_run.depth_steps
            if xy is not None and probe_run.approach is not None and results and probe_run.safe_z_steps is not None:
                depth = _approach(prober, probe_run, (int(xy[0]), int(xy[1])), results)
            elif xy is not None:
                z = probe_run.safe_z_steps if probe_run.safe_z_steps is not None else prober.position()[2]
                prober.travel((int(xy[0]), int(xy[1]), int(z)))
            r = prober.probe(depth, probe_run.feed_mm_min)
            results.append(r)
            session.progress(k + 1, n, 0)
            if not r.touched:  # the end's one line says it
                raise ProbeError(missed_line(r, s))
            session.detail(point_line(k, n, r, s, reference))
    except Exception as exc:  # noqa: BLE001 - reported in the log; nothing more is sent
        status, messages, fault = activity_end(exc)
    status = halted_status(ctl, status)
    end: Optional[Steps3] = start
    lost = ""
    if prober is not None:
        try:
            end, lost = prober.close(ctl, fault if status == "error" else "")
        except CamError as exc:
            end, lost = None, str(exc)
    if lost and status not in (EMERGENCY_STOPPED, LIMIT_STOPPED):
        status, messages = "error", [lost]
    moved = None if end is None else np.asarray(end, np.int64) - np.asarray(start, np.int64)
    info = {"activity": "probe", "label": probe_run.label, "status": status, "messages": messages,
            "probe": [r.as_dict() for r in results]}
    with session._lock:
        session._last_probe = list(results)
        if lost and session._activity is not None:  # the end booked keeps the position unknown
            session._activity.unknown_reason = lost
    session.finish(info, moved)
    text = f"{probe_run.label}: {status}" + (f" ({'; '.join(messages)})" if messages else "")
    session.log(text, "info" if status == FINISHED else "warning" if status == STOPPED else "error")


# -- the grid ------------------------------------------------------------------------------------------------

def grid_axis_mm(lo_mm: float, hi_mm: float, spacing_mm: float) -> np.ndarray:
    """Points ``spacing_mm`` apart that cover ``lo_mm..hi_mm``, centred on it (the last one past ``hi_mm`` by as
    much as the first before ``lo_mm``); at least two (a map is a grid of cells).

    >>> grid_axis_mm(0.0, 20.0, 10.0).tolist()
    [0.0, 10.0, 20.0]
    >>> grid_axis_mm(0.0, 15.0, 10.0).tolist()
    [-2.5, 7.5, 17.5]
    >>> grid_axis_mm(5.0, 5.0, 10.0).tolist()
    [0.0, 10.0]
    """
    if not (math.isfinite(lo_mm) and math.isfinite(hi_mm) and lo_mm <= hi_mm):
        raise PlanError(f"the area's low end must not be above its high end, got {lo_mm:g}..{hi_mm:g} mm")
    if not (math.isfinite(spacing_mm) and spacing_mm > 0):
        raise PlanError(f"the spacing must be a number > 0 mm, got {spacing_mm}")
    n = max(1, int(math.ceil((hi_mm - lo_mm) / spacing_mm - 1e-9)))
    first = lo_mm - (n * spacing_mm - (hi_mm - lo_mm)) / 2.0
    return first + spacing_mm * np.arange(n + 1, dtype=np.float64)


def serpentine(nx: int, ny: int) -> list[tuple[int, int]]:
    """The order a grid of ``nx`` by ``ny`` points is probed in, as ``(i, j)`` (column, row): row by row, each
    row the other way round from the one before (no travel back across the board between rows).

    >>> serpentine(3, 2)
    [(0, 0), (1, 0), (2, 0), (2, 1), (1, 1), (0, 1)]
    """
    return [(i if j % 2 == 0 else nx - 1 - i, j) for j in range(ny) for i in range(nx)]


def _home_of(job: Any, state: Any, origin: Optional[str]) -> tuple[int, int, int]:
    """Where (machine steps) a prepared job's home stands when it runs: see :func:`job_area_mm`."""
    kind = getattr(job, "kind", "")
    return placed_home(job, state, origin) if kind in placed_kinds() else tuple(state.position_steps)


def job_cuts_mm(job: Any, state: Any, settings: MachineSettings, origin: Optional[str] = None) -> list[np.ndarray]:
    """What a prepared job cuts, where it would run (placed as :func:`job_area_mm` places it): each run of
    consecutive points below the surface (``z > 0`` from the job's home) as an ``(N, 2)`` float64 polyline of
    machine X, Y in mm, in the order cut (N >= 1: a hole's bottom is one point).  Read a piece at a time from the
    job's plan (a run across two pieces is one)."""
    hx, hy, _ = _home_of(job, state, origin)
    per = settings.mm_per_step_axes
    runs = cut_runs_steps(job.plan.job)
    return [np.column_stack([(hx + r[:, 0]) * per[0], (hy + r[:, 1]) * per[1]]) for r in runs]


def job_area_mm(job: Any, state: Any, settings: MachineSettings, origin: Optional[str] = None
                ) -> tuple[float, float, float, float]:
    """The XY extent ``(x0, y0, x1, y1)`` in machine mm of what a prepared job cuts (its moves below the surface;
    all its moves when it cuts nothing) where it would run: a drawing, drill, HPGL or SVG file placed at the active
    work zero (:func:`cam.drive.placement.placed_home`, ``origin`` as ``cam drill --origin``), a G-code program
    from where the tool stands (its own work offsets place it)."""
    home = _home_of(job, state, origin)
    extent, cut = job.plan.motion_extent()
    box = cut if cut[2, 1] > 0 else extent
    per = settings.mm_per_step_axes
    x0, x1 = ((int(home[0]) + int(v)) * per[0] for v in box[0])
    y0, y1 = ((int(home[1]) + int(v)) * per[1] for v in box[1])
    return x0, y0, x1, y1
