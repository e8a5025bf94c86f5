"""Excellon reader: generated files in the styles of several PCB programs agree with gerbonara and with the
holes as written; literal files for every feature, error and warning; the CLI's info and drill."""
from __future__ import annotations

import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from cam.cli import main
from cam.errors import CamError, ParseError
from cam.formats.excellon import HoleList, load_excellon, parse_excellon

from conftest import ROOT, run_cli

sys.path.insert(0, str(Path(__file__).parent))
import excellon_gen as gen  # noqa: E402

BOARD = gen.realistic_board(seed=3)  # ~250 holes, five tools


def _gerbonara(text: str, settings, name: str):
    """Holes (N, 2) mm and diameters (N,) mm of every drilled hole as gerbonara reads them."""
    from gerbonara import ExcellonFile
    from gerbonara.cam import FileSettings
    from gerbonara.graphic_objects import Flash
    from gerbonara.utils import MM, Inch

    fs = None
    if settings is not None:
        units, digits, zeros = settings
        fs = FileSettings(unit=Inch if units == "inch" else MM, number_format=digits, zeros=zeros)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ef = ExcellonFile.from_string(text, settings=fs, filename=name)
    flashes = [o for o in ef.objects if isinstance(o, Flash)]
    xy = np.array([[o.unit.convert_to(MM, o.x), o.unit.convert_to(MM, o.y)] for o in flashes]).reshape(-1, 2)
    dia = np.array([o.tool.equivalent_width(MM) for o in flashes])
    return xy, dia


@pytest.mark.parametrize("style", sorted(gen.STYLES))
def test_generated_styles_match_gerbonara_and_the_written_holes(style):
    g = gen.STYLES[style](BOARD)
    holes = parse_excellon(g.text, source=f"{style}.drl")
    assert len(holes.holes_mm) == len(BOARD.holes_mm) > 200
    # the holes as written, in file order, with their tools
    np.testing.assert_allclose(holes.holes_mm, g.holes_mm, rtol=0, atol=1e-9)
    assert holes.tool_of_hole.tolist() == g.tool_of_hole.tolist()
    assert holes.tools == pytest.approx(g.tools, abs=1e-12)
    assert len(holes.tools) == 5
    # gerbonara (the reference) reads the same positions and diameters
    xy, dia = _gerbonara(g.gerbonara_text or g.text, g.gerbonara_settings, style)
    assert xy.shape == holes.holes_mm.shape
    np.testing.assert_allclose(holes.holes_mm, xy, rtol=0, atol=1e-6)
    np.testing.assert_allclose([holes.tools[t] for t in holes.tool_of_hole], dia, rtol=0, atol=1e-6)
    # a file that states its format reads without warnings; one that does not says what was assumed
    if g.states_format:
        assert holes.warnings == []
    else:
        assert holes.warnings and all("does not state" in w for w in holes.warnings)
    assert holes.line_of_hole.min() > 1 and np.all(np.diff(holes.line_of_hole) > 0)


def test_the_format_given_by_the_caller_is_used_when_the_file_does_not_say():
    g = gen.eagle_inch_2_4(BOARD)
    holes = parse_excellon(g.text, excellon_units="inch", excellon_digits=(2, 4), excellon_zeros="TZ")
    assert holes.warnings == []
    np.testing.assert_allclose(holes.holes_mm, g.holes_mm, rtol=0, atol=1e-9)
    # another digit split moves the decimal point: 3:3 metric file read as 4:2
    m = gen.metric_tz_implied(BOARD)
    wide = parse_excellon(m.text, excellon_digits=(4, 2))
    np.testing.assert_allclose(wide.holes_mm, m.holes_mm * 10, rtol=0, atol=1e-9)
    # ... but what the file states wins over the caller
    k = gen.kicad_inch_suppress_leading(BOARD)
    stated = parse_excellon(k.text, excellon_units="metric", excellon_digits=(3, 3), excellon_zeros="LZ")
    np.testing.assert_allclose(stated.holes_mm, k.holes_mm, rtol=0, atol=1e-9)


def _one(text: str, **kw) -> HoleList:
    return parse_excellon(text, source="t.drl", **kw)


def _xy(text: str, **kw) -> list[list[float]]:
    return np.round(_one(text, **kw).holes_mm, 9).tolist()


def test_zero_suppression_and_digit_formats():
    # LZ keeps leading zeros: digits read from the left; TZ keeps trailing zeros: read from the right
    assert _xy("M48\nMETRIC,LZ\nT1C0.8\n%\nT1\nX0125Y-0005\nM30\n", excellon_digits=(3, 3)) == [[12.5, -0.5]]
    assert _xy("M48\nMETRIC,TZ\nT1C0.8\n%\nT1\nX12500Y-500\nM30\n", excellon_digits=(3, 3)) == [[12.5, -0.5]]
    assert _xy("M48\nINCH,LZ\nT1C0.02\n%\nT1\nX01Y00005\nM30\n") == [[25.4, 0.127]]
    assert _xy("M48\nINCH,TZ\nT1C0.02\n%\nT1\nX10000Y50\nM30\n") == [[25.4, 0.127]]
    # the format in the units line, in a KiCad, Altium or Siemens comment
    assert _xy("M48\nMETRIC,TZ,0000.00\nT1C0.8\n%\nT1\nX1250Y5\nM30\n") == [[12.5, 0.05]]
    assert _xy("M48\n; FORMAT={3:3/ absolute / metric / suppress trailing zeros}\nMETRIC,LZ\nT1C.8\n%\nT1\nX0125Y0\n"
               ) == [[12.5, 0.0]]
    assert _xy("M48\n; FORMAT={2:4/ absolute / inch / keep zeros}\nINCH,TZ\nT1C.02\n%\nT1\nX010000Y-005000\n"
               ) == [[25.4, -12.7]]
    assert _xy("M48\n;FILE_FORMAT=2:5\nINCH,LZ\nT1F00S00C0.03150\n%\nT01\nX0085Y-001\nM30\n") == [[21.59, -2.54]]
    assert _xy("M48\n; Format : 3.3 / Absolute / MM / Leading\nT1C0.8\n%\nT1\nX0125Y005\nM30\n") == [[12.5, 5.0]]
    # decimal points win over any format; signs; M71/M72 switch units
    assert _xy("M48\nINCH,LZ\nT1C0.02\n%\nT1\nX+1.5Y-.25\nM71\nX2.Y3.\nM30\n") == [[38.1, -6.35], [2.0, 3.0]]


def test_modal_incremental_zero_set_and_repeated_holes():
    text = "M48\nMETRIC\nT1C1.0\n%\nT1\nX10.0Y20.0\nX15.0\nY25.0\nG91\nX1.0\nY-2.0X-1.0\nG90\nX0Y0\nM30\n"
    assert _xy(text) == [[10, 20], [15, 20], [15, 25], [16, 25], [15, 23], [0, 0]]
    assert _xy("M48\nMETRIC\nICI,ON\nT1C1.0\n%\nT1\nX1.0Y1.0\nX1.0\nM30\n") == [[1, 1], [2, 1]]
    assert _xy("M48\nMETRIC\nT1C1.0\n%\nG93X10.0Y5.0\nT1\nX1.0Y1.0\nM30\n") == [[11, 6]]
    assert _xy("M48\nMETRIC\nT1C1.0\n%\nT1\nX1.0Y1.0\nR3X2.54Y0\nM30\n") == [[1, 1], [3.54, 1], [6.08, 1], [8.62, 1]]


def test_tools_selection_definitions_and_table():
    text = ("M48\nMETRIC\nT01C0.80F200S65\nT2S100F50C1.0B10H2000Z0.1\nT3C3.2\n%\nT1\nX1.0Y1.0\nT02\nX2.0Y2.0\n"
            "T1\nX3.0Y3.0\nT0\nT4C0.5\nX4.0Y4.0\nM30\n")
    h = _one(text)
    assert h.tool_of_hole.tolist() == [1, 2, 1, 4]  # T1 == T01; a definition in the body selects the tool
    assert h.tools == {1: 0.8, 2: 1.0, 3: 3.2, 4: 0.5}
    assert h.tool_table() == [(1, 0.8, 2), (2, 1.0, 1), (3, 3.2, 0), (4, 0.5, 1)]  # every defined tool
    assert h.extent_mm() == (1.0, 1.0, 4.0, 4.0)
    assert h.line_of_hole.tolist() == [8, 10, 12, 15]
    assert h.warnings == []
    # inch diameters become mm; the OrCAD file of seed 000 Table 8-1 (no header, '%' first)
    t = _one("%\nT1C0.034F200S100\nX003000Y003000\nX004000Y003000\nX009000Y006000\nM30\n")
    assert t.tools == {1: pytest.approx(0.8636)}
    assert np.round(t.holes_mm, 9).tolist() == [[7.62, 7.62], [10.16, 7.62], [22.86, 15.24]]
    assert HoleList(np.zeros((0, 2)), np.zeros(0, np.int64), {}, np.zeros(0, np.int64)).extent_mm() == (0, 0, 0, 0)


def _error(text: str, **kw) -> str:
    with pytest.raises(ParseError) as info:
        _one(text, **kw)
    msg = str(info.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize("text, line, what", [
    ("M48\nMETRIC\nT1C0.8\n%\nT1\nX1.0Y1.0\nX12345678Y1\n", "X12345678Y1", "7:1: X12345678 has 8 digits, more than the 3:3"),
    ("M48\nINCH,LZ\nT1C0.8\n%\nT1\nX1.2.3Y1\n", "X1.2.3Y1", "6:1: X needs a number, got '1.2.3'"),
    ("M48\nINCH\nT1C0.8\n%\nT1\nX-Y1\n", "X-Y1", "6:1: X needs a number"),
    ("M48\nMETRIC\nT1C0.8\n%\nX1.0Y1.0\n", "X1.0Y1.0", "5: a hole before any tool is selected"),
    ("M48\nMETRIC\nT1C0.8\n%\nT1\nX1.0Y1.0\nT0\nX2.0Y1.0\n", "X2.0Y1.0", "8: a hole before any tool"),
    ("M48\nMETRIC\nT1C0.8\n%\nT2\nX1.0Y1.0\n", "T2", "5: tool T2 is selected but never defined"),
    ("M48\nMETRIC\nT1C-0.8\n%\n", "T1C-0.8", "3:3: tool T1 has a bad diameter -0.8"),
    ("M48\nMETRIC\nT1F200S100\n%\n", "T1F200S100", "3: tool T1 is defined without a diameter"),
    ("M48\nMETRIC\nT1C0.8Q5\n%\n", "T1C0.8Q5", "3:7: unexpected Q5 in a tool definition"),
    ("M48\nFMAT,3\n", "FMAT,3", "2: FMAT takes 1 or 2"),
    ("M48\nMETRIC,XZ\n", "METRIC,XZ", "2: unknown METRIC option 'XZ'"),
    ("M48\nMETRIC\nT1C0.8\n%\nT1\nM25\nX1.0Y1.0\nM01\nM02X5.0Y0\nM30\n", "M25", "6: repeated patterns"),
    ("M48\nMETRIC\nT1C0.8\n%\nT1\nQ17\n", "Q17", "6: unknown statement"),
    ("M48\nMETRIC\nT1C0.8\n%\nG91X1.0\n", "G91X1.0", "5:4: G91 takes no coordinates"),
])
def test_errors_name_file_line_and_text(text, line, what):
    msg = _error(text)
    assert msg.startswith("t.drl:") and what in msg and msg.endswith(f": '{line}'"), msg


@pytest.mark.parametrize("text, where", [
    ("hello world\nthis is not a drill file\n", "t.drl:1:"),
    ("G21\nG0 X10 Y10\nM30\n", "t.drl:1:"),
    ("%FSLAX46Y46*%\n%MOMM*%\n", "t.drl:1:"),
    ("; only a comment\n\n", "t.drl:"),
    ("", "t.drl:"),
    ("Hello, world\n", "t.drl:1:"),
    ("T1 is great\nX1 marks the spot\n", "t.drl:1:"),
])
def test_text_that_is_not_excellon_is_named_so(text, where):
    msg = _error(text)
    assert msg.startswith(where) and "not an Excellon drill file" in msg


def test_binary_and_missing_files(tmp_path):
    png = tmp_path / "board.drl"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    with pytest.raises(ParseError, match=r"board\.drl: not an Excellon drill file \(binary"):
        load_excellon(png)
    with pytest.raises(CamError, match="cannot read"):
        load_excellon(tmp_path / "missing.drl")
    with pytest.raises(CamError, match="zeros"):
        parse_excellon("M48\n", excellon_zeros="leading")
    with pytest.raises(CamError, match="digits"):
        parse_excellon("M48\n", excellon_digits=(2, 9))


def _warnings(text: str) -> tuple[HoleList, list[str]]:
    h = _one(text)
    return h, h.warnings


def test_slots_routing_and_other_oddities_are_warnings_with_the_line():
    text = "\n".join([
        "M48", "METRIC", "T1C0.8", "T2C2.0", "T1C0.9", "%", "T1", "X1.0Y1.0",
        "X2.0Y2.0G85X5.0Y2.0",        # 9: slot
        "T2", "G00X10.0Y10.0", "M15", "G01X20.0Y10.0", "G02X25.0Y15.0I5.0J0", "M16",  # 11: routing
        "G05", "X30.0Y30.0",          # back to drilling: a hole
        "M97,ABC",                    # 18: canned text
        "M123",                       # 19: unknown M code
        "M30", "X40.0Y40.0",          # 21: after the end
    ]) + "\n"
    h, w = _warnings(text)
    assert np.round(h.holes_mm, 9).tolist() == [[1, 1], [30, 30]]
    assert h.tool_of_hole.tolist() == [1, 2]
    expect = [
        ("t.drl:5:", "tool T1 redefined", "T1C0.9"),
        ("t.drl:9:", "slot (G85)", "X2.0Y2.0G85X5.0Y2.0"),
        ("t.drl:11:", "routing", "G00X10.0Y10.0"),
        ("t.drl:18:", "canned text", "M97,ABC"),
        ("t.drl:19:", "M123 ignored", "M123"),
        ("t.drl:21:", "after the end of the program", "X40.0Y40.0"),
    ]
    assert len(w) == len(expect), w
    for msg, (where, what, line) in zip(w, expect):
        assert msg.startswith(where) and what in msg and msg.endswith(f": '{line}'"), msg
    # the tool of a slot-only or route-only file still shows, with no holes, and its slot is kept (issue #31)
    only, ws = _warnings("M48\nMETRIC\nT1C2.0\n%\nT1\nX0Y0G85X1.0Y0\nM30\n")
    assert only.tool_table() == [(1, 2.0, 0)] and only.slot_paths_mm[0].tolist() == [[0, 0], [1, 0]]  # milled


def test_headers_from_other_programs_are_accepted():
    # Fritzing-like '%' before M48, header machine commands, FMAT 1 ends with M02, CRLF line ends, lower case
    text = "%\r\nM48\r\nVER,1\r\nDETECT,ON\r\nATC,ON\r\nFMAT,1\r\nINCH,TZ\r\nt1c0.04\r\n%\r\nG81\r\nT01\r\nx10000y2500\r\nM02\r\n"
    h = _one(text + "%\n")  # a tape end mark after the end is no oddity
    assert np.round(h.holes_mm, 9).tolist() == [[25.4, 6.35]]
    assert len(h.warnings) == 1 and "t.drl:12: the file does not state its digits (2:4)" in h.warnings[0]
    # holes inside the header, and M95 as the end of the header
    assert _xy("M48\nMETRIC\nT1C1\nT1\nX1.0Y2.0\nM95\nX3.0Y4.0\nM30\n") == [[1, 2], [3, 4]]


# -- the command line ------------------------------------------------------------------------------------

def test_info_prints_tools_extent_and_warnings(tmp_path, capsys):
    g = gen.altium_inch_2_5(BOARD)
    path = tmp_path / "altium.drl"
    path.write_text(g.text.replace("M30\n", "X0Y0G85X01Y0\nM30\n"))
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    holes = parse_excellon(g.text)
    x0, y0, x1, y1 = holes.extent_mm()
    assert f"{len(g.holes_mm)} holes" in out
    assert f"X {x0:.3f}..{x1:.3f} mm" in out and f"Y {y0:.3f}..{y1:.3f} mm" in out
    for tool, dia, count in holes.tool_table():
        assert f"T{tool}: {dia:.3f} mm, {count} holes" in out
    line = len(g.text.splitlines())  # the slot takes the place of the last line (M30)
    assert re.search(rf"warning: {re.escape(str(path))}:{line}: slot \(G85\).*'X0Y0G85X01Y0'", out)


def test_info_and_drill_on_a_bad_file_give_one_line_and_code_2(tmp_path, capsys):
    bad = tmp_path / "bad.drl"
    bad.write_text("M48\nMETRIC\nT1C0.8\n%\nT1\nX1.0Y1.0\nX123456789Y0\nM30\n")
    for cmd in (["info", str(bad)], ["drill", str(bad), "--yes", "--no-progress"]):
        assert main(cmd) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"{bad}:7:1:" in err and "'X123456789Y0'" in err
    png = tmp_path / "picture.drl"
    png.write_bytes((ROOT / "samples" / "disc.png").read_bytes())
    assert main(["info", str(png)]) == 0  # the content wins, with a warning (issue #16): never a silent misread
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "says an Excellon drill file but the content is an image" in err


def test_info_uses_the_excellon_format_options(tmp_path, capsys):
    g = gen.eagle_inch_2_4(BOARD)
    path = tmp_path / "eagle.drl"
    path.write_text(g.text)
    assert main(["info", str(path), "--excellon-units", "inch", "--excellon-digits", "2:4",
                 "--excellon-zeros", "TZ"]) == 0
    out = capsys.readouterr().out
    assert "warning" not in out
    assert main(["info", str(path), "--excellon-units", "metric", "--excellon-digits", "3:3"]) == 0
    out = capsys.readouterr().out
    metric = parse_excellon(g.text, excellon_units="metric", excellon_digits=(3, 3))
    x0, _, x1, _ = metric.extent_mm()
    assert f"X {x0:.3f}..{x1:.3f} mm" in out and "warning" in out  # zeros still assumed


def test_the_shipped_sample_is_what_the_generator_writes():
    path = ROOT / "samples" / "board.drl"
    assert path.read_text() == gen.sample_board().text
    h = load_excellon(path)
    x0, y0, x1, y1 = h.extent_mm()
    assert 0 <= x0 and x1 <= 100 and 0 <= y0 and y1 <= 80
    assert [(t, d) for t, d, _ in h.tool_table()] == [(1, 0.8), (2, 1.0), (3, 3.2)]
    assert 35 <= len(h.holes_mm) <= 50 and h.warnings == []


def test_drill_the_sample_on_the_mock_port():
    r = run_cli("drill", "samples/board.drl", "--yes", "--no-progress", cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert "T1 0.800 mm" in r.stderr + r.stdout and "T3 3.200 mm" in r.stderr + r.stdout


@pytest.mark.parametrize("name", sorted(gen.drill_samples()))
def test_shipped_drill_samples_are_what_the_generator_writes_and_info_reads_them(name, capsys):
    g = gen.drill_samples()[name]
    path = ROOT / "samples" / "drill" / name
    assert path.read_text() == g.text
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{path}: {len(g.holes_mm)} holes, board extent")
    assert len(re.findall(r"^  T\d+: \d+\.\d{3} mm, \d+ holes$", out, re.M)) == 5
