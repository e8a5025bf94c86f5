"""The grbl emulator's G-code parser: a block checked whole, then its actions in grbl's order.

A part of :class:`cam.sim.grbl.GrblEmulator`.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Optional

from ._grbl_base import MM_PER_INCH, WORD_RE, Block, GrblCodeError
from ._grbl_probe import PROBE_CODES

_G_GROUPS = {
    "motion": (0, 1, 2, 3, 38.2, 38.3, 38.4, 38.5, 80), "nonmodal": (4, 10, 28, 28.1, 30, 30.1, 53, 92, 92.1),
    "plane": (17, 18, 19), "distance": (90, 91), "arc": (91.1,), "feedmode": (93, 94), "units": (20, 21),
    "cutter": (40,), "tlo": (43.1, 49), "wcs": (54, 55, 56, 57, 58, 59), "path": (61,),
}
_M_GROUPS = {"stop": (0, 1, 2, 30), "spindle": (3, 4, 5), "coolant": (7, 8, 9)}


def classify_words(words: list[tuple[str, float]]) -> tuple[dict[str, float], dict[str, int], dict[str, float]]:
    """A block's words as grbl sorts them: G codes by modal group, M codes by group, value words by letter
    (errors 20 unsupported, 21 two of one modal group, 25 a repeated word, 29 G59.x)."""
    g_groups: dict[str, float] = {}
    m_groups: dict[str, int] = {}
    values: dict[str, float] = {}
    for letter, value in words:
        if letter == "G":
            code = round(value, 1)
            if code in (59.1, 59.2, 59.3):
                raise GrblCodeError(29)
            group = next((name for name, codes in _G_GROUPS.items() if code in codes), None)
            if group is None:
                raise GrblCodeError(20)
            if group in g_groups:
                raise GrblCodeError(21)
            g_groups[group] = code
        elif letter == "M":
            mgroup = next((name for name, codes in _M_GROUPS.items() if value in codes), None)
            if mgroup is None or value != int(value):
                raise GrblCodeError(20)
            if mgroup in m_groups and mgroup != "coolant":
                raise GrblCodeError(21)
            m_groups[mgroup] = int(value)
        elif letter in "FIJKLNPRSTXYZ":
            if letter in values:
                raise GrblCodeError(25)
            values[letter] = value
        else:
            raise GrblCodeError(20)
    return g_groups, m_groups, values


def arc_points(base: list[float], target: list[float], plane: int, clockwise: bool, values: dict[str, float],
               scale: float, tolerance_mm: float) -> tuple[list[list[float]], float]:
    """The chord ends of a G2/G3 arc from ``base`` to ``target`` (``target`` exact at the end), each chord's
    sagitta within ``tolerance_mm`` (``$12``), and the arc's length (errors 33, 34, 35 as grbl's)."""
    a0, a1, lin = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}[plane]
    x0, y0 = base[a0], base[a1]
    x1, y1 = target[a0], target[a1]
    if "R" in values:
        r = values["R"] * scale
        dx, dy = x1 - x0, y1 - y0
        chord2 = dx * dx + dy * dy
        if chord2 < 1e-18:
            raise GrblCodeError(33)
        h2 = r * r - chord2 / 4.0
        if h2 < -1e-9 * max(1.0, r * r):
            raise GrblCodeError(34)
        h = math.sqrt(max(h2, 0.0)) / math.sqrt(chord2) * (-1.0 if clockwise else 1.0) * (1.0 if r >= 0 else -1.0)
        r = abs(r)   # the centre: right of the chord for a clockwise arc under 180 degrees, left for one over
        cx, cy = x0 + 0.5 * dx - dy * h, y0 + 0.5 * dy + dx * h
    else:
        letters = "IJK"
        if letters[a0] not in values and letters[a1] not in values:
            raise GrblCodeError(35)
        cx = x0 + values.get(letters[a0], 0.0) * scale
        cy = y0 + values.get(letters[a1], 0.0) * scale
        r = math.hypot(x0 - cx, y0 - cy)
        r_end = math.hypot(x1 - cx, y1 - cy)
        if abs(r_end - r) > 0.005 and abs(r_end - r) > 0.001 * r:
            raise GrblCodeError(33)
    t0 = math.atan2(y0 - cy, x0 - cx)
    sweep = math.atan2(y1 - cy, x1 - cx) - t0
    if clockwise and sweep >= -1e-12:
        sweep -= 2.0 * math.pi
    elif not clockwise and sweep <= 1e-12:
        sweep += 2.0 * math.pi
    if "R" in values and abs(abs(sweep) - 2 * math.pi) < 1e-9:
        sweep = 0.0
    n = 1
    if r > tolerance_mm:
        n = max(1, int(math.ceil(abs(sweep) / (2.0 * math.acos(1.0 - tolerance_mm / r)) - 1e-9)))
    points = []
    for k in range(1, n):
        ang = t0 + sweep * k / n
        pt = list(base)
        pt[a0], pt[a1] = cx + r * math.cos(ang), cy + r * math.sin(ang)
        pt[lin] = base[lin] + (target[lin] - base[lin]) * k / n
        points.append(pt)
    points.append(list(target))
    return points, math.hypot(abs(sweep) * r, target[lin] - base[lin])


@dataclass
class _Modes:
    """One block's modes and offsets, worked out before anything of it runs."""

    g: dict
    inches: bool
    scale: float
    inverse_time: bool
    feed: float
    plane: int
    incremental: bool
    wcs: int
    tlo: float
    motion: int
    nonmodal: Optional[float]
    axis: dict
    axis_cmd: Optional[str]
    g92: list
    wcs_table: list
    base: list
    new_wcs_row: Optional[tuple[int, list[float]]] = None
    used: set = field(default_factory=set)

    def offset(self, i: int) -> float:
        return self.wcs_table[self.wcs][i] + self.g92[i] + (self.tlo if i == 2 else 0.0)


class _GCode:
    """The grbl emulator's G-code parser: a block checked whole, then its actions in grbl's order."""

    settings: dict

    @staticmethod
    def _words(line: str) -> list[tuple[str, float]]:
        words = []
        pos = 0
        while pos < len(line):
            if not line[pos].isalpha():
                raise GrblCodeError(1)
            m = WORD_RE.match(line, pos)
            if not m:
                raise GrblCodeError(2)
            words.append((m.group(1), float(m.group(2))))
            pos = m.end()
        return words

    def _parse_gcode(self, line: str, line_no: int, queue: bool) -> None:
        """Check a block completely (grbl executes nothing of a block it refuses), then set the parser state
        and list the actions (planner blocks, waits, calls) that run in grbl's order of execution."""
        g_groups, m_groups, values = classify_words(self._words(line))
        m = self._block_modes(g_groups, values)
        actions: deque = deque()
        self._pre_motion(m, m_groups, values, actions)
        self._offsets(m, values)
        if m.nonmodal == 53 and m.motion not in (0, 1):
            raise GrblCodeError(30)
        blocks, end = self._motion_blocks(m, values, line_no, actions)
        if set(values) - m.used:
            raise GrblCodeError(36)
        if self.settings[20] and blocks and not all(self._within_travel(b.end) for b in blocks):
            self._actions = deque([("call", lambda: self._raise_alarm(2, critical=True))])
            return
        self._commit(m, m_groups, values)
        if "spindle" in m_groups:
            spindle = m_groups["spindle"]
            actions.append(("call", lambda: setattr(self._parser, "spindle", spindle)))
        if "coolant" in m_groups:
            coolant = m_groups["coolant"]
            actions.append(("call", lambda: self._set_coolant(coolant)))
        if not self._check and m.motion in PROBE_CODES and m.axis_cmd == "motion":
            actions.extend(self._probe_actions(m.motion, blocks))  # a probing cycle (cam.sim._grbl_probe)
        elif not self._check:
            actions.extend(("block", b) for b in blocks)
        self._parser_pos = list(end)
        stop = m_groups.get("stop")
        if stop is not None and not self._check:
            actions.append(("sync", None))
            actions.append(("pause", None) if stop in (0, 1) else ("call", self._program_end))
        if queue and actions:
            self._actions = actions

    def _block_modes(self, g: dict[str, float], values: dict[str, float]) -> _Modes:
        p = self._parser
        inches = g["units"] == 20 if "units" in g else p.inches
        scale = MM_PER_INCH if inches else 1.0
        if "N" in values and not 0 <= values["N"] <= 9999999:
            raise GrblCodeError(27)
        if any(values.get(letter, 0.0) < 0 for letter in "FST"):
            raise GrblCodeError(4)
        if "T" in values and values["T"] != int(values["T"]):
            raise GrblCodeError(23)
        if values.get("T", 0) > 255:
            raise GrblCodeError(38)
        nonmodal = g.get("nonmodal")
        axis = {i: values["XYZ"[i]] * scale for i in range(3) if "XYZ"[i] in values}
        axis_cmd = None
        if nonmodal in (10, 28, 30, 92):
            axis_cmd = "nonmodal"
            if "motion" in g and axis:
                raise GrblCodeError(24)
        elif axis:
            axis_cmd = "motion"
        motion = (g["motion"] if g["motion"] in PROBE_CODES else int(g["motion"])) if "motion" in g else p.motion
        if axis_cmd == "motion" and motion == 80:
            raise GrblCodeError(31)
        inverse_time = g["feedmode"] == 93 if "feedmode" in g else p.inverse_time
        feed = values["F"] * (1.0 if inverse_time else scale) if "F" in values else (0.0 if inverse_time else p.feed)
        tlo = p.tlo_mm
        if g.get("tlo") == 43.1:
            if "Z" not in values or set(axis) - {2}:
                raise GrblCodeError(37)
            tlo = axis.pop(2)
            axis_cmd = axis_cmd if axis else None
        elif g.get("tlo") == 49:
            tlo = 0.0
        return _Modes(
            g=g, inches=inches, scale=scale, inverse_time=inverse_time, feed=feed,
            plane=int(g.get("plane", p.plane)), incremental=g["distance"] == 91 if "distance" in g else p.incremental,
            wcs=int(g["wcs"]) - 54 if "wcs" in g else p.wcs, tlo=tlo, motion=motion, nonmodal=nonmodal, axis=axis,
            axis_cmd=axis_cmd, g92=list(p.g92_mm), wcs_table=[list(r) for r in self._wcs_mm],
            base=list(self._parser_pos), used=set("NFST") | ({"X", "Y", "Z"} if axis_cmd else set()))

    def _pre_motion(self, m: _Modes, m_groups: dict[str, int], values: dict[str, float], actions: deque) -> None:
        """Spindle and coolant changes wait for the planner to empty; a dwell waits, then sleeps."""
        spindle_on = self._parser.spindle != 5
        if ("spindle" in m_groups or "S" in values) and (spindle_on or m_groups.get("spindle", 5) != 5):
            actions.append(("sync", None))
        if "coolant" in m_groups:
            actions.append(("sync", None))
        if m.nonmodal == 4:
            if "P" not in values:
                raise GrblCodeError(28)
            if values["P"] < 0:
                raise GrblCodeError(4)
            m.used.add("P")
            dwell_s = values["P"]
            actions.append(("sync", None))
            actions.append(("wait", lambda: self._start_dwell(dwell_s)))

    def _offsets(self, m: _Modes, values: dict[str, float]) -> None:
        """G10 L2/L20 (a work offset set, L20 so that the tool stands at the given position) and G92/G92.1."""
        if m.nonmodal == 10:
            if "L" not in values or "P" not in values:
                raise GrblCodeError(28)
            m.used |= {"L", "P"}
            if values["L"] not in (2, 20):
                raise GrblCodeError(20)
            if values["P"] != int(values["P"]) or not 0 <= values["P"] <= 6:
                raise GrblCodeError(29)
            if not m.axis:
                raise GrblCodeError(26)
            row = m.wcs if int(values["P"]) == 0 else int(values["P"]) - 1
            new = list(m.wcs_table[row])
            for i, v in m.axis.items():
                new[i] = v if values["L"] == 2 else m.base[i] - m.g92[i] - (m.tlo if i == 2 else 0.0) - v
            m.new_wcs_row = (row, new)
            m.wcs_table[row] = new
        elif m.nonmodal == 92:
            if not m.axis:
                raise GrblCodeError(26)
            for i, v in m.axis.items():
                m.g92[i] = m.base[i] - m.wcs_table[m.wcs][i] - (m.tlo if i == 2 else 0.0) - v
        elif m.nonmodal == 92.1:
            m.g92 = [0.0, 0.0, 0.0]

    def _motion_blocks(self, m: _Modes, values: dict[str, float], line_no: int,
                       actions: deque) -> tuple[list[Block], list[float]]:
        """The planner blocks of the block's motion (G0-G3, G28/G30 via a point) and where it ends."""
        base, target = m.base, list(m.base)
        if m.axis_cmd is not None and m.nonmodal not in (10, 92):
            for i, v in m.axis.items():
                target[i] = v if m.nonmodal == 53 else (base[i] + v if m.incremental else v + m.offset(i))
        points: list[list[float]] = []
        kind, rate, rapid = f"G{m.motion}", m.feed, m.motion == 0
        if m.nonmodal in (28, 30):
            stored = self._g28_mm if m.nonmodal == 28 else self._g30_mm
            points = [target if m.axis else list(base), list(stored)]
            kind, rapid = f"G{int(m.nonmodal)}", True
        elif m.nonmodal in (28.1, 30.1):
            which, pos = m.nonmodal, list(base)
            actions.append(("call", lambda: self._store_position(which, pos)))
        elif m.axis_cmd == "motion":
            if m.motion in (1, 2, 3) and ("F" not in values if m.inverse_time else m.feed <= 0):
                raise GrblCodeError(22)
            if m.motion in PROBE_CODES:
                if m.inverse_time or m.feed <= 0:
                    raise GrblCodeError(22)
                if all(abs(target[i] - base[i]) < 1e-9 for i in range(3)):
                    raise GrblCodeError(33)  # a probe target where the carriage stands
                points, rate = [target], m.feed
            elif m.motion in (0, 1):
                points = [target]
                rate = math.dist(base, target) * m.feed if m.inverse_time and m.motion == 1 else m.feed
            else:
                a0, a1, _ = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}[m.plane]
                if a0 not in m.axis and a1 not in m.axis:
                    raise GrblCodeError(32)
                m.used |= {"I", "J", "K", "R"}   # grbl takes any I J K with an arc, in or out of its plane
                points, length = arc_points(base, target, m.plane, m.motion == 2, values, m.scale,
                                            self.settings[12])
                rate = length * m.feed if m.inverse_time else m.feed
        blocks = []
        prev = base
        for pt in points:
            blk = self._make_block(line_no, kind, prev, pt, rate, rapid=rapid)
            if blk is not None:
                blocks.append(blk)
                prev = pt
        return blocks, (list(points[-1]) if points else list(base))

    def _commit(self, m: _Modes, m_groups: dict[str, int], values: dict[str, float]) -> None:
        """The block passed every check: grbl's parser takes its modes and offsets."""
        p = self._parser
        p.inches, p.inverse_time, p.plane, p.incremental = m.inches, m.inverse_time, m.plane, m.incremental
        p.motion = m.motion
        if "F" in values or m.inverse_time:
            p.feed = m.feed
        if "S" in values:
            p.rpm = values["S"]
        if "T" in values:
            p.tool = int(values["T"])
        offsets_before = self._wco()
        p.wcs, p.tlo_mm, p.g92_mm = m.wcs, m.tlo, m.g92
        if m.new_wcs_row is not None:
            self._wcs_mm[m.new_wcs_row[0]] = m.new_wcs_row[1]
        if self._wco() != offsets_before:
            self._wco_count = 0

    def _set_coolant(self, code: int) -> None:
        if code == 9:
            self._parser.coolant = set()
        else:
            self._parser.coolant.add(code)

    def _store_position(self, which: float, pos: list[float]) -> None:
        if which == 28.1:
            self._g28_mm = list(pos)
        else:
            self._g30_mm = list(pos)

    def _program_end(self) -> None:
        p = self._parser
        p.motion, p.plane, p.incremental, p.inverse_time, p.wcs = 1, 17, False, False, 0
        p.spindle, p.coolant = 5, set()
        self._feed_ov = self._rapid_ov = self._spindle_ov = 100
        self._wco_count = 0
        self._send("[MSG:Pgm End]")
