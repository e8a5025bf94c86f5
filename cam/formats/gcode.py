"""G-code in: run RS-274/NGC programs as LinuxCNC's interpreter runs them, text to moves in mm.

A small interpreter for the LinuxCNC language (tested against LinuxCNC's own ``rs274``):

* motion: G0, G1, G2/G3 in the G17 (XY), G18 (XZ) and G19 (YZ) planes by I/J/K or R, full circles,
  helical moves, ``P`` turns, G90.1/G91.1 arc centres; polar ``@`` ``^`` words (G17); G4 dwell;
  G5 (cubic) and G5.1 (quadratic) Bezier splines in G17, each on its own line as in rs274 (I J, P Q
  offset the control points from the start and the end; a G5 without I J right after a G5 goes on
  along its tangent); G33 as a straight feed at K x S, with one warning (no spindle encoder: nothing
  synchronised, a multi-pass thread does not line up);
* canned cycles G73, G81, G82, G83, G85, G89 (G17) with G98/G99, R, Q, P, L repeats and G80;
* frames: G20/G21 anywhere, G90/G91, G53 (one line in machine coordinates), G54..G59.3 work
  offsets with G10 L2/L20, G92, G92.1, G92.2, G92.3, G43 H / G43.1 / G49 tool length offsets
  (a tool table in LinuxCNC's format), G28/G30 (and G28.1/G30.1) to the homes the caller gives;
* as a G-code sender runs a program: it starts where the tool stands (``start_mm``, machine mm) in the work
  offsets the caller gives (the machine state's G54..G59.3 and the active one); program coordinates are
  machine coordinates minus the active offset (and G92); G53, G28 and G30 are machine positions; the moves
  are given from ``start_mm``; the program's G10 L2/L20 hold for its run, and it says how it left them;
* grbl's dialect: an arc's centre word of another plane (K0 on a G17 arc) ignored, ``$`` lines and ``?`` lines
  (grbl's status query) skipped (one warning each), a UTF-8 byte-order mark accepted; M3/M4/M5 and S recorded on every move (``spindle``,
  ``spindle_rpm``: for ports with a spindle; one warning that a step/dir port ignores them); Marlin's words
  (E, M17, M104, M140, G29, ...) refused naming Marlin;
* as rs274: a bare program number line (``O1000``, ``O1000 (name)``) runs nothing; G80 on a line with another
  motion code gives way to it (``G0 G90 G40 G21 G17 G94 G80`` leaves G0 the motion mode);
* accepted without motion: G61, G61.1, G64 (P Q), G93/G94 feed modes (G93 gives each move its time),
  G40, G8, G96/G97, M48..M53, M61 Q; M7/M8/M9 (no coolant output: one warning);
* probing (:mod:`._gcode_probe`): G38.2 and G38.3 along Z, down, with LinuxCNC's semantics: a straight feed move
  toward the target that stops where the probe trips (G38.2 an error if it never trips, G38.3 not), the program's
  position then the trip point and #5061..#5063 the trip point in the coordinate system of the probe (#5070: it
  tripped); refused as rs274 refuses them (no feed, G93, cutter compensation on, a target nearer than 0.254 mm).
  The interpreter reads nothing after a probe before the probe has run: the batch ends with it, and the next one
  is read when asked for, its trip point asked then (``probed``, :meth:`GcodeFile.move_batches`); without a machine
  every probe trips at its target;
* pauses: M6 with T (tool change), M0, M1, M60; M2/M30 (and a second ``%``) end the program;
* the language: numbered and named parameters (local ``#<name>``, global ``#<_name>``), expressions
  (:mod:`cam.formats.ngc`), O words (sub/endsub/call/return, if/elseif/else/endif, while/endwhile,
  do/while, repeat/endrepeat, break/continue), M70..M73 modal state, and ``O<name> call`` of
  ``name.ngc`` found in the subroutine path.

Cutter radius compensation G41.1/G42.1 D<diameter>, and G41/G42 D<tool> (the tool table's diameter, D
omitted: the tool in the spindle's) for G0/G1 moves and G2/G3 arcs in G17 as rs274 runs it (entry move or arc,
arcs offset about their centres, concave corners between lines and arcs met where the offsets cross, convex ones
rounded, Z-only moves, G40 and the exit move; a tool too big for an arc it runs inside or for a corner refused):
:mod:`._gcode_comp`.

Refused, each with a message saying why: probing away from the work (G38.4, G38.5) and along X or Y or upward, rotary
axes (A B C) and U V W, cutter
radius compensation G41/G42 by tool number without a tool table, and splines, cycles, dwells,
pauses or frame changes while it is on, lathe cycles and modes (G7, G7x, G76), rigid tapping (G33.1), NURBS blocks
(G5.2/G5.3), spindle cycles (G84, G86..G88), user M codes (M100..M199) and I/O (M62..M68).

Every error is a :class:`~cam.errors.ParseError` naming ``file:line``, the word and the line.
Every number a word takes is checked against :mod:`cam.limits` before it is used.  A program runs
at most ``max_lines`` lines (a loop that never ends is an error, not a hang).

The interpreter runs a line at a time and gives its moves in batches (:class:`MoveBatch`): :func:`parse_gcode`
and :func:`load_gcode` hold them all (a :class:`GcodeProgram`); :func:`open_gcode` gives a :class:`GcodeFile`,
whose program is interpreted again on each pass, its file read a line at a time
(:mod:`cam.formats._gcode_lines`), so neither its lines nor its moves are ever all held.

Planning the motion (frames, arcs, feeds, the half-step accuracy) is :mod:`cam.job.gcode`.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Mapping, Sequence

from ..errors import ParseError
from ..fileio import read_text
from ..limits import DEFAULT_GCODE_LINES, MAX_COORD_MM, MAX_TOOL_NUMBER
from ._gcode_block import _Block
from ._gcode_comp import _Comp
from ._gcode_cycles import _Cycles
from ._gcode_data import PLANE_AXES, GcodeMove, GcodeProgram, MoveBatch, _shown
from ._gcode_flow import _Flow
from ._gcode_lines import _Source
from ._gcode_motion import _Motion
from ._gcode_probe import ProbeFn, _Probe

__all__ = [
    "GcodeMove", "GcodeProgram", "GcodeFile", "MoveBatch", "PLANE_AXES", "parse_gcode", "load_gcode", "open_gcode",
    "load_tool_table", "ToolTable", "BATCH_MOVES", "ProbeFn",
]


class ToolTable(dict):
    """A tool table: tool number -> Z length offset mm (the dict), and :attr:`diameters_mm`, tool number -> its
    diameter D in mm (0 where a line gives none, as in LinuxCNC) for cutter compensation G41/G42."""

    def __init__(self, lengths_mm=(), diameters_mm=None) -> None:
        super().__init__(lengths_mm)
        self.diameters_mm: dict[int, float] = dict(diameters_mm or {})


def load_tool_table(path: str | os.PathLike) -> ToolTable:
    """A LinuxCNC tool table file (``T1 P1 Z0.511 D0.125 ;comment`` lines, the ``tool_table`` option's path):
    tool number -> Z length offset in mm, the ``tool_lengths_mm`` of :func:`parse_gcode`, with the diameters
    (:class:`ToolTable`) that G41/G42 take.

    The table is in the machine's units, millimetres for `cam`.  Errors name ``file:line``.
    """
    p, text = read_text(path, not_text="not a tool table text file")
    table = ToolTable()
    for no, raw in enumerate(text.splitlines(), start=1):
        body = raw.split(";", 1)[0].strip()
        if not body:
            continue
        words: dict[str, float] = {}
        for item in body.split():
            k, v = item[:1].upper(), item[1:]
            try:
                val = float(v)
            except ValueError:
                raise ParseError(f"{p}:{no}: cannot read '{_shown(item)}' in the tool table") from None
            if not math.isfinite(val):
                raise ParseError(f"{p}:{no}: '{_shown(item)}' is not a finite number")
            words[k] = val
        if "T" not in words:
            raise ParseError(f"{p}:{no}: a tool table line needs a tool number 'T'")
        tool, z = words["T"], words.get("Z", 0.0)
        if not (0 <= tool <= MAX_TOOL_NUMBER and tool == int(tool)):
            raise ParseError(f"{p}:{no}: tool 'T{tool:g}' is out of range: a whole number 0..{MAX_TOOL_NUMBER}")
        if abs(z) > MAX_COORD_MM:
            raise ParseError(f"{p}:{no}: tool length 'Z{z:g}' is beyond {MAX_COORD_MM:g} mm")
        dia = words.get("D", 0.0)
        if not 0 <= dia <= MAX_COORD_MM:
            raise ParseError(f"{p}:{no}: tool diameter 'D{dia:g}' must be 0..{MAX_COORD_MM:g} mm")
        table[int(tool)] = z
        table.diameters_mm[int(tool)] = dia
    return table


class _Interp(_Flow, _Block, _Motion, _Cycles, _Comp, _Probe):
    """The interpreter: one run of one program (its parts, each a module: the state and parameters
    :mod:`._gcode_state`, the lines and O words :mod:`._gcode_flow`, one block :mod:`._gcode_block`, motion
    :mod:`._gcode_motion`, canned cycles :mod:`._gcode_cycles`, probes :mod:`._gcode_probe`)."""


BATCH_MOVES = 1 << 12
"""Moves a :class:`GcodeFile` gives in one :class:`MoveBatch` (at least: a line's moves are never split)."""


def _interpret(src: _Source, batch_moves: int, options: dict) -> Iterator[MoveBatch]:
    """Run the program of ``src`` (``options`` as :func:`parse_gcode`'s) and give its moves in batches of at least
    ``batch_moves`` (the last may be shorter, and is given even when empty), each with the warnings first given
    while its moves were made.  A batch ends after a probe (G38.2, G38.3): the program reads on only when the next
    batch is asked for, once the probe has run (``options["probed"]`` says where it tripped)."""
    interp = _Interp(src, **options)
    interp.batch_moves = batch_moves
    warned = 0

    def take() -> MoveBatch:
        nonlocal warned
        batch = MoveBatch(interp.moves, interp.warnings[warned:])
        interp.moves, warned = [], len(interp.warnings)
        return batch

    try:
        for _ in interp.run():
            if len(interp.moves) >= batch_moves or interp.probe_pending is not None:
                yield take()
        interp.comp_off()  # the file ends with compensation on: its held moves run
        last = take()
        last.work_offsets_mm = interp.work_offsets_mm()
        yield last
    except RecursionError:  # pragma: no cover - an expression nested thousands deep
        raise interp.err("expression nested too deep") from None
    finally:
        src.close()
        for sub in interp.files.values():
            sub.close()


@dataclass
class GcodeFile:
    """A G-code program file, interpreted again on each pass a line at a time (:meth:`move_batches`): neither
    its lines nor its moves are ever all held, so a file of any size is planned in bounded memory
    (:func:`cam.job.gcode.stream_gcode`).  :func:`load_gcode` is its moves held (a :class:`GcodeProgram`).

    Attributes:
        path: the file; source: its name in messages.
        home_g28_mm, home_g30_mm, tool_lengths_mm, subroutine_path, max_lines, start_mm, work_offsets_mm,
        active_offset: as :func:`parse_gcode`'s.
        warnings: the warnings of the last pass that ran to the end (empty before).
        end_offsets_mm: the work offsets as the last pass that ran to the end left them (None before).
    """

    path: Path
    source: str
    home_g28_mm: Sequence[float] = (0.0, 0.0, 0.0)
    home_g30_mm: Sequence[float] = (0.0, 0.0, 0.0)
    tool_lengths_mm: Mapping[int, float] | None = None
    subroutine_path: Sequence[str | os.PathLike] = ()
    max_lines: int = DEFAULT_GCODE_LINES
    warnings: list[str] = field(default_factory=list)
    start_mm: Sequence[float] = (0.0, 0.0, 0.0)
    work_offsets_mm: Mapping[str, Sequence[float]] | None = None
    active_offset: str = "G54"
    end_offsets_mm: dict[str, tuple[float, float, float]] | None = None

    def move_batches(self, batch_moves: int = BATCH_MOVES, *, probed: ProbeFn | None = None) -> Iterator[MoveBatch]:
        """The program's moves in order, in batches of at least ``batch_moves`` (see :class:`MoveBatch`).

        A probe (G38.2, G38.3) ends its batch: the next batch is read from the program once it is asked for, and
        ``probed`` is asked then where the probe tripped (:data:`ProbeFn`: the probe has run on the machine; None:
        every probe trips at its target, :mod:`._gcode_probe`).

        Raises:
            ParseError: as :func:`parse_gcode` (``file:line``), when the line is reached.
        """
        options = dict(home_g28_mm=self.home_g28_mm, home_g30_mm=self.home_g30_mm,
                       tool_lengths_mm=self.tool_lengths_mm, subroutine_path=self.subroutine_path,
                       max_lines=self.max_lines, start_mm=self.start_mm, work_offsets_mm=self.work_offsets_mm,
                       active_offset=self.active_offset, probed=probed)
        found: list[str] = []
        for batch in _interpret(_Source(self.source, path=self.path), max(1, int(batch_moves)), options):
            found += batch.warnings
            if batch.work_offsets_mm is not None:
                self.end_offsets_mm = batch.work_offsets_mm
            yield batch
        self.warnings = found


def open_gcode(path: str | os.PathLike, *, home_g28_mm: Sequence[float] = (0.0, 0.0, 0.0),
               home_g30_mm: Sequence[float] = (0.0, 0.0, 0.0), tool_lengths_mm: Mapping[int, float] | None = None,
               subroutine_path: Sequence[str | os.PathLike] = (), max_lines: int = DEFAULT_GCODE_LINES,
               start_mm: Sequence[float] = (0.0, 0.0, 0.0),
               work_offsets_mm: Mapping[str, Sequence[float]] | None = None,
               active_offset: str = "G54") -> GcodeFile:
    """A G-code file to interpret a pass at a time (:class:`GcodeFile`); the options as :func:`parse_gcode`'s.

    Raises:
        ParseError: the file is missing or cannot be read.
    """
    p = Path(path)
    if not p.is_file():
        raise ParseError(f"{p}: file not found")
    return GcodeFile(p, str(p), tuple(home_g28_mm), tuple(home_g30_mm), tool_lengths_mm, tuple(subroutine_path),
                     int(max_lines), start_mm=tuple(start_mm),
                     work_offsets_mm=None if work_offsets_mm is None else dict(work_offsets_mm),
                     active_offset=active_offset)


def _program(batches: Iterator[MoveBatch], source: str) -> GcodeProgram:
    moves: list[GcodeMove] = []
    warnings: list[str] = []
    offsets = None
    for batch in batches:
        moves += batch.moves
        warnings += batch.warnings
        offsets = batch.work_offsets_mm if batch.work_offsets_mm is not None else offsets
    return GcodeProgram(moves, source, warnings, offsets)


def parse_gcode(
    text: str, *, source: str = "<gcode>", home_g28_mm: Sequence[float] = (0.0, 0.0, 0.0),
    home_g30_mm: Sequence[float] = (0.0, 0.0, 0.0), tool_lengths_mm: Mapping[int, float] | None = None,
    subroutine_path: Sequence[str | os.PathLike] = (), max_lines: int = DEFAULT_GCODE_LINES,
    start_mm: Sequence[float] = (0.0, 0.0, 0.0), work_offsets_mm: Mapping[str, Sequence[float]] | None = None,
    active_offset: str = "G54",
) -> GcodeProgram:
    """Interpret G-code text into absolute moves in mm, held in memory.

    The program runs as a G-code sender runs it: program coordinates are machine coordinates minus the active
    work offset (and G92), the tool starts where it stands (``start_mm``), G53 moves and G28/G30's homes are
    machine positions.  Machine mm are in G-code's axes (+Y away from the operator, +Z up) from the machine's
    home.  The moves are given from ``start_mm``: a move's ``end`` is its machine position minus ``start_mm``.

    Args:
        text: the program.
        source: its name in messages.
        home_g28_mm, home_g30_mm: where G28 and G30 go, machine mm (parameters 5161.. and 5181..).
        start_mm: where the tool stands when the program starts, machine mm.
        work_offsets_mm: work offset name (``"G54"`` .. ``"G59.3"``) -> its zero, machine mm (the
            machine state's; parameters 5221..); None or a name left out: zero.  ``G10 L2``/``L20`` change
            them for this run only; the program's :attr:`GcodeProgram.work_offsets_mm` says how it left them.
        active_offset: the work offset in force when the program starts (``G54`` unless the state says).
        tool_lengths_mm: tool number -> Z length offset mm, for G43 (a tool table file's, see
            :func:`load_tool_table`); None: G43 with a tool other than 0 is an error.  A :class:`ToolTable`'s
            diameters are the ones G41/G42 take (a plain mapping: every diameter 0); None: G41/G42 are errors.
        subroutine_path: folders where ``O<name> call`` finds ``name.ngc``.
        max_lines: the most lines the program may run (loops count each time).

    Raises:
        ParseError: ``source:line: message "line text"`` for any unsupported, refused or malformed word, and
            for a program that runs more than ``max_lines`` lines.
    """
    options = dict(home_g28_mm=home_g28_mm, home_g30_mm=home_g30_mm, tool_lengths_mm=tool_lengths_mm,
                   subroutine_path=subroutine_path, max_lines=max_lines, start_mm=start_mm,
                   work_offsets_mm=work_offsets_mm, active_offset=active_offset)
    return _program(_interpret(_Source(source, text), 1 << 62, options), source)


def load_gcode(path: str | os.PathLike, **options) -> GcodeProgram:
    """Read and interpret a G-code file, its moves held in memory (errors name file:line); ``options`` as
    :func:`parse_gcode`.  The file is read a line at a time, as :class:`GcodeFile` reads it."""
    f = open_gcode(path, **options)
    return _program(f.move_batches(1 << 62), f.source)
