"""G-code in: run RS-274 programs from other CAM programs on the step/dir machine.

Supported (what grbl- and LinuxCNC-oriented CAM programs emit):

* motion: G0, G1, G2/G3 (XY-plane arcs by I/J or by R, full circles by I/J,
  helical Z), G4 (dwell, P seconds); G17 (the only plane: G18/G19 are errors);
* units and modes: G20/G21, G90/G91, G92 (set position), F, S;
* M3/M4/M5 (spindle; the step/dir machine has no spindle output: accepted,
  no motion), M6 with T (tool change: the job pauses), M0/M1 (pause),
  M2/M30 (end; later lines are not run);
* harmless modal words that CAM headers carry: G40, G49, G54, G61, G64, G80, G94;
* comments in ``( )`` and after ``;``, ``N`` line numbers, ``%`` lines, several words per line.

Anything else is a :class:`~cam.errors.ParseError` naming the line and the word.

Every number is checked before it is used (the ranges are :mod:`cam.limits`): coordinates X Y Z I J R
and every position they lead to (G91 sums, G92 offsets) at most :data:`~cam.limits.MAX_COORD_MM`
either way, F :data:`~cam.limits.MIN_FEED_MM_MIN`..:data:`~cam.limits.MAX_FEED_MM_MIN` mm/min,
G4 P 0..:data:`~cam.limits.MAX_DWELL_S` s, T a whole number 0..:data:`~cam.limits.MAX_TOOL_NUMBER`,
S 0..:data:`~cam.limits.MAX_SPINDLE_RPM`, N 0..:data:`~cam.limits.MAX_LINE_NUMBER`; a word out of
range is a ParseError naming the line and the word.

Planning the motion (frames, arcs, feeds, the half-step accuracy) is :mod:`cam.job.gcode`.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field

from ..choices import GCODE_SUFFIXES
from ..errors import ParseError
from ..fileio import read_text
from ..limits import (
    MAX_COORD_MM, MAX_DWELL_S, MAX_FEED_MM_MIN, MAX_LINE_NUMBER, MAX_SPINDLE_RPM, MAX_TOOL_NUMBER, MIN_FEED_MM_MIN,
)

__all__ = ["GcodeMove", "GcodeProgram", "parse_gcode", "load_gcode", "GCODE_SUFFIXES"]


_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")
_NOOP_G = {40, 49, 54, 61, 64, 80, 94}


@dataclass
class GcodeMove:
    """One programmed move in mm (machine-independent, G-code frame: +Y up, +Z up).

    ``kind``: "rapid", "feed", "arc", "dwell" or "pause".  ``end`` is absolute mm;
    arcs carry ``center`` (mm) and ``clockwise``; dwell carries ``seconds``;
    pause carries ``note``; ``feed_mm_min`` applies to feed and arc moves.
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


@dataclass
class GcodeProgram:
    """Parsed program: moves in order, plus warnings; ``source`` names the file."""

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


@dataclass
class _Modal:
    """What a G-code program carries from one line to the next (mm, program frame)."""

    pos: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # absolute program position
    offset: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # G92: machine = program + offset
    scale: float = 1.0  # 25.4 in G20
    absolute: bool = True
    motion: int | None = None  # modal motion: 0, 1, 2, 3
    feed: float = 0.0
    tool: int = 0


def _shown(word: str) -> str:
    """A word as a message quotes it: at most 24 characters."""
    return word if len(word) <= 24 else word[:20] + "..."


def _line_words(body: str, err) -> tuple[list[float], list[float], dict[str, float], dict[str, str]]:
    """The G codes, the M codes and the other words (letter -> value, and letter -> the word as written)
    of one line without comments."""
    leftover = _WORD.sub("", body).strip()
    if leftover:
        bad = leftover.split()[0]
        if bad[:1].isalpha():
            raise err(f"word '{_shown(bad)}' has no number")
        raise err(f"cannot read '{_shown(bad)}'")
    gs: list[float] = []
    ms: list[float] = []
    vals: dict[str, float] = {}
    texts: dict[str, str] = {}
    for m in _WORD.finditer(body):
        k = m.group(1).upper()
        v = float(m.group(2))
        word = _shown(k + m.group(2))
        if k in "GM" and not math.isfinite(v):
            raise err(f"unsupported word '{word}'")
        if k == "G":
            gs.append(v)
        elif k == "M":
            ms.append(v)
        elif k not in "XYZIJRFSTPN":
            raise err(f"unsupported word '{_shown(m.group(0).replace(' ', ''))}'")
        elif k in vals:
            raise err(f"word '{k}' appears twice")
        else:
            vals[k] = v
            texts[k] = word
    return gs, ms, vals, texts


def _check_words(vals: dict[str, float], texts: dict[str, str], scale: float, err) -> None:
    """Every word of one line finite and in its range (:mod:`cam.limits`); ``scale`` is 25.4 in G20."""
    for k, v in vals.items():
        word = texts[k]
        if k in "XYZIJR":
            if not abs(v * scale) <= MAX_COORD_MM:
                raise err(f"word '{word}' is out of range: coordinates are at most {MAX_COORD_MM:g} mm either way")
        elif k == "F":
            if not MIN_FEED_MM_MIN <= v * scale <= MAX_FEED_MM_MIN:
                raise err(f"feed '{word}' is out of range: {MIN_FEED_MM_MIN:g}..{MAX_FEED_MM_MIN:g} mm/min")
        elif k == "P":
            if not 0 <= v <= MAX_DWELL_S:
                raise err(f"dwell '{word}' is out of range: 0..{MAX_DWELL_S:g} s")
        elif k == "T":
            if not (0 <= v <= MAX_TOOL_NUMBER and v == int(v)):
                raise err(f"tool '{word}' is out of range: a whole number 0..{MAX_TOOL_NUMBER}")
        elif k == "S":
            if not 0 <= v <= MAX_SPINDLE_RPM:
                raise err(f"spindle speed '{word}' is out of range: 0..{MAX_SPINDLE_RPM:g} rpm")
        elif k == "N":
            if not 0 <= v <= MAX_LINE_NUMBER:
                raise err(f"line number '{word}' is out of range: 0..{MAX_LINE_NUMBER}")


def _g_codes(gs: list[float], st: _Modal, err) -> tuple[bool, bool]:
    """Apply the modal G codes of one line; returns (dwell on this line, G92 on this line)."""
    dwell = False
    set_pos = False
    for g in gs:
        if g in (0, 1, 2, 3):
            st.motion = int(g)
        elif g == 4:
            dwell = True
        elif g == 17:
            pass
        elif g in (18, 19):
            raise err(f"unsupported plane 'G{g:g}' (only G17, the XY plane)")
        elif g == 20:
            st.scale = 25.4
        elif g == 21:
            st.scale = 1.0
        elif g == 90:
            st.absolute = True
        elif g == 91:
            st.absolute = False
        elif g == 92:
            set_pos = True
        elif g in _NOOP_G:
            pass
        else:
            raise err(f"unsupported word 'G{g:g}'")
    return dwell, set_pos


def _m_codes(ms: list[float], st: _Modal, line_no: int, moves: list[GcodeMove], err) -> bool:
    """Apply the M codes of one line (pauses join ``moves``); True at the end of the program."""
    end_program = False
    for mcode in ms:
        if mcode in (3, 4, 5):
            continue
        if mcode == 6:
            moves.append(GcodeMove("pause", line_no, tuple(st.pos), note=f"tool change: T{st.tool} (line {line_no})"))
        elif mcode in (0, 1):
            moves.append(GcodeMove("pause", line_no, tuple(st.pos),
                                   note=f"program pause M{mcode:g} (line {line_no})"))
        elif mcode in (2, 30):
            end_program = True
        else:
            raise err(f"unsupported word 'M{mcode:g}'")
    return end_program


def _set_position(vals: dict[str, float], st: _Modal, err) -> None:
    """G92: the named axes take the given program coordinates; the machine does not move."""
    if not any(a in vals for a in "XYZ"):
        raise err("G92 needs at least one of X, Y, Z")
    for i, a in enumerate("XYZ"):
        if a in vals:
            machine = st.pos[i] + st.offset[i]
            st.pos[i] = vals[a] * st.scale
            st.offset[i] = machine - st.pos[i]


def _arc_center(vals: dict[str, float], st: _Modal, target: list[float], err) -> tuple[float, float]:
    """Centre (program frame, mm) of the G2/G3 arc from ``st.pos`` to ``target``, by R or by I/J."""
    motion, scale = st.motion, st.scale
    x0, y0 = st.pos[0], st.pos[1]
    x1, y1 = target[0], target[1]
    if "R" in vals:
        if "I" in vals or "J" in vals:
            raise err("give either R or I/J for an arc, not both")
        r = vals["R"] * scale
        chord = math.hypot(x1 - x0, y1 - y0)
        if chord == 0:
            raise err("an R arc needs an end point different from its start")
        if abs(r) < chord / 2 - 1e-6 * max(1.0, chord):
            raise err(f"arc radius {abs(r) / scale:g} is too small to reach the end point")
        h = math.sqrt(max(0.0, r * r - chord * chord / 4))
        mx, my = (x0 + x1) / 2, (y0 + y1) / 2
        ux, uy = (x1 - x0) / chord, (y1 - y0) / chord
        # the centre lies right of the travel direction for G2 with R > 0 (and G3 with R < 0),
        # left of it otherwise; R > 0 picks the short arc, R < 0 the long one
        if (motion == 2) == (r > 0):
            return mx + h * uy, my - h * ux
        return mx - h * uy, my + h * ux
    if "I" not in vals and "J" not in vals:
        raise err(f"G{motion} arc needs I/J or R")
    cx, cy = x0 + vals.get("I", 0.0) * scale, y0 + vals.get("J", 0.0) * scale
    r0, r1 = math.hypot(x0 - cx, y0 - cy), math.hypot(x1 - cx, y1 - cy)
    if r0 == 0 or abs(r0 - r1) > max(0.002 * scale, 1e-3 * r0):
        raise err(f"arc end point is not on the circle (radius {r0 / scale:g} at the start, "
                  f"{r1 / scale:g} at the end)")
    return cx, cy


def _check_position(target: list[float], machine_end: tuple[float, ...], err) -> None:
    """Refuse a move to a position beyond :data:`~cam.limits.MAX_COORD_MM` (G91 sums, G92 offsets)."""
    for a, p, q in zip("XYZ", target, machine_end):
        if not (abs(p) <= MAX_COORD_MM and abs(q) <= MAX_COORD_MM):
            raise err(f"the move reaches {a}{q:.6g} mm, beyond {MAX_COORD_MM:g} mm from the origin")


def _motion(vals: dict[str, float], axes: list[str], st: _Modal, line_no: int, err) -> GcodeMove | None:
    """The move of one line in the modal motion mode (None if the line names no axis or arc word)."""
    has_arc_words = any(k in vals for k in "IJR")
    if not axes and not has_arc_words:
        return None
    if st.motion is None:
        raise err("coordinates without a motion mode (G0, G1, G2 or G3)")
    target = list(st.pos)
    for i, a in enumerate("XYZ"):
        if a in vals:
            target[i] = vals[a] * st.scale if st.absolute else st.pos[i] + vals[a] * st.scale
    machine_end = tuple(t + o for t, o in zip(target, st.offset))
    _check_position(target, machine_end, err)
    if st.motion in (0, 1):
        if has_arc_words:
            raise err("I, J or R given without G2/G3")
        if st.motion == 1 and st.feed <= 0:
            raise err("G1 without a feed rate 'F'")
        move = GcodeMove("rapid" if st.motion == 0 else "feed", line_no, machine_end, feed_mm_min=st.feed)
    else:
        if st.feed <= 0:
            raise err(f"G{st.motion} without a feed rate 'F'")
        cx, cy = _arc_center(vals, st, target, err)
        move = GcodeMove("arc", line_no, machine_end, feed_mm_min=st.feed,
                         center=(cx + st.offset[0], cy + st.offset[1]), clockwise=(st.motion == 2))
    st.pos = target
    return move


def parse_gcode(text: str, *, source: str = "<gcode>") -> GcodeProgram:
    """Interpret G-code text into absolute moves in mm.

    Raises:
        ParseError: ``source:line: message "line text"`` for any unsupported or malformed word.
    """
    moves: list[GcodeMove] = []
    st = _Modal()
    warnings: list[str] = []
    for line_no, raw in enumerate(text.splitlines(), start=1):
        def err(msg: str, line_no: int = line_no, raw: str = raw) -> ParseError:
            return ParseError(f'{source}:{line_no}: {msg} "{raw.strip()[:60]}"')

        body = _strip_comments(raw, err).strip()
        if not body or body == "%" or body.startswith("/"):
            continue
        gs, ms, vals, texts = _line_words(body, err)
        dwell, set_pos = _g_codes(gs, st, err)
        _check_words(vals, texts, st.scale, err)
        if "F" in vals:
            st.feed = vals["F"] * st.scale
        if "T" in vals:
            st.tool = int(vals["T"])
        end_program = _m_codes(ms, st, line_no, moves, err)
        if dwell:
            if "P" not in vals or vals["P"] < 0:
                raise err("G4 needs a dwell time 'P' in seconds")
            moves.append(GcodeMove("dwell", line_no, tuple(st.pos), seconds=vals["P"]))
        axes = [a for a in "XYZ" if a in vals]
        if set_pos:
            _set_position(vals, st, err)
            axes = []
        if end_program:
            break
        move = _motion(vals, axes, st, line_no, err)
        if move is not None:
            moves.append(move)
    return GcodeProgram(moves, source, warnings)


def load_gcode(path: str | os.PathLike) -> GcodeProgram:
    """Read and interpret a G-code file (errors name file:line)."""
    p, text = read_text(path, not_text="not a G-code text file")
    return parse_gcode(text, source=str(p))
