"""A part of :class:`~cam.drive.session.MachineSession`: probing the work's surface (issue #46 points 1 and 3).

:meth:`SessionProbe.probe_z` probes down where the tool stands, :meth:`SessionProbe.probe_grid` a grid of points
from a safe height, both one activity in the background (its worker :func:`cam.drive.probing.probe_worker`,
stoppable, the e-stop served), done by the port's back end (``start_probe``: capability ``probes``; the MAXIMUS
board and the ``cmd:`` control unit refuse in one line).  :meth:`SessionProbe.set_work_z` puts the active work
offset's Z zero at a probed height; :meth:`SessionProbe.probe_work_z` probes and sets it in one activity (remembering
the contact in the state file, :class:`~cam.drive.state.ToolProbe`), :meth:`SessionProbe.probe_tool` probes the next
tool at that contact's X, Y and shifts the work Z by the difference of the contacts (a tool change).

Like the other parts it keeps no state of its own but ``_last_probe`` (the results of the last probing): it works on
the attributes ``MachineSession.__init__`` sets (``port``, ``backend``, ``settings``, ``state_hold``, ``grbl``,
``_lock``, ``_position``) and calls the session's methods (``_check_free``, ``_require_known``, ``_begin``,
``_spawn``, ``wait_idle``, ``log``, ``_bump``).  Frames: machine steps, +Z deeper.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Callable, Optional, Sequence

import numpy as np

from ..errors import CamError, PlanError
from ..job.heightmap_level import save_height_map
from ..values import shown
from ._session_parts import Activity
from .probe_grid import GridApproach, GridPlan, grid_plan, height_map_of
from .probing import (
    DEFAULT_DEPTH_MM, ProbeError, Prober, ProbeResult, ProbeRun, probe_worker,
)
from .state import ToolProbe, check_in_travel, steps_to_mm

__all__ = ["SessionProbe"]

MAX_PROBE_POINTS = 100_000
"""The most points one grid may probe."""

DEFAULT_TOOL_CLEARANCE_MM = 5.0
"""``probe_tool`` starts this far above the first tool's contact and probes at most this far below it: a new tool
up to this much longer or shorter than the one that set the work Z is found."""


def _plate(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(float(value)) and 0 <= float(value) <= 1000):
        raise PlanError(f"the plate's thickness must be a number of mm 0..1000, got {shown(value)}")
    return float(value)


def _depth(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 < int(value) <= 10**9:
        raise PlanError(f"max_depth_steps must be a whole number of steps > 0, got {shown(value)}")
    return int(value)


def _feed(value: Any) -> Optional[float]:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(float(value)) and 0 < float(value) <= 1e5):
        raise PlanError(f"the probe feed must be a number of mm/min > 0 (at most 100000), got {shown(value)}")
    return float(value)


def _clearance(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not (math.isfinite(float(value)) and 0 < float(value) <= 1000):
        raise PlanError(f"clearance_mm must be a number of mm > 0 (at most 1000), got {shown(value)}")
    return float(value)


class SessionProbe:
    """Probe Z where the tool stands or over a grid, and set the work Z zero from a probe (a mixin; see the
    module)."""

    _last_probe: Optional[list[ProbeResult]] = None
    last_map: Any = None
    """The height map the last :meth:`probe_map` wrote (a :class:`~cam.job.heightmap_level.HeightMap`; None: none
    yet) and :attr:`last_map_path` where."""
    last_map_path: Optional[str] = None

    @property
    def last_probe(self) -> Optional[list[ProbeResult]]:
        """The probes of the last probing activity, in the order they were made (None: none ran yet)."""
        with self._lock:
            return None if self._last_probe is None else list(self._last_probe)

    def probe_z(self, feed_mm_min: Optional[float] = None, max_depth_steps: Optional[int] = None, *,
                wait: bool = True) -> Optional[ProbeResult]:
        """Probe down where the tool stands: Z moves down (+Z) at ``feed_mm_min`` (None: the machine's default,
        :func:`cam.drive.probing.step_dir_feed`) until the probe touches, at most ``max_depth_steps`` (None:
        :data:`~cam.drive.probing.DEFAULT_DEPTH_MM`), then lifts back to where it began.

        Returns:
            with ``wait`` the :class:`~cam.drive.probing.ProbeResult` (its ``contact_steps``: machine frame); else
            None at once (the result then in :attr:`last_probe` and ``last_run["probe"]`` when it has ended).

        Raises:
            CapabilityError: a machine with no probe (MAXIMUS, ``cmd:``), the mock without a probe surface;
            ProbeError: no probe input, a feed too fast, or (``wait``) a probe that did not touch, was stopped or
            failed (one line; the position stays known but after an emergency stop or a limit switch);
            PlanError, TravelError, BusyError, PositionUnknownError (nothing moves).
        """
        depth = _depth(max_depth_steps if max_depth_steps is not None
                       else int(round(DEFAULT_DEPTH_MM / self.settings.mm_per_step_z)))
        self.start_probe(ProbeRun((None,), depth, _feed(feed_mm_min), None, "probe Z"))
        if not wait:
            return None
        return self._probe_results()[0]

    def probe_grid(self, points_steps: Sequence[Sequence[int]], safe_z_steps: int, max_depth_steps: int,
                   feed_mm_min: Optional[float] = None, *, approach: Optional[GridApproach] = None,
                   wait: bool = True) -> Optional[list[ProbeResult]]:
        """Probe each of ``points_steps`` (machine X, Y in steps, in the order given): up to ``safe_z_steps``
        (machine Z) first, across at that height, probe down at most ``max_depth_steps`` and lift back to it.
        With ``approach`` (:class:`~cam.drive.probe_grid.GridApproach`; the points a grid's, each a neighbour of
        the one before) only the first point is probed so; each later one is travelled to at a clearance above the
        contacts so far, rapided down to just above the surface expected there and probed from there, its depth
        bounded (see :mod:`cam.drive.probe_grid`).  A point that does not touch ends the grid in one line
        (ProbeError, with ``wait``).

        Returns:
            with ``wait`` one :class:`~cam.drive.probing.ProbeResult` per point; else None (see :meth:`probe_z`)."""
        pts = [(int(p[0]), int(p[1])) for p in points_steps]
        if not 0 < len(pts) <= MAX_PROBE_POINTS:
            raise PlanError(f"a probe grid has 1..{MAX_PROBE_POINTS} points, got {len(pts)}")
        if isinstance(safe_z_steps, bool) or not isinstance(safe_z_steps, (int, np.integer)):
            raise PlanError(f"safe_z_steps must be a whole number of steps, got {shown(safe_z_steps)}")
        if approach is not None and not isinstance(approach, GridApproach):
            raise PlanError(f"approach must be a GridApproach or None, got {shown(approach)}")
        run = ProbeRun(tuple(pts), _depth(max_depth_steps), _feed(feed_mm_min), int(safe_z_steps),
                       f"probe grid of {len(pts)} points", approach)
        self.start_probe(run)
        if not wait:
            return None
        return self._probe_results()

    def probe_work_z(self, plate_mm: float = 0.0, feed_mm_min: Optional[float] = None,
                     max_depth_steps: Optional[int] = None, *, wait: bool = True) -> Optional[ProbeResult]:
        """:meth:`probe_z`, then (when it touched) the active work offset's Z zero ``plate_mm`` below the contact
        (:meth:`set_work_z`; ``cam probe z``, the page's Probe Z), and with a state file the contact kept there
        (:class:`~cam.drive.state.ToolProbe`) for :meth:`probe_tool` after a tool change.

        Returns:
            with ``wait`` the probe; else None (the work Z is set when the activity finishes)."""
        plate = _plate(plate_mm)
        per = self.settings.mm_per_step_z

        def then() -> None:
            contact = self._last_probe[0].contact_steps  # type: ignore[index]
            zero_z = int(contact[2]) + int(round(plate / per))
            self._after_probe("probe Z", zero_z, ToolProbe(tuple(int(v) for v in contact), plate))  # type: ignore

        with self._lock:  # the end's hook set before the worker can book its end
            self.probe_z(feed_mm_min, max_depth_steps, wait=False)
            self._then = then
        return self._probe_results()[0] if wait else None

    def probe_tool(self, plate_mm: Optional[float] = None, feed_mm_min: Optional[float] = None, *,
                   clearance_mm: float = DEFAULT_TOOL_CLEARANCE_MM, wait: bool = True) -> Optional[ProbeResult]:
        """After a tool change: probe the new tool where the tool that set the work Z touched (the state file's
        :class:`~cam.drive.state.ToolProbe`, kept by :meth:`probe_work_z`), on the same plate or sensor, and shift
        the active work offset's Z by the difference of the contacts (new minus old; a different ``plate_mm``,
        default the recorded one, counted in), so the new tool's tip is at the same work Z.  The tool goes there
        lifted (the higher of where it stands and ``clearance_mm`` above the old contact), probes at most
        ``clearance_mm`` below the old contact, lifts back to that height and stays there; the contact kept is the
        new tool's.

        Returns:
            with ``wait`` the probe; else None (the work Z is shifted when the activity finishes).

        Raises:
            PlanError: no state file, or no probe of a first tool in it (``cam probe z`` first); the rest as
            :meth:`probe_grid`."""
        self.backend.require(self.port, "probes", "probing")  # a machine that cannot probe: that first
        hold = self.state_hold
        old = None if hold is None else hold.state.tool_probe
        if old is None:
            raise PlanError("no tool has set the work Z by probing on this machine (or its position was said anew "
                            "since): probe the first tool with cam probe z (the page's Probe Z) on the plate first")
        plate = old.plate_mm if plate_mm is None else _plate(plate_mm)
        per = self.settings.mm_per_step_z
        clear = max(1, int(round(_clearance(clearance_mm) / per)))
        x, y, z_old = (int(v) for v in old.contact_steps)
        old_surface = z_old + int(round(old.plate_mm / per))

        def then() -> None:
            contact = self._last_probe[0].contact_steps  # type: ignore[index]
            shift = int(contact[2]) + int(round(plate / per)) - old_surface
            zero_z = int(hold.state.work_zero_steps()[2]) + shift
            self._after_probe("probe tool", zero_z, ToolProbe(tuple(int(v) for v in contact), plate),  # type: ignore
                              f"; the new tool's contact {shift * per:+.4g} mm from the old one's")

        with self._lock:
            top = min(int(self._position[2]), z_old - clear)
            self.start_probe(ProbeRun(((x, y),), z_old + clear - top, _feed(feed_mm_min), top, "probe tool"))
            self._then = then
        return self._probe_results()[0] if wait else None

    work_state: Any = None
    """The state file (a :class:`~cam.drive.state.StateHold`) whose first tool's contact and work Z a tool probed
    at a tool change uses when the session keeps none itself (``state``): ``cam drill``'s job session, whose
    command keeps the state file."""

    def _work_hold(self) -> Any:
        return self.state_hold if self.state_hold is not None else self.work_state

    def probe_map(self, area_mm: Sequence[float], out: Any, *, spacing_mm: float = 10.0, margin_mm: float = 0.0,
                  safe_height_mm: float = 2.0, depth_mm: Optional[float] = None, feed_mm_min: Optional[float] = None,
                  machine: Optional[str] = None, wait: bool = True) -> GridPlan:
        """Probe a height map over ``area_mm`` (machine mm ``x0, y0, x1, y1``, grown by ``margin_mm``) on a grid
        ``spacing_mm`` apart (:func:`cam.drive.probe_grid.grid_plan`), the first point from ``safe_height_mm``
        above the work Z zero, every probe at most ``depth_mm`` below that height (None: the safe height + 2 mm), the
        later points approached from the contacts before them (:class:`~cam.drive.probe_grid.GridApproach`: the
        travel at a clearance above them, the probe from just above the surface expected), and when it finishes write
        the map (:func:`cam.job.heightmap_level.save_height_map`, atomic) to ``out``: then :attr:`last_map` and
        :attr:`last_map_path` (``cam probe grid``, the page's Probe the job's area).  ``machine``: the machine
        file's path the map names.

        Returns:
            the grid probed (``wait``: after the map was written; a probe that found nothing, a stop: ProbeError)."""
        for name, v in (("the safe height", safe_height_mm), ("the depth", depth_mm)):
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                                  or not (math.isfinite(v) and 0 <= v <= 1e5)):
                raise PlanError(f"{name} must be a number of mm 0..100000, got {shown(v)}")
        self.backend.require(self.port, "probes", "probing")
        plan = grid_plan(area_mm, spacing_mm, self.settings, margin_mm=margin_mm)
        per = self.settings.mm_per_step_z
        depth = max(1, int(round((depth_mm if depth_mm is not None else safe_height_mm + 2.0) / per)))
        path = str(out)

        def then() -> None:
            try:
                hmap = height_map_of(plan, self._last_probe or [], self.settings, reference_steps=zero_z,
                                     machine=machine)
                save_height_map(hmap, path)
            except CamError as exc:
                self.last_run = dict(self.last_run, status="error", messages=[f"the height map was not written: {exc}"])
                self.log(self.last_run["messages"][0], "error")
                return
            self.last_map, self.last_map_path = hmap, path
            self.log(f"height map of {len(plan.order)} points written to {path}: heights "
                     f"{hmap.height_mm.min():.4g}..{hmap.height_mm.max():.4g} mm")

        with self._lock:
            hold = self.state_hold
            zero_z = int(hold.state.work_zero_steps()[2]) if hold is not None else 0
            safe_z = zero_z - int(round(float(safe_height_mm) / per))
            self.probe_grid(plan.points_steps, safe_z, depth, feed_mm_min, approach=GridApproach.of(self.settings),
                            wait=False)
            self._then = then
        if wait:
            self._probe_results()
        return plan

    def forget_map(self) -> None:
        """Forget the height map :meth:`probe_map` wrote (:attr:`last_map`, :attr:`last_map_path` None): the page
        levels no job planned from now on to it (its file stays where it was written).  Nothing moves; allowed
        while a job runs (that job keeps the plan it started with)."""
        with self._lock:
            path, self.last_map, self.last_map_path = self.last_map_path, None, None
            self._bump()
        self.log(f"height map {path} forgotten: the next jobs are not levelled" if path
                 else "no height map to forget")

    def _after_probe(self, what: str, zero_z: int, probe: ToolProbe, said: str = "") -> None:
        """The end's hook of :meth:`probe_work_z` and :meth:`probe_tool` (the lock held, the probe finished): the
        work Z zero at ``zero_z`` and, with a state file, ``probe`` kept; an error ends the activity in one line."""
        try:
            self.set_work_z(zero_z)
            if self.state_hold is not None:
                self.state_hold.record(replace(self.state_hold.state, tool_probe=probe))
        except CamError as exc:
            self.last_run = dict(self.last_run, status="error", messages=[f"{what}: the work Z was not set: {exc}"])
            self.log(self.last_run["messages"][0], "error")
            return
        if said:
            self.log(f"{what}: work Z shifted{said}")

    def _probe_results(self) -> list[ProbeResult]:
        """Wait for the probing activity; its results, or ProbeError saying in one line why there are none."""
        self.wait_idle(None)
        info = self.last_run
        if info.get("status") != "finished":
            raise ProbeError("; ".join(info.get("messages") or [str(info.get("status"))]))
        return list(self._last_probe or [])

    def start_probe(self, probe_run: ProbeRun) -> None:
        """Start a probing activity (:class:`~cam.drive.probing.ProbeRun`) in the background, checked first: the
        machine can probe, the position is known, and with a state file every place it goes is in the travel."""
        self.backend.require(self.port, "probes", "probing")
        with self._lock:
            self._check_free()
            self._require_known()
            if self.state_hold is not None:
                self._check_probe_travel(probe_run)
            self.backend.start_probe(self, probe_run)

    def _check_probe_travel(self, probe_run: ProbeRun) -> None:
        here = tuple(int(v) for v in self._position)
        s = self.settings
        per = s.mm_per_step_z
        for xy in probe_run.points:
            top = here[2] if probe_run.safe_z_steps is None else probe_run.safe_z_steps
            x, y = (here[0], here[1]) if xy is None else xy
            x_mm, y_mm, _ = steps_to_mm((x, y, 0), s)
            where = "where the tool stands" if xy is None else f"probe point X={x_mm:g} Y={y_mm:g} mm"
            if xy is not None:
                check_in_travel((x, y, top), s, f"the safe height over the {where}")
            check_in_travel((x, y, top + probe_run.depth_steps), s,
                            f"the deepest probe ({probe_run.depth_steps * per:g} mm down) {where}")

    def _launch_probe(self, probe_run: ProbeRun, ctl: Any, make_prober: Callable[[], Prober]) -> None:
        """Begin the probing activity (the lock held; called by a back end's ``start_probe``)."""
        self._last_probe = None
        self._begin(Activity("probe", probe_run.label, ctl, len(probe_run.points), 0.0))
        self.log(f"{probe_run.label}: started at {probe_run.feed_mm_min:g} mm/min")
        self._spawn(probe_worker, (self, ctl, make_prober, probe_run), "probe")

    def set_work_z(self, z_steps: int, offset: Optional[str] = None) -> None:
        """The Z zero of work offset ``offset`` (None: the active one) at machine Z ``z_steps`` (a probed surface,
        a plate's thickness below a contact), X and Y kept; on grbl its own offset too (``G10 L2``).  Without a
        state file the session's home moves there on Z.  Refused while busy or while the position is unknown."""
        if isinstance(z_steps, bool) or not isinstance(z_steps, (int, np.integer)):
            raise PlanError(f"z_steps must be a whole number of steps, got {shown(z_steps)}")
        with self._lock:
            self._check_free()
            self._require_known()
            hold = self.state_hold
            if hold is None:
                self._position = self._position - np.array([0, 0, int(z_steps)], np.int64)
                self.backend.rebase(self, tuple(int(v) for v in self._position))
                self._bump()
                self.log(f"Z {int(z_steps)} steps is the origin's Z now")
                return
            name, zero = self._work_z_in(hold, int(z_steps), offset)
        zmm = steps_to_mm(zero, self.settings)
        self.log(f"{name} Z zero set at machine Z {zmm[2]:g} mm ({int(z_steps)} steps)")

    def _work_z_in(self, hold: Any, z_steps: int, offset: Optional[str] = None, *,
                   running: bool = False) -> tuple[str, tuple[int, ...]]:
        """Work offset ``offset``'s (None: the active one's) Z zero at machine Z ``z_steps`` in ``hold``'s state
        (the lock held; checked against the travel): ``(its name, its zero)``.  ``running``: a job runs (its
        running marker kept in the file)."""
        st = hold.state
        name = offset or st.active_offset
        if not isinstance(name, str) or name not in st.offsets_steps:
            raise PlanError(f"offset must be one of {', '.join(st.offsets_steps)}, got {shown(offset)}")
        zero = list(st.work_zero_steps(name))
        zero[2] = int(z_steps)
        check_in_travel(zero, self.settings, f"the {name} work zero")
        self.backend.work_z_set(self, name, int(z_steps))
        (hold.save if running else hold.record)(st.with_offset(name, tuple(zero)))
        self._bump()
        return name, tuple(zero)
