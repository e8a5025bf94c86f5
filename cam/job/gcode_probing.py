"""A G-code program that probes (``G38.2``, ``G38.3``), run on a machine: its moves planned a part at a time, each
part once the probe before it has touched (issue #46 point 2).

The language's side is :mod:`cam.formats._gcode_probe` (LinuxCNC's semantics: a straight feed move toward the
target that stops where the probe trips; ``G38.2`` that never trips is an error, ``G38.3`` is not; the trip point
in #5061..#5063 and the program's position there).  As in rs274, nothing after a probe can be planned before the
probe has run: the interpreter stops after each probe until it is told where it tripped.  So a run of the program
(:class:`ProgramRun`, one interpreter run, read once) gives its moves as *parts*: the moves up to the next probe,
planned by the G-code planner (:class:`~cam.job.gcode.GcodeJobStream` with the part's start: the same pieces, checks
and spill as any program's, points from where the part starts), and that probe (:class:`ProgramProbe`: its target
in steps, never below the program's; its feed).  The machine runs the part on its one job path (a step plan on a
step/dir port, lines streamed to grbl), makes the probe (:mod:`cam.drive.program_probe`) and says where it touched
(:meth:`ProgramRun.touched`); only then is the next part read from the program and planned, from there.

Before a run, the program is planned whole as if each probe touched at its target (its deepest: the prepared job's
plan, its picture, its report and every check made before anything moves, the travel included); each part after a
probe is checked again, from where the probe touched, before it is sent.

Frames: a part's :class:`~cam.job.model.Job` points are steps from where the part starts; :class:`ProgramProbe`
and :attr:`ProgramPart.start_steps` are steps from the program's start (its home: where the tool stood when it
started), in the machine's sense (+Y toward the operator unless ``flip_y``, +Z deeper).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Iterator, Optional

import numpy as np

from ..errors import PlanError
from ..formats.gcode import GcodeFile, GcodeMove, MoveBatch
from ..settings import MachineSettings
from .gcode import PIECE_MOVES, STREAM_MOVES, GcodeJobStream
from .model import JobLike

__all__ = ["ProbingProgram", "ProgramRun", "ProgramPart", "ProgramProbe"]

Steps3 = tuple[int, int, int]


@dataclass(frozen=True)
class ProgramProbe:
    """One probe of a program as a machine makes it.

    Attributes:
        code: ``"G38.2"`` (an error if it does not touch) or ``"G38.3"`` (the program goes on from its target).
        where: ``file:line`` of its line.
        target_steps: the target, steps from the program's start: X and Y where the tool stands, Z rounded toward
            the start (the probe never goes below the program's target).
        feed_mm_min: its feed.
    """

    code: str
    where: str
    target_steps: Steps3
    feed_mm_min: float

    @property
    def must_touch(self) -> bool:
        return self.code == "G38.2"


@dataclass
class ProgramPart:
    """The moves of a program up to its next probe: ``job`` (a :class:`~cam.job.model.JobLike`, points from
    ``start_steps``), where it starts (steps from the program's start) and the probe that ends it (None: the last
    part)."""

    job: JobLike
    start_steps: Steps3
    probe: Optional[ProgramProbe]


@dataclass(frozen=True)
class ProbingProgram:
    """A prepared program that probes, as a machine runs it (:attr:`cam.kinds.jobs.PreparedJob.probing`): the file
    with the options it was planned with, the machine settings and frame, and what its probes ask (the planning
    pass's: ``probes``, ``feeds_mm_min``), which a machine checks before anything moves."""

    program: GcodeFile
    settings: MachineSettings
    flip_y: bool
    home_steps: Steps3
    probes: tuple[str, ...]
    feeds_mm_min: tuple[float, ...]

    def run(self) -> "ProgramRun":
        """A new run of the program (its interpreter from the first line)."""
        return ProgramRun(self)


class _PartSource:
    """The moves of one part, as :class:`~cam.job.gcode.GcodeJobStream` reads a program: the run's batches up to its
    next probe (read once: the part's stream keeps what it planned, :attr:`GcodeJobStream.spill`)."""

    def __init__(self, run: "ProgramRun") -> None:
        self.run = run
        self.source = run.source
        self.warnings: list[str] = []
        self.read = False
        self.probe: Optional[GcodeMove] = None  # the probe that ends the part (None: the program's end)

    def move_batches(self, batch_moves: int) -> Iterator[MoveBatch]:
        if self.read:
            raise PlanError(f"{self.source}: a part of a program that probes is read once (a planner fault: please "
                            "report the file)")
        self.read = True
        for batch in self.run.batches:
            self.warnings += batch.warnings
            if batch.moves and batch.moves[-1].kind == "probe":
                self.probe = batch.moves[-1]
                yield MoveBatch(batch.moves[:-1], batch.warnings)
                return
            yield batch
        self.run.ended = True


class ProgramRun:
    """One run of a program that probes: :meth:`parts` in order, each after the last one's probe has touched
    (:meth:`touched`).  Read once."""

    def __init__(self, spec: ProbingProgram) -> None:
        self.spec = spec
        self.source = spec.program.source
        self.batches = dataclasses.replace(spec.program).move_batches(PIECE_MOVES, probed=self._probed)
        self.pending: Optional[GcodeMove] = None  # the probe that ended the last part
        self.ended = False
        self._contact_mm: Optional[tuple[float, float, float]] = None
        self._told = False
        self._start_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._start_steps: Steps3 = (0, 0, 0)
        s = spec.settings
        self._to_steps = np.array([1 / s.mm_per_step_xy, (1 if spec.flip_y else -1) / s.mm_per_step_xy,
                                   -1 / s.mm_per_step_z])

    def parts(self) -> Iterator[ProgramPart]:
        """The parts of the program, each planned (its first pass made: its travel checked from where it starts,
        in the machine frame) when it is given.

        Raises:
            ParseError, TravelError, PlanError: as the program's planning, naming the line; PlanError: the next
            part asked for before the last one's probe was told (:meth:`touched`)."""
        while not self.ended:
            if self.pending is not None and not self._told:
                raise PlanError(f"{self.source}: the part after the probe at line {self.pending.line} was asked for "
                                "before that probe had touched (a fault of the machine's run: please report it)")
            src = _PartSource(self)
            # a stop lifts to the program's start height, or to where the part starts when that is higher
            stream = GcodeJobStream(src, self.spec.settings, self.spec.flip_y, spill=True,
                                    safe_z_steps=min(0, -int(self._start_steps[2])), home_steps=self.spec.home_steps,
                                    start_mm=self._start_mm, start_steps=self._start_steps)
            held = stream.held(STREAM_MOVES)  # the whole part planned now (spilled when large): read once
            job = stream if held is None else held
            self.pending, self._told = src.probe, False  # (the last probe's contact was asked as the part was read)
            yield ProgramPart(job, self._start_steps, None if src.probe is None else self._probe(src.probe))

    def _probe(self, mv: GcodeMove) -> ProgramProbe:
        exact = np.asarray(mv.end, np.float64) * self._to_steps
        x, y = (int(math.floor(v + 0.5)) for v in exact[:2])
        z = int(math.floor(exact[2] + 1e-6))  # +Z deeper: rounded up, toward the start, never past the target
        return ProgramProbe(mv.note, f"{mv.file or self.source}:{mv.line}", (x, y, z), mv.feed_mm_min)

    def touched(self, contact_steps: Optional[Steps3], at_steps: Steps3) -> None:
        """The probe that ended the last part has run: it touched at ``contact_steps`` (None: it did not, a
        ``G38.3`` that reached its target), and the tool stands at ``at_steps`` (both steps from the program's
        start).  The next part is planned from there; the program's position is the contact (its Z: X and Y are
        the program's own), or the target."""
        mv = self.pending
        if mv is None or self._told:
            raise PlanError(f"{self.source}: no probe waits for its contact")
        if contact_steps is None:
            self._contact_mm, start = None, tuple(float(v) for v in mv.end)
        else:
            z_mm = float(int(contact_steps[2]) / self._to_steps[2])
            self._contact_mm = start = (float(mv.end[0]), float(mv.end[1]), z_mm)
        self._start_mm = start  # type: ignore[assignment]
        self._start_steps = tuple(int(v) for v in at_steps)  # type: ignore[assignment]
        self._told = True

    def _probed(self, mv: GcodeMove) -> Optional[tuple[float, float, float]]:
        """The interpreter asks where the probe ``mv`` tripped (:data:`cam.formats.gcode.ProbeFn`)."""
        if mv is not self.pending or not self._told:
            raise PlanError(f"{self.source}:{mv.line}: the program was read past its probe before the probe had run "
                            "(a fault of the machine's run: please report it)")
        return self._contact_mm
