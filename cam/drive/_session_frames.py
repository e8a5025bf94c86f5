"""A part of :class:`~cam.drive.session.MachineSession`: where the machine is (issue #29).

:class:`SessionFrames` holds what a session does with the machine's state file (a
:class:`~cam.drive.state.StateHold`): work zeros and offsets, Go To, where the tool is in both frames, placing a
file's job at the work zero, booking every end; and the MAXIMUS board's Z Drill Up/Down and its live position.
It keeps no state of its own: it works on the attributes ``MachineSession.__init__`` sets, under the session's
lock (``_lock``, ``_position``, ``state_hold``, ``settings``, ``kind``, ``port``, ``_activity``,
``_activity_start``, ``_then``), and calls its methods (``_check_free``, ``_check_job``, ``_start_moves``,
``start``, ``log``, ``_bump``, ``position_steps``).

Frames: machine steps from the machine's home with a state file (+Z deeper), else from where the tool stood when
the session opened.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Optional

import numpy as np

from ..errors import CamError, PlanError
from ._session_parts import SessionControls
from .placement import approach_to_work_zero, ended_state, goto_path, placed_home
from .machine_job import MachineJob
from .machines import require
from .runner import Controller
from .state import steps_to_mm, check_in_travel, still_unknown
from ..values import shown, steps_in_range, xyz_numbers

__all__ = ["SessionFrames"]


class SessionFrames(SessionControls):
    """Work zeros and offsets, Go To, where the tool is, placing jobs, booking ends (a mixin; see the module)."""

    def _require_known(self) -> None:
        if self.state_hold is not None:
            self.state_hold.require_known()

    def _place(self, job: MachineJob, label: Optional[str], controller: Optional[Controller], journal: Any,
               origin: Optional[str]) -> bool:
        """With a state file: travel to the job's place at the work zero first (the job starts when the travel
        has finished).  True when that travel was started; False: the job starts here, as it is."""
        if self.state_hold is None or job.resumed:
            return False
        st = self.state_hold.state
        here = tuple(int(v) for v in self._position)
        approach = approach_to_work_zero(job, st, here, self.settings, origin)  # TravelError: no move
        if approach is None:
            return False
        home = np.asarray(placed_home(job, st, origin), np.int64)
        self._position, saved = home, self._position
        try:
            self._check_job(job)  # the job as it will start there: everything checked before the travel
        finally:
            self._position = saved

        def then() -> None:
            self.start(job, label=label, controller=controller, journal=journal, origin=origin)

        self._start_moves("jog", approach, "to the work zero")
        self._then = then
        return True


    def zero(self, axes: str = "XYZ", offset: Optional[str] = None) -> None:
        """Work zero of ``axes`` (``"X"``, ``"XY"``, ``"XYZ"``...) where the tool stands, in work offset ``offset``
        (``"G54"``..``"G59.3"``; None: the active one).  Without a state file the session's home moves there on
        those axes instead.  Refused while busy or while the position is unknown."""
        names = axes.upper() if isinstance(axes, str) else ""
        if not names or any(a not in "XYZ" for a in names) or len(set(names)) != len(names):
            raise PlanError(f"axes must be X, Y, Z or several of them (XY, XYZ), got {shown(axes)}")
        with self._lock:
            self._check_free()
            self._require_known()
            here = [int(v) for v in self._position]
            if self.state_hold is None:
                for a in names:
                    here["XYZ".index(a)] = 0
                self._position = np.asarray(here, np.int64)
                self.backend.rebase(self, tuple(here))
                self._bump()
                self.log(f"this position is the origin of {names} now")
                return
            st = self.state_hold.state
            name = offset or st.active_offset
            if not isinstance(name, str) or name not in st.offsets_steps:
                raise PlanError(f"offset must be one of {', '.join(st.offsets_steps)}, got {offset!r}")
            zero = list(st.work_zero_steps(name))
            for a in names:
                zero["XYZ".index(a)] = here["XYZ".index(a)]
            self.state_hold.record(st.with_offset(name, tuple(zero)))  # type: ignore[arg-type]
            self.backend.work_zero_set(self, name, names)  # a board that keeps offsets: its own agree
            self._bump()
        zmm = steps_to_mm(zero, self.settings)
        self.log(f"{name} zero of {names} set here: machine {', '.join(f'{v:g}' for v in zmm)} mm")

    def use_offset(self, offset: str) -> None:
        """Make work offset ``offset`` (``"G54"``..``"G59.3"``) the active one (a state file is needed)."""
        with self._lock:
            self._check_free()
            if self.state_hold is None:
                raise CamError("work offsets need a machine state file (cam serve --state FILE)")
            st = self.state_hold.state
            if not isinstance(offset, str) or offset not in st.offsets_steps:
                raise PlanError(f"offset must be one of {', '.join(st.offsets_steps)}, got {shown(offset)}")
            self.state_hold.record(replace(st, active_offset=offset))
            self.backend.offset_used(self, offset)
            self._bump()
        self.log(f"work offset {offset} active")

    def go_to(self, xyz: Any, unit: str = "mm", *, machine_coords: bool = False) -> None:
        """Go To ``xyz`` (a list of 3 numbers, ``unit`` ``"mm"`` or ``"steps"``) in the active work frame
        (``machine_coords``: the machine frame): lifted to the safe height first (the work zero's surface, or
        higher), across, then down.  Each number must be finite (no text such as ``"123"``, no booleans) and, in
        steps, at most :data:`cam.values.MAX_ABS_STEPS` either way.  Refused while busy, while the position is
        unknown, or outside the travel (nothing moves)."""
        values = xyz_numbers(xyz, "xyz")
        if not isinstance(machine_coords, bool):
            raise PlanError(f"machine must be true or false, got {shown(machine_coords)}")
        if not isinstance(unit, str) or unit not in ("mm", "steps"):
            raise PlanError(f"unit must be 'mm' or 'steps', got {shown(unit)}")
        s = self.settings
        per = s.mm_per_step_axes if unit == "mm" else (1.0, 1.0, 1.0)
        rel = tuple(steps_in_range(v / p, f"xyz {a}", asked=f"{v:g} {unit}") for v, p, a in zip(values, per, "XYZ"))
        with self._lock:
            self._check_free()
            self._require_known()
            st = self.state_hold.state if self.state_hold is not None else None
            zero = (0, 0, 0) if machine_coords or st is None else st.work_zero_steps()
            target = tuple(int(z) + int(r) for z, r in zip(zero, rel))
            frame = "machine" if machine_coords or st is None else st.active_offset
            if st is not None:
                check_in_travel(target, self.settings, f"X,Y,Z {', '.join(f'{v:g}' for v in values)} {unit} in "
                                                       f"{frame} (machine {list(target)} steps)")
            here = tuple(int(v) for v in self._position)
            job = goto_path(here, target, zero[2], self.settings)  # type: ignore[arg-type]
            if job is None:
                self.log("already there")
                return
            self._start_moves("jog", job, f"go to {', '.join(f'{v:g}' for v in values)} {unit} ({frame})")

    def state(self, log_after: int = 0) -> dict[str, Any]:
        """The view's snapshot (:meth:`SessionView.state`) with ``where``: machine and work position, live
        (:meth:`where`)."""
        with self._lock:
            snap = super().state(log_after)
            snap["where"] = self.where()
            snap["spindle"] = self.spindle_state()
            return snap

    def where(self) -> dict[str, Any]:
        """Machine and work position now (live while something runs), the active offset and the flags:
        JSON-able.  Without a state file the machine frame is the session's (home: where the tool stood at
        the start), and the work frame is the same."""
        s = self.settings
        pos = self.position_steps()
        st = self.state_hold.state if self.state_hold is not None else None
        work = pos if st is None else st.to_work(pos)
        return {
            "machine_steps": list(pos), "machine_mm": [round(v, 4) for v in steps_to_mm(pos, s)],
            "work_steps": list(work), "work_mm": [round(v, 4) for v in steps_to_mm(work, s)],
            "active_offset": "G54" if st is None else st.active_offset,
            "offsets_mm": {} if st is None else {k: [round(v, 4) for v in steps_to_mm(z, s)]
                                                 for k, z in st.offsets_steps.items()},
            "position_known": True if st is None else st.position_known,
            "unknown_reason": "" if st is None else st.unknown_reason,
            "homed": False if st is None else st.homed,
            "state_file": None if self.state_hold is None else str(self.state_hold.path),
        }


    def set_drill_z(self, which: str) -> None:
        """Z Drill Up (``"up"``) or Down (``"down"``) of the MAXIMUS drill stroke from where the head stands:
        its depth below the origin in steps (seed 000 Appendix 2, ``BtnSetZDrillUpPositionClick``: up must be
        below the origin, down below up).  Drill jobs of this session use them from now on.

        Raises:
            CapabilityError: not a MAXIMUS board; PlanError: a position the stroke cannot have; BusyError.
        """
        require(self.port, "drill_stroke", what="Z Drill Up / Down")
        if which not in ("up", "down"):
            raise PlanError(f"which must be 'up' or 'down', got {which!r}")
        with self._lock:
            self._check_free()
            self._require_known()
            z = int(self._position[2])  # below the origin: the work zero's Z with a state file, else the home's
            if self.state_hold is not None:
                z -= int(self.state_hold.state.work_zero_steps()[2])
            m = self.settings.maximus
            up, down = (z, m.drill_z_down_steps) if which == "up" else (m.drill_z_up_steps, z)
            if which == "up" and z < 0:
                raise PlanError(f"Z Drill Up must not be above the origin; the head is {-z} steps above it")
            if which == "down" and not z > up:
                raise PlanError(f"Z Drill Down must be below Z Drill Up ({up} steps); the head is at {z}")
            if which == "up" and down and not down > z:
                down = 0  # the old Z down lies above the new Z up: set it again
            self.settings = self.settings.replace(maximus=replace(m, drill_z_up_steps=up, drill_z_down_steps=down))
        self.log(f"Z Drill {which.capitalize()} = {z} steps below the origin"
                 + ("" if down else "; now set Z Drill Down"))

    def spindle(self, on: Any) -> None:
        """Switch the spindle on (``on`` True) or off, on a machine with a spindle switch (the MAXIMUS board: the PC
        program's spindle switch, issue #47 point 7), in the background; the snapshot's ``spindle`` says what it
        was switched to (None: not known, after any other activity).

        Raises:
            PlanError: ``on`` not true or false; CapabilityError: no spindle switch; BusyError: something runs.
        """
        if not isinstance(on, bool):
            raise PlanError(f"on must be true or false, got {shown(on)}")
        require(self.port, "spindle", what="the spindle switch")
        with self._lock:
            self._check_free()
            self._spindle_on = None
            self.backend.spindle(self, on)

    def spindle_switched(self, on: bool) -> None:
        """The machine confirmed the spindle switch (called by the activity's thread)."""
        with self._lock:
            self._spindle_on = bool(on)
            self._bump()

    def spindle_state(self) -> Optional[bool]:
        """The spindle as the last switch left it: True, False, or None when not known (never switched, or
        another activity ran since: a drill job and a jog switch it themselves)."""
        with self._lock:
            last = self._last_activity
            if self._activity is not None or last is None or last.name != "spindle":
                return None
            return getattr(self, "_spindle_on", None)

    def board_moved(self, done: int, moved_steps: Any) -> None:
        """A MAXIMUS board confirmed a move: the head stands ``moved_steps`` (x, y, z, session frame) from where the
        running activity started, after ``done`` holes or moves (the live position: after every hole)."""
        with self._lock:
            if self._activity is not None:
                self._activity.positions = _BoardPosition(int(done), tuple(int(v) for v in moved_steps))
                self._activity.done = max(self._activity.done, int(done))
                self._bump()


    def _record_state(self) -> None:
        """Book where the activity left the machine in the state file (a write that fails is logged)."""
        if self.state_hold is None:
            return
        try:
            end = ended_state(self.state_hold.state, self, self._activity_start)
            a = self._last_activity
            if a is not None and a.unknown_reason:  # a jog made while the position was unknown: still unknown
                end = still_unknown(end, a.unknown_reason, self.settings)
            self.state_hold.record(end)
        except (CamError, OSError) as e:
            self.log(f"the machine state file {self.state_hold.path} was not written: {e}")


class _BoardPosition:
    """The live position of a MAXIMUS activity, as a runner's cursor gives it (``sent``, ``position_steps``)."""

    def __init__(self, sent: int, position_steps: tuple[int, int, int]) -> None:
        self.sent = sent
        self.position_steps = position_steps
