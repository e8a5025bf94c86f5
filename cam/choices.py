"""Names the library accepts: file kinds by suffix and the 2D start rules.

Standard library only, so the command line can list them in ``--help``
without loading numpy, numba or OpenCV.  The modules that use a list
re-export it under the same name (``cam.formats.gcode.GCODE_SUFFIXES``,
``cam.formats.hpgl.HPGL_SUFFIXES``, ``cam.digitize.trace2d.START_RULES``).

Suffixes are lower case, with the dot.
"""
from __future__ import annotations

__all__ = [
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
"""Suffixes of each job kind, in the order :func:`cam.job.jobs.job_kind` tries them."""

FILE_JOB_SUFFIXES = EXCELLON_SUFFIXES + GCODE_SUFFIXES + HPGL_SUFFIXES
"""Files that are jobs already (not drawings): the job is in the file, not traced from a picture."""

START_RULES = ("top", "min-distance")
"""Where each 2D object starts: first pixel in scan order, or nearest the tool (:func:`cam.digitize.digitize`)."""
