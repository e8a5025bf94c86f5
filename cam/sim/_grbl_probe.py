"""The grbl emulator's probe: ``G38.2``-``G38.5`` on a simulated surface, as grbl 1.1's probing cycle
(``motion_control.c`` ``mc_probe_cycle``, ``stepper.c``'s probe check) and ``../shared/grbl_avr``'s simulated
probe behave.

The surface is ``z0 + ax*x + ay*y + b*((x-cx)^2 + (y-cy)^2)`` in grbl's machine frame (MPos, mm; up positive),
the probe in contact while the tool tip, counted in whole steps (``$100``-``$102``), is at or below it.  A probe
line waits for the planner to empty; a probe already in the state it should reach raises ``ALARM:4``; the motion
runs at its feed and stops with a feed hold at the first step in contact (``G38.4``/``G38.5``: out of contact), so
the carriage stands a deceleration past it; ``[PRB:x,y,z:1]`` gives the step where it changed, then ``ok``.  A move
that ends without a change: ``G38.2``/``G38.4`` raise ``ALARM:5`` and report the previous probe with ``:0``;
``G38.3``/``G38.5`` report where they ended with ``:0``.  Either way the line is answered ``ok``, and grbl's parser
takes where the carriage stopped.

A part of :class:`cam.sim.grbl.GrblEmulator`.
"""
from __future__ import annotations

import math
from typing import Any, Optional, Sequence

from ._grbl_base import Block, fmt

PROBE_CODES = (38.2, 38.3, 38.4, 38.5)
"""grbl's probing motions: toward the work (38.2 alarm on failure, 38.3 not), away from it (38.4, 38.5)."""


def parse_surface_spec(text: str) -> tuple[float, ...]:
    """``"z0,ax,ay,b,cx,cy"`` (missing trailing values 0) as six floats, as grbl_sim's ``--probe-surface``."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        values = []
    if not 1 <= len(values) <= 6 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"a probe surface is 1 to 6 numbers z0,ax,ay,b,cx,cy, got {text!r}")
    return tuple(values + [0.0] * (6 - len(values)))


class _Probe:
    """The grbl emulator's probe (see the module)."""

    settings: dict
    _probe_surface: Optional[tuple[float, ...]]
    _probe: Optional[dict]
    _prb: tuple[list[float], bool]

    def probe_contact(self, pos_mm: Sequence[float]) -> bool:
        """Whether the probe touches with the carriage at ``pos_mm`` (machine mm, counted in whole steps)."""
        if self._probe_surface is None:
            return False
        x, y, z = (round(v * self.settings[100 + i]) / self.settings[100 + i] for i, v in enumerate(pos_mm))
        z0, ax, ay, b, cx, cy = self._probe_surface
        return z <= z0 + ax * x + ay * y + b * ((x - cx) * (x - cx) + (y - cy) * (y - cy)) + 1e-9

    def _stepped(self, blk: Block, s_mm: float) -> list[float]:
        """Where ``s_mm`` along ``blk`` has stepped each axis to (whole steps from the block's start, as a
        stepper counts them: a step once the path has covered it)."""
        out = []
        for i in range(3):
            spm = self.settings[100 + i]
            start = round(blk.start[i] * spm)
            moved = math.floor(abs(blk.unit[i]) * s_mm * spm + 1e-6)
            out.append((start + (moved if blk.unit[i] >= 0 else -moved)) / spm)
        return out

    def _probe_actions(self, code: float, blocks: list[Block]) -> list[tuple[str, Any]]:
        """A probe line's actions: wait for the planner to empty, then the probing cycle."""
        return [("sync", None), ("probe", (code, blocks[0]))]

    def _probe_step(self, arg: tuple[float, Block]) -> bool:
        """The probing cycle, from :meth:`_run_actions`: True once the line may be answered, False while it runs."""
        if self._probe is None:
            code, blk = arg
            toward = code in (38.2, 38.3)
            if self.probe_contact(self._pos) == toward:  # already where it should get to: ALARM:4, nothing moves
                self._probe_alarm(4)
                return True
            self._probe = {"code": code, "block": blk, "toward": toward, "hit": None, "done": False}
            self._queue_block(blk)
            return False
        if not self._probe["done"]:
            return False
        self._probe = None
        return True

    def _probe_alarm(self, code: int) -> None:
        """A probe fail (ALARM:4 or 5): grbl stops in its Alarm state; the position is kept (``$X`` unlocks)."""
        self._alarm = True
        self._state = "Alarm"
        self._event(f"ALARM:{code}")
        self._send(f"ALARM:{code}")

    def _check_probe(self, blk: Block, ds: float) -> None:
        """While the probe block moves ``ds`` further: the first step where the probe changes stops it (a feed
        hold from there)."""
        p = self._probe
        if p is None or p["block"] is not blk or p["hit"] is not None:
            return
        lo, hi = self._s_mm, min(self._s_mm + ds, blk.length_mm)
        if self.probe_contact(self._stepped(blk, hi)) != p["toward"]:
            return
        for _ in range(60):  # the first stepped position that is in the new state
            mid = 0.5 * (lo + hi)
            if self.probe_contact(self._stepped(blk, mid)) == p["toward"]:
                hi = mid
            else:
                lo = mid
        p["hit"] = self._stepped(blk, hi)
        self._hold = True  # grbl's motion cancel: decelerate and stop past the trigger point

    def _probe_stopped(self) -> bool:
        """The hold after a trigger has come to a stop: end the cycle (True), else False."""
        p = self._probe
        if p is None or p["hit"] is None or p["done"]:
            return False
        if self._planner:
            self._log_block(self._planner[0], list(self._pos), halted=True)
            self._planner.clear()
        self._s_mm = 0.0
        self._hold = False
        self._state = "Idle"
        self._end_probe()
        return True

    def _probe_block_done(self, blk: Block) -> None:
        """The probe block ran to its end (triggered on the way or not)."""
        p = self._probe
        if p is not None and p["block"] is blk and not p["done"]:
            self._hold = False
            self._end_probe()

    def _end_probe(self) -> None:
        p = self._probe
        assert p is not None
        self._v = 0.0
        self._parser_pos = list(self._pos)
        if p["hit"] is not None:
            self._prb = (list(p["hit"]), True)
            self._send(f"[PRB:{fmt(p['hit'])}:1]")
        elif p["code"] in (38.2, 38.4):
            self._probe_alarm(5)
            self._send(f"[PRB:{fmt(self._prb[0])}:0]")
        else:
            self._prb = (list(self._pos), False)
            self._send(f"[PRB:{fmt(self._pos)}:0]")
        p["done"] = True
