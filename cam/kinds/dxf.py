"""DXF drawings (LibreCAD, QCAD, FreeCAD, Inkscape, Fusion 360): every line and curve cut at the cut depth.  Read
with ezdxf into the SVG reader's drawing (:mod:`cam.formats.dxf`) and planned, reported and exported as an SVG
drawing is (:mod:`cam.kinds.svg`)."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Optional

from . import Head, Kind
from .svg import drawing_exact_geometry, drawing_info, drawing_info_lines, prepare_drawing

__all__ = ["KIND"]

_DXF_START = re.compile(rb"\s*(?:999\r?\n[^\n]*\n\s*)?0\r?\n\s*SECTION\s*\r?\n")
"""A text DXF file: group code 0 (after an optional 999 comment) and SECTION."""
_DXF_BINARY = b"AutoCAD Binary DXF\r\n\x1a\x00"
"""A binary DXF file's sentinel."""


def _sniff(head: Head) -> bool:
    return head.raw.startswith(_DXF_BINARY) or bool(_DXF_START.match(head.raw))


def _load(path: Any) -> Any:
    from ..formats.dxf import load_dxf

    return load_dxf(path)


def _prepare(path: Path, options: Any, settings: Any, *, home: Any = None, progress: Any = None,
             machine_state: Any = None) -> Any:
    return prepare_drawing(_load, KIND, path, options, settings, home)


def _exact_geometry(prepared: Any, cut_depth_mm: Optional[float], options: Any) -> tuple[dict, dict]:
    return drawing_exact_geometry(_load, prepared, options)


KIND = Kind(
    name="dxf", noun="a DXF drawing", title="DXF", suffixes=(".dxf",),
    traits=frozenset({"placed", "strokes", "layers"}), prepare=_prepare, sniff=_sniff, sniff_rank=20,
    info=drawing_info, info_lines=drawing_info_lines, exact_geometry=_exact_geometry, job_noun="DXF job",
    help="every line and curve is cut at --cut-depth",
)
