"""Where a job goes: placing it at the active work zero, Go To paths, and the machine state after a run.

Issue #29: every job kind is placed by its own origin at the active work zero (machine frame, steps from the
machine's home, +Z deeper); the travel is checked in the machine frame before anything moves.  Library code,
used by the command line (:mod:`cam.cli.execute`) and by :class:`cam.drive.session.MachineSession` when it keeps
a machine state file (the web page).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Optional

import numpy as np

from ..errors import CamError, TravelError
from ..kinds import kinds
from ..kinds.jobs import default_origin, origin_anchor_steps
from ..job.model import Job, travel_job
from ..settings import MachineSettings
from ..motion.chunks import ChunkedPlan
from .machine_job import JobInput, MachineJob, machine_job
from .runner import EMERGENCY_STOPPED, FINISHED, LIMIT_STOPPED, STOPPED
from .state import MachineState

__all__ = ["goto_path", "placed_kinds", "ORIGINS", "origin_anchor", "placed_home", "approach_to_work_zero",
           "ended_state"]

Steps3 = tuple[int, int, int]


def goto_path(start_steps: Steps3, target_steps: Steps3, safe_z_steps: int, settings: MachineSettings
              ) -> Optional[Job]:
    """Go To from ``start_steps`` to ``target_steps`` (both machine frame): up to the safe height first (the
    highest of where the tool is, ``safe_z_steps`` and the target's Z; +Z is deeper), travel at it, then Z
    to the target.  The job's points are relative to the start; None when the tool is there already."""
    x0, y0, z0 = (int(v) for v in start_steps)
    x, y, z = (int(v) for v in target_steps)
    h = min(z0, int(safe_z_steps), z)
    rel: list[Steps3] = []
    for p in ((x0, y0, h), (x, y, h), (x, y, z)):
        r = (p[0] - x0, p[1] - y0, p[2] - z0)
        if r != (0, 0, 0) and (not rel or rel[-1] != r):
            rel.append(r)
    if not rel:
        return None
    return travel_job(np.array(rel, np.int64).reshape(-1, 3), settings, source="go to")


def placed_kinds() -> dict[str, str]:
    """The file kinds whose job is placed at the active work zero, and what messages call them (each kind's
    :attr:`cam.kinds.Kind.job_noun`; a G-code program is not placed: it runs in the state's work offsets from where
    the tool stands, planned so by ``cam drill``, see :func:`cam.kinds.jobs.prepare_job`'s ``machine_state``)."""
    return {k.name: k.job_noun for k in kinds() if k.job_noun is not None}


ORIGINS = ("file", "upper-left", "lower-left", "center")
"""Which point of a drawing, drill or vector job ``--origin`` puts at the work zero (see :func:`origin_anchor`)."""


def origin_anchor(job: "JobInput | MachineJob", origin: Optional[str]) -> tuple[int, int]:
    """The ``(x, y)`` point of a prepared job, in its own frame (steps, +y toward the front of the machine), that
    goes to the work zero: ``file`` its frame's zero (a drawing's top-left pixel, the thesis's), ``upper-left``,
    ``lower-left`` or ``center`` of what it cuts (the
    XY extent of the tool below the surface).  None: the job's own ``origin`` (the one its options chose,
    ``JobOptions.origin``), else ``file`` for drawings and digitized matrices, ``upper-left`` for the other kinds
    (the command line passes ``file`` for an ``--offset`` without ``--origin``)."""
    mj = machine_job(job)
    origin = origin or mj.origin or default_origin(mj.kind)
    if origin != "file" and not isinstance(mj.plan, ChunkedPlan):
        raise CamError(f"--origin {origin} places a file's job: {mj.name} has no plan of its own to measure")
    return origin_anchor_steps(mj.kind, origin, mj.plan)  # the rule, where the job layer needs it too (--level)


def placed_home(job: "JobInput | MachineJob", state: MachineState, origin: Optional[str]) -> tuple[int, int, int]:
    """Where (machine frame, steps) a job placed at the active work zero starts: its own frame's zero, so that its
    :func:`origin_anchor` lands on the work zero (Z: the work zero's surface).  A job levelled to a height map
    starts where it was levelled (its ``levelled_home_steps``, placed so for this work zero: its ``planned_in``
    refuses another)."""
    mj = machine_job(job)
    if mj.levelled_home_steps is not None:
        return mj.levelled_home_steps
    zero = state.work_zero_steps()
    ax, ay = origin_anchor(mj, origin)
    return zero[0] - ax, zero[1] - ay, zero[2]


def approach_to_work_zero(job: "JobInput | MachineJob", state: MachineState, start: tuple[int, int, int],
                          settings: MachineSettings, origin: Optional[str] = None) -> Optional[Job]:
    """The travel that places a file's job at the active work zero (issue #29 points 1 and 6, on every port: a MAXIMUS
    board drills a file's holes from where its head stands, so it travels there first too): its
    home, its own frame's (0, 0, 0), goes to the work zero: a drawing's top-left pixel at the surface (the
    thesis's), a drill file's top-left hole, or with ``origin`` "file" (or an ``--offset``) a drill, HPGL or SVG
    file's own zero (its job planned from the work zero, :func:`cam.kinds.jobs.own_zero_home`).  None when the
    tool is there already, or for a G-code program (its
    own work offsets place it) or any other job (planned from where the tool stands).  Positions in the machine frame.

    Raises:
        TravelError: the job placed there leaves the travel (naming the axis and by how much), before
        anything moves.
    """
    mj = machine_job(job)
    noun = placed_kinds().get(mj.kind)  # a prepared job's file kind; moves alone and step plans are not placed
    if noun is None:
        return None
    zero = placed_home(mj, state, origin)
    extent = mj.extent_steps
    if extent is not None:
        for a, (lo, hi) in enumerate(settings.travel.bounds_steps()):
            reach = (zero[a] + int(extent[a][0]), zero[a] + int(extent[a][1]))
            if reach[0] < lo or reach[1] > hi:
                v, beyond = (reach[0], lo - reach[0]) if reach[0] < lo else (reach[1], reach[1] - hi)
                raise TravelError(
                    f"the {noun} placed at the {state.active_offset} work zero (machine "
                    f"{list(state.work_zero_steps())} steps) "
                    f"leaves the {'XYZ'[a]} travel ({lo}..{hi} steps from the home): it reaches {v}, {beyond} "
                    f"steps beyond; set the work zero elsewhere (cam zero)")
    return goto_path(start, zero, zero[2], settings)


def ended_state(state: MachineState, session: Any, start: tuple[int, int, int],
                tool: Optional[str] = None) -> MachineState:
    """The machine state after the session's last activity (positions in the machine frame).

    A homing that did not finish: the position unknown (issue #43 point 5).  Finished or stopped: the tool
    where the session booked it.  An emergency stop, or a fault after writes
    were sent (or on a MAXIMUS board, which then has lost its offset): where it got to, position unknown.  A
    fault before anything was sent, or no run at all (refused before it started): where it started.
    """
    info = session.last_run
    status = info.get("status")
    end = session.position_steps()
    if info.get("activity") == "home" and status != FINISHED:  # a homing that failed never makes it known
        reason = "; ".join(info.get("messages") or [str(status or "stopped")])
        return state.lost(f"homing did not finish ({reason})", end)
    if status is None:
        return state.moved_to(start)
    if status == LIMIT_STOPPED and session.last_sent()[1] == (0, 0, 0):  # stopped before its first step
        return state.moved_to(end)
    if status == LIMIT_STOPPED:
        switch = (info.get("messages") or ["a limit switch closed"])[0].split(";")[0]
        return state.lost(f"{switch} during {info.get('label') or 'the run'}, at machine {list(end)} steps", end)
    if status == EMERGENCY_STOPPED:
        return state.lost(f"an emergency stop ended {info.get('label') or 'the run'} (steps may have been lost)",
                          end)
    if status not in (FINISHED, STOPPED):
        sent, moved = session.last_sent()
        own_steps = not session.backend.can("step_dir", session.port)  # a board: its word, not a cursor's
        if sent or session.backend.can("drills_alone"):
            booked = session.last_result is not None or own_steps
            guess = end if booked else tuple(s + m for s, m in zip(end, moved))
            reason = "; ".join(info.get("messages") or ["the run failed"])
            return state.lost(f"{info.get('label') or 'the run'} failed while moving ({reason})", guess)
        return state.moved_to(end)
    done = state.moved_to(end)
    return replace(done, tool=tool) if tool and status == FINISHED and session.last_run.get("activity") == "job" \
        else done
