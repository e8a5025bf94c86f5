"""A part of :class:`~cam.drive.session.MachineSession`: probing the new tool at a job's tool change (issue #46
point 1).  The tool-change prompt offers it where it can be done (:meth:`SessionPromptProbe._tool_probe_why_not`
says why not elsewhere); :meth:`SessionPromptProbe.probe_tool_at_prompt` answers the prompt with it, and the job's
thread probes on the job's own open port while the job waits (``_pause_work``, :mod:`cam.drive.pause_probe`),
then books the work Z and the new tool's contact as :meth:`~cam.drive._session_probe.SessionProbe.probe_tool`
does.

Like the other parts it keeps no state of its own but the options of the probe asked for: it works on the
attributes ``MachineSession.__init__`` sets and on :class:`~cam.drive._session_probe.SessionProbe`'s
(``_work_hold``, ``_work_z_in``).  Frames: machine steps, +Z deeper.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Optional

import numpy as np

from ..errors import CamError, CapabilityError, PlanError
from ._session_probe import DEFAULT_TOOL_CLEARANCE_MM, _clearance, _feed, _plate
from .pause_probe import PauseProbe
from .probing import DEFAULT_FEED_MM_MIN, check_step_dir_probe, step_dir_feed
from .state import ToolProbe, check_in_travel

__all__ = ["SessionPromptProbe"]


class SessionPromptProbe:
    """Probe the new tool while a job waits at its tool change (a mixin; see the module)."""

    _pause_probe_options: Optional[tuple[Optional[float], Optional[float], float]] = None

    def _check_tool_probe(self) -> None:
        """Raise the one line of why the new tool cannot be probed while the running job waits, if it cannot."""
        name = self.port if isinstance(self.port, str) else getattr(self.port, "name", "this port")
        if "probes" not in self.backend.capabilities_of(self.port):  # the message names the port, not an object
            self.backend.require(name, "probes", "probing the new tool")
            self.backend.require(self.port, "probes", "probing the new tool")
        hold = self._work_hold()
        if hold is None or hold.state.tool_probe is None:
            raise PlanError("no tool has set the work Z by probing on this machine (cam probe z, the page's Probe Z, "
                            "before the job): the new tool has nothing to be measured against")
        if self._pause_work is None:
            raise CapabilityError(f"{name} runs the job on its own: probing the new tool while a job waits runs "
                                  f"on step/dir machines (the mock, a parallel port) and grbl; stop the job, probe "
                                  f"the tool (cam probe tool) and resume it")
        if self.backend.can("step_dir", self.port):  # grbl: its own probe input (G38.2)
            check_step_dir_probe(self)

    def _tool_probe_why_not(self, note: str) -> Optional[str]:
        if not str(note).startswith("tool change"):
            return None
        try:
            self._check_tool_probe()
        except CamError as exc:
            return str(exc)
        return ""

    def _refuse_tool_probe(self, note: str) -> None:
        if not str(note).startswith("tool change"):
            raise PlanError(f"probing the tool is offered at a tool change only, not at {note!r}")
        self._check_tool_probe()
        raise PlanError("probing the tool is not offered at this prompt")

    def probe_tool_at_prompt(self, prompt_id: Any = None, plate_mm: Optional[float] = None,
                             feed_mm_min: Optional[float] = None, *,
                             clearance_mm: float = DEFAULT_TOOL_CLEARANCE_MM) -> None:
        """Answer the tool-change prompt ``prompt_id`` (None: whichever waits) with "probe the new tool": while
        the job waits, the new tool is probed as :meth:`probe_tool` probes it (lifted to where the tool that set the
        work Z touched, on the same plate: ``plate_mm`` None the recorded one), the work Z shifted by the
        difference of the contacts, and the tool goes back to where the job waits, shifted on Z by as much: the
        job's later moves, all relative, land shifted too, so the new tool cuts at the asked depth.  Then the
        prompt asks again (``prompt.probed`` says what the probe did): go on, probe again, or stop.  A probe that
        touches nothing brings the tool back where it waited, the work Z kept.  Returns at once (the page polls the
        state); the command line's answer "probe-tool" does the same with the defaults.

        Raises:
            PlanError: a bad plate, feed or clearance, no prompt's tool change, no first probe; CapabilityError: a
            machine that cannot probe, or a board that runs the job itself (the MAXIMUS board); BusyError: no
            prompt waits."""
        plate = None if plate_mm is None else _plate(plate_mm)
        feed = _feed(feed_mm_min)
        clearance = _clearance(clearance_mm)
        with self._lock:
            self._pause_probe_options = (plate, feed, clearance)
            self.answer(prompt_id, "probe-tool")

    def _probe_at_prompt(self, at_steps: tuple[int, int, int]) -> str:
        with self._lock:
            options, self._pause_probe_options = self._pause_probe_options, None
        plate, feed, clearance = options or (None, None, DEFAULT_TOOL_CLEARANCE_MM)
        try:
            return self._probe_while_waiting(at_steps, plate, feed, clearance)
        except CamError as exc:
            line = f"the new tool was not probed: {exc}"
            self.log(line, "warning")
            return line

    def _probe_while_waiting(self, at: tuple[int, int, int], plate_mm: Optional[float], feed_mm_min: Optional[float],
                             clearance_mm: float) -> str:
        """:meth:`probe_tool_at_prompt`'s work in the waiting job's thread: the probe on its port, then the work Z
        and the tool's contact booked; the line said at the prompt."""
        self._check_tool_probe()
        hold = self._work_hold()
        old = hold.state.tool_probe
        plate = old.plate_mm if plate_mm is None else plate_mm
        per = self.settings.mm_per_step_z
        clear = max(1, int(round(clearance_mm / per)))
        x, y, z_old = (int(v) for v in old.contact_steps)
        top = min(int(at[2]), z_old - clear)
        depth = z_old + clear - top
        check_in_travel((x, y, top), self.settings, "the lift over the first tool's probe point")
        check_in_travel((x, y, top + depth), self.settings, f"the deepest probe ({depth * per:g} mm down)")
        with self._lock:  # the job's own Z (its run's frame): where it waits less where it started and had moved
            base_z = int(self._position[2]) + int(self._pause_moved[2])
            job_z = int(at[2]) - base_z
            reach_of = None if self._activity is None else self._activity.reach
        reach = None if reach_of is None else reach_of()  # the whole run's, checked shifted (outside the lock)
        z_range = None if reach is None else (base_z + int(reach[2][0]), base_z + int(reach[2][1]))
        request = PauseProbe(tuple(int(v) for v in at), (x, y), top, depth,  # type: ignore[arg-type]
                             step_dir_feed(self.settings, feed_mm_min) if self.backend.can("step_dir", self.port)
                             else (feed_mm_min or DEFAULT_FEED_MM_MIN), z_old + int(round(old.plate_mm / per)),
                             int(round(plate / per)), job_z, z_range)
        self.log(f"probing the new tool at X={x} Y={y} steps (where the first tool touched), from Z={top}")
        reply = self._pause_work(request)  # type: ignore[misc]
        end = reply["end_steps"]
        with self._lock:
            if end is not None:
                self._pause_moved = self._pause_moved + np.asarray(end, np.int64) - np.asarray(at, np.int64)
            elif self._activity is not None:
                self._activity.unknown_reason = reply["message"]
            self._bump()
        if reply["status"] != "finished":
            back = "the tool is back where the job waits, " if reply["status"] == "missed" else ""
            line = f"the new tool was not probed: {reply['message']} ({back}the work Z kept)"
            self.log(line, "warning")
            return line
        shift = int(reply["shift_steps"])
        contact = tuple(int(v) for v in reply["contact_steps"])
        with self._lock:
            before = int(hold.state.work_zero_steps()[2])
            name, _ = self._work_z_in(hold, before + shift, running=True)
            hold.save(replace(hold.state, tool_probe=ToolProbe(contact, plate)))  # type: ignore[arg-type]
        line = (f"the new tool probed: {name} Z zero moved {-shift * per:+.4g} mm up, to machine Z {before + shift} "
                f"steps (height {-(before + shift) * per:.4g} mm; the contact at {contact[2]} steps); the job goes "
                f"on at the new work Z")
        self.log(line)
        return line
