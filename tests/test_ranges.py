"""Every number read from a file is finite and in its range (cam.limits) before use, and huge arcs are refused
before they are sampled: a bad number is one ParseError naming file, line and word (exit code 2 on the command
line), never a traceback, an overflow, or a NaN or infinity in a plan, a file or a report."""
import math
import subprocess
import sys

import numpy as np
import pytest

import cam
from cam.digitize.digitized import parse_digitized
from cam.formats.gcode import parse_gcode
from cam.job.gcode import _Arc, _curve_points, _Frame, plan_gcode
from cam.limits import MAX_MOVE_S

from test_cli_checks import ENV, cli, refused

# over 1.3 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {
    'test_a_program_longer_than_a_year_is_refused_naming_the_line',
    'test_excellon_repeats_are_bounded_in_all'}

DIGITS_400 = "9" * 400


def short(value):
    """A test id that does not spell out 400 digits."""
    return str(value).replace(DIGITS_400, "9x400")[:40]


# -- G-code words -----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("text, line, fragment", [
    (f"G21\nT{DIGITS_400} M6\n", 2, "tool 'T9999"),
    (f"G21\nG4 P{DIGITS_400}\n", 2, "dwell 'P9999"),
    ("G21\nG4 P10000000000\n", 2, "dwell 'P10000000000'"),
    ("G21\nG1 X1 F0.0000000001\n", 2, "feed 'F0.0000000001'"),
    ("G21\nG1 X1 F0\n", 2, "feed 'F0'"),
    ("G21\nG1 X1 F10\nG3 X2 Y0 R99999999999999999999\n", 3, "word 'R99999999999999999999'"),
    (f"G21\nG0 X{DIGITS_400}\n", 2, "word 'X9999"),
    ("G21\nG1 X1 F10\nG2 X1 Y0 I-2000000 J0\n", 3, "word 'I-2000000'"),
    ("G20\nG0 Y50000\n", 2, "word 'Y50000'"),  # 1.27 km in inches
    ("G21 G91\nG0 X900000\nG0 X900000\n", 3, "reaches X1.8e+06"),  # each word fits, their sum does not
    ("G21\nG92 X-900000\nG0 X900000\n", 3, "reaches X1.8e+06"),  # so does a G92 offset
    ("G21\nT1.5 M6\n", 2, "tool 'T1.5'"),
    (f"G21\nS{DIGITS_400} M3\n", 2, "spindle speed 'S9999"),
    (f"N{DIGITS_400} G21\n", 1, "line number 'N9999"),
    (f"G{DIGITS_400}\n", 1, "unsupported word 'G9999"),
    (f"M{DIGITS_400}\n", 1, "unsupported word 'M9999"),
], ids=short)
def test_gcode_words_out_of_range_name_the_line_and_the_word(text, line, fragment):
    with pytest.raises(cam.ParseError) as info:
        parse_gcode(text, source="bad.ngc")
    message = str(info.value)
    assert message.startswith(f"bad.ngc:{line}:") and fragment in message, message
    assert len(message) < 200 and "\n" not in message


def test_gcode_words_at_their_limits_are_read():
    program = parse_gcode("G21\nT999999 M6\nG4 P3600\nS1000000 M3\nN1000000000 G0 X1\nG1 X2 F0.001\n"
                          "G1 X3 F1000000\nG92 X-1000000\n")
    assert [m.kind for m in program.moves] == ["pause", "dwell", "rapid", "feed", "feed"]
    assert program.moves[1].seconds == 3600 and program.moves[3].feed_mm_min == 0.001


@pytest.mark.parametrize("text, fragments", [
    (f"G21\nT{DIGITS_400} M6\n", ("bad.ngc:2:", "tool 'T9999", "0..999999")),
    (f"G21\nG4 P{DIGITS_400}\n", ("bad.ngc:2:", "dwell 'P9999", "0..3600 s")),
    ("G21\nG1 X1 F0.0000000001\n", ("bad.ngc:2:", "feed 'F0.0000000001'")),
    ("G21\nG1 X1 F10\nG3 X2 Y0 R99999999999999999999\n", ("bad.ngc:3:", "'R99999999999999999999'")),
], ids=short)
def test_cli_refuses_gcode_numbers_in_one_line(tmp_path, text, fragments):
    path = tmp_path / "bad.ngc"
    path.write_text(text)
    for command in (["drill", path, "--no-progress"], ["info", path], ["preview", path, "-o", tmp_path / "p.png"]):
        refused(cli(*command), *fragments)
    assert not (tmp_path / "p.png").exists()


def test_a_feed_too_slow_for_its_move_is_refused_naming_the_line():
    # 10 mm at 0.001 mm/min would take 167 h: no plan of absurd times (it overflowed the step periods)
    with pytest.raises(cam.PlanError, match=r"slow\.ngc:3: at F0\.001 mm/min this 10 mm move takes 166\.7 h"):
        plan_gcode(parse_gcode("G21 G90\nG0 X1\nG1 X11 F0.001\n", source="slow.ngc"))
    # the same feed over a short move is planned, its periods as long as asked
    job = plan_gcode(parse_gcode("G21 G90\nG1 X0.0289 F0.001\n"))
    assert job.period_ns.max() == pytest.approx(0.0289 / (0.001 / 60) * 1e9, rel=1e-9)
    assert MAX_MOVE_S == 86400


# -- G-code arcs: checked against the travel before they are sampled ------------------------------------------------

def test_a_huge_arc_is_refused_before_it_is_sampled():
    """The 60-byte arc with I1000000 took 5.8 GB before the travel check; now 1 GiB of address space is plenty."""
    code = (
        "import resource\n"
        "resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
        "import cam\n"
        "from cam.formats.gcode import parse_gcode\n"
        "from cam.job.gcode import plan_gcode\n"
        "try:\n"
        "    plan_gcode(parse_gcode('G21 G90\\nG1 X1 F100\\nG2 X0 Y0 I1000000\\n', source='huge.ngc'))\n"
        "except cam.TravelError as exc:\n"
        "    print(exc)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    # clockwise from the left of a circle 1 km wide: the first point goes up (+Y), off the travel's Y 0 edge
    assert proc.stdout.startswith("huge.ngc:3: move to machine X1.000 Y-0.026 Z0.000 mm leaves the machine travel"), \
        proc.stdout


def test_cli_refuses_a_huge_arc_in_one_line(tmp_path):
    path = tmp_path / "huge.ngc"
    path.write_text("G21 G90\nG1 X1 F100\nG2 X0 Y0 I1000000\n")
    refused(cli("drill", path, "--no-progress"), "huge.ngc:3:", "leaves the machine travel")


def _sampled_refusal(program_text: str, settings: cam.MachineSettings) -> str:
    """The TravelError message of sampling the last arc and checking every point (the planner before the fix)."""
    program = parse_gcode(program_text, source="arc.ngc")
    *before, mv = program.moves
    cur = np.array(before[-1].end if before else (0.0, 0.0, 0.0))
    frame = _Frame(settings, False)
    arc = _Arc.of(cur, mv)
    way = _curve_points(arc, arc.n_points(frame.step_mm), np.array(mv.end))
    try:
        frame.check(way, way * frame.to_steps, f"arc.ngc:{mv.line}")
    except cam.TravelError as exc:
        return str(exc)
    return ""


def test_the_arc_check_names_the_point_sampling_would_name():
    """Arcs that cross the travel's bounds (X, Y and Z, helical too, both ways round): the computed check
    refuses exactly the arcs sampling refuses, naming the same first point outside."""
    rng = np.random.default_rng(7)
    settings = cam.MachineSettings().replace(travel=cam.settings.Travel(0, 400, 0, 400, -100, 100))
    span_mm = 400 * 0.0289
    compared = refused_n = 0
    for _ in range(300):
        x0, y0 = rng.uniform(0.5, span_mm - 0.5), -rng.uniform(0.5, span_mm - 0.5)
        cx, cy = x0 + rng.uniform(-8, 8), y0 + rng.uniform(-8, 8)
        r = math.hypot(x0 - cx, y0 - cy)
        a1 = rng.uniform(0, 2 * math.pi)
        x1, y1 = cx + r * math.cos(a1), cy + r * math.sin(a1)
        z1 = rng.choice([0.0, rng.uniform(-2.5, 2.5)])
        g = rng.choice(["G2", "G3"])
        text = (f"G21 G90\nG0 X{x0:.6f} Y{y0:.6f}\n{g} X{x1:.6f} Y{y1:.6f} Z{z1:.6f} "
                f"I{cx - x0:.6f} J{cy - y0:.6f} F500\n")
        expected = _sampled_refusal(text, settings)
        try:
            plan_gcode(parse_gcode(text, source="arc.ngc"), settings)
            got = ""
        except cam.TravelError as exc:
            got = str(exc)
        assert got == expected, text
        compared += 1
        refused_n += bool(got)
    assert compared == 300 and 50 < refused_n < 250  # both kinds were seen


# -- HPGL coordinates and pens ----------------------------------------------------------------------------------

@pytest.mark.parametrize("data, where, fragment", [
    (f"IN;SP1;PU0,0;\nPD{DIGITS_400},0;PU;", "2:3", "the coordinate of more than 300 digits is out of range"),
    (f"IN;SP1;PU0,0;\nPD10,-{DIGITS_400};PU;", "2:6", "the coordinate of more than 300 digits"),
    (f"IN;SP1;PU0,0;\nPD1.{DIGITS_400},0;PU;", "2:3", "more than 300 digits"),  # a NaN in the tokenizer
    ("IN;SP1;PU0,0;\nPD99999999999999999999,0;PU;", "2:3", "the coordinate 1e+20 is out of range"),
    ("IN;SP1;PU0,0;\nPD40000001,0;PU;", "2:3", "the coordinate 4e+07 is out of range"),
    ("IN;SP1;PU0,0;PD10,0;\nPR30000000,0,30000000,0;PU;", "2:14", "after the relative move 3e+07 lies"),
    (f"IN;SP1;PU0,0;PD10,0;\nPR{DIGITS_400},0,-{DIGITS_400},0;PU;", "2:3", "out of range"),
    (f"IN;\nSP{DIGITS_400};PU0,0;PD10,0;PU;", "2:1", "'SP' takes one pen number (a whole number 0..999999)"),
], ids=short)
def test_hpgl_numbers_out_of_range_name_file_line_and_column(data, where, fragment):
    for read in (cam.parse_hpgl, lambda d, source: cam.scan_hpgl(__import__("io").BytesIO(d.encode()), source=source)):
        with pytest.raises(cam.ParseError) as info:
            read(data, source="big.plt")
        assert str(info.value).startswith(f"big.plt:{where}: ") and fragment in str(info.value), str(info.value)


def test_hpgl_coordinates_at_the_limit_are_read():
    d = cam.parse_hpgl("IN;SP1;PU0,0;PD40000000,-40000000;PU;PR-40000000,40000000;PD;")
    assert d.extent_pu() == (0.0, -40000000.0, 40000000.0, 0.0)


def test_cli_refuses_hpgl_numbers_in_one_line(tmp_path):
    path = tmp_path / "big.plt"
    path.write_text(f"IN;SP1;PU0,0;PD{DIGITS_400},0;PU;")
    for command in (["info", path], ["drill", path, "--yes", "--no-progress"], ["export", path, "-o", tmp_path / "o.ngc"]):
        refused(cli(*command), "big.plt:1:16:", "out of range")
    assert not (tmp_path / "o.ngc").exists()


# -- Excellon coordinates, tools and repeats ----------------------------------------------------------------------

def drill_file(*body: str, header: str = "T1C0.8") -> str:
    return "\n".join(["M48", "METRIC", header, "%", "T1", *body, "M30"]) + "\n"


@pytest.mark.parametrize("text, where, fragment", [
    (drill_file(f"X{DIGITS_400}.0Y1.0"), "6:1", "X999999999999999999999... is out of range"),
    (drill_file(f"X1.0Y-{DIGITS_400}.5"), "6:5", "Y-99999999999999999999... is out of range"),
    (drill_file("X1000000.1Y0"), "6:1", "X1000000.1 is out of range (at most 1e+06 mm either way)"),
    (drill_file("G91", "X900000.0Y0", "X900000.0Y0"), "8", "the position X1.8e+06 mm lies beyond 1e+06 mm"),
    (drill_file("G93X900000.0Y0", "X900000.0Y0"), "7", "the position X1.8e+06 mm lies beyond"),
    (drill_file("X0Y0", "R9000X200.0"), "7", "the position X1.0002e+06 mm lies beyond"),
    (drill_file("X1.0Y1.0", header=f"T1C{DIGITS_400}.0"), "3:3", "C999999999999999999999... is out of range"),
    (drill_file("X1.0Y1.0", header="T1000000C0.8"), "3:1", "T1000000 is out of range (a whole number 0..999999)"),
    (drill_file("X1.0Y1.0", header=f"T{'9' * 5000}C0.8"), "3:1", "is out of range (a whole number 0..999999)"),
    (drill_file("X1.0Y1.0", f"G{'9' * 5000}"), "7:1", "is out of range (a whole number 0..999999999)"),
    (drill_file("X1.0Y1.0", "R999999999X0.1"), "7:1", "R999999999 is out of range (a whole number 0..10000)"),
], ids=short)
def test_excellon_numbers_out_of_range_name_the_line(text, where, fragment):
    with pytest.raises(cam.ParseError) as info:
        cam.parse_excellon(text, source="big.drl")
    message = str(info.value)
    assert message.startswith(f"big.drl:{where}:") and fragment in message, message
    assert len(message) < 260


@pytest.mark.parametrize("header, why", [("T1C100.1", "T1 100.100 mm (larger than the 100 mm a drill may be)"),
                                         ("T1C0", "T1 0.000 mm (zero size)")])
def test_excellon_tools_that_cannot_be_drilled_are_left_out_or_refused(header, why):
    """A bad tool is not a bad file (issue #31 point 3): its holes are left out with a warning; strict refuses the
    file, naming the tool and the line of its hole."""
    h = cam.parse_excellon(drill_file("X1.0Y1.0", header=header), source="big.drl")
    assert len(h.holes_mm) == 0 and h.skipped == {1: 1} and any(why in w for w in h.warnings)
    with pytest.raises(cam.ParseError) as info:
        cam.parse_excellon(drill_file("X1.0Y1.0", header=header), source="big.drl", strict=True)
    assert str(info.value).startswith("big.drl:6: tool ") and why in str(info.value)


def test_excellon_repeats_are_bounded_in_all():
    """A repeat makes at most 10,000 holes and a file at most a million: 101 'R10000' lines, not billions."""
    text = drill_file("X0Y0", *["R10000X0.0001Y0"] * 101)
    with pytest.raises(cam.ParseError, match=r"big\.drl:\d+: more than 1000000 holes"):
        cam.parse_excellon(text, source="big.drl")
    assert len(cam.parse_excellon(drill_file("X0Y0", "R10000X0.001Y0")).holes_mm) == 10001


def test_cli_refuses_excellon_numbers_in_one_line(tmp_path):
    path = tmp_path / "big.drl"
    path.write_text(drill_file(f"X{DIGITS_400}.0Y1.0"))
    for command in (["info", path], ["drill", path, "--yes", "--no-progress"]):
        refused(cli(*command), "big.drl:6:1:", "out of range")
    path.write_text(drill_file("X1.0Y1.0", header=f"T{'9' * 5000}C0.8"))  # was a ValueError traceback
    refused(cli("info", path), "big.drl:3:1:", "out of range")


# -- profile CSVs and digitized matrices --------------------------------------------------------------------------

@pytest.mark.parametrize("text, where, fragment", [
    (f"{DIGITS_400}\n", "1", "depth '999999999999999999999...' is out of range: 0..1000000 Z pixels"),
    (f"3\n{DIGITS_400},4\n", "2", "expected layer 2, got '999999999999999999999...'"),  # an OverflowError before
    ("1\ninf\n", "2", "depth 'inf' is out of range"),
    ("1\n2,nan\n", "2", "depth 'nan' is out of range"),
    ("layer,depth\n1,3\n2,-1\n", "3", "depth '-1' is out of range"),
    ("1\n1e308,4\n", "2", "expected layer 2, got '1e308'"),
], ids=short)
def test_profile_csv_values_out_of_range_name_the_line(tmp_path, text, where, fragment):
    path = tmp_path / "p.csv"
    path.write_text(text)
    with pytest.raises(cam.ParseError) as info:
        cam.load_profile(path)
    assert str(info.value).startswith(f"{path}:{where}: ") and fragment in str(info.value), str(info.value)


def test_cli_refuses_profile_csv_values_in_one_line(tmp_path):
    from conftest import SAMPLES

    path = tmp_path / "p.csv"
    path.write_text(f"3\n{DIGITS_400},4\n")
    refused(cli("profile", path), "p.csv:2:", "expected layer 2")
    refused(cli("drill", SAMPLES / "disc.png", "--profile", path, "--no-progress"), "p.csv:2:", "expected layer 2")


def matrix(width, height, *rows, mode="2d"):
    return (f"# cam digitized matrix v1\n# mode={mode} width_px={width} height_px={height} objects=1 "
            f"points={len(rows)}\nobject,x,y,level\n" + "".join(f"{r}\n" for r in rows))


@pytest.mark.parametrize("text, where, fragment", [
    (matrix(DIGITS_400, 3, "1,1,1,1"), "2", "image size 999999999999...x3 px is out of range"),
    (matrix(100000, 100000, "1,1,1,1"), "2", "image size 100000x100000 px is out of range: at most 32768 px on a side"),
    (matrix(8000, 8000, "1,1,1,1"), "2", "and 16777216 px in all"),
    (matrix(3, 3, f"1,1,1,{DIGITS_400}"), "4", "level must be 1..9 (the image's pixel count), got 999999999999..."),
    (matrix(3, 3, "1,1,1,10", mode="3d"), "4", "level must be 1..9"),
], ids=short)
def test_digitized_matrix_sizes_and_levels_in_range(text, where, fragment):
    with pytest.raises(cam.ParseError) as info:
        parse_digitized(text, source="m.txt")
    assert str(info.value).startswith(f"m.txt:{where}: ") and fragment in str(info.value), str(info.value)


def test_cli_refuses_a_huge_digitized_matrix_in_one_line(tmp_path):
    path = tmp_path / "m.txt"
    path.write_text(matrix(100000, 100000, "1,1,1,1"))  # tried to allocate 74.5 GiB
    refused(cli("drill", path, "--no-progress"), "m.txt:2:", "out of range")
    path.write_text(matrix(3, 3, f"1,1,1,{DIGITS_400}"))  # an OverflowError traceback
    refused(cli("drill", path, "--no-progress"), "m.txt:4:", "level must be")


def test_a_program_longer_than_a_year_is_refused_naming_the_line():
    """Each dwell is at most an hour, so 8761 of them pass a year (3 million would overflow the plan's clock)."""
    text = "G21\n" + "G4 P3600\n" * 8761
    with pytest.raises(cam.PlanError, match=r"long\.ngc:8762: the program takes more than 365 days up to this line"):
        plan_gcode(parse_gcode(text, source="long.ngc"))
    assert len(plan_gcode(parse_gcode("G21\n" + "G4 P3600\n" * 8760)).points_steps) == 8760
