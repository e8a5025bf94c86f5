"""Names the library accepts: file kinds by suffix, the 2D start rules (and :mod:`cam.options`' option kinds).

Standard library, :mod:`cam.errors` and :mod:`cam.options` only, so the command line can list and
check them in ``--help`` and before a command runs without loading numpy,
numba or OpenCV.  The modules that use a list
re-export it under the same name (``cam.formats.gcode.GCODE_SUFFIXES``,
``cam.formats.hpgl.HPGL_SUFFIXES``, ``cam.digitize.trace2d.START_RULES``).

Suffixes are lower case, with the dot.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

from .errors import CamError
from .options import OPTION_KINDS, OPTIONS  # which option applies to which kind: declared with the option
from .sniff import decide_kind, read_head, sniff_height_map

__all__ = ["POSTS", "DEFAULT_PORT", 
    "job_kind", "OPTION_KINDS",
    "DRAWING_SUFFIXES", "DIGITIZED_SUFFIXES", "EXCELLON_SUFFIXES", "HPGL_SUFFIXES", "GCODE_SUFFIXES",
    "PROFILE_SUFFIXES", "SVG_SUFFIXES", "DXF_SUFFIXES", "SUFFIXES", "FILE_JOB_SUFFIXES", "START_RULES", "HEIGHT_MAP_SUFFIXES",
    "is_height_map",
]

DRAWING_SUFFIXES = (".png", ".bmp", ".jpg", ".jpeg", ".tif", ".tiff", ".gif")
"""Drawings: black curves on white (2D), a black contour around red (3D)."""
DIGITIZED_SUFFIXES = (".txt", ".dig")
"""Saved digitized matrices (``cam digitize -o``, ``--load-digitized``)."""
EXCELLON_SUFFIXES = (".drl", ".xln", ".exc", ".drd")
"""PCB drill files (Excellon)."""
HPGL_SUFFIXES = (".plt", ".hpgl", ".hpg")
"""Pen-plotter files (HPGL)."""
GCODE_SUFFIXES = (".ngc", ".nc", ".gcode", ".gc", ".g", ".tap", ".cnc")
"""RS-274/NGC G-code programs."""
SVG_SUFFIXES = (".svg",)
"""Vector drawings (SVG: Inkscape, Illustrator, logo tools): every visible stroke and outline is cut."""
DXF_SUFFIXES = (".dxf",)
"""CAD drawings (DXF: LibreCAD, QCAD, FreeCAD, Inkscape, Fusion 360): every line and curve is cut."""
PROFILE_SUFFIXES = DRAWING_SUFFIXES + (".csv", ".txt")
"""Files a depth profile may come from (a profile drawing or a CSV of depths)."""

SUFFIXES = {
    "drawing": DRAWING_SUFFIXES,
    "digitized": DIGITIZED_SUFFIXES,
    "gcode": GCODE_SUFFIXES,
    "excellon": EXCELLON_SUFFIXES,
    "hpgl": HPGL_SUFFIXES,
    "svg": SVG_SUFFIXES,
    "dxf": DXF_SUFFIXES,
}
"""Suffixes of each job kind, in the order :func:`job_kind` tries them."""

FILE_JOB_SUFFIXES = EXCELLON_SUFFIXES + GCODE_SUFFIXES + HPGL_SUFFIXES + SVG_SUFFIXES + DXF_SUFFIXES
"""Files that are jobs already (not drawings): the job is in the file, not traced from a picture."""

START_RULES = OPTIONS["start"].choices
"""Where each 2D object starts: first pixel in scan order, nearest the tool, or nearest the origin (the thesis's
Min Distance rule) (:func:`cam.digitize.digitize`)."""


def job_kind(path: str | os.PathLike, warnings: Optional[list[str]] = None, *, head: Optional[bytes] = None) -> str:
    """The job kind of a file, from its suffix and, when the suffix is generic, unknown or contradicted, its content.

    A readable file's first few kB decide when its suffix is generic (none, .txt, .nc, .cnc) or unknown, and
    when they plainly show another kind than its suffix says (then a warning naming both is appended to
    ``warnings``): see :mod:`cam.sniff`.  ``head``: the file's first bytes when they are at hand (an upload);
    default: read from ``path`` if it is a file.  The kind may be "svg" (an SVG drawing) or "dxf" (a DXF drawing).

    >>> job_kind("board.DRL"), job_kind("part.ngc"), job_kind("gear.png")
    ('excellon', 'gcode', 'drawing')

    Raises:
        CamError: neither the suffix nor the content says (the message names the file and the accepted types).
    """
    suffix = Path(path).suffix.lower()
    by_suffix = next((kind for kind, suffixes in SUFFIXES.items() if suffix in suffixes), None)
    if head is None and (by_suffix is None or Path(path).is_file()):
        head = read_head(path)
    kind, warning = decide_kind(Path(path).name, by_suffix, head)
    if warning and warnings is not None:
        warnings.append(warning)
    if kind is not None:
        return kind
    listed = "; ".join(f"{k} {' '.join(v)}" for k, v in SUFFIXES.items())
    raise CamError(f"{Path(path).name}: unknown file type '{suffix or '(none)'}' (accepted: {listed})")

HEIGHT_MAP_SUFFIXES = (".json",)
"""Height maps (``cam probe grid --out MAP.json``; :mod:`cam.job.heightmap_level`): not a job, shown by ``cam info``
and ``cam preview``, read by ``--level``."""


def is_height_map(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a readable file whose content starts as a height map's (:func:`cam.sniff.sniff_height_map`),
    whatever its suffix.

    >>> is_height_map("no/such/map.json")
    False
    """
    head = read_head(path) if Path(path).is_file() else None
    return bool(head) and sniff_height_map(head)  # type: ignore[arg-type]


POSTS = ("generic", "grbl", "linuxcnc")
"""The controllers G-code is written for (``cam export --post``; :mod:`cam.kinds.gcode_export`)."""

DEFAULT_PORT = "mock"
"""The port every command and the page use when none is named: the logging mock (nothing leaves the PC;
:mod:`cam.drive.machines`)."""
