"""Two parts of :class:`~cam.drive.session.MachineSession`: what it shows, and how it is controlled.

:class:`SessionView` is the JSON-able state snapshot, the live position and
the log; :class:`SessionControls` (built on the view) holds pause / resume /
stop / emergency stop, the prompts a job waits on, and waiting for the end.
``MachineSession`` derives from :class:`SessionControls`.  Neither part keeps
state of its own: they work on the attributes that ``MachineSession.__init__``
sets (declared below for readers and type checkers), under the session's lock.

Frames: positions are machine steps ``(x, y, z)`` from the session's home (+Z deeper).
"""
from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

import numpy as np

from ..errors import BusyError, PlanError
from ..settings import MachineSettings
from ..values import shown, whole_number
from .machines import require

__all__ = ["Activity", "Prompt", "PromptFn", "PROMPT_ACTIONS", "SessionControls", "SessionView"]


@dataclass
class Prompt:
    """A question the machine waits on (a tool change, a Pause At point)."""

    id: int
    note: str
    position_steps: tuple[int, int, int]
    probe_tool: bool = False
    """A tool change where the new tool may be probed before the job goes on (answer "probe-tool"): the machine
    probes and a first probe set the work Z (:meth:`~cam.drive.session.MachineSession.probe_tool_at_prompt`)."""
    probe_tool_why_not: str = ""
    """A tool change where it may not: why, in one line ("" otherwise)."""
    probed: str = ""
    """What the last probe of the new tool at this pause did, in one line ("" none yet): the prompt asks again."""


PromptFn = Callable[[Prompt], str]
"""on_prompt(prompt) -> "continue", "stop" or "probe-tool" (offered when ``prompt.probe_tool``): answers a prompt
from the worker thread (it may block); after "probe-tool" it is asked again, with what the probe did."""

PROMPT_ACTIONS = ("continue", "stop", "probe-tool")


@dataclass
class Activity:
    """What runs now: its name, label, controller and progress."""

    name: str  # "job", "jog" or "origin"
    label: str
    controller: Any
    total: int
    estimate: "Callable[[], float] | float"  # machine seconds, or what gives them when first asked
    positions: Any = None  # the run's Cursor (cam.drive.runner): the writes sent and the position after them
    done: int = 0
    machine_ns: int = 0
    detail: str = ""
    started_wall: float = field(default_factory=time.monotonic)
    unknown_reason: str = ""  # the position stays unknown after it, for this reason (a jog made while unknown)
    halts: tuple[int, int] = (0, 0)  # the session's (stops, emergency stops) counted when it began (or its chain)
    reach: Optional[Callable[[], Any]] = None  # a run's (3, 2) min/max steps from where it started, when asked

    @property
    def estimated_s(self) -> float:
        """The activity's machine time in seconds, worked out when first asked (a plan's machine time takes a
        pass over its ramps; a command line run with no progress bar never asks)."""
        if callable(self.estimate):
            self.estimate = float(self.estimate())
        return float(self.estimate)


class SessionView:
    """The session as a snapshot: state, live position, progress, prompt and log (a mixin)."""

    port: str
    backend: Any  # the machine's back end (cam.drive.machines.Backend)
    settings: MachineSettings
    realtime: bool
    version: int
    last_run: dict[str, Any]
    _lock: threading.RLock
    _changed: threading.Condition
    _position: np.ndarray  # (3,) int64 steps from the home, booked at the end of each activity
    _pause_moved: np.ndarray  # (3,) int64 steps the tool moved at the running job's pauses (not in its cursor)
    _activity: Optional[Activity]
    _last_activity: Optional[Activity]
    _finished_wall: float
    _prompt: Optional[Prompt]
    _log: collections.deque
    _log_seq: int

    def _bump(self) -> None:
        self.version += 1
        self._changed.notify_all()

    def log(self, text: str, level: str = "info") -> None:
        """Add a line to the session's log."""
        with self._lock:
            self._log_line(text, level)
            self._bump()

    def _log_line(self, text: str, level: str) -> None:
        """Append a log line (the lock held; the caller bumps)."""
        self._log_seq += 1
        self._log.append({"seq": self._log_seq, "level": level, "text": text, "t": time.time()})

    @property
    def busy(self) -> bool:
        with self._lock:
            return self._activity is not None

    def position_steps(self) -> tuple[int, int, int]:
        """Where the tool is now, in steps from the home (live while something runs)."""
        with self._lock:
            pos = self._position.copy()
            a = self._activity
            if a is not None and a.positions is not None and a.done > 0:
                pos = pos + np.array(a.positions.position_steps, np.int64)
            if a is not None:  # the tool moved at a pause (a tool probed at a tool change: shifted on Z)
                pos = pos + self._pause_moved
            return tuple(int(v) for v in pos)  # type: ignore[return-value]

    def _state_name(self) -> str:
        a = self._activity
        if a is None:
            return "idle"
        if self._prompt is not None:
            return "prompt"
        if a.controller.halted:
            return "stopping"
        if a.controller.paused:
            return "paused"
        return "running" if a.name == "job" else "moving"

    def state(self, log_after: int = 0) -> dict[str, Any]:
        """JSON-able snapshot: state, position, progress, times, prompt, log lines after ``log_after``."""
        s = self.settings
        with self._lock:
            a = self._activity
            shown = a or self._last_activity
            pos = self.position_steps()
            end = time.monotonic() if a is not None else self._finished_wall
            return {
                "state": self._state_name(),
                "activity": a.name if a else None,
                "label": a.label if a else "",
                "detail": a.detail if a else "",
                "position_steps": list(pos),
                "position_mm": [round(v * p, 4) for v, p in zip(pos, s.mm_per_step_axes)],
                "progress": round(100.0 * shown.done / shown.total, 2) if shown and shown.total else 0.0,
                "writes_done": shown.done if shown else 0,
                "writes_total": shown.total if shown else 0,
                "elapsed_s": round(max(0.0, end - shown.started_wall), 2) if shown else 0.0,
                "remaining_s": round(max(0.0, a.estimated_s - a.machine_ns / 1e9), 2) if a else 0.0,
                "prompt": dict(vars(self._prompt), position_steps=list(self._prompt.position_steps))
                if self._prompt else None,
                "last": dict(self.last_run),
                "log": [dict(e) for e in self._log if e["seq"] > log_after][-100:],
                "port": self.port,
                "capabilities": sorted(self.backend.capabilities_of(self.port)),  # the page asks these, not names
                "realtime": self.realtime,
                "version": self.version,
                **(self.backend.state_extra(self) or {}),  # what the machine adds (grbl: its state, override)
            }

    def wait_change(self, version: int, timeout_s: float) -> int:
        """Block until the state's version differs from ``version`` (or the timeout); returns the version."""
        with self._changed:
            if self.version == version:
                self._changed.wait(timeout_s)
            return self.version


class SessionControls(SessionView):
    """Pause, resume, stop, emergency stop, prompts and waiting for the end (a mixin, on the view)."""

    on_prompt: Optional[PromptFn]
    _thread: Optional[threading.Thread]
    _prompt_seq: int
    _answer: threading.Event
    _answer_action: str
    _estop_request_ns: Optional[int]
    _halt_lock: threading.RLock
    _halts: tuple[int, int]  # (stops, emergency stops) asked so far: counted before the activity is read
    # the probing part's (cam.drive._session_probe.SessionProbe): why the new tool may not be probed at a prompt's
    # note ("" it may, None not a tool change), probing it while the job waits at (machine steps) -> the line said,
    # and the one line refusing "probe-tool" where it is not offered
    _tool_probe_why_not: Callable[[str], Optional[str]]
    _probe_at_prompt: Callable[[tuple[int, int, int]], str]
    _refuse_tool_probe: Callable[[str], None]

    def _controller(self) -> Any:
        a = self._activity  # no lock: the runner may hold it for a progress update
        return a.controller if a is not None else None

    def pause(self) -> None:
        """Hold the running job where it is (CapabilityError on a port that cannot pause)."""
        require(self.port, "pause")
        with self._lock:
            ctl = self._controller()
            if ctl is None:
                raise BusyError("nothing is running")
            ctl.pause()
            self._bump()
        self.log("paused")

    def resume(self) -> None:
        with self._lock:
            ctl = self._controller()
            if ctl is None or not ctl.paused:
                raise BusyError("nothing is paused")
            ctl.resume()
            self._bump()
        self.log("resumed")

    def _count_halt(self, emergency: bool) -> None:
        """Count a stop (``emergency``: an emergency stop) before the activity is read: whatever an activity hands
        over to as it ends (the job after the travel to its work zero) is not started when the count changed
        since that activity began, and an activity that begins finds it changed and halts at once
        (:meth:`~cam.drive.session.MachineSession.finish`, ``_begin``): no stop is lost between two of them."""
        with self._halt_lock:
            stops, estops = self._halts
            self._halts = (stops, estops + 1) if emergency else (stops + 1, estops)

    def _halt_handed_over(self, ctl: Any, emergency: bool) -> Any:
        """The second half of a stop, under the lock (an activity's hand-over holds it): the activity running now
        halted too when it is not the one ``ctl`` (read without the lock) belonged to; its controller, or None."""
        a = self._activity
        if a is not None and a.controller is not ctl:
            ctl = a.controller
            if emergency:
                ctl.emergency_stop()
            else:
                ctl.stop()
        return ctl

    def stop(self) -> None:
        """Stop and lift the tool to the safe plane (nothing happens when idle).  A stop as one activity hands
        over to the next (the travel to the work zero ending, the job about to start) stops the hand-over: the
        next one does not start."""
        self._count_halt(False)
        ctl = self._controller()  # no lock first: the runner stops before its next step
        if ctl is not None:
            ctl.stop()
        with self._lock:
            ctl = self._halt_handed_over(ctl, False)
            if ctl is not None:
                self._answer_action = "stop"
                self._answer.set()
                self._bump()
        self.log("stop requested" if ctl is not None else "stop: nothing was running")

    def emergency_stop(self, request_ns: Optional[int] = None) -> None:
        """Send nothing more at all (nothing handed over to after it either, as :meth:`stop`).  ``request_ns``:
        ``time.monotonic_ns()`` when the request arrived."""
        now = request_ns if request_ns is not None else time.monotonic_ns()
        self._count_halt(True)
        ctl = self._controller()
        if ctl is not None:
            ctl.emergency_stop()
        with self._lock:
            ctl = self._halt_handed_over(ctl, True)
            if ctl is not None:
                if self._estop_request_ns is None:
                    self._estop_request_ns = now
                self._answer.set()
                self._bump()
        self.log("EMERGENCY STOP" if ctl is not None else "emergency stop: nothing was moving", "error")

    def prompt(self, position_steps: tuple[int, int, int], note: str) -> None:
        """The job waits at a pause: ask :attr:`on_prompt`, or wait for :meth:`answer`; stop on "stop".  At a tool
        change "probe-tool" probes the new tool while the job waits (:meth:`probe_tool_at_prompt`), then asks
        again, saying what the probe did.

        Called by the worker thread; ``position_steps`` is relative to where the activity started.
        """
        with self._lock:
            a = self._activity
            ctl = a.controller if a else None
            (hx, hy, hz), (x, y, z) = self._position.tolist(), position_steps
            mx, my, mz = self._pause_moved.tolist()
            at = (hx + int(x) + mx, hy + int(y) + my, hz + int(z) + mz)
        if ctl is not None and ctl.halted:  # stopped as it reached the pause: nobody is asked
            return
        probed = ""
        while True:
            action = self._ask(note, at, ctl, probed)
            if action != "probe-tool" or ctl is None or ctl.halted:
                break
            with self._lock:
                if self._activity is not None:
                    self._activity.detail = "probing the new tool"
                self._bump()
            probed = self._probe_at_prompt(at)
            with self._lock:
                if self._activity is not None:
                    self._activity.detail = ""
                mx2, my2, mz2 = self._pause_moved.tolist()
                at = (at[0] + mx2 - mx, at[1] + my2 - my, at[2] + mz2 - mz)
                mx, my, mz = mx2, my2, mz2
            if ctl.halted:  # stopped while probing: the job ends there, nobody is asked again
                break
        if action == "stop" and ctl is not None:
            ctl.stop()

    def _ask(self, note: str, at: tuple[int, int, int], ctl: Any, probed: str) -> str:
        """One prompt (machine frame ``at``), answered by :attr:`on_prompt` or :meth:`answer`; its action."""
        why_not = self._tool_probe_why_not(note)
        with self._lock:
            self._prompt_seq += 1
            self._prompt = Prompt(self._prompt_seq, note, at, why_not == "", why_not or "", probed)
            prompt = self._prompt
            self._answer.clear()
            self._answer_action = "continue"
            self._log_line(f"{note}: waiting for an answer", "prompt")
            self._bump()  # the prompt and its log line seen at once
        if self.on_prompt is not None:
            self._answer_action = self.on_prompt(prompt)
        else:
            while not self._answer.wait(0.05):
                if ctl is None or ctl.halted:
                    break
        with self._lock:
            self._prompt = None
            action = self._answer_action
            self._bump()
        return action

    def answer(self, prompt_id: Any, action: str) -> None:
        """Answer the pending prompt ``prompt_id`` (a whole number, the prompt's ``id``; None: whichever waits):
        ``action`` "continue", "stop" or, at a tool change that offers it (``prompt.probe_tool``), "probe-tool"
        (probe the new tool, then the prompt asks again).  PlanError for a bad value (text or a boolean for the
        id), BusyError when no prompt, or another one, waits; "probe-tool" where it is not offered: one line
        saying why (CapabilityError on a machine that cannot probe, else PlanError)."""
        if not isinstance(action, str) or action not in PROMPT_ACTIONS:
            raise PlanError(f"action must be 'continue', 'stop' or 'probe-tool', got {shown(action)}")
        if prompt_id is not None:
            prompt_id = whole_number(prompt_id, "prompt")
        with self._lock:
            if self._prompt is None:
                raise BusyError("no prompt is waiting for an answer")
            if prompt_id is not None and prompt_id != self._prompt.id:
                raise BusyError(f"prompt {prompt_id!r} is no longer waiting (the current one is {self._prompt.id})")
            if action == "probe-tool" and not self._prompt.probe_tool:
                self._refuse_tool_probe(self._prompt.note)
            self._answer_action = action
            note = self._prompt.note
            self._answer.set()
        self.log(f"{note}: {action}")

    def wait_idle(self, timeout_s: Optional[float] = 10.0) -> bool:
        """Wait for the running activity to end (and what it starts when it finishes: a job after the travel
        to its work zero); True when idle."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            t = self._thread
            if t is None:
                break
            t.join(None if deadline is None else max(0.0, deadline - time.monotonic()))
            if t is self._thread or t.is_alive() or (deadline is not None and time.monotonic() >= deadline):
                break
        return not self.busy

    def shutdown(self) -> None:
        """Stop whatever runs (tool lifted) and wait for it; end the runner process."""
        if self.busy:
            self.stop()
            if not self.wait_idle(30):
                self.emergency_stop()
                self.wait_idle(5)
        if getattr(self, "_runner_process", None) is not None:
            self._runner_process.close()
