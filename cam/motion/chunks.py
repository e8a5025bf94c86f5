"""The step plan as a stream of chunks: every port write of a job, in bounded memory.

:func:`plan_steps` holds every write of a job at once (about
100 bytes per step period with the look-ahead ramps): a large job does not fit.
A :class:`ChunkedPlan` makes the same writes a chunk at a time:

1. the moves are turned into step periods a stretch of at most
   ``chunk_periods`` at a time (:func:`cam.motion.kernels.stretch_kernel`,
   the DDA of :mod:`cam.motion.steps` resumed inside a move);
2. the speed ramps lengthen them: ``constant`` keeps the nominal periods,
   ``linear40`` ramps each source move from its length and step counts (known
   from the moves, so a move may span chunks), ``lookahead`` plans a *window*:
   the chunk and ``margin_periods`` periods on each side, or up to the
   nearest rest when it is closer (nothing is planned across a rest), and
   keeps the chunk.  The margin is many times the longest ramp (the periods a
   stop from full speed takes, :func:`lookahead_margin`), so the chunk's
   periods are those of the whole-job planner: a ramp that must slow down
   before a stop in the next chunk starts in this one.  Tests check the
   identity on jobs whose chunk boundaries fall inside ramps;
3. the writes follow (:func:`cam.motion.kernels.chunk_writes_kernel`) with
   absolute times and write indices.

Memory: the job's points and a few per-move integers (``n_per_move``), plus
one window of periods; it does not grow with the number of step periods.
"""
from __future__ import annotations

import collections
import concurrent.futures
import ctypes
import math
from dataclasses import dataclass, field
from typing import Iterator, Optional

import numpy as np

from ..job.model import Job, JobLike, PlanFingerprint, TravelSpan, check_span, check_travel
from ..settings import MachineSettings
from .kernels import chunk_writes_kernel, move_extent_kernel, move_periods_kernel, stretch_kernel
from ..pins import axis_bits
from .ramps import _lookahead, linear40_periods

__all__ = ["StepChunk", "StepPlan", "ChunkedPlan", "plan_chunks", "plan_steps", "lookahead_margin", "move_extent",
           "DEFAULT_CHUNK_PERIODS"]

DEFAULT_CHUNK_PERIODS = 1 << 18
"""Step periods per chunk (a few tens of MB of writes, look-ahead and decoding arrays at most)."""

_MOVE_BLOCK = 1 << 16  # moves turned into periods per kernel call


@dataclass
class StepChunk:
    """Consecutive port writes of a job.

    Attributes:
        first_write: index of ``t_ns[0]`` among all the job's writes.
        t_ns: ``(M,)`` int64 scheduled times, ns from the job start.
        data: ``(M,)`` uint8 data register after each write.
        strobe: ``(M,)`` uint8 level of pin 1 after each write.
    """

    first_write: int
    t_ns: np.ndarray
    data: np.ndarray
    strobe: np.ndarray

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass
class StepPlan:
    """All port writes of a job.

    Attributes:
        t_ns: ``(M,)`` int64 scheduled time of each write, ns from the job start (non-decreasing).
        data: ``(M,)`` uint8 data register (pins 2..9) after each write.
        strobe: ``(M,)`` uint8 level of pin 1 after each write.
        point_write: ``(N,)`` int64 index of the write at which toolpath point i is reached.
        pause_writes: ``(P,)`` int64 write indices after which the job pauses (Pause At).
        steps_total: ``(3,)`` int64 steps made by X, Y, Z (absolute).
        settings: the machine settings.
        end_steps: machine position (x, y, z) in steps after the last write.
        safe_z_steps: Z a stop lifts the tool to (the surface or above it).
        pause_notes: what each pause is for (same order as ``pause_writes``), e.g. a tool change.
    """

    t_ns: np.ndarray
    data: np.ndarray
    strobe: np.ndarray
    point_write: np.ndarray
    pause_writes: np.ndarray
    steps_total: np.ndarray
    settings: MachineSettings
    end_steps: tuple[int, int, int] = (0, 0, 0)
    safe_z_steps: int = 0
    pause_notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def estimated_time_s(self) -> float:
        """Machine time of the job in seconds (pauses excluded)."""
        return float(self.t_ns[-1]) / 1e9 if len(self.t_ns) else 0.0

    def chunks(self) -> Iterator[StepChunk]:
        """The writes as one chunk (what the runner sends, as :meth:`ChunkedPlan.chunks`)."""
        yield StepChunk(0, self.t_ns, self.data, self.strobe)


class _RecentMoves:
    """The ``point_write`` of the move blocks a pass over a :class:`ChunkedPlan` made lately: enough to say which
    move a run's writes completed (its journal) without an array per move.  Older blocks are dropped as new
    ones come, keeping at least the moves of the look-ahead and the chunks made ahead of the writes sent
    (a run is never further behind the pass than that: each move takes a period at least)."""

    def __init__(self, plan: "ChunkedPlan") -> None:
        self.plan = plan
        self.blocks: list[tuple[int, np.ndarray]] = []  # (first move, (B,) point_write)

    def add(self, first_move: int, point_write: np.ndarray) -> None:
        if not len(point_write):
            return
        lag_moves = 4 * self.plan.chunk_periods + 2 * self.plan.margin_periods
        while len(self.blocks) > 1 and sum(len(b[1]) for b in self.blocks[1:]) > lag_moves:
            del self.blocks[0]
        self.blocks.append((int(first_move), np.asarray(point_write, np.int64)))

    def last_completed(self, writes_done: int) -> int:
        """Index of the last move reached after ``writes_done`` writes (-1: none), as
        :func:`cam.job.resume.last_completed`; never ahead (a move before the blocks kept counts as the last
        one before them)."""
        blocks = list(self.blocks)
        for first, pw in reversed(blocks):
            if int(pw[0]) < writes_done:
                return first + int(np.searchsorted(pw, int(writes_done), side="left")) - 1
        return blocks[0][0] - 1 if blocks else -1


def _per_move(piece: Job, pts: np.ndarray, prev: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(n_per_move, nominal_ns, steps)`` of the moves to ``(B, 3)`` points ``pts`` from ``(1, 3)`` ``prev``:
    ``(B,)`` int64 periods each takes and its nominal period (0: the settings' delays), ``(3,)`` steps per axis."""
    npm, steps = move_periods_kernel(np.ascontiguousarray(pts, np.int64), np.asarray(prev, np.int64).reshape(3))
    if piece.periods is not None:
        npm = np.maximum(npm, np.asarray(piece.periods, np.int64))
    nom = np.zeros(len(pts), np.int64) if piece.period_ns is None else np.asarray(piece.period_ns, np.int64)
    return npm, nom, steps


def move_extent(pts: np.ndarray, n_per_move: np.ndarray, extent: np.ndarray, cut: np.ndarray) -> None:
    """Widen ``extent`` and ``cut`` (each ``(3, 2)`` int64 min/max in steps, in place) by the positions the
    DDA takes the tool through on the moves between rows of ``pts``, as decoding their writes would.

    Args:
        pts: ``(B + 1, 3)`` int64 positions in steps (+Z deeper), the point before the moves first.
        n_per_move: ``(B,)`` int64 periods of each move; after period k of n an axis of a move of ``ad``
            steps has made ``floor(k ad / n)`` of them (:func:`cam.motion.kernels.stretch_kernel`).
        extent: every position; cut: the positions below the surface (z > 0).

    Every axis moves one way within a move, so the positions' extent is the points'.  A move with both
    ends below the surface is cut whole; one that crosses it is cut from (or up to) the period at which its
    Z passes from 0 to 1, and its X and Y there follow from the same floor.
    """
    move_extent_kernel(np.ascontiguousarray(pts, np.int64), np.ascontiguousarray(n_per_move, np.int64), extent, cut)


def lookahead_margin(settings: MachineSettings, min_period_ns: int) -> int:
    """Periods of look-ahead a chunk needs on each side: eight times the longest ramp plus the longest
    interval at which an axis still runs above its start speed (the ramp planner's reach), at least 4096.

    The longest ramp: from rest to the fastest rate ``u = 1e9 / min_period_ns`` periods/s at the smallest
    path acceleration ``0.9 A / s`` (periods/s^2) takes ``u^2 / (2 alpha)`` periods.
    """
    s_mm, v_start, _, acc = settings.axis_limits()
    u_max = 1e9 / max(1, int(min_period_ns))
    alpha = min(0.9 * a / s for a, s in zip(acc, s_mm))
    ramp = u_max * u_max / (2.0 * alpha)
    reach = max(s * u_max / v for s, v in zip(s_mm, v_start))
    return int(max(4096, 8 * math.ceil(ramp + reach + 2)))


def _move_blocks_of(pts: np.ndarray, prev: np.ndarray) -> Iterator[tuple[int, int, np.ndarray]]:
    """``(b0, b1, block)`` of the moves to ``(B, 3)`` points ``pts`` from ``(1, 3)`` ``prev``, at most
    ``_MOVE_BLOCK`` at a time: ``block`` ``(b1 - b0 + 1, 3)`` is the point before ``pts[b0]``, then ``pts[b0:b1]``."""
    for b0 in range(0, len(pts), _MOVE_BLOCK):
        b1 = min(len(pts), b0 + _MOVE_BLOCK)
        yield b0, b1, np.vstack([pts[b0 - 1:b0] if b0 else prev, pts[b0:b1]])


def _constant_time_ns(pts: np.ndarray, npm: np.ndarray, nom: np.ndarray, s: MachineSettings) -> int:
    """Machine time of ``(B,)`` moves with constant ramps: ``pts`` ``(B + 1, 3)`` the point before them, then theirs;
    each move's periods at its nominal length, else the settings' delay for the axes it moves."""
    d = pts[1:] - pts[:-1]
    xy, z = (d[:, 0] != 0) | (d[:, 1] != 0), d[:, 2] != 0
    per = np.where(xy & z, max(s.delay_xy_ns, s.delay_z_ns), np.where(xy, s.delay_xy_ns, s.delay_z_ns))
    return int((npm * np.where(nom > 0, nom, per)).sum())


class _Reach:
    """Where a job's moves take the tool (:func:`move_extent`) and, with constant ramps, their machine time: worked
    out from the moves in the pass of :func:`plan_chunks`, so no later pass over the job is needed for them."""

    def __init__(self, settings: MachineSettings) -> None:
        self.settings = settings
        self.extent = np.zeros((3, 2), np.int64)
        big = np.iinfo(np.int64).max
        self.cut = np.array([[big, -big]] * 3, np.int64)
        self.time_ns = 0

    def add(self, pts: np.ndarray, npm: np.ndarray, nom: np.ndarray, prev: np.ndarray) -> None:
        """The moves to ``(B, 3)`` points ``pts`` from ``(1, 3)`` ``prev``, ``(B,)`` periods and nominal periods."""
        for b0, b1, block in _move_blocks_of(pts, prev):
            self.add_block(block, npm[b0:b1], nom[b0:b1])

    def add_block(self, pts: np.ndarray, npm: np.ndarray, nom: np.ndarray) -> None:
        """``(B,)`` moves: ``pts`` ``(B + 1, 3)`` the point before them, then theirs; their periods and nominal
        periods."""
        move_extent(pts, npm, self.extent, self.cut)
        if self.settings.ramp == "constant":
            self.time_ns += _constant_time_ns(pts, npm, nom, self.settings)

    def extent_and_cut(self) -> tuple[np.ndarray, np.ndarray]:
        """As :meth:`ChunkedPlan.motion_extent`."""
        return self.extent, self.cut if self.cut[0, 0] != np.iinfo(np.int64).max else np.zeros((3, 2), np.int64)


_ALLOCATOR_TUNED = False


def _keep_freed_memory() -> None:
    """Ask glibc's allocator (once per process) to keep freed blocks of up to 128 MB for the next ones instead of
    handing them back to the system: each chunk and look-ahead window makes a dozen arrays of megabytes, and fresh
    pages (mapped, zeroed and faulted in by the kernel) were a third of the planner's time (the two-pen benchmark
    job: 5.4M -> 7.3M periods/s, peak RSS 301 -> 332 MB).  Every thread allocates from the one heap: glibc gave
    each thread that allocates its own, and each kept freed blocks of its own (the two-pen job on a machine file of
    long ramps: peak RSS 480 -> 463 MB, 575 MB before the planner held less).  Elsewhere than Linux with glibc:
    nothing."""
    global _ALLOCATOR_TUNED
    if _ALLOCATOR_TUNED:
        return
    _ALLOCATOR_TUNED = True
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-8, 1)  # M_ARENA_MAX: every thread allocates from the one heap
        libc.mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD: blocks under 32 MB come from the heap
        libc.mallopt(-1, 128 << 20)  # M_TRIM_THRESHOLD: up to 128 MB freed at the heap's top stay for reuse
    except (OSError, AttributeError):
        pass


_WINDOW_POOL: Optional[concurrent.futures.ThreadPoolExecutor] = None  # made on first use
_PARALLEL_WINDOW_PERIODS = 1 << 20
_WINDOWS_AHEAD = 2
"""Look-ahead windows planned while a chunk is handed out (the two-pen benchmark job: 8.3M periods/s with one,
8.9M with two, means of seven runs taken by turns; peak RSS 237 -> 251 MB)."""
"""Look-ahead windows up to this many periods are planned two at a time (:meth:`ChunkedPlan._windows`)."""


def _window_pool() -> concurrent.futures.ThreadPoolExecutor:
    """Two threads that plan look-ahead windows (:meth:`ChunkedPlan._windows`)."""
    global _WINDOW_POOL
    if _WINDOW_POOL is None:
        _WINDOW_POOL = concurrent.futures.ThreadPoolExecutor(2, thread_name_prefix="cam-window")
    return _WINDOW_POOL


@dataclass
class ChunkedPlan:
    """A job's step plan made a chunk at a time (see the module docstring); every step plan is one
    (:func:`plan_steps` is its chunks joined).

    Attributes:
        job: the job (a :class:`~cam.job.model.JobLike`: points in steps from where the tool stands at the
            start), read a piece at a time on each pass.
        settings: the machine settings.
        n_periods: step periods of the job; its writes number ``1 + 2 n_periods``.
        pause_writes: ``(P,)`` int64 write indices after which the job pauses.
        pause_notes, warnings, safe_z_steps, end_steps, steps_total: as :class:`~cam.motion.steps.StepPlan`.
        chunk_periods: step periods per chunk; margin_periods: look-ahead periods on each side of a chunk.
        any_move_start: whether some piece marks where source moves begin (``linear40`` ramps); if none
            does, the job is one ramp segment from its first move, as the whole-job ramp planner takes it.
        job_sha256: the job's :func:`cam.job.resume.plan_fingerprint` when :func:`plan_chunks` was asked for it,
            else None.
    """

    job: JobLike
    settings: MachineSettings
    n_periods: int
    pause_writes: np.ndarray
    steps_total: np.ndarray
    end_steps: tuple[int, int, int]
    safe_z_steps: int
    chunk_periods: int
    margin_periods: int
    pause_notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    any_move_start: bool = True
    _stops: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)
    job_sha256: Optional[str] = None
    _time_ns: Optional[int] = field(default=None, repr=False)
    _extent: Optional[tuple[np.ndarray, np.ndarray]] = field(default=None, repr=False)
    recent: Optional[_RecentMoves] = field(default=None, repr=False)
    """The moves of the blocks the latest pass over :meth:`chunks` made lately (one per plan)."""

    @property
    def point_write(self) -> _RecentMoves:
        """Which move a run's writes completed (``last_completed(writes_done)``), from the blocks of the latest
        pass over :meth:`chunks`: nothing per move is held.  :meth:`full_point_write` has every move's."""
        return self._recent_moves()

    def _recent_moves(self) -> _RecentMoves:
        if self.recent is None:
            self.recent = _RecentMoves(self)
        return self.recent

    def full_point_write(self) -> np.ndarray:
        """``(N,)`` int64 index of the write at which toolpath point i is reached (one pass over the moves)."""
        parts, period0 = [], 0
        for _, npm, _, _, _ in self._move_blocks():
            parts.append(2 * (period0 + np.cumsum(npm)))
            period0 += int(npm.sum())
        return np.concatenate(parts) if parts else np.zeros(0, np.int64)

    def __len__(self) -> int:
        return 1 + 2 * self.n_periods

    @property
    def estimated_time_s(self) -> float:
        """Machine time of the job in seconds (pauses excluded): one pass over the chunks, then kept."""
        if self._time_ns is None:
            self._time_ns = self._machine_time_ns()
        return self._time_ns / 1e9

    def motion_extent(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the writes take the tool, as :func:`cam.verify.pinlog.motion_extent`: ``(extent, cut)``, each
        ``(3, 2)`` int64 min/max position in steps (the start included; ``cut``: below the surface, z > 0).

        From the moves, not the writes (:func:`move_extent`): within a move each axis moves one way, so the
        extent is that of the points, and a move that crosses the surface is cut from the period its DDA
        crosses it.  One pass over the job's pieces; kept.
        """
        if self._extent is None:  # (plan_chunks gives it from its own pass)
            self._extent = self._reach().extent_and_cut()
        return self._extent

    def _reach(self) -> _Reach:
        """One pass over the moves: their extent and constant-ramp machine time (:class:`_Reach`)."""
        reach = _Reach(self.settings)
        for pts, npm, nom, _, _ in self._move_blocks():
            reach.add_block(pts, npm, nom)
        return reach

    def _machine_time_ns(self) -> int:
        """The job's machine time: the constant ramps' from the moves, else one pass over the ramped periods
        (no writes made)."""
        if self.settings.ramp == "constant":
            return self._reach().time_ns
        return sum(int(per.sum()) for _, _, per in self._ramped())

    # -- the stream ------------------------------------------------------------------------------------
    def _move_blocks(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray]]:
        """``(pts, n_per_move, nominal_ns, first_move, move_start)`` of consecutive blocks of at most
        ``_MOVE_BLOCK`` moves, read from the job's pieces: ``pts`` ``(B + 1, 3)`` int64, the point before the
        block then its points; ``(B,)`` int64 periods and nominal period of each move; ``(B,)`` bool, where a
        ramp segment of the ``linear40`` mode begins."""
        prev = np.zeros((1, 3), np.int64)
        first = 0
        for piece in self.job.pieces():
            p = np.asarray(piece.points_steps, np.int64).reshape(-1, 3)
            npm, nom, _ = _per_move(piece, p, prev)
            if not self.any_move_start:
                starts = np.zeros(len(p), bool)
                starts[:1] = first == 0
            elif piece.move_start is None:
                starts = np.ones(len(p), bool)
            else:
                starts = np.asarray(piece.move_start, bool)
            for b0, b1, block in _move_blocks_of(p, prev):
                yield block, npm[b0:b1], nom[b0:b1], first + b0, starts[b0:b1]
            if len(p):
                prev = p[-1:]
            first += len(p)

    def _stretches(self, segment_starts: Optional[list[int]] = None
                   ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """``(high, dirs, nominal_ns)`` of consecutive periods, at most ``chunk_periods`` each.

        Notes each block's ``point_write`` in :attr:`recent` as it goes (the run's journal), and appends the
        first period of each ``linear40`` ramp segment to ``segment_starts`` before that block's periods come."""
        s = self.settings
        clock, dirbit = axis_bits(s)
        clock, dirbit = clock.astype(np.int64), dirbit.astype(np.int64)
        dir_state = np.zeros(3, np.int64)
        recent = self._recent_moves()
        recent.blocks = []
        period0 = 0
        for pts, npm, nom, first, starts in self._move_blocks():
            point_period = period0 + np.cumsum(npm)
            recent.add(first, 2 * point_period)
            if segment_starts is not None:
                segment_starts.extend(int(v) for v in (point_period - npm)[starts])
            period0 = int(point_period[-1]) if len(npm) else period0
            i, k = 0, 0
            while i < len(npm):
                high, dirs, per, i, k = stretch_kernel(pts, s.delay_xy_ns, s.delay_z_ns, clock, dirbit, npm, nom,
                                                       dir_state, i, k, self.chunk_periods)
                if len(per):
                    yield high, dirs, per

    def _rebatched(self, segment_starts: Optional[list[int]] = None
                   ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """:meth:`_stretches` joined into stretches of exactly ``chunk_periods`` (the last one shorter)."""
        parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        have = 0
        for part in self._stretches(segment_starts):
            parts.append(part)
            have += len(part[2])
            while have >= self.chunk_periods:  # (one part, as a whole chunk's stretch most often is: no copy)
                joined = list(parts[0]) if len(parts) == 1 else [np.concatenate([p[j] for p in parts])
                                                                 for j in range(3)]
                c = self.chunk_periods
                yield joined[0][:c], joined[1][:c], joined[2][:c]
                parts = [(joined[0][c:], joined[1][c:], joined[2][c:])]
                have -= c
        if have:
            yield tuple(np.concatenate([p[j] for p in parts]) for j in range(3))  # type: ignore[misc]

    def _ramped(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """``(high, dirs, period_ns)`` of consecutive periods with the speed ramps, a chunk at a time."""
        mode = self.settings.ramp
        if mode == "constant":
            yield from self._rebatched()
        elif mode == "linear40":
            yield from self._linear40()
        else:
            yield from self._windows()

    def _linear40(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """The seed's per-move ramp (:func:`cam.motion.ramps.linear40_periods`), a closed ramp segment at a time:
        the periods of a segment are held until the next one begins (a source move's periods at most)."""
        starts: list[int] = []
        s_mm, v_start, _, _ = self.settings.axis_limits()
        clock, _ = axis_bits(self.settings)
        buf: list[np.ndarray] = [np.zeros(0, np.uint8), np.zeros(0, np.uint8), np.zeros(0, np.int64)]
        buf_start = 0  # global period index of buf[.][0]
        used = 0  # segment starts before this index in ``starts`` lie before buf_start
        stretches = self._rebatched(starts)
        while True:
            nxt = next(stretches, None)
            if nxt is not None:
                buf = [np.concatenate([buf[j], nxt[j]]) for j in range(3)]
            buf_end = buf_start + len(buf[2])
            known = [b for b in starts[used:] if b <= buf_end]
            end = buf_end if nxt is None else (known[-1] if known else buf_start)
            if end > buf_start:
                firsts = np.array([b - buf_start for b in known if b < end], np.int64)
                n = end - buf_start
                per = linear40_periods(buf[0][:n], buf[2][:n], firsts, clock, s_mm, v_start)
                yield buf[0][:n], buf[1][:n], per
                buf = [v[n:] for v in buf]
                buf_start = end
                used += len(firsts)
            if nxt is None:
                return

    def _windows(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Look-ahead ramps a chunk at a time, each planned in a window with ``margin_periods`` on each side.

        Windows are planned independently of each other, so the next two are planned by two other threads (the
        compiled planner lets go of the GIL) while this one's chunk is handed out, and only one at a time when a
        window is longer than :data:`_PARALLEL_WINDOW_PERIODS` (long ramps: the planner's memory, about 84 bytes
        a period, is then that of one window).
        """
        pending: collections.deque = collections.deque()
        for high, dirs, window_high, window_per, inner, keep in self._window_tasks():
            while pending and len(window_per) > _PARALLEL_WINDOW_PERIODS:
                yield self._planned(pending.popleft())
            pending.append((_window_pool().submit(_lookahead, window_high, window_per, self.settings, inner), high,
                            dirs, keep))
            if len(pending) > _WINDOWS_AHEAD:
                yield self._planned(pending.popleft())
        while pending:
            yield self._planned(pending.popleft())

    @staticmethod
    def _planned(task: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        future, high, dirs, (a, b) = task
        return high, dirs, future.result()[a:b]

    def _window_tasks(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                              tuple[int, int]]]:
        """``(high, dirs, window_high, window_nominal_ns, window_stops, (a, b))`` of each chunk: its periods, the
        window's around them and the rests inside it, and where the chunk lies in the window."""
        c, m = self.chunk_periods, self.margin_periods
        buf: list[np.ndarray] = [np.zeros(0, np.uint8), np.zeros(0, np.uint8), np.zeros(0, np.int64)]
        buf_start = 0  # global period index of buf[.][0]
        done = 0  # periods handed out
        stretches = self._rebatched()
        finished = False
        while True:
            lo, hi = self._window_ends(done - m, done, done + c, done + c + m)  # this chunk's window, at most
            drop = max(0, lo - buf_start)  # nothing before it is needed again
            if drop:
                buf = [v[drop:] for v in buf]
                buf_start += drop
            while not finished and buf_start + len(buf[2]) < hi:  # read no further than it
                nxt = next(stretches, None)
                if nxt is None:
                    finished = True
                    break
                buf = [np.concatenate([buf[j], nxt[j]]) for j in range(3)]
            buf_end = buf_start + len(buf[2])
            if done >= buf_end:
                return
            kept_end = min(done + c, buf_end)
            w0, w1 = max(buf_start, lo), min(buf_end, hi)
            a, b = w0 - buf_start, w1 - buf_start
            inner = self._stops[(self._stops > w0) & (self._stops < w1)] - w0
            ka, kb = done - buf_start, kept_end - buf_start
            yield buf[0][ka:kb], buf[1][ka:kb], buf[0][a:b], buf[2][a:b], inner, (done - w0, kept_end - w0)
            done = kept_end

    def _window_ends(self, w0: int, done: int, kept_end: int, w1: int) -> tuple[int, int]:
        """The window ``[w0, w1)`` around the chunk ``[done, kept_end)`` (periods), each end brought in to the
        nearest rest outside the chunk (a pause, a tool change, a stop of every axis) when there is one within
        the margin: the passes start again at a rest and no rule judges an interval or a pair across one, so
        what lies beyond a rest changes nothing before it, and the window's end is a rest to it as it is to the
        whole job.  A job of frequent rests is then planned in windows about the size of its chunks whatever
        the machine's ramps (a machine file of long ramps has margins of a million periods)."""
        stops = self._stops
        i = int(np.searchsorted(stops, done, "right"))  # the last rest at or before the chunk's start
        if i and stops[i - 1] > w0:
            w0 = int(stops[i - 1])
        k = int(np.searchsorted(stops, kept_end, "left"))  # the first rest at or after its end
        if k < len(stops) and stops[k] < w1:
            w1 = int(stops[k])
        return w0, w1

    def chunks(self) -> Iterator[StepChunk]:
        """The job's writes in order, a chunk at a time (the first holds the initial write at t = 0)."""
        _keep_freed_memory()
        strobe_level = 1 if self.settings.half_step else 0
        t = 0
        first_write = 0
        pending = None
        for high, dirs, per in self._ramped():
            if pending is None:
                t_ns = np.zeros(1, np.int64)
                data = np.array([dirs[0]], np.uint8)
                yield StepChunk(0, t_ns, data, np.full(1, strobe_level, np.uint8))
                first_write = 1
            else:
                yield_chunk, t = self._writes(*pending, int(dirs[0]), t, first_write, strobe_level)
                first_write += len(yield_chunk)
                yield yield_chunk
            pending = (high, dirs, per)
        if pending is None:
            yield StepChunk(0, np.zeros(1, np.int64), np.zeros(1, np.uint8), np.full(1, strobe_level, np.uint8))
            return
        last, t = self._writes(*pending, int(pending[1][-1]), t, first_write, strobe_level)
        if self._time_ns is None:
            self._time_ns = t  # a whole pass gives the machine time for free
        yield last

    @staticmethod
    def _writes(high: np.ndarray, dirs: np.ndarray, per: np.ndarray, next_dirs: int, t0: int, first_write: int,
                strobe_level: int) -> tuple[StepChunk, int]:
        t_ns, data = chunk_writes_kernel(np.asarray(high, np.uint8), np.asarray(dirs, np.uint8),
                                         np.asarray(per, np.int64), np.uint8(next_dirs), np.int64(t0))
        return StepChunk(first_write, t_ns, data, np.full(len(t_ns), strobe_level, np.uint8)), int(t0 + per.sum())

    def to_plan(self) -> StepPlan:
        """Every write at once: the chunks joined (:func:`plan_steps`; small jobs, tests)."""
        parts = list(self.chunks())
        return StepPlan(
            t_ns=np.concatenate([p.t_ns for p in parts]), data=np.concatenate([p.data for p in parts]),
            strobe=np.concatenate([p.strobe for p in parts]), point_write=self.full_point_write(),
            pause_writes=self.pause_writes, steps_total=self.steps_total, settings=self.settings,
            end_steps=self.end_steps, safe_z_steps=self.safe_z_steps, pause_notes=list(self.pause_notes),
            warnings=list(self.warnings))


def plan_chunks(job: JobLike, *, start_steps: Optional[tuple[int, int, int]] = (0, 0, 0),
                chunk_periods: int = DEFAULT_CHUNK_PERIODS, margin_periods: Optional[int] = None,
                fingerprint: bool = False) -> ChunkedPlan:
    """The step plan of a job of any size, made a chunk at a time (:class:`ChunkedPlan`).

    One pass over the job's pieces checks every point against the travel and counts what the plan needs
    (periods, pauses, rests, steps); nothing per move or per period is kept.

    Args:
        job: the moves, in steps relative to where the tool stands when it starts (any
            :class:`~cam.job.model.JobLike`: a :class:`~cam.job.model.Job` is one piece).
        start_steps: where the tool stands in the machine frame (the job is checked against the travel).  None:
            the job is planned in its own frame and placed when it runs (a drawing, a relief, a file placed by its
            extent: :func:`cam.kinds.jobs.prepare_job`): checked here to fit the travel's span
            (:class:`~cam.job.model.TravelSpan`), and in the machine frame where it is placed (the session checks
            the plan's extent from where it starts).
        chunk_periods: step periods per chunk.
        margin_periods: look-ahead periods on each side of a chunk (None: :func:`lookahead_margin`).
        fingerprint: also work out the job's :func:`cam.job.resume.plan_fingerprint` in this pass
            (:attr:`ChunkedPlan.job_sha256`; a job kept as pieces is then not made again for it).

    Raises:
        TravelError: a point of the job is outside the machine travel, or (``start_steps`` None) the job is wider
        than it (nothing is planned).
    """
    _keep_freed_memory()  # before the threads that will run the plan exist: they share one heap
    s = job.settings
    origin = None if start_steps is None else np.asarray(start_steps, np.int64)
    span = TravelSpan(s) if origin is None else None
    prev = np.zeros((1, 3), np.int64)
    steps_total = np.zeros(3, np.int64)
    period0 = 0
    stops: list[np.ndarray] = []
    pause_writes: list[np.ndarray] = []
    notes: list[str] = []
    warnings: list[str] = list(job.warnings)
    min_nominal: Optional[int] = None
    any_move_start = False
    last = (0, 0, 0)
    reach = _Reach(s)
    sha = PlanFingerprint() if fingerprint else None
    for piece in job.pieces():
        if sha is not None:
            sha.add(piece)
        pts = np.asarray(piece.points_steps, np.int64).reshape(-1, 3)
        if not len(pts):
            continue
        for b0 in range(0, len(pts), _MOVE_BLOCK * 16):
            if origin is None:
                check_span(pts[b0:b0 + _MOVE_BLOCK * 16], s, piece.pixels, span)
            else:
                check_travel(pts[b0:b0 + _MOVE_BLOCK * 16] + origin, s, piece.pixels)
        npm, nom, d = _per_move(piece, pts, prev)
        steps_total += d
        reach.add(pts, npm, nom, prev)
        point_period = period0 + np.cumsum(npm)
        pause_idx = np.flatnonzero(np.asarray(piece.pause, bool))
        stops.append(point_period[pause_idx])
        pause_writes.append(2 * point_period[pause_idx])
        notes += list(piece.pause_notes) if piece.pause_notes is not None else ["Pause At"] * len(pause_idx)
        if piece.rest is not None:
            rest = np.flatnonzero(np.asarray(piece.rest, bool))
            stops += [point_period[rest] - npm[rest], point_period[rest]]
        any_move_start |= piece.move_start is None or bool(np.any(piece.move_start))
        if (nom > 0).any():
            m = int(nom[nom > 0].min())
            min_nominal = m if min_nominal is None else min(min_nominal, m)
        warnings += [w for w in piece.warnings if w not in warnings]
        period0 = int(point_period[-1])
        prev = pts[-1:]
        last = tuple(int(v) for v in pts[-1])  # type: ignore[assignment]
    job_sha256 = None
    if sha is not None:
        job_sha256 = sha.hexdigest()
        sha.close()
    min_period = min([s.delay_xy_ns, s.delay_z_ns] + ([min_nominal] if min_nominal is not None else []))
    margin = lookahead_margin(s, min_period) if margin_periods is None else int(margin_periods)
    return ChunkedPlan(
        job=job, settings=s, n_periods=period0, pause_writes=np.concatenate(pause_writes or [np.zeros(0, np.int64)]),
        steps_total=steps_total, end_steps=last, safe_z_steps=int(job.safe_z_steps),
        chunk_periods=int(chunk_periods), margin_periods=margin, pause_notes=notes, warnings=warnings,
        any_move_start=any_move_start, job_sha256=job_sha256,
        _stops=np.unique(np.concatenate(stops or [np.zeros(0, np.int64)])),
        _time_ns=reach.time_ns if s.ramp == "constant" else None, _extent=reach.extent_and_cut())


def plan_steps(job: JobLike, *, start_steps: tuple[int, int, int] = (0, 0, 0)) -> StepPlan:
    """Every timed port write of a job at once: the chunks of :func:`plan_chunks` joined.

    The machine session, :func:`cam.run`, ``cam drill`` and the page all run the chunked plan; this is the
    same writes held in memory (about 20 bytes per step period), for pictures of every write and tests.

    Args:
        job: the moves, in steps relative to where the tool stands when it starts.
        start_steps: where the tool stands in the machine frame: the job is checked against the
            travel from there.

    Raises:
        TravelError: a point of the job is outside the machine travel (nothing is planned).
    """
    return plan_chunks(job, start_steps=start_steps).to_plan()
