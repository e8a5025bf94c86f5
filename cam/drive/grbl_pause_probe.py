"""Probing the new tool on grbl while a job waits at a tool change (issue #46 point 1: "the tool-change prompt of a
drill or G-code job offers ``cam probe tool``").

A job on grbl waits at a tool change in its worker thread (:func:`cam.drive.grbl_machine.run_on_grbl`): every line
before the pause was streamed and grbl stands idle with its planner empty (the stream waits for that before it
prompts).  :func:`probe_at_grbl_pause` then does what ``cam probe tool`` does on grbl (:class:`GrblProber`): ``G53
G0`` lifted to where the tool that set the work Z touched the plate, ``G38.2`` down, lift back; then back to where
the job waits, shifted on Z by the difference of the contacts.  The job's lines are in machine coordinates (``G53``
absolute, not grbl's work coordinates: a ``G10 L2`` alone would not move them), so the job's frame is shifted by as
much (``frame_moved``: its later lines, its live position, its journal's home and its end booked).  The session
books the work Z (grbl's own ``G10 L2`` too) and the new contact
(:meth:`cam.drive.session.MachineSession.probe_tool_at_prompt`).

A probe that touches nothing (grbl's ``ALARM:5``: stopped, unlocked, lifted back) brings the tool back where the job
waits, the work Z kept.  A stop or an emergency stop during the probe is the job's (:class:`GrblControl`): the job
ends there.  Any other fault stops grbl first (:func:`~cam.drive.grbl_machine.fault_stop`) and ends the job, the
position unknown.  Frames: machine steps, +Z deeper.
"""
from __future__ import annotations

from typing import Any, Callable

from ..errors import CamError
from .grbl_machine import GrblControl, fault_stop
from .grbl_probe import GrblProber
from .pause_probe import PauseProbe, probe_and_go_back
from .probing import ProbeError
from .runner import EMERGENCY_STOPPED, STOPPED

__all__ = ["probe_at_grbl_pause"]

Steps3 = tuple[int, int, int]


def probe_at_grbl_pause(session: Any, ctl: GrblControl, request: PauseProbe,
                        frame_moved: Callable[[Steps3], None]) -> dict[str, Any]:
    """Probe the new tool on the session's grbl board while the job waits (see the module); never raises.

    ``frame_moved(by_steps)`` is told the shift of a probe that touched, once the tool is back at the shifted
    place (the job's frame moves by as much).

    Returns:
        as :func:`cam.drive.pause_probe.probe_at_pause`: ``status`` ("finished", "missed", "error", "stopped",
        "emergency-stopped"), ``message`` (one line), ``contact_steps`` (or None), ``shift_steps`` and
        ``end_steps``: where the job now waits (``request.at_steps`` shifted by the shift; None: the position is
        lost).  Whatever the probe did, the session books the end of the job from where grbl reports the tool."""
    at = tuple(int(v) for v in request.at_steps)
    if ctl.halted:  # stopped as the answer came: nothing moves
        return {"status": EMERGENCY_STOPPED if ctl.estopped else STOPPED, "message": "stopped before the probe "
                "began", "contact_steps": None, "shift_steps": 0, "end_steps": at}
    settings = session.settings
    contact = None
    shift = 0
    status, message, fault = "finished", "", ""
    prober = None
    try:
        prober = GrblProber(session, ctl)
        status, message, contact, shift = probe_and_go_back(prober, request, settings)
    except ProbeError as exc:  # ALARM:4: lifted back, the position known; the tool goes on from where it waits
        status, message, shift = "error", str(exc), 0
        try:
            if prober is not None:
                prober.travel(at)  # type: ignore[arg-type]
        except CamError as again:
            fault = message = str(again)
    except CamError as exc:
        status, message, shift = "error", str(exc), 0
        if not ctl.halted:
            fault = message
    except Exception as exc:  # noqa: BLE001 - said in one line; grbl stopped, the job ended
        status, message, shift = "error", f"internal error: {type(exc).__name__}: {exc}", 0
        fault = message
    if ctl.halted:  # the job's stop: it ends there (its worker waits for grbl to stand still and resets it)
        return {"status": EMERGENCY_STOPPED if ctl.estopped else STOPPED, "message": "stopped during the probe",
                "contact_steps": contact, "shift_steps": 0, "end_steps": at}
    if fault:  # grbl stopped first; the job ends, the position unknown
        message = fault_stop(session.grbl, fault)
        ctl.stop()
        return {"status": "error", "message": message, "contact_steps": contact, "shift_steps": 0,
                "end_steps": None}
    if shift:
        frame_moved((0, 0, int(shift)))
    return {"status": status, "message": message, "contact_steps": contact, "shift_steps": int(shift),
            "end_steps": (at[0], at[1], at[2] + int(shift))}
