"""grbl's dialect in (issue #30 point 5): what programs written for grbl carry runs as grbl runs it.

An arc's centre word of another plane (FreeCAD's grbl post writes ``K0`` on XY arcs) is ignored; ``$`` lines (grbl's
own commands) are skipped with one warning; ``%`` lines mark the program as in LinuxCNC, with one warning when lines
follow the closing one; a UTF-8 byte-order mark is accepted; M3/M4/M5 and S are recorded with every move (for ports
that switch a spindle) with one note that a step/dir port ignores them; Marlin's words are refused naming Marlin.
"""
import numpy as np
import pytest

import cam
from cam.formats.gcode import load_gcode, open_gcode, parse_gcode

from test_cli import assert_one_line_error, cli

FREECAD_GRBL = """(Exported by FreeCAD)
(Post Processor: grbl_post)
(begin preamble)
G17 G90
G21
(begin operation: Profile)
G0 Z5.000
G0 X10.000 Y-10.000
G1 Z-0.500 F100.00
G2 X20.000 Y-10.000 Z-0.500 I5.000 J0.000 K0.000 F300.00
G3 X30.000 Y-10.000 Z-0.500 I5.000 J0.000 K0.000 F300.00
G1 X30.000 Y-20.000 F300.00
G0 Z5.000
(begin postamble)
M5
G17 G90
M2
"""


def _ends(program) -> list:
    return [(m.kind, m.end, m.center, m.clockwise) for m in program.moves]


def _without(text: str, word: str) -> str:
    return "\n".join(" ".join(w for w in line.split(" ") if not w.startswith(word)) for line in text.splitlines())


def test_an_xy_arc_with_k0_runs_as_grbl_runs_it(tmp_path):
    program = parse_gcode(FREECAD_GRBL, source="freecad.nc")
    assert program.warnings == []
    assert _ends(program) == _ends(parse_gcode(_without(FREECAD_GRBL, "K"), source="freecad.nc"))
    assert [m.kind for m in program.moves].count("arc") == 2
    path = tmp_path / "freecad.nc"
    path.write_text(FREECAD_GRBL)
    proc = cli("drill", path, "--state", tmp_path / "s.json", "--no-progress")
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("plane, arc, back, word", [
    ("G17", "G2 X20 Y-10 I5 J0 K2", "G2 X10 Y-10 I-5 J0 K2", "'K2'"),
    ("G18", "G2 X20 Z-0.5 I5 K0 J3", "G2 X10 Z-0.5 I-5 K0 J3", "'J3'"),
    ("G19", "G2 Y-20 Z-0.5 J-5 K0 I1.5", "G2 Y-10 Z-0.5 J5 K0 I1.5", "'I1.5'"),
])
def test_another_planes_centre_word_is_ignored_with_one_warning(plane, arc, back, word):
    head = f"G21 G90\nG0 X10 Y-10 Z-0.5\n{plane}\nG1 F300\n"
    text = head + f"{arc}\n{back}\nM2\n"
    program = parse_gcode(text, source="k.nc")
    assert len(program.warnings) == 1
    assert program.warnings[0].startswith("k.nc:5: " + word) and "ignored, as grbl does" in program.warnings[0]
    plain = parse_gcode(_without(text, word[1]), source="k.nc")
    assert _ends(program) == _ends(plain) and plain.warnings == []


def test_dollar_lines_are_skipped_with_one_warning():
    text = "$H\n$X\nG21 G90\n$32=0\nG0 X5 Y-5\nG1 Z-0.2 F100\nG0 Z1\nM2\n"
    program = parse_gcode(text, source="ugs.nc")
    assert program.warnings == ["ugs.nc:1: grbl system command '$H' skipped (and any later '$' lines): it is a "
                                "command to grbl itself, not G-code"]
    assert _ends(program) == _ends(parse_gcode(text.replace("$H\n", "").replace("$X\n", "")
                                               .replace("$32=0\n", ""), source="ugs.nc"))


def test_percent_lines_mark_the_program_and_what_follows_the_closing_one_is_said():
    text = "%\nG21 G90\nG0 X5\n%\n"
    program = parse_gcode(text, source="p.nc")
    assert program.warnings == [] and [m.end for m in program.moves] == [(5.0, 0.0, 0.0)]
    program = parse_gcode(text + "(after)\nG0 X9\n", source="p.nc")
    assert [m.end for m in program.moves] == [(5.0, 0.0, 0.0)]  # LinuxCNC's rule: the closing '%' ends it
    assert len(program.warnings) == 1 and program.warnings[0].startswith("p.nc:4: the program ends at this '%'") \
        and "line 6" in program.warnings[0]


def test_a_utf8_byte_order_mark_is_accepted(tmp_path):
    text = "G21 G90\nG0 X5 Y-5\nG1 Z-0.2 F100\nG0 Z1\nM2\n"
    plain = _ends(parse_gcode(text))
    assert _ends(parse_gcode("\ufeff" + text)) == plain
    path = tmp_path / "bom.nc"
    path.write_bytes(b"\xef\xbb\xbf" + text.encode())
    assert _ends(load_gcode(path)) == plain
    f = open_gcode(path)
    assert [(m.kind, m.end, m.center, m.clockwise) for b in f.move_batches(1) for m in b.moves] == plain
    # an O word on the first line, after the mark
    sub = tmp_path / "sub.ngc"
    sub.write_bytes(b"\xef\xbb\xbfo<sub> sub\nG0 X#1\no<sub> endsub\no<sub> call [3]\nM2\n")
    assert [m.end for m in load_gcode(sub).moves] == [(3.0, 0.0, 0.0)]
    proc = cli("drill", path, "--state", tmp_path / "s.json", "--no-progress")
    assert proc.returncode == 0, proc.stderr


def test_spindle_words_are_recorded_with_the_moves_and_noted_once():
    text = "G21 G90\nG0 Z2\nS12000 M3\nG0 X5\nS8000\nG1 Z-0.2 F100\nM5\nG0 Z2\nM4 S500\nG4 P0.1\nM5\nM2\n"
    program = parse_gcode(text, source="s.nc")
    assert [(m.kind, m.spindle, m.spindle_rpm) for m in program.moves] == [
        ("rapid", 0, 0.0), ("rapid", 3, 12000.0), ("feed", 3, 8000.0), ("rapid", 0, 0.0), ("dwell", 4, 500.0)]
    assert len(program.warnings) == 1
    assert program.warnings[0].startswith("s.nc:3: spindle M3 S12000 recorded with the moves") and \
        "ignores it" in program.warnings[0]
    assert parse_gcode("G21\nS1000\nG0 X1\nM2\n").warnings == []  # S alone: the spindle is not switched on


def test_the_spindle_note_is_a_warning_of_cam_drill(tmp_path):
    path = tmp_path / "s.nc"
    path.write_text("G21\nM3 S1000\nG0 X1 Y-1\nM5\nM2\n")
    proc = cli("drill", path, "--state", tmp_path / "s.json", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("warning:") == 1 and "s.nc:2: spindle M3 S1000 recorded" in proc.stderr


@pytest.mark.parametrize("line, word", [
    ("M17", "'M17'"), ("G1 X10 Y10 E1.5 F1200", "'E1.5'"), ("M104 S200", "'M104'"), ("M140 S60", "'M140'"),
    ("G29", "'G29'"), ("M107", "'M107'"), ("M84", "'M84'"),
])
def test_marlin_words_are_refused_naming_the_dialect(tmp_path, line, word):
    """Marlin's own words say so; those that are LinuxCNC user M codes too (M104, M140, M107) are refused as user
    M codes, naming Marlin as well."""
    path = tmp_path / "print.gcode"
    path.write_text(f";FLAVOR:Marlin\nG21\n{line}\nG1 X1 F100\n")
    with pytest.raises(cam.ParseError, match="print.gcode:3: .*" + word.replace(".", r"\.") + ".* Marlin"):
        load_gcode(path)
    assert_one_line_error(cli("drill", path, "--state", tmp_path / "s.json"), "print.gcode:3:", word,
                          "Marlin (3D printer firmware)", "not a mill")


def test_a_spindle_state_does_not_change_the_motion():
    text = "G21 G90\nG0 X5 Y-5\nG1 Z-0.2 F100\nG2 X10 Y-5 I2.5 J0\nG0 Z1\nM2\n"
    plain = parse_gcode(text)
    spun = parse_gcode(text.replace("G0 X5", "M3 S9000 G0 X5"))
    assert _ends(plain) == _ends(spun)
    assert np.all([m.spindle == 3 for m in spun.moves])
