"""Stage 4: the step plan -- every parallel-port write of a job, with its time.

Signals (thesis chapter 3): a step is a rising edge of an axis's clock bit;
the direction bit, set for the + direction, is written half a step period
before the edge.  Each step period of length ``T`` starting at ``t`` makes two
writes::

    t + T/2 : direction bits | clock bits of the axes that step   (rising edges)
    t + T   : direction bits of the next period, clocks low         (falling edges)

so the last write of a job lands exactly at the end of its last period, and
the job time is the sum of its periods.  X and Y step together in diagonal
moves (Eq. 4.4): a move of (dx, dy, dz) steps takes max(|dx|, |dy|, |dz|)
periods, the shorter axes spread evenly over them (a DDA).  The period is the
X/Y delay when X or Y moves, the Z delay for Z-only moves, and the larger of
the two when both move.  Those are the *nominal* periods (the thesis's constant
delay); the speed ramps of ``settings.ramp`` (look-ahead, the seed's 40-step
ramp, or none) then lengthen them.  Every step plan is made a chunk at a time
(:mod:`cam.motion.chunks`, where the step plan's types live); :class:`StepPlan` is
one held whole, :func:`plan_steps` the chunks joined.

Pin 1 (strobe) carries Half/Full* and is held low for full steps.
"""
from __future__ import annotations

from .chunks import StepChunk, StepPlan, plan_steps

__all__ = ["StepPlan", "StepChunk", "plan_steps"]
