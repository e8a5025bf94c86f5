"""Reading a file's first few kB to tell what it is: the head, the suffixes that say nothing, height maps.

PCB programs name their drill files by habit, not by the Excellon suffixes
(Altium ``NC Drill/*-RoundHoles.TXT``, Fritzing ``*_drill.txt``, CNC programs
``.nc``, ``.cnc``), so a file whose suffix says nothing certain is recognised
by its content: each file kind's module has its sniffer, and
:func:`cam.kinds.decide_kind` is the rule (:func:`cam.kinds.job_kind`).

Standard library only, so the command line checks a file's kind before it
loads numpy or OpenCV.  Only :data:`HEAD_BYTES` of a file are read.
"""
from __future__ import annotations

import os
import re
from typing import Optional

__all__ = ["HEAD_BYTES", "GENERIC_SUFFIXES", "read_head", "sniff_height_map"]

HEAD_BYTES = 8192
"""How much of a file is read to tell its kind."""

GENERIC_SUFFIXES = ("", ".txt", ".nc", ".cnc")
"""Suffixes that do not say what a file holds: the content decides (lower case, with the dot; "" = none)."""


def read_head(path: str | os.PathLike) -> Optional[bytes]:
    """The first :data:`HEAD_BYTES` of a file, or None when it is not a readable file."""
    try:
        with open(path, "rb") as f:
            return f.read(HEAD_BYTES)
    except OSError:
        return None


_HEIGHT_MAP_KEY = re.compile(r'^\s*\{[^{}\[\]]*"cam_height_map"\s*:')


def sniff_height_map(head: bytes) -> bool:
    """Whether a file's first bytes are a height map's (``cam probe grid --out MAP.json``): a JSON object whose
    keys before its first list include ``"cam_height_map"`` (:mod:`cam.job.heightmap_level`).  A height map is
    not a job kind: ``cam info`` and ``cam preview`` show it, ``--level`` reads it.

    >>> sniff_height_map(b'{"cam_height_map": 1, "frame": "machine", "x_mm": [0, 10]}'), sniff_height_map(b"IN;PU0,0;")
    (True, False)
    """
    if head.startswith(b"\xef\xbb\xbf"):
        head = head[3:]
    return bool(_HEIGHT_MAP_KEY.match(head[:HEAD_BYTES].decode("latin-1")))
