"""DXF in: the lines and curves of a DXF drawing as exact segments in mm, the same drawing SVG's reader gives.

Read with :mod:`ezdxf` (ASCII DXF R12 to 2018 as LibreCAD, QCAD, FreeCAD,
Inkscape and Fusion 360 write them, and binary DXF).  The model space is
cut, entity by entity, into the strokes of a :class:`DxfDrawing`, an
:class:`~cam.formats.svg.SvgDrawing` with the file's units and version: the
SVG planner (:func:`cam.job.svg.plan_svg`) cuts it, layers and all.

* LINE, ARC, CIRCLE, ELLIPSE, LWPOLYLINE and 2D POLYLINE (bulges as arcs; a
  spline-fit POLYLINE along its fit vertices, not its frame), a 3D POLYLINE that
  lies at one height, SPLINE: one stroke each (a polyline's pieces joined).  Arcs and ellipses are cubic Béziers of at most 1/16 turn
  (:data:`ARC_PIECES_PER_TURN`: within 7e-8 of the radius, 0.07 µm at 1 m); a
  cubic, non-rational, clamped SPLINE (most of them) is its exact Bézier pieces;
  any other (rational, other degrees, periodic) is flattened within
  :data:`SPLINE_TOLERANCE_MM` of the exact B-spline by ezdxf.
* INSERT (and MINSERT arrays) of blocks, nested: each block's entities
  placed by the insert's position, scale, rotation and extrusion (ezdxf's
  virtual entities); an entity on layer ``0`` of a block takes the layer of
  the insert that places it (as CAD programs draw it).  The entities a file
  expands to are counted before anything is expanded and at most
  :data:`MAX_DXF_ENTITIES` are read (blocks of blocks can fan out to millions).
* Not cut, one warning line each, naming the kind and how many: TEXT, MTEXT,
  ATTRIB (a font is no line), HATCH, SOLID, TRACE (fills), DIMENSION, LEADER
  and other annotations, IMAGE and underlays, POINT, XLINE and RAY (no ends), 3D
  entities (3DFACE, 3DSOLID, MESH, polyface and polygon meshes, curves in a plane
  other than XY) and anything else; entities marked invisible and those on a layer
  that is off or frozen (one line).  A file with nothing left to cut is refused,
  naming what it held.

Units: ``$INSUNITS`` (inch, foot, mm, cm, m, ...: :data:`INSUNITS`); when it is
0 (unitless) or absent (DXF R12 has none), ``$MEASUREMENT`` (0 inch, 1 mm);
when neither says, mm, with a warning.

Layers: every stroke belongs to the DXF layer of its entity (``layers_from``
"dxf"), listed in file order (the order their first strokes come in); a layer
is selected by its name, whatever its case (DXF layer names are not case
sensitive).

Frame: mm, x to the right, y *down*: the DXF's y negated, so that the drawing
is cut as it looks in the CAD program (SVG's frame: the machine's y grows
toward the operator), and the DXF's origin is the page origin that
``--offset`` places.

Bad input is one :class:`~cam.errors.ParseError` line naming the file (and the
line, or the entity's handle, where ezdxf or the entity tells): not a DXF file,
binary garbage, a truncated file, a number that is not one, a coordinate beyond
:data:`~cam.limits.MAX_COORD_MM`, a block that inserts itself, a file larger than
:data:`MAX_DXF_BYTES`.

>>> import ezdxf, io
>>> doc = ezdxf.new("R2000"); doc.units = 4   # mm
>>> _ = doc.modelspace().add_lwpolyline([(0, 0, 0), (10, 0, 1), (10, 10, 0)], format="xyb", dxfattribs={"layer": "CUT"})
>>> text = io.StringIO(); doc.write(text)
>>> d = parse_dxf(text.getvalue().encode(), source="part.dxf")
>>> d.n_strokes, d.layers(), d.units, d.element_counts
(1, ['CUT'], 'mm', {'lwpolyline': 1})
>>> [round(v, 6) + 0.0 for v in d.extent_mm()]   # the bulge (a half circle) reaches x 15; y down: y 0..10 is -10..0
[0.0, -10.0, 15.0, 0.0]
"""
from __future__ import annotations

import codecs
import io
import logging
import math
import os
from dataclasses import dataclass, field
from typing import Any, Iterable, Optional, Union

import numpy as np

from ..errors import ParseError
from ..fileio import read_bytes
from ..limits import MAX_COORD_MM
from .svg import LINE, Stroke, SvgDrawing

__all__ = ["DxfDrawing", "parse_dxf", "load_dxf", "MAX_DXF_BYTES", "MAX_DXF_ENTITIES", "INSUNITS",
           "ARC_PIECES_PER_TURN", "SPLINE_TOLERANCE_MM"]

MAX_DXF_BYTES = 64 * 1024 * 1024
"""Larger DXF files are refused before they are parsed (ezdxf holds about ten times a file's size)."""
MAX_DXF_ENTITIES = 200_000
"""Entities a DXF may hold once its block inserts are expanded (counted before anything is expanded)."""
MAX_BLOCK_DEPTH = 64
"""Blocks may insert blocks this deep at most."""
ARC_PIECES_PER_TURN = 16
"""Arcs and ellipses are cubic Béziers of at most 1/16 turn each: within 6.7e-8 of the radius of the arc."""
SPLINE_TOLERANCE_MM = 0.0005
"""A spline that is not exactly a chain of cubic Béziers is flattened within this many mm of its exact curve."""
_FLAT_Z = 1e-6
"""A curve whose points' heights differ by more than this (the file's units) is 3D."""

BINARY_SENTINEL = b"AutoCAD Binary DXF\r\n\x1a\x00"

logging.getLogger("ezdxf").addHandler(logging.NullHandler())
"""ezdxf logs what it repairs as warnings; without a handler Python would print them on stderr, past the one line
a command prints (an application that configures logging still gets them)."""

INSUNITS = {
    1: ("inch", 25.4), 2: ("foot", 304.8), 3: ("mile", 1_609_344.0), 4: ("mm", 1.0), 5: ("cm", 10.0),
    6: ("m", 1000.0), 7: ("km", 1e6), 8: ("microinch", 25.4e-6), 9: ("mil", 0.0254), 10: ("yard", 914.4),
    11: ("angstrom", 1e-7), 12: ("nanometre", 1e-6), 13: ("micron", 1e-3), 14: ("decimetre", 100.0),
    15: ("decametre", 10_000.0), 16: ("hectometre", 100_000.0), 17: ("gigametre", 1e12),
    18: ("astronomical unit", 1.495978707e14), 19: ("light year", 9.4607304725808e18), 20: ("parsec", 3.0856776e19),
    21: ("US survey foot", 1200.0 / 3937.0 * 1000.0), 22: ("US survey inch", 1000.0 / 39.37),
    23: ("US survey yard", 3600.0 / 3937.0 * 1000.0), 24: ("US survey mile", 6336.0 / 3937.0 * 1_000_000.0),
}
"""``$INSUNITS`` codes: (name, mm per unit); 0 is unitless."""

_CUT = frozenset({"LINE", "ARC", "CIRCLE", "ELLIPSE", "LWPOLYLINE", "POLYLINE", "SPLINE"})
_WHY = {
    "text": "cam cannot cut a font (explode the text into lines and curves in the CAD program)",
    "fill": "a fill: only lines and curves are cut (draw its outline as lines to cut it)",
    "annotation": "an annotation, not part of what is cut",
    "image": "a picture: only lines and curves are cut",
    "point": "a point has no length to cut",
    "infinite": "a construction line without ends",
    "3d": "a 3D entity: cam cuts the 2D drawing in the XY plane",
}
_SKIPPED = {
    **dict.fromkeys(("TEXT", "MTEXT", "ATTRIB", "ATTDEF", "SHAPE"), "text"),
    **dict.fromkeys(("HATCH", "MPOLYGON", "SOLID", "TRACE"), "fill"),
    **dict.fromkeys(("DIMENSION", "ARC_DIMENSION", "LARGE_RADIAL_DIMENSION", "LEADER", "MULTILEADER", "MLEADER",
                     "TOLERANCE", "ACAD_TABLE"), "annotation"),
    **dict.fromkeys(("IMAGE", "WIPEOUT", "PDFUNDERLAY", "DWFUNDERLAY", "DGNUNDERLAY", "OLE2FRAME", "OLEFRAME"),
                    "image"),
    "POINT": "point", "XLINE": "infinite", "RAY": "infinite",
    **dict.fromkeys(("3DFACE", "3DSOLID", "BODY", "REGION", "SURFACE", "EXTRUDEDSURFACE", "LOFTEDSURFACE",
                     "REVOLVEDSURFACE", "SWEPTSURFACE", "PLANESURFACE", "MESH", "HELIX"), "3d"),
}
"""Entity kinds that are not cut, and why (:data:`_WHY`)."""
_SILENT = frozenset({"VIEWPORT", "SEQEND", "VERTEX"})
"""Entities that are no drawing of their own."""


@dataclass
class DxfDrawing(SvgDrawing):
    """The strokes of a DXF file (see the module docstring for the frame), as an
    :class:`~cam.formats.svg.SvgDrawing` (its strokes, closed flags, layers, warnings) with the file's units.

    Attributes:
        units: the unit the file's numbers are in (``mm``, ``inch``, ...).
        mm_per_unit: mm per unit of the file.
        units_from: what said so: ``$INSUNITS``, ``$MEASUREMENT`` or ``default`` (neither).
        dxf_version: the file's ``$ACADVER`` (``AC1009`` is R12, ``AC1015`` R2000, ``AC1032`` R2018).
        skipped: ``{entity kind: count}`` of the entities not cut (each also one line of ``warnings``).
    """

    units: str = "mm"
    mm_per_unit: float = 1.0
    units_from: str = "default"
    dxf_version: str = ""
    skipped: dict[str, int] = field(default_factory=dict)

    def find_layers(self, name: str) -> list[int]:
        """The index of the layer called ``name``, whatever its case (DXF layer names are not case sensitive):
        ``[i]``, or empty."""
        want = name.strip().casefold()
        return [i for i, n in enumerate(self.layers()) if n.casefold() == want]


def _bad(source: str, what: str) -> ParseError:
    return ParseError(f"{source}: {what}")


def _looks_like_dxf(raw: bytes) -> bool:
    """Whether an ASCII file starts as a DXF does: group code 0 (or a 999 comment) on its first line."""
    for line in raw[:4096].splitlines():
        word = line.strip()
        if word:
            return word in (b"0", b"999")
    return False


def _read_document(raw: bytes, source: str) -> Any:
    """The ezdxf document of a DXF file's bytes (ASCII in its own encoding, or binary).

    Raises:
        ParseError: not a DXF file, truncated or damaged (naming the line where ezdxf tells it).
    """
    import ezdxf
    from ezdxf.document import Drawing
    from ezdxf.filemanagement import dxf_stream_info
    from ezdxf.lldxf.tagger import binary_tags_loader

    if raw.startswith(BINARY_SENTINEL):
        try:
            return Drawing.load(binary_tags_loader(raw, errors="surrogateescape"))
        except MemoryError:
            raise
        except Exception as exc:  # ezdxf's structure errors, and what a damaged binary stream raises (struct, index)
            raise _bad(source, f"not a readable binary DXF file ({_first_line(exc)})") from None
    if b"\0" in raw[:4096]:
        raise _bad(source, "not a DXF file (binary data; a binary DXF starts with 'AutoCAD Binary DXF')")
    if not _looks_like_dxf(raw):
        line = next((ln.strip() for ln in raw[:4096].splitlines() if ln.strip()), b"")
        shown = line[:40].decode("latin-1")
        raise _bad(source, "not a DXF file (it does not start with group code 0" + (f": line 1 is '{shown}')"
                                                                                      if shown else ": it is empty)"))
    try:  # R2007 and later: UTF-8; before, the header's $DWGCODEPAGE
        encoding = dxf_stream_info(io.StringIO(raw[:65536].decode("latin-1"))).encoding
        codecs.lookup(encoding)
    except MemoryError:
        raise
    except Exception:  # a header ezdxf cannot read, an unknown code page: the DXF default, and ezdxf says what is wrong
        encoding = "cp1252"
    text = raw.decode(encoding, errors="surrogateescape")
    try:
        return ezdxf.read(io.StringIO(text))
    except MemoryError:
        raise
    except Exception as exc:  # ezdxf's DXFStructureError, and ValueError of a bad number
        strict = _first_line(exc)
    raise _bad(source, _damage(raw, strict))


def _damage(raw: bytes, strict: str) -> str:
    """Why a DXF file cannot be read, with the line ezdxf's recovering reader finds when the strict one gave none."""
    from ezdxf import recover

    n_lines = raw.count(b"\n") + (not raw.endswith(b"\n"))
    why = strict
    if "line" not in strict:
        try:
            recover.read(io.BytesIO(raw))
        except MemoryError:
            raise
        except Exception as exc:  # it names the line
            why = _first_line(exc)
    if "ENDSEC" in why or "EOF" in why or "ENDTAB" in why or "ENDBLK" in why:
        return f"truncated or damaged DXF file ({why}; the file ends at line {n_lines})"
    return f"not a readable DXF file ({why})"


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return (text[0] if text else type(exc).__name__).removeprefix("DXFStructureError: ")


def _units(doc: Any, source: str) -> tuple[str, float, str, Optional[str]]:
    """``(unit name, mm per unit, what said so, warning)`` from the header's ``$INSUNITS`` and ``$MEASUREMENT``."""
    header = doc.header
    code = header.get("$INSUNITS", 0) if "$INSUNITS" in header else 0
    try:
        code = int(code)
    except (TypeError, ValueError):
        raise _bad(source, f"$INSUNITS is '{code}', not a unit code") from None
    if code:
        if code not in INSUNITS:
            raise _bad(source, f"$INSUNITS {code} is not a unit code (1 inch, 4 mm, ... 24)")
        name, mm = INSUNITS[code]
        return name, mm, "$INSUNITS", None
    if "$MEASUREMENT" in header:
        measurement = header.get("$MEASUREMENT")
        if measurement in (0, 1):
            return ("inch", 25.4, "$MEASUREMENT", None) if measurement == 0 else ("mm", 1.0, "$MEASUREMENT", None)
    return "mm", 1.0, "default", (f"{source}: the file does not say its units ($INSUNITS, $MEASUREMENT): read as mm "
                                  "(scale it with --scale 25.4 if it is in inches)")


def _repeats(insert: Any) -> int:
    """How many copies a (M)INSERT makes."""
    return max(1, int(insert.dxf.get("row_count", 1))) * max(1, int(insert.dxf.get("column_count", 1)))


def _expanded_count(doc: Any, source: str) -> int:
    """The entities the model space expands to, every insert of a block counted as its block's entities (and
    their inserts), without expanding any.

    Raises:
        ParseError: more than :data:`MAX_DXF_ENTITIES`, a block that inserts itself, blocks nested deeper than
        :data:`MAX_BLOCK_DEPTH`, an insert of a block the file does not define.
    """
    memo: dict[str, int] = {}
    cap = MAX_DXF_ENTITIES + 1

    def of_entities(entities: Iterable[Any], active: tuple[str, ...]) -> int:
        n = 0
        for e in entities:
            if e.dxftype() == "INSERT":
                n += _repeats(e) * (of_block(e, active) + len(e.attribs))
            else:
                n += 1
            if n >= cap:
                return cap
        return n

    def of_block(insert: Any, active: tuple[str, ...]) -> int:
        name = insert.dxf.name
        key = name.casefold()
        if key in memo:
            return memo[key]
        if key in active:
            raise _bad(source, f"block '{name}' inserts itself (INSERT #{insert.dxf.handle})")
        if len(active) >= MAX_BLOCK_DEPTH:
            raise _bad(source, f"blocks are nested more than {MAX_BLOCK_DEPTH} deep (block '{name}')")
        block = doc.blocks.get(name)
        if block is None:
            raise _bad(source, f"INSERT #{insert.dxf.handle} places block '{name}', which the file does not define")
        memo[key] = of_entities(block, active + (key,))
        return memo[key]

    total = of_entities(doc.modelspace(), ())
    if total > MAX_DXF_ENTITIES:
        raise _bad(source, f"its block inserts expand to more than {MAX_DXF_ENTITIES:,} entities; cam refuses it "
                           "before expanding them (explode fewer blocks, or split the drawing)")
    return total


class _Reader:
    """Walks the model space (and the blocks it inserts) into strokes in mm."""

    def __init__(self, doc: Any, source: str, mm_per_unit: float):
        self.doc = doc
        self.source = source
        self.k = mm_per_unit
        self.strokes: list[Stroke] = []
        self.closed: list[bool] = []
        self.layer_of: list[str] = []
        self.counts: dict[str, int] = {}
        self.skipped: dict[str, int] = {}
        self.hidden = 0
        self.hidden_layers: list[str] = []
        self.unplaced: list[str] = []
        self.layer_names: dict[str, str] = {}
        self.hidden_keys = set()
        for layer in doc.layers:
            name = layer.dxf.name
            self.layer_names[name.casefold()] = name
            if layer.is_off() or layer.is_frozen():
                self.hidden_keys.add(name.casefold())

    def walk(self, entities: Iterable[Any], insert_layer: Optional[str], where: str) -> None:
        """Read ``entities``; ``insert_layer``: the layer of the insert that placed them (None: the model space);
        ``where``: how a message names where they are (the insert's handle)."""
        for e in entities:
            kind = e.dxftype()
            layer = e.dxf.get("layer", "0")
            if insert_layer is not None and layer == "0":
                layer = insert_layer
            layer = self.layer_names.get(layer.casefold(), layer)
            if kind in _SILENT or (kind == "ATTDEF" and insert_layer is not None):
                continue  # a block's ATTDEF is a template: the insert's ATTRIBs are what shows
            if kind == "INSERT":
                self.insert(e, layer, where)
                continue
            if e.dxf.get("invisible", 0):
                continue
            if layer.casefold() in self.hidden_keys:
                self.hidden += 1
                if layer not in self.hidden_layers:
                    self.hidden_layers.append(layer)
                continue
            if kind not in _CUT or (kind == "POLYLINE" and (e.is_poly_face_mesh or e.is_polygon_mesh)):
                self.skip("POLYLINE mesh" if kind == "POLYLINE" else kind)
                continue
            self.entity(e, kind, layer, where)

    def skip(self, kind: str) -> None:
        self.skipped[kind] = self.skipped.get(kind, 0) + 1

    def insert(self, e: Any, layer: str, where: str) -> None:
        handle = e.dxf.handle or where
        for attrib in e.attribs:
            if not attrib.dxf.get("invisible", 0) and not attrib.is_invisible:
                self.skip("ATTRIB")
        copies = e.multi_insert() if _repeats(e) > 1 else [e]
        for copy in copies:
            def unplaced(entity: Any, reason: str) -> None:
                self.unplaced.append(f"{entity.dxftype()} of block '{e.dxf.name}' ({reason})")

            try:
                children = list(copy.virtual_entities(skipped_entity_callback=unplaced))
            except MemoryError:
                raise
            except Exception as exc:  # ezdxf: a transform it cannot apply, a missing block
                raise _bad(self.source, f"INSERT #{handle} of block '{e.dxf.name}' cannot be placed "
                                        f"({_first_line(exc)})") from None
            self.walk(children, layer, f"INSERT #{handle}")

    def entity(self, e: Any, kind: str, layer: str, where: str) -> None:
        from ezdxf import path as ezpath

        name = f"{kind} #{e.dxf.handle}" if e.dxf.handle else f"{kind} in {where}"
        try:
            if kind in ("ARC", "CIRCLE", "ELLIPSE", "LWPOLYLINE", "POLYLINE") and _tilted(e):
                self.skip(kind + " (3D)")
                return
            if kind == "SPLINE" and not _bezier_spline(e):
                tool = e.construction_tool()
                pts = np.array([tuple(v) for v in tool.flattening(SPLINE_TOLERANCE_MM / self.k, segments=4)], float)
                segs: list[tuple[list[int], np.ndarray]] = [([LINE] * (len(pts) - 1), pts)]
            else:
                p = _polyline_path(e) if kind == "POLYLINE" else ezpath.make_path(e, segments=_pieces(e, kind))
                segs = [_commands(sub) for sub in (p.sub_paths() if p.has_sub_paths else [p])]
        except MemoryError:
            raise
        except Exception as exc:  # ezdxf: degenerate or inconsistent data (a spline's knots, a polyline's vertices)
            raise _bad(self.source, f"{name} on layer '{layer}' cannot be read ({_first_line(exc)})") from None
        segs = [(kinds, pts) for kinds, pts in segs if kinds]
        if not segs:
            return  # a circle of radius 0, a polyline of one vertex: nothing to cut
        # a few reductions an entity (tens of thousands of entities): a NaN fails every comparison below
        pts = segs[0][1] if len(segs) == 1 else np.concatenate([p for _, p in segs])
        z_lo, z_hi = float(pts[:, 2].min()), float(pts[:, 2].max())
        if z_hi - z_lo > _FLAT_Z * max(1.0, abs(z_lo), abs(z_hi)):
            self.skip(kind + " (3D)")
            return
        if not float(np.abs(pts[:, :2]).max()) * self.k <= MAX_COORD_MM:
            xy = pts[:, :2] * self.k
            bad = xy[~(np.abs(xy) <= MAX_COORD_MM)][0]
            raise _bad(self.source, f"{name} on layer '{layer}': a coordinate {bad:g} mm lies beyond "
                                    f"{MAX_COORD_MM:g} mm of the origin")
        for kinds, pts in segs:
            xy = pts[:, :2] * (self.k, -self.k)
            (x0, y0), (x1, y1) = xy[0].tolist(), xy[-1].tolist()
            self.strokes.append(_stroke(kinds, xy))
            self.closed.append(len(xy) > 2 and abs(x0 - x1) <= 1e-9 and abs(y0 - y1) <= 1e-9)
            self.layer_of.append(layer)
        key = kind.lower()
        self.counts[key] = self.counts.get(key, 0) + 1


_FRAME_VERTEX = 16
"""A POLYLINE vertex that is a control point of a spline-fit polyline's frame (AutoCAD's PEDIT Spline; R12 files):
not on the curve, which its fit vertices draw."""


def _polyline_path(e: Any) -> Any:
    """The ezdxf path of a POLYLINE: ezdxf's own, but without the frame control points of a spline-fit one."""
    from ezdxf import path as ezpath
    from ezdxf.math import Vec3

    segments = _pieces(e, "POLYLINE")
    drawn = [v for v in e.vertices if not v.dxf.get("flags", 0) & _FRAME_VERTEX]
    if len(drawn) == len(e.vertices):
        return ezpath.make_path(e, segments=segments)
    if e.is_3d_polyline:
        return ezpath.from_vertices([v.dxf.location for v in drawn], close=e.is_closed)
    p = ezpath.Path()
    if drawn:
        ezpath.add_2d_polyline(p, [v.format("xyb") for v in drawn], close=e.is_closed, ocs=e.ocs(),
                               elevation=Vec3(e.dxf.get("elevation", (0, 0, 0))).z, segments=segments)
    return p


def _tilted(e: Any) -> bool:
    """Whether a planar entity's plane is not parallel to XY (its extrusion is not +Z or -Z)."""
    if not e.dxf.hasattr("extrusion"):
        return False
    ez = e.dxf.extrusion
    return abs(abs(float(ez[2])) - 1.0) > 1e-9


def _bezier_spline(e: Any) -> bool:
    """Whether ezdxf turns the spline into cubic Béziers exactly (cubic, non-rational, clamped)."""
    try:
        tool = e.construction_tool()
    except MemoryError:
        raise
    except Exception:
        return False
    return tool.degree == 3 and not tool.is_rational and tool.is_clamped


def _pieces(e: Any, kind: str) -> int:
    """The ``segments`` ezdxf's make_path is given, so that its Bézier pieces span at most 1/16 turn
    (:data:`ARC_PIECES_PER_TURN`): an arc's or an ellipse's pieces; a polyline's bulge arcs are each cut into
    ``ceil(segments / 3)`` arcs, of as many pieces as their quarter turns, so it is three times the pieces of its
    widest bulge (a bulge is the tangent of a quarter of its arc's angle)."""
    if kind in ("LWPOLYLINE", "POLYLINE"):
        bulges = [b for *_, b in e.get_points("xyb")] if kind == "LWPOLYLINE" else \
            [v.dxf.get("bulge", 0.0) for v in e.vertices]
        widest = max((4.0 * math.atan(abs(float(b))) for b in bulges), default=0.0)
        return 3 * max(1, math.ceil(ARC_PIECES_PER_TURN * widest / math.tau))
    if kind == "ARC":
        span = (float(e.dxf.end_angle) - float(e.dxf.start_angle)) % 360.0 or 360.0
        return max(1, math.ceil(ARC_PIECES_PER_TURN * span / 360.0))
    if kind == "ELLIPSE":
        span = (float(e.dxf.end_param) - float(e.dxf.start_param)) % math.tau or math.tau
        return max(1, math.ceil(ARC_PIECES_PER_TURN * span / math.tau))
    return ARC_PIECES_PER_TURN


_ARITY = {1: 1, 2: 2, 3: 3}
"""ezdxf path command code (LINE_TO, CURVE3_TO, CURVE4_TO) -> the control vertices it adds."""


def _commands(p: Any) -> tuple[list[int], np.ndarray]:
    """A path without sub-paths as its segments' kinds (:data:`~cam.formats.svg.LINE`, ``QUADRATIC``, ``CUBIC``) and
    its ``(V, 3)`` control vertices (the start first)."""
    codes = [int(c) for c in p.command_codes()]
    if any(c not in _ARITY for c in codes):
        raise ValueError("a path command ezdxf gave is not a line or a Bézier curve")
    pts = np.array([(v.x, v.y, v.z) for v in p.control_vertices()], float)
    return [_ARITY[c] + 1 for c in codes], pts


def _stroke(kinds: list[int], xy: np.ndarray) -> Stroke:
    """The segments of one path: one ``(n, k, 2)`` array when all are of one kind, else a list of ``(k, 2)`` arrays."""
    if all(k == kinds[0] for k in kinds):
        k = kinds[0]
        idx = np.arange(len(kinds))[:, None] * (k - 1) + np.arange(k)[None, :]
        return xy[idx]
    out = []
    at = 0
    for k in kinds:
        out.append(xy[at:at + k].copy())
        at += k - 1
    return out


def parse_dxf(data: Union[bytes, str], *, source: str = "<dxf>") -> DxfDrawing:
    """Read a DXF document (its bytes, or its text) into a :class:`DxfDrawing` in mm (see the module docstring).

    Raises:
        ParseError: not a DXF file, truncated or damaged, a bad entity (naming its handle), too many entities,
        nothing to cut (naming what was skipped).
    """
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    doc = _read_document(raw, source)
    units, k, units_from, unit_warning = _units(doc, source)
    _expanded_count(doc, source)
    reader = _Reader(doc, source, k)
    reader.walk(doc.modelspace(), None, "the model space")
    warnings = [] if unit_warning is None else [unit_warning]
    for kind, n in reader.skipped.items():
        base = kind.split(" ")[0]
        why = _WHY["3d"] if kind.endswith("(3D)") or kind == "POLYLINE mesh" else _WHY.get(_SKIPPED.get(base, ""),
                                                                                           "not a kind cam cuts")
        warnings.append(f"{n} {kind} skipped: {why}")
    if reader.hidden:
        listed = ", ".join(f"'{n}'" for n in reader.hidden_layers)
        warnings.append(f"{reader.hidden} entities on layers that are off or frozen ({listed}) skipped")
    if reader.unplaced:
        warnings.append(f"{len(reader.unplaced)} block entities could not be placed by their insert's scale and "
                        f"skipped: {reader.unplaced[0]}" + (" ..." if len(reader.unplaced) > 1 else ""))
    if not reader.strokes:
        held = ", ".join(f"{n} {kind}" for kind, n in reader.skipped.items())
        if reader.hidden:
            held += (", " if held else "") + f"{reader.hidden} on layers that are off or frozen"
        raise _bad(source, "nothing to cut: " + (f"it holds only what cam does not cut ({held})" if held else
                                                 "its model space holds no lines or curves"))
    names = list(dict.fromkeys(reader.layer_of))
    index = {name: i for i, name in enumerate(names)}
    drawing = DxfDrawing(strokes=reader.strokes, closed=np.array(reader.closed, bool), element_counts=reader.counts,
                         warnings=warnings, source=source, layer_names=names,
                         stroke_layer=np.array([index[n] for n in reader.layer_of], np.int64), layers_from="dxf",
                         units=units, mm_per_unit=k, units_from=units_from, dxf_version=str(doc.dxfversion),
                         skipped=dict(reader.skipped))
    x0, y0, x1, y1 = drawing.extent_mm()
    drawing.size_mm = (x1 - x0, y1 - y0)
    return drawing


def load_dxf(path: Union[str, os.PathLike]) -> DxfDrawing:
    """Read a DXF file (see :func:`parse_dxf`).

    Raises:
        ParseError: missing or unreadable file, larger than :data:`MAX_DXF_BYTES`, or bad content.
    """
    p, data = read_bytes(path, max_bytes=MAX_DXF_BYTES, what="a DXF file")
    return parse_dxf(data, source=p.name)
