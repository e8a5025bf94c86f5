"""G-code in, motion: G0, G1, G2/G3 arcs, G5/G5.1 splines, G33, G28/G30 and G53, each made a :class:`GcodeMove`
(probes, G38.2/G38.3: :mod:`._gcode_probe`).

A line's axis words lead to a program position (absolute or incremental, X Y Z or polar ``@`` ``^``);
:meth:`_Motion.go` turns it into machine mm through the offsets, checks it against :mod:`cam.limits` and
records the move.
"""
from __future__ import annotations

import math
from typing import Sequence

from ..limits import MAX_COORD_MM, MAX_FEED_MM_MIN, MIN_FEED_MM_MIN
from ._gcode_data import PLANE_AXES
from ._gcode_state import _State


class _Motion(_State):
    """Moves in the motion mode; a canned cycle's (:meth:`canned_cycle`) are :class:`~._gcode_cycles._Cycles`'."""

    def target(self, vals: dict[str, float]) -> list[float]:
        """The program position (mm) the axis words of a line lead to (from the programmed position while
        cutter compensation is on)."""
        pos = self.comp_base()
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
        st = self.start  # the moves are given from where the tool stood at the start
        if "center" in kw:
            first, second, _ = PLANE_AXES[kw.get("plane", "XY")]
            c = kw["center"]
            kw["center"] = (c[0] + off[first] - st[first], c[1] + off[second] - st[second])
        if "controls" in kw:
            controls_mach = tuple(tuple(p + o for p, o in zip(c, off)) for c in kw["controls"])
            for c_prog, c_mach in zip(controls_prog, controls_mach):
                for a, p, q in zip("XY", c_prog, c_mach):
                    if not (abs(p) <= MAX_COORD_MM and abs(q) <= MAX_COORD_MM):
                        raise self.err(f"the spline's control point reaches {a}{q:.6g} mm, beyond "
                                       f"{MAX_COORD_MM:g} mm from the origin")
            kw["controls"] = tuple(tuple(q - s for q, s in zip(c, st)) for c in controls_mach)
        self.g5_reflect = None
        if self.source is not self.main:
            kw["file"] = self.source.name
        self.emit(kind, mach, **kw)
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
        elif self.motion == 38:  # G38.2, G38.3 (:mod:`._gcode_probe`)
            if any(k in vals for k in "ijk") or ("r" in vals):
                raise self.err("I, J, K or R given without G2/G3")
            self.probe(self.target(vals))
            return
        elif self.motion in (0, 1, 2, 3, 33):
            if self.motion in (2, 3) and self.comp_exit is not None:
                raise self.err("the move just after cutter compensation is turned off (G40) must be straight, not an "
                               "arc (as rs274)")
            t = self.target(vals)
        else:
            self.canned_cycle(vals)
            return
        if self.motion in (0, 1):
            if any(k in vals for k in "ijk") or ("r" in vals):
                raise self.err("I, J, K or R given without G2/G3")
            if self.comp_side and not machine:
                self.comp_move("rapid" if self.motion == 0 else "feed", t,
                               {} if self.motion == 0 else self.feed_kw(vals))
                return
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
        p0 = list(self.comp_prog) if self.comp_side else self.pos()  # compensated: from the programmed start
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
            if third_word in vals and vals[third_word] != 0:  # grbl ignores it (FreeCAD's grbl post writes K0)
                self.note_once("ijk", f"'{texts_of(third_word)}' is not a centre word of an arc in the {self.plane} "
                                      "plane: ignored, as grbl does (LinuxCNC refuses it)")
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
        if self.comp_side:
            self.comp_arc(t, (cu, cv), self.motion == 2, turns, feed)
            return
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
