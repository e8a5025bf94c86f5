"""Probing the new tool while a job waits at a tool change (issue #46 point 1: "the tool-change prompt of a drill or
G-code job offers ``cam probe tool``").

A job on a step/dir port waits at a tool change in its runner (:func:`cam.drive.runner.run` calls the session's
prompt).  :func:`probe_at_pause` then does, on the job's own open port, what ``cam probe tool`` does between jobs:
travel lifted to where the tool that set the work Z touched the plate, probe the new tool there, lift back; and then
one more move the job needs: back to where the job waits, shifted on Z by the difference of the contacts.  The
job's later moves are relative step runs, so from that shifted place every one of them lands shifted by the same
amount: the new tool cuts at the asked depth below the new work Z.  The session books the shift
(:meth:`cam.drive.session.MachineSession.probe_tool_at_prompt`).

It runs where the job's port is open: in the session's worker thread, or in the real-time runner process
(:mod:`cam.drive.apart`, which passes a :class:`PauseProbe` over its socket and returns the dict).  On the mock the
pin log keeps one time line: the probe's writes come after the job's last write, and the job's next writes after
the probe's last (the port's ``time_offset_ns``).  The job's controller serves stop and e-stop throughout.
Frames: machine steps, +Z deeper.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

from ..errors import CamError, TravelError
from ..settings import MachineSettings
from .ports import MockPort, SwitchSchedule
from .probing import ProbeEnded, StepDirProber, missed_line
from .journal import JournalWriter
from .runner import EMERGENCY_STOPPED, LIMIT_STOPPED, STOPPED
from .state import check_in_travel

__all__ = ["PauseProbe", "probe_at_pause"]

Steps3 = tuple[int, int, int]


@dataclass(frozen=True)
class PauseProbe:
    """A tool probe at a job's pause, machine frame (steps): the tool stands at ``at_steps``; it goes to
    ``point_steps`` (X, Y of the first tool's contact) at ``top_z_steps``, probes at most ``depth_steps`` down at
    ``feed_mm_min`` (already checked for the machine), lifts back to ``top_z_steps``; a contact at machine Z ``c``
    shifts the work Z by ``c + plate_steps - old_surface_steps`` and the tool goes back to ``at_steps`` shifted by
    that on Z (not shifted when the probe touched nothing)."""

    at_steps: Steps3
    point_steps: tuple[int, int]
    top_z_steps: int
    depth_steps: int
    feed_mm_min: float
    old_surface_steps: int
    plate_steps: int
    job_z_steps: Optional[int] = None
    """Where the waiting job stands on Z in its own frame (steps from where its run started: its cursor's), for
    the top of the Z travel in that frame after the probe (:attr:`cam.drive.runner.Controller.z_top_steps`: a
    stop's lift from where the probe left the tool stays in the travel); None: not told."""
    job_z_range_steps: Optional[tuple[int, int]] = None
    """The machine Z the job's moves reach, highest and deepest (its run's whole extent, in the frame it goes on
    in): a shift that would take them out of the Z travel is refused, the work Z kept; None: not told."""


class _OnJobPort(StepDirProber):
    """A prober on the waiting job's port: on the mock each of its runs starts after the last write so far (a
    real-time run's writes are as late as the clock made them, later than its plan)."""

    def _after_last_write(self) -> None:
        port = self.opened
        if isinstance(port, MockPort):
            port._flush()
            if port.last_t_ns is not None:
                port.time_offset_ns = max(port.time_offset_ns, int(port.last_t_ns) + int(self.settings.delay_xy_ns))

    def _moves(self, rel_steps: Any, what: str) -> None:
        self._after_last_write()
        super()._moves(rel_steps, what)

    def probe(self, depth_steps: int, feed_mm_min: float) -> Any:
        self._after_last_write()
        return super().probe(depth_steps, feed_mm_min)


def _check_shifted_job(request: PauseProbe, shift_steps: int, settings: MachineSettings) -> None:
    """Refuse a work Z shift that takes the job's moves (``request.job_z_range_steps``, shifted by ``shift_steps``)
    out of the Z travel (TravelError, one line): the job goes on only where all of it stays in the travel."""
    if request.job_z_range_steps is None:
        return
    lo, hi = (int(v) + int(shift_steps) for v in request.job_z_range_steps)
    z_min, z_max = settings.travel.bounds_steps()[2]
    if lo < z_min or hi > z_max:
        v, beyond = (lo, z_min - lo) if lo < z_min else (hi, hi - z_max)
        raise TravelError(f"the job's moves, {shift_steps:+d} steps on Z with the new tool, would reach Z {v}, "
                          f"{beyond} steps beyond the Z travel ({z_min}..{z_max} steps from the home)")


def probe_and_go_back(prober: Any, request: PauseProbe, settings: MachineSettings
                      ) -> tuple[str, str, Optional[tuple[int, int, int]], int]:
    """The probe of a new tool while its job waits, on any machine's ``prober``: lifted and across to over the
    first tool's contact, probed, then back to where the job waits, shifted on Z by the difference of the
    contacts when that shift keeps the tool and the rest of the job in the travel (else not shifted: "error").

    Returns ``(status, message, contact_steps, shift_steps)``: "finished" (the contact, the shift), "missed" (no
    contact: back where the job waits, nothing shifted) or "error" (the shift refused)."""
    x, y = request.point_steps
    prober.travel((int(x), int(y), int(request.top_z_steps)))
    result = prober.probe(int(request.depth_steps), float(request.feed_mm_min))
    back = tuple(int(v) for v in request.at_steps)
    if result.contact_steps is None:
        prober.travel(back)
        return "missed", missed_line(result, settings), None, 0
    contact = tuple(int(v) for v in result.contact_steps)
    shift = contact[2] + int(request.plate_steps) - int(request.old_surface_steps)
    status, message = "finished", ""
    try:
        shifted = (back[0], back[1], back[2] + shift)
        check_in_travel(shifted, settings, "where the job goes on with the new tool")
        _check_shifted_job(request, shift, settings)
        back = shifted
    except CamError as exc:
        status, message, shift = "error", f"the work Z was not shifted: {exc}", 0
    prober.travel(back)
    return status, message, contact, shift  # type: ignore[return-value]


def probe_at_pause(port: Any, settings: MachineSettings, realtime: bool, ctl: Any, request: PauseProbe,
                   journal: Optional[JournalWriter] = None) -> dict[str, Any]:
    """Probe the new tool on the job's open ``port`` while it waits (see the module); never raises.

    A job stopped before it starts: nothing moves.  Wherever it leaves the tool, the job's stop lift from then on
    goes no higher than the top of the Z travel (``ctl.z_top_steps``, with ``request.job_z_steps``).  The job's
    ``journal`` (its writer, None: none kept) books the work Z's shift of a probe that touched: its home moves by
    as much (:meth:`cam.drive.journal.JournalWriter.home_moved`), so a resumed run goes on at the new work Z.

    Returns:
        ``status`` ("finished": touched, the tool back at the shifted place; "missed": no contact, back where it
        waited; "error": refused or failed; or the runner's stopped / emergency-stopped / limit-stopped),
        ``message`` (one line, "" when finished), ``contact_steps`` (or None), ``shift_steps`` (the work Z's
        shift, 0 unless finished) and ``end_steps`` (where the tool stands now; None: unknown)."""
    if ctl.halted:  # stopped before the probe began (as the answer came): nothing moves
        return {"status": EMERGENCY_STOPPED if ctl.estop_requested else STOPPED, "message": "stopped before the "
                "probe began", "contact_steps": None, "shift_steps": 0, "end_steps": tuple(request.at_steps)}
    mock = port if isinstance(port, MockPort) else None
    own_switches = False
    t_before = 0
    if mock is not None:
        mock._flush()
        t_before = int(mock.last_t_ns or 0)
        saved_offset = mock.time_offset_ns
        mock.time_offset_ns = t_before + int(settings.delay_xy_ns)  # after the job's last write
        if mock.switches is None:  # the job's mock simulated no switch: the probe's surface for this probe
            mock.switches = SwitchSchedule(settings, request.at_steps)
            own_switches = True
    prober = _OnJobPort.on_port(port, settings, realtime, ctl, request.at_steps)
    contact = None
    shift = 0
    status, message = "finished", ""
    try:
        status, message, contact, shift = probe_and_go_back(prober, request, settings)
    except ProbeEnded as exc:
        status, message, shift = exc.status, str(exc), 0
        if exc.status in (EMERGENCY_STOPPED, LIMIT_STOPPED):  # the job sends nothing more either
            ctl.emergency_stop()
    except CamError as exc:
        status, message, shift = "error", str(exc), 0
    except Exception as exc:  # noqa: BLE001 - said in one line; the job is stopped by the caller
        status, message, shift = "error", f"internal error: {type(exc).__name__}: {exc}", 0
    finally:
        if mock is not None:
            mock._flush()
            # the job's next writes after the probe's last (its own times run on from where it paused)
            mock.time_offset_ns = saved_offset + int(mock.last_t_ns or 0) - t_before + int(settings.delay_xy_ns)
            if own_switches:
                mock.switches = None
    end, lost = prober.close(ctl, message if status == "error" else "")
    if lost:
        status, message, end = "error", lost, None
    if end is not None and request.job_z_steps is not None:  # machine Z less the job's own Z, from now on
        ctl.z_top_steps = settings.travel.z_min_steps - (int(end[2]) - int(request.job_z_steps))
    if journal is not None and status == "finished" and shift:
        journal.home_moved((0, 0, int(shift)))
    return {"status": status, "message": message, "contact_steps": contact, "shift_steps": int(shift),
            "end_steps": end}
