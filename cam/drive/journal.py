"""The job journal on disk: written atomically as a job runs, read back to resume it.

A journal is a small JSON file (see :class:`cam.job.resume.Journal` for its
keys)::

    {"cam_journal": 1, "identity": "9f2c...", "plan_sha256": "51ab...", "source": "gear.png",
     "moves": 640, "last_move": 212, "position_steps": [1080, 56, 0], "state": "stopped", ...}

:class:`JournalWriter` writes it from the process that sends the steps (for
a real-time run that is the runner process, :mod:`cam.drive.apart`, so a
killed parent still leaves a closed journal): once when the run starts, at
most every :data:`JOURNAL_PERIOD_S` while it runs (from a thread of its own:
the runner never waits for the disk), and once at the end with the exact
position.  Every write goes through :func:`cam.fileio.atomic_write_text`:
the old journal or the new one, never half of one.  A journal is never
ahead of the machine: its move and position come from the writes already
sent, so a journal left behind by a run that ended without its last write
(state ``running``: killed, or its disk filled) is behind, never ahead:
resuming it cuts a little again, never skips.  Its position is not trusted
(:func:`cam.job.resume.resume_start`, issue #43 point 7): the run goes on
from where the machine state has the tool, once that is known.
"""
from __future__ import annotations

import dataclasses
import json
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import numpy as np

from ..errors import CamError
from ..fileio import atomic_write_text, read_text
from ..job.model import JobLike
from ..job.resume import Journal, JournalBase, journal_record, plan_fingerprint
from .runner import Cursor
from .priority import as_background

__all__ = ["JOURNAL_PERIOD_S", "JournalSpec", "JournalWriter", "journal_spec", "read_journal", "write_journal",
           "journal_state_of", "HoleJournal"]

JOURNAL_PERIOD_S = 0.25
"""The shortest time between two journal writes while a job runs."""

_MAX_JOURNAL_BYTES = 1 << 20


@dataclass
class JournalSpec:
    """Where and what a run's journal writes (picklable: it travels to the runner process with the plan).

    Attributes:
        path: the journal file.
        base: the job, and where the run starts in it (:class:`cam.job.resume.JournalBase`).
        home_steps: the job's home in the machine session's frame (moved by a tool probed at a tool change:
            :meth:`JournalWriter.home_moved`).
        pin_log_path: where the runner process writes the mock's pin log itself when its parent died
            (None: nowhere).
    """

    path: str
    base: JournalBase
    home_steps: tuple[int, int, int] = (0, 0, 0)
    pin_log_path: Optional[str] = None


def journal_spec(job: Any, path: str | os.PathLike, *, home_steps: tuple[int, int, int] = (0, 0, 0),
                 pin_log_path: Optional[str] = None) -> JournalSpec:
    """The journal spec of a run of ``job`` (a :class:`~cam.kinds.jobs.PreparedJob` or a :class:`~cam.job.model.Job`).

    ``home_steps``: where the tool stands when the run starts, in the session's frame; a resumed job's home
    is where its journal says (``home_steps`` minus where the run starts in the job).
    """
    base = getattr(job, "resumed", None)
    if base is None:
        toolpath = getattr(job, "toolpath", job)
        if not isinstance(toolpath, JobLike):
            raise CamError("this job has no moves to keep a journal of")
        base = JournalBase(identity=getattr(job, "identity", "") or "", source=str(getattr(job, "source", "")),
                           plan_sha256=getattr(job, "plan_sha256", "") or plan_fingerprint(toolpath),
                           moves=len(toolpath))
    home = np.asarray(home_steps, np.int64) - np.asarray(base.start_position_steps, np.int64)
    return JournalSpec(str(path), base, tuple(int(v) for v in home), pin_log_path)  # type: ignore[arg-type]


def write_journal(journal: Journal, path: str | os.PathLike) -> None:
    """Write a journal file atomically."""
    atomic_write_text(path, json.dumps(journal.to_dict()) + "\n")


def read_journal(path: str | os.PathLike) -> Journal:
    """Read a journal file.

    Raises:
        CamError: the file is missing, not JSON or not a `cam` journal (one line naming the file).
    """
    p = Path(path)
    if p.is_file() and p.stat().st_size > _MAX_JOURNAL_BYTES:
        raise CamError(f"{p}: not a cam journal (over {_MAX_JOURNAL_BYTES} bytes)")
    _, text = read_text(p, not_text="not a cam journal (not UTF-8 text)")
    try:
        values = json.loads(text)
    except (ValueError, RecursionError):
        raise CamError(f"{p}: not a cam journal (not JSON)") from None
    return Journal.from_dict(values, str(p))


def journal_state_of(status: str) -> str:
    """A run's status (:data:`cam.drive.runner.FINISHED`, ...) as a journal state."""
    return status if status in ("finished", "stopped", "emergency-stopped") else "failed"


class JournalWriter:
    """Keeps a run's journal: :meth:`progress` from the runner (cheap), a thread that writes, :meth:`close`.

    The first write (state ``running``) happens here, before the run sends anything.
    """

    def __init__(self, spec: JournalSpec, plan: Any, cursor: Cursor,
                 on_error: Optional[Callable[[], None]] = None) -> None:
        self.spec = spec
        self.on_error = on_error
        """Called once when a write during the run fails (the runner stops the job there: a run whose journal
        no longer says where it is could not be resumed)."""
        self.plan = plan
        self.cursor = cursor  # the run's: (writes sent, position after them), replaced whole by the runner
        self.error: Optional[str] = None
        self._pause_writes = set(int(i) for i in plan.pause_writes)
        self._point_write = plan.point_write
        self._written = -1
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._write(0, (0, 0, 0), "running")
        if self.error is not None:  # no journal, no resume: the job does not start without one
            raise CamError(f"{self.error}; the job was not started (its journal could not be written)")
        self._thread = threading.Thread(target=self._loop, name="cam-journal", daemon=True)
        self._thread.start()

    def _sent_and_position(self) -> tuple[int, tuple[int, int, int]]:
        """Writes sent and the position after them, never the one ahead of the other."""
        sent, position = self.cursor.live
        return int(sent), position

    def _loop(self) -> None:
        as_background()  # in the real-time runner process: not the writing thread's class and core
        while not self._closing.wait(JOURNAL_PERIOD_S):
            sent, position = self._sent_and_position()
            if sent != self._written:
                self._write(sent, position, "running")

    def _write(self, sent: int, position_steps: tuple[int, int, int], state: str) -> None:
        record = journal_record(self.spec.base, self._point_write, self._pause_writes, sent, len(self.plan),
                                position_steps, state, self.spec.home_steps)
        with self._lock:
            try:
                write_journal(record, self.spec.path)
                self._written = sent
            except CamError as exc:
                first = self.error is None
                self.error = str(exc)
                if first and state == "running" and self._written >= 0 and self.on_error is not None:
                    self.on_error()

    def home_moved(self, by_steps: Sequence[int]) -> None:
        """The tool was moved at a pause and the job goes on from there (a tool probed at a tool change: the work Z
        shifted by ``by_steps``, :mod:`cam.drive.pause_probe`): its later moves, all relative, land shifted by as
        much, as if the job had started there.  The journal's home (``home_steps``, machine frame) moves so, written
        at once: a resumed run goes on from it at the new work Z, where the machine state has the tool."""
        with self._lock:
            home = tuple(int(h) + int(b) for h, b in zip(self.spec.home_steps, by_steps))
            self.spec = dataclasses.replace(self.spec, home_steps=home)  # type: ignore[arg-type]
        sent, position = self._sent_and_position()
        self._write(sent, position, "running")

    def close(self, state: str, writes_done: Optional[int] = None,
              position_steps: Optional[tuple[int, int, int]] = None) -> Optional[str]:
        """The run ended: the last write, with the exact position (steps from the run's start).

        Without ``writes_done`` and ``position_steps`` (the run failed, its end is not known): the last
        progress and the position it reached.  Returns the message of a write that failed (the journal then
        is the last good one), or None.
        """
        self._closing.set()
        self._thread.join()
        if writes_done is None or position_steps is None:
            writes_done, position_steps = self._sent_and_position()
        self._write(int(writes_done), tuple(int(v) for v in position_steps), state)  # type: ignore[arg-type]
        return self.error


class HoleJournal:
    """Keeps a MAXIMUS board job's journal: a :class:`~cam.job.resume.Journal` whose moves are the holes in
    drilling order (``holes_done``, ``hole_order``), in the same file format, written atomically as the step/dir
    journal is: once before the first packet, once after each hole's reply (ONEHOLEDRILLED), once at the end.

    The board answers each hole (seconds apart), so each write is made at once, from the thread that drills;
    a journal is never ahead of the board: a hole counts once its reply came.  Positions are steps from the
    job's home (`cam`'s frame); ``spec.home_steps`` places the home in the session's frame.
    """

    def __init__(self, spec: JournalSpec, hole_order: Sequence[int], holes_done: int = 0,
                 position_steps: tuple[int, int, int] = (0, 0, 0),
                 on_error: Optional[Callable[[], None]] = None) -> None:
        self.spec = spec
        self.hole_order = tuple(int(v) for v in hole_order)
        self.on_error: Optional[Callable[[], None]] = None
        self.error: Optional[str] = None
        self.holes_done = int(holes_done)
        self.position_steps = tuple(int(v) for v in position_steps)
        self._write("running")
        if self.error is not None:  # no journal, no resume: the job does not start without one
            raise CamError(f"{self.error}; the job was not started (its journal could not be written)")
        self.on_error = on_error
        """Called once when a write during the run fails (the board stops before its next hole)."""

    def hole_done(self, holes_done: int, position_steps: tuple[int, int, int]) -> None:
        """The board answered a hole: ``holes_done`` in all, the head at ``position_steps``."""
        self.holes_done, self.position_steps = int(holes_done), tuple(int(v) for v in position_steps)
        self._write("running")

    def close(self, state: str, position_steps: Optional[tuple[int, int, int]] = None) -> Optional[str]:
        """The run ended in ``state`` (:data:`~cam.job.resume.JOURNAL_STATES`), the head at ``position_steps``
        (None: where the last hole left it).  Returns the message of a write that failed, or None."""
        if position_steps is not None:
            self.position_steps = tuple(int(v) for v in position_steps)
        if state == "finished":
            self.holes_done = len(self.hole_order)
        self._write(state)
        return self.error

    def _write(self, state: str) -> None:
        base = self.spec.base
        n = len(self.hole_order)
        start = tuple(int(v) for v in base.start_position_steps)
        record = Journal(identity=base.identity, plan_sha256=base.plan_sha256, source=base.source, moves=n,
                         last_move=self.holes_done - 1, position_steps=self.position_steps,  # type: ignore[arg-type]
                         state=state, writes_done=self.holes_done, writes_total=n,
                         home_steps=self.spec.home_steps, resumed_at_move=base.resumed_at_move,
                         start_position_steps=start,  # type: ignore[arg-type]
                         holes_done=self.holes_done, hole_order=self.hole_order)
        try:
            write_journal(record, self.spec.path)
        except CamError as exc:
            first = self.error is None
            self.error = str(exc)
            if first and state == "running" and self.on_error is not None:
                self.on_error()
