"""Saved digitized matrices (``cam digitize -o``, ``--load-digitized``): a drawing digitized once, cut again
without tracing it (:mod:`cam.digitize.digitized`)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from . import Head, Kind

__all__ = ["KIND"]

HEADER = "# CAM DIGITIZED MATRIX"
"""The first line of every saved matrix (upper case, as the sniffer reads lines)."""


def _sniff(head: Head) -> bool:
    return bool(head.lines) and head.lines[0].startswith(HEADER)


def _prepare(path: Path, options: Any, settings: Any, *, home: Any = None, progress: Any = None,
             machine_state: Any = None) -> Any:
    from .drawing import prepare_pixels

    return prepare_pixels(path, "digitized", options, settings)


def _picture(job: Any) -> Any:
    from .drawing import pixels_picture

    return pixels_picture(job)


KIND = Kind(
    name="digitized", noun="a digitized matrix", title="digitized matrix", suffixes=(".txt", ".dig"),
    traits=frozenset({"pixels"}), prepare=_prepare, sniff=_sniff, sniff_rank=40, forced_as="matrix",
    picture=_picture,
    job_noun="digitized matrix job", default_origin="file",
    help="is cut as the drawing it was digitized from",
)
