"""G-code in, canned cycles: G73, G81, G82, G83, G85 and G89 in the G17 plane, as LinuxCNC's ``rs274`` runs them.

Z, R, Q and P stay from one cycle line to the next (``sticky``); G98 goes back to the height the series started
at, G99 to R; L repeats a hole (in G91 each one further by X Y, with ``@`` ``^`` each one further around the
program origin).
"""
from __future__ import annotations

import math

from ._gcode_data import _CYCLE_PECK
from ._gcode_state import _State

MAX_PECKS = 100_000
"""Pecks of one G73/G83 hole (Q against the depth) past which the line is refused before a peck is made."""


class _Cycles(_State):
    """The holes of a canned cycle line, made moves by :meth:`go` (:class:`~._gcode_motion._Motion`)."""

    def canned_cycle(self, vals: dict[str, float]) -> None:
        """One canned cycle line in the motion mode: its L repeats, each a move to the hole and the hole."""
        code = self.motion
        sticky = self.cycle_words(code, vals)
        polar = "@" in vals or "^" in vals
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
        for _ in range(repeats):
            x, y = x + dx, y + dy
            if polar:
                x, y = self.cycle_polar(x, y, vals)
            self.go("rapid", (x, y, old))
            if old != r:
                self.go("rapid", (x, y, r))
            self.hole(code, (x, y), r, cc, clear, feed)
            old = clear

    def cycle_words(self, code: int, vals: dict[str, float]) -> dict[str, float]:
        """The cycle's Z, R, Q (mm) and P (s), this line's or kept from the last cycle line, checked."""
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
        return sticky

    def cycle_polar(self, x: float, y: float, vals: dict[str, float]) -> tuple[float, float]:
        """The next hole by ``@`` ``^``: each repeat from where the last hole is, around the program origin
        (rs274)."""
        r0, a0 = math.hypot(x, y), math.degrees(math.atan2(y, x))
        if self.absolute:
            rr = vals["@"] * self.scale if "@" in vals else r0
            aa = vals["^"] if "^" in vals else a0
        else:
            rr, aa = r0 + vals.get("@", 0.0) * self.scale, a0 + vals.get("^", 0.0)
        return rr * math.cos(math.radians(aa)), rr * math.sin(math.radians(aa))

    def hole(self, code: int, xy: tuple[float, float], r: float, cc: float, clear: float, feed: dict) -> None:
        """One hole from the retract plane ``r`` down to ``cc`` and back up to ``clear`` (mm)."""
        x, y = xy
        if code in (73, 83):
            delta = self.cycle["q"]
            pecks = math.ceil((r - cc) / delta) if r > cc else 0  # counted before one is made
            if pecks > MAX_PECKS:
                raise self.err(f"canned cycle G{code} would peck {pecks:,} times (Q{delta:g} mm over {r - cc:g} mm); "
                               f"at most {MAX_PECKS:,} pecks a hole are made: check the Q word's units")
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
            return
        self.go("feed", (x, y, cc), **feed)
        if code in (82, 89):
            self.emit("dwell", seconds=self.cycle.get("p", 0.0))
        if code == 85:
            self.go("feed", (x, y, r), **feed)
            if clear != r:
                self.go("rapid", (x, y, clear))
        elif code == 89:
            self.go("feed", (x, y, clear), **feed)
        else:
            self.go("rapid", (x, y, clear))
