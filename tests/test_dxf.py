"""DXF in (issue #48 point 2): the reader, its units and layers, what it skips, bad input, and the cut.

The fixtures are DXF files made here with ezdxf in the habits of the programs that write them: Inkscape's
"Desktop Cutting Plotter" R12 export (old-style POLYLINE, no units, a 999 comment first), LibreCAD and QCAD
(R2000+ LWPOLYLINE with bulges, arcs drawn clockwise with extrusion -Z, text, hatches, dimensions), FreeCAD
(R2013 splines from control points, elliptical arcs, a flat 3D polyline), Fusion 360 (R2018 in inches, rational
and quadratic splines) and blocks (INSERT with scale and rotation, nested, MINSERT arrays, entities on layer 0
taking the insert's layer).

The cut check runs each file's job on the mock port, decodes the pin log into motion and compares every cut
position with ezdxf's own flattening of the same file (``flattening`` of each line, arc, circle, ellipse and
spline, a polyline's through its virtual lines and arcs, blocks through ezdxf's virtual entities), piece by
piece: every point of each flattened entity within one step of a cut position, every cut position within one
step of a flattened entity.
"""
import io
import json
import math

import ezdxf
import numpy as np
import pytest
from scipy.spatial import cKDTree

import cam
from cam.errors import ParseError, PlanError
from cam.formats.dxf import load_dxf, parse_dxf
from cam.kinds.jobs import JobOptions, prepare_job
from cam.job.svg import plan_svg
from cam.verify.pinlog import decode_pin_log, read_pin_log

from conftest import SAMPLES, one_line_error, run_cli

S = cam.MachineSettings()
MM = S.mm_per_step_xy
OFFSET_MM = (5.0, 70.0)
"""Where the fixtures' DXF origin goes (machine mm from the home): their y up is the machine's -y."""


# -- fixtures in each program's habits -------------------------------------------------------------------------

def _text(doc) -> bytes:
    out = io.StringIO()
    doc.write(out)
    return out.getvalue().encode(doc.output_encoding, errors="replace")


def inkscape_r12() -> bytes:
    """Inkscape's Desktop Cutting Plotter export: R12, no $INSUNITS (R12 has none), every path flattened into an
    old-style POLYLINE (VERTEX ... SEQEND) on the Inkscape layer's name, a comment first."""
    doc = ezdxf.new("R12")
    doc.layers.add("Layer 1")
    doc.layers.add("cuts")
    msp = doc.modelspace()
    star = [(20 + 15 * math.cos(a) * (1 if i % 2 == 0 else 0.45), 25 + 15 * math.sin(a) * (1 if i % 2 == 0 else 0.45))
            for i, a in enumerate(np.linspace(math.pi / 2, math.pi / 2 + 2 * math.pi, 11)[:-1])]
    msp.add_polyline2d(star, close=True, dxfattribs={"layer": "Layer 1"})
    msp.add_polyline2d([(40, 5), (60, 5), (60, 20), (40, 20)], close=True, dxfattribs={"layer": "cuts"})
    msp.add_polyline2d([(40, 30), (50, 40), (60, 30)], dxfattribs={"layer": "cuts"})
    return b"999\nDXF R12 Output by Inkscape (Desktop Cutting Plotter)\n" + _text(doc)


def librecad_r2000() -> bytes:
    """LibreCAD / QCAD: R2000, $INSUNITS 4 (mm), LWPOLYLINE with bulges (a rounded rectangle, a slot), a circle,
    an arc drawn clockwise (extrusion -Z, as QCAD writes a mirrored arc), text, a hatch and a dimension."""
    doc = ezdxf.new("R2000", setup=True)
    doc.units = 4
    for name in ("Outline", "Holes", "Notes"):
        doc.layers.add(name)
    msp = doc.modelspace()
    b = math.tan(math.radians(90) / 4)  # a quarter circle's bulge
    msp.add_lwpolyline([(3, 0, 0), (47, 0, b), (50, 3, 0), (50, 27, b), (47, 30, 0), (3, 30, b), (0, 27, 0),
                        (0, 3, b)], format="xyb", close=True, dxfattribs={"layer": "Outline"})
    msp.add_lwpolyline([(15, 12, 0), (30, 12, 1), (30, 18, 0), (15, 18, 1)], format="xyb", close=True,
                       dxfattribs={"layer": "Outline"})
    msp.add_circle((8, 22), 2.5, dxfattribs={"layer": "Holes"})
    msp.add_arc((-40, 8), 4, 200, 340, dxfattribs={"layer": "Holes", "extrusion": (0, 0, -1)})  # centre x 40 in WCS
    msp.add_text("PART 7", dxfattribs={"layer": "Notes", "height": 2.5}).set_placement((5, 33))
    msp.add_mtext("made in\\PLibreCAD", dxfattribs={"layer": "Notes"})
    hatch = msp.add_hatch(color=2, dxfattribs={"layer": "Notes"})
    hatch.paths.add_polyline_path([(36, 20), (44, 20), (44, 26), (36, 26)], is_closed=True)
    msp.add_linear_dim(base=(0, -5), p1=(0, 0), p2=(50, 0), dxfattribs={"layer": "Notes"}).render()
    return _text(doc)


def freecad_r2013() -> bytes:
    """FreeCAD: R2013, mm, a cubic SPLINE from control points (clamped knots), a degree-5 spline, an elliptical arc,
    a 3D POLYLINE that lies flat."""
    doc = ezdxf.new("R2013")
    doc.units = 4
    msp = doc.modelspace()
    msp.add_open_spline([(0, 0), (10, 20), (20, -5), (30, 15), (40, 0), (45, 10)], degree=3)
    msp.add_open_spline([(0, 30), (8, 40), (16, 25), (24, 42), (32, 28), (40, 38), (48, 30)], degree=5)
    msp.add_ellipse((25, 10), major_axis=(12, 4), ratio=0.5, start_param=0.3, end_param=4.5)
    msp.add_polyline3d([(5, 50, 2), (20, 55, 2), (35, 50, 2)])
    return _text(doc)


def fusion_r2018() -> bytes:
    """Fusion 360: R2018 in inches ($INSUNITS 1), a rational (NURBS) spline, a quadratic spline, lines."""
    doc = ezdxf.new("R2018")
    doc.units = 1
    msp = doc.modelspace()
    msp.add_rational_spline([(0, 0), (0.5, 1), (1, 0), (1.5, 1), (2, 0)], weights=[1, 2, 0.5, 2, 1], degree=3)
    msp.add_open_spline([(0, 1.5), (0.7, 2.2), (1.4, 1.5), (2.0, 2.0)], degree=2)
    msp.add_line((0, -0.2), (2, -0.2))
    msp.add_circle((1, 1), 0.3)
    return _text(doc)


def blocks_r2010() -> bytes:
    """Blocks: a block of a circle (layer 0) and a line (its own layer) inserted scaled and rotated, a block
    that inserts it twice (nested), an insert scaled unevenly (its circle an ellipse), and a MINSERT array."""
    doc = ezdxf.new("R2010")
    doc.units = 4
    doc.layers.add("HOLES")
    doc.layers.add("MARKS")
    hole = doc.blocks.new("HOLE", base_point=(1, 0))
    hole.add_circle((1, 0), 2, dxfattribs={"layer": "0"})
    hole.add_line((1, 0), (5, 0), dxfattribs={"layer": "MARKS"})
    pair = doc.blocks.new("PAIR")
    pair.add_blockref("HOLE", (0, 0), dxfattribs={"layer": "0"})
    pair.add_blockref("HOLE", (10, 0), dxfattribs={"layer": "0", "rotation": 90})
    msp = doc.modelspace()
    msp.add_blockref("HOLE", (10, 10), dxfattribs={"layer": "HOLES", "xscale": 1.5, "yscale": 1.5, "rotation": 30})
    msp.add_blockref("PAIR", (20, 30), dxfattribs={"layer": "HOLES", "rotation": -45, "xscale": 0.8,
                                                   "yscale": 0.8})
    msp.add_blockref("HOLE", (45, 10), dxfattribs={"layer": "HOLES", "xscale": 2, "yscale": 1})
    grid = msp.add_blockref("HOLE", (5, 45), dxfattribs={"layer": "HOLES"})
    grid.grid(size=(2, 3), spacing=(6, 9))
    return _text(doc)


PROGRAMS = {"inkscape_r12": inkscape_r12, "librecad_r2000": librecad_r2000, "freecad_r2013": freecad_r2013,
            "fusion_r2018": fusion_r2018, "blocks_r2010": blocks_r2010}
"""Fixture name -> its DXF bytes."""


def write(tmp_path, name: str, data: bytes):
    path = tmp_path / name
    path.write_bytes(data)
    return path


# -- ezdxf's own flattening, the reference ----------------------------------------------------------------------

def _entities(entities, layer=None):
    """``(entity, layer)`` of everything drawn, the blocks' inserts expanded by ezdxf (an entity on layer 0 of a
    block on the insert's layer)."""
    for e in entities:
        own = e.dxf.get("layer", "0")
        here = layer if layer is not None and own == "0" else own
        if e.dxftype() == "INSERT":
            for copy in (e.multi_insert() if e.mcount > 1 else [e]):
                yield from _entities(copy.virtual_entities(), here)
        else:
            yield e, here


def ezdxf_flattening(data: bytes, mm_per_unit: float, layers=None, distance_mm: float = 0.1 * MM):
    """Every drawn line and curve of the file flattened by ezdxf, each piece ``(N, 2)`` machine mm (the DXF's
    origin at :data:`OFFSET_MM`, its y up the machine's -y); ``layers``: only those (names as written)."""
    doc = ezdxf.read(io.StringIO(data.decode("utf-8", errors="replace")))
    pieces = []
    d = distance_mm / mm_per_unit
    for e, layer in _entities(doc.modelspace()):
        if layers is not None and layer not in layers:
            continue
        kind = e.dxftype()
        if kind in ("LWPOLYLINE", "POLYLINE"):
            parts = list(e.virtual_entities())
        elif kind in ("LINE", "ARC", "CIRCLE", "ELLIPSE", "SPLINE"):
            parts = [e]
        else:
            continue
        for part in parts:
            if part.dxftype() == "LINE":
                pts = [part.dxf.start, part.dxf.end]
            else:
                pts = list(part.flattening(d))
            xy = np.array([(p.x, p.y) for p in pts], float) * mm_per_unit
            pieces.append(np.column_stack([OFFSET_MM[0] + xy[:, 0], OFFSET_MM[1] - xy[:, 1]]))
    return pieces


def _dense(poly: np.ndarray, spacing_mm: float) -> np.ndarray:
    """The polyline's points with more between them, at most ``spacing_mm`` apart."""
    out = [poly[:1]]
    for p, q in zip(poly[:-1], poly[1:]):
        n = max(1, math.ceil(float(np.hypot(*(q - p))) / spacing_mm))
        out.append(p + (q - p) * (np.arange(1, n + 1) / n)[:, None])
    return np.concatenate(out)


def cut_positions_mm(plan) -> np.ndarray:
    """Unique ``(K, 2)`` machine mm where the motion decoded from the mock's pin log is below the surface."""
    result = cam.run(plan)
    assert result.status == "finished"
    pos = decode_pin_log(result.pin_log(), S).position_steps
    assert tuple(pos[-1]) == (0, 0, 0)
    return np.unique(pos[pos[:, 2] > 0][:, :2], axis=0).astype(float) * MM


def assert_cuts_as_flattened(cut_mm: np.ndarray, pieces: list[np.ndarray]) -> None:
    """Each flattened piece, point by point, within one step of a cut position, and every cut position within one
    step of a piece."""
    assert len(cut_mm) and pieces
    tree = cKDTree(cut_mm)
    for i, piece in enumerate(pieces):
        d, _ = tree.query(_dense(piece, 0.05 * MM))
        assert d.max() <= MM * 1.0001, f"piece {i} (from {piece[0]} mm) lies {d.max() / MM:.3f} steps from the cut"
    exact = np.concatenate([_dense(p, 0.05 * MM) for p in pieces])
    d, _ = cKDTree(exact).query(cut_mm)
    assert d.max() <= MM * 1.0001, f"a cut at {cut_mm[np.argmax(d)]} mm lies {d.max() / MM:.3f} steps from the file"


# -- the cut ------------------------------------------------------------------------------------------------------

UNITS_MM = {"inkscape_r12": 1.0, "librecad_r2000": 1.0, "freecad_r2013": 1.0, "fusion_r2018": 25.4,
            "blocks_r2010": 1.0}


@pytest.mark.parametrize("program", list(PROGRAMS))
def test_dxf_cuts_as_ezdxf_flattens(tmp_path, program):
    """Each program's file, planned as ``cam drill`` plans it and cut on the mock, is where ezdxf's own flattening
    of the same file is, piece by piece, within one step."""
    data = PROGRAMS[program]()
    path = write(tmp_path, f"{program}.dxf", data)
    job = prepare_job(path, JobOptions(offset_mm=OFFSET_MM), S)
    assert job.kind == "dxf"
    cut = cut_positions_mm(job.plan)
    assert_cuts_as_flattened(cut, ezdxf_flattening(data, UNITS_MM[program]))


def test_the_check_sees_a_wrong_cut(tmp_path):
    """The comparison fails on a cut one step off in y (mirrored or shifted would be far worse)."""
    data = librecad_r2000()
    cut = cut_positions_mm(prepare_job(write(tmp_path, "a.dxf", data), JobOptions(offset_mm=OFFSET_MM), S).plan)
    with pytest.raises(AssertionError):
        assert_cuts_as_flattened(cut + [0.0, 1.5 * MM], ezdxf_flattening(data, 1.0))


def test_a_spline_fit_polyline_is_cut_along_its_fit_vertices_not_its_frame():
    """An R12 POLYLINE smoothed by AutoCAD's PEDIT Spline keeps its frame's control points as vertices too (flag
    16): they are not on the curve and are not cut (ezdxf's make_path would join them in)."""
    doc = ezdxf.new("R12")
    for version in ("2d", "3d"):
        add = doc.modelspace().add_polyline2d if version == "2d" else doc.modelspace().add_polyline3d
        line = add([(0, 0, 0), (10, 10, 0), (20, 0, 0)] if version == "3d" else [(0, 0), (10, 10), (20, 0)])
        line.dxf.flags |= 4  # spline-fit vertices added
        for v in line.vertices:
            v.dxf.flags |= 8  # made by the fit: on the curve
        line.append_vertices([(0, 20, 0), (10, 30, 0)], dxfattribs={"flags": 16 | (32 if version == "3d" else 0)})
    d = parse_dxf(_text(doc))
    assert [p.tolist() for p in d.polylines(0.01)] == [[[0, 0], [10, -10], [20, 0]]] * 2


def test_the_drawing_is_upright_and_the_dxf_origin_is_placed():
    """y up in the file is away from the operator (the machine's -y); --offset puts the DXF's 0,0 there."""
    doc = ezdxf.new("R2000")
    doc.units = 4
    doc.modelspace().add_line((0, 0), (0, 10))  # drawn upward from the origin
    d = parse_dxf(_text(doc))
    assert d.polylines(0.01)[0].tolist() == [[0.0, 0.0], [0.0, -10.0]]
    job = plan_svg(d, offset_mm=(20.0, 30.0), cut_depth_mm=0.5)
    cut = job.points_steps[job.target][:, :2] * MM
    assert np.allclose(cut.min(axis=0), (20.0, 20.0), atol=MM) and np.allclose(cut.max(axis=0), (20.0, 30.0), atol=MM)


def test_arcs_and_bulges_are_exact_to_a_fraction_of_a_micrometre():
    """A 500 mm circle, a bulge arc and a 1 degree arc keep their radius within 0.1 µm (Béziers of 1/16 turn)."""
    doc = ezdxf.new("R2000")
    doc.units = 4
    msp = doc.modelspace()
    msp.add_circle((0, 0), 500)
    msp.add_lwpolyline([(500, 0, 1), (-500, 0, 0)], format="xyb")  # a half circle of radius 500 about 0,0
    msp.add_arc((0, 0), 500, 10, 11)
    d = parse_dxf(_text(doc))
    for poly in d.polylines(1e-5):
        assert abs(np.hypot(*poly.T) - 500).max() < 1e-4


# -- units ------------------------------------------------------------------------------------------------------

def _line_doc(version: str = "R2000", insunits=None, measurement=None) -> bytes:
    doc = ezdxf.new(version)
    for key, value in (("$INSUNITS", insunits), ("$MEASUREMENT", measurement)):
        if key in doc.header:
            del doc.header[key]
        if value is not None:
            doc.header[key] = value
    doc.modelspace().add_line((0, 0), (2, 0))
    return _text(doc)


@pytest.mark.parametrize("insunits, measurement, unit, from_, length_mm", [
    (4, None, "mm", "$INSUNITS", 2.0),
    (1, 1, "inch", "$INSUNITS", 50.8),  # $INSUNITS wins over $MEASUREMENT
    (5, None, "cm", "$INSUNITS", 20.0),
    (6, None, "m", "$INSUNITS", 2000.0),
    (0, 0, "inch", "$MEASUREMENT", 50.8),  # unitless: $MEASUREMENT 0 is English
    (0, 1, "mm", "$MEASUREMENT", 2.0),
    (None, 0, "inch", "$MEASUREMENT", 50.8),
    (None, None, "mm", "default", 2.0),
])
def test_units_from_insunits_then_measurement(insunits, measurement, unit, from_, length_mm):
    d = parse_dxf(_line_doc(insunits=insunits, measurement=measurement), source="u.dxf")
    assert (d.units, d.units_from) == (unit, from_)
    assert d.layer_lengths_mm() == [pytest.approx(length_mm)]
    said = [w for w in d.warnings if "does not say its units" in w]
    assert len(said) == (from_ == "default")


def test_an_inch_file_cuts_25_4_times_larger_than_the_same_in_mm(tmp_path):
    sizes = {}
    for units in (1, 4):
        doc = ezdxf.new("R2013")
        doc.units = units
        doc.modelspace().add_lwpolyline([(0, 0), (1, 0), (1, 0.5), (0, 0.5)], close=True)
        job = prepare_job(write(tmp_path, f"u{units}.dxf", _text(doc)), None, S)
        sizes[units] = job.size_mm
    assert sizes[1] == pytest.approx((25.4, 12.7), abs=MM) and sizes[4] == pytest.approx((1.0, 0.5), abs=MM)


def test_r12_without_units_says_so_and_reads_mm():
    d = parse_dxf(inkscape_r12(), source="ink.dxf")
    assert d.dxf_version == "AC1009" and d.units == "mm" and d.units_from == "default"
    assert d.element_counts == {"polyline": 3} and d.layers() == ["Layer 1", "cuts"]
    assert d.warnings == ["ink.dxf: the file does not say its units ($INSUNITS, $MEASUREMENT): read as mm (scale it "
                          "with --scale 25.4 if it is in inches)"]


def test_a_unit_code_that_is_none_is_one_line():
    with pytest.raises(ParseError, match=r"^u\.dxf: \$INSUNITS 99 is not a unit code"):
        parse_dxf(_line_doc(insunits=99), source="u.dxf")


# -- layers -----------------------------------------------------------------------------------------------------

def test_layers_are_the_entities_layers_and_blocks_on_layer_0_take_the_inserts():
    d = parse_dxf(blocks_r2010(), source="b.dxf")
    assert d.layers_from == "dxf" and d.layers() == ["HOLES", "MARKS"]
    counts = np.bincount(d.layer_of_stroke).tolist()
    assert counts == [1 + 2 + 1 + 6, 1 + 2 + 1 + 6]  # every hole's circle (layer 0 -> HOLES) and line (MARKS)
    assert d.find_layers("holes") == [0] and d.find_layers("Marks") == [1] and d.find_layers("HOL") == []


@pytest.mark.parametrize("selection, layers", [("Holes", ["Holes"]), ("outline", ["Outline"]),
                                               ("Holes,Outline", ["Holes", "Outline"])])
def test_a_layers_selection_cuts_those_layers_only(tmp_path, selection, layers):
    data = librecad_r2000()
    job = prepare_job(write(tmp_path, "l.dxf", data), JobOptions(offset_mm=OFFSET_MM, layers=selection), S)
    assert_cuts_as_flattened(cut_positions_mm(job.plan), ezdxf_flattening(data, 1.0, layers=set(layers)))
    assert [layer["name"] for layer in job.report["layers"]] == ["Outline", "Holes"]


def test_an_unknown_layer_is_one_line_naming_the_layers(tmp_path):
    path = write(tmp_path, "l.dxf", librecad_r2000())
    with pytest.raises(PlanError, match=r"l\.dxf: no layer 'Notes'; the layers are 'Outline', 'Holes'"):
        prepare_job(path, JobOptions(layers="Notes"), S)
    r = run_cli("drill", path, "--layers", "nope")
    one_line_error(r, "l.dxf", "no layer 'nope'", "'Outline', 'Holes'")


def test_layers_that_are_off_or_frozen_are_not_cut():
    doc = ezdxf.new("R2000")
    doc.units = 4
    doc.layers.add("ON")
    doc.layers.add("OFF").off()
    doc.layers.add("FROZEN").freeze()
    msp = doc.modelspace()
    for i, layer in enumerate(("ON", "OFF", "FROZEN", "OFF")):
        msp.add_line((0, i), (10, i), dxfattribs={"layer": layer})
    msp.add_line((0, 9), (10, 9), dxfattribs={"layer": "ON", "invisible": 1})
    d = parse_dxf(_text(doc), source="h.dxf")
    assert d.layers() == ["ON"] and d.n_strokes == 1
    assert d.warnings == ["3 entities on layers that are off or frozen ('OFF', 'FROZEN') skipped"]


# -- what is skipped ----------------------------------------------------------------------------------------------

def test_text_hatches_dimensions_and_3d_are_skipped_with_one_line_each():
    doc = ezdxf.new("R2018", setup=True)
    doc.units = 4
    msp = doc.modelspace()
    msp.add_line((0, 0), (10, 0))
    msp.add_text("A")
    msp.add_text("B")
    msp.add_mtext("C")
    hatch = msp.add_hatch()
    hatch.paths.add_polyline_path([(0, 0), (1, 0), (1, 1)], is_closed=True)
    msp.add_linear_dim(base=(0, 5), p1=(0, 0), p2=(10, 0)).render()
    msp.add_3dface([(0, 0, 0), (1, 0, 1), (1, 1, 1)])
    msp.add_point((3, 3))
    msp.add_circle((0, 0, 0), 3, dxfattribs={"extrusion": (1, 0, 0)})  # in the YZ plane
    msp.add_line((0, 0, 0), (5, 5, 5))
    msp.add_polyface()
    d = parse_dxf(_text(doc), source="s.dxf")
    assert d.n_strokes == 1 and d.element_counts == {"line": 1}
    assert sorted(d.warnings) == sorted([
        "2 TEXT skipped: cam cannot cut a font (explode the text into lines and curves in the CAD program)",
        "1 MTEXT skipped: cam cannot cut a font (explode the text into lines and curves in the CAD program)",
        "1 HATCH skipped: a fill: only lines and curves are cut (draw its outline as lines to cut it)",
        "1 DIMENSION skipped: an annotation, not part of what is cut",
        "1 3DFACE skipped: a 3D entity: cam cuts the 2D drawing in the XY plane",
        "1 POINT skipped: a point has no length to cut",
        "1 CIRCLE (3D) skipped: a 3D entity: cam cuts the 2D drawing in the XY plane",
        "1 LINE (3D) skipped: a 3D entity: cam cuts the 2D drawing in the XY plane",
        "1 POLYLINE mesh skipped: a 3D entity: cam cuts the 2D drawing in the XY plane",
    ])
    assert d.skipped["TEXT"] == 2


def test_skipped_entities_are_job_warnings_and_cam_info_lines(tmp_path):
    path = write(tmp_path, "part.dxf", librecad_r2000())
    r = run_cli("info", path)
    assert r.returncode == 0, r.stderr
    assert "part.dxf: 4 strokes from 1 arc, 1 circle, 2 lwpolyline" in r.stdout  # the slot is one stroke
    assert "DXF AC1015, units mm (from $INSUNITS)" in r.stdout
    for line in ("warning: 1 TEXT skipped", "warning: 1 MTEXT skipped", "warning: 1 HATCH skipped",
                 "warning: 1 DIMENSION skipped", "'Outline': 2 strokes", "'Holes': 2 strokes"):
        assert line in r.stdout, (line, r.stdout)
    rep = json.loads(run_cli("info", path, "--json").stdout)
    assert rep["dxf"]["skipped"] == {"TEXT": 1, "MTEXT": 1, "HATCH": 1, "DIMENSION": 1}
    assert rep["layers_from"] == "dxf" and rep["dxf"]["units"] == "mm"


def test_only_text_is_refused_naming_what_it_held(tmp_path):
    doc = ezdxf.new("R2000")
    doc.modelspace().add_text("HELLO")
    doc.modelspace().add_point((1, 1))
    path = write(tmp_path, "t.dxf", _text(doc))
    with pytest.raises(ParseError, match=r"^t\.dxf: nothing to cut: it holds only what cam does not cut \(1 TEXT, "
                                         r"1 POINT\)$"):
        load_dxf(path)
    one_line_error(run_cli("drill", path), "t.dxf: nothing to cut", "1 TEXT")
    empty = write(tmp_path, "e.dxf", _text(ezdxf.new("R2000")))
    one_line_error(run_cli("info", empty), "e.dxf: nothing to cut: its model space holds no lines or curves")


# -- bad input ----------------------------------------------------------------------------------------------------

def _ok_bytes() -> bytes:
    doc = ezdxf.new("R2000")
    doc.units = 4
    doc.modelspace().add_line((0, 0), (10, 0))
    doc.modelspace().add_circle((5, 5), 3)
    return _text(doc)


@pytest.mark.parametrize("name, data, fragments", [
    ("text.dxf", b"hello world\nthis is not a drawing\n", ["text.dxf: not a DXF file", "'hello world'"]),
    ("empty.dxf", b"", ["empty.dxf: not a DXF file", "empty"]),
    ("noise.dxf", bytes(range(256)) * 8, ["noise.dxf: not a DXF file (binary data"]),
    ("half.dxf", _ok_bytes()[:len(_ok_bytes()) // 2], ["half.dxf: truncated or damaged DXF file", "ends at line"]),
    ("badnum.dxf", _ok_bytes().replace(b" 10\n0.0\n", b" 10\nabc\n", 1), ["badnum.dxf: not a readable DXF file",
                                                                          "line"]),
    ("badbin.dxf", b"AutoCAD Binary DXF\r\n\x1a\x00" + bytes(range(200)), ["badbin.dxf: not a readable binary DXF"]),
])
def test_bad_input_is_one_line_exit_2(tmp_path, name, data, fragments):
    path = write(tmp_path, name, data)
    with pytest.raises(ParseError) as err:
        load_dxf(path)
    assert "\n" not in str(err.value) and all(f in str(err.value) for f in fragments), str(err.value)
    for command in (("info", path), ("drill", path), ("preview", path, "-o", tmp_path / "p.png")):
        one_line_error(run_cli(*command), *fragments)


def test_a_bad_entity_is_named_by_its_handle():
    doc = ezdxf.new("R2000")
    doc.units = 4
    line = doc.modelspace().add_line((0, 0), (1e9, 0))  # 1000 km
    with pytest.raises(ParseError, match=rf"^far\.dxf: LINE #{line.dxf.handle} on layer '0': a coordinate 1e\+09 mm "
                                         r"lies beyond 1e\+06 mm"):
        parse_dxf(_text(doc), source="far.dxf")
    doc = ezdxf.new("R2000")
    spline = doc.modelspace().add_spline(dxfattribs={"layer": "CURVES"})
    spline.control_points = [(0, 0), (1, 1)]  # a cubic needs 4
    spline.knots = [0, 0, 1, 1]
    with pytest.raises(ParseError, match=rf"^bad\.dxf: SPLINE #{spline.dxf.handle} on layer 'CURVES' cannot be read "
                                         r"\(.*control points"):
        parse_dxf(_text(doc), source="bad.dxf")


def test_a_block_that_inserts_itself_and_a_block_bomb_are_refused_before_expanding():
    doc = ezdxf.new("R2000")
    loop = doc.blocks.new("LOOP")
    loop.add_line((0, 0), (1, 0))
    loop.add_blockref("LOOP", (1, 1))
    doc.modelspace().add_blockref("LOOP", (0, 0))
    with pytest.raises(ParseError, match=r"^loop\.dxf: block 'LOOP' inserts itself"):
        parse_dxf(_text(doc), source="loop.dxf")
    doc = ezdxf.new("R2000")
    doc.blocks.new("B0").add_line((0, 0), (1, 0))
    for level in range(1, 12):  # 4 ** 11 = 4 million lines
        block = doc.blocks.new(f"B{level}")
        for i in range(4):
            block.add_blockref(f"B{level - 1}", (i, 0))
    doc.modelspace().add_blockref("B11", (0, 0))
    with pytest.raises(ParseError, match=r"^bomb\.dxf: its block inserts expand to more than 200,000 entities"):
        parse_dxf(_text(doc), source="bomb.dxf")


def test_a_file_over_the_size_limit_is_refused_unread(tmp_path, monkeypatch):
    import cam.formats.dxf as dxf

    path = write(tmp_path, "big.dxf", _ok_bytes())
    monkeypatch.setattr(dxf, "MAX_DXF_BYTES", 1000)
    with pytest.raises(ParseError, match=r"big\.dxf: [\d,]+ bytes, more than a DXF file may be \(1,000\)"):
        dxf.load_dxf(path)


def test_binary_dxf_and_a_dxf_by_content_are_read(tmp_path):
    doc = ezdxf.new("R2000")
    doc.units = 4
    doc.modelspace().add_circle((5, 5), 3)
    binary = tmp_path / "bin.dxf"
    doc.saveas(binary, fmt="bin")
    assert binary.read_bytes().startswith(b"AutoCAD Binary DXF")
    assert load_dxf(binary).element_counts == {"circle": 1}
    from cam.kinds import job_kind

    txt = write(tmp_path, "drawing.txt", inkscape_r12())  # a generic suffix: the content says DXF
    assert job_kind(txt) == "dxf" and job_kind(binary) == "dxf"
    ok = run_cli("info", txt)
    assert ok.returncode == 0 and "3 strokes from 3 polyline" in ok.stdout, ok.stderr
    forced = write(tmp_path, "part.bin", _ok_bytes())
    assert run_cli("info", forced, "--kind", "dxf").returncode == 0


# -- the command line ----------------------------------------------------------------------------------------------

def test_cli_drill_cuts_what_the_library_cuts_and_info_preview_export_work(tmp_path):
    path = SAMPLES / "bracket.dxf"
    log = tmp_path / "job.csv"
    r = run_cli("drill", path, "--yes", "--pin-log", log, "--layers", "HOLES")
    assert r.returncode == 0, r.stderr
    cut = decode_pin_log(read_pin_log(log, part="job"), S).position_steps
    want = decode_pin_log(cam.run(prepare_job(path, JobOptions(layers="HOLES"), S).plan).pin_log(), S).position_steps
    assert np.array_equal(cut, want)
    plunges = np.flatnonzero((cut[1:, 2] > 0) & (cut[:-1, 2] == 0))
    assert len(plunges) == 8  # the HOLES layer: the four inserts' circles and arcs, nothing else
    info = run_cli("info", path)
    assert info.returncode == 0 and "3 layer(s), DXF layers" in info.stdout and "warning: 1 TEXT skipped" in info.stdout
    png = tmp_path / "p.png"
    assert run_cli("preview", path, "-o", png).returncode == 0 and png.read_bytes()[:4] == b"\x89PNG"
    ngc = tmp_path / "b.ngc"
    e = run_cli("export", path, "-o", ngc, "--layers", "HOLES")
    assert e.returncode == 0, e.stderr
    assert "G2" in ngc.read_text() or "G3" in ngc.read_text()  # the holes' circles, on the circle: fitted as arcs


def test_svg_only_options_apply_to_dxf_and_drawing_options_do_not(tmp_path):
    path = SAMPLES / "bracket.dxf"
    for flags in (["--scale", "2"], ["--fit", "40x40"], ["--pause-between-layers", "--yes"], ["--keep-duplicates"],
                  ["--origin", "upper-left"], ["--cut-depth", "0.2"], ["--tool", "v:60:0.1"]):
        r = run_cli("drill", path, *flags)
        assert r.returncode == 0, (flags, r.stderr)
    one_line_error(run_cli("drill", path, "--depth", "3"), "--depth does not apply", "a dxf file")


def test_pause_between_layers_names_the_dxf_layer(tmp_path):
    job = prepare_job(SAMPLES / "bracket.dxf", JobOptions(layers="engrave,holes", pause_between_layers=True), S)
    assert job.toolpath.pause_notes == ["layer 'HOLES': change the pen"]


# -- the page -------------------------------------------------------------------------------------------------------

def test_the_page_takes_dxf_with_its_layers(servers):
    """A DXF upload is a "dxf" job; the layers, scale and the "Read as" kind come from the page's form fields."""
    from test_web import FAST

    s = servers("dxf", settings=FAST, realtime=False)
    status, up = s.upload("bracket.dxf", (SAMPLES / "bracket.dxf").read_bytes())
    assert status == 200 and up["kind"] == "dxf", up
    status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {"layers": "holes", "scale": "0.5"}})
    assert status == 200 and planned["kind"] == "dxf", planned
    # the holes' extent: their 3.5 mm arcs' ends at 45 degrees, 10 - 3.5 sin 45 .. 70 + 3.5 sin 45 (and 10 .. 40), halved
    side = 3.5 * math.sin(math.radians(45))
    assert planned["size_mm"] == pytest.approx([(60 + 2 * side) / 2, (30 + 2 * side) / 2], abs=0.05)
    assert any("1 TEXT skipped" in w for w in planned["warnings"]), planned["warnings"]
    status, bad = s.call("POST", "/api/plan", {"job": up["job"], "options": {"layers": "nope"}})
    assert status == 400 and "no layer 'nope'" in str(bad)
    status, up = s.upload("part.txt", (SAMPLES / "bracket.dxf").read_bytes())
    status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {"kind": "dxf"}})
    assert status == 200 and planned["kind"] == "dxf", planned
    status, info = s.call("GET", "/api/config")
    assert status == 200 and info["accepted"]["dxf"] == [".dxf"]


from test_web import servers  # noqa: E402,F401  (the web server fixture)
