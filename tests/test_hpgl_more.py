"""More of HP-GL/2 read (issue #31): three-point arcs ``AT``/``RT``, ``RO`` (the coordinate system turned by
quarter turns) and ``IR`` (P1 and P2 in percent), each checked point by point against the reference's
semantics."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from cam.cli import main
from cam.errors import ParseError
from cam.formats.hpgl import DEFAULT_P1_PU, DEFAULT_P2_PU, parse_hpgl


def _pts(text: str) -> np.ndarray:
    d = parse_hpgl(text.encode(), source="t.plt")
    assert d.warnings == []
    return d.points_pu


def _arc(cx: float, cy: float, r: float, a0_deg: float, sweep_deg: float, n: int) -> np.ndarray:
    t = np.radians(a0_deg + sweep_deg * np.arange(n + 1) / n)
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def test_at_draws_the_arc_through_the_intermediate_point_to_the_end():
    # from (0, 0) over (100, 100) to (200, 0): the upper half of the circle about (100, 0), clockwise, 36 chords
    pts = _pts("IN;SP1;PU0,0;PD;AT100,100,200,0;PD300,0;PU;")
    assert len(pts) == 36 + 1 + 1
    np.testing.assert_allclose(pts[:37], _arc(100, 0, 100, 180, -180, 36), atol=1e-9)
    assert pts[36].tolist() == [200.0, 0.0] and pts[37].tolist() == [300.0, 0.0]  # the pen ends at the end point
    # the other way round when the intermediate point is below: counter-clockwise through (100, -100)
    low = _pts("IN;SP1;PU0,0;PD;AT100,-100,200,0;PU;")
    np.testing.assert_allclose(low, _arc(100, 0, 100, 180, 180, 36), atol=1e-9)
    # a major arc: from (0, 0) over (100, 100) to (100, -100), three quarters of the circle about (100, 0)
    major = _pts("IN;SP1;PU0,0;PD;AT100,100,100,-100;PU;")
    np.testing.assert_allclose(major, _arc(100, 0, 100, 180, -270, 54), atol=1e-9)


def test_rt_takes_both_points_relative_to_the_pen_and_a_chord_angle():
    pts = _pts("IN;SP1;PU1000,500;PD;RT100,100,200,0,30;PU;")
    np.testing.assert_allclose(pts, _arc(1100, 500, 100, 180, -180, 6), atol=1e-9)
    assert pts[-1].tolist() == [1200.0, 500.0]


def test_at_with_the_end_at_the_pen_is_a_circle_on_the_diameter_to_the_intermediate_point():
    pts = _pts("IN;SP1;PU0,0;PD;AT200,0,0,0;PU;")
    np.testing.assert_allclose(pts, _arc(100, 0, 100, 180, 360, 72), atol=1e-9)
    assert pts[-1].tolist() == [0.0, 0.0]


def test_degenerate_three_point_arcs_are_lines_or_refused():
    for cmd in ("AT100,0,200,0", "AT0,0,200,0", "AT200,0,200,0", "RT50,0,200,0"):  # on the line between, or at an end
        assert _pts(f"IN;SP1;PU0,0;PD;{cmd};PU;").tolist() == [[0.0, 0.0], [200.0, 0.0]]
    with pytest.raises(ParseError, match=r"t.plt:1:17: 'AT' has its three points on one line"):
        parse_hpgl(b"IN;SP1;PU0,0;PD;AT300,0,200,0;PU;", source="t.plt")
    with pytest.raises(ParseError, match=r"'RT' takes 4 .* or 5 .* parameters, got 3"):
        parse_hpgl(b"IN;PD;RT1,2,3;", source="t.plt")


def test_three_point_arcs_with_the_pen_up_only_move_it_and_scale_in_user_units():
    pts = _pts("IN;SP1;PU0,0;AT100,100,200,0;PD300,0;PU;")
    assert pts.tolist() == [[200.0, 0.0], [300.0, 0.0]]
    # 100 plotter units per user unit: the arc of the first test, ten times as large, from (0, 0)
    scaled = _pts("IN;SP1;IP0,0,1000,1000;SC0,10,0,10;PU0,0;PD;AT1,1,2,0;PU;")
    np.testing.assert_allclose(scaled, _arc(100, 0, 100, 180, -180, 36), atol=1e-9)


def test_ro_turns_the_coordinate_system_and_the_pen_stays_on_the_paper():
    # RO90: +X along the plotter's +Y: (x, y) is plotted at (-y, x)
    assert _pts("IN;SP1;RO90;PU0,0;PD100,0,100,50;PU;").tolist() == [[0.0, 0.0], [0.0, 100.0], [-50.0, 100.0]]
    assert _pts("IN;SP1;RO180;PU10,20;PD30,20;PU;").tolist() == [[-10.0, -20.0], [-30.0, -20.0]]
    assert _pts("IN;SP1;RO270;PU10,20;PD30,20;PU;").tolist() == [[20.0, -10.0], [20.0, -30.0]]
    # the pen does not move when the system turns: PR goes on from where it stands on the paper
    assert _pts("IN;SP1;PU100,0;RO90;PD;PR10,0;PU;").tolist() == [[100.0, 0.0], [100.0, 10.0]]
    # RO; and IN turn it back; arcs turn with it
    assert _pts("IN;SP1;RO90;RO;PU0,0;PD10,0;PU;").tolist() == [[0.0, 0.0], [10.0, 0.0]]
    assert _pts("IN;SP1;RO90;IN;SP1;PU0,0;PD10,0;PU;").tolist() == [[0.0, 0.0], [10.0, 0.0]]
    arc = _pts("IN;SP1;RO90;PU0,0;PD;AT100,100,200,0;PU;")
    want = _arc(100, 0, 100, 180, -180, 36)
    np.testing.assert_allclose(arc, np.column_stack([-want[:, 1], want[:, 0]]), atol=1e-9)
    with pytest.raises(ParseError, match=r"t.plt:1:6: 'RO' takes an angle of 0, 90, 180 or 270 degrees, got 45"):
        parse_hpgl(b"IN;RO45;", source="t.plt")


def test_ir_puts_p1_and_p2_at_percentages_of_the_page():
    (x1, y1), (x2, y2) = DEFAULT_P1_PU, DEFAULT_P2_PU
    # IR0,0,100,100 is the default P1 and P2: user (0, 0) at P1, (100, 100) at P2
    pts = _pts("IN;SP1;IR0,0,100,100;SC0,100,0,100;PU0,0;PD100,100;PU;")
    assert pts.tolist() == [[x1, y1], [x2, y2]]
    # IR50,50: P1 in the middle of the page, P2 kept as far from it as before
    mid = _pts("IN;SP1;IR50,50;SC0,100,0,100;PU0,0;PD100,100;PU;")
    px, py = x1 + 0.5 * (x2 - x1), y1 + 0.5 * (y2 - y1)
    assert mid.tolist() == [[px, py], [px + x2 - x1, py + y2 - y1]]
    quarter = _pts("IN;SP1;IR25,0,75,50;SC0,1,0,1;PU0,0;PD1,1;PU;")
    assert quarter.tolist() == [[x1 + 0.25 * (x2 - x1), y1], [x1 + 0.75 * (x2 - x1), y1 + 0.5 * (y2 - y1)]]
    assert _pts("IN;SP1;IR50,50;IR;SC0,100,0,100;PU0,0;PD100,100;PU;").tolist() == [[x1, y1], [x2, y2]]
    with pytest.raises(ParseError, match=r"t.plt:1:6: 'IR' takes percentages 0..100, got 150"):
        parse_hpgl(b"IN;IR150,0;", source="t.plt")


def test_a_three_point_arc_is_exported_as_an_arc(tmp_path):
    src = tmp_path / "at.plt"
    src.write_bytes(b"IN;SP1;PU0,0;PD;AT400,400,800,0;PD1200,0;PU;")
    out = tmp_path / "at.ngc"
    assert main(["export", str(src), "-o", str(out), "--post", "grbl"]) == 0
    code = [ln for ln in out.read_text().splitlines() if re.match(r"G[123] X", ln)]
    # the half circle r 10 mm (clockwise: G2) in one block, then the line; top-left (0, 400) at the home
    assert [ln.split()[0] for ln in code] == ["G2", "G1"]
    assert code[0].startswith("G2 X20 Y-10 I10 J0") and code[1].startswith("G1 X30 Y-10")
    assert math.isclose(float(re.search(r"I(\S+)", code[0]).group(1)), 10.0)
