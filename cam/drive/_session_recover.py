"""A part of :class:`~cam.drive.session.MachineSession`: finding the work again (issue #45 point 3).

After an emergency stop, a limit switch or a fault the position is unknown (the state file's latch: it is never
cleared by itself).  Three ways out, on every port, shared by the CLI, the page and the Python API:

* :meth:`SessionRecover.jog` with the position unknown: allowed, as LinuxCNC jogs an unhomed machine, with the soft
  limits off (logged: ``position unknown: soft limits are off for this jog``), at the jog's own speed and stoppable
  as any jog; the position stays unknown afterwards (a jog does not make it known).  Go-tos and jobs stay refused.
* :meth:`SessionRecover.set_position`: the user's word of where the tool stands (``cam where --set``, the page's
  Set position): the position known again.
* :meth:`SessionRecover.home`: a step/dir machine's home switches (:mod:`cam.drive.homing`: the mock with its
  simulated switches, or a parallel port), grbl's ``$H``; the MAXIMUS board has no switches cam reads (refused in
  one line).

Like the other parts it keeps no state of its own: it works on the attributes ``MachineSession.__init__`` sets
(``port``, ``kind``, ``settings``, ``state_hold``, ``grbl``, ``realtime``, ``_lock``, ``_position``) and calls
the session's methods (``_check_free``, ``_start_moves``, ``_begin``, ``_spawn``, ``finish``, ``log``, ``_bump``).
Frames: machine steps (+Z deeper).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Optional

import numpy as np

from ..errors import CamError, CapabilityError, PlanError
from ..job.moves import jog as jog_job
from ..settings import MachineSettings
from ..values import shown, steps_in_range, xyz_numbers, xyz_steps
from ._session_checks import SessionChecks
from ._session_parts import Activity
from .homing import HomingPhase, check_homing, home
from .machines import open_port
from .ports import MockPort, SwitchSchedule
from .runner import Controller
from .state import MachineState, PositionUnknownError, check_in_travel, soft_limits_off

__all__ = ["SessionRecover", "UNKNOWN_JOG_LINE", "steps_of", "maximus_cannot_home"]

UNKNOWN_JOG_LINE = "position unknown: soft limits are off for this jog"
"""What the log (and the CLI's stderr) says of a jog made while the position is unknown."""


def maximus_cannot_home(port: str) -> CapabilityError:
    """What a MAXIMUS board can do instead of homing, in one line (cam home and the page's Home say it alike): its
    firmware has no homing (seed 000 Appendix 1: mode selection, Jog and Drill mode only) and its limit switches
    only stop a move, so the board origin is where the operator jogs the head and sets it."""
    return CapabilityError(f"{port} (the MAXIMUS board) cannot home: its firmware has no homing and its limit "
                           f"switches only stop a move; jog the head to the board origin (cam jog, the page's jog "
                           f"buttons) and set it there (cam where --set 0,0,0, the page's Set position). Homing "
                           f"needs a step/dir port with home switches, or grbl")


def steps_of(xyz: Any, unit: Any, settings: MachineSettings, name: str = "xyz") -> tuple[int, int, int]:
    """A position given as X, Y, Z in ``unit`` (``"mm"`` or ``"steps"``) as machine steps: finite numbers (no text,
    no booleans), whole in steps, at most :data:`cam.values.MAX_ABS_STEPS` either way once converted.

    Raises:
        PlanError: naming the field and the axis."""
    if not isinstance(unit, str) or unit not in ("mm", "steps"):
        raise PlanError(f"unit must be 'mm' or 'steps', got {shown(unit)}")
    if unit == "steps":
        return xyz_steps(xyz, name)
    values = xyz_numbers(xyz, name)
    per = settings.mm_per_step_axes
    x, y, z = (steps_in_range(v / p, f"{name} {a}", asked=f"{v:g} mm") for v, p, a in zip(values, per, "XYZ"))
    return x, y, z


class SessionRecover(SessionChecks):
    """Jog while the position is unknown, Set position, Home (a mixin; see the module)."""

    def set_position(self, position_steps: Any, unit: str = "steps", *, name: str = "position") -> None:
        """Tell the session where the tool stands (machine frame; e.g. after homing by hand, an emergency stop or a
        limit stop): 3 numbers in ``unit`` (``"steps"``: whole numbers; ``"mm"``), checked as :func:`steps_of`
        (``name``: what a refusal calls the field).  With a state file the position is known from here on (not
        homed) and must lie in the travel; on grbl its alarm is unlocked where the tool stands.  Refused while
        busy (nothing changes on a refusal)."""
        position = steps_of(position_steps, unit, self.settings, name)
        with self._lock:
            self._check_free()
            if self.state_hold is not None:
                check_in_travel(position, self.settings, "the position given")
            self.backend.rebase(self, position)  # the user's word: a board that keeps its position takes it
            self._position = np.asarray(position, np.int64)
            if self.state_hold is not None:  # the user's word: the machine frame is not the switches' any more
                st = self.state_hold.state.moved_to(position)
                self.state_hold.record(replace(st, homed=False, tool_probe=None))  # a new frame: no tool's contact
            self._bump()
        if self.state_hold is not None:
            self.log(f"position set: machine {list(position)} steps (position known)")

    def _jog_unknown(self, axis: str, steps: int) -> bool:
        """With the position unknown (the lock held): start the jog with the soft limits off, the position kept
        unknown after it; True.  False: the position is known (the caller jogs as usual)."""
        hold = self.state_hold
        if hold is None or hold.state.position_known:
            return False
        try:
            hold.require_known()  # a missing device (a typo in --port) is still refused first
        except PositionUnknownError:
            pass
        self.backend.require(self.port, "jog", "a jog")
        reason = hold.state.unknown_reason or "not recorded"
        job = jog_job(axis, steps, settings=soft_limits_off(self.settings))
        self.log(UNKNOWN_JOG_LINE, "warning")
        self.backend.before_unknown_jog(self)  # grbl: its alarm unlocked for the jog
        self._start_moves("jog", job, job.source)
        if self._activity is not None:  # the worker books its end under this lock: not before this line
            self._activity.unknown_reason = reason
        return True

    def home(self, axes: Optional[str] = None) -> None:
        """Home the machine in the background: on a step/dir port with home switches (``[inputs]``; the mock with
        its simulated ones, ``[mock]``) each axis of ``axes`` (default ``[homing] order``) as
        :func:`cam.drive.homing.home` does; on grbl its own ``$H`` (all axes).  It may start while the position is
        unknown (that is what it is for); when it has finished the position is known and homed, else unknown.

        Raises:
            CapabilityError: a MAXIMUS board (no home switches cam reads), the mock without simulated switches,
            ``axes`` on grbl; HomingError: no home switch wired; BusyError."""
        if self.backend.home(self, axes):  # a board that homes with its own cycle (grbl's $H)
            return
        self.backend.home_refusal(self.port)
        order = check_homing(self.settings, axes)
        with self._lock:
            self._check_free()
            port = self._homing_port()
            hold = self.state_hold
            was = None if hold is None else hold.state
            if hold is not None:  # until homing has finished nothing says where the tool is
                hold.record(hold.state.lost("homing did not finish"))
            ctl = Controller()
            self._begin(Activity("home", f"home {order.upper()}", ctl, len(order), 0.0))
            self.log(f"home {order.upper()}: started")
            self._spawn(home_on_steps, (self, ctl, order, port, was), "home")

    def _homing_port(self) -> Any:
        """The port homing runs on: the session's own mock (given its switches), a new mock with the machine
        file's simulated switches, or the parallel port (opened by the worker)."""
        if not self.backend.can("simulated", self.port):
            return self.port
        if not self.settings.mock.places():
            raise CapabilityError("the mock port has no switches to find: give their places in the machine file's "
                                  "[mock] table (home_x_steps = 0, ...; see docs/machine-and-ports.md)")
        switches = SwitchSchedule(self.settings, tuple(int(v) for v in self._position))
        if isinstance(self.port, MockPort):
            self.port.switches = switches
            return self.port
        return MockPort(switches=switches)


def home_on_steps(session: Any, ctl: Controller, order: str, port: Any, was: Optional[MachineState]) -> None:
    """The worker of :meth:`SessionRecover.home` on a step/dir port: each axis of ``order`` homed, each phase
    logged; the state file told (homed, or the position unknown when homing did not finish).  ``was``: the state
    before (a new machine homed on some axes only stays unknown, as ``cam home`` always said)."""
    start = session.position_steps()
    moved = [0, 0, 0]
    error = ""

    def said(p: HomingPhase) -> None:
        moved["xyz".index(p.axis)] += p.moved_steps
        session.detail(f"homing {p.axis.upper()}: {p.phase} {p.moved_steps:+d} steps at {p.speed_mm_s:g} mm/s")

    opened = None
    try:
        opened = open_port(port, session.settings)
        result = home(opened, session.settings, start, axes=order, realtime=session.realtime, controller=ctl,
                      on_phase=said)
        end = tuple(int(v) for v in result.position_steps)
    except CamError as exc:
        error = "stopped" if ctl.stop_requested and not ctl.estop_requested else str(exc)
        end = tuple(int(s) + m for s, m in zip(start, moved))
    except Exception as exc:  # noqa: BLE001 - reported in the log; nothing more is sent
        error, end = f"internal error: {type(exc).__name__}: {exc}", tuple(int(s) + m for s, m in zip(start, moved))
    finally:
        if opened is not None and not isinstance(opened, MockPort):
            opened.close()
    _book_homing(session, ctl, order, start, end, error, was)


def _book_homing(session: Any, ctl: Controller, order: str, start: Any, end: Any, error: str,
                 was: Optional[MachineState]) -> None:
    """The end of a step/dir homing: the state file first (whoever sees the session idle sees it homed, or the
    position unknown), then the session's end."""
    hold = session.state_hold
    left = "".join(a for a in "XYZ" if a.lower() not in order)
    if hold is not None and error:
        hold.record(hold.state.lost(f"homing did not finish ({error})", end))
    elif hold is not None and left and was is not None and not was.position_known and not hold.existed:
        # a new machine: the axes not homed have no coordinate at all, not even a guess to keep (issue #43 point 5);
        # the end booked keeps it unknown (after a stop the file's guess is kept, as cam home always did)
        hold.record(hold.state.lost(f"homed {order.upper()} only, {left} unknown: home every axis or say where the "
                                    f"tool is (Set position, cam where --set X,Y,Z)", end))
        with session._lock:
            if session._activity is not None:
                session._activity.unknown_reason = hold.state.unknown_reason
    elif hold is not None:
        hold.record(replace(hold.state.moved_to(end), homed=True))
    status = "finished" if not error else ("emergency-stopped" if ctl.estop_requested else
                                           "stopped" if error == "stopped" else "error")
    # the line first: whoever sees the session idle sees its log line too (a busy machine ran the waiter between)
    session.log(f"homed {order.upper()}: machine {list(end)} steps" if not error else
                f"home {order.upper()}: {error}; the position is unknown", "info" if not error else "error")
    session.finish({"activity": "home", "label": f"home {order.upper()}", "status": status,
                    "messages": [error] if error else []}, np.asarray(end, np.int64) - np.asarray(start, np.int64))
