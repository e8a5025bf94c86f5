"""Probing on a grbl board (issue #46 point 3): ``G38.2`` and its ``[PRB:x,y,z:1]``.

The machine session's probing activity (:mod:`cam.drive.probing`) asks the grbl back end's prober
(:class:`GrblProber`) to travel (``G53 G0``: up to the safe height first, across, down to it) and to probe: ``G91
G38.2 Z-<depth> F<feed>`` (grbl's Z is up: cam's +Z deeper is grbl's -Z, :func:`~cam.drive.grbl_machine.mpos_to_steps`),
whose ``[PRB:x,y,z:1]`` report before the ``ok`` is where the probe touched; grbl stops a deceleration past it, and
the prober lifts back to where the probe began (``G53 G0 Z``).  A grid's guarded move down to just above the surface
(:meth:`GrblProber.descend`) is ``G91 G38.3 Z-<depth>``: no alarm when it touches nothing (``[PRB:...:0]``).

A probe that touches nothing within its depth is grbl's ``ALARM:5`` (``ALARM:4``: the probe touched before it
moved).  It comes as every alarm does (:class:`~cam.drive.grbl_link.GrblAlarm`) and is handled by the fault path:
grbl stopped first (feed hold, then a soft reset once still: :meth:`~cam.drive.grbl_link.GrblLink.halt`), then
unlocked (``$X``: a probe fail loses no position), the tool lifted back, and the probe ends in one line, the
position then as grbl reports it.  A stop and an emergency stop are the grbl session's (:class:`GrblControl`);
any other fault is :func:`~cam.drive.grbl_machine.fault_stop`'s (the position unknown).
"""
from __future__ import annotations

import re
from dataclasses import replace
from typing import Any, Optional

import numpy as np

from ..kinds.gcode_export import format_mm
from ..settings import MachineSettings
from .grbl_link import GrblAlarm, GrblError
from .grbl_machine import GRBL_OFFSETS, GrblControl, GrblMachine, fault_stop, finish_stop, mpos_to_steps, steps_to_mpos
from .probing import DEFAULT_FEED_MM_MIN, ProbeError, Prober, ProbeResult, ProbeRun

__all__ = ["GrblProber", "parse_prb", "start_probe_on_grbl", "grbl_set_work_z"]

Steps3 = tuple[int, int, int]

_PRB = re.compile(r"^\[PRB:([-+\d.]+),([-+\d.]+),([-+\d.]+)(?:,[-+\d.]+)*:([01])\]$")


def parse_prb(lines: Any) -> Optional[tuple[tuple[float, float, float], bool]]:
    """grbl's probe report among ``lines``: ``((x, y, z) mm, touched)``, or None when there is none.

    >>> parse_prb(["[PRB:10.000,-20.000,-4.600:1]"])
    ((10.0, -20.0, -4.6), True)
    """
    for line in lines:
        m = _PRB.match(str(line).strip())
        if m:
            return (float(m.group(1)), float(m.group(2)), float(m.group(3))), m.group(4) == "1"
    return None


class GrblProber(Prober):
    """Probing on the session's grbl board (see the module)."""

    def __init__(self, session: Any, ctl: GrblControl) -> None:
        self.machine: GrblMachine = session.grbl
        self.link = self.machine.link
        self.settings: MachineSettings = session.settings
        self.ctl = ctl
        self.link.allow()
        self.link.stream(["G21G90G94"], wait_idle=False)

    def position(self) -> Steps3:
        return self.machine.position_steps(self.link.status())

    def _z_text(self, z_steps: int) -> str:
        return format_mm(self._mpos((0, 0, z_steps))[2])

    def _mpos(self, steps: Any) -> tuple[float, float, float]:
        return steps_to_mpos(np.asarray(steps, np.int64) - np.asarray(self.machine.base_steps, np.int64),
                             self.settings)

    def travel(self, target_steps: Steps3) -> None:
        x, y, z = (int(v) for v in target_steps)
        x0, y0, z0 = self.position()
        mx, my, _ = self._mpos((x, y, z))
        lines = []
        if z0 > z:  # deeper than the safe height: up first
            lines.append(f"G53G0Z{self._z_text(z)}")
        if (x, y) != (x0, y0):
            lines.append(f"G53G0X{format_mm(mx)}Y{format_mm(my)}")
        if z0 < z:
            lines.append(f"G53G0Z{self._z_text(z)}")
        if lines:
            self.link.stream(lines, wait_idle=True)

    def _lift_to(self, z_steps: int) -> None:
        self.link.stream([f"G53G0Z{self._z_text(z_steps)}"], wait_idle=True)

    def probe(self, depth_steps: int, feed_mm_min: float) -> ProbeResult:
        start = self.position()
        depth_mm = int(depth_steps) * self.settings.mm_per_step_z
        try:
            lines = self.link.command(f"G91G38.2Z-{format_mm(depth_mm)}F{format_mm(feed_mm_min)}", timeout_s=None)
        except GrblAlarm as exc:
            if exc.code not in (4, 5):
                raise
            return self._failed(exc, start, int(depth_steps))
        self.link.command("G90")
        prb = parse_prb(lines)
        if prb is None or not prb[1]:
            raise GrblError(f"grbl on {self.link.device} answered G38.2 without a probe report [PRB:x,y,z:1] "
                            f"({'; '.join(lines) or 'nothing'})")
        raw = mpos_to_steps(prb[0], self.settings)
        contact = tuple(int(r) + int(b) for r, b in zip(raw, self.machine.base_steps))
        self._lift_to(start[2])
        return ProbeResult(start, contact, self.position(), int(depth_steps))  # type: ignore[arg-type]

    def descend(self, depth_steps: int, feed_mm_min: float) -> Optional[Steps3]:
        """A guarded move down: ``G91 G38.3 Z-<depth>`` (a probe toward the work that raises no alarm when it touches
        nothing), its ``[PRB:x,y,z:0|1]`` saying whether and where the probe closed; no lift."""
        depth_mm = int(depth_steps) * self.settings.mm_per_step_z
        try:
            lines = self.link.command(f"G91G38.3Z-{format_mm(depth_mm)}F{format_mm(feed_mm_min)}", timeout_s=None)
        except GrblAlarm as exc:
            if exc.code != 4:
                raise
            self._failed(exc, self.position(), int(depth_steps))  # ALARM:4: a ProbeError, the tool lifted back
            raise
        return self._trip_after(lines, "G38.3")

    def _trip_after(self, lines: list[str], code: str) -> Optional[Steps3]:
        """After a probing move ``code`` answered ``lines``: back to absolute (G90), and where its probe report
        says the probe tripped (machine steps), or None when it did not trip.

        Raises:
            GrblError: no probe report among ``lines``."""
        self.link.command("G90")
        prb = parse_prb(lines)
        if prb is None:
            raise GrblError(f"grbl on {self.link.device} answered {code} without a probe report [PRB:x,y,z:0|1] "
                            f"({'; '.join(lines) or 'nothing'})")
        if not prb[1]:
            return None
        raw = mpos_to_steps(prb[0], self.settings)
        return tuple(int(r) + int(b) for r, b in zip(raw, self.machine.base_steps))  # type: ignore[return-value]

    def _failed(self, exc: GrblAlarm, start: Steps3, depth_steps: int) -> ProbeResult:
        """A probe fail (ALARM:4 or 5) by the fault path: grbl stopped (feed hold, soft reset once still), then
        unlocked (a probe fail keeps the position), the tool lifted back; ALARM:4 is a ProbeError."""
        if not self.link.halt(str(exc)):
            raise GrblError(f"{exc}; cam could not reach grbl to stop it: check the machine")
        self.link.allow()
        if self.machine.in_alarm():
            self.link.unlock()
        self.link.stream(["G21G90G94"], wait_idle=False)
        self._lift_to(start[2])
        end = self.position()
        if exc.code == 4:
            raise ProbeError(f"probe: grbl raised ALARM:4: the probe was closed before it moved (the tool touches the "
                             f"work already, or $6, the probe pin's inversion, is wrong); the tool is back at machine "
                             f"Z {end[2]} steps, position known; lift it and probe again")
        return ProbeResult(start, None, end, depth_steps, note="grbl's ALARM:5, probe fail")

    def close(self, ctl: Any, fault: str) -> tuple[Optional[Steps3], str]:
        lost = ""
        if ctl.halted:
            lost = finish_stop(self.machine, ctl)
        elif fault:
            lost = fault_stop(self.machine, fault)
        try:
            end: Optional[Steps3] = self.machine.position_steps(self.machine.status())
        except GrblError as exc:
            end, lost = None, lost or str(exc)
        return end, lost


def start_probe_on_grbl(session: Any, probe_run: ProbeRun) -> None:
    """Start a probing activity on the session's grbl board (the grbl back end's ``start_probe``)."""
    assert session.grbl is not None
    ctl = GrblControl(session.grbl)
    run_ = probe_run if probe_run.feed_mm_min is not None else replace(probe_run, feed_mm_min=DEFAULT_FEED_MM_MIN)
    session._launch_probe(run_, ctl, lambda: GrblProber(session, ctl))


def grbl_set_work_z(machine: GrblMachine, offset: str, z_steps: int, settings: MachineSettings) -> None:
    """grbl's own work offset ``offset`` (G54-G59) Z zero at machine Z ``z_steps`` (``G10 L2 P<n> Z<mm>``: its Z
    offset is the zero's machine position), so that grbl's display agrees with the state file."""
    if offset not in GRBL_OFFSETS:
        return  # G59.1-G59.3: cam's own; grbl has none
    mz = steps_to_mpos(np.asarray((0, 0, z_steps), np.int64) - np.asarray(machine.base_steps, np.int64), settings)[2]
    machine.link.allow()
    machine.link.command(f"G10L2P{GRBL_OFFSETS.index(offset) + 1}Z{format_mm(mz)}")
