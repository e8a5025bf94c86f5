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
* accepted without motion: G61, G61.1, G64 (P Q), G93/G94 feed modes (G93 gives each move its time),
  G40, G8, G96/G97, M3/M4/M5, M48..M53, M61 Q; M7/M8/M9 (no coolant output: one warning);
* pauses: M6 with T (tool change), M0, M1, M60; M2/M30 (and a second ``%``) end the program;
* the language: numbered and named parameters (local ``#<name>``, global ``#<_name>``), expressions
  (:mod:`cam.formats.ngc`), O words (sub/endsub/call/return, if/elseif/else/endif, while/endwhile,
  do/while, repeat/endrepeat, break/continue), M70..M73 modal state, and ``O<name> call`` of
  ``name.ngc`` found in the subroutine path.

Refused, each with a message saying why: probing (G38.x), rotary axes (A B C) and U V W, cutter
radius compensation (G41/G42), lathe cycles and modes (G7, G7x, G76), rigid tapping (G33.1), NURBS blocks
(G5.2/G5.3), spindle cycles (G84, G86..G88), user M codes (M100..M199) and I/O (M62..M68).

Every error is a :class:`~cam.errors.ParseError` naming ``file:line``, the word and the line.
Every number a word takes is checked against :mod:`cam.limits` before it is used.  A program runs
at most ``max_lines`` lines (a loop that never ends is an error, not a hang).

Planning the motion (frames, arcs, feeds, the half-step accuracy) is :mod:`cam.job.gcode`.
"""
from __future__ import annotations

import bisect
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

from ..choices import GCODE_SUFFIXES
from ..errors import ParseError
from ..fileio import read_text
from ..limits import (
    DEFAULT_GCODE_LINES, MAX_COORD_MM, MAX_DWELL_S, MAX_FEED_MM_MIN, MAX_GCODE_CALL_DEPTH, MAX_LINE_NUMBER,
    MAX_REPEAT, MAX_SPINDLE_RPM, MAX_TOOL_NUMBER, MIN_FEED_MM_MIN,
)
from .ngc import Line, NgcSyntaxError, evaluate, read_line

__all__ = ["GcodeMove", "GcodeProgram", "parse_gcode", "load_gcode", "load_tool_table", "GCODE_SUFFIXES"]

PLANE_AXES = {"XY": (0, 1, 2), "XZ": (2, 0, 1), "YZ": (1, 2, 0)}
"""The (first, second, third) axes of each arc plane, as LinuxCNC orders them: arcs turn in the
(first, second) frame (G2 clockwise), the third axis moves linearly (helix)."""


@dataclass
class GcodeMove:
    """One programmed move in mm (machine frame, G-code axes: +Y up, +Z up).

    ``kind``: "rapid", "feed", "arc", "spline", "dwell" or "pause".  ``end`` is absolute mm; arcs carry
    ``center`` (mm, in the (first, second) axes of ``plane``, see :data:`PLANE_AXES`), ``clockwise``
    and ``turns``; a spline (G5, G5.1) is the Bezier curve from where the last move ended through its inner
    ``controls`` (absolute mm: one for G5.1, two for G5; Z as at the start) to ``end``; dwell carries
    ``seconds``; pause carries ``note``; ``feed_mm_min`` applies to feed, arc and spline moves, or
    ``minutes`` (G93 inverse time) when it is more than 0.
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


@dataclass
class GcodeProgram:
    """Interpreted program: moves in order, plus warnings; ``source`` names the file."""

    moves: list[GcodeMove]
    source: str = "<gcode>"
    warnings: list[str] = field(default_factory=list)


def _strip_comments(line: str, err) -> str:
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
    **{c: "probing is not supported: the machine has no probe input" for c in (382, 383, 384, 385)},
    **{c: "cutter radius compensation is not supported: give the tool centre's path"
       for c in (410, 411, 420, 421)},
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
_SUPPORTED_G = {0, 10, 20, 30, 40, 50, 51, 330, 80, 100, 170, 180, 190, 200, 210, 280, 281, 300, 301, 400, 430, 431, 490, 530,
                540, 550, 560, 570, 580, 590, 591, 592, 593, 610, 611, 640, 730, 800, 810, 820, 830, 850, 890,
                900, 901, 910, 911, 920, 921, 922, 923, 930, 940, 960, 970, 980, 990}
_CYCLES = {730, 810, 820, 830, 850, 890}
_MOTION = {0, 10, 20, 30, 330, 800} | _CYCLES
_SPLINES = {50, 51}  # G5, G5.1: motion on their own line only (rs274 keeps the modal motion mode)
_CS = {540: 1, 550: 2, 560: 3, 570: 4, 580: 5, 590: 6, 591: 7, 592: 8, 593: 9}
_IGNORED_M = {3, 4, 5, 48, 49, 50, 51, 52, 53}
_IO_M = {62, 63, 64, 65, 66, 67, 68}
_AXIS_WORDS = "xyz"
_LETTERS = set("xyzijkrfstpqlhn@^")
_CYCLE_PECK = 0.254  # mm: LinuxCNC's G73 chip-break retract and G83 rapid stop above the last peck (0.010 in)


def load_tool_table(path: str | os.PathLike) -> dict[int, float]:
    """A LinuxCNC tool table (``T1 P1 Z0.511 D0.125 ;comment`` lines): tool number -> Z offset in mm.

    The table is in the machine's units, millimetres for `cam`.  Errors name ``file:line``.
    """
    p, text = read_text(path, not_text="not a tool table text file")
    table: dict[int, float] = {}
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
        table[int(tool)] = z
    return table


class _Source:
    """One file's lines, read on demand, and where its O words are."""

    _O = re.compile(r"^\s*/?\s*[oO]\s*(<[^>]*>|\d+)\s*([a-zA-Z]+)")

    def __init__(self, name: str, text: str) -> None:
        self.name = name
        self.raw = text.splitlines()
        self.bodies: dict[int, str | None] = {}
        self.lines: dict[int, Line] = {}
        self.o_at: dict[str, list[tuple[int, str]]] = {}  # label -> [(index, keyword)] in order
        self.subs: dict[str, int] = {}
        for i, raw in enumerate(self.raw):
            m = self._O.match(raw.split("(", 1)[0].split(";", 1)[0])
            if m:
                label = re.sub(r"\s", "", m.group(1).lower())
                if not label.startswith("<"):
                    label = str(int(label))
                kw = m.group(2).lower()
                self.o_at.setdefault(label, []).append((i, kw))
                if kw == "sub" and label not in self.subs:
                    self.subs[label] = i

    def next_o(self, label: str, after: int, kws: Sequence[str]) -> int | None:
        """The first line after ``after`` with O word ``label`` and a keyword in ``kws``."""
        entries = self.o_at.get(label, [])
        k = bisect.bisect_right(entries, (after, "\uffff"))
        for i, kw in entries[k:]:
            if kw in kws:
                return i
        return None

    def prev_o(self, label: str, before: int) -> tuple[int, str] | None:
        """The last O word ``label`` before line ``before``."""
        entries = self.o_at.get(label, [])
        k = bisect.bisect_left(entries, (before, ""))
        return entries[k - 1] if k else None


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


class _Interp:
    def __init__(self, source: _Source, *, home_g28_mm, home_g30_mm, tool_table, subroutine_path, max_lines) -> None:
        self.main = source
        self.tool_table = None if tool_table is None else dict(tool_table)
        self.path = [Path(p) for p in subroutine_path]
        self.max_lines = int(max_lines)
        self.files: dict[str, _Source] = {}
        self.moves: list[GcodeMove] = []
        self.warnings: list[str] = []
        self.coolant_warned = False
        self.sync_warned = False
        self.spindle_rpm = 0.0  # S: the machine has no spindle output; G33's feed is K x S
        self.spindle_on = False  # M3/M4 (on) or M5 (off): rs274 refuses G33 with the spindle stopped
        self.params: dict[int, float] = {}
        for i, a in enumerate(home_g28_mm):
            self.params[5161 + i] = float(a)
        for i, a in enumerate(home_g30_mm):
            self.params[5181 + i] = float(a)
        self.params[5220] = 1.0
        self.globals: dict[str, float] = {}
        self.frames: list[_Frame] = [_Frame(source, -1, "", {})]
        self.mach = [0.0, 0.0, 0.0]  # machine position, mm
        self.g92 = [0.0, 0.0, 0.0]
        self.tlo = 0.0
        self.cs = 1
        self.scale = 1.0
        self.absolute = True
        self.arc_absolute = False
        self.plane = "XY"
        self.motion: int | None = None
        self.g5_reflect: tuple[float, float] | None = None  # mm: the I J a G5 without them takes after a G5
        self.feed = 0.0  # mm/min (G94) or 1/min (G93)
        self.inverse_time = False
        self.retract_r = False  # G99
        self.cycle_il: float | None = None
        self.cycle: dict[str, float] = {}
        self.selected_tool = 0
        self.tool = 0
        self.saved_modal: dict | None = None
        self.resync: list[float] | None = None  # after M6: the program position the next block starts from
        self.line_no = 0
        self.source = source
        self.raw = ""
        self.value = 0.0
        self.value_returned = 0.0

    # -- errors and parameters --------------------------------------------------------------------------------

    def err(self, msg: str) -> ParseError:
        return ParseError(f'{self.source.name}:{self.line_no}: {msg} "{self.raw.strip()[:60]}"')

    def g5x(self, cs: int | None = None) -> list[float]:
        base = 5221 + 20 * ((cs or self.cs) - 1)
        return [self.params.get(base + i, 0.0) for i in range(3)]

    def offsets(self) -> list[float]:
        g = self.g5x()
        return [g[0] + self.g92[0], g[1] + self.g92[1], g[2] + self.g92[2] + self.tlo]

    def pos(self) -> list[float]:
        """The program position (mm, in the active coordinate system)."""
        return [m - o for m, o in zip(self.mach, self.offsets())]

    def read_param(self, ref: tuple) -> float:
        if ref[0] == "num":
            n = ref[1]
            if n != int(n) or not 1 <= n <= 5602:
                raise self.err(f"parameter number #{n:g} is out of range 1..5602")
            n = int(n)
            if n in (5420, 5421, 5422):
                return self.pos()[n - 5420] / self.scale
            if n == 5400:
                return float(self.tool)
            if n == 5403:
                return self.tlo
            if n in (5211, 5212, 5213):
                return self.g92[n - 5211] if self.params.get(5210, 0.0) else self.params.get(n, 0.0)
            return self.params.get(n, 0.0)
        name = ref[1]
        if name.startswith("_"):
            special = self._special(name)
            if special is not None:
                return special
            if name in self.globals:
                return self.globals[name]
        elif name in self.frames[-1].named:
            return self.frames[-1].named[name]
        raise self.err(f"named parameter '#<{name}>' is not defined")

    def _special(self, name: str) -> float | None:
        p = self.pos()
        table = {
            "_x": p[0] / self.scale, "_y": p[1] / self.scale, "_z": p[2] / self.scale,
            "_metric": float(self.scale == 1.0), "_imperial": float(self.scale != 1.0),
            "_absolute": float(self.absolute), "_incremental": float(not self.absolute),
            "_value": self.value, "_value_returned": self.value_returned, "_call_level": float(len(self.frames) - 1),
            "_feed": self.feed / (1.0 if self.inverse_time else self.scale), "_current_tool": float(self.tool),
            "_selected_tool": float(self.selected_tool), "_line": float(self.line_no),
            "_coord_system": float({1: 540, 2: 550, 3: 560, 4: 570, 5: 580, 6: 590, 7: 591, 8: 592, 9: 593}[self.cs]),
            "_plane": float({"XY": 170, "XZ": 180, "YZ": 190}[self.plane]),
            "_motion_mode": float(self.motion * 10 if self.motion is not None else 800),
            "_retract_r_plane": float(self.retract_r), "_retract_old_z": float(not self.retract_r),
            "_task": 0.0, "_rpm": self.spindle_rpm,
        }
        return table.get(name)

    def exists(self, ref: tuple) -> bool:
        if ref[0] == "num":
            return True
        name = ref[1]
        if name.startswith("_"):
            return self._special(name) is not None or name in self.globals
        return name in self.frames[-1].named

    def write_param(self, ref: tuple, value: float) -> None:
        if ref[0] == "num":
            n = ref[1]
            if n != int(n) or not 1 <= n <= 5602:
                raise self.err(f"parameter number #{n:g} is out of range 1..5602")
            if int(n) in (5400, 5403, 5420, 5421, 5422):
                raise self.err(f"parameter #{int(n)} is read-only")
            self.params[int(n)] = value
            return
        name = ref[1]
        if name.startswith("_"):
            if self._special(name) is not None:
                raise self.err(f"parameter '#<{name}>' is read-only")
            self.globals[name] = value
        else:
            self.frames[-1].named[name] = value

    def value_of(self, tree) -> float:
        try:
            return evaluate(tree, self.read_param, self.exists)
        except NgcSyntaxError as exc:
            raise self.err(str(exc)) from None

    # -- the program ------------------------------------------------------------------------------------------

    def run(self) -> None:
        src, idx = self.main, 0
        executed = 0
        percent = False
        ran = False
        while True:
            if idx >= len(src.raw):
                if len(self.frames) > 1:
                    self.source, self.raw = src, ""
                    self.line_no = len(src.raw)
                    raise self.err(f"the file ends inside subroutine 'o{self.frames[-1].label}'")
                return
            self.source, self.line_no, self.raw = src, idx + 1, src.raw[idx]
            executed += 1
            if executed > self.max_lines:
                raise self.err(f"the program has run {self.max_lines} lines and does not end (a loop without an "
                               "exit?); raise the limit with --max-lines")
            body = src.bodies.get(idx, "")
            if body == "":
                body = re.sub(r"\s+", "", _strip_comments(self.raw, self.err)).lower()
                if body.startswith("/"):
                    body = body[1:]  # block delete is off, as in rs274: the line runs
                src.bodies[idx] = body
            if not body:
                idx += 1
                continue
            if body == "%":
                if percent or ran:
                    return  # the closing '%' ends the program
                percent = True
                idx += 1
                continue
            ran = True
            line = src.lines.get(idx)
            if line is None:
                try:
                    line = read_line(body)
                except NgcSyntaxError as exc:
                    raise self.err(str(exc)) from None
                src.lines[idx] = line
            if line.o is not None:
                src, idx = self.o_word(src, idx, line.o)
                continue
            try:
                self.block(line)
            except _End:
                return
            idx += 1

    # -- O words ----------------------------------------------------------------------------------------------

    def _o_args(self, src: _Source, i: int) -> list:
        line = src.lines.get(i)
        if line is None:
            body = re.sub(r"\s+", "", _strip_comments(src.raw[i], self.err)).lower().lstrip("/")
            try:
                line = src.lines[i] = read_line(body)
            except NgcSyntaxError as exc:
                raise self.err(str(exc)) from None
        return line.o[2]

    def _need(self, found: int | None, what: str) -> int:
        if found is None:
            raise self.err(f"no matching {what}")
        return found

    def _do_of(self, src: _Source, label: str, idx: int) -> int | None:
        """The ``do`` line whose loop the ``while`` at ``idx`` ends (its own break/continue skipped), or None."""
        prev = src.prev_o(label, idx)
        while prev is not None and prev[1] in ("break", "continue"):
            prev = src.prev_o(label, prev[0])
        return prev[0] if prev is not None and prev[1] == "do" else None

    def _loop_head(self, src: _Source, label: str, idx: int, opener: str) -> int:
        """The line of the ``o<label> opener`` (``while``/``repeat``) that the loop end at ``idx`` closes."""
        head = src.prev_o(label, idx)
        while head is not None and head[1] != opener:
            head = src.prev_o(label, head[0])
        return self._need(head and head[0], f"'o{label} {opener}'")

    def _is_do_tail(self, src: _Source, label: str, idx: int) -> bool:
        return self._do_of(src, label, idx) is not None

    def o_word(self, src: _Source, idx: int, o: tuple) -> tuple[_Source, int]:
        label, kw, args = o
        frame = self.frames[-1]
        cond = (lambda: self.value_of(args[0]) != 0) if args else (lambda: False)
        if kw == "sub":
            return src, self._need(src.next_o(label, idx, ("endsub",)), f"'o{label} endsub'") + 1
        if kw in ("endsub", "return"):
            if len(self.frames) == 1:
                raise self.err(f"'o{label} {kw}' outside a subroutine")
            if args:
                self.value, self.value_returned = self.value_of(args[0]), 1.0
            else:
                self.value_returned = 0.0
            self.frames.pop()
            for n in range(1, 31):
                self.params.pop(n, None)
            self.params.update(frame.saved_numbered)
            if frame.modal is not None:
                self.restore_modal(frame.modal)
            return frame.source, frame.back
        if kw == "call":
            values = [self.value_of(a) for a in args]
            target, start = self.find_sub(src, label)
            if len(self.frames) > MAX_GCODE_CALL_DEPTH:
                raise self.err(f"subroutines call each other more than {MAX_GCODE_CALL_DEPTH} deep")
            saved = {n: self.params[n] for n in range(1, 31) if n in self.params}
            for n in range(1, 31):
                self.params.pop(n, None)
            for n, v in enumerate(values[:30], start=1):
                self.params[n] = v
            self.frames.append(_Frame(src, idx + 1, label, saved))
            self.value_returned = 0.0
            return target, start + 1
        if kw == "if":
            if cond():
                return src, idx + 1
            j = idx
            while True:
                j = self._need(src.next_o(label, j, ("elseif", "else", "endif")), f"'o{label} endif'")
                kind = src.o_at[label][bisect.bisect_left(src.o_at[label], (j, ""))][1]
                if kind == "elseif":
                    self.line_no, self.raw = j + 1, src.raw[j]
                    elif_args = self._o_args(src, j)
                    if elif_args and self.value_of(elif_args[0]) != 0:
                        return src, j + 1
                    continue
                return src, j + 1
        if kw in ("elseif", "else"):
            return src, self._need(src.next_o(label, idx, ("endif",)), f"'o{label} endif'") + 1
        if kw in ("endif", "do"):
            return src, idx + 1
        if kw == "while":
            if self._is_do_tail(src, label, idx):
                return (src, self._do_of(src, label, idx) + 1) if cond() else (src, idx + 1)
            if cond():
                return src, idx + 1
            return src, self._need(src.next_o(label, idx, ("endwhile",)), f"'o{label} endwhile'") + 1
        if kw == "endwhile":
            return src, self._loop_head(src, label, idx, "while")
        if kw == "repeat":
            key = (id(src), idx)
            if key not in frame.repeats:
                n = self.value_of(args[0]) if args else 0.0
                if not 0 <= n <= MAX_REPEAT * 100:
                    raise self.err(f"repeat count {n:g} is out of range 0..{MAX_REPEAT * 100}")
                frame.repeats[key] = int(n)
            if frame.repeats[key] > 0:
                frame.repeats[key] -= 1
                return src, idx + 1
            del frame.repeats[key]
            return src, self._need(src.next_o(label, idx, ("endrepeat",)), f"'o{label} endrepeat'") + 1
        if kw == "endrepeat":
            return src, self._loop_head(src, label, idx, "repeat")
        # break / continue: the loop with this label that encloses the line
        j = idx
        while True:
            j = self._need(src.next_o(label, j, ("endwhile", "endrepeat", "while")), f"end of loop 'o{label}'")
            kind = src.o_at[label][bisect.bisect_left(src.o_at[label], (j, ""))][1]
            if kind != "while" or self._is_do_tail(src, label, j):
                break
        if kw == "break":
            if kind == "endrepeat":
                head = src.prev_o(label, j)
                while head is not None and head[1] != "repeat":
                    head = src.prev_o(label, head[0])
                if head is not None:
                    frame.repeats.pop((id(src), head[0]), None)
            return src, j + 1
        return src, j  # continue: endwhile / endrepeat jump back, a do's while tests its condition

    def find_sub(self, src: _Source, label: str) -> tuple[_Source, int]:
        for s in (src, self.main, *self.files.values()):
            if label in s.subs:
                return s, s.subs[label]
        if label.startswith("<"):
            name = label[1:-1]
            for d in self.path:
                f = d / f"{name}.ngc"
                if f.is_file():
                    _, text = read_text(f, not_text="not a G-code text file")
                    s = _Source(str(f), text)
                    self.files[str(f)] = s
                    if label in s.subs:
                        return s, s.subs[label]
                    raise self.err(f"{f} does not define 'o{label} sub'")
        where = f" (searched {', '.join(str(d) for d in self.path)})" if self.path else " (no --subroutine-path)"
        raise self.err(f"subroutine 'o{label}' is not defined{where}")

    # -- one block --------------------------------------------------------------------------------------------

    def block(self, line: Line) -> None:
        if self.resync is not None:
            # after a tool change LinuxCNC reads its position again at the next block: the program position
            # is where the last move ended, so a tool length offset taken on the M6 line itself moves Z with
            # the next move (as rs274 does)
            off = self.offsets()
            self.mach = [p + o for p, o in zip(self.resync, off)]
            self.resync = None
        gs: list[tuple[int, str]] = []
        ms: list[tuple[float, str]] = []
        vals: dict[str, float] = {}
        texts: dict[str, str] = {}
        for letter, tree, text in line.words:
            v = self.value_of(tree)
            word = _shown(text.upper())
            if letter in "gm" and not math.isfinite(v):
                raise self.err(f"unsupported word '{word}'")
            if letter == "g":
                code = int(round(v * 10))
                if abs(v * 10 - code) > 1e-6 or code in _REFUSED_G or code not in _SUPPORTED_G:
                    shown = _shown(f"G{v:g}")
                    if code in _REFUSED_G and abs(v * 10 - code) <= 1e-6:
                        raise self.err(f"'{shown}': {_REFUSED_G[code]}")
                    raise self.err(f"unsupported word '{shown}'")
                gs.append((code, f"G{v:g}"))
            elif letter == "m":
                if v != int(v) or not 0 <= v <= 199:
                    raise self.err(f"unsupported word '{_shown(f'M{v:g}')}'")
                ms.append((v, f"M{v:g}"))
            elif letter in "abc":
                raise self.err(f"rotary axis word '{word}' is not supported: the machine has three linear axes, "
                               "X Y Z")
            elif letter in "uvw":
                raise self.err(f"axis word '{word}' is not supported: the machine has three axes, X Y Z")
            elif letter == "d":
                raise self.err(f"cutter compensation word '{word}' is not supported: give the tool centre's path")
            elif letter not in _LETTERS:
                raise self.err(f"unsupported word '{word}'")
            elif letter in vals:
                raise self.err(f"word '{letter.upper()}' appears twice")
            else:
                vals[letter] = v
                texts[letter] = word
        values = [self.value_of(tree) for _, tree in line.assigns]
        if not all(math.isfinite(v) for v in values):
            raise self.err("a parameter is given a number that is not finite")
        for (ref, _), v in zip(line.assigns, values):
            if ref[0] == "num":
                ref = ("num", self.value_of(ref[1]))
            self.write_param(ref, v)
        codes = {c for c, _ in gs}
        mcodes = {int(m) for m, _ in ms}
        for m, text in ms:
            if 100 <= m <= 199:
                raise self.err(f"user M code '{text}' is not supported: it would run a program outside the G-code")
            if m in _IO_M:
                raise self.err(f"'{text}': digital and analog I/O is not supported: the machine has none")
            if m not in (0, 1, 2, 6, 7, 8, 9, 30, 60, 61, 70, 71, 72, 73) and m not in _IGNORED_M:
                raise self.err(f"unsupported word '{text}'")
        motions = codes & _MOTION
        splines = codes & _SPLINES
        if len(motions | splines) > 1:
            raise self.err("two motion codes on one line")
        if 930 in codes:
            self.inverse_time = True
        if 940 in codes:
            self.inverse_time = False
        # units first where they scale this line's words (LinuxCNC sets them before any word is used)
        if 200 in codes:
            self.scale = 25.4
        if 210 in codes:
            self.scale = 1.0
        self.check_words(vals, texts, pq_offsets=50 in codes)
        if "f" in vals:
            self.feed = vals["f"] if self.inverse_time else vals["f"] * self.scale
        if "s" in vals:
            self.spindle_rpm = vals["s"]
        if mcodes & {3, 4}:
            self.spindle_on = True
        if 5 in mcodes:
            self.spindle_on = False
        if "t" in vals:
            t = int(vals["t"])
            if self.tool_table is not None and t and t not in self.tool_table:
                raise self.err(f"tool 'T{t}' is not in the tool table")
            self.selected_tool = t
        if 6 in mcodes:
            self.moves.append(GcodeMove("pause", self.line_no, tuple(self.mach),
                                        note=f"tool change: T{self.selected_tool} (line {self.line_no})"))
            self.tool = self.selected_tool
            self.resync = self.pos()
        if 61 in mcodes:
            if "q" not in vals or vals["q"] != int(vals["q"]) or not 0 <= vals["q"] <= MAX_TOOL_NUMBER:
                raise self.err("M61 needs a tool number 'Q'")
            self.tool = self.selected_tool = int(vals["q"])
        if mcodes & {7, 8, 9} and not self.coolant_warned:
            self.coolant_warned = True
            self.warnings.append(f"{self.source.name}:{self.line_no}: coolant M7/M8/M9 ignored: the machine has "
                                 "no coolant output")
        if 70 in mcodes or 73 in mcodes:
            state = self.modal_state()
            if 70 in mcodes:
                self.saved_modal = state
            if 73 in mcodes:
                if len(self.frames) == 1:
                    raise self.err("M73 outside a subroutine")
                self.frames[-1].modal = state
        if 71 in mcodes:
            self.saved_modal = None
        if 72 in mcodes:
            if self.saved_modal is None:
                raise self.err("M72 without a state saved by M70")
            self.restore_modal(self.saved_modal)
        if 40 in codes:
            if "p" not in vals:
                raise self.err("G4 needs a dwell time 'P' in seconds")
            self.moves.append(GcodeMove("dwell", self.line_no, tuple(self.mach), seconds=vals["p"]))
        for code, plane in ((170, "XY"), (180, "XZ"), (190, "YZ")):
            if code in codes:
                self.plane = plane
        if 430 in codes or 431 in codes:
            self.tool_length(codes, vals)
        if 490 in codes:
            self.tlo = 0.0
        for code, cs in _CS.items():
            if code in codes:
                self.select_cs(cs)
        if 900 in codes:
            self.absolute = True
        if 910 in codes:
            self.absolute = False
        if 901 in codes:
            self.arc_absolute = True
        if 911 in codes:
            self.arc_absolute = False
        if 980 in codes:
            self.retract_r = False
        if 990 in codes:
            self.retract_r = True
        axes_used = False
        if codes & {280, 300}:
            self.go_home(300 in codes, vals)
            axes_used = True
        if codes & {281, 301}:
            base = 5181 if 301 in codes else 5161
            for i in range(3):
                self.params[base + i] = self.mach[i]
        if 100 in codes:
            self.g10(vals)
            axes_used = True
        if codes & {920, 921, 922, 923}:
            self.set_g92(codes, vals)
            axes_used = 920 in codes
        if motions:
            (m,) = motions
            in_cycle = self.motion is not None and self.motion * 10 in _CYCLES
            if m not in _CYCLES or not in_cycle:
                self.cycle_il = None  # a new series of canned cycles starts from where the tool stands
            self.motion = None if m == 800 else m // 10
            if m == 800:
                self.cycle_il = None
        if "q" in vals and not (codes & {640, 50} or 61 in mcodes or self.motion in (73, 83)):
            raise self.err(f"unsupported word '{texts['q']}' (no G or M code on the line uses it)")
        has_axes = any(a in vals for a in "xyz@^")
        if splines:
            if axes_used:
                raise self.err("a spline cannot share its line with G10, G28, G30 or G92 (they use the axis words)")
            self.spline(splines.pop(), vals)
        elif has_axes and not axes_used:
            self.move(vals, texts, 530 in codes)
        elif any(k in vals for k in "ijk") and not axes_used and self.motion in (2, 3):
            self.move(vals, texts, 530 in codes)  # a full circle names only its centre
        elif 530 in codes:
            raise self.err("G53 needs an axis word")
        if mcodes & {0, 1}:
            for m in sorted(mcodes & {0, 1}):
                self.moves.append(GcodeMove("pause", self.line_no, tuple(self.mach),
                                            note=f"program pause M{m} (line {self.line_no})"))
        if 60 in mcodes:
            self.moves.append(GcodeMove("pause", self.line_no, tuple(self.mach),
                                        note=f"pallet change pause M60 (line {self.line_no})"))
        if mcodes & {2, 30}:
            raise _End

    def check_words(self, vals: dict[str, float], texts: dict[str, str], *, pq_offsets: bool = False) -> None:
        """Every word of one line finite and in its range (:mod:`cam.limits`); ``pq_offsets``: P is a
        coordinate offset (G5), not a time."""
        scale = self.scale
        for k, v in vals.items():
            word = texts[k]
            if k in "xyzijkrq@" or (k == "p" and pq_offsets):
                if not abs(v * scale) <= MAX_COORD_MM:
                    raise self.err(f"word '{word}' is out of range: coordinates are at most {MAX_COORD_MM:g} mm "
                                   "either way")
            elif k == "f":
                lo, hi = (MIN_FEED_MM_MIN, MAX_FEED_MM_MIN)
                if not lo <= v * (1.0 if self.inverse_time else scale) <= hi:
                    raise self.err(f"feed '{word}' is out of range: {lo:g}..{hi:g} mm/min")
            elif k == "p":
                if not 0 <= v <= MAX_DWELL_S:
                    raise self.err(f"dwell '{word}' is out of range: 0..{MAX_DWELL_S:g} s")
            elif k in "th":
                if not (0 <= v <= MAX_TOOL_NUMBER and v == int(v)):
                    raise self.err(f"tool '{word}' is out of range: a whole number 0..{MAX_TOOL_NUMBER}")
            elif k == "s":
                if not 0 <= v <= MAX_SPINDLE_RPM:
                    raise self.err(f"spindle speed '{word}' is out of range: 0..{MAX_SPINDLE_RPM:g} rpm")
            elif k == "n":
                if not 0 <= v <= MAX_LINE_NUMBER:
                    raise self.err(f"line number '{word}' is out of range: 0..{MAX_LINE_NUMBER}")
            elif k == "l":
                if not (0 <= v <= MAX_REPEAT and v == int(v)):
                    raise self.err(f"word '{word}' is out of range: a whole number 0..{MAX_REPEAT}")
            elif k == "^":
                if not abs(v) <= 1e9:
                    raise self.err(f"angle '{word}' is out of range")

    # -- modal state, offsets ---------------------------------------------------------------------------------

    def modal_state(self) -> dict:
        return {"scale": self.scale, "absolute": self.absolute, "arc_absolute": self.arc_absolute,
                "plane": self.plane, "feed": self.feed, "inverse_time": self.inverse_time, "cs": self.cs,
                "retract_r": self.retract_r, "spindle_rpm": self.spindle_rpm, "spindle_on": self.spindle_on}

    def restore_modal(self, state: dict) -> None:
        for k, v in state.items():
            if k != "cs":
                setattr(self, k, v)
        self.select_cs(state["cs"])

    def select_cs(self, cs: int) -> None:
        self.cs = cs
        self.params[5220] = float(cs)

    def tool_length(self, codes: set[int], vals: dict[str, float]) -> None:
        if 431 in codes:
            if "z" not in vals:
                raise self.err("G43.1 needs a tool length 'Z'")
            self.tlo = vals.pop("z") * self.scale
            return
        tool = int(vals["h"]) if "h" in vals else self.tool
        if tool == 0:
            self.tlo = 0.0
            return
        if self.tool_table is None:
            raise self.err(f"G43 needs the length of tool {tool}: give a tool table (--tool-table FILE)")
        if tool not in self.tool_table:
            raise self.err(f"tool {tool} is not in the tool table")
        self.tlo = self.tool_table[tool]

    def g10(self, vals: dict[str, float]) -> None:
        lv = vals.get("l")
        if lv not in (1, 2, 20):
            raise self.err("unsupported G10: only G10 L1 (tool length), L2 and L20 (work offsets)")
        if "p" not in vals or vals["p"] != int(vals["p"]):
            raise self.err(f"G10 L{lv:g} needs a whole number 'P'")
        p = int(vals["p"])
        if lv == 1:
            if not 1 <= p <= MAX_TOOL_NUMBER:
                raise self.err("G10 L1 needs a tool number 'P'")
            if self.tool_table is None:
                self.tool_table = {}
            if "z" in vals:
                self.tool_table[p] = vals["z"] * self.scale
            for a in "xyz":
                vals.pop(a, None)
            return
        if not 0 <= p <= 9:
            raise self.err(f"G10 L{lv:g} P{p} names no coordinate system (P0..P9)")
        if vals.get("r", 0.0):
            raise self.err("coordinate system rotation (G10 L2 R) is not supported")
        cs = p or self.cs
        base = 5221 + 20 * (cs - 1)
        for i, a in enumerate("xyz"):
            if a in vals:
                v = vals[a] * self.scale
                if lv == 2:
                    self.params[base + i] = v
                else:
                    self.params[base + i] = self.mach[i] - self.g92[i] - (self.tlo if i == 2 else 0.0) - v

    def set_g92(self, codes: set[int], vals: dict[str, float]) -> None:
        if 920 in codes:
            if not any(a in vals for a in "xyz"):
                raise self.err("G92 needs at least one of X, Y, Z")
            g = self.g5x()
            for i, a in enumerate("xyz"):
                if a in vals:
                    self.g92[i] = self.mach[i] - g[i] - (self.tlo if i == 2 else 0.0) - vals[a] * self.scale
            for i in range(3):
                self.params[5211 + i] = self.g92[i]
            self.params[5210] = 1.0
        elif 921 in codes:
            self.g92 = [0.0, 0.0, 0.0]
            for i in range(3):
                self.params[5211 + i] = 0.0
            self.params[5210] = 0.0
        elif 922 in codes:
            self.g92 = [0.0, 0.0, 0.0]
            self.params[5210] = 0.0
        else:
            self.g92 = [self.params.get(5211 + i, 0.0) for i in range(3)]
            self.params[5210] = 1.0

    # -- motion -----------------------------------------------------------------------------------------------

    def target(self, vals: dict[str, float]) -> list[float]:
        """The program position (mm) the axis words of a line lead to."""
        pos = self.pos()
        t = list(pos)
        for i, a in enumerate("xyz"):
            if a in vals:
                t[i] = vals[a] * self.scale if self.absolute else pos[i] + vals[a] * self.scale
        if "@" in vals or "^" in vals:
            if self.plane != "XY":
                raise self.err("polar coordinates '@' '^' need the XY plane (G17)")
            if "x" in vals or "y" in vals:
                raise self.err("give polar coordinates '@' '^' or X Y, not both")
            r0, a0 = math.hypot(pos[0], pos[1]), math.degrees(math.atan2(pos[1], pos[0]))
            if self.absolute:
                r = vals["@"] * self.scale if "@" in vals else r0
                a = vals["^"] if "^" in vals else a0
            else:
                r = r0 + vals.get("@", 0.0) * self.scale
                a = a0 + vals.get("^", 0.0)
            t[0], t[1] = r * math.cos(math.radians(a)), r * math.sin(math.radians(a))
        return t

    def go(self, kind: str, prog: Sequence[float], **kw) -> None:
        """One move to the program position ``prog`` (mm); checks every position it leads to (a spline's
        control points too)."""
        off = self.offsets()
        controls_prog = kw.get("controls", ())
        mach = [p + o for p, o in zip(prog, off)]
        for a, p, q in zip("XYZ", prog, mach):
            if not (abs(p) <= MAX_COORD_MM and abs(q) <= MAX_COORD_MM):
                raise self.err(f"the move reaches {a}{q:.6g} mm, beyond {MAX_COORD_MM:g} mm from the origin")
        if "center" in kw:
            first, second, _ = PLANE_AXES[kw.get("plane", "XY")]
            c = kw["center"]
            kw["center"] = (c[0] + off[first], c[1] + off[second])
        if "controls" in kw:
            kw["controls"] = tuple(tuple(p + o for p, o in zip(c, off)) for c in kw["controls"])
            for c_prog, c_mach in zip(controls_prog, kw["controls"]):
                for a, p, q in zip("XY", c_prog, c_mach):
                    if not (abs(p) <= MAX_COORD_MM and abs(q) <= MAX_COORD_MM):
                        raise self.err(f"the spline's control point reaches {a}{q:.6g} mm, beyond "
                                       f"{MAX_COORD_MM:g} mm from the origin")
        self.g5_reflect = None
        if self.source is not self.main:
            kw["file"] = self.source.name
        self.moves.append(GcodeMove(kind, self.line_no, tuple(mach), **kw))
        self.mach = mach

    def feed_kw(self, vals: dict[str, float], what: str = "") -> dict:
        """The feed of one feed move (``what`` names it in the message, default the motion mode)."""
        if self.inverse_time:
            if "f" not in vals:
                raise self.err("in inverse time mode (G93) every feed move needs 'F'")
            return {"minutes": 1.0 / vals["f"], "feed_mm_min": 0.0}
        if self.feed <= 0:
            raise self.err(f"{what or f'G{self.motion}'} without a feed rate 'F'")
        return {"feed_mm_min": self.feed}

    def move(self, vals: dict[str, float], texts: dict[str, str], machine: bool) -> None:
        if self.motion is None:
            raise self.err("coordinates without a motion mode (G0, G1, G2, G3 or a canned cycle)")
        if machine:
            if self.motion not in (0, 1):
                raise self.err("G53 works with G0 or G1 only")
            if not self.absolute:
                raise self.err("G53 needs absolute mode (G90)")
            if "@" in vals or "^" in vals:
                raise self.err("G53 takes X Y Z, not polar coordinates")
            off = self.offsets()
            t = self.pos()
            for i, a in enumerate("xyz"):
                if a in vals:
                    t[i] = vals[a] * self.scale - off[i]
        elif self.motion in (0, 1, 2, 3, 33):
            t = self.target(vals)
        else:
            self.canned_cycle(vals)
            return
        if self.motion in (0, 1):
            if any(k in vals for k in "ijk") or ("r" in vals):
                raise self.err("I, J, K or R given without G2/G3")
            if self.motion == 0:
                self.go("rapid", t)
            else:
                self.go("feed", t, **self.feed_kw(vals))
            return
        if self.motion == 33:
            self.thread_feed(vals, t)
            return
        self.arc(vals, t)

    def spline(self, code: int, vals: dict[str, float]) -> None:
        """G5 (cubic) or G5.1 (quadratic) Bezier spline in the XY plane, as LinuxCNC's documentation and rs274
        define them: I J offset the first control point from the start, P Q (G5) the second one from the end;
        the offsets are incremental, in the program's units, whatever G90/G91, G90.1/G91.1 and the offsets."""
        name = "G5" if code == 50 else "G5.1"
        if self.plane != "XY":
            raise self.err(f"{name} splines need the XY plane (G17)")
        if "z" in vals:
            raise self.err(f"{name} splines move X and Y only, not Z")
        for k in "kr":
            if k in vals:
                raise self.err(f"'{k.upper()}' is not a word of {name} (it takes X Y I J"
                               + (" P Q)" if code == 50 else ")"))
        if not any(a in vals for a in "xy@^"):
            raise self.err(f"{name} needs an end point X and/or Y")
        feed = self.feed_kw(vals, name)
        s = self.scale
        p0, t = self.pos(), self.target(vals)
        has_ij = ("i" in vals, "j" in vals)
        if code == 51:
            if "p" in vals or "q" in vals:
                raise self.err("'P' and 'Q' are words of G5, not of G5.1")
            if not all(has_ij):
                raise self.err("G5.1 needs both I and J, the control point's offset from the start")
            controls = [(p0[0] + vals["i"] * s, p0[1] + vals["j"] * s, p0[2])]
        else:
            if any(has_ij) and not all(has_ij):
                raise self.err("G5 needs both I and J, or neither (right after a G5: its end tangent goes on)")
            if "p" not in vals or "q" not in vals:
                raise self.err("G5 needs both P and Q, the second control point's offset from the end")
            if all(has_ij):
                di, dj = vals["i"] * s, vals["j"] * s
            elif self.g5_reflect is None:
                raise self.err("G5 needs I and J unless the move before it is a G5 (the first of a series)")
            else:
                di, dj = self.g5_reflect
            controls = [(p0[0] + di, p0[1] + dj, p0[2]), (t[0] + vals["p"] * s, t[1] + vals["q"] * s, p0[2])]
        self.go("spline", t, controls=tuple(controls), **feed)
        if code == 50:
            self.g5_reflect = (-vals["p"] * s, -vals["q"] * s)

    def thread_feed(self, vals: dict[str, float], t: list[float]) -> None:
        """G33 as a straight feed move at K x S (the machine cannot follow a spindle it has no encoder on)."""
        if any(k in vals for k in "ijr"):
            raise self.err("I, J or R given with G33 (it takes X Y Z and K)")
        if "k" not in vals:
            raise self.err("G33 needs 'K', the distance per spindle revolution, on every line")
        k = vals["k"]
        if k <= 0:
            raise self.err(f"G33 needs a distance per revolution 'K' above 0, not K{k:g}")
        if not self.spindle_on:
            raise self.err("G33 needs the spindle turning (M3 or M4)")
        if self.spindle_rpm <= 0:
            raise self.err("G33 needs a spindle speed 'S' above 0: its feed is K x S")
        feed = k * self.scale * self.spindle_rpm
        if not MIN_FEED_MM_MIN <= feed <= MAX_FEED_MM_MIN:
            raise self.err(f"G33's feed K x S = {feed:g} mm/min is out of range: "
                           f"{MIN_FEED_MM_MIN:g}..{MAX_FEED_MM_MIN:g} mm/min")
        if not self.sync_warned:
            self.sync_warned = True
            self.warnings.append(f"{self.source.name}:{self.line_no}: G33 runs as a straight feed at K x S, not "
                                 "synchronised to the spindle (the machine has no spindle encoder): the passes of a "
                                 "multi-pass thread will not line up")
        self.go("feed", t, feed_mm_min=feed)

    def arc(self, vals: dict[str, float], t: list[float]) -> None:
        def texts_of(letter: str) -> str:
            return f"{letter.upper()}{vals[letter]:g}"

        feed = self.feed_kw(vals)
        first, second, _ = PLANE_AXES[self.plane]
        names = "ijk"
        p0 = self.pos()
        u0, v0, u1, v1 = p0[first], p0[second], t[first], t[second]
        if "r" in vals:
            if any(names[i] in vals for i in (first, second)):
                raise self.err("give either R or the arc's centre, not both")
            r = vals["r"] * self.scale
            chord = math.hypot(u1 - u0, v1 - v0)
            if chord == 0:
                raise self.err("an R arc needs an end point different from its start")
            if abs(r) < chord / 2 - 1e-6 * max(1.0, chord):
                raise self.err(f"arc radius {abs(r) / self.scale:g} is too small to reach the end point")
            h = math.sqrt(max(0.0, r * r - chord * chord / 4))
            mu, mv = (u0 + u1) / 2, (v0 + v1) / 2
            eu, ev = (u1 - u0) / chord, (v1 - v0) / chord
            if (self.motion == 2) == (r > 0):
                cu, cv = mu + h * ev, mv - h * eu
            else:
                cu, cv = mu - h * ev, mv + h * eu
        else:
            third_word = names[PLANE_AXES[self.plane][2]]
            if third_word in vals:
                raise self.err(f"'{texts_of(third_word)}' is not a centre word of an arc in the {self.plane} plane")
            if not any(names[i] in vals for i in (first, second)):
                raise self.err(f"G{self.motion} arc needs {names[first].upper()}/{names[second].upper()} or R")
            if self.arc_absolute:
                cu = vals.get(names[first], 0.0) * self.scale
                cv = vals.get(names[second], 0.0) * self.scale
            else:
                cu = u0 + vals.get(names[first], 0.0) * self.scale
                cv = v0 + vals.get(names[second], 0.0) * self.scale
            r0, r1 = math.hypot(u0 - cu, v0 - cv), math.hypot(u1 - cu, v1 - cv)
            if r0 == 0 or abs(r0 - r1) > max(0.002 * self.scale, 1e-3 * r0):
                raise self.err(f"arc end point is not on the circle (radius {r0 / self.scale:g} at the start, "
                               f"{r1 / self.scale:g} at the end)")
        turns = 1
        if "p" in vals:
            if vals["p"] != int(vals["p"]) or not 1 <= vals["p"] <= 1000:
                raise self.err("arc turns 'P' must be a whole number 1..1000")
            turns = int(vals["p"])
        self.go("arc", t, center=(cu, cv), clockwise=self.motion == 2, plane=self.plane, turns=turns, **feed)

    def go_home(self, g30: bool, vals: dict[str, float]) -> None:
        base = 5181 if g30 else 5161
        home = [self.params.get(base + i, 0.0) for i in range(3)]
        given = [a in vals for a in "xyz"]
        if any(given):
            self.go("rapid", self.target(vals))
        off = self.offsets()
        pos = self.pos()
        t = [home[i] - off[i] if (given[i] or not any(given)) else pos[i] for i in range(3)]
        self.go("rapid", t)

    def canned_cycle(self, vals: dict[str, float]) -> None:
        code = self.motion
        if self.plane != "XY":
            raise self.err(f"canned cycle G{code} needs the XY plane (G17)")
        polar = "@" in vals or "^" in vals
        if polar and ("x" in vals or "y" in vals):
            raise self.err("give polar coordinates '@' '^' or X Y, not both")
        sticky = self.cycle
        for k in "zrqp":
            if k in vals:
                sticky[k] = vals[k] * (self.scale if k in "zrq" else 1.0)
        if "z" not in sticky:
            raise self.err(f"canned cycle G{code} needs 'Z'")
        if "r" not in sticky:
            raise self.err(f"canned cycle G{code} needs a retract plane 'R'")
        if code in (73, 83) and sticky.get("q", 0.0) <= 0:
            raise self.err(f"canned cycle G{code} needs a peck depth 'Q' above 0")
        repeats = int(vals.get("l", 1))
        pos = self.pos()
        if self.cycle_il is None or self.retract_r:
            self.cycle_il = pos[2]  # G99: each block starts from where the tool stands (as rs274)
        old = self.cycle_il
        if self.absolute:
            r, cc = sticky["r"], sticky["z"]
            x = vals["x"] * self.scale if "x" in vals else pos[0]
            y = vals["y"] * self.scale if "y" in vals else pos[1]
            dx = dy = 0.0
        else:
            r = sticky["r"] + old
            cc = r + sticky["z"]
            x, y = pos[0], pos[1]
            dx, dy = vals.get("x", 0.0) * self.scale, vals.get("y", 0.0) * self.scale
        if r < cc:
            raise self.err(f"the retract plane R ({r / self.scale:g}) is below the bottom Z ({cc / self.scale:g})")
        if old < r:
            self.go("rapid", (pos[0], pos[1], r))
            old = r
        clear = r if self.retract_r else old
        feed = self.feed_kw(vals)
        dwell = sticky.get("p", 0.0)
        for _ in range(repeats):
            x, y = x + dx, y + dy
            if polar:  # each repeat from where the last hole is, around the program origin (rs274)
                r0, a0 = math.hypot(x, y), math.degrees(math.atan2(y, x))
                if self.absolute:
                    rr = vals["@"] * self.scale if "@" in vals else r0
                    aa = vals["^"] if "^" in vals else a0
                else:
                    rr, aa = r0 + vals.get("@", 0.0) * self.scale, a0 + vals.get("^", 0.0)
                x, y = rr * math.cos(math.radians(aa)), rr * math.sin(math.radians(aa))
            self.go("rapid", (x, y, old))
            if old != r:
                self.go("rapid", (x, y, r))
            if code in (73, 83):
                delta = sticky["q"]
                depth = r - delta
                while depth > cc:
                    self.go("feed", (x, y, depth), **feed)
                    if code == 83:
                        self.go("rapid", (x, y, r))
                        self.go("rapid", (x, y, depth + _CYCLE_PECK))
                    else:
                        self.go("rapid", (x, y, depth + _CYCLE_PECK))
                    depth -= delta
                self.go("feed", (x, y, cc), **feed)
                self.go("rapid", (x, y, clear))
            else:
                self.go("feed", (x, y, cc), **feed)
                if code in (82, 89):
                    self.moves.append(GcodeMove("dwell", self.line_no, tuple(self.mach), seconds=dwell))
                if code == 85:
                    self.go("feed", (x, y, r), **feed)
                    if clear != r:
                        self.go("rapid", (x, y, clear))
                elif code == 89:
                    self.go("feed", (x, y, clear), **feed)
                else:
                    self.go("rapid", (x, y, clear))
            old = clear


def parse_gcode(
    text: str, *, source: str = "<gcode>", home_g28_mm: Sequence[float] = (0.0, 0.0, 0.0),
    home_g30_mm: Sequence[float] = (0.0, 0.0, 0.0), tool_table: Mapping[int, float] | None = None,
    subroutine_path: Sequence[str | os.PathLike] = (), max_lines: int = DEFAULT_GCODE_LINES,
) -> GcodeProgram:
    """Interpret G-code text into absolute moves in mm (machine frame).

    Args:
        text: the program.
        source: its name in messages.
        home_g28_mm, home_g30_mm: where G28 and G30 go, machine mm (parameters 5161.. and 5181..).
        tool_table: tool number -> Z length offset mm, for G43 (see :func:`load_tool_table`); None: G43 with
            a tool other than 0 is an error.
        subroutine_path: folders where ``O<name> call`` finds ``name.ngc``.
        max_lines: the most lines the program may run (loops count each time).

    Raises:
        ParseError: ``source:line: message "line text"`` for any unsupported, refused or malformed word, and
            for a program that runs more than ``max_lines`` lines.
    """
    interp = _Interp(_Source(source, text), home_g28_mm=home_g28_mm, home_g30_mm=home_g30_mm, tool_table=tool_table,
                     subroutine_path=subroutine_path, max_lines=max_lines)
    try:
        interp.run()
    except RecursionError:  # pragma: no cover - an expression nested thousands deep
        raise interp.err("expression nested too deep") from None
    return GcodeProgram(interp.moves, source, interp.warnings)


def load_gcode(path: str | os.PathLike, **options) -> GcodeProgram:
    """Read and interpret a G-code file (errors name file:line); ``options`` as :func:`parse_gcode`."""
    p, text = read_text(path, not_text="not a G-code text file")
    return parse_gcode(text, source=str(p), **options)
