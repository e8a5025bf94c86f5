"""G-code in, cutter radius compensation: G41.1/G42.1 D (diameter) and G41/G42 D (tool) for G0/G1 moves and G2/G3
arcs in the XY plane, as LinuxCNC's rs274 runs them.

The tool runs the programmed path offset by its radius to the left (G41.1) or right (G42.1) of the direction of
travel; an arc keeps its centre and its radius shrinks by the tool radius where the tool is inside it (G41 with G3,
G42 with G2) and grows where it is outside:

* the entry move (the first XY move after G41.1/G42.1) runs from where the tool stands to the programmed end
  offset along the entry move's own normal; it must be longer than the radius.  An entry arc ends at its end
  offset along its radius and runs from where the tool stands about a new centre, on the line from that end to
  the programmed centre (as rs274: the arc the tool runs is tangent to the programmed one at the end only);
* at each corner between two XY moves (lines or arcs, compared by their directions at the corner) the offset
  paths meet: a concave corner (the path turns toward the compensation side) at their intersection, which
  moves the end of the move before it (and any Z-only moves in between): two offset lines at their crossing, a
  line and an offset arc or two offset arcs where they cross, at the crossing rs274 takes.  A convex one
  (turning away) is rounded with an arc about the programmed corner at the radius (a feed; before a G0, a
  straight traverse), flat at the height the move before it ended;
* a corner turning less than 0.05 radians either way is run straight on (neither met nor rounded), as rs274; a
  corner that turns back on itself (within 0.05 radians of a half turn) is met where the tool is outside the
  arc after it (or, before a line, outside the arc before it), else rounded, as rs274;
* a Z-only move keeps the XY offset of the move before it; G40 ends compensation and the next move runs
  straight from the offset point to its programmed end (the exit move), which must not be an arc; an offset
  changed before it keeps the machine position, and a tool change (M6) reads the position again, so that the
  exit move then starts where the tool is (as rs274);
* D0 runs the programmed path.

Gouges are refused, each in one line naming the line that decides them, as rs274 refuses them: an entry move
not longer than the radius (an entry arc's end not farther than the radius from where the tool stands); an
arc the tool is inside of whose radius is not larger than the tool's; a concave corner where the offset paths
do not meet (a line and an arc, or two arcs); a held move (not the entry move) whose end a concave corner moved
back past its start, so that the tool would run a line backwards or an arc round past its start and cut into the
part ("concave corner too tight").  rs274 does not check the held move at a corner it runs straight on, or at a
convex corner into an arc, and cuts there: `cam` refuses that too.  After an entry arc rs274 finds a concave
corner into a line as if the entry arc had the programmed centre (it has not), which puts the corner a little
off the offset line: `cam` does the same, so that the tool runs what rs274 runs.

Moves are held until the next XY move decides their ends (one corner of lookahead).  Refused while compensation
is on, each in one line naming the line: splines, canned cycles, G28/G30, G53, changes of the plane, the
coordinate system or offsets, dwells and pauses.  G41/G42 take the diameter of tool D (D omitted or D0: the tool
in the spindle, tool 0 none) from the tool table (a file's, or G10 L1 R); without a table they are refused.
"""
from __future__ import annotations

import math
from typing import Any, Optional

from ._gcode_state import _State

_EPS = 1e-9
_SMALL = 0.05  # radians: a corner turning less is run straight on, neither met nor rounded (as rs274)
_Vec = tuple[float, float]


def _unit(x: float, y: float) -> _Vec:
    length = math.hypot(x, y)
    return (x / length, y / length) if length else (0.0, 0.0)


def _left(v: _Vec) -> _Vec:
    """``v`` turned a quarter turn counter-clockwise."""
    return (-v[1], v[0])


def _dot(a: _Vec, b: _Vec) -> float:
    return a[0] * b[0] + a[1] * b[1]


def _sweep(start: _Vec, centre: _Vec, ccw: bool, turns: int, end: _Vec) -> float:
    """The angle (radians, >= 0) an arc about ``centre`` sweeps from ``start`` to ``end`` in its direction, a full
    turn where the two are at the same angle, plus ``turns`` - 1 full turns (as rs274 measures it)."""
    a0 = math.atan2(start[1] - centre[1], start[0] - centre[0])
    a1 = math.atan2(end[1] - centre[1], end[0] - centre[0])
    part = (a1 - a0) if ccw else (a0 - a1)
    part %= 2 * math.pi
    return (part or 2 * math.pi) + 2 * math.pi * (turns - 1)


class _Comp(_State):
    """Cutter radius compensation's state and moves (see the module's docstring)."""

    comp_side = 0  # +1: left (G41.1), -1: right (G42.1), 0: off (G40)
    comp_radius_mm = 0.0
    comp_prog: Optional[list[float]] = None  # the programmed (uncompensated) position, program mm
    comp_dir: Optional[_Vec] = None  # the direction of travel at the end of the last XY move (None: entry to come)
    comp_corner: _Vec = (0.0, 0.0)  # the programmed end of the last XY move
    comp_queue: Optional[list[dict[str, Any]]] = None  # moves held until the next XY move decides their ends
    comp_emitting = False
    comp_exit: Optional[list[float]] = None  # after G40: the programmed position the exit move starts from, machine mm

    def comp_on(self, side: int, diameter_mm: float) -> None:
        """G41/G41.1 (``side`` +1) or G42/G42.1 (-1) with the tool's diameter (mm)."""
        if self.comp_side:
            raise self.err("cutter compensation is already on: turn it off (G40) before turning it on again")
        if self.plane != "XY":
            raise self.err("cutter compensation here works in the XY plane only (G17)")
        if not 0 <= diameter_mm:
            raise self.err("cutter compensation needs a tool diameter 'D' of 0 or more")
        self.comp_side = side
        self.comp_radius_mm = diameter_mm / 2.0
        # the entry move starts from the programmed position (right after G40: the exit's, not the tool's), as rs274
        self.comp_prog = self.comp_base()
        self.comp_dir = None
        self.comp_queue = []

    def comp_off(self) -> None:
        """G40 (and the end of the program): the held moves run as they stand; the next move is the exit move."""
        if self.comp_side:
            self.comp_flush()
            self.comp_side = 0
            # kept in the machine frame: an offset changed before the exit move keeps the machine position (rs274)
            self.comp_exit = [p + o for p, o in zip(self.comp_prog, self.offsets())]
            self.comp_prog = None

    def comp_base(self) -> list[float]:
        """The position incremental words, unnamed axes and arc centres start from: the programmed one while
        compensation is on and for the exit move after G40 (not the tool centre's), as rs274."""
        if self.comp_side and self.comp_prog is not None:
            return list(self.comp_prog)
        if self.comp_exit is not None:
            base, self.comp_exit = [m - o for m, o in zip(self.comp_exit, self.offsets())], None
            return base
        return self.pos()

    def comp_refuse(self, what: str) -> None:
        """Refuse ``what`` while compensation is on (one line naming the line)."""
        if self.comp_side:
            raise self.err(f"{what} while cutter compensation is on is not supported: turn it off (G40) first")

    def comp_flush(self) -> None:
        """Run the held moves, refusing one that would run backwards against its programmed direction (a line) or
        round past its start (an arc): its end was moved back past its start by a concave corner too tight for
        the tool (rs274 refuses it too), the tool would cut into the part."""
        queue, self.comp_queue = self.comp_queue or [], []
        for mv in queue:
            if not mv["follows"] and not mv["entry"]:  # the entry move's end may move anywhere, as in rs274
                self._comp_check(mv)
            self._comp_go(mv["kind"], [mv["x"], mv["y"], mv["z"]], mv["line"], mv["source"], mv["kw"])

    def _gouge(self, what: str, rs274: str) -> Exception:
        return self.err(f"cutter compensation would gouge the part: a concave corner is too tight for the tool radius "
                        f"{self.comp_radius_mm / self.scale:g}, {what} (rs274: {rs274} cannot be reached by the "
                        "tool without gouging)")

    def _comp_check(self, mv: dict[str, Any]) -> None:
        """Refuse the held move ``mv`` if it would run against its programmed direction (a line) or sweep more
        than its programmed arc (an arc whose end passed its start: rs274's test, with its allowance)."""
        start = tuple(self.pos()[:2])
        if mv["kind"] == "arc":
            kw = mv["kw"]
            swept = _sweep(start, kw["center"], not kw["clockwise"], kw["turns"], (mv["x"], mv["y"]))
            if swept > mv["sweep"] + (0.0254 if self.scale == 1.0 else 0.001):
                raise self._gouge(f"the compensated arc of line {mv['line']} would run round past its start",
                                  "Arc move in concave corner")
            return
        d = mv["d"]
        if (mv["x"] - start[0]) * d[0] + (mv["y"] - start[1]) * d[1] < -1e-9:
            what = "traverse" if mv["kind"] == "rapid" else "feed"
            raise self._gouge(f"the compensated move of line {mv['line']} would run backwards",
                              f"Straight {what} in concave corner")

    def _comp_go(self, kind: str, prog: list[float], line: int, source: Any, kw: dict) -> None:
        here = (self.line_no, self.source)
        self.line_no, self.source = line, source
        self.comp_emitting = True
        try:
            self.go(kind, prog, **kw)
        finally:
            self.comp_emitting = False
            self.line_no, self.source = here

    def _normal(self, d: _Vec) -> _Vec:
        """The unit normal of direction ``d`` on the compensation side."""
        return (-d[1], d[0]) if self.comp_side > 0 else (d[1], -d[0])

    def _inside(self, ccw: bool) -> bool:
        """Whether the tool runs inside an arc turning counter-clockwise (``ccw``) or clockwise: G41 with G3,
        G42 with G2."""
        return (self.comp_side > 0) == ccw

    def comp_move(self, kind: str, t: list[float], kw: dict) -> None:
        """A G0 (``kind`` "rapid") or G1 ("feed") move to the program position ``t`` while compensation is on."""
        p = self.comp_prog
        r = self.comp_radius_mm
        if r == 0:  # as rs274: a zero radius runs the programmed path
            self.comp_flush()
            self._comp_go(kind, list(t), self.line_no, self.source, kw)
            self.comp_prog = list(t)
            return
        dx, dy = t[0] - p[0], t[1] - p[1]
        length = math.hypot(dx, dy)
        queue = self.comp_queue
        entry = dict(kind=kind, z=t[2], line=self.line_no, source=self.source, kw=kw)
        if length <= _EPS * max(1.0, r):
            if self.comp_dir is None:
                raise self.err("the cutter compensation entry move is not longer than the tool radius (rs274: "
                               "the first move after G41/G42 must move in X or Y)")
            last = queue[-1] if queue else None
            x, y = (last["x"], last["y"]) if last else tuple(self.pos()[:2])
            queue.append({**entry, "x": x, "y": y, "follows": True})
            self.comp_prog = list(t)
            return
        d = (dx / length, dy / length)
        n = self._normal(d)
        if self.comp_dir is None:  # the entry move
            if length <= r:
                raise self.err(f"the cutter compensation entry move ({length / self.scale:g}) is not longer than the "
                               f"tool radius ({r / self.scale:g})")
        else:
            self._comp_corner(kind, d, None, {} if kind == "rapid" else kw)
        self.comp_queue.append({**entry, "x": t[0] + r * n[0], "y": t[1] + r * n[1], "d": d, "follows": False,
                                "entry": self.comp_dir is None})
        self.comp_dir = d
        self.comp_corner = (t[0], t[1])
        self.comp_prog = list(t)

    def comp_arc(self, t: list[float], centre: _Vec, clockwise: bool, turns: int, kw: dict) -> None:
        """A G2 (``clockwise``) or G3 arc to the program position ``t`` about the programmed ``centre`` (found from
        the programmed start, :attr:`comp_prog`), ``turns`` turns, while compensation is on."""
        p = self.comp_prog
        r = self.comp_radius_mm
        arc_kw = dict(clockwise=clockwise, plane="XY", turns=turns, **kw)
        if r == 0:  # as rs274: a zero radius runs the programmed path
            self.comp_flush()
            self._comp_go("arc", list(t), self.line_no, self.source, dict(center=tuple(centre), **arc_kw))
            self.comp_prog = list(t)
            return
        ccw = not clockwise
        inside = self._inside(ccw)
        cx, cy = centre
        radius_end = math.hypot(t[0] - cx, t[1] - cy)
        out_end = _unit(t[0] - cx, t[1] - cy)  # the radius' direction at the end
        toward = -1.0 if inside else 1.0  # the offset along it
        end = (t[0] + toward * r * out_end[0], t[1] + toward * r * out_end[1])
        out_start = _unit(p[0] - cx, p[1] - cy)
        d_start = _left(out_start) if ccw else _left((-out_start[0], -out_start[1]))  # the directions of travel
        d_end = _left(out_end) if ccw else _left((-out_end[0], -out_end[1]))
        held = dict(kind="arc", x=end[0], y=end[1], z=t[2], line=self.line_no, source=self.source, follows=False,
                    ccw=ccw, inside=inside)
        if self.comp_dir is None:  # the entry arc: from where the tool stands, tangent to the programmed arc at its end
            if math.hypot(t[0] - p[0], t[1] - p[1]) <= r:
                raise self.err("the cutter compensation entry arc's end is not farther than the tool radius "
                               f"({r / self.scale:g}) from where the tool stands (rs274: Radius of cutter "
                               "compensation entry arc is not greater than the tool radius)")
            if inside and math.hypot(p[0] - cx, p[1] - cy) <= r:
                raise self._too_small_arc(math.hypot(p[0] - cx, p[1] - cy))
            # the new centre is on the line from the compensated end toward the programmed centre, as far from
            # the start as from the end
            w = _unit(cx - end[0], cy - end[1])
            v = (p[0] - end[0], p[1] - end[1])
            v_len = math.hypot(*v)
            cos_a = _dot(v, w) / v_len if v_len else 0.0
            if abs(cos_a) < 1e-6 or w == (0.0, 0.0):
                raise self._too_small_arc(radius_end)
            reach = v_len / 2 / cos_a
            new_centre = (end[0] + reach * w[0], end[1] + reach * w[1])
            held.update(kw=dict(center=new_centre, **arc_kw), entry=True, sweep=None,
                        ring=math.hypot(end[0] - new_centre[0], end[1] - new_centre[1]))
        else:
            if inside and radius_end <= r:
                raise self._too_small_arc(radius_end)
            self._comp_corner("arc", d_start, dict(centre=(cx, cy), radius=radius_end, ccw=ccw, inside=inside), kw)
            held.update(kw=dict(center=(cx, cy), **arc_kw), entry=False,
                        sweep=_sweep((p[0], p[1]), (cx, cy), ccw, turns, (t[0], t[1])),
                        ring=radius_end + toward * r)
        self.comp_queue.append(held)
        self.comp_dir = d_end
        self.comp_corner = (t[0], t[1])
        self.comp_prog = list(t)

    def _too_small_arc(self, radius_mm: float) -> Exception:
        return self.err(f"cutter compensation: the tool radius ({self.comp_radius_mm / self.scale:g}) is not smaller "
                        f"than the radius ({radius_mm / self.scale:g}) of the arc it runs inside, it would gouge the "
                        "part (rs274: Tool radius not less than arc radius with comp)")

    def _comp_corner(self, kind: str, d: _Vec, arc: Optional[dict[str, Any]], feed_kw: dict) -> None:
        """Run the held moves up to the corner between the last XY move and the next one, of ``kind`` ("rapid",
        "feed" or "arc"), starting in direction ``d`` (an arc's ``arc``: its programmed centre and end radius, its
        turning and side): meet a concave corner, round a convex one (with ``feed_kw``), or go straight on."""
        r = self.comp_radius_mm
        d1 = self.comp_dir
        queue = self.comp_queue
        prev = queue[0]  # the last XY move (the Z-only moves after it follow it)
        prev_arc = prev["kind"] == "arc"
        cross = d1[0] * d[1] - d1[1] * d[0]
        turn = self.comp_side * math.atan2(cross, _dot(d1, d))  # > 0: toward the offset side
        back = abs(turn) >= math.pi - _SMALL  # (nearly) turning back on itself
        # as rs274: turning back, the tool outside the arc on the far side goes round it on the near side
        outside = (not arc["inside"]) if arc is not None else (prev_arc and not prev["inside"])
        if _SMALL < turn < math.pi - _SMALL or (back and outside):  # concave: the offset paths meet
            if prev_arc and arc is not None:
                ix, iy = self._meet_arcs(prev, arc)
            elif prev_arc:
                ix, iy = self._meet_arc_line(prev, d)
            elif arc is not None:
                ix, iy = self._meet_line_arc(d1, d, arc)
            else:
                n, n1 = self._normal(d), self._normal(d1)
                cx, cy = self.comp_corner
                # (c + r n1) + s d1 = (c + r n) + u d: solve for s
                ax, ay = r * (n[0] - n1[0]), r * (n[1] - n1[1])
                s = (ax * d[1] - ay * d[0]) / cross
                ix, iy = cx + r * n1[0] + s * d1[0], cy + r * n1[1] + s * d1[1]
            for mv in reversed(queue):  # the move before and the Z-only moves after it end there
                mv["x"], mv["y"] = ix, iy
                if not mv["follows"]:
                    break
            self.comp_flush()
        elif turn < -_SMALL or back:  # convex: round the corner at the radius
            self.comp_flush()
            cx, cy = self.comp_corner
            n = self._normal(d)
            sx, sy = cx + r * n[0], cy + r * n[1]
            z = self.pos()[2]
            if kind == "rapid":
                self._comp_go("rapid", [sx, sy, z], self.line_no, self.source, {})
            else:
                self._comp_go("arc", [sx, sy, z], self.line_no, self.source,
                              dict(center=(cx, cy), clockwise=self.comp_side > 0, plane="XY", turns=1, **feed_kw))
        else:  # (nearly) straight on, within rs274's 0.05 radians: on from where the last move ended
            self.comp_flush()

    def _no_meeting(self, what: str, rs274: str) -> Exception:
        return self.err(f"cutter compensation would gouge the part: the tool (radius "
                        f"{self.comp_radius_mm / self.scale:g}) does not fit the concave corner between {what} "
                        f"(rs274: {rs274})")

    def _meet_line_arc(self, d1: _Vec, d: _Vec, arc: dict[str, Any]) -> _Vec:
        """Where the offset of the last line (direction ``d1``) meets the offset of the next arc, which starts in
        direction ``d``: of the two crossings, the one ahead along the line when the tool is inside the arc, the
        one behind when it is outside (as rs274)."""
        r = self.comp_radius_mm
        (cx, cy), radius = arc["centre"], arc["radius"]
        n1 = self._normal(d1)
        # the offset line's distance from the centre along n1, as rs274 finds it (from the corner's angle)
        if arc["inside"]:
            ring, off, sign = radius - r, r - radius * _dot(d1, d), 1.0
        else:
            ring, off, sign = radius + r, -radius * _dot(d1, d) - r, -1.0
        lat = off / ring
        if abs(lat) > 1:
            raise self._no_meeting("a line and this arc", "Arc move in concave corner cannot be reached by the tool "
                                   "without gouging")
        along = math.sqrt(1 - lat * lat)
        return (cx + ring * sign * (along * d1[0] + lat * n1[0]), cy + ring * sign * (along * d1[1] + lat * n1[1]))

    def _meet_arc_line(self, prev: dict[str, Any], d: _Vec) -> _Vec:
        """Where the offset of the held arc ``prev`` meets the offset of the next line (direction ``d``): of the
        two crossings, the one behind along the line when the tool is inside the arc, the one ahead when it is
        outside (as rs274)."""
        r = self.comp_radius_mm
        pcx, pcy = prev["kw"]["center"]
        ring = prev["ring"]  # the offset arc's radius
        m = _left(d) if prev["ccw"] else (d[1], -d[0])  # the line's normal toward the arc's turning side
        cx, cy = self.comp_corner
        # rs274 takes the programmed radius as the offset one plus or minus the tool radius and the centre's
        # distance from the programmed line along m from it: exact after any arc but an entry arc
        programmed = ring + r if prev["inside"] else ring - r
        lat = programmed * _dot(_unit(pcx - cx, pcy - cy), m)
        lat = (lat - r if prev["inside"] else lat + r) / ring if ring else math.inf
        if abs(lat) > 1:
            raise self._no_meeting(f"the arc of line {prev['line']} and this line", "Arc to straight motion makes a "
                                   "corner the compensated tool can't fit in without gouging")
        along = math.sqrt(1 - lat * lat) * (-1.0 if prev["inside"] else 1.0)
        return (pcx + ring * (along * d[0] - lat * m[0]), pcy + ring * (along * d[1] - lat * m[1]))

    def _meet_arcs(self, prev: dict[str, Any], arc: dict[str, Any]) -> _Vec:
        """Where the offset of the held arc ``prev`` meets the offset of the next arc: of the two crossings, the
        one left of the line from the held arc's centre to the next one's where the tool is inside the held arc
        and the next turns counter-clockwise, or outside and clockwise; else the right one (as rs274)."""
        r = self.comp_radius_mm
        pcx, pcy = prev["kw"]["center"]
        ring = prev["ring"]
        (cx, cy), radius = arc["centre"], arc["radius"]
        ring2 = radius - r if arc["inside"] else radius + r
        apart = math.hypot(cx - pcx, cy - pcy)
        if ring == 0 or apart == 0:
            raise self.err("cutter compensation: an arc after an arc about the same centre is a corner it cannot "
                           "run (rs274: Arc to arc motion is invalid because the arcs have the same center)")
        cos_at = (ring * ring + apart * apart - ring2 * ring2) / (2 * ring * apart)
        if abs(cos_at) > 1:
            raise self._no_meeting(f"the arc of line {prev['line']} and this arc", "Arc to arc motion makes a corner "
                                   "the compensated tool can't fit in without gouging")
        at = math.atan2(cy - pcy, cx - pcx) + math.acos(cos_at) * (1.0 if prev["inside"] == arc["ccw"] else -1.0)
        return (pcx + ring * math.cos(at), pcy + ring * math.sin(at))
