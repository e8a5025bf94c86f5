"""G-code in, cutter radius compensation: G41.1/G42.1 D (diameter) for straight G0/G1 moves in the XY plane, as
LinuxCNC's rs274 runs them.

The tool runs the programmed path offset by its radius to the left (G41.1) or right (G42.1) of the direction of
travel:

* the entry move (the first XY move after G41.1/G42.1) runs from where the tool stands to the programmed end
  offset along the entry move's own normal; it must be longer than the radius;
* at each corner between two XY moves the offset lines meet: a concave corner (the path turns toward the
  compensation side) at their intersection, which moves the end of the move before it (and any Z-only moves
  in between); a convex one (turning away) with an arc about the programmed corner at the radius (a feed;
  before a G0, a straight traverse), flat at the height the move before it ended;
* a corner turning less than 0.05 radians either way is run straight on (neither met nor rounded), as rs274;
* a Z-only move keeps the XY offset of the move before it; G40 ends compensation and the next move runs
  straight from the offset point to its programmed end (the exit move), which must not be an arc;
* D0 runs the programmed path.

Gouges are refused, each in one line naming the line that decides them, as rs274 refuses them: an entry move
not longer than the radius; a held move (not the entry move) whose end a concave corner moved back past its
start, so that the tool would run it backwards and cut into the part ("concave corner too tight").  rs274 does
not check a move run straight on after such a corner and cuts there: `cam` refuses that too.

Moves are held until the next XY move decides their ends (one corner of lookahead).  Refused while compensation
is on, each in one line naming the line: arcs (G2/G3), splines, canned cycles, G28/G30, G53, changes of the
coordinate system or offsets, dwells and pauses.  G41/G42 take the diameter of tool D (D omitted or D0: the tool
in the spindle, tool 0 none) from the tool table (a file's, or G10 L1 R); without a table they are refused.
"""
from __future__ import annotations

import math
from typing import Any, Optional

from ._gcode_state import _State

_EPS = 1e-9
_SMALL = 0.05  # radians: a corner turning less is run straight on, neither met nor rounded (as rs274)


class _Comp(_State):
    """Cutter radius compensation's state and moves (see the module's docstring)."""

    comp_side = 0  # +1: left (G41.1), -1: right (G42.1), 0: off (G40)
    comp_radius_mm = 0.0
    comp_prog: Optional[list[float]] = None  # the programmed (uncompensated) position, program mm
    comp_dir: Optional[tuple[float, float]] = None  # the direction of the last XY move (None: entry to come)
    comp_corner: tuple[float, float] = (0.0, 0.0)  # the programmed end of the last XY move
    comp_queue: Optional[list[dict[str, Any]]] = None  # moves held until the next XY move decides their ends
    comp_emitting = False
    comp_exit: Optional[list[float]] = None  # after G40: the programmed position the exit move starts from

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
        self.comp_prog, self.comp_exit = (self.pos() if self.comp_exit is None else list(self.comp_exit)), None
        self.comp_dir = None
        self.comp_queue = []

    def comp_off(self) -> None:
        """G40 (and the end of the program): the held moves run as they stand; the next move is the exit move."""
        if self.comp_side:
            self.comp_flush()
            self.comp_side = 0
            self.comp_exit, self.comp_prog = self.comp_prog, None

    def comp_base(self) -> list[float]:
        """The position incremental words and unnamed axes start from: the programmed one while compensation is
        on and for the exit move after G40 (not the tool centre's), as rs274."""
        if self.comp_side and self.comp_prog is not None:
            return list(self.comp_prog)
        if self.comp_exit is not None:
            base, self.comp_exit = self.comp_exit, None
            return base
        return self.pos()

    def comp_refuse(self, what: str) -> None:
        """Refuse ``what`` while compensation is on (one line naming the line)."""
        if self.comp_side:
            raise self.err(f"{what} while cutter compensation is on is not supported: turn it off (G40) first")

    def comp_flush(self) -> None:
        """Run the held moves, refusing one that would run backwards against its programmed direction: its end
        was moved back past its start by a concave corner too tight for the tool (rs274 refuses it too), the
        tool would cut into the part."""
        queue, self.comp_queue = self.comp_queue or [], []
        for mv in queue:
            if not mv["follows"] and not mv["entry"]:  # the entry move's end may move anywhere, as in rs274
                self._comp_check(mv)
            self._comp_go(mv["kind"], [mv["x"], mv["y"], mv["z"]], mv["line"], mv["source"], mv["kw"])

    def _comp_check(self, mv: dict[str, Any]) -> None:
        """Refuse the held straight move ``mv`` if it would run against its programmed direction."""
        sx, sy = self.pos()[:2]
        d = mv["d"]
        if (mv["x"] - sx) * d[0] + (mv["y"] - sy) * d[1] < -1e-9:
            what = "traverse" if mv["kind"] == "rapid" else "feed"
            raise self.err(f"cutter compensation would gouge the part: a concave corner is too tight for the tool "
                           f"radius {self.comp_radius_mm / self.scale:g}, the compensated move of line {mv['line']} "
                           f"would run backwards (rs274: Straight {what} in concave corner cannot be reached by the "
                           "tool without gouging)")

    def _comp_go(self, kind: str, prog: list[float], line: int, source: Any, kw: dict) -> None:
        here = (self.line_no, self.source)
        self.line_no, self.source = line, source
        self.comp_emitting = True
        try:
            self.go(kind, prog, **kw)
        finally:
            self.comp_emitting = False
            self.line_no, self.source = here

    def _normal(self, d: tuple[float, float]) -> tuple[float, float]:
        """The unit normal of direction ``d`` on the compensation side."""
        return (-d[1], d[0]) if self.comp_side > 0 else (d[1], -d[0])

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
            d1 = self.comp_dir
            n1 = self._normal(d1)
            cx, cy = self.comp_corner
            cross = d1[0] * d[1] - d1[1] * d[0]
            turn = self.comp_side * math.atan2(cross, d1[0] * d[0] + d1[1] * d[1])  # > 0: toward the offset side
            if _SMALL < turn < math.pi - _SMALL:  # concave: the offset lines meet
                # (c + r n1) + s d1 = (c + r n) + u d: solve for s
                ax, ay = r * (n[0] - n1[0]), r * (n[1] - n1[1])
                s = (ax * d[1] - ay * d[0]) / cross
                ix, iy = cx + r * n1[0] + s * d1[0], cy + r * n1[1] + s * d1[1]
                for mv in reversed(queue):  # the move before and the Z-only moves after it end there
                    mv["x"], mv["y"] = ix, iy
                    if not mv["follows"]:
                        break
                self.comp_flush()
            elif turn < -_SMALL or turn >= math.pi - _SMALL:  # convex: round the corner at the radius
                self.comp_flush()
                sx, sy = cx + r * n[0], cy + r * n[1]
                z = self.pos()[2]
                if kind == "rapid":
                    self._comp_go("rapid", [sx, sy, z], self.line_no, self.source, {})
                else:
                    self._comp_go("arc", [sx, sy, z], self.line_no, self.source,
                                  dict(center=(cx, cy), clockwise=self.comp_side > 0, plane="XY", turns=1, **kw))
            else:  # (nearly) straight on, within rs274's 0.05 radians: straight to the next offset end
                self.comp_flush()
        self.comp_queue.append({**entry, "x": t[0] + r * n[0], "y": t[1] + r * n[1], "d": d, "follows": False,
                                "entry": self.comp_dir is None})
        self.comp_dir = d
        self.comp_corner = (t[0], t[1])
        self.comp_prog = list(t)
