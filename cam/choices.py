"""Names the library accepts: file kinds by suffix, which job option applies to which kind, the 2D start rules.

Standard library and :mod:`cam.errors` only, so the command line can list and
check them in ``--help`` and before a command runs without loading numpy,
numba or OpenCV.  The modules that use a list
re-export it under the same name (``cam.formats.gcode.GCODE_SUFFIXES``,
``cam.formats.hpgl.HPGL_SUFFIXES``, ``cam.digitize.trace2d.START_RULES``).

Suffixes are lower case, with the dot.
"""
from __future__ import annotations

import os
from pathlib import Path

from .errors import CamError

__all__ = [
    "job_kind", "OPTION_KINDS",
    "DRAWING_SUFFIXES", "DIGITIZED_SUFFIXES", "EXCELLON_SUFFIXES", "HPGL_SUFFIXES", "GCODE_SUFFIXES",
    "PROFILE_SUFFIXES", "SUFFIXES", "FILE_JOB_SUFFIXES", "START_RULES",
]

DRAWING_SUFFIXES = (".png", ".bmp", ".jpg", ".jpeg", ".tif", ".tiff")
"""Drawings: black curves on white (2D), a black contour around red (3D)."""
DIGITIZED_SUFFIXES = (".txt", ".dig")
"""Saved digitized matrices (``cam digitize -o``, ``--load-digitized``)."""
EXCELLON_SUFFIXES = (".drl", ".xln", ".exc", ".drd")
"""PCB drill files (Excellon)."""
HPGL_SUFFIXES = (".plt", ".hpgl", ".hpg")
"""Pen-plotter files (HPGL)."""
GCODE_SUFFIXES = (".ngc", ".nc", ".gcode", ".gc", ".g", ".tap", ".cnc")
"""RS-274/NGC G-code programs."""
PROFILE_SUFFIXES = DRAWING_SUFFIXES + (".csv", ".txt")
"""Files a depth profile may come from (a profile drawing or a CSV of depths)."""

SUFFIXES = {
    "drawing": DRAWING_SUFFIXES,
    "digitized": DIGITIZED_SUFFIXES,
    "gcode": GCODE_SUFFIXES,
    "excellon": EXCELLON_SUFFIXES,
    "hpgl": HPGL_SUFFIXES,
}
"""Suffixes of each job kind, in the order :func:`job_kind` tries them."""

FILE_JOB_SUFFIXES = EXCELLON_SUFFIXES + GCODE_SUFFIXES + HPGL_SUFFIXES
"""Files that are jobs already (not drawings): the job is in the file, not traced from a picture."""

START_RULES = ("top", "min-distance")
"""Where each 2D object starts: first pixel in scan order, or nearest the tool (:func:`cam.digitize.digitize`)."""


def job_kind(path: str | os.PathLike) -> str:
    """The job kind of a file, from its suffix.

    >>> job_kind("board.DRL"), job_kind("part.ngc"), job_kind("gear.png")
    ('excellon', 'gcode', 'drawing')

    Raises:
        CamError: unknown suffix (the message names the file and the accepted types).
    """
    suffix = Path(path).suffix.lower()
    for kind, suffixes in SUFFIXES.items():
        if suffix in suffixes:
            return kind
    listed = "; ".join(f"{k} {' '.join(v)}" for k, v in SUFFIXES.items())
    raise CamError(f"{Path(path).name}: unknown file type '{suffix or '(none)'}' (accepted: {listed})")


_DRAWINGS = frozenset({"drawing", "digitized"})
OPTION_KINDS = {
    "depth": _DRAWINGS, "passes": _DRAWINGS, "start": frozenset({"drawing"}), "start_at": _DRAWINGS,
    "pause_at": _DRAWINGS, "profile": _DRAWINGS, "profile_expr": _DRAWINGS,
    "cut_depth_mm": _DRAWINGS | {"excellon", "hpgl"}, "travel_height_mm": frozenset({"excellon", "hpgl"}),
    "offset_mm": frozenset({"excellon", "hpgl"}), "mirror_x": frozenset({"excellon"}),
    "drill_order": frozenset({"excellon"}), "excellon_units": frozenset({"excellon"}),
    "excellon_digits": frozenset({"excellon"}), "excellon_zeros": frozenset({"excellon"}),
    "flip_y": frozenset({"gcode"}), "tool_table": frozenset({"gcode"}), "subroutine_path": frozenset({"gcode"}),
    "max_lines": frozenset({"gcode"}),
}
"""The job kinds each job option (:class:`cam.job.jobs.JobOptions`) applies to; the CLI's checks use it too."""
