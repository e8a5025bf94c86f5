"""G-code in, one block: a line's words read and checked, then run in LinuxCNC's order of execution.

Each word is read (a G or M code LinuxCNC does not have, or that this machine refuses, is an error naming it),
the parameters the line sets are set, every number is checked against :mod:`cam.limits`, and then the line's
codes act in the order rs274 gives them: feed mode and units, feed, spindle and tool, tool change, modal state
(M70..M73), dwell, plane, tool length, coordinate system, distance modes, G28/G30, G10, G92, the motion mode,
the motion itself, and last the pauses and the end of the program.
"""
from __future__ import annotations

import math

from ..limits import (
    MAX_COORD_MM, MAX_DWELL_S, MAX_FEED_MM_MIN, MAX_LINE_NUMBER, MAX_REPEAT, MAX_SPINDLE_RPM, MAX_TOOL_NUMBER,
    MIN_FEED_MM_MIN,
)
from ._gcode_data import (
    _CS, _CYCLES, _IGNORED_M, _IO_M, _LETTERS, _MARLIN, _MARLIN_G, _MARLIN_M, _MARLIN_USER_M, _MOTION, _REFUSED_G, _SPLINES,
    _SUPPORTED_G, COMP_NO_TABLE, _End, _shown,
)
from ._gcode_state import _State

_COMP_FRAME = {100, 180, 190, 280, 300, 430, 431, 490, 920, 921, 922, 923, 540, 550, 560, 570, 580, 590, 591, 592, 593}
"""Codes refused while cutter compensation is on (they change the plane or the frame its held moves are in)."""
from .ngc import Line


def _tool_diameter(block: _State, code: int, vals: dict[str, float]) -> float:
    """The diameter (mm) G41/G42 (``code`` 410/420) take from the tool table: tool D, or the tool in the
    spindle's (D omitted or D0), as rs274; tool 0 (none) is 0."""
    name = f"G{code // 10}"
    if block.tool_diameters_mm is None:
        raise block.err(f"'{name}': {COMP_NO_TABLE}")
    if "d" in vals and (vals["d"] != int(vals["d"]) or vals["d"] < 0):
        raise block.err(f"{name} needs a tool number 'D' (a whole number 0 or more), not 'D{vals['d']:g}': for a "
                        f"diameter give {name}.1 D<diameter>")
    tool = int(vals["d"]) if vals.get("d") else block.tool  # D0: the spindle's, as rs274
    if not tool:
        return 0.0
    if tool not in block.tool_lengths_mm:
        raise block.err(f"{name}: tool {tool} is not in the tool table")
    return block.tool_diameters_mm.get(tool, 0.0)


class _Block(_State):
    """Runs one line that is not an O word; the motion it makes is :class:`~._gcode_motion._Motion`'s."""

    def block(self, line: Line) -> None:
        """Run one line: its words, its parameter settings, then its codes in LinuxCNC's order."""
        if self.resync is not None:
            # after a tool change LinuxCNC reads its position again at the next block: the program position
            # is where the last move ended, so a tool length offset taken on the M6 line itself moves Z with
            # the next move (as rs274 does)
            off = self.offsets()
            self.mach = [p + o for p, o in zip(self.resync, off)]
            self.resync = None
        codes, ms, vals, texts = self.read_words(line)
        self.assign(line)
        mcodes = {int(m) for m, _ in ms}
        self.check_m_codes(ms)
        motions = codes & _MOTION
        splines = codes & _SPLINES
        if 800 in motions and len(motions | splines) > 1:
            motions.discard(800)  # rs274: G80 with another motion code of group 1 on its line gives way to it
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
        self.feed_spindle_tool(mcodes, vals)
        self.modal_m_codes(mcodes)
        self.modal_g_codes(codes, vals)
        axes_used = self.frame_codes(codes, vals)
        if motions:
            self.motion_mode(motions)
        if "q" in vals and not (codes & {640, 50} or 61 in mcodes or self.motion in (73, 83)):
            raise self.err(f"unsupported word '{texts['q']}' (no G or M code on the line uses it)")
        self.motion_of(codes, splines, vals, texts, axes_used)
        self.pauses_and_end(mcodes)

    def read_words(self, line: Line) -> tuple[set[int], list[tuple[float, str]], dict[str, float], dict[str, str]]:
        """The line's words, each valued and checked: its G codes (ten times the number: G43.1 is 431), its M codes
        with their text, and the values and texts of its other words by letter."""
        gs: list[tuple[int, str]] = []
        ms: list[tuple[float, str]] = []
        vals: dict[str, float] = {}
        texts: dict[str, str] = {}
        for letter, tree, text in line.words:
            v = tree[1] if tree[0] == "n" else self.value_of(tree)  # a number is its value (as evaluate gives it)
            word = _shown(text.upper())
            if letter in "gm" and not math.isfinite(v):
                raise self.err(f"unsupported word '{word}'")
            if letter == "e":
                raise self.err(f"'{word}' is " + _MARLIN.format(what="extruder word"))
            if letter == "m" and v in _MARLIN_M:
                raise self.err(f"'M{v:g}' is " + _MARLIN.format(what="code"))
            if letter == "g" and round(v * 10) in _MARLIN_G and abs(v * 10 - round(v * 10)) <= 1e-6:
                raise self.err(f"'G{v:g}' is " + _MARLIN.format(what="code"))
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
                if "d" in vals:
                    raise self.err("word 'D' appears twice")
                vals["d"], texts["d"] = v, word
            elif letter not in _LETTERS:
                raise self.err(f"unsupported word '{word}'")
            elif letter in vals:
                raise self.err(f"word '{letter.upper()}' appears twice")
            else:
                vals[letter] = v
                texts[letter] = word
        codes = {c for c, _ in gs}
        if "d" in vals and not codes & {410, 411, 420, 421}:
            raise self.err(f"cutter compensation word '{texts['d']}' without G41.1/G42.1 is not supported (nor "
                           "without G41/G42)")
        return codes, ms, vals, texts

    def assign(self, line: Line) -> None:
        """The line's parameter settings (``#1=2``): every value found before any is set, as in rs274."""
        values = [self.value_of(tree) for _, tree in line.assigns]
        if not all(math.isfinite(v) for v in values):
            raise self.err("a parameter is given a number that is not finite")
        for (ref, _), v in zip(line.assigns, values):
            if ref[0] == "num":
                ref = ("num", self.value_of(ref[1]))
            self.write_param(ref, v)

    def check_m_codes(self, ms: list[tuple[float, str]]) -> None:
        """Every M code of the line one that runs here (user M codes and I/O refused, each saying why)."""
        for m, text in ms:
            if 100 <= m <= 199:
                hint = f" ({text} is also a Marlin (3D printer firmware) code: if this program drives a 3D " \
                       "printer, it is not a mill's program)" if m in _MARLIN_USER_M else ""
                raise self.err(f"user M code '{text}' is not supported: it would run a program outside the G-code"
                               + hint)
            if m in _IO_M:
                raise self.err(f"'{text}': digital and analog I/O is not supported: the machine has none")
            if m not in (0, 1, 2, 6, 7, 8, 9, 30, 60, 61, 70, 71, 72, 73) and m not in _IGNORED_M:
                raise self.err(f"unsupported word '{text}'")

    def feed_spindle_tool(self, mcodes: set[int], vals: dict[str, float]) -> None:
        """F, S, M3/M4/M5, T, the tool change M6 (a pause), M61 and the coolant codes' warning."""
        if "f" in vals:
            self.feed = vals["f"] if self.inverse_time else vals["f"] * self.scale
        if "s" in vals:
            self.spindle_rpm = vals["s"]
        if mcodes & {3, 4}:
            self.spindle_on = True
            self.spindle = 4 if 4 in mcodes else 3
        if 5 in mcodes:
            self.spindle_on = False
            self.spindle = 0
        if self.spindle and not self.spindle_noted:
            self.spindle_noted = True
            self.warnings.append(f"{self.source.name}:{self.line_no}: spindle M{self.spindle} S{self.spindle_rpm:g} "
                                 "recorded with the moves, for ports that switch a spindle; a step/dir port (the "
                                 "parallel port, the mock) has no spindle output and ignores it: run the spindle "
                                 "by hand")
        if "t" in vals:
            t = int(vals["t"])
            if self.tool_lengths_mm is not None and t and t not in self.tool_lengths_mm:
                raise self.err(f"tool 'T{t}' is not in the tool table")
            self.selected_tool = t
        if 6 in mcodes:
            self.emit("pause", note=f"tool change: T{self.selected_tool} (line {self.line_no})")
            self.tool = self.selected_tool
            self.resync = self.pos()
            self.comp_exit = None  # the position is read again: after G40 too, the next move starts where the tool is
        if 61 in mcodes:
            if "q" not in vals or vals["q"] != int(vals["q"]) or not 0 <= vals["q"] <= MAX_TOOL_NUMBER:
                raise self.err("M61 needs a tool number 'Q'")
            self.tool = self.selected_tool = int(vals["q"])
        if mcodes & {7, 8, 9} and not self.coolant_warned:
            self.coolant_warned = True
            self.warnings.append(f"{self.source.name}:{self.line_no}: coolant M7/M8/M9 ignored: the machine has "
                                 "no coolant output")

    def modal_m_codes(self, mcodes: set[int]) -> None:
        """M70 (save the modal state), M71 (forget it), M72 (restore it), M73 (restore it when the subroutine
        returns)."""
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

    def modal_g_codes(self, codes: set[int], vals: dict[str, float]) -> None:
        """The dwell G4, then the plane, tool length, coordinate system, distance and retract modes."""
        if 40 in codes:
            if "p" not in vals:
                raise self.err("G4 needs a dwell time 'P' in seconds")
            self.emit("dwell", seconds=vals["p"])
        if self.comp_side and codes & _COMP_FRAME:
            raise self.err("a change of plane, coordinate system or offsets while cutter compensation is on is not "
                           "supported: turn it off (G40) first")
        for code, plane in ((170, "XY"), (180, "XZ"), (190, "YZ")):
            if code in codes:
                self.plane = plane
        if 400 in codes:
            self.comp_off()
        if codes & {411, 421}:
            if "d" not in vals:
                raise self.err("cutter compensation G41.1/G42.1 needs the tool's diameter 'D'")
            if "l" in vals:
                raise self.err(f"'L{vals['l']:g}' (a lathe tool's orientation) with cutter compensation G41.1/G42.1 is "
                               "not supported: the machine is a 3-axis mill")
            self.comp_on(1 if 411 in codes else -1, vals["d"] * self.scale)
        if codes & {410, 420}:
            self.comp_on(1 if 410 in codes else -1, _tool_diameter(self, 410 if 410 in codes else 420, vals))
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

    def frame_codes(self, codes: set[int], vals: dict[str, float]) -> bool:
        """G28/G30 (and .1), G10 and G92..G92.3; True when one of them took the line's axis words."""
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
        return axes_used

    def motion_mode(self, motions: set[int]) -> None:
        """The line's motion code becomes the motion mode (G80 ends it); a new series of canned cycles starts."""
        (m,) = motions
        in_cycle = self.motion is not None and self.motion * 10 in _CYCLES
        if m not in _CYCLES or not in_cycle:
            self.cycle_il = None  # a new series of canned cycles starts from where the tool stands
        self.motion = None if m == 800 else m // 10
        if m in (382, 383):
            self.probe_code = m  # motion mode 38: G38.2 or G38.3 (:mod:`._gcode_probe`)
        if m == 800:
            self.cycle_il = None

    def motion_of(self, codes: set[int], splines: set[int], vals: dict[str, float], texts: dict[str, str],
                  axes_used: bool) -> None:
        """The line's motion: a spline, or a move in the motion mode when axis words (or an arc's centre) are
        left for it."""
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

    def pauses_and_end(self, mcodes: set[int]) -> None:
        """M0, M1 and M60 pause after the line's motion; M2 and M30 end the program."""
        if mcodes & {0, 1}:
            for m in sorted(mcodes & {0, 1}):
                self.emit("pause", note=f"program pause M{m} (line {self.line_no})")
        if 60 in mcodes:
            self.emit("pause", note=f"pallet change pause M60 (line {self.line_no})")
        if mcodes & {2, 30}:
            self.comp_off()  # as rs274: the program's end turns compensation off
            raise _End

    def check_words(self, vals: dict[str, float], texts: dict[str, str], *, pq_offsets: bool = False) -> None:
        """Every word of one line finite and in its range (:mod:`cam.limits`); ``pq_offsets``: P is a
        coordinate offset (G5), not a time."""
        scale = self.scale
        for k, v in vals.items():
            word = texts[k]
            if k in "xyzijkrqd@" or (k == "p" and pq_offsets):
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

