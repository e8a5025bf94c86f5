"""The machine session: one port, where the tool stands, one activity at a time.

Every front end drives the machine through a :class:`MachineSession`: the
CLI, the web page and the Python API (:func:`cam.run`).  A session owns a
port opened by name (``mock``, ``/dev/parport0``, ``cmd:/dev/parport0``, ``maximus:/dev/ttyUSB0``,
``grbl:/dev/ttyUSB0``: the back end it names does the machine's part, :mod:`cam.drive.machines`) and runs jobs, jogs, go-tos and moves back to the
origin on it, one at a time, in a background thread::

    session = MachineSession()      # the mock
    session.start(job)             # a Job, a PreparedJob or a StepPlan
    session.pause(); session.resume(); session.stop(); session.emergency_stop()
    session.wait_idle()
    session.state()                # position, progress, prompt, log: JSON-able
    session.last_result            # the runner's RunResult (step/dir ports: the mock's pin log)

Frames: positions are machine steps ``(x, y, z)`` from the *home* (+Z deeper).
Without a machine state file the home is where the tool stood when the
session opened, and a job starts where the tool stands.  With one
(``state=``, a :class:`~cam.drive.state.StateHold`: issue #29) the home is the
machine's, the session starts where the file says the tool stands, keeps the
work offsets (G54-G59.3) there, places every file's job at the active work
zero (travelling there first, :mod:`cam.drive.placement`), refuses moves
while the position is unknown, and records where every activity ended (also
after a stop, an emergency stop or a fault).  Either way the travel is
checked before anything is sent.

What a port cannot do (the MAXIMUS firmware has no pause and takes drill
files only) is refused through one check, :func:`cam.drive.machines.require`,
with the same message in every front end.

On a MAXIMUS board the session's frame is the same (+y toward the operator,
+z deeper): a jog of Z -100 lifts the head, whatever the firmware's own
directions (:func:`cam.drive.maximus.board.to_board` converts).  The home is
the board origin: :meth:`MachineSession.set_offset` makes where the head
stands the origin (the PC program's Set Offset), and
:meth:`MachineSession.set_drill_z` takes Z Drill Up / Down from where it
stands.

This module starts activities and books their ends; the state snapshot, the
controls and the prompts are the session's parts in :mod:`cam.drive._session_parts`.
"""
from __future__ import annotations

import collections
import threading
import time
import weakref
from typing import Any, Callable, Optional

import numpy as np

from ..errors import BusyError, CamError, PortError
from ..job.model import Job, travel_job
from ..job.moves import jog as jog_job
from ..job.moves import jog_steps, to_origin
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..values import FEED_OVERRIDE_RANGE, finite_number
from ..verify.pinlog import motion_extent
from .apart import RunnerProcess
from .journal import JournalSpec, journal_spec
from ._session_parts import Activity, Prompt, PromptFn
from ._session_recover import UNKNOWN_JOG_LINE, SessionRecover, maximus_cannot_home
from ._session_pinlog import SessionPinLogs
from ._session_probe import SessionProbe
from ._session_prompt_probe import SessionPromptProbe
from ._session_tools import SessionTools
from .activities import run_steps
from .machine_job import JobInput, MachineJob, machine_job
from .machines import DEFAULT_PORT, backend_of
from .ports import MockPort, Port
from .runner import EMERGENCY_STOPPED, STOPPED, Controller, Cursor, RunResult
from ..motion.chunks import ChunkedPlan, plan_chunks
from ..motion.steps import StepPlan
from .state import StateHold

__all__ = ["MachineSession", "Prompt", "PromptFn", "MAX_JOG_STEPS", "UNKNOWN_JOG_LINE", "maximus_cannot_home", "run"]

MAX_JOG_STEPS = 100_000
"""The longest jog one request may ask for, either way."""


class MachineSession(SessionTools, SessionRecover, SessionPinLogs, SessionProbe, SessionPromptProbe):
    """The machine as every front end sees it (thread-safe).

    Args:
        port: the port name (see :mod:`cam.drive.ports`); it is opened for each activity.
        settings: the machine settings every job must be planned with.
        realtime: run the mock on the real clock (real ports always are).
        on_prompt: answers prompts in the worker thread (the CLI asks on the terminal); None: a prompt
            waits for :meth:`answer` (the web page).
        state: the hold on the machine's state file (:class:`~cam.drive.state.StateHold`, its lock taken by
            the caller, who closes it): positions in the machine frame, work offsets, jobs placed at the work
            zero, every end recorded (see the module docstring).  The session binds it to ``port``
            (:meth:`~cam.drive.state.StateHold.bind_port`): on a real port the device's own lock is taken and a
            new state file is a position unknown.  None: the home is where the tool stands now (no lock).
    """

    def __init__(self, port: str = DEFAULT_PORT, settings: MachineSettings = DEFAULT_SETTINGS, *,
                 realtime: bool = False, on_prompt: Optional[PromptFn] = None,
                 state: Optional[StateHold] = None) -> None:
        self.backend = backend_of(port)
        self.kind = self.backend.kind
        if state is not None:  # the device's own lock before the port opens; a real port's new file: unknown
            state.bind_port(port)
        self.port = self.backend.resolve(port, settings)
        self.settings = settings
        self.realtime = realtime or not self.backend.can("simulated", port)
        self.on_prompt = on_prompt
        self.on_progress: Optional[Callable[[int, int, int], None]] = None
        self.on_detail: Optional[Callable[[str], None]] = None
        self._lock = threading.RLock()
        self._changed = threading.Condition(self._lock)
        self._position = np.zeros(3, np.int64)
        self._activity: Optional[Activity] = None
        self._last_activity: Optional[Activity] = None  # the one that ended last: its progress stays shown
        self._thread: Optional[threading.Thread] = None
        self._finished_wall = 0.0
        self._prompt: Optional[Prompt] = None
        self._prompt_seq = 0
        self._answer = threading.Event()
        self._answer_action = "continue"
        self._estop_request_ns: Optional[int] = None
        self._halt_lock = threading.RLock()  # held only to count a stop (re-entrant: a signal handler may stop)
        self._halts = (0, 0)  # (stops, emergency stops) asked so far
        self._chain_halts: Optional[tuple[int, int]] = None  # the counts an activity handed over to begins with
        self._log: collections.deque = collections.deque(maxlen=500)
        self._log_seq = 0
        self.last_run: dict[str, Any] = {}
        self.last_result: Optional[RunResult] = None
        self._last_job_port: Optional[MockPort] = None  # the mock that ran the last job: it holds its log
        self._last_job_log: Any = None
        self._last_job_parts: list = []  # its (name, mock, start: machine frame) parts: the travel there, the job
        self._last_pin_log: Any = None
        self._travel_port: Any = None  # (mock, start) of the travel to the work zero of the job that runs next
        self.version = 0
        self._runner_process: Optional[RunnerProcess] = None
        self.state_hold = state
        self._activity_start = (0, 0, 0)  # machine frame: where the running activity started
        self._then: Optional[Callable[[], None]] = None  # what starts when the running activity finishes
        self._pause_moved = np.zeros(3, np.int64)  # the running job's moves at its pauses (a tool probed)
        self._pause_work: Optional[Callable[[Any], dict]] = None  # probes on the running job's open port
        if state is not None:
            self._position = np.asarray(state.state.position_steps, np.int64).copy()
        self.grbl: Any = None  # the grbl board the grbl back end attaches
        self.backend.attach(self)  # a board that reports its position: where the tool stands is its word

    def runner_process(self) -> RunnerProcess:
        """The process real-time step plans run in (started at the first; ended with the session)."""
        if self._runner_process is None:
            self._runner_process = RunnerProcess()
            weakref.finalize(self, self._runner_process.close)
        return self._runner_process

    def last_sent(self) -> tuple[int, tuple[int, int, int]]:
        """``(writes sent, position in steps from where it started)`` of the activity that ended last, from its
        cursor: how far a run that failed got.  ``(0, (0, 0, 0))`` when it had no cursor (a MAXIMUS board)."""
        with self._lock:
            a = self._last_activity
            if a is None or a.positions is None:
                return 0, (0, 0, 0)
            return int(a.positions.sent), tuple(int(v) for v in a.positions.position_steps)  # type: ignore

    # -- starting things ------------------------------------------------------------------
    def _check_free(self) -> None:
        if self._activity is not None:
            raise BusyError(f"the machine is busy ({self._activity.label}); wait for it to end or stop it")

    def start(self, job: JobInput, *, label: Optional[str] = None, controller: Optional[Controller] = None,
              journal: Any = None, origin: Optional[str] = None) -> None:
        """Run a job from where the tool stands, in the background.

        Args:
            job: a :class:`~cam.job.model.Job` (planned into steps here, checked against the travel from
                where the tool stands), a job kept as pieces, a :class:`~cam.kinds.jobs.PreparedJob`, a chunked
                plan or a :class:`StepPlan` (:data:`cam.drive.machine_job.JobInput`: read once into the typed
                :class:`~cam.drive.machine_job.MachineJob` the machine's back end takes).
            label: what the log calls it.
            controller: a :class:`~cam.drive.runner.Controller` of the caller's (step/dir ports), else a new one;
                :meth:`pause` and the other controls work either way.
            journal: keep the job's journal (:mod:`cam.drive.journal`) in this file (a path), or as a
                :class:`~cam.drive.journal.JournalSpec` says; None: no journal.  A resumed job
                (:func:`cam.kinds.jobs.resume_job`) starts where its journal says the tool stands.
            origin: with a state file, which point of a file's job goes to the active work zero (``file``,
                ``upper-left``, ``lower-left``, ``center``; None: the kind's default, see
                :func:`cam.drive.placement.origin_anchor`); the session travels there first (lifted), then runs
                the job.  A resumed job (a journal) and a G-code program start where the tool stands.

        A G-code program that probes (G38.2/G38.3: :attr:`~cam.kinds.jobs.PreparedJob.probing`) runs on a machine that
        probes only, a part at a time, each planned from where the probe before it touched
        (:mod:`cam.drive.program_probe`), and keeps no journal.

        A prepared job holds for the machine state it was planned in (:attr:`~cam.kinds.jobs.PreparedJob.planned_in`):
        a G-code program runs from where the tool stood when it was planned, in those work offsets, as ``cam drill``
        plans it; anywhere else it is refused (StalePlanError: plan it again), never run shifted.

        Raises:
            BusyError: something runs; CapabilityError: the port cannot run this job; TravelError:
            the job leaves the travel from here; StalePlanError: it was planned for another position or work
            zero (nothing is sent in every case).
        """
        mj = machine_job(job)
        with self._lock:
            self._check_free()
            self._require_known()
            self._check_planned_in(mj)
            if not mj.travel_only and self._place(mj, label, controller, journal, origin):
                return
            self._check_job(mj)
            name = label or f"job {mj.name}"
            if mj.travel_only:  # a jog or a go-to
                self._start_moves("jog", mj.given, label or mj.name)  # type: ignore[arg-type]
                return
            if mj.probing is not None:  # a part at a time, each from its probe's contact (cam.drive.program_probe)
                if journal is not None:
                    self.log(f"{name}: no journal kept: a program that probes runs again from its start", "warning")
                self.backend.start_program(self, mj, name, controller)
                return
            self.backend.start_job(self, mj, name, journal, controller)

    def _journal_spec(self, mj: MachineJob, journal: Any) -> Optional[JournalSpec]:
        if journal is None or isinstance(journal, JournalSpec):
            return journal
        if isinstance(mj.given, StepPlan):
            raise CamError("a step plan has no moves to keep a journal of: start the job or the prepared job")
        return journal_spec(mj.given, journal, home_steps=tuple(int(v) for v in self._position))

    def _plan(self, mj: MachineJob) -> "StepPlan | ChunkedPlan":
        if mj.plan is not None:  # a prepared job's (planned from its home, checked by its extent) or one given
            return mj.plan
        assert mj.moves is not None
        return plan_chunks(mj.moves, start_steps=tuple(int(v) for v in self._position))

    def run(self, job: JobInput, *, label: Optional[str] = None) -> dict[str, Any]:
        """:meth:`start` and wait for the end; returns :attr:`last_run`."""
        self.start(job, label=label)
        self.wait_idle(None)
        return dict(self.last_run)

    def jog(self, axis: str, steps: float, unit: str = "steps") -> None:
        """Move one axis by ``steps`` in ``unit`` (see :data:`cam.job.moves.JOG_UNITS`: machine steps, full
        steps, 0.1 mm, mm, 0.1 inch).  ``steps`` must be a finite number (no text, no boolean), at most
        :data:`MAX_JOG_STEPS` machine steps either way once converted.  BusyError while something runs;
        PlanError (naming the field) or TravelError for a bad jog.  With the position unknown (a state file's
        latch after an emergency stop, a limit or a fault) the jog is allowed with the soft limits off, as
        LinuxCNC jogs an unhomed machine, and the position stays unknown (:mod:`cam.drive._session_recover`)."""
        a = str(axis).lower()
        half = self.backend.half_step(self.settings, a)
        n = jog_steps(axis, steps, unit, settings=self.settings, half_step=bool(half), max_steps=MAX_JOG_STEPS)
        with self._lock:
            self._check_free()
            if self._jog_unknown(axis, n):  # the position unknown: soft limits off, still unknown after
                return
            job = jog_job(axis, n, settings=self.settings, position_steps=self.position_steps())
            self._start_moves("jog", job, job.source)

    def feed_override(self, percent: float) -> None:
        """Set the feed override to ``percent`` (a number 10..200, rounded to a whole percent) on a machine that
        has one (grbl: its real-time override bytes).

        Raises:
            PlanError: not a finite number (text, a boolean, infinity) or outside 10..200 (checked first, on any
            port); CapabilityError: the machine has no feed override."""
        lo, hi = FEED_OVERRIDE_RANGE
        pct = int(round(finite_number(percent, "percent", lo=lo, hi=hi, unit="%")))
        self.backend.require(self.port, "overrides", "a feed override")
        self.backend.feed_override(self, pct)
        self.log(f"feed override {pct} %")
        with self._lock:
            self._bump()

    def set_offset(self) -> None:
        """Make where the head stands the origin (the PC program's Set Offset: "positionX = 0; positionY = 0;
        positionZ = 0", seed 000 Appendix 2, ``BtnSetOffsetPositionClick``); refused while busy.  With a state
        file: the active work offset's zero of X, Y and Z here (:meth:`zero`)."""
        if self.state_hold is not None:
            self.zero("XYZ")
            return
        self.set_position((0, 0, 0))
        self.log("this position is the origin now")

    def detail(self, text: str) -> None:
        """What the running activity does now (e.g. "drilling hole 3 of 44"): shown in the state and logged."""
        with self._lock:
            if self._activity is not None:
                self._activity.detail = text
        self.log(text)
        if self.on_detail is not None:
            self.on_detail(text)

    def go_to_origin(self) -> None:
        """Back to the home: lift out of the material first, travel at that height, then Z to the home.  With a
        state file: to the active work zero (:meth:`go_to` 0, 0, 0)."""
        if self.state_hold is not None:
            self.go_to((0, 0, 0))
            return
        with self._lock:
            self._check_free()
            job = to_origin(self.position_steps(), settings=self.settings)
            if len(job) == 0:
                self.log("already at the origin")
                return
            self._start_moves("origin", job, job.source)

    def move_to(self, points_steps: np.ndarray, label: str) -> None:
        """Travel through ``(N, 3)`` points given relative to where the tool stands."""
        with self._lock:
            self._check_free()
            self._require_known()
            self._start_moves("jog", travel_job(points_steps, self.settings), label)

    def _start_moves(self, activity: str, job: Job, label: str) -> None:
        self.backend.start_moves(self, activity, job, label)

    def _begin(self, activity: Activity) -> None:
        if self.state_hold is not None:  # the marker a killed process leaves: the position then unknown
            self.state_hold.mark_running(f"{activity.name}: {activity.label}")
        self._activity_start = tuple(int(v) for v in self._position)
        self._pause_moved = np.zeros(3, np.int64)
        # the stops counted when it was asked for: the activity it follows began then (a job after its travel)
        activity.halts = self._chain_halts if self._chain_halts is not None else self._halts
        self._activity = activity
        self._estop_request_ns = None
        self._prompt = None
        now, ctl = self._halts, activity.controller  # a stop counted since, whose reader found no activity yet
        if ctl is not None and now[1] != activity.halts[1]:
            ctl.emergency_stop()
        elif ctl is not None and now[0] != activity.halts[0]:
            ctl.stop()
        self._bump()

    def _launch_steps(self, name: str, plan: "StepPlan | ChunkedPlan", label: str, estimated_s: Callable[[], float],
                      controller: Optional[Controller] = None, journal: Optional[JournalSpec] = None) -> None:
        ctl = controller or Controller()
        cursor = Cursor(plan.settings)  # the runner moves it on; the live position reads it
        self._begin(Activity(name, label, ctl, len(plan), estimated_s, cursor, reach=lambda: plan.motion_extent()[0]
                             if isinstance(plan, ChunkedPlan) else motion_extent(plan.data, plan.settings)[0]))
        self.log(f"{label}: started")
        self._spawn(run_steps, (self, name, plan, ctl, label, journal, cursor), name)

    def _spawn(self, target: Callable[..., None], args: tuple, name: str) -> None:
        t = threading.Thread(target=target, args=args, name=f"cam-{name}", daemon=True)
        self._thread = t
        t.start()

    # -- called by the worker threads -----------------------------------------------
    def progress(self, done: int, total: int, machine_ns: int) -> None:
        """Progress of the running activity (writes or holes done, machine time done)."""
        with self._lock:
            if self._activity is not None:
                self._activity.done, self._activity.machine_ns = done, machine_ns
                self._bump()
        if self.on_progress is not None:
            self.on_progress(done, total, machine_ns)

    def finish(self, info: dict[str, Any], moved_steps: Optional[np.ndarray], *, result: Optional[RunResult] = None,
               pin_log: Any = None) -> None:
        """The activity ended: book where the tool is and what happened."""
        with self._lock:
            a = self._activity
            goes_on = self._then is not None and info.get("status") == "finished"
            halted = self._halted_since(a)  # a stop as it ended: what it hands over to does not start
            if moved_steps is not None:  # and what the job moved at its pauses (a tool probed at a tool change)
                self._position = self._position + np.asarray(moved_steps, np.int64) + self._pause_moved
            self._pause_moved = np.zeros(3, np.int64)
            if self._estop_request_ns is not None and result is not None:
                info["estop_request_job_ns"] = int(self._estop_request_ns - result.started_ns)
            if a is not None and info.get("status") == "finished":
                a.done = a.total
            elif a is not None and result is not None:
                a.done = result.writes
            self.last_run = info
            self._last_activity = a
            self.last_result = result
            self._book_pin_log(None if a is None else a.name, pin_log, tuple(int(v) for v in self._activity_start),
                               goes_on and not halted)
            self._activity = None
            self._prompt = None
            self._finished_wall = time.monotonic()
            self._record_state()
            self._bump()
            then, self._then = self._then, None
            halted = halted or self._halted_since(a)  # (a stop that came as the end was booked too)
            if goes_on and halted:
                self._travel_port = None
                what = "an emergency stop" if halted == EMERGENCY_STOPPED else "a stop"
                line = f"{what} came as {a.label if a is not None else 'the run'} ended: what was to follow it " \
                       f"(the job after the travel to its work zero, a probe's work Z or height map) was not started"
                self.log(line, "error" if halted == EMERGENCY_STOPPED else "info")
                self.last_run = dict(info, status=halted, messages=[line])
            elif goes_on and then is not None:
                self._chain_halts = a.halts if a is not None else None  # a stop counted from now halts the next
                try:
                    then()
                except CamError as e:
                    self._travel_port = None
                    self.log(f"the job did not start: {e}")
                    self.last_run = dict(info, status="error", messages=[str(e)])
                finally:
                    self._chain_halts = None

    def _halted_since(self, a: Optional[Activity]) -> str:
        """Whether a stop came since activity ``a`` began (counted, or its controller halted; the lock held):
        :data:`~cam.drive.runner.STOPPED`, :data:`~cam.drive.runner.EMERGENCY_STOPPED`, or "" none."""
        if a is None:
            return ""
        stops, estops = self._halts
        ctl = a.controller
        if estops != a.halts[1] or getattr(ctl, "estop_requested", False):
            return EMERGENCY_STOPPED
        if stops != a.halts[0] or getattr(ctl, "halted", False):
            return STOPPED
        return ""

def run(job: JobInput, port: Any = DEFAULT_PORT, *, realtime: bool = False, controller: Optional[Controller] = None,
        progress: Optional[Callable[[int, int, int], None]] = None,
        on_pause: Optional[Callable[[tuple[int, int, int], str], None]] = None) -> RunResult:
    """Run a job on any machine and wait for the end: a one-job :class:`MachineSession`.

    Args:
        job: a :class:`~cam.job.model.Job`, a :class:`~cam.motion.steps.StepPlan` or a prepared job (a board takes
            what its session takes: grbl any job with moves, the MAXIMUS board drill files).
        port: a port name (``mock``, ``/dev/parport0``, ``cmd:mock``, ``grbl:/dev/ttyUSB0``, ``maximus:/dev/ttyUSB0``)
            or an open step/dir port.
        realtime: wait for each write's time (forced on for real ports).
        controller: pause / resume / stop / emergency stop from another thread.
        progress: called now and then with (writes done, writes total, machine ns done).
        on_pause: called at each pause (Pause At, tool change) with (position_steps, note); the job goes on
            when it returns.  Without it a pause holds the ``controller`` until it is resumed, or is passed
            at once when there is no controller.

    Returns:
        The :class:`~cam.drive.runner.RunResult`; the mock's pin log is ``result.pin_log()``.  On a board: its
        status, where the tool ended (steps from where it started), the lines or holes done, the planned machine
        time; it keeps no pin log (``result.pin_log()`` says so in one line).

    Raises:
        CamError: the job does not fit the travel, the port cannot be opened or cannot run it.
    """
    def on_prompt(prompt: Prompt) -> str:
        if on_pause is not None:
            on_pause(prompt.position_steps, prompt.note)
        elif controller is not None:
            controller.pause()  # held until the caller resumes it
        return "continue"

    mj = machine_job(job)
    settings = mj.settings or DEFAULT_SETTINGS
    session = MachineSession(port, settings, realtime=realtime, on_prompt=on_prompt)
    session.on_progress = progress
    if not session.backend.can("step_dir", session.port):  # a board that makes its own steps
        return _run_on_board(session, mj, controller)
    session.start(mj, controller=controller)
    session.wait_idle(None)
    if session.last_result is None:
        raise PortError("; ".join(session.last_run.get("messages") or ["the run failed"]))
    return session.last_result


class _BoardPort(Port):
    """What a board's :class:`RunResult` names as its port: the board's port name (it keeps no pin log)."""

    def __init__(self, name: str) -> None:
        self.name = name


def _run_on_board(session: MachineSession, job: MachineJob, controller: Optional[Controller]) -> RunResult:
    """:func:`run` on a board that makes its own steps (grbl, MAXIMUS): the session runs it; the caller's
    ``controller`` is passed on (pause, stop, emergency stop) while it runs."""
    t0 = time.monotonic()
    session.start(job)
    passed = (False, False, False)
    while not session.wait_idle(0.05):
        if controller is None:
            continue
        now = (controller.paused, controller.stop_requested, controller.estop_requested)
        try:
            if now[2] and not passed[2]:
                session.emergency_stop()
            elif now[1] and not passed[1]:
                session.stop()
            elif now[0] != passed[0]:
                session.pause() if now[0] else session.resume()
        except CamError as exc:  # a board that cannot pause: said once, the job goes on
            session.log(str(exc), "warning")
        passed = now
    info = session.last_run
    if info.get("status") not in ("finished", "stopped", "emergency-stopped"):
        raise PortError("; ".join(info.get("messages") or ["the run failed"]))
    a = session._last_activity
    return RunResult(str(info["status"]), session.position_steps(), int(a.done if a is not None else 0),
                     float(info.get("machine_time_s", job.estimated_s())),
                     time.monotonic() - t0, 0, _BoardPort(str(session.port)), list(info.get("messages") or []))
