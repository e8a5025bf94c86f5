"""G-code that LinuxCNC's rs274 runs, from real files (issue #44 point 6, round three): a bare program number, a line
of modal codes with G80 and a motion code, grbl's ``?`` query, cutter radius compensation G41/G42, a program
that makes no moves, and ``cam info`` of a program whose origin is the stock's corner from a fresh state."""
import json
import math
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from cam.errors import CamError, ParseError
from cam.formats.gcode import load_tool_table, parse_gcode
from support.lcnc import parse_canonical, run_rs274

from test_cli import assert_one_line_error, cli

needs_rs274 = pytest.mark.skipif(
    shutil.which("rs274") is None and not os.environ.get("CI"), reason="rs274 (linuxcnc-uspace) not installed"
)


def _rs274_ends(tmp_path, text: str, name: str = "p.ngc") -> list:
    """rs274's traverses and feeds of ``text``: (kind, end mm rounded to 1e-4), zero-length moves left out."""
    path = tmp_path / name
    path.write_text(text)
    out, last = [], (0.0, 0.0, 0.0)
    for mv in parse_canonical(run_rs274(str(path))):
        end = tuple(round(v, 4) + 0.0 for v in mv.end)
        if end != last or mv.kind == "arc":
            out.append(("rapid" if mv.kind == "traverse" else mv.kind, end))
        last = end
    return out


def _cam_ends(text: str) -> list:
    out, last = [], (0.0, 0.0, 0.0)
    for mv in parse_gcode(text, source="p.ngc").moves:
        end = tuple(round(v, 4) + 0.0 for v in mv.end)
        if end != last or mv.kind == "arc":
            out.append((mv.kind, end))
        last = end
    return out


@needs_rs274
@pytest.mark.parametrize("head", ["O1000", "O1000 (engrave the plate)", "o0042", "%\nO1000"])
def test_gcode_bare_program_number_runs_like_rs274(tmp_path, head):
    text = f"{head}\nG21 G90\nG0 Z2\nG0 X5 Y3\nG1 Z-0.5 F100\nG1 X9\nG0 Z2\nM2\n" + ("%\n" if "%" in head else "")
    assert _cam_ends(text) == _rs274_ends(tmp_path, text) == [
        ("rapid", (0.0, 0.0, 2.0)), ("rapid", (5.0, 3.0, 2.0)), ("feed", (5.0, 3.0, -0.5)), ("feed", (9.0, 3.0, -0.5)),
        ("rapid", (9.0, 3.0, 2.0))]
    assert parse_gcode(text, source="p.ngc").warnings == []
    # a program number with words after it is an O word without a keyword, refused as rs274 refuses it
    with pytest.raises(Exception, match=r"p.ngc:2: unknown O word keyword"):
        parse_gcode("G21\nO1000 G0 X1\nM2\n", source="p.ngc")


@needs_rs274
@pytest.mark.parametrize("line, then", [
    ("G0 G90 G40 G21 G17 G94 G80", "X5 Y2"),  # a post's safety line: G0 wins over G80, as in rs274
    ("G80 G1 G21 F100", "X5 Y2"),  # either order
    ("G21 G1 G80 X3 F100", "X5 Y2"),
    ("G21 G80 G81 R1 Z-1 X2 F100", "X5 Y2"),  # a canned cycle with G80 on its line: the cycle runs
])
def test_gcode_modal_codes_on_one_line_like_rs274(tmp_path, line, then):
    text = f"G21\n{line}\n{then}\nM2\n"
    ends = _cam_ends(text)
    assert ends == _rs274_ends(tmp_path, text) and ends
    prog = parse_gcode(f"G20 G91\n{line}\n#<m> = #<_motion_mode>\n#<u> = #<_metric>\n#<a> = #<_absolute>\n"
                       "G0 X[#<m>] Y[#<u>] Z[#<a>]\nM2\n", source="p.ngc")
    motion = {"G0": 0, "G1": 10, "G81": 810}[next(w for w in line.split() if w in ("G0", "G1", "G81"))]
    assert prog.moves[-1].end == pytest.approx((motion, 1.0, 1.0) if "G90" in line else
                                               (prog.moves[-1].end[0], 1.0, prog.moves[-1].end[2]))
    # two motion codes other than G80 are refused as rs274 refuses them, in one line naming the line
    path = tmp_path / "two.ngc"
    path.write_text("G21\nG0 G1 X1 F100\nM2\n")
    with pytest.raises(Exception, match="rs274 reports: Two g codes used from same modal group"):
        run_rs274(str(path))
    assert_one_line_error(cli("info", path, "--state", tmp_path / "s.json"), "two.ngc:2:", "two motion codes")


def test_gcode_question_mark_line_is_skipped():
    text = "?\nG21 G90\n?\nG0 X5 Y-5\n  ? \nG1 Z-0.2 F100\nG0 Z1\nM2\n"
    program = parse_gcode(text, source="ugs.nc")
    assert program.warnings == ["ugs.nc:1: grbl real-time status query '?' skipped (and any later '?' lines): it "
                                "asks grbl where it is, it is not G-code"]
    plain = parse_gcode("\n".join(ln for ln in text.splitlines() if ln.strip() != "?"), source="ugs.nc")
    assert [(m.kind, m.end) for m in program.moves] == [(m.kind, m.end) for m in plain.moves]
    with pytest.raises(Exception, match=r"ugs.nc:2: "):  # a '?' among words is still no G-code
        parse_gcode("G21\nG0 X1 ?\n", source="ugs.nc")


@pytest.mark.parametrize("text", ["G21 G90\nM2\n", "%\nO1000\nG21 G90 G17 (set up only)\nG4 P0.5\nM2\n%\n",
                                  "(nothing but a comment)\n"])
def test_gcode_without_moves_says_so(tmp_path, text):
    path = tmp_path / "empty.ngc"
    path.write_text(text)
    for command in ("info", "drill"):
        proc = cli(command, path, "--state", tmp_path / "s.json", *(["--no-progress"] if command == "drill" else []))
        assert_one_line_error(proc, "empty.ngc", "the program makes no moves")
        assert "steps" not in proc.stderr
    # a move shorter than a step is still the steps' message
    path.write_text("G21\nG0 X0.001\nM2\n")
    assert_one_line_error(cli("info", path, "--state", tmp_path / "s.json"), "moves 0 steps", "larger than it")


CORNER = "G21 G90\nG0 Z5\nG0 X10 Y10\nG1 Z-1 F100\nG1 X50 Y10\nG3 X50 Y30 I0 J10\nG1 X10 Y30\nG0 Z5\nM2\n"
"""A program whose origin is the stock's lower left corner (X and Y up from it): from the home of a fresh state
(the work zero at the home, the back left corner) its Y goes off the table."""


def test_cam_info_shows_a_program_extent_from_a_fresh_state(tmp_path):
    path = tmp_path / "corner.ngc"
    path.write_text(CORNER)
    state = tmp_path / "s.json"  # no file yet: a fresh state
    proc = cli("info", path, "--state", state)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    # not planned from the fresh work zero, said in the machine frame (machine +Y toward the operator, +Z deeper)
    assert "not planned where it would run now" in lines[0] and "corner.ngc:3: move to machine X10.000 Y-10.000 " \
        "Z-5.000 mm leaves the machine travel (machine X 0..289, Y 0..289" in lines[0] and "+Y toward the operator" \
        in lines[0]
    # the extent in its own frame: the arc bulges to X60 (centre X50 Y20, radius 10)
    assert lines[1] == ("  extent in the program's own frame (G-code mm from its zero, +Y up, +Z up): X 0.000..60.000, "
                        "Y 0.000..30.000, Z -1.000..5.000 mm (60.00 x 30.00 x 6.00 mm)")
    # where its zero may go: travel X 0..289, Y 0..289, Z -10.048..31.4 machine mm (the thesis machine)
    assert lines[2].startswith("  fits the machine travel with its work zero at machine X 0.000..229.000, "
                               "Y 30.000..289.000, Z -5.048..30.400 mm (the machine frame of cam where")
    rep = json.loads(cli("info", path, "--state", state, "--json").stdout)
    assert rep["extent_program_mm"] == [[0.0, 0.0, -1.0], [60.0, 30.0, 5.0]]
    assert rep["work_zero_fits_machine_mm"] == [[0.0, 30.0, -5.048], [229.0, 289.0, 30.4]]
    assert "leaves the machine travel" in rep["travel_error"]
    # a zero in that range (cam zero --at speaks the same frame): the program is planned there, as cam drill runs it
    assert cli("zero", "--at", "0,30,0", "--state", state).returncode == 0
    proc = cli("info", path, "--state", state)
    assert proc.returncode == 0 and proc.stdout.startswith(f"{path}: 7 moves, cut area 50.00 x 20.00 mm"), proc.stdout
    assert proc.stdout.splitlines()[1] == lines[1]
    # just outside it: refused again, named in the machine frame; a bad program is still a one-line error
    assert cli("zero", "--at", "0,29,0", "--state", state).returncode == 0
    assert "not planned where it would run now" in cli("info", path, "--state", state).stdout
    path.write_text("G21\nG0 X1 A2\n")
    assert_one_line_error(cli("info", path, "--state", state), "corner.ngc:2:", "rotary axis")


COMP_PROGRAMS = {
    # left: a convex entry (an arc about the first point), concave and convex corners, the exit after G40
    "left": "G21 G90 G17\nG0 X-10 Y-10 Z1\nG41.1 D4\nG1 X0 Y0 F100\nG1 X20 Y0\nG1 X20 Y10\nG1 X30 Y20\nG1 X10 Y20\n"
            "G40\nG0 X-10 Y30\nM2\n",
    # right: a concave entry, a Z-only plunge held with the corner, a helical line, a G0 (straight corner)
    "right": "G21 G90 G17\nG0 X-10 Y-10 Z1\nG42.1 D4\nG1 X0 Y0 F100\nG1 Z-1\nG1 X20 Y0\nG1 X20 Y10 Z-2\n"
             "G0 X10 Y10\nG40\nG1 X-10 Y30\nM2\n",
    # a pocket's outline in inches and incremental moves, compensation on the entry's own line, off on the exit's
    "inch": "G20 G91 G17\nG0 X-0.5 Y-0.5\nG1 Z-0.05 F10\nG41.1 D0.125 X0.5 Y0.5\nX1\nY0.6\nX-1\nY-0.6\n"
            "G40 X-0.3 Y-0.3\nG90 G0 Z0.5\nM2\n",
    # a plain exit line naming X only: its Y is the programmed one, not the tool centre's
    "exit": "G21 G90 G17\nG0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0 F100\nG1 X20 Y0\nG40\nG1 X30\nG91 X1\nM2\n",
}


@needs_rs274
@pytest.mark.parametrize("name", sorted(COMP_PROGRAMS))
def test_gcode_cutter_compensation_matches_rs274(tmp_path, name):
    text = COMP_PROGRAMS[name]
    path = tmp_path / f"{name}.ngc"
    path.write_text(text)
    want = [(mv.kind.replace("traverse", "rapid"), mv.end, mv.center, mv.rotation < 0)
            for mv in parse_canonical(run_rs274(str(path)))]
    got = [(mv.kind, mv.end, mv.center, mv.clockwise) for mv in parse_gcode(text, source=path.name).moves]
    atol_mm = 3e-3 if "G20" in text else 1e-4  # rs274 prints 4 decimals of its units
    assert len(got) == len(want), (got, want)
    for (kind, end, centre, cw), (want_kind, want_end, want_centre, want_cw) in zip(got, want):
        assert kind == want_kind and np.allclose(end, want_end, atol=atol_mm), (got, want)
        if kind == "arc":
            assert np.allclose(centre, want_centre, atol=atol_mm) and cw == want_cw
    assert sum(kind == "arc" for kind, *_ in got) >= 1  # a convex corner is rounded


@pytest.mark.parametrize("line, fragment", [
    ("G5 X20 Y10 I0 J5 P0 Q-5", "p.ngc:5: a spline (G5/G5.1) while cutter compensation is on"),  # arcs run
    ("G81 X5 Y5 Z-1 R1", "p.ngc:5: a move other than G0..G3 (a canned cycle, G28/G30, G53) while cutter"),
    ("G4 P1", "p.ngc:5: a dwell (G4) while cutter compensation is on"),
    ("G92 X0", "p.ngc:5: a change of plane, coordinate system or offsets while cutter compensation is on"),
    ("G41.1 D2", "p.ngc:5: cutter compensation is already on"),
])
def test_gcode_cutter_compensation_refuses_the_rest_in_one_line(line, fragment):
    head = "G21 G90\nG0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0 F100\n"
    with pytest.raises(Exception, match=re.escape(fragment)):
        parse_gcode(head + line + "\nM2\n", source="p.ngc")
    with pytest.raises(Exception, match=r"p.ngc:2: 'G41': cutter radius compensation G41/G42 takes the tool's radius from the tool table"):
        parse_gcode("G21\nG41 D1\n", source="p.ngc")
    with pytest.raises(Exception, match=r"p.ngc:3: the cutter compensation entry move \(1\) is not longer than"):
        parse_gcode("G21\nG41.1 D4\nG1 X1 F100\n", source="p.ngc")


def _rs274_refusal(path) -> tuple[str, int] | None:
    """rs274's refusal of the program at ``path``: (its message, the number of the line it names), or None."""
    var = path.with_suffix(".var")
    var.touch()  # rs274's parameters in the test's own directory (a missing file is one more line of stderr)
    try:
        run_rs274(str(path), var_file=var)
    except CamError as exc:
        message, _, line = str(exc).split("rs274 reports: ", 1)[1].partition(" / ")
        lines = path.read_text().splitlines()
        assert lines.count(line) == 1, (line, lines)
        return message, lines.index(line) + 1
    return None


GOUGES = {
    # left: up 1 after a long move, the next corner is concave again: the offset of the short move runs back 3
    "left_concave": ("G21 G90 G17\nG0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0 F100\nG1 X20 Y0\nG1 X20 Y1\nG1 X0 Y1\n"
                     "G40\nG0 X-10 Y-10\nM2\n", 7, "feed"),
    # right, traverses: a notch 1 wide with a tool 4 wide
    "right_notch": ("G21 G90 G17\nG0 X-10 Y10\nG42.1 D4\nG0 X0 Y0\nG0 X20 Y0\nG0 X20 Y5\nG0 X21 Y5\nG0 X21 Y0\n"
                    "G40\nM2\n", 8, "traverse"),
    # the short move's own corner is concave, the next one convex: refused when the convex corner runs it
    "then_convex": ("G21 G90 G17\nG0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0 F100\nG1 X20 Y0\nG1 X20 Y1\nG1 X40 Y1\n"
                    "G40\nM2\n", 7, "feed"),
    # ... or when G40 (or M2) runs it
    "then_g40": ("G21 G90 G17\nG0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0 F100\nG1 X20 Y0\nG1 X20 Y1\nG40\nG0 X0 Y-10\n"
                 "M2\n", 7, "feed"),
    "then_m2": ("G20 G90 G17\nG0 X-1 Y-1\nG41.1 D0.25\nG1 X0 Y0 F10\nG1 X2 Y0\nG1 X2 Y0.1\nM2\n", 7, "feed"),
}


@needs_rs274
@pytest.mark.parametrize("name", sorted(GOUGES))
def test_cutter_comp_refuses_a_concave_corner_tighter_than_the_tool_like_rs274(tmp_path, name):
    text, line, what = GOUGES[name]
    path = tmp_path / f"{name}.ngc"
    path.write_text(text)
    assert _rs274_refusal(path) == (f"Straight {what} in concave corner cannot be reached by the tool without "
                                    "gouging", line)
    proc = cli("info", path, "--state", tmp_path / "s.json")
    assert_one_line_error(proc, f"{name}.ngc:{line}: cutter compensation would gouge the part: a concave corner is "
                                "too tight for the tool radius", f"rs274: Straight {what} in concave corner")
    with pytest.raises(ParseError, match=f"{name}.ngc:{line}: "):
        parse_gcode(text, source=path.name)
    # the same outline with the tool small enough (radius 0.4 < the short move 1) runs as rs274 runs it
    small = text.replace("D4", "D0.8").replace("D0.25", "D0.08")
    path.write_text(small)
    assert _rs274_refusal(path) is None
    _assert_same_moves(small, path)


def _assert_same_moves(text: str, path) -> None:
    """cam runs ``text`` (in ``path``) as rs274 runs it: the same moves, ends and arcs."""
    want = [(mv.kind.replace("traverse", "rapid"), mv.end, mv.center, mv.rotation < 0)
            for mv in parse_canonical(run_rs274(str(path), var_file=path.with_suffix(".var")))]
    got = [(mv.kind, mv.end, mv.center, mv.clockwise) for mv in parse_gcode(text, source=path.name).moves]
    atol_mm = 3e-3 if "G20" in text else 2e-4  # rs274 prints 4 decimals of its units
    assert len(got) == len(want), (got, want)
    for (kind, end, centre, cw), (want_kind, want_end, want_centre, want_cw) in zip(got, want):
        assert kind == want_kind and np.allclose(end, want_end, atol=atol_mm), (got, want)
        if kind == "arc":
            assert np.allclose(centre, want_centre, atol=atol_mm) and cw == want_cw, (got, want)


@needs_rs274
@pytest.mark.parametrize("entry, line", [
    ("G1 X-8 Y-10 F100", 4),  # 2 long, the radius is 2
    ("G1 X-8.5 Y-9 F100", 4),  # shorter than the radius
    ("G1 Z-1 F100\nG1 X0 Y0", 4),  # a Z-only first move is an entry move of length 0
    ("G0 X-10 Y-10 (stay)\nG1 X0 Y0 F100", 4),  # so is a move to where the tool stands
])
def test_cutter_comp_refuses_a_short_entry_move_like_rs274(tmp_path, entry, line):
    text = f"G21 G90 G17\nG0 X-10 Y-10\nG41.1 D4\n{entry}\nG1 X20 Y0\nG40\nM2\n"
    path = tmp_path / "entry.ngc"
    path.write_text(text)
    assert _rs274_refusal(path) == ("Length of cutter compensation entry move is not greater than the tool radius",
                                    line)
    assert_one_line_error(cli("info", path, "--state", tmp_path / "s.json"), f"entry.ngc:{line}: the cutter "
                          "compensation entry move", "is not longer than the tool radius")
    # a little longer than the radius: runs as rs274 runs it; with D0 even a Z-only first move does
    for longer in (text.replace("X-8 Y-10", "X-7.9 Y-10"), text.replace("D4", "D0")):
        if longer != text:
            path.write_text(longer)
            assert _rs274_refusal(path) is None
            _assert_same_moves(longer, path)


_CANON_N = re.compile(r"^\s*\d+\s+N(\d+)\s+(STRAIGHT_FEED|STRAIGHT_TRAVERSE|ARC_FEED)\(([^)]*)\)")


def _rs274_runs_backwards(text: str, path, line: int, at: int) -> bool:
    """Whether rs274, running the block of line ``at``, makes a straight move against the programmed move of line
    ``line`` (a gouge), before any error it reports later.  Every line of ``text`` is numbered N10 x its line
    number; each move gives X and Y."""
    xy = [dict(re.findall(r"([XY])(-?[\d.]+)", ln)) for ln in text.splitlines()]
    prev = next(w for w in reversed(xy[:line - 1]) if w)
    direction = (float(xy[line - 1]["X"]) - float(prev["X"]), float(xy[line - 1]["Y"]) - float(prev["Y"]))
    last, backwards = (0.0, 0.0), False
    proc = subprocess.run(["rs274", "-v", str(path.with_suffix(".var")), "-g", str(path)], capture_output=True,
                          text=True, timeout=60, stdin=subprocess.DEVNULL)  # its moves up to an error too
    for canon in proc.stdout.splitlines():
        m = _CANON_N.match(canon)
        if m:
            end = tuple(float(a) for a in m.group(3).split(",")[:2])
            backwards |= (int(m.group(1)) == 10 * at and m.group(2) != "ARC_FEED"
                          and (end[0] - last[0]) * direction[0] + (end[1] - last[1]) * direction[1] < -1e-3)
            last = end
    return backwards


def _random_comp_program(rng) -> str:
    """A random outline run with cutter compensation: an entry from outside, 3..7 corners (some closing the
    outline, some with a Z-only move or a traverse), G40 and an exit move; every line numbered (N) so that the line
    rs274 names can be found."""
    def xy() -> str:
        return f"X{rng.uniform(-30, 30):.3f} Y{rng.uniform(-30, 30):.3f}"

    body = [f"G0 X{rng.uniform(-60, -40):.3f} Y{rng.uniform(-60, 60):.3f} Z1",
            f"G{rng.choice(['41.1', '42.1'])} D{rng.uniform(0.2, 12):.3f}", f"G1 {xy()} F100"]
    first = body[-1].split()[1:3]
    for _ in range(rng.integers(3, 8)):
        roll = rng.random()
        body.append(f"G1 Z{rng.uniform(-2, 0):.3f}" if roll < 0.1 else f"G0 {xy()}" if roll < 0.2 else f"G1 {xy()}")
    if rng.random() < 0.5:
        body.append("G1 " + " ".join(first))
    body += ["G40", f"G0 X{rng.uniform(40, 60):.3f} Y{rng.uniform(-60, 60):.3f}", "M2"]
    return "G21 G90 G17\n" + "".join(f"N{10 * (i + 2)} {ln}\n" for i, ln in enumerate(body))


def _assert_runs_like_rs274(text: str, path, refusal: tuple[str, int] | None) -> None:
    """cam runs the compensated program ``text`` as rs274 does (``refusal``: :func:`_rs274_refusal`'s): the same
    moves, or a one-line refusal naming the line rs274 names (a gouge for a gouge); or, where rs274 runs a move
    backwards straight on (a corner within its 0.05 rad of straight: not checked) and gouges, a refusal there."""
    try:
        parse_gcode(text, source=path.name)
    except ParseError as exc:
        message = str(exc)
        m = re.match(rf"{path.name}:(\d+): cutter compensation would gouge the part: .* the compensated move of "
                     r"line (\d+) would run backwards", message)
        if m and (refusal is None or refusal[1] > int(m.group(1))):  # cam refuses first: rs274 went on and gouged
            assert _rs274_runs_backwards(text, path, int(m.group(2)), int(m.group(1))), (message, refusal, text)
            return
        assert refusal is not None, (message, text)
    else:
        assert refusal is None, (refusal, text)
        _assert_same_moves(text, path)
        return
    assert "\n" not in message and message.startswith(f"{path.name}:{refusal[1]}: "), (refusal, message, text)
    assert ("gouge" in message) == ("gouging" in refusal[0]), (refusal, message)


@needs_rs274
def test_cutter_comp_agrees_with_rs274_on_random_polygons(tmp_path):
    """40 random outlines and tool radii: where rs274 runs one, cam runs the same moves; where rs274 refuses it
    (a tool too big for a corner, a short entry), cam refuses it in one line naming the same line."""
    rng = np.random.default_rng(44_6)
    texts = [_random_comp_program(rng) for _ in range(40)]
    paths = [tmp_path / f"r{i}.ngc" for i in range(len(texts))]
    for path, text in zip(paths, texts):
        path.write_text(text)
    refusals = [_rs274_refusal(path) for path in paths]  # one at a time: rs274s at once may crash (SIGBUS)
    for path, text, refusal in zip(paths, texts, refusals):
        _assert_runs_like_rs274(text, path, refusal)
    assert 8 <= refusals.count(None) <= 32, refusals  # both kinds are met


@needs_rs274
def test_cutter_comp_refuses_a_backwards_move_that_rs274_runs_straight_on(tmp_path):
    # up 1 after a long move (a concave corner meeting 2 above), then straight on up: rs274 checks no move before
    # a corner within 0.05 rad of straight, and runs the short move's offset back down 1 mm: the tool, 2 mm in
    # radius, cuts 1 mm below the edge Y0.  cam refuses it in one line.
    body = ["G21 G90 G17", "G0 X-10 Y-10", "G41.1 D4", "G1 X0 Y0 F100", "G1 X20 Y0", "G1 X20 Y1", "G1 X20 Y30",
            "G40", "G0 X40 Y40", "M2"]
    text = "".join(f"N{10 * i} {ln}\n" for i, ln in enumerate(body, 1))
    path = tmp_path / "on.ngc"
    path.write_text(text)
    assert _rs274_refusal(path) is None and _rs274_runs_backwards(text, path, 6, 7)
    assert_one_line_error(cli("info", path, "--state", tmp_path / "s.json"), "on.ngc:7: cutter compensation would "
                          "gouge the part", "the compensated move of line 6 would run backwards")
    # an arc just after G40 is refused by both
    path.write_text(text.replace("X20 Y1\n", "X20 Y10\n").replace("G0 X40 Y40", "G2 X30 Y10 R10"))
    assert _rs274_refusal(path) == (
        "The move just after exiting cutter compensation mode must be straight, not an arc", 9)
    assert_one_line_error(cli("info", path, "--state", tmp_path / "s.json"), "on.ngc:9: the move just after cutter "
                          "compensation is turned off (G40) must be straight")


@needs_rs274
def test_cutter_comp_g41_g42_take_the_tool_table_diameter_like_rs274(tmp_path):
    # G41 D1 (tool 1's diameter), then tool 2 in the spindle and G42 without D (its diameter), G41 D0 (the
    # spindle's too)
    text = ("G21 G90 G17\nG0 X-10 Y-10\nG41 D1\nG1 X0 Y0 F100\nG1 X20 Y0\nG1 X20 Y10\nG40\nG0 X0 Y30\nT2 M6\nG42\n"
            "G1 X0 Y0\nG1 X-20 Y0\nG1 X-20 Y-20\nG40\nG41 D0\nG1 X5 Y5\nG1 X9 Y5\nG40\nM2\n")
    path = tmp_path / "tt.ngc"
    path.write_text(text)
    inches, mm = tmp_path / "inch.tbl", tmp_path / "mm.tbl"
    inches.write_text("T1 P1 D0.25 ;rs274's machine units are inches\nT2 P2 Z0 D0.5\n")
    mm.write_text("T1 P1 D6.35 ;cam's are mm\nT2 P2 Z0 D12.7\n")
    (tmp_path / "tt.var").touch()
    want = [(mv.kind.replace("traverse", "rapid"), mv.end, mv.center) for mv in
            parse_canonical(run_rs274(str(path), tool_table=str(inches), var_file=tmp_path / "tt.var"))]
    got = [(mv.kind, mv.end, mv.center) for mv in parse_gcode(text, source=path.name,
                                                               tool_lengths_mm=load_tool_table(mm)).moves
           if mv.kind != "pause"]  # M6: cam pauses for the tool change
    assert len(got) == len(want) and sum(kind == "arc" for kind, *_ in got) >= 2, (got, want)
    for (kind, end, centre), (want_kind, want_end, want_centre) in zip(got, want):
        assert kind == want_kind and np.allclose(end, want_end, atol=2e-4), (got, want)
        assert kind != "arc" or np.allclose(centre, want_centre, atol=2e-4), (got, want)
    assert np.allclose(got[1][1], (-3.175 / 2**0.5, 3.175 / 2**0.5, 0), atol=1e-4)  # radius 3.175: tool 1's
    # G10 L1 R (a radius) sets a tool's diameter as in rs274; G41.1 D is still a diameter
    g10 = parse_gcode("G21\nG10 L1 P3 R2\nT3 M6\nG0 X-10 Y-10\nG42\nG1 X0 Y0 F100\nG40\nM2\n", source="g.ngc",
                      tool_lengths_mm=load_tool_table(mm))
    assert np.allclose(g10.moves[-1].end, (2 / 2**0.5, -2 / 2**0.5, 0))
    # refused in one line naming the line: no tool table, a tool not in it, a D that is no tool number
    assert_one_line_error(cli("info", path, "--state", tmp_path / "s.json"), "tt.ngc:3: 'G41': cutter radius "
                          "compensation G41/G42 takes the tool's radius from the tool table's diameter, and there "
                          "is none")
    for line, fragment in (("G41 D3", "tt.ngc:3: G41: tool 3 is not in the tool table"),
                           ("G41 D1.5", "tt.ngc:3: G41 needs a tool number 'D' (a whole number 0 or more)")):
        path.write_text(text.replace("G41 D1", line))
        assert _rs274_refusal_with(path, inches) is not None
        assert_one_line_error(cli("info", path, "--state", tmp_path / "s.json", "--tool-table", mm), fragment)


def _rs274_refusal_with(path, tool_table) -> str | None:
    try:
        run_rs274(str(path), tool_table=str(tool_table), var_file=path.with_suffix(".var"))
    except CamError as exc:
        return str(exc)
    return None
