"""The pin log: what a port was told, and how to read motion back out of it.

CSV format (one row per port write)::

    t_ns,data,strobe
    0,168,0
    2500000,186,0
    ...

``t_ns`` is nanoseconds from the start of the log, ``data`` the data register
(pins 2..9 = bits 0..7, 0..255) after the write, ``strobe`` the level of pin 1
(0 or 1).  :func:`decode_pin_log` turns it back into tool positions: a step
is a rising edge of an axis's clock bit, in the + direction when that axis's
direction bit is set in the same write.

A command's pin log holds every write of the command (issue #44 point 4): ``cam drill`` of a job placed at the
work zero travels there first, then runs the job.  A comment line before the first row of each part names it
(:class:`PinLogPart`)::

    # part travel from 1600,1600,0 steps at 0 ns
    0,40,0
    ...
    # part job from 4000,4000,0 steps at 1242500000 ns

``from`` is where the tool stood when the part began (machine frame, steps), ``at`` the part's start on the
log's one time line.  Every reader here reads every row by default; ``part="job"`` takes the job's rows alone,
their times from the job's start, as a log of the job alone (a log without parts is taken to be the job's).
"""
from __future__ import annotations

import functools

import io
import mmap
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional

import numpy as np

from ..arrays import column_range
from ..errors import CamError, ParseError
from ..fileio import atomic_write_text
from ..render.picture import encode_png, surface_picture
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..pins import axis_bits

__all__ = ["Surface", "PinLog", "PinLogPart", "join_pin_logs", "Motion", "decode_pin_log", "read_pin_log",
           "iter_pin_log", "write_pin_log", "carve", "motion_extent", "rising_edges", "decode_writes", "pixel_under"]

HEADER = "t_ns,data,strobe"


class Surface(np.ndarray):
    """A cut surface: ``(H, W)`` int64 depth in Z steps per drawing pixel; shows itself as a picture in notebooks."""

    def _repr_png_(self) -> bytes:
        return encode_png(surface_picture(np.asarray(self)))


@dataclass(frozen=True)
class PinLogPart:
    """One part of a command's pin log: ``name`` (``travel``: to the work zero, ``job``), the row it starts at
    (0-based, among the data rows), where the tool stood when it began (``start_steps``, machine frame) and when it
    began on the log's time line (``t0_ns``): the part's own times are ``t_ns - t0_ns``."""

    name: str
    first_row: int
    start_steps: tuple[int, int, int] = (0, 0, 0)
    t0_ns: int = 0

    def line(self) -> str:
        """The comment line that marks the part in the CSV (no newline)."""
        x, y, z = (int(v) for v in self.start_steps)
        return f"# part {self.name} from {x},{y},{z} steps at {int(self.t0_ns)} ns"


_PART_LINE = re.compile(r"# part ([a-z_]+) from (-?\d+),(-?\d+),(-?\d+) steps at (-?\d+) ns")


@dataclass
class PinLog:
    """Port writes: ``t_ns`` (M,) int64, ``data`` (M,) uint8, ``strobe`` (M,) uint8; ``parts``: the command's parts
    (:class:`PinLogPart`, in row order; empty: one run's writes, a job's)."""

    t_ns: np.ndarray
    data: np.ndarray
    strobe: np.ndarray
    parts: tuple[PinLogPart, ...] = ()

    def __len__(self) -> int:
        return len(self.t_ns)

    def part(self, name: str = "job") -> "PinLog":
        """The rows of part ``name`` alone, as a log of that part: times from its start, its one part at row 0.
        A log without parts is the job's own (``name`` "job": the log itself).

        Raises:
            CamError: the log has no such part.
        """
        lo, hi, part = _part_rows(self.parts, name, len(self))
        if part is None:
            return self
        return PinLog(np.asarray(self.t_ns[lo:hi], np.int64) - part.t0_ns, self.data[lo:hi], self.strobe[lo:hi],
                      (PinLogPart(part.name, 0, part.start_steps, 0),))


def _part_rows(parts: tuple[PinLogPart, ...], name: str, n_rows: int
               ) -> tuple[int, int, Optional[PinLogPart]]:
    """``(first row, row past the end, the part)`` of part ``name``; ``(0, n_rows, None)`` for the job of a log
    without parts.  CamError when there is no such part."""
    if not parts and name == "job":
        return 0, n_rows, None
    for i, p in enumerate(parts):
        if p.name == name:
            return p.first_row, (parts[i + 1].first_row if i + 1 < len(parts) else n_rows), p
    have = ", ".join(p.name for p in parts) or "none"
    raise CamError(f"the pin log has no {name} part (its parts: {have})")


def join_pin_logs(parts: list[tuple[str, PinLog, tuple[int, int, int]]], gap_ns: int) -> PinLog:
    """One log of a command's parts, each ``(name, its own log, where it started: machine frame, steps)``, on one
    time line: each part starts ``gap_ns`` after the last write before it (a log's own parts give way to the one
    named here)."""
    t, d, s, marks = [], [], [], []
    rows, t0 = 0, 0
    for name, log, start in parts:
        marks.append(PinLogPart(name, rows, tuple(int(v) for v in start), t0))  # type: ignore[arg-type]
        t.append(np.asarray(log.t_ns, np.int64) + t0)
        d.append(np.asarray(log.data, np.uint8))
        s.append(np.asarray(log.strobe, np.uint8))
        rows += len(log)
        if len(log):
            t0 = int(t[-1][-1]) + int(gap_ns)
    if not t:
        return PinLog(np.zeros(0, np.int64), np.zeros(0, np.uint8), np.zeros(0, np.uint8))
    return PinLog(np.concatenate(t), np.concatenate(d), np.concatenate(s), tuple(marks))


@dataclass
class Motion:
    """Decoded motion.

    Attributes:
        t_ns: ``(M,)`` int64 time of each write.
        position_steps: ``(M, 3)`` int64 machine position (x, y, z) in steps after each write.
        step_counts: ``(3,)`` int64 steps made per axis (absolute).
    """

    t_ns: np.ndarray
    position_steps: np.ndarray
    step_counts: np.ndarray

    @property
    def final_steps(self) -> tuple[int, int, int]:
        if len(self.position_steps) == 0:
            return (0, 0, 0)
        return tuple(int(v) for v in self.position_steps[-1])  # type: ignore[return-value]


def write_pin_log(log: PinLog, path: str | os.PathLike) -> Path:
    """Write the pin log CSV atomically (each of its parts marked by its comment line, :class:`PinLogPart`)."""
    buf = io.StringIO()
    buf.write(HEADER + "\n")
    bounds = [0] + [p.first_row for p in log.parts] + [len(log)]
    for i, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
        if i:
            buf.write(log.parts[i - 1].line() + "\n")
        if hi > lo:
            arr = np.column_stack([np.asarray(v[lo:hi], np.int64) for v in (log.t_ns, log.data, log.strobe)])
            np.savetxt(buf, arr, fmt="%d", delimiter=",")
    return atomic_write_text(path, buf.getvalue())


def read_pin_log(path: str | os.PathLike, part: Optional[str] = None) -> PinLog:
    """Read a pin log CSV (errors name the file and line): every row, with its parts (:class:`PinLogPart`);
    ``part`` (``"job"``): that part's rows alone, as :meth:`PinLog.part` gives them."""
    p = Path(path)
    try:
        with open(p, encoding="utf-8") as handle:
            first = handle.readline().strip()
            if first != HEADER:
                raise ParseError(f"{p}:1: not a pin log (expected header '{HEADER}')")
            rows = np.loadtxt(handle, delimiter=",", dtype=np.int64, ndmin=2)
    except FileNotFoundError:
        raise ParseError(f"{p}: file not found") from None
    except ValueError as exc:
        raise ParseError(f"{p}: bad pin log row ({exc})") from None
    log = _rows_log(rows, p, 2)
    log.parts = _scan_parts(p)
    return log if part is None else _named_part(log, part, p)


def _named_part(log: PinLog, part: str, p: Path) -> PinLog:
    try:
        return log.part(part)
    except CamError as exc:
        raise ParseError(f"{p}: {exc}") from None


def _scan_parts(p: Path) -> tuple[PinLogPart, ...]:
    """The parts a pin log file marks (its ``# part`` lines), found without reading it into memory."""
    parts: list[PinLogPart] = []
    with open(p, "rb") as handle:
        if os.fstat(handle.fileno()).st_size == 0:
            return ()
        with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            lines, comments, at = 0, 0, 0  # lines ended before ``at`` (the header's too), comment lines so far
            while True:
                hit = mm.find(b"\n#", at)
                if hit < 0:
                    return tuple(parts)
                lines += _newlines(mm, at, hit + 1)
                end = mm.find(b"\n", hit + 1)
                text = mm[hit + 1:end if end >= 0 else len(mm)].decode("utf-8", "replace").strip()
                if text.startswith("# part"):
                    m = _PART_LINE.fullmatch(text)
                    if m is None:
                        raise ParseError(f"{p}:{lines + 1}: bad part line {text!r} (expected '# part NAME from "
                                         f"X,Y,Z steps at T ns')")
                    x, y, z, t0 = (int(v) for v in m.groups()[1:])
                    parts.append(PinLogPart(m.group(1), lines - 1 - comments, (x, y, z), t0))
                comments += 1
                at = hit + 1


def _newlines(mm: "mmap.mmap", lo: int, hi: int, block: int = 1 << 24) -> int:
    """The newlines in ``mm[lo:hi]``, counted a block at a time."""
    return sum(mm[i:min(hi, i + block)].count(b"\n") for i in range(lo, hi, block))


def _rows_log(rows: np.ndarray, p: Path, line: int) -> PinLog:
    """The PinLog of ``(M, 3)`` rows read from ``p`` (its first row on ``line``)."""
    if rows.size == 0:
        rows = np.zeros((0, 3), np.int64)
    if rows.shape[1] != 3:
        raise ParseError(f"{p}:{line}: expected 3 columns t_ns,data,strobe")
    return PinLog(rows[:, 0], rows[:, 1].astype(np.uint8), rows[:, 2].astype(np.uint8))


def iter_pin_log(path: str | os.PathLike, rows: int = 1 << 20, part: Optional[str] = None) -> Iterator[PinLog]:
    """Read a pin log CSV ``rows`` writes at a time (a log of any length, in bounded memory); errors as
    :func:`read_pin_log`'s, naming the first line of the piece.  ``part`` (``"job"``): that part's rows alone,
    their times from its start (as :meth:`PinLog.part`)."""
    p = Path(path)
    lo, hi, t0 = 0, None, 0
    if part is not None:
        if not p.exists():
            raise ParseError(f"{p}: file not found")
        parts = _scan_parts(p)
        try:
            lo, end, chosen = _part_rows(parts, part, -1)
        except CamError as exc:
            raise ParseError(f"{p}: {exc}") from None
        hi = None if end < 0 else end
        t0 = chosen.t0_ns if chosen is not None else 0
    at = 0  # the row the next piece starts at
    for piece in _iter_rows(p, rows):
        n = len(piece)
        a, b = max(lo, at) - at, (n if hi is None else min(hi, at + n) - at)
        at += n
        if b <= a:
            if hi is not None and at >= hi:
                return
            continue
        yield PinLog(piece.t_ns[a:b] - t0, piece.data[a:b], piece.strobe[a:b]) if (a, b, t0) != (0, n, 0) \
            else piece


def _iter_rows(p: Path, rows: int) -> Iterator[PinLog]:
    """Every row of a pin log CSV, ``rows`` at a time."""
    try:
        with open(p, encoding="utf-8") as handle:
            if handle.readline().strip() != HEADER:
                raise ParseError(f"{p}:1: not a pin log (expected header '{HEADER}')")
            line = 2
            while True:
                try:
                    with warnings.catch_warnings():  # a part's comment line is no row: said once per call
                        warnings.filterwarnings("ignore", "Input line", UserWarning)
                        block = np.loadtxt(handle, delimiter=",", dtype=np.int64, ndmin=2, max_rows=rows)
                except ValueError as exc:
                    raise ParseError(f"{p}:{line}: bad pin log row in the {rows} from here ({exc})") from None
                if block.size == 0:
                    return
                yield _rows_log(block, p, line)
                line += len(block)
                if len(block) < rows:
                    return
    except FileNotFoundError:
        raise ParseError(f"{p}: file not found") from None


def rising_edges(data: np.ndarray, mask: int, prev_byte: int = 0) -> np.ndarray:
    """``(M,)`` bool: the writes at which a bit of ``mask`` goes from 0 to 1 (a step of that clock).

    ``prev_byte`` is the register before the first write (0 at the start of a job).
    """
    data = np.asarray(data, np.uint8)
    prev = np.empty(len(data), np.uint8)
    if len(data):
        prev[0] = prev_byte
        prev[1:] = data[:-1]
    return ((data & mask) != 0) & ((prev & mask) == 0)


def net_steps(data: np.ndarray, prev_byte: int, clock: np.ndarray, dirbit: np.ndarray) -> np.ndarray:
    """``(3,)`` int64 steps each axis made over a stretch of writes (+ for a step with its direction bit set),
    ``prev_byte`` the register before the stretch: where :func:`decode_writes`'s last position lands, without the
    position after every write (one histogram of the rising clocks and direction bits)."""
    data = np.asarray(data, np.uint8)
    if not len(data):
        return np.zeros(3, np.int64)
    clocks, dirs = int(np.bitwise_or.reduce(clock)), int(np.bitwise_or.reduce(dirbit))
    rising = np.empty(len(data), np.uint8)
    rising[0] = data[0] & ~np.uint8(prev_byte)
    np.bitwise_and(data[1:], ~data[:-1], out=rising[1:])
    code = (rising & np.uint8(clocks)) | (data & np.uint8(dirs))
    return np.bincount(code, minlength=256) @ _step_table(tuple(int(v) for v in clock), tuple(int(v) for v in dirbit))


@functools.lru_cache(maxsize=8)
def _step_table(clock: tuple[int, ...], dirbit: tuple[int, ...]) -> np.ndarray:
    """``(256, 3)`` int64: the step of each axis for a register byte of rising clocks | direction bits."""
    v = np.arange(256)
    return np.stack([np.where(v & c, np.where(v & d, 1, -1), 0) for c, d in zip(clock, dirbit)], axis=1)


def decode_writes(data: np.ndarray, prev_byte: int, start_steps: np.ndarray, clock: np.ndarray,
                  dirbit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``(len(data), 3)`` int64 in steps after each write of a stretch of writes, and its ``(3,)`` steps
    per axis (each rising clock edge counts one, whatever its direction).

    ``data`` is the ``(N,)`` uint8 data register of each write, ``prev_byte`` the register before the stretch,
    ``start_steps`` the ``(3,)`` position there, ``clock`` and ``dirbit`` the ``(3,)`` bit masks of each axis
    (:func:`cam.pins.axis_bits`).
    """
    data = np.asarray(data, np.uint8)
    pos = np.empty((len(data), 3), np.int64)
    counts = np.zeros(3, np.int64)
    for a in range(3):
        rising = rising_edges(data, int(clock[a]), prev_byte)
        step = np.where(rising, np.where((data & dirbit[a]) != 0, 1, -1), 0)
        pos[:, a] = np.cumsum(step) + int(start_steps[a])
        counts[a] = int(rising.sum())
    return pos, counts


def decode_pin_log(
    log: PinLog | str | os.PathLike, settings: MachineSettings = DEFAULT_SETTINGS, *, part: Optional[str] = None
) -> Motion:
    """Decode a pin log into machine positions (steps) after each write.

    The register is taken to be 0 before the first write; the tool starts at (0, 0, 0).  ``part`` (``"job"``):
    decode that part of a command's log alone (:meth:`PinLog.part`), the tool starting at (0, 0, 0) where it
    begins; None: every row (add the first part's ``start_steps`` for the machine frame).
    """
    if not isinstance(log, PinLog):
        log = read_pin_log(log, part)
    elif part is not None:
        log = log.part(part)
    clock, dirbit = axis_bits(settings)
    pos, counts = decode_writes(log.data, 0, np.zeros(3, np.int64), clock, dirbit)
    return Motion(t_ns=np.asarray(log.t_ns, np.int64), position_steps=pos, step_counts=counts)


def _decoded_chunks(data: np.ndarray, start: int, stop: int, pos0: np.ndarray, clock: np.ndarray,
                    dirbit: np.ndarray):
    """Positions after writes ``start..stop`` of ``data``, ``(k, 3)`` a chunk at a time (bounded memory),
    starting from ``pos0`` (the position after write ``start - 1``)."""
    pos = np.asarray(pos0, np.int64)
    for i in range(start, stop, _CHUNK):
        end = min(stop, i + _CHUNK)
        chunk, _ = decode_writes(data[i:end], int(data[i - 1]) if i else 0, pos, clock, dirbit)
        pos = chunk[-1]
        yield chunk


_CHUNK = 1 << 21


def fold_extent(extent: np.ndarray, cut: np.ndarray, pos: np.ndarray) -> None:
    """Widen ``extent`` and ``cut`` (each ``(3, 2)`` int64 min/max in steps, in place) by the ``(N, 3)`` positions
    ``pos`` (N > 0); ``cut`` only by those below the surface (z > 0)."""
    lo, hi = column_range(pos)
    np.minimum(extent[:, 0], lo, out=extent[:, 0])
    np.maximum(extent[:, 1], hi, out=extent[:, 1])
    below = pos[pos[:, 2] > 0]
    if len(below):
        lo, hi = column_range(below)
        np.minimum(cut[:, 0], lo, out=cut[:, 0])
        np.maximum(cut[:, 1], hi, out=cut[:, 1])


def motion_extent(data: np.ndarray, settings: MachineSettings = DEFAULT_SETTINGS) -> tuple[np.ndarray, np.ndarray]:
    """Where a sequence of port writes takes the tool, decoded in bounded chunks.

    Returns:
        ``(extent, cut)``: ``(3, 2)`` int64 min and max position (x, y, z) in steps, the start
        (0, 0, 0) included; and ``(3, 2)`` the same over the positions below the surface (z > 0),
        all zeros when nothing is below it.
    """
    data = np.asarray(data, np.uint8)
    clock, dirbit = axis_bits(settings)
    extent = np.zeros((3, 2), np.int64)
    big = np.iinfo(np.int64).max
    cut = np.array([[big, -big]] * 3, np.int64)
    for pos in _decoded_chunks(data, 0, len(data), np.zeros(3, np.int64), clock, dirbit):
        fold_extent(extent, cut, pos)
    return extent, (cut if cut[0, 0] != big else np.zeros((3, 2), np.int64))


def pixel_under(v_steps: np.ndarray, spp: int) -> np.ndarray:
    """Pixel index along one axis of each position ``v_steps`` (``(N,)`` steps, ``spp`` steps a pixel), rounded
    half up; a position on the border between two pixels keeps the previous position's pixel."""
    v = np.asarray(v_steps, np.int64)
    pix = np.floor_divide(2 * v + spp, 2 * spp)  # round half up
    if spp % 2 == 0:
        tie = np.mod(v, spp) == spp // 2
        if np.any(tie):
            idx = np.where(~tie, np.arange(len(v)), -1)
            last = np.maximum.accumulate(idx)
            # a border position at the very start of the log rounds toward the origin
            prev = np.where(last >= 0, pix[np.maximum(last, 0)], pix - 1)
            pix = np.where(tie, prev, pix)
    return pix


def carve(
    motion: Motion,
    shape_hw: tuple[int, int],
    settings: MachineSettings = DEFAULT_SETTINGS,
    *,
    origin_px: tuple[int, int, int] = (0, 0, 0),
) -> np.ndarray:
    """Cut surface left by a point tool that follows ``motion``.

    A tool position (x, y, z) in steps lies over pixel
    ``(round(x / spp_xy) - ox, round(y / spp_xy) - oy)`` and is
    ``z - oz x spp_z`` steps below the surface there.  A coordinate exactly
    on the border between two pixels (possible with an even number of steps
    per pixel) still counts for the pixel the tool is leaving: a point tool
    on a border has not yet entered the next pixel.  So a diagonal move
    through the shared corner of four pixels touches only its two end pixels.

    Returns:
        ``(H, W)`` int64 :class:`Surface`: the deepest cut at each drawing pixel in Z steps (0 = untouched).

    Raises:
        CamError: the tool went below the surface outside the drawing.
    """
    h, w = shape_hw
    s = settings
    ox, oy, oz = origin_px
    p = motion.position_steps
    col = pixel_under(p[:, 0], s.steps_per_px_xy) - ox
    row = pixel_under(p[:, 1], s.steps_per_px_xy) - oy
    depth = p[:, 2] - oz * s.steps_per_px_z
    below = depth > 0
    col, row, d = col[below], row[below], depth[below]
    outside = (col < 0) | (col >= w) | (row < 0) | (row >= h)
    if np.any(outside):
        i = int(np.flatnonzero(outside)[0])
        raise CamError(f"the tool cut below the surface outside the drawing at pixel ({col[i]}, {row[i]})")
    out = np.zeros((h, w), np.int64)
    np.maximum.at(out, (row, col), d)
    return out.view(Surface)
