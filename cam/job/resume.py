"""Resuming an interrupted job: the journal record, a job's identity, and the resumed job (computation only).

A running job keeps a small *journal* (written atomically by
:mod:`cam.drive.journal`, read back with :func:`cam.drive.journal.read_journal`):
which job it is, how far it got and where the tool stands.  After a stop, an
emergency stop, a crash or a power cut, :func:`resume_job` plans the same job
again and builds the *resumed job* from the journal.

Frames: every position here is in machine steps from the *job's home* (where
the tool stood when the original job started; +z deeper, see
:mod:`cam.job.model`), unless a name says otherwise.  Move ``i`` of a job goes
from point ``i - 1`` (the home for ``i = 0``) to point ``i``; "the last
completed move" ``k`` is the last point the tool reached.

The resumed job, from where the tool stands (``P``, the journal's position)::

    1. lift straight up to the travel height z_t = min(P.z, the job's safe Z, the highest Z of every
       move of the job that does not cut)
    2. a tool change or Pause At the stop skipped: travel at z_t above its point and pause there
    3. travel at z_t above the entry point e = point j - 1, the start of move j: the first move after
       the last completed one (k) that cuts (moves that do not cut -- travels, retracts -- are skipped)
    4. plunge straight down to e (a depth the job itself reached there)
    5. the moves j, j + 1, ... of the job, unchanged

So nothing uncut is skipped (the interrupted move is cut again from its start), nothing goes deeper than
the job asked for, and a hole the stop found drilled is not drilled again.  A move *cuts* unless both its
ends are at or above the surface, or it goes straight up (or stays put).

One implementation for every job size: :func:`resume_pieces` reads any :class:`~cam.job.model.JobLike`
(a :class:`~cam.job.model.Job` in memory is one piece) in one pass and gives the resumed run as pieces
(:class:`ResumedJob`: the way in, then the job's own pieces from move ``j`` on) and the move each of its
points completes (:class:`MoveIndex`); :func:`resume_toolpath` is those pieces joined.  The plan's
fingerprint (:func:`plan_fingerprint`) is likewise one pass over the pieces, whatever their size.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Iterator, Mapping, Optional

import numpy as np

from ..errors import CamError
from ..settings import MachineSettings
from .model import CUT, RETRACT, TRAVEL, Job, JobLike, PixelFrame, PlanFingerprint, join_pieces

__all__ = [
    "JOURNAL_FORMAT", "JOURNAL_STATES", "Journal", "JournalBase", "Resumed", "job_identity", "plan_fingerprint",
    "PlanFingerprint", "check_journal", "resume_pieces", "resume_toolpath", "ResumedJob", "MoveIndex",
    "last_completed", "journal_record", "cutting_moves", "check_journal_numbers", "resume_start",
]

JOURNAL_FORMAT = 1
"""The journal file's format number (its ``cam_journal`` key)."""

JOURNAL_STATES = ("running", "stopped", "emergency-stopped", "failed", "finished")
"""What a journal says of its run: still running (or its process died), or how it ended."""


@dataclass(frozen=True)
class Journal:
    """What a journal file says (see :mod:`cam.drive.journal` for the file).

    Attributes:
        identity: sha256 of the input file's bytes and every option and setting that changes the plan
            (:func:`job_identity`).
        plan_sha256: sha256 of the planned job's points, kinds and pauses (:func:`plan_fingerprint`):
            the same input planned differently (another version of `cam`) is refused too.
        source: the input file as the run named it (for messages only).
        moves: number of moves (points) of the job.
        last_move: index of the last completed move (the last point the tool reached; -1: none).
        pause_pending: a pause (tool change, Pause At) at ``last_move`` was reached but not answered.
        position_steps: ``(x, y, z)`` where the tool stood when this was written, steps from the job's home.
        state: one of :data:`JOURNAL_STATES`.
        writes_done, writes_total: port writes sent of the run's plan, and all of them.
        home_steps: where the job's home is in the machine session's frame (the web page's session).
        resumed_at_move: the run was itself a resumed one, from this move (None: from the start).
        start_position_steps: where the run began, steps from the job's home.
        holes_done: a MAXIMUS board job's journal (:class:`cam.drive.journal.HoleJournal`): the holes drilled,
            counted in drilling order (its ``moves`` are the holes, ``last_move`` is ``holes_done - 1``); None:
            a step/dir job's journal.
        hole_order: a board job's journal: the drill file's index (from 0, file order) of each hole in drilling
            order.
    """

    identity: str
    plan_sha256: str
    source: str
    moves: int
    last_move: int
    position_steps: tuple[int, int, int]
    state: str
    pause_pending: bool = False
    writes_done: int = 0
    writes_total: int = 0
    home_steps: tuple[int, int, int] = (0, 0, 0)
    resumed_at_move: Optional[int] = None
    start_position_steps: tuple[int, int, int] = (0, 0, 0)
    holes_done: Optional[int] = None
    hole_order: Optional[tuple[int, ...]] = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of the journal file."""
        out: dict[str, Any] = {"cam_journal": JOURNAL_FORMAT}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None and f.name in ("holes_done", "hole_order"):  # a step/dir job's journal: as it was
                continue
            out[f.name] = list(value) if isinstance(value, tuple) else value
        return out

    @classmethod
    def from_dict(cls, values: Any, source: str = "journal") -> "Journal":
        """Read a journal's JSON object back, checked.

        Raises:
            CamError: not a `cam` journal, a key missing or a value of the wrong type (one line, naming ``source``).
        """
        if not isinstance(values, dict) or values.get("cam_journal") != JOURNAL_FORMAT:
            raise CamError(f"{source}: not a cam journal (format {JOURNAL_FORMAT})")
        out: dict[str, Any] = {}
        for f in fields(cls):
            if f.name not in values:
                if f.default is not dataclasses.MISSING:
                    continue
                raise CamError(f"{source}: the journal has no '{f.name}'")
            out[f.name] = _checked(f.name, values[f.name], source)
        journal = cls(**out)
        if journal.state not in JOURNAL_STATES:
            raise CamError(f"{source}: unknown journal state {journal.state!r}")
        if not (-1 <= journal.last_move < max(journal.moves, 0)) or journal.moves < 0:
            raise CamError(f"{source}: last_move {journal.last_move} is outside the job's {journal.moves} moves")
        if journal.holes_done is not None and journal.holes_done != journal.last_move + 1:
            raise CamError(f"{source}: holes_done {journal.holes_done} does not follow last_move {journal.last_move}")
        if journal.hole_order is not None and len(journal.hole_order) != journal.moves:
            raise CamError(f"{source}: hole_order names {len(journal.hole_order)} holes, the job has {journal.moves}")
        return journal


_INTS = ("moves", "last_move", "writes_done", "writes_total")
_OPTIONAL = ("resumed_at_move", "holes_done", "hole_order")
_TRIPLES = ("position_steps", "home_steps", "start_position_steps")


def _checked(name: str, value: Any, source: str) -> Any:
    def bad(why: str) -> CamError:
        return CamError(f"{source}: journal key '{name}' {why}, got {value!r}"[:300])

    if value is None and name in _OPTIONAL:
        return None
    if name == "hole_order":
        if not isinstance(value, list) or \
                not all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 1 << 62 for v in value):
            raise bad("must be a list of hole numbers")
        return tuple(value)
    if name in _INTS or name in _OPTIONAL:
        if isinstance(value, bool) or not isinstance(value, int) or abs(value) > 1 << 62:
            raise bad("must be a whole number")
        return value
    if name in _TRIPLES:
        if not isinstance(value, list) or len(value) != 3 or \
                not all(isinstance(v, int) and not isinstance(v, bool) and abs(v) < 1 << 62 for v in value):
            raise bad("must be three whole numbers of steps")
        return tuple(value)
    if name == "pause_pending":
        if not isinstance(value, bool):
            raise bad("must be true or false")
        return value
    if not isinstance(value, str) or len(value) > 4096:
        raise bad("must be text")
    return value


@dataclass
class JournalBase:
    """What a run's journal says besides its progress: the job, and where the run starts in it.

    Attributes:
        identity, plan_sha256, source, moves: as in :class:`Journal`.
        move_index: the job's move each point of the *run* completes (a :class:`MoveIndex`, or an ``(M,)``
            int64 array; a resumed run's first points, before its entry point, complete nothing new: they
            keep ``last_move``); None: point i completes move i (a run from the start).
        pause: ``(M,)`` bool, the pauses of the run's points, or None (not kept: a run's plan has its pauses).
        last_move, pause_pending: where the job stood when the run began (-1, False: at the start).
        resumed_at_move: the run's first move of the job (None: from the start).
        start_position_steps: where the run begins, steps from the job's home.
    """

    identity: str
    plan_sha256: str
    source: str
    moves: int
    pause: Optional[np.ndarray] = None
    move_index: Optional[MoveIndex | np.ndarray] = None
    last_move: int = -1
    pause_pending: bool = False
    resumed_at_move: Optional[int] = None
    start_position_steps: tuple[int, int, int] = (0, 0, 0)


@dataclass
class Resumed:
    """A resumed job and how it maps onto the job it resumes.

    Attributes:
        job: the moves of the resumed run, steps relative to where it starts (``start_position_steps``).
        base: what its journal says besides its progress (:class:`JournalBase`).
        resumed_at_move: the first move of the original job the run makes in full (``j``).
        start_position_steps: where the run starts, steps from the original job's home.
    """

    job: Job
    base: JournalBase
    resumed_at_move: int
    start_position_steps: tuple[int, int, int]


def _sha_update_json(h: "hashlib._Hash", value: Any) -> None:
    h.update(json.dumps(value, sort_keys=True, default=str, separators=(",", ":")).encode("utf-8"))
    h.update(b"\0")


def job_identity(input_sha256: str, options: Mapping[str, Any], settings: MachineSettings,
                 files_sha256: Optional[Mapping[str, str]] = None) -> str:
    """The identity of a job: sha256 over its input, its options and its machine settings.

    Args:
        input_sha256: sha256 (hex) of the input file's bytes.
        options: every option that changes the plan (e.g. ``dataclasses.asdict(JobOptions)``); options that
            name files should be given as ``files_sha256`` instead (a path changes, the bytes matter).
        settings: the machine settings (all of them: steps, delays, ramps, travel, pins).
        files_sha256: option name -> sha256 of the bytes of the file it names (a profile, a tool table).

    >>> a = job_identity("00", {"depth": [3]}, MachineSettings())
    >>> a == job_identity("00", {"depth": [3]}, MachineSettings()), a == job_identity("00", {"depth": [4]}, MachineSettings())
    (True, False)
    """
    h = hashlib.sha256()
    _sha_update_json(h, {"input": input_sha256, "options": dict(options), "settings": asdict(settings),
                         "files": dict(files_sha256 or {})})
    return h.hexdigest()


def plan_fingerprint(job: JobLike) -> str:
    """sha256 (hex) of a job's points, kinds and pauses: two plans with the same fingerprint have the same moves.

    One pass over ``job.pieces()`` (:class:`PlanFingerprint`): a job gives the same fingerprint held in
    memory (one piece) or given in pieces of any size.  For a job in memory it is the fingerprint journals
    have always kept (sha256 of the points, kinds and pauses arrays, each followed by a zero byte).
    """
    h = PlanFingerprint()
    try:
        for piece in job.pieces():
            h.add(piece)
        return h.hexdigest()
    finally:
        h.close()


def check_journal(journal: Journal, identity: str, plan_sha256: str, where: str = "journal", *,
                  board: bool = False) -> None:
    """Refuse a journal written for another job, or one whose job finished; ``board``: the run to resume is a
    MAXIMUS board job's (its journal counts holes, :attr:`Journal.holes_done`), else a step/dir job's, and a
    journal of the other kind is refused too.

    Raises:
        CamError: one line naming ``where`` (the journal file).
    """
    if board and journal.holes_done is None:
        raise CamError(f"journal {where} is a step/dir job's journal, not a MAXIMUS board job's; resume it on its "
                       f"own port, or start the job again without --resume")
    if not board and journal.holes_done is not None:
        raise CamError(f"journal {where} is a MAXIMUS board job's journal (it counts holes); resume it with "
                       f"--port maximus:DEVICE, or start the job again without --resume")
    if journal.identity != identity:
        raise CamError(f"journal {where} was written for another input or options; run the same file with the "
                       f"same options and machine settings, or start the job again without --resume")
    if journal.plan_sha256 != plan_sha256:
        raise CamError(f"journal {where} was written for another plan of the same input (another version of "
                       f"cam?); start the job again without --resume")
    if journal.state == "finished":
        raise CamError(f"journal {where}: the job finished; there is nothing to resume")


def check_journal_numbers(journal: Journal, settings: MachineSettings, where: str = "journal") -> None:
    """Refuse a journal whose numbers no run on this machine could have written, before anything is planned.

    The machine positions it implies (``home_steps``; ``home_steps + position_steps`` and
    ``home_steps + start_position_steps``, its positions being steps from the job's home) must be inside the
    travel, and its write counts consistent; a tampered journal is refused at once, never walked.

    Raises:
        CamError: one line naming ``where``, the key and the axis.
    """
    bounds = settings.travel.bounds_steps()
    home = np.asarray(journal.home_steps, np.int64)
    triples = [("home_steps", home)]
    triples += [(name, home + np.asarray(getattr(journal, name), np.int64))
                for name in ("position_steps", "start_position_steps") if getattr(journal, name, None) is not None]
    for name, machine in triples:
        for a, (lo, hi) in enumerate(bounds):
            if not lo <= int(machine[a]) <= hi:
                raise CamError(f"journal {where}: '{name}' puts the tool at {'XYZ'[a]}={int(machine[a])} steps from "
                               f"the machine's home, outside its {'XYZ'[a]} travel {lo}..{hi}; not a journal of "
                               f"this machine")
    if not 0 <= journal.writes_done <= journal.writes_total:
        raise CamError(f"journal {where}: writes_done {journal.writes_done} is outside 0..writes_total "
                       f"{journal.writes_total}")


def cutting_moves(job: JobLike) -> np.ndarray:
    """``(N,)`` bool: which moves of ``job`` may cut (see the module docstring; one pass over its pieces)."""
    surface = _surface_steps(job)
    prev = np.zeros(3, np.int64)
    out = []
    for piece in job.pieces():
        pts = np.asarray(piece.points_steps, np.int64).reshape(-1, 3)
        out.append(_cuts(pts, prev, surface))
        if len(pts):
            prev = pts[-1]
    return np.concatenate(out) if out else np.zeros(0, bool)


@dataclass(frozen=True)
class MoveIndex:
    """The job's move each point of a resumed run completes (see :attr:`JournalBase.move_index`), without an
    array per move: the way in's ``(m,)`` int64 ``head``, then moves ``j, j + 1, ...`` (``n_points`` in all).

    >>> index = MoveIndex(np.array([2, 2]), 3, 4)
    >>> index[1], index[3], len(index), index.tolist()
    (2, 4, 4, [2, 2, 3, 4])
    """

    head: np.ndarray
    j: int
    n_points: int

    def __getitem__(self, i: int) -> int:
        m = len(self.head)
        return int(self.head[i]) if i < m else self.j + int(i) - m

    def __len__(self) -> int:
        return self.n_points

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        m = len(self.head)
        out = np.concatenate([np.asarray(self.head, np.int64), np.arange(self.j, self.j + self.n_points - m,
                                                                         dtype=np.int64)])
        return out if dtype is None else out.astype(dtype)

    def tolist(self) -> list[int]:
        return np.asarray(self).tolist()


_COLUMNS = ("period_ns", "periods", "move_start", "rest")
"""The per-move columns a :class:`~cam.job.model.Job` may leave None."""


@dataclass
class _Stop:
    """What one pass over a job's pieces finds for resuming after move ``k`` (see :func:`_find_stop`).

    Attributes:
        n: moves of the job; j: the first move after ``k`` that cuts (``n``: none); entry: ``(3,)`` its start
            (point ``j - 1``, the home for ``j = 0``); travel_z: the highest Z (<= 0) of the moves that do
            not cut; carried: ``(3,)`` the point of the last pause the stop left pending or skipped (None:
            none), and its note; notes: the notes of the pauses of moves ``j`` on; feed_ns: move ``j``'s
            nominal period (0: none, or the job has no ``period_ns``); columns: the optional per-move columns
            (``period_ns``, ``periods``, ``move_start``, ``rest``) some piece of the job has.
    """

    n: int
    j: int
    entry: np.ndarray
    travel_z: int
    carried: Optional[np.ndarray]
    carried_note: str
    notes: list[str]
    feed_ns: int
    columns: frozenset[str]


def _find_stop(job: JobLike, k: int, pause_pending: bool) -> _Stop:
    """One pass over ``job.pieces()``: where the resumed run after move ``k`` enters the job (frame: the job's).

    Raises:
        CamError: ``k`` lies outside the job.
    """
    surface = _surface_steps(job)
    prev = np.zeros(3, np.int64)
    n, j, travel_z, feed_ns = 0, -1, 0, 0
    columns: set[str] = set()
    entry = np.zeros(3, np.int64)
    carried: Optional[np.ndarray] = None
    carried_note = "Pause At"
    notes: list[str] = []  # the notes of the pauses of moves j on (once j is found)
    for piece in job.pieces():
        pts = np.asarray(piece.points_steps, np.int64).reshape(-1, 3)
        cuts = _cuts(pts, prev, surface)
        if np.any(~cuts):
            travel_z = min(travel_z, int(pts[~cuts, 2].min()))
        pause = np.asarray(piece.pause, bool)
        at = np.flatnonzero(pause)
        piece_notes = list(piece.pause_notes) if piece.pause_notes is not None else []
        piece_notes += ["Pause At"] * (len(at) - len(piece_notes))
        columns.update(name for name in _COLUMNS if getattr(piece, name) is not None)
        end = 0 if j >= 0 else len(pts)  # this piece's moves before j
        if j < 0:
            first = max(0, k + 1 - n)
            later = np.flatnonzero(cuts[first:]) + first
            if len(later):
                end = int(later[0])
                j = n + end
                entry = pts[end - 1].copy() if end >= 1 else prev.copy()
                feed_ns = int(np.asarray(piece.period_ns, np.int64)[end]) if piece.period_ns is not None else 0
        for i_note, i in enumerate(at.tolist()):
            if i >= end:  # a pause of move j on: kept where it is
                notes.append(piece_notes[i_note])
            elif n + i > k or (pause_pending and n + i == k):  # skipped, or left pending: made again
                carried, carried_note = pts[i].copy(), piece_notes[i_note]
        if len(pts):
            prev = pts[-1]
        n += len(pts)
    if not -1 <= k < n:
        raise CamError(f"the last completed move {k} is outside the job's {n} moves")
    if j < 0:  # nothing after the stop cuts: the job's way home
        j, entry = n, prev.copy()
    return _Stop(n, j, entry, travel_z, carried, carried_note, notes, feed_ns, frozenset(columns))


@dataclass
class ResumedJob:
    """The resumed run of a job (a :class:`~cam.job.model.JobLike`): :meth:`pieces` gives the way in, then the
    job's pieces from move ``j`` on, every point relative to where the tool stands (``start_steps``, steps
    from the job's home).  A job in memory gives two pieces; :meth:`joined` is :func:`resume_toolpath`.

    Attributes:
        job: the job resumed (as planned from the start); way_in: steps 1-4 of the module docstring, ``(m,)``
            rows; j: the first move of ``job`` run in full; start_steps: ``(x, y, z)`` where the run starts.
        pause_notes: the notes of the run's pauses; n_moves: its moves; job_moves: the moves of ``job``.
    """

    job: JobLike
    way_in: Job
    j: int
    start_steps: tuple[int, int, int]
    pause_notes: list[str]
    n_moves: int
    job_moves: int
    source: str = ""
    warnings: list[str] = field(default_factory=list)
    pixels: Optional[PixelFrame] = None

    @property
    def settings(self) -> MachineSettings:
        return self.job.settings

    @property
    def safe_z_steps(self) -> int:
        """The Z a stop lifts to, steps from where the run starts (+Z deeper)."""
        return int(self.job.safe_z_steps) - int(self.start_steps[2])

    @property
    def tool(self) -> Any:
        return self.job.tool

    def __len__(self) -> int:
        return self.n_moves

    def joined(self) -> Job:
        """Every move in one :class:`~cam.job.model.Job` (:func:`~cam.job.model.join_pieces` of :meth:`pieces`)."""
        return join_pieces(self.pieces(), self)

    def pieces(self) -> Iterator[Job]:
        """The way in, then the job's moves from ``j`` on (relative to ``start_steps``), each piece's per-move
        columns (feeds, periods, ramp segments, rests) kept."""
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
            columns = {name: None if getattr(piece, name) is None else np.asarray(getattr(piece, name))[cut:]
                       for name in _COLUMNS}
            yield Job(points_steps=np.asarray(piece.points_steps, np.int64).reshape(-1, 3)[cut:] - p0,
                      kind=np.asarray(piece.kind, np.uint8)[cut:], target=np.asarray(piece.target, bool)[cut:],
                      pause=pause[cut:], settings=self.settings, warnings=[], safe_z_steps=self.safe_z_steps,
                      pause_notes=notes, tool=self.tool, **columns)


def resume_pieces(job: JobLike, last_move: int, position_steps: tuple[int, int, int], *,
                  pause_pending: bool = False) -> tuple[ResumedJob, MoveIndex, int]:
    """The resumed run of ``job`` after its move ``last_move``, from ``position_steps`` (module docstring), as
    pieces: one pass over ``job.pieces()`` finds where the run enters the job; the run's pieces are made anew
    on each pass (:class:`ResumedJob`), nothing per move is held.

    Args:
        job: the job as planned from the start (its frame: steps from the job's home); a
            :class:`~cam.job.model.Job` in memory is one piece.
        last_move: index of the last completed move (-1: none).
        position_steps: where the tool stands, steps from the job's home.
        pause_pending: the pause at ``last_move`` (if any) was not answered: it is made again.

    Returns:
        ``(resumed, move_index, j)``: the resumed run (steps relative to ``position_steps``), the move of
        ``job`` each of its points completes, and ``j``, the first move of ``job`` it runs in full.

    Raises:
        CamError: ``last_move`` lies outside the job.
    """
    k = int(last_move)
    p0 = np.asarray(position_steps, np.int64).reshape(3)
    stop = _find_stop(job, k, pause_pending)
    j, s = stop.j, job.settings
    z_t = min(int(p0[2]), int(job.safe_z_steps), stop.travel_z)
    kept = _way_in(p0, k, j, stop.entry, z_t, stop.carried, _surface_steps(job))
    kinds = np.array([it[1] for it in kept], np.uint8)
    m = len(kept)
    columns: dict[str, Optional[np.ndarray]] = dict.fromkeys(_COLUMNS)  # None where the job has none
    if "period_ns" in stop.columns:  # the way in at the machine's speeds; a plunge no faster than move j's feed
        columns["period_ns"] = np.where(kinds == RETRACT, s.delay_z_ns, np.where(
            kinds == CUT, max(s.delay_z_ns, stop.feed_ns), s.delay_xy_ns)).astype(np.int64)
    if "periods" in stop.columns:  # the way in's moves take their longest axis's steps
        columns["periods"] = np.zeros(m, np.int64)
    if "move_start" in stop.columns:  # each move of the way in is its own ramp segment
        columns["move_start"] = np.ones(m, bool)
    if "rest" in stop.columns:
        columns["rest"] = np.zeros(m, bool)
    carried_note = [stop.carried_note] if stop.carried is not None else []
    way_in = Job(points_steps=np.array([it[0] for it in kept], np.int64).reshape(-1, 3) - p0, kind=kinds,
                 target=np.zeros(m, bool), pause=np.array([it[2] for it in kept], bool), settings=s, warnings=[],
                 safe_z_steps=int(job.safe_z_steps) - int(p0[2]), pause_notes=carried_note, tool=job.tool, **columns)
    source = f"{job.source} (resumed at move {j})" if job.source else f"resumed at move {j}"
    n_moves = m + stop.n - j
    resumed = ResumedJob(job, way_in, j, tuple(int(v) for v in p0), carried_note + stop.notes,  # type: ignore[arg-type]
                         n_moves, stop.n, source=source)
    return resumed, MoveIndex(np.array([it[3] for it in kept], np.int64), j, n_moves), j


def resume_toolpath(job: JobLike, last_move: int, position_steps: tuple[int, int, int], *,
                    pause_pending: bool = False) -> tuple[Job, np.ndarray, int]:
    """The resumed run of ``job`` in memory: :func:`resume_pieces`, joined (see the module docstring).

    Args:
        job: the job as planned from the start (its frame: steps from the job's home), in memory or in pieces.
        last_move: index of the last completed move (-1: none).
        position_steps: where the tool stands, steps from the job's home.
        pause_pending: the pause at ``last_move`` (if any) was not answered: it is made again.

    Returns:
        ``(resumed, move_index, j)``: the resumed :class:`Job` (steps relative to ``position_steps``), the
        ``(M,)`` move of ``job`` each of its points completes, and ``j``, the first move of ``job`` it runs in full.

    >>> from cam.job.model import travel_job
    >>> import numpy as np
    >>> pts = np.array([[0, 0, -5], [10, 0, -5], [10, 0, 3], [20, 0, 3], [20, 0, -5]])
    >>> job = travel_job(pts, MachineSettings()); job.kind[2:4] = CUT
    >>> r, index, j = resume_toolpath(job, 2, (14, 0, 0))      # stopped (lifted) during move 3
    >>> j, (r.points_steps + (14, 0, 0)).tolist(), index.tolist()
    (3, [[14, 0, -5], [10, 0, -5], [10, 0, 3], [20, 0, 3], [20, 0, -5]], [2, 2, 2, 3, 4])
    """
    resumed, move_index, j = resume_pieces(job, last_move, position_steps, pause_pending=pause_pending)
    return resumed.joined(), np.asarray(move_index), j


def _surface_steps(job: Any) -> int:
    """The machine z of a job's surface (a drawing's Start At Z; 0 for other jobs)."""
    return job.pixels.origin_px[2] * job.pixels.steps_per_px_z if job.pixels is not None else 0


def _way_in(p0: np.ndarray, k: int, j: int, entry: np.ndarray, z_t: int, pause_q: Optional[np.ndarray],
            surface: int) -> list[tuple[np.ndarray, int, bool, int]]:
    """Steps 1-4 of the module docstring: ``(point, kind, pause, move index)`` from where the tool stands ``p0``
    to the entry point ``entry`` of move ``j`` (the last completed move ``k``), at the travel height ``z_t``,
    pausing above ``pause_q`` (a pause the stop left or skipped; None: none).  Moves of length 0 are left out
    (but a pause's point, and the entry, are kept)."""
    prefix: list[tuple[np.ndarray, int, bool, int]] = []
    if p0[2] > z_t:
        prefix.append((np.array([p0[0], p0[1], z_t]), RETRACT, False, k))
    if pause_q is not None:
        prefix.append((np.array([pause_q[0], pause_q[1], z_t]), TRAVEL, True, k))
    if entry[2] == z_t:
        prefix.append((entry.copy(), TRAVEL, False, j - 1))
    else:
        prefix.append((np.array([entry[0], entry[1], z_t]), TRAVEL, False, k))
        prefix.append((entry.copy(), CUT if entry[2] > surface else TRAVEL, False, j - 1))
    kept: list[tuple[np.ndarray, int, bool, int]] = []
    at = p0
    for item in prefix:
        if item[2] or not np.array_equal(item[0], at) or item is prefix[-1]:
            kept.append(item)
            at = item[0]
    return kept


def _cuts(pts: np.ndarray, prev: np.ndarray, surface: int) -> np.ndarray:
    """``(N,)`` bool: which moves to ``pts`` (N, 3) from ``prev`` (3,) and on may cut (module docstring)."""
    before = np.vstack([prev.reshape(1, 3), pts[:-1]]) if len(pts) else pts
    above = np.maximum(before[:, 2], pts[:, 2]) <= surface
    up = np.all(before[:, :2] == pts[:, :2], axis=1) & (pts[:, 2] <= before[:, 2])
    return ~(above | up)


def last_completed(point_write: np.ndarray, writes_done: int) -> int:
    """Index of the last point reached after ``writes_done`` port writes (-1: none), from a plan's ``point_write``.

    Never ahead of the machine: a point counts once the write that reaches it was sent.

    >>> last_completed(np.array([2, 4, 4, 8]), 5), last_completed(np.array([2, 4]), 2)
    (2, -1)
    """
    return int(np.searchsorted(np.asarray(point_write, np.int64), int(writes_done), side="left")) - 1


def journal_record(base: JournalBase, point_write: np.ndarray, pause_writes: set[int], writes_done: int,
                   writes_total: int, position_steps: tuple[int, int, int], state: str,
                   home_steps: tuple[int, int, int] = (0, 0, 0)) -> Journal:
    """The journal of a run after ``writes_done`` of its ``writes_total`` writes.

    Args:
        base: the job and where the run started in it.
        point_write: ``(M,)`` the run's plan's write index at which each of its points is reached, or what
            stands for it in a streamed plan (an object with ``last_completed(writes_done)``).
        pause_writes: the writes after which the run pauses.
        position_steps: where the tool stands now, steps from the *run's* start (added to
            ``base.start_position_steps``).
        state: one of :data:`JOURNAL_STATES`.
    """
    i = point_write.last_completed(writes_done) if not isinstance(point_write, np.ndarray) else \
        last_completed(point_write, writes_done)
    if i < 0:
        last, pending = base.last_move, base.pause_pending
    else:
        last = int(base.move_index[i]) if base.move_index is not None else i
        pending = (writes_done - 1) in pause_writes and writes_done < writes_total
    if state == "finished":
        last, pending = base.moves - 1, False
    start = np.asarray(base.start_position_steps, np.int64)
    pos = tuple(int(v) for v in start + np.asarray(position_steps, np.int64))
    return Journal(identity=base.identity, plan_sha256=base.plan_sha256, source=base.source, moves=base.moves,
                   last_move=int(last), position_steps=pos, state=state, pause_pending=bool(pending),  # type: ignore[arg-type]
                   writes_done=int(writes_done), writes_total=int(writes_total),
                   home_steps=tuple(int(v) for v in home_steps),  # type: ignore[arg-type]
                   resumed_at_move=base.resumed_at_move, start_position_steps=tuple(int(v) for v in start))  # type: ignore[arg-type]


def resume_start(journal: Journal, state: Any, *, where: str = "journal",
                 reported_stop_steps: Optional[tuple[int, int, int]] = None) -> tuple[int, int, int]:
    """Where a resumed run of ``journal`` starts, steps from the job's home (issue #43 point 7).

    A closed journal (its run's last write: stopped, emergency-stopped, failed) holds the position the run ended
    at: its own.  A journal still ``running`` was left by a run that ended without its last write (killed, or its
    disk filled): it may be behind what was sent, so its position is not trusted; the run goes on from where the
    machine ``state`` (a :class:`cam.drive.state.MachineState`, machine frame) has the tool, which must be known:
    recorded at the stop, or set since by homing or ``cam where --set``.  ``reported_stop_steps``: where the machine reported the tool at the stop
    (machine frame), when the state file recorded one, for the message.

    Raises:
        CamError: a journal that may be behind, and the position unknown (one line: where the journal
            says, where the machine reported the stop when known, and how to make it known).
    """
    if journal.state != "running":
        return tuple(int(v) for v in journal.position_steps)  # type: ignore[return-value]
    home = tuple(int(v) for v in journal.home_steps)
    if state.position_known:
        return tuple(int(p) - h for p, h in zip(state.position_steps, home))  # type: ignore[return-value]
    said = [int(p) + h for p, h in zip(journal.position_steps, home)]
    reported = "" if reported_stop_steps is None else \
        f"; the machine reported the stop at machine {[int(v) for v in reported_stop_steps]} steps"
    raise CamError(
        f"journal {where} was not closed (its run ended without its last write: killed, or its disk filled), so "
        f"where it says the tool stands, machine {said} steps, may be behind the stop; the machine position is "
        f"unknown ({state.unknown_reason or 'not recorded'}){reported}: home the machine (cam home) or say where the "
        f"tool is (cam where --set X,Y,Z, machine mm), then resume again: it goes on from there")
