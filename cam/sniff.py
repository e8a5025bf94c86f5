"""What a file is, from its first few kB: images, Excellon, HPGL, G-code, SVG, DXF and saved digitized matrices.

PCB programs name their drill files by habit, not by the Excellon suffixes
(Altium ``NC Drill/*-RoundHoles.TXT``, Fritzing ``*_drill.txt``, CNC programs
``.nc``, ``.cnc``), so a file whose suffix says nothing certain is recognised
by its content.  :func:`decide_kind` is the rule :func:`cam.choices.job_kind`
applies:

* a generic suffix (:data:`GENERIC_SUFFIXES`: none, ``.txt``, ``.nc``,
  ``.cnc``) or an unknown one: the content decides; a generic suffix falls
  back to its usual kind when the content says nothing;
* a specific suffix (``.png``, ``.drl``, ``.plt``, ``.ngc``, ...) whose
  content is plainly another kind: the content decides, with a warning that
  names both (never a silent misread).

Standard library only, so the command line checks a file's kind before it
loads numpy or OpenCV.  Only :data:`HEAD_BYTES` of a file are read.
"""
from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Optional

__all__ = ["HEAD_BYTES", "GENERIC_SUFFIXES", "KIND_NAMES", "FORCED_KINDS", "read_head", "sniff_kind", "decide_kind",
           "forced_kind", "sniff_height_map"]

HEAD_BYTES = 8192
"""How much of a file is read to tell its kind."""

GENERIC_SUFFIXES = ("", ".txt", ".nc", ".cnc")
"""Suffixes that do not say what a file holds: the content decides (lower case, with the dot; "" = none)."""

KIND_NAMES = {
    "drawing": "an image", "digitized": "a digitized matrix", "excellon": "an Excellon drill file",
    "hpgl": "an HPGL file", "gcode": "G-code", "svg": "an SVG drawing",
    "dxf": "a DXF drawing",
}
"""How messages name each kind."""

_IMAGE_MAGIC = (b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff", b"II*\x00", b"MM\x00*", b"GIF87a", b"GIF89a")

# -- Excellon ---------------------------------------------------------------------------------------------
_EXC_HEADER = re.compile(
    r"M48|M7[12]|(?:INCH|METRIC)(?:,.*)?|FMAT,\d|ICI,.*|VER,\d|DETECT,.*|ATC,.*|OSTOP,.*|"
    r"T\d+(?:[FSBHZ][-+\d.]*)*C[\d.]+.*"  # a tool definition: T1C0.8, T01F00S00C0.0280
)
_EXC_COORD = re.compile(r"(?:T\d+)?(?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?")
_EXC_TOOL = re.compile(r"T\d+")
_EXC_COMMENT = re.compile(r";\s*(?:FILE_FORMAT|TYPE=|LAYER_COLOR|HEADER:|DRILL FILE|HOLESIZE|#@!)", re.I)

# -- G-code -----------------------------------------------------------------------------------------------
_GC_WORD = re.compile(r"([A-Z])\s*([-+]?(?:\d+(?:\.\d*)?|\.\d+))")
# each number reads one way only (digits, then an optional fraction): a long line that fails to match
# cannot start a backtracking storm (a 7 kB drill file hung the sniffer for minutes)
_GC_LINE = re.compile(r"(?:[A-Z]\s*[-+]?(?:\d+(?:\.\d*)?|\.\d+)\s*)+")
_GC_COMMENT = re.compile(r"\([^)]*\)|;.*")

# -- DXF: group code 0 (or a 999 comment) and SECTION, or the binary sentinel ---------------------------------
_DXF_START = re.compile(rb"\s*(?:999\r?\n[^\n]*\n\s*)?0\r?\n\s*SECTION\s*\r?\n")
_DXF_BINARY = b"AutoCAD Binary DXF\r\n\x1a\x00"

# -- HPGL -------------------------------------------------------------------------------------------------
_HPGL_TOKEN = re.compile(r"(?:[A-Z]{2}[-+\d.,\s]*)+")
_HPGL_MOTION = re.compile(r"IN|PU|PD|PA|PR|SP")
_ESCAPE = re.compile(r"\x1b\.[^A-Za-z:]*[A-Za-z:]?")


def read_head(path: str | os.PathLike) -> Optional[bytes]:
    """The first :data:`HEAD_BYTES` of a file, or None when it is not a readable file."""
    try:
        with open(path, "rb") as f:
            return f.read(HEAD_BYTES)
    except OSError:
        return None


def _lines(text: str, truncated: bool) -> list[str]:
    lines = text.splitlines()
    if truncated and lines:
        lines.pop()  # cut in the middle
    return [ln.strip().upper() for ln in lines if ln.strip()]


_EXC_REPEAT = re.compile(r"R\d+(?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?")  # Allegro's R02X001000: a repeated hole
_EXC_ROUTE_M = re.compile(r"M1[567]")  # Excellon routing: plunge, retract
_EXC_ROUTE = re.compile(r"G0[0-3](?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?(?:[AIJ][-+]?[\d.]+)*")  # G00X..Y.., no spaces
_EXC_DRILL_G = re.compile(r"G(?:05|85|90|93)(?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?|(?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?G85.*")
_EXC_HOLESIZE = re.compile(r";\s*(?:T\d+\s+)?HOLESIZE\s+\d+", re.I)


def _excellon_or_gcode(lines: list[str]) -> Optional[str]:
    """Excellon or G-code by weighed evidence (issue #31 point 1).

    For Excellon: a header (``M48``, ``M71`` / ``M72``, ``INCH`` / ``METRIC``, ``FMAT``, tool definitions
    ``T1C0.8``), its comments (Allegro's ``;T01 Holesize 1. = ...``, ``;FILE_FORMAT``, ...), ``R`` repeat codes,
    routing (``M15`` / ``M16`` with the ``G00`` / ``G01`` moves between them, written without spaces), tool
    selections and bare ``X..Y..`` holes.  For G-code: words with spaces, ``Z``, ``F``, ``S``, spindle and tool
    change ``M`` codes, plane and unit ``G`` codes, ``I`` / ``J`` arcs outside Excellon routing.
    """
    routes = any(_EXC_ROUTE_M.fullmatch(_GC_COMMENT.sub("", raw).strip()) for raw in lines)
    exc_strong = 0.0
    exc_weak = 0.0
    exc_tool = exc_coord = 0
    gcode_strong = gcode_like = 0
    for raw in lines:
        if raw.startswith(";"):
            if _EXC_HOLESIZE.match(raw):
                exc_strong += 3
            elif _EXC_COMMENT.match(raw):
                exc_strong += 2
            continue
        line = _GC_COMMENT.sub("", raw).strip()
        if not line or line == "%":
            continue
        if _EXC_HEADER.fullmatch(line):
            exc_strong += 3
            continue
        if _EXC_TOOL.fullmatch(line):
            exc_tool += 1
            continue
        if " " not in line and ("X" in line or "Y" in line) and _EXC_COORD.fullmatch(line):
            exc_coord += 1
            continue
        if " " not in line and _EXC_REPEAT.fullmatch(line):
            exc_strong += 2
            continue
        if routes and " " not in line and (_EXC_ROUTE_M.fullmatch(line) or _EXC_ROUTE.fullmatch(line)):
            exc_strong += 1
            continue
        if " " not in line and _EXC_DRILL_G.fullmatch(line):
            exc_weak += 1
            continue
        if not _GC_LINE.fullmatch(line):
            continue
        gcode_like += 1
        words = {(letter, float(value)) for letter, value in _GC_WORD.findall(line)}
        letters = {letter for letter, _ in words}
        if (letters & {"Z", "F", "I", "J", "R", "S"}
                or any(letter == "G" and value in (0, 1, 2, 3, 17, 20, 21, 28, 54, 91) for letter, value in words)
                or any(letter == "M" and value in (3, 4, 5, 6) for letter, value in words)):
            gcode_strong += 1
    exc_score = exc_strong + exc_weak + exc_tool + 0.25 * exc_coord
    gcode_score = 2.0 * gcode_strong + 0.5 * (gcode_like - gcode_strong)
    if exc_strong and exc_score >= gcode_score:
        return "excellon"
    if exc_tool and exc_coord and exc_score >= gcode_score:
        return "excellon"  # a headless drill file (old Eagle, P-CAD): tool selects and X..Y.. holes
    if gcode_like:
        return "gcode"
    if exc_tool and exc_coord:
        return "excellon"
    return None


def sniff_kind(head: bytes, *, truncated: Optional[bool] = None) -> Optional[str]:
    """The kind the first bytes of a file show, or None when they show none.

    Args:
        head: the file's first bytes (:func:`read_head`).
        truncated: whether the file goes on after ``head`` (its last line is then ignored); default: when
            ``head`` is :data:`HEAD_BYTES` long.

    Returns:
        "drawing" (PNG, JPEG, BMP, TIFF, GIF), "svg", "dxf", "digitized", "hpgl", "excellon", "gcode" or None.

    >>> sniff_kind(b"M48\\nMETRIC\\nT1C0.8\\n%\\nT1\\nX1.0Y2.0\\nM30\\n")
    'excellon'
    >>> sniff_kind(b"IN;SP1;PU0,0;PD100,0;"), sniff_kind(b"G21\\nG1 X1 Y2 F100\\n"), sniff_kind(b"hello")
    ('hpgl', 'gcode', None)
    """
    if truncated is None:
        truncated = len(head) >= HEAD_BYTES
    if head.startswith(_IMAGE_MAGIC) or (head[:2] == b"BM" and len(head) >= 26 and head[6:10] == b"\0\0\0\0"):
        return "drawing"
    if head.startswith(b"\xef\xbb\xbf"):
        head = head[3:]
    if head.startswith(_DXF_BINARY) or _DXF_START.match(head):
        return "dxf"
    if b"\0" in head:
        return None
    text = head.decode("latin-1")
    stripped = text.lstrip()
    if stripped.startswith("<"):
        return "svg" if re.search(r"<svg[\s>/]", text, re.I) else None
    lines = _lines(text, truncated)
    if not lines:
        return None
    if lines[0].startswith("# CAM DIGITIZED MATRIX"):
        return "digitized"
    hp_text = _ESCAPE.sub("", " ".join(lines))
    tokens = [t.strip() for t in re.split(r";", hp_text) if t.strip()]
    if tokens and _HPGL_MOTION.search(hp_text):
        good = sum(1 for t in tokens if _HPGL_TOKEN.fullmatch(t))
        if good >= 0.8 * len(tokens) and any(t[:2] in ("PU", "PD", "PA", "PR") for t in tokens):
            return "hpgl"
    return _excellon_or_gcode(lines)


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


def decide_kind(
    name: str, suffix_kind: Optional[str], head: Optional[bytes],
) -> tuple[Optional[str], Optional[str]]:
    """The kind of a file from its suffix's kind and its first bytes: ``(kind, warning)``.

    Args:
        name: the file's name (for the suffix and the warning).
        suffix_kind: the kind its suffix names (:data:`cam.choices.SUFFIXES`), or None.
        head: its first bytes, or None when it cannot be read (the suffix decides).

    Returns:
        The kind (None when neither says) and a warning when the suffix and the content disagree.
    """
    suffix = Path(name).suffix.lower()
    content = sniff_kind(head) if head else None
    if suffix_kind is None or suffix in GENERIC_SUFFIXES:
        return (content or suffix_kind), None
    if content is None or content == suffix_kind:
        return suffix_kind, None
    return content, (f"{name}: the suffix {Path(name).suffix} says {KIND_NAMES.get(suffix_kind, suffix_kind)} but "
                     f"the content is {KIND_NAMES.get(content, content)}; read as {KIND_NAMES.get(content, content)}")


FORCED_KINDS = {"excellon": "excellon", "gcode": "gcode", "hpgl": "hpgl", "svg": "svg", "drawing": "drawing",
                "matrix": "digitized", "dxf": "dxf"}
"""``--kind`` names (issue #31 point 1) and the job kind each forces ("matrix": a saved digitized matrix)."""


def forced_kind(name: Optional[str]) -> Optional[str]:
    """The job kind ``--kind NAME`` forces, or None when not given.

    >>> forced_kind("matrix"), forced_kind(None)
    ('digitized', None)
    """
    return None if name is None else FORCED_KINDS[name]
