"""SVG in: every visible stroke and outline of an SVG file as exact curves in mm, then polylines.

Parsing follows a full SVG library, :mod:`svgelements`: it applies
``viewBox``, physical units (``mm``, ``cm``, ``in``, ``pt``, ``px`` at 96 dpi),
nested group transforms, ``<use>``, CSS ``style`` and ``display:none``.  It builds
a Python object per point and shape (about 0.5 ms a circle), so a fast reader
walks the XML itself for the common cases and gives the same strokes (within
1e-9 mm; issue #32 point 5): it computes the values each element inherits as
svgelements does, circles and ellipses that are only scaled and moved as the same
12 cubic Béziers, and paths without arcs, with numpy; any other element is built
by svgelements from the same values, and a document with ``<use>``, ``<style>``,
text, images or a nested ``<svg>`` (or anything the fast reader does not take)
is read by svgelements whole.  This module picks what is to be cut and keeps it
as exact segments:

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
import re
from xml.etree import ElementTree
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

import cv2
import numpy as np
import svgelements as se

from ..errors import ParseError
from ..render.picture import encode_png

__all__ = ["SvgDrawing", "parse_svg", "load_svg", "MM_PER_PX", "MAX_SVG_BYTES", "MAX_SVG_ELEMENTS",
           "expanded_size", "NO_LAYER"]

MM_PER_PX = 25.4 / 96.0
"""An SVG user unit without a physical size (CSS px) is 1/96 inch."""
MAX_SVG_BYTES = 64 * 1024 * 1024
"""Larger SVG files are refused before they are parsed."""
MAX_SEGMENTS_PER_CURVE = 100_000
EVALUATE_POINTS = 1 << 17
"""Curves are flattened in blocks of about this many points."""
MAX_SVG_ELEMENTS = 200_000
"""Elements an SVG may hold once its ``<use>`` references are expanded (counted before anything is expanded: ten
levels of ``<use>`` fanning out four ways make a million copies from 2 kB)."""
"""The most straight pieces one curve is flattened into (a curve longer than 1 km at the finest tolerance)."""

Stroke = Union[list[np.ndarray], np.ndarray]
"""A stroke's segments: ``(k, 2)`` arrays (see :attr:`SvgDrawing.strokes`)."""

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
        strokes: one entry per stroke (a subpath): a sequence of ``(k, 2)`` float64 control point arrays in
            mm, ``k`` = 2 (line), 3 (quadratic Bézier) or 4 (cubic Bézier), each starting where the last ended
            (a list, or one ``(n, k, 2)`` array when all are of one kind: a circle's 12 cubics).
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

    strokes: list[Stroke]
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
        if not self.strokes:
            return [0.0] * len(self.layers())
        per_stroke = []
        for lo, hi in _stroke_blocks(self.strokes):  # a block of strokes at a time: the memory of a block
            pts, bounds = _flatten_block(self.strokes[lo:hi], tolerance_mm)
            step = np.hypot(*np.diff(pts, axis=0).T)
            step[bounds[1:-1] - 1] = 0.0  # from one stroke's end to the next one's start: no length
            per_stroke.append(np.add.reduceat(np.r_[step, 0.0], bounds[:-1]))
        return np.bincount(self.layer_of_stroke, np.concatenate(per_stroke), len(self.layers())).tolist()

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
            if isinstance(stroke, np.ndarray):  # segments of one kind
                counts[_KIND_NAMES[stroke.shape[1]]] += len(stroke)
                continue
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
        return _flatten_strokes(self.strokes, tolerance_mm)

    def polylines_joined(self, tolerance_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`polylines` one after another: ``(P, 2)`` float64 points in mm and ``(S + 1,)`` int64 offsets
        where each stroke's polyline begins (the last ``P``)."""
        if not tolerance_mm > 0:
            raise ValueError("the flattening tolerance must be > 0 mm")
        if not self.strokes:
            return np.zeros((0, 2)), np.zeros(1, np.int64)
        return _flatten_joined(self.strokes, tolerance_mm)

    def extent_mm(self, tolerance_mm: float = 1e-3) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` of the strokes in mm, within ``tolerance_mm``; zeros when there are none."""
        if not self.strokes:
            return (0.0, 0.0, 0.0, 0.0)
        pts = _flatten_joined(self.strokes, tolerance_mm)[0]
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


def _stroke_blocks(strokes: list[Stroke], segments: int = 1 << 15) -> list[tuple[int, int]]:
    """``(first, last + 1)`` of consecutive strokes of about ``segments`` segments each (a stroke is never cut)."""
    lengths = np.fromiter((len(stroke) for stroke in strokes), np.int64, len(strokes))
    cuts = np.unique(np.searchsorted(np.cumsum(lengths), np.arange(segments, int(lengths.sum()), segments)) + 1)
    bounds = np.r_[0, cuts[cuts < len(strokes)], len(strokes)]
    return list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))


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


def _flatten_strokes(strokes: list[Stroke], tolerance_mm: float) -> list[np.ndarray]:
    """Every stroke's polyline (see :meth:`SvgDrawing.polylines`), all segments of one kind at once: the same
    points :func:`_flatten_segment` gives one segment at a time."""
    if not strokes:
        return []
    out, bounds = _flatten_joined(strokes, tolerance_mm)
    return np.split(out, bounds[1:-1])


def _flatten_joined(strokes: list[Stroke], tolerance_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """The polylines of :func:`_flatten_strokes` one after another (``(P, 2)``), and where each begins (``(S + 1,)``
    offsets, the last ``P``); every stroke has a segment.  Made a block of strokes at a time
    (:func:`_stroke_blocks`): the working arrays are those of a block."""
    blocks = _stroke_blocks(strokes)
    if len(blocks) == 1:
        return _flatten_block(strokes, tolerance_mm)
    pts: list[np.ndarray] = []
    bounds: list[np.ndarray] = [np.zeros(1, np.int64)]
    done = 0
    for lo, hi in blocks:
        block_pts, block_bounds = _flatten_block(strokes[lo:hi], tolerance_mm)
        pts.append(block_pts)
        bounds.append(block_bounds[1:] + done)
        done += len(block_pts)
    return np.concatenate(pts), np.concatenate(bounds)


def _flatten_block(strokes: list[Stroke], tolerance_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_flatten_joined` of a few strokes at once."""
    kinds, parts, first_point = _segments_by_kind(strokes)
    n = np.ones(len(kinds), np.int64)
    curves = {}
    for k in (QUADRATIC, CUBIC):
        if parts[k][0]:
            where, ctrl = np.concatenate(parts[k][0]), np.concatenate(parts[k][1])
            second = ctrl[:, :-2] - 2 * ctrl[:, 1:-1] + ctrl[:, 2:]
            m = np.sqrt((second ** 2).sum(axis=2)).max(axis=1)
            bound = 6 * m if k == CUBIC else 2 * m
            with np.errstate(invalid="ignore"):
                pieces = np.ceil(np.sqrt(bound / (8 * tolerance_mm)))
            n[where] = np.where(bound > 0, np.clip(pieces, 1, MAX_SEGMENTS_PER_CURVE), 1).astype(np.int64)
            curves[k] = (where, ctrl)
    lengths = np.fromiter((len(stroke) for stroke in strokes), np.int64, len(strokes))
    seg_stroke = np.repeat(np.arange(len(strokes)), lengths)
    ends = np.cumsum(n) + seg_stroke + 1  # one past each segment's last point in the joined output
    starts = ends - n
    out = np.empty((int(ends[-1]) if len(ends) else 0, 2))
    first = np.cumsum(lengths) - lengths
    heads = starts[first[lengths > 0]] - 1
    out[heads] = first_point[first[lengths > 0]]
    if parts[LINE][0]:
        out[starts[np.concatenate(parts[LINE][0])]] = np.concatenate(parts[LINE][1])[:, -1]
    for k, (where, ctrl) in curves.items():
        # a block of curves at a time: about EVALUATE_POINTS points (the memory of a block, not of the drawing)
        block = np.searchsorted(np.cumsum(n[where]), np.arange(EVALUATE_POINTS, int(n[where].sum()), EVALUATE_POINTS))
        for lo, hi in zip(np.r_[0, block], np.r_[block, len(where)]):
            if hi > lo:
                _evaluate(out, ctrl[lo:hi], n[where[lo:hi]], starts[where[lo:hi]], k)
    return out, np.concatenate([[0], ends[np.cumsum(lengths) - 1]])


def _segments_by_kind(strokes: list[Stroke]) -> tuple[np.ndarray, dict[int, tuple[list, list]], np.ndarray]:
    """Every segment's kind (``(G,)``, in stroke order) and, for each kind, the segments' indices and control
    points as lists of arrays to join (the strokes held as one ``(n, k, 2)`` array are taken whole, all of one
    kind at once), and each segment's first control point (``(G, 2)``)."""
    parts: dict[int, tuple[list, list]] = {k: ([], []) for k in (LINE, QUADRATIC, CUBIC)}
    lengths = np.fromiter((len(stroke) for stroke in strokes), np.int64, len(strokes))
    at = np.cumsum(lengths) - lengths
    kinds = np.zeros(int(lengths.sum()), np.int64)
    whole: dict[int, list[int]] = {LINE: [], QUADRATIC: [], CUBIC: []}
    for s, stroke in enumerate(strokes):
        if isinstance(stroke, np.ndarray):
            whole[stroke.shape[1]].append(s)
            continue
        ks = np.fromiter((len(seg) for seg in stroke), np.int64, len(stroke))
        kinds[at[s]:at[s] + len(stroke)] = ks
        for k in (LINE, QUADRATIC, CUBIC):
            mine = np.flatnonzero(ks == k)
            if len(mine):
                parts[k][0].append(at[s] + mine)
                parts[k][1].append(np.stack([stroke[i] for i in mine]))
    for k, chosen in whole.items():
        if chosen:
            n = lengths[chosen]
            where = np.repeat(at[chosen] - (np.cumsum(n) - n), n) + np.arange(int(n.sum()))
            kinds[where] = k
            parts[k][0].append(where)
            parts[k][1].append(np.concatenate([strokes[s] for s in chosen]))
    first_point = np.empty((len(kinds), 2))
    for k, (where, ctrl) in parts.items():
        for w, c in zip(where, ctrl):
            first_point[w] = c[:, 0]
    return kinds, parts, first_point


def _evaluate(out: np.ndarray, ctrl: np.ndarray, n: np.ndarray, starts: np.ndarray, k: int) -> None:
    """Write the points ``t = 1/n .. 1`` of every curve ``ctrl[i]`` (``n[i]`` pieces) at ``out[starts[i]:]``."""
    index = np.repeat(np.arange(len(n)), n)
    step = np.arange(len(index)) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n within each curve
    pieces = n[index]
    t = np.where(step == pieces, 1.0, step * (1.0 / pieces))[:, None]
    s = 1 - t
    p = ctrl[index]
    if k == QUADRATIC:
        pts = s * s * p[:, 0] + 2 * s * t * p[:, 1] + t * t * p[:, 2]
    else:
        pts = s ** 3 * p[:, 0] + 3 * s * s * t * p[:, 1] + 3 * s * t * t * p[:, 2] + t ** 3 * p[:, 3]
    out[np.repeat(starts, n) + step - 1] = pts


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
        if pts[0] is None:  # a path that does not start with a move (M): its first point is where it is
            start = pts[-1]
            continue
        segs.append(np.array([_point(p, k) for p in pts]))
    finish(False)
    return out


def expanded_size(raw: bytes, source: str = "<svg>") -> int:
    """How many elements the document holds once every ``<use>`` is replaced by what it references (nested
    ``<use>`` included), counted on the XML tree without expanding anything: an element counts 1 plus its
    children; a ``<use>`` counts 1 plus its target.  Unreadable XML counts 0 (the SVG reader says why).

    Raises:
        ParseError: the count passes :data:`MAX_SVG_ELEMENTS` (one line, naming it and the limit), or a ``<use>``
            refers to an element that holds it (a reference cycle, an error in SVG: svgelements expanded it until
            Python's recursion limit, for minutes when it fans out).
    """
    try:
        root = ElementTree.fromstring(raw)
    except (ElementTree.ParseError, ValueError, LookupError):  # LookupError: an unknown declared encoding
        return 0
    return _expanded_count(root, source)


def _expanded_count(root, source: str) -> int:  # noqa: ANN001 - an ElementTree element
    """:func:`expanded_size` of a parsed document."""
    by_id = {el.get("id"): el for el in root.iter() if el.get("id")}
    memo: dict[int, int] = {}

    def size(el, active: frozenset) -> int:  # noqa: ANN001 - an ElementTree element
        key = id(el)
        if key in memo:
            return memo[key]
        if key in active:
            raise ParseError(f"{source}: a <use> refers to an element that holds it"
                             f"{' (#' + el.get('id') + ')' if el.get('id') else ''}: a reference cycle, which SVG "
                             f"does not allow; cam refuses it")
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
    tree = _read_tree(raw)
    if tree is None:
        return _parse_svgelements(raw, source)  # it says why it cannot read it
    _expanded_count(tree[0], source)  # counted before svgelements expands a single <use>
    try:
        _check_walkable(*tree)
        return _parse_fast(tree[0], source)
    except MemoryError:
        raise
    except Exception:  # what the fast reader does not read (or finds wrong) svgelements reads, and says why
        return _parse_svgelements(raw, source)


def _parse_svgelements(raw: bytes, source: str) -> SvgDrawing:
    """:func:`parse_svg` by svgelements alone (the whole document; ``<use>`` counted already)."""
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
    return _drawing(strokes, closed, size, counts, warnings, source, layer_paths, colours)


# --- the fast reader (issue #32 point 5) --------------------------------------------------------------------------
# svgelements builds a Python object per point, segment and shape: about 0.5 ms per circle.  The fast reader walks
# the XML tree itself and computes what svgelements would for the common cases (the same inherited values, the
# same transforms, circles and ellipses as the same 12 cubic Béziers, paths without arcs), with numpy for the
# arithmetic.  An element it does not compute itself (a rect, a line, a path with arcs, an odd attribute) is built
# by svgelements from the same values; a document it cannot walk (``<use>``, ``<style>``, text, images, nested
# ``<svg>``, anything that raises) is read by svgelements whole, as before.

class _Unsupported(Exception):
    """The fast reader leaves this document to svgelements."""


_SVG_NS = "{http://www.w3.org/2000/svg"
_WHOLE_DOCUMENT_TAGS = frozenset({"use", "style", "text", "tspan", "textPath", "image", "svg"})
"""Tags only svgelements reads (a ``<use>`` expands, a ``<style>`` restyles what follows, ``<text>`` is an error)."""
_NOT_RENDERED = frozenset({"defs", "clipPath", "pattern"})
_SHAPES = frozenset({"path", "circle", "ellipse", "line", "polyline", "polygon", "rect"})
_NON_PROPAGATING = ("preserveAspectRatio", "viewBox", "id", "class", "clip-path")
_STYLE_KEYS = ("stroke", "stroke_opacity", "stroke-opacity", "fill", "fill_opacity", "fill-opacity", "stroke_width",
               "stroke-width", "visibility")
_READ_KEYS = frozenset(_STYLE_KEYS + ("transform", "display", "color", "style", "d", "cx", "cy", "r", "rx", "ry",
                                      "center", "attributes", "tag", "x", "y", "width", "height", "points", "x1",
                                      "y1", "x2", "y2", "viewport_transform", "apply", "vector-effect"))
_FLOAT = re.compile(se.PATTERN_FLOAT)
_PATH_TOKEN = re.compile(r"([MmZzLlHhVvCcSsQqTt])|(" + se.PATTERN_FLOAT + ")")
_PATH_GAP = re.compile(r"[ ,\t\n\r\f]*")
_ARITY = {"M": 2, "L": 2, "T": 2, "H": 1, "V": 1, "C": 6, "S": 4, "Q": 4, "Z": 0}
_MOVE, _CLOSE = 0, 1
_TAU = math.tau


def _read_tree(raw: bytes):
    """``(root element, namespace prefixes declared)`` of the XML, or None when it is not well-formed XML."""
    prefixes: set[str] = set()
    try:
        parser = ElementTree.iterparse(io.BytesIO(raw), events=("start-ns",))
        for _event, (prefix, _uri) in parser:
            prefixes.add(prefix)
        return parser.root, prefixes
    except (ElementTree.ParseError, ValueError, LookupError):
        return None


def _local(tag) -> str:
    """An element's tag as svgelements names it (the SVG namespace dropped)."""
    if not isinstance(tag, str):
        return ""
    return tag[28:] if tag.startswith(_SVG_NS) else tag


def _check_walkable(root, prefixes: set[str]) -> None:
    """Raise :class:`_Unsupported` for a document only svgelements reads."""
    if _local(root.tag) != "svg" or prefixes & _READ_KEYS:
        raise _Unsupported
    for el in root.iter():
        if el is not root and _local(el.tag) in _WHOLE_DOCUMENT_TAGS:
            raise _Unsupported


def _values(elem, tag: str, parent: dict) -> dict:
    """The values svgelements gives an element: its parent's, its attributes and ``style`` over them, ``transform``
    appended to the parent's (as :meth:`svgelements.SVG.parse` computes them, with no style sheet)."""
    values = dict(parent)
    for key in _NON_PROPAGATING:
        values.pop(key, None)
    attributes = dict(elem.attrib)
    attributes["tag"] = tag
    style = attributes.get("style")
    if style is not None:
        for equate in style.split(";"):
            item = equate.split(":")
            if len(item) == 2:
                attributes[item[0].strip()] = item[1].strip()
    for key in ("fill", "stroke"):
        if attributes.get(key) == "currentColor":
            attributes[key] = attributes["color"] if "color" in attributes else values["color"]
    if "transform" in attributes and "transform" in values:
        attributes["transform"] = values["transform"] + " " + attributes["transform"]
    values.update(attributes)
    values["attributes"] = attributes
    return values


def _hidden(values: dict) -> bool:
    return "display" in values and values["display"].lower() == "none"


class _Walk:
    """One document walked: what each shape becomes, in document order (see :func:`_parse_fast`)."""

    def __init__(self, k: float):
        self.k = k
        self.items: list[tuple] = []  # (kind name, pieces or circle index, layer, colour)
        self.circles: list[tuple[float, float, float, float]] = []
        self.size = (0.0, 0.0)
        self.viewport = (0.0, 0.0)
        self.matrices: dict[str, se.Matrix] = {}
        self.styles: dict[tuple, tuple[bool, bool, str]] = {}

    def matrix(self, text: str) -> se.Matrix:
        m = self.matrices.get(text)
        if m is None:
            m = self.matrices[text] = se.Matrix(text)
        return m

    def style(self, values: dict) -> tuple[bool, bool, str]:
        """(cut it, only its fill makes it cut, its colour) of a shape, as :func:`_visible` and :func:`_colour_of`
        find them on the svgelements shape (computed once for each combination of the values they read)."""
        key = tuple(map(values.get, _STYLE_KEYS))
        got = self.styles.get(key)
        if got is None:
            probe = se.Path({name: v for name, v in zip(_STYLE_KEYS, key) if v is not None})
            got = self.styles[key] = (*_visible(probe), _colour_of(probe))
        return got

    def root(self, root) -> dict:
        """The values of the ``<svg>`` element, its viewport transform appended (as svgelements does)."""
        values = _values(root, "svg", {"color": "black", "fill": "black", "stroke": "none"})
        if _hidden(values):
            raise _Unsupported
        s = se.SVG(values)
        width = s.viewbox.width if s.viewbox is not None else 1000
        height = s.viewbox.height if s.viewbox is not None else 1000
        s.render(ppi=96.0, width=width, height=height, viewbox=s.viewbox)
        self.size = (s.width, s.height)
        self.viewport = (s.height, s.width)  # sic: svgelements swaps them when there is no viewBox
        if s.viewbox is not None:
            if s.height == 0 or s.width == 0:
                raise _Unsupported
            transform = s.viewbox_transform  # ZeroDivisionError: left to svgelements
            values["transform"] = values["transform"] + " " + transform if "transform" in values else transform
            values["viewport_transform"] = values["transform"]
            self.viewport = (s.viewbox.width, s.viewbox.height)
        self.matrix(values.get("transform", ""))
        return values

    def children(self, elem, values: dict, layer: Optional[str]) -> None:
        """Walk the children of an element whose values are ``values`` (iteratively: no recursion limit)."""
        stack = [(iter(elem), values, layer)]
        while stack:
            items, values, layer = stack[-1]
            child = next(items, None)
            if child is None:
                stack.pop()
                continue
            tag = _local(child.tag)
            if not tag or _hidden(values):
                continue
            own = _values(child, tag, values)
            if _hidden(own) or tag in _NOT_RENDERED:
                continue
            self.matrix(own.get("transform", ""))  # a transform svgelements cannot read is left to it
            inner = layer
            if tag == "g":
                attributes = own["attributes"]
                if attributes.get(_INKSCAPE + "groupmode") == "layer":
                    label = (attributes.get(_INKSCAPE + "label") or attributes.get("id") or "layer").strip()
                    label = label.replace("/", "-") or "layer"
                    inner = label if layer is None else f"{layer}/{label}"
            elif tag in _SHAPES:
                self.shape(tag, own, layer)
            stack.append((iter(child), own, inner))

    def shape(self, tag: str, values: dict, layer: Optional[str]) -> None:
        cut, fill_only, colour = self.style(values)
        if tag in ("circle", "ellipse") and self.round_shape(values, layer, cut, colour):
            return
        if tag == "path" and cut:
            pieces = _path_pieces(values, self.matrix(values.get("transform", "")), self.k, fill_only)
            if pieces is not None:
                self.add("path", pieces, layer, colour)
                return
        element = _svgelements_shape(tag, values, self.viewport)
        if element is None or not cut or (fill_only and tag == "line"):
            return
        name = type(element).__name__.lower().replace("simpleline", "line")
        self.add(name, _subpaths(abs(se.Path(element)), self.k, close_open=fill_only), layer, colour)

    def round_shape(self, values: dict, layer: Optional[str], cut: bool, colour: str) -> bool:
        """A circle or ellipse whose transform only scales (by > 0) and moves it: recorded for :func:`_circles`
        (or dropped when invisible or of no size); False when svgelements is to build it."""
        m = self.matrix(values.get("transform", ""))
        if m.b != 0 or m.c != 0 or not (m.a > 0 and m.d > 0) or "center" in values:
            return False
        if "r" in values:
            numbers = [values.get("cx", "0"), values.get("cy", "0"), values["r"], values["r"]]
        else:
            numbers = [values.get("cx", "0"), values.get("cy", "0"), values.get("rx"), values.get("ry")]
        for v in numbers:
            if not (isinstance(v, str) and _FLOAT.fullmatch(v)):
                return False
        cx, cy, rx, ry = map(float, numbers)
        rx, ry = m.a * rx, m.d * ry
        if not (rx > 0 and ry > 0 and math.isfinite(rx) and math.isfinite(ry)):
            return rx == 0 or ry == 0  # no size: svgelements drops it; a negative radius is left to it
        if cut:
            self.circles.append((cx * m.a + m.e, cy * m.d + m.f, rx, ry))
            self.add(values["tag"], len(self.circles) - 1, layer, colour)
        return True

    def add(self, name: str, pieces, layer: Optional[str], colour: str) -> None:
        self.items.append((name, pieces, layer, colour))


def _path_commands(d: str) -> Optional[list[tuple[str, list[float]]]]:
    """The commands of a path's ``d`` with their numbers, or None unless it is well formed (every command with
    whole groups of numbers, starting with a move) and has no arcs: svgelements then reads it as SVG says."""
    out: list[tuple[str, list[float]]] = []
    end = 0
    for found in _PATH_TOKEN.finditer(d):  # one pass: a regex of the whole d backtracks exponentially on a typo
        if _PATH_GAP.fullmatch(d, end, found.start()) is None:
            return None  # something that is neither a command, a number nor a separator ("NaN")
        end = found.end()
        command, number = found.groups()
        if command:
            out.append((command, []))
        elif not out:
            return None
        else:
            out[-1][1].append(float(number))
    if _PATH_GAP.fullmatch(d, end) is None or not out or out[0][0] not in "Mm":
        return None
    for command, numbers in out:
        arity = _ARITY[command.upper()]
        if (arity == 0 and numbers) or (arity and (not numbers or len(numbers) % arity)):
            return None
    return out


def _path_segments(commands: list[tuple[str, list[float]]]) -> tuple[list[int], list[tuple[float, float]]]:
    """The segments svgelements makes of the commands, in user units before the transform: each segment's kind
    (:data:`_MOVE`, :data:`_CLOSE` or its number of control points) and its points (a move its end, a close its
    start and end, a curve all its control points), all in one list."""
    kinds: list[int] = []
    pts: list[tuple[float, float]] = []
    cur = z = None
    last_kind, last_ctrl = _MOVE, None
    for command, numbers in commands:
        op, rel = command.upper(), command.islower()
        if op == "Z":
            kinds.append(_CLOSE)
            pts += [cur, z]
            cur, last_kind = z, _CLOSE
            continue
        arity = _ARITY[op]
        for i in range(0, len(numbers), arity):
            v = numbers[i:i + arity]
            if op in "HV":
                value = v[0] + (cur[0] if op == "H" else cur[1]) if rel else v[0]
                v = [value, cur[1]] if op == "H" else [cur[0], value]
            elif rel and cur is not None:
                v = [x + cur[j % 2] for j, x in enumerate(v)]
            given = [(v[j], v[j + 1]) for j in range(0, len(v), 2)]
            if op == "M" and i == 0:
                kinds.append(_MOVE)
                pts.append(given[0])
                cur = z = given[0]
                last_kind = _MOVE
                continue
            if op in "ST":
                smooth = cur if last_kind not in (QUADRATIC, CUBIC) else \
                    (cur[0] + (cur[0] - last_ctrl[0]), cur[1] + (cur[1] - last_ctrl[1]))
                given = [smooth] + given
            ctrl = [cur] + given
            kinds.append(len(ctrl))
            pts += ctrl
            cur, last_kind, last_ctrl = ctrl[-1], len(ctrl), ctrl[-2]
    return kinds, pts


def _path_pieces(values: dict, m: se.Matrix, k: float, close_open: bool):
    """A path's subpaths as :func:`_subpaths` gives them, or None when svgelements is to read its ``d``."""
    d = values.get("d")
    commands = _path_commands(d) if isinstance(d, str) else None
    if commands is None:
        return None
    kinds, pts = _path_segments(commands)
    xy = np.array(pts, float).reshape(-1, 2)
    px = np.empty_like(xy)
    with np.errstate(over="ignore", invalid="ignore"):  # a huge transform: inf, refused in one line later
        px[:, 0] = xy[:, 0] * m.a + xy[:, 1] * m.c + 1 * m.e
        px[:, 1] = xy[:, 0] * m.b + xy[:, 1] * m.d + 1 * m.f
        mm = px * k
    return _pieces_from(kinds, px, mm, close_open)


def _pieces_from(kinds: list[int], px: np.ndarray, mm: np.ndarray, close_open: bool):
    """:func:`_subpaths` on segments given as kinds and points (px, to compare as svgelements does; mm, kept)."""
    out: list[tuple[list[np.ndarray], bool]] = []
    segs: list[np.ndarray] = []

    def finish(closed: bool) -> None:
        nonlocal segs
        if segs:
            if close_open and not closed and np.any(segs[-1][-1] != segs[0][0]):
                segs.append(_checked(np.array([segs[-1][-1], segs[0][0]])))
                closed = True
            out.append((segs, closed or bool(np.all(segs[-1][-1] == segs[0][0]))))
        segs = []

    kind_of = np.array(kinds, np.int64)
    counts = np.where(kind_of == _MOVE, 1, np.where(kind_of == _CLOSE, 2, kind_of))
    cut = np.repeat(kind_of >= LINE, counts)  # the points of lines and curves, checked as _point does
    good = np.isfinite(mm).all(axis=1) & (np.abs(mm).max(axis=1, initial=0.0) <= 1e6)
    check = _checked if not good[cut].all() else (lambda pts: pts)
    at = 0
    for kind in kinds:
        if kind == _MOVE:
            finish(False)
            at += 1
            continue
        if kind == _CLOSE:
            (x0, y0), (x1, y1) = px[at], px[at + 1]
            if not (abs(x0 - x1) <= se.ERROR and abs(y0 - y1) <= se.ERROR):
                segs.append(_checked(mm[at:at + 2]))
            at += 2
            finish(True)
            continue
        segs.append(check(mm[at:at + kind]))
        at += kind
    finish(False)
    return out


def _checked(pts: np.ndarray) -> np.ndarray:
    """``pts`` (mm), or ValueError as :func:`_point` raises it."""
    if not (np.all(np.isfinite(pts)) and max(pts.max(initial=0.0), -pts.min(initial=0.0)) <= 1e6):
        raise ValueError("a coordinate is not a finite number within 1 km")
    return pts


def _svgelements_shape(tag: str, values: dict, viewport: tuple[float, float]):
    """The shape svgelements builds of an element with these values (rendered, its transform applied), or None
    where it drops it (as :meth:`svgelements.SVG.parse` does)."""
    element = None
    try:
        if tag == "path":
            element = se.Path(values, pathd_loaded=True)
            element.parse(values.get("d"))
        else:
            element = _SHAPE_CLASSES[tag](values)
    except ValueError:
        if element is None:
            return None
    element.render(ppi=96.0, width=viewport[0], height=viewport[1])
    element.reify()
    return None if element.is_degenerate() else element


_SHAPE_CLASSES = {"circle": se.Circle, "ellipse": se.Ellipse, "line": se.SimpleLine, "polyline": se.Polyline,
                  "polygon": se.Polygon, "rect": se.Rect}


def _quarter_turns() -> tuple[list[float], float, float]:
    """The parameters svgelements draws a circle with: ``t`` of the 5 quarter points (added up as it adds them),
    and the step and ``alpha`` of its 3 cubics a quarter (:meth:`svgelements.Arc.as_cubic_curves`)."""
    quarter = _TAU / 4
    t = [0.0]
    for _ in range(4):
        t.append(t[-1] + quarter)
    step = quarter / 3.0
    alpha = math.sin(step) * (math.sqrt(4 + 3 * pow(math.tan(step / 2.0), 2)) - 1) / 3.0
    return t, step, alpha


def _circles(params: list[tuple[float, float, float, float]], k: float) -> tuple[np.ndarray, np.ndarray]:
    """The 12 cubic Béziers (``(N, 12, 4, 2)`` mm) svgelements makes of each circle or ellipse ``(cx, cy, rx, ry)``
    (px, axis-aligned), and ``(N,)`` bool: its closing line is not of zero length (it then cuts it too)."""
    p = np.array(params, float).reshape(-1, 4)
    cx, cy, rx, ry = (p[:, i:i + 1] for i in range(4))
    quarters, step, alpha = _quarter_turns()
    t0 = np.array([quarters[q] + j * step for q in range(4) for j in range(3)])
    t1 = np.array([quarters[q] + (j + 1) * step for q in range(4) for j in range(3)])
    cos0, sin0 = np.array([math.cos(t) for t in t0]), np.array([math.sin(t) for t in t0])
    cos1, sin1 = np.array([math.cos(t) for t in t1]), np.array([math.sin(t) for t in t1])
    cq = np.array([math.cos(t) for t in quarters])
    sq = np.array([math.sin(t) for t in quarters])
    corner_x, corner_y = cx + rx * cq, cy + ry * sq  # the quarter points (N, 5)
    end_x, end_y = cx + rx * cos1, cy + ry * sin1
    end_x[:, 2::3], end_y[:, 2::3] = corner_x[:, 1:], corner_y[:, 1:]
    start_x = np.concatenate([corner_x[:, :1], end_x[:, :-1]], axis=1)
    start_y = np.concatenate([corner_y[:, :1], end_y[:, :-1]], axis=1)
    start_x[:, 0::3], start_y[:, 0::3] = corner_x[:, :4], corner_y[:, :4]
    out = np.empty((len(p), 12, 4, 2))
    out[:, :, 0, 0], out[:, :, 0, 1] = start_x, start_y
    out[:, :, 1, 0], out[:, :, 1, 1] = start_x + alpha * (-rx * sin0), start_y + alpha * (ry * cos0)
    out[:, :, 2, 0], out[:, :, 2, 1] = end_x - alpha * (-rx * sin1), end_y - alpha * (ry * cos1)
    out[:, :, 3, 0], out[:, :, 3, 1] = end_x, end_y
    gap = (np.abs(corner_x[:, 4] - corner_x[:, 0]) > se.ERROR) | (np.abs(corner_y[:, 4] - corner_y[:, 0]) > se.ERROR)
    out *= k
    return out, gap


def _parse_fast(root, source: str) -> SvgDrawing:
    """:func:`parse_svg` by the fast reader (raises :class:`_Unsupported` or any error for svgelements to read
    the document instead)."""
    k = MM_PER_PX
    walk = _Walk(k)
    walk.children(root, walk.root(root), None)
    with np.errstate(invalid="ignore", over="ignore"):  # a coordinate past 1 km is refused just below
        cubics, gaps = _circles(walk.circles, k)
    _checked(cubics)  # every control point is cut
    strokes: list[Stroke] = []
    closed: list[bool] = []
    counts: dict[str, int] = {}
    layer_paths: list[Optional[str]] = []
    colours: list[str] = []
    for name, pieces, layer, colour in walk.items:
        if isinstance(pieces, int):
            segs = cubics[pieces]  # one array of its 12 cubics (a stroke of one kind of segment)
            if gaps[pieces]:
                segs = list(segs) + [_checked(np.array([segs[-1][-1], segs[0][0]]))]
            pieces = [(segs, True)]
        if not pieces:
            continue
        counts[name] = counts.get(name, 0) + 1
        for segs, is_closed in pieces:
            strokes.append(segs)
            closed.append(is_closed)
            layer_paths.append(layer)
            colours.append(colour)
    w, h = walk.size
    size = (float(w) * k, float(h) * k) if w and h and math.isfinite(w) and math.isfinite(h) else (0.0, 0.0)
    return _drawing(strokes, closed, size, counts, [], source, layer_paths, colours)


def _drawing(strokes: list[Stroke], closed: list[bool], size: tuple[float, float], counts: dict[str, int],
             warnings: list[str], source: str, layer_paths: list[Optional[str]], colours: list[str]) -> SvgDrawing:
    """The drawing of the strokes read, with its layers (see the module docstring) and its size."""
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
