"""Resuming a job planned a piece at a time (:class:`~cam.job.drawing_stream.DrawingJobStream`,
:class:`~cam.job.hpgl_stream.HpglJobStream`), with the rules of :mod:`cam.job.resume`.

:func:`~cam.job.resume.resume_toolpath` reads the whole job's arrays.  A stream has none: one pass over its
pieces finds what the resumed run needs (the first move after the stop that cuts, its entry point, the
job's travel height, a pause the stop left or skipped), and :class:`ResumedStream` gives the resumed run as
pieces again: the way in (:func:`cam.job.resume._way_in`), then the job's own pieces from that move on.
Concatenated, they equal :func:`~cam.job.resume.resume_toolpath` of the whole job (tested).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterator, Optional

import numpy as np

from ..errors import CamError
from .hpgl_stream import _Hashes
from .model import Job, join_pieces
from .resume import _cuts, _surface_steps, _way_in

__all__ = ["ResumedStream", "MoveIndex", "resume_stream"]


@dataclass(frozen=True)
class MoveIndex:
    """The job's move each point of a resumed run completes, without an array per move (see
    :attr:`cam.job.resume.JournalBase.move_index`): the way in's ``(m,)`` ``head``, then moves ``j, j + 1, ...``."""

    head: np.ndarray
    j: int

    def __getitem__(self, i: int) -> int:
        m = len(self.head)
        return int(self.head[i]) if i < m else self.j + int(i) - m


@dataclass
class ResumedStream:
    """The resumed run of a stream: :meth:`pieces` gives the way in, then the job's pieces from move ``j`` on,
    every point relative to where the tool stands (``start_steps``).  Stands for a Job as the stream does."""

    job: Any
    way_in: Job
    j: int
    start_steps: tuple[int, int, int]
    pause_notes: list[str]
    n_moves: int
    fingerprint: str = ""
    source: str = ""
    warnings: list[str] = field(default_factory=list)
    pixels: Any = None
    period_ns: Any = None
    periods: Any = None
    move_start: Any = None
    rest: Any = None

    @property
    def settings(self) -> Any:
        return self.job.settings

    @property
    def safe_z_steps(self) -> int:
        return int(self.job.safe_z_steps) - int(self.start_steps[2])

    @property
    def tool(self) -> Any:
        return getattr(self.job, "tool", None)

    def __len__(self) -> int:
        return self.n_moves

    def joined(self) -> Job:
        """Every move in one :class:`~cam.job.model.Job` (:func:`~cam.job.model.join_pieces` of :meth:`pieces`)."""
        return join_pieces(self.pieces(), self)

    def pieces(self) -> Iterator[Job]:
        """The way in, then the stream's moves from ``j`` on (relative to ``start_steps``)."""
        hashes = _Hashes()
        hashes.add(self.way_in)
        yield self.way_in
        p0 = np.asarray(self.start_steps, np.int64)
        first = 0
        for piece in self.job.pieces():
            n = len(piece.points_steps)
            cut = max(0, self.j - first)
            first += n
            if cut >= n:
                continue
            pause = np.asarray(piece.pause, bool)
            notes = piece.pause_notes
            if notes is not None:  # the notes of the pauses left out go with them
                notes = list(notes)[int(np.count_nonzero(pause[:cut])):]
            part = Job(points_steps=np.asarray(piece.points_steps, np.int64)[cut:] - p0,
                       kind=np.asarray(piece.kind)[cut:], target=np.asarray(piece.target, bool)[cut:],
                       pause=pause[cut:], settings=self.settings, warnings=[], safe_z_steps=self.safe_z_steps,
                       pause_notes=notes)
            hashes.add(part)
            yield part
        self.fingerprint = hashes.h.hexdigest()


def resume_stream(job: Any, last_move: int, position_steps: tuple[int, int, int], *,
                  pause_pending: bool = False) -> tuple[ResumedStream, MoveIndex, int]:
    """:func:`cam.job.resume.resume_toolpath` of a stream (``job.pieces()``): ``(resumed, move_index, j)``.

    Args:
        job: the stream as planned from the start (its frame: steps from the job's home).
        last_move: index of the last completed move (-1: none); position_steps: where the tool stands.
        pause_pending: the pause at ``last_move`` (if any) was not answered: it is made again.

    Raises:
        CamError: ``last_move`` lies outside the job.
    """
    k = int(last_move)
    p0 = np.asarray(position_steps, np.int64).reshape(3)
    surface = _surface_steps(job)
    prev = np.zeros(3, np.int64)
    n = 0
    j = -1
    entry = np.zeros(3, np.int64)
    travel_z = 0
    n_pauses = 0  # pauses before move j (or before the point n, until j is found)
    pauses_before_j = -1
    carried: Optional[tuple[np.ndarray, int]] = None  # (point, index among the pauses) of the last carried pause
    for piece in job.pieces():
        pts = np.asarray(piece.points_steps, np.int64).reshape(-1, 3)
        cuts = _cuts(pts, prev, surface)
        if np.any(~cuts):
            travel_z = min(travel_z, int(pts[~cuts, 2].min()))
        pause = np.asarray(piece.pause, bool)
        if j < 0:
            later = np.flatnonzero(cuts[max(0, k + 1 - n):]) + max(0, k + 1 - n)
            end = int(later[0]) if len(later) else len(pts)  # j - n once found
            for i in np.flatnonzero(pause[:end]).tolist():  # the pauses before j: skipped, or left pending
                if n + i > k or (pause_pending and n + i == k):
                    carried = (pts[i].copy(), n_pauses)
                n_pauses += 1
            if len(later):
                j = n + end
                entry = pts[end - 1].copy() if end >= 1 else prev.copy()
                pauses_before_j = n_pauses
        if len(pts):
            prev = pts[-1]
        n += len(pts)
    if not -1 <= k < n:
        raise CamError(f"the last completed move {k} is outside the job's {n} moves")
    if j < 0:  # nothing after the stop cuts: the job's way home
        j, entry, pauses_before_j = n, prev.copy(), n_pauses
    z_t = min(int(p0[2]), int(job.safe_z_steps), travel_z)
    notes = list(job.pause_notes) if job.pause_notes else ["Pause At"] * n_pauses
    carried_note = [notes[carried[1]] if carried[1] < len(notes) else "Pause At"] if carried else []
    kept = _way_in(p0, k, j, entry, z_t, carried[0] if carried else None, surface)
    way_in = Job(points_steps=np.array([it[0] for it in kept], np.int64) - p0,
                 kind=np.array([it[1] for it in kept], np.uint8), target=np.zeros(len(kept), bool),
                 pause=np.array([it[2] for it in kept], bool), settings=job.settings, warnings=[],
                 safe_z_steps=int(job.safe_z_steps) - int(p0[2]), pause_notes=carried_note)
    source = f"{job.source} (resumed at move {j})" if job.source else f"resumed at move {j}"
    resumed = ResumedStream(job, way_in, j, tuple(int(v) for v in p0), carried_note + notes[pauses_before_j:],  # type: ignore[arg-type]
                            len(kept) + n - j, source=source)
    return resumed, MoveIndex(np.array([it[3] for it in kept], np.int64), j), j
