"""G-code as LinuxCNC runs it (#18): every construct, programs in the style of seven CAM post-processors and
LinuxCNC's own example programs, each run by ``rs274`` (the reference) and by `cam`, whose motion must stay
within half a step of rs274's canonical path; refused features are one line naming what and why."""
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

import cam
from cam.formats.gcode import ToolTable, load_gcode, load_tool_table, parse_gcode
from cam.job.gcode import plan_gcode
from cam.settings import MachineSettings, Travel
from support.lcnc import CanonMove, bezier_mm, canonical_polyline_mm, parse_canonical, mark_spline_ends, run_rs274

SLOW_CASES = {
    'test_post_processor_programs_follow_rs274[carbide_create]',
    'test_splines_follow_the_exact_curve_and_rs274_after_offsets[G21-1.0]'}
"""Cases run in the slow tier only (tests/conftest.py): the fast tier stays under 3 minutes."""

needs_rs274 = pytest.mark.skipif(
    shutil.which("rs274") is None and not os.environ.get("CI"), reason="rs274 (linuxcnc-uspace) not installed"
)

WIDE = MachineSettings(travel=Travel(-10**8, 10**8, -10**8, 10**8, -10**8, 10**8))
"""The thesis machine with a travel wide enough for any example program (the path is compared, not the reach)."""

# rs274's machine units are inches: its tool table and parameter file are written in inches, cam's in mm
TOOLS_IN = {1: 0.5, 2: -0.25, 3: 1.0, 102: 0.75}
HOME_G28_IN = (1.0, -2.0, 0.5)
HOME_G30_IN = (0.5, -0.5, 0.25)
RS274_DEFAULT_TOOLS_MM = ToolTable({1: 0.511 * 25.4, 2: 0.1 * 25.4, 3: 1.273 * 25.4},
                                   diameters_mm={1: 0.125 * 25.4, 2: 0.0625 * 25.4, 3: 0.201 * 25.4})
"""The tool table rs274 uses when given none (LinuxCNC's sample ``tool.tbl``: its lengths and the diameters G41/G42
take, in inches; here in mm)."""

SUBROUTINE = """o<square> sub (side, depth: a square pocket outline from where the tool stands)
#<side> = #1
G91 G1 Z[-#2] F100
G1 X#<side>
G1 Y#<side>
G1 X[-#<side>]
G1 Y[-#<side>]
G90
o<square> endsub [#<side> * 4]
M2
"""


def _positions_mm(job):
    """Every position the job's motors take (after each step period), in G-code mm (+Y up, +Z up)."""
    s = job.settings
    pts = job.points_steps.astype(np.int64)
    periods = job.periods.astype(np.int64)
    prev = np.vstack([np.zeros((1, 3), np.int64), pts[:-1]])
    keep = periods > 0
    prev, pts, periods = prev[keep], pts[keep], periods[keep]
    delta = (pts - prev) // periods[:, None]
    assert np.all(delta * periods[:, None] == pts - prev), "a run does not step the same way each period"
    seg = np.repeat(np.arange(len(pts)), periods)
    k = np.arange(len(seg)) - np.repeat(np.cumsum(periods) - periods, periods) + 1
    steps = prev[seg] + delta[seg] * k[:, None]
    return np.column_stack([steps[:, 0] * s.mm_per_step_xy, -steps[:, 1] * s.mm_per_step_xy,
                            -steps[:, 2] * s.mm_per_step_z])


def with_splines(path, canon, program, rs_args):
    """rs274's moves with each ``NURBS_FEED`` (printed without its points) made the exact Bezier curve.

    Its start is where rs274's move before it ends and its end is where rs274 says it is (its ``#<_x>``
    ``#<_y>`` ``#<_z>`` after the spline's line, :func:`~support.lcnc.mark_spline_ends`; every move of that run
    must be the same as in the first); only the inner control points, the start plus the line's I J (and the
    end plus P Q), are taken from cam's program, whose spline ends must be rs274's.
    """
    splines = [m for m in program.moves if m.kind == "spline"]
    assert sum(m.kind == "nurbs" for m in canon) == len(splines), f"{path}: not as many splines as rs274's"
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / Path(path).name
        copy.write_text(mark_spline_ends(Path(path).read_text()))
        marked = parse_canonical(run_rs274(str(copy), **rs_args))
    assert len(marked) == len(canon), f"{path}: the copy with spline ends marked moves differently"
    out, k = [], 0
    for mv, mark in zip(canon, marked):
        assert (mv.kind, mv.center, mv.rotation, mv.order) == (mark.kind, mark.center, mark.rotation, mark.order)
        if mv.kind != "nurbs":
            assert np.allclose(mv.end, mark.end, atol=1e-9), f"{path}: the marked copy moves differently"
            out.append(mv)
            continue
        spline = splines[k]
        k += 1
        assert mv.order == len(spline.controls) + 2
        assert np.allclose(spline.end, mark.end, atol=1e-4), f"{path}:{spline.line}: cam's spline ends elsewhere"
        out.append(CanonMove("spline", mark.end, controls=spline.controls))
    return out


def assert_follows_rs274(path, program, settings=WIDE):
    """cam's motion for ``program`` stays within half a step of rs274's canonical path for ``path``, and
    reaches every end point rs274 names within half a step; a spline's path is its exact curve
    (:func:`with_splines`)."""
    rs_args = {k: v for k, v in program.__dict__.get("_rs_args", {}).items()}
    canon_text = run_rs274(str(path), **rs_args)
    canon = parse_canonical(canon_text)
    if any(m.kind == "nurbs" for m in canon):
        canon = with_splines(path, canon, program, rs_args)
    step = np.array([settings.mm_per_step_xy, settings.mm_per_step_xy, settings.mm_per_step_z])
    job = plan_gcode(program, settings)
    got = _positions_mm(job) / step
    pts, _ = canonical_polyline_mm(canon, max_chord_mm=0.0005)
    if len(canon) == 0:
        assert len(got) == 0 or np.abs(got).max() <= 0.5
        return
    dense = [pts[:1] / step]
    for a, b in zip(pts[:-1] / step, pts[1:] / step):
        n = max(1, int(np.ceil(np.abs(b - a).max() / 0.02)))
        dense.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    dist, _ = cKDTree(np.vstack(dense)).query(got, p=np.inf)
    # rs274 prints 4 decimals: 0.00005 in is 0.044 step in X/Y and 0.081 step in Z
    slack = 0.09 if any("INCHES" in line for line in canon_text.splitlines()) else 0.03
    assert dist.max() <= 0.5 + slack, f"{path}: cam's motion strays {dist.max():.3f} steps from rs274's path"
    ends = np.array([m.end for m in canon]) / step
    d_end, _ = cKDTree(np.vstack([np.zeros((1, 3)), got])).query(ends, p=np.inf)
    assert d_end.max() <= 0.5 + slack, f"{path}: rs274's end point {ends[int(np.argmax(d_end))] * step} not reached"


def run_both(tmp_path, name, text, *, with_tables=True, **cam_options):
    """Write ``text``, run rs274 (with inch tool table, parameters and the subroutine folder) and cam on it."""
    path = tmp_path / f"{name}.ngc"
    path.write_text(text)
    subs = tmp_path / "subs"
    subs.mkdir(exist_ok=True)
    (subs / "square.ngc").write_text(SUBROUTINE)
    rs_args = {}
    options = dict(cam_options)
    if with_tables:
        (tmp_path / "tools.tbl").write_text("".join(f"T{t} P{t} Z{z} D0.125 ;tool {t}\n" for t, z in TOOLS_IN.items()))
        (tmp_path / "tools_mm.tbl").write_text("".join(f"T{t} P{t} Z{z * 25.4}\n" for t, z in TOOLS_IN.items()))
        var = tmp_path / f"{name}.var"
        var.write_text("".join(f"{5161 + i}\t{v}\n" for i, v in enumerate(HOME_G28_IN))
                       + "".join(f"{5181 + i}\t{v}\n" for i, v in enumerate(HOME_G30_IN)))
        ini = tmp_path / "rs274.ini"
        ini.write_text(f"[RS274NGC]\nSUBROUTINE_PATH = {subs}\n")
        rs_args = {"tool_table": str(tmp_path / "tools.tbl"), "var_file": str(var), "ini": str(ini)}
        options.setdefault("tool_lengths_mm", load_tool_table(tmp_path / "tools_mm.tbl"))
        options.setdefault("home_g28_mm", tuple(v * 25.4 for v in HOME_G28_IN))
        options.setdefault("home_g30_mm", tuple(v * 25.4 for v in HOME_G30_IN))
        options.setdefault("subroutine_path", [subs])
    program = load_gcode(path, **options)
    program._rs_args = rs_args
    assert_follows_rs274(path, program)
    return program


# -- each construct -----------------------------------------------------------------------------------------------

CONSTRUCTS = {
    "coolant_modes_pauses": """G21 G90 G17 G94 G61 G40 G49 G80 G54
G64 P0.02 Q0.01
G0 Z5 M8
G0 X10 Y5 M7
G1 Z-1 F200
G61.1 G1 X20
M0
M1
M60
G64 G1 Y15 M9
G20 G1 X1 Y1 (inches from here on)
G21 G1 X5 Y5
G93 G1 X10 Y10 F2 (inverse time: half a minute)
G2 X20 Y10 R5 F4
G94 F300 G1 X0 Y0
G0 Z5
M30
""",
    "canned_cycles": """G21 G90 G17
G0 Z-1
G98 G81 X1 Y1 Z-5 R2 F100
X2
G99 G81 X3 Y3 Z-5 R2
G0 Z10
G98 G83 X4 Y4 Z-5 R1 Q2
G99 G73 X5 Y5 Z-5 R1 Q2
G91 G98 G81 X1 Y0 Z-2 R-3 L3
G90 G80
G0 Z5
G82 X6 Y6 Z-1 R1 P0.5
G85 X7 Y7 Z-1 R1
G89 X8 Y8 Z-1 R1 P0.5
G99 G83 X9 Y-3 Z-4.1 R0.5 Q0.7 F80
Y-5
G80
G0 X15 Y0 Z0
G91 G81 R.1 Z-.5 ^60 L6 F10 (a bolt circle by polar steps)
G90 G80
G0 Z5
M2
""",
    "machine_moves_and_offsets": """G21 G90
G0 X1 Y2 Z3
G28
G28.1
G0 X4 Y4 Z4
G28 G91 Z0 (home Z only, as Fusion's posts write it)
G90 G28 X7 (through X7, then X home)
G30
G30.1
G0 X9 Y9 Z1
G30 Y3
G53 G0 Z0
G53 G1 X2 Y-3 F300
G10 L2 P1 X5 Y5 Z1
G0 X0 Y0 Z0
G10 L2 P0 X-2
G0 X1
G10 L20 P2 X1 Y1 Z0
G55 G0 X0 Y0
G56 G0 X2 Y2
G59.3 G0 X3 Y3
G10 L2 P9 X10
G0 X3
G54 G92 X0 Y0
G0 X5 Y5
G92.2
G0 X5 Y5
G92.3
G0 X6 Y6
G92.1
G0 X1 Y1
T1 M6
G43 H1
G0 Z0
G43 H2 G0 Z1
G0 X2 Y2
G43.1 Z3
G0 Z0
G49
G0 X0 Y0 Z0
M2
""",
    "planes_and_arcs": """G21 G90 G91.1
G0 X10 Y0 Z0
G18 G2 X20 Z0 I5 K0 F200
G3 X10 Z0 R5
G2 X10 Z0 I-2 K0 (a full circle in XZ)
G19 G3 Y10 Z0 J5 K0
G2 Y0 Z0 R-5
G17 G2 X10 Y0 I-3 J0 P2 (two turns)
G3 X10 Y10 Z-2 I0 J5 (helix)
G90.1 G2 X20 Y10 I15 J10
G91.1
G0 @5 ^45
G91 G1 ^30 @1
G90 G0 X0 Y0 Z0
M2
""",
    "parameters_and_expressions": """G21 G90
#1 = 3
#<depth> = -1.5
#<_safe> = 5
#[1+1] = [#1 * 2]
##1 = 7 (#3 = 7)
#4 = 1 #5 = #4 (parameters of one line take effect together: #5 = the old #4 = 0)
G0 Z#<_safe>
G0 X[#1 + #2] Y[#3 - #5]
G1 Z#<depth> F[100 * 2]
G1 X[SIN[30] * 10] Y[COS[60] * 10] Z[-SQRT[4]]
G1 X[ATAN[1]/[1] / 9] Y[ABS[-3]] Z[-FIX[2.7]]
G1 X[FUP[2.1]] Y[ROUND[2.5]] Z[-[7 MOD 3]]
G1 X[2 ** 3] Y[-7 MOD 3] Z[-[1 + 2 * 3 ** 2] / 10]
G1 X[[1 EQ 1] + [2 NE 2] + [3 GT 2] + [2 GE 2] + [1 LT 2] + [3 LE 2]]
G1 Y[[1 AND 0] + [1 OR 0] * 2 + [1 XOR 1] * 4 + EXISTS[#<depth>] * 8 + EXISTS[#<nothing>] * 16]
G1 X[EXP[1] + LN[1] + TAN[45] + ASIN[1] / 90 + ACOS[0] / 90] Y[#<_x> + 1]
G0 Z#<_safe>
M2
""",
    "o_word_flow": """G21 G90
#<_safe> = 2
o<hole> sub
  G0 X#1 Y#2
  G1 Z#3 F100
  G0 Z#<_safe>
o<hole> endsub
o<early> sub
  o10 if [#1 GT 5]
    o<early> return [#1 * 2]
  o10 endif
o<early> endsub [#1]
G0 Z#<_safe>
#<i> = 0
o100 while [#<i> LT 4]
  #<i> = [#<i> + 1]
  o101 if [#<i> EQ 2]
    o100 continue
  o101 elseif [#<i> EQ 4]
    G0 X40 Y0
  o101 else
    o<hole> call [#<i> * 10] [5] [-1]
  o101 endif
o100 endwhile
#<n> = 0
o110 do
  #<n> = [#<n> + 1]
  o111 if [#<n> GT 3]
    o110 break
  o111 endif
  G1 X[#<n> * 5] Y10 F200
o110 while [1]
o120 repeat [3]
  G91 G1 Y2 F200
  G90
o120 endrepeat
o<early> call [9]
G0 X#<_value> Y0
o<early> call [1]
G0 X#<_value> Y1
o<square> call [4] [0.5] (a subroutine file from the subroutine path)
G0 X#<_value> Z#<_safe>
M70
G20 G91
M72
G0 X1 Y1
M2
""",
}


@needs_rs274
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n == "planes_and_arcs" else n for n in CONSTRUCTS])
def test_each_construct_follows_rs274(tmp_path, name):
    program = run_both(tmp_path, name, CONSTRUCTS[name])
    assert program.moves, "nothing moved"
    if name == "coolant_modes_pauses":
        notes = [m.note for m in program.moves if m.kind == "pause"]
        assert notes == ["program pause M0 (line 7)", "program pause M1 (line 8)", "pallet change pause M60 (line 9)"]
        assert len([w for w in program.warnings if "coolant" in w]) == 1  # reported once
        assert any(m.minutes == 0.5 for m in program.moves)


def test_m73_restores_the_callers_modes_and_numbered_parameters_are_local():
    text = ("G21 G90\n#1 = 5\no<s> sub\nM73\nG20 G91\n#1 = 99\no<s> endsub\no<s> call [1]\n"
            "G0 X#1\nM2\n")
    program = parse_gcode(text)
    assert program.moves[-1].end == (5.0, 0.0, 0.0)  # mm and absolute again, and #1 the caller's


# -- programs as CAM post-processors write them ---------------------------------------------------------------------

POSTS = {
    "freecad_linuxcnc": """(Exported by FreeCAD)
(Post Processor: linuxcnc_post)
(Output Time:2024-03-02 10:11:12.000000)
(begin preamble)
G17 G54 G40 G49 G80 G90
G21
(begin operation: TC: Default Tool)
(machine units: mm/min)
M5
M6 T1
G43 H1
M3 S10000
(finish operation: TC: Default Tool)
(begin operation: Profile)
(machine units: mm/min)
G0 Z15.000
G0 X2.000 Y2.000
G0 Z5.000
G1 X2.000 Y2.000 Z-1.000 F120.000
G1 X32.000 Y2.000 Z-1.000 F600.000
G3 X35.000 Y5.000 Z-1.000 I0.000 J3.000 F600.000
G1 X35.000 Y20.000 Z-1.000 F600.000
G3 X32.000 Y23.000 Z-1.000 I-3.000 J0.000 F600.000
G1 X2.000 Y23.000 Z-1.000 F600.000
G1 X2.000 Y2.000 Z-1.000 F600.000
G0 Z15.000
(finish operation: Profile)
(begin postamble)
M05
G17 G54 G90 G80 G40
M2
""",
    "fusion360_grbl": """%
(1001)
(Machine)
(  vendor: Autodesk)
(T1 D=3.175 CR=0 - ZMIN=-1 - flat end mill)
G90 G94
G17
G21
(2D Contour1)
T1
S10000 M3
G0 X5 Y5
Z15
Z5
G1 Z1 F1000
Z-1 F300
X25 F1000
G3 X30 Y10 I0 J5
G1 Y20
G2 X25 Y25 R5
G1 X5
G1 Y5
G0 Z15
M5
G28 G91 Z0
G90
G28 G91 X0 Y0
G90
M30
%
""",
    "fusion360_linuxcnc": """%
(AXIS,stop)
(1001)
(T1  D=3.175 CR=0. - ZMIN=-2. - flat end mill)
N10 G90 G94 G40 G17 G91.1
N15 G21
N20 G53 G0 Z0.
(2D Pocket1)
N25 T1 M6
N30 S5000 M3
N35 G54
N40 M8
N45 G0 X10. Y10.
N50 G43 Z15. H1
N55 Z5.
N60 G1 Z1. F1000.
N65 Z-1. F300.
N70 G3 X15. Y15. I5. J0. F800.
N75 G1 X20.
N80 G2 X25. Y10. I0. J-5.
N85 G1 Y5.
N90 G83 X30. Y5. Z-2. R5. Q0.5 F100.
N95 X35.
N100 G80
N105 G0 Z15.
N110 M9
N115 G53 G0 Z0.
N120 M5
N125 G53 G0 X0. Y0.
N130 M30
%
""",
    "estlcam": """G21
G90
G94
F1000
M03 S24000
G00 Z5.0000
G00 X10.0000 Y10.0000
G01 Z-0.5000 F300
G01 X20.0000 Y10.0000 F1000
G02 X25.0000 Y15.0000 I0.0000 J5.0000
G01 X25.0000 Y25.0000
G03 X20.0000 Y30.0000 I-5.0000 J0.0000
G01 X10.0000 Y30.0000
G01 X10.0000 Y10.0000
G00 Z5.0000
M05
G00 X0.0000 Y0.0000
M30
""",
    "flatcam": """(G-CODE GENERATED BY FLATCAM v8.994 - www.flatcam.org - Version Date: 2020/11/7)
(Name: board_drill_cnc)
(Type: G-code from Excellon)
(Units: MM)
G21
G90
G94
G01 F100.00
M5
G00 Z15.0000
T1
M6
(MSG, Change to Tool Dia = 0.8000)
M0
G00 Z15.0000
M03
G00 X10.0000Y10.0000
G01 Z-1.7000
G01 Z0
G00 Z2.0000
G00 X12.5400Y10.0000
G01 Z-1.7000
G01 Z0
G00 Z2.0000
M05
G00 Z15.00
G00 X0Y0
M2
""",
    "pcb2gcode": """( pcb2gcode 2.4.0 )
( Software-independent Gcode )
G94 ( Millimeters per minute feed rate. )
G21 ( Units == Millimeters. )
G90 ( Absolute coordinates. )
G00 S10000 ( RPM spindle speed. )
G64 P0.01000 ( set maximum deviation from commanded toolpath )
G01 F600.00000 ( Feedrate. )
M3 ( Spindle on clockwise. )
G04 P1.00000 ( Wait for spindle to get up to speed )
G00 Z1.00000 ( retract )
G00 X1.00000 Y1.00000 ( rapid move to begin. )
G01 Z-0.05000 F100.00000 ( plunge. )
G04 P0 ( dwell for no time -- G64 should not smooth over this point )
G01 F600.00000
G01 X5.00000 Y1.00000
G01 X5.00000 Y3.00000
G01 X1.00000 Y3.00000
G01 X1.00000 Y1.00000
G00 Z1.00000 ( retract )
G81 R1.00000 Z-1.70000 F100.00000 X2.00000 Y2.00000
X4.00000 Y2.00000
G80
G00 Z1.00000 ( retract )
M5 ( Spindle off. )
M9 ( Coolant off. )
M2 ( Program end. )
""",
    "carbide_create": """(Design File: sign.c2d)
(stockMin:0.00mm, 0.00mm, -12.70mm)
(stockMax:100.00mm, 50.00mm, 0.00mm)
(STOCK/BLOCK,100.00, 50.00, 12.70,0.00, 0.00, 12.70)
G90
G21
(Move to safe Z to avoid workholding)
G53G0Z-5.000
(Tool: 102)
M6T102
M3S18000
(Toolpath: Contour)
G0Z12.700
G0X10.000Y10.000Z5.000
G1Z-1.000F400.0
G1X20.000Y10.000F1000.0
G2X25.000Y15.000I0.000J5.000
G1X25.000Y20.000
G3X20.000Y25.000I-5.000J0.000
G1X10.000Y25.000
G1X10.000Y10.000
G0Z12.700
M5
G53G0Z-5.000
M30
""",
}


@needs_rs274
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in ("fusion360_linuxcnc", "estlcam") else n
                                  for n in POSTS])
def test_post_processor_programs_follow_rs274(tmp_path, name):
    program = run_both(tmp_path, name, POSTS[name])
    assert any(m.kind in ("feed", "arc") for m in program.moves)


@needs_rs274
def test_a_post_processor_program_runs_on_the_mock_within_half_a_step(tmp_path):
    """The whole way once: plan, step plan, mock run, decoded pin log against rs274's path."""
    path = tmp_path / "fusion.ngc"
    path.write_text(POSTS["fusion360_grbl"].replace("G28 G91 X0 Y0", "G28 G91 X0"))
    canon = parse_canonical(run_rs274(str(path)))
    s = cam.MachineSettings(travel=Travel(-10**6, 10**6, -10**6, 10**6, -10**6, 10**6))
    step = np.array([s.mm_per_step_xy, s.mm_per_step_xy, s.mm_per_step_z])
    plan = cam.plan_steps(plan_gcode(load_gcode(path), s))
    result = cam.run(plan)
    motion = cam.decode_pin_log(result.pin_log(), s)
    p = motion.position_steps
    got = np.column_stack([p[:, 0], -p[:, 1], -p[:, 2]]).astype(float)
    pts, _ = canonical_polyline_mm(canon, max_chord_mm=0.0005)
    dense = [pts[:1] / step]
    for a, b in zip(pts[:-1] / step, pts[1:] / step):
        n = max(1, int(np.ceil(np.abs(b - a).max() / 0.02)))
        dense.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    dist, _ = cKDTree(np.vstack(dense)).query(got, p=np.inf)
    assert dist.max() <= 0.5 + 0.03


# -- splines (G5, G5.1) and G33 ------------------------------------------------------------------------------------

SPLINES = """G21 G90 G17 G94 F300
G10 L2 P1 X5 Y-3
G54
G0 X0 Y0 Z1
G1 Z-0.5
G5.1 X20 Y10 I5 J15
G92 X0 Y0
G5.1 X-10 Y5 I-2 J8
G91 G5.1 X-5 Y-5 I0 J-4
G90 G1 X0 Y0
G5 X10 Y10 I3 J0 P0 Q-4
G5 X20 Y0 P2 Q3
G1 X30
G92.1
G0 Z5
M2
"""
SPLINES_MM = [  # (start, inner control points, end): machine mm, worked out by hand from the text above
    ((5, -3, -0.5), ((10, 12, -0.5),), (25, 7, -0.5)),  # G54 (5, -3); the control point is the start + I J
    ((25, 7, -0.5), ((23, 15, -0.5),), (15, 12, -0.5)),  # G92 puts the program origin at (25, 7), not I J
    ((15, 12, -0.5), ((15, 8, -0.5),), (10, 7, -0.5)),  # G91: the end is incremental too
    ((25, 7, -0.5), ((28, 7, -0.5), (35, 13, -0.5)), (35, 17, -0.5)),  # G5: the second one is the end + P Q
    ((35, 17, -0.5), ((35, 21, -0.5), (47, 10, -0.5)), (45, 7, -0.5)),  # no I J after a G5: start - its P Q
]


def _spline_points(program):
    return [(m.controls, m.end) for m in program.moves if m.kind == "spline"]


@needs_rs274
@pytest.mark.parametrize("units, scale", [("G21", 1.0), pytest.param("G20", 25.4, marks=pytest.mark.slow)])
def test_splines_follow_the_exact_curve_and_rs274_after_offsets(tmp_path, units, scale):
    """G5.1 and G5 after G54, G92 and G91, in mm and in inches: the control points as worked out by hand; the
    motion within half a step of the exact curves (de Casteljau, densely) and of rs274's other moves."""
    program = run_both(tmp_path, f"splines_{units}", SPLINES.replace("G21", units))
    got = _spline_points(program)
    assert len(got) == len(SPLINES_MM)
    for (controls, end), (_, want_controls, want_end) in zip(got, SPLINES_MM):
        assert np.allclose(controls, np.array(want_controls) * scale, atol=1e-9)
        assert np.allclose(end, np.array(want_end) * scale, atol=1e-9)
    # run_both: every motor position within half a step of the path; and the motion goes all along each curve
    # as worked out by hand: every point of it is within a step of a motor position (samples 0.9 step apart)
    step = np.array([WIDE.mm_per_step_xy, WIDE.mm_per_step_xy, WIDE.mm_per_step_z])
    positions = cKDTree(_positions_mm(plan_gcode(program, WIDE)) / step)
    for start, controls, end in SPLINES_MM:
        ctrl = np.vstack([start, *controls, end]) * scale
        gap, _ = positions.query(bezier_mm(ctrl, np.linspace(0, 1, 20_001)) / step, p=np.inf)
        assert gap.max() <= 1.0
    # the tangent goes on smoothly from the first G5 to the second
    (_, c2), e = got[3]
    (c3, _), _ = got[4]
    assert np.allclose(np.array(e) - np.array(c2), np.array(c3) - np.array(e))


@needs_rs274
def test_splines_keep_the_motion_mode_as_rs274(tmp_path):
    """G5.1 is not modal (rs274): a canned cycle or G1 before it goes on after it."""
    run_both(tmp_path, "spline_modes", """G21 G90 G17 F100 G98
G0 Z5
G81 Z-1 R1 X1
G5.1 X10 Y5 I3 J1
X20 Y0
G80
G1 X2 Y2
G5.1 X4 Y2 I1 J1
X6
G0 Z5
M2
""")


def test_spline_samples_lie_on_the_exact_curve_and_its_box_and_crossings_are_exact():
    from cam.job.gcode import _Bezier, _curve_points

    s = cam.MachineSettings()
    step = np.array([s.mm_per_step_xy, s.mm_per_step_xy, s.mm_per_step_z])
    for pts in ([[0, 0, -1], [3, 40, -1], [10, -2, -1]], [[0, 0, 0], [3, 4, 0], [10, -20, 0], [8, 8, 0]],
                [[1, 1, 0], [1, 1, 0], [1, 1, 0]]):
        pts = np.array(pts, np.float64)
        curve = _Bezier(pts)
        n = curve.n_points(step)
        way = _curve_points(curve, n, pts[-1])
        assert np.abs(way - bezier_mm(pts, np.arange(1, n + 1) / n)).max() < 1e-9  # each sample on the curve
        assert (np.abs(np.diff(np.vstack([pts[:1], way]), axis=0)) / step).max() <= 0.9 + 1e-9
        dense = bezier_mm(pts, np.linspace(0, 1, 100_001))
        lo, hi = curve.box_mm()
        assert np.allclose(lo, dense.min(axis=0), atol=1e-6) and np.allclose(hi, dense.max(axis=0), atol=1e-6)
        for axis in np.flatnonzero(np.ptp(pts, axis=0)):  # a constant coordinate has no crossings
            value = float(dense[len(dense) // 3, axis])
            ts = curve.crossings(axis, value)
            assert ts and np.allclose(bezier_mm(pts, np.array(ts))[:, axis], value, atol=1e-9)
            assert all(0 <= t <= 1 for t in ts)
    assert _Bezier(np.array([[0, 0, 0], [3, 4, 0], [10, -20, 0], [8, 8, 0.0]])).crossings(0, 11.0) == []


def test_a_spline_that_bulges_out_of_the_travel_is_refused_naming_its_line():
    # both ends inside the thesis machine's travel (X 0..289 mm, Y -289..0 mm); the curve reaches Y +10
    program = parse_gcode("G21 G90 F100\nG0 X10 Y-10\nG5.1 X50 Y-10 I20 J40\nM2\n", source="bulge.ngc")
    with pytest.raises(cam.TravelError, match=r"^bulge\.ngc:3: move to .* leaves the machine travel"):
        plan_gcode(program, cam.MachineSettings())
    plan_gcode(parse_gcode("G21 G90 F100\nG0 X10 Y-50\nG5.1 X50 Y-50 I20 J40\nM2\n"), cam.MachineSettings())


THREAD = """G20 G90 G18 G64
S400 M3
G92 X-0.1 Z0.2
G0 X0.3 Z0.8
G1 X0.2 F10
G33 Z0.1 K0.05
G33 X0.3 Z0 K[SQRT[2]*0.05]
G0 X0.5
G21 G92.1
S1000
G0 X5 Z10
G33 Z2 K1.5
M5
M2
"""


@needs_rs274
def test_g33_is_a_straight_feed_at_k_times_s_with_one_warning(tmp_path):
    """rs274 prints G33 as START_SPEED_FEED_SYNC and a STRAIGHT_FEED: cam follows that line, at K x S, and says
    once that nothing is synchronised to the spindle."""
    program = run_both(tmp_path, "thread", THREAD)
    feeds = [m.feed_mm_min for m in program.moves if m.line in (6, 7, 12)]
    assert feeds == pytest.approx([0.05 * 25.4 * 400, math.sqrt(2) * 0.05 * 25.4 * 400, 1.5 * 1000])
    synced = [w for w in program.warnings if "spindle M3" not in w]  # the spindle's own note (issue #30 point 5)
    assert len(synced) == 1
    assert synced[0].startswith(f"{tmp_path / 'thread.ngc'}:6: G33") and "not synchronised" in synced[0]
    job = plan_gcode(program, WIDE)
    assert job.warnings == program.warnings


# -- LinuxCNC's own example programs ---------------------------------------------------------------------------------

NCFILES = Path("/usr/share/linuxcnc/ncfiles")
REFUSED_FEATURES = ("probing", "rotary axis", "cutter radius compensation", "cutter compensation", "lathe cycles",
                    "lathe diameter mode", "user M code")
"""What point 3 of #18 refuses (probing, rotary axes, cutter compensation, lathe cycles, user M codes): no example
program may be refused for anything else.  Splines (systems.ngc) and G33 (threading.ngc) run: their path is
compared as :func:`assert_follows_rs274` says."""


@needs_rs274
@pytest.mark.skipif(not NCFILES.is_dir(), reason="LinuxCNC's example programs (linuxcnc-uspace) not installed")
@pytest.mark.slow
def test_linuxcnc_example_programs_match_rs274_or_are_refused_naming_the_feature(tmp_path):
    matched, refused = [], []
    for path in sorted(NCFILES.rglob("*.ngc")):  # the subfolders (macros, probe, gladevcp, ...) too
        try:
            canon_text = run_rs274(str(path), timeout_s=120)
        except cam.CamError:
            continue  # rs274 does not run it on its own (needs a tool table, an INI, a probe, ...)
        try:
            program = load_gcode(path, tool_lengths_mm=RS274_DEFAULT_TOOLS_MM, max_lines=2_000_000)
        except cam.ParseError as exc:
            message = str(exc)
            assert "\n" not in message and message.startswith(f"{path}:"), message
            assert any(f in message for f in REFUSED_FEATURES), f"{path.name} refused for another reason: {message}"
            refused.append(path.name)
            continue
        program._rs_args = {}
        assert_follows_rs274(path, program)
        matched.append(path.name)
    assert len(matched) + len(refused) >= 20, (matched, refused)
    assert len(matched) > len(refused)
    assert {"systems.ngc", "threading.ngc"} <= set(matched), (matched, refused)


def test_refused_features_say_why_in_one_line():
    cases = {
        "G38.5 Z-5 F10": "'G38.5': probing away from the work (G38.4/G38.5) is not supported",
        "G38.2 Y1 Z-5 F10": "a probe along Y is not supported: cam probes down Z only",
        "G0 X1 B90": "rotary axis word 'B90' is not supported",
        "G0 X1 C-4": "rotary axis word 'C-4' is not supported",
        "G41 D2": "'G41': cutter radius compensation G41/G42 takes the tool's radius from the tool table",
        "G42.1 D2 L1": "'L1' (a lathe tool's orientation) with cutter compensation G41.1/G42.1 is not supported",
        "G1 X1 D3 F10": "cutter compensation word 'D3' without G41.1/G42.1 is not supported",
        "G70 P1 Q2": "'G70': lathe cycles are not supported",
        "G72 P1 Q2": "'G72': lathe cycles are not supported",
        "G76 P0.05 Z-1": "'G76': lathe cycles are not supported",
        "M100": "user M code 'M100' is not supported",
        "M150 P1": "user M code 'M150' is not supported",
        "G33.1 Z-5 K1": "'G33.1': rigid tapping is not supported: the machine has no spindle encoder",
        "G5.2 X1 Y1 P1 L3": "'G5.2': NURBS blocks (G5.2 .. G5.3) are not supported",
        "G5.3": "'G5.3': NURBS blocks (G5.2 .. G5.3) are not supported",
    }
    for words, fragment in cases.items():
        with pytest.raises(cam.ParseError) as info:
            parse_gcode(f"G21\n{words}\n", source="r.ngc")
        assert str(info.value).startswith("r.ngc:2:") and fragment in str(info.value), str(info.value)


def test_subroutine_files_and_tool_tables_from_the_command_line(tmp_path):
    from test_cli import assert_one_line_error, cli

    subs = tmp_path / "subs"
    subs.mkdir()
    (subs / "square.ngc").write_text(SUBROUTINE)
    (tmp_path / "tools.tbl").write_text("T1 P1 Z2.5 ;a 3 mm end mill\n")
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90\nT1 M6\nG43 H1\nG0 X5 Y-10 Z2\no<square> call [3] [0.5]\nG0 Z2\nM8\nM2\n")
    proc = cli("drill", prog, "--yes", "--no-progress", "--tool-table", tmp_path / "tools.tbl",
               "--subroutine-path", subs)
    assert proc.returncode == 0, proc.stderr
    assert "coolant" in proc.stderr + proc.stdout
    assert_one_line_error(cli("info", prog), "p.ngc:3:", "--tool-table")
    assert_one_line_error(cli("info", prog, "--tool-table", tmp_path / "tools.tbl"), "p.ngc:5:",
                          "subroutine 'o<square>' is not defined")
    loop = tmp_path / "loop.ngc"
    loop.write_text("o1 while [1]\no1 endwhile\n")
    assert_one_line_error(cli("info", loop, "--max-lines", "1000"), "loop.ngc:", "--max-lines")
    assert_one_line_error(cli("info", tmp_path / "tools.tbl", "--max-lines", "5"), "tools.tbl")
    help_text = cli("drill", "--help").stdout
    for flag in ("--tool-table", "--subroutine-path", "--max-lines"):
        assert flag in help_text


@needs_rs274
@pytest.mark.slow
def test_the_shipped_sample_follows_rs274_and_runs():
    from conftest import SAMPLES
    from test_cli import cli

    path = SAMPLES / "bolt_plate.ngc"
    program = load_gcode(path)
    program._rs_args = {}
    assert_follows_rs274(path, program, settings=cam.MachineSettings())  # inside the thesis machine's travel
    proc = cli("drill", path, "--yes", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "coolant" in proc.stdout + proc.stderr
