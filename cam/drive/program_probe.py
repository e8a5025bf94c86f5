"""A G-code program that probes, run on a machine that probes (issue #46 point 2): its ``G38.2``/``G38.3``.

One activity of the session (a ``job``): the program's parts (:mod:`cam.job.gcode_probing`) one after the other,
each planned from where the probe before it touched.  The machine runs a part on its own job path (a step plan by
the runner on a step/dir port, the lines of :func:`~cam.drive.grbl_machine.job_lines` streamed to grbl, its pauses
prompted), then makes the probe the part ends with and says where it touched:

* a step/dir port (:class:`StepDirProgram`: the mock with its simulated surface, a parallel port): a run of
  :func:`cam.drive.homing.seek` down Z at the probe's feed (at most Z's start speed, checked before anything moves)
  that ends on the first step where the probe input closes, never past the program's target (rounded toward the
  start); the tool stays there, the trip point;
* grbl (:class:`~cam.drive.grbl_program.GrblProgram`): the program's own code, ``G91 G38.2 Z-<d> F<feed>`` (or
  ``G38.3``) to the target, and its ``[PRB:x,y,z:1]``; grbl stops a deceleration past the trip point (never past
  the target, the end of its move), and the next part's lines, in machine coordinates (``G53``), go on from where
  it stopped.

A ``G38.2`` that touches nothing (grbl's ``ALARM:5``) ends the program in one line, the tool lifted back to where
the probe began, the position known; a ``G38.3`` that touches nothing goes on from its target.  The probe closed
before it moves is one line too (rs274's "probe already tripped").  The e-stop, a stop and the limit switches are
served throughout, as in any job.  A program that probes keeps no journal (its moves after a probe depend on the
contact of the run that stopped): it runs again from its start.  On a step/dir port it runs in the session's
thread, as probing does, not in the real-time runner process.

The MAXIMUS board and the ``cmd:`` control unit have no probe input: the session refuses such a program in one
line before anything moves (capability ``probes``).
"""
from __future__ import annotations

import time
from typing import Any, Callable, Optional

import numpy as np

from ..errors import CamError, CapabilityError, PlanError
from ..job.gcode_probing import ProbingProgram, ProgramProbe
from ..settings import INPUT_BITS, MachineSettings
from ._session_parts import Activity
from ..motion.chunks import plan_chunks
from .homing import seek
from .ports import MockPort, SwitchSchedule
from .probing import ProbeEnded, ProbeError, StepDirProber, activity_end, halted_status, step_dir_feed
from .runner import EMERGENCY_STOPPED, FINISHED, LIMIT_STOPPED, STOPPED, SWITCHED, Controller, RunResult, run
from .state import check_in_travel

__all__ = ["StepDirProgram", "start_program_on_steps", "launch_program", "program_worker"]

Steps3 = tuple[int, int, int]
PauseFn = Callable[[Steps3, str], None]
ProgressFn = Callable[[int, int, int], None]


class StepDirProgram(StepDirProber):
    """A program that probes on a step/dir port: every part and every probe a run of the runner on one open port
    (a mock's pin log holds them all on one time line)."""

    def __init__(self, session: Any, port: Any, ctl: Controller) -> None:
        super().__init__(session, port, ctl)
        self.machine_s = 0.0  # the machine time of the runs so far
        self.writes = 0

    def _booked(self, result: RunResult, what: str) -> None:
        """Where a run left the tool, its time; a run that ended early (a stop, the e-stop, a limit): ProbeEnded."""
        if isinstance(self.opened, MockPort):  # the next run's writes go on from this one's time
            self.opened.time_offset_ns += int(round(result.machine_time_s * 1e9)) + int(self.settings.delay_xy_ns)
        self.pos = self.pos + np.asarray(result.position_steps, np.int64)
        self.machine_s += result.machine_time_s
        self.writes += result.writes
        self.in_run = False
        if result.status not in (FINISHED, SWITCHED):
            raise ProbeEnded(result.status, f"{what}: " + "; ".join(result.messages or [result.status]))

    def run_part(self, job: Any, on_pause: PauseFn, progress: ProgressFn) -> None:
        """The moves of a part (points from where the tool stands), checked against the travel from here first."""
        plan = plan_chunks(job, start_steps=self.position())
        self.in_run = True
        result = run(plan, self.opened, realtime=self.realtime, controller=self.ctl, progress=progress,
                     on_pause=on_pause)
        self._booked(result, "the program")

    def program_probe(self, code: str, depth_steps: int, feed_mm_min: float) -> Optional[Steps3]:
        """Down Z at most ``depth_steps`` at ``feed_mm_min`` until the probe input closes; where it closed (the
        tool stays there), or None (the tool ``depth_steps`` lower)."""
        if self.opened.reads_inputs:
            pin, high = self.settings.inputs.wired()["probe"]
            if bool(self.opened.read_inputs() & (1 << INPUT_BITS[pin])) == high:
                raise ProbeError(f"{code}: the probe (inputs.probe) is closed before it moves (rs274: the probe is "
                                 "already tripped): the tool touches the work already, or the pin is wired or set the "
                                 "wrong way round (\"!N\" active low)")
        self.in_run = True
        result = seek(self.opened, self.settings, 2, int(depth_steps), feed_mm_min / 60.0, until=("probe", True),
                      realtime=self.realtime, controller=self.ctl, source=code)
        self.pos = self.pos + np.asarray(result.position_steps, np.int64)  # (seek moved the mock's time on)
        self.machine_s += result.machine_time_s
        self.writes += result.writes
        self.in_run = False
        if result.status not in (SWITCHED, FINISHED):
            raise ProbeEnded(result.status, f"{code}: " + "; ".join(result.messages or [result.status]))
        return self.position() if result.status == SWITCHED else None

    def lift_to(self, z_steps: int) -> None:
        """Z straight to machine ``z_steps``."""
        self._moves([(0, 0, int(z_steps) - int(self.pos[2]))] if int(self.pos[2]) != int(z_steps) else [],
                    "back to where the probe began")


def _probe(session: Any, machine: Any, probe: ProgramProbe, home: np.ndarray) -> Optional[Steps3]:
    """Make the probe a part ended with, from where the tool stands (its X and Y), down to its target at most:
    where it touched (machine frame), or None (a G38.3 that did not: the tool at its target).  A G38.2 that did
    not touch: the tool back where it began, ProbeError."""
    s: MachineSettings = session.settings
    here = machine.position()
    target = home + np.asarray(probe.target_steps, np.int64)
    if tuple(here[:2]) != tuple(int(v) for v in target[:2]):
        raise PlanError(f"{probe.where}: {probe.code} from machine X={here[0]} Y={here[1]} steps, but its target is at "
                        f"X={target[0]} Y={target[1]} (a planner fault: please report the file)")
    depth = int(target[2]) - int(here[2])
    if depth <= 0:
        raise ProbeError(f"{probe.where}: {probe.code}: its target (machine Z {target[2]} steps) is not below where "
                         f"the tool stands (Z {here[2]} steps)")
    check_in_travel(tuple(int(v) for v in target), s, f"{probe.where}: the {probe.code} probe's target")
    try:
        contact = machine.program_probe(probe.code, depth, probe.feed_mm_min)
    except ProbeError as exc:
        raise ProbeError(f"{probe.where}: {exc}") from None
    per = s.mm_per_step_z
    if contact is None and probe.must_touch:
        machine.lift_to(int(here[2]))
        raise ProbeError(f"{probe.where}: G38.2 found no contact down to its target (height {-target[2] * per:.4g} mm, "
                         f"machine Z {target[2]} steps): the tool is back at height {-here[2] * per:.4g} mm where the "
                         "probe began, position known; the program stops here (G38.3 would go on without a contact)")
    if contact is None:
        session.detail(f"{probe.where}: G38.3 touched nothing down to its target (height {-target[2] * per:.4g} mm): "
                       "the program goes on from there")
    else:
        session.detail(f"{probe.where}: {probe.code} touched at height {-contact[2] * per:.4g} mm (machine Z "
                       f"{contact[2]} steps): the moves after it are planned from there")
    return contact


def _run_parts(session: Any, machine: Any, spec: ProbingProgram, total: int) -> int:
    """Every part, each after the probe before it has touched; the probes made."""
    home = np.asarray(spec.home_steps, np.int64)
    start = np.asarray(session.position_steps(), np.int64)  # the activity's start (prompts are relative to it)
    done = [0, 0]  # progress: the units and machine ns of the parts before this one
    program = spec.run()
    probes = 0
    for part in program.parts():
        at = np.asarray(machine.position(), np.int64)
        if tuple(at) != tuple(int(v) for v in home + np.asarray(part.start_steps, np.int64)):
            raise PlanError(f"{spec.program.source}: a part planned from machine {list(home + part.start_steps)} "
                            f"steps, the tool at {list(at)} (a planner fault: please report the file)")
        if len(part.job):
            offset = at - start

            def on_pause(position: Steps3, note: str) -> None:
                session.prompt(tuple(int(o) + int(p) for o, p in zip(offset, position)), note)

            def progress(n: int, _total: int, ns: int) -> None:
                session.progress(min(max(1, total) - 1, done[0] + n), total, done[1] + ns)

            machine.run_part(part.job, on_pause, progress)
            if isinstance(machine, StepDirProgram):  # its progress counts writes, and its machine time is its own
                done[0], done[1] = machine.writes, int(machine.machine_s * 1e9)
            else:  # grbl: the points of the parts streamed
                done[0] += len(part.job)
        if part.probe is None:
            break
        contact = _probe(session, machine, part.probe, home)
        probes += 1
        program.touched(None if contact is None else tuple(int(c) - int(h) for c, h in zip(contact, home)),
                        tuple(int(p) - int(h) for p, h in zip(machine.position(), home)))
    return probes


def program_worker(session: Any, ctl: Any, make_machine: Callable[[], Any], spec: ProbingProgram, label: str,
                   total: int) -> None:
    """The worker thread of a program that probes: its parts and probes (:func:`_run_parts`), then the end booked
    as a job's (a step/dir port's :class:`~cam.drive.runner.RunResult` and pin log with it)."""
    start = session.position_steps()
    status, messages, fault = FINISHED, [], ""
    machine = None
    wall0 = time.monotonic()
    probes = 0
    try:
        machine = make_machine()
        probes = _run_parts(session, machine, spec, total)
    except Exception as exc:  # noqa: BLE001 - reported in the log; nothing more is sent
        status, messages, fault = activity_end(exc)
    status = halted_status(ctl, status)
    _book_end(session, machine, label, start, status, messages, fault, time.monotonic() - wall0, probes)


def _book_end(session: Any, machine: Any, label: str, start: Steps3, status: str, messages: list[str], fault: str,
              wall_s: float, probes: int) -> None:
    end: Optional[Steps3] = start
    lost = ""
    if machine is not None:
        try:
            end, lost = machine.close(machine.ctl, fault if status == "error" else "")
        except CamError as exc:
            end, lost = None, str(exc)
    if lost and status not in (EMERGENCY_STOPPED, LIMIT_STOPPED):
        status, messages = "error", [lost]
    moved = None if end is None else np.asarray(end, np.int64) - np.asarray(start, np.int64)
    machine_s = machine.machine_s if isinstance(machine, StepDirProgram) else wall_s  # grbl: its own time
    info = {"activity": "job", "label": label, "status": status, "messages": messages, "probes": probes,
            "machine_time_s": round(machine_s, 4), "wall_time_s": round(wall_s, 4)}
    result = log = None
    if isinstance(machine, StepDirProgram):
        result = RunResult(status, tuple(int(v) for v in (moved if moved is not None else (0, 0, 0))),  # type: ignore
                           machine.writes, machine_s, wall_s, 0, machine.opened, list(messages))
        info["writes"] = machine.writes
        if isinstance(machine.opened, MockPort) and machine.opened.pin_log_path is None:
            log = machine.opened  # its log stays with the port, read when asked
    with session._lock:
        if lost and session._activity is not None:  # the end booked keeps the position unknown
            session._activity.unknown_reason = lost
    session.finish(info, moved, result=result, pin_log=log)
    text = f"{label}: {status}" + (f" ({'; '.join(messages)})" if messages else "")
    session.log(text, "info" if status == FINISHED else "warning" if status == STOPPED else "error")


def launch_program(session: Any, name: str, ctl: Any, total: int, estimated_s: Any, spec: ProbingProgram,
                   make_machine: Callable[[], Any]) -> None:
    """Begin the activity of a program that probes (the lock held; a back end's ``start_program``): ``total``
    units of progress (a step/dir port's writes, grbl's points), ``make_machine()`` made in its worker thread."""
    session._begin(Activity("job", name, ctl, total, estimated_s))
    session.log(f"{name}: started; {len(spec.probes)} probe(s): the moves after each are planned from where it "
                "touches")
    session._spawn(program_worker, (session, ctl, make_machine, spec, name, total), "job")


def start_program_on_steps(session: Any, job: Any, name: str, controller: Optional[Controller]) -> None:
    """Start a program that probes on a step/dir port (the step/dir back ends' ``start_program``; ``job``: a
    :class:`~cam.drive.machine_job.MachineJob`): the probe input and, on the mock, its simulated surface, and every
    probe's feed against Z's start speed, checked before anything moves.

    Raises:
        ProbeError: no probe input, a probe's feed too fast (naming its line); CapabilityError: the mock without a
        probe surface."""
    s = session.settings
    spec: ProbingProgram = job.probing
    if "probe" not in s.inputs.wired():
        raise ProbeError(f"{spec.probes[0].split(': ')[0]}: the program probes, and the machine file has no probe "
                         "input: wire it in [inputs] (probe = \"!13\", a pin of its own; see "
                         "docs/machine-and-ports.md)")
    for where, feed in zip(spec.probes, spec.feeds_mm_min):
        try:
            step_dir_feed(s, feed)
        except ProbeError as exc:
            raise ProbeError(f"{where.split(': ')[0]}: {exc}") from None
    port: Any = session.port
    if session.backend.can("simulated", session.port):
        if s.mock.surface() is None:
            raise CapabilityError("the program probes, and the mock port has no surface to probe: give it in the "
                                  "machine file's [mock] table (probe_surface = \"z0,ax,ay,b,cx,cy\"; see "
                                  "docs/machine-and-ports.md)")
        switches = SwitchSchedule(s, tuple(int(v) for v in session.position_steps()))
        if isinstance(session.port, MockPort):
            session.port.switches = switches
        else:
            port = MockPort(switches=switches)
    ctl = controller or Controller()
    total = len(job.plan) if job.plan is not None else 1
    launch_program(session, name, ctl, total, job.estimated_s, spec, lambda: StepDirProgram(session, port, ctl))
