"""G-code in: programs from other CAM tools run on the mock; motion checked against LinuxCNC's rs274."""
import os
import shutil

import numpy as np
import pytest
from scipy.spatial import cKDTree

import cam
from cam.motion.steps import plan_steps
from cam.formats.gcode import load_gcode, parse_gcode
from cam.job.gcode import plan_gcode
from support.lcnc import canonical_polyline_mm, parse_canonical, run_rs274

from test_cli import assert_one_line_error, cli

needs_rs274 = pytest.mark.skipif(
    shutil.which("rs274") is None and not os.environ.get("CI"), reason="rs274 (linuxcnc-uspace) not installed"
)

ENGRAVING = """%
(engraving with arcs, as a CAM post-processor writes it)
N10 G21 G90 G17 G94 G40 G49 G54
N20 G0 Z2.0 S12000 M3
N30 G0 X10 Y-10
N40 G1 Z-0.3 F120
N50 G2 X20 Y-10 I5 J0 F400 ; half circle by I/J
N60 G3 X30 Y-10 R5          ; half circle by R
N70 G1 X30 Y-20
N80 G2 X30 Y-20 I-4 J0      ; full circle
N90 G3 X22 Y-28 R-8         ; long way round (270 degrees)
N100 G1 X12.5 Y-27.25 Z-0.5 (a ramp)
N110 G0 Z2
N120 M5
N130 G0 X0 Y0
N140 M30
%
"""

DRILLING = """(drilling job: plunges, dwell and a tool change)
G21 G90
G0 Z3
T1 M6 (0.8 mm drill)
G0 X5 Y-5
G1 Z-1.2 F60
G4 P0.2
G0 Z3
G0 X15.5 Y-7.25
G1 Z-1.2 F60
G0 Z3
T2 M6 (1.0 mm drill)
G0 X40 Y-30
G1 Z-1.2 F60
G0 Z3
G0 X0 Y0 Z0
M2
"""

INCHES = """(a file in inches with incremental moves and G92)
G20 G90
G0 Z0.1
G0 X0.5 Y-0.5
G92 X0 Y0
G91
G1 Z-0.12 F10
G1 X0.4 F20
G2 X0.4 Y0 R0.2
G1 Y-0.3
G90
G0 Z0.1
G0 X0 Y0
M2
"""

PROGRAMS = {"engraving": ENGRAVING, "drilling": DRILLING, "inches": INCHES}


def _decoded_mm(plan):
    result = cam.run(plan)
    motion = cam.decode_pin_log(result.pin_log(), plan.settings)
    s = plan.settings
    p = motion.position_steps
    return np.column_stack([p[:, 0] * s.mm_per_step_xy, -p[:, 1] * s.mm_per_step_xy, -p[:, 2] * s.mm_per_step_z]), result


@needs_rs274
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n == "engraving" else n for n in PROGRAMS])
def test_motion_follows_rs274_within_half_a_step(tmp_path, name):
    path = tmp_path / f"{name}.ngc"
    path.write_text(PROGRAMS[name])
    canon = parse_canonical(run_rs274(str(path)))
    s = cam.MachineSettings()
    step = np.array([s.mm_per_step_xy, s.mm_per_step_xy, s.mm_per_step_z])
    pts, _ = canonical_polyline_mm(canon, max_chord_mm=0.0005)
    # dense samples of the programmed path, in step units (spacing <= 0.02 step)
    dense = [pts[:1] / step]
    for a, b in zip(pts[:-1] / step, pts[1:] / step):
        n = max(1, int(np.ceil(np.abs(b - a).max() / 0.02)))
        dense.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    tree = cKDTree(np.vstack(dense))
    plan = plan_steps(plan_gcode(load_gcode(path), s))
    decoded_mm, result = _decoded_mm(plan)
    dist, _ = tree.query(decoded_mm / step, p=np.inf)
    assert dist.max() <= 0.5 + 0.03, f"decoded motion strays {dist.max():.3f} steps from the path"
    # and the motion reaches every programmed end point (within half a step)
    ends = np.array([m.end for m in canon]) / step
    d_end, _ = cKDTree(decoded_mm / step).query(ends, p=np.inf)
    assert d_end.max() <= 0.5 + 1e-6
    assert np.allclose(decoded_mm[-1] / step, np.rint(pts[-1] / step))


def test_tool_changes_pause_in_order():
    plan = plan_steps(plan_gcode(parse_gcode(DRILLING, source="drill.ngc")))
    seen = []
    result = cam.run(plan, on_pause=lambda pos, note: seen.append(note))
    assert seen == ["tool change: T1 (line 4)", "tool change: T2 (line 12)"]
    assert result.status == "finished"


def test_feed_rate_sets_step_periods():
    plan = plan_steps(plan_gcode(parse_gcode("G21 G90\nG1 X10 F60\nM2\n")))
    # 10 mm at 1 mm/s = 10 s; never faster than the 5 ms step delay allows
    assert plan.estimated_time_s == pytest.approx(10.0, rel=1e-3)
    constant = cam.MachineSettings().replace(ramp="constant")  # the thesis's timing, no speed ramps
    fast = plan_steps(plan_gcode(parse_gcode("G21 G90\nG1 X10 F100000\nM2\n"), constant))
    assert fast.estimated_time_s == pytest.approx(np.ceil(10 / 0.0289) * 0.005, rel=1e-6)
    # with the default look-ahead ramps: plus one speed-up from and one slow-down to the start speed
    ramped = plan_steps(plan_gcode(parse_gcode("G21 G90\nG1 X10 F100000\nM2\n"))).estimated_time_s
    assert fast.estimated_time_s + 0.05 < ramped < fast.estimated_time_s + 0.3


@pytest.mark.parametrize(
    "text, line, fragment",
    [
        ("G21\nG1 X1 F100 Q3\n", 2, "unsupported word 'Q3'"),
        ("G21\nG1 X F100\n", 2, "word 'X' has no number"),
        ("G21\nG1 X1 F100\nG2 X5 Y0 R1\n", 3, "radius 1 is too small"),
        ("G21\nG38.4 Z-5 F10\n", 2, "'G38.4': probing away from the work (G38.4/G38.5) is not supported"),
        ("G21\nG38.2 X1 Z-5 F10\n", 2, "a probe along X is not supported"),
        ("G21\nG0 X1 A90\n", 2, "rotary axis word 'A90' is not supported"),
        ("G21\nG41 D1\n", 2, "'G41': cutter radius compensation G41/G42 takes the tool's radius from the tool table"),
        ("G21\nG71 P1 Q2\n", 2, "'G71': lathe cycles are not supported"),
        ("G21\nG76 P1 Z-5\n", 2, "'G76': lathe cycles are not supported"),
        ("G21\nM101\n", 2, "user M code 'M101' is not supported"),
        ("G21\nM199 P1\n", 2, "user M code 'M199' is not supported"),
        ("G21\nG2 X5 Y0\n", 2, "without a feed rate"),
        ("G21\nG1 X1 F10\nG2 X5 Y0\n", 3, "needs I/J or R"),
        ("G21\nM200\n", 2, "unsupported word 'M200'"),
        ("G21\no<nowhere> call\n", 2, "subroutine 'o<nowhere>' is not defined"),
        ("G21\nG0 X[1/0]\n", 2, "division by zero"),
        ("G21\nG0 X#<undefined>\n", 2, "'#<undefined>' is not defined"),
        ("G21\nG0 X[1+\n", 2, "expected"),
        ("G21 (open comment\n", 1, "not closed"),
        ("G21\nG1 X1 F10\nG2 X3 Y0 I0.5 J0\n", 3, "not on the circle"),
        ("G21 F100\nG18\nG5.1 X10 I1 J1\n", 3, "G5.1 splines need the XY plane (G17)"),
        ("G21 F100\nG19 G5 X10 I1 J1 P1 Q1\n", 2, "G5 splines need the XY plane (G17)"),
        ("G21 F100\nG5.1 X10 I1\n", 2, "G5.1 needs both I and J"),
        ("G21 F100\nG5 X10 Y1 P1 Q1\n", 2, "G5 needs I and J unless the move before it is a G5"),
        ("G21 F100\nG5 X10 I1 J1 P1 Q1\nG1 X0\nG5 X10 P1 Q1\n", 4, "G5 needs I and J unless"),
        ("G21 F100\nG5 X10 Y1 I1 P1 Q1\n", 2, "G5 needs both I and J, or neither"),
        ("G21 F100\nG5 X10 Y1 I1 J1 Q1\n", 2, "G5 needs both P and Q"),
        ("G21 F100\nG5.1 X10 Z-1 I1 J1\n", 2, "G5.1 splines move X and Y only, not Z"),
        ("G21 F100\nG5.1 I1 J1\n", 2, "G5.1 needs an end point X and/or Y"),
        ("G21 F100\nG5.1 X1 I1 J1 K1\n", 2, "'K' is not a word of G5.1"),
        ("G21 F100\nG5.1 X1 I1 J1 P1\n", 2, "'P' and 'Q' are words of G5, not of G5.1"),
        ("G21\nG5.1 X10 I1 J1\n", 2, "G5.1 without a feed rate 'F'"),
        ("G21 F100\nG5 X1 I1 J1 P[10**7] Q1\n", 2, "word 'P[10**7]' is out of range"),
        ("G21 F100\nG0 X1\nG5.1 X1 I[10**6] J1\n", 3, "the spline's control point reaches X1e+06 mm"),
        ("G21 F100\nG1 G5.1 X1 I1 J1\n", 2, "two motion codes on one line"),
        ("G21 F100\nG5.2 X1 Y1 P1 L3\n", 2, "'G5.2': NURBS blocks (G5.2 .. G5.3) are not supported"),
        ("G21 S100 M3\nG33 Z-1\n", 2, "G33 needs 'K'"),
        ("G21 S100 M3\nG33 Z-1 K0\n", 2, "G33 needs a distance per revolution 'K' above 0"),
        ("G21 M3\nG33 Z-1 K1\n", 2, "G33 needs a spindle speed 'S' above 0"),
        ("G21 S100 M3\nM5\nG33 Z-1 K1\n", 3, "G33 needs the spindle turning (M3 or M4)"),
        ("G21 S100 M4\nG33 Z-1 K1 I1\n", 2, "I, J or R given with G33"),
        ("G21 S1000000 M3\nG33 Z-1 K1000\n", 2, "G33's feed K x S = 1e+09 mm/min is out of range"),
        ("G21 S100 M3\nG33.1 Z-1 K1\n", 2, "'G33.1': rigid tapping is not supported"),
    ],
)
def test_bad_gcode_names_line_and_word(text, line, fragment):
    with pytest.raises(cam.ParseError) as info:
        parse_gcode(text, source="bad.ngc")
    assert str(info.value).startswith(f"bad.ngc:{line}:") and fragment in str(info.value)
    assert "\n" not in str(info.value) and len(str(info.value)) < 300


def test_a_program_that_never_ends_is_stopped_at_the_line_limit():
    endless = "G21 G90\nG1 F100\no100 while [1]\nG1 X1\nG1 X0\no100 endwhile\nM2\n"
    with pytest.raises(cam.ParseError, match=r"loop\.ngc:\d: the program has run 5,000 lines more than its own 7 and does not end"):
        parse_gcode(endless, source="loop.ngc", max_lines=5000)
    quiet = "#1=0\no1 do\n#1=[#1+1]\no1 while [1]\n"  # no motion at all
    with pytest.raises(cam.ParseError, match="does not end"):
        parse_gcode(quiet, source="quiet.ngc", max_lines=5000)
    with pytest.raises(cam.ParseError, match="more than 100 deep"):
        parse_gcode("o<r> sub\no<r> call\no<r> endsub\no<r> call\nM2\n", source="r.ngc")


def test_cli_runs_gcode_and_rejects_bad(tmp_path):
    good = tmp_path / "e.ngc"
    good.write_text(ENGRAVING)
    proc = cli("drill", good, "--pin-log", tmp_path / "p.csv", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "job finished" in proc.stdout
    motion = cam.decode_pin_log(tmp_path / "p.csv")
    assert motion.final_steps == (0, 0, round(-2 / 0.0157))  # G0 X0 Y0 at Z2
    bad = tmp_path / "b.ngc"
    bad.write_text("G21\nG1 X1 F100\nG2 X5 Y0 R1\n")
    assert_one_line_error(cli("drill", bad), "b.ngc:3:", "too small")
    for text, fragment in (("G21\nG1 X1 F100 Q3\n", "'Q3'"), ("G21\nG38.3 Z-1\n", "G38.3 without a feed rate 'F'"),
                           ("G21\nG1 Y F9\n", "'Y'")):
        bad.write_text(text)
        assert_one_line_error(cli("drill", bad), "b.ngc:2:", fragment)
    far = tmp_path / "far.ngc"
    far.write_text("G21\nG0 X900\n")
    assert_one_line_error(cli("drill", far), "far.ngc:2:", "travel")


def test_cli_preview_of_a_gcode_program(tmp_path):
    import cv2

    good = tmp_path / "e.ngc"
    good.write_text(ENGRAVING)
    pic = tmp_path / "e.png"
    proc = cli("drill", good, "--preview", pic, "--no-progress")
    assert proc.returncode == 0, proc.stderr
    img = cv2.imread(str(pic))
    assert img is not None and img.shape[0] > 100 and (img < 128).any()  # a picture with the cut drawn
    # the G-code job is a job in steps: its toolpath is drawn as SVG too
    assert cli("drill", good, "--preview", tmp_path / "e.svg", "--no-progress").returncode == 0
    assert "<line" in (tmp_path / "e.svg").read_text()
    assert_one_line_error(cli("drill", good, "--preview", tmp_path / "e.gif", "--no-progress"), "e.gif", ".png")
    assert not (tmp_path / "e.gif").exists()


def test_a_long_straight_program_runs_whole_and_only_repeats_count():
    straight = "G21 G90\nG1 F100\n" + "".join(f"G1 X{i % 7} Y-{i % 5}\n" for i in range(3000)) + "M2\n"
    program = parse_gcode(straight, source="long.ngc", max_lines=100)  # 3,003 lines run: its own, none repeated
    assert len(program.moves) >= 3000
    looped = "G21 G90\nG1 F100\n#1=0\no1 while [#1 LT 40]\nG1 X1\nG1 X0\n#1=[#1+1]\no1 endwhile\nM2\n"
    parse_gcode(looped, source="ok.ngc", max_lines=200)  # 40 passes of 5 lines: 200 more than its own 9
    with pytest.raises(cam.ParseError, match="150 lines more than its own 9"):
        parse_gcode(looped, source="ok.ngc", max_lines=150)
