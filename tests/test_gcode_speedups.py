"""The G-code interpreter's fast path for plain lines (``cam.formats._gcode_flow``: ``G1 X.. Y.. F..`` lines run
without the general interpreter) gives exactly what the general interpreter gives: the same moves (their
``repr``, so every float bit for bit, -0.0 included), warnings, batches, work offsets and errors (``file:line``
and text), for programs that change the offsets, units, modes and motion between runs of plain lines, for the
post-processor programs and constructs of test_gcode_lang, LinuxCNC's example programs and random programs.
``FAST_LINES = False`` is the general interpreter alone, the reference; ``ngc.PLAIN_NUMBERS = False`` reads every
value of a line by the expression reader (the reference for its short cut for plain numbers)."""
import ast
import random

import pytest

from cam.errors import ParseError
from cam.formats import _gcode_flow, _gcode_lines, ngc
from cam.formats.gcode import open_gcode, parse_gcode
from cam.limits import MAX_COORD_MM
from test_gcode_lang import CONSTRUCTS, NCFILES, POSTS, RS274_DEFAULT_TOOLS_MM, SUBROUTINE

TOOLS_MM = {1: 12.7, 2: -6.35, 3: 25.4, 102: 19.05}
BATCHES = (1 << 62, 1, 7)
"""Batch sizes each program's moves are taken in (``GcodeFile.move_batches``): the batches must match too."""

SUB_FILE = """o<zig> sub
G1 X[#1] Y-1 F300
X2 Y-2
G0 Z1
X3.5 Y-3.25
o<zig> endsub
M2
"""


def _outcome(run) -> tuple:
    """What a run gives, batch by batch: the moves' reprs, the warnings, the end offsets; then the error."""
    batches = []
    try:
        for batch in run():
            batches.append(([repr(m) for m in batch.moves], batch.warnings, batch.work_offsets_mm))
    except ParseError as exc:
        return batches, str(exc)
    return batches, None


@pytest.fixture
def compare(monkeypatch, tmp_path):
    """``compare(text, **options)``: the program run with the fast path and without it, in memory and from a
    file in batches of :data:`BATCHES`, must give the same; returns the lines the fast path ran and the
    in-memory outcome."""
    fast_lines = [0]
    original = _gcode_flow._PlainLines.plain_lines

    def spy(self, src, idx, limit):
        done, pending = original(self, src, idx, limit)
        fast_lines[0] += done
        return done, pending

    monkeypatch.setattr(_gcode_flow._PlainLines, "plain_lines", spy)
    subs = tmp_path / "subs"
    subs.mkdir()
    (subs / "square.ngc").write_text(SUBROUTINE)
    (subs / "zig.ngc").write_text(SUB_FILE)

    def run(text: str, name: str = "prog", batches=BATCHES, **options):
        options.setdefault("subroutine_path", [subs])
        path = tmp_path / f"{name}.ngc"
        path.write_text(text)
        fast_lines[0] = 0
        got = {}
        for fast in (False, True):
            monkeypatch.setattr(_gcode_flow, "FAST_LINES", fast)
            monkeypatch.setattr(ngc, "PLAIN_NUMBERS", fast)

            def held():
                program = parse_gcode(text, source=f"{name}.ngc", **options)
                yield from program.move_batches(1 << 62)
            got[fast] = [_outcome(held)]
            for size in batches:
                got[fast].append(_outcome(lambda: open_gcode(path, **options).move_batches(size)))
        assert got[True] == got[False], name
        return fast_lines[0], got[True][0]

    return run


def _moves(outcome) -> list[str]:
    return [m for batch in outcome[0] for m in batch[0]]


# -- hand-made programs: the frame changes between runs of plain lines -------------------------------------------------

FRAMES = {
    "g92_g10_params": """G21 G90 G17
G10 L2 P1 X10 Y-10 Z0
G1 X1 Y-1 F100
X2 Y-2
G92 X0 Y0
X1 Y1
X1.5 Y1.5
#5221=20
X2 Y2
G92.1
X3 Y-3
G10 L20 P0 X1 Y-1
X4 Y-4 Z1
G92.3
X5 Y-5
G92 Z5
Z4
G92.2
Z3
M2
""",
    "coordinate_systems": """G21 G90
G10 L2 P2 X5 Y-5 Z1
G10 L2 P7 X7 Y-7
G10 L2 P9 X9 Y-9 Z-2
G0 X1 Y-1
G55
X1 Y-1
G59.1 X1 Y-1
Y-2
G59.3
X1 Y-1
#5381=3
#5383=4
#5223=[#5223+1]
G55 X1 Y-1
G54 X1.25 Y-1.25 Z0.5
M2
""",
    "tool_lengths_and_m6": """G21 G90 G17
G0 Z10
G1 X1 Y-1 Z5 F200
T1 M6
G43 H1
X2 Y-2 Z5
T2 M6 G43 H2
X3 Y-3
Z4
G43.1 Z1.5
X4 Y-4 Z3
G49
Z2
M6 T3
G0 X5 Y-5
M2
""",
    "units_and_increments": """G21 G90 G17
G1 X10 Y-10 F500
G20
X1 Y-1
F20
X1.5 Y-1.5
G91
X0.1 Y-0.1
X0.1 Y-0.1 Z-0.01
G0 Z0.5
G21 G90
X20 Y-20
G91 G1 X-0 Y-0 Z-0
X0.001 Y-0.001
G90
G53 G0 X5 Y-5
X6 Y-6
G53 X7 Y-7
Y-8
M2
""",
    "feed_modes_cycles_arcs": """G21 G90 G17 G94
G1 X10 Y-10 F300
G93 G1 X11 Y-11 F2
X12 Y-12 F3
G94 F400
X13 Y-13
G81 R2 Z-1 X14 Y-14
X15 Y-15
Y-16
G80
G0 Z5
X16 Y-16
G2 X20 Y-16 I2 J0 F100
G1 X21 Y-16
G3 X25 Y-16 R2
G0 X30 Y-30
G1 X31 Y-31
G5.1 X35 Y-31 I1 J1
X36 Y-32
M2
""",
    "subroutines_loops": """G21 G90
#1 = 0
o100 while [#1 lt 4]
G1 X[#1] Y-1 F200
X1 Y-2
X1.5 Y-2.5 Z-0.5
G0 Z1
#1 = [#1 + 1]
o100 endwhile
o<zig> call [4]
X5 Y-5
o200 repeat [3]
G91
X1 Y-1
G90
o200 endrepeat
o<square> call [3] [1]
X7 Y-7
M2
""",
    "spindle_comments_blank_lines": """%
G21 G90

M3 S12000
G1 X1 Y-1 F600
  X2   Y-2\t
x3 y-3 z-1
N10 X4 Y-4
N20 G01 X5 Y-5
n30 g00 x6 y-6
G1 X7 Y-7 (comment)
X8 Y-8 ; comment
X9. Y-.5
X+1.0 Y-+1
G1X10Y-10Z0F700
M5
X11 Y-11
M4 S100
X12 Y-12
M8
X13 Y-13
%
""",
    "modal_save": """G21 G90
G1 X1 Y-1 F100
M70
G20 G91 F10
X0.1 Y-0.1
M72
X2 Y-2
M2
""",
}


@pytest.mark.parametrize("name", sorted(FRAMES))
def test_frame_changes_give_the_same_moves(compare, name):
    fast, outcome = compare(FRAMES[name], name=name, tool_lengths_mm=TOOLS_MM, start_mm=(3.0, -4.0, 2.0),
                            work_offsets_mm={"G55": (1.5, -2.5, 0.25), "G59.2": (-3.0, 3.0, 1.0)})
    assert outcome[1] is None, outcome[1]
    assert fast >= 3, f"{name}: the fast path ran {fast} lines"


def test_offsets_worked_out_by_hand(compare):
    """The ends of the first program of :data:`FRAMES`, worked out by hand."""
    _, outcome = compare(FRAMES["g92_g10_params"], name="hand")
    ends = [ast.literal_eval(m.split("end=")[1].split("), ")[0] + ")") for m in _moves(outcome)]
    assert ends == [(11, -11, 0), (12, -12, 0), (13, -11, 0), (13.5, -10.5, 0), (24, -10, 0), (23, -13, 0),
                    (26, -16, 1), (27, -17, 1), (27, -17, 0), (27, -17, 3)]


def test_units_worked_out_by_hand(compare):
    _, outcome = compare("G20 G90\nG1 X1 Y-2 F10\nG91 X0.5 Y-0.5\n", name="inch")
    moves = _moves(outcome)
    assert "end=(25.4, -50.8, 0.0), feed_mm_min=254.0" in moves[0]
    assert f"end=({25.4 + 0.5 * 25.4!r}, {-50.8 - 0.5 * 25.4!r}, 0.0)" in moves[1]


# -- errors in a run of plain lines: the same message at the same line -----------------------------------------------

ERRORS = {
    "no feed": ("G21 G90\nG0 X1 Y-1\nX2 Y-2\nX3 Y-3\nG1 X4 Y-4\nX5 Y-5\n", 5, "G1 without a feed rate 'F'"),
    "no motion mode": ("G21\nN1\nF100\nX1 Y-1\n", 4, "coordinates without a motion mode"),
    "word out of range": ("G21 G1 F100\nX1\nX2\nX1000001\nX3\n", 4, "word 'X1000001' is out of range"),
    "move out of range": (f"G21 G1 F100\nG10 L2 P1 X{MAX_COORD_MM - 1:g}\nX0.5\nX1\nX1.5\n", 5,
                          "the move reaches X1e+06 mm, beyond"),
    "incremental word out of range": ("G21 G91 G1 F100\nX-500000\nX0.5\nX1200000\nX1\n", 4,
                                      "word 'X1200000' is out of range"),
    "z move out of range": ("G21 G1 F100\nG10 L2 P1 Z999999\nZ0.5\nZ1.5\n", 4, "the move reaches Z1e+06 mm"),
    "program position out of range": ("G21 G1 F100\nG10 L2 P1 Y10\nY-999995\nG91 Y-3\nY-3\n", 5,
                                      "the move reaches Y-999991 mm, beyond"),
    "feed out of range": ("G21 G1 F100\nX1\nX2 F0.0001\n", 3, "feed 'F0.0001' is out of range"),
    "line number": ("G21 G1 F100\nX1\nN1000000001 X2\n", 3, "line number 'N1000000001' is out of range"),
    "arc mode": ("G21 F100\nG1 X1\nG2 X2 I0.5\nX3 Y-1\n", 4, "G2 arc needs I/J or R"),
    "cycle mode": ("G21 F100\nG1 X1\nG81 X2 Y-1\n", 3, "canned cycle"),
    "after g80": ("G21 F100\nG1 X1\nG81 R1 Z-1 X2\nG80\nX3\n", 5, "coordinates without a motion mode"),
    "inverse time": ("G21 G1 F100\nX1\nG93 X2 F1\nX3\n", 4, "in inverse time mode (G93) every feed move needs 'F'"),
}


@pytest.mark.parametrize("name", sorted(ERRORS))
def test_errors_in_a_run_of_plain_lines_name_the_same_line(compare, name):
    text, line, message = ERRORS[name]
    _, outcome = compare(text, name="bad")
    assert outcome[1] is not None and outcome[1].startswith(f"bad.ngc:{line}: "), outcome[1]
    assert message in outcome[1], outcome[1]


def test_a_loop_of_plain_lines_stops_at_the_same_line(compare):
    text = "G21 G1 F100\no1 while [1]\nX1 Y-1\nX2 Y-2\nX3 Y-3\no1 endwhile\n"
    for max_lines in (5, 50, 51, 52, 53):
        _, outcome = compare(text, name="loop", max_lines=max_lines)
        assert "does not end" in outcome[1]


def test_a_small_line_cache_gives_the_same_moves(compare, monkeypatch):
    """Loops run their lines again from the cache, and the cache is emptied when full."""
    monkeypatch.setattr(_gcode_flow, "CACHE_LINES", 3)
    fast, outcome = compare(FRAMES["subroutines_loops"], name="cache")
    assert outcome[1] is None and fast > 10


# -- the corpora of the other tests ------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(POSTS) + sorted(CONSTRUCTS))
def test_post_processor_programs_and_constructs(compare, name):
    text = POSTS.get(name) or CONSTRUCTS[name]
    compare(text, name=name, batches=(1 << 62, 3), tool_lengths_mm=TOOLS_MM, home_g28_mm=(25.4, -50.8, 12.7),
            home_g30_mm=(12.7, -12.7, 6.35))


@pytest.mark.slow
@pytest.mark.skipif(not NCFILES.is_dir(), reason="LinuxCNC's example programs (linuxcnc-uspace) not installed")
def test_linuxcnc_example_programs(compare):
    ran = 0
    for path in sorted(NCFILES.rglob("*.ngc")):
        ran += compare(path.read_text(errors="replace"), name=path.stem, batches=(1 << 62,),
                       tool_lengths_mm=RS274_DEFAULT_TOOLS_MM, max_lines=200_000)[0]
    assert ran > 100


# -- random programs ---------------------------------------------------------------------------------------------------

PLAIN = ["G1 X{x} Y{y}", "X{x} Y{y}", "G0 Z{z}", "N{n} G1 X{x} F{f}", "Y{y}", "G01 X{x}Y{y}Z{z}F{f}", "x{x} y{y}",
         "F{f}", "G0", "G1", "  X{x}\t", "G0 X{x} Y{y} Z{z}", "N{n}", "X{x} Y{y} Z{z} F{f}"]
OTHER = ["G90", "G91", "G20", "G21", "G92 X{x} Y{y}", "G92.1", "G92.2", "G92.3", "G10 L2 P{p} X{x} Y{y} Z{z}",
         "G10 L20 P0 X{x}", "G5{cs}", "G59.{p3}", "#5221={x}", "#5242=[#5242+{z}]", "G43 H1", "G43.1 Z{z}", "G49",
         "M6 T2", "T1 M6 G43 H1", "G93 G1 X{x} F2\nG94", "G81 R1 Z-1 X{x} Y{y}", "G80", "G2 X{x} Y{y} R50\nG1",
         "G90 G53 G0 X{x}", "M3 S1000", "M5", "G28", "(comment) X{x}", "X{x} (c)", "G0 X{x} ; c", "", "G4 P0.01",
         "G18", "G17", "M70\nG20 G91\nX{x}\nM72", "G64", "#1={x}", "X#1", "G91.1", "G1 X[{x} + 1] Y-{y}"]
BAD = ["X{big}", "F0.00001", "F0", "N99999999999", "G1 X{x} F-1", "G0 X{x} Y{y} A1", "X{x} X{x}", "G1 X{x} I1",
       "G1 X{x} F1e3", "G2 X{x} Y{y}", "G80 X{x}"]


def _random_program(rng: random.Random, lines: int) -> str:
    def fill(template: str) -> str:
        return template.format(x=f"{rng.uniform(-40, 40):.{rng.randint(0, 4)}f}",
                               y=f"{rng.uniform(-40, 40):.{rng.randint(0, 4)}f}",
                               z=f"{rng.uniform(-5, 5):.3f}", f=rng.choice(["100", "250.5", "1000.", "3000"]),
                               n=rng.randint(0, 99999), p=rng.randint(0, 9), p3=rng.randint(1, 3),
                               cs=rng.randint(4, 9), big=rng.choice(["2000000", "999999.9", "-1000000.5"]))
    out = [rng.choice(["G21 G90", "G20 G90", "G21 G91", ""]) + " G1 F200"]
    for _ in range(lines):
        roll = rng.random()
        pool = PLAIN if roll < 0.7 else OTHER if roll < 0.99 else BAD
        out.append(fill(rng.choice(pool)))
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("seed", range(12))
def test_random_programs(compare, seed):
    rng = random.Random(seed)
    fast = ended = 0
    for k in range(15):
        ran, outcome = compare(_random_program(rng, 40), name=f"r{seed}_{k}", batches=(1 << 62, 2),
                               tool_lengths_mm=TOOLS_MM, start_mm=(1.0, -2.0, 0.5))
        fast += ran
        ended += outcome[1] is None
    assert fast > 100 and ended >= 3, (fast, ended)


def test_a_plain_move_ends_a_series_of_g5_splines(compare):
    text = "G21 G90 G17 F100\nG5 X10 Y-10 I2 J0 P-2 Q0\nG1 X11 Y-11\nG5 X20 Y-20 P-1 Q1\n"
    _, outcome = compare(text, name="g5")
    assert "G5 needs I and J unless the move before it is a G5" in outcome[1]
    assert outcome[1].startswith("g5.ngc:4: ")


BODIES = ["g1x1.5y-2", "g0x+.5y-0.z1.", "x1y2x3", "g2x1i-0j+0", "n10g1x1e5", "x1.5.3", "x-", "x--1", "x+-1",
          "g1x[1+2]y#1", "x-[1]", "#1=2x#1", "m3s1000", "x1y", "@5^-90", "f1e3", "x" + "9" * 400, "x-" + "9" * 400,
          "gx1", "x1..2", "x.", "x-.5", "xsin[30]", "g01x1y2z3f4", "é1", "x1#2=3", ""]


def _read(body: str):
    try:
        line = ngc.read_line(body)
    except ngc.NgcSyntaxError as exc:
        return "error", str(exc)
    return line.o, line.words, line.assigns


def test_plain_numbers_read_as_the_expression_reader_reads_them(monkeypatch):
    rng = random.Random(7)
    bodies = BODIES + ["".join(rng.choice("gxyzfn@^-+.0123456789#[]=e") for _ in range(rng.randint(1, 14)))
                       for _ in range(3000)]
    for body in bodies:
        monkeypatch.setattr(ngc, "PLAIN_NUMBERS", False)
        want = _read(body)
        monkeypatch.setattr(ngc, "PLAIN_NUMBERS", True)
        assert repr(_read(body)) == repr(want), body


FILE_BYTES = [
    b"G21 G90\nG0 X1\n\nG1 Y-2 F100\nG1 X3",
    b"\xef\xbb\xbfG21\r\nG0 X1\r\n(\xc3\xa9t\xc3\xa9)\nG1 Y-2 F100\r\n",
    b"G21\rG0 X1\rG1 X2 F100\r",
    b"G21 G90\x0cG0 X1\n\x1c\nG1 Y-2 F100\x0b\x1dG1 X3\x1e\n\n\n",
    b"",
    b"\n",
    b"o100 sub\nG0 X1\no100 endsub\nM2\n" * 3,
]


@pytest.mark.parametrize("block", [1, 5, 64, 1 << 16])
def test_a_file_read_a_block_at_a_time_gives_its_lines(tmp_path, monkeypatch, block):
    """``_Source`` reads a file a block of lines at a time: the lines ``str.splitlines`` of its text gives, read in
    order or after seeks (every mark, any line), whatever the block size."""
    monkeypatch.setattr(_gcode_lines, "_BLOCK_BYTES", block)
    monkeypatch.setattr(_gcode_lines, "MARK_EVERY", 2)
    rng = random.Random(block)
    for k, data in enumerate(FILE_BYTES + [b"X1 Y-1\n" * 50 + b"X\xc3\xa9\n" + b"X2 Y-2\r\n" * 50]):
        path = tmp_path / f"f{k}.ngc"
        path.write_bytes(data)
        want = _gcode_lines._Source("m", data.decode("utf-8"))
        got = _gcode_lines._Source("f", path=path)
        assert got.n_lines == want.n_lines and got.o_at == want.o_at and got.subs == want.subs, k
        lines = [want.line(i) for i in range(want.n_lines)]
        assert [got.line(i) for i in range(got.n_lines)] == lines, k
        for i in [rng.randrange(max(1, got.n_lines)) for _ in range(30)] if got.n_lines else []:
            assert got.line(i) == lines[i], (k, i)
        got.close()


def test_small_blocks_and_marks_give_the_same_moves(compare, monkeypatch):
    monkeypatch.setattr(_gcode_lines, "_BLOCK_BYTES", 9)
    monkeypatch.setattr(_gcode_lines, "MARK_EVERY", 3)
    monkeypatch.setattr(_gcode_flow, "CACHE_LINES", 2)
    for name in ("subroutines_loops", "spindle_comments_blank_lines"):
        assert compare(FRAMES[name], name=name)[1][1] is None
