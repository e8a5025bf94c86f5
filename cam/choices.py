"""Names the library accepts: image and profile suffixes, height maps, posts, the default port, the 2D start rules.

Standard library, :mod:`cam.errors`, :mod:`cam.options` and :mod:`cam.sniff` only, so the command line can list
and check them in ``--help`` and before a command runs without loading numpy, numba or OpenCV.  The file kinds
(their suffixes, sniffers and names) are each kind's module's: :mod:`cam.kinds`.

Suffixes are lower case, with the dot.
"""
from __future__ import annotations

import os
from pathlib import Path

from .options import OPTIONS
from .sniff import read_head, sniff_height_map

__all__ = ["POSTS", "DEFAULT_PORT", "IMAGE_SUFFIXES", "PROFILE_SUFFIXES", "START_RULES", "HEIGHT_MAP_SUFFIXES",
           "is_height_map"]

IMAGE_SUFFIXES = (".png", ".bmp", ".jpg", ".jpeg", ".tif", ".tiff", ".gif")
"""Images the image reader reads (:func:`cam.digitize.drawing.load_image`): drawings (:mod:`cam.kinds.drawing`),
profile drawings, sketches and height-map images."""
PROFILE_SUFFIXES = IMAGE_SUFFIXES + (".csv", ".txt")
"""Files a depth profile may come from (a profile drawing or a CSV of depths)."""

START_RULES = OPTIONS["start"].choices
"""Where each 2D object starts: first pixel in scan order, nearest the tool, or nearest the origin (the thesis's
Min Distance rule) (:func:`cam.digitize.digitize`)."""

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
