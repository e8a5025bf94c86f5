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

Left out, each with a warning naming the line: slots (``X..Y..G85X..Y..``),
routing (``G00`` ... ``M15`` / ``G01`` / ``G02`` / ``G03`` ... ``M16``, until
``G05``), routed circles (``G32`` / ``G33``) and canned text (``M97`` / ``M98``).
Their tool still appears in :meth:`HoleList.tool_table` (with the holes it drills,
possibly 0).  Repeated patterns (``M25`` ... ``M01`` / ``M02X..Y..``, ``M08``)
are refused with a :class:`~cam.errors.ParseError`: leaving them out would drop
holes without a trace.

**Zeros.** Excellon names the zeros a number *keeps*: ``LZ`` keeps leading zeros
(trailing ones may be dropped, so ``X0125`` in 3:3 is 12.5), ``TZ`` keeps
trailing zeros (leading ones may be dropped, so ``X12500`` in 3:3 is 12.5).  The
``excellon_zeros`` argument uses the same names.

**Defaults** when the file does not state them (each settable by the keyword
arguments ``excellon_units``, ``excellon_digits`` and ``excellon_zeros``, the job options of the same names
(:mod:`cam.options`, flags ``--excellon-units`` ...), which in turn give way to what the file says):

* units: ``"inch"`` -- Excellon's own default, and the unit of the OrCAD file in
  seed 000 §8.1, Table 8-1 (``X003000`` = 300 mil);
* digits: inch 2:4 (Table 8-1: six digits for 0.0001 in; also what gerbonara
  assumes for a bare ``INCH``), metric 3:3 (the KiCad and Eagle metric format);
* zeros: ``"TZ"`` (leading zeros suppressed) -- what old Eagle, gEDA, Fritzing
  and DipTrace files do and what gerbonara assumes.  Full-width numbers such as
  Table 8-1's read the same either way.

When a coordinate is read with a built-in default (not stated in the file nor
given by an argument), the hole list carries a warning that says so.

Frame: the board frame of the file, X right, Y up, in mm (inch values times 25.4).

Numbers are checked before use (:mod:`cam.limits`): coordinates and the positions they lead to
(incremental sums, ``G93`` zeros) at most :data:`~cam.limits.MAX_COORD_MM` either way, tool diameters
more than 0 and at most :data:`~cam.limits.MAX_TOOL_DIAMETER_MM`, tool numbers at most
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
    """

    holes_mm: np.ndarray
    tool_of_hole: np.ndarray
    tools: dict[int, float]
    line_of_hole: np.ndarray
    warnings: list[str] = field(default_factory=list)
    source: str = "<excellon>"

    def extent_mm(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)``: the smallest and largest hole centre coordinates (mm); all 0.0 without holes."""
        if len(self.holes_mm) == 0:
            return (0.0, 0.0, 0.0, 0.0)
        lo = self.holes_mm.min(axis=0)
        hi = self.holes_mm.max(axis=0)
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

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

    def __init__(self, source: str, units, digits, zeros) -> None:
        self.source = source
        # what the caller gave for "when the file does not say"
        self.opt_units, self.opt_digits, self.opt_zeros = units, digits, zeros
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
        return (units or DEFAULT_UNITS), src == "default"

    def current_format(self, units: str) -> tuple[tuple[int, int], str, list[str]]:
        """Digits and zeros for implied decimals, and which of them come from the built-in defaults."""
        digits, _ = self._setting("digits")
        zeros, _ = self._setting("zeros")
        assumed = []
        if digits is None:
            digits = DEFAULT_DIGITS[units]
            assumed.append("digits")
        if zeros is None:
            zeros = DEFAULT_ZEROS
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
        if len(self.holes) >= MAX_HOLES:
            raise self.error(f"more than {MAX_HOLES} holes")
        self.holes.append((self.pos_mm[0], self.pos_mm[1]))
        self.hole_tool.append(self.tool)
        self.hole_line.append(self.lineno)

    # -- one line -----------------------------------------------------------------------------------
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


_COMMENT_HANDLERS = ((_KICAD_FORMAT, _kicad_format), (_FILE_FORMAT, _file_format), (_SIEMENS_FORMAT, _siemens_format))
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
        r.warn(f"slot (G85) from X{start[0]:.3f} Y{start[1]:.3f} to X{r.pos_mm[0]:.3f} "
               f"Y{r.pos_mm[1]:.3f} mm is not drilled: left out")
        return
    r.move(words)
    if r.state == "route":
        return
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
    if not 0 < dia_mm <= MAX_TOOL_DIAMETER_MM:
        raise r.error(f"tool T{number} has a bad diameter {_shown(text)} (must be > 0 and at most "
                      f"{MAX_TOOL_DIAMETER_MM:g} mm)", col)
    if number == 0:
        raise r.error("tool T0 cannot be defined (T0 unloads the tool)")
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
        if r.state != "route":
            r.warn("routing (G00/G01/G02/G03 with M15/M16) is not drilled: left out up to the next G05")
        r.state = "route"
        if rest:
            _route_move(r, rest)
    elif code in (5, 81):
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
    allowed = [w for w in words if w[0] in "XY"]
    others = [w for w in words if w[0] not in "XYAIJ"]
    if others:
        raise r.error(f"unexpected {others[0][0]}{others[0][1]} in a routing move", others[0][2])
    r.move(allowed)


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
    elif code in (15, 16, 17):
        pass  # plunge / retract in routing: the route itself is left out
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
    count = r.integer(words[0], MAX_REPEAT)
    if r.state == "route":
        raise r.error("a repeated hole (R) while routing")
    x, y = r.xy(words[1:])
    for _ in range(count):
        r.pos_mm[0] += x or 0.0
        r.pos_mm[1] += y or 0.0
        r.check_position()
        r.hole()
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


def parse_excellon(
    text: str,
    *,
    source: str = "<excellon>",
    excellon_units: str | None = None,
    excellon_digits: tuple[int, int] | None = None,
    excellon_zeros: str | None = None,
) -> HoleList:
    """Read the holes of an Excellon drill program (pure: no I/O).

    Args:
        text: the whole file.
        source: file name used in messages.
        excellon_units: "inch" or "metric" when the file does not say (default :data:`DEFAULT_UNITS`).
        excellon_digits: (integer, fraction) digits of implied-decimal numbers when the file does not say
            (default :data:`DEFAULT_DIGITS` for the units).
        excellon_zeros: "LZ" (leading zeros kept) or "TZ" (trailing zeros kept) when the file does not say
            (default :data:`DEFAULT_ZEROS`).

        The three are the job options of the same names (:data:`cam.options.OPTIONS`, ``--excellon-units``,
        ``--excellon-digits``, ``--excellon-zeros``).

    Returns:
        The holes (board frame, mm) with their tools, lines and warnings.

    Raises:
        ParseError: not an Excellon file, a number the format cannot read, a hole without a tool,
            a tool selected but never defined, a bad diameter, ... (``file:line: what: 'line text'``).
        CamError: a bad keyword argument.
    """
    _check_options(excellon_units, excellon_digits, excellon_zeros)
    r = _Reader(source, excellon_units, tuple(excellon_digits) if excellon_digits is not None else None,
                excellon_zeros)
    for lineno, raw in enumerate(text.splitlines(), start=1):
        r.line(lineno, raw)
    if not r.seen_excellon:
        raise ParseError(f"{source}: not an Excellon drill file (no header, tool or hole)")
    if r.after_end:
        r.lineno = r.after_end[0]
        r.text = text.splitlines()[r.lineno - 1].strip()
        r.warn(f"{len(r.after_end)} statement(s) after the end of the program (M30/M00) ignored")
    if not r.holes:
        r.lineno, r.text = len(text.splitlines()), ""
        r.warnings.append(f"{source}: no holes to drill")
    holes = np.array(r.holes, np.float64).reshape(-1, 2)
    return HoleList(
        holes_mm=holes,
        tool_of_hole=np.array(r.hole_tool, np.int64),
        tools=dict(r.tools),
        line_of_hole=np.array(r.hole_line, np.int64),
        warnings=r.warnings,
        source=source,
    )


def load_excellon(
    path: str | os.PathLike,
    *,
    excellon_units: str | None = None,
    excellon_digits: tuple[int, int] | None = None,
    excellon_zeros: str | None = None,
) -> HoleList:
    """Read an Excellon drill file; see :func:`parse_excellon` for the arguments and the result.

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
    return parse_excellon(text, source=str(p), excellon_units=excellon_units, excellon_digits=excellon_digits,
                          excellon_zeros=excellon_zeros)
