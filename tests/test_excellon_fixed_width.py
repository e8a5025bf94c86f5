"""Fixed-width drill coordinates with no zero suppression (issue #44 points 1 and 6): Cadence Allegro's NC drill
tape (3:5 inch, tool sizes only in ';T01 Holesize' comments, the format only in nc_param.txt / ncdrill.log beside
it) and Zuken CR-8000's .fdr (4:4 inch), made by tests/excellon_gen.py in each program's habits.  The digits are
chosen by plausibility among the splits of the field's width, weighed by the hole sizes; a --excellon-digits that
the hole sizes cannot fit is a one-line warning naming the plausible format."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from cam.cli import main
from cam.formats.excellon import load_excellon, parse_excellon, parse_nc_param

sys.path.insert(0, str(Path(__file__).parent))
import excellon_gen as gen  # noqa: E402
from test_excellon import _gerbonara  # noqa: E402

MIL_MM = 0.0254
# a MinnowMax-sized board (99 x 74 mm): 8 mil vias, 32 / 40 / 52 mil pins, 125 mil mounting holes
BOARD = gen.apart(gen.realistic_board(seed=5, size_mm=(99.0, 74.0),
                                      diameters_mm=(8 * MIL_MM, 32 * MIL_MM, 40 * MIL_MM, 52 * MIL_MM, 125 * MIL_MM)))
ALLEGRO = gen.allegro_fixed_width(BOARD)
ALLEGRO_NAME = "MinnowMax_RevA1_NCDRILL.drl"


def _allegro(tmp_path: Path, *beside: str) -> Path:
    path = tmp_path / ALLEGRO_NAME
    path.write_bytes(ALLEGRO.text.encode("ascii"))
    for name in beside:
        text = gen.allegro_nc_param() if name == "nc_param.txt" else gen.allegro_ncdrill_log(ALLEGRO)
        (tmp_path / name).write_bytes(text.encode("ascii"))
    return path


def _format_warnings(holes) -> list[str]:
    return [w for w in holes.warnings if "does not state" in w]


def test_the_allegro_file_has_allegros_habits():
    lines = ALLEGRO.text.split("\r\n")
    assert lines[:3] == [";LEADER: 12", ";HEADER:", ";CODE  : ASCII"]
    assert ";T01 Holesize 1. = 8.000000 Tolerance = +2.000000/-2.000000 PLATED MILS Quantity = " in ALLEGRO.text
    assert "M48" not in lines and lines[lines.index("%") + 1] == "G90" and lines[-2] == "M30"
    coords = [ln for ln in lines if ln[:1] in "XY"]
    assert all(len(w) == 9 for ln in coords for w in ln.replace("Y", " Y").split())  # letter + 8 digits
    assert any("Y" not in ln for ln in coords) and any(not ln.startswith("X") for ln in coords)  # equal axes left out


def test_allegro_without_nc_param_reads_where_gerbonara_puts_it_with_3_5_inch(tmp_path):
    holes = load_excellon(_allegro(tmp_path))
    assert len(holes.holes_mm) == len(BOARD.holes_mm) > 200
    np.testing.assert_allclose(holes.holes_mm, ALLEGRO.holes_mm, rtol=0, atol=1e-9)
    assert holes.tools == pytest.approx(ALLEGRO.tools, abs=1e-12)
    assert holes.tool_of_hole.tolist() == ALLEGRO.tool_of_hole.tolist()
    xy, dia = _gerbonara(ALLEGRO.text, ("inch", (3, 5), "trailing"), ALLEGRO_NAME)  # Allegro's nc_param.txt
    np.testing.assert_allclose(holes.holes_mm, xy, rtol=0, atol=1e-6)
    np.testing.assert_allclose([holes.tools[t] for t in holes.tool_of_hole], dia, rtol=0, atol=1e-6)
    (w,) = _format_warnings(holes)
    assert "\n" not in w and f"{ALLEGRO_NAME}:" in w
    chosen, runner = w.split("read as the most plausible: ")[1].split("; the runner-up ")
    assert chosen.startswith("inch 3:5 (") and not runner.startswith("inch 3:5")
    assert "X00" in w  # the line of the first number read so


@pytest.mark.parametrize("beside", ["nc_param.txt", "ncdrill.log"])
def test_allegro_nc_param_or_ncdrill_log_beside_the_file_gives_the_format(tmp_path, beside):
    path = _allegro(tmp_path, beside)
    holes = load_excellon(path)
    assert _format_warnings(holes) == []  # stated beside the file: nothing is guessed
    np.testing.assert_allclose(holes.holes_mm, ALLEGRO.holes_mm, rtol=0, atol=1e-9)
    assert holes.tools == pytest.approx(ALLEGRO.tools, abs=1e-12)
    # its values are used, even where plausibility would choose otherwise
    (tmp_path / beside).write_text((tmp_path / beside).read_text().replace("3.5", "2.6"))
    tenth = load_excellon(path)
    np.testing.assert_allclose(tenth.holes_mm, ALLEGRO.holes_mm / 10, rtol=0, atol=1e-9)
    assert _format_warnings(tenth) == []


def test_nc_param_with_no_zero_suppression_and_log_tool_lines():
    stated = parse_nc_param(gen.allegro_nc_param())
    assert (stated["units"], stated["digits"], stated["zeros"], stated["incremental"]) == ("inch", (3, 5), "TZ", False)
    log = parse_nc_param(gen.allegro_ncdrill_log(ALLEGRO))
    assert log["digits"] == (3, 5) and log["tools"] == pytest.approx(ALLEGRO.tools, abs=1e-12)
    assert parse_nc_param("INTEGER-PLACES 2\nDECIMAL-PLACES 4\n")["digits"] == (2, 4)


def test_zuken_fdr_with_8_digit_coordinates_reads_as_4_4_inch(tmp_path):
    z = gen.zuken_fdr(BOARD)
    assert z.text.startswith("M48\nINCH,LZ\nICI,OFF\nVER,1\nFMAT,2\n") and "X000" in z.text and "Y-000" in z.text
    path = tmp_path / "8seg_Driver_Drill_thru_plt.fdr"
    path.write_text(z.text)
    holes = load_excellon(path)
    np.testing.assert_allclose(holes.holes_mm, z.holes_mm, rtol=0, atol=1e-9)
    xy, _ = _gerbonara(z.text, z.gerbonara_settings, path.name)
    np.testing.assert_allclose(holes.holes_mm, xy, rtol=0, atol=1e-6)
    (w,) = _format_warnings(holes)
    assert "does not state its digits (4:4)" in w and "most plausible: 4:4 (" in w and "runner-up 3:5" in w
    assert "units" not in w.split(";")[0]  # INCH is stated
    assert main(["info", str(path)]) == 0


def test_a_forced_digit_format_the_hole_sizes_cannot_fit_is_one_warning(tmp_path, capsys):
    wrong = parse_excellon(ALLEGRO.text, source=ALLEGRO_NAME, excellon_units="inch", excellon_digits=(2, 6))
    np.testing.assert_allclose(wrong.holes_mm, ALLEGRO.holes_mm / 10, rtol=0, atol=1e-9)  # still what was asked
    (w,) = [w for w in wrong.warnings if "--excellon-digits" in w]
    assert "\n" not in w and w.startswith(f"{ALLEGRO_NAME}:") and "--excellon-digits 2:6" in w
    assert "3:5 is more plausible" in w and "cut into their neighbour" in w
    right = parse_excellon(ALLEGRO.text, source=ALLEGRO_NAME, excellon_units="inch", excellon_digits=(3, 5))
    assert right.warnings == []
    # the command line says it too (and still reads)
    path = _allegro(tmp_path)
    assert main(["info", str(path), "--excellon-units", "inch", "--excellon-digits", "2:6"]) == 0
    said = capsys.readouterr()
    err = [e for e in (said.out + said.err).splitlines() if "--excellon-digits 2:6" in e]
    assert len(err) == 1 and "3:5 is more plausible" in err[0]
    # hole sizes that scale with the digits (C definitions) say nothing of them: no such warning
    g = gen.eagle_inch_2_4(BOARD)
    assert not any("more plausible" in w for w in parse_excellon(g.text, excellon_digits=(2, 4)).warnings)
