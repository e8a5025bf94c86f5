"""SVG in: every visible stroke and outline of an SVG file as exact curves in mm, then polylines.

Parsing is the job of a full SVG library, :mod:`svgelements`: it applies
``viewBox``, physical units (``mm``, ``cm``, ``in``, ``pt``, ``px`` at 96 dpi),
nested group transforms, ``<use>``, CSS ``style`` and ``display:none``.  This
module only picks what is to be cut and keeps it as exact segments:

* paths (lines, cubic and quadratic Béziers, elliptical arcs), ``rect`` (with
  rounded corners), ``circle``, ``ellipse``, ``line``, ``polyline``,
  ``polygon``; arcs are kept as the cubic Béziers :mod:`svgelements` splits
  them into (at most a quarter turn each, within a tiny fraction of a step).
* A shape is cut when it is visible: a stroke that is not ``none``, or a fill
  that is not ``none`` (its outline is cut, and a filled open subpath is
  closed, as the fill closes it; a ``line`` has no area, so only its stroke counts).  ``visibility: hidden`` and ``display: none``
  are not cut.
* ``<text>`` cannot be cut (its glyphs are in a font, not in the file): an
  error asks for the text to be converted to paths.  ``<image>`` is skipped
  with a warning.

Frame: SVG user space of the whole document in mm, x to the right, y *down*
(as on the page; the machine's y grows toward the operator, the same way).

>>> d = parse_svg(b'<svg xmlns="http://www.w3.org/2000/svg" width="20mm" height="10mm" viewBox="0 0 20 10">'
...               b'<path d="M1,1 H11 Q16,1 16,6" stroke="black" fill="none"/></svg>')
>>> d.n_strokes, d.segment_counts
(1, {'line': 1, 'quadratic': 1, 'cubic': 0})
>>> d.polylines(0.5)[0].round(3).tolist()
[[1.0, 1.0], [11.0, 1.0], [14.75, 2.25], [16.0, 6.0]]
"""
from __future__ import annotations

import io
import math
import os
from xml.etree import ElementTree
from dataclasses import dataclass, field
from pathlib import Path
from typing import Union

import cv2
import numpy as np
import svgelements as se

from ..choices import SVG_SUFFIXES
from ..errors import ParseError
from ..render.picture import encode_png

__all__ = ["SvgDrawing", "parse_svg", "load_svg", "SVG_SUFFIXES", "MM_PER_PX", "MAX_SVG_BYTES", "MAX_SVG_ELEMENTS",
           "expanded_size"]

MM_PER_PX = 25.4 / 96.0
"""An SVG user unit without a physical size (CSS px) is 1/96 inch."""
MAX_SVG_BYTES = 64 * 1024 * 1024
"""Larger SVG files are refused before they are parsed."""
MAX_SEGMENTS_PER_CURVE = 100_000
MAX_SVG_ELEMENTS = 200_000
"""Elements an SVG may hold once its ``<use>`` references are expanded (counted before anything is expanded: ten
levels of ``<use>`` fanning out four ways make a million copies from 2 kB)."""
"""The most straight pieces one curve is flattened into (a curve longer than 1 km at the finest tolerance)."""

LINE, QUADRATIC, CUBIC = 2, 3, 4
"""Segment kinds by their number of control points."""
_KIND_NAMES = {LINE: "line", QUADRATIC: "quadratic", CUBIC: "cubic"}


@dataclass
class SvgDrawing:
    """The strokes of an SVG file as exact segments in mm (see the module docstring for the frame).

    Attributes:
        strokes: one entry per stroke (a subpath): a list of ``(k, 2)`` float64 control point arrays in mm,
            ``k`` = 2 (line), 3 (quadratic Bézier) or 4 (cubic Bézier), each starting where the last ended.
        closed: ``(S,)`` bool, the stroke ends where it starts.
        size_mm: the document's ``(width, height)`` in mm (its viewport), or the extent of the strokes
            when the file gives none.
        element_counts: how many of each element kind were cut (``{"path": 3, "circle": 1, ...}``).
        warnings: what was skipped and why.
        source: the file name.
    """

    strokes: list[list[np.ndarray]]
    closed: np.ndarray
    size_mm: tuple[float, float] = (0.0, 0.0)
    element_counts: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    source: str = "<svg>"

    @property
    def n_strokes(self) -> int:
        return len(self.strokes)

    @property
    def segment_counts(self) -> dict[str, int]:
        """How many segments of each kind: ``{"line": n, "quadratic": n, "cubic": n}`` (arcs are cubics)."""
        counts = {name: 0 for name in _KIND_NAMES.values()}
        for stroke in self.strokes:
            for seg in stroke:
                counts[_KIND_NAMES[len(seg)]] += 1
        return counts

    def polylines(self, tolerance_mm: float) -> list[np.ndarray]:
        """Each stroke as an ``(N, 2)`` float64 polyline in mm, every point of it within ``tolerance_mm`` of the curve.

        A Bézier segment is cut into ``n`` pieces of equal parameter step: the chord of a piece of parameter
        length ``h`` lies within ``h² / 8 · max|B''|`` of the curve, and ``max|B''|`` is bounded by the control
        points' second differences (``6 · max|P0 - 2 P1 + P2|`` for a cubic, ``2 |P0 - 2 P1 + P2|`` for a
        quadratic), so ``n`` is the least that keeps the bound under the tolerance.
        """
        if not tolerance_mm > 0:
            raise ValueError("the flattening tolerance must be > 0 mm")
        out = []
        for stroke in self.strokes:
            pieces = [stroke[0][:1]]
            for seg in stroke:
                pieces.append(_flatten_segment(seg, tolerance_mm)[1:])
            out.append(np.concatenate(pieces))
        return out

    def extent_mm(self, tolerance_mm: float = 1e-3) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` of the strokes in mm, within ``tolerance_mm``; zeros when there are none."""
        if not self.strokes:
            return (0.0, 0.0, 0.0, 0.0)
        pts = np.concatenate(self.polylines(tolerance_mm))
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    def _repr_png_(self) -> bytes:
        """Notebook picture: the strokes, black on white, about 600 px on the longer side."""
        x0, y0, x1, y1 = self.extent_mm()
        k = 580.0 / max(x1 - x0, y1 - y0, 1e-9)
        w, h = int((x1 - x0) * k) + 21, int((y1 - y0) * k) + 21
        img = np.full((h, w, 3), 255, np.uint8)
        for poly in self.polylines(0.5 / k):
            p = np.rint((poly - (x0, y0)) * k * 16).astype(np.int32) + 10 * 16
            cv2.polylines(img, [p.reshape(-1, 1, 2)], False, (0, 0, 0), 1, cv2.LINE_AA, shift=4)
        return encode_png(img)


def _flatten_segment(seg: np.ndarray, tolerance_mm: float) -> np.ndarray:
    """``(n + 1, 2)`` points of one segment (see :meth:`SvgDrawing.polylines`)."""
    k = len(seg)
    if k == LINE:
        return seg
    second = seg[:-2] - 2 * seg[1:-1] + seg[2:]
    m = float(np.sqrt((second ** 2).sum(axis=1)).max())
    bound = 6 * m if k == CUBIC else 2 * m  # max |B''|
    n = max(1, math.ceil(math.sqrt(bound / (8 * tolerance_mm)))) if bound > 0 else 1
    n = min(n, MAX_SEGMENTS_PER_CURVE)
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    s = 1 - t
    if k == QUADRATIC:
        return s * s * seg[0] + 2 * s * t * seg[1] + t * t * seg[2]
    return s ** 3 * seg[0] + 3 * s * s * t * seg[1] + 3 * s * t * t * seg[2] + t ** 3 * seg[3]


def _visible(element) -> tuple[bool, bool]:
    """(cut it at all, its fill makes it a closed outline) of a shape."""
    values = element.values
    if str(values.get("visibility", "visible")).strip() in ("hidden", "collapse"):
        return False, False
    stroke = element.stroke is not None and element.stroke.value is not None and element.stroke.alpha != 0
    fill = element.fill is not None and element.fill.value is not None and element.fill.alpha != 0
    return stroke or fill, fill and not stroke


def _point(p, k: float) -> tuple[float, float]:
    x, y = float(p.x) * k, float(p.y) * k
    if not (math.isfinite(x) and math.isfinite(y)) or max(abs(x), abs(y)) > 1e6:
        raise ValueError("a coordinate is not a finite number within 1 km")
    return x, y


def _subpaths(path, k: float, close_open: bool) -> list[tuple[list[np.ndarray], bool]]:
    """The subpaths of a reified :class:`svgelements.Path` as segment lists in mm (``k`` mm per px)."""
    out: list[tuple[list[np.ndarray], bool]] = []
    segs: list[np.ndarray] = []
    start = None

    def finish(closed: bool) -> None:
        nonlocal segs
        if segs:
            if close_open and not closed and np.any(segs[-1][-1] != segs[0][0]):
                segs.append(np.array([segs[-1][-1], segs[0][0]]))
                closed = True
            out.append((segs, closed or bool(np.all(segs[-1][-1] == segs[0][0]))))
        segs = []

    for seg in path.segments():
        if isinstance(seg, se.Move):
            finish(False)
            start = seg.end
            continue
        if isinstance(seg, se.Close):
            if seg.start is not None and seg.end is not None and seg.start != seg.end:
                segs.append(np.array([_point(seg.start, k), _point(seg.end, k)]))
            finish(True)
            continue
        if isinstance(seg, se.Line):
            pts = [seg.start, seg.end]
        elif isinstance(seg, se.QuadraticBezier):
            pts = [seg.start, seg.control, seg.end]
        elif isinstance(seg, se.CubicBezier):
            pts = [seg.start, seg.control1, seg.control2, seg.end]
        elif isinstance(seg, se.Arc):
            for cubic in seg.as_cubic_curves():
                segs.append(np.array([_point(p, k) for p in (cubic.start, cubic.control1, cubic.control2, cubic.end)]))
            continue
        else:  # pragma: no cover - svgelements has no other segment kinds
            continue
        if pts[0] is None:
            pts[0] = start
        segs.append(np.array([_point(p, k) for p in pts]))
    finish(False)
    return out


def expanded_size(raw: bytes, source: str = "<svg>") -> int:
    """How many elements the document holds once every ``<use>`` is replaced by what it references (nested
    ``<use>`` included), counted on the XML tree without expanding anything: an element counts 1 plus its
    children; a ``<use>`` counts 1 plus its target.  A reference cycle counts as nothing more (svgelements drops
    it).  Unreadable XML counts 0 (the SVG reader says why).

    Raises:
        ParseError: the count passes :data:`MAX_SVG_ELEMENTS` (one line, naming it and the limit).
    """
    try:
        root = ElementTree.fromstring(raw)
    except (ElementTree.ParseError, ValueError):
        return 0
    by_id = {el.get("id"): el for el in root.iter() if el.get("id")}
    memo: dict[int, int] = {}

    def size(el, active: frozenset) -> int:  # noqa: ANN001 - an ElementTree element
        key = id(el)
        if key in memo:
            return memo[key]
        if key in active:
            return 0  # a cycle
        inner = active | {key}
        n = 1 + sum(size(child, inner) for child in el)
        if el.tag.rsplit("}", 1)[-1] == "use":
            ref = el.get("{http://www.w3.org/1999/xlink}href") or el.get("href") or ""
            target = by_id.get(ref[1:]) if ref.startswith("#") else None
            if target is not None:
                n += size(target, inner)
        memo[key] = n = min(n, MAX_SVG_ELEMENTS + 1)
        return n

    try:
        total = size(root, frozenset())
    except RecursionError:
        raise ParseError(f"{source}: elements nested too deeply to read") from None
    if total > MAX_SVG_ELEMENTS:
        raise ParseError(f"{source}: its <use> references expand to more than {MAX_SVG_ELEMENTS:,} elements; cam "
                         f"refuses it before expanding them (ungroup or unlink the clones, or split the drawing)")
    return total


def parse_svg(data: Union[bytes, str], *, source: str = "<svg>") -> SvgDrawing:
    """Read an SVG document (the text or its bytes) into an :class:`SvgDrawing` in mm.

    Raises:
        ParseError: not an SVG document, a ``<text>`` element (convert text to paths), a coordinate that is
        not a finite number.
    """
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    expanded_size(raw, source)  # counted before svgelements expands a single <use>
    try:
        svg = se.SVG.parse(io.BytesIO(raw), reify=True, ppi=96.0)
    except Exception as exc:  # svgelements raises the XML parser's and its own errors
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ParseError(f"{source}: not a readable SVG file ({message})") from None
    if not isinstance(svg, se.SVG):
        raise ParseError(f"{source}: not an SVG document (no <svg> element)")
    k = MM_PER_PX
    strokes: list[list[np.ndarray]] = []
    closed: list[bool] = []
    counts: dict[str, int] = {}
    warnings: list[str] = []
    images = 0
    try:
        for element in svg.elements():
            if isinstance(element, se.Text):
                words = (element.text or "").strip()
                shown = f" '{words[:30]}'" if words else ""
                raise ParseError(f"{source}: holds text{shown}; cam cannot cut a font: convert the text to paths "
                                 "first (Inkscape: Path > Object to Path; Illustrator: Type > Create Outlines)")
            if isinstance(element, se.SVGImage):
                images += 1
                continue
            if not isinstance(element, se.Shape):
                continue
            cut, fill_only = _visible(element)
            if not cut or (fill_only and isinstance(element, se.SimpleLine)):  # a line has no area to fill
                continue
            path = abs(se.Path(element))
            pieces = _subpaths(path, k, close_open=fill_only)
            if not pieces:
                continue
            name = type(element).__name__.lower().replace("simpleline", "line")
            counts[name] = counts.get(name, 0) + 1
            for segs, is_closed in pieces:
                strokes.append(segs)
                closed.append(is_closed)
    except ValueError as exc:
        raise ParseError(f"{source}: {exc}") from None
    if images:
        warnings.append(f"{images} embedded image(s) skipped: only strokes and outlines are cut")
    w, h = svg.width, svg.height
    size = (float(w) * k, float(h) * k) if w and h and math.isfinite(w) and math.isfinite(h) else (0.0, 0.0)
    drawing = SvgDrawing(strokes=strokes, closed=np.array(closed, bool), size_mm=size, element_counts=counts,
                         warnings=warnings, source=source)
    if drawing.size_mm == (0.0, 0.0) and strokes:
        x0, y0, x1, y1 = drawing.extent_mm()
        drawing.size_mm = (x1 - x0, y1 - y0)
    return drawing


def load_svg(path: Union[str, os.PathLike]) -> SvgDrawing:
    """Read an SVG file (see :func:`parse_svg`).

    Raises:
        ParseError: missing or unreadable file, larger than :data:`MAX_SVG_BYTES`, or bad content.
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > MAX_SVG_BYTES:
            raise ParseError(f"{p}: {size} bytes; SVG files over {MAX_SVG_BYTES // (1024 * 1024)} MB are refused")
        data = p.read_bytes()
    except OSError as exc:
        raise ParseError(f"{p}: cannot read ({exc.strerror or exc})") from None
    return parse_svg(data, source=p.name)
