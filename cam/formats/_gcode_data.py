"""G-code in, its data: the moves a program gives, the text it is read from, and the words it knows.

:mod:`cam.formats.gcode` is the interpreter's public face; these are the pieces its parts
(:mod:`._gcode_state`, :mod:`._gcode_flow`, :mod:`._gcode_block`, :mod:`._gcode_motion`,
:mod:`._gcode_cycles`) share.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator, Optional

from ._gcode_lines import _Source

PLANE_AXES = {"XY": (0, 1, 2), "XZ": (2, 0, 1), "YZ": (1, 2, 0)}
"""The (first, second, third) axes of each arc plane, as LinuxCNC orders them: arcs turn in the
(first, second) frame (G2 clockwise), the third axis moves linearly (helix)."""


@dataclass
class GcodeMove:
    """One programmed move in mm (machine frame, G-code axes: +Y up, +Z up).

    ``kind``: "rapid", "feed", "arc", "spline", "probe", "dwell" or "pause".  ``end`` is absolute mm; arcs carry
    ``center`` (mm, in the (first, second) axes of ``plane``, see :data:`PLANE_AXES`), ``clockwise``
    and ``turns``; a spline (G5, G5.1) is the Bezier curve from where the last move ended through its inner
    ``controls`` (absolute mm: one for G5.1, two for G5; Z as at the start) to ``end``; dwell carries
    ``seconds``; pause carries ``note``; a probe (G38.2, G38.3: :mod:`._gcode_probe`) is the straight feed move
    toward its target ``end`` that stops where the probe trips, its code in ``note`` (``"G38.2"``, ``"G38.3"``);
    ``feed_mm_min`` applies to feed, arc, spline and probe moves, or ``minutes`` (G93 inverse time) when it is
    more than 0.  ``spindle`` is the spindle's state the move runs
    with (3: M3 clockwise, 4: M4 counter-clockwise, 0: stopped, M5) and ``spindle_rpm`` the S word in force:
    recorded for ports that switch a spindle; the step/dir planner ignores them.

    Frame: :func:`cam.formats.gcode.parse_gcode`'s ``start_mm`` is subtracted from every position (``end``,
    ``center``, ``controls``), so the moves are given from where the tool stood when the program started
    (the machine frame itself when ``start_mm`` is the home, the default).
    """

    kind: str
    line: int
    end: tuple[float, float, float]
    feed_mm_min: float = 0.0
    center: tuple[float, float] | None = None
    clockwise: bool = False
    turns: int = 1
    seconds: float = 0.0
    note: str = ""
    plane: str = "XY"
    minutes: float = 0.0
    controls: tuple[tuple[float, float, float], ...] = ()
    file: str = ""  # the file of ``line`` when it is not the program's own (a subroutine file)
    spindle: int = 0
    spindle_rpm: float = 0.0


@dataclass
class MoveBatch:
    """Consecutive moves of a program, as its interpreter gives them a few at a time: ``moves`` in order, and
    the ``warnings`` first given while they were made (the warnings of the batches before are not repeated)."""

    moves: list[GcodeMove]
    warnings: list[str] = field(default_factory=list)
    work_offsets_mm: Optional[dict[str, tuple[float, float, float]]] = None
    """The last batch of a program that ran to its end: the work offsets G54..G59.3 as the program left them
    (machine mm, G-code axes; ``G10 L2``/``L20`` change them); None on the others."""


@dataclass
class GcodeProgram:
    """Interpreted program held in memory: moves in order, plus warnings; ``source`` names the file.

    :func:`cam.formats.gcode.parse_gcode` and :func:`~cam.formats.gcode.load_gcode` make it; a file too large to
    hold is a :class:`cam.formats.gcode.GcodeFile`, interpreted again on each pass.  Both give
    :meth:`move_batches`, which :func:`cam.job.gcode.stream_gcode` plans a piece at a time."""

    moves: list[GcodeMove]
    source: str = "<gcode>"
    warnings: list[str] = field(default_factory=list)
    work_offsets_mm: Optional[dict[str, tuple[float, float, float]]] = None
    """The work offsets as the program left them (see :attr:`MoveBatch.work_offsets_mm`)."""

    def move_batches(self, batch_moves: int) -> Iterator[MoveBatch]:
        """The moves in batches of ``batch_moves`` (the last shorter; one empty batch when there are none); the
        first batch carries the warnings."""
        step = max(1, int(batch_moves))
        for i in range(0, max(1, len(self.moves)), step):
            last = i + step >= len(self.moves)
            yield MoveBatch(self.moves[i:i + step], list(self.warnings) if i == 0 else [],
                            dict(self.work_offsets_mm) if last and self.work_offsets_mm is not None else None)


def _strip_comments(line: str, err) -> str:
    """``line`` without its comments (``( )`` and ``;`` to the end); ``err(message)`` makes the error of a
    malformed one."""
    if "(" not in line and ")" not in line and ";" not in line:
        return line  # nothing to strip (most lines): no walk over the characters
    out = []
    depth = 0
    for ch in line:
        if ch == "(":
            if depth:
                raise err("nested comment '('")
            depth = 1
        elif ch == ")":
            if not depth:
                raise err("')' without '('")
            depth = 0
        elif ch == ";" and not depth:
            break
        elif not depth:
            out.append(ch)
    if depth:
        raise err("comment '(' is not closed on its line")
    return "".join(out)


def _shown(word: str) -> str:
    """A word as a message quotes it: at most 24 characters."""
    return word if len(word) <= 24 else word[:20] + "..."


# -- refused features: one message each ---------------------------------------------------------------------------

_REFUSED_G = {
    **{c: "probing away from the work (G38.4/G38.5) is not supported: cam probes down to the work (G38.2/G38.3)"
       for c in (384, 385)},
    **{c: "lathe cycles are not supported: the machine is a 3-axis mill" for c in (700, 710, 711, 720, 721, 760)},
    70: "lathe diameter mode is not supported: the machine is a 3-axis mill",
    331: "rigid tapping is not supported: the machine has no spindle encoder",
    **{c: "NURBS blocks (G5.2 .. G5.3) are not supported: give G5 or G5.1 splines, lines or arcs"
       for c in (52, 53)},
    **{c: "this canned cycle needs spindle control, which the machine does not have" for c in (840, 860, 870, 880)},
    950: "feed per revolution is not supported: the machine has no spindle encoder",
    432: "G43.2 (added tool length offsets) is not supported",
    171: "user-defined planes are not supported", 181: "user-defined planes are not supported",
    191: "user-defined planes are not supported",
}
_SUPPORTED_G = {0, 10, 20, 30, 40, 50, 51, 330, 382, 383, 80, 100, 170, 180, 190, 200, 210, 280, 281, 300, 301, 400,
                410, 411, 420, 421,
                430, 431, 490, 530,
                540, 550, 560, 570, 580, 590, 591, 592, 593, 610, 611, 640, 730, 800, 810, 820, 830, 850, 890,
                900, 901, 910, 911, 920, 921, 922, 923, 930, 940, 960, 970, 980, 990}
COMP_NO_TABLE = ("cutter radius compensation G41/G42 takes the tool's radius from the tool table's diameter, and "
                 "there is none: give one (--tool-table FILE), or G41.1/G42.1 D<diameter>, or the tool centre's path")
_CYCLES = {730, 810, 820, 830, 850, 890}
_PROBES = {382, 383}  # G38.2, G38.3 (:mod:`._gcode_probe`)
_MOTION = {0, 10, 20, 30, 330, 800} | _CYCLES | _PROBES
_SPLINES = {50, 51}  # G5, G5.1: motion on their own line only (rs274 keeps the modal motion mode)
_CS = {540: 1, 550: 2, 560: 3, 570: 4, 580: 5, 590: 6, 591: 7, 592: 8, 593: 9}
CS_NAMES = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")
"""The work offsets (coordinate systems 1..9, P1..P9 of G10), as senders and the machine state name them."""
_IGNORED_M = {3, 4, 5, 48, 49, 50, 51, 52, 53}
_IO_M = {62, 63, 64, 65, 66, 67, 68}
_MARLIN_M = {17, 18, 82, 83, 84, 92, 201, 203, 204, 205, 220, 221, 500, 501, 503}  # Marlin's only: no G-code has them
_MARLIN_USER_M = {104, 105, 106, 107, 109, 114, 117, 140, 190}  # Marlin's, and user M codes in LinuxCNC
_MARLIN_G = {290}  # G29: bed levelling
_MARLIN = "a Marlin (3D printer firmware) {what}: this program drives a 3D printer, not a mill; give G-code for " \
          "LinuxCNC or grbl"
_AXIS_WORDS = "xyz"
_LETTERS = set("xyzijkrfstpqlhn@^")
_CYCLE_PECK = 0.254  # mm: LinuxCNC's G73 chip-break retract and G83 rapid stop above the last peck (0.010 in)


class _End(Exception):
    """M2, M30 or the closing ``%``: the program ends."""


@dataclass
class _Frame:
    """A subroutine call: where to return, the caller's local parameters, and the loops running in it."""

    source: _Source
    back: int
    label: str
    saved_numbered: dict[int, float]
    named: dict[str, float] = field(default_factory=dict)
    repeats: dict[tuple[int, int], int] = field(default_factory=dict)
    modal: dict | None = None  # M73: restored on return

