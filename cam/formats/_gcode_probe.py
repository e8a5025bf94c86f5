"""G-code in, probing: ``G38.2`` and ``G38.3`` moves, and what the interpreter knows once a probe has run.

LinuxCNC's semantics, as its ``rs274`` runs them (``convert_probe``, then the next read):

* ``G38.2``/``G38.3`` are motion codes of modal group 1 (a later line of axis words alone probes again); the line's
  ``F`` is taken before its motion, as for any move;
* refused before the probe, as rs274 refuses them: probing with cutter radius compensation on, in inverse time
  (G93), without a feed, or to a target less than 0.254 mm (0.01 inch) from where the tool stands; G53 with a probe
  is refused as it is with any motion but G0/G1;
* the probe is a straight feed move toward the target that ends where the probe trips; ``G38.2`` that reaches its
  target without tripping is an error, ``G38.3`` is not (its move ends at the target);
* after it, the program position is the trip point (the target when a ``G38.3`` did not trip), #5061..#5063 hold
  the trip point in the coordinate system the probe was made in, in the program's units (#5070 = 1; a ``G38.3``
  that did not trip: its target, and #5070 = 0).

Where the probe trips is known only once the machine has run every move before it and the probe itself: the
interpreter gives the probe's move (:class:`GcodeMove` of kind ``probe``: its ``end`` is the target, ``note`` its
code, ``feed_mm_min`` its feed) as the last move of a batch, and reads no further line until the consumer asks
for the next batch; then it asks the ``probed`` function it was given where the probe tripped (rs274's read of the
external position after a probe).  Without one (``cam preview``, ``cam info``, the checks made before a run) every
probe is taken to trip at its target, its deepest: the moves after it are what they would be then.

Here a probe moves along Z and down only (the machines `cam` probes with touch the work from above): a ``G38.2``
that moves X or Y, or goes up, is refused naming its line.  ``G38.4``/``G38.5`` (probing away from the work) are
refused.
"""
from __future__ import annotations

from typing import Callable, Optional

from ._gcode_data import GcodeMove
from ._gcode_state import _State

ProbeFn = Callable[[GcodeMove], Optional[tuple[float, float, float]]]
"""Where a program's probe tripped, asked once the moves after it are asked for: given the probe's move, the trip
point in the frame of :attr:`GcodeMove.end` (mm from where the tool stood when the program started), or None: it
did not trip (a ``G38.3`` that reached its target)."""

MIN_PROBE_MM = 0.254
"""The shortest probe move, as rs274 (0.01 inch): a target nearer the start is an error."""


class _Probe(_State):
    """The probe moves of the interpreter and what it knows after them (see the module)."""

    probed: Optional[ProbeFn] = None

    def probe(self, target: list[float]) -> None:
        """A probe toward the program position ``target`` (mm), checked as rs274 checks it, then given as a move of
        kind ``probe``; the interpreter waits for its trip point (:meth:`after_probe`)."""
        name = f"G38.{self.probe_code % 10}"
        if self.comp_side:
            raise self.err(f"{name} while cutter radius compensation is on: rs274 cannot probe with it on; turn it "
                           "off (G40) first")
        if self.inverse_time:
            raise self.err(f"{name} in inverse time feed mode (G93): rs274 cannot probe in it; give G94 and a feed F")
        if self.feed <= 0:
            raise self.err(f"{name} without a feed rate 'F' (rs274 cannot probe with zero feed rate)")
        here = self.pos()
        for i, axis in enumerate("XY"):
            if abs(target[i] - here[i]) > 1e-9:
                raise self.err(f"a probe along {axis} is not supported: cam probes down Z only (give {name} a Z word "
                               "and no other axis that moves)")
        down = here[2] - target[2]
        if down < 0:
            raise self.err(f"{name} upward is not supported: cam probes down toward the work (its Z target is "
                           f"{-down:g} mm above where the tool stands)")
        if down < MIN_PROBE_MM - 1e-9:
            raise self.err(f"{name}: its target is {down:g} mm from where the tool stands, less than "
                           f"{MIN_PROBE_MM:g} mm (rs274: start point too close to probe point)")
        self.go("probe", target, feed_mm_min=self.feed, note=name)
        self.probe_pending = self.moves[-1]

    def after_probe(self) -> None:
        """The probe given last has run: the program position is where it tripped and #5061..#5063, #5070 say it
        (see the module); asked of :attr:`probed`, or its target without one."""
        move, self.probe_pending = self.probe_pending, None
        assert move is not None
        target = [e + s for e, s in zip(move.end, self.start)]
        at, tripped = target, True
        if self.probed is not None:
            hit = self.probed(move)
            tripped = hit is not None
            if hit is not None:
                at = [float(h) + s for h, s in zip(hit, self.start)]
            elif move.note == "G38.2":
                raise self.err("G38.2: the probe reached its target without touching")
        self.mach = list(at)
        off = self.offsets()
        for i in range(3):
            self.params[5061 + i] = (at[i] - off[i]) / self.scale
        self.params[5070] = 1.0 if tripped else 0.0
