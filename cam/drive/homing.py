"""Homing: find each axis's home switch and set the machine's zero there (issue #29 point 5).

The pattern of LinuxCNC's HOME_SEARCH_VEL / HOME_LATCH_VEL / HOME_OFFSET, one axis at a time in the machine
file's ``[homing] order`` (Z first by default: the tool goes up, clear of the work):

1. **search**: toward the switch (``direction_A``) at ``search_speed_A_mm_s`` until it closes (at most the
   axis's travel and a half: a switch that never closes is an error);
2. **back off**: away at the search speed until it opens, then ``backoff_A_mm`` further;
3. **latch**: toward it again at ``latch_speed_A_mm_s`` until it closes: there the axis's machine coordinate
   is ``offset_A_mm`` (the tool stays there).

Each phase is a run of the runner (:func:`cam.drive.runner.run`) that ends when the switch changes
(:class:`cam.drive.runner.SwitchWatch`, status :data:`~cam.drive.runner.SWITCHED`); the search speed is at
most the axis's start speed, so the axis may stop at once when the switch closes.  Limit switches that share
the home switch's pin stop nothing while that axis homes; any other limit switch or the e-stop ends homing
(:class:`HomingError`: the position is unknown).  Frames: machine steps, +Z deeper.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from ..errors import CamError
from ..job.model import travel_job
from ..settings import MAX_TRAVEL_STEPS, MachineSettings, Travel
from ..motion.chunks import plan_chunks
from .ports import MockPort, Port
from .runner import FINISHED, SWITCHED, Controller, RunResult, SwitchWatch, run

__all__ = ["HomingError", "HomingPhase", "HomingResult", "home", "check_homing", "seek", "PHASES"]

PHASES = ("search", "back off", "clear", "latch")
"""The runs of one axis's homing, in order ("clear": the back-off's extra ``backoff_A_mm``)."""

Steps3 = tuple[int, int, int]


class HomingError(CamError):
    """Homing could not finish (a switch that never changed, a limit switch, the e-stop, a stop): the machine is
    not homed and its position is unknown."""


@dataclass
class HomingPhase:
    """One run of homing: the axis, the phase (:data:`PHASES`), the steps it moved, its speed (mm/s)."""

    axis: str
    phase: str
    moved_steps: int
    speed_mm_s: float
    writes: int


@dataclass
class HomingResult:
    """How homing ended: the machine position (steps, machine frame: the homed axes at their offsets) and each
    phase run."""

    position_steps: Steps3
    phases: list[HomingPhase] = field(default_factory=list)


def check_homing(settings: MachineSettings, axes: Optional[str] = None) -> str:
    """The axes to home (``axes``, else ``[homing] order``), lower case, each with a wired home switch.

    Raises:
        HomingError: no home switch is wired, or an axis to home has none (naming its ``[inputs]`` key).
    """
    wired = settings.inputs.wired()
    if not any(name.startswith("home") for name in wired):
        raise HomingError("no home switches in the machine file: wire them in [inputs] (home_x = \"!10\", ...; "
                          "see docs/machine-and-ports.md)")
    order = (axes or settings.homing.order).lower()
    for a in order:
        if f"home_{a}" not in wired:
            raise HomingError(f"axis {a.upper()} has no home switch: set inputs.home_{a} in the machine file, or "
                              f"leave {a} out of homing.order")
    return order


def _speed_settings(settings: MachineSettings, axis: int, speed_mm_s: float) -> MachineSettings:
    """``settings`` that step one axis at ``speed_mm_s``, constantly (at most its start speed: no ramp is
    needed), anywhere (the position is not known yet)."""
    per_mm = settings.mm_per_step_z if axis == 2 else settings.mm_per_step_xy
    period_ms = max(0.001, per_mm / speed_mm_s * 1000.0)
    wide = Travel(-MAX_TRAVEL_STEPS, MAX_TRAVEL_STEPS, -MAX_TRAVEL_STEPS, MAX_TRAVEL_STEPS, -MAX_TRAVEL_STEPS,
                  MAX_TRAVEL_STEPS)
    key = "delay_z_ms" if axis == 2 else "delay_xy_ms"
    return dataclasses.replace(settings, ramp="constant", travel=wide, **{key: period_ms})


def seek(port: Port, settings: MachineSettings, axis: int, steps: int, speed_mm_s: float, *,
         until: Optional[tuple[str, bool]] = None, ignore: "frozenset[str] | tuple[str, ...]" = (),
         realtime: bool = False, controller: Optional[Controller] = None, source: str = "seek") -> RunResult:
    """One run of ``steps`` (signed, machine steps) on ``axis`` (0, 1, 2: X, Y, Z) at ``speed_mm_s``, constantly
    (no ramp: at most the axis's start speed, so it stops at once), ending when ``until`` (``(switch name,
    closed)``) holds: status :data:`~cam.drive.runner.SWITCHED`, the tool on the first step where it holds.  The
    limit switches and the e-stop end it too (but those of ``ignore``).  Homing's phases and probing
    (:mod:`cam.drive.probing`) are such runs.  On a mock the next run's writes go on from this one's time."""
    s = _speed_settings(settings, axis, speed_mm_s)
    target = [0, 0, 0]
    target[axis] = int(steps)
    plan = plan_chunks(travel_job(np.array([target], np.int64), s, source=source))
    result = run(plan, port, realtime=realtime, controller=controller or Controller(),
                 switches=SwitchWatch(s, until=until, ignore=ignore))
    if isinstance(port, MockPort):  # the next run's writes go on from this one's time
        port.time_offset_ns += int(round(result.machine_time_s * 1e9)) + int(plan.settings.delay_xy_ns)
    return result


class _Homer:
    """Runs the phases of homing on one open port, one time line (a mock's pin log runs on from phase to
    phase)."""

    def __init__(self, port: Port, settings: MachineSettings, realtime: bool, controller: Controller,
                 on_phase: Optional[Callable[[HomingPhase], None]]) -> None:
        self.port, self.settings, self.realtime, self.ctl = port, settings, realtime, controller
        self.on_phase = on_phase
        self.phases: list[HomingPhase] = []

    def move(self, axis: int, steps: int, speed_mm_s: float, phase: str, until: Optional[tuple[str, bool]],
             ignore: frozenset) -> RunResult:
        """One run: ``steps`` on ``axis`` at ``speed_mm_s``, ending when ``until`` holds."""
        result = seek(self.port, self.settings, axis, steps, speed_mm_s, until=until, ignore=ignore,
                      realtime=self.realtime, controller=self.ctl, source=f"homing {phase}")
        done = HomingPhase("xyz"[axis], phase, int(result.position_steps[axis]), speed_mm_s, result.writes)
        self.phases.append(done)
        if self.on_phase is not None:
            self.on_phase(done)
        if result.status not in (FINISHED, SWITCHED):
            raise HomingError(f"homing {'XYZ'[axis]} ({phase}) ended: " + "; ".join(result.messages or [result.status]))
        return result

    def axis(self, a: str) -> int:
        """Home axis ``a``; returns the steps moved from where it started to the latch point."""
        h, i = self.settings.homing, "xyz".index(a)
        sign = -1 if getattr(h, f"direction_{a}") == "-" else 1
        per_mm = self.settings.mm_per_step_z if a == "z" else self.settings.mm_per_step_xy
        lo, hi = self.settings.travel.bounds_steps()[i]
        reach = (hi - lo) * 3 // 2 + 10
        search, latch = h.speeds_mm_s(self.settings, a)
        name = f"home_{a}"
        ignore = frozenset(n for n, (pin, _) in self.settings.inputs.wired().items()
                           if n.startswith("limit") and pin == self.settings.inputs.wired()[name][0])
        moved = 0
        r = self.move(i, sign * reach, search, "search", (name, True), ignore)
        if r.status != SWITCHED:
            raise HomingError(f"{name} did not close within {reach * per_mm:g} mm of searching {a.upper()}"
                              f"{'-' if sign < 0 else '+'}: is it wired to the pin inputs.{name} names?")
        moved += r.position_steps[i]
        r = self.move(i, -sign * reach, search, "back off", (name, False), ignore)
        if r.status != SWITCHED:
            raise HomingError(f"{name} did not open again within {reach * per_mm:g} mm of backing off")
        moved += r.position_steps[i]
        clear = int(round(getattr(h, f"backoff_{a}_mm") / per_mm))
        if clear:
            r = self.move(i, -sign * clear, search, "clear", None, ignore)
            moved += r.position_steps[i]
        r = self.move(i, sign * (2 * clear + reach // 10 + 10), latch, "latch", (name, True), ignore)
        if r.status != SWITCHED:
            raise HomingError(f"{name} did not close again at the latch speed")
        return moved + r.position_steps[i]


def home(port: Port, settings: MachineSettings, start_steps: Steps3 = (0, 0, 0), *, axes: Optional[str] = None,
         realtime: bool = False, controller: Optional[Controller] = None,
         on_phase: Optional[Callable[[HomingPhase], None]] = None) -> HomingResult:
    """Home the machine on an open step/dir ``port``: each axis of ``axes`` (default ``[homing] order``) in turn.

    Args:
        port: a :class:`~cam.drive.ports.ParallelPort`, or a :class:`~cam.drive.ports.MockPort` with a
            :class:`~cam.drive.ports.SwitchSchedule` (real ports always run in real time).
        settings: the machine settings (``[inputs]``, ``[homing]``, the speeds and the pin map).
        start_steps: where the tool is thought to stand (machine frame): the axes not homed keep it.
        realtime: wait for each write's time on the mock.
        controller: stop homing from another thread (a stop lifts nothing more: it raises HomingError).
        on_phase: called after each phase run (:class:`HomingPhase`).

    Returns:
        A :class:`HomingResult`: the homed axes at their ``offset_A_mm`` (steps, machine frame).

    Raises:
        HomingError: no home switch for an axis, a switch that never changed, a limit switch, the e-stop, or a
        stop: the position is unknown.
    """
    order = check_homing(settings, axes)
    homer = _Homer(port, settings, realtime or not isinstance(port, MockPort), controller or Controller(), on_phase)
    position = [int(v) for v in start_steps]
    for a in order:
        i = "xyz".index(a)
        per_mm = settings.mm_per_step_z if a == "z" else settings.mm_per_step_xy
        homer.axis(a)
        position[i] = int(round(getattr(settings.homing, f"offset_{a}_mm") / per_mm))
    return HomingResult((position[0], position[1], position[2]), homer.phases)
