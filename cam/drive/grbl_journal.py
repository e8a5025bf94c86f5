"""The journal of a job on a grbl board (issue #45 point 3): how far grbl certainly got, from where it says the tool is.

grbl answers ``ok`` once a line has entered its planner (up to 15 blocks queued, and its receive buffer behind
them), not once it has run, so an answer says nothing of how far the tool got.  Its status reports do: the tool
stands on the straight line of one of the lines sent.  :class:`GrblLines` keeps the lines sent that are not
certainly done yet (each one's end, steps from where the run started, and the last point of the job it reaches)
and, given a reported position, searches forward from the last line certainly done for the first line whose
segment the position lies on (within :func:`on_path_tolerance_steps`, grbl's step resolution and rounding): every
line before that one is done.  The first such line is never after the one the tool is really on (which lies on
the search too), so the journal is never ahead of the machine, even where the path runs back over itself (a
plunge and its retract): it takes the earlier of the two.  When grbl stands idle after every line it was sent (at
a pause of the job, at its end), every line is done.

:class:`GrblJournal` writes the job's journal in the same file format as a step/dir run's
(:class:`cam.job.resume.Journal`, :mod:`cam.drive.journal`): once before the first line, at most every
:data:`~cam.drive.journal.JOURNAL_PERIOD_S` while the job runs (from a thread of its own, on the poller's
latest report), and once at the end with where grbl reports the tool after the stop.  Frames: steps from where
the run started (+Y toward the operator, +Z deeper), as the job's points.
"""
from __future__ import annotations

import dataclasses
import threading
from collections import deque
from typing import Any, Callable, Optional

import numpy as np

from ..errors import CamError
from ..job.resume import journal_record
from ..settings import MachineSettings
from .journal import JOURNAL_PERIOD_S, JournalSpec, write_journal

__all__ = ["GrblLines", "GrblJournal", "on_path_tolerance_steps", "ON_PATH_STEPS", "Seen"]

Seen = tuple[np.ndarray, tuple[int, int, int]]
"""Where grbl reported the tool, steps from the run's start: ``(exact, booked)``, the ``(3,)`` position not rounded
and the whole steps the session books."""

ON_PATH_STEPS = 3.0
"""How far (in grbl's steps, or `cam`'s where grbl's are finer) a reported position may lie from the line grbl
runs and still be on it: grbl's target is rounded to its step (half a step), its position along a line is within
a step of the straight line on each axis, 1.5 steps on each of three axes is 2.6 in all.  A larger bound only
makes the journal more careful (an earlier line matches first), never ahead."""


def on_path_tolerance_steps(grbl_settings: dict[int, float], settings: MachineSettings) -> float:
    """:data:`ON_PATH_STEPS` in `cam`'s steps: times the size of grbl's step in `cam`'s (``$100``-``$102``
    against the machine file's resolution) where grbl's step is the coarser.

    >>> s = MachineSettings()
    >>> on_path_tolerance_steps({100: 1 / s.mm_per_step_xy}, s), on_path_tolerance_steps({102: 10.0}, s)
    (3.0, 19.108...)
    """
    ratio = 1.0
    for axis, mm_per_step in enumerate((settings.mm_per_step_xy, settings.mm_per_step_xy, settings.mm_per_step_z)):
        per_mm = float(grbl_settings.get(100 + axis, 0.0) or 0.0)
        if per_mm > 0:
            ratio = max(ratio, 1.0 / (per_mm * mm_per_step))
    return ON_PATH_STEPS * ratio


def _distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """How far ``p`` lies from the segment ``a``-``b`` (steps)."""
    ab = b - a
    length2 = float(ab @ ab)
    t = 0.0 if length2 == 0.0 else min(1.0, max(0.0, float((p - a) @ ab) / length2))
    return float(np.linalg.norm(p - (a + t * ab)))


class GrblLines:
    """The lines of a run on grbl not certainly done yet, and the last point certainly reached (see the module).

    Args:
        tolerance_steps: how far a reported position may lie from a line and be on it
            (:func:`on_path_tolerance_steps`).
    """

    def __init__(self, tolerance_steps: float) -> None:
        self.tolerance_steps = float(tolerance_steps)
        self._lock = threading.Lock()
        self._start = np.zeros(3, np.float64)  # the end of the last line certainly done (the run's start)
        self._lines: deque[tuple[np.ndarray, int]] = deque()  # (end, last point) of each line after it
        self.done_point = -1
        """The last point of the run certainly reached (-1: none)."""

    def add(self, end_steps: Any, last_point: int) -> None:
        """A line to ``end_steps`` (steps from the run's start) goes to grbl next; it reaches point ``last_point``."""
        with self._lock:
            self._lines.append((np.asarray(end_steps, np.float64).reshape(3), int(last_point)))

    def seen_at(self, position_steps: Any) -> int:
        """grbl reported the tool at ``position_steps`` (steps from the run's start, not rounded): the lines before
        the first one after the last certainly done whose segment holds it are done.  Returns :attr:`done_point`."""
        p = np.asarray(position_steps, np.float64).reshape(3)
        with self._lock:
            a = self._start
            for k, (end, _) in enumerate(self._lines):
                if _distance(p, a, end) <= self.tolerance_steps:
                    for _ in range(k):  # the lines before it
                        a_end, last = self._lines.popleft()
                        self._start = a_end
                        self.done_point = max(self.done_point, last)
                    break
                a = end
            return self.done_point

    def all_done(self, point: int) -> None:
        """grbl stands idle after answering every line sent: all of them are done, the run is at ``point``."""
        with self._lock:
            if self._lines:
                self._start = self._lines[-1][0]
                self.done_point = max(self.done_point, self._lines[-1][1])
                self._lines.clear()
            self.done_point = max(self.done_point, int(point))


class _PointsDone:
    """``point_write`` of :func:`~cam.job.resume.journal_record` for a run on grbl: a "write" is a point reached."""

    @staticmethod
    def last_completed(writes_done: int) -> int:
        return int(writes_done) - 1


class GrblJournal:
    """Keeps the journal of a job on grbl (see the module): written at once (state ``running``), by a thread while
    the job runs, and by :meth:`close`.

    Args:
        spec: where and what (:class:`~cam.drive.journal.JournalSpec`, as the session makes it).
        total_points: the run's points (a resumed run's way in included).
        lines: the run's :class:`GrblLines` (the stream adds each line before it goes).
        where: where grbl's latest status report has the tool, steps from the run's start: ``(exact, booked)``,
            the position not rounded and as the session books it (whole steps), or None (no report).
        on_error: called once when a write during the run fails (the session stops the job: a run whose journal
            no longer says where it is could not be resumed).

    Raises:
        CamError: the first write failed (nothing was sent).
    """

    def __init__(self, spec: JournalSpec, total_points: int, lines: GrblLines,
                 where: Callable[[], Optional[Seen]], on_error: Optional[Callable[[], None]] = None) -> None:
        self.spec = spec
        self.total_points = int(total_points)
        self.lines = lines
        self.where = where
        self.on_error = on_error
        self.error: Optional[str] = None
        self.pending: Optional[int] = None  # a pause's point whose prompt is not answered yet
        self._position = (0, 0, 0)
        self._written: Optional[tuple] = None
        self._lock = threading.RLock()  # the thread's update and the stream's pause: one at a time
        self._closing = threading.Event()
        self._write("running")
        if self.error is not None:  # no journal, no resume: the job does not start without one
            raise CamError(f"{self.error}; the job was not started (its journal could not be written)")
        self._thread = threading.Thread(target=self._loop, name="cam-grbl-journal", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._closing.wait(JOURNAL_PERIOD_S):
            self.update()

    def update(self, seen: Optional[Seen] = None) -> None:
        """Take where grbl has the tool (``seen``, as ``where`` gives it; None: its latest report) and write what
        changed."""
        with self._lock:
            self._take(self.where() if seen is None else seen)
            self._write("running")

    def _take(self, seen: Optional[Seen]) -> None:
        if seen is not None:
            self.lines.seen_at(seen[0])
            self._position = tuple(int(v) for v in seen[1])  # type: ignore[assignment]

    def paused_at(self, point: int) -> None:
        """grbl stands still at the pause of point ``point``, every line sent done; the prompt waits."""
        with self._lock:
            self.lines.all_done(point)
            self.pending = int(point)
            self.update()

    def home_moved(self, by_steps: Any) -> None:
        """The job's frame moved at its pause by ``by_steps`` (a tool probed at a tool change: the work Z shifted,
        :mod:`cam.drive.grbl_pause_probe`): its later lines, the tool and its reports are from a start shifted by as
        much.  The journal's home (``home_steps``, machine frame) moves so, written at once, as a step/dir run's
        (:meth:`cam.drive.journal.JournalWriter.home_moved`): a resumed run goes on at the new work Z."""
        with self._lock:
            home = tuple(int(h) + int(b) for h, b in zip(self.spec.home_steps, by_steps))
            self.spec = dataclasses.replace(self.spec, home_steps=home)  # type: ignore[arg-type]
            self._written = None  # the key does not hold the home: written again
            self._write("running")

    def answered(self) -> None:
        """The pause's prompt was answered: the job goes on."""
        self.pending = None

    def _write(self, state: str) -> None:
        with self._lock:
            done = self.lines.done_point + 1
            key = (done, self.pending, self._position, state)
            if key == self._written:
                return
            pauses = set() if self.pending is None else {self.pending}
            record = journal_record(self.spec.base, _PointsDone(), pauses, done,  # type: ignore[arg-type]
                                    self.total_points, self._position, state, self.spec.home_steps)
            try:
                write_journal(record, self.spec.path)
                self._written = key
            except CamError as exc:
                first = self.error is None
                self.error = str(exc)
                if first and state == "running" and self._written is not None and self.on_error is not None:
                    self.on_error()

    def close(self, state: str, seen: Optional[Seen] = None) -> Optional[str]:
        """The run ended in ``state`` (:data:`~cam.job.resume.JOURNAL_STATES`) with grbl reporting the tool where
        ``seen`` says (as ``where`` gives it; None: not known, the last report's is kept): the last write.
        Returns the message of a write that failed (the journal then is the last good one), or None."""
        self._closing.set()
        self._thread.join()
        with self._lock:
            self._take(seen)
            self._write(state)
        return self.error
