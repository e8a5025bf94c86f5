"""Excellon drill files (``.drl``, ``.xln``, ``.exc``, ``.drd``) in, a :class:`HoleList` out.

The reader takes the drill files that PCB programs really write (KiCad, Altium,
Eagle, OrCAD, Fritzing, EasyEDA, ...), one statement per line:

* header ``M48`` ... ``%`` (or ``M95``); a file that starts with ``%`` and no
  ``M48`` has no header (the OrCAD 9 file of seed 000 §8.1, Table 8-1);
* units ``METRIC`` / ``INCH`` (also ``M71`` / ``M72``) with optional ``,LZ`` /
  ``,TZ`` and a ``,000.000`` style digit format, in any order;
* ``FMAT,1`` / ``FMAT,2`` (in format 1 ``G81`` is the drill mode and ``M02``
  ends the program); ``ICI,ON|OFF``, ``G90`` / ``G91`` (absolute /
  incremental), ``G93X..Y..`` (zero set), ``G05`` / ``G81`` (drill mode);
* format hints in comments: KiCad ``; FORMAT={3:3/ absolute / metric / suppress
  leading zeros}`` (also ``decimal``, ``suppress trailing zeros``, ``keep
  zeros``), Altium / EasyEDA ``;FILE_FORMAT=2:5``, Siemens ``; Format : 3.3 /
  Absolute / MM / Leading``; other comments (``;TYPE=PLATED``, ...) are ignored;
* tool definitions ``T1C0.8`` with optional ``F``, ``S``, ``B``, ``H``, ``Z``
  parameters in any order (``T1F00S00C0.03150``).  A definition in the body
  (after the header) is allowed and also selects the tool, as a ``T`` word in
  the body does on the machine;
* tool selection ``T01`` (= ``T1``); ``T0`` unloads the tool;
* holes ``X..Y..``: with a decimal point, or implied decimals with leading
  (``TZ``) or trailing (``LZ``) zero suppression; signs; modal coordinates (a
  line with only ``X`` keeps the last ``Y``); ``R<n>X..Y..`` repeats a hole
  ``n`` times at that step;
* ``M30`` / ``M00`` end the program (later statements are ignored with a warning).

Slots to mill (issue #31 point 4), kept as paths in :attr:`HoleList.slot_paths_mm` with a
warning at the first of each kind: slots (``X..Y..G85X..Y..``) and routing (``G00`` ... ``M15``
/ ``G01`` / ``G02`` / ``G03`` ... ``M16``, until ``G05``; arcs as chords).  Left out, each with a
warning naming the line: routed circles (``G32`` / ``G33``) and canned text (``M97`` / ``M98``).
Every defined tool appears in :meth:`HoleList.tool_table` (with the holes it drills,
possibly 0).  Cadence Allegro's tool sizes come from its ``;T01 Holesize 1. = 12.0 ... MILS``
comments and an ``nc_param.txt`` beside the file (:func:`parse_nc_param`).  A tool that cannot
be drilled (zero size, over :data:`~cam.limits.MAX_TOOL_DIAMETER_MM`, a ``T0`` definition)
leaves its holes out with a warning (``strict=True``: an error); unused, it is ignored.  Repeated patterns (``M25`` ... ``M01`` / ``M02X..Y..``, ``M08``)
are refused with a :class:`~cam.errors.ParseError`: leaving them out would drop
holes without a trace.

**Zeros.** Excellon names the zeros a number *keeps*: ``LZ`` keeps leading zeros
(trailing ones may be dropped, so ``X0125`` in 3:3 is 12.5), ``TZ`` keeps
trailing zeros (leading ones may be dropped, so ``X12500`` in 3:3 is 12.5).  The
``excellon_zeros`` argument uses the same names.

**Defaults** when the file does not state them -- the first readings tried: what is
finally read is the most plausible reading (:func:`parse_excellon`) -- (each settable by the keyword
arguments ``excellon_units``, ``excellon_digits`` and ``excellon_zeros``, the job options of the same names
(:mod:`cam.options`, flags ``--excellon-units`` ...), which in turn give way to what the file says):

* units: ``"inch"`` -- Excellon's own default, and the unit of the OrCAD file in
  seed 000 §8.1, Table 8-1 (``X003000`` = 300 mil);
* digits: inch 2:4 (Table 8-1: six digits for 0.0001 in; also what gerbonara
  assumes for a bare ``INCH``), metric 3:3 (the KiCad and Eagle metric format);
* zeros: ``"TZ"`` (leading zeros suppressed) -- what old Eagle, gEDA, Fritzing
  and DipTrace files do and what gerbonara assumes.  Full-width numbers such as
  Table 8-1's read the same either way.

When a coordinate is read with a reading not stated in the file nor given by an
argument, the hole list carries one warning that names it and the runner-up.

**Fixed-width fields** (issue #44): coordinates all of one width with leading zeros kept and no format stated
(Allegro's ``X00130500Y00184500``, 3:5 inch; Zuken's ``.fdr``, 4:4) are tried in every integer:fraction split of
that width, and the hole sizes weigh them (:func:`_size_evidence`): holes do not cut into each other and a board is
much larger than its holes, so a 3.175 mm mounting hole rules out the 9 x 7 mm board of a 2:6 reading.  A
``--excellon-digits`` the file's comment hole sizes cannot fit is read as given, with a warning naming the
plausible format.  Allegro's ``ncdrill.log`` is read when there is no ``nc_param.txt``.

Frame: the board frame of the file, X right, Y up, in mm (inch values times 25.4).

Numbers are checked before use (:mod:`cam.limits`): coordinates and the positions they lead to
(incremental sums, ``G93`` zeros) at most :data:`~cam.limits.MAX_COORD_MM` either way, tool diameters
not negative (zero or over :data:`~cam.limits.MAX_TOOL_DIAMETER_MM`: the tool's holes are left out), tool numbers at most
:data:`~cam.limits.MAX_TOOL_NUMBER`, ``R`` repeats at most :data:`~cam.limits.MAX_REPEAT`, at most
:data:`~cam.limits.MAX_HOLES` holes; whole numbers (``G``, ``M``, ``T``, ``R``) have at most nine digits.

Errors raise :class:`~cam.errors.ParseError` with ``file:line: what: 'line
text'`` (``file:line:column`` for a bad number); recoverable oddities become
warnings with the same context.

>>> h = parse_excellon("M48\\nMETRIC,TZ,000.000\\nT1C0.8\\n%\\nT1\\nX12500Y-3000\\nY-5\\nM30\\n")
>>> h.holes_mm.tolist(), h.tool_table()
([[12.5, -3.0], [12.5, -0.005]], [(1, 0.8, 2)])
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import CamError, ParseError
from ..limits import MAX_COORD_MM, MAX_HOLES, MAX_REPEAT, MAX_TOOL_DIAMETER_MM, MAX_TOOL_NUMBER
from ..options import OPTIONS

__all__ = [
    "HoleList",
    "parse_excellon",
    "load_excellon",
    "DEFAULT_UNITS",
    "DEFAULT_DIGITS",
    "DEFAULT_ZEROS",
    "PLAUSIBLE_DRILL_MM",
    "PLAUSIBLE_BOARD_MM",
    "parse_nc_param",
]

DEFAULT_UNITS = "inch"
"""Units of a file that does not say (seed 000 §8.1, Table 8-1 is in inches)."""
DEFAULT_DIGITS = {"inch": (2, 4), "metric": (3, 3)}
"""Integer:fraction digits of implied-decimal numbers when the file does not say, per unit."""
DEFAULT_ZEROS = "TZ"
"""Trailing zeros kept, leading zeros suppressed, when the file does not say."""

MM_PER_INCH = 25.4
_UNIT_MM = {"inch": MM_PER_INCH, "metric": 1.0}

_WORD = re.compile(r"([A-Z])([+-]?[0-9.]*)")
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)")
_KICAD_FORMAT = re.compile(
    r"FORMAT\s*=\s*\{\s*([-0-9]+)\s*:\s*([-0-9]+)\s*/\s*(absolute|incremental)\s*/\s*(metric|inch)\s*/\s*([^}]*)\}",
    re.IGNORECASE,
)
_FILE_FORMAT = re.compile(r"FILE_FORMAT\s*=\s*([0-9])\s*:\s*([0-9])", re.IGNORECASE)
_SIEMENS_FORMAT = re.compile(
    r"Format\s*:\s*([0-9])\.([0-9])\s*/\s*(Absolute|Incremental)\s*/\s*(Inch|MM)\s*/\s*(Leading|Trailing)", re.IGNORECASE
)
# Header commands of the Excellon machines that say nothing about hole positions.
_QUIET_COMMANDS = {
    "VER", "DETECT", "ATC", "AFS", "BLKD", "CCW", "CP", "DN", "DTMDIST", "EXDA", "FSB", "HBCK", "NCSL", "OM48",
    "OSTOP", "OTCLMP", "PCKPARAM", "PF", "PPR", "PVS", "SBK", "SG", "SIXM", "TCST", "UP", "RSB", "ZA", "ZC", "ZS",
}
_TOOL_PARAMS = set("CFSBHZN")
_LETTERS = set("XYTGMRFSCBHZNAIJ")  # the address letters of Excellon statements
_HARMLESS_M = {6, 9, 45, 47, 50, 51, 52, 60, 61, 62, 63}  # tool change, messages, ...
_HARMLESS_G = {40, 41, 42, 4}  # cutter compensation, dwell


@dataclass
class HoleList:
    """The holes of a drill file, in the file's board frame.

    Attributes:
        holes_mm: ``(N, 2)`` float64 hole centres (X right, Y up, mm), in file order.
        tool_of_hole: ``(N,)`` int64 tool number of each hole.
        tools: tool number -> diameter in mm, every tool the file defines.
        line_of_hole: ``(N,)`` int64 source line (1-based) of each hole.
        warnings: ``"file:line: message: 'line text'"`` for each recoverable oddity.
        source: the file name used in messages.
        slot_paths_mm: the slots to mill, each a ``(K, 2)`` float64 path (K >= 2, board frame, mm): a ``G85``
            slot is its two ends, a route (``M15`` ... ``M16``) the points its ``G01`` / ``G02`` / ``G03`` moves
            pass (arcs as short chords).
        tool_of_slot, line_of_slot: ``(M,)`` int64 tool and first source line of each slot.
        skipped: tool -> number of its holes and slots left out because the tool cannot be drilled (zero size,
            larger than :data:`~cam.limits.MAX_TOOL_DIAMETER_MM`); such a tool is not in ``tools``.
    """

    holes_mm: np.ndarray
    tool_of_hole: np.ndarray
    tools: dict[int, float]
    line_of_hole: np.ndarray
    warnings: list[str] = field(default_factory=list)
    source: str = "<excellon>"
    slot_paths_mm: list[np.ndarray] = field(default_factory=list)
    tool_of_slot: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    line_of_slot: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    skipped: dict[int, int] = field(default_factory=dict)

    def extent_mm(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)``: the smallest and largest hole centre coordinates (mm), or of the slots' points in
        a file of slots only; all 0.0 without either (:meth:`points_mm` has both)."""
        pts = self.holes_mm if len(self.holes_mm) else self.points_mm()
        if len(pts) == 0:
            return (0.0, 0.0, 0.0, 0.0)
        lo = pts.min(axis=0)
        hi = pts.max(axis=0)
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    def points_mm(self) -> np.ndarray:
        """``(N, 2)`` every hole centre and slot point (mm), holes first."""
        return np.concatenate([np.asarray(self.holes_mm, np.float64).reshape(-1, 2)]
                              + [np.asarray(p, np.float64).reshape(-1, 2) for p in self.slot_paths_mm])

    def slot_count(self, tool: int) -> int:
        """How many slots ``tool`` mills."""
        return int(np.count_nonzero(np.asarray(self.tool_of_slot) == tool))

    def tool_table(self) -> list[tuple[int, float, int]]:
        """``[(tool, diameter_mm, hole_count)]`` for every *defined* tool, by tool number.

        Tools that drill no hole (e.g. only slots, left out) are listed with a count of 0.
        """
        tools, counts = np.unique(self.tool_of_hole, return_counts=True)
        count = dict(zip(tools.tolist(), counts.tolist()))
        return [(t, float(d), int(count.get(t, 0))) for t, d in sorted(self.tools.items())]


def _shown(text: str, most: int = 24) -> str:
    """Text as a message quotes it: at most ``most`` characters."""
    return text if len(text) <= most else text[:most - 3] + "..."


class _Reader:
    """State of one pass over a drill file (internal): what the file said so far, and the holes read.

    Statements go to the handlers of :data:`_WORD_HANDLERS` (by their first letter), header
    commands to :func:`_command` and comments to :func:`_comment`.
    """

    def __init__(self, source: str, units, digits, zeros, guess=None, max_lines: int | None = None) -> None:
        self.source = source
        # what the caller gave for "when the file does not say"
        self.opt_units, self.opt_digits, self.opt_zeros = units, digits, zeros
        # the reading tried for what neither says (_Guess), else the built-in defaults
        self.guess = guess
        self.max_lines = max_lines
        # what the file said (None = not stated)
        self.units: str | None = None
        self.digits: tuple[int, int] | None = None
        self.zeros: str | None = None
        self.fmat = 2
        self.state = "start"  # start, header, body, route, end
        self.seen_excellon = False
        self.incremental = False
        self.zero_mm = (0.0, 0.0)
        self.pos_mm = [0.0, 0.0]
        self.tool: int | None = None
        self.tools: dict[int, float] = {}
        self.holes: list[tuple[float, float]] = []
        self.hole_tool: list[int] = []
        self.hole_line: list[int] = []
        self.warnings: list[str] = []
        self.defaults_warned: set[str] = set()
        self.after_end: list[int] = []
        self.lineno = 0
        self.text = ""
        self.default_warnings: list[int] = []  # indexes into warnings of the "does not state" ones
        self.first_default_units: str | None = None  # the units where a number was first read by default
        self.bad_tools: dict[int, str] = {}  # tool -> why it cannot be drilled
        self.comment_tools: dict[int, float] = {}  # Allegro ';T01 Holesize 1. = 12.0 ... MILS': tool -> mm
        self.slots: list[tuple[list[tuple[float, float]], int, int]] = []  # (path, tool, line)
        self.route_path: list[tuple[float, float]] | None = None  # the route being cut (between M15 and M16)
        self.route_line = 0
        self.route_mode = 0  # G00 / G01 / G02 / G03 in routing
        self.warned_slot = self.warned_route = False

    # -- messages ---------------------------------------------------------------------------
    def where(self, col: int | None = None) -> str:
        return f"{self.source}:{self.lineno}" + (f":{col}" if col is not None else "")

    def error(self, message: str, col: int | None = None) -> ParseError:
        return ParseError(f"{self.where(col)}: {message}: '{_shown(self.text, 80)}'")

    def warn(self, message: str) -> None:
        self.warnings.append(f"{self.where()}: {message}: '{self.text}'")

    def not_excellon(self) -> ParseError:
        return ParseError(f"{self.where()}: not an Excellon drill file (this line is not an Excellon "
                          f"statement): '{self.text[:60]}'")

    # -- number format ----------------------------------------------------------------------
    def _setting(self, name: str):
        stated = getattr(self, name)
        if stated is not None:
            return stated, "file"
        given = getattr(self, "opt_" + name)
        if given is not None:
            return given, "option"
        return None, "default"

    def current_units(self) -> tuple[str, bool]:
        units, src = self._setting("units")
        guessed = self.guess.units if self.guess is not None else DEFAULT_UNITS
        return (units or guessed), src == "default"

    def current_format(self, units: str) -> tuple[tuple[int, int], str, list[str]]:
        """Digits and zeros for implied decimals, and which of them come from the built-in defaults."""
        digits, _ = self._setting("digits")
        zeros, _ = self._setting("zeros")
        assumed = []
        if digits is None:
            g = self.guess
            digits = g.digits if g is not None and g.digits_units == units else DEFAULT_DIGITS[units]
            assumed.append("digits")
        if zeros is None:
            zeros = self.guess.zeros if self.guess is not None else DEFAULT_ZEROS
            assumed.append("zeros")
        return digits, zeros, assumed

    def _warn_defaults(self, what: list[str], units: str, digits, zeros) -> None:
        what = [w for w in what if w not in self.defaults_warned]
        if not what:
            return
        self.defaults_warned.update(what)
        parts = []
        if "units" in what:
            parts.append(f"units ({units})")
        if "digits" in what:
            parts.append(f"digits ({digits[0]}:{digits[1]})")
        if "zeros" in what:
            parts.append(f"zeros ({zeros}: {'leading' if zeros == 'TZ' else 'trailing'} zeros suppressed)")
        self.default_warnings.append(len(self.warnings))
        if self.first_default_units is None:
            self.first_default_units = units
        self.warn("the file does not state its " + ", ".join(parts) + "; read with these defaults "
                  "(set --excellon-units / --excellon-digits / --excellon-zeros if the holes look wrong)")

    def value_mm(self, text: str, letter: str, col: int) -> float:
        """Read one number word (without its letter) as mm, with the current units and format; at most
        :data:`~cam.limits.MAX_COORD_MM` either way."""
        value_mm = self._value_mm(text, letter, col)
        if not abs(value_mm) <= MAX_COORD_MM:
            raise self.error(f"{letter}{_shown(text)} is out of range (at most {MAX_COORD_MM:g} mm either way)", col)
        return value_mm

    def _value_mm(self, text: str, letter: str, col: int) -> float:
        if not _NUMBER.fullmatch(text):
            raise self.error(f"{letter} needs a number, got '{_shown(text)}'" if text else f"{letter} without a number",
                             col)
        units, units_assumed = self.current_units()
        scale = _UNIT_MM[units]
        if "." in text:
            if units_assumed:
                self._warn_defaults(["units"], units, None, None)
            return float(text) * scale
        digits, zeros, assumed = self.current_format(units)
        if units_assumed:
            assumed.insert(0, "units")
        sign = -1 if text.startswith("-") else 1
        body = text.lstrip("+-")
        if not body.strip("0"):
            return 0.0  # zero in every format
        n_int, n_frac = digits
        if len(body) > n_int + n_frac:
            raise self.error(
                f"{letter}{_shown(text)} has {len(body)} digits, more than the {n_int}:{n_frac} format allows "
                f"({units}, {zeros})", col)
        if len(body) == n_int + n_frac and "zeros" in assumed:
            assumed.remove("zeros")  # a full-width number reads the same with LZ and TZ
        self._warn_defaults(assumed, units, digits, zeros)
        if zeros == "LZ":  # leading zeros kept: the digits are read from the left
            body = body.ljust(n_int + n_frac, "0")
        return sign * (int(body) * scale) / 10 ** n_frac

    def digits_of(self, a: str, b: str) -> tuple[int, int]:
        """``(integer, fraction)`` digit counts from their text; a ParseError if out of range."""
        try:
            digits = int(a), int(b)
        except ValueError:
            raise self.error(f"bad digit format {a}:{b}") from None
        if not (all(OPTIONS["excellon_digits"].in_range(d) for d in digits) and sum(digits) > 0):
            raise self.error(f"bad digit format {a}:{b}")
        return digits

    # -- words and positions ----------------------------------------------------------------
    def integer(self, word, most: int = 999_999_999) -> int:
        """A whole-number word 0..``most`` (at most nine digits, leading zeros aside)."""
        letter, text, col = word
        if not re.fullmatch(r"[+]?[0-9]+", text):
            raise self.error(f"{letter} needs a whole number, got '{_shown(text)}'", col)
        digits = text.lstrip("+").lstrip("0")
        if len(digits) > 9 or int(digits or "0") > most:
            raise self.error(f"{letter}{_shown(text)} is out of range (a whole number 0..{most})", col)
        return int(digits or "0")

    def xy(self, words) -> tuple[float | None, float | None]:
        x = y = None
        for letter, text, col in words:
            if letter == "X" and x is None:
                x = self.value_mm(text, letter, col)
            elif letter == "Y" and y is None:
                y = self.value_mm(text, letter, col)
            else:
                raise self.error(f"unexpected {letter}{text}", col)
        return x, y

    def move(self, words) -> tuple[float, float]:
        x, y = self.xy(words)
        if self.incremental:
            self.pos_mm[0] += x or 0.0
            self.pos_mm[1] += y or 0.0
        else:
            if x is not None:
                self.pos_mm[0] = self.zero_mm[0] + x
            if y is not None:
                self.pos_mm[1] = self.zero_mm[1] + y
        self.check_position()
        return self.pos_mm[0], self.pos_mm[1]

    def check_position(self) -> None:
        """Refuse a position (incremental sums, ``G93`` zeros) beyond :data:`~cam.limits.MAX_COORD_MM`."""
        for axis, v in zip("XY", self.pos_mm):
            if not abs(v) <= MAX_COORD_MM:
                raise self.error(f"the position {axis}{v:.6g} mm lies beyond {MAX_COORD_MM:g} mm from the origin")

    def hole(self) -> None:
        if self.tool is None:
            raise self.error("a hole before any tool is selected")
        if self.route_path is not None:
            return  # a position in a route: part of the cut
        if len(self.holes) >= MAX_HOLES:
            raise self.error(f"more than {MAX_HOLES} holes")
        self.holes.append((self.pos_mm[0], self.pos_mm[1]))
        self.hole_tool.append(self.tool)
        self.hole_line.append(self.lineno)

    # -- one line -----------------------------------------------------------------------------------
    def slot(self, path: list[tuple[float, float]], line: int) -> None:
        """A slot or route milled with the current tool along ``path`` (board mm)."""
        if self.tool is None:
            raise self.error("a slot before any tool is selected")
        if len(self.slots) >= MAX_HOLES:
            raise self.error(f"more than {MAX_HOLES} slots")
        if len(path) >= 2:
            self.slots.append((path, self.tool, line))

    def end_route(self) -> None:
        """``M16`` / ``M17`` / ``G05``: the tool lifts; the route cut so far becomes a slot."""
        if self.route_path is not None:
            self.slot(self.route_path, self.route_line)
        self.route_path = None

    def line(self, lineno: int, raw: str) -> None:
        self.lineno = lineno
        self.text = raw.strip()
        code, semi, note = self.text.partition(";")
        if semi:
            _comment(self, note)
        code = "".join(code.split()).upper()
        if code.startswith("/"):
            code = code[1:]  # block delete mark: the machine runs the line anyway unless told
        if not code:
            return
        if self.state == "end":
            if code != "%":  # a tape end mark after M30 is common and harmless
                self.after_end.append(lineno)
            return
        self.statement(code)

    def statement(self, line: str) -> None:
        if len(line) > MAX_STATEMENT_CHARS:  # before any word is split: every reading of the file meets it
            if not self.seen_excellon:
                raise self.not_excellon()
            raise self.error(f"a statement of {len(line):,} characters (drill files write under "
                             f"{MAX_STATEMENT_CHARS})", 1)
        if line == "%":
            if self.state == "header":
                self.state = "body"
            elif self.state == "start":
                self.state = "body"  # no header (seed 000 §8.1, Table 8-1)
            self.seen_excellon = True
            return
        if "," in line or line.isalpha() or line == "OM48" or re.fullmatch(r"M[0-9]+,.*", line):
            if _command(self, line):
                return
            if not self.seen_excellon:
                raise self.not_excellon()
            raise self.error("unknown statement")
        words = []
        pos = 0
        for m in _WORD.finditer(line):
            if m.start() != pos:
                break
            words.append((m.group(1), m.group(2), m.start() + 1))
            pos = m.end()
        if pos != len(line) or not words:
            if not self.seen_excellon:
                raise self.not_excellon()
            raise self.error("unknown statement", pos + 1 if pos < len(line) else None)
        if not self.seen_excellon and any(w[0] not in _LETTERS for w in words):
            raise self.not_excellon()
        letter = words[0][0]
        handler = _WORD_HANDLERS.get(letter)
        if handler is not None:
            handler(self, words)
        elif letter in "FS" and all(w[0] in "FS" for w in words):
            self.integer(words[0])  # feed / spindle speed: nothing to drill
        else:
            if not self.seen_excellon:
                raise self.not_excellon()
            raise self.error("unknown statement")


# ---------------------------------------------------------------------- format hints in comments
def _kicad_format(r: _Reader, m: re.Match) -> None:
    a, b, notation, units, zeros = m.groups()
    r.units = units.lower()
    r.incremental = notation.lower() == "incremental"
    if a != "-" and b != "-":
        r.digits = r.digits_of(a, b)
    z = zeros.strip().lower()
    if z.startswith("suppress leading") or z.startswith("keep"):
        r.zeros = "TZ"
    elif z.startswith("suppress trailing"):
        r.zeros = "LZ"


def _file_format(r: _Reader, m: re.Match) -> None:
    r.digits = r.digits_of(*m.groups())


def _siemens_format(r: _Reader, m: re.Match) -> None:
    a, b, notation, units, zeros = m.groups()
    r.digits = r.digits_of(a, b)
    r.incremental = notation.lower() == "incremental"
    r.units = "inch" if units.lower() == "inch" else "metric"
    r.zeros = "LZ" if zeros.lower() == "leading" else "TZ"


_HOLESIZE = re.compile(r"(?:\bT(\d+)\s+)?HOLESIZE\s+(\d+)\.?\s*=\s*([0-9]*\.?[0-9]+)(.*)", re.IGNORECASE)
_SIZE_UNITS_MM = {"MILS": 0.0254, "MIL": 0.0254, "MM": 1.0, "INCH": MM_PER_INCH, "INCHES": MM_PER_INCH, "IN": MM_PER_INCH}


def _size_mm(value: str, rest: str) -> float:
    """A size with the first unit word of ``rest`` (MILS, MM, INCH); Allegro writes mils when it does not say."""
    unit = next((w for w in re.findall(r"[A-Za-z]+", rest.upper()) if w in _SIZE_UNITS_MM), "MILS")
    return float(value) * _SIZE_UNITS_MM[unit]


def _holesize(r: _Reader, m: re.Match) -> None:
    """Cadence Allegro's ``;T01 Holesize 1. = 12.000000 Tolerance = ... PLATED MILS Quantity = 20``: the size of
    the tool the body selects with ``T01`` (a definition with ``C`` wins)."""
    tool, index, value, rest = m.groups()
    r.comment_tools[int(tool if tool is not None else index)] = _size_mm(value, rest)


_COMMENT_HANDLERS = ((_KICAD_FORMAT, _kicad_format), (_FILE_FORMAT, _file_format), (_SIEMENS_FORMAT, _siemens_format),
                     (_HOLESIZE, _holesize))
"""Format hints that CAD programs write in comments, tried in order; the first that matches is read."""


def _comment(r: _Reader, text: str) -> None:
    for pattern, handler in _COMMENT_HANDLERS:
        m = pattern.search(text)
        if m:
            handler(r, m)
            return


# ---------------------------------------------------------------------- statements
def _command(r: _Reader, line: str) -> bool:
    """Header style commands (``METRIC,TZ``, ``FMAT,2``, ``VER,1``, ...); False if ``line`` is not one."""
    head, comma, rest = line.partition(",")
    args = rest.split(",") if comma else []
    if re.fullmatch(r"M[0-9]+", head):  # M47,message / M97,text
        _m_word(r, [("M", head[1:], 1)])
        return True
    if head in ("METRIC", "INCH"):
        _units_command(r, head, args)
    elif head == "FMAT":
        if args not in (["1"], ["2"]):
            raise r.error("FMAT takes 1 or 2")
        r.fmat = int(args[0])
    elif head == "ICI":
        r.incremental = not args or args[0] != "OFF"
    elif head in _QUIET_COMMANDS:
        pass
    elif not r.seen_excellon or not re.fullmatch(r"[A-Z][A-Z0-9]*", head):
        return False
    else:
        r.warn(f"unknown header command {head} ignored")
    r.seen_excellon = True
    return True


def _units_command(r: _Reader, head: str, args: list[str]) -> None:
    """``METRIC`` / ``INCH`` with ``LZ`` / ``TZ`` and a ``000.000`` digit format, in any order."""
    r.units = "metric" if head == "METRIC" else "inch"
    for a in args:
        if a in ("LZ", "TZ"):
            r.zeros = a
        elif re.fullmatch(r"0*\.0*", a) and a != ".":
            i, _, f = a.partition(".")
            r.digits = r.digits_of(str(len(i)), str(len(f)))
        elif a:
            raise r.error(f"unknown {head} option '{a}'")


def _coordinates(r: _Reader, words) -> None:
    r.seen_excellon = True
    if r.state in ("start", "header"):
        r.state = "body"  # holes inside the header: many files do it
    g = [i for i, w in enumerate(words) if w[0] == "G"]
    if g:
        i = g[0]
        code = r.integer(words[i])
        if code != 85:
            raise r.error(f"unexpected G{words[i][1]} after coordinates", words[i][2])
        r.move(words[:i])
        start = tuple(r.pos_mm)
        r.move(words[i + 1:])
        if not r.warned_slot:
            r.warned_slot = True
            r.warn(f"slot (G85) from X{start[0]:.3f} Y{start[1]:.3f} to X{r.pos_mm[0]:.3f} "
                   f"Y{r.pos_mm[1]:.3f} mm: slots are milled with their tool (plunge, along the slot, lift)")
        r.slot([start, (r.pos_mm[0], r.pos_mm[1])], r.lineno)
        return
    if r.state == "route":
        _route_move(r, words)
        return
    r.move(words)
    r.hole()


def _tool_word(r: _Reader, words) -> None:
    r.seen_excellon = True
    number = r.integer(words[0], MAX_TOOL_NUMBER)
    params = {}
    for letter, text, col in words[1:]:
        if letter not in _TOOL_PARAMS or letter in params:
            raise r.error(f"unexpected {letter}{text} in a tool definition", col)
        params[letter] = (text, col)
    if not params:  # selection
        if number == 0:
            r.tool = None
            return
        if number not in r.tools and number in r.comment_tools:
            r.tools[number] = r.comment_tools[number]  # Allegro: the size is in a comment or nc_param.txt
        if number not in r.tools:
            raise r.error(f"tool T{number} is selected but never defined")
        r.tool = number
        return
    if "C" not in params:
        if number in r.tools:  # T1F200S100 in the body: feeds and speeds of a known tool
            if r.state != "header":
                r.tool = number
            return
        raise r.error(f"tool T{number} is defined without a diameter (C)")
    _define_tool(r, number, *params["C"])


def _define_tool(r: _Reader, number: int, text: str, col: int) -> None:
    """``T<number>C<text>``: a tool's diameter; in the body the definition also selects the tool."""
    if not _NUMBER.fullmatch(text):
        raise r.error(f"tool T{number} has a bad diameter '{text}'", col)
    dia_mm = r.value_mm(text, "C", col)
    if dia_mm < 0:
        raise r.error(f"tool T{number} has a bad diameter {_shown(text)} (must be > 0 and at most "
                      f"{MAX_TOOL_DIAMETER_MM:g} mm)", col)
    if number == 0:  # T0 unloads the tool: a definition of it can drill nothing (issue #31 point 3)
        r.bad_tools[0] = f"T0 {dia_mm:.3f} mm (T0 unloads the tool)"
        return
    if dia_mm == 0 or dia_mm > MAX_TOOL_DIAMETER_MM:  # not a bad file: its holes are left out, if it has any
        why = "zero size" if dia_mm == 0 else f"larger than the {MAX_TOOL_DIAMETER_MM:g} mm a drill may be"
        r.bad_tools[number] = f"T{number} {dia_mm:.3f} mm ({why})"
    else:
        r.bad_tools.pop(number, None)
    if number in r.tools and abs(r.tools[number] - dia_mm) > 1e-9:
        r.warn(f"tool T{number} redefined: {r.tools[number]:.4f} mm -> {dia_mm:.4f} mm")
    r.tools[number] = dia_mm
    if r.state in ("body", "route"):
        r.tool = number  # a T word in the body selects the tool (seed 000 §8.1, Table 8-1)
    if r.state == "start":
        r.state = "header"


def _g_word(r: _Reader, words) -> None:
    code = r.integer(words[0])
    rest = words[1:]
    if code in (0, 1, 2, 3):
        if r.state != "route" and not r.warned_route:
            r.warned_route = True
            r.warn("routing (G00/G01/G02/G03 with M15/M16): routes are milled with their tool up to the next G05")
        r.state = "route"
        r.route_mode = code
        if code == 0:
            r.end_route()  # a rapid move lifts the tool
        if rest:
            _route_move(r, rest)
    elif code in (5, 81):
        r.end_route()
        if r.state in ("start", "header", "route"):
            r.state = "body"
        if rest:
            _coordinates(r, rest)
    elif code in (90, 91):
        if rest:
            raise r.error(f"G{code} takes no coordinates", rest[0][2])
        r.incremental = code == 91
    elif code == 93:
        x, y = r.xy(rest)
        r.zero_mm = (x or 0.0, y or 0.0)
    elif code in (32, 33):
        r.warn(f"routed circle (G{code}) is not drilled: left out")
    elif code == 85:
        raise r.error("G85 slot without a start point")
    elif code in _HARMLESS_G and not rest:
        pass
    elif not r.seen_excellon:
        raise r.not_excellon()
    elif rest:
        raise r.error(f"unsupported G{code} with coordinates")
    else:
        r.warn(f"G{code} ignored")
    r.seen_excellon = True


def _route_move(r: _Reader, words) -> None:
    """A move in routing: with the tool down (after ``M15``) it extends the route being cut; ``G02`` / ``G03``
    arcs (centre by ``I`` / ``J`` from the start, or radius ``A``) become chords of at most 0.01 mm error."""
    allowed = [w for w in words if w[0] in "XY"]
    others = [w for w in words if w[0] not in "XYAIJ"]
    if others:
        raise r.error(f"unexpected {others[0][0]}{others[0][1]} in a routing move", others[0][2])
    start = (r.pos_mm[0], r.pos_mm[1])
    r.move(allowed)
    end = (r.pos_mm[0], r.pos_mm[1])
    if r.route_path is None:
        return
    if r.route_mode in (2, 3):
        arc = {w[0]: r.value_mm(w[1], w[0], w[2]) for w in words if w[0] in "AIJ"}
        r.route_path.extend(_arc_points(start, end, arc, r.route_mode == 2))
    else:
        r.route_path.append(end)


def _arc_points(start, end, arc: dict[str, float], clockwise: bool) -> list[tuple[float, float]]:
    """Points after ``start`` up to ``end`` along a routed arc (``I``/``J`` centre offsets or ``A`` radius)."""
    sx, sy = start
    ex, ey = end
    if "I" in arc or "J" in arc:
        cx, cy = sx + arc.get("I", 0.0), sy + arc.get("J", 0.0)
    elif "A" in arc and arc["A"] > 0:
        radius = arc["A"]
        mx, my = (sx + ex) / 2, (sy + ey) / 2
        dx, dy = ex - sx, ey - sy
        half = np.hypot(dx, dy) / 2
        if half == 0 or half > radius:
            return [end]
        h = np.sqrt(radius * radius - half * half)
        side = -1.0 if clockwise else 1.0  # the short arc
        cx, cy = mx - side * h * dy / (2 * half), my + side * h * dx / (2 * half)
    else:
        return [end]
    radius = float(np.hypot(sx - cx, sy - cy))
    a0, a1 = np.arctan2(sy - cy, sx - cx), np.arctan2(ey - cy, ex - cx)
    sweep = a1 - a0
    if clockwise:
        sweep = sweep if sweep < 0 else sweep - 2 * np.pi
    else:
        sweep = sweep if sweep > 0 else sweep + 2 * np.pi
    if radius <= 0:
        return [end]
    step = 2 * np.arccos(max(-1.0, 1 - 0.01 / radius)) if radius > 0.01 else np.pi / 2
    n = int(min(max(2, np.ceil(abs(sweep) / step)), 720))
    t = a0 + sweep * np.arange(1, n) / n
    return [(float(cx + radius * np.cos(a)), float(cy + radius * np.sin(a))) for a in t] + [end]


def _m_word(r: _Reader, words) -> None:
    code = r.integer(words[0])
    rest = words[1:]
    if code == 48:
        if r.holes or r.tool is not None:
            r.warn("M48 (header start) after holes: ignored")
        else:
            r.state = "header"
    elif code == 95:
        r.state = "body"
    elif code in (30, 0) or (code == 2 and r.fmat == 1 and not rest):
        r.state = "end"
    elif code == 2 and not rest:
        r.warn("M02 (end of pattern in FMAT,2) without a pattern: read as the end of the program")
        r.state = "end"
    elif code in (71, 72):
        r.units = "metric" if code == 71 else "inch"
    elif code == 15:  # plunge: the route starts here
        if r.tool is None:
            raise r.error("a route before any tool is selected")
        r.end_route()
        r.route_path = [(r.pos_mm[0], r.pos_mm[1])]
        r.route_line = r.lineno
    elif code in (16, 17):  # retract: the route ends
        r.end_route()
    elif code in (25, 1, 8) or code == 2:
        raise r.error(f"repeated patterns (M25/M01/M02/M08) are not supported (M{words[0][1]})")
    elif code in (97, 98):
        r.warn(f"canned text (M{code}) is not drilled: left out")
    elif code in _HARMLESS_M:
        pass
    elif not r.seen_excellon:
        raise r.not_excellon()
    else:
        r.warn(f"M{code} ignored")
    if rest:
        raise r.error(f"M{code} takes no coordinates", rest[0][2])
    r.seen_excellon = True


def _repeat(r: _Reader, words) -> None:
    """``R<n>X..Y..``: ``n`` holes, each a step on from the last.  The same as ``n`` steps and holes one by one
    (the positions summed in the same order, the same error at the same step), worked out with numpy: a file's
    readings tried for plausibility each expand every repeat, and 101 ``R10000`` lines took 20 s one by one."""
    count = r.integer(words[0], MAX_REPEAT)
    if r.state == "route":
        raise r.error("a repeated hole (R) while routing")
    x, y = r.xy(words[1:])
    if count:
        xs = np.cumsum(np.concatenate([[r.pos_mm[0]], np.full(count, x or 0.0)]))[1:]
        ys = np.cumsum(np.concatenate([[r.pos_mm[1]], np.full(count, y or 0.0)]))[1:]
        bad = np.flatnonzero(~((np.abs(xs) <= MAX_COORD_MM) & (np.abs(ys) <= MAX_COORD_MM)))
        stop = int(bad[0]) if len(bad) else count  # the first step beyond the limit (check_position's rule)
        if r.tool is None:
            stop = 0  # hole() refuses the first step (after its position check)
        elif r.route_path is None:  # (in a route hole() keeps nothing: only the positions are checked)
            stop = min(stop, MAX_HOLES - len(r.holes))  # hole() refuses the step that passes MAX_HOLES
            r.holes.extend(zip(xs[:stop].tolist(), ys[:stop].tolist()))
            r.hole_tool.extend([r.tool] * stop)
            r.hole_line.extend([r.lineno] * stop)
        if stop < count:  # that step by hand: its position check, then its hole, raise as they do
            r.pos_mm[0], r.pos_mm[1] = float(xs[stop]), float(ys[stop])
            r.check_position()
            r.hole()
        r.pos_mm[0], r.pos_mm[1] = float(xs[-1]), float(ys[-1])
    r.seen_excellon = True


_WORD_HANDLERS = {"X": _coordinates, "Y": _coordinates, "T": _tool_word, "G": _g_word, "M": _m_word, "R": _repeat}
"""Statements by their first letter (``F`` / ``S`` feeds and speeds are read and dropped)."""


def _check_options(excellon_units, excellon_digits, excellon_zeros) -> None:
    """The keywords against their job options' one declaration (:data:`cam.options.OPTIONS`)."""
    for name, value in (("excellon_units", excellon_units), ("excellon_zeros", excellon_zeros)):
        choices = OPTIONS[name].choices
        if value is not None and value not in choices:
            raise CamError(f"{name} must be " + " or ".join(repr(c) for c in choices) + f", got {value!r}")
    if excellon_digits is not None:
        o = OPTIONS["excellon_digits"]
        ok = (isinstance(excellon_digits, (tuple, list)) and len(excellon_digits) == 2
              and all(isinstance(d, (int, np.integer)) and o.in_range(float(d)) for d in excellon_digits)
              and sum(excellon_digits) > 0)
        if not ok:
            raise CamError(f"excellon_digits must be (integer, fraction) digit counts {o.range_text()} such as "
                           f"(2, 4), got {excellon_digits!r}")


# ---------------------------------------------------------------------- reading by plausibility
PLAUSIBLE_DRILL_MM = (0.1, 6.5)
"""Tool diameters a drill file plausibly holds (issue #31 point 2)."""
PLAUSIBLE_BOARD_MM = 500.0
"""The largest board a drill file plausibly holds, either way."""
_PITCHES_MM = np.array([0.5, 0.635, 0.65, 0.8, 1.0, 1.27, 1.5, 1.778, 2.0, 2.5, 2.54, 3.0, 3.5, 3.81, 3.96, 5.0,
                        5.08, 7.62])
"""Distances between neighbouring holes that boards are made of (pin pitches in mm and in tenths of an inch)."""
_GUESS_LINES = 1500
"""How many lines of a file the readings are tried on (the chosen one then reads the whole file)."""
_DIGIT_CHOICES = {"inch": ((2, 4), (2, 3), (2, 5), (3, 3)), "metric": ((3, 3), (4, 2), (3, 2), (4, 3))}
_NUMBER_TEXT = re.compile(r"[XY][+-]?([0-9]+)(?![0-9.])")


@dataclass(frozen=True)
class _Guess:
    """A reading of what a file does not state: its units, the digits in those units, its zeros."""

    units: str
    digits: tuple[int, int]
    zeros: str

    @property
    def digits_units(self) -> str:
        return self.units

    def describe(self, what: set[str]) -> str:
        parts = []
        if "units" in what:
            parts.append(self.units)
        if "digits" in what:
            parts.append(f"{self.digits[0]}:{self.digits[1]}")
        if "zeros" in what:
            parts.append(f"{self.zeros} ({'leading' if self.zeros == 'TZ' else 'trailing'} zeros suppressed)")
        return " ".join(parts)


def _read(text: str, source: str, units, digits, zeros, guess: _Guess | None = None,
          max_lines: int | None = None, params: dict | None = None) -> _Reader:
    r = _Reader(source, units, digits, zeros, guess, max_lines)
    if params:
        _apply_params(r, params)
    for lineno, raw in enumerate(text.splitlines(), start=1):
        if max_lines is not None and lineno > max_lines:
            break
        r.line(lineno, raw)
    r.end_route()
    return r


def _plausibility(r: _Reader, numbers: list[str], guess: _Guess | None) -> tuple[float, str]:
    """How implausible a reading is (lower is better) and why, in a few words: its holes should lie on
    the pitches boards are made of, its tools be drills of 0.1-6.5 mm, its board fit in half a metre and be much
    larger than its holes, its holes not cut into each other (:func:`_size_evidence`), and its numbers' zeros be
    the kind it suppresses (a leading-zero number shorter than the format is not trailing-zero, and the other way
    round).  ``guess``: the reading tried (None: the options given, whose zeros are not weighed)."""
    penalty = 0.0
    holes = np.array(r.holes, np.float64).reshape(-1, 2)
    pts = np.concatenate([holes] + [np.array(p, np.float64) for p, _, _ in r.slots])
    used = [t for t in set(r.hole_tool) | {t for _, t, _ in r.slots} if t in r.tools]
    lo, hi = PLAUSIBLE_DRILL_MM
    odd_tools = [t for t in used if not lo <= r.tools[t] <= hi]
    if used:
        penalty += 4.0 * len(odd_tools) / len(used)
    span = (pts.max(axis=0) - pts.min(axis=0)) if len(pts) else np.zeros(2)
    if span.max() > PLAUSIBLE_BOARD_MM:
        penalty += 10.0
    if len(pts) >= 4 and span.max() < 2.0:
        penalty += 5.0
    on_pitch = 0.0
    nearest = np.zeros(0)
    if len(holes) >= 3:
        sample = holes[:: max(1, len(holes) // 600)]
        d = np.hypot(*(sample[:, None, :] - sample[None, :, :]).transpose(2, 0, 1))
        d[d < 1e-6] = np.inf
        nearest = d.min(axis=1)
        nearest = nearest[np.isfinite(nearest)]
        if len(nearest):
            err = np.abs(nearest[:, None] - _PITCHES_MM[None, :]).min(axis=1)
            on_pitch = float(np.mean(err <= np.maximum(0.012, 0.004 * nearest)))
            penalty += 2.0 * (1.0 - on_pitch)
    size_penalty, size_why = _size_evidence(r)
    penalty += size_penalty
    if guess is not None:
        width = sum(guess.digits)
        short = [n for n in numbers if len(n) < width]
        if short:
            wrong = sum(1 for n in short if (n.startswith("0") if guess.zeros == "TZ" else n.endswith("0")))
            penalty += 3.0 * wrong / len(short)
    why = f"{span[0]:.1f} x {span[1]:.1f} mm"
    if odd_tools:
        why += ", tools " + ", ".join(f"T{t} {r.tools[t]:.3f} mm" for t in sorted(odd_tools)[:3])
    if len(holes) >= 3:
        why += f", {on_pitch:.0%} of holes at a usual pitch from their neighbour"
    why += "".join(", " + w for w in size_why)
    return penalty, why


BOARD_PER_HOLE = 5.0
"""A board's hole centres span at least this many times its largest hole (a board is larger than its holes by a
lot): a reading that makes a board smaller is implausible."""
SMALLEST_BOARD_MM = 5.0
"""The smallest board a drill file plausibly holds (its holes' centres span at least this)."""


def _size_evidence(r: _Reader) -> tuple[float, list[str]]:
    """What the hole sizes say of a reading's positions (penalty, reasons): holes are drilled apart, so a hole
    whose nearest neighbour is closer than their mean diameter (the two cut into each other) is implausible, and so
    is a board under :data:`SMALLEST_BOARD_MM` or under :data:`BOARD_PER_HOLE` times its largest hole.  Telling
    when the sizes do not scale with the reading (Allegro's ``;T01 Holesize`` comments, ``nc_param.txt``)."""
    holes = np.array(r.holes, np.float64).reshape(-1, 2)
    dia_mm = np.array([r.tools.get(t, np.nan) for t in r.hole_tool], np.float64)
    lo, hi = PLAUSIBLE_DRILL_MM  # an odd tool is weighed as such (:func:`_plausibility`), not its holes' sizes
    known = np.isfinite(dia_mm) & (dia_mm >= lo) & (dia_mm <= hi)
    holes, dia_mm = holes[known], dia_mm[known]
    if len(holes) < 2:
        return 0.0, []
    penalty, why = 0.0, []
    step = max(1, len(holes) // 600)
    sample, sample_dia = holes[::step], dia_mm[::step]
    d_mm = np.hypot(*(sample[:, None, :] - sample[None, :, :]).transpose(2, 0, 1))
    d_mm[d_mm < 1e-6] = np.inf  # a hole drilled twice is not two holes
    j = np.argmin(d_mm, axis=1)
    near_mm = d_mm[np.arange(len(sample)), j]
    finite = np.isfinite(near_mm)
    if finite.any():
        cut = near_mm[finite] < 0.5 * (sample_dia[finite] + sample_dia[j[finite]])
        overlap = float(np.mean(cut))
        if overlap > 0:
            penalty += 6.0 * overlap
            why.append(f"{overlap:.0%} of holes cut into their neighbour")
    span_mm = float((holes.max(axis=0) - holes.min(axis=0)).max())
    biggest_mm = float(dia_mm.max())
    if span_mm < SMALLEST_BOARD_MM:
        penalty += 3.0
        why.append(f"a board under {SMALLEST_BOARD_MM:g} mm")
    elif span_mm < BOARD_PER_HOLE * biggest_mm:
        penalty += 3.0
        why.append(f"a board under {BOARD_PER_HOLE:g} times its {biggest_mm:.3f} mm hole")
    return penalty, why


def _fixed_width(numbers: list[str]) -> int | None:
    """The width of a fixed-width number field with no zero suppression (every coordinate the same number of
    digits, some with a leading zero: ``X00130500``), else None."""
    widths = {len(n) for n in numbers}
    if len(numbers) >= 2 and len(widths) == 1 and any(n.startswith("0") for n in numbers):
        width = widths.pop()
        return width if width >= 2 else None
    return None


def _fixed_digits(width: int) -> list[tuple[int, int]]:
    """The digit formats of a ``width``-digit field: every integer:fraction split the options allow."""
    o = OPTIONS["excellon_digits"]
    return [(i, width - i) for i in range(1, width) if o.in_range(float(i)) and o.in_range(float(width - i))]


def _guesses(unstated: set[str], units, digits, zeros, stated_units: str, fixed_width: int | None = None
             ) -> list[_Guess]:
    """The readings to try, the built-in defaults first (a given option is never varied); ``stated_units``: the
    units in effect where the first number was read by default; ``fixed_width``: the width of a fixed-width field
    (:func:`_fixed_width`), whose every integer:fraction split is tried too (with one zeros: full-width numbers
    read alike)."""
    if units is not None or "units" not in unstated:
        all_units: tuple[str, ...] = (units or stated_units,)
    else:
        all_units = (DEFAULT_UNITS, "metric")
    out = []
    for u in all_units:
        digit_choices = (tuple(digits),) if digits is not None else (
            _DIGIT_CHOICES[u] if "digits" in unstated else (DEFAULT_DIGITS[u],))
        zero_choices = (zeros,) if zeros is not None else ((DEFAULT_ZEROS, "LZ") if "zeros" in unstated
                                                           else (DEFAULT_ZEROS,))
        for d in digit_choices:
            for z in zero_choices:
                out.append(_Guess(u, tuple(d), z))
        if fixed_width is not None and digits is None and "digits" in unstated:
            tried = {tuple(d) for d in digit_choices}
            out += [_Guess(u, d, zero_choices[0]) for d in _fixed_digits(fixed_width) if d not in tried]
    return out


def _choose(text: str, source: str, units, digits, zeros, params, first: _Reader | None
            ) -> tuple[_Guess, str] | None:
    """The most plausible reading of what the file does not state, and the warning naming it and the
    runner-up; None when no reading reads the first lines.  ``first``: the first lines read with the defaults
    (None when they cannot be: a number too long for the default digits, say; then every reading is tried, and
    what the file leaves unstated is what the readings that read it assumed)."""
    unstated = set(first.defaults_warned) if first is not None else {"units", "digits", "zeros"}
    numbers = _NUMBER_TEXT.findall("\n".join(text.splitlines()[:_GUESS_LINES]).upper())
    scored = []
    stated_units = (first.first_default_units if first is not None else None) or DEFAULT_UNITS
    for k, guess in enumerate(_guesses(unstated, units, digits, zeros, stated_units, _fixed_width(numbers))):
        try:
            r = _read(text, source, units, digits, zeros, guess, _GUESS_LINES, params)
        except ParseError:
            continue
        penalty, why = _plausibility(r, numbers, guess)
        key = np.round(np.array(r.holes, np.float64), 6).tobytes() + repr(sorted(r.tools.items())).encode()
        scored.append((penalty + (0.15 if k else 0.0) + 0.01 * k, k, guess, why, key, r.defaults_warned))
    if not scored:
        return None
    scored.sort(key=lambda s: s[:2])
    best = scored[0]
    if first is None:
        unstated = set(best[5]) or unstated
    runner = next((s for s in scored[1:] if s[4] != best[4]), None)
    note = f"read as the most plausible: {best[2].describe(unstated)} ({best[3]})"
    if runner is not None:
        note += f"; the runner-up {runner[2].describe(unstated)} gives {runner[3]}"
    return best[2], note


MAX_STATEMENT_CHARS = 10_000
"""The longest statement read; a longer line is an error naming it (a coordinate line is under 40 characters, a
header line under 100; a number of a few thousand digits still gets its own range error), so a 100,000-character
line is not split into words once per reading tried."""


# ---------------------------------------------------------------------- nc_param.txt (Allegro)
NC_PARAM_NAME = "nc_param.txt"
"""The parameter file Cadence Allegro writes beside its drill files: the format and (tool lines) the sizes."""
NC_LOG_NAME = "ncdrill.log"
"""The log Allegro writes with its drill files: the same parameters and a tool table; read when there is no
:data:`NC_PARAM_NAME`."""


def parse_nc_param(text: str, source: str = NC_PARAM_NAME) -> dict:
    """What an Allegro ``nc_param.txt`` (or the parameter lines of its ``ncdrill.log``) states: ``{"units",
    "digits", "zeros", "incremental", "tools"}`` (only the keys it states; ``tools`` maps tool number -> mm from
    lines ``T01 12.0 MILS`` or the log's ``T01  1.  12.0  +2.0/-2.0  PLATED  34``).

    ``FORMAT 3.5`` (or ``INTEGER-PLACES`` / ``DECIMAL-PLACES``) gives the digits; ``SUPPRESS-LEAD-ZEROES`` and
    ``SUPPRESS-TRAIL-ZEROES`` both ``NO`` state full-width numbers, read alike either way (``"TZ"``).

    >>> parse_nc_param("FORMAT 2.5\\nOUTPUT-UNITS ENGLISH\\nSUPPRESS-LEAD-ZEROES YES\\nT01 12.0\\n")["digits"]
    (2, 5)
    """
    out: dict = {"tools": {}}
    suppress: dict[str, bool] = {}
    size_unit = ""
    n_int = n_frac = None
    for raw in text.splitlines():
        words = raw.strip().split()
        if len(words) < 2:
            continue
        key, value = words[0].upper(), words[1].upper()
        if key == "FORMAT" and re.fullmatch(r"[0-9]\.[0-9]", value):
            n_int, n_frac = int(value[0]), int(value[2])
        elif key == "INTEGER-PLACES" and value.isdigit() and len(value) == 1:
            n_int = int(value)
        elif key == "DECIMAL-PLACES" and value.isdigit() and len(value) == 1:
            n_frac = int(value)
        elif key == "OUTPUT-UNITS":
            out["units"] = "inch" if value in ("ENGLISH", "INCH", "INCHES") else "metric"
            size_unit = "MILS" if out["units"] == "inch" else "MM"
        elif key in ("SUPPRESS-LEAD-ZEROES", "SUPPRESS-TRAIL-ZEROES") and value in ("YES", "NO"):
            suppress[key] = value == "YES"
        elif key == "COORDINATES":
            out["incremental"] = value.startswith("INCREMENTAL")
        elif re.fullmatch(r"T[0-9]+", key) and re.fullmatch(r"[0-9]*\.?[0-9]+", value):
            out["tools"][int(key[1:])] = _size_mm(value, " ".join(words[2:] + [size_unit]))
        elif (re.fullmatch(r"T[0-9]+", key) and re.fullmatch(r"[0-9]+\.", value) and len(words) >= 3
              and re.fullmatch(r"[0-9]*\.?[0-9]+", words[2])):  # ncdrill.log: tool, index, size, ...
            out["tools"][int(key[1:])] = _size_mm(words[2], " ".join(words[3:] + [size_unit]))
    if n_int is not None and n_frac is not None:
        out["digits"] = (n_int, n_frac)
    if suppress.get("SUPPRESS-LEAD-ZEROES"):
        out["zeros"] = "TZ"
    elif suppress.get("SUPPRESS-TRAIL-ZEROES"):
        out["zeros"] = "LZ"
    elif len(suppress) == 2:
        out["zeros"] = "TZ"  # no suppression: full-width numbers, read alike with TZ and LZ
    return out


def _apply_params(r: _Reader, params: dict) -> None:
    r.units = params.get("units", r.units)
    r.digits = params.get("digits", r.digits)
    r.zeros = params.get("zeros", r.zeros)
    r.incremental = params.get("incremental", r.incremental)
    r.comment_tools.update(params.get("tools", {}))


# ---------------------------------------------------------------------- the reader
def parse_excellon(
    text: str,
    *,
    source: str = "<excellon>",
    excellon_units: str | None = None,
    excellon_digits: tuple[int, int] | None = None,
    excellon_zeros: str | None = None,
    strict: bool = False,
    nc_param: str | None = None,
) -> HoleList:
    """Read the holes and slots of an Excellon drill program (pure: no I/O).

    Args:
        text: the whole file.
        source: file name used in messages.
        excellon_units: "inch" or "metric" when the file does not say.
        excellon_digits: (integer, fraction) digits of implied-decimal numbers when the file does not say.
        excellon_zeros: "LZ" (leading zeros kept) or "TZ" (trailing zeros kept) when the file does not say.

        The three are the job options of the same names (:data:`cam.options.OPTIONS`, ``--excellon-units``,
        ``--excellon-digits``, ``--excellon-zeros``).  What neither the file nor they say is chosen by
        plausibility (issue #31 point 2): of the readings (units, digits, zeros; the built-in defaults first,
        :data:`DEFAULT_UNITS`, :data:`DEFAULT_DIGITS`, :data:`DEFAULT_ZEROS`), the one whose holes lie at the
        pitches boards are made of, whose tools are drills of :data:`PLAUSIBLE_DRILL_MM`, whose board fits in
        :data:`PLAUSIBLE_BOARD_MM` and whose numbers' zeros are the kind it suppresses; one warning names it
        and the runner-up.
        strict: refuse a used tool that cannot be drilled (zero size, larger than
            :data:`~cam.limits.MAX_TOOL_DIAMETER_MM`) instead of leaving its holes out with a warning.
        nc_param: the text of an Allegro ``nc_param.txt`` beside the file (:func:`parse_nc_param`): what it
            states counts as stated by the file.

    Returns:
        The holes (board frame, mm) with their tools, lines and warnings; the slots to mill.

    Raises:
        ParseError: not an Excellon file, a number the format cannot read, a hole without a tool,
            a tool selected but never defined, a negative diameter, a board that no reading fits in half a
            metre, a tool that cannot be drilled with ``strict`` ... (``file:line: what: 'line text'``).
        CamError: a bad keyword argument.
    """
    _check_options(excellon_units, excellon_digits, excellon_zeros)
    digits = tuple(excellon_digits) if excellon_digits is not None else None
    params = parse_nc_param(nc_param) if nc_param else None
    chosen = None
    try:  # the first lines tell whether anything is read by default
        sample = _read(text, source, excellon_units, digits, excellon_zeros, None, _GUESS_LINES, params)
    except ParseError:
        sample = None  # the whole reading below names the error
    if sample is None or sample.defaults_warned:
        chosen = _choose(text, source, excellon_units, digits, excellon_zeros, params, sample)
    r = _read(text, source, excellon_units, digits, excellon_zeros, chosen[0] if chosen else None, None, params)
    if not r.seen_excellon:
        raise ParseError(f"{source}: not an Excellon drill file (no header, tool or hole)")
    lines = text.splitlines()
    if r.default_warnings:  # one warning, where the first number read so was, naming the choice and the runner-up
        first = r.warnings[r.default_warnings[0]]
        stated = first.split("; read with these defaults")[0]
        note = chosen[1] if chosen is not None else "read with these defaults"
        line_text = first[first.rindex(": '"):]
        merged = (f"{stated}; {note} (set --excellon-units / --excellon-digits / --excellon-zeros if the holes "
                  f"look wrong){line_text}")
        if len(r.default_warnings) > 1:  # the other fields came later: name them in the one warning
            for k in r.default_warnings[1:]:
                more = r.warnings[k].split("does not state its ", 1)[1].split("; read with")[0]
                merged = merged.replace(" does not state its ", f" does not state its {more}, ", 1)
        drop = set(r.default_warnings)
        r.warnings = [merged if k == r.default_warnings[0] else w for k, w in enumerate(r.warnings) if k == r.default_warnings[0] or k not in drop]
    if r.after_end:
        r.lineno = r.after_end[0]
        r.text = lines[r.lineno - 1].strip()
        r.warn(f"{len(r.after_end)} statement(s) after the end of the program (M30/M00) ignored")
    skipped = _bad_tools(r, strict)
    _check_plausible(r, chosen is not None, any(v is not None for v in (excellon_units, digits, excellon_zeros)))
    if digits is not None and r.digits is None:
        _check_given_digits(r, text, excellon_units, digits, excellon_zeros, params)
    if not r.holes and not r.slots:
        r.warnings.append(f"{source}: no holes to drill")
    holes = np.array(r.holes, np.float64).reshape(-1, 2)
    return HoleList(
        holes_mm=holes,
        tool_of_hole=np.array(r.hole_tool, np.int64),
        tools={t: d for t, d in r.tools.items() if t not in r.bad_tools},
        line_of_hole=np.array(r.hole_line, np.int64),
        warnings=r.warnings,
        source=source,
        slot_paths_mm=[np.array(p, np.float64) for p, _, _ in r.slots],
        tool_of_slot=np.array([t for _, t, _ in r.slots], np.int64),
        line_of_slot=np.array([ln for _, _, ln in r.slots], np.int64),
        skipped=skipped,
    )


def _bad_tools(r: _Reader, strict: bool) -> dict[int, int]:
    """Leave out the holes and slots of tools that cannot be drilled, with a warning naming them (an error with
    ``strict``); a bad tool never used is ignored with a note.  Returns tool -> holes and slots left out."""
    skipped: dict[int, int] = {}
    if not r.bad_tools:
        return skipped
    tools = np.array(r.hole_tool, np.int64)
    lines = np.array(r.hole_line, np.int64)
    for tool, why in sorted(r.bad_tools.items()):
        mine = np.flatnonzero(tools == tool)
        slot_lines = [ln for _, t, ln in r.slots if t == tool]
        n = len(mine) + len(slot_lines)
        if n == 0:
            r.warnings.append(f"{r.source}: tool {why} is defined but never used: ignored")
            continue
        first = int(lines[mine[0]]) if len(mine) else slot_lines[0]
        shown = ", ".join(str(int(v)) for v in sorted(lines[mine].tolist() + slot_lines)[:5])
        more = ", ..." if n > 5 else ""
        what = f"tool {why} cannot be drilled: its {n} hole(s) and slot(s) (lines {shown}{more})"
        if strict:
            raise ParseError(f"{r.source}:{first}: {what} (refused: --strict)")
        r.warnings.append(f"{r.source}:{first}: {what} are left out (--strict refuses the file instead)")
        keep = tools != tool
        r.holes = [h for h, k in zip(r.holes, keep) if k]
        r.hole_tool = [t for t, k in zip(r.hole_tool, keep) if k]
        r.hole_line = [ln for ln, k in zip(r.hole_line, keep) if k]
        tools, lines = tools[keep], lines[keep]
        r.slots = [s for s in r.slots if s[1] != tool]
        skipped[tool] = n
    return skipped


def _check_plausible(r: _Reader, guessed: bool, given: bool) -> None:
    """After the reading: a board larger than half a metre when the reading was a guess (and no format option
    was given) is an error naming the farthest hole; a used tool outside :data:`PLAUSIBLE_DRILL_MM` is a warning naming it and its holes."""
    holes = np.array(r.holes, np.float64).reshape(-1, 2)
    if guessed and not given and len(holes) >= 2:
        span = holes.max(axis=0) - holes.min(axis=0)
        if span.max() > PLAUSIBLE_BOARD_MM:
            axis = int(np.argmax(span))
            far = int(np.argmax(np.abs(holes[:, axis])))
            raise ParseError(
                f"{r.source}:{r.hole_line[far]}: no reading of this file's unstated format fits the board in "
                f"{PLAUSIBLE_BOARD_MM:g} mm: the hole at X{holes[far, 0]:.3f} Y{holes[far, 1]:.3f} mm makes it "
                f"{span[axis]:.0f} mm; give --excellon-units / --excellon-digits / --excellon-zeros")
    lo, hi = PLAUSIBLE_DRILL_MM
    tools = np.array(r.hole_tool, np.int64)
    for tool in sorted(set(r.hole_tool) | {t for _, t, _ in r.slots}):
        dia = r.tools.get(tool)
        if dia is None or lo <= dia <= hi:
            continue
        n = int(np.count_nonzero(tools == tool)) + sum(1 for _, t, _ in r.slots if t == tool)
        first = next((ln for ln, t in zip(r.hole_line, r.hole_tool) if t == tool), None)
        first = first if first is not None else next(ln for _, t, ln in r.slots if t == tool)
        r.warnings.append(f"{r.source}:{first}: tool T{tool} {dia:.3f} mm is not a usual drill "
                          f"({lo:g}-{hi:g} mm): {n} hole(s) and slot(s) use it")


def _check_given_digits(r: _Reader, text: str, units, digits: tuple[int, int], zeros, params) -> None:
    """``--excellon-digits`` given for a file that does not state them, with hole sizes that do not depend on them
    (Allegro's ``;T01 Holesize`` comments, ``nc_param.txt``): when the sizes say the board the digits make cannot
    be (holes cutting into each other, a board hardly larger than its holes; :func:`_size_evidence`) and another
    split of the same width fits clearly better, one warning names it (the digits given are still used)."""
    used = set(r.hole_tool)
    if not used or not any(t in r.comment_tools and r.tools.get(t) == r.comment_tools[t] for t in used):
        return
    given_penalty, given_why = _size_evidence(r)
    if given_penalty <= 0:
        return
    numbers = _NUMBER_TEXT.findall("\n".join(text.splitlines()[:_GUESS_LINES]).upper())
    width = max((len(n) for n in numbers), default=sum(digits))
    mine, _ = _plausibility(r, numbers, None)
    better = []
    for d in _fixed_digits(width):
        if d == tuple(digits):
            continue
        try:
            other = _read(text, r.source, units, d, zeros, None, _GUESS_LINES, params)
        except ParseError:
            continue
        penalty, why = _plausibility(other, numbers, None)
        if penalty < mine - 1.5 and _size_evidence(other)[0] < given_penalty:
            better.append((penalty, d, why))
    if not better:
        return
    _, d, why = min(better)
    holes = np.array(r.holes, np.float64).reshape(-1, 2)
    span = holes.max(axis=0) - holes.min(axis=0)
    r.warnings.append(
        f"{r.source}:{r.hole_line[0]}: --excellon-digits {digits[0]}:{digits[1]} makes the board "
        f"{span[0]:.1f} x {span[1]:.1f} mm with {', '.join(given_why)}, which the hole sizes in the file's comments "
        f"cannot fit; {d[0]}:{d[1]} is more plausible ({why})")


def load_excellon(
    path: str | os.PathLike,
    *,
    excellon_units: str | None = None,
    excellon_digits: tuple[int, int] | None = None,
    excellon_zeros: str | None = None,
    strict: bool = False,
) -> HoleList:
    """Read an Excellon drill file; see :func:`parse_excellon` for the arguments and the result.

    An Allegro ``nc_param.txt`` in the same folder (any case), else its ``ncdrill.log``, is read with it
    (:func:`parse_nc_param`).

    Raises:
        ParseError: the file is binary, not Excellon, or has a bad statement (naming file and line).
        CamError: the file cannot be read.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise CamError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    head = data[:8192]
    if b"\x00" in head or head.startswith(b"\x89PNG"):
        raise ParseError(f"{p}: not an Excellon drill file (binary data)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    nc_param = None
    try:
        beside = {q.name.lower(): q for q in p.parent.iterdir() if q.name.lower() in (NC_PARAM_NAME, NC_LOG_NAME)
                  and q.is_file()}
        found = beside.get(NC_PARAM_NAME) or beside.get(NC_LOG_NAME)
        if found is not None:
            nc_param = found.read_text(encoding="latin-1")
    except OSError:
        nc_param = None
    return parse_excellon(text, source=str(p), excellon_units=excellon_units, excellon_digits=excellon_digits,
                          excellon_zeros=excellon_zeros, strict=strict, nc_param=nc_param)
