"""Stage 2: the digitized matrix (thesis 4.1.4.4), and its text file.

A :class:`Digitized` holds the traced objects of a drawing as ordered pixel
paths.  In 2D each traced curve is one object and its ``level`` is its
object number; in 3D each traced ring is one object and its ``level`` is its
layer (1 = the contour).

File format (UTF-8 text, written atomically)::

    # cam digitized matrix v1
    # mode=2d width_px=300 height_px=158 objects=1 points=812
    object,x,y,level
    1,7,79,1
    1,7,78,1
    ...

``object`` counts from 1 and never decreases; ``x`` is the column and ``y``
the row of the pixel (origin top-left); ``level`` is constant within an
object.  Lines starting with ``#`` after the header are comments.

The image is at most :data:`~cam.limits.MAX_IMAGE_SIDE_PX` on a side and
:data:`~cam.limits.MAX_IMAGE_PIXELS` in all (as a drawing), and a level at most
its pixel count (every object, every layer has a pixel of its own).
"""
from __future__ import annotations

import io
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ParseError
from ..fileio import atomic_write_text, read_text
from ..limits import MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE_PX
from ..render.picture import depth_colours, encode_png

__all__ = ["Digitized", "save_digitized", "load_digitized", "format_digitized", "parse_digitized"]

FORMAT_LINE = "# cam digitized matrix v1"
COLUMNS_LINE = "object,x,y,level"
MODES = ("2d", "3d")


@dataclass
class Digitized:
    """Traced objects of a drawing.

    Attributes:
        mode: ``"2d"`` or ``"3d"``.
        width_px, height_px: size of the source image.
        objects: one ``(n_i, 2)`` int32 array per object: ``(x, y)`` pixels in
            cutting order, x = column, y = row, origin at the top-left pixel.
        levels: ``(n_objects,)`` int32: object number (2D) or layer (3D), from 1.
        warnings: messages about the drawing and the trace.
    """

    mode: str
    width_px: int
    height_px: int
    objects: list[np.ndarray]
    levels: np.ndarray
    warnings: list[str] = field(default_factory=list)

    @property
    def n_points(self) -> int:
        return int(sum(len(o) for o in self.objects))

    @property
    def n_layers(self) -> int:
        return int(self.levels.max()) if len(self.levels) else 0

    def to_array(self) -> np.ndarray:
        """``(N, 4)`` int64 rows ``(object, x, y, level)``, objects numbered from 1, in cutting order."""
        if not self.objects:
            return np.zeros((0, 4), np.int64)
        rows = []
        for i, (obj, level) in enumerate(zip(self.objects, self.levels), start=1):
            block = np.empty((len(obj), 4), np.int64)
            block[:, 0] = i
            block[:, 1:3] = obj
            block[:, 3] = level
            rows.append(block)
        return np.concatenate(rows)

    @classmethod
    def from_array(cls, rows: np.ndarray, *, mode: str, width_px: int, height_px: int) -> "Digitized":
        """Inverse of :meth:`to_array` (rows sorted by object number)."""
        rows = np.asarray(rows, np.int64)
        objects: list[np.ndarray] = []
        levels: list[int] = []
        if len(rows):
            cuts = np.flatnonzero(np.diff(rows[:, 0])) + 1
            for block in np.split(rows, cuts):
                objects.append(block[:, 1:3].astype(np.int32))
                levels.append(int(block[0, 3]))
        return cls(mode, int(width_px), int(height_px), objects, np.array(levels, np.int32))

    def bounding_box_px(self) -> tuple[int, int, int, int]:
        """(x_min, y_min, x_max, y_max) of all points; (0, 0, -1, -1) when empty."""
        if not self.objects:
            return (0, 0, -1, -1)
        pts = np.concatenate(self.objects)
        return (int(pts[:, 0].min()), int(pts[:, 1].min()), int(pts[:, 0].max()), int(pts[:, 1].max()))

    def _repr_png_(self) -> bytes:
        """Notebook picture: traced pixels coloured by level (shallow/first yellow, last purple)."""
        rgb = np.full((self.height_px, self.width_px, 3), 255, np.uint8)
        for obj, level in zip(self.objects, self.levels):
            rgb[obj[:, 1], obj[:, 0]] = depth_colours([level], max(1, self.n_layers or len(self.objects)))[0]
        k = max(1, min(8, 600 // max(1, self.width_px, self.height_px)))
        return encode_png(np.repeat(np.repeat(rgb, k, axis=0), k, axis=1))

    def label_image(self) -> np.ndarray:
        """``(H, W)`` int32: object number (from 1) at each traced pixel, 0 elsewhere."""
        out = np.zeros((self.height_px, self.width_px), np.int32)
        for i, obj in enumerate(self.objects, start=1):
            out[obj[:, 1], obj[:, 0]] = i
        return out


def format_digitized(d: Digitized) -> str:
    """The text of a digitized-matrix file (see the module docstring)."""
    buf = io.StringIO()
    buf.write(FORMAT_LINE + "\n")
    buf.write(
        f"# mode={d.mode} width_px={d.width_px} height_px={d.height_px} "
        f"objects={len(d.objects)} points={d.n_points}\n"
    )
    buf.write(COLUMNS_LINE + "\n")
    arr = d.to_array()
    if len(arr):
        np.savetxt(buf, arr, fmt="%d", delimiter=",")
    return buf.getvalue()


def save_digitized(d: Digitized, path: str | os.PathLike) -> Path:
    """Write ``d`` to ``path`` atomically."""
    return atomic_write_text(path, format_digitized(d))


def _short(n: int) -> str:
    """A whole number as a message shows it: at most 15 characters."""
    text = str(n)
    return text if len(text) <= 15 else text[:12] + "..."


def parse_digitized(text: str, *, source: str = "<text>") -> Digitized:
    """Parse and validate digitized-matrix text; errors name ``source:line``."""
    lines = text.splitlines()

    def err(line_no: int, msg: str) -> ParseError:
        shown = lines[line_no - 1] if 0 < line_no <= len(lines) else ""
        quoted = f' "{shown[:60]}"' if shown else ""
        return ParseError(f"{source}:{line_no}: {msg}{quoted}")

    if not lines or lines[0].strip() != FORMAT_LINE:
        raise err(1, f"not a cam digitized matrix (expected first line '{FORMAT_LINE}')")
    if len(lines) < 3:
        raise err(len(lines) + 1, "file ends inside the header")
    meta_line = lines[1].strip()
    if not meta_line.startswith("#"):
        raise err(2, "expected the header line '# mode=... width_px=... height_px=... objects=... points=...'")
    meta: dict[str, str] = {}
    for word in meta_line[1:].split():
        key, sep, value = word.partition("=")
        if not sep:
            raise err(2, f"header word '{word}' is not key=value")
        meta[key] = value
    for key in ("mode", "width_px", "height_px", "objects", "points"):
        if key not in meta:
            raise err(2, f"header lacks '{key}='")
    mode = meta["mode"]
    if mode not in MODES:
        raise err(2, f"mode must be one of {', '.join(MODES)}, got '{mode}'")
    try:
        width_px, height_px, n_objects, n_points = (
            int(meta[k]) for k in ("width_px", "height_px", "objects", "points")
        )
    except ValueError:
        raise err(2, "width_px, height_px, objects and points must be whole numbers") from None
    if width_px < 1 or height_px < 1:
        raise err(2, "image size must be at least 1x1")
    if max(width_px, height_px) > MAX_IMAGE_SIDE_PX or width_px * height_px > MAX_IMAGE_PIXELS:
        raise err(2, f"image size {_short(width_px)}x{_short(height_px)} px is out of range: at most {MAX_IMAGE_SIDE_PX} px on a "
                  f"side and {MAX_IMAGE_PIXELS} px in all")
    max_level = width_px * height_px
    if lines[2].strip().replace(" ", "") != COLUMNS_LINE:
        raise err(3, f"expected the column line '{COLUMNS_LINE}'")

    values: list[tuple[int, int, int, int]] = []
    prev_obj, prev_level = 0, 0
    for line_no in range(4, len(lines) + 1):
        raw = lines[line_no - 1].strip()
        if not raw or raw.startswith("#"):
            continue
        parts = raw.split(",")
        if len(parts) != 4:
            raise err(line_no, f"expected 4 comma-separated integers 'object,x,y,level', got {len(parts)} field(s)")
        try:
            obj, x, y, level = (int(p) for p in parts)
        except ValueError:
            raise err(line_no, "expected 4 integers 'object,x,y,level'") from None
        if not (0 <= x < width_px and 0 <= y < height_px):
            raise err(line_no, f"point ({x}, {y}) lies outside the {width_px}x{height_px} image")
        if not 1 <= level <= max_level:
            raise err(line_no, f"level must be 1..{max_level} (the image's pixel count), got {_short(level)}")
        if obj == prev_obj:
            if level != prev_level:
                raise err(line_no, f"level changes within object {obj} ({prev_level} -> {level})")
        elif obj == prev_obj + 1:
            prev_obj, prev_level = obj, level
        else:
            raise err(line_no, f"object numbers must count up from 1 without gaps, got {_short(obj)} after {prev_obj}")
        values.append((obj, x, y, level))
    if prev_obj != n_objects:
        raise err(len(lines), f"header says {n_objects} objects, the file has {prev_obj}")
    if len(values) != n_points:
        raise err(len(lines), f"header says {n_points} points, the file has {len(values)}")
    rows = np.array(values, np.int64).reshape(-1, 4)
    return Digitized.from_array(rows, mode=mode, width_px=width_px, height_px=height_px)


def load_digitized(path: str | os.PathLike) -> Digitized:
    """Load a digitized matrix written by :func:`save_digitized` (validated; errors name file:line)."""
    p, text = read_text(path, not_text="not a cam digitized matrix (not UTF-8 text)")
    return parse_digitized(text, source=str(p))
