"""The ranges every number read from a file must lie in, in one place.

A file (G-code, HPGL, Excellon, a profile CSV, a digitized matrix, an image
header) may hold any digit string; each number is checked to be finite and
inside the range below before it is used, so no overflow, NaN or infinity
reaches a plan, a file or a report, and a bad one is a one-line
:class:`~cam.errors.CamError` naming the file, the line and the word.  The
ranges are what a small 3-axis machine can mean, far wider than any real
job; the machine's travel, checked later, refuses far less.

Job options have their bounds in their one declaration, :mod:`cam.options`
(the command line and :class:`cam.kinds.jobs.JobOptions` check them alike);
settings theirs in :mod:`cam.settings`, profile depths in
:mod:`cam.digitize.profile`.

Standard library only: the readers, the planners and the command line import it cheaply.
"""
from __future__ import annotations

__all__ = [
    "MAX_COORD_MM", "MIN_FEED_MM_MIN", "MAX_FEED_MM_MIN", "MAX_DWELL_S", "MAX_MOVE_S", "MAX_PROGRAM_S", "MAX_TOOL_NUMBER",
    "MAX_SPINDLE_RPM", "MAX_LINE_NUMBER", "MAX_MOVE_PERIODS", "MAX_TOOL_DIAMETER_MM", "MAX_REPEAT", "MAX_HOLES",
    "MAX_IMAGE_SIDE_PX", "MAX_IMAGE_PIXELS", "DEFAULT_GCODE_LINES", "MAX_GCODE_LINES", "MAX_GCODE_CALL_DEPTH",
]

MAX_COORD_MM = 1_000_000.0
"""Every coordinate in a file, and every position it leads to, at most 1 km (1e6 mm) from its origin
either way: G-code X Y Z I J R, G5's P Q and the control points of splines (after G20's inch scale,
G91 sums and G92 offsets), HPGL coordinates (4e7 plotter units) and pen positions after relative
moves, Excellon hole positions and offsets."""

MIN_FEED_MM_MIN = 1e-3
MAX_FEED_MM_MIN = 1e8
"""A G-code feed ``F`` is 0.001..1e8 mm/min (after G20's inch scale; LinuxCNC's own 3D_Chips.ngc asks for
4.5e6 mm/min: nothing moves faster than the step delays allow anyway).  A feed within the range that makes
one move longer than :data:`MAX_MOVE_S` is refused by the planner, naming the line."""

MAX_DWELL_S = 3600.0
"""A G-code dwell ``G4 P`` is 0..3600 s (one hour)."""

MAX_MOVE_S = 86_400.0
"""One G-code move (a line or an arc) may take at most a day at its feed; a slower one is an error naming
the line instead of a plan of absurd, overflowing times."""

MAX_PROGRAM_S = 365 * 86_400.0
"""A G-code program may take at most a year at its feeds and dwells (three million one-hour dwells would
overflow the plan's clock of 292 years in nanoseconds); the line where it passes a year is named."""

MAX_TOOL_NUMBER = 999_999
"""Tool numbers 0..999999: G-code ``T``, Excellon ``T``, HPGL pens ``SP``."""

MAX_SPINDLE_RPM = 1_000_000.0
"""A G-code spindle speed ``S`` is 0..1e6 rpm (the machine has no spindle output: S only sets G33's feed, K x S,
which must lie within the feed range)."""

MAX_LINE_NUMBER = 1_000_000_000
"""A G-code line number ``N`` is 0..1e9 (read and ignored)."""

MAX_MOVE_PERIODS = 1 << 22
"""The most step periods one G-code move (a line, or an arc with its chords) may take: 4,194,304, 121 m of
path at 0.0289 mm per step.  Bounds the memory of planning one move (about 150 bytes a period); checked
before an arc is sampled, after its bounding box is checked against the travel."""

DEFAULT_GCODE_LINES = 250_000
MAX_GCODE_LINES = 1_000_000_000
"""A G-code program may run at most this many lines more than its own (the file's lines once, then each
further pass of a loop and each line of a subroutine counted: ``--max-lines``, default 250,000, a few seconds
of interpreting, issue #32 point 3): a loop that never ends is an error naming the line it reached, not a
hang, and a program of millions of straight lines runs whole.  The option itself is 1..1e9."""

MAX_GCODE_CALL_DEPTH = 100
"""G-code subroutines may call each other at most 100 deep (endless recursion is an error)."""

MAX_TOOL_DIAMETER_MM = 100.0
"""An Excellon tool diameter ``C`` is more than 0 and at most 100 mm."""

MAX_REPEAT = 10_000
"""An Excellon repeat ``R<n>`` makes at most 10,000 holes."""

MAX_HOLES = 1_000_000
"""A drill file has at most a million holes (so that a few ``R`` lines cannot make billions)."""

MAX_IMAGE_SIDE_PX = 32_768
MAX_IMAGE_PIXELS = 16_777_216
"""A drawing (an image, or the image a digitized matrix is for) is at most 32,768 pixels on a side and
16,777,216 pixels (4096 x 4096) in all, read from the file's header before it is decoded
(:mod:`cam.digitize.image_size`); loading and classifying a drawing takes about 26 bytes a pixel, 430 MB at
the limit.  A drawing to plan must also fit the machine's travel at its steps per
pixel (:func:`cam.job.drawing.check_drawing_size`), which refuses far smaller ones."""
