"""HPGL ``IW`` (input window) clips the pen-down strokes as a plotter does (issue #44 point 6): the part of each
segment inside the window is drawn, the pen moves up outside; ``IW;``, ``IN`` and ``DF`` take the window away;
while scaling is on its corners are user units and move with P1 and P2 until an ``SC`` binds them."""
import re

import numpy as np
import pytest

from cam.formats.hpgl import load_hpgl, parse_hpgl, scan_hpgl
from cam.job.hpgl import plan_hpgl

from test_hpgl import assert_carves_the_drawing

NO_WINDOW = None
# (a line of the file, the window in force while its strokes are drawn: (x0, y0, x1, y1) plotter units as
# plotted, worked out here by hand from the HP-GL/2 rules, or None)
LINES = [
    ("IN;SP1;", NO_WINDOW),
    ("PU0,0;PD4000,0;PU;", NO_WINDOW),
    ("IW1000,1000,3000,2500;", NO_WINDOW),
    ("PU500,500;PD3500,3000,3500,500,2000,1750,500,1750;PU;", (1000, 1000, 3000, 2500)),  # out, in, across
    ("PU1500,1500;PD2500,1500,2500,2000;PU;", (1000, 1000, 3000, 2500)),  # wholly inside
    ("PU0,3000;PD4000,3000;PU;PD;PU;", (1000, 1000, 3000, 2500)),  # wholly outside, and a dot outside
    ("PU2000,2000;PD;PU;", (1000, 1000, 3000, 2500)),  # a dot inside
    ("SP2;PU2000,1750;CI1000;", (1000, 1000, 3000, 2500)),  # a circle out through the top and bottom
    ("PU2000,2600;PR;PD0,-200,300,0;PA;PU;", (1000, 1000, 3000, 2500)),  # relative moves coming in
    ("IW3000,2500,1000,1000;", (1000, 1000, 3000, 2500)),  # the corners either way round: the same window
    ("PU1000,1000;PD3000,1000,3000,2500;PU;", (1000, 1000, 3000, 2500)),  # along its edges: drawn
    ("PU500,1200;PD1200,1200,1200,500;", (1000, 1000, 3000, 2500)),  # in, and out again
    ("IW;PD1300,900;PU;", NO_WINDOW),  # taken away with the pen down: drawn on from where the pen stands
    ("PU0,4000;PD100,4000;PU;", NO_WINDOW),
    ("SP1;SC0,100,0,100;", NO_WINDOW),
    ("IW10,10,50,50;", NO_WINDOW),  # user units: plotted at P1 + u * (P2 - P1) / 100
    ("PU0,0;PD60,60;PU;", (603 + 1000, 521 + 720, 603 + 5000, 521 + 3600)),
    ("IP0,0,4000,4000;", NO_WINDOW),  # the window keeps its user units: it moves with P1 and P2
    ("PU0,0;PD60,60;PU;", (400, 400, 2000, 2000)),
    ("SC;", NO_WINDOW),  # binds it to the plotter units it stands at
    ("IP;PU0,0;PD2400,2400;PU;", (400, 400, 2000, 2000)),
    ("DF;PU0,0;PD2400,0;PU;", NO_WINDOW),  # DF takes it away
    ("IW0,0,100,100;IN;SP2;PU0,0;PD2400,0;PU;", NO_WINDOW),  # and IN
]
TEXT = "\n".join(text for text, _ in LINES) + "\n"


def _clipped(p, q, window):
    """The part of the segment p -> q inside ``window`` (edges included), or None: the parameters where it
    crosses each edge's line, sorted, and the pieces between them whose middle is inside (not the reader's
    Liang-Barsky clip)."""
    if window is None:
        return p, q
    x0, y0, x1, y1 = window
    d = q - p
    ts = {0.0, 1.0}
    for axis, bound in ((0, x0), (0, x1), (1, y0), (1, y1)):
        if d[axis] != 0:
            t = (bound - p[axis]) / d[axis]
            if 0 < t < 1:
                ts.add(t)
    ts = sorted(ts)
    inside = [a for a, b in zip(ts[:-1], ts[1:]) if x0 - 1e-9 <= p[0] + d[0] * (a + b) / 2 <= x1 + 1e-9
              and y0 - 1e-9 <= p[1] + d[1] * (a + b) / 2 <= y1 + 1e-9]
    if not inside:
        return None
    t0, t1 = inside[0], [b for a, b in zip(ts[:-1], ts[1:]) if a in inside][-1]
    return p + d * t0, p + d * t1


def _segments(drawing):
    """Each pen-down segment (pen, from, to) in order, and the dots (pen, point) of one-point strokes."""
    segs, dots = [], []
    for pen, pts in drawing.strokes():
        if len(pts) == 1:
            dots.append((pen, tuple(pts[0])))
        segs += [(pen, a, b) for a, b in zip(pts[:-1], pts[1:])]
    return segs, dots


def test_hpgl_iw_clips_as_a_plotter_does(tmp_path):
    path = tmp_path / "window.plt"
    path.write_text(TEXT)
    drawing = load_hpgl(path)
    assert drawing.warnings == []  # IW is known: no "unknown command"
    # the independent clip: the same file without its IW commands, each segment clipped to the window of its line
    plain = parse_hpgl(re.sub(r"IW[^;]*;", "", TEXT), source="plain.plt")
    windows = {no: window for no, (_, window) in enumerate(LINES, start=1)}
    want_segs, want_dots = [], []
    ends = np.append(plain.stroke_start[1:], len(plain.points_pu))
    for pen, a, b in zip(plain.stroke_pen.tolist(), plain.stroke_start.tolist(), ends.tolist()):
        pts, lines = plain.points_pu[a:b], plain.point_line[a:b]
        if b - a == 1:
            w = windows[int(lines[0])]
            if w is None or (w[0] <= pts[0][0] <= w[2] and w[1] <= pts[0][1] <= w[3]):
                want_dots.append((pen, tuple(pts[0])))
        for p, q, line in zip(pts[:-1], pts[1:], lines[1:]):
            piece = _clipped(p, q, windows[int(line)])
            if piece is not None and np.any(piece[0] != piece[1]):
                want_segs.append((pen, *piece))
    got_segs, got_dots = _segments(drawing)
    assert got_dots == want_dots == [(1, (2000.0, 2000.0))]
    assert len(got_segs) == len(want_segs)
    for (pen, a, b), (want_pen, c, d) in zip(got_segs, want_segs):
        assert pen == want_pen and np.allclose(a, c, atol=1e-6) and np.allclose(b, d, atol=1e-6), (a, b, c, d)
    # a stroke starts again wherever it comes back in: as many strokes as pieces that do not join
    joined = sum(1 for (_, _, b), (_, c, _) in zip(want_segs[:-1], want_segs[1:]) if np.allclose(b, c))
    assert drawing.n_strokes == len(want_segs) - joined + len(want_dots)
    # every point inside the window of its line: none cut outside what the plotter draws
    for (x, y), line in zip(drawing.points_pu.tolist(), drawing.point_line.tolist()):
        w = windows[line]
        assert w is None or (w[0] - 1e-9 <= x <= w[2] + 1e-9 and w[1] - 1e-9 <= y <= w[3] + 1e-9), (x, y, line)
    # the streamed scan sees the same clipped drawing, in any chunk size
    scan = scan_hpgl(path)
    assert (scan.n_strokes, scan.n_points, scan.extent_pu) == (drawing.n_strokes, len(drawing.points_pu),
                                                                drawing.extent_pu())
    for chunk in (7, 64):
        small = load_hpgl(path, chunk_bytes=chunk)
        assert np.array_equal(small.points_pu, drawing.points_pu)
        assert np.array_equal(small.stroke_start, drawing.stroke_start)
    # the carved surface on the mock: exactly the clipped strokes
    assert_carves_the_drawing(drawing, plan_hpgl(drawing, cut_depth_mm=0.2, travel_height_mm=0.3))


@pytest.mark.parametrize("text, fragment", [
    ("IW1,2,3;", "'IW' takes none (no window) or 4"),
    ("IW1,2,3,4,5;", "'IW' takes none (no window) or 4"),
])
def test_hpgl_iw_with_the_wrong_parameters_is_one_line(text, fragment):
    with pytest.raises(Exception, match=re.escape(fragment)):
        parse_hpgl(text.encode(), source="w.plt")
