"""What a machine session's worker thread does: run a step plan on a step/dir port, or work a MAXIMUS board.

Each function reports to the session through its worker hooks
(:meth:`~cam.drive.session.MachineSession.progress`, ``prompt``, ``finish``,
``log``) and never raises: an error ends the activity with a log line.
"""
from __future__ import annotations

import threading
from typing import Any, Callable, Optional

import numpy as np

from ..errors import CamError, PortError
from ..settings import MachineSettings
from ..values import format_duration
from .maximus.board import MaximusBoard, drill_arguments, from_board, to_board
from .journal import HoleJournal, JournalSpec, JournalWriter, journal_state_of
from .maximus.resume import holes_left, resumed_arguments
from .machines import open_port, require
from .pause_probe import probe_at_pause
from .ports import MockPort
from .runner import Controller, Cursor, run
from ..motion.chunks import ChunkedPlan
from ..motion.steps import StepPlan

__all__ = ["run_steps", "run_on_board", "BoardControl", "drill_work", "move_work"]

BoardWork = Callable[[MaximusBoard, Any], Any]
"""work(board, session): what to do with an open board; it may return where the head ended (x, y, z steps from
where it started), else the activity's own ``moved_steps`` say."""


def run_steps(session: Any, name: str, plan: "StepPlan | ChunkedPlan", ctl: Controller, label: str,
              journal: Optional[JournalSpec] = None, cursor: Optional[Cursor] = None) -> None:
    """Run ``plan`` on the session's step/dir port (the worker thread of a job, jog or move).

    ``journal``: keep the job's journal (in the runner process for a real-time run, else here).
    """
    result = None
    error = None
    port = None
    writer: Optional[JournalWriter] = None
    ctl.z_top_steps = None  # a controller used again: no top of the travel from an earlier run's frame
    try:
        if session.realtime and isinstance(session.port, str):  # a process of its own: nothing holds it up
            if not session.backend.can("simulated", session.port):
                open_port(session.port, session.settings).close()  # a port that cannot be opened: its own message
            # the child makes a chunked plan's writes itself, a chunk at a time (bounded memory)
            runner = session.runner_process()
            if not runner.claimed:  # a new runner process: say once what it got (class, memory, core)
                runner.start()
                session.log(f"step runner: {runner.claimed or 'started'}")
            session._pause_work = runner.pause_work  # a tool probed at a tool change: on the child's port
            result = runner.run(plan, session.port, ctl, progress=session.progress, on_pause=session.prompt,
                                journal=journal, cursor=cursor)
        else:  # the simulated clock, or a port object the caller opened
            port = open_port(session.port, session.settings)
            cursor = cursor or Cursor(plan.settings)
            if journal is not None:
                writer = JournalWriter(journal, plan, cursor, on_error=ctl.stop)
            opened = port
            session._pause_work = lambda request: probe_at_pause(opened, plan.settings, session.realtime, ctl,
                                                                 request, writer)  # a tool probed at a tool change
            result = run(plan, port, realtime=session.realtime, controller=ctl, progress=session.progress,
                         on_pause=session.prompt, cursor=cursor)
            if writer is not None:
                journal_error = writer.close(journal_state_of(result.status), result.writes, result.position_steps)
                writer = None
                if journal_error:
                    result.messages.append(journal_error)
    except CamError as exc:
        error = str(exc)
    except Exception as exc:  # noqa: BLE001 - reported in the log; the runner sent nothing more
        error = f"internal error: {type(exc).__name__}: {exc}"
    finally:
        session._pause_work = None
        if writer is not None:  # the run failed: the journal says where it got to
            writer.close("failed")
        if port is not None and not isinstance(port, MockPort):
            try:
                port.close()
            except CamError as exc:
                error = error or str(exc)
    info: dict[str, Any] = {"activity": name, "label": label}
    if journal is not None:
        info["journal"] = journal.path
    if result is None:
        info.update(status="error", messages=[error or "failed"])
        session.finish(info, None)
        session.log(f"{label}: {error}", "error")
        return
    info.update(status=result.status, writes=result.writes, messages=list(result.messages),
                machine_time_s=round(result.machine_time_s, 4), wall_time_s=round(result.wall_time_s, 4),
                started_ns=result.started_ns,
                step_period_ns=int(max(plan.settings.delay_xy_ns, plan.settings.delay_z_ns)))
    if session.realtime:
        info.update(max_late_s=round(result.lateness.max_ns / 1e9, 6), stalls=result.lateness.stalls,
                    late_total_s=round(result.lateness.total_ns / 1e9, 6), reramps=result.lateness.reramps)
    log = None
    if isinstance(result.port, MockPort):  # its log stays with the port (bounded memory), read when asked
        last = result.port.last_t_ns
        info["last_write_job_ns"] = None if last is None else last - result.port.time_offset_ns  # the run's own
        log = result.port if result.port.pin_log_path is None else None
    # (a travel's too: the session keeps the one to a job's work zero with the job's)
    session.finish(info, np.array(result.position_steps, np.int64), result=result, pin_log=log)
    text = f"{label}: {result.status}"
    if result.status == "finished" and name == "job":  # the page's finished line: elapsed, and how late
        text += "; " + run_timing_text(result.machine_time_s, result.wall_time_s, info, plan.settings.ramp,
                                       simulated=not session.realtime)
    if result.messages:
        text += " (" + "; ".join(result.messages) + ")"
    session.log(text, "info" if result.status == "finished" else "warning")


def run_timing_text(machine_time_s: float, wall_s: float, timing: dict, ramp: str, *, simulated: bool) -> str:
    """How long a finished step/dir run took, as the CLI's and the page's finished lines say it (issue #32 point 6):
    on the simulated clock the machine time; in real time the elapsed time, the planned machine time and, when
    the run was late, by how much, its stalls over 1 ms, the longest, and the re-ramps after them.  ``timing``:
    ``late_total_s``, ``stalls``, ``max_late_s``, ``reramps`` (a run's :class:`~cam.drive.runner.Lateness`)."""
    if simulated:
        return (f"total time {format_duration(machine_time_s)} ({machine_time_s:.1f} s machine time, {ramp} ramps, "
                f"simulated)")
    text = f"the run took {format_duration(wall_s)} ({machine_time_s:.1f} s machine time planned, {ramp} ramps"
    late_s, stalls = float(timing.get("late_total_s", 0.0)), int(timing.get("stalls", 0))
    if late_s >= 0.001 or stalls:
        text += (f"; {late_s:.1f} s late: {stalls} stall{'s' if stalls != 1 else ''} over 1 ms, the longest "
                 f"{1000 * float(timing.get('max_late_s', 0.0)):.0f} ms")
        reramps = int(timing.get("reramps", 0))
        if reramps:
            text += f", {reramps} re-ramp{'s' if reramps != 1 else ''}"
    return text + ")"


class BoardControl:
    """Pause / stop controls of an activity on a MAXIMUS board (the :class:`Controller` of step/dir ports).

    The firmware has no pause.  Stop and emergency stop both go to
    :meth:`MaximusBoard.emergency_stop`: during a move it sends the firmware's stop byte, between moves it
    sends nothing more and the job ends before the next packet.
    """

    paused = False

    def __init__(self, port: str) -> None:
        self.port = port
        self.halted = False
        self._board: Any = None
        self._lock = threading.Lock()

    def attach(self, board: MaximusBoard) -> None:
        """The board is open; a stop asked for before this point ends the job now."""
        with self._lock:
            self._board = board
            halted = self.halted
        if halted:
            board.emergency_stop()
            raise PortError("stopped before the board started")

    def stop(self) -> None:
        with self._lock:
            self.halted = True
            board = self._board
        if board is not None:
            board.emergency_stop()

    emergency_stop = stop

    def pause(self) -> None:
        require(self.port, "pause")

    def resume(self) -> None:
        require(self.port, "pause")


def drill_work(job: Any, settings: MachineSettings, journal: Optional[JournalSpec] = None) -> BoardWork:
    """The board work of a prepared drill job: every hole, with its tool-change prompts and progress.

    Each hole is announced as the PC program does ("Drilling hole n of N", seed 000 Appendix 2,
    ``ComPort1RxChar``) through the session's :meth:`~cam.drive.session.MachineSession.detail`; hole numbers
    count from 1 in every message.  ``journal``: keep the job's journal of the holes drilled
    (:class:`~cam.drive.journal.HoleJournal`).  A resumed job (:func:`cam.drive.maximus.resume.resume_board_job`)
    first brings the head to the start height, then goes on from the first hole not drilled and ends at the
    job's home (:mod:`cam.drive.maximus.resume`); the work returns where the head ended, from where it started.
    """
    holes_steps = np.asarray(job.drill_plan.holes_steps, np.int64).reshape(-1, 2)
    n_holes = len(holes_steps)
    done0, start = holes_left(job)
    arguments, lift_steps = resumed_arguments(drill_arguments(job.drill_plan, settings), done0, start)
    p0 = np.asarray(start, np.int64)

    def work(board: MaximusBoard, session: Any) -> np.ndarray:
        def here() -> tuple[int, int, int]:  # where the head stands, steps from the job's home
            return tuple(int(v) for v in p0 + _board_moved(board))  # type: ignore[return-value]

        keeper = None if journal is None else HoleJournal(journal, job.drill_plan.hole_index, done0, start,
                                                           on_error=board.emergency_stop)

        def on_hole(drilled: int) -> None:
            done = done0 + drilled
            session.progress(done, n_holes, int(job.estimated_time_s * 1e9 * done / max(1, n_holes)))
            session.board_moved(done, _board_moved(board))  # the page's live position: after every hole
            if keeper is not None:
                keeper.hole_done(done, here())

        def on_tool_change(index: int, note: str) -> None:  # spindle off, head at the start height
            i = done0 + index
            x, y = (int(v) for v in holes_steps[i - 1]) if i > 0 else (0, 0)
            if index == 0 and done0:  # a resumed job: the head lifted where the stop left it
                x, y = int(p0[0]), int(p0[1])
            session.prompt((x - int(p0[0]), y - int(p0[1]), -int(p0[2])), note)

        if settings.maximus.drill_stroke_set:
            session.log(f"Z drill up {arguments['z_up_steps']}, down {arguments['z_down_steps']} steps below the "
                        f"origin, from the machine settings (the job's travel height and cut depth do not apply)")
        try:
            if lift_steps:
                board.move(0, 0, lift_steps)  # a resumed job: the head to the start height first
            if len(arguments["holes_steps"]):
                board.drill(**arguments, on_tool_change=on_tool_change, on_hole=on_hole,
                            before_hole=lambda i: session.detail(f"drilling hole {done0 + i + 1} of {n_holes}"))
            elif np.any(p0[:2]):  # every hole was drilled: only the way back to the job's home is left
                board.move(-int(p0[0]), int(p0[1]), 0)
        except BaseException:
            if keeper is not None:
                keeper.close("emergency-stopped" if board.stop_asked else "failed", here())
            raise
        if keeper is not None and keeper.close("finished", (0, 0, 0)):
            session.log(f"the journal was not written at the end: {keeper.error}", "warning")
        return -p0  # back at the job's home, Z at the start height

    work.journal_path = None if journal is None else journal.path  # type: ignore[attr-defined]  # the page's Resume
    return work


def move_work(points_steps: np.ndarray) -> BoardWork:
    """The board work of a travel job through ``(N, 3)`` points (`cam`'s frame, relative to where the head
    stands): each move in the board's frame, up first, X and Y together, down last
    (:meth:`MaximusBoard.travel`)."""
    pts = np.asarray(points_steps, np.int64).reshape(-1, 3)
    moves = to_board(np.diff(np.vstack([np.zeros((1, 3), np.int64), pts]), axis=0))

    def work(board: MaximusBoard, session: Any) -> None:
        board.travel(moves)

    return work


def _board_moved(board: MaximusBoard | None) -> np.ndarray | None:
    """Where the board's confirmed replies put the head, in `cam`'s frame from where it started."""
    if board is None:
        return None
    return from_board(np.array([board.position_pulses], np.int64))[0]


def run_on_board(session: Any, name: str, work: BoardWork, ctl: BoardControl, label: str,
                 moved_steps: np.ndarray) -> None:
    """Open the session's MAXIMUS board and do ``work`` on it (the worker thread)."""
    error = None
    board = None
    try:
        board = MaximusBoard(session.port, session.settings.maximus)
        ctl.attach(board)
        ended = work(board, session)
        if ended is not None:  # the work says where the head ended (a resumed drill job: at the job's home)
            moved_steps = np.asarray(ended, np.int64)
    except CamError as exc:
        error = str(exc)
    except Exception as exc:  # noqa: BLE001 - reported in the log; the host sent nothing more
        error = f"internal error: {type(exc).__name__}: {exc}"
    finally:
        if board is not None:
            board.close()
    kept = {"journal": work.journal_path} if getattr(work, "journal_path", None) else {}  # a drill job's journal
    if error is None:
        session.finish({"activity": name, "label": label, "status": "finished", "messages": [], **kept}, moved_steps)
        session.log(f"{label}: finished")
        return
    status = "emergency-stopped" if ctl.halted else "error"
    # a stopped move has moved part of the way: where the head is, is not known exactly any more (the PC
    # program says "Offset Coordinates lost!", seed 000 Appendix 2, GoEStopExecute)
    session.finish({"activity": name, "label": label, "status": status, "messages": [error], **kept},
                   _board_moved(board))
    session.log(f"{label}: {error} (the head's position is not known exactly any more: jog it to the board "
                f"origin and set the offset there)", "error")
