"""Running a job from the command line: a thin adapter over the machine session.

The session (:class:`cam.drive.session.MachineSession`) does the work on every
port; here are only the terminal's parts: the progress bar, the prompts at
tool changes and Pause At points (Enter, or ``--yes``; ``p`` at a tool change probes the new tool while the
job waits, :meth:`~cam.drive.session.MachineSession.probe_tool_at_prompt`), Ctrl-C (stop: the tool
is lifted), the pin log file (every write of the command: the travel to the work
zero, then the job, each part marked), and the machine state file (:mod:`cam.drive.state`):
every run starts where it says the tool stands and records where it ended.
"""
from __future__ import annotations

import argparse
import select
import signal
import sys
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any, Optional

from tqdm import tqdm

from ..drive.journal import journal_spec, read_journal
from ..drive.machine_job import machine_job
from ..drive.machines import backend_of, can, require
from ..drive.ports import MockPort, SwitchSchedule
from ..drive.runner import FINISHED, STOPPED
from ..drive.session import MachineSession, Prompt
from ..drive.state import (
    MachineState, PositionUnknownError, StateHold, check_in_travel, steps_to_mm, still_unknown,
)
from ..errors import CamError, CapabilityError, PortError
from ..job.model import Job
from ..kinds import has
from ..settings import MachineSettings
from ..verify.pinlog import join_pin_logs, write_pin_log
from .checks import job_kind_of
from .common import progress_wanted
from .machine_state import hold_machine
from ..drive.placement import (
    ORIGINS, placed_kinds, approach_to_work_zero, ended_state, origin_anchor, placed_home,
)

__all__ = ["execute", "Outcome", "check_port_options", "ended_state", "unrecorded_message", "approach_to_work_zero",
           "placed_kinds", "ORIGINS", "origin_anchor", "placed_home"]


@dataclass
class Outcome:
    """How a run ended, whatever the port."""

    status: str
    messages: list[str] = field(default_factory=list)
    machine_time_s: float = 0.0
    position_steps: tuple[int, int, int] = (0, 0, 0)
    """Where the tool stands at the end, in the session's frame (steps from where it stood at the start, plus
    ``start_steps``)."""
    timing: dict = field(default_factory=dict)
    """Real-time runs: ``max_late_s`` (the latest write), ``stalls`` (writes over 1 ms late) and ``late_total_s``
    (how much later the run ended than planned); every delay moved the rest of the run later."""
    state_error: Optional[str] = None
    """The machine state file could not record where the run left the tool (one line naming it, with the
    position): said after the run's own outcome, which is kept whole."""

    @property
    def finished(self) -> bool:
        return self.status == FINISHED


def check_port_options(args: argparse.Namespace, settings: Optional[MachineSettings] = None) -> None:
    """Options and files that need a port's capability, checked before anything is planned or sent.

    ``settings``: the machine settings of the port (a MAXIMUS board's Z Drill Up / Down there make
    --cut-depth and --travel-height an error: they would say the same thing twice).
    """
    kind = job_kind_of(args)
    drills_alone = can(args.port, "drills_alone")
    if kind is not None and not has(kind, "holes") and drills_alone:
        require(args.port, "step_dir", what=f"a {kind} job")
    if getattr(args, "pin_log", None):
        require(args.port, "pin_log")
    if getattr(args, "spindle", None):
        require(args.port, "spindle", what="--spindle")
    if drills_alone and getattr(args, "level", None):
        raise CapabilityError(f"--level: {args.port} drills every hole at its own Z stroke and cannot follow a "
                              f"levelled job; level it on a step/dir or grbl port")
    if drills_alone and getattr(args, "ramp", None):
        raise CapabilityError(f"{args.port} moves at the constant speed of its Delay bytes: --ramp applies to "
                              f"step/dir ports (set the speed with --delay)")
    if can(args.port, "drill_stroke") and settings is not None and settings.maximus.drill_stroke_set:
        for flag in ("cut_depth", "travel_height"):
            if getattr(args, flag, None) is not None:
                raise CapabilityError(
                    f"--{flag.replace('_', '-')}: the machine file sets the drill stroke of {args.port} "
                    f"([maximus] drill_z_up_steps, drill_z_down_steps); leave the flag out or those keys")


_STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
"""Signals that stop a job as Ctrl-C does: the tool is lifted, the position printed, the pin log and report written."""


def _read_answer(stopping: threading.Event) -> str:
    """A line from stdin, or "" when it is closed; gives up (returns "") as soon as a stop is asked for."""
    try:
        fd = sys.stdin.fileno()
    except AttributeError:
        return ""
    except (OSError, ValueError):  # a stream with no descriptor (text fed in): read it as it is
        try:
            return sys.stdin.readline()
        except (OSError, ValueError):
            return ""
    while not stopping.is_set():
        try:
            ready, _, _ = select.select([fd], [], [], 0.1)
        except (OSError, ValueError):
            return sys.stdin.readline()
        if ready:
            return sys.stdin.readline()
    return ""


class _Answers:
    """The session's ``on_prompt``: what the command line answers at a pause.  With ``--yes`` it goes on and says
    so in a line; those lines are written a few at a time (at most a quarter second late), since a job of tens of
    thousands of tool changes would otherwise write to stderr, and wait to take the GIL back, at each one.
    Without ``--yes`` it asks on stdin and stops when nobody can answer."""

    FLUSH_S = 0.25

    def __init__(self, args: argparse.Namespace, stopping: threading.Event) -> None:
        self.yes = bool(getattr(args, "yes", False))
        self.stopping = stopping
        self.lines: list[str] = []
        self.flushed_s = time.monotonic()

    def __call__(self, prompt: Prompt) -> str:
        x, y, z = prompt.position_steps
        if self.yes:
            self.lines.append(f"{prompt.note}: at X={x} Y={y} Z={z} steps; going on (--yes)\n")
            if time.monotonic() - self.flushed_s >= self.FLUSH_S:
                self.flush()
            return "continue"
        self.flush()
        if prompt.probed:  # the new tool was probed at this tool change: what it did, then asked again
            print(prompt.probed, file=sys.stderr)
        offer = ""
        if prompt.probe_tool:
            offer = ", or p and Enter to probe the new tool " + ("again" if prompt.probed else "(cam probe tool)")
        print(f"{prompt.note}: paused at X={x} Y={y} Z={z} steps; press Enter to resume{offer}", file=sys.stderr)
        if prompt.probe_tool_why_not and not prompt.probed:
            print(f"(probing the new tool is not offered: {prompt.probe_tool_why_not})", file=sys.stderr)
        while True:
            line = _read_answer(self.stopping)
            if line == "":  # stopped meanwhile, or nobody can answer: stop, never carry on blindly
                if not self.stopping.is_set():
                    print("no answer at the pause (stdin closed): stopping", file=sys.stderr)
                return "stop"
            if line.strip().lower() != "p":
                return "continue"
            if prompt.probe_tool:
                return "probe-tool"
            why = prompt.probe_tool_why_not or "this pause is not a tool change"
            print(f"cam: probing the new tool is not offered here: {why}; press Enter to resume", file=sys.stderr)

    def flush(self) -> None:
        """Write the lines held back."""
        if self.lines:
            lines, self.lines = self.lines, []
            sys.stderr.write("".join(lines))
            sys.stderr.flush()
        self.flushed_s = time.monotonic()


def _bar(args: argparse.Namespace, estimated_s: float) -> Optional[Any]:
    if not progress_wanted(args):
        return None
    return tqdm(
        total=round(estimated_s, 3), unit="s", unit_scale=False, desc="cutting", file=sys.stderr,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} machine s [{elapsed}<{remaining}]",
        mininterval=0.2,
    )


def execute(job: Any, args: argparse.Namespace, settings: MachineSettings, *,
            start_steps: Optional[tuple[int, int, int]] = None, journal: Optional[str] = None,
            hold: Optional[StateHold] = None, state_error_in_outcome: bool = False) -> Outcome:
    """Run a job (a Job, a PreparedJob or a StepPlan) on ``args.port`` through a machine session.

    The job starts where the machine state file (``args.state``, else the machine's default one: see
    :mod:`cam.drive.state`) says the tool stands, and the file records where it ended, also after Ctrl-C,
    SIGTERM or a fault.  ``hold``: the caller's hold on that file (a go-to or a jog, planned from its
    position); None: taken here, for the run.  ``start_steps``: a resumed job's start in its own frame (the
    journal's ``position_steps``; the journal's home places it in the machine frame).  Ctrl-C stops the job
    cleanly (tool lifted, position reported).  Writes ``args.pin_log`` after a run on the mock: every write of the
    command, the travel to the work zero (part ``travel``) and the job (part ``job``) on one time line.
    ``journal``: keep the job's journal in this file (:mod:`cam.drive.journal`); should this process die,
    the real-time runner process writes the journal and the pin log itself.
    ``state_error_in_outcome``: a state file that cannot record where the run ended comes back as the outcome's
    ``state_error`` (the caller says what the run did first, then that error); else it is raised (after the
    pin log was written).

    Raises:
        CamError: the job does not fit the port or the travel (nothing is sent), the position is unknown,
        another command drives the machine, or the port failed.
    """
    own = hold is None
    if hold is None:
        hold = hold_machine(args, settings, "cam drill")
    try:
        start = _start_position(hold, args, start_steps)
        outcome = _run(job, args, settings, hold, start, journal)
        if outcome.state_error is not None and not state_error_in_outcome:
            raise CamError(outcome.state_error)
        return outcome
    finally:
        if own:
            hold.close()


def _start_position(hold: StateHold, args: argparse.Namespace,
                    start_steps: Optional[tuple[int, int, int]]) -> tuple[int, int, int]:
    """Where the run starts, machine frame: the state's position, or a resumed job's journal's."""
    if start_steps is None:
        if not getattr(args, "position_unknown", None):  # cam jog: a jog with the position unknown (issue #45)
            hold.require_known()
        return hold.state.position_steps
    home = read_journal(args.resume).home_steps if getattr(args, "resume", None) else (0, 0, 0)
    start = tuple(int(s) + int(h) for s, h in zip(start_steps, home))
    check_in_travel(start, hold.settings, f"where journal {getattr(args, 'resume', '')} left the tool")
    st = hold.state
    if hold.existed and st.position_known and st.position_steps != start:
        raise PositionUnknownError(
            f"the state file {hold.path} has the tool at {list(st.position_steps)} steps, the journal's run left it "
            f"at {list(start)}: go back there (cam goto X,Y,Z --machine-coords --unit steps) and resume again")
    return start  # type: ignore[return-value]


def _run(job: Any, args: argparse.Namespace, settings: MachineSettings, hold: StateHold,
         start: tuple[int, int, int], journal: Optional[str]) -> Outcome:
    """Run the job; a state file that cannot be written at the end does not take the outcome with it (its pin log,
    its report, its finished line): it comes back in ``state_error`` (issue #43 point 7)."""
    unrecorded: list[str] = []
    outcome = _drive(job, args, settings, hold, start, journal, unrecorded)
    if unrecorded:
        outcome.state_error = unrecorded[0]
    return outcome


def _job_port(args: argparse.Namespace, settings: MachineSettings, realtime: bool) -> Any:
    """The port a job runs on: ``--port`` as named, but a logging port (the mock, ``cmd:mock``) as the run needs
    it (:meth:`~cam.drive.machines.Backend.logging_port`)."""
    backend = backend_of(args.port)
    if not backend.can("pin_log", args.port):
        return args.port
    if getattr(args, "pin_log", None) and not realtime:  # the pin log streams to its file: nothing held
        return backend.logging_port(args.port, settings, pin_log_path=args.pin_log)
    if not realtime:  # nobody reads this run's pin log: the writes are counted, not kept
        return backend.logging_port(args.port, settings, keep_log=False)
    if settings.mock.places() and backend.can("home_switches", args.port):
        return backend.logging_port(args.port, settings)  # simulated switches (below): in real time too
    return args.port


def _job_session(port: Any, args: argparse.Namespace, settings: MachineSettings, hold: StateHold,
                 stopping: threading.Event) -> "tuple[MachineSession, _Answers]":
    """The job's session on ``port``: its prompts answered from the terminal (or ``--yes``), the machine's tool
    table named at tool changes, the state file a tool probed at a tool change books to, grbl's feed override."""
    answers = _Answers(args, stopping)
    session = MachineSession(port, settings, realtime=getattr(args, "realtime", False), on_prompt=answers)
    session.tool_table_path = getattr(args, "tool_table_path", None)  # the prompt names the table's tool
    session.work_state = hold  # a tool probed at a tool change: the first tool's contact, the work Z set there
    if getattr(args, "feed_override", None) is not None:  # grbl's override (CapabilityError elsewhere)
        session.feed_override(args.feed_override)
    return session, answers


def _drive(job: Any, args: argparse.Namespace, settings: MachineSettings, hold: StateHold,
           start: tuple[int, int, int], journal: Optional[str], unrecorded: list[str]) -> Outcome:
    stopping = threading.Event()
    realtime = getattr(args, "realtime", False)
    port = _job_port(args, settings, realtime)
    session, answers = _job_session(port, args, settings, hold, stopping)
    # --origin, else the job's own (an --offset places the file by its own zero: cam.kinds.jobs.prepare_job, the rule
    # the page's offset_mm follows too)
    origin = getattr(args, "origin", None)
    approach = None if getattr(args, "resume", None) else approach_to_work_zero(job, hold.state, start, settings,
                                                                                origin)
    at = start if approach is None else placed_home(job, hold.state, origin)
    session.set_position(at)
    if isinstance(port, MockPort) and settings.mock.places():  # the machine file's simulated switches ([mock])
        port.switches = SwitchSchedule(settings, at)
    # the streamed pin log: the travel to the work zero runs on this mock too, its part marked before the job's
    shared = port if isinstance(port, MockPort) and port.pin_log_path is not None else None
    runs: list[tuple[str, MachineSession, tuple[int, int, int]]] = []  # the command's parts that ran
    session.check_job(job)  # before the progress bar: a bad job is one clean line
    # the machine time takes a pass over the ramps: only worked out before the run for a bar to show it
    bar = _bar(args, machine_job(job).estimated_s()) if progress_wanted(args) else None
    if bar is not None:
        session.on_progress = lambda done, total, t_ns: bar.update(round(t_ns / 1e9, 3) - bar.n)
    # each hole on a board that drills by itself, as the MAXIMUS PC program shows it ("Drilling hole n of N")
    def detail(text: str) -> None:
        answers.flush()  # the pause lines held back come first
        if bar is not None:
            bar.write(text, file=sys.stderr)
        else:
            print(text, file=sys.stderr, flush=True)

    session.on_detail = detail
    sessions = [session]

    def stop(signum: int, frame: Any) -> None:
        stopping.set()
        for s in sessions:
            s.stop()

    previous = {s: signal.signal(s, stop) for s in _STOP_SIGNALS}
    ended, ended_start = session, at
    try:
        hold.mark_running(_command_text(args))
        if approach is not None:
            ended, ended_start = _approach(approach, args, settings, start, sessions, shared), start
            runs.append(("travel", ended, start))
            if ended.last_run.get("status") != FINISHED:
                return _outcome(ended, args, runs)
            if stopping.is_set():  # Ctrl-C as the travel ended, before the job began: the job is not started
                out = _outcome(ended, args, runs)
                return replace(out, status=STOPPED, messages=[
                    "stopped at the work zero, as the travel there ended: the job was not started"])
            ended, ended_start = session, at
        if isinstance(port, MockPort):
            port.begin_part("job", at, _step_period_ns(settings))
        runs.append(("job", session, at))
        spec = None if journal is None else journal_spec(job, journal, home_steps=session.position_steps(),
                                                         pin_log_path=getattr(args, "pin_log", None))
        session.start(job, journal=spec)
        if stopping.is_set():  # Ctrl-C while it was being started, before it had an activity to stop
            session.stop()
        if bar is not None and not bar.total:  # a jog or a go-to: its time is known once the session planned it
            bar.total = round(session.state()["remaining_s"], 3)
            bar.refresh()
        while not session.wait_idle(0.2):  # wakes for signals (Ctrl-C), not for each change of the session
            pass
    finally:
        answers.flush()
        if hold.state.running is not None:  # recorded before the handlers go: a SIGTERM now still stops cleanly
            end = _ended_state(hold, ended, ended_start, args)
            try:
                hold.record(end)
            except CamError as exc:  # a full disk: what the run did is still said and written
                unrecorded.append(unrecorded_message(end, exc, settings))
        for s, handler in previous.items():
            signal.signal(s, handler)
        if bar is not None:
            bar.close()
    return _outcome(session, args, runs)


def _ended_state(hold: StateHold, ended: MachineSession, start: tuple[int, int, int],
                 args: argparse.Namespace) -> MachineState:
    """Where the run left the machine (:func:`ended_state`); after a jog made with the position unknown
    (``args.position_unknown``: why it was) the position stays unknown (:func:`still_unknown`)."""
    end = ended_state(hold.state, ended, start, getattr(args, "tool", None))
    reason = getattr(args, "position_unknown", None)
    return end if not reason else still_unknown(end, reason, hold.settings)


def unrecorded_message(end: MachineState, exc: Exception, settings: MachineSettings) -> str:
    """The one line of a state file that could not record where a run left the tool (``end``, machine frame):
    the cause, the position (the next command finds it unknown) and how to say it."""
    mm = ", ".join(f"{v:g}" for v in steps_to_mm(end.position_steps, settings))
    where = f"at machine {list(end.position_steps)} steps ({mm} mm)"
    said = f"the tool stands {where}" if end.position_known else f"the machine's last word had the tool {where}"
    return (f"the machine state was not recorded ({exc}): {said}; the next command finds the position unknown: "
            f"free the disk, then say where the tool is (cam where --set X,Y,Z) or home the machine (cam home)")


def _approach(job: Job, args: argparse.Namespace, settings: MachineSettings, start: tuple[int, int, int],
              sessions: list, shared: Optional[MockPort] = None) -> MachineSession:
    """Travel to the work zero in a session of its own; returns it.  ``shared``: the mock whose pin log streams
    (``--pin-log``): the travel runs on it, its part marked (the job's comes next); else the pin log joins the
    travel's writes to the job's at the end (:func:`_write_pin_log`)."""
    simulated = can(args.port, "simulated") and can(args.port, "home_switches") and settings.mock.places()
    port: Any = MockPort(switches=SwitchSchedule(settings, start)) if simulated else args.port
    if shared is not None:
        job_switches, port = shared.switches, shared
        if simulated:
            shared.switches = SwitchSchedule(settings, start)
        shared.begin_part("travel", start)
    first = MachineSession(port, settings, realtime=getattr(args, "realtime", False))
    first.set_position(start)
    sessions.append(first)
    print(f"going to the work zero first: machine {list(first.position_steps())} -> "
          f"{[int(s) + int(v) for s, v in zip(start, job.points_steps[-1])]} steps", file=sys.stderr, flush=True)
    first.start(job, label="to the work zero")
    while not first.wait_idle(0.2):
        pass
    if shared is not None:
        shared.switches = job_switches
    return first


def _step_period_ns(settings: MachineSettings) -> int:
    """The time between one part's last write and the next part's first in a command's pin log: a step period."""
    return int(max(settings.delay_xy_ns, settings.delay_z_ns))


def _write_pin_log(args: argparse.Namespace, runs: list[tuple[str, MachineSession, tuple[int, int, int]]]) -> None:
    """``--pin-log``: every write of the command, each part marked (:class:`~cam.verify.pinlog.PinLogPart`): put in
    place when it streamed to its file, else the parts' logs joined on one time line and written."""
    done = [(name, s.last_result, at) for name, s, at in runs if s.last_result is not None]
    if not done:
        return
    last = done[-1][1].port
    if isinstance(last, MockPort) and last.pin_log_path is not None:  # every part streamed to it
        last.finish_pin_log()
        return
    settings = runs[-1][1].settings
    write_pin_log(join_pin_logs([(name, r.pin_log(), at) for name, r, at in done], _step_period_ns(settings)),
                  args.pin_log)


def _command_text(args: argparse.Namespace) -> str:
    """The command as the running marker names it (``drill part.png``)."""
    what = getattr(args, "image", None) or getattr(args, "load_digitized", None) or ""
    return f"cam {args.command} {what}".strip()


def _outcome(session: MachineSession, args: argparse.Namespace,
             runs: list[tuple[str, MachineSession, tuple[int, int, int]]]) -> Outcome:
    """How the command ended (``session``: its last run); writes ``--pin-log`` of every part in ``runs``."""
    info = session.last_run
    result = session.last_result
    if info.get("status") == "error":
        raise PortError("; ".join(info.get("messages") or ["the run failed"]))
    if getattr(args, "pin_log", None) and result is not None:
        _write_pin_log(args, runs)
    if result is None:  # a board that makes its own steps: its planned time, where it has one (grbl)
        return Outcome(info.get("status", "error"), list(info.get("messages", [])),
                       float(info.get("machine_time_s", 0.0)), position_steps=session.position_steps())
    timing = {k: info[k] for k in ("max_late_s", "stalls", "late_total_s", "reramps") if k in info}
    return Outcome(result.status, list(result.messages), result.machine_time_s, session.position_steps(), timing)
