"""G-code in: cutter radius compensation of arcs (issue #44 point 6), compared with LinuxCNC's rs274.

G2/G3 under G41/G42 (the tool table's diameter) and G41.1/G42.1 (a diameter): the arc keeps its centre and its
radius shrinks or grows by the tool radius (the tool inside or outside it); corners between a line and an arc,
an arc and a line and two arcs are met (concave) or rounded (convex) where rs274 meets or rounds them; an entry
arc runs about a new centre from where the tool stands; a tool too big for an arc it runs inside, or for a
concave corner, is a one-line error naming the line, where rs274 refuses it too."""
import math
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from cam.errors import ParseError
from cam.formats.gcode import load_tool_table, parse_gcode
from support.lcnc import parse_canonical, run_rs274

from test_cli import assert_one_line_error, cli
from test_gcode_round3 import _rs274_refusal, _rs274_runs_backwards

needs_rs274 = pytest.mark.skipif(
    shutil.which("rs274") is None and not os.environ.get("CI"), reason="rs274 (linuxcnc-uspace) not installed"
)

TOOLS_IN = "T1 P1 D0.125 ;rs274's machine units are inches: a 1/8 in end mill\nT2 P2 D0.25\n"
TOOLS_MM = "T1 P1 D3.175 ;cam's are mm\nT2 P2 D6.35\n"


def _moves_like_rs274(tmp_path, name: str, text: str) -> list:
    """Run ``text`` through rs274 and cam (tool tables :data:`TOOLS_IN` and :data:`TOOLS_MM`), check that cam runs
    the moves rs274 runs (kinds, ends, arc centres and directions, within rs274's 4 printed decimals) and give
    cam's moves."""
    path = tmp_path / f"{name}.ngc"
    path.write_text(text)
    (tmp_path / "in.tbl").write_text(TOOLS_IN)
    (tmp_path / "mm.tbl").write_text(TOOLS_MM)
    var = path.with_suffix(".var")
    var.touch()
    want = [(mv.kind.replace("traverse", "rapid"), mv.end, mv.center, mv.rotation)
            for mv in parse_canonical(run_rs274(str(path), tool_table=str(tmp_path / "in.tbl"), var_file=var))]
    moves = parse_gcode(text, source=path.name, tool_lengths_mm=load_tool_table(tmp_path / "mm.tbl")).moves
    moves = [mv for mv in moves if mv.kind != "pause"]  # M6: cam pauses for the tool change
    got = [(mv.kind, mv.end, mv.center, (-1 if mv.clockwise else 1) * mv.turns if mv.kind == "arc" else 0)
           for mv in moves]
    atol_mm = 3e-3 if "G20" in text else 2e-4
    assert len(got) == len(want), (got, want)
    for (kind, end, centre, turns), (want_kind, want_end, want_centre, want_turns) in zip(got, want):
        assert kind == want_kind and np.allclose(end, want_end, atol=atol_mm), (got, want)
        if kind == "arc":
            assert np.allclose(centre, want_centre, atol=atol_mm) and turns == want_turns, (got, want)
    return moves


# a 40 x 30 mm rectangle with corners of radius 5, from the middle of its bottom edge, counter-clockwise or
# clockwise; its corner arcs alternate R and I J words
RECT_CCW = ["G1 X35 Y0", "G3 X40 Y5 R5", "G1 X40 Y25", "G3 X35 Y30 I-5 J0", "G1 X5 Y30", "G3 X0 Y25 R5",
            "G1 X0 Y5", "G3 X5 Y0 I5 J0", "G1 X20 Y0"]
RECT_CW = ["G1 X5 Y0", "G2 X0 Y5 I0 J5", "G1 X0 Y25", "G2 X5 Y30 R5", "G1 X35 Y30", "G2 X40 Y25 I0 J-5",
           "G1 X40 Y5", "G2 X35 Y0 R5", "G1 X20 Y0"]
CORNERS = [(5.0, 5.0), (35.0, 5.0), (35.0, 25.0), (5.0, 25.0)]
RECTANGLES = {
    # a pocket (the tool inside the outline, inside its corner arcs): enter from the middle, leave back to it
    "pocket_g41_ccw": ("G0 X20 Y15 Z2\nG1 Z-1 F300\nG41 D1\nG1 X20 Y0 F100", RECT_CCW, "G40\nG1 X20 Y15"),
    "pocket_g42_cw": ("G0 X20 Y15 Z2\nG1 Z-1 F300\nG42 D1\nG1 X20 Y0 F100", RECT_CW, "G40\nG1 X20 Y15"),
    # a profile (the tool outside): an entry arc onto the outline, or a straight entry; leave outward
    "profile_g42_ccw": ("G0 X10 Y-10 Z2\nG1 Z-1 F300\nG42 D1\nG2 X20 Y0 I10 J0 F100", RECT_CCW,
                        "G40\nG1 X20 Y-10"),
    "profile_g41_cw": ("G0 X30 Y-10 Z2\nG1 Z-1 F300\nT2 M6\nG41\nG1 X20 Y0 F100", RECT_CW, "G40\nG0 X30 Y-10"),
}


@needs_rs274
@pytest.mark.parametrize("name", sorted(RECTANGLES))
def test_rounded_rectangle_outline_with_compensation_matches_rs274(tmp_path, name):
    head, outline, tail = RECTANGLES[name]
    text = "G21 G90 G17\n" + "\n".join([head, *outline, tail]) + "\nG0 Z2\nM2\n"
    moves = _moves_like_rs274(tmp_path, name, text)
    # the corner arcs run about the programmed corners, the tool radius (tool 1: 1.5875, tool 2: 3.175) less
    # than 5 inside them (a pocket), more outside (a profile)
    tool_r = 3.175 if "T2" in head else 1.5875
    radius = 5 - tool_r if name.startswith("pocket") else 5 + tool_r
    lines = {n for n, ln in enumerate(text.splitlines(), 1) if ln in outline and ln.startswith(("G2", "G3"))}
    corners = [mv for mv in moves if mv.line in lines]
    assert len(corners) == 4 and {mv.center for mv in corners} == set(CORNERS), corners
    for mv in corners:
        assert math.hypot(mv.end[0] - mv.center[0], mv.end[1] - mv.center[1]) == pytest.approx(radius, abs=1e-9)
        assert mv.clockwise == name.endswith("_cw")
    # the tool's path keeps the tool radius from the outline: the straight edges are offset by it
    edges = [mv.end for mv in moves if mv.kind == "feed" and mv.end[2] == -1]
    inset = tool_r if name.startswith("pocket") else -tool_r
    assert any(e[1] == pytest.approx(inset, abs=1e-9) for e in edges)  # the bottom edge
    assert any(e[0] == pytest.approx(40 - inset, abs=1e-9) for e in edges)  # the right edge
    if name == "pocket_g41_ccw":  # the entry move, a concave corner with the bottom edge: met at (20 + r, r)
        assert moves[2].kind == "feed" and np.allclose(moves[2].end, (20 + tool_r, tool_r, -1))
    if name == "profile_g42_ccw":  # the entry arc, tangent to the edge: from where the tool stands to (20, -r),
        # about a new centre
        entry = moves[2]
        assert entry.kind == "arc" and np.allclose(entry.end, (20, -tool_r, -1))
        assert math.hypot(entry.end[0] - entry.center[0], entry.end[1] - entry.center[1]) == pytest.approx(
            math.hypot(10 - entry.center[0], -10 - entry.center[1]))


ARC_PROGRAMS = {
    # a ring of half circles (scallops): the tool outside them, convex arc-to-arc corners rounded about the cusps
    "scallops_outside": "G0 X-10 Y-10 Z1\nG42.1 D3\nG1 X0 Y0 F100\nG3 X20 Y0 R10\nG3 X40 Y0 R10\nG3 X40 Y20 R10\n"
                        "G3 X20 Y20 R10\nG3 X0 Y20 R10\nG3 X0 Y0 R10\nG40\nG0 X-10 Y-10\n",
    # ... the tool inside them: concave arc-to-arc corners met where the offset arcs cross
    "scallops_inside": "G0 X-10 Y-10 Z1\nG41.1 D2\nG1 X0 Y0 F100\nG3 X20 Y0 R10\nG3 X40 Y0 R10\nG3 X40 Y20 R10\n"
                       "G3 X20 Y20 R10\nG3 X0 Y20 R10\nG3 X0 Y0 R10\nG40\nG0 X-10 Y-10\n",
    # an S of two arcs (tangent: on from one to the other), a concave arc-to-arc corner, a Z-only move between arcs,
    # a concave arc-to-line and a convex line-to-arc corner, a helical arc
    "s_curves": "G0 X0 Y-10 Z1\nG41.1 D2\nG1 X0 Y0 F100\nG2 X10 Y0 R5\nG3 X20 Y0 R5\nG2 X25 Y5 I0 J5\nG1 Z-1\n"
                "G2 X30 Y0 R5\nG1 X30 Y-10\nG3 X40 Y-10 R5 Z-2\nG40\nG0 X50 Y-20\n",
    # the same on the right, the arcs' centres absolute (G90.1)
    "s_curves_right": "G90.1\nG0 X0 Y-10 Z1\nG42.1 D2\nG1 X0 Y0 F100\nG2 X10 Y0 I5 J0\nG3 X20 Y0 I15 J0\n"
                      "G2 X25 Y5 I25 J0\nG1 Z-1\nG2 X30 Y0 I27.5 J2.5\nG1 X30 Y-10\nG3 X40 Y-10 I35 J-10 Z-2\nG40\n"
                      "G0 X50 Y-20\nG91.1\n",
    # an entry arc, then a concave corner into a line: rs274 finds it as if the entry arc ran about the programmed
    # centre (it does not), a little off the line's offset
    "entry_arc_concave": "G0 X0 Y0 Z1\nG41.1 D4\nG3 X20 Y0 R10 F100\nG1 X10 Y10\nG1 X0 Y30\nG40\nG0 X-10 Y40\n",
    # an entry arc, then two full turns of a helix about the hole's centre, and out (a hole milled with comp)
    "helix": "G0 X50 Y50 Z1\nG41.1 D5\nG3 X60 Y50 Z0 I5 J0 F100\nG3 X60 Y50 Z-2 I-10 J0 P2\nG3 I-10 J0\n"
             "G3 X50 Y50 Z1 I-5 J0\nG40\nG0 X50 Y50\n",
    # a program in inches, incremental, with a traverse rounding a convex arc-to-line corner (a straight traverse)
    "inch": "G20 G91\nG0 X-0.5 Y-0.5\nG42.1 D0.125\nG1 X0.5 Y0.5 F10\nG3 X0.5 Y0.5 R0.5\nG0 X-0.5 Y0.5\n"
            "G2 X-0.5 Y-0.5 R0.5\nG40\nG0 X-1 Y-1\nG90\n",
}


@needs_rs274
@pytest.mark.parametrize("name", sorted(ARC_PROGRAMS))
def test_compensated_arcs_and_their_corners_match_rs274(tmp_path, name):
    text = ("G21 G90 G17\n" if "G20" not in ARC_PROGRAMS[name] else "") + ARC_PROGRAMS[name] + "M2\n"
    moves = _moves_like_rs274(tmp_path, name, text)
    assert sum(mv.kind == "arc" for mv in moves) >= 2


def test_compensated_arcs_hand_worked():
    """G3 from (0, 0) about (10, 0) to (20, 0) with a tool of radius 2, the entry along the X axis."""
    def run(side: str) -> list:
        moves = parse_gcode(f"G21\nG0 X-10 Y0\n{side} D4\nG1 X0 Y0 F100\nG3 X20 Y0 I10 J0\nG40\nM2\n").moves
        return [(mv.kind, tuple(round(v, 4) + 0.0 for v in mv.end), mv.center, mv.clockwise) for mv in moves]

    # on the left the tool is inside the arc (radius 10 - 2) and the corner convex: rounded clockwise about (0, 0)
    # from the entry's offset end (0, 2) to the arc's offset start (2, 0)
    assert run("G41.1") == [("rapid", (-10, 0, 0), None, False), ("feed", (0, 2, 0), None, False),
                            ("arc", (2, 0, 0), (0, 0), True), ("arc", (18, 0, 0), (10, 0), False)]
    # on the right it is outside (radius 12) and the corner concave: the entry ends where its offset Y-2 meets the
    # offset arc, behind the corner: X = 10 - sqrt(12^2 - 2^2)
    assert run("G42.1") == [("rapid", (-10, 0, 0), None, False), ("feed", (round(10 - 140**0.5, 4), -2, 0), None,
                                                                           False),
                            ("arc", (22, 0, 0), (10, 0), False)]


REFUSALS = {
    # a pocket whose corners (radius 1) are tighter than the tool (radius 1.5875): the first corner arc
    "tool_bigger_than_arc": ("G0 X20 Y15\nG41 D1\nG1 X20 Y0 F100\nG1 X39 Y0\nG3 X40 Y1 R1\nG1 X40 Y15\nG40\n"
                             "G1 X20 Y15\n", 6, "Tool radius not less than arc radius with comp",
                             "cutter compensation: the tool radius (1.5875) is not smaller than the radius (1) of the "
                             "arc it runs inside"),
    # a line, then an arc the tool is inside of, turning back 135 degrees: the offsets do not meet
    "line_into_arc": ("G0 X-20 Y0\nG41.1 D4\nG1 X-10 Y0 F100\nG1 X0 Y0\nG3 X-8.5355 Y-3.5355 I-3.5355 J-3.5355\n"
                      "G40\n", 6, "Arc move in concave corner cannot be reached by the tool without gouging",
                      "does not fit the concave corner between a line and this arc"),
    # two arcs the tool is inside of, the second turning back 150 degrees: the offset arcs do not cross
    "arc_into_arc": ("G0 X5 Y-10\nG41.1 D4\nG1 X5 Y0 F100\nG3 X0 Y5 I-5 J0\nG3 X5 Y5 I2.5 J4.330127\nG40\n", 6,
                     "Arc to arc motion makes a corner the compensated tool can't fit in without gouging",
                     "does not fit the concave corner between the arc of line 5 and this arc"),
    "arc_into_line": ("G0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0 F100\nG3 X10 Y0 R5\nG1 X9 Y-3\nG40\n", 6,
                      "Arc to straight motion makes a corner the compensated tool can't fit in without gouging",
                      "does not fit the concave corner between the arc of line 5 and this line"),
    "same_centre": ("G0 X0 Y-10\nG41.1 D2\nG1 X0 Y0 F100\nG3 X10 Y0 R5\nG2 X0 Y0 R5\nG40\n", 6,
                    "Arc to arc motion is invalid because the arcs have the same center", "about the same centre"),
    "entry_arc": ("G0 X0 Y0\nG41.1 D6\nG3 X2 Y0 R1 F100\nG40\n", 4,
                  "Radius of cutter compensation entry arc is not greater than the tool radius",
                  "the cutter compensation entry arc's end is not farther than the tool radius (3)"),
}


@needs_rs274
@pytest.mark.parametrize("name", sorted(REFUSALS))
def test_compensated_arc_refused_in_one_line_naming_the_line_like_rs274(tmp_path, name):
    body, line, rs274_says, cam_says = REFUSALS[name]
    text = "G21 G90 G17\n" + body + "M2\n"
    path = tmp_path / f"{name}.ngc"
    path.write_text(text)
    (tmp_path / "in.tbl").write_text(TOOLS_IN)
    (tmp_path / "mm.tbl").write_text(TOOLS_MM)
    path.with_suffix(".var").touch()  # rs274's parameters in the test's own directory
    try:
        run_rs274(str(path), tool_table=str(tmp_path / "in.tbl"), var_file=path.with_suffix(".var"))
    except Exception as exc:
        message, _, at = str(exc).split("rs274 reports: ", 1)[1].partition(" / ")
    else:
        pytest.fail("rs274 runs it")
    assert message == rs274_says and text.splitlines().index(at) + 1 == line
    proc = cli("info", path, "--state", tmp_path / "s.json", "--tool-table", tmp_path / "mm.tbl")
    assert_one_line_error(proc, f"{name}.ngc:{line}: ", cam_says, f"(rs274: {rs274_says})")
    with pytest.raises(ParseError, match=f"^{name}.ngc:{line}: "):
        parse_gcode(text, source=path.name, tool_lengths_mm=load_tool_table(tmp_path / "mm.tbl"))


def _random_arc_program(rng) -> str:
    """A random outline of lines and arcs (R, or I J on any point of the chord's bisector) run with cutter
    compensation: an entry move or arc from outside, 2..6 more moves (some Z-only), G40 and a traverse out; every
    line numbered (N, ten times its line number)."""
    def xy() -> tuple[float, float]:
        return round(rng.uniform(-30, 30), 3), round(rng.uniform(-30, 30), 3)

    here = (round(rng.uniform(-60, -40), 3), round(rng.uniform(-60, 60), 3))
    body = [f"G0 X{here[0]:.3f} Y{here[1]:.3f} Z1", f"G{rng.choice(['41.1', '42.1'])} D{rng.uniform(0.2, 8):.3f}"]
    for k in range(rng.integers(3, 8)):
        if k and rng.random() < 0.1:
            body.append(f"G1 Z{rng.uniform(-2, 0):.3f}")
            continue
        x, y = xy()
        feed = " F100" if k == 0 else ""
        chord = math.hypot(x - here[0], y - here[1])
        roll = rng.random()
        if roll < 0.5 or chord == 0:
            body.append(f"G1 X{x:.3f} Y{y:.3f}{feed}")
        elif roll < 0.75:
            r = chord / 2 * rng.uniform(1.001, 3) * rng.choice([1, -1])
            body.append(f"{rng.choice(['G2', 'G3'])} X{x:.3f} Y{y:.3f} R{r:.3f}{feed}")
        else:
            h = rng.uniform(-2, 2)  # the centre: off the chord's middle by h chords, to its left
            cx, cy = (here[0] + x) / 2 - h * (y - here[1]), (here[1] + y) / 2 + h * (x - here[0])
            body.append(f"{rng.choice(['G2', 'G3'])} X{x:.3f} Y{y:.3f} I{cx - here[0]:.4f} J{cy - here[1]:.4f}{feed}")
        here = (x, y)
    body += ["G40", f"G0 X{rng.uniform(40, 60):.3f} Y{rng.uniform(-60, 60):.3f}", "M2"]
    return "G21 G90 G17\n" + "".join(f"N{10 * (i + 2)} {ln}\n" for i, ln in enumerate(body))


_CANON_ARC = re.compile(r"^\s*\d+\s+N(\d+)\s+(STRAIGHT_FEED|STRAIGHT_TRAVERSE|ARC_FEED)\(([^)]*)\)")


def _sweep_rad(start, centre, rotation: int, end) -> float:
    a0 = math.atan2(start[1] - centre[1], start[0] - centre[0])
    a1 = math.atan2(end[1] - centre[1], end[0] - centre[0])
    part = ((a1 - a0) if rotation > 0 else (a0 - a1)) % (2 * math.pi)
    return (part or 2 * math.pi) + 2 * math.pi * (abs(rotation) - 1)


def _rs274_runs_past_its_start(text: str, path, line: int, at: int) -> bool:
    """Whether rs274, running the block of line ``at``, runs the arc of line ``line`` round more than its programmed
    sweep (its start moved past its end: a gouge), before any error it reports later.  The programmed arc is
    cam's of the program with no compensation (D0), which the G-code tests check against rs274."""
    plain = parse_gcode(re.sub(r"D[\d.]+", "D0", text)).moves
    k = next(i for i, mv in enumerate(plain) if mv.line == line)
    arc, start = plain[k], plain[k - 1].end
    programmed = _sweep_rad(start, arc.center, -1 if arc.clockwise else 1, arc.end)
    proc = subprocess.run(["rs274", "-v", str(path.with_suffix(".var")), "-g", str(path)], capture_output=True,
                          text=True, timeout=60, stdin=subprocess.DEVNULL)  # its moves up to an error too
    last, past = (0.0, 0.0), False
    for canon in proc.stdout.splitlines():
        m = _CANON_ARC.match(canon)
        if m:
            args = [float(a) for a in m.group(3).split(",")]
            if (m.group(2) == "ARC_FEED" and int(m.group(1)) == 10 * at
                    and np.allclose(args[2:4], arc.center, atol=1e-3)):
                past |= _sweep_rad(last, args[2:4], int(args[4]), args[:2]) > programmed + 0.0254
            last = tuple(args[:2])
    return past


GOUGES = {
    # a concave corner moves the start of a short line past its end; the next corner, into an arc, rs274 does not
    # check: it runs the line backwards
    "backwards": ("G0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0 F100\nG1 X20 Y0\nG1 X20 Y1\nG2 X25 Y6 I5 J0\n", 7, 6),
    # ... moves the start of a short arc (20 degrees, the tool inside) past its end: rs274 runs it round 338
    "past_its_start": ("G0 X0 Y-10\nG41.1 D4\nG1 X0 Y0 F100\nG1 X20 Y0\nG3 X19.6985 Y1.7101 I-5 J0\n"
                       "G2 X24.6985 Y-3.2899 I0 J-5\n", 7, 6),
}


@needs_rs274
@pytest.mark.parametrize("name", sorted(GOUGES))
def test_compensated_arcs_refuse_a_gouge_that_rs274_runs(tmp_path, name):
    body, at, line = GOUGES[name]
    lines = ["G21 G90 G17", *body.splitlines(), "G40", "G0 X40 Y-20", "M2"]
    text = "".join(f"N{10 * i} {ln}\n" for i, ln in enumerate(lines, 1))
    path = tmp_path / f"{name}.ngc"
    path.write_text(text)
    assert _rs274_refusal(path) is None
    if name == "backwards":
        assert _rs274_runs_backwards(text, path, line, at)
        what = f"the compensated move of line {line} would run backwards"
    else:
        assert _rs274_runs_past_its_start(text, path, line, at)
        what = f"the compensated arc of line {line} would run round past its start"
    assert_one_line_error(cli("info", path, "--state", tmp_path / "s.json"), f"{name}.ngc:{at}: cutter compensation "
                          "would gouge the part: a concave corner is too tight for the tool radius 2", what)


@needs_rs274
def test_compensated_arcs_agree_with_rs274_on_random_outlines(tmp_path):
    """40 random outlines of lines and arcs and tool radii: where rs274 runs one, cam runs the same moves; where
    rs274 refuses it, cam refuses it in one line naming the same line; where rs274 runs a held move backwards or
    an arc round past its start after a corner it does not check, cam refuses it there."""
    rng = np.random.default_rng(44_6_2)
    texts = [_random_arc_program(rng) for _ in range(40)]
    runs = refused = 0
    for i, text in enumerate(texts):
        path = tmp_path / f"r{i}.ngc"
        path.write_text(text)
        refusal = _rs274_refusal(path)
        try:
            moves = parse_gcode(text, source=path.name).moves
        except ParseError as exc:
            message = str(exc)
            assert "\n" not in message, message
            m = re.match(rf"{path.name}:(\d+): cutter compensation would gouge the part: .* the compensated "
                         r"(move|arc) of line (\d+) would run (backwards|round past its start)", message)
            if m and (refusal is None or refusal[1] > int(m.group(1))):  # rs274 runs on and gouges
                at, line = int(m.group(1)), int(m.group(3))
                gouges = (_rs274_runs_backwards(text, path, line, at) if m.group(2) == "move"
                          else _rs274_runs_past_its_start(text, path, line, at))
                assert gouges, (message, refusal, text)
                continue
            assert refusal is not None and message.startswith(f"{path.name}:{refusal[1]}: "), (message, refusal, text)
            refused += 1
            continue
        assert refusal is None, (refusal, text)
        want = [(mv.kind.replace("traverse", "rapid"), mv.end, mv.center, mv.rotation)
                for mv in parse_canonical(run_rs274(str(path), var_file=path.with_suffix(".var")))]
        assert len(moves) == len(want), (text, moves, want)
        for mv, (kind, end, centre, rotation) in zip(moves, want):
            assert mv.kind == kind and np.allclose(mv.end, end, atol=2e-4), (text, moves, want)
            if kind == "arc":
                assert np.allclose(mv.center, centre, atol=2e-4), (text, moves, want)
                assert (-1 if mv.clockwise else 1) * mv.turns == rotation, (text, moves, want)
        runs += 1
    assert runs >= 20 and refused >= 3, (runs, refused)


@needs_rs274
@pytest.mark.parametrize("between", ["G43.1 Z3", "T1 M6\nG43"])
def test_exit_move_after_an_offset_or_a_tool_change_starts_like_rs274(tmp_path, between):
    # after G40 the exit move starts from the programmed position: a tool length offset taken before it keeps
    # the machine position (Z), a tool change reads the position again (the tool's, offset in Y); the exit move
    # names X only
    text = f"G21 G90 G17\nG0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0 F100\nG1 X20 Y0\nG40\n{between}\nG0 X30\nM2\n"
    moves = _moves_like_rs274(tmp_path, "exit", text)
    assert np.allclose(moves[-1].end, (30, 2 if "M6" in between else 0, 0))
