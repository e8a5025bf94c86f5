"""HPGL as plotters draw it (issue #31 point 5): ``SC`` and ``IP`` scale the plot, ``CI``, ``AA`` and ``AR`` are
drawn with their chord angles (or ``CT1`` chord tolerances), ``--scale``, ``--fit`` and ``--offset`` work as on
SVG; a circle's or an arc's chords are counted before they are made and a file asking too many is refused.

Every file is written here in a plotter's or a program's habits (an HP 7475A instrument plot, an oscilloscope
dump with no ``IP``, ``;`` terminators or none, lower-case mnemonics, coordinate lists, ``CI`` with the pen up
and down).  Each cut is run on the mock and checked from the decoded pin log: the positions at the cutting
depth must reach every expected vertex (computed here from the HP-GL/2 rules, in mm) within a step, and span
the expected extent within a step.
"""
import math

import numpy as np
import pytest

import cam
from cam.errors import ParseError
from cam.formats.hpgl import DEFAULT_P1_PU, DEFAULT_P2_PU, MAX_ARC_CHORDS, parse_hpgl
from cam.job.hpgl import plan_hpgl

from conftest import run_cli

S = cam.MachineSettings().replace(mm_per_step_xy=0.1)
"""Coarser steps than the thesis machine's 0.0289 mm, so that an A4 plot runs on the mock in a fraction of a second."""
MM_PER_STEP = S.mm_per_step_xy
CLI_MM_PER_STEP = cam.MachineSettings().mm_per_step_xy
PU_MM = 0.025


def cut_positions(job):
    """``(M, 2)`` machine steps where the tool stood at the cutting depth, decoded from the mock's pin log."""
    result = cam.run(job)
    assert result.status == "finished"
    motion = cam.decode_pin_log(result.pin_log(), job.settings)
    pos = motion.position_steps
    depth = int(job.points_steps[job.target][:, 2].max())
    assert pos[:, 2].max() == depth and motion.final_steps == (0, 0, 0)
    return np.unique(pos[pos[:, 2] == depth, :2], axis=0)


def assert_cut_matches(cut, expected_mm, *, extent_mm=None):
    """Every expected point (machine mm from the drawing's top-left, y toward the operator) was cut within a
    step, and the cut spans ``extent_mm`` (default: the expected points') within a step."""
    exp = np.asarray(expected_mm, float) / MM_PER_STEP
    dist = np.abs(exp[:, None, :] - cut[None, :, :].astype(float)).max(axis=2).min(axis=1)
    assert dist.max() <= 1.0, f"point {expected_mm[int(dist.argmax())]} mm not cut (nearest {dist.max():.2f} steps)"
    span_mm = (cut.max(axis=0) - cut.min(axis=0)) * MM_PER_STEP
    want = np.ptp(np.asarray(expected_mm, float), axis=0) if extent_mm is None else np.asarray(extent_mm)
    assert np.all(np.abs(span_mm - want) <= MM_PER_STEP), (span_mm, want)


def machine_mm(pu):
    """Plotter units (Y up) to machine mm from the drawing's top-left (the default placement)."""
    pu = np.asarray(pu, float)
    return np.column_stack([(pu[:, 0] - pu[:, 0].min()) * PU_MM, (pu[:, 1].max() - pu[:, 1]) * PU_MM])


def frame_and_trace(xmax, ymax, n=12):
    """A frame around the plot and a sine trace through it, in user units, as PU/PD coordinate lists."""
    t = np.linspace(0, xmax, n)
    wave = ymax / 2 + ymax / 3 * np.sin(t / xmax * 2 * math.pi)
    trace = ",".join(f"{x:.2f},{y:.2f}" for x, y in zip(t, wave))
    return (f"PU0,0;PD{xmax},0,{xmax},{ymax},0,{ymax},0,0;PU;PU0,{wave[0]:.2f};PD{trace};PU;",
            [(0, 0), (xmax, 0), (xmax, ymax), (0, ymax)] + list(zip(t, wave)))


# -- SC and IP: the plot's own scaling -----------------------------------------------------------------------------

def test_oscilloscope_dump_without_ip_fills_the_default_p1_p2_about_a4():
    """An instrument's screen dump: SC to its 1023 x 767 screen, P1 and P2 left at the plotter's (A4 on an HP
    7475A: 250 x 180 mm).  Without SC it would be 25.6 x 19.2 mm."""
    body, user = frame_and_trace(1023, 767)
    d = parse_hpgl(f"IN;DF;SC0,1023,0,767;SP1;{body}SP0;", source="scope.plt")
    assert not d.warnings
    (p1x, p1y), (p2x, p2y) = DEFAULT_P1_PU, DEFAULT_P2_PU
    pu = [(p1x + x / 1023 * (p2x - p1x), p1y + y / 767 * (p2y - p1y)) for x, y in user]
    np.testing.assert_allclose(d.points_pu[[0, 1, 2, 3]], pu[:4])
    assert_cut_matches(cut_positions(plan_hpgl(d, settings=S)), machine_mm(pu), extent_mm=(250.0, 180.0))


def test_hp7475a_instrument_plot_with_ip_and_sc_no_terminators_lower_case():
    """An HP 7475A habit: IP to the A4 hard-clip corners, SC 0..100 percent; commands with no terminators, lower
    case, pairs split by spaces."""
    text = ("in sp1 ip603,521,10603,7721 sc0,100,0,100\n"
            "pu0,0 pd100,0 100,100 0,100 0,0 pu\n"
            "pa10,10pd90,10,90,90pu sp0\n")
    d = parse_hpgl(text, source="hp7475a.plt")
    assert not d.warnings
    pu = [(603 + x * 100, 521 + y * 72) for x, y in [(0, 0), (100, 0), (100, 100), (0, 100), (10, 10), (90, 10),
                                                     (90, 90)]]
    np.testing.assert_allclose(d.points_pu, [pu[i] for i in (0, 1, 2, 3, 0, 4, 5, 6)])
    assert_cut_matches(cut_positions(plan_hpgl(d, settings=S)), machine_mm(pu), extent_mm=(250.0, 180.0))


@pytest.mark.parametrize("sc, p1, unit, expect_x0, expect_y0", [
    # isotropic: 8000 x 4000 pu for 100 x 100 units -> 40 pu a unit; 4000 pu spare in X, split by `left`
    ("SC0,100,0,100,1", (0, 0), (40, 40), 2000, 0),          # centred (50 %)
    ("SC0,100,0,100,1,0,0", (0, 0), (40, 40), 0, 0),
    ("SC0,100,0,100,1,100,100", (0, 0), (40, 40), 4000, 0),
    ("SC0,100,0,100", (0, 0), (80, 40), 0, 0),               # anisotropic
    ("SC0,100,0,100,0", (0, 0), (80, 40), 0, 0),
    ("SC-10,2.5,5,4,2", (0, 0), (2.5, 4), 25, -20),           # point factor: (xmin, ymin) at P1
    ("SC100,0,0,100", (0, 0), (-80, 40), 8000, 0),            # a reversed axis mirrors
])
def test_every_form_of_sc(sc, p1, unit, expect_x0, expect_y0):
    d = parse_hpgl(f"IN;IP0,0,8000,4000;{sc};SP1;PU0,0;PD10,0,10,10;PU;")
    ux, uy = unit
    np.testing.assert_allclose(d.points_pu, [(expect_x0, expect_y0), (expect_x0 + 10 * ux, expect_y0),
                                             (expect_x0 + 10 * ux, expect_y0 + 10 * uy)])


def test_sc_off_ip_forms_and_relative_moves_in_user_units():
    d = parse_hpgl("IN;IP0,0,4000,4000;SC0,100,0,100;SP1;PA10,10;PD;PR10,0,0,10;SC;PR40,0;PU;"
                   "IP1000,1000;SC0,100,0,100;PA0,0;PD100,100;PU;IP;PA0,0;PD100,0;PU;DF;PA0,0;PD100,0;PU;")
    np.testing.assert_allclose(d.points_pu, [
        (400, 400), (800, 400), (800, 800), (840, 800),      # PR in user units; SC; cancels: plotter units
        (1000, 1000), (5000, 5000),                          # IP P1 only: P2 keeps its distance
        (603, 521), (10603, 521),                            # IP; the defaults
        (0, 0), (100, 0),                                    # DF: scaling off
    ])


def test_sc_cancel_and_scaled_pen_position_carry_between_chunks():
    """The plotter state (scaling, P1/P2, the pen) goes on from one chunk of the file to the next."""
    body = "".join(f"PA{i},{i % 7};PD{i + 1},{(i + 3) % 7};PU;" for i in range(400))
    text = "IN;IP0,0,1000,1000;SC0,10,0,10;SP1;" + body + "SC;PA5,5;PD10,10;PU;"
    whole = parse_hpgl(text)
    from cam.formats.hpgl import load_hpgl
    import io
    small = load_hpgl(io.BytesIO(text.encode()), chunk_bytes=64)
    np.testing.assert_array_equal(small.points_pu, whole.points_pu)
    assert whole.points_pu[-1].tolist() == [10, 10] and whole.points_pu[0].tolist() == [0, 0]
    assert whole.points_pu[1].tolist() == [100, 300]


# -- CI, AA, AR: circles and arcs ---------------------------------------------------------------------------------

def circle_pu(cx, cy, r, chord_deg=5.0, ax=1.0, ay=1.0):
    n = math.ceil(360 / chord_deg - 1e-9)
    t = np.arange(n + 1) / n * 2 * math.pi
    return np.column_stack([cx + ax * r * np.cos(t), cy + ay * r * np.sin(t)])


def test_ci_with_pen_up_and_down_is_its_own_stroke_and_pen_state_comes_back():
    d = parse_hpgl("IN;SP1;PU2000,2000;CI400;PU0,0;PD;PA2000,0;CI200,30;PA2000,400;PU;")
    starts = d.stroke_start.tolist()
    assert starts == [0, 73, 75, 88]       # the circle, the line, the circle, then the line on from its centre
    np.testing.assert_allclose(d.points_pu[:73], circle_pu(2000, 2000, 400), atol=1e-9)
    np.testing.assert_allclose(d.points_pu[75:88], circle_pu(2000, 0, 200, 30), atol=1e-9)
    np.testing.assert_allclose(d.points_pu[88:], [(2000, 0), (2000, 400)])
    # the pen lowered at the centre before the circle is a dot there (as a plotter leaves it); after the circle,
    # back down at the centre, it makes no second one unless it moves
    assert parse_hpgl("SP1;PA100,100;PD;CI50;PU;PA0,0;").stroke_start.tolist() == [0, 1]


def test_ci_under_anisotropic_scaling_is_an_ellipse_and_a_negative_radius_starts_at_180():
    d = parse_hpgl("IN;IP0,0,2000,1000;SC0,100,0,100;SP1;PA50,50;CI-10,90;PU;")
    np.testing.assert_allclose(d.points_pu, [(800, 500), (1000, 400), (1200, 500), (1000, 600), (800, 500)],
                               atol=1e-9)


def test_aa_ar_chord_angles_pen_up_moves_and_ct_tolerance():
    # AA from (1000,0) about (0,0) by 90 degrees with 10 degree chords: 9 chords
    d = parse_hpgl("SP1;PA1000,0;PD;AA0,0,90,10;AR-1000,0,-90;PU;AR0,1000,90;PD;PR0,0;PU;")
    t = np.radians(np.arange(10) * 10)
    first = np.column_stack([1000 * np.cos(t), 1000 * np.sin(t)])
    np.testing.assert_allclose(d.points_pu[:10], first, atol=1e-9)
    # AR about (-1000, 1000) relative to (0, 1000) clockwise 90 degrees, 5 degree chords (18)
    t2 = np.radians(-np.arange(19) * 5)
    second = np.column_stack([-1000 + 1000 * np.cos(t2), 1000 + 1000 * np.sin(t2)])
    np.testing.assert_allclose(d.points_pu[9:28], second, atol=1e-9)
    # pen up at (-1000, 0): AR only moves (about (-1000, 1000) back by 90: to (0, 1000)), nothing drawn; a dot there
    np.testing.assert_allclose(d.points_pu[28:], [(0, 1000), (0, 1000)], atol=1e-9)
    # CT1: the chord parameter is the most a chord strays from the arc: 2*acos(1 - 1/100) = 16.2 deg -> 23 chords
    ct = parse_hpgl("SP1;CT1;PA100,0;PD;AA0,0,360,1;PU;CT0;PA100,0;PD;AA0,0,360,1;PU;CT;PA100,0;PD;AA0,0,360;PU;")
    n_tol = math.ceil(360 / math.degrees(2 * math.acos(1 - 1 / 100)))
    assert np.diff(np.append(ct.stroke_start, len(ct.points_pu))).tolist() == [n_tol + 1, 361, 73]


def test_circles_and_arcs_cut_on_the_mock_within_a_step():
    """A plotted part outline: a scaled slot (AA ends), a hole (CI), an arc relative; cut and decoded."""
    text = ("IN;IP0,0,4000,4000;SC0,100,0,100,1;SP1;\n"
            "PU20,40;PD60,40;AA60,50,180,10;PD20,60;AA20,50,180,10;PU;\n"
            "PU80,50;CI8,15;\n"
            "PU10,10;PD;AR10,0,-90,15;PU;\n")
    d = parse_hpgl(text, source="part.plt")
    def pt(x, y):
        return (x * 40, y * 40)
    slot = [pt(20, 40), pt(60, 40)] + [pt(60 + 10 * math.sin(math.radians(a)), 50 - 10 * math.cos(math.radians(a)))
                                       for a in range(10, 181, 10)]
    slot += [pt(20, 60)] + [pt(20 - 10 * math.sin(math.radians(a)), 50 + 10 * math.cos(math.radians(a)))
                            for a in range(10, 181, 10)]
    hole = [pt(80 + 8 * math.cos(math.radians(a)), 50 + 8 * math.sin(math.radians(a))) for a in range(0, 360, 15)]
    arc = [pt(20 + 10 * math.cos(math.radians(180 - a)), 10 + 10 * math.sin(math.radians(180 - a)))
           for a in range(0, 91, 15)]
    expected = slot + hole + arc
    np.testing.assert_allclose(np.unique(np.round(d.points_pu, 6), axis=0),
                               np.unique(np.round(expected, 6), axis=0), atol=1e-6)
    assert_cut_matches(cut_positions(plan_hpgl(d, settings=S)), machine_mm(expected))


# -- count before work --------------------------------------------------------------------------------------------

def test_too_many_chords_are_refused_before_one_is_made(tmp_path):
    ok = parse_hpgl("SP1;PA0,0;CI100,0.5;")  # the finest chord angle: 720 chords
    assert len(ok.points_pu) == 721
    with pytest.raises(ParseError, match=r"^big\.plt:2:9: 'AA' would be drawn as 2,000,000,000 chords; "
                                         rf"at most {MAX_ARC_CHORDS:,} chords"):
        parse_hpgl("SP1;PA100,0;\nPD0,100;AA0,0,1000000000,0.5;", source="big.plt")
    assert len(parse_hpgl("SP1;CT1;CI1,0.000001;").points_pu) == 721  # a tolerance finer than 0.5 degrees
    with pytest.raises(ParseError, match=r"'AR' would be drawn as more than 4,000,000,000,000,000,000 chords"):
        parse_hpgl("SP1;PD;AR0,1,1" + "0" * 300 + ";")
    path = tmp_path / "big.plt"
    path.write_text("IN;SP1;PA100,0;PD;AR-100,0,36000000,0.5;PU;")
    for command in ("info", "drill"):
        r = run_cli(command, path, *(["--yes"] if command == "drill" else []))
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert "big.plt:1:19: 'AR' would be drawn as 72,000,000 chords" in r.stderr


@pytest.mark.parametrize("text, fragment", [
    ("SC0,100,0;", "'SC' takes none, 4"),
    ("SC0,100,0,100,3;", "'SC' takes none, 4"),
    ("SC0,0,0,100;", "'SC' needs xmin != xmax"),
    ("SC0,0,0,1,2;", "type 2: factors != 0"),
    ("SC0,1,0,1,1,150,0;", "left and bottom 0..100"),
    ("IP0,0,1;", "'IP' takes none, 2"),
    ("CI;", "'CI' takes 1"),
    ("AA0,0;", "'AA' takes 3"),
    ("CT2;", "'CT' takes none"),
])
def test_bad_scaling_and_arcs_are_one_line_errors(text, fragment):
    with pytest.raises(ParseError) as exc:
        parse_hpgl("IN;SP1;\n" + text, source="bad.plt")
    msg = str(exc.value)
    assert msg.startswith("bad.plt:2:1: ") and fragment in msg and "\n" not in msg


# -- --scale, --fit, --offset as on SVG ----------------------------------------------------------------------------

SQUARE = "IN;SP1;PU0,0;PD2000,0,2000,1000,0,1000,0,0;PU;"  # 50 x 25 mm


@pytest.mark.parametrize("args, extent_mm, corner_mm", [
    ((), (50.0, 25.0), (0.0, 0.0)),
    (("--scale", "2"), (100.0, 50.0), (0.0, 0.0)),
    (("--fit", "80x80"), (80.0, 40.0), (0.0, 0.0)),
    (("--fit", "30x10"), (20.0, 10.0), (0.0, 0.0)),
])
def test_cli_scale_fit_offset_on_hpgl_decoded_from_the_pin_log(tmp_path, args, extent_mm, corner_mm):
    path = tmp_path / "sq.plt"
    path.write_text(SQUARE)
    log = tmp_path / "p.csv"
    r = run_cli("drill", path, "--yes", "--no-progress", "--pin-log", log, *args)
    assert r.returncode == 0, r.stderr
    motion = cam.decode_pin_log(log)
    pos = motion.position_steps
    cut = pos[pos[:, 2] == pos[:, 2].max(), :2]
    lo_mm, hi_mm = cut.min(axis=0) * CLI_MM_PER_STEP, cut.max(axis=0) * CLI_MM_PER_STEP
    assert np.all(np.abs((hi_mm - lo_mm) - extent_mm) <= CLI_MM_PER_STEP), (hi_mm - lo_mm)
    assert np.all(np.abs(lo_mm - corner_mm) <= CLI_MM_PER_STEP), lo_mm


def test_offset_puts_the_scaled_plotter_origin_there_on_the_mock():
    """As SVG's: ``offset_mm`` is where plotter (0, 0), scaled, goes (Y up in the plot, toward the front on the
    machine); a plot drawn with SC in user units is placed by its plotter units."""
    for text in (SQUARE, "IN;SP1;IP0,0,2000,1000;SC0,4,0,2;PU0,0;PD4,0,4,2,0,2,0,0;PU;"):
        cut = cut_positions(plan_hpgl(parse_hpgl(text), settings=S, scale=0.5, offset_mm=(10.0, 40.0)))
        lo_mm, hi_mm = cut.min(axis=0) * MM_PER_STEP, cut.max(axis=0) * MM_PER_STEP
        assert np.all(np.abs(lo_mm - (10.0, 27.5)) <= MM_PER_STEP) and np.all(np.abs(hi_mm - (35.0, 40.0)) <= MM_PER_STEP)


def test_cli_scale_and_fit_together_is_one_line_error(tmp_path):
    path = tmp_path / "sq.plt"
    path.write_text(SQUARE)
    r = run_cli("drill", path, "--yes", "--scale", "2", "--fit", "10x10")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
