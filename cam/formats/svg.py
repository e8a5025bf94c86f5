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

Layers (issue #31 point 6): every stroke belongs to one layer.  When the file has Inkscape layers
(``<g inkscape:groupmode="layer" inkscape:label="...">``), a stroke's layer is the innermost layer group it is
in, named by its label (a sublayer as ``parent/child``; a layer without a label by its ``id``; strokes outside
every layer in ``(no layer)``; two layers of one name are one).  Otherwise strokes are grouped by their
stroke colour (a shape with no stroke by its fill colour), named by the colour in hex (``#ff0000``); a
drawing in one colour is one layer.  Layers are listed in file order (the order their first strokes come in).

Frame: SVG user space of the whole document in mm, x to the right, y *down*
(as on the page; the machine's y grows toward the operator, the same way).

>>> d = parse_svg(b'<svg xmlns="http://www.w3.org/2000/svg" width="20mm" height="10mm" viewBox="0 0 20 10">'
...               b'<path d="M1,1 H11 Q16,1 16,6" stroke="black" fill="none"/></svg>')
>>> d.n_strokes, d.segment_counts
(1, {'line': 1, 'quadratic': 1, 'cubic': 0})
>>> d.polylines(0.5)[0].round(3).tolist()
[[1.0, 1.0], [11.0, 1.0], [14.75, 2.25], [16.0, 6.0]]
>>> d.layer_names, d.layers_from
(['#000000'], 'colour')
"""
from __future__ import annotations

import io
import math
import os
from xml.etree import ElementTree
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

import cv2
import numpy as np
import svgelements as se

from ..choices import SVG_SUFFIXES
from ..errors import ParseError
from ..render.picture import encode_png

__all__ = ["SvgDrawing", "parse_svg", "load_svg", "SVG_SUFFIXES", "MM_PER_PX", "MAX_SVG_BYTES", "MAX_SVG_ELEMENTS",
           "expanded_size", "NO_LAYER"]

MM_PER_PX = 25.4 / 96.0
"""An SVG user unit without a physical size (CSS px) is 1/96 inch."""
MAX_SVG_BYTES = 64 * 1024 * 1024
"""Larger SVG files are refused before they are parsed."""
MAX_SEGMENTS_PER_CURVE = 100_000
MAX_SVG_ELEMENTS = 200_000
"""Elements an SVG may hold once its ``<use>`` references are expanded (counted before anything is expanded: ten
levels of ``<use>`` fanning out four ways make a million copies from 2 kB)."""
"""The most straight pieces one curve is flattened into (a curve longer than 1 km at the finest tolerance)."""

NO_LAYER = "(no layer)"
"""The layer of strokes outside every Inkscape layer of a file that has some."""
_INKSCAPE = "{http://www.inkscape.org/namespaces/inkscape}"

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
        layer_names: the layers in file order (see the module docstring); empty: one unnamed layer.
        stroke_layer: ``(S,)`` int, the index in ``layer_names`` of each stroke's layer (None: all in layer 0).
        layers_from: what named the layers: "inkscape" (layer groups) or "colour" (stroke colours).
    """

    strokes: list[list[np.ndarray]]
    closed: np.ndarray
    size_mm: tuple[float, float] = (0.0, 0.0)
    element_counts: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    source: str = "<svg>"
    layer_names: list[str] = field(default_factory=list)
    stroke_layer: Optional[np.ndarray] = None
    layers_from: str = "colour"

    @property
    def layer_of_stroke(self) -> np.ndarray:
        """``(S,)`` int64, each stroke's index in :meth:`layers` (0 for all when the drawing names none)."""
        if self.stroke_layer is None:
            return np.zeros(len(self.strokes), np.int64)
        return np.asarray(self.stroke_layer, np.int64)

    def layers(self) -> list[str]:
        """The layer names in file order (one layer, ``"all"``, when the drawing names none)."""
        return list(self.layer_names) or ["all"]

    def layer_lengths_mm(self, tolerance_mm: float = 1e-3) -> list[float]:
        """The length of every layer's strokes in mm (as :meth:`layers`; curves flattened within ``tolerance_mm``)."""
        out = np.zeros(len(self.layers()))
        for poly, layer in zip(self.polylines(tolerance_mm), self.layer_of_stroke):
            out[layer] += float(np.hypot(*np.diff(poly, axis=0).T).sum())
        return out.tolist()

    def find_layers(self, name: str) -> list[int]:
        """The indices (file order) of the layers ``name`` selects: the layer of that name and its sublayers
        (``parent`` selects ``parent/child``); when the layers are colours, any CSS colour that is the same
        (``red`` is ``#ff0000``).  Empty when none is."""
        names = self.layers()
        want = name.strip()
        hit = [i for i, n in enumerate(names) if n == want or n.startswith(want + "/")]
        if hit or self.layers_from != "colour":
            return hit
        colour = _colour_hex(want)
        return [i for i, n in enumerate(names) if colour is not None and n == colour]

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


def _colour_hex(text: str) -> Optional[str]:
    """A CSS colour (``red``, ``#f00``, ``rgb(255,0,0)``) as the hex the layers are named by, or None."""
    try:
        colour = se.Color(text)
    except Exception:  # svgelements' parser raises on odd input
        return None
    if int(colour) == 255 and text.strip().lower() not in ("black", "#000", "#000000", "#000000ff", "rgb(0,0,0)"):
        return None  # svgelements reads what is no colour as black
    return colour.hex


def _colour_of(element) -> str:
    """The layer name of a shape in a file without Inkscape layers: its stroke colour, else its fill colour."""
    stroke = element.stroke
    if stroke is not None and stroke.value is not None and stroke.alpha != 0:
        return stroke.hex
    return element.fill.hex if element.fill is not None and element.fill.value is not None else "none"


def _walk(svg) -> list[tuple[object, Optional[str]]]:
    """Every element under ``svg`` in document order (as ``svg.elements()`` gives them), each with the path of
    the Inkscape layers it is in (``parent/child``; None: in none)."""
    out: list[tuple[object, Optional[str]]] = []
    stack = [(iter(svg), None)]
    while stack:
        items, layer = stack[-1]
        element = next(items, None)
        if element is None:
            stack.pop()
            continue
        out.append((element, layer))
        if isinstance(element, (se.Group, se.Use)):
            inner = layer
            attributes = element.values.get("attributes", {}) if isinstance(element, se.Group) else {}
            if attributes.get(_INKSCAPE + "groupmode") == "layer":
                label = (attributes.get(_INKSCAPE + "label") or attributes.get("id") or "layer").strip()
                label = label.replace("/", "-") or "layer"
                inner = label if layer is None else f"{layer}/{label}"
            stack.append((iter(element), inner))
    return out


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
    except (ElementTree.ParseError, ValueError, LookupError):  # LookupError: an unknown declared encoding
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
    layer_paths: list[Optional[str]] = []
    colours: list[str] = []
    try:
        for element, layer in _walk(svg):
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
            colour = _colour_of(element)
            for segs, is_closed in pieces:
                strokes.append(segs)
                closed.append(is_closed)
                layer_paths.append(layer)
                colours.append(colour)
    except ValueError as exc:
        raise ParseError(f"{source}: {exc}") from None
    if images:
        warnings.append(f"{images} embedded image(s) skipped: only strokes and outlines are cut")
    w, h = svg.width, svg.height
    size = (float(w) * k, float(h) * k) if w and h and math.isfinite(w) and math.isfinite(h) else (0.0, 0.0)
    inkscape = any(layer is not None for layer in layer_paths)
    names = [NO_LAYER if layer is None else layer for layer in layer_paths] if inkscape else colours
    layer_names = list(dict.fromkeys(names))  # file order of first appearance
    index = {name: i for i, name in enumerate(layer_names)}
    drawing = SvgDrawing(strokes=strokes, closed=np.array(closed, bool), size_mm=size, element_counts=counts,
                         warnings=warnings, source=source, layer_names=layer_names,
                         stroke_layer=np.array([index[n] for n in names], np.int64),
                         layers_from="inkscape" if inkscape else "colour")
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
