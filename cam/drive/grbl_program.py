"""A G-code program that probes, on grbl (issue #46 point 2): its parts streamed as any job's lines, its probes
grbl's own ``G38.2``/``G38.3`` (see :mod:`cam.drive.program_probe`, which runs them)."""
from __future__ import annotations

from typing import Any, Optional

from ..kinds.gcode_export import format_mm
from .grbl_link import GrblAlarm
from .grbl_machine import GrblControl, GrblPosition, _stream_until_pause, job_lines
from .grbl_probe import GrblProber
from .probing import ProbeEnded, ProbeError
from .program_probe import PauseFn, ProgressFn, launch_program
from .runner import EMERGENCY_STOPPED, STOPPED

__all__ = ["GrblProgram", "start_program_on_grbl"]

Steps3 = tuple[int, int, int]


class GrblProgram(GrblProber):
    """A program that probes on grbl: its parts streamed as any job's lines, its probes grbl's own G38.2/G38.3."""

    def run_part(self, job: Any, on_pause: PauseFn, progress: ProgressFn) -> None:
        start = self.position()
        position = GrblPosition(self.machine, start)
        items = job_lines(job, start, self.machine.base_steps, self.settings, lambda index: progress(index + 1, 0, 0))
        self.link.stream(["G21G90G94"], wait_idle=False)
        while True:
            pause = _stream_until_pause(self.link, items, position)
            if pause is None or self.ctl.halted:
                break
            on_pause(pause.position_steps, pause.note)
            if self.ctl.halted:
                break
        if self.ctl.halted:
            raise ProbeEnded(EMERGENCY_STOPPED if self.ctl.estopped else STOPPED, "the program: " +
                             ("emergency stop" if self.ctl.estopped else "stopped"))

    def program_probe(self, code: str, depth_steps: int, feed_mm_min: float) -> Optional[Steps3]:
        """``G91 G38.x Z-<depth> F<feed>``, then ``G90``: where grbl's ``[PRB:...:1]`` says it touched (the tool
        where grbl stopped), or None (``G38.3``'s ``[PRB:...:0]``, or ``G38.2``'s ``ALARM:5``: the tool lifted back
        to where the probe began)."""
        start = self.position()
        depth_mm = int(depth_steps) * self.settings.mm_per_step_z
        try:
            lines = self.link.command(f"G91{code}Z-{format_mm(depth_mm)}F{format_mm(feed_mm_min)}", timeout_s=None)
        except GrblAlarm as exc:
            if exc.code not in (4, 5):
                raise
            try:
                self._failed(exc, start, int(depth_steps))
            except ProbeError:
                raise ProbeError(f"{code}: grbl raised ALARM:4: the probe was closed before it moved (rs274: the "
                                 "probe is already tripped; or $6, the probe pin's inversion, is wrong); the tool is "
                                 f"back at machine Z {self.position()[2]} steps") from None
            return None
        return self._trip_after(lines, code)

    def lift_to(self, z_steps: int) -> None:
        if self.position()[2] != int(z_steps):
            self._lift_to(int(z_steps))


def start_program_on_grbl(session: Any, job: Any, name: str, controller: Any) -> None:
    """Start a program that probes on the session's grbl board (the grbl back end's ``start_program``)."""
    ctl = GrblControl(session.grbl)
    total = sum(len(piece) for piece in job.moves.pieces()) if job.moves is not None else 1
    launch_program(session, name, ctl, total, job.estimated_s, job.probing, lambda: GrblProgram(session, ctl))
